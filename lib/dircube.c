/* dircube.c — the direction cube around a light: conservative projection
 * of primitives onto its faces, the light buffer (Haines & Greenberg) and
 * the item buffer drawn by a software scanline z-buffer (see dircube.h).
 *
 * Every primitive is reduced, for projection, to a few convex polygons in
 * light-relative coordinates whose projections cover its own: a triangle
 * is itself; a sphere seen from outside is the pyramid over a polygon that
 * circumscribes its cone of directions; a cone or cylinder lies inside the
 * frustum over two polygons circumscribing its end circles (planar
 * trapezoid sides, two caps).  Each polygon is clipped to a face's
 * frustum, projected, and turned into a run of cells per row. */
#include "dircube.h"
#include "kdtree.h" /* rtpi_tri_degenerate */
#include "shadow.h"  /* rtpi_shadow_ray */

#include <float.h>
#include <stdlib.h>

#define DC_PI 3.14159265358979323846
#define DC_N 8               /* sides of the polygons bounding round shapes */
#define DC_MAXV (DC_N + 8)   /* a convex polygon gains <= 1 vertex per clip */
#define DC_MAXP (2 + DC_N)   /* polygons per primitive (a cone: caps + sides) */

typedef struct dc_poly {
    int n;
    double v[DC_MAXV][3];
} dc_poly;

typedef struct dc_bounds {
    int full;   /* may be seen in any direction: every cell */
    int npoly;
    int sides;  /* a cone's: its sides are still to add (dc_bound_sides) */
    dc_poly poly[DC_MAXP];
} dc_bounds;

/* Receives runs of cells [cell, cell + count) of one face row. */
typedef void (*dc_emit_fn)(void *user, size_t cell, int count);

typedef struct dc_ctx {
    const rtp_scene *s;
    rtpi_v3 L;
    int res;
    int *rlo, *rhi; /* per row: first and last cell of the run (scratch) */
    double *ulo, *uhi; /* per row: a polygon's extent (dc_spans_conservative) */
    /* per face f and row j, at [f res + j]: the row's slab before its
       widening, v0 + dv j and v0 + dv (j + 1), -HUGE_VAL and HUGE_VAL
       at the window's edges (dc_ctx_borders) */
    double *blo, *bhi;
    /* where dc_spans_conservative may emit its rows itself (emit_fn non-
       NULL: a bound of one polygon, dc_cover_fast) */
    dc_emit_fn emit_fn;
    void *emit_user;
    int jmin, jmax;
    double u0[6], v0[6], du[6], dv[6]; /* faces' windows (see dircube.h) */
    size_t fbase[6];
    unsigned present; /* bit f: fbase[f] != RTPI_DC_ABSENT */
    dc_bounds b;
    double S; /* dc_scale, made when first needed (ib_draw); < 0 before */
    unsigned faces; /* bit f: dc_cover may have emitted cells of face f */
    unsigned long long casts; /* rays ib_cast_run cast */
} dc_ctx;

/* ------------------------------------------------------ face geometry */

/* The two axes after axis a, in order: a face's local x and y. */
static const int dc_next[3][2] = {{1, 2}, {2, 0}, {0, 1}};

static inline void dc_local(int f, const double q[3], double out[3])
{
    int a = f >> 1;
    out[0] = q[dc_next[a][0]];
    out[1] = q[dc_next[a][1]];
    out[2] = (f & 1) ? -q[a] : q[a];
}

/* Keeps the part of convex polygon `in` (local coordinates) inside the
   face's frustum widened to |x|, |y| <= lim z.  Each crossing point is
   computed from the inside endpoint towards the outside one, so two
   triangles sharing an edge get the same point.  @return the vertex
   count, or -1 if the polygon proved not convex (too many vertices). */
static int dc_clip(const dc_poly *in, dc_poly *out, double lim)
{
    dc_poly tmp[2];
    const dc_poly *src = in;
    int p, i;
    for (p = 0; p < 4; p++) {
        int k = p >> 1, n = src->n, m = 0;
        double sx = (p & 1) ? -1.0 : 1.0;
        dc_poly *dst = p == 3 ? out : &tmp[p & 1];
        for (i = 0; i < n; i++) {
            const double *P = src->v[i], *Q = src->v[i + 1 < n ? i + 1 : 0];
            double fp = lim * P[2] - sx * P[k], fq = lim * Q[2] - sx * Q[k];
            if (m + 2 > DC_MAXV)
                return -1;
            if (fp >= 0.0) {
                memcpy(dst->v[m++], P, sizeof dst->v[0]);
            }
            if ((fp >= 0.0) != (fq >= 0.0)) {
                const double *I = fp >= 0.0 ? P : Q, *O = fp >= 0.0 ? Q : P;
                double fi = fp >= 0.0 ? fp : fq, fo = fp >= 0.0 ? fq : fp;
                double t = fi / (fi - fo);
                dst->v[m][0] = I[0] + (O[0] - I[0]) * t;
                dst->v[m][1] = I[1] + (O[1] - I[1]) * t;
                dst->v[m][2] = I[2] + (O[2] - I[2]) * t;
                m++;
            }
        }
        dst->n = m;
        if (m == 0) {
            out->n = 0;
            return 0;
        }
        src = dst;
    }
    return out->n;
}

/* Projects a clipped polygon to face coordinates.  @return 0 when a
   vertex sits at the light itself (z == 0 after clipping), where the
   projection is undefined. */
static int dc_project(const dc_poly *p, double uv[][2])
{
    int i;
    for (i = 0; i < p->n; i++) {
        double z = p->v[i][2];
        if (!(z > 0.0))
            return 0;
        uv[i][0] = p->v[i][0] / z;
        uv[i][1] = p->v[i][1] / z;
    }
    return 1;
}

static void dc_rows_reset(dc_ctx *c)
{
    c->jmin = c->res;
    c->jmax = -1;
}

static void dc_row_add(dc_ctx *c, int j, int i0, int i1)
{
    if (j < c->jmin || j > c->jmax) {
        /* Rows outside the touched range hold stale values: clear them. */
        int k, lo = j < c->jmin ? j : c->jmax + 1, hi = j > c->jmax ? j : c->jmin - 1;
        if (c->jmax < c->jmin) {
            lo = hi = j;
        }
        for (k = lo; k <= hi; k++) {
            c->rlo[k] = c->res;
            c->rhi[k] = -1;
        }
        if (j < c->jmin)
            c->jmin = j;
        if (j > c->jmax)
            c->jmax = j;
    }
    if (i0 < c->rlo[j])
        c->rlo[j] = i0;
    if (i1 > c->rhi[j])
        c->rhi[j] = i1;
}

/* An edge from (px, py), (ex, ey) to its other end, over rows ja..jb
   (emin, emax: its v range): its extent within each row's slab widened
   by m, from its start where the slab holds it and its crossings of the
   slab's borders strictly inside its range, gathered into ulo, uhi (the
   edge rows' slabs reach to infinity: dc_ctx_borders). */
static RTPI_FORCE_INLINE void dc_edge_span(double px, double py, double ex, double ey,
                                           double emin, double emax, int ja, int jb, double m,
                                           const double *blo, const double *bhi, double *ulo,
                                           double *uhi)
{
    int j;
    for (j = ja; j <= jb; j++) {
        double lo = blo[j] - m, hi = bhi[j] + m;
        double mn = ulo[j], mx = uhi[j];
        if (py >= lo && py <= hi) {
            mn = px < mn ? px : mn;
            mx = px > mx ? px : mx;
        }
        if (emin < lo && lo < emax) {
            double u = px + ex * ((lo - py) / ey);
            mn = u < mn ? u : mn;
            mx = u > mx ? u : mx;
        }
        if (emin < hi && hi < emax) {
            double u = px + ex * ((hi - py) / ey);
            mn = u < mn ? u : mn;
            mx = u > mx ? u : mx;
        }
        ulo[j] = mn;
        uhi[j] = mx;
    }
}

/* Adds the cells that the convex polygon uv[0..n) grown by m (in face
   coordinates, both axes) touches: per row, the polygon's extent within
   the row's slab widened by m, found from the vertices inside the slab
   and the edges' crossings of its borders.  Edge by edge, each over the
   rows its own v range reaches (a row whose slab holds a vertex or has
   a border strictly inside an edge's v range lies there, the slab being
   widened by m on both sides as the range is), the extents gathered in
   c->ulo, c->uhi: a triangle's rows then see about two edges each rather
   than all three, with the same crossings computed the same way, so the
   same cells (row by row over every edge, this was a fifth of tetra's
   light-buffer move). */
static void dc_spans_conservative(dc_ctx *c, int f, const double uv[][2], int n,
                                  double m)
{
    int res = c->res, j, j0, j1, k;
    double vmin = uv[0][1], vmax = uv[0][1];
    double u0 = c->u0[f], v0 = c->v0[f], du = c->du[f], dv = c->dv[f];
    double *ulo = c->ulo, *uhi = c->uhi;
    const double *blo = c->blo + (size_t)f * (size_t)res, *bhi = c->bhi + (size_t)f * (size_t)res;
    for (k = 1; k < n; k++) {
        vmin = uv[k][1] < vmin ? uv[k][1] : vmin;
        vmax = uv[k][1] > vmax ? uv[k][1] : vmax;
    }
    j0 = rtpi_dc_wcoord(vmin - m, v0, dv, res);
    j1 = rtpi_dc_wcoord(vmax + m, v0, dv, res);
    for (j = j0; j <= j1; j++) {
        ulo[j] = DBL_MAX;
        uhi[j] = -DBL_MAX;
    }
    for (k = 0; k < n; k++) {
        const double *P = uv[k], *Q = uv[k + 1 < n ? k + 1 : 0];
        /* (the edge in locals, its differences made once: ulo's and
           uhi's stores may alias uv for all the compiler knows, and it
           loaded and subtracted them again a row; the same numbers) */
        const double px = P[0], py = P[1], ex = Q[0] - px, ey = Q[1] - py;
        double emin = py < Q[1] ? py : Q[1], emax = py < Q[1] ? Q[1] : py;
        int ja = rtpi_dc_wcoord(emin - m, v0, dv, res), jb = rtpi_dc_wcoord(emax + m, v0, dv, res);
        /* (within [j0, j1]: the same mapping of values within vmin - m,
           vmax + m; and a NaN, which every test below fails, maps to
           row 0 as vmin's would) */
        ja = ja < j0 ? j0 : ja;
        jb = jb > j1 ? j1 : jb;
        dc_edge_span(px, py, ex, ey, emin, emax, ja, jb, m, blo, bhi, ulo, uhi);
    }
    if (c->emit_fn) {
        /* One polygon: its rows are the runs, in the order dc_emit_rows
           gives them, without dc_row_add's merging (a third of the cost
           of a small triangle's rows) */
        size_t base = c->fbase[f];
        dc_emit_fn fn = c->emit_fn; /* (not loaded again after each call) */
        void *user = c->emit_user;
        for (j = j0; j <= j1; j++)
            if (ulo[j] <= uhi[j]) {
                int i0 = rtpi_dc_wcoord(ulo[j] - m, u0, du, res);
                fn(user, base + (size_t)j * (size_t)res + (size_t)i0,
                   rtpi_dc_wcoord(uhi[j] + m, u0, du, res) - i0 + 1);
            }
        return;
    }
    for (j = j0; j <= j1; j++)
        if (ulo[j] <= uhi[j])
            dc_row_add(c, j, rtpi_dc_wcoord(ulo[j] - m, u0, du, res),
                       rtpi_dc_wcoord(uhi[j] + m, u0, du, res));
}

static void dc_emit_rows(dc_ctx *c, int f, dc_emit_fn fn, void *user)
{
    int j;
    size_t res = (size_t)c->res;
    for (j = c->jmin; j <= c->jmax; j++)
        if (c->rlo[j] <= c->rhi[j])
            fn(user, c->fbase[f] + (size_t)j * res + (size_t)c->rlo[j],
               c->rhi[j] - c->rlo[j] + 1);
}

static void dc_emit_face(dc_ctx *c, int f, dc_emit_fn fn, void *user)
{
    int j;
    size_t res = (size_t)c->res;
    for (j = 0; j < c->res; j++)
        fn(user, c->fbase[f] + (size_t)j * res, c->res);
}

/* The rows' borders of c's windows (c->blo, c->bhi), made once a window
   rather than twice a row of every polygon (lo, hi in
   dc_spans_conservative; the same values, so the same cells).  The edge
   rows reach to infinity: directions beyond a window's edge are clamped
   to its edge cells (rtpi_dc_wcoord), which must then list whatever lies
   there. */
static void dc_ctx_borders(dc_ctx *c)
{
    int f, j, res = c->res;
    for (f = 0; f < 6; f++) {
        double *lo = c->blo + (size_t)f * (size_t)res, *hi = c->bhi + (size_t)f * (size_t)res;
        double v0 = c->v0[f], dv = c->dv[f];
        for (j = 0; j < res; j++) {
            lo[j] = j == 0 ? -HUGE_VAL : v0 + dv * (double)j;
            hi[j] = j == res - 1 ? HUGE_VAL : v0 + dv * (double)(j + 1);
        }
    }
}

static void dc_ctx_window(dc_ctx *c, const rtpi_dc_window *w)
{
    int f;
    memcpy(c->u0, w->u0, sizeof c->u0);
    memcpy(c->v0, w->v0, sizeof c->v0);
    memcpy(c->du, w->du, sizeof c->du);
    memcpy(c->dv, w->dv, sizeof c->dv);
    memcpy(c->fbase, w->fbase, sizeof c->fbase);
    c->present = 0;
    for (f = 0; f < 6; f++)
        c->present |= (unsigned)(w->fbase[f] != RTPI_DC_ABSENT) << f;
    dc_ctx_borders(c);
}

static void dc_windows_some(const rtp_scene *s, const unsigned char *sel, unsigned char want,
                            rtpi_v3 light, int res, double lim, rtpi_dc_window *w);

/* ---------------------------------------------------- bounding polygons */

/* Orthonormal e1, e2 perpendicular to unit n (Duff et al. 2017). */
static void dc_basis(rtpi_v3 n, rtpi_v3 *e1, rtpi_v3 *e2)
{
    double sg = n.z >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sg + n.z);
    double b = n.x * n.y * a;
    *e1 = v3(1.0 + sg * n.x * n.x * a, sg * b, -sg * n.x);
    *e2 = v3(b, sg + n.y * n.y * a, -n.y);
}

static void dc_put(double dst[3], rtpi_v3 q)
{
    dst[0] = q.x;
    dst[1] = q.y;
    dst[2] = q.z;
}

/* Regular DC_N-gon around centre c (light-relative) across unit axis w,
   circumscribing the circle of radius r.  Eight sides: the bound of a
   sphere or a cone's end is then 8% wider than the circle, where sixteen
   made it 2%, but a cone's two ends are 16 points to project, sort into a
   hull and scan on each face it reaches instead of 32 (rings, 4,200
   cylinders: a light-buffer move at 256 cells 464.5 -> 431.8 M
   instructions; spheres too: balls 309.8 -> 305.2 M, with mount's four
   glass balls +0.2%). */
static void dc_ngon(dc_poly *p, rtpi_v3 c, rtpi_v3 e1, rtpi_v3 e2, double r)
{
    /* cos and sin of 2 pi k / 8, and 1 / cos(pi / 8) */
    static const double cs[DC_N][2] = {
        {1.0, 0.0}, {0.70710678118654752, 0.70710678118654752}, {0.0, 1.0},
        {-0.70710678118654752, 0.70710678118654752}, {-1.0, 0.0},
        {-0.70710678118654752, -0.70710678118654752}, {0.0, -1.0},
        {0.70710678118654752, -0.70710678118654752}};
    int k;
    /* a hair over 1/cos(pi/8) = 1.0823922002...: rounding of the table
       must not shrink the polygon inside the circle */
    double R = r * (1.0823922002923940 * (1.0 + 1e-12));
    p->n = DC_N;
    for (k = 0; k < DC_N; k++)
        dc_put(p->v[k], v3_madd(v3_madd(c, e1, R * cs[k][0]), e2, R * cs[k][1]));
}

/* Has rtpi_scene_bounds kept what a move asks of every primitive (the
   same numbers as made here)? */
static int dc_kept(const rtp_scene *s)
{
    return s->pbounds && s->phit && s->npbounds == rtpi_scene_nprims(s);
}

/* rtpi_prim_hittable, from the scene's kept flags where rtpi_scene_bounds
   made them. */
static int dc_hittable(const rtp_scene *s, uint32_t prim)
{
    return dc_kept(s) ? s->phit[prim] : rtpi_prim_hittable(s, prim);
}

/* Polygons (light-relative) whose projections from the light cover the
   primitive's projection widened by the angle `ang`; b->full when that
   cannot be bounded (the light inside or too close to it). */
static void dc_bound_prim(dc_ctx *c, uint32_t prim, double ang)
{
    const rtp_scene *s = c->s;
    dc_bounds *b = &c->b;
    size_t i = prim;
    b->full = 0;
    b->npoly = 0;
    b->sides = 0;
    if (i < s->ntris) {
        const rtpi_tri *t = &s->tris[i];
        int k;
        b->npoly = 1;
        b->poly[0].n = 3;
        for (k = 0; k < 3; k++)
            dc_put(b->poly[0].v[k], v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[k]), c->L));
        return;
    }
    if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 cl = v3_sub(v3_from_f(sp->c), c->L), w, e1, e2;
        double D = v3_len(cl), r = fabs((double)sp->r), alpha;
        /* The sphere's directions form a cone of half-angle asin(r/D);
           past ~89 degrees the bounding pyramid degenerates: take all. */
        if (!(D > r))
            goto full;
        alpha = asin(r / D) + ang;
        if (!(alpha < 1.55))
            goto full;
        w = v3_mul(cl, 1.0 / D);
        dc_basis(w, &e1, &e2);
        b->npoly = 1;
        dc_ngon(&b->poly[0], w, e1, e2, tan(alpha));
        return;
    }
    if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone *cn = &s->cones[i];
        rtpi_v3 base = v3_sub(v3_from_f(cn->base), c->L);
        rtpi_v3 apex = v3_sub(v3_from_f(cn->apex), c->L);
        rtpi_v3 w = v3_norm(v3_sub(apex, base)), e1, e2;
        dc_basis(w, &e1, &e2);
        dc_ngon(&b->poly[0], base, e1, e2, fabs((double)cn->rb));
        dc_ngon(&b->poly[1], apex, e1, e2, fabs((double)cn->ra));
        b->npoly = 2;
        b->sides = 1; /* (only the faces dc_cover_fast cannot take need them) */
        return;
    }
full:
    b->full = 1;
}

/* A cone's sides, after its two end polygons: corresponding edges of the
   two homothetic polygons are parallel, so each side of their hull is a
   planar trapezoid. */
static void dc_bound_sides(dc_bounds *b)
{
    int k, n = b->poly[0].n;
    for (k = 0; k < n; k++) {
        dc_poly *q = &b->poly[2 + k];
        int k1 = (k + 1) % n;
        q->n = 4;
        memcpy(q->v[0], b->poly[0].v[k], sizeof q->v[0]);
        memcpy(q->v[1], b->poly[0].v[k1], sizeof q->v[0]);
        memcpy(q->v[2], b->poly[1].v[k1], sizeof q->v[0]);
        memcpy(q->v[3], b->poly[1].v[k], sizeof q->v[0]);
    }
    b->npoly = 2 + n;
    b->sides = 0;
}

/* > 0 when a, b, c turn counter-clockwise. */
static double dc_turn(const double a[2], const double b[2], const double c[2])
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/* The 2D convex hull of pts[0..n) (n <= 2 DC_N), counter-clockwise,
   into hull (Andrew's monotone chain).  @return its vertex count. */
static int dc_hull2(double pts[][2], int n, double hull[][2])
{
    int i, k = 0, t;
    /* insertion sort by (u, v): n is at most 2 DC_N */
    for (i = 1; i < n; i++) {
        double a = pts[i][0], b = pts[i][1];
        int j = i - 1;
        while (j >= 0 && (pts[j][0] > a || (pts[j][0] == a && pts[j][1] > b))) {
            pts[j + 1][0] = pts[j][0];
            pts[j + 1][1] = pts[j][1];
            j--;
        }
        pts[j + 1][0] = a;
        pts[j + 1][1] = b;
    }
    if (n < 3) {
        for (i = 0; i < n; i++) {
            hull[i][0] = pts[i][0];
            hull[i][1] = pts[i][1];
        }
        return n;
    }
    for (i = 0; i < n; i++) { /* lower hull */
        while (k >= 2 && dc_turn(hull[k - 2], hull[k - 1], pts[i]) <= 0.0)
            k--;
        hull[k][0] = pts[i][0];
        hull[k][1] = pts[i][1];
        k++;
    }
    for (i = n - 2, t = k + 1; i >= 0; i--) { /* upper hull */
        while (k >= t && dc_turn(hull[k - 2], hull[k - 1], pts[i]) <= 0.0)
            k--;
        hull[k][0] = pts[i][0];
        hull[k][1] = pts[i][1];
        k++;
    }
    return k - 1; /* the last point repeats the first */
}

/* The fast way to a face for a bound whose points all lie well in front
   of it (|x|, |y| <= DC_FAST_UV z: projected coordinates of size <= 10,
   whose rounding stays ~1e-15, far below the widening m >= 4e-9): the
   projection of the bound's convex hull is the 2D hull of its points'
   projections, drawn without clipping (parts beyond the face land on its
   edge cells, which is still a cover).  pts: the points (light-relative);
   @return 0 if they do not qualify, 1 when done (culled, or drawn into
   c's rows), 2 when the runs went to fn already. */
