/* intersect.c — ray/primitive intersection, surface data at a hit, bounds
 * and the self-intersection offset.  Everything is computed in double from
 * the scene's float geometry. */
#include "kdtree.h"

#define RTPI_PI 3.14159265358979323846

/* ----------------------------------------------------------- triangles */

static int hit_tri(const rtp_scene *s, const rtpi_tri *tr, const rtpi_ray *ray,
                   rtpi_hit *hit)
{
    const float *p0 = s->pos + 3 * (size_t)tr->v[0];
    const float *p1 = s->pos + 3 * (size_t)tr->v[1];
    const float *p2 = s->pos + 3 * (size_t)tr->v[2];
    rtpi_wt_ray w;
    if (rtpi_tri_degenerate(p0, p1, p2) || !rtpi_wt_setup(&w, ray))
        return 0;
    return rtpi_wt_tri(&w, p0, p1, p2, ray->tmin, ray->tmax, &hit->t, &hit->u,
                       &hit->v);
}

/* ------------------------------------------------------------- spheres */

static int hit_sphere(const rtpi_sphere *sp, const rtpi_ray *ray,
                      rtpi_hit *hit)
{
    if (!rtpi_sphere_t(sp, ray, v3_dot(ray->d, ray->d), &hit->t))
        return 0;
    hit->u = hit->v = 0.0;
    return 1;
}

/* --------------------------------------------------- cones and cylinders */

typedef rtpi_cone_frame cone_frame;

void rtpi_cone_frame_of(const rtpi_cone *cn, rtpi_cone_frame *f)
{
    rtpi_v3 ax;
    memset(f, 0, sizeof *f);
    f->b = v3_from_f(cn->base);
    ax = v3_sub(v3_from_f(cn->apex), f->b);
    f->h = v3_len(ax);
    f->rb = fabs((double)cn->rb);
    f->ra = fabs((double)cn->ra);
    /* No height or no radius at all: a disc edge or a line, nothing to hit. */
    if (!(f->h > 0.0) || !(f->rb + f->ra > 0.0) || !(f->h < 1e300))
        return;
    f->w = v3_mul(ax, 1.0 / f->h);
    f->k = (f->ra - f->rb) / f->h;
    f->mid = v3_madd(f->b, f->w, 0.5 * f->h);
    /* every point of the nappe between base and apex lies within
       sqrt((h/2)^2 + max(rb, ra)^2) of mid; 1e-6 more covers rounding in
       it and in hit_cone's own arithmetic many times over */
    {
        double r = f->rb > f->ra ? f->rb : f->ra;
        f->bound = sqrt(0.25 * f->h * f->h + r * r) * (1.0 + 1e-6);
    }
    f->ok = 1;
}

/* Orthonormal e1, e2 perpendicular to unit n (Duff et al. 2017). */
static void basis(rtpi_v3 n, rtpi_v3 *e1, rtpi_v3 *e2)
{
    double sg = n.z >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sg + n.z);
    double b = n.x * n.y * a;
    *e1 = v3(1.0 + sg * n.x * n.x * a, sg * b, -sg * n.x);
    *e2 = v3(b, sg + n.y * n.y * a, -n.y);
}

/* (hit_cone's rest, inline in it: a call there cost the light buffer's
   queries among cones 1%) */
