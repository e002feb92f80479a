/* nff.c — the NFF reader: Eric Haines' Neutral File Format exactly as the
 * SPD generators write it, read token by token (not line by line), plus
 * rtp's additions (scenes/README.md): name, off, ambient, ka, checker,
 * texture, bump, include and bezier.
 *
 * Every malformed input is a parse error at the offending token's line
 * and column; nothing is allocated from a count before the text has been
 * checked to be long enough to hold what the count announces. */
#include "readers.h"

#include <stdio.h>

/* Largest magnitude accepted for geometry and the camera (their squares
   must stay finite), and for the values the keys set too: RTPI_*_LIMIT. */
#define NUM_LIMIT RTPI_COORD_LIMIT
#define VALUE_LIMIT RTPI_VALUE_LIMIT

/* Image size limit per side for `resolution`. */
#define RES_MAX 32768

/* Bezier subdivisions per patch side (2*DIV^2 triangles per patch). */
#define BEZIER_DIV_MAX 256

/* Names of materials and lights. */
#define NAME_MAX_LEN 63

typedef struct nff {
    rtp_scene *s;
    rtpi_lex lx;
    rtp_error *err;
    int depth;
    uint32_t mat;     /* current material; RTPI_MAT_PENDING before any f */
    int named_kind;   /* 'f' or 'l': what `name` applies to; 0 none */
    size_t named_index;
    rtpi_nff_stats *st;
    rtpi_mtl_reg *mtl; /* the MTL files the load's OBJ includes read */
    double *pts;      /* polygon scratch: xyz (and normals for pp) */
    size_t cap_pts;
    uint32_t *tri;
    size_t cap_tri;
} nff;

static rtp_status parse(nff *c);

/* ------------------------------------------------------------- tokens */

/* Next token of statement `what` (e.g. "s (sphere)"), which expects
   `field` next; end of input is an error naming both. */
static rtp_status need(nff *c, rtpi_tok *t, const char *what,
                       const char *field)
{
    if (rtpi_lex_next(&c->lx, t))
        return RTP_OK;
    return rtpi_lex_error(&c->lx, t,
                          "unexpected end of file in %s line, expected %s",
                          what, field);
}

/* A field's name in a message: `field`, or "vertex N field" for vertex
   vtx (1-based; 0: none) of a polygon. */
static const char *field_name(char *buf, size_t size, size_t vtx, const char *field)
{
    if (!vtx)
        return field;
    snprintf(buf, size, "vertex %zu %s", vtx, field);
    return buf;
}

/* A number up to `limit` in magnitude; vtx as field_name's.  (A polygon's
   field is named only for a message: one snprintf a number had been 43%
   of mount_s6's parse.) */
static rtp_status num_upto_v(nff *c, const char *what, const char *noun,
                             const char *field, size_t vtx, double limit, double *out,
                             rtpi_tok *tok)
{
    rtpi_tok t;
    char show[48], fb[48];
    int r;
    if (!rtpi_lex_next(&c->lx, &t))
        return rtpi_lex_error(&c->lx, &t, "unexpected end of file in %s line, expected %s",
                              what, field_name(fb, sizeof fb, vtx, field));
    r = rtpi_tok_number(&t, out);
    if (r == -1)
        return rtpi_lex_error(&c->lx, &t, "expected number for %s %s, got '%s'", noun,
                              field_name(fb, sizeof fb, vtx, field),
                              rtpi_tok_show(&t, show, sizeof show));
    if (r != 0 || fabs(*out) > limit) {
        char lim[32];
        rtpi_fmt_g(lim, sizeof lim, 6, limit);
        return rtpi_lex_error(&c->lx, &t, "%s %s %s is out of range (|x| <= %s)", noun,
                              field_name(fb, sizeof fb, vtx, field),
                              rtpi_tok_show(&t, show, sizeof show), lim);
    }
    if (tok)
        *tok = t;
    return RTP_OK;
}

static rtp_status num_upto(nff *c, const char *what, const char *noun,
                           const char *field, double limit, double *out,
                           rtpi_tok *tok)
{
    return num_upto_v(c, what, noun, field, 0, limit, out, tok);
}

/* A number within NUM_LIMIT. */
static rtp_status num(nff *c, const char *what, const char *noun,
                      const char *field, double *out, rtpi_tok *tok)
{
    return num_upto(c, what, noun, field, NUM_LIMIT, out, tok);
}

/* n numbers with field names, each within `limit`; tokens to toks (may
   be NULL). */
static rtp_status nums_upto(nff *c, const char *what, const char *noun,
                            const char *const *fields, int n, double limit,
                            double *out, rtpi_tok *toks)
{
    int i;
    for (i = 0; i < n; i++) {
        rtp_status st = num_upto(c, what, noun, fields[i], limit, &out[i],
                                 toks ? &toks[i] : NULL);
        if (st != RTP_OK)
            return st;
    }
    return RTP_OK;
}

static rtp_status nums(nff *c, const char *what, const char *noun,
                       const char *const *fields, int n, double *out,
                       rtpi_tok *toks)
{
    return nums_upto(c, what, noun, fields, n, NUM_LIMIT, out, toks);
}

/* num and nums for a value a key sets too (VALUE_LIMIT). */
static rtp_status val(nff *c, const char *what, const char *noun, const char *field,
                      double *out, rtpi_tok *tok)
{
    return num_upto(c, what, noun, field, VALUE_LIMIT, out, tok);
}

