/* bezier.c — Newell's bicubic Bezier patches (.bpt: the patch count, 16
 * 1-based control point indices per patch, the point count and the
 * points, all separated by commas and/or white space), tessellated into
 * DIV x DIV quads per patch with analytic vertex normals.
 *
 * A patch's triangles wind so that their normals point along
 * dP/dv x dP/du, u running down the 4x4 control grid (from one row of
 * four indices to the next), v along a row: for Newell's teapot that is
 * outwards on every patch.  Where a patch edge collapses to a point (the teapot's lid
 * top and bottom centre) one partial derivative vanishes and the cross
 * product with it; the normal there is the limit taken from just inside
 * the patch. */
#include "readers.h"

#include <stdio.h>

/* Patches and points a .bpt may announce; far above any real model. */
#define PATCH_MAX 1000000
#define POINT_MAX 16000000

typedef struct patch {
    double p[16][3];
    double size2; /* squared size of the control net: the tolerances' scale */
} patch;

static void bernstein(double t, double b[4], double d[4])
{
    double s = 1.0 - t;
    b[0] = s * s * s;
    b[1] = 3.0 * t * s * s;
    b[2] = 3.0 * t * t * s;
    b[3] = t * t * t;
    d[0] = -3.0 * s * s;
    d[1] = 3.0 * s * s - 6.0 * t * s;
    d[2] = 6.0 * t * s - 3.0 * t * t;
    d[3] = 3.0 * t * t;
}

/* Position and (unnormalised) normal Pv x Pu at (u, v). */
static void eval(const patch *pa, double u, double v, rtpi_v3 *pos,
                 rtpi_v3 *nrm)
{
    double bu[4], du[4], bv[4], dv[4];
    rtpi_v3 p = v3(0, 0, 0), pu = v3(0, 0, 0), pv = v3(0, 0, 0);
    int i, j;
    bernstein(u, bu, du);
    bernstein(v, bv, dv);
    for (i = 0; i < 4; i++) {
        for (j = 0; j < 4; j++) {
            const double *c = pa->p[4 * i + j];
            rtpi_v3 cp = v3(c[0], c[1], c[2]);
            p = v3_madd(p, cp, bu[i] * bv[j]);
            pu = v3_madd(pu, cp, du[i] * bv[j]);
            pv = v3_madd(pv, cp, bu[i] * dv[j]);
        }
    }
    *pos = p;
    *nrm = v3_cross(pv, pu);
}

/* A cross product this small against the net's size squared is a
   vanished derivative, not a real surface direction. */
static int degenerate(const patch *pa, rtpi_v3 n)
{
    return !(v3_dot(n, n) > 1e-20 * pa->size2 * pa->size2);
}

/* The unit normal at (u, v): analytic, or at a collapsed edge the limit
   from a point moved a little towards the patch centre. */
static rtpi_v3 normal_at(const patch *pa, double u, double v, rtpi_v3 n)
{
    static const double step[] = {1e-6, 1e-4, 1e-2};
    rtpi_v3 p;
    size_t k;
    for (k = 0; degenerate(pa, n) && k < sizeof step / sizeof *step; k++)
        eval(pa, u + (0.5 - u) * step[k], v + (0.5 - v) * step[k], &p, &n);
    return degenerate(pa, n) ? v3(0, 0, 0) : v3_norm(n);
}

static rtp_status read_int(rtpi_lex *lx, const char *what, long lo, long hi,
                           long *out, rtpi_tok *tok)
{
    char show[48];
    if (!rtpi_lex_next(lx, tok))
        return rtpi_lex_error(lx, tok, "unexpected end of file, expected %s", what);
    if (rtpi_tok_int(tok, out) != 0 || *out < lo || *out > hi)
        return rtpi_lex_error(lx, tok, "expected %s from %ld to %ld, got '%s'", what,
                              lo, hi, rtpi_tok_show(tok, show, sizeof show));
    return RTP_OK;
}

/* flip: the transform mirrors, so dP/dv x dP/du (and the winding made
   from it) points inwards: the normals are turned and each triangle's
   corners taken in the other order, as for a mirrored OBJ (a glass
   teapot mirrored was refracted as if seen from inside) */