#define DC_FAST_UV 10.0
#define DC_BOX_EDGE 2   /* a bound this many cells wide or high, */
#define DC_BOX_CELLS 16 /* or of this many cells: its box (dc_cover_fast) */
static int dc_cover_fast(dc_ctx *c, int f, const double (*pts)[3], int n, double m,
                         double lim, dc_emit_fn fn, void *user)
{
    double uv[2 * DC_N][2], hull[2 * DC_N + 1][2];
    double umin = HUGE_VAL, umax = -HUGE_VAL, vmin = HUGE_VAL, vmax = -HUGE_VAL;
    int k, nh;
    for (k = 0; k < n; k++) {
        double q[3];
        dc_local(f, pts[k], q);
        if (!(q[2] > 0.0 && fabs(q[0]) <= DC_FAST_UV * q[2] && fabs(q[1]) <= DC_FAST_UV * q[2]))
            return 0;
        uv[k][0] = q[0] / q[2];
        uv[k][1] = q[1] / q[2];
        /* (finite here: no NaN for fmin's rule, and no call) */
        umin = uv[k][0] < umin ? uv[k][0] : umin;
        umax = uv[k][0] > umax ? uv[k][0] : umax;
        vmin = uv[k][1] < vmin ? uv[k][1] : vmin;
        vmax = uv[k][1] > vmax ? uv[k][1] : vmax;
    }
    if (umin > lim || umax < -lim || vmin > lim || vmax < -lim)
        return 1; /* wholly off this face */
    if (n > 3) {
        /* A round shape's bound a few cells across (most of those of a
           big scene): the cells of its box, widened as
           dc_spans_conservative widens, hold every cell of its hull's
           spans (each row's extent lies within the box's), at a few more
           cells than the hull's and none of the hull's cost (a cone's 32
           points, as its bound then had, sorted, then clipped row by row:
           7,000 instructions a cylinder).  Cells beyond the window clamp
           to its edges alike.  Not for a triangle: its spans cost little,
           and the box's extra cells lengthen the lists of a mesh's every
           cell (mount: 2-5% more to a move); its four divisions not
           made for one (gears: 1% of a move). */
        int i0 = rtpi_dc_wcoord(umin - m, c->u0[f], c->du[f], c->res),
            i1 = rtpi_dc_wcoord(umax + m, c->u0[f], c->du[f], c->res),
            j0 = rtpi_dc_wcoord(vmin - m, c->v0[f], c->dv[f], c->res),
            j1 = rtpi_dc_wcoord(vmax + m, c->v0[f], c->dv[f], c->res), j;
        int ni = i1 - i0 + 1, nj = j1 - j0 + 1;
        if (ni <= DC_BOX_EDGE || nj <= DC_BOX_EDGE || ni * nj <= DC_BOX_CELLS) {
            for (j = j0; j <= j1; j++)
                dc_row_add(c, j, i0, i1);
            return 1;
        }
    }
    if (c->b.npoly == 1) { /* one convex polygon: a triangle or a sphere's bound */
        c->emit_fn = fn;
        c->emit_user = user;
        dc_spans_conservative(c, f, (const double(*)[2])uv, n, m);
        c->emit_fn = NULL;
        return 2;
    }
    nh = dc_hull2(uv, n, hull);
    dc_spans_conservative(c, f, (const double(*)[2])hull, nh, m);
    return 1;
}

/* dc_faces_reached's test of one face: its depth axis reaches zmax, its
   other two axes' least |x| are m1 and m2. */
static inline int dc_face_live(double zmax, double m1, double m2, double lim)
{
    double zl = lim * zmax;
    return !(zmax < 0.0 || m1 > zl || m2 > zl);
}

/* The faces (bit f) whose frustum widened to |x|, |y| <= lim z the
   convex hull of pts[0..n) (light-relative) may reach; 0 bits only where
   it cannot: by the points' bounding box, every point of the hull has
   z <= zmax and |x| >= the least |x| of the box's x range, so where that
   least |x| (or |y|) exceeds lim zmax, or zmax < 0, the hull misses the
   frustum.  Culling a face here leaves out only cells the clipping would
   have found empty, at the cost of 48 comparisons instead of projecting
   the points onto all six faces.  (In scalars, each face's test written
   out: as loops over arrays indexed by dc_next it took 225 instructions
   a triangle, gears 2% of a move.) */
static RTPI_FORCE_INLINE int dc_faces_reached(const double (*pts)[3], int n, double lim)
{
    double lx, ly, lz, hx, hy, hz, mx, my, mz;
    int k;
    if (n <= 0)
        return 0x3f;
    lx = hx = pts[0][0];
    ly = hy = pts[0][1];
    lz = hz = pts[0][2];
    for (k = 1; k < n; k++) {
        double x = pts[k][0], y = pts[k][1], z = pts[k][2];
        lx = x < lx ? x : lx;
        hx = x > hx ? x : hx;
        ly = y < ly ? y : ly;
        hy = y > hy ? y : hy;
        lz = z < lz ? z : lz;
        hz = z > hz ? z : hz;
    }
    /* the least |x| over [lo, hi]; a NaN anywhere keeps every face
       (every comparison below is then false) */
    mx = lx > 0.0 ? lx : hx < 0.0 ? -hx : 0.0;
    my = ly > 0.0 ? ly : hy < 0.0 ? -hy : 0.0;
    mz = lz > 0.0 ? lz : hz < 0.0 ? -hz : 0.0;
    /* face f looks along axis f >> 1 (towards - for odd f); its local
       x and y are the next two axes (dc_next) */
    return dc_face_live(hx, my, mz, lim) | dc_face_live(-lx, my, mz, lim) << 1 |
           dc_face_live(hy, mz, mx, lim) << 2 | dc_face_live(-ly, mz, mx, lim) << 3 |
           dc_face_live(hz, mx, my, lim) << 4 | dc_face_live(-lz, mx, my, lim) << 5;
}

/* dc_cover's way to face f where dc_cover_fast cannot take the bound
   c->b (made): each polygon clipped to the face's frustum widened to
   lim, projected and drawn grown by m, or the whole face. */
static void dc_cover_face(dc_ctx *c, int f, double m, double lim, dc_emit_fn fn, void *user)
{
    double uv[DC_MAXV][2];
    int whole = c->b.full, k;
    dc_rows_reset(c);
    if (!whole && c->b.sides)
        dc_bound_sides(&c->b);
    for (k = 0; k < c->b.npoly && !whole; k++) {
        dc_poly loc, clipped;
        int v, n;
        loc.n = c->b.poly[k].n;
        for (v = 0; v < loc.n; v++)
            dc_local(f, c->b.poly[k].v[v], loc.v[v]);
        n = dc_clip(&loc, &clipped, lim);
        if (n < 0 || (n > 0 && !dc_project(&clipped, uv)))
            whole = 1; /* not convex after rounding, or through the light */
        else if (n > 0)
            dc_spans_conservative(c, f, (const double(*)[2])uv, n, m);
    }
    if (whole)
        dc_emit_face(c, f, fn, user);
    else
        dc_emit_rows(c, f, fn, user);
    if (whole || c->jmin <= c->jmax)
        c->faces |= 1u << f;
}

/* Emits every cell the primitive's projection widened by `ang` radians
   may touch.  Face coordinates change by at most ~3x an angle change on
   a face (du/dtheta <= 1 + u^2 + v^2), so the polygons are grown by 4 ang
   in face coordinates and clipped to a frustum as much wider: a ray just
   across a cube edge from the primitive still finds it listed. */
static void dc_cover(dc_ctx *c, uint32_t prim, double ang, dc_emit_fn fn,
                     void *user)
{
    double m = 4.0 * ang, lim = 1.0 + m;
    int f, k;
    double pts[2 * DC_N][3];
    int npts = 0, live = 0x3f, r;
    dc_bound_prim(c, prim, ang);
    if (!c->b.full) {
        /* the bound's points: a cone's two end polygons span its hull */
        int np = c->b.npoly == 1 ? 1 : 2, v;
        for (k = 0; k < np; k++)
            for (v = 0; v < c->b.poly[k].n; v++)
                memcpy(pts[npts++], c->b.poly[k].v[v], sizeof pts[0]);
        live = dc_faces_reached((const double(*)[3])pts, npts, lim);
    }
    for (f = 0; f < 6; f++) {
        int whole = c->b.full;
        if (c->fbase[f] == RTPI_DC_ABSENT || !((live >> f) & 1))
            continue;
        dc_rows_reset(c);
        if (!whole && (r = dc_cover_fast(c, f, (const double(*)[3])pts, npts, m, lim, fn, user))) {
            if (r == 1)
                dc_emit_rows(c, f, fn, user);
            if (r == 2 || c->jmin <= c->jmax)
                c->faces |= 1u << f;
            continue;
        }
        dc_cover_face(c, f, m, lim, fn, user);
    }
}

/* The light buffer's cells for sphere prim (of s->spheres) by the box of
   its exact projection, where that is quick and sure: 1 when done, 0
   for dc_cover to do it (the item buffer's cells keep dc_cover's).
   dc_cover bounds the sphere's cone of directions (half-angle alpha =
   asin(r / D) + ang about w, the unit direction to its centre, as
   dc_bound_prim) by an octagon, projects its 8 points and lists the
   cells of their box: 1,400 instructions a sphere (balls_s4: 10.6 M of
   its lightbuf:256 move), and the box of the octagon's corners.  Here,
   in face f's local frame (w = (wx, wy, wz), wz > 0) the cone's u range
   on the plane z = 1 is bounded by the planes x = u z tangent to it:
   (wx - u wz)^2 = sin^2(alpha) (1 + u^2), so with sn = sin alpha,
   u = (wx wz -+ sn sqrt(wx^2 + wz^2 - sn^2)) / (wz^2 - sn^2), and v
   alike with wy.  Taken only where wz^2 - sn^2 >= 1/4 (the cone well in
   front of the face: no division by a small number), and where the box
   widened by m lies within |u|, |v| < 0.9 of the face: every direction
   of the cone then has its face's axis the largest by a tenth, so it is
   face f's (rtpi_dc_face), and no other face lists it (a ray that can
   hit the sphere runs within ang of a direction to it, the lists'
   argument above, so inside the cone).  Rounding: sn is grown by 1e-9 of
   itself for asin's and sin's; every input of the formula is at most 1,
   the denominator at least 1/4, so u is off by a few 1e-15, w (cl / D)
   by as little; the box is widened by 1e-10 besides m (= 4 ang, as
   dc_cover widens).  Cells clamp to the window as in dc_cover_fast.
   Where the box is not small (DC_BOX_EDGE, DC_BOX_CELLS), dc_cover's
   spans are kept (fewer cells than a big box). */
static int dc_cover_sphere(dc_ctx *c, uint32_t prim, double ang, dc_emit_fn fn, void *user)
{
    const rtpi_sphere *sp = &c->s->spheres[prim - c->s->ntris];
    rtpi_v3 cl = v3_sub(v3_from_f(sp->c), c->L);
    double D = v3_len(cl), r = fabs((double)sp->r), alpha, sn, den, wq[3], q[3], box[4];
    double m = 4.0 * ang + 1e-10;
    int f, a, k, i0, i1, j0, j1, j, res = c->res;
    if (!(D > r) || !(D < HUGE_VAL))
        return 0;
    alpha = asin(r / D) + ang;
    if (!(alpha < 0.5))
        return 0;
    sn = sin(alpha) * (1.0 + 1e-9);
    wq[0] = cl.x / D;
    wq[1] = cl.y / D;
    wq[2] = cl.z / D;
    a = fabs(wq[0]) >= fabs(wq[1]) ? (fabs(wq[0]) >= fabs(wq[2]) ? 0 : 2)
                                   : (fabs(wq[1]) >= fabs(wq[2]) ? 1 : 2);
    f = 2 * a + (wq[a] < 0.0);
    dc_local(f, wq, q);
    den = q[2] * q[2] - sn * sn;
    if (!(den >= 0.25))
        return 0;
    for (k = 0; k < 2; k++) {
        double root = sn * sqrt(q[k] * q[k] + den), mid = q[k] * q[2];
        box[2 * k] = (mid - root) / den - m;
        box[2 * k + 1] = (mid + root) / den + m;
        if (!(box[2 * k] > -0.9 && box[2 * k + 1] < 0.9))
            return 0;
    }
    if (c->fbase[f] == RTPI_DC_ABSENT)
        return 1; /* no cell holds its directions */
    i0 = rtpi_dc_wcoord(box[0], c->u0[f], c->du[f], res);
    i1 = rtpi_dc_wcoord(box[1], c->u0[f], c->du[f], res);
    j0 = rtpi_dc_wcoord(box[2], c->v0[f], c->dv[f], res);
    j1 = rtpi_dc_wcoord(box[3], c->v0[f], c->dv[f], res);
    if (!(i1 - i0 + 1 <= DC_BOX_EDGE || j1 - j0 + 1 <= DC_BOX_EDGE ||
          (i1 - i0 + 1) * (j1 - j0 + 1) <= DC_BOX_CELLS))
        return 0;
    for (j = j0; j <= j1; j++)
        fn(user, c->fbase[f] + (size_t)j * (size_t)res + (size_t)i0, i1 - i0 + 1);
    c->faces |= 1u << f;
    return 1;
}

/* ------------------------------------------------ a triangle's own way */

/* dc_spans_tri's edge from P to Q (face coordinates; jlP, jhP and jlQ,
   jhQ their rows' wcoord of v - m and v + m): dc_spans_conservative's
   steps for one edge over its rows, into ulo, uhi. */
static RTPI_FORCE_INLINE void dc_edge_rows(const double P[2], const double Q[2], int jlP, int jhP,
                                           int jlQ, int jhQ, double m, const double *blo,
                                           const double *bhi, double *ulo, double *uhi)
{
    const double px = P[0], py = P[1], qy = Q[1];
    const double ex = Q[0] - px, ey = qy - py;
    const int low = py < qy;
    const double emin = low ? py : qy, emax = low ? qy : py;
    dc_edge_span(px, py, ex, ey, emin, emax, low ? jlP : jlQ, low ? jhQ : jhP, m, blo, bhi, ulo,
                 uhi);
}

/* dc_spans_conservative of a triangle drawn whole on face f (dc_cover_tri's
   fast case), its runs handed to fn: the same rows, crossings and
   extents, with each vertex's rows (wcoord of v - m and v + m) made once
   rather than once an edge it ends and again for the triangle's span:
   rtpi_dc_wcoord is monotone, so the triangle's first and last rows are
   the least and greatest of its vertices', and an edge's rows those of
   its lower and upper end, which lie within them (the clamping a no-op);
   vmin and vmax not found again, there being none to find.  n is 3, the
   edges' loop unrolled. */
static RTPI_FORCE_INLINE void dc_spans_tri(dc_ctx *c, int f, const double uv[3][2], double m,
                                           dc_emit_fn fn, void *user)
{
    int res = c->res, j, j0, j1, jl[3], jh[3];
    double u0 = c->u0[f], v0 = c->v0[f], du = c->du[f], dv = c->dv[f];
    double *ulo = c->ulo, *uhi = c->uhi;
    const double *blo = c->blo + (size_t)f * (size_t)res, *bhi = c->bhi + (size_t)f * (size_t)res;
    size_t base;
    jl[0] = rtpi_dc_wcoord(uv[0][1] - m, v0, dv, res);
    jh[0] = rtpi_dc_wcoord(uv[0][1] + m, v0, dv, res);
    jl[1] = rtpi_dc_wcoord(uv[1][1] - m, v0, dv, res);
    jh[1] = rtpi_dc_wcoord(uv[1][1] + m, v0, dv, res);
    jl[2] = rtpi_dc_wcoord(uv[2][1] - m, v0, dv, res);
    jh[2] = rtpi_dc_wcoord(uv[2][1] + m, v0, dv, res);
    j0 = jl[0] < jl[1] ? jl[0] : jl[1];
    j0 = jl[2] < j0 ? jl[2] : j0;
    j1 = jh[0] > jh[1] ? jh[0] : jh[1];
    j1 = jh[2] > j1 ? jh[2] : j1;
    for (j = j0; j <= j1; j++) {
        ulo[j] = DBL_MAX;
        uhi[j] = -DBL_MAX;
    }
    /* (the three edges written out: each its ends' places and rows
       known, not looked up from k) */
    dc_edge_rows(uv[0], uv[1], jl[0], jh[0], jl[1], jh[1], m, blo, bhi, ulo, uhi);
    dc_edge_rows(uv[1], uv[2], jl[1], jh[1], jl[2], jh[2], m, blo, bhi, ulo, uhi);
    dc_edge_rows(uv[2], uv[0], jl[2], jh[2], jl[0], jh[0], m, blo, bhi, ulo, uhi);
    base = c->fbase[f];
    for (j = j0; j <= j1; j++)
        if (ulo[j] <= uhi[j]) {
            int i0 = rtpi_dc_wcoord(ulo[j] - m, u0, du, res);
            fn(user, base + (size_t)j * (size_t)res + (size_t)i0,
               rtpi_dc_wcoord(uhi[j] + m, u0, du, res) - i0 + 1);
        }
}

/* dc_cover_fast's test and projection of one point p (light-relative)
   on face f: 0 if it is not well in front of the face. */
static RTPI_FORCE_INLINE int dc_fast_uv(int f, const double p[3], double out[2])
{
    double q[3];
    dc_local(f, p, q);
    if (!(q[2] > 0.0 && fabs(q[0]) <= DC_FAST_UV * q[2] && fabs(q[1]) <= DC_FAST_UV * q[2]))
        return 0;
    out[0] = q[0] / q[2];
    out[1] = q[1] / q[2];
    return 1;
}

/* The lowest bit set of a face mask (0 for none). */
static const unsigned char dc_lowest[64] = {
    0, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0,
    4, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0,
    5, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0,
    4, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0};

/* Where dc_spans_tri's crossings may round to: each is
   px + ex ((lo - py) / ey) with lo strictly between py and qy, so by
   rounding's monotony the quotient lies in [0, 1], the product between 0
   and ex, and the sum between px and fl(px + ex), ex = fl(qx - px): beyond
   px and qx by at most the rounding of that difference and that sum,
   (20 + 10) 2^-53 = 3.4e-15 for coordinates within DC_FAST_UV = 10 (the
   fast case's).  1e-14 has room to spare and is far below m (>= 4e-12). */
#define DC_BOX_ROUND 1e-14

/* A triangle drawn whole on face f (dc_cover_tri's fast case) listed by
   its box: its projected vertices' u range [umin, umax] widened by m and
   DC_BOX_ROUND, in each of dc_spans_tri's rows (the same wcoord of
   vmin - m .. vmax + m).  Every run dc_spans_tri gives lies within it
   (a row's extent is its vertices' u and its edges' crossings, within
   [umin, umax] but for rounding, DC_BOX_ROUND), so a cover still: about
   twice the cells of the spans' (a triangle fills at most half its box),
   none of the edges' crossings (tetra: 2.8 M of a 28 M move).  Taken
   where a move's queries are few against the triangles
   (rtpi_lightbuf_build_q). */
static RTPI_FORCE_INLINE void dc_box_tri(dc_ctx *c, int f, double umin, double umax, double vmin,
                                         double vmax, double m, dc_emit_fn fn, void *user)
{
    int res = c->res, j;
    int i0 = rtpi_dc_wcoord(umin - m - DC_BOX_ROUND, c->u0[f], c->du[f], res),
        i1 = rtpi_dc_wcoord(umax + m + DC_BOX_ROUND, c->u0[f], c->du[f], res),
        j0 = rtpi_dc_wcoord(vmin - m, c->v0[f], c->dv[f], res),
        j1 = rtpi_dc_wcoord(vmax + m, c->v0[f], c->dv[f], res);
    size_t base = c->fbase[f];
    for (j = j0; j <= j1; j++)
        fn(user, base + (size_t)j * (size_t)res + (size_t)i0, i1 - i0 + 1);
}

/* dc_cover of triangle prim (prim < ntris): the same cells in the same
   order, its points taken straight from the scene rather than through
   its bound's polygon and a copy of it, and the fast case (dc_cover_fast:
   a triangle is one polygon) drawn by dc_spans_tri; a face the fast way
   cannot take goes dc_cover's way (dc_cover_face). */
static RTPI_FORCE_INLINE void dc_cover_tri(dc_ctx *c, uint32_t prim, const rtpi_v3 p[3],
                                           double ang, dc_emit_fn fn, void *user)
{
    double m = 4.0 * ang, lim = 1.0 + m;
    double pts[3][3];
    int f, bound = 0;
    unsigned todo;
    dc_put(pts[0], v3_sub(p[0], c->L));
    dc_put(pts[1], v3_sub(p[1], c->L));
    dc_put(pts[2], v3_sub(p[2], c->L));
    /* the faces present and reached, lowest first: a triangle's one or
       two rather than a test of each of six (2 M of gears' move) */
    todo = (unsigned)dc_faces_reached((const double(*)[3])pts, 3, lim) & c->present;
    while (todo) {
        double uv[3][2], umin = HUGE_VAL, umax = -HUGE_VAL, vmin = HUGE_VAL, vmax = -HUGE_VAL;
        f = dc_lowest[todo];
        todo &= todo - 1;
        if (!(dc_fast_uv(f, pts[0], uv[0]) && dc_fast_uv(f, pts[1], uv[1]) &&
              dc_fast_uv(f, pts[2], uv[2]))) { /* not the fast way: dc_cover's, with its bound */
            if (!bound) {
                dc_bound_prim(c, prim, ang);
                bound = 1;
            }
            dc_cover_face(c, f, m, lim, fn, user);
            continue;
        }
        /* (the points in turn, as dc_cover_fast takes them) */
        umin = uv[0][0] < umin ? uv[0][0] : umin;
        umax = uv[0][0] > umax ? uv[0][0] : umax;
        vmin = uv[0][1] < vmin ? uv[0][1] : vmin;
        vmax = uv[0][1] > vmax ? uv[0][1] : vmax;
        umin = uv[1][0] < umin ? uv[1][0] : umin;
        umax = uv[1][0] > umax ? uv[1][0] : umax;
        vmin = uv[1][1] < vmin ? uv[1][1] : vmin;
        vmax = uv[1][1] > vmax ? uv[1][1] : vmax;
        umin = uv[2][0] < umin ? uv[2][0] : umin;
        umax = uv[2][0] > umax ? uv[2][0] : umax;
        vmin = uv[2][1] < vmin ? uv[2][1] : vmin;
        vmax = uv[2][1] > vmax ? uv[2][1] : vmax;
        if (umin > lim || umax < -lim || vmin > lim || vmax < -lim)
            continue; /* wholly off this face */
        dc_spans_tri(c, f, (const double(*)[2])uv, m, fn, user);
        c->faces |= 1u << f;
    }
}

/* dc_cover_tri with the fast case's triangle listed by its box
   (dc_box_tri) rather than its spans; the faces the fast way cannot take
   as there.  A copy rather than a flag to dc_cover_tri: with one body
   for both, lb_part's registers came out otherwise and gears' move took
   0.22 M more, mount's and teapot's 0.05, with no box listed. */
