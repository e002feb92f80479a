/* shade.c — the one shading routine.  It evaluates the paper's equation
 *   I = kd c_obj sum_{i in Omega} (n.l_i) c_li + ks sum_{i in Omega} (r_i.v)^n c_li
 *       + ks I_r + kt I_t + I_a
 * over a recorded ray tree of compact nodes.  It never casts a ray: the
 * tree holds where each ray hit and which lights each hit saw; normals,
 * texture coordinates and view vectors are derived from the hit positions
 * and the scene's geometry; the scene holds every optical parameter.  Conventions (README.md, "Shading"): c_li is the light colour
 * times the scene's light scale; I_a = ambient * kd * c_obj. */
#include "internal.h"

#include <float.h>

static double fract_floor(double x) { return x - floor(x); }

static void image_lookup(const rtp_image *img, double u, double v, int clamp_v,
                         double rgb[3])
{
    /* Bilinear, wrapping: uv (0,0) is the image's bottom-left corner as
       OBJ's vt convention has it.  With clamp_v, v is not wrapped but
       held to the image's edge rows: a sphere's latitude and a cone's
       height run from one edge to the other, and wrapped, the half
       texel next to a pole or rim blended the top row with the bottom
       (a sphere's north pole, v = 1, took the bottom row's colour half
       and half with its own). */
    double x = fract_floor(u) * img->width - 0.5;
    double y = (1.0 - (clamp_v ? v : fract_floor(v))) * img->height - 0.5;
    int x0, y0;
    double fx, fy;
    int c, dx, dy;
    if (clamp_v) /* (within two texels of the rows: floor stays in int) */
        y = y < -2.0 ? -2.0 : y > img->height + 1.0 ? img->height + 1.0 : y;
    x0 = (int)floor(x);
    y0 = (int)floor(y);
    fx = x - x0;
    fy = y - y0;
    for (c = 0; c < 3; c++)
        rgb[c] = 0.0;
    for (dy = 0; dy < 2; dy++) {
        for (dx = 0; dx < 2; dx++) {
            int xi = ((x0 + dx) % img->width + img->width) % img->width;
            int yi = clamp_v ? (y0 + dy < 0 ? 0 : y0 + dy >= img->height ? img->height - 1 : y0 + dy)
                             : ((y0 + dy) % img->height + img->height) % img->height;
            double w = (dx ? fx : 1.0 - fx) * (dy ? fy : 1.0 - fy);
            const float *px = img->pixels + 3 * ((size_t)yi * img->width + xi);
            for (c = 0; c < 3; c++)
                rgb[c] += w * px[c];
        }
    }
}

/* Whether prim's v is clamped, not wrapped (image_lookup): a sphere's
   and a cone's, whose v spans the image once from edge to edge. */
static int v_clamped(const rtp_scene *s, uint32_t prim)
{
    return (size_t)prim >= s->ntris;
}

void rtpi_texture_factor(const rtp_scene *s, const rtpi_material *m, uint32_t prim,
                         rtpi_v3 p, const double uv[2], double f[3])
{
    int c;
    if (m->tex == RTPI_TEX_CHECKER && m->tex_scale > 0.0f) {
        double inv = 1.0 / m->tex_scale;
        /* Planes often lie exactly on a cell boundary (a table top at
           z = 0): a bias of 1e-4 cell puts hits within float noise of a
           boundary consistently on one side instead of speckling.  fmod
           keeps the parity right for cells beyond long's range. */
        const double bias = 1e-4;
        double cell = floor(p.x * inv + bias) + floor(p.y * inv + bias) +
                      floor(p.z * inv + bias);
        double sel = fmod(fabs(cell), 2.0) >= 1.0 ? 0.0 : 1.0;
        for (c = 0; c < 3; c++)
            f[c] = sel; /* 1: colour, 0: color2 */
        return;
    }
    if (m->tex == RTPI_TEX_IMAGE && m->tex_image < s->ntexs && s->texs[m->tex_image].image) {
        image_lookup(s->texs[m->tex_image].image, uv[0], uv[1], v_clamped(s, prim), f);
        return;
    }
    for (c = 0; c < 3; c++)
        f[c] = 1.0;
}

