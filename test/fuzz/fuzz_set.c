/* fuzz_set.c — fuzzes parameter edits as a --params file holds them:
 * KEY=VALUE items separated by blanks, one or more per line, '#' comments
 * (cli/rtp.c's apply_line).  Each item goes to rtp_tree_set on the trees
 * of a small recorded scene and, when the tree takes it, to rtp_scene_set
 * on the scene, which must take it too.  After each line the trees are
 * evaluated into one kept image (as --stream does, so later lines take
 * the cached paths) and compared with an uncached evaluation of a twin
 * tree given the same edits; at the end the kept image and a fresh
 * evaluation are compared with a full trace of the edited scene: the
 * brief promises the images agree for every edit the tree accepts. */
#include "fuzz_common.h"

static const char scene_text[] =
    "b 0.1 0.2 0.3\n"
    "v from 0 -6 2 at 0 0 0.5 up 0 0 1 angle 40 hither 0.01 resolution 4 4\n"
    "ambient 0.05 0.05 0.05\n"
    "l 3 -4 6 0.8 0.7 0.6\nname lamp\n"
    "l -3 -4 5\n"
    "l 0 3 5\nname spare\noff\n"
    "f 0.9 0.9 0.9 0.8 0.2 20 0 0\nname floor\nchecker 0.1 0.1 0.1 0.5\n"
    "p 4 -4 -4 0 4 -4 0 4 4 0 -4 4 0\n"
    "f 0.8 0.3 0.3 0.5 0.4 40 0.4 1.5\nname glass\n"
    "s 0 0 1 0.8\n"
    "f 0.3 0.8 0.3 0.9 0 100000 0 0\n"
    "c 1.5 0 0 0.3 1.5 0 1.5 0.1\n"
    "pp 3 -2 0 0 0 0 1 -1 0 1 0 0 1 -2 0 2 0 0 1\n";

#define W 4
#define H 4

/* One item to the trees, their uncached twin and the scene. */
static void apply(rtp_tree *t, rtp_tree *twin, rtp_scene *s, char *item)
{
    char *eq = strchr(item, '=');
    rtp_error err;
    rtp_status st, st2;
    if (!eq || eq == item)
        return;
    *eq = '\0';
    memset(&err, 0, sizeof err);
    st = rtp_tree_set(t, item, eq + 1, &err);
    fuzz_check_error(&err, st);
    st2 = rtp_tree_set(twin, item, eq + 1, &err);
    FUZZ_ASSERT(st2 == st);
    if (st == RTP_OK) {
        char now[8192], tree_now[8192];
        st2 = rtp_scene_set(s, item, eq + 1, &err);
        fuzz_check_error(&err, st2);
        FUZZ_ASSERT(st2 == RTP_OK);
        /* every key set reads back, the same from the tree's scene */
        st2 = rtp_scene_get(s, item, now, sizeof now, &err);
        fuzz_check_error(&err, st2);
        FUZZ_ASSERT(st2 == RTP_OK);
        FUZZ_ASSERT(rtp_scene_get(rtp_tree_scene(t), item, tree_now, sizeof tree_now, NULL) ==
                        RTP_OK &&
                    strcmp(now, tree_now) == 0);
    }
    *eq = '=';
}

/* Aborts unless a and b agree to float rounding (see check_traced). */
static void check_same(const rtp_image *a, const rtp_image *b, const char *what)
{
    rtp_diff_stats d;
    double big = 1.0;
    size_t i, np = 3 * (size_t)b->width * (size_t)b->height;
    if (rtp_image_diff(a, b, 1e-6, &d, NULL) != RTP_OK)
        return;
    for (i = 0; i < np; i++)
        if (fabs(b->pixels[i]) > big)
            big = fabs(b->pixels[i]);
    if (!(d.max_abs <= 1e-4 * big)) {
        fprintf(stderr, "fuzz_set: %s differs by %g\n", what, d.max_abs);
        abort();
    }
}

/* Aborts unless img equals a full trace of s: edits take float
   parameters, so float rounding only is allowed, 1e-4 of the image's
   largest value (a ks of 10 over a few bounces makes values of
   thousands, whose float ulp is 1e-4), at least 1e-4. */
