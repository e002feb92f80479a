/*
 * dircube.h — direction cubes around a point light (the paper's 4.1-4.3),
 * shared by shadow.c, osmesa.c and the tests.
 *
 * A direction q (from the light) belongs to face f = 2*a + (q[a] < 0) of
 * the axis a where |q[a]| is largest (ties go to the lower axis).  On face
 * f the local coordinates of q are x = q[(a+1)%3], y = q[(a+2)%3],
 * z = +-q[a] (z > 0: the depth along the face's axis), and the face
 * coordinates u = x/z, v = y/z run over [-1, 1].  Cell (i, j) of a face
 * with res cells per edge covers u in [-1 + 2i/res, -1 + 2(i+1)/res] and v
 * likewise with j; its index in a cube's arrays is (f*res + j)*res + i.
 * OpenGL's viewport with the same face frame puts pixel (i, j) at the same
 * place, so the OSMesa backend fills the very same layout.
 *
 * Two structures live on the cube:
 *  - the light buffer: per cell the primitives whose conservative
 *    projection touches it, in ascending order of a lower bound of their
 *    distance from the light; a shadow ray is tested against its cell's
 *    list only, with the same intersection routine the kd-tree uses, so
 *    the answer equals the kd-tree's;
 *  - the item buffer: per cell the nearest occluding primitive along the
 *    ray through the cell's centre, and its depth z.  Its decisions
 *    intersect the shadow ray with the primitives sampled around it and
 *    leave shadow edges open (see dircube.c); shadow.c completes them
 *    with light buffers.
 * Both are immutable once built: queries may run on many threads.
 */
#ifndef RTP_DIRCUBE_H
#define RTP_DIRCUBE_H

#include "internal.h"

#define RTPI_DC_DEFAULT_RES 512
#define RTPI_DC_MAX_RES RTP_MAX_SHADOW_RES

/* The cell index along one face edge for face coordinate u; NaN and
   values outside [-1, 1] are clamped to the edge cells. */
static inline int rtpi_dc_coord(double u, int res)
{
    double x = (u + 1.0) * 0.5 * (double)res;
    if (!(x > 0.0))
        return 0;
    if (!(x < (double)res))
        return res - 1;
    return (int)x;
}

/* The face of direction d (from the light; any length) and its face
   coordinates there. */
static inline int rtpi_dc_face(rtpi_v3 d, double *u, double *v)
{
    double c[3];
    double ax, ay, az, m, inv;
    int a;
    c[0] = d.x;
    c[1] = d.y;
    c[2] = d.z;
    ax = fabs(c[0]);
    ay = fabs(c[1]);
    az = fabs(c[2]);
    a = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    m = fabs(c[a]);
    /* |c[other]| <= m, so u and v land in [-1, 1] exactly: a direction on
       a cube edge or corner maps to this face's edge cell. */
    inv = m > 0.0 ? 1.0 / m : 0.0;
    /* (the other two axes in order a+1, a+2 mod 3, without the modulo) */
    *u = (a == 0 ? c[1] : a == 1 ? c[2] : c[0]) * inv;
    *v = (a == 0 ? c[2] : a == 1 ? c[0] : c[1]) * inv;
    return 2 * a + (c[a] < 0.0);
}

/* Seen from a light outside the scene's bounds, the scene covers a part
   of each face only: a cube may spread its res x res cells of face f over
   a window [u0, u0 + res du] x [v0, v0 + res dv] that holds the
   projection of the bounds (the whole face when the light is inside
   them), so that a far light still sees the scene through many cells.
   Cell (i, j) of face f then spans u0 + [i, i+1] du, v0 + [j, j+1] dv.
   zbase and zext: the nearest depth of the bounds on the face and their
   depth extent there.  A face the scene does not reach has no cells at
   all (fbase (size_t)-1): a light above a scene keeps one to five faces.
   The cells of face f are fbase[f] + j res + i. */
typedef struct rtpi_dc_window {
    double u0[6], v0[6], du[6], dv[6];
    double zbase[6], zext[6];
    size_t fbase[6];
    size_t ncells;
} rtpi_dc_window;

#define RTPI_DC_ABSENT ((size_t)-1)

