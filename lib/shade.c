/* shade.c — the one shading routine.  It evaluates the paper's equation
 *   I = kd c_obj sum_{i in Omega} (n.l_i) c_li + ks sum_{i in Omega} (r_i.v)^n c_li
 *       + ks I_r + kt I_t + I_a
 * over a recorded ray tree of compact nodes.  It never casts a ray: the
 * tree holds where each ray hit and which lights each hit saw; normals,
 * texture coordinates and view vectors are derived from the hit positions
 * and the scene's geometry; the scene holds every optical parameter.  Conventions (README.md, "Shading"): c_li is the light colour
 * times the scene's light scale; I_a = ambient * ka * c_obj, per channel,
 * with ka the material's ambient coefficient (mat.N.ambient), kd in each
 * channel where it has none (the sums then exactly as before ka came). */
#include "internal.h"

#include <float.h>
#include <stddef.h>
/* (SSE2, which every x86-64 has: rtpi_light_redo's node arithmetic two
   coordinates a vector; elsewhere, or with RTP_NO_SSE2, its plain C twin,
   the same operations in the same order) */
#if defined(__SSE2__) && !defined(RTP_NO_SSE2)
#include <emmintrin.h>
#define SHADE_SSE2 1
#endif

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

/* (float)pow(x, y) for the highlight's term, to the bit, mostly without
   calling pow (a fifth of a moved light's redo on teapot, whose
   materials' shines, 3.0827 and 4.81884, are not integers).  v = 2^(y
   log2 x) is made in double with a relative error below 2^-42.3 (see
   below); glibc's pow (Arm's optimized routines, glibc 2.28 on) states a
   worst case of 0.54 ulp of double, and 2^-44 is allowed for it here
   (some 500 ulps): pow's and v lie within 2^-41 v of each other.  Where
   no float rounding boundary (a midpoint between neighbouring floats)
   lies that close to v, (float)v and (float)pow(x, y) are the same
   float.  The boundaries of v's binade
   sit where v's 29 low mantissa bits (those a float drops) are 2^28;
   2^-41 v is below 2^12 ulps of v, and the test asks for 2^16 (16x that,
   for any slip in the bound: pow is then called for 1 v in 4096; at a
   binade's ends a float, not a boundary, lies within reach).  Elsewhere
   pow: x not a positive normal double, |y| above 1024 (the bound grows
   with y), v outside the normal floats (a float subnormal's boundaries
   do not sit at those bits), but where v < 2^-152 (x^y < 2^-150, half
   the least float: 0 either way).

   The error: x = 2^k z, z in [0.7058, 1.4117), its 128th part (by z's
   bits, as in glibc's log2) holds 1/c and log2 c rounded (pow_log2_tab,
   made with 200-bit mpmath: c the middle of the part, log2 c = -log2 of
   the rounded 1/c); r = z/c - 1 from one rounded product (the
   subtraction is exact: Sterbenz), |r| < 2^-8.01, off by <= 2^-53;
   log2(1 + r) by its series to r^6 (the rest below |r|^7 / (7 ln 2) <
   2^-58.3), off by < 2^-52.4 with r's error and the series' roundings;
   L = (k + log2 c) + p off by < 2^-52.2 + 2^-52 |L|; t = y L off by <
   |y| 2^-52.2 + 2^-51.4 |t| (|t| <= 160 here: < |y| 2^-52.2 + 2^-44.1).
   2^t = 2^e 2^(j/128) 2^f, |f| <= 1/256 exact (t - kd/128: two doubles
   within 1/256), 2^(j/128) rounded (pow_exp2_tab), 2^f by its series to
   f^5 (rest < 2^-60.7), two roundings of 2^-53 besides: relative <
   2^-51.9 + ln 2 (error of t) < 2^-51.9 + |y| 2^-52.7 + 2^-44.6, below
   2^-42.3 for |y| <= 1024 (measured against powl: 2^-42.8 at |y| 1024,
   2^-44.7 at the SPD shines).  In double arithmetic only
   (FLT_EVAL_METHOD 0: SSE2, not x87). */
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0
static const double pow_log2_tab[128][2] = {
    {0x1.69be8c81fb00cp+0, -0x1.fecc6670c0ed3p-2},
    {0x1.67c22fe4dcddap+0, -0x1.f6aa97eb30d82p-2},
    {0x1.65cb6049c63c4p+0, -0x1.ee942efb1584fp-2},
    {0x1.63da068aeb033p+0, -0x1.e6890bdb248e2p-2},
    {0x1.61ee0c0281abbp+0, -0x1.de890f4a34fd9p-2},
    {0x1.60075a87531dbp+0, -0x1.d6941a88668e3p-2},
    {0x1.5e25dc6966c26p+0, -0x1.ceaa0f545c71bp-2},
    {0x1.5c497c6ec9c1ap+0, -0x1.c6cacfe88afdep-2},
    {0x1.5a7225d070680p+0, -0x1.bef63ef897a3ep-2},
    {0x1.589fc43730bf1p+0, -0x1.b72c3faeca9f4p-2},
    {0x1.56d243b8d56c2p+0, -0x1.af6cb5a991cd9p-2},
    {0x1.550990d547f30p+0, -0x1.a7b784f91426dp-2},
    {0x1.53459873d182dp+0, -0x1.a00c921cd54c7p-2},
    {0x1.518647e0717edp+0, -0x1.986bc20168b87p-2},
    {0x1.4fcb8cc948f96p+0, -0x1.90d4f9fe34082p-2},
    {0x1.4e15553c1a639p+0, -0x1.89481fd33ff1fp-2},
    {0x1.4c638fa3dcb8ep+0, -0x1.81c519a71771ep-2},
    {0x1.4ab62ac66176cp+0, -0x1.7a4bce04b4bc8p-2},
    {0x1.490d15c20cb76p+0, -0x1.72dc23d97b912p-2},
    {0x1.4768400b9ecd3p+0, -0x1.6b76027340830p-2},
    {0x1.45c7996c0ec27p+0, -0x1.6419517e5cd35p-2},
    {0x1.442b11fe75285p+0, -0x1.5cc5f903ce821p-2},
    {0x1.42929a2e06a4dp+0, -0x1.557be16764342p-2},
    {0x1.40fe22b41db5ep+0, -0x1.4e3af365f4994p-2},
    {0x1.3f6d9c965323ep+0, -0x1.47031813a0f68p-2},
    {0x1.3de0f924a4a53p+0, -0x1.3fd438da22884p-2},
    {0x1.3c5829f7a9375p+0, -0x1.38ae3f7722678p-2},
    {0x1.3ad320eed2b70p+0, -0x1.319115fa9ba26p-2},
    {0x1.3951d02ebc479p+0, -0x1.2a7ca6c547447p-2},
    {0x1.37d42a1f851a3p+0, -0x1.2370dc8711fcfp-2},
    {0x1.365a216b372dap+0, -0x1.1c6da23d9b235p-2},
    {0x1.34e3a8fc39a0ap+0, -0x1.1572e332bcd35p-2},
    {0x1.3370b3fbce360p+0, -0x1.0e808afb1ce04p-2},
    {0x1.320135d099ac2p+0, -0x1.07968574c65d4p-2},
    {0x1.3095221d368ecp+0, -0x1.00b4bec5cb816p-2},
    {0x1.2f2c6cbed22b0p+0, -0x1.f3b646b5df4edp-3},
    {0x1.2dc709cbd3534p+0, -0x1.e6133fccb2692p-3},
    {0x1.2c64ed928aa10p+0, -0x1.d88042bc96524p-3},
    {0x1.2b060c97ebe82p+0, -0x1.cafd29f7cc541p-3},
    {0x1.29aa5b9650907p+0, -0x1.bd89d073e19a4p-3},
    {0x1.2851cf7c428cdp+0, -0x1.b02611a74de70p-3},
    {0x1.26fc5d6b4fab4p+0, -0x1.a2d1c9872008dp-3},
    {0x1.25a9fab6e4facp+0, -0x1.958cd484b7b2cp-3},
    {0x1.245a9ce332056p+0, -0x1.88570f8b8c50dp-3},
    {0x1.230e39a413a1bp+0, -0x1.7b3057ff008edp-3},
    {0x1.21c4c6dc061e2p+0, -0x1.6e188bb8422e3p-3},
    {0x1.207e3a9b1e8d3p+0, -0x1.610f890435e07p-3},
    {0x1.1f3a8b1e0af9dp+0, -0x1.54152ea16ecdfp-3},
    {0x1.1df9aecd194e9p+0, -0x1.47295bbe31820p-3},
    {0x1.1cbb9c3b44badp+0, -0x1.3a4beff681e8bp-3},
    {0x1.1b804a2549645p+0, -0x1.2d7ccb523c1bdp-3},
    {0x1.1a47af70be33ap+0, -0x1.20bbce4337af0p-3},
    {0x1.1911c32b348dcp+0, -0x1.1408d9a375417p-3},
    {0x1.17de7c895dcc0p+0, -0x1.0763ceb356018p-3},
    {0x1.16add2e63647fp+0, -0x1.f5991e2fb9e4cp-4},
    {0x1.157fbdc235cffp+0, -0x1.dc85f9b1f34edp-4},
    {0x1.145434c2855c5p+0, -0x1.c38df4bfb881dp-4},
    {0x1.132b2fb039dc6p+0, -0x1.aab0d4eaa4c53p-4},
    {0x1.1204a67793f6ap+0, -0x1.91ee608059f0fp-4},
    {0x1.10e0912744966p+0, -0x1.79465e875d130p-4},
    {0x1.0fbee7efb622ep+0, -0x1.60b896bc03bdcp-4},
    {0x1.0e9fa3225a3e1p+0, -0x1.4844d18d71a2dp-4},
    {0x1.0d82bb30fbe96p+0, -0x1.2fead81aa60ffp-4},
    {0x1.0c6828ad15f01p+0, -0x1.17aa742f98e2ep-4},
    {0x1.0b4fe4472d780p+0, -0x1.ff06e084cd30cp-5},
    {0x1.0a39e6ce309acp+0, -0x1.ceeb2ee1162e5p-5},
    {0x1.0926292ed8e9ep+0, -0x1.9f016af855c03p-5},
    {0x1.0814a47311c1ap+0, -0x1.6f492d92d47b7p-5},
    {0x1.070551c1624f2p+0, -0x1.3fc210b7a44eap-5},
    {0x1.05f82a5c5b2f9p+0, -0x1.106bafa785084p-5},
    {0x1.04ed27a2078e3p+0, -0x1.c28b4dafc5c25p-6},
    {0x1.03e4430b61a92p+0, -0x1.649f27dbdd25ep-6},
    {0x1.02dd762bcaa3fp+0, -0x1.07122b739c631p-6},
    {0x1.01d8bab085916p+0, -0x1.53c730c7994f4p-7},
    {0x1.00d60a60359dbp+0, -0x1.344ac371d7b43p-8},
    {0x1.ff0087b8260bep-1, 0x1.70ecbb0f4e5b9p-9},
    {0x1.fb602a2f91e1fp-1, 0x1.aceb0fc432f1dp-7},
    {0x1.f77a4dd695191p-1, 0x1.8cc05eb20bbeap-6},
    {0x1.f3a3a89273f9ep-1, 0x1.20d307d6489cap-5},
    {0x1.efdbe1f975defp-1, 0x1.7a9603d2d7ca6p-5},
    {0x1.ec22a449beb96p-1, 0x1.d3abca04b572fp-5},
    {0x1.e8779c4ff8ee3p-1, 0x1.160b78f318196p-4},
    {0x1.e4da794f1f1e5p-1, 0x1.41ed0214dc8c5p-4},
    {0x1.e14aece9570c6p-1, 0x1.6d7bbd94ba4d1p-4},
    {0x1.ddc8ab09cfb09p-1, 0x1.98b8e1a95b45ap-4},
    {0x1.da5369cf9557bp-1, 0x1.c3a59dc6cb645p-4},
    {0x1.d6eae1794f6f3p-1, 0x1.ee431ad064cf6p-4},
    {0x1.d38ecc51dc50bp-1, 0x1.0c493da4794d4p-3},
    {0x1.d03ee69dc00cap-1, 0x1.214a6dc08eb62p-3},
    {0x1.ccfaee895bcefp-1, 0x1.3625a8e21a5abp-3},
    {0x1.c9c2a417e40ffp-1, 0x1.4adb7741b306ap-3},
    {0x1.c695c9130c4d5p-1, 0x1.5f6c5e3fb9c2bp-3},
    {0x1.c37420fb5f8a6p-1, 0x1.73d8e0787c747p-3},
    {0x1.c05d70f93d515p-1, 0x1.88217dd7a78ebp-3},
    {0x1.bd517fce73629p-1, 0x1.9c46b3ab0e0d6p-3},
    {0x1.ba5015c86caaap-1, 0x1.b048fcb4cea84p-3},
    {0x1.b758fcb2ee7e3p-1, 0x1.c428d13cdcc4ap-3},
    {0x1.b46bffcb5d798p-1, 0x1.d7e6a721f373fp-3},
    {0x1.b188ebb483bc1p-1, 0x1.eb82f1e9f86ffp-3},
    {0x1.aeaf8e6ad28c6p-1, 0x1.fefe22d1d4cd8p-3},
    {0x1.abdfb73919c0fp-1, 0x1.092c546e6466ep-2},
    {0x1.a91936adaf945p-1, 0x1.12c97871a003bp-2},
    {0x1.a65bde9003d33p-1, 0x1.1c56b2d095692p-2},
    {0x1.a3a781d69993ap-1, 0x1.25d437e1f0dc0p-2},
    {0x1.a0fbf49d62e51p-1, 0x1.2f423afbcbb48p-2},
    {0x1.9e590c1c7a228p-1, 0x1.38a0ee7a2ec5fp-2},
    {0x1.9bbe9e9f34c91p-1, 0x1.41f083c56042ap-2},
    {0x1.992c837b8be99p-1, 0x1.4b312b57ff145p-2},
    {0x1.96a29309d67c9p-1, 0x1.546314c4ed8f0p-2},
    {0x1.9420a69cd210dp-1, 0x1.5d866ebd0d49cp-2},
    {0x1.91a69879f676ap-1, 0x1.669b6714cddadp-2},
    {0x1.8f3443d211372p-1, 0x1.6fa22ac990198p-2},
    {0x1.8cc984ba25cabp-1, 0x1.789ae606df817p-2},
    {0x1.8a6638248faa5p-1, 0x1.8185c42b83374p-2},
    {0x1.880a3bda6379bp-1, 0x1.8a62efce68240p-2},
    {0x1.85b56e750ca95p-1, 0x1.933292c3658c3p-2},
    {0x1.8367af582510cp-1, 0x1.9bf4d61fdd769p-2},
    {0x1.8120deab841dcp-1, 0x1.a4a9e23f3a2cep-2},
    {0x1.7ee0dd558352dp-1, 0x1.ad51dec74a0e8p-2},
    {0x1.7ca78cf575ea8p-1, 0x1.b5ecf2ac7ae29p-2},
    {0x1.7a74cfde518dap-1, 0x1.be7b4435f5cc2p-2},
    {0x1.7848891186241p-1, 0x1.c6fcf9019cf3ap-2},
    {0x1.76229c3a02dd9p-1, 0x1.cf723607ebf30p-2},
    {0x1.7402eda766a7bp-1, 0x1.d7db1f9fbbffep-2},
    {0x1.71e962495a585p-1, 0x1.e037d981ecce0p-2},
    {0x1.6fd5dfab12e9ep-1, 0x1.e88886ccf3146p-2},
    {0x1.6dc84beefa396p-1, 0x1.f0cd4a084d935p-2},
    {0x1.6bc08dca7cc53p-1, 0x1.f9064527e17e8p-2},
};
static const double pow_exp2_tab[128] = {
    0x1.0000000000000p+0, 0x1.0163da9fb3335p+0,
    0x1.02c9a3e778061p+0, 0x1.04315e86e7f85p+0,
    0x1.059b0d3158574p+0, 0x1.0706b29ddf6dep+0,
    0x1.0874518759bc8p+0, 0x1.09e3ecac6f383p+0,
    0x1.0b5586cf9890fp+0, 0x1.0cc922b7247f7p+0,
    0x1.0e3ec32d3d1a2p+0, 0x1.0fb66affed31bp+0,
    0x1.11301d0125b51p+0, 0x1.12abdc06c31ccp+0,
    0x1.1429aaea92de0p+0, 0x1.15a98c8a58e51p+0,
    0x1.172b83c7d517bp+0, 0x1.18af9388c8deap+0,
    0x1.1a35beb6fcb75p+0, 0x1.1bbe084045cd4p+0,
    0x1.1d4873168b9aap+0, 0x1.1ed5022fcd91dp+0,
    0x1.2063b88628cd6p+0, 0x1.21f49917ddc96p+0,
    0x1.2387a6e756238p+0, 0x1.251ce4fb2a63fp+0,
    0x1.26b4565e27cddp+0, 0x1.284dfe1f56381p+0,
    0x1.29e9df51fdee1p+0, 0x1.2b87fd0dad990p+0,
    0x1.2d285a6e4030bp+0, 0x1.2ecafa93e2f56p+0,
    0x1.306fe0a31b715p+0, 0x1.32170fc4cd831p+0,
    0x1.33c08b26416ffp+0, 0x1.356c55f929ff1p+0,
    0x1.371a7373aa9cbp+0, 0x1.38cae6d05d866p+0,
    0x1.3a7db34e59ff7p+0, 0x1.3c32dc313a8e5p+0,
    0x1.3dea64c123422p+0, 0x1.3fa4504ac801cp+0,
    0x1.4160a21f72e2ap+0, 0x1.431f5d950a897p+0,
    0x1.44e086061892dp+0, 0x1.46a41ed1d0057p+0,
    0x1.486a2b5c13cd0p+0, 0x1.4a32af0d7d3dep+0,
    0x1.4bfdad5362a27p+0, 0x1.4dcb299fddd0dp+0,
    0x1.4f9b2769d2ca7p+0, 0x1.516daa2cf6642p+0,
    0x1.5342b569d4f82p+0, 0x1.551a4ca5d920fp+0,
    0x1.56f4736b527dap+0, 0x1.58d12d497c7fdp+0,
    0x1.5ab07dd485429p+0, 0x1.5c9268a5946b7p+0,
    0x1.5e76f15ad2148p+0, 0x1.605e1b976dc09p+0,
    0x1.6247eb03a5585p+0, 0x1.6434634ccc320p+0,
    0x1.6623882552225p+0, 0x1.68155d44ca973p+0,
    0x1.6a09e667f3bcdp+0, 0x1.6c012750bdabfp+0,
    0x1.6dfb23c651a2fp+0, 0x1.6ff7df9519484p+0,
    0x1.71f75e8ec5f74p+0, 0x1.73f9a48a58174p+0,
    0x1.75feb564267c9p+0, 0x1.780694fde5d3fp+0,
    0x1.7a11473eb0187p+0, 0x1.7c1ed0130c132p+0,
    0x1.7e2f336cf4e62p+0, 0x1.80427543e1a12p+0,
    0x1.82589994cce13p+0, 0x1.8471a4623c7adp+0,
    0x1.868d99b4492edp+0, 0x1.88ac7d98a6699p+0,
    0x1.8ace5422aa0dbp+0, 0x1.8cf3216b5448cp+0,
    0x1.8f1ae99157736p+0, 0x1.9145b0b91ffc6p+0,
    0x1.93737b0cdc5e5p+0, 0x1.95a44cbc8520fp+0,
    0x1.97d829fde4e50p+0, 0x1.9a0f170ca07bap+0,
    0x1.9c49182a3f090p+0, 0x1.9e86319e32323p+0,
    0x1.a0c667b5de565p+0, 0x1.a309bec4a2d33p+0,
    0x1.a5503b23e255dp+0, 0x1.a799e1330b358p+0,
    0x1.a9e6b5579fdbfp+0, 0x1.ac36bbfd3f37ap+0,
    0x1.ae89f995ad3adp+0, 0x1.b0e07298db666p+0,
    0x1.b33a2b84f15fbp+0, 0x1.b59728de5593ap+0,
    0x1.b7f76f2fb5e47p+0, 0x1.ba5b030a1064ap+0,
    0x1.bcc1e904bc1d2p+0, 0x1.bf2c25bd71e09p+0,
    0x1.c199bdd85529cp+0, 0x1.c40ab5fffd07ap+0,
    0x1.c67f12e57d14bp+0, 0x1.c8f6d9406e7b5p+0,
    0x1.cb720dcef9069p+0, 0x1.cdf0b555dc3fap+0,
    0x1.d072d4a07897cp+0, 0x1.d2f87080d89f2p+0,
    0x1.d5818dcfba487p+0, 0x1.d80e316c98398p+0,
    0x1.da9e603db3285p+0, 0x1.dd321f301b460p+0,
    0x1.dfc97337b9b5fp+0, 0x1.e264614f5a129p+0,
    0x1.e502ee78b3ff6p+0, 0x1.e7a51fbc74c83p+0,
    0x1.ea4afa2a490dap+0, 0x1.ecf482d8e67f1p+0,
    0x1.efa1bee615a27p+0, 0x1.f252b376bba97p+0,
    0x1.f50765b6e4540p+0, 0x1.f7bfdad9cbe14p+0,
    0x1.fa7c1819e90d8p+0, 0x1.fd3c22b8f71f1p+0,
};
/* (out of line: the loops calling pow_float keep their registers) */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static float pow_libm(double x, double y)
{
    return (float)pow(x, y);
}

