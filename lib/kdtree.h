/*
 * kdtree.h — what intersect.c and kdtree.c share beyond internal.h: the
 * watertight ray/triangle test (Woop, Benthin, Wald 2013), split into a
 * per-ray set-up and a per-triangle test so that the kd-tree sets a ray up
 * once and then tests many triangles.  Both the kd-tree and
 * rtpi_intersect_prim run this very code on the very same floats, so a
 * brute-force loop and the tree agree bit for bit.
 *
 * Watertightness: the three edge functions of a triangle are computed from
 * the sheared vertex coordinates alone, and a shared edge gives exactly
 * negated values in its two triangles (a*b - c*d is negated exactly by
 * c*d - a*b).  That needs plain multiplications: fused multiply-adds would
 * round the two orders differently.  ISO C mode (-std=c99) makes gcc keep
 * contractions off; clang is told so below.
 */
#ifndef RTP_KDTREE_H
#define RTP_KDTREE_H

#include "internal.h"

#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

/* A ray prepared for the watertight test: the axis where the direction is
   largest becomes z, and the shear that maps the direction onto +z. */
typedef struct rtpi_wt_ray {
    double ox, oy, oz; /* the origin's coordinates on axes kx, ky, kz (read
                          by each triangle's test: by index they were
                          reloaded there, 4 instructions of its 80) */
    double sx, sy, sz;
    int kx, ky, kz;
} rtpi_wt_ray;

/* Whether rtpi_wt_setup accepts r's direction: not 0, every component
   finite (written so that NaN or infinite components fail). */
static inline int rtpi_wt_valid(const rtpi_ray *r)
{
    double s = fabs(r->d.x) + fabs(r->d.y) + fabs(r->d.z);
    return s > 0.0 && s <= 1.79e308;
}

/* rtpi_wt_setup for a direction rtpi_wt_valid accepts. */
static inline void rtpi_wt_make(rtpi_wt_ray *w, const rtpi_ray *r)
{
    double d[3];
    double ax, ay, az;
    int kx, ky, kz;
    d[0] = r->d.x;
    d[1] = r->d.y;
    d[2] = r->d.z;
    ax = fabs(d[0]);
    ay = fabs(d[1]);
    az = fabs(d[2]);
    kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0.0) { /* keep the winding so front and back faces agree */
        int t = kx;
        kx = ky;
        ky = t;
    }
    w->kx = kx;
    w->ky = ky;
    w->kz = kz;
    w->sx = d[kx] / d[kz];
    w->sy = d[ky] / d[kz];
    w->sz = 1.0 / d[kz];
    {
        const double o[3] = {r->o.x, r->o.y, r->o.z};
        w->ox = o[kx];
        w->oy = o[ky];
        w->oz = o[kz];
    }
}

/* @return 0 when the direction is zero or not finite (nothing can be hit). */
static inline int rtpi_wt_setup(rtpi_wt_ray *w, const rtpi_ray *r)
{
    if (!rtpi_wt_valid(r))
        return 0;
    rtpi_wt_make(w, r);
    return 1;
}

/* Tests the triangle (p0,p1,p2) for t in [tmin, tmax].  On a hit sets
   *t and the barycentrics *u (of p1) and *v (of p2) and returns 1.  A
   triangle seen exactly edge-on (det == 0) is missed; so is a zero-area
   triangle, which the callers filter out beforehand (rtpi_tri_degenerate)
   because rounding can make its det non-zero. */
/* Inlined into the traversal loops whatever the compiler's heuristics
   say (RTPI_FORCE_INLINE): a call per triangle costs as much as the
   test. */