static rtp_status vals(nff *c, const char *what, const char *noun,
                       const char *const *fields, int n, double *out, rtpi_tok *toks)
{
    return nums_upto(c, what, noun, fields, n, VALUE_LIMIT, out, toks);
}

/* A non-negative value, or an error at its token. */
static rtp_status nonneg(nff *c, const rtpi_tok *t, const char *noun,
                         const char *field, double v)
{
    char g[32];
    if (v >= 0.0)
        return RTP_OK;
    rtpi_fmt_g(g, sizeof g, 6, v);
    return rtpi_lex_error(&c->lx, t, "%s %s must not be negative, got %s", noun, field, g);
}

/* Whether the next token is meant as a number (without consuming it):
   a bad one ("nan", "1e999", "0x10") too, which num then names by its
   field, where taking it for the next keyword said "unknown keyword
   'nan'" of `ka 0.1 nan 0.2`. */
static int peek_number(const nff *c)
{
    rtpi_lex save = c->lx;
    rtpi_tok t;
    return rtpi_lex_next(&save, &t) && rtpi_tok_numlike(&t);
}

/* Consumes the next token if it is `word`. */
static int accept(nff *c, const char *word, rtpi_tok *t)
{
    rtpi_lex save = c->lx;
    if (rtpi_lex_next(&save, t) && rtpi_tok_is(t, word)) {
        c->lx = save;
        return 1;
    }
    return 0;
}

/* A count for `p`/`pp`: 3 <= n <= RTPI_POLY_MAX and the rest of the text
   long enough for n vertices of `per` numbers (each at least one digit
   and one separator), checked before anything is allocated. */
static rtp_status count(nff *c, const char *what, const char *noun, int per,
                        size_t *out)
{
    rtpi_tok t;
    long n;
    char show[48];
    size_t left;
    rtp_status st = need(c, &t, what, "vertex count");
    if (st != RTP_OK)
        return st;
    if (rtpi_tok_int(&t, &n) != 0)
        return rtpi_lex_error(&c->lx, &t, "expected vertex count for %s, got '%s'",
                              noun, rtpi_tok_show(&t, show, sizeof show));
    if (n < 3)
        return rtpi_lex_error(&c->lx, &t, "%s vertex count %ld < 3", noun, n);
    if (n > RTPI_POLY_MAX)
        return rtpi_lex_error(&c->lx, &t, "%s vertex count %ld exceeds the limit of %d",
                              noun, n, RTPI_POLY_MAX);
    left = (size_t)(c->lx.end - c->lx.p);
    if ((size_t)n * (size_t)per * 2 > left + 1)
        return rtpi_lex_error(&c->lx, &t,
                              "%s vertex count %ld, but the file ends before %ld vertices",
                              noun, n, n);
    *out = (size_t)n;
    return RTP_OK;
}

static rtp_status nomem(nff *c, const rtpi_tok *t)
{
    return rtpi_error(c->err, RTP_ERR_NOMEM, c->lx.name, t->line, t->col,
                      "out of memory");
}

/* ---------------------------------------------------------- statements */

static rtp_status read_view(nff *c, const rtpi_tok *vtok)
{
    static const char *const xyz[] = {"x", "y", "z"};
    rtpi_camera *cam = &c->s->camera;
    rtpi_tok t, at_tok = *vtok, up_tok = *vtok, tk[2];
    double v[3];
    rtp_status st = RTP_OK;
    int i;
    const char *why;
    char g0[32]; /* a number in a message, '.' whatever the locale */
    for (;;) {
        if (accept(c, "from", &t)) {
            st = nums(c, "v (view) from", "view from", xyz, 3, cam->from, NULL);
        } else if (accept(c, "at", &t)) {
            at_tok = t;
            st = nums(c, "v (view) at", "view at", xyz, 3, cam->at, NULL);
        } else if (accept(c, "up", &t)) {
            up_tok = t;
            st = nums(c, "v (view) up", "view up", xyz, 3, cam->up, NULL);
        } else if (accept(c, "angle", &t)) {
            st = num(c, "v (view) angle", "view", "angle", &v[0], &tk[0]);
            if (st == RTP_OK && !(v[0] > 0.0 && v[0] < 180.0)) {
                rtpi_fmt_g(g0, sizeof g0, 6, v[0]);
                st = rtpi_lex_error(&c->lx, &tk[0],
                                    "view angle %s must be between 0 and 180 degrees", g0);
            }
            cam->angle = v[0];
        } else if (accept(c, "hither", &t)) {
            st = num(c, "v (view) hither", "view", "hither", &v[0], &tk[0]);
            if (st == RTP_OK)
                st = nonneg(c, &tk[0], "view", "hither", v[0]);
            cam->hither = v[0];
        } else if (accept(c, "resolution", &t)) {
            static const char *const wh[] = {"width", "height"};
            st = nums(c, "v (view) resolution", "resolution", wh, 2, v, tk);
            for (i = 0; st == RTP_OK && i < 2; i++)
                if (!(v[i] >= 1 && v[i] <= RES_MAX && v[i] == floor(v[i]))) {
                    rtpi_fmt_g(g0, sizeof g0, 6, v[i]);
                    st = rtpi_lex_error(&c->lx, &tk[i],
                                        "resolution %s %s must be a whole number from 1 to %d",
                                        wh[i], g0, RES_MAX);
                }
            /* (the whole image's bound too, which trace would name
               without the file's line) */
            if (st == RTP_OK && !rtpi_image_size_ok((int)v[0], (int)v[1]))
                st = rtpi_lex_error(&c->lx, &tk[1],
                                    "resolution %dx%d is over the limit of 2^27 pixels",
                                    (int)v[0], (int)v[1]);
            if (st == RTP_OK) {
                c->s->width = (int)v[0];
                c->s->height = (int)v[1];
            }
        } else {
            break;
        }
        if (st != RTP_OK)
            return st;
    }
    /* (the test rtp_scene_set's camera keys and the tree reader make,
       named in NFF's words at the token, and kept for when a frame is
       made: keys set after the file is read may repair it, as
       `rtp trace s.nff --set camera.at=...` does) */
    why = rtpi_camera_problem(c->s);
    c->s->cam_bad[0] = c->s->cam_bad[1] = 0;
    if (why && strstr(why, "camera.at")) {
        rtpi_error(&c->s->cam_err[0], RTP_ERR_ARGUMENT, c->lx.name, at_tok.line, at_tok.col,
                   "view at equals view from");
        c->s->cam_bad[0] = 1;
    } else if (why) {
        rtpi_error(&c->s->cam_err[1], RTP_ERR_ARGUMENT, c->lx.name, up_tok.line, up_tok.col,
                   "view up is zero or parallel to the view direction");
        c->s->cam_bad[1] = 1;
    }
    return RTP_OK;
}

