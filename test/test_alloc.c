/* test_alloc.c — allocation-failure injection.  An rtp_allocator that fails
 * the N-th allocation (counted in a struct passed as `user`) and tracks
 * every live block runs each operation with N = 1, 2, 3, ... until one run
 * meets no failure.  Every failing run must return RTP_ERR_NOMEM (or
 * another documented status, listed per operation), leave nothing
 * allocated once what it returned is destroyed, and not crash.  Prints how
 * many allocation sites (allocations of the successful run) each
 * operation exercised.  Deterministic: no seed. */
#if defined(__linux__) && !defined(_GNU_SOURCE)
#define _GNU_SOURCE /* mincore (test_large_block_untouched) */
#endif
#include "check.h"
#include "internal.h"
#include "rtp.h"

#include <sched.h>
#include <stdint.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#if defined(__linux__)
#include <sys/mman.h>
#endif

/* ------------------------------------------------------------ allocator */

typedef struct failing {
    int armed;       /* count and fail only while armed */
    long count;      /* allocations (malloc, realloc) while armed */
    long fail_at;    /* fail the fail_at-th; 0: never */
    int failed;      /* a failure was injected */
    long live;       /* blocks allocated and not freed (armed or not) */
    long bad_frees;  /* frees of pointers this allocator never gave */
    long odd_calls;  /* a size of 0 or a free of NULL (rtp.h: rtp makes none) */
} failing;

/* Each block carries a header with a magic word, so a free of a foreign
   pointer or a double free is caught instead of corrupting the heap. */
#define HDR 16
#define MAGIC 0x52545041u  /* "RTPA" */
#define DEAD 0x44454144u

static int inject(failing *f)
{
    if (!f->armed)
        return 0;
    f->count++;
    if (f->fail_at && f->count == f->fail_at) {
        f->failed = 1;
        return 1;
    }
    return 0;
}

static void *fa_malloc(void *user, size_t size)
{
    failing *f = (failing *)user;
    unsigned char *p;
    uint32_t m = MAGIC;
    f->odd_calls += size == 0;
    if (inject(f) || size > (size_t)-1 - HDR)
        return NULL;
    p = (unsigned char *)malloc(size + HDR);
    if (!p)
        return NULL;
    memcpy(p, &m, sizeof m);
    f->live++;
    return p + HDR;
}

static int fa_check(failing *f, void *ptr)
{
    uint32_t m;
    memcpy(&m, (unsigned char *)ptr - HDR, sizeof m);
    if (m != MAGIC) {
        f->bad_frees++;
        return 0;
    }
    return 1;
}

static void fa_free(void *user, void *ptr)
{
    failing *f = (failing *)user;
    uint32_t d = DEAD;
    f->odd_calls += ptr == NULL;
    if (!ptr || !fa_check(f, ptr))
        return;
    memcpy((unsigned char *)ptr - HDR, &d, sizeof d);
    f->live--;
    free((unsigned char *)ptr - HDR);
}

static void *fa_realloc(void *user, void *ptr, size_t size)
{
    failing *f = (failing *)user;
    unsigned char *p;
    if (!ptr)
        return fa_malloc(user, size);
    f->odd_calls += size == 0;
    if (!fa_check(f, ptr))
        return NULL;
    if (inject(f) || size > (size_t)-1 - HDR)
        return NULL;
    p = (unsigned char *)realloc((unsigned char *)ptr - HDR, size + HDR);
    return p ? p + HDR : NULL;
}

/* An allocator over f that fails nothing (f->fail_at 0) and counts live
   blocks. */
static void failing_init(failing *f, rtp_allocator *a)
{
    memset(f, 0, sizeof *f);
    a->malloc_fn = fa_malloc;
    a->realloc_fn = fa_realloc;
    a->free_fn = fa_free;
    a->user = f;
}

/* ------------------------------------------------------------- fixtures */

static char dir[512];

static const char *tmp_path(const char *name)
{
    static char buf[8][600];
    static int i;
    i = (i + 1) % 8;
    snprintf(buf[i], sizeof buf[i], "%s/%s", dir, name);
    return buf[i];
}

static int write_text(const char *name, const char *text)
{
    FILE *f = fopen(tmp_path(name), "wb");
    if (!f)
        return -1;
    fputs(text, f);
    return fclose(f);
}

/* Every NFF construct and addition: camera, background, ambient, named
   and switched-off lights, materials with names, checker, image texture,
   bump maps, sphere, cone, polygon (concave), pp, an included OBJ with its
   MTL and a transform, an included NFF and a Bezier patch. */
static const char nff_text[] =
    "b 0.1 0.1 0.2\n"
    "v from 0 -6 2 at 0 0 0.5 up 0 0 1 angle 40 hither 0.01 resolution 6 5\n"
    "ambient 0.05 0.05 0.05\n"
    "l 3 -4 6 0.8 0.7 0.6\nname lamp\n"
    "l -3 -4 5\n"
    "l 0 3 5\nname spare\noff\n"
    "s -3 3 0.2 0.2\n" /* before any f: the default material */
    "f 0.9 0.9 0.9 0.8 0.2 20 0 0\nname floor\nchecker 0.1 0.1 0.1 0.5\n"
    "bump waves 0.5 0.2\n"
    "p 6 -4 -4 0 4 -4 0 4 0 0 0 0 0 0 4 0 -4 4 0\n"
    "f 0.8 0.3 0.3 0.5 0.4 40 0.4 1.5\nname glass\nbump noise 0.2 0.3\n"
    "s 0 0 1 0.8\n"
    "f 0.3 0.8 0.3 0.9 0 100000 0 0\nname green\ntexture tex.ppm\n"
    "bump tex.ppm 0.5\n"
    "c 1.5 0 0 0.3 1.5 0 1.5 0.1\n"
    "pp 3 -2 0 0 0 0 1 -1 0 1 0 0 1 -2 0 2 0 0 1\n"
    "include mesh.obj scale 0.5 rotate z 30 translate -2 1 0.5\n"
    "include sub.nff\n"
    "bezier patch.bpt 2 scale 0.3 translate 2 2 1\n";

static const char sub_text[] =
    "f 0.5 0.5 0.9 0.7 0.2 30 0 0\nname inner\n"
    "l 1 1 4 0.3 0.3 0.3\nname inner_lamp\n"
    "s 0 2 0.5 0.3\n";

static const char obj_text[] =
    "mtllib mesh.mtl\n"
    "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv 0 0 1\n"
    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
    "vn 0 0 1\nvn 0 0.7 0.7\n"
    "usemtl red\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
    "usemtl pic\nf -5/-4/-2 -4/-3/-2 -1/-1/-1\n"
    "usemtl clear\nf 1 2 5\nf 3 4 5\n";

static const char mtl_text[] =
    "newmtl red\nKd 0.8 0.2 0.2\nKs 0.3\nNs 40\n"
    "newmtl clear\nKd 0.2 0.2 0.2\nKs 0.5\nNi 1.5\nd 0.3\n"
    "newmtl pic\nKd 1 1 1\nmap_Kd tex.ppm\nbump -bm 0.5 tex.ppm\n";

/* Two lights: a first evaluation into a kept image makes their colour
   planes and S (tree.c cp_ready) */
static const char ready_text[] =
    "b 0.1 0.1 0.2\n"
    "v from 0 -6 2 at 0 0 0.5 up 0 0 1 angle 40 hither 0.01 resolution 6 5\n"
    "ambient 0.05 0.05 0.05\n"
    "l 3 -4 6 0.8 0.7 0.6\nname lamp\n"
    "l -3 -4 5\n"
    "f 0.9 0.9 0.9 0.8 0.2 20 0 0\nname floor\n"
    "p 4 -4 -4 0 4 -4 0 4 4 0 -4 4 0\n"
    "f 0.8 0.3 0.3 0.5 0.4 40 0.4 1.5\nname glass\n"
    "s 0 0 1 0.8\n";

static const char ppm_text[] = "P3\n2 2\n255\n255 0 0  0 255 0\n0 0 255  255 255 255\n";

static int write_patch(void)
{
    FILE *f = fopen(tmp_path("patch.bpt"), "wb");
    int i, j;
    if (!f)
        return -1;
    fprintf(f, "1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n16\n");
    for (j = 0; j < 4; j++)
        for (i = 0; i < 4; i++)
            fprintf(f, "%g,%g,%g\n", i - 1.5, j - 1.5, 0.1 * (i * j));
    return fclose(f);
}

static int setup(void)
{
    const char *t = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/rtp-alloc.%ld", t && *t ? t : "/tmp", (long)getpid());
    if (mkdir(dir, 0700) != 0)
        return -1;
    return write_text("scene.nff", nff_text) || write_text("sub.nff", sub_text) ||
           write_text("mesh.obj", obj_text) || write_text("mesh.mtl", mtl_text) ||
           write_text("tex.ppm", ppm_text) || write_text("ready.nff", ready_text) ||
           write_patch();
}

/* ----------------------------------------------------------- operations */

/* What an operation gets: the allocator (unarmed), and what earlier,
   unarmed steps made with it.  An operation arms f around the one call it
   tests, destroys all it made and returns that call's status. */
typedef struct ctx {
    failing *f;
    const rtp_allocator *a;
    rtp_error err;
} ctx;

#define ARM(c) ((c)->f->armed = 1)
#define DISARM(c) ((c)->f->armed = 0)

