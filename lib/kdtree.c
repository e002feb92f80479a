/* kdtree.c — the SAH kd-tree: a fast build of clipped ("perfect") splits,
 * binned near the root and exact below, 8-byte nodes after PBRT, and a
 * robust iterative traversal.
 *
 * Build.  A node holds a list of references: a primitive and its bounds
 * clipped to the node.  Large nodes (more than KD_SMALL_MAX references)
 * choose their plane by binned SAH (KD_BINS candidate planes per axis,
 * one O(n) pass), where the exact plane matters least; small ones by the
 * exact SAH of Wald & Havran 2006 ("On building fast kd-trees for ray
 * tracing, and on doing that in O(N log N)"): every face of every
 * reference's box is a candidate, found by sweeping the sorted starts,
 * ends and planar positions of each axis.  Splitting a node copies the
 * references that lie on one side to that child; a triangle that
 * straddles the plane gets for each side the bounds of its part there
 * (its vertices and edge crossings, in double, rounded outward) within
 * its old box, so the children's boxes stay tight without a full polygon
 * clip.  Reference lists live in one arena used as a stack: a node's list
 * is replaced by its right child's followed by its left child's, the left
 * subtree is built on top, then the right one.  Nothing is sorted that is
 * longer than KD_SMALL_MAX.  The top of the tree is built first, down to
 * nodes of at most 1/KD_TASKS of the references; their subtrees are tasks
 * with their own arenas, built on any number of threads and put together
 * in the order one recursion writes them, so the tree never depends on
 * the number of threads.
 *
 * Traversal.  Rays are double; the interval of the ray inside a node is
 * widened by a slack of ~1e-11 of the coordinates' size (in t units) on
 * both ends, so a hit at a split plane, on a triangle lying in the plane,
 * or on a ray running exactly along a plane is never lost to rounding; it
 * costs an extra node now and then.  An axis where the direction is zero
 * is handled apart (the ray stays on one side of the plane, or on it), so
 * no 0 * inf ever happens.
 *
 * A built tree is immutable: several threads may trace through it.
 */
#include "kdtree.h"

#include <float.h>
#include <stdlib.h>
#ifdef RTP_HAVE_THREADS
#include <pthread.h>
#endif

/* SAH costs (Wald & Havran): one traversal step, one intersection test,
   and the factor that makes cutting off empty space attractive.  The bonus
   is only given when the empty child is at least KD_EMPTY_MIN of the
   node's extent: with these costs it would otherwise pay to shave off
   slivers of empty space around every clipped triangle down to the depth
   limit (measured on the bunny: 60% empty leaves, 5 references a
   triangle), which makes the tree bigger, not faster.  At 0.2 rather than
   0.1: 7% fewer nodes and a fifth less build time on the bunny, rays as
   fast.  (Each constant can be overridden with -D to tune.) */
#ifndef KD_COST_TRAV
#define KD_COST_TRAV 1.0
#endif
#ifndef KD_COST_ISECT
#define KD_COST_ISECT 1.5
#endif
#ifndef KD_EMPTY_BONUS
#define KD_EMPTY_BONUS 0.8
#endif
#ifndef KD_EMPTY_MIN
#define KD_EMPTY_MIN 0.2
#endif
/* A node is split only when the split's SAH cost is below this share of
   the leaf's: splits that gain less than 10% cost a level of build time
   and memory for little.  On the bunny: 25% fewer nodes and references,
   a fifth less build time; camera and shadow rays as fast, random rays
   faster (fewer cache misses). */
#ifndef KD_LEAF_MARGIN
#define KD_LEAF_MARGIN 0.9
#endif
/* Nodes with fewer primitives are leaves whatever the SAH says: SAH does
   not see that a deeper tree misses the cache more often.  On the bunny,
   8 rather than 4 halves the nodes (316k to 145k), takes references from
   4.2 to 3.3 a triangle and builds 1.5 times faster, camera, shadow and
   random rays as fast (more tests a ray, fewer cache misses). */
#ifndef KD_MIN_SPLIT
#define KD_MIN_SPLIT 8
#endif
/* Depth limit 8 + 1.3 log2(N) (Wald & Havran). */
#ifndef KD_DEPTH_A
#define KD_DEPTH_A 8.0
#endif
#ifndef KD_DEPTH_B
#define KD_DEPTH_B 1.3
#endif
/* Nodes with at most KD_SMALL_MAX references get the exact SAH, larger
   ones the binned one with KD_BINS planes per axis.  Exact everywhere
   builds 2.5 times slower for a tree only ~2% better (bunny: steps and
   tests per ray).  With leaves of at least KD_MIN_SPLIT = 8 references
   the exact sweep runs on nodes of 8 to KD_SMALL_MAX: at 10 rather than
   16 the build is 1.5 times faster for 5% more tests a camera ray (the
   sorts had been a fifth of the build; a branch-free sorting network
   instead of the insertion sorts was no faster). */
#ifndef KD_SMALL_MAX
#define KD_SMALL_MAX 10
#endif
#ifndef KD_BINS
#define KD_BINS 32
#endif
/* The top of the tree is split until nodes have at most 1/KD_TASKS of
   the references (but no fewer than KD_TASK_MIN); their subtrees are
   tasks, built on as many threads as asked. */
#define KD_TASKS 32
#define KD_TASK_MIN 4096
#define KD_MAX_THREADS 64
/* The references a tree may hold, KD_REF_BUDGET a primitive, shared out
   deterministically (each node's own data, not the order of a parallel
   build): the root may hold KD_REF_BUDGET N, and a split hands each child
   the node's budget in proportion to the references it gets; a node is
   split only if its children's references fit its budget.  The
   references a leaf holds add up to at most the root's.  SAH alone
   subdivides some legal inputs without end: a fan of slivers in an
   axis-aligned plane (a convex n-gon triangulated from one corner) asks
   for cells one sliver wide near the fan's apex, N^2 of them: 64,000
   triangles made 829 M references (11 GB).  The SPD scenes hold 1.5 to
   6 references a primitive, the bunny 3.3; no path in them is cut.
   KD_REF_FLOOR more are allowed whatever the scene's size (8 MB of leaf
   lists, 28 bytes a reference of build arena, three times that while a
   look-ahead clips): long thin triangles that run
   diagonally need cells about as short as they are thin to be told apart
   (a pipe of 4,000 triangles 20 long and 0.05 thick along (1,1,0): 1.1 M
   references, 0.26 s a frame; at 16 a triangle 32 k, leaves of 4,000 and
   4 s; 20,000 diagonal slivers: 1.9 M, 4 s rather than 19; a floor of
   4 M made the slivers 3.6 s and the pipe no faster), and a small scene
   can afford that; a large one keeps its 16 a primitive. */
#ifndef KD_REF_BUDGET
#define KD_REF_BUDGET 16.0
#endif
#ifndef KD_REF_FLOOR
#define KD_REF_FLOOR 2097152.0
#endif
/* Look-ahead nodes of at least this many references are checked for
   primitives alike (kd_group).  Fewer copies than that the depth limit
   holds to a few thousand references (31 copies of a triangle: 2,294),
   and the look-ahead nodes of meshes are mostly smaller (the bunny: 482
   of 489 have 11-15 references, teapot_s12 173 of 181), so the check
   rarely runs. */
#define KD_ALIKE_MIN 32
/* Hard cap on the depth; the traversal stack holds one entry per level. */
#define KD_DEPTH_CAP 60
/* The largest primitive count: counts share a word with the 2-bit node
   kind. */
#define KD_MAX_PRIMS ((size_t)1 << 30)
/* Traversal slack, relative to the largest coordinate magnitude involved:
   rounding of a split position, a hit's t and a clipped box is ~1e-16
   relative, so 1e-11 is a wide margin, and it is still far too small to
   make a ray visit many extra nodes. */
#define KD_SLACK 1e-11

typedef struct kd_node {
    union {
        float split;    /* interior */
        uint32_t one;   /* leaf with one primitive: its id */
        uint32_t off;   /* leaf with more: first index into refs */
    } a;
    uint32_t flags;     /* bits 0-1: split axis, 3 = leaf; bits 2-31: the
                           above child's index (interior) or the primitive
                           count (leaf); the below child is the next node */
} kd_node;

struct rtpi_kdtree {
    rtp_allocator alloc;
    const rtp_scene *scene;
    kd_node *nodes;
    size_t nnodes;
    uint32_t *refs;
    size_t nrefs;
    float *tri;        /* 9 floats per triangle (its vertices), by id */
    size_t ntris;
    double lo[3], hi[3]; /* root box */
    double maxabs[3];    /* largest |coordinate| of the root box per axis */
    double boxabs;       /* the largest of maxabs (a kept leaf's walks) */
    double tol_in[3];    /* KD_SLACK * maxabs: a kept leaf's walks' tol */
    double ahead[2][3];  /* hi, lo: the face a direction's sign bit meets */
    int has_box;         /* 0: no primitive at all */
    rtpi_kd_stats stats;
    /* each leaf's ancestors, root first (rtpi_kd_paths_make; NULL: not
       made): a header (the leaf, their count) and one entry each */
    struct kd_pe *path;
    uint32_t *path_at; /* per node: a leaf's header in path */
    size_t path_n;     /* path's entries (kd_path_count), found once:
                          0 not yet, (size_t)-1 none can be made */
};

/* ================================================================ build */

/* A primitive reference in a node under construction: the primitive's
   bounds clipped to the node (conservatively: rounded outward). */
typedef struct kd_ref {
    float lo[3], hi[3];
    uint32_t prim;
} kd_ref;

typedef struct kd_task kd_task;

/* One build: the reference arena it works in and the nodes and leaf
   lists it writes.  The top of the tree is one build whose "leaves" are
   tasks (subtrees of at most task_max references); each task is a build
   of its own, run on any thread, and the pieces are put together in the
   order a single recursion would have written them. */
typedef struct kd_build {
    const rtp_allocator *a;
    const rtpi_kdtree *kd; /* read only: the triangles' vertices */
    kd_ref *ref;           /* the arena of reference lists, used as a stack */
    size_t ref_cap;
    kd_node *nodes;
    size_t nnodes, nodes_cap;
    uint32_t *refs;
    size_t nrefs, refs_cap;
    int max_depth, depth_seen;
    int check, saw;        /* check: a look-ahead node holding primitives
                              alike stops the build, saw set (kd_group) */
    const uint32_t *wt;    /* NULL, or by id the size of the group each
                              reference stands for (kd_group, kd_weigh) */
    int leaf_alike;        /* make_leaf asks its references whether two are
                              alike: the first pass, where the scene holds
                              two (asked once of all, at the root) */
    size_t task_max;       /* top build: nodes this small become tasks */
    kd_task *tasks;
    size_t ntasks, tasks_cap;
} kd_build;

struct kd_task {
    float lo[3], hi[3];
    size_t n;
    int depth;
    double budget; /* the references its subtree may hold (KD_REF_BUDGET) */
    kd_build b;
};

/* The float next to f towards -inf or +inf (f finite): nextafterf
   without the call, which the build makes millions of times. */
