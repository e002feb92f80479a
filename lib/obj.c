/* obj.c — the Wavefront OBJ and MTL reader.
 *
 * OBJ: v, vn, vt, f (v, v/t, v//n, v/t/n; negative indices count back
 * from the last vertex read; polygons of any size, concave ones too, are
 * triangulated keeping their winding), usemtl, mtllib; o, g, s and the
 * free-form statements are read past (vp's numbers checked).  MTL:
 * newmtl, Kd, Ks, Ns, Ni, d, Tr, map_Kd, bump/map_bump (-bm strength);
 * Ka, Ke, illum and the other values have their numbers checked and are
 * not used; the other maps are read past.  How MTL values become rtp materials is written in
 * scenes/README.md.  Positions are transformed by the 4x3 `xform`,
 * normals by its inverse transpose. */
#include "readers.h"

#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>

/* Largest magnitude accepted for a coordinate, and for an MTL value (a
   mat.N key's too): RTPI_*_LIMIT. */
#define NUM_LIMIT RTPI_COORD_LIMIT
#define VALUE_LIMIT RTPI_VALUE_LIMIT

typedef struct obj {
    rtp_scene *s;
    rtpi_lex lx;
    rtp_error *err;
    const double *xf;
    double nm[9];
    int flip; /* xf mirrors: each face's corners in the other order */
    uint32_t base_p, base_n, base_t; /* scene counts before this file */
    size_t np, nn, nt;               /* vertices of each kind read so far */
    uint32_t mat;                    /* current; RTPI_NONE: the default */
    uint32_t default_mat;
    size_t faces;
    double *pts;     /* face scratch: xyz per corner */
    size_t cap_pts;
    uint32_t *crn;   /* v, t, n scene indices per corner */
    size_t cap_crn;
    uint32_t *tri;
    size_t cap_tri;
    rtpi_names own;  /* the materials this file's mtllibs named, first wins */
    rtpi_mtl_reg *reg; /* the load's MTL files (never NULL while reading) */
} obj;

static rtp_status nomem(const rtpi_lex *lx, const rtpi_tok *t)
{
    return rtpi_error(lx->err, RTP_ERR_NOMEM, lx->name, t->line, t->col,
                      "out of memory");
}

/* The next number on this line for `what` (e.g. "v (vertex)"), `field`,
   within limit. */
static rtp_status line_num_upto(rtpi_lex *lx, const char *what, const char *field,
                                double limit, double *out, rtpi_tok *tok)
{
    rtpi_tok t;
    char show[48];
    int r;
    if (!rtpi_lex_next_inline(lx, &t))
        return rtpi_lex_error(lx, &t, "unexpected end of %s in %s, expected %s",
                              lx->p < lx->end ? "line" : "file", what, field);
    r = rtpi_tok_number(&t, out);
    if (r == -1)
        return rtpi_lex_error(lx, &t, "expected number for %s %s, got '%s'", what,
                              field, rtpi_tok_show(&t, show, sizeof show));
    if (r != 0 || fabs(*out) > limit)
        return rtpi_lex_error(lx, &t, "%s %s %s is out of range", what, field,
                              rtpi_tok_show(&t, show, sizeof show));
    if (tok)
        *tok = t;
    return RTP_OK;
}

/* A coordinate (NUM_LIMIT), and an MTL value (VALUE_LIMIT). */
static rtp_status line_num(rtpi_lex *lx, const char *what, const char *field,
                           double *out, rtpi_tok *tok)
{
    return line_num_upto(lx, what, field, NUM_LIMIT, out, tok);
}

static rtp_status line_val(rtpi_lex *lx, const char *what, const char *field,
                           double *out, rtpi_tok *tok)
{
    return line_num_upto(lx, what, field, VALUE_LIMIT, out, tok);
}

/* Up to `max` more optional numbers, then the end of the line; `done`
   numbers precede them on the line (for a message). */
static rtp_status line_rest(rtpi_lex *lx, const char *what, int done, int max)
{
    rtpi_tok t;
    char show[48];
    double d;
    int n = 0;
    while (rtpi_lex_next_inline(lx, &t)) {
        int r = rtpi_tok_number(&t, &d);
        if (r == -2 && n < max)
            return rtpi_lex_error(lx, &t, "%s value %s is out of range", what,
                                  rtpi_tok_show(&t, show, sizeof show));
        /* (a bad number where one may be, `v 0 0 0 nan`: not "unexpected
           'nan' at the end") */
        if (r == -1 && n < max && rtpi_tok_numlike(&t))
            return rtpi_lex_error(lx, &t, "expected number for %s value %d, got '%s'", what,
                                  done + n + 1, rtpi_tok_show(&t, show, sizeof show));
        if (r != 0 || n++ >= max)
            return rtpi_lex_error(lx, &t, "unexpected '%s' at the end of %s",
                                  rtpi_tok_show(&t, show, sizeof show), what);
    }
    return RTP_OK;
}

/* The rest of the line as one string (a name or a file name that may
   contain spaces); trailing white space dropped. */
static rtp_status line_string(rtpi_lex *lx, const char *what, rtpi_tok *out)
{
    rtpi_tok t, more;
    const char *last_end;
    if (!rtpi_lex_next_inline(lx, &t))
        return rtpi_lex_error(lx, &t, "unexpected end of line in %s, expected a name",
                              what);
    last_end = t.s + t.n;
    while (rtpi_lex_next_inline(lx, &more))
        last_end = more.s + more.n;
    *out = t;
    out->n = (size_t)(last_end - t.s);
    return RTP_OK;
}

/* OBJ statements rtp does not draw, read past: names (o, g, usemap,
   maplib, ...), render hints (lod, bevel, c_interp, ...), and free-form
   geometry (cstype, deg, curv, surf, ... and their blocks up to `end`):
   a language of its own, whose statements mean something only in the
   state earlier ones set (cstype and deg give parm and the control
   points' count), so a check of their words alone would refuse files it
   misread; rtp draws none of it.  Checked though not drawn: s (read_smoothing),
   l and p (read_element), whose indices are a face's, and vp, whose
   numbers are v's (ignored_numbers). */
static const char *const ignored_obj[] = {
    "o", "g", "mg", "cstype", "deg", "bmat", "step",
    "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end",
    "con", "lod", "usemap", "maplib", "shadow_obj", "trace_obj", "ctech",
    "stech", "bevel", "c_interp", "d_interp", NULL};

/* MTL statements rtp does not use.  Those of numbers (a colour: Ka, Ke,
   Tf; a value: illum, sharpness and the PBR extension's) have them
   checked as Kd's are, 1 to 3 each (Ka's "xyz" and "spectral FILE" forms
   too): "Ka nan 0 0" or "Ka x y z" loaded silently while "Kd nan" was
   refused, and a file that holds them is malformed whatever rtp draws.
   The maps (disp, decal, refl, norm) are read past: a file's name, whose
   options are the image's reader's business, and no image is read. */
static const char *const ignored_mtl_nums[] = {
    "Ka", "Ke", "Tf", "illum", "sharpness", "Pr", "Pm", "Ps", "Pc", "Pcr", "aniso",
    "anisor", NULL};
