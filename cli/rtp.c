/* rtp.c — the command-line tool.  It uses only rtp.h and libc (plus
 * isatty for progress), and chains the library's steps: trace, diff.
 *
 * Exit status: 0 ok, 1 failure (with a message), 2 usage error,
 * 3 diff over its --fail-above threshold. */
#define _POSIX_C_SOURCE 200809L
#include "rtp.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <signal.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define EXIT_USAGE 2
#define EXIT_OVER 3

static int verbosity = 1; /* 0 quiet, 1 normal, 2 verbose; CLI-only state */
static int std_closed[3];  /* stdin, stdout, stderr were closed (hold_std_fds) */
/* What stdin serves when a command reads it for an input ("the scene",
   "--stream's edits"), else NULL: a value '-' (an image from stdin) is
   then refused */
static const char *stdin_user;

#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
static void msg(const char *fmt, ...);
static void put_shown(FILE *f, const char *s);
/* A message line on stderr, "rtp: " first, its bytes as put_shown shows
   them (a file's name is any bytes). */
static void msg(const char *fmt, ...)
{
    char small[1024], *big = NULL;
    const char *s = small;
    va_list ap;
    int n;
    va_start(ap, fmt);
    n = vsnprintf(small, sizeof small, fmt, ap);
    va_end(ap);
    if (n < 0)
        small[0] = '\0';
    else if ((size_t)n >= sizeof small && (big = (char *)malloc((size_t)n + 1)) != NULL) {
        va_start(ap, fmt);
        vsnprintf(big, (size_t)n + 1, fmt, ap);
        va_end(ap);
        s = big;
    }
    fputs("rtp: ", stderr);
    put_shown(stderr, s);
    fputc('\n', stderr);
    free(big);
}

/* Bytes of the well-formed UTF-8 sequence at s (1-4), or 0. */
static int utf8_len(const unsigned char *s)
{
    int n, k;
    unsigned cp;
    if (s[0] < 0x80)
        return 1;
    if (s[0] >= 0xc2 && s[0] <= 0xdf)
        n = 2, cp = s[0] & 0x1fu;
    else if (s[0] >= 0xe0 && s[0] <= 0xef)
        n = 3, cp = s[0] & 0x0fu;
    else if (s[0] >= 0xf0 && s[0] <= 0xf4)
        n = 4, cp = s[0] & 0x07u;
    else
        return 0;
    for (k = 1; k < n; k++) {
        if ((s[k] & 0xc0u) != 0x80u)
            return 0;
        cp = cp << 6 | (s[k] & 0x3fu);
    }
    /* overlong forms, surrogates and past U+10FFFF are not UTF-8 */
    if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10ffff)) ||
        (cp >= 0xd800 && cp <= 0xdfff))
        return 0;
    return n;
}

/* s as a terminal is to show it, as the library's messages show a
   scene's words (lex.c utf8_shown): well-formed UTF-8 as it is, '?' for
   each byte of a control (C0, DEL, C1: ESC and CSI start a terminal's
   escapes), of a line or paragraph separator or a bidirectional control
   (which reorder or break the rest of the line), and of what is not
   UTF-8.  A file named "\033[2J.nff" cleared the screen in its error,
   and the library's own file field beside a word showed it raw. */
static void put_shown(FILE *f, const char *s)
{
    const unsigned char *p = (const unsigned char *)s;
    while (*p) {
        int n = utf8_len(p), k;
        int hide = n == 0 || (n == 1 && (*p < 0x20 || *p == 0x7f)) ||
                   (n == 2 && ((p[0] == 0xc2 && p[1] < 0xa0) || (p[0] == 0xd8 && p[1] == 0x9c))) ||
                   (n == 3 && p[0] == 0xe2 &&
                    ((p[1] == 0x80 && ((p[2] >= 0x8e && p[2] <= 0x8f) ||
                                       (p[2] >= 0xa8 && p[2] <= 0xae))) ||
                     (p[1] == 0x81 && p[2] >= 0xa6 && p[2] <= 0xa9)));
        if (n == 0)
            n = 1;
        if (hide)
            for (k = 0; k < n; k++)
                fputc('?', f);
        else
            fwrite(p, 1, (size_t)n, f);
        p += n;
    }
}

/* s as a JSON string: quotes, backslashes and control characters
   escaped (a scene path may hold any of them), and a byte that is not
   part of well-formed UTF-8 written as the code point of the same value
   (\u00XX: JSON must be UTF-8; such a path reads back as another name,
   not as invalid JSON). */
static void json_string(FILE *f, const char *s)
{
    const unsigned char *p = (const unsigned char *)s;
    fputc('"', f);
    while (*p) {
        int n = utf8_len(p);
        if (*p == '"' || *p == '\\')
            fprintf(f, "\\%c", *p);
        else if (*p < 0x20 || n == 0)
            fprintf(f, "\\u%04x", *p);
        else
            fwrite(p, 1, (size_t)n, f);
        p += n ? n : 1;
    }
    fputc('"', f);
}

static int fail_err(const rtp_error *err)
{
    char buf[600];
    msg("%s", rtp_error_format(err, buf, sizeof buf));
    return 1;
}

/* fail_err, naming the --stream line whose edits failed (line 0: none). */
static int fail_line(const rtp_error *err, int line)
{
    char buf[600];
    if (line > 0)
        msg("<stdin>:%d: %s", line, rtp_error_format(err, buf, sizeof buf));
    else
        fail_err(err);
    return 1;
}

/* A count's noun: one for 1, else many ("1 materials", "traced all 1
   samples" had been said). */
static const char *noun(unsigned long long n, const char *one, const char *many)
{
    return n == 1 ? one : many;
}

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ------------------------------------------------------------- progress */

typedef struct progress {
    double start;
    double first_t, first_done; /* the first report's (first_t < 0: none yet) */
    int shown;
} progress;

/* The estimate of the time left is the rate since the first report: the
   time before it (loading, the kd-tree's build, a direction cube) is not
   the rows' (an 8M-triangle mesh said "0.2%  9538.8 s left" after 25 s
   of building, and was done 4 s later). */
static void progress_cb(void *user, double done)
{
    progress *p = (progress *)user;
    double t = now_seconds(), el = t - p->start;
    if (p->first_t < 0.0) {
        p->first_t = t;
        p->first_done = done;
    }
    if (done > p->first_done && done < 1.0) {
        double left = (t - p->first_t) / (done - p->first_done) * (1.0 - done);
        fprintf(stderr, "\r%5.1f%%  %.1f s left   ", 100.0 * done, left);
    } else if (done < 1.0) {
        fprintf(stderr, "\r%5.1f%%  %.1f s         ", 100.0 * done, el);
    } else {
        fprintf(stderr, "\r%5.1f%%  %.1f s        ", 100.0 * done, el);
    }
    p->shown = 1;
}

/* Starts p's clock; with reports to make, says at once that work began
   (a large mesh's load and build were seconds of silence). */
static void progress_start(progress *p, int show)
{
    p->start = now_seconds();
    p->first_t = -1.0;
    p->first_done = 0.0;
    p->shown = 0;
    if (show) {
        fprintf(stderr, "\r  0.0%%  preparing   ");
        p->shown = 1;
    }
}

/* Ends the progress line (once), so that what follows starts a line of
   its own. */
static void progress_end(progress *p)
{
    if (p->shown)
        fputc('\n', stderr);
    p->shown = 0;
}

/* ------------------------------------------------------------ arguments */

static int parse_int(const char *s, int lo, int hi, int *out)
{
    char *end;
    long v;
    errno = 0;
    /* (strtol skips leading blanks: "osmesa: 5" was taken) */
    if (isspace((unsigned char)*s))
        return -1;
    v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi)
        return -1;
    *out = (int)v;
    return 0;
}

/* Does s (up to a ',' or its end) look like a decimal number?  strtod
   also takes hex, "nan" and "inf", which scene files and --set refuse. */
static int decimal_start(const char *s)
{
    while (*s && strchr(" \t\r\n\v\f", *s))
        s++; /* (strtod's white space) */
    if (!(*s == '-' || *s == '+' || *s == '.' || (*s >= '0' && *s <= '9')))
        return 0;
    for (; *s && *s != ','; s++)
        if (strchr("xXnNiI", *s))
            return 0;
    return 1;
}

static int parse_double(const char *s, double *out)
{
    char *end;
    double v;
    if (!decimal_start(s))
        return -1;
    errno = 0;
    v = strtod(s, &end);
    /* (ERANGE on an underflow is no error: 1e-320 is a number >= 0, a
       subnormal or 0, as --set and --add-light take it; an overflow is
       infinite, refused by isfinite) */
    if (end == s || *end || (errno && errno != ERANGE) || !isfinite(v))
        return -1;
    *out = v;
    return 0;
}

/* v (finite) in the fewest significant digits that read back as v
   (0.1, not %.17g's 0.10000000000000001): into buf, which it returns. */
static const char *shortest(char *buf, size_t size, double v)
{
    int prec;
    for (prec = 1; prec < 17; prec++) {
        snprintf(buf, size, "%.*g", prec, v);
        if (strtod(buf, NULL) == v)
            return buf;
    }
    snprintf(buf, size, "%.17g", v);
    return buf;
}

/* Returns the option's value: "--opt=value" or the next argument. */
static const char *opt_value(int argc, char **argv, int *i, const char *name)
{
    size_t n = strlen(name);
    if (strncmp(argv[*i], name, n) == 0 && argv[*i][n] == '=')
        return argv[*i] + n + 1;
    if (n == 2 && strncmp(argv[*i], name, 2) == 0 && argv[*i][2] != '\0')
        return argv[*i] + 2; /* -j2 */
    if (*i + 1 >= argc) {
        msg("%s needs a value", name);
        return NULL;
    }
    return argv[++*i];
}

/* An argument that is an option: '-' and more ('-' alone is stdin or
   stdout).  After '--' nothing is (names_only in each command's loop), so
   a file whose name begins with '-' is named as `-- -x.nff`, as POSIX
   utilities take it. */
static int is_option_like(const char *arg)
{
    return arg[0] == '-' && arg[1] != '\0';
}

enum { ARG_END, ARG_OPERAND, ARG_OPTION };

/* What a command's loop does with arg: ARG_END for the first '--' (taken:
   every later argument is an ARG_OPERAND, *names_only set), ARG_OPERAND
   for a file or a value, ARG_OPTION for an option to parse. */
static int arg_kind(const char *arg, int *names_only)
{
    if (*names_only)
        return ARG_OPERAND;
    if (strcmp(arg, "--") == 0) {
        *names_only = 1;
        return ARG_END;
    }
    return is_option_like(arg) ? ARG_OPTION : ARG_OPERAND;
}

static int is_opt(const char *arg, const char *name)
{
    size_t n = strlen(name);
    return strncmp(arg, name, n) == 0 && (arg[n] == '\0' || arg[n] == '=');
}

/* "WxH" into *w, *h (1 .. 2^20 each); returns 0 or -1 (with a message). */
static int parse_size(const char *v, int *w, int *h)
{
    char buf[64], *x;
    if (!v)
        return -1; /* (opt_value said it) */
    if (strlen(v) >= sizeof buf) {
        msg("--size: expected WxH");
        return -1;
    }
    strcpy(buf, v);
    x = strchr(buf, 'x');
    if (!x) {
        msg("--size %s: expected WxH", v);
        return -1;
    }
    *x = '\0';
    if (parse_int(buf, 1, 1 << 20, w) || parse_int(x + 1, 1, 1 << 20, h)) {
        msg("--size %s: expected WxH with integers from 1 to 1048576", v);
        return -1;
    }
    return 0;
}

/* "x0,y0,x1,y1" into r: four fields, none empty (strtok had taken
   "1,1,2,2," and "1,,1,2,2"); returns 0 or -1. */
static int parse_region(const char *v, int *r)
{
    char buf[128];
    const char *p = v;
    int k;
    for (k = 0; k < 4; k++) {
        const char *e = strchr(p, ',');
        size_t n = e ? (size_t)(e - p) : strlen(p);
        if ((k < 3) != (e != NULL) || n == 0 || n >= sizeof buf)
            return -1;
        memcpy(buf, p, n);
        buf[n] = '\0';
        if (parse_int(buf, 0, 1 << 20, &r[k]))
            return -1;
        p = e ? e + 1 : p + n;
    }
    if (r[0] >= r[2] || r[1] >= r[3])
        return -1;
    return 0;
}

/* Options every subcommand takes: -q, -v, -j N, --stats FILE.  Returns 1
   when argv[*i] was one (consumed), 0 when not, -1 on a bad value. */
/* -j's default: the processors online (images are the same for any
   count, so this only makes them sooner), 1 where that cannot be told. */
static int default_threads(void)
{
#ifdef _SC_NPROCESSORS_ONLN
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n < 1 ? 1 : n > 256 ? 256 : (int)n;
#else
    return 1;
#endif
}