static RTPI_FORCE_INLINE int rtpi_wt_tri(const rtpi_wt_ray *w, const float *p0,
                              const float *p1, const float *p2, double tmin,
                              double tmax, double *t, double *u, double *v)
{
    const int kx = w->kx, ky = w->ky, kz = w->kz;
    const double ox = w->ox, oy = w->oy, oz = w->oz;
    double az = p0[kz] - oz, bz = p1[kz] - oz, cz = p2[kz] - oz;
    double ax = (p0[kx] - ox) - w->sx * az, ay = (p0[ky] - oy) - w->sy * az;
    double bx = (p1[kx] - ox) - w->sx * bz, by = (p1[ky] - oy) - w->sy * bz;
    double cx = (p2[kx] - ox) - w->sx * cz, cy = (p2[ky] - oy) - w->sy * cz;
    double e0 = cx * by - cy * bx; /* weight of p0 */
    double e1 = ax * cy - ay * cx; /* weight of p1 */
    double e2 = bx * ay - by * ax; /* weight of p2 */
    double det, tt, inv;
    /* Missed where the weights differ in sign: some below 0 and some
       above, i.e. the least below 0 and the largest above (as minsd and
       maxsd: 4 instructions where testing each weight twice took 12 of
       the test's 80).  A NaN weight, which these could take either way,
       makes det and tt NaN below: a miss whichever way it goes here.
       Bitwise, not short-circuit: one branch (mostly "missed", so well
       predicted) rather than two that go either way. */
    {
        double lo = e0 < e1 ? e0 : e1, hi = e0 > e1 ? e0 : e1;
        lo = lo < e2 ? lo : e2;
        hi = hi > e2 ? hi : e2;
        if ((lo < 0.0) & (hi > 0.0))
            return 0;
    }
    det = e0 + e1 + e2;
    if (det == 0.0)
        return 0;
    inv = 1.0 / det;
    tt = (e0 * az + e1 * bz + e2 * cz) * w->sz * inv;
    if (!(tt >= tmin && tt <= tmax))
        return 0;
    *t = tt;
    *u = e1 * inv;
    *v = e2 * inv;
    return 1;
}

/* One triangle's entry of rtpi_tri_edges (the exact moves') and of the
   light buffer's edges (lb_edges), which must be the same numbers: its
   plane's normal q[0..2] and constant d, and edge 2's, interleaved, then
   edges 0 and 1 (rtpi_edges_sure's layout); each edge's plane through
   the light, n_i and n_i.light. */
static RTPI_FORCE_INLINE void rtpi_tri_edge_entry(double *e, const rtp_scene *s,
                                                  const rtpi_tri *t, rtpi_v3 light,
                                                  const double *q, double d)
{
    rtpi_v3 A = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[0]), light);
    rtpi_v3 B = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[1]), light);
    rtpi_v3 C = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[2]), light);
    rtpi_v3 n[3];
    int k;
    n[0] = v3_cross(C, B);
    n[1] = v3_cross(A, C);
    n[2] = v3_cross(B, A);
    e[0] = q[0];
    e[2] = q[1];
    e[4] = q[2];
    e[6] = d;
    e[1] = n[2].x;
    e[3] = n[2].y;
    e[5] = n[2].z;
    e[7] = v3_dot(n[2], light);
    for (k = 0; k < 2; k++) {
        e[8 + k] = n[k].x;
        e[10 + k] = n[k].y;
        e[12 + k] = n[k].z;
        e[14 + k] = v3_dot(n[k], light);
    }
}

/* rtpi_tri_edges' test, the ray's origin o set up once a walk (SSE2,
   which every x86-64 has: two of the three edges in one vector, whose
   lanes round each operation as the plain code does; RTP_NO_SSE2 makes
   the plain code, the same answers). */
#if defined(__SSE2__) && !defined(RTP_NO_SSE2)
#include <emmintrin.h>
#define RTPI_EDGE_SSE2 1
#endif
typedef struct rtpi_edge_o {
#ifdef RTPI_EDGE_SSE2
    __m128d x, y, z;
#endif
    double ox, oy, oz;
} rtpi_edge_o;

static inline void rtpi_edge_o_make(rtpi_edge_o *eo, const rtpi_v3 *o)
{
#ifdef RTPI_EDGE_SSE2
    eo->x = _mm_set1_pd(o->x);
    eo->y = _mm_set1_pd(o->y);
    eo->z = _mm_set1_pd(o->z);
#endif
    eo->ox = o->x;
    eo->oy = o->y;
    eo->oz = o->z;
}

