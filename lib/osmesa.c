/* osmesa.c — the item buffer drawn by OpenGL through OSMesa (off-screen
 * Mesa), only in builds with OSMESA=1 (RTP_HAVE_OSMESA). */
#include "dircube.h"

#if !defined(RTP_HAVE_OSMESA)

rtp_status rtpi_itembuf_build_osmesa_wide(const rtp_scene *s, rtpi_v3 light, int res,
                                          double cells, unsigned char *thin,
                                          const rtp_allocator *a, rtpi_itembuf *ib,
                                          rtp_error *err)
{
    (void)s;
    (void)light;
    (void)res;
    (void)cells;
    (void)thin;
    (void)a;
    memset(ib, 0, sizeof *ib);
    return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                      "osmesa shadows: this build has no OSMesa (rebuild with "
                      "make OSMESA=1 and libosmesa6-dev); use itembuf for the "
                      "same item buffer in software");
}

#else

#include <GL/gl.h>
#include <GL/osmesa.h>
#ifdef RTP_HAVE_THREADS
#include <pthread.h>
#endif

#define OSM_PI 3.14159265358979323846
#define OSM_2M24 (1.0 / 16777216.0) /* a step of the 24-bit depth buffer */
#define OSM_DEPTH_STEP 1e-5         /* the largest step, of the extent */

/* One face being drawn: vertices go to OpenGL in eye coordinates sheared
   so that the window's centre lies on the axis, and with the depth taken
   from the bounds' nearest depth zb, (x - uc z, y - vc z, zb - z): the
   numbers OpenGL rounds to float are then of the scene's size, not of the
   distance from a far light (osm_projection puts zb back).  Depth at the
   light's full distance was rounded to float first: 0.125 apart at
   1.7e6, where the software buffer told primitives 0.05 apart. */
typedef struct osm_face {
    int f;
    double uc, vc;
    double ua, ub, va, vb; /* the window */
    double zb;
    rtpi_v3 L;
} osm_face;

static void osm_vertex(const osm_face *fc, rtpi_v3 p)
{
    double q[3], x, y, z;
    int a = fc->f >> 1;
    q[0] = p.x - fc->L.x;
    q[1] = p.y - fc->L.y;
    q[2] = p.z - fc->L.z;
    x = q[(a + 1) % 3];
    y = q[(a + 2) % 3];
    z = (fc->f & 1) ? -q[a] : q[a];
    glVertex3f((GLfloat)(x - fc->uc * z), (GLfloat)(y - fc->vc * z), (GLfloat)(fc->zb - z));
}

/* The projection of glFrustum(-hu zn, hu zn, -hv zn, hv zn, zn, zf) after
   a translation of the eye depth by -zb, made in double and loaded whole
   (glFrustum then glTranslated multiply in float, where the depth row's
   two terms of ~zb^2 / extent cancel: an offset of 1e4 at zb = 1e6):
   clip z = A Z + C and w = zb - Z for the vertex depth Z = zb - z, with
   C = (zb (N - F) + 2 F N) / (F + N), F = zf - zb, N = zb - zn. */
static void osm_projection(double hu, double hv, double zn, double zf, double zb)
{
    double m[16], F = zf - zb, N = zb - zn;
    memset(m, 0, sizeof m);
    m[0] = 1.0 / hu;
    m[5] = 1.0 / hv;
    m[10] = -(zf + zn) / (zf - zn);
    m[11] = -1.0;
    m[14] = (zb * (N - F) + 2.0 * F * N) / (F + N);
    m[15] = zb;
    glMatrixMode(GL_PROJECTION);
    glLoadMatrixd(m);
}

/* Colour id: prim + 1 in 24 bits of RGB; 0 is the empty background. */
static void osm_color(uint32_t prim)
{
    uint32_t c = prim + 1u;
    glColor4ub((GLubyte)(c & 0xffu), (GLubyte)((c >> 8) & 0xffu), (GLubyte)((c >> 16) & 0xffu),
               255);
}