static RTPI_FORCE_INLINE float pow_float(double x, double y)
{
    /* 0x3fe6955500000000: z's range starts near 1/sqrt 2, so that |log2
       z| <= 0.5 */
    const uint64_t off = 0x3fe6955500000000u;
    const double shift = 0x1.8p52; /* adding it rounds to an integer */
    uint64_t ix, tmp, iv;
    double z, r, p, L, t, kd, f, q, s, v, sc;
    const double *lt;
    unsigned u, j, ev;
    memcpy(&ix, &x, sizeof ix);
    if (ix - 0x0010000000000000u >= 0x7fe0000000000000u || !(fabs(y) <= 1024.0))
        return pow_libm(x, y);
    tmp = ix - off;
    lt = pow_log2_tab[(tmp >> 45) & 127];
    ix -= tmp & 0xfff0000000000000u;
    memcpy(&z, &ix, sizeof z);
    r = z * lt[0] - 1.0;
    p = r * (0x1.71547652b82fep+0 +
             r * (-0x1.71547652b82fep-1 +
                  r * (0x1.ec709dc3a03fdp-2 +
                       r * (-0x1.71547652b82fep-2 +
                            r * (0x1.2776c50ef9bfep-2 + r * -0x1.ec709dc3a03fdp-3)))));
    /* k: tmp's exponent field as a signed 12-bit number */
    L = ((double)((int)((tmp + 0x8000000000000000u) >> 52) - 2048) + lt[1]) + p;
    t = y * L;
    if (t < -160.0)
        return 0.0f; /* x^y < 2^-159 */
    if (!(t <= 160.0))
        return pow_libm(x, y);
    kd = t * 128.0 + shift;
    kd -= shift;
    f = t - kd * (1.0 / 128.0);
    u = (unsigned)((int)kd + 128 * 1024); /* 128 e + j, e biased by 1024 */
    j = u & 127u;
    q = f * (0x1.62e42fefa39efp-1 +
             f * (0x1.ebfbdff82c58fp-3 +
                  f * (0x1.c6b08d704a0c0p-5 +
                       f * (0x1.3b2ab6fba4e77p-7 + f * 0x1.5d87fe78a6731p-10))));
    s = pow_exp2_tab[j] + pow_exp2_tab[j] * q;
    iv = (uint64_t)((u >> 7) - 1024u + 1023u) << 52; /* 2^e, e in [-161, 160] */
    memcpy(&sc, &iv, sizeof sc);
    v = s * sc;
    memcpy(&iv, &v, sizeof iv);
    ev = (unsigned)(iv >> 52);
    if (ev - 897u <= 253u) { /* v in [2^-126, 2^127) */
        if (((uint32_t)iv & 0x1fffffffu) - (0x10000000u - 0x10000u) >= 0x20000u)
            return (float)v;
    } else if (ev - (1023u - 152u) < 26u) {
        /* v in [2^-152, 2^-126): the float subnormals, whose boundaries
           are (i + 1/2) 2^-149; w = v 2^149 (exact) below 2^23, so 2^-41
           v is below 2^-18 of w's units: w's distance to i + 1/2 asked
           above 2^-17 (w - its nearest integer exact: both below 2^23) */
        double w = v * 0x1p149, wi = w + shift;
        wi -= shift;
        if (fabs(fabs(w - wi) - 0.5) > 0x1p-17)
            return (float)v;
    } else if (ev < 1023u - 152u) {
        return 0.0f;
    }
    return pow_libm(x, y);
}
#else
static float pow_float(double x, double y)
{
    return (float)pow(x, y);
}
#endif