/* Sets w for a cube of res cells around light L over the scene s, with
   the faces' frusta widened to |u|, |v| <= lim when projecting. */
void rtpi_dc_windows(const rtp_scene *s, rtpi_v3 L, int res, double lim,
                     rtpi_dc_window *w);

/* The cell along a window's edge holding coordinate x; outside values and
   NaN are clamped to the edge cells.  The one mapping both the filling of
   cells and the queries use (but the light buffer's queries, whose cell
   may differ from it by roundings its lists' widening covers: dircube.c
   lb_cell). */
static inline int rtpi_dc_wcoord(double x, double x0, double dx, int res)
{
    double t = (x - x0) / dx;
    if (!(t > 0.0))
        return 0;
    if (!(t < (double)res))
        return res - 1;
    return (int)t;
}

/* A direction's face and coordinates on it (rtpi_dc_face): made once,
   they serve every cube of the same light (rtpi_dc_wcell_at). */
typedef struct rtpi_dc_at {
    int f;
    double u, v;
} rtpi_dc_at;

/* The cell at a in windows w, or RTPI_DC_ABSENT on a face without
   cells. */
static inline size_t rtpi_dc_wcell_at(const rtpi_dc_window *w, int res, const rtpi_dc_at *a)
{
    int f = a->f, i, j;
    if (w->fbase[f] == RTPI_DC_ABSENT)
        return RTPI_DC_ABSENT;
    i = rtpi_dc_wcoord(a->u, w->u0[f], w->du[f], res);
    j = rtpi_dc_wcoord(a->v, w->v0[f], w->dv[f], res);
    return w->fbase[f] + (size_t)j * (size_t)res + (size_t)i;
}

/* The cell of direction d (from the light; any length) in windows w, or
   RTPI_DC_ABSENT on a face without cells. */
static inline size_t rtpi_dc_wcell(const rtpi_dc_window *w, int res, rtpi_v3 d)
{
    rtpi_dc_at a;
    a.f = rtpi_dc_face(d, &a.u, &a.v);
    return rtpi_dc_wcell_at(w, res, &a);
}

/* The cell of direction d (from the light; any length) on a cube of full
   faces. */
static inline size_t rtpi_dc_cell(int res, rtpi_v3 d)
{
    double u, v;
    int f = rtpi_dc_face(d, &u, &v);
    int i = rtpi_dc_coord(u, res), j = rtpi_dc_coord(v, res);
    return ((size_t)f * (size_t)res + (size_t)j) * (size_t)res + (size_t)i;
}

/* Depth of q (from the light) along the axis of face f. */
static inline double rtpi_dc_depth(int f, rtpi_v3 q)
{
    double z = v3_get(q, f >> 1);
    return (f & 1) ? -z : z;
}

/* World direction of local (x, y, z) on face f. */
static inline rtpi_v3 rtpi_dc_world(int f, double x, double y, double z)
{
    double c[3];
    int a = f >> 1;
    c[(a + 1) % 3] = x;
    c[(a + 2) % 3] = y;
    c[a] = (f & 1) ? -z : z;
    return v3(c[0], c[1], c[2]);
}

/* ------------------------------------------------------- light buffer */

typedef struct rtpi_lb_cand {
    double near;   /* lower bound of the primitive's distance from the light */
    uint32_t prim;
} rtpi_lb_cand;

/* A candidate's cone entry (lb_cone), with its near and prim beside it:
   the round walk's scan reads the three from one record of a rank
   rather than from cand's and the cone's (the second record's address,
   three instructions an entry), and the walk's tests after the scan take
   prim from there too (cand[rank] loaded there instead was a cache line
   more a passing entry: balls' moves 2% slower in time).  `skip` is prim
   again, in the record's padding: the scan compares it with the query's
   own primitive in one instruction, where with prim itself, wanted after
   the scan, gcc kept the load in a register (an instruction more an
   entry: balls 191.73 -> 192.69 M). */
typedef struct rtpi_lb_cone {
    double v[4];   /* the axis, and the bound below its cosine */
    double near;   /* cand's */
    uint32_t prim; /* cand's */
    uint32_t skip; /* prim again (the scan's) */
} rtpi_lb_cone;

