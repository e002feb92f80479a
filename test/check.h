/* check.h — the tests' tiny harness.  A test program defines functions,
 * runs them with RUN(fn) and ends with return check_report(); each test
 * function passes when none of its CHECKs fail.  SKIP(msg) marks the
 * current test skipped (never counted as passed). */
#ifndef RTP_CHECK_H
#define RTP_CHECK_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <locale.h>

#if defined(__GNUC__)
#define CHECK_UNUSED __attribute__((unused))
#else
#define CHECK_UNUSED
#endif

CHECK_UNUSED static int check_failed_now, check_skipped_now;
CHECK_UNUSED static int check_passed, check_failed, check_skipped;

#define CHECK(cond)                                                         \
    do {                                                                    \
        if (!(cond)) {                                                      \
            fprintf(stderr, "%s:%d: CHECK(%s) failed\n", __FILE__,          \
                    __LINE__, #cond);                                       \
            check_failed_now = 1;                                           \
        }                                                                   \
    } while (0)

#define CHECK_MSG(cond, ...)                                                \
    do {                                                                    \
        if (!(cond)) {                                                      \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__,          \
                    __LINE__, #cond);                                       \
            fprintf(stderr, __VA_ARGS__);                                   \
            fputc('\n', stderr);                                            \
            check_failed_now = 1;                                           \
        }                                                                   \
    } while (0)

#define SKIP(msg)                                                           \
    do {                                                                    \
        fprintf(stderr, "skip: %s: %s\n", __func__, msg);                   \
        check_skipped_now = 1;                                              \
        return;                                                             \
    } while (0)

/* (RTP_TEST_ONLY=NAME runs that test alone, when working on it) */
#define RUN(fn)                                                             \
    do {                                                                    \
        const char *only_ = getenv("RTP_TEST_ONLY");                        \
        if (only_ && *only_ && strcmp(only_, #fn) != 0)                     \
            break;                                                          \
        check_failed_now = 0;                                               \
        check_skipped_now = 0;                                              \
        fn();                                                               \
        if (check_failed_now) {                                             \
            check_failed++;                                                 \
            fprintf(stderr, "FAIL %s\n", #fn);                              \
        } else if (check_skipped_now) {                                     \
            check_skipped++;                                                \
        } else {                                                            \
            check_passed++;                                                 \
        }                                                                   \
    } while (0)

CHECK_UNUSED static int check_report(void)
{
    printf("%d passed, %d failed, %d skipped\n", check_passed, check_failed,
           check_skipped);
    return check_failed ? 1 : 0;
}

/* A folder for the files a test program writes, made under TMPDIR (or
   /tmp) at the first call ("" if none could be made); the program
   removes its files and, at its end, the folder (rmdir check_tmpdir).
   (test_nff and test_obj each had their own copy of these three.) */
CHECK_UNUSED static char check_tmpdir[256];

CHECK_UNUSED static const char *check_tmp_folder(void)
{
    if (!check_tmpdir[0]) {
        const char *t = getenv("TMPDIR");
        snprintf(check_tmpdir, sizeof check_tmpdir, "%s/rtp-test-XXXXXX", t && *t ? t : "/tmp");
        if (!mkdtemp(check_tmpdir))
            check_tmpdir[0] = '\0';
    }
    return check_tmpdir;
}

/* Writes text to dir/name: 0, or -1 where it could not. */
CHECK_UNUSED static int check_write_file(const char *dir, const char *name, const char *text)
{
    char path[512];
    FILE *f;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    f = fopen(path, "wb");
    if (!f)
        return -1;
    fputs(text, f);
    return fclose(f);
}

CHECK_UNUSED static void check_remove_file(const char *dir, const char *name)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    remove(path);
}

/* The seven default SPD scenes (../shared/scenes/spd/NAME.nff) the
   benchmarks measure. */
#define CHECK_SPD_SCENES 7
CHECK_UNUSED static const char *const check_spd_scenes[CHECK_SPD_SCENES] = {
    "balls_s4", "gears_s4", "mount_s6", "rings_s7", "teapot_s12", "tetra_s6", "tree_s11"};

/* Sets LC_NUMERIC to a locale whose decimal point is ',' (a host
   program's, for the tests that numbers read and print with '.'
   whatever it is), the one before into saved; 0 where none is
   installed (.ci/run makes de_DE.UTF-8).  setlocale(LC_NUMERIC, saved)
   puts it back. */
CHECK_UNUSED static inline int check_comma_locale(char *saved, size_t n)
{
    static const char *const names[] = {"de_DE.UTF-8", "de_DE.utf8", "fr_FR.UTF-8",
                                        "fr_FR.utf8", "de_DE", "fr_FR"};
    const char *old = setlocale(LC_NUMERIC, NULL);
    size_t i;
    snprintf(saved, n, "%s", old ? old : "C");
    for (i = 0; i < sizeof names / sizeof *names; i++)
        if (setlocale(LC_NUMERIC, names[i]))
            return 1;
    return 0;
}

/* The folder ../shared/scenes when present, else NULL (tests skip). */
CHECK_UNUSED static inline const char *check_shared_scenes(void)
{
    const char *env = getenv("RTP_SHARED_SCENES");
    static const char *cands[] = {"../shared/scenes", "../../shared/scenes"};
    FILE *f;
    size_t i;
    char buf[512];
    if (env && *env)
        return env;
    for (i = 0; i < sizeof cands / sizeof *cands; i++) {
        snprintf(buf, sizeof buf, "%s/README.md", cands[i]);
        f = fopen(buf, "r");
        if (f) {
            fclose(f);
            return cands[i];
        }
    }
    return NULL;
}
#endif