static RTPI_FORCE_INLINE void dc_cover_tri_box(dc_ctx *c, uint32_t prim, const rtpi_v3 p[3],
                                               double ang, dc_emit_fn fn, void *user)
{
    double m = 4.0 * ang, lim = 1.0 + m;
    double pts[3][3];
    int f, bound = 0;
    unsigned todo;
    dc_put(pts[0], v3_sub(p[0], c->L));
    dc_put(pts[1], v3_sub(p[1], c->L));
    dc_put(pts[2], v3_sub(p[2], c->L));
    /* the faces present and reached, lowest first: a triangle's one or
       two rather than a test of each of six (2 M of gears' move) */
    todo = (unsigned)dc_faces_reached((const double(*)[3])pts, 3, lim) & c->present;
    while (todo) {
        double uv[3][2], umin = HUGE_VAL, umax = -HUGE_VAL, vmin = HUGE_VAL, vmax = -HUGE_VAL;
        f = dc_lowest[todo];
        todo &= todo - 1;
        if (!(dc_fast_uv(f, pts[0], uv[0]) && dc_fast_uv(f, pts[1], uv[1]) &&
              dc_fast_uv(f, pts[2], uv[2]))) { /* not the fast way: dc_cover's, with its bound */
            if (!bound) {
                dc_bound_prim(c, prim, ang);
                bound = 1;
            }
            dc_cover_face(c, f, m, lim, fn, user);
            continue;
        }
        /* (the points in turn, as dc_cover_fast takes them) */
        umin = uv[0][0] < umin ? uv[0][0] : umin;
        umax = uv[0][0] > umax ? uv[0][0] : umax;
        vmin = uv[0][1] < vmin ? uv[0][1] : vmin;
        vmax = uv[0][1] > vmax ? uv[0][1] : vmax;
        umin = uv[1][0] < umin ? uv[1][0] : umin;
        umax = uv[1][0] > umax ? uv[1][0] : umax;
        vmin = uv[1][1] < vmin ? uv[1][1] : vmin;
        vmax = uv[1][1] > vmax ? uv[1][1] : vmax;
        umin = uv[2][0] < umin ? uv[2][0] : umin;
        umax = uv[2][0] > umax ? uv[2][0] : umax;
        vmin = uv[2][1] < vmin ? uv[2][1] : vmin;
        vmax = uv[2][1] > vmax ? uv[2][1] : vmax;
        if (umin > lim || umax < -lim || vmin > lim || vmax < -lim)
            continue; /* wholly off this face */
        dc_box_tri(c, f, umin, umax, vmin, vmax, m, fn, user);
        c->faces |= 1u << f;
    }
}

/* Lower bound of the distance from the light to the primitive. */
static RTPI_FORCE_INLINE double dc_near(const rtp_scene *s, uint32_t prim, rtpi_v3 L)
{
    double lo[3], hi[3], d2 = 0.0, best;
    size_t i = prim;
    int k;
    if (s->pbounds && s->npbounds == rtpi_scene_nprims(s)) {
        /* (rtpi_prim_bounds_kept's kept bounds, read here: its call was
           a sixth of a triangle's near) */
        const double *b = s->pbounds + 6 * i;
        for (k = 0; k < 3; k++) {
            lo[k] = b[k];
            hi[k] = b[3 + k];
        }
    } else
        rtpi_prim_bounds_kept(s, prim, lo, hi);
    for (k = 0; k < 3; k++) {
        double x = v3_get(L, k);
        double e = x < lo[k] ? lo[k] - x : x > hi[k] ? x - hi[k] : 0.0;
        d2 += e * e;
    }
    best = sqrt(d2); /* distance to the bounding box */
    if (i < s->ntris) {
        /* A big triangle's box may hold the light: its plane is a bound too. */
        const rtpi_tri *t = &s->tris[i];
        rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)t->v[0]);
        rtpi_v3 n = v3_cross(v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[1]), p0),
                             v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[2]), p0));
        double nl = v3_len(n);
        if (nl > 0.0) {
            double dp = fabs(v3_dot(n, v3_sub(L, p0))) / nl;
            best = dp > best ? dp : best;
        }
    } else if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        double ds = v3_len(v3_sub(v3_from_f(sp->c), L)) - fabs((double)sp->r);
        best = ds > best ? ds : best;
    }
    return best;
}

/* Largest coordinate magnitude of the light and the scene's geometry:
   the scale of the intersection routines' rounding. */
static double dc_scale(const rtp_scene *s, rtpi_v3 L)
{
    double S = fmax(fabs(L.x), fmax(fabs(L.y), fabs(L.z)));
    size_t i, n = rtpi_scene_nprims(s);
    if (dc_kept(s)) /* (the fold below over the same bounds: their maximum) */
        return s->pbabs > S ? s->pbabs : S;
    for (i = 0; i < n; i++) {
        double lo[3], hi[3];
        int k;
        rtpi_prim_bounds_kept(s, (uint32_t)i, lo, hi);
        for (k = 0; k < 3; k++) {
            S = fabs(lo[k]) > S ? fabs(lo[k]) : S;
            S = fabs(hi[k]) > S ? fabs(hi[k]) : S;
        }
    }
    return S;
}

static void dc_ctx_free(dc_ctx *c, const rtp_allocator *a);

static rtp_status dc_ctx_init(dc_ctx *c, const rtp_scene *s, rtpi_v3 L, int res,
                              const rtp_allocator *a)
{
    int f;
    c->s = s;
    c->L = L;
    c->res = res;
    c->S = -1.0;
    c->casts = 0;
    c->faces = 0;
    c->emit_fn = NULL;
    c->emit_user = NULL;
    for (f = 0; f < 6; f++) { /* whole faces */
        c->u0[f] = c->v0[f] = -1.0;
        c->du[f] = c->dv[f] = 2.0 / (double)res;
        c->fbase[f] = (size_t)f * (size_t)res * (size_t)res;
    }
    c->present = 0x3f;
    c->rlo = (int *)rtpi_malloc_array(a, (size_t)res, sizeof *c->rlo);
    c->rhi = (int *)rtpi_malloc_array(a, (size_t)res, sizeof *c->rhi);
    c->ulo = (double *)rtpi_malloc_array(a, (size_t)res, sizeof *c->ulo);
    c->uhi = (double *)rtpi_malloc_array(a, (size_t)res, sizeof *c->uhi);
    c->blo = (double *)rtpi_malloc_array(a, 6 * (size_t)res, sizeof *c->blo);
    c->bhi = (double *)rtpi_malloc_array(a, 6 * (size_t)res, sizeof *c->bhi);
    if (!c->rlo || !c->rhi || !c->ulo || !c->uhi || !c->blo || !c->bhi) {
        dc_ctx_free(c, a);
        return RTP_ERR_NOMEM;
    }
    dc_ctx_borders(c);
    return RTP_OK;
}

static void dc_ctx_free(dc_ctx *c, const rtp_allocator *a)
{
    rtpi_free(a, c->rlo);
    rtpi_free(a, c->rhi);
    rtpi_free(a, c->ulo);
    rtpi_free(a, c->uhi);
    rtpi_free(a, c->blo);
    rtpi_free(a, c->bhi);
}

static int dc_res_ok(int res)
{
    return res >= 1 && res <= RTPI_DC_MAX_RES;
}

/* Sets each face's window to the projection of the bounds of every
   hittable primitive (grown by 1e-6 of the geometry's scale and 1e-12
   of the light's, far above the rounding of bounds and projection) within the face's frustum widened
   to lim, clamped to the face; to the whole face when the light is
   inside those bounds; to no cells when the bounds miss the face.  A
   window is never narrower than 1e-6 of its other side nor than 1e-14
   (a flat scene seen edge-on), so cell sizes stay positive. */
void rtpi_dc_windows(const rtp_scene *s, rtpi_v3 light, int res, double lim,
                     rtpi_dc_window *w)
{
    dc_windows_some(s, NULL, 0, light, res, lim, w);
}

/* The same over the primitives i with sel[i] == want (sel NULL: all). */
static void dc_windows_some(const rtp_scene *s, const unsigned char *sel, unsigned char want,
                            rtpi_v3 light, int res, double lim, rtpi_dc_window *w)
{
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    double L[3], S, g;
    size_t i, n = rtpi_scene_nprims(s);
    int f, k, inside = 1, any = 0;
    int present[6] = {1, 1, 1, 1, 1, 1};
    L[0] = light.x;
    L[1] = light.y;
    L[2] = light.z;
    for (f = 0; f < 6; f++) {
        w->u0[f] = w->v0[f] = -1.0;
        w->du[f] = w->dv[f] = 2.0 / (double)res;
        w->zbase[f] = 0.0;
        w->zext[f] = 1.0;
    }
    if (!sel && dc_kept(s)) {
        /* every primitive: the bounds rtpi_scene_bounds folded alike */
        for (k = 0; k < 3; k++) {
            lo[k] = s->phlo[k];
            hi[k] = s->phhi[k];
        }
        any = s->phany;
        n = 0;
    }
    for (i = 0; i < n; i++) {
        double pl[3], ph[3];
        if (!dc_hittable(s, (uint32_t)i) || (sel && sel[i] != want))
            continue;
        rtpi_prim_bounds_kept(s, (uint32_t)i, pl, ph);
        for (k = 0; k < 3; k++) {
            lo[k] = pl[k] < lo[k] ? pl[k] : lo[k];
            hi[k] = ph[k] > hi[k] ? ph[k] : hi[k];
        }
        any = 1;
    }
    if (!any)
        goto done;
    /* The margin covers the rounding of the bounds (1e-16 of the
       geometry's coordinates) and of their corners' offsets from the
       light (1e-16 of the light's), a millionfold and a hundredfold
       (ten thousandfold until session 20: 1e-12 of a light at 1e13 is
       10 units, five times a scene of size 2, and the scene shrank to a
       fifth of its window).
       It is not what
       keeps the light buffer exact (a direction past a window's edge is
       clamped to the edge cells, whose slabs run to infinity), so it
       need not grow with the light's distance beyond that rounding: a
       margin of 1e-6 of the light's coordinates made a light at 1e8 see
       a scene of size 2 in 1% of each face's cells, and its moves 8-16x
       slower (balls_s2). */
    {
        double SL = fmax(fabs(L[0]), fmax(fabs(L[1]), fabs(L[2]))), SG = 0.0;
        for (k = 0; k < 3; k++)
            SG = fmax(SG, fmax(fabs(lo[k]), fabs(hi[k])));
        g = 1e-6 * SG + 1e-14 * SL + 1e-30;
        S = fmax(SL, SG); /* (the bounds' and the light's: no pass over the
                             primitives again, as dc_scale makes) */
    }
    for (k = 0; k < 3; k++) {
        lo[k] -= g;
        hi[k] += g;
        inside = inside && L[k] >= lo[k] && L[k] <= hi[k];
    }
    {
        /* Depth extent from the light: the farthest corner. */
        double e = 0.0;
        for (k = 0; k < 3; k++)
            e = fmax(e, fmax(fabs(lo[k] - L[k]), fabs(hi[k] - L[k])));
        for (f = 0; f < 6; f++)
            w->zext[f] = e > 0.0 ? e : 1.0;
    }
    if (inside || !(S < 1e300))
        goto done;
    for (f = 0; f < 6; f++) {
        double umin = HUGE_VAL, umax = -HUGE_VAL, vmin = HUGE_VAL, vmax = -HUGE_VAL;
        double zmin = HUGE_VAL, zmax = -HUGE_VAL;
        int side;
        /* the box's six sides as polygons */
        for (side = 0; side < 6; side++) {
            int ax = side >> 1, a1 = (ax + 1) % 3, a2 = (ax + 2) % 3, v;
            static const int cu[4] = {0, 1, 1, 0}, cv[4] = {0, 0, 1, 1};
            dc_poly q, loc, cl;
            double uv[DC_MAXV][2];
            q.n = 4;
            for (v = 0; v < 4; v++) {
                q.v[v][ax] = ((side & 1) ? hi[ax] : lo[ax]) - L[ax];
                q.v[v][a1] = (cu[v] ? hi[a1] : lo[a1]) - L[a1];
                q.v[v][a2] = (cv[v] ? hi[a2] : lo[a2]) - L[a2];
            }
            loc.n = 4;
            for (v = 0; v < 4; v++)
                dc_local(f, q.v[v], loc.v[v]);
            k = dc_clip(&loc, &cl, lim);
            if (k < 0 || (k > 0 && !dc_project(&cl, uv))) {
                umin = vmin = -1.0;
                umax = vmax = 1.0;
                continue;
            }
            for (v = 0; v < k; v++) {
                /* The box within the frustum is convex, and its vertices
                   are these: its nearest and farthest depths are here. */
                zmin = fmin(zmin, cl.v[v][2]);
                zmax = fmax(zmax, cl.v[v][2]);
                umin = fmin(umin, uv[v][0]);
                umax = fmax(umax, uv[v][0]);
                vmin = fmin(vmin, uv[v][1]);
                vmax = fmax(vmax, uv[v][1]);
            }
        }
        if (!(umin <= umax && vmin <= vmax)) {
            present[f] = 0; /* the scene is not on this face */
            continue;
        }
        /* Within the face, and never narrower than a millionth of the
           other side (a flat scene seen edge-on) nor than 1e-14 (a
           hundred roundings of a face coordinate), so cell sizes stay
           positive; below every primitive's widening (lb_ang), so a
           window that narrow is listed as one.  (An absolute 1e-9 until
           session 19: a scene of size 10 at 1e11 covered 1% of it.) */
        umin = fmin(fmax(-1.0, umin), 1.0);
        vmin = fmin(fmax(-1.0, vmin), 1.0);
        umax = fmin(fmax(-1.0, umax), 1.0);
        vmax = fmin(fmax(-1.0, vmax), 1.0);
        {
            double mw = fmax(1e-14, 1e-6 * fmax(umax - umin, vmax - vmin));
            if (umax - umin < mw) {
                umax = fmin(1.0, umin + mw);
                umin = umax - mw;
            }
            if (vmax - vmin < mw) {
                vmax = fmin(1.0, vmin + mw);
                vmin = vmax - mw;
            }
        }
        w->u0[f] = umin;
        w->v0[f] = vmin;
        w->du[f] = (umax - umin) / (double)res;
        w->dv[f] = (vmax - vmin) / (double)res;
        if (zmin <= zmax) {
            w->zbase[f] = zmin;
            w->zext[f] = zmax - zmin > 0.0 ? zmax - zmin : 1.0;
        }
    }
done:
    w->ncells = 0;
    for (f = 0; f < 6; f++) {
        w->fbase[f] = present[f] ? w->ncells : RTPI_DC_ABSENT;
        w->ncells += present[f] ? (size_t)res * (size_t)res : 0;
    }
}

/* ------------------------------------------------------- light buffer */

/* Why the lists are exact: if rtpi_intersect_prim reports a hit of prim
   with the shadow ray, the exact line of the ray passes within
   delta ~ 1e-15 S of prim (double rounding of coordinates of size <= S),
   and that line passes within lambda ~ 1e-15 S of the light (the ray's
   direction is (light - o)/dist, rounded).  The hit's direction from the
   light therefore differs from the ray's by at most
   (delta + lambda) / near(prim) radians.  Each primitive is projected
   widened by ang = 1e-12 + 1e-13 S / near: the first term covers the
   rounding of face coordinates (a few 1e-16) with a thousandfold margin,
   the second the above with a hundredfold one.  (The first was 1e-7 until
   session 19: at a light 1e8 away that widened every primitive by 10
   units, a scene of size 2 listed all its primitives in every cell, and a
   move took 8-16x as long as at 1e6.)  delta is larger for a grazing hit
   of a sphere or a cone, whose quadratic loses digits as its discriminant
   nears 0: a harness (session 20) found a cone hit 1.3e-3 off the cone at
   coordinates of 3e5, 9e-14 rad from the ray seen from a light 8e9 away,
   5 times the widening then tried (1e-14 + 1e-14 S / near) and a tenth of
   this one, which is kept.  From about 1e11 a scene of size 2 spans
   little more than the widening (2e-11 rad against 1.1e-12); beyond it
   cells finer than a widening list each primitive in more of them only,
   so the light buffer then has fewer (lb_res), its entries staying near
   one a primitive instead of growing as res^2 each, and RTP_SHADOWS_AUTO
   and the item buffer take shadow rays (rtpi_lightbuf_res).  A primitive so close to the light that the bound
   grows past LB_ANG_MAX (1e-3, near < 1e-10 S) is listed in every cell.
   Windows and absent faces keep this: a window is the bounds' projection
   through frusta widened by more than any listed primitive's widening,
   and a direction beyond a window's edge is clamped to the edge cell,
   which lists everything whose widened projection reaches past the edge
   (the edge rows' slabs run to infinity). */
#define LB_ANG_BASE 1e-12
#define LB_ANG_SCALE 1e-13
#define LB_ANG_MAX 1e-3

#define LB_MAX_THREADS 16 /* threads of a light buffer's passes */

/* Threads for a pass of nchunks chunks: the caller's count within 1 ..
   LB_MAX_THREADS, and no more than one for each `per` chunks (a pass too
   short for a second thread is the calling thread's alone: lb_edges,
   rtpi_itembuf_thin) */
static int lb_chunk_threads(int threads, int nchunks, int per)
{
    int nt = threads < 1 ? 1 : threads > LB_MAX_THREADS ? LB_MAX_THREADS : threads;
    if (nt > nchunks / per)
        nt = nchunks / per > 1 ? nchunks / per : 1;
    return nt;
}
#define LB_MAX_PARTS 64   /* parts of its counting pass (rows: progress and cancel between) */

/* A run of cells [cell, cell + n) listing candidate `rank`: recorded by
   the counting pass so the filling pass need not project again. */
typedef struct lb_run {
    size_t cell;
    uint32_t n, rank;
} lb_run;

/* The bytes the runs of every part may take (the memory limit less the
   buffer's other blocks) and have taken, as the parts grow them. */
typedef struct lb_budget {
    rtpi_mutex lock;
    double room, stored;
} lb_budget;

/* The runs of one part of the candidates (ranks [r0, r1)). */
typedef struct lb_fill {
    uint32_t rank, r0, r1;
    uint64_t total;
    lb_run *runs;
    size_t nruns, cap;
    const rtp_allocator *a;
    int oom;
    lb_budget *bud;
    size_t counted; /* runs added to bud->stored */
    int over;       /* the runs of all parts passed bud->room (oom is set
                       too: the pass stops) */
} lb_fill;

static void lb_put(lb_fill *lf, size_t cell, int n)
{
    lb_run *r = &lf->runs[lf->nruns++];
    r->cell = cell;
    r->n = (uint32_t)n;
    r->rank = lf->rank;
}

/* A part's first block of runs (16 bytes each): 256 KiB, 16 MiB for
   LB_MAX_PARTS parts, of which only the pages written are taken.  Each
   doubling copies the block (realloc): from 4096 runs, tetra_s6's four
   parts of 1,024 triangles (10-20 runs each) copied 256 KiB in a move,
   as many instructions under callgrind as bytes (auto's move 0.26 M of
   27.3); SPD's parts of about 1,000 primitives make 4-17 k runs. */
#define LB_RUNS_FIRST 16384

/* lb_count where the runs are full: more room, then the run (nothing
   more once out of memory, lf->oom). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void lb_count_grow(lb_fill *lf, size_t cell, int n)
{
    size_t cap = lf->cap ? 2 * lf->cap : LB_RUNS_FIRST;
    lb_run *r;
    if (lf->oom)
        return;
    /* The runs stored so far, of every part, against the room (runs are
       16 bytes a primitive a row of cells: 10,000 stacked quads at 4096
       cells took 5.1 GB before the lists were counted against a limit of
       500 MiB).  Only runs really made are counted, so a part stops only
       where the whole pass would pass the room: the verdict is the same
       for any number of parts (a share of the room each, against their
       doubled blocks, refused at 100 MiB with two threads what one
       built); the blocks, doubled as they grow, may take up to twice
       that for the moment. */
    rtpi_mutex_lock(&lf->bud->lock);
    lf->bud->stored += (double)(lf->nruns - lf->counted) * sizeof *r;
    lf->counted = lf->nruns;
    lf->over = !(lf->bud->stored <= lf->bud->room);
    rtpi_mutex_unlock(&lf->bud->lock);
    if (lf->over) {
        lf->oom = 1;
        return;
    }
    r = cap <= (size_t)-1 / sizeof *r ? (lb_run *)rtpi_realloc(lf->a, lf->runs, cap * sizeof *r)
                                      : NULL;
    if (!r) {
        lf->oom = 1;
        return;
    }
    lf->runs = r;
    lf->cap = cap;
    lb_put(lf, cell, n);
}

/* (the growth out of line, a tail call: the run's store alone saves no
   registers, half its instructions before; gears' 214k runs a move) */
static void lb_count(void *user, size_t cell, int n)
{
    lb_fill *lf = (lb_fill *)user;
    lf->total += (uint64_t)n;
    if (lf->nruns == lf->cap)
        lb_count_grow(lf, cell, n);
    else
        lb_put(lf, cell, n);
}

static int lb_cmp(const void *a, const void *b)
{
    const rtpi_lb_cand *x = (const rtpi_lb_cand *)a, *y = (const rtpi_lb_cand *)b;
    if (x->near != y->near)
        return x->near < y->near ? -1 : 1;
    return x->prim < y->prim ? -1 : x->prim > y->prim;
}

/* near's bits as an unsigned key in the doubles' order (negative ones
   turned over, positive ones above them). */
static inline uint64_t lb_key(double d)
{
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    return u >> 63 ? ~u : u | (uint64_t)1 << 63;
}

/* lb_key's inverse: the double's bits again. */
static inline uint64_t lb_unkey(uint64_t k)
{
    return k >> 63 ? k & ~((uint64_t)1 << 63) : ~k;
}

/* The candidates in lb_cmp's order, given in ascending prim order: a
   stable radix sort on near's 64 bits, 11 at a time, skipping the digits
   every key shares (the exponent's high bits mostly).  qsort's calls of
   lb_cmp had been 3-20% of a light buffer's build (gears' thin
   primitives: 23 M instructions).  (Eleven bits rather than eight: six
   digits, five passes of gears' 36k keys rather than seven of bytes,
   7.5 -> 5.5 M instructions; the same stable order.)  *cp is replaced
   by the scratch block where the last pass left the order there (an odd
   count of passes), rather than copied back.  -1 when out of memory. */