static float f_next(float f, int up)
{
    uint32_t u;
    if (f == 0.0f)
        return up ? 1.4e-45f : -1.4e-45f; /* the smallest subnormals */
    memcpy(&u, &f, sizeof u);
    u += (f > 0.0f) == (up != 0) ? 1u : (uint32_t)-1;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* x rounded down (up) to a float.  -0 becomes +0 so that positions
   compare and sort alike. */
static float f_down(double x)
{
    float f = (float)x;
    if ((double)f > x)
        f = f_next(f, 0);
    return f + 0.0f;
}

static float f_up(double x)
{
    float f = (float)x;
    if ((double)f < x)
        f = f_next(f, 1);
    return f + 0.0f;
}

/* The SAH cost of a split with nl and nr primitives on the two sides,
   al and ar the children's areas relative to the node's; the plane is at
   x from the node's low face on an axis of extent dk. */
static RTPI_FORCE_INLINE double sah(double al, double ar, size_t nl,
                                    size_t nr, double x, double dk)
{
    /* Through int64_t: x86-64 converts a signed integer to double in one
       instruction, an unsigned 64-bit one in a branchy sequence, and this
       runs ~90 times a node.  Counts are below 2^32. */
    double c = KD_COST_TRAV + KD_COST_ISECT * (al * (double)(int64_t)nl +
                                               ar * (double)(int64_t)nr);
    if (nl == 0 || nr == 0) { /* rare: the share is needed only here */
        double fl = x / dk;
        if ((nl == 0 && fl >= KD_EMPTY_MIN) || (nr == 0 && 1.0 - fl >= KD_EMPTY_MIN))
            c *= KD_EMPTY_BONUS;
    }
    return c;
}

typedef struct kd_split {
    double cost;
    int axis, planar_left;
    float pos;
} kd_split;

/* Sorts a[0, n), and w[0, n) along with it unless w is NULL. */
static RTPI_FORCE_INLINE void sort_f(float *a, uint32_t *w, size_t n)
{
    size_t i, j;
    for (i = 1; i < n; i++) {
        float x = a[i];
        uint32_t y = w ? w[i] : 0;
        for (j = i; j > 0 && x < a[j - 1]; j--) {
            a[j] = a[j - 1];
            if (w)
                w[j] = w[j - 1];
        }
        a[j] = x;
        if (w)
            w[j] = y;
    }
}

/* The references r[0, n) weigh: each the size of the group it stands
   for (kd_build.wt), or 1 each where wt is NULL. */
static size_t kd_weigh(const uint32_t *wt, const kd_ref *r, size_t n)
{
    size_t i, w = 0;
    if (!wt)
        return n;
    for (i = 0; i < n; i++)
        w += wt[r[i].prim];
    return w;
}

/* The same exact SAH for a few references (at most KD_SMALL_MAX): the
   starts, ends and planar positions of each axis sorted apart (insertion
   sorts, cheap for short lists) and swept together.  Each reference
   counts as the group it stands for (wt, w the node's total; NULL and n
   where there are none): the inline body is compiled once for each. */
static RTPI_FORCE_INLINE void split_small_w(const kd_ref *r, size_t n, const float *lo,
                                            const float *hi, const double *d, double area,
                                            kd_split *best, const uint32_t *wt, size_t w)
{
    float st[KD_SMALL_MAX + 1], en[KD_SMALL_MAX + 1], pl[KD_SMALL_MAX + 1];
    uint32_t ws[KD_SMALL_MAX + 1], we[KD_SMALL_MAX + 1], wp[KD_SMALL_MAX + 1];
    int k;
    size_t i;
    for (k = 0; k < 3; k++) {
        double o1 = d[(k + 1) % 3], o2 = d[(k + 2) % 3];
        double inv = 1.0 / area, cap = o1 * o2 * inv, perim = (o1 + o2) * inv;
        size_t ns = 0, np = 0, is = 0, ie = 0, ip = 0, nl = 0, nr = w;
        if (!(d[k] > 0.0))
            continue;
        for (i = 0; i < n; i++) {
            if (r[i].lo[k] == r[i].hi[k]) {
                if (wt)
                    wp[np] = wt[r[i].prim];
                pl[np++] = r[i].lo[k];
            } else {
                if (wt)
                    ws[ns] = we[ns] = wt[r[i].prim];
                st[ns] = r[i].lo[k];
                en[ns++] = r[i].hi[k];
            }
        }
        sort_f(st, wt ? ws : NULL, ns);
        sort_f(en, wt ? we : NULL, ns);
        sort_f(pl, wt ? wp : NULL, np);
        /* Sentinels: every position is finite. */
        st[ns] = en[ns] = pl[np] = INFINITY;
        while (ie < ns || ip < np) {
            float p = st[is] < en[ie] ? st[is] : en[ie];
            size_t pe = 0, pp = 0, ps = 0;
            p = pl[ip] < p ? pl[ip] : p;
            while (en[ie] == p)
                pe += wt ? we[ie] : 1, ie++;
            while (pl[ip] == p)
                pp += wt ? wp[ip] : 1, ip++;
            while (st[is] == p)
                ps += wt ? ws[is] : 1, is++;
            nr -= pp + pe;
            if (p > lo[k] && p < hi[k]) {
                double x = (double)p - lo[k];
                double al = cap + x * perim, ar = cap + (d[k] - x) * perim;
                double c = sah(al, ar, nl + pp, nr, x, d[k]);
                if (c < best->cost) {
                    best->cost = c;
                    best->axis = k;
                    best->pos = p;
                    best->planar_left = 1;
                }
                if (pp) {
                    c = sah(al, ar, nl, nr + pp, x, d[k]);
                    if (c < best->cost) {
                        best->cost = c;
                        best->axis = k;
                        best->pos = p;
                        best->planar_left = 0;
                    }
                }
            }
            nl += ps + pp;
        }
    }
}

static void split_small(const kd_ref *r, size_t n, const float *lo, const float *hi,
                        const double *d, double area, kd_split *best, const uint32_t *wt,
                        size_t w)
{
    if (wt)
        split_small_w(r, n, lo, hi, d, area, best, wt, w);
    else
        split_small_w(r, n, lo, hi, d, area, best, NULL, n);
}

/* Binned SAH (KD_BINS planes per axis, counting where boxes start and
   end): O(n) for the large nodes near the root, where the exact plane
   matters least.  Weights as split_small_w's. */
static RTPI_FORCE_INLINE void split_binned_w(const kd_ref *r, size_t n, const float *lo,
                                             const float *hi, const double *d, double area,
                                             kd_split *best, const uint32_t *wt, size_t w)
{
    uint32_t cs[3][KD_BINS], ce[3][KD_BINS];
    float sc[3];
    int k, j;
    size_t i;
    memset(cs, 0, sizeof cs);
    memset(ce, 0, sizeof ce);
    for (k = 0; k < 3; k++)
        sc[k] = d[k] > 0.0 ? (float)(KD_BINS / d[k]) : 0.0f;
    for (i = 0; i < n; i++) {
        const uint32_t wi = wt ? wt[r[i].prim] : 1;
        for (k = 0; k < 3; k++) {
            /* The boxes lie inside the node's, so the offsets are >= 0;
               rounding may give KD_BINS at the top, which the clamp
               absorbs.  A bin only steers the choice of plane: the
               partition below uses the exact coordinates. */
            unsigned s0 = (unsigned)((r[i].lo[k] - lo[k]) * sc[k]);
            unsigned s1 = (unsigned)((r[i].hi[k] - lo[k]) * sc[k]);
            s0 = s0 < KD_BINS - 1 ? s0 : KD_BINS - 1;
            s1 = s1 < KD_BINS - 1 ? s1 : KD_BINS - 1;
            cs[k][s0] += wi;
            ce[k][s1] += wi;
        }
    }
    for (k = 0; k < 3; k++) {
        double o1 = d[(k + 1) % 3], o2 = d[(k + 2) % 3];
        double inv = 1.0 / area, cap = o1 * o2 * inv, perim = (o1 + o2) * inv;
        size_t nl = 0, nr = w;
        if (!(d[k] > 0.0))
            continue;
        for (j = 1; j < KD_BINS; j++) {
            float p = (float)((double)lo[k] + d[k] * j * (1.0 / KD_BINS));
            double c, x;
            nl += cs[k][j - 1];
            nr -= ce[k][j - 1];
            if (!(p > lo[k] && p < hi[k]))
                continue;
            x = (double)p - lo[k];
            c = sah(cap + x * perim, cap + (d[k] - x) * perim, nl, nr, x,
                    d[k]);
            if (c < best->cost) {
                best->cost = c;
                best->axis = k;
                best->pos = p;
                best->planar_left = 1;
            }
        }
    }
}

static void split_binned(const kd_ref *r, size_t n, const float *lo, const float *hi,
                         const double *d, double area, kd_split *best, const uint32_t *wt,
                         size_t w)
{
    if (wt)
        split_binned_w(r, n, lo, hi, d, area, best, wt, w);
    else
        split_binned_w(r, n, lo, hi, d, area, best, NULL, n);
}

/* Splits the reference r of a straddling primitive at `pos` on `axis`:
   l and rr get its bounds on either side.  A triangle's bounds are those
   of its part on that side (its vertices there and its edges' crossing
   points, in double, rounded outward) within r's box, which already
   bounds it within the node: a tight box at the cost of a few flops.
   Other primitives keep r's box cut at the plane.
   @return bit 0: the left part is not empty, bit 1: the right part. */
static int split_ref(const kd_build *b, const kd_ref *r, int axis, float pos,
                     kd_ref *l, kd_ref *rr)
{
    int k, ret = 3;
    *l = *r;
    *rr = *r;
    l->hi[axis] = pos;
    rr->lo[axis] = pos;
    if (r->prim < b->kd->ntris) {
        const float *v = b->kd->tri + 9 * (size_t)r->prim;
        double mn[2][3], mx[2][3], c = pos;
        int i, sd;
        for (sd = 0; sd < 2; sd++)
            for (k = 0; k < 3; k++) {
                mn[sd][k] = HUGE_VAL;
                mx[sd][k] = -HUGE_VAL;
            }
        for (i = 0; i < 3; i++) {
            const float *P = v + 3 * i, *Q = v + 3 * (i == 2 ? 0 : i + 1);
            double x[3];
            if (P[axis] <= c)
                for (k = 0; k < 3; k++) {
                    mn[0][k] = P[k] < mn[0][k] ? P[k] : mn[0][k];
                    mx[0][k] = P[k] > mx[0][k] ? P[k] : mx[0][k];
                }
            if (P[axis] >= c)
                for (k = 0; k < 3; k++) {
                    mn[1][k] = P[k] < mn[1][k] ? P[k] : mn[1][k];
                    mx[1][k] = P[k] > mx[1][k] ? P[k] : mx[1][k];
                }
            if ((P[axis] < c && Q[axis] > c) || (P[axis] > c && Q[axis] < c)) {
                double t = (c - P[axis]) / ((double)Q[axis] - P[axis]);
                for (k = 0; k < 3; k++)
                    x[k] = P[k] + t * ((double)Q[k] - P[k]);
                x[axis] = c;
                for (sd = 0; sd < 2; sd++)
                    for (k = 0; k < 3; k++) {
                        mn[sd][k] = x[k] < mn[sd][k] ? x[k] : mn[sd][k];
                        mx[sd][k] = x[k] > mx[sd][k] ? x[k] : mx[sd][k];
                    }
            }
        }
        for (k = 0; k < 3; k++) {
            if (k == axis)
                continue;
            if (mn[0][k] <= mx[0][k]) {
                float f0 = f_down(mn[0][k]), f1 = f_up(mx[0][k]);
                l->lo[k] = f0 > l->lo[k] ? f0 : l->lo[k];
                l->hi[k] = f1 < l->hi[k] ? f1 : l->hi[k];
            }
            if (mn[1][k] <= mx[1][k]) {
                float f0 = f_down(mn[1][k]), f1 = f_up(mx[1][k]);
                rr->lo[k] = f0 > rr->lo[k] ? f0 : rr->lo[k];
                rr->hi[k] = f1 < rr->hi[k] ? f1 : rr->hi[k];
            }
        }
        {
            /* The split axis: the part's extent, at most up to the plane. */
            float f0 = f_down(mn[0][axis]), f1 = f_up(mx[1][axis]);
            l->lo[axis] = f0 > l->lo[axis] ? f0 : l->lo[axis];
            rr->hi[axis] = f1 < rr->hi[axis] ? f1 : rr->hi[axis];
        }
        /* A part whose box came out empty lies outside the node: the
           triangle's part on that side and the node's box do not meet. */
        for (k = 0; k < 3; k++) {
            if (!(l->lo[k] <= l->hi[k]))
                ret &= ~1;
            if (!(rr->lo[k] <= rr->hi[k]))
                ret &= ~2;
        }
    }
    return ret;
}

/* The best cost of the node [lo,hi] holding the n references r: its
   leaf's, or its best split's if that is lower (by the same rules as
   build_node's choice, without the look-ahead). */
static double node_cost(const uint32_t *wt, const kd_ref *r, size_t n, const float *lo,
                        const float *hi)
{
    kd_split sp;
    size_t w = kd_weigh(wt, r, n);
    double d[3], area, leaf = KD_COST_ISECT * (double)w;
    int k;
    for (k = 0; k < 3; k++)
        d[k] = (double)hi[k] - lo[k];
    area = d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
    sp.cost = HUGE_VAL;
    if (n >= KD_MIN_SPLIT && area > 0.0) {
        if (n <= KD_SMALL_MAX)
            split_small(r, n, lo, hi, d, area, &sp, wt, w);
        else
            split_binned(r, n, lo, hi, d, area, &sp, wt, w);
    }
    return sp.cost < KD_LEAF_MARGIN * leaf ? sp.cost : leaf;
}

/* The look-ahead for a node that the box SAH leaves a leaf although it is
   large.  Long thin triangles that run diagonally (a pipe or hair along
   (1,1,0)) each have a box that spans the whole node in two axes, so
   every plane straddles them all and no single split pays, though two
   do: a cut at the middle of x whose clipped parts lie in one half of y,
   then the cut that drops the (nearly) empty half.  So for the middle
   plane of each axis this clips every straddler (split_ref, as the
   partition would) into the free arena above the node's list and prices
   the split with each child's own best cost (node_cost) rather than its
   leaf's: a two-level SAH.  Only where the binned SAH failed on more
   than KD_SMALL_MAX references: such leaves are rare in ordinary scenes,
   and the cost there is 3 n clips and 6 binned passes.
   @return 0, or -1 when out of memory. */
static int split_lookahead(kd_build *b, size_t off, size_t n,
                           const float *lo, const float *hi, double area,
                           kd_split *best)
{
    int k;
    size_t i;
    if (rtpi_grow(b->a, (void **)&b->ref, &b->ref_cap, off + 3 * n,
                  sizeof *b->ref))
        return -1;
    for (k = 0; k < 3; k++) {
        const kd_ref *r = b->ref + off;
        kd_ref *pl = b->ref + off + n, *pr = pl + n;
        float p = (float)(0.5 * ((double)lo[k] + hi[k]));
        float clo[3], chi[3];
        size_t nl = 0, nr = 0;
        double c, d = (double)hi[k] - lo[k], o1, o2, x, cap, perim;
        int m;
        if (!(p > lo[k] && p < hi[k]))
            continue;
        for (i = 0; i < n; i++) {
            float a0 = r[i].lo[k], a1 = r[i].hi[k];
            if (a1 < p || (a1 == p && a0 <= p)) { /* as planar_left */
                pl[nl++] = r[i];
            } else if (a0 >= p) {
                pr[nr++] = r[i];
            } else {
                kd_ref lp, rp;
                int s = split_ref(b, &r[i], k, p, &lp, &rp);
                if (s & 1)
                    pl[nl++] = lp;
                if (s & 2)
                    pr[nr++] = rp;
            }
        }
        o1 = (double)hi[(k + 1) % 3] - lo[(k + 1) % 3];
        o2 = (double)hi[(k + 2) % 3] - lo[(k + 2) % 3];
        cap = o1 * o2 / area;
        perim = (o1 + o2) / area;
        x = (double)p - lo[k];
        for (m = 0; m < 3; m++) {
            clo[m] = lo[m];
            chi[m] = hi[m];
        }
        chi[k] = p;
        c = KD_COST_TRAV + (cap + x * perim) * node_cost(b->wt, pl, nl, clo, chi);
        clo[k] = p;
        chi[k] = hi[k];
        c += (cap + (d - x) * perim) * node_cost(b->wt, pr, nr, clo, chi);
        if (c < best->cost) {
            best->cost = c;
            best->axis = k;
            best->pos = p;
            best->planar_left = 1;
        }
    }
    return 0;
}

static int push_node(kd_build *b, uint32_t *idx)
{
    if (b->nnodes >= KD_MAX_PRIMS ||
        rtpi_grow(b->a, (void **)&b->nodes, &b->nodes_cap, b->nnodes + 1,
                  sizeof *b->nodes))
        return -1;
    *idx = (uint32_t)b->nnodes++;
    return 0;
}

static int cmp_id(const void *pa, const void *pb)
{
    uint32_t x = *(const uint32_t *)pa, y = *(const uint32_t *)pb;
    return (x > y) - (x < y);
}

static int kd_alike(const rtpi_kdtree *kd, const kd_ref *a, const kd_ref *b);
static int kd_node_alike(kd_build *b, size_t off, size_t n);

/* Makes the leaf of the n references b->ref[off, off + n).  Where two
   of them are alike (kd_alike: copies, never grouped, as kd_group only
   groups where a look-ahead splits a node holding them), its ids are
   sorted ascending, the order the brute-force loop meets them in: of
   hits at one t the last tested wins, and copies (the same floats) are
   hit at the same t, so the last copy shows, as in brute force.  The
   partitions leave a leaf's ids in any order: 5,000 copies of a triangle
   (each its own material) among 5,000 others made one leaf without a
   look-ahead, and 44 of 1,000 rays hit a middle copy.  Other leaves keep
   their order, and their images the same bits: sorting every leaf
   changed 16 pixels of gears_s2 (hits at one t on a shared edge). */
static int make_leaf(kd_build *b, size_t off, size_t n)
{
    uint32_t idx;
    size_t i, j;
    int al = 0;
    if (!b->leaf_alike || n < 2) {
        /* (no two alike: a scene without copies pays one hash at the
           root, not a test a leaf -- gears_s4's build +2.6% when each leaf
           asked -- and the second pass has grouped every copy) */
    } else if (n > KD_SMALL_MAX) { /* (a hash, as the look-ahead's check) */
        al = kd_node_alike(b, off, n);
        if (al < 0)
            return -1;
    } else {
        const kd_ref *r = b->ref + off;
        for (i = 1; i < n && !al; i++)
            for (j = 0; j < i && !al; j++)
                al = kd_alike(b->kd, &r[j], &r[i]);
    }
    if (push_node(b, &idx))
        return -1;
    b->nodes[idx].flags = 3u | (uint32_t)n << 2;
    b->nodes[idx].a.off = 0;
    if (n == 1) {
        b->nodes[idx].a.one = b->ref[off].prim;
    } else if (n > 1) {
        uint32_t *ids;
        if (b->nrefs + n > 0xffffffffu ||
            rtpi_grow(b->a, (void **)&b->refs, &b->refs_cap, b->nrefs + n,
                      sizeof *b->refs))
            return -1;
        b->nodes[idx].a.off = (uint32_t)b->nrefs;
        ids = b->refs + b->nrefs;
        for (i = 0; i < n; i++)
            ids[i] = b->ref[off + i].prim;
        b->nrefs += n;
        if (al)
            qsort(ids, n, sizeof *ids, cmp_id);
    }
    return 0;
}

/* Whether the split sp parts the n references r into two non-empty
   groups with none straddling the plane (sides as build_node's partition
   decides them).  Such a split is taken whenever the SAH prices it below
   the leaf, without KD_LEAF_MARGIN: it adds no reference, and the splits
   it allows part the references each time, so they add fewer nodes than
   the node has references.  The margin had made a stack of parallel
   quads two leaves whatever its size: each half of a thin slab is nearly
   as large as the whole (a half of the stack's: 0.944 of the leaf's cost,
   over the margin), as the SAH prices a ray through every quad, while
   a ray stops at the first quad it hits; every ray tested half the quads
   (16,000 quads at 256x256: 5.8 s of tracing after a build of 0.02 s;
   split, 0.04 s after one of 0.8 s: the slabs' leaves are then cut
   along the quads' diagonals, within KD_REF_BUDGET).  Where the
   margin decides, such splits are rare in meshes: the SPD scenes, the
   bunny and the other meshes keep their references, up to 64 more nodes
   (teapot.obj 13,523 to 13,587), and their images are the same bits. */
static int split_clean(const kd_ref *r, size_t n, const kd_split *sp)
{
    const int ax = sp->axis, pl = sp->planar_left;
    const float pos = sp->pos;
    size_t i, nl = 0;
    for (i = 0; i < n; i++) {
        float a0 = r[i].lo[ax], a1 = r[i].hi[ax];
        if (a1 < pos || (a1 == pos && (a0 < pos || pl)))
            nl++;
        else if (!(a0 >= pos))
            return 0; /* straddles */
    }
    return nl > 0 && nl < n;
}

/* Whether references a and b are primitives that no split can part:
   triangles with the same three vertices (in any order: the same point
   set, so every cell meets both or neither), or other primitives with
   the same box (their references are only ever their boxes cut at
   planes).  In a node, a's and b's boxes are their clipped ones: alike
   triangles in one order, or others, have the same there too. */
static int kd_alike(const rtpi_kdtree *kd, const kd_ref *a, const kd_ref *b)
{
    int k, i, j;
    /* (the boxes' floats are never NaN, and never -0: f_down, f_up) */
    for (k = 0; k < 3; k++)
        if (a->lo[k] != b->lo[k] || a->hi[k] != b->hi[k])
            return 0;
    if ((a->prim < kd->ntris) != (b->prim < kd->ntris))
        return 0;
    if (a->prim >= kd->ntris)
        return 1;
    /* Non-degenerate: three distinct vertices each, so a's being among
       b's makes the sets equal. */
    for (i = 0; i < 3; i++) {
        const float *p = kd->tri + 9 * (size_t)a->prim + 3 * i;
        for (j = 0; j < 3; j++) {
            const float *q = kd->tri + 9 * (size_t)b->prim + 3 * j;
            for (k = 0; k < 3 && p[k] == q[k]; k++)
                ;
            if (k == 3)
                break;
        }
        if (j == 3)
            return 0;
    }
    return 1;
}

/* A hash that alike references share (kd_alike): a triangle's of its
   vertices, summed so that their order does not count (-0 as +0, as ==
   has it); another primitive's of its box.  Not the triangles' boxes:
   a fan of slivers over one box (all sharing its diagonal) put every
   triangle in one chain. */
static uint32_t kd_alike_hash(const rtpi_kdtree *kd, const kd_ref *r, size_t cap)
{
    uint64_t h = 0;
    int i;
    if (r->prim < kd->ntris) {
        const float *v = kd->tri + 9 * (size_t)r->prim;
        for (i = 0; i < 3; i++, v += 3) {
            float f[4];
            uint64_t w[2];
            f[0] = v[0] + 0.0f;
            f[1] = v[1] + 0.0f;
            f[2] = v[2] + 0.0f;
            f[3] = 0.0f;
            memcpy(w, f, sizeof w);
            h += (w[0] * 0x9e3779b97f4a7c15ull ^ w[1] * 0xc2b2ae3d27d4eb4full) >> 7;
        }
    } else {
        uint64_t w[3];
        memcpy(w, r, sizeof w); /* lo and hi, its first 24 bytes */
        h = w[0] * 0x9e3779b97f4a7c15ull ^ w[1] * 0xc2b2ae3d27d4eb4full ^
            w[2] * 0x165667b19e3779f9ull;
    }
    h ^= h >> 29;
    h ^= h >> 17;
    return (uint32_t)(h & (cap - 1));
}

/* Finds the references among r[0, n) alike to an earlier one (kd_alike)
   by a hash (kd_alike_hash), chained in `room`, which holds at least 3 n
   words.  With nx NULL: @return 1 at the first found, else 0.  Else each
   found one is appended to its first's list (nx by id, the lists' tails
   in nx + np), its prim set to RTPI_NONE, and @return the count found. */
static size_t kd_find_alike(const rtpi_kdtree *kd, kd_ref *r, size_t n, uint32_t *room,
                            uint32_t *nx, size_t np)
{
    uint32_t *head = room, *chain, x;
    size_t cap = 1, i, found = 0;
    while (cap < n)
        cap *= 2;
    chain = head + cap; /* (cap < 2 n) */
    memset(head, 0xff, cap * sizeof *head); /* RTPI_NONE: an empty chain */
    for (i = 0; i < n; i++) {
        uint32_t hs = kd_alike_hash(kd, &r[i], cap), j;
        for (x = head[hs]; x != RTPI_NONE; x = chain[x])
            if (r[x].lo[0] == r[i].lo[0] && kd_alike(kd, &r[x], &r[i]))
                break;
        if (x == RTPI_NONE) {
            chain[i] = head[hs];
            head[hs] = (uint32_t)i;
            continue;
        }
        if (!nx)
            return 1;
        j = r[x].prim; /* the group's first, whose reference stays */
        nx[nx[np + j]] = r[i].prim;
        nx[np + j] = r[i].prim;
        r[i].prim = RTPI_NONE; /* (never chained: x is always a first) */
        found++;
    }
    return found;
}

/* Whether the node b->ref[off, off + n) holds two references alike, asked
   where its look-ahead splits it (the build's check).  @return 1 or 0, or -1 when
   out of memory. */
static int kd_node_alike(kd_build *b, size_t off, size_t n)
{
    if (rtpi_grow(b->a, (void **)&b->ref, &b->ref_cap, off + 2 * n, sizeof *b->ref))
        return -1;
    /* (3 n words fit in the n references above the list: 28 bytes each) */
    return (int)kd_find_alike(b->kd, b->ref + off, n, (uint32_t *)(void *)(b->ref + off + n),
                              NULL, 0);
}

/* Primitives alike (kd_alike) are built as one: N copies of a triangle
   (an exporter's duplicated faces, a mesh included many times in one
   place) can never be parted, yet the SAH, pricing each cell at N tests,
   cut the empty space around them ever finer, each cell holding all N,
   until KD_REF_BUDGET stopped it (8,000 copies: 2.0 M references and 2.6
   s; 256 k: 9.3 s and 566 MB).  Past the few box splits that cut off
   space or other primitives, only the look-ahead can split such a node
   (every plane straddles them all), so the build checks there (check,
   from KD_ALIKE_MIN references) and, where a node the look-ahead splits
   holds two alike, starts again with this: the first of each group (by
   id) stands for it in the build, and its leaves list the others after
   it (kd_expand), in ascending id as the brute-force loop meets them (of
   hits at one t the last tested wins in both).  A scene whose checks
   find none keeps its tree, node for node (the SPD scenes, the bunny
   and the meshes, scenes/).  The list r[0, *n) keeps its order with the
   others taken out; the hash's chains live in the arena above it (2 np
   references).  Each first weighs as its group in the build (kd_build.wt,
   *same + np): in the SAH's counts, the leaf's cost, the look-ahead's and
   the reference budget, so that N copies crossing other primitives are
   cut as N would be (weighing one, 2 triangles of 3,000 copies through
   20,000 small ones made 4.1 M references rather than 102 k); whether a
   node is split at all (KD_MIN_SPLIT), sweeps its references exactly
   (KD_SMALL_MAX) or looks ahead still counts references, not copies, so
   that copies alone (or with fewer than KD_MIN_SPLIT others) stay one
   leaf, as no cut can take them apart.
   @return 0 (*same NULL when no two are alike), or -1 when out of
   memory. */
static int kd_group(const rtp_allocator *a, const rtpi_kdtree *kd, size_t np,
                    kd_ref *r, size_t *n, uint32_t **same)
{
    uint32_t *nx;
    size_t i, j;
    *same = NULL;
    if (*n < 2)
        return 0;
    nx = (uint32_t *)rtpi_malloc_array(a, 2 * np, sizeof *nx);
    if (!nx)
        return -1;
    memset(nx, 0xff, np * sizeof *nx); /* RTPI_NONE */
    for (j = 0; j < np; j++)
        nx[np + j] = (uint32_t)j; /* a group's last member */
    if (!kd_find_alike(kd, r, *n, (uint32_t *)(void *)(r + *n), nx, np)) {
        rtpi_free(a, nx);
        return 0;
    }
    for (i = 0, j = 0; i < *n; i++)
        if (r[i].prim != RTPI_NONE)
            r[j++] = r[i];
    *n = j;
    /* The tails are no longer read: the second half becomes the weights
       (kd_build.wt), by the first's id the size of its group. */
    for (i = 0; i < j; i++) {
        uint32_t p, c = 0;
        for (p = r[i].prim; p != RTPI_NONE; p = nx[p])
            c++;
        nx[np + r[i].prim] = c;
    }
    *same = nx;
    return 0;
}

/* In the top build: the node becomes a task with a copy of its
   references (the arena above them is reused) and a placeholder node
   that names it. */
static int make_task(kd_build *b, const float *lo, const float *hi,
                     size_t off, size_t n, int depth, double budget)
{
    kd_task *t;
    uint32_t idx;
    int k;
    if (rtpi_grow(b->a, (void **)&b->tasks, &b->tasks_cap, b->ntasks + 1,
                  sizeof *b->tasks) ||
        push_node(b, &idx))
        return -1;
    t = &b->tasks[b->ntasks];
    memset(t, 0, sizeof *t);
    for (k = 0; k < 3; k++) {
        t->lo[k] = lo[k];
        t->hi[k] = hi[k];
    }
    t->n = n;
    t->depth = depth;
    t->budget = budget;
    t->b.a = b->a;
    t->b.kd = b->kd;
    t->b.max_depth = b->max_depth;
    t->b.check = b->check;
    t->b.leaf_alike = b->leaf_alike;
    t->b.wt = b->wt;
    t->b.ref_cap = 2 * n + KD_SMALL_MAX;
    t->b.ref = (kd_ref *)rtpi_malloc_array(b->a, t->b.ref_cap, sizeof(kd_ref));
    if (!t->b.ref)
        return -1;
    b->ntasks++; /* counted once it owns memory, so cleanup frees it */
    if (n)
        memcpy(t->b.ref, b->ref + off, n * sizeof(kd_ref));
    b->nodes[idx].flags = 3u;
    b->nodes[idx].a.off = (uint32_t)(b->ntasks - 1);
    return 0;
}

/* Builds the subtree of the node with box [lo,hi] whose references are
   b->ref[off, off + n), holding at most `budget` references in its
   leaves (KD_REF_BUDGET). */
static int build_node(kd_build *b, const float *lo, const float *hi,
                      size_t off, size_t n, int depth, double budget)
{
    kd_split sp;
    double d[3], area, wd;
    size_t i, nl, nr, w, wl;
    kd_ref *r;
    float clo[3], chi[3];
    uint32_t idx;
    int k, take;

    if (b->task_max && n <= b->task_max)
        return make_task(b, lo, hi, off, n, depth, budget);
    if (depth > b->depth_seen)
        b->depth_seen = depth;
    w = kd_weigh(b->wt, b->ref + off, n);
    sp.cost = HUGE_VAL;
    sp.axis = 0;
    sp.pos = 0.0f;
    sp.planar_left = 1;
    for (k = 0; k < 3; k++)
        d[k] = (double)hi[k] - lo[k];
    area = d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
    if (depth < b->max_depth && n >= KD_MIN_SPLIT && area > 0.0) {
        if (n <= KD_SMALL_MAX)
            split_small(b->ref + off, n, lo, hi, d, area, &sp, b->wt, w);
        else
            split_binned(b->ref + off, n, lo, hi, d, area, &sp, b->wt, w);
    }
    wd = (double)(int64_t)w; /* (as sah's: signed converts faster) */
    take = sp.cost < KD_LEAF_MARGIN * KD_COST_ISECT * wd;
    if (!take && sp.cost < KD_COST_ISECT * wd)
        take = split_clean(b->ref + off, n, &sp);
    if (!take && depth < b->max_depth && n > KD_SMALL_MAX && area > 0.0) {
        if (split_lookahead(b, off, n, lo, hi, area, &sp))
            return -1;
        take = sp.cost < KD_LEAF_MARGIN * KD_COST_ISECT * wd;
        if (take && b->check && n >= KD_ALIKE_MIN) { /* (kd_group) */
            int al = kd_node_alike(b, off, n);
            if (al) {
                b->saw = al > 0;
                return -1;
            }
        }
    }
    if (!take) {
        if (b->task_max) /* the task decides the same again */
            return make_task(b, lo, hi, off, n, depth, budget);
        return make_leaf(b, off, n);
    }

    /* Partition in place into [right | straddling | left] (three-way, as
       the Dutch flag), then split each straddler: its right part takes
       its place, its left part goes after the left ones.  The right
       child's list ends up at off, the left child's above it, so that the
       left subtree is built on top and the right one after it; the arena
       grows by the straddlers only. */
    {
        const int ax = sp.axis, pl = sp.planar_left;
        const float pos = sp.pos;
        size_t j = 0, e = n, q, t;
        kd_ref x;
        r = b->ref + off;
        i = 0;
        while (j < e) {
            float a0 = r[j].lo[ax], a1 = r[j].hi[ax];
            if (a1 < pos || (a1 == pos && (a0 < pos || pl))) {
                e--; /* left */
                x = r[j];
                r[j] = r[e];
                r[e] = x;
            } else if (a0 >= pos) { /* right */
                x = r[j];
                r[j] = r[i];
                r[i] = x;
                i++;
                j++;
            } else { /* straddles */
                j++;
            }
        }
        /* the children hold at most n + (j - i) references, weighing w
           and the straddlers' again: over the budget, the node stays a
           leaf (its references only reordered) */
        if ((double)(int64_t)(w + kd_weigh(b->wt, r + i, j - i)) > budget) {
            if (b->task_max)
                return make_task(b, lo, hi, off, n, depth, budget);
            return make_leaf(b, off, n);
        }
        if (rtpi_grow(b->a, (void **)&b->ref, &b->ref_cap, off + n + (j - i),
                      sizeof *b->ref))
            return -1;
        r = b->ref + off;
        q = i;
        t = n;
        for (; i < j; i++) {
            kd_ref lp, rp;
            int m = split_ref(b, &r[i], ax, pos, &lp, &rp);
            if (m & 2)
                r[q++] = rp;
            if (m & 1)
                r[t++] = lp;
        }
        nr = q;
        nl = t - j;
        memmove(r + q, r + j, nl * sizeof *r);
        wl = kd_weigh(b->wt, r + nr, nl);
        w = kd_weigh(b->wt, r, nr) + wl; /* the children's, both sides */
    }

    if (push_node(b, &idx))
        return -1;
    b->nodes[idx].a.split = sp.pos;
    b->nodes[idx].flags = (uint32_t)sp.axis;
    for (k = 0; k < 3; k++) {
        clo[k] = lo[k];
        chi[k] = hi[k];
    }
    chi[sp.axis] = sp.pos;
    if (build_node(b, clo, chi, off + nr, nl, depth + 1, budget * (double)(int64_t)wl / (double)(int64_t)w))
        return -1;
    if (b->nnodes >= KD_MAX_PRIMS)
        return -1;
    b->nodes[idx].flags |= (uint32_t)b->nnodes << 2;
    clo[sp.axis] = sp.pos;
    chi[sp.axis] = hi[sp.axis];
    return build_node(b, clo, chi, off, nr, depth + 1, budget * (double)(int64_t)(w - wl) / (double)(int64_t)w);
}

static void build_free(kd_build *b)
{
    size_t i;
    for (i = 0; i < b->ntasks; i++)
        build_free(&b->tasks[i].b);
    rtpi_free(b->a, b->tasks);
    rtpi_free(b->a, b->ref);
    rtpi_free(b->a, b->nodes);
    rtpi_free(b->a, b->refs);
}

void rtpi_kd_destroy(rtpi_kdtree *kd)
{
    rtp_allocator a;
    if (!kd)
        return;
    a = kd->alloc;
    rtpi_free(&a, kd->nodes);
    rtpi_free(&a, kd->refs);
    rtpi_free(&a, kd->tri);
    rtpi_free(&a, kd->path);
    rtpi_free(&a, kd->path_at);
    rtpi_free(&a, kd);
}

/* Writes the subtree of the top build's node i at kd->nodes[kd->nnodes],
   in the order one recursion writes it (the below child next, the above
   one after the below subtree), relocating each task's nodes and leaf
   lists. */
static void assemble(rtpi_kdtree *kd, const kd_build *top, uint32_t i)
{
    const kd_node *nd = &top->nodes[i];
    if ((nd->flags & 3) == 3) {
        const kd_build *t = &top->tasks[nd->a.off].b;
        kd_node *out = kd->nodes + kd->nnodes;
        uint32_t base = (uint32_t)kd->nnodes, rbase = (uint32_t)kd->nrefs;
        size_t j;
        for (j = 0; j < t->nnodes; j++) {
            kd_node x = t->nodes[j];
            if ((x.flags & 3) != 3)
                x.flags += base << 2;
            else if ((x.flags >> 2) > 1)
                x.a.off += rbase;
            out[j] = x;
        }
        if (t->nrefs)
            memcpy(kd->refs + kd->nrefs, t->refs, t->nrefs * sizeof *t->refs);
        kd->nnodes += t->nnodes;
        kd->nrefs += t->nrefs;
    } else {
        size_t idx = kd->nnodes++;
        kd->nodes[idx].a.split = nd->a.split;
        assemble(kd, top, i + 1);
        kd->nodes[idx].flags = (nd->flags & 3) | (uint32_t)kd->nnodes << 2;
        assemble(kd, top, nd->flags >> 2);
    }
}

/* The tasks in the order threads take them: largest first, so that the
   last one to finish is a small one.  Insertion sort: a few dozen. */
typedef struct kd_run {
    kd_task *tasks;
    size_t *order;
} kd_run;

static int run_task(void *ctx, int row)
{
    kd_run *r = (kd_run *)ctx;
    kd_task *t = &r->tasks[r->order[row]];
    return build_node(&t->b, t->lo, t->hi, 0, t->n, t->depth, t->budget);
}

/* Builds every task on up to nthreads threads.  @return 0 or -1. */
static int run_tasks(kd_build *top, int nthreads)
{
    kd_run run;
    void *ctx[KD_MAX_THREADS];
    size_t i, j, n = top->ntasks;
    int ret, k;
    rtpi_locked_alloc lk;
    if (n == 0)
        return 0;
    run.tasks = top->tasks;
    run.order = (size_t *)rtpi_malloc_array(top->a, n, sizeof(size_t));
    if (!run.order)
        return -1;
    for (i = 0; i < n; i++) {
        size_t x = i;
        for (j = i; j > 0 && top->tasks[run.order[j - 1]].n < top->tasks[x].n; j--)
            run.order[j] = run.order[j - 1];
        run.order[j] = x;
    }
    if (nthreads > KD_MAX_THREADS)
        nthreads = KD_MAX_THREADS;
    if ((size_t)nthreads > n)
        nthreads = (int)n;
    for (k = 0; k < KD_MAX_THREADS; k++)
        ctx[k] = &run;
    /* the caller's allocator need not be thread-safe: while tasks run on
       several threads every call goes through one lock */
    if (nthreads > 1 && rtpi_locked_alloc_init(&lk, top->a) == 0) {
        for (i = 0; i < n; i++)
            top->tasks[i].b.a = &lk.a;
        ret = rtpi_parallel_rows((int)n, nthreads, ctx, run_task, NULL, NULL);
        for (i = 0; i < n; i++)
            top->tasks[i].b.a = top->a;
        rtpi_locked_alloc_destroy(&lk);
        rtpi_free(top->a, run.order);
        return ret ? -1 : 0;
    }
    ret = rtpi_parallel_rows((int)n, 1, ctx, run_task, NULL, NULL);
    rtpi_free(top->a, run.order);
    return ret ? -1 : 0;
}

/* Lists after each primitive of kd's leaves the others alike to it
   (kd_group's lists, same).  @return 0, or -1 when out of memory. */
static int kd_expand(rtpi_kdtree *kd, const uint32_t *same)
{
    size_t i, j, total = 0, at = 0;
    uint32_t *refs, p;
    for (i = 0; i < kd->nnodes; i++) {
        const kd_node *nd = &kd->nodes[i];
        uint32_t cnt = nd->flags >> 2;
        const uint32_t *list = cnt == 1 ? &nd->a.one : kd->refs + nd->a.off;
        if ((nd->flags & 3) != 3)
            continue;
        for (j = 0; j < cnt; j++)
            for (p = list[j]; p != RTPI_NONE; p = same[p])
                total++;
    }
    if (total > 0xffffffffu)
        return -1;
    refs = (uint32_t *)rtpi_malloc_array(&kd->alloc, total ? total : 1, sizeof *refs);
    if (!refs)
        return -1;
    for (i = 0; i < kd->nnodes; i++) {
        kd_node *nd = &kd->nodes[i];
        uint32_t cnt = nd->flags >> 2;
        const uint32_t *list = cnt == 1 ? &nd->a.one : kd->refs + nd->a.off;
        size_t from = at;
        if ((nd->flags & 3) != 3)
            continue;
        for (j = 0; j < cnt; j++)
            for (p = list[j]; p != RTPI_NONE; p = same[p])
                refs[at++] = p;
        /* (fewer than 2^30: they are primitives) */
        nd->flags = 3u | (uint32_t)(at - from) << 2;
        if (at - from <= 1) { /* (none: an empty leaf, off 0) */
            nd->a.one = at > from ? refs[from] : 0;
            at = from;
        } else {
            nd->a.off = (uint32_t)from;
        }
    }
    rtpi_free(&kd->alloc, kd->refs);
    kd->refs = refs;
    kd->nrefs = at;
    return 0;
}

/* The references of every primitive into r, their bounds rounded
   outward to floats, and the box of them all in lo, hi; degenerate or
   non-finite primitives never hit and are left out.  @return how many. */
static size_t kd_refs(const rtp_scene *s, const rtpi_kdtree *kd, kd_ref *ref, float *lo,
                      float *hi)
{
    size_t np = rtpi_scene_nprims(s), i, nvalid = 0;
    int k;
    for (k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    for (i = 0; i < np; i++) {
        double dlo[3], dhi[3];
        kd_ref *r = ref + nvalid;
        int ok = 1;
        if (i < s->ntris) {
            const float *v = kd->tri + 9 * i;
            ok = !rtpi_tri_degenerate(v, v + 3, v + 6);
        }
        rtpi_prim_bounds(s, (uint32_t)i, dlo, dhi);
        for (k = 0; k < 3; k++) {
            if (!(dlo[k] <= dhi[k]) || !(fabs(dlo[k]) < 1e30) ||
                !(fabs(dhi[k]) < 1e30))
                ok = 0;
        }
        if (!ok)
            continue;
        r->prim = (uint32_t)i;
        for (k = 0; k < 3; k++) {
            r->lo[k] = f_down(dlo[k]);
            r->hi[k] = f_up(dhi[k]);
            lo[k] = r->lo[k] < lo[k] ? r->lo[k] : lo[k];
            hi[k] = r->hi[k] > hi[k] ? r->hi[k] : hi[k];
        }
        nvalid++;
    }
    return nvalid;
}

rtp_status rtpi_kd_build(const rtp_scene *s, const rtp_allocator *alloc,
                         rtpi_kdtree **out, rtp_error *err)
{
    return rtpi_kd_build_mt(s, alloc, 1, out, err);
}

rtp_status rtpi_kd_build_mt(const rtp_scene *s, const rtp_allocator *alloc,
                            int nthreads, rtpi_kdtree **out, rtp_error *err)
{
    rtp_allocator a;
    rtpi_kdtree *kd;
    kd_build top;
    size_t np = rtpi_scene_nprims(s), i, nvalid = 0, nn, nr, nw;
    uint32_t *same = NULL;
    float lo[3], hi[3];
    int k, pass;
    double lg;

    *out = NULL;
    rtpi_allocator_init(&a, alloc);
    if (np >= KD_MAX_PRIMS)
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "kd-tree: %lu primitives, at most %lu",
                          (unsigned long)np, (unsigned long)KD_MAX_PRIMS - 1);
    kd = (rtpi_kdtree *)rtpi_malloc(&a, sizeof *kd);
    if (!kd)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    memset(kd, 0, sizeof *kd);
    kd->alloc = a;
    kd->scene = s;
    kd->ntris = s->ntris;
    memset(&top, 0, sizeof top);
    if (np > 0) {
        kd->tri = (float *)rtpi_malloc_array(&a, s->ntris ? s->ntris : 1,
                                             9 * sizeof(float));
        if (!kd->tri)
            goto nomem;
    }
    for (i = 0; i < s->ntris; i++) {
        const rtpi_tri *t = &s->tris[i];
        for (k = 0; k < 3; k++)
            memcpy(kd->tri + 9 * i + 3 * k, s->pos + 3 * (size_t)t->v[k],
                   3 * sizeof(float));
    }

    /* Built once, or twice where the first build met primitives alike in
       a node its look-ahead split (kd_group): the second builds them as
       one. */
    for (pass = 0;; pass++) {
        memset(&top, 0, sizeof top);
        top.a = &kd->alloc;
        top.kd = kd;
        top.check = pass == 0;
        if (np > 0) {
            top.ref = (kd_ref *)rtpi_malloc_array(&a, np, 2 * sizeof(kd_ref));
            if (!top.ref)
                goto nomem;
            top.ref_cap = 2 * np;
        }
        nvalid = kd_refs(s, kd, top.ref, lo, hi);
        /* (the first pass only: the second builds each group as one, so
           no two of its references are alike) */
        if (pass == 0 && nvalid > 1 && (top.leaf_alike = kd_node_alike(&top, 0, nvalid)) < 0)
            goto nomem;
        nw = nvalid; /* what the references weigh, copies and all */
        if (pass && kd_group(&a, kd, np, top.ref, &nvalid, &same))
            goto nomem;
        top.wt = same ? same + np : NULL;

        if (nvalid > 0) {
            kd->has_box = 1;
            for (k = 0; k < 3; k++) {
                kd->lo[k] = lo[k];
                kd->hi[k] = hi[k];
                kd->maxabs[k] = fmax(fabs(kd->lo[k]), fabs(kd->hi[k]));
                kd->boxabs = fmax(kd->boxabs, kd->maxabs[k]);
                kd->tol_in[k] = KD_SLACK * kd->maxabs[k];
                kd->ahead[0][k] = kd->hi[k];
                kd->ahead[1][k] = kd->lo[k];
            }
        } else {
            for (k = 0; k < 3; k++)
                lo[k] = hi[k] = 0.0f;
        }

        lg = nw > 1 ? log((double)nw) / log(2.0) : 0.0;
        top.max_depth = (int)(KD_DEPTH_A + KD_DEPTH_B * lg);
        if (top.max_depth > KD_DEPTH_CAP)
            top.max_depth = KD_DEPTH_CAP;
        /* Tasks of at most 1/KD_TASKS of the references (however many
           threads: the tree must not depend on them), and none smaller
           than KD_TASK_MIN, where a thread's start costs more than it
           saves. */
        top.task_max = nvalid / KD_TASKS;
        if (top.task_max < KD_TASK_MIN)
            top.task_max = KD_TASK_MIN;
        if (build_node(&top, lo, hi, 0, nvalid, 0,
                       KD_REF_BUDGET * (double)nw + KD_REF_FLOOR) == 0) {
            rtpi_free(top.a, top.ref); /* the tasks have their own copies */
            top.ref = NULL;
            if (run_tasks(&top, nthreads) == 0)
                break;
        }
        /* (whether a task saw them: the run stops at the first that
           fails, but a tree saw them only if a task of it would) */
        for (i = 0; i < top.ntasks; i++)
            top.saw |= top.tasks[i].b.saw;
        if (!top.saw)
            goto nomem;
        build_free(&top);
    }

    /* Put the pieces together. */
    nn = top.nnodes - top.ntasks;
    nr = 0;
    for (i = 0; i < top.ntasks; i++) {
        const kd_build *t = &top.tasks[i].b;
        nn += t->nnodes;
        nr += t->nrefs;
        if (t->depth_seen > top.depth_seen)
            top.depth_seen = t->depth_seen;
    }
    if (nn >= KD_MAX_PRIMS || nr > 0xffffffffu)
        goto nomem;
    kd->nodes = (kd_node *)rtpi_malloc_array(&a, nn, sizeof *kd->nodes);
    kd->refs = (uint32_t *)rtpi_malloc_array(&a, nr ? nr : 1, sizeof *kd->refs);
    if (!kd->nodes || !kd->refs)
        goto nomem;
    assemble(kd, &top, 0);
    if (same && kd_expand(kd, same))
        goto nomem;

    kd->stats.nodes = kd->nnodes;
    kd->stats.depth = top.depth_seen;
    for (i = 0; i < kd->nnodes; i++) {
        if ((kd->nodes[i].flags & 3) == 3) {
            size_t c = kd->nodes[i].flags >> 2;
            kd->stats.leaves++;
            kd->stats.prim_refs += c;
            kd->stats.empty_leaves += c == 0;
        }
    }
    build_free(&top);
    rtpi_free(&a, same);
    *out = kd;
    return RTP_OK;

nomem:
    build_free(&top);
    rtpi_free(&a, same);
    rtpi_kd_destroy(kd);
    return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                      "out of memory building the kd-tree");
}

