/* scene.c — the scene object: creation, appending from readers, loading
 * by file type, and the parameter keys of `--set`. */
#include "internal.h"

#include <ctype.h>
#include <errno.h>
#include <float.h>
#include <stdio.h>
#include <stdlib.h>

void rtpi_material_default(rtpi_material *m)
{
    memset(m, 0, sizeof *m);
    m->color[0] = m->color[1] = m->color[2] = 1.0f;
    m->kd = 1.0f;
    m->shine = 100000.0f; /* SPD's "no highlight" */
    m->ior = 1.0f;
    m->tex_scale = 1.0f;
    m->bump_scale = 1.0f;
    m->tex_image = RTPI_NONE;
    m->bump_image = RTPI_NONE;
}

rtp_status rtpi_scene_create(const rtp_allocator *alloc, rtp_scene **out)
{
    rtp_allocator a;
    rtp_scene *s;
    rtpi_allocator_init(&a, alloc);
    s = (rtp_scene *)rtpi_malloc(&a, sizeof *s);
    if (!s)
        return RTP_ERR_NOMEM;
    memset(s, 0, sizeof *s);
    s->alloc = a;
    /* NFF defaults: camera at +z looking at the origin, 45 degrees. */
    s->camera.from[2] = 1.0;
    s->camera.up[1] = 1.0;
    s->camera.angle = 45.0;
    s->width = s->height = 512;
    s->light_scale = 1.0;
    s->ambient[0] = -1.0f; /* unset: a default follows the lights */
    *out = s;
    return RTP_OK;
}

void rtp_scene_destroy(rtp_scene *s)
{
    size_t i;
    rtp_allocator a;
    if (!s)
        return;
    a = s->alloc;
    for (i = 0; i < s->nmats; i++)
        rtpi_free(&a, s->mats[i].name);
    for (i = 0; i < s->nlights; i++)
        rtpi_free(&a, s->lights[i].name);
    for (i = 0; i < s->ntexs; i++) {
        rtpi_free(&a, s->texs[i].path);
        rtpi_texture_release(&s->texs[i]);
    }
    for (i = 0; i < s->nfiles; i++)
        rtpi_free(&a, s->files[i]);
    rtpi_free(&a, s->files);
    rtpi_free(&a, s->pos);
    rtpi_free(&a, s->nrm);
    rtpi_free(&a, s->uv);
    rtpi_free(&a, s->tris);
    rtpi_free(&a, s->spheres);
    rtpi_free(&a, s->cones);
    rtpi_free(&a, s->cframes);
    rtpi_free(&a, s->pbounds);
    rtpi_free(&a, s->phit);
    rtpi_free(&a, s->mats);
    rtpi_free(&a, s->lights);
    rtpi_free(&a, s->texs);
    rtpi_free(&a, s);
}

#define GROW(s, arr, n, cap)                                                 \
    rtpi_grow(&(s)->alloc, (void **)&(s)->arr, &(s)->cap, (s)->n + 1,        \
              sizeof *(s)->arr)

int rtpi_scene_add_file(rtp_scene *s, const char *path)
{
    char *p = rtpi_strdup(&s->alloc, path);
    if (!p || GROW(s, files, nfiles, cap_files)) {
        rtpi_free(&s->alloc, p);
        return -1;
    }
    s->files[s->nfiles++] = p;
    return 0;
}

int rtpi_scene_add_pos(rtp_scene *s, double x, double y, double z)
{
    float *p;
    if (s->npos >= RTPI_NONE - 1 ||
        rtpi_grow(&s->alloc, (void **)&s->pos, &s->cap_pos, (s->npos + 1) * 3,
                  sizeof *s->pos))
        return -1;
    p = s->pos + 3 * s->npos++;
    p[0] = (float)x;
    p[1] = (float)y;
    p[2] = (float)z;
    return 0;
}

int rtpi_scene_add_nrm(rtp_scene *s, double x, double y, double z)
{
    float *p;
    if (s->nnrm >= RTPI_NONE - 1 ||
        rtpi_grow(&s->alloc, (void **)&s->nrm, &s->cap_nrm, (s->nnrm + 1) * 3,
                  sizeof *s->nrm))
        return -1;
    p = s->nrm + 3 * s->nnrm++;
    p[0] = (float)x;
    p[1] = (float)y;
    p[2] = (float)z;
    return 0;
}

int rtpi_scene_add_uv(rtp_scene *s, double u, double v)
{
    float *p;
    if (s->nuv >= RTPI_NONE - 1 ||
        rtpi_grow(&s->alloc, (void **)&s->uv, &s->cap_uv, (s->nuv + 1) * 2,
                  sizeof *s->uv))
        return -1;
    p = s->uv + 2 * s->nuv++;
    p[0] = (float)u;
    p[1] = (float)v;
    return 0;
}

/* Primitive ids must stay below RTPI_NONE. */
static int prim_room(const rtp_scene *s)
{
    return rtpi_scene_nprims(s) < (size_t)RTPI_NONE - 1;
}

int rtpi_scene_add_tri(rtp_scene *s, const rtpi_tri *t)
{
    if (!prim_room(s) || GROW(s, tris, ntris, cap_tris))
        return -1;
    s->tris[s->ntris++] = *t;
    return 0;
}

int rtpi_scene_add_sphere(rtp_scene *s, const rtpi_sphere *sp)
{
    if (!prim_room(s) || GROW(s, spheres, nspheres, cap_spheres))
        return -1;
    s->spheres[s->nspheres++] = *sp;
    return 0;
}

int rtpi_scene_add_cone(rtp_scene *s, const rtpi_cone *c)
{
    if (!prim_room(s) || GROW(s, cones, ncones, cap_cones) ||
        GROW(s, cframes, ncones, cap_cframes))
        return -1;
    rtpi_cone_frame_of(c, &s->cframes[s->ncones]);
    s->cones[s->ncones++] = *c;
    return 0;
}

int rtpi_scene_cone_frames(rtp_scene *s)
{
    size_t i;
    if (s->ncones &&
        rtpi_grow(&s->alloc, (void **)&s->cframes, &s->cap_cframes, s->ncones,
                  sizeof *s->cframes))
        return -1;
    for (i = 0; i < s->ncones; i++)
        rtpi_cone_frame_of(&s->cones[i], &s->cframes[i]);
    return 0;
}

long rtpi_scene_add_material(rtp_scene *s, const rtpi_material *m)
{
    if (s->nmats >= 0x7fffffff || GROW(s, mats, nmats, cap_mats))
        return -1;
    s->mats[s->nmats] = *m;
    return (long)s->nmats++;
}

long rtpi_scene_add_light(rtp_scene *s, const rtpi_light *l)
{
    if (s->nlights >= 0x7fffffff || GROW(s, lights, nlights, cap_lights))
        return -1;
    s->lights[s->nlights] = *l;
    return (long)s->nlights++;
}

