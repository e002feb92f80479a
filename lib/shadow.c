/* shadow.c — visibility of moved lights (see shadow.h): one interface over
 * the kd-tree (EXACT), the light buffer, and the item buffer drawn in
 * software or by OSMesa (dircube.c, osmesa.c). */
#include "shadow.h"
#include "dircube.h"
#include "kdtree.h"

/* Item-buffer modes: a primitive narrower than SH_THIN_CELLS cells of the
   item buffer may slip between its samples, so such primitives are left
   out of it (where drawn they would only hide wide ones) and go to a
   light buffer of half the item buffer's resolution (thin: a
   quarter of the cells to fill, lists not much longer); the item
   buffer answers for the rest, and where its neighbourhood leaves the
   answer open, a coarse light buffer over the others (wide) decides. */
#ifndef SH_THIN_CELLS
#define SH_THIN_CELLS 2.0
#endif
#ifndef SH_THIN_DIV
#define SH_THIN_DIV 2 /* the thin light buffer's cells: 2x2 of the item buffer's */
#endif
#ifndef SH_WIDE_RES
#define SH_WIDE_RES 64
#endif
/* The light buffers beside an item buffer are exact whatever their
   resolution, which sets only their speed: below SH_WIDE_RES cells a face
   they take that many, not the item buffer's (at RES 1 or 2 every cell
   listed every primitive: the bunny's move took 4.2 s at itembuf:1
   against 0.15 s at 512). */

struct rtpi_shadow {
    /* first: rtpi_shadow_visible_cached and _own (shadow.h) call them */
    rtpi_shadow_fns fn;
    rtp_allocator alloc;
    rtpi_shadow_mode mode;
    const rtp_scene *s;
    const rtpi_kdtree *kd;
    rtpi_v3 light;
    rtpi_lightbuf lb;   /* LIGHTBUF; the thin primitives for the item buffer */
    /* LIGHTBUF: lb's query functions (rtpi_lightbuf_occ_fn, _vis_fn) */
    rtpi_lb_occ_fn lb_occ;
    rtpi_lb_vis_fn lb_vis;
    rtpi_lightbuf wide; /* the other primitives, for the item buffer */
    rtpi_itembuf ib;
    unsigned char *thin; /* per primitive: 1 if in lb */
    uint64_t *thin_cells; /* bit c: lb's cell c lists a thin primitive */
    double limit;         /* bytes the light buffers may list (HUGE_VAL: no bound) */
    /* EXACT: rtpi_tri_planes for the light (32 bytes a triangle while
       the light's queries run: a lit shadow ray among a terrain's
       triangles tests most of them in vain otherwise) */
    double *planes;
    double *edges; /* EXACT: rtpi_tri_edges for the light (128 bytes a triangle) */
    double *cones; /* EXACT: rtpi_round_cones for the light */
    double *spheres; /* EXACT: rtpi_sphere_entries for the light (32 bytes a sphere) */
    double *cyls;    /* EXACT: rtpi_cyl_entries for the light (48 bytes a cone) */
    double pscale;
    /* per sphere (NULL: none): |light - c|^2 and r^2, what
       rtpi_prim_shadows_own_solid derives from the light and the sphere
       alone (sh_own) */
    double *ball;
    /* per sphere (NULL: none): sh_own's answer (0 or 1) for every origin
       rtpi_ball_near_outside holds, else RTPI_OWN_ASK (the light in the
       band where sh_own_sphere looks closer) */
    unsigned char *ball_own;
};

/* rtpi_prim_shadows_own_solid for sphere i (prim) and the query's
   light, with the light's half of the arithmetic taken from sh->ball
   (the same operations on the same values, so the same answer) where
   the light lies off the band around the surface where the function
   looks closer; else the function.  Out of line: inlined into each of
   the queries' paths it cost the cones' queries more (rings) than the
   call costs the spheres'. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int sh_own_sphere(const rtpi_shadow *sh, size_t i, uint32_t prim, const rtpi_v3 *op)
{
    const rtpi_v3 o = *op;
    const rtpi_sphere *sp = &sh->s->spheres[i];
    rtpi_v3 oc = v3_sub(o, v3_from_f(sp->c));
    double d2o = v3_dot(oc, oc), d2l = sh->ball[2 * i], r2 = sh->ball[2 * i + 1];
    double big = d2o > d2l ? d2o : d2l;
    int oin = d2o < r2, lin = d2l < r2;
    if (!(fabs(d2l - r2) <= 1e-8 * (big > r2 ? big : r2)))
        return sp->r > 0.0f ? oin != lin : oin && !lin;
    return rtpi_prim_shadows_own_solid(sh->s, prim, o, sh->light);
}

/* rtpi_prim_shadows_own for the query's light (every query on a sphere
   asks: the call, with the light's distance made again, was ~75
   instructions of balls' and mount's queries, 2% of a light-buffer
   move). */
static RTPI_FORCE_INLINE int sh_own(const rtpi_shadow *sh, uint32_t prim, const rtpi_v3 *op)
{
    const rtp_scene *s = sh->s;
    size_t i = (size_t)prim - s->ntris;
    if (prim < s->ntris)
        return 0;
    /* (sh->ball made: the scene has spheres) */
    if (i < s->nspheres)
        return sh_own_sphere(sh, i, prim, op);
    /* (rtpi_prim_shadows_own_solid's answers) */
    return (i -= s->nspheres) < s->ncones ? rtpi_cone_shadows_own(s, i, op) : -1;
}

