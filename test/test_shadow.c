/* test_shadow.c — shadows for moved lights (lib/shadow.h, lib/dircube.h):
 * the light buffer gives exactly the kd-tree's answers, the software item
 * buffer is wrong on a small share of decisions only, OSMesa draws the
 * same item buffer, and the direction cube maps every direction (edges,
 * corners, zeros) to a cell.  Points come from random rays cast like
 * trace casts them (float positions, surface derived from them). */
#include "check.h"
#include "dircube.h"
#include "shadow.h"

#include <time.h>

static uint64_t rng_state;

static double rnd(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (double)((rng_state * 2685821657736338717ull) >> 11) * (1.0 / 9007199254740992.0);
}

/* Triangles, a concave polygon, a floor whose corners lie on cube-corner
   directions of a light at (0,0,5), spheres (one inside-only), a cone, a
   pointed cone and cylinders (one along an axis). */
static const char scene_text[] =
    "v\nfrom 0 -9 4\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\nresolution 64 64\n"
    "b 0.1 0.1 0.1\n"
    "l 2 -2 6\n"
    "f 0.8 0.8 0.8 1 0 0 0 1\n"
    "p 4\n-5 -5 0\n5 -5 0\n5 5 0\n-5 5 0\n"
    "f 0.9 0.2 0.2 0.7 0.3 20 0 1\n"
    "s 0 0 1 0.8\n"
    "s 1.5 1.5 0.6 0.6\n"
    "s -2.5 2.5 1 -0.9\n"
    "c\n-1.5 0.5 0 0.6\n-1.5 0.5 1.5 0.15\n"
    "c\n2 -1.5 0.2 0.4\n2 -1.5 2.2 0.4\n"
    "c\n-3 -2 0.5 0.3\n-1 -3 0.7 0.3\n"
    "c\n3 2.5 0 0.5\n3 2.5 1.2 0\n"
    "f 0.2 0.8 0.3 0.8 0.2 10 0 1\n"
    /* concave: an L-shaped slab floating above, and a star */
    "p 6\n-1 -1 2.5\n1 -1 2.5\n1 -0.5 2.5\n-0.5 -0.5 2.5\n-0.5 1 2.5\n-1 1 2.5\n"
    "p 10\n2 0 3\n2.2 0.6 3.2\n2.8 0.6 3.2\n2.3 1 3.1\n2.5 1.6 3\n"
    "2 1.2 2.9\n1.5 1.6 3\n1.7 1 3.1\n1.2 0.6 3.2\n1.8 0.6 3.2\n"
    "p 3\n-4 3 0.01\n-3 4 2\n-4.5 4.5 1.5\n"
    /* a wall of thin slanted triangles */
    "p 3\n0.5 3 0\n0.6 3 3\n0.7 3.1 0\n"
    "p 3\n-0.5 3 0\n-0.4 3.05 3\n-0.3 3.1 0\n";

typedef struct light_case {
    const char *name;
    double pos[3];
} light_case;

static const light_case lights[] = {
    {"above", {2, -2, 6}},
    {"cube corners", {0, 0, 5}},
    {"low, inside the bounds", {0.4, -1.3, 0.35}},
    {"between objects", {-0.2, 1.2, 1.9}},
    {"inside a sphere", {0.1, 0.05, 1.1}},
    {"inside the inside-only sphere", {-2.4, 2.5, 1.2}},
    {"inside the cylinder", {2, -1.5, 1.0}},
    {"far away", {1e4, -2e4, 3e4}},
    {"very far away", {3e7, -1e7, 1e8}},
    {"as far as the sun, in metres", {1e11, 5e10, 6e10}},
    {"a hundred times farther", {1e13, -3e12, 5e12}},
    {"so far the scene fits in one widening", {2e15, 1e15, 1e16}},
    {"on a floor corner", {5, 5, 0}},
    {"just inside a cone's tip", {3, 2.5, 1.2}},
};
#define NLIGHTS (sizeof lights / sizeof *lights)

typedef struct sample {
    rtpi_v3 p, o;
    uint32_t prim;
} sample;

/* Random rays (half from the camera, half from random points in the
   bounds in random directions, which reach backs and insides); for each
   hit that trace would ask about, the hit and its shadow-ray origin. */
static size_t make_samples(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp,
                           sample *out, size_t want)
{
    size_t n = 0, tries;
    rtpi_v3 eye = v3(s->camera.from[0], s->camera.from[1], s->camera.from[2]);
    rtpi_v3 at = v3(s->camera.at[0], s->camera.at[1], s->camera.at[2]);
    for (tries = 0; n < want && tries < want * 20; tries++) {
        rtpi_ray r;
        rtpi_hit h;
        if (tries & 1) {
            r.o = eye;
            r.d = v3_norm(v3_add(v3_sub(at, eye),
                                 v3(8 * (rnd() - 0.5), 8 * (rnd() - 0.5), 6 * (rnd() - 0.5))));
        } else {
            double z = 2 * rnd() - 1, ph = 6.283185307179586 * rnd(), rr = sqrt(1 - z * z);
            r.o = v3(10 * (rnd() - 0.5), 10 * (rnd() - 0.5), 0.05 + 3.5 * rnd());
            r.d = v3(rr * cos(ph), rr * sin(ph), z);
        }
        r.tmin = 0.0;
        r.tmax = HUGE_VAL;
        if (!rtpi_kd_intersect(kd, &r, &h) ||
            !rtpi_shadow_query_at(s, 0, h.prim, v3_madd(r.o, r.d, h.t), r.d, lp, rtpi_offset_floor(s, NULL),
                                  &out[n].p,
                                  &out[n].o))
            continue;
        out[n].prim = h.prim;
        n++;
    }
    return n;
}

static rtp_scene *load(const char *text, size_t len)
{
    rtp_scene *s = NULL;
    rtp_error err;
    if (rtp_scene_load_memory(text, len, "test.nff", "nff", NULL, &s, &err) != RTP_OK) {
        char buf[256];
        fprintf(stderr, "load: %s\n", rtp_error_format(&err, buf, sizeof buf));
        return NULL;
    }
    return s;
}

/* Compares a mode with EXACT at every sample; @return mismatches. */
static size_t compare(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp,
                      rtpi_shadow_mode mode, int res, const sample *sm, size_t n,
                      size_t *lit)
{
    rtpi_shadow *ex = NULL, *sh = NULL;
    rtp_allocator a;
    size_t k, bad = 0;
    rtpi_allocator_init(&a, NULL);
    if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
        rtpi_shadow_create(s, kd, lp, mode, res, &a, &sh, NULL) != RTP_OK) {
        rtpi_shadow_destroy(ex);
        return (size_t)-1;
    }
    if (lit)
        *lit = 0;
    for (k = 0; k < n; k++) {
        int e = rtpi_shadow_visible(ex, sm[k].p, sm[k].o, sm[k].prim);
        int v = rtpi_shadow_visible(sh, sm[k].p, sm[k].o, sm[k].prim);
        bad += e != v;
        if (lit)
            *lit += (size_t)e;
    }
    rtpi_shadow_destroy(ex);
    rtpi_shadow_destroy(sh);
    return bad;
}

#define NSAMPLES 30000