static RTPI_FORCE_INLINE int cone_rest(const rtpi_cone_frame *cf, const rtpi_ray *ray, double a,
                                       double tc, rtpi_v3 o2, double *t)
{
    rtpi_v3 f, q0, qd;
    double h0, hd, s0, sd, qa, qb, qc, disc, q, r[2], lo = 0.0, hi = cf->h;
    int n = 0, i;
    if (cf->ra == 0.0 || cf->rb == 0.0) {
        /* A cone that comes to a point: a line passing near its tip meets
           the cone and its mirror image beyond the tip near the same
           place, a near double root, which the quadratic about the
           middle gives only to ~1e-8 of the cone's size (the difference
           of two squares of its size): within 2e-8 of a tip the mirror
           image's root was taken for the cone's (a light at the tip
           shadowed speckles of the floor in a trace, and the light
           buffer, listing what can be hit to 1e-13, disagreed).  About
           the line's point nearest the tip every coefficient is of the
           line's distance from it, and the roots as exact as the
           point. */
        double hp = cf->ra == 0.0 ? cf->h : 0.0;
        rtpi_v3 tip = v3_madd(cf->b, cf->w, hp), g;
        double ta = v3_dot(v3_sub(tip, o2), ray->d) / a;
        /* (the middle's roots err by ~1.5e-8 of the size, so only lines
           that close to the tip need this; 1e-4 of it keeps the tip's
           own numbers small and is far outside that) */
        double lim = 1e-4 * (cf->h + cf->rb + cf->ra);
        rtpi_v3 o3 = v3_madd(o2, ray->d, ta);
        g = v3_sub(o3, tip);
        if (v3_dot(g, g) < lim * lim) {
            /* heights from the tip: the nappe lies in [lo, hi] */
            tc += ta;
            h0 = v3_dot(g, cf->w);
            hd = v3_dot(ray->d, cf->w);
            q0 = v3_madd(g, cf->w, -h0);
            qd = v3_madd(ray->d, cf->w, -hd);
            s0 = cf->k * h0;
            lo = -hp;
            hi = cf->h - hp;
            goto solve;
        }
    }
    f = v3_sub(o2, cf->b);
    /* Point o2 + t d: height h0 + t hd, offset from the axis q0 + t qd,
       cone radius there s0 + t sd.  Surface: |q|^2 = s^2. */
    h0 = v3_dot(f, cf->w);
    hd = v3_dot(ray->d, cf->w);
    q0 = v3_madd(f, cf->w, -h0);
    qd = v3_madd(ray->d, cf->w, -hd);
    s0 = cf->rb + cf->k * h0;
solve:
    sd = cf->k * hd;
    qa = v3_dot(qd, qd) - sd * sd;
    qb = v3_dot(q0, qd) - s0 * sd;
    qc = v3_dot(q0, q0) - s0 * s0;
    disc = qb * qb - qa * qc;
    if (!(disc >= 0.0))
        return 0;
    /* Citardauq form: no cancellation in either root.  qa == 0 (a ray along
       a generator line, or any ray parallel to a cylinder's axis) leaves
       the single root qc/q; q == 0 then means the ray lies on the surface
       or never meets it: a miss. */
    q = -(qb + (qb >= 0.0 ? sqrt(disc) : -sqrt(disc)));
    if (q != 0.0) {
        r[n++] = qc / q;
        if (qa != 0.0)
            r[n++] = q / qa;
    } else if (qa != 0.0) {
        r[n++] = 0.0; /* qb == 0 and qc == 0: tangent at o2 */
    }
    if (n == 2 && r[1] < r[0]) {
        double x = r[0];
        r[0] = r[1];
        r[1] = x;
    }
    for (i = 0; i < n; i++) {
        double tt = tc + r[i];
        double hh = h0 + r[i] * hd;
        /* Keeps to the nappe between base and apex (the quadratic also
           describes the mirrored cone beyond the apex). */
        if (tt >= ray->tmin && tt <= ray->tmax && hh >= lo && hh <= hi) {
            *t = tt;
            return 1;
        }
    }
    return 0;
}

int rtpi_cone_t(const rtpi_cone_frame *cf, const rtpi_ray *ray, double a, double tc,
                rtpi_v3 o2, double *t)
{
    return cone_rest(cf, ray, a, tc, o2, t);
}

static int hit_cone(const cone_frame *cf, const rtpi_ray *ray, rtpi_hit *hit)
{
    rtpi_v3 o2;
    double a = v3_dot(ray->d, ray->d), tc;
    if (!rtpi_cone_near(cf, ray, a, &tc, &o2) || !cone_rest(cf, ray, a, tc, o2, &hit->t))
        return 0;
    hit->u = hit->v = 0.0;
    return 1;
}