long rtpi_scene_add_white_light(rtp_scene *s, const double pos[3])
{
    rtpi_light l;
    memset(&l, 0, sizeof l);
    l.pos[0] = pos[0];
    l.pos[1] = pos[1];
    l.pos[2] = pos[2];
    l.color[0] = l.color[1] = l.color[2] = 1.0f;
    l.on = 1;
    return rtpi_scene_add_light(s, &l);
}

int rtpi_texture_share(const rtp_allocator *a, rtpi_texture *t)
{
#ifndef RTP_HAVE_THREADS
    /* Not shared: a build without threads has no lock (rtpi_mutex is a
       stub), yet a caller's own threads may record from one scene at once
       (rtp.h: a scene not being modified may be used from several
       threads) and destroy the scene and its trees on two threads; an
       unlocked count lost increments (TSan: rtpi_scene_clone's refs++
       raced in two rtp_record calls), freeing an image a tree still
       read.  Clones copy the images, as before the sharing. */
    (void)a;
    (void)t;
    return 0;
#else
    rtpi_texshare *sh;
    if (!t->image || t->share)
        return 0;
    sh = (rtpi_texshare *)rtpi_malloc(a, sizeof *sh);
    if (!sh)
        return -1;
    if (rtpi_mutex_init(&sh->m)) {
        rtpi_free(a, sh);
        return -1;
    }
    sh->alloc = *a;
    sh->refs = 1;
    t->share = sh;
    return 0;
#endif
}

void rtpi_texture_release(rtpi_texture *t)
{
    rtpi_texshare *sh = t->share;
    if (sh) {
        size_t left;
        rtpi_mutex_lock(&sh->m);
        left = --sh->refs;
        rtpi_mutex_unlock(&sh->m);
        if (left == 0) {
            rtp_allocator a = sh->alloc;
            rtp_image_destroy(t->image);
            rtpi_mutex_destroy(&sh->m);
            rtpi_free(&a, sh);
        }
    } else {
        rtp_image_destroy(t->image);
    }
    t->image = NULL;
    t->share = NULL;
}

rtp_status rtpi_scene_add_texture(rtp_scene *s, const char *path, int fresh,
                                  uint32_t *index, rtp_error *err)
{
    size_t i;
    double mx;
    rtp_image *img = NULL;
    rtp_status st;
    char *p;
    for (i = 0; !fresh && i < s->ntexs; i++) {
        if (s->texs[i].image && strcmp(s->texs[i].path, path) == 0) {
            *index = (uint32_t)i;
            return RTP_OK;
        }
    }
    /* (a tree file names each texture in a string of at most 255 bytes:
       a longer path was cut there, naming a file that is not there) */
    if (strlen(path) > 255)
        return rtpi_error(err, RTP_ERR_ARGUMENT, path, 0, 0,
                          "texture path longer than 255 bytes (a tree file cannot name it): "
                          "move the image or the scene to a shorter path");
    st = rtp_image_read(path, &s->alloc, &img, err);
    if (st != RTP_OK)
        return st;
    /* (a PFM can hold NaN and infinity: every pixel it shades would be
       NaN, and the tree file could not hold it) */
    for (i = 0, mx = 0.0; i < 3 * (size_t)img->width * (size_t)img->height; i++) {
        if (fabs(img->pixels[i]) > mx)
            mx = fabs(img->pixels[i]);
        if (!isfinite(img->pixels[i])) {
            size_t px = i / 3, w = (size_t)img->width;
            rtp_image_destroy(img);
            return rtpi_error(err, RTP_ERR_FORMAT, path, 0, 0,
                              "pixel (%zu, %zu) is not a finite number: a texture or bump map "
                              "needs finite values",
                              px % w, px / w);
        }
    }
    /* read afresh (a key's image: the file may have changed since, or be
       another file from another folder, or stdin): where it
       is an image the scene holds under that name, pixel for pixel, that
       one (a stream setting the same image again adds nothing, and the
       edit changes nothing) */
    for (i = 0; fresh && i < s->ntexs; i++) {
        const rtp_image *o = s->texs[i].image;
        if (strcmp(s->texs[i].path, path) == 0 && o && o->width == img->width &&
            o->height == img->height &&
            memcmp(o->pixels, img->pixels,
                   3 * (size_t)img->width * (size_t)img->height * sizeof *img->pixels) == 0) {
            rtp_image_destroy(img);
            *index = (uint32_t)i;
            return RTP_OK;
        }
    }
    p = rtpi_strdup(&s->alloc, path);
    if (!p || GROW(s, texs, ntexs, cap_texs)) {
        rtpi_free(&s->alloc, p);
        rtp_image_destroy(img);
        return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory");
    }
    s->texs[s->ntexs].path = p;
    s->texs[s->ntexs].image = img;
    s->texs[s->ntexs].share = NULL;
    s->texs[s->ntexs].max_abs = mx;
    if (rtpi_texture_share(&s->alloc, &s->texs[s->ntexs])) {
        rtpi_free(&s->alloc, p);
        rtp_image_destroy(img);
        return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory");
    }
    *index = (uint32_t)s->ntexs++;
    return RTP_OK;
}

/* ------------------------------------------------------------- loading */

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix), i;
    if (m > n)
        return 0;
    for (i = 0; i < m; i++)
        if (tolower((unsigned char)s[n - m + i]) != suffix[i])
            return 0;
    return 1;
}

/* An OBJ on its own has no camera or light: look at its bounds from the
   front (+z, y up, OBJ's usual frame) with a light beside the camera. */
static int frame_bounds(rtp_scene *s)
{
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL};
    double hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    double c[3], r = 0.0, dir[3] = {0.35, 0.45, 1.0}, dl;
    size_t i;
    int k;
    rtpi_light l;
    for (i = 0; i < s->ntris; i++) {
        for (k = 0; k < 3; k++) {
            const float *p = s->pos + 3 * (size_t)s->tris[i].v[k];
            int a;
            for (a = 0; a < 3; a++) {
                if (p[a] < lo[a]) lo[a] = p[a];
                if (p[a] > hi[a]) hi[a] = p[a];
            }
        }
    }
    if (!s->ntris) {
        for (k = 0; k < 3; k++)
            lo[k] = hi[k] = 0.0;
    }
    for (k = 0; k < 3; k++) {
        c[k] = 0.5 * (lo[k] + hi[k]);
        r += 0.25 * (hi[k] - lo[k]) * (hi[k] - lo[k]);
    }
    r = sqrt(r);
    if (!(r > 0.0))
        r = 1.0;
    dl = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    for (k = 0; k < 3; k++) {
        /* 45 degrees sees a sphere of radius r whole from 2.7 r away. */
        s->camera.from[k] = c[k] + dir[k] / dl * 2.7 * r;
        s->camera.at[k] = c[k];
        s->camera.up[k] = k == 1 ? 1.0 : 0.0;
    }
    s->camera.angle = 45.0;
    s->camera.hither = 0.0;
    s->has_camera = 0;
    if (s->nlights == 0) {
        memset(&l, 0, sizeof l);
        for (k = 0; k < 3; k++) {
            l.pos[k] = s->camera.from[k] + (k == 0 ? r : k == 1 ? 2.0 * r : 0.0);
            l.color[k] = 1.0f;
        }
        l.on = 1;
        if (rtpi_scene_add_light(s, &l) < 0)
            return -1;
    }
    return 0;
}

