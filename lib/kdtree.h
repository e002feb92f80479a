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
    double o[3];
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
    w->o[0] = r->o.x;
    w->o[1] = r->o.y;
    w->o[2] = r->o.z;
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
    const double ox = w->o[kx], oy = w->o[ky], oz = w->o[kz];
    double az = p0[kz] - oz, bz = p1[kz] - oz, cz = p2[kz] - oz;
    double ax = (p0[kx] - ox) - w->sx * az, ay = (p0[ky] - oy) - w->sy * az;
    double bx = (p1[kx] - ox) - w->sx * bz, by = (p1[ky] - oy) - w->sy * bz;
    double cx = (p2[kx] - ox) - w->sx * cz, cy = (p2[ky] - oy) - w->sy * cz;
    double e0 = cx * by - cy * bx; /* weight of p0 */
    double e1 = ax * cy - ay * cx; /* weight of p1 */
    double e2 = bx * ay - by * ax; /* weight of p2 */
    double det, tt, inv;
    /* Bitwise, not short-circuit: one branch (mostly "missed", so well
       predicted) rather than up to six that go either way. */
    if (((e0 < 0.0) | (e1 < 0.0) | (e2 < 0.0)) &
        ((e0 > 0.0) | (e1 > 0.0) | (e2 > 0.0)))
        return 0;
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


#endif /* RTP_KDTREE_H */