/* ------------------------------------------------------------ interface */

int rtpi_intersect_prim(const rtp_scene *s, uint32_t prim, const rtpi_ray *ray,
                        rtpi_hit *hit)
{
    size_t i = prim;
    int r;
    if (i < s->ntris) {
        r = hit_tri(s, &s->tris[i], ray, hit);
    } else if ((i -= s->ntris) < s->nspheres) {
        r = hit_sphere(&s->spheres[i], ray, hit);
    } else if ((i -= s->nspheres) < s->ncones) {
        r = hit_cone(&s->cframes[i], ray, hit);
    } else {
        return 0;
    }
    if (r)
        hit->prim = prim;
    return r;
}

/* Whether all three vertex normals of tr point away from ng (the side
   its winding makes its front). */
static int all_away(const rtp_scene *s, const rtpi_tri *tr, rtpi_v3 ng)
{
    int k;
    for (k = 0; k < 3; k++)
        if (!(v3_dot(v3_from_f(s->nrm + 3 * (size_t)tr->n[k]), ng) < 0.0))
            return 0;
    return 1;
}

/* Whether prim shadows a point of its own whose shadow ray starts at o:
   0 no, 1 yes, -1 cannot tell.  A triangle never does.  A sphere does
   exactly when the segment from o to the light crosses it where it
   counts: o and the light on different sides for r > 0 (a point inside
   a glass sphere, reached by a refracted ray, with the light outside);
   o inside and the light outside for r < 0 (the ray leaves through the
   visible inside).  An open cone bounds a convex solid: from its outside
   (o radially beyond the wall, so the normal towards o is the outward
   one and faces the light) the ray runs away from the solid and cannot
   meet the wall again; from its inside it may. */
int rtpi_prim_shadows_own_solid(const rtp_scene *s, uint32_t prim, rtpi_v3 o, rtpi_v3 L)
{
    size_t i = prim;
    if (i < s->ntris)
        return 0;
    if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 c = v3_from_f(sp->c), oc = v3_sub(o, c), lc = v3_sub(L, c);
        double r = fabs((double)sp->r), r2 = r * r, d2o = v3_dot(oc, oc), d2l = v3_dot(lc, lc);
        double big = d2o > d2l ? d2o : d2l;
        int oin = d2o < r2, lin = d2l < r2;
        /* A light on the surface: a shadow ray stops 1e-9 of its length
           short of the light (rtpi_shadow_ray), so a crossing that close
           to it does not count, whichever side the light rounds to (an
           item buffer took the glass ball's inside as shadowed by the
           ball for a light on it: 0.24 off).  Within twice that, and
           double rounding's few 1e-16 of the sizes, say cannot tell.
           (Squares first: |dl^2 - r^2| beyond 1e-8 of the largest square
           is beyond that band, with no square root; o lies a float
           offset off its surface, far outside any rounding.) */
        if (fabs(d2l - r2) <= 1e-8 * (big > r2 ? big : r2)) {
            double dl = sqrt(d2l);
            if (fabs(dl - r) <= 2e-9 * v3_len(v3_sub(L, o)) + 1e-14 * (r + dl))
                return -1;
        }
        return sp->r > 0.0f ? oin != lin : oin && !lin;
    }
    if ((i -= s->nspheres) < s->ncones)
        return rtpi_cone_shadows_own(s, i, &o);
    return -1;
}