static void run_scene(const char *label, const char *text, size_t len, int check_ib)
{
    rtp_scene *s = load(text, len);
    rtpi_kdtree *kd = NULL;
    sample *sm = (sample *)malloc(NSAMPLES * sizeof *sm);
    size_t li;
    static const int lb_res[] = {1024, 64, 7, 1};
    CHECK(s != NULL && sm != NULL);
    if (!s || !sm || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        free(sm);
        rtp_scene_destroy(s);
        return;
    }
    for (li = 0; li < NLIGHTS; li++) {
        rtpi_v3 lp = v3(lights[li].pos[0], lights[li].pos[1], lights[li].pos[2]);
        size_t n = make_samples(s, kd, lp, sm, NSAMPLES), lit = 0, bad, r;
        CHECK(n > NSAMPLES / 4);
        for (r = 0; r < sizeof lb_res / sizeof *lb_res; r++) {
            bad = compare(s, kd, lp, RTPI_SHADOW_LIGHTBUF, lb_res[r], sm, n, &lit);
            CHECK_MSG(bad == 0, "%s, light %s, res %d: %lu of %lu light-buffer answers differ",
                      label, lights[li].name, lb_res[r], (unsigned long)bad, (unsigned long)n);
        }
        if (check_ib) {
            bad = compare(s, kd, lp, RTPI_SHADOW_ITEMBUF, 1024, sm, n, NULL);
            printf("  %-10s light %-30s %6lu points, %5.1f%% lit: item buffer 1024 wrong %.3f%%\n",
                   label, lights[li].name, (unsigned long)n, 100.0 * (double)lit / (double)n,
                   100.0 * (double)bad / (double)n);
            CHECK_MSG((double)bad < 0.01 * (double)n, "%s, light %s: item buffer wrong on %lu of %lu",
                      label, lights[li].name, (unsigned long)bad, (unsigned long)n);
        }
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    free(sm);
}

static void test_lightbuf_equals_exact(void)
{
    run_scene("scene", scene_text, sizeof scene_text - 1, 1);
}

/* The same scene moved far from the origin and shrunk: the rounding of
   every routine grows relative to the geometry. */
static void test_lightbuf_far_from_origin(void)
{
    /* Rewrites each number n of the geometry lines as 3000 + n/100 on x. */
    char *buf = (char *)malloc(sizeof scene_text * 4);
    const char *p = scene_text;
    size_t m = 0;
    int line_no = 0, in_geom = 0;
    if (!buf) {
        CHECK(0);
        return;
    }
    while (*p) {
        const char *e = strchr(p, '\n');
        size_t L = e ? (size_t)(e - p) : strlen(p);
        double x, y, z, w;
        int k;
        char tmp[128];
        line_no++;
        memcpy(tmp, p, L < 127 ? L : 127);
        tmp[L < 127 ? L : 127] = 0;
        in_geom = strncmp(tmp, "from", 4) && strncmp(tmp, "at", 2) && strncmp(tmp, "up", 2) &&
                  strncmp(tmp, "angle", 5) && strncmp(tmp, "hither", 6) &&
                  strncmp(tmp, "resolution", 10) && tmp[0] != 'b' && tmp[0] != 'f';
        k = sscanf(tmp, "%lf %lf %lf %lf", &x, &y, &z, &w);
        if (in_geom && k >= 3 && tmp[0] != 'l' && tmp[0] != 's' && tmp[0] != 'p' && tmp[0] != 'c') {
            if (k == 4)
                m += (size_t)sprintf(buf + m, "%.9g %.9g %.9g %.9g\n", 3000 + x / 100, y / 100,
                                     z / 100, w / 100);
            else
                m += (size_t)sprintf(buf + m, "%.9g %.9g %.9g\n", 3000 + x / 100, y / 100, z / 100);
        } else if (tmp[0] == 's' && tmp[1] == ' ' &&
                   sscanf(tmp + 2, "%lf %lf %lf %lf", &x, &y, &z, &w) == 4) {
            m += (size_t)sprintf(buf + m, "s %.9g %.9g %.9g %.9g\n", 3000 + x / 100, y / 100,
                                 z / 100, w / 100);
        } else if (!strncmp(tmp, "from", 4) || !strncmp(tmp, "at", 2)) {
            sscanf(tmp + (tmp[0] == 'f' ? 4 : 2), "%lf %lf %lf", &x, &y, &z);
            m += (size_t)sprintf(buf + m, "%s %.9g %.9g %.9g\n", tmp[0] == 'f' ? "from" : "at",
                                 3000 + x / 100, y / 100, z / 100);
        } else {
            memcpy(buf + m, tmp, strlen(tmp));
            m += strlen(tmp);
            buf[m++] = '\n';
        }
        p += L + (e ? 1 : 0);
    }
    buf[m] = 0;
    {
        rtp_scene *s = load(buf, m);
        rtpi_kdtree *kd = NULL;
        sample *sm = (sample *)malloc(NSAMPLES * sizeof *sm);
        size_t li;
        CHECK(s != NULL);
        if (s && sm && rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK) {
            for (li = 0; li < NLIGHTS; li++) {
                /* The sampler's box is for the original scene: scale the
                   samples' scene instead by casting from the camera only. */
                rtpi_v3 lp = v3(3000 + lights[li].pos[0] / 100, lights[li].pos[1] / 100,
                                lights[li].pos[2] / 100);
                size_t n = 0, bad, tries;
                rtpi_v3 eye = v3(s->camera.from[0], s->camera.from[1], s->camera.from[2]);
                rtpi_v3 at = v3(s->camera.at[0], s->camera.at[1], s->camera.at[2]);
                for (tries = 0; n < NSAMPLES / 3 && tries < NSAMPLES; tries++) {
                    rtpi_ray r;
                    rtpi_hit h;
                    rtpi_surface sf;
                    rtpi_v3 pe, ng, ns, o;
                    r.o = eye;
                    r.d = v3_norm(v3_add(v3_sub(at, eye), v3(0.08 * (rnd() - 0.5),
                                                            0.08 * (rnd() - 0.5),
                                                            0.06 * (rnd() - 0.5))));
                    r.tmin = 0.0;
                    r.tmax = HUGE_VAL;
                    if (!rtpi_kd_intersect(kd, &r, &h))
                        continue;
                    pe = v3_madd(r.o, r.d, h.t);
                    {
                        const float pf[3] = {(float)pe.x, (float)pe.y, (float)pe.z};
                        rtpi_surface_from_point(s, h.prim, pf, 0, &sf);
                    }
                    ng = sf.ng;
                    ns = sf.ns;
                    if (v3_dot(r.d, ng) >= 0.0) {
                        ng = v3_mul(ng, -1.0);
                        ns = v3_mul(ns, -1.0);
                    }
                    if (!rtpi_shadow_setup(sf.p, ng, ns, lp, rtpi_offset_floor(s, NULL), &o))
                        continue;
                    sm[n].p = sf.p;
                    sm[n].o = o;
                    sm[n].prim = h.prim;
                    n++;
                }
                CHECK_MSG(n > NSAMPLES / 10, "far scene, light %s: only %lu points",
                          lights[li].name, (unsigned long)n);
                bad = compare(s, kd, lp, RTPI_SHADOW_LIGHTBUF, 512, sm, n, NULL);
                CHECK_MSG(bad == 0, "far scene, light %s: %lu of %lu differ", lights[li].name,
                          (unsigned long)bad, (unsigned long)n);
            }
        } else {
            CHECK(0);
        }
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
        free(sm);
    }
    free(buf);
}

/* A small SPD scene from ../shared/scenes, if present. */
static void test_spd_scene(void)
{
    const char *dir = check_shared_scenes();
    static const char *names[] = {"tetra_s2", "balls_s2", "rings_s2", "tree_s2"};
    size_t k;
    if (!dir)
        SKIP("../shared/scenes absent");
    for (k = 0; k < sizeof names / sizeof *names; k++) {
        char path[512];
        rtp_scene *s = NULL;
        rtpi_kdtree *kd = NULL;
        sample *sm;
        size_t n, bad;
        rtpi_v3 lp;
        snprintf(path, sizeof path, "%s/spd/%s.nff", dir, names[k]);
        if (rtp_scene_load(path, NULL, &s, NULL) != RTP_OK)
            continue;
        sm = (sample *)malloc(NSAMPLES * sizeof *sm);
        if (!sm || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK || !s->nlights) {
            free(sm);
            rtp_scene_destroy(s);
            continue;
        }
        lp = v3(s->lights[0].pos[0] * 0.7 + 0.3, s->lights[0].pos[1] * 0.8 - 0.2,
                s->lights[0].pos[2] * 0.9 + 0.1);
        n = make_samples(s, kd, lp, sm, NSAMPLES / 2);
        bad = compare(s, kd, lp, RTPI_SHADOW_LIGHTBUF, 256, sm, n, NULL);
        CHECK_MSG(bad == 0, "%s: %lu of %lu light-buffer answers differ", names[k],
                  (unsigned long)bad, (unsigned long)n);
        bad = compare(s, kd, lp, RTPI_SHADOW_ITEMBUF, 1024, sm, n, NULL);
        printf("  %-10s %6lu points: item buffer 1024 wrong %.3f%%\n", names[k], (unsigned long)n,
               n ? 100.0 * (double)bad / (double)n : 0.0);
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
        free(sm);
    }
}

/* A light buffer built on several threads is the one-thread buffer, cell
   for cell and entry for entry (the project's scene, and a mesh large
   enough to be split over threads when ../shared is there). */
static void lb_same(const rtp_scene *s, rtpi_v3 lp, int res, const char *what)
{
    rtpi_lightbuf a, b;
    rtp_allocator al;
    size_t k;
    int threads;
    rtpi_allocator_init(&al, NULL);
    if (rtpi_lightbuf_build_some(s, lp, res, NULL, 0, 1, HUGE_VAL, HUGE_VAL, NULL, &al, &a, NULL) != RTP_OK) {
        CHECK_MSG(0, "%s: build failed", what);
        return;
    }
    for (threads = 2; threads <= 5; threads += 3) {
        int same;
        if (rtpi_lightbuf_build_some(s, lp, res, NULL, 0, threads, HUGE_VAL, HUGE_VAL, NULL, &al, &b,
                                     NULL) != RTP_OK) {
            CHECK_MSG(0, "%s: build on %d threads failed", what, threads);
            continue;
        }
        same = a.w.ncells == b.w.ncells && a.nrefs == b.nrefs && a.ncand == b.ncand &&
               memcmp(a.off, b.off, (a.w.ncells + 1) * sizeof *a.off) == 0 &&
               memcmp(a.ref, b.ref, a.nrefs * sizeof *a.ref) == 0;
        for (k = 0; same && k < a.ncand; k++) /* (field by field: padding) */
            same = a.cand[k].prim == b.cand[k].prim && a.cand[k].near == b.cand[k].near;
        CHECK_MSG(same, "%s: the buffer on %d threads differs from one thread's", what, threads);
        rtpi_lightbuf_free(&b, &al);
    }
    rtpi_lightbuf_free(&a, &al);
}

/* The item buffer drawn on 2 and 5 threads equals one thread's, cell
   for cell (ids, and depths where there is an id), and so do the thin
   marks. */
static void ib_same(const rtp_scene *s, rtpi_v3 lp, int res, const char *what)
{
    rtpi_itembuf a, b;
    rtp_allocator al;
    size_t k, n = rtpi_scene_nprims(s);
    unsigned char *ta = (unsigned char *)calloc(n + 1, 1), *tb = (unsigned char *)calloc(n + 1, 1);
    int threads;
    rtpi_allocator_init(&al, NULL);
    if (!ta || !tb ||
        rtpi_itembuf_build_wide_mt(s, lp, res, 2.0, ta, 1, NULL, &al, &a, NULL) != RTP_OK) {
        CHECK_MSG(0, "%s: item buffer build failed", what);
        free(ta);
        free(tb);
        return;
    }
    for (threads = 2; threads <= 5; threads += 3) {
        int same;
        if (rtpi_itembuf_build_wide_mt(s, lp, res, 2.0, tb, threads, NULL, &al, &b, NULL) != RTP_OK) {
            CHECK_MSG(0, "%s: item buffer on %d threads failed", what, threads);
            continue;
        }
        same = a.w.ncells == b.w.ncells && memcmp(ta, tb, n) == 0;
        for (k = 0; same && k < a.w.ncells; k++)
            same = a.id[k] == b.id[k] && (a.id[k] == RTPI_NONE || a.z[k] == b.z[k]);
        CHECK_MSG(same, "%s: the item buffer on %d threads differs from one thread's", what,
                  threads);
        rtpi_itembuf_free(&b, &al);
    }
    rtpi_itembuf_free(&a, &al);
    free(ta);
    free(tb);
}

/* From far away a scene looks the same whatever the distance (the
   orthographic limit), so its light buffer's lists should be about as
   long at 1e10 as at 1e4, and it should hold no more entries however far
   the light.  Until session 19 each primitive was widened by 1e-7
   radians (10 units at 1e8) and each window by 1e-6 of the light's
   coordinates: from 1e8 on every cell listed nearly every primitive, and
   moves took 8-16 times as long; since session 19 by 1e-12 radians, and
   from 1e12 on the same happened (a terrain of 8k triangles: 2 GB) until
   session 20: so far that the scene lies within a few widenings, the
   buffer has fewer cells (a finer grid would only list every primitive in
   more of them), and RTP_SHADOWS_AUTO takes shadow rays
   (rtpi_lightbuf_res). */
static void test_lightbuf_far_light_lists(void)
{
    static const double dist[] = {1e4, 1e6, 1e8, 1e10, 1e12, 1e13, 1e14, 1e16, 1e20, 1e30};
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtp_allocator al;
    double base = 0.0;
    size_t k, base_refs = 0;
    CHECK(s != NULL);
    if (!s)
        return;
    rtpi_allocator_init(&al, NULL);
    for (k = 0; k < sizeof dist / sizeof *dist; k++) {
        rtpi_lightbuf lb;
        rtpi_v3 lp = v3_mul(v3_norm(v3(3, -1, 10)), dist[k]);
        double per_cell;
        int useful = rtpi_lightbuf_res(s, lp, 64);
        if (rtpi_lightbuf_build(s, lp, 64, &al, &lb, NULL) != RTP_OK) {
            CHECK_MSG(0, "light buffer at %g failed", dist[k]);
            continue;
        }
        per_cell = (double)lb.nrefs / (double)lb.w.ncells;
        printf("  light at %-6g: %lu candidates, %d cells a face edge, %lu entries, %.2f listed "
               "a cell\n",
               dist[k], (unsigned long)lb.ncand, lb.res, (unsigned long)lb.nrefs, per_cell);
        CHECK(lb.res == useful);
        if (k == 0) {
            base = per_cell;
            base_refs = lb.nrefs;
        } else if (dist[k] <= 1e10) {
            CHECK_MSG(per_cell <= 1.5 * base + 0.01,
                      "light at %g: %.2f candidates a cell, %.2f at 1e4", dist[k], per_cell,
                      base);
        }
        CHECK_MSG(lb.nrefs <= 3 * base_refs, "light at %g: %lu entries, %lu at 1e4",
                  dist[k], (unsigned long)lb.nrefs, (unsigned long)base_refs);
        /* full resolution while it sharpens the lists; shadow rays for
           auto once the scene is within a few widenings */
        if (dist[k] <= 1e10)
            CHECK_MSG(useful == 64, "light at %g: %d cells", dist[k], useful);
        if (dist[k] >= 1e13)
            CHECK_MSG(useful < 16, "light at %g: %d cells", dist[k], useful);
        rtpi_lightbuf_free(&lb, &al);
    }
    rtp_scene_destroy(s);
}

/* A flat mesh seen edge-on from far away: its window is a millionth as
   tall as it is wide, and its rows were far narrower than a widening, so
   every triangle was listed in every row (51,200 triangles, 2048 cells,
   light at 1e8: 1.2 G entries, 5 GB).  Each side of a window is now at
   least res widenings wide; the lists stay exact. */
static void test_lightbuf_edge_on(void)
{
    static const double dist[] = {1e2, 1e6, 1e8, 1e10};
    char *text = (char *)malloc(1 << 20);
    size_t len = 0, k;
    int i, j;
    const int g = 30;
    rtp_scene *s;
    rtpi_kdtree *kd = NULL;
    rtp_allocator al;
    size_t near_refs = 0;
    if (!text)
        return;
    len += (size_t)sprintf(text + len, "v\nfrom 0 -3 2\nat 0 0 0\nup 0 0 1\nangle 40\n"
                                       "resolution 32 32\nl 0 0 5\nf 1 1 1 1 0 1 0 1\n");
    for (j = 0; j < g; j++)
        for (i = 0; i < g; i++) {
            double x0 = -1 + 2.0 * i / g, x1 = -1 + 2.0 * (i + 1) / g;
            double y0 = -1 + 2.0 * j / g, y1 = -1 + 2.0 * (j + 1) / g;
            len += (size_t)sprintf(text + len, "p 3\n%g %g 0\n%g %g 0\n%g %g 0\n", x0, y0, x1,
                                   y0, x1, y1);
            len += (size_t)sprintf(text + len, "p 3\n%g %g 0\n%g %g 0\n%g %g 0\n", x0, y0, x1,
                                   y1, x0, y1);
        }
    /* grains on the floor, low enough to keep the scene flat from afar,
       so that some grazing queries meet an occluder */
    for (i = 0; i < 25; i++)
        len += (size_t)sprintf(text + len, "s %g %g 0.0004 0.0004\n", -0.9 + 0.07 * i,
                               -0.8 + 0.061 * i);
    s = load(text, len);
    free(text);
    CHECK(s != NULL);
    if (!s)
        return;
    rtpi_allocator_init(&al, NULL);
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    for (k = 0; kd && k < sizeof dist / sizeof *dist; k++) {
        rtpi_lightbuf lb;
        rtpi_v3 lp = v3_mul(v3_norm(v3(1, 0.3, 1e-3)), dist[k]);
        static sample sm[2000];
        size_t n, bad, lit = 0;
        if (rtpi_lightbuf_build(s, lp, 512, &al, &lb, NULL) != RTP_OK) {
            CHECK_MSG(0, "light buffer at %g failed", dist[k]);
            continue;
        }
        printf("  edge-on at %-6g: %lu triangles, %lu entries\n", dist[k],
               (unsigned long)s->ntris, (unsigned long)lb.nrefs);
        if (k == 0)
            near_refs = lb.nrefs;
        CHECK_MSG(lb.nrefs <= 2 * near_refs, "edge-on at %g: %lu entries, %lu at 100",
                  dist[k], (unsigned long)lb.nrefs, (unsigned long)near_refs);
        rtpi_lightbuf_free(&lb, &al);
        n = make_samples(s, kd, lp, sm, sizeof sm / sizeof *sm);
        bad = compare(s, kd, lp, RTPI_SHADOW_LIGHTBUF, 512, sm, n, &lit);
        printf("    %lu queries, %lu lit\n", (unsigned long)n, (unsigned long)lit);
        CHECK_MSG(bad == 0, "edge-on at %g: %lu of %lu decisions differ from shadow rays",
                  dist[k], (unsigned long)bad, (unsigned long)n);
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_lightbuf_threads(void)
{
    const char *dir = check_shared_scenes();
    rtp_scene *s = NULL;
    char path[512];
    if (rtp_scene_load_memory(scene_text, sizeof scene_text - 1, "t.nff", "nff", NULL, &s,
                              NULL) == RTP_OK) {
        lb_same(s, v3(2, -2, 6), 128, "test scene");
        ib_same(s, v3(2, -2, 6), 128, "test scene");
        rtp_scene_destroy(s);
        s = NULL;
    }
    if (!dir)
        SKIP("../shared/scenes absent (the test scene alone was built)");
    snprintf(path, sizeof path, "%s/spd/teapot_s3.nff", dir);
    if (rtp_scene_load(path, NULL, &s, NULL) == RTP_OK) {
        lb_same(s, v3(s->lights[0].pos[0] + 0.5, s->lights[0].pos[1], s->lights[0].pos[2]), 256,
                "teapot_s3");
        ib_same(s, v3(s->lights[0].pos[0] + 0.5, s->lights[0].pos[1], s->lights[0].pos[2]), 256,
                "teapot_s3");
        rtp_scene_destroy(s);
    } else {
        CHECK_MSG(0, "cannot load %s", path);
    }
    /* spheres (drawn by a ray per cell) and a polygon */
    snprintf(path, sizeof path, "%s/spd/balls_s2.nff", dir);
    s = NULL;
    if (rtp_scene_load(path, NULL, &s, NULL) == RTP_OK) {
        ib_same(s, v3(s->lights[0].pos[0] + 0.5, s->lights[0].pos[1], s->lights[0].pos[2]), 256,
                "balls_s2");
        rtp_scene_destroy(s);
    } else {
        CHECK_MSG(0, "cannot load %s", path);
    }
}

/* lb_build_paths's buffer a against b: cells, entries, candidates and
   planes bit for bit. */
static int lb_equal(const rtpi_lightbuf *a, const rtpi_lightbuf *b)
{
    size_t k;
    int same = a->res == b->res && a->w.ncells == b->w.ncells && a->nrefs == b->nrefs &&
               a->ncand == b->ncand &&
               memcmp(a->off, b->off, (a->w.ncells + 1) * sizeof *a->off) == 0 &&
               memcmp(a->ref, b->ref, a->nrefs * sizeof *a->ref) == 0 &&
               !a->plane == !b->plane &&
               (!a->plane || memcmp(a->plane, b->plane, 5 * a->ncand * sizeof *a->plane) == 0);
    for (k = 0; same && k < a->ncand; k++) /* (field by field: padding) */
        same = a->cand[k].prim == b->cand[k].prim && a->cand[k].near == b->cand[k].near;
    return same;
}

/* The light buffer's build reads the primitives' bounds from the scene's
   kept ones where rtpi_scene_bounds made them (dc_near, dc_scale), else
   makes them: the same lists either way; and each triangle's plane entry,
   made turned to the light's side as it is stored (lb_plane_turned), is
   the exact mode's plane (rtpi_tri_planes: n and n.p0 turned, t added to
   n.p0) entry for entry.  Lights above, at the cube's corners, low inside
   the scene's bounds and between its objects (faces reached near their
   edges). */
static void lb_build_paths(rtp_scene *s, const char *what)
{
    rtp_allocator al;
    size_t i, r;
    rtpi_allocator_init(&al, NULL);
    for (i = 0; i < sizeof lights / sizeof *lights; i++) {
        rtpi_v3 lp = v3(lights[i].pos[0], lights[i].pos[1], lights[i].pos[2]);
        rtpi_lightbuf a, b;
        double *tp = NULL, scale;
        int res;
        for (res = 16; res <= 256; res *= 4) {
            /* without kept bounds first (the scene as loaded), then with */
            rtpi_free(&s->alloc, s->pbounds);
            rtpi_free(&s->alloc, s->phit);
            s->pbounds = NULL;
            s->phit = NULL;
            s->npbounds = 0;
            if (rtpi_lightbuf_build(s, lp, res, &al, &a, NULL) != RTP_OK) {
                CHECK_MSG(0, "%s, %s: build failed", what, lights[i].name);
                return;
            }
            CHECK(rtpi_scene_bounds(s) == 0);
            if (rtpi_lightbuf_build(s, lp, res, &al, &b, NULL) != RTP_OK) {
                CHECK_MSG(0, "%s, %s: build with kept bounds failed", what, lights[i].name);
                rtpi_lightbuf_free(&a, &al);
                return;
            }
            CHECK_MSG(lb_equal(&a, &b), "%s, %s, %d cells: the buffer with kept bounds differs",
                      what, lights[i].name, res);
            if (res == 16 && rtpi_tri_planes(s, lp, &al, &tp, &scale, NULL) == RTP_OK && tp) {
                size_t bad = 0;
                CHECK(b.scale == scale);
                for (r = 0; r < b.ncand; r++) {
                    uint32_t p = b.cand[r].prim;
                    const double *q = b.plane + 5 * r, *o = tp + 4 * (size_t)p;
                    if (p >= s->ntris)
                        continue;
                    if (q[4] == HUGE_VAL)
                        bad += !(q[0] == 0.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0 &&
                                 o[3] == HUGE_VAL);
                    else
                        bad += !(q[4] > 0.0 && q[0] == o[0] && q[1] == o[1] && q[2] == o[2] &&
                                 q[3] + q[4] == o[3]);
                }
                CHECK_MSG(bad == 0, "%s, %s: %lu plane entries differ from the exact mode's", what,
                          lights[i].name, (unsigned long)bad);
            }
            rtpi_free(&al, tp);
            tp = NULL;
            rtpi_lightbuf_free(&a, &al);
            rtpi_lightbuf_free(&b, &al);
        }
    }
}

static void test_lightbuf_build_paths(void)
{
    const char *dir = check_shared_scenes();
    rtp_scene *s = NULL;
    char path[512];
    if (rtp_scene_load_memory(scene_text, sizeof scene_text - 1, "t.nff", "nff", NULL, &s,
                              NULL) == RTP_OK) {
        lb_build_paths(s, "test scene");
        rtp_scene_destroy(s);
        s = NULL;
    } else {
        CHECK_MSG(0, "cannot load the test scene");
    }
    if (!dir)
        SKIP("../shared/scenes absent (the test scene alone was built)");
    snprintf(path, sizeof path, "%s/spd/gears_s2.nff", dir);
    if (rtp_scene_load(path, NULL, &s, NULL) == RTP_OK) {
        lb_build_paths(s, "gears_s2");
        rtp_scene_destroy(s);
    } else {
        CHECK_MSG(0, "cannot load %s", path);
    }
}

/* Edges, corners and zero components map to a cell on a face that
   touches the direction; the cell's face coordinates hold it. */
static void test_cell_mapping(void)
{
    static const double dirs[][3] = {
        {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1},
        {1, 1, 0}, {1, -1, 0}, {-1, 1, 1}, {1, 1, 1}, {-1, -1, -1}, {0, -0.0, 1},
        {-0.0, 0, -0.0001}, {1e-300, 1e-300, -1e-300}, {3, 3, -3}, {0.5, -0.5, 0.5}};
    int res = 8, k;
    for (k = 0; k < (int)(sizeof dirs / sizeof *dirs); k++) {
        rtpi_v3 d = v3(dirs[k][0], dirs[k][1], dirs[k][2]);
        size_t c = rtpi_dc_cell(res, d);
        int f = (int)(c / 64), a = f >> 1;
        double z = v3_get(d, a) * ((f & 1) ? -1 : 1);
        CHECK(c < 6 * 64);
        /* the face's axis is a largest component, with the right sign */
        CHECK(z > 0.0);
        CHECK(z >= fabs(d.x) && z >= fabs(d.y) && z >= fabs(d.z));
        CHECK(rtpi_dc_depth(f, d) == z);
    }
    /* +x+y+z corner: ties go to x; u = y/x = 1 -> last column, last row */
    CHECK(rtpi_dc_cell(res, v3(1, 1, 1)) == (size_t)((0 * res + 7) * res + 7));
    CHECK(rtpi_dc_cell(res, v3(-1, -1, -1)) == (size_t)((1 * res + 0) * res + 0));
    CHECK(rtpi_dc_cell(res, v3(0, 0, 1)) == (size_t)((4 * res + 4) * res + 4));
    /* NaN lands somewhere valid */
    CHECK(rtpi_dc_cell(res, v3(NAN, 1, 0)) < 6 * 64);
}

typedef struct counting {
    long calls, fail_at, live;
} counting;

static void *c_malloc(void *u, size_t n)
{
    counting *c = (counting *)u;
    if (c->calls++ == c->fail_at)
        return NULL;
    c->live++;
    return malloc(n);
}
static void *c_realloc(void *u, void *p, size_t n)
{
    counting *c = (counting *)u;
    void *q;
    if (c->calls++ == c->fail_at)
        return NULL;
    q = realloc(p, n);
    if (q && !p)
        c->live++;
    return q;
}
static void c_free(void *u, void *p)
{
    counting *c = (counting *)u;
    if (p)
        c->live--;
    free(p);
}

/* 1 where some cone of s is a cylinder (sh_lb_quadrics makes its
   numbers) */
static int has_cyl(const rtp_scene *s)
{
    size_t i;
    for (i = 0; i < s->ncones; i++)
        if (s->cframes[i].ok && s->cframes[i].ra == s->cframes[i].rb)
            return 1;
    return 0;
}

/* Every allocation failing in turn: NOMEM, nothing leaked. */
/* Creates the shadow structures of mode with allocation k failed, for k
   = 0, 1, ... until one succeeds (at most max tries): each failure must
   be RTP_ERR_NOMEM with nothing left allocated, the success must free
   all it took.  Returns the bad outcomes; *sites the allocations. */
static int fail_each(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp, rtpi_shadow_mode mode,
                     int res, int threads, long max, long *sites)
{
    counting c;
    rtp_allocator a;
    long fail;
    int bad = 0, spared = 0;
    a.malloc_fn = c_malloc;
    a.realloc_fn = c_realloc;
    a.free_fn = c_free;
    a.user = &c;
    for (fail = 0; fail < max; fail++) {
        rtpi_shadow *sh = NULL;
        rtp_status st;
        c.calls = 0;
        c.live = 0;
        c.fail_at = fail;
        st = rtpi_shadow_create_mt(s, kd, lp, mode, res, threads, HUGE_VAL, HUGE_VAL, NULL, &a, &sh,
                                   NULL);
        if (c.calls <= fail) {
            bad += st != RTP_OK;
            rtpi_shadow_destroy(sh);
            bad += c.live != 0;
            break;
        }
        if (st == RTP_OK && sh) {
            /* speed-ups are left out where their memory cannot be had,
               the move going on: EXACT's triangles' edges and spheres'
               and cylinders' numbers (rtpi_tri_edges, rtpi_sphere_entries,
               rtpi_cyl_entries), one site each, and a light buffer's
               cones' bands (lb_slabs), two a light buffer with cone
               entries and cones (the item buffer's thin and wide ones:
               four at most); a light buffer's spheres' and
               cylinders' numbers for its cached occluder
               (sh_lb_quadrics: spheres where they outnumber the cones,
               cylinders where a cone is one), one site each */
            spared++;
            rtpi_shadow_destroy(sh);
            bad += c.live != 0;
            continue;
        }
        bad += st != RTP_ERR_NOMEM || sh != NULL || c.live != 0;
    }
    *sites = fail;
    return bad + (fail == max) +
           (mode == RTPI_SHADOW_EXACT
                ? spared != (s->ntris ? 1 : 0) + (s->nspheres ? 1 : 0) + (s->ncones ? 1 : 0)
            : mode == RTPI_SHADOW_LIGHTBUF
                ? spared != (s->ncones ? 2 : 0) + (s->nspheres > s->ncones ? 1 : 0) + has_cyl(s)
                                           : spared > (s->ncones ? 4 : 0));
}

static void test_alloc_failures(void)
{
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtpi_kdtree *kd = NULL;
    static const rtpi_shadow_mode modes[] = {RTPI_SHADOW_EXACT, RTPI_SHADOW_LIGHTBUF,
                                             RTPI_SHADOW_ITEMBUF};
    char *text;
    size_t len;
    long sites;
    int m, k, bad = 0;
    if (!s || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    for (m = 0; m < 3; m++)
        bad += fail_each(s, kd, v3(1, 2, 3), modes[m], 32, 1, 100, &sites);
    CHECK_MSG(bad == 0, "%d bad outcomes", bad);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    /* a light buffer projected on 3 threads (enough primitives to be
       split: 600 spheres), each allocation failed in turn, the threads'
       ones through the lock */
    text = (char *)malloc(600 * 48 + 256);
    if (!text) {
        CHECK(0);
        return;
    }
    len = (size_t)sprintf(text, "v\nfrom 0 -30 10\nat 0 0 0\nup 0 0 1\nangle 40\n"
                                "resolution 8 8\nl 1 -2 20\nf 1 1 1 1 0 0 0 1\n");
    for (k = 0; k < 600; k++)
        len += (size_t)sprintf(text + len, "s %d %d %d 0.3\n", k % 10 - 5, k / 10 % 10 - 5,
                               k / 100);
    s = load(text, len);
    free(text);
    if (!s) {
        CHECK(0);
        return;
    }
    bad = fail_each(s, NULL, v3(1, -2, 20), RTPI_SHADOW_LIGHTBUF, 64, 3, 400, &sites);
    CHECK_MSG(bad == 0, "3 threads: %d bad outcomes (%ld sites)", bad, sites);
    rtp_scene_destroy(s);
}

static void test_bad_arguments(void)
{
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtpi_shadow *sh = NULL;
    rtp_allocator a;
    rtpi_allocator_init(&a, NULL);
    if (!s) {
        CHECK(0);
        return;
    }
    CHECK(rtpi_shadow_create(s, NULL, v3(0, 0, 5), RTPI_SHADOW_ITEMBUF, -3, &a, &sh, NULL) == RTP_OK);
    rtpi_shadow_destroy(sh);
    CHECK(rtpi_shadow_create(s, NULL, v3(0, 0, 5), RTPI_SHADOW_ITEMBUF, 100000, &a, &sh, NULL) ==
          RTP_ERR_ARGUMENT);
    CHECK(sh == NULL);
    CHECK(rtpi_shadow_create(s, NULL, v3(0, 0, 5), RTPI_SHADOW_EXACT, 0, &a, &sh, NULL) ==
          RTP_ERR_ARGUMENT);
    CHECK(rtpi_shadow_create(s, NULL, v3(0, 0, 5), (rtpi_shadow_mode)9, 0, &a, &sh, NULL) ==
          RTP_ERR_ARGUMENT);
    rtpi_shadow_destroy(NULL);
    rtp_scene_destroy(s);
}

/* OSMesa draws the same item buffer as the software z-buffer. */
/* Whether a light buffer fits a memory limit does not depend on the
   threads that count its runs: a share of the limit each, checked on
   their doubled blocks, refused with two threads (at 6-10x the lists'
   need) what one thread built. */
static void test_lightbuf_limit_threads(void)
{
    static char text[400000];
    size_t len = 0;
    unsigned st = 12345;
    int i, thr, j, ok[3];
    rtp_scene *s;
    len += (size_t)sprintf(text + len, "v\nfrom 0 -9 6\nat 0 0 0\nup 0 0 1\nangle 50\n"
                                       "hither 0.01\nresolution 8 8\nl 0 0 10\n"
                                       "f 1 1 1 1 0 0 0 1\n");
    /* slivers near the light first (the first part's ranks: most runs),
       then small triangles far below */
    for (i = 0; i < 600; i++) {
        double x = -4 + 8.0 * i / 600;
        len += (size_t)sprintf(text + len, "p 3\n%g -4 5\n%g -4 5\n%g 4 5\n", x, x + 0.0005, x);
    }
    for (i = 0; i < 1200; i++) {
        double x, y;
        st = st * 1103515245u + 12345u;
        x = ((st >> 8) % 10000) / 1000.0 - 5;
        st = st * 1103515245u + 12345u;
        y = ((st >> 8) % 10000) / 1000.0 - 5;
        len += (size_t)sprintf(text + len, "p 3\n%g %g 0\n%g %g 0\n%g %g 0\n", x, y, x + 0.001,
                               y, x, y + 0.001);
    }
    s = load(text, len);
    if (!s || rtpi_scene_bounds(s) != 0) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    for (j = 0; j < 16; j++) {
        double lim = 1048576.0 * pow(2.0, j / 3.0); /* 1 .. 32 MiB */
        for (thr = 1; thr <= 4; thr *= 2) {
            rtp_allocator a;
            rtpi_lightbuf lb;
            rtp_error err;
            int k = thr == 1 ? 0 : thr == 2 ? 1 : 2;
            rtpi_allocator_init(&a, NULL);
            ok[k] = rtpi_lightbuf_build_some(s, v3(0, 0, 10), 256, NULL, 0, thr, lim, HUGE_VAL, NULL, &a, &lb,
                                             &err) == RTP_OK;
            if (ok[k])
                rtpi_lightbuf_free(&lb, &a);
        }
        CHECK_MSG(ok[0] == ok[1] && ok[0] == ok[2],
                  "limit %.0f: built with 1, 2, 4 threads: %d %d %d", lim, ok[0], ok[1], ok[2]);
    }
    CHECK(ok[0]); /* (32 MiB is enough) */
    rtp_scene_destroy(s);
}

/* A light at a pointed cone's tip: the cone's quadratic about its middle
   gave a line passing within ~2e-8 of the tip its mirror image's root, so
   a trace shadowed speckles of the floor (7.8% of pixels 0.36 off the
   trace with the light 1e-5 higher) and the light buffer, which lists
   what can really be hit, disagreed with it (auto and lightbuf 7.4%
   of pixels).  Now the trace is smooth in the light's place and every
   exact mode equals it, the light at the tip or within 1e-12..1e-7 of
   it. */
static void test_light_at_cone_tip(void)
{
    static const char text[] =
        "v\nfrom 0 -6 5\nat 0 0 0.5\nup 0 0 1\nangle 55\nhither 0.01\nresolution 48 48\n"
        "l 2 -2 4\n"
        "f 0.8 0.6 0.4 0.8 0.2 20 0 1\n"
        "p 4\n-6 -6 -0.5\n6 -6 -0.5\n6 6 -0.5\n-6 6 -0.5\n"
        "f 0.9 0.9 0.9 0.1 0.1 30 0.7 1.3\n"
        "c 2 0 0.38 0.1 1 -1 1.63 0\n";
    static const rtp_shadow_mode modes[] = {RTP_SHADOWS_LIGHTBUF, RTP_SHADOWS_AUTO,
                                            RTP_SHADOWS_EXACT};
    rtp_scene *s = load(text, sizeof text - 1);
    rtp_tree *t = NULL;
    rtp_image *a = NULL, *b = NULL;
    rtp_trace_options o;
    rtp_eval_options eo;
    rtp_diff_stats d;
    rtp_error err;
    int k;
    size_t m;
    if (!s) {
        CHECK(0);
        return;
    }
    memset(&o, 0, sizeof o);
    CHECK(rtp_record(s, &o, &t, NULL, NULL, &err) == RTP_OK);
    /* the trace itself: the light at the tip and 1e-5 above it */
    CHECK(rtp_scene_set(s, "light.0.pos", "1,-1,1.63", &err) == RTP_OK);
    CHECK(rtp_trace(s, &o, &a, NULL, &err) == RTP_OK);
    CHECK(rtp_scene_set(s, "light.0.pos", "1,-1,1.63001", &err) == RTP_OK);
    CHECK(rtp_trace(s, &o, &b, NULL, &err) == RTP_OK);
    CHECK(a && b && rtp_image_diff(a, b, 0.0, &d, NULL) == RTP_OK);
    CHECK_MSG(d.max_abs < 1e-4, "the light at the tip and 1e-5 above: %g apart", d.max_abs);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    for (k = 0; k < 6 && t; k++) {
        /* at the tip, then 1e-12 .. 1e-7 from it in a direction of its own */
        double e = k ? pow(10.0, -12.0 + k) : 0.0;
        char pos[96];
        snprintf(pos, sizeof pos, "%.17g,%.17g,%.17g", 1.0 + 0.6 * e, -1.0 - 0.48 * e,
                 1.63 + (k % 2 ? 0.64 : -0.64) * e);
        CHECK(rtp_tree_set(t, "light.0.pos", pos, &err) == RTP_OK);
        CHECK(rtp_tree_trace(t, 1, &b, NULL, &err) == RTP_OK);
        for (m = 0; m < sizeof modes / sizeof *modes; m++) {
            memset(&eo, 0, sizeof eo);
            eo.shadows = modes[m];
            a = NULL;
            CHECK(rtp_tree_eval(t, &eo, &a, NULL, &err) == RTP_OK);
            CHECK(a && b && rtp_image_diff(a, b, 0.0, &d, NULL) == RTP_OK);
            CHECK_MSG(d.max_abs <= 1e-6, "light %s, mode %d: %g off a full trace", pos,
                      (int)modes[m], d.max_abs);
            rtp_image_destroy(a);
        }
        rtp_image_destroy(b);
        b = NULL;
    }
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

static void test_osmesa(void)
{
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtp_allocator a;
    rtpi_itembuf sw, gl;
    rtp_error err;
    size_t li;
    rtpi_allocator_init(&a, NULL);
    if (!s) {
        CHECK(0);
        return;
    }
    memset(&err, 0, sizeof err);
    /* (rtp_features says the same as the backend does) */
    CHECK(!(rtp_features() & RTP_FEATURE_OSMESA) ==
          (rtpi_itembuf_build_osmesa(s, v3(2, -2, 6), 16, &a, &gl, &err) == RTP_ERR_UNSUPPORTED));
    if (rtp_features() & RTP_FEATURE_OSMESA)
        rtpi_itembuf_free(&gl, &a);
    if (rtpi_itembuf_build_osmesa(s, v3(2, -2, 6), 64, &a, &gl, &err) == RTP_ERR_UNSUPPORTED) {
        char buf[256];
        rtpi_shadow *sh = NULL;
        CHECK(strstr(rtp_error_format(&err, buf, sizeof buf), "OSMESA=1") != NULL);
        CHECK(rtpi_shadow_create(s, NULL, v3(2, -2, 6), RTPI_SHADOW_OSMESA, 0, &a, &sh, NULL) ==
              RTP_ERR_UNSUPPORTED);
        CHECK(sh == NULL);
        rtp_scene_destroy(s);
        SKIP("not built with OSMESA=1");
    }
    rtpi_itembuf_free(&gl, &a);
    {
        /* its decisions against the kd-tree's, as for the software one */
        rtpi_kdtree *kd = NULL;
        sample *sm = (sample *)malloc(NSAMPLES * sizeof *sm);
        if (sm && rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK) {
            for (li = 0; li < NLIGHTS; li++) {
                rtpi_v3 lp = v3(lights[li].pos[0], lights[li].pos[1], lights[li].pos[2]);
                size_t n = make_samples(s, kd, lp, sm, NSAMPLES / 3);
                size_t bad = compare(s, kd, lp, RTPI_SHADOW_OSMESA, 1024, sm, n, NULL);
                printf("  osmesa light %-30s %6lu points: wrong %.3f%%\n", lights[li].name,
                       (unsigned long)n, 100.0 * (double)bad / (double)(n ? n : 1));
                CHECK((double)bad < 0.01 * (double)n);
            }
        } else {
            CHECK(0);
        }
        rtpi_kd_destroy(kd);
        free(sm);
    }
    for (li = 0; li < NLIGHTS; li++) {
        rtpi_v3 lp = v3(lights[li].pos[0], lights[li].pos[1], lights[li].pos[2]);
        size_t k, same = 0, ncells;
        if (rtpi_itembuf_build(s, lp, 1024, &a, &sw, NULL) != RTP_OK) {
            CHECK(0);
            continue;
        }
        if (rtpi_itembuf_build_osmesa(s, lp, 1024, &a, &gl, &err) != RTP_OK) {
            char buf[256];
            CHECK_MSG(0, "%s", rtp_error_format(&err, buf, sizeof buf));
            rtpi_itembuf_free(&sw, &a);
            continue;
        }
        ncells = sw.w.ncells;
        CHECK(gl.w.ncells == ncells);
        for (k = 0; k < ncells && gl.w.ncells == ncells; k++)
            same += sw.id[k] == gl.id[k];
        printf("  osmesa light %-30s cells agreeing with the software z-buffer: %.4f%%\n",
               lights[li].name, 100.0 * (double)same / (double)ncells);
        CHECK((double)same >= 0.999 * (double)ncells);
        rtpi_itembuf_free(&sw, &a);
        rtpi_itembuf_free(&gl, &a);
    }
    /* Far lights: OpenGL's depths were floats at the light's distance
       (0.125 apart at 1e6) and its far plane at twice it, so primitives
       close in depth swapped: 99.16-99.86% of the SPD scenes' cells at
       (1e6, 1e6, 1e6).  Now at >= 99.9% of the cells holding one. */
    for (li = 0; li < 2; li++) {
        const double d = li ? 1e7 : 1e6;
        rtpi_v3 lp = v3(0.7 * d, -0.5 * d, d);
        size_t k, held = 0, same = 0;
        if (rtpi_itembuf_build(s, lp, 512, &a, &sw, NULL) != RTP_OK) {
            CHECK(0);
            continue;
        }
        if (rtpi_itembuf_build_osmesa(s, lp, 512, &a, &gl, &err) != RTP_OK) {
            CHECK(0);
            rtpi_itembuf_free(&sw, &a);
            continue;
        }
        for (k = 0; k < sw.w.ncells && gl.w.ncells == sw.w.ncells; k++)
            if (sw.id[k] != RTPI_NONE || gl.id[k] != RTPI_NONE) {
                held++;
                same += sw.id[k] == gl.id[k];
            }
        printf("  osmesa light at %g: %lu cells hold a primitive, %.4f%% agree\n", d,
               (unsigned long)held, 100.0 * (double)same / (double)(held ? held : 1));
        CHECK(held > 1000 && (double)same >= 0.999 * (double)held);
        rtpi_itembuf_free(&sw, &a);
        rtpi_itembuf_free(&gl, &a);
    }
    rtp_scene_destroy(s);
}

/* Curved primitives in OpenGL: a lattice of chains like SPD's rings
   (spheres joined by cylinders of their own radius, tangent along a
   circle), and cones of two radii.  At 256 cells their outlines and
   joints are a large share of the cells holding a primitive; OSMesa's
   polygons must land where the exact software buffer does at >= 99.75%
   of those (measured: 99.86-99.93%; 99.97-99.98% of all cells).
   Polygons inscribed at even angles, before the outlines were made
   vertices and the rest set to straddle the surfaces, gave 99.53-99.81%
   of those cells.  What stays is mostly joints: where a cylinder is
   tangent to its sphere, or two cylinders cross inside one, the
   surfaces lie within the polygons' error of each other. */
static void test_osmesa_curved(void)
{
    static const double lp[][3] = {{7, -5, 9}, {-3, 2, 8}, {0.5, -9, 1.5}};
    char *text = (char *)malloc(65536), *p;
    rtp_scene *s;
    rtp_allocator a;
    rtpi_itembuf sw, gl;
    size_t li;
    int i, j;
    if (!text) {
        CHECK(0);
        return;
    }
    p = text;
    p += sprintf(p, "v\nfrom 0 -9 4\nat 0 0 0\nup 0 0 1\nangle 40\nhither 0.01\n"
                    "resolution 8 8\nl 7 -5 9\nf 0.8 0.5 0.3 0.7 0.3 20 0 1\n");
    for (j = 0; j < 8; j++)
        for (i = 0; i < 8; i++) {
            double x = -3.5 + i, y = -3.5 + j, z = 0.3 * ((i + j) % 3), r = 0.06 + 0.01 * (i % 3);
            p += sprintf(p, "s %g %g %g %g\n", x, y, z, r);
            if (i < 7)
                p += sprintf(p, "c %g %g %g %g %g %g %g %g\n", x, y, z, r, x + 1, y,
                             0.3 * ((i + 1 + j) % 3), r);
            if (j < 7)
                p += sprintf(p, "c %g %g %g %g %g %g %g %g\n", x, y, z, r, x, y + 1,
                             0.3 * ((i + j + 1) % 3), r);
            /* a cone of two radii standing over every other joint */
            if ((i + j) % 2 == 0)
                p += sprintf(p, "c %g %g %g %g %g %g %g %g\n", x + 0.5, y + 0.5, z, 0.12,
                             x + 0.6, y + 0.4, z + 1.2, 0.03);
        }
    s = load(text, (size_t)(p - text));
    free(text);
    if (!s) {
        CHECK(0);
        return;
    }
    rtpi_allocator_init(&a, NULL);
    if (rtpi_itembuf_build_osmesa(s, v3(0, 0, 9), 8, &a, &gl, NULL) == RTP_ERR_UNSUPPORTED) {
        rtp_scene_destroy(s);
        SKIP("not built with OSMESA=1");
    }
    rtpi_itembuf_free(&gl, &a);
    for (li = 0; li < sizeof lp / sizeof *lp; li++) {
        rtpi_v3 L = v3(lp[li][0], lp[li][1], lp[li][2]);
        size_t k, curved = 0, differ = 0;
        if (rtpi_itembuf_build(s, L, 256, &a, &sw, NULL) != RTP_OK) {
            CHECK(0);
            continue;
        }
        if (rtpi_itembuf_build_osmesa(s, L, 256, &a, &gl, NULL) != RTP_OK) {
            CHECK(0);
            rtpi_itembuf_free(&sw, &a);
            continue;
        }
        CHECK(gl.w.ncells == sw.w.ncells);
        for (k = 0; k < sw.w.ncells && gl.w.ncells == sw.w.ncells; k++) {
            curved += sw.id[k] != RTPI_NONE || gl.id[k] != RTPI_NONE;
            differ += sw.id[k] != gl.id[k];
        }
        printf("  osmesa curved, light (%g, %g, %g): %lu cells hold a primitive, "
               "%.4f%% of them agree\n",
               lp[li][0], lp[li][1], lp[li][2], (unsigned long)curved,
               100.0 - 100.0 * (double)differ / (double)(curved ? curved : 1));
        CHECK(curved > 10000);
        CHECK((double)differ <= 0.0025 * (double)curved);
        rtpi_itembuf_free(&sw, &a);
        rtpi_itembuf_free(&gl, &a);
    }
    rtp_scene_destroy(s);
}

/* rtpi_stopper: the calling thread's polls call progress and cancel at
   most STOPPER_REPORTS (250) times a build however often it is asked (an
   item buffer asked every 256 of a million triangles had called them
   4,000 times, against a step's "about a thousand"), its progress only
   forward and within [lo, lo + span]; a yes stops every thread's rows. */
typedef struct stop_count {
    long progress, cancel, at;
    double last, lo, hi;
    int back;
} stop_count;

static void sc_progress(void *user, double done)
{
    stop_count *c = (stop_count *)user;
    c->back |= done < c->last || done < c->lo || done > c->hi;
    c->last = done;
    c->progress++;
}

static int sc_cancel(void *user)
{
    stop_count *c = (stop_count *)user;
    return ++c->cancel == c->at;
}

static void test_stopper_reports(void)
{
    stop_count c;
    rtpi_poll p;
    rtpi_stopper st;
    long i, n = 1000000;
    memset(&c, 0, sizeof c);
    c.lo = 0.2;
    c.hi = 0.7;
    p.progress = sc_progress;
    p.cancel = sc_cancel;
    p.user = &c;
    CHECK(rtpi_stopper_init(&st, &p, 0.2, 0.5) == 0);
    for (i = 0; i <= n; i++)
        CHECK(rtpi_stopper_poll(&st, 1, (double)i / (double)n) == 0);
    /* (another thread's polls call nothing) */
    CHECK(rtpi_stopper_poll(&st, 0, 0.5) == 0);
    CHECK_MSG(c.progress >= 100 && c.progress <= 126 && c.cancel == c.progress && !c.back,
              "%ld progress and %ld cancel calls for a million polls over half a build",
              c.progress, c.cancel);
    rtpi_stopper_destroy(&st);
    /* a yes at the fifth question: every later poll, any thread's, stops */
    memset(&c, 0, sizeof c);
    c.at = 5;
    c.hi = 1.0;
    CHECK(rtpi_stopper_init(&st, &p, 0.0, 1.0) == 0);
    for (i = 0; i < 10000 && !rtpi_stopper_poll(&st, 1, (double)i / 10000.0); i++)
        ;
    CHECK(c.cancel == 5 && rtpi_stopper_poll(&st, 0, 0.9) == 1);
    rtpi_stopper_destroy(&st);
}

/* EXACT's cache (rtpi_shadow_visible_cached): the occluders met before
   the last one are asked too (sh_earlier), which changes no answer.  A
   row crossing the shadows of two squares A and B by turns: after A then
   B, a point in A's shadow is answered by A, the one before the last
   (its score goes up: it was asked and hit); random points in random
   order answer as uncached queries, and so do points where the earlier
   occluders are the point's own primitive. */
static void test_exact_cache_earlier(void)
{
    static const char text[] =
        "v\nfrom 0 -9 4\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\nresolution 8 8\n"
        "l 0 0 6\nf 0.8 0.8 0.8 1 0 0 0 1\n"
        "p 4\n-5 -5 0\n5 -5 0\n5 5 0\n-5 5 0\n"
        "p 4\n-2 -0.5 2\n-1 -0.5 2\n-1 0.5 2\n-2 0.5 2\n"
        "p 4\n1 -0.5 2\n2 -0.5 2\n2 0.5 2\n1 0.5 2\n";
    static const double row[] = {-2.2, 2.2, -2.3, 2.3, -2.4, 0.0, 2.4, -2.5};
    rtp_scene *s = load(text, sizeof text - 1);
    rtpi_kdtree *kd = NULL;
    rtpi_shadow *sh = NULL;
    rtp_allocator a;
    rtpi_shadow_cache c = {0}, c2 = {0};
    rtpi_v3 lp = v3(0, 0, 6);
    sample *sm = (sample *)malloc(NSAMPLES * sizeof *sm);
    size_t k, n, bad = 0;
    rtpi_allocator_init(&a, NULL);
    CHECK(s != NULL && sm != NULL);
    if (!s || !sm || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK ||
        rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &sh, NULL) != RTP_OK) {
        CHECK(0);
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
        free(sm);
        return;
    }
    for (k = 0; k < sizeof row / sizeof *row; k++) {
        /* the floor's point under (row[k], 0.1), as trace would ask it */
        rtpi_ray r;
        rtpi_hit h;
        rtpi_v3 p, o;
        int e, v;
        r.o = v3(row[k], 0.1, -1.0);
        r.d = v3(0, 0, 1);
        r.tmin = 0.0;
        r.tmax = HUGE_VAL;
        CHECK(rtpi_kd_intersect(kd, &r, &h) && h.prim < 2);
        CHECK(rtpi_shadow_query_at(s, 0, h.prim, v3_madd(r.o, r.d, h.t), v3(0, 0, -1), lp,
                                   rtpi_offset_floor(s, NULL), &p, &o));
        e = rtpi_shadow_visible(sh, p, o, h.prim);
        v = rtpi_shadow_visible_cached(sh, &c, &p, &o, h.prim);
        CHECK_MSG(e == (row[k] == 0.0), "point %lu (x %g): lit %d", (unsigned long)k, row[k], e);
        CHECK_MSG(v == e, "point %lu (x %g): cached %d, uncached %d", (unsigned long)k, row[k],
                  v, e);
        if (k == 2) /* A, B, then A: asked as the one before the last, and hit */
            CHECK_MSG(c.gain > 0 && c.last == c.h1 && c.h2 != 0 && c.h1 != c.h2,
                      "after A, B, A: gain %d, last %u, h1 %u, h2 %u", c.gain,
                      (unsigned)c.last, (unsigned)c.h1, (unsigned)c.h2);
    }
    /* random points in random order, and the first scene's */
    n = make_samples(s, kd, lp, sm, NSAMPLES);
    CHECK(n > NSAMPLES / 4);
    for (k = 0; k < n; k++)
        bad += rtpi_shadow_visible_cached(sh, &c, &sm[k].p, &sm[k].o, sm[k].prim) !=
               rtpi_shadow_visible(sh, sm[k].p, sm[k].o, sm[k].prim);
    CHECK_MSG(bad == 0, "%lu of %lu cached answers differ", (unsigned long)bad, (unsigned long)n);
    rtpi_shadow_destroy(sh);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    s = load(scene_text, sizeof scene_text - 1);
    kd = NULL;
    sh = NULL;
    CHECK(s != NULL);
    if (!s || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        free(sm);
        return;
    }
    for (k = 0; k < NLIGHTS; k++) {
        size_t j;
        lp = v3(lights[k].pos[0], lights[k].pos[1], lights[k].pos[2]);
        if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &sh, NULL) != RTP_OK) {
            CHECK(0);
            break;
        }
        n = make_samples(s, kd, lp, sm, 4000);
        bad = 0;
        /* each point twice, the second time after the cache met its own
           primitive in the way of another point */
        for (j = 0; j < n; j++) {
            int e = rtpi_shadow_visible(sh, sm[j].p, sm[j].o, sm[j].prim);
            bad += rtpi_shadow_visible_cached(sh, &c2, &sm[j].p, &sm[j].o, sm[j].prim) != e;
            bad += rtpi_shadow_visible_cached(sh, &c2, &sm[j].p, &sm[j].o, sm[j].prim) != e;
        }
        CHECK_MSG(bad == 0, "light %s: %lu cached answers differ", lights[k].name,
                  (unsigned long)bad);
        rtpi_shadow_destroy(sh);
        sh = NULL;
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    free(sm);
}

/* A mesh scene of random triangles: a fan sharing edges and vertices, a
   ground of two triangles, slivers and small tilted ones; each coordinate
   scaled by sc and moved by off (far from the origin). */
static rtp_scene *edge_scene(double off, double sc)
{
    char *t = (char *)malloc(64 * 1024);
    size_t n = 0;
    int k;
    rtp_scene *s;
#define EP(x, y, z) n += (size_t)sprintf(t + n, "%.17g %.17g %.17g\n", off + sc * (x), off + sc * (y), \
                                         off + sc * (z))
    if (!t)
        return NULL;
    n += (size_t)sprintf(t + n, "v\nfrom 0 -9 4\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\n"
                                "resolution 16 16\nl 0 0 9\nf 0.8 0.8 0.8 1 0 0 0 1\n");
    n += (size_t)sprintf(t + n, "p 3\n");
    EP(-5, -5, 0);
    EP(5, -5, 0);
    EP(5, 5, 0);
    n += (size_t)sprintf(t + n, "p 3\n");
    EP(-5, -5, 0);
    EP(5, 5, 0);
    EP(-5, 5, 0);
    for (k = 0; k < 12; k++) { /* a fan around (0, 0, 2): shared edges */
        double a0 = 6.283185307179586 * k / 12, a1 = 6.283185307179586 * (k + 1) / 12;
        n += (size_t)sprintf(t + n, "p 3\n");
        EP(0, 0, 2);
        EP(1.5 * cos(a0), 1.5 * sin(a0), 2 + 0.3 * sin(3 * a0));
        EP(1.5 * cos(a1), 1.5 * sin(a1), 2 + 0.3 * sin(3 * a1));
    }
    for (k = 0; k < 40; k++) { /* small, tilted, some slivers */
        double x = 8 * (rnd() - 0.5), y = 8 * (rnd() - 0.5), z = 0.2 + 3 * rnd();
        double w = k % 4 == 0 ? 1e-3 : 0.6;
        n += (size_t)sprintf(t + n, "p 3\n");
        EP(x, y, z);
        EP(x + 0.8 * (rnd() - 0.5), y + 0.8 * (rnd() - 0.5), z + w * (rnd() - 0.5));
        EP(x + 0.8 * (rnd() - 0.5), y + 0.8 * (rnd() - 0.5), z + w * (rnd() - 0.5));
    }
#undef EP
    s = load(t, n);
    free(t);
    return s;
}

/* A point of triangle prim: barycentric (a, b), or on its edge e (b < 0). */
static rtpi_v3 tri_point(const rtp_scene *s, uint32_t prim, double a, double b)
{
    const rtpi_tri *tr = &s->tris[prim];
    rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)tr->v[0]);
    rtpi_v3 p1 = v3_from_f(s->pos + 3 * (size_t)tr->v[1]);
    rtpi_v3 p2 = v3_from_f(s->pos + 3 * (size_t)tr->v[2]);
    return v3_add(p0, v3_add(v3_mul(v3_sub(p1, p0), a), v3_mul(v3_sub(p2, p0), b)));
}

