/* trace.c — the Whitted ray tracer.  For each pixel sample it records the
 * ray tree (hits, light visibility, reflected and refracted subtrees) and
 * then evaluates that tree with rtpi_shade_tree: the image trace produces
 * is the evaluation of the trees it recorded. */
#include "internal.h"

#include <stdlib.h>
#include <time.h>
#ifdef RTP_HAVE_THREADS
#include <pthread.h>
#endif

/* Per-sample tree size cap: past it no further secondary rays are spawned
   (depth 64 in a hall of mirrors and glass would otherwise grow 2^64). */
#define MAX_NODES_PER_SAMPLE (1u << 20)

typedef struct camera {
    rtpi_v3 from, dir, right, up;
    double step;   /* image-plane distance between neighbouring samples */
    double hither;
    int nx, ny;    /* samples across and down */
} camera;

typedef struct counts {
    unsigned long long eye_rays, eye_hits, shadow_rays, reflected_rays,
        refracted_rays, capped;
} counts;

typedef struct shared shared;

typedef struct worker {
    shared *sh;
    rtpi_node *nodes;
    size_t nn, cap;
    unsigned char *vis;
    size_t vis_cap;
    counts n;
    rtp_status status;
} worker;

struct shared {
    const rtp_scene *s;
    const rtpi_kdtree *kd;
    camera cam;
    int spd, max_depth;
    double min_weight;
    float *out;        /* nx*ny samples, RGB */
    int next_row, rows_done;
    const rtp_trace_options *opt;
#ifdef RTP_HAVE_THREADS
    pthread_mutex_t lock;
#endif
};

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void camera_init(camera *c, const rtp_scene *s, int nx, int ny)
{
    rtpi_v3 up;
    int span = nx > ny ? nx : ny;
    c->from = v3(s->camera.from[0], s->camera.from[1], s->camera.from[2]);
    c->dir = v3_norm(v3_sub(v3(s->camera.at[0], s->camera.at[1], s->camera.at[2]),
                            c->from));
    if (v3_len(c->dir) == 0.0)
        c->dir = v3(0, 0, -1);
    up = v3(s->camera.up[0], s->camera.up[1], s->camera.up[2]);
    c->right = v3_norm(v3_cross(c->dir, up));
    if (v3_len(c->right) < 0.5) {
        /* up parallel to the view direction: any perpendicular will do. */
        up = fabs(c->dir.z) < 0.9 ? v3(0, 0, 1) : v3(0, 1, 0);
        c->right = v3_norm(v3_cross(c->dir, up));
    }
    c->up = v3_cross(c->right, c->dir);
    /* NFF: the angle spans the centres of the outermost samples. */
    c->step = 2.0 * tan(s->camera.angle * (3.14159265358979323846 / 360.0)) /
              (double)(span > 1 ? span - 1 : 1);
    c->hither = s->camera.hither > 0.0 ? s->camera.hither : 0.0;
    c->nx = nx;
    c->ny = ny;
}

static int32_t push_node(worker *w)
{
    size_t nl = w->sh->s->nlights, bytes;
    if (w->nn >= MAX_NODES_PER_SAMPLE)
        return -1;
    if (rtpi_grow(&w->sh->s->alloc, (void **)&w->nodes, &w->cap, w->nn + 1,
                  sizeof *w->nodes)) {
        w->status = RTP_ERR_NOMEM;
        return -1;
    }
    bytes = ((w->nn + 1) * nl + 7) / 8;
    if (rtpi_grow(&w->sh->s->alloc, (void **)&w->vis, &w->vis_cap, bytes, 1)) {
        w->status = RTP_ERR_NOMEM;
        return -1;
    }
    return (int32_t)w->nn++;
}

static int32_t trace_ray(worker *w, const rtpi_ray *ray, int depth,
                         double weight);

/* Spawns a secondary ray from node idx at p leaving in unit direction dir. */
static int32_t spawn(worker *w, rtpi_v3 p, rtpi_v3 ng, rtpi_v3 dir, int depth,
                     double weight)
{
    rtpi_ray r;
    r.o = rtpi_offset_origin(p, ng, v3_dot(ng, dir) >= 0.0 ? 1.0 : -1.0);
    r.d = dir;
    r.tmin = 0.0;
    r.tmax = HUGE_VAL;
    return trace_ray(w, &r, depth, weight);
}