void rtpi_sphere_entries(const rtp_scene *s, rtpi_v3 light, double scale, const rtp_allocator *a,
                         double **out)
{
    size_t i;
    *out = NULL;
    if (!s->nspheres || s->nspheres > RTPI_EDGE_TRIS || !(scale >= 1e-90 && scale <= 1e90))
        return;
    *out = (double *)rtpi_malloc_array(a, 4 * s->nspheres, sizeof **out);
    if (!*out)
        return;
    for (i = 0; i < s->nspheres; i++) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 g = v3_sub(v3_from_f(sp->c), light);
        double r = fabs((double)sp->r), *e = *out + 4 * i;
        e[0] = g.x;
        e[1] = g.y;
        e[2] = g.z;
        e[3] = v3_dot(g, g) - r * r;
        if (!(r > 0.0) || !(r < HUGE_VAL)) /* (rtpi_sphere_roots: no hit; NaN: -1) */
            e[0] = e[1] = e[2] = e[3] = NAN;
    }
}

void rtpi_cyl_entries(const rtp_scene *s, rtpi_v3 light, double scale, const rtp_allocator *a,
                      double **out)
{
    size_t i, n = 0;
    *out = NULL;
    if (!s->ncones || s->ncones > RTPI_EDGE_TRIS || !(scale >= 1e-90 && scale <= 1e90))
        return;
    *out = (double *)rtpi_malloc_array(a, 6 * s->ncones, sizeof **out);
    if (!*out)
        return;
    for (i = 0; i < s->ncones; i++) {
        const rtpi_cone_frame *cf = &s->cframes[i];
        double *e = *out + 6 * i;
        rtpi_v3 g = v3_sub(light, cf->b), gp;
        double gw = v3_dot(g, cf->w), R = cf->rb;
        gp = v3_madd(g, cf->w, -gw);
        e[0] = gp.x;
        e[1] = gp.y;
        e[2] = gp.z;
        e[3] = gw;
        e[4] = v3_dot(gp, gp) - R * R;
        e[5] = cf->h;
        /* (rtpi_cyl_sure: cylinders only, and none so small against the
           scale that rtpi_cone_near's rounding could matter) */
        if (!cf->ok || cf->ra != cf->rb || !(R > 0.0) || !(cf->bound >= 1e-7 * scale))
            e[0] = e[1] = e[2] = e[3] = e[4] = e[5] = NAN;
        else
            n++;
    }
    /* (none at all, as SPD's tree of cones: no entries, so that the
       walk is the one without them; asking its 2,048 cones made
       tree_s11's move 4% dearer) */
    if (!n) {
        rtpi_free(a, *out);
        *out = NULL;
    }
}

void rtpi_balls_around(const rtp_scene *s, rtpi_v3 L, unsigned char *out)
{
    size_t i;
    for (i = 0; i < s->nspheres; i++) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 lc = v3_sub(L, v3_from_f(sp->c));
        double r = fabs((double)sp->r), r2 = r * r, d2l = v3_dot(lc, lc);
        /* rtpi_prim_shadows_own_solid's operations: with o inside (its
           square below r2) its band's bound is 1e-8 max(d2l, r2) */
        out[i] = !(d2l < r2) && !(fabs(d2l - r2) <= 1e-8 * (d2l > r2 ? d2l : r2));
    }
}

static double wrap01(double x)
{
    x -= floor(x);
    return x < 1.0 ? x : 0.0;
}

void rtpi_surface_at(const rtp_scene *s, const rtpi_ray *ray,
                     const rtpi_hit *hit, rtpi_surface *out)
{
    rtpi_surface_at_ex(s, ray, hit, 1, out);
}