/* The light buffer's edge entries (lb_edges: the walk's edges' test, and a
   cached first triangle answered by its edges and its t's bounds where
   they are sure) answer every query as the buffer without them does (the
   planes' walk and the watertight test of the first), primitive for
   primitive, also for origins on the lines from the light through the
   triangles' edges and vertices (to 1e-16..1e-9 of the way), on their
   planes, just before and beyond them, lights in a triangle's plane, at a
   vertex, just above a triangle, far away; and the edge entries are
   rtpi_tri_edges' (the exact mode's) number for number. */
static void test_lightbuf_edges_same(void)
{
    static const double offs[][2] = {{0, 1}, {3000, 0.01}, {-2e5, 3}};
    size_t oi;
    for (oi = 0; oi < sizeof offs / sizeof *offs; oi++) {
        double off = offs[oi][0], sc = offs[oi][1];
        rtp_scene *s = edge_scene(off, sc);
        rtp_allocator al;
        int li;
        rtpi_allocator_init(&al, NULL);
        CHECK(s != NULL);
        if (!s)
            return;
        for (li = 0; li < 7; li++) {
            rtpi_v3 L;
            rtpi_lightbuf lb, pl;
            double *te = NULL, *tp = NULL, scale;
            size_t q, bad = 0, badf = 0, badn = 0, nq = 0, r;
            uint32_t last = RTPI_NONE;
            switch (li) {
            case 0: L = v3(0.3, -0.2, 9); break;
            case 1: L = v3(2e4, -1e4, 3e4); break;
            case 2: L = tri_point(s, 2, 0, 0); /* the fan's shared vertex */
                L = v3((L.x - off) / sc, (L.y - off) / sc, (L.z - off) / sc); break;
            case 3: L = v3(0.2, 0.1, 2.0 + 1e-9); break; /* just above the fan's centre */
            case 4: L = v3(-3, 2, 0); break; /* in the ground's plane */
            case 5: L = v3(1, 1, 2.05); break; /* among the fan's triangles */
            default: L = v3(4 * (rnd() - 0.5), 4 * (rnd() - 0.5), 0.1 + 4 * rnd()); break;
            }
            L = v3(off + sc * L.x, off + sc * L.y, off + sc * L.z);
            if (li == 2)
                L = tri_point(s, 2, 0, 0);
            if (rtpi_lightbuf_build(s, L, li & 1 ? 64 : 256, &al, &lb, NULL) != RTP_OK) {
                CHECK_MSG(0, "edges: build failed, light %d", li);
                continue;
            }
            CHECK_MSG(lb.edge != NULL && lb.rank_of != NULL, "edges: none made, light %d", li);
            if (!lb.edge) {
                rtpi_lightbuf_free(&lb, &al);
                continue;
            }
            /* entries: rtpi_tri_edges' */
            if (rtpi_tri_planes(s, L, &al, &tp, &scale, NULL) == RTP_OK && tp) {
                rtpi_tri_edges(s, L, scale, tp, &al, &te);
                CHECK(te != NULL && scale == lb.scale && lb.ethr == RTPI_EDGE_MARGIN * scale * scale * scale);
                for (r = 0; te && r < lb.ncand; r++) {
                    uint32_t p = lb.cand[r].prim;
                    bad += memcmp(lb.edge + RTPI_EDGE_N * r, te + RTPI_EDGE_N * (size_t)p,
                                  RTPI_EDGE_N * sizeof *te) != 0 || lb.rank_of[p] != r;
                }
                CHECK_MSG(bad == 0, "edges: %lu entries differ from rtpi_tri_edges', light %d",
                          (unsigned long)bad, li);
            }
            rtpi_free(&al, te);
            rtpi_free(&al, tp);
            pl = lb; /* the same buffer without its edges: the planes' walk */
            pl.edge = NULL;
            pl.rank_of = NULL;
            for (q = 0; q < 6000; q++) {
                uint32_t prim = (uint32_t)(rnd() * (double)s->ntris), first, a1, a2, skip;
                double f = rnd(), g = rnd(), tiny = pow(10.0, -16 + 7 * rnd()), m;
                rtpi_v3 pt, o;
                rtpi_ray ray;
                int kind = (int)(rnd() * 6), side = (int)(rnd() * 3);
                if (prim >= s->ntris || lb.rank_of[prim] == RTPI_NONE)
                    continue;
                if (f + g > 1) {
                    f = 1 - f;
                    g = 1 - g;
                }
                switch (kind) {
                case 0: pt = tri_point(s, prim, f, g); break;           /* inside */
                case 1: pt = tri_point(s, prim, f, 0); break;           /* an edge */
                case 2: pt = tri_point(s, prim, 0, g); break;           /* an edge */
                case 3: pt = tri_point(s, prim, f, 1 - f); break;       /* the third */
                case 4: pt = tri_point(s, prim, (double)(side == 1), (double)(side == 2));
                    break;                                              /* a vertex */
                default: pt = tri_point(s, prim, f * (1 + tiny), g); break;
                }
                /* along the light's line through pt: beyond it, on it,
                   or just before it (between it and the light) */
                side = (int)(rnd() * 7);
                m = side == 0 ? 1 + 2 * rnd() : side == 1 ? 1 - 0.5 * rnd() : side <= 3 ? 1 + tiny
                    : side <= 5 ? 1 - tiny : 1;
                o = v3_add(L, v3_mul(v3_sub(pt, L), m));
                if (q % 5 == 0) /* a nudge off the line, by up to 1e-9 of the scale */
                    o = v3_add(o, v3_mul(v3(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5),
                                         tiny * fabs(sc) * 10));
                ray = rtpi_shadow_ray(o, L);
                skip = q % 7 == 0 ? prim : RTPI_NONE;
                first = q % 4 == 3 && last != RTPI_NONE ? last : prim;
                if (first == skip)
                    first = RTPI_NONE;
                a1 = rtpi_lightbuf_occluder_first(&lb, s, &ray, skip, first);
                a2 = rtpi_lightbuf_occluder_first(&pl, s, &ray, skip, first);
                badf += a1 != a2;
                nq++;
                a1 = rtpi_lightbuf_occluder(&lb, s, &ray, skip);
                a2 = rtpi_lightbuf_occluder(&pl, s, &ray, skip);
                badn += a1 != a2;
                if (a2 != RTPI_NONE && a2 < s->ntris)
                    last = a2;
            }
            CHECK(nq > 1000);
            CHECK_MSG(badf == 0 && badn == 0,
                      "edges: offset %g, light %d: %lu of %lu answers with a first differ, "
                      "%lu without", off, li, (unsigned long)badf, (unsigned long)nq,
                      (unsigned long)badn);
            rtpi_lightbuf_free(&lb, &al);
        }
        rtp_scene_destroy(s);
    }
}

