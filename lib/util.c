/* util.c — allocation hooks, errors, version: what every file needs. */
#if defined(__linux__) && !defined(_DEFAULT_SOURCE)
#define _DEFAULT_SOURCE /* madvise (below) */
#endif
#include "internal.h"

#include <errno.h>
#include <stdarg.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#if defined(__linux__)
#include <sys/mman.h>
#include <stdint.h>
#endif

/* Large arrays (ray trees, evaluation caches, images) are written once
   from start to end soon after they are made, and in a virtual machine a
   page fault costs microseconds: tens of thousands of them were a third
   of what recording added to a trace.  Where Linux has transparent huge
   pages in "madvise" mode, the default allocator asks for them on the
   2 MiB-aligned inside of blocks of 1 MiB and more (a user's allocator is
   left as it is).  Why 1 MiB: on the development VM a fresh 4 KiB page
   cost 10 us (2.5 ms a MiB) and a fresh huge page 0.13-2.3 ms (2 MiB
   zeroed), so a block of 1 MiB touched through costs less as one huge
   page, for at most 1 MiB more resident memory; from 4 MiB on (session
   11) the 1-4 MiB caches of an evaluation (path weights, q, the planes'
   pixel lists) took 400-2200 faults: half of a material's first kd edit
   on balls (7.8 -> 3.9 ms) and most of a first light-colour edit. */
#if defined(__linux__) && defined(MADV_HUGEPAGE)
#define RTPI_HUGE_MIN ((size_t)1 << 20)
#define RTPI_HUGE_PAGE ((uintptr_t)2 << 20)
static void *huge_advice(void *p, size_t size)
{
    if (p && size >= RTPI_HUGE_MIN) {
        uintptr_t a = ((uintptr_t)p + RTPI_HUGE_PAGE - 1) & ~(RTPI_HUGE_PAGE - 1);
        uintptr_t b = ((uintptr_t)p + size) & ~(RTPI_HUGE_PAGE - 1);
        if (b > a)
            (void)madvise((void *)a, (size_t)(b - a), MADV_HUGEPAGE); /* advice only */
    }
    return p;
}
#else
static void *huge_advice(void *p, size_t size)
{
    (void)size;
    return p;
}
#endif

static void *default_malloc(void *user, size_t size)
{
    (void)user;
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (size >= RTPI_HUGE_MIN && size <= (size_t)-1 - RTPI_HUGE_PAGE) {
        /* aligned and rounded up to whole huge pages, so that every page
           of the block can be one (a fresh block's first touch then costs
           a fault per 2 MiB, not per 4 KiB); realloc and free take it */
        size_t whole = (size + RTPI_HUGE_PAGE - 1) & ~(size_t)(RTPI_HUGE_PAGE - 1);
        void *p = NULL;
        if (posix_memalign(&p, (size_t)RTPI_HUGE_PAGE, whole) == 0)
            return huge_advice(p, whole);
        return NULL;
    }
#endif
    return malloc(size);
}
static void *default_realloc(void *user, void *p, size_t size)
{
    (void)user;
    return huge_advice(realloc(p, size), size);
}
static void default_free(void *user, void *p)
{
    (void)user;
    free(p);
}

void rtpi_allocator_init(rtp_allocator *out, const rtp_allocator *in)
{
    if (in && in->malloc_fn && in->realloc_fn && in->free_fn) {
        *out = *in;
    } else {
        out->malloc_fn = default_malloc;
        out->realloc_fn = default_realloc;
        out->free_fn = default_free;
        out->user = NULL;
    }
}

void *rtpi_malloc(const rtp_allocator *a, size_t size)
{
    return a->malloc_fn(a->user, size ? size : 1);
}

void *rtpi_realloc(const rtp_allocator *a, void *p, size_t size)
{
    return a->realloc_fn(a->user, p, size ? size : 1);
}

void rtpi_free(const rtp_allocator *a, void *p)
{
    if (p)
        a->free_fn(a->user, p);
}