static void osm_basis(rtpi_v3 n, rtpi_v3 *e1, rtpi_v3 *e2)
{
    double sg = n.z >= 0.0 ? 1.0 : -1.0;
    double a = -1.0 / (sg + n.z);
    double b = n.x * n.y * a;
    *e1 = v3(1.0 + sg * n.x * n.x * a, sg * b, -sg * n.x);
    *e2 = v3(b, sg + n.y * n.y * a, -n.y);
}

/* Segments around a circle of radius r at distance d from the light so
   that the polygon strays from the circle by under ~1/32 cell
   (r (1 - cos(pi/N)) ~ r pi^2 / 2N^2): silhouettes, and the curves where
   a cylinder meets a sphere at a small angle, then land in the cells the
   exact software buffer puts them in. */
static int osm_segments(double r, double d, double cell)
{
    double rc = d > 0.0 ? r / d / cell : 1e9; /* radius in cells */
    double n = ceil(OSM_PI * sqrt(16.0 * (rc > 0.0 ? rc : 0.0)));
    return n < 8.0 ? 8 : n > 2048.0 ? 2048 : (int)n;
}

/* The part of a sphere the item buffer holds: from a light outside, the
   cap facing it (up to the tangent circle, which then is exact up to the
   polygon), for both signs of r (see dircube.c); from inside, all of it.
   Vertices sit at r (1 + delta / 2) from the centre, delta = 1 - cos of
   half the largest angle between neighbours: an inscribed polygon's
   facets lie up to r delta inside the sphere, these straddle it (about
   r delta / 2 either way), which about halves the cells along the
   outline, and where a sphere meets another surface at a small angle,
   that OpenGL decides otherwise than the exact software buffer. */
static void osm_sphere(const osm_face *fc, const rtpi_sphere *sp, double cell)
{
    rtpi_v3 c = v3_from_f(sp->c), w, e1, e2;
    double r = fabs((double)sp->r), D, th_max, rs;
    int n, m, i, k;
    w = v3_sub(fc->L, c);
    D = v3_len(w);
    w = D > 0.0 ? v3_mul(w, 1.0 / D) : v3(0.0, 0.0, 1.0);
    osm_basis(w, &e1, &e2);
    th_max = D > r ? acos(r / D) : OSM_PI;
    n = osm_segments(r, D > r ? D - r : r, cell);
    m = n / 4 < 4 ? 4 : n / 4;
    if (D <= r)
        m *= 2;
    {
        double half = fmax(OSM_PI / n, 0.5 * th_max / m);
        rs = r * (1.0 + 0.5 * (1.0 - cos(half)));
    }
    glBegin(GL_TRIANGLES);
    for (i = 0; i < m; i++) {
        double t0 = th_max * i / m, t1 = th_max * (i + 1) / m;
        for (k = 0; k < n; k++) {
            double p0 = 2.0 * OSM_PI * k / n, p1 = 2.0 * OSM_PI * (k + 1) / n;
            rtpi_v3 q[4];
            double tt[4], pp[4];
            int j;
            tt[0] = t0; pp[0] = p0;
            tt[1] = t1; pp[1] = p0;
            tt[2] = t1; pp[2] = p1;
            tt[3] = t0; pp[3] = p1;
            for (j = 0; j < 4; j++) {
                rtpi_v3 d = v3_madd(v3_madd(v3_mul(w, cos(tt[j])), e1, sin(tt[j]) * cos(pp[j])),
                                    e2, sin(tt[j]) * sin(pp[j]));
                q[j] = v3_madd(c, d, rs);
            }
            osm_vertex(fc, q[0]);
            osm_vertex(fc, q[1]);
            osm_vertex(fc, q[2]);
            osm_vertex(fc, q[0]);
            osm_vertex(fc, q[2]);
            osm_vertex(fc, q[3]);
        }
    }
    glEnd();
}

/* One quad of an open cone between the generator lines at angles p0 and
   p1, at s0 and s1 times the cone's radii (planar: they meet at the
   apex). */