static int sh_cached_lb(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                        const rtpi_v3 *op, uint32_t prim);
static int sh_cached(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                     const rtpi_v3 *op, uint32_t prim);
static int sh_cached_cyl(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                         const rtpi_v3 *op, uint32_t prim);
static int sh_own_lb(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                     const rtpi_v3 *op, uint32_t prim, int own);
static int sh_own_plain(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                        const rtpi_v3 *op, uint32_t prim, int own);
static int sh_own_cyl(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                      const rtpi_v3 *op, uint32_t prim, int own);

/* Whether EXACT's kd walks ask the cylinders' numbers (rtpi_kd_occluder_cyls):
   in scenes mostly of spheres and cones.  Chosen once, with the query's
   function (sh->fn): a test in every query had cost the scenes of
   triangles' moves 0.3-0.5% (gears_s4 exact). */
static int sh_cyl_walk(const rtpi_shadow *sh)
{
    return sh->mode == RTPI_SHADOW_EXACT && sh->cyls && sh->cones &&
           sh->s->ntris < sh->s->nspheres + sh->s->ncones;
}

/* sh->ball for the light; 0, or -1 out of memory. */
static int sh_balls(rtpi_shadow *sh, const rtp_allocator *a)
{
    const rtp_scene *s = sh->s;
    size_t i;
    if (!s->nspheres)
        return 0;
    sh->ball = (double *)rtpi_malloc_array(a, 2 * s->nspheres, sizeof *sh->ball);
    sh->ball_own = (unsigned char *)rtpi_malloc_array(a, s->nspheres, 1);
    if (!sh->ball || !sh->ball_own)
        return -1;
    for (i = 0; i < s->nspheres; i++) {
        /* (rtpi_prim_shadows_own_solid's expressions) */
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 lc = v3_sub(sh->light, v3_from_f(sp->c));
        double r = fabs((double)sp->r);
        double d2l = v3_dot(lc, lc), r2 = r * r, m = d2l > 2.0 * r2 ? d2l : 2.0 * r2;
        sh->ball[2 * i] = d2l;
        sh->ball[2 * i + 1] = r2;
        /* An origin outside (d2o >= r2) within d2o <= 2 r2: sh_own_sphere's
           band bound 1e-8 max(d2o, d2l, r2) is at most 1e-8 m (max exact,
           the product's rounding monotone), so off m's band it answers
           oin != lin (r > 0) or oin && !lin with oin 0, for every such
           origin; NaN or within m's band: asked as ever. */
        sh->ball_own[i] = fabs(d2l - r2) > 1e-8 * m ? (unsigned char)(sp->r > 0.0f && d2l < r2)
                                                    : (unsigned char)RTPI_OWN_ASK;
    }
    return 0;
}

/* Marks the cells of the thin light buffer whose lists are not empty.  A
   query whose direction falls in an unmarked cell meets no thin
   primitive (the lists are exact: see dircube.c), so the item buffer's
   answer stands without building the ray and reading the cell's list:
   the bits, 1/32 of the list starts, stay in cache where the starts do
   not. */
static rtp_status sh_thin_cells(rtpi_shadow *sh, const rtp_allocator *a, rtp_error *err)
{
    size_t n = sh->lb.w.ncells, c;
    sh->thin_cells = (uint64_t *)rtpi_calloc_array(a, n / 64 + 1, sizeof *sh->thin_cells);
    if (!sh->thin_cells)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (c = 0; c < n; c++)
        if (sh->lb.off[c] != sh->lb.off[c + 1])
            sh->thin_cells[c >> 6] |= (uint64_t)1 << (c & 63);
    return RTP_OK;
}

/* May a thin primitive lie in the way from o to the light?  0 only where
   none can (its direction's cell lists none).  at: the face and
   coordinates of o - light, which the item buffer's query made (made
   again here they had cost tree_s11 1% of an item-buffer move).  Inline
   (the compiler's heuristics kept it a call): balls_s4's item-buffer move
   341.04 -> 339.46 M instructions. */
static RTPI_FORCE_INLINE int sh_thin_near(const rtpi_shadow *sh, const rtpi_v3 *op,
                                          const rtpi_dc_at *at)
{
    rtpi_v3 d = v3_sub(*op, sh->light);
    size_t c;
    if (d.x == 0.0 && d.y == 0.0 && d.z == 0.0)
        return 1; /* at the light: the light buffer asks every candidate */
    /* The cell of o - light, not of the ray's rounded -d: both lie far
       within a listed primitive's widening (1e-7 radians) of it where the
       ray can hit it, so the same cells list it. */
    c = rtpi_dc_wcell_at(&sh->lb.w, sh->lb.res, at);
    return c != RTPI_DC_ABSENT && ((sh->thin_cells[c >> 6] >> (c & 63)) & 1u);
}

/* A companion light buffer's error said as the item buffer's (it named
   "a light buffer of 256 cells" where an item buffer was asked; helper
   79). */
static rtp_status companion_error(rtp_status st, int res, int osmesa, rtp_error *err)
{
    if (st != RTP_OK && st != RTP_ERR_CANCELLED && err && err->message[0]) {
        /* (fitted whole: "%.180s" could end inside a character) */
        char m[sizeof err->message + 64];
        int n = snprintf(m, sizeof m, "%s at %d cells a face needs beside it %s",
                         osmesa ? "osmesa's item buffer" : "the item buffer", res, err->message);
        rtpi_fit_text(err->message, sizeof err->message, m, n >= 0 && (size_t)n < sizeof m);
    }
    return st;
}

/* The item buffer over the wide primitives and its companions (see
   above). */