/* Edge entry e's test (rtpi_edges_miss below), with a third
   answer: 0 where it turns the ray away (the segment misses the
   triangle), 1 where the line from the light through o passes inside all
   three edges by more than thr (n.o - n.light all above thr, or all below
   -thr), else 2.  For 1: the proof at rtpi_tri_edges bounds each of
   rtpi_wt_tri's computed weights within k' m of its exact value -k'
   n_i.(o - L), whose sizes then exceed k' m: the three computed weights
   are of one sign and none 0, so the watertight test passes its sign test
   and det != 0, and what it answers is its t's test alone
   (rtpi_wt_t_sure).  (The light buffer's walk and first, the kd-tree's
   exact walk and EXACT's cached triangles ask it.) */
static RTPI_FORCE_INLINE int rtpi_edges_sure(const double *e, const rtpi_edge_o *eo, double thr)
{
    double p, e0, e1, e2, lo, hi;
#ifdef RTPI_EDGE_SSE2
    __m128d v = _mm_add_pd(_mm_mul_pd(_mm_loadu_pd(e), eo->x),
                           _mm_mul_pd(_mm_loadu_pd(e + 2), eo->y));
    v = _mm_add_pd(v, _mm_mul_pd(_mm_loadu_pd(e + 4), eo->z));
    p = _mm_cvtsd_f64(v);
    if (p > e[6])
        return 0;
    e2 = _mm_cvtsd_f64(_mm_unpackhi_pd(v, v)) - e[7];
    v = _mm_add_pd(_mm_mul_pd(_mm_loadu_pd(e + 8), eo->x),
                   _mm_mul_pd(_mm_loadu_pd(e + 10), eo->y));
    v = _mm_sub_pd(_mm_add_pd(v, _mm_mul_pd(_mm_loadu_pd(e + 12), eo->z)), _mm_loadu_pd(e + 14));
    e0 = _mm_cvtsd_f64(v);
    e1 = _mm_cvtsd_f64(_mm_unpackhi_pd(v, v));
#else
    p = e[0] * eo->ox + e[2] * eo->oy + e[4] * eo->oz;
    if (p > e[6])
        return 0;
    e2 = e[1] * eo->ox + e[3] * eo->oy + e[5] * eo->oz - e[7];
    e0 = e[8] * eo->ox + e[10] * eo->oy + e[12] * eo->oz - e[14];
    e1 = e[9] * eo->ox + e[11] * eo->oy + e[13] * eo->oz - e[15];
#endif
    lo = e0 < e1 ? e0 : e1;
    hi = e0 > e1 ? e0 : e1;
    lo = lo < e2 ? lo : e2;
    hi = hi > e2 ? hi : e2;
    if ((lo < -thr) & (hi > thr))
        return 0;
    return ((lo > thr) | (hi < -thr)) ? 1 : 2;
}

/* Whether a shadow ray from o (eo) towards the light of rtpi_tri_edges'
   entry e (a triangle's 16 doubles) misses the triangle: its light's
   plane test first (rtpi_tri_planes' n.o > n.p0 + t, the same sums in
   the same order), then the edges' (the line from the light through o
   passes outside one edge by more than thr, RTPI_EDGE_MARGIN scale^3,
   and inside another).  o within the scale.  (The plane and the third
   edge in one vector, the first two edges in another, each lane in the
   plain code's order: 24 instructions for both tests where the plane's
   alone took 12 and the edges' scalar code 40.) */
static RTPI_FORCE_INLINE int rtpi_edges_miss(const double *e, const rtpi_edge_o *eo, double thr)
{
    return rtpi_edges_sure(e, eo, thr) == 0;
}