static const char *const ignored_mtl[] = {"disp", "decal", "refl", "norm", NULL};

static int in_list(const rtpi_tok *t, const char *const *list)
{
    for (; *list; list++)
        if (rtpi_tok_is(t, *list))
            return 1;
    return 0;
}

/* The numbers of a statement rtp does not use (ignored_mtl_nums, vp): 1
   to 3, each within VALUE_LIMIT, checked as a used one's; "spectral FILE
   [factor]" read past, "xyz" before the numbers taken. */
static rtp_status ignored_numbers(rtpi_lex *lx, const rtpi_tok *kw)
{
    char what[16];
    rtpi_lex save = *lx;
    rtpi_tok peek;
    double d;
    int n;
    rtp_status st;
    rtpi_tok_show(kw, what, sizeof what);
    if (rtpi_lex_next_inline(&save, &peek)) {
        if (rtpi_tok_is(&peek, "spectral")) {
            rtpi_lex_skip_line(lx);
            return RTP_OK;
        }
        if (rtpi_tok_is(&peek, "xyz"))
            *lx = save;
    }
    if ((st = line_val(lx, what, "value", &d, NULL)) != RTP_OK)
        return st;
    for (n = 1; n < 3; n++) {
        static const char *const field[] = {"value", "value 2", "value 3"};
        save = *lx;
        if (!rtpi_lex_next_inline(&save, &peek) || !rtpi_tok_numlike(&peek))
            break;
        if ((st = line_val(lx, what, field[n], &d, NULL)) != RTP_OK)
            return st;
    }
    return line_rest(lx, what, n, 0);
}

static const char *reg_name(const rtp_scene *s, int kind, uint32_t i)
{
    return kind == 'l' ? s->lights[i].name : s->mats[i].name;
}