static rtp_status tessellate(rtp_scene *s, const patch *pa, int div,
                             uint32_t mat, rtpi_v3 *gp, rtpi_v3 *gn,
                             const rtpi_lex *lx, int flip)
{
    int i, j, n1 = div + 1;
    uint32_t base_p = (uint32_t)s->npos, base_n = (uint32_t)s->nnrm;
    rtpi_tok here;
    rtpi_lex_here(lx, &here);
    for (i = 0; i <= div; i++) {
        for (j = 0; j <= div; j++) {
            double u = (double)i / div, v = (double)j / div;
            rtpi_v3 n;
            eval(pa, u, v, &gp[i * n1 + j], &n);
            gn[i * n1 + j] = normal_at(pa, u, v, n);
        }
    }
    /* Points where even the inner limit failed (a patch collapsed to a
       curve) take the summed normals of the grid triangles around them. */
    for (i = 0; i <= div; i++) {
        for (j = 0; j <= div; j++) {
            rtpi_v3 *n = &gn[i * n1 + j], acc = v3(0, 0, 0);
            int di, dj;
            if (v3_dot(*n, *n) > 0.0)
                continue;
            for (di = -1; di <= 0; di++) {
                for (dj = -1; dj <= 0; dj++) {
                    int a = i + di, b = j + dj;
                    rtpi_v3 p00, p10, p11, p01;
                    if (a < 0 || b < 0 || a >= div || b >= div)
                        continue;
                    p00 = gp[a * n1 + b];
                    p10 = gp[(a + 1) * n1 + b];
                    p11 = gp[(a + 1) * n1 + b + 1];
                    p01 = gp[a * n1 + b + 1];
                    acc = v3_add(acc, v3_cross(v3_sub(p01, p10), v3_sub(p11, p00)));
                }
            }
            *n = v3_dot(acc, acc) > 0.0 ? v3_norm(acc) : v3(0, 0, 1);
        }
    }
    for (i = 0; i < n1 * n1; i++) {
        if (flip)
            gn[i] = v3_mul(gn[i], -1.0);
        if (rtpi_scene_add_pos(s, gp[i].x, gp[i].y, gp[i].z) ||
            rtpi_scene_add_nrm(s, gn[i].x, gn[i].y, gn[i].z))
            return rtpi_error(lx->err, RTP_ERR_NOMEM, lx->name, here.line,
                              here.col, "out of memory");
    }
    for (i = 0; i < div; i++) {
        for (j = 0; j < div; j++) {
            uint32_t q[4];
            int t;
            q[0] = (uint32_t)(i * n1 + j);
            q[1] = (uint32_t)(i * n1 + j + 1);
            q[2] = (uint32_t)((i + 1) * n1 + j + 1);
            q[3] = (uint32_t)((i + 1) * n1 + j);
            for (t = 0; t < 2; t++) {
                uint32_t a = q[0], b = q[1 + t], c = q[2 + t];
                rtpi_v3 g = v3_cross(v3_sub(gp[b], gp[a]), v3_sub(gp[c], gp[a]));
                rtpi_tri tr;
                int k;
                /* Triangles on a collapsed edge have no area. */
                if (degenerate(pa, v3_mul(g, (double)div * div)))
                    continue;
                tr.v[0] = base_p + a;
                tr.v[1] = base_p + (flip ? c : b);
                tr.v[2] = base_p + (flip ? b : c);
                for (k = 0; k < 3; k++) {
                    tr.n[k] = base_n + (tr.v[k] - base_p);
                    tr.t[k] = RTPI_NONE;
                }
                tr.mat = mat;
                if (rtpi_scene_add_tri(s, &tr))
                    return rtpi_error(lx->err, RTP_ERR_NOMEM, lx->name,
                                      here.line, here.col, "out of memory");
            }
        }
    }
    return RTP_OK;
}