/* A light buffer's query finds its cell from its origin seen from the
   light (dircube.c lb_cell: o - light, the windows' reciprocals), not by
   rtpi_dc_wcell's arithmetic on the ray's direction: its answers are still
   exactly those of every primitive's own test, for origins on the lines
   from the light through the triangles' edges and vertices (to 1e-16..1e-9
   of the way inside), where a cell a rounding off would miss a triangle
   its list's widening does not reach (a query's cell off by 1e-4 of its
   coordinate: dozens of answers lit where a triangle is in the way). */
static void test_lightbuf_query_cells(void)
{
    static const double offs[][2] = {{0, 1}, {3000, 0.01}, {-2e5, 3}};
    size_t oi;
    for (oi = 0; oi < sizeof offs / sizeof *offs; oi++) {
        double off = offs[oi][0], sc = offs[oi][1];
        rtp_scene *s = edge_scene(off, sc);
        rtp_allocator al;
        int li;
        rtpi_allocator_init(&al, NULL);
        CHECK(s != NULL);
        if (!s)
            return;
        for (li = 0; li < 6; li++) {
            rtpi_v3 L;
            rtpi_lightbuf lb;
            size_t q, bad = 0, nq = 0, hits = 0;
            switch (li) {
            case 0: L = v3(0.3, -0.2, 9); break;
            case 1: L = v3(2e4, -1e4, 3e4); break;
            case 2: L = v3(0.2, 0.1, 2.5); break; /* above the fan, near */
            case 3: L = v3(-3, 2, 0.5); break;    /* low, several faces */
            default: L = v3(4 * (rnd() - 0.5), 4 * (rnd() - 0.5), 0.1 + 4 * rnd()); break;
            }
            L = v3(off + sc * L.x, off + sc * L.y, off + sc * L.z);
            if (rtpi_lightbuf_build(s, L, li & 1 ? 64 : 512, &al, &lb, NULL) != RTP_OK) {
                CHECK_MSG(0, "query cells: build failed, light %d", li);
                continue;
            }
            for (q = 0; q < 4000; q++) {
                uint32_t prim = (uint32_t)(rnd() * (double)s->ntris), a, k, e = RTPI_NONE;
                double f = rnd(), g = rnd(), tiny = pow(10.0, -16 + 7 * rnd()), m;
                rtpi_v3 pt, o;
                rtpi_ray ray;
                rtpi_hit h;
                int kind = (int)(rnd() * 4);
                if (prim >= s->ntris)
                    continue;
                if (f + g > 1) {
                    f = 1 - f;
                    g = 1 - g;
                }
                switch (kind) {
                case 0: pt = tri_point(s, prim, f * (1 - tiny), tiny); break; /* by an edge */
                case 1: pt = tri_point(s, prim, tiny, g * (1 - tiny)); break; /* by an edge */
                case 2: pt = tri_point(s, prim, f * (1 - tiny), (1 - f) * (1 - tiny)); break;
                default: pt = tri_point(s, prim, tiny, tiny); break;         /* by a vertex */
                }
                /* beyond pt from the light: the segment to the light
                   passes through it */
                m = 1 + (q & 1 ? 2 * rnd() : 1e-3 * rnd());
                o = v3_add(L, v3_mul(v3_sub(pt, L), m));
                ray = rtpi_shadow_ray(o, L);
                for (k = 0; k < s->ntris && e == RTPI_NONE; k++)
                    if (rtpi_intersect_prim(s, k, &ray, &h))
                        e = k;
                a = rtpi_lightbuf_occluder(&lb, s, &ray, RTPI_NONE);
                bad += (a == RTPI_NONE) != (e == RTPI_NONE);
                hits += e != RTPI_NONE;
                nq++;
            }
            CHECK(nq > 1000 && hits > nq / 2);
            CHECK_MSG(bad == 0, "query cells: offset %g, light %d: %lu of %lu answers differ",
                      off, li, (unsigned long)bad, (unsigned long)nq);
            rtpi_lightbuf_free(&lb, &al);
        }
        rtp_scene_destroy(s);
    }
}

