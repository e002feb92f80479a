/* test_kdtree.c — intersection routines and the kd-tree: the tree against
 * brute force, watertightness of closed meshes, self-intersection
 * avoidance, sphere precision, cones, and allocation failures.
 * Randomised: the seed is printed; RTP_SEED=N replays a run. */
#include "internal.h"
#include "check.h"
#include "dircube.h"
#include "shadow.h"
#include "kdtree.h"

#include <time.h>

/* ------------------------------------------------------------- helpers */

typedef struct rng {
    uint64_t s;
} rng;

static double rnd(rng *r) /* [0,1) */
{
    r->s ^= r->s >> 12;
    r->s ^= r->s << 25;
    r->s ^= r->s >> 27;
    return (double)((r->s * 2685821657736338717ull) >> 11) * (1.0 / 9007199254740992.0);
}

static double rndr(rng *r, double a, double b) { return a + (b - a) * rnd(r); }

static rtpi_v3 rnd_dir(rng *r)
{
    for (;;) {
        rtpi_v3 v = v3(rndr(r, -1, 1), rndr(r, -1, 1), rndr(r, -1, 1));
        double l = v3_dot(v, v);
        if (l > 1e-4 && l <= 1.0)
            return v3_mul(v, 1.0 / sqrt(l));
    }
}

static uint64_t g_seed;

static rtp_scene *new_scene(void)
{
    rtp_scene *s = NULL;
    if (rtpi_scene_create(NULL, &s) != RTP_OK)
        return NULL;
    return s;
}

static uint32_t add_v(rtp_scene *s, double x, double y, double z)
{
    rtpi_scene_add_pos(s, x, y, z);
    return (uint32_t)(s->npos - 1);
}

static void add_t(rtp_scene *s, uint32_t a, uint32_t b, uint32_t c)
{
    rtpi_tri t;
    int k;
    for (k = 0; k < 3; k++)
        t.n[k] = t.t[k] = RTPI_NONE;
    t.v[0] = a;
    t.v[1] = b;
    t.v[2] = c;
    t.mat = 0;
    rtpi_scene_add_tri(s, &t);
}

static void add_sphere(rtp_scene *s, double x, double y, double z, double r)
{
    rtpi_sphere sp;
    sp.c[0] = (float)x;
    sp.c[1] = (float)y;
    sp.c[2] = (float)z;
    sp.r = (float)r;
    sp.mat = 0;
    rtpi_scene_add_sphere(s, &sp);
}

static void add_cone(rtp_scene *s, rtpi_v3 b, double rb, rtpi_v3 a, double ra)
{
    rtpi_cone c;
    c.base[0] = (float)b.x;
    c.base[1] = (float)b.y;
    c.base[2] = (float)b.z;
    c.apex[0] = (float)a.x;
    c.apex[1] = (float)a.y;
    c.apex[2] = (float)a.z;
    c.rb = (float)rb;
    c.ra = (float)ra;
    c.mat = 0;
    rtpi_scene_add_cone(s, &c);
}

static int brute(const rtp_scene *s, const rtpi_ray *ray, rtpi_hit *hit)
{
    rtpi_ray r = *ray;
    rtpi_hit h;
    size_t i, n = rtpi_scene_nprims(s);
    int found = 0;
    for (i = 0; i < n; i++) {
        if (rtpi_intersect_prim(s, (uint32_t)i, &r, &h)) {
            *hit = h;
            r.tmax = h.t;
            found = 1;
        }
    }
    return found;
}

static rtpi_ray mkray(rtpi_v3 o, rtpi_v3 d)
{
    rtpi_ray r;
    r.o = o;
    r.d = d;
    r.tmin = 0.0;
    r.tmax = HUGE_VAL;
    return r;
}

/* Compares tree and brute force on one ray; returns 1 on agreement.  When
   two primitives are hit at the same t (a shared edge) either may win, so
   the t values are compared, with room for nothing but rounding. */
static int agree(const rtp_scene *s, const rtpi_kdtree *kd, const rtpi_ray *r)
{
    rtpi_hit a, b;
    int ha = rtpi_kd_intersect(kd, r, &a);
    int hb = brute(s, r, &b);
    int occ = rtpi_kd_occluded(kd, r, RTPI_NONE);
    if (ha != hb || occ != hb)
        return 0;
    if (!ha)
        return 1;
    if (a.prim == b.prim)
        return a.t == b.t;
    return fabs(a.t - b.t) <= 1e-9 * fabs(b.t) + 1e-12;
}

static int run_rays(const rtp_scene *s, const rtpi_kdtree *kd, rng *g,
                    const double lo[3], const double hi[3], int n, int grid)
{
    int i, bad = 0;
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    for (i = 0; i < n; i++) {
        rtpi_v3 o, d;
        int kind = i % 6;
        o = v3(rndr(g, lo[0] - 0.2 * ext, hi[0] + 0.2 * ext),
               rndr(g, lo[1] - 0.2 * ext, hi[1] + 0.2 * ext),
               rndr(g, lo[2] - 0.2 * ext, hi[2] + 0.2 * ext));
        d = rnd_dir(g);
        if (grid) { /* origins on grid planes: rays run along split planes */
            o = v3(floor(o.x * 4) / 4, floor(o.y * 4) / 4, floor(o.z * 4) / 4);
        }
        if (kind == 1) { /* axis-aligned */
            int ax = (int)(rnd(g) * 3), sg = rnd(g) < 0.5 ? -1 : 1;
            d = v3(ax == 0 ? sg : 0, ax == 1 ? sg : 0, ax == 2 ? sg : 0);
        } else if (kind == 2) { /* one zero component */
            int ax = (int)(rnd(g) * 3);
            if (ax == 0) d.x = 0;
            if (ax == 1) d.y = 0;
            if (ax == 2) d.z = 0;
        } else if (kind == 3 && s->ntris > 0) { /* at a vertex or an edge */
            const rtpi_tri *t = &s->tris[(size_t)(rnd(g) * (double)s->ntris)];
            rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)t->v[0]);
            rtpi_v3 p1 = v3_from_f(s->pos + 3 * (size_t)t->v[1]);
            rtpi_v3 target = rnd(g) < 0.5 ? p0 : v3_mul(v3_add(p0, p1), 0.5);
            d = v3_sub(target, o);
        } else if (kind == 4) { /* not unit length, with a zero component */
            d = v3_mul(d, rndr(g, 1e-3, 1e3));
            d.y = 0;
        }
        if (v3_dot(d, d) == 0.0)
            d = v3(1, 0, 0);
        {
            rtpi_ray r = mkray(o, d);
            if (kind == 5) { /* a finite segment */
                r.tmin = rndr(g, 0, 0.5 * ext);
                r.tmax = r.tmin + rndr(g, 0, ext);
            }
            if (!agree(s, kd, &r)) {
                if (bad < 5)
                    fprintf(stderr,
                            "  disagree: o=(%.17g,%.17g,%.17g) d=(%.17g,%.17g,%.17g)\n",
                            o.x, o.y, o.z, d.x, d.y, d.z);
                bad++;
            }
        }
    }
    return bad;
}

static void scene_bounds(const rtp_scene *s, double lo[3], double hi[3])
{
    size_t i, n = rtpi_scene_nprims(s);
    int k;
    for (k = 0; k < 3; k++) {
        lo[k] = 1e300;
        hi[k] = -1e300;
    }
    for (i = 0; i < n; i++) {
        double a[3], b[3];
        rtpi_prim_bounds(s, (uint32_t)i, a, b);
        for (k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], a[k]);
            hi[k] = fmax(hi[k], b[k]);
        }
    }
}

static void check_scene_vs_brute(rtp_scene *s, rng *g, int nrays, int grid)
{
    rtpi_kdtree *kd = NULL;
    double lo[3], hi[3];
    int bad;
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (!kd)
        return;
    scene_bounds(s, lo, hi);
    bad = run_rays(s, kd, g, lo, hi, nrays, grid);
    CHECK_MSG(bad == 0, "%d of %d rays disagree (seed %llu)", bad, nrays,
              (unsigned long long)g_seed);
    rtpi_kd_destroy(kd);
}

/* --------------------------------------------------------------- tests */

static void test_empty(void)
{
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    rtpi_ray r = mkray(v3(0, 0, 0), v3(1, 0, 0));
    rtpi_hit h;
    CHECK(s != NULL);
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    CHECK(kd != NULL);
    if (kd) {
        CHECK(!rtpi_kd_intersect(kd, &r, &h));
        CHECK(!rtpi_kd_occluded(kd, &r, RTPI_NONE));
        rtpi_kd_get_stats(kd, &st);
        CHECK(st.prim_refs == 0);
    }
    rtpi_kd_destroy(kd);
    rtpi_kd_destroy(NULL);
    rtp_scene_destroy(s);
}

static void test_soup(void)
{
    rng g;
    rtp_scene *s = new_scene();
    int i;
    g.s = g_seed ^ 0x1111;
    for (i = 0; i < 600; i++) {
        rtpi_v3 c = v3(rnd(&g), rnd(&g), rnd(&g));
        double sz = rnd(&g) < 0.1 ? 0.5 : 0.05;
        uint32_t a = add_v(s, c.x, c.y, c.z);
        uint32_t b = add_v(s, c.x + rndr(&g, -sz, sz), c.y + rndr(&g, -sz, sz),
                           c.z + rndr(&g, -sz, sz));
        uint32_t d = add_v(s, c.x + rndr(&g, -sz, sz), c.y + rndr(&g, -sz, sz),
                           c.z + rndr(&g, -sz, sz));
        if (i % 50 == 0) /* zero area: never hit */
            d = b;
        add_t(s, a, b, d);
    }
    check_scene_vs_brute(s, &g, 6000, 0);
    rtp_scene_destroy(s);
}

/* Unit-grid-aligned axis-parallel quads: triangles lie in split planes,
   and rays with grid origins run along them. */
static void test_grid(void)
{
    rng g;
    rtp_scene *s = new_scene();
    int i;
    g.s = g_seed ^ 0x2222;
    for (i = 0; i < 400; i++) {
        int ax = i % 3;
        double x = floor(rnd(&g) * 8) / 4, y = floor(rnd(&g) * 8) / 4,
               z = floor(rnd(&g) * 8) / 4, w = 0.25 * (1 + (i % 3));
        uint32_t a, b, c, d;
        if (ax == 0) {
            a = add_v(s, x, y, z);
            b = add_v(s, x, y + w, z);
            c = add_v(s, x, y + w, z + w);
            d = add_v(s, x, y, z + w);
        } else if (ax == 1) {
            a = add_v(s, x, y, z);
            b = add_v(s, x + w, y, z);
            c = add_v(s, x + w, y, z + w);
            d = add_v(s, x, y, z + w);
        } else {
            a = add_v(s, x, y, z);
            b = add_v(s, x + w, y, z);
            c = add_v(s, x + w, y + w, z);
            d = add_v(s, x, y + w, z);
        }
        add_t(s, a, b, c);
        add_t(s, a, c, d);
    }
    check_scene_vs_brute(s, &g, 8000, 1);
    rtp_scene_destroy(s);
}

/* Many axis-parallel quads on the planes x, y or z = k/32 of a unit box:
   the large nodes choose binned planes, which are then exactly these
   planes, so triangles lie in the binned split planes as well as in the
   exact ones below, and rays with grid origins run along them. */
static void test_bin_planes(void)
{
    rng g;
    rtp_scene *s = new_scene();
    int i;
    g.s = g_seed ^ 0x2323;
    add_t(s, add_v(s, 0, 0, 0), add_v(s, 1, 0, 0), add_v(s, 0, 1, 0));
    add_t(s, add_v(s, 1, 1, 1), add_v(s, 0, 1, 1), add_v(s, 1, 0, 1));
    for (i = 0; i < 1500; i++) {
        int ax = i % 3;
        double x = floor(rnd(&g) * 31) / 32, y = floor(rnd(&g) * 31) / 32,
               z = floor(rnd(&g) * 31) / 32, w = (1 + (i % 2)) / 32.0;
        uint32_t a, b, c, d;
        if (ax == 0) {
            a = add_v(s, x, y, z);
            b = add_v(s, x, y + w, z);
            c = add_v(s, x, y + w, z + w);
            d = add_v(s, x, y, z + w);
        } else if (ax == 1) {
            a = add_v(s, x, y, z);
            b = add_v(s, x + w, y, z);
            c = add_v(s, x + w, y, z + w);
            d = add_v(s, x, y, z + w);
        } else {
            a = add_v(s, x, y, z);
            b = add_v(s, x + w, y, z);
            c = add_v(s, x + w, y + w, z);
            d = add_v(s, x, y + w, z);
        }
        add_t(s, a, b, c);
        add_t(s, a, c, d);
    }
    check_scene_vs_brute(s, &g, 8000, 1);
    rtp_scene_destroy(s);
}

