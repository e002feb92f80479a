/*
 * metrics.c — how far one image is from another: error statistics and a
 * heat map that reads without other tools (colour scale and its numbers
 * drawn into the image).
 *
 * A NaN or infinity in one image that the other does not share counts as
 * an infinite error: a broken pixel must never make two images look close.
 */
#include "internal.h"

#include <stdio.h>

/* |a - b| for one sample, with the non-finite rule above. */
static double sample_error(float a, float b)
{
    double d;
    if (a == b) /* also equal infinities */
        return 0.0;
    d = fabs((double)a - (double)b);
    if (isnan(d))
        return isnan(a) && isnan(b) ? 0.0 : HUGE_VAL;
    return d;
}

/* The error of one pixel: its largest channel error. */
static double pixel_error(const float *a, const float *b)
{
    double e0 = sample_error(a[0], b[0]), e1 = sample_error(a[1], b[1]),
           e2 = sample_error(a[2], b[2]);
    double e = e0 > e1 ? e0 : e1;
    return e > e2 ? e : e2;
}

/* what: the caller's call ("image diff", "heat map"), which its errors
   name */
static rtp_status check_pair(const rtp_image *a, const rtp_image *b, const char *what,
                             rtp_error *err)
{
    if (!a || !b || !a->pixels || !b->pixels)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: missing image", what);
    if (a->width != b->width || a->height != b->height)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "image sizes differ: %dx%d and %dx%d", a->width,
                          a->height, b->width, b->height);
    if (!rtpi_image_size_ok(a->width, a->height))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: invalid image size %dx%d", what, a->width,
                          a->height);
    return RTP_OK;
}

rtp_status rtp_image_diff(const rtp_image *a, const rtp_image *b,
                          double threshold, rtp_diff_stats *stats,
                          rtp_error *err)
{
    size_t w, h, x, y, above = 0, n;
    double sum = 0.0, sum2 = 0.0, max = 0.0;
    rtp_status st;
    if (!stats)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "image diff: stats is NULL");
    memset(stats, 0, sizeof *stats);
    st = check_pair(a, b, "image diff", err);
    if (st != RTP_OK)
        return st;
    if (isnan(threshold))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "image diff: the threshold is NaN");
    w = (size_t)a->width;
    h = (size_t)a->height;
    for (y = 0; y < h; y++) {
        /* Row sums first: a few hundred terms of similar size, then one
           addition per row, keeps rounding small for large images. */
        double rs = 0.0, rs2 = 0.0;
        const float *pa = a->pixels + y * w * 3, *pb = b->pixels + y * w * 3;
        for (x = 0; x < w; x++, pa += 3, pb += 3) {
            double pe = 0.0;
            int c;
            for (c = 0; c < 3; c++) {
                double e = sample_error(pa[c], pb[c]);
                rs += e;
                rs2 += e * e;
                if (e > pe)
                    pe = e;
            }
            if (pe > max)
                max = pe;
            if (pe > threshold)
                above++;
        }
        sum += rs;
        sum2 += rs2;
    }
    n = w * h;
    stats->pixels = n;
    stats->mae = sum / (3.0 * (double)n);
    stats->rmse = sqrt(sum2 / (3.0 * (double)n));
    stats->max_abs = max;
    stats->psnr = stats->rmse > 0.0 ? -20.0 * log10(stats->rmse) : HUGE_VAL;
    stats->share_above = (double)above / (double)n;
    return RTP_OK;
}

/* ------------------------------------------------------------ heat map */

/* Black -> blue -> red -> yellow -> white: lightness rises steadily, so
   the order of errors reads in grey too, and zero error is black. */
static void heat_colour(double t, float rgb[3])
{
    static const float stops[5][3] = {{0.00f, 0.00f, 0.00f},
                                      {0.15f, 0.10f, 0.80f},
                                      {0.90f, 0.10f, 0.20f},
                                      {1.00f, 0.80f, 0.00f},
                                      {1.00f, 1.00f, 1.00f}};
    double s;
    int i, c;
    if (!(t > 0.0))
        t = 0.0;
    if (t > 1.0)
        t = 1.0;
    s = t * 4.0;
    i = (int)s;
    if (i > 3)
        i = 3;
    s -= i;
    for (c = 0; c < 3; c++)
        rgb[c] = (float)(stops[i][c] + (stops[i + 1][c] - stops[i][c]) * s);
}

/* A 5x7 font for the legend's numbers: seven rows, bit 4 leftmost. */
static const unsigned char *glyph(char ch)
{
    static const unsigned char digits[10][7] = {
        {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E},
        {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E},
        {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F},
        {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E},
        {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02},
        {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E},
        {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E},
        {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08},
        {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E},
        {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}};
    static const unsigned char dot[7] = {0, 0, 0, 0, 0, 0x0C, 0x0C};
    static const unsigned char e[7] = {0, 0, 0x0E, 0x11, 0x1F, 0x10, 0x0E};
    static const unsigned char minus[7] = {0, 0, 0, 0x1F, 0, 0, 0};
    static const unsigned char plus[7] = {0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0};
    if (ch >= '0' && ch <= '9')
        return digits[ch - '0'];
    switch (ch) {
    case '.': return dot;
    case 'e': return e;
    case '-': return minus;
    case '+': return plus;
    default: return NULL;
    }
}

#define GLYPH_W 5
#define GLYPH_H 7
#define GLYPH_ADVANCE 6

/* Formats v like "%.3g" with '.' whatever the locale (a decimal point
   of two bytes, as ps_AF's U+066B, printed as two dots before). */
static void format_number(double v, char *buf, size_t size)
{
    rtpi_fmt_g(buf, size, 3, v);
}