typedef struct rtpi_lightbuf {
    int res;
    rtpi_v3 light;
    rtpi_dc_window w;
    double slack;        /* absolute slack of the early stop (see build) */
    uint32_t *off;       /* w.ncells + 1 list starts into ref */
    uint32_t *ref;       /* candidate ranks, ascending within a cell */
    rtpi_lb_cand *cand;  /* by rank: ascending near */
    /* by rank, 5 each, where the scene has triangles: a triangle's plane
       n (unnormalised, turned to the light's side), n.p0, and t:
       HUGE_VAL (no test), or the light lies farther than t from the
       plane, t the distance (times |n|) at which a shadow ray's origin
       on the light's side too (n.o - n.p0 > t) lets the segment miss it
       (lb_plane_turned) */
    double *plane;
    /* by rank, where spheres and cones are at least a sixteenth of the
       scene's primitives (NULL elsewhere): in v the unit direction from
       the light to the centre of a ball holding the candidate, and a
       bound below the cosine of the widest angle between that direction
       and a ray that can hit it (-2: no bound; a triangle's 0 0 0 -2): a
       ray whose direction's cosine falls below misses it (see lb_cone);
       near and prim as cand's, skip a copy of prim (rtpi_lb_cone) */
    rtpi_lb_cone *cone;
    /* by rank, 4 each, where made (NULL: none; a speed-up only, made
       where the buffer has cone entries and cones, and its memory fits
       within the build's limit): a cone's unit normal q of the plane
       through the light and its axis, and a bound q[3] above |q.d| for
       every direction d a ray that can hit it has (2, no bound, for
       other candidates): a ray whose direction's |q.d| passes it misses
       the cone (see lb_slabs) */
    double *slab;
    uint32_t *cone_rank; /* with slab: cone i's rank (RTPI_NONE: not a
                            candidate), for a query's cached cone */
    /* by rank, RTPI_EDGE_N each, where made (NULL: none; a speed-up only,
       made where its memory fits within the build's limit): a triangle's
       rtpi_tri_edges entry (its plane as rtpi_tri_planes makes it, and
       the planes through the light and each edge), which the walk asks
       in place of its plane entry (rtpi_edges_miss, margin ethr =
       RTPI_EDGE_MARGIN scale^3); other primitives' entries never turn a
       ray away (0, and HUGE_VAL for the plane's bound) */
    double *edge;
    double ethr;
    uint32_t *rank_of;   /* with edge: each triangle's rank (RTPI_NONE: none) */
    double scale;        /* the scene's and light's largest |coordinate| */
    double ru[6], rv[6]; /* 1 / w.du, 1 / w.dv: a query's cell (lb_cell) */
    double top;          /* res - 1: the last cell's i and j */
    /* bytes the build's limit leaves once the lists and the speed-ups
       above are made (HUGE_VAL: no limit), for the light buffer's shadow
       query's own numbers (shadow.c, sh_lb_quadrics) */
    double room;
    size_t nrefs, ncand;
} rtpi_lightbuf;

rtp_status rtpi_lightbuf_build(const rtp_scene *s, rtpi_v3 light, int res,
                               const rtp_allocator *a, rtpi_lightbuf *lb,
                               rtp_error *err);
/* The cells a face edge a light buffer for a light at `light` would have
   when asked for res: fewer where the light is so far that the scene lies
   within a few of the lists' widenings (lb_res in dircube.c), and such a
   buffer lists most primitives in every cell: RTP_SHADOWS_AUTO then
   takes shadow rays. */
int rtpi_lightbuf_res(const rtp_scene *s, rtpi_v3 light, int res);

/* The same over the primitives i with sel[i] == want only (sel NULL:
   all): its answers are the kd-tree's over those primitives.  Projects
   the primitives on up to `threads` threads (the same buffer for any
   number; a's calls are then serialised by a lock).  limit: bytes the
   buffer may take, its lists counted before they are made (HUGE_VAL:
   none): past it RTP_ERR_LIMIT, as past max_entries list entries
   (HUGE_VAL: none; RTP_SHADOWS_AUTO's bound, tree.c auto_lb_entries).
   poll (NULL: none): the build's progress,
   and its cancel asked between parts of it (RTP_ERR_CANCELLED). */