/* The round primitives' tests (cone bands, sphere boxes), run by
   round_run: scenes at the origin and moved far from it, small and large
   (offset, scale), each a view, a light, a material and the test's
   primitives (`add`: their text after `len` bytes of ROUND_TEXT; the new
   length); for each of six lights (`light`: where in the unit scene),
   placed as the scene is, the light buffer at 64 cells a face edge for
   odd lights, 256 for even, which `check` examines. */
#define ROUND_TEXT 65536

typedef struct round_test {
    const char *what;
    size_t (*add)(char *text, size_t len, double off, double sc);
    rtpi_v3 (*light)(const rtp_scene *s, int li, double off, double sc);
    void (*check)(const rtp_scene *s, const rtpi_lightbuf *lb, rtpi_v3 L, double off, int li);
} round_test;

static void round_run(const round_test *t)
{
    static const double offs[][2] = {{0, 1}, {3000, 0.01}, {-2e5, 3}};
    size_t oi;
    for (oi = 0; oi < sizeof offs / sizeof *offs; oi++) {
        double off = offs[oi][0], sc = offs[oi][1];
        char *text = (char *)malloc(ROUND_TEXT);
        size_t len;
        rtp_scene *s;
        rtp_allocator al;
        int li;
        rtpi_allocator_init(&al, NULL);
        CHECK(text != NULL);
        if (!text)
            return;
        len = (size_t)snprintf(text, ROUND_TEXT,
                               "v\nfrom 0 -9 4\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\n"
                               "resolution 8 8\nl 0 0 9\nf 0.8 0.8 0.8 1 0 0 0 1\n");
        len = t->add(text, len, off, sc);
        s = load(text, len);
        free(text);
        CHECK(s != NULL);
        if (!s)
            return;
        for (li = 0; li < 6; li++) {
            rtpi_v3 L = t->light(s, li, off, sc);
            rtpi_lightbuf lb;
            L = v3(off + sc * L.x, off + sc * L.y, off + sc * L.z);
            if (rtpi_lightbuf_build(s, L, li & 1 ? 64 : 256, &al, &lb, NULL) != RTP_OK) {
                CHECK_MSG(0, "%s: build failed, light %d", t->what, li);
                continue;
            }
            t->check(s, &lb, L, off, li);
            rtpi_lightbuf_free(&lb, &al);
        }
        rtp_scene_destroy(s);
    }
}