void rtpi_surface_at_ex(const rtp_scene *s, const rtpi_ray *ray,
                        const rtpi_hit *hit, int want_uv, rtpi_surface *out)
{
    size_t i = hit->prim;
    out->p = v3_madd(ray->o, ray->d, hit->t);
    out->uv[0] = out->uv[1] = 0.0;
    out->mat = 0;
    if (i < s->ntris) {
        const rtpi_tri *tr = &s->tris[i];
        double b0 = 1.0 - hit->u - hit->v;
        out->mat = tr->mat;
        out->ng = rtpi_tri_normal(s, tr);
        out->ns = out->ng;
        if (tr->n[0] != RTPI_NONE && tr->n[1] != RTPI_NONE &&
            tr->n[2] != RTPI_NONE) {
            rtpi_v3 n = v3_mul(v3_from_f(s->nrm + 3 * (size_t)tr->n[0]), b0);
            double dn;
            n = v3_madd(n, v3_from_f(s->nrm + 3 * (size_t)tr->n[1]), hit->u);
            n = v3_madd(n, v3_from_f(s->nrm + 3 * (size_t)tr->n[2]), hit->v);
            dn = v3_dot(n, out->ng);
            /* A triangle whose three vertex normals all point away from
               it is wound the other way round from its normals (a mesh
               written clockwise, as some exporters write them): its
               normal is turned over, which puts it on ng's side with its
               lean kept.  Mirrored, as below, the lean was reversed and a
               smooth clockwise sphere shaded faceted (0.07 off its
               counter-clockwise twin).  A triangle with only some vertex
               normals pointing away from it (a few in SPD's teapot) has
               them wrong, not its winding: those are mirrored at the
               triangle's plane, which keeps their tangential lean and
               puts them on ng's side. */
            if (dn < 0.0)
                n = all_away(s, tr, out->ng) ? v3_mul(n, -1.0) : v3_madd(n, out->ng, -2.0 * dn);
            if (v3_dot(n, n) > 0.0)
                out->ns = v3_norm(n);
        }
        if (want_uv && tr->t[0] != RTPI_NONE && tr->t[1] != RTPI_NONE &&
            tr->t[2] != RTPI_NONE) {
            const float *t0 = s->uv + 2 * (size_t)tr->t[0];
            const float *t1 = s->uv + 2 * (size_t)tr->t[1];
            const float *t2 = s->uv + 2 * (size_t)tr->t[2];
            out->uv[0] = b0 * t0[0] + hit->u * t1[0] + hit->v * t2[0];
            out->uv[1] = b0 * t0[1] + hit->u * t1[1] + hit->v * t2[1];
        }
        return;
    }
    if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 n = rtpi_sphere_normal(sp, out->p);
        out->mat = sp->mat;
        /* Longitude around z from +x, latitude from -z (0) to +z (1). */
        if (want_uv) {
            out->uv[0] = wrap01(atan2(n.y, n.x) / (2.0 * RTPI_PI));
            out->uv[1] = 0.5 + asin(n.z < -1.0 ? -1.0 : n.z > 1.0 ? 1.0 : n.z) /
                                   RTPI_PI;
        }
        if (sp->r < 0.0f)
            n = v3_mul(n, -1.0); /* inside-only: the visible side faces in */
        out->ng = out->ns = n;
        return;
    }
    if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone *cn = &s->cones[i];
        const cone_frame cf = s->cframes[i];
        rtpi_v3 q, e1, e2, n;
        double h;
        out->mat = cn->mat;
        if (!cf.ok) { /* never hit; something sane */
            out->ng = out->ns = v3(0.0, 0.0, 1.0);
            return;
        }
        /* (the frame across the axis only where it is used: a moved
           light asks every recorded hit's normal) */
        if (!rtpi_cone_normal(&cf, out->p, &n, &q, &h)) {
            basis(cf.w, &e1, &e2);
            q = e1; /* at a pointed apex: any direction across */
            n = v3_norm(v3_madd(q, cf.w, -cf.k));
        } else if (want_uv) {
            basis(cf.w, &e1, &e2);
        }
        out->ng = out->ns = n;
        if (want_uv) {
            out->uv[0] = wrap01(atan2(v3_dot(q, e2), v3_dot(q, e1)) /
                                (2.0 * RTPI_PI));
            out->uv[1] = h / cf.h < 0.0 ? 0.0 : h / cf.h > 1.0 ? 1.0 : h / cf.h;
        }
        return;
    }
    out->ng = out->ns = v3(0.0, 0.0, 1.0);
}

