/* test_diff.c — image error metrics against closed-form values, and the
 * heat map (written, read back, colours and legend where they belong). */
#include "check.h"
#include "internal.h"

#include <dirent.h>
#include <stdint.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdir[256];

static const char *tpath(const char *name)
{
    static char buf[2][512];
    static int k;
    k = (k + 1) % 2;
    snprintf(buf[k], sizeof buf[k], "%s/%s", tmpdir, name);
    return buf[k];
}

static int near(double got, double want, double rel)
{
    double d = fabs(got - want);
    return d <= rel * fabs(want) || d == 0.0;
}

/* An image of dyadic values k/256 in [0, 0.5]: sums and differences of
   such values and small dyadic offsets are exact in float and double. */
static rtp_image *dyadic_image(int w, int h)
{
    rtp_image *img = NULL;
    size_t i, n;
    if (rtp_image_create(w, h, NULL, &img, NULL) != RTP_OK)
        return NULL;
    n = (size_t)w * (size_t)h * 3;
    for (i = 0; i < n; i++)
        img->pixels[i] = (float)((i * 37) % 129) / 256.0f;
    return img;
}

static rtp_image *copy_image(const rtp_image *src)
{
    rtp_image *img = NULL;
    if (rtp_image_create(src->width, src->height, NULL, &img, NULL) !=
        RTP_OK)
        return NULL;
    memcpy(img->pixels, src->pixels,
           (size_t)src->width * (size_t)src->height * 3 * sizeof(float));
    return img;
}

