/* test_memory.c — memory over long runs, in a process of its own (a heap
 * other tests have used would hide what one run does to it): re-traces
 * again and again keep resident memory near what one needs. */
#include "rtp.h"

#include "check.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

int main(void)
{
    RUN(test_retrace_memory_bounded);
    return check_report();
}