#if defined(__GNUC__)
__attribute__((noinline))
#endif
float rtpi_pow_float(double x, double y)
{
    return pow_float(x, y);
}

static int seen(const rtpi_cnode *nd, const uint32_t *ext, size_t i)
{
    if (!ext)
        return (int)((nd->vis >> i) & 1u);
    return (int)((ext[i >> 5] >> (i & 31)) & 1u);
}

static inline rtpi_v3 light_pos(const rtpi_light *L)
{
    return v3(L->pos[0], L->pos[1], L->pos[2]);
}

/* n.l and l (the unit vector to the light); 0 where n.l <= 0 (a NaN
   n.l goes on, as the terms have always taken it) */
static inline int light_ndl(const float *nv, rtpi_v3 p, rtpi_v3 lp, double *ndl, rtpi_v3 *l)
{
    rtpi_v3 n = v3(nv[0], nv[1], nv[2]);
    *l = v3_norm(v3_sub(lp, p));
    *ndl = v3_dot(n, *l);
    return !(*ndl <= 0.0);
}

/* r_i.v, r_i being l mirrored about n; the highlight is (r_i.v)^shine. */
static inline double light_rv(const float *nv, double ndl, rtpi_v3 l)
{
    rtpi_v3 n = v3(nv[0], nv[1], nv[2]), v = v3(nv[3], nv[4], nv[5]);
    return v3_dot(v3_sub(v3_mul(n, 2.0 * ndl), l), v);
}