/* Where rtpi_edges_sure answered 1 for the triangle (p0, p1, p2): 1 when
   rtpi_wt_tri's t certainly lies in [tmin, tmax] (the test then reports
   the hit), else 0 (it must be asked).  kz, oz, sz: rtpi_wt_make's.  Its
   t is (e0 z0 + e1 z1 + e2 z2) sz / det with the weights e_i of one sign,
   z_i = p_i[kz] - oz as it makes them: the weighted mean of the z_i sz,
   weights in [0, 1] summing to 1, to within 9 u Z |sz| (Z = max |z_i|,
   u = 2^-53: the sum's rounding below 3 u Z |det| with the weights of one
   sign, then two products and the division's); so within [min z_i sz,
   max z_i sz] widened by 1e-13 max |z_i sz| (each product's own rounding
   included) it is in range wherever that widened interval is.  A NaN
   fails. */
static RTPI_FORCE_INLINE int rtpi_wt_t_sure(const float *p0, const float *p1, const float *p2,
                                              int kz, double oz, double sz, double tmin,
                                              double tmax)
{
    double z0 = ((double)p0[kz] - oz) * sz, z1 = ((double)p1[kz] - oz) * sz,
           z2 = ((double)p2[kz] - oz) * sz, lo, hi, m;
    lo = z0 < z1 ? z0 : z1;
    hi = z0 > z1 ? z0 : z1;
    lo = lo < z2 ? lo : z2;
    hi = hi > z2 ? hi : z2;
    m = 1e-13 * (fabs(lo) > fabs(hi) ? fabs(lo) : fabs(hi));
    return lo - m >= tmin && hi + m <= tmax;
}

/* rtpi_wt_make's kz, oz and sz for ray r (not its whole set-up: gears'
   lightbuf move 143 k of them, 45 instructions each), for a direction
   rtpi_wt_valid accepts: else 0 (the test reports no hit: asked there). */
static RTPI_FORCE_INLINE int rtpi_wt_z(const rtpi_ray *r, int *kz, double *oz, double *sz)
{
    double ax = fabs(r->d.x), ay = fabs(r->d.y), az = fabs(r->d.z);
    int k;
    if (!rtpi_wt_valid(r))
        return 0;
    k = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
    *kz = k;
    *oz = k == 0 ? r->o.x : k == 1 ? r->o.y : r->o.z;
    *sz = 1.0 / (k == 0 ? r->d.x : k == 1 ? r->d.y : r->d.z);
    return 1;
}

/* @return 1 when (p1-p0)x(p2-p0), in double from the float vertices, is
   exactly zero: such a triangle has no plane and is never hit. */
static inline int rtpi_tri_degenerate(const float *p0, const float *p1,
                                      const float *p2)
{
    double e1x = (double)p1[0] - p0[0], e1y = (double)p1[1] - p0[1],
           e1z = (double)p1[2] - p0[2];
    double e2x = (double)p2[0] - p0[0], e2y = (double)p2[1] - p0[1],
           e2z = (double)p2[2] - p0[2];
    double nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z,
           nz = e1x * e2y - e1y * e2x;
    /* Also rejects NaN/infinite vertices: their normal is never finite. */
    return !(fabs(nx) + fabs(ny) + fabs(nz) > 0.0) ||
           !(fabs(nx) + fabs(ny) + fabs(nz) <= 1.79e308);
}


/* Roots of |o + t d - c|^2 = r^2, t0 <= t1.  The origin is first moved to
 * the point of the ray closest to the centre (parameter tc), so the
 * quadratic is solved with numbers of the size of r instead of the size of
 * the distance (Ray Tracing Gems, ch. 7: the discriminant comes from the
 * squared distance of the centre to the line, never from b^2 - ac), and tc
 * is added back.  At distance/radius 1e5 this keeps ~1e-11 relative error
 * in the hit point, where the textbook formula loses all digits. */