/* 40 cylinders and cones (every fourth) of random sizes and directions, a
   sphere, and a floor far below: two triangles among the round
   candidates. */
static size_t cone_slabs_add(char *text, size_t len, double off, double sc)
{
    size_t k;
    for (k = 0; k < 40; k++) {
        double ax = 6 * (rnd() - 0.5), ay = 6 * (rnd() - 0.5), az = 3 * rnd();
        double ln = 0.2 + 2 * rnd(), z = 2 * rnd() - 1, ph = 6.283185307179586 * rnd();
        double rr = sqrt(1 - z * z), r0 = 0.01 + 0.3 * rnd();
        double r1 = k % 4 == 3 ? 0.01 + 0.3 * rnd() : r0; /* every fourth a cone */
        len += (size_t)snprintf(text + len, ROUND_TEXT - len, "c\n%.17g %.17g %.17g %.17g\n"
                                "%.17g %.17g %.17g %.17g\n",
                                off + sc * ax, off + sc * ay, off + sc * az, sc * r0,
                                off + sc * (ax + ln * rr * cos(ph)),
                                off + sc * (ay + ln * rr * sin(ph)), off + sc * (az + ln * z),
                                sc * r1);
    }
    len += (size_t)snprintf(text + len, ROUND_TEXT - len, "s %.17g %.17g %.17g %.17g\n", off,
                            off, off + sc * 5, sc * 0.3);
    len += (size_t)snprintf(text + len, ROUND_TEXT - len,
                            "p 4\n%.17g %.17g %.17g\n%.17g %.17g %.17g\n"
                            "%.17g %.17g %.17g\n%.17g %.17g %.17g\n",
                            off - sc * 9, off - sc * 9, off - sc * 20, off + sc * 9,
                            off - sc * 9, off - sc * 20, off + sc * 9, off + sc * 9,
                            off - sc * 20, off - sc * 9, off + sc * 9, off - sc * 20);
    return len;
}

/* near, far, on the first cylinder's axis line beyond its end, and at
   random above the floor */
static rtpi_v3 cone_slabs_light(const rtp_scene *s, int li, double off, double sc)
{
    rtpi_v3 L;
    switch (li) {
    case 0: return v3(0.3, -0.2, 9);
    case 1: return v3(2e4, -1e4, 3e4);
    case 2: {
        const rtpi_cone_frame *cf = &s->cframes[0];
        L = v3_madd(cf->b, cf->w, -0.5 * sc);
        return v3((L.x - off) / sc, (L.y - off) / sc, (L.z - off) / sc);
    }
    default: return v3(8 * (rnd() - 0.5), 8 * (rnd() - 0.5), 0.1 + 4 * rnd());
    }
}