static rtp_status read_light(nff *c)
{
    static const char *const xyz[] = {"x", "y", "z"};
    static const char *const rgb[] = {"red", "green", "blue"};
    rtpi_light l;
    rtpi_tok tk[3];
    rtp_status st;
    int i;
    long idx;
    memset(&l, 0, sizeof l);
    st = nums_upto(c, "l (light)", "light", xyz, 3, VALUE_LIMIT, l.pos,
                   NULL);
    if (st != RTP_OK)
        return st;
    l.color[0] = l.color[1] = l.color[2] = 1.0f;
    l.on = 1;
    if (peek_number(c)) {
        double col[3];
        st = vals(c, "l (light)", "light", rgb, 3, col, tk);
        for (i = 0; st == RTP_OK && i < 3; i++) {
            st = nonneg(c, &tk[i], "light", rgb[i], col[i]);
            l.color[i] = (float)col[i];
        }
        if (st != RTP_OK)
            return st;
    }
    idx = rtpi_scene_add_light(c->s, &l);
    if (idx < 0) {
        rtpi_tok here;
        rtpi_lex_here(&c->lx, &here);
        return nomem(c, &here);
    }
    c->named_kind = 'l';
    c->named_index = (size_t)idx;
    return RTP_OK;
}

static rtp_status read_rgb(nff *c, const char *what, const char *noun,
                           float *dst)
{
    static const char *const rgb[] = {"red", "green", "blue"};
    double v[3];
    rtpi_tok tk[3];
    int i;
    rtp_status st = vals(c, what, noun, rgb, 3, v, tk);
    for (i = 0; st == RTP_OK && i < 3; i++) {
        st = nonneg(c, &tk[i], noun, rgb[i], v[i]);
        dst[i] = (float)v[i];
    }
    return st;
}

static rtp_status read_material(nff *c)
{
    static const char *const f[] = {"red", "green", "blue", "Kd", "Ks",
                                    "Shine", "T", "ior"};
    rtpi_material m;
    double v[8];
    rtpi_tok tk[8];
    int i;
    long idx;
    rtp_status st = vals(c, "f (material)", "material", f, 8, v, tk);
    if (st != RTP_OK)
        return st;
    for (i = 0; i < 8; i++)
        if ((st = nonneg(c, &tk[i], "material", f[i], v[i])) != RTP_OK)
            return st;
    rtpi_material_default(&m);
    for (i = 0; i < 3; i++)
        m.color[i] = (float)v[i];
    m.kd = (float)v[3];
    m.ks = (float)v[4];
    m.shine = (float)v[5];
    m.kt = (float)v[6];
    /* SPD writes ior 0 for opaque materials (and one below the float
       range, 1e-50, is 0 as the scene keeps it) */
    m.ior = (float)v[7] > 0.0f ? (float)v[7] : 1.0f;
    idx = rtpi_scene_add_material(c->s, &m);
    if (idx < 0)
        return nomem(c, &tk[7]);
    c->mat = (uint32_t)idx;
    c->named_kind = 'f';
    c->named_index = (size_t)idx;
    return RTP_OK;
}

static rtp_status read_sphere(nff *c)
{
    static const char *const f[] = {"x", "y", "z", "radius"};
    double v[4];
    rtpi_tok tk[4];
    rtpi_sphere sp;
    rtp_status st = nums(c, "s (sphere)", "sphere", f, 4, v, tk);
    if (st != RTP_OK)
        return st;
    /* (as the float it is kept as: 1e-46 became 0, a sphere the tree
       file's reader refuses) */
    if ((float)v[3] == 0.0f)
        return rtpi_lex_error(&c->lx, &tk[3], "sphere radius is 0 (as a float)");
    sp.c[0] = (float)v[0];
    sp.c[1] = (float)v[1];
    sp.c[2] = (float)v[2];
    sp.r = (float)v[3];
    sp.mat = c->mat;
    if (rtpi_scene_add_sphere(c->s, &sp))
        return nomem(c, &tk[3]);
    if (c->st)
        c->st->spheres++;
    return RTP_OK;
}