double rtpi_kd_far(const rtpi_kdtree *kd, rtpi_v3 L)
{
    double l[3], d2 = 0.0;
    int k;
    if (!kd->has_box)
        return 0.0;
    l[0] = L.x;
    l[1] = L.y;
    l[2] = L.z;
    for (k = 0; k < 3; k++) {
        double a = fmax(fabs(l[k] - kd->lo[k]), fabs(l[k] - kd->hi[k]));
        d2 += a * a;
    }
    return sqrt(d2);
}

void rtpi_kd_get_stats(const rtpi_kdtree *kd, rtpi_kd_stats *st)
{
    *st = kd->stats;
}

/* ============================================================ traversal */

/* Built with -DKD_COUNT (never in the library proper: it is global
   state), the traversal counts interior steps, leaves, intersection tests
   and rays in kd_cnt, which bench_kd built the same way reports. */
#ifdef KD_COUNT
unsigned long long kd_cnt[4];
#define KD_CNT(i) (kd_cnt[i]++)
#else
#define KD_CNT(i) ((void)0)
#endif

typedef struct kd_ray {
    double o[3], inv[3], slack[3], tol[3];
    unsigned par;    /* bit k: the direction is exactly 0 on axis k */
    unsigned neg;    /* bit k: direction < 0, the above child comes first */
} kd_ray;

