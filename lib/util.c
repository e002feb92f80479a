/* util.c — allocation hooks, errors, version: what every file needs. */
#if defined(__linux__) && !defined(_GNU_SOURCE)
#define _GNU_SOURCE /* madvise, mremap (below) */
#endif
#include "internal.h"

#include <errno.h>
#include <langinfo.h>
#include <stdarg.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#if defined(__linux__)
#include <sys/mman.h>
#include <stdint.h>
#include <unistd.h>
#endif

/* Large arrays (ray trees, evaluation caches, images) are written once
   from start to end soon after they are made, so what a large block
   costs is mostly its pages' first touch, and that depends on the
   machine.

   Transparent huge pages (MADV_HUGEPAGE) are asked for only on the
   blocks realloc grows (below: the ray trees while trace records them,
   a kd-tree's nodes while it is built), not on the blocks malloc makes
   (an evaluation's caches, the colour planes, a tree read from a file,
   images).  Sessions 11-44 asked on every block of 1 MiB and more: on
   session 11's VM a fresh 4 KiB page cost 10 us (2.5 ms a MiB) and a
   fresh huge page 0.13-2.3 ms (2 MiB zeroed), and the caches of an
   evaluation took 400-2200 faults, half of a material's first kd edit on
   balls (7.8 -> 3.9 ms).  On session 44-45's host (KVM, Linux 6.18, THP
   "madvise", defrag "madvise", a virtio balloon that reports free memory
   back to the host in 2 MiB blocks: page_reporting_order 9) a fresh
   4 KiB page costs 0.45-0.6 ms a MiB and an advised huge page 2.2-6.4 ms
   a MiB on its first touch (a probe touching every page of 64 MiB; perf:
   99% clear_page_erms, the guest zeroing memory the host backs again
   page by page), 0.13 ms when the same 2 MiB come back within the
   balloon's 2 s delay.  A huge page takes a whole free 2 MiB block,
   which the host has taken back; small pages come first from those the
   guest freed last, still backed.  With the guest's memory fragmented
   (session 44: 22.7 GB of page cache) advised faults also compacted
   memory (compact_stall 6,389).  Measured in session 45 (the seven SPD
   scenes, builds in turn, CPU time): advised, streams of six edits on a
   tree read from its file took 1.4x the time at 1024x1024 (sys 0.5 s
   against 0.2) and 1.1x at 512x512, first evaluations up to 2-3x (0.7x
   right after another process freed its huge pages), first light-colour
   edits 0.75x (1-2 ms less), moves on the advised tree 0.93-0.98x;
   recording and traces within 2-5%, resident peaks 5-25% more.  The
   grown blocks keep the advice: the recorded trees, which every edit in
   the process reads (moves, and a stream of the tree's bytes 1.5x faster
   than in small pages), and what saved most on session 11's VM; with THP
   "always" the system gives huge pages to every block unasked.

   A block realloc makes of 1 MiB or more is a mapping of its own,
   2 MiB-aligned, whole 2 MiB pages, so that growing it moves its pages
   with mremap instead of copying them.  Memory a process touches for the
   first time is what costs in a VM (its kernel zeroes each page while
   the host backs it: 0.6-2.7 ms a MiB on session 11's VM; clear_page was
   a sixth of recording mount_s6 at 1024x1024 in perf), and a growing
   tree copied into fresh blocks touched 116 MB for its 63.  Recording
   mount_s6 at 1024x1024, the best of three over the best of three
   traces, one process each, three processes of each build in turn:
   +5.6..+18% copied, +1.3..+1.9% moved (session 11).  Blocks malloc makes
   stay plain malloc blocks, which glibc hands the memory of blocks freed
   before (until session 45 they were 2 MiB-aligned inside 2 MiB more
   than they held, in size classes an eighth apart, for the huge pages:
   without the advice the same, a stream of 20 camera edits of balls at
   512x512 took 113 MB resident and 40,900 faults, now 93 MB, 36,000).
   Every block carries a header of two words before it, so that free and
   realloc can tell the kinds apart and know the size: the mapping's
   length (0: malloc's) and the size asked.  Not under AddressSanitizer,
   whose checks of the heap the mappings would escape (RTPI_ASAN:
   internal.h), nor under ThreadSanitizer, which does not see mremap
   (RTPI_TSAN). */