void *rtpi_malloc_array(const rtp_allocator *a, size_t count, size_t size)
{
    if (size && count > (size_t)-1 / size)
        return NULL;
    return rtpi_malloc(a, count * size);
}

void *rtpi_calloc_array(const rtp_allocator *a, size_t count, size_t size)
{
    void *p = rtpi_malloc_array(a, count, size);
    if (p)
        memset(p, 0, count * size);
    return p;
}

int rtpi_grow(const rtp_allocator *a, void **p, size_t *cap, size_t need,
              size_t size)
{
    size_t ncap;
    void *np;
    if (need <= *cap)
        return 0;
    ncap = *cap ? *cap : 16;
    while (ncap < need) {
        if (ncap > (size_t)-1 / 2)
            return -1;
        ncap *= 2;
    }
    if (size && ncap > (size_t)-1 / size)
        return -1;
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (*p && a->realloc_fn == default_realloc && ncap * size >= RTPI_HUGE_MIN) {
        /* realloc copies into pages it touches before huge_advice can
           ask for huge ones: one 4 KiB fault per page copied (recording
           mount_s6 at 1024x1024: 14,500, a sixth of the trace's time).
           A fresh block advised first, then the copy: a fault per 2 MiB. */
        np = default_malloc(a->user, ncap * size);
        if (!np)
            return -1;
        memcpy(np, *p, *cap * size);
        default_free(a->user, *p);
        *p = np;
        *cap = ncap;
        return 0;
    }
#endif
    np = rtpi_realloc(a, *p, ncap * size);
    if (!np)
        return -1;
    *p = np;
    *cap = ncap;
    return 0;
}

char *rtpi_strdup(const rtp_allocator *a, const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = (char *)rtpi_malloc(a, n);
    if (d)
        memcpy(d, s, n);
    return d;
}

rtp_status rtpi_error(rtp_error *err, rtp_status status, const char *file,
                      int line, int col, const char *fmt, ...)
{
    va_list ap;
    if (!err)
        return status;
    err->status = status;
    err->file[0] = '\0';
    if (file) {
        strncpy(err->file, file, sizeof err->file - 1);
        err->file[sizeof err->file - 1] = '\0';
    }
    err->line = line;
    err->column = col;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    return status;
}

char *rtp_error_format(const rtp_error *err, char *buf, size_t size)
{
    if (!buf || !size)
        return buf;
    if (!err) {
        snprintf(buf, size, "unknown error");
    } else if (err->file[0] && err->line > 0 && err->column > 0) {
        snprintf(buf, size, "%s:%d:%d: %s", err->file, err->line, err->column,
                 err->message);
    } else if (err->file[0] && err->line > 0) {
        snprintf(buf, size, "%s:%d: %s", err->file, err->line, err->message);
    } else if (err->file[0]) {
        snprintf(buf, size, "%s: %s", err->file, err->message);
    } else if (err->message[0]) {
        snprintf(buf, size, "%s", err->message);
    } else {
        snprintf(buf, size, "%s", rtp_status_string(err->status));
    }
    return buf;
}

const char *rtp_status_string(rtp_status status)
{
    switch (status) {
    case RTP_OK: return "ok";
    case RTP_ERR_NOMEM: return "out of memory";
    case RTP_ERR_IO: return "input/output error";
    case RTP_ERR_PARSE: return "parse error";
    case RTP_ERR_ARGUMENT: return "invalid argument";
    case RTP_ERR_UNSUPPORTED: return "not supported by this build";
    case RTP_ERR_FORMAT: return "corrupt, truncated or foreign file";
    case RTP_ERR_LIMIT: return "size limit exceeded";
    case RTP_ERR_KEY: return "unknown parameter key";
    }
    return "unknown status";
}

unsigned rtp_version_number(void) { return RTP_VERSION_NUMBER; }