static void osm_cone_quad(const osm_face *fc, rtpi_v3 b, rtpi_v3 a, rtpi_v3 e1, rtpi_v3 e2,
                          double rb, double ra, double p0, double s0, double p1, double s1)
{
    rtpi_v3 d0 = v3_mul(v3_madd(v3_mul(e1, cos(p0)), e2, sin(p0)), s0);
    rtpi_v3 d1 = v3_mul(v3_madd(v3_mul(e1, cos(p1)), e2, sin(p1)), s1);
    rtpi_v3 q0 = v3_madd(b, d0, rb), q1 = v3_madd(b, d1, rb);
    rtpi_v3 q2 = v3_madd(a, d1, ra), q3 = v3_madd(a, d0, ra);
    osm_vertex(fc, q0);
    osm_vertex(fc, q1);
    osm_vertex(fc, q2);
    osm_vertex(fc, q0);
    osm_vertex(fc, q2);
    osm_vertex(fc, q3);
}

/* An open cone, its generator lines at most 2 pi / n apart.  The
   polygons are inscribed, so a tessellation at even angles draws the
   cone's outline up to r (1 - cos(pi / n)) inside the true one, which
   decided about 1 cell in 16 along the outlines of rings' thin
   cylinders at 256 cells differently from the exact software buffer.
   The outline, seen from L, is the two generators where the surface
   turns from facing L to facing away: with u(phi) = cos phi e1 +
   sin phi e2 and the normal along a generator proportional to h u -
   (ra - rb) w, its plane holds L where

       u(phi) . (L - b) = rb + (ra - rb) / h ((L - b) . w)

   (independent of the point on the generator), that is rho cos(phi -
   phi0) = c with rho, phi0 the polar form of L - b in e1, e2.  Those
   two generators are made vertices: the outline of the polygons is then
   the cone's own (no generator of an inscribed polygon passes beyond
   the tangent plane through one on the surface).  Where |c| >= rho
   (L inside the cone's extension: every generator faces L, or none),
   there is no outline, and the angles are even.  The other generators
   are drawn at 1 + delta / 2 times the radii (delta = 1 - cos of half
   their step), as osm_sphere's vertices, so that where a cylinder meets
   a sphere of its own radius (rings' joints: tangent along a circle)
   both straddle their surfaces alike; they stay inside the outline's
   tangent planes (in each cross-section a vertex at angle s from the
   tangent point lies (1 + delta / 2) cos s <= 1 radii along it). */
static void osm_cone(const osm_face *fc, const rtpi_cone *cn, double cell)
{
    rtpi_v3 b = v3_from_f(cn->base), a = v3_from_f(cn->apex), w, e1, e2, lb;
    double rb = fabs((double)cn->rb), ra = fabs((double)cn->ra), h, d, rho, c, p0 = 0.0;
    double arc[2] = {2.0 * OSM_PI, 0.0};
    int n, k, j, outline = 0;
    w = v3_sub(a, b);
    h = v3_len(w);
    if (!(h > 0.0))
        return;
    w = v3_mul(w, 1.0 / h);
    osm_basis(w, &e1, &e2);
    d = fmin(v3_len(v3_sub(b, fc->L)), v3_len(v3_sub(a, fc->L)));
    n = osm_segments(rb > ra ? rb : ra, d > 0.0 ? d : 1e-30, cell);
    lb = v3_sub(fc->L, b);
    rho = hypot(v3_dot(lb, e1), v3_dot(lb, e2));
    c = rb + (ra - rb) / h * v3_dot(lb, w);
    if (rho > 0.0 && fabs(c) < rho) {
        double al = acos(c / rho); /* (0, pi): the arc facing L is 2 al */
        p0 = atan2(v3_dot(lb, e2), v3_dot(lb, e1)) - al;
        arc[0] = 2.0 * al;
        arc[1] = 2.0 * OSM_PI - arc[0];
        outline = 1;
    }
    glBegin(GL_TRIANGLES);
    for (j = 0; j < 2; j++) {
        /* each arc in as many even steps as keep them within 2 pi / n */
        int m = (int)ceil(arc[j] * n / (2.0 * OSM_PI));
        double step, sc;
        if (m < 1) {
            if (!(arc[j] > 0.0))
                continue;
            m = 1;
        }
        step = arc[j] / m;
        sc = 1.0 + 0.5 * (1.0 - cos(0.5 * step));
        for (k = 0; k < m; k++)
            osm_cone_quad(fc, b, a, e1, e2, rb, ra, p0 + step * k, outline && k == 0 ? 1.0 : sc,
                          k + 1 == m ? p0 + arc[j] : p0 + step * (k + 1),
                          outline && k + 1 == m ? 1.0 : sc);
        p0 += arc[j];
    }
    glEnd();
}