#define LB_DIGIT 11
#define LB_DIGITS ((64 + LB_DIGIT - 1) / LB_DIGIT)
static int lb_sort(rtpi_lb_cand **cp, size_t n, const rtp_allocator *a)
{
    rtpi_lb_cand *c = *cp;
    const uint64_t mask = ((uint64_t)1 << LB_DIGIT) - 1;
    size_t (*cnt)[(size_t)1 << LB_DIGIT], i;
    rtpi_lb_cand *tmp, *src = c, *dst;
    int b;
    if (n < 64) {
        qsort(c, n, sizeof *c, lb_cmp);
        return 0;
    }
    cnt = (size_t(*)[(size_t)1 << LB_DIGIT])rtpi_calloc_array(a, LB_DIGITS, sizeof *cnt);
    tmp = (rtpi_lb_cand *)rtpi_malloc_array(a, n, sizeof *tmp);
    if (!cnt || !tmp) {
        rtpi_free(a, cnt);
        rtpi_free(a, tmp);
        return -1;
    }
    /* (each near's bits replaced by its key for the passes, and back after:
       lb_key is one to one, its inverse lb_unkey; a key made once rather
       than once a pass, gears 1.5 M instructions) */
    for (i = 0; i < n; i++) {
        uint64_t k = lb_key(c[i].near);
        memcpy(&c[i].near, &k, sizeof k);
#if LB_DIGITS == 6
        /* (the digits' loop written out: its own steps had been half of
           the counting, gears 0.9 M instructions) */
        cnt[0][k & mask]++;
        cnt[1][(k >> LB_DIGIT) & mask]++;
        cnt[2][(k >> (2 * LB_DIGIT)) & mask]++;
        cnt[3][(k >> (3 * LB_DIGIT)) & mask]++;
        cnt[4][(k >> (4 * LB_DIGIT)) & mask]++;
        cnt[5][(k >> (5 * LB_DIGIT)) & mask]++;
#else
        for (b = 0; b < LB_DIGITS; b++)
            cnt[b][(k >> (LB_DIGIT * b)) & mask]++;
#endif
    }
    dst = tmp;
    for (b = 0; b < LB_DIGITS; b++) {
        size_t sum = 0, j;
        uint64_t k;
        memcpy(&k, &src[0].near, sizeof k);
        if (cnt[b][(k >> (LB_DIGIT * b)) & mask] == n)
            continue; /* one value of this digit: the order holds */
        for (j = 0; j <= mask; j++) {
            size_t x = cnt[b][j];
            cnt[b][j] = sum;
            sum += x;
        }
        for (i = 0; i < n; i++) {
            memcpy(&k, &src[i].near, sizeof k);
            dst[cnt[b][(k >> (LB_DIGIT * b)) & mask]++] = src[i];
        }
        dst = src;
        src = src == c ? tmp : c;
    }
    for (i = 0; i < n; i++) {
        uint64_t k;
        memcpy(&k, &src[i].near, sizeof k);
        k = lb_unkey(k);
        memcpy(&src[i].near, &k, sizeof k);
    }
    rtpi_free(a, cnt);
    rtpi_free(a, src == c ? tmp : c);
    *cp = src;
    return 0;
}

/* A triangle's plane entry (see rtpi_lightbuf), the light buffer's and,
   with t added to n.p0, the exact moves' (rtpi_tri_planes): one
   computation for both (each had its own copy of it).  Where the light
   and a shadow ray's origin o both lie more than 1e-9 S from a
   triangle's plane on one side (S the scale: every coordinate, the
   light's and o's, at most S), the segment between them misses the plane
   by as much; the ray rtpi_shadow_ray makes runs on that segment to
   within ~1e-16 of its length, and the watertight test's rounding
   (~1e-15 S) is far below 1e-9 S, so it reports no hit either.  n.o -
   n.p0 is within ~1e-15 S |n| of n.(o - p0).
   The entry is turned to the light's side, so that the walk asks so > t
   alone, and t is HUGE_VAL where there is no test (degenerate, or the
   light (nearly) in the plane: n 0).  Negating n, n.p0 and t is exact,
   and so the walk's n.o - n.p0 is exactly the negated one's: the same
   candidates are turned away as by so < t on the other side.  (The
   sign's choice and the zero test had been a third of the test:
   lightbuf:256, third move, 512^2 SPD, gears 304.18 -> 299.51 M,
   teapot 189.31 -> 186.91; turned as they are made, not stored, read
   back and negated: gears 0.7 M instructions a move.  The vertices by
   value: rtpi_tri_planes loads them itself, through lb_tri_points 0.8 M
   more instructions on gears.) */
static RTPI_FORCE_INLINE void lb_plane_turned(rtpi_v3 p0, rtpi_v3 p1, rtpi_v3 p2, rtpi_v3 L,
                                              double S, double *pl)
{
    rtpi_v3 n = v3_cross(v3_sub(p1, p0), v3_sub(p2, p0));
    double d = v3_dot(n, p0), sl = v3_dot(n, L) - d, thr = 1e-9 * S * v3_len(n);
    if (!(thr > 0.0 && fabs(sl) > thr && thr < HUGE_VAL)) {
        pl[0] = pl[1] = pl[2] = pl[3] = 0.0; /* no test */
        pl[4] = HUGE_VAL;
    } else if (sl > 0.0) {
        pl[0] = n.x;
        pl[1] = n.y;
        pl[2] = n.z;
        pl[3] = d;
        pl[4] = thr;
    } else { /* (the light on n's other side: every entry negated) */
        pl[0] = -n.x;
        pl[1] = -n.y;
        pl[2] = -n.z;
        pl[3] = -d;
        pl[4] = thr;
    }
}

/* A triangle's vertices, as dc_cover_tri takes them. */
static RTPI_FORCE_INLINE void lb_tri_points(const rtp_scene *s, uint32_t prim, rtpi_v3 p[3])
{
    const rtpi_tri *t = &s->tris[prim];
    int k;
    for (k = 0; k < 3; k++)
        p[k] = v3_from_f(s->pos + 3 * (size_t)t->v[k]);
}

static double lb_ang(double S, double near)
{
    return near > 0.0 ? LB_ANG_BASE + LB_ANG_SCALE * S / near : HUGE_VAL;
}

/* The cells a face edge worth having for windows w made at res: cells
   narrower than the smallest widening any primitive gets (lb_ang at the
   farthest point of the windows) only list each primitive in more of
   them (terrain of 8k triangles, light at 1e12: as fast with cells that
   wide, in 14 MB instead of 31; at half of it 9.7 MB, a tenth slower
   from 3e12).  Far lights: a scene of size 2 at 1e16 spans 2e-16 radians, all
   of it within one widening. */
/* The smallest widening lb_ang gives any primitive in windows w: at the
   farthest point of them.  A point in a face's frustum (|u|, |v| <= 1.02)
   at depth z lies at most z sqrt(1 + 2 1.02^2) < 1.75 z from the light. */
static double lb_ang_min(const rtpi_dc_window *w, double S)
{
    double zmax = 0.0;
    int f;
    for (f = 0; f < 6; f++)
        if (w->fbase[f] != RTPI_DC_ABSENT)
            zmax = fmax(zmax, w->zbase[f] + w->zext[f]);
    return lb_ang(S, 1.75 * zmax);
}

static int lb_res(const rtpi_dc_window *w, int res, double S)
{
    double wmax = 0.0, ang = lb_ang_min(w, S), cap;
    int f;
    for (f = 0; f < 6; f++)
        if (w->fbase[f] != RTPI_DC_ABSENT)
            wmax = fmax(wmax, fmax(w->du[f], w->dv[f]) * (double)res);
    if (!(wmax > 0.0) || !(ang > 0.0) || !(ang < HUGE_VAL))
        return res;
    cap = ceil(wmax / ang);
    return cap < (double)res ? (cap < 1.0 ? 1 : (int)cap) : res;
}

/* One side of a window [*o, *o + res *d] made no narrower than res cells
   of `ang` (within the face [-1, 1]), around its middle. */
static void lb_grow_side(double *o, double *d, int res, double ang)
{
    double want = (double)res * ang, mid;
    if (!(*d < ang))
        return;
    if (!(want < 2.0)) {
        *o = -1.0;
        *d = 2.0 / (double)res;
        return;
    }
    mid = *o + 0.5 * (double)res * *d;
    *o = fmin(fmax(mid - 0.5 * want, -1.0), 1.0 - want);
    *d = want / (double)res;
}

/* A flat scene seen edge-on has a window a millionth as tall as it is
   wide (dc_windows_some), its rows far narrower than a widening: each
   primitive was listed in every row (51,200 triangles edge-on from 1e8
   away at 2048: 1.2 G entries, 5 GB).  Each side of each window is made
   at least res cells of the smallest widening wide; a window wider than
   the projection it holds keeps the lists exact (it still holds it). */
static void lb_narrow(rtpi_dc_window *w, int res, double S)
{
    double ang = lb_ang_min(w, S);
    int f;
    if (!(ang > 0.0) || !(ang < HUGE_VAL))
        return;
    for (f = 0; f < 6; f++)
        if (w->fbase[f] != RTPI_DC_ABSENT) {
            lb_grow_side(&w->u0[f], &w->du[f], res, ang);
            lb_grow_side(&w->v0[f], &w->dv[f], res, ang);
        }
}

/* The cone entry of candidate prim, a sphere or a cone (see
   rtpi_lightbuf): a ball B(C, R) holding it (a sphere itself, a cone its
   bounds' box), R grown by 1e-9 of itself and 1e-12 S for the
   rounding of the ball and of hit points.  Seen from the light at
   distance D > R the ball spans the angle asin(R/D) around C - L; a ray
   that hits the candidate runs within ang = lb_ang(S, near) of a
   direction to one of its points (the lists' own argument, above), so
   within asin(R/D) + ang of C - L.  With x = R/D, cos(asin x + ang) =
   sqrt(1 - x^2) cos ang - x sin ang >= sqrt(1 - x^2) (1 - ang^2/2) -
   x ang; 1e-12 less again covers the rounding of that bound and of the
   query's dot product (~1e-16), so a ray whose direction's dot product
   with the unit C - L is below the entry misses the candidate.  Most
   candidates of a cell only touch it: this test costs a dot product
   where the intersection test costs a square root and tens of
   operations.  -2 (never below) where the light is in the ball or the
   angle is wide. */
static void lb_cone(const rtp_scene *s, uint32_t prim, rtpi_v3 L, double S, double near,
                    double *out)
{
    size_t i = prim;
    rtpi_v3 C;
    double R, D, x, ang = lb_ang(S, near);
    out[0] = out[1] = out[2] = 0.0;
    out[3] = -2.0;
    if (i >= s->ntris && (i -= s->ntris) < s->nspheres) {
        C = v3_from_f(s->spheres[i].c);
        R = fabs((double)s->spheres[i].r);
    } else {
        double lo[3], hi[3];
        rtpi_prim_bounds_kept(s, prim, lo, hi);
        C = v3(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2]));
        R = 0.5 * v3_len(v3(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
    }
    R = R * (1.0 + 1e-9) + 1e-12 * S;
    D = v3_len(v3_sub(C, L));
    if (!(D > R) || !(ang < 1e-3) || !(D < HUGE_VAL))
        return;
    x = R / D;
    if (!(x < 0.99))
        return; /* wider than ~82 degrees: not worth a test */
    out[3] = sqrt(1.0 - x * x) * (1.0 - 0.5 * ang * ang) - x * ang - 1e-12;
    C = v3_mul(v3_sub(C, L), 1.0 / D);
    out[0] = C.x;
    out[1] = C.y;
    out[2] = C.z;
}

rtp_status rtpi_lightbuf_build(const rtp_scene *s, rtpi_v3 light, int res,
                               const rtp_allocator *a, rtpi_lightbuf *lb,
                               rtp_error *err)
{
    return rtpi_lightbuf_build_some(s, light, res, NULL, 0, 1, HUGE_VAL, HUGE_VAL, NULL, a, lb,
                                    err);
}

/* A thread of the counting pass: its projection scratch, and the parts
   (lb_fill) it is handed. */
typedef struct lb_worker {
    dc_ctx c;
    const rtpi_lightbuf *lb;
    lb_fill *parts;
    double S;
    char pad[64]; /* the workers lie side by side: no cache line shared */
} lb_worker;

static int lb_part(void *ctx, int part)
{
    lb_worker *w = (lb_worker *)ctx;
    lb_fill *lf = &w->parts[part];
    uint32_t i;
    for (i = lf->r0; i < lf->r1 && !lf->oom; i++) {
        uint32_t prim = w->lb->cand[i].prim;
        double ang = lb_ang(w->S, w->lb->cand[i].near);
        double *pl = w->lb->plane ? w->lb->plane + 5 * (size_t)i : NULL;
        lf->rank = i;
        if (prim < w->c.s->ntris) { /* (lb_count inlined into it) */
            rtpi_v3 p[3];
            lb_tri_points(w->c.s, prim, p);
            if (pl)
                lb_plane_turned(p[0], p[1], p[2], w->c.L, w->S, pl);
            dc_cover_tri(&w->c, prim, p, ang, lb_count, lf);
        } else {
            if (pl) { /* no plane: no test */
                pl[0] = pl[1] = pl[2] = pl[3] = 0.0;
                pl[4] = HUGE_VAL;
            }
            if (prim - w->c.s->ntris >= w->c.s->nspheres ||
                !dc_cover_sphere(&w->c, prim, ang, lb_count, lf))
                dc_cover(&w->c, prim, ang, lb_count, lf);
        }
    }
    return lf->oom;
}

/* lb_part with the triangles listed by their box (dc_box_tri), a
   function of its own so that lb_part's code stays as it was (one
   function asking a flag a triangle, or lb_part's body made twice, had
   cost gears' spans-cover move 0.2-0.5 M, mount's and teapot's 0.05-0.1);
   the other primitives handed to lb_part one at a time (its inlined
   sphere cover then still its only call). */
static int lb_part_box(void *ctx, int part)
{
    lb_worker *w = (lb_worker *)ctx;
    lb_fill *lf = &w->parts[part];
    uint32_t i, r0 = lf->r0, r1 = lf->r1;
    for (i = r0; i < r1 && !lf->oom; i++) {
        uint32_t prim = w->lb->cand[i].prim;
        if (prim < w->c.s->ntris) {
            double ang = lb_ang(w->S, w->lb->cand[i].near);
            double *pl = w->lb->plane ? w->lb->plane + 5 * (size_t)i : NULL;
            rtpi_v3 p[3];
            lf->rank = i;
            lb_tri_points(w->c.s, prim, p);
            if (pl)
                lb_plane_turned(p[0], p[1], p[2], w->c.L, w->S, pl);
            dc_cover_tri_box(&w->c, prim, p, ang, lb_count, lf);
        } else {
            lf->r0 = i;
            lf->r1 = i + 1;
            lb_part(ctx, part);
            lf->r0 = r0;
            lf->r1 = r1;
        }
    }
    return lf->oom;
}

/* One range of cells [lo, hi) of the lists, in three phases over every
   run (each range's own cells only, so the ranges run side by side and
   the buffer is the same for any number of them).  Phase 0 marks each
   run's clipped part [a, b) by +1 at off[a + 2] and -1 at off[b + 2]
   (b < hi), two writes a run where counting its cells had been one a
   cell (half of lb_cells_fn on tetra, whose triangles span hundreds of
   cells each); phase 1 turns those differences into each cell's count
   and the counts into running sums (from the range's first start, in
   `sum`), so that off[c + 1] is cell c's start; phase 2 fills each
   cell's list with off[c + 1] as its cursor, the runs taken in ascending
   rank (each list in ascending near), which leaves off[c] at cell c's
   start: the starts without a pass to shift them.  (Differences and
   sums are uint32_t: -1 wraps, and the running count is back in range
   at every cell.) */
typedef struct lb_cells {
    rtpi_lightbuf *lb;
    const lb_fill *parts;
    int nparts, phase;
    size_t lo, hi;
    uint32_t sum; /* phase 0: the range's count; then its first start */
    char pad[64]; /* side by side: no cache line shared */
} lb_cells;

/* The part [*a, *b) of run r within cells [lo, hi) (empty: *a >= *b). */
static inline void lb_clip(const lb_run *r, size_t lo, size_t hi, size_t *a, size_t *b)
{
    *a = r->cell > lo ? r->cell : lo;
    *b = r->cell + r->n < hi ? r->cell + r->n : hi;
}

/* A thread of lb_cells_fn: the ranges, and the caller's progress and
   cancel, which the calling thread (is_main) asks every LB_POLL_CELLS
   cells or LB_POLL_CELLS / 16 runs of its range (rtpi_stopper_poll calls
   them at most STOPPER_REPORTS times a build): at 8192 cells a face the
   bunny's cube passes over 400 M cells, 3 s. */
typedef struct lb_cells_thr {
    lb_cells *lc;
    rtpi_stopper *stp;
    int is_main;
} lb_cells_thr;

#define LB_POLL_CELLS ((size_t)1 << 20)

/* lb_cells_fn's phase 0 or 2 over runs r[0..n) (see lb_cells), `sum`
   carried: whole, the range [lo, hi) holds every cell (one thread's
   lists: lo 0, hi the cells), where each run lies within it and its clip
   is left out (gears' 125k runs a move, twice: 3 M instructions). */
static RTPI_FORCE_INLINE uint32_t lb_runs(const lb_run *r, size_t n, size_t lo, size_t hi,
                                          int whole, int phase, uint32_t *off, uint32_t *ref,
                                          uint32_t sum)
{
    size_t i, c;
    for (i = 0; i < n; i++) {
        size_t a, b;
        if (whole) {
            a = r[i].cell;
            b = a + r[i].n;
        } else {
            lb_clip(&r[i], lo, hi, &a, &b);
            if (a >= b)
                continue;
        }
        if (phase == 0) {
            off[a + 2]++;
            if (b < hi)
                off[b + 2]--;
            sum += (uint32_t)(b - a);
        } else {
            /* (the rank in a local: ref's stores may alias it for all
               the compiler knows, which reloaded it an entry) */
            uint32_t rank = r[i].rank, *o = off + 1;
            /* (two cells a step: the floor's runs in every row) */
            for (c = a; c + 2 <= b; c += 2) {
                ref[o[c]++] = rank;
                ref[o[c + 1]++] = rank;
            }
            if (c < b)
                ref[o[c]++] = rank;
        }
    }
    return sum;
}

static int lb_cells_fn(void *ctx, int part)
{
    const lb_cells_thr *th = (const lb_cells_thr *)ctx;
    lb_cells *lc = th->lc + part;
    uint32_t *off = lc->lb->off;
    size_t lo = lc->lo, hi = lc->hi, i, c, done = 0, span = hi > lo ? hi - lo : 1, all = 0;
    int k;
    uint32_t *ref = lc->lb->ref, sum = lc->sum, d = 0;
    const int whole = lo == 0 && hi == lc->lb->w.ncells; /* (lb_runs) */
    if (lc->phase == 1) {
        size_t c1;
        if (lo == 0)
            off[1] = 0;
        for (c = lo; c < hi; c = c1) {
            c1 = hi - c > LB_POLL_CELLS ? c + LB_POLL_CELLS : hi;
            if (c > lo && rtpi_stopper_poll(th->stp, th->is_main, (double)(c - lo) / (double)span))
                return 1;
            /* (four cells a step: a pass over every cell of the cube, whose
               loop's own instructions had been half of it; tree 1.3 M cells) */
            for (; c + 4 <= c1; c += 4) {
                uint32_t *o = off + c + 2;
                d += o[0];
                o[0] = sum += d;
                d += o[1];
                o[1] = sum += d;
                d += o[2];
                o[2] = sum += d;
                d += o[3];
                o[3] = sum += d;
            }
            for (; c < c1; c++) {
                d += off[c + 2];
                sum += d;
                off[c + 2] = sum;
            }
        }
        return 0;
    }
    if (lc->phase == 0) {
        /* (the first touch of the cells' memory: most of a fine cube's
           build, so asked between blocks too) */
        for (c = lo; c < hi; c += LB_POLL_CELLS) {
            size_t n = hi - c > LB_POLL_CELLS ? LB_POLL_CELLS : hi - c;
            if (c > lo &&
                rtpi_stopper_poll(th->stp, th->is_main, 0.5 * (double)(c - lo) / (double)span))
                return 1;
            memset(off + c + 2, 0, n * sizeof *off);
        }
        sum = 0;
    }
    for (k = 0; k < lc->nparts; k++)
        all += lc->parts[k].nruns;
    /* phase 0 marks the runs' ends, phase 2 lists the runs' ranks (asking
       between blocks of runs: a test a run cost gears' moves 1%) */
    for (k = 0; k < lc->nparts; k++)
        for (i = 0; i < lc->parts[k].nruns;) {
            const size_t i1 = lc->parts[k].nruns - i > LB_POLL_CELLS / 16
                                  ? i + LB_POLL_CELLS / 16
                                  : lc->parts[k].nruns;
            if (done &&
                rtpi_stopper_poll(th->stp, th->is_main,
                                  (lc->phase == 0 ? 0.5 : 0.0) +
                                      (lc->phase == 0 ? 0.5 : 1.0) * (double)done / (double)all))
                return 1;
            done += i1 - i;
            if (whole) /* (the same steps, the clip a no-op) */
                sum = lb_runs(lc->parts[k].runs + i, i1 - i, lo, hi, 1, lc->phase, off, ref, sum);
            else
                sum = lb_runs(lc->parts[k].runs + i, i1 - i, lo, hi, 0, lc->phase, off, ref, sum);
            i = i1;
        }
    if (lc->phase == 0)
        lc->sum = sum;
    return 0;
}

/* Takes the faces of lb's windows that no run reaches (bit f of `used`
   0) out of its cells: they are absent then, a query in their directions
   answering at once what their empty lists would (nothing in the way),
   and the lists' passes over every cell pass over fewer (teapot: two of
   its three faces' 786k cells list nothing, rings four of six).  The
   runs' cells renumbered to the faces kept.  @return the cells now. */
static size_t lb_drop_faces(rtpi_lightbuf *lb, lb_fill *parts, int np, unsigned used)
{
    size_t fcells = (size_t)lb->res * (size_t)lb->res, shift[6], ncells = 0, i;
    int f, k, nf = 0, drop = 0;
    for (f = 0; f < 6; f++)
        if (lb->w.fbase[f] != RTPI_DC_ABSENT)
            drop |= !((used >> f) & 1u);
    if (!drop || !fcells)
        return lb->w.ncells;
    for (f = 0; f < 6; f++) {
        if (lb->w.fbase[f] == RTPI_DC_ABSENT)
            continue;
        /* (the nf-th face's cells lay at nf fcells) */
        if ((used >> f) & 1u) {
            shift[nf] = (size_t)nf * fcells - ncells;
            lb->w.fbase[f] = ncells;
            ncells += fcells;
        } else {
            shift[nf] = 0; /* (no run there) */
            lb->w.fbase[f] = RTPI_DC_ABSENT;
        }
        nf++;
    }
    lb->w.ncells = ncells;
    for (k = 0; k < np; k++)
        for (i = 0; i < parts[k].nruns; i++) {
            lb_run *r = &parts[k].runs[i];
            r->cell -= shift[r->cell / fcells];
        }
    return ncells;
}

/* The candidates' edge entries (rtpi_lightbuf.edge) once the lists are
   made, where room (bytes the limit leaves) holds them: for a triangle
   rtpi_tri_edges' entry, the same numbers by the same operations (its
   plane from the turned entry: n, and n.p0 + t, as rtpi_tri_planes adds
   them; test_shadow compares them), so that rtpi_edges_miss' proof (at
   rtpi_tri_edges) holds for the walk's rays, shadow rays towards the
   light from origins within the scale.  (lightbuf:256, third move,
   512^2 SPD: the walks' watertight tests on gears 266 k -> 86 k with the
   edges' test alone, the move 286.95 -> 281.11 M.) */
