/* fuzz_mtl.c — fuzzes the MTL reader.  MTL is only read through an OBJ's
 * mtllib, so each input is written to a file in $TMPDIR (one per process)
 * and loaded by a small OBJ; every material it defines is then given to
 * a face and a 4x4 image traced, recorded and re-evaluated.  map_Kd and
 * bump names resolve next to that file. */
#include "fuzz_common.h"

#include <unistd.h>

static char mtl_path[512];

static void make_path(void)
{
    const char *dir = getenv("TMPDIR");
    if (mtl_path[0])
        return;
    if (!dir || !*dir)
        dir = "/tmp";
    snprintf(mtl_path, sizeof mtl_path, "%s/rtp-fuzz-mtl-%ld.mtl", dir,
             (long)getpid());
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char obj[700];
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_status st;
    FILE *f;
    int n;
    if (size > 1 << 16 || fuzz_names_special_file(data, size))
        return 0;
    make_path();
    f = fopen(mtl_path, "wb");
    if (!f)
        return 0;
    if (size)
        fwrite(data, 1, size, f);
    if (fclose(f) != 0)
        return 0;
    n = snprintf(obj, sizeof obj,
                 "mtllib %s\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                 "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                 "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n", mtl_path);
    memset(&err, 0, sizeof err);
    st = rtp_scene_load_memory(obj, (size_t)n, "fuzz-mtl.obj", "obj",
                               &fuzz_alloc, &s, &err);
    fuzz_check_error(&err, st);
    if (st == RTP_OK && s->nmats > 0) {
        size_t i;
        for (i = 0; i < s->ntris; i++)
            s->tris[i].mat = (uint32_t)(i % s->nmats);
        fuzz_trace_scene(s, 4, 4);
    }
    rtp_scene_destroy(s);
    remove(mtl_path);
    return 0;
}
