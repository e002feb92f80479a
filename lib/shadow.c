/* shadow.c — visibility of moved lights (see shadow.h): one interface over
 * the kd-tree (EXACT), the light buffer, and the item buffer drawn in
 * software or by OSMesa (dircube.c, osmesa.c). */
#include "shadow.h"
#include "dircube.h"

struct rtpi_shadow {
    rtp_allocator alloc;
    rtpi_shadow_mode mode;
    const rtp_scene *s;
    const rtpi_kdtree *kd;
    rtpi_v3 light;
    rtpi_lightbuf lb;
    rtpi_itembuf ib;
};

rtp_status rtpi_shadow_create(const rtp_scene *s, const rtpi_kdtree *kd,
                              rtpi_v3 light, rtpi_shadow_mode mode, int res,
                              const rtp_allocator *a, rtpi_shadow **out,
                              rtp_error *err)
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
        st = rtpi_lightbuf_build(s, light, res, a, &sh->lb, err);
        break;
    case RTPI_SHADOW_ITEMBUF:
        st = rtpi_itembuf_build(s, light, res, a, &sh->ib, err);
        break;
    case RTPI_SHADOW_OSMESA:
        st = rtpi_itembuf_build_osmesa(s, light, res, a, &sh->ib, err);
        break;
    case RTPI_SHADOW_EXACT:
        break;
    }
    if (st != RTP_OK) {
        rtpi_free(a, sh);
        return st;
    }
    *out = sh;
    return RTP_OK;
}

int rtpi_shadow_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o, uint32_t prim)
{
    rtpi_ray r;
    switch (sh->mode) {
    case RTPI_SHADOW_LIGHTBUF:
        r = rtpi_shadow_ray(o, sh->light);
        return rtpi_lightbuf_visible(&sh->lb, sh->s, &r);
    case RTPI_SHADOW_ITEMBUF:
    case RTPI_SHADOW_OSMESA:
        return rtpi_itembuf_visible(&sh->ib, sh->s, p, o, prim);
    case RTPI_SHADOW_EXACT:
        break;
    }
    r = rtpi_shadow_ray(o, sh->light);
    return !rtpi_kd_occluded(sh->kd, &r);
}

void rtpi_shadow_destroy(rtpi_shadow *sh)
{
    rtp_allocator a;
    if (!sh)
        return;
    a = sh->alloc;
    rtpi_lightbuf_free(&sh->lb, &a);
    rtpi_itembuf_free(&sh->ib, &a);
    rtpi_free(&a, sh);
}