static rtp_trace_options small_opt(void)
{
    rtp_trace_options o;
    memset(&o, 0, sizeof o);
    o.width = 6;
    o.height = 5;
    o.threads = 1;
    return o;
}

static rtp_status op_load_nff(ctx *c)
{
    rtp_scene *s = NULL;
    rtp_status st;
    ARM(c);
    st = rtp_scene_load(tmp_path("scene.nff"), c->a, &s, &c->err);
    DISARM(c);
    if (st == RTP_OK) {
        rtp_scene_info info;
        rtp_scene_get_info(s, &info);
        CHECK(info.spheres == 3 && info.cones == 1 && info.textures == 1);
        CHECK(info.lights == 4);
    }
    rtp_scene_destroy(s);
    return st;
}

static rtp_status op_load_obj(ctx *c)
{
    rtp_scene *s = NULL;
    rtp_status st;
    ARM(c);
    st = rtp_scene_load(tmp_path("mesh.obj"), c->a, &s, &c->err);
    DISARM(c);
    if (st == RTP_OK) {
        rtp_scene_info info;
        rtp_scene_get_info(s, &info);
        CHECK(info.triangles == 5 && info.materials >= 3 && info.textures == 1);
    }
    rtp_scene_destroy(s);
    return st;
}

static const char *scene_name = "scene.nff"; /* scene()'s */

/* Loads the NFF scene (scene_name) unarmed. */
static rtp_scene *scene(ctx *c)
{
    rtp_scene *s = NULL;
    if (rtp_scene_load(tmp_path(scene_name), c->a, &s, &c->err) != RTP_OK) {
        fprintf(stderr, "setup: %s\n", c->err.message);
        return NULL;
    }
    return s;
}

static rtp_status op_trace(ctx *c)
{
    rtp_scene *s = scene(c);
    rtp_image *img = NULL;
    rtp_trace_options o = small_opt();
    rtp_status st;
    if (!s)
        return RTP_ERR_IO;
    ARM(c);
    st = rtp_trace(s, &o, &img, NULL, &c->err);
    DISARM(c);
    rtp_image_destroy(img);
    rtp_scene_destroy(s);
    return st;
}

static rtp_status op_record(ctx *c)
{
    rtp_scene *s = scene(c);
    rtp_image *img = NULL;
    rtp_tree *t = NULL;
    rtp_trace_options o = small_opt();
    rtp_status st;
    if (!s)
        return RTP_ERR_IO;
    ARM(c);
    st = rtp_record(s, &o, &t, &img, NULL, &c->err);
    DISARM(c);
    CHECK(st == RTP_OK || (!t && !img));
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    return st;
}

/* A tree handed in through the builder: eye hits on every sample, a
   reflected hit and a miss below some (the builder finish once freed by a
   tree whose allocator was not yet set: a jump to address 0). */
static rtp_status op_builder(ctx *c)
{
    rtp_scene *s = scene(c);
    rtp_builder *b = NULL;
    rtp_tree *t = NULL;
    rtp_hit_record h;
    rtp_status st;
    int x, y;
    if (!s)
        return RTP_ERR_IO;
    memset(&h, 0, sizeof h);
    ARM(c);
    st = rtp_builder_create(s, 3, 2, 0, &b, &c->err);
    for (y = 0; st == RTP_OK && y < 2; y++)
        for (x = 0; st == RTP_OK && x < 3; x++) {
            int root;
            h.pos[0] = 0.1 * x;
            h.pos[2] = 0.5 + 0.1 * y;
            h.prim = 0;
            root = rtp_builder_hit(b, x, y, RTP_NO_PARENT, RTP_RAY_EYE, &h, &c->err);
            if (root < 0) {
                st = (rtp_status)-root;
                break;
            }
            if (x == 1) {
                int r = rtp_builder_hit(b, x, y, root, RTP_RAY_REFLECTED, &h, &c->err);
                if (r < 0)
                    st = (rtp_status)-r;
                else
                    st = rtp_builder_miss(b, x, y, root, RTP_RAY_REFRACTED, &c->err);
            }
        }
    if (st == RTP_OK) {
        st = rtp_builder_finish(b, &t, &c->err);
        b = NULL; /* (finish frees the builder, whatever it returns) */
    }
    DISARM(c);
    CHECK(st == RTP_OK || !t);
    rtp_builder_destroy(b);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    return st;
}

/* Records the NFF scene's trees unarmed. */
static int tree_spd; /* tree(): SPD's corner samples */

static rtp_tree *tree(ctx *c)
{
    rtp_scene *s = scene(c);
    rtp_tree *t = NULL;
    rtp_trace_options o = small_opt();
    if (!s)
        return NULL;
    if (tree_spd) { /* a 6x5 region of SPD's 512x512 */
        o.spd = 1;
        o.region[0] = 253;
        o.region[1] = 253;
        o.region[2] = 259;
        o.region[3] = 258;
    }
    if (rtp_record(s, &o, &t, NULL, NULL, &c->err) != RTP_OK)
        t = NULL;
    rtp_scene_destroy(s);
    return t;
}

static rtp_status op_tree_write(ctx *c)
{
    rtp_tree *t = tree(c);
    rtp_status st;
    unsigned long long bytes = 0;
    if (!t)
        return RTP_ERR_IO;
    ARM(c);
    st = rtp_tree_write(t, tmp_path("w.rtp"), &bytes, &c->err);
    DISARM(c);
    rtp_tree_destroy(t);
    return st;
}

static rtp_status op_tree_read(ctx *c)
{
    rtp_tree *t = NULL;
    rtp_status st;
    ARM(c);
    st = rtp_tree_read(tmp_path("r.rtp"), c->a, &t, &c->err);
    DISARM(c);
    CHECK(st == RTP_OK || !t);
    rtp_tree_destroy(t);
    return st;
}

/* The same file summarised: its trees checked a band at a time, none
   kept (rtp info). */
static rtp_status op_tree_read_summary(ctx *c)
{
    rtp_tree *t = NULL;
    rtp_tree_info ti;
    rtp_status st;
    ARM(c);
    st = rtp_tree_read_summary(tmp_path("r.rtp"), c->a, &t, &c->err);
    DISARM(c);
    CHECK(st == RTP_OK || !t);
    rtp_tree_get_info(t, &ti);
    CHECK(st != RTP_OK || ti.nodes > 0);
    rtp_tree_destroy(t);
    return st;
}

static rtp_status op_tree_eval(ctx *c)
{
    rtp_tree *t = tree(c);
    rtp_image *img = NULL;
    rtp_status st;
    if (!t)
        return RTP_ERR_IO;
    ARM(c);
    st = rtp_tree_eval(t, NULL, &img, NULL, &c->err);
    DISARM(c);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    return st;
}

/* rtp_tree_eval_file's edits: the first `n` of `kv` (pairs). */
typedef struct file_edits {
    const char *const (*kv)[2];
    size_t n;
} file_edits;

static rtp_status file_edit(void *user, rtp_tree *t, rtp_error *err)
{
    file_edits *f = (file_edits *)user;
    size_t i;
    rtp_status st;
    for (i = 0; i < f->n; i++)
        if ((st = rtp_tree_set(t, f->kv[i][0], f->kv[i][1], err)) != RTP_OK)
            return st;
    return RTP_OK;
}

/* Optical edits and a bump kept: the trees evaluated as they are read. */
static const char *const file_a_edits[][2] = {
    {"mat.floor.color", "0.2,0.4,0.6"}, {"light.lamp.color", "1,0.5,0"},
    {"light.spare.on", "1"},            {"mat.floor.bump_strength", "0.9"}};

static rtp_status eval_file_with(ctx *c, const char *const (*kv)[2], size_t n, int threads)
{
    rtp_image *img = NULL;
    rtp_eval_options eo;
    file_edits fe;
    rtp_status st;
    fe.kv = kv;
    fe.n = n;
    memset(&eo, 0, sizeof eo);
    eo.threads = threads;
    ARM(c);
    st = rtp_tree_eval_file(tmp_path("r.rtp"), c->a, file_edit, &fe, &eo, &img, NULL, NULL,
                            &c->err);
    DISARM(c);
    CHECK(st == RTP_OK || !img);
    rtp_image_destroy(img);
    return st;
}

static rtp_status op_tree_eval_file(ctx *c)
{
    return eval_file_with(c, file_a_edits, sizeof file_a_edits / sizeof *file_a_edits, 1);
}

/* A moved light with them: its shadows decided a band at a time. */
static const char *const file_b_edits[][2] = {
    {"light.lamp.color", "1,0.5,0"}, {"light.0.pos", "2,-3,5"}, {"ambient", "0.2"}};

static rtp_status op_tree_eval_file_moved(ctx *c)
{
    return eval_file_with(c, file_b_edits, sizeof file_b_edits / sizeof *file_b_edits, 2);
}

static rtp_status op_tree_eval_file_threads(ctx *c)
{
    return eval_file_with(c, file_a_edits, sizeof file_a_edits / sizeof *file_a_edits, 3);
}

/* Edits of every class the tree takes: optical (A), a moved light (B,
   shadows decided anew at evaluation), a raised ks (D, re-traced). */
static const char *const tree_edits[][2] = {
    {"mat.floor.color", "0.2,0.4,0.6"}, {"light.lamp.color", "1,0.5,0"},
    {"light.spare.on", "1"},            {"ambient", "0.2"},
    {"light.0.pos", "2,-3,5"},          {"mat.green.ks", "0.3"},
    {"mat.glass.ior", "1.2"}};