rtp_status rtpi_lightbuf_build_some(const rtp_scene *s, rtpi_v3 light, int res,
                                    const unsigned char *sel, unsigned char want, int threads,
                                    double limit, double max_entries, const rtpi_poll *poll,
                                    const rtp_allocator *a,
                                    rtpi_lightbuf *lb, rtp_error *err);
/* The same, told the shadow queries the buffer is expected to answer
   (HUGE_VAL: unknown, many): where they are few against the triangles,
   each triangle is listed by its box rather than its exact cells
   (dircube.c LB_BOX_QUERIES): a cheaper build, longer lists, the same
   answers. */
rtp_status rtpi_lightbuf_build_q(const rtp_scene *s, rtpi_v3 light, int res,
                                 const unsigned char *sel, unsigned char want, int threads,
                                 double limit, double max_entries, double queries,
                                 const rtpi_poll *poll, const rtp_allocator *a,
                                 rtpi_lightbuf *lb, rtp_error *err);
/* 1 when no candidate of ray's cell hits ray in [tmin, tmax]; ray must run
   towards the light (rtpi_shadow_ray(o, lb->light): the cell is that of
   its origin seen from lb->light). */
int rtpi_lightbuf_visible(const rtpi_lightbuf *lb, const rtp_scene *s,
                          const rtpi_ray *ray);
/* The first candidate found in the ray's way, or RTPI_NONE; candidate
   skip (RTPI_NONE: none) is not asked, the caller knowing it cannot be
   in the way (rtpi_prim_shadows_own). */
uint32_t rtpi_lightbuf_occluder(const rtpi_lightbuf *lb, const rtp_scene *s,
                                const rtpi_ray *ray, uint32_t skip);
/* The same, with primitive `first` (RTPI_NONE: none; not skip) asked
   before the cell's list: a hit of it is returned as rtpi_intersect_prim
   would find it, and a triangle's test shares the watertight set-up the
   list's walk makes (a shadow query's last occluder, rtpi_shadow_cache).
   A triangle `first` must be hittable (rtpi_prim_hittable: not of zero
   area), as every occluder a light buffer answers is (its lists hold no
   other): it is asked without that test, as the lists' triangles are.
   (callgrind, lightbuf:256, third move, 512^2 SPD: gears 305.4 ->
   304.2 M without it, 141 k queries asking a first; teapot 189.7 ->
   189.3.) */
uint32_t rtpi_lightbuf_occluder_first(const rtpi_lightbuf *lb, const rtp_scene *s,
                                      const rtpi_ray *ray, uint32_t skip, uint32_t first);
/* The functions the two above choose between for lb (by its entries, as
   built): a caller asking one buffer many times calls them itself (the
   choice's loads and branches, 5 instructions a query, were 0.5% of
   mount_s6's lightbuf:256 move). */
typedef uint32_t (*rtpi_lb_occ_fn)(const rtpi_lightbuf *lb, const rtp_scene *s,
                                   const rtpi_ray *ray, uint32_t skip);
rtpi_lb_occ_fn rtpi_lightbuf_occ_fn(const rtpi_lightbuf *lb);
/* A shadow query from origin o whole: rtpi_lightbuf_occluder_first's
   answer for the ray rtpi_shadow_ray(*o, lb->light), which is made only
   where a test asks for it (most queries on meshes reach none: the cell,
   the planes, the edges and the early stop take o and the ray's tmax
   alone), with *last set to the occluder found + 1 (0: none, as
   rtpi_shadow_cache.last); 1 where lit.  One call a query: the shadow
   query's steps end in it with a jump (shadow.c sh_cached_lb_body). */
typedef int (*rtpi_lb_vis_fn)(const rtpi_lightbuf *lb, const rtp_scene *s, const rtpi_v3 *o,
                              uint32_t skip, uint32_t first, uint32_t *last);
rtpi_lb_vis_fn rtpi_lightbuf_vis_fn(const rtpi_lightbuf *lb);

void rtpi_lightbuf_free(rtpi_lightbuf *lb, const rtp_allocator *a);