rtp_status rtp_scene_load_memory(const char *text, size_t size,
                                 const char *name, const char *format,
                                 const rtp_allocator *alloc, rtp_scene **out,
                                 rtp_error *err)
{
    rtp_scene *s = NULL;
    rtp_status st;
    if (out)
        *out = NULL;
    if (!out || (!text && size))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_scene_load_memory: NULL argument");
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_scene_load_memory");
    if (!name)
        name = "<memory>";
    /* (a NUL in a comment was read past, as in no file: rtpi_read_file
       refuses any, as a binary or UTF-16 file's; a scene's text is the
       same text wherever it comes from) */
    if ((st = rtpi_text_nul(text, size, name, err)) != RTP_OK)
        return st;
    st = rtpi_scene_create(alloc, &s);
    if (st != RTP_OK)
        return rtpi_error(err, st, name, 0, 0, "out of memory");
    if (format && strcmp(format, "obj") == 0)
        st = rtpi_read_obj(s, text, size, name, NULL, RTPI_NONE, err);
    else if (!format || strcmp(format, "nff") == 0)
        st = rtpi_read_nff(s, text, size, name, 0, err);
    else
        st = rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                        "unknown scene format '%s' (nff or obj)", format);
    if (st != RTP_OK) {
        rtp_scene_destroy(s);
        return st;
    }
    if (format && strcmp(format, "obj") == 0) {
        if (frame_bounds(s) != 0) {
            rtp_scene_destroy(s);
            return rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0, "out of memory");
        }
    } else {
        s->has_camera = 1;
    }
    /* SPD's advice: each light and the ambient light shine with
       sqrt(L)/(2L) for L lights, so many lights do not wash a scene out. */
    s->light_scale = 0.5 / sqrt((double)(s->nlights > 0 ? s->nlights : 1));
    if (s->ambient[0] < 0.0f)
        s->ambient[0] = s->ambient[1] = s->ambient[2] = (float)s->light_scale;
    *out = s;
    return RTP_OK;
}

rtp_status rtp_scene_load(const char *path, const rtp_allocator *alloc,
                          rtp_scene **out, rtp_error *err)
{
    rtp_allocator a;
    char *text = NULL;
    size_t size = 0;
    rtp_status st;
    if (out)
        *out = NULL;
    if (!path || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_scene_load: NULL argument");
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_scene_load");
    if (!*path) /* (fopen's error would name no file, as rtp_image_read says) */
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "no scene file name");
    rtpi_allocator_init(&a, alloc);
    st = rtpi_read_file(&a, path, &text, &size, err);
    if (st != RTP_OK)
        return st;
    /* (stdin is "<stdin>" in errors, as every reader names it; its
       relative paths resolve from the current folder either way) */
    st = rtp_scene_load_memory(text, size, strcmp(path, "-") == 0 ? "<stdin>" : path,
                               ends_with(path, ".obj") ? "obj" : "nff", &a,
                               out, err);
    rtpi_free(&a, text);
    return st;
}

void rtp_scene_get_info(const rtp_scene *s, rtp_scene_info *info)
{
    size_t i;
    if (!info)
        return; /* (a NULL scene gives zeros; a NULL info, nothing) */
    memset(info, 0, sizeof *info);
    if (!s)
        return;
    info->triangles = s->ntris;
    info->spheres = s->nspheres;
    info->cones = s->ncones;
    info->materials = s->nmats;
    info->lights = s->nlights;
    info->textures = 0;
    for (i = 0; i < s->ntexs; i++)
        info->textures += s->texs[i].image != NULL; /* (not those edits replaced) */
    info->width = s->width;
    info->height = s->height;
}

/* ---------------------------------------------------------------- keys */

/* Parses up to `max` comma-separated finite numbers; returns how many. */
static int parse_numbers(const char *v, double *out, int max)
{
    int n = 0;
    char *end;
    for (;;) {
        double d;
        while (*v == ' ' || *v == '\t')
            v++;
        const char *c;
        while (*v && strchr(" \t\r\n\v\f", *v))
            v++; /* (strtod's white space) */
        /* decimal numbers only, as the scene readers take them
           (rtpi_tok_number): strtod's hex, "nan" and "inf" are not */
        if (!(*v == '-' || *v == '+' || *v == '.' || (*v >= '0' && *v <= '9')))
            return -1;
        for (c = v; *c && *c != ','; c++)
            if (*c == 'x' || *c == 'X' || *c == 'n' || *c == 'N' || *c == 'i' || *c == 'I')
                return -1;
        d = rtpi_strtod(v, &end);
        /* values are stored as floats (colours, coefficients): beyond
           float's range they would become infinite; below it (1e-400,
           strtod's ERANGE too) they are 0, as the readers have them */
        if (end == v || !isfinite(d) || fabs(d) > RTPI_VALUE_LIMIT)
            return -1;
        if (n == max)
            return -1;
        out[n++] = d;
        v = end;
        while (*v == ' ' || *v == '\t')
            v++;
        if (*v == '\0')
            return n;
        if (*v != ',')
            return -1;
        v++;
    }
}

/* Whether tok[0..len) is digits alone, an index: its value in *idx, or
   (size_t)-1 past nine significant digits (more items than any scene
   holds).  Leading zeros count for nothing: mat.0000000001 is mat.1, as
   mat.01 is (it was read as a name, "no such material", from ten
   characters on). */
static int digits_index(const char *tok, size_t len, size_t *idx)
{
    size_t i, v = 0;
    if (len == 0)
        return 0;
    for (i = 0; i < len; i++)
        if (!isdigit((unsigned char)tok[i]))
            return 0;
    for (i = 0; i < len && tok[i] == '0'; i++)
        ;
    if (len - i > 9) {
        *idx = (size_t)-1;
        return 1;
    }
    for (; i < len; i++)
        v = v * 10 + (size_t)(tok[i] - '0');
    *idx = v;
    return 1;
}

/* Resolves "N" or a name among n items; returns index or -1.  Digits
   alone are always an index (README): a name of digits is reached by its
   index. */
static long find_index(const char *tok, size_t toklen, size_t n,
                       const char *(*name_of)(const rtp_scene *, size_t),
                       const rtp_scene *s)
{
    size_t i, idx;
    if (digits_index(tok, toklen, &idx))
        return idx < n ? (long)idx : -1;
    for (i = 0; i < n; i++) {
        const char *nm = name_of(s, i);
        if (nm && strlen(nm) == toklen && memcmp(nm, tok, toklen) == 0)
            return (long)i;
    }
    return -1;
}

static const char *light_name(const rtp_scene *s, size_t i) { return s->lights[i].name; }
static const char *mat_name(const rtp_scene *s, size_t i) { return s->mats[i].name; }

/* Where a material's one-number field (kd, ks, kt, shine, ior,
   checker_scale, bump_strength, bump_scale) lies in rtpi_material, as
   *off; 0 for another field. */