static rtp_status op_tree_set(ctx *c)
{
    rtp_tree *t = tree(c);
    rtp_status st = RTP_OK;
    size_t i;
    if (!t)
        return RTP_ERR_IO;
    ARM(c);
    for (i = 0; i < sizeof tree_edits / sizeof *tree_edits && st == RTP_OK; i++)
        st = rtp_tree_set(t, tree_edits[i][0], tree_edits[i][1], &c->err);
    DISARM(c);
    rtp_tree_destroy(t);
    return st;
}

/* Evaluation after those edits: moved-light shadows and re-tracing. */
static rtp_status op_tree_eval_edited(ctx *c)
{
    rtp_tree *t = tree(c);
    rtp_image *img = NULL;
    rtp_status st;
    size_t i;
    if (!t)
        return RTP_ERR_IO;
    for (i = 0; i < sizeof tree_edits / sizeof *tree_edits; i++)
        if (rtp_tree_set(t, tree_edits[i][0], tree_edits[i][1], &c->err) != RTP_OK) {
            fprintf(stderr, "setup: %s\n", c->err.message);
            rtp_tree_destroy(t);
            return RTP_ERR_IO;
        }
    ARM(c);
    st = rtp_tree_eval(t, NULL, &img, NULL, &c->err);
    DISARM(c);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    return st;
}

/* The same from the file: its trees read whole, then evaluated. */
static rtp_status op_tree_eval_file_whole(ctx *c)
{
    return eval_file_with(c, tree_edits, sizeof tree_edits / sizeof *tree_edits, 1);
}

/* A stream of edits on warm caches, into one kept image: what allocates
   the one-term planes (light colour, ambient, a material's kd and colour),
   the highlight lists (consecutive shine edits) and the kept samples.
   Each image, also where a failure was tolerated (an optional cache or
   scratch left out), must be an uncached twin tree's. */
static const char *const warm_edits[][2] = {
    {"light.lamp.color", "1,0.5,0"}, {"light.lamp.color", "0.5,1,0"},
    {"ambient", "0.2"},              {"mat.glass.kd", "0.3"},
    {"mat.glass.color", "0.1,0.2,0.9"}, {"mat.glass.shine", "10"},
    {"mat.glass.shine", "80"},       {"mat.glass.shine", "5"},
    {"light.lamp.color", "0.2,0.2,0.2"}, {"mat.glass.shine", "7"},
    {"mat.glass.shine", "9"},        {"mat.green.ks", "0.2"}};

static rtp_status warm_run(ctx *c, const char *const (*edits)[2], size_t n, int arm_first)
{
    rtp_tree *t = tree(c), *twin = tree(c);
    rtp_image *img = NULL;
    rtp_eval_options eo, fo;
    rtp_status st;
    size_t i;
    if (!t || !twin) {
        rtp_tree_destroy(t);
        rtp_tree_destroy(twin);
        return RTP_ERR_IO;
    }
    memset(&eo, 0, sizeof eo);
    eo.incremental = 1;
    memset(&fo, 0, sizeof fo);
    fo.no_cache = 1; /* the twin: every image from scratch */
    if (arm_first)
        ARM(c);
    st = rtp_tree_eval(t, &eo, &img, NULL, &c->err);
    DISARM(c);
    if (st != RTP_OK && !arm_first)
        fprintf(stderr, "setup: %s\n", c->err.message);
    if (st != RTP_OK) {
        rtp_tree_destroy(t);
        rtp_tree_destroy(twin);
        return arm_first ? st : RTP_ERR_IO;
    }
    for (i = 0; i < n && st == RTP_OK; i++) {
        rtp_image *ref = NULL;
        rtp_diff_stats d;
        ARM(c);
        st = rtp_tree_set(t, edits[i][0], edits[i][1], &c->err);
        if (st == RTP_OK)
            st = rtp_tree_eval_into(t, &eo, img, NULL, &c->err);
        DISARM(c);
        if (st != RTP_OK)
            break;
        /* each image, also where a failure was tolerated, the twin's */
        CHECK(rtp_tree_set(twin, edits[i][0], edits[i][1], NULL) == RTP_OK &&
              rtp_tree_eval(twin, &fo, &ref, NULL, NULL) == RTP_OK);
        CHECK_MSG(ref && rtp_image_diff(img, ref, 0.0, &d, NULL) == RTP_OK && d.max_abs <= 1e-5,
                  "%s=%s: %g off the uncached twin", edits[i][0], edits[i][1],
                  ref ? d.max_abs : -1.0);
        rtp_image_destroy(ref);
    }
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_tree_destroy(twin);
    return st;
}

static rtp_status op_tree_eval_warm(ctx *c)
{
    return warm_run(c, warm_edits, sizeof warm_edits / sizeof *warm_edits, 0);
}

/* A scene of two lights, its first evaluation armed too: the colour
   planes and S it makes for the edits (cp_ready), each left out where
   there is no memory for it, then edits that use them, each image the
   uncached twin's. */
static const char *const ready_edits[][2] = {
    {"light.lamp.color", "1,0.5,0"}, {"light.1.color", "0.2,0.3,0.9"},
    {"mat.glass.shine", "10"},       {"light.lamp.color", "0.5,1,0"},
    {"ambient", "0.2"},              {"light.1.color", "1,1,1"}};

static rtp_status op_tree_eval_ready(ctx *c)
{
    rtp_status st;
    scene_name = "ready.nff";
    st = warm_run(c, ready_edits, sizeof ready_edits / sizeof *ready_edits, 1);
    tree_spd = 1;
    if (st == RTP_OK)
        st = warm_run(c, ready_edits, sizeof ready_edits / sizeof *ready_edits, 1);
    tree_spd = 0;
    scene_name = "scene.nff";
    return st;
}

/* The same on a tree of SPD's corner samples (material planes from the
   kept image count and mark the pixels first). */
static rtp_status op_tree_eval_warm_spd(ctx *c)
{
    rtp_status st;
    tree_spd = 1;
    st = op_tree_eval_warm(c);
    tree_spd = 0;
    return st;
}

static const char *const image_names[] = {"i.png", "i.ppm", "i.pfm"};
static int image_kind;

static rtp_image *gradient(ctx *c, float k)
{
    rtp_image *img = NULL;
    int i;
    if (rtp_image_create(7, 5, c->a, &img, &c->err) != RTP_OK)
        return NULL;
    for (i = 0; i < 7 * 5 * 3; i++)
        img->pixels[i] = (float)((i * 37) % 101) / 100.0f * k;
    return img;
}

static rtp_status op_image_write(ctx *c)
{
    rtp_image *img = gradient(c, 1.0f);
    rtp_status st;
    if (!img)
        return RTP_ERR_IO;
    ARM(c);
    st = rtp_image_write(img, tmp_path(image_names[image_kind]), RTP_IMAGE_AUTO, &c->err);
    DISARM(c);
    rtp_image_destroy(img);
    return st;
}

static rtp_status op_image_read(ctx *c)
{
    rtp_image *img = NULL;
    rtp_status st;
    ARM(c);
    st = rtp_image_read(tmp_path(image_names[image_kind]), c->a, &img, &c->err);
    DISARM(c);
    CHECK(st == RTP_OK || !img);
    if (st == RTP_OK)
        CHECK(img->width == 7 && img->height == 5);
    rtp_image_destroy(img);
    return st;
}