/* lb_edges' entries for ranks [LB_EDGE_CHUNK row, + LB_EDGE_CHUNK): each
   a function of its own candidate alone, so in chunks on any threads
   the same bytes.  (A serial loop, it was 4% of gears_s4's lightbuf
   move at one thread and, at two, 7% of the move's time on one.) */
#define LB_EDGE_CHUNK 1024
#define LB_EDGE_THREADS 16

typedef struct lb_edge_job {
    rtpi_lightbuf *lb;
    const rtp_scene *s;
    rtpi_v3 light;
} lb_edge_job;

static int lb_edge_chunk(void *ctx, int chunk)
{
    const lb_edge_job *jb = (const lb_edge_job *)ctx;
    rtpi_lightbuf *lb = jb->lb;
    const rtp_scene *s = jb->s;
    size_t r = (size_t)chunk * LB_EDGE_CHUNK, r1 = r + LB_EDGE_CHUNK;
    if (r1 > lb->ncand)
        r1 = lb->ncand;
    for (; r < r1; r++) {
        uint32_t prim = lb->cand[r].prim;
        const double *q = lb->plane + 5 * r;
        double *e = lb->edge + RTPI_EDGE_N * r;
        int k;
        if (prim >= s->ntris) {
            for (k = 0; k < RTPI_EDGE_N; k++)
                e[k] = 0.0;
            e[6] = HUGE_VAL;
            continue;
        }
        lb->rank_of[prim] = (uint32_t)r; /* (a triangle's one rank: no two chunks write one) */
        /* (q[3] + q[4]: its plane turned, as the walk's; no test where
           0 + HUGE_VAL) */
        rtpi_tri_edge_entry(e, s, &s->tris[prim], jb->light, q, q[3] + q[4]);
    }
    return 0;
}

static void lb_edges(rtpi_lightbuf *lb, const rtp_scene *s, rtpi_v3 light,
                     const rtp_allocator *a, double room, int threads)
{
    size_t nc = lb->ncand;
    double S = lb->scale;
    lb_edge_job jb;
    void *ctx[LB_MAX_THREADS];
    int k, nchunks, nt;
    lb->edge = NULL;
    if (!lb->plane || lb->cone || !nc || nc > RTPI_EDGE_TRIS || !(S >= 1e-90 && S <= 1e90) ||
        !((double)nc * RTPI_EDGE_N * sizeof(double) + (double)s->ntris * sizeof(uint32_t) <=
          room))
        return;
    lb->edge = (double *)rtpi_malloc_array(a, RTPI_EDGE_N * nc, sizeof *lb->edge);
    lb->rank_of = (uint32_t *)rtpi_malloc_array(a, s->ntris, sizeof *lb->rank_of);
    if (!lb->edge || !lb->rank_of) { /* (a speed-up only: the walk asks the planes instead) */
        rtpi_free(a, lb->edge);
        rtpi_free(a, lb->rank_of);
        lb->edge = NULL;
        lb->rank_of = NULL;
        return;
    }
    memset(lb->rank_of, 0xff, s->ntris * sizeof *lb->rank_of); /* (RTPI_NONE) */
    lb->ethr = RTPI_EDGE_MARGIN * S * S * S;
    jb.lb = lb;
    jb.s = s;
    jb.light = light;
    nchunks = (int)((nc + LB_EDGE_CHUNK - 1) / LB_EDGE_CHUNK);
    /* (threads from LB_EDGE_THREADS chunks a thread: below, the calling
       thread alone, as tree.c's threads_for, a pass under a millisecond
       there, where a worker's start costs tens of microseconds and, on
       a busy machine, its wake-up a scheduler slice the pass then waits
       for: tetra_s6's 4 chunks, 0.07 ms of work, took 1.0 ms of wall at
       two threads under a load of 6; gears_s4's 36 chunks took 1.5 ms at one) */
    nt = lb_chunk_threads(threads, nchunks, LB_EDGE_THREADS);
    for (k = 0; k < nt; k++)
        ctx[k] = &jb;
    rtpi_parallel_rows(nchunks, nt, ctx, lb_edge_chunk, NULL, NULL);
}

/* lb->slab (see dircube.h) where lb has cone entries and s cones, and
   their memory fits in `room`.  A cone (rtpi_cone_frame cf: axis from b
   along the unit w, radii ra and rb) lies within R = max(ra, rb) of its
   axis, which lies in the plane through the light L and the axis, of
   unit normal q: every point X of it has |q.(X - L)| <= R, so at
   |X - L| >= near (dc_near's bound, rtpi_lightbuf_cand) its direction x
   from L has |q.x| <= R / near.  A ray that hits it has a direction
   within ang (lb_ang: the hit's rounding and the ray's, see above) of
   such an x, so |q.d| <= R / near + ang.  Made as lb_cone's, R grown by
   1e-9 of itself and 1e-12 of the scale; q computed from w x (b - L),
   off the true normal by a few u |b - L| / |w x (b - L)| (u = 2^-53),
   under 1e-13 where |w x (b - L)| >= 1e-2 |b - L| (asked: else no
   bound), which moves |q.x| by as much; 1e-12 more covers that and the
   rounding of the bound and of the query's dot product (~1e-16).  No
   bound (2, above any |q.d|) where the light is near the axis' line,
   the cone's frame is not ok (rtpi_intersect_prim then tests the cone
   otherwise) or the bound passes 1: the cone test (lb_cone) holds most
   of the rest.  Rings: the cone test lets 45% of its walks' candidates
   through, a bounding ball being wide for a long cylinder, and the
   cylinder test misses 70% of those. */
static void lb_slabs(rtpi_lightbuf *lb, const rtp_scene *s, rtpi_v3 light,
                     const rtp_allocator *a, double room)
{
    size_t r, nc = lb->ncand, c0 = s->ntris + s->nspheres;
    double S = lb->scale;
    lb->slab = NULL;
    lb->cone_rank = NULL;
    if (!lb->cone || !s->ncones || !nc ||
        !((double)nc * 4.0 * sizeof(double) + (double)s->ncones * sizeof(uint32_t) <= room))
        return;
    lb->slab = (double *)rtpi_malloc_array(a, 4 * nc, sizeof *lb->slab);
    lb->cone_rank = (uint32_t *)rtpi_malloc_array(a, s->ncones, sizeof *lb->cone_rank);
    if (!lb->slab || !lb->cone_rank) { /* (a speed-up only) */
        rtpi_free(a, lb->slab);
        rtpi_free(a, lb->cone_rank);
        lb->slab = NULL;
        lb->cone_rank = NULL;
        return;
    }
    memset(lb->cone_rank, 0xff, s->ncones * sizeof *lb->cone_rank); /* (RTPI_NONE) */
    for (r = 0; r < nc; r++) {
        uint32_t prim = lb->cand[r].prim;
        double *q = lb->slab + 4 * r, near = lb->cand[r].near;
        q[0] = q[1] = q[2] = 0.0;
        q[3] = 2.0;
        if (prim >= c0 && prim - c0 < s->ncones) {
            const rtpi_cone_frame *cf = &s->cframes[prim - c0];
            rtpi_v3 bl = v3_sub(cf->b, light), m = v3_cross(cf->w, bl);
            lb->cone_rank[prim - c0] = (uint32_t)r;
            double mm = v3_len(m), R, t, ang = lb_ang(S, near);
            if (!cf->ok || !(mm >= 1e-2 * v3_len(bl)) || !(mm < HUGE_VAL) || !(ang < 1e-3))
                continue;
            R = fabs(cf->ra) > fabs(cf->rb) ? fabs(cf->ra) : fabs(cf->rb);
            R = R * (1.0 + 1e-9) + 1e-12 * S;
            t = R / near + ang + 1e-12;
            if (!(t < 1.0))
                continue;
            m = v3_mul(m, 1.0 / mm);
            q[0] = m.x;
            q[1] = m.y;
            q[2] = m.z;
            q[3] = t;
        }
    }
}

int rtpi_lightbuf_res(const rtp_scene *s, rtpi_v3 light, int res)
{
    rtpi_dc_window w;
    if (res <= 0)
        res = RTPI_DC_DEFAULT_RES;
    dc_windows_some(s, NULL, 0, light, res, 1.02, &w);
    return lb_res(&w, res, dc_scale(s, light));
}

/* Box covers for the triangles (dc_box_tri) where the queries the
   buffer is expected to answer are fewer than this many a triangle
   candidate.  The box saves the spans' crossings in the build, a cost a
   triangle, and lengthens the lists (about twice the cells: a triangle
   fills at most half its box), a cost a query: measured (512² SPD, the
   third lightbuf:256 move, the box for all triangles against none),
   tetra_s6 at 4.0 queries a triangle gains 2.4 M of 28.3, gears_s4 at
   7.4-8.2 loses 3.0-3.9 M (thin teeth: boxes far larger than them),
   teapot at 18.6 6.2 M, mount at 57 2.1 M; 6 lies between with room on
   both sides (gears' 7.4 the nearest).  Queries, not walks: a query the
   cached occluder answers walks no list, so this errs towards the
   spans. */
#define LB_BOX_QUERIES 6.0

rtp_status rtpi_lightbuf_build_some(const rtp_scene *s, rtpi_v3 light, int res,
                                    const unsigned char *sel, unsigned char want, int threads,
                                    double limit, double max_entries, const rtpi_poll *poll,
                                    const rtp_allocator *a,
                                    rtpi_lightbuf *lb, rtp_error *err)
{
    return rtpi_lightbuf_build_q(s, light, res, sel, want, threads, limit, max_entries, HUGE_VAL,
                                 poll, a, lb, err);
}

static rtp_status lb_build(const rtp_scene *s, rtpi_v3 light, int res,
                          const unsigned char *sel, unsigned char want, int threads, double limit,
                          double max_entries, double queries, const rtpi_poll *poll,
                          const rtp_allocator *a, rtpi_lightbuf *lb, rtp_error *err);

rtp_status rtpi_lightbuf_build_q(const rtp_scene *s, rtpi_v3 light, int res,
                                 const unsigned char *sel, unsigned char want, int threads,
                                 double limit, double max_entries, double queries,
                                 const rtpi_poll *poll, const rtp_allocator *a,
                                 rtpi_lightbuf *lb, rtp_error *err)
{
    rtp_status st = lb_build(s, light, res, sel, want, threads, limit, max_entries, queries, poll,
                             a, lb, err);
    /* The box's longer lists past the limit or AUTO's bound where the
       spans' may fit (thin triangles' boxes list far more cells, as
       gears' teeth): the spans then, as without an expectation. */
    if ((st == RTP_ERR_LIMIT || st == RTPI_OVER_ENTRIES) &&
        queries < LB_BOX_QUERIES * (double)s->ntris)
        st = lb_build(s, light, res, sel, want, threads, limit, max_entries, HUGE_VAL, poll, a, lb,
                      err);
    return st;
}

static rtp_status lb_build(const rtp_scene *s, rtpi_v3 light, int res,
                          const unsigned char *sel, unsigned char want, int threads, double limit,
                          double max_entries, double queries, const rtpi_poll *poll,
                          const rtp_allocator *a, rtpi_lightbuf *lb, rtp_error *err)
{
    size_t n = rtpi_scene_nprims(s), ncells, i, nc = 0;
    lb_worker *wk = NULL; /* (on the heap: 16 were a 72 KB frame) */
    lb_fill parts[LB_MAX_PARTS];
    void *ctx[LB_MAX_THREADS];
    rtpi_locked_alloc la;
    const rtp_allocator *ta = a;
    uint64_t total = 0;
    size_t runs = 0;
    lb_budget bud;
    int np, nt, k, nw = 0, failed = 0, over = 0, rows, by_entries, box;
    size_t ntc = 0; /* the candidates that are triangles */
    unsigned used = 0; /* faces whose cells the runs reach (dc_ctx.faces) */
    double S, lists = HUGE_VAL; /* (the buffer's bytes, once its lists are counted) */
    const unsigned char *hit = dc_kept(s) ? s->phit : NULL; /* (dc_hittable's) */
    memset(lb, 0, sizeof *lb);
    if (res <= 0)
        res = RTPI_DC_DEFAULT_RES;
    if (!dc_res_ok(res))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "light buffer resolution %d outside 1..%d", res, RTPI_DC_MAX_RES);
    lb->res = res;
    lb->light = light;
    /* Windows projected with frusta 2% wider than the faces: more than
       any primitive's widening (4 LB_ANG_MAX), so a primitive that can
       be hit through a face lies in that face's window. */
    dc_windows_some(s, sel, want, light, res, 1.02, &lb->w);
    S = dc_scale(s, light);
    {
        int r = lb_res(&lb->w, res, S);
        if (r < res) {
            res = lb->res = r;
            dc_windows_some(s, sel, want, light, res, 1.02, &lb->w);
        }
        lb_narrow(&lb->w, res, S);
    }
    lb->top = (double)(res - 1);
    for (k = 0; k < 6; k++) {
        lb->ru[k] = 1.0 / lb->w.du[k];
        lb->rv[k] = 1.0 / lb->w.dv[k];
    }
    ncells = lb->w.ncells;
    /* Early stop: a primitive can be hit on the segment from o to the
       light only if near <= dist + delta + lambda (see above); 1e-12 S
       bounds delta + lambda with room to spare. */
    lb->slack = 1e-12 * S;
    lb->scale = S;
    /* The candidates' arrays against the limit before they are made (the
       runs' budget below counts them only once made): a candidate, then
       its sort's scratch or its plane and cone.  An 8M-triangle mesh's
       took 600 MB before a limit of 50 MiB refused the lists. */
    for (i = 0; i < n; i++)
        nc += (hit ? hit[i] : rtpi_prim_hittable(s, (uint32_t)i)) && !(sel && sel[i] != want);
    {
        int cones = nc && (s->nspheres + s->ncones) * 16 >= rtpi_scene_nprims(s);
        double per = (double)sizeof *lb->cand +
                     fmax((double)sizeof *lb->cand,
                          (s->ntris ? 40.0 : 0.0) +
                              (cones ? (double)sizeof *lb->cone : 0.0));
        double need = 4.0 * ((double)ncells + 2.0) + (double)nc * per;
        if (!(need <= limit)) {
            char g[2][32]; /* '.' whatever the locale */
            rtpi_fmt_g(g[0], sizeof g[0], 6, rtpi_mib_up(need));
            rtpi_fmt_g(g[1], sizeof g[1], 6, limit / 1048576.0);
            return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                              "a light buffer of %d cells a face: its %zu primitives take %s MiB "
                              "before its lists, over the memory limit of %s MiB (take --shadows "
                              "exact, or raise memory_limit: rtp's --memory-limit)",
                              res, nc, g[0], g[1]);
        }
    }
    nc = 0;
    lb->cand = (rtpi_lb_cand *)rtpi_malloc_array(a, n ? n : 1, sizeof *lb->cand);
    /* (ncells + 2: lb_cells' cursors; zeroed there, by parts) */
    lb->off = (uint32_t *)rtpi_malloc_array(a, ncells + 2, sizeof *lb->off);
    if (!lb->cand || !lb->off) {
        rtpi_lightbuf_free(lb, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the light buffer");
    }
    for (i = 0; i < n; i++) {
        if (!(hit ? hit[i] : rtpi_prim_hittable(s, (uint32_t)i)))
            continue; /* never hit by any ray: cannot shadow */
        if (sel && sel[i] != want)
            continue;
        lb->cand[nc].prim = (uint32_t)i;
        lb->cand[nc].near = dc_near(s, (uint32_t)i, light);
        nc++;
    }
    lb->ncand = nc;
    /* (the triangles among the candidates counted only where the rule
       may hold: not at all for a build without an expectation) */
    if (queries < LB_BOX_QUERIES * (double)s->ntris)
        for (i = 0; i < nc; i++)
            ntc += lb->cand[i].prim < s->ntris;
    box = ntc && queries < LB_BOX_QUERIES * (double)ntc;
    /* Filling the cells in ascending near order sorts every list. */
    if (lb_sort(&lb->cand, nc, a) != 0) {
        rtpi_lightbuf_free(lb, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the light buffer");
    }
    if (s->ntris && nc) {
        if (!(lb->plane = (double *)rtpi_malloc_array(a, 5 * nc, sizeof *lb->plane))) {
            rtpi_lightbuf_free(lb, a);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                              "out of memory for the light buffer");
        }
        /* (its entries made in the counting pass, lb_part: a triangle's
           vertices loaded once for its plane and its cells) */
    }
    /* (only spheres and cones use it, and only where they are more than a
       sixteenth of the scene: a few round shapes among a mesh's
       triangles, as mount's four glass balls, saved less than the test's
       branch cost the triangles, 1.6%) */
    if (nc && (s->nspheres + s->ncones) * 16 >= rtpi_scene_nprims(s)) {
        if (!(lb->cone = (rtpi_lb_cone *)rtpi_malloc_array(a, nc, sizeof *lb->cone))) {
            rtpi_lightbuf_free(lb, a);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                              "out of memory for the light buffer");
        }
        /* (a triangle's entry never below: the round walk's scan stops
           at it by the cone test alone, lb_walk) */
        for (i = 0; i < nc; i++) {
            rtpi_lb_cone *cn = &lb->cone[i];
            if (lb->cand[i].prim >= s->ntris)
                lb_cone(s, lb->cand[i].prim, light, S, lb->cand[i].near, cn->v);
            else {
                cn->v[0] = cn->v[1] = cn->v[2] = 0.0;
                cn->v[3] = -2.0;
            }
            cn->near = lb->cand[i].near;
            cn->prim = cn->skip = lb->cand[i].prim;
        }
    }
    /* The counting pass: every candidate projected, its runs of cells
       recorded, in parts of consecutive ranks on up to `threads` threads
       (the parts' runs, taken in order, are the one-thread pass's runs:
       the same buffer for any thread count). */
    nt = threads < 1 ? 1 : threads > LB_MAX_THREADS ? LB_MAX_THREADS : threads;
    if ((size_t)nt > nc / 256 + 1)
        nt = (int)(nc / 256 + 1); /* small scenes: not worth a thread */
    /* (parts of 1024 candidates and more, up to LB_MAX_PARTS: the
       caller's progress and cancel between them; the bunny's 69k
       triangles 64 parts) */
    np = (int)(nc / 1024 < LB_MAX_PARTS ? nc / 1024 : LB_MAX_PARTS);
    np = np > nt ? np : nt;
    memset(parts, 0, sizeof parts);
    if (nt > 1 && rtpi_locked_alloc_init(&la, a) == 0) {
        ta = &la.a;
    } else {
        nt = 1;
        np = (int)(nc / 1024 < LB_MAX_PARTS ? nc / 1024 : LB_MAX_PARTS);
        np = np > 1 ? np : 1;
    }
    for (k = 0; k < np; k++) {
        parts[k].r0 = (uint32_t)(nc * (size_t)k / (size_t)np);
        parts[k].r1 = (uint32_t)(nc * (size_t)(k + 1) / (size_t)np);
        parts[k].a = ta;
        parts[k].bud = &bud;
    }
    /* the runs within the limit too, less what is made already; and no
       more runs than entries may be (a run lists a cell at least) */
    bud.room = limit - 4.0 * ((double)ncells + 2.0) -
               (double)nc * (sizeof *lb->cand + (lb->plane ? 40.0 : 0.0) +
                             (lb->cone ? (double)sizeof *lb->cone : 0.0));
    by_entries = bud.room > max_entries * sizeof(lb_run);
    if (by_entries)
        bud.room = max_entries * sizeof(lb_run);
    bud.stored = 0.0;
    if (rtpi_mutex_init(&bud.lock) != 0) {
        if (ta != a)
            rtpi_locked_alloc_destroy(&la);
        rtpi_lightbuf_free(lb, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the light buffer");
    }
    wk = (lb_worker *)rtpi_malloc_array(a, (size_t)nt, sizeof *wk);
    for (nw = 0; wk && nw < nt; nw++) {
        if (dc_ctx_init(&wk[nw].c, s, light, res, a) != RTP_OK)
            break;
        dc_ctx_window(&wk[nw].c, &lb->w);
        wk[nw].lb = lb;
        wk[nw].parts = parts;
        wk[nw].S = S;
        ctx[nw] = &wk[nw];
    }
    rows = nw < nt ? 1
                   : rtpi_parallel_rows_poll(np, nt, ctx, box ? lb_part_box : lb_part, poll, 0.0,
                                             0.4);
    failed = rows != 0;
    for (k = 0; k < nw; k++) {
        used |= wk[k].c.faces;
        dc_ctx_free(&wk[k].c, a);
    }
    rtpi_free(a, wk);
    if (ta != a)
        rtpi_locked_alloc_destroy(&la);
    rtpi_mutex_destroy(&bud.lock);
    for (k = 0; k < np; k++) {
        total += parts[k].total;
        runs += parts[k].nruns;
        over |= parts[k].over;
    }
    if (rows == 2) { /* (cancelled: before any limit's verdict, as asked) */
        for (k = 0; k < np; k++)
            rtpi_free(a, parts[k].runs);
        rtpi_lightbuf_free(lb, a);
        return rtpi_cancelled(err);
    }
    /* (a whole pass: its runs, all made, against the room) */
    if (over || (!failed && !((double)runs * sizeof(lb_run) <= bud.room))) {
        char g[32]; /* '.' whatever the locale */
        for (k = 0; k < np; k++)
            rtpi_free(a, parts[k].runs);
        rtpi_lightbuf_free(lb, a);
        if (by_entries) {
            /* (more runs than entries allowed: more entries too) */
            rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                       "a light buffer of %d cells a face would list over %.0f entries", res,
                       max_entries);
            return RTPI_OVER_ENTRIES;
        }
        rtpi_fmt_g(g, sizeof g, 6, limit / 1048576.0);
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "a light buffer of %d cells a face: counting its lists passed the "
                          "memory limit of %s MiB (lower its resolution, take --shadows exact, or "
                          "raise memory_limit: rtp's --memory-limit)",
                          res, g);
    }
    if (!failed && (double)total > max_entries) { /* (the caller falls back: no message) */
        for (k = 0; k < np; k++)
            rtpi_free(a, parts[k].runs);
        rtpi_lightbuf_free(lb, a);
        rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                   "a light buffer of %d cells a face would list %.0f entries, over %.0f", res,
                   (double)total, max_entries);
        return RTPI_OVER_ENTRIES;
    }
    if (!failed && total > 0xffffffffu) {
        for (k = 0; k < np; k++)
            rtpi_free(a, parts[k].runs);
        rtpi_lightbuf_free(lb, a);
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "light buffer would hold more than 2^32 entries; lower the resolution");
    }
    /* The lists against the memory limit before they are made: 4 bytes an
       entry, with the cell starts and the candidates' records (the runs
       counted are freed first).  200k coplanar triangles seen edge on
       listed 3.6 GB at 4096 cells under --memory-limit 500. */
    if (!failed) {
        double need = 4.0 * ((double)total + (double)ncells) +
                      (double)nc * (sizeof *lb->cand + (lb->plane ? 40.0 : 0.0) +
                                    (lb->cone ? (double)sizeof *lb->cone : 0.0));
        lists = need;
        if (!(need <= limit)) {
            char g[2][32]; /* '.' whatever the locale */
            for (k = 0; k < np; k++)
                rtpi_free(a, parts[k].runs);
            rtpi_lightbuf_free(lb, a);
            rtpi_fmt_g(g[0], sizeof g[0], 6, rtpi_mib_up(need));
            rtpi_fmt_g(g[1], sizeof g[1], 6, limit / 1048576.0);
            return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                              "a light buffer of %d cells a face lists %s MiB, over the memory "
                              "limit of %s MiB (lower its resolution, take --shadows exact, or "
                              "raise memory_limit: rtp's --memory-limit)",
                              res, g[0], g[1]);
        }
    }
    if (!failed)
        ncells = lb_drop_faces(lb, parts, np, used);
    lb->nrefs = (size_t)total;
    lb->ref = failed ? NULL
                     : (uint32_t *)rtpi_malloc_array(a, lb->nrefs ? lb->nrefs : 1, sizeof *lb->ref);
    if (!lb->ref) {
        for (k = 0; k < np; k++)
            rtpi_free(a, parts[k].runs);
        rtpi_lightbuf_free(lb, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the light buffer");
    }
    /* The lists from the runs, by ranges of cells on up to `threads`
       threads (lb_cells) */
    {
        lb_cells lc[LB_MAX_THREADS];
        lb_cells_thr th[LB_MAX_THREADS];
        rtpi_stopper stp;
        /* (the phases' shares of the build's progress after the counting
           pass's 0.4: marking with the cells' first touch, summing,
           listing) */
        static const double plo[3] = {0.4, 0.65, 0.75}, pspan[3] = {0.25, 0.1, 0.25};
        int nr = threads < 1 ? 1 : threads > LB_MAX_THREADS ? LB_MAX_THREADS : threads;
        uint32_t base = 0;
        if ((size_t)nr > ncells / 4096 + 1)
            nr = (int)(ncells / 4096 + 1); /* small buffers: not worth a thread */
        if (rtpi_stopper_init(&stp, poll, 0.0, 0.0) != 0) {
            for (k = 0; k < np; k++)
                rtpi_free(a, parts[k].runs);
            rtpi_lightbuf_free(lb, a);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                              "out of memory for the light buffer");
        }
        for (k = 0; k < nr; k++) {
            lc[k].lb = lb;
            lc[k].parts = parts;
            lc[k].nparts = np;
            lc[k].lo = ncells * (size_t)k / (size_t)nr;
            lc[k].hi = ncells * (size_t)(k + 1) / (size_t)nr;
            th[k].lc = lc;
            th[k].stp = &stp;
            th[k].is_main = k == 0; /* (ctx[0]: the calling thread's) */
            ctx[k] = &th[k];
        }
        for (k = 0; k < 3 && !stp.stop; k++) {
            int q;
            for (q = 0; q < nr; q++)
                lc[q].phase = k;
            stp.lo = plo[k];
            stp.span = pspan[k]; /* (rising: stp.last carries over) */
            rtpi_parallel_rows(nr, nr, ctx, lb_cells_fn, NULL, NULL);
            if (k == 0)
                for (q = 0; q < nr; q++) { /* each range's first start */
                    uint32_t c = lc[q].sum;
                    lc[q].sum = base;
                    base += c;
                }
        }
        rtpi_stopper_destroy(&stp);
        if (stp.stop) {
            for (k = 0; k < np; k++)
                rtpi_free(a, parts[k].runs);
            rtpi_lightbuf_free(lb, a);
            return rtpi_cancelled(err);
        }
        lb->off[0] = 0;
    }
    for (k = 0; k < np; k++)
        rtpi_free(a, parts[k].runs);
    lb_edges(lb, s, light, a, limit - lists, threads);
    lb_slabs(lb, s, light, a, limit - lists);
    /* (lb_edges' and lb_slabs' bytes, as they count them) */
    lb->room = limit - lists;
    if (lb->edge)
        lb->room -= (double)lb->ncand * RTPI_EDGE_N * sizeof(double) +
                    (double)s->ntris * sizeof(uint32_t);
    if (lb->slab)
        lb->room -= (double)lb->ncand * 4.0 * sizeof(double) +
                    (double)s->ncones * sizeof(uint32_t);
    return RTP_OK;
}

