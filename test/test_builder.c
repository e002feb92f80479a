/* test_builder.c — a renderer of its own (analytic sphere and floor, in
 * this file) hands its hits to rtp through the builder, using only rtp.h,
 * then uses rtp's evaluation, edits and tree files.  Its image must match
 * rtp's own trace of the same scene. */
#include "rtp.h"

#include "check.h"

#include <math.h>
#include <string.h>

static const char scene_text[] =
    "v from 0 -6 2.5 at 0 0 0.6 up 0 0 1 angle 40 hither 0.1 resolution 40 30\n"
    "b 0.2 0.3 0.5\n"
    "ambient 0.1 0.1 0.1\n"
    "l 3 -3 6\nname key\n"
    "f 0.8 0.7 0.5 0.9 0 100000 0 1\nname floor\n"
    "p 4 -4 -4 0 4 -4 0 4 4 0 -4 4 0\n"
    "f 0.9 0.2 0.2 0.6 0.4 40 0 1\nname ball\n"
    "s 0 0 1 1\n";

/* This "renderer" knows the floor square (triangles 0 and 1, as rtp
   triangulates the polygon: 0,1,2 and 0,2,3) and the sphere (prim 2). */
typedef struct hitinfo {
    double t, p[3], n[3];
    unsigned prim;
} hitinfo;

static int intersect(const double o[3], const double d[3], hitinfo *h)
{
    double best = HUGE_VAL, oc[3] = {o[0], o[1], o[2] - 1.0}, b, c, disc, t;
    int k, any = 0;
    /* sphere at (0,0,1), radius 1 */
    b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    c = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - 1.0;
    disc = b * b - c;
    if (disc > 0) {
        t = -b - sqrt(disc);
        if (t > 1e-6 && t < best) {
            best = t;
            h->prim = 2;
            any = 1;
        }
    }
    /* floor z = 0, |x|,|y| <= 4 */
    if (d[2] != 0.0) {
        t = -o[2] / d[2];
        if (t > 1e-6 && t < best) {
            double x = o[0] + t * d[0], y = o[1] + t * d[1];
            if (fabs(x) <= 4 && fabs(y) <= 4) {
                best = t;
                /* triangles (-4,-4)(4,-4)(4,4) and (-4,-4)(4,4)(-4,4) */
                h->prim = x >= y ? 0u : 1u;
                any = 1;
            }
        }
    }
    if (!any)
        return 0;
    h->t = best;
    for (k = 0; k < 3; k++)
        h->p[k] = o[k] + best * d[k];
    if (h->prim == 2) {
        h->n[0] = h->p[0];
        h->n[1] = h->p[1];
        h->n[2] = h->p[2] - 1.0;
    } else {
        h->n[0] = h->n[1] = 0.0;
        h->n[2] = 1.0;
    }
    return 1;
}

static void add_hit(rtp_builder *b, int x, int y, int parent, rtp_ray_kind kind,
                    const double o[3], const double d[3], int depth, int *bad)
{
    hitinfo h;
    rtp_hit_record rec;
    unsigned char lights = 0;
    double l[3] = {3, -3, 6}, ld[3], len, so[3], ndl;
    int k, node;
    if (!intersect(o, d, &h)) {
        if (kind != RTP_RAY_EYE && rtp_builder_miss(b, x, y, parent, kind, NULL) != RTP_OK)
            (*bad)++;
        return;
    }
    for (k = 0; k < 3; k++)
        ld[k] = l[k] - h.p[k];
    len = sqrt(ld[0] * ld[0] + ld[1] * ld[1] + ld[2] * ld[2]);
    ndl = (ld[0] * h.n[0] + ld[1] * h.n[1] + ld[2] * h.n[2]) / len;
    if (ndl > 0) {
        hitinfo sh;
        for (k = 0; k < 3; k++) {
            so[k] = h.p[k] + 1e-6 * h.n[k];
            ld[k] /= len;
        }
        if (!intersect(so, ld, &sh) || sh.t > len)
            lights = 1;
    }
    memset(&rec, 0, sizeof rec);
    for (k = 0; k < 3; k++)
        rec.pos[k] = h.p[k];
    rec.prim = h.prim;
    rec.lights = &lights;
    rec.back = (d[0] * h.n[0] + d[1] * h.n[1] + d[2] * h.n[2]) > 0;
    node = rtp_builder_hit(b, x, y, parent, kind, &rec, NULL);
    if (node < 0) {
        (*bad)++;
        return;
    }
    if (h.prim == 2 && depth < 5) { /* the ball reflects */
        double r[3], dn = d[0] * h.n[0] + d[1] * h.n[1] + d[2] * h.n[2];
        for (k = 0; k < 3; k++) {
            r[k] = d[k] - 2 * dn * h.n[k];
            so[k] = h.p[k] + 1e-6 * h.n[k];
        }
        add_hit(b, x, y, node, RTP_RAY_REFLECTED, so, r, depth + 1, bad);
    }
}