static rtp_status op_image_diff(ctx *c)
{
    rtp_image *a = gradient(c, 1.0f), *b = gradient(c, 0.9f);
    rtp_diff_stats d;
    rtp_status st = RTP_ERR_IO;
    if (a && b) {
        ARM(c);
        st = rtp_image_diff(a, b, 0.01, &d, &c->err);
        DISARM(c);
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    return st;
}

static rtp_status op_heatmap(ctx *c)
{
    rtp_image *a = gradient(c, 1.0f), *b = gradient(c, 0.9f);
    rtp_status st = RTP_ERR_IO;
    if (a && b) {
        ARM(c);
        /* (PNG where the build has it: libpng's writes allocate too) */
        st = rtp_diff_heatmap(a, b, 0.0,
                              tmp_path(rtp_png_supported() ? "heat.png" : "heat.ppm"), &c->err);
        DISARM(c);
    }
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    return st;
}


/* ------------------------------------------------------------- cancel */

/* A caller's cancel that says yes at its at-th question (0: never), and
   counts the progress calls made after it did. */
typedef struct asker {
    long asked, at, progress_after;
    int said;
    double last; /* the last progress reported */
} asker;

static int ask_cancel(void *user)
{
    asker *k = (asker *)user;
    k->asked++;
    if (k->at && k->asked >= k->at)
        k->said = 1;
    return k->said;
}

static void ask_progress(void *user, double done)
{
    asker *k = (asker *)user;
    k->last = done;
    k->progress_after += k->said;
}

static void same_image(const rtp_image *a, const rtp_image *b, double tol, const char *what)
{
    rtp_diff_stats d;
    CHECK_MSG(a && b && rtp_image_diff(a, b, 0.0, &d, NULL) == RTP_OK && d.max_abs <= tol,
              "%s: not the same image", what);
}

/* An evaluation of t (eo, stats into es) equals its full trace on
   `threads` threads, within 1e-6: what a cancelled call must leave. */
static void eval_is_trace(rtp_tree *t, const rtp_eval_options *eo, rtp_eval_stats *es,
                          int threads, const char *what)
{
    rtp_image *img = NULL, *ref = NULL;
    rtp_error err;
    memset(&err, 0, sizeof err);
    CHECK_MSG(rtp_tree_eval(t, eo, &img, es, &err) == RTP_OK, "%s", err.message);
    CHECK(rtp_tree_trace(t, threads, &ref, NULL, &err) == RTP_OK);
    same_image(img, ref, 1e-6, what);
    rtp_image_destroy(img);
    rtp_image_destroy(ref);
}

/* rtp_trace and rtp_record with options.cancel: a yes at any point (before
   or after the kd-tree's build, after some rows, on one thread or two,
   with the caller relaying a deep tree's workers) stops the trace with
   RTP_ERR_CANCELLED, nothing made or leaked, no row begun after it; a
   cancel that never says yes changes no bit. */
static void test_cancel_trace(void)
{
    static const long ats[] = {1, 2, 3, 7, 0};
    failing f;
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_image *ref = NULL;
    rtp_error err;
    rtp_trace_options o = small_opt();
    int threads, rec, deep;
    size_t i;
    failing_init(&f, &a);
    o.width = 40;
    o.height = 30;
    if (rtp_scene_load(tmp_path("scene.nff"), &a, &s, &err) != RTP_OK ||
        rtp_trace(s, &o, &ref, NULL, &err) != RTP_OK) {
        CHECK_MSG(0, "fixture: %s", err.message);
        rtp_scene_destroy(s);
        return;
    }
    for (deep = 0; deep < 2; deep++)
        for (threads = 1; threads <= 2; threads++)
            for (rec = 0; rec < 2; rec++)
                for (i = 0; i < sizeof ats / sizeof *ats; i++) {
                    asker k;
                    rtp_image *img = NULL;
                    rtp_tree *t = NULL;
                    rtp_status st;
                    long live = f.live;
                    /* (the calling thread of two asks after its own rows
                       alone, and a relaying one as it sees rows end: on a
                       busy machine the other threads may trace every row
                       first, so only the questions on either side of the
                       kd-tree's build are sure to be asked) */
                    if ((threads > 1 || deep) && ats[i] > 2)
                        continue;
                    memset(&k, 0, sizeof k);
                    k.at = ats[i];
                    o.threads = threads;
                    /* (past 32 levels the rows run on rtp's own threads,
                       the caller relaying progress and cancel) */
                    o.max_depth = deep ? 40 : 0;
                    o.progress = ask_progress;
                    o.cancel = ask_cancel;
                    o.progress_user = &k;
                    memset(&err, 0, sizeof err);
                    st = rec ? rtp_record(s, &o, &t, &img, NULL, &err)
                             : rtp_trace(s, &o, &img, NULL, &err);
                    if (k.at) {
                        CHECK_MSG(st == RTP_ERR_CANCELLED && err.status == st && !img && !t,
                                  "deep %d threads %d record %d at %ld: status %d", deep,
                                  threads, rec, k.at, (int)st);
                        CHECK_MSG(k.asked == k.at, "at %ld: asked %ld times", k.at, k.asked);
                        /* (workers end the rows they are in, and the last
                           report counts them: one a worker) */
                        CHECK_MSG(k.progress_after <= (deep ? threads : threads - 1),
                                  "deep %d threads %d at %ld: %ld rows after the yes", deep,
                                  threads, k.at, k.progress_after);
                    } else {
                        CHECK_MSG(st == RTP_OK, "%s", err.message);
                        /* (the last report says all is done, however the
                           rows fell to the threads: with two it could stop
                           at the calling thread's last row) */
                        CHECK_MSG(k.last == 1.0, "threads %d deep %d: progress ended at %g",
                                  threads, deep, k.last);
                        /* (one thread: after each row and on either side of
                           the kd-tree's build; the calling thread of two
                           asks after its own rows) */
                        CHECK_MSG(threads > 1 || deep ? k.asked >= 2 : k.asked == o.height + 2,
                                  "threads %d deep %d: asked %ld times", threads, deep, k.asked);
                        /* (a deep trace is another trace: the depth differs) */
                        if (!deep)
                            same_image(img, ref, 0.0, "a cancel that never said yes");
                    }
                    rtp_image_destroy(img);
                    rtp_tree_destroy(t);
                    CHECK_MSG(f.live == live, "at %ld: %ld block(s) leaked", k.at, f.live - live);
                }
    rtp_image_destroy(ref);
    rtp_scene_destroy(s);
    CHECK(f.live == 0 && f.bad_frees == 0);
}

/* rtp_tree_eval with options.cancel through a class-D re-trace and a
   camera edit's: a yes gives RTP_ERR_CANCELLED, the tree as it was (the
   next evaluation, uncancelled, equals a full trace of the edited scene),
   nothing leaked; an evaluation that traces nothing does not ask. */
static void test_cancel_eval(void)
{
    static const char *const keys[][2] = {{"mat.glass.ior", "1.3"},
                                          {"camera.from", "0.5,-6,2.5"}};
    failing f;
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_trace_options o = small_opt();
    size_t i;
    int threads;
    failing_init(&f, &a);
    o.width = 40;
    o.height = 30;
    if (rtp_scene_load(tmp_path("scene.nff"), &a, &s, &err) != RTP_OK) {
        CHECK_MSG(0, "fixture: %s", err.message);
        return;
    }
    for (threads = 1; threads <= 2; threads++)
        for (i = 0; i < sizeof keys / sizeof *keys; i++) {
            rtp_tree *t = NULL;
            rtp_image *img = NULL;
            rtp_eval_options eo;
            rtp_eval_stats es;
            asker k;
            o.threads = threads;
            if (rtp_record(s, &o, &t, NULL, NULL, &err) != RTP_OK) {
                CHECK_MSG(0, "record: %s", err.message);
                break;
            }
            memset(&eo, 0, sizeof eo);
            memset(&k, 0, sizeof k);
            eo.threads = threads;
            eo.cancel = ask_cancel;
            eo.progress_user = &k;
            CHECK(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK);
            CHECK_MSG(k.asked == 0, "an evaluation without a re-trace asked %ld times",
                      k.asked);
            rtp_image_destroy(img);
            img = NULL;
            CHECK(rtp_tree_set(t, keys[i][0], keys[i][1], &err) == RTP_OK);
            /* asked before the first chunk and after each the calling
               thread traces: one thread says yes after two chunks, two
               before any (the calling thread of two may trace one chunk
               only: a later yes might never be asked) */
            k.at = threads == 1 ? 3 : 1;
            memset(&err, 0, sizeof err);
            CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_ERR_CANCELLED &&
                          err.status == RTP_ERR_CANCELLED && !img,
                      "%s: %s", keys[i][0], err.message);
            CHECK_MSG(k.asked == k.at, "%s: asked %ld times", keys[i][0], k.asked);
            /* the tree as it was: traced again now, as a full trace */
            memset(&k, 0, sizeof k);
            memset(&es, 0, sizeof es);
            eval_is_trace(t, &eo, &es, threads, keys[i][0]);
            CHECK(es.retraced_samples > 0 && k.asked >= 1 && !k.said);
            rtp_tree_destroy(t);
        }
    rtp_scene_destroy(s);
    CHECK(f.live == 0 && f.bad_frees == 0);
}

/* rtp_tree_eval with options.cancel through a moved light: a yes before
   the shadow structure's build, after it, or after some rows gives
   RTP_ERR_CANCELLED and leaks nothing; half-decided rows are not taken
   for the light's new place: moved back to where it was last decided
   with one thread's rows cut short, the next evaluation equals a full
   trace (the light's place as decided stays that of the rows' old
   half otherwise). */
static void test_cancel_move(void)
{
    static const rtp_shadow_mode modes[] = {RTP_SHADOWS_EXACT, RTP_SHADOWS_LIGHTBUF};
    static const long ats[] = {1, 2, 20};
    failing f;
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_trace_options o = small_opt();
    size_t m, i;
    int threads;
    failing_init(&f, &a);
    o.width = 40;
    o.height = 30;
    if (rtp_scene_load(tmp_path("scene.nff"), &a, &s, &err) != RTP_OK) {
        CHECK_MSG(0, "fixture: %s", err.message);
        return;
    }
    for (threads = 1; threads <= 2; threads++)
        for (m = 0; m < sizeof modes / sizeof *modes; m++)
            for (i = 0; i < sizeof ats / sizeof *ats; i++) {
                rtp_tree *t = NULL;
                rtp_image *img = NULL;
                rtp_eval_options eo;
                rtp_eval_stats es;
                asker k;
                long live;
                /* (the calling thread of two may decide one row only: a
                   later yes might never be asked) */
                if (threads > 1 && ats[i] > 2)
                    continue;
                o.threads = threads;
                if (rtp_record(s, &o, &t, NULL, NULL, &err) != RTP_OK) {
                    CHECK_MSG(0, "record: %s", err.message);
                    break;
                }
                memset(&eo, 0, sizeof eo);
                memset(&k, 0, sizeof k);
                eo.threads = threads;
                eo.shadows = modes[m];
                eo.shadow_res = 32;
                eo.cancel = ask_cancel;
                eo.progress = ask_progress;
                eo.progress_user = &k;
                /* decided at one place (the caches made) */
                CHECK(rtp_tree_set(t, "light.lamp.pos", "-1,-5,4", &err) == RTP_OK);
                CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK, "%s", err.message);
                CHECK_MSG(k.asked >= 2 && !k.said, "a move asked %ld times", k.asked);
                rtp_image_destroy(img);
                img = NULL;
                /* a move to another, cancelled */
                CHECK(rtp_tree_set(t, "light.lamp.pos", "2,-3,7", &err) == RTP_OK);
                memset(&k, 0, sizeof k);
                k.at = ats[i];
                live = f.live;
                memset(&err, 0, sizeof err);
                CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_ERR_CANCELLED &&
                              err.status == RTP_ERR_CANCELLED && !img,
                          "threads %d mode %d at %ld: %s", threads, (int)modes[m], k.at,
                          err.message);
                CHECK_MSG(k.asked == k.at, "at %ld: asked %ld times", k.at, k.asked);
                CHECK_MSG(f.live == live, "at %ld: %ld block(s) leaked", k.at, f.live - live);
                /* back where it was last decided: decided anew, as a full
                   trace */
                CHECK(rtp_tree_set(t, "light.lamp.pos", "-1,-5,4", &err) == RTP_OK);
                memset(&k, 0, sizeof k);
                memset(&es, 0, sizeof es);
                eval_is_trace(t, &eo, &es, threads, "moved back after a cancelled move");
                /* (a yes before the rows left the last decisions whole) */
                CHECK_MSG(ats[i] <= 2 || (es.moved_lights == 1 && es.shadow_queries > 0),
                          "at %ld: the light not decided anew", ats[i]);
                rtp_tree_destroy(t);
            }
    rtp_scene_destroy(s);
    CHECK(f.live == 0 && f.bad_frees == 0);
}

