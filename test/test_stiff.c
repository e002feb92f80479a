/* test_stiff.c — numerical stability on stiff and extreme cases.
 *
 * Every case traces a tiny scene (scenes/stiff/, each stating at its top
 * the property it checks, or a scene generated here) and checks, besides
 * its own property, what holds for every scene:
 *  - no pixel is NaN or infinite, in the trace and in every re-evaluation:
 *    no edit, a light colour edit, a moved light with exact, light-buffer
 *    and item-buffer shadows;
 *  - re-evaluation without edits reproduces the trace bit for bit;
 *  - a light colour edit and a moved light with exact shadows equal a full
 *    trace of the edited scene within 1e-6 (the light buffer is reported,
 *    the item buffer is approximate by design and only reported).
 * A shadow mode that returns an error is reported on stderr ("note:"); it
 * fails the test only when the error is malformed (unknown status, no
 * message).  Run from the top of the repository. */
#include "check.h"

#include <rtp.h>

#include <math.h>
#include <string.h>
#include <time.h>

#define SCENES "scenes/stiff/"

/* ------------------------------------------------------------ helpers */

static char *read_text(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long n;
    if (!f)
        return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        buf = (char *)malloc((size_t)n + 1);
        if (buf && fread(buf, 1, (size_t)n, f) == (size_t)n) {
            buf[n] = '\0';
            if (size)
                *size = (size_t)n;
        } else {
            free(buf);
            buf = NULL;
        }
    }
    fclose(f);
    return buf;
}

static void print_error(const char *what, const rtp_error *err)
{
    char buf[600];
    fprintf(stderr, "%s: %s\n", what, rtp_error_format(err, buf, sizeof buf));
}

static rtp_scene *load_file(const char *name)
{
    char path[256];
    rtp_scene *s = NULL;
    rtp_error err;
    snprintf(path, sizeof path, SCENES "%s", name);
    if (rtp_scene_load(path, NULL, &s, &err) != RTP_OK) {
        print_error(path, &err);
        return NULL;
    }
    return s;
}

static rtp_scene *load_text(const char *text, const char *name)
{
    rtp_scene *s = NULL;
    rtp_error err;
    if (rtp_scene_load_memory(text, strlen(text), name, "nff", NULL, &s, &err) != RTP_OK) {
        print_error(name, &err);
        return NULL;
    }
    return s;
}

static size_t npix(const rtp_image *im) { return (size_t)im->width * (size_t)im->height; }

static const float *px(const rtp_image *im, int x, int y)
{
    return im->pixels + 3 * ((size_t)y * (size_t)im->width + (size_t)x);
}

static size_t count_nonfinite(const rtp_image *im)
{
    size_t i, n = 0;
    if (!im)
        return 0;
    for (i = 0; i < 3 * npix(im); i++)
        if (!isfinite(im->pixels[i]))
            n++;
    return n;
}

static int same_bits(const rtp_image *a, const rtp_image *b)
{
    return a && b && a->width == b->width && a->height == b->height &&
           memcmp(a->pixels, b->pixels, sizeof(float) * 3 * npix(a)) == 0;
}

/* rtp_image_diff's statistics; max_abs is +inf when sizes differ or a
   pixel is not finite (so a CHECK on it fails). */
static rtp_diff_stats diff(const rtp_image *a, const rtp_image *b, double threshold)
{
    rtp_diff_stats d;
    memset(&d, 0, sizeof d);
    d.max_abs = HUGE_VAL;
    if (!a || !b || count_nonfinite(a) || count_nonfinite(b) ||
        rtp_image_diff(a, b, threshold, &d, NULL) != RTP_OK)
        d.max_abs = HUGE_VAL;
    return d;
}

static double max_abs(const rtp_image *a, const rtp_image *b) { return diff(a, b, 1.0).max_abs; }

/* An error status from a shadow mode is acceptable (reported) if it is a
   well-formed error; a crash-like failure is one that is not. */
static int well_formed_error(rtp_status st, const rtp_error *err)
{
    return st >= RTP_ERR_NOMEM && st <= RTP_ERR_KEY && err->status == st &&
           err->message[0] != '\0';
}


/* ------------------------------------------------ the common checks */

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}


static const char *const mode_names[] = {"exact", "lightbuf", "itembuf"};

/* Records the scene, checks the trace and every re-evaluation mode (see
   the top), prints one summary line.  light: the light edited and moved
   (-1: the scene has none); pos: where it moves.  *trace_out (may be
   NULL) receives the trace's image. */
