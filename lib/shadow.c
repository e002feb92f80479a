/* shadow.c — visibility of moved lights (see shadow.h).  This first
 * version answers EXACT only; the direction-cube modes are being added. */
#include "shadow.h"

struct rtpi_shadow {
    rtp_allocator alloc;
    const rtpi_kdtree *kd;
    rtpi_v3 light;
};

rtp_status rtpi_shadow_create(const rtp_scene *s, const rtpi_kdtree *kd,
                              rtpi_v3 light, rtpi_shadow_mode mode, int res,
                              const rtp_allocator *a, rtpi_shadow **out,
                              rtp_error *err)
{
    rtpi_shadow *sh;
    (void)s;
    (void)res;
    *out = NULL;
    if (mode != RTPI_SHADOW_EXACT)
        return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                          "this shadow mode is not available yet; use exact");
    sh = (rtpi_shadow *)rtpi_malloc(a, sizeof *sh);
    if (!sh)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    sh->alloc = *a;
    sh->kd = kd;
    sh->light = light;
    *out = sh;
    return RTP_OK;
}

int rtpi_shadow_visible(const rtpi_shadow *sh, rtpi_v3 p, rtpi_v3 o, uint32_t prim)
{
    rtpi_ray r = rtpi_shadow_ray(o, sh->light);
    (void)p;
    (void)prim;
    return !rtpi_kd_occluded(sh->kd, &r);
}

void rtpi_shadow_destroy(rtpi_shadow *sh)
{
    rtp_allocator a;
    if (!sh)
        return;
    a = sh->alloc;
    rtpi_free(&a, sh);
}