static int text_width(const char *s, int fs)
{
    int n = (int)strlen(s);
    return n ? (n * GLYPH_ADVANCE - 1) * fs : 0;
}

static void put(rtp_image *img, int x, int y, const float rgb[3])
{
    float *p;
    if (x < 0 || y < 0 || x >= img->width || y >= img->height)
        return;
    p = img->pixels + ((size_t)y * (size_t)img->width + (size_t)x) * 3;
    p[0] = rgb[0];
    p[1] = rgb[1];
    p[2] = rgb[2];
}

/* Draws s with its top-left corner at (x, y), each font pixel fs x fs. */
static void draw_text(rtp_image *img, int x, int y, const char *s, int fs,
                      const float rgb[3])
{
    for (; *s; s++, x += GLYPH_ADVANCE * fs) {
        const unsigned char *g = glyph(*s);
        int gx, gy, i, j;
        if (!g)
            continue;
        for (gy = 0; gy < GLYPH_H; gy++)
            for (gx = 0; gx < GLYPH_W; gx++)
                if (g[gy] & (0x10 >> gx))
                    for (j = 0; j < fs; j++)
                        for (i = 0; i < fs; i++)
                            put(img, x + gx * fs + i, y + gy * fs + j, rgb);
    }
}

/* Legend layout below the heat, in font pixels (times fs): a gap, the
   colour bar, a gap, the numbers, a gap. */
#define LEG_GAP 4
#define LEG_BAR 10
#define LEG_TEXT_GAP 3
#define LEG_HEIGHT (LEG_GAP + LEG_BAR + LEG_TEXT_GAP + GLYPH_H + LEG_GAP)

rtp_status rtp_diff_heatmap(const rtp_image *a, const rtp_image *b,
                            double scale, const char *png_path,
                            rtp_error *err)
{
    static const float grey[3] = {0.18f, 0.18f, 0.18f};
    static const float white[3] = {1.0f, 1.0f, 1.0f};
    rtp_image *out = NULL;
    rtp_image_format fmt;
    rtp_status st;
    char lmax[32], lmid[32];
    int w, h, ow, oh, fs, x, y, bar0, bar1, need;
    double max = 0.0;

    st = check_pair(a, b, "heat map", err);
    if (st != RTP_OK)
        return st;
    if (!png_path || !*png_path)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "heat map: no file name");
    if (!(scale >= 0.0) || isinf(scale))
        return rtpi_error(err, RTP_ERR_ARGUMENT, png_path, 0, 0,
                          "heat map: the scale must be a finite number "
                          ">= 0 (0: the largest error)");
    w = a->width;
    h = a->height;
    if (scale == 0.0) {
        /* The largest finite error; infinite ones show at full heat. */
        size_t i, n = (size_t)w * (size_t)h;
        for (i = 0; i < n; i++) {
            double e = pixel_error(a->pixels + 3 * i, b->pixels + 3 * i);
            if (e > max && !isinf(e))
                max = e;
        }
        scale = max > 0.0 ? max : 1.0;
    }

    /* Large images get a font twice the size; the output is widened when
       the image is too narrow for the legend's numbers. */
    fs = w >= 480 ? 2 : 1;
    format_number(scale, lmax, sizeof lmax);
    format_number(scale / 2, lmid, sizeof lmid);
    need = 2 * LEG_GAP * fs + text_width("0", fs) + text_width(lmax, fs) +
           2 * GLYPH_ADVANCE * fs;
    ow = w > need ? w : need;
    oh = h + LEG_HEIGHT * fs;
    if (!rtpi_image_size_ok(ow, oh))
        return rtpi_error(err, RTP_ERR_LIMIT, png_path, 0, 0,
                          "heat map: %dx%d image is too large", ow, oh);
    st = rtp_image_create(ow, oh, &a->alloc, &out, err);
    if (st != RTP_OK)
        return st;

    for (y = 0; y < oh; y++)
        for (x = 0; x < ow; x++)
            put(out, x, y, grey);
    for (y = 0; y < h; y++) {
        for (x = 0; x < w; x++) {
            size_t i = (size_t)y * (size_t)w + (size_t)x;
            float rgb[3];
            heat_colour(pixel_error(a->pixels + 3 * i, b->pixels + 3 * i) /
                            scale,
                        rgb);
            put(out, x, y, rgb);
        }
    }

    /* Colour bar from 0 (left) to scale (right), numbers under its ends
       and, where there is room, its middle. */
    bar0 = LEG_GAP * fs;
    bar1 = ow - LEG_GAP * fs - 1;
    for (x = bar0; x <= bar1; x++) {
        float rgb[3];
        heat_colour((double)(x - bar0) / (double)(bar1 - bar0), rgb);
        for (y = 0; y < LEG_BAR * fs; y++)
            put(out, x, h + LEG_GAP * fs + y, rgb);
    }
    y = h + (LEG_GAP + LEG_BAR + LEG_TEXT_GAP) * fs;
    draw_text(out, bar0, y, "0", fs, white);
    draw_text(out, bar1 + 1 - text_width(lmax, fs), y, lmax, fs, white);
    if (ow >= need + text_width(lmid, fs) + 2 * GLYPH_ADVANCE * fs)
        draw_text(out, (bar0 + bar1 + 1 - text_width(lmid, fs)) / 2, y, lmid,
                  fs, white);

    /* Any other name is the PNG, or the PPM where this build has no
       libpng (as the CLI's default image names): a heat map is to be
       looked at, so an 8-bit image either way. */
    fmt = rtp_image_format_from_path(png_path);
    if (fmt == RTP_IMAGE_AUTO)
        fmt = rtp_png_supported() ? RTP_IMAGE_PNG : RTP_IMAGE_PPM;
    st = rtp_image_write(out, png_path, fmt, err);
    rtp_image_destroy(out);
    return st;
}