void rtpi_surface_from_point(const rtp_scene *s, uint32_t prim, const float pf[3],
                             int want_uv, rtpi_surface *out)
{
    const rtpi_v3 p = v3_from_f(pf);
    rtpi_ray ray;
    rtpi_hit hit;
    hit.t = 0.0;
    hit.prim = prim;
    hit.u = hit.v = 0.0;
    if (prim < s->ntris) {
        const rtpi_tri *t = &s->tris[prim];
        if (t->n[0] != RTPI_NONE || (want_uv && t->t[0] != RTPI_NONE)) {
            /* Barycentrics of p, only where normals or uvs need them. */
            rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)t->v[0]);
            rtpi_v3 e1 = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[1]), p0);
            rtpi_v3 e2 = v3_sub(v3_from_f(s->pos + 3 * (size_t)t->v[2]), p0);
            rtpi_v3 w = v3_sub(p, p0);
            double d11 = v3_dot(e1, e1), d12 = v3_dot(e1, e2), d22 = v3_dot(e2, e2);
            double w1 = v3_dot(w, e1), w2 = v3_dot(w, e2);
            double den = d11 * d22 - d12 * d12;
            if (den > 0.0) {
                hit.u = (d22 * w1 - d12 * w2) / den;
                hit.v = (d11 * w2 - d12 * w1) / den;
            }
        }
    }
    ray.o = p;
    ray.d = v3(0.0, 0.0, 1.0);
    ray.tmin = 0.0;
    ray.tmax = 0.0;
    rtpi_surface_at_ex(s, &ray, &hit, want_uv, out);
}

/* ------------------------------------------------------------ bumps */

/* A smooth hash of an integer lattice point to [-1, 1]. */
static double lattice(long x, long y, long z)
{
    unsigned long h = (unsigned long)x * 73856093ul ^ (unsigned long)y * 19349663ul ^
                      (unsigned long)z * 83492791ul;
    h ^= h >> 13;
    h *= 0x5bd1e995ul;
    h ^= h >> 15;
    return (double)(h & 0xffffu) / 32767.5 - 1.0;
}

static double smooth(double t) { return t * t * (3.0 - 2.0 * t); }

/* floor(x) (f) as a lattice coordinate: wrapped into (-2^30, 2^30), so
   that it and the next one fit a long (32 bits at least) however far out
   the point or small the scale (a float beyond a long's range converted
   to it is undefined: a file with a noise bump of scale 1e-20 found it);
   not finite, 0.  The noise repeats every 2^30 cells. */
static long lattice_coord(double f)
{
    if (!(fabs(f) <= DBL_MAX))
        return 0;
    return (long)fmod(f, 1073741824.0); /* (exact: f is an integer) */
}

/* Value noise: trilinear over the lattice with smoothstep weights. */
static double noise3(double x, double y, double z)
{
    double fx = floor(x), fy = floor(y), fz = floor(z), v = 0.0;
    double tx = smooth(x - fx), ty = smooth(y - fy), tz = smooth(z - fz);
    long ix = lattice_coord(fx), iy = lattice_coord(fy), iz = lattice_coord(fz);
    int c;
    for (c = 0; c < 8; c++) {
        double w = ((c & 1) ? tx : 1.0 - tx) * ((c & 2) ? ty : 1.0 - ty) * ((c & 4) ? tz : 1.0 - tz);
        v += w * lattice(ix + (c & 1), iy + ((c >> 1) & 1), iz + ((c >> 2) & 1));
    }
    return v;
}

/* Gradient of a procedural solid height field at p (cell/period: scale). */
static rtpi_v3 solid_gradient(const rtpi_material *m, rtpi_v3 p)
{
    double k = 1.0 / (m->bump_scale > 0.0f ? m->bump_scale : 1.0f);
    if (m->bump == RTPI_BUMP_WAVES) {
        /* three plane waves across fixed directions; analytic gradient */
        static const double dir[3][3] = {{0.8, 0.6, 0.0}, {0.0, 0.6, 0.8}, {0.6, 0.0, -0.8}};
        rtpi_v3 g = v3(0.0, 0.0, 0.0);
        int i;
        for (i = 0; i < 3; i++) {
            rtpi_v3 a = v3(dir[i][0], dir[i][1], dir[i][2]);
            double ph = 2.0 * 3.14159265358979323846 * k * v3_dot(a, p) + i;
            g = v3_madd(g, a, 2.0 * 3.14159265358979323846 * k * cos(ph) / 3.0);
        }
        return g;
    } else {
        /* value noise; central differences a thousandth of a cell apart,
           far below the cell and far above double rounding of p * k */
        double h = 1e-3, x = p.x * k, y = p.y * k, z = p.z * k, inv = k / (2.0 * h);
        return v3((noise3(x + h, y, z) - noise3(x - h, y, z)) * inv,
                  (noise3(x, y + h, z) - noise3(x, y - h, z)) * inv,
                  (noise3(x, y, z + h) - noise3(x, y, z - h)) * inv);
    }
}

static double height_at(const rtp_image *img, double u, double v, int clamp_v)
{
    double rgb[3];
    image_lookup(img, u, v, clamp_v, rgb);
    return (rgb[0] + rgb[1] + rgb[2]) / 3.0;
}