static RTPI_FORCE_INLINE int rtpi_sphere_roots(const rtpi_sphere *sp, const rtpi_ray *ray,
                                               double a, double *t0, double *t1)
{
    rtpi_v3 c = v3_from_f(sp->c), o2, f, l;
    double r = fabs((double)sp->r);
    double tc, b, disc, half;
    if (!(a > 0.0) || !(r > 0.0))
        return 0;
    tc = v3_dot(v3_sub(c, ray->o), ray->d) / a;
    o2 = v3_madd(ray->o, ray->d, tc);
    f = v3_sub(o2, c);
    b = -v3_dot(f, ray->d); /* ~0 by construction; kept for exactness */
    l = v3_madd(f, ray->d, b / a); /* centre -> closest point of the line */
    disc = r * r - v3_dot(l, l);
    if (!(disc >= 0.0))
        return 0;
    half = sqrt(disc / a);
    *t0 = tc + b / a - half;
    *t1 = tc + b / a + half;
    return 1;
}

/* Where ray meets sphere sp within [tmin, tmax]: 1 with *t, else 0.  a:
   v3_dot(ray->d, ray->d), made once a ray by the callers that test many
   primitives (a tenth of a sphere's test).  Here, not in intersect.c
   alone, so that a shadow ray's walk through the kd-tree tests spheres
   inline, by this very code (the call through rtpi_intersect_prim was a
   fifth of a sphere's test). */
static RTPI_FORCE_INLINE int rtpi_sphere_t(const rtpi_sphere *sp, const rtpi_ray *ray, double a,
                                           double *t)
{
    double t0, t1;
    if (!rtpi_sphere_roots(sp, ray, a, &t0, &t1))
        return 0;
    /* r < 0: only the inside is visible, i.e. only where the ray leaves. */
    if (sp->r > 0.0f && t0 >= ray->tmin && t0 <= ray->tmax) {
        *t = t0;
    } else if (t1 >= ray->tmin && t1 <= ray->tmax) {
        *t = t1;
    } else {
        return 0;
    }
    return 1;
}

/* A cone's (frame cf's) first test for ray: 0 where the cone or the
   direction is degenerate or the ray's line passes farther from the
   cone's middle than its bound, so the ray misses it; else 1 with tc
   and o2 = o + tc d, the line's point nearest the middle.  a:
   v3_dot(ray->d, ray->d) (as for rtpi_sphere_t).  hit_cone
   (intersect.c) starts with it, and shadow rays in the kd-tree ask it
   inline before rtpi_cone_t (most of their cones end here). */
static RTPI_FORCE_INLINE int rtpi_cone_near(const rtpi_cone_frame *cf, const rtpi_ray *ray,
                                            double a, double *tc, rtpi_v3 *o2)
{
    rtpi_v3 mid, g;
    double lim;
    if (!cf->ok)
        return 0;
    if (!(a > 0.0))
        return 0;
    /* As for spheres: move the origin next to the cone's middle first so the
       quadratic sees numbers of the cone's size, then add tc back. */
    mid = cf->mid;
    *tc = v3_dot(v3_sub(mid, ray->o), ray->d) / a;
    *o2 = v3_madd(ray->o, ray->d, *tc);
    /* A line farther from mid than the cone's bound misses it: most
       tests of a shadow ray among cones end here, before the quadratic.
       o2 is the line's point nearest mid up to rounding of the size of
       |tc| |d| 2^-52 (its offset from mid and the direction are then not
       quite perpendicular): 1e-9 |tc| |d| more covers that, so no line
       the quadratic would find a hit on is turned away. */
    g = v3_sub(*o2, mid);
    lim = cf->bound + 1e-9 * fabs(*tc) * sqrt(a);
    return !(v3_dot(g, g) > lim * lim);
}

