/*
 * shadow.h — which recorded hits see a light that moved or was added
 * (the paper's section 4).  One interface, four ways to answer:
 *
 *   RTPI_SHADOW_EXACT     shadow rays through the kd-tree: the reference,
 *                         the very rays trace casts
 *   RTPI_SHADOW_LIGHTBUF  light buffer (Haines & Greenberg): a direction
 *                         cube around the light whose cells list the
 *                         primitives projecting onto them, sorted by
 *                         distance; the shadow ray is tested only against
 *                         its cell's list, so the answer equals EXACT
 *   RTPI_SHADOW_ITEMBUF   item buffer: each cube face rendered by a
 *                         software scanline z-buffer, one primitive per
 *                         cell.  Primitives narrower than 2 cells go to
 *                         a light buffer of half the resolution instead
 *                         (exact for them); for the rest the shadow ray
 *                         is intersected with the primitives sampled in
 *                         the 3x3 cells around it (a hit is certain), and
 *                         where one of those lies in front of the point
 *                         but misses the ray (a shadow edge) a coarse
 *                         light buffer decides exactly.  Approximate: it
 *                         answers "lit" wrongly only where a wide
 *                         primitive reaches across the ray between the
 *                         samples while none shows in front of the point
 *                         (a corner sharper than a cell); measured below
 *                         0.01% of decisions at 256-2048 cells on the
 *                         SPD scenes (test/bench/bench_shadow.c)
 *   RTPI_SHADOW_OSMESA    the same item buffer drawn by OpenGL (OSMesa);
 *                         only in builds with OSMESA=1
 *
 * A built rtpi_shadow is immutable: queries may run on many threads.
 */
#ifndef RTP_SHADOW_H
#define RTP_SHADOW_H

#include "internal.h"

typedef enum rtpi_shadow_mode {
    RTPI_SHADOW_EXACT = 0,
    RTPI_SHADOW_LIGHTBUF = 1,
    RTPI_SHADOW_ITEMBUF = 2,
    RTPI_SHADOW_OSMESA = 3
} rtpi_shadow_mode;

typedef struct rtpi_shadow rtpi_shadow;

/* Prepares visibility queries for a point light at `light` in scene s.
   kd is the scene's kd-tree (EXACT uses it; others may).  res: cells per
   cube face edge (0: the default, RTPI_DC_DEFAULT_RES = 512, where the
   item buffer is as accurate as at 1024 and cheaper to build).
   RTP_ERR_UNSUPPORTED for OSMESA in builds without it. */
rtp_status rtpi_shadow_create(const rtp_scene *s, const rtpi_kdtree *kd,
                              rtpi_v3 light, rtpi_shadow_mode mode, int res,
                              const rtp_allocator *a, rtpi_shadow **out,
                              rtp_error *err);
/* The same, building the direction cube's light buffers on up to
   `threads` threads (the same buffers for any number), their lists within
   `limit` bytes and a light buffer's within max_entries entries
   (HUGE_VAL: no bound; past either RTP_ERR_LIMIT).  poll (NULL:
   none): the build's progress, and its cancel asked inside the cubes'
   builds (RTP_ERR_CANCELLED; the item buffer drawn by OSMesa is not
   stopped inside). */
rtp_status rtpi_shadow_create_mt(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 light,
                                 rtpi_shadow_mode mode, int res, int threads, double limit,
                                 double max_entries, const rtpi_poll *poll,
                                 const rtp_allocator *a, rtpi_shadow **out, rtp_error *err);
/* The same, told the shadow queries a LIGHTBUF mode's buffer is expected
   to answer (HUGE_VAL: unknown; rtpi_lightbuf_build_q). */
rtp_status rtpi_shadow_create_q(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 light,
                                rtpi_shadow_mode mode, int res, int threads, double limit,
                                double max_entries, double queries, const rtpi_poll *poll,
                                const rtp_allocator *a, rtpi_shadow **out, rtp_error *err);

/* Does the recorded hit at p (a float position, as the tree keeps it) on
   primitive prim, whose shadow ray trace would start at o (p moved off the
   surface by rtpi_offset_origin), see the light?  The caller has already
   checked that the surface faces the light. */
int rtpi_shadow_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o,
                        uint32_t prim);

/* One thread's memory of the primitive found in the last shadow ray's
   way: neighbouring queries (a row of samples) in a shadow often meet the
   same one, and testing it first answers them with one intersection.  The answers are
   rtpi_shadow_visible's (a hit is a hit; LIGHTBUF and EXACT stay exact).
   Zero-initialise one per thread and never share it; it stays valid
   across lights and modes of the same scene. */
typedef struct rtpi_shadow_cache {
    uint32_t last; /* primitive + 1; 0: none */
    /* EXACT: the last two distinct primitives its queries found in the
       way (+ 1; 0: none), kept across lit answers: asked after `last`
       missed */
    uint32_t h1, h2;
    int gain; /* whether asking h1 and h2 pays (sh_earlier) */
    int least; /* item buffers: whether the least of 9 pays (sh_visible) */
    /* EXACT: the next query's origin's kd leaf (rtpi_kd_path_of) + 1,
       its walk's start; 0: the root (a zeroed cache's).  Set by the
       caller for each query: a query leaves it as it is */
    uint32_t from;
} rtpi_shadow_cache;

/* The query's steps for sh's mode, chosen once at sh's creation; sh's
   structure's first member (shadow.c), which a pointer to it, converted,
   points to: a light buffer's queries then pay no saving of the
   registers the other modes' steps take (24 instructions a query as one
   body: tree's lightbuf:256 move 3.6 M of 129), and no mode's a test of
   the mode at the call.  (p and o by address: a query's arguments
   copied by value cost a tenth of a light buffer's answer) */
