/* fuzz_tree.c — fuzzes the tree-file reader (rtp_tree_read_memory).
 * Section checksums would stop almost every mutation at the first CRC, so
 * the target recomputes each section's CRC in a copy of even-sized inputs
 * (the reader must survive whatever passes its checks, not only what
 * fails them).  A file
 * it accepts is then evaluated, re-edited, inspected and, when small,
 * full-traced: validation must make every accepted file safe to use. */
#include "fuzz_common.h"
#include "fuzz_crc.h"

static void use_tree(rtp_tree *t)
{
    rtp_image *img = NULL;
    rtp_tree_info info;
    rtp_eval_options eo;
    rtp_error err;
    rtp_status st;
    static const char *const edits[][2] = {
        {"mat.0.color", "0.5,0.25,1"}, {"light.0.color", "2,1,0"},
        {"light.0.on", "0"},           {"ambient", "0.3"},
        {"mat.0.kd", "0.1"},           {"mat.0.checker", "1"},
        {"light.0.pos", "1,2,3"},      {"background", "1,0,0"}};
    size_t i;
    rtp_tree_get_info(t, &info);
    /* An evaluation traces again the subtrees a material's ks or kt made
       non-zero since the trace (class D: the file keeps both values), up
       to samples x 2^20 nodes (trace's cap a sample): a file asking for
       depth 255 over 48 samples of glass needed 1.2 GB, what `trace
       --depth 255` of that scene costs.  The evaluation's memory limit
       keeps it to 2 MiB (about 80,000 nodes: quick), over it a named
       error. */
    memset(&eo, 0, sizeof eo);
    eo.memory_limit = 2.0 * 1048576.0;
    st = rtp_tree_eval(t, &eo, &img, NULL, &err);
    fuzz_check_error(&err, st);
    rtp_image_destroy(img);
    img = NULL;
    for (i = 0; i < sizeof edits / sizeof *edits; i++) {
        st = rtp_tree_set(t, edits[i][0], edits[i][1], &err);
        fuzz_check_error(&err, st);
    }
    st = rtp_tree_eval(t, &eo, &img, NULL, &err);
    fuzz_check_error(&err, st);
    rtp_image_destroy(img);
    img = NULL;
    /* A full trace costs samples x primitives x rays per sample, and a
       file may ask for depth 1000 (up to 2^20 rays a sample, trace's
       cap: seconds, not a bug): keep it small. */
    if (info.samples <= 64 && info.max_depth <= 8 &&
        info.triangles + info.spheres + info.cones <= 256) {
        st = rtp_tree_trace(t, 1, &img, NULL, &err);
        fuzz_check_error(&err, st);
        rtp_image_destroy(img);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    unsigned char *copy;
    rtp_tree *t = NULL;
    rtp_error err;
    rtp_status st;
    if (size > 1 << 20)
        return 0;
    copy = (unsigned char *)malloc(size ? size : 1);
    if (!copy)
        return 0;
    if (size)
        memcpy(copy, data, size);
    /* Even-sized inputs get their CRCs recomputed, odd-sized ones are
       read as they are: both paths stay reachable, and the seeds stay
       plain tree files (no mode byte in front). */
    if (size > 8 && size % 2 == 0)
        fix_crcs(copy, size);
    memset(&err, 0, sizeof err);
    st = rtp_tree_read_memory(copy, size, "fuzz.rtp", &fuzz_alloc, &t, &err);
    fuzz_check_error(&err, st);
    FUZZ_ASSERT((st == RTP_OK) == (t != NULL));
    if (st == RTP_OK)
        use_tree(t);
    rtp_tree_destroy(t);
    free(copy);
    return 0;
}