/* The light buffer's plane test (rtpi_lightbuf.plane) for every
   triangle of s and a light at `light`, by primitive, 4 doubles each: n
   and m, where n.o > m for a shadow ray's origin o (within *scale on
   every axis: the scene's and light's largest |coordinate|, as
   rtpi_lightbuf.scale) says that o and the light lie on one side of the
   triangle's plane, each farther from it than the watertight test's
   rounding could bridge: the ray misses the triangle (n = 0, m = inf
   where that cannot be told).  For shadow rays through the kd-tree
   (rtpi_kd_occluder_planes).  *out NULL where s has no triangles. */
rtp_status rtpi_tri_planes(const rtp_scene *s, rtpi_v3 light, const rtp_allocator *a,
                           double **out, double *scale, rtp_error *err);
/* The light buffer's cone test (rtpi_lightbuf.cone) for every sphere and
   cone of s (primitive ntris + i: entry i, 4 doubles) and a light at
   `light`, scale as rtpi_tri_planes gives it: a shadow ray whose
   direction d has -d.c < c[3] with the entry's c misses the primitive.
   The 4 (nspheres + ncones) doubles are followed by 6 for each cone i
   (cframes[i]): a cylinder's line test for shadow rays towards the light
   (rtpi_kd_occluder_planes: m = w x (light - b), its margins M and E,
   and the longest ray T it holds for, from `far`, rtpi_kd_far of the
   light; T = 0 where there is no test).  *out NULL where s has none. */
rtp_status rtpi_round_cones(const rtp_scene *s, rtpi_v3 light, double scale, double far,
                            const rtp_allocator *a, double **out, rtp_error *err);

/* -------------------------------------------------------- item buffer */

/* The item buffer's cells sample the ray through their centres,
   u0 + (i + 1/2) du, v0 + (j + 1/2) dv; OpenGL draws the same windows
   with glFrustum. */
typedef struct rtpi_itembuf {
    int res;
    rtpi_v3 light;
    rtpi_dc_window w;
    double cell_angle[6]; /* bound of the angle between a direction and
                             the centre of its cell, radians */
    uint32_t *id;         /* nearest occluder per cell, RTPI_NONE: none */
    float *z;             /* its depth along the face axis minus w.zbase
                             (unset where id is RTPI_NONE):
                             float keeps ~1e-7 of the scene's extent, not
                             of the distance from a far light */
    unsigned long long casts; /* rays cast at round shapes while drawing
                                 (their cells' centres): the build's work */
    double zq[6];         /* per face: the depths' quantum where it is one
                             for the whole face (OSMesa's 24-bit buffer:
                             IB_BIAS of the extent); 0: float depths,
                             whose error is relative to z - w.zbase */
} rtpi_itembuf;

/* The cell of direction d (from the light) and its face, or
   RTPI_DC_ABSENT when d points at a face without cells or outside its
   window by more than a cell (nothing drawn there). */
static inline size_t rtpi_itembuf_cell(const rtpi_itembuf *ib, rtpi_v3 d, int *face)
{
    double u, v, x, y;
    int f = rtpi_dc_face(d, &u, &v), res = ib->res, i, j;
    *face = f;
    if (ib->w.fbase[f] == RTPI_DC_ABSENT)
        return RTPI_DC_ABSENT;
    x = (u - ib->w.u0[f]) / ib->w.du[f];
    y = (v - ib->w.v0[f]) / ib->w.dv[f];
    if (!(x > -1.0 && x < res + 1.0 && y > -1.0 && y < res + 1.0))
        return RTPI_DC_ABSENT;
    i = x < 0.0 ? 0 : x >= res ? res - 1 : (int)x;
    j = y < 0.0 ? 0 : y >= res ? res - 1 : (int)y;
    return ib->w.fbase[f] + (size_t)j * (size_t)res + (size_t)i;
}

/* The software scanline z-buffer. */
rtp_status rtpi_itembuf_build(const rtp_scene *s, rtpi_v3 light, int res,
                              const rtp_allocator *a, rtpi_itembuf *ib,
                              rtp_error *err);
/* The same over the wide primitives only: thin (one per primitive) is
   set by rtpi_itembuf_thin(ib, s, cells, thin) once the windows are
   known, and the primitives it marks are left out of the buffer (the
   caller decides them otherwise; they would only hide wide ones).  thin
   NULL: every primitive, as rtpi_itembuf_build. */
