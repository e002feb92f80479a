/* builder.c — ray trees handed in by another renderer: hits are collected
 * per sample in any order, then put in the preorder layout trace records
 * and validated like a tree file, so evaluation, edits and files work the
 * same on them. */
#include "internal.h"

#include <float.h>
#include <limits.h>
#include <stdlib.h>

#define MAX_BUILD_DEPTH RTP_MAX_DEPTH /* as tree files: bounds evaluation recursion */

typedef struct bhit {
    uint32_t sample, prim, vis;
    int32_t parent;
    uint8_t kind, back, tir;
    float p[3];
    size_t ext; /* first visibility word in b->ext (> 32 lights) */
} bhit;

typedef struct bmiss {
    uint32_t sample;
    int32_t parent;
    uint8_t kind;
} bmiss;

struct rtp_builder {
    rtp_allocator alloc;
    rtp_scene *scene;
    int width, height, nx, ny, spd;
    size_t words;         /* visibility words per hit when > 32 lights */
    int max_depth;        /* the renderer's depth (rtp_builder_set_depth), 0: the deepest ray */
    uint32_t *count;      /* hits per sample so far */
    unsigned char *eye_miss; /* per sample: its eye ray was given as a miss */
    bhit *hits;
    size_t nhits, cap_hits;
    bmiss *misses;
    size_t nmisses, cap_misses;
    uint32_t *ext;
    size_t next, cap_ext;
};

void rtp_builder_destroy(rtp_builder *b)
{
    rtp_allocator a;
    if (!b)
        return;
    a = b->alloc;
    rtp_scene_destroy(b->scene);
    rtpi_free(&a, b->count);
    rtpi_free(&a, b->eye_miss);
    rtpi_free(&a, b->hits);
    rtpi_free(&a, b->misses);
    rtpi_free(&a, b->ext);
    rtpi_free(&a, b);
}

rtp_status rtp_builder_create(const rtp_scene *scene, int width, int height, int spd,
                              rtp_builder **out, rtp_error *err)
{
    rtp_builder *b;
    size_t ns;
    if (out)
        *out = NULL;
    if (!scene || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_builder_create: NULL argument");
    if (width <= 0 || height <= 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_builder_create: image size %dx%d: not positive", width, height);
    /* (the samples' grid, as rtp_trace counts it) */
    if (!rtpi_image_size_ok(width, height) ||
        !rtpi_image_size_ok(width + (spd != 0), height + (spd != 0)))
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "rtp_builder_create: image size %dx%d not allowed", width, height);
    /* (a tree keeps its camera: one with no view could be written but
       not read back, nor traced again) */
    if (rtpi_camera_problem(scene))
        return rtpi_camera_error(scene, "rtp_builder_create", "no view to build trees for",
                                 err);
    b = (rtp_builder *)rtpi_calloc_array(&scene->alloc, 1, sizeof *b);
    if (!b)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    b->alloc = scene->alloc;
    b->width = width;
    b->height = height;
    b->spd = spd ? 1 : 0;
    b->nx = width + b->spd;
    b->ny = height + b->spd;
    b->words = scene->nlights > 32 ? (scene->nlights + 31) / 32 : 0;
    ns = (size_t)b->nx * b->ny;
    b->count = (uint32_t *)rtpi_calloc_array(&b->alloc, ns, sizeof *b->count);
    b->eye_miss = (unsigned char *)rtpi_calloc_array(&b->alloc, ns, 1);
    if (!b->count || !b->eye_miss || rtpi_scene_clone(scene, &b->scene) != RTP_OK) {
        rtp_builder_destroy(b);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    *out = b;
    return RTP_OK;
}

rtp_status rtp_builder_set_depth(rtp_builder *b, int max_depth, rtp_error *err)
{
    if (!b)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_builder_set_depth: NULL builder");
    if (max_depth < 1 || max_depth > RTP_MAX_DEPTH)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_builder_set_depth: ray-tree depth %d: not within 1..%d", max_depth,
                          RTP_MAX_DEPTH);
    b->max_depth = max_depth;
    return RTP_OK;
}

/* (fn: the call, named in its messages; a renderer making many calls
   cannot tell them apart otherwise) */
static rtp_status check_link(const char *fn, rtp_builder *b, int x, int y, int parent,
                             rtp_ray_kind kind, uint32_t *sample, rtp_error *err)
{
    if (!b)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: NULL builder", fn);
    if (x < 0 || y < 0 || x >= b->nx || y >= b->ny)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: sample (%d, %d) outside the %dx%d samples", fn, x, y, b->nx,
                          b->ny);
    *sample = (uint32_t)((size_t)y * b->nx + x);
    if ((unsigned)kind > RTP_RAY_REFRACTED)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: ray kind %d: not RTP_RAY_EYE, RTP_RAY_REFLECTED or "
                          "RTP_RAY_REFRACTED",
                          fn, (int)kind);
    if ((kind == RTP_RAY_EYE) != (parent == RTP_NO_PARENT))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: parent %d: an eye ray has no parent (RTP_NO_PARENT); reflected "
                          "and refracted rays have one",
                          fn, parent);
    if (parent != RTP_NO_PARENT && (parent < 0 || (uint32_t)parent >= b->count[*sample]))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: sample (%d, %d): parent %d is not a node of this sample", fn, x,
                          y, parent);
    return RTP_OK;
}