/* Whether a cylinder's (frame cf's, ra == rb) test certainly finds no
   hit for ray, after rtpi_cone_near said 1 with tc and o2: 1 where the
   ray's line passes farther from the axis than the radius R plus a
   margin, so rtpi_cone_t would say 0; else 0.  ld: sqrt(a); ts: |tmin|
   + |tmax|.  A thin cylinder's bounding sphere (rtpi_cone_near) lets
   through most lines that pass it (rings: 0.074 thick, 1.1 long), and
   this costs a third of rtpi_cone_t's quadratic.

   Why the margin suffices.  With f = o2 - b, the line's distance from
   the axis is D = |f.n| / |n|, n = d x w.  rtpi_cone_t (k = 0: s0 = R,
   sd = 0) solves |q0 + r qd|^2 = R^2 for the parts q0, qd of f and d
   across the axis; a hit needs tt = tc + r in [tmin, tmax], so |r| <= T
   = |tc| + ts (to rounding).  Its computed q0, qd are within a few u
   (u = 2^-53) of |f| and |d| of the true ones; its discriminant errs by
   a few u (qb^2 + qa |qc|) <= a few u qa (|q0|^2 + R^2) (Cauchy-Schwarz:
   qb^2 <= qa |q0|^2), which is a change of qc by a few u (|f|^2 + R^2);
   the citardauq roots are exact roots of coefficients changed by a few
   u more.  So at a root it reports, the true point o2 + r d lies within
   R + c u ((|f| + T |d|)^2 / R + |f| + T |d|) of the axis, c well under
   100: a hit there needs D below that.  The margin m below is 1e-12 (S
   + S^2 / R) with S = 2 bound + (2 |tc| + ts) |d| >= |f| + T |d| (|f|
   <= |o2 - mid| + h/2, and rtpi_cone_near let o2 through within bound
   + 1e-9 |tc| |d| of mid), over 40 times that bound; its own test's
   rounding (of f.n and |n|, a few u |f| |d| and u |d|) is the 1e-12 (S
   + R) |d| added.  A line nearly along the axis (|n| of the
   order of u |d|) is then never turned away; an unbounded ray (tmax
   infinite) makes m infinite or the product NaN: never turned away. */
static RTPI_FORCE_INLINE int rtpi_cylinder_far(const rtpi_cone_frame *cf, const rtpi_ray *ray,
                                               double tc, rtpi_v3 o2, double ld, double ts)
{
    rtpi_v3 f = v3_sub(o2, cf->b), n = v3_cross(ray->d, cf->w);
    double R = cf->rb, S = 2.0 * cf->bound + (2.0 * fabs(tc) + ts) * ld;
    double m = 1e-12 * (S + S * (S / R));
    return fabs(v3_dot(f, n)) > (R + m) * sqrt(v3_dot(n, n)) + 1e-12 * (S + R) * ld;
}

