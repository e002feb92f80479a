/* fuzz_nff.c — fuzzes the NFF reader with rtp's additions
 * (rtp_scene_load_memory), then traces, records and re-evaluates a 3x3
 * image of every scene it accepts, checking that the trees reproduce the
 * traced image bit for bit.  Relative file names (include, texture, bump,
 * bezier) resolve in test/fuzz/data/, so run from the repository's top. */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_status st;
    if (size > 1 << 16 || fuzz_names_special_file(data, size))
        return 0;
    memset(&err, 0, sizeof err);
    st = rtp_scene_load_memory((const char *)data, size, "test/fuzz/data/fuzz.nff",
                               "nff", &fuzz_alloc, &s, &err);
    fuzz_check_error(&err, st);
    FUZZ_ASSERT((st == RTP_OK) == (s != NULL));
    if (st == RTP_OK) {
        rtp_scene_info info;
        rtp_scene_get_info(s, &info);
        /* Big meshes from an include make the trace slow, not deeper. */
        if (info.triangles + info.spheres + info.cones < 4096)
            fuzz_trace_scene(s, 3, 3);
    }
    rtp_scene_destroy(s);
    return 0;
}