typedef struct kd_item {
    double t0, t1;
    uint32_t node;
} kd_item;

/* kd_ray_setup for axis k (a constant where it is inlined: the loop over
   the axes, not unrolled by gcc -O2, had cost 4 instructions an axis and
   the shift of the sign bit by a variable 3 more, of tree_s11's 43).
   @return 0 when the ray misses the root box on this axis. */
static RTPI_FORCE_INLINE int kd_axis_setup(const rtpi_kdtree *kd, kd_ray *kr, double d, int k,
                                           double *a0, double *a1, int in)
{
    /* fmax without the call; a NaN origin gives maxabs, as fmax.  (in:
       maxabs, the origin lying inside the box, |o| <= maxabs; the third
       exact move of test/instr/run.sh, 512^2 SPD, M: balls 356.6 ->
       350.3, rings 597.1 -> 593.4, tree 195.8 -> 193.5, gears 275.4 ->
       274.8, teapot 294.8 -> 294.5, but mount 368.1 -> 368.5, tetra
       36.78 -> 36.82) */
    double ao = fabs(kr->o[k]);
    double m;
    if (in == 2) {
        /* a kept leaf's walk as in (below) without the test of d against
           0, the par bit and tol: tol_in, the same product, is > 0 there
           (rtpi_kd_path_of refuses a tol below KD_PATH_TOL), so a 0 on
           an axis makes inv and the slack infinite, which kd_occluder's
           check of the slacks' sum sends to the full set-up (in 1) and
           the walk from the root; a 0 leaves a1 as it is here (tb +
           slack NaN or +inf).  The direction's sign bits as below. */
        uint64_t b;
        double tb;
        memcpy(&b, &d, sizeof b);
        kr->neg |= (unsigned)(b >> 63) << k;
        kr->inv[k] = 1.0 / d;
        kr->slack[k] = kd->tol_in[k] * fabs(kr->inv[k]);
        /* the face ahead by the sign bit (d < 0's for every d not 0 or
           NaN, which do not walk from here) */
        tb = (kd->ahead[b >> 63][k] - kr->o[k]) * kr->inv[k] + kr->slack[k];
        *a1 = tb < *a1 ? tb : *a1;
        return 1;
    }
    m = in ? kd->maxabs[k] : ao > kd->maxabs[k] ? ao : kd->maxabs[k];
    kr->tol[k] = KD_SLACK * m;
    {
        /* the sign bit: d < 0 but for -0 and a NaN, whose neg no walk
           reads (a 0 on an axis takes kd_descend's par branch there and
           walks from the root; a NaN direction is refused by
           rtpi_wt_valid and rtpi_wt_setup before the walk); the compare
           and its flag cost ~2 instructions more an axis */
        uint64_t b;
        memcpy(&b, &d, sizeof b);
        kr->neg |= (unsigned)(b >> 63) << k;
    }
    if (d == 0.0) {
        kr->par |= 1u << k;
        kr->inv[k] = 0.0;
        kr->slack[k] = 0.0;
        if (kr->o[k] < kd->lo[k] - kr->tol[k] || kr->o[k] > kd->hi[k] + kr->tol[k])
            return 0;
    } else if (in) {
        /* the origin 2 tol or more inside the root box (a kept leaf's,
           rtpi_kd_path_of of the ray's origin): the face behind it clips
           nothing (ta - slack < 0 = tmin, the walks' contract a shadow
           ray's tmin 0: the argument at kd_pe), and the face ahead is the
           one below's tb, the same expression (its ta > tb swap), NaN
           alike */
        double tb;
        kr->inv[k] = 1.0 / d;
        kr->slack[k] = kr->tol[k] * fabs(kr->inv[k]);
        tb = ((d < 0.0 ? kd->lo[k] : kd->hi[k]) - kr->o[k]) * kr->inv[k];
        if (tb + kr->slack[k] < *a1)
            *a1 = tb + kr->slack[k];
    } else {
        double ta, tb, x;
        kr->inv[k] = 1.0 / d;
        kr->slack[k] = kr->tol[k] * fabs(kr->inv[k]);
        ta = (kd->lo[k] - kr->o[k]) * kr->inv[k];
        tb = (kd->hi[k] - kr->o[k]) * kr->inv[k];
        if (ta > tb) {
            x = ta;
            ta = tb;
            tb = x;
        }
        /* Written so that a NaN leaves the interval as it is. */
        if (ta - kr->slack[k] > *a0)
            *a0 = ta - kr->slack[k];
        if (tb + kr->slack[k] < *a1)
            *a1 = tb + kr->slack[k];
    }
    return 1;
}