static int32_t trace_ray(worker *w, const rtpi_ray *ray, int depth,
                         double weight)
{
    const shared *sh = w->sh;
    const rtp_scene *s = sh->s;
    const rtpi_material *m;
    rtpi_hit hit;
    rtpi_surface sf;
    rtpi_v3 d = ray->d, ng, ns;
    int32_t idx, refl = RTPI_CHILD_NONE;
    int front;
    size_t i, nl = s->nlights;

    if (!rtpi_kd_intersect(sh->kd, ray, &hit))
        return RTPI_CHILD_MISS;
    idx = push_node(w);
    if (idx < 0) {
        w->n.capped++;
        return RTPI_CHILD_NONE;
    }
    rtpi_surface_at(s, ray, &hit, &sf);
    m = &s->mats[sf.mat];
    ng = sf.ng;
    ns = sf.ns;
    front = v3_dot(d, ng) < 0.0;
    /* Transparent objects are two-sided always; opaque ones only outside
       SPD mode (SPD: one-sided, back faces keep their normal). */
    if (!front && (!sh->spd || m->kt > 0.0f)) {
        ng = v3_mul(ng, -1.0);
        ns = v3_mul(ns, -1.0);
    }
    {
        rtpi_node *nd = &w->nodes[idx];
        nd->p = sf.p;
        nd->n = ns;
        nd->v = v3_mul(d, -1.0);
        nd->uv[0] = sf.uv[0];
        nd->uv[1] = sf.uv[1];
        nd->prim = hit.prim;
        nd->mat = sf.mat;
        nd->refl = nd->refr = RTPI_CHILD_NONE;
        nd->vis = (uint32_t)((size_t)idx * nl);
    }

    /* Shadows: no ray where the surface faces away from the light. */
    for (i = 0; i < nl; i++) {
        const rtpi_light *L = &s->lights[i];
        rtpi_v3 lp = v3(L->pos[0], L->pos[1], L->pos[2]);
        rtpi_v3 l = v3_sub(lp, sf.p);
        size_t bit = (size_t)idx * nl + i;
        rtpi_ray sr;
        double dist;
        w->vis[bit >> 3] &= (unsigned char)~(1u << (bit & 7));
        if (v3_dot(ns, l) <= 0.0)
            continue;
        sr.o = rtpi_offset_origin(sf.p, ng, v3_dot(ng, l) >= 0.0 ? 1.0 : -1.0);
        l = v3_sub(lp, sr.o);
        dist = v3_len(l);
        if (!(dist > 0.0))
            continue;
        sr.d = v3_mul(l, 1.0 / dist);
        sr.tmin = 0.0;
        /* Stop just short of the light: a surface passing through the
           light itself must not shadow it (1e-9 relative is far above
           double rounding and far below any feature size). */
        sr.tmax = dist * (1.0 - 1e-9);
        w->n.shadow_rays++;
        if (!rtpi_kd_occluded(sh->kd, &sr))
            w->vis[bit >> 3] |= (unsigned char)(1u << (bit & 7));
    }

    if (depth >= sh->max_depth)
        return idx;
    if (m->ks > 0.0f && weight * m->ks >= sh->min_weight) {
        rtpi_v3 r = v3_norm(v3_madd(d, ns, -2.0 * v3_dot(d, ns)));
        w->n.reflected_rays++;
        refl = spawn(w, sf.p, ng, r, depth + 1, weight * m->ks);
        w->nodes[idx].refl = refl;
    }
    if (m->kt > 0.0f && weight * m->kt >= sh->min_weight) {
        double ior = m->ior > 0.0f ? m->ior : 1.0;
        double eta = front ? 1.0 / ior : ior;
        double cosi = -v3_dot(d, ns);
        double k = 1.0 - eta * eta * (1.0 - cosi * cosi);
        int32_t refr;
        if (k < 0.0) {
            /* Total internal reflection: the transmitted share follows
               the reflected ray; reuse it when it was traced. */
            if (refl == RTPI_CHILD_NONE) {
                rtpi_v3 r = v3_norm(v3_madd(d, ns, -2.0 * v3_dot(d, ns)));
                w->n.reflected_rays++;
                refr = spawn(w, sf.p, ng, r, depth + 1, weight * m->kt);
            } else {
                refr = refl;
            }
        } else {
            rtpi_v3 t = v3_norm(v3_add(v3_mul(d, eta),
                                       v3_mul(ns, eta * cosi - sqrt(k))));
            w->n.refracted_rays++;
            refr = spawn(w, sf.p, ng, t, depth + 1, weight * m->kt);
        }
        w->nodes[idx].refr = refr;
    }
    return idx;
}