static int mat_number(const char *field, size_t *off)
{
    static const struct {
        const char *name;
        size_t off;
    } f[] = {{"kd", offsetof(rtpi_material, kd)},
             {"ks", offsetof(rtpi_material, ks)},
             {"kt", offsetof(rtpi_material, kt)},
             {"shine", offsetof(rtpi_material, shine)},
             {"ior", offsetof(rtpi_material, ior)},
             {"checker_scale", offsetof(rtpi_material, tex_scale)},
             {"bump_strength", offsetof(rtpi_material, bump_strength)},
             {"bump_scale", offsetof(rtpi_material, bump_scale)}};
    size_t i;
    for (i = 0; i < sizeof f / sizeof *f; i++)
        if (strcmp(field, f[i].name) == 0) {
            *off = f[i].off;
            return 1;
        }
    return 0;
}

/* A texture or bump map the key names could not be read: the message
   (whose file is the image's) names the key and what else it takes. */
static rtp_status image_key_error(rtp_error *err, rtp_status st, const char *key,
                                  const char *others)
{
    if (err) {
        /* (made whole, then fitted to the message: cut at its size, it
           could end inside a character) */
        char msg[2 * sizeof err->message + 128];
        int n = snprintf(msg, sizeof msg, "%s: %s (values: %s)", key, err->message, others);
        rtpi_fit_text(err->message, sizeof err->message, msg,
                      n >= 0 && (size_t)n < sizeof msg);
    }
    return st;
}

/* need numbers, or for a colour (need 3, `broadcast`) one for all three
   channels. */
static rtp_status want_n(rtp_error *err, const char *key, const char *value, int got, int need,
                         int broadcast)
{
    if (got == need || (broadcast && got == 1))
        return RTP_OK;
    return rtpi_error(err, RTP_ERR_PARSE, NULL, 0, 0,
                      "%s: expected %d comma-separated number%s%s (|x| <= 3.4e38), got '%s'", key, need,
                      need > 1 ? "s" : "", broadcast ? " (or one for all three)" : "", value);
}

static rtp_status want(rtp_error *err, const char *key, const char *value, int got, int need)
{
    return want_n(err, key, value, got, need, need == 3);
}

/* light.N.FIELD or mat.N.FIELD (N an index or a name): which (ITEM_LIGHT,
   ITEM_MAT), N's index and FIELD; else RTP_ERR_KEY naming what is wrong. */
enum { ITEM_LIGHT = 1, ITEM_MAT = 2 };
/* What a key of no family is told: the families, and the remedy for an
   edit no class has (an object moved, BRIEF's "later" class D; it said
   only "unknown key"). */
#define KEYS_THERE                                                                         \
    "keys: light.N.FIELD, mat.N.FIELD, camera.FIELD, ambient, background; objects are "   \
    "not parameters: to move one, edit the scene and trace it again"

static rtp_status item_key(const rtp_scene *s, const char *key, int *kind, long *idx,
                           const char **field, rtp_error *err)
{
    /* (the field is after the last dot: a name may hold dots, as MTL
       names often do, "Material.001") */
    const char *dot1 = strchr(key, '.'), *dot2 = strrchr(key, '.');
    size_t len;
    if (!dot1 || dot2 == dot1)
        return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0, "unknown key '%s' (%s)", key, KEYS_THERE);
    *field = dot2 + 1;
    len = (size_t)(dot2 - dot1 - 1);
    if ((size_t)(dot1 - key) == 5 && memcmp(key, "light", 5) == 0) {
        *kind = ITEM_LIGHT;
        if ((*idx = find_index(dot1 + 1, len, s->nlights, light_name, s)) < 0)
            return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                              "%s: no such light (the scene has %zu; light.%zu.pos adds one)",
                              key, s->nlights, s->nlights);
        return RTP_OK;
    }
    if ((size_t)(dot1 - key) == 3 && memcmp(key, "mat", 3) == 0) {
        size_t j, d;
        *kind = ITEM_MAT;
        if ((*idx = find_index(dot1 + 1, len, s->nmats, mat_name, s)) >= 0)
            return RTP_OK;
        /* digits are an index, never a name: an MTL material named "12"
           is reached by its own index, which the message gives (it said
           only that there was no such material) */
        for (j = 0; j < s->nmats && digits_index(dot1 + 1, len, &d); j++)
            if (s->mats[j].name && strlen(s->mats[j].name) == len &&
                memcmp(s->mats[j].name, dot1 + 1, len) == 0)
                return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                                  "%s: no such material (the scene has %zu; digits are an "
                                  "index: the material named '%.*s' is mat.%zu)",
                                  key, s->nmats, (int)len, dot1 + 1, j);
        return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                          "%s: no such material (the scene has %zu)", key, s->nmats);
    }
    return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0, "unknown key '%s' (%s)", key, KEYS_THERE);
}

/* What is wrong with s's camera for a frame to be made, or NULL: at
   equal to from, or up without a part across the view direction (1e-9 of
   the lengths' product: far below any intended tilt), as NFF's v block
   refuses them.  Checked where a frame is made (trace, a camera edit's
   re-trace) and where a tree file is read, not at each key: setting
   from and then at may pass through from == at. */
const char *rtpi_camera_problem(const rtp_scene *s)
{
    const double *f = s->camera.from, *a = s->camera.at, *u = s->camera.up;
    rtpi_v3 dir = v3(a[0] - f[0], a[1] - f[1], a[2] - f[2]), up = v3(u[0], u[1], u[2]);
    if (!(v3_len(dir) > 0.0))
        return "camera.at equals camera.from";
    if (!(v3_len(v3_cross(dir, up)) > 1e-9 * v3_len(dir) * v3_len(up)))
        return "camera.up is zero or parallel to the view direction";
    return NULL;
}

rtp_status rtpi_camera_error(const rtp_scene *s, const char *fn, const char *what,
                             rtp_error *err)
{
    const char *why = rtpi_camera_problem(s);
    int k = why && strstr(why, "camera.at") ? 0 : 1;
    if (why && s->cam_bad[k]) {
        const rtp_error *e = &s->cam_err[k];
        return rtpi_error(err, RTP_ERR_ARGUMENT, e->file, e->line, e->column, "%s: %s",
                          e->message, what);
    }
    if (fn)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: %s: %s", fn,
                          why ? why : "the camera", what);
    return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: %s", why ? why : "the camera",
                      what);
}

static void put_num(char *out, size_t size, size_t *at, double v, int is_float, int first);

/* The camera's numbers are geometry: |x| <= RTPI_COORD_LIMIT, as NFF's v
   block has them (a key took 1e30, the file refused 1e19).  The number
   said in its shortest form that reads back (6 digits said
   "-1e+18 is out of range (|x| <= 1e+18)" of -1.0000001e18). */
static rtp_status want_coord(rtp_error *err, const char *key, const double *v, int n)
{
    int i;
    char g[40], lim[32]; /* '.' whatever the locale */
    for (i = 0; i < n; i++)
        if (fabs(v[i]) > RTPI_COORD_LIMIT) {
            size_t at = 0;
            put_num(g, sizeof g, &at, v[i], 0, 1);
            rtpi_fmt_g(lim, sizeof lim, 6, RTPI_COORD_LIMIT);
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              "%s: %s is out of range (|x| <= %s, as a scene's view)", key, g,
                              lim);
        }
    return RTP_OK;
}