rtpi_v3 rtpi_bump_normal(const rtp_scene *s, const rtpi_material *m, uint32_t prim,
                         rtpi_v3 p, const double uv[2], rtpi_v3 n)
{
    if (m->bump == RTPI_BUMP_NONE || m->bump_strength == 0.0f)
        return n;
    if (m->bump == RTPI_BUMP_IMAGE) {
        /* Blinn 1978: n' = n + (h_u (n x P_v) - h_v (n x P_u)) / |P_u x P_v|,
           with P_u, P_v the surface's derivatives by uv (triangles with
           uvs, spheres, cones) and the height differences one texel
           apart. */
        const rtp_image *img;
        rtpi_v3 pu, pv, c, d;
        double hu, hv, a, eu, ev;
        int cv;
        if (m->bump_image >= s->ntexs || !s->texs[m->bump_image].image ||
            !rtpi_uv_tangents(s, prim, p, &pu, &pv))
            return n;
        img = s->texs[m->bump_image].image;
        c = v3_cross(pu, pv);
        a = v3_len(c);
        if (!(a > 0.0))
            return n;
        eu = 1.0 / img->width;
        ev = 1.0 / img->height;
        cv = v_clamped(s, prim);
        hu = (height_at(img, uv[0] + eu, uv[1], cv) - height_at(img, uv[0] - eu, uv[1], cv)) /
             (2.0 * eu);
        hv = (height_at(img, uv[0], uv[1] + ev, cv) - height_at(img, uv[0], uv[1] - ev, cv)) /
             (2.0 * ev);
        /* Blinn's d raises the surface along P_u x P_v.  Heights rise
           along a triangle's front (its winding's normal, which its
           shading normal shares a side with) whichever way its uvs run:
           where they are mirrored (P_u x P_v against the front, as on
           half of a mesh with mirrored uvs) the heights' gradient is
           taken the other way round, or that half showed every bump as
           a dent (a ramp on two mirror-image quads lit from between them
           gave 0.6 on one and 0.8 on the other).  A sphere's and a cone's
           P_u x P_v point out, the front. */
        if (prim < s->ntris && v3_dot(c, rtpi_tri_normal(s, &s->tris[prim])) < 0.0) {
            hu = -hu;
            hv = -hv;
        }
        d = v3_sub(v3_mul(v3_cross(n, pv), hu), v3_mul(v3_cross(n, pu), hv));
        {
            /* strength x scale as a float product (what every image was
               made with), but in double where that overflows (keys take
               each up to 3.4e38: 1e20 x 1e20 made the normal NaN); and
               where n + k d would square past the double range, the same
               direction from n / k + d */
            float sk = m->bump_strength * m->bump_scale;
            double k = (isinf(sk) ? (double)m->bump_strength * (double)m->bump_scale
                                  : (double)sk) /
                       a;
            rtpi_v3 r = v3_madd(n, d, k);
            if (!(v3_dot(r, r) < 1e300) && k != 0.0)
                r = v3_madd(v3_mul(n, 1.0 / k), d, 1.0);
            return v3_norm(r);
        }
    } else {
        /* a solid height field: tilt n against the surface part of its
           gradient */
        rtpi_v3 g = solid_gradient(m, p);
        g = v3_madd(g, n, -v3_dot(g, n));
        return v3_norm(v3_madd(n, g, -(double)m->bump_strength));
    }
}

static int seen(const rtpi_cnode *nd, const uint32_t *ext, size_t i)
{
    if (!ext)
        return (int)((nd->vis >> i) & 1u);
    return (int)((ext[i >> 5] >> (i & 31)) & 1u);
}

/* The terms of one light at a hit: d = n.l and s = (r.v)^shine where the
   hit sees the light and faces it.  n and v come rounded to float (as the
   evaluation cache keeps them), so recomputing one light's terms from the
   cache repeats this arithmetic exactly. */
/* n.l and the highlight's base r.v at a hit facing the light; 0 where
   the light is behind the surface. */
static inline rtpi_v3 light_pos(const rtpi_light *L)
{
    return v3(L->pos[0], L->pos[1], L->pos[2]);
}

static inline int light_geometry(const float *nv, rtpi_v3 p, rtpi_v3 lp, double *ndl,
                                 double *rv)
{
    rtpi_v3 n = v3(nv[0], nv[1], nv[2]), v = v3(nv[3], nv[4], nv[5]), l;
    l = v3_norm(v3_sub(lp, p));
    *ndl = v3_dot(n, l);
    if (*ndl <= 0.0)
        return 0;
    /* r_i: l mirrored about n; the highlight is (r_i.v)^shine. */
    *rv = v3_dot(v3_sub(v3_mul(n, 2.0 * *ndl), l), v);
    return 1;
}

static inline void light_term(const float *nv, rtpi_v3 p, rtpi_v3 lp, int visible,
                              const rtpi_material *m, float *out)
{
    double ndl, rv;
    out[0] = out[1] = 0.0f;
    if (!visible || !light_geometry(nv, p, lp, &ndl, &rv))
        return;
    out[0] = (float)ndl;
    /* no highlight to weigh where ks is 0 (an edit making it non-zero
       recomputes these terms) */
    out[1] = rv > 0.0 && m->ks > 0.0f ? (float)pow(rv, m->shine) : 0.0f;
}

/* c_obj at a node: its texture factor t[0..2] and the material's
   colours now (coeffs_node and rtpi_light_redo). */
