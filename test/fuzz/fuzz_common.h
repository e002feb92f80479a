/* fuzz_common.h — what the fuzz targets share: an allocator that caps a
 * single request (so a reader that trusts a length shows up as a finding,
 * not as an out-of-memory kill), a check that a loaded scene traces and
 * re-evaluates consistently, and the replay main (replay.h). */
#ifndef RTP_FUZZ_COMMON_H
#define RTP_FUZZ_COMMON_H

#include "rtp.h"
#include "internal.h"
#include "replay.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Largest single allocation a reader may make for a fuzz input: every
   input here is at most a few hundred kilobytes, and no reader should
   need more than this for one. */
#if defined(__GNUC__)
#define FUZZ_UNUSED __attribute__((unused))
#else
#define FUZZ_UNUSED
#endif

#define FUZZ_ALLOC_MAX ((size_t)256 << 20)

static inline void *fuzz_malloc(void *user, size_t size)
{
    (void)user;
    if (size > FUZZ_ALLOC_MAX) {
        fprintf(stderr, "fuzz: allocation of %zu bytes\n", size);
        abort();
    }
    return malloc(size);
}

static inline void *fuzz_realloc(void *user, void *p, size_t size)
{
    (void)user;
    if (size > FUZZ_ALLOC_MAX) {
        fprintf(stderr, "fuzz: reallocation to %zu bytes\n", size);
        abort();
    }
    return realloc(p, size);
}

static inline void fuzz_free(void *user, void *p)
{
    (void)user;
    free(p);
}

FUZZ_UNUSED static const rtp_allocator fuzz_alloc = {fuzz_malloc, fuzz_realloc, fuzz_free, NULL};

/* For readers of streams, which cannot know the data's length before
   they allocate an image the header asks for: a request over the cap
   fails (the reader must report RTP_ERR_NOMEM cleanly) instead of
   aborting. */
static inline void *fuzz_soft_malloc(void *user, size_t size)
{
    (void)user;
    return size > FUZZ_ALLOC_MAX ? NULL : malloc(size);
}

static inline void *fuzz_soft_realloc(void *user, void *p, size_t size)
{
    (void)user;
    return size > FUZZ_ALLOC_MAX ? NULL : realloc(p, size);
}

FUZZ_UNUSED static const rtp_allocator fuzz_soft_alloc = {fuzz_soft_malloc, fuzz_soft_realloc,
                                              fuzz_free, NULL};

/* Aborts (a finding) when cond is false. */
#define FUZZ_ASSERT(cond)                                                   \
    do {                                                                    \
        if (!(cond)) {                                                      \
            fprintf(stderr, "%s:%d: fuzz assertion failed: %s\n", __FILE__, \
                    __LINE__, #cond);                                       \
            abort();                                                        \
        }                                                                   \
    } while (0)

/* A status the documented contract allows for a failed call. */
static inline int fuzz_status_ok(rtp_status st)
{
    return st >= RTP_OK && st <= RTP_ERR_KEY;
}

/* Error messages must be NUL-terminated and formattable. */
static inline void fuzz_check_error(const rtp_error *err, rtp_status st)
{
    char buf[700];
    FUZZ_ASSERT(fuzz_status_ok(st));
    if (st == RTP_OK)
        return;
    FUZZ_ASSERT(err->status == st);
    FUZZ_ASSERT(memchr(err->message, '\0', sizeof err->message) != NULL);
    FUZZ_ASSERT(memchr(err->file, '\0', sizeof err->file) != NULL);
    FUZZ_ASSERT(err->message[0] != '\0');
    rtp_error_format(err, buf, sizeof buf);
    FUZZ_ASSERT(memchr(buf, '\0', sizeof buf) != NULL);
}

/* Traces a tiny image of the scene, records its trees and checks the
   brief's promise: evaluating the unedited trees reproduces the traced
   image bit for bit, and rtp_trace gives the same image as rtp_record. */
static inline void fuzz_trace_scene(const rtp_scene *s, int w, int h)
{
    rtp_trace_options opt;
    rtp_image *img = NULL, *rec = NULL, *ev = NULL;
    rtp_tree *tree = NULL;
    rtp_error err;
    rtp_status st;
    memset(&opt, 0, sizeof opt);
    opt.width = w;
    opt.height = h;
    opt.threads = 1;
    memset(&err, 0, sizeof err);
    st = rtp_trace(s, &opt, &img, NULL, &err);
    fuzz_check_error(&err, st);
    if (st != RTP_OK)
        return;
    st = rtp_record(s, &opt, &tree, &rec, NULL, &err);
    fuzz_check_error(&err, st);
    if (st == RTP_OK) {
        FUZZ_ASSERT(rec->width == img->width && rec->height == img->height);
        FUZZ_ASSERT(memcmp(rec->pixels, img->pixels,
                           sizeof(float) * 3 * (size_t)w * (size_t)h) == 0);
        st = rtp_tree_eval(tree, NULL, &ev, NULL, &err);
        fuzz_check_error(&err, st);
        if (st == RTP_OK)
            FUZZ_ASSERT(memcmp(ev->pixels, img->pixels,
                               sizeof(float) * 3 * (size_t)w * (size_t)h) == 0);
    }
    rtp_image_destroy(ev);
    rtp_image_destroy(rec);
    rtp_image_destroy(img);
    rtp_tree_destroy(tree);
}

/* Inputs that name device or process files could block or never end
   (a mtllib of /dev/zero); the targets skip them. */
static inline int fuzz_names_special_file(const uint8_t *data, size_t size)
{
    static const char *const bad[] = {"/dev", "/proc", "/sys", "/run"};
    size_t i, k;
    for (k = 0; k < sizeof bad / sizeof *bad; k++) {
        size_t n = strlen(bad[k]);
        for (i = 0; i + n <= size; i++)
            if (memcmp(data + i, bad[k], n) == 0)
                return 1;
    }
    return 0;
}

#endif