/* Is the box lo..hi wholly outside the face's window (all corners beyond
   one of its four planes)? */
static int osm_culled(const osm_face *fc, const double lo[3], const double hi[3])
{
    int plane, k;
    for (plane = 0; plane < 4; plane++) {
        int out = 1;
        for (k = 0; k < 8 && out; k++) {
            double q[3], x, y, z, e;
            int a = fc->f >> 1;
            q[0] = ((k & 1) ? hi[0] : lo[0]) - fc->L.x;
            q[1] = ((k & 2) ? hi[1] : lo[1]) - fc->L.y;
            q[2] = ((k & 4) ? hi[2] : lo[2]) - fc->L.z;
            x = q[(a + 1) % 3];
            y = q[(a + 2) % 3];
            z = (fc->f & 1) ? -q[a] : q[a];
            e = plane == 0 ? x - fc->ua * z : plane == 1 ? fc->ub * z - x
              : plane == 2 ? y - fc->va * z : fc->vb * z - y;
            out = e < 0.0;
        }
        if (out)
            return 1;
    }
    return 0;
}

static void osm_draw(const osm_face *fc, const rtp_scene *s, double cell,
                     const unsigned char *soft, const unsigned char *thin)
{
    size_t i, n = rtpi_scene_nprims(s);
    for (i = 0; i < n; i++) {
        uint32_t prim = (uint32_t)i;
        double lo[3], hi[3];
        if (soft[i] || (thin && thin[i]) || !rtpi_itembuf_renders(s, prim, fc->L))
            continue;
        rtpi_prim_bounds(s, prim, lo, hi);
        if (osm_culled(fc, lo, hi))
            continue; /* not on this face: spare OpenGL the triangles */
        osm_color(prim);
        if (i < s->ntris) {
            const rtpi_tri *t = &s->tris[i];
            glBegin(GL_TRIANGLES);
            osm_vertex(fc, v3_from_f(s->pos + 3 * (size_t)t->v[0]));
            osm_vertex(fc, v3_from_f(s->pos + 3 * (size_t)t->v[1]));
            osm_vertex(fc, v3_from_f(s->pos + 3 * (size_t)t->v[2]));
            glEnd();
        } else if (i < s->ntris + s->nspheres) {
            osm_sphere(fc, &s->spheres[i - s->ntris], cell);
        } else {
            osm_cone(fc, &s->cones[i - s->ntris - s->nspheres], cell);
        }
    }
}

/* What osm_render draws with, and how it ended. */
enum { OSM_OK, OSM_NO_CONTEXT, OSM_SMALL_VIEWPORT };
typedef struct osm_job {
    const rtp_scene *s;
    rtpi_v3 light;
    rtpi_itembuf *ib;
    int res;
    unsigned char *rgba;
    float *depth;
    const unsigned char *soft, *thin;
    const double *znear, *zfar;
    size_t n, npix;
    int status, max_dim;
} osm_job;

/* The six faces through an OSMesa context made, bound and destroyed
   here, on the thread that runs it (a pthread start routine). */