/* Spheres seen from one light L (rtpi_sphere_entries, intersect.c):
   rtpi_sphere_t's answer for a shadow ray towards L decided without it
   where a margin makes the cheap answer certain.  Entry e: g = C - L and
   k = |g|^2 - r^2, made once a light.  The ray is rtpi_shadow_ray(o, L)
   (d of unit length to a few u, tmax = |L - o| (1 - 1e-9)), every
   coordinate of o, L and the spheres (c +- r) at most S in magnitude
   (rtpi_tri_planes' scale; the callers ask |o| <= S).  With the line
   written from the light, X(s) = L - s d (s = |L - o| - t): |X - C|^2 =
   r^2 at s = P -+ sqrt(Q), P = d.(L - C) = -d.g, Q = P^2 - k (|d|^2
   taken as 1).  @return 1 where rtpi_sphere_t says hit, 0 where it says
   miss, -1 where the margins do not decide it (ask rtpi_sphere_t); io:
   the sphere is inside-only (r < 0: only the root nearer the light, its
   larger t, counts, as there).

   Why it is exact (u = 2^-53; every length below 3.5 S: |C - o|, |g|,
   |L - o| <= 2 sqrt(3) S, r <= S).  rtpi_sphere_roots' disc = r^2 -
   |l|^2 is within 400 u S^2 of r^2 - D^2 for the exact line o + t d (its
   d, as rounded), D the centre's distance from it (tc within 25 u S,
   o2 40, f 45, l 50 u S off, each squared term's rounding), and its
   centre tc + b / a within 80 u S of the exact nearest point's t.  The
   exact line passes within 5 u |L - o| <= 18 u S of L (d's rounding:
   rtpi_shadow_ray), so P is within 34 u S of the exact line's own
   value, k within 200 u S^2 (g's and the squares' rounding, the line's
   offset), |d|^2 within 10 u of 1, and Q within 700 u S^2 of that
   line's a (r^2 - D^2): Q and a disc differ by at most 1200 u S^2 <
   1.4e-13 S^2.  mq = 1e-11 S^2 is 70 times that: Q < -mq makes
   rtpi_sphere_roots' disc negative (a miss there), Q > mq its disc
   positive, with both square roots (over sqrt(mq - 1.4e-13 S^2) >= 3e-6
   S) within 1e-11 S of the exact chord's half and every root, its and
   these, within 2e-10 S of the exact line's.  t = |L - o| - s and |L -
   o| - tmax <= 3.6e-9 S (the 1e-9 and the rounding of tmax), so a root
   s in [m, tmax - tmin - m], m = 1e-7 S, is there a t within [tmin,
   tmax] by more than 9e-8 S, and one outside [-m, tmax - tmin + m] a t
   outside it: the answer is that root's.  For |Q| <= mq the roots
   rtpi_sphere_t may find lie within sqrt(mq + 1.4e-13 S^2) + 2e-10 S <
   3.2e-6 S of P: P beyond [-m3, tmax - tmin + m3], m3 = 5e-6 S, puts
   them all outside the range.  A NaN anywhere fails every comparison:
   -1.  (test_quadric_sure asks it against rtpi_sphere_t on rays through
   silhouettes, tangent, at the range's ends; it fails with the margins
   dropped.) */
typedef struct rtpi_quad_k {
    double mq, m, m3; /* spheres' (rtpi_sphere_sure) */
    double cq, c1, c2; /* cylinders' (rtpi_cyl_sure) */
} rtpi_quad_k;

static inline void rtpi_quad_k_make(double S, rtpi_quad_k *k)
{
    k->mq = 1e-11 * S * S;
    k->m = 1e-7 * S;
    k->m3 = 5e-6 * S;
    k->cq = 1e-10 * S * S;
    k->c1 = 1e-6 * S;
    k->c2 = 1e-8 * S;
}

static RTPI_FORCE_INLINE int rtpi_sphere_sure(const double *e, int io, const rtpi_ray *ray,
                                              const rtpi_quad_k *k)
{
    double P = -(ray->d.x * e[0] + ray->d.y * e[1] + ray->d.z * e[2]);
    double Q = P * P - e[3], top = ray->tmax - ray->tmin;
    if (Q > k->mq) {
        double sq = sqrt(Q), s1 = P - sq, s2 = P + sq, m = k->m;
        if ((s1 >= m && s1 <= top - m) || (!io && s2 >= m && s2 <= top - m))
            return 1;
        return (s1 < -m || s1 > top + m) && (io || s2 < -m || s2 > top + m) ? 0 : -1;
    }
    if (Q < -k->mq || P < -k->m3 || P > top + k->m3)
        return 0;
    return -1;
}