/* camera.from, camera.at, camera.up (x,y,z), camera.angle (degrees, as
   NFF's: between 0 and 180), camera.hither (>= 0): what NFF's v block
   says.  The camera is then the scene's, not framed for an OBJ. */
static rtp_status set_camera(rtp_scene *s, const char *key, const char *value,
                             const double *v, int n, rtp_error *err)
{
    const char *field = key + 7;
    double *dst = strcmp(field, "from") == 0 ? s->camera.from
                  : strcmp(field, "at") == 0 ? s->camera.at
                  : strcmp(field, "up") == 0 ? s->camera.up
                                             : NULL;
    rtp_status st;
    if (dst) {
        if ((st = want_n(err, key, value, n, 3, 0)) != RTP_OK)
            return st;
        if ((st = want_coord(err, key, v, 3)) != RTP_OK)
            return st;
        dst[0] = v[0];
        dst[1] = v[1];
        dst[2] = v[2];
        /* (a problem of the file's v block is now the keys', said so) */
        s->cam_bad[1] = 0;
        if (dst != s->camera.up)
            s->cam_bad[0] = 0;
    } else if (strcmp(field, "angle") == 0 || strcmp(field, "hither") == 0) {
        int angle = field[0] == 'a';
        if ((st = want_n(err, key, value, n, 1, 0)) != RTP_OK)
            return st;
        if (!angle && (st = want_coord(err, key, v, 1)) != RTP_OK)
            return st;
        if (angle ? !(v[0] > 0.0 && v[0] < 180.0) : !(v[0] >= 0.0)) {
            char g[32]; /* '.' whatever the locale */
            rtpi_fmt_g(g, sizeof g, 6, v[0]);
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              angle ? "%s: %s: the view angle must be between 0 and 180 degrees"
                                    : "%s: %s: hither must be 0 or more",
                              key, g);
        }
        if (angle)
            s->camera.angle = v[0];
        else
            s->camera.hither = v[0];
    } else {
        return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                          "unknown key '%s' (camera fields: from, at, up, angle, hither)", key);
    }
    s->has_camera = 1;
    return RTP_OK;
}

/* Colours are 0 or more, as NFF takes them (a negative colour made
   negative pixels). */
static rtp_status want_rgb(rtp_error *err, const char *key, const double *v, int n)
{
    int i;
    char g[32]; /* '.' whatever the locale */
    for (i = 0; i < n; i++)
        if (v[i] < 0.0) {
            rtpi_fmt_g(g, sizeof g, 6, v[i]);
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              "%s: %s: a colour's components must be 0 or more", key, g);
        }
    return RTP_OK;
}

/* On and off keys take 0 or 1. */
static rtp_status want_01(rtp_error *err, const char *key, double v)
{
    char g[32]; /* '.' whatever the locale */
    if (v == 0.0 || v == 1.0)
        return RTP_OK;
    rtpi_fmt_g(g, sizeof g, 6, v);
    return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: %s: expected 0 (off) or 1 (on)",
                      key, g);
}

static void set_rgb(float *dst, const double *v, int n)
{
    int i;
    for (i = 0; i < 3; i++)
        dst[i] = (float)v[n == 1 ? 0 : i];
}

/* A light's intensity is its colour's largest component: setting it to v
   scales the colour to that, its hue kept (that component v itself, the
   others c v / max in double, rounded once); a black light, which has no
   hue, turns white of v.  Nothing is kept beside the colour, so the tree
   file holds it as it holds the colour, and setting v twice is setting it
   once; trace --set and reeval --set make the same floats. */
static int light_brightest(const float *c)
{
    int i, k = 0;
    for (i = 1; i < 3; i++)
        if (c[i] > c[k])
            k = i;
    return k;
}

static void light_intensity(float *c, double v)
{
    int i, k = light_brightest(c);
    double m = c[k];
    if (!(m > 0.0)) {
        c[0] = c[1] = c[2] = (float)v;
        return;
    }
    for (i = 0; i < 3; i++)
        c[i] = i == k ? (float)v : (float)((double)c[i] * v / m);
}

/* A field rtp_scene_set does not take.  name and ambient_own are ones
   rtp_scene_get reads: "unknown key" for them sent a caller who had just
   read one looking for a typo. */
static rtp_status field_refused(rtp_error *err, const char *key, const char *field,
                                const char *fields)
{
    if (strcmp(field, "name") == 0 || strcmp(field, "ambient_own") == 0)
        return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                          "%s is read only (%s)", key, fields);
    return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0, "unknown key '%s' (%s)", key, fields);
}

/* The files a scene read besides its own, for a message about file.N:
   "none", "1, file.0", "3, file.0 to file.2". */
static const char *files_read(const rtp_scene *s, char *buf, size_t size)
{
    if (s->nfiles == 0)
        snprintf(buf, size, "none");
    else if (s->nfiles == 1)
        snprintf(buf, size, "1, file.0");
    else
        snprintf(buf, size, "%zu, file.0 to file.%zu", s->nfiles, s->nfiles - 1);
    return buf;
}

/* A file.N key given to rtp_scene_set: read only, whatever N (the scene's
   record of what it read, rtp_scene_get's; "unknown key" for it sent a
   caller who had just read file.0 looking for a typo, and named only
   light, mat, camera, ambient and background) */
static rtp_status file_key_refused(const rtp_scene *s, const char *key, rtp_error *err)
{
    char what[64];
    size_t d;
    if (digits_index(key + 5, strlen(key + 5), &d))
        return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                          "%s is read only (file.N: the files a loaded scene read besides its "
                          "own, not parameters; this one read %s)",
                          key, files_read(s, what, sizeof what));
    return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                      "unknown key '%s' (file.N, N a number, is read only: the files a loaded "
                      "scene read besides its own; %s)",
                      key, KEYS_THERE);
}

/* Is key light.N.pos with N the scene's count of lights (an index, as
   find_index reads one), which adds light N?  Only pos: a light's other
   fields are set once it is there. */
static int adds_light(const rtp_scene *s, const char *key)
{
    const char *d = key + 6, *e;
    size_t idx;
    if (strncmp(key, "light.", 6) != 0)
        return 0;
    for (e = d; isdigit((unsigned char)*e); e++)
        ;
    if (strcmp(e, ".pos") != 0 || !digits_index(d, (size_t)(e - d), &idx))
        return 0;
    return idx == s->nlights;
}

