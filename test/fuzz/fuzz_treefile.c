/* fuzz_treefile.c — fuzzes the file-based tree readers against the whole
 * read: rtp_tree_read (a regular file; in some runs through a pipe, the
 * stream of unknown size that '-' may be), rtp_tree_read_memory,
 * rtp_tree_read_summary and rtp_tree_eval_file (with an edit callback).
 * Each input is written to a temporary file and read by each; the
 * promises checked (rtp.h):
 *   - no crash, sanitizer report or leak (ASan's leak check at exit);
 *   - rtp_tree_read_memory, rtp_tree_read_summary and rtp_tree_eval_file
 *     give rtp_tree_read's status and message for the same bytes, and
 *     so do all three through a pipe (a stream of unknown size), but for
 *     "bytes after END", which a stream is not read past.
 *     rtp_tree_eval_file's one exception: the edit callback runs once the file's scene is read, before its trees, so
 *     its own error (an edit refused) comes first;
 *   - where rtp_tree_read reads the file: the summary's rtp_tree_get_info
 *     and scene are the whole read's; rtp_tree_eval_file's image, info
 *     and stats are rtp_tree_read's + the same edits + rtp_tree_eval with
 *     no_cache, bit for bit, and an edit refused there is refused alike.
 * As fuzz_tree.c, even-sized inputs have every whole section's CRC
 * recomputed (so mutations reach the parsers), odd-sized ones are read
 * as they are.  The edits, threads and shadow mode come from a hash of
 * the input (fuzz_plan), so a reproducer replays as it failed;
 * RTP_FUZZ_ALL_PLANS=1 runs every plan on each input instead (for seeds,
 * by hand: 176 runs an input), RTP_FUZZ_VERBOSE=1 says what each did.
 *
 * Run (from the top of the repository; build-fuzz/ is clang's libFuzzer
 * build with ASan and UBSan, `make fuzz`):
 *   make build-fuzz/fuzz_treefile
 *   mkdir -p /tmp/tf && build-fuzz/fuzz_treefile -rss_limit_mb=2048 \
 *       -max_len=65536 -max_total_time=1200 /tmp/tf test/fuzz/corpus/fuzz_treefile
 * (-fork=2 -ignore_crashes=1 for both cores, collecting every finding;
 * TMPDIR picks the temporary file's folder.)  Without libFuzzer the same file builds into the replay
 * main `make test` runs over test/fuzz/corpus/fuzz_treefile/
 * (test/cli_fuzz_replay.sh), or by hand:
 *   make build/fuzz/fuzz_treefile && build/fuzz/fuzz_treefile -v FILE...
 * A finding prints "fuzz assertion failed" with what differed. */
#if defined(__linux__) && !defined(_GNU_SOURCE)
#define _GNU_SOURCE /* (F_SETPIPE_SZ) */
#endif
#include <errno.h>
#include <fcntl.h>
#include <unistd.h>

#include "fuzz_common.h"
#include "fuzz_crc.h"

#ifdef RTP_LIBFUZZER
/* libFuzzer's own mutations mostly break a section's length or CRC (even
   sizes get their CRCs recomputed, but an insertion still breaks the
   length); three times in four this mutator instead mutates a window of
   one section's body (the trees' one time in two), writes the section's
   new length and recomputes its CRC, so the mutation reaches the parsers
   of that section, the trees' above all.  (Not in the replay build.) */