int rtp_builder_hit(rtp_builder *b, int x, int y, int parent, rtp_ray_kind kind,
                    const rtp_hit_record *hit, rtp_error *err)
{
    uint32_t sample = 0; /* (set by check_link where it succeeds; -O3 cannot tell) */
    rtp_status st = check_link("rtp_builder_hit", b, x, y, parent, kind, &sample, err);
    bhit *h;
    size_t i, nl;
    if (st != RTP_OK)
        return -(int)st;
    if (!hit)
        return -(int)rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_builder_hit: NULL hit");
    if (hit->prim >= rtpi_scene_nprims(b->scene))
        return -(int)rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                "rtp_builder_hit: hit->prim %u: no such primitive (the scene "
                                "has %zu)",
                                hit->prim, rtpi_scene_nprims(b->scene));
    /* (kept as floats: a double past the float range would be infinite;
       false for NaN too) */
    for (i = 0; i < 3; i++)
        if (!(fabs(hit->pos[i]) <= FLT_MAX)) {
            char g[32]; /* (with '.' whatever the locale) */
            rtpi_fmt_g(g, sizeof g, 6, hit->pos[i]);
            return -(int)rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                    "rtp_builder_hit: hit->pos[%zu] %s: not finite as a float",
                                    i, g);
        }
    if (b->count[sample] >= RTPI_MAX_SUBTREE)
        return -(int)rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                                "rtp_builder_hit: sample (%d, %d): more than %u hits", x, y,
                                RTPI_MAX_SUBTREE);
    nl = b->scene->nlights;
    if (rtpi_grow(&b->alloc, (void **)&b->hits, &b->cap_hits, b->nhits + 1, sizeof *b->hits) ||
        (b->words && rtpi_grow(&b->alloc, (void **)&b->ext, &b->cap_ext, b->next + b->words,
                               sizeof *b->ext)))
        return -(int)rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    h = &b->hits[b->nhits++];
    memset(h, 0, sizeof *h);
    h->sample = sample;
    h->parent = parent;
    h->kind = (uint8_t)kind;
    h->back = hit->back != 0;
    h->tir = hit->total_internal != 0;
    h->prim = hit->prim;
    for (i = 0; i < 3; i++)
        h->p[i] = (float)hit->pos[i];
    h->ext = b->next;
    if (b->words) {
        memset(b->ext + b->next, 0, b->words * sizeof *b->ext);
        b->next += b->words;
    }
    for (i = 0; hit->lights && i < nl; i++) {
        if (!((hit->lights[i >> 3] >> (i & 7)) & 1u))
            continue;
        if (b->words)
            b->ext[h->ext + (i >> 5)] |= 1u << (i & 31);
        else
            h->vis |= 1u << i;
    }
    return (int)b->count[sample]++;
}

rtp_status rtp_builder_miss(rtp_builder *b, int x, int y, int parent, rtp_ray_kind kind,
                            rtp_error *err)
{
    uint32_t sample = 0; /* (set by check_link where it succeeds; -O3 cannot tell) */
    rtp_status st = check_link("rtp_builder_miss", b, x, y, parent, kind, &sample, err);
    bmiss *m;
    if (st != RTP_OK)
        return st;
    if (kind == RTP_RAY_EYE) {
        /* no hit at all: the sample shows the background (an eye hit
           given too contradicts it: finish says so) */
        b->eye_miss[sample] = 1;
        return RTP_OK;
    }
    if (rtpi_grow(&b->alloc, (void **)&b->misses, &b->cap_misses, b->nmisses + 1,
                  sizeof *b->misses))
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    m = &b->misses[b->nmisses++];
    m->sample = sample;
    m->parent = parent;
    m->kind = (uint8_t)kind;
    return RTP_OK;
}