static rtp_status sh_itembuf(rtpi_shadow *sh, int res, int threads, const rtpi_poll *poll,
                             const rtp_allocator *a, rtp_error *err)
{
    /* (the companions' builds asked the caller's cancel too; the item
       buffer's own reports the progress) */
    rtpi_poll cpoll = {NULL, NULL, NULL};
    size_t n = rtpi_scene_nprims(sh->s);
    rtp_status st;
    if (poll) {
        cpoll.cancel = poll->cancel;
        cpoll.user = poll->user;
    }
    sh->thin = (unsigned char *)rtpi_malloc_array(a, n ? n : 1, 1);
    if (!sh->thin)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    st = sh->mode == RTPI_SHADOW_OSMESA
             ? rtpi_itembuf_build_osmesa_wide(sh->s, sh->light, res, SH_THIN_CELLS, sh->thin, a,
                                              &sh->ib, err)
             : rtpi_itembuf_build_wide_mt(sh->s, sh->light, res, SH_THIN_CELLS, sh->thin, threads,
                                          poll, a, &sh->ib, err);
    if (st != RTP_OK)
        return st;
    st = rtpi_lightbuf_build_some(sh->s, sh->light,
                                  sh->ib.res >= SH_THIN_DIV * SH_WIDE_RES
                                      ? (sh->ib.res + 1) / SH_THIN_DIV
                                      : SH_WIDE_RES,
                                  sh->thin, 1, threads, sh->limit, HUGE_VAL, &cpoll, a, &sh->lb,
                                  err);
    if (st == RTP_OK && sh->lb.ncand)
        st = sh_thin_cells(sh, a, err);
    if (st == RTP_OK)
        st = rtpi_lightbuf_build_some(sh->s, sh->light, SH_WIDE_RES, sh->thin, 0, threads,
                                      sh->limit, HUGE_VAL, &cpoll, a, &sh->wide, err);
    return companion_error(st, res, sh->mode == RTPI_SHADOW_OSMESA, err);
}

rtp_status rtpi_shadow_create(const rtp_scene *s, const rtpi_kdtree *kd,
                              rtpi_v3 light, rtpi_shadow_mode mode, int res,
                              const rtp_allocator *a, rtpi_shadow **out,
                              rtp_error *err)
{
    return rtpi_shadow_create_mt(s, kd, light, mode, res, 1, HUGE_VAL, HUGE_VAL, NULL, a, out,
                                 err);
}

/* A light buffer's numbers for its query's cached sphere or cylinder
   (sh_cached_lb_body): EXACT's (rtpi_sphere_entries, rtpi_cyl_entries),
   with pscale the buffer's scale -- dc_scale, as rtpi_tri_planes gives
   EXACT, so that rtpi_sphere_sure's and rtpi_cyl_sure's conditions on S
   hold as there (the light's and every primitive's |coordinate| within
   it; the query asks it of the origin) -- where their memory fits in
   what the build's limit leaves (lb.room).  A speed-up only: left out
   where that memory cannot be had.  Spheres' only where they outnumber
   the cones: their making (some 60 instructions a sphere) outweighed
   what the cached spheres' tests saved on SPD's tree (4,095 of each:
   lightbuf:256 move 122.64 -> 122.52 M without them) and rings (4,200
   of each: 288.46 -> 288.40), where the cached occluder is mostly a
   cone. */
static void sh_lb_quadrics(rtpi_shadow *sh, const rtp_allocator *a)
{
    const rtp_scene *s = sh->s;
    double room = sh->lb.room;
    size_t i;
    sh->pscale = sh->lb.scale;
    if (s->nspheres > s->ncones && (double)s->nspheres * 4.0 * sizeof(double) <= room) {
        rtpi_sphere_entries(s, sh->light, sh->pscale, a, &sh->spheres);
        room -= (double)s->nspheres * 4.0 * sizeof(double);
    }
    if (!s->ncones || !((double)s->ncones * 6.0 * sizeof(double) <= room))
        return;
    /* (rtpi_cyl_entries makes and frees them where no cone is a
       cylinder: not asked there, as for SPD's tree, whose 4,095 cones'
       entries had cost its lightbuf:256 move 0.48 M of 122) */
    for (i = 0; i < s->ncones; i++)
        if (s->cframes[i].ok && s->cframes[i].ra == s->cframes[i].rb)
            break;
    if (i < s->ncones)
        rtpi_cyl_entries(s, sh->light, sh->pscale, a, &sh->cyls);
}

rtp_status rtpi_shadow_create_mt(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 light,
                                 rtpi_shadow_mode mode, int res, int threads, double limit,
                                 double max_entries, const rtpi_poll *poll,
                                 const rtp_allocator *a, rtpi_shadow **out, rtp_error *err)
{
    return rtpi_shadow_create_q(s, kd, light, mode, res, threads, limit, max_entries, HUGE_VAL,
                                poll, a, out, err);
}

