/* tree.c — a traced image's ray trees: editing parameters (with the checks
 * that keep re-evaluation exact) and evaluation with the one shading
 * routine. */
#include "internal.h"

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
        const rtpi_light *l = &s->lights[i], *l0 = &t->lights0[i];
        if (l->pos[0] != l0->pos[0] || l->pos[1] != l0->pos[1] || l->pos[2] != l0->pos[2])
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "%s=%s: moving light %zu changes its shadows, which "
                              "this version cannot re-evaluate; trace again with "
                              "--set %s=%s",
                              key, value, i, key, value);
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

/* ----------------------------------------------------------- evaluation */

typedef struct eval_ctx {
    const rtp_tree *t;
    rtpi_shade_ctx shade;
    rtpi_v3 eye;
    float *samples;
} eval_ctx;

static int eval_row(void *ctx, int y)
{
    const eval_ctx *e = (const eval_ctx *)ctx;
    const rtp_tree *t = e->t;
    size_t k = (size_t)y * t->nx;
    int x;
    for (x = 0; x < t->nx; x++, k++) {
        double col[3];
        size_t a = (size_t)t->start[k], n = (size_t)(t->start[k + 1] - t->start[k]);
        float *px = e->samples + 3 * k;
        rtpi_shade_sample(&e->shade, t->nodes + a, n,
                          t->vis_words ? t->vis_ext + a * t->vis_words : NULL, e->eye, col);
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

rtp_status rtp_tree_eval(const rtp_tree *t, const rtp_eval_options *opt,
                         rtp_image **out, rtp_eval_stats *stats, rtp_error *err)
{
    eval_ctx e;
    void *ctx[RTPI_MAX_THREADS];
    rtp_image *img = NULL;
    int i, nthreads = opt && opt->threads > 1 ? opt->threads : 1;
    rtp_status st;
    double t0 = seconds_now();
    if (!t || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_eval: NULL argument");
    *out = NULL;
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    st = rtp_image_create(t->width, t->height, &t->alloc, &img, err);
    if (st != RTP_OK)
        return st;
    memset(&e, 0, sizeof e);
    e.t = t;
    e.shade.s = t->scene;
    e.shade.one_sided = t->spd;
    e.shade.vis_words = t->vis_words;
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
        ctx[i] = &e; /* evaluation keeps no per-thread state */
    rtpi_parallel_rows(t->ny, nthreads, ctx, eval_row, opt ? opt->progress : NULL,
                       opt ? opt->progress_user : NULL);
    if (t->spd) {
        rtpi_resolve_samples(e.samples, 1, img);
        rtpi_free(&t->alloc, e.samples);
    }
    if (stats) {
        stats->seconds = seconds_now() - t0;
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