static void check_modes(const char *label, const rtp_scene *s, const rtp_trace_options *o,
                        int light, const double *pos, rtp_image **trace_out)
{
    rtp_tree *t = NULL;
    rtp_image *img = NULL, *re = NULL, *ref = NULL;
    rtp_eval_options eo;
    rtp_error err;
    rtp_status st;
    char key[64], val[128];
    double dcol = -1.0, dmove[3] = {-1.0, -1.0, -1.0}, share_item = 0.0, effect = -1.0;
    double t0 = now();
    int m;

    if (trace_out)
        *trace_out = NULL;
    memset(&eo, 0, sizeof eo);
    /* Direction cubes of 256 cells a side: ample for these tiny scenes,
       and a quarter of a second per cube less than the default 1024. */
    eo.shadow_res = 256;
    st = rtp_record(s, o, &t, &img, NULL, &err);
    CHECK_MSG(st == RTP_OK, "%s: record: %s", label, err.message);
    if (st != RTP_OK)
        return;
    CHECK_MSG(count_nonfinite(img) == 0, "%s: %zu non-finite values in the trace", label,
              count_nonfinite(img));
    /* No edits: bit for bit. */
    st = rtp_tree_eval(t, &eo, &re, NULL, &err);
    CHECK_MSG(st == RTP_OK && same_bits(img, re),
              "%s: re-evaluation without edits differs from the trace", label);
    rtp_image_destroy(re);
    re = NULL;

    if (light < 0 && pos) {
        /* No light to edit: add one (decided like a moved light). */
        for (m = 0; m < 3; m++) {
            rtp_image *mv = NULL;
            if (rtp_tree_add_light(t, pos, &err) != RTP_OK) {
                CHECK_MSG(0, "%s: add a light: %s", label, err.message);
                break;
            }
            if (!ref && rtp_tree_trace(t, 1, &ref, NULL, &err) != RTP_OK) {
                CHECK_MSG(0, "%s: trace with the added light: %s", label, err.message);
                break;
            }
            eo.shadows = m == 0 ? RTP_SHADOWS_EXACT
                                : m == 1 ? RTP_SHADOWS_LIGHTBUF : RTP_SHADOWS_ITEMBUF;
            st = rtp_tree_eval(t, &eo, &mv, NULL, &err);
            if (st != RTP_OK) {
                fprintf(stderr, "note: %s: added light, %s shadows: %s (%s)\n", label,
                        mode_names[m], rtp_status_string(st), err.message);
                CHECK_MSG(well_formed_error(st, &err), "%s: %s: malformed error", label,
                          mode_names[m]);
            } else {
                CHECK_MSG(count_nonfinite(mv) == 0, "%s: added light, %s: non-finite pixels",
                          label, mode_names[m]);
                dmove[m] = max_abs(mv, ref);
                if (m == 0)
                    CHECK_MSG(dmove[m] <= 1e-6,
                              "%s: added light, exact shadows, differs from a full trace by %g",
                              label, dmove[m]);
                if (m == 0)
                    effect = max_abs(mv, img);
            }
            rtp_image_destroy(mv);
            rtp_tree_destroy(t);
            t = NULL;
            if (m < 2 && rtp_record(s, o, &t, NULL, NULL, &err) != RTP_OK) {
                CHECK_MSG(0, "%s: record: %s", label, err.message);
                break;
            }
        }
        rtp_image_destroy(ref);
    } else if (light >= 0) {
        /* A light colour edit (class A): exact. */
        snprintf(key, sizeof key, "light.%d.color", light);
        st = rtp_tree_set(t, key, "0.3,0.6,0.9", &err);
        CHECK_MSG(st == RTP_OK, "%s: %s: %s", label, key, err.message);
        if (st == RTP_OK && rtp_tree_eval(t, &eo, &re, NULL, &err) == RTP_OK &&
            rtp_tree_trace(t, 1, &ref, NULL, &err) == RTP_OK) {
            CHECK_MSG(count_nonfinite(re) == 0, "%s: colour edit: non-finite pixels", label);
            dcol = max_abs(re, ref);
            CHECK_MSG(dcol <= 1e-6, "%s: colour edit differs from a full trace by %g", label,
                      dcol);
        } else {
            CHECK_MSG(0, "%s: colour edit: %s", label, err.message);
        }
        rtp_image_destroy(re);
        rtp_image_destroy(ref);
        re = ref = NULL;
        rtp_tree_destroy(t);
        t = NULL;

        /* A moved light, once per shadow mode, each on a fresh tree. */
        snprintf(key, sizeof key, "light.%d.pos", light);
        snprintf(val, sizeof val, "%.17g,%.17g,%.17g", pos[0], pos[1], pos[2]);
        for (m = 0; m < 3; m++) {
            rtp_image *mv = NULL;
            if (rtp_record(s, o, &t, NULL, NULL, &err) != RTP_OK ||
                rtp_tree_set(t, key, val, &err) != RTP_OK) {
                CHECK_MSG(0, "%s: move %s: %s", label, key, err.message);
                break;
            }
            if (!ref && rtp_tree_trace(t, 1, &ref, NULL, &err) != RTP_OK) {
                CHECK_MSG(0, "%s: trace of the moved scene: %s", label, err.message);
                break;
            }
            CHECK(count_nonfinite(ref) == 0);
            eo.shadows = m == 0 ? RTP_SHADOWS_EXACT
                                : m == 1 ? RTP_SHADOWS_LIGHTBUF : RTP_SHADOWS_ITEMBUF;
            st = rtp_tree_eval(t, &eo, &mv, NULL, &err);
            if (st != RTP_OK) {
                fprintf(stderr, "note: %s: moved light, %s shadows: %s (%s)\n", label,
                        mode_names[m], rtp_status_string(st), err.message);
                CHECK_MSG(well_formed_error(st, &err), "%s: %s: malformed error", label,
                          mode_names[m]);
            } else {
                rtp_diff_stats d = diff(mv, ref, 1e-3);
                CHECK_MSG(count_nonfinite(mv) == 0, "%s: moved light, %s: non-finite pixels",
                          label, mode_names[m]);
                dmove[m] = d.max_abs;
                if (m == 0)
                    effect = max_abs(mv, img);
                if (m == 0)
                    CHECK_MSG(d.max_abs <= 1e-6,
                              "%s: moved light, exact shadows, differs from a full trace by %g",
                              label, d.max_abs);
                else if (m == 1 && d.max_abs > 1e-6)
                    fprintf(stderr,
                            "note: %s: moved light, lightbuf differs from a full trace by %g "
                            "(%.2f%% of pixels > 1e-3)\n",
                            label, d.max_abs, 100.0 * d.share_above);
                else if (m == 2)
                    share_item = d.share_above;
            }
            rtp_image_destroy(mv);
            rtp_tree_destroy(t);
            t = NULL;
        }
        rtp_image_destroy(ref);
    }
    rtp_tree_destroy(t);
    printf("%-24s %2dx%-2d colour edit %.0e; light %s (changes up to %.2f): exact %.0e "
           "lightbuf %.0e itembuf %.0e (%.1f%% > 1e-3); %.2f s\n",
           label, img->width, img->height, dcol, light >= 0 ? "moved" : "added", effect,
           dmove[0], dmove[1], dmove[2], 100.0 * share_item, now() - t0);
    if (trace_out)
        *trace_out = img;
    else
        rtp_image_destroy(img);
}

