/* bench_shadow.c — deciding shadows for a moved light, per mode.
 *
 * For each default SPD scene in ../shared/scenes/spd: light 0 moves by a
 * fixed offset (0.1 of the scene's bounding diagonal along (1, 1, 1)/sqrt 3),
 * a 512x512 grid of eye rays through the scene's camera is cast, and for
 * every hit that trace would ask about (the surface facing the light) the
 * moved light's visibility is decided by every mode.  Reported per mode:
 * build time, query time (all queries, one thread, wall clock), and the
 * share of decisions that differ from EXACT (the kd-tree's shadow rays):
 * LIGHTBUF must have none; ITEMBUF at 256..2048 cells per face edge may
 * miss a corner sharper than its cells (lib/shadow.h); OSMESA (in OSMESA=1
 * builds) likewise, plus
 * the share of cells where its item buffer agrees with the software one.
 * Non-exact modes also time the same queries through one thread's shadow
 * cache (rtpi_shadow_visible_cached).
 * Reports; never fails on speed. */
#include "dircube.h"
#include "shadow.h"
#include "../check.h"

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

typedef struct query {
    rtpi_v3 p, o;
    uint32_t prim;
} query;

/* Eye rays as trace casts them (NFF: the angle spans the outermost
   sample centres), surfaces derived from float positions. */
static size_t make_queries(const rtp_scene *s, const rtpi_kdtree *kd, rtpi_v3 lp,
                           int n, query *q)
{
    rtpi_v3 from = v3(s->camera.from[0], s->camera.from[1], s->camera.from[2]);
    rtpi_v3 dir = v3_norm(v3_sub(v3(s->camera.at[0], s->camera.at[1], s->camera.at[2]), from));
    rtpi_v3 up = v3(s->camera.up[0], s->camera.up[1], s->camera.up[2]);
    rtpi_v3 right = v3_norm(v3_cross(dir, up)), upv;
    double step = 2.0 * tan(s->camera.angle * (3.14159265358979323846 / 360.0)) / (n - 1);
    size_t m = 0;
    int x, y;
    if (v3_len(right) < 0.5)
        right = v3_norm(v3_cross(dir, fabs(dir.z) < 0.9 ? v3(0, 0, 1) : v3(0, 1, 0)));
    upv = v3_cross(right, dir);
    for (y = 0; y < n; y++) {
        for (x = 0; x < n; x++) {
            rtpi_ray r;
            rtpi_hit h;
            rtpi_v3 d = v3_add(dir, v3_add(v3_mul(right, (x - 0.5 * (n - 1)) * step),
                                           v3_mul(upv, (0.5 * (n - 1) - y) * step)));
            double len = v3_len(d);
            r.o = from;
            r.d = v3_mul(d, 1.0 / len);
            r.tmin = (s->camera.hither > 0.0 ? s->camera.hither : 0.0) * len;
            r.tmax = HUGE_VAL;
            if (!rtpi_kd_intersect(kd, &r, &h) ||
                !rtpi_shadow_query_at(s, 1, h.prim, v3_madd(r.o, r.d, h.t), r.d, lp, rtpi_offset_floor(s, NULL),
                                  &q[m].p,
                                      &q[m].o))
                continue;
            q[m].prim = h.prim;
            m++;
        }
    }
    return m;
}

/* Builds a mode, answers every query; prints a table row.  ref: EXACT's
   answers (NULL: fill them).  @return 0, or -1 if the mode is missing. */