#if defined(__linux__) && defined(MREMAP_MAYMOVE) && defined(MREMAP_FIXED) && \
    !defined(RTPI_ASAN) && !defined(RTPI_TSAN)
#define RTPI_BIG_MIN ((size_t)1 << 20)
#define RTPI_BIG_ALIGN ((size_t)2 << 20)
/* where a block's data starts: 16 bytes in keep malloc's alignment; a
   mapping's starts a cache line in */
#define RTPI_HDR 16
#define RTPI_BIG_HDR 64

typedef struct {
    size_t maplen; /* the mapping's length; 0: in malloc's heap */
    size_t size;   /* what was asked for */
} blk_hdr;

static blk_hdr *hdr_of(void *p)
{
    return (blk_hdr *)(void *)((char *)p - RTPI_HDR);
}

/* The start of block p as malloc or mmap gave it. */
static char *base_of(void *p)
{
    return (char *)p - (hdr_of(p)->maplen ? RTPI_BIG_HDR : RTPI_HDR);
}

/* Whole 2 MiB for size bytes and a mapping's header; 0 when too large. */
static size_t big_len(size_t size)
{
    if (size > (size_t)-1 - RTPI_BIG_HDR - RTPI_BIG_ALIGN)
        return 0;
    return (size + RTPI_BIG_HDR + RTPI_BIG_ALIGN - 1) & ~(RTPI_BIG_ALIGN - 1);
}

/* A fresh 2 MiB-aligned mapping of len bytes (a multiple of 2 MiB),
   advised for huge pages as a whole, or NULL. */
