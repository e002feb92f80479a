/* polygon.c — ear clipping for planar polygons, convex or concave (SPD's
 * gears have 144-gon faces), keeping the polygon's winding.
 *
 * The polygon is projected onto the coordinate plane its normal (Newell's
 * method, which gives the true area-weighted normal of any simple
 * polygon, whichever corners are convex) is most perpendicular to, and
 * clipped in 2D.  Each vertex keeps an "is an ear" flag; clipping an ear
 * only changes its two neighbours, so the whole run is O(n^2) (for a
 * convex polygon O(n) tests and the removals' memmoves: an 8192-gon in
 * 20 ms).  Clipping goes round the ring, an ear and then on past its
 * neighbour, so a convex polygon loses every other vertex a round and
 * comes out as triangles of halving sizes, none sharing a vertex with
 * more than about 2 log2 n others: not a fan of slivers out of one corner,
 * which a kd-tree cannot separate.  Collinear and duplicate vertices are
 * dropped without a triangle (they enclose no area). */
#include "internal.h"

/* The ring of remaining vertices lives, right-aligned, in the tail of the
   caller's output array: after k clips it holds n-k entries and at most k
   triangles (3k entries) have been written at the front, and
   3k + n-k <= 3(n-2) while k <= n-3, so they never meet and no memory is
   allocated.  Each entry is a vertex index with two flag bits on top. */
#define EAR 0x80000000u
#define REFLEX 0x40000000u
#define IDX 0x3fffffffu

typedef struct ring {
    const double *x, *y; /* projected coordinates, stride 3 */
    uint32_t *v;         /* m entries: index | flags */
    size_t m;
    double sign;         /* +1 or -1: makes the polygon's winding positive */
} ring;

static size_t rprev(const ring *r, size_t j) { return j ? j - 1 : r->m - 1; }
static size_t rnext(const ring *r, size_t j) { return j + 1 < r->m ? j + 1 : 0; }

static double px(const ring *r, size_t j) { return r->x[3 * (r->v[j] & IDX)]; }
static double py(const ring *r, size_t j) { return r->y[3 * (r->v[j] & IDX)]; }

/* Twice the signed area of (a, b, c) (ring positions), positive for the
   polygon's winding. */
static double area2(const ring *r, size_t a, size_t b, size_t c)
{
    double ax = px(r, a), ay = py(r, a);
    return r->sign * ((px(r, b) - ax) * (py(r, c) - ay) -
                      (py(r, b) - ay) * (px(r, c) - ax));
}

static double dist2(const ring *r, size_t a, size_t b)
{
    double dx = px(r, a) - px(r, b), dy = py(r, a) - py(r, b);
    return dx * dx + dy * dy;
}

/* 1: convex corner, 0: collinear or duplicate (no area), -1: reflex.  The
   tolerance is relative to the two edges' lengths: a corner whose sine is
   below 1e-12 is straight to double precision. */
static int corner(const ring *r, size_t b)
{
    size_t a = rprev(r, b), c = rnext(r, b);
    double ar = area2(r, a, b, c);
    double tol = 1e-12 * sqrt(dist2(r, a, b) * dist2(r, b, c));
    if (ar > tol)
        return 1;
    if (ar < -tol)
        return -1;
    return 0;
}

static int same_point(const ring *r, size_t a, size_t b)
{
    return px(r, a) == px(r, b) && py(r, a) == py(r, b);
}

/* p on the left of a->b or on it, within corner()'s tolerance: a vertex
   that lies on a diagonal in exact numbers may be a rounding off it (a
   polygon of collinear runs in a tilted plane), and taken for outside it
   let the diagonal run through it: a fold, triangles over a notch. */
static int on_left(const ring *r, size_t a, size_t b, size_t p)
{
    return area2(r, a, b, p) >= -1e-12 * sqrt(dist2(r, a, b) * dist2(r, a, p));
}

/* An ear: a convex corner whose triangle holds no other non-convex vertex
   (points on its border count as inside, so no diagonal runs through a
   vertex).  Only non-convex vertices can lie inside a convex corner's
   triangle of a simple polygon, so only those are tested. */
static int is_ear(const ring *r, size_t b, size_t nreflex)
{
    size_t a = rprev(r, b), c = rnext(r, b), p;
    if (corner(r, b) <= 0)
        return 0;
    if (nreflex == 0)
        return 1;
    for (p = rnext(r, c); p != a; p = rnext(r, p)) {
        if (!(r->v[p] & REFLEX) || same_point(r, p, a) ||
            same_point(r, p, b) || same_point(r, p, c))
            continue;
        if (on_left(r, a, b, p) && on_left(r, b, c, p) && on_left(r, c, a, p))
            return 0;
    }
    return 1;
}

