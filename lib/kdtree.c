/* kdtree.c — the SAH kd-tree: an O(N log N) build by event sweep with
 * perfect (clipped) splits after Wald & Havran 2006, "On building fast
 * kd-trees for ray tracing, and on doing that in O(N log N)", 8-byte nodes
 * after PBRT, and a robust iterative traversal.
 *
 * Build.  Every primitive in a node contributes, per axis, either a
 * "planar" event (its box clipped to the node is flat on that axis) or a
 * "start" and an "end" event.  Each axis keeps its events sorted by
 * (position, end < planar < start) so one sweep per axis evaluates the
 * surface-area heuristic at every candidate plane.  Splitting a node
 * partitions the sorted lists into the children's (keeping the order, no
 * re-sort), and only the primitives that straddle the plane are clipped to
 * the two child boxes (triangles exactly, by polygon clipping; spheres and
 * cones by their bounds) and get new events, which are sorted and merged
 * in.  All event lists live in one arena used as a stack: a node's lists
 * are replaced by its right child's followed by its left child's, the left
 * subtree is built on top, then the right one.
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

#include <stdlib.h>

/* SAH costs (Wald & Havran): one traversal step, one intersection test,
   and the factor that makes cutting off empty space attractive.  The bonus
   is only given when the empty child is at least KD_EMPTY_MIN of the
   node's extent: with these costs it would otherwise pay to shave off
   slivers of empty space around every clipped triangle down to the depth
   limit (measured on the bunny: 60% empty leaves, 5 references a
   triangle), which makes the tree bigger, not faster. */
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
#define KD_EMPTY_MIN 0.1
#endif
/* Nodes with fewer primitives are leaves whatever the SAH says: SAH does
   not see that a deeper tree misses the cache more often, and on the bunny
   stopping at 4 was faster for every kind of ray and builds faster. */
#ifndef KD_MIN_SPLIT
#define KD_MIN_SPLIT 4
#endif
/* Depth limit 8 + 1.3 log2(N) (Wald & Havran). */
#ifndef KD_DEPTH_A
#define KD_DEPTH_A 8.0
#endif
#ifndef KD_DEPTH_B
#define KD_DEPTH_B 1.3
#endif
/* Hard cap on the depth; the traversal stack holds one entry per level. */
#define KD_DEPTH_CAP 60
/* The largest primitive count: ids share a word with a 2-bit event type,
   and counts share one with the 2-bit node kind. */
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
    int has_box;         /* 0: no primitive at all */
    rtpi_kd_stats stats;
};

/* ================================================================ build */

enum { EV_END = 0, EV_PLANAR = 1, EV_START = 2 };
enum { SIDE_BOTH = 0, SIDE_LEFT = 1, SIDE_RIGHT = 2 };

typedef struct kd_ev {
    float pos;
    uint32_t pt; /* primitive id << 2 | event type */
} kd_ev;

typedef struct kd_build {
    const rtp_allocator *a;
    const rtp_scene *s;
    rtpi_kdtree *kd;
    kd_ev *ev;        /* the arena of event lists */
    size_t ev_cap;
    kd_ev *tmp, *tmp2; /* new events of straddlers; sort scratch */
    size_t tmp_cap, tmp2_cap;
    float *pbox;      /* 6 floats per primitive: its bounds */
    uint8_t *side;    /* per primitive, during one split */
    uint32_t *both;   /* straddling primitives of one split */
    float *cbox;      /* their boxes clipped to the children, 12 floats */
    size_t both_cap;
    size_t nodes_cap, refs_cap;
    int max_depth, depth_seen;
    uint32_t hist[3][4096];
} kd_build;

static float f_down(double x)
{
    float f = (float)x;
    if ((double)f > x)
        f = nextafterf(f, -INFINITY);
    return f + 0.0f; /* -0 becomes +0: events compare and sort alike */
}

static float f_up(double x)
{
    float f = (float)x;
    if ((double)f < x)
        f = nextafterf(f, INFINITY);
    return f + 0.0f;
}

static uint32_t ev_key(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u & 0x80000000u ? ~u : u | 0x80000000u;
}

static int ev_less(kd_ev x, kd_ev y)
{
    return x.pos < y.pos || (x.pos == y.pos && (x.pt & 3) < (y.pt & 3));
}