rtp_status rtpi_itembuf_build_wide(const rtp_scene *s, rtpi_v3 light, int res,
                                   double cells, unsigned char *thin,
                                   const rtp_allocator *a, rtpi_itembuf *ib,
                                   rtp_error *err);
/* The same drawn on up to `threads` threads (the same buffer for any
   number; a's functions are called from the calling thread only). */
rtp_status rtpi_itembuf_build_wide_mt(const rtp_scene *s, rtpi_v3 light, int res, double cells,
                                      unsigned char *thin, int threads, const rtpi_poll *poll,
                                      const rtp_allocator *a, rtpi_itembuf *ib, rtp_error *err);
/* The same buffers drawn by OSMesa (osmesa.c); RTP_ERR_UNSUPPORTED in
   builds without it. */
rtp_status rtpi_itembuf_build_osmesa(const rtp_scene *s, rtpi_v3 light,
                                     int res, const rtp_allocator *a,
                                     rtpi_itembuf *ib, rtp_error *err);
rtp_status rtpi_itembuf_build_osmesa_wide(const rtp_scene *s, rtpi_v3 light, int res,
                                          double cells, unsigned char *thin,
                                          const rtp_allocator *a, rtpi_itembuf *ib,
                                          rtp_error *err);
/* Draws the listed primitives into ib with the software z-buffer, over
   what is there (osmesa.c: primitives too close to the light for
   OpenGL's near plane).  @return RTP_OK or RTP_ERR_NOMEM. */
rtp_status rtpi_itembuf_draw(rtpi_itembuf *ib, const rtp_scene *s,
                             const uint32_t *prims, size_t n,
                             const rtp_allocator *a);
/* Allocates the arrays, all cells empty, and sets the faces' windows
   from the bounds of s (used by both builders). */
rtp_status rtpi_itembuf_alloc(rtpi_itembuf *ib, const rtp_scene *s,
                              rtpi_v3 light, int res, const rtp_allocator *a,
                              rtp_error *err);
/* The item buffer's depth bias (dircube.c's rule: IB_BIAS). */
#define RTPI_IB_BIAS 1e-4

/* p's depth zp on face f and the depth zlim nothing at or beyond which
   is in front of p (see dircube.c, ib_zlim); @return the bias. */
static inline double rtpi_itembuf_zlim(const rtpi_itembuf *ib, int f, const rtpi_v3 *pp,
                                       double *zp, double *zlim)
{
    double bias;
    *zp = rtpi_dc_depth(f, v3_sub(*pp, ib->light));
    bias = RTPI_IB_BIAS * fabs(*zp - ib->w.zbase[f]);
    /* (fmax(zq, bias) by a comparison, not a libm call a query: bias is
       not negative, a NaN one gives zq as fmax does) */
    *zlim = *zp - (bias > ib->zq[f] ? bias : ib->zq[f]);
    return bias;
}

/* What a query's first steps found (rtpi_itembuf_pre): the cell (i, j)
   of at's face holding the direction at window coordinates (x, y), and
   where `direct` (float depths, the 9 samples inside the window) p's
   depth and its zlim. */
typedef struct rtpi_ib_query {
    double x, y, zp, zlim;
    int i, j, direct;
} rtpi_ib_query;

/* The item-buffer decision's first steps, inline in its caller: sets
   *at as rtpi_itembuf_visible does and @return 1 where that would answer
   1 for want of cells there, with `least` 2 where it would answer 1
   because none of the 9 samples' depths lies in front of p's zlim (an
   empty cell's depth is the huge one rtpi_itembuf_alloc gives it: it
   only makes the least smaller, and a least in front leaves the answer
   to the full pass), else -1 with *q for rtpi_itembuf_visible_rest. */