/* Cylinders (ra == rb) seen from one light L, as rtpi_sphere_sure:
   rtpi_cone_near and rtpi_cone_t's answer (hit_cone's) for a shadow
   ray towards L, from entry e (rtpi_cyl_entries: with g = L - b, gw =
   g.w, gp = g - gw w: gp, gw, kc = |gp|^2 - R^2, h), where margins make
   it certain; 1 hit, 0 miss, -1 ask the full test.  Same conditions on
   the ray and S.  The line from the light, X(s) = L - s d (s = |L - o|
   - t), meets the infinite cylinder where |gp - s dp|^2 = R^2, dp = d -
   dw w, dw = d.w: A s^2 - 2 B s + kc = 0 with A = 1 - dw^2 (|d|^2 taken
   as 1), B = d.gp, Q = B^2 - A kc, s = (B -+ sqrt Q) / A, at height H =
   gw - s dw.  hit_cone's answer: some root with t in [tmin, tmax] and
   its height in [0, h].

   Why it is exact (u = 2^-53, lengths below 3.5 S as for spheres; the
   cylinder is the frame's b, w, h, R as doubles, which both tests use).
   rtpi_cone_t's coefficients (from o2, its f, h0, q0, qd) err by at most
   15 u (qa), 150 u S (qb), 950 u S^2 (qc), so its disc by 2500 u S^2,
   and with o2's own offset from the line (40 u S) by under 3000 u S^2
   from the exact line's A (R^2 - D^2); Q here errs by under 1500 u S^2
   (gp's and kc's rounding, B's 70 u S with the exact line's 18 u S
   offset from L, A's 20 u): the two differ by under 5000 u S^2 < 6e-13
   S^2, and cq = 1e-10 S^2 is 160 times that.  Q < -cq: its disc is
   negative, a miss.  Q > cq and A >= 1e-3 (the line at least 1.8
   degrees off the axis): both square roots exceed 1e-5 S and err by
   under 1.6e-8 S, so each root, its (with tc's 25 u S) and these, lies
   within 2e-8 S / A + 30 u S of the exact line's, |s| <= 10 S / A
   adding under 2.2e-11 S / A through A's error; each height (h0's 60 u
   S, the root's error times |dw| <= 1) as close.  The margin M = c1 / A
   + c2 (1e-6 S / A + 1e-8 S) is over 40 times that and covers |L - o| -
   tmax <= 3.6e-9 S: a root inside [M, top - M] with its height inside
   [M, h - M] is a hit of rtpi_cone_t's at t within [tmin, tmax] (and
   rtpi_cone_near passes it: the point lies within sqrt(h^2/4 + R^2) of
   the middle, and rtpi_cyl_entries leaves out cylinders whose bound,
   1e-6 larger, is below 1e-7 S, where the 60 u S of its own test could
   matter); both roots outside [-M, top + M] or their heights outside
   [-M, h + M]: a miss.  Else, and for |Q| <= cq or A < 1e-3, -1; NaN
   anywhere (entries of cones that are not cylinders) fails every
   comparison: -1.  (test_cyl_sure; it fails with the margins
   dropped.) */
static RTPI_FORCE_INLINE int rtpi_cyl_sure(const double *e, const rtpi_cone_frame *cf,
                                           const rtpi_ray *ray, const rtpi_quad_k *k)
{
    double dw = ray->d.x * cf->w.x + ray->d.y * cf->w.y + ray->d.z * cf->w.z;
    double A = 1.0 - dw * dw, B = ray->d.x * e[0] + ray->d.y * e[1] + ray->d.z * e[2];
    double Q = B * B - A * e[4], top = ray->tmax - ray->tmin;
    if (Q < -k->cq)
        return 0;
    if (Q > k->cq && A >= 1e-3) {
        double ia = 1.0 / A, sq = sqrt(Q), M = k->c1 * ia + k->c2, h = e[5];
        double s1 = (B - sq) * ia, s2 = (B + sq) * ia;
        double h1 = e[3] - s1 * dw, h2 = e[3] - s2 * dw;
        if ((s1 >= M && s1 <= top - M && h1 >= M && h1 <= h - M) ||
            (s2 >= M && s2 <= top - M && h2 >= M && h2 <= h - M))
            return 1;
        if ((s1 < -M || s1 > top + M || h1 < -M || h1 > h + M) &&
            (s2 < -M || s2 > top + M || h2 < -M || h2 > h + M))
            return 0;
    }
    return -1;
}

/* The rest of a cone's test after rtpi_cone_near said 1 (a, tc, o2 as
   it gave them): 1 with *t where ray meets the cone's nappe between
   base and apex within [tmin, tmax], else 0 (intersect.c). */
int rtpi_cone_t(const rtpi_cone_frame *cf, const rtpi_ray *ray, double a, double tc,
                rtpi_v3 o2, double *t);

#endif /* RTP_KDTREE_H */