static int run_mode(const char *scene, const rtp_scene *s, const rtpi_kdtree *kd,
                    rtpi_v3 lp, rtpi_shadow_mode mode, const char *name, int res,
                    const query *q, size_t n, unsigned char *ref, const rtpi_itembuf *sw)
{
    rtpi_shadow *sh = NULL;
    rtp_allocator a;
    rtp_error err;
    double t0, t1, t2;
    size_t k, diff = 0, lit = 0;
    char extra[64] = "", cached[64] = "";
    rtpi_allocator_init(&a, NULL);
    t0 = now();
    if (rtpi_shadow_create(s, kd, lp, mode, res, &a, &sh, &err) != RTP_OK) {
        char buf[256];
        printf("| %s | %s | - | - | - | - | %s |\n", scene, name,
               rtp_error_format(&err, buf, sizeof buf));
        return -1;
    }
    t1 = now();
    for (k = 0; k < n; k++) {
        int v = rtpi_shadow_visible(sh, q[k].p, q[k].o, q[k].prim);
        lit += (size_t)v;
        if (!ref)
            continue;
        if (mode == RTPI_SHADOW_EXACT)
            ref[k] = (unsigned char)v;
        else
            diff += (size_t)(ref[k] != v);
    }
    t2 = now();
    if (mode != RTPI_SHADOW_EXACT) {
        /* the same queries through one thread's cache of the last
           occluder (rows of samples, as vis_row asks them) */
        rtpi_shadow_cache cache = {0};
        double t3 = now(), t4;
        size_t cdiff = 0;
        for (k = 0; k < n; k++) {
            int v = rtpi_shadow_visible_cached(sh, &cache, &q[k].p, &q[k].o, q[k].prim);
            cdiff += ref && (size_t)(ref[k] != v);
        }
        t4 = now();
        snprintf(cached, sizeof cached, "; cached %.1f ns/query, %.4f%% differ",
                 1e9 * (t4 - t3) / (double)(n ? n : 1),
                 100.0 * (double)cdiff / (double)(n ? n : 1));
    }
    if (mode == RTPI_SHADOW_EXACT)
        snprintf(extra, sizeof extra, "%.1f%% of queries lit",
                 100.0 * (double)lit / (double)(n ? n : 1));
    if (mode == RTPI_SHADOW_ITEMBUF) {
        /* 8 bytes per cell of the faces the scene reaches */
        rtpi_dc_window w;
        rtpi_dc_windows(s, lp, res, 1.0, &w);
        snprintf(extra, sizeof extra, "%.1f MB, %lu of 6 faces",
                 (double)w.ncells * 8.0 / 1048576.0, (unsigned long)(w.ncells / ((size_t)res * res)));
    }
    if (mode == RTPI_SHADOW_LIGHTBUF) {
        /* built once more on its own to see its size */
        rtpi_lightbuf lb;
        if (rtpi_lightbuf_build(s, lp, res, &a, &lb, NULL) == RTP_OK) {
            snprintf(extra, sizeof extra, "%.1f MB, %.2f candidates per cell",
                     ((double)(lb.w.ncells + 1) * 4.0 + (double)lb.nrefs * 4.0 +
                      (double)lb.ncand * sizeof *lb.cand +
                      (lb.plane ? (double)lb.ncand * 5.0 * sizeof *lb.plane : 0.0)) /
                         1048576.0,
                     (double)lb.nrefs / (double)(lb.w.ncells ? lb.w.ncells : 1));
            rtpi_lightbuf_free(&lb, &a);
        }
    }
    if (sw && mode == RTPI_SHADOW_OSMESA) {
        /* cell agreement with the software z-buffer at the same res */
        rtpi_itembuf gl;
        if (rtpi_itembuf_build_osmesa(s, lp, res, &a, &gl, NULL) == RTP_OK) {
            size_t c, same = 0, nc = sw->w.ncells < gl.w.ncells ? sw->w.ncells : gl.w.ncells;
            for (c = 0; c < nc; c++)
                same += sw->id[c] == gl.id[c];
            snprintf(extra, sizeof extra, "cells agreeing with software: %.4f%%",
                     100.0 * (double)same / (double)nc);
            rtpi_itembuf_free(&gl, &a);
        }
    }
    printf("| %s | %s | %.3f | %.3f | %.1f | %.4f%% | %s%s |\n", scene, name, t1 - t0, t2 - t1,
           1e9 * (t2 - t1) / (double)(n ? n : 1), 100.0 * (double)diff / (double)(n ? n : 1),
           extra, cached);
    fflush(stdout);
    rtpi_shadow_destroy(sh);
    return 0;
}

static const char *find_spd(void)
{
    static const char *cands[] = {"../shared/scenes/spd", "../../shared/scenes/spd"};
    size_t i;
    for (i = 0; i < sizeof cands / sizeof *cands; i++) {
        char path[256];
        FILE *f;
        snprintf(path, sizeof path, "%s/balls_s4.nff", cands[i]);
        f = fopen(path, "r");
        if (f) {
            fclose(f);
            return cands[i];
        }
    }
    return NULL;
}

