/* test_itembuf.c — the item buffer's share of wrong shadow decisions
 * (lib/shadow.h, RTPI_SHADOW_ITEMBUF and, in OSMESA=1 builds, OSMESA)
 * stays at most 0.1% of the kd-tree's at 256, 512 and 1024 cells a face,
 * on scenes built to trip it: branches far thinner than a cell under a
 * far light over a wide floor, a fine mesh whose triangles are smaller
 * than the cells, slivers, and the light between objects; and on the
 * small SPD scenes when ../shared/scenes is present.  Its "in shadow"
 * answers are certain (a real intersection): never wrong.  A thread's
 * shadow cache (the last occluder met, tested first) changes no light-
 * buffer answer and only rights item-buffer ones.  Query points
 * are eye-ray hits as trace makes them, plus random rays through the
 * scene (which reach backs, undersides and grazing spots). */
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

typedef struct sample {
    rtpi_v3 p, o;
    uint32_t prim;
} sample;

/* Hits of rays from the camera towards its target (spread by `spread`)
   and from random points of the box lo..hi in random directions, kept
   where trace would ask about light lp. */
static size_t make_samples(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp,
                           const double lo[3], const double hi[3], double spread,
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
            r.d = v3_norm(v3_add(v3_sub(at, eye), v3(spread * (rnd() - 0.5), spread * (rnd() - 0.5),
                                                     spread * (rnd() - 0.5))));
        } else {
            double z = 2 * rnd() - 1, ph = 6.283185307179586 * rnd(), rr = sqrt(1 - z * z);
            r.o = v3(lo[0] + (hi[0] - lo[0]) * rnd(), lo[1] + (hi[1] - lo[1]) * rnd(),
                     lo[2] + (hi[2] - lo[2]) * rnd());
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

/* Checks one mode at one resolution against EXACT on n samples. */
static void check_mode(const char *label, const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp,
                       rtpi_shadow_mode mode, int res, const sample *sm, size_t n)
{
    rtpi_shadow *ex = NULL, *sh = NULL;
    rtp_allocator a;
    rtp_error err;
    size_t k, wrong = 0, false_shadow = 0, lit = 0, cache_bad = 0;
    rtpi_shadow_cache cache = {0};
    rtpi_allocator_init(&a, NULL);
    if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
        rtpi_shadow_create(s, NULL, lp, mode, res, &a, &sh, &err) != RTP_OK) {
        CHECK_MSG(0, "%s: cannot create the shadow queries", label);
        rtpi_shadow_destroy(ex);
        return;
    }
    for (k = 0; k < n; k++) {
        int e = rtpi_shadow_visible(ex, sm[k].p, sm[k].o, sm[k].prim);
        int v = rtpi_shadow_visible(sh, sm[k].p, sm[k].o, sm[k].prim);
        int vc = rtpi_shadow_visible_cached(sh, &cache, &sm[k].p, &sm[k].o, sm[k].prim);
        /* the cache only finds real occluders: it may right a wrong "lit" */
        cache_bad += vc != v && vc != e;
        wrong += e != v;
        false_shadow += e && !v;
        lit += (size_t)e;
    }
    printf("  %-34s %-7s %4d: %6lu points, %5.1f%% lit, wrong %.4f%%\n", label,
           mode == RTPI_SHADOW_OSMESA ? "osmesa" : "itembuf", res, (unsigned long)n,
           100.0 * (double)lit / (double)(n ? n : 1), 100.0 * (double)wrong / (double)(n ? n : 1));
    CHECK_MSG((double)wrong <= 0.001 * (double)n, "%s, res %d: %lu of %lu decisions wrong", label,
              res, (unsigned long)wrong, (unsigned long)n);
    CHECK_MSG(false_shadow == 0, "%s, res %d: %lu lit points put in shadow", label, res,
              (unsigned long)false_shadow);
    CHECK_MSG(cache_bad == 0, "%s, res %d: %lu cached answers wrong where uncached were right",
              label, res, (unsigned long)cache_bad);
    rtpi_shadow_destroy(ex);
    rtpi_shadow_destroy(sh);
}

/* The queries the least of 9 answered itself over every case, and all
   of them (test_least_answers). */
static unsigned long least_answered, least_asked;