/* Loads scenes/stiff/NAME, runs check_modes with default options. */
static rtp_image *file_case(const char *name, int light, double x, double y, double z)
{
    rtp_scene *s = load_file(name);
    rtp_image *img = NULL;
    rtp_trace_options o;
    double pos[3];
    pos[0] = x;
    pos[1] = y;
    pos[2] = z;
    memset(&o, 0, sizeof o);
    CHECK_MSG(s != NULL, "%s does not load", name);
    if (!s)
        return NULL;
    check_modes(name, s, &o, light, pos, &img);
    rtp_scene_destroy(s);
    return img;
}

/* ------------------------------------------------------------- cases */

/* Grazing rays at a plane and at a sphere's silhouette: no speckle. */
static void test_grazing(void)
{
    rtp_image *img = file_case("grazing_plane.nff", 0, 0, 50, 3);
    size_t i, hit = 0, bg = 0, dark = 0;
    if (img) {
        for (i = 0; i < npix(img); i++) {
            float r = img->pixels[3 * i];
            if (r == 0.0f)
                bg++;
            else if (r >= 0.999f)
                hit++;
            else
                dark++;
        }
        printf("  grazing plane: %zu lit plane pixels, %zu background, %zu dark\n", hit, bg,
               dark);
        CHECK(hit > npix(img) / 4 && bg > npix(img) / 4);
        CHECK_MSG(dark == 0, "%zu speckled (dark) plane pixels", dark);
        rtp_image_destroy(img);
    }
    img = file_case("grazing_sphere.nff", 0, 3, -10, 3);
    if (img) {
        size_t sph = 0, acne = 0;
        float minlit = 1.0f;
        for (i = 0; i < npix(img); i++) {
            const float *p = img->pixels + 3 * i;
            if (p[1] > 0.0f) {
                sph++;
                if (!(p[1] > 0.1f + 1e-7f))
                    acne++;
                if (p[1] - 0.1f < minlit)
                    minlit = p[1] - 0.1f;
            }
        }
        printf("  grazing sphere: %zu sphere pixels, %zu at ambient level (acne), smallest "
               "lit term %.3g\n",
               sph, acne, (double)minlit);
        CHECK(sph > 100);
        CHECK_MSG(acne == 0, "%zu sphere pixels facing the light are shadowed", acne);
        rtp_image_destroy(img);
    }
}

/* The same scene at scale 1e-4 and 1e6 (camera, geometry, lights): the
   images equal the unit-scale image. */
static void test_scale(void)
{
    rtp_image *unit = file_case("scale_1.nff", 0, 2, -3, 5);
    rtp_image *small = file_case("scale_1e-4.nff", 0, 2e-4, -3e-4, 5e-4);
    rtp_image *big = file_case("scale_1e6.nff", 0, 2e6, -3e6, 5e6);
    if (unit && small && big) {
        rtp_diff_stats ds = diff(small, unit, 1e-3), db = diff(big, unit, 1e-3);
        printf("  scale 1e-4 vs 1: max %.2e mae %.2e, %.2f%% pixels > 1e-3\n", ds.max_abs,
               ds.mae, 100 * ds.share_above);
        printf("  scale 1e6  vs 1: max %.2e mae %.2e, %.2f%% pixels > 1e-3\n", db.max_abs,
               db.mae, 100 * db.share_above);
        /* Float geometry and float hit positions round differently at
           each scale (relative 6e-8): measured max 1.8e-7.  Allow a small
           mean error and an edge pixel or two flipping. */
        CHECK(ds.mae <= 1e-5 && ds.share_above <= 2.0 / npix(unit));
        CHECK(db.mae <= 1e-5 && db.share_above <= 2.0 / npix(unit));
    }
    rtp_image_destroy(unit);
    rtp_image_destroy(small);
    rtp_image_destroy(big);
}