/* Per sample, during finish. */
typedef struct emit {
    const bhit *const *h;  /* the sample's hits in insertion order */
    int32_t *refl, *refr;  /* child local index, -1 none, -2 miss */
    rtpi_cnode *out;
    uint32_t *out_ext;
    const uint32_t *ext;
    size_t words, n;
    int depth;
    const rtp_scene *s;
    int cut;               /* the shallowest hit missing a ray (INT_MAX: none) */
} emit;

static size_t emit_node(emit *e, int32_t i, int depth, size_t at)
{
    const bhit *h = e->h[i];
    rtpi_cnode *nd = &e->out[at];
    size_t end = at + 1;
    uint32_t link = (h->back ? RTPI_L_BACK : 0u) | (h->tir ? RTPI_L_TIR : 0u);
    if (depth > e->depth)
        e->depth = depth;
    memcpy(nd->p, h->p, sizeof nd->p);
    nd->prim = h->prim;
    nd->vis = h->vis;
    if (e->words)
        memcpy(e->out_ext + at * e->words, e->ext + h->ext, e->words * sizeof *e->ext);
    if (e->refl[i] >= 0) {
        link |= RTPI_L_REFL;
        end = emit_node(e, e->refl[i], depth + 1, end);
    } else if (e->refl[i] == -2) {
        link |= RTPI_L_REFL_MISS;
        /* (a miss is a ray of the next level: a re-trace or a full
           trace of the tree must cast it too) */
        if (depth + 1 > e->depth)
            e->depth = depth + 1;
    }
    if (e->refr[i] >= 0) {
        link |= RTPI_L_REFR | (uint32_t)(end - at) << RTPI_L_SHIFT;
        end = emit_node(e, e->refr[i], depth + 1, end);
    } else if (e->refr[i] == -2) {
        link |= RTPI_L_REFR_MISS;
        if (depth + 1 > e->depth)
            e->depth = depth + 1;
    }
    e->out[at].link = link;
    {
        /* The rays a trace without a weight cut-off casts here (trace.c):
           reflected where ks > 0 (or kt > 0 reflected totally), refracted
           where kt > 0.  One missing is the renderer's own cut-off; the
           tree's depth, known at the end, says whether it was above it. */
        const rtpi_material *m = &e->s->mats[rtpi_prim_material(e->s, h->prim)];
        if ((((m->ks > 0.0f || (h->tir && m->kt > 0.0f)) && e->refl[i] == -1) ||
             (m->kt > 0.0f && !h->tir && e->refr[i] == -1)) &&
            depth < e->cut)
            e->cut = depth;
    }
    return end;
}

/* Does node i's subtree (i at `depth`) stay within `limit` levels,
   counting a miss as a ray of the next level? */
static int depth_ok(const emit *e, int32_t i, int depth, int limit)
{
    if (depth > limit)
        return 0;
    return (e->refl[i] == -1 || (e->refl[i] == -2 ? depth < limit
                                                   : depth_ok(e, e->refl[i], depth + 1, limit))) &&
           (e->refr[i] == -1 || (e->refr[i] == -2 ? depth < limit
                                                   : depth_ok(e, e->refr[i], depth + 1, limit)));
}