int rtpi_lightbuf_visible(const rtpi_lightbuf *lb, const rtp_scene *s,
                          const rtpi_ray *ray)
{
    return rtpi_lightbuf_occluder(lb, s, ray, RTPI_NONE) == RTPI_NONE;
}

/* A query's cell: that of direction q = o - light, the ray's origin seen
   from the light, where rtpi_dc_wcell took the ray's direction -d.  The
   same arithmetic as rtpi_dc_face and rtpi_dc_wcoord, but q is exact
   (-(light - o), which the ray's d is rounded from, through a square
   root and a division), the divisions by du and dv are products with
   their reciprocals, and the clamps selects.  The cell is then made
   without waiting on the ray's normalisation, and the list's loads
   (off, ref, cand: each waits on the one before) start about that much
   earlier: perf showed half of a walk's time on the cell's divisions and
   the loads behind them.  A few roundings of u (and of t: a few 1e-16 of
   a face coordinate) from rtpi_dc_wcell's, which the lists' widening
   (1e-12 rad and more, lb_ang) covers as it covers those of -d: the same
   lists, the same answers.  m = |q[a]| > 0: the caller's tmax > 0 makes
   dist = |q| > 0 (a tmax of NaN does not reach here).  (lightbuf:512,
   one thread, CPU ms of a move, medians of 6 alternating processes:
   balls_s4 36.5 -> 32.9, mount_s6 34.7 -> 30.0, teapot_s12 28.1 -> 24.7;
   instructions, lightbuf:256: balls 206.96 -> 205.94 M, mount 209.01 ->
   207.81, teapot 154.19 -> 153.24.)  0 where the face has no cells
   (nothing can be met in these directions), else 1 and the cell in
   *cell: the caller branches on the face's test itself, not again on a
   returned RTPI_DC_ABSENT (two instructions a walk: balls' lightbuf:256
   move 192.69 -> 192.18 M). */
static RTPI_FORCE_INLINE int lb_cell(const rtpi_lightbuf *lb, rtpi_v3 q, size_t *cell)
{
    double c[3], u, v, t, top = lb->top, inv;
    int a, f, i, j, res = lb->res;
    c[0] = q.x;
    c[1] = q.y;
    c[2] = q.z;
    {
        double ax = fabs(c[0]), ay = fabs(c[1]), az = fabs(c[2]);
        a = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    }
    inv = 1.0 / fabs(c[a]);
    u = (a == 0 ? c[1] : a == 1 ? c[2] : c[0]) * inv;
    v = (a == 0 ? c[2] : a == 1 ? c[0] : c[1]) * inv;
    f = 2 * a + (c[a] < 0.0);
    if (lb->w.fbase[f] == RTPI_DC_ABSENT)
        return 0;
    t = (u - lb->w.u0[f]) * lb->ru[f];
    t = t > 0.0 ? t : 0.0;
    t = t < top ? t : top;
    i = (int)t;
    t = (v - lb->w.v0[f]) * lb->rv[f];
    t = t > 0.0 ? t : 0.0;
    t = t < top ? t : top;
    j = (int)t;
    *cell = lb->w.fbase[f] + (size_t)j * (size_t)res + (size_t)i;
    return 1;
}

/* The watertight test's ray, made at a query's first triangle. */
typedef struct lb_tri_ray {
    rtpi_wt_ray w;
    int made; /* -1: not yet; 0: nothing can be hit; 1: w holds it */
} lb_tri_ray;

/* rtpi_intersect_prim's test of triangle prim, the ray set up once a
   query rather than once a triangle, and without its check for a
   zero-area triangle: no candidate is one (dc_hittable).  Out of line:
   as fast, and a compiler that inlines it may find w used unmade. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int lb_tri_hit(const rtp_scene *s, uint32_t prim, const rtpi_ray *ray, lb_tri_ray *w)
{
    const rtpi_tri *tr = &s->tris[prim];
    double t, u, v;
    if (w->made < 0)
        w->made = rtpi_wt_setup(&w->w, ray);
    return w->made && rtpi_wt_tri(&w->w, s->pos + 3 * (size_t)tr->v[0],
                                  s->pos + 3 * (size_t)tr->v[1], s->pos + 3 * (size_t)tr->v[2],
                                  ray->tmin, ray->tmax, &t, &u, &v);
}

/* lb_tri_hit's answer where rtpi_edges_sure answered 1 for triangle
   prim: rtpi_wt_t_sure's (kdtree.h) on the scene's vertices, which
   lb_tri_hit tests. */
static RTPI_FORCE_INLINE int lb_t_sure(const rtp_scene *s, uint32_t prim, const rtpi_ray *ray)
{
    const rtpi_tri *tr;
    double oz, sz;
    int kz;
    if (!rtpi_wt_z(ray, &kz, &oz, &sz))
        return 0;
    tr = &s->tris[prim];
    return rtpi_wt_t_sure(s->pos + 3 * (size_t)tr->v[0], s->pos + 3 * (size_t)tr->v[1],
                          s->pos + 3 * (size_t)tr->v[2], kz, oz, sz, ray->tmin, ray->tmax);
}

/* Whether origin o lies within the light buffer's scale, where the
   planes' test holds (lb_plane_turned): the largest |coordinate| by
   selects, not three branches (an origin with a NaN coordinate may keep
   the planes: its test's comparisons are then false, and it rejects
   nothing, as without them; teapot's lightbuf:256 move 190.81 -> 189.93
   M instructions, mount 256.47 -> 255.31, balls 260.15 -> 259.38). */
static RTPI_FORCE_INLINE int lb_in_scale(const rtpi_lightbuf *lb, const rtpi_v3 *o)
{
    double ax = fabs(o->x), ay = fabs(o->y), az = fabs(o->z);
    double am = ax > ay ? ax : ay;
    return (am > az ? am : az) <= lb->scale;
}

/* The shadow ray of a query given its origin o alone (lb_occluder's
   ray NULL): rtpi_shadow_ray(*o, lb->light) made into *rb the first
   time a test asks for it, the very ray trace casts (the walk's cell,
   planes, edges and early stop take o and tmax alone).  Most queries on
   meshes reach no such test (one move at lightbuf:256: mount_s6 21 k of
   221 k walks, teapot_s12 25 k of 192 k): their direction's division
   and the ray's stores are not made. */
#define LB_RAY(ray, rb, o) ((ray) ? (ray) : (*(rb) = rtpi_shadow_ray(*(o), lb->light), (ray) = (rb)))

/* The list from entry k to end (one cell's) for the ray with direction
   -dn; `round` 0 where the buffer has no cone entries (few or no spheres
   and cones: a constant at each call, so the compiler makes the loop
   twice, and a mesh's candidates pay no test of their kind).  Forced
   inline: gcc had made it a call once lb_tri_hit came (balls' moves 5%
   more). */
static RTPI_FORCE_INLINE uint32_t lb_walk(const rtpi_lightbuf *lb, const rtp_scene *s,
                                          const rtpi_ray *ray, const rtpi_v3 *o, double tmax,
                                          rtpi_ray *rb, uint32_t skip, size_t k, size_t end,
                                          rtpi_v3 dn, int round, int band, int edges,
                                          const rtpi_edge_o *eop, int inscale, lb_tri_ray *wp)
{
    /* tmax = dist (1 - 1e-9): the segment reaches no farther than dist. */
    double lim = tmax * (1.0 + 2e-9) + lb->slack;
    /* the planes' test holds for origins within the scale (lb_in_scale) */
    /* (with edges: inscale and eo made by the caller, lb_occluder; in a
       round walk the check is made at its first triangle, plk then 1:
       most of its entries are spheres and cones, and most of its walks
       meet no triangle -- tree's lightbuf:256 move 2.3 M instructions of
       its 129 M, the check made at each query) */
    const double *pl = edges ? (inscale ? lb->plane : NULL)
                             : round ? NULL : lb_in_scale(lb, o) ? lb->plane : NULL;
    int plk = !round || edges;
    const double *sb = band ? lb->slab : NULL;
    const double *pe = edges && pl ? lb->edge : NULL;
    size_t ntris = s->ntris;
    rtpi_hit h;
    for (; k < end; k++) {
        uint32_t rank, prim;
        if (round) {
            /* A round walk's usual entry, a sphere or cone its cone test
               turns away (balls: 904 k of 1.2 M entries), in a loop of
               its own without calls, whose numbers stay in registers
               (in the whole loop the calls spill them: the direction,
               lim, skip and the arrays were reloaded at every entry).
               It stops at the first entry the loop below must see; the
               same entries in the same order. */
            const uint32_t *ref = lb->ref;
            const rtpi_lb_cone *cone = lb->cone, *cn;
            double dx = dn.x, dy = dn.y, dz = dn.z;
            for (;;) {
                rank = ref[k];
                cn = &cone[rank];
                if (cn->near > lim)
                    return RTPI_NONE; /* sorted: as the break below */
                if (cn->skip != skip) { /* (prim: rtpi_lb_cone) */
                    /* (a triangle's entry, 0 0 0 -2, stops it: its dot
                       product 0, or NaN, is never below -2) */
                    if (!(dx * cn->v[0] + dy * cn->v[1] + dz * cn->v[2] < cn->v[3]))
                        break;
                }
                if (++k == end)
                    return RTPI_NONE;
            }
            prim = cn->prim; /* (cand's: the record's; cand[rank] not loaded) */
        } else {
            const rtpi_lb_cand *cd;
            rank = lb->ref[k];
            cd = &lb->cand[rank];
            if (cd->near > lim)
                break; /* sorted: nothing farther on can reach the segment */
            prim = cd->prim;
            if (prim == skip)
                continue;
        }
        if (!round || prim < ntris) {
            if (pe) {
                /* its plane's test as the exact mode's, then its edges'
                   (lb_edges): the line from the light through the origin
                   passes outside one of them; or inside all three, and
                   the hit's t certainly in range: the watertight test's
                   answer without it */
                int e = rtpi_edges_sure(pe + RTPI_EDGE_N * (size_t)rank, eop, lb->ethr);
                if (e == 0)
                    continue;
                if (e == 1 && lb_t_sure(s, prim, LB_RAY(ray, rb, o)))
                    return prim;
            } else if (plk ? pl != NULL
                           : (plk = 1, (pl = lb_in_scale(lb, o) ? lb->plane : NULL) != NULL)) {
                /* a triangle with the light on one side of its plane: the
                   origin on that side too, the segment misses it (a floor
                   under the scene is in most cells' lists) */
                const double *q = pl + 5 * (size_t)rank;
                if (q[0] * o->x + q[1] * o->y + q[2] * o->z - q[3] > q[4])
                    continue;
            }
        } else {
            /* a sphere or cone, inside the cone of directions it can be
               hit in (lb_cone: the scan above turned away those outside;
               for triangles the plane test rejects as much, and this one
               cost more than it saved: gears 3%) */
            /* a cone: outside its band of directions about the plane
               through the light and its axis (lb_slabs) */
            if (band) {
                const double *q = sb + 4 * (size_t)rank;
                if (fabs(dn.x * q[0] + dn.y * q[1] + dn.z * q[2]) > q[3])
                    continue;
            }
        }
        if (prim < ntris ? lb_tri_hit(s, prim, LB_RAY(ray, rb, o), wp)
                         : rtpi_intersect_prim(s, prim, LB_RAY(ray, rb, o), &h))
            return prim;
    }
    return RTPI_NONE;
}

/* rtpi_lightbuf_occluder_first's body, inline in both entries: a query
   without a first candidate (most of them: teapot 133 k of 175 k) no
   longer passes through the other as a second call (lightbuf:256, third
   move, 512^2 SPD: teapot 189.93 -> 189.66 M, balls 259.38 -> 258.87). */
enum { LB_PLAIN, LB_ROUND, LB_EDGES, LB_BAND }; /* the walk lb_occluder takes (lb_walk's;
                                                   LB_BAND: LB_ROUND's with the cones' bands) */
/* ray NULL: a query from origin o, its ray rtpi_shadow_ray(*o, lb->light)
   made where a test asks for it (LB_RAY; for the round kinds at once:
   their cone and band tests take its direction); else o is &ray->o. */
static RTPI_FORCE_INLINE uint32_t lb_occluder(const rtpi_lightbuf *lb, const rtp_scene *s,
                                              const rtpi_ray *ray, const rtpi_v3 *o,
                                              uint32_t skip, uint32_t first, int kind)
{
    size_t cell, k;
    rtpi_v3 dn, q = v3_sub(*o, lb->light);
    rtpi_hit h;
    lb_tri_ray w;
    rtpi_edge_o eo;
    rtpi_ray rb;
    double tmax;
    int inscale = 0;
    w.made = -1;
    if (!ray && (kind == LB_ROUND || kind == LB_BAND)) {
        rb = rtpi_shadow_ray(*o, lb->light);
        ray = &rb;
    }
    /* rtpi_shadow_ray's tmax, from |q|: q = o - light is -(light - o)
       exactly (a difference's rounding is odd: each component the same
       magnitude, or both +0), so |q|^2 and its root are that ray's */
    tmax = ray ? ray->tmax : rtpi_shadow_tmax(v3_len(q));
    if (kind == LB_EDGES) { /* (once for the first and the walk) */
        double ax = fabs(o->x), ay = fabs(o->y), az = fabs(o->z);
        double am = ax > ay ? ax : ay;
        inscale = (am > az ? am : az) <= lb->scale;
        rtpi_edge_o_make(&eo, o);
    }
    if (first != RTPI_NONE) {
        /* (rtpi_intersect_prim's answer without its zero-area test, as
           lb_walk's: a triangle `first` is hittable, dircube.h); with
           edge entries, a triangle's answered by them where they can
           (rtpi_edges_sure, lb_t_sure: the same answer) */
        int e = 2;
        if (kind == LB_EDGES && inscale && first < s->ntris &&
            lb->rank_of[first] != RTPI_NONE) {
            e = rtpi_edges_sure(lb->edge + RTPI_EDGE_N * (size_t)lb->rank_of[first], &eo,
                              lb->ethr);
            if (e == 1 && lb_t_sure(s, first, LB_RAY(ray, &rb, o)))
                return first;
        }
        if (e != 0 && (first < s->ntris ? lb_tri_hit(s, first, LB_RAY(ray, &rb, o), &w)
                                        : rtpi_intersect_prim(s, first, LB_RAY(ray, &rb, o), &h)))
            return first;
    }
    if (!(tmax > 0.0)) {
        /* The origin is at the light: the direction means nothing; ask
           every candidate (never happens with real hits). */
        LB_RAY(ray, &rb, o);
        for (k = 0; k < lb->ncand; k++)
            if (rtpi_intersect_prim(s, lb->cand[k].prim, ray, &h))
                return lb->cand[k].prim;
        return RTPI_NONE;
    }
    dn = kind == LB_ROUND || kind == LB_BAND ? v3_mul(ray->d, -1.0) : v3(0.0, 0.0, 0.0);
    if (!lb_cell(lb, q, &cell))
        return RTPI_NONE; /* no primitive can be met in these directions */
    return lb_walk(lb, s, ray, o, tmax, &rb, skip, lb->off[cell], lb->off[cell + 1], dn,
                   kind == LB_ROUND || kind == LB_BAND, kind == LB_BAND, kind == LB_EDGES, &eo,
                   inscale, &w);
}

/* lb_occluder for each kind of buffer, out of line, the entries choosing
   one: the walk with the edges' test (lb_edges) inline beside the other
   two had changed their compiled loops (lightbuf:256, third move, 512^2
   SPD: balls 248.20 -> 251.25 M, rings 368.25 -> 370.72, their walks
   without it); alone, each compiles as the one it is. */
#if defined(__GNUC__)
#define LB_NOINLINE __attribute__((noinline))
#else
#define LB_NOINLINE
#endif
#define LB_OCCLUDERS(kind, name)                                                                   \
    static LB_NOINLINE uint32_t name(const rtpi_lightbuf *lb, const rtp_scene *s,                  \
                                     const rtpi_ray *ray, uint32_t skip)                           \
    {                                                                                              \
        return lb_occluder(lb, s, ray, &ray->o, skip, RTPI_NONE, kind);                            \
    }                                                                                              \
    static LB_NOINLINE uint32_t name##_first(const rtpi_lightbuf *lb, const rtp_scene *s,          \
                                             const rtpi_ray *ray, uint32_t skip, uint32_t first)   \
    {                                                                                              \
        return lb_occluder(lb, s, ray, &ray->o, skip, first, kind);                                \
    }                                                                                              \
    static LB_NOINLINE int name##_vis(const rtpi_lightbuf *lb, const rtp_scene *s,                 \
                                      const rtpi_v3 *o, uint32_t skip, uint32_t first,             \
                                      uint32_t *last)                                              \
    {                                                                                              \
        /* (two copies: the one without first keeps the edges' origin in  \
           registers, where the test of first had it stored and loaded) */ \
        uint32_t occ = first == RTPI_NONE ? lb_occluder(lb, s, NULL, o, skip, RTPI_NONE, kind)     \
                                          : lb_occluder(lb, s, NULL, o, skip, first, kind);        \
        *last = occ != RTPI_NONE ? occ + 1u : 0u;                                                  \
        return occ == RTPI_NONE;                                                                   \
    }
LB_OCCLUDERS(LB_PLAIN, lb_occ_plain)
LB_OCCLUDERS(LB_ROUND, lb_occ_round)
LB_OCCLUDERS(LB_EDGES, lb_occ_edges)
LB_OCCLUDERS(LB_BAND, lb_occ_band)

uint32_t rtpi_lightbuf_occluder(const rtpi_lightbuf *lb, const rtp_scene *s,
                                const rtpi_ray *ray, uint32_t skip)
{
    return lb->cone ? (lb->slab ? lb_occ_band(lb, s, ray, skip) : lb_occ_round(lb, s, ray, skip))
           : lb->edge ? lb_occ_edges(lb, s, ray, skip)
                      : lb_occ_plain(lb, s, ray, skip);
}

uint32_t rtpi_lightbuf_occluder_first(const rtpi_lightbuf *lb, const rtp_scene *s,
                                      const rtpi_ray *ray, uint32_t skip, uint32_t first)
{
    return lb->cone ? (lb->slab ? lb_occ_band_first(lb, s, ray, skip, first)
                                : lb_occ_round_first(lb, s, ray, skip, first))
           : lb->edge ? lb_occ_edges_first(lb, s, ray, skip, first)
                      : lb_occ_plain_first(lb, s, ray, skip, first);
}