static void test_spheres_cones(void)
{
    rng g;
    rtp_scene *s = new_scene();
    int i;
    g.s = g_seed ^ 0x3333;
    for (i = 0; i < 120; i++) {
        double r = rndr(&g, 0.01, 0.15);
        add_sphere(s, rnd(&g), rnd(&g), rnd(&g), i % 7 == 0 ? -r : r);
    }
    for (i = 0; i < 120; i++) {
        rtpi_v3 b = v3(rnd(&g), rnd(&g), rnd(&g));
        rtpi_v3 a = v3_add(b, v3_mul(rnd_dir(&g), rndr(&g, 0.05, 0.3)));
        double rb = rndr(&g, 0.01, 0.1), ra = i % 3 == 0 ? rb : i % 3 == 1 ? 0 : rndr(&g, 0, 0.1);
        if (i % 10 == 0) /* axis-aligned cylinders */
            a = v3(b.x, b.y, b.z + 0.25);
        add_cone(s, b, rb, a, ra);
    }
    for (i = 0; i < 100; i++) {
        rtpi_v3 c = v3(rnd(&g), rnd(&g), rnd(&g));
        add_t(s, add_v(s, c.x, c.y, c.z), add_v(s, c.x + 0.1, c.y, c.z),
              add_v(s, c.x, c.y + 0.1, c.z + 0.05));
    }
    check_scene_vs_brute(s, &g, 8000, 0);
    rtp_scene_destroy(s);
}

/* Icosphere with `level` subdivisions around (c,c,c), radius 1. */
static void icosphere(rtp_scene *s, double c, int level)
{
    static const double X = 0.525731112119133606, Z = 0.850650808352039932;
    static const double v0[12][3] = {
        {-X, 0, Z}, {X, 0, Z}, {-X, 0, -Z}, {X, 0, -Z}, {0, Z, X}, {0, Z, -X},
        {0, -Z, X}, {0, -Z, -X}, {Z, X, 0}, {-Z, X, 0}, {Z, -X, 0}, {-Z, -X, 0}};
    static const int f0[20][3] = {
        {0, 4, 1}, {0, 9, 4}, {9, 5, 4}, {4, 5, 8}, {4, 8, 1}, {8, 10, 1}, {8, 3, 10},
        {5, 3, 8}, {5, 2, 3}, {2, 7, 3}, {7, 10, 3}, {7, 6, 10}, {7, 11, 6}, {11, 0, 6},
        {0, 1, 6}, {6, 1, 10}, {9, 0, 11}, {9, 11, 2}, {9, 2, 5}, {7, 2, 11}};
    /* Recursive subdivision without shared midpoints would leave cracks, so
       subdivide each face into a grid of level+1 rows with shared points. */
    int f, i, j, n = level + 1;
    for (f = 0; f < 20; f++) {
        uint32_t idx[64][64];
        rtpi_v3 a = v3(v0[f0[f][0]][0], v0[f0[f][0]][1], v0[f0[f][0]][2]);
        rtpi_v3 b = v3(v0[f0[f][1]][0], v0[f0[f][1]][1], v0[f0[f][1]][2]);
        rtpi_v3 cc = v3(v0[f0[f][2]][0], v0[f0[f][2]][1], v0[f0[f][2]][2]);
        for (i = 0; i <= n; i++) {
            for (j = 0; j <= n - i; j++) {
                /* Summed in corner-id order so that a point on an edge
                   shared by two faces comes out bit-identical in both. */
                int id[3], m1, m2;
                double wt[3];
                rtpi_v3 p = v3(0, 0, 0), cv[3];
                id[0] = f0[f][0], id[1] = f0[f][1], id[2] = f0[f][2];
                wt[0] = (double)(n - i - j) / n, wt[1] = (double)i / n, wt[2] = (double)j / n;
                cv[0] = a, cv[1] = b, cv[2] = cc;
                for (m1 = 0; m1 < 12; m1++)
                    for (m2 = 0; m2 < 3; m2++)
                        if (id[m2] == m1 && wt[m2] != 0.0)
                            p = v3_add(p, v3_mul(cv[m2], wt[m2]));
                p = v3_norm(p);
                idx[i][j] = add_v(s, p.x + c, p.y + c, p.z + c);
            }
        }
        for (i = 0; i < n; i++) {
            for (j = 0; j < n - i; j++) {
                add_t(s, idx[i][j], idx[i + 1][j], idx[i][j + 1]);
                if (j + 1 < n - i)
                    add_t(s, idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]);
            }
        }
    }
}

/* The shared edges of the face grids above do not share vertex indices
   between faces (each face makes its own): that is a float-exact copy of
   the same point, which is what matters for watertightness. */

static void cube(rtp_scene *s, double c, int n)
{
    int f, i, j;
    for (f = 0; f < 6; f++) {
        int ax = f / 2;
        double sg = f % 2 ? 1.0 : -1.0;
        uint32_t idx[17][17];
        for (i = 0; i <= n; i++) {
            for (j = 0; j <= n; j++) {
                double p[3], u = -1 + 2.0 * i / n, v = -1 + 2.0 * j / n;
                p[ax] = sg;
                p[(ax + 1) % 3] = u;
                p[(ax + 2) % 3] = v * sg;
                idx[i][j] = add_v(s, p[0] + c, p[1] + c, p[2] + c);
            }
        }
        for (i = 0; i < n; i++) {
            for (j = 0; j < n; j++) {
                add_t(s, idx[i][j], idx[i + 1][j], idx[i + 1][j + 1]);
                add_t(s, idx[i][j], idx[i + 1][j + 1], idx[i][j + 1]);
            }
        }
    }
}

static int shoot_closed(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 o)
{
    size_t i;
    int k, miss = 0;
    for (i = 0; i < s->ntris; i++) {
        const rtpi_tri *t = &s->tris[i];
        for (k = 0; k < 3; k++) {
            rtpi_v3 a = v3_from_f(s->pos + 3 * (size_t)t->v[k]);
            rtpi_v3 b = v3_from_f(s->pos + 3 * (size_t)t->v[(k + 1) % 3]);
            rtpi_ray r1 = mkray(o, v3_sub(a, o));
            rtpi_ray r2 = mkray(o, v3_sub(v3_mul(v3_add(a, b), 0.5), o));
            rtpi_hit h;
            if (!rtpi_kd_intersect(kd, &r1, &h) || !rtpi_kd_occluded(kd, &r1, RTPI_NONE))
                miss++;
            if (!rtpi_kd_intersect(kd, &r2, &h) || !rtpi_kd_occluded(kd, &r2, RTPI_NONE))
                miss++;
            if (i % 7 == 0 && !brute(s, &r2, &h))
                miss++;
        }
    }
    return miss;
}

static void test_closed_meshes(void)
{
    static const double offs[3] = {0.0, 1e3, 1e5};
    rng g;
    int oi, m, j;
    g.s = g_seed ^ 0x4444;
    for (m = 0; m < 2; m++) {
        for (oi = 0; oi < 3; oi++) {
            rtp_scene *s = new_scene();
            rtpi_kdtree *kd = NULL;
            double c = offs[oi];
            int miss = 0;
            if (m == 0)
                icosphere(s, c, 7);
            else
                cube(s, c, 8);
            CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
            if (!kd) {
                rtp_scene_destroy(s);
                continue;
            }
            /* The centre (on many split planes) and random inner points. */
            for (j = 0; j < 4; j++) {
                rtpi_v3 o = v3(c, c, c);
                if (j > 0)
                    o = v3_add(o, v3_mul(rnd_dir(&g), rndr(&g, 0, 0.5)));
                miss += shoot_closed(s, kd, o);
            }
            CHECK_MSG(miss == 0, "%s at offset %g: %d rays escaped (seed %llu)",
                      m ? "cube" : "icosphere", c, miss,
                      (unsigned long long)g_seed);
            rtpi_kd_destroy(kd);
            rtp_scene_destroy(s);
        }
    }
}

/* A triangle of size `sz` at offset `off` and a neighbour sharing its edge
   p1-p2, folded up by `fold` radians towards the first's front side. */