/* n.l and the highlight's base r.v at a hit facing the light; 0 where
   the light is behind the surface (rtpi_material_highlights). */
static inline int light_geometry(const float *nv, rtpi_v3 p, rtpi_v3 lp, double *ndl,
                                 double *rv)
{
    rtpi_v3 l;
    if (!light_ndl(nv, p, lp, ndl, &l))
        return 0;
    *rv = light_rv(nv, *ndl, l);
    return 1;
}

/* The terms of one light at a hit: d = n.l and s = (r.v)^shine where the
   hit sees the light and faces it.  n and v come rounded to float (as the
   evaluation cache keeps them), so recomputing one light's terms from the
   cache repeats this arithmetic exactly (rtpi_light_redo has its own
   inline copy of it, with the power inline: pow_inline is 0 at every
   call now, kept because folding it into light_term cost the first
   evaluation 0.5-0.7%, session 44). */
static RTPI_FORCE_INLINE void light_term_pow(const float *nv, rtpi_v3 p, rtpi_v3 lp,
                                             int visible, const rtpi_material *m, float *out,
                                             int pow_inline)
{
    double ndl, rv;
    rtpi_v3 l;
    out[0] = out[1] = 0.0f;
    if (!visible || !light_ndl(nv, p, lp, &ndl, &l))
        return;
    out[0] = (float)ndl;
    /* no highlight to weigh where ks is 0 (an edit making it non-zero
       recomputes these terms): r.v not made there (tree's materials,
       most of balls' lit nodes), as in rtpi_light_redo */
    if (!(m->ks > 0.0f))
        return;
    rv = light_rv(nv, ndl, l);
    if (rv > 0.0)
        out[1] = pow_inline ? pow_float(rv, m->shine) : rtpi_pow_float(rv, m->shine);
}

/* light_term_pow with the power called (the first evaluation's
   node_terms over every light, where inline it cost mount's 2%: the
   spills around the loop's other work) */
static RTPI_FORCE_INLINE void light_term(const float *nv, rtpi_v3 p, rtpi_v3 lp, int visible,
                                         const rtpi_material *m, float *out)
{
    light_term_pow(nv, p, lp, visible, m, out, 0);
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

/* rtpi_combine's sums where one came out NaN or past RTPI_SAMPLE_MAX: a
   colour of 0 adds nothing there (RTPI_TERM_SUM), and each sum is held to
   the sample's range, 0 where it is NaN still. */
static void combine_zero(const rtp_scene *s, const double *cl, const float *coeffs, float rgb[3])
{
    size_t i, nl = s->nlights;
    int k;
    for (k = 0; k < 3; k++) {
        double a = RTPI_TERM_SUM(RTPI_TERM_SUM(0.0, coeffs[k], (double)s->background[k]),
                                 coeffs[3 + k], (double)s->ambient[k]);
        for (i = 0; i < nl; i++)
            a = RTPI_TERM_SUM(a, coeffs[6 + 3 * i + k], cl[3 * i + k]);
        rgb[k] = a > RTPI_SAMPLE_MAX ? RTPI_SAMPLE_MAX
                 : a < -RTPI_SAMPLE_MAX ? -RTPI_SAMPLE_MAX
                 : a == a ? (float)a : 0.0f;
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
       rule leaves as they are).  The same test sends sums past
       RTPI_SAMPLE_MAX there, to be held to it: their squares summed, as
       one past it passes its square, and NaN fails (the pair's squares
       are one vector operation: the magnitudes summed cost a first
       evaluation 0.4-0.6%, balls 336.75 -> 338.86 M, the squares 338.33;
       channels each within it whose squares sum past its square take the
       slower way, to the same values). */
    if (!(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <=
          (double)RTPI_SAMPLE_MAX * RTPI_SAMPLE_MAX)) {
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

#ifdef SHADE_SSE2
/* light_redo loads a material's kd and ks as one pair */
typedef char shade_kd_ks[offsetof(rtpi_material, ks) == offsetof(rtpi_material, kd) + sizeof(float)
                             ? 1
                             : -1];

/* f[0] and f[1] widened (cvtps2pd) */
static RTPI_FORCE_INLINE __m128d load2f(const float *f)
{
    return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)f)));
}

/* f[0] widened (in the low lane, 0 in the other) */
static RTPI_FORCE_INLINE __m128d load1f(const float *f)
{
    return _mm_cvtps_pd(_mm_load_ss(f));
}

static RTPI_FORCE_INLINE void store3f(float *o, __m128d v01, __m128d v2)
{
    _mm_storel_epi64((__m128i *)o, _mm_castps_si128(_mm_cvtpd_ps(v01)));
    o[2] = (float)_mm_cvtsd_f64(v2);
}
#endif

/* A kept product (t->mv_kc) is told made by its first word's bits: the
   array starts zeroed.  A red product of +0 (rings_s7's 420 of 841
   materials have no red) would read as not made and be made again at
   every move, so it is kept as -0, the same number in every sum it
   enters: d > 0 there, so -0 d is -0, and -0 + x is x for every x, +0
   included (round to nearest); a NaN d gives the same NaN either way. */