static int common_option(int argc, char **argv, int *i, int *threads, const char **stats)
{
    const char *a = argv[*i], *v;
    if (strcmp(a, "-q") == 0 || strcmp(a, "--quiet") == 0) {
        verbosity = 0;
        return 1;
    }
    if (strcmp(a, "-v") == 0 || strcmp(a, "--verbose") == 0) {
        verbosity = 2;
        return 1;
    }
    if (threads && (strncmp(a, "-j", 2) == 0 || is_opt(a, "--threads"))) {
        if (!(v = opt_value(argc, argv, i, a[1] == 'j' ? "-j" : "--threads")))
            return -1;
        if (parse_int(v, 1, 256, threads)) {
            msg("-j: expected a thread count from 1 to 256");
            return -1;
        }
        return 1;
    }
    if (stats && is_opt(a, "--stats")) {
        if (!(*stats = opt_value(argc, argv, i, "--stats")))
            return -1;
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------ signals */

/* trace's tree as it was before its write (keep_take, below) */
typedef struct keep_old {
    char dest[4096]; /* the file the write replaces (a link's target) */
    char old[4096];  /* its old contents' hard link, when state is 1 */
    int state;       /* 0 nothing to undo, 1 old kept, 2 it was new,
                        3 it could not be kept (errno in why) */
    int why;
} keep_old;


/* SIGINT, SIGTERM, SIGHUP, SIGQUIT and SIGPIPE end rtp as they would, without
   leaving a temporary file behind (and so do the others whose default
   ends a process and that reach a batch job: SIGXCPU from a CPU limit,
   SIGALRM, SIGUSR1, SIGUSR2, SIGVTALRM, which had left a --stream's
   stats temporary; not SIGPROF, a profiling build's own): they wait while an image or tree file
   is written (the library writes it beside the file and renames it into
   place), and a stats file's temporary name is removed before the signal
   takes its course.  SIGXFSZ (a file size limit) is ignored, so that the
   write fails with "File too large" and cleans up instead of killing rtp
   half way. */
static sigset_t term_signals, saved_mask;
static char stats_tmp[4096];
static volatile sig_atomic_t stats_tmp_live;
/* trace -o TREE -i IMAGE with the image a pipe, device or stdout: its
   write may block as long as its reader, so signals stay live through it;
   one arriving then puts the tree back as keep_undo would (pair_keep[0]:
   the keep_old of the tree, set while pair_live).  So too while the
   --stats file is written after them (it may be a FIFO): pair_keep[1]
   is the image's then, and a signal puts both back. */
static const struct keep_old *pair_keep[2];
static volatile sig_atomic_t pair_live;

static void on_term(int sig)
{
    if (stats_tmp_live)
        unlink(stats_tmp); /* (async-signal-safe) */
    if (pair_live) {
        /* (rename and unlink are async-signal-safe; keep_old's fields
           were set before pair_live) */
        int k;
        for (k = 0; k < 2; k++) {
            if (!pair_keep[k])
                continue;
            if (pair_keep[k]->state == 1)
                rename(pair_keep[k]->old, pair_keep[k]->dest);
            else if (pair_keep[k]->state == 2)
                unlink(pair_keep[k]->dest);
        }
    }
    signal(sig, SIG_DFL);
    raise(sig);
}

static void install_signals(void)
{
    static const int sigs[] = {SIGINT,  SIGTERM, SIGHUP,  SIGQUIT,  SIGPIPE,
                               SIGXCPU, SIGALRM, SIGUSR1, SIGUSR2, SIGVTALRM};
    size_t k;
    sigemptyset(&term_signals);
    for (k = 0; k < sizeof sigs / sizeof *sigs; k++) {
        struct sigaction sa, old;
        sigaddset(&term_signals, sigs[k]);
        memset(&sa, 0, sizeof sa);
        sa.sa_handler = on_term;
        sigemptyset(&sa.sa_mask);
        /* (a signal ignored by who started rtp, as nohup does, stays so) */
        if (sigaction(sigs[k], NULL, &old) == 0 && old.sa_handler != SIG_IGN)
            sigaction(sigs[k], &sa, NULL);
    }
    signal(SIGXFSZ, SIG_IGN);
}

/* Holds the signals off while a file at path is written and renamed into
   place (not for stdout, a FIFO or a device, where a reader that stalls
   would make rtp deaf to Ctrl-C); @return whether they were held. */
static int held_depth; /* holds nest (trace's pair of outputs, each write) */

static int hold_signals(const char *path)
{
    struct stat sb;
    if (!path || strcmp(path, "-") == 0 || (stat(path, &sb) == 0 && !S_ISREG(sb.st_mode)))
        return 0;
    if (held_depth > 0) {
        held_depth++;
        return 1;
    }
    if (sigprocmask(SIG_BLOCK, &term_signals, &saved_mask) != 0)
        return 0;
    held_depth = 1;
    return 1;
}

static void release_signals(int held)
{
    if (held && --held_depth == 0)
        sigprocmask(SIG_SETMASK, &saved_mask, NULL);
}

static rtp_status write_image(const rtp_image *img, const char *path, rtp_error *err)
{
    int held = hold_signals(path);
    rtp_status st = rtp_image_write(img, path, RTP_IMAGE_AUTO, err);
    release_signals(held);
    return st;
}

static rtp_status write_tree(const rtp_tree *t, const char *path, unsigned long long *bytes,
                             rtp_error *err)
{
    int held = hold_signals(path);
    rtp_status st = rtp_tree_write(t, path, bytes, err);
    release_signals(held);
    return st;
}

/* trace -o TREE -i IMAGE writes two files: when the second fails (a full
   disk) the first is put back as it was — its old contents kept under a
   hard link beside it until both are written, or removed when it was
   new — so the pair never mixes a new tree with an old image.  For a
   tree that is a regular file (a FIFO or stdout cannot be taken back);
   the image may be anything. */
static int is_stdout(const char *path);
static int link_target(const char *path, char *buf, size_t size);
static int link_walk(const char *path, char *buf, size_t size, int *via_fd);

/* Whether a link chain at path passes through /proc or /dev/fd (another
   open file: the library appends to it, nothing can be taken back). */
static int via_fd_link(const char *path)
{
    char buf[4096];
    int via;
    return link_walk(path, buf, sizeof buf, &via) != 0 || via;
}

static int output_is_file(const char *path)
{
    struct stat sb;
    return path && strcmp(path, "-") != 0 && !is_stdout(path) && !via_fd_link(path) &&
           (stat(path, &sb) != 0 ? errno == ENOENT : S_ISREG(sb.st_mode));
}

static void keep_take(keep_old *k, const char *path)
{
    struct stat sb;
    const char *slash;
    size_t dl;
    int tries;
    k->state = 0;
    if (link_target(path, k->dest, sizeof k->dest) != 0)
        return;
    if (lstat(k->dest, &sb) != 0) {
        k->state = errno == ENOENT ? 2 : 0;
        return;
    }
    if (!S_ISREG(sb.st_mode))
        return;
    slash = strrchr(k->dest, '/');
    dl = slash ? (size_t)(slash - k->dest) + 1 : 0;
    if (dl + 32 > sizeof k->old)
        return;
    for (tries = 0; tries < 64; tries++) {
        memcpy(k->old, k->dest, dl);
        snprintf(k->old + dl, sizeof k->old - dl, ".rtp-%ld-%d.old", (long)getpid(), tries);
        if (link(k->dest, k->old) == 0) {
            k->state = 1;
            return;
        }
        if (errno != EEXIST)
            break; /* (no hard links here, or too many: said if needed) */
    }
    k->why = errno;
    k->state = 3;
}

/* what: the output put back ("tree", "image"); why: the file whose
   write failed ("the image", "the --stats file") */
static void keep_undo(keep_old *k, const char *path, const char *what, const char *why)
{
    if (k->state == 1 && rename(k->old, k->dest) == 0)
        msg("%s: put back as it was: %s could not be written", path, why);
    else if (k->state == 1)
        unlink(k->old);
    if (k->state == 2 && unlink(k->dest) == 0)
        msg("%s: removed: %s could not be written", path, why);
    if (k->state == 3)
        msg("%s: the new %s stays: its old contents could not be kept beside it (%s)",
            path, what, strerror(k->why));
    k->state = 0;
}

static void keep_drop(keep_old *k)
{
    if (k->state == 1)
        unlink(k->old);
    k->state = 0;
}

/* Writes tree to tree_path and then img to image_path (either pair may be
   NULL) as one: when the image fails, the tree is put back as it was.
   trace -o -i and merge -o -i both write such a pair (merge had left a
   new tree, or replaced an old one, under a failed image: exit 1).
   With keeps (two, the tree's and the image's), a --stats file follows:
   the old contents of both stay kept there until pair_settle says
   whether the stats were written (trace --stats /dev/full had exited 1
   with the new image and tree in place).  @return 0, or -1 with the
   error said (keeps then settled). */
static int write_pair(const rtp_tree *tree, const char *tree_path, unsigned long long *bytes,
                      const rtp_image *img, const char *image_path, keep_old *keeps)
{
    keep_old own[2];
    keep_old *keep = keeps ? keeps : own;
    rtp_error err;
    int pair = tree_path && (image_path || keeps) && output_is_file(tree_path), held = 0,
        tree_held = 0, img_held = 0;
    memset(&err, 0, sizeof err);
    keep[0].state = keep[1].state = 0;
    if (pair) {
        /* (signals held over both writes: Ctrl-C between them would
           leave the new tree with the old image; not over an image to a
           pipe, device or stdout, whose write may block as long as its
           reader: Ctrl-C then puts the tree back, on_term) */
        held = !image_path || output_is_file(image_path) ? hold_signals(tree_path) : 0;
        keep_take(&keep[0], tree_path);
        /* (and from the tree's write until pair_live is set: a signal
           between the two, once the new tree was in place, had left it
           and the old one's .old link; one held till then puts it back) */
        tree_held = held ? 0 : hold_signals(tree_path);
    }
    if (tree_path && write_tree(tree, tree_path, bytes, &err) != RTP_OK) {
        fail_err(&err);
        keep_drop(&keep[0]);
        release_signals(tree_held);
        release_signals(held);
        return -1;
    }
    if (pair && !held) {
        pair_keep[0] = &keep[0];
        pair_live = 1;
    }
    release_signals(tree_held);
    /* (the image's old contents kept only for a --stats to follow; a
       pipe's or a device's cannot be) */
    if (keeps && image_path && output_is_file(image_path)) {
        /* (held until pair_live: a signal between had left the new
           image and its old one's link) */
        img_held = hold_signals(image_path);
        keep_take(&keep[1], image_path);
    }
    if (image_path && write_image(img, image_path, &err) != RTP_OK) {
        release_signals(img_held);
        pair_live = 0;
        pair_keep[0] = NULL; /* (keep ends with this call: gcc -O3's
                                -Wdangling-pointer saw it kept) */
        fail_err(&err);
        keep_undo(&keep[0], tree_path, "tree", "the image");
        keep_drop(&keep[1]); /* (the failed write left the old image) */
        release_signals(held);
        return -1;
    }
    if (keeps) {
        /* (a signal held till now puts both back: the command did not
           finish) */
        pair_keep[0] = &keep[0];
        pair_keep[1] = &keep[1];
        pair_live = 1;
        release_signals(img_held);
        release_signals(held);
        return 0;
    }
    pair_live = 0;
    pair_keep[0] = NULL;
    keep_drop(&keep[0]);
    release_signals(held);
    return 0;
}

/* The outputs write_pair kept for a --stats file: failed (its write or
   its rename), both put back as they were (a new one removed); else
   their old contents dropped. */
static void pair_settle(keep_old *keeps, const char *tree_path, const char *image_path,
                        int failed)
{
    pair_live = 0;
    pair_keep[0] = pair_keep[1] = NULL;
    if (failed) {
        keep_undo(&keeps[1], image_path, "image", "the --stats file");
        keep_undo(&keeps[0], tree_path, "tree", "the --stats file");
    } else {
        keep_drop(&keeps[0]);
        keep_drop(&keeps[1]);
    }
}

/* ---------------------------------------------------------------- stats */

static mode_t stats_umask(void)
{
    mode_t m = umask(022);
    umask(m);
    return m;
}

/* The file a write to path replaces: path, or where a chain of symbolic
   links at path leads (as the library's writers follow it).  via_fd (may
   be NULL): set when a name on the way lies in /proc or /dev/fd (another
   open file, which the library appends to).  0, or -1 with errno. */
static int link_walk(const char *path, char *buf, size_t size, int *via_fd)
{
    struct stat sb;
    char link[4096];
    ssize_t n;
    const char *slash;
    size_t dir;
    int hops;
    if (strlen(path) >= size) {
        errno = ENAMETOOLONG;
        return -1;
    }
    strcpy(buf, path);
    if (via_fd)
        *via_fd = 0;
    for (hops = 0;; hops++) {
        if (via_fd && (strncmp(buf, "/proc/", 6) == 0 || strncmp(buf, "/dev/fd/", 8) == 0))
            *via_fd = 1;
        if (lstat(buf, &sb) != 0 || !S_ISLNK(sb.st_mode))
            break;
        slash = strrchr(buf, '/');
        if (hops == 40) {
            errno = ELOOP;
            return -1;
        }
        n = readlink(buf, link, sizeof link - 1);
        if (n < 0)
            return -1;
        link[n] = '\0';
        dir = link[0] != '/' && slash ? (size_t)(slash - buf) + 1 : 0;
        if (dir + (size_t)n >= size) {
            errno = ENAMETOOLONG;
            return -1;
        }
        memmove(buf + dir, link, (size_t)n + 1);
    }
    return 0;
}

static int link_target(const char *path, char *buf, size_t size)
{
    return link_walk(path, buf, size, NULL);
}

/* Whether path is the file stdout or stderr writes ("/dev/stderr" when
   it goes to a file): @return that stream, or NULL. */
static FILE *std_stream(const struct stat *sb)
{
    struct stat so;
    if (fstat(fileno(stdout), &so) == 0 && so.st_dev == sb->st_dev && so.st_ino == sb->st_ino)
        return stdout;
    if (fstat(fileno(stderr), &so) == 0 && so.st_dev == sb->st_dev && so.st_ino == sb->st_ino)
        return stderr;
    return NULL;
}

/* A stats file goes to a temporary file beside it, renamed into place when
   the command succeeds: a failure keeps the old file (it had been emptied
   as the command began) and leaves no half file.  stdout, FIFOs and
   devices are written as they are.  One a command. */
static const char *stats_final;
static char stats_dest[4096]; /* where the temporary file goes: path's link target */

static FILE *stats_open(const char *path)
{
    FILE *f;
    struct stat sb;
    int fd, exists;
    const char *slash;
    char target[4096];
    if (strcmp(path, "-") == 0)
        return stdout;
    if (stat(path, &sb) == 0) {
        FILE *std = S_ISREG(sb.st_mode) ? std_stream(&sb) : NULL;
        if (std)
            return std; /* (closed as stdout is: flushed, not closed) */
        if (!S_ISREG(sb.st_mode)) {
            f = fopen(path, "w"); /* a FIFO, a device: in place */
            if (!f)
                msg("%s: cannot write stats: %s", path, strerror(errno));
            return f;
        }
    }
    /* as the library writes images and trees: the file a link names, a
       read-only file refused, its mode kept */
    if (link_target(path, target, sizeof target) != 0) {
        msg("%s: cannot write stats: %s", path, strerror(errno));
        return NULL;
    }
    exists = stat(target, &sb) == 0;
    if (exists && access(target, W_OK) != 0) {
        msg("%s: cannot write stats: %s", path, strerror(errno));
        return NULL;
    }
    slash = strrchr(target, '/');
    if (snprintf(stats_tmp, sizeof stats_tmp, "%.*s.rtp-stats-XXXXXX",
                 slash ? (int)(slash - target) + 1 : 0, target) >= (int)sizeof stats_tmp ||
        strlen(target) >= sizeof stats_dest) {
        msg("%s: cannot write stats: %s", path, strerror(ENAMETOOLONG));
        return NULL;
    }
    strcpy(stats_dest, target);
    fd = mkstemp(stats_tmp);
    if (fd < 0) {
        msg("%s: cannot write stats: %s", path, strerror(errno));
        return NULL;
    }
    stats_tmp_live = 1;
    f = fdopen(fd, "w");
    if (!f) {
        msg("%s: cannot write stats: %s", path, strerror(errno));
        stats_tmp_live = 0;
        close(fd);
        unlink(stats_tmp);
        return NULL;
    }
    /* (mkstemp makes it 0600; a file root replaces keeps its owner) */
    (void)fchmod(fd, exists ? sb.st_mode & 07777 : 0666 & ~stats_umask());
    if (exists && geteuid() == 0)
        (void)fchown(fd, sb.st_uid, sb.st_gid);
    stats_final = path;
    return f;
}

/* A stats file given up: the command failed, the old file stays. */
static void stats_discard(FILE *f)
{
    if (!f || f == stdout || f == stderr)
        return;
    fclose(f);
    if (stats_tmp_live) {
        stats_tmp_live = 0;
        unlink(stats_tmp);
    }
}

/* Peak resident memory of this process in KiB, or -1. */
static long peak_rss_kb(void)
{
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) != 0)
        return -1;
    return (long)ru.ru_maxrss; /* Linux reports KiB */
}

static int stats_close(FILE *f, const char *path)
{
    int bad, e, tmp = stats_tmp_live && stats_final == path;
    if (f == stdout || f == stderr) {
        if (fflush(f) != 0 || ferror(f)) {
            msg("%s: error writing stats: %s", f == stdout ? "stdout" : "stderr",
                strerror(errno));
            return 1;
        }
        return 0;
    }
    errno = 0;
    bad = fflush(f) != 0 || ferror(f) != 0;
    e = errno;
    if (fclose(f) != 0 && !bad) {
        bad = 1;
        e = errno;
    }
    if (!bad && tmp && rename(stats_tmp, stats_dest) != 0) {
        bad = 1;
        e = errno;
    }
    if (tmp) {
        if (bad)
            unlink(stats_tmp);
        stats_tmp_live = 0;
    }
    if (bad) {
        msg("%s: error writing stats: %s", path, e ? strerror(e) : "write failed");
        return 1;
    }
    return 0;
}

/* The end of a command's --stats file f (NULL: none) and of the outputs
   write_pair kept for it (keeps, the tree at tree_path and the image at
   image_path): f closed into place, or given up where the command failed
   already; the outputs put back if either failed, else their old contents
   dropped; signals held over the rename and the settling (one between had
   put back the outputs of stats in place).  1 where the stats file failed
   or the command had. */
static int stats_settle(FILE *f, const char *path, keep_old *keeps, const char *tree_path,
                        const char *image_path, int failed)
{
    int held, bad = failed;
    if (!f)
        return failed;
    held = hold_signals(path);
    if (failed)
        stats_discard(f);
    else
        bad = stats_close(f, path);
    pair_settle(keeps, tree_path, image_path, bad);
    release_signals(held);
    return bad;
}

/* Whether an image can be written to path, said before the work that
   makes it (a trace of minutes, then "cannot tell the image format"):
   0 after a message.  (A name without a %d in a --stream pattern is
   the pattern's own.) */
static int image_name_ok(const char *path)
{
    rtp_image_format f;
    struct stat sb;
    if (strcmp(path, "-") == 0)
        return 1;
    f = rtp_image_format_from_path(path);
    /* (a pipe or a device, /dev/null, named without an extension is
       written PFM, as "-" is: rtp_image_write) */
    if (f == RTP_IMAGE_AUTO && stat(path, &sb) == 0 && !S_ISREG(sb.st_mode) &&
        !S_ISDIR(sb.st_mode))
        return 1;
    if (f == RTP_IMAGE_AUTO) {
        msg("%s: cannot tell the image format from the name: use .png, .ppm or .pfm", path);
        return 0;
    }
    if (f == RTP_IMAGE_PNG && !rtp_png_supported()) {
        msg("%s: PNG is not supported by this build of rtp (libpng was not found when it was "
            "built); use .ppm or .pfm", path);
        return 0;
    }
    return 1;
}

/* Whether a file can be made at path, said before the work (a trace of
   minutes then "cannot create a temporary file beside it"): its folder
   exists and may be written, and path is not a folder.  0 after a
   message.  (A FIFO, a device or stdout is written as it is.) */
static int output_ok(const char *path)
{
    struct stat sb;
    char dir[4096], target[4096];
    const char *slash;
    if (!path || strcmp(path, "-") == 0)
        return 1;
    if (!*path) {
        /* ('' from an unset shell variable: it failed after the work, at
           the rename, naming nothing) */
        msg("an output's file name is empty");
        return 0;
    }
    {
        /* a name for a standard stream the caller closed (hold_std_fds:
           it is the root folder now; said as what it is) */
        struct stat sp, sh;
        int f;
        for (f = 0; f < 3; f++)
            if (std_closed[f] && stat(path, &sp) == 0 && fstat(f, &sh) == 0 &&
                sp.st_dev == sh.st_dev && sp.st_ino == sh.st_ino && strcmp(path, "/") != 0) {
                msg("%s: cannot write: %s is closed", path,
                    f == 0 ? "stdin" : f == 1 ? "stdout" : "stderr");
                return 0;
            }
    }
    if (stat(path, &sb) == 0) {
        if (S_ISDIR(sb.st_mode)) {
            msg("%s: cannot write: %s", path, strerror(EISDIR));
            return 0;
        }
        if (!S_ISREG(sb.st_mode))
            return 1; /* (a FIFO, a device: written in place) */
    }
    /* the file a link names is the one written (rtpi_write_target) */
    if (link_target(path, target, sizeof target) != 0) {
        msg("%s: cannot write: %s", path, strerror(errno));
        return 0;
    }
    if (stat(target, &sb) == 0 && access(target, W_OK) != 0) {
        msg("%s: cannot write: %s", path, strerror(errno));
        return 0;
    }
    slash = strrchr(target, '/');
    if (!slash) {
        strcpy(dir, ".");
    } else {
        memcpy(dir, target, (size_t)(slash - target) + 1);
        dir[slash - target + 1] = '\0';
    }
    if (access(dir, W_OK | X_OK) != 0) {
        msg("%s: cannot write in folder %s: %s", path, dir, strerror(errno));
        return 0;
    }
    {
        /* A sticky folder (/tmp) lets only a file's owner (or the
           folder's) replace it, and files are replaced by a rename: said
           now, not after the work */
        struct stat sd, sf;
        uid_t me = geteuid();
        if (me != 0 && stat(dir, &sd) == 0 && (sd.st_mode & 01000) /* S_ISVTX (XSI) */ &&
            stat(target, &sf) == 0 &&
            sf.st_uid != me && sd.st_uid != me) {
            msg("%s: cannot replace another user's file in the sticky folder %s", path, dir);
            return 0;
        }
    }
    return 1;
}

/* Whether path is stdout: '-', or the file stdout writes (a link to
   /proc/self/fd/1, /dev/stdout). */
static int is_stdout(const char *path)
{
    struct stat sb, so;
    if (!path)
        return 0;
    if (strcmp(path, "-") == 0)
        return 1;
    /* (a closed stdout holds /dev/null: no file named is stdout then) */
    return !std_closed[1] && stat(path, &sb) == 0 && fstat(fileno(stdout), &so) == 0 &&
           sb.st_dev == so.st_dev && sb.st_ino == so.st_ino;
}

/* Whether two names (link targets) are one name in one folder: the
   folders stat'ed, the final names compared, for outputs not yet made,
   whose names alone differ (-i x.pfm --stats ./x.pfm, dir/../x.pfm: the
   stats replaced the image, exit 0). */