/* A w x h image's samples: its pixels, or with spd its (w+1) x (h+1)
   corners. */
static rtp_tree *build(const rtp_scene *s, int w, int h, int spd)
{
    rtp_builder *b = NULL;
    rtp_tree *t = NULL;
    rtp_error err;
    const double pi = 3.14159265358979323846;
    double from[3] = {0, -6, 2.5}, at[3] = {0, 0, 0.6}, dir[3], right[3], up[3], step, len;
    int x, y, k, bad = 0, iw = w, ih = h;
    w += spd;
    h += spd;
    for (k = 0; k < 3; k++)
        dir[k] = at[k] - from[k];
    len = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    for (k = 0; k < 3; k++)
        dir[k] /= len;
    /* right = dir x (0,0,1), up = right x dir */
    right[0] = dir[1];
    right[1] = -dir[0];
    right[2] = 0;
    len = sqrt(right[0] * right[0] + right[1] * right[1]);
    right[0] /= len;
    right[1] /= len;
    up[0] = right[1] * dir[2] - right[2] * dir[1];
    up[1] = right[2] * dir[0] - right[0] * dir[2];
    up[2] = right[0] * dir[1] - right[1] * dir[0];
    step = 2 * tan(40.0 * pi / 360.0) / (double)((w > h ? w : h) - 1);
    CHECK(rtp_builder_create(s, iw, ih, spd, &b, &err) == RTP_OK);
    for (y = 0; b && y < h; y++)
        for (x = 0; x < w; x++) {
            double sx = (x - 0.5 * (w - 1)) * step, sy = (0.5 * (h - 1) - y) * step, d[3];
            for (k = 0; k < 3; k++)
                d[k] = dir[k] + sx * right[k] + sy * up[k];
            len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (k = 0; k < 3; k++)
                d[k] /= len;
            add_hit(b, x, y, RTP_NO_PARENT, RTP_RAY_EYE, from, d, 1, &bad);
        }
    CHECK(bad == 0);
    CHECK(b && rtp_builder_finish(b, &t, &err) == RTP_OK);
    return t;
}

