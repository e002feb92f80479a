/* shade.c — the one shading routine.  It evaluates the paper's equation
 *   I = kd c_obj sum_{i in Omega} (n.l_i) c_li + ks sum_{i in Omega} (r_i.v)^n c_li
 *       + ks I_r + kt I_t + I_a
 * over a recorded ray tree.  It never casts a ray: the tree holds where
 * each ray hit and which lights each hit saw; the scene holds every optical
 * parameter.  Conventions (README.md, "Shading"): c_li is the light colour
 * times the scene's light scale; I_a = ambient * kd * c_obj. */
#include "internal.h"

static double fract_floor(double x) { return x - floor(x); }

static void image_lookup(const rtp_image *img, double u, double v,
                         double rgb[3])
{
    /* Bilinear, wrapping: uv (0,0) is the image's bottom-left corner as
       OBJ's vt convention has it. */
    double x = fract_floor(u) * img->width - 0.5;
    double y = (1.0 - fract_floor(v)) * img->height - 0.5;
    int x0 = (int)floor(x), y0 = (int)floor(y);
    double fx = x - x0, fy = y - y0;
    int c, dx, dy;
    for (c = 0; c < 3; c++)
        rgb[c] = 0.0;
    for (dy = 0; dy < 2; dy++) {
        for (dx = 0; dx < 2; dx++) {
            int xi = ((x0 + dx) % img->width + img->width) % img->width;
            int yi = ((y0 + dy) % img->height + img->height) % img->height;
            double w = (dx ? fx : 1.0 - fx) * (dy ? fy : 1.0 - fy);
            const float *px = img->pixels + 3 * ((size_t)yi * img->width + xi);
            for (c = 0; c < 3; c++)
                rgb[c] += w * px[c];
        }
    }
}

void rtpi_object_color(const rtp_scene *s, const rtpi_material *m,
                       const rtpi_node *node, double rgb[3])
{
    int c;
    if (m->tex == RTPI_TEX_CHECKER && m->tex_scale > 0.0f) {
        double inv = 1.0 / m->tex_scale;
        long parity = (long)floor(node->p.x * inv) + (long)floor(node->p.y * inv) +
                      (long)floor(node->p.z * inv);
        const float *src = (parity & 1) ? m->color2 : m->color;
        for (c = 0; c < 3; c++)
            rgb[c] = src[c];
        return;
    }
    if (m->tex == RTPI_TEX_IMAGE && m->tex_image < s->ntexs &&
        s->texs[m->tex_image].image) {
        image_lookup(s->texs[m->tex_image].image, node->uv[0], node->uv[1], rgb);
        for (c = 0; c < 3; c++)
            rgb[c] *= m->color[c];
        return;
    }
    for (c = 0; c < 3; c++)
        rgb[c] = m->color[c];
}

static void shade_node(const rtp_scene *s, const rtpi_tree *tree, int32_t idx,
                       double out[3])
{
    const rtpi_node *nd;
    const rtpi_material *m;
    double cobj[3], diff[3] = {0, 0, 0}, spec[3] = {0, 0, 0}, sub[3];
    size_t i;
    int c;

    if (idx < 0) {
        for (c = 0; c < 3; c++)
            out[c] = idx == RTPI_CHILD_MISS ? s->background[c] : 0.0;
        return;
    }
    nd = &tree->nodes[idx];
    m = &s->mats[nd->mat];
    rtpi_object_color(s, m, nd, cobj);

    for (i = 0; i < s->nlights; i++) {
        const rtpi_light *L = &s->lights[i];
        rtpi_v3 l;
        double ndl, rv, w;
        if (!L->on || !(tree->vis[(nd->vis + i) >> 3] & (1u << ((nd->vis + i) & 7))))
            continue;
        l = v3_norm(v3_sub(v3(L->pos[0], L->pos[1], L->pos[2]), nd->p));
        ndl = v3_dot(nd->n, l);
        if (ndl <= 0.0)
            continue;
        /* r_i: l mirrored about n; the highlight is (r_i.v)^shine. */
        rv = v3_dot(v3_sub(v3_mul(nd->n, 2.0 * ndl), l), nd->v);
        w = (rv > 0.0 && m->ks > 0.0f) ? pow(rv, m->shine) : 0.0;
        for (c = 0; c < 3; c++) {
            double cl = L->color[c] * s->light_scale;
            diff[c] += ndl * cl;
            spec[c] += w * cl;
        }
    }
    for (c = 0; c < 3; c++)
        out[c] = m->kd * cobj[c] * (diff[c] + s->ambient[c]) + m->ks * spec[c];
    if (nd->refl != RTPI_CHILD_NONE && m->ks > 0.0f) {
        shade_node(s, tree, nd->refl, sub);
        for (c = 0; c < 3; c++)
            out[c] += m->ks * sub[c];
    }
    if (nd->refr != RTPI_CHILD_NONE && m->kt > 0.0f) {
        shade_node(s, tree, nd->refr, sub);
        for (c = 0; c < 3; c++)
            out[c] += m->kt * sub[c];
    }
}

void rtpi_shade_tree(const rtp_scene *s, const rtpi_tree *tree, double rgb[3])
{
    shade_node(s, tree, tree->root, rgb);
}