static int one_place(const char *a, const char *b)
{
    const char *sa = strrchr(a, '/'), *sb = strrchr(b, '/');
    const char *na = sa ? sa + 1 : a, *nb = sb ? sb + 1 : b;
    char da[4096], db[4096];
    struct stat xa, xb;
    /* (the folder: the part before the last '/', "/" for "/x", "." for "x") */
    size_t la = !sa ? 1 : sa == a ? 1 : (size_t)(sa - a);
    size_t lb = !sb ? 1 : sb == b ? 1 : (size_t)(sb - b);
    if (!*na || strcmp(na, nb) != 0 || la >= sizeof da || lb >= sizeof db)
        return 0;
    memcpy(da, sa ? a : ".", la);
    da[la] = '\0';
    memcpy(db, sb ? b : ".", lb);
    db[lb] = '\0';
    return stat(da, &xa) == 0 && stat(db, &xb) == 0 && xa.st_dev == xb.st_dev &&
           xa.st_ino == xb.st_ino;
}

/* Whether two outputs are one file (-o x -i x, --stats x): the last
   written would replace the other silently.  1 after a message. */
static int one_output(const char *a, const char *b)
{
    char ta[4096], tb[4096];
    struct stat sa, sb;
    if (!a || !b || strcmp(a, "-") == 0 || strcmp(b, "-") == 0)
        return 0;
    if (link_target(a, ta, sizeof ta) != 0 || link_target(b, tb, sizeof tb) != 0)
        return 0;
    /* (a device takes both as it took one: -o /dev/null -i /dev/null,
       a trace timed, was refused; a FIFO's reader would get them mixed) */
    if (stat(ta, &sa) == 0 && S_ISCHR(sa.st_mode))
        return 0;
    return strcmp(ta, tb) == 0 || (stat(ta, &sa) == 0 && stat(tb, &sb) == 0 &&
                                   S_ISREG(sa.st_mode) && sa.st_dev == sb.st_dev &&
                                   sa.st_ino == sb.st_ino) ||
           one_place(ta, tb);
}

/* ra, rb: what each output is ("the image", "the --stats file"): two
   names alike said only "x and x are one file", not which options gave
   them (the default image among them).  One line, no usage lines after
   it: the options are well formed, their files collide (the usage said
   nothing about that). */
static int same_output(const char *cmd, const char *ra, const char *a, const char *rb,
                       const char *b)
{
    if (!one_output(a, b))
        return 0;
    msg("%s: %s %s and %s %s are one file: give each output its own", cmd, ra, a, rb, b);
    return 1;
}

/* An output that is the input file itself (a tree named t.png, whose
   default image is t.png; -i naming the scene): written, it replaced the
   input, which cannot be had back.  Compared by device and inode, so a
   link or another spelling of the name is caught too. */
/* '-' is stdin as an input and stdout as an output: `reeval t.rtp -i -
   >> t.rtp` appended the images to the tree, exit 0 (the tree then read
   "bytes after END"), where -i /dev/stdout was refused; and with `>
   t.rtp` the shell had emptied the tree before rtp began, which only
   said "t.rtp: empty: not an rtp tree file". */
static int std_stat(const char *path, int fd, struct stat *sb)
{
    if (strcmp(path, "-") != 0)
        return stat(path, sb);
    return std_closed[fd] ? -1 : fstat(fd, sb);
}

static int is_input(const char *in, const char *out)
{
    struct stat si, so;
    if (!in || !out)
        return 0;
    return std_stat(in, 0, &si) == 0 && std_stat(out, 1, &so) == 0 && S_ISREG(si.st_mode) &&
           si.st_dev == so.st_dev && si.st_ino == so.st_ino;
}

/* The refusal of an output over an input: one line naming the option,
   the file and what the input is ("trace: -o s.nff is the scene s.nff";
   it said "s.nff is the input s.nff" and printed the usage after it, as
   for options badly given, where the options were fine).  in_role: "the
   scene", "the tree", ...; opt: the output's option ("-o", "--stats"),
   NULL for the default image.  1 after the message (a usage error: the
   caller returns EXIT_USAGE without the usage lines). */
static int overwrites_input(const char *cmd, const char *in_role, const char *in,
                            const char *opt, const char *out)
{
    struct stat si;
    const char *in_name;
    if (!is_input(in, out))
        return 0;
    in_name = strcmp(in, "-") ? in : "(standard input)";
    if (strcmp(out, "-") == 0)
        /* (stdout sent to the input by the shell: with > it was emptied
           before rtp began, and the message says why it is empty) */
        msg("%s: %s - writes to standard output, which is %s %s%s: name another file", cmd,
            opt ? opt : "the image", in_role, in_name,
            std_stat(in, 0, &si) == 0 && si.st_size == 0
                ? " (empty now: a shell's > empties its file before the command starts)"
                : "");
    else if (!opt)
        msg("%s: the default image %s is %s itself: name the image with -i", cmd, out, in_role);
    else
        msg("%s: %s %s is %s %s: writing it would replace it; name another file", cmd, opt,
            out, in_role, in_name);
    return 1;
}

/* Any of the outputs out[0..nout) (given by the options opts[0..nout))
   that is one of the inputs in[0..nin) (--stats or --heatmap naming the
   scene, the tree, an image diff reads or a params file): refused as -i
   naming the input is, before anything is read.  1 after a message. */
static int outputs_over_inputs(const char *cmd, const char *in_role, const char *const *in,
                               int nin, const char *const *opts, const char *const *out,
                               int nout)
{
    int i, o;
    for (o = 0; o < nout; o++)
        for (i = 0; i < nin; i++)
            if (overwrites_input(cmd, in_role, in[i], opts[o], out[o]))
                return 1;
    return 0;
}

/* Any of the outputs out[0..nout) that is an image the scene reads, a
   material's texture or bump map (the scene's own, or one a key named):
   written, it replaced the user's image ("trace textured.nff -i tex.ppm"
   wrote over the scene's texture).  Known once the scene is read (and
   for a stream's frames, after each line's edits).  line: the --stream
   line (0: none).  1 after a message. */
static int overwrites_scene_image(const char *cmd, const rtp_scene *s, const char *const *opts,
                                  const char *const *out, int nout, int line)
{
    static const char *const fields[] = {"texture", "bump"};
    rtp_scene_info si;
    size_t m;
    int k, o;
    rtp_scene_get_info(s, &si);
    for (m = 0; m < si.materials; m++)
        for (k = 0; k < 2; k++) {
            char key[64], path[4096];
            snprintf(key, sizeof key, "mat.%zu.%s", m, fields[k]);
            /* (none, waves and noise name no file) */
            if (rtp_scene_get(s, key, path, sizeof path, NULL) != RTP_OK ||
                strcmp(path, "none") == 0 || strcmp(path, "waves") == 0 ||
                strcmp(path, "noise") == 0)
                continue;
            for (o = 0; o < nout; o++)
                if (is_input(path, out[o])) {
                    if (line)
                        msg("<stdin>:%d: %s: %s is the image %s that %s reads: writing it "
                            "would replace it; name another file",
                            line, cmd, out[o], path, key);
                    else
                        msg("%s: %s%s%s is the image %s that %s reads: writing it would "
                            "replace it; name another file",
                            cmd, opts[o] ? opts[o] : "", opts[o] ? " " : "", out[o], path, key);
                    return 1;
                }
        }
    /* (and the files it includes, meshes and mtllibs: trace s.nff -o
       mesh.obj wrote the tree over the included mesh) */
    for (m = 0;; m++) {
        char key[64], path[4096];
        snprintf(key, sizeof key, "file.%zu", m);
        rtp_status st = rtp_scene_get(s, key, path, sizeof path, NULL);
        if (st == RTP_ERR_KEY || (st != RTP_OK && st != RTP_ERR_ARGUMENT))
            break; /* (past the last; ARGUMENT: a path longer than path holds) */
        for (o = 0; st == RTP_OK && o < nout; o++)
            if (is_input(path, out[o])) {
                msg("%s: %s%s%s is a file the scene reads (%s, %s): writing it would replace "
                    "it; name another file",
                    cmd, opts[o] ? opts[o] : "", opts[o] ? " " : "", out[o], key, path);
                return 1;
            }
    }
    return 0;
}

/* --stats - with an image or tree to stdout: the JSON would land inside
   the binary stream (between a stream's images); an image or tree '-'
   where stdout is a terminal: its bytes would go to the screen (as gzip
   refuses them; a terminal named as a file is written); 1 after a
   message. */