/* Sorts by (pos, type): insertion sort when short, else a three-pass LSD
   radix sort on the 34-bit key (order-preserving float bits, type). */
static void ev_sort(kd_build *b, kd_ev *e, size_t n, kd_ev *scratch)
{
    size_t i, j;
    int pass;
    if (n <= 32) {
        for (i = 1; i < n; i++) {
            kd_ev x = e[i];
            for (j = i; j > 0 && ev_less(x, e[j - 1]); j--)
                e[j] = e[j - 1];
            e[j] = x;
        }
        return;
    }
    memset(b->hist, 0, sizeof b->hist);
    for (i = 0; i < n; i++) {
        uint64_t k = (uint64_t)ev_key(e[i].pos) << 2 | (e[i].pt & 3);
        b->hist[0][k & 4095]++;
        b->hist[1][(k >> 12) & 4095]++;
        b->hist[2][(k >> 24) & 4095]++;
    }
    for (pass = 0; pass < 3; pass++) {
        uint32_t sum = 0, c;
        kd_ev *src = pass == 1 ? scratch : e, *dst = pass == 1 ? e : scratch;
        int sh = 12 * pass;
        for (i = 0; i < 4096; i++) {
            c = b->hist[pass][i];
            b->hist[pass][i] = sum;
            sum += c;
        }
        for (i = 0; i < n; i++) {
            uint64_t k = (uint64_t)ev_key(src[i].pos) << 2 | (src[i].pt & 3);
            dst[b->hist[pass][(k >> sh) & 4095]++] = src[i];
        }
    }
    memcpy(e, scratch, n * sizeof *e);
}

static int grow_ev(kd_build *b, kd_ev **p, size_t *cap, size_t need)
{
    size_t nc;
    kd_ev *q;
    if (need <= *cap)
        return 0;
    nc = *cap + *cap / 2;
    if (nc < need)
        nc = need;
    if (nc > (size_t)-1 / sizeof **p)
        return -1;
    q = (kd_ev *)rtpi_realloc(b->a, *p, nc * sizeof **p);
    if (!q)
        return -1;
    *p = q;
    *cap = nc;
    return 0;
}

/* Clips triangle (p0,p1,p2) to the box [lo,hi] (Sutherland-Hodgman, in
   double, crossing points snapped onto the plane they were cut at) and
   returns the bounds of what is left, rounded outward to floats and kept
   inside the box.  @return 0 if nothing is left. */
static int clip_tri(const float *p0, const float *p1, const float *p2,
                    const float *tb, const float *lo, const float *hi,
                    float *out)
{
    double poly[2][12][3];
    double mn[3], mx[3];
    int n = 3, cur = 0, a, i, k;
    for (k = 0; k < 3; k++) {
        poly[0][0][k] = p0[k];
        poly[0][1][k] = p1[k];
        poly[0][2][k] = p2[k];
    }
    for (a = 0; a < 3; a++) {
        int sd;
        for (sd = 0; sd < 2; sd++) {
            double c = sd ? hi[a] : lo[a];
            int m = 0;
            /* A plane that does not cut the triangle's own box changes
               nothing. */
            if (sd ? tb[3 + a] <= hi[a] : tb[a] >= lo[a])
                continue;
            for (i = 0; i < n; i++) {
                const double *P = poly[cur][i];
                const double *Q = poly[cur][i + 1 == n ? 0 : i + 1];
                int pin = sd ? P[a] <= c : P[a] >= c;
                int qin = sd ? Q[a] <= c : Q[a] >= c;
                if (pin)
                    memcpy(poly[!cur][m++], P, sizeof poly[0][0]);
                if (pin != qin) {
                    double t = (c - P[a]) / (Q[a] - P[a]);
                    for (k = 0; k < 3; k++)
                        poly[!cur][m][k] = P[k] + t * (Q[k] - P[k]);
                    poly[!cur][m][a] = c;
                    m++;
                }
            }
            cur = !cur;
            n = m;
            if (n == 0)
                return 0;
        }
    }
    for (k = 0; k < 3; k++)
        mn[k] = mx[k] = poly[cur][0][k];
    for (i = 1; i < n; i++) {
        for (k = 0; k < 3; k++) {
            double x = poly[cur][i][k];
            mn[k] = x < mn[k] ? x : mn[k];
            mx[k] = x > mx[k] ? x : mx[k];
        }
    }
    for (k = 0; k < 3; k++) {
        out[k] = mn[k] > lo[k] ? f_down(mn[k]) : lo[k];
        out[3 + k] = mx[k] < hi[k] ? f_up(mx[k]) : hi[k];
        if (out[k] > out[3 + k])
            return 0;
    }
    return 1;
}