static void trace_sample(worker *w, int x, int y, float *rgb)
{
    const camera *c = &w->sh->cam;
    rtpi_ray ray;
    rtpi_v3 d;
    rtpi_tree tree;
    double len, col[3];
    double sx = ((double)x - 0.5 * (c->nx - 1)) * c->step;
    double sy = (0.5 * (c->ny - 1) - (double)y) * c->step;
    d = v3_add(c->dir, v3_add(v3_mul(c->right, sx), v3_mul(c->up, sy)));
    len = v3_len(d);
    ray.o = c->from;
    ray.d = v3_mul(d, 1.0 / len);
    /* hither is a distance along the view axis; d has unit length along
       it, so the same plane is at hither * |d| along the unit ray. */
    ray.tmin = c->hither * len;
    ray.tmax = HUGE_VAL;
    w->nn = 0;
    w->n.eye_rays++;
    tree.root = trace_ray(w, &ray, 1, 1.0);
    if (tree.root >= 0)
        w->n.eye_hits++;
    tree.nodes = w->nodes;
    tree.vis = w->vis;
    rtpi_shade_tree(w->sh->s, &tree, col);
    rgb[0] = (float)col[0];
    rgb[1] = (float)col[1];
    rgb[2] = (float)col[2];
}

static void lock(shared *sh)
{
#ifdef RTP_HAVE_THREADS
    pthread_mutex_lock(&sh->lock);
#else
    (void)sh;
#endif
}
static void unlock(shared *sh)
{
#ifdef RTP_HAVE_THREADS
    pthread_mutex_unlock(&sh->lock);
#else
    (void)sh;
#endif
}

static void work(worker *w, int is_main)
{
    shared *sh = w->sh;
    for (;;) {
        int y, x, done;
        lock(sh);
        y = sh->next_row++;
        unlock(sh);
        if (y >= sh->cam.ny || w->status != RTP_OK)
            break;
        for (x = 0; x < sh->cam.nx; x++)
            trace_sample(w, x, y, sh->out + 3 * ((size_t)y * sh->cam.nx + x));
        lock(sh);
        done = ++sh->rows_done;
        unlock(sh);
        if (is_main && sh->opt->progress)
            sh->opt->progress(sh->opt->progress_user, (double)done / sh->cam.ny);
    }
}

#ifdef RTP_HAVE_THREADS
static void *thread_main(void *arg)
{
    work((worker *)arg, 0);
    return NULL;
}
#endif