rtp_status rtpi_read_bpt(rtp_scene *s, const char *text, size_t size,
                         const char *name, int div, const double *xform,
                         uint32_t mat, rtp_error *err)
{
    rtpi_lex lx;
    rtpi_tok t, max_tok;
    long npatch, npts, v, max_idx = 0;
    uint32_t *idx = NULL;
    double *pts = NULL;
    rtpi_v3 *grid = NULL;
    size_t i, k, left;
    rtp_status st;
    int r;
    char show[48];
    const rtp_allocator *a = &s->alloc;
    rtpi_lex_init(&lx, text, size, name ? name : "<memory>", err);
    lx.commas = 1;
    memset(&max_tok, 0, sizeof max_tok);
    if (div < 1 || div > 1024)
        return rtpi_error(err, RTP_ERR_ARGUMENT, lx.name, 0, 0,
                          "bezier subdivisions %d out of range", div);
    if ((st = read_int(&lx, "patch count", 1, PATCH_MAX, &npatch, &t)) != RTP_OK)
        return st;
    /* Each index takes at least two bytes: refuse counts the text cannot
       hold before allocating for them. */
    left = (size_t)(lx.end - lx.p);
    if ((size_t)npatch * 32 > left + 1)
        return rtpi_lex_error(&lx, &t, "patch count %ld, but the file ends before %ld patches",
                              npatch, npatch);
    idx = (uint32_t *)rtpi_malloc_array(a, (size_t)npatch * 16, sizeof *idx);
    if (!idx)
        return rtpi_error(err, RTP_ERR_NOMEM, lx.name, t.line, t.col, "out of memory");
    for (i = 0; i < (size_t)npatch * 16; i++) {
        char what[64];
        snprintf(what, sizeof what, "control point index %zu of patch %zu",
                 i % 16 + 1, i / 16 + 1);
        if ((st = read_int(&lx, what, 1, POINT_MAX, &v, &t)) != RTP_OK)
            goto done;
        if (v > max_idx) {
            max_idx = v;
            max_tok = t;
        }
        idx[i] = (uint32_t)(v - 1);
    }
    if ((st = read_int(&lx, "point count", 1, POINT_MAX, &npts, &t)) != RTP_OK)
        goto done;
    if (max_idx > npts) {
        st = rtpi_lex_error(&lx, &max_tok, "control point index %ld out of range (%ld points)",
                            max_idx, npts);
        goto done;
    }
    left = (size_t)(lx.end - lx.p);
    if ((size_t)npts * 6 > left + 1) {
        st = rtpi_lex_error(&lx, &t, "point count %ld, but the file ends before %ld points",
                            npts, npts);
        goto done;
    }
    pts = (double *)rtpi_malloc_array(a, (size_t)npts * 3, sizeof *pts);
    grid = (rtpi_v3 *)rtpi_malloc_array(a, (size_t)(div + 1) * (size_t)(div + 1) * 2,
                                        sizeof *grid);
    if (!pts || !grid) {
        st = rtpi_error(err, RTP_ERR_NOMEM, lx.name, t.line, t.col, "out of memory");
        goto done;
    }
    for (i = 0; i < (size_t)npts; i++) {
        double p[3];
        for (k = 0; k < 3; k++) {
            if (!rtpi_lex_next(&lx, &t)) {
                st = rtpi_lex_error(&lx, &t, "unexpected end of file, expected point %zu %c",
                                    i + 1, (int)('x' + k));
                goto done;
            }
            r = rtpi_tok_number(&t, &p[k]);
            if (r == -1) {
                st = rtpi_lex_error(&lx, &t, "expected number for point %zu %c, got '%s'",
                                    i + 1, (int)('x' + k), rtpi_tok_show(&t, show, sizeof show));
                goto done;
            }
            /* (as the NFF reader says it: 1e999 is a number, too large) */
            if (r != 0 || fabs(p[k]) > 1e18) {
                st = rtpi_lex_error(&lx, &t, "point %zu %c %s is out of range (|x| <= 1e+18)",
                                    i + 1, (int)('x' + k), rtpi_tok_show(&t, show, sizeof show));
                goto done;
            }
        }
        rtpi_xform_point(xform, p, pts + 3 * i);
        /* (the bound after the transform too, as for OBJ vertices) */
        for (k = 0; k < 3; k++)
            if (!(fabs(pts[3 * i + k]) <= 1e18)) {
                st = rtpi_lex_error(&lx, &t,
                                    "point %zu out of range after the transform (at most 1e18)",
                                    i + 1);
                goto done;
            }
    }
    if (rtpi_lex_next(&lx, &t)) {
        st = rtpi_lex_error(&lx, &t, "unexpected '%s' after the last point",
                            rtpi_tok_show(&t, show, sizeof show));
        goto done;
    }
    for (i = 0; i < (size_t)npatch; i++) {
        patch pa;
        double lo[3], hi[3];
        for (k = 0; k < 16; k++) {
            memcpy(pa.p[k], pts + 3 * (size_t)idx[16 * i + k], sizeof pa.p[k]);
            if (k == 0) {
                memcpy(lo, pa.p[k], sizeof lo);
                memcpy(hi, pa.p[k], sizeof hi);
            }
            for (v = 0; v < 3; v++) {
                lo[v] = pa.p[k][v] < lo[v] ? pa.p[k][v] : lo[v];
                hi[v] = pa.p[k][v] > hi[v] ? pa.p[k][v] : hi[v];
            }
        }
        pa.size2 = (hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                   (hi[2] - lo[2]) * (hi[2] - lo[2]);
        if (pa.size2 == 0.0)
            continue; /* a patch collapsed to a point shows nothing */
        st = tessellate(s, &pa, div, mat, grid, grid + (size_t)(div + 1) * (div + 1), &lx,
                        xform && rtpi_xform_mirrors(xform));
        if (st != RTP_OK)
            goto done;
    }
done:
    rtpi_free(a, idx);
    rtpi_free(a, pts);
    rtpi_free(a, grid);
    return st;
}