rtp_status rtpi_scene_set(rtp_scene *s, const char *key, const char *value,
                          rtp_error *err)
{
    double v[4];
    int n, kind;
    long i;
    const char *field;
    rtp_status st;
    if (!s || !key || !value)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_scene_set: NULL argument");
    n = parse_numbers(value, v, 4);
    if (strcmp(key, "ambient") == 0 || strcmp(key, "background") == 0) {
        if ((st = want(err, key, value, n, 3)) != RTP_OK ||
            (st = want_rgb(err, key, v, n)) != RTP_OK)
            return st;
        set_rgb(key[0] == 'a' ? s->ambient : s->background, v, n);
        return RTP_OK;
    }
    if (strncmp(key, "camera.", 7) == 0)
        return set_camera(s, key, value, v, n, err);
    if (adds_light(s, key)) {
        /* a new light, as rtp_tree_add_light makes one (its colour scaled
           as the loaded lights are: light_scale) */
        if ((st = want_n(err, key, value, n, 3, 0)) != RTP_OK)
            return st;
        if (rtpi_scene_add_white_light(s, v) < 0)
            return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0, "%s: out of memory", key);
        return RTP_OK;
    }
    if (strncmp(key, "file.", 5) == 0)
        return file_key_refused(s, key, err);
    if ((st = item_key(s, key, &kind, &i, &field, err)) != RTP_OK)
        return st;
    if (kind == ITEM_LIGHT) {
        rtpi_light *l = &s->lights[i];
        if (strcmp(field, "pos") == 0) {
            /* (a position: x,y,z, never one number for all three) */
            if ((st = want_n(err, key, value, n, 3, 0)) != RTP_OK)
                return st;
            l->pos[0] = v[0];
            l->pos[1] = v[1];
            l->pos[2] = v[2];
        } else if (strcmp(field, "color") == 0) {
            if ((st = want(err, key, value, n, 3)) != RTP_OK ||
                (st = want_rgb(err, key, v, n)) != RTP_OK)
                return st;
            set_rgb(l->color, v, n);
        } else if (strcmp(field, "intensity") == 0) {
            if ((st = want(err, key, value, n, 1)) != RTP_OK ||
                (st = want_rgb(err, key, v, n)) != RTP_OK)
                return st;
            light_intensity(l->color, v[0]);
        } else if (strcmp(field, "on") == 0) {
            if ((st = want(err, key, value, n, 1)) != RTP_OK ||
                (st = want_01(err, key, v[0])) != RTP_OK)
                return st;
            l->on = v[0] != 0.0;
        } else {
            return field_refused(err, key, field, "light fields: pos, color, intensity, on");
        }
        return RTP_OK;
    }
    {
        rtpi_material *m = &s->mats[i];
        float *dst = NULL;
        if (strcmp(field, "color") == 0 || strcmp(field, "color2") == 0) {
            if ((st = want(err, key, value, n, 3)) != RTP_OK ||
                (st = want_rgb(err, key, v, n)) != RTP_OK)
                return st;
            set_rgb(field[5] == '2' ? m->color2 : m->color, v, n);
            return RTP_OK;
        }
        if (strcmp(field, "ambient") == 0) {
            /* the ambient coefficient ka, grey (one number) or r,g,b; 0
               or more, as kd (its message): set, it no longer follows kd.
               "kd" unsets it: ka follows kd again, the material as if
               never given one (ka zeroed too: merge compares materials
               whole, and a tree file then has no MAMB entry for it) */
            int c;
            if (strcmp(value, "kd") == 0) {
                memset(m->ka, 0, sizeof m->ka);
                m->ka_set = 0;
                return RTP_OK;
            }
            if ((st = want(err, key, value, n, 3)) != RTP_OK)
                return st;
            for (c = 0; c < n; c++)
                if (v[c] < 0.0) {
                    char g[32]; /* '.' whatever the locale */
                    rtpi_fmt_g(g, sizeof g, 6, v[c]);
                    return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                      "%s: %s: must be 0 or more", key, g);
                }
            set_rgb(m->ka, v, n);
            m->ka_set = 1;
            return RTP_OK;
        }
        if (strcmp(field, "checker_scale") == 0) {
            if ((st = want(err, key, value, n, 1)) != RTP_OK)
                return st;
            /* (kept as a float: one that rounds to 0 is 0, which a tree
               file refuses) */
            if (!((float)v[0] > 0.0f))
                return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                  "%s: the checker cell size must be > 0 (as a float)", key);
            m->tex_scale = (float)v[0];
            return RTP_OK;
        }
        if (strcmp(field, "checker") == 0) {
            /* turns the solid checker on (1) or off (0) */
            if ((st = want(err, key, value, n, 1)) != RTP_OK ||
                (st = want_01(err, key, v[0])) != RTP_OK)
                return st;
            if (v[0] != 0.0) {
                m->tex = RTPI_TEX_CHECKER;
            } else if (m->tex == RTPI_TEX_CHECKER) {
                m->tex = RTPI_TEX_NONE;
            }
            return RTP_OK;
        }
        if (strcmp(field, "texture") == 0) {
            /* an image texture (PNG/PPM/PFM) by uv, or none */
            if (strcmp(value, "none") == 0) {
                if (m->tex == RTPI_TEX_IMAGE)
                    m->tex = RTPI_TEX_NONE;
            } else {
                uint32_t idx;
                if ((st = rtpi_scene_add_texture(s, value, 1, &idx, err)) != RTP_OK)
                    return image_key_error(err, st, key, "none, or a PNG, PPM or PFM image");
                m = &s->mats[i];
                m->tex = RTPI_TEX_IMAGE;
                m->tex_image = idx;
            }
            return RTP_OK;
        }
        if (strcmp(field, "bump") == 0) {
            /* none, waves, noise, or a PNG height map */
            if (strcmp(value, "none") == 0) {
                m->bump = RTPI_BUMP_NONE;
            } else if (strcmp(value, "waves") == 0) {
                m->bump = RTPI_BUMP_WAVES;
            } else if (strcmp(value, "noise") == 0) {
                m->bump = RTPI_BUMP_NOISE;
            } else {
                uint32_t idx;
                if ((st = rtpi_scene_add_texture(s, value, 1, &idx, err)) != RTP_OK)
                    return image_key_error(err, st, key,
                                           "none, waves, noise, or a height map image");
                m = &s->mats[i]; /* (textures live apart; m is still valid) */
                m->bump = RTPI_BUMP_IMAGE;
                m->bump_image = idx;
            }
            if (m->bump != RTPI_BUMP_NONE && m->bump_strength == 0.0f)
                m->bump_strength = 1.0f;
            return RTP_OK;
        }
        if (strcmp(field, "bump_strength") == 0 || strcmp(field, "bump_scale") == 0) {
            if ((st = want(err, key, value, n, 1)) != RTP_OK)
                return st;
            if (field[5] == 's' && field[6] == 'c' && !((float)v[0] > 0.0f))
                return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                                  "%s: the bump scale must be > 0 (as a float)", key);
            if (field[6] == 't')
                m->bump_strength = (float)v[0];
            else
                m->bump_scale = (float)v[0];
            return RTP_OK;
        }
        {
            /* (checker_scale and the bump numbers were taken above) */
            size_t off;
            if (mat_number(field, &off))
                dst = (float *)(void *)((char *)m + off);
        }
        if (!dst)
            return field_refused(err, key, field,
                                 "material fields: color, kd, ks, kt, shine, ior, ambient, "
                                 "checker, color2, checker_scale, texture, bump, "
                                 "bump_strength, bump_scale");
        if ((st = want(err, key, value, n, 1)) != RTP_OK)
            return st;
        /* (an ior is kept as a float: one that rounds to 0 is 0) */
        if (v[0] < 0.0 || (dst == &m->ior && !((float)v[0] > 0.0f))) {
            char g[32]; /* '.' whatever the locale */
            rtpi_fmt_g(g, sizeof g, 6, v[0]);
            return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                              dst == &m->ior ? "%s: %s: an index of refraction must be > 0"
                                             : "%s: %s: must be 0 or more",
                              key, g);
        }
        *dst = (float)v[0];
        return RTP_OK;
    }
}