size_t LLVMFuzzerMutate(uint8_t *data, size_t size, size_t max_size);
size_t LLVMFuzzerCustomMutator(uint8_t *d, size_t n, size_t max, unsigned int seed);
size_t LLVMFuzzerCustomMutator(uint8_t *d, size_t n, size_t max, unsigned int seed)
{
    size_t at = 8, sat[64], slen[64], ns = 0, pick, body, len, off, sub, extra, got, tail_n, i;
    uint32_t r = seed, c;
    unsigned char *tail;
    int k;
    if (n < 24 || max < n || r % 4 == 0)
        return LLVMFuzzerMutate(d, n, max);
    while (ns < 64 && n - at >= 16) {
        uint64_t l = 0;
        for (k = 7; k >= 0; k--)
            l = l << 8 | d[at + 4 + (size_t)k];
        if (l > n - at - 16)
            break;
        sat[ns] = at;
        slen[ns] = (size_t)l;
        ns++;
        at += 16 + (size_t)l;
    }
    if (ns == 0)
        return LLVMFuzzerMutate(d, n, max);
    r = r * 1103515245u + 12345u;
    pick = (r >> 16) % ns;
    if ((r >> 4) & 1)
        for (i = 0; i < ns; i++)
            if (memcmp(d + sat[i], "TREE", 4) == 0)
                pick = i;
    r = r * 1103515245u + 12345u;
    body = sat[pick] + 12;
    len = slen[pick];
    off = len ? (r >> 8) % (len + 1) : 0;
    r = r * 1103515245u + 12345u;
    sub = len - off < 1 + (r >> 12) % 48 ? len - off : 1 + (r >> 12) % 48;
    extra = max - n < 32 ? max - n : 32;
    tail_n = n - (body + off + sub);
    tail = (unsigned char *)malloc(tail_n ? tail_n : 1);
    if (!tail)
        return n;
    memcpy(tail, d + body + off + sub, tail_n);
    got = sub ? LLVMFuzzerMutate(d + body + off, sub, sub + extra) : 0;
    memcpy(d + body + off + got, tail, tail_n);
    free(tail);
    len = len - sub + got;
    n = n - sub + got;
    for (k = 0; k < 8; k++)
        d[sat[pick] + 4 + (size_t)k] = (unsigned char)((uint64_t)len >> (8 * k));
    c = crc32_of(d + sat[pick], 12 + len);
    for (k = 0; k < 4; k++)
        d[body + len + (size_t)k] = (unsigned char)(c >> (8 * k));
    return n;
}
#endif

/* ------------------------------------------------------------- the plan */

/* The edits of one run (key, value pairs; NULL ends), a light to add. */
typedef struct edit_set {
    const char *kv[8];
    int add;
    int costly; /* traces again (class D, camera): on small files only */
} edit_set;

static const edit_set edit_sets[] = {
    {{NULL}, 0, 0}, /* (the callback, no edit) */
    {{"light.0.color", "1,0.5,0.25", "mat.0.kd", "0.3", "ambient", "0.2", NULL}, 0, 0},
    {{"light.0.pos", "1,-3,6", NULL}, 0, 0},
    {{NULL}, 1, 0},
    {{"light.0.color", "0.2,0.4,1", "mat.0.color", "0.9,0.1,0.1", NULL}, 1, 0},
    {{"light.0.pos", "0.3,-0.4,2", NULL}, 1, 0}, /* (two: read whole) */
    {{"mat.0.ks", "0.5", NULL}, 0, 1},
    {{"camera.angle", "30", NULL}, 0, 1},
    {{"mat.1.kd", "0.1", "light.1.pos", "-2,1,3", NULL}, 0, 0}, /* (a key error, often) */
    {{"light.0.on", "0", "background", "1,0,0", "mat.0.shine", "7", NULL}, 0, 0},
    {{"light.1.pos", "2,2,5", "mat.0.kt", "0", NULL}, 0, 0},
};
#define NSETS (sizeof edit_sets / sizeof *edit_sets)

typedef struct plan {
    int set;     /* edit_sets[set], or -1: no callback */
    int threads; /* 1 or 2 */
    rtp_shadow_mode shadows;
    int shadow_res;
    int fifo;    /* read through a pipe too */
} plan;