static void *osm_render(void *arg)
{
    osm_job *j = (osm_job *)arg;
    const rtp_scene *s = j->s;
    const rtpi_v3 light = j->light;
    rtpi_itembuf *ib = j->ib;
    const int res = j->res;
    unsigned char *rgba = j->rgba;
    float *depth = j->depth;
    const unsigned char *soft = j->soft, *thin = j->thin;
    const double *znear = j->znear, *zfar = j->zfar;
    const size_t n = j->n, npix = j->npix;
    OSMesaContext ctx;
    GLint dims[2] = {0, 0};
    size_t k;
    int f;
    ctx = OSMesaCreateContextExt(OSMESA_RGBA, 24, 0, 0, NULL);
    if (!ctx || !OSMesaMakeCurrent(ctx, rgba, GL_UNSIGNED_BYTE, res, res)) {
        if (ctx)
            OSMesaDestroyContext(ctx);
        j->status = OSM_NO_CONTEXT;
        return NULL;
    }
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, dims);
    if (dims[0] < res || dims[1] < res) {
        OSMesaMakeCurrent(NULL, NULL, 0, 0, 0);
        OSMesaDestroyContext(ctx);
        j->status = OSM_SMALL_VIEWPORT;
        j->max_dim = (int)dims[0];
        return NULL;
    }
    /* Ids, not colours: nothing may blend, dither or smooth them. */
    glDisable(GL_LIGHTING);
    glDisable(GL_DITHER);
    glDisable(GL_BLEND);
    glDisable(GL_LINE_SMOOTH);
    glDisable(GL_POLYGON_SMOOTH);
    glDisable(GL_MULTISAMPLE);
    glDisable(GL_CULL_FACE); /* primitives are hit from both sides */
    glDisable(GL_FOG);
    glDisable(GL_TEXTURE_2D);
    glShadeModel(GL_FLAT);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glViewport(0, 0, res, res);
    glClearColor(0.0f, 0.0f, 0.0f, 0.0f);
    glClearDepth(1.0);
    for (f = 0; f < 6; f++) {
        osm_face fc;
        double hu = 0.5 * res * ib->w.du[f], hv = 0.5 * res * ib->w.dv[f];
        double zn = znear[f], zf = zfar[f], cell = fmin(ib->w.du[f], ib->w.dv[f]);
        size_t base = ib->w.fbase[f];
        if (base == RTPI_DC_ABSENT)
            continue;
        fc.f = f;
        fc.L = light;
        fc.uc = ib->w.u0[f] + hu;
        fc.vc = ib->w.v0[f] + hv;
        fc.ua = ib->w.u0[f];
        fc.ub = ib->w.u0[f] + 2.0 * hu;
        fc.va = ib->w.v0[f];
        fc.vb = ib->w.v0[f] + 2.0 * hv;
        fc.zb = ib->w.zbase[f];
        /* (24-bit depths: a quantum of the extent, IB_BIAS's 1e-4 of it
           as before, rtpi_itembuf_visible) */
        ib->zq[f] = 1e-4 * ib->w.zext[f];
        osm_projection(hu, hv, zn, zf, fc.zb);
        glMatrixMode(GL_MODELVIEW);
        glLoadIdentity();
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        osm_draw(&fc, s, cell, soft, thin);
        glFinish();
        glReadPixels(0, 0, res, res, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
        glReadPixels(0, 0, res, res, GL_DEPTH_COMPONENT, GL_FLOAT, depth);
        /* OSMesa's rows run bottom-up (OSMESA_Y_UP): row j is v0 + j dv,
           as in the software buffer. */
        for (k = 0; k < npix; k++) {
            uint32_t id = (uint32_t)rgba[4 * k] | (uint32_t)rgba[4 * k + 1] << 8 |
                          (uint32_t)rgba[4 * k + 2] << 16;
            if (id == 0u || id > n)
                continue;
            {
                double dz = depth[k];
                double z = zn * zf / (zf - dz * (zf - zn)); /* window depth -> eye */
                ib->id[base + k] = id - 1u;
                ib->z[base + k] = (float)(z - ib->w.zbase[f]);
            }
        }
    }
    OSMesaMakeCurrent(NULL, NULL, 0, 0, 0);
    OSMesaDestroyContext(ctx);
    j->status = OSM_OK;
    return NULL;
}