/* A direction cube's build asks the caller's cancel inside it (a fine
   cube takes seconds: the bunny's light buffer at 8192 cells 3 s, 10,000
   stacked quads' item buffer at 2048 300 s): 3,200 small triangles over
   a floor, a light buffer of 1024 cells a face and an item buffer at
   256, 1 and 2 threads.  On one thread a move asks more often than an
   exact one, which builds no cube (asked before the build, after it and
   after rows only, a cube's move asked as often); a yes at the second
   question, the
   first inside the build, stops it, nothing leaked, and the next
   evaluation equals a full trace. */
static void test_cancel_cube_build(void)
{
    static const struct {
        rtp_shadow_mode mode;
        int res;
    } cases[] = {{RTP_SHADOWS_LIGHTBUF, 1024}, {RTP_SHADOWS_ITEMBUF, 256}};
    failing f;
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_error err;
    rtp_trace_options o = small_opt();
    char *text = (char *)malloc(300000);
    size_t len = 0, c;
    int i, j, threads;
    failing_init(&f, &a);
    if (!text) {
        CHECK(text != NULL);
        return;
    }
    len += (size_t)sprintf(text + len, "v\nfrom 0 -6 5\nat 0 0 0\nup 0 0 1\nangle 45\n"
                                       "hither 0.01\nresolution 32 24\nb 0.1 0.1 0.1\n"
                                       "l 0.5 0.3 4\nf 0.8 0.6 0.3 0.7 0.3 20 0 1\n"
                                       "p 4\n-4 -4 0\n4 -4 0\n4 4 0\n-4 4 0\n");
    for (i = 0; i < 40; i++)
        for (j = 0; j < 40; j++) {
            double x = -2.0 + 0.1 * i, y = -2.0 + 0.1 * j, z = 1.0 + 0.01 * ((i * 7 + j) % 5);
            len += (size_t)sprintf(text + len, "p 4\n%g %g %g\n%g %g %g\n%g %g %g\n%g %g %g\n", x,
                                   y, z, x + 0.05, y, z, x + 0.05, y + 0.05, z, x, y + 0.05, z);
        }
    o.width = 32;
    o.height = 24;
    if (rtp_scene_load_memory(text, len, "grid.nff", NULL, &a, &s, &err) != RTP_OK) {
        CHECK_MSG(0, "fixture: %s", err.message);
        free(text);
        return;
    }
    free(text);
    for (threads = 1; threads <= 2; threads++)
        for (c = 0; c < sizeof cases / sizeof *cases; c++) {
            rtp_tree *t = NULL;
            rtp_image *img = NULL;
            rtp_eval_options eo;
            asker k;
            long coarse, fine, live;
            o.threads = threads;
            if (rtp_record(s, &o, &t, NULL, NULL, &err) != RTP_OK) {
                CHECK_MSG(0, "record: %s", err.message);
                break;
            }
            memset(&eo, 0, sizeof eo);
            eo.threads = threads;
            eo.shadows = cases[c].mode;
            eo.cancel = ask_cancel;
            eo.progress = ask_progress;
            /* the questions of an exact move, then of the case's */
            memset(&k, 0, sizeof k);
            eo.progress_user = &k;
            eo.shadows = RTP_SHADOWS_EXACT;
            CHECK(rtp_tree_set(t, "light.0.pos", "0.4,0.2,4", &err) == RTP_OK);
            CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK, "%s", err.message);
            coarse = k.asked;
            rtp_image_destroy(img);
            img = NULL;
            memset(&k, 0, sizeof k);
            eo.shadows = cases[c].mode;
            eo.shadow_res = cases[c].res;
            CHECK(rtp_tree_set(t, "light.0.pos", "0.3,0.2,4", &err) == RTP_OK);
            CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK, "%s", err.message);
            fine = k.asked;
            rtp_image_destroy(img);
            img = NULL;
            /* (with two threads the calling thread's rows, and so the
               questions after them, vary from run to run) */
            CHECK_MSG(threads > 1 || fine > coarse,
                      "mode %d: asked %ld times, %ld for an exact move", (int)cases[c].mode, fine,
                      coarse);
            /* cancelled inside the build */
            memset(&k, 0, sizeof k);
            k.at = 2;
            live = f.live;
            CHECK(rtp_tree_set(t, "light.0.pos", "0.2,0.2,4", &err) == RTP_OK);
            memset(&err, 0, sizeof err);
            CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_ERR_CANCELLED && !img,
                      "threads %d mode %d: %s", threads, (int)cases[c].mode, err.message);
            CHECK_MSG(k.asked == 2, "threads %d mode %d: asked %ld times", threads,
                      (int)cases[c].mode, k.asked);
            CHECK_MSG(f.live == live, "threads %d mode %d: %ld block(s) leaked", threads,
                      (int)cases[c].mode, f.live - live);
            eo.cancel = NULL;
            eval_is_trace(t, &eo, NULL, threads, "after a cancelled build");
            rtp_tree_destroy(t);
        }
    rtp_scene_destroy(s);
    CHECK(f.live == 0 && f.bad_frees == 0);
}

/* The test scene recorded at w x h on one thread (the library's own
   allocator): 0, or -1 with a failed check and nothing left. */
static int recorded(int w, int h, rtp_scene **s, rtp_tree **t)
{
    rtp_trace_options o = small_opt();
    rtp_error err;
    o.width = w;
    o.height = h;
    *s = NULL;
    *t = NULL;
    if (rtp_scene_load(tmp_path("scene.nff"), NULL, s, &err) != RTP_OK ||
        rtp_record(*s, &o, t, NULL, NULL, &err) != RTP_OK) {
        CHECK_MSG(0, "fixture: %s", err.message);
        rtp_scene_destroy(*s);
        *s = NULL;
        return -1;
    }
    return 0;
}

/* A move of two lights by the item buffer cancelled after the first was
   decided: those decisions are the item buffer's, while the mode on file
   stayed the last whole evaluation's, and an exact evaluation after it
   kept them (a moved light decided 1 of 2).  Both are decided anew. */
static void test_cancel_move_mode(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *img = NULL, *ref = NULL;
    rtp_error err;
    rtp_eval_options eo;
    rtp_eval_stats es;
    asker k;
    if (recorded(40, 30, &s, &t) != 0)
        return;
    memset(&eo, 0, sizeof eo);
    eo.threads = 1;
    eo.shadows = RTP_SHADOWS_EXACT;
    CHECK(rtp_tree_set(t, "light.lamp.pos", "-1,-5,4", &err) == RTP_OK);
    CHECK(rtp_tree_set(t, "light.1.pos", "-2,-4,6", &err) == RTP_OK);
    CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK, "%s", err.message);
    rtp_image_destroy(img);
    img = NULL;
    /* the item buffer, cancelled before the second light's build: two
       questions and one a row for the first */
    memset(&k, 0, sizeof k);
    k.at = 2 + 30 + 1;
    eo.shadows = RTP_SHADOWS_ITEMBUF;
    eo.shadow_res = 8; /* (coarse: its decisions differ from exact ones) */
    eo.cancel = ask_cancel;
    eo.progress_user = &k;
    CHECK(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_ERR_CANCELLED);
    CHECK_MSG(k.asked == k.at, "asked %ld times", k.asked);
    /* exact again: both lights decided anew, as a full trace */
    eo.shadows = RTP_SHADOWS_EXACT;
    eo.shadow_res = 0;
    eo.cancel = NULL;
    memset(&es, 0, sizeof es);
    CHECK_MSG(rtp_tree_eval(t, &eo, &img, &es, &err) == RTP_OK, "%s", err.message);
    CHECK_MSG(es.moved_lights == 2, "%d of 2 moved lights decided anew", es.moved_lights);
    CHECK(rtp_tree_trace(t, 1, &ref, NULL, &err) == RTP_OK);
    same_image(img, ref, 1e-6, "exact after a cancelled item-buffer move");
    rtp_image_destroy(img);
    rtp_image_destroy(ref);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* A UI running its event loop in the progress or cancel callback may
   call the library on the tree being evaluated: each such call is
   refused with RTP_ERR_ARGUMENT (an edit there was lost, the call
   returned OK, and the tree, off its scene by 0.38, could be written),
   and the evaluation goes on to equal a full trace. */
