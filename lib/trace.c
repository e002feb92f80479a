/* trace.c — the Whitted ray tracer.  For each pixel sample it records the
 * ray tree (hits, light visibility, reflected and refracted subtrees) and
 * then evaluates that tree by the shading steps (rtpi_sample_eval,
 * rtpi_combine): the image trace produces
 * is the evaluation of the trees it recorded. */
#include "internal.h"
#include "dircube.h"
#include "shadow.h"

#include <stdlib.h>
#include <time.h>

/* Per-sample tree size cap: past it no further secondary rays are spawned
   (depth 64 in a hall of mirrors and glass would otherwise grow 2^64);
   it also keeps subtree offsets within the node's 24 bits. */
#define MAX_NODES_PER_SAMPLE (1u << 20)

/* What trace_ray returns besides a node index. */
#define RTPI_CHILD_NONE (-1) /* nothing recorded (the node cap was hit) */
#define RTPI_CHILD_MISS (-2) /* the ray left the scene */
#define RTPI_CHILD_DROPPED (-3) /* cast, counted, not kept (weighs 0) */

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

/* A finished row's trees, kept until the image is done. */
typedef struct row_rec {
    rtpi_cnode *nodes;
    uint32_t *counts; /* nodes per sample */
    uint32_t *vis;
    size_t nnodes;
} row_rec;

typedef struct shared shared;

/* A light's plane and cone tests (rtpi_tri_planes, rtpi_round_cones):
   what a moved light's shadow rays through the kd-tree skip primitives
   by (rtpi_kd_occluder_planes), exact as theirs are. */
typedef struct rtpi_ray_tests {
    double *planes, *cones, scale;
} rtpi_ray_tests;

typedef struct worker {
    shared *sh;
    rtpi_cnode *nodes; /* the current row's trees, preorder per sample */
    size_t nn, cap, sample_base;
    uint32_t *vis;     /* visibility words when there are > 32 lights */
    size_t vis_cap;
    uint32_t *counts;  /* nodes per sample of the current row */
    float *terms;      /* shading terms of the current sample */
    size_t terms_cap;
    float *coeffs;     /* its linear coefficients */
    double *acc;
    counts n;
    int row;           /* the row being traced (shared's direct) */
    /* Re-tracing a sample whose old tree is kept above its edited
       materials (rtpi_retrace's keep): the old sample's nodes and their
       visibility words, NULL while tracing afresh */
    const rtpi_cnode *old;
    const uint32_t *old_vis;
    rtp_status status;
    char pad[64]; /* the workers lie side by side, each writing its counts
                     and nn for every ray: no cache line shared */
} worker;