int main(void)
{
    static const int ib_res[] = {256, 512, 1024, 2048};
    const char *dir = find_spd();
    const int grid = 512;
    query *q;
    unsigned char *ref;
    size_t i;
    if (!dir) {
        printf("bench_shadow: skip: ../shared/scenes/spd absent\n");
        return 0;
    }
    q = (query *)malloc((size_t)grid * grid * sizeof *q);
    ref = (unsigned char *)malloc((size_t)grid * grid);
    if (!q || !ref) {
        fprintf(stderr, "bench_shadow: out of memory\n");
        return 1;
    }
    printf("## Shadows of a moved light (light 0 + 0.1 diagonal), %dx%d eye-ray hits, 1 thread\n\n",
           grid, grid);
    printf("| scene | mode | build s | queries s | ns/query | differ from exact | note |\n");
    printf("|---|---|---|---|---|---|---|\n");
    for (i = 0; i < (size_t)CHECK_SPD_SCENES; i++) {
        char path[512];
        rtp_scene *s = NULL;
        rtpi_kdtree *kd = NULL;
        rtpi_v3 lp;
        double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
        double diag;
        size_t k, n;
        int r, c;
        snprintf(path, sizeof path, "%s/%s.nff", dir, check_spd_scenes[i]);
        if (rtp_scene_load(path, NULL, &s, NULL) != RTP_OK || !s->nlights ||
            rtpi_kd_build(s, NULL, &kd, NULL) != RTP_OK) {
            printf("| %s | skipped: cannot load | | | | | |\n", check_spd_scenes[i]);
            rtp_scene_destroy(s);
            continue;
        }
        for (k = 0; k < rtpi_scene_nprims(s); k++) {
            double pl[3], ph[3];
            rtpi_prim_bounds(s, (uint32_t)k, pl, ph);
            for (c = 0; c < 3; c++) {
                lo[c] = fmin(lo[c], pl[c]);
                hi[c] = fmax(hi[c], ph[c]);
            }
        }
        diag = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                    (hi[2] - lo[2]) * (hi[2] - lo[2]));
        lp = v3_add(v3(s->lights[0].pos[0], s->lights[0].pos[1], s->lights[0].pos[2]),
                    v3_mul(v3(1, 1, 1), 0.1 * diag / sqrt(3.0)));
        n = make_queries(s, kd, lp, grid, q);
        {
            char name[64];
            snprintf(name, sizeof name, "%s (%lu prims, %lu queries)", check_spd_scenes[i],
                     (unsigned long)rtpi_scene_nprims(s), (unsigned long)n);
            run_mode(name, s, kd, lp, RTPI_SHADOW_EXACT, "exact", 0, q, n, ref, NULL);
        }
        run_mode(check_spd_scenes[i], s, kd, lp, RTPI_SHADOW_LIGHTBUF, "lightbuf 1024", 1024, q, n, ref, NULL);
        for (r = 0; r < (int)(sizeof ib_res / sizeof *ib_res); r++) {
            char name[32];
            rtpi_itembuf sw;
            rtp_allocator a;
            int have_sw;
            snprintf(name, sizeof name, "itembuf %d", ib_res[r]);
            run_mode(check_spd_scenes[i], s, kd, lp, RTPI_SHADOW_ITEMBUF, name, ib_res[r], q, n, ref, NULL);
#if defined(RTP_HAVE_OSMESA)
            rtpi_allocator_init(&a, NULL);
            have_sw = rtpi_itembuf_build(s, lp, ib_res[r], &a, &sw, NULL) == RTP_OK;
            snprintf(name, sizeof name, "osmesa %d", ib_res[r]);
            run_mode(check_spd_scenes[i], s, kd, lp, RTPI_SHADOW_OSMESA, name, ib_res[r], q, n, ref,
                     have_sw ? &sw : NULL);
            if (have_sw)
                rtpi_itembuf_free(&sw, &a);
#else
            (void)sw;
            (void)a;
            (void)have_sw;
#endif
        }
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
    }
#if !defined(RTP_HAVE_OSMESA)
    printf("\nosmesa: not built (make OSMESA=1 to include it)\n");
#endif
    free(q);
    free(ref);
    return 0;
}