static size_t name_hash(const char *p, size_t n)
{
    size_t h = 2166136261u, i; /* FNV-1a */
    for (i = 0; i < n; i++)
        h = (h ^ (unsigned char)p[i]) * 16777619u;
    return h;
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* Adds entry i (named) to h: after the entries of its name already
   there, so that probing meets them in the order added. */
static int names_put(rtpi_names *h, const rtp_allocator *a, const rtp_scene *s, int kind,
                     uint32_t i)
{
    const char *nm = reg_name(s, kind, i);
    size_t k;
    if (!nm)
        return 0;
    if (2 * (h->n + 1) > h->cap) {
        /* twice the size, the entries put again in the order added (their
           indices rise with it: materials and lights are only appended) */
        rtpi_names g;
        size_t j, m = 0;
        uint32_t *all = h->n ? (uint32_t *)rtpi_malloc_array(a, h->n, sizeof *all) : NULL;
        if (h->n && !all)
            return -1;
        for (j = 0; j < h->cap; j++)
            if (h->slot[j])
                all[m++] = h->slot[j];
        g.cap = h->cap ? 2 * h->cap : 64;
        g.n = 0;
        g.slot = (uint32_t *)rtpi_calloc_array(a, g.cap, sizeof *g.slot);
        if (!g.slot) {
            rtpi_free(a, all);
            return -1;
        }
        /* (by index: entries of one name were added in rising index
           order, and slot order may have wrapped round past them) */
        if (m > 1) /* (qsort's array must not be NULL, even for 0) */
            qsort(all, m, sizeof *all, cmp_u32);
        for (j = 0; j < m; j++) {
            const char *o = reg_name(s, kind, all[j] - 1);
            k = name_hash(o, strlen(o)) & (g.cap - 1);
            while (g.slot[k])
                k = (k + 1) & (g.cap - 1);
            g.slot[k] = all[j];
            g.n++;
        }
        rtpi_free(a, all);
        rtpi_free(a, h->slot);
        *h = g;
    }
    k = name_hash(nm, strlen(nm)) & (h->cap - 1);
    while (h->slot[k])
        k = (k + 1) & (h->cap - 1);
    h->slot[k] = i + 1u;
    h->n++;
    return 0;
}

/* The names the scene had before this load's first lookup. */
static int reg_sync(rtpi_mtl_reg *r, const rtp_scene *s)
{
    size_t i;
    if (r->synced)
        return 0;
    r->synced = 1;
    for (i = 0; i < s->nmats; i++)
        if (names_put(&r->mats, &s->alloc, s, 'f', (uint32_t)i) != 0)
            return -1;
    for (i = 0; i < s->nlights; i++)
        if (names_put(&r->lights, &s->alloc, s, 'l', (uint32_t)i) != 0)
            return -1;
    return 0;
}

int rtpi_reg_add(rtpi_mtl_reg *r, const rtp_scene *s, int kind, uint32_t i)
{
    if (!r->synced)
        return reg_sync(r, s); /* (i is among them) */
    return names_put(kind == 'l' ? &r->lights : &r->mats, &s->alloc, s, kind, i);
}

/* The next entry of h named name[0..n) after *at. */
static long names_find(const rtpi_names *h, const rtp_scene *s, int kind, const char *name,
                       size_t n, size_t *at)
{
    size_t k, step;
    if (!h->cap)
        return -1;
    k = (name_hash(name, n) + *at) & (h->cap - 1);
    for (step = *at; step < h->cap && h->slot[k]; step++, k = (k + 1) & (h->cap - 1)) {
        const char *m = reg_name(s, kind, h->slot[k] - 1);
        if (strlen(m) == n && memcmp(m, name, n) == 0) {
            *at = step + 1;
            return (long)h->slot[k] - 1;
        }
    }
    *at = h->cap;
    return -1;
}

long rtpi_reg_find(rtpi_mtl_reg *r, const rtp_scene *s, int kind, const char *name,
                   size_t n, size_t *at)
{
    if (reg_sync(r, s) != 0)
        return -1; /* (out of memory: nothing found; the load then fails on
                      a name it cannot find, or makes a material anew) */
    return names_find(kind == 'l' ? &r->lights : &r->mats, s, kind, name, n, at);
}

/* The first material of that name, or -1. */
static long find_material(obj *o, const char *name, size_t n)
{
    size_t at = 0;
    return rtpi_reg_find(o->reg, o->s, 'f', name, n, &at);
}

/* The material of that name this OBJ file's mtllibs gave, or -1. */
static long own_material(const obj *o, const char *name, size_t n)
{
    size_t at = 0;
    return names_find(&o->own, o->s, 'f', name, n, &at);
}

/* Which of the scene's materials named so a newmtl in MTL file `file`
   (its index in the registry) is (an earlier read of the same file made
   it, or an NFF `name` did, to override a mesh's material), or -1 for a
   new one: a material that another MTL file made is another material of
   the same name. */
static long mtl_existing(obj *o, size_t file, const char *name, size_t n)
{
    size_t at = 0;
    long i;
    while ((i = rtpi_reg_find(o->reg, o->s, 'f', name, n, &at)) >= 0) {
        uint32_t src = (size_t)i < o->reg->nsrc ? o->reg->src[i] : 0u;
        if (src == 0u || src == file + 1u)
            return i;
    }
    return -1;
}

/* Records that MTL file `file` made material m; 0, or -1. */
static int mtl_made(obj *o, size_t file, uint32_t m)
{
    rtpi_mtl_reg *r = o->reg;
    if (m >= r->nsrc) {
        if (rtpi_grow(&o->s->alloc, (void **)&r->src, &r->cap_src, (size_t)m + 1, sizeof *r->src))
            return -1;
        memset(r->src + r->nsrc, 0, ((size_t)m + 1 - r->nsrc) * sizeof *r->src);
        r->nsrc = (size_t)m + 1;
    }
    r->src[m] = (uint32_t)file + 1u;
    return 0;
}

/* The registry's index of MTL file `path` (taking it over) or of the same
   file under another spelling ("d/./x.mtl", "d/sub/../x.mtl": compared by
   device and inode), added if new; -1 when out of memory. */
static long mtl_file(obj *o, char *path)
{
    rtpi_mtl_reg *r = o->reg;
    struct stat sb;
    int has_id = stat(path, &sb) == 0;
    size_t k;
    for (k = 0; k < r->n; k++) {
        const rtpi_mtl_seen *e = &r->v[k];
        if (has_id && e->has_id ? e->dev == (unsigned long long)sb.st_dev &&
                                      e->ino == (unsigned long long)sb.st_ino
                                : strcmp(e->path, path) == 0) {
            rtpi_free(&o->s->alloc, path);
            return (long)k;
        }
    }
    if (rtpi_grow(&o->s->alloc, (void **)&r->v, &r->cap, r->n + 1, sizeof *r->v)) {
        rtpi_free(&o->s->alloc, path);
        return -1;
    }
    r->v[r->n].path = path;
    r->v[r->n].has_id = has_id;
    r->v[r->n].dev = has_id ? (unsigned long long)sb.st_dev : 0;
    r->v[r->n].ino = has_id ? (unsigned long long)sb.st_ino : 0;
    return (long)r->n++;
}

void rtpi_mtl_reg_free(rtpi_mtl_reg *r, const rtp_allocator *a)
{
    size_t i;
    for (i = 0; i < r->n; i++)
        rtpi_free(a, r->v[i].path);
    rtpi_free(a, r->v);
    rtpi_free(a, r->src);
    rtpi_free(a, r->mats.slot);
    rtpi_free(a, r->lights.slot);
    memset(r, 0, sizeof *r);
}

/* ------------------------------------------------------------------ MTL */

/* Whether t is word, letter case aside (exporters write map_Kd, map_kd,
   map_KD; Blender map_Bump). */
static int tok_is_nocase(const rtpi_tok *t, const char *word)
{
    size_t i, n = strlen(word);
    if (t->n != n)
        return 0;
    for (i = 0; i < n; i++)
        if (tolower((unsigned char)t->s[i]) != tolower((unsigned char)word[i]))
            return 0;
    return 1;
}

static int file_exists(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (f)
        fclose(f);
    return f != NULL;
}

/* The file a name in an OBJ or MTL file means, from the folder of base:
   the name as written, else with Windows' '\' read as '/' (3ds Max and
   Blender on Windows write "maps\brick.png"), else, for a Windows
   absolute name ("C:\Users\me\maps\brick.png", "\\server\maps\x.png"),
   its last part beside base, where such exports are usually copied with
   their textures.  @return the path (from the allocator) of a file that
   exists, NULL when none does or memory ran out (*nomem then 1). */
static char *find_file(const rtp_allocator *a, const char *base, const char *name, size_t n,
                       int *nomem)
{
    char *path = rtpi_path_join(a, base, name, n), *fixed;
    size_t i, last = 0;
    int abs;
    *nomem = path == NULL;
    if (!path || file_exists(path))
        return path;
    rtpi_free(a, path);
    if (!memchr(name, '\\', n))
        return NULL;
    fixed = (char *)rtpi_malloc(a, n + 1);
    if (!fixed) {
        *nomem = 1;
        return NULL;
    }
    for (i = 0; i < n; i++) {
        fixed[i] = name[i] == '\\' ? '/' : name[i];
        if (fixed[i] == '/')
            last = i + 1;
    }
    fixed[n] = '\0';
    abs = (n >= 3 && isalpha((unsigned char)name[0]) && name[1] == ':' && name[2] == '\\') ||
          (n >= 2 && name[0] == '\\' && name[1] == '\\');
    path = abs ? rtpi_path_join(a, base, fixed + last, n - last)
               : rtpi_path_join(a, base, fixed, n);
    rtpi_free(a, fixed);
    *nomem = path == NULL;
    if (path && !file_exists(path)) {
        rtpi_free(a, path);
        return NULL;
    }
    return path;
}

#define MAP_TOKENS 64 /* words on a map line: options and the name */

/* Where the file name begins on a map line of n words (at least 1): past
   MTL's options and their arguments (-o, -s and -t take one to three
   numbers; -mm two; the others one).  An unknown option is taken to have
   none, and *unknown set.  The name is at least the last word; *spent
   says that word is an option's argument (no name follows the options).
   *bad is the index of a bad number where -o, -s or -t may take one
   ("nan", "inf", "1e999": the name began there, "cannot load image 'nan 1
   t.png'"), or of an option's argument before the last word that is not
   what the option takes (*why: "on or off" for -blendu, -blendv, -cc and
   -clamp; "a number" for -boost, -texres and -mm's two; the channel for
   -imfchan; the map's shape for -type), else -1.  (The options are read
   and not applied: rtp maps an image over uv 0..1, repeated; scenes/
   README.md says so.  -bm, which is, is checked by mtl_map.) */
static int map_name_start(const rtpi_tok *tk, int n, int *unknown, int *spent, int *bad,
                          const char **why)
{
    /* each option of one argument: what it takes (NULL: -bm, mtl_map's),
       and the words that are it (words[w0..w1); none: a number) */
    static const char *const words[] = {"on",         "off",        "r",         "g",
                                        "b",          "m",          "l",         "z",
                                        "sphere",     "cube_top",   "cube_bottom",
                                        "cube_front", "cube_back",  "cube_left", "cube_right"};
    static const struct {
        const char *opt, *why;
        int w0, w1;
    } one[] = {{"-blendu", "on or off", 0, 2},
               {"-blendv", "on or off", 0, 2},
               {"-bm", NULL, 0, 0},
               {"-boost", "a number", 0, 0},
               {"-cc", "on or off", 0, 2},
               {"-clamp", "on or off", 0, 2},
               {"-imfchan", "r, g, b, m, l or z", 2, 8},
               {"-texres", "a number", 0, 0},
               {"-type", "sphere, cube_top, cube_bottom, cube_front, cube_back, cube_left or "
                         "cube_right", 8, 15}};
    int i = 0;
    *unknown = 0;
    *bad = -1;
    *why = NULL;
    while (i < n - 1 && tk[i].s[0] == '-') {
        const rtpi_tok *o = &tk[i++];
        size_t k;
        double d;
        if (rtpi_tok_is(o, "-o") || rtpi_tok_is(o, "-s") || rtpi_tok_is(o, "-t")) {
            for (k = 0; k < 3 && i < n - 1 && rtpi_tok_number(&tk[i], &d) == 0; k++)
                i++;
            if (k < 3 && i < n - 1 && *bad < 0 &&
                (rtpi_tok_nan_inf(&tk[i]) || rtpi_tok_number(&tk[i], &d) == -2))
                *bad = i;
        } else if (rtpi_tok_is(o, "-mm")) {
            /* (base and gain: numbers, where a word follows them) */
            for (k = 0; k < 2; k++, i++)
                if (i < n - 1 && *bad < 0 && rtpi_tok_number(&tk[i], &d) != 0) {
                    *bad = i;
                    *why = rtpi_tok_nan_inf(&tk[i]) || !rtpi_tok_numlike(&tk[i]) ? "a number"
                                                                                 : NULL;
                }
        } else {
            for (k = 0; k < sizeof one / sizeof *one; k++)
                if (rtpi_tok_is(o, one[k].opt))
                    break;
            if (k == sizeof one / sizeof *one) {
                *unknown = 1;
                continue;
            }
            /* the argument, where a word (the name) follows it */
            if (i < n - 1 && *bad < 0 && one[k].why) {
                int fits = 0, w;
                if (one[k].w0 == one[k].w1) {
                    int r = rtpi_tok_number(&tk[i], &d);
                    fits = r == 0;
                    if (r == -2 && !rtpi_tok_nan_inf(&tk[i]))
                        fits = -1; /* (out of range: said as -o's is) */
                } else {
                    for (w = one[k].w0; w < one[k].w1; w++)
                        fits |= rtpi_tok_is(&tk[i], words[w]);
                }
                if (fits <= 0) {
                    *bad = i;
                    *why = fits < 0 ? NULL : one[k].why;
                }
            }
            i++;
        }
    }
    *spent = i >= n;
    return i < n ? i : n - 1;
}

/* map_Kd / bump: options (-name args...) then the file name, which may
   hold spaces (Blender writes them unquoted): the longest run of the
   line's last words that names a file, else the name past the options
   (map_name_start), whose error then names it; -bm gives bump strength.  @return the image index via
   *index. */
static rtp_status mtl_map(rtpi_lex *lx, rtp_scene *s, const char *what,
                          uint32_t *index, double *bm)
{
    rtpi_tok tk[MAP_TOKENS], t, file;
    char *path = NULL;
    rtp_error inner;
    rtp_status st;
    int n = 0, i, from, start, unknown, spent, bad, oom;
    const char *why;
    while (rtpi_lex_next_inline(lx, &t)) {
        if (n == MAP_TOKENS)
            return rtpi_lex_error(lx, &t, "%s: more than %d words on the line", what,
                                  MAP_TOKENS);
        tk[n++] = t;
    }
    if (!n)
        return rtpi_lex_error(lx, &t, "unexpected end of line in %s, expected a file name",
                              what);
    /* The name is the rest of the line past the options (spaces and all:
       "map_Kd my tex.png" is never "tex.png"); after an option this
       reader does not know, whose arguments it cannot count, the longest
       run of the last words that names a file. */
    start = map_name_start(tk, n, &unknown, &spent, &bad, &why);
    if (bad >= 0) {
        char show[48], opt[12];
        for (i = bad - 1; i > 0 && tk[i].s[0] != '-'; i--)
            ;
        if (why)
            return rtpi_lex_error(lx, &tk[bad], "%s: %s takes %s, got '%s'", what,
                                  rtpi_tok_show(&tk[i], opt, sizeof opt), why,
                                  rtpi_tok_show(&tk[bad], show, sizeof show));
        return rtpi_lex_error(lx, &tk[bad],
                              rtpi_tok_nan_inf(&tk[bad]) ? "%s: expected number for %s, got '%s'"
                                                         : "%s: %s %s is out of range",
                              what, rtpi_tok_show(&tk[i], opt, sizeof opt),
                              rtpi_tok_show(&tk[bad], show, sizeof show));
    }
    for (from = start; from <= (unknown ? n - 1 : start); from++) {
        char *cand;
        file = tk[from]; /* (its line and column for a message) */
        file.n = (size_t)(tk[n - 1].s + tk[n - 1].n - tk[from].s);
        if (tk[from].s[0] == '-' || memchr(file.s, '\0', file.n))
            continue;
        if ((cand = find_file(&s->alloc, lx->name, file.s, file.n, &oom)) != NULL) {
            path = cand;
            break;
        }
        if (oom)
            return nomem(lx, &tk[from]);
    }
    if (!path) {
        /* the error names the whole name */
        from = start;
        file = tk[from];
        file.n = (size_t)(tk[n - 1].s + tk[n - 1].n - tk[from].s);
        /* the last word an option's argument, and no such file ("bump -bm
           2", "map_Kd -clamp on"): no name (the -bm check below said
           "expected a number after -bm" of a line that has one) */
        if (spent && !unknown)
            return rtpi_lex_error(lx, &tk[n - 1], "%s: expected a file name after the options",
                                  what);
        /* an option where the name should be: "bump -bm" lacks its
           number and its file, and "-bm" is no image to look for */
        if (file.s[0] == '-')
            return rtpi_lex_error(lx, &file,
                                  bm && rtpi_tok_is(&file, "-bm")
                                      ? "%s: expected a number after -bm, then a file name"
                                      : "%s: expected a file name after the options",
                                  what);
    }
    for (i = 0; bm && i < from; i++)
        if (rtpi_tok_is(&tk[i], "-bm")) {
            if (i + 1 >= from || rtpi_tok_number(&tk[i + 1], bm) != 0 || !isfinite(*bm)) {
                rtpi_free(&s->alloc, path);
                return rtpi_lex_error(lx, i + 1 < n ? &tk[i + 1] : &tk[i],
                                      "%s: expected a number after -bm", what);
            }
            /* (as every number these readers take: a strength past the
               float range was stored as inf, and the tree file written
               from it could not be read) */
            if (fabs(*bm) > VALUE_LIMIT) {
                char show[48], lim[32]; /* ('.' whatever the locale) */
                rtpi_free(&s->alloc, path);
                rtpi_fmt_g(lim, sizeof lim, 6, VALUE_LIMIT);
                return rtpi_lex_error(lx, &tk[i + 1], "%s: -bm %s is out of range (|x| <= %s)",
                                      what, rtpi_tok_show(&tk[i + 1], show, sizeof show), lim);
            }
        }
    /* A NUL would silently cut the name (the folder itself was read). */
    if (memchr(file.s, '\0', file.n))
        return rtpi_lex_error(lx, &file, "%s: a file name must not contain a NUL byte", what);
    if (!path && !(path = rtpi_path_join(&s->alloc, lx->name, file.s, file.n)))
        return nomem(lx, &file);
    memset(&inner, 0, sizeof inner);
    st = rtpi_scene_add_texture(s, path, 0, index, &inner);
    rtpi_free(&s->alloc, path);
    if (st != RTP_OK)
        return rtpi_lex_wrap(lx, &file, st, &inner, "cannot load image");
    return RTP_OK;
}

static int own_add(obj *o, uint32_t m)
{
    return names_put(&o->own, &o->s->alloc, o->s, 'f', m);
}

static rtp_status read_mtl(obj *o, const char *text, size_t size, const char *name,
                           size_t file)
{
    rtp_scene *s = o->s;
    rtp_error *err = o->err;
    rtpi_lex lx;
    rtpi_tok kw;
    char show[48];
    long cur = -1;     /* material being defined */
    int skipping = 0;  /* newmtl of a name the scene already has */
    rtp_status st = RTP_OK;
    rtpi_lex_init(&lx, text, size, name, err);
    lx.continuation = 1;
    while (st == RTP_OK && rtpi_lex_next(&lx, &kw)) {
        rtpi_material *m = cur >= 0 ? &s->mats[cur] : NULL;
        double v[3];
        rtpi_tok tk;
        if (rtpi_tok_is(&kw, "newmtl")) {
            rtpi_tok nt;
            rtpi_material def;
            char *nm;
            if ((st = line_string(&lx, "newmtl", &nt)) != RTP_OK)
                break;
            if (nt.n > 255) {
                /* (bytes, as a tree file holds it: a name of 128
                   two-byte characters was said to be over 255 characters) */
                st = rtpi_lex_error(&lx, &nt,
                                    "material name of %zu bytes: at most 255 (a tree file "
                                    "cannot hold more)",
                                    nt.n);
                break;
            }
            /* A name this OBJ's mtllibs gave already (the first wins), an
               NFF material's, or one this MTL file made when read before
               is that material; another MTL file's is not (mtl_existing) */
            cur = own_material(o, nt.s, nt.n);
            skipping = cur >= 0;
            if (skipping && memchr(nt.s + nt.n, '#', (size_t)(lx.p - (nt.s + nt.n)))) {
                /* "newmtl Material #26" after "newmtl Material #25": both
                   read "Material" (the comment cut them), and the second
                   was dropped, its faces in the first's colour */
                st = rtpi_lex_error(&lx, &nt,
                                    "newmtl '%.*s': a material of that name is defined "
                                    "already; a '#' after a blank starts a comment, which cut "
                                    "the name here (write it without the blank: '%.*s#...')",
                                    (int)nt.n, nt.s, (int)nt.n, nt.s);
                break;
            }
            if (skipping)
                continue;
            cur = mtl_existing(o, file, nt.s, nt.n);
            skipping = cur >= 0;
            if (skipping) {
                if (own_add(o, (uint32_t)cur) != 0)
                    return nomem(&lx, &nt);
                continue;
            }
            nm = (char *)rtpi_malloc(&s->alloc, nt.n + 1);
            if (!nm)
                return nomem(&lx, &nt);
            memcpy(nm, nt.s, nt.n);
            nm[nt.n] = '\0';
            rtpi_material_default(&def);
            def.name = nm;
            cur = rtpi_scene_add_material(s, &def);
            if (cur < 0) {
                rtpi_free(&s->alloc, nm);
                return nomem(&lx, &nt);
            }
            if (own_add(o, (uint32_t)cur) != 0 ||
                rtpi_reg_add(o->reg, s, 'f', (uint32_t)cur) != 0 ||
                mtl_made(o, file, (uint32_t)cur) != 0)
                return nomem(&lx, &nt);
            continue;
        }
        if (in_list(&kw, ignored_mtl_nums)) {
            if ((st = ignored_numbers(&lx, &kw)) != RTP_OK)
                break;
            continue;
        }
        rtpi_tok head = kw; /* (its first 4 letters: map_ in any case) */
        head.n = 4;
        if (in_list(&kw, ignored_mtl) ||
            (kw.n > 4 && tok_is_nocase(&head, "map_") && !tok_is_nocase(&kw, "map_Kd") &&
             !tok_is_nocase(&kw, "map_bump"))) {
            rtpi_lex_skip_line(&lx);
            continue;
        }
        if (!(rtpi_tok_is(&kw, "Kd") || rtpi_tok_is(&kw, "Ks") ||
              rtpi_tok_is(&kw, "Ns") || rtpi_tok_is(&kw, "Ni") ||
              rtpi_tok_is(&kw, "d") || rtpi_tok_is(&kw, "Tr") ||
              tok_is_nocase(&kw, "map_Kd") || tok_is_nocase(&kw, "bump") ||
              tok_is_nocase(&kw, "map_bump")))
            return rtpi_lex_error(&lx, &kw, "unknown MTL keyword '%s'",
                                  rtpi_tok_show(&kw, show, sizeof show));
        if (!m)
            return rtpi_lex_error(&lx, &kw, "%s before any newmtl",
                                  rtpi_tok_show(&kw, show, sizeof show));
        if (skipping) {
            rtpi_lex_skip_line(&lx);
            continue;
        }
        if (rtpi_tok_is(&kw, "Kd") || rtpi_tok_is(&kw, "Ks")) {
            const char *what = kw.s[1] == 'd' ? "Kd" : "Ks";
            int i;
            static const char *const rgb[3] = {"red", "green", "blue"};
            rtpi_tok ct[3];
            if ((st = line_val(&lx, what, "red", &v[0], &ct[0])) != RTP_OK)
                break;
            v[1] = v[2] = v[0];
            ct[1] = ct[2] = ct[0];
            {
                rtpi_lex save = lx;
                rtpi_tok peek;
                if (rtpi_lex_next_inline(&save, &peek) && rtpi_tok_numlike(&peek)) {
                    if ((st = line_val(&lx, what, "green", &v[1], &ct[1])) != RTP_OK ||
                        (st = line_val(&lx, what, "blue", &v[2], &ct[2])) != RTP_OK)
                        break;
                }
            }
            for (i = 0; i < 3; i++)
                if (v[i] < 0.0)
                    return rtpi_lex_error(&lx, &ct[i], "%s %s must not be negative, got %s",
                                          what, rgb[i], rtpi_tok_show(&ct[i], show, sizeof show));
            if ((st = line_rest(&lx, what, 1, 0)) != RTP_OK)
                break;
            if (what[1] == 'd') {
                /* kd carries the brightness, color the hue (max 1), so
                   mat.N.kd scales an MTL material like an NFF one. */
                double mx = v[0] > v[1] ? v[0] : v[1];
                mx = mx > v[2] ? mx : v[2];
                m->kd = (float)mx;
                for (i = 0; i < 3; i++)
                    m->color[i] = mx > 0.0 ? (float)(v[i] / mx) : 1.0f;
            } else {
                m->ks = (float)((v[0] + v[1] + v[2]) / 3.0);
            }
        } else if (rtpi_tok_is(&kw, "Ns") || rtpi_tok_is(&kw, "Ni") ||
                   rtpi_tok_is(&kw, "d") || rtpi_tok_is(&kw, "Tr")) {
            char what[8];
            rtpi_tok_show(&kw, what, sizeof what);
            if (what[0] == 'd') {
                /* (the standard's "d -halo F": a dissolve by the surface's
                   angle to the eye, which rtp's one kt a material cannot
                   hold; its number alone would be another material) */
                rtpi_lex save = lx;
                rtpi_tok peek;
                if (rtpi_lex_next_inline(&save, &peek) && rtpi_tok_is(&peek, "-halo"))
                    return rtpi_lex_error(&lx, &peek,
                                          "d -halo (a dissolve by the surface's angle to "
                                          "the eye) is not supported: give d a number "
                                          "alone (opacity, 0 to 1)");
            }
            if ((st = line_val(&lx, what, "value", &v[0], &tk)) != RTP_OK ||
                (st = line_rest(&lx, what, 1, 0)) != RTP_OK)
                break;
            if (v[0] < 0.0)
                return rtpi_lex_error(&lx, &tk, "%s must not be negative", what);
            if (what[0] == 'N' && what[1] == 's') {
                m->shine = (float)v[0];
            } else if (what[0] == 'N') {
                /* (0, or below the float range: 1, as NFF has it) */
                m->ior = (float)v[0] > 0.0f ? (float)v[0] : 1.0f;
            } else {
                /* d is opacity, Tr transparency; both in [0, 1]. */
                double tr = what[0] == 'd' ? 1.0 - v[0] : v[0];
                m->kt = (float)(tr < 0.0 ? 0.0 : tr > 1.0 ? 1.0 : tr);
            }
        } else if (tok_is_nocase(&kw, "map_Kd")) {
            uint32_t idx;
            if ((st = mtl_map(&lx, s, "map_Kd", &idx, NULL)) != RTP_OK)
                break;
            m = &s->mats[cur];
            m->tex = RTPI_TEX_IMAGE;
            m->tex_image = idx;
        } else { /* bump, map_bump */
            uint32_t idx;
            double bm = 1.0;
            if ((st = mtl_map(&lx, s, "bump", &idx, &bm)) != RTP_OK)
                break;
            m = &s->mats[cur];
            m->bump = RTPI_BUMP_IMAGE;
            m->bump_image = idx;
            m->bump_strength = (float)bm;
        }
    }
    return st;
}

/* One MTL file, `path` its name from the OBJ's folder; t its words. */
static rtp_status read_one_mtl(obj *o, const rtpi_tok *t, char *path)
{
    char *text = NULL;
    size_t size = 0;
    rtp_error inner;
    rtp_status st;
    long file;
    const char *name;
    memset(&inner, 0, sizeof inner);
    st = rtpi_read_file(&o->s->alloc, path, &text, &size, &inner);
    if (st != RTP_OK) {
        rtpi_free(&o->s->alloc, path);
        return rtpi_lex_wrap(&o->lx, t, st, &inner, "cannot read mtllib");
    }
    if (rtpi_scene_add_file(o->s, path) != 0) {
        rtpi_free(&o->s->alloc, path);
        rtpi_free(&o->s->alloc, text);
        return nomem(&o->lx, t);
    }
    /* (the registry takes path over; errors name the spelling read first) */
    if ((file = mtl_file(o, path)) < 0) {
        rtpi_free(&o->s->alloc, text);
        return nomem(&o->lx, t);
    }
    name = o->reg->v[file].path;
    st = read_mtl(o, text, size, name, (size_t)file);
    rtpi_free(&o->s->alloc, text);
    return st;
}

/* mtllib FILE...: several names, or one holding spaces (Blender writes
   the OBJ's own name unquoted: "mtllib my model.mtl"), read whole when
   the whole rest of the line names a file. */
static rtp_status read_mtllib(obj *o)
{
    rtpi_tok t, tk[MAP_TOKENS], whole;
    rtp_status st;
    int n = 0, i, oom;
    char *path;
    while (rtpi_lex_next_inline(&o->lx, &t)) {
        if (n == MAP_TOKENS)
            return rtpi_lex_error(&o->lx, &t, "mtllib: more than %d words on the line",
                                  MAP_TOKENS);
        /* A NUL would silently cut the name (the folder itself was read). */
        if (memchr(t.s, '\0', t.n))
            return rtpi_lex_error(&o->lx, &t, "mtllib: a file name must not contain a NUL byte");
        tk[n++] = t;
    }
    if (n > 1) {
        int some = 0;
        whole = tk[0];
        whole.n = (size_t)(tk[n - 1].s + tk[n - 1].n - tk[0].s);
        if ((path = find_file(&o->s->alloc, o->lx.name, whole.s, whole.n, &oom)) != NULL)
            return read_one_mtl(o, &whole, path);
        if (oom)
            return nomem(&o->lx, &whole);
        for (i = 0; i < n && !some; i++) {
            path = find_file(&o->s->alloc, o->lx.name, tk[i].s, tk[i].n, &oom);
            if (oom)
                return nomem(&o->lx, &tk[i]);
            some = path != NULL;
            rtpi_free(&o->s->alloc, path);
        }
        /* no word names a file either: the error names the whole name
           ("cannot read mtllib 'my model.mtl'", not 'my') */
        if (!some) {
            tk[0] = whole;
            n = 1;
        }
    }
    for (i = 0; i < n; i++) {
        path = find_file(&o->s->alloc, o->lx.name, tk[i].s, tk[i].n, &oom);
        if (!path && (oom || !(path = rtpi_path_join(&o->s->alloc, o->lx.name, tk[i].s,
                                                     tk[i].n))))
            return nomem(&o->lx, &tk[i]);
        if ((st = read_one_mtl(o, &tk[i], path)) != RTP_OK)
            return st;
    }
    return RTP_OK;
}

/* ------------------------------------------------------------------ OBJ */

static rtp_status read_vertex(obj *o, int kind)
{
    static const char *const xyz[] = {"x", "y", "z"};
    const char *what = kind == 'v' ? "v (vertex)" : kind == 'n' ? "vn (normal)"
                                                                 : "vt (texture vertex)";
    double p[3] = {0.0, 0.0, 0.0}, q[3];
    int i, need = kind == 't' ? 1 : 3;
    rtp_status st;
    rtpi_tok here;
    for (i = 0; i < need; i++)
        if ((st = line_num(&o->lx, what, kind == 't' ? "u" : xyz[i], &p[i],
                           NULL)) != RTP_OK)
            return st;
    if (kind == 't') {
        /* vt u [v [w]] */
        rtpi_lex save = o->lx;
        rtpi_tok peek;
        if (rtpi_lex_next_inline(&save, &peek) && rtpi_tok_numlike(&peek) &&
            (st = line_num(&o->lx, what, "v", &p[1], NULL)) != RTP_OK)
            return st;
    }
    /* v: optional w or r g b (read past); vt: optional w. */
    if ((st = line_rest(&o->lx, what, kind == 't' ? 2 : 3,
                        kind == 'v' ? 4 : kind == 't' ? 1 : 0)) != RTP_OK)
        return st;
    rtpi_lex_here(&o->lx, &here);
    if (kind == 'v') {
        rtpi_xform_point(o->xf, p, q);
        /* (the readers' bound on coordinates, 1e18, after the include's
           transform too: past it squares overflow, and past the float
           range the vertex is infinite) */
        if (!(fabs(q[0]) <= 1e18 && fabs(q[1]) <= 1e18 && fabs(q[2]) <= 1e18)) {
            char g[3][32]; /* '.' whatever the locale */
            rtpi_fmt_g(g[0], sizeof g[0], 6, q[0]);
            rtpi_fmt_g(g[1], sizeof g[1], 6, q[1]);
            rtpi_fmt_g(g[2], sizeof g[2], 6, q[2]);
            return rtpi_lex_error(&o->lx, &here,
                                  "vertex (%s, %s, %s) out of range after the include's "
                                  "transform (at most 1e18)",
                                  g[0], g[1], g[2]);
        }
        if (rtpi_scene_add_pos(o->s, q[0], q[1], q[2]))
            return nomem(&o->lx, &here);
        o->np++;
    } else if (kind == 'n') {
        if (o->xf) {
            for (i = 0; i < 3; i++)
                q[i] = o->nm[3 * i] * p[0] + o->nm[3 * i + 1] * p[1] +
                       o->nm[3 * i + 2] * p[2];
        } else {
            memcpy(q, p, sizeof q);
        }
        {
            rtpi_v3 n = rtpi_unit_normal(q[0], q[1], q[2]);
            if (rtpi_scene_add_nrm(o->s, n.x, n.y, n.z))
                return nomem(&o->lx, &here);
        }
        o->nn++;
    } else {
        if (rtpi_scene_add_uv(o->s, p[0], p[1]))
            return nomem(&o->lx, &here);
        o->nt++;
    }
    return RTP_OK;
}

/* One index of a face corner: s[0..n) relative to `count` read so far. */
static rtp_status corner_index(obj *o, const rtpi_tok *corner, size_t off,
                               size_t n, const char *kind, const char *kinds,
                               size_t count,
                               uint32_t base, uint32_t *out, const char *elem)
{
    rtpi_tok t = *corner;
    long v;
    char show[48];
    t.s += off;
    t.n = n;
    t.col += (int)off;
    if (rtpi_tok_int(&t, &v) != 0)
        return rtpi_lex_error(&o->lx, &t, "expected %s index in %s, got '%s'",
                              kind, elem, rtpi_tok_show(&t, show, sizeof show));
    if (v == 0)
        return rtpi_lex_error(&o->lx, &t, "%s index 0 is invalid (OBJ indices start at 1)",
                              kind);
    if (v > 0 ? (size_t)v > count : (size_t)(-v) > count)
        return rtpi_lex_error(&o->lx, &t, "%s index %ld out of range (%zu %s so far)",
                              kind, v, count, count == 1 ? kind : kinds);
    *out = base + (uint32_t)(v > 0 ? (size_t)v - 1 : count - (size_t)(-v));
    return RTP_OK;
}

/* l (a line: vertices v or v/vt, two or more) and p (points: vertices
   v, one or more): not drawn, as rtp traces surfaces and a line or a
   point has no area a ray could hit, but their indices are checked as a
   face's (a vertex that is not there, an index 0, "1//2") at the index:
   they were read past unchecked while the same index in an f was an
   error, and a file that holds one is malformed whatever rtp draws. */
static rtp_status read_element(obj *o, const rtpi_tok *kw, int line)
{
    const char *elem = line ? "line" : "point";
    rtpi_tok t;
    size_t n = 0, a;
    uint32_t idx;
    rtp_status st;
    while (rtpi_lex_next_inline(&o->lx, &t)) {
        for (a = 0; a < t.n && t.s[a] != '/'; a++)
            ;
        if ((st = corner_index(o, &t, 0, a, "vertex", "vertices", o->np, o->base_p, &idx,
                               elem)) != RTP_OK)
            return st;
        if (a < t.n) {
            if (!line || a + 1 == t.n || memchr(t.s + a + 1, '/', t.n - a - 1)) {
                char show[48];
                return rtpi_lex_error(&o->lx, &t, "malformed %s vertex '%s' (%s)", elem,
                                      rtpi_tok_show(&t, show, sizeof show),
                                      line ? "v or v/vt" : "v alone");
            }
            if ((st = corner_index(o, &t, a + 1, t.n - a - 1, "texture vertex",
                                   "texture vertices", o->nt, o->base_t, &idx, elem)) !=
                RTP_OK)
                return st;
        }
        n++;
    }
    if (n < (line ? 2u : 1u))
        return rtpi_lex_error(&o->lx, kw, "%s has %zu vert%s, needs at least %d", elem, n,
                              n == 1 ? "ex" : "ices", line ? 2 : 1);
    return RTP_OK;
}

/* s: a smoothing group, a number (0 is none) or off (on, as some
   exporters write, taken too), checked and not applied: normals come from
   vn or the face itself, so a mesh without vn renders faceted whatever
   its groups (smoothing them would average the normals of the faces that
   share a vertex and a group: not done).  The number is not used, so any
   run of digits is taken: exporters write groups as bit masks up to
   4294967295, which rtpi_tok_int's 2^31-1 had refused as "not a number,
   0 or more".  "s" alone, "s -1", "s 1.5" or a second word is an error
   at it. */
static int all_digits(const rtpi_tok *t)
{
    size_t i = t->n && t->s[0] == '+' ? 1 : 0;
    if (i == t->n)
        return 0;
    for (; i < t->n; i++)
        if (t->s[i] < '0' || t->s[i] > '9')
            return 0;
    return 1;
}

static rtp_status read_smoothing(obj *o, const rtpi_tok *kw)
{
    rtpi_tok t;
    char show[48];
    if (!rtpi_lex_next_inline(&o->lx, &t))
        return rtpi_lex_error(&o->lx, kw, "s: expected a smoothing group (a number, or off)");
    if (!rtpi_tok_is(&t, "off") && !rtpi_tok_is(&t, "on") && !all_digits(&t))
        return rtpi_lex_error(&o->lx, &t,
                              "s: expected a smoothing group (a number, 0 or more, or off), "
                              "got '%s'",
                              rtpi_tok_show(&t, show, sizeof show));
    if (rtpi_lex_next_inline(&o->lx, &t))
        return rtpi_lex_error(&o->lx, &t, "unexpected '%s' at the end of s",
                              rtpi_tok_show(&t, show, sizeof show));
    return RTP_OK;
}

static int zero_normal(const rtp_scene *s, uint32_t n)
{
    const float *f = s->nrm + 3 * (size_t)n;
    return f[0] == 0.0f && f[1] == 0.0f && f[2] == 0.0f;
}

static rtp_status read_face(obj *o, const rtpi_tok *kw)
{
    rtpi_tok t;
    size_t n = 0, i, k, ntri;
    int has_t = 1, has_n = 1;
    rtp_status st;
    while (rtpi_lex_next_inline(&o->lx, &t)) {
        size_t a, b;
        uint32_t *c;
        if (n >= RTPI_POLY_MAX)
            return rtpi_lex_error(&o->lx, &t, "face has more than %d vertices",
                                  RTPI_POLY_MAX);
        if (rtpi_grow(&o->s->alloc, (void **)&o->crn, &o->cap_crn, 3 * (n + 1),
                      sizeof *o->crn) ||
            rtpi_grow(&o->s->alloc, (void **)&o->pts, &o->cap_pts, 3 * (n + 1),
                      sizeof *o->pts))
            return nomem(&o->lx, &t);
        c = o->crn + 3 * n;
        c[1] = c[2] = RTPI_NONE;
        for (a = 0; a < t.n && t.s[a] != '/'; a++)
            ;
        if ((st = corner_index(o, &t, 0, a, "vertex", "vertices", o->np, o->base_p, &c[0],
                                "face")) != RTP_OK)
            return st;
        if (a < t.n) {
            for (b = a + 1; b < t.n && t.s[b] != '/'; b++)
                ;
            if (b > a + 1 && (st = corner_index(o, &t, a + 1, b - a - 1, "texture vertex",
                                                "texture vertices", o->nt, o->base_t, &c[1],
                                                "face")) != RTP_OK)
                return st;
            if (b < t.n && (st = corner_index(o, &t, b + 1, t.n - b - 1, "normal",
                                              "normals", o->nn, o->base_n, &c[2],
                                              "face")) != RTP_OK)
                return st;
            if (b == a + 1 && b == t.n) {
                char show[48];
                return rtpi_lex_error(&o->lx, &t, "malformed face vertex '%s'",
                                      rtpi_tok_show(&t, show, sizeof show));
            }
        }
        has_t &= c[1] != RTPI_NONE;
        has_n &= c[2] != RTPI_NONE && !zero_normal(o->s, c[2]);
        for (k = 0; k < 3; k++)
            o->pts[3 * n + k] = o->s->pos[3 * (size_t)c[0] + k];
        n++;
    }
    if (n < 3)
        return rtpi_lex_error(&o->lx, kw, "face has %zu vert%s, needs at least 3",
                              n, n == 1 ? "ex" : "ices");
    o->faces++;
    if (o->mat == RTPI_NONE) {
        if (o->default_mat == RTPI_NONE) {
            rtpi_material def;
            long m;
            rtpi_material_default(&def);
            m = rtpi_scene_add_material(o->s, &def);
            if (m < 0)
                return nomem(&o->lx, kw);
            o->default_mat = (uint32_t)m;
        }
        o->mat = o->default_mat;
    }
    if (rtpi_grow(&o->s->alloc, (void **)&o->tri, &o->cap_tri, 3 * n,
                  sizeof *o->tri))
        return nomem(&o->lx, kw);
    if (n == 3) {
        o->tri[0] = 0;
        o->tri[1] = 1;
        o->tri[2] = 2;
        ntri = 1;
    } else {
        ntri = rtpi_triangulate(o->pts, n, o->tri);
    }
    for (i = 0; i < ntri; i++) {
        rtpi_tri tr;
        for (k = 0; k < 3; k++) {
            /* (mirrored: corners 0, 2, 1, so the face keeps its side) */
            const uint32_t *c = o->crn + 3 * (size_t)o->tri[3 * i + (o->flip && k ? 3 - k : k)];
            tr.v[k] = c[0];
            tr.t[k] = has_t ? c[1] : RTPI_NONE;
            tr.n[k] = has_n ? c[2] : RTPI_NONE;
        }
        tr.mat = o->mat;
        if (rtpi_scene_add_tri(o->s, &tr))
            return nomem(&o->lx, kw);
    }
    return RTP_OK;
}

static rtp_status read_usemtl(obj *o)
{
    rtpi_tok t;
    long m;
    char show[80];
    rtp_status st = line_string(&o->lx, "usemtl", &t);
    if (st != RTP_OK)
        return st;
    /* this file's MTL's material first, then any of the name (an NFF
       material's, or one an MTL read before gave) */
    m = own_material(o, t.s, t.n);
    if (m < 0)
        m = find_material(o, t.s, t.n);
    if (m < 0)
        return rtpi_lex_error(&o->lx, &t,
                              "unknown material '%s' (no newmtl of that name in the mtllib files read so far)",
                              rtpi_tok_show(&t, show, sizeof show));
    o->mat = (uint32_t)m;
    return RTP_OK;
}

rtp_status rtpi_read_obj_reg(rtp_scene *s, const char *text, size_t size,
                             const char *name, const double *xform,
                             uint32_t default_mat, size_t *faces,
                             rtpi_mtl_reg *reg, rtp_error *err)
{
    obj o;
    rtpi_tok kw;
    char show[48];
    rtp_status st = RTP_OK;
    rtpi_mtl_reg local;
    memset(&o, 0, sizeof o);
    memset(&local, 0, sizeof local);
    o.s = s;
    o.err = err;
    o.reg = reg ? reg : &local;
    rtpi_lex_init(&o.lx, text, size, name ? name : "<memory>", err);
    o.lx.continuation = 1;
    if (xform) {
        if (rtpi_xform_normal_matrix(xform, o.nm) != 0)
            return rtpi_error(err, RTP_ERR_ARGUMENT, o.lx.name, 0, 0,
                              "singular transform");
        o.xf = xform;
        o.flip = rtpi_xform_mirrors(xform);
    }
    o.base_p = (uint32_t)s->npos;
    o.base_n = (uint32_t)s->nnrm;
    o.base_t = (uint32_t)s->nuv;
    o.mat = RTPI_NONE;
    o.default_mat = default_mat;
    while (st == RTP_OK && rtpi_lex_next(&o.lx, &kw)) {
        if (rtpi_tok_is(&kw, "v"))
            st = read_vertex(&o, 'v');
        else if (rtpi_tok_is(&kw, "vn"))
            st = read_vertex(&o, 'n');
        else if (rtpi_tok_is(&kw, "vt"))
            st = read_vertex(&o, 't');
        else if (rtpi_tok_is(&kw, "f"))
            st = read_face(&o, &kw);
        else if (rtpi_tok_is(&kw, "usemtl"))
            st = read_usemtl(&o);
        else if (rtpi_tok_is(&kw, "mtllib"))
            st = read_mtllib(&o);
        else if (rtpi_tok_is(&kw, "vp"))
            st = ignored_numbers(&o.lx, &kw);
        else if (rtpi_tok_is(&kw, "l") || rtpi_tok_is(&kw, "p"))
            st = read_element(&o, &kw, rtpi_tok_is(&kw, "l"));
        else if (rtpi_tok_is(&kw, "s"))
            st = read_smoothing(&o, &kw);
        else if (in_list(&kw, ignored_obj))
            rtpi_lex_skip_line(&o.lx);
        else
            st = rtpi_lex_error(&o.lx, &kw, "unknown OBJ keyword '%s'",
                                rtpi_tok_show(&kw, show, sizeof show));
    }
    rtpi_free(&s->alloc, o.pts);
    rtpi_free(&s->alloc, o.crn);
    rtpi_free(&s->alloc, o.tri);
    rtpi_free(&s->alloc, o.own.slot);
    rtpi_mtl_reg_free(&local, &s->alloc);
    if (faces)
        *faces = o.faces;
    return st;
}

rtp_status rtpi_read_obj_ex(rtp_scene *s, const char *text, size_t size,
                            const char *name, const double *xform,
                            uint32_t default_mat, size_t *faces,
                            rtp_error *err)
{
    return rtpi_read_obj_reg(s, text, size, name, xform, default_mat, faces, NULL, err);
}

rtp_status rtpi_read_obj(rtp_scene *s, const char *text, size_t size,
                         const char *name, const double *xform,
                         uint32_t default_mat, rtp_error *err)
{
    return rtpi_read_obj_ex(s, text, size, name, xform, default_mat, NULL, err);
}