/* Bounds of primitive `prim` inside the box [lo,hi].  Triangles are
   clipped; if rounding made the clipped polygon vanish although the
   primitive straddles the plane, the plain bounds cut to the box are used
   (conservative: an extra reference, never a lost one). */
static void clip_prim(const kd_build *b, uint32_t prim, const float *lo,
                      const float *hi, float *out)
{
    const float *pb = b->pbox + 6 * (size_t)prim;
    int k;
    if (prim < b->kd->ntris) {
        const float *v = b->kd->tri + 9 * (size_t)prim;
        if (clip_tri(v, v + 3, v + 6, pb, lo, hi, out))
            return;
    }
    for (k = 0; k < 3; k++) {
        out[k] = pb[k] > lo[k] ? pb[k] : lo[k];
        out[3 + k] = pb[3 + k] < hi[k] ? pb[3 + k] : hi[k];
        if (out[k] > out[3 + k]) /* cannot happen for a straddler; safe */
            out[3 + k] = out[k];
    }
}

static int push_node(kd_build *b, uint32_t *idx)
{
    rtpi_kdtree *kd = b->kd;
    if (kd->nnodes >= KD_MAX_PRIMS ||
        rtpi_grow(b->a, (void **)&kd->nodes, &b->nodes_cap, kd->nnodes + 1,
                  sizeof *kd->nodes))
        return -1;
    *idx = (uint32_t)kd->nnodes++;
    return 0;
}

static int make_leaf(kd_build *b, const kd_ev *e0, size_t n0, size_t nprim)
{
    rtpi_kdtree *kd = b->kd;
    uint32_t idx;
    size_t i;
    if (push_node(b, &idx))
        return -1;
    kd->nodes[idx].flags = 3u | (uint32_t)nprim << 2;
    kd->nodes[idx].a.off = 0;
    if (nprim == 1) {
        for (i = 0; i < n0; i++)
            if ((e0[i].pt & 3) != EV_END)
                kd->nodes[idx].a.one = e0[i].pt >> 2;
    } else if (nprim > 1) {
        if (kd->nrefs + nprim > 0xffffffffu ||
            rtpi_grow(b->a, (void **)&kd->refs, &b->refs_cap,
                      kd->nrefs + nprim, sizeof *kd->refs))
            return -1;
        kd->nodes[idx].a.off = (uint32_t)kd->nrefs;
        /* Every primitive has exactly one start or planar event per axis. */
        for (i = 0; i < n0; i++)
            if ((e0[i].pt & 3) != EV_END)
                kd->refs[kd->nrefs++] = e0[i].pt >> 2;
    }
    return 0;
}

/* The best split of a node by SAH over all three axes.
   @return its cost (HUGE_VAL when there is no usable plane). */
