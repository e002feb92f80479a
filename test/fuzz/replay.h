/* replay.h — the plain main every fuzz target gets when it is not built
 * with libFuzzer (-DRTP_LIBFUZZER): it runs LLVMFuzzerTestOneInput on each
 * file named on the command line, and on every file inside each named
 * directory, so the checked-in corpora replay under any compiler and
 * sanitizer.  Exit status: 0 when every input ran, 1 when one could not be
 * read, 2 on usage.  A crash or sanitizer report is the failure it is
 * there to catch. */
#ifndef RTP_FUZZ_REPLAY_H
#define RTP_FUZZ_REPLAY_H

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#ifndef RTP_LIBFUZZER
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static int replay_file(const char *path, int verbose)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data = NULL;
    size_t size = 0, cap = 0, n;
    if (!f) {
        fprintf(stderr, "%s: cannot open\n", path);
        return 1;
    }
    for (;;) {
        if (size == cap) {
            unsigned char *p;
            cap = cap ? 2 * cap : 4096;
            p = (unsigned char *)realloc(data, cap);
            if (!p) {
                fclose(f);
                free(data);
                fprintf(stderr, "%s: out of memory\n", path);
                return 1;
            }
            data = p;
        }
        n = fread(data + size, 1, cap - size, f);
        size += n;
        if (n == 0)
            break;
    }
    if (ferror(f)) {
        fclose(f);
        free(data);
        fprintf(stderr, "%s: read error\n", path);
        return 1;
    }
    fclose(f);
    if (verbose)
        fprintf(stderr, "replay %s (%zu bytes)\n", path, size);
    /* An exact-size copy, so ASan sees reads past the end of the input. */
    {
        unsigned char *exact = (unsigned char *)malloc(size ? size : 1);
        if (!exact) {
            free(data);
            return 1;
        }
        if (size)
            memcpy(exact, data, size);
        free(data);
        LLVMFuzzerTestOneInput(exact, size);
        free(exact);
    }
    return 0;
}

static int cmp_names(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every regular file directly inside dir, in name order. */
static int replay_dir(const char *dir, int verbose, int *count)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    char **names = NULL;
    size_t n = 0, cap = 0, i;
    int rc = 0;
    if (!d) {
        fprintf(stderr, "%s: cannot open directory\n", dir);
        return 1;
    }
    while ((e = readdir(d)) != NULL) {
        if (e->d_name[0] == '.')
            continue;
        if (n == cap) {
            char **p;
            cap = cap ? 2 * cap : 64;
            p = (char **)realloc(names, cap * sizeof *names);
            if (!p) {
                rc = 1;
                break;
            }
            names = p;
        }
        names[n] = (char *)malloc(strlen(dir) + strlen(e->d_name) + 2);
        if (!names[n]) {
            rc = 1;
            break;
        }
        sprintf(names[n], "%s/%s", dir, e->d_name);
        n++;
    }
    closedir(d);
    if (n)
        qsort(names, n, sizeof *names, cmp_names);
    for (i = 0; i < n; i++) {
        struct stat st;
        if (stat(names[i], &st) == 0 && S_ISREG(st.st_mode)) {
            rc |= replay_file(names[i], verbose);
            ++*count;
        }
        free(names[i]);
    }
    free(names);
    return rc;
}

int main(int argc, char **argv)
{
    int i, rc = 0, count = 0, verbose = 0;
    if (argc < 2) {
        fprintf(stderr, "usage: %s [-v] FILE|DIR...\n"
                        "Runs the fuzz target once on every input.\n", argv[0]);
        return 2;
    }
    for (i = 1; i < argc; i++) {
        struct stat st;
        if (strcmp(argv[i], "-v") == 0) {
            verbose = 1;
            continue;
        }
        if (stat(argv[i], &st) == 0 && S_ISDIR(st.st_mode)) {
            rc |= replay_dir(argv[i], verbose, &count);
        } else {
            rc |= replay_file(argv[i], verbose);
            count++;
        }
    }
    printf("%d inputs replayed\n", count);
    return rc;
}
#endif /* RTP_LIBFUZZER */
#endif