/* Prepares the ray and clips it to the root box.
   @return 0 when it misses the box or its interval is empty. */
static RTPI_FORCE_INLINE int kd_ray_setup(const rtpi_kdtree *kd, const rtpi_ray *r, kd_ray *kr,
                        double *t0, double *t1, int in)
{
    double a0 = r->tmin, a1 = r->tmax;
    if (!kd->has_box)
        return 0;
    kr->o[0] = r->o.x;
    kr->o[1] = r->o.y;
    kr->o[2] = r->o.z;
    kr->par = kr->neg = 0;
    /* (in tested once a walk, not at each axis: a kept leaf's walks,
       the third exact move of test/instr/run.sh, 512^2 SPD, M
       instructions: balls 358.3 -> 356.3, mount 372.4 -> 368.4, teapot
       299.0 -> 295.6, rings 605.7 -> 604.6, gears 277.1 -> 275.8, tetra
       37.3 -> 36.9, but tree 196.0 -> 197.1, its walk's loop compiled
       differently) */
    if (in == 2) {
        kd_axis_setup(kd, kr, r->d.x, 0, &a0, &a1, 2);
        kd_axis_setup(kd, kr, r->d.y, 1, &a0, &a1, 2);
        kd_axis_setup(kd, kr, r->d.z, 2, &a0, &a1, 2);
    } else if (in) {
        if (!kd_axis_setup(kd, kr, r->d.x, 0, &a0, &a1, 1) ||
            !kd_axis_setup(kd, kr, r->d.y, 1, &a0, &a1, 1) ||
            !kd_axis_setup(kd, kr, r->d.z, 2, &a0, &a1, 1))
            return 0;
    } else if (!kd_axis_setup(kd, kr, r->d.x, 0, &a0, &a1, 0) ||
               !kd_axis_setup(kd, kr, r->d.y, 1, &a0, &a1, 0) ||
               !kd_axis_setup(kd, kr, r->d.z, 2, &a0, &a1, 0))
        return 0;
    *t0 = a0;
    *t1 = a1;
    return a0 <= a1;
}