typedef int (*rtpi_shadow_cached_fn)(const rtpi_shadow *sh, rtpi_shadow_cache *c,
                                     const rtpi_v3 *p, const rtpi_v3 *o, uint32_t prim);
/* rtpi_shadow_visible_own's steps, the same way (own: as there) */
typedef int (*rtpi_shadow_own_fn)(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *p,
                                  const rtpi_v3 *o, uint32_t prim, int own);
typedef struct rtpi_shadow_fns {
    rtpi_shadow_cached_fn cached;
    rtpi_shadow_own_fn own;
} rtpi_shadow_fns;
static inline int rtpi_shadow_visible_cached(const rtpi_shadow *sh, rtpi_shadow_cache *c,
                                             const rtpi_v3 *p, const rtpi_v3 *o, uint32_t prim)
{
    return ((const rtpi_shadow_fns *)(const void *)sh)->cached(sh, c, p, o, prim);
}
/* rtpi_shadow_visible_cached with rtpi_prim_shadows_own's answer for
   prim and o (0, 1 or -1) known already to the caller (vis_row keeps a
   cone's per node: its origin does not depend on the light).  Through
   sh's function too: one function testing the mode, the other modes'
   steps beside a light buffer's, had the light buffer's queries save
   their registers (rings_s7's lightbuf:256 move 261.07 M against
   256.92), and one calling the others out of line cost their moves
   0.2% (rings' exact 570.26 -> 571.27). */
#define RTPI_OWN_ASK 2 /* (not known: shadow.c's own copy asks) */
static inline int rtpi_shadow_visible_own(const rtpi_shadow *sh, rtpi_shadow_cache *c,
                                          const rtpi_v3 *p, const rtpi_v3 *o, uint32_t prim,
                                          int own)
{
    return ((const rtpi_shadow_fns *)(const void *)sh)->own(sh, c, p, o, prim, own);
}

/* Per sphere of the scene (NULL: none), for sh's light:
   rtpi_prim_shadows_own's answer (0 or 1) for every origin o that
   rtpi_ball_near_outside holds (a front hit's: the same for every
   light, kept per node by vis_row), else RTPI_OWN_ASK: the sphere's
   queries then pass it to rtpi_shadow_visible_own, and a light buffer's
   take the triangles' path where its cache allows. */
const unsigned char *rtpi_shadow_ball_own(const rtpi_shadow *sh);

void rtpi_shadow_destroy(rtpi_shadow *sh);

/* The end of rtpi_shadow_ray's segment for a light at distance dist
   from its origin. */
static inline double rtpi_shadow_tmax(double dist)
{
    /* Stop just short of the light: a surface passing through the light
       itself must not shadow it (1e-9 relative is far above double
       rounding and far below any feature size). */
    return dist * (1.0 - 1e-9);
}

/* The shadow ray trace casts from o to a light at lp: the one definition
   EXACT, LIGHTBUF and trace share. */
static inline rtpi_ray rtpi_shadow_ray(rtpi_v3 o, rtpi_v3 lp)
{
    rtpi_ray r;
    rtpi_v3 l = v3_sub(lp, o);
    double dist = v3_len(l);
    r.o = o;
    r.d = dist > 0.0 ? v3_mul(l, 1.0 / dist) : v3(0.0, 0.0, 1.0);
    r.tmin = 0.0;
    /* (a light buffer's query makes tmax alone, as here, and the ray
       only where a test asks for it: dircube.c lb_occluder) */
    r.tmax = rtpi_shadow_tmax(dist);
    return r;
}

/* Trace's decision for one hit and light: 0 where the (shading) normal ns
   faces away from the light at lp, else 1 with *o the shadow ray's origin,
   p moved off the surface (geometric normal ng) towards the light.  Trace
   and re-evaluation both call this, so they cast identical rays. */
static inline int rtpi_shadow_setup(rtpi_v3 p, rtpi_v3 ng, rtpi_v3 ns, rtpi_v3 lp,
                                    double floor, rtpi_v3 *o)
{
    rtpi_v3 l = v3_sub(lp, p);
    if (v3_dot(ns, l) <= 0.0)
        return 0;
    *o = rtpi_offset_origin(p, ng, v3_dot(ng, l) >= 0.0 ? 1.0 : -1.0, floor);
    return 1;
}

/* The query trace makes for a ray (direction d) hitting primitive prim
   at pe: pe rounded to float as the tree keeps it, the surface derived
   from that, the normals turned towards the ray where the material is
   two-sided (one_sided: SPD's rule), then rtpi_shadow_setup.  0 where the
   surface faces away from the light, else 1 with the query's p and o
   (floor: rtpi_offset_floor(s, NULL)).  For tests and benchmarks that ask what
   trace would ask. */
static inline int rtpi_shadow_query_at(const rtp_scene *s, int one_sided, uint32_t prim,
                                       rtpi_v3 pe, rtpi_v3 d, rtpi_v3 lp, double floor,
                                       rtpi_v3 *p, rtpi_v3 *o)
{
    rtpi_surface sf;
    rtpi_v3 ng, ns;
    const float pf[3] = {(float)pe.x, (float)pe.y, (float)pe.z};
    rtpi_surface_from_point(s, prim, pf, 0, &sf);
    ng = sf.ng;
    ns = sf.ns;
    if (v3_dot(d, ng) >= 0.0 && rtpi_two_sided(s, one_sided, prim, &s->mats[sf.mat])) {
        ng = v3_mul(ng, -1.0);
        ns = v3_mul(ns, -1.0);
    }
    *p = sf.p;
    return rtpi_shadow_setup(sf.p, ng, ns, lp, rtpi_prim_offset_floor(s, prim, floor), o);
}

#endif
