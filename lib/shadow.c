/* shadow.c — visibility of moved lights (see shadow.h): one interface over
 * the kd-tree (EXACT), the light buffer, and the item buffer drawn in
 * software or by OSMesa (dircube.c, osmesa.c). */
#include "shadow.h"
#include "dircube.h"

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

struct rtpi_shadow {
    rtp_allocator alloc;
    rtpi_shadow_mode mode;
    const rtp_scene *s;
    const rtpi_kdtree *kd;
    rtpi_v3 light;
    rtpi_lightbuf lb;   /* LIGHTBUF; the thin primitives for the item buffer */
    rtpi_lightbuf wide; /* the other primitives, for the item buffer */
    rtpi_itembuf ib;
    unsigned char *thin; /* per primitive: 1 if in lb */
};

/* The item buffer over the wide primitives and its companions (see
   above). */
static rtp_status sh_itembuf(rtpi_shadow *sh, int res, int threads, const rtp_allocator *a,
                             rtp_error *err)
{
    size_t n = rtpi_scene_nprims(sh->s);
    rtp_status st;
    sh->thin = (unsigned char *)rtpi_malloc_array(a, n ? n : 1, 1);
    if (!sh->thin)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    st = sh->mode == RTPI_SHADOW_OSMESA
             ? rtpi_itembuf_build_osmesa_wide(sh->s, sh->light, res, SH_THIN_CELLS, sh->thin, a,
                                              &sh->ib, err)
             : rtpi_itembuf_build_wide_mt(sh->s, sh->light, res, SH_THIN_CELLS, sh->thin, threads,
                                          a, &sh->ib, err);
    if (st == RTP_OK)
        st = rtpi_lightbuf_build_some(sh->s, sh->light, (sh->ib.res + 1) / SH_THIN_DIV, sh->thin,
                                      1, threads, a, &sh->lb, err);
    if (st == RTP_OK)
        st = rtpi_lightbuf_build_some(sh->s, sh->light,
                                      sh->ib.res < SH_WIDE_RES ? sh->ib.res : SH_WIDE_RES,
                                      sh->thin, 0, threads, a, &sh->wide, err);
    return st;
}

rtp_status rtpi_shadow_create(const rtp_scene *s, const rtpi_kdtree *kd,
                              rtpi_v3 light, rtpi_shadow_mode mode, int res,
                              const rtp_allocator *a, rtpi_shadow **out,
                              rtp_error *err)
{
    return rtpi_shadow_create_mt(s, kd, light, mode, res, 1, a, out, err);
}

rtp_status rtpi_shadow_create_mt(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 light,
                                 rtpi_shadow_mode mode, int res, int threads,
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
    switch (mode) {
    case RTPI_SHADOW_LIGHTBUF:
        st = rtpi_lightbuf_build_some(s, light, res, NULL, 0, threads, a, &sh->lb, err);
        break;
    case RTPI_SHADOW_ITEMBUF:
    case RTPI_SHADOW_OSMESA:
        st = sh_itembuf(sh, res, threads, a, err);
        break;
    case RTPI_SHADOW_EXACT:
        break;
    }
    if (st != RTP_OK) {
        rtpi_shadow_destroy(sh);
        return st;
    }
    *out = sh;
    return RTP_OK;
}

/* The point's own primitive when it cannot be in the way of the point's
   shadow ray (a triangle, a sphere seen from outside with the light
   outside too, an open cone from outside): the light buffers then need
   not ask it (for scenes of spheres and meshes about half of their
   tests), nor the kd-tree (trace leaves it out alike).  RTPI_NONE
   otherwise. */
static uint32_t own_skip(const rtpi_shadow *sh, uint32_t prim, rtpi_v3 o)
{
    return rtpi_prim_shadows_own(sh->s, prim, o, sh->light) == 0 ? prim : RTPI_NONE;
}

/* The decision, and in *occ a primitive in the way when one was seen
   (RTPI_NONE otherwise). */
static int sh_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o, uint32_t prim,
                      uint32_t *occ)
{
    rtpi_ray r;
    uint32_t skip;
    int v;
    *occ = RTPI_NONE;
    switch (sh->mode) {
    case RTPI_SHADOW_LIGHTBUF:
        r = rtpi_shadow_ray(o, sh->light);
        return (*occ = rtpi_lightbuf_occluder(&sh->lb, sh->s, &r, own_skip(sh, prim, o))) ==
               RTPI_NONE;
    case RTPI_SHADOW_ITEMBUF:
    case RTPI_SHADOW_OSMESA:
        v = rtpi_itembuf_visible(&sh->ib, sh->s, p, o, prim, sh->thin, occ);
        if (v == 0)
            return 0;
        if (!sh->lb.ncand && v > 0)
            return 1; /* (no light buffer to ask: skip not needed) */
        r = rtpi_shadow_ray(o, sh->light);
        skip = own_skip(sh, prim, o);
        if (sh->lb.ncand &&
            (*occ = rtpi_lightbuf_occluder(&sh->lb, sh->s, &r, skip)) != RTPI_NONE)
            return 0;
        if (v > 0)
            return 1;
        return (*occ = rtpi_lightbuf_occluder(&sh->wide, sh->s, &r, skip)) == RTPI_NONE;
    case RTPI_SHADOW_EXACT:
        break;
    }
    r = rtpi_shadow_ray(o, sh->light);
    return (*occ = rtpi_kd_occluder(sh->kd, &r, own_skip(sh, prim, o))) == RTPI_NONE;
}

int rtpi_shadow_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o, uint32_t prim)
{
    uint32_t occ;
    return sh_visible(sh, p, o, prim, &occ);
}

int rtpi_shadow_visible_cached(const rtpi_shadow *sh, rtpi_shadow_cache *c, rtpi_v3 p,
                               rtpi_v3 o, uint32_t prim)
{
    uint32_t occ;
    int v;
    if (c->last && c->last - 1u != prim) {
        /* A hit is a hit: the primitive is in the way whichever mode
           asks, and every exact mode's lists would hold it (the kd-tree's
           too: the same intersection tests).  Not the point's own
           primitive, which the queries may leave out (own_skip). */
        rtpi_ray r = rtpi_shadow_ray(o, sh->light);
        rtpi_hit h;
        if (rtpi_intersect_prim(sh->s, c->last - 1u, &r, &h))
            return 0;
    }
    v = sh_visible(sh, p, o, prim, &occ);
    /* Remembered only while queries keep meeting occluders: after a lit
       answer the next is most likely lit too, and a test would be lost. */
    c->last = occ != RTPI_NONE ? occ + 1u : 0u;
    return v;
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
    rtpi_free(&a, sh);
}