rtp_status rtpi_itembuf_build_osmesa_wide(const rtp_scene *s, rtpi_v3 light, int res,
                                          double cells, unsigned char *thin,
                                          const rtp_allocator *a, rtpi_itembuf *ib,
                                          rtp_error *err)
{
    unsigned char *rgba = NULL, *soft = NULL;
    float *depth = NULL;
    double *pdist = NULL, znear[6], zfar[6], znmax = 0.0;
    size_t nsoft = 0;
    size_t npix, k, n = rtpi_scene_nprims(s);
    double dmin = HUGE_VAL;
    rtp_status st = RTP_OK;
    int f;
    /* (ids prim + 1, 1 to 2^24 - 1: 16,777,215 primitives fit; the test
       said >= and refused that many) */
    if (n > 0xffffffu)
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "osmesa shadows: %lu primitives do not fit 24-bit colour ids (at "
                          "most 16777215): use itembuf, the same item buffer in software",
                          (unsigned long)n);
    st = rtpi_itembuf_alloc(ib, s, light, res, a, err);
    if (st != RTP_OK)
        return st;
    res = ib->res;
    if (thin)
        rtpi_itembuf_thin(ib, s, cells, thin);
    npix = (size_t)res * (size_t)res;
    rgba = (unsigned char *)rtpi_malloc_array(a, npix, 4);
    depth = (float *)rtpi_malloc_array(a, npix, sizeof *depth);
    soft = (unsigned char *)rtpi_malloc_array(a, n ? n : 1, 1);
    pdist = (double *)rtpi_malloc_array(a, n ? n : 1, sizeof *pdist);
    if (!rgba || !depth || !soft || !pdist) {
        rtpi_free(a, rgba);
        rtpi_free(a, depth);
        rtpi_free(a, soft);
        rtpi_free(a, pdist);
        rtpi_itembuf_free(ib, a);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the item buffer");
    }
    /* The near plane must stay in front of everything: the nearest
       primitive's distance bounds every depth on every face from below
       (depth >= distance / sqrt(3)). */
    for (k = 0; k < n; k++) {
        double lo[3], hi[3], d2 = 0.0;
        int c;
        rtpi_prim_bounds(s, (uint32_t)k, lo, hi);
        for (c = 0; c < 3; c++) {
            double x = v3_get(light, c);
            double e = x < lo[c] ? lo[c] - x : x > hi[c] ? x - hi[c] : 0.0;
            d2 += e * e;
        }
        pdist[k] = sqrt(d2);
        if (rtpi_itembuf_renders(s, (uint32_t)k, light) && pdist[k] > 0.0)
            dmin = fmin(dmin, pdist[k]);
    }
    /* Near and far planes hug the scene's depths on each face (1e-3 of
       its extent outside them, for rounding), so the 24-bit depth buffer
       resolves ~1e-7 of that extent near the front. */
    for (f = 0; f < 6; f++) {
        double zn = ib->w.zbase[f] - 1e-3 * ib->w.zext[f], zf, zres, ze = ib->w.zext[f];
        int cut = ib->w.zbase[f] == 0.0;
        if (!(zn > 0.0))
            zn = dmin / sqrt(3.0) * 0.5;
        if (!(zn > 1e-6 * ze))
            zn = 1e-6 * ze;
        /* (just past the bounds: a far plane at 2 zbase, as it was,
           spent the depth buffer's resolution on empty space, 0.03 apart
           at 1e6) */
        zf = cut ? ze * sqrt(3.0) * (1.0 + 1e-3) + zn : ib->w.zbase[f] + ze * (1.0 + 1e-3);
        /* The depth buffer's step at the far plane, 2^-24 (zf - zn) zf /
           zn, at most OSM_DEPTH_STEP of the extent (IB_BIAS, what the
           item buffer takes as "in front", is 1e-4 of it): a primitive
           1e-6 from the light had put the near plane at 1e-5, the steps
           at the far side at 0.5, and a plate 0.02 over a floor 10 away
           lost to it: the shadow under the plate was gone (23 dB).  A
           nearer near plane is moved out, and what it may cut is drawn
           in software (soft, below). */
        zres = OSM_2M24 * zf * zf / (OSM_DEPTH_STEP * ze + OSM_2M24 * zf);
        if (zn < zres) {
            zn = zres;
            cut = 1;
            if (ib->w.zbase[f] == 0.0)
                zf = ze * sqrt(3.0) * (1.0 + 1e-3) + zn;
        }
        znear[f] = zn;
        zfar[f] = zf;
        if (cut)
            znmax = fmax(znmax, zn);
    }
    /* With the light outside the bounds every primitive lies behind the
       near planes unless one was moved out for the depth buffer's sake.
       Inside them (or past such a plane), a primitive nearer the light than
       2 sqrt(3) znmax (depth >= distance / sqrt 3, and a factor of 2) may
       reach in front of a near plane and be cut: the software z-buffer
       draws those after OpenGL, into the same cells. */
    for (k = 0; k < n; k++) {
        soft[k] = (unsigned char)(rtpi_itembuf_renders(s, (uint32_t)k, light) &&
                                  !(thin && thin[k]) && pdist[k] < 2.0 * sqrt(3.0) * znmax);
        nsoft += soft[k];
    }
    {
        osm_job job;
        int started = 0;
        job.s = s;
        job.light = light;
        job.ib = ib;
        job.res = res;
        job.rgba = rgba;
        job.depth = depth;
        job.soft = soft;
        job.thin = thin;
        job.znear = znear;
        job.zfar = zfar;
        job.n = n;
        job.npix = npix;
        job.status = OSM_NO_CONTEXT;
        job.max_dim = 0;
#ifdef RTP_HAVE_THREADS
        /* OpenGL's current context is the calling thread's: bound and
           unbound here, it took the caller's own away (a host drawing
           with Mesa, EGL or OSMesa found nothing bound after a move).  A
           thread of its own leaves the caller's binding alone. */
        {
            pthread_t tid;
            if (pthread_create(&tid, NULL, osm_render, &job) == 0) {
                pthread_join(tid, NULL);
                started = 1;
            }
        }
#endif
        if (!started)
            osm_render(&job); /* (builds without threads: see rtp.h) */
        if (job.status != OSM_OK) {
            rtpi_free(a, rgba);
            rtpi_free(a, depth);
            rtpi_free(a, soft);
            rtpi_free(a, pdist);
            rtpi_itembuf_free(ib, a);
            if (job.status == OSM_SMALL_VIEWPORT && job.max_dim <= 0)
                /* (no answer at all: the calls went to another OpenGL,
                   a GLVND libGL loaded first, with nothing bound there) */
                return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                                  "osmesa shadows: OpenGL calls do not reach the OSMesa "
                                  "context (another libGL loaded before libOSMesa?); "
                                  "itembuf makes the same item buffer in software");
            if (job.status == OSM_SMALL_VIEWPORT)
                return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                                  "osmesa shadows: resolution %d above OpenGL's %d", res,
                                  job.max_dim);
            return rtpi_error(err, RTP_ERR_UNSUPPORTED, NULL, 0, 0,
                              "osmesa shadows: cannot make a %dx%d OSMesa context", res, res);
        }
    }
    rtpi_free(a, rgba);
    rtpi_free(a, depth);
    if (nsoft) {
        /* the primitives OpenGL's near plane would cut, in software */
        uint32_t *list = (uint32_t *)rtpi_malloc_array(a, nsoft, sizeof *list);
        size_t m = 0;
        if (list) {
            for (k = 0; k < n; k++)
                if (soft[k])
                    list[m++] = (uint32_t)k;
            st = rtpi_itembuf_draw(ib, s, list, m, a);
        }
        rtpi_free(a, list);
        if (!list || st != RTP_OK) {
            rtpi_free(a, soft);
            rtpi_free(a, pdist);
            rtpi_itembuf_free(ib, a);
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "out of memory for the item buffer");
        }
    }
    rtpi_free(a, soft);
    rtpi_free(a, pdist);
    return RTP_OK;
}

#endif

/* (one for both builds: each branch had its own copy) */
rtp_status rtpi_itembuf_build_osmesa(const rtp_scene *s, rtpi_v3 light,
                                     int res, const rtp_allocator *a,
                                     rtpi_itembuf *ib, rtp_error *err)
{
    return rtpi_itembuf_build_osmesa_wide(s, light, res, 0.0, NULL, a, ib, err);
}