static RTPI_FORCE_INLINE void kc_mark(double *kj)
{
    if (kj[0] == 0.0)
        kj[0] = -0.0;
}

/* rtpi_light_redo's body; with_rest: rest is not NULL (a constant at
   each call: the loop compiled twice, the one without the kept rest
   combining inline, which in the one with it had cost balls' and rings'
   moves 0.1-0.2%) */
static RTPI_FORCE_INLINE unsigned long long
light_redo(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, const uint64_t *start, size_t k0,
           size_t k1, const uint32_t *vis_ext, const float *nv, const double *w, size_t light,
           float *terms, float *coeffs, const double *cl, float *samples, int *bad,
           unsigned char *mark, double *rest, unsigned char *rest_ok, double *kc, int with_rest,
           int one_word, int no_ks, size_t nlc)
{
    const rtp_scene *s = c->s;
    const rtpi_v3 lp = light_pos(&s->lights[light]);
    /* (nlc: the scene's lights where the call knows them (1 or 2, the
       copies without a kept rest), else 0: the strides constants and the
       sum's loops unrolled there) */
    const size_t nlv = nlc ? nlc : s->nlights;
    /* (one_word: vis_ext holds a word a node, light's bit in it) */
    const size_t nt = RTPI_TERMS(nlv), nc = RTPI_COEFFS(nlv),
                 wi = one_word ? 0 : light >> 5;
    const size_t vw = one_word ? 1 : c->vis_words;
    const uint32_t bit = 1u << (light & 31);
    const rtpi_material *const mats = s->mats;
    const rtpi_tri *const tris = s->tris;
    const rtpi_sphere *const sph = s->spheres;
    const rtpi_cone *const cones = s->cones;
    const size_t ntris = s->ntris, nsph = s->nspheres;
#ifdef SHADE_SSE2
    const __m128d lpxy = _mm_set_pd(lp.y, lp.x), lpz = _mm_set_sd(lp.z);
    const __m128d absm = _mm_castsi128_pd(_mm_set1_epi64x(0x7fffffffffffffff));
    const __m128d bg01 = load2f(s->background), bg2 = _mm_set_sd(s->background[2]);
    const __m128d am01 = load2f(s->ambient), am2 = _mm_set_sd(s->ambient[2]);
    const __m128d lc01 = _mm_loadu_pd(cl + 3 * light), lc2 = _mm_load_sd(cl + 3 * light + 2);
    const __m128d cmax = _mm_set_sd(RTPI_COEFF_MAX);
    __m128d badv = _mm_setzero_pd();
    const size_t nl = nlv;
    /* (no_ks: c->no_ks and kc, a constant in each copy: as a run-time
       test in the one loop its branch a lit node had cost the scenes with
       highlights 1.2-2.3 M a move) */
    const int no_ks_kc = no_ks;
    size_t i;
#endif
    /* (a kept rest only where the samples are combined (rtpi_light_redo):
       the copy with it tests nothing) */
    const int comb = with_rest || samples != NULL;
#ifndef SHADE_SSE2
    (void)no_ks; /* (the scalar loop looks the material up at every lit node) */
#endif
    unsigned long long combined = 0;
    int nonfinite = 0;
    size_t k, j;
    for (k = k0; k < k1; k++) {
        size_t a = (size_t)start[k], b = (size_t)start[k + 1];
        float *co = coeffs + k * nc;
#ifdef SHADE_SSE2
        __m128d a01 = _mm_setzero_pd(), a2v = _mm_setzero_pd();
        __m128 f01, f2; /* the coefficient rounded, kept for its colour */
#else
        double a0 = 0.0, a1 = 0.0, a2 = 0.0;
#endif
        if (a == b)
            continue; /* the background: no light in it, nothing changes */
#ifdef SHADE_SSE2
        /* light_term_pow's and the sums' arithmetic below on (x, y) in a
           vector and z alone: each lane's operations are the plain C's,
           in its order (a dot product (x x' + y y') + z z'), so the bits
           are its own; the floats are widened two at a time (cvtps2pd,
           where gcc's scalar code paid a pxor for each cvtss2sd).
           Instructions a lit node, teapot's moves: 141 -> 121 (gcc). */
        for (j = a; j < b; j++) {
            const rtpi_cnode *nd = &nodes[j];
            const rtpi_material *m;
            float *t = terms + j * nt, *tl = t + 3 + 2 * light;
            int visible = vis_ext ? (vis_ext[j * vw + wi] & bit) != 0
                                  : (int)((nd->vis >> light) & 1u);
            const float *q = nv + 6 * j;
            const double *wj = w + j;
            __m128 qa, pa;
            __m128d nxy, nzvx, vyz, vxy, lxy, lz, sq, len, ndl, rv, two, txy, tz, kds, d;
            double ndl_d, rv_d;
            uint64_t wb;
            uint32_t prim, db;
            float df;
            if (!visible) {
                tl[0] = tl[1] = 0.0f;
                continue;
            }
            /* p[0..2] and prim, n and v[0] (16 bytes each), v[1..2] */
            pa = _mm_loadu_ps(nd->p);
            qa = _mm_loadu_ps(q);
            lxy = _mm_sub_pd(lpxy, _mm_cvtps_pd(pa));
            lz = _mm_sub_sd(lpz, _mm_cvtps_pd(_mm_movehl_ps(pa, pa)));
            /* v3_norm: |l| = sqrt((x x + y y) + z z), l / |l| as l (1 / |l|) */
            sq = _mm_mul_pd(lxy, lxy);
            sq = _mm_add_sd(_mm_add_sd(sq, _mm_unpackhi_pd(sq, sq)), _mm_mul_sd(lz, lz));
            len = _mm_sqrt_sd(sq, sq);
            if (_mm_cvtsd_f64(len) > 0.0) {
                __m128d inv = _mm_div_sd(_mm_set_sd(1.0), len);
                inv = _mm_unpacklo_pd(inv, inv);
                lxy = _mm_mul_pd(lxy, inv);
                lz = _mm_mul_sd(lz, inv);
            }
            nxy = _mm_cvtps_pd(qa);
            nzvx = _mm_cvtps_pd(_mm_movehl_ps(qa, qa)); /* (n.z, v.x) */
            ndl = _mm_mul_pd(nxy, lxy);
            ndl = _mm_add_sd(_mm_add_sd(ndl, _mm_unpackhi_pd(ndl, ndl)), _mm_mul_sd(nzvx, lz));
            ndl_d = _mm_cvtsd_f64(ndl);
            if (ndl_d <= 0.0) {
                tl[0] = tl[1] = 0.0f;
                continue;
            }
            if (no_ks_kc) {
                /* no material with a highlight (tree): a node reached,
                   lit and kept needs no material (its lookup ~8
                   instructions a lit node) */
                uint64_t k0b;
                df = (float)ndl_d;
                memcpy(&k0b, kc + 3 * j, sizeof k0b);
                memcpy(&wb, wj, sizeof wb);
                memcpy(&db, &df, sizeof db);
                if (k0b && (wb << 1) && (db << 1)) {
                    tl[0] = df;
                    tl[1] = 0.0f;
                    d = _mm_set1_pd((double)df);
                    a01 = _mm_add_pd(a01, _mm_mul_pd(_mm_loadu_pd(kc + 3 * j), d));
                    a2v = _mm_add_sd(a2v, _mm_mul_sd(_mm_load_sd(kc + 3 * j + 2), d));
                    continue;
                }
            }
            prim = nd->prim;
            m = &mats[prim < ntris        ? tris[prim].mat
                      : prim - ntris < nsph ? sph[prim - ntris].mat
                                            : cones[prim - ntris - nsph].mat];
            df = (float)ndl_d;
            tl[0] = df;
            /* the highlight only where ks > 0: r.v is not made where it
               weighs nothing (tree's materials, most of balls' lit
               nodes) */
            if (m->ks > 0.0f) {
                /* r.v with r = n (2 n.l) - l (2 n.l as n.l + n.l, the
                   same number) */
                vyz = _mm_cvtps_pd(
                    _mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)(q + 4))));
                vxy = _mm_shuffle_pd(nzvx, vyz, 1);
                two = _mm_add_sd(ndl, ndl);
                two = _mm_unpacklo_pd(two, two);
                txy = _mm_sub_pd(_mm_mul_pd(nxy, two), lxy);
                tz = _mm_sub_sd(_mm_mul_sd(nzvx, two), lz);
                rv = _mm_mul_pd(txy, vxy);
                rv = _mm_add_sd(_mm_add_sd(rv, _mm_unpackhi_pd(rv, rv)),
                                _mm_mul_sd(tz, _mm_unpackhi_pd(vyz, vyz)));
                rv_d = _mm_cvtsd_f64(rv);
                tl[1] = rv_d > 0.0 ? pow_float(rv_d, m->shine) : 0.0f;
            } else {
                tl[1] = 0.0f;
            }
            memcpy(&wb, wj, sizeof wb);
            memcpy(&db, &df, sizeof db);
            if (!(wb << 1) || !(db << 1))
                continue;
            if (kc) {
                /* the node's kept (w kd) c_obj (light_kc): a += kd_c d
                   (+ (w ks) s where ks > 0; elsewhere that term is +-0,
                   which changes no sum: the sum starts at +0 and is
                   never -0) */
                double *kj = kc + 3 * j;
                uint64_t k0b;
                memcpy(&k0b, kj, sizeof k0b);
                if (k0b) {
                    __m128d kcxy = _mm_loadu_pd(kj), kcz = _mm_load_sd(kj + 2);
                    d = _mm_set1_pd((double)df);
                    if (m->ks > 0.0f) {
                        __m128d hs = _mm_set1_pd(*wj * (double)m->ks * (double)tl[1]);
                        a01 = _mm_add_pd(a01, _mm_add_pd(_mm_mul_pd(kcxy, d), hs));
                        a2v = _mm_add_sd(a2v, _mm_add_sd(_mm_mul_sd(kcz, d), hs));
                    } else {
                        a01 = _mm_add_pd(a01, _mm_mul_pd(kcxy, d));
                        a2v = _mm_add_sd(a2v, _mm_mul_sd(kcz, d));
                    }
                    continue;
                }
            }
            /* (kd, ks) = w (m->kd, m->ks), the two floats side by side
               (shade_kd_ks); c_obj = t colour (+ (1 - t) colour2);
               a += kd c_obj d + ks s */
            kds = _mm_mul_pd(_mm_load1_pd(wj),
                             _mm_cvtps_pd(_mm_castsi128_ps(
                                 _mm_loadl_epi64((const __m128i *)&m->kd))));
            {
                __m128d txy2 = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)t)));
                __m128d cxy = _mm_cvtps_pd(
                    _mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)m->color)));
                __m128d tz2 = load1f(&t[2]), cz = load1f(&m->color[2]);
                __m128d kd = _mm_unpacklo_pd(kds, kds), ks = _mm_unpackhi_pd(kds, kds), hs;
                cxy = _mm_mul_pd(txy2, cxy);
                cz = _mm_mul_sd(tz2, cz);
                if (m->tex == RTPI_TEX_CHECKER) {
                    __m128d one = _mm_set1_pd(1.0);
                    __m128d c2xy = _mm_cvtps_pd(
                        _mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)m->color2)));
                    cxy = _mm_add_pd(cxy, _mm_mul_pd(_mm_sub_pd(one, txy2), c2xy));
                    cz = _mm_add_sd(cz, _mm_mul_sd(_mm_sub_sd(one, tz2),
                                                   load1f(&m->color2[2])));
                }
                d = _mm_set1_pd((double)df);
                hs = _mm_mul_pd(ks, _mm_set1_pd((double)tl[1]));
                cxy = _mm_mul_pd(kd, cxy);
                cz = _mm_mul_sd(kd, cz);
                /* kept where the term it leaves out is +-0 or made
                   at each move: not where w ks is not finite (inf 0) */
                if (kc && (m->ks > 0.0f || fabs(_mm_cvtsd_f64(ks)) <= DBL_MAX)) {
                    _mm_storeu_pd(kc + 3 * j, cxy);
                    _mm_store_sd(kc + 3 * j + 2, cz);
                    kc_mark(kc + 3 * j);
                }
                a01 = _mm_add_pd(a01, _mm_add_pd(_mm_mul_pd(cxy, d), hs));
                a2v = _mm_add_sd(a2v, _mm_add_sd(_mm_mul_sd(cz, d), hs));
            }
        }
        {
            /* the block below on the vectors: (float) a, |a0| + |a1| + |a2|
               in its order, the comparison of the bits as two integers */
            float *cf = co + 6 + 3 * light;
            __m128d ab = _mm_and_pd(a01, absm);
            uint64_t lo, old_lo;
            uint32_t hi, old_hi;
            f01 = _mm_cvtpd_ps(a01);
            f2 = _mm_cvtsd_ss(_mm_setzero_ps(), a2v);
            ab = _mm_add_sd(_mm_add_sd(ab, _mm_unpackhi_pd(ab, ab)), _mm_and_pd(a2v, absm));
            /* !(ab <= RTPI_COEFF_MAX), a NaN's too, as a mask */
            badv = _mm_or_pd(badv, _mm_cmpnle_sd(ab, cmax));
            _mm_storel_epi64((__m128i *)&lo, _mm_castps_si128(f01)); /* (also i386) */
            hi = (uint32_t)_mm_cvtsi128_si32(_mm_castps_si128(f2));
            memcpy(&old_lo, cf, sizeof old_lo);
            memcpy(&old_hi, cf + 2, sizeof old_hi);
            if (comb && lo == old_lo && hi == old_hi)
                continue;
            memcpy(cf, &lo, sizeof lo);
            memcpy(cf + 2, &hi, sizeof hi);
        }