static void test_builder_matches_trace(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL, *t2 = NULL;
    rtp_image *mine = NULL, *theirs = NULL, *again = NULL;
    rtp_trace_options o;
    rtp_diff_stats d;
    char path[256];
    const char *tmp = getenv("TMPDIR");
    CHECK(rtp_scene_load_memory(scene_text, strlen(scene_text), "b.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    memset(&o, 0, sizeof o);
    t = build(s, 40, 30, 0);
    CHECK(t != NULL);
    if (!t)
        goto out;
    CHECK(rtp_tree_eval(t, NULL, &mine, NULL, NULL) == RTP_OK);
    CHECK(rtp_trace(s, &o, &theirs, NULL, NULL) == RTP_OK);
    CHECK(mine && theirs && rtp_image_diff(mine, theirs, 1e-3, &d, NULL) == RTP_OK);
    /* the two renderers' hit points differ in the last bits only; a
       silhouette pixel may fall either way */
    CHECK_MSG(d.share_above < 0.01, "share above 1e-3: %g", d.share_above);
    CHECK_MSG(d.mae < 1e-3, "mae %g", d.mae);
    rtp_image_destroy(mine);
    rtp_image_destroy(theirs);
    mine = theirs = NULL;
    /* edits on the handed-in trees equal a trace of the edited scene */
    CHECK(rtp_tree_set(t, "mat.ball.color", "0.1,0.9,0.3", NULL) == RTP_OK);
    CHECK(rtp_tree_set(t, "light.key.color", "0.5,0.5,1", NULL) == RTP_OK);
    CHECK(rtp_scene_set(s, "mat.ball.color", "0.1,0.9,0.3", NULL) == RTP_OK);
    CHECK(rtp_scene_set(s, "light.key.color", "0.5,0.5,1", NULL) == RTP_OK);
    CHECK(rtp_tree_eval(t, NULL, &mine, NULL, NULL) == RTP_OK);
    CHECK(rtp_trace(s, &o, &theirs, NULL, NULL) == RTP_OK);
    CHECK(mine && theirs && rtp_image_diff(mine, theirs, 1e-3, &d, NULL) == RTP_OK);
    CHECK(d.share_above < 0.01);
    /* and the tree file keeps them */
    snprintf(path, sizeof path, "%s/rtp-builder.rtp", tmp && *tmp ? tmp : "/tmp");
    CHECK(rtp_tree_write(t, path, NULL, NULL) == RTP_OK);
    CHECK(rtp_tree_read(path, NULL, &t2, NULL) == RTP_OK);
    CHECK(t2 && rtp_tree_eval(t2, NULL, &again, NULL, NULL) == RTP_OK);
    CHECK(again && mine &&
          memcmp(again->pixels, mine->pixels, sizeof(float) * 3 * 40 * 30) == 0);
    remove(path);
out:
    rtp_image_destroy(mine);
    rtp_image_destroy(theirs);
    rtp_image_destroy(again);
    rtp_tree_destroy(t);
    rtp_tree_destroy(t2);
    rtp_scene_destroy(s);
}

/* A tree of corner samples (spd) of a size other than SPD's 512x512:
   rtp_tree_trace, the reference of `reeval --reference`, traces that
   size (it traced the top-left 40x30 of a 512x512 frame, or refused a
   tree wider than 512), and rtp_trace takes spd as on or off. */
static void test_builder_corner_samples(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_image *mine = NULL, *theirs = NULL, *two = NULL, *mine2 = NULL, *big = NULL;
    rtp_trace_options o;
    rtp_diff_stats d;
    rtp_error err;
    CHECK(rtp_scene_load_memory(scene_text, strlen(scene_text), "b.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    t = build(s, 40, 30, 1);
    CHECK(t != NULL);
    CHECK(t && rtp_tree_eval(t, NULL, &mine, NULL, NULL) == RTP_OK);
    CHECK(t && rtp_tree_trace(t, 1, &theirs, NULL, &err) == RTP_OK);
    CHECK(mine && theirs && theirs->width == 40 && theirs->height == 30 &&
          rtp_image_diff(mine, theirs, 1e-3, &d, NULL) == RTP_OK);
    CHECK_MSG(mine && theirs && d.share_above < 0.01 && d.mae < 1e-3,
              "corner samples: share above 1e-3 %g, mae %g", d.share_above, d.mae);
    /* spd = 2 is spd = 1 (it read past the samples) */
    memset(&o, 0, sizeof o);
    o.spd = 1;
    CHECK(rtp_trace(s, &o, &mine2, NULL, &err) == RTP_OK);
    o.spd = 2;
    CHECK(rtp_trace(s, &o, &two, NULL, &err) == RTP_OK);
    CHECK(two && mine2 && two->width == 512 &&
          memcmp(two->pixels, mine2->pixels, sizeof(float) * 3 * 512 * 512) == 0);
    /* a side past the limit is refused */
    o.width = 2147483647;
    o.height = 1;
    o.spd = 0;
    CHECK(rtp_trace(s, &o, &big, NULL, &err) == RTP_ERR_LIMIT && !big);
    rtp_image_destroy(mine);
    rtp_image_destroy(theirs);
    rtp_image_destroy(two);
    rtp_image_destroy(mine2);
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
}

static void test_builder_rejects(void)
{
    rtp_scene *s = NULL;
    rtp_builder *b = NULL;
    rtp_tree *t = NULL;
    rtp_hit_record rec;
    rtp_error err;
    int root;
    CHECK(rtp_scene_load_memory(scene_text, strlen(scene_text), "b.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    memset(&rec, 0, sizeof rec);
    rec.pos[2] = 1.0;
    CHECK(rtp_builder_create(s, 4, 4, 0, &b, &err) == RTP_OK);
    CHECK(rtp_builder_hit(b, 9, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) < 0);
    CHECK(rtp_builder_hit(b, 0, 0, 5, RTP_RAY_REFLECTED, &rec, &err) < 0);
    CHECK(strstr(err.message, "rtp_builder_hit: sample (0, 0): parent 5") != NULL);
    CHECK(rtp_builder_miss(b, 0, 0, 5, RTP_RAY_REFLECTED, &err) == RTP_ERR_ARGUMENT);
    CHECK(strstr(err.message, "rtp_builder_miss: sample (0, 0): parent 5") != NULL);
    rec.prim = 99;
    CHECK(rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) < 0);
    /* (messages name the call and the field: a renderer makes many) */
    CHECK(strstr(err.message, "rtp_builder_hit: hit->prim 99") != NULL);
    rec.prim = 2;
    /* a position past the float range the node keeps */
    rec.pos[0] = 1e39;
    CHECK(rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) < 0);
    CHECK(strstr(err.message, "rtp_builder_hit: hit->pos[0]") != NULL &&
          strstr(err.message, "not finite") != NULL);
    rec.pos[0] = 0.0;
    root = rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err);
    CHECK(root == 0);
    CHECK(rtp_builder_hit(b, 0, 0, root, RTP_RAY_REFLECTED, &rec, &err) == 1);
    CHECK(rtp_builder_miss(b, 0, 0, root, RTP_RAY_REFLECTED, &err) == RTP_OK);
    /* two reflected rays from one node: refused at finish */
    CHECK(rtp_builder_finish(b, &t, &err) == RTP_ERR_ARGUMENT);
    CHECK(t == NULL && strstr(err.message, "rtp_builder_finish: sample (0, 0): node 0 has two reflected") != NULL);
    /* sizes as rtp_trace takes them: not positive is an argument error,
       the largest side rtp_trace traces is taken */
    CHECK(rtp_builder_create(s, 0, 4, 0, &b, &err) == RTP_ERR_ARGUMENT && !b);
    CHECK(rtp_builder_create(s, 1048576, 1, 0, &b, &err) == RTP_OK && b);
    rtp_builder_destroy(b);
    b = NULL;
    CHECK(rtp_builder_create(s, 2147483647, 1, 1, &b, &err) == RTP_ERR_LIMIT && !b);
    rtp_scene_destroy(s);
}

/* One pixel of a mirror plane (ks 0.5) whose renderer cast the mirror ray
   and saw it leave the scene.  The miss is a ray of the second level:
   the tree's depth is 2, so that rtp_tree_trace and a class-D re-trace
   cast it too (they traced one level only, losing the reflected
   background: 0.73 0.49 0.37 against 0.83 0.64 0.57). */
static const char mirror_text[] =
    "v from 0 0 5 at 0 0 0 up 0 1 0 angle 40 hither 0.1 resolution 1 1\n"
    "b 0.2 0.3 0.4\nambient 0.1 0.1 0.1\n"
    "l 0 0 5\n"
    "f 1 0.5 0.25 0.8 0.5 10 0 1\n"
    "p 3 -10 -10 0 10 -10 0 0 10 0\n";

static rtp_tree *mirror_tree(rtp_scene *s, int depth, int expect)
{
    rtp_builder *b = NULL;
    rtp_tree *t = NULL;
    rtp_hit_record rec;
    rtp_error err;
    unsigned char lit = 1;
    int root;
    memset(&rec, 0, sizeof rec);
    rec.lights = &lit;
    CHECK(rtp_builder_create(s, 1, 1, 0, &b, &err) == RTP_OK);
    if (!b)
        return NULL;
    if (depth)
        CHECK(rtp_builder_set_depth(b, depth, &err) == RTP_OK);
    root = rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err);
    CHECK(root == 0);
    CHECK(rtp_builder_miss(b, 0, 0, root, RTP_RAY_REFLECTED, &err) == RTP_OK);
    CHECK(rtp_builder_finish(b, &t, &err) == (rtp_status)expect);
    if (expect != RTP_OK)
        CHECK(t == NULL && strstr(err.message, "deeper than the depth 1 set") != NULL);
    return t;
}

static void pixel_near(const rtp_image *a, const rtp_image *b, double tol)
{
    int c;
    if (!a || !b)
        return;
    for (c = 0; c < 3; c++)
        CHECK_MSG(fabs((double)a->pixels[c] - b->pixels[c]) <= tol, "channel %d: %.9g against %.9g",
                  c, a->pixels[c], b->pixels[c]);
}

static void test_builder_depth(void)
{
    rtp_scene *s = NULL;
    rtp_tree *t, *rec = NULL;
    rtp_image *a = NULL, *b = NULL;
    rtp_tree_info ti;
    rtp_trace_options o;
    rtp_error err;
    CHECK(rtp_scene_load_memory(mirror_text, strlen(mirror_text), "m.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    t = mirror_tree(s, 0, RTP_OK);
    memset(&o, 0, sizeof o);
    CHECK(rtp_record(s, &o, &rec, NULL, NULL, &err) == RTP_OK);
    if (!t || !rec)
        goto out;
    rtp_tree_get_info(t, &ti);
    CHECK(ti.max_depth == 2);
    /* its evaluation is the full trace's, and rtp_tree_trace's */
    CHECK(rtp_tree_eval(t, NULL, &a, NULL, &err) == RTP_OK);
    CHECK(rtp_tree_trace(t, 1, &b, NULL, &err) == RTP_OK);
    pixel_near(a, b, 1e-6);
    /* (by hand: 0.83 0.64 0.57) */
    CHECK_MSG(a && fabs(a->pixels[0] - 0.83) < 0.01, "red %.6g", a ? a->pixels[0] : 0.0f);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    a = b = NULL;
    /* kt raised from 0: the sample is traced again to the tree's depth,
       reflected background included, as the recorded tree does */
    CHECK(rtp_tree_set(t, "mat.0.kt", "0.3", &err) == RTP_OK);
    CHECK(rtp_tree_set(rec, "mat.0.kt", "0.3", &err) == RTP_OK);
    CHECK(rtp_tree_eval(t, NULL, &a, NULL, &err) == RTP_OK);
    CHECK(rtp_tree_eval(rec, NULL, &b, NULL, &err) == RTP_OK);
    pixel_near(a, b, 1e-6);
    rtp_image_destroy(a);
    rtp_image_destroy(b);
    a = b = NULL;
    rtp_tree_destroy(t);
    /* the renderer's own depth where it says: kept, and a ray deeper than
       it refused */
    t = mirror_tree(s, 5, RTP_OK);
    if (t) {
        rtp_tree_get_info(t, &ti);
        CHECK(ti.max_depth == 5);
    }
    rtp_tree_destroy(t);
    t = mirror_tree(s, 1, RTP_ERR_ARGUMENT);
    rtp_tree_destroy(t);
    {
        /* a chain of hits RTP_MAX_DEPTH deep is a tree; a miss below its
           last hit is a ray one level deeper, past what a tree holds */
        rtp_builder *bb = NULL;
        rtp_hit_record hr;
        int k, parent = RTP_NO_PARENT;
        memset(&hr, 0, sizeof hr);
        CHECK(rtp_builder_create(s, 1, 1, 0, &bb, &err) == RTP_OK);
        for (k = 0; bb && k < RTP_MAX_DEPTH; k++)
            parent = rtp_builder_hit(bb, 0, 0, parent,
                                     k ? RTP_RAY_REFLECTED : RTP_RAY_EYE, &hr, &err);
        CHECK(parent == RTP_MAX_DEPTH - 1);
        CHECK(rtp_builder_miss(bb, 0, 0, parent, RTP_RAY_REFRACTED, &err) == RTP_OK);
        t = NULL;
        CHECK(rtp_builder_finish(bb, &t, &err) == RTP_ERR_LIMIT && !t);
    }
    {
        rtp_builder *bb = NULL;
        CHECK(rtp_builder_create(s, 1, 1, 0, &bb, &err) == RTP_OK);
        CHECK(rtp_builder_set_depth(bb, 0, &err) == RTP_ERR_ARGUMENT);
        CHECK(rtp_builder_set_depth(bb, RTP_MAX_DEPTH + 1, &err) == RTP_ERR_ARGUMENT);
        CHECK(rtp_builder_set_depth(NULL, 3, &err) == RTP_ERR_ARGUMENT);
        rtp_builder_destroy(bb);
    }
out:
    rtp_tree_destroy(rec);
    rtp_scene_destroy(s);
}

/* A renderer with a weight cut-off of its own leaves out rays a full
   trace casts: here the mirror's (ks 0.5) reflected ray, with depth 5
   set.  Taken as complete, a ks edit was evaluated from the trees alone
   and was silently not the full trace (0.93 against 1.11); the tree
   keeps a cut-off (min_weight > 0), so the edit traces the sample
   again.  A ray left out at the depth set is no cut-off. */
static void test_builder_cut_off(void)
{
    rtp_scene *s = NULL;
    rtp_builder *b = NULL;
    rtp_tree *t = NULL, *back = NULL;
    rtp_image *a = NULL, *ref = NULL;
    rtp_hit_record rec;
    rtp_tree_info ti;
    rtp_eval_stats st;
    rtp_error err;
    unsigned char lit = 1;
    int depth;
    CHECK(rtp_scene_load_memory(mirror_text, strlen(mirror_text), "m.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    memset(&rec, 0, sizeof rec);
    rec.lights = &lit;
    for (depth = 1; depth <= 5; depth += 4) {
        t = NULL;
        CHECK(rtp_builder_create(s, 1, 1, 0, &b, &err) == RTP_OK);
        if (!b)
            break;
        CHECK(rtp_builder_set_depth(b, depth, &err) == RTP_OK);
        CHECK(rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) == 0);
        CHECK(rtp_builder_finish(b, &t, &err) == RTP_OK);
        if (!t)
            break;
        rtp_tree_get_info(t, &ti);
        CHECK_MSG(depth == 1 ? ti.min_weight == 0.0 : ti.min_weight > 0.0,
                  "depth %d: min_weight %g", depth, ti.min_weight);
        if (depth == 5) {
            /* (the file keeps it) */
            char path[600];
            const char *tmp = getenv("TMPDIR");
            snprintf(path, sizeof path, "%s/rtp-builder-cut.rtp", tmp && *tmp ? tmp : "/tmp");
            CHECK(rtp_tree_write(t, path, NULL, &err) == RTP_OK);
            CHECK(rtp_tree_read(path, NULL, &back, &err) == RTP_OK);
            remove(path);
            if (back) {
                rtp_tree_get_info(back, &ti);
                CHECK(ti.min_weight > 0.0);
            }
            rtp_tree_destroy(back);
            CHECK(rtp_tree_set(t, "mat.0.ks", "0.9", &err) == RTP_OK);
            memset(&st, 0, sizeof st);
            CHECK(rtp_tree_eval(t, NULL, &a, &st, &err) == RTP_OK);
            CHECK(rtp_tree_trace(t, 1, &ref, NULL, &err) == RTP_OK);
            CHECK(st.retraced_samples == 1);
            /* (one pixel traced both ways by one tracer: 1e-6 covers
               float rounding of its sums) */
            pixel_near(a, ref, 1e-6);
            rtp_image_destroy(a);
            rtp_image_destroy(ref);
            a = ref = NULL;
        }
        rtp_tree_destroy(t);
    }
    rtp_scene_destroy(s);
}

/* A scene without a view: refused as rtp_trace refuses it (a tree of it
   was written and then refused by rtp_tree_read); a ray kind that is
   none named as such; an eye ray given both as a miss and as a hit. */
static void test_builder_misuse(void)
{
    rtp_scene *s = NULL;
    rtp_builder *b = NULL;
    rtp_tree *t = NULL;
    rtp_hit_record rec;
    rtp_error err;
    CHECK(rtp_scene_load_memory(mirror_text, strlen(mirror_text), "m.nff", "nff", NULL, &s,
                                NULL) == RTP_OK);
    if (!s)
        return;
    CHECK(rtp_scene_set(s, "camera.at", "0,0,5", &err) == RTP_OK);
    CHECK(rtp_builder_create(s, 1, 1, 0, &b, &err) == RTP_ERR_ARGUMENT && !b);
    CHECK(strstr(err.message, "no view") != NULL);
    CHECK(rtp_scene_set(s, "camera.at", "0,0,0", &err) == RTP_OK);
    CHECK(rtp_builder_create(s, 2, 1, 0, &b, &err) == RTP_OK);
    if (!b)
        goto out;
    memset(&rec, 0, sizeof rec);
    CHECK(rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, (rtp_ray_kind)7, &rec, &err) < 0);
    CHECK(strstr(err.message, "ray kind 7") != NULL);
    CHECK(rtp_builder_miss(b, 1, 0, RTP_NO_PARENT, RTP_RAY_EYE, &err) == RTP_OK);
    CHECK(rtp_builder_hit(b, 1, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) == 0);
    CHECK(rtp_builder_finish(b, &t, &err) == RTP_ERR_ARGUMENT && !t);
    CHECK(strstr(err.message, "sample (1, 0)") != NULL &&
          strstr(err.message, "as a miss and as a hit") != NULL);
    /* total internal reflection and a refracted ray: one or the other
       (it was taken, the refracted subtree used as well) */
    b = NULL;
    CHECK(rtp_builder_create(s, 1, 1, 0, &b, &err) == RTP_OK);
    if (b) {
        rec.total_internal = 1;
        CHECK(rtp_builder_hit(b, 0, 0, RTP_NO_PARENT, RTP_RAY_EYE, &rec, &err) == 0);
        rec.total_internal = 0;
        CHECK(rtp_builder_hit(b, 0, 0, 0, RTP_RAY_REFLECTED, &rec, &err) == 1);
        CHECK(rtp_builder_miss(b, 0, 0, 0, RTP_RAY_REFRACTED, &err) == RTP_OK);
        CHECK(rtp_builder_finish(b, &t, &err) == RTP_ERR_ARGUMENT && !t);
        CHECK(strstr(err.message, "reflects totally") != NULL);
    }
out:
    rtp_scene_destroy(s);
}

int main(void)
{
    RUN(test_builder_matches_trace);
    RUN(test_builder_corner_samples);
    RUN(test_builder_rejects);
    RUN(test_builder_depth);
    RUN(test_builder_misuse);
    RUN(test_builder_cut_off);
    return check_report();
}