/* An item buffer's first steps with the least depth of the 9 samples
   (rtpi_itembuf_pre, inline in shadow.c) and the rest answer as the
   whole query without it; the least's own answers are counted for
   test_least_answers (one case may have none: a light among thin
   branches, every sample's cells holding one in front). */
static void check_itembuf_least(const char *label, const rtp_scene *s, rtpi_v3 lp, int res,
                                const sample *sm, size_t n)
{
    rtpi_itembuf ib;
    rtp_allocator a;
    size_t k, bad = 0, least = 0;
    rtpi_allocator_init(&a, NULL);
    if (rtpi_itembuf_build(s, lp, res, &a, &ib, NULL) != RTP_OK) {
        CHECK_MSG(0, "%s: cannot build the item buffer", label);
        return;
    }
    for (k = 0; k < n; k++) {
        int self = rtpi_prim_shadows_own(s, sm[k].prim, sm[k].o, lp), v, w;
        uint32_t occ = RTPI_NONE, occ2 = RTPI_NONE;
        rtpi_dc_at at, at2;
        rtpi_ib_query q;
        v = rtpi_itembuf_visible(&ib, s, &sm[k].p, &sm[k].o, sm[k].prim, self, NULL, &occ, &at);
        if (self == 1) {
            w = 0;
            occ2 = sm[k].prim;
        } else if ((w = rtpi_itembuf_pre(&ib, &sm[k].p, &sm[k].o, &at2, &q, 1)) < 0) {
            w = rtpi_itembuf_visible_rest(&ib, s, &sm[k].p, &sm[k].o, sm[k].prim, self, NULL,
                                          &occ2, &at2, &q);
        }
        least += w == 2;
        bad += (w > 0) != (v > 0) || (w < 0) != (v < 0) || occ != occ2 ||
               (v != 0 && (at.f != at2.f || at.u != at2.u || at.v != at2.v));
    }
    CHECK_MSG(bad == 0, "%s, res %d: %lu of %lu answers through the least of 9 differ", label,
              res, (unsigned long)bad, (unsigned long)n);
    least_answered += (unsigned long)least;
    least_asked += (unsigned long)n;
    rtpi_itembuf_free(&ib, &a);
}

/* The least of 9 answers queries itself (else the checks of its answers
   above would prove nothing): over every scene, light and resolution
   run before this. */
static void test_least_answers(void)
{
    printf("  the least of 9 answered %lu of %lu queries\n", least_answered, least_asked);
    CHECK_MSG(least_answered > least_asked / 10, "the least of 9 answered %lu of %lu queries",
              least_answered, least_asked);
}

/* The light buffer through a thread's cache still answers as EXACT. */
static void check_lightbuf_cached(const char *label, const rtp_scene *s, const rtpi_kdtree *kd,
                                  rtpi_v3 lp, const sample *sm, size_t n)
{
    rtpi_shadow *ex = NULL, *lb = NULL;
    rtpi_shadow_cache cache = {0};
    rtp_allocator a;
    size_t k, bad = 0;
    rtpi_allocator_init(&a, NULL);
    if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
        rtpi_shadow_create(s, NULL, lp, RTPI_SHADOW_LIGHTBUF, 256, &a, &lb, NULL) != RTP_OK) {
        CHECK_MSG(0, "%s: cannot create the shadow queries", label);
        rtpi_shadow_destroy(ex);
        return;
    }
    for (k = 0; k < n; k++)
        bad += rtpi_shadow_visible(ex, sm[k].p, sm[k].o, sm[k].prim) !=
               rtpi_shadow_visible_cached(lb, &cache, &sm[k].p, &sm[k].o, sm[k].prim);
    CHECK_MSG(bad == 0, "%s: %lu of %lu cached light-buffer answers differ from exact", label,
              (unsigned long)bad, (unsigned long)n);
    rtpi_shadow_destroy(ex);
    rtpi_shadow_destroy(lb);
}

static int have_osmesa(const rtp_scene *s)
{
    rtpi_itembuf ib;
    rtp_allocator a;
    rtpi_allocator_init(&a, NULL);
    if (rtpi_itembuf_build_osmesa(s, v3(0, 0, 100), 8, &a, &ib, NULL) != RTP_OK)
        return 0;
    rtpi_itembuf_free(&ib, &a);
    return 1;
}