#else
        for (j = a; j < b; j++) {
            const rtpi_cnode *nd = &nodes[j];
            const rtpi_material *m;
            float *t = terms + j * nt, *tl = t + 3 + 2 * light;
            int visible = vis_ext ? (vis_ext[j * vw + wi] & bit) != 0
                                  : (int)((nd->vis >> light) & 1u);
            const float *q = nv + 6 * j;
            const double *wj = w + j;
            double ndl, rv, d, sp, kd, ks, c0, c1, c2;
            uint64_t wb;
            uint32_t prim, db;
            float df;
            rtpi_v3 n, l;
            if (!visible) {
                /* light_term's terms where the light is not seen, and
                   nothing to sum (most nodes of a scene in shadow: no
                   material to look up) */
                tl[0] = tl[1] = 0.0f;
                continue;
            }
            /* light_term_pow's arithmetic inline (the light's position
               taken once), a node turned away leaving at once */
            n = v3(q[0], q[1], q[2]);
            l = v3_norm(v3_sub(lp, v3(nd->p[0], nd->p[1], nd->p[2])));
            ndl = v3_dot(n, l);
            if (ndl <= 0.0) {
                tl[0] = tl[1] = 0.0f;
                continue;
            }
            prim = nd->prim;
            /* (rtpi_prim_material with the scene's arrays in locals) */
            m = &mats[prim < ntris        ? tris[prim].mat
                      : prim - ntris < nsph ? sph[prim - ntris].mat
                                            : cones[prim - ntris - nsph].mat];
            df = (float)ndl;
            tl[0] = df;
            /* no highlight to weigh where ks is 0 (an edit making it
               non-zero recomputes these terms): r.v not made there */
            if (m->ks > 0.0f) {
                rv = v3_dot(v3_sub(v3_mul(n, 2.0 * ndl), l), v3(q[3], q[4], q[5]));
                tl[1] = rv > 0.0 ? pow_float(rv, m->shine) : 0.0f;
            } else {
                tl[1] = 0.0f;
            }
            /* coeffs_node's sum for this light, node by node in its order
               (depth first, reflected subtree first: the order they are
               stored in), leaving out the nodes it does not reach: w or
               d zero (+0 or -0) told by their bits, one test each (as
               == 0.0, gcc made ~14 instructions of the pair) */
            memcpy(&wb, wj, sizeof wb);
            memcpy(&db, &df, sizeof db);
            if (!(wb << 1) || !(db << 1))
                continue;
            d = df;
            sp = tl[1];
            if (kc) {
                /* the node's kept (w kd) c_obj, as in the SSE2 loop */
                double *kj = kc + 3 * j;
                uint64_t k0b;
                memcpy(&k0b, kj, sizeof k0b);
                if (k0b) {
                    if (m->ks > 0.0f) {
                        ks = *wj * m->ks;
                        a0 += kj[0] * d + ks * sp;
                        a1 += kj[1] * d + ks * sp;
                        a2 += kj[2] * d + ks * sp;
                    } else {
                        a0 += kj[0] * d;
                        a1 += kj[1] * d;
                        a2 += kj[2] * d;
                    }
                    continue;
                }
            }
            kd = *wj * m->kd;
            ks = *wj * m->ks;
            /* obj_colour's */
            if (m->tex == RTPI_TEX_CHECKER) {
                c0 = t[0] * (double)m->color[0] + (1.0 - t[0]) * (double)m->color2[0];
                c1 = t[1] * (double)m->color[1] + (1.0 - t[1]) * (double)m->color2[1];
                c2 = t[2] * (double)m->color[2] + (1.0 - t[2]) * (double)m->color2[2];
            } else {
                c0 = t[0] * (double)m->color[0];
                c1 = t[1] * (double)m->color[1];
                c2 = t[2] * (double)m->color[2];
            }
            c0 = kd * c0;
            c1 = kd * c1;
            c2 = kd * c2;
            if (kc && (m->ks > 0.0f || fabs(ks) <= DBL_MAX)) {
                kc[3 * j] = c0;
                kc[3 * j + 1] = c1;
                kc[3 * j + 2] = c2;
                kc_mark(kc + 3 * j);
            }
            a0 += c0 * d + ks * sp;
            a1 += c1 * d + ks * sp;
            a2 += c2 * d + ks * sp;
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
            if (comb && memcmp(cf, f, sizeof f) == 0)
                continue;
            memcpy(cf, f, sizeof f);
        }