static void cone_slabs_check(const rtp_scene *s, const rtpi_lightbuf *lb, rtpi_v3 L, double off,
                             int li)
{
    size_t r, hits = 0, turned = 0, bad = 0, banded = 0;
    CHECK_MSG(lb->slab != NULL && lb->cone != NULL, "cone bands: none made, light %d", li);
    /* a triangle's cone entry turns nothing away: the round walk's scan
       stops at it by that test alone (lb_walk) */
    CHECK(s->ntris == 2);
    for (r = 0; lb->cone && r < lb->ncand; r++)
        if (lb->cand[r].prim < s->ntris)
            CHECK(lb->cone[r].v[0] == 0.0 && lb->cone[r].v[1] == 0.0 &&
                  lb->cone[r].v[2] == 0.0 && lb->cone[r].v[3] == -2.0);
    for (r = 0; lb->slab && r < lb->ncand; r++) {
        uint32_t prim = lb->cand[r].prim;
        const double *q = lb->slab + 4 * r;
        const rtpi_cone_frame *cf;
        rtpi_v3 e1, e2;
        int t;
        if (prim < s->ntris + s->nspheres)
            continue;
        /* (the cone's rank, for a query's cached cone) */
        CHECK(lb->cone_rank[prim - s->ntris - s->nspheres] == r);
        if (!(q[3] < 2.0))
            continue;
        banded++;
        cf = &s->cframes[prim - s->ntris - s->nspheres];
        e1 = v3_norm(v3_cross(cf->w, fabs(cf->w.x) < 0.6 ? v3(1, 0, 0) : v3(0, 1, 0)));
        e2 = v3_cross(cf->w, e1);
        for (t = 0; t < 300; t++) {
            /* a point about the axis within 1.5 radii, or at the radius,
               1e-7 of it either way; the ray from behind it through it */
            double h = cf->h * rnd(), ph = 6.283185307179586 * rnd();
            double rad = (cf->rb + cf->k * h) *
                         (t & 1 ? 1.5 * rnd() : 1.0 + 1e-7 * (double)(t % 3 - 1));
            rtpi_v3 X = v3_madd(v3_madd(v3_madd(cf->b, cf->w, h), e1, rad * cos(ph)), e2,
                                rad * sin(ph));
            rtpi_v3 o = v3_madd(X, v3_sub(X, L), 0.05 + rnd()), dn;
            rtpi_ray ray = rtpi_shadow_ray(o, L);
            rtpi_hit hh;
            int in;
            dn = v3_mul(ray.d, -1.0);
            in = !(fabs(dn.x * q[0] + dn.y * q[1] + dn.z * q[2]) > q[3]);
            if (rtpi_intersect_prim(s, prim, &ray, &hh)) {
                hits++;
                bad += !in;
            } else {
                turned += !in;
            }
        }
    }
    CHECK_MSG(bad == 0, "cone bands, offset %g, light %d: %lu of %lu hits outside", off, li,
              (unsigned long)bad, (unsigned long)hits);
    CHECK_MSG(banded >= 20 && hits > 1000 && turned > 50,
              "cone bands, offset %g, light %d: %lu banded, %lu hits, %lu turned away", off, li,
              (unsigned long)banded, (unsigned long)hits, (unsigned long)turned);
}

/* The light buffer's band test for cones (lb_slabs): every shadow ray
   that rtpi_intersect_prim finds hitting a cone passes its cone's band,
   for rays grazing the cones' sides (points at their radius, 1e-7 of it
   either way, behind them as the light sees them), over cylinders and
   cones of random sizes and directions, lights near and far and one on
   a cylinder's axis line, at the origin and moved far from it; and the
   band turns some missing rays away (the test has teeth). */
static void test_lightbuf_cone_slabs(void)
{
    static const round_test t = {"cone bands", cone_slabs_add, cone_slabs_light,
                                 cone_slabs_check};
    round_run(&t);
}

/* 200 spheres: a third of radius a tenth of a cell at 256 cells, a third
   about a cell, a third many cells */
static size_t sphere_box_add(char *text, size_t len, double off, double sc)
{
    size_t k;
    for (k = 0; k < 200; k++) {
        double r = k % 3 == 0 ? 0.003 + 0.01 * rnd() : k % 3 == 1 ? 0.03 * rnd() + 0.01
                                                                 : 0.1 + 0.4 * rnd();
        len += (size_t)snprintf(text + len, ROUND_TEXT - len, "s %.17g %.17g %.17g %.17g\n",
                                off + sc * 6 * (rnd() - 0.5), off + sc * 6 * (rnd() - 0.5),
                                off + sc * 3 * rnd(), sc * r);
    }
    return len;
}

/* near, far, and at random above the spheres */
static rtpi_v3 sphere_box_light(const rtp_scene *s, int li, double off, double sc)
{
    (void)s;
    (void)off;
    (void)sc;
    switch (li) {
    case 0: return v3(0.3, -0.2, 9);
    case 1: return v3(2e2, -1e2, 3e2);
    default: return v3(8 * (rnd() - 0.5), 8 * (rnd() - 0.5), 4 + 4 * rnd());
    }
}

static void sphere_box_check(const rtp_scene *s, const rtpi_lightbuf *lb, rtpi_v3 L, double off,
                             int li)
{
    size_t i, hits = 0, bad = 0;
    for (i = 0; i < s->nspheres; i++) {
        uint32_t prim = (uint32_t)(s->ntris + i);
        rtpi_v3 C = v3_from_f(s->spheres[i].c), w = v3_sub(C, L), e1, e2;
        double r = fabs((double)s->spheres[i].r), D = v3_len(w);
        int t;
        if (!(D > 1.01 * r))
            continue;
        w = v3_mul(w, 1.0 / D);
        e1 = v3_norm(v3_cross(w, fabs(w.x) < 0.6 ? v3(1, 0, 0) : v3(0, 1, 0)));
        e2 = v3_cross(w, e1);
        for (t = 0; t < 200; t++) {
            /* a point of the silhouette's circle (centre C - w r^2 / D,
               radius r sqrt(1 - r^2 / D^2)), its radius 1e-7 of itself
               either way, or within it; the ray from behind it through
               it */
            double ph = 6.283185307179586 * rnd();
            double rad = r * sqrt(1.0 - r * r / (D * D)) *
                         (t & 1 ? rnd() : 1.0 + 1e-7 * (double)(t % 3 - 1));
            rtpi_v3 X = v3_madd(v3_madd(v3_madd(C, w, -r * r / D), e1, rad * cos(ph)), e2,
                                rad * sin(ph));
            rtpi_v3 o = v3_madd(X, v3_sub(X, L), 0.05 + rnd());
            rtpi_ray ray = rtpi_shadow_ray(o, L);
            rtpi_hit hh;
            size_t cell, e;
            int listed = 0;
            if (!rtpi_intersect_prim(s, prim, &ray, &hh))
                continue;
            hits++;
            cell = rtpi_dc_wcell(&lb->w, lb->res, v3_mul(ray.d, -1.0));
            for (e = cell == RTPI_DC_ABSENT ? 0 : lb->off[cell];
                 cell != RTPI_DC_ABSENT && e < lb->off[cell + 1]; e++)
                listed |= lb->cand[lb->ref[e]].prim == prim;
            bad += !listed;
        }
    }
    CHECK_MSG(bad == 0, "sphere box, offset %g, light %d: %lu of %lu hits not listed", off, li,
              (unsigned long)bad, (unsigned long)hits);
    CHECK_MSG(hits > 10000, "sphere box, offset %g, light %d: %lu hits", off, li,
              (unsigned long)hits);
}

/* The light buffer lists a sphere by the box of its exact projection
   (dircube.c, dc_cover_sphere): every shadow ray that rtpi_intersect_prim
   finds hitting a sphere, grazing ones above all (through points at its
   silhouette seen from the light, 1e-7 of its radius either way), finds
   it in its cell's list; over spheres of random sizes from a tenth of a
   cell to many cells, lights near and far, at the origin and moved far
   from it (round_run's scenes, as the cone bands'), at 64 and 256 cells.
   It fails with the box's sine 3% smaller. */
static void test_lightbuf_sphere_box(void)
{
    static const round_test t = {"sphere box", sphere_box_add, sphere_box_light,
                                 sphere_box_check};
    round_run(&t);
}

/* A light buffer's query from its origin alone (rtpi_lightbuf_vis_fn,
   dircube.c: the shadow ray made only where a test asks for it, tmax
   from |o - light|) answers as rtpi_lightbuf_occluder_first does on
   rtpi_shadow_ray(o, light), primitive for primitive (the cache's `last`
   the same), for each kind of walk: the edges' (edge_scene), the
   planes' (its buffer without edges), the spheres' (round) and the
   cones' bands (cone_slabs_add).  Origins on the lines from the light
   through triangles' edges and vertices (1e-16..1e-9 inside), beyond
   them and between them and the light, as near the light as 1e-16 of
   the way, at the light itself, and in random places; a first (the last
   answer's occluder) and the own primitive skipped by turns; the scenes
   at the origin, far from it, tiny (1e-9) and huge (1e7).  A ray made
   with each component divided by the distance (not multiplied by its
   reciprocal, as rtpi_shadow_ray does) fails it. */
static size_t vis_origin_check(const rtp_scene *s, const rtpi_lightbuf *lb, rtpi_v3 L,
                               size_t nq)
{
    rtpi_lb_vis_fn vis = rtpi_lightbuf_vis_fn(lb);
    size_t q, bad = 0;
    uint32_t last = 0;
    for (q = 0; q < nq; q++) {
        uint32_t prim = (uint32_t)(rnd() * (double)rtpi_scene_nprims(s)), skip, first, a, l2;
        double f = rnd(), g = rnd(), tiny = pow(10.0, -16 + 7 * rnd()), m;
        int kind = (int)(rnd() * 4), side = (int)(rnd() * 6), lit;
        rtpi_v3 pt, o;
        rtpi_ray ray;
        if (prim >= rtpi_scene_nprims(s))
            continue;
        if (f + g > 1) {
            f = 1 - f;
            g = 1 - g;
        }
        if (prim < s->ntris) {
            switch (kind) {
            case 0: pt = tri_point(s, prim, f * (1 - tiny), tiny); break;
            case 1: pt = tri_point(s, prim, tiny, g * (1 - tiny)); break;
            case 2: pt = tri_point(s, prim, f * (1 - tiny), (1 - f) * (1 - tiny)); break;
            default: pt = tri_point(s, prim, tiny, tiny); break;
            }
        } else {
            double lo[3], hi[3];
            rtpi_prim_bounds(s, prim, lo, hi);
            pt = v3(lo[0] + (hi[0] - lo[0]) * rnd(), lo[1] + (hi[1] - lo[1]) * rnd(),
                    lo[2] + (hi[2] - lo[2]) * rnd());
        }
        /* beyond pt, just beyond or before it, near the light, at it */
        m = side == 0 ? 1 + 2 * rnd() : side == 1 ? 1 + tiny : side == 2 ? 1 - tiny
            : side == 3 ? rnd() : side == 4 ? tiny : 0.0;
        o = v3_add(L, v3_mul(v3_sub(pt, L), m));
        if (q % 9 == 0) /* anywhere about the scene */
            o = v3_add(pt, v3_mul(v3_sub(pt, L), rnd() - 0.5));
        ray = rtpi_shadow_ray(o, L);
        skip = q % 3 == 0 ? prim : RTPI_NONE;
        first = last && last - 1u != skip && q % 4 != 1 ? last - 1u : RTPI_NONE;
        a = rtpi_lightbuf_occluder_first(lb, s, &ray, skip, first);
        l2 = 12345u;
        lit = vis(lb, s, &o, skip, first, &l2);
        bad += lit != (a == RTPI_NONE) || l2 != (a == RTPI_NONE ? 0u : a + 1u);
        last = a == RTPI_NONE ? last : a + 1u;
    }
    return bad;
}

static void vis_origin_round(const rtp_scene *s, const rtpi_lightbuf *lb, rtpi_v3 L, double off,
                             int li)
{
    size_t bad = vis_origin_check(s, lb, L, 3000);
    CHECK_MSG(lb->cone != NULL, "query from the origin: no cone entries, light %d", li);
    CHECK_MSG(bad == 0, "query from the origin (%s), offset %g, light %d: %lu of 3000 differ",
              lb->slab ? "bands" : "round", off, li, (unsigned long)bad);
}

static void test_lightbuf_query_from_origin(void)
{
    static const double offs[][2] = {{0, 1}, {3000, 0.01}, {-2e5, 3}, {1e-7, 1e-9}, {0, 1e7}};
    static const round_test rt[] = {
        {"query from the origin", cone_slabs_add, cone_slabs_light, vis_origin_round},
        {"query from the origin", sphere_box_add, sphere_box_light, vis_origin_round}};
    size_t oi;
    for (oi = 0; oi < sizeof offs / sizeof *offs; oi++) {
        double off = offs[oi][0], sc = offs[oi][1];
        rtp_scene *s = edge_scene(off, sc);
        rtp_allocator al;
        int li;
        rtpi_allocator_init(&al, NULL);
        CHECK(s != NULL);
        if (!s)
            return;
        for (li = 0; li < 6; li++) {
            rtpi_v3 L;
            rtpi_lightbuf lb, pl;
            size_t bad, badp;
            switch (li) {
            case 0: L = v3(0.3, -0.2, 9); break;
            case 1: L = v3(2e4, -1e4, 3e4); break;
            case 2: L = v3(0.2, 0.1, 2.0 + 1e-9); break; /* just above the fan */
            case 3: L = v3(-3, 2, 0); break;             /* in the ground's plane */
            default: L = v3(4 * (rnd() - 0.5), 4 * (rnd() - 0.5), 0.1 + 4 * rnd()); break;
            }
            L = v3(off + sc * L.x, off + sc * L.y, off + sc * L.z);
            if (rtpi_lightbuf_build(s, L, li & 1 ? 64 : 256, &al, &lb, NULL) != RTP_OK) {
                CHECK_MSG(0, "query from the origin: build failed, light %d", li);
                continue;
            }
            CHECK(lb.edge != NULL && lb.cone == NULL);
            pl = lb; /* the planes' walk */
            pl.edge = NULL;
            pl.rank_of = NULL;
            bad = vis_origin_check(s, &lb, L, 4000);
            badp = vis_origin_check(s, &pl, L, 4000);
            CHECK_MSG(bad == 0 && badp == 0,
                      "query from the origin: offset %g, scale %g, light %d: %lu of 4000 differ "
                      "(edges), %lu (planes)", off, sc, li, (unsigned long)bad,
                      (unsigned long)badp);
            rtpi_lightbuf_free(&lb, &al);
        }
        rtp_scene_destroy(s);
    }
    round_run(&rt[0]);
    round_run(&rt[1]);
}