rtpi_lb_occ_fn rtpi_lightbuf_occ_fn(const rtpi_lightbuf *lb)
{
    return lb->cone ? (lb->slab ? lb_occ_band : lb_occ_round)
           : lb->edge ? lb_occ_edges
                      : lb_occ_plain;
}

rtpi_lb_vis_fn rtpi_lightbuf_vis_fn(const rtpi_lightbuf *lb)
{
    return lb->cone ? (lb->slab ? lb_occ_band_vis : lb_occ_round_vis)
           : lb->edge ? lb_occ_edges_vis
                      : lb_occ_plain_vis;
}

void rtpi_lightbuf_free(rtpi_lightbuf *lb, const rtp_allocator *a)
{
    if (!lb)
        return;
    rtpi_free(a, lb->off);
    rtpi_free(a, lb->ref);
    rtpi_free(a, lb->cand);
    rtpi_free(a, lb->plane);
    rtpi_free(a, lb->cone);
    rtpi_free(a, lb->slab);
    rtpi_free(a, lb->cone_rank);
    rtpi_free(a, lb->edge);
    rtpi_free(a, lb->rank_of);
    lb->off = lb->ref = lb->rank_of = NULL;
    lb->cand = NULL;
    lb->plane = lb->edge = lb->slab = NULL;
    lb->cone = NULL;
    lb->cone_rank = NULL;
}

rtp_status rtpi_tri_planes(const rtp_scene *s, rtpi_v3 light, const rtp_allocator *a,
                           double **out, double *scale, rtp_error *err)
{
    size_t i;
    *out = NULL;
    *scale = dc_scale(s, light);
    if (!s->ntris)
        return RTP_OK;
    *out = (double *)rtpi_malloc_array(a, 4 * s->ntris, sizeof **out);
    if (!*out)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (i = 0; i < s->ntris; i++) {
        const rtpi_tri *t = &s->tris[i];
        double q[5], *o = *out + 4 * i;
        lb_plane_turned(v3_from_f(s->pos + 3 * (size_t)t->v[0]),
                        v3_from_f(s->pos + 3 * (size_t)t->v[1]),
                        v3_from_f(s->pos + 3 * (size_t)t->v[2]), light, *scale, q);
        /* The margin added to n.p0: n.o > n.p0 + t, the sum's rounding
           (~1e-16 of it) far below t (1e-9 S |n|, against n.p0's at most
           ~1.7 S |n|), so lb_plane_turned's argument holds unchanged; no
           test: 0 + inf, which n.o never exceeds. */
        o[0] = q[0];
        o[1] = q[1];
        o[2] = q[2];
        o[3] = q[3] + q[4];
    }
    return RTP_OK;
}

rtp_status rtpi_round_cones(const rtp_scene *s, rtpi_v3 light, double scale, double far,
                            const rtp_allocator *a, double **out, rtp_error *err)
{
    size_t i, n = s->nspheres + s->ncones;
    *out = NULL;
    if (!n)
        return RTP_OK;
    *out = (double *)rtpi_malloc_array(a, 4 * n + 6 * s->ncones, sizeof **out);
    if (!*out)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (i = 0; i < n; i++) {
        uint32_t prim = (uint32_t)(s->ntris + i);
        lb_cone(s, prim, light, scale, dc_near(s, prim, light), *out + 4 * i);
    }
    /* The cylinders' line test (rtpi_kd_occluder_planes) holds for rays
       with ts |d| <= T, T as the test's margins take it: T = 4 scale
       took every ray (|L - o| <= 2 sqrt(3) scale), and made the margins
       useless for a scene far from the origin (rings moved by 1e5: M
       past 29 R, none of 239,770 cylinders asked turned away).  Shadow
       rays leave hits, which lie in the kd-tree's box, moved off it by
       the float rounding of the hit and the offset (under 1e-6 of the
       scale, internal.h): T the light's greatest distance from the box
       (far, rtpi_kd_far) plus 1e-5 of the scale holds them all; a ray
       beyond T (none) would only not be asked. */
    far += 1e-5 * scale;
    for (i = 0; i < s->ncones; i++) {
        /* m = w x (L - b); M = R + 1e-12 (S' + S'^2 / R) + 1e-14 T with
           S' = 2 bound + 2 |mid - L| + 3.01 T; E = 1e-14 (|L - b| + M); T */
        const rtpi_cone_frame *cf = &s->cframes[i];
        double *q = *out + 4 * n + 6 * i;
        rtpi_v3 lb = v3_sub(light, cf->b), m = v3_cross(cf->w, lb);
        double T = far < 4.0 * scale ? far : 4.0 * scale, R = cf->rb,
               sp = 2.0 * cf->bound + 2.0 * v3_len(v3_sub(cf->mid, light)) + 3.01 * T;
        double M = R + 1e-12 * (sp + sp * (sp / R)) + 1e-14 * T;
        q[0] = q[1] = q[2] = q[3] = q[4] = q[5] = 0.0; /* (T 0: no test) */
        if (cf->ok && cf->ra == cf->rb && R > 0.0 && M < HUGE_VAL && T < HUGE_VAL &&
            m.x - m.x == 0.0 && m.y - m.y == 0.0 && m.z - m.z == 0.0) {
            q[0] = m.x;
            q[1] = m.y;
            q[2] = m.z;
            q[3] = M;
            q[4] = 1e-14 * (v3_len(lb) + M);
            q[5] = T;
        }
    }
    return RTP_OK;
}

/* -------------------------------------------------------- item buffer */

/* The ITEMBUF rule (rtpi_itembuf_visible; shadow.c adds the light
   buffers).  The shadow ray leaves o towards the light; its direction
   o - light lies in cell c.  The hit at p on prim
     1. is in shadow when prim itself must block the segment from o to
        the light (rtpi_prim_shadows_own: exact and cheap, never for a triangle; for a
        sphere by whether o and the light lie inside it; for a cone when o
        is outside its convex solid; the inside of a cone cannot tell, and
        prim is then tested like any other);
     2. sees the light when its direction falls on no cell at all (a face
        or a part of a window the scene does not reach);
     3. else looks at the 9 samples of c and its neighbours (across a cube
        edge on the next face), leaving out empty ones and prim itself
        where it cannot shadow itself, and thin primitives (decided
        exactly by shadow.c's light buffer; too narrow to hide a wide
        primitive from all 9 samples).  The shadow ray is intersected, by
        the kd-tree's own routine, with each primitive sampled there in
        front of p (depth below zp - B; one sampled at or
        beyond it is not tested: in a mesh those are mostly prim's
        neighbours, which the ray misses, and testing them cost more than
        the rest of the decision): a hit is in shadow, exactly.
        Otherwise, when no such sample lies clearly in front of p, it sees
        the light; when one does (a shadow edge: something in front,
        beside the ray), the answer is left open (-1) for an exact
        query.
   "Clearly in front": depth along the face axis zs < zp - (B + zp e
   tan(theta)), theta the angle between the surface normal and the
   light, e the sample's distance from the ray's direction in face
   coordinates (>= the angle between them), B the bias below.  On a plane
   tilted by theta depth changes by ~zp e tan(theta) over that angle:
   that term keeps the neighbours of prim in one mesh from counting;
   tan(theta) is capped at IB_TAN_MAX so that grazing surfaces still see
   real occluders.  B, IB_BIAS (1e-4) of p's depth beyond the nearest on
   the face (zp - zbase: not of the distance, so a far light keeps its
   precision, nor of the face's whole extent, so a far speck does not
   blur the rest), covers the float depths of the buffer; OSMesa's 24-bit
   ones take 1e-4 of the extent at least (zq).  The normal comes free:
   o - p is rtpi_offset_origin's step along the geometric normal, towards
   the light (~1e-9 relative error).
   What can still be wrong: "sees the light" where a wide primitive blocks
   the ray yet shows at none of the 9 samples in front of p while nothing
   else there lies in front of p: a part of it narrower than the samples'
   spacing (a sharp corner) reaches across the ray between them, or it
   blocks the ray just in front of p while sampled beside the ray at or
   behind p's depth (steep, touching p's surface: a contact shadow's edge,
   within a cell of the contact). */
#define IB_BIAS RTPI_IB_BIAS
#define IB_TAN_MAX 8.0

int rtpi_itembuf_renders(const rtp_scene *s, uint32_t prim, rtpi_v3 L)
{
    size_t i = prim;
    if (!dc_hittable(s, prim))
        return 0;
    if (i >= s->ntris && (i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        /* An inside-only sphere around the light never stops a shadow
           ray: rays from outside enter it unseen and reach the light
           before leaving it; rays from inside never leave it. */
        if (sp->r < 0.0f && v3_len(v3_sub(v3_from_f(sp->c), L)) < -(double)sp->r)
            return 0;
    }
    return 1;
}

/* The sample at window cell (i, j) of face f, where i or j may lie a cell
   outside the window: such samples are looked up by direction, on the
   neighbouring face across a cube edge, or as nothing beyond a window's
   edge (the window holds the whole scene).  @return its cell or
   RTPI_DC_ABSENT, *g its face. */
static size_t ib_sample(const rtpi_itembuf *ib, int f, int i, int j, int *g)
{
    int res = ib->res;
    if (i >= 0 && i < res && j >= 0 && j < res) {
        *g = f;
        return ib->w.fbase[f] + (size_t)j * (size_t)res + (size_t)i;
    }
    return rtpi_itembuf_cell(ib, rtpi_dc_world(f, ib->w.u0[f] + ib->w.du[f] * (i + 0.5),
                                               ib->w.v0[f] + ib->w.dv[f] * (j + 0.5), 1.0),
                             g);
}

/* tan of the angle between the normal o - p and the light at L, capped
   at IB_TAN_MAX (see the rule above). */
static double ib_tan(rtpi_v3 p, rtpi_v3 o, rtpi_v3 L)
{
    rtpi_v3 nv = v3_sub(o, p), l = v3_sub(L, p);
    double nl = v3_len(nv) * v3_len(l), cs = nl > 0.0 ? v3_dot(nv, l) / nl : 0.0, tn, s2;
    /* (fmax's by a comparison, not a libm call: s2 is never -0 nor,
       where taken, NaN) */
    s2 = 1.0 - cs * cs;
    tn = cs * IB_TAN_MAX > 1.0 ? sqrt(s2 > 0.0 ? s2 : 0.0) / cs : IB_TAN_MAX;
    return tn < IB_TAN_MAX ? tn : IB_TAN_MAX;
}

/* p's depth zp on face f and the depth zlim nothing at or beyond which is
   in front of p; @return the bias.  Float depths are kept to ~1e-7 of
   z - zbase, so the bias is IB_BIAS of that, not of the face's whole
   depth extent (one speck 1e5 away made it 10, more than the scene:
   every real occluder behind the bias, 37% of the pixels lit in shadow);
   OSMesa's depths carry their own quantum (zq). */
static double ib_zlim(const rtpi_itembuf *ib, int f, rtpi_v3 p, double *zp, double *zlim)
{
    return rtpi_itembuf_zlim(ib, f, &p, zp, zlim);
}

/* The decision from its first steps (at, st; rtpi_itembuf_pre): zmade 1
   where these made zlim (a direct query), 0 where it is to be made at
   the first sample that needs it. */
static RTPI_FORCE_INLINE int ib_rest(const rtpi_itembuf *ib, const rtp_scene *s,
                                     const rtpi_v3 *pp, const rtpi_v3 *op, uint32_t prim,
                                     int self, const rtpi_ray *r, uint32_t *occ,
                                     const rtpi_dc_at *at, const rtpi_ib_query *st, int zmade)
{
    const rtpi_v3 p = *pp, o = *op;
    int f = at->f, res = ib->res, i = st->i, j = st->j, di, dj, k, n = 0, m = 0, coarse = 0,
        nf = 0;
    uint32_t cand[9];
    double fz[9];          /* the direct pass's samples in front: depth */
    unsigned char fq[9];   /* and place, 3 (dj + 1) + di + 1 */
    double x = st->x, y = st->y, zp = st->zp, zlim = st->zlim, tn = -1.0;
    rtpi_ray rr;
    rtpi_hit h;
    lb_tri_ray w;
    /* (thin primitives are not drawn: no sample holds one) */
    if (st->direct) {
        /* The common case: float depths (never coarse) and the 9
           samples inside the window, on face f, read straight from its
           rows in the loop below's order, with its tests; zlim made at
           the first sample that needs it (or by rtpi_itembuf_pre, whose
           least depth found one in front).  Most queries meet only
           nothing or prim around p, answered lit by this one pass; on a
           mesh they meet its own triangles, at p's depth (a first pass
           for empty samples alone, then the loop below's with
           ib_sample's bounds again had cost mount 11% of an item-buffer
           move). */
        size_t c0 = ib->w.fbase[f] + (size_t)(j - 1) * (size_t)res + (size_t)(i - 1);
        const uint32_t *row = ib->id + c0, own = self == 0 ? prim : RTPI_NONE;
        const float *zr = ib->z + c0;
        const double zb = ib->w.zbase[f];
        /* Sample q (3 (dj + 1) + di + 1) of the rows from row and zr,
           written out for each of the 9 in the loop's order: as two
           loops, their counting and the sample's place were a tenth of
           an item-buffer move (gears).  (whether it lies clearly in
           front: after the candidates' tests, which a hit ends) */
#define IB_DIRECT(q, id_row, z_row)                                                              \
    do {                                                                                         \
        uint32_t id = (id_row)[(q) % 3];                                                         \
        double zc;                                                                               \
        if (id == RTPI_NONE || id == own)                                                        \
            break;                                                                               \
        if (!zmade) {                                                                            \
            (void)ib_zlim(ib, f, p, &zp, &zlim);                                                 \
            zmade = 1;                                                                           \
        }                                                                                        \
        if (!((zc = (z_row)[(q) % 3] + zb) < zlim))                                              \
            break;                                                                               \
        for (k = 0; k < n && cand[k] != id; k++)                                                 \
            ;                                                                                    \
        if (k == n)                                                                              \
            cand[n++] = id;                                                                      \
        fz[nf] = zc;                                                                             \
        fq[nf++] = (unsigned char)(q);                                                           \
    } while (0)
        IB_DIRECT(0, row, zr);
        IB_DIRECT(1, row, zr);
        IB_DIRECT(2, row, zr);
        row += res;
        zr += res;
        IB_DIRECT(3, row, zr);
        IB_DIRECT(4, row, zr);
        IB_DIRECT(5, row, zr);
        row += res;
        zr += res;
        IB_DIRECT(6, row, zr);
        IB_DIRECT(7, row, zr);
        IB_DIRECT(8, row, zr);
#undef IB_DIRECT
    } else {
        /* OSMesa's quantum far coarser than p's own bias (a face whose
           depth extent dwarfs p's depth in it: one speck far away): its
           depths cannot tell what lies in front of p, so every sample is
           tested and, none hitting, an exact query decides */
        coarse = ib->zq[f] > 100.0 * ib_zlim(ib, f, p, &zp, &zlim);
        for (dj = -1; dj <= 1; dj++) {
            for (di = -1; di <= 1; di++) {
                int g;
                size_t c = ib_sample(ib, f, i + di, j + dj, &g);
                uint32_t id;
                double zc = 0.0, ex, ey;
                if (c == RTPI_DC_ABSENT || (id = ib->id[c]) == RTPI_NONE ||
                    (id == prim && self == 0))
                    continue;
                if (g == f && !((zc = ib->z[c] + ib->w.zbase[g]) < zlim) && !coarse)
                    continue;
                for (k = 0; k < n && cand[k] != id; k++)
                    ;
                if (k == n)
                    cand[n++] = id;
                if (m)
                    continue;
                if (g != f) {
                    m = 1; /* a sample on another face: depths not comparable */
                    continue;
                }
                if (tn < 0.0)
                    tn = ib_tan(p, o, ib->light);
                ex = (i + di + 0.5 - x) * ib->w.du[f];
                ey = (j + dj + 0.5 - y) * ib->w.dv[f];
                m = zc < zlim - zp * sqrt(ex * ex + ey * ey) * tn;
            }
        }
    }
    if (!n)
        return 1;
    if (!r) {
        rr = rtpi_shadow_ray(o, ib->light);
        r = &rr;
    }
    w.made = -1;
    for (k = 0; k < n; k++)
        /* (an item buffer draws no zero-area triangle: rtpi_itembuf_renders) */
        if (cand[k] < s->ntris ? lb_tri_hit(s, cand[k], r, &w)
                               : rtpi_intersect_prim(s, cand[k], r, &h)) {
            *occ = cand[k];
            return 0;
        }
    /* The samples the direct pass found in front, in its order: is one
       clearly in front (the rule above)?  tn is at most IB_TAN_MAX and not
       negative, so where zp e >= 0 and the bound with IB_TAN_MAX holds
       it holds with tn (the roundings are monotonic), and tn (three roots
       and two divisions) need not be made. */
    for (k = 0; k < nf && !m; k++) {
        double ex, ey, ze;
        di = fq[k] % 3 - 1;
        dj = fq[k] / 3 - 1;
        ex = (i + di + 0.5 - x) * ib->w.du[f];
        ey = (j + dj + 0.5 - y) * ib->w.dv[f];
        ze = zp * sqrt(ex * ex + ey * ey);
        if (ze >= 0.0 && fz[k] < zlim - ze * IB_TAN_MAX) {
            m = 1;
            break;
        }
        if (tn < 0.0)
            tn = ib_tan(p, o, ib->light);
        m = fz[k] < zlim - ze * tn;
    }
    return m || coarse ? -1 : 1;
}

int rtpi_itembuf_visible(const rtpi_itembuf *ib, const rtp_scene *s,
                         const rtpi_v3 *pp, const rtpi_v3 *op, uint32_t prim, int self,
                         const rtpi_ray *r, uint32_t *occ, rtpi_dc_at *at)
{
    rtpi_ib_query q;
    if (self == 1) {
        *occ = prim;
        return 0;
    }
    if (rtpi_itembuf_pre(ib, pp, op, at, &q, 0) > 0)
        return 1;
    return ib_rest(ib, s, pp, op, prim, self, r, occ, at, &q, 0);
}

int rtpi_itembuf_visible_rest(const rtpi_itembuf *ib, const rtp_scene *s, const rtpi_v3 *pp,
                              const rtpi_v3 *op, uint32_t prim, int self, const rtpi_ray *r,
                              uint32_t *occ, const rtpi_dc_at *at, const rtpi_ib_query *q)
{
    return ib_rest(ib, s, pp, op, prim, self, r, occ, at, q, 1);
}

/* For triangle prim (q: its corners less L): every point of it lies
   within its least altitude h of its longest edge, and two points h
   apart, both d or more from L, are at most asin(h/d) apart in
   direction; so its projection lies within asin(h/d) of its longest
   edge's, d being the least distance from L (dc_near).  2 asin(h/d): an
   upper bound of its angular width across the edge (what it calls thin
   is thin), HUGE_VAL where h reaches d.  For a triangle with
   a corner 75 degrees or more off its centroid's direction, which had
   been wide whatever its width: a needle 3 long and 1e-7 wide passing
   0.3 under the light was drawn into the item buffer, slipped between
   its samples at every resolution, and the wall along its shadow was
   lit (degenerate.nff, light 0,0,0.5: 42 pixels 0.26 off at 64 to
   4096 cells). */
static double dc_band_width(const rtp_scene *s, uint32_t prim, const rtpi_v3 q[3], rtpi_v3 L)
{
    rtpi_v3 e0 = v3_sub(q[1], q[0]), e1 = v3_sub(q[2], q[1]), e2 = v3_sub(q[0], q[2]);
    double emax = fmax(v3_len(e0), fmax(v3_len(e1), v3_len(e2)));
    double h = emax > 0.0 ? v3_len(v3_cross(e0, e1)) / emax : 0.0, d = dc_near(s, prim, L);
    return h < d ? 2.0 * asin(h / d) : HUGE_VAL;
}

/* A lower bound, roughly, of the angle (radians) a primitive's
   projection from L spans across its narrowest direction; HUGE_VAL where
   it is large or the light is close to it.  A sphere: its angular
   diameter.  A cone: the diameter of its wider end seen from its far
   end (a pointed tip is thin like any corner; corners are left to the
   item buffer's neighbourhood test).  A triangle: the width of its
   gnomonic projection around its centroid's direction, where distances
   are at least the angles and about equal for a small triangle, or where
   that projection cannot be made, dc_band_width. */
static double dc_ang_width(const rtp_scene *s, uint32_t prim, rtpi_v3 L)
{
    size_t i = prim;
    if (i < s->ntris) {
        const rtpi_tri *t = &s->tris[i];
        rtpi_v3 q[3], w, e1, e2;
        double x[3], y[3], area, emax = 0.0;
        int k;
        for (k = 0; k < 3; k++)
            q[k] = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[k]), L);
        w = v3_add(q[0], v3_add(q[1], q[2]));
        if (!(v3_len(w) > 0.0))
            return dc_band_width(s, prim, q, L);
        w = v3_norm(w);
        dc_basis(w, &e1, &e2);
        for (k = 0; k < 3; k++) {
            double tk = v3_dot(q[k], w);
            /* a vertex 75 degrees or more off the centroid: no projection */
            if (!(tk > 0.25 * v3_len(q[k])))
                return dc_band_width(s, prim, q, L);
            x[k] = v3_dot(q[k], e1) / tk;
            y[k] = v3_dot(q[k], e2) / tk;
        }
        area = fabs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]));
        for (k = 0; k < 3; k++) {
            double ex = x[(k + 1) % 3] - x[k], ey = y[(k + 1) % 3] - y[k];
            emax = fmax(emax, sqrt(ex * ex + ey * ey));
        }
        return emax > 0.0 ? area / emax : 0.0;
    }
    if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        double D = v3_len(v3_sub(v3_from_f(sp->c), L)), r = fabs((double)sp->r);
        /* 0.99: within 8 degrees of filling half the sky, wide */
        return r < 0.99 * D ? 2.0 * asin(r / D) : HUGE_VAL;
    }
    if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone *cn = &s->cones[i];
        double r = fmax(fabs((double)cn->rb), fabs((double)cn->ra));
        double D = fmax(v3_len(v3_sub(v3_from_f(cn->base), L)),
                        v3_len(v3_sub(v3_from_f(cn->apex), L))) + r;
        return D > 0.0 ? 2.0 * r / D : HUGE_VAL;
    }
    return HUGE_VAL;
}

/* rtpi_itembuf_thin's primitives [IB_THIN_CHUNK chunk, + IB_THIN_CHUNK):
   each its own flag, so the same bytes on any threads. */
#define IB_THIN_CHUNK 4096
/* (threads from this many chunks a thread, 16k primitives, as lb_edges'
   LB_EDGE_THREADS 16k candidates: a second thread from ~0.8 ms of work.
   gears_s4's itembuf:512 move had ~1 ms of this serial, 2.2%) */