rtp_status rtpi_shadow_create_q(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 light,
                                rtpi_shadow_mode mode, int res, int threads, double limit,
                                double max_entries, double queries, const rtpi_poll *poll,
                                const rtp_allocator *a, rtpi_shadow **out, rtp_error *err)
{
    rtpi_shadow *sh;
    rtp_status st = RTP_OK;
    *out = NULL;
    if (mode != RTPI_SHADOW_EXACT && mode != RTPI_SHADOW_LIGHTBUF &&
        mode != RTPI_SHADOW_ITEMBUF && mode != RTPI_SHADOW_OSMESA)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "unknown shadow mode %d",
                          (int)mode);
    if (mode == RTPI_SHADOW_EXACT && !kd)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "exact shadows need the scene's kd-tree");
    sh = (rtpi_shadow *)rtpi_calloc_array(a, 1, sizeof *sh);
    if (!sh)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    sh->alloc = *a;
    sh->mode = mode;
    sh->s = s;
    sh->kd = kd;
    sh->light = light;
    sh->limit = limit;
    switch (mode) {
    case RTPI_SHADOW_LIGHTBUF:
        st = rtpi_lightbuf_build_q(s, light, res, NULL, 0, threads, limit, max_entries, queries,
                                   poll, a, &sh->lb, err);
        break;
    case RTPI_SHADOW_ITEMBUF:
    case RTPI_SHADOW_OSMESA:
        /* A light so far that the scene lies within a few of the light
           buffer's widenings (rtpi_lightbuf_res) also lies within a few
           of the item buffer's samples, whose depths can no longer tell
           what is in front (2e15, 1e15, 1e16 over the test scene: 7% of
           the decisions wrong): decided exactly instead, by shadow rays
           where the kd-tree is there. */
        if (rtpi_lightbuf_res(s, light, res) < (res <= 0 ? RTPI_DC_DEFAULT_RES : res) / 4) {
            sh->mode = kd ? RTPI_SHADOW_EXACT : RTPI_SHADOW_LIGHTBUF;
            if (!kd)
                st = rtpi_lightbuf_build_some(s, light, res, NULL, 0, threads, limit,
                                              max_entries, poll, a, &sh->lb, err);
            break;
        }
        st = sh_itembuf(sh, res, threads, poll, a, err);
        break;
    case RTPI_SHADOW_EXACT:
        break;
    }
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_EXACT)
        st = rtpi_tri_planes(s, light, a, &sh->planes, &sh->pscale, err);
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_EXACT && sh->planes)
        rtpi_tri_edges(s, light, sh->pscale, sh->planes, a, &sh->edges);
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_EXACT)
        rtpi_sphere_entries(s, light, sh->pscale, a, &sh->spheres);
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_EXACT)
        rtpi_cyl_entries(s, light, sh->pscale, a, &sh->cyls);
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_EXACT)
        st = rtpi_round_cones(s, light, sh->pscale, rtpi_kd_far(sh->kd, light), a,
                              &sh->cones, err);
    if (st == RTP_OK && sh->mode == RTPI_SHADOW_LIGHTBUF) {
        sh_lb_quadrics(sh, a);
        sh->lb_occ = rtpi_lightbuf_occ_fn(&sh->lb);
        sh->lb_vis = rtpi_lightbuf_vis_fn(&sh->lb);
    }
    sh->fn.cached = sh->mode == RTPI_SHADOW_LIGHTBUF ? sh_cached_lb
                    : sh_cyl_walk(sh)                  ? sh_cached_cyl
                                                       : sh_cached;
    sh->fn.own = sh->mode == RTPI_SHADOW_LIGHTBUF ? sh_own_lb
                 : sh_cyl_walk(sh)                  ? sh_own_cyl
                                                    : sh_own_plain;
    if (st == RTP_OK && sh_balls(sh, a) != 0)
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    if (st != RTP_OK) {
        rtpi_shadow_destroy(sh);
        return st;
    }
    *out = sh;
    return RTP_OK;
}

/* Item buffers: a query's least depth of its 9 samples (rtpi_itembuf_pre)
   answers most queries lit at once where nothing lies in front around
   the point (teapot 87% of them, tree 75%, balls 66%, rings 65%, gears
   51%), and costs ~45 instructions more where it does not (mount's
   terrain, its samples in front of the point: 19% answered; tetra 4%).
   So a thread asks it while it pays: each answer by it counts
   SH_LEAST_HIT in `least`, each miss -1, and at SH_LEAST_OFF it is no
   longer asked for SH_LEAST_REST queries (the whole query out of line, as
   before), then tried again a few times.  The answers are the same
   either way.  (callgrind, 512^2 SPD, itembuf:256, third move: balls
   339.8 -> 328.2 M, gears 427.5 -> 413.9, rings 522.0 -> 509.0, teapot
   266.2 -> 252.5, tree 164.2 -> 158.6, mount 408.0 -> 406.9, tetra 53.81
   -> 53.89; asked always, mount took 417.3 and tetra 54.4) */
#define SH_LEAST_HIT 2
#define SH_LEAST_MAX 32
#define SH_LEAST_OFF (-16)
#define SH_LEAST_REST 64
#define SH_LEAST_RETRY 4

/* The decision, and in *occ a primitive in the way when one was seen
   (RTPI_NONE otherwise).  r: rtpi_shadow_ray(o, light), or NULL where
   the caller has not made it (made here when needed).  The point's own
   primitive is left out where it cannot be in the way of the point's
   shadow ray (rtpi_prim_shadows_own 0: a triangle, a sphere seen from
   outside with the light outside too, an open cone from outside): the
   light buffers then need not ask it (for scenes of spheres and meshes
   about half of their tests), nor the kd-tree (trace leaves it out
   alike). */
/* (inlined whatever the compiler's heuristics say: every query passes
   through it, and the calls with their copies of p and o cost a quarter
   of a light buffer's query on tree); least: the thread's score (NULL:
   the least asked always) */