static uint64_t fnv(const unsigned char *p, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    size_t i;
    for (i = 0; i < n; i++)
        h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

static plan fuzz_plan(const unsigned char *d, size_t n)
{
    static const rtp_shadow_mode modes[4] = {RTP_SHADOWS_AUTO, RTP_SHADOWS_EXACT,
                                             RTP_SHADOWS_LIGHTBUF, RTP_SHADOWS_ITEMBUF};
    uint64_t h = fnv(d, n);
    plan p;
    p.set = (int)(h % (NSETS + 1)) - 1;
    h /= NSETS + 1;
    p.threads = 1 + (int)(h % 2);
    h /= 2;
    p.shadows = modes[h % 4];
    h /= 4;
    p.shadow_res = h % 3 == 0 ? 64 : 0;
    h /= 3;
    p.fifo = h % 4 == 0;
    return p;
}

/* ------------------------------------------------------- the edit callback */

typedef struct edit_state {
    const edit_set *es;
    int calls;
    int cheap;           /* the costly edits were left out (decided on the
                            callback's tree, before its trees) */
    int refused_evals;   /* rtp_tree_eval on the callback's tree refused */
    int failed_at;       /* the edit refused (-1: add_light; n: kv pair n),
                            or -2 */
    rtp_status st;       /* the callback's status */
    rtp_error err;       /* its error */
} edit_state;

static const double added_light[3] = {0.5, -2, 4};

/* Whether an edit set's costly edits are made for a file of this info:
   a retrace or a camera's full trace costs samples x primitives x rays. */
static int cheap_file(const rtp_tree_info *i)
{
    return (unsigned long long)i->width * i->height <= 400 && i->max_depth <= 6 &&
           i->triangles + i->spheres + i->cones <= 512;
}

/* The edits on t (the callback's tree, or the whole read's): their status,
   *failed_at the one refused. */
static rtp_status apply_edits(const edit_set *es, int costly_ok, rtp_tree *t, int *failed_at,
                              rtp_error *err)
{
    rtp_status st;
    int i;
    *failed_at = -2;
    if (es->add && (st = rtp_tree_add_light(t, added_light, err)) != RTP_OK) {
        *failed_at = -1;
        return st;
    }
    if (es->costly && !costly_ok)
        return RTP_OK;
    for (i = 0; i < 8 && es->kv[i]; i += 2)
        if ((st = rtp_tree_set(t, es->kv[i], es->kv[i + 1], err)) != RTP_OK) {
            *failed_at = i / 2;
            return st;
        }
    return RTP_OK;
}

static rtp_status edit_cb(void *user, rtp_tree *t, rtp_error *err)
{
    edit_state *e = (edit_state *)user;
    rtp_image *img = NULL;
    rtp_tree_info info;
    rtp_error e2;
    e->calls++;
    /* (its trees are not there yet: refused) */
    e->refused_evals = rtp_tree_eval(t, NULL, &img, NULL, &e2) == RTP_ERR_ARGUMENT;
    FUZZ_ASSERT(img == NULL);
    rtp_tree_get_info(t, &info);
    e->cheap = cheap_file(&info);
    e->st = apply_edits(e->es, e->cheap, t, &e->failed_at, err);
    if (e->st != RTP_OK && err)
        e->err = *err;
    return e->st;
}

/* ------------------------------------------------------------- the files */

static char tmp_path[512];

static void remove_tmp(void)
{
    if (tmp_path[0])
        remove(tmp_path);
}

static void make_paths(void)
{
    const char *dir = getenv("TMPDIR");
    if (tmp_path[0])
        return;
    if (!dir || !*dir)
        dir = "/tmp";
    snprintf(tmp_path, sizeof tmp_path, "%s/rtp-fuzz-treefile-%d.rtp", dir, (int)getpid());
    atexit(remove_tmp);
}

static void write_file(const unsigned char *d, size_t n)
{
    FILE *f = fopen(tmp_path, "wb");
    FUZZ_ASSERT(f != NULL);
    FUZZ_ASSERT(n == 0 || fwrite(d, 1, n, f) == n);
    FUZZ_ASSERT(fclose(f) == 0);
}

/* A pipe holding the bytes, its writer closed, named as a path
   (/proc/self/fd/N, Linux: opening it opens the pipe, without waiting for
   a writer; a FIFO's open waits, and a signal then, libFuzzer's timer,
   left a writer or reader blocked for ever).  The pipe is grown to hold
   them all (F_SETPIPE_SZ), so nothing blocks.  @return its read end, or
   -1 (no pipe run). */
static int pipe_of(const unsigned char *d, size_t n, char *path, size_t cap)
{
#if defined(__linux__)
    int p[2];
    size_t at = 0;
    if (pipe(p) != 0)
        return -1;
    if (n > 65536)
        (void)fcntl(p[1], F_SETPIPE_SZ, (int)(n + 4096));
    (void)fcntl(p[1], F_SETFL, O_NONBLOCK);
    while (at < n) {
        ssize_t k = write(p[1], d + at, n - at);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0)
            break;
        at += (size_t)k;
    }
    close(p[1]);
    if (at < n) {
        close(p[0]);
        return -1;
    }
    snprintf(path, cap, "/proc/self/fd/%d", p[0]);
    return p[0];
#else
    (void)d;
    (void)n;
    (void)path;
    (void)cap;
    return -1;
#endif
}