struct shared {
    const rtp_scene *s;
    /* What the workers allocate with: the scene's allocator, behind a lock
       when a caller's own runs on several threads (rtp.h promises nothing
       of it: an arena or a counting wrapper was called from two threads
       at once); the library's own is malloc's and needs none. */
    const rtp_allocator *wa;
    const rtpi_kdtree *kd;
    camera cam;
    int spd, max_depth;
    double min_weight;
    double off_floor; /* rtpi_offset_floor of s */
    int prim_floor;   /* rtpi_offset_floor said: ask each hit's primitive */
    float *out;        /* nx*ny samples, RGB */
    /* Recording with several workers: finished rows go into the tree's
       arrays in row order, so each node is copied once, from its
       worker's row buffer (reused and cache-warm) to its final place, and
       fresh memory is touched once.  A row finished before its
       predecessors waits in rows[] until they are in (then its buffers
       are freed for the next such row to reuse). */
    row_rec *rows;     /* per row when recording, else NULL */
    /* Recording with one worker: its rows come in order, so it pushes
       its nodes straight into tnodes and tvis (its own buffers are
       those while it traces a row) and nothing is copied: the copy was
       most of what recording mount_s6 added in user time at 1024x1024
       (perf: memmove and append_row 7.4 ms of a 0.86 s trace) and 16 of
       its 17.5 M instructions over the trace at 512x512 SPD. */
    int direct;
    unsigned char *stashed; /* row y waits in rows[y] */
    int next_row;      /* the next row to go in */
    rtpi_cnode *tnodes;/* the tree's nodes so far, tn of them */
    size_t tn, tcap;
    uint32_t *tvis;    /* their visibility words (> 32 lights), tcap a node */
    uint64_t *tstart;  /* gx*gy + 1 sample starts */
    rtpi_mutex lock;   /* guards the above and room */
    /* Recording and re-tracing: bytes the nodes may still take under the
       caller's memory limit.  Workers take from it when their buffers
       grow and when a row's nodes are copied into the tree or kept
       waiting, so a scene whose trees would outgrow the machine (glass in
       a mirrored room at depth 30: each sample up to 2^20 nodes) stops
       with RTP_ERR_LIMIT instead of being killed for memory. */
    double room;
    int limited;       /* room applies */
    rtpi_shade_ctx shade;
    double *cl;        /* light colours as shading sees them */
    /* Per light, the tests by which shadow rays through the kd-tree pass
       over primitives they cannot meet (trace_tests); NULL for a light
       without them (re-traces, lights past the budget) */
    rtpi_ray_tests *tests;
    int gx, gy;        /* samples traced: the region's grid */
    int ox, oy;        /* its first sample in the frame's grid */
    /* Re-tracing (rtpi_retrace's keep): per material, 1 where the rays
       below its hits are traced afresh; the old trees, their starts and
       visibility words.  NULL: every sample traced whole. */
    const unsigned char *redo;
    const rtpi_cnode *old_nodes;
    const uint64_t *old_start;
    const uint32_t *old_vis;
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

/* Bytes a node takes with its visibility words. */
static double node_bytes(const shared *sh)
{
    return (double)sizeof(rtpi_cnode) + (double)sh->shade.vis_words * sizeof(uint32_t);
}

/* Takes bytes from the room the trees have; 0, or 1 with w->status set
   to RTP_ERR_LIMIT.  The caller must not hold sh->lock. */
static int take_room(worker *w, double bytes)
{
    shared *sh = w->sh;
    int ok;
    if (!sh->limited)
        return 0;
    rtpi_mutex_lock(&sh->lock);
    ok = bytes <= sh->room;
    if (ok)
        sh->room -= bytes;
    rtpi_mutex_unlock(&sh->lock);
    if (!ok)
        w->status = RTP_ERR_LIMIT;
    return !ok;
}

static rtp_status grow_tree(shared *sh, int y, size_t need);

/* Makes room in the worker's buffers for node w->nn: the tree's arrays
   grown when the worker writes into them (shared's direct), else its own
   buffers.  0, or 1 with w->status set. */
static int push_room(worker *w)
{
    size_t words = w->sh->shade.vis_words;
    if (w->sh->direct) {
        /* (one node more than pushed, as append_row grows them: a tree's
           nodes are never NULL) */
        rtp_status st = grow_tree(w->sh, w->row, w->nn + 2);
        if (st != RTP_OK) {
            w->status = st;
            return 1;
        }
        w->nodes = w->sh->tnodes;
        w->vis = w->sh->tvis;
        w->cap = w->sh->tcap;
        w->vis_cap = w->sh->tcap * words;
        return 0;
    }
    /* (the room counts what the buffers grow to: rtpi_grow_cap's) */
    if (w->nn + 1 > w->cap &&
        take_room(w, (double)(rtpi_grow_cap(w->cap, w->nn + 1) - w->cap) * sizeof *w->nodes))
        return 1;
    if (words && (w->nn + 1) * words > w->vis_cap &&
        take_room(w, (double)(rtpi_grow_cap(w->vis_cap, (w->nn + 1) * words) - w->vis_cap) *
                         sizeof *w->vis))
        return 1;
    if (rtpi_grow(w->sh->wa, (void **)&w->nodes, &w->cap, w->nn + 1,
                  sizeof *w->nodes)) {
        w->status = RTP_ERR_NOMEM;
        return 1;
    }
    if (words && rtpi_grow(w->sh->wa, (void **)&w->vis, &w->vis_cap,
                           (w->nn + 1) * words, sizeof *w->vis)) {
        w->status = RTP_ERR_NOMEM;
        return 1;
    }
    return 0;
}

/* Appends a node to the current sample; returns its index within the
   sample, or -1.  (The buffers are grown out of line, only when full:
   rtpi_grow called for every node had cost 10.9 M instructions of
   mount_s6's 2909 M trace at 512x512 SPD, callgrind.) */
static int32_t push_node(worker *w)
{
    size_t words = w->sh->shade.vis_words;
    if (w->status != RTP_OK)
        return -1;
    if (w->nn - w->sample_base >= MAX_NODES_PER_SAMPLE) {
        w->n.capped++;
        return -1;
    }
    if ((w->nn + 1 + (size_t)w->sh->direct > w->cap ||
         (words && (w->nn + 1) * words > w->vis_cap)) &&
        push_room(w))
        return -1;
    if (words)
        memset(w->vis + w->nn * words, 0, words * sizeof *w->vis);
    return (int32_t)(w->nn++ - w->sample_base);
}

/* Tracing recurses a level a ray of the tree: trace_ray and spawn take
   about 0.9 KiB of stack a level at -O2 (gcc -fstack-usage), more at -O0
   or under a sanitizer.  Up to RTPI_CALLER_DEPTH levels the calling
   thread's stack is used (a host thread has 128 KiB on musl, 512 KiB on
   macOS); deeper trees, up to RTP_MAX_DEPTH's 1000 (about 1 MiB), run on
   threads of rtp's own with 4 KiB a level and 256 KiB to spare. */
#define RTPI_CALLER_DEPTH 32

size_t rtpi_trace_stack(int max_depth)
{
    return max_depth > RTPI_CALLER_DEPTH ? ((size_t)256 << 10) + ((size_t)max_depth << 12) : 0;
}

/* A ray traced afresh, and one replayed from node old of the sample's
   old tree (trace_ray below): two copies of one body, so that a trace,
   which never replays, carries none of the replay's tests (one body for
   both had made mount_s6's trace 0.8% dearer: 2991.1 -> 3016.8 M
   instructions, `rtp trace --spd -j1` under callgrind). */
static int32_t trace_fresh(worker *w, const rtpi_ray *ray, int depth, double weight);
static int32_t trace_old(worker *w, const rtpi_ray *ray, int depth, double weight,
                         int32_t old);

/* d mirrored about the shading normal nb; where a bumped
   normal would send it through the surface (on the incoming ray's side
   of the geometric normal ng: it would go on into the surface), its ng
   part mirrored, so a reflection never sees what lies behind an opaque
   surface (a floor with the README's waves 0.5 showed a plane 1 below
   it in 36% of its pixels).  Only where a bump bent the normal:
   interpolated normals (pp) bend mildly, and the images of such scenes
   stay as they were. */
static rtpi_v3 reflect_dir(rtpi_v3 d, rtpi_v3 nb, rtpi_v3 ng, int bumped)
{
    rtpi_v3 r = v3_madd(d, nb, -2.0 * v3_dot(d, nb));
    double rn = v3_dot(r, ng), dn = v3_dot(d, ng);
    if (bumped && (rn < 0.0) == (dn < 0.0) && rn != 0.0)
        r = v3_madd(r, ng, -2.0 * rn);
    return v3_norm(r);
}

/* Traces a secondary ray from p in unit direction dir (old: see
   trace_ray; RTPI_CHILD_MISS: the old tree says it leaves the scene). */
static RTPI_FORCE_INLINE int32_t spawn(worker *w, rtpi_v3 p, rtpi_v3 ng, rtpi_v3 dir,
                                       int depth, double weight, double floor, int32_t old)
{
    rtpi_ray r;
    if (old == RTPI_CHILD_MISS)
        return RTPI_CHILD_MISS;
    r.o = rtpi_offset_origin(p, ng, v3_dot(ng, dir) >= 0.0 ? 1.0 : -1.0, floor);
    r.d = dir;
    r.tmin = 0.0;
    r.tmax = HUGE_VAL;
    return old >= 0 ? trace_old(w, &r, depth, weight, old) : trace_fresh(w, &r, depth, weight);
}

/* The old child a replayed node's child ray reaches: its index, a miss,
   or -1 (trace it) where the old node has none (capped, or not cast) or
   its material's subtrees are what is traced again. */
static RTPI_FORCE_INLINE int32_t old_child(const worker *w, int32_t old, int redo,
                                           uint32_t node_flag, uint32_t miss_flag, uint32_t off)
{
    uint32_t link;
    if (old < 0 || redo)
        return -1;
    link = w->old[old].link;
    return (link & node_flag) ? old + (int32_t)off
           : (link & miss_flag) ? RTPI_CHILD_MISS : -1;
}

/* Link flags for a child: traced subtree, miss, or nothing (capped). */
static uint32_t child_flags(int32_t child, uint32_t node_flag,
                            uint32_t miss_flag)
{
    return child >= 0 ? node_flag : child == RTPI_CHILD_MISS ? miss_flag : 0u;
}

/* old >= 0: the ray is the one that reached node `old` of the sample's
   old tree (w->old), whose hit and light bits are taken as they are (the
   same ray hits the same point and sees the same lights: rtpi_retrace's
   keep); its children are decided as ever and replayed likewise where
   the old tree holds them and its material is not traced again. */
static RTPI_FORCE_INLINE int32_t trace_ray(worker *w, const rtpi_ray *ray, int depth,
                                           double weight, int32_t old)
{
    const shared *sh = w->sh;
    const rtp_scene *s = sh->s;
    const rtpi_material *m;
    rtpi_hit hit;
    rtpi_surface sf;
    rtpi_v3 d = ray->d, ng, ns, nb;
    int32_t idx, refl = RTPI_CHILD_NONE;
    double eta = 1.0, cosi = 0.0, k = 0.0;
    int refracts = 0;
    uint32_t link = 0, vis = 0;
    int front, bent, redo = 0;
    double pfloor;
    size_t i, nl = s->nlights, words = sh->shade.vis_words;

    if (old >= 0)
        hit.prim = w->old[old].prim;
    else if (!rtpi_kd_intersect(sh->kd, ray, &hit))
        return RTPI_CHILD_MISS;
    idx = push_node(w);
    if (idx < 0)
        return RTPI_CHILD_NONE;
    {
        /* Everything below starts from the float position the tree keeps,
           with the surface derived from it exactly as shading derives it,
           so a re-evaluation that casts rays again casts these very rays. */
        const rtpi_material *hm = &s->mats[rtpi_prim_material(s, hit.prim)];
        float pf[3];
        if (old >= 0) {
            memcpy(pf, w->old[old].p, sizeof pf);
        } else {
            rtpi_v3 pe = v3_madd(ray->o, ray->d, hit.t);
            pf[0] = (float)pe.x;
            pf[1] = (float)pe.y;
            pf[2] = (float)pe.z;
        }
        rtpi_surface_from_point(s, hit.prim, pf, hm->bump == RTPI_BUMP_IMAGE, &sf);
    }
    m = &s->mats[sf.mat];
    pfloor = sh->prim_floor ? rtpi_prim_offset_floor(s, hit.prim, sh->off_floor) : sh->off_floor;
    ng = sf.ng;
    ns = sf.ns;
    /* Bumps bend the reflected and refracted rays; shadow rays follow the
       unbumped surface, so the recorded visibility holds for any bump a
       re-evaluation may set. */
    nb = m->bump == RTPI_BUMP_NONE ? ns : rtpi_bump_normal(s, m, hit.prim, sf.p, sf.uv, ns);
    /* (bent: the bump changed the normal here.  A bump that bends nothing
       — strength 0, an image on a primitive without uvs — leaves it as
       it was, bit for bit, and the rays as without a bump, which is what
       the trees keep when such a bump is set: bump_bends) */
    bent = nb.x != ns.x || nb.y != ns.y || nb.z != ns.z;
    front = v3_dot(d, ng) < 0.0;
    if (!front)
        link |= RTPI_L_BACK;
    if (!front && rtpi_two_sided(s, sh->spd, hit.prim, m)) {
        ng = v3_mul(ng, -1.0);
        ns = v3_mul(ns, -1.0);
        nb = v3_mul(nb, -1.0);
    }

    /* (SPD's opaque surfaces are one-sided, kt > 0 ones two-sided: a hit
       from behind of a material whose kt went from or to 0 (redo 3) faces
       the lights otherwise than when it was traced, so it casts its
       shadow rays anew; a replayed hit had kept the old one's light
       bits: a one-sided square seen from behind, lit from the eye's side,
       given kt 0.5 stayed dark, 23% of an SPD image's pixels off a full
       trace) */
    if (old >= 0)
        redo = sh->redo[sf.mat];
    if (old >= 0 && !(redo == 3 && !front)) {
        vis = w->old[old].vis;
        if (words)
            memcpy(w->vis + (w->sample_base + (size_t)idx) * words, w->old_vis + (size_t)old * words,
                   words * sizeof *w->vis);
        nl = 0; /* (the old node's light bits) */
    }
    /* Shadows: no ray where the surface faces away from the light. */
    for (i = 0; i < nl; i++) {
        const rtpi_light *L = &s->lights[i];
        rtpi_v3 lp = v3(L->pos[0], L->pos[1], L->pos[2]), o;
        rtpi_ray sr;
        if (!rtpi_shadow_setup(sf.p, ng, ns, lp, pfloor, &o))
            continue;
        sr = rtpi_shadow_ray(o, lp);
        w->n.shadow_rays++;
        /* (the hit's own primitive left out where it cannot be in the way:
           one test fewer a ray, the same answer) */
        {
            uint32_t skip = rtpi_prim_shadows_own(s, hit.prim, o, lp) == 0 ? hit.prim : RTPI_NONE;
            const rtpi_ray_tests *rt = sh->tests ? &sh->tests[i] : NULL;
            if (rt && (rt->planes || rt->cones)
                    ? rtpi_kd_occluder_planes(sh->kd, &sr, skip, rt->planes, NULL,
                                              rt->cones, rt->scale) != RTPI_NONE
                    : rtpi_kd_occluded(sh->kd, &sr, skip))
                continue;
        }
        if (words)
            w->vis[(w->sample_base + (size_t)idx) * words + (i >> 5)] |= 1u << (i & 31);
        else
            vis |= 1u << i;
    }

    /* (refraction's terms first: whether the ray is reflected totally
       decides below what a reflected subtree is kept for) */
    if (depth < sh->max_depth && m->kt > 0.0f && weight * m->kt >= sh->min_weight) {
        double ior = m->ior > 0.0f ? m->ior : 1.0;
        eta = front ? 1.0 / ior : ior;
        cosi = -v3_dot(d, nb);
        k = 1.0 - eta * eta * (1.0 - cosi * cosi);
        refracts = 1;
    }
    /* SPD: transmitting surfaces spawn reflection rays too, even with
       ks 0 (SPD's statistics count them).  Where ks is 0 and the ray is
       not reflected totally, its subtree weighs 0 in every evaluation
       (ks from 0 traces the samples again: edit class D), so it is cast
       and counted but not kept: 40% of gears' nodes were such, every
       edit and move paying for them. */
    if (depth < sh->max_depth &&
        ((m->ks > 0.0f && weight * m->ks >= sh->min_weight) ||
         (sh->spd && m->kt > 0.0f))) {
        rtpi_v3 r = reflect_dir(d, nb, ng, bent);
        size_t nn = w->nn;
        int32_t oc = old_child(w, old, redo, RTPI_L_REFL, RTPI_L_REFL_MISS, 1);
        int keep = m->ks > 0.0f || (refracts && k < 0.0);
        /* (replayed: a reflection not kept is not cast, nor one the old
           tree says leaves the scene) */
        if (oc == -1 && (old < 0 || keep)) {
            w->n.reflected_rays++;
            refl = spawn(w, sf.p, ng, r, depth + 1, weight * m->ks, pfloor, -1);
        } else {
            refl = keep ? spawn(w, sf.p, ng, r, depth + 1, weight * m->ks, pfloor, oc)
                        : RTPI_CHILD_MISS;
        }
        if (keep) {
            link |= child_flags(refl, RTPI_L_REFL, RTPI_L_REFL_MISS);
        } else {
            /* (a subtree's nodes are the last pushed; push_node clears
               the visibility words of those it hands out again) */
            w->nn = nn;
            refl = RTPI_CHILD_DROPPED;
        }
    }
    if (refracts) {
        if (k < 0.0) {
            /* Total internal reflection: the transmitted share follows
               the reflected ray; trace it if ks did not already. */
            if (refl == RTPI_CHILD_NONE) {
                rtpi_v3 r = reflect_dir(d, nb, ng, bent);
                int32_t oc = old_child(w, old, redo, RTPI_L_REFL, RTPI_L_REFL_MISS, 1);
                if (oc == -1)
                    w->n.reflected_rays++;
                refl = spawn(w, sf.p, ng, r, depth + 1, weight * m->kt, pfloor, oc);
                link |= child_flags(refl, RTPI_L_REFL, RTPI_L_REFL_MISS);
            }
            link |= RTPI_L_TIR;
        } else {
            rtpi_v3 t = v3_norm(v3_add(v3_mul(d, eta),
                                       v3_mul(nb, eta * cosi - sqrt(k))));
            int32_t refr,
                oc = old_child(w, old, redo, RTPI_L_REFR, RTPI_L_REFR_MISS,
                               old >= 0 ? w->old[old].link >> RTPI_L_SHIFT : 0);
            if (oc == -1)
                w->n.refracted_rays++;
            refr = spawn(w, sf.p, ng, t, depth + 1, weight * m->kt, pfloor, oc);
            link |= child_flags(refr, RTPI_L_REFR, RTPI_L_REFR_MISS);
            if (refr >= 0)
                link |= (uint32_t)(refr - idx) << RTPI_L_SHIFT;
        }
    }
    {
        rtpi_cnode *nd = &w->nodes[w->sample_base + (size_t)idx];
        nd->p[0] = (float)sf.p.x;
        nd->p[1] = (float)sf.p.y;
        nd->p[2] = (float)sf.p.z;
        nd->prim = hit.prim;
        nd->vis = vis;
        nd->link = link;
    }
    return idx;
}

static int32_t trace_fresh(worker *w, const rtpi_ray *ray, int depth, double weight)
{
    return trace_ray(w, ray, depth, weight, -1);
}

static int32_t trace_old(worker *w, const rtpi_ray *ray, int depth, double weight, int32_t old)
{
    return trace_ray(w, ray, depth, weight, old);
}

/* Traces sample (x, y) of the camera grid and records its tree at the end
   of the worker's nodes; returns how many nodes it has. */
static size_t record_sample(worker *w, int x, int y)
{
    const camera *c = &w->sh->cam;
    rtpi_ray ray;
    rtpi_v3 d;
    double len;
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
    w->sample_base = w->nn;
    if (!w->old)
        w->n.eye_rays++;
    if ((w->old ? trace_old(w, &ray, 1, 1.0, 0) : trace_fresh(w, &ray, 1, 1.0)) >= 0)
        w->n.eye_hits++;
    return w->nn - w->sample_base;
}

static void trace_sample(worker *w, int x, int y, float *rgb)
{
    const camera *c = &w->sh->cam;
    size_t words = w->sh->shade.vis_words;
    w->counts[x] = (uint32_t)record_sample(w, w->sh->ox + x, w->sh->oy + y);
    /* The sample's colour is the evaluation of the tree just recorded,
       by the steps re-evaluation takes. */
    {
        const rtp_scene *s = w->sh->s;
        size_t n = w->nn - w->sample_base, nt = RTPI_TERMS(s->nlights);
        /* (a sample of 2^20 nodes takes 4 (3 + 2 lights) MiB of these) */
        if (n * nt + 1 > w->terms_cap &&
            take_room(w, (double)(rtpi_grow_cap(w->terms_cap, n * nt + 1) - w->terms_cap) *
                             sizeof *w->terms))
            return;
        if (rtpi_grow(w->sh->wa, (void **)&w->terms, &w->terms_cap, n * nt + 1,
                      sizeof *w->terms)) {
            w->status = RTP_ERR_NOMEM;
            return;
        }
        /* (no NULL + 0 when nothing was hit yet) */
        const rtpi_cnode *nodes = n ? w->nodes + w->sample_base : NULL;
        rtpi_sample_eval(&w->sh->shade, nodes, n,
                         words && n ? w->vis + w->sample_base * words : NULL, c->from, w->terms,
                         NULL, w->acc, w->coeffs, NULL);
        rtpi_combine(s, w->sh->cl, w->coeffs, rgb);
    }
    if (!w->sh->rows)
        w->nn = 0; /* not recording: only the current sample is kept */
}

/* Keeps the worker's current nodes (nsamples samples' trees) in r, at
   their exact size; 0, or 1 with w->status set. */
static int keep_row(worker *w, row_rec *r, size_t nsamples)
{
    const rtp_allocator *a = w->sh->wa;
    size_t words = w->sh->shade.vis_words;
    r->nnodes = w->nn;
    r->nodes = (rtpi_cnode *)rtpi_malloc_array(a, w->nn + 1, sizeof *r->nodes);
    r->counts = (uint32_t *)rtpi_malloc_array(a, nsamples + 1, sizeof *r->counts);
    r->vis = words ? (uint32_t *)rtpi_malloc_array(a, w->nn * words + 1, sizeof *r->vis)
                   : NULL;
    if (!r->nodes || !r->counts || (words && !r->vis)) {
        w->status = RTP_ERR_NOMEM;
        return 1;
    }
    if (w->nn) /* (memcpy from a NULL buffer is undefined even for 0) */
        memcpy(r->nodes, w->nodes, w->nn * sizeof *r->nodes);
    memcpy(r->counts, w->counts, nsamples * sizeof *r->counts);
    if (words && w->nn)
        memcpy(r->vis, w->vis, w->nn * words * sizeof *r->vis);
    return 0;
}

/* Bytes a row kept waiting takes (keep_row's blocks). */
static double row_bytes(const shared *sh, size_t nn)
{
    return (double)(nn + 1) * node_bytes(sh) + (double)(sh->gx + 1) * sizeof(uint32_t);
}

/* Appends row y's trees (nn nodes, per[x] of sample x) to the tree's
   arrays; the caller holds sh->lock.  RTP_OK, RTP_ERR_NOMEM, or
   RTP_ERR_LIMIT when the arrays cannot grow within the room. */
static rtp_status append_row(shared *sh, int y, const rtpi_cnode *nodes, const uint32_t *vis,
                             const uint32_t *per, size_t nn)
{
    size_t words = sh->shade.vis_words, k = (size_t)y * sh->gx, at = sh->tn;
    int x;
    if (sh->tn + nn + 1 > sh->tcap) {
        rtp_status st = grow_tree(sh, y, sh->tn + nn + 1);
        if (st != RTP_OK)
            return st;
    }
    if (nn) /* (memcpy from a NULL buffer is undefined even for 0) */
        memcpy(sh->tnodes + sh->tn, nodes, nn * sizeof *nodes);
    if (words && nn)
        memcpy(sh->tvis + sh->tn * words, vis, nn * words * sizeof *vis);
    for (x = 0; x < sh->gx; x++) {
        sh->tstart[k + (size_t)x] = at;
        at += per[x];
    }
    sh->tn = at;
    return RTP_OK;
}

/* Grows the tree's arrays to hold need > tcap nodes, row y being the
   last in them (append_row's, or the direct worker's row so far); the
   caller holds sh->lock or is the one worker.  RTP_OK, RTP_ERR_NOMEM, or
   RTP_ERR_LIMIT when the arrays cannot grow within the room. */
static rtp_status grow_tree(shared *sh, int y, size_t need)
{
    const rtp_allocator *a = sh->wa;
    size_t words = sh->shade.vis_words;
    size_t est = need / ((size_t)y + 1) * (size_t)sh->gy;
    void *p;
    /* Room for the rows to come at the rate so far, an eighth more:
       doubling from small copied the nodes, tens of megabytes, many
       times over and touched twice the pages (mount_s6 at
       1024x1024: 27,000 page faults, then 14,500).  With the default
       allocator a block past 1 MiB grows by moving its pages
       (util.c), so this mostly saves a user's allocator the copies.
       The arrays take from the room what they grow by (grown to
       exactly est, not to a power of two, so that they hold no more
       than the limit lets them): near the limit at most half of what
       is left, so that workers still have room for their rows. */
    est += est / 8;
    if (est < need)
        est = need;
    if (sh->limited) {
        double nb = node_bytes(sh), fits = sh->room / nb;
        if ((double)(need - sh->tcap) > fits)
            return RTP_ERR_LIMIT;
        if ((double)(est - sh->tcap) > fits) {
            double half = 0.5 * fits;
            est = (double)(need - sh->tcap) > half ? need : sh->tcap + (size_t)half;
        }
        sh->room -= (double)(est - sh->tcap) * nb;
    }
    if (est > (size_t)-1 / sizeof *sh->tnodes ||
        !(p = rtpi_realloc(a, sh->tnodes, est * sizeof *sh->tnodes)))
        return RTP_ERR_NOMEM;
    sh->tnodes = (rtpi_cnode *)p;
    if (words) {
        if (est > (size_t)-1 / (words * sizeof *sh->tvis) ||
            !(p = rtpi_realloc(a, sh->tvis, est * words * sizeof *sh->tvis)))
            return RTP_ERR_NOMEM;
        sh->tvis = (uint32_t *)p;
    }
    sh->tcap = est;
    return RTP_OK;
}

/* Puts the worker's finished row y into the tree, with every waiting row
   after it, or makes it wait (a copy, which takes its bytes from the
   room until it goes in).  0, or 1 with w->status set. */
static int commit_row(worker *w, int y)
{
    shared *sh = w->sh;
    const rtp_allocator *a = sh->wa;
    rtp_status st = RTP_OK;
    rtpi_mutex_lock(&sh->lock);
    if (y != sh->next_row) {
        double bytes = row_bytes(sh, w->nn);
        if (sh->limited && bytes > sh->room) {
            st = RTP_ERR_LIMIT;
        } else {
            if (sh->limited)
                sh->room -= bytes;
            if (keep_row(w, &sh->rows[y], (size_t)sh->gx))
                st = RTP_ERR_NOMEM;
            else
                sh->stashed[y] = 1;
        }
    } else {
        st = append_row(sh, y, w->nodes, w->vis, w->counts, w->nn);
        if (st == RTP_OK)
            sh->next_row++;
        while (st == RTP_OK && sh->next_row < sh->gy && sh->stashed[sh->next_row]) {
            row_rec *r = &sh->rows[sh->next_row];
            st = append_row(sh, sh->next_row, r->nodes, r->vis, r->counts, r->nnodes);
            if (st != RTP_OK)
                break;
            if (sh->limited)
                sh->room += row_bytes(sh, r->nnodes);
            rtpi_free(a, r->nodes);
            rtpi_free(a, r->counts);
            rtpi_free(a, r->vis);
            memset(r, 0, sizeof *r);
            sh->stashed[sh->next_row++] = 0;
        }
    }
    rtpi_mutex_unlock(&sh->lock);
    if (st != RTP_OK)
        w->status = st;
    return st != RTP_OK;
}

/* Row y traced by the one worker of a recording (shared's direct) goes
   straight into the tree's arrays: the worker's buffers are those while
   it traces the row (row_begin), and the row's starts are set after
   (row_end).  0, or 1 with w->status set. */
static int row_begin(worker *w, int y)
{
    shared *sh = w->sh;
    /* (rows come to one worker in order: rtpi_parallel_rows) */
    if (y != sh->next_row) {
        w->status = RTP_ERR_ARGUMENT;
        return 1;
    }
    w->row = y;
    w->nodes = sh->tnodes;
    w->vis = sh->tvis;
    w->nn = sh->tn;
    w->cap = sh->tcap;
    w->vis_cap = sh->tcap * sh->shade.vis_words;
    return 0;
}

static int row_end(worker *w, int y)
{
    shared *sh = w->sh;
    size_t k = (size_t)y * sh->gx, at = sh->tn;
    int x;
    /* (the arrays are the tree's again: freed once, as sh's) */
    w->nodes = NULL;
    w->vis = NULL;
    w->cap = w->vis_cap = 0;
    if (w->status == RTP_OK && sh->tn + 1 > sh->tcap) /* (rows of no nodes) */
        w->status = grow_tree(sh, y, sh->tn + 1);
    if (w->status != RTP_OK)
        return 1;
    for (x = 0; x < sh->gx; x++) {
        sh->tstart[k + (size_t)x] = at;
        at += w->counts[x];
    }
    sh->tn = at;
    sh->next_row++;
    return 0;
}

static int trace_row(void *ctx, int y)
{
    worker *w = (worker *)ctx;
    shared *sh = w->sh;
    int x;
    if (w->status != RTP_OK)
        return 1;
    if (sh->direct) {
        if (row_begin(w, y))
            return 1;
    } else {
        w->nn = 0;
    }
    for (x = 0; x < sh->gx; x++)
        trace_sample(w, x, y, sh->out + 3 * ((size_t)y * sh->gx + x));
    if (sh->direct)
        return row_end(w, y);
    if (w->status != RTP_OK)
        return 1;
    if (sh->rows)
        return commit_row(w, y);
    return 0;
}

void rtpi_resolve_samples(const float *samples, int spd, rtp_image *img)
{
    int w = img->width, h = img->height, x, y;
    if (!spd) {
        memcpy(img->pixels, samples, sizeof(float) * 3 * (size_t)w * h);
        return;
    }
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            rtpi_resolve_pixel(samples, img, x, y);
}

/* Moves the rows' trees into one tree object. */
static rtp_status gather_tree(shared *sh, int w, int h, rtp_tree **out,
                              rtp_error *err)
{
    const rtp_scene *s = sh->s;
    const rtp_allocator *a = &s->alloc;
    rtp_tree *t;
    size_t total = sh->tn, words = sh->shade.vis_words, k;
    void *p;
    t = (rtp_tree *)rtpi_calloc_array(a, 1, sizeof *t);
    if (!t)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    t->alloc = *a;
    t->width = w;
    t->height = h;
    t->nx = sh->gx;
    t->ny = sh->gy;
    t->full_w = sh->cam.nx - sh->spd;
    t->full_h = sh->cam.ny - sh->spd;
    t->rx = sh->ox;
    t->ry = sh->oy;
    t->spd = sh->spd;
    t->max_depth = sh->max_depth;
    t->min_weight = sh->min_weight;
    t->vis_words = words;
    t->nnodes = total;
    t->nlights0 = s->nlights;
    t->cam0 = s->camera;
    /* the arrays the rows went into, at their exact size */
    sh->tstart[(size_t)sh->gx * sh->gy] = total;
    if (sh->tcap > total + 1 && (p = rtpi_realloc(a, sh->tnodes, (total + 1) * sizeof *t->nodes)))
        sh->tnodes = (rtpi_cnode *)p;
    t->nodes = sh->tnodes;
    t->start = sh->tstart;
    t->vis_ext = sh->tvis;
    sh->tnodes = NULL;
    sh->tstart = NULL;
    sh->tvis = NULL;
    if (rtpi_scene_clone(s, &t->scene) != RTP_OK ||
        !(t->mats0 = (rtpi_material *)rtpi_malloc_array(a, s->nmats ? s->nmats : 1,
                                                         sizeof *t->mats0)) ||
        !(t->lights0 = (rtpi_light *)rtpi_malloc_array(a, s->nlights ? s->nlights : 1,
                                                        sizeof *t->lights0))) {
        rtp_tree_destroy(t);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory keeping ray trees");
    }
    if (s->nmats)
        memcpy(t->mats0, s->mats, s->nmats * sizeof *t->mats0);
    if (s->nlights)
        memcpy(t->lights0, s->lights, s->nlights * sizeof *t->lights0);
    for (k = 0; k < s->nmats; k++)
        t->mats0[k].name = NULL;
    for (k = 0; k < s->nlights; k++)
        t->lights0[k].name = NULL;
    *out = t;
    return RTP_OK;
}

/* The error a worker's status stands for: over the memory limit (the
   remedy given, said in parentheses: none of its own, "(raise
   memory_limit (rtp's --memory-limit))" had nested them), or out of
   memory, while doing what. */
static rtp_status worker_error(rtp_status st, double limit, const char *what,
                               const char *remedy, rtp_error *err)
{
    if (st == RTP_ERR_LIMIT) {
        char g[32]; /* '.' whatever the locale */
        rtpi_fmt_g(g, sizeof g, 6, limit / 1048576.0);
        return rtpi_error(err, st, NULL, 0, 0,
                          "the ray trees grew past the memory limit of %s MiB while %s (%s)", g,
                          what, remedy);
    }
    return rtpi_error(err, st, NULL, 0, 0, "out of memory while %s", what);
}

/* sized: opt's width and height are the frame even with spd (a
   builder's tree of corner samples, traced again by rtp_tree_trace);
   otherwise spd is SPD's 512x512 whatever they say, as rtp.h has it. */
rtp_status rtpi_cancelled(rtp_error *err)
{
    return rtpi_error(err, RTP_ERR_CANCELLED, NULL, 0, 0, "cancelled by the caller");
}

/* Bytes the lights' plane and cone tests may take in all: 32 a triangle,
   sphere or cone a light (the Stanford bunny, 69k triangles: 2.2 MB a
   light).  Lights past it go without; a million triangles under 8 lights
   would otherwise hold 256 MB for a trace a few percent faster. */
#define TRACE_TESTS_BYTES (64.0 * 1024.0 * 1024.0)

/* sh->tests for the trace of `samples` samples of s: each light's tests
   while they fit TRACE_TESTS_BYTES, where there are at least as many
   samples as primitives (making a primitive's tests costs about what
   they save a shadow ray: rtp_trace --spd, callgrind, balls_s4 -12%,
   tree_s11 -10%, teapot_s12 -2.3%, mount_s6 -1.7%; a small image of a
   large mesh would pay more than it saves).  RTP_OK, or RTP_ERR_NOMEM. */
static rtp_status trace_tests(shared *sh, const rtp_scene *s, double samples, rtp_error *err)
{
    size_t i, np = rtpi_scene_nprims(s);
    double each = 32.0 * (double)np, used = 0.0;
    if (!s->nlights || !np || samples < (double)np || each > TRACE_TESTS_BYTES)
        return RTP_OK; /* (none at all: plain shadow rays) */
    sh->tests = (rtpi_ray_tests *)rtpi_calloc_array(&s->alloc, s->nlights, sizeof *sh->tests);
    if (!sh->tests)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (i = 0; i < s->nlights && used + each <= TRACE_TESTS_BYTES; i++, used += each) {
        rtpi_ray_tests *rt = &sh->tests[i];
        const double *pos = s->lights[i].pos;
        rtpi_v3 lp = v3(pos[0], pos[1], pos[2]); /* (trace_ray's light) */
        rtp_status st = rtpi_tri_planes(s, lp, &s->alloc, &rt->planes, &rt->scale, err);
        if (st == RTP_OK)
            st = rtpi_round_cones(s, lp, rt->scale, rtpi_kd_far(sh->kd, lp), &s->alloc,
                                  &rt->cones, err);
        if (st != RTP_OK)
            return st;
    }
    return RTP_OK;
}

static void trace_tests_free(shared *sh, const rtp_scene *s)
{
    size_t i;
    for (i = 0; sh->tests && i < s->nlights; i++) {
        rtpi_free(&s->alloc, sh->tests[i].planes);
        rtpi_free(&s->alloc, sh->tests[i].cones);
    }
    rtpi_free(&s->alloc, sh->tests);
    sh->tests = NULL;
}

static rtp_status trace_impl(const rtp_scene *s, const rtp_trace_options *opt_in, int sized,
                             rtp_tree **tree_out, rtp_image **out,
                             rtp_trace_stats *stats, rtp_error *err)
{
    rtp_trace_options opt;
    shared sh;
    worker *ws = NULL;
    void *ctx[RTPI_MAX_THREADS];
    rtpi_kdtree *kd = NULL;
    rtp_image *img = NULL;
    float *samples = NULL;
    rtp_status st;
    int w, h, fw, fh, rg[4], nthreads, i, lock_made = 0, la_made = 0;
    rtpi_locked_alloc la;
    double t0, t1, t2, limit;
    rtpi_kd_stats ks;

    if (out)
        *out = NULL;
    if (tree_out)
        *tree_out = NULL;
    if (!s || (!out && !tree_out))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: NULL argument",
                          tree_out ? "rtp_record" : "rtp_trace");
    memset(&opt, 0, sizeof opt);
    if (opt_in)
        opt = *opt_in;
    /* (on or off: the sample grid is the image's plus spd, so any other
       value read past the samples or made a grid no reader takes) */
    opt.spd = opt.spd != 0;
    /* (memory_limit 0 is the default; a negative or NaN one had fallen
       back to it silently) */
    {
        const char *bad = opt.max_depth < 0           ? "max_depth"
                          : opt.width < 0              ? "width"
                          : opt.height < 0             ? "height"
                          : opt.threads < 0            ? "threads"
                          : !(opt.min_weight >= 0.0)   ? "min_weight"
                          : !(opt.memory_limit >= 0.0) ? "memory_limit"
                                                       : NULL;
        if (bad)
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              "%s: option %s is negative or not a number (0: the default)",
                              tree_out ? "rtp_record" : "rtp_trace", bad);
    }
    /* (the trace recurses along a ray tree's depth, and a tree file
       holds no deeper tree: 10,000 overflowed a thread's stack) */
    if (opt.max_depth > RTP_MAX_DEPTH)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: option max_depth %d over %d (RTP_MAX_DEPTH)",
                          tree_out ? "rtp_record" : "rtp_trace", opt.max_depth, RTP_MAX_DEPTH);
    if (rtpi_camera_problem(s))
        return rtpi_camera_error(s, NULL, "no view to trace", err);
    fw = opt.width > 0 ? opt.width : s->width;
    fh = opt.height > 0 ? opt.height : s->height;
    if (opt.spd && !sized)
        fw = fh = 512;
    rg[0] = opt.region[0];
    rg[1] = opt.region[1];
    rg[2] = opt.region[2];
    rg[3] = opt.region[3];
    if (!rg[0] && !rg[1] && !rg[2] && !rg[3]) {
        rg[2] = fw;
        rg[3] = fh;
    }
    if (rg[0] < 0 || rg[1] < 0 || rg[2] > fw || rg[3] > fh || rg[0] >= rg[2] ||
        rg[1] >= rg[3])
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "region %d,%d,%d,%d is not inside the %dx%d image", rg[0], rg[1],
                          rg[2], rg[3], fw, fh);
    w = rg[2] - rg[0];
    h = rg[3] - rg[1];
    nthreads = opt.threads > 1 ? opt.threads : 1;
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    limit = opt.memory_limit > 0.0 ? opt.memory_limit : RTPI_MEMORY_LIMIT;
    /* (the samples' grid: the image's, or SPD's 513x513) */
    if (!rtpi_image_size_ok(fw, fh) || !rtpi_image_size_ok(fw + opt.spd, fh + opt.spd))
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "image size %dx%d is over the limit (2^20 a side, 2^27 pixels)", fw,
                          fh);
    {
        /* What this trace will hold at least: the image, the samples and,
           when recording, one node per sample (most samples have one). */
        double need = (double)w * h * 12.0 + (double)(w + 1) * (h + 1) * 12.0 +
                      (tree_out ? (double)(w + 1) * (h + 1) * (24.0 + 8.0) : 0.0);
        if (!(need <= limit)) {
            char g[2][32]; /* '.' whatever the locale */
            rtpi_fmt_g(g[0], sizeof g[0], 3, need / 1048576.0);
            rtpi_fmt_g(g[1], sizeof g[1], 3, limit / 1048576.0);
            return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                              "a %dx%d %s needs at least %s MiB, over the memory limit of "
                              "%s MiB (raise memory_limit: rtp's --memory-limit)",
                              w, h, tree_out ? "traced image with its trees" : "traced image",
                              g[0], g[1]);
        }
    }
    st = rtp_image_create(w, h, &s->alloc, &img, err);
    if (st != RTP_OK)
        return st;

    memset(&sh, 0, sizeof sh);
    sh.s = s;
    sh.off_floor = rtpi_offset_floor(s, &sh.prim_floor);
    sh.wa = &s->alloc;
    if (nthreads > 1 && !rtpi_allocator_is_default(&s->alloc)) {
        if (rtpi_locked_alloc_init(&la, &s->alloc) == 0) {
            la_made = 1;
            sh.wa = &la.a;
        } else {
            nthreads = 1; /* (no lock: one thread needs none) */
        }
    }
    sh.spd = opt.spd;
    sh.max_depth = opt.max_depth > 0 ? opt.max_depth : 5;
    sh.min_weight = opt.spd ? 0.0 : opt.min_weight;
    sh.shade.s = s;
    sh.shade.one_sided = opt.spd;
    sh.shade.has_ka = rtpi_scene_has_ka(s);
    sh.shade.vis_words = s->nlights > 32 ? (s->nlights + 31) / 32 : 0;
    /* SPD: rays through the (w+1)x(h+1) pixel corners, averaged.  The
       camera spans the whole frame; a region traces its part of it. */
    camera_init(&sh.cam, s, fw + opt.spd, fh + opt.spd);
    sh.gx = w + opt.spd;
    sh.gy = h + opt.spd;
    sh.ox = rg[0];
    sh.oy = rg[1];
    samples = (float *)rtpi_malloc_array(&s->alloc, (size_t)sh.gx * sh.gy, 3 * sizeof(float));
    sh.cl = (double *)rtpi_malloc_array(&s->alloc, s->nlights ? 3 * s->nlights : 1,
                                        sizeof *sh.cl);
    if (sh.cl)
        rtpi_light_colors(s, sh.cl);
    ws = (worker *)rtpi_calloc_array(&s->alloc, (size_t)nthreads, sizeof *ws);
    if (tree_out) {
        sh.rows = (row_rec *)rtpi_calloc_array(&s->alloc, (size_t)sh.gy, sizeof *sh.rows);
        sh.stashed = (unsigned char *)rtpi_calloc_array(&s->alloc, (size_t)sh.gy, 1);
        sh.tstart = (uint64_t *)rtpi_malloc_array(&s->alloc, (size_t)sh.gx * sh.gy + 1,
                                                  sizeof *sh.tstart);
        if (!sh.stashed || !sh.tstart)
            rtpi_free(&s->alloc, sh.rows), sh.rows = NULL;
        sh.direct = nthreads == 1;
    }
    lock_made = rtpi_mutex_init(&sh.lock) == 0;
    /* the image, the samples and their starts are made; the nodes take
       the rest (the up-front check counted one a sample), and without a
       tree the workers' buffers for one sample's tree (a sample of 2^20
       nodes and many lights: hundreds of MiB) */
    sh.limited = 1;
    sh.room = limit - ((double)w * h * 12.0 +
                       (double)sh.gx * sh.gy * (12.0 + (tree_out ? 8.0 : 0.0)));
    if (!samples || !ws || !sh.cl || !lock_made || (tree_out && !sh.rows)) {
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }
    /* every sample's colour, and with a tree every sample's start, is
       written once (util.c: rtpi_prefault) */
    rtpi_prefault(&s->alloc, samples, (size_t)sh.gx * sh.gy * 3 * sizeof(float));
    if (tree_out)
        rtpi_prefault(&s->alloc, sh.tstart, ((size_t)sh.gx * sh.gy + 1) * sizeof *sh.tstart);
    sh.out = samples;
    for (i = 0; i < nthreads; i++) {
        ws[i].sh = &sh;
        ws[i].status = RTP_OK;
        ws[i].counts = (uint32_t *)rtpi_malloc_array(&s->alloc, (size_t)sh.gx,
                                                     sizeof *ws[i].counts);
        /* (16 more each: scratch written for every node shares no cache
           line with another thread's) */
        ws[i].coeffs = (float *)rtpi_malloc_array(&s->alloc, RTPI_COEFFS(s->nlights) + 16,
                                                  sizeof *ws[i].coeffs);
        ws[i].acc = (double *)rtpi_malloc_array(&s->alloc, RTPI_COEFFS(s->nlights) + 16,
                                                sizeof *ws[i].acc);
        if (!ws[i].counts || !ws[i].coeffs || !ws[i].acc) {
            st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
            goto done;
        }
        ctx[i] = &ws[i];
    }

    t0 = now_seconds();
    /* (the kd-tree's build of a large mesh takes a second or more: the
       caller's cancel is asked on either side of it) */
    if (opt.cancel && opt.cancel(opt.progress_user)) {
        st = rtpi_cancelled(err);
        goto done;
    }
    st = rtpi_kd_build_mt(s, &s->alloc, nthreads, &kd, err);
    if (st != RTP_OK)
        goto done;
    sh.kd = kd;
    st = trace_tests(&sh, s, (double)sh.gx * sh.gy, err);
    if (st != RTP_OK)
        goto done;
    t1 = now_seconds();
    if ((opt.cancel && opt.cancel(opt.progress_user)) ||
        rtpi_parallel_rows_cancel(sh.gy, nthreads, ctx, trace_row, opt.progress, opt.cancel,
                                  opt.progress_user, rtpi_trace_stack(sh.max_depth)) == 2) {
        st = rtpi_cancelled(err);
        goto done;
    }
    t2 = now_seconds();
    for (i = 0; i < nthreads; i++)
        if (ws[i].status != RTP_OK) {
            st = worker_error(ws[i].status, limit, "tracing",
                              "raise memory_limit, or trace with a lower max_depth or a "
                              "min_weight: rtp's --memory-limit, --depth, --min-weight",
                              err);
            goto done;
        }
    rtpi_resolve_samples(samples, opt.spd, img);
    if (tree_out) {
        st = gather_tree(&sh, w, h, tree_out, err);
        if (st != RTP_OK)
            goto done;
    }
    if (stats) {
        memset(stats, 0, sizeof *stats);
        for (i = 0; i < nthreads; i++) {
            stats->eye_rays += ws[i].n.eye_rays;
            stats->eye_hits += ws[i].n.eye_hits;
            stats->shadow_rays += ws[i].n.shadow_rays;
            stats->reflected_rays += ws[i].n.reflected_rays;
            stats->refracted_rays += ws[i].n.refracted_rays;
            stats->capped_rays += ws[i].n.capped;
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
    trace_tests_free(&sh, s);
    if (ws) {
        for (i = 0; i < nthreads; i++) {
            rtpi_free(&s->alloc, ws[i].nodes);
            rtpi_free(&s->alloc, ws[i].vis);
            rtpi_free(&s->alloc, ws[i].counts);
            rtpi_free(&s->alloc, ws[i].terms);
            rtpi_free(&s->alloc, ws[i].coeffs);
            rtpi_free(&s->alloc, ws[i].acc);
        }
        rtpi_free(&s->alloc, ws);
    }
    if (sh.rows) {
        for (i = 0; i < sh.gy; i++) {
            rtpi_free(&s->alloc, sh.rows[i].nodes);
            rtpi_free(&s->alloc, sh.rows[i].counts);
            rtpi_free(&s->alloc, sh.rows[i].vis);
        }
        rtpi_free(&s->alloc, sh.rows);
    }
    if (lock_made)
        rtpi_mutex_destroy(&sh.lock);
    if (la_made)
        rtpi_locked_alloc_destroy(&la);
    rtpi_free(&s->alloc, sh.stashed);
    rtpi_free(&s->alloc, sh.tnodes);
    rtpi_free(&s->alloc, sh.tvis);
    rtpi_free(&s->alloc, sh.tstart);
    rtpi_kd_destroy(kd);
    rtpi_free(&s->alloc, samples);
    rtpi_free(&s->alloc, sh.cl);
    if (st != RTP_OK || !out) {
        rtp_image_destroy(img);
        return st;
    }
    *out = img;
    return RTP_OK;
}

rtp_status rtp_trace(const rtp_scene *s, const rtp_trace_options *opt,
                     rtp_image **out, rtp_trace_stats *stats, rtp_error *err)
{
    return trace_impl(s, opt, 0, NULL, out, stats, err);
}

rtp_status rtpi_trace_sized(const rtp_scene *s, const rtp_trace_options *opt,
                            rtp_image **out, rtp_trace_stats *stats, rtp_error *err)
{
    return trace_impl(s, opt, 1, NULL, out, stats, err);
}

rtp_status rtp_record(const rtp_scene *s, const rtp_trace_options *opt,
                      rtp_tree **tree, rtp_image **image,
                      rtp_trace_stats *stats, rtp_error *err)
{
    if (!tree) {
        if (image)
            *image = NULL;
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_record: NULL tree");
    }
    return trace_impl(s, opt, 0, tree, image, stats, err);
}

/* ------------------------------------------------------------ re-trace */

typedef struct retrace_job {
    worker w;
    const uint32_t *samples;
    size_t n, chunk;
    row_rec *chunks;   /* per chunk: its samples' new trees */
} retrace_job;

static int retrace_chunk(void *ctx, int ci)
{
    retrace_job *j = (retrace_job *)ctx;
    worker *w = &j->w;
    shared *sh = w->sh;
    size_t i = (size_t)ci * j->chunk, end = i + j->chunk, k = 0;
    row_rec *r = &j->chunks[ci];
    if (end > j->n)
        end = j->n;
    w->nn = 0;
    for (; i < end; i++, k++) {
        uint32_t smp = j->samples[i];
        uint64_t o0 = sh->old_start ? sh->old_start[smp] : 0;
        /* (a sample whose eye ray left the scene holds no material) */
        w->old = sh->redo && sh->old_start[smp + 1] > o0 ? sh->old_nodes + o0 : NULL;
        w->old_vis = w->old && sh->old_vis ? sh->old_vis + o0 * sh->shade.vis_words : NULL;
        w->counts[k] = (uint32_t)record_sample(w, sh->ox + (int)(smp % (uint32_t)sh->gx),
                                               sh->oy + (int)(smp / (uint32_t)sh->gx));
        if (w->status != RTP_OK)
            return 1;
    }
    if (take_room(w, row_bytes(sh, w->nn)))
        return 1;
    return keep_row(w, r, k);
}

rtp_status rtpi_retrace(rtp_tree *t, const uint32_t *samples, size_t n, int threads,
                        size_t nlights_now, const unsigned char *redo, double limit, unsigned long long *rays,
                        unsigned long long *capped, void (*progress)(void *, double),
                        int (*cancel)(void *), void *progress_user, rtp_error *err)
{
    const rtp_allocator *a = &t->alloc;
    rtp_scene tmp;
    rtpi_light *lights = NULL;
    shared sh;
    retrace_job *jobs = NULL;
    void *ctx[RTPI_MAX_THREADS];
    row_rec *chunks = NULL;
    size_t nchunks, chunk = 64, i, k, ns = (size_t)t->nx * t->ny, total, words = t->vis_words, nl;
    rtpi_cnode *nodes = NULL;
    uint64_t *start = NULL;
    uint32_t *vis = NULL;
    rtp_status st = RTP_OK;
    int nthreads = threads > 1 ? threads : 1, lock_made = 0, la_made = 0;
    rtpi_locked_alloc la;
    double nb, kept;
    if (n == 0)
        return RTP_OK;
    if (rtpi_camera_problem(t->scene))
        return rtpi_camera_error(t->scene, NULL, "no view to trace", err);
    if (nthreads > RTPI_MAX_THREADS)
        nthreads = RTPI_MAX_THREADS;
    if (!t->kd && (st = rtpi_kd_build_mt(t->scene, a, nthreads, &t->kd, err)) != RTP_OK)
        return st;
    /* The trees record visibility of the lights where they were traced:
       trace the new samples with the lights there (moved lights are
       decided anew at evaluation, as for every other sample), or where
       every sample is traced again, with them where they are now (the
       caller records them as traced there). */
    tmp = *t->scene;
    nl = nlights_now ? nlights_now : t->nlights0;
    lights = (rtpi_light *)rtpi_malloc_array(a, nl + 1, sizeof *lights);
    if (!lights)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    for (i = 0; i < nl; i++) {
        lights[i] = t->scene->lights[i];
        if (!nlights_now)
            memcpy(lights[i].pos, t->lights0[i].pos, sizeof lights[i].pos);
    }
    tmp.lights = lights;
    tmp.nlights = nl;
    /* every sample traced anew keeps no old node: its light words are
       those of the lights it is traced with (as a trace makes them),
       which may be more than the old trees' */
    if (nlights_now)
        words = nl > 32 ? (nl + 31) / 32 : 0;

    memset(&sh, 0, sizeof sh);
    sh.s = &tmp;
    sh.off_floor = rtpi_offset_floor(&tmp, &sh.prim_floor);
    sh.wa = &tmp.alloc;
    if (nthreads > 1 && !rtpi_allocator_is_default(&tmp.alloc)) {
        if (rtpi_locked_alloc_init(&la, &tmp.alloc) == 0) {
            la_made = 1;
            sh.wa = &la.a;
        } else {
            nthreads = 1; /* (no lock: one thread needs none) */
        }
    }
    sh.kd = t->kd;
    sh.spd = t->spd;
    sh.max_depth = t->max_depth;
    sh.min_weight = t->min_weight;
    sh.shade.s = &tmp;
    sh.shade.one_sided = t->spd;
    sh.shade.has_ka = rtpi_scene_has_ka(&tmp);
    sh.shade.vis_words = words;
    camera_init(&sh.cam, &tmp, t->full_w + t->spd, t->full_h + t->spd);
    sh.gx = t->nx;
    sh.gy = t->ny;
    sh.ox = t->rx;
    sh.oy = t->ry;
    if (redo && !nlights_now) {
        sh.redo = redo;
        sh.old_nodes = t->nodes;
        sh.old_start = t->start;
        sh.old_vis = words ? t->vis_ext : NULL;
    }
    /* The trees now, with their starts, stay until the new ones are
       spliced in. */
    nb = node_bytes(&sh);
    kept = (double)t->nnodes * ((double)sizeof(rtpi_cnode) + 4.0 * (double)t->vis_words) +
           (double)(ns + 1) * 8.0;
    sh.limited = 1;
    sh.room = limit - kept;
    if (rtpi_mutex_init(&sh.lock) != 0) {
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }
    lock_made = 1;
    nchunks = (n + chunk - 1) / chunk;
    jobs = (retrace_job *)rtpi_calloc_array(a, (size_t)nthreads, sizeof *jobs);
    chunks = (row_rec *)rtpi_calloc_array(a, nchunks, sizeof *chunks);
    if (!jobs || !chunks) {
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }
    for (i = 0; i < (size_t)nthreads; i++) {
        jobs[i].w.sh = &sh;
        jobs[i].w.status = RTP_OK;
        jobs[i].w.counts = (uint32_t *)rtpi_malloc_array(a, chunk, sizeof(uint32_t));
        jobs[i].samples = samples;
        jobs[i].n = n;
        jobs[i].chunk = chunk;
        jobs[i].chunks = chunks;
        if (!jobs[i].w.counts) {
            st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
            goto done;
        }
        ctx[i] = &jobs[i];
    }
    if ((cancel && cancel(progress_user)) ||
        rtpi_parallel_rows_cancel((int)nchunks, nthreads, ctx, retrace_chunk, progress, cancel,
                                  progress_user, rtpi_trace_stack(sh.max_depth)) == 2) {
        st = rtpi_cancelled(err); /* (before the splice: the trees as they were) */
        goto done;
    }
    for (i = 0; i < (size_t)nthreads; i++)
        if (jobs[i].w.status != RTP_OK) {
            st = worker_error(jobs[i].w.status, limit, "re-tracing",
                              "raise memory_limit: rtp's --memory-limit", err);
            goto done;
        }
    for (i = 0; i < (size_t)nthreads; i++) {
        if (rays)
            *rays += jobs[i].w.n.eye_rays + jobs[i].w.n.shadow_rays +
                     jobs[i].w.n.reflected_rays + jobs[i].w.n.refracted_rays;
        if (capped)
            *capped += jobs[i].w.n.capped;
    }

    /* Splice: every sample keeps its old tree unless it was re-traced. */
    total = t->nnodes;
    for (i = 0; i < n; i++)
        total -= (size_t)(t->start[samples[i] + 1] - t->start[samples[i]]);
    for (i = 0; i < nchunks; i++)
        total += chunks[i].nnodes;
    /* (the new trees' chunks, taken from the room, are freed after the
       splice: the spliced copy is the peak) */
    if ((double)total * nb + (double)(ns + 1) * 8.0 > sh.room) {
        st = worker_error(RTP_ERR_LIMIT, limit, "re-tracing",
                          "raise memory_limit: rtp's --memory-limit", err);
        goto done;
    }
    nodes = (rtpi_cnode *)rtpi_malloc_array(a, total + 1, sizeof *nodes);
    start = (uint64_t *)rtpi_malloc_array(a, ns + 1, sizeof *start);
    vis = words ? (uint32_t *)rtpi_malloc_array(a, total * words + 1, sizeof *vis) : NULL;
    if (!nodes || !start || (words && !vis)) {
        st = rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
        goto done;
    }
    {
        size_t at = 0, next = 0, ci = 0, cj = 0, coff = 0;
        for (k = 0; k < ns; k++) {
            size_t cnt;
            start[k] = at;
            if (next < n && samples[next] == k) {
                const row_rec *r = &chunks[ci];
                cnt = r->counts[cj];
                memcpy(nodes + at, r->nodes + coff, cnt * sizeof *nodes);
                if (words)
                    memcpy(vis + at * words, r->vis + coff * words, cnt * words * sizeof *vis);
                coff += cnt;
                next++;
                if (++cj == chunk) {
                    ci++;
                    cj = 0;
                    coff = 0;
                }
            } else {
                size_t a0 = (size_t)t->start[k];
                cnt = (size_t)(t->start[k + 1] - t->start[k]);
                memcpy(nodes + at, t->nodes + a0, cnt * sizeof *nodes);
                if (words)
                    memcpy(vis + at * words, t->vis_ext + a0 * words, cnt * words * sizeof *vis);
            }
            at += cnt;
        }
        start[ns] = at;
    }
    rtpi_free(a, t->nodes);
    rtpi_free(a, t->start);
    rtpi_free(a, t->vis_ext);
    t->nodes = nodes;
    t->start = start;
    t->vis_ext = vis;
    t->vis_words = words;
    t->nnodes = total;
    nodes = NULL;
    start = NULL;
    vis = NULL;
done:
    if (jobs) {
        for (i = 0; i < (size_t)nthreads; i++) {
            rtpi_free(a, jobs[i].w.nodes);
            rtpi_free(a, jobs[i].w.vis);
            rtpi_free(a, jobs[i].w.counts);
        }
        rtpi_free(a, jobs);
    }
    if (chunks) {
        for (i = 0; i < nchunks; i++) {
            rtpi_free(a, chunks[i].nodes);
            rtpi_free(a, chunks[i].counts);
            rtpi_free(a, chunks[i].vis);
        }
        rtpi_free(a, chunks);
    }
    rtpi_free(a, nodes);
    rtpi_free(a, start);
    rtpi_free(a, vis);
    rtpi_free(a, lights);
    if (lock_made)
        rtpi_mutex_destroy(&sh.lock);
    if (la_made)
        rtpi_locked_alloc_destroy(&la);
    return st;
}