static RTPI_FORCE_INLINE int sh_visible(const rtpi_shadow *sh, const rtpi_v3 *pp,
                                        const rtpi_v3 *op, uint32_t prim, const rtpi_ray *r,
                                        uint32_t *occ, int *least, int own_in, int cyl,
                                        uint32_t from)
{
    rtpi_ray rr;
    rtpi_dc_at at;
    rtpi_ib_query q;
    int own = own_in != RTPI_OWN_ASK ? own_in : sh_own(sh, prim, op), v;
    uint32_t skip = own == 0 ? prim : RTPI_NONE;
    *occ = RTPI_NONE;
    if (own == 1) {
        /* The point's own primitive is in the way for certain (a point
           inside a glass ball, the light outside: most of mount's
           queries on its balls): every mode's intersection test reports
           the crossing, which rtpi_prim_shadows_own_solid answers 1 for
           only where it lies more than 1e-9 of the ray's length (and
           1e-14 of the ball's size) short of the light: within tmax,
           far beyond the test's rounding.  The walk of a list or of the
           kd-tree to find it, or something nearer, is not needed. */
        *occ = prim;
        return 0;
    }
    switch (sh->mode) {
    case RTPI_SHADOW_LIGHTBUF:
        break;
    case RTPI_SHADOW_ITEMBUF:
    case RTPI_SHADOW_OSMESA:
        /* (own is not 1 here; the first steps inline) */
        if (!least || *least > SH_LEAST_OFF) {
            v = rtpi_itembuf_pre(&sh->ib, pp, op, &at, &q, 1);
            if (v == 2 && least && *least < SH_LEAST_MAX)
                *least += SH_LEAST_HIT;
            if (v < 0) {
                if (least && q.direct)
                    --*least;
                v = rtpi_itembuf_visible_rest(&sh->ib, sh->s, pp, op, prim, own, r, occ, &at,
                                              &q);
            }
        } else {
            if (--*least < SH_LEAST_OFF - SH_LEAST_REST)
                *least = SH_LEAST_OFF + SH_LEAST_RETRY;
            v = rtpi_itembuf_visible(&sh->ib, sh->s, pp, op, prim, own, r, occ, &at);
        }
        if (v == 0)
            return 0;
        if (v > 0 && (!sh->lb.ncand || !sh_thin_near(sh, op, &at)))
            return 1; /* (no thin primitive to ask) */
        if (!r) {
            rr = rtpi_shadow_ray(*op, sh->light);
            r = &rr;
        }
        if (sh->lb.ncand &&
            (*occ = rtpi_lightbuf_occluder(&sh->lb, sh->s, r, skip)) != RTPI_NONE)
            return 0;
        if (v > 0)
            return 1;
        return (*occ = rtpi_lightbuf_occluder(&sh->wide, sh->s, r, skip)) == RTPI_NONE;
    case RTPI_SHADOW_EXACT:
        break;
    }
    if (!r) {
        rr = rtpi_shadow_ray(*op, sh->light);
        r = &rr;
    }
    if (sh->mode == RTPI_SHADOW_LIGHTBUF)
        return (*occ = rtpi_lightbuf_occluder(&sh->lb, sh->s, r, skip)) == RTPI_NONE;
    if (cyl)
        return (*occ = rtpi_kd_occluder_cyls_from(sh->kd, r, skip, sh->planes, sh->cones,
                                                  sh->cyls, sh->pscale, from)) == RTPI_NONE;
    return (*occ = rtpi_kd_occluder_planes_from(sh->kd, r, skip, sh->planes, sh->edges,
                                                sh->cones, sh->pscale, from)) == RTPI_NONE;
}

int rtpi_shadow_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o, uint32_t prim)
{
    uint32_t occ;
    return sh_visible(sh, &p, &o, prim, NULL, &occ, NULL, RTPI_OWN_ASK, sh_cyl_walk(sh),
                      RTPI_NONE);
}

/* Whether triangle q is in the way of r, for EXACT's cache: the walk's
   own tests in the walk's order (rtpi_kd_occluder_planes): the light's
   plane first, a miss it proves (asked, as there, only for origins within
   sh->pscale), then hit_tri's test on the same floats (not the edges'
   test the walk asks with the plane's: a miss it proves is hit_tri's
   miss too, rtpi_tri_edges).  The same answer
   as rtpi_intersect_prim's, without its call, and without the set-up
   where the plane turns the ray away: through it the cache's tests were
   9% of gears' exact move (140,573 of them for 57,503 hits).  (Spheres'
   and cones' round cones, with rtpi_cylinder_far, turned away too few of
   rings' cached cones, which lie close to the ray by their nature: its
   move took 0.5% more.)  Out of line: inlined, it cost rings' cached
   spheres and cones 0.1% of the move.  Without hit_tri's test for a
   zero-area triangle (rtpi_tri_degenerate): q is a triangle a query of
   this cache found in the way (c->last, h1, h2 start at 0 and are set
   from occluders only), and every mode's occluder passed a test that
   leaves such triangles out -- the kd-tree holds none (its build), a
   light buffer lists none (dc_hittable), the item buffer's tests are
   rtpi_intersect_prim's -- so the walk would never meet it either.  (It
   was ~30 of the ~210 instructions of a cached test: callgrind, third
   `exact` move, 512^2 SPD: gears 332.0 -> 327.9 M, teapot 374.3 ->
   373.0.) */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int sh_exact_tri(const rtpi_shadow *sh, uint32_t q, const rtpi_ray *r)
{
    const rtp_scene *s = sh->s;
    const double S = sh->pscale;
    const rtpi_tri *tr = &s->tris[q];
    const float *p0 = s->pos + 3 * (size_t)tr->v[0];
    const float *p1 = s->pos + 3 * (size_t)tr->v[1];
    const float *p2 = s->pos + 3 * (size_t)tr->v[2];
    rtpi_wt_ray w;
    double t, u, v;
    if (sh->planes && fabs(r->o.x) <= S && fabs(r->o.y) <= S && fabs(r->o.z) <= S) {
        const double *pl = sh->planes + 4 * (size_t)q;
        if (sh->edges) {
            /* the walk's test (rtpi_edges_sure: its plane's, then the
               edges'): a miss it proves, or a hit with t certainly in
               range, is hit_tri's answer (the proof at rtpi_tri_edges) */
            rtpi_edge_o eo;
            double oz, sz;
            int e, kz;
            rtpi_edge_o_make(&eo, &r->o);
            e = rtpi_edges_sure(sh->edges + RTPI_EDGE_N * (size_t)q, &eo,
                                RTPI_EDGE_MARGIN * S * S * S);
            if (e == 0)
                return 0;
            if (e == 1 && rtpi_wt_z(r, &kz, &oz, &sz) &&
                rtpi_wt_t_sure(p0, p1, p2, kz, oz, sz, r->tmin, r->tmax))
                return 1;
        } else if (pl[0] * r->o.x + pl[1] * r->o.y + pl[2] * r->o.z > pl[3]) {
            return 0;
        }
    }
    return rtpi_wt_setup(&w, r) &&
           rtpi_wt_tri(&w, p0, p1, p2, r->tmin, r->tmax, &t, &u, &v);
}