#define RTPI_STR2(x) #x
#define RTPI_STR(x) RTPI_STR2(x)
const char *rtp_version_string(void)
{
    return RTPI_STR(RTP_VERSION_MAJOR) "." RTPI_STR(RTP_VERSION_MINOR) "." RTPI_STR(RTP_VERSION_PATCH);
}

rtp_status rtpi_read_file(const rtp_allocator *a, const char *path,
                          char **text, size_t *size, rtp_error *err)
{
    FILE *f;
    char *buf = NULL, *nb;
    size_t cap = 0, len = 0, n;
    int is_stdin = strcmp(path, "-") == 0;
    f = is_stdin ? stdin : fopen(path, "rb");
    if (!f)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot open: %s",
                          strerror(errno));
    if (!is_stdin) {
        struct stat sb;
        if (fstat(fileno(f), &sb) != 0 || S_ISDIR(sb.st_mode)) {
            fclose(f);
            return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "is a directory, not a file");
        }
    }
    if (!is_stdin && fseek(f, 0, SEEK_END) == 0) {
        /* a regular file: one allocation of its size (+1 to see EOF) */
        long fsize = ftell(f);
        if (fsize >= 0 && (unsigned long)fsize < (size_t)-2 && fseek(f, 0, SEEK_SET) == 0)
            cap = (size_t)fsize + 2;
        else
            rewind(f);
        if (cap) {
            buf = (char *)rtpi_malloc(a, cap);
            if (!buf) {
                fclose(f);
                return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory reading file");
            }
        }
    }
    for (;;) {
        if (len + 1 >= cap) {
            size_t ncap = cap ? cap * 2 : 65536;
            if (ncap < cap) {
                rtpi_free(a, buf);
                if (!is_stdin)
                    fclose(f);
                return rtpi_error(err, RTP_ERR_LIMIT, path, 0, 0, "file too large");
            }
            nb = (char *)rtpi_realloc(a, buf, ncap);
            if (!nb) {
                rtpi_free(a, buf);
                if (!is_stdin)
                    fclose(f);
                return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory reading file");
            }
            buf = nb;
            cap = ncap;
        }
        n = fread(buf + len, 1, cap - len - 1, f);
        len += n;
        if (n == 0)
            break;
    }
    if (ferror(f)) {
        rtpi_free(a, buf);
        if (!is_stdin)
            fclose(f);
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "read error");
    }
    if (!is_stdin)
        fclose(f);
    buf[len] = '\0';
    *text = buf;
    *size = len;
    return RTP_OK;
}

/* ------------------------------------------------- a locked allocator */

static void *lk_malloc(void *u, size_t n)
{
    rtpi_locked_alloc *l = (rtpi_locked_alloc *)u;
    void *p;
    rtpi_mutex_lock(&l->m);
    p = rtpi_malloc(&l->inner, n);
    rtpi_mutex_unlock(&l->m);
    return p;
}

static void *lk_realloc(void *u, void *q, size_t n)
{
    rtpi_locked_alloc *l = (rtpi_locked_alloc *)u;
    void *p;
    rtpi_mutex_lock(&l->m);
    p = rtpi_realloc(&l->inner, q, n);
    rtpi_mutex_unlock(&l->m);
    return p;
}

static void lk_free(void *u, void *q)
{
    rtpi_locked_alloc *l = (rtpi_locked_alloc *)u;
    rtpi_mutex_lock(&l->m);
    rtpi_free(&l->inner, q);
    rtpi_mutex_unlock(&l->m);
}

int rtpi_locked_alloc_init(rtpi_locked_alloc *l, const rtp_allocator *inner)
{
    l->inner = *inner;
    l->a.malloc_fn = lk_malloc;
    l->a.realloc_fn = lk_realloc;
    l->a.free_fn = lk_free;
    l->a.user = l;
    return rtpi_mutex_init(&l->m) == 0 ? 0 : -1;
}

void rtpi_locked_alloc_destroy(rtpi_locked_alloc *l)
{
    rtpi_mutex_destroy(&l->m);
}