static inline void obj_colour(const rtpi_material *m, const float *t, double cobj[3])
{
    int k;
    if (m->tex == RTPI_TEX_CHECKER)
        for (k = 0; k < 3; k++)
            cobj[k] = t[k] * (double)m->color[k] + (1.0 - t[k]) * (double)m->color2[k];
    else
        for (k = 0; k < 3; k++)
            cobj[k] = t[k] * (double)m->color[k];
}

/* Step 1 for node idx seen from `from`, the node alone; its material. */
static inline const rtpi_material *node_terms(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                              size_t idx, const uint32_t *vis_ext, rtpi_v3 from,
                                              float *terms, float *nv_out)
{
    const rtp_scene *s = c->s;
    const rtpi_cnode *nd = &nodes[idx];
    const uint32_t *ext = vis_ext ? vis_ext + idx * c->vis_words : NULL;
    size_t nl = s->nlights, i;
    float *t = terms + idx * RTPI_TERMS(nl), nvl[6], *nv = nv_out ? nv_out + 6 * idx : nvl;
    const rtpi_material *m;
    rtpi_surface sf;
    rtpi_v3 p = v3(nd->p[0], nd->p[1], nd->p[2]), n, v;
    double tex[3];

    m = &s->mats[rtpi_prim_material(s, nd->prim)];
    if (m->tex == RTPI_TEX_IMAGE || m->bump == RTPI_BUMP_IMAGE) {
        rtpi_surface_from_point(s, nd->prim, nd->p, 1, &sf);
    } else {
        /* no uv wanted: the normals by rtpi_surface_normals' own
           arithmetic for spheres, flat triangles and cones (the same
           expressions), not through a ray and rtpi_surface_at_ex (mount,
           whose glass balls hold most nodes: 4% of a first evaluation).
           At p + 0, the point rtpi_surface_at_ex takes (o + 0 d: a -0
           coordinate becomes +0), so that the normals are its own to the
           sign of a zero. */
        rtpi_v3 ng;
        (void)rtpi_surface_normals(s, nd->prim, v3(p.x + 0.0, p.y + 0.0, p.z + 0.0), &ng,
                                   &sf.ns);
        sf.uv[0] = sf.uv[1] = 0.0;
    }
    /* (the calls only where the material has a bump or texture: each
       was a call and a test a node, 9% of mount's first evaluation,
       whose materials have neither) */
    n = m->bump == RTPI_BUMP_NONE ? sf.ns : rtpi_bump_normal(s, m, nd->prim, p, sf.uv, sf.ns);
    if ((nd->link & RTPI_L_BACK) && rtpi_two_sided(s, c->one_sided, nd->prim, m))
        n = v3_mul(n, -1.0);
    v = v3_norm(v3_sub(from, p));
    nv[0] = (float)n.x;
    nv[1] = (float)n.y;
    nv[2] = (float)n.z;
    nv[3] = (float)v.x;
    nv[4] = (float)v.y;
    nv[5] = (float)v.z;
    if (m->tex == RTPI_TEX_NONE)
        tex[0] = tex[1] = tex[2] = 1.0; /* (rtpi_texture_factor's) */
    else
        rtpi_texture_factor(s, m, nd->prim, p, sf.uv, tex);
    t[0] = (float)tex[0];
    t[1] = (float)tex[1];
    t[2] = (float)tex[2];
    for (i = 0; i < nl; i++)
        light_term(nv, p, light_pos(&s->lights[i]), seen(nd, ext, i), m, t + 3 + 2 * i);
    return m;
}

/* rtpi_combine's sums where one came out NaN: a colour of 0 adds nothing
   there (RTPI_TERM_SUM). */
static void combine_zero(const rtp_scene *s, const double *cl, const float *coeffs, float rgb[3])
{
    size_t i, nl = s->nlights;
    int k;
    for (k = 0; k < 3; k++) {
        double a = RTPI_TERM_SUM(RTPI_TERM_SUM(0.0, coeffs[k], (double)s->background[k]),
                                 coeffs[3 + k], (double)s->ambient[k]);
        for (i = 0; i < nl; i++)
            a = RTPI_TERM_SUM(a, coeffs[6 + 3 * i + k], cl[3 * i + k]);
        rgb[k] = (float)a;
    }
}

/* The sums of rtpi_combine, each channel in the same order as ever
   (background, ambient, the lights ascending), the three side by side;
   light `skip` left out (none where it is nlights). */
static inline void combine_sums(const rtp_scene *s, const double *cl, const float *coeffs,
                                size_t skip, double v[3])
{
    size_t i, nl = s->nlights;
    const float *c = coeffs + 6;
    double v0 = coeffs[0] * (double)s->background[0] + coeffs[3] * (double)s->ambient[0];
    double v1 = coeffs[1] * (double)s->background[1] + coeffs[4] * (double)s->ambient[1];
    double v2 = coeffs[2] * (double)s->background[2] + coeffs[5] * (double)s->ambient[2];
    for (i = 0; i < nl; i++, c += 3, cl += 3) {
        if (i == skip)
            continue;
        v0 += c[0] * cl[0];
        v1 += c[1] * cl[1];
        v2 += c[2] * cl[2];
    }
    v[0] = v0;
    v[1] = v1;
    v[2] = v2;
}