/* ------------------------------------------------------------------ get */

/* Appends v in the shortest form that reads back to the same value (as a
   float where is_float: the parameter's own precision), after a comma
   unless first.  A normal value's 6 (float) or 15 (double) digits lose
   their trailing zeros to its shortest form (and keep 30 from %.1g's
   "3e+01"); a subnormal one's do not (1e-45 came back as 1.4013e-45,
   5e-324 as 4.94065645841247e-324), so those start from one digit (in
   exponent form whatever the digits). */
static void put_num(char *out, size_t size, size_t *at, double v, int is_float, int first)
{
    char tmp[40];
    int prec;
    double a = v < 0 ? -v : v;
    int subnormal = a > 0 && (is_float ? a < FLT_MIN : a < DBL_MIN);
    for (prec = subnormal ? 1 : is_float ? 6 : 15; prec <= 17; prec++) {
        double back;
        rtpi_fmt_g(tmp, sizeof tmp, prec, v);
        back = rtpi_strtod(tmp, NULL);
        if (is_float ? (float)back == (float)v : back == v)
            break;
    }
    if (*at < size)
        *at += (size_t)snprintf(out + *at, size - *at, "%s%s", first ? "" : ",", tmp);
    else
        *at += strlen(tmp) + !first;
}

static void put_nums(char *out, size_t size, size_t *at, const double *v, int n, int is_float)
{
    int i;
    for (i = 0; i < n; i++)
        put_num(out, size, at, v[i], is_float, i == 0);
}

static void put_floats(char *out, size_t size, size_t *at, const float *v, int n)
{
    int i;
    for (i = 0; i < n; i++)
        put_num(out, size, at, v[i], 1, i == 0);
}

static void put_str(char *out, size_t size, size_t *at, const char *str)
{
    if (*at < size)
        *at += (size_t)snprintf(out + *at, size - *at, "%s", str);
    else
        *at += strlen(str);
}

/* The path of texture idx, or "?" if it has none. */
static const char *texture_path(const rtp_scene *s, uint32_t idx)
{
    return idx < s->ntexs && s->texs[idx].path ? s->texs[idx].path : "?";
}

void rtpi_scene_drop_textures(rtp_scene *s, const rtpi_material *mats0)
{
    size_t i, m;
    for (i = 0; i < s->ntexs; i++) {
        int used = 0;
        if (!s->texs[i].image)
            continue;
        for (m = 0; m < s->nmats && !used; m++) {
            const rtpi_material *a = &s->mats[m];
            used = (a->tex == RTPI_TEX_IMAGE && a->tex_image == i) ||
                   (a->bump == RTPI_BUMP_IMAGE && a->bump_image == i) ||
                   (mats0 && mats0[m].bump == RTPI_BUMP_IMAGE && mats0[m].bump_image == i);
        }
        if (!used)
            rtpi_texture_release(&s->texs[i]);
    }
}

rtp_status rtp_scene_set(rtp_scene *s, const char *key, const char *value,
                         rtp_error *err)
{
    rtp_status st = rtpi_scene_set(s, key, value, err);
    /* (an image replaced by a texture or bump key: its pixels go) */
    if (s && key && (strstr(key, ".texture") || strstr(key, ".bump")))
        rtpi_scene_drop_textures(s, NULL);
    return st;
}

rtp_status rtp_scene_get(const rtp_scene *s, const char *key, char *buf, size_t size,
                         rtp_error *err)
{
    const char *field;
    size_t at = 0;
    int kind;
    long i;
    rtp_status st;
    if (!s || !key || !buf || size == 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_scene_get: NULL argument");
    buf[0] = '\0';
    if (strcmp(key, "ambient") == 0 || strcmp(key, "background") == 0) {
        put_floats(buf, size, &at, key[0] == 'a' ? s->ambient : s->background, 3);
    } else if (strncmp(key, "camera.", 7) == 0) {
        const rtpi_camera *c = &s->camera;
        field = key + 7;
        if (strcmp(field, "from") == 0 || strcmp(field, "at") == 0 || strcmp(field, "up") == 0)
            put_nums(buf, size, &at, field[0] == 'f' ? c->from : field[0] == 'a' ? c->at : c->up,
                     3, 0);
        else if (strcmp(field, "angle") == 0 || strcmp(field, "hither") == 0)
            put_num(buf, size, &at, field[0] == 'a' ? c->angle : c->hither, 0, 1);
        else
            return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                              "unknown key '%s' (camera fields: from, at, up, angle, hither)",
                              key);
    } else if (strncmp(key, "file.", 5) == 0) {
        /* (read only: the files the scene read besides its own) */
        char *end;
        unsigned long n;
        errno = 0;
        n = key[5] >= '0' && key[5] <= '9' ? strtoul(key + 5, &end, 10) : 0;
        if (!(key[5] >= '0' && key[5] <= '9') || *end || errno || n >= s->nfiles) {
            char what[64];
            return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                              "no key '%s' (the files the scene read besides its own: %s)", key,
                              files_read(s, what, sizeof what));
        }
        put_str(buf, size, &at, s->files[n]);
    } else if ((st = item_key(s, key, &kind, &i, &field, err)) != RTP_OK) {
        return st;
    } else {
        if (kind == ITEM_LIGHT) {
            const rtpi_light *l = &s->lights[i];
            if (strcmp(field, "pos") == 0)
                put_nums(buf, size, &at, l->pos, 3, 0);
            else if (strcmp(field, "color") == 0)
                put_floats(buf, size, &at, l->color, 3);
            else if (strcmp(field, "intensity") == 0)
                put_floats(buf, size, &at, l->color + light_brightest(l->color), 1);
            else if (strcmp(field, "on") == 0)
                put_str(buf, size, &at, l->on ? "1" : "0");
            else if (strcmp(field, "name") == 0)
                put_str(buf, size, &at, l->name ? l->name : "");
            else
                return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                                  "unknown key '%s' (light fields: pos, color, intensity, on, name)", key);
        } else {
            const rtpi_material *m = &s->mats[i];
            size_t off;
            if (strcmp(field, "color") == 0 || strcmp(field, "color2") == 0)
                put_floats(buf, size, &at, field[5] == '2' ? m->color2 : m->color, 3);
            else if (mat_number(field, &off))
                put_floats(buf, size, &at, (const float *)(const void *)((const char *)m + off),
                           1);
            else if (strcmp(field, "ambient") == 0) {
                /* the effective ka: kd in each channel while unset */
                const float kd3[3] = {m->kd, m->kd, m->kd};
                put_floats(buf, size, &at, m->ka_set ? m->ka : kd3, 3);
            } else if (strcmp(field, "ambient_own") == 0) {
                /* (whether that ka is the material's own or kd's: one set
                   equal to kd reads as kd,kd,kd too, and stays under kd's
                   edits where kd's moves with them) */
                put_str(buf, size, &at, m->ka_set ? "1" : "0");
            } else if (strcmp(field, "checker") == 0)
                put_str(buf, size, &at, m->tex == RTPI_TEX_CHECKER ? "1" : "0");
            else if (strcmp(field, "texture") == 0)
                put_str(buf, size, &at,
                        m->tex == RTPI_TEX_IMAGE ? texture_path(s, m->tex_image) : "none");
            else if (strcmp(field, "bump") == 0)
                put_str(buf, size, &at,
                        m->bump == RTPI_BUMP_WAVES   ? "waves"
                        : m->bump == RTPI_BUMP_NOISE ? "noise"
                        : m->bump == RTPI_BUMP_IMAGE ? texture_path(s, m->bump_image)
                                                     : "none");
            else if (strcmp(field, "name") == 0)
                put_str(buf, size, &at, m->name ? m->name : "");
            else
                return rtpi_error(err, RTP_ERR_KEY, NULL, 0, 0,
                                  "unknown key '%s' (material fields: color, kd, ks, kt, shine, "
                                  "ior, ambient, ambient_own, checker, color2, checker_scale, "
                                  "texture, bump, bump_strength, bump_scale, name)",
                                  key);
        }
    }
    if (at >= size) {
        buf[0] = '\0';
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "%s: the value takes %zu bytes, the buffer %zu", key, at + 1, size);
    }
    return RTP_OK;
}