static int stdout_taken(const char *cmd, const char *stats_path, const char *a, const char *b)
{
    if ((a && strcmp(a, "-") == 0) || (b && strcmp(b, "-") == 0)) {
        if (!std_closed[1] && isatty(fileno(stdout))) {
            msg("%s: stdout is a terminal: send the image or tree on '-' to a file or a pipe "
                "(> or |)",
                cmd);
            return 1;
        }
    }
    if (!is_stdout(stats_path))
        return 0;
    if (is_stdout(a) || is_stdout(b)) {
        msg("%s: --stats - and an image or tree on stdout cannot share it: give --stats a file",
            cmd);
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------ edits */

/* A --set argument has the form KEY=VALUE with a key (a usage error
   otherwise, on trace and reeval alike); 0 after a message. */
static int set_arg_ok(const char *v)
{
    const char *eq = strchr(v, '=');
    if (!eq || eq == v) {
        msg("--set %s: expected KEY=VALUE", v);
        return 0;
    }
    return 1;
}

/* Applies "KEY=VALUE" through set(); where/line name its origin. */
typedef rtp_status (*set_fn)(void *obj, const char *key, const char *value,
                             rtp_error *err);

static rtp_status set_scene(void *obj, const char *k, const char *v, rtp_error *e)
{
    return rtp_scene_set((rtp_scene *)obj, k, v, e);
}

static rtp_status set_tree(void *obj, const char *k, const char *v, rtp_error *e)
{
    return rtp_tree_set((rtp_tree *)obj, k, v, e);
}

/* Whether key's value may name an image file (mat.N.texture, mat.N.bump),
   which '-' reads from stdin. */
static int image_key(const char *key)
{
    const char *dot = strrchr(key, '.');
    return dot && (strcmp(dot, ".texture") == 0 || strcmp(dot, ".bump") == 0);
}

/* line > 0: kv is the word at column col of that line of `where` (a
   --params file or the stream), which every message names as
   where:line:col, as the scene readers name a token; else a --set. */
static int apply_kv(set_fn set, void *obj, const char *kv, const char *where, int line,
                    int col)
{
    char key[512]; /* (mat. + a name of up to 255 characters + a field) */
    const char *eq = strchr(kv, '=');
    size_t kn;
    rtp_error err;
    rtp_status st;
    memset(&err, 0, sizeof err);
    if (!eq || eq == kv) {
        /* (a line's pairs are separated by blanks: "mat.Floor Mat.kd=0.3"
           is two words, the first no pair) */
        if (line && (strncmp(kv, "mat.", 4) == 0 || strncmp(kv, "light.", 6) == 0))
            msg("%s:%d:%d: expected KEY=VALUE, got '%s' (blanks separate a line's edits: a name "
                "holding a blank is reached by its index, mat.N or light.N, as 'rtp info "
                "TREE' lists them)",
                where, line, col, kv);
        else if (line)
            msg("%s:%d:%d: expected KEY=VALUE, got '%s'", where, line, col, kv);
        else
            msg("%s %s: expected KEY=VALUE", where, kv);
        return 1;
    }
    kn = (size_t)(eq - kv);
    if (kn >= sizeof key) {
        /* (a params file's or a stream's line named, as every other
           error of a line names it) */
        if (line)
            msg("%s:%d:%d: key too long (%zu characters; at most %zu)", where, line, col, kn,
                sizeof key - 1);
        else
            msg("%s: key too long (%zu characters; at most %zu)", where, kn, sizeof key - 1);
        return 1;
    }
    memcpy(key, kv, kn);
    key[kn] = '\0';
    if (stdin_user && strcmp(eq + 1, "-") == 0 && image_key(key)) {
        /* an image (mat.N.texture=-) read from stdin would take the
           stream's next lines, or the rest of the tree, as its bytes */
        if (line)
            msg("%s:%d:%d: %s=-: stdin already serves %s; name the file", where, line, col, key,
                stdin_user);
        else
            msg("%s %s=-: stdin already serves %s; name the file", where, key, stdin_user);
        return 1;
    }
    st = set(obj, key, eq + 1, &err);
    if (st == RTP_OK)
        return 0;
    if (st == RTP_ERR_KEY) {
        /* A name may hold '=' (an MTL "newmtl a=b"): a key that names
           nothing is tried longer, up to each later '=' in turn, so that
           mat.a=b.kd=0.5 reaches it ("unknown key 'mat.a'" said it did not
           exist).  Only after a key error, which changes nothing: a value
           holding '=' (a texture "x=1.png") is still a value.  The first
           longer key that names something gives the outcome; none does,
           the first key's error stands. */
        const char *e2 = eq;
        while ((e2 = strchr(e2 + 1, '=')) != NULL && (size_t)(e2 - kv) < sizeof key) {
            rtp_error err2;
            rtp_status st2;
            memset(&err2, 0, sizeof err2);
            memcpy(key, kv, (size_t)(e2 - kv));
            key[e2 - kv] = '\0';
            if (stdin_user && strcmp(e2 + 1, "-") == 0 && image_key(key))
                break; /* (the first key's error: stdin is not read) */
            if ((st2 = set(obj, key, e2 + 1, &err2)) == RTP_OK)
                return 0;
            if (st2 != RTP_ERR_KEY) {
                err = err2;
                eq = e2;
                break;
            }
        }
    }
    {
        char buf[600];
        rtp_error_format(&err, buf, sizeof buf);
        /* (an empty value in a line: "light.0.color= 1" is two words) */
        if (line && !eq[1])
            msg("%s:%d:%d: %s (blanks separate a line's edits: no blank after '=')", where,
                line, col, buf);
        else if (line)
            msg("%s:%d:%d: %s", where, line, col, buf);
        else
            msg("%s", buf);
        return 1;
    }
}

/* Applies every KEY=VALUE of a line (separated by blanks); a '#' where a
   word could start (the line's start, after a blank) starts a comment, as
   in the scene readers: inside a word it is part of it (a material
   "Material#25", as 3ds Max names them).  Returns 0 or 1. */
static int apply_line(set_fn set, void *obj, char *text, const char *where, int line)
{
    char *p = text, *hash;
    for (hash = text; *hash; hash++)
        if (*hash == '#' && (hash == text || hash[-1] == ' ' || hash[-1] == '\t' ||
                             hash[-1] == '\r' || hash[-1] == '\n')) {
            *hash = '\0';
            break;
        }
    for (;;) {
        char *tok;
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
            p++;
        if (!*p)
            return 0;
        tok = p;
        while (*p && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n')
            p++;
        if (*p)
            *p++ = '\0';
        if (apply_kv(set, obj, tok, where, line, (int)(tok - text) + 1))
            return 1;
    }
}

/* The next line of f into line (MAX_LINE + 1 bytes), read a byte at a
   time so that no line takes more than that (getline held a line of
   /dev/zero whole), as line number *lineno: 1, 0 at the end, -1 after a
   message naming name:line (a read error, such as a folder given as the
   file; a line longer than MAX_LINE characters: cut in two it would be
   two edit sets; a NUL byte in it — fgets could not tell one from the
   line's end, so what followed was dropped).  A UTF-8 byte-order mark before the first line
   is skipped, as the scene readers skip it.  (A mebibyte: one line may set
   every light of a scene of thousands; 8190 stopped a stream setting 300
   lights' colours in one line.)  Lines end with '\n', "\r\n" or a lone
   '\r' (classic Mac OS files), as the scene readers' do: read as blanks,
   a file of '\r' ends was one line, whose first comment hid every edit
   after it and whose frames a stream made one.  *cr (0 before the first
   line) says the last line ended with '\r', so a '\n' starting this one
   is that line's end: known without reading past the '\r', which would
   wait on a stream's writer for its next line before the frame. */
#define MAX_LINE 1048575
static int next_line(FILE *f, const char *name, char *line, int *lineno, int *cr)
{
    size_t n = 0;
    int c, nul = 0; /* the first NUL's column, 0: none */
    if (*cr) {
        *cr = 0;
        if ((c = getc(f)) != '\n' && c != EOF)
            ungetc(c, f);
    }
    while ((c = getc(f)) != EOF && c != '\n') {
        if (c == '\r') {
            *cr = 1;
            break;
        }
        if (n == MAX_LINE) {
            msg("%s:%d:%d: line too long (at most %d characters)", name, *lineno + 1,
                MAX_LINE + 1, MAX_LINE);
            return -1;
        }
        line[n++] = (char)c;
        if (c == '\0' && !nul)
            nul = (int)n;
    }
    if (c == EOF && ferror(f)) {
        msg("%s: cannot read: %s", name, strerror(errno ? errno : EIO));
        return -1;
    }
    if (c == EOF && n == 0)
        return 0;
    line[n] = '\0';
    ++*lineno;
    if (nul) {
        /* (a BOM before it counts for nothing, as the scene readers have it) */
        if (*lineno == 1 && n >= 3 && memcmp(line, "\xef\xbb\xbf", 3) == 0 && nul > 3)
            nul -= 3;
        msg("%s:%d:%d: a NUL byte in the line", name, *lineno, nul);
        return -1;
    }
    if (*lineno == 1 && n >= 3 && memcmp(line, "\xef\xbb\xbf", 3) == 0)
        memmove(line, line + 3, n - 2);
    return 1;
}

/* An input's name in messages: '-' is "<stdin>", as the library names it. */
static const char *in_name(const char *path)
{
    return strcmp(path, "-") == 0 ? "<stdin>" : path;
}

static int apply_params_file(set_fn set, void *obj, const char *path)
{
    FILE *f = strcmp(path, "-") == 0 ? stdin : fopen(path, "r");
    char *line = (char *)malloc(MAX_LINE + 1);
    int n = 0, rc = 0, got, cr = 0;
    if (!f || !line) {
        if (!*path)
            msg("no params file name");
        else if (!f)
            msg("%s: cannot open: %s", path, strerror(errno));
        else
            msg("%s: out of memory", path);
        if (f && f != stdin)
            fclose(f);
        free(line);
        return 1;
    }
    path = in_name(path);
    while ((got = next_line(f, path, line, &n, &cr)) > 0)
        if (apply_line(set, obj, line, path, n)) {
            rc = 1;
            break;
        }
    if (got < 0)
        rc = 1;
    if (f != stdin)
        fclose(f);
    free(line);
    return rc;
}

/* Whether path reads what stdin holds: '-', or another name of the pipe
   or socket stdin is (/dev/stdin, /dev/fd/0, /proc/self/fd/0, a FIFO's
   own name), which shares its bytes (a regular file's other name is read
   from its own start, and reads nothing of stdin's). */
static int reads_stdin(const char *path)
{
    struct stat sp, s0;
    if (strcmp(path, "-") == 0)
        return 1;
    return !std_closed[0] && fstat(0, &s0) == 0 &&
           (S_ISFIFO(s0.st_mode) || S_ISSOCK(s0.st_mode)) && stat(path, &sp) == 0 &&
           sp.st_dev == s0.st_dev && sp.st_ino == s0.st_ino;
}

/* Whether path is '-' while stdin is closed: said as trace and reeval
   say it (1 after a message: a usage error); info, diff and merge read
   the directory that holds fd 0 and said "-: is a directory". */
static int stdin_closed_for(const char *cmd, const char *path, const char *what)
{
    if (!std_closed[0] || strcmp(path, "-") != 0)
        return 0;
    msg("%s: stdin is closed: nothing there for %s", cmd, what);
    return 1;
}

/* stdin serves one input: the command's file (the scene or tree, when
   it is '-'), one --params file, --stream's edits (stream: its name, or
   NULL), or an image a --set value '-' names.  Two of them read it in
   turn, the second finding it empty or in the middle of the first (a
   scene read whole, then "--params -" read nothing and the trace went on
   unedited).  Sets stdin_user for the edits read later; 1 after a
   message. */
static int stdin_inputs(const char *cmd, const char *file, const char *file_what,
                        const char *const *params, int nparams, const char *const *sets,
                        int nsets, const char *stream)
{
    const char *users[3];
    int n = 0, i, np = 0;
    if (std_closed[0]) {
        /* (held by a directory: each reader said "is a directory") */
        const char *what = strcmp(file, "-") == 0 ? file_what : stream;
        for (i = 0; !what && i < nparams; i++)
            if (strcmp(params[i], "-") == 0)
                what = "--params -";
        for (i = 0; !what && i < nsets; i++) {
            const char *eq = strchr(sets[i], '=');
            if (eq && strcmp(eq + 1, "-") == 0)
                what = sets[i];
        }
        if (what) {
            msg("%s: stdin is closed: nothing there for %s", cmd, what);
            return 1;
        }
    }
    /* (another name of a piped stdin reads it too: "--params /dev/stdin
       --stream" read every line as the params file's, then the stream
       found none and exited 0 with no image) */
    if (reads_stdin(file))
        users[n++] = file_what;
    for (i = 0; i < nparams; i++)
        np += reads_stdin(params[i]);
    if (np)
        users[n++] = "--params";
    if (stream)
        users[n++] = stream;
    if (np > 1) {
        msg("%s: --params - (or another name of stdin) given twice: stdin can serve only one", cmd);
        return 1;
    }
    if (n > 1) {
        msg("%s: stdin can serve only one of %s and %s", cmd, users[0], users[1]);
        return 1;
    }
    stdin_user = n ? users[0] : NULL;
    for (i = 0; stdin_user && i < nsets; i++) {
        const char *eq = strchr(sets[i], '=');
        char key[256];
        size_t kn = eq ? (size_t)(eq - sets[i]) : 0;
        if (!eq || kn >= sizeof key)
            continue;
        memcpy(key, sets[i], kn);
        key[kn] = '\0';
        if (strcmp(eq + 1, "-") == 0 && image_key(key)) {
            msg("--set %s: stdin already serves %s; name the file", sets[i], stdin_user);
            return 1;
        }
    }
    return 0;
}

/* ---------------------------------------------------------------- trace */

/* After a usage error: the command's usage line (the first of its help)
   and where the rest is, not the whole help, which buried the message
   above it. */
static void usage_hint(const char *help)
{
    const char *nl = strchr(help, '\n'), *cmd = help + strlen("usage: rtp ");
    int n = (int)strcspn(cmd, " \n");
    fprintf(stderr, "%.*s\n'rtp %.*s --help' lists the options\n", (int)(nl - help), help, n,
            cmd);
}

static const char trace_help[] =
    "usage: rtp trace SCENE [options]\n"
    "Traces SCENE (NFF, or .obj; '-' = NFF on stdin) with a Whitted ray tracer\n"
    "and writes the image and, with -o, the ray trees that `rtp reeval`\n"
    "re-evaluates.\n"
    "  -o, --output TREE    write the ray trees to TREE (.rtp; '-' = stdout)\n"
    "  -i, --image FILE     image to write (.png .ppm .pfm; '-' = PFM on stdout);\n"
    "                       default: SCENE's name with .png ('-': trace.png;\n"
    "                       .ppm in a build without PNG), in the current folder\n"
    "                       (none with -o)\n"
    "  --set KEY=VALUE      edit the scene first (repeatable): light.N.pos|color|\n"
    "                       intensity|on,\n"
    "                       mat.N.color|kd|ks|kt|shine|ior|ambient|checker|\n"
    "                       color2|checker_scale|texture|bump|bump_strength|\n"
    "                       bump_scale,\n"
    "                       ambient, background, camera.from|at|up|angle|hither;\n"
    "                       N is a 0-based index or a name; light.N.pos with N\n"
    "                       the count of lights adds a light\n"
    "  --params FILE        edits from FILE: KEY=VALUE per line, '#' comments;\n"
    "                       repeatable (files in turn, then the --set edits)\n"
    "  --size WxH           image size (default: the scene's resolution)\n"
    "  --region X0,Y0,X1,Y1 trace only pixels X0 <= x < X1, Y0 <= y < Y1 of the\n"
    "                       frame; image and trees are the region's (rtp merge\n"
    "                       joins regions into the frame)\n"
    "  --spd                SPD testing procedure: 512x512 from 513x513 corner\n"
    "                       rays, depth 5, no weight cut-off, one-sided opaque;\n"
    "                       it overrides --size, --depth and --min-weight in\n"
    "                       any order (a warning names those ignored)\n"
    "  --depth N            maximum ray-tree depth, eye ray = 1 (default 5)\n"
    "  --memory-limit MIB   stop when the image and its trees need more (default\n"
    "                       16384)\n"
    "  --min-weight W       do not spawn rays weighing less than W (default 0)\n"
    "  -j, --threads N      threads, 1 to 256 (default: the processors online)\n"
    "  --stats FILE         write statistics as one JSON object ('-' = stdout)\n"
    "  -q, --quiet          no messages but errors\n"
    "  -v, --verbose        a line of times and ray counts on stderr\n"
    "  -h, --help           this help\n";

/* The image written where none is named: the input's name without its
   folder and extension (the current folder's), with .png, or .ppm where
   the library was built without libpng (a default that could only fail). */
static char *default_image_name(const char *scene)
{
    const char *base = strrchr(scene, '/');
    const char *dot;
    size_t n;
    char *out;
    base = base ? base + 1 : scene;
    dot = strrchr(base, '.');
    n = dot && dot != base ? (size_t)(dot - base) : strlen(base);
    out = (char *)malloc(n + 5);
    if (!out)
        return NULL;
    memcpy(out, base, n);
    memcpy(out + n, rtp_png_supported() ? ".png" : ".ppm", 5);
    return out;
}

/* "X,Y,Z" (--add-light) into pos, each |x| <= 3.4e38 as a key's value
   (rtp_tree_add_light refuses more, a message that named no option); 0,
   or -1. */
static int parse_xyz(const char *p, double pos[3])
{
    char *end;
    int k;
    for (k = 0; k < 3; k++) {
        if (!decimal_start(p))
            return -1;
        pos[k] = strtod(p, &end);
        if (end == p || !(fabs(pos[k]) <= 3.4e38) || (k < 2 && *end != ',') ||
            (k == 2 && *end != '\0'))
            return -1;
        p = end + 1;
    }
    return 0;
}

/* --memory-limit MIB (trace and reeval) as bytes; 0, or -1 with a message. */
static int memory_limit_option(int argc, char **argv, int *i, double *bytes)
{
    const char *v = opt_value(argc, argv, i, "--memory-limit");
    double mib;
    if (!v)
        return -1; /* (said) */
    if (parse_double(v, &mib) || !(mib > 0)) {
        msg("--memory-limit: expected a size in MiB > 0");
        return -1;
    }
    *bytes = mib * 1048576.0;
    return 0;
}

/* Says that rays were not followed because a sample's tree was full: the
   image is not the full Whitted trace (the trees and the image agree, so
   re-evaluation stays exact against them). */
static int stale_warned; /* the stale-subtree warning said (once a run) */

static void capped_warning(unsigned long long n)
{
    fprintf(stderr,
            "rtp: warning: %llu %s not followed: %s reached 2^20 nodes (lower --depth or set "
            "--min-weight)\n",
            n, noun(n, "ray was", "rays were"),
            noun(n, "its sample's ray tree", "their samples' ray trees"));
}

static int cmd_trace(int argc, char **argv)
{
    const char *scene_path = NULL, *image_path = NULL, *stats_path = NULL;
    const char *tree_path = NULL;
    char *default_image = NULL;
    const char *image_role; /* (the image, or the default image, in messages) */
    rtp_trace_options opt;
    rtp_trace_stats st;
    keep_old keeps[2]; /* the tree's and image's old contents while --stats is written */
    rtp_tree *tree = NULL;
    rtp_tree_info ti;
    unsigned long long file_bytes = 0;
    rtp_scene *scene = NULL;
    rtp_image *img = NULL;
    rtp_error err;
    progress prog;
    int i, rc = 1, nsets = 0, nparams = 0, c, names_only = 0;
    const char **sets, **params;
    double t0, t_load, t_trace, t_write;

    memset(&opt, 0, sizeof opt);
    opt.threads = default_threads();
    memset(&err, 0, sizeof err);
    sets = (const char **)calloc(2 * ((size_t)argc + 1), sizeof *sets);
    if (!sets) {
        msg("out of memory");
        return 1;
    }
    params = sets + argc + 1;
    for (i = 0; i < argc; i++) {
        const char *a = argv[i], *v;
        int kind = arg_kind(a, &names_only);
        if (kind == ARG_END)
            continue;
        if (kind == ARG_OPERAND) {
            if (scene_path) {
                msg("trace: more than one scene ('%s' and '%s')", scene_path, a);
                goto usage;
            }
            scene_path = a;
        } else if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            fputs(trace_help, stdout);
            free(sets);
            return 0;
        } else if ((c = common_option(argc, argv, &i, &opt.threads, &stats_path)) != 0) {
            if (c < 0)
                goto usage;
        } else if (strcmp(a, "--spd") == 0) {
            opt.spd = 1;
        } else if (strcmp(a, "-i") == 0 || is_opt(a, "--image")) {
            if (!(image_path = opt_value(argc, argv, &i, a[1] == 'i' ? "-i" : "--image")))
                goto usage;
        } else if (strcmp(a, "-o") == 0 || is_opt(a, "--output")) {
            if (!(tree_path = opt_value(argc, argv, &i, a[1] == 'o' ? "-o" : "--output")))
                goto usage;
        } else if (is_opt(a, "--set")) {
            if (!(v = opt_value(argc, argv, &i, "--set")))
                goto usage;
            if (!set_arg_ok(v))
                goto usage;
            sets[nsets++] = v;
        } else if (is_opt(a, "--params")) {
            if (!(params[nparams++] = opt_value(argc, argv, &i, "--params")))
                goto usage;
        } else if (is_opt(a, "--memory-limit")) {
            if (memory_limit_option(argc, argv, &i, &opt.memory_limit))
                goto usage;
        } else if (is_opt(a, "--region")) {
            if (!(v = opt_value(argc, argv, &i, "--region")))
                goto usage;
            if (parse_region(v, opt.region)) {
                msg("--region: expected x0,y0,x1,y1 with x0 < x1 and y0 < y1");
                goto usage;
            }
        } else if (is_opt(a, "--size")) {
            if (parse_size(opt_value(argc, argv, &i, "--size"), &opt.width, &opt.height))
                goto usage;
        } else if (is_opt(a, "--depth")) {
            if (!(v = opt_value(argc, argv, &i, "--depth")))
                goto usage;
            if (parse_int(v, 1, RTP_MAX_DEPTH, &opt.max_depth)) {
                msg("--depth: expected an integer from 1 to %d", RTP_MAX_DEPTH);
                goto usage;
            }
        } else if (is_opt(a, "--min-weight")) {
            if (!(v = opt_value(argc, argv, &i, "--min-weight")))
                goto usage;
            if (parse_double(v, &opt.min_weight) || opt.min_weight < 0) {
                msg("--min-weight: expected a finite number >= 0");
                goto usage;
            }
        } else {
            msg("trace: unknown option '%s'", a);
            goto usage;
        }
    }
    if (!scene_path) {
        msg("trace: no scene given");
        goto usage;
    }
    if (stdin_inputs("trace", scene_path, "the scene", params, nparams, sets, nsets, NULL))
        goto usage;
    if (tree_path && image_path && is_stdout(tree_path) && is_stdout(image_path)) {
        msg("trace: the tree and the image cannot both go to stdout");
        goto usage;
    }
    if (stdout_taken("trace", stats_path, tree_path, image_path))
        goto usage;
    if (!image_path && !tree_path) {
        /* (named before the outputs are checked: --stats s.png wrote over
           the default image s.png, exit 0) */
        default_image = default_image_name(strcmp(scene_path, "-") ? scene_path : "trace");
        if (!default_image) {
            msg("out of memory");
            goto out;
        }
        image_path = default_image;
    }
    /* two outputs on one file: a usage error, as two on stdout are (it
       was exit 1) */
    image_role = image_path == default_image ? "the default image" : "the image";
    if (same_output("trace", "the tree", tree_path, image_role, image_path) ||
        same_output("trace", "the tree", tree_path, "the --stats file", stats_path) ||
        same_output("trace", image_role, image_path, "the --stats file", stats_path)) {
        rc = EXIT_USAGE;
        goto out;
    }
    /* (the default's format is known: a scene named '' made it ".png",
       said instead of "no scene file name") */
    if (image_path && image_path != default_image && !image_name_ok(image_path))
        goto out;
    if (!output_ok(tree_path) || !output_ok(image_path) || !output_ok(stats_path))
        goto out;
    if (opt.spd && verbosity > 0) {
        const char *ign[3];
        int n = 0;
        if (opt.width && (opt.width != 512 || opt.height != 512))
            ign[n++] = "--size";
        if (opt.max_depth && opt.max_depth != 5)
            ign[n++] = "--depth";
        if (opt.min_weight > 0.0)
            ign[n++] = "--min-weight";
        if (n)
            msg("warning: --spd traces 512x512 to depth 5 with no weight cut-off: %s%s%s%s%s "
                "ignored", ign[0], n > 1 ? ", " : "", n > 1 ? ign[1] : "", n > 2 ? ", " : "",
                n > 2 ? ign[2] : "");
    }
    if (opt.spd) {
        /* (a size given with spd is the library's to trace: a builder's
           tree of corner samples) */
        opt.width = opt.height = 0;
        opt.max_depth = 5;
    }
    {
        const char *outs[3], *opts[3];
        outs[0] = tree_path;
        outs[1] = image_path;
        outs[2] = stats_path;
        opts[0] = "-o";
        opts[1] = image_path == default_image ? NULL : "-i";
        opts[2] = "--stats";
        if (outputs_over_inputs("trace", "the scene", &scene_path, 1, opts, outs, 3) ||
            outputs_over_inputs("trace", "the --params file", (const char *const *)params,
                                nparams, opts, outs, 3)) {
            rc = EXIT_USAGE;
            goto out;
        }
    }

    t0 = now_seconds();
    if (rtp_scene_load(scene_path, NULL, &scene, &err) != RTP_OK) {
        fail_err(&err);
        goto out;
    }
    /* the --params files in turn, then the --set edits: a later edit of a
       key wins */
    for (i = 0; i < nparams; i++)
        if (apply_params_file(set_scene, scene, params[i]))
            goto out;
    for (i = 0; i < nsets; i++)
        if (apply_kv(set_scene, scene, sets[i], "--set", 0, 0))
            goto out;
    {
        const char *outs[3], *opts[3];
        outs[0] = tree_path;
        outs[1] = image_path;
        outs[2] = stats_path;
        opts[0] = "-o";
        opts[1] = image_path == default_image ? "the default image" : "-i";
        opts[2] = "--stats";
        if (overwrites_scene_image("trace", scene, opts, outs, 3, 0)) {
            rc = EXIT_USAGE; /* (as an output naming the scene is) */
            goto out;
        }
    }
    t_load = now_seconds() - t0;
    if (verbosity > 0) {
        /* (a valid scene, but from a generator whose output went missing
           or an empty file, most likely a mistake: said, not refused) */
        rtp_scene_info si;
        rtp_scene_get_info(scene, &si);
        if (si.triangles + si.spheres + si.cones == 0)
            msg("warning: %s has no objects: the image is the background",
                in_name(scene_path)); /* (stdin's <stdin>, as every message names it) */
    }
    progress_start(&prog, verbosity > 0 && isatty(2));
    if (verbosity > 0 && isatty(2)) {
        opt.progress = progress_cb;
        opt.progress_user = &prog;
    }
    if ((tree_path ? rtp_record(scene, &opt, &tree, &img, &st, &err)
                   : rtp_trace(scene, &opt, &img, &st, &err)) != RTP_OK) {
        progress_end(&prog);
        /* an error of no file (out of memory in the kd-tree's build, a
           limit, keys that leave no view) said with the scene it stopped,
           stdin's named <stdin> as every message names it */
        if (!err.file[0] && err.line == 0) {
            char buf[600];
            msg("%s: %s", in_name(scene_path), rtp_error_format(&err, buf, sizeof buf));
        } else {
            fail_err(&err);
        }
        goto out;
    }
    progress_end(&prog);
    t_trace = now_seconds() - prog.start;
    t0 = now_seconds();
    /* (the image of any kind: one written to a full device or a pipe
       whose reader left fails as a file's does, and the tree is put
       back then too) */
    if (write_pair(tree, tree_path, &file_bytes, img, image_path, stats_path ? keeps : NULL))
        goto out;
    rtp_tree_get_info(tree, &ti);
    t_write = now_seconds() - t0;
    if (verbosity > 0 && st.capped_rays)
        capped_warning(st.capped_rays);
    if (verbosity > 1)
        fprintf(stderr,
                "rtp: %dx%d in %.3f s (load %.3f, build %.3f, trace %.3f, write %.3f); "
                "%llu eye %s, %llu %s, %llu shadow, %llu reflected, %llu refracted\n",
                st.width, st.height, t_load + t_trace + t_write, t_load,
                st.build_seconds, st.trace_seconds, t_write, st.eye_rays,
                noun(st.eye_rays, "ray", "rays"), st.eye_hits, noun(st.eye_hits, "hit", "hits"),
                st.shadow_rays, st.reflected_rays, st.refracted_rays);
    if (stats_path) {
        FILE *f = stats_open(stats_path);
        if (!f) {
            pair_settle(keeps, tree_path, image_path, 1);
            goto out;
        }
        fputs("{\"command\": \"trace\", \"scene\": ", f);
        json_string(f, scene_path);
        fprintf(f,
                ", \"width\": %d, \"height\": %d, "
                "\"spd\": %s, \"threads\": %d, \"seconds\": %.6f, \"load_seconds\": %.6f, "
                "\"build_seconds\": %.6f, \"trace_seconds\": %.6f, \"write_seconds\": %.6f, "
                "\"eye_rays\": %llu, \"eye_hits\": %llu, \"shadow_rays\": %llu, "
                "\"reflected_rays\": %llu, \"refracted_rays\": %llu, "
                "\"kd_nodes\": %llu, \"kd_leaves\": %llu, \"kd_prim_refs\": %llu, "
                "\"kd_depth\": %d, \"capped_rays\": %llu",
                st.width, st.height, opt.spd ? "true" : "false",
                opt.threads > 1 ? opt.threads : 1, t_load + t_trace + t_write, t_load,
                st.build_seconds, st.trace_seconds, t_write, st.eye_rays, st.eye_hits,
                st.shadow_rays, st.reflected_rays, st.refracted_rays, st.kd_nodes,
                st.kd_leaves, st.kd_prim_refs, st.kd_depth, st.capped_rays);
        fprintf(f, ", \"pixels\": %llu",
                (unsigned long long)st.width * (unsigned long long)st.height);
        if (tree)
            fprintf(f, ", \"samples\": %llu, \"nodes\": %llu, "
                       "\"bytes_per_node\": %u, \"tree_bytes\": %llu, \"file_bytes\": %llu",
                    ti.samples, ti.nodes, ti.bytes_per_node, ti.tree_bytes, file_bytes);
        fprintf(f, ", \"peak_rss_kb\": %ld}\n", peak_rss_kb());
        if (stats_settle(f, stats_path, keeps, tree_path, image_path, 0))
            goto out;
    }
    rc = 0;
out:
    rtp_tree_destroy(tree);
    rtp_image_destroy(img);
    rtp_scene_destroy(scene);
    free(default_image);
    free(sets);
    return rc;
usage:
    usage_hint(trace_help);
    free(default_image);
    free(sets);
    return EXIT_USAGE;
}

/* ----------------------------------------------------------------- diff */

static const char diff_help[] =
    "usage: rtp diff A B [options]\n"
    "Compares images A and B ('-' = stdin) and prints MAE, RMSE, PSNR, the\n"
    "maximum absolute error and the share of pixels above the threshold.\n"
    "  --threshold T           per-pixel error counted in 'above' (default 1/255)\n"
    "  --heatmap IMAGE         write a heat map of the per-pixel error (.png .ppm\n"
    "                          .pfm; '-' = PNG on stdout, PPM without libpng),\n"
    "                          full heat at the largest finite error, legend below\n"
    "  --fail-above METRIC=V   exit 3 when METRIC (mae, rmse, max_abs, above,\n"
    "                          or psnr: below V) is worse than V; repeatable,\n"
    "                          every one checked; above is a share from 0 to 1\n"
    "                          or a percent with '%' (above=0.5, above=50%)\n"
    "  --stats FILE            write the metrics as one JSON object ('-' = stdout)\n"
    "  -q, --quiet             print nothing on success\n"
    "  -v, --verbose           accepted (diff has nothing more to say)\n"
    "  -h, --help              this help\n"
    "With --heatmap - the heat map is on stdout and the line of metrics goes to\n"
    "stderr.\n";

static void json_number(FILE *f, const char *key, double v)
{
    if (isinf(v))
        fprintf(f, "\"%s\": \"%s\"", key, v > 0 ? "inf" : "-inf");
    else
        fprintf(f, "\"%s\": %.9g", key, v);
}

/* One --fail-above: its metric and limit. */
typedef struct fail_limit {
    char metric[32];
    double value;
    int percent; /* given as a percent: said as one */
} fail_limit;

static int cmd_diff(int argc, char **argv)
{
    const char *pa = NULL, *pb = NULL, *heat = NULL, *stats_path = NULL;
    keep_old hkeep[2]; /* the heat map's old contents while --stats is written */
    double threshold = 1.0 / 255.0;
    rtp_image *a = NULL, *b = NULL;
    rtp_diff_stats d;
    rtp_error err;
    int i, rc = 1, over = 0, c, held, nfail = 0, k, names_only = 0;
    rtp_status hs;
    fail_limit *fails;
    double t0, seconds;

    memset(&err, 0, sizeof err);
    fails = (fail_limit *)calloc((size_t)argc + 1, sizeof *fails);
    if (!fails) {
        msg("out of memory");
        return 1;
    }
    for (i = 0; i < argc; i++) {
        const char *arg = argv[i], *v;
        int kind = arg_kind(arg, &names_only);
        if (kind == ARG_END)
            continue;
        if (kind == ARG_OPERAND) {
            if (pa && pb) {
                msg("diff: more than two images");
                goto usage;
            }
            *(pa ? &pb : &pa) = arg;
        } else if (strcmp(arg, "-h") == 0 || strcmp(arg, "--help") == 0) {
            fputs(diff_help, stdout);
            free(fails);
            return 0;
        } else if ((c = common_option(argc, argv, &i, NULL, &stats_path)) != 0) {
            if (c < 0)
                goto usage;
        } else if (is_opt(arg, "--heatmap")) {
            if (!(heat = opt_value(argc, argv, &i, "--heatmap")))
                goto usage;
        } else if (is_opt(arg, "--threshold")) {
            if (!(v = opt_value(argc, argv, &i, "--threshold")))
                goto usage;
            if (parse_double(v, &threshold) || threshold < 0) {
                msg("--threshold: expected a finite number >= 0");
                goto usage;
            }
        } else if (is_opt(arg, "--fail-above")) {
            /* repeatable: every limit is checked (a second one had
               silently replaced the first, so a regression the first
               caught exited 0) */
            fail_limit *fl = &fails[nfail];
            const char *eq;
            char num[64];
            size_t n, vn;
            int percent;
            if (!(v = opt_value(argc, argv, &i, "--fail-above")))
                goto usage;
            eq = strchr(v, '=');
            n = eq ? (size_t)(eq - v) : 0;
            vn = eq ? strlen(eq + 1) : 0;
            percent = vn > 0 && eq[vn] == '%';
            if (percent)
                vn--;
            if (eq && vn < sizeof num) {
                memcpy(num, eq + 1, vn);
                num[vn] = '\0';
            }
            if (!eq || n >= sizeof fl->metric) {
                msg("--fail-above %s: expected METRIC=VALUE", v);
                goto usage;
            }
            memcpy(fl->metric, v, n);
            fl->metric[n] = '\0';
            /* (the metric first: psrn=inf had been told of its number) */
            if (strcmp(fl->metric, "mae") && strcmp(fl->metric, "rmse") &&
                strcmp(fl->metric, "max_abs") && strcmp(fl->metric, "psnr") &&
                strcmp(fl->metric, "above")) {
                msg("--fail-above: unknown metric '%s' (mae, rmse, psnr, max_abs, above)",
                    fl->metric);
                goto usage;
            }
            /* (psnr=inf, "identical or fail", had been told it was not
               METRIC=VALUE; a finite number too long for num, that it
               was no finite number) */
            if (vn >= sizeof num) {
                msg("--fail-above %s: the number after '=' is over %d characters", v,
                    (int)sizeof num - 1);
                goto usage;
            }
            if (parse_double(num, &fl->value)) {
                msg("--fail-above %s: expected a finite number after '='%s", v,
                    strcmp(fl->metric, "psnr") == 0 ? " (identical images: max_abs=0)" : "");
                goto usage;
            }
            if (percent && strcmp(fl->metric, "above") != 0) {
                msg("--fail-above %s: only above takes a percent", v);
                goto usage;
            }
            /* above: the share of pixels over --threshold, which the
               line of metrics prints as a percent and JSON as a share;
               a limit over 1 without '%' was one that never failed */
            fl->percent = percent;
            if (percent)
                fl->value /= 100.0;
            if (strcmp(fl->metric, "above") == 0 && !(fl->value >= 0.0 && fl->value <= 1.0)) {
                msg("--fail-above %s: above is a share from 0 to 1, or a percent from 0%% to "
                    "100%% (above=0.05 or above=5%%)",
                    v);
                goto usage;
            }
            /* (an error is never below 0: mae=-1 failed every pair of
               images, identical ones too; psnr may be, past a peak of 1) */
            if (strcmp(fl->metric, "psnr") != 0 && fl->value < 0.0) {
                msg("--fail-above %s: %s is 0 or more: expected a limit >= 0", v, fl->metric);
                goto usage;
            }
            nfail++;
        } else {
            msg("diff: unknown option '%s'", arg);
            goto usage;
        }
    }
    if (!pa || !pb) {
        msg("diff: two images needed");
        goto usage;
    }
    if (reads_stdin(pa) && reads_stdin(pb)) {
        /* (- and /dev/stdin, a pipe's two names: the second read it
           empty, "the file is empty") */
        msg("diff: only one image can come from stdin");
        goto usage;
    }
    if (stdin_closed_for("diff", pa, "an image") || stdin_closed_for("diff", pb, "an image"))
        goto usage;
    if (stdout_taken("diff", stats_path, heat, NULL))
        goto usage;
    {
        const char *ins[2], *outs[2], *opts[2];
        ins[0] = pa;
        ins[1] = pb;
        outs[0] = heat;
        outs[1] = stats_path;
        opts[0] = "--heatmap";
        opts[1] = "--stats";
        if (outputs_over_inputs("diff", "the image", ins, 2, opts, outs, 2) ||
            same_output("diff", "the heat map", heat, "the --stats file", stats_path)) {
            rc = EXIT_USAGE;
            goto out;
        }
    }
    /* outputs checked before the inputs are read, as trace's are; the
       heat map's format by its name, as -i's (x.jpg had been written a
       PNG, exit 0) */
    if (heat && !image_name_ok(heat))
        goto out;
    if (!output_ok(heat) || !output_ok(stats_path))
        goto out;
    t0 = now_seconds();
    if (rtp_image_read(pa, NULL, &a, &err) != RTP_OK ||
        rtp_image_read(pb, NULL, &b, &err) != RTP_OK) {
        fail_err(&err);
        goto out;
    }
    if (a->width != b->width || a->height != b->height) {
        /* (the library's message has the sizes; the names are here) */
        msg("%s is %dx%d, %s %dx%d: image sizes differ", in_name(pa), a->width, a->height,
            in_name(pb), b->width, b->height);
        goto out;
    }
    if (rtp_image_diff(a, b, threshold, &d, &err) != RTP_OK) {
        fail_err(&err);
        goto out;
    }
    /* (the heat map's old contents kept while --stats is written: a
       stats file that fails puts it back, as trace's image) */
    hkeep[0].state = hkeep[1].state = 0;
    if (heat && stats_path && output_is_file(heat))
        keep_take(&hkeep[1], heat);
    held = heat ? hold_signals(heat) : 0;
    hs = heat ? rtp_diff_heatmap(a, b, 0.0, heat, &err) : RTP_OK;
    if (hs != RTP_OK) {
        release_signals(held);
        keep_drop(&hkeep[1]); /* (the failed write left the old file) */
        fail_err(&err);
        goto out;
    }
    if (stats_path) {
        pair_keep[1] = &hkeep[1];
        pair_live = 1;
    }
    release_signals(held);
    /* (the command's whole work, as trace's seconds: both reads, the
       comparison and the heat map; BRIEF's --stats keys have seconds) */
    seconds = now_seconds() - t0;
    if (verbosity > 0 && !(stats_path && strcmp(stats_path, "-") == 0)) {
        /* (to stderr when the heat map takes stdout) */
        fprintf(is_stdout(heat) ? stderr : stdout,
               "pixels %zu  mae %.6g  rmse %.6g  psnr %s%.6g dB  max_abs %.6g  above %.4f%%\n",
               d.pixels, d.mae, d.rmse, isinf(d.psnr) ? "" : "", d.psnr, d.max_abs,
               100.0 * d.share_above);
    }
    if (stats_path) {
        FILE *f = stats_open(stats_path);
        if (!f) {
            pair_settle(hkeep, NULL, heat, 1);
            goto out;
        }
        fprintf(f, "{\"command\": \"diff\", \"seconds\": %.6f, \"pixels\": %zu, ", seconds,
                d.pixels);
        json_number(f, "mae", d.mae);
        fputs(", ", f);
        json_number(f, "rmse", d.rmse);
        fputs(", ", f);
        json_number(f, "psnr", d.psnr);
        fputs(", ", f);
        json_number(f, "max_abs", d.max_abs);
        fputs(", ", f);
        json_number(f, "above", d.share_above);
        fprintf(f, ", \"threshold\": %.9g}\n", threshold);
        hs = stats_settle(f, stats_path, hkeep, NULL, heat, 0) ? RTP_ERR_IO : RTP_OK;
        if (hs != RTP_OK)
            goto out;
    }
    for (k = 0; k < nfail; k++) {
        const char *m = fails[k].metric;
        double got = strcmp(m, "mae") == 0       ? d.mae
                     : strcmp(m, "rmse") == 0    ? d.rmse
                     : strcmp(m, "max_abs") == 0 ? d.max_abs
                     : strcmp(m, "above") == 0   ? d.share_above
                                                 : d.psnr;
        int psnr = strcmp(m, "psnr") == 0;
        if (psnr ? got < fails[k].value : got > fails[k].value) {
            /* said under -q too: quiet is for success; a percent limit
               as a percent, as the line of metrics says above (5% was
               said as "the limit 0.05") */
            double f = fails[k].percent ? 100.0 : 1.0;
            const char *pc = fails[k].percent ? "%" : "";
            msg("diff: %s = %.6g%s is %s the limit %.6g%s", m, f * got, pc,
                psnr ? "below" : "above", f * fails[k].value, pc);
            over = 1;
        }
    }
    rc = over ? EXIT_OVER : 0;
out:
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    free(fails);
    return rc;
usage:
    usage_hint(diff_help);
    free(fails);
    return EXIT_USAGE;
}


/* --------------------------------------------------------------- reeval */

static const char reeval_help[] =
    "usage: rtp reeval TREE [options]\n"
    "Re-evaluates the ray trees in TREE ('-' = stdin) with edited parameters\n"
    "and writes the image, without tracing a ray.\n"
    "  -i, --image FILE     image to write (.png .ppm .pfm; '-' = PFM on stdout);\n"
    "                       default: TREE's name with .png ('-': reeval.png;\n"
    "                       .ppm in a build without PNG), in the current folder\n"
    "  --set KEY=VALUE      edit a parameter (repeatable); keys as for trace\n"
    "  --params FILE        edits from FILE: KEY=VALUE per line, '#' comments;\n"
    "                       repeatable (files in turn, then the --set edits)\n"
    "  --stream             read edit sets from stdin, one line each (KEY=VALUE\n"
    "                       pairs; edits persist; light.N.pos with N the count\n"
    "                       of lights adds one), and write one image per line:\n"
    "                       -i takes a pattern with %d (or %04d; %% for a '%'),\n"
    "                       or '-' for a stream of PFM images on stdout (so\n"
    "                       does a device: /dev/null)\n"
    "  --shadows MODE       shadows of moved or added lights: auto[:RES] (exact:\n"
    "                       the light buffer where the tree has 4 or more hits a\n"
    "                       primitive, else shadow rays, but the light buffer for\n"
    "                       one or two lights moved by a single reeval, which\n"
    "                       builds no kd-tree; default),\n"
    "                       exact (shadow rays), lightbuf[:RES] (light buffer,\n"
    "                       exact), itembuf[:RES] (item buffer, approximate at\n"
    "                       shadow edges), osmesa[:RES] (item buffer by OSMesa);\n"
    "                       RES: direction-cube cells per face edge, 1 to 8192\n"
    "                       (default: the light buffer's 64 to 512 from the\n"
    "                       tree's hits, --stats' shadow_res; the item\n"
    "                       buffer's 512)\n"
    "  --stale MODE         after a bump edit, the reflected and refracted rays\n"
    "                       below changed normals: keep (the paper's way, fast,\n"
    "                       approximate; default) or retrace (exact)\n"
    "  --add-light X,Y,Z    add a white light (repeatable); it is light N, after\n"
    "                       the scene's lights, for --set light.N.*; as bright\n"
    "                       as each of them (their intensity is not rescaled)\n"
    "  --region X0,Y0,X1,Y1 evaluate and write only these pixels of the frame\n"
    "                       (edits cost in proportion to the region)\n"
    "  --memory-limit MIB   stop when trees traced again (with those held), a\n"
    "                       moved light's direction cube or light buffer lists,\n"
    "                       or --reference's full trace would take more (for\n"
    "                       a light buffer without :RES, coarser cells; auto's\n"
    "                       where none fits or with :RES, shadow rays instead;\n"
    "                       default 16384)\n"
    "  --reference          also trace the edited scene in full and report both\n"
    "                       times and the error of the re-evaluation\n"
    "  -j, --threads N      threads, 1 to 256 (default: the processors online)\n"
    "  --stats FILE         write statistics as one JSON object ('-' = stdout)\n"
    "  -q, --quiet          no messages but errors\n"
    "  -v, --verbose        the evaluation's time and nodes on stderr\n"
    "  -h, --help           this help\n"
    "Edits that change where rays go (a new ior, ks or kt raised from 0, any\n"
    "ks or kt edit of a tree traced with --min-weight) trace again exactly the\n"
    "samples that contain the material, the rays below its hits (--stats\n"
    "reports retraced_samples and retraced_rays); the result equals a full\n"
    "trace.  A camera key\n"
    "(camera.from|at|up|angle|hither) traces every sample again: a full trace\n"
    "from the tree file, said so; later edits re-evaluate.\n";

/* Expands a --stream pattern: its one %d or %0Nd (N up to 12) to n, each
   %% to a '%' (a literal '%' in a folder's or frame's name); returns 0,
   or -1 where it has no %d, two, another conversion, or out of room. */
static int expand_pattern(const char *pat, int n, char *out, size_t size)
{
    size_t o = 0;
    int seen = 0;
    for (; *pat; pat++) {
        char num[32];
        const char *piece = pat;
        size_t len = 1;
        if (*pat == '%' && pat[1] == '%') {
            pat++;
        } else if (*pat == '%') {
            int width = 0;
            const char *q = pat + 1;
            if (*q == '0')
                for (q++; *q >= '0' && *q <= '9'; q++)
                    if ((width = width * 10 + (*q - '0')) > 12)
                        return -1;
            if (*q != 'd' || seen++)
                return -1;
            snprintf(num, sizeof num, "%0*d", width, n);
            piece = num;
            len = strlen(num);
            pat = q;
        }
        if (o + len >= size)
            return -1;
        memcpy(out + o, piece, len);
        o += len;
    }
    if (!seen)
        return -1;
    out[o] = '\0';
    return 0;
}

/* Whether a --stream's -i is a character device named without a %d
   (/dev/null, a stream timed): every frame is written there, one after
   another, as '-' writes them to stdout.  (Not a FIFO: each frame opens
   its file, and its reader, at the end of a frame, could be gone before
   the next frame's open, which then waited for ever.) */
static int stream_device(const char *path)
{
    struct stat sb;
    char probe[4096];
    return stat(path, &sb) == 0 && S_ISCHR(sb.st_mode) &&
           expand_pattern(path, 0, probe, sizeof probe) != 0;
}

/* --shadows' modes, indexed by rtp_shadow_mode (--stats' "shadows" names
   the one that decided a move, auto resolved). */
static const char *const shadow_modes[] = {"exact", "lightbuf", "itembuf", "osmesa", "auto"};
#define N_SHADOW_MODES (sizeof shadow_modes / sizeof *shadow_modes)

/* A regular file's size, else -1 (a FIFO is not opened again: that waited
   for a writer that never came). */
static long long file_size(const char *path)
{
    struct stat sb;
    if (strcmp(path, "-") == 0 || stat(path, &sb) != 0 || !S_ISREG(sb.st_mode))
        return -1;
    return (long long)sb.st_size;
}

/* What follows an evaluation: the full trace of --reference (tree: the
   tree evaluated; under --memory-limit, as trace is), its image written,
   the messages, its --stats line.  0, or 1 after a message.  With
   stats, the image's old contents are kept (keep: the image's and an
   unused one, as write_pair's) until its line is written: a line that
   fails puts the image back (a new one removed), so a frame fails whole;
   with ikeep they stay kept for the caller's pair_settle after the stats
   file's close (a one-off's), else settled here (a stream's frame). */
static int reeval_report(const rtp_tree *tree, const rtp_image *img, const rtp_eval_stats *es_in,
                         const rtp_tree_info *ti_in, const char *image_path, int reference,
                         int threads, double memory_limit, FILE *stats, const char *stats_path,
                         const char *tree_path, double load_seconds, int line, keep_old *ikeep)
{
    keep_old own[2];
    keep_old *keep = ikeep ? ikeep : own;
    keep[0].state = keep[1].state = 0;
    rtp_image *ref = NULL;
    rtp_eval_stats es = *es_in;
    rtp_tree_info ti = *ti_in;
    rtp_trace_stats ts;
    rtp_diff_stats d;
    rtp_error err;
    double t_ref = 0.0;
    int rc = 1, held = 0;
    memset(&err, 0, sizeof err);
    if (reference) {
        /* the full trace alone, as `seconds` is the evaluation alone
           (the comparison after it was timed with it); before the image
           is written, so that a reference that fails leaves no image
           (exit 1 had left it written) */
        double t0 = now_seconds();
        rtp_trace_options to;
        memset(&to, 0, sizeof to);
        to.threads = threads;
        to.memory_limit = memory_limit;
        if (rtp_tree_trace_opt(tree, &to, &ref, &ts, &err) != RTP_OK) {
            /* (said as the reference's: "a 40x30 traced image needs"
               answered a reeval) */
            char buf[600], where[32] = "";
            if (line > 0)
                snprintf(where, sizeof where, "<stdin>:%d: ", line);
            msg("%s--reference: %s", where, rtp_error_format(&err, buf, sizeof buf));
            goto out;
        }
        t_ref = now_seconds() - t0;
        if (rtp_image_diff(img, ref, 1.0 / 255.0, &d, &err) != RTP_OK) {
            fail_line(&err, line);
            goto out;
        }
    }
    if (stats && image_path && output_is_file(image_path)) {
        held = hold_signals(image_path); /* (till pair_live, as write_pair's) */
        keep_take(&keep[1], image_path);
    }
    if (image_path && write_image(img, image_path, &err) != RTP_OK) {
        release_signals(held);
        fail_line(&err, line);
        keep_drop(&keep[1]); /* (the failed write left the old image) */
        goto out;
    }
    if (stats) {
        pair_keep[1] = &keep[1];
        pair_live = 1;
    }
    release_signals(held);
    if (reference) {
        if (verbosity > 0)
            fprintf(stderr,
                    "rtp: reeval %.4f s, full trace %.4f s (%.1fx); error: rmse %.3g, "
                    "psnr %.4g dB, max_abs %.3g\n",
                    es.seconds, t_ref, es.seconds > 0 ? t_ref / es.seconds : 0.0, d.rmse,
                    d.psnr, d.max_abs);
    } else if (verbosity > 1) {
        fprintf(stderr, "rtp: reeval %.4f s, %llu %s\n", es.seconds, es.nodes,
                noun(es.nodes, "node", "nodes"));
    }
    if (verbosity > 0 && es.camera_moved)
        fprintf(stderr, "rtp: traced %s %llu %s again (%llu %s): the camera moved, a full "
                        "trace\n",
                noun(es.retraced_samples, "the", "all"), es.retraced_samples,
                noun(es.retraced_samples, "sample", "samples"), es.retraced_rays,
                noun(es.retraced_rays, "ray", "rays"));
    else if (verbosity > 0 && es.retraced_samples)
        fprintf(stderr, "rtp: traced %llu of %llu %s again (%llu %s) for edits that move rays\n",
                es.retraced_samples, es.samples, noun(es.samples, "sample", "samples"),
                es.retraced_rays, noun(es.retraced_rays, "ray", "rays"));
    if (verbosity > 0 && es.capped_rays)
        capped_warning(es.capped_rays);
    /* (once a run: a stream of bump edits would say it every frame) */
    if (verbosity > 0 && es.stale_samples && !stale_warned) {
        fprintf(stderr,
                "rtp: warning: %llu %s reflected or refracted rays traced before "
                "the bump edit (--stale keep, the default: approximate there; --stale retrace "
                "is exact, --reference measures the error)\n",
                es.stale_samples, noun(es.stale_samples, "sample keeps", "samples keep"));
        stale_warned = 1;
    }
    if (stats) {
        long long fb = file_size(tree_path);
        fprintf(stats,
                "{\"command\": \"reeval\", \"seconds\": %.6f, \"load_seconds\": %.6f, "
                "\"shadow_seconds\": %.6f, \"moved_lights\": %d, \"shadow_queries\": %llu, "
                "\"retraced_samples\": %llu, \"retraced_rays\": %llu, \"capped_rays\": %llu, "
                "\"stale_samples\": %llu, "
                "\"combined_samples\": %llu, \"written_pixels\": %llu, \"pixels\": %llu, \"samples\": %llu, \"nodes\": %llu, \"bytes_per_node\": %u, "
                "\"tree_bytes\": %llu",
                es.seconds, load_seconds, es.shadow_seconds, es.moved_lights,
                es.shadow_queries, es.retraced_samples, es.retraced_rays, es.capped_rays,
                es.stale_samples, es.combined_samples,
                es.written_pixels,
                (unsigned long long)img->width * img->height,
                ti.samples, ti.nodes, ti.bytes_per_node, ti.tree_bytes);
        if (fb >= 0)
            fprintf(stats, ", \"file_bytes\": %lld", fb);
        if (es.moved_lights)
            fprintf(stats, ", \"shadows\": \"%s\", \"shadow_res\": %d",
                    (size_t)es.shadows < N_SHADOW_MODES ? shadow_modes[es.shadows] : "?",
                    es.shadow_res);
        if (reference) {
            fprintf(stats, ", \"reference_seconds\": %.6f, \"speedup\": %.3f, ", t_ref,
                    es.seconds > 0 ? t_ref / es.seconds : 0.0);
            json_number(stats, "mae", d.mae);
            fputs(", ", stats);
            json_number(stats, "rmse", d.rmse);
            fputs(", ", stats);
            json_number(stats, "psnr", d.psnr);
            fputs(", ", stats);
            json_number(stats, "max_abs", d.max_abs);
        }
        fprintf(stats, ", \"peak_rss_kb\": %ld}\n", peak_rss_kb());
        /* (each frame's line as its image goes out: a UI reading --stats
           from a pipe or FIFO got them ten at a time, 4 KiB of buffer) */
        errno = 0;
        if (fflush(stats) != 0 || ferror(stats)) {
            /* a line that fails: a stream whose stats could not be
               written ran on to its last line and failed only then,
               every frame's stats lost, the reason too */
            int e = errno;
            char where[32] = "";
            if (line > 0)
                snprintf(where, sizeof where, "<stdin>:%d: ", line);
            msg("%s%s: error writing stats: %s", where,
                stats == stdout ? "stdout" : stats == stderr ? "stderr" : stats_path,
                e ? strerror(e) : "write failed");
            pair_settle(keep, NULL, image_path, 1);
            goto out;
        }
        if (!ikeep)
            pair_settle(keep, NULL, image_path, 0);
    }
    rc = 0;
out:
    rtp_image_destroy(ref);
    return rc;
}

static int reeval_one(rtp_tree *tree, const rtp_eval_options *eo, rtp_image **keep,
                      const char *image_path, int reference, int threads,
                      FILE *stats, const char *stats_path, const char *tree_path,
                      double load_seconds, int line, keep_old *ikeep)
{
    rtp_image *img = *keep;
    rtp_eval_stats es;
    rtp_tree_info ti;
    rtp_error err;
    rtp_status st;
    memset(&err, 0, sizeof err);
    if (eo->progress == progress_cb)
        progress_start((progress *)eo->progress_user, 1);
    /* a stream of edits reuses one image */
    st = img ? rtp_tree_eval_into(tree, eo, img, &es, &err)
             : rtp_tree_eval(tree, eo, &img, &es, &err);
    if (eo->progress == progress_cb) /* (its line ended before any other) */
        progress_end((progress *)eo->progress_user);
    if (st != RTP_OK) {
        fail_line(&err, line);
        return 1;
    }
    *keep = img;
    rtp_tree_get_info(tree, &ti);
    return reeval_report(tree, img, &es, &ti, image_path, reference, threads, eo->memory_limit,
                         stats, stats_path,
                         tree_path, load_seconds, line, ikeep);
}

/* A one-off reeval's edits, made by rtp_tree_eval_file's callback once
   the tree file's scene is read: the added lights, the --params files in
   turn, then the --set edits (a later edit of a key wins). */
typedef struct cli_edits {
    const char **add_lights, **params, **sets;
    int nadd, nparams, nsets;
    int reported; /* a message was printed (apply_kv's, with its place) */
    int usage;    /* ...and it was a usage error's (an output over an input) */
    const char *outs[2]; /* the image and --stats files */
    const char *opts[2]; /* their options (the default image: its words) */
    double t_edits; /* when the callback was called */
} cli_edits;

static rtp_status make_edits(void *user, rtp_tree *tree, rtp_error *err)
{
    cli_edits *c = (cli_edits *)user;
    int i;
    rtp_status st;
    c->t_edits = now_seconds();
    for (i = 0; i < c->nadd; i++) {
        double pos[3];
        parse_xyz(c->add_lights[i], pos); /* (checked with the options) */
        if ((st = rtp_tree_add_light(tree, pos, err)) != RTP_OK)
            return st;
    }
    for (i = 0; i < c->nparams; i++)
        if (apply_params_file(set_tree, tree, c->params[i])) {
            c->reported = 1;
            return RTP_ERR_ARGUMENT;
        }
    for (i = 0; i < c->nsets; i++)
        if (apply_kv(set_tree, tree, c->sets[i], "--set", 0, 0)) {
            c->reported = 1;
            return RTP_ERR_ARGUMENT;
        }
    if (overwrites_scene_image("reeval", rtp_tree_scene(tree), c->opts, c->outs, 2, 0)) {
        c->reported = c->usage = 1;
        return RTP_ERR_ARGUMENT;
    }
    return RTP_OK;
}

static int cmd_reeval(int argc, char **argv)
{
    const char *tree_path = NULL, *image_path = NULL, *stats_path = NULL;
    char *default_image = NULL;
    const char **sets, **add_lights, **params;
    rtp_image *img = NULL;
    int region[4] = {0, 0, 0, 0};
    int i, nsets = 0, nadd = 0, nparams = 0, rc = 1, stream = 0, reference = 0, names_only = 0,
        threads = default_threads(), c, frames = 0;
    rtp_tree *tree = NULL;
    rtp_error err;
    rtp_eval_options eo;
    progress prog;
    FILE *stats = NULL;
    keep_old ikeep[2]; /* the image's old contents while --stats is written */
    double t0, t_load;

    memset(&err, 0, sizeof err);
    memset(&eo, 0, sizeof eo);
    eo.shadows = RTP_SHADOWS_AUTO; /* exact, by whichever is faster for the tree */
    sets = (const char **)calloc(2 * ((size_t)argc + 1), sizeof *sets);
    add_lights = (const char **)calloc((size_t)argc + 1, sizeof *add_lights);
    params = sets ? sets + argc + 1 : NULL;
    if (!sets || !add_lights) {
        free(sets);
        free(add_lights);
        msg("out of memory");
        return 1;
    }
    for (i = 0; i < argc; i++) {
        const char *a = argv[i], *v;
        int kind = arg_kind(a, &names_only);
        if (kind == ARG_END)
            continue;
        if (kind == ARG_OPERAND) {
            if (tree_path) {
                msg("reeval: more than one tree ('%s' and '%s')", tree_path, a);
                goto usage;
            }
            tree_path = a;
        } else if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            fputs(reeval_help, stdout);
            free(sets);
            free(add_lights);
            return 0;
        } else if ((c = common_option(argc, argv, &i, &threads, &stats_path)) != 0) {
            if (c < 0)
                goto usage;
        } else if (strcmp(a, "--stream") == 0) {
            stream = 1;
        } else if (strcmp(a, "--reference") == 0) {
            reference = 1;
        } else if (strcmp(a, "-i") == 0 || is_opt(a, "--image")) {
            if (!(image_path = opt_value(argc, argv, &i, a[1] == 'i' ? "-i" : "--image")))
                goto usage;
        } else if (is_opt(a, "--set")) {
            if (!(v = opt_value(argc, argv, &i, "--set")) || !set_arg_ok(v))
                goto usage;
            sets[nsets++] = v;
        } else if (is_opt(a, "--params")) {
            if (!(params[nparams++] = opt_value(argc, argv, &i, "--params")))
                goto usage;
        } else if (is_opt(a, "--shadows")) {
            const char *colon;
            size_t n, m;
            if (!(v = opt_value(argc, argv, &i, "--shadows")))
                goto usage;
            colon = strchr(v, ':');
            n = colon ? (size_t)(colon - v) : strlen(v);
            for (m = 0; m < N_SHADOW_MODES; m++)
                if (strlen(shadow_modes[m]) == n && strncmp(v, shadow_modes[m], n) == 0)
                    break;
            if (m == N_SHADOW_MODES || (colon && (m < 1 || parse_int(colon + 1, 1, RTP_MAX_SHADOW_RES, &eo.shadow_res)))) {
                msg("--shadows %s: expected auto[:RES], exact, lightbuf[:RES], itembuf[:RES] or "
                    "osmesa[:RES], RES from 1 to %d",
                    v, RTP_MAX_SHADOW_RES);
                goto usage;
            }
            eo.shadows = (rtp_shadow_mode)m;
            if (eo.shadows == RTP_SHADOWS_OSMESA && !(rtp_features() & RTP_FEATURE_OSMESA)) {
                /* (here, before a stream waits on its first line: the
                   evaluation would refuse it there) */
                msg("--shadows osmesa: this build has no OSMesa (rebuild with make OSMESA=1 "
                    "and libosmesa6-dev); use itembuf for the same item buffer in software");
                goto out; /* (rc is 1 until the end) */
            }
        } else if (is_opt(a, "--region")) {
            if (!(v = opt_value(argc, argv, &i, "--region")))
                goto usage;
            if (parse_region(v, region)) {
                msg("--region: expected x0,y0,x1,y1 with x0 < x1 and y0 < y1");
                goto usage;
            }
        } else if (is_opt(a, "--memory-limit")) {
            if (memory_limit_option(argc, argv, &i, &eo.memory_limit))
                goto usage;
        } else if (is_opt(a, "--stale")) {
            if (!(v = opt_value(argc, argv, &i, "--stale")))
                goto usage;
            if (strcmp(v, "keep") == 0) {
                eo.stale = RTP_STALE_KEEP;
            } else if (strcmp(v, "retrace") == 0) {
                eo.stale = RTP_STALE_RETRACE;
            } else {
                msg("--stale %s: expected keep or retrace", v);
                goto usage;
            }
        } else if (is_opt(a, "--add-light")) {
            double pos[3];
            if (!(v = opt_value(argc, argv, &i, "--add-light")))
                goto usage;
            if (parse_xyz(v, pos)) {
                msg("--add-light %s: expected X,Y,Z: 3 comma-separated numbers (|x| <= 3.4e38)",
                    v);
                goto usage;
            }
            add_lights[nadd++] = v;
        } else {
            msg("reeval: unknown option '%s'", a);
            goto usage;
        }
    }
    if (!tree_path) {
        msg("reeval: no tree file given");
        goto usage;
    }
    if (stream && strcmp(tree_path, "-") == 0) {
        msg("reeval: --stream reads edits from stdin, so the tree cannot come from it");
        goto usage;
    }
    if (stdin_inputs("reeval", tree_path, "the tree", params, nparams, sets, nsets,
                     stream ? "--stream's edits" : NULL))
        goto usage;
    if (!image_path) {
        default_image = default_image_name(strcmp(tree_path, "-") ? tree_path : "reeval");
        if (!default_image) {
            msg("out of memory");
            goto out;
        }
        image_path = default_image;
    }
    {
        const char *outs[2], *opts[2];
        outs[0] = stats_path;
        /* (a stream's frames are checked as their names come, but '-'
           is one name, known now: with `> TREE` the tree read empty) */
        outs[1] = stream && strcmp(image_path, "-") != 0 ? NULL : image_path;
        opts[0] = "--stats";
        opts[1] = image_path == default_image ? NULL : "-i";
        if (outputs_over_inputs("reeval", "the tree", &tree_path, 1, opts, outs, 2) ||
            outputs_over_inputs("reeval", "the --params file", (const char *const *)params,
                                nparams, opts, outs, 2) ||
            (!stream &&
             same_output("reeval", image_path == default_image ? "the default image" : "the image",
                         image_path, "the --stats file", stats_path))) {
            rc = EXIT_USAGE;
            goto out;
        }
    }
    if (stdout_taken("reeval", stats_path, image_path, NULL))
        goto usage;
    if (stream && strcmp(image_path, "-") != 0 && !stream_device(image_path)) {
        char probe[4096];
        if (expand_pattern(image_path, 0, probe, sizeof probe) != 0) {
            msg("--stream: -i needs a pattern with one %%d (e.g. frame%%04d.png; %%%% for a "
                "'%%') or '-'");
            goto usage;
        }
        if (!image_name_ok(probe) || !output_ok(probe))
            goto out;
    } else if (!image_name_ok(image_path) || !output_ok(image_path)) {
        goto out;
    }
    if (!output_ok(stats_path))
        goto out;
    eo.threads = threads;
    /* one image: caches for later edits would only cost time */
    eo.no_cache = !stream;
    /* the stream's one image is only read between edits: an edit writes
       only the pixels it changes */
    eo.incremental = stream;
    progress_start(&prog, 0);
    if (verbosity > 0 && isatty(2) && !stream) {
        eo.progress = progress_cb;
        eo.progress_user = &prog;
    }

    t0 = now_seconds();
    if (!stream && !reference && region[2] == 0) {
        /* One image: the tree's samples evaluated as they are read, none
           kept where the edits allow it (rtp_tree_eval_file; README:
           "One-off evaluation") */
        cli_edits ce;
        rtp_eval_stats es;
        rtp_tree_info ti;
        rtp_status st;
        memset(&ce, 0, sizeof ce);
        ce.add_lights = add_lights;
        ce.nadd = nadd;
        ce.params = params;
        ce.nparams = nparams;
        ce.sets = sets;
        ce.nsets = nsets;
        ce.outs[0] = image_path;
        ce.outs[1] = stats_path;
        ce.opts[0] = image_path == default_image ? "the default image" : "-i";
        ce.opts[1] = "--stats";
        ce.t_edits = -1.0;
        if (eo.progress == progress_cb)
            progress_start(&prog, 1);
        st = rtp_tree_eval_file(tree_path, NULL, make_edits, &ce, &eo, &img, &ti, &es, &err);
        progress_end(&prog);
        if (st != RTP_OK) {
            if (!ce.reported)
                fail_err(&err);
            if (ce.usage)
                rc = EXIT_USAGE;
            goto out;
        }
        /* (the scene's reading: the trees' is in es.seconds) */
        t_load = ce.t_edits - t0;
        if (stats_path && !(stats = stats_open(stats_path)))
            goto out;
        rc = reeval_report(NULL, img, &es, &ti, image_path, 0, threads, eo.memory_limit, stats,
                           stats_path,
                           tree_path, t_load, 0, ikeep);
        if (stats_settle(stats, stats_path, ikeep, NULL, image_path, rc != 0) && rc == 0)
            rc = 1;
        stats = NULL;
        goto out;
    }
    if (rtp_tree_read(tree_path, NULL, &tree, &err) != RTP_OK) {
        fail_err(&err);
        goto out;
    }
    /* --region: the tree of those pixels only, so every evaluation, move
       and re-trace costs in proportion to the region */
    if (region[2] > 0) {
        rtp_tree *part = NULL;
        if (rtp_tree_crop(tree, region, &part, &err) != RTP_OK) {
            fail_err(&err);
            goto out;
        }
        rtp_tree_destroy(tree);
        tree = part;
    }
    t_load = now_seconds() - t0;
    for (i = 0; i < nadd; i++) {
        double pos[3];
        parse_xyz(add_lights[i], pos); /* (checked with the options) */
        if (rtp_tree_add_light(tree, pos, &err) != RTP_OK) {
            fail_err(&err);
            goto out;
        }
    }
    /* the --params files in turn, then the --set edits: a later edit of a
       key wins */
    for (i = 0; i < nparams; i++)
        if (apply_params_file(set_tree, tree, params[i]))
            goto out;
    for (i = 0; i < nsets; i++)
        if (apply_kv(set_tree, tree, sets[i], "--set", 0, 0))
            goto out;
    {
        const char *outs[2], *opts[2];
        outs[0] = stream ? NULL : image_path; /* (a stream's frames: at each line) */
        outs[1] = stats_path;
        opts[0] = image_path == default_image ? "the default image" : "-i";
        opts[1] = "--stats";
        if (overwrites_scene_image("reeval", rtp_tree_scene(tree), opts, outs, 2, 0)) {
            rc = EXIT_USAGE;
            goto out;
        }
    }
    if (stats_path && !(stats = stats_open(stats_path)))
        goto out;
    if (!stream) {
        rc = reeval_one(tree, &eo, &img, image_path, reference, threads, stats, stats_path,
                        tree_path, t_load, 0, ikeep);
        progress_end(&prog);
        if (stats_settle(stats, stats_path, ikeep, NULL, image_path, rc != 0) && rc == 0)
            rc = 1;
        stats = NULL;
        goto out;
    } else {
        char *line = (char *)malloc(MAX_LINE + 1), path[4096];
        int n = 0, got, cr = 0;
        rc = 0;
        frames = 0;
        if (!line) {
            msg("--stream: out of memory");
            rc = 1;
        }
        while (line && (got = next_line(stdin, "<stdin>", line, &n, &cr)) != 0) {
            if (got < 0 || apply_line(set_tree, tree, line, "<stdin>", n)) {
                rc = 1;
                break;
            }
            if (strcmp(image_path, "-") == 0 || stream_device(image_path)) {
                snprintf(path, sizeof path, "%s", image_path);
            } else if (expand_pattern(image_path, n - 1, path, sizeof path) != 0) {
                msg("--stream: image name too long");
                rc = 1;
                break;
            }
            /* (a single reeval refuses these before it begins; a stream's
               names come a line at a time: frame 3 of t%d.png is a tree
               t3.png, read once at the start, which the image replaced) */
            if (is_input(tree_path, path)) {
                msg("<stdin>:%d: --stream: the image %s is the tree %s: writing it would "
                    "replace it; name the frames another way",
                    n, path, tree_path);
                rc = 1;
                break;
            }
            {
                /* (a --params file, read before the first line, is an
                   input as the tree is: a frame of its name replaced it) */
                int k, hit = -1;
                for (k = 0; k < nparams && hit < 0; k++)
                    if (is_input(params[k], path))
                        hit = k;
                if (hit >= 0) {
                    msg("<stdin>:%d: --stream: the image %s is the --params file %s: writing it "
                        "would replace it; name the frames another way",
                        n, path, params[hit]);
                    rc = 1;
                    break;
                }
            }
            if (one_output(path, stats_path)) {
                msg("<stdin>:%d: --stream: the image %s is the --stats file %s: give each "
                    "output its own",
                    n, path, stats_path);
                rc = 1;
                break;
            }
            {
                /* (a texture or bump image a line named, or the scene's) */
                const char *fr = path, *fo = NULL;
                if (overwrites_scene_image("--stream", rtp_tree_scene(tree), &fo, &fr, 1, n)) {
                    rc = 1;
                    break;
                }
            }
            if (reeval_one(tree, &eo, &img, path, reference, threads, stats, stats_path,
                           tree_path,
                           t_load, n, NULL)) {
                rc = 1;
                break;
            }
            frames++;
            fflush(stdout);
        }
        free(line);
    }
    /* A stream stopped by a bad line keeps the images written before it,
       and so the statistics of those images: a line each.  Its frames are
       written as they go (a UI shows each as it comes), so a stats file
       that fails at its end, its rename, leaves them written, not put
       back as a single reeval's image is (stats_settle): said, as the
       message alone read as if nothing had been made */
    if (stats) {
        if (rc != 0 && (!frames || ferror(stats))) {
            stats_discard(stats);
        } else if (stats_close(stats, stats_path)) {
            if (frames)
                msg("%s: the stream's %d %s written; their statistics are not", stats_path,
                    frames, frames == 1 ? "image stays" : "images stay");
            rc = 1;
        }
    }
    stats = NULL;
out:
    stats_discard(stats);
    rtp_image_destroy(img);
    rtp_tree_destroy(tree);
    free(default_image);
    free(sets);
    free(add_lights);
    return rc;
usage:
    usage_hint(reeval_help);
    free(default_image);
    free(sets);
    free(add_lights);
    return EXIT_USAGE;
}

/* ----------------------------------------------------------------- info */

/* Prints "KEY=VALUE" for each of fields under prefix ("" or "light.0."),
   on one line after head. */
/* s with each control byte (below 0x20, and DEL) as '?', for the
   terminal: a tree file's names and texture paths may hold any byte but
   NUL (an MTL's newmtl takes ESC), and `rtp info` of a file from anywhere
   must not send escape sequences or forge lines of its own. */
static char *printable(char *s)
{
    char *p;
    for (p = s; *p; p++)
        if ((unsigned char)*p < 0x20 || *p == 0x7f)
            *p = '?';
    return s;
}

static void print_fields(const rtp_scene *s, const char *head, const char *prefix,
                         const char *const *fields, size_t n)
{
    char key[96], val[4096];
    size_t i;
    fputs(head, stdout);
    for (i = 0; i < n; i++) {
        snprintf(key, sizeof key, "%s%s", prefix, fields[i]);
        if (rtp_scene_get(s, key, val, sizeof val, NULL) == RTP_OK)
            printf(" %s=%s", fields[i], printable(val));
    }
    putchar('\n');
}

/* Item i of kind ("light", "mat"): its keys' prefix ("mat.2.") and the
   head of its line ("mat.2 (glass):", or "mat.2:" unnamed). */
static void item_head(const rtp_scene *s, const char *kind, size_t i, char *prefix,
                      size_t psize, char *head, size_t hsize)
{
    char key[96], name[300];
    snprintf(prefix, psize, "%s.%zu.", kind, i);
    snprintf(key, sizeof key, "%sname", prefix);
    if (rtp_scene_get(s, key, name, sizeof name, NULL) == RTP_OK && name[0])
        snprintf(head, hsize, "%s.%zu (%.255s):", kind, i, printable(name));
    else
        snprintf(head, hsize, "%s.%zu:", kind, i);
}

/* The keys --set takes and their values now: the camera, the environment,
   each light and material (by index and name; texture and bump fields
   where a material uses them). */
static void print_keys(const rtp_scene *s, const rtp_tree_info *ti)
{
    static const char *const camera[] = {"from", "at", "up", "angle", "hither"};
    static const char *const env[] = {"ambient", "background"};
    /* (intensity, a key of its own since session 41, is the colour's
       largest component: shown beside the colour it is read from) */
    static const char *const light[] = {"pos", "color", "intensity", "on"};
    static const char *const mat[] = {"color", "kd", "ks", "kt", "shine", "ior"};
    static const char *const ambient[] = {"ambient"};
    static const char *const checker[] = {"checker", "color2", "checker_scale"};
    static const char *const texture[] = {"texture"};
    static const char *const bump[] = {"bump", "bump_strength", "bump_scale"};
    char prefix[64], head[400], val[4096];
    size_t i;
    print_fields(s, "camera:", "camera.", camera, 5);
    print_fields(s, "environment:", "", env, 2);
    for (i = 0; i < ti->lights; i++) {
        item_head(s, "light", i, prefix, sizeof prefix, head, sizeof head);
        print_fields(s, head, prefix, light, 4);
    }
    for (i = 0; i < ti->materials; i++) {
        char line[96];
        item_head(s, "mat", i, prefix, sizeof prefix, head, sizeof head);
        print_fields(s, head, prefix, mat, 6);
        /* (the ambient coefficient where the material has one of its
           own, on the line after the material's own: one set equal to
           kd too, which kd's edits leave where one that follows kd moves
           with them, so that the keys shown set the scene as it is) */
        snprintf(line, sizeof line, "%sambient_own", prefix);
        if (rtp_scene_get(s, line, val, sizeof val, NULL) == RTP_OK && strcmp(val, "1") == 0)
            print_fields(s, "   ", prefix, ambient, 1);
        /* (texture and bump fields where the material uses them, on the
           lines after its own) */
        snprintf(line, sizeof line, "%schecker", prefix);
        if (rtp_scene_get(s, line, val, sizeof val, NULL) == RTP_OK && strcmp(val, "1") == 0)
            print_fields(s, "   ", prefix, checker, 3);
        snprintf(line, sizeof line, "%stexture", prefix);
        if (rtp_scene_get(s, line, val, sizeof val, NULL) != RTP_ERR_KEY &&
            strcmp(val, "none") != 0)
            print_fields(s, "   ", prefix, texture, 1);
        snprintf(line, sizeof line, "%sbump", prefix);
        if (rtp_scene_get(s, line, val, sizeof val, NULL) != RTP_ERR_KEY &&
            strcmp(val, "none") != 0)
            print_fields(s, "   ", prefix, bump, 3);
    }
}

static const char info_help[] =
    "usage: rtp info TREE [options]\n"
    "Prints what a tree file ('-' = stdin) holds: image and sample sizes,\n"
    "nodes, bytes per node, file size, and the keys --set takes with their\n"
    "values now: the camera, ambient and background, each light and material\n"
    "by index and name (texture and bump fields where a material has them, its\n"
    "ambient coefficient where it has one of its own rather than follow kd).\n"
    "  --stats FILE         write the sizes as one JSON object ('-' = stdout)\n"
    "  -q, --quiet          print nothing (--stats still writes)\n"
    "  -v, --verbose        accepted (info has nothing more to say)\n"
    "  -h, --help           this help\n";

static int cmd_info(int argc, char **argv)
{
    const char *tree_path = NULL, *stats_path = NULL;
    rtp_tree *tree = NULL;
    rtp_tree_info ti;
    rtp_error err;
    long long fb;
    int i, c, names_only = 0;
    memset(&err, 0, sizeof err);
    for (i = 0; i < argc; i++) {
        int kind = arg_kind(argv[i], &names_only);
        if (kind == ARG_END)
            continue;
        if (kind == ARG_OPERAND) {
            if (tree_path) {
                msg("info: one tree file at a time");
                return EXIT_USAGE;
            }
            tree_path = argv[i];
        } else if (strcmp(argv[i], "-h") == 0 || strcmp(argv[i], "--help") == 0) {
            fputs(info_help, stdout);
            return 0;
        } else if ((c = common_option(argc, argv, &i, NULL, &stats_path)) != 0) {
            if (c < 0) {
                usage_hint(info_help);
                return EXIT_USAGE;
            }
        } else {
            msg("info: unknown option '%s'", argv[i]);
            usage_hint(info_help);
            return EXIT_USAGE;
        }
    }
    if (!tree_path) {
        msg("info: no tree file given");
        usage_hint(info_help);
        return EXIT_USAGE;
    }
    if (overwrites_input("info", "the tree", tree_path, "--stats", stats_path))
        return EXIT_USAGE; /* (one line: the options are well formed) */
    if (stdin_closed_for("info", tree_path, "the tree")) {
        usage_hint(info_help);
        return EXIT_USAGE;
    }
    if (!output_ok(stats_path))
        return 1;
    /* (every check rtp_tree_read makes, in the memory of a band of trees:
       a summary needs none of them kept) */
    if (rtp_tree_read_summary(tree_path, NULL, &tree, &err) != RTP_OK)
        return fail_err(&err);
    rtp_tree_get_info(tree, &ti);
    fb = file_size(tree_path);
    if ((!stats_path || strcmp(stats_path, "-") != 0) && verbosity > 0) {
        unsigned long long px = (unsigned long long)ti.width * ti.height;
        printf("%s: %dx%d image%s, %llu %s, depth %d", tree_path, ti.width, ti.height,
               ti.spd ? " (SPD: corner samples)" : "", ti.samples,
               noun(ti.samples, "sample", "samples"), ti.max_depth);
        if (ti.min_weight > 0.0)
            printf(", min weight %.9g", ti.min_weight);
        printf("\n");
        printf("nodes %llu (%.3f per sample), %u bytes per node, trees %llu bytes\n", ti.nodes,
               ti.samples ? (double)ti.nodes / (double)ti.samples : 0.0, ti.bytes_per_node,
               ti.tree_bytes);
        if (fb >= 0)
            printf("file %lld bytes = %.2f x the raw 8-bit RGB image (%llu bytes)\n", fb,
                   px ? (double)fb / (3.0 * (double)px) : 0.0, 3 * px);
        printf("scene: %zu %s, %zu %s, %zu %s; %zu %s, %zu %s\n", ti.triangles,
               noun(ti.triangles, "triangle", "triangles"), ti.spheres,
               noun(ti.spheres, "sphere", "spheres"), ti.cones, noun(ti.cones, "cone", "cones"),
               ti.materials, noun(ti.materials, "material", "materials"), ti.lights,
               noun(ti.lights, "light", "lights"));
        if (ti.width != ti.full_width || ti.height != ti.full_height)
            printf("region: pixels %d,%d to %d,%d of a %dx%d frame\n", ti.region_x,
                   ti.region_y, ti.region_x + ti.width, ti.region_y + ti.height,
                   ti.full_width, ti.full_height);
        print_keys(rtp_tree_scene(tree), &ti);
    }
    if (stats_path) {
        FILE *f = stats_open(stats_path);
        char mw[32];
        if (!f) {
            rtp_tree_destroy(tree);
            return 1;
        }
        fprintf(f,
                "{\"command\": \"info\", \"width\": %d, \"height\": %d, \"spd\": %s, "
                "\"pixels\": %llu, \"samples\": %llu, \"nodes\": %llu, \"bytes_per_node\": %u, "
                "\"tree_bytes\": %llu, \"lights\": %zu, \"materials\": %zu, \"depth\": %d, "
                "\"full_width\": %d, \"full_height\": %d, \"region_x\": %d, \"region_y\": %d, "
                "\"min_weight\": %s",
                ti.width, ti.height, ti.spd ? "true" : "false",
                (unsigned long long)ti.width * ti.height, ti.samples, ti.nodes,
                ti.bytes_per_node, ti.tree_bytes, ti.lights, ti.materials, ti.max_depth,
                ti.full_width, ti.full_height, ti.region_x, ti.region_y,
                shortest(mw, sizeof mw, ti.min_weight));
        /* (a pipe has no size: left out, as reeval leaves it out) */
        if (fb >= 0)
            fprintf(f, ", \"file_bytes\": %lld", fb);
        fputs("}\n", f);
        if (stats_close(f, stats_path)) {
            rtp_tree_destroy(tree);
            return 1;
        }
    }
    rtp_tree_destroy(tree);
    return 0;
}


/* ---------------------------------------------------------------- merge */

static const char merge_help[] =
    "usage: rtp merge -o TREE [-i IMAGE] [-j N] REGION.rtp...\n"
    "       rtp merge -i IMAGE --size WxH REGION-IMAGE@X,Y...\n"
    "Joins what `rtp trace --region` made on several machines into the whole\n"
    "frame: region trees into the frame's tree (and, with -i, its image,\n"
    "identical to a whole-frame trace), or region images placed at X,Y.\n"
    "  -o, --output TREE    the joined tree file ('-' = stdout)\n"
    "  -i, --image FILE     the joined image (.png .ppm .pfm; '-' = PFM on stdout)\n"
    "  --size WxH           the frame's size (image mode)\n"
    "  -j, --threads N      threads for evaluating the joined tree, 1 to 256\n"
    "                       (default: the processors online)\n"
    "  -q, --quiet          no messages but errors\n"
    "  -v, --verbose        accepted (merge has nothing more to say)\n"
    "  -h, --help           this help\n"
    "Regions must cover the frame without overlapping.\n";

/* The library names a part by its index, "parts[K]": here it is the
   K-th file given, named ("tree 1" had meant the second), and the message
   said here whole: written back into err->message (256 bytes), two long
   paths cut it before its reason (a TMPDIR of 100 characters lost "p1.rtp
   to depth 5"). */
static int fail_parts(const rtp_error *err, const char *const *in, int n)
{
    const char *p = err->message, *e = p + sizeof err->message;
    if (err->file[0] || err->line > 0)
        return fail_err(err); /* (no part named: merge's own are whole) */
    fputs("rtp: ", stderr);
    while (p < e && *p) {
        char *end;
        long k;
        if (strncmp(p, "parts[", 6) == 0 && (k = strtol(p + 6, &end, 10), *end == ']') &&
            end > p + 6 && k >= 0 && k < n) {
            fputs(in[k], stderr);
            p = end + 1;
        } else {
            fputc(*p++, stderr);
        }
    }
    fputc('\n', stderr);
    return 1;
}

/* A part's "X,Y" (after its '@') into *x, *y; returns 0 or -1.  sscanf's
   %d overflowed past INT_MAX, undefined behaviour: glibc took
   "4294967326,20" as 30,20 and placed the part there.  Negative offsets
   parse, so that merge says the part does not fit the frame. */
static int parse_offset(const char *s, int *x, int *y)
{
    char buf[32];
    const char *comma = strchr(s, ',');
    size_t n = comma ? (size_t)(comma - s) : 0;
    if (!comma || n == 0 || n >= sizeof buf)
        return -1;
    memcpy(buf, s, n);
    buf[n] = '\0';
    if (parse_int(buf, INT_MIN, INT_MAX, x) || parse_int(comma + 1, INT_MIN, INT_MAX, y))
        return -1;
    return 0;
}

static int cmd_merge(int argc, char **argv)
{
    const char *out_tree = NULL, *out_image = NULL;
    int i, n = 0, rc = 1, fw = 0, fh = 0, threads = default_threads(), images = 0, c,
        names_only = 0;
    const char **in = (const char **)calloc((size_t)argc + 1, sizeof *in);
    rtp_tree **parts = NULL, *joined = NULL;
    rtp_image *img = NULL;
    unsigned char *covered = NULL;
    rtp_error err;
    memset(&err, 0, sizeof err);
    if (!in) {
        msg("out of memory");
        return 1;
    }
    for (i = 0; i < argc; i++) {
        const char *a = argv[i];
        int kind = arg_kind(a, &names_only);
        if (kind == ARG_END)
            continue;
        if (kind == ARG_OPERAND || a[1] == '@') {
            /* ("-@X,Y" is an image part on stdin) */
            in[n++] = a;
            if (strchr(a, '@'))
                images = 1;
        } else if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            fputs(merge_help, stdout);
            free(in);
            return 0;
        } else if ((c = common_option(argc, argv, &i, &threads, NULL)) != 0) {
            if (c < 0)
                goto usage;
        } else if (strcmp(a, "-o") == 0 || is_opt(a, "--output")) {
            if (!(out_tree = opt_value(argc, argv, &i, a[1] == 'o' ? "-o" : "--output")))
                goto usage;
        } else if (strcmp(a, "-i") == 0 || is_opt(a, "--image")) {
            if (!(out_image = opt_value(argc, argv, &i, a[1] == 'i' ? "-i" : "--image")))
                goto usage;
        } else if (is_opt(a, "--size")) {
            if (parse_size(opt_value(argc, argv, &i, "--size"), &fw, &fh))
                goto usage;
        } else {
            msg("merge: unknown option '%s'", a);
            goto usage;
        }
    }
    if (!n || (!out_tree && !out_image) || (images && (!out_image || !fw || out_tree))) {
        msg("merge: give region trees and -o (and/or -i), or region images with @X,Y, "
            "--size and -i");
        goto usage;
    }
    if (!images && fw) {
        /* (it was taken and ignored: the frame is the one the trees were
           traced in, whatever --size said) */
        msg("merge: --size is for region images (IMAGE@X,Y): region trees know their frame");
        goto usage;
    }
    if (out_tree && out_image && is_stdout(out_tree) && is_stdout(out_image)) {
        msg("merge: the tree and the image cannot both go to stdout");
        goto usage;
    }
    if (stdout_taken("merge", NULL, out_tree, out_image))
        goto usage;
    for (i = 0; images && i < n; i++) {
        const char *at = strrchr(in[i], '@');
        int x0, y0;
        if (!at || at == in[i] || parse_offset(at + 1, &x0, &y0)) {
            msg("merge: %s: expected IMAGE@X,Y", in[i]);
            goto usage;
        }
    }
    for (i = 0, c = 0; i < n; i++) {
        /* a part named as an output: written, the merge replaced it */
        char path[4096];
        const char *at = images ? strrchr(in[i], '@') : NULL;
        size_t pl = at ? (size_t)(at - in[i]) : strlen(in[i]);
        if (pl >= sizeof path)
            continue; /* (no such file: its read fails) */
        memcpy(path, in[i], pl);
        path[pl] = '\0';
        if (overwrites_input("merge", "a part", path, "-o", out_tree) ||
            overwrites_input("merge", "a part", path, "-i", out_image)) {
            rc = EXIT_USAGE;
            goto out;
        }
        /* stdin holds one input: a second '-' (or /dev/stdin, another
           name of the pipe) read it empty ("-: empty: not an rtp tree
           file") */
        c += reads_stdin(path);
        if (stdin_closed_for("merge", path, "a part"))
            goto usage;
    }
    if (c > 1) {
        msg("merge: only one part can come from stdin (-, or another name of it)");
        goto usage;
    }
    if (same_output("merge", "the tree", out_tree, "the image", out_image)) {
        rc = EXIT_USAGE;
        goto out;
    }
    if ((out_image && !image_name_ok(out_image)) || !output_ok(out_image) ||
        !output_ok(out_tree))
        goto out;
    if (images) {
        int x0, y0, x, y;
        if (rtp_image_create(fw, fh, NULL, &img, &err) != RTP_OK) {
            fail_err(&err);
            goto out;
        }
        /* what the regions have covered so far (a region's own pixels may
           be anything, NaN too) */
        covered = (unsigned char *)calloc((size_t)fw * (size_t)fh, 1);
        if (!covered) {
            msg("out of memory");
            goto out;
        }
        for (i = 0; i < n; i++) {
            char path[4096];
            const char *at = strrchr(in[i], '@');
            rtp_image *part = NULL;
            size_t pl;
            if (!at || (pl = (size_t)(at - in[i])) >= sizeof path ||
                parse_offset(at + 1, &x0, &y0)) {
                msg("merge: %s: expected IMAGE@X,Y", in[i]);
                goto out;
            }
            memcpy(path, in[i], pl);
            path[pl] = '\0';
            if (rtp_image_read(path, NULL, &part, &err) != RTP_OK) {
                fail_err(&err);
                goto out;
            }
            if (x0 < 0 || y0 < 0 || part->width > fw - x0 || part->height > fh - y0) {
                msg("merge: %s (%dx%d at %d,%d) does not fit the %dx%d frame", in_name(path),
                    part->width, part->height, x0, y0, fw, fh);
                rtp_image_destroy(part);
                goto out;
            }
            for (y = 0; y < part->height; y++)
                for (x = 0; x < part->width; x++) {
                    size_t k = (size_t)(y0 + y) * (size_t)fw + (size_t)(x0 + x);
                    float *d = img->pixels + 3 * k;
                    const float *sp = part->pixels + 3 * ((size_t)y * part->width + x);
                    if (covered[k]) {
                        msg("merge: %s overlaps another region at %d,%d", in_name(path), x0 + x,
                            y0 + y);
                        rtp_image_destroy(part);
                        goto out;
                    }
                    covered[k] = 1;
                    d[0] = sp[0];
                    d[1] = sp[1];
                    d[2] = sp[2];
                }
            rtp_image_destroy(part);
        }
        for (i = 0; i < fw * fh; i++)
            if (!covered[i]) {
                msg("merge: pixel %d,%d is in no region", i % fw, i / fw);
                goto out;
            }
    } else {
        rtp_eval_options eo;
        parts = (rtp_tree **)calloc((size_t)n, sizeof *parts);
        if (!parts) {
            msg("out of memory");
            goto out;
        }
        for (i = 0; i < n; i++)
            if (rtp_tree_read(in[i], NULL, &parts[i], &err) != RTP_OK) {
                fail_err(&err);
                goto out;
            }
        if (rtp_tree_merge(parts, (size_t)n, &joined, &err) != RTP_OK) {
            fail_parts(&err, in, n);
            goto out;
        }
        memset(&eo, 0, sizeof eo);
        eo.threads = threads;
        eo.no_cache = 1;
        /* (the image made before either is written: the pair is written
           as one) */
        if (out_image && rtp_tree_eval(joined, &eo, &img, NULL, &err) != RTP_OK) {
            fail_err(&err);
            goto out;
        }
    }
    if (write_pair(joined, out_tree, NULL, img, out_image, NULL))
        goto out;
    rc = 0;
out:
    if (parts)
        for (i = 0; i < n; i++)
            rtp_tree_destroy(parts[i]);
    free(parts);
    rtp_tree_destroy(joined);
    rtp_image_destroy(img);
    free(covered);
    free(in);
    return rc;
usage:
    usage_hint(merge_help);
    free(in);
    return EXIT_USAGE;
}