typedef struct reenter {
    rtp_tree *t;
    int calls;
    int refused; /* calls refused with RTP_ERR_ARGUMENT */
} reenter;

static int reenter_cb(void *user)
{
    reenter *r = (reenter *)user;
    rtp_error e;
    rtp_image *img = NULL;
    rtp_tree *crop = NULL;
    const double pos[3] = {1, 1, 1};
    static const int region[4] = {0, 0, 4, 4};
    r->calls++;
    r->refused += rtp_tree_set(r->t, "camera.from", "0.5,-6,2.5", &e) == RTP_ERR_ARGUMENT;
    r->refused += rtp_tree_set(r->t, "mat.glass.ior", "1.7", &e) == RTP_ERR_ARGUMENT;
    r->refused += rtp_tree_add_light(r->t, pos, &e) == RTP_ERR_ARGUMENT;
    r->refused += rtp_tree_eval(r->t, NULL, &img, NULL, &e) == RTP_ERR_ARGUMENT && !img;
    r->refused += rtp_tree_trace(r->t, 1, &img, NULL, &e) == RTP_ERR_ARGUMENT && !img;
    r->refused += rtp_tree_write(r->t, tmp_path("reenter.rtp"), NULL, &e) == RTP_ERR_ARGUMENT;
    r->refused += rtp_tree_crop(r->t, region, &crop, &e) == RTP_ERR_ARGUMENT && !crop;
    r->refused += rtp_tree_merge(&r->t, 1, &crop, &e) == RTP_ERR_ARGUMENT && !crop;
    return 0;
}

static void reenter_progress(void *user, double done)
{
    (void)done;
    (void)reenter_cb(user);
}

static void test_callback_reentry(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *img = NULL, *ref = NULL;
    rtp_error err;
    rtp_eval_options eo;
    reenter r;
    int cb;
    if (recorded(40, 30, &s, &t) != 0)
        return;
    for (cb = 0; cb < 2; cb++) {
        memset(&r, 0, sizeof r);
        r.t = t;
        memset(&eo, 0, sizeof eo);
        eo.threads = 1;
        if (cb)
            eo.progress = reenter_progress;
        else
            eo.cancel = reenter_cb;
        eo.progress_user = &r;
        /* a class-D edit and a moved light: both callbacks are called */
        CHECK(rtp_tree_set(t, "mat.glass.ior", cb ? "1.4" : "1.3", &err) == RTP_OK);
        CHECK(rtp_tree_set(t, "light.lamp.pos", cb ? "2,-3,7" : "-1,-5,4", &err) == RTP_OK);
        CHECK_MSG(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK, "%s", err.message);
        CHECK_MSG(r.calls > 0 && r.refused == 8 * r.calls, "%s: %d of %d calls refused",
                  cb ? "progress" : "cancel", r.refused, 8 * r.calls);
        /* nothing the callback asked was done: the tree is its scene's */
        CHECK(rtp_tree_trace(t, 1, &ref, NULL, &err) == RTP_OK);
        same_image(img, ref, 1e-6, "evaluated with refused calls from its callback");
        rtp_image_destroy(img);
        rtp_image_destroy(ref);
        img = ref = NULL;
    }
    /* The full trace of the tree's scene (rtp_tree_trace_opt, reeval
       --reference's) takes the caller's callbacks too, and they met no
       refusal: a light added there grew the scene's lights under the
       rows being traced (ASan: heap-buffer-overflow in combine_sums),
       an edit made the rows before and after it two scenes' */
    for (cb = 0; cb < 2; cb++) {
        rtp_trace_options to;
        memset(&r, 0, sizeof r);
        r.t = t;
        memset(&to, 0, sizeof to);
        to.threads = 1;
        if (cb)
            to.progress = reenter_progress;
        else
            to.cancel = reenter_cb;
        to.progress_user = &r;
        CHECK_MSG(rtp_tree_trace_opt(t, &to, &img, NULL, &err) == RTP_OK, "%s", err.message);
        CHECK_MSG(r.calls > 0 && r.refused == 8 * r.calls, "trace's %s: %d of %d calls refused",
                  cb ? "progress" : "cancel", r.refused, 8 * r.calls);
        CHECK(rtp_tree_trace(t, 1, &ref, NULL, &err) == RTP_OK);
        same_image(img, ref, 0, "traced with refused calls from its callback");
        rtp_image_destroy(img);
        rtp_image_destroy(ref);
        img = ref = NULL;
    }
    /* and after it, the same calls are taken */
    CHECK(rtp_tree_set(t, "camera.from", "0.5,-6,2.5", &err) == RTP_OK);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* A re-trace works in chunks of 64 samples and asked progress and cancel
   after each: a 1024x1024 camera edit called them 16,385 times, and a
   UI's progress of 1 ms made that 1.5 s edit 21.9 s on one thread.  At
   most about a thousand calls a call now, still ending at 1. */
static void test_progress_calls_bounded(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *img = NULL;
    rtp_error err;
    rtp_eval_options eo;
    rtp_eval_stats es;
    asker k;
    if (recorded(320, 240, &s, &t) != 0)
        return;
    memset(&eo, 0, sizeof eo);
    memset(&k, 0, sizeof k);
    memset(&es, 0, sizeof es);
    eo.threads = 1;
    eo.progress = ask_progress;
    eo.cancel = ask_cancel;
    eo.progress_user = &k;
    CHECK(rtp_tree_set(t, "camera.from", "0.5,-6,2.5", &err) == RTP_OK);
    CHECK_MSG(rtp_tree_eval(t, &eo, &img, &es, &err) == RTP_OK, "%s", err.message);
    /* (76,800 samples: 1,200 chunks) */
    CHECK_MSG(es.retraced_samples == 76800, "%llu samples traced again", es.retraced_samples);
    CHECK_MSG(k.asked >= 100 && k.asked <= 1002, "cancel asked %ld times", k.asked);
    CHECK_MSG(k.last == 1.0, "progress ended at %g", k.last);
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

/* ------------------------------------------------------ shared allocator */

/* rtp.h: "A caller's allocator need not be thread-safe: calls with
   options.threads > 1 take a lock around it".  This one is not, and says
   when two calls overlapped: a call made while armed waits (a bounded
   number of yields, no clock) for another to come in, so that an unlocked
   call from a second thread is caught whatever the scheduling; where the
   library locks, the bound only makes the run slower.  The uncached
   evaluation's rows grew their scratch through the caller's allocator
   from every thread without the lock (TSan saw it; an arena allocator
   would have been corrupted). */
typedef struct serial {
    rtpi_mutex m; /* guards the counts, never held across a call */
    int armed, inside;
    long calls, overlaps;
} serial;

static void serial_enter(serial *z)
{
    long k, seen;
    int wait;
    rtpi_mutex_lock(&z->m);
    if (++z->inside > 1)
        z->overlaps++;
    z->calls++;
    wait = z->armed && z->inside == 1;
    seen = z->overlaps;
    rtpi_mutex_unlock(&z->m);
    for (k = 0; wait && k < 20000; k++) {
        long now;
        rtpi_mutex_lock(&z->m);
        now = z->overlaps;
        rtpi_mutex_unlock(&z->m);
        if (now != seen)
            break;
        sched_yield();
    }
}

static void serial_leave(serial *z)
{
    rtpi_mutex_lock(&z->m);
    z->inside--;
    rtpi_mutex_unlock(&z->m);
}

static void *se_malloc(void *user, size_t size)
{
    void *p;
    serial_enter((serial *)user);
    p = malloc(size);
    serial_leave((serial *)user);
    return p;
}

static void *se_realloc(void *user, void *ptr, size_t size)
{
    void *p;
    serial_enter((serial *)user);
    p = realloc(ptr, size);
    serial_leave((serial *)user);
    return p;
}

static void se_free(void *user, void *ptr)
{
    serial_enter((serial *)user);
    free(ptr);
    serial_leave((serial *)user);
}

static void test_threads_share_allocator(void)
{
    serial z;
    rtp_allocator a;
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *img = NULL;
    rtp_trace_options o = small_opt();
    rtp_eval_options eo;
    rtp_error err;
    if (!(rtp_features() & RTP_FEATURE_THREADS))
        SKIP("a build without threads");
    memset(&z, 0, sizeof z);
    CHECK(rtpi_mutex_init(&z.m) == 0);
    a.malloc_fn = se_malloc;
    a.realloc_fn = se_realloc;
    a.free_fn = se_free;
    a.user = &z;
    CHECK(rtp_scene_load(tmp_path("scene.nff"), &a, &s, &err) == RTP_OK);
    o.width = 16;
    o.height = 12;
    CHECK(s && rtp_record(s, &o, &t, NULL, NULL, &err) == RTP_OK);
    if (t) {
        /* one evaluation without caches on two threads: each row's
           samples grow the thread's scratch */
        memset(&eo, 0, sizeof eo);
        eo.threads = 2;
        eo.no_cache = 1;
        z.armed = 1;
        CHECK(rtp_tree_eval(t, &eo, &img, NULL, &err) == RTP_OK);
        z.armed = 0;
        CHECK_MSG(z.overlaps == 0, "%ld of %ld allocator calls overlapped", z.overlaps,
                  z.calls);
    }
    rtp_image_destroy(img);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    rtpi_mutex_destroy(&z.m);
}

/* -------------------------------------------------------------- driver */

/* Runs op with the 1st, 2nd, ... allocation failing until a run meets no
   failure.  @return the allocation sites (allocations of that run). */
static long sweep(const char *name, rtp_status (*op)(ctx *))
{
    long n, sites = -1;
    for (n = 1; n < 100000; n++) {
        failing f;
        rtp_allocator a;
        ctx c;
        rtp_status st;
        failing_init(&f, &a);
        f.fail_at = n;
        memset(&c, 0, sizeof c);
        c.f = &f;
        c.a = &a;
        st = op(&c);
        CHECK_MSG(f.live == 0, "%s: fail at %ld: %ld block(s) leaked", name, n, f.live);
        CHECK_MSG(f.bad_frees == 0, "%s: fail at %ld: %ld bad free(s)", name, n,
                  f.bad_frees);
        CHECK_MSG(f.odd_calls == 0, "%s: fail at %ld: %ld call(s) for 0 bytes or freeing NULL",
                  name, n, f.odd_calls);
        if (!f.failed) {
            CHECK_MSG(st == RTP_OK, "%s: no failure injected, yet status %d (%s)", name,
                      (int)st, c.err.message);
            sites = f.count;
            break;
        }
        if (st == RTP_OK)
            continue; /* the failure was tolerated (an optional cache) */
        CHECK_MSG(st == RTP_ERR_NOMEM, "%s: fail at %ld: status %d (%s), not NOMEM",
                  name, n, (int)st, c.err.message);
        CHECK_MSG(c.err.status == st, "%s: fail at %ld: err.status %d, returned %d",
                  name, n, (int)c.err.status, (int)st);
        if (check_failed_now)
            break; /* one report per operation is enough */
    }
    printf("%-24s %ld allocation sites\n", name, sites);
    return sites;
}

#define SWEEP(fn) static void test_##fn(void) { CHECK(sweep(#fn, op_##fn) >= 0); }
SWEEP(tree_eval_file)
SWEEP(tree_eval_file_threads)
SWEEP(tree_eval_file_moved)
SWEEP(tree_eval_file_whole)
SWEEP(load_nff)
SWEEP(load_obj)
SWEEP(trace)
SWEEP(record)
SWEEP(builder)
SWEEP(tree_write)
SWEEP(tree_read)
SWEEP(tree_read_summary)
SWEEP(tree_eval)
SWEEP(tree_set)
SWEEP(tree_eval_edited)
SWEEP(tree_eval_warm)
SWEEP(tree_eval_warm_spd)
SWEEP(tree_eval_ready)
SWEEP(image_diff)
SWEEP(heatmap)

/* The default allocator (util.c): small blocks in malloc's heap, large
   ones (1 MiB up) too when malloc makes them, as mappings of their own
   when realloc makes them, moved rather than copied as they grow.  Every
   change of size keeps the bytes both sizes hold, across each kind. */
static int holds(const uint32_t *p, size_t n, uint32_t seed)
{
    size_t i;
    for (i = 0; i < n; i++)
        if (p[i] != (uint32_t)(i * 2654435761u) + seed)
            return 0;
    return 1;
}

static void fill(uint32_t *p, size_t from, size_t n, uint32_t seed)
{
    size_t i;
    for (i = from; i < n; i++)
        p[i] = (uint32_t)(i * 2654435761u) + seed;
}

static void test_default_allocator(void)
{
    static const size_t sizes[] = {1000,      300000,    (1u << 20) / 4, 3u << 20,
                                   20u << 20, 5u << 20,  (1u << 20) / 4 - 1,
                                   25000,     12u << 20, 100};
    rtp_allocator a;
    uint32_t *p, *q;
    size_t i, n, cap = 0;
    rtpi_allocator_init(&a, NULL);
    /* one block through every kind: heap, mapping grown, shrunk, heap */
    p = (uint32_t *)rtpi_malloc(&a, 16 * sizeof *p);
    CHECK(p != NULL);
    if (!p)
        return;
    n = 16;
    fill(p, 0, n, 7);
    for (i = 0; i < sizeof sizes / sizeof *sizes; i++) {
        size_t m = sizes[i];
        q = (uint32_t *)rtpi_realloc(&a, p, m * sizeof *q);
        CHECK_MSG(q != NULL, "realloc to %zu words", m);
        if (!q)
            break;
        p = q;
        CHECK_MSG(holds(p, n < m ? n : m, 7), "%zu words kept going to %zu", n, m);
        CHECK_MSG(((uintptr_t)p & 15u) == 0, "%zu words: aligned to 16", m);
        fill(p, n < m ? n : m, m, 7);
        n = m;
    }
    rtpi_free(&a, p);
    /* a large block malloc made, grown and shrunk */
    n = (2u << 20) / sizeof *p;
    p = (uint32_t *)rtpi_malloc(&a, n * sizeof *p);
    CHECK(p != NULL);
    if (p) {
        fill(p, 0, n, 3);
        q = (uint32_t *)rtpi_realloc(&a, p, 3 * n * sizeof *q);
        CHECK(q != NULL && holds(q, n, 3));
        p = q ? q : p;
        q = (uint32_t *)rtpi_realloc(&a, p, 1000 * sizeof *q);
        CHECK(q != NULL && holds(q, 1000, 3));
        rtpi_free(&a, q ? q : p);
    }
    /* rtpi_grow as trace grows the ray trees: one word at a time to
       48 MiB, every word where it was put */
    p = NULL;
    for (i = 0; i < (48u << 20) / sizeof *p; i++) {
        if (rtpi_grow(&a, (void **)&p, &cap, i + 1, sizeof *p)) {
            CHECK_MSG(0, "rtpi_grow to %zu words", i + 1);
            break;
        }
        p[i] = (uint32_t)(i * 2654435761u) + 11;
    }
    CHECK(p != NULL && holds(p, i, 11));
    rtpi_free(&a, p);
    rtpi_free(&a, NULL); /* (nothing) */
}

#if defined(__linux__) && defined(MREMAP_MAYMOVE) && defined(MREMAP_FIXED) && \
    !defined(RTPI_ASAN) && !defined(RTPI_TSAN)
/* (util.c's condition for its mappings) */
#define BIG_BLOCKS 1

/* The system's transparent huge page setting: 2 "always", 1 "madvise",
   0 "never" or none (no such file). */
static int thp_mode(void)
{
    FILE *f = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    char line[128];
    int mode = 0;
    if (!f)
        return 0;
    if (fgets(line, sizeof line, f))
        mode = strstr(line, "[always]") ? 2 : strstr(line, "[madvise]") ? 1 : 0;
    fclose(f);
    return mode;
}

/* 1 where the mapping that holds p is advised for transparent huge pages
   (VmFlags "hg" in /proc/self/smaps), 0 where not, -1 where smaps says
   nothing of p. */
static int huge_advised(const void *p)
{
    FILE *f = fopen("/proc/self/smaps", "r");
    char line[512];
    int in = 0, found = -1;
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f)) {
        unsigned long lo, hi;
        char c;
        if (sscanf(line, "%lx-%lx %c", &lo, &hi, &c) == 3) {
            in = (uintptr_t)p >= lo && (uintptr_t)p < hi;
        } else if (in && strncmp(line, "VmFlags:", 8) == 0) {
            found = strstr(line, " hg") != NULL;
            in = 0;
        }
    }
    fclose(f);
    return found;
}
#endif