/* ---------------------------------------------------------------- clone */

static int dup_array(const rtp_allocator *a, void **dst, const void *src,
                     size_t count, size_t size)
{
    *dst = NULL;
    if (!count)
        return 0;
    *dst = rtpi_malloc_array(a, count, size);
    if (!*dst)
        return -1;
    memcpy(*dst, src, count * size);
    return 0;
}

static int dup_name(const rtp_allocator *a, char **name)
{
    if (!*name)
        return 0;
    *name = rtpi_strdup(a, *name);
    return *name ? 0 : -1;
}

rtp_status rtpi_scene_clone(const rtp_scene *s, rtp_scene **out)
{
    rtp_scene *c;
    const rtp_allocator *a = &s->alloc;
    size_t i;
    int bad = 0;
    *out = NULL;
    c = (rtp_scene *)rtpi_malloc(a, sizeof *c);
    if (!c)
        return RTP_ERR_NOMEM;
    *c = *s;
    c->pos = c->nrm = c->uv = NULL;
    c->tris = NULL;
    c->spheres = NULL;
    c->cones = NULL;
    c->cframes = NULL;
    c->pbounds = NULL; /* (made again where needed) */
    c->phit = NULL;
    c->npbounds = 0;
    c->mats = NULL;
    c->lights = NULL;
    c->texs = NULL;
    c->nmats = c->nlights = c->ntexs = 0;
    c->files = NULL; /* (a tree reads no file) */
    c->nfiles = c->cap_files = 0;
    bad |= dup_array(a, (void **)&c->pos, s->pos, s->npos * 3, sizeof *s->pos);
    bad |= dup_array(a, (void **)&c->nrm, s->nrm, s->nnrm * 3, sizeof *s->nrm);
    bad |= dup_array(a, (void **)&c->uv, s->uv, s->nuv * 2, sizeof *s->uv);
    bad |= dup_array(a, (void **)&c->tris, s->tris, s->ntris, sizeof *s->tris);
    bad |= dup_array(a, (void **)&c->spheres, s->spheres, s->nspheres, sizeof *s->spheres);
    bad |= dup_array(a, (void **)&c->cones, s->cones, s->ncones, sizeof *s->cones);
    bad |= dup_array(a, (void **)&c->cframes, s->cframes, s->ncones, sizeof *s->cframes);
    c->cap_pos = s->npos * 3;
    c->cap_nrm = s->nnrm * 3;
    c->cap_uv = s->nuv * 2;
    c->cap_tris = s->ntris;
    c->cap_spheres = s->nspheres;
    c->cap_cones = c->cap_cframes = s->ncones;
    if (!bad && !dup_array(a, (void **)&c->mats, s->mats, s->nmats, sizeof *s->mats)) {
        c->cap_mats = s->nmats;
        for (i = 0; i < s->nmats; i++)
            c->mats[i].name = NULL;
        c->nmats = s->nmats;
        for (i = 0; i < s->nmats; i++) {
            c->mats[i].name = s->mats[i].name;
            bad |= dup_name(a, &c->mats[i].name);
            if (bad) {
                for (; i < s->nmats; i++)
                    c->mats[i].name = NULL;
                break;
            }
        }
    } else {
        bad = 1;
    }
    if (!bad && !dup_array(a, (void **)&c->lights, s->lights, s->nlights, sizeof *s->lights)) {
        c->cap_lights = s->nlights;
        c->nlights = s->nlights;
        for (i = 0; i < s->nlights; i++) {
            if (bad) {
                c->lights[i].name = NULL;
                continue;
            }
            bad |= dup_name(a, &c->lights[i].name);
            if (bad)
                c->lights[i].name = NULL;
        }
    } else {
        bad = 1;
    }
    if (!bad && s->ntexs) {
        c->texs = (rtpi_texture *)rtpi_calloc_array(a, s->ntexs, sizeof *c->texs);
        if (!c->texs) {
            bad = 1;
        } else {
            c->cap_texs = s->ntexs;
            c->ntexs = s->ntexs;
            for (i = 0; i < s->ntexs && !bad; i++) {
                const rtp_image *src = s->texs[i].image;
                c->texs[i].path = rtpi_strdup(a, s->texs[i].path);
                c->texs[i].max_abs = s->texs[i].max_abs;
                if (!c->texs[i].path) {
                    bad = 1;
                    break;
                }
                if (!src)
                    continue; /* (replaced by an edit: rtpi_scene_drop_textures) */
                if (s->texs[i].share) { /* read only: held, not copied */
                    rtpi_texshare *sh = s->texs[i].share;
                    rtpi_mutex_lock(&sh->m);
                    sh->refs++;
                    rtpi_mutex_unlock(&sh->m);
                    c->texs[i].image = s->texs[i].image;
                    c->texs[i].share = sh;
                    continue;
                }
                if (rtp_image_create(src->width, src->height, a, &c->texs[i].image, NULL) !=
                    RTP_OK) {
                    bad = 1;
                    break;
                }
                memcpy(c->texs[i].image->pixels, src->pixels,
                       sizeof(float) * 3 * (size_t)src->width * src->height);
            }
        }
    }
    if (bad) {
        rtp_scene_destroy(c);
        return RTP_ERR_NOMEM;
    }
    *out = c;
    return RTP_OK;
}