static double find_split(const kd_ev *const ev[3], const size_t n[3],
                         size_t nprim, const float *lo, const float *hi,
                         int *axis, float *pos, int *planar_left)
{
    double d[3], best = HUGE_VAL, area;
    int k;
    for (k = 0; k < 3; k++)
        d[k] = (double)hi[k] - lo[k];
    area = d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
    if (!(area > 0.0))
        return best;
    for (k = 0; k < 3; k++) {
        const kd_ev *e = ev[k];
        double o1 = d[(k + 1) % 3], o2 = d[(k + 2) % 3];
        double cap = o1 * o2, perim = o1 + o2, inv = 1.0 / area;
        size_t nl = 0, nr = nprim, i = 0, m = n[k];
        while (i < m) {
            float p = e[i].pos;
            size_t pe = 0, pp = 0, ps = 0;
            while (i < m && e[i].pos == p && (e[i].pt & 3) == EV_END)
                pe++, i++;
            while (i < m && e[i].pos == p && (e[i].pt & 3) == EV_PLANAR)
                pp++, i++;
            while (i < m && e[i].pos == p && (e[i].pt & 3) == EV_START)
                ps++, i++;
            nr -= pp + pe;
            /* Planes on the box's faces cut nothing off. */
            if (p > lo[k] && p < hi[k]) {
                double pl = (cap + ((double)p - lo[k]) * perim) * inv;
                double pr = (cap + ((double)hi[k] - p) * perim) * inv;
                double cl, cr;
                size_t a1 = nl + pp, b1 = nr, a2 = nl, b2 = nr + pp;
                double fl = ((double)p - lo[k]) / d[k], fr = 1.0 - fl;
                cl = KD_COST_TRAV + KD_COST_ISECT * (pl * (double)a1 + pr * (double)b1);
                if ((a1 == 0 && fl >= KD_EMPTY_MIN) || (b1 == 0 && fr >= KD_EMPTY_MIN))
                    cl *= KD_EMPTY_BONUS;
                cr = KD_COST_TRAV + KD_COST_ISECT * (pl * (double)a2 + pr * (double)b2);
                if ((a2 == 0 && fl >= KD_EMPTY_MIN) || (b2 == 0 && fr >= KD_EMPTY_MIN))
                    cr *= KD_EMPTY_BONUS;
                if (cl < best) {
                    best = cl;
                    *axis = k;
                    *pos = p;
                    *planar_left = 1;
                }
                if (cr < best) {
                    best = cr;
                    *axis = k;
                    *pos = p;
                    *planar_left = 0;
                }
            }
            nl += ps + pp;
        }
    }
    return best;
}

/* Appends the events of box bx (clipped bounds of prim) on axis a. */
static size_t put_events(kd_ev *out, uint32_t prim, const float *bx, int a)
{
    if (bx[a] == bx[3 + a]) {
        out[0].pos = bx[a];
        out[0].pt = prim << 2 | EV_PLANAR;
        return 1;
    }
    out[0].pos = bx[a];
    out[0].pt = prim << 2 | EV_START;
    out[1].pos = bx[3 + a];
    out[1].pt = prim << 2 | EV_END;
    return 2;
}

