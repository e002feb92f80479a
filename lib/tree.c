/* tree.c — a traced image's ray trees: editing parameters (with the checks
 * that keep re-evaluation exact) and evaluation with the one shading
 * routine. */
#include "internal.h"
#include "shadow.h"
#include "dircube.h"

#include <float.h>
/* (SSE2, which every x86-64 has: pk_img_row's vectors; elsewhere its
   scalar code, the same operations) */
#if defined(__SSE2__) && !defined(RTP_NO_SSE2)
#include <emmintrin.h>
#define PK_SSE2 1
#endif
#include <time.h>

static void cp_free(rtp_tree *t);

void rtp_tree_destroy(rtp_tree *t)
{
    rtp_allocator a;
    size_t i;
    if (!t)
        return;
    a = t->alloc;
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++)
        rtpi_free(&a, t->blocks[i].p);
    rtp_scene_destroy(t->scene);
    rtpi_free(&a, t->mats0);
    rtpi_free(&a, t->lights0);
    rtpi_free(&a, t->nodes);
    rtpi_free(&a, t->start);
    rtpi_free(&a, t->vis_ext);
    rtpi_kd_destroy(t->kd);
    rtpi_free(&a, t->cur_vis);
    rtpi_free(&a, t->cur_pos);
    rtpi_free(&a, t->ball_in);
    rtpi_free(&a, t->ball_sph);
    rtpi_free(&a, t->prim_nrm);
    rtpi_free(&a, t->cone_own);
    rtpi_free(&a, t->kd_from);
    rtpi_free(&a, t->kd_from_kt);
    rtpi_free(&a, t->vrec);
    rtpi_free(&a, t->vrec_mat);
    rtpi_free(&a, t->tri_nrm);
    rtpi_free(&a, t->ev_terms);
    rtpi_free(&a, t->ev_coeffs);
    rtpi_free(&a, t->ev_nv);
    rtpi_free(&a, t->ev_w);
    rtpi_free(&a, t->ev_mark);
    rtpi_free(&a, t->mv_rest);
    rtpi_free(&a, t->mv_ok);
    rtpi_free(&a, t->mv_kc);
    rtpi_free(&a, t->mv_kc_mats);
    rtpi_free(&a, t->ev_samples);
    rtpi_free(&a, t->ev_cl);
    rtpi_free(&a, t->pk);
    rtpi_free(&a, t->pk_q);
    rtpi_free(&a, t->pk_nz); /* (pk_c lies in its block) */
    rtpi_free(&a, t->pk_seg);
    rtpi_free(&a, t->pk_off);
    cp_free(t);
    rtpi_free(&a, t->mat_uv);
    rtpi_free(&a, t->hl_idx);
    rtpi_free(&a, t->hl_lrv);
    rtpi_free(&a, t->hl_w);
    rtpi_free(&a, t->hl_off);
    rtpi_free(&a, t->hl_p);
    rtpi_free(&a, t->ev_pos);
    rtpi_free(&a, t->ev_mats);
    rtpi_free(&a, t->mat_start);
    rtpi_free(&a, t->mat_samples);
    rtpi_free(&a, t->mat_nstart);
    rtpi_free(&a, t->mat_nodes);
    rtpi_free(&a, t);
}

void rtp_tree_get_info(const rtp_tree *t, rtp_tree_info *info)
{
    if (!info)
        return; /* (as rtp_scene_get_info) */
    memset(info, 0, sizeof *info);
    if (!t)
        return;
    info->width = t->width;
    info->height = t->height;
    info->full_width = t->full_w;
    info->full_height = t->full_h;
    info->region_x = t->rx;
    info->region_y = t->ry;
    info->spd = t->spd;
    info->max_depth = t->max_depth;
    info->samples = (unsigned long long)t->nx * (unsigned long long)t->ny;
    info->nodes = t->nnodes;
    info->bytes_per_node = (unsigned)sizeof(rtpi_cnode);
    info->tree_bytes = (unsigned long long)t->nnodes *
                           (sizeof(rtpi_cnode) + 4 * t->vis_words) +
                       (info->samples + 1) * sizeof *t->start;
    info->lights = t->scene->nlights;
    info->materials = t->scene->nmats;
    info->triangles = t->scene->ntris;
    info->spheres = t->scene->nspheres;
    info->cones = t->scene->ncones;
    info->min_weight = t->min_weight;
}

/* ---------------------------------------------------------------- edits */

/* Checks an edited value the trees cannot take at all. */
static rtp_status check_exact(const rtp_tree *t, const char *key,
                              const char *value, rtp_error *err)
{
    const rtp_scene *s = t->scene;
    size_t i;
    for (i = 0; i < s->nlights; i++) {
        const rtpi_light *l = &s->lights[i];
        if (!isfinite(l->pos[0]) || !isfinite(l->pos[1]) || !isfinite(l->pos[2]))
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              "%s=%s: light position must be finite", key, value);
    }
    (void)t;
    return RTP_OK;
}

/* (the image index only where an image is the bump map, strength and
   scale only where there is one: what a tree file keeps of them) */
static int bump_changed(const rtpi_material *a, const rtpi_material *b)
{
    if (a->bump != b->bump)
        return 1;
    if (a->bump == RTPI_BUMP_NONE)
        return 0;
    return (a->bump == RTPI_BUMP_IMAGE && a->bump_image != b->bump_image) ||
           a->bump_strength != b->bump_strength || a->bump_scale != b->bump_scale;
}

/* Does material a (material m of the tree's scene) bend normals at all?
   Not with strength 0, nor an image on primitives without uvs
   (rtpi_bump_normal leaves those alone). */
static int bump_bends(rtp_tree *t, size_t m, const rtpi_material *a)
{
    const rtp_scene *s = t->scene;
    if (a->bump == RTPI_BUMP_NONE || a->bump_strength == 0.0f)
        return 0;
    if (a->bump != RTPI_BUMP_IMAGE)
        return 1;
    if (a->bump_image >= s->ntexs || !s->texs[a->bump_image].image || a->bump_scale == 0.0f)
        return 0; /* (an image's heights are scaled by bump_scale too) */
    if (!t->mat_uv) {
        size_t i;
        t->mat_uv = (unsigned char *)rtpi_calloc_array(&t->alloc, s->nmats + 1, 1);
        if (!t->mat_uv)
            return 1; /* (cannot tell: as if it did) */
        for (i = 0; i < s->ntris; i++) {
            const rtpi_tri *tr = &s->tris[i];
            if (tr->t[0] != RTPI_NONE && tr->t[1] != RTPI_NONE && tr->t[2] != RTPI_NONE &&
                tr->mat < s->nmats)
                t->mat_uv[tr->mat] = 1;
        }
        for (i = 0; i < s->nspheres; i++)
            if (s->spheres[i].mat < s->nmats)
                t->mat_uv[s->spheres[i].mat] = 1;
        for (i = 0; i < s->ncones; i++)
            if (s->cones[i].mat < s->nmats)
                t->mat_uv[s->cones[i].mat] = 1;
    }
    return t->mat_uv[m];
}

/* Has material m's bump changed since its subtrees were traced in a way
   that bends their rays (bump_changed, and one of the two bends)? */
static int bump_stale(rtp_tree *t, size_t m)
{
    const rtpi_material *a = &t->scene->mats[m], *a0 = &t->mats0[m];
    return bump_changed(a, a0) && (bump_bends(t, m, a) || bump_bends(t, m, a0));
}

/* Must material m's samples be traced again before the trees can show it
   exactly (edit class D)?  Rays the trace did not cast — reflected where
   ks was 0, refracted where kt was 0 or below the weight cut-off — or cast
   elsewhere — refracted with another ior, one-sidedness in SPD mode.
   With a weight cut-off any ks or kt edit: raised, rays below it may now
   be cast; lowered, rays the trees hold may now fall below it, and a full
   trace would not cast them (their subtrees were kept and counted). */
/* Traced to depth 1 (eye rays alone), no reflected or refracted ray is
   cast whatever ks, kt, ior or bump: the trees are what any of them
   traces (SPD's depth is 5; its one-sidedness by kt is not so). */
static int eye_rays_alone(const rtp_tree *t)
{
    return t->max_depth <= 1 && !t->spd;
}

static int needs_retrace(rtp_tree *t, size_t m, int stale_retrace)
{
    const rtpi_material *a = &t->scene->mats[m], *a0 = &t->mats0[m];
    /* (nothing to trace: eye_rays_alone) */
    if (eye_rays_alone(t))
        return 0;
    /* a new bump bends the reflected and refracted rays below it: those
       subtrees are stale; kept (the paper's way) unless asked otherwise */
    if (stale_retrace && (a0->ks > 0.0f || a0->kt > 0.0f) && bump_stale(t, m))
        return 1;
    return (a->ks > 0.0f && a0->ks == 0.0f) || (a->kt > 0.0f && a0->kt == 0.0f) ||
           (a0->kt > 0.0f && a->kt > 0.0f && a->ior != a0->ior) ||
           (t->spd && a0->kt > 0.0f && a->kt == 0.0f) ||
           (t->min_weight > 0.0 && (a->ks != a0->ks || a->kt != a0->kt));
}

/* Does a sample (its n nodes) hold a reflected or refracted ray below a
   material whose bump is stale (count_stale)? */
static int sample_stale(rtp_tree *t, const rtpi_cnode *nd, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++, nd++) {
        /* (a ray that left the scene is as stale: bent, it may hit) */
        if ((nd->link & (RTPI_L_REFL | RTPI_L_REFL_MISS | RTPI_L_REFR | RTPI_L_REFR_MISS |
                         RTPI_L_TIR)) &&
            bump_stale(t, rtpi_prim_material(t->scene, nd->prim)))
            return 1;
    }
    return 0;
}

/* Any material whose bump is stale below rays the samples may hold? */
static int any_stale(rtp_tree *t)
{
    size_t m;
    int any = 0;
    for (m = 0; m < t->scene->nmats; m++)
        any |= (t->mats0[m].ks > 0.0f || t->mats0[m].kt > 0.0f) && bump_stale(t, m);
    return any;
}

/* Samples holding a reflected or refracted ray (a subtree, or a ray that
   left the scene) below a material whose bump map changed since its
   samples were traced, kept there (--stale keep: the paper's way,
   approximate): stats->stale_samples, so the approximation is said, not
   silent.  Counted once after a bump key or a re-trace (t->stale_ok). */
static unsigned long long count_stale(rtp_tree *t)
{
    size_t k, ns = (size_t)t->nx * t->ny;
    unsigned long long n = 0;
    if (!any_stale(t))
        return 0;
    if (t->stale_ok)
        return t->stale_n;
    for (k = 0; k < ns; k++)
        n += sample_stale(t, t->nodes + t->start[k], (size_t)(t->start[k + 1] - t->start[k]));
    t->stale_n = n;
    t->stale_ok = 1;
    return n;
}

const rtp_scene *rtp_tree_scene(const rtp_tree *t)
{
    return t ? t->scene : NULL;
}

rtp_status rtpi_tree_busy(const rtp_tree *t, const char *fn, rtp_error *err)
{
    if (!t->busy)
        return RTP_OK;
    if (t->busy == RTPI_TREE_SUMMARY)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: the tree was read by rtp_tree_read_summary, which keeps no "
                          "ray trees: read the file with rtp_tree_read to evaluate, trace, "
                          "write, merge or crop it", fn);
    if (t->busy == 2)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: the tree rtp_tree_eval_file's edit callback is given has "
                          "no ray trees yet: only rtp_tree_set and rtp_tree_add_light may "
                          "be called on it there", fn);
    if (t->busy == RTPI_TREE_TRACING)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: the tree's scene is being traced (called from rtp_tree_trace's "
                          "progress or cancel callback): call it after rtp_tree_trace returns",
                          fn);
    return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                      "%s: the tree is being evaluated (called from the evaluation's "
                      "progress or cancel callback): call it after rtp_tree_eval returns",
                      fn);
}

/* The scene's last light was just added (rtp_tree_add_light, or a
   light.N.pos key naming the next light): its lights0 entry, never traced
   (pos NaN), so its visibility is always decided anew.  0, or -1 out of
   memory (the caller takes the light away again). */
static int added_light(rtp_tree *t)
{
    size_t n = t->scene->nlights, cap = n - 1;
    if (rtpi_grow(&t->alloc, (void **)&t->lights0, &cap, n, sizeof *t->lights0))
        return -1;
    t->lights0[n - 1] = t->scene->lights[n - 1];
    t->lights0[n - 1].pos[0] = NAN;
    return 0;
}

rtp_status rtp_tree_set(rtp_tree *t, const char *key, const char *value,
                        rtp_error *err)
{
    rtp_scene *s;
    rtpi_material *mats = NULL;
    rtpi_light *lights = NULL;
    float amb[3], bg[3];
    size_t nl;
    rtp_status st;
    if (!t || !key || !value)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_set: NULL argument");
    /* (an edit callback's tree, busy 2, takes edits: rtp_tree_eval_file;
       so does a summary's, which has no trees to make stale) */
    if ((t->busy == 1 || t->busy == RTPI_TREE_TRACING) &&
        (st = rtpi_tree_busy(t, "rtp_tree_set", err)) != RTP_OK)
        return st;
    s = t->scene;
    /* Keep the parameters so a refused edit leaves the tree unchanged. */
    mats = (rtpi_material *)rtpi_malloc_array(&t->alloc, s->nmats ? s->nmats : 1, sizeof *mats);
    lights = (rtpi_light *)rtpi_malloc_array(&t->alloc, s->nlights ? s->nlights : 1,
                                             sizeof *lights);
    if (!mats || !lights) {
        rtpi_free(&t->alloc, mats);
        rtpi_free(&t->alloc, lights);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    if (s->nmats) /* (memcpy from NULL is undefined even for 0 bytes) */
        memcpy(mats, s->mats, s->nmats * sizeof *mats);
    if (s->nlights)
        memcpy(lights, s->lights, s->nlights * sizeof *lights);
    memcpy(amb, s->ambient, sizeof amb);
    memcpy(bg, s->background, sizeof bg);
    nl = s->nlights;
    st = rtpi_scene_set(s, key, value, err);
    if (st == RTP_OK && s->nlights > nl && added_light(t) != 0)
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "%s: out of memory", key);
    if (st == RTP_OK)
        st = check_exact(t, key, value, err);
    if (strstr(key, ".bump"))
        t->stale_ok = 0;
    if (st != RTP_OK) {
        /* names are untouched by rtp_scene_set: the copies' pointers are
           the scene's own; a light the key added goes */
        s->nlights = nl;
        if (s->nmats)
            memcpy(s->mats, mats, s->nmats * sizeof *mats);
        if (s->nlights)
            memcpy(s->lights, lights, s->nlights * sizeof *lights);
        memcpy(s->ambient, amb, sizeof amb);
        memcpy(s->background, bg, sizeof bg);
    }
    rtpi_free(&t->alloc, mats);
    rtpi_free(&t->alloc, lights);
    if (strstr(key, ".texture") || strstr(key, ".bump"))
        rtpi_scene_drop_textures(s, t->mats0);
    return st;
}

/* ------------------------------------------------------ moved lights */

/* The direction cube of a moved light takes tens of megabytes; the next
   move needs as much again.  Blocks of a megabyte or more are kept for
   reuse (best fit, at most twice the size asked), so a sequence of moves
   touches warm memory instead of faulting fresh pages in. */
#define BLOCK_MIN (1u << 20)

static void *blk_malloc(void *user, size_t size)
{
    rtp_tree *t = (rtp_tree *)user;
    size_t i, best = (size_t)-1;
    void *p;
    if (size < BLOCK_MIN)
        return rtpi_malloc(&t->alloc, size);
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++) {
        const struct rtpi_block *b = &t->blocks[i];
        if (b->p && !b->live && b->n >= size && b->n / 2 <= size &&
            (best == (size_t)-1 || b->n < t->blocks[best].n))
            best = i;
    }
    if (best != (size_t)-1) {
        t->blocks[best].live = 1;
        return t->blocks[best].p;
    }
    /* A miss gives one idle block back first: the one too small for this
       size (the largest such), else the largest too big for it.  Without
       it the slots filled with idle blocks of sizes gone by (a light
       buffer's lists change size with the light): 600 moves of gears
       kept 80 MB idle where one move takes 8, past --memory-limit. */
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++) {
        const struct rtpi_block *b = &t->blocks[i];
        int small, best_small;
        if (!b->p || b->live)
            continue;
        if (best == (size_t)-1) {
            best = i;
            continue;
        }
        small = b->n < size;
        best_small = t->blocks[best].n < size;
        if (small != best_small ? small : b->n > t->blocks[best].n)
            best = i;
    }
    if (best != (size_t)-1) {
        rtpi_free(&t->alloc, t->blocks[best].p);
        t->blocks[best].p = NULL;
    }
    p = rtpi_malloc(&t->alloc, size);
    if (!p)
        return NULL;
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++)
        if (!t->blocks[i].p) {
            t->blocks[i].p = p;
            t->blocks[i].n = size;
            t->blocks[i].live = 1;
            break;
        }
    return p; /* untracked when every slot is taken: freed as usual */
}

static void blk_free(void *user, void *p)
{
    rtp_tree *t = (rtp_tree *)user;
    size_t i;
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++)
        if (t->blocks[i].p == p) {
            t->blocks[i].live = 0;
            return;
        }
    rtpi_free(&t->alloc, p);
}

static void *blk_realloc(void *user, void *p, size_t size)
{
    rtp_tree *t = (rtp_tree *)user;
    size_t i;
    void *q;
    for (i = 0; i < sizeof t->blocks / sizeof *t->blocks; i++)
        if (p && t->blocks[i].p == p) {
            if (size <= t->blocks[i].n)
                return p;
            q = rtpi_realloc(&t->alloc, p, size);
            if (q) {
                t->blocks[i].p = q;
                t->blocks[i].n = size;
            }
            return q;
        }
    return rtpi_realloc(&t->alloc, p, size);
}

rtp_status rtp_tree_add_light(rtp_tree *t, const double pos[3], rtp_error *err)
{
    rtp_scene *s;
    if (!t || !pos)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_add_light: NULL argument");
    if (t->busy == 1 || t->busy == RTPI_TREE_TRACING)
        return rtpi_tree_busy(t, "rtp_tree_add_light", err);
    /* the range a key's value has (rtp_scene_set), so that the position
       rtp_scene_get gives back can be set again */
    if (!(fabs(pos[0]) <= 3.4e38 && fabs(pos[1]) <= 3.4e38 && fabs(pos[2]) <= 3.4e38))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "light position must be finite, |x| <= 3.4e38");
    s = t->scene;
    if (rtpi_scene_add_white_light(s, pos) < 0)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    if (added_light(t) != 0) {
        s->nlights--;
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    return RTP_OK;
}

static int light_at(const rtp_tree *t, size_t i, const double *pos)
{
    const double *p = t->scene->lights[i].pos;
    return p[0] == pos[0] && p[1] == pos[1] && p[2] == pos[2];
}

/* Has light i left the position it was traced at (or was it added)? */
static int light_moved(const rtp_tree *t, size_t i)
{
    return i >= t->nlights0 || !light_at(t, i, t->lights0[i].pos);
}

/* rtpi_parallel_rows for the tree's work: evaluating a sample recurses
   a level a ray of its tree (rtpi_sample_eval and the others: up to
   ~0.6 KiB a level), so the rows of a tree deeper than a host's thread
   can be counted on to hold run on threads of rtp's own
   (rtpi_trace_stack; a 1000-level tree's evaluation overflowed a
   thread of 128 KiB). */
static int tree_rows(const rtp_tree *t, int nrows, int nthreads, void *const *ctx,
                     rtpi_row_fn fn, void (*progress)(void *, double), void *progress_user)
{
    return rtpi_parallel_rows_stack(nrows, nthreads, ctx, fn, progress, progress_user,
                                    rtpi_trace_stack(t->max_depth));
}

typedef struct vis_ctx {
    rtp_tree *t;
    const rtpi_shadow *sh;
    /* rtpi_shadow_ball_own for sh's light, read where a sphere's front
       asks (ball_own_of) */
    const unsigned char *ball_own;
    rtpi_v3 lp;
    double off_floor; /* rtpi_offset_floor of the scene */
    int prim_floor;   /* rtpi_offset_floor said: ask each primitive */
    size_t light;
    unsigned long long queries;
    const unsigned char *balls; /* rtpi_balls_around for the light (NULL:
                                   no spheres) */
    rtpi_shadow_cache cache; /* the thread's last occluder */
    int keep_balls;          /* a ball that holds a hit goes to the cache */
    uint32_t *kd_from;       /* t->kd_from for EXACT's walks, or NULL */
    const rtpi_kdtree *kd;
    double *vrec;            /* t->vrec where it holds for this move, or NULL
                                (its kinds after its nnodes + 1 steps) */
    char pad[64];            /* the contexts lie side by side (vis_row) */
} vis_ctx;

/* Whether the shadow ray of a back hit at p on sphere sp (prim), its
   normal turned inwards, starts inside the ball: vis_row's o and
   rtpi_ball_holds by their own arithmetic, with the side a query takes
   (the normals being one, a hit facing the light moves towards it). */
static int ball_holds_back(const vis_ctx *v, const rtpi_sphere *sp, uint32_t prim, rtpi_v3 p)
{
    const rtp_scene *s = v->t->scene;
    rtpi_v3 n = rtpi_sphere_normal(sp, p);
    double floor = v->prim_floor ? rtpi_prim_offset_floor(s, prim, v->off_floor) : v->off_floor;
    if (sp->r < 0.0f)
        n = v3_mul(n, -1.0);
    n = v3_mul(n, -1.0);
    return rtpi_ball_holds(sp, rtpi_offset_origin(p, n, 1.0, floor));
}

/* rtpi_surface_normals' normal (ng = ns) at p on sphere or cone prim (not
   a triangle), by its own arithmetic, through the node's c[0..2]
   (t->prim_nrm): derived and kept the first time, read from then on (the
   node's p and the scene's geometry do not change while it is kept).  0
   where rtpi_surface_normals takes another path (a cone's axis). */
static RTPI_FORCE_INLINE int kept_normal(double *c, const rtp_scene *s, uint32_t prim, rtpi_v3 p,
                                         rtpi_v3 *n)
{
    size_t i = prim - s->ntris;
    if (c[0] != 0.0 || c[1] != 0.0 || c[2] != 0.0) {
        *n = v3(c[0], c[1], c[2]);
        return 1;
    }
    /* (0 0 0, which no sphere or cone off its axis gives but at a
       sphere's centre, is derived again each time: the same numbers) */
    if (i < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        *n = rtpi_sphere_normal(sp, p);
        if (sp->r < 0.0f)
            *n = v3_mul(*n, -1.0);
    } else {
        rtpi_v3 q;
        double h;
        i -= s->nspheres;
        if (!(i < s->ncones && s->cframes[i].ok && rtpi_cone_normal(&s->cframes[i], p, n, &q, &h)))
            return 0;
    }
    c[0] = n->x;
    c[1] = n->y;
    c[2] = n->z;
    return 1;
}

/* The shadow cache's `from` for node n's query from o, the origin on the
   side of its surface the geometric normal faces (the offset's +1): the
   leaf of o, found the first time (rtpi_kd_path_of) and kept in kf[n] as
   its list + 2 (1: the walk cannot start there, RTPI_NONE).  A node's o
   depends on the light only through that side (its p, normal and offset
   stay), so the kept leaf holds for every query on that side; the other
   side's (a smooth triangle's light behind its geometric normal) walk
   from the root.  (Keeping the side found first instead, either one,
   cost a compare a query: 0.1-1.2 M more on every scene's move.)  The
   normal's turn for a back hit, which a material's kt can change, makes
   them anew (kd_from_make). */
static RTPI_FORCE_INLINE uint32_t vis_from(uint32_t *kf, const rtpi_kdtree *kd, size_t n,
                                           const rtpi_v3 *o)
{
    uint32_t v = kf[n];
    if (!v)
        v = kf[n] = rtpi_kd_path_of(kd, *o) + 2u; /* (RTPI_NONE + 2: 1) */
    return v - 1u;
}

/* o's x and y written to memory as one 16-byte store, where a query is
   about to read them as one (rtpi_shadow_ray's l = lp - o on a vector):
   a load spanning two 8-byte stores cannot take its bytes from the store
   buffer and waits until both have reached the cache -- perf put ~19% of
   vis_row's samples on it (then on sh_cached's) on mount's exact moves.
   The same bits; without SSE2, nothing. */
static RTPI_FORCE_INLINE void o_store(rtpi_v3 *o)
{
#ifdef PK_SSE2
    _mm_storeu_pd(&o->x, _mm_set_pd(o->y, o->x));
#else
    (void)o;
#endif
}

/* A node's kind in its record (t->vrec's bytes after the steps): 0 not
   yet known; a flat triangle's, its normal tri_nrm's or turned over (a
   two-sided back hit); a smooth triangle's (ng tri_nrm's turned to the
   ray, ns ev_nv's); a sphere's or a cone's seen from the front (the
   normal prim_nrm's; the cone's own answer cone_own's); none (a back hit
   on a sphere: its path each move). */
#define VK_FLAT 1
#define VK_FLAT_TURNED 2
#define VK_SMOOTH 3
#define VK_SPHERE 4
#define VK_CONE 5
#define VK_NONE 6

/* rtpi_prim_shadows_own's answer for front hit n on sphere si from
   origin *o, or RTPI_OWN_ASK: whether o lies outside the sphere near its
   surface (rtpi_ball_near_outside) kept in own[n] (0 not yet known, 1
   it does, 2 not), as no light changes o, and for a light the sphere's
   answer for such origins (rtpi_shadow_ball_own).  Mount_s6's glass
   balls' fronts: sh_own_sphere's call every query was ~60 instructions,
   and a light buffer's query then takes the triangles' path where its
   cache holds no other sphere.  Out of line: inlined (vis_row is
   flattened), the scenes without spheres' moves paid up to 0.4% (gears,
   teapot) and tree_s11's 0.57%. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int ball_own_of(unsigned char *own, size_t n,
                                         const unsigned char *ball_own,
                                         const rtpi_sphere *spheres, size_t si,
                                         const rtpi_v3 *o)
{
    unsigned char *k = &own[n];
    if (!*k)
        *k = rtpi_ball_near_outside(&spheres[si], *o) ? 1 : 2;
    return *k == 1 ? ball_own[si] : RTPI_OWN_ASK;
}

/* Decides light `light` anew for every node of one row of samples, with
   trace's own rule (rtpi_shadow_setup) and the chosen shadow query.
   kf: 1 where EXACT's walks start at the origins' leaves (t->kd_from),
   a copy of its own: the other modes' queries pay nothing for it.  kb: 1
   where the runs of back hits inside balls serve (ball_runs_serve), in a
   loop of their own, a copy too: the other trees' walks test nothing
   more. */
static RTPI_FORCE_INLINE int vis_row_body(void *ctx, int y, int kf, int kb)
{
    vis_ctx *v = (vis_ctx *)ctx;
    rtp_tree *t = v->t;
    const rtp_scene *s = t->scene;
    size_t k0 = (size_t)y * t->nx, k1 = k0 + (size_t)t->nx;
    size_t n, words = t->cur_words, wi = v->light >> 5;
    uint32_t bit = 1u << (v->light & 31);
    /* the thread's counts and cache in locals, stored once a row: the
       contexts of the threads lie side by side, and a store per query
       into one made the other thread's reads of its own miss (2 threads:
       vis_row took 16% of a move's time, against 5% on one) */
    unsigned long long queries = 0;
    rtpi_shadow_cache cache = v->cache;
    size_t ok_si = (size_t)-1; /* the sphere last found to take a run's path */
    /* the shading normals the evaluation keeps (rounded to float) */
    const float *nv = t->ev_valid ? t->ev_nv : NULL;
    /* (NULL also where the light buffer has no balls: no sphere) */
    unsigned char *ball_in = v->balls ? t->ball_in : NULL;
    double *const prim_nrm = t->prim_nrm;
    unsigned char *const cone_own = prim_nrm ? t->cone_own : NULL;
    /* (the tree's and scene's arrays in locals: the query's call may
       write anything for all the compiler knows, and they were loaded
       again a node, with the row's end) */
    const rtpi_cnode *const nodes = t->nodes;
    uint32_t *const cur_vis = t->cur_vis;
    const double *const tri_nrm = t->tri_nrm;
    const rtpi_tri *const tris = s->tris;
    const size_t ntris = s->ntris, nspheres = s->nspheres, n1 = (size_t)t->start[k1];
    const rtpi_shadow *const sh = v->sh;
    const unsigned char *const balls = v->balls;
    const rtpi_v3 lp = v->lp;
    const double off_floor = v->off_floor;
    const int prim_floor = v->prim_floor, keep_balls = v->keep_balls, spd = t->spd;
    const rtpi_sphere *const spheres = s->spheres;
    const rtpi_material *const mats = s->mats, *const ev_mats = t->ev_mats;
    uint32_t *const kd_from = kf ? v->kd_from : NULL;
    double *const vrec = v->vrec;
    unsigned char *const vk = vrec ? (unsigned char *)(vrec + t->nnodes + 1) : NULL;
    for (n = (size_t)t->start[k0]; n < n1; n++) {
        if (kb && ball_in[n] == 1) {
            /* A run of back hits inside balls (three quarters of mount's
               nodes, ~3.8 a run): the ball path below, their normals
               kept (ball_runs_known), in a loop of their own -- the
               tests of the node's kind, its material and its normal's
               were ~60 of its ~90 instructions a node.  A node whose ball
               the light is inside of, or whose material is not two-sided
               (a kt edit), or a NaN d, is left to the steps below, which
               decide it as ever; the cache's last occluder as the path
               below leaves it (the run's last hit facing the light). */
            uint32_t last = 0;
            int left = 0; /* node n left to the steps below */
            do {
                const rtpi_cnode *nd = &nodes[n];
                const size_t si = nd->prim - ntris;
                const double *c = prim_nrm + 3 * n;
                double d;
                if (si != ok_si) {
                    if (!(balls[si] && rtpi_two_sided(s, spd, nd->prim, &mats[spheres[si].mat]))) {
                        left = 1;
                        break;
                    }
                    ok_si = si;
                }
                /* (the path's d: the kept normal's n.(lp - p)) */
                d = v3_dot(v3(c[0], c[1], c[2]), v3_sub(lp, v3(nd->p[0], nd->p[1], nd->p[2])));
                if (d < 0.0) {
                    queries++;
                    last = nd->prim + 1u;
                } else if (!(d >= 0.0)) {
                    left = 1;
                    break;
                }
                cur_vis[n * words + wi] &= ~bit;
            } while (++n < n1 && ball_in[n] == 1);
            if (keep_balls && last)
                cache.last = last;
            if (!left) {
                n--; /* (the loop's n++: the node after the run) */
                continue;
            }
        }
        { /* (a block: without it gcc's registers cost mount_s6 0.7 M a move) */
            const rtpi_cnode *nd = &nodes[n];
            rtpi_v3 p = v3(nd->p[0], nd->p[1], nd->p[2]), ng, ns, o, l;
            uint32_t *w = &cur_vis[n * words + wi], mat;
            const rtpi_tri *tr; /* (found below the record's paths: gcc took it first) */
            int flip = 1; /* ng and ns still to be turned over for a back face */
            int same = 1; /* ng and ns one vector (but a smooth triangle's) */
            int rk = 0; /* the node's record's kind to make (VK_) */
            double dn, sd; /* (sd: ng.l, whose sign is the offset's side) */
            if (vk && vk[n] - 1u < VK_NONE - 1u) {
                /* The node's record (vrec_make): its kind and the offset's
                   step, which no light changes -- the node's kind tests,
                   material, two-sidedness and the step's arithmetic.  The
                   steps below with the same numbers: o is
                   rtpi_offset_origin's, dn and the side's sign as there */
                const unsigned kind = vk[n];
                const double e = vrec[n];
                if (kind >= VK_SPHERE) {
                    const double *c = prim_nrm + 3 * n;
                    ng = v3(c[0], c[1], c[2]);
                } else {
                    const double *tn = tri_nrm + 3 * (size_t)nd->prim;
                    /* (a smooth triangle's ng turned to the ray) */
                    double sg = kind == VK_FLAT_TURNED ||
                                        (kind == VK_SMOOTH && (nd->link & RTPI_L_BACK))
                                    ? -1.0
                                    : 1.0;
                    ng = v3(sg * tn[0], sg * tn[1], sg * tn[2]);
                }
                *w &= ~bit;
                l = v3_sub(lp, p);
                if (kind == VK_SMOOTH) {
                    /* ns the evaluation's (as below), the side ng's */
                    const float *q = nv + 6 * n;
                    dn = v3_dot(v3(q[0], q[1], q[2]), l);
                    if (dn <= 0.0)
                        continue;
                    sd = v3_dot(ng, l);
                } else {
                    /* ng = ns: the side is dn's */
                    dn = sd = v3_dot(ng, l);
                    if (dn <= 0.0)
                        continue;
                }
                o = v3_madd(p, ng, sd >= 0.0 ? e : -e);
                o_store(&o);
                queries++;
                if (kf)
                    cache.from = sd >= 0.0 ? vis_from(kd_from, v->kd, n, &o) : 0u;
                if (kind == VK_CONE) {
                    /* its own answer kept (cone_own, as below) */
                    unsigned char *co = &cone_own[n];
                    if (!*co)
                        *co = (unsigned char)(1 - rtpi_cone_shadows_own(
                                                      s, nd->prim - ntris - nspheres, &o));
                    if (rtpi_shadow_visible_own(sh, &cache, &p, &o, nd->prim, 1 - *co))
                        *w |= bit;
                } else if (kind == VK_SPHERE && cone_own) {
                    /* a sphere's: whether o lies outside near it kept
                       (cone_own, as below) */
                    if (rtpi_shadow_visible_own(sh, &cache, &p, &o, nd->prim,
                                                ball_own_of(cone_own, n, v->ball_own, spheres,
                                                            nd->prim - ntris, &o)))
                        *w |= bit;
                } else if (rtpi_shadow_visible_cached(sh, &cache, &p, &o, nd->prim)) {
                    *w |= bit;
                }
                continue;
            }
            tr = tri_nrm && nd->prim < ntris ? &tris[nd->prim] : NULL;
            if (tr && (tr->n[0] == RTPI_NONE || tr->n[1] == RTPI_NONE || tr->n[2] == RTPI_NONE)) {
                /* flat: ng as rtpi_surface_normals makes it */
                const double *tn = tri_nrm + 3 * (size_t)nd->prim;
                ng = ns = v3(tn[0], tn[1], tn[2]);
                mat = tr->mat;
                rk = VK_FLAT;
            } else if (tr && nv && mats[tr->mat].bump == RTPI_BUMP_NONE &&
                       ev_mats[tr->mat].bump == RTPI_BUMP_NONE) {
                /* Smooth, not bumped: the shading normal the evaluation kept,
                   turned over already (a triangle with vertex normals is
                   two-sided), instead of interpolating it again (teapot: 12%
                   of a move).  Rounded to float, it can differ from trace's
                   in its sign towards the light only where n.l is within
                   ~1e-7 |l| of 0, where the light's term is as small. */
                const float *q = nv + 6 * n;
                const double *tn = tri_nrm + 3 * (size_t)nd->prim;
                double sg = nd->link & RTPI_L_BACK ? -1.0 : 1.0;
                ng = v3(sg * tn[0], sg * tn[1], sg * tn[2]);
                ns = v3(q[0], q[1], q[2]);
                mat = tr->mat;
                flip = 0;
                same = 0;
                rk = VK_SMOOTH;
            } else {
                double *pn = prim_nrm && nd->prim >= ntris ? prim_nrm + 3 * n : NULL;
                if (ball_in && (nd->link & RTPI_L_BACK) && nd->prim - ntris < nspheres) {
                    /* A back hit on a sphere (a glass ball's inside: three
                       quarters of mount's nodes): its shadow ray's origin does
                       not depend on the light (the normals are one), nor then
                       whether it lies in the ball, found once a tree (ball_in).
                       Where it does and the light is outside (balls), the ball
                       is in the way, whether or not the hit faces the light: the
                       normal only for the query count (the same decisions and
                       count as below, without the offset or the ball's test:
                       mount_s6's moves 5% fewer instructions). */
                    size_t si = nd->prim - ntris;
                    const rtpi_sphere *sp = &spheres[si];
                    unsigned char *bi = &ball_in[n];
                    if (!*bi)
                        *bi = ball_holds_back(v, sp, nd->prim, p) ? 1 : 2;
                    if (*bi == 1 && balls[si] &&
                        rtpi_two_sided(s, spd, nd->prim, &mats[sp->mat])) {
                        rtpi_v3 nn;
                        double d;
                        if (!pn || !kept_normal(pn, s, nd->prim, p, &nn)) {
                            nn = rtpi_sphere_normal(sp, p);
                            if (sp->r < 0.0f)
                                nn = v3_mul(nn, -1.0);
                        }
                        /* rtpi_shadow_setup's d' = (-n).(lp - p) is this d
                           negated exactly (each product and the sums turn
                           sign alone): d' > 0 where d < 0, d' <= 0 where d >=
                           0, NaN in neither -- the turned normal's three
                           products saved (mount_s6's moves 1.48 M) */
                        d = v3_dot(nn, v3_sub(lp, p));
                        if (d < 0.0) {
                            *w &= ~bit;
                            queries++;
                            if (keep_balls)
                                cache.last = nd->prim + 1u;
                            continue;
                        }
                        if (d >= 0.0) {
                            *w &= ~bit;
                            continue;
                        }
                        /* (NaN: as below) */
                    }
                }
                if (pn && kept_normal(pn, s, nd->prim, p, &ng)) {
                    size_t i = nd->prim - ntris;
                    if (!(nd->link & RTPI_L_BACK)) {
                        /* A sphere or cone seen from the front (no turn, no
                           ball, no material to look up): the steps below.  On
                           a cone, o is p moved along the kept normal (the
                           side it faces) by the scene's offset, the same for
                           every light, and so is whether o lies in the cone's
                           solid, the query's own test (sh_own), kept too
                           (rings_s7: 3% of a move) */
                        if (vk && !vk[n]) {
                            /* (a cone's without cone_own: its path) */
                            vrec[n] = rtpi_offset_eps(
                                p, prim_floor ? rtpi_prim_offset_floor(s, nd->prim, off_floor)
                                              : off_floor);
                            vk[n] = i < nspheres ? VK_SPHERE : cone_own ? VK_CONE : VK_NONE;
                        }
                        *w &= ~bit;
                        l = v3_sub(lp, p);
                        dn = v3_dot(ng, l);
                        if (dn <= 0.0)
                            continue;
                        o = rtpi_offset_origin(p, ng, dn >= 0.0 ? 1.0 : -1.0,
                                               prim_floor
                                                   ? rtpi_prim_offset_floor(s, nd->prim, off_floor)
                                                   : off_floor);
                        o_store(&o);
                        queries++;
                        if (kf)
                            cache.from = vis_from(kd_from, v->kd, n, &o);
                        if (i >= nspheres && cone_own) {
                            unsigned char *co = &cone_own[n];
                            if (!*co)
                                *co = (unsigned char)(1 -
                                                      rtpi_cone_shadows_own(s, i - nspheres, &o));
                            if (rtpi_shadow_visible_own(sh, &cache, &p, &o, nd->prim, 1 - *co))
                                *w |= bit;
                        } else if (cone_own) {
                            if (rtpi_shadow_visible_own(
                                    sh, &cache, &p, &o, nd->prim,
                                    ball_own_of(cone_own, n, v->ball_own, spheres, i, &o)))
                                *w |= bit;
                        } else if (rtpi_shadow_visible_cached(sh, &cache, &p, &o, nd->prim)) {
                            *w |= bit;
                        }
                        continue;
                    }
                    ns = ng;
                    mat = i < nspheres ? spheres[i].mat : s->cones[i - nspheres].mat;
                    if (vk && !vk[n])
                        vk[n] = VK_NONE; /* (a back hit's ball: its path) */
                } else {
                    mat = rtpi_surface_normals(s, nd->prim, p, &ng, &ns);
                    same = 0;
                }
            }
            if (flip && (nd->link & RTPI_L_BACK) &&
                rtpi_two_sided(s, spd, nd->prim, &mats[mat])) {
                ng = v3_mul(ng, -1.0);
                ns = v3_mul(ns, -1.0);
                rk += rk == VK_FLAT; /* (VK_FLAT_TURNED) */
            }
            if (rk && vk && !vk[n]) {
                vrec[n] = rtpi_offset_eps(
                    p, prim_floor ? rtpi_prim_offset_floor(s, nd->prim, off_floor) : off_floor);
                vk[n] = (unsigned char)rk;
            }
            *w &= ~bit;
            /* rtpi_shadow_setup's arithmetic, whose second dot product, ng's,
               is its first where ng and ns are one vector (the same bits:
               then the side is the one the normal faces, NaN as ever) */
            l = v3_sub(lp, p);
            dn = v3_dot(ns, l);
            if (dn <= 0.0)
                continue;
            /* (sd kept only where kf asks for it: the other copy as before
               it, whose code it changed) */
            sd = kf ? same ? dn : v3_dot(ng, l) : 0.0;
            o = rtpi_offset_origin(p, ng,
                                   (kf ? sd : same ? dn : v3_dot(ng, l)) >= 0.0 ? 1.0 : -1.0,
                                   prim_floor ? rtpi_prim_offset_floor(s, nd->prim, off_floor)
                                              : off_floor);
            o_store(&o);
            queries++;
            if ((nd->link & RTPI_L_BACK) && balls && nd->prim - ntris < nspheres &&
                balls[nd->prim - ntris] && rtpi_ball_holds(&spheres[nd->prim - ntris], o)) {
                /* inside a ball the light is outside of: the ball is in the
                   way (rtpi_prim_shadows_own_solid 1), which every mode
                   answers without a test (sh_visible).  Here before the
                   query's call and its own arithmetic (mount, whose glass
                   balls hold three quarters of its nodes: 7% of a move), for
                   back hits only (a front hit's o lies outside: balls' 7381
                   spheres paid 2% for the test).  The cache as the query
                   leaves it for shadow rays, whose next query the ball saves
                   a walk of the kd-tree; a light buffer's is cheaper than the
                   ball's test (mount: 1.9% of a move) */
                if (keep_balls)
                    cache.last = nd->prim + 1u;
                continue;
            }
            if (kf)
                cache.from = sd >= 0.0 ? vis_from(kd_from, v->kd, n, &o) : 0u;
            if (rtpi_shadow_visible_cached(sh, &cache, &p, &o, nd->prim))
                *w |= bit;
        }
    }
    v->queries += queries;
    v->cache = cache;
    return 0;
}

/* (the copies flattened: with two, gcc left rtpi_surface_normals and
   others out of line, and the light buffers' moves paid 1.5%) */
#if defined(__GNUC__)
__attribute__((flatten))
#endif
static int vis_row(void *ctx, int y)
{
    return vis_row_body(ctx, y, 0, 0);
}

#if defined(__GNUC__)
__attribute__((flatten))
#endif
static int vis_row_kb(void *ctx, int y)
{
    return vis_row_body(ctx, y, 0, 1);
}

#if defined(__GNUC__)
__attribute__((flatten))
#endif
static int vis_row_kf(void *ctx, int y)
{
    return vis_row_body(ctx, y, 1, 0);
}

#if defined(__GNUC__)
__attribute__((flatten))
#endif
static int vis_row_kf_kb(void *ctx, int y)
{
    return vis_row_body(ctx, y, 1, 1);
}

/* t->tri_nrm where the scene has triangles (else it stays NULL); 0, or
   -1 when out of memory. */
static int tri_normals(rtp_tree *t)
{
    const rtp_scene *s = t->scene;
    size_t i;
    if (!s->ntris)
        return 0;
    t->tri_nrm = (double *)rtpi_malloc_array(&t->alloc, 3 * s->ntris, sizeof *t->tri_nrm);
    if (!t->tri_nrm)
        return -1;
    for (i = 0; i < s->ntris; i++) {
        rtpi_v3 n = rtpi_tri_normal(s, &s->tris[i]);
        t->tri_nrm[3 * i] = n.x;
        t->tri_nrm[3 * i + 1] = n.y;
        t->tri_nrm[3 * i + 2] = n.z;
    }
    return 0;
}

/* The recorded bit of light i at node n. */
static uint32_t recorded_bit(const rtp_tree *t, size_t n, size_t i)
{
    if (t->vis_words)
        return (t->vis_ext[n * t->vis_words + (i >> 5)] >> (i & 31)) & 1u;
    return (t->nodes[n].vis >> i) & 1u;
}

/* Shadow rays and the light buffer (at any resolution) answer alike:
   visibility one decided holds for the other.  The key decisions are
   kept under (cur_mode, ev_vis_mode): EXACT and 0 for both, else the mode
   and resolution. */
static void vis_key(int mode, int res, int *kmode, int *kres)
{
    int exact = mode == RTP_SHADOWS_EXACT || mode == RTP_SHADOWS_LIGHTBUF;
    *kmode = exact ? RTP_SHADOWS_EXACT : mode;
    *kres = exact ? 0 : res;
}

/* RTP_SHADOWS_AUTO's method for tree t, both exact.  The light buffer
   projects every primitive onto the cube at each move, then answers a
   query in a quarter to a half of a shadow ray's instructions; the
   kd-tree is built once a tree (at about twice a light buffer's cost)
   and kept.  Measured (a moved light, 1 thread): the light buffer takes
   0.4-0.85 of the shadow rays' time on the seven SPD scenes at 512x512
   (12 to 80 recorded hits a primitive) and on the Stanford bunny at
   2048x2048 (13); they are even at 3 (the bunny at 1024x1024); shadow
   rays take 0.5 of its time at 0.8 (512x512) and 0.08 at 0.05 (128x128)
   once the kd-tree is there.  Without a kd-tree a first move is faster
   with the light buffer whatever the scene (the kd-tree's build alone
   costs more); from a second move on, shadow rays pay for it.  So the
   light buffer without a kd-tree only for a one-off evaluation (no_cache:
   no move follows) of one or two lights: a stream's first move built a
   light buffer and its second the kd-tree anyway (an 8M-triangle
   heightfield: 50.5 s for 4 moves against 27.4 by shadow rays), and 100
   lights moved at once built 100 light buffers (5.8 s against 3.9). */
#define AUTO_HITS_PER_PRIM 4

static int auto_shadows(const rtp_tree *t, int one_off, size_t moving)
{
    if (t->nnodes >= AUTO_HITS_PER_PRIM * rtpi_scene_nprims(t->scene))
        return RTP_SHADOWS_LIGHTBUF;
    if (t->kd || t->cur_vis || !one_off || moving > 2)
        return RTP_SHADOWS_EXACT;
    return RTP_SHADOWS_LIGHTBUF;
}

/* The list entries RTP_SHADOWS_AUTO lets a light buffer hold before it
   takes shadow rays instead.  Primitives that overlap as seen from the
   light list each other in every cell they share: 10,000 stacked quads
   at 128 cells listed 61.8 M entries for 119 k recorded hits, 0.89 s
   against shadow rays' 0.22 s, of which 0.20 s was the kd-tree's build.
   An entry costs about 15 ns to fill (that stack, one thread); a shadow
   ray's query a sixteenth of a microsecond and up (stacks of 30 to
   10,000 quads at 256x256 with the kd-tree's build: even at about 16
   entries a hit, shadow rays 2x as fast at 51), and the kd-tree's build,
   where there is none yet, 2-10 us a primitive (mount_s6 2, the stack
   10): AUTO_LB_ENTRIES a hit and a primitive, AUTO_LB_BUILD more a
   primitive without a kd-tree, and never fewer than 2^18 (a few
   milliseconds: below that either is quick, and a small image of a large
   scene, few hits, lists more than its hits).  The seven SPD scenes list
   0.4-1.9 entries a hit (tree_s11 the most), far below.  The runs the
   counting pass makes are bounded by it too (lb_budget: a run lists a
   cell at least), so the pass stops early where the lists would be
   long. */
#define AUTO_LB_ENTRIES 16.0
#define AUTO_LB_BUILD 150.0

static double auto_lb_entries(const rtp_tree *t)
{
    double np = (double)rtpi_scene_nprims(t->scene);
    double entries =
        AUTO_LB_ENTRIES * ((double)t->nnodes + np) + (t->kd ? 0.0 : AUTO_LB_BUILD * np);
    return entries > 262144.0 ? entries : 262144.0;
}

/* The light buffer's cells a face edge without a resolution asked
   (LIGHTBUF and AUTO; the item buffers keep 512, their accuracy): the
   power of two nearest 256 sqrt(nodes / 250,000), 64 to 512.  Its
   decisions are exact at any resolution, which trades the build (6 res^2
   cells filled each move, the candidates' covers) against the queries
   (shorter lists in finer cells): more queries pay for finer cells.  The
   nodes are known before the build, at a drag's first move too; the last
   move's queries (lb_queries) are not, and they follow the light (tetra's
   16k at 512x512 for its 50k nodes, best at 128 all the same).  Measured
   (callgrind, a drag's move, 1 thread; the best of 64-1024, the rule's):
   at 512x512 SPD tetra 128 (50k nodes; 128), teapot 256 (229k; 256),
   tree 256 (170k; 256), rings 128 (443k; 256 +1.3%), gears 192 (375k;
   256 +0.3%), balls 384 (390k; 256 +4.5%), mount 384 (651k; 512 +0.7%);
   at 1024x1024 tetra 128 (256 +1.2%), teapot 512, tree 256 (512 +1.6%),
   gears 384 (512 +0.6%), balls 768 (512 +0.1%), rings 384 (512 +0.7%),
   mount 512 (2.6M nodes; 1024, the cap until session 48, took 1.5% more
   and 8.5% more thread time: nothing measured was best finer than 768,
   the Stanford bunny at 2048x2048 neither, 894k nodes, 512 by time).  A
   first move adds the same at every resolution (balls +79 M).  Thread
   time favours coarser cells a little more (the cells' memory): 512, the
   light buffer's default until session 48, took 12-28% more a drag's
   move at 512x512 than the rule's (balls 41.2 ms against 36.2).  The
   primitives matter too (rings' long cones, balls' small spheres: 443k
   and 390k nodes, best 128 and 384), within the few percent above. */
#define LB_DEFAULT_MAX 512
static int lb_default_res(const rtp_tree *t)
{
    double want = 256.0 * sqrt((double)t->nnodes / 250000.0);
    int res = 64;
    while (res < LB_DEFAULT_MAX && want > res * 1.4142135623730951) /* (nearest in log) */
        res *= 2;
    return res;
}

/* Progress of one step of an evaluation, as part [lo, lo + span] of the
   caller's. */
typedef struct progress_part {
    void (*fn)(void *user, double done);
    void *user;
    double lo, span;
    int (*cancel)(void *user); /* the caller's (re-traces ask it) */
} progress_part;

static void progress_part_cb(void *user, double done)
{
    const progress_part *p = (const progress_part *)user;
    p->fn(p->user, p->lo + p->span * done);
}

static int progress_part_cancel(void *user)
{
    const progress_part *p = (const progress_part *)user;
    return p->cancel(p->user);
}

/* Whether the caller's cancel says to stop now. */
static int part_cancelled(const progress_part *p)
{
    return p->cancel && p->cancel(p->user);
}

/* Whether light i's visibility in t->cur_vis is as mode and res would
   decide it now. */
static int vis_up_to_date(const rtp_tree *t, size_t i, int kmode, int kres)
{
    return !isnan(t->cur_pos[3 * i]) && light_at(t, i, t->cur_pos + 3 * i) &&
           (!light_moved(t, i) || (t->cur_mode == kmode && t->cur_res == kres));
}

/* A moved light's shadow queries (light_vis_make) and what its rows of
   decisions need (light_vis_rows). */
typedef struct light_vis {
    size_t light;
    int mode;                /* the mode that decides it (AUTO's fallback
                                to shadow rays made) */
    int res;                 /* its cube's cells a face edge (0: shadow
                                rays) */
    int threads;
    rtpi_shadow *sh;
    unsigned char *balls;    /* rtpi_balls_around (NULL: no spheres) */
} light_vis;

static void light_vis_free(rtp_tree *t, light_vis *lv)
{
    rtpi_shadow_destroy(lv->sh);
    rtpi_free(&t->alloc, lv->balls);
    lv->sh = NULL;
    lv->balls = NULL;
}

/* light_vis_make's `fallback` bits (shadow_mode_for's *fallback_out). */
#define LV_AUTO 1     /* AUTO asked: shadow rays where the light buffer's
                         lists pass the memory limit (at 1 cell where
                         LV_RES_FREE) or AUTO's bound on entries */
#define LV_RES_FREE 2 /* no resolution asked (lb_default_res chose it):
                         a light buffer whose lists pass the limit tries
                         half the cells (fewer entries: a primitive
                         covers fewer of them) before RTP_ERR_LIMIT, or
                         AUTO's shadow rays */

/* The limit's error once a resolution nobody asked was halved down to
   `res` (lb_default_res's, or coarser for the cells' starts: shadow_mode_for,
   then down from light_vis_make's res0): it named "a light buffer of 1 cells a
   face", which no one had asked, and told to lower that resolution
   (--memory-limit 2 on gears_s4's tree).  The cause stays (its lists or
   its primitives before them), the advice but that. */
static void halved_error(int res, rtp_error *err)
{
    static const char lower[] = "lower its resolution, ";
    const char *tail, *cut;
    char m[sizeof err->message + 96];
    int n;
    if (!err || !err->message[0])
        return;
    tail = strstr(err->message, "cells a face: ");
    tail = tail ? tail + strlen("cells a face: ") : err->message;
    cut = strstr(tail, lower);
    n = snprintf(m, sizeof m,
                 "a light buffer of the default resolution, halved down to %d cell%s a face: "
                 "%.*s%s",
                 res, res == 1 ? "" : "s", cut ? (int)(cut - tail) : (int)strlen(tail), tail,
                 cut ? cut + strlen(lower) : "");
    rtpi_fit_text(err->message, sizeof err->message, m, n >= 0 && (size_t)n < sizeof m);
}

/* Light i's shadow queries by `mode` (not AUTO) at `res` cells: its
   direction cube's build (its progress and cancel through poll), or the
   kd-tree's where shadow rays decide.  `fallback`: LV_ bits. */
static rtp_status light_vis_make(rtp_tree *t, size_t i, int mode, int res, int threads,
                                 double limit, int fallback, rtpi_poll *poll, light_vis *lv,
                                 rtp_error *err)
{
    rtp_scene *s = t->scene;
    const double *lp = s->lights[i].pos;
    double lb_cap, lb_q;
    int res0;
    rtp_status rs;
    memset(lv, 0, sizeof *lv);
    lv->light = i;
    lv->threads = threads;
    if (mode != RTP_SHADOWS_EXACT && rtpi_scene_bounds(s) != 0)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    /* only shadow rays need the kd-tree; the cubes draw the scene */
    if (mode == RTP_SHADOWS_EXACT && !t->kd &&
        (rs = rtpi_kd_build_mt(s, &t->alloc, threads, &t->kd, err)) != RTP_OK)
        return rs;
    t->cube_alloc.malloc_fn = blk_malloc;
    t->cube_alloc.realloc_fn = blk_realloc;
    t->cube_alloc.free_fn = blk_free;
    t->cube_alloc.user = t;
    lb_cap = (fallback & LV_AUTO) && mode == RTP_SHADOWS_LIGHTBUF ? auto_lb_entries(t) : HUGE_VAL;
    /* (the last light buffer's queries, as the next's expectation: a
       drag's moves ask about as many each; none known at the first) */
    lb_q = t->lb_queries_known ? t->lb_queries : HUGE_VAL;
    res0 = res;
    for (;;) {
        rs = rtpi_shadow_create_q(s, t->kd, v3(lp[0], lp[1], lp[2]), (rtpi_shadow_mode)mode,
                                  res, threads, limit, lb_cap, lb_q, poll, &t->cube_alloc,
                                  &lv->sh, err);
        /* (a resolution nobody asked refused by the limit while a
           coarser one may fit, AUTO's too: shadow_mode_for; AUTO takes
           shadow rays below where none does, and where the lists are
           too long for it, RTPI_OVER_ENTRIES) */
        if (rs != RTP_ERR_LIMIT || !(fallback & LV_RES_FREE) ||
            mode != RTP_SHADOWS_LIGHTBUF || res <= 1)
            break;
        res /= 2;
    }
    if (rs == RTP_ERR_LIMIT && (fallback & LV_RES_FREE) && !(fallback & LV_AUTO) &&
        mode == RTP_SHADOWS_LIGHTBUF && res < res0)
        halved_error(res, err);
    /* (AUTO's light buffer refused by the limit down to 1 cell: the next
       moves under this limit or a lower one take shadow rays at once,
       shadow_mode_for.  Each halving counts the lists again before the
       limit refuses them: the bunny's 1280x1280 tree under 4 MiB, where
       its 69k triangles' arrays fit but no light buffer's lists do,
       counted 9 light buffers a move, 634 M instructions over the 1.1 G
       of shadow rays', +55% a move.  Another light position may fit a
       coarse buffer; shadow rays are as exact, and a light buffer of a
       few cells is about as slow as they are: lightbuf:1 1.3x their
       time on mount_s1, 0.9x on balls_s1) */
    if (rs == RTP_ERR_LIMIT && (fallback & LV_RES_FREE) && (fallback & LV_AUTO) &&
        mode == RTP_SHADOWS_LIGHTBUF && res <= 1 && limit > t->auto_tight)
        t->auto_tight = limit;
    if ((rs == RTP_ERR_LIMIT || rs == RTPI_OVER_ENTRIES) && (fallback & LV_AUTO) &&
        mode != RTP_SHADOWS_EXACT) {
        /* AUTO: shadow rays where the lists would not fit (a mesh
           seen edge on lists every triangle in a row of cells) */
        /* (the lists too long for AUTO, not for the memory limit:
           the next move at this resolution or finer need not
           count them again; a limit may be raised, a coarser
           buffer list less) */
        if (rs == RTPI_OVER_ENTRIES && (!t->auto_long || res < t->auto_long))
            t->auto_long = res;
        mode = RTP_SHADOWS_EXACT;
        if (!t->kd && (rs = rtpi_kd_build_mt(s, &t->alloc, threads, &t->kd, err)) != RTP_OK)
            return rs;
        rs = rtpi_shadow_create_mt(s, t->kd, v3(lp[0], lp[1], lp[2]), RTPI_SHADOW_EXACT, res,
                                   threads, limit, HUGE_VAL, poll, &t->cube_alloc, &lv->sh, err);
    }
    if (rs != RTP_OK)
        return rs;
    lv->mode = mode;
    lv->res = mode == RTP_SHADOWS_EXACT ? 0 : res;
    if (s->nspheres) {
        lv->balls = (unsigned char *)rtpi_malloc_array(&t->alloc, s->nspheres, 1);
        if (!lv->balls) {
            light_vis_free(t, lv);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        rtpi_balls_around(s, v3(lp[0], lp[1], lp[2]), lv->balls);
    }
    return RTP_OK;
}

/* t->ball_sph, after a move that found every node's ball_in (vis_row
   finds each back hit's on a sphere where the light has balls, and keeps
   its normal in prim_nrm on either of its paths: the runs read it as
   kept).  Once a tree (t->ball_known); without the memory, or with no
   ball_in 1, none (vis_row without its runs). */
static void ball_runs_known(rtp_tree *t)
{
    const rtp_scene *s = t->scene;
    size_t n;
    int any = 0;
    t->ball_known = 1;
    t->ball_sph = (unsigned char *)rtpi_calloc_array(&t->alloc, s->nspheres, 1);
    if (!t->ball_sph)
        return;
    for (n = 0; n < t->nnodes; n++)
        if (t->ball_in[n] == 1) {
            t->ball_sph[t->nodes[n].prim - s->ntris] = 1;
            any = 1;
        }
    if (!any) { /* (none: no move asks the spheres) */
        rtpi_free(&t->alloc, t->ball_sph);
        t->ball_sph = NULL;
    }
}

/* Whether vis_row's runs serve light lv's move: some node's ball_in 1
   on a sphere the light is outside of, two-sided (else every run would
   leave its nodes to the walk, in the copy that tests for them). */
static int ball_runs_serve(const rtp_tree *t, const light_vis *lv)
{
    const rtp_scene *s = t->scene;
    size_t i;
    if (!lv->balls || !t->ball_in || !t->prim_nrm || !t->ball_sph)
        return 0;
    for (i = 0; i < s->nspheres; i++)
        if (t->ball_sph[i] && lv->balls[i] &&
            rtpi_two_sided(s, t->spd, (uint32_t)(s->ntris + i), &s->mats[s->spheres[i].mat]))
            return 1;
    return 0;
}

/* Decides lv's light for every node of t's sample rows into t->cur_vis
   (vis_row); st (may be NULL) counts the queries and the light.  0, 1
   out of memory, 2 cancelled (some rows decided, the rest not). */
static int light_vis_rows(rtp_tree *t, const light_vis *lv, double off_floor, int prim_floor,
                          void (*progress)(void *, double), int (*cancel)(void *), void *user,
                          rtp_eval_stats *st)
{
    const double *lp = t->scene->lights[lv->light].pos;
    int k, rows, kb, threads = lv->threads;
    /* (on the heap: 256 on the stack were a 37 KB frame) */
    vis_ctx *vc = (vis_ctx *)rtpi_malloc_array(&t->alloc, (size_t)threads, sizeof *vc);
    void **ctx = (void **)rtpi_malloc_array(&t->alloc, (size_t)threads, sizeof *ctx);
    if (!vc || !ctx) {
        rtpi_free(&t->alloc, vc);
        rtpi_free(&t->alloc, ctx);
        return 1;
    }
    for (k = 0; k < threads; k++) {
        vc[k].t = t;
        vc[k].sh = lv->sh;
        vc[k].ball_own = rtpi_shadow_ball_own(lv->sh);
        vc[k].lp = v3(lp[0], lp[1], lp[2]);
        vc[k].off_floor = off_floor;
        vc[k].prim_floor = prim_floor;
        vc[k].light = lv->light;
        vc[k].queries = 0;
        vc[k].balls = lv->balls;
        memset(&vc[k].cache, 0, sizeof vc[k].cache);
        vc[k].keep_balls = lv->mode == RTP_SHADOWS_EXACT;
        vc[k].kd_from = lv->mode == RTP_SHADOWS_EXACT ? t->kd_from : NULL;
        vc[k].kd = t->kd;
        /* (its smooth entries read ev_nv: made and used only with it) */
        vc[k].vrec = t->ev_valid && t->ev_nv ? t->vrec : NULL;
        ctx[k] = &vc[k];
    }
    /* (the runs' copy where ball_in has 1s: vis_row_body's kb) */
    kb = ball_runs_serve(t, lv);
    rows = rtpi_parallel_rows_cancel(t->ny, threads, ctx,
                                     vc[0].kd_from ? kb ? vis_row_kf_kb : vis_row_kf
                                     : kb          ? vis_row_kb
                                                   : vis_row,
                                     progress, cancel, user, rtpi_trace_stack(t->max_depth));
    if (rows == 0 && lv->balls && t->ball_in && t->prim_nrm && !t->ball_known)
        ball_runs_known(t);
    if (rows != 2 && lv->mode == RTP_SHADOWS_LIGHTBUF) {
        double q = 0.0;
        for (k = 0; k < threads; k++)
            q += (double)vc[k].queries;
        t->lb_queries = q;
        t->lb_queries_known = 1;
    }
    if (rows != 2 && st) {
        st->moved_lights++;
        st->shadows = (rtp_shadow_mode)lv->mode;
        st->shadow_res = lv->res;
        for (k = 0; k < threads; k++)
            st->shadow_queries += vc[k].queries;
    }
    rtpi_free(&t->alloc, vc);
    rtpi_free(&t->alloc, ctx);
    return rows == 2 ? 2 : 0;
}

/* Brings cur_vis up to date for every light: recorded bits where a light
   is where it was traced, new decisions where it moved, by shadow mode
   `mode` (not AUTO) at `res` cells.  Only lights whose position (or the
   shadow mode's key, vis_key) changed since the last call are redone.
   limit: the bytes a light buffer's lists may take; where they would take
   more, `fallback` (LV_ bits) takes shadow rays for that light (AUTO) or
   coarser cells (a resolution not asked), else RTP_ERR_LIMIT. */
static rtp_status update_visibility_body(rtp_tree *t, int mode, int res, int threads,
                                         double limit, int fallback, const progress_part *prog,
                                         rtp_eval_stats *st, rtp_error *err);

static void kd_from_make(rtp_tree *t, size_t nl, double limit);
static int vrec_make(rtp_tree *t, size_t nl, double limit);
static void vrec_free(rtp_tree *t);

static rtp_status update_visibility(rtp_tree *t, int mode, int res, int threads,
                                    double limit, int fallback, const progress_part *prog,
                                    rtp_eval_stats *st, rtp_error *err)
{
    int kmode, kres, same;
    size_t i;
    rtp_status rs;
    vis_key(mode, res, &kmode, &kres);
    same = t->cur_vis && t->cur_mode == kmode && t->cur_res == kres;
    rs = update_visibility_body(t, mode, res, threads, limit, fallback, prog, st, err);
    if (rs != RTP_OK && !same && t->cur_vis) {
        /* The lights decided before it stopped (cancelled, out of memory,
           over the limit) were decided by this mode, while the mode on
           file (cur_mode, cur_res) is the last whole call's: as nothing
           decided, every moved light (an exact evaluation after a
           cancelled item-buffer one had kept a light's item-buffer
           bits). */
        for (i = 0; i < t->cur_nl; i++)
            if (light_moved(t, i))
                t->cur_pos[3 * i] = NAN;
    }
    return rs;
}

static rtp_status update_visibility_body(rtp_tree *t, int mode, int res, int threads,
                                         double limit, int fallback, const progress_part *prog,
                                         rtp_eval_stats *st, rtp_error *err)
{
    const int mode_asked = mode;
    rtp_scene *s = t->scene;
    size_t nl = s->nlights, words = (nl + 31) / 32, i, n, todo = 0, done = 0;
    double off_floor;
    int prim_floor;
    int kmode, kres;
    vis_key(mode, res, &kmode, &kres);
    if (threads < 1)
        threads = 1;
    if (threads > RTPI_MAX_THREADS)
        threads = RTPI_MAX_THREADS;
    if (t->cur_vis && (t->cur_words != words)) {
        rtpi_free(&t->alloc, t->cur_vis);
        rtpi_free(&t->alloc, t->cur_pos);
        t->cur_vis = NULL;
        t->cur_pos = NULL;
    }
    if (!t->cur_vis) {
        t->cur_vis = (uint32_t *)rtpi_calloc_array(&t->alloc, t->nnodes ? t->nnodes * words : 1,
                                                    sizeof *t->cur_vis);
        t->cur_pos = (double *)rtpi_malloc_array(&t->alloc, nl * 3, sizeof *t->cur_pos);
        if (!t->cur_vis || !t->cur_pos) {
            rtpi_free(&t->alloc, t->cur_vis);
            rtpi_free(&t->alloc, t->cur_pos);
            t->cur_vis = NULL;
            t->cur_pos = NULL;
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        t->cur_words = words;
        t->cur_nl = nl;
        for (i = 0; i < nl; i++)
            t->cur_pos[3 * i] = NAN; /* nothing decided yet */
        /* the first move: the triangles' normals (without them vis_row
           derives each hit's) */
        if (!t->tri_nrm && tri_normals(t) != 0)
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        /* (and for a scene with spheres the nodes' ball_in, found as
           vis_row meets them) */
        if (s->nspheres && !t->ball_in &&
            !(t->ball_in = (unsigned char *)rtpi_calloc_array(&t->alloc, t->nnodes + 1, 1)))
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        /* (and for a scene with spheres or cones the nodes' normals on
           them, kept as vis_row meets them: a cone's two square roots
           and divisions were a third of rings_s7's vis_row; without the
           memory each move derives them) */
        if ((s->nspheres || s->ncones) && !t->prim_nrm)
            t->prim_nrm = (double *)rtpi_calloc_array(&t->alloc, 3 * t->nnodes + 1,
                                                      sizeof *t->prim_nrm);
        /* (and their queries' own answer on cones: rtpi_cone_shadows_own,
           ~64 instructions a query, was 3% of rings_s7's moves) */
        if ((s->ncones || s->nspheres) && t->prim_nrm && !t->cone_own)
            t->cone_own = (unsigned char *)rtpi_calloc_array(&t->alloc, t->nnodes + 1, 1);
    }
    if (nl > t->cur_nl) {
        /* lights added since (within the same visibility words): their
           places, nothing decided */
        double *p = (double *)rtpi_realloc(&t->alloc, t->cur_pos, nl * 3 * sizeof *t->cur_pos);
        if (!p)
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        t->cur_pos = p;
        for (i = t->cur_nl; i < nl; i++)
            t->cur_pos[3 * i] = NAN;
        t->cur_nl = nl;
    }
    /* (the moved lights to decide share the progress this step reports) */
    for (i = 0; i < nl; i++)
        todo += light_moved(t, i) && !vis_up_to_date(t, i, kmode, kres);
    /* (trace's floor for the shadow rays' origins: the same rays) */
    /* (once a tree: a pass over the scene's every coordinate, rings_s7
       0.15% of a move) */
    if (todo && !t->floor_ok) {
        t->off_floor = rtpi_offset_floor(s, &t->prim_floor);
        t->floor_ok = 1;
    }
    prim_floor = todo ? t->prim_floor : 0;
    off_floor = todo ? t->off_floor : 0.0;
    for (i = 0; i < nl; i++) {
        const double *lp = s->lights[i].pos;
        int moved = light_moved(t, i);
        progress_part part, bpart;
        rtpi_poll poll;
        if (vis_up_to_date(t, i, kmode, kres))
            continue;
        if (!moved) {
            for (n = 0; n < t->nnodes; n++) {
                uint32_t *w = &t->cur_vis[n * words + (i >> 5)];
                *w = (*w & ~(1u << (i & 31))) | recorded_bit(t, n, i) << (i & 31);
            }
        } else {
            light_vis lv;
            rtp_status rs;
            int rows, vnew;
            /* (the caller's cancel on either side of the kd-tree's or the
               buffer's build and after each row: a moved light of a
               large mesh takes seconds) */
            if (part_cancelled(prog))
                return rtpi_cancelled(err);
            /* this light's share of the step's progress: a direction
               cube's build the first half of it (a fine cube takes
               seconds: the bunny's light buffer at 8192 cells 3 s), the
               decisions' rows the rest */
            part = *prog;
            part.lo = prog->lo + prog->span * (double)done / (double)todo;
            part.span = prog->span / (double)todo;
            done++;
            bpart = part;
            bpart.span = mode_asked != RTP_SHADOWS_EXACT ? 0.5 * part.span : 0.0;
            poll.progress = part.fn ? progress_part_cb : NULL;
            poll.cancel = part.cancel ? progress_part_cancel : NULL;
            poll.user = &bpart;
            part.lo += bpart.span;
            part.span -= bpart.span;
            if ((rs = light_vis_make(t, i, mode_asked, res, threads, limit, fallback, &poll, &lv,
                                     err)) != RTP_OK)
                return rs;
            if (part_cancelled(prog)) {
                light_vis_free(t, &lv);
                return rtpi_cancelled(err);
            }
            if (lv.mode == RTP_SHADOWS_EXACT)
                kd_from_make(t, nl, limit);
            vnew = t->ev_valid && t->ev_nv && vrec_make(t, nl, limit);
            rows = light_vis_rows(t, &lv, off_floor, prim_floor, part.fn ? progress_part_cb : NULL,
                                  part.cancel ? progress_part_cancel : NULL, &part, st);
            light_vis_free(t, &lv);
            if (rows == 2) {
                /* some rows hold the new decisions, the rest the old: the
                   light is decided anew at the next evaluation, wherever
                   it then is (its place as nothing decided); a record
                   made for this move goes with it (a cancelled move
                   leaves no memory behind) */
                t->cur_pos[3 * i] = NAN;
                if (vnew)
                    vrec_free(t);
                return rtpi_cancelled(err);
            }
            if (rows != 0)
                return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        t->cur_pos[3 * i] = lp[0];
        t->cur_pos[3 * i + 1] = lp[1];
        t->cur_pos[3 * i + 2] = lp[2];
    }
    t->cur_mode = kmode;
    t->cur_res = kres;
    return RTP_OK;
}

/* ----------------------------------------------------------- evaluation */

/* Caches are kept for up to this many lights, or for more where they
   take at most EV_CACHE_BYTES (ev_cache_bytes): beyond, every evaluation
   works per sample from scratch, as trace does.  (A count alone dropped
   them for 65 lights on any tree: every line of a stream evaluated the
   whole frame, a blank one too, 250-1450 ms at 512x512 against a few;
   1000 lights at 64x64 take 80 MB of them.) */
#define EV_MAX_LIGHTS 64
#define EV_CACHE_BYTES (1024.0 * 1048576.0)

/* Bytes the evaluation caches take for nl lights (ev_terms, ev_coeffs,
   ev_nv, ev_w). */
static double ev_cache_bytes(const rtp_tree *t, size_t nl, size_t ns)
{
    return (double)t->nnodes * ((double)RTPI_TERMS(nl) * 4.0 + 6.0 * 4.0 + 8.0) +
           (double)ns * (double)RTPI_COEFFS(nl) * 4.0;
}

/* t->kd_from and the kd-tree's leaf lists for exact moves' walks from
   their origins' leaves (rtpi_kd_paths_make), where they fit the memory
   limit with the evaluation's caches (as mv_kc_check: 4 bytes a node and
   the lists, 9 entries of 8 bytes a kd leaf and 4 an ancestor: 2.3-6.6
   MB for the SPD scenes, gears_s4's 37.6); without them every walk
   starts at the root (the same answers).  Made anew (all zero: found
   again) where a material's kt went from or to 0 since: an SPD tree's
   back hits then turn their normal (rtpi_two_sided), and their origins
   move to the other side. */
static void kd_from_make(rtp_tree *t, size_t nl, double limit)
{
    const rtp_scene *s = t->scene;
    size_t m;
    int same = t->kd_from && t->kd_from_kt && t->kd_from_nmats == s->nmats;
    for (m = 0; same && m < s->nmats; m++)
        same = t->kd_from_kt[m] == (s->mats[m].kt > 0.0f);
    if (same)
        return;
    if (!t->kd_from) {
        double bytes = rtpi_kd_paths_bytes(t->kd) + 4.0 * (double)t->nnodes;
        if (!(ev_cache_bytes(t, nl, (size_t)t->nx * t->ny) + bytes <=
              fmin(EV_CACHE_BYTES, limit)) ||
            rtpi_kd_paths_make(t->kd) != 0)
            return;
        t->kd_from =
            (uint32_t *)rtpi_calloc_array(&t->alloc, t->nnodes + 1, sizeof *t->kd_from);
    } else {
        memset(t->kd_from, 0, (t->nnodes + 1) * sizeof *t->kd_from);
    }
    if (t->kd_from && (!t->kd_from_kt || t->kd_from_nmats != s->nmats)) {
        rtpi_free(&t->alloc, t->kd_from_kt);
        t->kd_from_kt = (unsigned char *)rtpi_malloc_array(&t->alloc, s->nmats + 1, 1);
    }
    if (!t->kd_from || !t->kd_from_kt) {
        rtpi_free(&t->alloc, t->kd_from);
        rtpi_free(&t->alloc, t->kd_from_kt);
        t->kd_from = NULL;
        t->kd_from_kt = NULL;
        return;
    }
    for (m = 0; m < s->nmats; m++)
        t->kd_from_kt[m] = s->mats[m].kt > 0.0f;
    t->kd_from_nmats = s->nmats;
}

static void vrec_free(rtp_tree *t)
{
    rtpi_free(&t->alloc, t->vrec);
    rtpi_free(&t->alloc, t->vrec_mat);
    t->vrec = NULL;
    t->vrec_mat = NULL;
}

/* What t->vrec's entries of material m's nodes hold for: its
   two-sidedness (an SPD tree's opaque back hits keep their normal,
   rtpi_two_sided: kt > 0 turns it) and whether it is bumped, as the
   materials now and the evaluation's (ev_mats, the smooth triangles'
   ns from ev_nv only where neither is; where no evaluation holds its
   caches the materials' alone, ev_nv then none and no smooth entry used
   or made). */
static unsigned char vrec_key(const rtp_tree *t, size_t m)
{
    const rtpi_material *mt = &t->scene->mats[m];
    int bump = mt->bump != RTPI_BUMP_NONE;
    int ev_bump = t->ev_valid && t->ev_mats ? t->ev_mats[m].bump != RTPI_BUMP_NONE : bump;
    return (unsigned char)((mt->kt > 0.0f) | bump << 1 | ev_bump << 2);
}

/* t->vrec for a move: made at the first whose evaluation caches are
   there (ev_nv: a one-off move, the tree's first evaluation, makes none),
   every kind 0 (each node's made as vis_row meets it), where it fits
   the memory limit with the evaluation's caches and the other per-node
   ones; made anew where some material's vrec_key changed since (a bump;
   a kt edit turning an SPD tree's back faces over, which also traces
   them again: the re-trace frees it with the nodes); without the memory,
   none: every node's full steps, the same answers.  9 bytes a node
   (mount_s6 at 512x512 5.9 MB: 32, the normals in it too, saved more
   instructions but took more time, the memory read each move).  1 where
   it was made now. */
static int vrec_make(rtp_tree *t, size_t nl, double limit)
{
    const rtp_scene *s = t->scene;
    size_t m, n = t->nnodes + 1;
    int same = t->vrec && t->vrec_mat && t->vrec_nmats == s->nmats, made = 0;
    for (m = 0; same && m < s->nmats; m++)
        same = t->vrec_mat[m] == vrec_key(t, m);
    if (same)
        return 0;
    if (!t->vrec) {
        double bytes = ev_cache_bytes(t, nl, (size_t)t->nx * t->ny) +
                       9.0 * (double)t->nnodes + (t->mv_kc ? 24.0 * (double)t->nnodes : 0.0) +
                       (t->kd_from ? 4.0 * (double)t->nnodes + rtpi_kd_paths_bytes(t->kd) : 0.0);
        if (!t->nnodes || !(bytes <= fmin(EV_CACHE_BYTES, limit)))
            return 0;
        made = 1;
        t->vrec = (double *)rtpi_malloc_array(&t->alloc, n, sizeof *t->vrec + 1);
    }
    if (t->vrec) /* (the kinds alone: a step is read only where its kind is known) */
        memset(t->vrec + n, 0, n);
    if (t->vrec && (!t->vrec_mat || t->vrec_nmats != s->nmats)) {
        rtpi_free(&t->alloc, t->vrec_mat);
        t->vrec_mat = (unsigned char *)rtpi_malloc_array(&t->alloc, s->nmats + 1, 1);
    }
    if (!t->vrec || !t->vrec_mat) {
        vrec_free(t);
        return 0;
    }
    for (m = 0; m < s->nmats; m++)
        t->vrec_mat[m] = vrec_key(t, m);
    t->vrec_nmats = s->nmats;
    return made;
}

/* Float images carry 2^-24 of the magnitudes they are summed from: where
   those pass CP_SPAN times a value (and CP_SPAN * 2: below, the error
   stays under 2^-21 absolute, 5e-7), the value lost digits to
   cancellation (a colour or kd cut from thousands to a fraction), and
   the full path makes the image instead (hl_build, pk_put, cp_lost). */
#define CP_SPAN 4.0

/* Colour planes kept at most (16 bytes a pixel each): with more terms
   edited, the least recently used give way; with more differing from S
   at once, the full path makes the image. */
#define CP_MAX_PLANES 8

typedef struct eval_ctx {
    rtp_tree *t;
    const rtpi_shade_ctx *shade;
    const uint32_t *vis;      /* visibility words per node, or NULL */
    rtpi_v3 eye;
    const double *cl;         /* light colours */
    float *samples;
    const uint32_t *list;     /* samples to redo (NULL: all) */
    size_t nlist, chunk;
    size_t light;             /* light_row: the light to redo */
    int spec_only;            /* redo_chunk: mat's light terms alone */
    int combine_too;          /* redo_chunk: step 3 for the sample too */
    /* one-term path */
    const double *cv;         /* colours of every term */
    size_t term;              /* the colour term edited */
    int pk_mat;               /* a material's kd * colour is edited */
    uint32_t mat;             /* that material */
    double xold[3];           /* its kd * colour in the coefficients */
    const double *x;          /* the term's value now */
    const float *kp;          /* K per sample: kp + k kstride */
    size_t kstride;
    float *pixels;            /* the image */
    int redo_terms;           /* recompute terms too, not only coeffs */
    int cached;               /* ev_terms / ev_coeffs in use */
    /* per thread scratch (uncached path and coefficient sums) */
    const rtp_allocator *wa;  /* what rows grow terms with: t->alloc, behind
                                 a lock when threads share a caller's */
    float *terms;
    size_t terms_cap;
    float *coeffs;
    double *acc;
    int nomem;
    int nonfinite;            /* pk_put met a plane value that is not finite */
    float *rest;              /* pk_build_chunk: two sample rows' rest */
    int coef_bad;             /* a coefficient made was not finite */
    unsigned long long combined; /* light_row, cp_full_pixel: samples it combined */
    unsigned char *mark;      /* light_row (may be NULL): 1 for each
                                 sample it combined (t->ev_mark) */
    unsigned long long written; /* mark_row: pixels it wrote */
    double *mv_rest;          /* light_row (may be NULL): t->mv_rest */
    double *mv_kc;            /* light_row (may be NULL): t->mv_kc */
    size_t rest_bytes;
    int pk_pack;              /* pk_img_chunk: bands in order, each band's
                                 entries right after the band before's */
    float *qgrid;             /* pk_img_chunk: a band's q (corner samples:
                                 in a grid of its rows, 0 between uses) */
    int qk_band;              /* pk_img_chunk: the band whose first sample
                                 row qgrid's row 0 holds (its band before's
                                 last, kept), -1 for none */
    size_t qk_lo, qk_hi;      /* that row's list entries */
    /* cp_plane_chunk: the terms whose planes it makes (cp_planes), and
       per term the largest |K| per channel */
    const size_t *cp_terms;
    size_t cp_n;
    double kmax[3 * CP_MAX_PLANES];
} eval_ctx;

/* Steps 1 and 2 for sample k, into the caches or the scratch. */
static int sample_coeffs(eval_ctx *e, size_t k, int redo_terms, float **coeffs_out)
{
    rtp_tree *t = e->t;
    size_t nl = t->scene->nlights, a = (size_t)t->start[k];
    size_t n = (size_t)(t->start[k + 1] - t->start[k]), words = e->shade->vis_words;
    float *terms, *coeffs;
    if (e->cached) {
        terms = t->ev_terms + a * RTPI_TERMS(nl);
        coeffs = t->ev_coeffs + k * RTPI_COEFFS(nl);
    } else {
        if (rtpi_grow(e->wa, (void **)&e->terms, &e->terms_cap, n * RTPI_TERMS(nl) + 1,
                      sizeof *e->terms)) {
            e->nomem = 1;
            return -1;
        }
        terms = e->terms;
        coeffs = e->coeffs;
        redo_terms = 1;
    }
    /* (coefficients near the float range count as not finite too: the
       planes then give way needlessly, which is safe) */
    if (redo_terms)
        e->coef_bad |= !rtpi_sample_eval(e->shade, t->nodes + a, n,
                                         e->vis ? e->vis + a * words : NULL, e->eye, terms,
                                         e->cached ? t->ev_nv + 6 * a : NULL, e->acc, coeffs,
                                         e->cached ? t->ev_w + a : NULL);
    else
        e->coef_bad |= !rtpi_sample_coeffs(e->shade, t->nodes + a, n, terms, e->acc, coeffs,
                                           e->cached ? t->ev_w + a : NULL);
    *coeffs_out = coeffs;
    return 0;
}

/* A row of samples, every step (first evaluation or uncached). */
static int eval_row(void *ctx, int y)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    const rtpi_shade_ctx *sh = e->shade;
    const size_t nl = t->scene->nlights, nt = RTPI_TERMS(nl), nc = RTPI_COEFFS(nl);
    const size_t words = sh->vis_words, nx = (size_t)t->nx;
    const uint64_t *st = t->start + (size_t)y * nx;
    size_t k = (size_t)y * nx, x, a = (size_t)st[0], i;
    float *o = e->samples + 3 * k, bg[3];
    int bg_ok = 0, bad = 0;
    /* (the cached path's pointers by the row, not sample_coeffs' call
       and its reloads a sample, 90 instructions each: mount_s6's first
       evaluation 375.8 -> 367.6 M) */
    for (x = 0; x < nx; x++, k++, o += 3) {
        size_t b = (size_t)st[x + 1], n = b - a;
        float *coeffs = e->cached ? t->ev_coeffs + k * nc : e->coeffs;
        if (n == 0) {
            /* The background: rtpi_sample_coeffs' coefficients for no
               node (G 1, the rest 0), and so one colour for every such
               sample, combined once a row.  The steps' calls and sums
               were about 230 instructions a sample, 81% of tetra_s6's
               samples at 512 SPD (a first evaluation 120.0 -> 64.4 M). */
            coeffs[0] = coeffs[1] = coeffs[2] = 1.0f;
            for (i = 3; i < nc; i++)
                coeffs[i] = 0.0f;
            if (!bg_ok) {
                rtpi_combine(t->scene, e->cl, coeffs, bg);
                bg_ok = 1;
            }
            o[0] = bg[0];
            o[1] = bg[1];
            o[2] = bg[2];
            continue;
        }
        if (e->cached) {
            /* sample_coeffs' steps 1 and 2 into the caches */
            bad |= !rtpi_sample_eval(sh, t->nodes + a, n, e->vis ? e->vis + a * words : NULL,
                                     e->eye, t->ev_terms + a * nt, t->ev_nv + 6 * a, e->acc,
                                     coeffs, t->ev_w + a);
        } else if (sample_coeffs(e, k, 1, &coeffs)) {
            return 1;
        }
        rtpi_combine(t->scene, e->cl, coeffs, o);
        a = b;
    }
    e->coef_bad |= bad;
    return 0;
}

/* Sample k's image from its coefficients, in double, in the order
   rtpi_combine sums. */
static void rest_of(const double *cv, size_t nc, const float *coeffs, double v[3])
{
    /* each channel summed over the terms in ascending order, as before,
       the three side by side (a third of the loop's steps) */
    double a0 = 0.0, a1 = 0.0, a2 = 0.0;
    size_t i;
    for (i = 0; i < nc; i += 3) {
        a0 += coeffs[i] * cv[i];
        a1 += coeffs[i + 1] * cv[i + 1];
        a2 += coeffs[i + 2] * cv[i + 2];
    }
    if (a0 != a0 || a1 != a1 || a2 != a2) {
        /* rtpi_combine's rule: a colour of 0 adds nothing */
        a0 = a1 = a2 = 0.0;
        for (i = 0; i < nc; i += 3) {
            a0 = RTPI_TERM_SUM(a0, coeffs[i], cv[i]);
            a1 = RTPI_TERM_SUM(a1, coeffs[i + 1], cv[i + 1]);
            a2 = RTPI_TERM_SUM(a2, coeffs[i + 2], cv[i + 2]);
        }
    }
    v[0] = a0;
    v[1] = a1;
    v[2] = a2;
}

/* One pixel: P + K x. */
static void pk_pixel(const float *pk, const double *x, float *out)
{
    out[0] = (float)(pk[0] + pk[3] * x[0]);
    out[1] = (float)(pk[1] + pk[4] * x[1]);
    out[2] = (float)(pk[2] + pk[5] * x[2]);
}

/* ------------------------------------------------------- highlights
   A shine edit changes the highlights (r.v)^shine of one material's nodes
   and nothing else of step 1, and each sample's colour is affine in them:
   colour = P + sum W s over the sample's highlights s of that material,
   with W = path weight * ks * light colour.  Consecutive shine edits of a
   material keep the list of its highlights that are not 0 (per sample of
   the material: log2 (r.v), W, and P from the coefficients the caches
   hold), and each edit sets every term to 2^(shine log2 (r.v)) (within a
   float ulp of pow's) and the samples' colours from them: no lights or
   mirror vectors derived anew, no coefficients summed.  The coefficients
   stay those of the shine before, as with a material's kd (mat_term). */

/* Lists material m's highlights over its samples (serially); 0, or -1
   when out of memory (the list is then not used).  cl: light colours. */
static int hl_build(rtp_tree *t, const rtpi_shade_ctx *shade, const uint32_t *vis, uint32_t m,
                    const double *cl, const double *cv)
{
    const rtp_allocator *al = &t->alloc;
    size_t j, nl = t->scene->nlights, nc = RTPI_COEFFS(nl), nt = RTPI_TERMS(nl);
    size_t nlist = t->mat_start[m + 1] - t->mat_start[m], wcap = 0;
    double ks = t->scene->mats[m].ks, *w = NULL;
    t->hl_mat = 0;
    t->hl_n = 0;
    rtpi_free(al, t->hl_off);
    rtpi_free(al, t->hl_p);
    t->hl_off = (size_t *)rtpi_malloc_array(al, nlist + 1, sizeof *t->hl_off);
    t->hl_p = (float *)rtpi_malloc_array(al, nlist + 1, 3 * sizeof *t->hl_p);
    if (!t->hl_off || !t->hl_p)
        return -1;
    for (j = 0; j < nlist; j++) {
        size_t k = t->mat_samples[t->mat_start[m] + j], a = (size_t)t->start[k];
        size_t n = (size_t)(t->start[k + 1] - a), cap = t->hl_cap, cap2 = t->hl_cap;
        size_t cap3 = t->hl_cap, e0 = t->hl_n, e;
        double pv[3], ws[3] = {0.0, 0.0, 0.0};
        int c, finite = 1;
        if (n > ((size_t)-1 - t->hl_n) / (nl + 1) ||
            rtpi_grow(al, (void **)&t->hl_idx, &cap, t->hl_n + n * nl + 1, sizeof *t->hl_idx) ||
            rtpi_grow(al, (void **)&t->hl_lrv, &cap2, t->hl_n + n * nl + 1, sizeof *t->hl_lrv) ||
            rtpi_grow(al, (void **)&t->hl_w, &cap3, t->hl_n + n * nl + 1, 4 * sizeof *t->hl_w) ||
            rtpi_grow(al, (void **)&w, &wcap, n + 1, sizeof *w)) {
            t->hl_cap = cap < cap2 ? cap : cap2;
            t->hl_cap = t->hl_cap < cap3 ? t->hl_cap : cap3;
            rtpi_free(al, w);
            return -1;
        }
        t->hl_cap = cap < cap2 ? cap : cap2;
        t->hl_cap = t->hl_cap < cap3 ? t->hl_cap : cap3;
        t->hl_off[j] = e0;
        rtpi_material_highlights(shade, t->nodes + a, n, a,
                                 vis ? vis + a * shade->vis_words : NULL, t->ev_nv + 6 * a, m,
                                 t->hl_idx, t->hl_lrv, &t->hl_n);
        /* W per highlight, and P: the sample's colour from the cached
           coefficients less what these highlights (as the terms hold them
           now) add to it */
        rtpi_sample_weights(shade, t->nodes + a, n, w);
        rest_of(cv, nc, t->ev_coeffs + k * nc, pv);
        for (e = e0; e < t->hl_n; e++) {
            size_t node = t->hl_idx[e] / nt, li = (t->hl_idx[e] % nt - 4) / 2;
            double sold = t->ev_terms[t->hl_idx[e]];
            for (c = 0; c < 3; c++) {
                float wc = (float)(w[node - a] * ks * cl[3 * li + c]);
                t->hl_w[4 * e + c] = wc;
                pv[c] -= wc * sold;
                ws[c] += fabs(wc * sold);
                finite &= isfinite(wc);
            }
            t->hl_w[4 * e + 3] = (float)sold; /* (a float term) */
        }
        for (c = 0; c < 3; c++) {
            double pa = fabs(pv[c]);
            t->hl_p[3 * j + c] = (float)pv[c];
            finite &= isfinite(t->hl_p[3 * j + c]);
            /* P lost digits where the highlights were far above it */
            finite &= pa + 2.0 * ws[c] <= CP_SPAN * (pa > 2.0 ? pa : 2.0);
        }
        /* P or W beyond the float range (values near it, as with the
           planes: pk_put), or P without its digits: the list is not used */
        if (!finite) {
            rtpi_free(al, w);
            return -1;
        }
    }
    t->hl_off[nlist] = t->hl_n;
    rtpi_free(al, w);
    t->hl_mat = (int)m + 1;
    /* the samples hold the colours of the caches' shine (hl_after below
       has them at the scene's, which the caches are about to take) */
    t->hl_shine = t->ev_mats[m].shine;
    return 0;
}

/* The listed highlights' terms back to the shine the coefficients (and
   ev_mats) still have, and the list dropped.  A chain of shine edits moves
   those terms and the material's samples along with each edit but leaves
   the coefficients as they were; any other evaluation must first find
   terms and coefficients agreeing again.  The material's samples still
   hold the chain's colours: the caller redoes them.  Returns the
   material. */
static int hl_restore(rtp_tree *t)
{
    size_t q;
    int m = t->hl_mat - 1;
    for (q = 0; q < t->hl_n; q++)
        t->ev_terms[t->hl_idx[q]] = t->hl_w[4 * q + 3];
    t->hl_mat = 0;
    return m;
}

/* A chunk of 4096 listed highlights set for the new shine. */
static int hl_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t i = (size_t)chunk * 4096, end = i + 4096;
    double shine = t->scene->mats[e->mat].shine;
    if (end > t->hl_n)
        end = t->hl_n;
    for (; i < end; i++)
        t->ev_terms[t->hl_idx[i]] = (float)exp2(shine * t->hl_lrv[i]);
    return 0;
}

/* A chunk of 256 of the material's samples: their highlights for the new
   shine and their colours P + sum W s. */
static int hl_apply_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t j = (size_t)chunk * 256, end = j + 256, q;
    double shine = t->scene->mats[e->mat].shine;
    if (end > e->nlist)
        end = e->nlist;
    for (; j < end; j++) {
        double v0 = t->hl_p[3 * j], v1 = t->hl_p[3 * j + 1], v2 = t->hl_p[3 * j + 2];
        float *out = e->samples + 3 * (size_t)e->list[j];
        for (q = t->hl_off[j]; q < t->hl_off[j + 1]; q++) {
            float sp = (float)exp2(shine * t->hl_lrv[q]);
            const float *wq = t->hl_w + 4 * q;
            t->ev_terms[t->hl_idx[q]] = sp;
            v0 += wq[0] * sp;
            v1 += wq[1] * sp;
            v2 += wq[2] * sp;
        }
        out[0] = (float)v0;
        out[1] = (float)v1;
        out[2] = (float)v2;
    }
    return 0;
}

/* A chunk of a material's sample list: steps 1 (if needed) and 2. */
static int redo_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    size_t i = (size_t)chunk * e->chunk, end = i + e->chunk;
    if (end > e->nlist)
        end = e->nlist;
    for (; i < end; i++) {
        rtp_tree *t = e->t;
        size_t k = e->list[i];
        float *coeffs;
        if (e->spec_only) {
            size_t a = (size_t)t->start[k];
            rtpi_material_light_terms(e->shade, t->nodes + a, (size_t)(t->start[k + 1] - a),
                                      e->vis ? e->vis + a * e->shade->vis_words : NULL,
                                      t->ev_nv + 6 * a, e->mat,
                                      t->ev_terms + a * RTPI_TERMS(t->scene->nlights));
        }
        if (sample_coeffs(e, k, e->redo_terms, &coeffs))
            return 1;
        if (e->combine_too) /* the other samples' colours are kept */
            rtpi_combine(t->scene, e->cl, coeffs, e->samples + 3 * k);
    }
    return 0;
}

/* t->ev_mark holds a byte a sample (and 8 more), then a byte a sample
   row: 1 where the row has a mark, so that mark_row passes over rows
   without any and only those rows are cleared (tetra at 512x512: a moved
   light marks 5% of the samples, on 410 of the 513 rows). */
static size_t mark_rows_at(const rtp_tree *t)
{
    return (size_t)t->nx * t->ny + 8;
}

/* Clears the marks and the rows' flags (all 0 between evaluations). */
static void marks_clear(rtp_tree *t)
{
    unsigned char *rows = t->ev_mark + mark_rows_at(t);
    size_t y;
    for (y = 0; y < (size_t)t->ny; y++)
        if (rows[y]) {
            memset(t->ev_mark + y * t->nx, 0, (size_t)t->nx);
            rows[y] = 0;
        }
}

/* The columns *lo .. *hi - 1 of sample row r from its first sample with
   nodes to its last (*lo == *hi: none).  start rises with the sample and
   a sample has nodes where it rises after it, so two bisections find
   them. */
static void row_nodes(const rtp_tree *t, size_t r, size_t *lo, size_t *hi)
{
    const uint64_t *st = t->start;
    size_t k0 = r * (size_t)t->nx, k1 = k0 + (size_t)t->nx, a, b;
    const uint64_t s0 = st[k0], s1 = st[k1];
    *lo = *hi = 0;
    if (s0 == s1)
        return; /* a row of background */
    for (a = k0 + 1, b = k1; a < b;) {
        size_t mid = a + (b - a) / 2;
        if (st[mid] > s0)
            b = mid;
        else
            a = mid + 1;
    }
    *lo = a - 1 - k0; /* st[a] > s0: sample a - 1 has nodes, none before */
    for (a = k0 + *lo, b = k1; a < b;) {
        size_t mid = a + (b - a) / 2;
        if (st[mid] < s1)
            a = mid + 1;
        else
            b = mid;
    }
    *hi = a - k0; /* st[a - 1] < s1: sample a - 1 has nodes, none after */
}

/* One light's terms and coefficients for a row of samples, from the
   cached normals and view vectors: what a moved light changes. */
static int light_row(void *ctx, int y)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t k0 = (size_t)y * t->nx, k1, lo, hi;
    const uint64_t *st = t->start;
    unsigned long long n;
    /* the row's first and last samples with nodes: the background on
       either side of the scene is not walked */
    row_nodes(t, (size_t)y, &lo, &hi);
    if (lo == hi)
        return 0; /* a row of background */
    k1 = k0 + hi;
    k0 += lo;
    n = rtpi_light_redo(e->shade, t->nodes, st, k0, k1, e->vis, t->ev_nv, t->ev_w, e->light,
                        t->ev_terms, t->ev_coeffs, e->cl, e->combine_too ? e->samples : NULL,
                        &e->coef_bad, e->mark, e->mv_rest, t->mv_ok, e->mv_kc);
    if (n && e->mark) /* (the row's flag after the marks: mark_rows_at) */
        e->mark[mark_rows_at(t) + (size_t)y] = 1;
    e->combined += n;
    return 0;
}

/* Lights a scene has at least where a moved light keeps the rest of its
   samples' sums (eval_impl). */
#define MV_REST_LIGHTS 3

/* Step 3 only, from the cached coefficients. */
static int combine_row(void *ctx, int y)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t k = (size_t)y * t->nx, nc = RTPI_COEFFS(t->scene->nlights);
    int x;
    for (x = 0; x < t->nx; x++, k++)
        rtpi_combine(t->scene, e->cl, t->ev_coeffs + k * nc, e->samples + 3 * k);
    return 0;
}

/* ----------------------------------------------------- one-term path
   The image is linear in the colours of its terms (background, ambient,
   each light).  While an edit changes the colour of one term alone, every
   pixel is P + K c: P the rest of the image, K the term's coefficient (for
   SPD both averaged over the pixel's four corner samples), fixed until
   something else changes.  The first such edit of a term precombines P
   and K per pixel in one pass over the coefficients (pk_build_chunk);
   each further edit of that term (a script animating a light's colour, a
   slider) reads 24 bytes and writes 12 a pixel whose K is not 0.  P is
   rounded to float once more than the full path rounds, so pixels differ
   from it by about a float ulp of their value.

   The planes are made and kept in bands of PK_ROWS pixel rows, one band
   a task: in band b, pk_c and pk_nz from entry pk_off[b] on hold pk_seg[b]
   pixels whose K is not 0, in pixel order (pk_off[b]: the band's first
   pixel, or where only the material's pixels are made, the entries of
   the bands before: pk_img_chunk, in the samples' block as far as it
   lends room, pk_lend, then in pk_nz's: pk_band); pk holds P of the
   band's other pixels, at their own place. */
#define PK_ROWS 16

/* Band b's planes: entries pk_off[b] on of the block lent by the samples
   (pk_lend) before pk_split, else of pk_nz's own block (with none of that,
   every band lies in the lent one: those of no entries at its end). */
static void pk_band(const rtp_tree *t, int b, float **pc, uint32_t **nz)
{
    size_t o = t->pk_off[b];
    if (o < t->pk_split || !t->pk_nz) {
        uint32_t *ln = (uint32_t *)(void *)t->ev_samples;
        *nz = ln + o;
        *pc = (float *)(void *)(ln + t->pk_split) + 6 * o;
    } else {
        *nz = t->pk_nz + (o - t->pk_split);
        *pc = t->pk_c + 6 * (o - t->pk_split);
    }
}

/* The rest P_s of sample k into out (3 floats): the material's diffuse
   part x q taken off the whole (q: the sample's, 0 where the material is
   not). */
static void pk_rest_one(const eval_ctx *e, size_t k, const float *q, float *out)
{
    size_t nc = RTPI_COEFFS(e->t->scene->nlights);
    double v[3];
    int c;
    rest_of(e->cv, nc, e->t->ev_coeffs + k * nc, v);
    for (c = 0; c < 3; c++)
        out[c] = (float)(v[c] - e->xold[c] * q[c]);
}

/* The same for each sample of sample row y (pk_q 0 where the material is
   not). */
static void pk_rest_into(const eval_ctx *e, int y, float *out)
{
    size_t k = (size_t)y * e->t->nx;
    int x;
    for (x = 0; x < e->t->nx; x++, k++, out += 3)
        pk_rest_one(e, k, e->t->pk_q + 3 * k, out);
}

/* One pixel's planes pk (P then K) into its band: the list where K is
   not 0, else P alone in t->pk.  P and K held as floats overflow where an
   image's values come near the float range (a kt of 1e21 over a few
   bounces: the pixel stays finite, its rest P and coefficient K need
   not); and P = rest - xold q loses digits where xold q is far above P
   (a colour of 10000 cut to 0: the rest, about |P| + |xold K|, carries
   2^-24 of itself).  Then the planes are not used and the edit takes the
   full path. */
static inline int pk_bad(const double *xold, const float *pk)
{
    int c, bad = 0;
    for (c = 0; c < 3; c++) {
        /* (false for a NaN P or K, and for an infinite K: xold K is then
           infinite or NaN; an infinite P fails the second test) */
        double a = fabs(pk[c]);
        bad |= !(a + 2.0 * fabs(xold[c] * pk[3 + c]) <= CP_SPAN * (a > 2.0 ? a : 2.0)) |
               !(a <= FLT_MAX);
    }
    return bad;
}

static inline int pk_guard(eval_ctx *e, const float *pk)
{
    e->nonfinite |= pk_bad(e->xold, pk);
    return pk[3] != 0.0f || pk[4] != 0.0f || pk[5] != 0.0f;
}

static void pk_put(eval_ctx *e, const float *pk, size_t p, float *pc, uint32_t *nz, size_t *n)
{
    rtp_tree *t = e->t;
    if (pk_guard(e, pk)) {
        memcpy(pc + 6 * *n, pk, 6 * sizeof *pk);
        nz[(*n)++] = (uint32_t)p;
    } else {
        memcpy(t->pk + 3 * p, pk, 3 * sizeof *pk);
    }
}

/* The planes of one band: the rest of its samples (kept for two sample
   rows at a time: SPD's pixels average the corners of two) and the
   term's coefficient K (kp, kstride floats a sample), averaged per pixel
   with SPD. */
static int pk_build_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t w = (size_t)t->width, nx = (size_t)t->nx, ks = e->kstride, n = 0, base;
    int y0 = chunk * PK_ROWS, y1 = y0 + PK_ROWS, y, x, c;
    float *ra, *rb, *pc, pk[6];
    uint32_t *nz;
    if (y1 > t->height)
        y1 = t->height;
    base = (size_t)y0 * w;
    t->pk_off[chunk] = base;
    pc = t->pk_c + 6 * base;
    nz = t->pk_nz + base;
    ra = e->rest;
    rb = ra + 3 * nx;
    if (t->spd)
        pk_rest_into(e, y0, ra);
    for (y = y0; y < y1; y++) {
        size_t p = (size_t)y * w;
        if (!t->spd) {
            const float *kk = e->kp + p * ks;
            pk_rest_into(e, y, ra);
            for (x = 0; x < t->width; x++, kk += ks) {
                for (c = 0; c < 3; c++) {
                    pk[c] = ra[3 * x + c];
                    pk[3 + c] = kk[c];
                }
                pk_put(e, pk, p + (size_t)x, pc, nz, &n);
            }
            continue;
        }
        /* the four corners: sample rows y (ra) and y + 1 (rb) */
        pk_rest_into(e, y + 1, rb);
        {
            const float *sa = ra, *sb = rb, *ka = e->kp + (size_t)y * nx * ks, *kb = ka + nx * ks;
            float *tmp;
            for (x = 0; x < t->width; x++, sa += 3, sb += 3, ka += ks, kb += ks) {
                for (c = 0; c < 3; c++) {
                    pk[c] = (float)(0.25 * ((double)sa[c] + sa[3 + c] + sb[c] + sb[3 + c]));
                    pk[3 + c] = (float)(0.25 * (((double)ka[c] + kb[c]) +
                                                ((double)ka[ks + c] + kb[ks + c])));
                }
                pk_put(e, pk, p + (size_t)x, pc, nz, &n);
            }
            tmp = ra;
            ra = rb;
            rb = tmp;
        }
    }
    t->pk_seg[chunk] = (uint32_t)n;
    return 0;
}

/* The first index of the sorted list (n entries) at or above v. */
static size_t lower_bound(const uint32_t *list, size_t n, size_t v)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (list[mid] < v)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* The bits of |x| (x a float): ordered as |x| is, and at or above
   0x7f800000 exactly where x is infinite or NaN. */
static inline uint32_t abs_bits(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return u & 0x7fffffffu;
}

#ifndef PK_SSE2 /* (else pk_img_row's and pk_img_list's vectors) */
/* One pixel's planes P = B - xold K and K into o (6 floats), and its B
   and K into the band's largest |B| and |K| as abs_bits (bd: 2; integer
   maxima, which see a NaN or infinity too). */
static inline void pk_img_one(const float *b, float k0, float k1, float k2, double xo0,
                              double xo1, double xo2, float *o, uint32_t *bd)
{
    const double x0 = xo0 * k0, x1 = xo1 * k1, x2 = xo2 * k2;
    uint32_t bmax = bd[0], kmax = bd[1], u;
    u = abs_bits(b[0]), bmax = u > bmax ? u : bmax;
    u = abs_bits(b[1]), bmax = u > bmax ? u : bmax;
    u = abs_bits(b[2]), bmax = u > bmax ? u : bmax;
    u = abs_bits(k0), kmax = u > kmax ? u : kmax;
    u = abs_bits(k1), kmax = u > kmax ? u : kmax;
    u = abs_bits(k2), kmax = u > kmax ? u : kmax;
    bd[0] = bmax;
    bd[1] = kmax;
    o[0] = (float)((double)b[0] - x0);
    o[1] = (float)((double)b[1] - x1);
    o[2] = (float)((double)b[2] - x2);
    o[3] = k0;
    o[4] = k1;
    o[5] = k2;
}

/* pk_img_chunk's planes of m pixels pix[] whose K is kq (3 floats a
   pixel) and B the image's: those whose K is not 0 (else the pixel stays
   B: nothing to keep) into pc and nz, with the band's largest |B| and |K|
   (bd: pk_img_one's) for its bound; returns how many. */
static size_t pk_img_pixels(const float *kq, const uint32_t *pix, size_t m, const float *img,
                            const double *xo, float *pc, uint32_t *nz, uint32_t *bd)
{
    const double xo0 = xo[0], xo1 = xo[1], xo2 = xo[2];
    uint32_t acc[2];
    size_t j, n = 0;
    memcpy(acc, bd, sizeof acc);
    for (j = 0; j < m; j++, kq += 3) {
        const float k0 = kq[0], k1 = kq[1], k2 = kq[2];
        if (k0 == 0.0f && k1 == 0.0f && k2 == 0.0f)
            continue;
        pk_img_one(img + 3 * (size_t)pix[j], k0, k1, k2, xo0, xo1, xo2, pc + 6 * n, acc);
        nz[n++] = pix[j];
    }
    memcpy(bd, acc, sizeof acc);
    return n;
}
#endif

#ifdef PK_SSE2
/* One node of rtpi_nodes_diffuse_nl on SSE2's vectors, into the sums s01
   (channels 0 and 1) and s2 (channel 2 in the low lane; the high lane 0
   and unused): each lane the scalar code's operations in its order,
   rounded the same, so the same bits.  a01, a2: the ambient colour; c01,
   c2: light 0's (the others read from cv, nl of them). */
static RTPI_FORCE_INLINE void node_diffuse_v(size_t nl, const float *t, double wj, __m128d a01,
                                             __m128d a2, __m128d c01, __m128d c2,
                                             const double *cv, __m128d *s01, __m128d *s2)
{
    const __m128 zf = _mm_setzero_ps();
    const __m128d w2 = _mm_set1_pd(wj), d = _mm_set1_pd((double)t[3]);
    __m128d l01 = _mm_add_pd(a01, _mm_mul_pd(d, c01)), l2 = _mm_add_pd(a2, _mm_mul_pd(d, c2));
    size_t i;
    for (i = 1; i < nl; i++) {
        const __m128d di = _mm_set1_pd((double)t[3 + 2 * i]);
        l01 = _mm_add_pd(l01, _mm_mul_pd(di, _mm_loadu_pd(cv + 6 + 3 * i)));
        l2 = _mm_add_pd(l2, _mm_mul_pd(di, _mm_load_sd(cv + 8 + 3 * i)));
    }
    *s01 = _mm_add_pd(
        *s01, _mm_mul_pd(_mm_mul_pd(w2, _mm_cvtps_pd(_mm_loadl_pi(
                                            zf, (const __m64 *)(const void *)t))),
                         l01));
    *s2 = _mm_add_pd(*s2, _mm_mul_pd(_mm_mul_pd(w2, _mm_cvtps_pd(_mm_load_ss(t + 2))), l2));
}
#endif

/* q of the edited material's listed samples e->list[i0 .. i1) (i0 < i1),
   from its own nodes (rtpi_nodes_diffuse: rtpi_sample_diffuse bit for
   bit), each into out + 3 (k - base) for sample k, or with by_list into
   out + 3 (i - i0), one after another.  (Inlined: pk_img_chunk calls it
   for a band's samples, pk_q_chunk for a chunk of the list.)  nl: the
   scene's lights (listed_q). */
/* listed_q_nl asks for the terms and weight of the material's node
   LQ_AHEAD on at each sample: its nodes are a sparse rising walk through
   ev_terms and ev_w (mount_s6 at 512: 13 and 5 MB, from the last level
   of cache), and the loop waited on their loads (perf: 60% of
   pk_img_q1's time at the first load of a node's terms).  One node a
   sample, not each node: the same time for a third of the added instructions
   (mount_s6's first kd edit 23.66 M -> 24.80 M, each node 26.81 M; CPU
   median -10%, HISTORY session 46). */
#define LQ_AHEAD 32
static RTPI_FORCE_INLINE void listed_q_nl(const eval_ctx *e, size_t i0, size_t i1, float *out,
                                          size_t base, int by_list, size_t nl)
{
    const rtp_tree *t = e->t;
    const uint32_t *mn = t->mat_nodes, *list = e->list;
    const uint64_t *st = t->start;
    const float *terms = t->ev_terms;
    const double *w = t->ev_w, *cv = e->cv;
    const size_t nt = RTPI_TERMS(nl);
    size_t i, jend = t->mat_nstart[e->mat + 1], j = t->mat_nstart[e->mat], pf;
#ifdef PK_SSE2
    const __m128d a01 = _mm_loadu_pd(cv + 3), a2 = _mm_load_sd(cv + 5), c01 = _mm_loadu_pd(cv + 6),
                  c2 = _mm_load_sd(cv + 8);
#endif
    /* the material's nodes from the first sample on */
    j += lower_bound(mn + j, jend - j, (size_t)st[list[i0]]);
    for (i = i0; i < i1; i++) {
        size_t k = list[i], b = (size_t)st[k + 1];
        float *o = out + 3 * (by_list ? i - i0 : k - base);
        /* the terms and weights of the node LQ_AHEAD on asked for now */
        if (j + LQ_AHEAD < jend) {
            pf = mn[j + LQ_AHEAD];
            RTPI_PREFETCH(terms, pf * nt * sizeof *terms);
            RTPI_PREFETCH(w, pf * sizeof *w);
        }
        /* (a listed sample has a node of the material at least: mn[j]
           is its first) */
#ifdef PK_SSE2
        {
            /* its nodes summed as they are passed (rtpi_nodes_diffuse_nl's
               sums: nodes_diffuse_v) */
            __m128d s01 = _mm_setzero_pd(), s2 = _mm_setzero_pd();
            do {
                const size_t nd = mn[j];
                const double wj = w[nd];
                if (wj != 0.0)
                    node_diffuse_v(nl, terms + nd * nt, wj, a01, a2, c01, c2, cv, &s01, &s2);
                j++;
            } while (j < jend && mn[j] < b);
            _mm_storel_pi((__m64 *)(void *)o, _mm_cvtpd_ps(s01));
            _mm_store_ss(o + 2, _mm_cvtpd_ps(s2));
        }
#else
        {
            size_t j0 = j;
            double q[3];
            do
                j++;
            while (j < jend && mn[j] < b);
            rtpi_nodes_diffuse_nl(nl, mn + j0, j - j0, terms, w, cv, q);
            o[0] = (float)q[0];
            o[1] = (float)q[1];
            o[2] = (float)q[2];
        }
#endif
    }
}

/* listed_q_nl with the scene's lights, a constant where there is one
   (a third of the SPD scenes): the loop has its one light's colours in
   registers and no test of the count per sample (rtpi_nodes_diffuse_nl) */
static RTPI_FORCE_INLINE void listed_q(const eval_ctx *e, size_t i0, size_t i1, float *out,
                                       size_t base, int by_list)
{
    size_t nl = e->shade->s->nlights;
    if (nl == 1)
        listed_q_nl(e, i0, i1, out, base, by_list, 1);
    else
        listed_q_nl(e, i0, i1, out, base, by_list, nl);
}

/* listed_q for pk_img_chunk's band, into its grid, where the scene has
   one light: a call of its own, as inlined there its loop shared the
   registers with the pixel rows' and spilled two a sample (mount_s6's
   first kd edit 24.65 M -> 23.66 M instructions, tetra_s6's 9.13 M ->
   8.81 M).  Not with more lights: their loop, a call of its own, spilled
   more (balls_s4 25.95 M -> 26.54 M). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void pk_img_q1(const eval_ctx *e, size_t i0, size_t i1, float *g, size_t base)
{
    listed_q_nl(e, i0, i1, g, base, 0, 1);
}

/* The pixels x0 .. x1 - 1 of a pixel row, from the listed columns of
   its two sample rows (the list's entries bnd[0] .. bnd[1] - 1 and
   bnd[1] .. bnd[2] - 1, sample row base .. base + nx - 1 and the next):
   every pixel with a listed corner (pixel x: columns x and x + 1) lies
   there.  0 where neither row has a listed sample. */
static int pk_img_span(const uint32_t *list, const size_t *bnd, size_t base, size_t nx,
                       size_t *x0, size_t *x1)
{
    size_t lo = nx, hi = 0; /* columns: the first listed, 1 + the last */
    if (bnd[0] < bnd[1]) {
        lo = list[bnd[0]] - base;
        hi = list[bnd[1] - 1] - base + 1;
    }
    if (bnd[1] < bnd[2]) {
        size_t a = list[bnd[1]] - base - nx, b = list[bnd[2] - 1] - base - nx + 1;
        lo = a < lo ? a : lo;
        hi = b > hi ? b : hi;
    }
    if (lo >= hi)
        return 0;
    *x0 = lo > 0 ? lo - 1 : 0;
    *x1 = hi < nx ? hi : nx - 1; /* (pixels: nx - 1 of them) */
    return 1;
}

#ifdef PK_SSE2
/* The running bound of pk_img_row and pk_img_list_nl on SSE2's lanes:
   the largest |B| and |K| so far and the sum of the edited pixels (see
   pk_img_row). */
typedef struct pk_vb {
    __m128 bm, km, sum;
} pk_vb;

static RTPI_FORCE_INLINE void pk_vb_start(pk_vb *v, const uint32_t *bd)
{
    float f[2];
    memcpy(&f[0], &bd[0], sizeof *f);
    memcpy(&f[1], &bd[1], sizeof *f);
    v->bm = _mm_set1_ps(f[0]);
    v->km = _mm_set1_ps(f[1]);
    v->sum = _mm_setzero_ps();
}

/* A pixel whose K (k01: channels 0 and 1, k2: 2) is not 0: its planes P
   = B - xo K and K into o, the edit P + K xn over B at px, the bound. */
static RTPI_FORCE_INLINE void pk_vb_entry(pk_vb *v, __m128 k01, __m128 k2, float *px, float *o,
                                          __m128d xo01, __m128d xo2, __m128d xn01,
                                          __m128d xn2)
{
    const __m128 zf = _mm_setzero_ps(), absm = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
    const __m128 b01 = _mm_loadl_pi(zf, (const __m64 *)(const void *)px), b2 = _mm_load_ss(px + 2);
    const __m128d kd01 = _mm_cvtps_pd(k01), kd2 = _mm_cvtps_pd(k2);
    const __m128 pf01 = _mm_cvtpd_ps(_mm_sub_pd(_mm_cvtps_pd(b01), _mm_mul_pd(xo01, kd01))),
                 pf2 = _mm_cvtpd_ps(_mm_sub_pd(_mm_cvtps_pd(b2), _mm_mul_pd(xo2, kd2)));
    __m128 o01, o2;
    v->bm = _mm_max_ps(_mm_and_ps(_mm_movelh_ps(b01, b2), absm), v->bm);
    v->km = _mm_max_ps(_mm_and_ps(_mm_movelh_ps(k01, k2), absm), v->km);
    _mm_storel_pi((__m64 *)(void *)o, pf01);
    _mm_store_ss(o + 2, pf2);
    _mm_storel_pi((__m64 *)(void *)(o + 3), k01);
    _mm_store_ss(o + 5, k2);
    o01 = _mm_cvtpd_ps(_mm_add_pd(_mm_cvtps_pd(pf01), _mm_mul_pd(kd01, xn01)));
    o2 = _mm_cvtpd_ps(_mm_add_pd(_mm_cvtps_pd(pf2), _mm_mul_pd(kd2, xn2)));
    _mm_storel_pi((__m64 *)(void *)px, o01);
    _mm_store_ss(px + 2, o2);
    v->sum = _mm_add_ps(v->sum, _mm_movelh_ps(o01, o2));
}

/* The lanes' largest into bd (lane 3: 0 or what came in; abs_bits of a
   float at or above 0 are its bits), infinite where the sum is not
   finite. */
static RTPI_FORCE_INLINE void pk_vb_end(const pk_vb *v, uint32_t *bd)
{
    float f[4];
    _mm_storeu_ps(f, v->bm);
    f[0] = f[1] > f[0] ? f[1] : f[0];
    f[0] = f[2] > f[0] ? f[2] : f[0];
    memcpy(&bd[0], &f[0], sizeof *f);
    _mm_storeu_ps(f, v->km);
    f[0] = f[1] > f[0] ? f[1] : f[0];
    f[0] = f[2] > f[0] ? f[2] : f[0];
    memcpy(&bd[1], &f[0], sizeof *f);
    _mm_storeu_ps(f, v->sum);
    if (!(fabsf(f[0] + f[1] + f[2]) <= FLT_MAX))
        bd[0] = 0x7f800000u;
}
#endif

/* A row's listed columns in runs (pk_img_runs): a gap of PK_GAP unlisted
   columns or more between two runs, fewer within one (walking a pixel of
   a gap cost about 25 instructions: tetra_s6 at 512, SPD, walked 77 k
   pixels for 56 k with a listed corner, 13 k of the others in gaps of 16
   or more). */
#define PK_GAP 16
#define PK_RUNS 16 /* runs kept a row: past them the last takes the rest */

/* The runs of the listed columns list[i0 .. i1) (i0 < i1; column
   list[i] - base), appended to r (pairs: first, 1 + last; *n of them,
   PK_RUNS at most), by halves: a part whose columns miss fewer than
   PK_GAP is one run, so a row without holes costs one test, not one a
   column. */
static void pk_img_runs(const uint32_t *list, size_t i0, size_t i1, size_t base, uint32_t *r,
                        int *n)
{
    const size_t c0 = list[i0] - base, c1 = list[i1 - 1] - base;
    if (c1 + 1 - c0 - (i1 - i0) >= PK_GAP && *n < PK_RUNS) {
        const size_t mid = i0 + (i1 - i0) / 2;
        pk_img_runs(list, i0, mid, base, r, n);
        pk_img_runs(list, mid, i1, base, r, n);
        return;
    }
    if (*n > 0 && (*n == PK_RUNS || c0 < r[2 * *n - 1] + PK_GAP)) {
        r[2 * *n - 1] = (uint32_t)c1 + 1;
        return;
    }
    r[2 * *n] = (uint32_t)c0;
    r[2 * *n + 1] = (uint32_t)c1 + 1;
    (*n)++;
}

/* pk_img_chunk's pixels of a pixel row, m of them from its column x0:
   K from the band's grid of q (ga and gb: its two sample rows from
   column x0 on), whose columns x0 .. x0 + m of the first row are put
   back to 0; where K is not 0, the planes into o and nz (ids from id
   on), the band's largest |B| and |K| into bd (pk_img_one's), and the
   edit itself (pk_apply_listed's, xn: its colour) over B at px, just
   read (where the band's planes turn out not to be used, pk_img_chunk's
   check, the full path writes every pixel anew); returns how many.
   Where K is 0 the pixel stays B: nothing to keep (-0 counts as 0).
   pk_build_chunk's sums, by columns: the corners (x, y) and (x, y + 1)
   of pixel x are its left column, the next pixel's right one (each
   column's sum made once, not twice). */
static size_t pk_img_row(float *ga, const float *gb, float *px, uint32_t id, size_t m,
                         const double *xo, const double *xn, float *o, uint32_t *nz,
                         uint32_t *bd)
{
    size_t n = 0, x;
#ifdef PK_SSE2
    /* The same operations on SSE2's vectors (every x86-64 has them): a
       pixel's channels 0 and 1 in one, channel 2 in the low lane of
       another (its high lane 0, unused): the same IEEE operations,
       rounded the same, so the same bits as the scalar code below.  For
       the bound, the largest |B| and |K| by lanes, in floats (maxps),
       which pass over a NaN: so the edited pixels are summed too, a sum
       that is not finite where a B or K is not (P = B - xold K, then
       P + K x, are NaN or infinite whatever xold and x), and bd then
       says infinite (a sum that overflows only sends the band to the
       per-pixel test).  gcc -O2's scalar code took 127 instructions a
       pixel of the planes, a fifth of them moving channels between
       registers and 22 the integer maxima: mount_s6's first kd edit
       30.33 M -> 24.65 M instructions, tetra_s6's 11.35 M -> 9.13 M
       (with integer maxima by lanes, pcmpgtd: 26.40 M, 9.85 M). */
    const __m128d q4 = _mm_set1_pd(0.25), xo01 = _mm_loadu_pd(xo), xo2 = _mm_load_sd(xo + 2),
                  xn01 = _mm_loadu_pd(xn), xn2 = _mm_load_sd(xn + 2);
    const __m128 zf = _mm_setzero_ps();
    pk_vb v;
    __m128d l01, l2;
    pk_vb_start(&v, bd);
    l01 = _mm_add_pd(_mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)ga)),
                     _mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)gb)));
    l2 = _mm_add_pd(_mm_cvtps_pd(_mm_load_ss(ga + 2)), _mm_cvtps_pd(_mm_load_ss(gb + 2)));
    _mm_storel_pi((__m64 *)(void *)ga, zf);
    _mm_store_ss(ga + 2, zf);
    for (x = 0; x < m; x++, px += 3, id++) {
        float *qa = ga + 3 * x + 3;
        const float *qc = gb + 3 * x + 3;
        const __m128d r01 = _mm_add_pd(_mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)qa)),
                                       _mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)qc))),
                      r2 = _mm_add_pd(_mm_cvtps_pd(_mm_load_ss(qa + 2)),
                                      _mm_cvtps_pd(_mm_load_ss(qc + 2)));
        const __m128 k01 = _mm_cvtpd_ps(_mm_mul_pd(q4, _mm_add_pd(l01, r01))),
                     k2 = _mm_cvtpd_ps(_mm_mul_pd(q4, _mm_add_pd(l2, r2))),
                     k = _mm_movelh_ps(k01, k2);
        l01 = r01;
        l2 = r2;
        _mm_storel_pi((__m64 *)(void *)qa, zf);
        _mm_store_ss(qa + 2, zf);
        if (!_mm_movemask_ps(_mm_cmpneq_ps(k, zf)))
            continue;
        pk_vb_entry(&v, k01, k2, px, o, xo01, xo2, xn01, xn2);
        o += 6;
        nz[n++] = id;
    }
    pk_vb_end(&v, bd);
#else
    const double xo0 = xo[0], xo1 = xo[1], xo2 = xo[2];
    double l0 = (double)ga[0] + gb[0], l1 = (double)ga[1] + gb[1], l2 = (double)ga[2] + gb[2];
    /* (pointers walked along the row: the pixel's, its planes' and its
       index made from x and n for each pixel cost mount_s6's first kd
       edit 0.47 M instructions of 31.8 M) */
    float *qa = ga + 3;
    const float *qc = gb + 3;
    ga[0] = ga[1] = ga[2] = 0.0f;
    for (x = 0; x < m; x++, px += 3, qa += 3, qc += 3, id++) {
        const double r0 = (double)qa[0] + qc[0], r1 = (double)qa[1] + qc[1],
                     r2 = (double)qa[2] + qc[2];
        float k0 = (float)(0.25 * (l0 + r0)), k1 = (float)(0.25 * (l1 + r1)),
              k2 = (float)(0.25 * (l2 + r2));
        l0 = r0;
        l1 = r1;
        l2 = r2;
        qa[0] = qa[1] = qa[2] = 0.0f;
        if (k0 == 0.0f && k1 == 0.0f && k2 == 0.0f)
            continue;
        pk_img_one(px, k0, k1, k2, xo0, xo1, xo2, o, bd);
        px[0] = (float)(o[0] + k0 * xn[0]);
        px[1] = (float)(o[1] + k1 * xn[1]);
        px[2] = (float)(o[2] + k2 * xn[2]);
        o += 6;
        nz[n++] = id;
    }
#endif
    return n;
}

#ifdef PK_SSE2
/* pk_img_chunk's band where each sample is a pixel of its own, in one
   pass over the listed samples e->list[i0 .. i1): q from the material's
   nodes (listed_q_nl's sums) as K, then where K is not 0 the planes into
   o and nz, the band's largest |B| and |K| into bd and the edit over B
   at the pixel, as pk_img_row does for corner samples (its vectors; the
   same bits as pk_img_pixels and pk_pixel's scalar operations).  Returns
   how many.  (listed_q into a list of q, pk_img_pixels, then the edit
   over the planes: three passes, 172 instructions a sample on tetra_s6
   at 1024x1024.) */
static RTPI_FORCE_INLINE size_t pk_img_list_nl(const eval_ctx *e, size_t i0, size_t i1,
                                               const double *xo, const double *xn, float *o,
                                               uint32_t *nz, uint32_t *bd, size_t nl)
{
    const rtp_tree *t = e->t;
    const uint32_t *mn = t->mat_nodes, *list = e->list;
    const uint64_t *st = t->start;
    const float *terms = t->ev_terms;
    const double *w = t->ev_w, *cv = e->cv;
    float *img = e->pixels;
    const size_t nt = RTPI_TERMS(nl);
    size_t i, jend = t->mat_nstart[e->mat + 1], j = t->mat_nstart[e->mat], n = 0;
    const __m128d a01 = _mm_loadu_pd(cv + 3), a2 = _mm_load_sd(cv + 5), c01 = _mm_loadu_pd(cv + 6),
                  c2 = _mm_load_sd(cv + 8), xo01 = _mm_loadu_pd(xo), xo2 = _mm_load_sd(xo + 2),
                  xn01 = _mm_loadu_pd(xn), xn2 = _mm_load_sd(xn + 2);
    const __m128 zf = _mm_setzero_ps();
    pk_vb v;
    pk_vb_start(&v, bd);
    j += lower_bound(mn + j, jend - j, (size_t)st[list[i0]]);
    for (i = i0; i < i1; i++) {
        const size_t k = list[i], b = (size_t)st[k + 1];
        __m128d s01 = _mm_setzero_pd(), s2 = _mm_setzero_pd();
        __m128 k01, k2;
        if (j + LQ_AHEAD < jend) {
            const size_t pf = mn[j + LQ_AHEAD];
            RTPI_PREFETCH(terms, pf * nt * sizeof *terms);
            RTPI_PREFETCH(w, pf * sizeof *w);
        }
        /* (a listed sample has a node of the material at least) */
        do {
            const size_t nd = mn[j];
            const double wj = w[nd];
            if (wj != 0.0)
                node_diffuse_v(nl, terms + nd * nt, wj, a01, a2, c01, c2, cv, &s01, &s2);
            j++;
        } while (j < jend && mn[j] < b);
        k01 = _mm_cvtpd_ps(s01);
        k2 = _mm_cvtpd_ps(s2);
        if (!_mm_movemask_ps(_mm_cmpneq_ps(_mm_movelh_ps(k01, k2), zf)))
            continue;
        pk_vb_entry(&v, k01, k2, img + 3 * k, o, xo01, xo2, xn01, xn2);
        o += 6;
        nz[n++] = (uint32_t)k;
    }
    pk_vb_end(&v, bd);
    return n;
}

/* pk_img_list_nl with the scene's lights, a constant where there is one */
static size_t pk_img_list(const eval_ctx *e, size_t i0, size_t i1, const double *xo,
                          const double *xn, float *o, uint32_t *nz, uint32_t *bd)
{
    size_t nl = e->shade->s->nlights;
    if (nl == 1)
        return pk_img_list_nl(e, i0, i1, xo, xn, o, nz, bd, 1);
    return pk_img_list_nl(e, i0, i1, xo, xn, o, nz, bd, nl);
}
#endif

/* The planes of one band where only the pixels the edited material's
   samples (e->list) reach can change: an image kept from the last
   evaluation (opt->incremental) that is the image of the coefficients
   and colours now (t->last_exact), B.  K as pk_build_chunk makes it
   (q of the listed samples alone: with corner samples made here, band by
   band, else read from pk_q by list place, which is not cleared), and P =
   B - xold K, so no sample's rest is summed: P differs from the rest
   pk_build_chunk sums by the rounding of B (a float ulp of the pixel),
   and pk_bad's guard (per band where its bound settles it) stops the
   planes where xold K is far above P.  Pixels whose K is 0 keep B and
   are not part of the planes. */
static int pk_img_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t w = (size_t)t->width, nx = (size_t)t->nx, n = 0, i, lo, hi;
    int y0 = chunk * PK_ROWS, y1 = y0 + PK_ROWS, y, c, spd = t->spd;
    const float *img = e->pixels;
    const double xo[3] = {e->xold[0], e->xold[1], e->xold[2]};
    float *pc;
    uint32_t bd[2] = {0, 0}; /* bd: pk_img_one's */
    uint32_t *nz;
    int bad = 0;
    if (y1 > t->height)
        y1 = t->height;
    if (e->pk_pack) {
        /* after the band before; past the lent block's end where this
           band's bound (pk_seg, pk_build's) does not fit before it */
        size_t o = chunk ? t->pk_off[chunk - 1] + t->pk_seg[chunk - 1] : 0;
        if (o < t->pk_split && o + t->pk_seg[chunk] > t->pk_split)
            o = t->pk_split;
        t->pk_off[chunk] = o;
    }
    pk_band(t, chunk, &pc, &nz);
    if (!spd) {
        /* a pixel of its own per sample: the band's listed samples are
           its pixels, in order, with their q as K (no map of them), made
           here for the band (made for the whole list first, they were
           12 bytes a sample more memory, fresh: mount_s6 at 1024x1024,
           8 of the 24 MB the edit touched) */
        lo = lower_bound(e->list, e->nlist, (size_t)y0 * w);
        hi = lower_bound(e->list, e->nlist, (size_t)y1 * w);
#ifdef PK_SSE2
        if (lo < hi) {
            const double xn[3] = {e->x[0], e->x[1], e->x[2]};
            n = pk_img_list(e, lo, hi, xo, xn, pc, nz, bd);
        }
        (void)img;
#else
        if (lo < hi)
            listed_q(e, lo, hi, e->qgrid, 0, 1);
        n = pk_img_pixels(e->qgrid, e->list + lo, hi - lo, img, xo, pc, nz, bd);
#endif
        goto check;
    }
    {
        const double xn[3] = {e->x[0], e->x[1], e->x[2]};
        const uint32_t *list = e->list;
        const size_t srows = (size_t)(y1 - y0) + 1u;
        size_t bnd[PK_ROWS + 2], r;
        uint32_t run[PK_ROWS + 1][2 * PK_RUNS];
        int nrun[PK_ROWS + 1];
        float *g = e->qgrid;
        uint32_t acc[2] = {0, 0};
        /* bnd[r]: the list's first entry in sample row y0 + r or after */
        for (r = 0; r <= srows; r++)
            bnd[r] = lower_bound(list, e->nlist, ((size_t)y0 + r) * nx);
        /* the band's samples' q (pk_q_chunk's, from the material's own
           nodes) in a grid of its sample rows, 0 where the material is
           not: each pixel's four corners are read without a test.  The
           grid is all 0 between bands (clearing the whole grid each band
           was a fifth of tetra's edit, whose material is small): pixel
           row r puts sample row r's columns back to 0 as it sums them
           (pk_img_row; its span holds every listed column of the row,
           pk_img_span),
           and the entries of the last sample row, which no pixel row
           reads first, are put back below (every entry put back by the
           list after the rows, a loop of its own, cost mount_s6's first
           kd edit 1.03 M instructions of 31.4 M, two stores a column
           of the spans the less) */
        size_t q0 = bnd[0]; /* the first entry whose q is to be summed */
        /* The band's first sample row is the band before's last: where
           this thread made that band, it kept that row's q in row 0 of
           the grid (below) and it is not summed again (1/16 of q);
           elsewhere what it kept, of another band, is put back to 0. */
        if (e->qk_band == chunk)
            q0 = bnd[1];
        else
            for (i = e->qk_lo; i < e->qk_hi; i++)
                memset(g + 3 * (list[i] % nx), 0, 3 * sizeof *g);
        e->qk_band = -1;
        if (q0 < bnd[srows] && e->shade->s->nlights == 1)
            pk_img_q1(e, q0, bnd[srows], g, (size_t)y0 * nx);
        else if (q0 < bnd[srows])
            listed_q_nl(e, q0, bnd[srows], g, (size_t)y0 * nx, 0, e->shade->s->nlights);
        /* each sample row's runs of listed columns (pk_img_runs) */
        for (r = 0; r < srows; r++) {
            nrun[r] = 0;
            if (bnd[r] < bnd[r + 1])
                pk_img_runs(list, bnd[r], bnd[r + 1], ((size_t)y0 + r) * nx, run[r], &nrun[r]);
        }
        for (y = y0, r = 0; y < y1; y++, r++) {
            float *ga = g + 3 * r * nx;
            const float *gb = ga + 3 * nx;
            const size_t p = (size_t)y * w;
            int ia = 0, ib = 0;
            size_t x = 0, x1 = 0; /* the pixels x .. x1 - 1 to walk, none yet */
            /* the pixels with a listed corner (pixel x: columns x and x +
               1) lie in the two rows' runs, each a pixel wider on the
               left: by their first columns, walked where PK_GAP pixels
               or more lie between them */
            for (;;) {
                const uint32_t *ra = ia < nrun[r] ? run[r] + 2 * ia : NULL,
                               *rb = ib < nrun[r + 1] ? run[r + 1] + 2 * ib : NULL, *rr;
                size_t a, b;
                if (!ra && !rb)
                    break;
                rr = !rb || (ra && ra[0] <= rb[0]) ? ra : rb;
                if (rr == ra)
                    ia++;
                else
                    ib++;
                a = rr[0] > 0 ? rr[0] - 1 : 0;
                b = rr[1] < nx ? rr[1] : nx - 1;
                if (x1 > x && a < x1 + PK_GAP) {
                    x1 = b > x1 ? b : x1;
                    continue;
                }
                if (x1 > x)
                    n += pk_img_row(ga + 3 * x, gb + 3 * x, e->pixels + 3 * (p + x),
                                    (uint32_t)(p + x), x1 - x, xo, xn, pc + 6 * n, nz + n, acc);
                x = a;
                x1 = b;
            }
            if (x1 > x)
                n += pk_img_row(ga + 3 * x, gb + 3 * x, e->pixels + 3 * (p + x), (uint32_t)(p + x),
                                x1 - x, xo, xn, pc + 6 * n, nz + n, acc);
        }
        if (y1 < t->height) {
            /* the last sample row's q into row 0 for the next band (rows
               0 .. srows - 2 are all 0 now) */
            float *last = g + 3 * (srows - 1) * nx;
            for (i = bnd[srows - 1]; i < bnd[srows]; i++) {
                size_t col = 3 * (list[i] % nx);
                memcpy(g + col, last + col, 3 * sizeof *g);
                memset(last + col, 0, 3 * sizeof *g);
            }
            e->qk_band = chunk + 1;
            e->qk_lo = bnd[srows - 1];
            e->qk_hi = bnd[srows];
        } else {
            for (i = bnd[srows - 1]; i < bnd[srows]; i++)
                memset(g + 3 * (list[i] - (size_t)y0 * nx), 0, 3 * sizeof *g);
            e->qk_lo = e->qk_hi = 0;
        }
        memcpy(bd, acc, sizeof acc);
    }
check:
    /* Each pixel's pk_bad test, and a finite sum of its P and K, hold
       where |P| + 2 |xold K| <= 8 <= CP_SPAN max(|P|, 2) and |K| <= 1e30
       in every channel.  With X the largest |xold|, |xold K| <= X |K|
       (1 + 2^-52) =: A (a double product) and |P| <= (|B| + A)(1 +
       2^-24), so |B| + 3 X |K| (1 + 2^-21) <= 7.99 for the largest |B|
       and |K| of the band settles it, if its B and K are finite (their
       largest abs_bits below 0x7f800000: a NaN or infinity shows there,
       or pk_img_row's vectors set it so).  Otherwise each pixel is tested
       as the full path would need. */
    {
        double xm = fabs(xo[0]) > fabs(xo[1]) ? fabs(xo[0]) : fabs(xo[1]);
        float bm, km;
        xm = fabs(xo[2]) > xm ? fabs(xo[2]) : xm;
        memcpy(&bm, &bd[0], sizeof bm);
        memcpy(&km, &bd[1], sizeof km);
        if (!(bd[0] < 0x7f800000u && bd[1] < 0x7f800000u && km <= 1e30f &&
              (double)bm + 3.0 * xm * km * (1.0 + 0x1p-21) <= 7.99))
            for (i = 0; i < n; i++) {
                const float *o = pc + 6 * i;
                float ps = 0.0f;
                for (c = 0; c < 3; c++)
                    ps += o[c] + o[3 + c];
                /* a NaN or infinity shows in the sum (or a sum beyond
                   the float range: the full path then, as for those) */
                bad |= !(fabsf(ps) <= FLT_MAX);
                bad |= pk_bad(xo, o);
            }
    }
    e->nonfinite |= bad;
    t->pk_seg[chunk] = (uint32_t)n;
    /* the edit itself for the band (pk_apply_listed's), while its planes
       are in cache: a pass over them all after every band was made read
       them from memory again (where a band's planes are not to be used,
       the full path makes the image anew) */
#ifndef PK_SSE2
    if (!bad && !spd) { /* (with corner samples done as the planes were made) */
        const double xn[3] = {e->x[0], e->x[1], e->x[2]};
        float *out = e->pixels;
        for (i = 0; i < n; i++)
            pk_pixel(pc + 6 * i, xn, out + 3 * (size_t)nz[i]);
    }
#endif
    return 0;
}

static int pk_run(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads, int part);

/* Does pk_img_chunk need a grid of q?  With corner samples; a pixel of
   its own per sample, only without SSE2 (pk_img_list sums each sample's
   q where it is used) */
#ifdef PK_SSE2
#define PK_QGRID(t) ((t)->spd)
#else
#define PK_QGRID(t) 1
#endif

/* The entries of a material's planes (pk_img_chunk's) the samples' block
   lends, 0 where it lends none.  The planes of a kd edit live as long as
   the samples hold nothing: the edit leaves them stale (ev_samples_ok: a
   material's P + K x changes the image, not its samples), and whatever
   reads them next (a light moved, a shine edit, any other term) combines
   every sample anew first, in an evaluation that drops the planes
   (eval_body's end).  Their block is memory the first evaluation wrote,
   already the process's: a block of the planes' own, made fresh, took a
   page fault each 4 KiB the edit wrote (tetra_s6 at 1024x1024: 1,363, 1.9
   of its 4.3 ms).  Not where S lives there (cp_snapshot): S holds while
   the material's coefficients stay those before, for a colour edit once
   the material is back. */
static size_t pk_lend(const rtp_tree *t, const eval_ctx *e)
{
    size_t ns = (size_t)t->nx * t->ny;
    if (!t->ev_samples || e->pixels == t->ev_samples || (t->cp_s_ok && t->cp_s == t->ev_samples))
        return 0;
    return 3 * ns * sizeof(float) / (6 * sizeof(float) + sizeof(uint32_t));
}

/* Band i of at most m entries at *off, which it then passes: the lent
   block's entries 0 .. lend - 1 first, while the band fits there (a band
   lies in one block), then the block of the planes' own (pk_band).  m
   kept as pk_seg until the band is made: pk_img_chunk's bound where one
   thread packs the bands. */
static void pk_place(rtp_tree *t, int i, size_t m, size_t lend, size_t *off)
{
    if (*off < lend && *off + m > lend)
        *off = lend;
    t->pk_off[i] = *off;
    t->pk_seg[i] = (uint32_t)m;
    *off += m;
}

/* Builds the planes for the term the contexts name (with `part`, only
   where the material's samples reach: pk_img_chunk); 1 if they came out
   finite, else 0 (not to be used; out of memory for the threads' scratch
   also sets e->nomem). */
static int pk_build(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads, int part)
{
    int i, nb = (t->height + PK_ROWS - 1) / PK_ROWS;
    size_t off; /* the planes' entries */
    /* two sample rows' rest, or with `part` a band's q: with corner
       samples a grid of its sample rows, all 0; a pixel of its own per
       sample, its listed samples' one after another */
    size_t nx = (size_t)t->nx, bytes = 6 * nx * sizeof(float);
    for (i = 0; part && PK_QGRID(t) && i < nthreads; i++)
        if (!e[i].qgrid &&
            !(e[i].qgrid = (float *)rtpi_calloc_array(&t->alloc, (PK_ROWS + 1) * nx,
                                                       3 * sizeof(float)))) {
            e[i].nomem = 1;
            return 0;
        }
    for (i = 0; !part && i < nthreads; i++) {
        if (e[i].rest && e[i].rest_bytes < bytes) {
            rtpi_free(&t->alloc, e[i].rest);
            e[i].rest = NULL;
        }
        if (!e[i].rest && !(e[i].rest = (float *)rtpi_malloc_array(&t->alloc, bytes, 1))) {
            e[i].nomem = 1;
            return 0;
        }
        e[i].rest_bytes = bytes;
    }
    if (part) {
        /* the bands one after another in pk_c and pk_nz, so that their
           memory is as much as the material's pixels need (spread over
           every band's own place, the entries of a small material touched
           a page or, with transparent huge pages, 2 MB more a band: tetra
           at 1024x1024, 20% slower).  A pixel of its own per sample: the
           band's listed samples bound its entries; corner samples: the
           spans of its rows (pk_img_span). */
        size_t lend = pk_lend(t, e), own;
        off = 0;
        if (!t->spd) {
            size_t w = (size_t)t->width, lo = 0;
            for (i = 0; i < nb; i++) {
                size_t y1 = (size_t)(i + 1) * PK_ROWS, hi;
                hi = y1 >= (size_t)t->height ? e->nlist
                                              : lower_bound(e->list, e->nlist, y1 * w);
                pk_place(t, i, hi - lo, lend, &off);
                lo = hi;
            }
        } else {
            size_t r, x0, x1, bnd[3];
            bnd[1] = lower_bound(e->list, e->nlist, 0);
            bnd[2] = lower_bound(e->list, e->nlist, nx);
            for (i = 0, r = 0; i < nb; i++) {
                size_t m = 0;
                for (; r < (size_t)(i + 1) * PK_ROWS && r < (size_t)t->height; r++) {
                    /* pixel row r: sample rows r and r + 1 */
                    bnd[0] = bnd[1];
                    bnd[1] = bnd[2];
                    bnd[2] = lower_bound(e->list, e->nlist, (r + 2) * nx);
                    if (pk_img_span(e->list, bnd, r * nx, nx, &x0, &x1))
                        m += x1 - x0;
                }
                pk_place(t, i, m, lend, &off);
            }
        }
        t->pk_split = lend;
        own = off > lend ? off - lend : 0;
        if (!own)
            return pk_run(t, e, ctx, nthreads, part);
        off = own;
    } else {
        off = (size_t)t->width * (size_t)t->height;
        t->pk_split = 0;
    }
    /* a block as large as these planes need (a material's alone: a block
       for every pixel, made fresh each time, cost mount_s6 at 1024x1024
       a 29 MB mapping where 8 did, which no freed memory could serve),
       the pixels' list right after the entries: the memory the planes
       touch is one run */
    if (off > t->pk_cap || !t->pk_nz) {
        const size_t room = 3 * (size_t)t->width * t->height * sizeof(float) /
                            (6 * sizeof(float) + sizeof(uint32_t));
        rtpi_free(&t->alloc, t->pk_nz);
        t->pk_cap = 0;
        t->pk_c = NULL;
        if (part && t->cp_sown && off <= room) {
            /* S's own block (cp_ready's), where it holds the rest: memory
               the first evaluation wrote, where a fresh block took a page
               fault each 4 KiB the edit wrote (mount_s6 at 1024x1024:
               1,214, 1.7 of its 9.9 ms).  S holds for the material as the
               caches have it, which a kd edit leaves behind: past it, only
               that kd set back again and no other change evaluates from
               S; without it that evaluation combines every sample. */
            t->pk_nz = (uint32_t *)(void *)t->cp_sown;
            t->cp_sown = NULL;
            t->cp_s = NULL;
            t->cp_s_ok = 0;
            t->cp_gen++; /* (a chain's P' was made from S) */
            t->pk_cap = room;
        } else {
            t->pk_nz = (uint32_t *)rtpi_malloc_array(&t->alloc, off ? off : 1,
                                                     6 * sizeof *t->pk_c + sizeof *t->pk_nz);
            if (!t->pk_nz)
                return 0; /* (the full path needs no more memory) */
            t->pk_cap = off;
        }
    }
    t->pk_c = (float *)(void *)(t->pk_nz + (off ? off : 1));
    return pk_run(t, e, ctx, nthreads, part);
}

/* pk_build's bands made, the block(s) for them there. */
static int pk_run(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads, int part)
{
    int i, nb = (t->height + PK_ROWS - 1) / PK_ROWS, ok = 1;
    /* One thread takes the bands one after another, in order
       (rtpi_parallel_rows hands rows out one at a time, ascending): each
       band's entries then start where the band before ended (pk_img_chunk)
       instead of at the room its spans allow, so the memory touched is
       the entries' own, in as few huge pages as they fill (tetra_s6 at
       512: 1 of 2 MiB, where the gaps took 2).  The list of pixels comes
       first in the block for that too: behind the room of the entries,
       it began a page of its own. */
    for (i = 0; i < nthreads; i++) {
        e[i].pk_pack = part && nthreads == 1;
        e[i].qk_band = -1;
        e[i].qk_lo = e[i].qk_hi = 0;
    }
    tree_rows(t, nb, nthreads, ctx, part ? pk_img_chunk : pk_build_chunk, NULL, NULL);
    /* a row of q kept for a band another thread made (pk_img_chunk's
       grid is all 0 between uses) */
    for (i = 0; i < nthreads; i++) {
        size_t j, nx = (size_t)t->nx;
        for (j = e[i].qk_lo; j < e[i].qk_hi; j++)
            memset(e[i].qgrid + 3 * (e[i].list[j] % nx), 0, 3 * sizeof(float));
    }
    for (i = 0; i < nthreads; i++) {
        ok &= !e[i].nonfinite;
        e[i].nonfinite = 0;
    }
    t->pk_nnz = 0;
    for (i = 0; ok && i < nb; i++)
        t->pk_nnz += t->pk_seg[i];
    return ok;
}

/* A chunk of the edited material's samples: q, from the material's own
   nodes (rtpi_nodes_diffuse: rtpi_sample_diffuse bit for bit). */
static int pk_q_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    size_t i = (size_t)chunk * e->chunk, end = i + e->chunk;
    if (end > e->nlist)
        end = e->nlist;
    if (i < end)
        listed_q(e, i, end, e->t->pk_q, 0, 0);
    return 0;
}

/* The edit itself for one band, every pixel: P + K x where K is not 0,
   P elsewhere. */
static int pk_apply_band(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t p = (size_t)chunk * PK_ROWS * (size_t)t->width, end = p + PK_ROWS * (size_t)t->width;
    size_t n = t->pk_seg[chunk], j = 0;
    float *pc;
    uint32_t *nz;
    pk_band(t, chunk, &pc, &nz);
    if (end > (size_t)t->width * t->height)
        end = (size_t)t->width * t->height;
    for (; p < end; p++)
        if (j < n && nz[j] == p) {
            pk_pixel(pc + 6 * j, e->x, e->pixels + 3 * p);
            j++;
        } else {
            memcpy(e->pixels + 3 * p, t->pk + 3 * p, 3 * sizeof *t->pk);
        }
    return 0;
}

/* The same for the pixels whose K is not 0 alone (opt->incremental). */
static int pk_apply_listed(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t n = t->pk_seg[chunk], j;
    const double *c = e->x;
    float *pc;
    uint32_t *nz;
    pk_band(t, chunk, &pc, &nz);
    for (j = 0; j < n; j++)
        pk_pixel(pc + 6 * j, c, e->pixels + 3 * (size_t)nz[j]);
    return 0;
}
static void free_material_lists(rtp_tree *t)
{
    rtpi_free(&t->alloc, t->mat_start);
    rtpi_free(&t->alloc, t->mat_samples);
    rtpi_free(&t->alloc, t->mat_nstart);
    rtpi_free(&t->alloc, t->mat_nodes);
    t->mat_start = t->mat_samples = t->mat_nstart = t->mat_nodes = NULL;
}

/* Do trees of nnodes nodes fit the material lists?  They hold node
   indices and their per-material offsets in 32 bits (mat_nodes,
   mat_nstart, mat_start): at 2^32 nodes (96 GiB of trees, which a trace
   or a merge under a large enough memory limit makes; a tree file holds
   at most 2^31 - 1) they wrapped, and the lists named other nodes. */
int rtpi_material_lists_fit(size_t nnodes)
{
    return (uint64_t)nnodes <= 0xffffffffu;
}

/* For each material, the samples whose trees contain it and its nodes
   (built once).  mk (may be NULL): room for a uint16_t a node, where the
   first pass keeps each node's material for the second (up to 65536
   materials). */
static rtp_status build_material_lists(rtp_tree *t, uint16_t *mk)
{
    const rtp_scene *s = t->scene;
    const uint64_t *start = t->start;
    const rtpi_cnode *nodes = t->nodes;
    size_t nm = s->nmats, ns = (size_t)t->nx * t->ny, k, n, total = 0;
    uint32_t *last = NULL, *fill = NULL, *nfill = NULL, *ms, *mn, *samples, *mnodes;
    /* (the lists and arrays in locals: each store to the lists read the
       tree's fields again, 1.1 M instructions of mount_s6's first
       evaluation; the second lookup, where mk spares it, 3.2 M) */
    last = (uint32_t *)rtpi_malloc_array(&t->alloc, nm ? nm : 1, sizeof *last);
    fill = (uint32_t *)rtpi_malloc_array(&t->alloc, nm ? nm : 1, sizeof *fill);
    nfill = (uint32_t *)rtpi_malloc_array(&t->alloc, nm ? nm : 1, sizeof *nfill);
    t->mat_start = (uint32_t *)rtpi_calloc_array(&t->alloc, nm + 1, sizeof *t->mat_start);
    t->mat_nstart = (uint32_t *)rtpi_calloc_array(&t->alloc, nm + 1, sizeof *t->mat_nstart);
    t->mat_nodes = (uint32_t *)rtpi_malloc_array(&t->alloc, t->nnodes ? t->nnodes : 1,
                                                 sizeof *t->mat_nodes);
    if (!last || !fill || !nfill || !t->mat_start || !t->mat_nstart || !t->mat_nodes)
        goto nomem;
    rtpi_prefault(&t->alloc, t->mat_nodes, t->nnodes * sizeof *t->mat_nodes);
    if (nm > 65536)
        mk = NULL;
    ms = t->mat_start;
    mn = t->mat_nstart;
    mnodes = t->mat_nodes;
    for (k = 0; k < nm; k++)
        last[k] = 0xffffffffu;
    for (k = 0, n = (size_t)start[0]; k < ns; k++)
        for (; n < (size_t)start[k + 1]; n++) {
            uint32_t m = rtpi_prim_material(s, nodes[n].prim);
            if (mk)
                mk[n] = (uint16_t)m;
            mn[m + 1]++;
            if (last[m] != (uint32_t)k) {
                last[m] = (uint32_t)k;
                ms[m + 1]++;
                total++;
            }
        }
    for (k = 0; k < nm; k++) {
        ms[k + 1] += ms[k];
        mn[k + 1] += mn[k];
    }
    t->mat_samples = samples = (uint32_t *)rtpi_malloc_array(&t->alloc, total ? total : 1,
                                                             sizeof *t->mat_samples);
    if (!samples)
        goto nomem;
    rtpi_prefault(&t->alloc, samples, total * sizeof *samples);
    for (k = 0; k < nm; k++) {
        last[k] = 0xffffffffu;
        fill[k] = ms[k];
        nfill[k] = mn[k];
    }
    for (k = 0, n = (size_t)start[0]; k < ns; k++)
        for (; n < (size_t)start[k + 1]; n++) {
            uint32_t m = mk ? mk[n] : rtpi_prim_material(s, nodes[n].prim);
            mnodes[nfill[m]++] = (uint32_t)n;
            if (last[m] != (uint32_t)k) {
                last[m] = (uint32_t)k;
                samples[fill[m]++] = (uint32_t)k;
            }
        }
    rtpi_free(&t->alloc, last);
    rtpi_free(&t->alloc, fill);
    rtpi_free(&t->alloc, nfill);
    return RTP_OK;
nomem:
    /* (none kept: mat_start alone would read as built) */
    rtpi_free(&t->alloc, last);
    rtpi_free(&t->alloc, fill);
    rtpi_free(&t->alloc, nfill);
    free_material_lists(t);
    return RTP_ERR_NOMEM;
}

/* Does a material edit change step 1 (terms), or only step 2? */
static int terms_changed(const rtpi_material *a, const rtpi_material *b)
{
    /* (a highlight is 0 at any shine where ks is 0: light_term) */
    return (a->shine != b->shine && (a->ks > 0.0f || b->ks > 0.0f)) || a->tex != b->tex ||
           a->tex_scale != b->tex_scale ||
           a->tex_image != b->tex_image || (a->ks > 0.0f) != (b->ks > 0.0f) ||
           bump_changed(a, b);
}

/* Does a material edit change only the nodes' light terms (shine, or ks
   to or from 0), not their normals or texture factors? */
static int light_terms_only(const rtpi_material *a, const rtpi_material *b)
{
    rtpi_material x = *a;
    x.shine = b->shine;
    x.ks = b->ks;
    return !terms_changed(&x, b);
}

/* Do a's and b's ambient coefficients differ (set or not, or as set)?
   Unset, ka is kd, which coeffs_changed compares anyway. */
static int ka_changed(const rtpi_material *a, const rtpi_material *b)
{
    return a->ka_set != b->ka_set ||
           (a->ka_set && memcmp(a->ka, b->ka, sizeof a->ka) != 0);
}

static int coeffs_changed(const rtpi_material *a, const rtpi_material *b)
{
    return terms_changed(a, b) || a->kd != b->kd || a->ks != b->ks || a->kt != b->kt ||
           memcmp(a->color, b->color, sizeof a->color) != 0 ||
           memcmp(a->color2, b->color2, sizeof a->color2) != 0 || ka_changed(a, b);
}

/* Does a material edit change the shine alone? */
static int shine_only(const rtpi_material *a, const rtpi_material *b)
{
    rtpi_material x = *a;
    x.shine = b->shine;
    return !coeffs_changed(&x, b);
}

/* ------------------------------------------------ a moved light's kc
   A moved light's pass sums (w kd) c_obj d (+ (w ks) s) over each lit
   node it reaches; the product (w kd) c_obj does not depend on the light.
   It is kept per node (t->mv_kc, 24 bytes a node: rtpi_light_redo's kc,
   each node's made the first time a move lights it; a scene never moved
   has none), from the nodes' path weights and texture factors and the
   materials' kd, colours and texture: an evaluation that makes the
   caches anew (ev_w, the terms) forgets it, and so does a move after any
   edit of a material since it was made (mv_kc_mats, compared whole as
   coeffs_changed does: kd, ks, kt, colours, texture, shine, bump, ka).
   Light colours, the ambient and the background are not in it.  It is
   taken where the caches with it fit the memory limit, as the caches
   themselves (ev_cache_bytes); without it a move makes each product. */
static void mv_kc_free(rtp_tree *t)
{
    rtpi_free(&t->alloc, t->mv_kc);
    rtpi_free(&t->alloc, t->mv_kc_mats);
    t->mv_kc = NULL;
    t->mv_kc_mats = NULL;
    t->mv_kc_nmats = 0;
}

/* The nodes' kc for a move now (NULL: none), each node's made anew where
   the materials changed since (all zero bits: not made). */
static double *mv_kc_check(rtp_tree *t, size_t nl, size_t ns, double limit)
{
    const rtp_scene *s = t->scene;
    size_t m, n = 3 * t->nnodes + 1;
    int same = t->mv_kc && t->mv_kc_mats && t->mv_kc_nmats == s->nmats;
    for (m = 0; same && m < s->nmats; m++)
        same = !coeffs_changed(&t->mv_kc_mats[m], &s->mats[m]);
    if (same)
        return t->mv_kc;
    if (!t->mv_kc) {
        if (!(ev_cache_bytes(t, nl, ns) + 24.0 * (double)t->nnodes <=
              fmin(EV_CACHE_BYTES, limit)))
            return NULL;
        t->mv_kc = (double *)rtpi_calloc_array(&t->alloc, n, sizeof *t->mv_kc);
    } else {
        memset(t->mv_kc, 0, n * sizeof *t->mv_kc);
    }
    if (t->mv_kc && t->mv_kc_nmats != s->nmats) {
        rtpi_free(&t->alloc, t->mv_kc_mats);
        t->mv_kc_mats = (rtpi_material *)rtpi_malloc_array(&t->alloc, s->nmats + 1,
                                                          sizeof *t->mv_kc_mats);
    }
    if (!t->mv_kc || !t->mv_kc_mats) {
        mv_kc_free(t);
        return NULL;
    }
    memcpy(t->mv_kc_mats, s->mats, s->nmats * sizeof *t->mv_kc_mats);
    t->mv_kc_nmats = s->nmats;
    return t->mv_kc;
}

/* Are light l's terms not those of where it is now (it moved since, or
   its shadows are to be decided another way: mode and res as vis_key
   makes them)? */
static int light_terms_stale(const rtp_tree *t, size_t l, int mode, int res)
{
    const rtpi_light *L = &t->scene->lights[l];
    return memcmp(t->ev_pos + 3 * l, L->pos, sizeof L->pos) != 0 ||
           (light_moved(t, l) && (t->ev_vis_mode != mode || t->ev_vis_res != res));
}

/* Notes material m among those whose samples alone step 3 set; -1 once
   there are more than RESOLVE_MAX (every pixel is then averaged). */
#define RESOLVE_MAX 8
static void note_set(uint32_t *mats, int *n, uint32_t m)
{
    if (*n >= 0 && *n < RESOLVE_MAX)
        mats[(*n)++] = m;
    else
        *n = -1;
}

/* An incremental evaluation's step 3 for the pixels of the listed samples
   only (the image holds every other pixel): a sample is a pixel, or (SPD)
   a corner of four.  Returns the pixels written (a pixel written by the
   sample left of it in the list is not written again; one below a
   listed sample may be). */
static unsigned long long resolve_listed(const rtp_tree *t, const float *samples,
                                         const uint32_t *list, size_t n, rtp_image *img)
{
    unsigned long long writes = 0;
    size_t i;
    for (i = 0; i < n; i++) {
        size_t k = list[i];
        int sx = (int)(k % (size_t)t->nx), sy = (int)(k / (size_t)t->nx), x, y;
        if (!t->spd) {
            memcpy(img->pixels + 3 * k, samples + 3 * k, 3 * sizeof *samples);
            writes++;
            continue;
        }
        for (y = sy - 1; y <= sy; y++)
            for (x = sx - 1; x <= sx; x++)
                if (x >= 0 && y >= 0 && x < img->width && y < img->height &&
                    !(x < sx && i > 0 && list[i - 1] == k - 1)) {
                    rtpi_resolve_pixel(samples, img, x, y);
                    writes++;
                }
    }
    return writes;
}

/* The lowest bit set of m (m > 0). */
#if defined(__GNUC__)
#define mark_low(m) __builtin_ctz(m)
#else
static int mark_low(unsigned m)
{
    int i = 0;
    while (!(m & 1u)) {
        m >>= 1;
        i++;
    }
    return i;
}
#endif

/* 8 marks of 1 (a mark is a byte of 0 or 1), in either byte order */
#define MARK_ALL UINT64_C(0x0101010101010101)

/* Eight pixels from their corner samples' rows s0 and s1 into out: mark_row's
   sums, float by float in the same order (they vectorise: no test a
   pixel). */
static void pix_avg24(const float *restrict s0, const float *restrict s1, float *restrict out)
{
    int i;
    for (i = 0; i < 24; i++)
        out[i] = 0.25f * (s0[i] + s0[i + 3] + s1[i] + s1[i + 3]);
}

/* Pixel row y of the samples light_row marked (t->ev_mark: one byte a
   sample, and 8 more, all 0; mark_rows_at) from e->samples into e->pixels, which hold
   every other pixel already; with corner samples pixel x of row y
   averages samples x and x + 1 of sample rows y and y + 1.  Rows are read
   8 samples a word, skipping those with no mark.  eval_impl clears the
   marks once every row is done (a row's serve two pixel rows). */
static int mark_row(void *ctx, int y)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    const unsigned char *r0 = t->ev_mark + (size_t)y * t->nx, *r1 = r0 + t->nx,
                        *rows = t->ev_mark + mark_rows_at(t);
    const float *samples = e->samples;
    size_t nx = (size_t)t->nx, w = (size_t)t->width, x, q;
    unsigned long long writes = 0;
    /* (a pixel row's samples: row y, and y + 1 with corner samples) */
    if (!rows[y] && !(t->spd && rows[y + 1]))
        return 0;
    if (!t->spd) {
        for (x = 0; x < w; x++)
            if (r0[x]) {
                memcpy(e->pixels + 3 * ((size_t)y * w + x), samples + 3 * ((size_t)y * nx + x),
                       3 * sizeof *samples);
                writes++;
            }
    } else {
        /* (rtpi_resolve_pixel's sums, with the rows' places kept) */
        const float *s0 = samples + 3 * (size_t)y * nx, *s1 = s0 + 3 * nx;
        float *out = e->pixels + 3 * (size_t)y * w;
        /* (the marks' bytes read as a word put column x + i at byte i,
           bits 8i up, on a little-endian host: the compiler's constant) */
        const uint64_t one = 1;
        unsigned char first;
        int le;
        memcpy(&first, &one, 1);
        le = first == 1;
        for (x = 0; x < w; x += 8) {
            /* pixels x .. x + 7 have samples x .. x + 8 as corners */
            uint64_t a, b;
            size_t end = x + 8 < w ? x + 8 : w;
            memcpy(&a, r0 + x, 8);
            memcpy(&b, r1 + x, 8);
            if (!(a | b | r0[x + 8] | r1[x + 8]))
                continue;
            if ((a | b) == MARK_ALL && end == x + 8) {
                /* every column marked in one row or the other: all 8
                   pixels are written, by one loop over their 24 floats
                   without a test each (a moved light marks most samples
                   it reaches: balls, 8.5 M of a move went to this row's
                   tests and sums) */
                pix_avg24(s0 + 3 * x, s1 + 3 * x, out + 3 * x);
                writes += 8;
                continue;
            }
            if (le) {
                /* The pixels to write as the bits of a byte: pixel x + i
                   where column x + i or x + i + 1 is marked in either
                   row (byte i of a | b, shifted down a byte, column x + 8
                   on top), the bytes' low bits gathered by the product
                   (each byte 0 or 1: no carries), then only those pixels
                   visited rather than a test of each (tetra: a moved light
                   marks scattered samples, 40k of its 8-pixel groups went
                   through the test of 8 pixels) */
                uint64_t c = a | b;
                unsigned m;
                c |= c >> 8 | (uint64_t)(r0[x + 8] | r1[x + 8]) << 56;
                if (end < x + 8)
                    c &= ((uint64_t)1 << (8 * (end - x))) - 1u;
                m = (unsigned)((c * UINT64_C(0x0102040810204080)) >> 56);
                for (; m; m &= m - 1u) {
                    const float *u, *v;
                    float *o;
                    q = x + (size_t)mark_low(m);
                    u = s0 + 3 * q;
                    v = s1 + 3 * q;
                    o = out + 3 * q;
                    o[0] = 0.25f * (u[0] + u[3] + v[0] + v[3]);
                    o[1] = 0.25f * (u[1] + u[4] + v[1] + v[4]);
                    o[2] = 0.25f * (u[2] + u[5] + v[2] + v[5]);
                    writes++;
                }
                continue;
            }
            for (q = x; q < end; q++)
                if (r0[q] | r0[q + 1] | r1[q] | r1[q + 1]) {
                    const float *u = s0 + 3 * q, *v = s1 + 3 * q;
                    float *o = out + 3 * q;
                    o[0] = 0.25f * (u[0] + u[3] + v[0] + v[3]);
                    o[1] = 0.25f * (u[1] + u[4] + v[1] + v[4]);
                    o[2] = 0.25f * (u[2] + u[5] + v[2] + v[5]);
                    writes++;
                }
        }
    }
    e->written += writes;
    return 0;
}

/* Every pixel row from e->samples into e->pixels (rtpi_resolve_samples,
   by rows on the threads). */
/* A pixel row of w pixels from SPD's corner samples: sample rows s0 and
   the one after it (w + 1 samples each). */
static void spd_row(const float *s0, float *out, size_t w)
{
    const float *s1 = s0 + 3 * (w + 1);
    size_t x;
    for (x = 0; x < w; x++, s0 += 3, s1 += 3, out += 3) {
        out[0] = 0.25f * (s0[0] + s0[3] + s1[0] + s1[3]);
        out[1] = 0.25f * (s0[1] + s0[4] + s1[1] + s1[4]);
        out[2] = 0.25f * (s0[2] + s0[5] + s1[2] + s1[5]);
    }
}

static int resolve_row(void *ctx, int y)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t w = (size_t)t->width;
    if (!t->spd) {
        memcpy(e->pixels + 3 * (size_t)y * w, e->samples + 3 * (size_t)y * w,
               3 * w * sizeof *e->pixels);
        return 0;
    }
    spd_row(e->samples + 3 * (size_t)y * (w + 1), e->pixels + 3 * (size_t)y * w, w);
    return 0;
}

/* mark_row and resolve_row over bands of PIX_BAND pixel rows: a row of
   either is ~1 us at 512 wide, and each row handed out takes the pool's
   lock twice, which two threads then pass to and fro (rows of ~0.5 us
   through rtpi_parallel_rows: 290 us of CPU a 513-row pass at one
   thread, 320-330 at two).  Each pixel its own samples': the same bytes
   in bands. */
#define PIX_BAND 8

static int mark_band(void *ctx, int b)
{
    const eval_ctx *e = (const eval_ctx *)ctx;
    int y = b * PIX_BAND, y1 = y + PIX_BAND < e->t->height ? y + PIX_BAND : e->t->height;
    for (; y < y1; y++)
        mark_row(ctx, y);
    return 0;
}

static int resolve_band(void *ctx, int b)
{
    const eval_ctx *e = (const eval_ctx *)ctx;
    int y = b * PIX_BAND, y1 = y + PIX_BAND < e->t->height ? y + PIX_BAND : e->t->height;
    for (; y < y1; y++)
        resolve_row(ctx, y);
    return 0;
}

/* Does this evaluation go on with the listed highlights: no light's terms
   stale, and no material changed since the list was made but its own,
   in its shine alone? */
static int hl_continues(const rtp_tree *t, int mode, int res)
{
    const rtp_scene *s = t->scene;
    size_t l, m, hm = (size_t)t->hl_mat - 1;
    for (l = 0; l < s->nlights; l++)
        if (light_terms_stale(t, l, mode, res))
            return 0;
    for (m = 0; m < s->nmats; m++)
        if (m == hm ? !shine_only(&t->ev_mats[m], &s->mats[m])
                    : coeffs_changed(&t->ev_mats[m], &s->mats[m]))
            return 0;
    return 1;
}

/* Is material m the listed one with its samples at another shine than
   the scene's?  (Back at the caches' shine after a chain, say: a shine
   edit like any other, though the material equals the caches'.) */
static int hl_pending(const rtp_tree *t, size_t m)
{
    return t->hl_mat == (int)m + 1 && t->hl_shine != (double)t->scene->mats[m].shine;
}

static double seconds_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Drops the caches (after a failure, or when the lights change in number). */
static void drop_caches(rtp_tree *t)
{
    rtpi_free(&t->alloc, t->ev_terms);
    rtpi_free(&t->alloc, t->ev_coeffs);
    rtpi_free(&t->alloc, t->ev_nv);
    rtpi_free(&t->alloc, t->ev_w);
    rtpi_free(&t->alloc, t->ev_mark);
    rtpi_free(&t->alloc, t->ev_pos);
    rtpi_free(&t->alloc, t->ev_mats);
    rtpi_free(&t->alloc, t->ev_cl);
    rtpi_free(&t->alloc, t->pk);
    rtpi_free(&t->alloc, t->pk_q);
    rtpi_free(&t->alloc, t->pk_nz); /* (pk_c lies in its block) */
    rtpi_free(&t->alloc, t->pk_seg);
    rtpi_free(&t->alloc, t->pk_off);
    cp_free(t);
    rtpi_free(&t->alloc, t->hl_idx);
    rtpi_free(&t->alloc, t->hl_lrv);
    rtpi_free(&t->alloc, t->hl_w);
    rtpi_free(&t->alloc, t->hl_off);
    rtpi_free(&t->alloc, t->hl_p);
    t->hl_idx = NULL;
    t->hl_lrv = NULL;
    t->hl_w = NULL;
    t->hl_off = NULL;
    t->hl_p = NULL;
    t->hl_n = t->hl_cap = 0;
    t->hl_mat = 0;
    t->pk_nz = NULL;
    t->pk_c = NULL;
    t->pk_cap = 0;
    t->pk_split = 0;
    t->pk_seg = NULL;
    t->pk_off = NULL;
    t->ev_cl = NULL;
    t->pk = NULL;
    t->pk_q = NULL;
    t->pk_term = 0;
    t->ev_samples_ok = 0;
    t->ev_terms = NULL;
    t->ev_coeffs = NULL;
    t->ev_nv = NULL;
    t->ev_w = NULL;
    t->ev_mark = NULL;
    rtpi_free(&t->alloc, t->mv_rest);
    rtpi_free(&t->alloc, t->mv_ok);
    t->mv_rest = NULL;
    t->mv_ok = NULL;
    mv_kc_free(t);
    t->mv_light = 0;
    t->ev_pos = NULL;
    t->ev_mats = NULL;
    t->ev_valid = 0;
}

/* Class D: samples whose trees contain a material the recorded trees
   cannot show exactly are traced again (only those), then every cache
   that referred to the old nodes is dropped.  A moved camera changes
   every ray: every sample is traced again, a full trace into the same
   trees (later edits re-evaluate them as ever). */
/* Exchanges a's and b's bump maps (kind, image, strength, scale). */
static void swap_bump(rtpi_material *a, rtpi_material *b)
{
    rtpi_material x = *a;
    a->bump = b->bump;
    a->bump_image = b->bump_image;
    a->bump_strength = b->bump_strength;
    a->bump_scale = b->bump_scale;
    b->bump = x.bump;
    b->bump_image = x.bump_image;
    b->bump_strength = x.bump_strength;
    b->bump_scale = x.bump_scale;
}

static rtp_status retrace_edited(rtp_tree *t, int threads, int stale, double limit,
                                 progress_part *progress, rtp_eval_stats *st, rtp_error *err)
{
    const rtp_scene *s = t->scene;
    size_t m, k, ns = (size_t)t->nx * t->ny, n = 0, nl_now = 0;
    unsigned char *mark, *swapped = NULL, *redo = NULL;
    uint32_t *list;
    int any = 0, camera = memcmp(&s->camera, &t->cam0, sizeof t->cam0) != 0;
    rtp_status rs;
    for (m = 0; m < s->nmats; m++)
        any |= needs_retrace(t, m, stale);
    if (!any && !camera)
        return RTP_OK;
    if (!camera && !rtpi_material_lists_fit(t->nnodes))
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "%zu nodes: samples to trace again are found by lists of at most "
                          "2^32 - 1 nodes; trace the scene again instead",
                          t->nnodes);
    if (!camera && !t->mat_start && build_material_lists(t, NULL) != RTP_OK)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    mark = (unsigned char *)rtpi_calloc_array(&t->alloc, ns + 1, 1);
    list = (uint32_t *)rtpi_malloc_array(&t->alloc, ns + 1, sizeof *list);
    if (!mark || !list) {
        rtpi_free(&t->alloc, mark);
        rtpi_free(&t->alloc, list);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    for (m = 0; !camera && m < s->nmats; m++)
        if (needs_retrace(t, m, stale))
            for (k = t->mat_start[m]; k < t->mat_start[m + 1]; k++)
                mark[t->mat_samples[k]] = 1;
    for (k = 0; k < ns; k++)
        if (camera || mark[k])
            list[n++] = (uint32_t)k;
    /* A material whose bump changed but whose subtrees are kept (--stale
       keep) has every subtree below it traced with its bump as mats0
       says: the samples traced again here spawn their rays below it with
       that bump too, so the trees stay one state per material (its rays
       spawned with the new bump, the tree said exact when the bump went
       back, 0.17 off a full trace; shading uses the new bump either way). */
    if (!camera) {
        swapped = (unsigned char *)rtpi_calloc_array(&t->alloc, 2 * s->nmats + 1, 1);
        if (!swapped) {
            rtpi_free(&t->alloc, mark);
            rtpi_free(&t->alloc, list);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        /* (redo: the materials below whose hits the re-trace casts
           rays; above them, and beside, a sample's old nodes are what a
           trace casts: rtpi_retrace's redo.  A renderer's own hits are
           not: its samples are traced whole) */
        redo = t->foreign ? NULL : swapped + s->nmats;
        for (m = 0; m < s->nmats; m++) {
            /* (3: an SPD tree's surfaces of m face the lights otherwise
               from behind now, two-sided or one-sided: rtpi_retrace) */
            if (redo)
                redo[m] = (unsigned char)(needs_retrace(t, m, stale)
                                              ? t->spd && (s->mats[m].kt > 0.0f) !=
                                                              (t->mats0[m].kt > 0.0f)
                                                    ? 3
                                                    : 1
                                              : 0);
            if (!needs_retrace(t, m, stale) && bump_stale(t, m)) {
                swap_bump(&t->scene->mats[m], &t->mats0[m]);
                swapped[m] = 1;
            }
        }
    }
    /* A moved camera traces every sample again: with every light where
       it is now, added ones too (the new trees' light words as many as
       they need), which the trees then record as traced.  With the lights
       where they were traced, a moved light was decided again for every
       node after this full trace, by --shadows: an item buffer's error
       stayed in an image called a full trace, and every node paid a
       query. */
    if (camera)
        nl_now = s->nlights;
    rs = rtpi_retrace(t, list, n, threads, nl_now, redo, limit, st ? &st->retraced_rays : NULL,
                      st ? &st->capped_rays : NULL, progress->fn ? progress_part_cb : NULL,
                      progress->cancel ? progress_part_cancel : NULL, progress, err);
    for (m = 0; swapped && m < s->nmats; m++)
        if (swapped[m])
            swap_bump(&t->scene->mats[m], &t->mats0[m]);
    rtpi_free(&t->alloc, swapped);
    rtpi_free(&t->alloc, mark);
    rtpi_free(&t->alloc, list);
    if (rs != RTP_OK)
        return rs;
    if (st) {
        st->retraced_samples += n;
        st->camera_moved = camera;
    }
    t->cam0 = s->camera;
    for (k = 0; k < nl_now; k++)
        memcpy(t->lights0[k].pos, s->lights[k].pos, sizeof t->lights0[k].pos);
    if (nl_now)
        t->nlights0 = nl_now;
    /* The samples just traced spawned rays with every material as it is
       now: where another material's ks or kt is lower now than when its
       own samples were traced (0: no reflected or refracted rays at all),
       those samples hold less below it, so raising it later must trace
       again (for the samples traced before, which kept theirs, this is
       conservative).  Found by fuzz_set: ks 0, a class-D edit elsewhere,
       then ks 2 missed the glass's reflections in the re-traced samples. */
    for (m = 0; !camera && m < s->nmats; m++)
        if (!needs_retrace(t, m, stale)) {
            if (s->mats[m].ks < t->mats0[m].ks)
                t->mats0[m].ks = s->mats[m].ks;
            if (s->mats[m].kt < t->mats0[m].kt)
                t->mats0[m].kt = s->mats[m].kt;
        }
    /* the trees now hold these materials (after a camera move, all) as
       they are */
    for (m = 0; m < s->nmats; m++)
        if (camera || needs_retrace(t, m, stale)) {
            t->mats0[m].ks = s->mats[m].ks;
            t->mats0[m].kt = s->mats[m].kt;
            t->mats0[m].ior = s->mats[m].ior;
            t->mats0[m].bump = s->mats[m].bump;
            t->mats0[m].bump_image = s->mats[m].bump_image;
            t->mats0[m].bump_strength = s->mats[m].bump_strength;
            t->mats0[m].bump_scale = s->mats[m].bump_scale;
        }
    drop_caches(t);
    t->stale_ok = 0;
    rtpi_free(&t->alloc, t->cur_vis);
    rtpi_free(&t->alloc, t->cur_pos);
    rtpi_free(&t->alloc, t->ball_in); /* (nodes traced again) */
    rtpi_free(&t->alloc, t->ball_sph);
    rtpi_free(&t->alloc, t->prim_nrm);
    rtpi_free(&t->alloc, t->cone_own);
    rtpi_free(&t->alloc, t->kd_from);
    rtpi_free(&t->alloc, t->kd_from_kt);
    rtpi_free(&t->alloc, t->vrec);
    rtpi_free(&t->alloc, t->vrec_mat);
    free_material_lists(t);
    t->cur_vis = NULL;
    t->cur_pos = NULL;
    t->ball_in = NULL;
    t->ball_sph = NULL;
    t->ball_known = 0;
    t->prim_nrm = NULL;
    t->cone_own = NULL;
    t->kd_from = NULL;
    t->kd_from_kt = NULL;
    t->vrec = NULL;
    t->vrec_mat = NULL;
    return RTP_OK;
}

static int pk_alloc(rtp_tree *t, int q);

/* Threads for a quick pass moving `bytes`: below 8 MiB (a millisecond or
   so) the calling thread alone, as starting a thread costs tens of
   microseconds and, on a busy machine, waking it a scheduler slice. */
static int threads_for(double bytes, int nthreads)
{
    return bytes < 8.0 * 1048576.0 ? 1 : nthreads;
}

/* P + K x into the image: every pixel, or with `sparse` (the image holds
   the last evaluation, which differed in this term alone) the pixels
   whose K is not 0. */
static void pk_apply(rtp_tree *t, void *const *ctx, int nthreads, int sparse,
                     rtp_eval_stats *st)
{
    int nb = (t->height + PK_ROWS - 1) / PK_ROWS;
    if (sparse) {
        tree_rows(t, nb, threads_for(40.0 * (double)t->pk_nnz, nthreads), ctx,
                           pk_apply_listed, NULL, NULL);
        st->written_pixels = t->pk_nnz;
    } else {
        tree_rows(t, nb, threads_for(36.0 * (double)t->width * (double)t->height, nthreads),
                           ctx, pk_apply_band, NULL, NULL);
        st->written_pixels = (unsigned long long)t->width * t->height;
    }
}

/* The planes' memory but pk_c's block (pk_build makes that), unless it
   is there: the bands' counts and offsets, and with `part` 0 (every
   pixel's planes: pk_build_chunk) P of the other pixels (pk) and q of
   every sample (pk_q); `part` (only the material's pixels: pk_img_chunk)
   needs neither.  Only what the path uses: a block made and not used
   still costs a fault as it is made, and its first use another
   (tetra_s6 at 512, a material's first kd edit made 13 MB and used
   1.5).  1 if it is there. */
static int pk_alloc(rtp_tree *t, int part)
{
    size_t np = (size_t)t->width * t->height;
    if (!t->pk_seg)
        t->pk_seg = (uint32_t *)rtpi_malloc_array(
            &t->alloc, (size_t)(t->height + PK_ROWS - 1) / PK_ROWS + 1, sizeof *t->pk_seg);
    if (t->pk_seg && !t->pk_off)
        t->pk_off = (size_t *)rtpi_malloc_array(
            &t->alloc, (size_t)(t->height + PK_ROWS - 1) / PK_ROWS + 1, sizeof *t->pk_off);
    if (!t->pk_off)
        return 0;
    if (!part && !t->pk)
        t->pk = (float *)rtpi_malloc_array(&t->alloc, np, 3 * sizeof *t->pk);
    if (!part && !t->pk_q)
        t->pk_q = (float *)rtpi_malloc_array(&t->alloc, (size_t)t->nx * t->ny,
                                             3 * sizeof *t->pk_q);
    return part || (t->pk && t->pk_q);
}

/* Does a material's part of a sample's coefficients stay within
   RTPI_COEFF_MAX, so that the full path's float coefficients cannot
   overflow where a plane's value stays finite?  Each node adds
   w (kd c_obj d + ks s), d and s at most 1, c_obj the colour times a texel (at most the
   texture's largest, 1 for 8-bit images), and w a path weight: a product
   of one ks or kt (ks + kt on total internal reflection) a bounce, so at
   most M^(depth - 1) for M the largest ks + kt, and summed over a tree's
   levels at most depth times that (1 each level where M <= 1, as in
   every physical scene).  A mirror of ks 1e10 under a colour of 1e29
   overflowed a full trace's coefficients where the planes gave 5.8e18
   under lights of 1e-30. */
static int mat_in_range(const rtp_tree *t, const rtpi_material *m)
{
    const rtp_scene *s = t->scene;
    double tex = 1.0, big = 1.0, wsum;
    size_t j;
    int c;
    for (j = 0; j < s->nmats; j++)
        big = fmax(big, (double)s->mats[j].ks + s->mats[j].kt);
    wsum = (big > 1.0 ? pow(big, t->max_depth - 1) : 1.0) * t->max_depth;
    if (m->tex == RTPI_TEX_IMAGE && m->tex_image < s->ntexs)
        tex = s->texs[m->tex_image].max_abs;
    for (c = 0; c < 3; c++)
        if (!((fabs((double)m->kd * m->color[c]) * tex + fabs((double)m->ks)) * wsum <=
              RTPI_COEFF_MAX))
            return 0;
    return 1;
}

/* May planes make images at all: the kept coefficients within
   RTPI_COEFF_MAX (t->ev_inf: one passed it since the last full
   evaluation) and the colours cv (nc of them) summing within it too. */
static int planes_in_range(const rtp_tree *t, const double *cv, size_t nc)
{
    double sum = 0.0;
    size_t j;
    for (j = 0; j < nc; j++)
        sum += fabs(cv[j]);
    return !t->ev_inf && sum <= RTPI_COEFF_MAX;
}

/* May the one-term path make this image for a material edit?  Yes when
   the lights, their colours and every other material are as the caches
   have them, and one material without a checker differs from them in kd
   or colour alone: the image is then affine in x = kd * colour of that
   material (rtpi_sample_diffuse).  *mat: the material. */
static int mat_term(rtp_tree *t, const double *cv, size_t nl, uint32_t *mat)
{
    const rtp_scene *s = t->scene;
    size_t j, found = 0;
    /* (coefficients or colours past RTPI_COEFF_MAX: the planes' values
       can be finite where the image the coefficients make is not, so the
       samples are summed as trace sums them) */
    if (!t->ev_valid || !t->ev_cl || !planes_in_range(t, cv, RTPI_COEFFS(nl)))
        return 0;
    for (j = 0; j < RTPI_COEFFS(nl); j++)
        if (cv[j] != t->ev_cl[j])
            return 0;
    for (j = 0; j < s->nmats; j++) {
        const rtpi_material *a = &t->ev_mats[j], *b = &s->mats[j];
        rtpi_material x;
        if (!coeffs_changed(a, b))
            continue;
        if (found++)
            return 0;
        x = *a;
        x.kd = b->kd;
        memcpy(x.color, b->color, sizeof x.color);
        /* (a material with its own ambient coefficient, before or after:
           its ambient part is ka colour, not kd colour, so the image is
           not affine in the one x = kd colour (a kd edit moves only the
           diffuse part, a colour edit both with different weights); its
           edits take the general path, which sums the samples as trace
           does.  Splitting q into its ambient and diffuse parts would
           keep the planes for it, at a second plane a pixel) */
        if (coeffs_changed(&x, b) || b->tex == RTPI_TEX_CHECKER || a->ka_set || b->ka_set)
            return 0;
        *mat = (uint32_t)j;
    }
    /* a sample's coefficient is kd c_obj times path weights and dot
       products, rounded to a float: the full path made it infinite where
       kd c_obj passed the float range, while K x from the planes, the
       lights' colours taken in, stayed finite (kd 2, colour 3e38, lights
       1e-20: 5e18 for infinity): mat_in_range */
    if (!found || !mat_in_range(t, &t->ev_mats[*mat]) || !mat_in_range(t, &s->mats[*mat]))
        return 0;
    if (t->pk_term != (int)(2 + nl + *mat) + 1)
        t->pk_term = 0;
    return 1;
}

/* ------------------------------------------------------ colour planes
   The image is linear in the colours of its terms (background, ambient,
   each light): pixel = sum over terms i of K_i c_i, K_i the term's
   coefficient (for SPD averaged over the pixel's four corner samples).
   While the coefficients stay as they are (no material, shine or light
   position changed), an image for other colours is

       pixel = S + sum over terms d whose colour differs from S's of
               K_d (c_d - cS_d)

   with S the image made by the full path for colours cS (the snapshot,
   cp_s) and K_d one float plane per term (cp_k), made the first time its
   term is edited (or, for the lights, by the evaluation before: cp_ready).  The edit reads 12 bytes of S and of each differing
   term's plane and writes 12 a pixel, and with an image that holds the
   last evaluation (opt->incremental) only the pixels whose K is not 0 of
   the term that changed since (cp_run, in bands of PK_ROWS rows as the
   planes of pk).  Moving between terms (one light's colour, then
   another's, then back) costs no more than editing one; several colours
   at once, one plane each.  S and the planes are made from what the
   full path made (no image of this path feeds the next), so errors do not
   build up along a chain of edits: a pixel is within about a float ulp
   of S's value and its own of what the full path gives. */

/* A plane's table: 4 words a band (cp_seg).  The entries of a band are
   its pixels whose K is not 0, in pixel order, and its runs cover them:
   each is a run of consecutive pixels with consecutive entries, so a
   further edit of the term reads S, K and the image straight through a
   run (cp_run1).  Each band has room from its first entry and run on for
   as many as its rows' spans allow (cp_plane), so threads make bands
   side by side; only what a band holds is touched. */
#define CP_KOFF 0 /* the band's first entry in cp_k */
#define CP_NK 1   /* its entries */
#define CP_ROFF 2 /* its first run in cp_run */
#define CP_NR 3   /* its runs */

/* Frees term i's plane. */
static void cp_drop(rtp_tree *t, size_t i)
{
    rtpi_free(&t->alloc, t->cp_k[i]);
    rtpi_free(&t->alloc, t->cp_seg[i]);
    t->cp_k[i] = NULL;
    t->cp_run[i] = NULL;
    t->cp_seg[i] = NULL;
    t->cp_cap[i] = 0;
    t->cp_ok[i] = 0;
}

/* Frees the colour planes and S. */
static void cp_free(rtp_tree *t)
{
    size_t i;
    for (i = 0; t->cp_k && i < t->cp_nt; i++) {
        rtpi_free(&t->alloc, t->cp_k[i]);
        rtpi_free(&t->alloc, t->cp_seg[i]);
    }
    rtpi_free(&t->alloc, t->cp_k);
    rtpi_free(&t->alloc, t->cp_run);
    rtpi_free(&t->alloc, t->cp_seg);
    rtpi_free(&t->alloc, t->cp_cap);
    rtpi_free(&t->alloc, t->cp_ok);
    rtpi_free(&t->alloc, t->cp_cl);
    rtpi_free(&t->alloc, t->cp_d);
    rtpi_free(&t->alloc, t->cp_dc);
    rtpi_free(&t->alloc, t->cp_ab);
    rtpi_free(&t->alloc, t->cp_kmax);
    rtpi_free(&t->alloc, t->cb_cl);
    rtpi_free(&t->alloc, t->cp_used);
    rtpi_free(&t->alloc, t->cb_p);
    rtpi_free(&t->alloc, t->cp_sown);
    t->cp_sown = NULL;
    t->cp_k = NULL;
    t->cp_run = t->cp_seg = NULL;
    t->cp_cap = NULL;
    t->cp_ok = NULL;
    t->cp_cl = t->cp_dc = t->cp_ab = t->cp_kmax = t->cb_cl = NULL;
    t->cb_p = NULL;
    t->cb_cap = 0;
    t->cp_used = NULL;
    t->cb_term = 0;
    t->cp_d = NULL;
    t->cp_s = NULL;
    t->cp_nt = t->cp_nd = 0;
    t->cp_s_ok = 0;
}

/* The colour term arrays (cp_nt of them), unless they are there. */
static int cp_alloc(rtp_tree *t, size_t nt)
{
    if (t->cp_k && t->cp_nt == nt)
        return 1;
    if (t->cp_k)
        return 0; /* (drop_caches frees them when the lights change) */
    t->cp_k = (float **)rtpi_calloc_array(&t->alloc, nt, sizeof *t->cp_k);
    t->cp_run = (uint32_t **)rtpi_calloc_array(&t->alloc, nt, sizeof *t->cp_run);
    t->cp_seg = (uint32_t **)rtpi_calloc_array(&t->alloc, nt, sizeof *t->cp_seg);
    t->cp_cap = (size_t *)rtpi_calloc_array(&t->alloc, nt, sizeof *t->cp_cap);
    t->cp_ok = (unsigned char *)rtpi_calloc_array(&t->alloc, nt, 1);
    t->cp_cl = (double *)rtpi_malloc_array(&t->alloc, 3 * nt, sizeof *t->cp_cl);
    t->cp_d = (size_t *)rtpi_malloc_array(&t->alloc, nt, sizeof *t->cp_d);
    t->cp_dc = (double *)rtpi_malloc_array(&t->alloc, 3 * nt, sizeof *t->cp_dc);
    t->cp_ab = (double *)rtpi_malloc_array(&t->alloc, 3 * nt, sizeof *t->cp_ab);
    t->cp_kmax = (double *)rtpi_malloc_array(&t->alloc, 3 * nt, sizeof *t->cp_kmax);
    t->cb_cl = (double *)rtpi_malloc_array(&t->alloc, 3 * nt, sizeof *t->cb_cl);
    t->cp_used = (unsigned *)rtpi_calloc_array(&t->alloc, nt, sizeof *t->cp_used);
    if (!t->cp_k || !t->cp_run || !t->cp_seg || !t->cp_cap || !t->cp_ok || !t->cp_cl ||
        !t->cp_d || !t->cp_dc || !t->cp_ab || !t->cp_kmax || !t->cb_cl || !t->cp_used) {
        cp_free(t);
        return 0;
    }
    t->cp_nt = nt;
    return 1;
}

/* Forgets S, and its own block where it has one (cp_ready's: the next S
   lies in the samples' block, cp_snapshot). */
static void cp_s_drop(rtp_tree *t)
{
    t->cp_s_ok = 0;
    rtpi_free(&t->alloc, t->cp_sown);
    t->cp_sown = NULL;
}

/* Forgets S (the coefficients changed) and, for term i (or every term
   where i is (size_t)-1), its plane. */
static void cp_stale(rtp_tree *t, size_t i)
{
    cp_s_drop(t);
    t->cp_gen++;
    if (!t->cp_ok)
        return;
    if (i == (size_t)-1)
        memset(t->cp_ok, 0, t->cp_nt);
    else if (i < t->cp_nt)
        t->cp_ok[i] = 0;
}


/* The pixels *x0 .. *x1 - 1 of pixel row y where term j's K can be other
   than 0: the background's, every pixel; any other term's, the pixels
   with a corner sample that has nodes (cp_plane_chunk: a sample without
   them has no term but the background's), whose hull this is. */
static void cp_span(const rtp_tree *t, size_t j, int y, size_t *x0, size_t *x1)
{
    size_t w = (size_t)t->width, lo, hi, lo2, hi2;
    *x0 = 0;
    *x1 = w;
    if (j == 0)
        return;
    row_nodes(t, (size_t)y, &lo, &hi);
    if (t->spd) {
        /* pixel x: the corners x and x + 1 of sample rows y and y + 1 */
        row_nodes(t, (size_t)y + 1, &lo2, &hi2);
        if (lo2 < hi2) {
            lo = lo < hi && lo < lo2 ? lo : lo2;
            hi = hi > hi2 ? hi : hi2;
        }
        if (lo < hi) {
            lo = lo > 0 ? lo - 1 : 0;
            hi = hi < w ? hi : w;
        }
    }
    *x0 = lo;
    *x1 = hi > lo ? hi : lo;
}

/* A plane's entries and runs as cp_plane_chunk fills them in a band. */
typedef struct cp_fill {
    float *kp;
    uint32_t *run;
    size_t n, nr, next;
    uint32_t mx[3]; /* largest |K| per channel as abs_bits: integer
                       maxima, at or above 0x7f800000 exactly where a K
                       is infinite or NaN */
} cp_fill;

/* One pixel's K (k0, k1, k2, not all 0) into its plane's entries and
   runs (cp_plane_chunk). */
static RTPI_FORCE_INLINE void cp_put(cp_fill *f, float k0, float k1, float k2, size_t p)
{
    uint32_t u;
    float *kp = f->kp + 3 * f->n;
    u = abs_bits(k0), f->mx[0] = u > f->mx[0] ? u : f->mx[0];
    u = abs_bits(k1), f->mx[1] = u > f->mx[1] ? u : f->mx[1];
    u = abs_bits(k2), f->mx[2] = u > f->mx[2] ? u : f->mx[2];
    kp[0] = k0;
    kp[1] = k1;
    kp[2] = k2;
    f->n++;
    if (p == f->next) {
        f->run[2 * f->nr - 1]++;
    } else {
        f->run[2 * f->nr] = (uint32_t)p;
        f->run[2 * f->nr + 1] = 1;
        f->nr++;
    }
    f->next = p + 1;
}

/* cp_row_spd_v and cp_row_flat ask for the coefficients of the sample
   CP_AHEAD on (of sample row y + 1, the one the row pair reads from
   memory; row y's came to cache as the pair before's y + 1): the walk
   rises through ev_coeffs (balls_s4 at 512: 15.8 MB, 60 bytes a sample)
   and the loop waited on its loads (perf: 52% of cp_plane_chunk's time
   at the loads of a column).  A line each 64 bytes: two asked for each
   step of two samples (120 bytes), one a sample in the loop with the
   test.  First light colour edits, CPU medians: balls_s4 4.17 -> 3.39
   ms, tree_s11 3.61 -> 2.62 (HISTORY session 46). */
#define CP_AHEAD 32

#ifdef PK_SSE2
/* 1 where none of the n pixels from sa's column on has four corners
   without nodes (cp_row_spd_v's test), sample rows sa and sa + so: two
   pixels a step, the sums of the rows' node ranges compared as 64-bit
   lanes (both halves equal). */
static int cp_row_full(const uint64_t *sa, size_t so, size_t n)
{
    __m128i lo = _mm_add_epi64(_mm_loadu_si128((const __m128i *)(const void *)sa),
                               _mm_loadu_si128((const __m128i *)(const void *)(sa + so)));
    size_t i = 0;
    for (; i + 2 <= n; i += 2) {
        const __m128i hi =
            _mm_add_epi64(_mm_loadu_si128((const __m128i *)(const void *)(sa + i + 2)),
                          _mm_loadu_si128((const __m128i *)(const void *)(sa + so + i + 2)));
        const int m = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(lo, hi)));
        if (m & (m >> 1) & 5)
            return 0;
        lo = hi;
    }
    return i == n || sa[i + 2] + sa[so + i + 2] != sa[i] + sa[so + i];
}

/* cp_row_spd_v's state along a row. */
typedef struct {
    __m128 mx, bad;  /* largest |K| by lanes; lanes that saw a NaN */
    float *kp;       /* the next entry */
    uint32_t *run;
    size_t nr, next; /* as in cp_fill */
    int in;          /* the pixel before is an entry */
} cp_vrow;

/* Pixel p of cp_row_spd_v from the column sums of its corners (l: left,
   r: right; channels 0 and 1 in one vector, 2 in the low lane of the
   other): its K at the next entry, which advances where K is not 0, and
   the runs opened or closed where that changes. */
static RTPI_FORCE_INLINE void cp_vpx(cp_vrow *v, __m128d l01, __m128d l2, __m128d r01,
                                     __m128d r2, size_t p)
{
    const __m128d q4 = _mm_set1_pd(0.25);
    const __m128 k01 = _mm_cvtpd_ps(_mm_mul_pd(q4, _mm_add_pd(l01, r01)));
    const __m128 k2 = _mm_cvtpd_ps(_mm_mul_pd(q4, _mm_add_pd(l2, r2)));
    /* (lane 3 is 0: cvtpd_ps zeroes the upper half; -0 counts as 0) */
    const __m128i ki = _mm_and_si128(_mm_castps_si128(_mm_movelh_ps(k01, k2)),
                                     _mm_set1_epi32(0x7fffffff));
    const __m128 ka = _mm_castsi128_ps(ki);
    const int nz =
        _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(ki, _mm_setzero_si128()))) != 0xf;
    v->mx = _mm_max_ps(v->mx, ka);
    v->bad = _mm_or_ps(v->bad, _mm_cmpunord_ps(ka, ka));
    _mm_storel_pi((__m64 *)(void *)v->kp, k01);
    _mm_store_ss(v->kp + 2, k2);
    if (nz) {
        v->kp += 3;
        if (!v->in) {
            if (p != v->next) {
                v->run[2 * v->nr] = (uint32_t)p;
                v->nr++;
            } /* (else the run before goes on: the row before ended in it) */
            v->in = 1;
        }
    } else if (v->in) {
        v->run[2 * v->nr - 1] = (uint32_t)(p - v->run[2 * v->nr - 2]);
        v->next = p;
        v->in = 0;
    }
}

/* cp_row_spd's loop on SSE2's vectors: its n pixels from p on (sa: the
   node ranges of sample row y, sa + sbo of row y + 1), skip a constant.
   The same IEEE operations in the same order as the scalar code (the
   same bits).  Each pixel's K is stored at the next entry whether or not
   it is 0 and the entries advance by its being not 0 (a 0 is
   overwritten by the next entry: the band's room has a slot for each
   pixel of its spans, so no store passes it), and a run is opened or
   closed only where that changes; the maxima of |K| by lanes are float
   maxima, with the lanes that saw a NaN apart (a float maximum drops a
   NaN), which are as the scalar code's integer maxima (at or above
   0x7f800000 where a K is infinite or NaN).  A pixel whose four corners
   have no nodes is told by the sums of its two sample rows' node ranges,
   which rise with x (equal two columns apart exactly where both rows'
   are); a row pair without such a pixel (cp_row_spd asks) is walked two
   pixels a step without the test.  About 48 instructions a pixel, the
   scan included, where the loop before, a pixel's entry and run kept up
   pixel by pixel, took 67 (balls_s4: a light's plane at 512 SPD 12.5 M,
   17.6 M before; the scalar code 80). */
static RTPI_FORCE_INLINE void cp_row_spd_v(const float *ka, size_t ks, size_t kbo,
                                           const uint64_t *sa, size_t sbo, size_t n, size_t p,
                                           const int skip, cp_fill *fp)
{
    const __m128 zf = _mm_setzero_ps();
    __m128d l01 = _mm_setzero_pd(), l2 = _mm_setzero_pd(), r01, r2;
    const float *ra = ka + ks, *rb = ka + ks + kbo; /* the pixel's right corners */
    cp_vrow v;
    size_t i = 0;
    uint64_t u0 = 0, u1 = 0;
    int have = 0;
    {
        float m[4];
        uint32_t u[4] = {fp->mx[0], fp->mx[1], fp->mx[2], 0};
        memcpy(m, u, sizeof m);
        v.mx = _mm_loadu_ps(m);
        v.bad = _mm_cmpunord_ps(v.mx, v.mx);
    }
    v.kp = fp->kp + 3 * fp->n;
    v.run = fp->run;
    v.nr = fp->nr;
    v.next = fp->next;
    v.in = 0;
#define CP_COL(a, b, c01, c2)                                                                   \
    (c01 = _mm_add_pd(_mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)(a))),        \
                      _mm_cvtps_pd(_mm_loadl_pi(zf, (const __m64 *)(const void *)(b)))),        \
     c2 = _mm_add_pd(_mm_cvtps_pd(_mm_load_ss((a) + 2)), _mm_cvtps_pd(_mm_load_ss((b) + 2))))
    if (!skip) {
        __m128d s01, s2;
        if (n)
            CP_COL(ka, ka + kbo, l01, l2);
        for (; i + 2 <= n; i += 2, ra += 2 * ks, rb += 2 * ks) {
            RTPI_PREFETCH(rb, CP_AHEAD * ks * sizeof *rb);
            RTPI_PREFETCH(rb, (CP_AHEAD * ks + 16) * sizeof *rb);
            CP_COL(ra, rb, r01, r2);
            CP_COL(ra + ks, rb + ks, s01, s2);
            cp_vpx(&v, l01, l2, r01, r2, p + i);
            cp_vpx(&v, r01, r2, s01, s2, p + i + 1);
            l01 = s01;
            l2 = s2;
        }
        if (i < n) {
            CP_COL(ra, rb, r01, r2);
            cp_vpx(&v, l01, l2, r01, r2, p + i);
            i++;
        }
    } else {
        u0 = sa[0] + sa[sbo];
        u1 = sa[1] + sa[sbo + 1];
        for (; i < n; i++, ra += ks, rb += ks) {
            const uint64_t u2 = sa[i + 2] + sa[sbo + i + 2];
            const int none = u2 == u0;
            RTPI_PREFETCH(rb, CP_AHEAD * ks * sizeof *rb);
            u0 = u1;
            u1 = u2;
            if (none) {
                if (v.in) {
                    v.run[2 * v.nr - 1] = (uint32_t)(p + i - v.run[2 * v.nr - 2]);
                    v.next = p + i;
                    v.in = 0;
                }
                have = 0;
                continue;
            }
            if (!have)
                CP_COL(ra - ks, rb - ks, l01, l2);
            CP_COL(ra, rb, r01, r2);
            cp_vpx(&v, l01, l2, r01, r2, p + i);
            l01 = r01;
            l2 = r2;
            have = 1;
        }
    }
#undef CP_COL
    if (v.in) {
        v.run[2 * v.nr - 1] = (uint32_t)(p + n - v.run[2 * v.nr - 2]);
        v.next = p + n;
    }
    {
        float m[4];
        uint32_t u[4], b[4];
        _mm_storeu_ps(m, v.mx);
        memcpy(u, m, sizeof u);
        _mm_storeu_ps(m, v.bad);
        memcpy(b, m, sizeof b);
        fp->mx[0] = b[0] ? 0x7fc00000u : u[0];
        fp->mx[1] = b[1] ? 0x7fc00000u : u[1];
        fp->mx[2] = b[2] ? 0x7fc00000u : u[2];
    }
    fp->n = (size_t)(v.kp - fp->kp) / 3;
    fp->nr = v.nr;
    fp->next = v.next;
}
#endif


/* cp_plane_chunk's pixels x .. x1 - 1 of a pixel row with corner
   samples for one term (the first pixel p, its coefficients at ka, its
   samples' node ranges at sa and sb; skip: the term is not the
   background's), into f: pk_build_chunk's sums, by columns.  The corners
   (x, y) and (x, y + 1) of pixel x are its left column, the next pixel's
   right one, each column's sum made once (`have`: l holds column x's);
   the sum of four floats in double is exact but where their exponents
   lie more than 29 apart, so the order of the sums does not show.  One
   term at a time, its sums and entries in registers (several terms'
   planes, cp_ready's, each walk the two sample rows again, from cache). */
static void cp_row_spd(const float *ka, size_t ks, size_t kbo, const uint64_t *sa,
                       const uint64_t *sb, size_t x, size_t x1, size_t p, int skip,
                       cp_fill *fp)
{
    cp_fill f = *fp;
#ifdef PK_SSE2
    {
        /* (a row pair where no pixel's corners are all without nodes,
           balls_s4's every one, is walked without the test, two pixels a
           step: cp_row_spd_v) */
        const size_t n = x1 - x, so = (size_t)(sb - sa);
        if (skip && !cp_row_full(sa, so, n))
            cp_row_spd_v(ka, ks, kbo, sa, so, n, p, 1, &f);
        else
            cp_row_spd_v(ka, ks, kbo, sa, so, n, p, 0, &f);
    }
#else
    double l0 = 0.0, l1 = 0.0, l2 = 0.0;
    int have = 0;
    for (; x < x1; x++, p++, ka += ks, sa++, sb++) {
        double r0, r1, r2;
        float k0, k1, k2;
        if (skip && sa[2] == sa[0] && sb[2] == sb[0]) {
            /* Samples without nodes (the eye ray saw the background)
               have no term but the background's: 0 here, known without
               reading their coefficients (tetra: 81% of the samples,
               whose coefficients were most of the bytes a light's first
               colour edit read) */
            have = 0;
            continue;
        }
        if (!have) {
            l0 = (double)ka[0] + ka[kbo];
            l1 = (double)ka[1] + ka[kbo + 1];
            l2 = (double)ka[2] + ka[kbo + 2];
        }
        r0 = (double)ka[ks] + ka[kbo + ks];
        r1 = (double)ka[ks + 1] + ka[kbo + ks + 1];
        r2 = (double)ka[ks + 2] + ka[kbo + ks + 2];
        k0 = (float)(0.25 * (l0 + r0));
        k1 = (float)(0.25 * (l1 + r1));
        k2 = (float)(0.25 * (l2 + r2));
        l0 = r0;
        l1 = r1;
        l2 = r2;
        have = 1;
        /* (-0 counts as 0) */
        if ((abs_bits(k0) | abs_bits(k1) | abs_bits(k2)) != 0)
            cp_put(&f, k0, k1, k2, p);
    }
#endif
    *fp = f;
}

/* cp_row_spd's work where each pixel is a sample of its own. */
static void cp_row_flat(const float *ka, size_t ks, const uint64_t *sa, size_t x, size_t x1,
                        size_t p, int skip, cp_fill *fp)
{
    cp_fill f = *fp;
    for (; x < x1; x++, p++, ka += ks, sa++) {
        RTPI_PREFETCH(ka, CP_AHEAD * ks * sizeof *ka); /* (CP_AHEAD) */
        /* (a sample without nodes: cp_row_spd) */
        if ((!skip || sa[1] != sa[0]) &&
            (abs_bits(ka[0]) | abs_bits(ka[1]) | abs_bits(ka[2])) != 0)
            cp_put(&f, ka[0], ka[1], ka[2], p);
    }
    *fp = f;
}

/* One band of the planes of terms e->cp_terms (e->cp_n of them, each a
   light's or the ambient's when more than one: their spans and the
   samples they skip are alike), row by row (a row's coefficients read
   from memory once): their pixels whose K is not 0, their K and runs
   (cp_seg's layout). */
static int cp_plane_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    rtp_tree *t = e->t;
    size_t w = (size_t)t->width, nx = (size_t)t->nx, ks = RTPI_COEFFS(t->scene->nlights);
    size_t nq = e->cp_n, q, j0 = e->cp_terms[0];
    cp_fill f[CP_MAX_PLANES];
    int y0 = chunk * PK_ROWS, y1 = y0 + PK_ROWS, y, c, spd = t->spd;
    if (y1 > t->height)
        y1 = t->height;
    for (q = 0; q < nq; q++) {
        const size_t j = e->cp_terms[q];
        const uint32_t *bt = t->cp_seg[j] + 4 * (size_t)chunk;
        f[q].kp = t->cp_k[j] + 3 * (size_t)bt[CP_KOFF];
        f[q].run = t->cp_run[j] + 2 * (size_t)bt[CP_ROFF];
        f[q].n = f[q].nr = 0;
        f[q].next = (size_t)-1;
        f[q].mx[0] = f[q].mx[1] = f[q].mx[2] = 0;
    }
    for (y = y0; y < y1; y++) {
        size_t x, x1, p;
        const float *ka;
        const uint64_t *sa, *sb;
        /* (outside the span K is 0: the background's rows and the sides
           of the scene are not walked, their coefficients not read) */
        cp_span(t, j0, y, &x, &x1);
        p = (size_t)y * w + x;
        ka = t->ev_coeffs + (spd ? (size_t)y * nx + x : p) * ks;
        /* the node ranges of the pixel's samples (its corners: sample
           rows y and y + 1) */
        sa = t->start + (spd ? (size_t)y * nx + x : p);
        sb = spd ? sa + nx : sa;
        for (q = 0; q < nq; q++)
            if (spd)
                cp_row_spd(ka + 3 * e->cp_terms[q], ks, nx * ks, sa, sb, x, x1, p, j0 > 0,
                           &f[q]);
            else
                cp_row_flat(ka + 3 * e->cp_terms[q], ks, sa, x, x1, p, j0 > 0, &f[q]);
    }
    for (q = 0; q < nq; q++) {
        uint32_t *bt = t->cp_seg[e->cp_terms[q]] + 4 * (size_t)chunk;
        for (c = 0; c < 3; c++) {
            float m;
            /* (an infinite or NaN K: an infinite maximum, which
               cp_planes takes for a plane not to be used) */
            if (f[q].mx[c] >= 0x7f800000u)
                m = HUGE_VALF;
            else
                memcpy(&m, &f[q].mx[c], sizeof m);
            if (m > e->kmax[3 * q + c])
                e->kmax[3 * q + c] = m;
        }
        bt[CP_NK] = (uint32_t)f[q].n;
        bt[CP_NR] = (uint32_t)f[q].nr;
    }
    return 0;
}

/* Room for the plane of term j, unless it holds or has it; 0 where
   there is no memory for it. */
static int cp_plane_room(rtp_tree *t, size_t j)
{
    size_t nk = 0, nr = 0, bytes;
    int b, y, nb = (t->height + PK_ROWS - 1) / PK_ROWS;
    uint32_t *bt;
    if (!t->cp_k[j]) {
        /* at most CP_MAX_PLANES planes: the least recently used other
           than this evaluation's (cp_used == cp_clock) goes */
        size_t have = 0, victim = (size_t)-1, q;
        for (q = 0; q < t->cp_nt; q++)
            if (t->cp_k[q]) {
                have++;
                if (t->cp_used[q] != t->cp_clock &&
                    (victim == (size_t)-1 || t->cp_used[q] < t->cp_used[victim]))
                    victim = q;
            }
        if (have >= CP_MAX_PLANES && victim != (size_t)-1)
            cp_drop(t, victim);
    }
    if (!t->cp_seg[j] &&
        !(t->cp_seg[j] = (uint32_t *)rtpi_malloc_array(&t->alloc, (size_t)nb, 4 * sizeof(uint32_t))))
        return 0;
    /* each band's room: its rows' spans, a run at most every other pixel
       of a span (runs are apart), so the block is about as large as the
       pixels the term reaches (tetra's lights: a third of the image) */
    bt = t->cp_seg[j];
    for (b = 0, y = 0; b < nb; b++) {
        bt[4 * b + CP_KOFF] = (uint32_t)nk;
        bt[4 * b + CP_ROFF] = (uint32_t)nr;
        bt[4 * b + CP_NK] = bt[4 * b + CP_NR] = 0;
        for (; y < (b + 1) * PK_ROWS && y < t->height; y++) {
            size_t x0, x1;
            cp_span(t, j, y, &x0, &x1);
            nk += x1 - x0;
            nr += (x1 - x0 + 1) / 2;
        }
    }
    bytes = (3 * nk + 2 * nr + 1) * sizeof(float);
    if (t->cp_k[j] && t->cp_cap[j] < bytes) {
        rtpi_free(&t->alloc, t->cp_k[j]);
        t->cp_k[j] = NULL;
    }
    if (!t->cp_k[j]) {
        t->cp_k[j] = (float *)rtpi_malloc_array(&t->alloc, 3 * nk + 2 * nr + 1, sizeof(float));
        t->cp_cap[j] = t->cp_k[j] ? bytes : 0;
    }
    if (!t->cp_k[j])
        return 0;
    t->cp_run[j] = (uint32_t *)(void *)(t->cp_k[j] + 3 * nk);
    return 1;
}

/* The room for entries term j's plane has (what its bands' spans
   allow): cb_p's room. */
static size_t cp_extent(const rtp_tree *t, size_t j)
{
    return (size_t)(t->cp_run[j] - (const uint32_t *)(const void *)t->cp_k[j]) / 3;
}

/* The planes of the n terms terms[] (at most CP_MAX_PLANES; more than
   one: lights' or the ambient's, cp_plane_chunk), but those that hold, in
   one pass; 0 where one cannot be made (no memory, or values beyond the
   float range: the full path serves). */
static int cp_planes(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads,
                     const size_t *terms, size_t n)
{
    size_t todo[CP_MAX_PLANES], m = 0, q;
    int i, c, nb = (t->height + PK_ROWS - 1) / PK_ROWS, ok = 1;
    double work = 0.0;
    for (q = 0; q < n; q++)
        if (!t->cp_ok[terms[q]]) {
            if (!cp_plane_room(t, terms[q]))
                return 0;
            todo[m++] = terms[q];
            work += (double)cp_extent(t, terms[q]);
        }
    if (!m)
        return 1;
    for (i = 0; i < nthreads; i++) {
        e[i].cp_terms = todo;
        e[i].cp_n = m;
        for (c = 0; c < 3 * CP_MAX_PLANES; c++)
            e[i].kmax[c] = 0.0;
    }
    tree_rows(t, nb,
              threads_for((16.0 + 4.0 * RTPI_COEFFS(t->scene->nlights)) * work, nthreads),
              ctx, cp_plane_chunk, NULL, NULL);
    for (q = 0; q < m; q++) {
        const size_t j = todo[q];
        int okj = 1;
        for (c = 0; c < 3; c++)
            t->cp_kmax[3 * j + c] = 0.0;
        for (i = 0; i < nthreads; i++)
            for (c = 0; c < 3; c++)
                if (e[i].kmax[3 * q + c] > t->cp_kmax[3 * j + c])
                    t->cp_kmax[3 * j + c] = e[i].kmax[3 * q + c];
        for (c = 0; c < 3; c++)
            okj &= isfinite(t->cp_kmax[3 * j + c]) != 0;
        t->cp_ok[j] = (unsigned char)okj;
        ok &= okj;
    }
    return ok;
}

/* The plane of term j, unless it holds (cp_planes). */
static int cp_plane(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads, size_t j)
{
    return cp_planes(t, e, ctx, nthreads, &j, 1);
}

/* Copies n pixels src to dst (unless dst is NULL) and sets m[c] to the
   largest |value| of channel c; 1 where every value is finite.  Four
   pixels a step as three rows of four values against the channels'
   pattern, each row's maxima and zero sums a four-wide operation with
   gcc 12 -O2 (a float max is one instruction; an integer one takes four
   without SSE4): 7.8 instructions a pixel where a scan after memcpy took
   14.7, and one pass over the image, not two. */
static int cp_copy_max(float *restrict dst, const float *restrict src, size_t n, double m[3])
{
    /* a[r][c]: lane c of row r (channel (4 r + c) % 3); z: sums of each
       value times 0, which stay 0 unless a value is infinite or NaN (a
       NaN fails the comparisons of the maxima) */
    float a0[4] = {0.0f}, a1[4] = {0.0f}, a2[4] = {0.0f};
    float z0[4] = {0.0f}, z1[4] = {0.0f}, z2[4] = {0.0f}, mc[3], z = 0.0f;
    size_t i;
    int c;
    for (i = 0; i + 4 <= n; i += 4) {
        const float *q = src + 3 * i;
        for (c = 0; c < 4; c++) {
            const float x = fabsf(q[c]), y = fabsf(q[4 + c]), w = fabsf(q[8 + c]);
            a0[c] = x > a0[c] ? x : a0[c];
            a1[c] = y > a1[c] ? y : a1[c];
            a2[c] = w > a2[c] ? w : a2[c];
            z0[c] += q[c] * 0.0f;
            z1[c] += q[4 + c] * 0.0f;
            z2[c] += q[8 + c] * 0.0f;
        }
        if (dst)
            memcpy(dst + 3 * i, q, 12 * sizeof *q);
    }
    /* lanes to channels: row 0 holds 0 1 2 0, row 1 1 2 0 1, row 2 2 0 1 2 */
    mc[0] = a0[0] > a0[3] ? a0[0] : a0[3];
    mc[1] = a0[1] > a1[0] ? a0[1] : a1[0];
    mc[2] = a0[2] > a1[1] ? a0[2] : a1[1];
    mc[2] = a2[0] > mc[2] ? a2[0] : mc[2];
    mc[2] = a2[3] > mc[2] ? a2[3] : mc[2];
    mc[0] = a1[2] > mc[0] ? a1[2] : mc[0];
    mc[0] = a2[1] > mc[0] ? a2[1] : mc[0];
    mc[1] = a1[3] > mc[1] ? a1[3] : mc[1];
    mc[1] = a2[2] > mc[1] ? a2[2] : mc[1];
    for (c = 0; c < 4; c++)
        z += z0[c] + z1[c] + z2[c];
    for (; i < n; i++)
        for (c = 0; c < 3; c++) {
            const float v = src[3 * i + c], x = fabsf(v);
            mc[c] = x > mc[c] ? x : mc[c];
            z += v * 0.0f;
            if (dst)
                dst[3 * i + c] = v;
        }
    for (c = 0; c < 3; c++)
        m[c] = mc[c];
    return z == 0.0f;
}

/* S from the samples (which hold the colours ev_cl for the coefficients
   now), unless it holds: the image `last` when it holds the last
   evaluation (made from those samples), else the samples resolved; in
   the samples' own block (ev_samples), which holds S from then on (cp_s
   points into it).  The samples are used up: every colour edit leaves
   them holding the colours before (cp_eval), so the next thing to read
   them makes them all anew first (eval_row, combine_row), and S goes with
   them (cp_stale, and combine_row's branch of eval_impl).  A block of its
   own for S was 3 MB of fresh memory at 512x512, two huge pages the
   kernel zeroed: tetra_s6's first light-colour edit took 7 page faults,
   now 3.  0 where it cannot be made (a value beyond the float range; the
   samples are used up all the same), or where the colours they hold sum
   past RTPI_COEFF_MAX (planes_in_range): S + K (c - cS) then cancels
   digits the samples never held (an ambient of 3.4e38, then 0.9: the
   samples hold 2^126 where K cS is 8.5e37 and more, and the pixel read
   -2.5e38 against the full path's 1.06; fuzz_streams seed 18251). */
static int cp_snapshot(rtp_tree *t, float *samples, const float *last, size_t nt)
{
    size_t np = (size_t)t->width * t->height, w = (size_t)t->width, x, y;
    int c, finite;
    if (t->cp_s_ok)
        return 1;
    if (!t->ev_samples_ok || !samples || samples != t->ev_samples ||
        !planes_in_range(t, t->ev_cl, 3 * nt))
        return 0;
    t->ev_samples_ok = 0;
    cp_s_drop(t); /* (S in its own block no more: cp_ready's) */
    if (last) {
        finite = cp_copy_max(samples, last, np, t->cp_smax);
    } else {
        if (t->spd)
            /* each pixel the average of its four corners (rtpi_resolve_pixel's
               sum), in place: pixel (x, y) goes to 3 (y w + x), below where
               every pixel after it reads, at 3 (y (w + 1) + x) and on (its
               own first corner there when y is 0, each channel read before
               it is written) */
            for (y = 0; y < (size_t)t->height; y++) {
                const float *a = samples + 3 * y * (w + 1), *b = a + 3 * (w + 1);
                float *o = samples + 3 * y * w;
                for (x = 0; x < w; x++, a += 3, b += 3, o += 3)
                    for (c = 0; c < 3; c++)
                        o[c] = 0.25f * (a[c] + a[3 + c] + b[c] + b[3 + c]);
            }
        /* (a pixel of its own per sample: the samples are S as they are) */
        finite = cp_copy_max(NULL, samples, np, t->cp_smax);
    }
    t->cp_s = samples;
    for (c = 0; c < 3; c++)
        finite &= isfinite(t->cp_smax[c]) != 0;
    if (!finite)
        return 0; /* an infinity or NaN */
    memcpy(t->cp_cl, t->ev_cl, 3 * nt * sizeof *t->cp_cl);
    t->cp_s_ok = 1;
    t->cp_gen++; /* (a chain's P' was made from another S) */
    return 1;
}

/* Lights a scene has at most for a first evaluation to make their colour
   planes (cp_ready). */
#define CP_READY_LIGHTS 2

/* After the full path into an image the caller keeps for further edits
   (opt->incremental), S and, in a scene of one or two lights, their
   colour planes, so that the first colour edit of a light costs what a
   further one does (with more lights, S spares that edit its copy: 2.4 M
   instructions at 512 SPD, balls' first light-colour edit 19.09 -> 16.67
   M, tree's 14.06 -> 11.63, for 2.4 M more in the first evaluation,
   +0.6-0.9%).  A light's plane costs about what its first colour
   edit did (made then, that edit was 1/53 to 1/128 of a trace's time on
   the one- and two-light SPD scenes: mount's 17.7 M instructions against
   1.9 M for a further edit), and here it is made while the evaluation's
   coefficients are at hand, where a session starts (first evaluation
   +4% on mount, +6% on tetra, +10% on teapot).  With more lights a
   session that edits one light's colour would pay for every plane (tree's
   seven: +28%; session 44, the loop of session 42: balls +11.8%, tree
   +23.3%): they are made at each light's first edit, as before.  S
   takes a block of its own (12 bytes a pixel), not the samples'
   (cp_snapshot): the samples stay, for a material's shine edit to
   recombine only its own.  Nothing is made where any of it cannot be:
   the first edit makes what it needs then. */
static void cp_ready(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads,
                     const double *cv, const float *pixels)
{
    size_t nl = t->scene->nlights, nt = 2 + nl, np = (size_t)t->width * t->height, j, n = 0;
    size_t terms[CP_READY_LIGHTS];
    int c, finite;
    if (!nl || !t->ev_valid || !t->ev_cl ||
        !planes_in_range(t, cv, RTPI_COEFFS(nl)) ||
        !cp_alloc(t, nt))
        return;
    if (!t->cp_sown &&
        !(t->cp_sown = (float *)rtpi_malloc_array(&t->alloc, np, 3 * sizeof(float))))
        return;
    finite = cp_copy_max(t->cp_sown, pixels, np, t->cp_smax);
    for (c = 0; c < 3; c++)
        finite &= isfinite(t->cp_smax[c]) != 0;
    if (!finite) {
        rtpi_free(&t->alloc, t->cp_sown);
        t->cp_sown = NULL;
        return;
    }
    t->cp_s = t->cp_sown;
    memcpy(t->cp_cl, t->ev_cl, 3 * nt * sizeof *t->cp_cl);
    t->cp_s_ok = 1;
    t->cp_gen++;
    if (nl > CP_READY_LIGHTS)
        return;
    t->cp_clock++;
    for (j = 2; j < nt; j++) {
        terms[n++] = j;
        t->cp_used[j] = t->cp_clock;
    }
    /* (a plane that could not be made is made at its first edit) */
    (void)cp_planes(t, e, ctx, nthreads, terms, n);
}

/* S and the planes are floats: S + K (c - cS) carries their rounding,
   about 2^-24 of |S| + sum |K_d| (|c_d| + |cS_d|), where P + K c from
   the coefficients carries 2^-24 of the pixel.  That sum may not pass
   CP_SPAN times the pixel, nor CP_SPAN * 2 (see CP_SPAN): else the full
   path makes the image (and S anew from it).  Where the bound of the sum
   over the whole image (cp_smax, cp_kmax) is below CP_SPAN * 2, no pixel
   is checked. */

static int cp_lost(double s, double kc, double v)
{
    double a = fabs(v);
    return !(fabs(s) + kc <= CP_SPAN * (a > 2.0 ? a : 2.0));
}

/* A walk through one plane's runs in a band, pixel by pixel in rising
   order: K at a pixel without reading the plane's other pixels. */
typedef struct {
    const uint32_t *run, *rend; /* the runs ahead */
    const float *k;             /* K of pixel p0 */
    size_t p0, p1;              /* the run at hand: pixels p0 .. p1 - 1 */
} cp_cur;

static void cp_cur_band(const rtp_tree *t, size_t j, int chunk, cp_cur *cu)
{
    const uint32_t *bt = t->cp_seg[j] + 4 * (size_t)chunk;
    cu->run = t->cp_run[j] + 2 * (size_t)bt[CP_ROFF];
    cu->rend = cu->run + 2 * (size_t)bt[CP_NR];
    cu->k = t->cp_k[j] + 3 * (size_t)bt[CP_KOFF];
    cu->p0 = cu->p1 = 0;
}

/* K at pixel p (at or after the pixel of the call before), or NULL where
   it is 0. */
static inline const float *cp_at(cp_cur *cu, size_t p)
{
    while (p >= cu->p1) {
        if (cu->run == cu->rend)
            return NULL;
        cu->k += 3 * (cu->p1 - cu->p0);
        cu->p0 = cu->run[0];
        cu->p1 = cu->p0 + cu->run[1];
        cu->run += 2;
    }
    return p >= cu->p0 ? cu->k + 3 * (p - cu->p0) : NULL;
}

/* The cursors of the differing terms in band `chunk`. */
static void cp_curs(const rtp_tree *t, int chunk, cp_cur *cu)
{
    size_t i;
    for (i = 0; i < t->cp_nd; i++)
        cp_cur_band(t, t->cp_d[i], chunk, &cu[i]);
}

/* S + sum K_d (c_d - cS_d) at pixel p over the first n differing terms
   (cp_d's order: the one changed last is last, cp_eval), K_d from cursor
   cu[i] of each (k[i]: NULL where 0).  A term whose K is 0 adds nothing
   (adding its 0 x dc changed nothing but the sign of a zero sum).  The
   changed term last: a chain's P' (cb_chunk, the sum without it) plus
   its K dc is then this sum to the bit, so a region whose pixels hold no
   lost digits (cp_check 0: the chain) makes the pixels its frame makes
   by cp_pixel (a frame's check is set by pixels elsewhere; the chain's P'
   in floats put them a float step apart, 5.96e-8 at 1). */
static void cp_sum(const rtp_tree *t, size_t p, size_t n, cp_cur *cu, double v[3],
                   const float **k)
{
    const float *sp = t->cp_s + 3 * p;
    size_t i;
    int c;
    for (c = 0; c < 3; c++)
        v[c] = sp[c];
    for (i = 0; i < n; i++) {
        const double *dc = t->cp_dc + 3 * i;
        k[i] = cp_at(&cu[i], p);
        if (k[i])
            for (c = 0; c < 3; c++)
                v[c] += k[i][c] * dc[c];
    }
}

/* The full path's pixel p (combine_row, then resolve_row's sums for
   SPD's corners) from the coefficients, which hold, into out. */
static void cp_full_pixel(eval_ctx *e, size_t p, float *out)
{
    const rtp_tree *t = e->t;
    size_t nc = RTPI_COEFFS(t->scene->nlights), w = (size_t)t->width, k;
    float a[3], b[3], d[3], f[3];
    int c;
    e->combined += t->spd ? 4 : 1;
    if (!t->spd) {
        rtpi_combine(t->scene, e->cl, t->ev_coeffs + p * nc, out);
        return;
    }
    k = (p / w) * (w + 1) + p % w;
    rtpi_combine(t->scene, e->cl, t->ev_coeffs + k * nc, a);
    rtpi_combine(t->scene, e->cl, t->ev_coeffs + (k + 1) * nc, b);
    rtpi_combine(t->scene, e->cl, t->ev_coeffs + (k + w + 1) * nc, d);
    rtpi_combine(t->scene, e->cl, t->ev_coeffs + (k + w + 2) * nc, f);
    for (c = 0; c < 3; c++)
        out[c] = 0.25f * (a[c] + b[c] + d[c] + f[c]);
}

/* One pixel: cp_sum over every differing term; where
   checked and it lost digits, the full path's pixel instead.  That pixel
   alone: the image's other pixels, and S, stay as the planes make them
   (a lost pixel sent the whole image down the full path and made S anew
   from it, so a region without one, traced or evaluated apart, kept
   other bits than its frame: README "Splitting a frame"). */
static void cp_pixel(eval_ctx *e, size_t p, cp_cur *cu, float *out)
{
    const rtp_tree *t = e->t;
    const float *sp = t->cp_s + 3 * p, *k[CP_MAX_PLANES];
    double v[3], kc[3] = {0.0, 0.0, 0.0};
    size_t i, nd = t->cp_nd;
    int c;
    cp_sum(t, p, nd, cu, v, k);
    for (c = 0; c < 3; c++)
        out[c] = (float)v[c];
    if (!t->cp_check)
        return;
    for (i = 0; i < nd; i++)
        for (c = 0; k[i] && c < 3; c++)
            kc[c] += fabs(k[i][c]) * t->cp_ab[3 * i + c];
    if (cp_lost(sp[0], kc[0], v[0]) | cp_lost(sp[1], kc[1], v[1]) | cp_lost(sp[2], kc[2], v[2]))
        cp_full_pixel(e, p, out);
}

/* A band of every pixel. */
static int cp_apply_band(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t p = (size_t)chunk * PK_ROWS * (size_t)t->width, end = p + PK_ROWS * (size_t)t->width;
    cp_cur cu[CP_MAX_PLANES];
    if (end > (size_t)t->width * t->height)
        end = (size_t)t->width * t->height;
    cp_curs(t, chunk, cu);
    for (; p < end; p++)
        cp_pixel(e, p, cu, e->pixels + 3 * p);
    return 0;
}

/* S + K dc at four consecutive pixels (dd: dc's colours four times). */
static RTPI_FORCE_INLINE void cp_quad1(const float *restrict a, const float *restrict b,
                                       const double *restrict dd, float *restrict o)
{
    int c;
    /* the twelve values in one loop against the colours' pattern: gcc 12
       -O2 makes two-wide operations of all of them (two pixels a step
       paired four of six); the same arithmetic value by value */
    for (c = 0; c < 12; c++)
        o[c] = (float)(a[c] + b[c] * dd[c]);
}

/* S + K dc over len consecutive pixels (cp_apply_listed, one term).  A
   run of four or more ends with the quad of its last four pixels, which
   makes again the pixels the quad before made where len is not a
   multiple of 4 (the same values from the same inputs, S and K, never
   the image's block, cp_snapshot: the same bits): a run's length then
   decides one branch, the loop's exit, where the steps of two and the
   last pixel decided two more (tetra_s6's light plane: 3,348 runs for
   49,370 pixels at 512x512, 546 of them under four pixels; callgrind's
   branch simulation 7.7 k mispredicted of 57.7 k; the further light
   colour edit 4% less time at 512x512, 14% at 1024x1024). */
static void cp_run1(const float *restrict sp, const float *restrict k, const double *dd,
                    float *restrict out, size_t len)
{
    size_t i;
    if (len >= 4) {
        const size_t last = len - 4;
        for (i = 0; i < last; i += 4)
            cp_quad1(sp + 3 * i, k + 3 * i, dd, out + 3 * i);
        cp_quad1(sp + 3 * last, k + 3 * last, dd, out + 3 * last);
        return;
    }
    for (i = 0; i < len; i++) {
        out[3 * i] = (float)(sp[3 * i] + k[3 * i] * dd[0]);
        out[3 * i + 1] = (float)(sp[3 * i + 1] + k[3 * i + 1] * dd[1]);
        out[3 * i + 2] = (float)(sp[3 * i + 2] + k[3 * i + 2] * dd[2]);
    }
}

/* Runs ahead of the one at hand whose S and image lines are asked for
   (two lines of each: a run is 15-17 pixels, 3-4 lines, on tetra_s6):
   the runs start where the plane's pixels do, scattered over the image,
   and the hardware's prefetchers meet each run's first lines as misses
   (perf: the hottest instruction of cp_apply_listed a load of S).  2, 4,
   8 or 16 runs ahead: tetra_s6's further light colour edit 9-26% less
   time than none (HISTORY, session 52); 8 kept. */
#ifndef CP_RUN_AHEAD
#define CP_RUN_AHEAD 8
#endif

/* A band of the pixels whose K is not 0 in the plane of term e->term. */
static int cp_apply_listed(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    const uint32_t *bt = t->cp_seg[e->term] + 4 * (size_t)chunk;
    const uint32_t *run = t->cp_run[e->term] + 2 * (size_t)bt[CP_ROFF];
    const uint32_t *rend = run + 2 * (size_t)bt[CP_NR];
    float *out = e->pixels;
    if (!t->cp_check && t->cp_nd == 1 && t->cp_d[0] == e->term) {
        /* the common case, the term alone differing from S: a run at a
           time, S, K and the image read and written straight through
           (the sums as cp_pixel makes them) */
        const float *k = t->cp_k[e->term] + 3 * (size_t)bt[CP_KOFF];
        const double *dc = t->cp_dc;
        const double dd[12] = {dc[0], dc[1], dc[2], dc[0], dc[1], dc[2],
                               dc[0], dc[1], dc[2], dc[0], dc[1], dc[2]};
        for (; run < rend; run += 2) {
            size_t p0 = run[0], len = run[1];
            if (rend - run > 2 * CP_RUN_AHEAD) {
                const size_t pa = 3 * (size_t)run[2 * CP_RUN_AHEAD];
                RTPI_PREFETCH(t->cp_s + pa, 0);
                RTPI_PREFETCH(t->cp_s + pa, 64);
                RTPI_PREFETCH(out + pa, 0);
                RTPI_PREFETCH(out + pa, 64);
            }
            cp_run1(t->cp_s + 3 * p0, k, dd, out + 3 * p0, len);
            k += 3 * len;
        }
    } else {
        cp_cur cu[CP_MAX_PLANES];
        cp_curs(t, chunk, cu);
        for (; run < rend; run += 2) {
            size_t p = run[0], end = p + run[1];
            for (; p < end; p++)
                cp_pixel(e, p, cu, out + 3 * p);
        }
    }
    return 0;
}

/* A chain of edits of one term j while other terms differ from S too
   (the ambient after a light's colour): the sum of the others, P' = S +
   sum over d other than j of K_d (c_d - cS_d), is made once at the
   pixels whose K_j is not 0 (cb_p, as the entries of plane j), and each
   edit of the chain reads it and K_j alone, as for one term.  P' is
   kept in doubles, cp_sum's own before it adds K_j: each edit gives the
   bits cp_pixel gives (a float P' was rounded once more, a float step
   off them); it is made from S and the planes, never from an image. */
static int cb_chunk(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    const uint32_t *bt = t->cp_seg[e->term] + 4 * (size_t)chunk;
    const uint32_t *run = t->cp_run[e->term] + 2 * (size_t)bt[CP_ROFF];
    const uint32_t *rend = run + 2 * (size_t)bt[CP_NR];
    double *pb = t->cb_p + 3 * (size_t)bt[CP_KOFF];
    cp_cur cu[CP_MAX_PLANES];
    const float *k[CP_MAX_PLANES];
    /* (the others: e->term, where it differs, is cp_d's last) */
    const size_t n = t->cp_nd - (size_t)(t->cp_nd && t->cp_d[t->cp_nd - 1] == e->term);
    cp_curs(t, chunk, cu);
    for (; run < rend; run += 2) {
        size_t p = run[0], end = p + run[1];
        for (; p < end; p++, pb += 3)
            cp_sum(t, p, n, cu, pb, k);
    }
    return 0;
}

#ifdef PK_SSE2
/* cb_apply's o = P' + K dc for four values (dlo, dhi: the colours of
   values 0-1 and 2-3), the scalar code's operations. */
static inline void cb_quad(const double *pb, const float *k, float *o, __m128d dlo, __m128d dhi)
{
    const __m128 kf = _mm_loadu_ps(k);
    const __m128d lo = _mm_add_pd(_mm_loadu_pd(pb), _mm_mul_pd(_mm_cvtps_pd(kf), dlo)),
                  hi = _mm_add_pd(_mm_loadu_pd(pb + 2),
                                  _mm_mul_pd(_mm_cvtps_pd(_mm_movehl_ps(kf, kf)), dhi));
    _mm_storeu_ps(o, _mm_movelh_ps(_mm_cvtpd_ps(lo), _mm_cvtpd_ps(hi)));
}
#endif

#ifdef PK_SSE2
/* cb_quad over four pixels (twelve values). */
static RTPI_FORCE_INLINE void cb_four(const double *pb, const float *k, float *o, __m128d d01,
                                      __m128d d20, __m128d d12)
{
    cb_quad(pb, k, o, d01, d20);
    cb_quad(pb + 4, k + 4, o + 4, d12, d01);
    cb_quad(pb + 8, k + 8, o + 8, d20, d12);
}
#endif

/* An edit of the chain: P' + K_j (c_j - cS_j) at those pixels. */
static int cb_apply(void *ctx, int chunk)
{
    eval_ctx *e = (eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    const uint32_t *bt = t->cp_seg[e->term] + 4 * (size_t)chunk;
    const uint32_t *run = t->cp_run[e->term] + 2 * (size_t)bt[CP_ROFF];
    const uint32_t *rend = run + 2 * (size_t)bt[CP_NR];
    const double *pb = t->cb_p + 3 * (size_t)bt[CP_KOFF];
    const float *k = t->cp_k[e->term] + 3 * (size_t)bt[CP_KOFF];
    const double d0 = t->cb_dc[0], d1 = t->cb_dc[1], d2 = t->cb_dc[2];
#ifdef PK_SSE2
    const __m128d d01 = _mm_set_pd(d1, d0), d20 = _mm_set_pd(d0, d2), d12 = _mm_set_pd(d2, d1);
#endif
    for (; run < rend; run += 2) {
        size_t p0 = run[0], len = run[1], i;
        float *o = e->pixels + 3 * p0;
        if (rend - run > 2 * CP_RUN_AHEAD) {
            const size_t pa = 3 * (size_t)run[2 * CP_RUN_AHEAD];
            RTPI_PREFETCH(e->pixels + pa, 0);
            RTPI_PREFETCH(e->pixels + pa, 64);
        }
        i = 0;
#ifdef PK_SSE2
        /* four pixels a step on SSE2's vectors, the same operations
           value by value (gcc -O2 made the loop below scalar: balls_s4's
           third ambient edit, a chain's, 6.30 M instructions, 3.22 M
           this way; with P' in floats and cp_run1's loop, 3.75 M); a run
           of four or more ends with its last four pixels, made again
           where the step before made them (cp_run1: the same bits, one
           branch a run by its length) */
        if (len >= 4) {
            const size_t last = len - 4;
            for (; i < last; i += 4)
                cb_four(pb + 3 * i, k + 3 * i, o + 3 * i, d01, d20, d12);
            cb_four(pb + 3 * last, k + 3 * last, o + 3 * last, d01, d20, d12);
            i = len;
        }
#endif
        for (; i < len; i++) {
            o[3 * i] = (float)(pb[3 * i] + k[3 * i] * d0);
            o[3 * i + 1] = (float)(pb[3 * i + 1] + k[3 * i + 1] * d1);
            o[3 * i + 2] = (float)(pb[3 * i + 2] + k[3 * i + 2] * d2);
        }
        pb += 3 * len;
        k += 3 * len;
    }
    return 0;
}

/* Room in cb_p for n entries; 0 where there is no memory for it.  The
   chain writes most of it at once, so from a quarter MiB on it is made a
   MiB at least, which the default allocator gave in huge pages until
   session 45 (util.c: a fresh 4 KiB page cost about 10 us on session
   11's VM; tetra_s6's ambient, 0.9 MB of room, took 182 faults and
   3.4 ms where 2.2 ms had done with the image-sized block before, 11
   faults); now a malloc block, its room beyond what is written never
   touched, so the rounding costs nothing. */
static int cb_room(rtp_tree *t, size_t n)
{
    const size_t mib = ((size_t)1 << 20) / (3 * sizeof *t->cb_p) + 1;
    if (n >= mib / 4 && n < mib)
        n = mib;
    if (t->cb_p && t->cb_cap >= n)
        return 1;
    rtpi_free(&t->alloc, t->cb_p);
    t->cb_term = 0; /* (what it held is gone) */
    t->cb_p = (double *)rtpi_malloc_array(&t->alloc, n ? n : 1, 3 * sizeof *t->cb_p);
    t->cb_cap = t->cb_p ? n : 0;
    return t->cb_p != NULL;
}

/* Are the chain's P' those of term j with the other colours cv? */
static int cb_holds(const rtp_tree *t, size_t j, const double *cv)
{
    size_t i;
    if (t->cb_term != j + 1 || t->cb_gen != t->cp_gen)
        return 0;
    for (i = 0; i < 3 * t->cp_nt; i++)
        if (i / 3 != j && cv[i] != t->cb_cl[i])
            return 0;
    return 1;
}

/* Does term j's colour in cv differ from S's? */
static int cp_differs(const rtp_tree *t, const double *cv, size_t j)
{
    const double *a = cv + 3 * j, *b = t->cp_cl + 3 * j;
    return a[0] != b[0] || a[1] != b[1] || a[2] != b[2];
}

/* The image for colours cv by the colour planes into pixels, if they can
   make it (the coefficients as the last evaluation left them; `sparse`:
   pixels hold that evaluation).  1 when done. */
static int cp_eval(rtp_tree *t, eval_ctx *e, void *const *ctx, int nthreads, const double *cv,
                   float *samples, float *pixels, int sparse, rtp_eval_stats *st)
{
    size_t nt = 2 + t->scene->nlights, j, nd = 0, nc = 0, changed = 0;
    size_t np = (size_t)t->width * t->height;
    int i, c, nb = (t->height + PK_ROWS - 1) / PK_ROWS;
    /* the kept image serves only where it is the coefficients' image */
    sparse = sparse && t->last_exact;
    if (!t->ev_valid || !t->ev_cl || !cp_alloc(t, nt) ||
        !cp_snapshot(t, samples, sparse ? pixels : NULL, nt))
        return 0;
    for (j = 0; j < nt; j++) {
        const double *a = cv + 3 * j, *b = t->cp_cl + 3 * j, *l = t->ev_cl + 3 * j;
        if (a[0] != b[0] || a[1] != b[1] || a[2] != b[2]) {
            t->cp_d[nd] = j;
            for (c = 0; c < 3; c++) {
                t->cp_dc[3 * nd + c] = a[c] - b[c];
                t->cp_ab[3 * nd + c] = fabs(a[c]) + fabs(b[c]);
            }
            nd++;
        }
        if (a[0] != l[0] || a[1] != l[1] || a[2] != l[2]) {
            changed = j;
            nc++;
        }
    }
    /* the one changed last (e->term) last, the others in their order
       (cp_sum; made once here, not tested a term and pixel: gears_s4's
       whole-image kd edit 45.1 M instructions that way, 39.6 M before) */
    for (j = 0; j + 1 < nd; j++)
        if (t->cp_d[j] == changed) {
            double dc[3], ab[3];
            memcpy(dc, t->cp_dc + 3 * j, sizeof dc);
            memcpy(ab, t->cp_ab + 3 * j, sizeof ab);
            memmove(t->cp_d + j, t->cp_d + j + 1, (nd - 1 - j) * sizeof *t->cp_d);
            memmove(t->cp_dc + 3 * j, t->cp_dc + 3 * j + 3, 3 * (nd - 1 - j) * sizeof *t->cp_dc);
            memmove(t->cp_ab + 3 * j, t->cp_ab + 3 * j + 3, 3 * (nd - 1 - j) * sizeof *t->cp_ab);
            t->cp_d[nd - 1] = changed;
            memcpy(t->cp_dc + 3 * (nd - 1), dc, sizeof dc);
            memcpy(t->cp_ab + 3 * (nd - 1), ab, sizeof ab);
            break;
        }
    t->cp_nd = nd;
    /* the planes of those terms and of the one changed last (more than
       CP_MAX_PLANES differing: the full path, which is then about as
       quick) */
    if (nd + 1 > CP_MAX_PLANES) {
        cp_s_drop(t); /* S anew from the full path's image: none differ */
        return 0;
    }
    /* (all marked first: none of them is the one that gives way) */
    t->cp_clock++;
    for (j = 0; j < nd; j++)
        t->cp_used[t->cp_d[j]] = t->cp_clock;
    if (nc == 1)
        t->cp_used[changed] = t->cp_clock;
    for (j = 0; j < nd; j++)
        if (!cp_plane(t, e, ctx, nthreads, t->cp_d[j]))
            return 0;
    /* the bound of |S| + sum |K_d| (|c_d| + |cS_d|) over the image */
    t->cp_check = 0;
    for (c = 0; c < 3; c++) {
        double b = t->cp_smax[c];
        for (j = 0; j < nd; j++)
            b += t->cp_kmax[3 * t->cp_d[j] + c] * t->cp_ab[3 * j + c];
        t->cp_check |= !(b <= 2.0 * CP_SPAN);
    }
    for (i = 0; i < nthreads; i++) {
        e[i].term = changed;
        e[i].pixels = pixels;
    }
    if (nc)
        t->ev_samples_ok = 0; /* they hold the colours before */
    if (sparse && nc <= 1) {
        /* (nothing changed since the last image: nothing to write) */
        size_t nw = 0;
        if (nc == 1) {
            if (!cp_plane(t, e, ctx, nthreads, changed))
                return 0;
            for (i = 0; i < nb; i++)
                nw += t->cp_seg[changed][4 * i + CP_NK];
            if (nd - (size_t)(nd && cp_differs(t, cv, changed)) >= 1 && !t->cp_check &&
                cb_room(t, cp_extent(t, changed))) {
                /* other terms differ from S too: their sum once a chain */
                if (!cb_holds(t, changed, cv)) {
                    tree_rows(t, nb, threads_for(16.0 * (1.0 + (double)nd) * (double)nw,
                                                       nthreads),
                                       ctx, cb_chunk, NULL, NULL);
                    t->cb_term = changed + 1;
                    t->cb_gen = t->cp_gen;
                    memcpy(t->cb_cl, cv, 3 * nt * sizeof *cv);
                }
                for (c = 0; c < 3; c++)
                    t->cb_dc[c] = cv[3 * changed + c] - t->cp_cl[3 * changed + c];
                tree_rows(t, nb, threads_for(28.0 * (double)nw, nthreads), ctx, cb_apply,
                                   NULL, NULL);
            } else {
                tree_rows(t, nb, threads_for(16.0 * (1.0 + (double)nd) * (double)nw,
                                                   nthreads),
                                   ctx, cp_apply_listed, NULL, NULL);
            }
        }
        st->written_pixels = nw;
    } else {
        tree_rows(t, nb, threads_for(12.0 * (2.0 + (double)nd) * (double)np, nthreads), ctx,
                           cp_apply_band, NULL, NULL);
        st->written_pixels = np;
    }
    /* (the pixels that lost digits: their samples summed) */
    for (i = 0; i < nthreads; i++) {
        st->combined_samples += e[i].combined;
        e[i].combined = 0;
    }
    if (st->combined_samples > (unsigned long long)t->nx * (unsigned long long)t->ny)
        st->combined_samples = (unsigned long long)t->nx * (unsigned long long)t->ny;
    return 1;
}

/* The shadow mode and resolution moved lights are decided by: AUTO
   resolved, shadow rays for a light too far for a cube, the cube's cells
   against the memory limit.  *fallback_out: LV_ bits (AUTO asked, the
   light buffer's resolution not asked). */
static rtp_status shadow_mode_for(rtp_tree *t, const rtp_eval_options *opt, int *mode_out,
                                  int *res_out, int *fallback_out, rtp_error *err)
{
    const rtp_scene *s = t->scene;
    size_t l;
    int mode, res, asked_auto, res_free, cam_pending;
    mode = opt ? (int)opt->shadows : 0;
    res_free = !(opt && opt->shadow_res > 0);
    res = res_free ? RTPI_DC_DEFAULT_RES : opt->shadow_res;
    asked_auto = mode == RTP_SHADOWS_AUTO;
    if (mode == RTP_SHADOWS_AUTO) {
        size_t moving = 0;
        for (l = 0; l < s->nlights; l++)
            moving += light_moved(t, l) && s->lights[l].on;
        mode = auto_shadows(t, opt && opt->no_cache, moving);
    }
    /* (the item buffers keep 512: their resolution is their accuracy) */
    res_free = res_free && mode == RTP_SHADOWS_LIGHTBUF;
    if (res_free)
        res = lb_default_res(t);
    /* (lists found too long at this resolution or a coarser one:
       update_visibility's fallback) */
    if (asked_auto && mode == RTP_SHADOWS_LIGHTBUF && t->auto_long && res >= t->auto_long)
        mode = RTP_SHADOWS_EXACT;
    /* (no light buffer fitted this limit or a higher one down to 1 cell:
       light_vis_make's t->auto_tight) */
    if (asked_auto && res_free && mode == RTP_SHADOWS_LIGHTBUF && t->auto_tight > 0.0 &&
        !((opt && opt->memory_limit > 0.0 ? opt->memory_limit : RTPI_MEMORY_LIMIT) >
          t->auto_tight))
        mode = RTP_SHADOWS_EXACT;
    /* A light so far that its buffer would list most primitives in every
       cell (a sun at 1e11 over a terrain of size 2: 14 times the shadow
       rays' time; 524k triangles at 1e11 took 49 s and 5.4 GB before
       lb_res): shadow rays, as exact, which --stats names.  The item
       buffer does the same in rtpi_shadow_create. */
    /* (a moved camera's re-trace below traces every light where it is:
       none is decided by a cube then, whatever its distance or cells) */
    cam_pending = memcmp(&s->camera, &t->cam0, sizeof t->cam0) != 0;
    for (l = 0; mode != RTP_SHADOWS_EXACT && !cam_pending && l < s->nlights; l++) {
        const double *lp = s->lights[l].pos;
        /* (the item buffers too, as rtpi_shadow_create decides them: here
           so that --stats says so and no cube is charged to the memory
           limit; itembuf:8192 from 1e13 was refused under 100 MiB while
           it took 3 MB) */
        if (light_moved(t, l) && s->lights[l].on &&
            rtpi_lightbuf_res(s, v3(lp[0], lp[1], lp[2]), res) < res / 4)
            mode = RTP_SHADOWS_EXACT;
    }
    /* A direction cube's cells against the memory limit, before it is
       made: 9 bytes a cell for an item buffer (id and depth, and the
       cell starts of the thin light buffer beside it, a quarter as many
       cells: SH_THIN_DIV), and for OSMesa 12 bytes a face cell on top
       (its colour and depth buffers and the ids read back); 4 for a light
       buffer's cell starts (its lists come on top); six whole faces (a
       far light's window has fewer: an upper bound).  itembuf:8192 took
       2.9 GB of a 64x64 tree's move under --memory-limit 100; charged 8
       bytes a cell, itembuf:8192 peaked at 3.52 GB under a limit of 3072
       MiB and osmesa:8192 at 4.28 GB under 3584 (helper 78). */
    if (mode != RTP_SHADOWS_EXACT) {
        double lim = opt && opt->memory_limit > 0.0 ? opt->memory_limit : RTPI_MEMORY_LIMIT;
        double cells = 6.0 * (double)res * (double)res;
        double need = cells * (mode == RTP_SHADOWS_LIGHTBUF ? 4.0 : 9.0) +
                      (mode == RTP_SHADOWS_OSMESA ? cells / 6.0 * 12.0 : 0.0);
        /* (a resolution nobody asked: the finest at most the rule's
           whose cells fit; light_vis_make does the same for the lists.
           AUTO too: its light buffer is LIGHTBUF's, and a coarser one
           took 0.51-0.66 of shadow rays' instructions a move where the
           limit refused the rule's (mount_s1, balls_s1, teapot_s6 SPD
           trees under --memory-limit 1: 128 cells against 512 and 256;
           lightbuf:1 took 1.3x shadow rays' time on mount_s1, 0.9x on
           balls_s1); shadow rays where none fits) */
        while (res_free && !(need <= lim) && res > 1) {
            res /= 2;
            need = 6.0 * (double)res * (double)res * 4.0;
        }
        for (l = 0; mode != RTP_SHADOWS_EXACT && !cam_pending && l < s->nlights; l++)
            if (light_moved(t, l) && !(need <= lim) && asked_auto) {
                /* AUTO chose between two exact ways: shadow rays need no
                   cube, as where a light buffer's lists pass the limit
                   (update_visibility's fallback); a stream under
                   --memory-limit 1 stopped at its first move, the error
                   telling to lower a resolution nobody had asked */
                mode = RTP_SHADOWS_EXACT;
            } else if (light_moved(t, l) && !(need <= lim)) {
                char g[2][32]; /* '.' whatever the locale */
                rtpi_fmt_g(g[0], sizeof g[0], 6, rtpi_mib_up(need));
                rtpi_fmt_g(g[1], sizeof g[1], 6, lim / 1048576.0);
                if (res_free) /* (halved to 1 cell: nothing to lower; halved_error) */
                    return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                                      "a light buffer of the default resolution, halved down "
                                      "to 1 cell a face: its cells take %s MiB, over the "
                                      "memory limit of %s MiB (take --shadows exact, or raise "
                                      "memory_limit: rtp's --memory-limit)",
                                      g[0], g[1]);
                return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                                  "a direction cube of %d cells a face takes up to %s MiB, "
                                  "over the memory limit of %s MiB (lower its resolution or "
                                  "raise memory_limit: rtp's --memory-limit)",
                                  res, g[0], g[1]);
            }
    }
    *mode_out = mode;
    *res_out = res;
    *fallback_out = (asked_auto ? LV_AUTO : 0) | (res_free ? LV_RES_FREE : 0);
    return RTP_OK;
}

/* The options' checks, before anything is done. */
static rtp_status opts_check(const rtp_eval_options *opt, rtp_error *err)
{
    /* (each names its field and value, as the others below) */
    if (opt && (unsigned)opt->shadows > RTP_SHADOWS_AUTO)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "shadows: unknown mode %d",
                          (int)opt->shadows);
    if (opt && opt->shadow_res < 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "shadow_res: %d is negative (0: the default)", opt->shadow_res);
    if (opt && opt->shadow_res > RTP_MAX_SHADOW_RES)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "shadow_res: %d is over %d (RTP_MAX_SHADOW_RES)", opt->shadow_res,
                          RTP_MAX_SHADOW_RES);
#ifndef RTP_HAVE_OSMESA
    /* (refused whether or not a light moves: the stub that said so was
       reached only by a moved light decided by the item buffer, and a
       far light or none went on in another mode, exit 0) */
    if (opt && opt->shadows == RTP_SHADOWS_OSMESA)
        return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                          "osmesa shadows: this build has no OSMesa (rebuild with make "
                          "OSMESA=1 and libosmesa6-dev); use itembuf for the same item "
                          "buffer in software");
#endif
    /* (each had been taken for the default: a stale mode of 7 for keep,
       the approximate one) */
    if (opt && (unsigned)opt->stale > RTP_STALE_RETRACE)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "stale: unknown mode %d",
                          (int)opt->stale);
    if (opt && opt->threads < 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "threads: %d is negative (0 or 1: the calling thread)", opt->threads);
    if (opt && !(opt->memory_limit >= 0.0))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "memory_limit: negative or not a number (0: the default)");
    return RTP_OK;
}

/* The colours of the image's linear terms in the coefficients' order:
   the background's, the ambient's, then the lights' (cv + 6). */
static void term_colours(const rtp_scene *s, double *cv)
{
    int i;
    for (i = 0; i < 3; i++) {
        cv[i] = s->background[i];
        cv[3 + i] = s->ambient[i];
    }
    rtpi_light_colors(s, cv + 6);
}

/* Lights added since the caches were made (t->ev_nlights of them, valid,
   to nl now): the caches grow to nl lights in place of being dropped, so
   that adding a light costs what moving one does, not a first evaluation
   of every sample over every light (placing lights one by one was
   quadratic in their count: a line of 0.005 s at 4 lights, 0.22 s at 300
   on balls at 128x128).  Each node's terms and each sample's coefficients
   move to their wider strides (the old lights' kept, each new light's 0),
   the new lights' positions are NaN (their terms stale: eval_body redoes
   them as a moved light's, rtpi_light_redo), and their colours the
   scene's now, so that samples a new light does not reach, combined
   without it, stay as they are: rtpi_combine's sums + 0 x c, the same
   bits but where a sum is -0 (+0 then) or NaN (its sums made again by
   the rule for colours of 0).  Where any sample holds a -0 or NaN
   channel (not in a scene of colours >= 0), the samples are said not to
   hold, and every one is combined again.  The
   highlight list's term indices are moved too; the colour planes go (a
   plane per term, and S, which lacks the new light), the material
   planes and the moved light's rests are no longer said to hold (their
   blocks, of a size the lights do not change, are kept).  @return 0, or
   -1 when out of memory (the caller then drops them all). */
static int grow_caches(rtp_tree *t, size_t nl, size_t ns)
{
    const rtp_allocator *al = &t->alloc;
    const size_t ol = t->ev_nlights, ot = RTPI_TERMS(ol), nt = RTPI_TERMS(nl);
    const size_t oc = RTPI_COEFFS(ol), nc = RTPI_COEFFS(nl);
    size_t j, i;
    float *terms, *coeffs;
    double *pos, *cl, *cv;
    if (nl <= ol || t->nnodes > ((size_t)-1 / sizeof(float) - 1) / nt ||
        ns > (size_t)-1 / sizeof(float) / nc)
        return -1;
    cv = (double *)rtpi_malloc_array(al, nc, sizeof *cv);
    if (!cv)
        return -1;
    terms = (float *)rtpi_realloc(al, t->ev_terms, (t->nnodes * nt + 1) * sizeof *terms);
    if (terms)
        t->ev_terms = terms;
    coeffs = terms ? (float *)rtpi_realloc(al, t->ev_coeffs, ns * nc * sizeof *coeffs) : NULL;
    if (coeffs)
        t->ev_coeffs = coeffs;
    pos = coeffs ? (double *)rtpi_realloc(al, t->ev_pos, (3 * nl + 1) * sizeof *pos) : NULL;
    if (pos)
        t->ev_pos = pos;
    cl = pos ? (double *)rtpi_realloc(al, t->ev_cl, nc * sizeof *cl) : NULL;
    if (cl)
        t->ev_cl = cl;
    if (!cl) {
        rtpi_free(al, cv);
        return -1;
    }
    /* (from the last node down: each moves up, onto room no node still to
       move holds) */
    for (j = t->nnodes; j-- > 0;) {
        memmove(terms + j * nt, terms + j * ot, ot * sizeof *terms);
        memset(terms + j * nt + ot, 0, (nt - ot) * sizeof *terms);
    }
    for (j = ns; j-- > 0;) {
        memmove(coeffs + j * nc, coeffs + j * oc, oc * sizeof *coeffs);
        memset(coeffs + j * nc + oc, 0, (nc - oc) * sizeof *coeffs);
    }
    for (j = 3 * ol; j < 3 * nl; j++)
        pos[j] = NAN;
    term_colours(t->scene, cv);
    memcpy(cl + oc, cv + oc, (nc - oc) * sizeof *cl);
    rtpi_free(al, cv);
    for (i = 0; i < t->hl_n; i++)
        t->hl_idx[i] = t->hl_idx[i] / ot * nt + t->hl_idx[i] % ot;
    for (j = 0; t->ev_samples_ok && j < 3 * ns; j++) {
        float v = t->ev_samples[j];
        if (v != v || (v == 0.0f && signbit(v)))
            t->ev_samples_ok = 0;
    }
    cp_free(t);
    t->pk_term = 0;
    t->mv_light = 0;
    t->ev_nlights = nl;
    return 0;
}

/* What the workers' rows grow their scratch with: t->alloc, behind *la
   (*la_made set) where threads share a caller's allocator, which need not
   be thread-safe.  The thread count to use (1 where no lock could be
   made: one thread needs none). */
static int rows_allocator(rtp_tree *t, int nthreads, rtpi_locked_alloc *la, int *la_made)
{
    *la_made = 0;
    if (nthreads > 1 && !rtpi_allocator_is_default(&t->alloc)) {
        if (rtpi_locked_alloc_init(la, &t->alloc) != 0)
            return 1;
        *la_made = 1;
    }
    return nthreads;
}

/* eval_row's context for each of nthreads threads (e zeroed), ctx[i] =
   &e[i]; 0, or -1 where a thread's scratch could not be had (its nomem
   set; what was had is freed with the contexts). */
static int eval_ctxs_init(rtp_tree *t, eval_ctx *e, void **ctx, int nthreads,
                          const rtp_allocator *wa, const rtpi_shade_ctx *shade,
                          const uint32_t *vis, const double *cl, float *samples, int cached)
{
    const rtp_scene *s = t->scene;
    size_t nc = RTPI_COEFFS(s->nlights);
    int i, bad = 0;
    for (i = 0; i < nthreads; i++) {
        e[i].t = t;
        e[i].wa = wa;
        e[i].shade = shade;
        e[i].vis = vis;
        e[i].eye = v3(s->camera.from[0], s->camera.from[1], s->camera.from[2]);
        e[i].cl = cl;
        e[i].samples = samples;
        e[i].cached = cached;
        /* (16 more each: the threads' scratch, written for every node,
           must share no cache line with another thread's) */
        e[i].coeffs = (float *)rtpi_malloc_array(&t->alloc, nc + 16, sizeof(float));
        e[i].acc = (double *)rtpi_malloc_array(&t->alloc, nc + 16, sizeof(double));
        if (!e[i].coeffs || !e[i].acc)
            e[i].nomem = bad = 1;
        ctx[i] = &e[i];
    }
    return bad ? -1 : 0;
}

static rtp_status eval_body(rtp_tree *t, const rtp_eval_options *opt, rtp_image *into,
                            rtp_image **out, rtp_eval_stats *stats, rtp_error *err);

/* eval_body with the tree marked busy while it runs (its callbacks may
   not use it) */
static rtp_status eval_impl(rtp_tree *t, const rtp_eval_options *opt, rtp_image *into,
                            rtp_image **out, rtp_eval_stats *stats, rtp_error *err)
{
    rtp_status st;
    if (out)
        *out = NULL;
    if (t && t->busy)
        return rtpi_tree_busy(t, into ? "rtp_tree_eval_into" : "rtp_tree_eval", err);
    if (t)
        t->busy = 1;
    st = eval_body(t, opt, into, out, stats, err);
    if (t)
        t->busy = 0;
    return st;
}

static rtp_status eval_body(rtp_tree *t, const rtp_eval_options *opt, rtp_image *into,
                            rtp_image **out, rtp_eval_stats *stats, rtp_error *err)
{
    rtpi_shade_ctx shade;
    /* (on the heap: 256 of them were an 85 KB frame, which a host's
       thread of 96 KiB stack could not hold) */
    eval_ctx *e = NULL;
    void **ctx = NULL;
    rtp_image *img = NULL;
    rtp_eval_stats st;
    progress_part prog;
    rtp_scene *s;
    int i, nthreads = opt && opt->threads > 1 ? opt->threads : 1, any_moved = 0, full;
    int fallback = 0;
    int cached, mode = 0, res = 0, kmode, kres, one = 0, matpath = 0, sparse, list_combine = 0, hl_used = 0;
    int hl_apply = 0, hl_after = 0, restored = -1;
    /* the materials whose samples alone step 3 set (RESOLVE_MAX at most;
       more: -1), so an incremental evaluation averages only their pixels */
    int nset = 0, partial = 0, by_mark = 0;
    rtpi_locked_alloc la;
    int la_made = 0;
    /* a moved light's rest holds only through moves of that light alone:
       every other evaluation ends it */
    size_t mv_light = t ? t->mv_light : 0; /* (a NULL t is refused below) */
    uint32_t set_mats[RESOLVE_MAX];
    size_t nmat_changed = 0;
    uint32_t mt = 0;
    double xold[3], xnew[3];
    rtp_status rs = RTP_OK;
    size_t l, nl, ns, m;
    double *cl = NULL, *cv = NULL;
    float *samples = NULL;
    double t0 = seconds_now(), t1, t0s;
    const uint32_t *vis;
    if (!t || (!out && !into))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval: NULL argument");
    if (out)
        *out = NULL;
    if (into && !into->pixels)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval_into: no pixels");
    if (into && (into->width != t->width || into->height != t->height))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "image is %dx%d, the tree %dx%d", into->width, into->height,
                          t->width, t->height);
    memset(&st, 0, sizeof st);
    t->mv_light = 0;
    s = t->scene;
    nl = s->nlights;
    ns = (size_t)t->nx * t->ny;
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    if ((rs = opts_check(opt, err)) != RTP_OK)
        return rs;
    if ((rs = shadow_mode_for(t, opt, &mode, &res, &fallback, err)) != RTP_OK)
        return rs;
    vis_key(mode, res, &kmode, &kres);
    memset(&shade, 0, sizeof shade);
    shade.s = s;
    shade.one_sided = t->spd;
    shade.has_ka = rtpi_scene_has_ka(s);
    shade.no_ks = 1;
    for (m = 0; m < s->nmats; m++)
        shade.no_ks &= !(s->mats[m].ks > 0.0f);
    /* (a re-trace, when there is one, is most of the time: the first 90%
       of what progress reports; the evaluation of every sample after it
       the rest) */
    prog.fn = opt ? opt->progress : NULL;
    prog.user = opt ? opt->progress_user : NULL;
    prog.cancel = opt ? opt->cancel : NULL;
    prog.lo = 0.0;
    prog.span = 0.9;
    rs = retrace_edited(t, nthreads, opt && opt->stale == RTP_STALE_RETRACE,
                        opt && opt->memory_limit > 0.0 ? opt->memory_limit : RTPI_MEMORY_LIMIT,
                        &prog, &st, err);
    if (st.retraced_samples) {
        prog.lo = 0.9;
        prog.span = 0.1;
    } else {
        prog.span = 1.0;
    }
    if (rs != RTP_OK)
        return rs;
    if (!(opt && opt->stale == RTP_STALE_RETRACE))
        st.stale_samples = count_stale(t);
    /* (after the re-trace: it replaces vis_ext, the visibility of trees
       with more than 32 lights) */
    shade.vis_words = t->vis_words;
    vis = t->vis_words ? t->vis_ext : NULL;
    for (l = 0; l < nl; l++)
        any_moved |= light_moved(t, l);
    /* (shadow_seconds: the moved lights' visibility alone, not the
       re-trace before it, which it counted: 1.19 of a class-D edit's
       1.28 s with no shadow query) */
    t0s = seconds_now();
    if (any_moved) {
        /* (deciding moved lights' shadows is most of a move: the first
           90% of what is left to report) */
        progress_part vp = prog;
        vp.span = 0.9 * prog.span;
        rs = update_visibility(t, mode, res, nthreads,
                               opt && opt->memory_limit > 0.0 ? opt->memory_limit
                                                              : RTPI_MEMORY_LIMIT,
                               fallback, &vp, &st, err);
        if (rs != RTP_OK)
            return rs;
        if (st.moved_lights) {
            prog.lo += vp.span;
            prog.span -= vp.span;
        }
        shade.vis_words = t->cur_words;
        vis = t->cur_vis;
    }
    t1 = seconds_now();

    /* What the caches hold versus what is asked now. */
    /* (past 64 lights within the memory limit too, when it is lower) */
    cached = (nl <= EV_MAX_LIGHTS ||
              ev_cache_bytes(t, nl, ns) <=
                  fmin(EV_CACHE_BYTES, opt && opt->memory_limit > 0.0 ? opt->memory_limit
                                                                      : RTPI_MEMORY_LIMIT)) &&
             !(opt && opt->no_cache) &&
             rtpi_material_lists_fit(t->nnodes); /* (else the full path, which needs none) */
    /* (caches made for another count of lights grow where they hold and
       lights were added (grow_caches, which sets ev_nlights), else go: an
       evaluation that failed after making them, out of memory, left
       ev_valid 0 and them sized for its lights, and a light added then
       overran ev_coeffs and ev_terms; ev_nlights is set where they are
       made) */
    if (t->ev_terms && t->ev_nlights != nl) {
        if (!(cached && t->ev_valid && nl > t->ev_nlights && grow_caches(t, nl, ns) == 0))
            drop_caches(t);
        mv_light = 0; /* (the rests lack the lights added) */
    }
    if (cached && !t->ev_terms) {
        t->ev_nlights = nl;
        t->ev_terms = (float *)rtpi_malloc_array(&t->alloc, t->nnodes * RTPI_TERMS(nl) + 1,
                                                 sizeof *t->ev_terms);
        t->ev_coeffs = (float *)rtpi_malloc_array(&t->alloc, ns * RTPI_COEFFS(nl),
                                                  sizeof *t->ev_coeffs);
        t->ev_nv = (float *)rtpi_malloc_array(&t->alloc, t->nnodes * 6 + 1, sizeof *t->ev_nv);
        t->ev_w = (double *)rtpi_malloc_array(&t->alloc, t->nnodes + 1, sizeof *t->ev_w);
        t->ev_pos = (double *)rtpi_malloc_array(&t->alloc, 3 * nl + 1, sizeof *t->ev_pos);
        t->ev_mats = (rtpi_material *)rtpi_malloc_array(&t->alloc, s->nmats + 1,
                                                        sizeof *t->ev_mats);
        t->ev_cl = (double *)rtpi_malloc_array(&t->alloc, RTPI_COEFFS(nl), sizeof *t->ev_cl);
        if (!t->ev_terms || !t->ev_coeffs || !t->ev_nv || !t->ev_w || !t->ev_pos || !t->ev_mats ||
            !t->ev_cl) {
            drop_caches(t), cached = 0; /* evaluate without caches */
        } else {
            /* the full path below writes every entry of these (ev_w
               first lends the material lists its room) */
            rtpi_prefault(&t->alloc, t->ev_terms, t->nnodes * RTPI_TERMS(nl) * sizeof *t->ev_terms);
            rtpi_prefault(&t->alloc, t->ev_coeffs, ns * RTPI_COEFFS(nl) * sizeof *t->ev_coeffs);
            rtpi_prefault(&t->alloc, t->ev_nv, t->nnodes * 6 * sizeof *t->ev_nv);
            rtpi_prefault(&t->alloc, t->ev_w, t->nnodes * sizeof *t->ev_w);
        }
        t->ev_valid = 0;
    }
    /* (the path weights' cache lends the lists its room where the full
       path is to write every node's weight anew: ev_valid is 0.  A block
       of their own, made and freed, raised glibc's mmap threshold, and
       a light buffer's lists grown by realloc later were copied, not
       remapped: rings_s7's move_lightbuf256 391.54 -> 392.06 M, every
       move) */
    if (cached && !t->mat_start &&
        build_material_lists(t, t->ev_valid ? NULL : (uint16_t *)(void *)t->ev_w) != RTP_OK)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    full = !cached || !t->ev_valid;
    if (full && t->mv_kc) /* (ev_w and the terms made anew: mv_kc_check) */
        t->mv_kc_nmats = (size_t)-1;
    /* the caller's image holds the last evaluation: only changes need
       writing (pk_apply) */
    sparse = opt && opt->incremental && into && t->last_pixels == into->pixels;
    t->last_pixels = NULL; /* until this evaluation has written it */
    st.written_pixels = (unsigned long long)t->width * t->height;
    /* cv: the colours of every term of the image's linear form, in the
       order of the coefficients; cl: the lights' part of it */
    cv = (double *)rtpi_malloc_array(&t->alloc, RTPI_COEFFS(nl), sizeof *cv);
    cl = cv ? cv + 6 : NULL;
    e = (eval_ctx *)rtpi_malloc_array(&t->alloc, (size_t)nthreads, sizeof *e);
    ctx = (void **)rtpi_malloc_array(&t->alloc, (size_t)nthreads, sizeof *ctx);
    if (into)
        img = into;
    else
        rs = rtp_image_create(t->width, t->height, &t->alloc, &img, err);
    if (rs != RTP_OK || !cv || !e || !ctx) {
        rtpi_free(&t->alloc, cv);
        rtpi_free(&t->alloc, e);
        rtpi_free(&t->alloc, ctx);
        if (img != into)
            rtp_image_destroy(img);
        return rs != RTP_OK ? rs : rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    /* (after the returns above, which keep ev_valid: the restore drops
       the list and leaves the material's samples at the chain's shine
       for this evaluation to redo, and a failure from there on goes to
       done, which clears ev_valid.  Made before them, an allocation that
       failed here lost the restored material: with its shine back at the
       caches' the next evaluation saw nothing to redo and kept the
       chain's highlights, 0.012 off a full trace on checker.nff.  An
       evaluation without the caches (no_cache; past 64 lights, over the
       memory limit) ends the chain too: it leaves ev_valid and the
       caches as they were and drops the list, so the terms go back
       first; left at the chain's shine with the shine back at the
       caches', a later kd edit of the material summed them, 0.097 off) */
    if (t->hl_mat && (full ? !cached : !hl_continues(t, kmode, kres)))
        restored = hl_restore(t);
    term_colours(s, cv);
    /* the samples' colours: kept across evaluations with the caches (and
       always with SPD, whose pixels average them) */
    if ((t->spd || cached) && !t->ev_samples)
        t->ev_samples = (float *)rtpi_malloc_array(&t->alloc, ns, 3 * sizeof(float));
    samples = t->spd || cached ? t->ev_samples : img->pixels;
    /* (rows of the uncached path grow their scratch on the workers,
       behind a lock as the trace's workers do) */
    nthreads = rows_allocator(t, nthreads, &la, &la_made);
    memset(e, 0, sizeof e[0] * (size_t)nthreads);
    if (eval_ctxs_init(t, e, ctx, nthreads, la_made ? &la.a : &t->alloc, &shade, vis, cl,
                       samples, cached) != 0 ||
        !samples) {
        rs = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }

    if (full) {
        /* every step for every sample */
        t->ev_inf = 0;
        tree_rows(t, t->ny, nthreads, ctx, eval_row, prog.fn ? progress_part_cb : NULL,
                           &prog);
        cp_stale(t, (size_t)-1);
        st.samples = ns;
        st.combined_samples = ns;
        t->pk_term = 0;
        t->ev_samples_ok = cached;
    } else {
        int coeffs_dirty = 0, moved_combined = 0, applied = 0, kc_made = 0;
        size_t nstale, lmoved = 0;
        /* a light that moved (or whose shadows were decided another way):
           its terms and coefficients only, for every sample; where the
           samples hold every other colour as it is (no colour or material
           edited with the move), each is combined there too */
        if (t->ev_samples_ok && t->ev_cl && restored < 0 &&
            memcmp(cv, t->ev_cl, RTPI_COEFFS(nl) * sizeof *cv) == 0) {
            moved_combined = 1;
            for (m = 0; m < s->nmats; m++)
                if (coeffs_changed(&s->mats[m], &t->ev_mats[m]) || hl_pending(t, m))
                    moved_combined = 0;
        }
        /* the image holds the last evaluation, that is the samples as they
           are: only the pixels of samples combined anew need writing (a
           moved light's shadows and light are local: on tetra 5% of the
           samples change; resolving every pixel was a fifth of a move) */
        if (moved_combined && sparse && samples != img->pixels &&
            (t->ev_mark ||
             (t->ev_mark = (unsigned char *)rtpi_calloc_array(&t->alloc, ns + 8 + (size_t)t->ny,
                                                               1)) != NULL))
            for (i = 0; i < nthreads; i++)
                e[i].mark = t->ev_mark;
        /* One light moved alone, again and again (a drag): the sums of
           its samples but for its term hold while nothing else changes.
           They are kept (t->mv_rest, each made when its sample first
           changes), and a sample is its rest plus the light's term, not
           the sum over every term (tree, 7 lights: combining was 13% of
           a move).  With 1 or 2 lights the sum is short and the rest not
           worth its memory. */
        for (l = 0, nstale = 0; l < nl; l++)
            if (light_terms_stale(t, l, kmode, kres))
                nstale++, lmoved = l;
        if (moved_combined && nstale == 1 && nl >= MV_REST_LIGHTS) {
            if (mv_light != lmoved + 1) {
                if (!t->mv_rest)
                    t->mv_rest = (double *)rtpi_malloc_array(&t->alloc, 3 * ns,
                                                             sizeof *t->mv_rest);
                if (!t->mv_ok)
                    t->mv_ok = (unsigned char *)rtpi_malloc_array(&t->alloc, ns, 1);
                if (t->mv_rest && t->mv_ok) {
                    memset(t->mv_ok, 0, ns);
                    mv_light = lmoved + 1;
                }
            }
            if (mv_light == lmoved + 1) {
                for (i = 0; i < nthreads; i++)
                    e[i].mv_rest = t->mv_rest;
                t->mv_light = mv_light; /* (this move changes no other term) */
            }
        }
        for (l = 0; l < nl; l++) {
            if (!light_terms_stale(t, l, kmode, kres))
                continue;
            if (!kc_made) {
                /* (not where a material's samples get their weights or
                   texture factors anew after this pass (its ks, kt or
                   terms edited): the products made now would be of
                   those before.  A kd or colour edit leaves both) */
                int as_cached = restored < 0;
                double *kc = NULL;
                for (m = 0; as_cached && m < s->nmats; m++)
                    as_cached = !terms_changed(&s->mats[m], &t->ev_mats[m]) &&
                                s->mats[m].ks == t->ev_mats[m].ks &&
                                s->mats[m].kt == t->ev_mats[m].kt && !hl_pending(t, m);
                if (as_cached)
                    kc = mv_kc_check(t, nl, ns,
                                     opt && opt->memory_limit > 0.0 ? opt->memory_limit
                                                                    : RTPI_MEMORY_LIMIT);
                else if (t->mv_kc)
                    t->mv_kc_nmats = (size_t)-1;
                for (i = 0; i < nthreads; i++)
                    e[i].mv_kc = kc;
                kc_made = 1;
            }
            for (i = 0; i < nthreads; i++) {
                e[i].light = l;
                e[i].combine_too = moved_combined;
            }
            tree_rows(t, t->ny, nthreads, ctx, light_row, NULL, NULL);
            cp_stale(t, 2 + l);
            st.samples += ns;
            coeffs_dirty = 1;
        }
        /* the samples hold the colours of the coefficients and colours as
           they are: a material edit recombines only its own samples */
        list_combine = t->ev_samples_ok && !coeffs_dirty && t->ev_cl &&
                       memcmp(cv, t->ev_cl, RTPI_COEFFS(nl) * sizeof *cv) == 0;
        if (!coeffs_dirty && mat_term(t, cv, nl, &mt)) {
            /* one material's kd * colour changed: P + K x per pixel */
            const rtpi_material *mo = &t->ev_mats[mt], *mn = &s->mats[mt];
            for (l = 0; l < 3; l++) {
                xold[l] = (double)mo->kd * mo->color[l];
                xnew[l] = (double)mn->kd * mn->color[l];
            }
            for (i = 0; i < nthreads; i++) {
                e[i].cv = cv;
                e[i].pk_mat = 1;
                e[i].mat = mt;
                memcpy(e[i].xold, xold, sizeof xold);
                e[i].x = xnew;
                e[i].kstride = 3;
                e[i].pixels = img->pixels;
                e[i].list = t->mat_samples + t->mat_start[mt];
                e[i].nlist = t->mat_start[mt + 1] - t->mat_start[mt];
                e[i].chunk = 256;
            }
            if (t->pk_term != (int)(2 + nl + mt) + 1 || (t->pk_part && !sparse)) {
                /* Into a kept image that is the coefficients' own
                   (last_exact), only the pixels of the material's
                   samples change: their planes alone, P from that image
                   (pk_img_chunk).  Any other image (a new one, or a
                   material's P + K x, whose other pixels show that
                   material as last edited) gets every pixel's planes
                   and is written whole. */
                int part = sparse && t->last_exact, mem = pk_alloc(t, part);
                if (!part)
                    sparse = 0;
                t->pk_term = 0; /* (until the planes are made) */
                if (mem && !part) {
                    /* q of every sample (pk_img_chunk makes the
                       material's band by band) */
                    memset(t->pk_q, 0, ns * 3 * sizeof *t->pk_q);
                    for (i = 0; i < nthreads; i++)
                        e[i].kp = t->pk_q;
                    tree_rows(t, (int)((e[0].nlist + 255) / 256), nthreads, ctx, pk_q_chunk,
                                       NULL, NULL);
                }
                /* (no memory for them: the full combine needs none) */
                if (mem && pk_build(t, e, ctx, nthreads, part)) {
                    t->pk_term = (int)(2 + nl + mt) + 1;
                    t->pk_part = part;
                    applied = part;
                    st.combined_samples = part ? 0 : ns;
                }
            }
            if (t->pk_term == (int)(2 + nl + mt) + 1) {
                if (applied) /* (pk_img_chunk wrote them as it made their planes) */
                    st.written_pixels = t->pk_nnz;
                else
                    pk_apply(t, ctx, nthreads, sparse, &st);
                one = 1;
                matpath = 1; /* the coefficients stay those of the material before */
            } else {
                /* planes not finite (or no memory for them): the
                   material's samples below, then every sample */
                list_combine = 0;
                t->ev_samples_ok = 0;
            }
        }
        /* steps 1-2 only for samples containing an edited material */
        /* (the material whose highlights were put back has its samples
           redone whether or not it changed since, and the listed one is
           edited whenever its samples hold another shine than the
           scene's: hl_pending) */
        for (m = 0; !matpath && m < s->nmats; m++)
            nmat_changed += coeffs_changed(&s->mats[m], &t->ev_mats[m]) || (int)m == restored ||
                            hl_pending(t, m);
        for (m = 0; !matpath && m < s->nmats; m++) {
            int redo, pend = hl_pending(t, m);
            size_t n;
            if (!coeffs_changed(&s->mats[m], &t->ev_mats[m]) && (int)m != restored && !pend)
                continue;
            redo = terms_changed(&s->mats[m], &t->ev_mats[m]) || pend;
            n = t->mat_start[m + 1] - t->mat_start[m];
            if (redo && nmat_changed == 1 && !coeffs_dirty &&
                shine_only(&t->ev_mats[m], &s->mats[m]) && mat_in_range(t, &s->mats[m]) &&
                planes_in_range(t, cv, RTPI_COEFFS(nl)) &&
                (t->hl_mat == (int)m + 1 || hl_build(t, &shade, vis, (uint32_t)m, cl, cv) == 0)) {
                for (i = 0; i < nthreads; i++) {
                    e[i].mat = (uint32_t)m;
                    e[i].list = t->mat_samples + t->mat_start[m];
                    e[i].nlist = n;
                }
                if (list_combine && t->hl_shine == (double)s->mats[m].shine) {
                    /* the samples hold this shine already */
                    hl_used = 1;
                    hl_apply = 1;
                    continue;
                }
                if (list_combine) {
                    /* every other sample's colour holds: the material's
                       samples from their highlights alone */
                    tree_rows(t, (int)((n + 255) / 256),
                                       threads_for(28.0 * (double)t->hl_n + 28.0 * (double)n,
                                                   nthreads),
                                       ctx, hl_apply_chunk, NULL, NULL);
                    hl_used = 1;
                    hl_apply = 1;
                    t->hl_shine = s->mats[m].shine;
                    st.combined_samples = n;
                    note_set(set_mats, &nset, (uint32_t)m);
                    continue;
                }
                /* the listed highlights for the new shine, then step 2
                   below; the list is made again once the samples are
                   (its P and W are those of the coefficients and colours
                   now), so the next shine edit applies it */
                tree_rows(t, (int)((t->hl_n + 4095) / 4096), nthreads, ctx, hl_chunk, NULL,
                                   NULL);
                redo = 0;
                hl_after = (int)m + 1;
            }
            for (i = 0; i < nthreads; i++) {
                e[i].list = t->mat_samples + t->mat_start[m];
                e[i].nlist = n;
                e[i].chunk = 256;
                /* a new ks: the material's light terms, not all terms */
                e[i].spec_only = redo && light_terms_only(&t->ev_mats[m], &s->mats[m]);
                e[i].redo_terms = redo && !e[i].spec_only;
                e[i].mat = (uint32_t)m;
                e[i].combine_too = list_combine;
            }
            if (list_combine)
                note_set(set_mats, &nset, (uint32_t)m);
            tree_rows(t, (int)((n + 255) / 256), nthreads, ctx, redo_chunk, NULL, NULL);
            cp_stale(t, (size_t)-1);
            st.samples += n;
            coeffs_dirty = 1;
        }
        if (matpath) {
            t->ev_samples_ok = 0;
        } else if (hl_apply) {
            /* the samples were set with the highlights */
            t->pk_term = 0;
            partial = 1;
        } else if (list_combine && coeffs_dirty) {
            /* step 3 was done with step 2, for the edited samples only */
            st.combined_samples = st.samples;
            t->pk_term = 0;
            partial = 1;
        } else if (list_combine && !coeffs_dirty) {
            /* nothing changed since: the samples hold their colours (and
               an incremental image its pixels) */
            partial = 1;
        } else if (coeffs_dirty && moved_combined) {
            /* light_row combined the samples with lights in them */
            for (st.combined_samples = 0, i = 0; i < nthreads; i++)
                st.combined_samples += e[i].combined;
            if (st.combined_samples > ns) /* (several lights moved) */
                st.combined_samples = ns;
            t->pk_term = 0;
            by_mark = e[0].mark != NULL;
        } else if (!coeffs_dirty && planes_in_range(t, cv, RTPI_COEFFS(nl)) &&
                   cp_eval(t, e, ctx, nthreads, cv, samples, img->pixels, sparse, &st)) {
            /* colours alone changed: S + K (c - cS) per pixel */
            one = 1;
            t->pk_term = 0; /* (a material's planes hold the colours before) */
        } else {
            /* step 3 for every sample (S, which lives in the samples'
               block but after cp_ready, goes: cp_snapshot) */
            cp_s_drop(t);
            tree_rows(t, t->ny, nthreads, ctx, combine_row, NULL, NULL);
            st.combined_samples = ns;
            t->pk_term = 0;
            t->ev_samples_ok = cached;
        }
        if (e[0].mark && !by_mark) /* (marks not to be read: none may stay) */
            marks_clear(t);
        if (hl_after && t->ev_samples_ok &&
            hl_build(t, &shade, vis, (uint32_t)(hl_after - 1), cl, cv) == 0) {
            hl_used = 1;
            t->hl_shine = s->mats[hl_after - 1].shine;
        }
    }
    for (i = 0; i < nthreads; i++) {
        t->ev_inf |= e[i].coef_bad; /* (until the full path makes them all anew) */
        if (e[i].nomem) {
            rs = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
            goto done;
        }
    }
    if (cached) {
        /* (the material and highlight paths leave the coefficients as
           they were for the edited material) */
        if (s->nmats && !matpath && !hl_apply)
            memcpy(t->ev_mats, s->mats, s->nmats * sizeof *t->ev_mats);
        for (l = 0; l < nl; l++)
            memcpy(t->ev_pos + 3 * l, s->lights[l].pos, sizeof s->lights[l].pos);
        memcpy(t->ev_cl, cv, RTPI_COEFFS(nl) * sizeof *cv);
        t->ev_nlights = nl;
        t->ev_vis_mode = kmode;
        t->ev_vis_res = kres;
        t->ev_valid = 1;
    }
    if (!one && samples != img->pixels) {
        if (sparse && partial && nset >= 0) {
            /* only the samples of these materials changed */
            unsigned long long wr = 0;
            /* (none when nothing changed) */
            for (i = 0; i < nset; i++)
                wr += resolve_listed(t, samples, t->mat_samples + t->mat_start[set_mats[i]],
                                     t->mat_start[set_mats[i] + 1] - t->mat_start[set_mats[i]],
                                     img);
            if (wr < st.written_pixels)
                st.written_pixels = wr;
        } else {
            for (i = 0; i < nthreads; i++) {
                e[i].samples = samples;
                e[i].pixels = img->pixels;
                e[i].written = 0;
            }
            tree_rows(t, (t->height + PIX_BAND - 1) / PIX_BAND, nthreads, ctx,
                      by_mark ? mark_band : resolve_band, NULL, NULL);
            if (by_mark) {
                for (st.written_pixels = 0, i = 0; i < nthreads; i++)
                    st.written_pixels += e[i].written;
                marks_clear(t);
            }
        }
    }
    /* (for the edits an image kept for them will see) */
    if (full && cached && opt && opt->incremental && samples != img->pixels)
        cp_ready(t, e, ctx, nthreads, cv, img->pixels);
done:
    /* planes the samples' block lends (pk_lend) hold through their
       material's kd edits alone: any other evaluation may have written
       samples over them */
    if (t->pk_split && !matpath) {
        t->pk_term = 0;
        t->pk_split = 0;
    }
    for (i = 0; i < nthreads; i++) {
        rtpi_free(&t->alloc, e[i].terms);
        rtpi_free(&t->alloc, e[i].coeffs);
        rtpi_free(&t->alloc, e[i].acc);
        rtpi_free(&t->alloc, e[i].rest);
        rtpi_free(&t->alloc, e[i].qgrid);
    }
    rtpi_free(&t->alloc, e);
    rtpi_free(&t->alloc, ctx);
    rtpi_free(&t->alloc, cv);
    if (la_made)
        rtpi_locked_alloc_destroy(&la);
    if (rs != RTP_OK) {
        /* a half-made cache must not be trusted next time */
        t->ev_valid = 0;
        if (img != into)
            rtp_image_destroy(img);
        return rs;
    }
    if (stats) {
        *stats = st;
        stats->seconds = seconds_now() - t0;
        stats->shadow_seconds = st.moved_lights ? t1 - t0s : 0.0;
        stats->nodes = t->nnodes;
    }
    /* (an evaluation without the caches, no_cache or over the memory
       limit, leaves them and ev_valid as the one before made them: its
       image is not theirs, and an incremental evaluation after it, which
       writes only what changed since the caches and takes a material's
       P from the image, left a kd edit's pixels 0.108 off a full trace
       on spheres.nff; the next evaluation writes every pixel) */
    t->last_pixels = cached ? img->pixels : NULL;
    /* a material's planes and listed highlights make images the
       coefficients (held at the material before) do not */
    t->last_exact = !matpath && !hl_apply;
    if (!hl_used)
        t->hl_mat = 0; /* the list holds only while shine edits follow */
    if (prog.fn && prog.lo > 0.0)
        prog.fn(prog.user, 1.0); /* (the steps after a re-trace or a move
                                    report no progress of their own) */
    if (out)
        *out = img;
    return RTP_OK;
}

rtp_status rtp_tree_eval(rtp_tree *t, const rtp_eval_options *opt, rtp_image **out,
                         rtp_eval_stats *stats, rtp_error *err)
{
    if (!out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval: NULL argument");
    *out = NULL;
    return eval_impl(t, opt, NULL, out, stats, err);
}

rtp_status rtp_tree_eval_into(rtp_tree *t, const rtp_eval_options *opt, rtp_image *image,
                              rtp_eval_stats *stats, rtp_error *err)
{
    if (!image)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval_into: NULL image");
    return eval_impl(t, opt, image, NULL, stats, err);
}

/* ------------------------------------------- one-off from a tree file */

/* rtp_tree_eval_file's state: the evaluation eval_body's full uncached
   path makes (eval_row for every sample, then SPD's corner samples
   averaged), done a band of sample rows at a time as the reader hands
   them over. */
typedef struct file_eval {
    rtp_tree_edit_fn edit;
    void *user;
    rtp_eval_options opt; /* the caller's, no_cache set */
    int nthreads;
    int streamed;         /* the bands came: no tree kept */
    double t0;            /* when the edits were made */
    rtpi_shade_ctx shade;
    eval_ctx *e;
    void **ctx;
    double *cv;
    rtpi_locked_alloc la;
    int la_made;
    rtp_image *img;
    float *rows;          /* SPD: the band's sample rows after the row
                             before it */
    size_t rows_cap;      /* (floats) */
    int stale_any;        /* any_stale: count stale samples */
    unsigned long long stale;
    /* moved or added lights: decided a band at a time */
    light_vis *lv;        /* one a light (lv[i].sh NULL: not moved) */
    size_t nl;
    int nmoved;
    double off_floor;     /* rtpi_offset_floor's */
    int prim_floor;
    size_t words;         /* visibility words a node */
    uint32_t *vis;        /* the band's */
    size_t vis_cap;       /* (words) */
    unsigned long long queries;
    int shadows;          /* the mode that decided them */
    int shadow_res;       /* and the last one's cells (light_vis.res) */
    double shadow_s;      /* deciding them, cubes' builds included */
    rtp_status deferred;  /* the evaluation's setup failed (file_begin):
                             its error, given once the file is read */
    rtp_error deferred_err;
} file_eval;

/* Can the trees be evaluated as they come?  The camera where it was
   traced, no material to trace again (needs_retrace, with --stale retrace
   a changed bump's), one light moved or added at most: its shadow
   queries are made first, its rows decided a band at a time.  (Two or
   more would hold their direction cubes at once, where the whole tree's
   evaluation makes and frees one after the other: two light buffers of
   the glass trap at 512 cells took 11 MB more than its tree.) */
static int file_streamable(rtp_tree *t, const rtp_eval_options *opt)
{
    const rtp_scene *s = t->scene;
    size_t i, moved = 0;
    if (memcmp(&s->camera, &t->cam0, sizeof t->cam0) != 0)
        return 0;
    for (i = 0; i < s->nlights; i++)
        moved += light_moved(t, i);
    if (moved > 1)
        return 0;
    for (i = 0; i < s->nmats; i++)
        if (needs_retrace(t, i, opt->stale == RTP_STALE_RETRACE))
            return 0;
    return 1;
}

static rtp_status file_setup(file_eval *f, rtp_tree *t, int can_stream, int *stream,
                             rtp_error *err);

/* The edits, then the evaluation's setup (file_setup).  A setup that fails
   (a moved light's cube over the memory limit, no memory) is made before
   the trees are read, and rtp_tree_read + the edits + rtp_tree_eval would
   refuse a corrupt file for its trees before that evaluation failed: its
   error waits until the file has been read and checked (the bands are
   read, checked and dropped), and a corrupt file gets rtp_tree_read's.
   An edit's error and a cancel stop the read at once. */
static rtp_status file_begin(void *user, rtp_tree *t, int can_stream, int *stream,
                             rtp_error *err)
{
    file_eval *f = (file_eval *)user;
    rtp_status st;
    if (f->edit) {
        if (err)
            memset(err, 0, sizeof *err);
        /* (the tree's trees are not read: only edits may be made) */
        t->busy = 2;
        st = f->edit(f->user, t, err);
        t->busy = 0;
        if (st != RTP_OK) {
            if (err && !err->message[0])
                rtpi_error(err, st, NULL, 0, 0, "rtp_tree_eval_file: the edit callback "
                                                 "returned status %d", (int)st);
            return st;
        }
    }
    f->t0 = seconds_now();
    st = file_setup(f, t, can_stream, stream, err);
    if (st != RTP_OK && st != RTP_ERR_CANCELLED) {
        f->deferred = st;
        if (err)
            f->deferred_err = *err;
        else
            rtpi_error(&f->deferred_err, st, NULL, 0, 0, "rtp_tree_eval_file: status %d",
                       (int)st);
        f->streamed = 1; /* (nothing to evaluate: the trees only checked) */
        *stream = 1;
        t->busy = 0;
        return RTP_OK;
    }
    return st;
}

/* Decides whether the trees are evaluated as they come (*stream) and, if
   so, makes what their evaluation needs. */
static rtp_status file_setup(file_eval *f, rtp_tree *t, int can_stream, int *stream,
                             rtp_error *err)
{
    const rtp_scene *s = t->scene;
    size_t nl;
    int i;
    nl = s->nlights; /* (lights added by the edits included) */
    if (!can_stream || !file_streamable(t, &f->opt))
        return RTP_OK; /* (read whole, then rtp_tree_eval) */
    f->shade.s = s;
    f->shade.one_sided = t->spd;
    f->shade.has_ka = rtpi_scene_has_ka(s);
    f->shade.vis_words = 0; /* (light bits in the nodes: can_stream) */
    f->stale_any = f->opt.stale != RTP_STALE_RETRACE && any_stale(t);
    f->cv = (double *)rtpi_malloc_array(&t->alloc, RTPI_COEFFS(nl), sizeof *f->cv);
    f->e = (eval_ctx *)rtpi_calloc_array(&t->alloc, (size_t)f->nthreads, sizeof *f->e);
    f->ctx = (void **)rtpi_malloc_array(&t->alloc, (size_t)f->nthreads, sizeof *f->ctx);
    if (!f->cv || !f->e || !f->ctx)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    term_colours(s, f->cv);
    f->nthreads = rows_allocator(t, f->nthreads, &f->la, &f->la_made);
    /* (samples: each band's, set by file_band; the caches: none) */
    if (eval_ctxs_init(t, f->e, f->ctx, f->nthreads, f->la_made ? &f->la.a : &t->alloc,
                       &f->shade, NULL, f->cv + 6, NULL, 0) != 0)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    if (rtp_image_create(t->width, t->height, &t->alloc, &f->img, err) != RTP_OK)
        return err ? err->status : RTP_ERR_NOMEM;
    f->nl = nl;
    for (i = 0; (size_t)i < nl; i++)
        f->nmoved += light_moved(t, (size_t)i);
    if (f->nmoved) {
        /* as update_visibility decides them, each light's queries made
           now (a cube's build, or the kd-tree's), their rows a band at a
           time (file_band) */
        int mode, res, fallback;
        double limit = f->opt.memory_limit > 0.0 ? f->opt.memory_limit : RTPI_MEMORY_LIMIT;
        double t0s = seconds_now();
        rtp_status st;
        rtpi_poll poll;
        if ((st = shadow_mode_for(t, &f->opt, &mode, &res, &fallback, err)) != RTP_OK)
            return st;
        f->lv = (light_vis *)rtpi_calloc_array(&t->alloc, nl, sizeof *f->lv);
        if (!f->lv || (!t->tri_nrm && tri_normals(t) != 0))
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        f->off_floor = rtpi_offset_floor(s, &f->prim_floor);
        f->words = (nl + 31) / 32;
        f->shade.vis_words = f->words;
        /* (the builds' cancel is the caller's; their progress is not
           reported: the bands' follows) */
        memset(&poll, 0, sizeof poll);
        poll.cancel = f->opt.cancel;
        poll.user = f->opt.progress_user;
        for (i = 0; (size_t)i < nl; i++) {
            if (!light_moved(t, (size_t)i))
                continue;
            if (f->opt.cancel && f->opt.cancel(f->opt.progress_user))
                return rtpi_cancelled(err);
            st = light_vis_make(t, (size_t)i, mode, res, f->nthreads, limit, fallback, &poll,
                                &f->lv[i], err);
            if (st != RTP_OK)
                return st;
            f->shadows = f->lv[i].mode;
            f->shadow_res = f->lv[i].res;
        }
        f->shadow_s = seconds_now() - t0s;
    }
    f->streamed = 1;
    *stream = 1;
    /* (a tree pointer kept from the edit callback and used from progress
       or cancel meets a busy tree, as during rtp_tree_eval: file_end
       clears it) */
    t->busy = 1;
    return RTP_OK;
}

/* The band's visibility (b: the band's tree): the recorded light bits
   (light bits in the nodes: a file of at most 32 lights), then each moved
   light decided anew (light_vis_rows: vis_row), into f->vis. */
static rtp_status file_band_vis(file_eval *f, rtp_tree *b, rtp_error *err)
{
    size_t i, n0 = (size_t)b->start[0], n1 = (size_t)b->start[(size_t)b->ny * b->nx],
              words = f->words, w;
    double t0 = seconds_now();
    if (rtpi_grow(&b->alloc, (void **)&f->vis, &f->vis_cap, n1 * words, sizeof *f->vis))
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (i = n0; i < n1; i++) {
        f->vis[i * words] = b->nodes[i].vis;
        for (w = 1; w < words; w++)
            f->vis[i * words + w] = 0;
    }
    b->cur_vis = f->vis;
    b->cur_words = words;
    for (i = 0; i < f->nl; i++) {
        rtp_eval_stats st;
        if (!f->lv[i].sh)
            continue;
        memset(&st, 0, sizeof st);
        if (light_vis_rows(b, &f->lv[i], f->off_floor, f->prim_floor, NULL, NULL, NULL, &st))
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        f->queries += st.shadow_queries;
    }
    f->shadow_s += seconds_now() - t0;
    return RTP_OK;
}

/* Sample rows y0 .. y1 - 1: eval_row's for each, into the image (a pixel
   a sample) or the band's rows, whose pixel rows are then averaged. */
static rtp_status file_band(void *user, rtp_tree *t, int y0, int y1, const rtpi_cnode *nodes,
                            const uint64_t *start, rtp_error *err)
{
    file_eval *f = (file_eval *)user;
    size_t nx = (size_t)t->nx, w = (size_t)t->width, k, n = (size_t)(y1 - y0) * nx;
    /* The band as a tree of its own rows, for eval_row (which reads the
       tree's scene, sample starts and nodes): a shallow copy, read only,
       freed with nothing. */
    rtp_tree b = *t;
    float *samples;
    int i, y;
    if (f->deferred) {
        /* (the setup failed: the file is only checked, which a cancel
           may stop) */
        if (y1 < t->ny && f->opt.cancel && f->opt.cancel(f->opt.progress_user))
            return rtpi_cancelled(err);
        return RTP_OK;
    }
    b.nodes = (rtpi_cnode *)(uintptr_t)nodes;
    b.start = (uint64_t *)(uintptr_t)start;
    b.ball_in = NULL; /* (t's nodes', not the band's) */
    b.ball_sph = NULL;
    b.prim_nrm = NULL;
    b.cone_own = NULL;
    b.kd_from = NULL;
    b.kd_from_kt = NULL;
    b.vrec = NULL;
    b.vrec_mat = NULL;
    b.mv_kc = NULL; /* (t's nodes', not the band's) */
    b.ny = y1 - y0;
    if (t->spd) {
        /* the row before the band (its last, kept from the band before)
           and the band's */
        if (rtpi_grow(&t->alloc, (void **)&f->rows, &f->rows_cap, 3 * (n + nx), sizeof(float)))
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        samples = f->rows + 3 * nx;
    } else {
        samples = f->img->pixels + 3 * (size_t)y0 * nx;
    }
    if (f->nmoved) {
        rtp_status st = file_band_vis(f, &b, err);
        if (st != RTP_OK)
            return st;
    }
    for (i = 0; i < f->nthreads; i++) {
        f->e[i].t = &b;
        f->e[i].samples = samples;
        f->e[i].vis = f->nmoved ? f->vis : NULL;
    }
    tree_rows(&b, y1 - y0, f->nthreads, f->ctx, eval_row, NULL, NULL);
    for (i = 0; i < f->nthreads; i++) {
        f->e[i].t = t;
        if (f->e[i].nomem)
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    for (k = 0; f->stale_any && k < n; k++)
        f->stale += (unsigned long long)sample_stale(t, nodes + start[k],
                                                     (size_t)(start[k + 1] - start[k]));
    if (t->spd) {
        /* pixel row y from sample rows y and y + 1: those whose second
           row is in the band */
        for (y = y0 > 0 ? y0 - 1 : 0; y + 1 < y1 && y < t->height; y++)
            spd_row(f->rows + 3 * (size_t)(y - y0 + 1) * nx, f->img->pixels + 3 * (size_t)y * w,
                    w);
        memcpy(f->rows, f->rows + 3 * n, 3 * nx * sizeof(float));
    }
    if (f->opt.progress)
        f->opt.progress(f->opt.progress_user, (double)y1 / t->ny);
    if (y1 < t->ny && f->opt.cancel && f->opt.cancel(f->opt.progress_user))
        return rtpi_cancelled(err);
    return RTP_OK;
}

/* What the evaluation made with the tree, freed before the reader frees
   the tree (the shadow queries' cubes live in its blocks). */
static void file_end(void *user, rtp_tree *t)
{
    file_eval *f = (file_eval *)user;
    size_t i;
    t->busy = 0;
    for (i = 0; f->lv && i < f->nl; i++)
        light_vis_free(t, &f->lv[i]);
    rtpi_free(&t->alloc, f->lv);
    rtpi_free(&t->alloc, f->vis);
    f->lv = NULL;
    f->vis = NULL;
}

static void file_free(file_eval *f, const rtp_allocator *a)
{
    int i;
    for (i = 0; f->e && i < f->nthreads; i++) {
        rtpi_free(a, f->e[i].terms);
        rtpi_free(a, f->e[i].coeffs);
        rtpi_free(a, f->e[i].acc);
    }
    rtpi_free(a, f->e);
    rtpi_free(a, f->ctx);
    rtpi_free(a, f->cv);
    rtpi_free(a, f->rows);
    if (f->la_made)
        rtpi_locked_alloc_destroy(&f->la);
    f->e = NULL;
    f->ctx = NULL;
    f->cv = NULL;
    f->rows = NULL;
    f->la_made = 0;
}

rtp_status rtp_tree_eval_file(const char *path, const rtp_allocator *alloc,
                              rtp_tree_edit_fn edit, void *user,
                              const rtp_eval_options *opt, rtp_image **out,
                              rtp_tree_info *info, rtp_eval_stats *stats, rtp_error *err)
{
    file_eval f;
    rtp_allocator a;
    rtpi_tree_sink sink;
    rtp_tree *t = NULL;
    rtp_status st;
    if (out)
        *out = NULL;
    if (info)
        memset(info, 0, sizeof *info);
    if (!path || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval_file: NULL argument");
    if ((st = opts_check(opt, err)) != RTP_OK)
        return st;
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_tree_eval_file");
    rtpi_allocator_init(&a, alloc);
    memset(&f, 0, sizeof f);
    f.edit = edit;
    f.user = user;
    if (opt)
        f.opt = *opt;
    f.opt.no_cache = 1;
    f.opt.incremental = 0;
    f.nthreads = f.opt.threads > 1 ? f.opt.threads : 1;
    if (f.nthreads > RTPI_MAX_THREADS)
        f.nthreads = RTPI_MAX_THREADS;
    sink.begin = file_begin;
    sink.band = file_band;
    sink.end = file_end;
    sink.user = &f;
    st = rtpi_tree_read_sink(path, alloc, &sink, &t, err);
    if (st == RTP_OK && f.deferred) {
        /* (the file is sound: the setup's error) */
        st = f.deferred;
        if (err)
            *err = f.deferred_err;
    } else if (st == RTP_OK && f.streamed) {
        size_t ns = (size_t)t->nx * t->ny;
        if (stats) {
            memset(stats, 0, sizeof *stats);
            stats->samples = stats->combined_samples = ns;
            stats->written_pixels = (unsigned long long)t->width * t->height;
            stats->stale_samples = f.stale;
            stats->nodes = t->nnodes;
            stats->moved_lights = f.nmoved;
            stats->shadow_queries = f.queries;
            stats->shadows = (rtp_shadow_mode)f.shadows;
            stats->shadow_res = f.shadow_res;
            stats->shadow_seconds = f.nmoved ? f.shadow_s : 0.0;
            stats->seconds = seconds_now() - f.t0;
        }
        *out = f.img;
        f.img = NULL;
    } else if (st == RTP_OK) {
        st = eval_impl(t, &f.opt, NULL, out, stats, err);
        if (st == RTP_OK && stats)
            stats->seconds = seconds_now() - f.t0;
    }
    if (st == RTP_OK && info)
        rtp_tree_get_info(t, info);
    /* (a failed read has freed its tree: the state's blocks came from
       the allocator it was given, which a holds too) */
    file_free(&f, &a);
    rtp_image_destroy(f.img);
    rtp_tree_destroy(t);
    return st;
}

static rtp_status tree_trace(const rtp_tree *t, const rtp_trace_options *opt, rtp_image **out,
                             rtp_trace_stats *stats, rtp_error *err, const char *call);

rtp_status rtp_tree_trace(const rtp_tree *t, int threads, rtp_image **out,
                          rtp_trace_stats *stats, rtp_error *err)
{
    rtp_trace_options o;
    if (out)
        *out = NULL;
    if (threads < 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_tree_trace: threads %d is negative (0 or 1: the calling thread)",
                          threads);
    memset(&o, 0, sizeof o);
    o.threads = threads;
    return tree_trace(t, &o, out, stats, err, "rtp_tree_trace");
}

rtp_status rtp_tree_trace_opt(const rtp_tree *t, const rtp_trace_options *opt, rtp_image **out,
                              rtp_trace_stats *stats, rtp_error *err)
{
    return tree_trace(t, opt, out, stats, err, "rtp_tree_trace_opt");
}

/* Both: their refusals name the call made (rtp_tree_trace_opt's had named
   rtp_tree_trace). */
static rtp_status tree_trace(const rtp_tree *t, const rtp_trace_options *opt, rtp_image **out,
                             rtp_trace_stats *stats, rtp_error *err, const char *call)
{
    rtp_trace_options o;
    rtp_tree *mark;
    rtp_status st;
    if (out)
        *out = NULL;
    if (!t)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: NULL tree", call);
    if (t->busy)
        return rtpi_tree_busy(t, call, err);
    /* (the caller's limit, threads and callbacks: reeval --reference's
       trace had taken none of its --memory-limit) */
    memset(&o, 0, sizeof o);
    if (opt)
        o = *opt;
    /* a region's tree: the frame its camera spans, traced over the region */
    o.width = t->full_w;
    o.height = t->full_h;
    o.region[0] = t->rx;
    o.region[1] = t->ry;
    o.region[2] = t->rx + t->width;
    o.region[3] = t->ry + t->height;
    o.spd = t->spd;
    o.max_depth = t->max_depth;
    o.min_weight = t->min_weight;
    /* (the tree's frame: a builder's corner samples need not be SPD's
       512x512)  The tree is marked busy while its callbacks run, as an
       evaluation's: the flag is the one field a const tree's call
       writes (a tree is one thread's at a time, rtp.h; the object is
       never defined const, the library made it). */
    mark = (rtp_tree *)(uintptr_t)t;
    mark->busy = RTPI_TREE_TRACING;
    st = rtpi_trace_sized(t->scene, &o, out, stats, err);
    mark->busy = 0;
    return st;
}

/* ------------------------------------------------ merge and crop */

/* A new tree of w x h pixels at rx, ry of like's frame, with like's scene
   (cloned, edits included), options and as-traced materials and lights,
   and room for nnodes nodes and their visibility words (nodes, start and
   vis_ext left for the caller to fill); NULL when out of memory. */
static rtp_tree *tree_shell(const rtp_tree *like, int w, int h, int rx, int ry, size_t nnodes)
{
    const rtp_allocator *a = &like->alloc;
    size_t words = like->vis_words, nl;
    rtp_tree *t = (rtp_tree *)rtpi_calloc_array(a, 1, sizeof *t);
    if (!t)
        return NULL;
    t->alloc = *a;
    t->width = w;
    t->height = h;
    t->nx = w + like->spd; /* SPD: the corners around the pixels */
    t->ny = h + like->spd;
    t->full_w = like->full_w;
    t->full_h = like->full_h;
    t->rx = rx;
    t->ry = ry;
    t->spd = like->spd;
    t->max_depth = like->max_depth;
    t->min_weight = like->min_weight;
    t->foreign = like->foreign;
    t->vis_words = words;
    t->nnodes = nnodes;
    t->nlights0 = like->nlights0;
    t->cam0 = like->cam0;
    if (rtpi_scene_clone(like->scene, &t->scene) != RTP_OK) {
        rtp_tree_destroy(t);
        return NULL;
    }
    /* (lights0 has an entry for every light, added ones too: their
       positions NaN, so they are decided anew as in like) */
    nl = t->scene->nlights;
    t->mats0 = (rtpi_material *)rtpi_malloc_array(a, t->scene->nmats + 1, sizeof *t->mats0);
    t->lights0 = (rtpi_light *)rtpi_malloc_array(a, nl + 1, sizeof *t->lights0);
    t->nodes = (rtpi_cnode *)rtpi_malloc_array(a, nnodes + 1, sizeof *t->nodes);
    t->start = (uint64_t *)rtpi_malloc_array(a, (size_t)t->nx * (size_t)t->ny + 1,
                                             sizeof *t->start);
    if (words)
        t->vis_ext = (uint32_t *)rtpi_malloc_array(a, nnodes * words + 1, sizeof *t->vis_ext);
    if (!t->mats0 || !t->lights0 || !t->nodes || !t->start || (words && !t->vis_ext)) {
        rtp_tree_destroy(t);
        return NULL;
    }
    memcpy(t->mats0, like->mats0, t->scene->nmats * sizeof *t->mats0);
    memcpy(t->lights0, like->lights0, nl * sizeof *t->lights0);
    return t;
}

/* ---------------------------------------------------------------- merge */

/* Same scene and options?  The parts of one frame were traced from one
   scene file with one command line, so their scenes are equal value for
   value (names and texture paths included).  NULL when they are, else
   what differs, for the message: in a farm of many jobs, which of them
   ran with another option, --set or file is the thing to find (every
   refusal said "another scene, frame or options, or edited otherwise"). */
static const char *mat_field(const rtpi_material *m, const rtpi_material *n)
{
    if (memcmp(m->color, n->color, sizeof m->color) != 0)
        return "color";
    if (m->kd != n->kd)
        return "kd";
    if (m->ks != n->ks)
        return "ks";
    if (m->shine != n->shine)
        return "shine";
    if (m->kt != n->kt)
        return "kt";
    if (m->ior != n->ior)
        return "ior";
    if (m->tex != n->tex || m->tex_image != n->tex_image)
        return "texture";
    if (memcmp(m->color2, n->color2, sizeof m->color2) != 0)
        return "color2";
    if (m->tex_scale != n->tex_scale)
        return "checker_scale";
    if (m->bump != n->bump || m->bump_image != n->bump_image)
        return "bump";
    if (m->bump_strength != n->bump_strength)
        return "bump_strength";
    if (m->bump_scale != n->bump_scale)
        return "bump_scale";
    if (ka_changed(m, n))
        return "ambient";
    return "values"; /* (equal as numbers, not as bits: -0 and 0) */
}

/* Which of the values material m0 was traced with (mats0) differs from
   n0's, of those that decide which edits the trees can evaluate
   (needs_retrace, bump_stale): what a tree file keeps of them, and none
   where t traced eye rays alone (a ks or kt edit from 0 traced nothing
   there and kept mats0's).  NULL where none.  (Comparing the whole
   records refused parts alike: one given a colour, kd or ks edit after
   its trace, the other traced with it -- in memory; read from its file,
   a part's other fields are the material's own.) */
static const char *traced_field(const rtp_tree *t, const rtpi_material *m0,
                                const rtpi_material *n0)
{
    if (eye_rays_alone(t))
        return NULL;
    if (m0->ks != n0->ks)
        return "ks";
    if (m0->kt != n0->kt)
        return "kt";
    if (m0->ior != n0->ior)
        return "ior";
    if (m0->bump != n0->bump || m0->bump_image != n0->bump_image)
        return "bump";
    if (m0->bump_strength != n0->bump_strength)
        return "bump_strength";
    if (m0->bump_scale != n0->bump_scale)
        return "bump_scale";
    return NULL;
}

static const char *setup_diff(const rtp_tree *a, const rtp_tree *b, char *buf, size_t size)
{
    const rtp_scene *x = a->scene, *y = b->scene;
    size_t i;
    if (a->full_w != b->full_w || a->full_h != b->full_h) {
        snprintf(buf, size, "a region of a %dx%d frame, parts[0] of a %dx%d one", b->full_w,
                 b->full_h, a->full_w, a->full_h);
        return buf;
    }
    if (a->spd != b->spd)
        return b->spd ? "traced with SPD corner samples, parts[0] without"
                      : "traced without SPD corner samples, parts[0] with them";
    if (a->max_depth != b->max_depth) {
        snprintf(buf, size, "traced to depth %d, parts[0] to depth %d", b->max_depth,
                 a->max_depth);
        return buf;
    }
    if (a->min_weight != b->min_weight) {
        char g[2][32]; /* (with '.' whatever the locale: rtpi_fmt_g) */
        rtpi_fmt_g(g[0], sizeof g[0], 17, b->min_weight);
        rtpi_fmt_g(g[1], sizeof g[1], 17, a->min_weight);
        snprintf(buf, size, "traced with min_weight %s, parts[0] with %s", g[0], g[1]);
        return buf;
    }
    if (a->vis_words != b->vis_words || a->nlights0 != b->nlights0 ||
        x->nlights != y->nlights || x->nmats != y->nmats || x->ntris != y->ntris ||
        x->nspheres != y->nspheres || x->ncones != y->ncones || x->npos != y->npos ||
        x->nnrm != y->nnrm || x->nuv != y->nuv || x->ntexs != y->ntexs) {
        snprintf(buf, size,
                 "traced from another scene: %zu lights, %zu materials, %zu triangles, %zu "
                 "spheres, %zu cones; parts[0] %zu, %zu, %zu, %zu, %zu",
                 y->nlights, y->nmats, y->ntris, y->nspheres, y->ncones, x->nlights, x->nmats,
                 x->ntris, x->nspheres, x->ncones);
        return buf;
    }
    if ((x->npos && memcmp(x->pos, y->pos, x->npos * 3 * sizeof *x->pos)) ||
        (x->nnrm && memcmp(x->nrm, y->nrm, x->nnrm * 3 * sizeof *x->nrm)) ||
        (x->nuv && memcmp(x->uv, y->uv, x->nuv * 2 * sizeof *x->uv)) ||
        (x->ntris && memcmp(x->tris, y->tris, x->ntris * sizeof *x->tris)) ||
        (x->nspheres && memcmp(x->spheres, y->spheres, x->nspheres * sizeof *x->spheres)) ||
        (x->ncones && memcmp(x->cones, y->cones, x->ncones * sizeof *x->cones)))
        return "traced from another scene: other geometry than parts[0]'s";
    if (memcmp(&a->cam0, &b->cam0, sizeof a->cam0) != 0)
        return "traced from another camera than parts[0] (camera.* keys)";
    if (memcmp(&x->camera, &y->camera, sizeof x->camera) != 0)
        return "edited to another camera than parts[0] (camera.* keys)";
    if (memcmp(x->background, y->background, sizeof x->background) != 0)
        return "given another background than parts[0]";
    if (memcmp(x->ambient, y->ambient, sizeof x->ambient) != 0)
        return "given another ambient than parts[0]";
    if (x->light_scale != y->light_scale)
        return "traced from another scene: its lights are scaled for another light count "
               "than parts[0]'s";
    /* (the images themselves: parts may have loaded different files into
       the same slot by a texture or bump edit) */
    for (i = 0; i < x->ntexs; i++) {
        const rtp_image *u = x->texs[i].image, *v = y->texs[i].image;
        if ((u == NULL) != (v == NULL) ||
            (u && (u->width != v->width || u->height != v->height ||
                   memcmp(u->pixels, v->pixels,
                          (size_t)u->width * (size_t)u->height * 3 * sizeof *u->pixels) !=
                       0))) {
            snprintf(buf, size,
                     "given other pixels for image %zu (%s) than parts[0] (a file changed "
                     "between the jobs, or an edit)",
                     i, y->texs[i].path ? y->texs[i].path : "?");
            return buf;
        }
    }
    for (i = 0; i < x->nmats; i++) {
        rtpi_material m = x->mats[i], n = y->mats[i];
        const char *nm = y->mats[i].name, *f;
        m.name = n.name = NULL;
        if (memcmp(&m, &n, sizeof m) != 0) {
            snprintf(buf, size, "given another mat.%zu.%s%s%s%s than parts[0]", i,
                     mat_field(&n, &m), nm ? " (" : "", nm ? nm : "", nm ? ")" : "");
            return buf;
        }
        if ((f = traced_field(a, &b->mats0[i], &a->mats0[i])) != NULL) {
            snprintf(buf, size,
                     "traced with another mat.%zu.%s%s%s%s than parts[0] (one was evaluated "
                     "after an edit that traces again)",
                     i, f, nm ? " (" : "", nm ? nm : "", nm ? ")" : "");
            return buf;
        }
    }
    for (i = 0; i < x->nlights; i++) {
        rtpi_light l = x->lights[i], k = y->lights[i];
        const char *nm = y->lights[i].name;
        l.name = k.name = NULL;
        if (memcmp(&l, &k, sizeof l) != 0) {
            snprintf(buf, size, "given another light.%zu.%s%s%s%s than parts[0]", i,
                     memcmp(l.pos, k.pos, sizeof l.pos) != 0       ? "pos"
                     : memcmp(l.color, k.color, sizeof l.color) != 0 ? "color"
                                                                    : "on",
                     nm ? " (" : "", nm ? nm : "", nm ? ")" : "");
            return buf;
        }
    }
    /* the lights as traced: each part's visibility bits were decided
       there (a part written after a move holds its bits for the traced
       place, and its lights now where they were moved) */
    for (i = 0; i < a->nlights0; i++)
        if (memcmp(a->lights0[i].pos, b->lights0[i].pos, sizeof a->lights0[i].pos) != 0) {
            /* (positions alone: a file keeps no more of them; the light
               named as the edits' refusals name it) */
            const char *nm = y->lights[i].name;
            snprintf(buf, size, "traced with light.%zu%s%s%s at another place than parts[0]",
                     i, nm ? " (" : "", nm ? nm : "", nm ? ")" : "");
            return buf;
        }
    return NULL;
}

rtp_status rtp_tree_merge(rtp_tree *const *parts, size_t n, rtp_tree **out, rtp_error *err)
{
    const rtp_tree *p0;
    rtp_tree *t = NULL;
    const rtp_allocator *a;
    size_t i, k, ns, total = 0, at = 0, words;
    int fw, fh, gx, gy, x, y, spd;
    int32_t *owner = NULL; /* per frame sample: which part has it */
    rtp_status st = RTP_OK;
    if (out)
        *out = NULL;
    if (!parts || !n || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_merge: no trees");
    for (i = 0; i < n; i++)
        if (!parts[i])
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_merge: NULL tree");
        else if (parts[i]->busy)
            return rtpi_tree_busy(parts[i], "rtp_tree_merge", err);
    p0 = parts[0];
    a = &p0->alloc;
    fw = p0->full_w;
    fh = p0->full_h;
    spd = p0->spd;
    gx = fw + spd;
    gy = fh + spd;
    words = p0->vis_words;
    for (i = 0; i < n; i++) {
        char why[192];
        const char *d = i ? setup_diff(p0, parts[i], why, sizeof why) : NULL;
        if (d)
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              "parts[%zu] cannot join parts[0]: it was %s", i, d);
        if (parts[i]->scene->nlights != parts[i]->nlights0)
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "parts[%zu] has added lights", i);
    }
    ns = (size_t)gx * gy;
    owner = (int32_t *)rtpi_malloc_array(a, ns, sizeof *owner);
    if (!owner)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (k = 0; k < ns; k++)
        owner[k] = -1;
    /* pixels: each exactly once; SPD corner samples on shared edges are
       traced by both neighbours, identically: the first one is kept */
    {
        unsigned char *px = (unsigned char *)rtpi_calloc_array(a, (size_t)fw * fh, 1);
        if (!px) {
            rtpi_free(a, owner);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        for (i = 0; i < n && st == RTP_OK; i++) {
            const rtp_tree *p = parts[i];
            for (y = 0; y < p->height && st == RTP_OK; y++)
                for (x = 0; x < p->width; x++) {
                    unsigned char *c = &px[(size_t)(p->ry + y) * fw + (size_t)(p->rx + x)];
                    if (*c) {
                        st = rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                        "regions overlap at pixel %d,%d (parts[%zu])", p->rx + x,
                                        p->ry + y, i);
                        break;
                    }
                    *c = 1;
                }
            for (y = 0; y < p->ny; y++)
                for (x = 0; x < p->nx; x++) {
                    size_t f = (size_t)(p->ry + y) * gx + (size_t)(p->rx + x);
                    if (owner[f] < 0) {
                        owner[f] = (int32_t)i;
                        total += (size_t)(p->start[(size_t)y * p->nx + x + 1] -
                                          p->start[(size_t)y * p->nx + x]);
                    }
                }
        }
        for (k = 0; st == RTP_OK && k < (size_t)fw * fh; k++)
            if (!px[k])
                st = rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                "the regions leave pixel %d,%d uncovered", (int)(k % (size_t)fw),
                                (int)(k / (size_t)fw));
        rtpi_free(a, px);
    }
    if (st != RTP_OK)
        goto fail;
    if (!(t = tree_shell(p0, fw, fh, 0, 0, total)))
        goto nomem;
    for (i = 0; i < n; i++)
        t->foreign |= parts[i]->foreign;
    for (y = 0; y < gy; y++)
        for (x = 0; x < gx; x++) {
            size_t f = (size_t)y * gx + x, ls, cnt;
            const rtp_tree *p = parts[owner[f]];
            ls = (size_t)(y - p->ry) * p->nx + (size_t)(x - p->rx);
            cnt = (size_t)(p->start[ls + 1] - p->start[ls]);
            t->start[f] = at;
            memcpy(t->nodes + at, p->nodes + p->start[ls], cnt * sizeof *t->nodes);
            if (words)
                memcpy(t->vis_ext + at * words, p->vis_ext + p->start[ls] * words,
                       cnt * words * sizeof *t->vis_ext);
            at += cnt;
        }
    t->start[ns] = at;
    rtpi_free(a, owner);
    *out = t;
    return RTP_OK;
nomem:
    st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
fail:
    rtpi_free(a, owner);
    rtp_tree_destroy(t);
    return st;
}

/* ----------------------------------------------------------------- crop */

rtp_status rtp_tree_crop(const rtp_tree *src, const int region[4], rtp_tree **out,
                         rtp_error *err)
{
    rtp_tree *t = NULL;
    size_t words, total = 0, at = 0;
    int x0, y0, w, h, nx, ny, x, y, whole[4];
    if (out)
        *out = NULL;
    if (!src || !region || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_crop: NULL argument");
    if (src->busy)
        return rtpi_tree_busy(src, "rtp_tree_crop", err);
    if (!region[0] && !region[1] && !region[2] && !region[3]) {
        /* all 0: the tree's own pixels, as rtp_trace_options.region's
           all 0 is the frame */
        whole[0] = src->rx;
        whole[1] = src->ry;
        whole[2] = src->rx + src->width;
        whole[3] = src->ry + src->height;
        region = whole;
    }
    if (!(region[0] < region[2] && region[1] < region[3]))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "region %d,%d,%d,%d is empty (x0 < x1 and y0 < y1 are needed)",
                          region[0], region[1], region[2], region[3]);
    if (!(region[0] >= src->rx && region[1] >= src->ry && region[2] - src->rx <= src->width &&
          region[3] - src->ry <= src->height))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "region %d,%d,%d,%d is not inside the tree's pixels %d,%d,%d,%d",
                          region[0], region[1], region[2], region[3], src->rx, src->ry,
                          src->rx + src->width, src->ry + src->height);
    x0 = region[0] - src->rx; /* in the source's sample grid */
    y0 = region[1] - src->ry;
    w = region[2] - region[0];
    h = region[3] - region[1];
    nx = w + src->spd; /* SPD: the corners around the region's pixels */
    ny = h + src->spd;
    words = src->vis_words;
    for (y = 0; y < ny; y++) {
        size_t r = (size_t)(y0 + y) * (size_t)src->nx + (size_t)x0;
        total += (size_t)(src->start[r + (size_t)nx] - src->start[r]);
    }
    if (!(t = tree_shell(src, w, h, region[0], region[1], total)))
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (y = 0; y < ny; y++) {
        size_t r = (size_t)(y0 + y) * (size_t)src->nx + (size_t)x0;
        size_t first = (size_t)src->start[r], cnt = (size_t)src->start[r + (size_t)nx] - first;
        for (x = 0; x < nx; x++)
            t->start[(size_t)y * (size_t)nx + (size_t)x] =
                at + (size_t)(src->start[r + (size_t)x] - first);
        memcpy(t->nodes + at, src->nodes + first, cnt * sizeof *t->nodes);
        if (words)
            memcpy(t->vis_ext + at * words, src->vis_ext + first * words,
                   cnt * words * sizeof *t->vis_ext);
        at += cnt;
    }
    t->start[(size_t)nx * (size_t)ny] = at;
    *out = t;
    return RTP_OK;
}