#endif
#ifdef SHADE_SSE2
        if (comb) {
            /* the block below on the vectors, each lane its operations
               (the background, ambient and this light's colour widened
               once a call) */
            float *o = samples + 3 * k;
            __m128d v01, v2;
            if (with_rest) {
                double *r = rest + 3 * k;
                __m128d ab;
                if (!rest_ok[k]) {
                    rtpi_combine_rest(s, cl, co, light, r);
                    rest_ok[k] = 1;
                }
                /* (the coefficient as stored: f01, f2) */
                v01 = _mm_add_pd(_mm_loadu_pd(r), _mm_mul_pd(_mm_cvtps_pd(f01), lc01));
                v2 = _mm_add_sd(_mm_load_sd(r + 2), _mm_mul_sd(_mm_cvtps_pd(f2), lc2));
                ab = _mm_and_pd(v01, absm);
                ab = _mm_add_sd(_mm_add_sd(ab, _mm_unpackhi_pd(ab, ab)), _mm_and_pd(v2, absm));
                if (_mm_cvtsd_f64(ab) <= RTPI_SAMPLE_MAX)
                    store3f(o, v01, v2);
                else
                    rtpi_combine(s, cl, co, o);
            } else {
                const float *cc = co + 6;
                const double *cli = cl;
                double sum;
                v01 = _mm_add_pd(_mm_mul_pd(load2f(co), bg01), _mm_mul_pd(load2f(co + 3), am01));
                v2 = _mm_add_sd(_mm_mul_sd(load1f(&co[2]), bg2),
                                _mm_mul_sd(load1f(&co[5]), am2));
                /* the moved light's term in its place, from the
                   coefficient as stored (f01, f2) and the light's colour
                   widened once a call (lc01, lc2), not reloaded; with
                   one or two lights (nlc) the other's term written out */
                if (nlc == 2 && light == 0) {
                    v01 = _mm_add_pd(v01, _mm_mul_pd(_mm_cvtps_pd(f01), lc01));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(_mm_cvtps_pd(f2), lc2));
                    v01 = _mm_add_pd(v01, _mm_mul_pd(load2f(cc + 3), _mm_loadu_pd(cli + 3)));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(load1f(&cc[5]), _mm_load_sd(cli + 5)));
                } else if (nlc == 2) {
                    v01 = _mm_add_pd(v01, _mm_mul_pd(load2f(cc), _mm_loadu_pd(cli)));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(load1f(&cc[2]), _mm_load_sd(cli + 2)));
                    v01 = _mm_add_pd(v01, _mm_mul_pd(_mm_cvtps_pd(f01), lc01));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(_mm_cvtps_pd(f2), lc2));
                } else if (nlc == 1) {
                    v01 = _mm_add_pd(v01, _mm_mul_pd(_mm_cvtps_pd(f01), lc01));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(_mm_cvtps_pd(f2), lc2));
                } else {
                    for (i = 0; i < light; i++, cc += 3, cli += 3) {
                        v01 = _mm_add_pd(v01, _mm_mul_pd(load2f(cc), _mm_loadu_pd(cli)));
                        v2 = _mm_add_sd(v2,
                                        _mm_mul_sd(load1f(&cc[2]), _mm_load_sd(cli + 2)));
                    }
                    v01 = _mm_add_pd(v01, _mm_mul_pd(_mm_cvtps_pd(f01), lc01));
                    v2 = _mm_add_sd(v2, _mm_mul_sd(_mm_cvtps_pd(f2), lc2));
                    for (i++, cc += 3, cli += 3; i < nl; i++, cc += 3, cli += 3) {
                        v01 = _mm_add_pd(v01, _mm_mul_pd(load2f(cc), _mm_loadu_pd(cli)));
                        v2 = _mm_add_sd(v2,
                                        _mm_mul_sd(load1f(&cc[2]), _mm_load_sd(cli + 2)));
                    }
                }
                {
                    /* (combine_into's test, its squares in its order) */
                    __m128d sq = _mm_mul_pd(v01, v01);
                    sum = _mm_cvtsd_f64(_mm_add_sd(_mm_add_sd(sq, _mm_unpackhi_pd(sq, sq)),
                                                   _mm_mul_sd(v2, v2)));
                }
                if (!(sum <= (double)RTPI_SAMPLE_MAX * RTPI_SAMPLE_MAX))
                    combine_zero(s, cl, co, o); /* (combine_into's rule) */
                else
                    store3f(o, v01, v2);
            }
            if (mark)
                mark[k] = 1;
            combined++;
        }