rtp_status rtp_trace(const rtp_scene *s, const rtp_trace_options *opt_in,
                     rtp_image **out, rtp_trace_stats *stats, rtp_error *err)
{
    rtp_trace_options opt;
    shared sh;
    worker *ws = NULL;
    rtpi_kdtree *kd = NULL;
    rtp_image *img = NULL;
    float *corners = NULL;
    rtp_status st;
    int w, h, nthreads, i, started = 1;
    double t0, t1, t2;
    rtpi_kd_stats ks;

    if (!s || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_trace: NULL argument");
    *out = NULL;
    memset(&opt, 0, sizeof opt);
    if (opt_in)
        opt = *opt_in;
    w = opt.width > 0 ? opt.width : s->width;
    h = opt.height > 0 ? opt.height : s->height;
    if (opt.spd)
        w = h = 512;
    if (opt.max_depth < 0 || opt.width < 0 || opt.height < 0 || opt.threads < 0 ||
        !(opt.min_weight >= 0.0))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_trace: negative option value");
    nthreads = opt.threads > 1 ? opt.threads : 1;
#ifndef RTP_HAVE_THREADS
    nthreads = 1;
#endif
    if (nthreads > 256)
        nthreads = 256;
    st = rtp_image_create(w, h, &s->alloc, &img, err);
    if (st != RTP_OK)
        return st;

    memset(&sh, 0, sizeof sh);
    sh.s = s;
    sh.spd = opt.spd;
    sh.max_depth = opt.max_depth > 0 ? opt.max_depth : 5;
    sh.min_weight = opt.spd ? 0.0 : opt.min_weight;
    sh.opt = &opt;
    if (opt.spd) {
        /* SPD: rays through the (w+1)x(h+1) pixel corners, averaged. */
        corners = (float *)rtpi_malloc_array(&s->alloc, (size_t)(w + 1) * (h + 1),
                                             3 * sizeof(float));
        if (!corners) {
            rtp_image_destroy(img);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        }
        camera_init(&sh.cam, s, w + 1, h + 1);
        sh.out = corners;
    } else {
        camera_init(&sh.cam, s, w, h);
        sh.out = img->pixels;
    }

    t0 = now_seconds();
    st = rtpi_kd_build(s, &s->alloc, &kd, err);
    if (st != RTP_OK) {
        rtpi_free(&s->alloc, corners);
        rtp_image_destroy(img);
        return st;
    }
    sh.kd = kd;
    t1 = now_seconds();

    ws = (worker *)rtpi_calloc_array(&s->alloc, (size_t)nthreads, sizeof *ws);
    if (!ws) {
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }
    for (i = 0; i < nthreads; i++) {
        ws[i].sh = &sh;
        ws[i].status = RTP_OK;
    }
#ifdef RTP_HAVE_THREADS
    if (nthreads > 1) {
        pthread_t tid[256];
        pthread_mutex_init(&sh.lock, NULL);
        for (i = 1; i < nthreads; i++) {
            if (pthread_create(&tid[i], NULL, thread_main, &ws[i]) != 0)
                break;
        }
        started = i;
        work(&ws[0], 1);
        for (i = 1; i < started; i++)
            pthread_join(tid[i], NULL);
        pthread_mutex_destroy(&sh.lock);
    } else {
        work(&ws[0], 1);
    }
#else
    work(&ws[0], 1);
#endif
    (void)started;
    t2 = now_seconds();
    st = RTP_OK;
    for (i = 0; i < nthreads; i++)
        if (ws[i].status != RTP_OK)
            st = rtpi_error(err, ws[i].status, NULL, 0, 0, "out of memory while tracing");
    if (st == RTP_OK && corners) {
        int x, y, c;
        for (y = 0; y < h; y++)
            for (x = 0; x < w; x++)
                for (c = 0; c < 3; c++) {
                    size_t a = 3 * ((size_t)y * (w + 1) + x) + c;
                    size_t b = a + 3 * (size_t)(w + 1);
                    img->pixels[3 * ((size_t)y * w + x) + c] =
                        0.25f * (corners[a] + corners[a + 3] + corners[b] + corners[b + 3]);
                }
    }
    if (stats) {
        memset(stats, 0, sizeof *stats);
        for (i = 0; i < nthreads; i++) {
            stats->eye_rays += ws[i].n.eye_rays;
            stats->eye_hits += ws[i].n.eye_hits;
            stats->shadow_rays += ws[i].n.shadow_rays;
            stats->reflected_rays += ws[i].n.reflected_rays;
            stats->refracted_rays += ws[i].n.refracted_rays;
        }
        rtpi_kd_get_stats(kd, &ks);
        stats->kd_nodes = ks.nodes;
        stats->kd_leaves = ks.leaves;
        stats->kd_prim_refs = ks.prim_refs;
        stats->kd_depth = ks.depth;
        stats->build_seconds = t1 - t0;
        stats->trace_seconds = t2 - t1;
        stats->width = w;
        stats->height = h;
    }
done:
    if (ws) {
        for (i = 0; i < nthreads; i++) {
            rtpi_free(&s->alloc, ws[i].nodes);
            rtpi_free(&s->alloc, ws[i].vis);
        }
        rtpi_free(&s->alloc, ws);
    }
    rtpi_kd_destroy(kd);
    rtpi_free(&s->alloc, corners);
    if (st != RTP_OK) {
        rtp_image_destroy(img);
        return st;
    }
    *out = img;
    return RTP_OK;
}