int rtpi_uv_tangents(const rtp_scene *s, uint32_t prim, rtpi_v3 p, rtpi_v3 *pu, rtpi_v3 *pv)
{
    size_t i = prim;
    if (i < s->ntris) {
        const rtpi_tri *t = &s->tris[i];
        const float *t0, *t1, *t2;
        rtpi_v3 p0, e1, e2;
        double du1, dv1, du2, dv2, det;
        if (t->t[0] == RTPI_NONE || t->t[1] == RTPI_NONE || t->t[2] == RTPI_NONE)
            return 0;
        t0 = s->uv + 2 * (size_t)t->t[0];
        t1 = s->uv + 2 * (size_t)t->t[1];
        t2 = s->uv + 2 * (size_t)t->t[2];
        p0 = v3_from_f(s->pos + 3 * (size_t)t->v[0]);
        e1 = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[1]), p0);
        e2 = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[2]), p0);
        du1 = t1[0] - t0[0];
        dv1 = t1[1] - t0[1];
        du2 = t2[0] - t0[0];
        dv2 = t2[1] - t0[1];
        det = du1 * dv2 - du2 * dv1;
        if (det == 0.0)
            return 0;
        *pu = v3_mul(v3_sub(v3_mul(e1, dv2), v3_mul(e2, dv1)), 1.0 / det);
        *pv = v3_mul(v3_sub(v3_mul(e2, du1), v3_mul(e1, du2)), 1.0 / det);
        return 1;
    }
    if ((i -= s->ntris) < s->nspheres) {
        /* u = longitude / 2 pi, v = 1/2 + latitude / pi (rtpi_surface_at):
           P_u = 2 pi r cos(lat) east, P_v = pi r north */
        const rtpi_sphere *sp = &s->spheres[i];
        double r = fabs((double)sp->r), cl;
        rtpi_v3 d = v3_sub(p, v3_from_f(sp->c));
        if (!(v3_dot(d, d) > 0.0))
            return 0;
        d = v3_norm(d);
        cl = sqrt(d.x * d.x + d.y * d.y);
        if (!(cl > 0.0))
            return 0; /* a pole: longitude has no derivative */
        *pu = v3(-2.0 * RTPI_PI * r * d.y, 2.0 * RTPI_PI * r * d.x, 0.0);
        *pv = v3(-RTPI_PI * r * d.z * d.x / cl, -RTPI_PI * r * d.z * d.y / cl, RTPI_PI * r * cl);
        return 1;
    }
    if ((i -= s->nspheres) < s->ncones) {
        /* u = the angle around the axis / 2 pi from the frame's e1, v =
           height / h: P_u = 2 pi rho(h) (w x q), P_v = h (w + k q) */
        const rtpi_cone_frame *cf = &s->cframes[i];
        rtpi_v3 q, n, e1, e2, t;
        double h, rho;
        if (!cf->ok || !rtpi_cone_normal(cf, p, &n, &q, &h))
            return 0;
        rho = cf->rb + cf->k * h;
        if (!(rho > 0.0))
            return 0; /* the apex */
        basis(cf->w, &e1, &e2);
        t = v3_add(v3_mul(e1, -v3_dot(q, e2)), v3_mul(e2, v3_dot(q, e1)));
        *pu = v3_mul(t, 2.0 * RTPI_PI * rho);
        *pv = v3_mul(v3_madd(cf->w, q, cf->k), cf->h);
        return 1;
    }
    return 0;
}

void rtpi_prim_bounds_kept(const rtp_scene *s, uint32_t prim, double lo[3], double hi[3])
{
    if (s->pbounds && s->npbounds == rtpi_scene_nprims(s)) {
        const double *b = s->pbounds + 6 * (size_t)prim;
        lo[0] = b[0];
        lo[1] = b[1];
        lo[2] = b[2];
        hi[0] = b[3];
        hi[1] = b[4];
        hi[2] = b[5];
        return;
    }
    rtpi_prim_bounds(s, prim, lo, hi);
}