/* (inline in rtpi_light_redo: its call, with the spills around it, was
   a fifth of the combine's instructions: teapot's moves 151 k of them) */
static RTPI_FORCE_INLINE void combine_into(const rtp_scene *s, const double *cl,
                                           const float *coeffs, float rgb[3])
{
    double v[3];
    combine_sums(s, cl, coeffs, s->nlights, v);
    /* A colour of 0 adds nothing, whatever its coefficient: a light
       turned off keeps its coefficients (for turning it on again), and
       where a huge kt or ks took one beyond the float range, inf x 0 made
       the pixel NaN.  Only a NaN sum can hold such a product (else the
       rule gives the same sums, but for the sign of a zero), so only then
       are the sums made again with it (tested as one: their sum is NaN
       where one is, or where infinities of both signs meet, which the
       rule leaves as they are). */
    if (!(v[0] + v[1] + v[2] == v[0] + v[1] + v[2])) {
        combine_zero(s, cl, coeffs, rgb); /* (a tail call: no frame here) */
        return;
    }
    rgb[0] = (float)v[0];
    rgb[1] = (float)v[1];
    rgb[2] = (float)v[2];
}

void rtpi_combine(const rtp_scene *s, const double *cl, const float *coeffs, float rgb[3])
{
    combine_into(s, cl, coeffs, rgb);
}

/* rtpi_light_redo's body; with_rest: rest is not NULL (a constant at
   each call: the loop compiled twice, the one without the kept rest
   combining inline, which in the one with it had cost balls' and rings'
   moves 0.1-0.2%) */
static RTPI_FORCE_INLINE unsigned long long
light_redo(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, const uint64_t *start, size_t k0,
           size_t k1, const uint32_t *vis_ext, const float *nv, const double *w, size_t light,
           float *terms, float *coeffs, const double *cl, float *samples, int *bad,
           unsigned char *mark, double *rest, unsigned char *rest_ok, int with_rest)
{
    const rtp_scene *s = c->s;
    const rtpi_v3 lp = light_pos(&s->lights[light]);
    const size_t nt = RTPI_TERMS(s->nlights), nc = RTPI_COEFFS(s->nlights), wi = light >> 5;
    const size_t vw = c->vis_words;
    const uint32_t bit = 1u << (light & 31);
    unsigned long long combined = 0;
    int nonfinite = 0;
    size_t k, j;
    for (k = k0; k < k1; k++) {
        size_t a = (size_t)start[k], b = (size_t)start[k + 1];
        float *co = coeffs + k * nc;
        double a0 = 0.0, a1 = 0.0, a2 = 0.0;
        if (a == b)
            continue; /* the background: no light in it, nothing changes */
        for (j = a; j < b; j++) {
            const rtpi_cnode *nd = &nodes[j];
            const rtpi_material *m;
            float *t = terms + j * nt, *tl = t + 3 + 2 * light;
            int visible = vis_ext ? (vis_ext[j * vw + wi] & bit) != 0
                                  : (int)((nd->vis >> light) & 1u);
            double d, sp, kd, ks, cobj[3];
            if (!visible) {
                /* light_term's terms where the light is not seen, and
                   nothing to sum (most nodes of a scene in shadow: no
                   material to look up) */
                tl[0] = tl[1] = 0.0f;
                continue;
            }
            m = &s->mats[rtpi_prim_material(s, nd->prim)];
            /* (the light's position taken once: light_term inline) */
            light_term(nv + 6 * j, v3(nd->p[0], nd->p[1], nd->p[2]), lp, visible, m, tl);
            /* coeffs_node's sum for this light, node by node in its order
               (depth first, reflected subtree first: the order they are
               stored in), leaving out the nodes it does not reach */
            d = tl[0];
            if (w[j] == 0.0 || d == 0.0)
                continue;
            sp = tl[1];
            kd = w[j] * m->kd;
            ks = w[j] * m->ks;
            obj_colour(m, t, cobj);
            a0 += kd * cobj[0] * d + ks * sp;
            a1 += kd * cobj[1] * d + ks * sp;
            a2 += kd * cobj[2] * d + ks * sp;
        }
        {
            /* a coefficient the same to the bit (a node in shadow before
               and after, or out of the light's reach) combines to the
               same colour: that sample holds */
            const float f[3] = {(float)a0, (float)a1, (float)a2};
            float *cf = co + 6 + 3 * light;
            /* their magnitudes within RTPI_COEFF_MAX, as in
               rtpi_sample_coeffs (a NaN fails the test): one test, not
               three classifications (a tenth of a move's sums on
               tetra) */
            nonfinite |= !(fabs(a0) + fabs(a1) + fabs(a2) <= RTPI_COEFF_MAX);
            if (samples && memcmp(cf, f, sizeof f) == 0)
                continue;
            memcpy(cf, f, sizeof f);
        }
        if (samples) { /* the other samples' colours hold */
            if (with_rest) {
                /* the rest of the sum, then this light's term: as
                   rtpi_combine where the light is the last, else about
                   a float ulp from it; it serves where the sum is finite */
                double *r = rest + 3 * k, v0, v1, v2;
                const double *lc = cl + 3 * light;
                const float *f = co + 6 + 3 * light;
                if (!rest_ok[k]) { /* (made the first time the sample changes) */
                    rtpi_combine_rest(s, cl, co, light, r);
                    rest_ok[k] = 1;
                }
                v0 = r[0] + f[0] * lc[0];
                v1 = r[1] + f[1] * lc[1];
                v2 = r[2] + f[2] * lc[2];
                if (fabs(v0) + fabs(v1) + fabs(v2) <= DBL_MAX) {
                    float *o = samples + 3 * k;
                    o[0] = (float)v0;
                    o[1] = (float)v1;
                    o[2] = (float)v2;
                } else {
                    rtpi_combine(s, cl, co, samples + 3 * k);
                }
            } else {
                combine_into(s, cl, co, samples + 3 * k);
            }
            if (mark)
                mark[k] = 1;
            combined++;
        }
    }
    *bad |= nonfinite;
    return combined;
}