static void set_flag(uint32_t *e, uint32_t flag, int on)
{
    *e = on ? (*e | flag) : (*e & ~flag);
}

/* Recomputes the reflex flag of position j, keeping the count. */
static void update_reflex(ring *r, size_t j, size_t *nreflex)
{
    int refl = corner(r, j) <= 0;
    *nreflex -= (r->v[j] & REFLEX) != 0;
    set_flag(&r->v[j], REFLEX, refl);
    *nreflex += refl;
}

static void newell(const double *pts, size_t n, double nrm[3])
{
    size_t i;
    nrm[0] = nrm[1] = nrm[2] = 0.0;
    for (i = 0; i < n; i++) {
        const double *p = pts + 3 * i, *q = pts + 3 * ((i + 1) % n);
        nrm[0] += (p[1] - q[1]) * (p[2] + q[2]);
        nrm[1] += (p[2] - q[2]) * (p[0] + q[0]);
        nrm[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
}

static size_t clip(ring *r, uint32_t *tri)
{
    size_t out = 0, nreflex = 0, tries = 0, j, cur = 0;
    for (j = 0; j < r->m; j++)
        update_reflex(r, j, &nreflex);
    for (j = 0; j < r->m; j++)
        set_flag(&r->v[j], EAR, is_ear(r, j, nreflex));
    while (r->m > 3) {
        size_t a = rprev(r, cur), c = rnext(r, cur);
        uint32_t va = r->v[a] & IDX, vb = r->v[cur] & IDX, vc = r->v[c] & IDX;
        int k = corner(r, cur);
        int take = k == 0 || (r->v[cur] & EAR);
        /* No ear in a whole round: the polygon is not simple (or rounding
           made it look so).  Clip the current convex corner anyway (or any
           corner, later) so that the loop ends. */
        if (!take && tries > r->m)
            take = k > 0 || tries > 2 * r->m;
        if (!take) {
            cur = c;
            tries++;
            continue;
        }
        nreflex -= (r->v[cur] & REFLEX) != 0;
        /* Remove position cur: shift the entries before it one step
           right; positions after it keep theirs. */
        memmove(r->v + 1, r->v, cur * sizeof *r->v);
        r->v++;
        r->m--;
        if (k > 0) {
            tri[3 * out] = va;
            tri[3 * out + 1] = vb;
            tri[3 * out + 2] = vc;
            out++;
        }
        a = cur ? cur - 1 : r->m - 1;
        c = cur < r->m ? cur : 0;
        update_reflex(r, a, &nreflex);
        update_reflex(r, c, &nreflex);
        set_flag(&r->v[a], EAR, is_ear(r, a, nreflex));
        set_flag(&r->v[c], EAR, is_ear(r, c, nreflex));
        /* On past c, not back to a: clipping at a again would fan every
           triangle out of one vertex (a convex n-gon: n - 2 slivers
           sharing a corner, which no kd-tree can separate).  Going round
           the ring clips every other vertex a round, like halving the
           polygon: triangles of each size in their own place. */
        cur = rnext(r, c);
        tries = 0;
    }
    if (corner(r, 1) > 0) {
        uint32_t v0 = r->v[0] & IDX, v1 = r->v[1] & IDX, v2 = r->v[2] & IDX;
        tri[3 * out] = v0;
        tri[3 * out + 1] = v1;
        tri[3 * out + 2] = v2;
        out++;
    }
    return out;
}

size_t rtpi_triangulate(const double *pts, size_t n, uint32_t *tri)
{
    double nrm[3], ax[3];
    int k;
    size_t i;
    ring r;
    if (n < 3 || n > IDX)
        return 0;
    newell(pts, n, nrm);
    ax[0] = fabs(nrm[0]);
    ax[1] = fabs(nrm[1]);
    ax[2] = fabs(nrm[2]);
    if (!(ax[0] + ax[1] + ax[2] > 0.0)) /* zero area or NaN */
        return 0;
    /* Drop the dominant axis k; (k+1, k+2) is a right-handed plane, so the
       normal's k component gives the winding's sign. */
    k = ax[0] >= ax[1] && ax[0] >= ax[2] ? 0 : ax[1] >= ax[2] ? 1 : 2;
    r.x = pts + (k + 1) % 3;
    r.y = pts + (k + 2) % 3;
    r.sign = (k == 0 ? nrm[0] : k == 1 ? nrm[1] : nrm[2]) > 0 ? 1.0 : -1.0;
    r.m = n;
    r.v = tri + 3 * (n - 2) - n;
    for (i = 0; i < n; i++)
        r.v[i] = (uint32_t)i;
    return clip(&r, tri);
}