double rtpi_prim_offset_floor(const rtp_scene *s, uint32_t prim, double floor)
{
    double m = 0.0, f;
    size_t i = prim;
    int j, k;
    if (i < s->ntris) {
        const rtpi_tri *tr = &s->tris[i];
        for (j = 0; j < 3; j++)
            for (k = 0; k < 3; k++)
                m = fmax(m, fabs((double)s->pos[3 * (size_t)tr->v[j] + k]));
    } else if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        for (k = 0; k < 3; k++)
            m = fmax(m, fabs((double)sp->c[k]) + fabs((double)sp->r));
    } else if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone *c = &s->cones[i];
        double r = fmax(fabs((double)c->rb), fabs((double)c->ra));
        for (k = 0; k < 3; k++)
            m = fmax(m, fmax(fabs((double)c->base[k]), fabs((double)c->apex[k])) + r);
    }
    /* (4e-15: a few double ulps, 2.2e-16 each, of the coordinates the hit
       was computed from, with room for the solver's roundings) */
    f = 4e-15 * m;
    return f > floor ? f : floor;
}

static double scene_extent(const rtp_scene *s);

double rtpi_offset_floor(const rtp_scene *s, int *per_prim)
{
    double m = scene_extent(s);
    /* (a scene of 1e-3 and more: 1e-12 as it always was; no geometry or
       none off the origin: the same) */
    double floor = m > 0.0 && 1e-9 * m < 1e-12 ? 1e-9 * m : 1e-12;
    if (per_prim)
        *per_prim = 4e-15 * m > floor;
    return floor;
}

/* The largest coordinate of s's geometry (spheres and cones with their
   radii), as rtpi_prim_offset_floor counts it. */
static double scene_extent(const rtp_scene *s)
{
    double m = 0.0;
    float mp = 0.0f;
    size_t i;
    int k;
    /* (without fmax's calls: a mesh's every coordinate) */
    for (i = 0; i < 3 * s->npos; i++) {
        float a = fabsf(s->pos[i]);
        mp = a > mp ? a : mp;
    }
    m = mp;
    for (i = 0; i < s->nspheres; i++)
        for (k = 0; k < 3; k++)
            m = fmax(m, fabs((double)s->spheres[i].c[k]) + fabs((double)s->spheres[i].r));
    for (i = 0; i < s->ncones; i++) {
        const rtpi_cone *c = &s->cones[i];
        double r = fmax(fabs((double)c->rb), fabs((double)c->ra));
        for (k = 0; k < 3; k++)
            m = fmax(m, fmax(fabs((double)c->base[k]), fabs((double)c->apex[k])) + r);
    }
    return m;
}

int rtpi_prim_hittable(const rtp_scene *s, uint32_t prim)
{
    size_t i = prim;
    if (i < s->ntris) {
        const rtpi_tri *t = &s->tris[i];
        return !rtpi_tri_degenerate(s->pos + 3 * (size_t)t->v[0],
                                    s->pos + 3 * (size_t)t->v[1],
                                    s->pos + 3 * (size_t)t->v[2]);
    }
    if ((i -= s->ntris) < s->nspheres)
        return s->spheres[i].r != 0.0f;
    if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone *cn = &s->cones[i];
        double h = v3_len(v3_sub(v3_from_f(cn->apex), v3_from_f(cn->base)));
        return h > 0.0 && h < 1e300 && fabs((double)cn->rb) + fabs((double)cn->ra) > 0.0;
    }
    return 0;
}