static int build_node(kd_build *b, const float *lo, const float *hi,
                      size_t off, const size_t n[3], size_t nprim, int depth)
{
    const kd_ev *ev[3];
    size_t total = n[0] + n[1] + n[2];
    size_t cnt[2][3], nnew[2][3], nch[2][3], nside[2], nboth, i, gcap;
    size_t out, base[2];
    int axis = 0, planar_left = 1, k, sd;
    float pos = 0.0f, clo[3], chi[3];
    uint32_t idx;
    kd_ev *e;
    double cost;

    if (depth > b->depth_seen)
        b->depth_seen = depth;
    ev[0] = b->ev + off;
    ev[1] = ev[0] + n[0];
    ev[2] = ev[1] + n[1];
    cost = depth >= b->max_depth || nprim < KD_MIN_SPLIT
               ? HUGE_VAL
               : find_split(ev, n, nprim, lo, hi, &axis, &pos, &planar_left);
    if (!(cost < KD_COST_ISECT * (double)nprim))
        return make_leaf(b, ev[0], n[0], nprim);

    /* Classify: left only, right only, or both (straddling). */
    for (i = 0; i < n[0]; i++)
        b->side[ev[0][i].pt >> 2] = SIDE_BOTH;
    e = b->ev + off + (axis == 0 ? 0 : axis == 1 ? n[0] : n[0] + n[1]);
    for (i = 0; i < n[axis]; i++) {
        uint32_t prim = e[i].pt >> 2, t = e[i].pt & 3;
        if (t == EV_END && e[i].pos <= pos)
            b->side[prim] = SIDE_LEFT;
        else if (t == EV_START && e[i].pos >= pos)
            b->side[prim] = SIDE_RIGHT;
        else if (t == EV_PLANAR)
            b->side[prim] = e[i].pos < pos || (e[i].pos == pos && planar_left)
                                ? SIDE_LEFT
                                : SIDE_RIGHT;
    }
    nboth = 0;
    for (i = 0; i < n[axis]; i++)
        if ((e[i].pt & 3) == EV_START && b->side[e[i].pt >> 2] == SIDE_BOTH)
            nboth++;
    if (nboth > b->both_cap) {
        uint32_t *nb = (uint32_t *)rtpi_realloc(b->a, b->both,
                                                nboth * sizeof *nb);
        float *nc;
        if (!nb)
            return -1;
        b->both = nb;
        nc = (float *)rtpi_realloc(b->a, b->cbox, nboth * 12 * sizeof *nc);
        if (!nc)
            return -1;
        b->cbox = nc;
        b->both_cap = nboth;
    }
    nboth = 0;
    for (i = 0; i < n[axis]; i++)
        if ((e[i].pt & 3) == EV_START && b->side[e[i].pt >> 2] == SIDE_BOTH)
            b->both[nboth++] = e[i].pt >> 2;

    /* Count the events each child keeps. */
    memset(cnt, 0, sizeof cnt);
    nside[0] = nside[1] = 0;
    for (k = 0; k < 3; k++) {
        for (i = 0; i < n[k]; i++) {
            int s = b->side[ev[k][i].pt >> 2];
            if (s != SIDE_BOTH)
                cnt[s - 1][k]++;
            if (k == 0 && s != SIDE_BOTH && (ev[0][i].pt & 3) != EV_END)
                nside[s - 1]++;
        }
    }

    /* Clip the straddlers to both children and make their new events:
       group (side, axis) in tmp at (side * 3 + axis) * gcap. */
    gcap = 2 * nboth;
    if (grow_ev(b, &b->tmp, &b->tmp_cap, 6 * gcap) ||
        grow_ev(b, &b->tmp2, &b->tmp2_cap, gcap))
        return -1;
    memset(nnew, 0, sizeof nnew);
    for (sd = 0; sd < 2; sd++) {
        for (k = 0; k < 3; k++) {
            clo[k] = lo[k];
            chi[k] = hi[k];
        }
        if (sd == 0)
            chi[axis] = pos;
        else
            clo[axis] = pos;
        for (i = 0; i < nboth; i++) {
            float *bx = b->cbox + 12 * i + 6 * sd;
            clip_prim(b, b->both[i], clo, chi, bx);
            for (k = 0; k < 3; k++)
                nnew[sd][k] += put_events(b->tmp + (sd * 3 + k) * gcap +
                                              nnew[sd][k],
                                          b->both[i], bx, k);
        }
        for (k = 0; k < 3; k++)
            ev_sort(b, b->tmp + (sd * 3 + k) * gcap, nnew[sd][k], b->tmp2);
    }

    /* Write the right child's lists, then the left child's, above this
       node's, merging kept and new events; then move them down over it. */
    for (sd = 0; sd < 2; sd++)
        for (k = 0; k < 3; k++)
            nch[sd][k] = cnt[sd][k] + nnew[sd][k];
    base[1] = 0;
    base[0] = nch[1][0] + nch[1][1] + nch[1][2];
    if (grow_ev(b, &b->ev, &b->ev_cap,
                off + total + base[0] + nch[0][0] + nch[0][1] + nch[0][2]))
        return -1;
    ev[0] = b->ev + off;
    ev[1] = ev[0] + n[0];
    ev[2] = ev[1] + n[1];
    out = off + total;
    for (sd = 1; sd >= 0; sd--) {
        uint8_t want = (uint8_t)(sd + 1);
        for (k = 0; k < 3; k++) {
            const kd_ev *x = ev[k], *xe = ev[k] + n[k];
            const kd_ev *y = b->tmp + (sd * 3 + k) * gcap;
            const kd_ev *ye = y + nnew[sd][k];
            kd_ev *o = b->ev + out;
            for (;;) {
                while (x < xe && b->side[x->pt >> 2] != want)
                    x++;
                if (x == xe)
                    break;
                if (y < ye && ev_less(*y, *x))
                    *o++ = *y++;
                else
                    *o++ = *x++;
            }
            while (y < ye)
                *o++ = *y++;
            out += nch[sd][k];
        }
    }
    memmove(b->ev + off, b->ev + off + total,
            (out - off - total) * sizeof *b->ev);

    if (push_node(b, &idx))
        return -1;
    b->kd->nodes[idx].a.split = pos;
    b->kd->nodes[idx].flags = (uint32_t)axis;
    for (k = 0; k < 3; k++) {
        clo[k] = lo[k];
        chi[k] = hi[k];
    }
    chi[axis] = pos;
    {
        size_t nl = nside[0] + nboth, nr = nside[1] + nboth;
        size_t nr3[3];
        for (k = 0; k < 3; k++)
            nr3[k] = nch[1][k];
        if (build_node(b, clo, chi, off + base[0], nch[0], nl, depth + 1))
            return -1;
        if (b->kd->nnodes >= KD_MAX_PRIMS)
            return -1;
        b->kd->nodes[idx].flags |= (uint32_t)b->kd->nnodes << 2;
        clo[axis] = pos;
        chi[axis] = hi[axis];
        return build_node(b, clo, chi, off, nr3, nr, depth + 1);
    }
}

