/* tree.c — a traced image's ray trees: editing parameters (with the checks
 * that keep re-evaluation exact) and evaluation with the one shading
 * routine. */
#include "internal.h"
#include "shadow.h"

#include <time.h>

void rtp_tree_destroy(rtp_tree *t)
{
    rtp_allocator a;
    if (!t)
        return;
    a = t->alloc;
    rtp_scene_destroy(t->scene);
    rtpi_free(&a, t->mats0);
    rtpi_free(&a, t->lights0);
    rtpi_free(&a, t->nodes);
    rtpi_free(&a, t->start);
    rtpi_free(&a, t->vis_ext);
    rtpi_kd_destroy(t->kd);
    rtpi_free(&a, t->cur_vis);
    rtpi_free(&a, t->cur_pos);
    rtpi_free(&a, t);
}

void rtp_tree_get_info(const rtp_tree *t, rtp_tree_info *info)
{
    memset(info, 0, sizeof *info);
    if (!t)
        return;
    info->width = t->width;
    info->height = t->height;
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
}

/* ---------------------------------------------------------------- edits */

/* Checks the tree's scene against what was traced: may the recorded trees
   evaluate it exactly?  Returns RTP_OK or RTP_ERR_UNSUPPORTED with the
   remedy in err. */
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
    for (i = 0; i < s->nmats; i++) {
        const rtpi_material *m = &s->mats[i], *m0 = &t->mats0[i];
        if (m->ks > 0.0f && m0->ks == 0.0f)
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: material %zu had ks 0 when traced, so no "
                              "reflected rays were recorded for it; trace again with "
                              "--set %s=%s",
                              key, value, i, key, value);
        if (m->kt > 0.0f && m0->kt == 0.0f)
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: material %zu had kt 0 when traced, so no "
                              "refracted rays were recorded for it; trace again with "
                              "--set %s=%s",
                              key, value, i, key, value);
        if (t->spd && m0->kt > 0.0f && m->kt == 0.0f)
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: in SPD mode kt 0 makes material %zu one-sided, "
                              "which changes its shadow rays; trace again with "
                              "--set %s=%s",
                              key, value, i, key, value);
        if (m0->kt > 0.0f && m->ior != m0->ior)
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: a new index of refraction bends material %zu's "
                              "refracted rays elsewhere; trace again with --set %s=%s",
                              key, value, i, key, value);
        if (t->min_weight > 0.0 && (m->ks > m0->ks || m->kt > m0->kt))
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: the trace skipped rays weighing less than %g, "
                              "which a larger ks or kt would make count; trace again "
                              "with --min-weight 0",
                              key, value, t->min_weight);
    }
    return RTP_OK;
}

rtp_status rtp_tree_set(rtp_tree *t, const char *key, const char *value,
                        rtp_error *err)
{
    rtp_scene *s;
    rtpi_material *mats = NULL;
    rtpi_light *lights = NULL;
    float amb[3], bg[3];
    rtp_status st;
    if (!t || !key || !value)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_set: NULL argument");
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
    memcpy(mats, s->mats, s->nmats * sizeof *mats);
    memcpy(lights, s->lights, s->nlights * sizeof *lights);
    memcpy(amb, s->ambient, sizeof amb);
    memcpy(bg, s->background, sizeof bg);
    st = rtp_scene_set(s, key, value, err);
    if (st == RTP_OK)
        st = check_exact(t, key, value, err);
    if (st != RTP_OK) {
        /* names are untouched by rtp_scene_set: the copies' pointers are
           the scene's own */
        memcpy(s->mats, mats, s->nmats * sizeof *mats);
        memcpy(s->lights, lights, s->nlights * sizeof *lights);
        memcpy(s->ambient, amb, sizeof amb);
        memcpy(s->background, bg, sizeof bg);
    }
    rtpi_free(&t->alloc, mats);
    rtpi_free(&t->alloc, lights);
    return st;
}

/* ------------------------------------------------------ moved lights */

rtp_status rtp_tree_add_light(rtp_tree *t, const double pos[3], rtp_error *err)
{
    rtp_scene *s;
    rtpi_light l;
    size_t cap0;
    if (!t || !pos)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_add_light: NULL argument");
    if (!isfinite(pos[0]) || !isfinite(pos[1]) || !isfinite(pos[2]))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "light position must be finite");
    s = t->scene;
    cap0 = s->nlights;
    if (rtpi_grow(&t->alloc, (void **)&t->lights0, &cap0, s->nlights + 1, sizeof *t->lights0))
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    memset(&l, 0, sizeof l);
    l.pos[0] = pos[0];
    l.pos[1] = pos[1];
    l.pos[2] = pos[2];
    l.color[0] = l.color[1] = l.color[2] = 1.0f;
    l.on = 1;
    if (rtpi_scene_add_light(s, &l) < 0)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    /* never traced: its visibility is always decided anew */
    t->lights0[s->nlights - 1] = l;
    t->lights0[s->nlights - 1].pos[0] = NAN;
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

