/* test_memory.c — memory over long runs, in a process of its own (a heap
 * other tests have used would hide what one run does to it): re-traces
 * again and again keep resident memory near what one needs. */
#include "rtp.h"

#include "check.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Resident memory (KiB) from /proc/self/status, or -1. */
static long rss_kib(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long v = -1;
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f))
        if (strncmp(line, "VmRSS:", 6) == 0)
            v = strtol(line + 6, NULL, 10);
    fclose(f);
    return v;
}

/* Each re-trace (class D) frees the trees and caches and makes them anew
   at sizes a little different.  The default allocator's large blocks,
   aligned by posix_memalign, never fitted the room the last ones left in
   malloc's heap: 40 ior edits of spheres at 384x288 grew from 60 to 306
   MB resident (a stream of 30 at 512x512 of gears to 711 MB, of 60
   camera edits of balls_s1 from 94 to 367 MB); since session 19 42 to
   51 MB. */
static void test_retrace_memory_bounded(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *img = NULL;
    rtp_trace_options o;
    rtp_eval_options eo;
    rtp_error err;
    long r4 = -1, r40;
    int i;
#if defined(__SANITIZE_ADDRESS__)
    SKIP("built with AddressSanitizer, whose allocator keeps freed memory (quarantine)");
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer)
    SKIP("built with a sanitizer, whose allocator is not the default one");
#endif
#endif
    if (rss_kib() < 0)
        SKIP("no /proc/self/status to read resident memory from");
    if (rtp_scene_load("scenes/spheres.nff", NULL, &s, &err) != RTP_OK) {
        CHECK_MSG(0, "scenes/spheres.nff: %s", err.message);
        return;
    }
    memset(&o, 0, sizeof o);
    memset(&eo, 0, sizeof eo);
    o.width = 384;
    o.height = 288;
    eo.threads = 2;
    eo.incremental = 1; /* one image kept, as --stream keeps it */
    CHECK(rtp_record(s, &o, &t, NULL, NULL, NULL) == RTP_OK);
    CHECK(t && rtp_tree_eval(t, &eo, &img, NULL, NULL) == RTP_OK);
    for (i = 0; t && img && i < 40; i++) {
        CHECK(rtp_tree_set(t, "mat.glass.ior", i % 2 ? "1.2" : "1.3", NULL) == RTP_OK);
        CHECK(rtp_tree_eval_into(t, &eo, img, NULL, NULL) == RTP_OK);
        if (i == 3)
            r4 = rss_kib();
    }
    r40 = rss_kib();
    printf("  40 ior edits at 384x288: %ld KiB resident after 4, %ld after 40\n", r4, r40);
    CHECK_MSG(r40 <= r4 + r4 / 2 + 8192, "resident memory grew from %ld to %ld KiB", r4, r40);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* An allocator that counts the bytes live and their peak. */
typedef struct {
    size_t live, peak;
} counted;

static void *cnt_malloc(void *user, size_t n)
{
    counted *c = (counted *)user;
    size_t *p = (size_t *)malloc(n + 16);
    if (!p)
        return NULL;
    *p = n;
    c->live += n;
    if (c->live > c->peak)
        c->peak = c->live;
    return (char *)p + 16;
}

static void cnt_free(void *user, void *q)
{
    size_t *p;
    if (!q)
        return;
    p = (size_t *)(void *)((char *)q - 16);
    ((counted *)user)->live -= *p;
    free(p);
}

static void *cnt_realloc(void *user, void *q, size_t n)
{
    counted *c = (counted *)user;
    size_t *p = q ? (size_t *)(void *)((char *)q - 16) : NULL, old = p ? *p : 0;
    p = (size_t *)realloc(p, n + 16);
    if (!p)
        return NULL;
    *p = n;
    c->live = c->live - old + n;
    if (c->live > c->peak)
        c->peak = c->live;
    return (char *)p + 16;
}

/* Writes a w x h binary PPM of a pattern; 0 or -1. */
static int write_ppm(const char *path, int w, int h)
{
    FILE *f = fopen(path, "wb");
    int x, y;
    if (!f)
        return -1;
    fprintf(f, "P6\n%d %d\n255\n", w, h);
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            fputc((x * 7 + y) & 255, f);
            fputc((x ^ y) & 255, f);
            fputc((x * y) & 255, f);
        }
    return fclose(f) ? -1 : 0;
}