/* EXACT, after the last occluder (c->last) missed r: the two
   primitives found in the way before it (c->h1, c->h2; the one other than
   the last, and not the point's own), tested as the walk would, the
   answer +1 where one is in the way (promoted to the front), else 0.  A
   row of samples in a shadow crosses the shadows of a few primitives by
   turns (gears: 26,490 of the 85,647 walks that met an occluder after one
   had been met could have been answered by the one before the last;
   mount's, whose glass balls put themselves in the cache, 15,300 of
   16,462 by the last one the walk found), and a walk that meets one costs
   several times a test.  Only while they pay: a walk costs some ten
   tests, so each hit counts SH_GAIN_HIT and each miss -1 in c->gain, and
   below SH_GAIN_OFF they are no longer asked until a walk finds one of
   them in the way (tetra: 21 of 2263 such walks, whose tests had cost
   1% of its move). */
/* A sphere q in the way of r, for EXACT's cache: rtpi_sphere_t's
   answer, from the light's numbers where they decide it
   (rtpi_sphere_sure; asked, as the walk asks them, for origins within
   sh->pscale).  balls_s4's cached spheres: 108 k tests a move, 61 k
   hits. */
static RTPI_FORCE_INLINE int sh_exact_sphere(const rtpi_shadow *sh, uint32_t i, const rtpi_ray *r)
{
    const rtpi_sphere *sp = &sh->s->spheres[i];
    const double S = sh->pscale;
    double t;
    if (sh->spheres && fabs(r->o.x) <= S && fabs(r->o.y) <= S && fabs(r->o.z) <= S) {
        rtpi_quad_k qk;
        int e;
        rtpi_quad_k_make(S, &qk);
        e = rtpi_sphere_sure(sh->spheres + 4 * (size_t)i, !(sp->r > 0.0f), r, &qk);
        if (e >= 0)
            return e;
    }
    return rtpi_sphere_t(sp, r, v3_dot(r->d, r->d), &t);
}

/* A cone q (of the scene's cones) in the way of r, for EXACT's cache:
   hit_cone's answer, from the light's numbers where they decide it
   (rtpi_cyl_sure: cylinders; origins within sh->pscale). */
static int sh_exact_cone(const rtpi_shadow *sh, uint32_t i, const rtpi_ray *r)
{
    const double S = sh->pscale;
    rtpi_hit h;
    if (sh->cyls && fabs(r->o.x) <= S && fabs(r->o.y) <= S && fabs(r->o.z) <= S) {
        rtpi_quad_k qk;
        int e;
        rtpi_quad_k_make(S, &qk);
        e = rtpi_cyl_sure(sh->cyls + 6 * (size_t)i, &sh->s->cframes[i], r, &qk);
        if (e >= 0)
            return e;
    }
    return rtpi_intersect_prim(sh->s, (uint32_t)(sh->s->ntris + sh->s->nspheres + i), r, &h);
}

/* Whether prim q, a sphere or cone, is in the way of r, for EXACT's
   cache (each kind by its function above).  Out of line: inline, the
   cache's query for the light buffer, compiled with it, took rings_s7's
   move 1.3 M more.  (Triangles not through it: the call more cost
   gears' move 1%.) */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int sh_exact_prim(const rtpi_shadow *sh, uint32_t q, const rtpi_ray *r)
{
    const rtp_scene *s = sh->s;
    if (q - s->ntris < s->nspheres)
        return sh_exact_sphere(sh, q - s->ntris, r);
    return sh_exact_cone(sh, q - s->ntris - s->nspheres, r);
}

#define SH_GAIN_HIT 8
#define SH_GAIN_MAX 64
#define SH_GAIN_OFF (-32)
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int sh_earlier(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_ray *r,
                      uint32_t prim)
{
    uint32_t k;
    for (k = 0; k < 2; k++) {
        uint32_t e = k ? c->h2 : c->h1, q = e - 1u;
        int hit;
        if (!e || e == c->last || q == prim)
            continue;
        hit = q < sh->s->ntris ? sh_exact_tri(sh, q, r) : sh_exact_prim(sh, q, r);
        if (!hit) {
            c->gain--;
        } else {
            if (c->gain < SH_GAIN_MAX)
                c->gain += SH_GAIN_HIT;
            if (k) { /* the most recent first */
                c->h2 = c->h1;
                c->h1 = e;
            }
            return (int)e;
        }
    }
    return 0;
}

