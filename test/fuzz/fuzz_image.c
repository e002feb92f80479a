/* fuzz_image.c — fuzzes the image readers (PNG, PPM P3/P6, PFM) through
 * rtp_image_read_stream on a memory stream.  An image it accepts is
 * written back as PFM, PPM and PNG to memory streams, and the PFM read
 * again must give the same floats bit for bit. */
#include "fuzz_common.h"

static void write_back(const rtp_image *img)
{
    static const rtp_image_format fmts[] = {RTP_IMAGE_PFM, RTP_IMAGE_PPM,
                                            RTP_IMAGE_PNG};
    size_t i;
    for (i = 0; i < sizeof fmts / sizeof *fmts; i++) {
        char *buf = NULL;
        size_t len = 0;
        FILE *f = open_memstream(&buf, &len);
        rtp_error err;
        rtp_status st;
        if (!f)
            return;
        memset(&err, 0, sizeof err);
        st = rtp_image_write_stream(img, f, fmts[i], &err);
        fuzz_check_error(&err, st);
        fclose(f);
        if (st == RTP_OK && fmts[i] == RTP_IMAGE_PFM) {
            rtp_image *back = NULL;
            FILE *g = fmemopen(buf, len, "rb");
            if (g) {
                st = rtp_image_read_stream(g, "back.pfm", &fuzz_soft_alloc, &back, &err);
                fuzz_check_error(&err, st);
                FUZZ_ASSERT(st == RTP_OK);
                FUZZ_ASSERT(back->width == img->width && back->height == img->height);
                FUZZ_ASSERT(memcmp(back->pixels, img->pixels,
                                   sizeof(float) * 3 * (size_t)img->width *
                                       (size_t)img->height) == 0);
                rtp_image_destroy(back);
                fclose(g);
            }
        }
        free(buf);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    rtp_image *img = NULL;
    rtp_error err;
    rtp_status st;
    FILE *f;
    if (size == 0 || size > 1 << 20)
        return 0; /* fmemopen refuses an empty buffer */
    f = fmemopen((void *)(uintptr_t)data, size, "rb");
    if (!f)
        return 0;
    memset(&err, 0, sizeof err);
    st = rtp_image_read_stream(f, "fuzz.img", &fuzz_soft_alloc, &img, &err);
    fclose(f);
    fuzz_check_error(&err, st);
    FUZZ_ASSERT((st == RTP_OK) == (img != NULL));
    if (st == RTP_OK) {
        FUZZ_ASSERT(img->width > 0 && img->height > 0 && img->pixels);
        /* Writing back costs per pixel; a decoded bomb needs no echo. */
        if ((size_t)img->width * (size_t)img->height <= (size_t)1 << 16)
            write_back(img);
    }
    rtp_image_destroy(img);
    return 0;
}