static RTPI_FORCE_INLINE int rtpi_itembuf_pre(const rtpi_itembuf *ib, const rtpi_v3 *pp,
                                              const rtpi_v3 *op, rtpi_dc_at *at,
                                              rtpi_ib_query *q, int least)
{
    double u, v, x, y;
    int f = rtpi_dc_face(v3_sub(*op, ib->light), &u, &v), res = ib->res, i, j;
    at->f = f;
    at->u = u;
    at->v = v;
    if (ib->w.fbase[f] == RTPI_DC_ABSENT)
        return 1;
    x = (u - ib->w.u0[f]) / ib->w.du[f];
    y = (v - ib->w.v0[f]) / ib->w.dv[f];
    if (!(x > -1.0 && x < res + 1.0 && y > -1.0 && y < res + 1.0))
        return 1;
    i = x < 0.0 ? 0 : x >= res ? res - 1 : (int)x;
    j = y < 0.0 ? 0 : y >= res ? res - 1 : (int)y;
    q->x = x;
    q->y = y;
    q->i = i;
    q->j = j;
    q->zp = q->zlim = 0.0;
    q->direct = ib->zq[f] == 0.0 && i > 0 && j > 0 && i < res - 1 && j < res - 1;
    if (q->direct && least) {
        const float *z = ib->z + ib->w.fbase[f] + (size_t)(j - 1) * (size_t)res + (size_t)(i - 1);
        float m = HUGE_VALF;
        /* The least of the 9 depths, a NaN one (never in front) left out:
           z + zbase rounds monotonically in z, so no sample's sum lies
           below the least's. */
#define IB_PRE_MIN(k) m = z[k] < m ? z[k] : m
        IB_PRE_MIN(0);
        IB_PRE_MIN(1);
        IB_PRE_MIN(2);
        z += res;
        IB_PRE_MIN(0);
        IB_PRE_MIN(1);
        IB_PRE_MIN(2);
        z += res;
        IB_PRE_MIN(0);
        IB_PRE_MIN(1);
        IB_PRE_MIN(2);
#undef IB_PRE_MIN
        (void)rtpi_itembuf_zlim(ib, f, pp, &q->zp, &q->zlim);
        if (!(m + ib->w.zbase[f] < q->zlim))
            return 2;
    }
    return -1;
}

/* The rest of the decision after rtpi_itembuf_pre answered -1 (its *at
   and *q): as rtpi_itembuf_visible.  Only after a call with `least` 1:
   it takes q's zlim as made for a direct query, which with `least` 0 is
   left 0 (depths are positive: no sample would lie in front, every
   such query answered lit, occluders or not). */
int rtpi_itembuf_visible_rest(const rtpi_itembuf *ib, const rtp_scene *s, const rtpi_v3 *pp,
                              const rtpi_v3 *op, uint32_t prim, int self, const rtpi_ray *r,
                              uint32_t *occ, const rtpi_dc_at *at, const rtpi_ib_query *q);

/* The item-buffer decision for the hit at p on prim with shadow-ray
   origin o (see dircube.c for the rule): 1 lit, 0 in shadow (then
   certain), -1 open (something lies in front near the ray: ask an exact
   query).  The thin primitives of rtpi_itembuf_build_wide (the caller
   decides those itself) are not drawn, so never intersected here.  self: rtpi_prim_shadows_own(s, prim, o, light), which the caller needs
   too.  r (NULL: made here when needed): rtpi_shadow_ray(o, light).  On
   0, *occ is the primitive found in the way; otherwise *at is the face
   and coordinates of o - light, for other cubes of the light.  (p and o
   by address, as shadow.c's callers hold them: by value, their copies
   onto the stack for each call took balls_s4's item-buffer move 347.10
   -> 341.04 M instructions, gears_s4's 433.73 -> 428.75) */
int rtpi_itembuf_visible(const rtpi_itembuf *ib, const rtp_scene *s,
                         const rtpi_v3 *pp, const rtpi_v3 *op, uint32_t prim, int self,
                         const rtpi_ray *r, uint32_t *occ, rtpi_dc_at *at);
/* Sets thin[i] (one per primitive) to 1 where primitive i is drawn and
   its projection may be narrower than `cells` cells of ib somewhere, else
   0. */
void rtpi_itembuf_thin(const rtpi_itembuf *ib, const rtp_scene *s, double cells,
                       unsigned char *thin);
void rtpi_itembuf_free(rtpi_itembuf *ib, const rtp_allocator *a);

/* Whether a primitive is rendered into the item buffer from light L:
   inside-only spheres around the light occlude nothing and are left out. */
int rtpi_itembuf_renders(const rtp_scene *s, uint32_t prim, rtpi_v3 L);

#endif /* RTP_DIRCUBE_H */