static void self_case(rng *g, double sz, double off, int *self_hits,
                      int *neighbour_misses, int *tests)
{
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_v3 c = v3(off * rndr(g, 0.5, 1), -off * rndr(g, 0.5, 1), off * rndr(g, -1, 1));
    rtpi_v3 n = rnd_dir(g), e1, e2, p0, p1, p2, q;
    double fold = rndr(g, 0.3, 2.8);
    int i;
    e1 = v3_norm(v3_cross(n, fabs(n.x) < 0.9 ? v3(1, 0, 0) : v3(0, 1, 0)));
    e2 = v3_cross(n, e1);
    p0 = v3_add(c, v3_mul(e1, -sz));
    p1 = v3_add(c, v3_mul(e1, sz));
    p2 = v3_add(c, v3_mul(e2, sz));
    /* Neighbour apex: across edge p1-p2, rotated out of the plane towards n. */
    {
        rtpi_v3 mid = v3_mul(v3_add(p1, p2), 0.5);
        rtpi_v3 out = v3_norm(v3_sub(mid, p0));
        q = v3_add(mid, v3_mul(v3_add(v3_mul(out, cos(fold)), v3_mul(n, sin(fold))), sz));
    }
    add_t(s, add_v(s, p0.x, p0.y, p0.z), add_v(s, p1.x, p1.y, p1.z),
          add_v(s, p2.x, p2.y, p2.z));
    add_t(s, 1, 3, add_v(s, q.x, q.y, q.z)); /* p1, q, p2 order below */
    s->tris[1].v[0] = 2;
    s->tris[1].v[1] = 1;
    s->tris[1].v[2] = 3;
    if (rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        (*self_hits)++;
        rtp_scene_destroy(s);
        return;
    }
    for (i = 0; i < 40; i++) {
        /* A camera on the front side looks at a random point of tri 0. */
        double b1 = rnd(g), b2 = rnd(g);
        rtpi_v3 f0 = v3_from_f(s->pos), f1 = v3_from_f(s->pos + 3), f2 = v3_from_f(s->pos + 6);
        rtpi_v3 target, eye, d, refl, tang;
        rtpi_ray r;
        rtpi_hit h, h2;
        rtpi_surface su;
        double side;
        int j;
        if (b1 + b2 > 1) {
            b1 = 1 - b1;
            b2 = 1 - b2;
        }
        target = v3_add(f0, v3_add(v3_mul(v3_sub(f1, f0), b1), v3_mul(v3_sub(f2, f0), b2)));
        eye = v3_add(target, v3_mul(v3_add(n, v3_mul(rnd_dir(g), 0.9)), sz * rndr(g, 1, 100)));
        if (i % 4 == 3) /* from the back */
            eye = v3_add(target, v3_sub(target, eye));
        r = mkray(eye, v3_sub(target, eye));
        if (!rtpi_kd_intersect(kd, &r, &h) || h.prim != 0)
            continue; /* the neighbour may be in the way */
        rtpi_surface_at(s, &r, &h, &su);
        side = v3_dot(r.d, su.ng) < 0 ? 1.0 : -1.0;
        d = v3_norm(r.d);
        refl = v3_madd(d, su.ng, -2.0 * v3_dot(d, su.ng));
        tang = v3_norm(v3_madd(d, su.ng, -v3_dot(d, su.ng)));
        for (j = 0; j < 5; j++) {
            rtpi_ray r2;
            rtpi_v3 dir = refl;
            if (j == 1) /* grazing, just off the plane */
                dir = v3_madd(tang, su.ng, side * 1e-7);
            else if (j == 2) /* exactly along the plane */
                dir = tang;
            else if (j == 3) /* random into the same half-space */
                dir = v3_madd(rnd_dir(g), su.ng, 0.0);
            if (j == 3 && v3_dot(dir, su.ng) * side < 0)
                dir = v3_madd(dir, su.ng, -2 * v3_dot(dir, su.ng));
            if (j == 4) { /* transmitted: straight on through */
                r2 = mkray(rtpi_offset_origin(su.p, su.ng, -side, rtpi_offset_floor(s, NULL)), d);
            } else {
                r2 = mkray(rtpi_offset_origin(su.p, su.ng, side, rtpi_offset_floor(s, NULL)), dir);
            }
            (*tests)++;
            if (rtpi_kd_intersect(kd, &r2, &h2) && h2.prim == 0)
                (*self_hits)++;
            if (rtpi_intersect_prim(s, 0, &r2, &h2))
                (*self_hits)++;
        }
        /* Rays into the neighbour from the front side still hit it. */
        if (side > 0) {
            rtpi_v3 nq = v3_from_f(s->pos + 9), nb = v3_from_f(s->pos + 3), nc = v3_from_f(s->pos + 6);
            rtpi_v3 aim = v3_mul(v3_add(nq, v3_add(nb, nc)), 1.0 / 3.0);
            rtpi_ray r3 = mkray(rtpi_offset_origin(su.p, su.ng, side, rtpi_offset_floor(s, NULL)), v3_sub(aim, su.p));
            rtpi_v3 nn = v3_norm(v3_cross(v3_sub(nb, nq), v3_sub(nc, nq)));
            /* "Nearby" means farther than the offset itself: geometry
               closer than that is what the offset is meant to jump.  So
               only hit points at least 10 offsets from the neighbour's
               plane count, and rays not too grazing to decide. */
            double off_len = v3_len(v3_sub(r3.o, su.p));
            double dplane = fabs(v3_dot(v3_sub(su.p, nq), nn));
            if (dplane > 10.0 * off_len && fabs(v3_dot(nn, v3_norm(r3.d))) > 1e-3) {
                (*tests)++;
                if (!rtpi_kd_intersect(kd, &r3, &h2) || h2.prim != 1)
                    (*neighbour_misses)++;
            }
        }
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_self_intersection(void)
{
    static const double sizes[] = {1e-3, 1e-2, 1e-1, 1, 1e1, 1e2, 1e3};
    static const double offs[] = {0, 1, 1e2, 1e3, 1e4, 1e5};
    rng g;
    size_t i, j;
    int k, self = 0, nmiss = 0, tests = 0;
    g.s = g_seed ^ 0x5555;
    for (i = 0; i < sizeof sizes / sizeof *sizes; i++) {
        for (j = 0; j < sizeof offs / sizeof *offs; j++) {
            /* Float geometry cannot hold a triangle below ~1e4 float ulps of
               its position; those sizes are not geometry. */
            if (offs[j] > 0 && sizes[i] < 1e-4 * offs[j])
                continue;
            for (k = 0; k < 10; k++)
                self_case(&g, sizes[i], offs[j], &self, &nmiss, &tests);
        }
    }
    CHECK_MSG(self == 0, "%d self-intersections in %d rays (seed %llu)", self,
              tests, (unsigned long long)g_seed);
    CHECK_MSG(nmiss == 0, "%d neighbour misses (seed %llu)", nmiss,
              (unsigned long long)g_seed);
    CHECK(tests > 1000);
}

static void test_sphere_precision(void)
{
    static const double radii[] = {1e-2, 1, 1e2};
    static const double dist[] = {1e3, 1e5};
    rng g;
    size_t i, j;
    int k, bad = 0, nohit = 0, nan = 0;
    double worst = 0;
    g.s = g_seed ^ 0x6666;
    for (i = 0; i < 3; i++) {
        for (j = 0; j < 2; j++) {
            rtp_scene *s = new_scene();
            rtpi_kdtree *kd = NULL;
            double r = radii[i];
            rtpi_v3 c;
            add_sphere(s, rndr(&g, -1, 1) * r, rndr(&g, -1, 1) * r, 3 * r, r);
            c = v3_from_f(s->spheres[0].c);
            r = s->spheres[0].r; /* the float values are the geometry */
            CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
            for (k = 0; k < 2000 && kd; k++) {
                rtpi_v3 o = v3_madd(c, rnd_dir(&g), dist[j] * r);
                rtpi_v3 w = v3_norm(v3_sub(c, o)), e = v3_norm(v3_cross(w, rnd_dir(&g)));
                /* Aim at the disc, often close to the silhouette. */
                double rho = k % 2 ? rndr(&g, 0, 0.99) : 1.0 - pow(10.0, -rndr(&g, 2, 6));
                rtpi_v3 aim = v3_madd(c, e, rho * r);
                rtpi_ray ray = mkray(o, v3_sub(aim, o));
                rtpi_hit h;
                rtpi_surface su;
                double err;
                if (!rtpi_kd_intersect(kd, &ray, &h)) {
                    nohit++;
                    continue;
                }
                rtpi_surface_at(s, &ray, &h, &su);
                err = fabs(v3_len(v3_sub(su.p, c)) - r) / r;
                if (err != err || su.ng.x != su.ng.x)
                    nan++;
                if (err > worst)
                    worst = err;
                if (!(err <= 1e-4) || v3_dot(su.ng, v3_sub(su.p, c)) <= 0 ||
                    v3_dot(su.ng, ray.d) >= 0)
                    bad++;
            }
            rtpi_kd_destroy(kd);
            rtp_scene_destroy(s);
        }
    }
    printf("sphere: worst relative radius error %.3g\n", worst);
    CHECK_MSG(bad == 0, "%d bad sphere hits (seed %llu)", bad, (unsigned long long)g_seed);
    CHECK(nohit == 0);
    CHECK(nan == 0);
    /* Tighter than the 1e-4 asked for: the formulation keeps ~1e-10. */
    CHECK(worst < 1e-8);
}

static void test_inside_sphere(void)
{
    rtp_scene *s = new_scene();
    rtpi_hit h;
    rtpi_surface su;
    rtpi_ray r;
    add_sphere(s, 1, 2, 3, -2);
    /* From outside: only the far side, where the ray leaves. */
    r = mkray(v3(1, 2, -10), v3(0, 0, 1));
    CHECK(rtpi_intersect_prim(s, 0, &r, &h));
    CHECK(fabs(h.t - 15) < 1e-12);
    rtpi_surface_at(s, &r, &h, &su);
    CHECK(fabs(su.ng.z + 1) < 1e-12); /* faces inward, towards the ray */
    /* From inside. */
    r = mkray(v3(1, 2, 3), v3(0, 2, 0));
    CHECK(rtpi_intersect_prim(s, 0, &r, &h));
    CHECK(fabs(h.t - 1) < 1e-12);
    /* Leaving it behind: nothing. */
    r = mkray(v3(1, 2, 10), v3(0, 0, 1));
    CHECK(!rtpi_intersect_prim(s, 0, &r, &h));
    /* A positive sphere from inside hits its far side, outward normal. */
    s->spheres[0].r = 2;
    r = mkray(v3(1, 2, 3), v3(0, 0, -1));
    CHECK(rtpi_intersect_prim(s, 0, &r, &h));
    CHECK(fabs(h.t - 2) < 1e-12);
    r = mkray(v3(1, 2, -10), v3(0, 0, 1));
    CHECK(rtpi_intersect_prim(s, 0, &r, &h));
    CHECK(fabs(h.t - 11) < 1e-12);
    rtpi_surface_at(s, &r, &h, &su);
    CHECK(fabs(su.ng.z + 1) < 1e-12);
    CHECK(su.uv[0] >= 0 && su.uv[0] <= 1 && fabs(su.uv[1]) < 1e-6);
    rtp_scene_destroy(s);
}

/* A random cone for case i: base b, apex a, radii rb and ra (every
   third a cylinder, every third pointed at the apex). */
static void random_cone(rng *g, int i, rtpi_v3 *b, rtpi_v3 *a, double *rb, double *ra)
{
    *b = v3(rndr(g, -5, 5), rndr(g, -5, 5), rndr(g, -5, 5));
    *a = v3_add(*b, v3_mul(rnd_dir(g), rndr(g, 0.5, 3)));
    *rb = rndr(g, 0.1, 1);
    *ra = i % 3 == 0 ? *rb : i % 3 == 1 ? 0 : rndr(g, 0, 1);
}

/* Cone 0 of s as its floats make it (the float values are the geometry):
   base B, unit axis w, height H, radii rb and ra. */
static void cone_floats(const rtp_scene *s, rtpi_v3 *B, rtpi_v3 *w, double *H, double *rb,
                        double *ra)
{
    rtpi_v3 A = v3_from_f(s->cones[0].apex);
    *B = v3_from_f(s->cones[0].base);
    *H = v3_len(v3_sub(A, *B));
    *w = v3_mul(v3_sub(A, *B), 1 / *H);
    *rb = s->cones[0].rb;
    *ra = s->cones[0].ra;
}

static void test_cones(void)
{
    rng g;
    int i, k, hits = 0, bad = 0, nan = 0;
    g.s = g_seed ^ 0x7777;
    for (i = 0; i < 300; i++) {
        rtp_scene *s = new_scene();
        rtpi_v3 b, a, B, w;
        double rb, ra, H;
        random_cone(&g, i, &b, &a, &rb, &ra);
        if (i % 5 == 0) /* axis along a coordinate axis */
            a = v3(b.x, b.y + 2, b.z);
        if (i % 6 == 1) /* apex first */
            rb = 0, ra = 0.7;
        add_cone(s, b, rb, a, ra);
        cone_floats(s, &B, &w, &H, &rb, &ra);
        for (k = 0; k < 200; k++) {
            rtpi_v3 o = v3_madd(B, rnd_dir(&g), rndr(&g, 0.1, 20));
            rtpi_v3 d = v3_sub(v3_madd(B, w, rndr(&g, -0.2, 1.2) * H), o);
            rtpi_hit h;
            rtpi_surface su;
            rtpi_ray r;
            if (k % 10 == 0) /* along the axis */
                d = v3_mul(w, k % 20 ? 1.0 : -1.0), o = v3_madd(B, w, -1);
            if (k % 10 == 1) /* zero components */
                d.x = 0, d.z = 0;
            if (k % 10 == 2) /* origin on the axis, perpendicular ray */
                o = v3_madd(B, w, 0.5 * H), d = v3_cross(w, rnd_dir(&g));
            r = mkray(o, d);
            if (!rtpi_intersect_prim(s, 0, &r, &h))
                continue;
            hits++;
            rtpi_surface_at(s, &r, &h, &su);
            {
                rtpi_v3 f = v3_sub(su.p, B);
                double hh = v3_dot(f, w), rad = v3_len(v3_madd(f, w, -hh));
                double want = rb + (ra - rb) * hh / H;
                double tol = 1e-9 * (10 + H);
                if (h.t != h.t || su.p.x != su.p.x || su.ng.x != su.ng.x ||
                    su.uv[0] != su.uv[0])
                    nan++;
                else if (hh < -tol || hh > H + tol || fabs(rad - want) > tol ||
                         fabs(v3_len(su.ng) - 1) > 1e-9 || h.t < 0)
                    bad++;
                /* Outward normal: away from the axis (or along the axis at
                   a pointed apex). */
                else if (rad > 1e-6 && v3_dot(su.ng, v3_madd(f, w, -hh)) <= 0)
                    bad++;
            }
        }
        rtp_scene_destroy(s);
    }
    CHECK_MSG(bad == 0, "%d cone hits off the surface (seed %llu)", bad,
              (unsigned long long)g_seed);
    CHECK(nan == 0);
    CHECK(hits > 10000);
    /* A cylinder seen along its axis is missed; crossing it hits twice. */
    {
        rtp_scene *s = new_scene();
        rtpi_hit h;
        rtpi_ray r = mkray(v3(0, 0, -5), v3(0, 0, 1));
        add_cone(s, v3(0, 0, 0), 1, v3(0, 0, 2), 1);
        CHECK(!rtpi_intersect_prim(s, 0, &r, &h));
        r = mkray(v3(-5, 0, 1), v3(1, 0, 0));
        CHECK(rtpi_intersect_prim(s, 0, &r, &h) && fabs(h.t - 4) < 1e-12);
        r.tmin = 4.5;
        CHECK(rtpi_intersect_prim(s, 0, &r, &h) && fabs(h.t - 6) < 1e-12);
        r = mkray(v3(-5, 0, 3), v3(1, 0, 0)); /* above the open end */
        CHECK(!rtpi_intersect_prim(s, 0, &r, &h));
        rtp_scene_destroy(s);
    }
}

/* hit_cone turns away lines farther from the cone's middle than its
   bound: rays aimed at points of the surface a millionth of the height
   from either end (within ~1e-6 of that bound), from near and from a
   million heights away, must all still hit, no farther than the point.
   A bound too small (the full height instead of half, the smaller
   radius) or its rounding margin lost at a far origin fails here. */
static void test_cone_bound(void)
{
    rng g;
    int i, k, miss = 0, far = 0;
    g.s = g_seed ^ 0x5151;
    for (i = 0; i < 200; i++) {
        rtp_scene *s = new_scene();
        rtpi_v3 b, a, B, w;
        double rb, ra, H;
        random_cone(&g, i, &b, &a, &rb, &ra);
        if (i % 2)
            rb = ra, ra = rndr(&g, 0.1, 1); /* the wider end either way */
        add_cone(s, b, rb, a, ra);
        cone_floats(s, &B, &w, &H, &rb, &ra);
        for (k = 0; k < 200; k++) {
            /* a point of the surface at height hh, across the axis u */
            double hh = (k % 2 ? 1e-6 : 1 - 1e-6) * H, rad = rb + (ra - rb) * hh / H;
            double dist = H * (k % 3 == 0 ? 2.0 : k % 3 == 1 ? 1e3 : 1e6);
            rtpi_v3 u = v3_norm(v3_cross(w, rnd_dir(&g)));
            rtpi_v3 p = v3_madd(v3_madd(B, w, hh), u, rad);
            /* from outside, within about 30 degrees of the surface's
               normal there (u - k w): a grazing ray may miss the surface
               by rounding whatever the bound, and is not what this tests */
            rtpi_v3 n = v3_norm(v3_madd(u, w, -(ra - rb) / H));
            rtpi_v3 o = v3_madd(p, v3_norm(v3_madd(n, rnd_dir(&g), 0.5)), dist);
            rtpi_ray r = mkray(o, v3_sub(p, o));
            rtpi_hit h;
            if (!(rad > 1e-3))
                continue; /* (a pointed end: no surface to aim at there) */
            if (!rtpi_intersect_prim(s, 0, &r, &h))
                miss++;
            else if (h.t > v3_len(v3_sub(p, o)) * (1 + 1e-9))
                far++;
        }
        rtp_scene_destroy(s);
    }
    CHECK_MSG(miss == 0, "%d rays at a cone's ends missed it (seed %llu)", miss,
              (unsigned long long)g_seed);
    CHECK_MSG(far == 0, "%d rays at a cone's ends hit beyond their point (seed %llu)", far,
              (unsigned long long)g_seed);
}

static void test_shading_normal(void)
{
    rtp_scene *s = new_scene();
    rtpi_tri t;
    rtpi_hit h;
    rtpi_surface su;
    rtpi_ray r = mkray(v3(0.2, 0.2, 1), v3(0, 0, -1));
    int k;
    add_v(s, 0, 0, 0);
    add_v(s, 1, 0, 0);
    add_v(s, 0, 1, 0);
    /* two of the three normals face away from the triangle, and at the
       hit their mix does (a triangle whose normals all face away is
       wound the other way round and turned over instead:
       test_nff's test_clockwise_patch) */
    rtpi_scene_add_nrm(s, 0.3, 0, -1);
    rtpi_scene_add_nrm(s, 0.3, 0, 0.2);
    for (k = 0; k < 3; k++) {
        t.v[k] = (uint32_t)k;
        t.n[k] = k < 2 ? 0 : 1;
        t.t[k] = RTPI_NONE;
    }
    t.mat = 0;
    rtpi_scene_add_tri(s, &t);
    CHECK(rtpi_intersect_prim(s, 0, &r, &h));
    CHECK(fabs(h.u - 0.2) < 1e-12 && fabs(h.v - 0.2) < 1e-12);
    rtpi_surface_at(s, &r, &h, &su);
    CHECK(fabs(su.ng.z - 1) < 1e-12);
    CHECK(su.ns.z > 0 && fabs(v3_len(su.ns) - 1) < 1e-12);
    CHECK(su.ns.x > 0); /* keeps its lean */
    rtp_scene_destroy(s);
}

/* Fails the n-th allocation; counts what is live. */
typedef struct fail_alloc {
    long left, live;
} fail_alloc;

static void *fa_malloc(void *u, size_t n)
{
    fail_alloc *f = (fail_alloc *)u;
    void *p;
    if (f->left-- <= 0)
        return NULL;
    p = malloc(n);
    if (p)
        f->live++;
    return p;
}

static void *fa_realloc(void *u, void *p, size_t n)
{
    fail_alloc *f = (fail_alloc *)u;
    void *q;
    if (f->left-- <= 0)
        return NULL;
    q = realloc(p, n);
    if (q && !p)
        f->live++;
    return q;
}

static void fa_free(void *u, void *p)
{
    fail_alloc *f = (fail_alloc *)u;
    if (p)
        f->live--;
    free(p);
}

static void test_nomem(void)
{
    rng g;
    rtp_scene *s = new_scene();
    int i, ok = 0, leaks = 0, wrong = 0;
    long n;
    g.s = g_seed ^ 0x8888;
    for (i = 0; i < 3000; i++) {
        rtpi_v3 c = v3(rnd(&g), rnd(&g), rnd(&g));
        add_t(s, add_v(s, c.x, c.y, c.z), add_v(s, c.x + 0.05, c.y, c.z),
              add_v(s, c.x, c.y + 0.05, c.z + 0.02));
    }
    add_sphere(s, 0.5, 0.5, 0.5, 0.1);
    for (i = 0; i < 40; i++) /* copies of the first: the build starts again (kd_group) */
        add_t(s, 0, 1, 2);
    for (n = 0; n < 100000 && !ok; n++) {
        fail_alloc f;
        rtp_allocator a;
        rtpi_kdtree *kd = NULL;
        rtp_status st;
        f.left = n;
        f.live = 0;
        a.malloc_fn = fa_malloc;
        a.realloc_fn = fa_realloc;
        a.free_fn = fa_free;
        a.user = &f;
        st = rtpi_kd_build(s, &a, &kd, NULL);
        if (st == RTP_OK) {
            ok = 1;
            rtpi_kd_destroy(kd);
        } else if (st != RTP_ERR_NOMEM || kd != NULL) {
            wrong++;
        }
        if (f.live != 0)
            leaks++;
    }
    CHECK(ok);
    CHECK(leaks == 0);
    CHECK(wrong == 0);
    rtp_scene_destroy(s);
}

/* A fan of slivers in the plane y = 0 (a convex polygon triangulated from
   one corner): SAH alone asked for cells a sliver wide near the apex, N^2
   of them (4,000 slivers: 5.8 M references; 64,000: 829 M and 11 GB).
   The reference budget holds it to KD_REF_BUDGET a primitive, and the
   tree still answers as the brute force does. */
static void test_fan_budget(void)
{
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    const int n = 4000;
    int i;
    uint32_t apex, prev;
    g.s = g_seed ^ 0x7777;
    apex = add_v(s, 3.0, 0.0, 0.0);
    prev = add_v(s, 3.0 * cos(2.0 * 3.14159265358979 / (n + 2)), 0.0,
                 3.0 * sin(2.0 * 3.14159265358979 / (n + 2)));
    for (i = 2; i <= n + 1; i++) {
        double a = 2.0 * 3.14159265358979 * i / (n + 2);
        uint32_t v = add_v(s, 3.0 * cos(a), 0.0, 3.0 * sin(a));
        add_t(s, apex, prev, v);
        prev = v;
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        rtpi_kd_get_stats(kd, &st);
        /* KD_REF_BUDGET a triangle and KD_REF_FLOOR */
        CHECK_MSG(st.prim_refs <= 16 * (size_t)n + 2097152, "%lu references for %d slivers",
                  (unsigned long)st.prim_refs, n);
        rtpi_kd_destroy(kd);
    }
    check_scene_vs_brute(s, &g, 3000, 0);
    rtp_scene_destroy(s);
}

/* A pipe of long thin triangles along the diagonal (1,1,0), and a ball.
   Each triangle's box spans the pipe's whole box in x and y, so every
   plane straddled them all and the box SAH made the scene one leaf: each
   ray tested every triangle (a pipe of 4,000: 23 s a frame, 0.1 s along
   x).  Clipped parts of a diagonal triangle do fit in smaller boxes; the
   tree must find them: a leaf holds a quarter of the pipe at most on
   average (55 references here; 600, all of it, before), and rays are
   answered as the brute force does. */
static void test_diagonal_pipe(void)
{
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    const int m = 300; /* around */
    const double len = 20.0, rad = 0.05, pi = 3.14159265358979;
    int i;
    g.s = g_seed ^ 0x9191;
    for (i = 0; i < m; i++) {
        /* the axis along (1,1,0)/sqrt 2, the ring in the plane of
           (-1,1,0)/sqrt 2 and z */
        double a0 = 2.0 * pi * i / m, a1 = 2.0 * pi * (i + 1) / m;
        double h = 0.5 * len / sqrt(2.0), q = 1.0 / sqrt(2.0);
        uint32_t v[4];
        int e;
        for (e = 0; e < 4; e++) {
            double a = e & 1 ? a1 : a0, sg = e & 2 ? 1.0 : -1.0;
            double u = rad * cos(a), z = 0.5 + rad * sin(a);
            v[e] = add_v(s, sg * h - u * q, sg * h + u * q, z);
        }
        add_t(s, v[0], v[1], v[3]);
        add_t(s, v[0], v[3], v[2]);
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        size_t full;
        rtpi_kd_get_stats(kd, &st);
        full = st.leaves - st.empty_leaves;
        CHECK_MSG(st.leaves > 1 && full > 0 && st.prim_refs / full <= (size_t)m / 2,
                  "%lu leaves (%lu empty), %lu references for %d triangles",
                  (unsigned long)st.leaves, (unsigned long)st.empty_leaves,
                  (unsigned long)st.prim_refs, 2 * m);
        rtpi_kd_destroy(kd);
    }
    check_scene_vs_brute(s, &g, 3000, 0);
    rtp_scene_destroy(s);
}

/* A stack of parallel quads, as shelves or a pile of sheets are: each
   half of the slab is nearly as large as the whole (0.94 of its surface
   here), so the box SAH, which prices a ray through every quad of a
   leaf, left the split short of KD_LEAF_MARGIN and the stack two leaves of
   half its quads each (16,000 of them traced 256x256 in 5.8 s, 0.04 s
   split).  A ray stops at the
   first quad it hits: splits that part the quads without cutting one
   (split_clean) are taken, and a leaf holds a few triangles (8 a leaf
   here; 500 before, in two leaves). */
static void test_stacked_quads(void)
{
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    const int m = 500;
    int i;
    g.s = g_seed ^ 0x5151;
    for (i = 0; i < m; i++) {
        double z = (double)i / m;
        uint32_t a = add_v(s, -2, -2, z), b = add_v(s, 2, -2, z), c = add_v(s, 2, 2, z),
                 d = add_v(s, -2, 2, z);
        add_t(s, a, b, c);
        add_t(s, a, c, d);
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        size_t full;
        rtpi_kd_get_stats(kd, &st);
        full = st.leaves - st.empty_leaves;
        printf("stack of %d quads: %lu leaves (%lu empty), %lu references\n", m,
               (unsigned long)st.leaves, (unsigned long)st.empty_leaves,
               (unsigned long)st.prim_refs);
        CHECK_MSG(full > 0 && st.prim_refs / full <= 16,
                  "%lu leaves (%lu empty), %lu references for %d triangles",
                  (unsigned long)st.leaves, (unsigned long)st.empty_leaves,
                  (unsigned long)st.prim_refs, 2 * m);
        rtpi_kd_destroy(kd);
    }
    check_scene_vs_brute(s, &g, 3000, 0);
    rtp_scene_destroy(s);
}

/* Primitives no split can part: 20,000 copies of one triangle (shared
   vertices, vertices of their own, rotated and reversed: the same three
   points), as an exporter's duplicated faces or a mesh included twice in
   one place give.  The SAH priced each cell at 20,000 tests and cut the
   empty space around the triangle until the reference budget stopped it,
   every leaf holding all of them (1.3 M references in 471 nodes); built as one
   triangle they are one leaf.  With others about (a triangle through the
   copies, 500 copies of a sphere, a few triangles apart) the copies still
   count as one; triangles that only share a box with each other (a fan
   over its diagonal) are not alike and are still parted.  Every tree
   answers as the brute force does. */
static void test_alike(void)
{
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    const int n = 20000;
    const double P[3][3] = {{0, 0, 0}, {1, 0.2, 0.1}, {0.3, 1, 0.5}};
    uint32_t a, b, c;
    int i;
    g.s = g_seed ^ 0xa11e;
    a = add_v(s, P[0][0], P[0][1], P[0][2]);
    b = add_v(s, P[1][0], P[1][1], P[1][2]);
    c = add_v(s, P[2][0], P[2][1], P[2][2]);
    for (i = 0; i < n; i++) {
        if (i % 4 == 1) {
            a = add_v(s, P[0][0], P[0][1], P[0][2]);
            b = add_v(s, P[1][0], P[1][1], P[1][2]);
            c = add_v(s, P[2][0], P[2][1], P[2][2]);
        }
        if (i % 4 == 2)
            add_t(s, b, c, a);
        else if (i % 4 == 3)
            add_t(s, a, c, b);
        else
            add_t(s, a, b, c);
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        rtpi_kd_get_stats(kd, &st);
        printf("%d copies of a triangle: %lu nodes, %lu references\n", n,
               (unsigned long)st.nodes, (unsigned long)st.prim_refs);
        CHECK_MSG(st.nodes == 1 && st.prim_refs == (size_t)n,
                  "%lu nodes, %lu references for %d copies", (unsigned long)st.nodes,
                  (unsigned long)st.prim_refs, n);
        rtpi_kd_destroy(kd);
        kd = NULL;
    }
    check_scene_vs_brute(s, &g, 300, 0);

    /* a triangle through the copies, copies of a sphere, some apart */
    add_t(s, add_v(s, 0.5, -0.5, 0.6), add_v(s, 0.4, 1.5, 0.5), add_v(s, 0.2, 0.3, -0.8));
    for (i = 0; i < 500; i++)
        add_sphere(s, 2.0, 0.5, 0.2, 0.3);
    for (i = 0; i < 40; i++) {
        double x = rndr(&g, -3, 3), y = rndr(&g, 2, 4), z = rndr(&g, -1, 1);
        add_t(s, add_v(s, x, y, z), add_v(s, x + 0.3, y, z), add_v(s, x, y + 0.2, z + 0.1));
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        size_t np = rtpi_scene_nprims(s);
        rtpi_kd_get_stats(kd, &st);
        printf("  with others: %lu nodes, %lu references for %lu primitives\n",
               (unsigned long)st.nodes, (unsigned long)st.prim_refs, (unsigned long)np);
        /* the copies in a leaf or two (the crossing triangle's cells) */
        CHECK_MSG(st.prim_refs <= 2 * np, "%lu references for %lu primitives",
                  (unsigned long)st.prim_refs, (unsigned long)np);
        rtpi_kd_destroy(kd);
        kd = NULL;
    }
    check_scene_vs_brute(s, &g, 300, 0);
    rtp_scene_destroy(s);

    /* a fan over one box: apexes along the anti-diagonal of the unit
       square, all sharing the diagonal */
    s = new_scene();
    for (i = 0; i < 2000; i++) {
        double f = (i + 0.5) / 2000;
        add_t(s, add_v(s, 0, 0, 0), add_v(s, 1, 1, 0), add_v(s, f, 1 - f, 0));
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        rtpi_kd_get_stats(kd, &st);
        CHECK_MSG(st.leaves > 8, "a fan over one box: %lu leaves", (unsigned long)st.leaves);
        rtpi_kd_destroy(kd);
    }
    check_scene_vs_brute(s, &g, 1000, 0);
    rtp_scene_destroy(s);
}

/* Copies among other primitives weigh as what they are: 2 large
   triangles of C copies each through 4,000 small ones.  Weighing one, a
   group was cut wherever the small triangles asked for it, each cell
   listing all C (C = 200: 15 times the references of the scene with one
   copy each, 69 k; C = 3,000 with 20,000 small: 4.1 M); weighing C, the
   copies stay in a few cells and the small triangles around them are
   left in those leaves (2.1 times).  The bound: at most 3 times the
   one-copy scene's references. */
static void alike_among_scene(rtp_scene *s, uint64_t seed, int copies)
{
    static const double B[2][9] = {{0, 0, 0.1, 1, 0.1, 0.9, 0.4, 1, 0.5},
                                   {1, 0, 0.2, 0.1, 0.9, 0.1, 0.6, 1, 0.95}};
    rng g;
    int i, t;
    g.s = seed;
    for (i = 0; i < 4000; i++) {
        double x = rnd(&g), y = rnd(&g), z = rnd(&g);
        add_t(s, add_v(s, x, y, z), add_v(s, x + 0.02 * rnd(&g), y + 0.02 * rnd(&g), z),
              add_v(s, x, y + 0.02 * rnd(&g), z + 0.02 * rnd(&g)));
    }
    for (t = 0; t < 2; t++) {
        const double *v = B[t];
        uint32_t a = add_v(s, v[0], v[1], v[2]), b = add_v(s, v[3], v[4], v[5]),
                 c = add_v(s, v[6], v[7], v[8]);
        for (i = 0; i < copies; i++)
            add_t(s, a, b, c);
    }
}

static void test_alike_among(void)
{
    const int copies = 200;
    size_t refs[2] = {0, 0};
    rng g;
    int pass;
    g.s = g_seed ^ 0xa1a2;
    for (pass = 0; pass < 2; pass++) {
        rtp_scene *s = new_scene();
        rtpi_kdtree *kd = NULL;
        rtpi_kd_stats st;
        alike_among_scene(s, g_seed ^ 0x5eed, pass ? copies : 1);
        CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
        if (kd) {
            rtpi_kd_get_stats(kd, &st);
            refs[pass] = st.prim_refs;
            rtpi_kd_destroy(kd);
        }
        if (pass)
            check_scene_vs_brute(s, &g, 1000, 0);
        rtp_scene_destroy(s);
    }
    printf("2 triangles of %d copies among 4,000: %lu references, %lu with one copy each\n",
           copies, (unsigned long)refs[1], (unsigned long)refs[0]);
    CHECK_MSG(refs[0] > 0 && refs[1] <= 3 * refs[0],
              "%lu references with %d copies, %lu with one (seed %llu)",
              (unsigned long)refs[1], copies, (unsigned long)refs[0],
              (unsigned long long)g_seed);
}

/* Copies that make a leaf with no look-ahead met (kd_group never groups
   them) are listed ascending there, so that of hits at one t the last
   copy wins, as in brute force (each copy may have its own material): a
   triangle of 5,000 copies among 2,000 small ones, one fixed scene whose
   partitions left the copies' leaf out of order (282 of 600 rays hit
   another copy than brute force's; of random scenes, a few in 20 do).
   Rays at the copies, from the seed, must hit brute force's primitive. */
static void test_copies_leaf_order(void)
{
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rng g;
    int i, bad = 0, hits = 0;
    uint32_t a, b, c;
    g.s = 3 ^ 0xc0b1e5;
    for (i = 0; i < 2000; i++) {
        double x = rnd(&g), y = rnd(&g), z = rnd(&g);
        add_t(s, add_v(s, x, y, z),
              add_v(s, x + rndr(&g, -0.06, 0.06), y + rndr(&g, -0.06, 0.06),
                    z + rndr(&g, -0.06, 0.06)),
              add_v(s, x + rndr(&g, -0.06, 0.06), y + rndr(&g, -0.06, 0.06),
                    z + rndr(&g, -0.06, 0.06)));
    }
    a = add_v(s, rnd(&g), rnd(&g), rnd(&g));
    b = add_v(s, rnd(&g), rnd(&g), rnd(&g));
    c = add_v(s, rnd(&g), rnd(&g), rnd(&g));
    for (i = 0; i < 5000; i++)
        add_t(s, a, b, c);
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    g.s = g_seed ^ 0xc0b1e5;
    for (i = 0; kd && i < 300; i++) {
        double u = rnd(&g), v = rnd(&g) * (1.0 - u);
        rtpi_v3 pa = v3_from_f(s->pos + 3 * (size_t)a), pb = v3_from_f(s->pos + 3 * (size_t)b),
                pc = v3_from_f(s->pos + 3 * (size_t)c);
        rtpi_v3 t = v3_add(pa, v3_add(v3_mul(v3_sub(pb, pa), u), v3_mul(v3_sub(pc, pa), v)));
        rtpi_v3 o = v3(rndr(&g, -0.5, 1.5), rndr(&g, -0.5, 1.5), rndr(&g, -0.5, 1.5));
        rtpi_ray r = mkray(o, v3_sub(t, o));
        rtpi_hit hk, hb;
        int k = rtpi_kd_intersect(kd, &r, &hk), q = brute(s, &r, &hb);
        hits += q;
        if (k != q || (q && (hk.prim != hb.prim || hk.t != hb.t)))
            bad++;
    }
    CHECK_MSG(bad == 0 && hits > 100, "%d of 300 rays (%d hits) not brute force's (seed %llu)",
              bad, hits, (unsigned long long)g_seed);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_stats(void)
{
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtpi_kd_stats st;
    icosphere(s, 0, 20);
    CHECK(rtpi_kd_build(s, NULL, &kd, NULL) == RTP_OK);
    if (kd) {
        rtpi_kd_get_stats(kd, &st);
        printf("icosphere %lu tris: %lu nodes, %lu leaves (%lu empty), %lu refs, depth %d\n",
               (unsigned long)s->ntris, (unsigned long)st.nodes,
               (unsigned long)st.leaves, (unsigned long)st.empty_leaves,
               (unsigned long)st.prim_refs, st.depth);
        CHECK(st.leaves * 2 == st.nodes + 1);
        CHECK(st.prim_refs >= s->ntris);
        /* Clipped splits keep duplication bounded on a closed surface. */
        CHECK(st.prim_refs < 8 * s->ntris);
        CHECK(st.empty_leaves < st.leaves);
        CHECK(st.depth > 8 && st.depth <= 8 + 1.3 * log((double)s->ntris) / log(2.0));
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

/* The cylinders' line test of shadow rays towards a light
   (rtpi_round_cones' data, kd_cylinder_line_far in the walk) turns away
   no ray rtpi_cone_t hits: rays from beyond points at R (1 + e) from an
   axis, e from -1e-6 to 1e-6 (1e-9 the closest), near and far, rays along
   an axis (d x w = 0), directions with zero components, lights on an
   axis' extension, inside the scene and far away: the walk with the
   light's tests answers as brute force over rtpi_intersect_prim.  The
   scene at the origin and moved off it by `off` along x, where the test's
   margins must still be of the cylinders' size (they were made for rays
   as long as 4 times the largest coordinate: 1e5 from the origin, M was
   29 R and nothing was turned away). */
static void cylinder_line_case(double off)
{
    static const double es[] = {-1e-6, -1e-9, 0.0, 1e-9, 1e-6, 1e-3, -0.5};
    rtpi_v3 lights[6];
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtp_allocator a;
    int i, li, k, bad = 0, hits = 0, graze_hit = 0, graze_miss = 0, nc;
    g.s = g_seed ^ 0x3131;
    rtpi_allocator_init(&a, NULL);
    for (i = 0; i < 60; i++) {
        rtpi_v3 b = v3(off + rndr(&g, -2, 2), rndr(&g, -2, 2), rndr(&g, 0, 2));
        rtpi_v3 d = v3_mul(rnd_dir(&g), rndr(&g, 0.3, 2));
        double r = rndr(&g, 0.01, 0.06);
        if (i % 4 == 0) /* along a coordinate axis */
            d = i % 8 ? v3(0, 0, 1.5) : v3(1.2, 0, 0);
        add_cone(s, b, r, v3_add(b, d), r);
    }
    add_sphere(s, off + 0.5, 0.5, 1, 0.3);
    nc = (int)s->ncones;
    if (rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    {
        const rtpi_cone_frame *c0 = &s->cframes[0], *c1 = &s->cframes[1];
        lights[0] = v3(off + 2, 3, 9);
        lights[1] = v3(off + 0.1, -0.2, 1.0);                 /* among them */
        lights[2] = v3_madd(c0->b, c0->w, -2.0);              /* on an axis */
        lights[3] = v3_madd(c1->b, c1->w, c1->h + 0.7);       /* and another */
        lights[4] = v3(3e5, -1e5, 8e5);
        lights[5] = v3(off - 4, 0, 1); /* level with the x cylinders */
    }
    for (li = 0; li < 6; li++) {
        rtpi_v3 L = lights[li];
        double *planes = NULL, *cones = NULL, scale = 0.0;
        if (rtpi_tri_planes(s, L, &a, &planes, &scale, NULL) != RTP_OK ||
            rtpi_round_cones(s, L, scale, rtpi_kd_far(kd, L), &a, &cones, NULL) != RTP_OK) {
            CHECK(0);
            break;
        }
        if (li < 2) {
            /* lights among the cylinders: a margin of their size */
            int wide = 0;
            for (k = 0; k < nc; k++) {
                const double *q = cones + 4 * (s->nspheres + s->ncones) + 6 * (size_t)k;
                wide += !(q[5] > 0.0 && q[3] < 1.001 * s->cframes[k].rb);
            }
            CHECK_MSG(wide == 0, "offset %g, light %d: %d cylinders' line tests with wide "
                      "margins", off, li, wide);
        }
        for (k = 0; k < 6000; k++) {
            int c = (int)(rnd(&g) * nc) % nc, kind = k % 10, brute = 0, walk;
            const rtpi_cone_frame *cf = &s->cframes[c];
            double e = es[k % (sizeof es / sizeof *es)];
            rtpi_v3 u = v3_cross(cf->w, rnd_dir(&g)), P, o;
            rtpi_ray r;
            rtpi_hit h;
            uint32_t q;
            u = v3_mul(u, 1.0 / v3_len(u));
            P = v3_madd(v3_madd(cf->b, cf->w, rndr(&g, 0.02, 0.98) * cf->h), u, cf->rb * (1 + e));
            o = v3_add(L, v3_mul(v3_sub(P, L), kind < 5 ? 1.0001 + kind : 1.0 + 1e-6 * kind));
            if (kind < 5) {
                /* a line through L in a plane parallel to the axis at R
                   (1 + e) from it, which it touches at height hq */
                rtpi_v3 Lp = v3_madd(cf->b, cf->w, v3_dot(v3_sub(L, cf->b), cf->w));
                rtpi_v3 vv = v3_sub(L, Lp);
                double dL = v3_len(vv), rho = cf->rb * (1 + e);
                if (dL > 2 * rho) {
                    double ct = rho / dL, st = sqrt(1 - ct * ct);
                    double hq = rndr(&g, 0.02, 0.98) * cf->h, hL = v3_dot(v3_sub(L, cf->b), cf->w);
                    rtpi_v3 v2, T, Q;
                    vv = v3_mul(vv, 1.0 / dL);
                    v2 = v3_cross(cf->w, vv);
                    T = v3_add(Lp, v3_add(v3_mul(vv, rho * ct), v3_mul(v2, rho * st)));
                    Q = v3_madd(T, cf->w, hq - hL);
                    o = v3_add(L, v3_mul(v3_sub(Q, L), 1.0001 + kind));
                }
            }
            if (kind == 7 && (li == 2 || li == 3)) {
                /* from the axis of the cylinder whose axis holds the
                   light: along it (d x w = 0), or off it by R (1 + e) */
                const rtpi_cone_frame *ca = &s->cframes[li - 2];
                o = v3_madd(ca->b, ca->w, li == 2 ? ca->h + 0.5 : -0.5);
                if (k & 32)
                    o = v3_madd(o, u, ca->rb * (1 + e));
            }
            if (kind == 8) /* zero components */
                o = v3(L.x + 0.5, P.y, P.z);
            if (kind == 9) /* random */
                o = v3(off + rndr(&g, -3, 3), rndr(&g, -3, 3), rndr(&g, -0.5, 3));
            r = rtpi_shadow_ray(o, L);
            for (q = 0; q < (uint32_t)rtpi_scene_nprims(s) && !brute; q++)
                brute = rtpi_intersect_prim(s, q, &r, &h);
            walk = rtpi_kd_occluder_planes(kd, &r, RTPI_NONE, planes, NULL, cones, scale) !=
                   RTPI_NONE;
            bad += walk != brute;
            hits += brute;
            if (kind < 5 && e == -1e-9)
                graze_hit += brute;
            if (kind < 5 && e == 1e-3)
                graze_miss += !brute;
        }
        rtpi_free(&a, planes);
        rtpi_free(&a, cones);
    }
    CHECK_MSG(bad == 0, "%d walks with the cylinders' line test differ from brute force (seed "
              "%llu)", bad, (unsigned long long)g_seed);
    printf("cylinders line test (offset %g): %d hits, grazing %d hit, %d missed\n", off, hits,
           graze_hit, graze_miss);
    CHECK(hits > 5000);
    /* the grazing rays are what they were made to be, mostly */
    CHECK_MSG(graze_hit > 1000 && graze_miss > 1000, "grazing: %d hit, %d missed", graze_hit,
              graze_miss);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_cylinder_line(void)
{
    cylinder_line_case(0.0);
    cylinder_line_case(1e5);
}

/* The sure hit (rtpi_edges_sure 1, then rtpi_wt_t_sure: the exact
   walk's, the light buffer's and EXACT's cache's) for triangle t and ray
   r, r's range as it is and cut at the vertices' z bounds along the
   test's axis (the bounds rtpi_wt_t_sure widens by 1e-13), at the hit's
   t and a few ulps around each: wherever it answers a hit, the watertight
   test on the same floats must too (out[0] counts those it misses), and
   the kd walk with the edges must answer the primitive the walk without
   them answers (out[1]).  out[2]: sure answers; out[3]: ranges cut at a
   bound where the vertices' z bounds are one value (a level triangle
   seen along z: without the widening, sure where the test's own t rounds
   past the bound); out[4]: lines inside all three edges by less than the
   margin, where the weights' signs are not sure. */
static void sure_case(const rtp_scene *s, const rtpi_kdtree *kd, int t, const rtpi_ray *r,
                      const double *planes, const double *edges, double scale,
                      const rtpi_edge_o *eo, int *out)
{
    const rtpi_tri *tr = &s->tris[t];
    const float *p0 = s->pos + 3 * (size_t)tr->v[0], *p1 = s->pos + 3 * (size_t)tr->v[1],
                *p2 = s->pos + 3 * (size_t)tr->v[2];
    const double *e = edges + RTPI_EDGE_N * (size_t)t;
    double oz, sz, z[3], lo, hi, cut[12], tt, uu, vv;
    int kz, c, n = 0, es;
    rtpi_wt_ray w;
    if (!(fabs(r->o.x) <= scale && fabs(r->o.y) <= scale && fabs(r->o.z) <= scale) ||
        !rtpi_wt_z(r, &kz, &oz, &sz) || !rtpi_wt_setup(&w, r))
        return;
    es = rtpi_edges_sure(e, eo, RTPI_EDGE_MARGIN * scale * scale * scale);
    if (es == 2 && rtpi_edges_sure(e, eo, 0.0) == 1)
        out[4]++;
    if (es != 1)
        return;
    z[0] = ((double)p0[kz] - oz) * sz;
    z[1] = ((double)p1[kz] - oz) * sz;
    z[2] = ((double)p2[kz] - oz) * sz;
    lo = fmin(z[0], fmin(z[1], z[2]));
    hi = fmax(z[0], fmax(z[1], z[2]));
    cut[n++] = lo;
    cut[n++] = hi;
    cut[n++] = nextafter(lo, -HUGE_VAL);
    cut[n++] = nextafter(hi, HUGE_VAL);
    cut[n++] = lo * (1.0 - 1e-13);
    cut[n++] = hi * (1.0 + 1e-13);
    cut[n++] = hi * (1.0 + 2e-13);
    cut[n++] = lo * (1.0 - 2e-13);
    if (rtpi_wt_tri(&w, p0, p1, p2, -HUGE_VAL, HUGE_VAL, &tt, &uu, &vv)) {
        cut[n++] = tt;
        cut[n++] = nextafter(tt, HUGE_VAL);
        cut[n++] = nextafter(tt, -HUGE_VAL);
    }
    for (c = -1; c < 2 * n; c++) {
        rtpi_ray q = *r;
        int sr, hit;
        if (c >= 0 && c < n)
            q.tmax = cut[c];
        else if (c >= n)
            q.tmin = cut[c - n];
        if (!(q.tmin <= q.tmax))
            continue;
        sr = rtpi_wt_t_sure(p0, p1, p2, kz, oz, sz, q.tmin, q.tmax);
        hit = rtpi_wt_tri(&w, p0, p1, p2, q.tmin, q.tmax, &tt, &uu, &vv);
        out[0] += sr && !hit;
        out[2] += sr;
        out[3] += c >= 0 && lo == hi && (q.tmax == hi || q.tmin == lo);
        out[1] += rtpi_kd_occluder_planes(kd, &q, RTPI_NONE, planes, edges, NULL, scale) !=
                  rtpi_kd_occluder_planes(kd, &q, RTPI_NONE, planes, NULL, NULL, scale);
    }
}

/* rtpi_tri_edges' test turns away no shadow ray the watertight test
   hits: each triangle asked directly (rtpi_edges_miss against
   rtpi_intersect_prim) on rays towards the light through points beside
   its edges and vertices, 1e-12 to 1e-3 of the edge's length inside or
   outside, from origins just beyond the triangle and far beyond it;
   and the walk with planes and edges answers as brute force.  A mesh of
   shared edges, slivers and large triangles; lights inside the scene,
   on a triangle's plane, on an edge's line and far away; the scene at
   the origin and moved off it by `off` (the margin scale^3). */
static void tri_edges_case(double off)
{
    static const double es[] = {-1e-3, -1e-7, -1e-12, 0.0, 1e-12, 1e-7, 1e-3};
    rtpi_v3 lights[5];
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtp_allocator a;
    int i, j, li, k, bad = 0, badwalk = 0, culled = 0, hits = 0, near_hit = 0, nt;
    int sure[5] = {0, 0, 0, 0, 0};
    g.s = g_seed ^ 0x7131;
    rtpi_allocator_init(&a, NULL);
    for (i = 0; i < 6; i++) /* a mesh: shared edges */
        for (j = 0; j < 6; j++) {
            double z = 0.2 * sin(i + 2 * j);
            uint32_t v0 = add_v(s, off + i * 0.3, j * 0.3, z), v1 = add_v(s, off + i * 0.3 + 0.3, j * 0.3, z),
                     v2 = add_v(s, off + i * 0.3, j * 0.3 + 0.3, z + 0.05);
            add_t(s, v0, v1, v2);
            add_t(s, v1, add_v(s, off + i * 0.3 + 0.3, j * 0.3 + 0.3, z), v2);
        }
    for (i = 0; i < 80; i++) {
        rtpi_v3 p = v3(off + rndr(&g, -1, 3), rndr(&g, -1, 3), rndr(&g, 0.3, 2.5));
        double sz = i % 4 == 0 ? 1.5 : 0.05;
        rtpi_v3 q = v3_add(p, v3_mul(rnd_dir(&g), sz)), r2 = v3_add(p, v3_mul(rnd_dir(&g), sz));
        if (i % 8 == 1) /* a sliver */
            r2 = v3_add(v3_mul(v3_add(p, q), 0.5), v3_mul(rnd_dir(&g), 1e-4 * sz));
        if (i % 8 == 3) /* level: its vertices' z alike (the sure hit's t bound, below) */
            q.z = r2.z = p.z;
        add_t(s, add_v(s, p.x, p.y, p.z), add_v(s, q.x, q.y, q.z), add_v(s, r2.x, r2.y, r2.z));
    }
    nt = (int)s->ntris;
    if (rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return;
    }
    {
        const float *p0 = s->pos + 3 * (size_t)s->tris[nt - 1].v[0];
        const float *p1 = s->pos + 3 * (size_t)s->tris[nt - 1].v[1];
        lights[0] = v3(off + 2, 3, 9);
        lights[1] = v3(off + 0.8, 0.7, 1.4); /* among them */
        lights[2] = v3(3e5, -1e5, 8e5);
        /* on an edge's line beyond its end */
        lights[3] = v3(p1[0] + 2.0 * (p1[0] - p0[0]), p1[1] + 2.0 * (p1[1] - p0[1]),
                       p1[2] + 2.0 * (p1[2] - p0[2]));
        lights[4] = v3(off + 0.9, 0.9, 0.2 * sin(3.0 + 6.0) + 0.0); /* near the mesh's plane */
    }
    for (li = 0; li < 5; li++) {
        rtpi_v3 L = lights[li];
        double *planes = NULL, *edges = NULL, scale = 0.0, thr;
        if (rtpi_tri_planes(s, L, &a, &planes, &scale, NULL) == RTP_OK)
            rtpi_tri_edges(s, L, scale, planes, &a, &edges);
        if (!planes || !edges) {
            CHECK(0);
            rtpi_free(&a, planes);
            break;
        }
        thr = RTPI_EDGE_MARGIN * scale * scale * scale;
        for (k = 0; k < 8000; k++) {
            int t = (int)(rnd(&g) * nt) % nt, kind = k % 4, brute = 0, walk, hit, miss;
            const rtpi_tri *tr = &s->tris[t];
            rtpi_v3 v[3], P, o;
            double e = es[k % (sizeof es / sizeof *es)], u = rnd(&g);
            int ed = (int)(rnd(&g) * 3) % 3;
            rtpi_edge_o eo;
            rtpi_ray r;
            rtpi_hit h;
            uint32_t q;
            for (i = 0; i < 3; i++)
                v[i] = v3_from_f(s->pos + 3 * (size_t)tr->v[i]);
            /* beside edge ed (u along it; a vertex where kind is 3),
               moved by e of the way towards the opposite vertex (< 0:
               away from it) */
            if (kind == 3)
                u = 0.0;
            P = v3_add(v[ed], v3_mul(v3_sub(v[(ed + 1) % 3], v[ed]), u));
            P = v3_add(P, v3_mul(v3_sub(v[(ed + 2) % 3], P), e));
            o = v3_add(L, v3_mul(v3_sub(P, L), kind == 0 ? 1.0 + 1e-6 : kind == 1 ? 1.3 : 4.0));
            r = rtpi_shadow_ray(o, L);
            hit = rtpi_intersect_prim(s, (uint32_t)t, &r, &h);
            rtpi_edge_o_make(&eo, &o);
            miss = fabs(o.x) <= scale && fabs(o.y) <= scale && fabs(o.z) <= scale &&
                   rtpi_edges_miss(edges + RTPI_EDGE_N * (size_t)t, &eo, thr);
            bad += hit && miss;
            culled += miss;
            hits += hit;
            near_hit += hit && e < 0.0 && e > -1e-6;
            for (q = 0; q < (uint32_t)nt && !brute; q++)
                brute = rtpi_intersect_prim(s, q, &r, &h);
            walk = rtpi_kd_occluder_planes(kd, &r, RTPI_NONE, planes, edges, NULL, scale) !=
                   RTPI_NONE;
            badwalk += walk != brute;
            sure_case(s, kd, t, &r, planes, edges, scale, &eo, sure);
        }
        rtpi_free(&a, planes);
        rtpi_free(&a, edges);
    }
    CHECK_MSG(sure[0] == 0 && sure[1] == 0,
              "offset %g: %d sure hits the watertight test misses, %d walks with the edges found "
              "another primitive than without (seed %llu)",
              off, sure[0], sure[1], (unsigned long long)g_seed);
    printf("triangles' sure hits (offset %g): %d sure, %d of them with t at a range's end, %d "
           "within the margin\n", off, sure[2], sure[3], sure[4]);
    /* asked and met (at the origin: off it the margin, scale^3, is wider
       than these triangles' values): sure hits, some with t's range cut
       at the vertices' bounds (level triangles) and lines inside the
       edges by less than the margin (the cases a dropped margin or bound
       answers wrongly) */
    CHECK_MSG(off != 0.0 || (sure[2] > 2000 && sure[3] > 100 && sure[4] > 1000),
              "offset %g: %d sure, %d at a range's end, %d within the margin", off, sure[2],
              sure[3], sure[4]);
    CHECK_MSG(bad == 0, "offset %g: %d hits turned away by the edges' test (seed %llu)", off, bad,
              (unsigned long long)g_seed);
    CHECK_MSG(badwalk == 0, "offset %g: %d walks with the edges differ from brute force (seed "
              "%llu)", off, badwalk, (unsigned long long)g_seed);
    printf("triangles' edge test (offset %g): %d hits, %d beside an edge, %d turned away\n", off,
           hits, near_hit, culled);
    /* the test is asked and turns rays away (at the origin: off it the
       margin, scale^3, is wider than any of these triangles' values);
       grazing rays hit */
    CHECK_MSG((off != 0.0 || culled > 1000) && hits > 4000 && near_hit > 500,
              "offset %g: %d hits, %d beside an edge, %d turned away", off, hits, near_hit,
              culled);
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_tri_edges(void)
{
    tri_edges_case(0.0);
    tri_edges_case(1e5);
}

/* rtpi_sphere_sure against rtpi_sphere_t on the same floats: shadow
   rays (rtpi_shadow_ray) towards a light far off, near, on and inside a
   sphere, through points of the sphere's silhouette seen from the light
   and of its surface, 0 and 1e-16 to 1e-3 of the radius outside or
   inside, from origins in front of that point, just beside it (the
   range's end) and beyond it; radii 1e-6 to 1e3 of the scene, inside-
   only spheres; the scene at the origin and moved by `off`.  Every
   answer it gives must be the full test's; it must give many (sure hits
   and misses); with its margins dropped it must answer some wrongly
   (the cases reach the margins). */
static void sphere_sure_case(double off, int *out)
{
    static const double eps[] = {-1e-3, -1e-9, -1e-12, -1e-16, 0.0, 1e-16, 1e-12, 1e-9, 1e-3};
    static const double lam[] = {0.3, 1.0 - 1e-12, 1.0, 1.0 + 1e-12, 1.0 + 1e-6, 2.0, 5.0};
    static const double rad[] = {1e-6, 1e-3, 0.05, 0.7, 30.0};
    rng g;
    rtp_allocator a;
    int c, k;
    g.s = g_seed ^ 0x5f3e ^ (uint64_t)off;
    rtpi_allocator_init(&a, NULL);
    for (c = 0; c < 200; c++) {
        rtp_scene *s = new_scene();
        double r = rad[c % 5] * (0.5 + rnd(&g)), sr = c % 7 == 3 ? -r : r, *planes = NULL,
               *e = NULL, scale = 0.0, D;
        rtpi_v3 C = v3(off + rndr(&g, -1, 1), rndr(&g, -1, 1), rndr(&g, -1, 1)), L, gl;
        rtpi_quad_k qk, q0;
        int lk = c % 5;
        add_sphere(s, C.x, C.y, C.z, sr);
        add_sphere(s, off + 3, 3, 3, 0.5); /* (the scene's extent) */
        C = v3_from_f(s->spheres[0].c);
        r = fabs((double)s->spheres[0].r);
        /* the light: far, near, on the surface, just inside, deep inside */
        if (lk == 0)
            L = v3_add(C, v3_mul(rnd_dir(&g), 50.0 * r + 10.0));
        else if (lk == 1)
            L = v3_add(C, v3_mul(rnd_dir(&g), 1.5 * r));
        else if (lk == 2)
            L = v3_add(C, v3_mul(rnd_dir(&g), r));
        else if (lk == 3)
            L = v3_add(C, v3_mul(rnd_dir(&g), r * (1.0 - 1e-12)));
        else
            L = v3_add(C, v3_mul(rnd_dir(&g), 0.3 * r));
        if (rtpi_tri_planes(s, L, &a, &planes, &scale, NULL) != RTP_OK) {
            CHECK(0);
            rtp_scene_destroy(s);
            return;
        }
        rtpi_sphere_entries(s, L, scale, &a, &e);
        CHECK(e != NULL);
        rtpi_quad_k_make(scale, &qk);
        q0.mq = q0.m = q0.m3 = 0.0;
        gl = v3_sub(L, C);
        D = v3_len(gl);
        for (k = 0; e && k < 120; k++) {
            rtpi_v3 n = rnd_dir(&g), T, o;
            double ep = eps[k % 9], lm = lam[(k / 9) % 7], t;
            rtpi_ray ray;
            int full, sure, zero;
            if (k % 2 == 0 && D > r) {
                /* a silhouette point: (T - C).(T - L) = 0 */
                rtpi_v3 u = v3_mul(gl, 1.0 / D), p = v3_sub(n, v3_mul(u, v3_dot(n, u)));
                double pl = v3_len(p), x = r / D;
                if (!(pl > 1e-6))
                    continue;
                p = v3_mul(p, 1.0 / pl);
                T = v3_add(C, v3_add(v3_mul(u, r * x), v3_mul(p, r * sqrt(1.0 - x * x))));
                T = v3_add(C, v3_mul(v3_sub(T, C), 1.0 + ep));
            } else {
                T = v3_add(C, v3_mul(n, r * (1.0 + ep)));
            }
            o = v3_add(L, v3_mul(v3_sub(T, L), lm));
            ray = rtpi_shadow_ray(o, L);
            if (!(fabs(o.x) <= scale && fabs(o.y) <= scale && fabs(o.z) <= scale))
                continue;
            full = rtpi_sphere_t(&s->spheres[0], &ray, v3_dot(ray.d, ray.d), &t);
            sure = rtpi_sphere_sure(e, !(s->spheres[0].r > 0.0f), &ray, &qk);
            zero = rtpi_sphere_sure(e, !(s->spheres[0].r > 0.0f), &ray, &q0);
            out[0] += sure >= 0 && sure != full;
            out[1] += sure == 1;
            out[2] += sure == 0;
            out[3] += sure < 0;
            out[4] += zero >= 0 && zero != full;
            out[5] += full;
        }
        rtpi_free(&a, planes);
        rtpi_free(&a, e);
        rtp_scene_destroy(s);
    }
}

static void test_sphere_sure(void)
{
    int out[6] = {0, 0, 0, 0, 0, 0}, o2[6] = {0, 0, 0, 0, 0, 0}, i;
    sphere_sure_case(0.0, out);
    sphere_sure_case(1e5, o2);
    for (i = 0; i < 6; i++)
        printf("%s%d", i ? " " : "spheres' sure test (wrong, hits, misses, open, wrong without "
                                 "margins, full hits): offset 0: ", out[i]);
    for (i = 0; i < 6; i++)
        printf("%s%d", i ? " " : "; offset 1e5: ", o2[i]);
    printf("\n");
    CHECK_MSG(out[0] == 0 && o2[0] == 0, "%d, %d sure answers not rtpi_sphere_t's (seed %llu)",
              out[0], o2[0], (unsigned long long)g_seed);
    /* (the counts follow the clock's seed: over seeds 1-1000 the fewest
       were 5298 2976 13003, 1430 2249; out[2] > 3000 failed 17 seeds of
       2000, a make test in 120: seed 1796670008 gave 2997) */
    CHECK_MSG(out[1] > 3000 && out[2] > 2500 && out[3] > 500 && o2[1] > 1000 && o2[2] > 1000,
              "too few decided: %d %d %d, %d %d", out[1], out[2], out[3], o2[1], o2[2]);
    CHECK_MSG(out[4] + o2[4] > 0, "no answer wrong without the margins: the cases miss them");
}

/* rtpi_cyl_sure against hit_cone (rtpi_intersect_prim) on the same
   floats, as sphere_sure_case: shadow rays towards a light far off,
   near, beside the axis's line, close to the surface and inside,
   through points of the side, its silhouette seen from the light and
   its two rims (0 and 1e-16 to 1e-3 off, heights just outside and
   inside the ends), from origins in front of the point, at it and
   beyond; radii and heights 1e-6 to 30; cones that are not cylinders
   (never decided); the scene at the origin and moved by `off`. */
static void cyl_sure_case(double off, int *out)
{
    static const double eps[] = {-1e-3, -1e-9, -1e-12, -1e-16, 0.0, 1e-16, 1e-12, 1e-9, 1e-3};
    static const double lam[] = {0.3, 1.0 - 1e-12, 1.0, 1.0 + 1e-12, 1.0 + 1e-6, 2.0, 5.0};
    static const double hts[] = {-1e-3, -1e-12, 0.0, 1e-12, 0.3, 0.5, 1.0 - 1e-12, 1.0, 1.0 + 1e-9};
    static const double rad[] = {1e-6, 1e-3, 0.05, 0.7, 30.0};
    rng g;
    rtp_allocator a;
    int c, k;
    g.s = g_seed ^ 0xc71d ^ (uint64_t)off;
    rtpi_allocator_init(&a, NULL);
    for (c = 0; c < 200; c++) {
        rtp_scene *s = new_scene();
        double R = rad[c % 5] * (0.5 + rnd(&g)), H = rad[(c / 5) % 5] * (0.5 + 2.0 * rnd(&g)),
               *planes = NULL, *e = NULL, scale = 0.0, gpl;
        rtpi_v3 B = v3(off + rndr(&g, -1, 1), rndr(&g, -1, 1), rndr(&g, -1, 1)), L, gl, gp, e1;
        const rtpi_cone_frame *cf;
        rtpi_quad_k qk, q0;
        int lk = c % 6, cone = c % 11 == 4;
        add_cone(s, B, R, v3_add(B, v3_mul(rnd_dir(&g), H)), cone ? 0.5 * R : R);
        add_sphere(s, off + 3, 3, 3, 0.5); /* (the scene's extent) */
        cf = &s->cframes[0];
        if (!cf->ok) {
            rtp_scene_destroy(s);
            continue;
        }
        R = cf->rb;
        /* the light: far, near, on the axis's line, on the surface, inside */
        if (lk == 0)
            L = v3_add(cf->mid, v3_mul(rnd_dir(&g), 50.0 * cf->bound + 10.0));
        else if (lk == 1)
            L = v3_add(cf->mid, v3_mul(rnd_dir(&g), 1.5 * cf->bound));
        else if (lk == 2)
            L = v3_madd(cf->b, cf->w, cf->h * rndr(&g, -2, 3));
        else if (lk == 3)
            L = v3_madd(cf->mid, v3_norm(v3_cross(cf->w, rnd_dir(&g))), R);
        else if (lk == 4)
            L = v3_madd(cf->mid, v3_norm(v3_cross(cf->w, rnd_dir(&g))), R * (1.0 + 1e-9));
        else
            L = v3_madd(cf->mid, v3_norm(v3_cross(cf->w, rnd_dir(&g))), 0.5 * R);
        if (rtpi_tri_planes(s, L, &a, &planes, &scale, NULL) != RTP_OK) {
            CHECK(0);
            rtp_scene_destroy(s);
            return;
        }
        rtpi_cyl_entries(s, L, scale, &a, &e);
        /* (none where no cone is a cylinder; nor where the one is small
           against the scale) */
        CHECK(!cone || e == NULL);
        rtpi_quad_k_make(scale, &qk);
        q0 = qk;
        q0.cq = q0.c1 = q0.c2 = 0.0;
        gl = v3_sub(L, cf->b);
        gp = v3_madd(gl, cf->w, -v3_dot(gl, cf->w));
        gpl = v3_len(gp);
        e1 = v3_norm(v3_cross(cf->w, rnd_dir(&g)));
        for (k = 0; e && k < 150; k++) {
            double ep = eps[k % 9], lm = lam[(k / 9) % 7], hv = hts[(k / 63 + k) % 9], phi;
            rtpi_v3 n, T, o;
            rtpi_ray ray;
            rtpi_hit hh;
            int full, sure, zero;
            if (k % 3 == 0 && gpl > R) {
                /* a silhouette line: n.gp = R */
                rtpi_v3 u = v3_mul(gp, 1.0 / gpl), p = v3_cross(cf->w, u);
                double x = R / gpl;
                n = v3_add(v3_mul(u, x), v3_mul(p, (k & 4 ? 1.0 : -1.0) * sqrt(1.0 - x * x)));
            } else {
                phi = rndr(&g, 0, 6.283185307179586);
                n = v3_add(v3_mul(e1, cos(phi)), v3_mul(v3_cross(cf->w, e1), sin(phi)));
            }
            if (k % 5 != 1)
                hv = rnd(&g);
            T = v3_add(v3_madd(cf->b, cf->w, cf->h * hv), v3_mul(n, R * (1.0 + ep)));
            o = v3_add(L, v3_mul(v3_sub(T, L), lm));
            ray = rtpi_shadow_ray(o, L);
            if (!(fabs(o.x) <= scale && fabs(o.y) <= scale && fabs(o.z) <= scale))
                continue;
            full = rtpi_intersect_prim(s, (uint32_t)(s->ntris + s->nspheres), &ray, &hh);
            sure = rtpi_cyl_sure(e, cf, &ray, &qk);
            zero = rtpi_cyl_sure(e, cf, &ray, &q0);
            out[0] += sure >= 0 && sure != full;
            out[1] += sure == 1;
            out[2] += sure == 0;
            out[3] += sure < 0;
            out[4] += zero >= 0 && zero != full;
            out[5] += cone && sure >= 0;
        }
        rtpi_free(&a, planes);
        rtpi_free(&a, e);
        rtp_scene_destroy(s);
    }
}

/* The walk with the cylinders' numbers (rtpi_kd_occluder_cyls) answers
   the primitive the walk without them answers, on shadow rays from
   points on and around thin cylinders (a ring of them, as SPD's rings)
   and spheres; returns the walks that met one. */
static int cyl_walk_case(double off, int *bad)
{
    rng g;
    rtp_allocator a;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    int i, k, li, met = 0;
    g.s = g_seed ^ 0x3a7 ^ (uint64_t)off;
    rtpi_allocator_init(&a, NULL);
    for (i = 0; i < 60; i++) {
        double a0 = 0.1047 * i, a1 = a0 + 0.1047, z = 0.1 * (i / 20);
        add_cone(s, v3(off + cos(a0), sin(a0), z), 0.03, v3(off + cos(a1), sin(a1), z), 0.03);
    }
    add_cone(s, v3(off, 0, 0), 0.2, v3(off, 0, 0.5), 0.1); /* (a cone: never decided) */
    for (i = 0; i < 10; i++)
        add_sphere(s, off + rndr(&g, -1, 1), rndr(&g, -1, 1), rndr(&g, 0, 0.5), 0.05);
    if (rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
        CHECK(0);
        rtp_scene_destroy(s);
        return 0;
    }
    for (li = 0; li < 3; li++) {
        rtpi_v3 L = li == 0 ? v3(off + 2, 3, 9) : li == 1 ? v3(off + 0.2, 0.1, 0.3)
                                                 : v3(off + 1.0, 0.03, 0.0);
        double *planes = NULL, *cones = NULL, *cyls = NULL, scale = 0.0;
        if (rtpi_tri_planes(s, L, &a, &planes, &scale, NULL) != RTP_OK ||
            rtpi_round_cones(s, L, scale, rtpi_kd_far(kd, L), &a, &cones, NULL) != RTP_OK) {
            CHECK(0);
            break;
        }
        rtpi_cyl_entries(s, L, scale, &a, &cyls);
        CHECK(cyls != NULL);
        for (k = 0; cyls && k < 4000; k++) {
            const rtpi_cone_frame *cf = &s->cframes[(int)(rnd(&g) * 60) % 60];
            rtpi_v3 n = v3_norm(v3_cross(cf->w, rnd_dir(&g))), p, o;
            rtpi_ray r;
            uint32_t q0, q1;
            p = v3_add(v3_madd(cf->b, cf->w, cf->h * rnd(&g)),
                       v3_mul(n, cf->rb * (1.0 + (k % 3 ? 1e-7 : 0.5))));
            o = k % 2 ? p : v3_add(p, v3_mul(rnd_dir(&g), 0.3));
            r = rtpi_shadow_ray(o, L);
            q0 = rtpi_kd_occluder_planes(kd, &r, RTPI_NONE, planes, NULL, cones, scale);
            q1 = rtpi_kd_occluder_cyls(kd, &r, RTPI_NONE, planes, cones, cyls, scale);
            *bad += q0 != q1;
            met += q0 != RTPI_NONE;
        }
        rtpi_free(&a, planes);
        rtpi_free(&a, cones);
        rtpi_free(&a, cyls);
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
    return met;
}

static void test_cyl_sure(void)
{
    int out[6] = {0, 0, 0, 0, 0, 0}, o2[6] = {0, 0, 0, 0, 0, 0}, i, bad = 0, met;
    met = cyl_walk_case(0.0, &bad) + cyl_walk_case(1e5, &bad);
    printf("cylinders' walk: %d of 24000 rays blocked\n", met);
    CHECK_MSG(bad == 0 && met > 3000, "%d walks with the cylinders' numbers answered another "
              "primitive (%d blocked; seed %llu)", bad, met, (unsigned long long)g_seed);
    cyl_sure_case(0.0, out);
    cyl_sure_case(1e5, o2);
    for (i = 0; i < 6; i++)
        printf("%s%d", i ? " " : "cylinders' sure test (wrong, hits, misses, open, wrong "
                                 "without margins, cones decided): offset 0: ", out[i]);
    for (i = 0; i < 6; i++)
        printf("%s%d", i ? " " : "; offset 1e5: ", o2[i]);
    printf("\n");
    CHECK_MSG(out[0] == 0 && o2[0] == 0, "%d, %d sure answers not hit_cone's (seed %llu)",
              out[0], o2[0], (unsigned long long)g_seed);
    CHECK_MSG(out[5] == 0 && o2[5] == 0, "cones (not cylinders) decided: %d, %d", out[5], o2[5]);
    CHECK_MSG(out[1] > 1500 && out[2] > 1500 && out[3] > 500 && o2[1] > 100 && o2[2] > 200,
              "too few decided: %d %d %d, %d %d", out[1], out[2], out[3], o2[1], o2[2]);
    CHECK_MSG(out[4] + o2[4] > 0, "no answer wrong without the margins: the cases miss them");
}

/* Walks from the origin's own leaf (rtpi_kd_occluder_planes_from) name
   the walk from the root's occluder, the first met: the same leaves in
   the same order.  Origins on the grid's split planes, and off them by
   multiples of the walk's slack (tol = 1e-11 of the largest coordinate,
   kd_axis_setup) on either side of the 2 tol the leaf's list asks for;
   lights anywhere, in the origin's planes (a direction exactly 0 on one
   or two axes), on a grid plane (a segment ending in a split plane), or
   close by.  Among many small triangles (and, lazy = 1, spheres) a
   changed order names another occluder. */
static void from_case(int lazy, double sc, double off, int *n_from, int *n_none,
                      int *n_blocked, int *bad)
{
    /* (the scene, origins and lights at off + sc x: far from the
       origin, huge or tiny; maxabs the root box's largest coordinate
       about, the slack's scale) */
    const double maxabs = fabs(off) + 2.75 * sc;
    rng g;
    rtp_scene *s = new_scene();
    rtpi_kdtree *kd = NULL;
    rtp_error err;
    int i, j;
    g.s = g_seed ^ (lazy ? 0x7a7a : 0x7b7b);
    for (i = 0; i < 300; i++) {
        int ax = i % 3;
        double x = floor(rnd(&g) * 8) / 4, y = floor(rnd(&g) * 8) / 4,
               z = floor(rnd(&g) * 8) / 4, w = 0.25 * (1 + (i % 3));
        uint32_t a = add_v(s, off + sc * x, off + sc * y, off + sc * z), b, c, d;
        if (ax == 0) {
            b = add_v(s, off + sc * x, off + sc * (y + w), off + sc * z);
            c = add_v(s, off + sc * x, off + sc * (y + w), off + sc * (z + w));
            d = add_v(s, off + sc * x, off + sc * y, off + sc * (z + w));
        } else if (ax == 1) {
            b = add_v(s, off + sc * (x + w), off + sc * y, off + sc * z);
            c = add_v(s, off + sc * (x + w), off + sc * y, off + sc * (z + w));
            d = add_v(s, off + sc * x, off + sc * y, off + sc * (z + w));
        } else {
            b = add_v(s, off + sc * (x + w), off + sc * y, off + sc * z);
            c = add_v(s, off + sc * (x + w), off + sc * (y + w), off + sc * z);
            d = add_v(s, off + sc * x, off + sc * (y + w), off + sc * z);
        }
        if (!lazy || i % 4 == 0) {
            add_t(s, a, b, c);
            add_t(s, a, c, d);
        }
    }
    for (i = 0; i < (lazy ? 1500 : 900); i++) {
        rtpi_v3 c = v3(off + sc * rndr(&g, 0, 2.5), off + sc * rndr(&g, 0, 2.5),
                       off + sc * rndr(&g, 0, 2.5));
        double sz = 0.04 * sc;
        if (lazy) {
            add_sphere(s, c.x, c.y, c.z, sz * rnd(&g) + 0.005 * sc);
        } else {
            uint32_t a = add_v(s, c.x, c.y, c.z);
            uint32_t b = add_v(s, c.x + rndr(&g, -sz, sz), c.y + rndr(&g, -sz, sz),
                               c.z + rndr(&g, -sz, sz));
            uint32_t d = add_v(s, c.x + rndr(&g, -sz, sz), c.y + rndr(&g, -sz, sz),
                               c.z + rndr(&g, -sz, sz));
            add_t(s, a, b, d);
        }
    }
    CHECK(rtpi_kd_build(s, NULL, &kd, &err) == RTP_OK);
    CHECK(kd && rtpi_kd_paths_make(kd) == 0);
    CHECK(rtpi_kd_paths_make(kd) == 0); /* (made once) */
    for (i = 0; kd && i < 4000; i++) {
        static const double ms[] = {0.0, 0.5, 1.0, 1.5, 1.9, 1.99, 2.0, 2.01, 2.1, 3.0, 5.0, 50.0};
        double o[3], tol;
        rtpi_v3 ov;
        uint32_t from;
        int k, kind = i % 4;
        for (k = 0; k < 3; k++) {
            /* a grid plane (k/4) on some axes, or anywhere */
            o[k] = off + sc * (kind == 3 || rnd(&g) < 0.3 ? rndr(&g, -0.2, 2.7)
                                                           : floor(rnd(&g) * 11) / 4);
            tol = 1e-11 * (fabs(o[k]) > maxabs ? fabs(o[k]) : maxabs);
            if (kind == 1 || kind == 2)
                o[k] += (rnd(&g) < 0.5 ? -1.0 : 1.0) * tol *
                        (kind == 1 ? ms[(size_t)(rnd(&g) * 12) % 12] : rndr(&g, 0.0, 4.0));
        }
        ov = v3(o[0], o[1], o[2]);
        from = rtpi_kd_path_of(kd, ov);
        if (from == RTPI_NONE)
            ++*n_none;
        else
            ++*n_from;
        for (j = 0; j < 9; j++) {
            double l[3];
            rtpi_ray r;
            uint32_t q0, q1;
            int kind2 = j % 4;
            for (k = 0; k < 3; k++) {
                l[k] = off + sc * rndr(&g, -1.0, 3.5);
                if (kind2 == 1 && (k == j % 3 || (j & 4 && k == (j + 1) % 3)))
                    l[k] = o[k]; /* 0 on this axis */
                else if (kind2 == 2 && k == j % 3)
                    l[k] = off + sc * floor(rnd(&g) * 11) / 4; /* ends in a grid plane */
                else if (kind2 == 3)
                    l[k] = o[k] + sc * rndr(&g, -0.01, 0.01); /* close by */
            }
            r = rtpi_shadow_ray(ov, v3(l[0], l[1], l[2]));
            if (j == 8) {
                /* a direction not 0 on an axis but so small there that
                   1/d is infinite or huge (subnormal, or just above),
                   of either sign: the slack infinite or the planes'
                   distances overflowing, the walk from the leaf's
                   fallback and arithmetic as the root's */
                static const double tiny[] = {4.9406564584124654e-324, 1e-310, 2.2250738585072014e-308,
                                              1e-300, 1e-290, 3e-200};
                double v = tiny[(size_t)(rnd(&g) * 6) % 6] * (rnd(&g) < 0.5 ? -1.0 : 1.0);
                k = (int)(rnd(&g) * 3) % 3;
                if (k == 0)
                    r.d.x = v;
                else if (k == 1)
                    r.d.y = v;
                else
                    r.d.z = v;
            }
            q0 = rtpi_kd_occluder_planes(kd, &r, RTPI_NONE, NULL, NULL, NULL, 10.0);
            q1 = rtpi_kd_occluder_planes_from(kd, &r, RTPI_NONE, NULL, NULL, NULL, 10.0, from);
            *n_blocked += q0 != RTPI_NONE;
            if (q0 != q1 && (*bad)++ < 5)
                printf("  from_case %d: o %.17g %.17g %.17g, light %.17g %.17g %.17g: "
                       "%u from the root, %u from the leaf\n",
                       lazy, o[0], o[1], o[2], l[0], l[1], l[2], q0, q1);
            /* (and from the root by the same entry) */
            CHECK(rtpi_kd_occluder_planes_from(kd, &r, RTPI_NONE, NULL, NULL, NULL, 10.0,
                                               RTPI_NONE) == q0);
            if (kind2 == 1) {
                /* the 0s as -0 (sign bit set: the kept leaf's set-up,
                   kd_axis_setup's in 2, takes the face ahead by the sign
                   bit and leaves the 0s to the full set-up) */
                rtpi_ray rn = r;
                if (rn.d.x == 0.0)
                    rn.d.x = -0.0;
                if (rn.d.y == 0.0)
                    rn.d.y = -0.0;
                if (rn.d.z == 0.0)
                    rn.d.z = -0.0;
                q1 = rtpi_kd_occluder_planes_from(kd, &rn, RTPI_NONE, NULL, NULL, NULL, 10.0,
                                                  from);
                if (q0 != q1 && (*bad)++ < 5)
                    printf("  from_case %d (-0): o %.17g %.17g %.17g, light %.17g %.17g %.17g: "
                           "%u from the root, %u from the leaf\n",
                           lazy, o[0], o[1], o[2], l[0], l[1], l[2], q0, q1);
            }
        }
    }
    rtpi_kd_destroy(kd);
    rtp_scene_destroy(s);
}

static void test_kd_from(void)
{
    int lazy;
    /* (the scene at its place, then far from the origin, huge and tiny
       within a float's range and the builder's 1e30, and spanning 0 at
       a tiny scale) */
    static const double place[][2] = {{1.0, 0.0}, {1.0, 3e4}, {1.0, -7e6}, {1e28, 0.0},
                                      {1e-30, 0.0}, {1e-30, -1.25e-30}, {1e20, 1e25}};
    size_t pi;
    for (pi = 0; pi < sizeof place / sizeof *place; pi++)
        for (lazy = 0; lazy < 2; lazy++) {
            int n_from = 0, n_none = 0, n_blocked = 0, bad = 0;
            from_case(lazy, place[pi][0], place[pi][1], &n_from, &n_none, &n_blocked, &bad);
            printf("  walks from the leaf (%s, at %g + %g x): %d origins with a list, %d "
                   "without; %d of 36000 rays blocked; %d differ\n",
                   lazy ? "spheres" : "triangles", place[pi][1], place[pi][0], n_from, n_none,
                   n_blocked, bad);
            CHECK(bad == 0);
            /* both sides of the 2 tol margin met (at the scene's own
               place: far off, the float grid is coarser than 2 tol) */
            if (pi == 0)
                CHECK(n_from > 2000 && n_none > 20);
            else
                CHECK(n_from > 500);
        }
}

int main(void)
{
    /* RTP_TEST_SEED, as test_itembuf and test_shadow take it (this one
       read RTP_SEED alone, still taken: a run over seeds 1-40 by the
       common name ran 40 seeds of the clock here) */
    const char *env = getenv("RTP_TEST_SEED");
    if (!env || !*env)
        env = getenv("RTP_SEED");
    g_seed = env && *env ? strtoull(env, NULL, 10) : (uint64_t)time(NULL);
    if (g_seed == 0)
        g_seed = 1;
    (void)check_shared_scenes; /* check.h's helper; not needed here */
    printf("seed %llu (RTP_TEST_SEED=%llu repeats it)\n", (unsigned long long)g_seed,
           (unsigned long long)g_seed);
    RUN(test_empty);
    RUN(test_soup);
    RUN(test_grid);
    RUN(test_bin_planes);
    RUN(test_spheres_cones);
    RUN(test_closed_meshes);
    RUN(test_self_intersection);
    RUN(test_sphere_precision);
    RUN(test_inside_sphere);
    RUN(test_cones);
    RUN(test_cone_bound);
    RUN(test_shading_normal);
    RUN(test_nomem);
    RUN(test_fan_budget);
    RUN(test_diagonal_pipe);
    RUN(test_stacked_quads);
    RUN(test_alike);
    RUN(test_alike_among);
    RUN(test_copies_leaf_order);
    RUN(test_stats);
    RUN(test_cylinder_line);
    RUN(test_tri_edges);
    RUN(test_sphere_sure);
    RUN(test_cyl_sure);
    RUN(test_kd_from);
    return check_report();
}