/* A large block the default allocator makes and nobody touches has at
   most its header's page in memory.  (Advised for huge pages, as blocks
   of 1 MiB and more were until session 45, the header's write zeroed the
   block's whole first 2 MiB: a material's first kd edit made blocks it
   never used.)  Where util.c makes its own mappings: Linux (mincore
   too), not under AddressSanitizer nor ThreadSanitizer; not where the
   system gives huge pages unasked (THP "always"). */
static void test_large_block_untouched(void)
{
#if defined(BIG_BLOCKS)
    /* 64 MiB: above glibc's largest mmap threshold (32 MiB), so fresh
       memory whatever this process freed before */
    const size_t size = (size_t)64 << 20, span = (size_t)2 << 20;
    rtp_allocator a;
    unsigned char vec[((size_t)2 << 20) / 4096];
    long pg = sysconf(_SC_PAGESIZE);
    size_t i, resident = 0;
    char *p, *start;
    rtpi_allocator_init(&a, NULL);
    if (pg <= 0 || (size_t)pg > span || span / (size_t)pg > sizeof vec) {
        printf("  (skipped: page size %ld)\n", pg);
        return;
    }
    if (thp_mode() == 2) {
        printf("  (skipped: transparent huge pages \"always\")\n");
        return;
    }
    p = (char *)rtpi_malloc(&a, size);
    CHECK(p != NULL);
    if (!p)
        return;
    /* from the page p lies in: a header before p in that page counts */
    start = (char *)((uintptr_t)p & ~(uintptr_t)(pg - 1));
    CHECK(mincore(start, span, vec) == 0);
    for (i = 0; i < span / (size_t)pg; i++)
        resident += vec[i] & 1u;
    CHECK_MSG(resident <= 1, "%zu of the first %zu pages resident", resident,
              span / (size_t)pg);
    /* and it is usable end to end */
    memset(p, 0x5a, size);
    CHECK(p[0] == 0x5a && p[size - 1] == 0x5a);
    rtpi_free(&a, p);
#endif
}