unsigned long long rtpi_light_redo(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                   const uint64_t *start, size_t k0, size_t k1,
                                   const uint32_t *vis_ext, const float *nv, const double *w,
                                   size_t light, float *terms, float *coeffs, const double *cl,
                                   float *samples, int *bad, unsigned char *mark,
                                   double *rest, unsigned char *rest_ok)
{
    return rest ? light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                             samples, bad, mark, rest, rest_ok, 1)
                : light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                             samples, bad, mark, NULL, rest_ok, 0);
}

void rtpi_material_light_terms(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                               const uint32_t *vis_ext, const float *nv, uint32_t mat,
                               float *terms)
{
    const rtp_scene *s = c->s;
    size_t k, i, nl = s->nlights, nt = RTPI_TERMS(nl);
    const rtpi_material *m = &s->mats[mat];
    for (k = 0; k < n; k++) {
        const rtpi_cnode *nd = &nodes[k];
        const uint32_t *ext = vis_ext ? vis_ext + k * c->vis_words : NULL;
        rtpi_v3 p;
        if (rtpi_prim_material(s, nd->prim) != mat)
            continue;
        p = v3(nd->p[0], nd->p[1], nd->p[2]);
        for (i = 0; i < nl; i++)
            light_term(nv + 6 * k, p, light_pos(&s->lights[i]), seen(nd, ext, i), m,
                       terms + k * nt + 3 + 2 * i);
    }
}

void rtpi_material_highlights(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                              size_t node0, const uint32_t *vis_ext, const float *nv,
                              uint32_t mat, size_t *idx, double *lrv, size_t *count)
{
    const rtp_scene *s = c->s;
    size_t k, i, nl = s->nlights, nt = RTPI_TERMS(nl);
    const rtpi_material *m = &s->mats[mat];
    if (!(m->ks > 0.0f))
        return;
    for (k = 0; k < n; k++) {
        const rtpi_cnode *nd = &nodes[k];
        const uint32_t *ext = vis_ext ? vis_ext + k * c->vis_words : NULL;
        rtpi_v3 p;
        if (rtpi_prim_material(s, nd->prim) != mat)
            continue;
        p = v3(nd->p[0], nd->p[1], nd->p[2]);
        for (i = 0; i < nl; i++) {
            double ndl, rv;
            /* light_term's terms, up to the power */
            if (!seen(nd, ext, i) ||
                !light_geometry(nv + 6 * k, p, light_pos(&s->lights[i]), &ndl, &rv) ||
                !(rv > 0.0))
                continue;
            idx[*count] = (node0 + k) * nt + 4 + 2 * i;
            lrv[*count] = log2(rv);
            ++*count;
        }
    }
}

/* Step 2 for one node of material m reached with path weight w, the
   node alone: its terms t into acc's A and K_i (coeffs_node, eval_node). */