/* Walks down from `node` over [*t0,*t1] to the first leaf the ray may
   meet, pushing the far children it will need later.  One interior step:
   a plane crossed outside the interval (widened by the slack) leaves one
   child, else both are visited, the near one first; a ray parallel to
   the plane stays on its side, or runs in it and visits both.  par: 0
   where kr->par is 0 (the direction is 0 on no axis: nearly every ray),
   which leaves its test out of each step.  skip (shadow rays, whose
   walk any hit ends: the order of the leaves is theirs to choose, yet
   kept): 1, a far child that is an empty leaf is not pushed (an empty
   leaf holds nothing to test); 2, also an empty leaf reached otherwise
   pops the next pending node here, not in the caller.  teapot_s12's
   shadow rays visited 820 k leaves, 494 k of them empty.  Measured
   (callgrind, a moved light's third `exact` move, 512^2 SPD, M
   instructions; 2 where kd_occluder is lazy, else 1): teapot 380.0 ->
   374.3, mount 479.8 -> 471.8, rings 782.3 -> 771.6, tree 219.8 ->
   218.2, balls 413.6 -> 411.3, tetra 48.61 -> 48.27, gears 331.3 ->
   332.0.  Tried: the near child too, an empty one left for the far at
   once (teapot 375.9, mount 478.4, gears 333.2); 2 for every scene
   (teapot 374.6, gears 333.0); 1 for every scene (rings 777.4, tree
   221.1).  rtpi_kd_intersect passes 0: not measured for nearest hits.
   Tried (session 51, the third exact move, 512^2 SPD): the step without
   branches (the near child by a mask of the direction's sign, the far
   entry written always and sp += a 0/1 flag, t1 and the next node by
   selects, SSE2's for t1): callgrind's mispredictions balls 3.47 -> 2.18
   M, teapot 2.43 -> 1.44, mount 3.35 -> 2.76, but instructions balls
   339.1 -> 402.5 M, teapot 284.9 -> 329.2, mount 346.0 -> 382.2 and the
   time +16% (balls, interleaved runs): the next node's load then waits
   for the compares, where a predicted branch lets it start at once; the
   near child alone by the mask: balls 345.7, no faster.  (gcc turns a
   plain `a ? x : y` on doubles here back into a branch.)
   @return the leaf's index (empty only where nothing is pending). */
static RTPI_FORCE_INLINE uint32_t kd_descend(const kd_node *nodes,
                                             const kd_ray *kr, uint32_t node,
                                             double *t0p, double *t1p,
                                             kd_item *stack, int *spp, int par, int skip)
{
    double t0 = *t0p, t1 = *t1p;
    int sp = *spp;
    for (;;) {
        const kd_node *nd = &nodes[node];
        uint32_t fl = nd->flags, ax = fl & 3, above = fl >> 2,
                 below = node + 1;
        double split = nd->a.split;
        if (ax == 3) {
            if (skip > 1 && fl == 3u && sp > 0) {
                /* an empty leaf: the next pending node at once */
                sp--;
                node = stack[sp].node;
                t0 = stack[sp].t0;
                t1 = stack[sp].t1;
                continue;
            }
            break;
        }
        KD_CNT(0);
        if (par && (kr->par >> ax & 1)) {
            double dd = split - kr->o[ax];
            if (dd > kr->tol[ax]) {
                node = below;
            } else if (dd < -kr->tol[ax]) {
                node = above;
            } else {
                stack[sp].node = above;
                stack[sp].t0 = t0;
                stack[sp].t1 = t1;
                sp++;
                node = below;
            }
        } else {
            double ts = (split - kr->o[ax]) * kr->inv[ax];
            double lo = ts - kr->slack[ax], hi = ts + kr->slack[ax];
            int neg = (int)(kr->neg >> ax & 1);
            uint32_t nearc = neg ? above : below;
            uint32_t farc = neg ? below : above;
            if (hi < t0) {
                node = farc;
            } else if (lo > t1) {
                node = nearc;
            } else {
                if (!skip || nodes[farc].flags != 3u) {
                    stack[sp].node = farc;
                    stack[sp].t0 = lo > t0 ? lo : t0;
                    stack[sp].t1 = t1;
                    sp++;
                }
                if (hi < t1)
                    t1 = hi;
                node = nearc;
            }
        }
    }
    *t0p = t0;
    *t1p = t1;
    *spp = sp;
    return node;
}

/* ------------------------------------ walks from the origin's own leaf

   A moved light's shadow rays start at points that stay where they are
   (a node's origin, o, depends on the light only through the side of its
   surface the light lies on); only the light moves.  Half and more of a
   lit ray's interior steps came before its first non-empty leaf: the
   descent from the root to o's own leaf (helper 160, session 45: mount_s6
   66%).  Where o lies 2 tol or more inside every plane on its leaf's path
   and every face of the root box (tol the walk's, kd_axis_setup: a
   function of o alone), the walk from the root is known without taking
   it, for any direction not 0 on an axis:
   - the root box's clip leaves t0 at 0 (tmin 0: rtpi_shadow_ray's), by
     the argument below for a plane moved away from;
   - an ancestor whose plane the ray moves away from: D = split - o[ax] by
     the walk's arithmetic is 2 tol or more on o's side, so |ts| = |D|
     |inv| rounds to at least twice the slack tol |inv| (a normal number:
     tol >= KD_PATH_TOL and |inv| >= 1e-18), hi = ts + slack <= -slack <
     0 = t0, and the walk takes o's side alone, pushing nothing, its
     interval unchanged;
   - an ancestor whose plane the ray moves towards: ts >= 0 = t0, never hi
     < t0, so the walk goes to o's side, pushing the other child where lo
     <= t1 and cutting t1 to hi: the same arithmetic done here, from the
     leaf's list for the ray's octant (kd_pe), root first.
   So the stack, t0 and t1 at o's leaf are the root walk's, bit for bit,
   and the rest of the walk, its leaves in their order and its answer with
   them.  The walk checks the rest itself: no direction 0 on an axis
   (kr.par: from the root), every slack finite, |d_x| + |d_y| + |d_z| <=
   1e18 (|inv| >= 1e-18).  Measured (callgrind, the third `exact` move,
   512^2 SPD): see rtpi_kd_occluder_planes_from. */

typedef struct kd_pe {
    union {
        float split;   /* an ancestor's plane (kd_node's) */
        uint32_t leaf; /* the header's: the leaf */
    } u;
    /* an ancestor's: bits 4-31 its child away from the leaf, bit 3 that
       child an empty leaf (not pushed: kd_descend's skip), bit 2 the leaf
       above the plane, bits 0-1 the axis (c & 3, one shift less an entry
       than at bits 1-2: the third exact move, 512^2 SPD, M, balls 333.6
       -> 332.5, mount 340.4 -> 339.4, teapot 280.4 -> 279.2); the
       header's: its depth */
    uint32_t code;
} kd_pe;

/* A leaf's block's header and its octants' starts (kd_path_fill) */
#define KD_PATH_HEAD 9u

/* The least tol a path is made for (its slack then normal: 1e-280 *
   1e-18 > DBL_MIN); coordinates of 1e-269 and more. */
#define KD_PATH_TOL 1e-280

/* Entries of every leaf's lists (KD_PATH_HEAD + 4 an ancestor: each is
   in the lists of the 4 octants whose rays move towards its plane from
   the leaf's side); 0 where the tree has more nodes than a code names. */
static size_t kd_path_count(const rtpi_kdtree *kd)
{
    uint32_t st[KD_DEPTH_CAP + 8], dp[KD_DEPTH_CAP + 8];
    size_t total = 0;
    int n = 0;
    if (!kd->nnodes || kd->nnodes >= (1u << 28))
        return 0;
    st[n] = 0;
    dp[n++] = 0;
    while (n > 0) {
        uint32_t q, d;
        n--;
        q = st[n];
        d = dp[n];
        if ((kd->nodes[q].flags & 3u) == 3u) {
            total += KD_PATH_HEAD + 4 * (size_t)d;
            continue;
        }
        if (n + 2 > KD_DEPTH_CAP + 8)
            return 0; /* (deeper than the build makes) */
        st[n] = kd->nodes[q].flags >> 2;
        dp[n++] = d + 1;
        st[n] = q + 1;
        dp[n++] = d + 1;
    }
    return total;
}

/* A leaf's block: its header (u.leaf the leaf), then for each octant
   (bit k: the ray's direction < 0 on axis k, kd_ray's neg) the start of
   its list, from the header, in u.leaf and its length in code, then the
   lists: the ancestors whose planes such rays move towards, root
   first. */
static void kd_path_fill(rtpi_kdtree *kd, uint32_t node, kd_pe *cur, uint32_t depth, size_t *k)
{
    const kd_node *nd = &kd->nodes[node];
    uint32_t ax = nd->flags & 3u, above = nd->flags >> 2;
    if (ax == 3u) {
        kd_pe *h = kd->path + *k;
        uint32_t oct, i, pos = KD_PATH_HEAD;
        h->u.leaf = node;
        h->code = depth;
        for (oct = 0; oct < 8; oct++) {
            h[1 + oct].u.leaf = pos;
            for (i = 0; i < depth; i++) {
                uint32_t c = cur[i].code;
                if ((oct >> (c & 3u) & 1u) == (c >> 2 & 1u))
                    h[pos++] = cur[i];
            }
            h[1 + oct].code = pos - h[1 + oct].u.leaf;
        }
        kd->path_at[node] = (uint32_t)*k;
        *k += pos;
        return;
    }
    cur[depth].u.split = nd->a.split;
    cur[depth].code = above << 4 | (uint32_t)(kd->nodes[above].flags == 3u) << 3 | ax;
    kd_path_fill(kd, node + 1, cur, depth + 1, k);
    cur[depth].code =
        (node + 1) << 4 | (uint32_t)(kd->nodes[node + 1].flags == 3u) << 3 | 1u << 2 | ax;
    kd_path_fill(kd, above, cur, depth + 1, k);
}

/* kd_path_count once a tree (a move asks it while the lists are not
   made: a pass over the nodes each time) */
static size_t kd_path_n(rtpi_kdtree *kd)
{
    if (!kd->path_n) {
        size_t n = kd_path_count(kd);
        kd->path_n = n ? n : (size_t)-1;
    }
    return kd->path_n == (size_t)-1 ? 0 : kd->path_n;
}

double rtpi_kd_paths_bytes(rtpi_kdtree *kd)
{
    size_t n = kd ? kd_path_n(kd) : 0;
    return n ? (double)n * sizeof(kd_pe) + 4.0 * (double)kd->nnodes : HUGE_VAL;
}

int rtpi_kd_paths_make(rtpi_kdtree *kd)
{
    kd_pe cur[KD_DEPTH_CAP + 8];
    size_t n, k = 0;
    if (!kd)
        return -1;
    if (kd->path)
        return 0;
    n = kd_path_n(kd);
    if (!n || n >= 0x7ffffff0u)
        return -1;
    kd->path = (kd_pe *)rtpi_malloc_array(&kd->alloc, n, sizeof *kd->path);
    kd->path_at = (uint32_t *)rtpi_malloc_array(&kd->alloc, kd->nnodes, sizeof *kd->path_at);
    if (!kd->path || !kd->path_at) {
        rtpi_free(&kd->alloc, kd->path);
        rtpi_free(&kd->alloc, kd->path_at);
        kd->path = NULL;
        kd->path_at = NULL;
        return -1;
    }
    memset(kd->path_at, 0xff, kd->nnodes * sizeof *kd->path_at);
    kd_path_fill(kd, 0, cur, 0, &k);
    return 0;
}

