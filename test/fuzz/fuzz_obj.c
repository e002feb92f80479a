/* fuzz_obj.c — fuzzes the OBJ reader (rtp_scene_load_memory "obj"), and
 * the OBJ reader with a transform (rtpi_read_obj, as NFF's include uses
 * it), then traces, records and re-evaluates a 3x3 image of every mesh
 * it accepts.  mtllib names resolve in test/fuzz/data/ (quad.mtl there). */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_status st;
    if (size > 1 << 16 || fuzz_names_special_file(data, size))
        return 0;
    memset(&err, 0, sizeof err);
    st = rtp_scene_load_memory((const char *)data, size, "test/fuzz/data/fuzz.obj",
                               "obj", &fuzz_alloc, &s, &err);
    fuzz_check_error(&err, st);
    FUZZ_ASSERT((st == RTP_OK) == (s != NULL));
    if (st == RTP_OK) {
        if (s->ntris < 4096)
            fuzz_trace_scene(s, 3, 3);
        rtp_scene_destroy(s);
        s = NULL;
        /* Again with a mirroring, shearing transform and a default
           material, as `include x.obj scale -1 2 3 rotate z 30` reads it. */
        if (rtpi_scene_create(&fuzz_alloc, &s) == RTP_OK) {
            static const double xf[12] = {-0.8, 0.5, 0, 1, 0.4, 1.7, 0, -2,
                                          0, 0.3, 3, 0.5};
            rtpi_material m;
            rtpi_material_default(&m);
            if (rtpi_scene_add_material(s, &m) == 0) {
                memset(&err, 0, sizeof err);
                st = rtpi_read_obj(s, (const char *)data, size,
                                   "test/fuzz/data/fuzz.obj", xf, 0, &err);
                fuzz_check_error(&err, st);
            }
        }
    }
    rtp_scene_destroy(s);
    return 0;
}
