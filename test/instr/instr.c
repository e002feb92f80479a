/* instr.c — instructions of each edit class, under callgrind (make instr).
 *
 * Wall-clock figures on a shared machine move by 20% and more between runs,
 * more than most changes to an edit's code; the instructions an edit
 * executes do not.  This program loads a tree, makes the edits
 * bench_reeval times, in its order, and around each measured evaluation
 * switches callgrind's instrumentation and collection on and dumps the
 * count under the edit's name (CALLGRIND_DUMP_STATS_AT): test/instr/run.sh
 * reads the dumps back.  Run natively it only evaluates.
 *
 *   instr TREE MAT [trace]   MAT: the material whose kd is edited; with
 *                            `trace`, first a full trace of the scene
 *                            (rtp_tree_trace, kd-tree build included): the
 *                            denominator of bench_reeval's speed-ups
 */
#include "rtp.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <valgrind/callgrind.h>

static int fail(const char *what, const rtp_error *err)
{
    fprintf(stderr, "instr: %s: %s\n", what, err->message);
    return 1;
}

/* key=value then one evaluation; measured under `label` when not NULL */
static int step(rtp_tree *t, rtp_image *img, const rtp_eval_options *eo, const char *key,
                const char *value, const char *label)
{
    rtp_error err;
    if (key && rtp_tree_set(t, key, value, &err) != RTP_OK)
        return fail(key, &err);
    if (label) {
        CALLGRIND_START_INSTRUMENTATION;
        CALLGRIND_TOGGLE_COLLECT;
    }
    if (rtp_tree_eval_into(t, eo, img, NULL, &err) != RTP_OK)
        return fail(label ? label : "evaluation", &err);
    if (label) {
        CALLGRIND_TOGGLE_COLLECT;
        CALLGRIND_DUMP_STATS_AT(label);
        CALLGRIND_STOP_INSTRUMENTATION;
    }
    return 0;
}

int main(int argc, char **argv)
{
    static const char *const lc[] = {"1,0.6,0.4", "0.4,0.6,1"};
    static const char *const kd[] = {"0.3", "0.6"};
    static const char *const am[] = {"0.2", "0.05"};
    static const char *const mv[] = {"2,3,9", "-3,2,8"};
    static const struct {
        rtp_shadow_mode mode;
        const char *label;
    } moves[] = {{RTP_SHADOWS_EXACT, "move_exact"},
                 {RTP_SHADOWS_LIGHTBUF, "move_lightbuf256"},
                 {RTP_SHADOWS_ITEMBUF, "move_itembuf256"},
                 {RTP_SHADOWS_AUTO, "move_auto"}};
    rtp_tree *t = NULL;
    rtp_image *img = NULL;
    rtp_eval_options eo;
    rtp_tree_info ti;
    rtp_error err;
    char mkd[32];
    int i, rc = 1;
    size_t m;
    if (argc != 3 && !(argc == 4 && strcmp(argv[3], "trace") == 0)) {
        fprintf(stderr, "usage: instr TREE MAT [trace]\n");
        return 2;
    }
    if (rtp_tree_read(argv[1], NULL, &t, &err) != RTP_OK)
        return fail(argv[1], &err);
    snprintf(mkd, sizeof mkd, "mat.%s.kd", argv[2]);
    rtp_tree_get_info(t, &ti);
    if (rtp_image_create(ti.width, ti.height, NULL, &img, &err) != RTP_OK) {
        fail("image", &err);
        goto out;
    }
    memset(&eo, 0, sizeof eo);
    eo.threads = 1;
    eo.incremental = 1; /* one image kept, as --stream keeps it */
    if (argc == 4) {
        rtp_image *full = NULL;
        rtp_status st;
        CALLGRIND_START_INSTRUMENTATION;
        CALLGRIND_TOGGLE_COLLECT;
        st = rtp_tree_trace(t, 1, &full, NULL, &err);
        CALLGRIND_TOGGLE_COLLECT;
        CALLGRIND_DUMP_STATS_AT("full_trace");
        CALLGRIND_STOP_INSTRUMENTATION;
        rtp_image_destroy(full);
        if (st != RTP_OK) {
            fail("full trace", &err);
            goto out;
        }
    }
    if (step(t, img, &eo, NULL, NULL, "first_eval"))
        goto out;
    /* bench_reeval's order: light colour, ambient, kd (3 each), moves */
    for (i = 0; i < 3; i++)
        if (step(t, img, &eo, "light.0.color", lc[i % 2],
                 i == 0 ? "light_colour_1st" : i == 2 ? "light_colour" : NULL))
            goto out;
    for (i = 0; i < 3; i++)
        if (step(t, img, &eo, "ambient", am[i % 2], i == 2 ? "ambient" : NULL))
            goto out;
    for (i = 0; i < 3; i++)
        if (step(t, img, &eo, mkd, kd[i % 2],
                 i == 0 ? "material_kd_1st" : i == 2 ? "material_kd" : NULL))
            goto out;
    for (m = 0; m < sizeof moves / sizeof *moves; m++) {
        eo.shadows = moves[m].mode;
        /* (auto: the CLI's default, its own resolution) */
        eo.shadow_res = moves[m].mode == RTP_SHADOWS_AUTO ? 0 : 256;
        /* the third of three: a drag as it goes on (the first after the
           material edits combines every sample, the second starts the
           light's kept rest of the sums: tree.c); from mv[0] to mv[1] as
           the second of two was before session 11 */
        for (i = 0; i < 3; i++)
            if (step(t, img, &eo, "light.0.pos", mv[(i + 1) % 2],
                     i == 2 ? moves[m].label : NULL))
                goto out;
    }
    rc = 0;
out:
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    return rc;
}