/* ----------------------------------------------------------------- main */

static const char main_help[] =
    "usage: rtp COMMAND [options]   (rtp help COMMAND for each)\n"
    "Parameterized ray tracing with geometric parameters.\n"
    "  trace SCENE   trace a scene (NFF or OBJ); write the image and ray trees\n"
    "  reeval TREE   re-evaluate ray trees with edited parameters, no tracing\n"
    "  info TREE     what a tree file holds\n"
    "  merge ...     join region trees or images into the whole frame\n"
    "  diff A B      compare two images: MAE, RMSE, PSNR, max error, heat map\n"
    "  version       print the version\n"
    "Exit status: 0 ok, 1 failure, 2 usage error, 3 diff over --fail-above.\n";

/* What went to stdout (info's summary, diff's numbers, version, help) must
   have arrived: a full disk or a closed stdout is a failure, said so. */
static int stdout_done(int rc)
{
    /* (diff over its limit too: its line lost is a failure, as a lost
       --stats or --heatmap is; `diff --fail-above ... >/dev/full` was
       exit 3 with nothing said) */
    if ((fflush(stdout) != 0 || ferror(stdout)) && (rc == 0 || rc == EXIT_OVER)) {
        msg("stdout: write failed: %s", strerror(errno));
        rc = 1;
    }
    return rc;
}

