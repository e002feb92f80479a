/* osmesa.c — the item buffer drawn by OpenGL through OSMesa (off-screen
 * Mesa), only in builds with OSMESA=1 (RTP_HAVE_OSMESA). */
#include "dircube.h"

#if !defined(RTP_HAVE_OSMESA)

rtp_status rtpi_itembuf_build_osmesa(const rtp_scene *s, rtpi_v3 light,
                                     int res, const rtp_allocator *a,
                                     rtpi_itembuf *ib, rtp_error *err)
{
    (void)s;
    (void)light;
    (void)res;
    (void)a;
    memset(ib, 0, sizeof *ib);
    return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                      "osmesa shadows: this build has no OSMesa (rebuild with "
                      "make OSMESA=1 and libosmesa6-dev); use itembuf for the "
                      "same item buffer in software");
}

#else
#error "not yet"
#endif