/* The shadow's cached query in a light buffer (shadow.c sh_cached_lb:
   a triangle's query whose cache holds no sphere or cone goes straight
   to the buffer's query from the origin, the others' steps out of line)
   answers as EXACT's uncached query, through rtpi_shadow_visible_cached
   and rtpi_shadow_visible_own (rtpi_prim_shadows_own's answer given),
   each point asked twice in a row (its own primitive then in the cache)
   and the points in random order (spheres and cones in the cache by
   turns), for every light of the first scene.  It fails where the query
   asks its own primitive first. */
static void test_lightbuf_cached_fast(void)
{
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtpi_kdtree *kd = NULL;
    sample *sm = (sample *)malloc(4000 * sizeof *sm);
    rtp_allocator a;
    size_t k;
    rtpi_allocator_init(&a, NULL);
    CHECK(s != NULL && sm != NULL);
    if (!s || !sm || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        free(sm);
        return;
    }
    for (k = 0; k < NLIGHTS; k++) {
        rtpi_v3 lp = v3(lights[k].pos[0], lights[k].pos[1], lights[k].pos[2]);
        rtpi_shadow *ex = NULL, *sh = NULL;
        rtpi_shadow_cache c = {0}, c2 = {0};
        size_t n = make_samples(s, kd, lp, sm, 4000), j, bad = 0;
        if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
            rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_LIGHTBUF, k & 1 ? 64 : 256, &a, &sh,
                               NULL) != RTP_OK) {
            CHECK(0);
            rtpi_shadow_destroy(ex);
            break;
        }
        for (j = 0; j < n; j++) {
            const sample *q = &sm[j];
            int e = rtpi_shadow_visible(ex, q->p, q->o, q->prim);
            int own = rtpi_prim_shadows_own(s, q->prim, q->o, lp);
            bad += rtpi_shadow_visible_cached(sh, &c, &q->p, &q->o, q->prim) != e;
            bad += rtpi_shadow_visible_cached(sh, &c, &q->p, &q->o, q->prim) != e;
            bad += rtpi_shadow_visible_own(sh, &c2, &q->p, &q->o, q->prim, own) != e;
            bad += rtpi_shadow_visible_own(sh, &c2, &q->p, &q->o, q->prim, own) != e;
        }
        CHECK(n > 1000);
        CHECK_MSG(bad == 0, "cached light buffer, light %s: %lu of %lu answers differ",
                  lights[k].name, (unsigned long)bad, (unsigned long)(4 * n));
        rtpi_shadow_destroy(ex);
        rtpi_shadow_destroy(sh);
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    free(sm);
}

/* A sphere's own answer for its front hits' origins (vis_row keeps per
   node whether the origin lies outside it near its surface,
   rtpi_ball_near_outside, and takes the answer for the light from
   rtpi_shadow_ball_own): where both give one, it is
   rtpi_prim_shadows_own's, on the first scene's spheres (one hollow),
   lights far, inside, near the surface inside and out, and in the band
   where rtpi_prim_shadows_own_solid looks closer, origins at random
   directions from just off the surface to sqrt(2) of the radius.  It
   fails where the hollow sphere's answer is the solid one's (1,058 of
   8,532 differ) or where the light's inside is not asked.  (Not where
   the band's bound leaves out the origin's distance: in that band the
   solid function answers the same for these origins.) */
static void test_ball_own_kept(void)
{
    static const double lf[] = {0.0, 0.3, 0.999, 1.0 - 5e-9, 1.0 + 2e-9, 1.0 + 1.2e-8,
                                1.0 + 3e-8, 1.001, 1.5, 40.0};
    rtp_scene *s = load(scene_text, sizeof scene_text - 1);
    rtpi_kdtree *kd = NULL;
    rtp_allocator a;
    unsigned long checked = 0, asked = 0, bad = 0, ones = 0;
    uint64_t st = 0x9e3779b97f4a7c15ull;
    size_t i, li, j;
    rtpi_allocator_init(&a, NULL);
    CHECK(s != NULL);
    if (!s || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    for (i = 0; i < s->nspheres; i++) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 c = v3_from_f(sp->c);
        double r = fabs((double)sp->r);
        for (li = 0; li < sizeof lf / sizeof *lf; li++) {
            rtpi_v3 lp = v3_madd(c, v3_norm(v3(0.3, -0.5, 0.8)), lf[li] * r);
            rtpi_shadow *sh = NULL;
            const unsigned char *bo;
            if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &sh, NULL) != RTP_OK) {
                CHECK(0);
                continue;
            }
            bo = rtpi_shadow_ball_own(sh);
            CHECK(bo != NULL);
            if (!bo) {
                rtpi_shadow_destroy(sh);
                continue;
            }
            asked += bo[i] == RTPI_OWN_ASK;
            ones += bo[i] == 1;
            for (j = 0; j < 400; j++) {
                double u[3], f, q;
                rtpi_v3 d, o;
                size_t m;
                for (m = 0; m < 3; m++) {
                    st = st * 6364136223846793005ull + 1442695040888963407ull;
                    u[m] = (double)(st >> 11) / 9007199254740992.0;
                }
                d = v3_norm(v3(u[0] - 0.5, u[1] - 0.5, u[2] - 0.5));
                /* (from just off the surface to beyond sqrt(2) r) */
                q = u[2] < 0.5 ? 1e-12 * (double)(j % 7) : u[2] - 0.5;
                f = 1.0 + q;
                o = v3_madd(c, d, f * r);
                if (!rtpi_ball_near_outside(sp, o) || bo[i] == RTPI_OWN_ASK)
                    continue;
                checked++;
                bad += bo[i] != rtpi_prim_shadows_own(s, (uint32_t)(s->ntris + i), o, lp);
            }
            rtpi_shadow_destroy(sh);
        }
    }
    CHECK(checked > 5000);
    CHECK(asked > 0);
    CHECK(ones > 0);
    CHECK_MSG(bad == 0, "kept sphere own answers: %lu of %lu differ", bad, checked);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

/* A triangle's box cover (rtpi_lightbuf_build_q with few queries
   expected: dircube.c dc_box_tri) holds every cell of its exact cover:
   over 300 random triangles (tiny, a few cells, many cells, slivers
   thin one way or the other), lights near and far, the scene at the
   origin and moved far from it (round_run's offsets and scales), at 64
   and 256 cells, each cell's list of the box buffer holds its list of
   the spans' buffer (both in ascending rank), and the box buffer is the
   longer (the box taken); held to the spans' count of entries, the build
   lists by the spans.  It fails with the box one cell narrower on either
   side, or a row shorter, and without the spans' second build. */
static void test_lightbuf_tri_box(void)
{
    static const double offs[][2] = {{0, 1}, {3000, 0.01}, {-2e5, 3}};
    static const double lps[][3] = {{0, 0, 9}, {0.3, -0.2, 4}, {40, 25, 60}, {0, 0, 1.2}};
    size_t oi;
    for (oi = 0; oi < sizeof offs / sizeof *offs; oi++) {
        double off = offs[oi][0], sc = offs[oi][1];
        char *text = (char *)malloc(ROUND_TEXT);
        size_t len, k;
        rtp_scene *s;
        rtp_allocator al;
        int li;
        rtpi_allocator_init(&al, NULL);
        CHECK(text != NULL);
        if (!text)
            return;
        len = (size_t)snprintf(text, ROUND_TEXT,
                               "v\nfrom 0 -9 4\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\n"
                               "resolution 8 8\nl 0 0 9\nf 0.8 0.8 0.8 1 0 0 0 1\np 3\n");
        for (k = 0; k < 300; k++) {
            /* a centre, two edge vectors of random sizes (1e-3 to 3),
               every fifth a sliver (its second edge 1e-3 of the first) */
            double c[3], e[2][3], sz = pow(10.0, -3.0 + 3.5 * rnd());
            int a, b;
            for (a = 0; a < 3; a++)
                c[a] = a < 2 ? 6 * (rnd() - 0.5) : 3 * rnd() - 1;
            for (b = 0; b < 2; b++)
                for (a = 0; a < 3; a++)
                    e[b][a] = sz * (rnd() - 0.5) * (b && k % 5 == 4 ? 1e-3 : 1.0);
            if (k)
                len += (size_t)snprintf(text + len, ROUND_TEXT - len, "p 3\n");
            len += (size_t)snprintf(text + len, ROUND_TEXT - len,
                                    "%.17g %.17g %.17g\n%.17g %.17g %.17g\n%.17g %.17g %.17g\n",
                                    off + sc * c[0], off + sc * c[1], off + sc * c[2],
                                    off + sc * (c[0] + e[0][0]), off + sc * (c[1] + e[0][1]),
                                    off + sc * (c[2] + e[0][2]),
                                    off + sc * (c[0] + e[1][0]), off + sc * (c[1] + e[1][1]),
                                    off + sc * (c[2] + e[1][2]));
        }
        s = load(text, len);
        free(text);
        CHECK(s != NULL);
        if (!s)
            return;
        for (li = 0; li < 8; li++) {
            const double *q = lps[li / 2];
            rtpi_v3 L = v3(off + sc * q[0], off + sc * q[1], off + sc * q[2]);
            int res = li & 1 ? 64 : 256;
            rtpi_lightbuf ex, bx;
            size_t cell, missing = 0;
            if (rtpi_lightbuf_build_q(s, L, res, NULL, 0, 1, HUGE_VAL, HUGE_VAL, HUGE_VAL, NULL,
                                      &al, &ex, NULL) != RTP_OK) {
                CHECK_MSG(0, "tri box: spans build failed, offset %g, light %d", off, li);
                continue;
            }
            if (rtpi_lightbuf_build_q(s, L, res, NULL, 0, 1, HUGE_VAL, HUGE_VAL, 0.0, NULL, &al,
                                      &bx, NULL) != RTP_OK) {
                CHECK_MSG(0, "tri box: box build failed, offset %g, light %d", off, li);
                rtpi_lightbuf_free(&ex, &al);
                continue;
            }
            CHECK_MSG(ex.w.ncells == bx.w.ncells && ex.ncand == bx.ncand && ex.res == bx.res,
                      "tri box, offset %g, light %d: other windows", off, li);
            if (ex.w.ncells == bx.w.ncells) {
                for (cell = 0; cell < ex.w.ncells; cell++) {
                    uint32_t e = ex.off[cell], b = bx.off[cell];
                    for (; e < ex.off[cell + 1]; e++) {
                        while (b < bx.off[cell + 1] && bx.ref[b] < ex.ref[e])
                            b++;
                        missing += !(b < bx.off[cell + 1] && bx.ref[b] == ex.ref[e]);
                    }
                }
                CHECK_MSG(bx.off[bx.w.ncells] > ex.off[ex.w.ncells],
                          "tri box, offset %g, light %d: %lu entries, the spans' %lu", off, li,
                          (unsigned long)bx.off[bx.w.ncells],
                          (unsigned long)ex.off[ex.w.ncells]);
            }
            CHECK_MSG(missing == 0, "tri box, offset %g, light %d: %lu entries missing", off, li,
                      (unsigned long)missing);
            rtpi_lightbuf_free(&bx, &al);
            /* the box past a bound on entries the spans meet: the spans */
            if (li < 2) {
                double cap = (double)ex.off[ex.w.ncells];
                rtp_status st = rtpi_lightbuf_build_q(s, L, res, NULL, 0, 1, HUGE_VAL, cap, 0.0,
                                                      NULL, &al, &bx, NULL);
                CHECK_MSG(st == RTP_OK, "tri box, offset %g, light %d: %d within %g entries", off,
                          li, (int)st, cap);
                if (st == RTP_OK) {
                    CHECK(bx.off[bx.w.ncells] == ex.off[ex.w.ncells]);
                    rtpi_lightbuf_free(&bx, &al);
                }
            }
            rtpi_lightbuf_free(&ex, &al);
        }
        rtp_scene_destroy(s);
    }
}

int main(void)
{
    const char *env = getenv("RTP_TEST_SEED");
    unsigned seed = env ? (unsigned)strtoul(env, NULL, 10) : (unsigned)time(NULL);
    printf("test_shadow: seed %u (RTP_TEST_SEED=%u repeats it)\n", seed, seed);
    rng_state = 0x9e3779b97f4a7c15ull ^ ((uint64_t)seed * 0xbf58476d1ce4e5b9ull);
    if (!rng_state)
        rng_state = 1;
    RUN(test_cell_mapping);
    RUN(test_bad_arguments);
    RUN(test_alloc_failures);
    RUN(test_lightbuf_equals_exact);
    RUN(test_lightbuf_far_from_origin);
    RUN(test_lightbuf_far_light_lists);
    RUN(test_lightbuf_edge_on);
    RUN(test_lightbuf_threads);
    RUN(test_lightbuf_build_paths);
    RUN(test_spd_scene);
    RUN(test_light_at_cone_tip);
    RUN(test_exact_cache_earlier);
    RUN(test_lightbuf_edges_same);
    RUN(test_lightbuf_query_cells);
    RUN(test_lightbuf_cone_slabs);
    RUN(test_lightbuf_sphere_box);
    RUN(test_lightbuf_tri_box);
    RUN(test_lightbuf_query_from_origin);
    RUN(test_lightbuf_cached_fast);
    RUN(test_ball_own_kept);
    RUN(test_lightbuf_limit_threads);
    RUN(test_stopper_reports);
    RUN(test_osmesa);
    RUN(test_osmesa_curved);
    return check_report();
}