/* Geometry 1e5 from the origin: equals the scene at the origin; a plane
   facing the light has no acne. */
static void test_offset(void)
{
    rtp_image *unit = file_case("scale_1.nff", 0, 2, -3, 5);
    rtp_image *far = file_case("offset_1e5.nff", 0, 100002, 99997, 100005);
    rtp_image *plane = file_case("offset_plane.nff", 0, 100010, 100020, 100002);
    size_t i, unlit = 0;
    if (unit && far) {
        rtp_diff_stats d = diff(far, unit, 1e-2);
        printf("  offset 1e5 vs 0: max %.2e mae %.2e, %.2f%% pixels > 1e-2\n", d.max_abs, d.mae,
               100 * d.share_above);
        /* At 1e5 a float position (the tree's) is good to ~4e-3: shading
           normals, reflected rays and shadow edges move by that much.
           Measured: mae 5e-4, 3 of 1024 pixels > 1e-2 (two shadow-edge
           pixels flip, one reflection). */
        CHECK(d.mae <= 2e-3 && d.share_above <= 0.01);
    }
    if (plane) {
        for (i = 0; i < npix(plane); i++)
            if (!(plane->pixels[3 * i] >= 0.999f))
                unlit++;
        printf("  offset plane: %zu of %zu pixels unlit\n", unlit, npix(plane));
        CHECK_MSG(unlit == 0, "%zu acne pixels on a plane facing the light at 1e5", unlit);
    }
    rtp_image_destroy(unit);
    rtp_image_destroy(far);
    rtp_image_destroy(plane);
}

/* Coincident and nearly coplanar quads: lit, never shadowed by the twin;
   the nearer of two 1e-6 apart wins; deterministic. */
static void test_coplanar(void)
{
    rtp_image *img = file_case("coplanar.nff", 0, 0.5, 0.2, 3), *img1 = NULL;
    rtp_scene *s = load_file("coplanar.nff");
    rtp_trace_options o;
    int x, y, bad = 0, left_red = 0, right_red = 0, right_green = 0;
    if (!img || !s) {
        CHECK(0);
        rtp_image_destroy(img);
        rtp_scene_destroy(s);
        return;
    }
    for (y = 0; y < img->height; y++)
        for (x = 0; x < img->width; x++) {
            const float *p = px(img, x, y);
            int red = p[0] >= 0.999f && p[1] == 0.0f && p[2] == 0.0f;
            int green = p[1] >= 0.999f && p[0] == 0.0f && p[2] == 0.0f;
            int bg = p[0] == 0.0f && p[1] == 0.0f && p[2] == 1.0f;
            if (!red && !green && !bg)
                bad++;
            if (x < img->width / 2)
                left_red += red;
            else {
                right_red += red;
                right_green += green;
            }
        }
    printf("  coplanar: %d pixels neither lit nor background; 1e-6 apart: %d red (under) "
           "pixels; coincident: %d red, %d green\n",
           bad, left_red, right_red, right_green);
    CHECK_MSG(bad == 0, "%d coplanar pixels shadowed or mixed", bad);
    CHECK_MSG(left_red == 0, "the quad 1e-6 below shows through in %d pixels", left_red);
    CHECK(right_red + right_green > 0);
    memset(&o, 0, sizeof o);
    o.threads = 2;
    CHECK(rtp_trace(s, &o, &img1, NULL, NULL) == RTP_OK && same_bits(img, img1));
    rtp_image_destroy(img1);
    rtp_image_destroy(img);
    rtp_scene_destroy(s);
}

/* Zero-area triangles are never hit; needles do not produce NaN. */
static void test_degenerate(void)
{
    rtp_image *img = file_case("degenerate.nff", 0, -1, -2, 6);
    size_t i, red = 0, cyan = 0;
    if (!img) {
        CHECK(0);
        return;
    }
    for (i = 0; i < npix(img); i++) {
        const float *p = img->pixels + 3 * i;
        red += p[0] != 0.0f;
        cyan += p[1] > 0.0f && p[2] > 0.0f && p[2] == p[1];
    }
    printf("  degenerate: %zu pixels hit a zero-area triangle, %zu show a needle\n", red, cyan);
    CHECK_MSG(red == 0, "a zero-area triangle was hit in %zu pixels", red);
    rtp_image_destroy(img);
}

/* Rays exactly along the axes. */
static void test_axes(void)
{
    rtp_image *img = file_case("axes.nff", 0, 1, 1, 8);
    if (!img) {
        CHECK(0);
        return;
    }
    {
        const float *c = px(img, 8, 8), *k = px(img, 0, 0), *k2 = px(img, 16, 16);
        printf("  axes: middle pixel %.3f %.3f %.3f, corners %.3f / %.3f (red)\n",
               (double)c[0], (double)c[1], (double)c[2], (double)k[0], (double)k2[0]);
        CHECK_MSG(c[0] > 0.5f && c[0] > 4.0f * c[1] && c[0] > 4.0f * c[2],
                  "the middle ray (0,0,-1) does not show the red sphere");
        CHECK_MSG(k[0] > 0.05f && k2[0] > 0.05f, "a corner does not show the floor");
    }
    rtp_image_destroy(img);
}