/* sh_cached_lb_body's other queries: a sphere or cone in the cache,
   tested first on the ray made here, which the walk then takes; a
   query on a sphere or cone, rtpi_prim_shadows_own asked where the
   caller has not.  Out of line: the triangles' queries then save no
   registers and make no frame (mount_s6: 142 k of 263 k queries a move
   come here, its glass balls'; teapot_s12 none). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int sh_cached_lb_slow(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *op,
                             uint32_t prim, int own_in)
{
    const rtp_scene *s = sh->s;
    uint32_t occ, last = c->last;
    int own;
    if (last > s->ntris && last - 1u != prim) {
        /* (the cached sphere or cone) */
        uint32_t q = last - 1u;
        int hit;
        rtpi_ray r = rtpi_shadow_ray(*op, sh->light);
        if (q - s->ntris < s->nspheres) {
            hit = sh_exact_sphere(sh, q - s->ntris, &r);
        } else {
            /* a cone outside its band (lb_slabs) is missed; r.d is the
               walk's -d, |q.d| the same */
            size_t i = q - s->ntris - s->nspheres;
            uint32_t k = sh->lb.slab && i < s->ncones ? sh->lb.cone_rank[i] : RTPI_NONE;
            hit = 1;
            if (k != RTPI_NONE) {
                const double *b = sh->lb.slab + 4 * (size_t)k;
                hit = !(fabs(r.d.x * b[0] + r.d.y * b[1] + r.d.z * b[2]) > b[3]);
            }
            hit = hit && sh_exact_cone(sh, (uint32_t)i, &r);
        }
        if (hit)
            return 0;
        own = own_in != RTPI_OWN_ASK ? own_in : sh_own(sh, prim, op);
        if (own == 1) {
            c->last = prim + 1u;
            return 0;
        }
        occ = sh->lb_occ(&sh->lb, s, &r, own == 0 ? prim : RTPI_NONE);
        c->last = occ != RTPI_NONE ? occ + 1u : 0u;
        return occ == RTPI_NONE;
    }
    own = own_in != RTPI_OWN_ASK ? own_in : sh_own(sh, prim, op);
    if (own == 1) {
        c->last = prim + 1u;
        return 0;
    }
    return sh->lb_vis(&sh->lb, s, op, own == 0 ? prim : RTPI_NONE,
                      last && last - 1u != prim ? last - 1u : RTPI_NONE, &c->last);
}

/* rtpi_shadow_visible_cached for a light buffer (RTPI_SHADOW_LIGHTBUF):
   sh_cached's steps for that mode alone, in a
   function of their own, so a query pays no saving of the registers the
   other modes' paths take (24 instructions a query as one body: tree's
   lightbuf:256 move 3.6 M of 129).  own_in: RTPI_OWN_ASK, or
   rtpi_prim_shadows_own's answer the caller knows (rtpi_shadow_visible_own).
   A triangle's query (rtpi_prim_shadows_own 0: its own primitive not
   asked) whose cache holds no sphere or cone goes straight to the light
   buffer's (sh->lb_vis), which makes the shadow ray only where a test
   needs it, and sets the cache: a jump, no frame.  (The ray made here
   and the walk's call had cost ~30 instructions a query more:
   lightbuf:256, third move, 512^2 SPD, teapot_s12 144.34 -> 140.49 M,
   tree_s11 99.84 -> 97.28, gears_s4 239.62 -> 236.51.)  A triangle in
   c->last was answered by this light buffer, whose lists hold hittable
   ones only: the walk's condition on `first`. */
static RTPI_FORCE_INLINE int sh_cached_lb_body(const rtpi_shadow *sh, rtpi_shadow_cache *c,
                                               const rtpi_v3 *pp, const rtpi_v3 *op,
                                               uint32_t prim, int own_in)
{
    const rtp_scene *s = sh->s;
    uint32_t last = c->last;
    (void)pp;
    if (own_in == RTPI_OWN_ASK ? prim >= s->ntris || last > s->ntris
                               : own_in != 0 || (last > s->ntris && last - 1u != prim))
        return sh_cached_lb_slow(sh, c, op, prim, own_in);
    /* (last 0: last - 1 is RTPI_NONE) */
    return sh->lb_vis(&sh->lb, s, op, prim, last - 1u != prim ? last - 1u : RTPI_NONE, &c->last);
}

const unsigned char *rtpi_shadow_ball_own(const rtpi_shadow *sh)
{
    return sh->ball_own;
}

static int sh_cached_lb(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                        const rtpi_v3 *op, uint32_t prim)
{
    return sh_cached_lb_body(sh, c, pp, op, prim, RTPI_OWN_ASK);
}

/* The other modes' steps (sh_cached), own_in a constant in each copy (a
   test of it in every query had cost tree_s11's moves 0.1%) */
