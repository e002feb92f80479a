/* bench_pairs.c — how often the item buffer decides a moved light's
 * shadow wrongly, over every recorded hit (node-light pairs: eye rays and
 * the reflected and refracted rays below them), and the error that makes
 * in the image.
 *
 * For each default SPD scene in ../shared/scenes/spd at 512x512 (SPD
 * corner samples): the trees are recorded, light 0 moves to (2, 3, 9) as
 * bench_reeval moves it, and the move is evaluated with exact shadow rays,
 * then with ITEMBUF at 256, 512, 1024 and 2048 cells per face edge.  Each
 * node's decision for light 0 (the tree's visibility bits) is compared
 * with the exact one; the share that differ is of the pairs decided (hits
 * facing the light).  PSNR and RMSE are the image's against the exact
 * move's (both evaluations on one thread, as before session 26, when the
 * item buffer's answers depended on the order they were asked in: the
 * blocker of a thread's previous query, tested first, corrected some of
 * its wrong "lit" calls; that cache is now the exact modes' alone, and the
 * figures are the item buffer's own).  The target:
 * at most 0.1% wrong and at least 45 dB at 1024.  Reports; never fails. */
#include "internal.h"
#include "../check.h"

#include <string.h>

static void run(const char *dir, const char *name)
{
    static const int res[] = {256, 512, 1024, 2048};
    char path[512];
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *ex = NULL, *ib = NULL;
    rtp_trace_options o;
    rtp_eval_options eo;
    rtp_eval_stats st;
    rtp_tree_info ti;
    uint32_t *ref = NULL;
    size_t words, n, k;
    unsigned long long queries;
    snprintf(path, sizeof path, "%s/spd/%s.nff", dir, name);
    if (rtp_scene_load(path, NULL, &s, NULL) != RTP_OK)
        return;
    memset(&o, 0, sizeof o);
    o.spd = 1;
    o.width = o.height = 512;
    o.threads = 2;
    if (rtp_record(s, &o, &t, NULL, NULL, NULL) != RTP_OK)
        goto out;
    rtp_tree_get_info(t, &ti);
    if (rtp_image_create(ti.width, ti.height, NULL, &ex, NULL) != RTP_OK ||
        rtp_image_create(ti.width, ti.height, NULL, &ib, NULL) != RTP_OK)
        goto out;
    memset(&eo, 0, sizeof eo);
    eo.threads = 1;
    memset(&st, 0, sizeof st);
    if (rtp_tree_set(t, "light.0.pos", "2,3,9", NULL) != RTP_OK ||
        rtp_tree_eval_into(t, &eo, ex, &st, NULL) != RTP_OK || !t->cur_vis)
        goto out;
    queries = st.shadow_queries;
    words = t->cur_words;
    n = t->nnodes;
    ref = (uint32_t *)malloc((n ? n : 1) * words * sizeof *ref);
    if (!ref)
        goto out;
    memcpy(ref, t->cur_vis, n * words * sizeof *ref);
    for (k = 0; k < sizeof res / sizeof *res; k++) {
        rtp_diff_stats d;
        char ps[32];
        unsigned long long wrong = 0, lit_wrong = 0;
        size_t i;
        eo.shadows = RTP_SHADOWS_ITEMBUF;
        eo.shadow_res = res[k];
        if (rtp_tree_eval_into(t, &eo, ib, NULL, NULL) != RTP_OK ||
            rtp_image_diff(ib, ex, 1e-6, &d, NULL) != RTP_OK)
            goto out;
        for (i = 0; i < n; i++) {
            uint32_t a = ref[i * words] & 1u, b = t->cur_vis[i * words] & 1u;
            wrong += a != b;
            lit_wrong += b && !a; /* called lit, in shadow */
        }
        if (d.psnr == HUGE_VAL)
            snprintf(ps, sizeof ps, "exact");
        else
            snprintf(ps, sizeof ps, "%.1f", d.psnr);
        printf("| %s | %d | %llu | %.4f%% | %.4f%% | %.3g | %s |\n", name, res[k], queries,
               queries ? 100.0 * (double)wrong / (double)queries : 0.0,
               queries ? 100.0 * (double)lit_wrong / (double)queries : 0.0, d.rmse, ps);
        fflush(stdout);
    }
out:
    free(ref);
    rtp_image_destroy(ex);
    rtp_image_destroy(ib);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

int main(void)
{
    const char *dir = check_shared_scenes();
    size_t i;
    if (!dir) {
        printf("bench_pairs: ../shared/scenes absent: skipped\n");
        return 0;
    }
    printf("\n## Item buffer against exact shadows, every recorded hit "
           "(light 0 moved, 512x512)\n\n");
    printf("Decisions of light 0's visibility at every node that faces it, item buffer "
           "against exact shadow rays; 'called lit' is the part of the wrong ones that "
           "were in shadow; RMSE and PSNR of the image against the exact move's.\n\n");
    printf("| scene | cells per face edge | pairs decided | wrong | called lit | RMSE | PSNR dB "
           "|\n|---|---|---|---|---|---|---|\n");
    for (i = 0; i < (size_t)CHECK_SPD_SCENES; i++)
        run(dir, check_spd_scenes[i]);
    return 0;
}