static inline void node_coeffs(const rtpi_material *m, const float *t, size_t nl, double w,
                               double *acc)
{
    double kd = w * m->kd, ks = w * m->ks, cobj[3], kc0, kc1, kc2;
    size_t i;
    obj_colour(m, t, cobj);
    /* kd c_obj once, the ambient's and each light's product (kd * cobj[k]
       * d is (kd * cobj[k]) * d: the same operations), the three
       channels side by side: gears_s4's first evaluation 444.8 -> 423.8 M,
       mount_s6's 364.0 -> 355.1) */
    kc0 = kd * cobj[0];
    kc1 = kd * cobj[1];
    kc2 = kd * cobj[2];
    acc[3] += kc0; /* ambient: kd c_obj */
    acc[4] += kc1;
    acc[5] += kc2;
    for (i = 0; i < nl; i++) {
        double d = t[3 + 2 * i], hs, *a = acc + 6 + 3 * i;
        if (d == 0.0)
            continue;
        hs = ks * t[4 + 2 * i];
        a[0] += kc0 * d + hs;
        a[1] += kc1 * d + hs;
        a[2] += kc2 * d + hs;
    }
}

/* The weights a node hands its subtrees: ks I_r + kt I_t; on total
   internal reflection the transmitted share rides on the reflected
   subtree. */
static inline void node_split(const rtpi_material *m, uint32_t link, double *wr, double *wt)
{
    *wr = m->ks;
    *wt = m->kt;
    if (link & RTPI_L_TIR) {
        *wr += *wt;
        *wt = 0.0;
    }
}

/* Step 2 for node idx reached with path weight w (accumulated in double):
   every coefficient into acc (G, A, K_i); rtpi_light_redo makes one
   light's K_i by the very same operations. */
static void coeffs_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                        const float *terms, double w, double *acc, double *wout)
{
    const rtp_scene *s = c->s;
    const rtpi_cnode *nd = &nodes[idx];
    size_t nl = s->nlights;
    const rtpi_material *m = &s->mats[rtpi_prim_material(s, nd->prim)];
    double wr, wt;
    int k;
    if (wout)
        wout[idx] = w;
    node_coeffs(m, terms + idx * RTPI_TERMS(nl), nl, w, acc);
    node_split(m, nd->link, &wr, &wt);
    if (wr > 0.0) {
        if (nd->link & RTPI_L_REFL)
            coeffs_node(c, nodes, idx + 1, terms, w * wr, acc, wout);
        else if (nd->link & RTPI_L_REFL_MISS)
            for (k = 0; k < 3; k++)
                acc[k] += w * wr;
    }
    if (wt > 0.0) {
        if (nd->link & RTPI_L_REFR)
            coeffs_node(c, nodes, idx + (nd->link >> RTPI_L_SHIFT), terms, w * wt, acc, wout);
        else if (nd->link & RTPI_L_REFR_MISS)
            for (k = 0; k < 3; k++)
                acc[k] += w * wt;
    }
}

/* Steps 1 and 2 in one descent: node idx's terms, and where step 2
   reaches it (reached; path weight w) its coefficients, in coeffs_node's
   order (the node, its reflected subtree or miss, its refracted one), so
   every sum is the same.  Every node is visited, so each one's weight is
   written (0 where step 2 does not reach it).  One descent, not two, a
   node's call, lookups and reloads once (mount_s6's first evaluation
   355.1 -> 350.3 M, tree_s11's 289.0 -> 283.9). */
static void eval_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                      const uint32_t *vis_ext, rtpi_v3 from, float *terms, float *nv_out,
                      double w, int reached, double *acc, double *wout)
{
    const rtpi_cnode *nd = &nodes[idx];
    const size_t nl = c->s->nlights;
    const rtpi_material *m = node_terms(c, nodes, idx, vis_ext, from, terms, nv_out);
    const rtpi_v3 p = v3(nd->p[0], nd->p[1], nd->p[2]);
    const uint32_t link = nd->link;
    double wr = 0.0, wt = 0.0;
    int k;
    if (wout)
        wout[idx] = reached ? w : 0.0;
    if (reached) {
        node_coeffs(m, terms + idx * RTPI_TERMS(nl), nl, w, acc);
        node_split(m, link, &wr, &wt);
    }
    /* (!(wr > 0.0): also NaN, as coeffs_node tests it) */
    if (link & RTPI_L_REFL)
        eval_node(c, nodes, idx + 1, vis_ext, p, terms, nv_out, w * wr, reached && wr > 0.0,
                  acc, wout);
    else if (reached && wr > 0.0 && (link & RTPI_L_REFL_MISS))
        for (k = 0; k < 3; k++)
            acc[k] += w * wr;
    if (link & RTPI_L_REFR)
        eval_node(c, nodes, idx + (link >> RTPI_L_SHIFT), vis_ext, p, terms, nv_out, w * wt,
                  reached && wt > 0.0, acc, wout);
    else if (reached && wt > 0.0 && (link & RTPI_L_REFR_MISS))
        for (k = 0; k < 3; k++)
            acc[k] += w * wt;
}

/* acc rounded into coeffs (m of them); 0 where their magnitudes sum past
   RTPI_COEFF_MAX or one is not finite. */