/* ------------------------------------------------------------ the checks */

static void report(const char *what, rtp_status s1, const rtp_error *e1, rtp_status s2,
                   const rtp_error *e2)
{
    fprintf(stderr, "fuzz_treefile: %s: expected %d \"%s\" (%s), got %d \"%s\" (%s)\n", what,
            (int)s1, s1 ? e1->message : "", s1 ? e1->file : "", (int)s2, s2 ? e2->message : "",
            s2 ? e2->file : "");
}

/* Same status, and the same message where it failed. */
static int same_error(rtp_status s1, const rtp_error *e1, rtp_status s2, const rtp_error *e2)
{
    return s1 == s2 && (s1 == RTP_OK || strcmp(e1->message, e2->message) == 0);
}

static int same_pixels(const rtp_image *a, const rtp_image *b)
{
    return a && b && a->width == b->width && a->height == b->height &&
           memcmp(a->pixels, b->pixels, sizeof(float) * 3 * (size_t)a->width * a->height) == 0;
}

static void same_scene(const rtp_tree *t, const rtp_tree *u)
{
    static const char *const keys[] = {"camera.from", "camera.angle", "ambient",
                                       "background",  "light.0.pos",  "light.0.color",
                                       "mat.0.color", "mat.0.ks",     "mat.1.kt",
                                       "mat.1.ior",   "mat.0.texture"};
    size_t k;
    for (k = 0; k < sizeof keys / sizeof *keys; k++) {
        char v1[256], v2[256];
        rtp_status s1 = rtp_scene_get(rtp_tree_scene(t), keys[k], v1, sizeof v1, NULL),
                   s2 = rtp_scene_get(rtp_tree_scene(u), keys[k], v2, sizeof v2, NULL);
        if (s1 != s2 || (s1 == RTP_OK && strcmp(v1, v2) != 0)) {
            fprintf(stderr, "fuzz_treefile: summary's %s: %s, read's %s\n", keys[k],
                    s2 == RTP_OK ? v2 : "-", s1 == RTP_OK ? v1 : "-");
            FUZZ_ASSERT(!"the summary's scene is the whole read's");
        }
    }
}

static void run_plan(const unsigned char *d, size_t size, plan p);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    unsigned char *d;
    const char *all = getenv("RTP_FUZZ_ALL_PLANS");
    if (size > 1 << 18)
        return 0;
    make_paths();
    d = (unsigned char *)malloc(size ? size : 1);
    if (!d)
        return 0;
    if (size)
        memcpy(d, data, size);
    if (size > 8 && size % 2 == 0)
        fix_crcs(d, size);
    write_file(d, size);
    if (all && *all == '1') {
        /* (by hand, over seeds: every edit set, thread count and shadow
           mode, the pipe too) */
        static const rtp_shadow_mode modes[4] = {RTP_SHADOWS_AUTO, RTP_SHADOWS_EXACT,
                                                 RTP_SHADOWS_LIGHTBUF, RTP_SHADOWS_ITEMBUF};
        plan p;
        int i;
        for (i = 0; i < (int)(NSETS + 1) * 2 * 4 * 2; i++) {
            p.set = i % (int)(NSETS + 1) - 1;
            p.threads = 1 + (i / (int)(NSETS + 1)) % 2;
            p.shadows = modes[(i / (2 * (int)(NSETS + 1))) % 4];
            p.shadow_res = (i / (8 * (int)(NSETS + 1))) % 2 ? 64 : 0;
            p.fifo = i % 7 == 0;
            run_plan(d, size, p);
        }
    } else {
        run_plan(d, size, fuzz_plan(d, size));
    }
    free(d);
    return 0;
}