#else
        if (comb) { /* the other samples' colours hold */
            if (with_rest) {
                /* the rest of the sum, then this light's term: as
                   rtpi_combine where the light is the last, else about
                   a float ulp from it; it serves where the sum is within
                   RTPI_SAMPLE_MAX */
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
                if (fabs(v0) + fabs(v1) + fabs(v2) <= RTPI_SAMPLE_MAX) {
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
#endif
    }
#ifdef SHADE_SSE2
    nonfinite |= _mm_movemask_pd(badv) & 1;
#endif
    *bad |= nonfinite;
    return combined;
}

unsigned long long rtpi_light_redo(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                   const uint64_t *start, size_t k0, size_t k1,
                                   const uint32_t *vis_ext, const float *nv, const double *w,
                                   size_t light, float *terms, float *coeffs, const double *cl,
                                   float *samples, int *bad, unsigned char *mark,
                                   double *rest, unsigned char *rest_ok, double *kc)
{
    const size_t s_nl = c->s->nlights;
    /* (scenes of up to 32 lights keep their bits in the nodes: compiled
       without the parallel words there, a test a node and a register
       less) */
    /* (a rest serves only where samples are combined: the copy with it
       takes samples for given) */
    if (!samples)
        rest = NULL;
    /* (one or two lights, so no kept rest (MV_REST_LIGHTS): copies of
       their own, the count a constant, the colour's sum written out and
       the strides constants; with the moved light's term from registers
       a lightbuf move went mount 189.02 -> 186.75 M, teapot 147.66 ->
       144.66, the copies' part of it 0.6-0.8 M) */
    if (!vis_ext) {
        if (rest)
            return light_redo(c, nodes, start, k0, k1, NULL, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, rest, rest_ok, kc, 1, 0, 0, 0);
        if (s_nl == 1)
            return light_redo(c, nodes, start, k0, k1, NULL, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, NULL, rest_ok, kc, 0, 0, 0, 1);
        if (s_nl == 2)
            return light_redo(c, nodes, start, k0, k1, NULL, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, NULL, rest_ok, kc, 0, 0, 0, 2);
        return light_redo(c, nodes, start, k0, k1, NULL, nv, w, light, terms, coeffs, cl,
                          samples, bad, mark, NULL, rest_ok, kc, 0, 0, 0, 0);
    }
    /* (a moved light's bits, up to 32 lights: a word a node, indexed
       by the node without a product a sample) */
    /* (no material with a highlight: a copy of its own, with the kept
       rest only (tree_s11, 7 lights: 108.30 -> 105.99 M a move); the copy
       without the rest (tetra, one light) came out 28.45 -> 28.80) */
    if (c->vis_words == 1 && kc && c->no_ks && rest)
        return light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                          samples, bad, mark, rest, rest_ok, kc, 1, 1, 1, 0);
    if (c->vis_words == 1) {
        if (rest)
            return light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, rest, rest_ok, kc, 1, 1, 0, 0);
        if (s_nl == 1)
            return light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, NULL, rest_ok, kc, 0, 1, 0, 1);
        if (s_nl == 2)
            return light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                              samples, bad, mark, NULL, rest_ok, kc, 0, 1, 0, 2);
        return light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                          samples, bad, mark, NULL, rest_ok, kc, 0, 1, 0, 0);
    }
    return rest ? light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                             samples, bad, mark, rest, rest_ok, kc, 1, 0, 0, 0)
                : light_redo(c, nodes, start, k0, k1, vis_ext, nv, w, light, terms, coeffs, cl,
                             samples, bad, mark, NULL, rest_ok, kc, 0, 0, 0, 0);
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
static RTPI_FORCE_INLINE void node_coeffs(const rtpi_material *m, const float *t, size_t nl,
                                          double w, double *acc, int ka)
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
    if (!(ka && m->ka_set)) {
        acc[3] += kc0; /* ambient: kd c_obj (ka follows kd) */
        acc[4] += kc1;
        acc[5] += kc2;
    } else {
        /* ambient: ka c_obj, as (w ka) c_obj the way kd's is (w kd) c_obj.
           The test only in the descents of a scene where some material
           has its own ka (ka: c->has_ka, a constant in each copy of
           coeffs_node and eval_node): a node's test had cost balls_s4's
           first evaluation 344.54 -> 346.49 M instructions */
        acc[3] += w * m->ka[0] * cobj[0];
        acc[4] += w * m->ka[1] * cobj[1];
        acc[5] += w * m->ka[2] * cobj[2];
    }
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
static void coeffs_node0(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                         const float *terms, double w, double *acc, double *wout);
static void coeffs_node1(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                         const float *terms, double w, double *acc, double *wout);

static RTPI_FORCE_INLINE void coeffs_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                          size_t idx, const float *terms, double w,
                                          double *acc, double *wout, int ka)
{
    const rtp_scene *s = c->s;
    const rtpi_cnode *nd = &nodes[idx];
    size_t nl = s->nlights;
    const rtpi_material *m = &s->mats[rtpi_prim_material(s, nd->prim)];
    double wr, wt;
    int k;
    if (wout)
        wout[idx] = w;
    node_coeffs(m, terms + idx * RTPI_TERMS(nl), nl, w, acc, ka);
    node_split(m, nd->link, &wr, &wt);
    if (wr > 0.0) {
        if (nd->link & RTPI_L_REFL)
            (ka ? coeffs_node1 : coeffs_node0)(c, nodes, idx + 1, terms, w * wr, acc, wout);
        else if (nd->link & RTPI_L_REFL_MISS)
            for (k = 0; k < 3; k++)
                acc[k] += w * wr;
    }
    if (wt > 0.0) {
        if (nd->link & RTPI_L_REFR)
            (ka ? coeffs_node1 : coeffs_node0)(c, nodes, idx + (nd->link >> RTPI_L_SHIFT),
                                               terms, w * wt, acc, wout);
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
static void coeffs_node0(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                         const float *terms, double w, double *acc, double *wout)
{
    coeffs_node(c, nodes, idx, terms, w, acc, wout, 0);
}

static void coeffs_node1(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                         const float *terms, double w, double *acc, double *wout)
{
    coeffs_node(c, nodes, idx, terms, w, acc, wout, 1);
}

static void eval_node0(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                       const uint32_t *vis_ext, rtpi_v3 from, float *terms, float *nv_out,
                       double w, int reached, double *acc, double *wout);
static void eval_node1(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                       const uint32_t *vis_ext, rtpi_v3 from, float *terms, float *nv_out,
                       double w, int reached, double *acc, double *wout);

static RTPI_FORCE_INLINE void eval_node(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                        size_t idx, const uint32_t *vis_ext, rtpi_v3 from,
                                        float *terms, float *nv_out, double w, int reached,
                                        double *acc, double *wout, int ka)
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
        node_coeffs(m, terms + idx * RTPI_TERMS(nl), nl, w, acc, ka);
        node_split(m, link, &wr, &wt);
    }
    /* (!(wr > 0.0): also NaN, as coeffs_node tests it) */
    if (link & RTPI_L_REFL)
        (ka ? eval_node1 : eval_node0)(c, nodes, idx + 1, vis_ext, p, terms, nv_out, w * wr,
                                       reached && wr > 0.0, acc, wout);
    else if (reached && wr > 0.0 && (link & RTPI_L_REFL_MISS))
        for (k = 0; k < 3; k++)
            acc[k] += w * wr;
    if (link & RTPI_L_REFR)
        (ka ? eval_node1 : eval_node0)(c, nodes, idx + (link >> RTPI_L_SHIFT), vis_ext, p,
                                       terms, nv_out, w * wt, reached && wt > 0.0, acc, wout);
    else if (reached && wt > 0.0 && (link & RTPI_L_REFR_MISS))
        for (k = 0; k < 3; k++)
            acc[k] += w * wt;
}

static void eval_node0(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                       const uint32_t *vis_ext, rtpi_v3 from, float *terms, float *nv_out,
                       double w, int reached, double *acc, double *wout)
{
    eval_node(c, nodes, idx, vis_ext, from, terms, nv_out, w, reached, acc, wout, 0);
}

static void eval_node1(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t idx,
                       const uint32_t *vis_ext, rtpi_v3 from, float *terms, float *nv_out,
                       double w, int reached, double *acc, double *wout)
{
    eval_node(c, nodes, idx, vis_ext, from, terms, nv_out, w, reached, acc, wout, 1);
}

int rtpi_scene_has_ka(const rtp_scene *s)
{
    size_t i;
    for (i = 0; i < s->nmats; i++)
        if (s->mats[i].ka_set)
            return 1;
    return 0;
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
        (c->has_ka ? coeffs_node1 : coeffs_node0)(c, nodes, 0, terms, 1.0, acc, w);
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
        (c->has_ka ? eval_node1 : eval_node0)(c, nodes, 0, vis_ext, eye, terms, nv, 1.0, 1, acc,
                                              w);
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