/* A standard stream closed by the caller (>&-) is held open on the root
   folder, read-only, so that a file rtp opens never gets its number
   (with stdout closed the stats file's temporary took fd 1, and `reeval
   -i - --stats s.json >&-` wrote the image into s.json, exit 0), while
   using the stream still fails (writing: EBADF; reading: EISDIR) and so
   does any name that reaches it (/proc/self/fd/1 through a link: a
   folder, which cannot be written; /dev/null there had taken the image
   silently). */
static void hold_std_fds(void)
{
    int fd;
    for (fd = 0; fd <= 2; fd++)
        if (fcntl(fd, F_GETFD) == -1 && errno == EBADF) {
            int got = open("/", O_RDONLY);
            std_closed[fd] = 1;
            if (got >= 0 && got != fd)
                close(got); /* (a lower one was closed too: it took it) */
        }
}

int main(int argc, char **argv)
{
    int rc;
    hold_std_fds();
    if (argc < 2) {
        fputs(main_help, stderr);
        return EXIT_USAGE;
    }
    if (strcmp(argv[1], "help") == 0 && argc > 2) {
        /* rtp help COMMAND: that command's --help, as git and go say it
           (it printed the list of commands) */
        static char help_opt[] = "--help";
        if (argc > 3) {
            msg("help: unexpected argument '%s'", argv[3]);
            fputs("usage: rtp help [COMMAND]\n", stderr);
            return EXIT_USAGE;
        }
        argv[1] = argv[2];
        argv[2] = help_opt;
        argc = 3;
    }
    if (strcmp(argv[1], "-h") == 0 || strcmp(argv[1], "--help") == 0 ||
        strcmp(argv[1], "help") == 0) {
        fputs(main_help, stdout);
        return stdout_done(0);
    }
    if (strcmp(argv[1], "version") == 0 || strcmp(argv[1], "--version") == 0) {
        unsigned f = rtp_features();
        int k;
        /* --help anywhere, as every command takes it ('rtp version -v
           --help' was a usage error) */
        for (k = 2; k < argc; k++)
            if (strcmp(argv[k], "-h") == 0 || strcmp(argv[k], "--help") == 0) {
                fputs("usage: rtp version [-q] [-v]\nPrints the versions of rtp and of its "
                      "library, and what this build has\n(png, threads, osmesa).\n",
                      stdout);
                return stdout_done(0);
            }
        {
            /* -q and -v as every command takes them (it prints what it
               always prints) */
            for (k = 2; k < argc; k++)
                if (strcmp(argv[k], "-q") && strcmp(argv[k], "--quiet") &&
                    strcmp(argv[k], "-v") && strcmp(argv[k], "--verbose")) {
                    msg("version: unexpected argument '%s'", argv[k]);
                    fputs("usage: rtp version [-q] [-v]\n", stderr);
                    return EXIT_USAGE;
                }
        }
        printf("rtp %s (library %s)\n", RTP_VERSION_NUMBER == rtp_version_number()
                                            ? rtp_version_string()
                                            : "mismatch",
               rtp_version_string());
        printf("built with:%s%s%s\n", f & RTP_FEATURE_PNG ? " png" : " (no png)",
               f & RTP_FEATURE_THREADS ? " threads" : " (no threads)",
               f & RTP_FEATURE_OSMESA ? " osmesa" : " (no osmesa)");
        return stdout_done(0);
    }
    install_signals();
    if (strcmp(argv[1], "trace") == 0)
        rc = cmd_trace(argc - 2, argv + 2);
    else if (strcmp(argv[1], "diff") == 0)
        rc = cmd_diff(argc - 2, argv + 2);
    else if (strcmp(argv[1], "reeval") == 0)
        rc = cmd_reeval(argc - 2, argv + 2);
    else if (strcmp(argv[1], "info") == 0)
        rc = cmd_info(argc - 2, argv + 2);
    else if (strcmp(argv[1], "merge") == 0)
        rc = cmd_merge(argc - 2, argv + 2);
    else {
        msg("unknown command '%s'", argv[1]);
        fputs(main_help, stderr);
        return EXIT_USAGE;
    }
    return stdout_done(rc);
}