/* A tree keeps the scene it was traced in, but not a second copy of its
   texture and bump images: they are read only, and shared by the scene
   and its trees (each freed with the last that holds it).  rtp trace -o
   with a 4096x4096 bump map held it twice (the scene's and the tree's
   copy: 200 MB more).  Here a 512x512 texture and a 256x256 bump map
   (3.8 MB of floats) and an 8x8 trace: recording adds far less than
   them, the tree evaluates the same once the scene is gone, and nothing
   is left when both are. */
static void test_tree_shares_textures(void)
{
    char dir[256], tex[300], bump[300], text[1024];
    counted c = {0, 0};
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *i1 = NULL, *i2 = NULL;
    rtp_trace_options o;
    rtp_error err;
    size_t base, images = sizeof(float) * 3 * (512 * 512 + 256 * 256);
    const char *tmp = getenv("TMPDIR"); /* (as the other tests: /tmp was fixed) */
    snprintf(dir, sizeof dir, "%s/rtp-test-memory-XXXXXX", tmp && *tmp ? tmp : "/tmp");
    if (!mkdtemp(dir)) {
        CHECK(!"a temporary folder");
        return;
    }
    snprintf(tex, sizeof tex, "%s/tex.ppm", dir);
    snprintf(bump, sizeof bump, "%s/bump.ppm", dir);
    CHECK(write_ppm(tex, 512, 512) == 0 && write_ppm(bump, 256, 256) == 0);
    snprintf(text, sizeof text,
             "v from 0 -5 0 at 0 0 0 up 0 0 1 angle 40 hither 0.1 resolution 8 8\n"
             "b 0.1 0.1 0.1\nl 2 -6 5\n"
             "f 1 1 1 0.9 0.1 30 0 0\ntexture %s\ns -0.6 0 0 0.5\n"
             "f 0.8 0.6 0.4 0.8 0.2 40 0 0\nbump %s 1\ns 0.6 0 0 0.5\n",
             tex, bump);
    a.malloc_fn = cnt_malloc;
    a.realloc_fn = cnt_realloc;
    a.free_fn = cnt_free;
    a.user = &c;
    memset(&o, 0, sizeof o);
    o.width = 8;
    o.height = 8;
    o.threads = 1;
    if (rtp_scene_load_memory(text, strlen(text), "mem.nff", "nff", &a, &s, &err) != RTP_OK) {
        CHECK_MSG(0, "load: %s", err.message);
    } else {
        CHECK(c.live >= images);
        base = c.live;
        c.peak = c.live;
        CHECK(rtp_record(s, &o, &t, &i1, NULL, &err) == RTP_OK);
        printf("  recording over %lu bytes of images: %ld bytes more at the peak, %ld kept\n",
               (unsigned long)images, (long)(c.peak - base), (long)(c.live - base));
#ifdef RTP_HAVE_THREADS
        CHECK_MSG(c.peak - base < images / 4, "recording took %lu bytes more (images: %lu)",
                  (unsigned long)(c.peak - base), (unsigned long)images);
#else
        /* A build without threads has no lock to count the holders under
           (rtpi_texture_share), and a caller's threads may each record
           from one scene at once (rtp.h): the tree copies the images. */
        CHECK_MSG(c.live - base >= images, "the tree kept %lu bytes (images: %lu)",
                  (unsigned long)(c.live - base), (unsigned long)images);
#endif
        rtp_scene_destroy(s);
        s = NULL;
        CHECK(c.live >= images); /* the tree's */
        if (t && i1) {
            rtp_eval_options eo;
            memset(&eo, 0, sizeof eo);
            eo.threads = 1;
            CHECK(rtp_tree_eval(t, &eo, &i2, NULL, &err) == RTP_OK);
            CHECK(i2 && memcmp(i1->pixels, i2->pixels, sizeof(float) * 3 * 8 * 8) == 0);
        }
        rtp_image_destroy(i1);
        rtp_image_destroy(i2);
        rtp_tree_destroy(t);
        CHECK_MSG(c.live == 0, "%lu bytes left", (unsigned long)c.live);
    }
    remove(tex);
    remove(bump);
    rmdir(dir);
}

int main(void)
{
    RUN(test_retrace_memory_bounded);
    RUN(test_tree_shares_textures);
    return check_report();
}