static void test_constant_offset(void)
{
    const double c = 0.09375; /* 3/32 */
    rtp_image *a = dyadic_image(7, 5), *b;
    rtp_diff_stats st;
    size_t i;
    int sign;
    if (!a)
        return;
    b = copy_image(a);
    for (sign = -1; b && sign <= 1; sign += 2) {
        for (i = 0; i < 7 * 5 * 3; i++)
            b->pixels[i] = a->pixels[i] + (float)(sign * c);
        CHECK(rtp_image_diff(a, b, c / 2, &st, NULL) == RTP_OK);
        CHECK(st.pixels == 35);
        CHECK(st.mae == c);
        CHECK(st.rmse == c);
        CHECK(st.max_abs == c);
        CHECK(near(st.psnr, -20.0 * log10(c), 1e-14));
        CHECK(st.share_above == 1.0);
        /* "Exceeds" is strict. */
        CHECK(rtp_image_diff(a, b, c, &st, NULL) == RTP_OK);
        CHECK(st.share_above == 0.0);
        CHECK(rtp_image_diff(b, a, c * 0.999, &st, NULL) == RTP_OK);
        CHECK(st.share_above == 1.0 && st.mae == c);
    }
    /* A non-dyadic offset from black: the error is the float value. */
    if (b) {
        memset(a->pixels, 0, 7 * 5 * 3 * sizeof(float));
        for (i = 0; i < 7 * 5 * 3; i++)
            b->pixels[i] = 0.1f;
        CHECK(rtp_image_diff(a, b, 0.0, &st, NULL) == RTP_OK);
        CHECK(near(st.mae, (double)0.1f, 1e-15));
        CHECK(near(st.rmse, (double)0.1f, 1e-15));
        CHECK(st.max_abs == (double)0.1f);
        CHECK(near(st.psnr, -20.0 * log10((double)0.1f), 1e-14));
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static void test_single_pixel(void)
{
    const int w = 8, h = 6;
    const double d = 0.3125;
    const double n3 = 3.0 * w * h;
    rtp_image *a = dyadic_image(w, h), *b;
    rtp_diff_stats st;
    if (!a)
        return;
    b = copy_image(a);
    if (!b) {
        rtp_image_destroy(a);
        return;
    }
    b->pixels[(2 * w + 3) * 3 + 1] += (float)d;
    CHECK(rtp_image_diff(a, b, 0.1, &st, NULL) == RTP_OK);
    CHECK(st.pixels == (size_t)(w * h));
    CHECK(near(st.mae, d / n3, 1e-15));
    CHECK(near(st.rmse, d / sqrt(n3), 1e-15));
    CHECK(st.max_abs == d);
    CHECK(near(st.psnr, -20.0 * log10(d / sqrt(n3)), 1e-14));
    CHECK(st.share_above == 1.0 / (w * h));
    CHECK(rtp_image_diff(a, b, d, &st, NULL) == RTP_OK);
    CHECK(st.share_above == 0.0);
    /* Negative thresholds count every pixel. */
    CHECK(rtp_image_diff(a, b, -1.0, &st, NULL) == RTP_OK);
    CHECK(st.share_above == 1.0);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static void test_identical(void)
{
    rtp_image *a = dyadic_image(5, 4), *b;
    rtp_diff_stats st;
    if (!a)
        return;
    b = copy_image(a);
    CHECK(b && rtp_image_diff(a, b, 0.0, &st, NULL) == RTP_OK);
    CHECK(st.mae == 0.0 && st.rmse == 0.0 && st.max_abs == 0.0);
    CHECK(isinf(st.psnr) && st.psnr > 0);
    CHECK(st.psnr == HUGE_VAL);
    CHECK(st.share_above == 0.0 && st.pixels == 20);
    CHECK(rtp_image_diff(a, a, 0.0, &st, NULL) == RTP_OK);
    CHECK(st.psnr == HUGE_VAL);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static void test_non_finite(void)
{
    rtp_image *a = dyadic_image(3, 2), *b;
    rtp_diff_stats st;
    float nan_ = (float)NAN, inf = (float)INFINITY;
    if (!a)
        return;
    b = copy_image(a);
    if (!b) {
        rtp_image_destroy(a);
        return;
    }
    /* The same NaN or infinity in both: no error. */
    a->pixels[0] = b->pixels[0] = nan_;
    a->pixels[4] = b->pixels[4] = inf;
    a->pixels[5] = b->pixels[5] = -inf;
    CHECK(rtp_image_diff(a, b, 0.0, &st, NULL) == RTP_OK);
    CHECK(st.max_abs == 0.0 && st.psnr == HUGE_VAL);
    /* NaN against a number: infinite error, never "identical". */
    b->pixels[7] = nan_;
    CHECK(rtp_image_diff(a, b, 0.5, &st, NULL) == RTP_OK);
    CHECK(isinf(st.max_abs) && isinf(st.mae) && isinf(st.rmse));
    CHECK(st.psnr < 0 && isinf(st.psnr));
    CHECK(st.share_above == 1.0 / 6.0);
    b->pixels[7] = a->pixels[7];
    b->pixels[4] = -inf;
    CHECK(rtp_image_diff(a, b, 0.5, &st, NULL) == RTP_OK);
    CHECK(isinf(st.max_abs));
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static void test_arguments(void)
{
    rtp_image *a = dyadic_image(4, 3), *b = dyadic_image(3, 4);
    rtp_diff_stats st;
    rtp_error err;
    if (!a || !b) {
        rtp_image_destroy(a);
        rtp_image_destroy(b);
        return;
    }
    CHECK(rtp_image_diff(a, b, 0.0, &st, &err) == RTP_ERR_ARGUMENT);
    CHECK(err.status == RTP_ERR_ARGUMENT);
    CHECK(strstr(err.message, "4x3") && strstr(err.message, "3x4"));
    CHECK(rtp_image_diff(a, NULL, 0.0, &st, &err) == RTP_ERR_ARGUMENT);
    CHECK(rtp_image_diff(a, a, 0.0, NULL, &err) == RTP_ERR_ARGUMENT);
    CHECK(rtp_image_diff(a, a, (double)NAN, &st, &err) == RTP_ERR_ARGUMENT);
    CHECK(rtp_diff_heatmap(a, b, 0.0, tpath("h.ppm"), &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(strstr(err.message, "4x3") && strstr(err.message, "3x4"));
    CHECK(rtp_diff_heatmap(a, a, -1.0, tpath("h.ppm"), &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(rtp_diff_heatmap(a, a, (double)NAN, tpath("h.ppm"), &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(rtp_diff_heatmap(a, a, 0.0, NULL, &err) == RTP_ERR_ARGUMENT);
    /* (the heat map's errors name it, not rtp_image_diff) */
    CHECK(rtp_diff_heatmap(a, NULL, 0.0, tpath("h.ppm"), &err) == RTP_ERR_ARGUMENT &&
          strncmp(err.message, "heat map:", 9) == 0);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static float q8(double x) { return (float)(int)(x * 255.0 + 0.5) / 255.0f; }

static const float *px(const rtp_image *img, int x, int y)
{
    return img->pixels + ((size_t)y * (size_t)img->width + (size_t)x) * 3;
}

/* a against b: error 0 at the left column, rising to `top` at the right. */
static void ramp_pair(int w, int h, double top, rtp_image **pa,
                      rtp_image **pb)
{
    int x, y, c;
    *pa = *pb = NULL;
    if (rtp_image_create(w, h, NULL, pa, NULL) != RTP_OK ||
        rtp_image_create(w, h, NULL, pb, NULL) != RTP_OK)
        return;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < 3; c++) {
                (*pa)->pixels[((size_t)y * w + x) * 3 + c] = 0.25f;
                (*pb)->pixels[((size_t)y * w + x) * 3 + c] =
                    0.25f + (c == 1 ? (float)(top * x / (w - 1)) : 0.0f);
            }
}

/* Counts legend pixels below the heat that are white (the numbers) and
   that are neither white nor the grey background (the colour bar). */
static void legend_pixels(const rtp_image *img, int h, int *text, int *bar)
{
    int x, y;
    *text = *bar = 0;
    for (y = h; y < img->height; y++)
        for (x = 0; x < img->width; x++) {
            const float *p = px(img, x, y);
            if (p[0] == 1.0f && p[1] == 1.0f && p[2] == 1.0f)
                (*text)++;
            else if (!(p[0] == p[1] && p[1] == p[2]))
                (*bar)++;
        }
}

static void test_heatmap(void)
{
    const int w = 33, h = 9;
    rtp_image *a, *b, *hm = NULL;
    rtp_error err;
    rtp_status st;
    const char *exts[2] = {"heat.png", "heat.ppm"};
    int k, text, bar;
    ramp_pair(w, h, 0.5, &a, &b);
    if (!a || !b) {
        CHECK(0);
        rtp_image_destroy(a);
        rtp_image_destroy(b);
        return;
    }
    for (k = 0; k < 2; k++) {
        st = rtp_diff_heatmap(a, b, 0.0, tpath(exts[k]), &err);
        if (k == 0 && !rtp_png_supported()) {
            CHECK(st == RTP_ERR_UNSUPPORTED);
            continue;
        }
        CHECK_MSG(st == RTP_OK, "%s: %s", exts[k], err.message);
        CHECK(rtp_image_read(tpath(exts[k]), NULL, &hm, &err) == RTP_OK);
        if (!hm)
            continue;
        /* The heat at top left, at least as wide, a legend below. */
        CHECK(hm->width >= w && hm->height >= h + 20);
        /* Zero error black, the largest (scale 0 = max_abs) white. */
        CHECK(px(hm, 0, 0)[0] == 0.0f && px(hm, 0, h - 1)[2] == 0.0f);
        CHECK(px(hm, w - 1, 0)[0] == 1.0f && px(hm, w - 1, 0)[1] == 1.0f &&
              px(hm, w - 1, 4)[2] == 1.0f);
        /* Error rises left to right: so does lightness (sum of RGB). */
        {
            int x, rising = 1;
            for (x = 1; x < w; x++) {
                const float *p = px(hm, x - 1, 3), *q = px(hm, x, 3);
                rising &= q[0] + q[1] + q[2] >= p[0] + p[1] + p[2];
            }
            CHECK(rising);
        }
        legend_pixels(hm, h, &text, &bar);
        CHECK(text > 20 && bar > hm->width * 5);
        rtp_image_destroy(hm);
        hm = NULL;
    }

    /* An explicit scale: an error of half the scale sits mid-map (red),
       errors beyond it saturate. */
    st = rtp_diff_heatmap(a, b, 0.5, tpath("half.ppm"), &err);
    CHECK(st == RTP_OK);
    CHECK(rtp_image_read(tpath("half.ppm"), NULL, &hm, &err) == RTP_OK);
    if (hm) {
        const float *p = px(hm, (w - 1) / 2, 2); /* error 0.25 = scale/2 */
        CHECK(p[0] == q8(0.9f) && p[1] == q8(0.1f) && p[2] == q8(0.2f));
        rtp_image_destroy(hm);
        hm = NULL;
    }
    st = rtp_diff_heatmap(a, b, 0.125, tpath("sat.ppm"), &err);
    CHECK(st == RTP_OK);
    CHECK(rtp_image_read(tpath("sat.ppm"), NULL, &hm, &err) == RTP_OK);
    if (hm) {
        const float *p = px(hm, w - 2, 2);
        CHECK(p[0] == 1.0f && p[1] == 1.0f && p[2] == 1.0f);
        rtp_image_destroy(hm);
        hm = NULL;
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);

    /* Identical images: all black, scale 1, still a legend. */
    ramp_pair(3, 2, 0.0, &a, &b);
    st = rtp_diff_heatmap(a, b, 0.0, tpath("same.ppm"), &err);
    CHECK(st == RTP_OK);
    CHECK(rtp_image_read(tpath("same.ppm"), NULL, &hm, &err) == RTP_OK);
    if (hm) {
        /* A tiny image is widened for the legend's numbers. */
        CHECK(hm->width > 3 && hm->height > 2);
        CHECK(px(hm, 2, 1)[0] == 0.0f && px(hm, 2, 1)[1] == 0.0f);
        legend_pixels(hm, 2, &text, &bar);
        CHECK(text > 10 && bar > 0);
        rtp_image_destroy(hm);
        hm = NULL;
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);

    /* A large image gets a larger font: a taller legend. */
    ramp_pair(600, 4, 1e-4, &a, &b);
    st = rtp_diff_heatmap(a, b, 0.0, tpath("big.ppm"), &err);
    CHECK(st == RTP_OK);
    CHECK(rtp_image_read(tpath("big.ppm"), NULL, &hm, &err) == RTP_OK);
    if (hm) {
        CHECK(hm->width == 600 && hm->height >= 4 + 40);
        rtp_image_destroy(hm);
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);

    /* Writing into a missing folder fails cleanly. */
    ramp_pair(3, 2, 0.1, &a, &b);
    CHECK(rtp_diff_heatmap(a, b, 0.0, tpath("none/h.ppm"), &err) ==
          RTP_ERR_IO);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
}

static void cleanup(void)
{
    DIR *d = opendir(tmpdir);
    struct dirent *e;
    char buf[600];
    if (!d)
        return;
    while ((e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        snprintf(buf, sizeof buf, "%s/%s", tmpdir, e->d_name);
        remove(buf);
    }
    closedir(d);
    remove(tmpdir);
}

int main(void)
{
    (void)check_shared_scenes; /* check.h's helper, unused here */
    snprintf(tmpdir, sizeof tmpdir, "%s/rtp-test-diff.XXXXXX",
             getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    if (!mkdtemp(tmpdir)) {
        fprintf(stderr, "cannot make a temporary folder\n");
        return 1;
    }
    RUN(test_constant_offset);
    RUN(test_single_pixel);
    RUN(test_identical);
    RUN(test_non_finite);
    RUN(test_arguments);
    RUN(test_heatmap);
    if (getenv("RTP_KEEP_TEST_FILES"))
        fprintf(stderr, "files kept in %s\n", tmpdir);
    else
        cleanup();
    return check_report();
}