rtp_status rtp_builder_finish(rtp_builder *b, rtp_tree **out, rtp_error *err)
{
    rtp_tree *t = NULL;
    const rtp_allocator *a;
    size_t ns, k, i, maxn = 0;
    const bhit **order = NULL;
    uint64_t *first = NULL;
    int32_t *refl = NULL, *refr = NULL;
    rtp_status st = RTP_OK;
    emit e;
    if (out)
        *out = NULL;
    if (!b || !out) {
        rtp_builder_destroy(b);
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_builder_finish: NULL argument");
    }
    *out = NULL;
    a = &b->alloc;
    ns = (size_t)b->nx * b->ny;
    t = (rtp_tree *)rtpi_calloc_array(a, 1, sizeof *t);
    if (t) /* (before anything can fail: rtp_tree_destroy frees by it) */
        t->alloc = *a;
    first = (uint64_t *)rtpi_malloc_array(a, ns + 1, sizeof *first);
    order = (const bhit **)rtpi_malloc_array(a, b->nhits + 1, sizeof *order);
    if (!t || !first || !order)
        goto nomem;
    /* hits grouped by sample, insertion order kept (local indices) */
    first[0] = 0;
    for (k = 0; k < ns; k++) {
        first[k + 1] = first[k] + b->count[k];
        if (b->count[k] > maxn)
            maxn = b->count[k];
    }
    {
        uint64_t *fill = (uint64_t *)rtpi_malloc_array(a, ns + 1, sizeof *fill);
        if (!fill)
            goto nomem;
        memcpy(fill, first, (ns + 1) * sizeof *fill);
        for (i = 0; i < b->nhits; i++)
            order[fill[b->hits[i].sample]++] = &b->hits[i];
        rtpi_free(a, fill);
    }
    refl = (int32_t *)rtpi_malloc_array(a, maxn + 1, sizeof *refl);
    refr = (int32_t *)rtpi_malloc_array(a, maxn + 1, sizeof *refr);
    t->nodes = (rtpi_cnode *)rtpi_malloc_array(a, b->nhits + 1, sizeof *t->nodes);
    t->start = (uint64_t *)rtpi_malloc_array(a, ns + 1, sizeof *t->start);
    if (b->words)
        t->vis_ext = (uint32_t *)rtpi_malloc_array(a, b->nhits * b->words + 1, sizeof *t->vis_ext);
    if (!refl || !refr || !t->nodes || !t->start || (b->words && !t->vis_ext))
        goto nomem;
    memset(&e, 0, sizeof e);
    e.s = b->scene;
    e.cut = INT_MAX;
    e.refl = refl;
    e.refr = refr;
    e.out = t->nodes;
    e.out_ext = t->vis_ext;
    e.ext = b->ext;
    e.words = b->words;
    /* misses, sorted by sample too: one pass per sample over a sorted copy */
    {
        size_t *mfirst = (size_t *)rtpi_calloc_array(a, ns + 1, sizeof *mfirst);
        const bmiss **morder = (const bmiss **)rtpi_malloc_array(a, b->nmisses + 1, sizeof *morder);
        if (!mfirst || !morder) {
            rtpi_free(a, mfirst);
            rtpi_free(a, morder);
            goto nomem;
        }
        for (i = 0; i < b->nmisses; i++)
            mfirst[b->misses[i].sample + 1]++;
        for (k = 0; k < ns; k++)
            mfirst[k + 1] += mfirst[k];
        for (i = 0; i < b->nmisses; i++)
            morder[mfirst[b->misses[i].sample]++] = &b->misses[i];
        for (k = ns; k > 0; k--)
            mfirst[k] = mfirst[k - 1];
        mfirst[0] = 0;
        for (k = 0; k < ns && st == RTP_OK; k++) {
            size_t n = b->count[k], roots = 0, m;
            int32_t root = -1;
            const int sx = (int)(k % (size_t)b->nx), sy = (int)(k / (size_t)b->nx);
            e.h = order + first[k];
            e.n = n;
            for (i = 0; i < n; i++)
                refl[i] = refr[i] = -1;
            for (i = 0; i < n && st == RTP_OK; i++) {
                const bhit *h = e.h[i];
                int32_t *slot;
                if (h->parent == RTP_NO_PARENT) {
                    roots++;
                    root = (int32_t)i;
                    continue;
                }
                slot = h->kind == RTP_RAY_REFLECTED ? &refl[h->parent] : &refr[h->parent];
                if (*slot != -1)
                    st = rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                    "rtp_builder_finish: sample (%d, %d): node %d has two %s rays",
                                    sx, sy, (int)h->parent,
                                    h->kind == RTP_RAY_REFLECTED ? "reflected" : "refracted");
                *slot = (int32_t)i;
            }
            for (m = mfirst[k]; m < mfirst[k + 1] && st == RTP_OK; m++) {
                const bmiss *ms = morder[m];
                int32_t *slot =
                    ms->kind == RTP_RAY_REFLECTED ? &refl[ms->parent] : &refr[ms->parent];
                if (*slot != -1)
                    st = rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                    "rtp_builder_finish: sample (%d, %d): node %d has two %s rays",
                                    sx, sy, (int)ms->parent,
                                    ms->kind == RTP_RAY_REFLECTED ? "reflected" : "refracted");
                *slot = -2;
            }
            /* (total internal reflection sends no ray through: its
               transmitted share follows the reflected ray) */
            for (i = 0; i < n && st == RTP_OK; i++)
                if (e.h[i]->tir && refr[i] != -1)
                    st = rtpi_error(
                        err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                        "rtp_builder_finish: sample (%d, %d): node %d reflects totally and has a "
                        "refracted ray",
                        sx, sy, (int)i);
            if (st == RTP_OK && n && roots != 1)
                st = rtpi_error(
                    err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                    "rtp_builder_finish: sample (%d, %d): %zu eye-ray hits (one expected)", sx, sy,
                    roots);
            if (st == RTP_OK && roots && b->eye_miss[k])
                st = rtpi_error(
                    err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                    "rtp_builder_finish: sample (%d, %d): its eye ray given as a miss and as a hit",
                    sx, sy);
            if (st == RTP_OK && n && !depth_ok(&e, root, 1, MAX_BUILD_DEPTH))
                st = rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                                "rtp_builder_finish: sample (%d, %d): tree deeper than %d (a miss "
                                "counts as a ray "
                                "of the next level)",
                                sx, sy, MAX_BUILD_DEPTH);
            if (st == RTP_OK && n && b->max_depth && !depth_ok(&e, root, 1, b->max_depth))
                st = rtpi_error(
                    err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                    "rtp_builder_finish: sample (%d, %d): rays deeper than the depth %d set "
                    "(rtp_builder_set_depth)",
                    sx, sy, b->max_depth);
            t->start[k] = first[k];
            if (st == RTP_OK && n && emit_node(&e, root, 1, (size_t)first[k]) != first[k] + n)
                st = rtpi_error(
                    err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                    "rtp_builder_finish: sample (%d, %d): hits not connected to the eye ray", sx,
                    sy);
        }
        t->start[ns] = first[ns];
        rtpi_free(a, mfirst);
        rtpi_free(a, morder);
    }
    if (st != RTP_OK)
        goto fail;
    t->nnodes = b->nhits;
    t->vis_words = b->words;
    t->width = b->width;
    t->height = b->height;
    t->full_w = b->width;
    t->full_h = b->height;
    t->nx = b->nx;
    t->ny = b->ny;
    t->spd = b->spd;
    t->foreign = 1; /* (the renderer's hits: re-traces trace whole samples) */
    /* the renderer's depth where it said, else the deepest ray handed in
       (misses too): re-traces and rtp_tree_trace go as deep */
    t->max_depth = b->max_depth ? b->max_depth : e.depth > 0 ? e.depth : 1;
    /* A ray left out above the depth: the renderer cut its trees (a weight
       cut-off of its own).  Kept as a cut-off, the smallest there is, so
       that ks and kt edits trace the material's samples again, as for
       rtp_trace's min_weight: the trees cannot tell what the left-out rays
       would carry, and taken as complete such an edit was silently not
       the full trace (a mirror of ks 0.5 with no reflected ray, ks 0.9:
       0.93 against 1.11). */
    t->min_weight = e.cut < t->max_depth ? DBL_MIN : 0.0;
    t->scene = b->scene;
    b->scene = NULL;
    t->nlights0 = t->scene->nlights;
    t->cam0 = t->scene->camera;
    t->mats0 = (rtpi_material *)rtpi_malloc_array(a, t->scene->nmats + 1, sizeof *t->mats0);
    t->lights0 = (rtpi_light *)rtpi_malloc_array(a, t->scene->nlights + 1, sizeof *t->lights0);
    if (!t->mats0 || !t->lights0)
        goto nomem;
    if (t->scene->nmats)
        memcpy(t->mats0, t->scene->mats, t->scene->nmats * sizeof *t->mats0);
    if (t->scene->nlights)
        memcpy(t->lights0, t->scene->lights, t->scene->nlights * sizeof *t->lights0);
    for (i = 0; i < t->scene->nmats; i++)
        t->mats0[i].name = NULL;
    for (i = 0; i < t->scene->nlights; i++)
        t->lights0[i].name = NULL;
    rtpi_free(a, first);
    rtpi_free(a, order);
    rtpi_free(a, refl);
    rtpi_free(a, refr);
    rtp_builder_destroy(b);
    *out = t;
    return RTP_OK;
nomem:
    st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
fail:
    rtpi_free(a, first);
    rtpi_free(a, order);
    rtpi_free(a, refl);
    rtpi_free(a, refr);
    rtp_builder_destroy(b);
    rtp_tree_destroy(t);
    return st;
}