static rtp_status read_cone(nff *c)
{
    static const char *const f[] = {"base x", "base y", "base z",
                                    "base radius", "apex x", "apex y",
                                    "apex z", "apex radius"};
    double v[8];
    rtpi_tok tk[8];
    rtpi_cone cn;
    int i;
    rtp_status st = nums(c, "c (cone)", "cone", f, 8, v, tk);
    if (st != RTP_OK)
        return st;
    if ((st = nonneg(c, &tk[3], "cone", f[3], v[3])) != RTP_OK ||
        (st = nonneg(c, &tk[7], "cone", f[7], v[7])) != RTP_OK)
        return st;
    if ((float)v[3] == 0.0f && (float)v[7] == 0.0f)
        return rtpi_lex_error(&c->lx, &tk[7], "cone radii are both 0");
    /* (as floats, as the scene keeps them and a tree file's reader checks
       them: 1 and 1.00000001 are one point) */
    if ((float)v[0] == (float)v[4] && (float)v[1] == (float)v[5] && (float)v[2] == (float)v[6])
        return rtpi_lex_error(&c->lx, &tk[4], "cone apex equals its base (as a float)");
    for (i = 0; i < 3; i++) {
        cn.base[i] = (float)v[i];
        cn.apex[i] = (float)v[4 + i];
    }
    cn.rb = (float)v[3];
    cn.ra = (float)v[7];
    cn.mat = c->mat;
    if (rtpi_scene_add_cone(c->s, &cn))
        return nomem(c, &tk[0]);
    if (c->st)
        c->st->cones++;
    return RTP_OK;
}

/* p n (smooth = 0) or pp n (smooth = 1). */
static rtp_status read_polygon(nff *c, const rtpi_tok *kw, int smooth)
{
    const char *what = smooth ? "pp (polygon patch)" : "p (polygon)";
    const char *noun = smooth ? "polygon patch" : "polygon";
    static const char *const f[] = {"x", "y", "z", "normal x", "normal y",
                                    "normal z"};
    size_t n = 0, i, k, ntri;
    int per = smooth ? 6 : 3;
    uint32_t base_p, base_n;
    rtp_status st = count(c, what, noun, per, &n);
    if (st != RTP_OK)
        return st;
    if (rtpi_grow(&c->s->alloc, (void **)&c->pts, &c->cap_pts, 6 * n,
                  sizeof *c->pts) ||
        rtpi_grow(&c->s->alloc, (void **)&c->tri, &c->cap_tri, 3 * n,
                  sizeof *c->tri))
        return nomem(c, kw);
    for (i = 0; i < n; i++) {
        double v[6];
        rtpi_tok tk[6];
        for (k = 0; k < (size_t)per; k++) {
            st = num_upto_v(c, what, noun, f[k], i + 1, NUM_LIMIT, &v[k], &tk[k]);
            if (st != RTP_OK)
                return st;
        }
        memcpy(c->pts + 3 * i, v, 3 * sizeof *v);
        if (smooth) {
            if (v[3] == 0.0 && v[4] == 0.0 && v[5] == 0.0)
                return rtpi_lex_error(&c->lx, &tk[3],
                                      "polygon patch vertex %zu normal is zero",
                                      i + 1);
            memcpy(c->pts + 3 * (n + i), v + 3, 3 * sizeof *v);
        }
    }
    if (c->st) {
        if (smooth)
            c->st->polypatches++;
        else
            c->st->polygons++;
    }
    if (n == 3) {
        /* Triangles are kept as written, even degenerate ones. */
        c->tri[0] = 0;
        c->tri[1] = 1;
        c->tri[2] = 2;
        ntri = 1;
    } else {
        ntri = rtpi_triangulate(c->pts, n, c->tri);
        if (ntri == 0)
            return RTP_OK; /* no area: nothing to see */
    }
    base_p = (uint32_t)c->s->npos;
    base_n = (uint32_t)c->s->nnrm;
    for (i = 0; i < n; i++) {
        const double *p = c->pts + 3 * i;
        if (rtpi_scene_add_pos(c->s, p[0], p[1], p[2]))
            return nomem(c, kw);
        if (smooth) {
            const double *q = c->pts + 3 * (n + i);
            rtpi_v3 nv = rtpi_unit_normal(q[0], q[1], q[2]);
            if (rtpi_scene_add_nrm(c->s, nv.x, nv.y, nv.z))
                return nomem(c, kw);
        }
    }
    for (i = 0; i < ntri; i++) {
        rtpi_tri t;
        for (k = 0; k < 3; k++) {
            t.v[k] = base_p + c->tri[3 * i + k];
            t.n[k] = smooth ? base_n + c->tri[3 * i + k] : RTPI_NONE;
            t.t[k] = RTPI_NONE;
        }
        t.mat = c->mat;
        if (rtpi_scene_add_tri(c->s, &t))
            return nomem(c, kw);
    }
    return RTP_OK;
}

/* ----------------------------------------------------------- additions */