int rtpi_scene_bounds(rtp_scene *s)
{
    size_t i, n = rtpi_scene_nprims(s);
    double *b, m = 0.0;
    unsigned char *h;
    int k;
    if (s->pbounds && s->npbounds == n)
        return 0;
    rtpi_free(&s->alloc, s->pbounds);
    rtpi_free(&s->alloc, s->phit);
    s->pbounds = NULL;
    s->phit = NULL;
    s->npbounds = 0;
    b = (double *)rtpi_malloc_array(&s->alloc, n ? n : 1, 6 * sizeof *b);
    h = (unsigned char *)rtpi_malloc_array(&s->alloc, n ? n : 1, 1);
    if (!b || !h) {
        rtpi_free(&s->alloc, b);
        rtpi_free(&s->alloc, h);
        return -1;
    }
    for (k = 0; k < 3; k++) {
        s->phlo[k] = HUGE_VAL;
        s->phhi[k] = -HUGE_VAL;
    }
    /* (the folds dircube.c made at every move, in the same order and
       with the same comparisons: the same numbers) */
    for (i = 0; i < n; i++) {
        double *lo = b + 6 * i, *hi = lo + 3;
        rtpi_prim_bounds(s, (uint32_t)i, lo, hi);
        h[i] = (unsigned char)rtpi_prim_hittable(s, (uint32_t)i);
        for (k = 0; k < 3; k++) {
            m = fabs(lo[k]) > m ? fabs(lo[k]) : m;
            m = fabs(hi[k]) > m ? fabs(hi[k]) : m;
            if (h[i]) {
                s->phlo[k] = lo[k] < s->phlo[k] ? lo[k] : s->phlo[k];
                s->phhi[k] = hi[k] > s->phhi[k] ? hi[k] : s->phhi[k];
            }
        }
    }
    s->pbabs = m;
    s->phany = 0;
    for (i = 0; i < n && !s->phany; i++)
        s->phany = h[i];
    s->pbounds = b;
    s->phit = h;
    s->npbounds = n;
    return 0;
}

void rtpi_prim_bounds(const rtp_scene *s, uint32_t prim, double lo[3],
                      double hi[3])
{
    size_t i = prim;
    int k;
    if (i < s->ntris) {
        const rtpi_tri *tr = &s->tris[i];
        int j;
        for (k = 0; k < 3; k++)
            lo[k] = hi[k] = s->pos[3 * (size_t)tr->v[0] + k];
        for (j = 1; j < 3; j++) {
            for (k = 0; k < 3; k++) {
                double x = s->pos[3 * (size_t)tr->v[j] + k];
                lo[k] = x < lo[k] ? x : lo[k];
                hi[k] = x > hi[k] ? x : hi[k];
            }
        }
        return;
    }
    if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        double r = fabs((double)sp->r);
        for (k = 0; k < 3; k++) {
            lo[k] = sp->c[k] - r;
            hi[k] = sp->c[k] + r;
        }
        return;
    }
    if ((i -= s->nspheres) < s->ncones) {
        /* Each end is a disc of radius r across the axis w: along axis k
           it reaches r * sqrt(1 - w_k^2). */
        const rtpi_cone *cn = &s->cones[i];
        rtpi_v3 w = v3_norm(v3_sub(v3_from_f(cn->apex), v3_from_f(cn->base)));
        double wk[3];
        wk[0] = w.x;
        wk[1] = w.y;
        wk[2] = w.z;
        for (k = 0; k < 3; k++) {
            double e = 1.0 - wk[k] * wk[k];
            double sk = e > 0.0 ? sqrt(e) : 0.0;
            double rb = fabs((double)cn->rb) * sk, ra = fabs((double)cn->ra) * sk;
            double b0 = cn->base[k] - rb, b1 = cn->base[k] + rb;
            double a0 = cn->apex[k] - ra, a1 = cn->apex[k] + ra;
            if (v3_dot(w, w) == 0.0) { /* zero height: never hit anyway */
                b0 = a0 = cn->base[k];
                b1 = a1 = cn->base[k];
            }
            lo[k] = b0 < a0 ? b0 : a0;
            hi[k] = b1 > a1 ? b1 : a1;
        }
        return;
    }
    for (k = 0; k < 3; k++)
        lo[k] = hi[k] = 0.0;
}