/* The checks of one input (d: its bytes as written to tmp_path). */
static void run_plan(const unsigned char *d, size_t size, plan p)
{
    rtp_tree *t = NULL, *m = NULL, *u = NULL;
    rtp_error e_read, e_mem, e_sum, e_ef, e_ref;
    rtp_status s_read, s_mem, s_sum, s_ef, s_ref;
    rtp_tree_info ti_read, ti_sum, ti_ef, ti_ref;
    rtp_eval_stats es_ef, es_ref;
    rtp_eval_options eo;
    rtp_image *img = NULL, *ref = NULL;
    edit_state es;

    /* the whole reads: from the file and from memory */
    memset(&e_read, 0, sizeof e_read);
    memset(&e_mem, 0, sizeof e_mem);
    s_read = rtp_tree_read(tmp_path, &fuzz_alloc, &t, &e_read);
    fuzz_check_error(&e_read, s_read);
    FUZZ_ASSERT((s_read == RTP_OK) == (t != NULL));
    s_mem = rtp_tree_read_memory(d, size, tmp_path, &fuzz_alloc, &m, &e_mem);
    if (!same_error(s_read, &e_read, s_mem, &e_mem)) {
        report("rtp_tree_read_memory", s_read, &e_read, s_mem, &e_mem);
        FUZZ_ASSERT(!"rtp_tree_read_memory's error is rtp_tree_read's");
    }
    rtp_tree_destroy(m);
    m = NULL;
    if (t)
        rtp_tree_get_info(t, &ti_read);

    /* the summary */
    memset(&e_sum, 0, sizeof e_sum);
    s_sum = rtp_tree_read_summary(tmp_path, &fuzz_alloc, &u, &e_sum);
    fuzz_check_error(&e_sum, s_sum);
    FUZZ_ASSERT((s_sum == RTP_OK) == (u != NULL));
    if (!same_error(s_read, &e_read, s_sum, &e_sum)) {
        report("rtp_tree_read_summary", s_read, &e_read, s_sum, &e_sum);
        FUZZ_ASSERT(!"rtp_tree_read_summary's error is rtp_tree_read's");
    }
    if (u && t) {
        rtp_tree_get_info(u, &ti_sum);
        if (memcmp(&ti_sum, &ti_read, sizeof ti_sum) != 0) {
            fprintf(stderr, "fuzz_treefile: summary's info: %llu nodes, %zu lights; "
                            "read's %llu, %zu\n",
                    ti_sum.nodes, ti_sum.lights, ti_read.nodes, ti_read.lights);
            FUZZ_ASSERT(!"the summary's info is the whole read's");
        }
        same_scene(t, u);
        {
            /* what needs the trees: refused */
            rtp_image *x = NULL;
            FUZZ_ASSERT(rtp_tree_eval(u, NULL, &x, NULL, NULL) == RTP_ERR_ARGUMENT && !x);
        }
    }
    rtp_tree_destroy(u);
    u = NULL;

    if (p.fifo) {
        /* a stream of unknown size: the whole read and the summary */
        int k;
        for (k = 0; k < 2; k++) {
            char pp[64];
            rtp_error e_f;
            rtp_status s_f;
            rtp_tree *ft = NULL;
            int fd = pipe_of(d, size, pp, sizeof pp);
            if (fd < 0)
                break;
            memset(&e_f, 0, sizeof e_f);
            s_f = k == 0 ? rtp_tree_read(pp, &fuzz_alloc, &ft, &e_f)
                         : rtp_tree_read_summary(pp, &fuzz_alloc, &ft, &e_f);
            close(fd);
            fuzz_check_error(&e_f, s_f);
            FUZZ_ASSERT((s_f == RTP_OK) == (ft != NULL));
            if (!same_error(s_read, &e_read, s_f, &e_f) &&
                !(s_read == RTP_ERR_FORMAT && s_f == RTP_OK &&
                  strncmp(e_read.message, "bytes after END", 15) == 0)) {
                report(k == 0 ? "rtp_tree_read of a pipe" : "rtp_tree_read_summary of a pipe",
                       s_read, &e_read, s_f, &e_f);
                FUZZ_ASSERT(!"a pipe's error is the file's");
            }
            if (ft && t) {
                rtp_tree_info fi;
                rtp_tree_get_info(ft, &fi);
                FUZZ_ASSERT(memcmp(&fi, &ti_read, sizeof fi) == 0);
            }
            rtp_tree_destroy(ft);
        }
    }

    /* the one-off evaluation */
    memset(&eo, 0, sizeof eo);
    eo.threads = p.threads;
    eo.shadows = p.shadows;
    eo.shadow_res = p.shadow_res;
    /* (a retrace is kept small: fuzz_tree.c; 32 MiB holds a light
       buffer's cube of 512 cells, the default) */
    eo.memory_limit = 32.0 * 1048576.0;
    memset(&es, 0, sizeof es);
    es.es = p.set >= 0 ? &edit_sets[p.set] : NULL;
    es.failed_at = -2;
    memset(&e_ef, 0, sizeof e_ef);
    memset(&es_ef, 0, sizeof es_ef);
    s_ef = rtp_tree_eval_file(tmp_path, &fuzz_alloc, es.es ? edit_cb : NULL, &es, &eo, &img,
                              &ti_ef, &es_ef, &e_ef);
    fuzz_check_error(&e_ef, s_ef);
    FUZZ_ASSERT((s_ef == RTP_OK) == (img != NULL));
    FUZZ_ASSERT(es.calls <= 1);
    FUZZ_ASSERT(es.calls == 0 || es.refused_evals);
    if (es.calls && es.st != RTP_OK) {
        /* the callback's error, first */
        if (!same_error(es.st, &es.err, s_ef, &e_ef)) {
            report("rtp_tree_eval_file against its callback", es.st, &es.err, s_ef, &e_ef);
            FUZZ_ASSERT(!"rtp_tree_eval_file returns its callback's error");
        }
    }
    if (s_read != RTP_OK) {
        /* refused as rtp_tree_read refuses it, but for an edit refused
           before the trees were read */
        if (!(es.calls && es.st != RTP_OK) && !same_error(s_read, &e_read, s_ef, &e_ef)) {
            report("rtp_tree_eval_file", s_read, &e_read, s_ef, &e_ef);
            FUZZ_ASSERT(!"rtp_tree_eval_file's error is rtp_tree_read's");
        }
    } else {
        /* the reference: the whole read, the same edits, no_cache */
        int failed_at = -2;
        /* (a file rtp_tree_read reads gets its callback: textures and
           all are there) */
        FUZZ_ASSERT(!es.es || es.calls == 1);
        memset(&e_ref, 0, sizeof e_ref);
        s_ref = es.es ? apply_edits(es.es, cheap_file(&ti_read), t, &failed_at, &e_ref)
                      : RTP_OK;
        if (es.es)
            FUZZ_ASSERT(es.cheap == cheap_file(&ti_read));
        if (s_ref != RTP_OK) {
            /* refused alike, at the same edit */
            if (!same_error(s_ref, &e_ref, s_ef, &e_ef) || failed_at != es.failed_at) {
                report("an edit, rtp_tree_eval_file", s_ref, &e_ref, s_ef, &e_ef);
                FUZZ_ASSERT(!"rtp_tree_eval_file refuses the edit rtp_tree_set refuses");
            }
        } else {
            eo.no_cache = 1;
            memset(&es_ref, 0, sizeof es_ref);
            s_ref = rtp_tree_eval(t, &eo, &ref, &es_ref, &e_ref);
            fuzz_check_error(&e_ref, s_ref);
            if (!same_error(s_ref, &e_ref, s_ef, &e_ef)) {
                report("rtp_tree_eval (reference), rtp_tree_eval_file", s_ref, &e_ref, s_ef,
                       &e_ef);
                FUZZ_ASSERT(!"rtp_tree_eval_file's status is rtp_tree_eval's");
            }
            if (s_ref == RTP_OK) {
                rtp_tree_get_info(t, &ti_ref);
                if (!same_pixels(img, ref)) {
                    fprintf(stderr, "fuzz_treefile: images differ (set %d, %d threads, "
                                    "shadows %d/%d, %s)\n",
                            p.set, p.threads, (int)p.shadows, p.shadow_res,
                            es_ef.moved_lights ? "moved" : "none moved");
                    FUZZ_ASSERT(!"rtp_tree_eval_file's image is rtp_tree_eval's");
                }
                FUZZ_ASSERT(memcmp(&ti_ef, &ti_ref, sizeof ti_ef) == 0);
                FUZZ_ASSERT(es_ef.samples == es_ref.samples && es_ef.nodes == es_ref.nodes &&
                            es_ef.combined_samples == es_ref.combined_samples &&
                            es_ef.written_pixels == es_ref.written_pixels &&
                            es_ef.stale_samples == es_ref.stale_samples &&
                            es_ef.moved_lights == es_ref.moved_lights &&
                            es_ef.retraced_samples == es_ref.retraced_samples &&
                            es_ef.retraced_rays == es_ref.retraced_rays &&
                            es_ef.capped_rays == es_ref.capped_rays &&
                            es_ef.shadow_queries == es_ref.shadow_queries &&
                            es_ef.camera_moved == es_ref.camera_moved &&
                            (!es_ef.moved_lights || es_ef.shadows == es_ref.shadows));
            }
        }
    }
    if (p.fifo) {
        /* the one-off evaluation through a pipe: the file's */
        char pp[64];
        edit_state es2;
        rtp_error e_f;
        rtp_status s_f;
        rtp_image *pimg = NULL;
        int fd = pipe_of(d, size, pp, sizeof pp);
        if (fd >= 0) {
            eo.no_cache = 0;
            memset(&es2, 0, sizeof es2);
            es2.es = es.es;
            es2.failed_at = -2;
            memset(&e_f, 0, sizeof e_f);
            s_f = rtp_tree_eval_file(pp, &fuzz_alloc, es2.es ? edit_cb : NULL, &es2, &eo, &pimg,
                                     NULL, NULL, &e_f);
            close(fd);
            fuzz_check_error(&e_f, s_f);
            if (es2.calls && es2.st != RTP_OK && !es.calls && s_ef == RTP_ERR_FORMAT &&
                strncmp(e_ef.message, "truncated", 9) == 0) {
                /* a pipe's size is not known: the file's truncation, found
                   from its size before the scene's edits were asked, comes
                   through a pipe after them, and an edit refused there
                   stops the read first: the callback's error */
                if (!same_error(es2.st, &es2.err, s_f, &e_f)) {
                    report("rtp_tree_eval_file of a pipe against its callback", es2.st,
                           &es2.err, s_f, &e_f);
                    FUZZ_ASSERT(!"a pipe's one-off evaluation returns its callback's error");
                }
            } else if (!(s_ef == RTP_ERR_FORMAT &&
                         strncmp(e_ef.message, "bytes after END", 15) == 0)) {
                if (!same_error(s_ef, &e_ef, s_f, &e_f)) {
                    report("rtp_tree_eval_file of a pipe (expected: of the file)", s_ef, &e_ef,
                           s_f, &e_f);
                    FUZZ_ASSERT(!"a pipe's one-off evaluation is the file's");
                }
                FUZZ_ASSERT(s_f != RTP_OK || same_pixels(img, pimg));
            }
            rtp_image_destroy(pimg);
        }
    }
    if (getenv("RTP_FUZZ_VERBOSE"))
        fprintf(stderr, "fuzz_treefile: %zu bytes, set %d, %d threads, shadows %d/%d, fifo %d: "
                        "read %d \"%s\", eval_file %d \"%s\" (%d calls, %s)\n",
                size, p.set, p.threads, (int)p.shadows, p.shadow_res, p.fifo, (int)s_read,
                s_read ? e_read.message : "", (int)s_ef, s_ef ? e_ef.message : "", es.calls,
                img && es_ef.moved_lights ? "moved" : "-");
    rtp_image_destroy(img);
    rtp_image_destroy(ref);
    rtp_tree_destroy(t);
}