static void check_traced(const rtp_image *img, const rtp_scene *s, const rtp_trace_options *o,
                         const char *what)
{
    rtp_image *full = NULL;
    if (rtp_trace(s, o, &full, NULL, NULL) == RTP_OK)
        check_same(img, full, what);
    rtp_image_destroy(full);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL, *twin = NULL;
    rtp_image *re = NULL, *plain = NULL;
    rtp_trace_options o;
    rtp_eval_options eo, eo_plain;
    rtp_image *kept = NULL;
    rtp_status st;
    rtp_error err;
    char *text, *p, *line;
    /* (mat.N.texture= and mat.N.bump= open the file they name) */
    if (size > 4096 || fuzz_names_special_file(data, size))
        return 0;
    text = (char *)malloc(size + 1);
    if (!text)
        return 0;
    if (size)
        memcpy(text, data, size);
    text[size] = '\0';
    memset(&err, 0, sizeof err);
    memset(&o, 0, sizeof o);
    o.width = W;
    o.height = H;
    o.threads = 1;
    if (rtp_scene_load_memory(scene_text, sizeof scene_text - 1, "set.nff", "nff",
                              &fuzz_alloc, &s, &err) != RTP_OK ||
        rtp_record(s, &o, &t, NULL, NULL, &err) != RTP_OK ||
        rtp_record(s, &o, &twin, NULL, NULL, &err) != RTP_OK) {
        fprintf(stderr, "fuzz_set: setup failed: %s\n", err.message);
        abort();
    }
    /* Bump edits below reflective or transparent surfaces are exact only
       with their stale subtrees traced again (the default keeps them, the
       paper's approximation): ask for that. */
    memset(&eo, 0, sizeof eo);
    eo.stale = RTP_STALE_RETRACE;
    eo.incremental = 1;
    /* the twin evaluates every line from its trees alone, no caches */
    eo_plain = eo;
    eo_plain.incremental = 0;
    eo_plain.no_cache = 1;
    /* Lines as apply_params_file reads them, items as apply_line splits
       them (a NUL ends the text as it ends a C string). */
    for (line = text; line && *line; line = p) {
        char *hash, *q;
        p = strchr(line, '\n');
        if (p)
            *p++ = '\0';
        hash = strchr(line, '#');
        if (hash)
            *hash = '\0';
        q = line;
        for (;;) {
            char *tok;
            while (*q == ' ' || *q == '\t' || *q == '\r')
                q++;
            if (!*q)
                break;
            tok = q;
            while (*q && *q != ' ' && *q != '\t' && *q != '\r')
                q++;
            if (*q)
                *q++ = '\0';
            apply(t, twin, s, tok);
        }
        /* each line evaluated into one kept image, as --stream does: the
           paths later evaluations take (planes, highlight lists, a
           material's samples alone, incremental writes) */
        if (!kept)
            st = rtp_tree_eval(t, &eo, &kept, NULL, &err);
        else
            st = rtp_tree_eval_into(t, &eo, kept, NULL, &err);
        fuzz_check_error(&err, st);
        /* every line's image, not only the last (a cache left wrong by
           one line may be overwritten by the next before it shows),
           against the twin's evaluation without caches: a full trace
           after every line would cost a kd-tree build each */
        if (st == RTP_OK && rtp_tree_eval(twin, &eo_plain, &plain, NULL, &err) == RTP_OK)
            check_same(kept, plain, "the image after a line, against no caches,");
        rtp_image_destroy(plain);
        plain = NULL;
    }
    /* at the end, the kept image and a fresh evaluation against a full
       trace of the edited scene */
    if (kept)
        check_traced(kept, s, &o, "the kept image");
    if (rtp_tree_eval(t, &eo, &re, NULL, &err) == RTP_OK)
        check_traced(re, s, &o, "the re-evaluation");
    rtp_image_destroy(re);
    rtp_image_destroy(kept);
    rtp_tree_destroy(t);
    rtp_tree_destroy(twin);
    rtp_scene_destroy(s);
    free(text);
    return 0;
}