static void build_free(kd_build *b)
{
    rtpi_free(b->a, b->ev);
    rtpi_free(b->a, b->tmp);
    rtpi_free(b->a, b->tmp2);
    rtpi_free(b->a, b->pbox);
    rtpi_free(b->a, b->side);
    rtpi_free(b->a, b->both);
    rtpi_free(b->a, b->cbox);
    rtpi_free(b->a, b);
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
    rtpi_free(&a, kd);
}

rtp_status rtpi_kd_build(const rtp_scene *s, const rtp_allocator *alloc,
                         rtpi_kdtree **out, rtp_error *err)
{
    rtp_allocator a;
    rtpi_kdtree *kd;
    kd_build *b;
    size_t np = rtpi_scene_nprims(s), i, nvalid = 0, n[3];
    float lo[3], hi[3];
    int k;
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
    b = (kd_build *)rtpi_malloc(&a, sizeof *b);
    if (!b) {
        rtpi_kd_destroy(kd);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory");
    }
    memset(b, 0, sizeof *b);
    b->a = &kd->alloc;
    b->s = s;
    b->kd = kd;
    if (np > 0) {
        kd->tri = (float *)rtpi_malloc_array(&a, s->ntris ? s->ntris : 1,
                                             9 * sizeof(float));
        b->pbox = (float *)rtpi_malloc_array(&a, np, 6 * sizeof(float));
        b->side = (uint8_t *)rtpi_malloc_array(&a, np, 1);
        b->ev = (kd_ev *)rtpi_malloc_array(&a, np, 6 * sizeof(kd_ev));
        b->tmp2 = (kd_ev *)rtpi_malloc_array(&a, np, 2 * sizeof(kd_ev));
        if (!kd->tri || !b->pbox || !b->side || !b->ev || !b->tmp2)
            goto nomem;
        b->ev_cap = 6 * np;
        b->tmp2_cap = 2 * np;
    }
    for (i = 0; i < s->ntris; i++) {
        const rtpi_tri *t = &s->tris[i];
        for (k = 0; k < 3; k++)
            memcpy(kd->tri + 9 * i + 3 * k, s->pos + 3 * (size_t)t->v[k],
                   3 * sizeof(float));
    }

    /* Bounds of every primitive, rounded outward to floats; degenerate or
       non-finite primitives never hit and are left out. */
    for (k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
    for (i = 0; i < np; i++) {
        double dlo[3], dhi[3];
        float *pb = b->pbox + 6 * i;
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
        b->side[i] = (uint8_t)ok;
        if (!ok)
            continue;
        for (k = 0; k < 3; k++) {
            pb[k] = f_down(dlo[k]);
            pb[3 + k] = f_up(dhi[k]);
            lo[k] = pb[k] < lo[k] ? pb[k] : lo[k];
            hi[k] = pb[3 + k] > hi[k] ? pb[3 + k] : hi[k];
        }
        nvalid++;
    }

    if (nvalid > 0) {
        kd->has_box = 1;
        for (k = 0; k < 3; k++) {
            kd->lo[k] = lo[k];
            kd->hi[k] = hi[k];
            kd->maxabs[k] = fmax(fabs(kd->lo[k]), fabs(kd->hi[k]));
        }
        /* Initial events, per axis in its own third, then packed. */
        for (k = 0; k < 3; k++) {
            kd_ev *e = b->ev + 2 * np * (size_t)k;
            size_t m = 0;
            for (i = 0; i < np; i++)
                if (b->side[i])
                    m += put_events(e + m, (uint32_t)i, b->pbox + 6 * i, k);
            ev_sort(b, e, m, b->tmp2);
            n[k] = m;
        }
        memmove(b->ev + n[0], b->ev + 2 * np, n[1] * sizeof *b->ev);
        memmove(b->ev + n[0] + n[1], b->ev + 4 * np, n[2] * sizeof *b->ev);
    } else {
        for (k = 0; k < 3; k++) {
            n[k] = 0;
            lo[k] = hi[k] = 0.0f;
        }
    }

    lg = nvalid > 1 ? log((double)nvalid) / log(2.0) : 0.0;
    b->max_depth = (int)(KD_DEPTH_A + KD_DEPTH_B * lg);
    if (b->max_depth > KD_DEPTH_CAP)
        b->max_depth = KD_DEPTH_CAP;
    if (build_node(b, lo, hi, 0, n, nvalid, 0))
        goto nomem;

    kd->stats.nodes = kd->nnodes;
    kd->stats.depth = b->depth_seen;
    for (i = 0; i < kd->nnodes; i++) {
        if ((kd->nodes[i].flags & 3) == 3) {
            size_t c = kd->nodes[i].flags >> 2;
            kd->stats.leaves++;
            kd->stats.prim_refs += c;
            kd->stats.empty_leaves += c == 0;
        }
    }
    build_free(b);
    *out = kd;
    return RTP_OK;

nomem:
    build_free(b);
    rtpi_kd_destroy(kd);
    return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                      "out of memory building the kd-tree");
}