#define NSAMPLES 20000

static void run(const char *label, const rtp_scene *s, const rtpi_v3 *lights, size_t nl,
                double spread)
{
    static const int res[] = {256, 512, 1024};
    rtpi_kdtree *kd = NULL;
    sample *sm = (sample *)malloc(NSAMPLES * sizeof *sm);
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    size_t li, k;
    int r, c, gl = have_osmesa(s);
    if (!sm || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        free(sm);
        return;
    }
    for (k = 0; k < rtpi_scene_nprims(s); k++) {
        double pl[3], ph[3];
        rtpi_prim_bounds(s, (uint32_t)k, pl, ph);
        for (c = 0; c < 3; c++) {
            lo[c] = fmin(lo[c], pl[c]);
            hi[c] = fmax(hi[c], ph[c]);
        }
    }
    for (li = 0; li < nl; li++) {
        size_t n = make_samples(s, kd, lights[li], lo, hi, spread, sm, NSAMPLES);
        char name[96];
        CHECK_MSG(n > NSAMPLES / 10, "%s: only %lu points", label, (unsigned long)n);
        snprintf(name, sizeof name, "%s, light %lu", label, (unsigned long)li);
        check_lightbuf_cached(name, s, kd, lights[li], sm, n);
        for (r = 0; r < 3; r++) {
            check_mode(name, s, kd, lights[li], RTPI_SHADOW_ITEMBUF, res[r], sm, n);
            check_itembuf_least(name, s, lights[li], res[r], sm, n);
            if (gl)
                check_mode(name, s, kd, lights[li], RTPI_SHADOW_OSMESA, res[r], sm, n);
        }
    }
    rtpi_kd_destroy(kd);
    free(sm);
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

/* run() on a scene given as NFF text. */
static void run_text(const char *label, const char *text, size_t len, const rtpi_v3 *lights,
                     size_t nl)
{
    rtp_scene *s = load(text, len);
    if (!s) {
        CHECK(0);
        return;
    }
    run(label, s, lights, nl, 1.0);
    rtp_scene_destroy(s);
}

/* A wide floor, thin branches (cones of radius 0.004 to 0.03, far below a
   cell from a light 50 away), twigs ending in small spheres, slivers. */
static void test_thin_branches(void)
{
    char *text = (char *)malloc(200000);
    size_t m = 0;
    int k;
    rtp_scene *s;
    rtpi_v3 lights[3];
    if (!text) {
        CHECK(0);
        return;
    }
    m += (size_t)sprintf(text + m,
                         "v\nfrom 4.5 0.4 2\nat 0 0 1.2\nup 0 0 1\nangle 45\nhither 0.01\n"
                         "resolution 64 64\nl -5 5 50\n"
                         "f 0.2 0.7 0.2 1 0 10 0 0\np 4\n50 50 0\n-50 50 0\n-50 -50 0\n50 -50 0\n"
                         "f 0.55 0.4 0.2 1 0 10 0 0\n");
    for (k = 0; k < 300; k++) {
        double a = 6.283185307179586 * rnd(), z0 = 0.2 + 1.6 * rnd(), len = 0.2 + 0.6 * rnd();
        double x0 = 0.3 * cos(a) * rnd(), y0 = 0.3 * sin(a) * rnd();
        double x1 = x0 + len * cos(a), y1 = y0 + len * sin(a), z1 = z0 + 0.5 * len * (rnd() - 0.3);
        double r0 = 0.004 + 0.026 * rnd(), r1 = r0 * (0.3 + 0.7 * rnd());
        m += (size_t)sprintf(text + m, "c\n%.6f %.6f %.6f %.6f\n%.6f %.6f %.6f %.6f\n", x0, y0, z0,
                             r0, x1, y1, z1, r1);
        m += (size_t)sprintf(text + m, "s %.6f %.6f %.6f %.6f\n", x1, y1, z1, r1);
        if (k % 3 == 0) /* a sliver leaf */
            m += (size_t)sprintf(text + m, "p 3\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n",
                                 x1, y1, z1, x1 + 0.2, y1 + 0.01, z1 + 0.05, x1 + 0.2,
                                 y1 + 0.02, z1 + 0.04);
    }
    s = load(text, m);
    CHECK(s != NULL);
    if (s) {
        lights[0] = v3(-5, 5, 50);
        lights[1] = v3(3, -2, 6);    /* close: branches a few cells wide */
        lights[2] = v3(0.1, 0.2, 1); /* among the branches */
        run("thin branches", s, lights, 3, 2.0);
    }
    rtp_scene_destroy(s);
    free(text);
}

/* A height field of 2 x 64 x 64 triangles (each a fraction of a cell at
   256 from the far light) with boxes and a sphere standing on it. */
static void test_fine_mesh(void)
{
    enum { N = 64 };
    char *text = (char *)malloc(3000000); /* ~190 bytes a cell */
    size_t m = 0;
    int x, y;
    rtp_scene *s;
    rtpi_v3 lights[3];
    if (!text) {
        CHECK(0);
        return;
    }
    m += (size_t)sprintf(text + m,
                         "v\nfrom 0 -6 4\nat 0 0 0\nup 0 0 1\nangle 50\nhither 0.01\n"
                         "resolution 64 64\nl 20 10 30\nf 0.8 0.8 0.8 1 0 10 0 0\n");
    for (y = 0; y < N; y++)
        for (x = 0; x < N; x++) {
            double q[4][3];
            int c;
            for (c = 0; c < 4; c++) {
                double u = -3 + 6.0 * (x + (c == 1 || c == 2)) / N;
                double v = -3 + 6.0 * (y + (c >= 2)) / N;
                q[c][0] = u;
                q[c][1] = v;
                q[c][2] = 0.3 * sin(2 * u) * cos(1.5 * v) + 0.05 * sin(9 * u + 4 * v);
            }
            m += (size_t)sprintf(text + m, "p 3\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n",
                                 q[0][0], q[0][1], q[0][2], q[1][0], q[1][1], q[1][2], q[2][0],
                                 q[2][1], q[2][2]);
            m += (size_t)sprintf(text + m, "p 3\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n%.6f %.6f %.6f\n",
                                 q[0][0], q[0][1], q[0][2], q[2][0], q[2][1], q[2][2], q[3][0],
                                 q[3][1], q[3][2]);
        }
    m += (size_t)sprintf(text + m, "s 0.5 0.5 0.8 0.4\nc\n-1 1 0 0.3\n-1 1 1.2 0.3\n"
                                   "p 4\n1 -1 0.9\n2 -1 0.9\n2 0 0.9\n1 0 0.9\n");
    s = load(text, m);
    CHECK(s != NULL);
    if (s) {
        lights[0] = v3(20, 10, 30);
        lights[1] = v3(1e3, -2e3, 1.5e3); /* far: the mesh in few cells */
        lights[2] = v3(0.2, -0.3, 0.9);   /* low, just over the mesh */
        run("fine mesh", s, lights, 3, 4.0);
    }
    rtp_scene_destroy(s);
    free(text);
}

/* The small SPD scenes, light 0 moved. */
static void test_spd(void)
{
    static const char *names[] = {"balls_s2", "gears_s2", "mount_s3", "rings_s2",
                                  "teapot_s3", "tetra_s3", "tree_s3"};
    const char *dir = check_shared_scenes();
    size_t k;
    if (!dir)
        SKIP("../shared/scenes absent");
    for (k = 0; k < sizeof names / sizeof *names; k++) {
        char path[512];
        rtp_scene *s = NULL;
        rtpi_v3 lp;
        snprintf(path, sizeof path, "%s/spd/%s.nff", dir, names[k]);
        if (rtp_scene_load(path, NULL, &s, NULL) != RTP_OK || !s->nlights) {
            CHECK_MSG(0, "cannot load %s", path);
            rtp_scene_destroy(s);
            continue;
        }
        lp = v3(s->lights[0].pos[0] * 0.8 + 0.4, s->lights[0].pos[1] * 0.9 - 0.3,
                s->lights[0].pos[2] * 1.1 + 0.2);
        run(names[k], s, &lp, 1, 0.8);
        rtp_scene_destroy(s);
    }
}

/* A moved light a millionth from a small triangle, over a plate 0.02
   above a floor 10 away: OSMesa's near plane went to 1e-5 with the
   nearest primitive, its depth steps at the floor to 0.5, and the plate
   lost the depth test to the floor behind it: the shadow under the plate
   was gone (4.9% of the decisions wrong, 23 dB).  Also from inside a
   sphere 1e-4 from its surface. */
static void test_light_near_a_primitive(void)
{
    static const char text[] =
        "v\nfrom 0 -2.6 0.05\nat 0 0 0.01\nup 0 0 1\nangle 40\nhither 0.01\n"
        "resolution 64 64\nb 0.1 0.1 0.1\nl 0 -20 0.3\nf 0.8 0.8 0.8 0.8 0 1 0 0\n"
        "p 4\n-5 -5 0\n5 -5 0\n5 5 0\n-5 5 0\nf 0.2 0.8 0.2 0.8 0 1 0 0\n"
        "p 4\n-2 -2 0.02\n2 -2 0.02\n2 2 0.02\n-2 2 0.02\nf 0.9 0.3 0.2 0.8 0 1 0 0\n"
        "p 3\n0.3 0.2 10.000001\n0.301 0.2 10.000001\n0.3 0.201 10.000001\n"
        "s 1.3005 0.2003 10 0.9999\n";
    rtpi_v3 lp = v3(0.3005, 0.2003, 10);
    run_text("light near a primitive", text, sizeof text - 1, &lp, 1);
}

/* A light exactly on a sphere: on a glass ball (points inside it, reached
   by refracted rays) and on an inside-only backdrop.  A shadow ray stops
   short of the light, so the ball's surface there does not block it; the
   item buffer took the ball as blocking its own inside (the light
   rounded to outside it): 0.24 off on the glass, 43% of the pixels too
   dark under the backdrop. */
static void test_light_on_a_sphere(void)
{
    static const char text[] =
        "v\nfrom 0 -8 4\nat 0 0 0.5\nup 0 0 1\nangle 45\nhither 0.01\nresolution 32 32\n"
        "b 0 0 0\nl 3 -4 6\nf 0.8 0.8 0.8 1 0 1 0 0\n"
        "p 4\n-4 -4 0\n4 -4 0\n4 4 0\n-4 4 0\nf 0.3 0.3 0.9 0.5 0.5 50 0.5 1.4\n"
        "s 0 0 1 1\nf 0.3 0.3 0.35 0.6 0 100000 0 0\ns 0 0 0 -16\n";
    const rtpi_v3 lights[] = {{0, 0, 2}, {1, 0, 1}, {0, 0, 16}, {0, 16, 0}};
    run_text("light on a sphere", text, sizeof text - 1, lights, sizeof lights / sizeof *lights);
}

/* The hit of a ray straight down from (x, y, z) and its shadow query
   towards lp decided by ex (exact) and sh: 0 where nothing is hit or the
   hit faces away from the light, else 1, counting the hit into *n, a
   shadow into *shadowed and a disagreement into *wrong. */
static int down_decision(const rtp_scene *s, const rtpi_kdtree *kd, const rtpi_shadow *ex,
                         const rtpi_shadow *sh, rtpi_v3 lp, double x, double y, double z,
                         int *n, int *shadowed, int *wrong)
{
    rtpi_ray ray;
    rtpi_hit h;
    rtpi_v3 p, o;
    int e;
    ray.o = v3(x, y, z);
    ray.d = v3(0, 0, -1);
    ray.tmin = 0.0;
    ray.tmax = HUGE_VAL;
    if (!rtpi_kd_intersect(kd, &ray, &h) ||
        !rtpi_shadow_query_at(s, 0, h.prim, v3_madd(ray.o, ray.d, h.t), ray.d, lp,
                              rtpi_offset_floor(s, NULL), &p, &o))
        return 0;
    (*n)++;
    e = rtpi_shadow_visible(ex, p, o, h.prim);
    *shadowed += !e;
    *wrong += e != rtpi_shadow_visible(sh, p, o, h.prim);
    return 1;
}

/* A needle 3 long and 2e-7 wide passing 0.3 under the light: points on
   the wall below, on the line under it, are in its shadow (exactly: their
   shadow rays run along its middle).  Its corners lie more than 75
   degrees off its centroid's direction from the light, where the width
   was not estimated and it was taken as wide: drawn into the item buffer,
   it slipped between its samples at every resolution and the whole line
   was lit (degenerate.nff's needle under a light at 0,0,0.5: 42 pixels
   0.26 off from 64 to 4096 cells).  Thin, the light buffer beside the
   item buffer decides it exactly. */
static void test_needle_near_light(void)
{
    static const char text[] =
        "v\nfrom 0 0 10\nat 0 0 0\nup 0 1 0\nangle 30\nhither 0.01\nresolution 8 8\n"
        "l 0 0 0.5\nf 0 1 0 1 0 1 0 0\np 4\n-3 -3 -1\n3 -3 -1\n3 3 -1\n-3 3 -1\n"
        "f 0 1 1 1 0 1 0 0\np 3\n-1.5 0 0.2\n1.5 -0.0000001 0.2\n1.5 0.0000001 0.2\n";
    static const int res[] = {64, 256, 1024};
    rtp_scene *s = load(text, sizeof text - 1);
    rtpi_kdtree *kd = NULL;
    rtpi_v3 lp = v3(0, 0, 0.5);
    rtp_allocator a;
    int r, k, gl;
    if (!s || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    gl = have_osmesa(s);
    rtpi_allocator_init(&a, NULL);
    for (r = 0; r < 3 * (gl ? 2 : 1); r++) {
        rtpi_shadow_mode mode = r < 3 ? RTPI_SHADOW_ITEMBUF : RTPI_SHADOW_OSMESA;
        rtpi_shadow *ex = NULL, *sh = NULL;
        int n = 0, shadowed = 0, wrong = 0;
        if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
            rtpi_shadow_create(s, NULL, lp, mode, res[r % 3], &a, &sh, NULL) != RTP_OK) {
            CHECK(0);
            rtpi_shadow_destroy(ex);
            continue;
        }
        for (k = 0; k < 200; k++) /* down onto the wall between the needle and it */
            (void)down_decision(s, kd, ex, sh, lp, -2.9 + 5.8 * k / 199.0, 0, -0.5, &n,
                                &shadowed, &wrong);
        printf("  needle near the light, %s %4d: %d points, %d in shadow, %d wrong\n",
               mode == RTPI_SHADOW_OSMESA ? "osmesa" : "itembuf", res[r % 3], n, shadowed, wrong);
        CHECK_MSG(n == 200 && shadowed > 150, "needle: %d points, %d in shadow", n, shadowed);
        CHECK_MSG(wrong == 0, "needle, res %d: %d of %d decisions wrong", res[r % 3], wrong, n);
        rtpi_shadow_destroy(ex);
        rtpi_shadow_destroy(sh);
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

/* A light a double ulp above a ball's top, the ball far from the origin
   for its size (rings_s1 at scale 1e5, light 0 on a ball's top: 1e5 x
   its radius's ulp out, where the ray's set-up rounds by 1e-11): the
   item buffer's rays into the ball met it at t within rounding of 0, and
   where at or below 0 the ball was not drawn there; points on the floor,
   seen by the light through the ball, were lit where a neighbouring
   sample did not show it (0.22 off; 2 to 6 in 2000 here). */
static void test_light_on_a_far_ball(void)
{
    static const double cfg[][4] = {{1e5, 2e5, 10, 64},      {1e5, 2e5, 10, 256},
                                    {1e5, 2e5, 10, 1024},    {3e3, -1e3, 1, 256},
                                    {-93099.5, 261313, 7412, 256}};
    size_t c;
    for (c = 0; c < sizeof cfg / sizeof *cfg; c++) {
        double cx = cfg[c][0], cy = cfg[c][1], r = cfg[c][2];
        char text[1024];
        rtp_scene *s;
        rtpi_kdtree *kd = NULL;
        rtpi_shadow *ex = NULL, *sh = NULL;
        rtp_allocator a;
        rtpi_v3 lp;
        int k, n = 0, shadowed = 0, wrong = 0;
        snprintf(text, sizeof text,
                 "v\nfrom %.17g %.17g %.17g\nat %.17g %.17g 0\nup 0 0 1\nangle 40\nhither 1\n"
                 "resolution 8 8\nl 0 0 1\nf 1 1 1 1 0 1 0 0\np 4\n%.17g %.17g %.17g\n"
                 "%.17g %.17g %.17g\n%.17g %.17g %.17g\n%.17g %.17g %.17g\n"
                 "f 1 0 0 1 0 1 0 0\ns %.17g %.17g 0 %.17g\n",
                 cx, cy - 4 * r, 2 * r, cx, cy, cx - 8 * r, cy - 8 * r, -1.5 * r, cx + 8 * r,
                 cy - 8 * r, -1.5 * r, cx + 8 * r, cy + 8 * r, -1.5 * r, cx - 8 * r, cy + 8 * r,
                 -1.5 * r, cx, cy, r);
        s = load(text, strlen(text));
        if (!s || rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
            CHECK(0);
            rtp_scene_destroy(s);
            continue;
        }
        lp = v3(s->spheres[0].c[0], s->spheres[0].c[1],
                nextafter((double)s->spheres[0].c[2] + fabs((double)s->spheres[0].r), HUGE_VAL));
        rtpi_allocator_init(&a, NULL);
        if (rtpi_shadow_create(s, kd, lp, RTPI_SHADOW_EXACT, 0, &a, &ex, NULL) != RTP_OK ||
            rtpi_shadow_create(s, NULL, lp, RTPI_SHADOW_ITEMBUF, (int)cfg[c][3], &a, &sh, NULL) !=
                RTP_OK) {
            CHECK(0);
        } else {
            for (k = 0; k < 2000; k++) {
                /* down onto the floor around the ball, out to 5 radii:
                   every shadow ray enters the ball below the light */
                double ang = 6.283185307179586 * k / 2000.0;
                double rad = r * (0.3 + 5.0 * ((k * 7919) % 1000) / 1000.0);
                (void)down_decision(s, kd, ex, sh, lp, cx + rad * cos(ang),
                                    cy + rad * sin(ang), -1.2 * r, &n, &shadowed, &wrong);
            }
            printf("  light on a far ball (%g, %g, r %g) %4d: %d points, %d in shadow, %d wrong\n",
                   cx, cy, r, (int)cfg[c][3], n, shadowed, wrong);
            CHECK_MSG(n > 1900 && shadowed == n, "far ball %g: %d points, %d in shadow", cx, n,
                      shadowed);
            CHECK_MSG(wrong == 0, "far ball (%g, %g, r %g) at %d: %d of %d decisions wrong", cx,
                      cy, r, (int)cfg[c][3], wrong, n);
        }
        rtpi_shadow_destroy(ex);
        rtpi_shadow_destroy(sh);
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
    }
}

/* One speck far away (1e5 above a scene of size 8) took the depth bias to
   1e-4 of the face's whole extent, 10 units: every real occluder lay
   within it, and 37% of the pixels were lit in shadow. */
static void test_far_speck(void)
{
    static const char text[] =
        "v\nfrom 0 -8 3\nat 0 0 0.5\nup 0 0 1\nangle 50\nhither 0.01\nresolution 64 64\n"
        "b 0.1 0.1 0.1\nl 3 -4 5\nf 0.8 0.8 0.8 0.7 0.3 20 0 0\n"
        "p 4\n-4 -4 0\n4 -4 0\n4 4 0\n-4 4 0\nf 0.2 0.9 0.2 0.5 0.2 30 0.6 1.5\n"
        "s 0 1 1 0.8\ns -1 -2 0.7 0.3\nc -2 2 0 1 -2 2 1.5 0\ns 2 0 1e5 1e-4\n";
    const rtpi_v3 lights[] = {{-1, 0, 1}, {3, -4, 5}};
    run_text("far speck", text, sizeof text - 1, lights, sizeof lights / sizeof *lights);
}

/* The rays cast at round shapes while the item buffer is drawn stay
   near the cells they cover, wherever the light is: each sphere and cone
   was widened by an absolute 1e-9 radians, and seen from 2e9 a scene of
   size 2 spans 1e-9 radians: every shape took every cell of the window
   (balls_s2's move at 1024 cells: 5 s, against 0.03 s from 1e7). */
static void test_far_light_casts(void)
{
    static const char text[] =
        "v\nfrom 0 -6 4\nat 0 0 0\nup 0 0 1\nangle 50\nhither 0.01\nresolution 8 8\n"
        "l 2 3 9\nf 0.8 0.8 0.8 1 0 10 0 0\n"
        "s 0 0 0 0.5\ns 1 0 0 0.3\ns -1 0.5 0.2 0.4\ns 0 1 -0.5 0.25\ns 0.5 -1 0.3 0.35\n"
        "c\n-1 -1 0 0.3\n-1 -1 1 0.1\n";
    static const double dist[] = {1e2, 1e5, 1e7, 1e9, 2e9, 1e10};
    rtp_scene *s = load(text, sizeof text - 1);
    unsigned long long casts[6];
    rtp_allocator a;
    size_t k;
    rtpi_allocator_init(&a, NULL);
    if (!s) {
        CHECK(0);
        return;
    }
    for (k = 0; k < 6; k++) {
        rtpi_itembuf ib;
        rtpi_v3 L = v3(0.3 * dist[k], 0.2 * dist[k], dist[k]);
        casts[k] = 0;
        if (rtpi_itembuf_build(s, L, 256, &a, &ib, NULL) != RTP_OK) {
            CHECK_MSG(0, "item buffer from %g", dist[k]);
            continue;
        }
        casts[k] = ib.casts;
        printf("  from %g: %llu\n", dist[k], ib.casts);
        rtpi_itembuf_free(&ib, &a);
    }
    for (k = 1; k < 6; k++)
        CHECK_MSG(casts[k] <= 4 * casts[0] + 4096, "from %g: %llu rays cast, from %g: %llu",
                  dist[k], casts[k], dist[0], casts[0]);
    rtp_scene_destroy(s);
}

#ifdef RTP_HAVE_OSMESA
#include <GL/osmesa.h>
/* A host with an OSMesa context of its own bound on its thread keeps it
   through a buffer drawn by OSMesa (it found none bound after: every GL
   call it made then was lost). */
static void test_osmesa_leaves_the_callers_context(void)
{
    static const char sc[] = "v from 0 0 5 at 0 0 0 up 0 1 0 angle 40 hither 0.1 "
                             "resolution 8 8\nl 0 0 5\nf 1 1 1 1 0 1 0 1\n"
                             "p 3 -1 -1 0 1 -1 0 0 1 0\n";
    rtp_scene *s = NULL;
    static unsigned char buf[4 * 4 * 4];
    OSMesaContext mine = OSMesaCreateContextExt(OSMESA_RGBA, 16, 0, 0, NULL);
    rtpi_itembuf ib;
    rtp_allocator a;
    rtpi_allocator_init(&a, NULL);
    CHECK(rtp_scene_load_memory(sc, strlen(sc), "t.nff", "nff", NULL, &s, NULL) == RTP_OK);
    CHECK(mine && OSMesaMakeCurrent(mine, buf, GL_UNSIGNED_BYTE, 4, 4));
    if (s && mine && rtpi_itembuf_build_osmesa(s, v3(0, 0, 3), 16, &a, &ib, NULL) == RTP_OK) {
        CHECK(OSMesaGetCurrentContext() == mine);
        rtpi_itembuf_free(&ib, &a);
    } else {
        CHECK(0);
    }
    OSMesaMakeCurrent(NULL, NULL, 0, 0, 0);
    if (mine)
        OSMesaDestroyContext(mine);
    rtp_scene_destroy(s);
}
#endif

int main(void)
{
    const char *env = getenv("RTP_TEST_SEED");
    unsigned seed = env ? (unsigned)strtoul(env, NULL, 10) : (unsigned)time(NULL);
    printf("test_itembuf: seed %u (RTP_TEST_SEED=%u repeats it)\n", seed, seed);
    rng_state = 0x9e3779b97f4a7c15ull ^ ((uint64_t)seed * 0xbf58476d1ce4e5b9ull);
    if (!rng_state)
        rng_state = 1;
    RUN(test_thin_branches);
    RUN(test_fine_mesh);
    RUN(test_spd);
    RUN(test_far_light_casts);
    RUN(test_light_near_a_primitive);
    RUN(test_light_on_a_sphere);
    RUN(test_far_speck);
    RUN(test_needle_near_light);
    RUN(test_light_on_a_far_ball);
    RUN(test_least_answers);
#ifdef RTP_HAVE_OSMESA
    RUN(test_osmesa_leaves_the_callers_context);
#endif
    return check_report();
}