/* A light on a surface, a light inside a closed object. */
static void test_light_placement(void)
{
    /* Light 0 moves within the floor plane: direction cubes centred on a
       surface. */
    rtp_image *img = file_case("light_on_surface.nff", 0, -0.5, -1, 0);
    rtp_scene *s;
    rtp_tree *t = NULL;
    rtp_image *off = NULL, *ref = NULL;
    rtp_trace_options o;
    memset(&o, 0, sizeof o);
    if (img) {
        /* With the other light off, the floor (grey pixels) shows ambient
           only: light 0 lies in its plane, n.l = 0. */
        s = load_file("light_on_surface.nff");
        if (s && rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK &&
            rtp_tree_set(t, "light.1.on", "0", NULL) == RTP_OK &&
            rtp_tree_eval(t, NULL, &off, NULL, NULL) == RTP_OK) {
            size_t i, floor = 0, wrong = 0;
            for (i = 0; i < npix(off); i++) {
                const float *p = off->pixels + 3 * i;
                if (p[0] == p[1] && p[1] == p[2] && p[0] > 0.0f) {
                    floor++;
                    if (fabs(p[0] - 0.2) > 1e-6)
                        wrong++;
                }
            }
            printf("  light on the floor plane: %zu floor pixels, %zu not ambient-only\n",
                   floor, wrong);
            CHECK(floor > 100 && wrong == 0);
        } else {
            CHECK(0);
        }
        rtp_image_destroy(off);
        off = NULL;
        rtp_tree_destroy(t);
        t = NULL;
        rtp_scene_destroy(s);
        rtp_image_destroy(img);
    }

    /* The light moves within the sphere: still dark outside. */
    img = file_case("light_inside.nff", 0, 0.2, -0.1, 1.3);
    s = load_file("light_inside.nff");
    if (img && s) {
        int m;
        for (m = 0; m < 3; m++) {
            rtp_eval_options eo;
            rtp_image *mv = NULL;
            memset(&eo, 0, sizeof eo);
            eo.shadows = m == 0 ? RTP_SHADOWS_EXACT
                                : m == 1 ? RTP_SHADOWS_LIGHTBUF : RTP_SHADOWS_ITEMBUF;
            if (rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK &&
                rtp_tree_set(t, "light.0.pos", "0.2,-0.1,1.3", NULL) == RTP_OK &&
                rtp_tree_eval(t, &eo, &mv, NULL, NULL) == RTP_OK) {
                double d = max_abs(mv, img);
                CHECK_MSG(d <= 1e-6, "light moved inside the sphere, %s shadows: the "
                          "outside changes by %g", mode_names[m], d);
            }
            rtp_image_destroy(mv);
            rtp_tree_destroy(t);
            t = NULL;
        }
    }
    if (img && s && rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK &&
        rtp_tree_set(t, "light.0.on", "0", NULL) == RTP_OK &&
        rtp_tree_eval(t, NULL, &off, NULL, NULL) == RTP_OK &&
        rtp_tree_trace(t, 1, &ref, NULL, NULL) == RTP_OK) {
        double d1 = max_abs(img, off), d2 = max_abs(img, ref);
        printf("  light inside a sphere: on vs off %.1e (re-evaluated), %.1e (traced)\n", d1,
               d2);
        CHECK(d1 <= 1e-6 && d2 <= 1e-6);
    } else {
        CHECK(0);
    }
    rtp_image_destroy(off);
    rtp_image_destroy(ref);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* Phong exponents 0, 1, 1e4, 1e6: finite; 1e6 a tiny highlight. */
static void test_phong(void)
{
    rtp_image *img = file_case("phong.nff", 0, 0, -10, -3);
    rtp_scene *s = load_file("phong.nff");
    rtp_tree *t = NULL;
    rtp_image *flat = NULL;
    rtp_trace_options o;
    int band[4] = {0, 0, 0, 0}, x, y, m, ok = 1;
    const int edge[5] = {0, 11, 24, 37, 48};
    char key[32];
    memset(&o, 0, sizeof o);
    if (!img || !s || rtp_record(s, &o, &t, NULL, NULL, NULL) != RTP_OK) {
        CHECK(0);
        goto done;
    }
    /* Exponent 1e18: no highlight anywhere (pow underflows to 0). */
    for (m = 0; m < 4; m++) {
        snprintf(key, sizeof key, "mat.%d.shine", m);
        ok &= rtp_tree_set(t, key, "1e18", NULL) == RTP_OK;
    }
    CHECK(ok && rtp_tree_eval(t, NULL, &flat, NULL, NULL) == RTP_OK);
    if (!flat)
        goto done;
    CHECK(count_nonfinite(flat) == 0);
    for (m = 0; m < 4; m++)
        for (y = 0; y < img->height; y++)
            for (x = edge[m]; x < edge[m + 1]; x++)
                band[m] += px(img, x, y)[0] > px(flat, x, y)[0] + 1e-4f;
    printf("  phong: highlight pixels for exponent 0: %d, 1: %d, 1e4: %d, 1e6: %d\n", band[0],
           band[1], band[2], band[3]);
    CHECK(band[0] > 50 && band[1] > 20);
    CHECK(band[3] <= 4 && band[3] <= band[2] && band[2] < band[1]);
done:
    rtp_image_destroy(flat);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* Drops the lines starting with `prefix` from text (a fresh string). */
static char *drop_lines(const char *text, const char *prefix)
{
    size_t n = strlen(text), k = strlen(prefix);
    char *out = (char *)malloc(n + 1), *o = out;
    const char *p = text;
    if (!out)
        return NULL;
    while (*p) {
        const char *e = strchr(p, '\n');
        size_t len = e ? (size_t)(e - p) + 1 : strlen(p);
        if (strncmp(p, prefix, k) != 0) {
            memcpy(o, p, len);
            o += len;
        }
        p += len;
    }
    *o = '\0';
    return out;
}

/* ior 1 glass vanishes; ior 1.0001 nearly; diamond from inside; total
   internal reflection. */
static void test_glass(void)
{
    char *text = read_text(SCENES "glass_ior1.nff", NULL), *bare = NULL;
    rtp_scene *s = NULL, *sb = NULL, *sd = NULL;
    rtp_image *img = NULL, *without = NULL, *near = NULL, *ref = NULL;
    rtp_tree *t = NULL;
    rtp_trace_options o;
    rtp_trace_stats ts;
    rtp_eval_stats es;
    memset(&o, 0, sizeof o);
    memset(&es, 0, sizeof es);
    CHECK(text != NULL);
    if (!text)
        return;
    bare = drop_lines(text, "s ");
    s = load_text(text, SCENES "glass_ior1.nff");
    sb = load_text(bare, SCENES "glass_ior1-without.nff");
    if (s && sb) {
        rtp_diff_stats d, dn;
        check_modes("glass_ior1.nff", s, &o, -1, (const double[3]){2, -3, 4}, &img);
        CHECK(rtp_trace(sb, &o, &without, NULL, NULL) == RTP_OK);
        d = diff(img, without, 1e-3);
        printf("  ior 1: vs the scene without the sphere: max %.2e, %.2f%% pixels > 1e-3\n",
               d.max_abs, 100 * d.share_above);
        CHECK(d.max_abs <= 1e-5);
        /* ior 1.0001, a class-D edit (traced again): nearly vanishes. */
        if (rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK &&
            rtp_tree_set(t, "mat.1.ior", "1.0001", NULL) == RTP_OK &&
            rtp_tree_eval(t, NULL, &near, &es, NULL) == RTP_OK &&
            rtp_tree_trace(t, 1, &ref, NULL, NULL) == RTP_OK) {
            dn = diff(near, without, 1e-3);
            printf("  ior 1.0001: vs without: max %.2e mae %.2e, %.2f%% pixels > 1e-3; "
                   "re-evaluated (%llu samples traced again) vs traced: %.1e\n",
                   dn.max_abs, dn.mae, 100 * dn.share_above, es.retraced_samples,
                   max_abs(near, ref));
            CHECK(count_nonfinite(near) == 0 && max_abs(near, ref) <= 1e-6);
            CHECK(dn.share_above <= 0.05 && dn.mae <= 5e-3);
        } else {
            CHECK(0);
        }
    } else {
        CHECK(0);
    }

    /* Diamond seen from inside: total internal reflection. */
    sd = load_file("diamond.nff");
    if (sd) {
        rtp_image *di = NULL;
        check_modes("diamond.nff", sd, &o, 0, (const double[3]){-2, -3, 4}, NULL);
        memset(&ts, 0, sizeof ts);
        CHECK(rtp_trace(sd, &o, &di, &ts, NULL) == RTP_OK && count_nonfinite(di) == 0);
        printf("  diamond from inside: %llu refracted, %llu reflected rays (ks 0: total "
               "internal reflection)\n",
               ts.refracted_rays, ts.reflected_rays);
        CHECK(ts.reflected_rays > 0 && ts.refracted_rays > 0);
        rtp_image_destroy(di);
    } else {
        CHECK(0);
    }
    rtp_scene_destroy(sd);
    rtp_image_destroy(img);
    rtp_image_destroy(without);
    rtp_image_destroy(near);
    rtp_image_destroy(ref);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    rtp_scene_destroy(sb);
    free(bare);
    free(text);
}

/* Depth 1, default, 64 in a hall of mirrors; the node cap in a hall of
   mirrors and glass. */
static void test_depth(void)
{
    rtp_scene *s = load_file("mirrors.nff");
    rtp_trace_options o;
    rtp_trace_stats ts;
    rtp_tree *t = NULL;
    rtp_tree_info ti;
    rtp_error err;
    rtp_image *img = NULL;
    const int depths[3] = {1, 0, 64};
    int i;
    const double pos[3] = {1, -1, 2.5};
    if (!s) {
        CHECK(0);
        return;
    }
    for (i = 0; i < 3; i++) {
        char label[64];
        memset(&o, 0, sizeof o);
        o.max_depth = depths[i];
        snprintf(label, sizeof label, "mirrors.nff depth %d", depths[i]);
        check_modes(label, s, &o, 0, pos, NULL);
        memset(&ts, 0, sizeof ts);
        CHECK(rtp_record(s, &o, &t, NULL, &ts, NULL) == RTP_OK);
        if (t) {
            rtp_tree_get_info(t, &ti);
            printf("  depth %d: %d recorded, %llu nodes for %llu samples, %llu eye hits, "
                   "%llu reflected rays\n",
                   depths[i], ti.max_depth, ti.nodes, ti.samples, ts.eye_hits,
                   ts.reflected_rays);
            CHECK(ti.nodes <= ti.samples * (unsigned long long)ti.max_depth);
            if (depths[i] == 1)
                CHECK(ti.nodes == ts.eye_hits && ts.reflected_rays == 0);
            if (depths[i] == 0)
                CHECK(ti.max_depth == 5);
            if (depths[i] == 64)
                CHECK(ti.nodes > ti.samples * 10);
        }
        rtp_tree_destroy(t);
        t = NULL;
    }
    memset(&o, 0, sizeof o);
    o.max_depth = -1;
    CHECK(rtp_trace(s, &o, &img, NULL, &err) == RTP_ERR_ARGUMENT && !img);
    rtp_scene_destroy(s);

    /* A closed box of mirrors with glass spheres, ambient light only (no
       shadow rays, to keep it quick): every glass hit spawns two rays, so
       at depth 64 the tree would grow without end; the per-sample node
       cap (2^20, lib/trace.c) must hold.  One sample. */
    {
        static const char text[] =
            "b 0.1 0.15 0.3\nv\nfrom 0 -1.5 1.5\nat 0.3 3 1.2\nup 0 0 1\nangle 30\n"
            "hither 0.01\nresolution 1 1\nambient 0.3 0.3 0.3\n"
            "f 0.9 0.9 0.9 0.1 0.9 100 0 0\n"
            "p 4\n-2 -5 0\n-2 5 0\n-2 5 3\n-2 -5 3\n"
            "p 4\n2 -5 0\n2 -5 3\n2 5 3\n2 5 0\n"
            "p 4\n-2 -5 0\n2 -5 0\n2 5 0\n-2 5 0\n"
            "p 4\n-2 -5 3\n-2 5 3\n2 5 3\n2 -5 3\n"
            "p 4\n-2 5 0\n2 5 0\n2 5 3\n-2 5 3\n"
            "p 4\n-2 -5 0\n-2 -5 3\n2 -5 3\n2 -5 0\n"
            "f 1 1 1 0.1 0.5 100 0.5 1.5\n"
            "s 0 1 1.5 0.6\ns 0.8 2.5 1.2 0.4\ns -1 -3 1 0.5\n";
        double t0 = now();
        s = load_text(text, "glass-hall");
        memset(&o, 0, sizeof o);
        o.max_depth = 64;
        if (s) {
            rtp_image *re = NULL;
            CHECK(rtp_record(s, &o, &t, &img, &ts, NULL) == RTP_OK);
            if (t) {
                rtp_tree_get_info(t, &ti);
                printf("  glass hall of mirrors, depth 64, 1 sample: %llu nodes (cap %u), "
                       "%llu rays, %.2f s\n",
                       ti.nodes, 1u << 20, ts.reflected_rays + ts.refracted_rays + 1,
                       now() - t0);
                CHECK(ti.nodes <= (1u << 20) && ti.nodes > (1u << 19));
                CHECK(count_nonfinite(img) == 0);
                CHECK(rtp_tree_eval(t, NULL, &re, NULL, NULL) == RTP_OK && same_bits(img, re));
            }
            rtp_image_destroy(re);
            rtp_image_destroy(img);
            rtp_tree_destroy(t);
        } else {
            CHECK(0);
        }
        rtp_scene_destroy(s);
    }
}

/* No lights; 1000 lights (the > 32 lights visibility words). */
static void test_lights(void)
{
    rtp_image *img = file_case("nolights.nff", -1, 1, -2, 3);
    char *text;
    size_t cap = 64 * 1024, n;
    int i, j;
    if (img) {
        /* The bottom row sees the matte floor. */
        const float *p = px(img, 0, img->height - 1);
        printf("  no lights: floor %.6f %.6f %.6f (ambient * kd * colour: 0.2 0.4 0.8)\n",
               (double)p[0], (double)p[1], (double)p[2]);
        CHECK(fabs(p[0] - 0.2) < 1e-6 && fabs(p[1] - 0.4) < 1e-6 && fabs(p[2] - 0.8) < 1e-6);
        rtp_image_destroy(img);
    }

    text = (char *)malloc(cap);
    if (!text) {
        CHECK(0);
        return;
    }
    n = (size_t)snprintf(text, cap,
                         "# 1000 lights over a floor with a sphere and a box\n"
                         "b 0.1 0.15 0.3\nv\nfrom 0 -6 4\nat 0 0 0.5\nup 0 0 1\nangle 40\n"
                         "hither 0.01\nresolution 24 24\n");
    for (j = 0; j < 25; j++)
        for (i = 0; i < 40; i++)
            n += (size_t)snprintf(text + n, cap - n, "l %.3f %.3f %.3f\n", -4 + 0.2 * i,
                                  -4 + 0.33 * j, 5 + 0.01 * (i % 7));
    snprintf(text + n, cap - n,
             "f 0.8 0.8 0.75 0.9 0 1 0 0\np 4\n-4 -4 0\n4 -4 0\n4 4 0\n-4 4 0\n"
             "f 0.9 0.2 0.15 0.7 0.3 30 0 0\ns -1 0.5 1 1\n"
             "f 0.2 0.8 0.3 0.8 0 1 0 0\np 4\n1 -1 1.5\n2.5 -1 1.5\n2.5 0.5 1.5\n1 0.5 1.5\n");
    {
        rtp_scene *s = load_text(text, "lights1000");
        rtp_scene_info si;
        rtp_trace_options o;
        rtp_tree *t = NULL;
        rtp_image *base = NULL, *off = NULL, *ref = NULL;
        const double pos[3] = {3, -3, 2};
        memset(&o, 0, sizeof o);
        if (!s) {
            CHECK(0);
            free(text);
            return;
        }
        rtp_scene_get_info(s, &si);
        CHECK(si.lights == 1000);
        check_modes("1000 lights (light 700)", s, &o, 700, pos, &base);
        if (base && rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK &&
            rtp_tree_set(t, "light.500.on", "0", NULL) == RTP_OK &&
            rtp_tree_eval(t, NULL, &off, NULL, NULL) == RTP_OK &&
            rtp_tree_trace(t, 1, &ref, NULL, NULL) == RTP_OK) {
            double changed = max_abs(off, base), d = max_abs(off, ref);
            printf("  1000 lights, light 500 off: changes the image by up to %.2e; "
                   "re-evaluated vs traced %.1e\n",
                   changed, d);
            CHECK(changed > 1e-4 && d <= 1e-6);
        } else {
            CHECK(0);
        }
        rtp_image_destroy(base);
        rtp_image_destroy(off);
        rtp_image_destroy(ref);
        rtp_tree_destroy(t);
        rtp_scene_destroy(s);
    }
    free(text);
}

/* 1x1 images; sizes over the memory and size limits; an empty scene. */
static void test_sizes(void)
{
    rtp_scene *s = load_file("scale_1.nff");
    rtp_trace_options o;
    rtp_error err;
    rtp_image *img = NULL;
    rtp_tree *t = NULL;
    rtp_status st;
    const double pos[3] = {2, -3, 5};
    if (!s) {
        CHECK(0);
        return;
    }
    memset(&o, 0, sizeof o);
    o.width = o.height = 1;
    check_modes("scale_1.nff 1x1", s, &o, 0, pos, NULL);

    /* A 64x64 trace with a 10 kB limit: refused, before tracing. */
    memset(&o, 0, sizeof o);
    o.width = o.height = 64;
    o.memory_limit = 10000;
    st = rtp_record(s, &o, &t, &img, NULL, &err);
    printf("  64x64 within 10 kB: %s: %s\n", rtp_status_string(st), err.message);
    CHECK(st == RTP_ERR_LIMIT && !t && !img && strstr(err.message, "memory limit"));
    st = rtp_trace(s, &o, &img, NULL, &err);
    CHECK(st == RTP_ERR_LIMIT && !img && strstr(err.message, "memory limit"));
    /* Huge sizes under the default limits. */
    o.memory_limit = 0;
    o.width = o.height = 1 << 20;
    st = rtp_record(s, &o, &t, &img, NULL, &err);
    printf("  2^20 x 2^20 by default: %s: %s\n", rtp_status_string(st), err.message);
    CHECK(st == RTP_ERR_LIMIT && !t && !img && err.message[0]);
    o.width = o.height = 40000;
    st = rtp_trace(s, &o, &img, NULL, &err);
    printf("  40000 x 40000 by default: %s: %s\n", rtp_status_string(st), err.message);
    CHECK(st == RTP_ERR_LIMIT && !img && err.message[0]);
    rtp_scene_destroy(s);

    /* An empty scene: the background, exactly, everywhere. */
    img = file_case("empty.nff", 0, -1, -1, 1);
    if (img) {
        size_t i, bad = 0;
        for (i = 0; i < npix(img); i++) {
            const float *p = img->pixels + 3 * i;
            bad += p[0] != 0.25f || p[1] != 0.5f || p[2] != 0.75f;
        }
        CHECK_MSG(bad == 0, "%zu pixels of the empty scene are not the background", bad);
        rtp_image_destroy(img);
    }
    s = load_file("empty.nff");
    memset(&o, 0, sizeof o);
    o.width = o.height = 1;
    if (s)
        check_modes("empty.nff 1x1", s, &o, 0, pos, NULL);
    rtp_scene_destroy(s);
}

int main(void)
{
    double t0 = now();
    RUN(test_grazing);
    RUN(test_scale);
    RUN(test_offset);
    RUN(test_coplanar);
    RUN(test_degenerate);
    RUN(test_axes);
    RUN(test_light_placement);
    RUN(test_phong);
    RUN(test_glass);
    RUN(test_depth);
    RUN(test_lights);
    RUN(test_sizes);
    fprintf(stderr, "test_stiff: %.2f s\n", now() - t0);
    return check_report();
}