static inline int round_coeffs(const double *acc, size_t m, float *coeffs)
{
    double sum = 0.0;
    size_t i;
    /* (three at a time, m being 6 + 3 nlights, the sum in the same
       order: the loop's own steps were a third of its 27 instructions
       a light; mount_s6's first evaluation 367.6 -> 365.0 M) */
    for (i = 0; i < m; i += 3) {
        coeffs[i] = (float)acc[i];
        coeffs[i + 1] = (float)acc[i + 1];
        coeffs[i + 2] = (float)acc[i + 2];
        sum += fabsf(coeffs[i]);
        sum += fabsf(coeffs[i + 1]);
        sum += fabsf(coeffs[i + 2]);
    }
    /* (a coefficient not finite makes the sum so) */
    return sum <= RTPI_COEFF_MAX;
}

int rtpi_sample_coeffs(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                       const float *terms, double *acc, float *coeffs, double *w)
{
    size_t m = RTPI_COEFFS(c->s->nlights), i;
    for (i = 0; i < m; i++)
        acc[i] = 0.0;
    if (w)
        for (i = 0; i < n; i++)
            w[i] = 0.0; /* (nodes step 2 does not reach) */
    if (n == 0)
        acc[0] = acc[1] = acc[2] = 1.0; /* the eye ray saw the background */
    else
        coeffs_node(c, nodes, 0, terms, 1.0, acc, w);
    return round_coeffs(acc, m, coeffs);
}

int rtpi_sample_eval(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                     const uint32_t *vis_ext, rtpi_v3 eye, float *terms, float *nv, double *acc,
                     float *coeffs, double *w)
{
    size_t m = RTPI_COEFFS(c->s->nlights), i;
    for (i = 0; i < m; i++)
        acc[i] = 0.0;
    if (n == 0)
        acc[0] = acc[1] = acc[2] = 1.0; /* the eye ray saw the background */
    else
        eval_node(c, nodes, 0, vis_ext, eye, terms, nv, 1.0, 1, acc, w);
    return round_coeffs(acc, m, coeffs);
}

void rtpi_light_colors(const rtp_scene *s, double *cl)
{
    size_t i;
    int k;
    for (i = 0; i < s->nlights; i++)
        for (k = 0; k < 3; k++)
            cl[3 * i + k] = s->lights[i].on ? s->lights[i].color[k] * s->light_scale : 0.0;
}

void rtpi_combine_rest(const rtp_scene *s, const double *cl, const float *coeffs, size_t light,
                       double rest[3])
{
    combine_sums(s, cl, coeffs, light, rest);
}

static void diffuse_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                         const float *terms, uint32_t mat, const double *cv, double w,
                         double q[3])
{
    const rtp_scene *s = c->s;
    const rtpi_cnode *nd = &nodes[idx];
    size_t nl = s->nlights, i;
    const float *t = terms + idx * RTPI_TERMS(nl);
    uint32_t mi = rtpi_prim_material(s, nd->prim);
    const rtpi_material *m = &s->mats[mi];
    double wr, wt;
    int k;
    if (mi == mat)
        for (k = 0; k < 3; k++) {
            double l = cv[3 + k];
            for (i = 0; i < nl; i++)
                l += (double)t[3 + 2 * i] * cv[6 + 3 * i + k];
            q[k] += w * t[k] * l;
        }
    /* the path weights as coeffs_node has them */
    wr = m->ks;
    wt = m->kt;
    if (nd->link & RTPI_L_TIR) {
        wr += wt;
        wt = 0.0;
    }
    if (wr > 0.0 && (nd->link & RTPI_L_REFL))
        diffuse_node(c, nodes, idx + 1, terms, mat, cv, w * wr, q);
    if (wt > 0.0 && (nd->link & RTPI_L_REFR))
        diffuse_node(c, nodes, idx + (nd->link >> RTPI_L_SHIFT), terms, mat, cv, w * wt, q);
}

void rtpi_sample_diffuse(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                         const float *terms, uint32_t mat, const double *cv, double q[3])
{
    q[0] = q[1] = q[2] = 0.0;
    if (n > 0)
        diffuse_node(c, nodes, 0, terms, mat, cv, 1.0, q);
}

static void weights_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx, double w,
                         double *out)
{
    const rtp_scene *s = c->s;
    const rtpi_cnode *nd = &nodes[idx];
    const rtpi_material *m = &s->mats[rtpi_prim_material(s, nd->prim)];
    double wr = m->ks, wt = m->kt;
    out[idx] = w;
    /* coeffs_node's descent */
    if (nd->link & RTPI_L_TIR) {
        wr += wt;
        wt = 0.0;
    }
    if (wr > 0.0 && (nd->link & RTPI_L_REFL))
        weights_node(c, nodes, idx + 1, w * wr, out);
    if (wt > 0.0 && (nd->link & RTPI_L_REFR))
        weights_node(c, nodes, idx + (nd->link >> RTPI_L_SHIFT), w * wt, out);
}

void rtpi_sample_weights(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n, double *w)
{
    size_t k;
    for (k = 0; k < n; k++)
        w[k] = 0.0;
    if (n > 0)
        weights_node(c, nodes, 0, 1.0, w);
}