typedef struct vis_ctx {
    rtp_tree *t;
    const rtpi_shadow *sh;
    rtpi_v3 lp;
    size_t light;
    unsigned long long queries;
} vis_ctx;

/* Decides light `light` anew for every node of one row of samples, with
   trace's own rule (rtpi_shadow_setup) and the chosen shadow query. */
static int vis_row(void *ctx, int y)
{
    vis_ctx *v = (vis_ctx *)ctx;
    rtp_tree *t = v->t;
    const rtp_scene *s = t->scene;
    size_t k0 = (size_t)y * t->nx, k1 = k0 + (size_t)t->nx;
    size_t n, words = t->cur_words, wi = v->light >> 5;
    uint32_t bit = 1u << (v->light & 31);
    for (n = (size_t)t->start[k0]; n < (size_t)t->start[k1]; n++) {
        const rtpi_cnode *nd = &t->nodes[n];
        rtpi_surface sf;
        rtpi_v3 ng, ns, o;
        uint32_t *w = &t->cur_vis[n * words + wi];
        rtpi_surface_from_point(s, nd->prim, v3(nd->p[0], nd->p[1], nd->p[2]), &sf);
        ng = sf.ng;
        ns = sf.ns;
        if ((nd->link & RTPI_L_BACK) &&
            rtpi_two_sided(s, t->spd, nd->prim, &s->mats[sf.mat])) {
            ng = v3_mul(ng, -1.0);
            ns = v3_mul(ns, -1.0);
        }
        *w &= ~bit;
        if (!rtpi_shadow_setup(sf.p, ng, ns, v->lp, &o))
            continue;
        v->queries++;
        if (rtpi_shadow_visible(v->sh, sf.p, o, nd->prim))
            *w |= bit;
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

/* Brings cur_vis up to date for every light: recorded bits where a light
   is where it was traced, new decisions where it moved.  Only lights whose
   position (or the shadow mode) changed since the last call are redone. */
static rtp_status update_visibility(rtp_tree *t, const rtp_eval_options *opt,
                                    rtp_eval_stats *st, rtp_error *err)
{
    rtp_scene *s = t->scene;
    size_t nl = s->nlights, words = (nl + 31) / 32, i, n;
    int mode = opt ? (int)opt->shadows : 0, res = opt && opt->shadow_res > 0 ? opt->shadow_res : 1024;
    int threads = opt && opt->threads > 1 ? opt->threads : 1, k;
    void *ctx[RTPI_MAX_THREADS];
    vis_ctx vc[RTPI_MAX_THREADS];
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
        for (i = 0; i < nl; i++)
            t->cur_pos[3 * i] = NAN; /* nothing decided yet */
    }
    for (i = 0; i < nl; i++) {
        const double *lp = s->lights[i].pos;
        int moved = light_moved(t, i);
        if (!isnan(t->cur_pos[3 * i]) && light_at(t, i, t->cur_pos + 3 * i) &&
            (!moved || (t->cur_mode == mode && t->cur_res == res)))
            continue; /* up to date */
        if (!moved) {
            for (n = 0; n < t->nnodes; n++) {
                uint32_t *w = &t->cur_vis[n * words + (i >> 5)];
                *w = (*w & ~(1u << (i & 31))) | recorded_bit(t, n, i) << (i & 31);
            }
        } else {
            rtpi_shadow *sh = NULL;
            rtp_status rs;
            if (!t->kd && (rs = rtpi_kd_build(s, &t->alloc, &t->kd, err)) != RTP_OK)
                return rs;
            rs = rtpi_shadow_create(s, t->kd, v3(lp[0], lp[1], lp[2]), (rtpi_shadow_mode)mode,
                                    res, &t->alloc, &sh, err);
            if (rs != RTP_OK)
                return rs;
            for (k = 0; k < threads; k++) {
                vc[k].t = t;
                vc[k].sh = sh;
                vc[k].lp = v3(lp[0], lp[1], lp[2]);
                vc[k].light = i;
                vc[k].queries = 0;
                ctx[k] = &vc[k];
            }
            rtpi_parallel_rows(t->ny, threads, ctx, vis_row, NULL, NULL);
            rtpi_shadow_destroy(sh);
            if (st) {
                st->moved_lights++;
                for (k = 0; k < threads; k++)
                    st->shadow_queries += vc[k].queries;
            }
        }
        t->cur_pos[3 * i] = lp[0];
        t->cur_pos[3 * i + 1] = lp[1];
        t->cur_pos[3 * i + 2] = lp[2];
    }
    t->cur_mode = mode;
    t->cur_res = res;
    return RTP_OK;
}

/* ----------------------------------------------------------- evaluation */

typedef struct eval_ctx {
    const rtp_tree *t;
    rtpi_shade_ctx shade;
    const uint32_t *vis;  /* visibility words per node, or NULL */
    rtpi_v3 eye;
    float *samples;
} eval_ctx;

static int eval_row(void *ctx, int y)
{
    const eval_ctx *e = (const eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t k = (size_t)y * t->nx, words = e->shade.vis_words;
    int x;
    for (x = 0; x < t->nx; x++, k++) {
        double col[3];
        size_t a = (size_t)t->start[k], n = (size_t)(t->start[k + 1] - t->start[k]);
        float *px = e->samples + 3 * k;
        rtpi_shade_sample(&e->shade, t->nodes + a, n, e->vis ? e->vis + a * words : NULL,
                          e->eye, col);
        px[0] = (float)col[0];
        px[1] = (float)col[1];
        px[2] = (float)col[2];
    }
    return 0;
}

static double seconds_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

rtp_status rtp_tree_eval(rtp_tree *t, const rtp_eval_options *opt, rtp_image **out,
                         rtp_eval_stats *stats, rtp_error *err)
{
    eval_ctx e;
    void *ctx[RTPI_MAX_THREADS];
    rtp_image *img = NULL;
    rtp_eval_stats st;
    int i, nthreads = opt && opt->threads > 1 ? opt->threads : 1, any_moved = 0;
    rtp_status rs;
    size_t l;
    double t0 = seconds_now(), t1;
    if (!t || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval: NULL argument");
    *out = NULL;
    memset(&st, 0, sizeof st);
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    if (opt && ((unsigned)opt->shadows > RTP_SHADOWS_OSMESA || opt->shadow_res < 0 ||
                opt->shadow_res > 16384))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "invalid shadow mode or resolution (1..16384)");
    memset(&e, 0, sizeof e);
    e.t = t;
    e.shade.s = t->scene;
    e.shade.one_sided = t->spd;
    e.shade.vis_words = t->vis_words;
    e.vis = t->vis_words ? t->vis_ext : NULL;
    for (l = 0; l < t->scene->nlights; l++)
        any_moved |= light_moved(t, l);
    if (any_moved) {
        rs = update_visibility(t, opt, &st, err);
        if (rs != RTP_OK)
            return rs;
        e.shade.vis_words = t->cur_words;
        e.vis = t->cur_vis;
    }
    t1 = seconds_now();
    rs = rtp_image_create(t->width, t->height, &t->alloc, &img, err);
    if (rs != RTP_OK)
        return rs;
    e.eye = v3(t->scene->camera.from[0], t->scene->camera.from[1], t->scene->camera.from[2]);
    if (t->spd) {
        e.samples = (float *)rtpi_malloc_array(&t->alloc, (size_t)t->nx * t->ny,
                                               3 * sizeof(float));
        if (!e.samples) {
            rtp_image_destroy(img);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
    } else {
        e.samples = img->pixels;
    }
    for (i = 0; i < nthreads; i++)
        ctx[i] = &e; /* shading keeps no per-thread state */
    rtpi_parallel_rows(t->ny, nthreads, ctx, eval_row, opt ? opt->progress : NULL,
                       opt ? opt->progress_user : NULL);
    if (t->spd) {
        rtpi_resolve_samples(e.samples, 1, img);
        rtpi_free(&t->alloc, e.samples);
    }
    if (stats) {
        *stats = st;
        stats->seconds = seconds_now() - t0;
        stats->shadow_seconds = t1 - t0;
        stats->samples = (unsigned long long)t->nx * (unsigned long long)t->ny;
        stats->nodes = t->nnodes;
    }
    *out = img;
    return RTP_OK;
}

rtp_status rtp_tree_trace(const rtp_tree *t, int threads, rtp_image **out,
                          rtp_trace_stats *stats, rtp_error *err)
{
    rtp_trace_options o;
    if (!t)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_trace: NULL tree");
    memset(&o, 0, sizeof o);
    o.width = t->width;
    o.height = t->height;
    o.spd = t->spd;
    o.max_depth = t->max_depth;
    o.min_weight = t->min_weight;
    o.threads = threads;
    return rtp_trace(t->scene, &o, out, stats, err);
}