uint32_t rtpi_kd_path_of(const rtpi_kdtree *kd, rtpi_v3 o)
{
    const kd_node *nodes = kd->nodes;
    double p[3], tol[3];
    uint32_t node = 0;
    int k;
    if (!kd->path || !kd->has_box)
        return RTPI_NONE;
    p[0] = o.x;
    p[1] = o.y;
    p[2] = o.z;
    for (k = 0; k < 3; k++) {
        /* kd_axis_setup's tol, by its arithmetic */
        double ao = fabs(p[k]);
        double m = ao > kd->maxabs[k] ? ao : kd->maxabs[k];
        tol[k] = KD_SLACK * m;
        if (!(ao <= DBL_MAX && tol[k] >= KD_PATH_TOL))
            return RTPI_NONE;
        /* inside the root box by 2 tol, as inside the planes below: the
           walk's clip (kd_axis_setup) leaves t0 at 0 */
        if (!(p[k] - kd->lo[k] >= 2.0 * tol[k] && kd->hi[k] - p[k] >= 2.0 * tol[k]))
            return RTPI_NONE;
    }
    while ((nodes[node].flags & 3u) != 3u) {
        uint32_t fl = nodes[node].flags, ax = fl & 3u;
        double dd = (double)nodes[node].a.split - p[ax]; /* (kd_descend's) */
        if (dd >= 2.0 * tol[ax])
            node = node + 1;
        else if (dd <= -2.0 * tol[ax])
            node = fl >> 2;
        else
            return RTPI_NONE;
    }
    return kd->path_at[node];
}

int rtpi_kd_intersect(const rtpi_kdtree *kd, const rtpi_ray *ray,
                      rtpi_hit *hit)
{
    kd_item stack[KD_DEPTH_CAP + 4];
    kd_ray kr;
    rtpi_wt_ray w;
    const kd_node *nodes = kd->nodes;
    const float *tri = kd->tri;
    const uint32_t *refs = kd->refs;
    const rtp_scene *s = kd->scene;
    uint32_t ntris = (uint32_t)kd->ntris, nspheres = (uint32_t)s->nspheres;
    double t0, t1, best = ray->tmax, tmin = ray->tmin;
    double bt = 0.0, bu = 0.0, bv = 0.0;
    const double dd = v3_dot(ray->d, ray->d); /* (spheres' a) */
    rtpi_ray rb = *ray; /* the ray up to the best hit (spheres and cones) */
    uint32_t node = 0, bprim = 0;
    int sp = 0, found = 0;

    KD_CNT(3);
    if (!kd_ray_setup(kd, ray, &kr, &t0, &t1, 0) || !rtpi_wt_setup(&w, ray))
        return 0;
    for (;;) {
        node = kr.par ? kd_descend(nodes, &kr, node, &t0, &t1, stack, &sp, 1, 0)
                      : kd_descend(nodes, &kr, node, &t0, &t1, stack, &sp, 0, 0);
        KD_CNT(1);
        {
            const kd_node *nd = &nodes[node];
            uint32_t cnt = nd->flags >> 2, j;
            const uint32_t *list = cnt == 1 ? &nd->a.one : refs + nd->a.off;
            for (j = 0; j < cnt; j++) {
                uint32_t prim = list[j];
                KD_CNT(2);
                if (prim < ntris) {
                    const float *v = tri + 9 * (size_t)prim;
                    double t, u, v2;
                    if (rtpi_wt_tri(&w, v, v + 3, v + 6, tmin, best, &t, &u,
                                    &v2)) {
                        best = bt = t;
                        bu = u;
                        bv = v2;
                        bprim = prim;
                        found = 1;
                    }
                } else if (prim - ntris < nspheres) {
                    /* a sphere inline, by rtpi_intersect_prim's own test
                       (rtpi_sphere_t; u and v 0 as it gives them), with
                       dd made once a ray: through the call and a copy of
                       the ray it took 13% of balls' trace */
                    double t;
                    rb.tmax = best;
                    if (rtpi_sphere_t(&s->spheres[prim - ntris], &rb, dd, &t)) {
                        best = bt = t;
                        bu = bv = 0.0;
                        bprim = prim;
                        found = 1;
                    }
                } else if (prim - ntris - nspheres < s->ncones) {
                    /* a cone the same way (hit_cone's two steps; most
                       end at the first) */
                    const rtpi_cone_frame *cf = &s->cframes[prim - ntris - nspheres];
                    rtpi_v3 o2;
                    double tc, t;
                    rb.tmax = best;
                    if (rtpi_cone_near(cf, &rb, dd, &tc, &o2) &&
                        rtpi_cone_t(cf, &rb, dd, tc, o2, &t)) {
                        best = bt = t;
                        bu = bv = 0.0;
                        bprim = prim;
                        found = 1;
                    }
                }
            }
        }
        /* No "best <= t1: done" shortcut: the children of a plane the ray
           runs in, and the slack around a crossing, give siblings
           overlapping intervals.  Skipping every pending node that starts
           beyond the best hit is exact and costs a compare per entry. */
        for (;;) {
            if (sp == 0) {
                if (found) {
                    hit->t = bt;
                    hit->u = bu;
                    hit->v = bv;
                    hit->prim = bprim;
                }
                return found;
            }
            sp--;
            if (!found || stack[sp].t0 <= best)
                break;
        }
        node = stack[sp].node;
        t0 = stack[sp].t0;
        t1 = stack[sp].t1;
    }
}

/* Why the edges' test is exact.  rtpi_wt_tri's weights for a ray o + t d
   are, exactly, e_i = k [P, Q, d] with (P, Q) = (c - o, b - o), (a - o,
   c - o), (b - o, a - o) for i = 0, 1, 2 and one k != 0 for all three
   (the shear projects along d; its axes' order and the sign of d's
   largest component give k's sign, 1 / |d_kz| its size); [P, Q, L - o]
   = -(P' x Q').(o - L) with P', Q' the vertices less L, which is -n_i.(o
   - L), n_i as stored.  d is (L - o) / |L - o| to a few u (u = 2^-53),
   so for the exact d: e_i = -k' n_i.(o - L), k' = k / |L - o|, the same
   factor for all three.  Where one n_i.(o - L) is below -m and another
   above m, the exact e_i differ in sign by more than k' m; the computed
   ones then do too if each is within k' m of its exact value, and
   rtpi_wt_tri reports a miss ((lo < 0) & (hi > 0)).  Bounds, with every
   coordinate (vertices, light, o) at most S, so every difference at most
   R = 2 sqrt(3) S: the sheared coordinates are at most 2 R (|sx|, |sy| <=
   1) with errors below 10 u R (the differences, sx and sy from d's few u,
   the products), the weights then below 104 u R^2, which is k' times 104
   u R^2 |d_kz| |L - o| <= 104 u R^3 in n.(o - L)'s units; the direction's
   error is among sx's.  Here n_i (each component below 2 R^2, error below
   6 u R^2) and n_i.light, and the walk's n_i.o - n_i.light, err by less
   than 60 u R^3.  Together < 170 u R^3 < 8e-13 S^3, and m =
   RTPI_EDGE_MARGIN S^3 = 1e-9 S^3 is over a thousand times that.  S in
   [1e-90, 1e90] keeps every product (at most ~1e272) finite and m (at
   least 1e-279) far above the subnormals, where the errors would not be
   relative any more.  A NaN anywhere fails a comparison: no cull. */
void rtpi_tri_edges(const rtp_scene *s, rtpi_v3 light, double scale, const double *planes,
                    const rtp_allocator *a, double **out)
{
    size_t i;
    *out = NULL;
    if (!s->ntris || !planes || s->ntris > RTPI_EDGE_TRIS || !(scale >= 1e-90 && scale <= 1e90))
        return;
    /* (none where memory is short: a speed-up only, the walk's answers
       the same without it) */
    *out = (double *)rtpi_malloc_array(a, RTPI_EDGE_N * s->ntris, sizeof **out);
    if (!*out)
        return;
    for (i = 0; i < s->ntris; i++) {
        const double *q = planes + 4 * i;
        rtpi_tri_edge_entry(*out + RTPI_EDGE_N * i, s, &s->tris[i], light, q, q[3]);
    }
}

/* Whether a shadow ray towards the light of rtpi_round_cones' line test
   q (a cylinder cf's: m = w x (L - b), M, E, T; see there) certainly
   misses the cylinder: rtpi_cylinder_far's test with the light's half
   and the margins made once a light.  tl: ts ld (as there).  Rings: 83%
   of the cylinders a shadow ray asks pass rtpi_cone_near's sphere, which
   with rtpi_cylinder_far took 131 instructions.

   Why it is exact.  The ray's line passes within eL of the light L: o is
   exact, d = (L - o) / |L - o| is off by a few u (u = 2^-53) in
   direction, so eL <= 5 u |L - o| <= 1e-14 T (|L - o| is tmax / (1 -
   1e-9) <= ts ld = tl to rounding, and tl <= T is asked).  Its distance
   from the axis is then at least |(L - b).n^| - eL with n = d x w, and
   (L - b).n = d.m.  Computed, |d.m| is within 8 u |d| |L - b| of the
   true one (m's rounding, then the dot product's) and |n| within 5 u |d|:
   E |d| = 1e-14 |d| (|L - b| + M) on the right covers both.  So the test
   holding means the line passes farther than M - eL >= R + 1e-12 (S' +
   S'^2 / R) from the axis, S' = 2 bound + 2 |mid - L| + 3.01 T being at
   least rtpi_cylinder_far's S = 2 bound + (2 |tc| + ts) ld (|tc| ld <=
   |mid - o| <= |mid - L| + |L - o|): at least its margin (to a rounding
   of M far below that margin's factor 40), beyond which it shows
   rtpi_cone_t finds no hit.  T 0 (no test) or NaN never passes. */
static RTPI_FORCE_INLINE int kd_cylinder_line_far(const double *q, const rtpi_cone_frame *cf,
                                                  const rtpi_ray *ray, double ld, double tl)
{
    rtpi_v3 n;
    if (!(tl <= q[5]))
        return 0;
    n = v3_cross(ray->d, cf->w);
    return fabs(ray->d.x * q[0] + ray->d.y * q[1] + ray->d.z * q[2]) >
           q[3] * sqrt(v3_dot(n, n)) + q[4] * ld;
}

/* lazy: make the watertight set-up at the first triangle (for scenes
   mostly of spheres and cones, whose shadow rays may test none), else at
   once (a test for it at every triangle cost mesh scenes 5% of a shadow
   ray: tetra). */
/* pl: rtpi_tri_planes' planes, the ray's origin within their scale, or
   NULL; pc: rtpi_round_cones' cones or NULL; cn: 1 to test cones with
   the slots of those tested and rtpi_cylinder_far, 0 with their plain
   test, for scenes without cones: the former inline made the compiled
   loop dearer for triangles and spheres (gears', mount's and balls'
   moves 1-1.4%), and leaving the cones' branch out altogether did too
   (balls' 2%). */