static char *map_aligned(size_t len)
{
    char *m, *a;
    size_t head;
    if (len > (size_t)-1 - RTPI_BIG_ALIGN)
        return NULL;
    m = (char *)mmap(NULL, len + RTPI_BIG_ALIGN, PROT_READ | PROT_WRITE,
                     MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (m == (char *)MAP_FAILED)
        return NULL;
    a = (char *)(((uintptr_t)m + RTPI_BIG_ALIGN - 1) & ~(uintptr_t)(RTPI_BIG_ALIGN - 1));
    head = (size_t)(a - m);
    if (head)
        (void)munmap(m, head);
    (void)munmap(a + len, RTPI_BIG_ALIGN - head);
#if defined(MADV_HUGEPAGE)
    (void)madvise(a, len, MADV_HUGEPAGE); /* advice only */
#endif
    return a;
}

/* A block of size bytes (1 MiB or more) as a mapping of its own, or
   NULL. */
static void *map_block(size_t size)
{
    size_t len = big_len(size);
    char *m = len ? map_aligned(len) : NULL;
    if (!m)
        return NULL;
    hdr_of(m + RTPI_BIG_HDR)->maplen = len;
    hdr_of(m + RTPI_BIG_HDR)->size = size;
    return m + RTPI_BIG_HDR;
}

static void *default_malloc(void *user, size_t size)
{
    blk_hdr *h;
    char *b;
    (void)user;
    if (size > (size_t)-1 - RTPI_HDR)
        return NULL;
    b = (char *)malloc(size + RTPI_HDR);
    if (!b)
        return NULL;
    h = (blk_hdr *)(void *)b;
    h->maplen = 0;
    h->size = size;
    return b + RTPI_HDR;
}

static void default_free(void *user, void *p)
{
    blk_hdr *h;
    (void)user;
    if (!p)
        return;
    h = hdr_of(p);
    if (h->maplen)
        (void)munmap(base_of(p), h->maplen);
    else
        free(base_of(p));
}

static void *default_realloc(void *user, void *p, size_t size)
{
    blk_hdr *h;
    char *m;
    size_t len;
    if (!p) {
        /* a block made by realloc is one that grows (the recorded trees
           start at their estimate's size): a mapping from the start where
           it is large, so that its pages are the huge ones the growth
           keeps; malloc's where no mapping can be had */
        void *np = size >= RTPI_BIG_MIN ? map_block(size) : NULL;
        return np ? np : default_malloc(user, size);
    }
    h = hdr_of(p);
    if (size < RTPI_BIG_MIN && !h->maplen) {
        char *b = (char *)realloc(base_of(p), size + RTPI_HDR);
        if (!b)
            return NULL;
        ((blk_hdr *)(void *)b)->size = size;
        return b + RTPI_HDR;
    }
    if (size < RTPI_BIG_MIN || !h->maplen) {
        /* into a block of the other kind (a heap block growing past 1 MiB
           becomes a mapping): a new block, the bytes both hold */
        void *np = size < RTPI_BIG_MIN ? default_malloc(user, size) : map_block(size);
        if (!np)
            return NULL;
        memcpy(np, p, h->size < size ? h->size : size);
        default_free(user, p);
        return np;
    }
    /* a mapping growing or shrinking: its pages move, none is copied, in
       place where the addresses after it are free, else to a fresh
       aligned range (a huge page the system gives stays whole only
       2 MiB-aligned) */
    m = base_of(p);
    len = big_len(size);
    if (!len)
        return NULL;
    if (len != h->maplen) {
        char *to = (char *)mremap(m, h->maplen, len, 0);
        if (to == (char *)MAP_FAILED) {
            char *dst = map_aligned(len);
            if (!dst)
                return NULL;
            to = (char *)mremap(m, h->maplen, len, MREMAP_MAYMOVE | MREMAP_FIXED, dst);
            if (to == (char *)MAP_FAILED) {
                (void)munmap(dst, len);
                return NULL;
            }
        }
        m = to;
        hdr_of(m + RTPI_BIG_HDR)->maplen = len;
    }
    hdr_of(m + RTPI_BIG_HDR)->size = size;
    return m + RTPI_BIG_HDR;
}
#else
static void *default_malloc(void *user, size_t size)
{
    (void)user;
    return malloc(size);
}
static void *default_realloc(void *user, void *p, size_t size)
{
    (void)user;
    return realloc(p, size);
}
static void default_free(void *user, void *p)
{
    (void)user;
    free(p);
}
#endif

int rtpi_allocator_partial(const rtp_allocator *a)
{
    int n = a ? !!a->malloc_fn + !!a->realloc_fn + !!a->free_fn : 0;
    return n > 0 && n < 3;
}

rtp_status rtpi_allocator_refused(rtp_error *err, const char *fn)
{
    return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                      "%s: an allocator needs malloc_fn, realloc_fn and free_fn all three "
                      "(or none, or NULL: the library's own)",
                      fn);
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

int rtpi_allocator_is_default(const rtp_allocator *a)
{
    return a->malloc_fn == default_malloc;
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

/* Blocks about to be written whole (a cache every entry of which the
   next pass writes, a block calloc zeroes): their pages are made in one
   call (MADV_POPULATE_WRITE, Linux 5.14) instead of a page fault each as
   the writes reach them.  On session 46's host (KVM, 4 KiB pages) a fault
   a page cost 0.25 ms a MiB of pages the guest had freed just before
   and 0.35-0.6 of others, the populate 0.11-0.15: the trap and return a
   page, not the zeroing, was half the cost (the rest: the kernel's page
   allocation and cgroup accounting).  mount_s6 at 512x512: a first
   evaluation took 12,741 faults (50 MB: ev_terms, ev_coeffs, ev_nv,
   ev_w, the material lists), 17 of its 53 ms; populated, 49 ms.  Only
   for blocks of the default allocator (a user's may not be memory of
   this process to populate) and only where every byte is written soon:
   a block made and not used (the room of a light's plane, the kd planes'
   block, which holds more entries than an edit writes, a capacity grown
   ahead) must stay untouched (test_alloc's test_large_block_untouched).
   Advice only: where the kernel lacks it the writes fault as before. */
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
#define RTPI_PREFAULT_MIN ((size_t)256 << 10)
void rtpi_prefault(const rtp_allocator *a, void *p, size_t n)
{
    long pg;
    uintptr_t lo, hi;
    if (!p || n < RTPI_PREFAULT_MIN || !rtpi_allocator_is_default(a))
        return;
    pg = sysconf(_SC_PAGESIZE);
    if (pg <= 0)
        return;
    /* whole pages inside the block: a page it shares with another
       block is faulted (or there) already */
    lo = ((uintptr_t)p + (uintptr_t)pg - 1) & ~(uintptr_t)(pg - 1);
    hi = ((uintptr_t)p + n) & ~(uintptr_t)(pg - 1);
    if (hi > lo)
        (void)madvise((void *)lo, (size_t)(hi - lo), MADV_POPULATE_WRITE);
}
#else
void rtpi_prefault(const rtp_allocator *a, void *p, size_t n)
{
    (void)a;
    (void)p;
    (void)n;
}
#endif

void *rtpi_calloc_array(const rtp_allocator *a, size_t count, size_t size)
{
    void *p = rtpi_malloc_array(a, count, size);
    if (p) {
        rtpi_prefault(a, p, count * size);
        memset(p, 0, count * size);
    }
    return p;
}

size_t rtpi_grow_cap(size_t cap, size_t need)
{
    size_t ncap = cap ? cap : 16;
    while (ncap < need) {
        if (ncap > (size_t)-1 / 2)
            return 0;
        ncap *= 2;
    }
    return ncap;
}

int rtpi_grow(const rtp_allocator *a, void **p, size_t *cap, size_t need,
              size_t size)
{
    size_t ncap;
    void *np;
    if (need <= *cap)
        return 0;
    if (!(ncap = rtpi_grow_cap(*cap, need)))
        return -1;
    if (size && ncap > (size_t)-1 / size)
        return -1;
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

/* Whether byte c continues a UTF-8 sequence (is not a character's first). */
static int utf8_cont(char c)
{
    return ((unsigned char)c & 0xc0u) == 0x80u;
}

void rtpi_fit_text(char *dst, size_t size, const char *text, int whole)
{
    size_t n = strlen(text), head, tail = 0, dots = size >= 8 ? 3 : 0;
    const char *t = text + n;
    if (!size)
        return;
    if (whole && n < size) {
        memcpy(dst, text, n + 1);
        return;
    }
    head = size - 1 - dots;
    /* a message cut at its end lost what went wrong: a key or a path of
       hundreds of bytes comes first ("mat.NAME.kd: no such material"),
       the reason after it; a third of the room keeps the end */
    if (whole && dots) {
        tail = head / 3;
        head -= tail;
        t = text + n - tail;
        while (utf8_cont(*t))
            t++;
    }
    if (head > n)
        head = n;
    while (head > 0 && utf8_cont(text[head]))
        head--;
    memcpy(dst, text, head);
    memcpy(dst + head, "...", dots);
    memcpy(dst + head + dots, t, (size_t)(text + n - t));
    dst[head + dots + (size_t)(text + n - t)] = '\0';
}

rtp_status rtpi_error(rtp_error *err, rtp_status status, const char *file,
                      int line, int col, const char *fmt, ...)
{
    va_list ap;
    /* the message whole, then fitted to err->message (a key or a value
       of hundreds of bytes had pushed out the reason after it, and the
       cut could split a character in two); past this, its start */
    char whole[768];
    int got;
    if (!err)
        return status;
    err->status = status;
    err->file[0] = '\0';
    if (file) {
        size_t n = strlen(file);
        if (n < sizeof err->file) {
            memcpy(err->file, file, n + 1);
        } else {
            /* too long: its end, which names the file ("...dir/x.png"),
               from a character's first byte on (a cut ".pn" named
               another file) */
            const char *tail = file + n - (sizeof err->file - 4);
            while (utf8_cont(*tail))
                tail++;
            memcpy(err->file, "...", 3);
            memcpy(err->file + 3, tail, strlen(tail) + 1);
        }
    }
    err->line = line;
    err->column = col;
    va_start(ap, fmt);
    got = vsnprintf(whole, sizeof whole, fmt, ap);
    va_end(ap);
    if (got < 0)
        whole[0] = '\0';
    rtpi_fit_text(err->message, sizeof err->message, whole,
                  got >= 0 && (size_t)got < sizeof whole);
    return status;
}

char *rtp_error_format(const rtp_error *err, char *buf, size_t size)
{
    /* (no byte read past a field: one a caller filled itself need not
       end in a NUL) */
    const int fw = (int)sizeof err->file, mw = (int)sizeof err->message;
    if (!buf || !size)
        return buf;
    if (!err) {
        snprintf(buf, size, "unknown error");
    } else if (err->file[0] && err->line > 0 && err->column > 0) {
        snprintf(buf, size, "%.*s:%d:%d: %.*s", fw, err->file, err->line, err->column, mw,
                 err->message);
    } else if (err->file[0] && err->line > 0) {
        snprintf(buf, size, "%.*s:%d: %.*s", fw, err->file, err->line, mw, err->message);
    } else if (err->file[0]) {
        snprintf(buf, size, "%.*s: %.*s", fw, err->file, mw, err->message);
    } else if (err->line > 0 && err->column > 0) {
        /* (no file: a scene from rtp_scene_load_memory named "" still
           says where, as rtp.h's "as much as is known" promises) */
        snprintf(buf, size, "%d:%d: %.*s", err->line, err->column, mw, err->message);
    } else if (err->line > 0) {
        snprintf(buf, size, "%d: %.*s", err->line, mw, err->message);
    } else if (err->message[0]) {
        snprintf(buf, size, "%.*s", mw, err->message);
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
    case RTP_ERR_CANCELLED: return "cancelled";
    }
    return "unknown status";
}

unsigned rtp_version_number(void) { return RTP_VERSION_NUMBER; }

unsigned rtp_features(void)
{
    unsigned f = 0;
#if defined(RTP_HAVE_PNG) && RTP_HAVE_PNG
    f |= RTP_FEATURE_PNG;
#endif
#ifdef RTP_HAVE_THREADS
    f |= RTP_FEATURE_THREADS;
#endif
#ifdef RTP_HAVE_OSMESA
    f |= RTP_FEATURE_OSMESA;
#endif
    return f;
}

#define RTPI_STR2(x) #x
#define RTPI_STR(x) RTPI_STR2(x)
const char *rtp_version_string(void)
{
    return RTPI_STR(RTP_VERSION_MAJOR) "." RTPI_STR(RTP_VERSION_MINOR) "." RTPI_STR(RTP_VERSION_PATCH);
}

rtp_status rtpi_text_nul(const char *text, size_t size, const char *name, rtp_error *err)
{
    const char *z = size ? (const char *)memchr(text, '\0', size) : NULL, *p;
    int line = 1, col = 1;
    if (!z)
        return RTP_OK;
    /* (lines end as the lexer ends them: '\n', or a '\r' alone) */
    for (p = text; p < z; p++) {
        if (*p == '\n' || (*p == '\r' && p[1] != '\n'))
            line++, col = 1;
        else
            col++;
    }
    return rtpi_error(err, RTP_ERR_PARSE, name, line, col,
                      "a NUL byte: not a text file (binary, or UTF-16?)");
}

rtp_status rtpi_read_file(const rtp_allocator *a, const char *path,
                          char **text, size_t *size, rtp_error *err)
{
    FILE *f;
    char *buf = NULL, *nb;
    size_t cap = 0, len = 0, n;
    int is_stdin = strcmp(path, "-") == 0, read_errno = 0;
    f = is_stdin ? stdin : fopen(path, "rb");
    if (is_stdin)
        path = "<stdin>"; /* (its name in errors, as every reader's) */
    if (!f)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot open: %s",
                          strerror(errno));
    {
        /* (stdin too: `rtp trace - < folder` said only "read error") */
        struct stat sb;
        if (fstat(fileno(f), &sb) == 0 && S_ISDIR(sb.st_mode)) {
            if (!is_stdin)
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
        errno = 0;
        n = fread(buf + len, 1, cap - len - 1, f);
        if (n && memchr(buf + len, '\0', n)) {
            /* Every file read here is a scene's text: a NUL byte means a
               binary or UTF-16 file (or /dev/zero, which would be read
               until memory ran out), refused where it is first seen. */
            rtp_status st = rtpi_text_nul(buf, len + n, path, err);
            rtpi_free(a, buf);
            if (!is_stdin)
                fclose(f);
            return st;
        }
        len += n;
        if (n == 0) {
            read_errno = errno; /* (before fclose or free can change it) */
            break;
        }
    }
    if (ferror(f)) {
        rtpi_free(a, buf);
        if (!is_stdin)
            fclose(f);
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "read error: %s",
                          read_errno ? strerror(read_errno) : "the stream failed");
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

/* ------------------------------------------------------------ numbers */

/* The current decimal point when it is not ".", else NULL.  nl_langinfo
   follows the thread's locale (uselocale) as strtod and printf do, and
   unlike localeconv writes no shared state. */
static const char *other_point(void)
{
    const char *dp = nl_langinfo(RADIXCHAR);
    return dp && *dp && strcmp(dp, ".") != 0 ? dp : NULL;
}

double rtpi_strtod(const char *s, char **end)
{
    const char *dp = other_point(), *dot, *s0;
    char buf[512], *e;
    size_t n, dl, at, used;
    double d;
    if (!dp)
        return strtod(s, end);
    /* strtod's leading white space (the C locale's isspace) */
    s0 = s;
    while (*s == ' ' || (*s >= '\t' && *s <= '\r'))
        s++;
    /* A copy of the number's characters, its '.' the locale's point; the
       copy ends where they do, so that strtod never meets the locale's
       point in s ("1,5" is two numbers in a key's value, not 1.5).  A
       number longer than any float needs is cut at the buffer. */
    for (n = 0; n < sizeof buf - 8 && s[n] && strchr("0123456789+-.eExXpPaAbBcCdDfFiInNtTyY", s[n]);
         n++)
        ;
    dot = (const char *)memchr(s, '.', n);
    dl = strlen(dp);
    if (dl > 7)
        dl = 7; /* (no locale has one that long) */
    at = dot ? (size_t)(dot - s) : n;
    memcpy(buf, s, at);
    if (dot) {
        memcpy(buf + at, dp, dl);
        memcpy(buf + at + dl, dot + 1, n - at - 1);
        buf[n - 1 + dl] = '\0';
    } else {
        buf[n] = '\0';
    }
    d = strtod(buf, &e);
    used = (size_t)(e - buf);
    /* back to s's characters: the point took dl bytes for one */
    if (dot && used > at)
        used -= dl - 1;
    if (end) /* (no number: strtod's end is where it began) */
        *end = (char *)(uintptr_t)(used ? s + used : s0);
    return d;
}

void rtpi_fmt_g(char *out, size_t size, int prec, double v)
{
    const char *dp;
    char *p;
    snprintf(out, size, "%.*g", prec, v);
    dp = other_point();
    if (dp && (p = strstr(out, dp)) != NULL) {
        size_t dl = strlen(dp);
        *p = '.';
        memmove(p + 1, p + dl, strlen(p + dl) + 1);
    }
}

/* (a whole MiB alone said "a direction cube of 64 cells a face takes up
   to 1 MiB, over the memory limit of 0.05 MiB" of 0.094 MiB, and "lists
   1 MiB" under a limit of 0.435 that 0.44 met: the figure to raise the
   limit to, off by 2-10x) */
double rtpi_mib_up(double bytes)
{
    double m = bytes / 1048576.0, p;
    if (!(m > 0.0) || m >= 100.0 || !(m < HUGE_VAL))
        return ceil(m);
    p = pow(10.0, 2.0 - floor(log10(m)));
    /* (a product rounded up a step past m * p, or a quotient past the
       digits, shows one unit more: still at least what is needed) */
    return ceil(m * p) / p;
}
