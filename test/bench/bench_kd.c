/* bench_kd.c — kd-tree build rate and single-thread ray rates.
 *
 * Builds the tree over the Stanford bunny (../shared/scenes/meshes) and a
 * generated ~1M-triangle displaced sphere, then shoots, one thread:
 * camera rays (1024x1024 pinhole looking at the bunny's bounds), shadow
 * rays from the camera hits to a point light (any-hit), and random rays
 * (origins inside the bounds, uniform directions).  Builds are timed on
 * two threads and on one: wall clock, and the CPU time of all threads
 * (on a busy machine the wall clock says little).  Rays are timed on one
 * thread, in its CPU time, best of three passes, and are made before the
 * clock starts, so the rates are the kd-tree's alone.  Reports; never
 * fails on speed.  Built with -DKD_COUNT (kdtree.c too) it also prints
 * steps, leaves and tests a ray.  `bench_kd --bunny` runs the bunny
 * alone, `--big` the generated mesh alone. */
#include "kdtree.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* CPU time of this thread: the benchmark is single-threaded, and other
   load on a shared machine then does not count against it. */
#ifdef KD_COUNT
extern unsigned long long kd_cnt[4];
static void cnt_report(void)
{
    printf("   per ray: %.1f steps, %.1f leaves, %.1f tests\n",
           (double)kd_cnt[0] / (double)kd_cnt[3], (double)kd_cnt[1] / (double)kd_cnt[3],
           (double)kd_cnt[2] / (double)kd_cnt[3]);
    memset(kd_cnt, 0, sizeof kd_cnt);
}
#define CNT_REPORT() cnt_report()
#else
#define CNT_REPORT() ((void)0)
#endif

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Wall-clock time, for builds on more than one thread. */
static double wall(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU time of the whole process (all threads). */
static double cpu(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;

static double rnd(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (double)((rng_state * 2685821657736338717ull) >> 11) *
           (1.0 / 9007199254740992.0);
}

static const char *find_bunny(void)
{
    static const char *cands[] = {
        "../shared/scenes/meshes/stanford-bunny.obj",
        "../../shared/scenes/meshes/stanford-bunny.obj"};
    size_t i;
    for (i = 0; i < sizeof cands / sizeof *cands; i++) {
        FILE *f = fopen(cands[i], "r");
        if (f) {
            fclose(f);
            return cands[i];
        }
    }
    return NULL;
}

/* Builds `reps` times on `threads` threads; reports the fastest (wall
   clock: the build may use more than this thread).  @return the last
   tree. */
static rtpi_kdtree *timed_build(const rtp_scene *s, const char *name, int reps,
                                int threads)
{
    rtpi_kdtree *kd = NULL;
    double best = 1e30, best_cpu = 1e30;
    int i;
    for (i = 0; i < reps; i++) {
        double t = wall(), c = cpu();
        rtpi_kd_destroy(kd);
        kd = NULL;
        if (rtpi_kd_build_mt(s, NULL, threads, &kd, NULL) != RTP_OK) {
            fprintf(stderr, "bench_kd: build failed\n");
            return NULL;
        }
        t = wall() - t;
        c = cpu() - c;
        best = t < best ? t : best;
        best_cpu = c < best_cpu ? c : best_cpu;
    }
    {
        rtpi_kd_stats st;
        rtpi_kd_get_stats(kd, &st);
        printf("build %s %dT: %lu tris in %.3f s = %.2f Mtris/s"
               " (CPU %.3f s = %.2f Mtris/s;"
               " %lu nodes, %lu leaves, %lu empty, %.2f refs/tri, depth %d)\n",
               name, threads, (unsigned long)s->ntris, best,
               (double)s->ntris / best * 1e-6, best_cpu,
               (double)s->ntris / best_cpu * 1e-6, (unsigned long)st.nodes,
               (unsigned long)st.leaves, (unsigned long)st.empty_leaves,
               (double)st.prim_refs / (double)(s->ntris ? s->ntris : 1),
               st.depth);
    }
    return kd;
}

static void bounds(const rtp_scene *s, double lo[3], double hi[3])
{
    size_t i;
    int k;
    for (k = 0; k < 3; k++) {
        lo[k] = 1e300;
        hi[k] = -1e300;
    }
    for (i = 0; i < s->npos; i++) {
        for (k = 0; k < 3; k++) {
            double x = s->pos[3 * i + k];
            lo[k] = x < lo[k] ? x : lo[k];
            hi[k] = x > hi[k] ? x : hi[k];
        }
    }
}

/* A sphere of radius ~1 with bumps, nu x nv quads, two triangles each. */
static rtp_scene *make_big(int nu, int nv)
{
    rtp_scene *s = NULL;
    int i, j;
    const double pi = 3.14159265358979323846;
    if (rtpi_scene_create(NULL, &s) != RTP_OK)
        return NULL;
    for (j = 0; j <= nv; j++) {
        double th = pi * j / nv;
        for (i = 0; i < nu; i++) {
            double ph = 2 * pi * i / nu;
            double r = 1.0 + 0.05 * sin(9 * th) * sin(7 * ph) + 0.01 * rnd();
            if (rtpi_scene_add_pos(s, r * sin(th) * cos(ph), r * sin(th) * sin(ph),
                                   r * cos(th)))
                goto fail;
        }
    }
    for (j = 0; j < nv; j++) {
        for (i = 0; i < nu; i++) {
            rtpi_tri t;
            uint32_t a = (uint32_t)(j * nu + i), b = (uint32_t)(j * nu + (i + 1) % nu);
            uint32_t c = a + (uint32_t)nu, d = b + (uint32_t)nu;
            int k;
            for (k = 0; k < 3; k++)
                t.n[k] = t.t[k] = RTPI_NONE;
            t.mat = 0;
            t.v[0] = a, t.v[1] = c, t.v[2] = d;
            if (rtpi_scene_add_tri(s, &t))
                goto fail;
            t.v[0] = a, t.v[1] = d, t.v[2] = b;
            if (rtpi_scene_add_tri(s, &t))
                goto fail;
        }
    }
    return s;
fail:
    rtp_scene_destroy(s);
    return NULL;
}

static void rays_bunny(const rtp_scene *s, const rtpi_kdtree *kd)
{
    enum { W = 1024, H = 1024, NRAND = 1 << 20, REPS = 3 };
    rtpi_ray *rays = (rtpi_ray *)malloc(sizeof(rtpi_ray) * (size_t)W * H);
    rtpi_hit *hits = (rtpi_hit *)malloc(sizeof(rtpi_hit) * (size_t)W * H);
    unsigned char *hit = (unsigned char *)malloc((size_t)W * H);
    double lo[3], hi[3], c[3], ext = 0, t;
    size_t i, n, nhit = 0, nocc = 0;
    rtpi_v3 eye, light;
    int k, x, y, rep;
    if (!rays || !hits || !hit) {
        fprintf(stderr, "bench_kd: out of memory\n");
        goto done;
    }
    bounds(s, lo, hi);
    for (k = 0; k < 3; k++) {
        c[k] = 0.5 * (lo[k] + hi[k]);
        ext = fmax(ext, hi[k] - lo[k]);
    }
    /* Looking down -z at the bounds from 1.6 extents away; a 40 degree
       field of view frames them. */
    eye = v3(c[0], c[1], c[2] + 1.6 * ext);
    for (y = 0; y < H; y++) {
        for (x = 0; x < W; x++) {
            double u = (x + 0.5) / W * 2 - 1, v = 1 - (y + 0.5) / H * 2;
            double f = tan(20.0 * 3.14159265358979323846 / 180.0);
            rtpi_ray *r = &rays[(size_t)y * W + x];
            r->o = eye;
            r->d = v3_norm(v3(u * f, v * f, -1));
            r->tmin = 0;
            r->tmax = HUGE_VAL;
        }
    }
    n = (size_t)W * H;
    t = 1e30;
    for (rep = 0; rep < REPS; rep++) {
        double t1 = now();
        nhit = 0;
        for (i = 0; i < n; i++) {
            hit[i] = (unsigned char)rtpi_kd_intersect(kd, &rays[i], &hits[i]);
            nhit += hit[i];
        }
        t1 = now() - t1;
        t = t1 < t ? t1 : t;
    }
    printf("camera bunny %dx%d: %lu rays in %.3f s = %.2f Mrays/s (%.0f%% hit)\n",
           W, H, (unsigned long)n, t, (double)n / t * 1e-6,
           100.0 * (double)nhit / (double)n);
    CNT_REPORT();

    /* Shadow rays from every hit to a light above, right and in front. */
    light = v3(c[0] + ext, c[1] + 1.5 * ext, c[2] + ext);
    {
        size_t m = 0;
        const double floor = rtpi_offset_floor(s, NULL);
        for (i = 0; i < n; i++) {
            rtpi_surface su;
            double side;
            if (!hit[i])
                continue;
            rtpi_surface_at(s, &rays[i], &hits[i], &su);
            side = v3_dot(rays[i].d, su.ng) < 0 ? 1.0 : -1.0;
            rays[m].o = rtpi_offset_origin(su.p, su.ng, side, floor);
            rays[m].d = v3_sub(light, rays[m].o);
            rays[m].tmin = 0;
            rays[m].tmax = 1; /* up to the light */
            m++;
        }
        t = 1e30;
        for (rep = 0; rep < REPS; rep++) {
            double t1 = now();
            nocc = 0;
            for (i = 0; i < m; i++)
                nocc += (size_t)rtpi_kd_occluded(kd, &rays[i], RTPI_NONE);
            t1 = now() - t1;
            t = t1 < t ? t1 : t;
        }
        printf("shadow bunny: %lu rays in %.3f s = %.2f Mrays/s (%.0f%% occluded)\n",
               (unsigned long)m, t, (double)m / t * 1e-6,
               100.0 * (double)nocc / (double)(m ? m : 1));
        CNT_REPORT();
    }

    for (i = 0; i < NRAND; i++) {
        rtpi_v3 d;
        do {
            d = v3(2 * rnd() - 1, 2 * rnd() - 1, 2 * rnd() - 1);
        } while (v3_dot(d, d) > 1 || v3_dot(d, d) < 1e-6);
        rays[i].o = v3(lo[0] + rnd() * (hi[0] - lo[0]), lo[1] + rnd() * (hi[1] - lo[1]),
                       lo[2] + rnd() * (hi[2] - lo[2]));
        rays[i].d = v3_norm(d);
        rays[i].tmin = 0;
        rays[i].tmax = HUGE_VAL;
    }
    t = 1e30;
    for (rep = 0; rep < REPS; rep++) {
        double t1 = now();
        nhit = 0;
        for (i = 0; i < NRAND; i++)
            nhit += (size_t)rtpi_kd_intersect(kd, &rays[i], &hits[i]);
        t1 = now() - t1;
        t = t1 < t ? t1 : t;
    }
    printf("random bunny: %lu rays in %.3f s = %.2f Mrays/s (%.0f%% hit)\n",
           (unsigned long)NRAND, t, (double)NRAND / t * 1e-6,
           100.0 * (double)nhit / NRAND);
    CNT_REPORT();
done:
    free(rays);
    free(hits);
    free(hit);
}

int main(int argc, char **argv)
{
    /* --bunny: the bunny alone; --big: the generated mesh alone. */
    int only_bunny = argc > 1 && strcmp(argv[1], "--bunny") == 0;
    int only_big = argc > 1 && strcmp(argv[1], "--big") == 0;
    const char *path = find_bunny();
    rtp_scene *s = NULL, *big;
    rtpi_kdtree *kd;
    rtp_error err;
    if (only_big) {
        /* the generated mesh alone */
    } else if (!path) {
        printf("skip: ../shared/scenes/meshes/stanford-bunny.obj absent\n");
    } else if (rtp_scene_load(path, NULL, &s, &err) != RTP_OK) {
        char buf[600];
        printf("skip: %s\n", rtp_error_format(&err, buf, sizeof buf));
    } else {
        rtpi_kd_destroy(timed_build(s, "bunny", 5, 2));
        kd = timed_build(s, "bunny", 5, 1);
        if (kd)
            rays_bunny(s, kd);
        rtpi_kd_destroy(kd);
        rtp_scene_destroy(s);
    }
    if (only_bunny)
        return 0;
    big = make_big(1000, 500);
    if (!big) {
        fprintf(stderr, "bench_kd: out of memory\n");
        return 1;
    }
    rtpi_kd_destroy(timed_build(big, "sphere-1M", 2, 2));
    rtpi_kd_destroy(timed_build(big, "sphere-1M", 1, 1));
    rtp_scene_destroy(big);
    return 0;
}