void rtpi_kd_get_stats(const rtpi_kdtree *kd, rtpi_kd_stats *st)
{
    *st = kd->stats;
}

/* ============================================================ traversal */

typedef struct kd_ray {
    double o[3], inv[3], slack[3], tol[3];
    int par[3];      /* direction is exactly 0 on this axis */
    int neg[3];      /* direction < 0: the above child comes first */
} kd_ray;

typedef struct kd_item {
    double t0, t1;
    uint32_t node;
} kd_item;

/* Prepares the ray and clips it to the root box.
   @return 0 when it misses the box or its interval is empty. */
static int kd_ray_setup(const rtpi_kdtree *kd, const rtpi_ray *r, kd_ray *kr,
                        double *t0, double *t1)
{
    double d[3];
    int k;
    if (!kd->has_box)
        return 0;
    kr->o[0] = r->o.x;
    kr->o[1] = r->o.y;
    kr->o[2] = r->o.z;
    d[0] = r->d.x;
    d[1] = r->d.y;
    d[2] = r->d.z;
    *t0 = r->tmin;
    *t1 = r->tmax;
    for (k = 0; k < 3; k++) {
        double m = fmax(fabs(kr->o[k]), kd->maxabs[k]);
        kr->tol[k] = KD_SLACK * m;
        kr->par[k] = d[k] == 0.0;
        kr->neg[k] = d[k] < 0.0;
        if (kr->par[k]) {
            kr->inv[k] = 0.0;
            kr->slack[k] = 0.0;
            if (kr->o[k] < kd->lo[k] - kr->tol[k] ||
                kr->o[k] > kd->hi[k] + kr->tol[k])
                return 0;
        } else {
            double ta, tb, x;
            kr->inv[k] = 1.0 / d[k];
            kr->slack[k] = kr->tol[k] * fabs(kr->inv[k]);
            ta = (kd->lo[k] - kr->o[k]) * kr->inv[k];
            tb = (kd->hi[k] - kr->o[k]) * kr->inv[k];
            if (ta > tb) {
                x = ta;
                ta = tb;
                tb = x;
            }
            /* Written so that a NaN leaves the interval as it is. */
            if (ta - kr->slack[k] > *t0)
                *t0 = ta - kr->slack[k];
            if (tb + kr->slack[k] < *t1)
                *t1 = tb + kr->slack[k];
        }
    }
    return *t0 <= *t1;
}

/* One interior step: picks the child(ren) of `nd` for [*t0,*t1]; pushes
   the far one when both are needed.  @return the node to go on with. */
static inline uint32_t kd_step(const kd_ray *kr, const kd_node *nd,
                               uint32_t node, double *t0, double *t1,
                               kd_item *stack, int *sp)
{
    uint32_t fl = nd->flags, ax = fl & 3;
    uint32_t below = node + 1, above = fl >> 2;
    double split = nd->a.split;
    if (kr->par[ax]) {
        /* Parallel to the plane: stays on its side, or runs in it. */
        double dd = split - kr->o[ax];
        if (dd > kr->tol[ax])
            return below;
        if (dd < -kr->tol[ax])
            return above;
        stack[*sp].node = above;
        stack[*sp].t0 = *t0;
        stack[*sp].t1 = *t1;
        (*sp)++;
        return below;
    } else {
        double ts = (split - kr->o[ax]) * kr->inv[ax];
        double lo = ts - kr->slack[ax], hi = ts + kr->slack[ax];
        uint32_t nearc = kr->neg[ax] ? above : below;
        uint32_t farc = kr->neg[ax] ? below : above;
        if (hi < *t0)
            return farc;
        if (lo > *t1)
            return nearc;
        stack[*sp].node = farc;
        stack[*sp].t0 = lo > *t0 ? lo : *t0;
        stack[*sp].t1 = *t1;
        (*sp)++;
        if (hi < *t1)
            *t1 = hi;
        return nearc;
    }
}