/* Which large blocks the default allocator advises for transparent huge
   pages (MADV_HUGEPAGE): the mappings that realloc grows (the ray trees
   while they are recorded, a kd-tree's nodes), not the blocks malloc
   makes (an evaluation's caches, a tree read from a file).  On this
   project's KVM host a fresh huge page's first touch cost 2.2-6.4 ms a
   MiB where a small page's cost 0.45-0.6 (util.c): advised, the caches
   made first evaluations 2-3x slower on rings, tree and mount. */
static void test_large_block_advice(void)
{
#if defined(BIG_BLOCKS)
    rtp_allocator a;
    char *p, *q, *m, *r;
    rtpi_allocator_init(&a, NULL);
    p = (char *)rtpi_malloc(&a, (size_t)64 << 20); /* a large heap block */
    q = (char *)rtpi_malloc(&a, 1000);
    m = q ? (char *)rtpi_realloc(&a, q, (size_t)8 << 20) : NULL; /* grown: a mapping */
    /* made large by realloc (the recorded trees start at their estimate) */
    r = (char *)rtpi_realloc(&a, NULL, (size_t)8 << 20);
    CHECK(p != NULL && m != NULL && r != NULL);
    if (p && m && r) {
        int hp = huge_advised(p + ((size_t)32 << 20)), hm = huge_advised(m + ((size_t)4 << 20));
        int hr = huge_advised(r + ((size_t)4 << 20));
        if (hp < 0 || hm < 0 || hr < 0) {
            printf("  (skipped: /proc/self/smaps says nothing of the blocks)\n");
        } else {
            CHECK_MSG(hp == 0, "a 64 MiB block from malloc advised for huge pages");
            /* (madvise fails where the kernel has no transparent huge
               pages) */
#if defined(MADV_HUGEPAGE)
            if (thp_mode() > 0)
                CHECK_MSG(hm == 1, "a block grown to 8 MiB not advised for huge pages");
            if (thp_mode() > 0)
                CHECK_MSG(hr == 1, "an 8 MiB block made by realloc not advised for huge pages");
#endif
        }
    }
    rtpi_free(&a, p);
    rtpi_free(&a, m ? m : q);
    rtpi_free(&a, r);
#endif
}

#if defined(BIG_BLOCKS) && defined(MADV_POPULATE_WRITE)
/* Pages of [p, p + size) in memory, from the page after p's (a block's
   header shares p's page with it) to the last whole page; -1 if mincore
   fails.  With drop, those pages are dropped instead (MADV_DONTNEED: the
   block may be memory malloc had, in memory already): 0. */
static long resident_pages(const char *p, size_t size, size_t *pages, int drop)
{
    long pg = sysconf(_SC_PAGESIZE);
    uintptr_t lo, hi;
    unsigned char *vec;
    size_t i, n;
    long r = 0;
    if (pg <= 0)
        return -1;
    lo = ((uintptr_t)p + (uintptr_t)pg) & ~(uintptr_t)(pg - 1);
    hi = ((uintptr_t)p + size) & ~(uintptr_t)(pg - 1);
    n = hi > lo ? (size_t)(hi - lo) / (size_t)pg : 0;
    *pages = n;
    if (drop && hi > lo && madvise((void *)lo, (size_t)(hi - lo), MADV_DONTNEED) != 0)
        return -1;
    if (drop)
        return 0;
    vec = (unsigned char *)malloc(n + 1);
    if (!vec || mincore((void *)lo, (size_t)(hi - lo), vec) != 0) {
        free(vec);
        return -1;
    }
    for (i = 0; i < n; i++)
        r += vec[i] & 1u;
    free(vec);
    return r;
}
#endif

/* Blocks about to be written whole are populated in one call
   (rtpi_prefault, util.c: MADV_POPULATE_WRITE; a page fault each cost
   twice as much on session 46's host): a fresh block of the default
   allocator has every page in memory after it, before any write; a
   block of a user's allocator is left alone (its memory may not be this
   process's to populate), and so is a block below the threshold. */
static void test_prefault(void)
{
#if defined(BIG_BLOCKS) && defined(MADV_POPULATE_WRITE)
    /* (each range dropped from memory first: a block malloc had may be
       in memory already) */
    const size_t size = (size_t)64 << 20;
    rtp_allocator a, ua;
    failing f;
    size_t pages = 0;
    long res, pg = sysconf(_SC_PAGESIZE);
    char *p, *m;
    rtpi_allocator_init(&a, NULL);
    failing_init(&f, &ua);
    if (pg <= 0) {
        printf("  (skipped: page size %ld)\n", pg);
        return;
    }
    /* a kernel before 5.14 refuses the advice (EINVAL): nothing to test */
    m = (char *)mmap(NULL, (size_t)pg, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1,
                     0);
    if (m == (char *)MAP_FAILED)
        return;
    res = madvise(m, (size_t)pg, MADV_POPULATE_WRITE);
    (void)munmap(m, (size_t)pg);
    if (res != 0) {
        printf("  (skipped: the kernel has no MADV_POPULATE_WRITE)\n");
        return;
    }
    p = (char *)rtpi_malloc(&a, size);
    CHECK(p != NULL);
    if (p) {
        CHECK(resident_pages(p, size, &pages, 1) == 0);
        rtpi_prefault(&a, p, size);
        res = resident_pages(p, size, &pages, 0);
        CHECK_MSG(res == (long)pages, "%ld of %zu pages in memory after rtpi_prefault", res,
                  pages);
        rtpi_free(&a, p);
    }
    if (thp_mode() == 2)
        return; /* (the header's write would bring a whole huge page) */
    p = (char *)rtpi_malloc(&ua, size);
    CHECK(p != NULL);
    if (p) {
        CHECK(resident_pages(p, size, &pages, 1) == 0);
        rtpi_prefault(&ua, p, size);
        res = resident_pages(p, size, &pages, 0);
        CHECK_MSG(res == 0, "%ld pages of a user's allocator's block populated", res);
        rtpi_free(&ua, p);
    }
    p = (char *)rtpi_malloc(&a, size);
    CHECK(p != NULL);
    if (p) {
        /* below the threshold (256 KiB) a syscall costs more than the
           faults it saves */
        CHECK(resident_pages(p, (size_t)64 << 10, &pages, 1) == 0);
        rtpi_prefault(&a, p, (size_t)64 << 10);
        res = resident_pages(p, (size_t)64 << 10, &pages, 0);
        CHECK_MSG(res == 0, "%ld pages of a 64 KiB range populated", res);
        rtpi_free(&a, p);
    }
#endif
}

static void test_image_io(void)
{
    char name[64];
    for (image_kind = 0; image_kind < 3; image_kind++) {
        if (image_kind == 0 && !rtp_png_supported())
            continue;
        snprintf(name, sizeof name, "image_write %s", image_names[image_kind] + 2);
        CHECK(sweep(name, op_image_write) >= 0);
        snprintf(name, sizeof name, "image_read %s", image_names[image_kind] + 2);
        CHECK(sweep(name, op_image_read) >= 0);
    }
}

static void cleanup(void)
{
    static const char *const names[] = {"scene.nff", "sub.nff", "mesh.obj", "mesh.mtl",
                                        "tex.ppm", "ready.nff", "patch.bpt", "w.rtp", "r.rtp",
                                        "i.png", "i.ppm", "i.pfm", "heat.png", "heat.ppm"};
    size_t i;
    for (i = 0; i < sizeof names / sizeof *names; i++)
        remove(tmp_path(names[i]));
    rmdir(dir);
}

int main(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_trace_options o = small_opt();
    rtp_error err;
    if (setup() != 0) {
        fprintf(stderr, "cannot write the fixtures in %s\n", dir);
        cleanup(); /* (what setup wrote before failing: it was left) */
        return 1;
    }
    /* The file op_tree_read reads. */
    if (rtp_scene_load(tmp_path("scene.nff"), NULL, &s, &err) != RTP_OK ||
        rtp_record(s, &o, &t, NULL, NULL, &err) != RTP_OK ||
        rtp_tree_write(t, tmp_path("r.rtp"), NULL, &err) != RTP_OK) {
        char buf[600];
        fprintf(stderr, "fixture: %s\n", rtp_error_format(&err, buf, sizeof buf));
        rtp_tree_destroy(t);
        rtp_scene_destroy(s);
        cleanup();
        return 1;
    }
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    RUN(test_load_nff);
    RUN(test_load_obj);
    RUN(test_trace);
    RUN(test_record);
    RUN(test_builder);
    RUN(test_tree_write);
    RUN(test_tree_read);
    RUN(test_tree_read_summary);
    RUN(test_tree_eval);
    RUN(test_tree_set);
    RUN(test_tree_eval_edited);
    RUN(test_tree_eval_file);
    RUN(test_tree_eval_file_threads);
    RUN(test_tree_eval_file_moved);
    RUN(test_tree_eval_file_whole);
    RUN(test_tree_eval_warm);
    RUN(test_tree_eval_warm_spd);
    RUN(test_tree_eval_ready);
    RUN(test_image_io);
    RUN(test_image_diff);
    RUN(test_heatmap);
    RUN(test_default_allocator);
    RUN(test_large_block_untouched);
    RUN(test_large_block_advice);
    RUN(test_prefault);
    RUN(test_cancel_trace);
    RUN(test_cancel_eval);
    RUN(test_cancel_move);
    RUN(test_cancel_move_mode);
    RUN(test_cancel_cube_build);
    RUN(test_callback_reentry);
    RUN(test_progress_calls_bounded);
    RUN(test_threads_share_allocator);
    cleanup();
    return check_report();
}