static int name_char(char ch, int first)
{
    return (ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z') || ch == '_' ||
           (!first && ((ch >= '0' && ch <= '9') || ch == '-'));
}

static rtp_status read_name(nff *c, const rtpi_tok *kw)
{
    rtpi_tok t;
    char show[80], *nm;
    size_t i;
    char **slot;
    const char *kind = c->named_kind == 'f' ? "material" : "light";
    rtp_status st = need(c, &t, "name", "a name");
    if (st != RTP_OK)
        return st;
    rtpi_tok_show(&t, show, sizeof show);
    if (!c->named_kind)
        return rtpi_lex_error(&c->lx, kw,
                              "name '%s' must follow an f (material) or l (light) line",
                              show);
    for (i = 0; i < t.n; i++)
        if (!name_char(t.s[i], i == 0))
            return rtpi_lex_error(&c->lx, &t,
                                  "invalid name '%s' (letters, digits, '_' and '-', not starting with a digit or '-')",
                                  show);
    if (t.n > NAME_MAX_LEN)
        return rtpi_lex_error(&c->lx, &t, "name '%s' is longer than %d characters",
                              show, NAME_MAX_LEN);
    if (c->named_kind == 'f')
        slot = &c->s->mats[c->named_index].name;
    else
        slot = &c->s->lights[c->named_index].name;
    if (*slot)
        return rtpi_lex_error(&c->lx, &t, "%s %zu is already named '%s'", kind,
                              c->named_index, *slot);
    {
        size_t at = 0;
        long other = rtpi_reg_find(c->mtl, c->s, c->named_kind, t.s, t.n, &at);
        if (other >= 0)
            return rtpi_lex_error(&c->lx, &t, "%s name '%s' is already used by %s %ld",
                                  kind, show, kind, other);
    }
    nm = (char *)rtpi_malloc(&c->s->alloc, t.n + 1);
    if (!nm)
        return nomem(c, &t);
    memcpy(nm, t.s, t.n);
    nm[t.n] = '\0';
    *slot = nm;
    if (rtpi_reg_add(c->mtl, c->s, c->named_kind, (uint32_t)c->named_index) != 0)
        return nomem(c, &t);
    return RTP_OK;
}

/* The material that checker/texture/bump modify. */
static rtp_status current_material(nff *c, const rtpi_tok *kw,
                                   rtpi_material **m)
{
    char show[32];
    if (c->mat == RTPI_MAT_PENDING || c->mat >= c->s->nmats)
        return rtpi_lex_error(&c->lx, kw,
                              "%s needs a material: put it after an f line",
                              rtpi_tok_show(kw, show, sizeof show));
    *m = &c->s->mats[c->mat];
    return RTP_OK;
}

static rtp_status read_checker(nff *c, const rtpi_tok *kw)
{
    rtpi_material *m;
    float col[3];
    double scale;
    rtpi_tok tk;
    rtp_status st = current_material(c, kw, &m);
    if (st != RTP_OK || (st = read_rgb(c, "checker", "checker", col)) != RTP_OK ||
        (st = val(c, "checker", "checker", "scale", &scale, &tk)) != RTP_OK)
        return st;
    if (!((float)scale > 0.0f)) { /* (kept as a float: see rtpi_material) */
        char g[32];
        rtpi_fmt_g(g, sizeof g, 6, scale);
        return rtpi_lex_error(&c->lx, &tk, "checker scale must be positive, got %s", g);
    }
    m = &c->s->mats[c->mat];
    m->tex = RTPI_TEX_CHECKER;
    memcpy(m->color2, col, sizeof col);
    m->tex_scale = (float)scale;
    return RTP_OK;
}

/* ka V (grey) or ka R G B: the current material's ambient coefficient
   (mat.N.ambient; unset, it follows kd).  NFF's own keywords hold no ka. */
static rtp_status read_ka(nff *c, const rtpi_tok *kw)
{
    static const char *const field[] = {"value", "green", "blue"};
    rtpi_material *m;
    double v[3];
    rtpi_tok tk[3];
    int i, n = 1;
    rtp_status st = current_material(c, kw, &m);
    if (st != RTP_OK || (st = val(c, "ka", "ka", field[0], &v[0], &tk[0])) != RTP_OK)
        return st;
    if (peek_number(c)) {
        for (n = 1; n < 3; n++)
            if ((st = val(c, "ka", "ka", field[n], &v[n], &tk[n])) != RTP_OK)
                return st;
    }
    for (i = 0; i < n; i++)
        if ((st = nonneg(c, &tk[i], "ka", field[i], v[i])) != RTP_OK)
            return st;
    m = &c->s->mats[c->mat];
    for (i = 0; i < 3; i++)
        m->ka[i] = (float)v[n == 1 ? 0 : i];
    m->ka_set = 1;
    return RTP_OK;
}

/* A file name token resolved against the current file's folder. */
static rtp_status read_path(nff *c, const char *what, rtpi_tok *t,
                            char **path)
{
    rtp_status st = need(c, t, what, "a file name");
    if (st != RTP_OK)
        return st;
    /* A NUL would silently cut the name (the folder itself was read). */
    if (memchr(t->s, '\0', t->n))
        return rtpi_lex_error(&c->lx, t, "%s: a file name must not contain a NUL byte", what);
    *path = rtpi_path_join(&c->s->alloc, c->lx.name, t->s, t->n);
    return *path ? RTP_OK : nomem(c, t);
}

static rtp_status load_texture(nff *c, const char *what, uint32_t *index)
{
    rtpi_tok t;
    char *path = NULL;
    rtp_error inner;
    rtp_status st = read_path(c, what, &t, &path);
    if (st != RTP_OK)
        return st;
    memset(&inner, 0, sizeof inner);
    st = rtpi_scene_add_texture(c->s, path, 0, index, &inner);
    rtpi_free(&c->s->alloc, path);
    if (st != RTP_OK)
        return rtpi_lex_wrap(&c->lx, &t, st, &inner, "cannot load image");
    return RTP_OK;
}

static rtp_status read_texture(nff *c, const rtpi_tok *kw)
{
    rtpi_material *m;
    uint32_t idx;
    rtp_status st = current_material(c, kw, &m);
    if (st != RTP_OK || (st = load_texture(c, "texture", &idx)) != RTP_OK)
        return st;
    m = &c->s->mats[c->mat];
    m->tex = RTPI_TEX_IMAGE;
    m->tex_image = idx;
    return RTP_OK;
}

static rtp_status read_bump(nff *c, const rtpi_tok *kw)
{
    rtpi_material *m;
    rtpi_tok t;
    double scale = 1.0, strength;
    uint32_t idx = RTPI_NONE;
    rtpi_bump_kind kind;
    rtp_status st = current_material(c, kw, &m);
    if (st != RTP_OK)
        return st;
    if (accept(c, "waves", &t) || accept(c, "noise", &t)) {
        kind = t.s[0] == 'w' ? RTPI_BUMP_WAVES : RTPI_BUMP_NOISE;
        st = val(c, "bump", "bump", "scale", &scale, &t);
        if (st != RTP_OK)
            return st;
        if (!((float)scale > 0.0f)) {
            char g[32];
            rtpi_fmt_g(g, sizeof g, 6, scale);
            return rtpi_lex_error(&c->lx, &t, "bump scale must be positive, got %s", g);
        }
    } else {
        kind = RTPI_BUMP_IMAGE;
        if ((st = load_texture(c, "bump", &idx)) != RTP_OK)
            return st;
    }
    if ((st = val(c, "bump", "bump", "strength", &strength, NULL)) != RTP_OK)
        return st;
    m = &c->s->mats[c->mat];
    m->bump = kind;
    m->bump_image = idx;
    m->bump_scale = (float)scale;
    m->bump_strength = (float)strength;
    return RTP_OK;
}

/* [translate x y z] [scale s | scale sx sy sz] [rotate x|y|z DEG]...,
   applied in the order written. */
static rtp_status read_transforms(nff *c, const char *what, double m[12],
                                  int *any)
{
    static const char *const xyz[] = {"x", "y", "z"};
    rtpi_tok t;
    rtp_status st;
    *any = 0;
    rtpi_xform_identity(m);
    for (;;) {
        double v[3], a[12];
        rtpi_xform_identity(a);
        if (accept(c, "translate", &t)) {
            if ((st = nums(c, what, "translate", xyz, 3, v, NULL)) != RTP_OK)
                return st;
            a[3] = v[0];
            a[7] = v[1];
            a[11] = v[2];
        } else if (accept(c, "scale", &t)) {
            rtpi_tok tk;
            if ((st = num(c, what, "scale", "factor", &v[0], &tk)) != RTP_OK)
                return st;
            if (peek_number(c)) {
                static const char *const yz[] = {"y", "z"};
                if ((st = nums(c, what, "scale", yz, 2, v + 1, NULL)) != RTP_OK)
                    return st;
            } else {
                v[1] = v[2] = v[0];
            }
            if (v[0] == 0.0 || v[1] == 0.0 || v[2] == 0.0)
                return rtpi_lex_error(&c->lx, &tk, "scale factor 0 flattens the object");
            a[0] = v[0];
            a[5] = v[1];
            a[10] = v[2];
        } else if (accept(c, "rotate", &t)) {
            rtpi_tok ax;
            char show[32];
            int i, j, k;
            double rad, cs, sn;
            if ((st = need(c, &ax, what, "rotation axis x, y or z")) != RTP_OK)
                return st;
            if (ax.n != 1 || ax.s[0] < 'x' || ax.s[0] > 'z')
                return rtpi_lex_error(&c->lx, &ax,
                                      "expected rotation axis x, y or z, got '%s'",
                                      rtpi_tok_show(&ax, show, sizeof show));
            if ((st = num(c, what, "rotate", "angle", &v[0], NULL)) != RTP_OK)
                return st;
            k = ax.s[0] - 'x';
            i = (k + 1) % 3;
            j = (k + 2) % 3;
            rad = v[0] * (3.14159265358979323846 / 180.0);
            cs = cos(rad);
            sn = sin(rad);
            /* Right-handed rotation about axis k: i -> j. */
            a[4 * i + i] = cs;
            a[4 * i + j] = -sn;
            a[4 * j + i] = sn;
            a[4 * j + j] = cs;
        } else {
            return RTP_OK;
        }
        rtpi_xform_mul(m, a, m);
        *any = 1;
    }
}

static int has_ext(const rtpi_tok *t, const char *ext)
{
    size_t n = strlen(ext), i;
    if (t->n <= n)
        return 0;
    for (i = 0; i < n; i++) {
        char ch = t->s[t->n - n + i];
        if (ch >= 'A' && ch <= 'Z')
            ch = (char)(ch - 'A' + 'a');
        if (ch != ext[i])
            return 0;
    }
    return 1;
}

/* include FILE.obj [transforms] | include FILE.nff, and
   bezier FILE.bpt DIV [transforms]. */
static rtp_status read_include(nff *c, const rtpi_tok *kw, int bezier)
{
    const char *what = bezier ? "bezier" : "include";
    rtpi_tok t, dt;
    char *path = NULL, *text = NULL, show[96];
    size_t size = 0;
    double m[12], nm[9];
    int any = 0, is_obj = 0;
    long div = 0;
    rtp_error inner;
    rtp_status st;
    rtp_allocator *a = &c->s->alloc;
    if (c->depth >= RTPI_INCLUDE_MAX)
        return rtpi_lex_error(&c->lx, kw,
                              "%s nested deeper than %d files (does a file include itself?)",
                              what, RTPI_INCLUDE_MAX);
    if ((st = read_path(c, what, &t, &path)) != RTP_OK)
        return st;
    rtpi_tok_show_path(&t, show, sizeof show);
    if (bezier) {
        if ((st = need(c, &dt, what, "subdivisions")) != RTP_OK)
            goto done;
        if (rtpi_tok_int(&dt, &div) != 0 || div < 1 || div > BEZIER_DIV_MAX) {
            char ds[48];
            st = rtpi_lex_error(&c->lx, &dt,
                                "expected bezier subdivisions from 1 to %d, got '%s'",
                                BEZIER_DIV_MAX, rtpi_tok_show(&dt, ds, sizeof ds));
            goto done;
        }
    } else if (has_ext(&t, ".obj")) {
        is_obj = 1;
    } else if (!has_ext(&t, ".nff")) {
        st = rtpi_lex_error(&c->lx, &t,
                            "include '%s': unknown file type (expected .obj or .nff)",
                            show);
        goto done;
    }
    if ((st = read_transforms(c, what, m, &any)) != RTP_OK)
        goto done;
    if (any && !bezier && !is_obj) {
        st = rtpi_lex_error(&c->lx, &t,
                            "include '%s': transforms apply to .obj includes only",
                            show);
        goto done;
    }
    if (any && rtpi_xform_normal_matrix(m, nm) != 0) {
        st = rtpi_lex_error(&c->lx, &t, "%s '%s': the transform is singular",
                            what, show);
        goto done;
    }
    memset(&inner, 0, sizeof inner);
    st = rtpi_read_file(a, path, &text, &size, &inner);
    if (st != RTP_OK) {
        st = rtpi_lex_wrap(&c->lx, &t, st, &inner, bezier ? "cannot read bezier file"
                                                          : "cannot read include file");
        goto done;
    }
    if (c->st)
        c->st->includes++;
    if (rtpi_scene_add_file(c->s, path) != 0) {
        st = nomem(c, &t);
        goto done;
    }
    if (bezier) {
        st = rtpi_read_bpt(c->s, text, size, path, (int)div, any ? m : NULL,
                           c->mat, c->err);
    } else if (is_obj) {
        st = rtpi_read_obj_reg(c->s, text, size, path, any ? m : NULL, c->mat,
                               NULL, c->mtl, c->err);
    } else {
        nff child;
        memset(&child, 0, sizeof child);
        child.s = c->s;
        child.err = c->err;
        child.depth = c->depth + 1;
        child.st = c->st;
        child.mtl = c->mtl;
        /* An included NFF file reads as its text would in place of the
           include line: it starts with the includer's current material
           and last f or l, and leaves its own current after it.  (The
           includer's current material was restored after it while name
           and off named the child's last f or l, so that after an
           include `name` named one material and `ka`, `texture` and the
           objects went to another.) */
        child.mat = c->mat;
        child.named_kind = c->named_kind;
        child.named_index = c->named_index;
        rtpi_lex_init(&child.lx, text, size, path, c->err);
        st = parse(&child);
        c->mat = child.mat;
        c->named_kind = child.named_kind;
        c->named_index = child.named_index;
        rtpi_free(a, child.pts);
        rtpi_free(a, child.tri);
    }
done:
    rtpi_free(a, text);
    rtpi_free(a, path);
    return st;
}

/* ---------------------------------------------------------------- main */

static rtp_status parse(nff *c)
{
    rtpi_tok t;
    rtp_status st = RTP_OK;
    char show[48], pshow[48];
    /* the statement before, for a message (its keyword's start and
       length and its line; NULL at the start: scalars, not the token,
       which copied a statement cost mount_s6's parse 0.2%) */
    const char *prev = NULL;
    size_t prev_n = 0;
    int prev_line = 0;
    t.s = NULL;
    t.n = 0;
    t.line = 0;
    while (st == RTP_OK && (prev = t.s, prev_n = t.n, prev_line = t.line,
                            rtpi_lex_next(&c->lx, &t))) {
        switch (t.n == 0 ? 0 : t.s[0]) {
        case 'v':
            if (t.n == 1) {
                st = read_view(c, &t);
                continue;
            }
            break;
        case 'b':
            if (t.n == 1) {
                st = read_rgb(c, "b (background)", "background", c->s->background);
                continue;
            }
            if (rtpi_tok_is(&t, "bump")) {
                st = read_bump(c, &t);
                continue;
            }
            if (rtpi_tok_is(&t, "bezier")) {
                st = read_include(c, &t, 1);
                continue;
            }
            break;
        case 'l':
            if (t.n == 1) {
                st = read_light(c);
                continue;
            }
            break;
        case 'f':
            if (t.n == 1) {
                st = read_material(c);
                continue;
            }
            break;
        case 'c':
            if (t.n == 1) {
                st = read_cone(c);
                continue;
            }
            if (rtpi_tok_is(&t, "checker")) {
                st = read_checker(c, &t);
                continue;
            }
            break;
        case 's':
            if (t.n == 1) {
                st = read_sphere(c);
                continue;
            }
            break;
        case 'p':
            if (t.n == 1 || rtpi_tok_is(&t, "pp")) {
                st = read_polygon(c, &t, t.n == 2);
                continue;
            }
            break;
        case 'o':
            if (rtpi_tok_is(&t, "off")) {
                if (c->named_kind != 'l')
                    return rtpi_lex_error(&c->lx, &t, "off must follow an l (light) line");
                c->s->lights[c->named_index].on = 0;
                continue;
            }
            break;
        case 'n':
            if (rtpi_tok_is(&t, "name")) {
                st = read_name(c, &t);
                continue;
            }
            break;
        case 'a':
            if (rtpi_tok_is(&t, "ambient")) {
                st = read_rgb(c, "ambient", "ambient", c->s->ambient);
                continue;
            }
            break;
        case 't':
            if (rtpi_tok_is(&t, "texture")) {
                st = read_texture(c, &t);
                continue;
            }
            break;
        case 'k':
            if (rtpi_tok_is(&t, "ka")) {
                st = read_ka(c, &t);
                continue;
            }
            break;
        case 'i':
            if (rtpi_tok_is(&t, "include")) {
                st = read_include(c, &t, 0);
                continue;
            }
            break;
        default:
            break;
        }
        /* (a number where a statement should begin is one too many for
           the statement before: `s 0 0 0 1 2` said "unknown keyword '2'") */
        if (rtpi_tok_numlike(&t) && prev) {
            rtpi_tok p = t;
            p.s = prev;
            p.n = prev_n;
            return rtpi_lex_error(&c->lx, &t,
                                  "expected a keyword, got '%s' (more numbers than the "
                                  "'%s' at line %d takes)",
                                  rtpi_tok_show(&t, show, sizeof show),
                                  rtpi_tok_show(&p, pshow, sizeof pshow), prev_line);
        }
        if (rtpi_tok_numlike(&t))
            return rtpi_lex_error(&c->lx, &t, "expected a keyword, got '%s'",
                                  rtpi_tok_show(&t, show, sizeof show));
        return rtpi_lex_error(&c->lx, &t, "unknown keyword '%s'",
                              rtpi_tok_show(&t, show, sizeof show));
    }
    return st;
}

rtp_status rtpi_read_nff_stats(rtp_scene *s, const char *text, size_t size,
                               const char *name, int include_depth,
                               rtpi_nff_stats *stats, rtp_error *err)
{
    nff c;
    rtp_status st;
    size_t t0 = s->ntris, s0 = s->nspheres, c0 = s->ncones, i;
    rtpi_mtl_reg mtl;
    memset(&c, 0, sizeof c);
    memset(&mtl, 0, sizeof mtl);
    c.mtl = &mtl;
    if (stats)
        memset(stats, 0, sizeof *stats);
    c.s = s;
    c.err = err;
    c.depth = include_depth < 0 ? 0 : include_depth;
    c.mat = RTPI_MAT_PENDING;
    c.st = stats;
    rtpi_lex_init(&c.lx, text, size, name ? name : "<memory>", err);
    st = parse(&c);
    rtpi_free(&s->alloc, c.pts);
    rtpi_free(&s->alloc, c.tri);
    rtpi_mtl_reg_free(&mtl, &s->alloc);
    if (st != RTP_OK)
        return st;
    /* Objects before the first f line: a default material, appended last
       so that material N is still the N-th f line. */
    {
        int pending = 0;
        long m;
        rtpi_material def;
        for (i = t0; i < s->ntris && !pending; i++)
            pending = s->tris[i].mat == RTPI_MAT_PENDING;
        for (i = s0; i < s->nspheres && !pending; i++)
            pending = s->spheres[i].mat == RTPI_MAT_PENDING;
        for (i = c0; i < s->ncones && !pending; i++)
            pending = s->cones[i].mat == RTPI_MAT_PENDING;
        if (!pending)
            return RTP_OK;
        rtpi_material_default(&def);
        m = rtpi_scene_add_material(s, &def);
        if (m < 0)
            return rtpi_error(err, RTP_ERR_NOMEM, c.lx.name, 0, 0, "out of memory");
        for (i = t0; i < s->ntris; i++)
            if (s->tris[i].mat == RTPI_MAT_PENDING)
                s->tris[i].mat = (uint32_t)m;
        for (i = s0; i < s->nspheres; i++)
            if (s->spheres[i].mat == RTPI_MAT_PENDING)
                s->spheres[i].mat = (uint32_t)m;
        for (i = c0; i < s->ncones; i++)
            if (s->cones[i].mat == RTPI_MAT_PENDING)
                s->cones[i].mat = (uint32_t)m;
    }
    return RTP_OK;
}

rtp_status rtpi_read_nff(rtp_scene *s, const char *text, size_t size,
                         const char *name, int include_depth, rtp_error *err)
{
    return rtpi_read_nff_stats(s, text, size, name, include_depth, NULL, err);
}