int rtpi_kd_intersect(const rtpi_kdtree *kd, const rtpi_ray *ray,
                      rtpi_hit *hit)
{
    kd_item stack[KD_DEPTH_CAP + 4];
    kd_ray kr;
    rtpi_wt_ray w;
    rtpi_ray r2;
    const kd_node *nodes = kd->nodes;
    const float *tri = kd->tri;
    size_t ntris = kd->ntris;
    double t0, t1, best = ray->tmax, tmin = ray->tmin;
    uint32_t node = 0;
    int sp = 0, found = 0;

    if (!kd_ray_setup(kd, ray, &kr, &t0, &t1) || !rtpi_wt_setup(&w, ray))
        return 0;
    r2 = *ray;
    for (;;) {
        const kd_node *nd = &nodes[node];
        if ((nd->flags & 3) != 3) {
            node = kd_step(&kr, nd, node, &t0, &t1, stack, &sp);
            continue;
        }
        {
            uint32_t cnt = nd->flags >> 2, j;
            const uint32_t *list = cnt == 1 ? &nd->a.one : kd->refs + nd->a.off;
            for (j = 0; j < cnt; j++) {
                uint32_t prim = list[j];
                if (prim < ntris) {
                    const float *v = tri + 9 * (size_t)prim;
                    double t, u, v2;
                    if (rtpi_wt_tri(&w, v, v + 3, v + 6, tmin, best, &t, &u,
                                    &v2)) {
                        best = t;
                        hit->t = t;
                        hit->u = u;
                        hit->v = v2;
                        hit->prim = prim;
                        found = 1;
                    }
                } else {
                    rtpi_hit h;
                    r2.tmax = best;
                    if (rtpi_intersect_prim(kd->scene, prim, &r2, &h)) {
                        best = h.t;
                        *hit = h;
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
            if (sp == 0)
                return found;
            sp--;
            if (!found || stack[sp].t0 <= best)
                break;
        }
        node = stack[sp].node;
        t0 = stack[sp].t0;
        t1 = stack[sp].t1;
    }
}

int rtpi_kd_occluded(const rtpi_kdtree *kd, const rtpi_ray *ray)
{
    kd_item stack[KD_DEPTH_CAP + 4];
    kd_ray kr;
    rtpi_wt_ray w;
    const kd_node *nodes = kd->nodes;
    const float *tri = kd->tri;
    size_t ntris = kd->ntris;
    double t0, t1, tmin = ray->tmin, tmax = ray->tmax;
    uint32_t node = 0;
    int sp = 0;

    if (!kd_ray_setup(kd, ray, &kr, &t0, &t1) || !rtpi_wt_setup(&w, ray))
        return 0;
    for (;;) {
        const kd_node *nd = &nodes[node];
        if ((nd->flags & 3) != 3) {
            node = kd_step(&kr, nd, node, &t0, &t1, stack, &sp);
            continue;
        }
        {
            uint32_t cnt = nd->flags >> 2, j;
            const uint32_t *list = cnt == 1 ? &nd->a.one : kd->refs + nd->a.off;
            for (j = 0; j < cnt; j++) {
                uint32_t prim = list[j];
                if (prim < ntris) {
                    const float *v = tri + 9 * (size_t)prim;
                    double t, u, v2;
                    if (rtpi_wt_tri(&w, v, v + 3, v + 6, tmin, tmax, &t, &u,
                                    &v2))
                        return 1;
                } else {
                    rtpi_hit h;
                    if (rtpi_intersect_prim(kd->scene, prim, ray, &h))
                        return 1;
                }
            }
        }
        if (sp == 0)
            return 0;
        sp--;
        node = stack[sp].node;
        t0 = stack[sp].t0;
        t1 = stack[sp].t1;
    }
}