static RTPI_FORCE_INLINE uint32_t kd_occluder(const rtpi_kdtree *kd, const rtpi_ray *ray,
                                              uint32_t skip, int lazy, const double *pl,
                                              const double *pe, double thr, const double *pc,
                                              int cn, const double *py, const rtpi_quad_k *qk,
                                              const kd_pe *path)
{
    kd_item stack[KD_DEPTH_CAP + 4];
    kd_ray kr;
    rtpi_wt_ray w;
    rtpi_edge_o eo; /* (pe's origin) */
    const kd_node *nodes = kd->nodes;
    const float *tri = kd->tri;
    const uint32_t *refs = kd->refs;
    const rtp_scene *s = kd->scene;
    uint32_t ntris = (uint32_t)kd->ntris, nspheres = (uint32_t)s->nspheres;
    double t0, t1, tmin = ray->tmin, tmax = ray->tmax;
    const double dd = v3_dot(ray->d, ray->d); /* (spheres' and cones' a) */
    const rtpi_v3 dn = v3_mul(ray->d, -1.0);   /* (the cones' test, as the light buffer's) */
    /* (rtpi_cylinder_far's) */
    const double ld = cn ? sqrt(dd) : 0.0, ts = cn ? fabs(tmin) + fabs(tmax) : 0.0;
    const double tl = ts * ld; /* (kd_cylinder_line_far's) */
    /* The cones this ray has tested, by their number's last 3 bits (all
       missed: a hit ends the walk).  A long thin cone lies in many
       leaves along a ray, and 29% of rings' shadow rays' cone tests were
       of a cone the same ray had tested in an earlier leaf.  The test is
       a function of the cone and the ray alone, so its answer again is a
       miss: skipping it changes no bit.  (Made at the first cone: mesh
       scenes' rays test none.) */
    uint32_t seen[8];
    /* (the cylinders' line tests after the round cones: rtpi_round_cones) */
    const double *cy = cn && pc ? pc + 4 * ((size_t)nspheres + s->ncones) : NULL;
    uint32_t node = 0;
    int sp = 0, wt = !lazy, sn = 0; /* wt: w made; sn: seen made */

    KD_CNT(3);
    /* (a shadow ray among spheres and cones never needs w: making it
       anyway was 2% of balls' moved-light shadow rays) */
    if (!kd_ray_setup(kd, ray, &kr, &t0, &t1, path ? 2 : 0) || !rtpi_wt_valid(ray))
        return RTPI_NONE;
    if (!lazy)
        rtpi_wt_make(&w, ray);
    if (pe)
        rtpi_edge_o_make(&eo, &ray->o);
    if (path && !(fabs(ray->d.x) + fabs(ray->d.y) + fabs(ray->d.z) <= 1e18 &&
                  kr.slack[0] + kr.slack[1] + kr.slack[2] <= DBL_MAX)) {
        /* (a 0 on an axis among them: kd_axis_setup's in 2) the set-up
           the walk from the root takes */
        path = NULL;
        if (!kd_ray_setup(kd, ray, &kr, &t0, &t1, 1))
            return RTPI_NONE;
    }
    if (path) {
        /* from o's own leaf (rtpi_kd_path_of): the ancestors whose planes
           the ray moves towards (its octant's list), as kd_descend steps
           over them; a direction 0 on an axis walks from the root */
        const kd_pe *q = path + path[1 + kr.neg].u.leaf;
        uint32_t cnt = path[1 + kr.neg].code, i;
        for (i = 0; i < cnt; i++) {
            uint32_t c = q[i].code, ax = c & 3u;
            double tq = ((double)q[i].u.split - kr.o[ax]) * kr.inv[ax];
            double lo = tq - kr.slack[ax], hi = tq + kr.slack[ax];
            if (lo > t1)
                continue;
            if (!(c & 8u)) {
                stack[sp].node = c >> 4;
                stack[sp].t0 = lo > t0 ? lo : t0;
                stack[sp].t1 = t1;
                sp++;
            }
            if (hi < t1)
                t1 = hi;
        }
        node = path->u.leaf;
    }
    for (;;) {
        node = kr.par ? kd_descend(nodes, &kr, node, &t0, &t1, stack, &sp, 1, lazy ? 2 : 1)
                      : kd_descend(nodes, &kr, node, &t0, &t1, stack, &sp, 0, lazy ? 2 : 1);
        KD_CNT(1);
        {
            const kd_node *nd = &nodes[node];
            uint32_t cnt = nd->flags >> 2, j;
            const uint32_t *list = cnt == 1 ? &nd->a.one : refs + nd->a.off;
            for (j = 0; j < cnt; j++) {
                uint32_t prim = list[j];
                if (prim == skip)
                    continue;
                KD_CNT(2);
                if (prim < ntris) {
                    const float *v = tri + 9 * (size_t)prim;
                    double t, u, v2;
                    if (pe) {
                        /* the plane's test below and the edges': the line
                           from the light through the origin passing
                           outside an edge (rtpi_tri_edges: the watertight
                           test's weights of two vertices then differ in
                           sign; teapot: 91% of the triangles past the
                           plane) */
                        int e = rtpi_edges_sure(pe + RTPI_EDGE_N * (size_t)prim, &eo, thr);
                        if (e == 0)
                            continue;
                        /* inside all three by the margin, t certainly in
                           range: rtpi_wt_tri's answer a hit, without it
                           (rtpi_edges_sure; w made: pe's walks are not
                           lazy) */
                        if (e == 1 &&
                            rtpi_wt_t_sure(v, v + 3, v + 6, w.kz, w.oz, w.sz, tmin, tmax))
                            return prim;
                    } else if (pl) {
                        /* the light on one side of its plane, the
                           origin too: missed (a terrain's shadow rays
                           leave half its tests so; as
                           rtpi_lightbuf_occluder's lists ask them) */
                        const double *q = pl + 4 * (size_t)prim;
                        if (q[0] * ray->o.x + q[1] * ray->o.y + q[2] * ray->o.z > q[3])
                            continue;
                    }
                    if (lazy && !wt) {
                        rtpi_wt_make(&w, ray);
                        wt = 1;
                    }
                    if (rtpi_wt_tri(&w, v, v + 3, v + 6, tmin, tmax, &t, &u,
                                    &v2))
                        return prim;
                } else if (pc && dn.x * pc[4 * (size_t)(prim - ntris)] +
                                         dn.y * pc[4 * (size_t)(prim - ntris) + 1] +
                                         dn.z * pc[4 * (size_t)(prim - ntris) + 2] <
                                     pc[4 * (size_t)(prim - ntris) + 3]) {
                    /* outside the directions it can be hit in from the
                       light (lb_cone: a dot product where the test takes
                       tens of operations and a square root) */
                    continue;
                } else if (prim - ntris < nspheres) {
                    double t;
                    if (rtpi_sphere_t(&s->spheres[prim - ntris], ray, dd, &t))
                        return prim;
                } else if (!cn && prim - ntris - nspheres < s->ncones) {
                    /* (cn 0: the plain test, without the slots and
                       rtpi_cylinder_far, as before them) */
                    const rtpi_cone_frame *cf = &s->cframes[prim - ntris - nspheres];
                    rtpi_v3 o2;
                    double tc, t;
                    if (rtpi_cone_near(cf, ray, dd, &tc, &o2) &&
                        rtpi_cone_t(cf, ray, dd, tc, o2, &t))
                        return prim;
                } else if (prim - ntris - nspheres < s->ncones) {
                    /* (a cone's first test inline: most end there) */
                    const rtpi_cone_frame *cf = &s->cframes[prim - ntris - nspheres];
                    rtpi_v3 o2;
                    double tc, t;
                    if (!sn) {
                        memset(seen, 0xff, sizeof seen); /* RTPI_NONE */
                        sn = 1;
                    } else if (seen[prim & 7u] == prim) {
                        continue;
                    }
                    if (py) {
                        /* a cylinder decided from the light's numbers
                           where they are certain (rtpi_cyl_sure; its
                           miss by the line's distance, before the line
                           test below) */
                        int e = rtpi_cyl_sure(py + 6 * (size_t)(prim - ntris - nspheres), cf, ray,
                                              qk);
                        if (e > 0)
                            return prim;
                        if (e == 0) {
                            seen[prim & 7u] = prim;
                            continue;
                        }
                    }
                    if (cy && kd_cylinder_line_far(cy + 6 * (size_t)(prim - ntris - nspheres),
                                                   cf, ray, ld, tl)) {
                        seen[prim & 7u] = prim;
                        continue;
                    }
                    if (rtpi_cone_near(cf, ray, dd, &tc, &o2) &&
                        !(cf->ra == cf->rb && rtpi_cylinder_far(cf, ray, tc, o2, ld, ts)) &&
                        rtpi_cone_t(cf, ray, dd, tc, o2, &t))
                        return prim;
                    seen[prim & 7u] = prim;
                }
            }
        }
        if (sp == 0)
            return RTPI_NONE;
        sp--;
        node = stack[sp].node;
        t0 = stack[sp].t0;
        t1 = stack[sp].t1;
    }
}

#define KD_OCC(lazy, pl, pe, thr, pc, pa)                                                      \
    (s->ncones ? kd_occluder(kd, ray, skip, lazy, pl, pe, thr, pc, 1, NULL, NULL, pa)          \
               : kd_occluder(kd, ray, skip, lazy, pl, pe, thr, pc, 0, NULL, NULL, pa))

uint32_t rtpi_kd_occluder(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip)
{
    const rtp_scene *s = kd->scene;
    if (s->ntris < s->nspheres + s->ncones)
        return KD_OCC(1, NULL, NULL, 0.0, NULL, NULL);
    return KD_OCC(0, NULL, NULL, 0.0, NULL, NULL);
}

/* rtpi_kd_occluder_planes, from path's leaf (NULL: the root; a constant
   where inlined: a trace's walks carry no code of it) */
static RTPI_FORCE_INLINE uint32_t kd_occ_planes(const rtpi_kdtree *kd, const rtpi_ray *ray,
                                                uint32_t skip, const double *planes,
                                                const double *edges, const double *cones,
                                                double scale, const kd_pe *pa)
{
    const rtp_scene *s = kd->scene;
    /* the planes' test holds for origins within the scale (lb_plane_turned in
       dircube.c), and so does the edges'.  A kept leaf's origin lies inside
       the root box (rtpi_kd_path_of): within the scale where the box is
       (the third exact move of test/instr/run.sh, 512^2 SPD, M: rings
       604.6 -> 597.1, tree 197.1 -> 195.8, teapot 295.6 -> 294.8, mount
       368.4 -> 368.1, gears 275.8 -> 275.4, but balls 356.3 -> 356.6, its
       lazy walk's loop compiled differently; the test below only for
       the walks of triangles: balls 359.5, tree 197.5) */
    if (!(pa && kd->boxabs <= scale) &&
        !(fabs(ray->o.x) <= scale && fabs(ray->o.y) <= scale && fabs(ray->o.z) <= scale))
        planes = NULL;
    /* (spheres and cones: lazy, as rtpi_kd_occluder; without the edges,
       whose margin's product alone made balls' move 0.7% dearer) */
    if (s->ntris < s->nspheres + s->ncones)
        return cones ? KD_OCC(1, planes, NULL, 0.0, cones, pa)
                     : KD_OCC(1, NULL, NULL, 0.0, NULL, pa);
    if (planes && edges) {
        const double thr = RTPI_EDGE_MARGIN * scale * scale * scale; /* (rtpi_tri_edges') */
        return cones ? KD_OCC(0, planes, edges, thr, cones, pa)
                     : KD_OCC(0, planes, edges, thr, NULL, pa);
    }
    /* (without edges, as a trace asks: a walk of its own, with no edge
       test compiled in; one walk for both made gears' trace 1.5% dearer) */
    if (planes)
        return cones ? KD_OCC(0, planes, NULL, 0.0, cones, pa)
                     : KD_OCC(0, planes, NULL, 0.0, NULL, pa);
    if (!pa)
        return rtpi_kd_occluder(kd, ray, skip);
    if (s->ntris < s->nspheres + s->ncones)
        return KD_OCC(1, NULL, NULL, 0.0, NULL, pa);
    return KD_OCC(0, NULL, NULL, 0.0, NULL, pa);
}

uint32_t rtpi_kd_occluder_planes(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                 const double *planes, const double *edges,
                                 const double *cones, double scale)
{
    return kd_occ_planes(kd, ray, skip, planes, edges, cones, scale, NULL);
}

static RTPI_FORCE_INLINE uint32_t kd_occ_cyls(const rtpi_kdtree *kd, const rtpi_ray *ray,
                                              uint32_t skip, const double *planes,
                                              const double *cones, const double *cyls,
                                              double scale, const kd_pe *pa)
{
    const rtp_scene *s = kd->scene;
    rtpi_quad_k qk;
    if (cones && cyls && s->ntris < s->nspheres + s->ncones &&
        ((pa && kd->boxabs <= scale) || /* (kd_occ_planes') */
         (fabs(ray->o.x) <= scale && fabs(ray->o.y) <= scale && fabs(ray->o.z) <= scale))) {
        rtpi_quad_k_make(scale, &qk);
        return kd_occluder(kd, ray, skip, 1, planes, NULL, 0.0, cones, 1, cyls, &qk, pa);
    }
    return pa ? kd_occ_planes(kd, ray, skip, planes, NULL, cones, scale, pa)
              : rtpi_kd_occluder_planes(kd, ray, skip, planes, NULL, cones, scale);
}

uint32_t rtpi_kd_occluder_cyls(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                               const double *planes, const double *cones, const double *cyls,
                               double scale)
{
    return kd_occ_cyls(kd, ray, skip, planes, cones, cyls, scale, NULL);
}

/* (callgrind, the third `exact` move of test/instr/run.sh, 512^2 SPD, M
   instructions, from the root -> from o's leaf: balls 381.6 -> 367.6,
   gears 290.4 -> 283.4, mount 413.4 -> 384.6, rings 661.6 -> 609.9,
   teapot 318.8 -> 306.2, tetra 40.5 -> 38.3; tree 199.6 -> 202.8, whose
   origins lie in shallow leaves (4.2 ancestors a walk, 1.3 of them moved
   away from), where the walk gains ~1 M and vis_row's look-up and the
   query's argument cost ~3 M.  Tried: one list of a leaf's ancestors
   with a test of the direction at each (balls 394.0, mount 417.8: the
   test and loop cost what the steps did); one list with a mask an
   octant (a sixth of the memory: balls 372.0, rings 619.7); the lists'
   steps in a function of their own (tree 205.3, rings 619.6); leaves of
   depth 6 or more only (tree 204.0).) */
uint32_t rtpi_kd_occluder_planes_from(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                      const double *planes, const double *edges,
                                      const double *cones, double scale, uint32_t from)
{
    /* the walk from the root by its own function: inlined here as a
       second copy it compiled worse (gears_s4 without lists, the third
       exact move: 290.4 -> 300.4 M) */
    if (from == RTPI_NONE)
        return rtpi_kd_occluder_planes(kd, ray, skip, planes, edges, cones, scale);
    return kd_occ_planes(kd, ray, skip, planes, edges, cones, scale, kd->path + from);
}

uint32_t rtpi_kd_occluder_cyls_from(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                    const double *planes, const double *cones,
                                    const double *cyls, double scale, uint32_t from)
{
    if (from == RTPI_NONE)
        return kd_occ_cyls(kd, ray, skip, planes, cones, cyls, scale, NULL);
    return kd_occ_cyls(kd, ray, skip, planes, cones, cyls, scale, kd->path + from);
}

int rtpi_kd_occluded(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip)
{
    return rtpi_kd_occluder(kd, ray, skip) != RTPI_NONE;
}