#define IB_THIN_THREADS 4

typedef struct ib_thin_job {
    const rtpi_itembuf *ib;
    const rtp_scene *s;
    double cells, cell;
    unsigned char *thin;
    size_t n;
} ib_thin_job;

static int ib_thin_chunk(void *ctx, int chunk)
{
    const ib_thin_job *jb = (const ib_thin_job *)ctx;
    const rtp_scene *s = jb->s;
    rtpi_v3 light = jb->ib->light;
    size_t i = (size_t)chunk * IB_THIN_CHUNK, i1 = i + IB_THIN_CHUNK;
    if (i1 > jb->n)
        i1 = jb->n;
    for (; i < i1; i++)
        jb->thin[i] = (unsigned char)(rtpi_itembuf_renders(s, (uint32_t)i, light) &&
                                      dc_ang_width(s, (uint32_t)i, light) < jb->cells * jb->cell);
    return 0;
}

/* rtpi_itembuf_thin on up to `threads` threads. */
static void ib_thin_mt(const rtpi_itembuf *ib, const rtp_scene *s, double cells,
                       unsigned char *thin, int threads)
{
    ib_thin_job jb;
    void *ctx[LB_MAX_THREADS];
    int f, k, nchunks, nt;
    jb.ib = ib;
    jb.s = s;
    jb.cells = cells;
    jb.cell = 0.0;
    jb.thin = thin;
    jb.n = rtpi_scene_nprims(s);
    for (f = 0; f < 6; f++)
        if (ib->w.fbase[f] != RTPI_DC_ABSENT)
            jb.cell = fmax(jb.cell, fmax(ib->w.du[f], ib->w.dv[f]));
    nchunks = (int)((jb.n + IB_THIN_CHUNK - 1) / IB_THIN_CHUNK);
    nt = lb_chunk_threads(threads, nchunks, IB_THIN_THREADS);
    for (k = 0; k < nt; k++)
        ctx[k] = &jb;
    rtpi_parallel_rows(nchunks, nt, ctx, ib_thin_chunk, NULL, NULL);
}

void rtpi_itembuf_thin(const rtpi_itembuf *ib, const rtp_scene *s, double cells,
                       unsigned char *thin)
{
    ib_thin_mt(ib, s, cells, thin, 1);
}

rtp_status rtpi_itembuf_alloc(rtpi_itembuf *ib, const rtp_scene *s,
                              rtpi_v3 light, int res, const rtp_allocator *a,
                              rtp_error *err)
{
    size_t ncells;
    int f;
    memset(ib, 0, sizeof *ib);
    if (res <= 0)
        res = RTPI_DC_DEFAULT_RES;
    if (!dc_res_ok(res))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "item buffer resolution %d outside 1..%d", res, RTPI_DC_MAX_RES);
    ib->res = res;
    ib->light = light;
    rtpi_dc_windows(s, light, res, 1.0, &ib->w);
    ncells = ib->w.ncells;
    /* A cell spans du x dv in face coordinates, no more radians; its
       centre is within half a diagonal of any of its directions; 1.25
       covers the sampling of clipped, rounded edges. */
    for (f = 0; f < 6; f++)
        ib->cell_angle[f] = 1.25 * 0.5 * sqrt(ib->w.du[f] * ib->w.du[f] + ib->w.dv[f] * ib->w.dv[f]);
    ib->id = (uint32_t *)rtpi_malloc_array(a, ncells ? ncells : 1, sizeof *ib->id);
    ib->z = (float *)rtpi_malloc_array(a, ncells ? ncells : 1, sizeof *ib->z);
    if (!ib->id || !ib->z) {
        rtpi_itembuf_free(ib, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the item buffer");
    }
    /* RTPI_NONE is all ones; an empty cell's depth is read only by
       rtpi_itembuf_pre's least of 9, which a huge one (bytes 0x7f:
       3.39e38) leaves to the drawn cells. */
    memset(ib->id, 0xff, ncells * sizeof *ib->id);
    memset(ib->z, 0x7f, ncells * sizeof *ib->z);
    return RTP_OK;
}

void rtpi_itembuf_free(rtpi_itembuf *ib, const rtp_allocator *a)
{
    if (!ib)
        return;
    rtpi_free(a, ib->id);
    rtpi_free(a, ib->z);
    ib->id = NULL;
    ib->z = NULL;
}

/* Drawing on several threads, each owns the rows j of every face with
   (j / IB_BAND) % nparts == part and draws every primitive into them in
   the same order one thread would: each cell sees the same stores in the
   same order, so the buffer is the same for any number of parts. */
#define IB_BAND 8

typedef struct ib_part {
    int part, nparts;
} ib_part;

static int ib_owns(const ib_part *pt, int j)
{
    return pt->nparts <= 1 || (j / IB_BAND) % pt->nparts == pt->part;
}

static void ib_store(rtpi_itembuf *ib, int f, size_t cell, double z, uint32_t prim)
{
    float zr = (float)(z - ib->w.zbase[f]);
    /* Ties keep the first (lower id): deterministic. */
    if (ib->id[cell] == RTPI_NONE || zr < ib->z[cell]) {
        ib->z[cell] = zr;
        ib->id[cell] = prim;
    }
}

/* Scan-converts a triangle onto face f: cells whose centres lie in its
   projection (edges inclusive, crossings computed from the lower end so
   neighbours agree: no cracks), depth from the plane, exact at the centre
   (1/z is linear in u, v: perspective-correct). */
static void ib_tri(rtpi_itembuf *ib, const rtp_scene *s, int f, uint32_t prim,
                   const ib_part *pt)
{
    const rtpi_tri *t = &s->tris[prim];
    int res = ib->res, k, j, j0, j1;
    dc_poly loc, cl;
    double uv[DC_MAXV][2], e1[3], e2[3], nn[3], kk, scale, vmin, vmax;
    double u0 = ib->w.u0[f], v0 = ib->w.v0[f], du = ib->w.du[f], dv = ib->w.dv[f];
    loc.n = 3;
    uv[0][0] = uv[0][1] = 0.0; /* (quiets a may-be-uninitialized warning) */
    for (k = 0; k < 3; k++) {
        double q[3];
        const float *pp = s->pos + 3 * (size_t)t->v[k];
        q[0] = pp[0] - ib->light.x;
        q[1] = pp[1] - ib->light.y;
        q[2] = pp[2] - ib->light.z;
        dc_local(f, q, loc.v[k]);
    }
    for (k = 0; k < 3; k++) {
        e1[k] = loc.v[1][k] - loc.v[0][k];
        e2[k] = loc.v[2][k] - loc.v[0][k];
    }
    nn[0] = e1[1] * e2[2] - e1[2] * e2[1];
    nn[1] = e1[2] * e2[0] - e1[0] * e2[2];
    nn[2] = e1[0] * e2[1] - e1[1] * e2[0];
    kk = nn[0] * loc.v[0][0] + nn[1] * loc.v[0][1] + nn[2] * loc.v[0][2];
    scale = sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]) *
            fmax(fabs(loc.v[0][0]), fmax(fabs(loc.v[0][1]), fabs(loc.v[0][2])));
    /* Plane through the light (to rounding): seen edge-on, covers no
       cell centre; 1e-12 is far above double rounding of kk. */
    if (!(fabs(kk) > 1e-12 * scale))
        return;
    /* 1e-9 wider than the face: centres are >= 1/res inside anyway. */
    if (dc_clip(&loc, &cl, 1.0 + 1e-9) <= 0 || !dc_project(&cl, uv))
        return;
    vmin = vmax = uv[0][1];
    for (k = 1; k < cl.n; k++) {
        vmin = uv[k][1] < vmin ? uv[k][1] : vmin;
        vmax = uv[k][1] > vmax ? uv[k][1] : vmax;
    }
    j0 = (int)fmax(-1.0, ceil((vmin - v0) / dv - 0.5));
    j1 = (int)fmin((double)res, floor((vmax - v0) / dv - 0.5));
    j0 = j0 < 0 ? 0 : j0;
    j1 = j1 > res - 1 ? res - 1 : j1;
    for (j = j0; j <= j1; j++) {
        double vc = v0 + dv * (j + 0.5), umin = DBL_MAX, umax = -DBL_MAX;
        int i, i0, i1;
        if (!ib_owns(pt, j))
            continue;
        for (k = 0; k < cl.n; k++) {
            const double *P = uv[k], *Q = uv[k + 1 < cl.n ? k + 1 : 0];
            const double *A = P[1] <= Q[1] ? P : Q, *B = P[1] <= Q[1] ? Q : P;
            double u;
            if (!(A[1] <= vc && vc <= B[1]))
                continue;
            if (A[1] == B[1]) {
                umin = fmin(umin, fmin(A[0], B[0]));
                umax = fmax(umax, fmax(A[0], B[0]));
                continue;
            }
            u = A[0] + (B[0] - A[0]) * ((vc - A[1]) / (B[1] - A[1]));
            umin = u < umin ? u : umin;
            umax = u > umax ? u : umax;
        }
        if (!(umin <= umax))
            continue;
        i0 = (int)fmax(-1.0, ceil((umin - u0) / du - 0.5));
        i1 = (int)fmin((double)res, floor((umax - u0) / du - 0.5));
        i0 = i0 < 0 ? 0 : i0;
        i1 = i1 > res - 1 ? res - 1 : i1;
        {
            /* Local point z (uc, vc, 1) on the plane nn.x = kk: z = 1/w,
               w = (nn0 uc + nn1 vc + nn2) / kk, with the row's part and
               nn0/kk taken once (one division a cell, not two: drawing a
               floor at 1024 cells a face edge divides millions of times) */
            const double wa = nn[0] / kk, wb = (nn[1] * vc + nn[2]) / kk;
            const size_t row = ib->w.fbase[f] + (size_t)j * res;
            for (i = i0; i <= i1; i++) {
                double w = wa * (u0 + du * (i + 0.5)) + wb;
                if (w > 0.0)
                    ib_store(ib, f, row + (size_t)i, 1.0 / w, prim);
            }
        }
    }
}

/* Depth along the ray L + t d (d's face-axis component is 1, so t is the
   depth) of a sphere's occluding surface, as rtpi_intersect_prim solves
   it (origin moved next to the centre first).  From outside: where the
   ray enters (an inside-only sphere too: a shadow ray from a point inside
   it leaves through there, and that counts); from inside (r > 0 only,
   see rtpi_itembuf_renders): where it leaves. */
static int ib_sphere_t(const rtpi_sphere *sp, rtpi_v3 L, rtpi_v3 d, int inside,
                       double *t)
{
    rtpi_v3 c = v3_from_f(sp->c), f, lv;
    double r = fabs((double)sp->r), a = v3_dot(d, d), tc, disc, half;
    tc = v3_dot(v3_sub(c, L), d) / a;
    f = v3_sub(v3_madd(L, d, tc), c);
    lv = v3_madd(f, d, -v3_dot(f, d) / a);
    disc = r * r - v3_dot(lv, lv);
    if (!(disc >= 0.0))
        return 0;
    half = sqrt(disc / a);
    /* (r > 0: a light on the surface, put outside by `inside` where it
       lies a rounding off, sees the ball's entry at itself, t within
       the set-up's rounding of 0 (~1e-16 of the ball's coordinates, not
       of its size) on either side; where not above 0 the ray is taken as
       from inside: its exit, where a shadow ray from beyond the ball
       enters.  rings_s1 scaled by 1e5, light 0 a double ulp over a ball
       35 radii from the origin: t -1.3e-11, the ball left out of those
       cells, the backdrop seen through it lit, 0.22 off) */
    *t = inside || (sp->r > 0.0f && !(tc - half > 0.0)) ? tc + half : tc - half;
    return *t > 0.0;
}

typedef struct ib_cast {
    rtpi_itembuf *ib;
    const rtp_scene *s;
    uint32_t prim;
    int sphere, inside;
    double near2; /* the square of dc_near's bound, less its roundings */
    const ib_part *pt;
    unsigned long long *casts;
} ib_cast;

/* Casts the ray through each cell's centre at a sphere or cone. */
static void ib_cast_run(void *user, size_t cell, int count)
{
    ib_cast *ic = (ib_cast *)user;
    rtpi_itembuf *ib = ic->ib;
    size_t res = (size_t)ib->res, rem;
    int f = 0, j, i0, i;
    while (f < 5 && (ib->w.fbase[f] == RTPI_DC_ABSENT || cell >= ib->w.fbase[f] + res * res))
        f++;
    rem = cell - ib->w.fbase[f];
    j = (int)(rem / res);
    i0 = (int)(rem % res);
    if (!ib_owns(ic->pt, j))
        return; /* (a run lies in one row) */
    double vc = ib->w.v0[f] + ib->w.dv[f] * (j + 0.5);
    *ic->casts += (unsigned long long)count;
    for (i = i0; i < i0 + count; i++) {
        rtpi_v3 d = rtpi_dc_world(f, ib->w.u0[f] + ib->w.du[f] * (i + 0.5), vc, 1.0);
        size_t cc = cell + (size_t)(i - i0);
        double t;
        if (ib->id[cc] != RTPI_NONE) {
            /* A hit at t along d (depth t: d's component along the face's
               axis is 1) lies t |d| from the light, at least dc_near's
               bound: where the cell holds a depth zs with zs |d| below
               that bound (less the roundings of either side: near2), no
               hit can be nearer and none is stored, so the ray is not
               cast (rings at 1024 cells: nine in ten of the cones' rays
               met a cell holding something nearer) */
            double zs = (double)ib->z[cc] + ib->w.zbase[f];
            if (zs >= 0.0 && zs * zs * v3_dot(d, d) < ic->near2)
                continue;
        }
        if (ic->sphere) {
            if (ib_sphere_t(&ic->s->spheres[ic->prim - ic->s->ntris], ib->light, d,
                            ic->inside, &t))
                ib_store(ib, f, cc, t, ic->prim);
        } else {
            rtpi_ray r;
            rtpi_hit h;
            r.o = ib->light;
            r.d = d;
            r.tmin = 0.0;
            r.tmax = ib->id[cc] == RTPI_NONE ? HUGE_VAL : (double)ib->z[cc] + ib->w.zbase[f];
            if (rtpi_intersect_prim(ic->s, ic->prim, &r, &h))
                ib_store(ib, f, cc, h.t, ic->prim);
        }
    }
}

/* Draws one primitive into the buffer (the part's rows). */
static void ib_draw(rtpi_itembuf *ib, const rtp_scene *s, dc_ctx *c, uint32_t prim,
                    const ib_part *pt)
{
    size_t i = prim;
    if (!rtpi_itembuf_renders(s, prim, ib->light))
        return;
    if (i < s->ntris) {
        const rtpi_tri *t = &s->tris[i];
        double q[3][3];
        int f, k, live;
        for (k = 0; k < 3; k++) {
            const float *pp = s->pos + 3 * (size_t)t->v[k];
            q[k][0] = pp[0] - ib->light.x;
            q[k][1] = pp[1] - ib->light.y;
            q[k][2] = pp[2] - ib->light.z;
        }
        /* (ib_tri's clipping frustum; a face the triangle cannot reach
           is not clipped against at all) */
        live = dc_faces_reached((const double(*)[3])q, 3, 1.0 + 1e-9);
        for (f = 0; f < 6; f++)
            if (ib->w.fbase[f] != RTPI_DC_ABSENT && ((live >> f) & 1))
                ib_tri(ib, s, f, prim, pt);
    } else {
        /* Round shapes exactly: a ray per cell within their bounds, a
           hair wider for rounding: the light buffer's widening (which
           lists a primitive in every cell any of whose rays can meet it),
           at most 1e-9 radians.  An absolute 1e-9 alone took every cell
           of a far light's window: balls_s2 from 2e9 spans 1e-9 radians,
           and its item buffer at 1024 cast a ray per cell for every
           sphere (5 s, against 0.03 s from 1e7). */
        double ang;
        ib_cast ic;
        if (c->S < 0.0)
            c->S = dc_scale(s, ib->light);
        double near = dc_near(s, prim, ib->light), lo[3], hi[3], ext;
        ang = fmin(1e-9, lb_ang(c->S, near));
        /* The cast's t and dc_near's bound both carry roundings of about
           1e-16 of the distances they are made of (|c - L| + r for a
           sphere: of the shape's size too, where the light is close to
           it): the bound is lowered by 1e-9 of near plus the shape's
           extent, far beyond them, and where that leaves nothing every
           ray is cast. */
        rtpi_prim_bounds_kept(s, prim, lo, hi);
        ext = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                   (hi[2] - lo[2]) * (hi[2] - lo[2]));
        near -= 1e-9 * (near + ext);
        ic.near2 = near > 0.0 ? near * near : 0.0;
        ic.ib = ib;
        ic.s = s;
        ic.prim = prim;
        ic.sphere = i < s->ntris + s->nspheres;
        ic.inside = ic.sphere &&
                    v3_len(v3_sub(v3_from_f(s->spheres[i - s->ntris].c), ib->light)) <=
                        fabs((double)s->spheres[i - s->ntris].r);
        ic.pt = pt;
        ic.casts = &c->casts;
        dc_cover(c, prim, ang, ib_cast_run, &ic);
    }
}

rtp_status rtpi_itembuf_draw(rtpi_itembuf *ib, const rtp_scene *s,
                             const uint32_t *prims, size_t n,
                             const rtp_allocator *a)
{
    dc_ctx c;
    size_t k;
    ib_part whole = {0, 1};
    if (!n)
        return RTP_OK;
    if (dc_ctx_init(&c, s, ib->light, ib->res, a) != RTP_OK)
        return RTP_ERR_NOMEM;
    dc_ctx_window(&c, &ib->w);
    for (k = 0; k < n; k++)
        ib_draw(ib, s, &c, prims[k], &whole);
    ib->casts += c.casts;
    dc_ctx_free(&c, a);
    return RTP_OK;
}

rtp_status rtpi_itembuf_build(const rtp_scene *s, rtpi_v3 light, int res,
                              const rtp_allocator *a, rtpi_itembuf *ib,
                              rtp_error *err)
{
    return rtpi_itembuf_build_wide(s, light, res, 0.0, NULL, a, ib, err);
}

rtp_status rtpi_itembuf_build_wide(const rtp_scene *s, rtpi_v3 light, int res,
                                   double cells, unsigned char *thin,
                                   const rtp_allocator *a, rtpi_itembuf *ib,
                                   rtp_error *err)
{
    return rtpi_itembuf_build_wide_mt(s, light, res, cells, thin, 1, NULL, a, ib, err);
}

typedef struct ib_job {
    rtpi_itembuf *ib;
    const rtp_scene *s;
    const unsigned char *thin;
    dc_ctx c;
    ib_part pt;
    rtpi_stopper *stp; /* the caller's progress and cancel */
    int is_main;       /* the calling thread's job (ctx[0]) */
    char pad[64]; /* the jobs lie side by side: no cache line shared */
} ib_job;

/* Primitives an item buffer's part draws between asking the caller's
   cancel (10,000 stacked quads at 2048 cells: 300 s a build). */
#define IB_POLL_PRIMS 256

/* One part: every primitive into the part's rows. */
static int ib_job_run(void *ctx, int part)
{
    ib_job *jb = (ib_job *)ctx;
    size_t n = rtpi_scene_nprims(jb->s), i;
    jb->pt.part = part;
    for (i = 0; i < n; i++) {
        if (i % IB_POLL_PRIMS == IB_POLL_PRIMS - 1 &&
            rtpi_stopper_poll(jb->stp, jb->is_main, (double)i / (double)n))
            return 1;
        if (!jb->thin || !jb->thin[i])
            ib_draw(jb->ib, jb->s, &jb->c, (uint32_t)i, &jb->pt);
    }
    return 0;
}

rtp_status rtpi_itembuf_build_wide_mt(const rtp_scene *s, rtpi_v3 light, int res, double cells,
                                      unsigned char *thin, int threads, const rtpi_poll *poll,
                                      const rtp_allocator *a, rtpi_itembuf *ib, rtp_error *err)
{
    rtpi_stopper stp;
    /* (the jobs on the heap: 256 of them on the stack were a 1.1 MB
       frame, more than a host's thread may have) */
    ib_job *jobs;
    void **ctx;
    int k, nparts = threads < 1 ? 1 : threads > RTPI_MAX_THREADS ? RTPI_MAX_THREADS : threads;
    rtp_status st = rtpi_itembuf_alloc(ib, s, light, res, a, err);
    if (st != RTP_OK)
        return st;
    /* no more parts than bands of rows */
    if (nparts > (ib->res + IB_BAND - 1) / IB_BAND)
        nparts = (ib->res + IB_BAND - 1) / IB_BAND;
    /* (the item buffer's drawing: the first 0.8 of its build's progress,
       the thin primitives' light buffers the rest) */
    if (rtpi_stopper_init(&stp, poll, 0.0, 0.8) != 0) {
        rtpi_itembuf_free(ib, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the item buffer");
    }
    jobs = (ib_job *)rtpi_malloc_array(a, (size_t)nparts, sizeof *jobs);
    ctx = (void **)rtpi_malloc_array(a, (size_t)nparts, sizeof *ctx);
    for (k = 0; k < nparts; k++) {
        if (!jobs || !ctx || dc_ctx_init(&jobs[k].c, s, light, ib->res, a) != RTP_OK) {
            while (jobs && k-- > 0)
                dc_ctx_free(&jobs[k].c, a);
            rtpi_free(a, jobs);
            rtpi_free(a, ctx);
            rtpi_itembuf_free(ib, a);
            rtpi_stopper_destroy(&stp);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                              "out of memory for the item buffer");
        }
        dc_ctx_window(&jobs[k].c, &ib->w);
        jobs[k].ib = ib;
        jobs[k].s = s;
        jobs[k].thin = thin;
        jobs[k].stp = &stp;
        jobs[k].is_main = k == 0; /* (ctx[0]: the calling thread's) */
        jobs[k].pt.part = k;
        jobs[k].pt.nparts = nparts;
        ctx[k] = &jobs[k];
    }
    if (thin)
        ib_thin_mt(ib, s, cells, thin, threads);
    /* (rtpi_parallel_rows hands part k to some thread: each job keeps
       its own context and scratch, and any thread may run any part) */
    rtpi_parallel_rows(nparts, nparts, ctx, ib_job_run, NULL, NULL);
    for (k = 0; k < nparts; k++) {
        ib->casts += jobs[k].c.casts;
        dc_ctx_free(&jobs[k].c, a);
    }
    rtpi_free(a, jobs);
    rtpi_free(a, ctx);
    rtpi_stopper_destroy(&stp);
    if (stp.stop) {
        rtpi_itembuf_free(ib, a);
        return rtpi_cancelled(err);
    }
    return RTP_OK;
}