static RTPI_FORCE_INLINE int sh_cached_body(const rtpi_shadow *sh, rtpi_shadow_cache *c,
                                            const rtpi_v3 *pp, const rtpi_v3 *op,
                                            uint32_t prim, int own_in, int cyl)
{
    uint32_t occ;
    int v;
    rtpi_ray r;
    /* Only where it cannot change the answer: an item buffer may call a
       blocked point lit, and whether the previous query's occluder is
       tested first then depends on the query before it -- on how the
       frame was split into regions and on the threads' rows. */
    if (c->last && c->last - 1u != prim &&
        (sh->mode == RTPI_SHADOW_EXACT ||
         (sh->mode == RTPI_SHADOW_LIGHTBUF && c->last - 1u >= sh->s->ntris))) {
        /* A hit is a hit: the primitive is in the way whichever mode
           asks, and every exact mode's lists would hold it (the kd-tree's
           too: the same intersection tests).  Not the point's own
           primitive, which the queries may leave out (sh_visible). */
        const rtp_scene *s = sh->s;
        uint32_t q = c->last - 1u;
        int hit;
        r = rtpi_shadow_ray(*op, sh->light);
        if (q < s->ntris && sh->mode == RTPI_SHADOW_EXACT) {
            hit = sh_exact_tri(sh, q, &r);
        } else if (sh->mode == RTPI_SHADOW_EXACT) {
            hit = sh_exact_prim(sh, q, &r);
        } else if (q - s->ntris < s->nspheres) {
            /* (a sphere inline, as the kd-tree's walk tests it) */
            double t;
            hit = rtpi_sphere_t(&s->spheres[q - s->ntris], &r, v3_dot(r.d, r.d), &t);
        } else {
            rtpi_hit h;
            hit = rtpi_intersect_prim(s, q, &r, &h);
        }
        if (hit)
            return 0;
        if (sh->mode == RTPI_SHADOW_EXACT && c->gain > SH_GAIN_OFF &&
            (hit = sh_earlier(sh, c, &r, prim)) != 0) {
            c->last = (uint32_t)hit;
            return 0;
        }
        v = sh_visible(sh, pp, op, prim, &r, &occ, &c->least, own_in, cyl, c->from - 1u);
    } else if (c->last && c->last - 1u != prim && sh->mode == RTPI_SHADOW_LIGHTBUF) {
        /* A triangle: sh_visible's, with the last occluder asked by the
           light buffer first, whose test then shares the list walk's
           set-up (as a call of its own, with its own, it had cost gears
           9% of a move).  The point's own primitive, where it is in the
           way, answers before it: the same answer, both being hits (for
           a sphere or cone first, as above: mount's glass balls, their
           own test a call, 0.8% more).  A triangle in c->last was
           answered by this light buffer, whose lists hold hittable ones
           only: occluder_first's condition on `first`. */
        int own = own_in != RTPI_OWN_ASK ? own_in : sh_own(sh, prim, op);
        if (own == 1) {
            occ = prim;
        } else {
            r = rtpi_shadow_ray(*op, sh->light);
            occ = rtpi_lightbuf_occluder_first(&sh->lb, sh->s, &r, own == 0 ? prim : RTPI_NONE,
                                               c->last - 1u);
        }
        v = occ == RTPI_NONE;
    } else {
        v = sh_visible(sh, pp, op, prim, NULL, &occ, &c->least, own_in, cyl, c->from - 1u);
    }
    /* Remembered only while queries keep meeting occluders: after a lit
       answer the next is most likely lit too, and a test would be lost. */
    if (occ != RTPI_NONE && sh->mode == RTPI_SHADOW_EXACT) {
        uint32_t e = occ + 1u;
        /* the walk met an earlier one that was not asked: worth asking */
        if (c->gain <= SH_GAIN_OFF && c->last && e != c->last && (e == c->h1 || e == c->h2))
            c->gain += SH_GAIN_HIT;
        if (e != c->h1) {
            c->h2 = c->h1;
            c->h1 = e;
        }
    }
    c->last = occ != RTPI_NONE ? occ + 1u : 0u;
    return v;
}

static int sh_cached(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                     const rtpi_v3 *op, uint32_t prim)
{
    return sh_cached_body(sh, c, pp, op, prim, RTPI_OWN_ASK, 0);
}

static int sh_cached_cyl(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                         const rtpi_v3 *op, uint32_t prim)
{
    return sh_cached_body(sh, c, pp, op, prim, RTPI_OWN_ASK, 1);
}

static int sh_own_lb(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                     const rtpi_v3 *op, uint32_t prim, int own)
{
    return sh_cached_lb_body(sh, c, pp, op, prim, own);
}

static int sh_own_plain(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                        const rtpi_v3 *op, uint32_t prim, int own)
{
    return sh_cached_body(sh, c, pp, op, prim, own, 0);
}

static int sh_own_cyl(const rtpi_shadow *sh, rtpi_shadow_cache *c, const rtpi_v3 *pp,
                      const rtpi_v3 *op, uint32_t prim, int own)
{
    return sh_cached_body(sh, c, pp, op, prim, own, 1);
}

void rtpi_shadow_destroy(rtpi_shadow *sh)
{
    rtp_allocator a;
    if (!sh)
        return;
    a = sh->alloc;
    rtpi_lightbuf_free(&sh->lb, &a);
    rtpi_lightbuf_free(&sh->wide, &a);
    rtpi_itembuf_free(&sh->ib, &a);
    rtpi_free(&a, sh->thin);
    rtpi_free(&a, sh->thin_cells);
    rtpi_free(&a, sh->planes);
    rtpi_free(&a, sh->edges);
    rtpi_free(&a, sh->cones);
    rtpi_free(&a, sh->spheres);
    rtpi_free(&a, sh->ball_own);
    rtpi_free(&a, sh->cyls);
    rtpi_free(&a, sh->ball);
    rtpi_free(&a, sh);
}
