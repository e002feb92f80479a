/*
 * internal.h — what the files of librtp share and nothing else sees.
 *
 * Flow: readers (nff.c, obj.c, bezier.c) -> scene (scene.c) -> kd-tree
 * (kdtree.c, intersect.c) -> trace (trace.c) -> shade (shade.c).
 * Internal names use the rtpi_ prefix (or are static).
 */
#ifndef RTP_INTERNAL_H
#define RTP_INTERNAL_H

#include "rtp.h"

#include <math.h>
#include <float.h>
#include <stdint.h>
#include <string.h>

/* Inline whatever the compiler's heuristics say, where a call costs as
   much as the work (kd-tree traversal, per-sample sums). */
#if defined(__GNUC__)
#define RTPI_FORCE_INLINE __attribute__((always_inline)) inline
#else
#define RTPI_FORCE_INLINE inline
#endif
/* Asks for the cache line `bytes` past p before a loop reads it, where
   the loop's walk is one the hardware does not foresee in time (tree.c:
   LQ_AHEAD, CP_AHEAD); nothing where the compiler has no such call.  The
   address is made as an integer: it may lie past the array's end near
   the end of a walk, where a prefetch does nothing (it never faults) but
   a pointer made there would be undefined. */
#if defined(__GNUC__)
#define RTPI_PREFETCH(p, bytes) __builtin_prefetch((const void *)((uintptr_t)(p) + (bytes)))
#else
#define RTPI_PREFETCH(p, bytes) ((void)(p), (void)(bytes))
#endif

/* Built with AddressSanitizer: the default allocator then leaves every
   block to malloc (util.c), whose checks its own mappings would escape. */
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define RTPI_ASAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define RTPI_ASAN 1
#endif
/* Built with ThreadSanitizer, the same: it sees mmap and munmap, not
   mremap (gcc 12's libtsan, clang 14's), so a mapping moved off a range
   or grown in place over it left the range's old accesses in its shadow,
   and another thread's block made there later was a data race reported
   where none is (make tsan: test_trees_outgrow_limit's two workers'
   trees, every run). */
#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define RTPI_TSAN 1
#endif
#endif
#if defined(__SANITIZE_THREAD__)
#define RTPI_TSAN 1
#endif

/* ------------------------------------------------------------ allocation */

void *rtpi_malloc(const rtp_allocator *a, size_t size);
void *rtpi_realloc(const rtp_allocator *a, void *p, size_t size);
void rtpi_free(const rtp_allocator *a, void *p);
/* count*size with overflow check; NULL on overflow or failure. */
void *rtpi_malloc_array(const rtp_allocator *a, size_t count, size_t size);
void *rtpi_calloc_array(const rtp_allocator *a, size_t count, size_t size);
/* Makes the pages of n bytes at p (a block from a, about to be written
   whole) in one call where a is the default allocator (util.c). */
void rtpi_prefault(const rtp_allocator *a, void *p, size_t n);
/* Grows *p (of *cap elements of `size`) to hold at least `need`; doubles.
   @return 0 on success, -1 on overflow or allocation failure (*p kept). */
int rtpi_grow(const rtp_allocator *a, void **p, size_t *cap, size_t need,
              size_t size);
/* The capacity rtpi_grow gives a block of cap elements to hold need
   (more than cap), so that a caller can count it first; 0 on overflow. */
size_t rtpi_grow_cap(size_t cap, size_t need);
char *rtpi_strdup(const rtp_allocator *a, const char *s);
/* Fills `*out` with the default allocator when `in` is NULL. */
/* Whether an allocator has some of its three functions and not all (a
   zeroed one is the library's own, as NULL is); rtpi_allocator_refused
   says so as RTP_ERR_ARGUMENT for function fn. */
int rtpi_allocator_partial(const rtp_allocator *a);
rtp_status rtpi_allocator_refused(rtp_error *err, const char *fn);
void rtpi_allocator_init(rtp_allocator *out, const rtp_allocator *in);

/* ---------------------------------------------------------------- errors */

/* Sets err (if not NULL) and returns status.  file may be NULL. */
/* Numbers in scene files, keys and values are written with '.' whatever
   the C library's LC_NUMERIC says: a host program may have set a locale
   whose decimal point is ',' (setlocale(LC_ALL, "")), where strtod stops
   at the '.' and printf writes ','.  rtpi_strtod is strtod reading '.',
   rtpi_fmt_g is snprintf's "%.*g" writing '.' (util.c). */
double rtpi_strtod(const char *s, char **end);
void rtpi_fmt_g(char *out, size_t size, int prec, double v);
/* bytes in MiB for a message that something needs them, rounded up: to
   a whole MiB from 100 up, else to 3 significant digits (util.c) */
double rtpi_mib_up(double bytes);

rtp_status rtpi_error(rtp_error *err, rtp_status status, const char *file,
                      int line, int col, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 6, 7)))
#endif
    ;
/* text into dst (size bytes, NUL-terminated): whole where it fits, else
   its start and its end with "..." between (whole 0: text is only the
   start of a longer one, said as its start and "..."), each cut at a
   UTF-8 character's first byte.  For rtp_error's message. */
void rtpi_fit_text(char *dst, size_t size, const char *text, int whole);

/* ---------------------------------------------------------------- vectors */

typedef struct rtpi_v3 {
    double x, y, z;
} rtpi_v3;

static inline rtpi_v3 v3(double x, double y, double z)
{
    rtpi_v3 r;
    r.x = x;
    r.y = y;
    r.z = z;
    return r;
}
static inline rtpi_v3 v3_add(rtpi_v3 a, rtpi_v3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline rtpi_v3 v3_sub(rtpi_v3 a, rtpi_v3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline rtpi_v3 v3_mul(rtpi_v3 a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline rtpi_v3 v3_madd(rtpi_v3 a, rtpi_v3 b, double s) { return v3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s); }
static inline double v3_dot(rtpi_v3 a, rtpi_v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline rtpi_v3 v3_cross(rtpi_v3 a, rtpi_v3 b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double v3_len(rtpi_v3 a) { return sqrt(v3_dot(a, a)); }
static inline rtpi_v3 v3_norm(rtpi_v3 a)
{
    double l = v3_len(a);
    return l > 0.0 ? v3_mul(a, 1.0 / l) : a;
}
static inline double v3_get(rtpi_v3 a, int axis) { return axis == 0 ? a.x : axis == 1 ? a.y : a.z; }
static inline rtpi_v3 v3_from_f(const float *f) { return v3(f[0], f[1], f[2]); }

/* ----------------------------------------------------------------- scene */

#define RTPI_NONE 0xffffffffu

/* The magnitudes a scene's numbers may have, the same whether a scene
   file or a key (rtp_scene_set, rtp_tree_set, --add-light) gives them.
   RTPI_COORD_LIMIT: geometry and the camera (coordinates, radii, a
   transform's numbers, from/at/up and hither): squares and products of
   coordinates must stay finite.  RTPI_VALUE_LIMIT: what is kept as a
   float and only scaled (colours, coefficients, the exponent, ior, the
   checker's and a bump's numbers, a light's position, which shading
   works in double, a far light being a direction): float's range.  (A
   key took 3.4e38 for every one while a file stopped at 1e18: the same
   material was given by a key and not in its file, and a camera at
   1e30 by key only.) */
#define RTPI_COORD_LIMIT 1e18
#define RTPI_VALUE_LIMIT 3.4e38

/* Triangle: indices into the scene's position/normal/uv arrays.  n[] and
   t[] are RTPI_NONE when the triangle has no vertex normals / uvs.  The
   geometric normal is (p1-p0)x(p2-p0), counter-clockwise = front. */
typedef struct rtpi_tri {
    uint32_t v[3], n[3], t[3];
    uint32_t mat;
} rtpi_tri;

/* Sphere; r < 0: only the inside is visible (NFF negative radius). */
typedef struct rtpi_sphere {
    float c[3], r;
    uint32_t mat;
} rtpi_sphere;

/* Open cone or cylinder (no caps) from base (radius rb) to apex (ra). */
typedef struct rtpi_cone {
    float base[3], rb, apex[3], ra;
    uint32_t mat;
} rtpi_cone;

/* A cone's axis frame in double, derived from its floats once (every ray
   test and surface normal needs it; deriving it each time, a square root
   and two divisions, was a fifth of a shadow ray's work on rings): unit
   axis w from base b to the apex, height h, end radii rb and ra, slope k
   (radius change per unit height); ok 0 where the cone has no height or
   radius, or is too long to handle (never hit). */
typedef struct rtpi_cone_frame {
    rtpi_v3 b, w;
    double h, rb, ra, k;
    rtpi_v3 mid;  /* the axis' middle, b + w h/2 */
    double bound; /* a radius about mid the cone lies within, with margin */
    int ok;
} rtpi_cone_frame;

typedef enum rtpi_tex_kind {
    RTPI_TEX_NONE = 0,
    RTPI_TEX_CHECKER = 1, /* solid 3D checker: colour / color2, cell size */
    RTPI_TEX_IMAGE = 2    /* image[tex_image] looked up by uv */
} rtpi_tex_kind;

typedef enum rtpi_bump_kind {
    RTPI_BUMP_NONE = 0,
    RTPI_BUMP_IMAGE = 1,  /* height map image[bump_image], by uv */
    RTPI_BUMP_WAVES = 2,  /* procedural: sum of sines, period bump_scale */
    RTPI_BUMP_NOISE = 3   /* procedural: value noise, cell bump_scale */
} rtpi_bump_kind;

typedef struct rtpi_material {
    float color[3];
    float kd, ks, shine, kt, ior;
    char *name; /* NULL if unnamed */
    rtpi_tex_kind tex;
    float color2[3];   /* checker's second colour */
    float tex_scale;   /* checker cell size (world units) */
    uint32_t tex_image;
    rtpi_bump_kind bump;
    uint32_t bump_image;
    float bump_strength, bump_scale;
    /* The ambient coefficient ka per channel (mat.N.ambient, NFF's ka),
       where ka_set: I_a = ambient ka c_obj.  Unset (0, every material
       until a key or file sets it, and after mat.N.ambient=kd, which
       zeroes ka too), ka is kd, read at evaluation: a kd
       edit moves the ambient part too, and the sums are today's to the
       bit (shade.c node_coeffs). */
    float ka[3];
    int ka_set;
} rtpi_material;

typedef struct rtpi_light {
    double pos[3];
    float color[3];
    int on;
    char *name; /* NULL if unnamed */
} rtpi_light;

typedef struct rtpi_camera {
    double from[3], at[3], up[3];
    double angle;  /* full field of view, degrees */
    double hither;
} rtpi_camera;

/* A texture or bump map.  Its pixels are read only once made, and shared
   by the scenes cloned from one (rtpi_scene_clone: a tree's, a
   builder's) through share, which counts them: rtp trace -o had held a
   4096x4096 bump map twice, the scene's and its tree's (200 MB).  The
   last to let go frees them (rtpi_texture_release). */
typedef struct rtpi_texshare rtpi_texshare;
typedef struct rtpi_texture {
    char *path;
    rtp_image *image;
    rtpi_texshare *share; /* NULL: image is this scene's alone */
    double max_abs; /* the largest |texel|: the plane paths' bound (tree.c mat_in_range) */
} rtpi_texture;

struct rtp_scene {
    rtp_allocator alloc;
    rtpi_camera camera;
    int width, height;
    float background[3];
    float ambient[3];
    double light_scale; /* every light's colour is multiplied by this:
                           sqrt(L)/(2L) for L lights, SPD's advice */
    int has_camera;     /* 0: frame the bounds (an OBJ on its own) */
    /* An NFF v block's camera that makes no view (at equal to from: [0];
       up zero or along the view: [1]), said as reading it would have,
       at its token: the check waits until a frame is made, after the
       keys (--set camera.at=... repairs such a file).  cam_bad[k] 0: no
       such error, or a key set the camera since (camera.from and .at
       clear both, .up [1]). */
    rtp_error cam_err[2];
    int cam_bad[2];

    float *pos;  size_t npos, cap_pos;   /* xyz per vertex */
    float *nrm;  size_t nnrm, cap_nrm;   /* xyz per normal */
    float *uv;   size_t nuv, cap_uv;     /* uv per texture vertex */

    /* Primitive ids: [0, ntris) triangles, then spheres, then cones. */
    rtpi_tri *tris;       size_t ntris, cap_tris;
    rtpi_sphere *spheres; size_t nspheres, cap_spheres;
    rtpi_cone *cones;     size_t ncones, cap_cones;
    rtpi_cone_frame *cframes; size_t cap_cframes; /* one per cone */
    double *pbounds; size_t npbounds; /* rtpi_prim_bounds of every
                                  primitive (lo, hi: 6 each) for the
                                  direction cubes, which ask them 3 times a
                                  primitive a move; made by
                                  rtpi_scene_bounds (npbounds: the
                                  primitives then), else NULL */
    /* Made with pbounds (valid where it is): what every move of a light
       asks of every primitive, which stays while the geometry does (a
       light buffer's windows, scale and candidates: gears' three passes
       over 36,610 primitives, 4% of a move) */
    unsigned char *phit; /* per primitive: rtpi_prim_hittable */
    double pbabs;        /* the largest |lo|, |hi| of every primitive's
                            bounds (0 where none) */
    double phlo[3], phhi[3]; /* the bounds of the hittable primitives
                                (HUGE_VAL, -HUGE_VAL where none is) */
    int phany;           /* some primitive is hittable */

    rtpi_material *mats;  size_t nmats, cap_mats;
    rtpi_light *lights;   size_t nlights, cap_lights;
    rtpi_texture *texs;   size_t ntexs, cap_texs;
    /* The files read besides the scene's own (include and bezier files,
       mtllibs), as resolved from its folder, in the order read:
       rtp_scene_get's file.N, so that a caller does not write over them
       (`rtp trace s.nff -o mesh.obj` replaced the included mesh).  A
       clone (a tree's scene) has none: a tree reads no file. */
    char **files;         size_t nfiles, cap_files;
};

/* scene.c: creation and appending; each returns 0 or -1 (out of memory). */
rtp_status rtpi_scene_create(const rtp_allocator *alloc, rtp_scene **out);
int rtpi_scene_add_file(rtp_scene *s, const char *path);
int rtpi_scene_add_pos(rtp_scene *s, double x, double y, double z);
int rtpi_scene_add_nrm(rtp_scene *s, double x, double y, double z);
int rtpi_scene_add_uv(rtp_scene *s, double u, double v);
int rtpi_scene_add_tri(rtp_scene *s, const rtpi_tri *t);
int rtpi_scene_add_sphere(rtp_scene *s, const rtpi_sphere *sp);
int rtpi_scene_add_cone(rtp_scene *s, const rtpi_cone *c);
/* Derives cframes for every cone (cones put in place by other means than
   rtpi_scene_add_cone); 0 or -1. */
int rtpi_scene_cone_frames(rtp_scene *s);
/* Adds a material with NFF defaults; returns its index or -1. */
long rtpi_scene_add_material(rtp_scene *s, const rtpi_material *m);
long rtpi_scene_add_light(rtp_scene *s, const rtpi_light *l);
/* A white light, on, at pos (rtp_tree_add_light's, a light.N.pos key's
   naming the next light): its index, or -1 out of memory. */
long rtpi_scene_add_white_light(rtp_scene *s, const double pos[3]);
/* Loads (once per path, or with fresh each time: a key's image, kept
   apart unless the scene holds the same pixels under that name) a PNG,
   PPM or PFM texture; returns its index via *index. */
rtp_status rtpi_scene_add_texture(rtp_scene *s, const char *path, int fresh,
                                  uint32_t *index, rtp_error *err);
/* A deep copy of s with the same allocator. */
rtp_status rtpi_scene_clone(const rtp_scene *s, rtp_scene **out);
/* rtp_scene_set without what follows it there: */
rtp_status rtpi_scene_set(rtp_scene *s, const char *key, const char *value, rtp_error *err);
/* Frees the pixels of textures no material uses (an image texture or
   bump map now; mats0, when given: a tree's bump maps as traced, which
   --stale keep and class-D re-traces still use): a stream of texture
   edits kept every image it replaced.  The slot stays, its index never
   reused (caches compare materials by index), its image NULL. */
void rtpi_scene_drop_textures(rtp_scene *s, const rtpi_material *mats0);
/* Makes t's image shareable by clones (its count 1), allocating with a;
   in a build without threads, nothing (no lock to count under: clones
   copy the image).  @return 0, or -1 when out of memory (t as it was). */
int rtpi_texture_share(const rtp_allocator *a, rtpi_texture *t);
/* Lets go of t's image (freed when no other scene holds it); t's image
   and share become NULL. */
void rtpi_texture_release(rtpi_texture *t);
/* A new file beside path to write and then rename over it: a name of
   its own (tmp, tmpsize >= strlen(path) + 32 bytes) made with O_EXCL,
   so writers of one path at once never share it; the mode of a file
   already at path.  NULL with errno on failure. */
FILE *rtpi_open_temp(const char *path, char *tmp, size_t tmpsize);
/* Durability, POSIX (nothing elsewhere): rtpi_sync_file flushes f and
   fsyncs it, so that a rename after it cannot leave an empty file after a
   crash; rtpi_sync_dir fsyncs the folder holding path, so that the
   rename itself lasts.  A file system that refuses fsync (EINVAL: a pipe,
   some network and special file systems) is skipped quietly, as is a
   folder rtp may not open.  @return 0, else errno. */
int rtpi_sync_file(FILE *f);
int rtpi_sync_dir(const char *path);
/* How a file at path is written: RTPI_WRITE_FILE beside it and renamed
   over it (a regular file or none yet), RTPI_WRITE_IN_PLACE (a FIFO, a
   device, a pipe behind /dev/fd/N: never replaced by a rename), or
   RTPI_WRITE_STDOUT (the very file stdout is, as /dev/stdout names it,
   a file, pipe or terminal: written through stdout, so that '>>' still
   appends, no link in /dev is replaced and the bytes follow what the
   caller printed to stdout before), or RTPI_WRITE_APPEND (a
   regular file named through /proc/PID/fd or /dev/fd: another open
   file, as 2>>log makes stderr: appended to, never replaced). */
enum { RTPI_WRITE_FILE, RTPI_WRITE_IN_PLACE, RTPI_WRITE_STDOUT, RTPI_WRITE_APPEND };
int rtpi_write_kind(const char *path);
/* The file a write to `path` replaces: path itself, or where a symbolic
   link at path leads (a chain followed; a dangling link's target name),
   so that a write through a link changes the file it names rather than
   turning the link into a file, in *out (allocated with a); err set when
   out of memory, when the chain loops, or when the file there may not
   be written (a read-only file in a writable folder: what the shell's
   '>' refuses, rename would have replaced). */
rtp_status rtpi_write_target(const rtp_allocator *a, const char *path, char **out,
                             rtp_error *err);

/* What is wrong with s's camera for a frame to be made (at equal to
   from, up along the view), or NULL. */
const char *rtpi_camera_problem(const rtp_scene *s);
/* The error for s's camera problem, RTP_ERR_ARGUMENT: the v block's (its
   file, line and column) while no key has set what it left wrong, else
   "[fn: ]<problem>: <what>" ("no view to trace"). */
rtp_status rtpi_camera_error(const rtp_scene *s, const char *fn, const char *what,
                             rtp_error *err);
/* A material with default values (white, kd 1). */
void rtpi_material_default(rtpi_material *m);

static inline size_t rtpi_scene_nprims(const rtp_scene *s)
{
    return s->ntris + s->nspheres + s->ncones;
}

/* The material of a primitive. */
static inline uint32_t rtpi_prim_material(const rtp_scene *s, uint32_t prim)
{
    if (prim < s->ntris)
        return s->tris[prim].mat;
    prim -= (uint32_t)s->ntris;
    if (prim < s->nspheres)
        return s->spheres[prim].mat;
    return s->cones[prim - s->nspheres].mat;
}

/* Readers.  `text` need not be NUL-terminated; `name` is for messages and
   relative paths.  They append to `s`. */
rtp_status rtpi_read_nff(rtp_scene *s, const char *text, size_t size,
                         const char *name, int include_depth, rtp_error *err);
/* Reads an OBJ (and its mtllib).  `xform` (4x3 row-major affine: rows are
   x' = m[0..2].p + m[3], ...; NULL = identity) is applied to positions and
   (inverse-transposed) to normals.  `default_mat` is used for faces with no
   usemtl (RTPI_NONE: add a default material). */
rtp_status rtpi_read_obj(rtp_scene *s, const char *text, size_t size,
                         const char *name, const double *xform,
                         uint32_t default_mat, rtp_error *err);
/* Tessellates Bezier patches in Newell's .bpt text into triangles with
   vertex normals, `div` x `div` quads per patch. */
rtp_status rtpi_read_bpt(rtp_scene *s, const char *text, size_t size,
                         const char *name, int div, const double *xform,
                         uint32_t mat, rtp_error *err);
/* Reads a whole scene text file into memory (path "-" = stdin); a NUL
   byte is refused (RTP_ERR_PARSE at its line and column), where read. */
rtp_status rtpi_read_file(const rtp_allocator *a, const char *path,
                          char **text, size_t *size, rtp_error *err);
/* The refusal of the first NUL byte in text[0..size) (RTP_ERR_PARSE at
   its line and column, named `name`), as rtpi_read_file refuses a file's;
   RTP_OK without one. */
rtp_status rtpi_text_nul(const char *text, size_t size, const char *name, rtp_error *err);

/* Triangulates a planar polygon (concave allowed, as NFF `p`), keeping its
   winding.  pts: n xyz doubles.  Writes up to n-2 index triples to tri.
   @return the number of triangles written (0 for a degenerate polygon). */
size_t rtpi_triangulate(const double *pts, size_t n, uint32_t *tri);

/* ------------------------------------------------------ rays and geometry */

typedef struct rtpi_ray {
    rtpi_v3 o, d;     /* d need not be unit length */
    double tmin, tmax;
} rtpi_ray;

typedef struct rtpi_hit {
    double t;
    uint32_t prim;
    double u, v;      /* triangle barycentrics of p1, p2; other kinds: any */
} rtpi_hit;

/* Surface data at a hit.  ng is the geometric normal (unit, outward /
   front-facing as the primitive defines it); ns the shading normal (unit;
   interpolated vertex normals for triangles that have them, moved to ng's
   side), uv texture coordinates (0,0 when the primitive has none). */
typedef struct rtpi_surface {
    rtpi_v3 p, ng, ns;
    double uv[2];
    uint32_t mat;
} rtpi_surface;

void rtpi_surface_at(const rtp_scene *s, const rtpi_ray *ray,
                     const rtpi_hit *hit, rtpi_surface *out);
/* The same; want_uv 0 leaves uv at 0,0 (saves the trigonometry where no
   image texture needs it). */
void rtpi_surface_at_ex(const rtp_scene *s, const rtpi_ray *ray,
                        const rtpi_hit *hit, int want_uv, rtpi_surface *out);

/* The derivatives P_u, P_v of position by uv at p on prim, for a bump
   map (Blinn): triangles with uvs by their corners; spheres and cones by
   the uv rtpi_surface_at gives them (longitude and latitude; angle and
   height).  @return 0 where there are none: no uvs, degenerate uvs, a
   sphere's pole, a cone's apex. */
int rtpi_uv_tangents(const rtp_scene *s, uint32_t prim, rtpi_v3 p, rtpi_v3 *pu, rtpi_v3 *pv);

/* The least step rtpi_offset_origin takes in scene s: 1e-12, or 1e-9 of
   the largest coordinate of s's geometry where that is below 1e-3 (see
   there).  per_prim (may be NULL): whether some primitive's
   rtpi_prim_offset_floor exceeds it (else it is the floor for every one,
   and need not be asked: no scene coordinate reaches 250 where the floor
   is 1e-12).  One scan of the geometry: made once a trace or a move. */
double rtpi_offset_floor(const rtp_scene *s, int *per_prim);
/* The least step off primitive prim: floor (rtpi_offset_floor), or 4e-15
   of the primitive's largest coordinate where that is more.  A hit is
   computed in double from the primitive's coordinates, so it may lie a
   few of their double ulps off the surface: beyond 4e-7 |p| where p is
   near the origin on a primitive far larger (a ground quad or sphere
   1e12 across under a scene of size 1 reflected and shadowed itself in
   40% of its pixels). */
double rtpi_prim_offset_floor(const rtp_scene *s, uint32_t prim, double floor);

/* rtpi_offset_origin's step at p: o is p + ng times it, negated for the
   side ng does not face (vis_row keeps it per node: it does not depend on
   the light). */
static inline double rtpi_offset_eps(rtpi_v3 p, double floor)
{
    /* (inline, without fmax's calls: every hit and shadow query takes
       this step; a NaN p gives a NaN origin either way) */
    double ax = fabs(p.x), ay = fabs(p.y), az = fabs(p.z);
    double m = ax > ay ? (ax > az ? ax : az) : (ay > az ? ay : az);
    /* Hit points are rounded to float before anything leaves them (the
       ray tree stores float positions, and re-evaluation must cast the
       very rays trace cast), so p may be off its surface by half a float
       ulp per coordinate: at most sqrt(3) * 2^-24 * max|p| ~ 1.03e-7 max|p|
       along the normal (double rounding, ~1e-15, adds nothing).  4e-7 *
       max|p| clears that with a factor of four, at every scale and
       distance from the origin; surfaces closer than that to each other
       cannot be told apart by float positions anyway.  The floor keeps
       the offset non-zero near the origin, where the error comes from the
       vertices (double rounding of the geometry, ~1e-16 of its size)
       rather than from p: 1e-12, or for a scene smaller than 1e-3 1e-9 of
       its size (an absolute 1e-12 was 0.1% of a scene 1e-9 across, all
       of one 1e-12 across: its shadow rays started off the surface, and
       false shadows grew as the scene shrank, 26.6 dB at 1e-12). */
    return 4e-7 * m + floor;
}

/* A ray origin for a ray leaving surface point p, moved off the surface
   along the geometric normal ng (unit) to the side `side` (+1: the side ng
   points to, -1: the other) by an amount that scales with |p|, so that the
   new ray cannot hit the surface it starts on at any scale or distance
   from the origin, yet does not skip nearby geometry; `floor`:
   rtpi_offset_floor of the scene. */
static inline rtpi_v3 rtpi_offset_origin(rtpi_v3 p, rtpi_v3 ng, double side, double floor)
{
    double eps = rtpi_offset_eps(p, floor);
    return v3_madd(p, ng, side >= 0.0 ? eps : -eps);
}

/* Whether prim shadows a point of its own whose shadow ray starts at o
   (rtpi_offset_origin's step off the surface, towards light L): 0 no, 1
   yes, -1 cannot tell (see intersect.c).  Where 0, shadow queries leave
   prim out. */
int rtpi_prim_shadows_own_solid(const rtp_scene *s, uint32_t prim, rtpi_v3 o, rtpi_v3 L);
/* out[i] (one a sphere): 1 where rtpi_prim_shadows_own_solid answers 1
   for sphere i and light L at every o inside it (rtpi_ball_holds): the
   light outside it, beyond the band around its surface where that
   function cannot tell.  A shadow query from inside such a ball needs no
   other test (moved lights: vis_row). */
void rtpi_balls_around(const rtp_scene *s, rtpi_v3 L, unsigned char *out);
/* Whether o lies inside sphere sp as rtpi_prim_shadows_own_solid decides
   it (the same operations). */
static inline int rtpi_ball_holds(const rtpi_sphere *sp, rtpi_v3 o)
{
    rtpi_v3 oc = v3_sub(o, v3_from_f(sp->c));
    double r = fabs((double)sp->r);
    return v3_dot(oc, oc) < r * r;
}
/* Whether o lies outside sphere sp, as rtpi_prim_shadows_own_solid
   decides it (the same operations), and within sqrt(2) of its radius
   from its centre: a front hit's shadow-ray origin, which no light
   changes.  rtpi_shadow_ball_own answers its own test then for any
   light (vis_row keeps it per node). */
static inline int rtpi_ball_near_outside(const rtpi_sphere *sp, rtpi_v3 o)
{
    rtpi_v3 oc = v3_sub(o, v3_from_f(sp->c));
    double r = fabs((double)sp->r), d2o = v3_dot(oc, oc);
    return d2o >= r * r && d2o <= 2.0 * (r * r);
}
/* rtpi_prim_shadows_own_solid for cone i (of s->cones) and shadow-ray
   origin *o: 0 where o lies outside its convex solid, else -1 (the light
   plays no part).  Inline for shadow.c's queries (rings_s7: the call with
   o and L copied by value was 1.5% of a light-buffer move). */
static inline int rtpi_cone_shadows_own(const rtp_scene *s, size_t i, const rtpi_v3 *o)
{
    const rtpi_cone *cn = &s->cones[i];
    const rtpi_cone_frame *cf = &s->cframes[i];
    rtpi_v3 b, ax, q;
    double H, h, hc, rb, ra;
    if (cf->ok) { /* (the same axis, height and radii, derived once) */
        b = cf->b;
        ax = cf->w;
        H = cf->h;
        rb = cf->rb;
        ra = cf->ra;
    } else {
        b = v3_from_f(cn->base);
        ax = v3_sub(v3_from_f(cn->apex), b);
        H = v3_len(ax);
        rb = fabs((double)cn->rb);
        ra = fabs((double)cn->ra);
        if (!(H > 0.0))
            return -1;
        ax = v3_mul(ax, 1.0 / H);
    }
    q = v3_sub(*o, b);
    h = v3_dot(q, ax);
    hc = h < 0.0 ? 0.0 : h > H ? H : h;
    return v3_len(v3_madd(q, ax, -h)) > rb + (ra - rb) * (hc / H) ? 0 : -1;
}
/* (a triangle answered inline: every shadow query asks, and for a mesh
   the call was most of the answer) */
static inline int rtpi_prim_shadows_own(const rtp_scene *s, uint32_t prim, rtpi_v3 o, rtpi_v3 L)
{
    return prim < s->ntris ? 0 : rtpi_prim_shadows_own_solid(s, prim, o, L);
}

/* Closest hit of ray with one primitive in [tmin, tmax]; 1 on hit. */
int rtpi_intersect_prim(const rtp_scene *s, uint32_t prim,
                        const rtpi_ray *ray, rtpi_hit *hit);

/* The axis frame of cone cn (rtp_scene.cframes): ok 0 where it has no
   height or radius (never hit). */
void rtpi_cone_frame_of(const rtpi_cone *cn, rtpi_cone_frame *f);

/* Bounds of one primitive. */
/* rtpi_prim_bounds, from s->pbounds where rtpi_scene_bounds made them for
   the primitives there are (the very same numbers). */
void rtpi_prim_bounds_kept(const rtp_scene *s, uint32_t prim, double lo[3], double hi[3]);
/* Can the primitive be hit at all (rtpi_intersect_prim)?  Degenerate
   triangles, zero spheres and cones without height or radius never are. */
int rtpi_prim_hittable(const rtp_scene *s, uint32_t prim);
/* Keeps every primitive's bounds in s->pbounds (once: again only where
   primitives were added since); 0, or -1 when out of memory. */
int rtpi_scene_bounds(rtp_scene *s);
void rtpi_prim_bounds(const rtp_scene *s, uint32_t prim, double lo[3],
                      double hi[3]);

/* ---------------------------------------------------------------- kd-tree */

typedef struct rtpi_kdtree rtpi_kdtree;

typedef struct rtpi_kd_stats {
    size_t nodes, leaves, prim_refs, empty_leaves;
    int depth;
} rtpi_kd_stats;

/* Builds an SAH kd-tree over all primitives of s (which must outlive it and
   not change geometry while it lives). */
rtp_status rtpi_kd_build(const rtp_scene *s, const rtp_allocator *a,
                         rtpi_kdtree **out, rtp_error *err);
/* rtpi_kd_build on up to nthreads threads (1 without RTP_HAVE_THREADS).
   The tree is the same for every nthreads; while it builds on more than
   one thread, calls to the allocator are serialised by a lock. */
rtp_status rtpi_kd_build_mt(const rtp_scene *s, const rtp_allocator *a,
                            int nthreads, rtpi_kdtree **out, rtp_error *err);
void rtpi_kd_destroy(rtpi_kdtree *kd);
void rtpi_kd_get_stats(const rtpi_kdtree *kd, rtpi_kd_stats *st);
/* The greatest distance from L to the tree's box, where every hit lies
   (0 without a primitive). */
double rtpi_kd_far(const rtpi_kdtree *kd, rtpi_v3 L);
/* Closest hit with t in [ray->tmin, ray->tmax].  @return 1 on hit. */
int rtpi_kd_intersect(const rtpi_kdtree *kd, const rtpi_ray *ray,
                      rtpi_hit *hit);
/* Any hit with t in [ray->tmin, ray->tmax], primitive skip (RTPI_NONE:
   none) left out.  @return 1 if occluded. */
int rtpi_kd_occluded(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip);
/* The same, naming the first primitive found in the way (RTPI_NONE: none). */
uint32_t rtpi_kd_occluder(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip);
/* The same for a shadow ray towards the light that rtpi_tri_planes made
   planes and scale for, and rtpi_round_cones cones (each NULL: none): a
   triangle whose plane has the light and the ray's origin on one side,
   by the light buffer's margin, or a sphere or cone outside the cone of
   directions it can be hit in, is not tested (the ray misses it: the
   same answer).  rtpi_tri_edges' edges (NULL: none), made from these
   planes, are asked with a triangle's plane. */
uint32_t rtpi_kd_occluder_planes(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                 const double *planes, const double *edges,
                                 const double *cones, double scale);
/* For each sphere of s and a light at `light`, with rtpi_tri_planes'
   scale for it: rtpi_sphere_sure's entry (4 doubles: C - L, |C - L|^2 -
   r^2; NaN where the sphere's radius is 0 or not finite).  *out NULL
   where s has no spheres, more than RTPI_EDGE_TRIS of them, a scale
   outside [1e-90, 1e90], or its memory cannot be had (a speed-up
   only). */
void rtpi_sphere_entries(const rtp_scene *s, rtpi_v3 light, double scale, const rtp_allocator *a,
                         double **out);
/* For each cone of s and a light at `light`, with rtpi_tri_planes' scale
   for it: rtpi_cyl_sure's entry (6 doubles: L - b across the axis, along
   it, |across|^2 - R^2, h; NaN for cones that are not cylinders and
   cylinders below 1e-7 of the scale).  *out NULL as for
   rtpi_sphere_entries, and where no cone is such a cylinder. */
void rtpi_cyl_entries(const rtp_scene *s, rtpi_v3 light, double scale, const rtp_allocator *a,
                      double **out);
/* rtpi_kd_occluder_planes (without edges) in scenes mostly of spheres
   and cones, with rtpi_cyl_entries' cylinders (cyls) deciding
   cylinder tests where their margins make it certain (rtpi_cyl_sure):
   the same answer; the ray a shadow ray towards the entries' light. */
uint32_t rtpi_kd_occluder_cyls(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                               const double *planes, const double *cones, const double *cyls,
                               double scale);
/* The walks of rtpi_kd_occluder_planes and rtpi_kd_occluder_cyls from
   the leaf of the ray's origin: `from` rtpi_kd_path_of(kd, ray->o)
   (RTPI_NONE: from the root).  The same leaves in the same order, the
   same answer (kdtree.c, "walks from the origin's own leaf"); for
   shadow rays as rtpi_shadow_ray makes them (tmin 0, a unit direction;
   other rays walk from the root or are not asked so). */
uint32_t rtpi_kd_occluder_planes_from(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                      const double *planes, const double *edges,
                                      const double *cones, double scale, uint32_t from);
uint32_t rtpi_kd_occluder_cyls_from(const rtpi_kdtree *kd, const rtpi_ray *ray, uint32_t skip,
                                    const double *planes, const double *cones,
                                    const double *cyls, double scale, uint32_t from);
/* Bytes rtpi_kd_paths_make would take (HUGE_VAL: it would not make
   them). */
double rtpi_kd_paths_bytes(rtpi_kdtree *kd);
/* Makes every leaf's lists of ancestors, one for each octant of
   directions (once; kept with kd, freed with it).  0, or -1 where not
   made (out of memory, too many nodes). */
int rtpi_kd_paths_make(rtpi_kdtree *kd);
/* The lists of o's leaf for walks from it (rtpi_kd_occluder_planes_from),
   or RTPI_NONE: no lists, o within 2 tol of a plane on its path or of
   the root box's faces (tol the walk's slack, kd_axis_setup), o not
   finite or the scene within 1e-269 of 0. */
uint32_t rtpi_kd_path_of(const rtpi_kdtree *kd, rtpi_v3 o);
/* rtpi_tri_edges' margin, times scale^3 (see there). */
#define RTPI_EDGE_MARGIN 1e-9
/* For each triangle of s (RTPI_EDGE_N doubles a triangle) and a light at
   `light`, with rtpi_tri_planes' planes and scale for it: the plane's
   entry and the planes through the light and each edge, as n and
   n.light (rtpi_edges_miss' order).  A shadow ray towards the light
   whose origin o (within the scale) has n.o - n.light below -m for one
   edge and above m for another, m = RTPI_EDGE_MARGIN scale^3, misses the
   triangle (rtpi_kd_occluder_planes asks them, with the plane's test).
   *out NULL where s has no triangles or planes is NULL, more than
   RTPI_EDGE_TRIS of them, a scale outside [1e-90, 1e90], or its memory
   cannot be had (a speed-up only).  (The
   bound keeps a move's edges within 128 MB beside the planes' 32 MB a
   million triangles: they are written whole for every moved light, a
   speed-up only, and a scene of millions of triangles seen in a frame of
   a million samples asks few of them.) */
#define RTPI_EDGE_TRIS ((size_t)1 << 20)
#define RTPI_EDGE_N 16
void rtpi_tri_edges(const rtp_scene *s, rtpi_v3 light, double scale, const double *planes,
                    const rtp_allocator *a, double **out);

/* ------------------------------------------------------------- ray trees */

/* One hit of a sample's ray tree: 24 bytes, all a hit needs.  The normal,
   material and texture coordinates are derived from prim and p (with the
   scene's geometry), the view vector from the parent hit (or the eye), so
   the shading of a node depends only on this record, the scene's
   parameters and the hit above it.  A sample's nodes are stored in
   preorder: a node, its reflected subtree, its refracted subtree. */
typedef struct rtpi_cnode {
    float p[3];     /* hit position */
    uint32_t prim;  /* primitive hit */
    uint32_t vis;   /* bit i: light i seen (scenes with <= 32 lights; more
                       lights keep their bits in a parallel word array) */
    uint32_t link;  /* RTPI_L_* flags | refracted child offset << 8 */
} rtpi_cnode;

#define RTPI_L_BACK 0x01u      /* the ray hit the back of the surface */
#define RTPI_L_REFL 0x02u      /* reflected subtree follows at +1 */
#define RTPI_L_REFL_MISS 0x04u /* reflected ray left the scene */
#define RTPI_L_REFR 0x08u      /* refracted subtree at + (link >> 8) */
#define RTPI_L_REFR_MISS 0x10u /* refracted ray left the scene */
#define RTPI_L_TIR 0x20u       /* total internal reflection: the
                                  transmitted share follows the reflected
                                  ray (REFL / REFL_MISS) */
#define RTPI_L_SHIFT 8
#define RTPI_MAX_SUBTREE (1u << 23) /* offsets must fit in 24 bits */

/* Does a hit on the back of prim shade with its normal turned towards the
   ray?  Transparent surfaces always; opaque ones too, except in SPD mode,
   where opaque objects are one-sided but for smooth patches (SPD asks for
   the teapot, its only patches, to be double-sided). */
static inline int rtpi_two_sided(const rtp_scene *s, int spd, uint32_t prim,
                                 const rtpi_material *m)
{
    return !spd || m->kt > 0.0f ||
           (prim < s->ntris && s->tris[prim].n[0] != RTPI_NONE);
}

/* What shading needs besides the nodes. */
typedef struct rtpi_shade_ctx {
    const rtp_scene *s;
    int one_sided;           /* SPD: opaque surfaces keep their normal */
    size_t vis_words;        /* words per node in vis_ext (> 32 lights) */
    int has_ka;              /* some material of s has its own ambient
                                coefficient (rtpi_scene_has_ka, when the
                                context is made for an evaluation): only
                                then do the sums look at ka_set */
    int no_ks;               /* no material of s has ks > 0 (made with the
                                context for an evaluation; 0: not known):
                                rtpi_light_redo then needs no material
                                for a node whose kc is kept */
} rtpi_shade_ctx;
/* Whether some material of s has its own ambient coefficient (ka_set). */
int rtpi_scene_has_ka(const rtp_scene *s);

/* The one shading routine, in three steps that trace and reeval share so
   that re-evaluation reproduces trace bit for bit:

   1. the terms: for each node of a sample, the object colour c_obj
      and, per light, d = n.l and s = (r.v)^shine where the node sees the
      light and faces it (0 elsewhere) — everything geometric, as floats;
   2. the coefficients: the sample's colour is linear in the light
      colours, the ambient light and the background:
         I = G (.) background + A (.) ambient + sum_i K_i (.) c_li
      with G, A, K_i (RGB) gathered over the tree with the materials' kd,
      ks, kt and the path weights;
   3. rtpi_combine: I from G, A, K_i and the current light colours.
   rtpi_sample_eval makes steps 1 and 2 in one descent of a sample's tree;
   rtpi_sample_coeffs step 2 again from kept terms.

   An edit of light colours, ambient or background redoes only step 3; a
   material edit redoes step 2 for the samples that contain it. */
#define RTPI_TERMS(nl) (3 + 2 * (size_t)(nl))
#define RTPI_COEFFS(nl) (6 + 3 * (size_t)(nl))

/* The largest sum of a sample's |coefficients| with which re-evaluation
   makes images from planes (tree.c): with the colours' magnitudes summing
   to no more than it too, and an edited material's new part within it,
   every sum either path makes stays below 2^101, far inside the float
   range, so planes and full path cannot part at an overflow (a mirror
   of ks 1.5 carrying a colour of 2.3e38 into one coefficient, another
   material's edit adding 4e28 to it: the full path's float coefficient
   overflowed, the planes' sum did not;
   coefficients of +-1e29 whose corners cancel in an SPD pixel's plane,
   times an ambient of 1e20: NaN against a finite value).  Physical
   scenes stay near 1. */
#define RTPI_COEFF_MAX 0x1p50
/* coeffs: RTPI_COEFFS(nlights) floats: G, A, then K_i; acc: as many
   doubles of scratch (sums are kept in double, then rounded once).  w
   (NULL: not wanted): the path weight step 2 reaches each of the n nodes
   with, as rtpi_sample_weights gives it.  0 where the coefficients'
   magnitudes sum past RTPI_COEFF_MAX (or one is not finite), else 1. */
int rtpi_sample_coeffs(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                       size_t n, const float *terms, double *acc,
                       float *coeffs, double *w);
/* (float)pow(x, y), the same bits, mostly without calling pow (shade.c's
   light_term) */
float rtpi_pow_float(double x, double y);

/* Steps 1 and 2 for a sample of n nodes seen from eye: its terms, then
   from them its coefficients as rtpi_sample_coeffs makes them (the same
   bits), in one descent of the tree.  terms: n * RTPI_TERMS(nlights)
   floats.  vis_ext: the nodes' visibility words (c->vis_words per node)
   or NULL for the nodes' own bits.  nv (may be NULL): receives each
   node's shading normal and view vector (6 floats), from which
   rtpi_light_redo recomputes one light's terms exactly.  acc, coeffs, w
   and the result as for rtpi_sample_coeffs. */
int rtpi_sample_eval(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                     const uint32_t *vis_ext, rtpi_v3 eye, float *terms, float *nv,
                     double *acc, float *coeffs, double *w);
/* A moved light's terms and coefficients (coeffs[6 + 3 light ..]) for
   samples k0 .. k1 - 1 (sample k's nodes from start[k] to start[k + 1];
   nodes, vis_ext, nv, w and terms indexed by node, coeffs and samples by
   sample), with the nodes' path weights w (rtpi_sample_coeffs'): bit for
   bit what rtpi_sample_eval and rtpi_sample_coeffs make for that light.
   Where samples is not NULL each sample's colour is combined there too
   with the colours cl (rtpi_combine; the other coefficients must be those
   the colours are to be combined with).  *bad |= 1 where a coefficient
   made is not finite.  Returns how many samples were combined; where
   mark is not NULL, mark[k] is set to 1 for each.  rest (NULL: none):
   3 doubles a sample, rtpi_combine_rest's for this light where
   rest_ok[k] is 1 (else made there, and rest_ok[k] set), from which a
   sample is combined with this light's term alone.  kc (NULL: none): 3
   doubles a node, its light-independent (w kd) c_obj where the first is
   not all zero bits (else made there where the node is lit and reached):
   they must be those of w, terms and the materials now. */
unsigned long long rtpi_light_redo(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                                   const uint64_t *start, size_t k0, size_t k1,
                                   const uint32_t *vis_ext, const float *nv, const double *w,
                                   size_t light, float *terms, float *coeffs, const double *cl,
                                   float *samples, int *bad, unsigned char *mark,
                                   double *rest, unsigned char *rest_ok, double *kc);
/* The light terms (n.l, highlight) of every node of material mat among a
   sample's n nodes, from the cached normals and view vectors nv, exactly
   as rtpi_sample_eval computes them: what an edit of mat's shine or ks
   changes. */
void rtpi_material_light_terms(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                               size_t n, const uint32_t *vis_ext, const float *nv,
                               uint32_t mat, float *terms);
/* The highlights of material mat among a sample's n nodes (numbered from
   node0 in the whole tree): for every node of mat and light it sees and
   faces with r.v > 0 (ks > 0), the index of its highlight term in the
   terms of the whole tree and log2(r.v), appended at idx[*count] and
   lrv[*count] (room for n * nlights more).  A new shine makes each term
   2^(shine lrv); every other highlight of mat is 0 for any shine. */
void rtpi_material_highlights(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                              size_t n, size_t node0, const uint32_t *vis_ext,
                              const float *nv, uint32_t mat, size_t *idx,
                              double *lrv, size_t *count);
/* The path weight with which step 2 reaches each of a sample's n nodes
   (0 where it does not), into w[0..n). */
void rtpi_sample_weights(const rtpi_shade_ctx *c, const rtpi_cnode *nodes, size_t n,
                         double *w);
/* The diffuse light material mat receives in a sample, per channel:
   q = sum over its nodes of path weight * texture factor * (ambient +
   sum_i (n.l_i) c_li), with cv the colours of every term (background,
   ambient, lights: RTPI_COEFFS).  For a material without a checker the
   sample's colour is affine in x = kd * colour of mat: x q is what mat's
   diffuse and ambient shading add, so an edit of kd or colour alone moves
   the colour by (x' - x) q.  By descent of the sample's tree: the
   definition rtpi_nodes_diffuse (what evaluation uses) is tested
   against. */
void rtpi_sample_diffuse(const rtpi_shade_ctx *c, const rtpi_cnode *nodes,
                         size_t n, const float *terms, uint32_t mat,
                         const double *cv, double q[3]);
/* The same q from the listed nodes idx[0..n) of mat alone (ascending:
   one sample's nodes of that material), with terms and the path weights w
   (rtpi_sample_coeffs') indexed by node: bit for bit rtpi_sample_diffuse,
   without descending the sample's tree. */
/* (inlined whatever the compiler's heuristics say: the first edit of a
   material calls it once a sample, for one or two nodes, and the call
   cost as much as the sums: mount 10 M of 40 M.  rtpi_nodes_diffuse_nl
   takes the scene's lights as nl: a loop over samples that tests for one
   light once and passes a constant 1 (tree.c: listed_q) has the one-light
   sums' colours loaded once, not the test and loads per sample: mount_s6's
   first kd edit 33.46 M -> 31.82 M instructions) */
static RTPI_FORCE_INLINE void rtpi_nodes_diffuse_nl(size_t nl, const uint32_t *idx, size_t n,
                                         const float *terms, const double *w,
                                         const double *cv, double q[3])
{
    size_t nt = RTPI_TERMS(nl), j, i;
    double q0 = 0.0, q1 = 0.0, q2 = 0.0;
    /* diffuse_node's operations on the listed nodes (the material's), in
       its order (depth first, reflected subtree first: the order they are
       stored in); it does not reach the nodes of weight 0 */
    if (nl == 1) {
        /* one light (a third of the SPD scenes): the same sums without
           the loop over lights */
        const double a0 = cv[3], a1 = cv[4], a2 = cv[5], c0 = cv[6], c1 = cv[7], c2 = cv[8];
        for (j = 0; j < n; j++) {
            const float *t = terms + (size_t)idx[j] * nt;
            double wj = w[idx[j]], d;
            if (wj == 0.0)
                continue;
            d = t[3];
            q0 += wj * t[0] * (a0 + d * c0);
            q1 += wj * t[1] * (a1 + d * c1);
            q2 += wj * t[2] * (a2 + d * c2);
        }
        q[0] = q0;
        q[1] = q1;
        q[2] = q2;
        return;
    }
    for (j = 0; j < n; j++) {
        const float *t = terms + (size_t)idx[j] * nt;
        const double *cl = cv + 6;
        double l0 = cv[3], l1 = cv[4], l2 = cv[5], wj = w[idx[j]];
        if (wj == 0.0)
            continue;
        for (i = 0; i < nl; i++, cl += 3) {
            double d = t[3 + 2 * i];
            l0 += d * cl[0];
            l1 += d * cl[1];
            l2 += d * cl[2];
        }
        q0 += wj * t[0] * l0;
        q1 += wj * t[1] * l1;
        q2 += wj * t[2] * l2;
    }
    q[0] = q0;
    q[1] = q1;
    q[2] = q2;
}
/* (rtpi_nodes_diffuse_nl with the scene's own count of lights) */
static RTPI_FORCE_INLINE void rtpi_nodes_diffuse(const rtpi_shade_ctx *c, const uint32_t *idx, size_t n,
                                      const float *terms, const double *w, const double *cv,
                                      double q[3])
{
    rtpi_nodes_diffuse_nl(c->s->nlights, idx, n, terms, w, cv, q);
}
/* The largest magnitude a sample's channel takes (rtpi_combine): where
   its sum passes it (numbers near RTPI_VALUE_LIMIT: a kd of 3.4e38 under a
   light of 3.4e38) the channel is this, with the sum's sign, and 0 where
   the sum is NaN (infinities of both signs, from negative texels; an
   infinite path weight times 0).  A quarter of float's range, not all of
   it, so that SPD's four corner samples sum in float without overflow:
   every image rtp makes (trace, reeval, each stream frame, --reference) is
   finite, and the PNG's pixel white where it had been an infinity, shown
   black.  (Without it PFMs held infinities and NaN.) */
#define RTPI_SAMPLE_MAX (0.25f * FLT_MAX)
/* acc + coefficient k x colour c, where a colour of 0 adds nothing (not
   even a NaN from an infinite k: rtpi_combine, which takes it where its
   plain sum came out NaN). */
#define RTPI_TERM_SUM(acc, k, c) ((c) != 0.0 ? (acc) + (k) * (c) : (acc))
/* cl: 3 per light: colour * light scale, 0 when off (rtpi_light_colors). */
void rtpi_combine(const rtp_scene *s, const double *cl, const float *coeffs,
                  float rgb[3]);
/* rtpi_combine's sums, in its order, over every term but light `light`
   (rtpi_light_redo's rest): 3 doubles, not rounded. */
void rtpi_combine_rest(const rtp_scene *s, const double *cl, const float *coeffs, size_t light,
                       double rest[3]);
void rtpi_light_colors(const rtp_scene *s, double *cl);

/* Surface data at a recorded hit position, the float position a tree
   node keeps (normals, material, and uv when want_uv).  It takes the
   floats themselves: gcc 12.2 at -O2 drops the rounding of
   (double)(float)x where its SLP vectorizer pairs two coordinates, so
   trace, handing over v3((float)pe.x, (float)pe.y, (float)pe.z), cast
   its reflected, refracted and shadow rays from the unrounded hit while
   re-evaluation cast them from the rounded one (images and files
   differed from -O0's and clang's; 1e-5 apart at a reflection between
   touching balls).  A float array in memory, read in another file, is
   rounded whatever the optimiser does. */
void rtpi_surface_from_point(const rtp_scene *s, uint32_t prim, const float p[3],
                             int want_uv, rtpi_surface *out);

/* A triangle's geometric normal, and a sphere's outward one at p (its
   visible side's is the reverse where r < 0): the expressions
   rtpi_surface_at_ex and rtpi_surface_normals share. */
static inline rtpi_v3 rtpi_tri_normal(const rtp_scene *s, const rtpi_tri *tr)
{
    rtpi_v3 p0 = v3_from_f(s->pos + 3 * (size_t)tr->v[0]);
    rtpi_v3 p1 = v3_from_f(s->pos + 3 * (size_t)tr->v[1]);
    rtpi_v3 p2 = v3_from_f(s->pos + 3 * (size_t)tr->v[2]);
    return v3_norm(v3_cross(v3_sub(p1, p0), v3_sub(p2, p0)));
}

static inline rtpi_v3 rtpi_sphere_normal(const rtpi_sphere *sp, rtpi_v3 p)
{
    return v3_norm(v3_sub(p, v3_from_f(sp->c)));
}

/* A cone's outward normal n at p (its frame cf, ok): the gradient of
   |q|^2 - (rb + k h)^2, with h the height of p along the axis and q its
   unit offset from the axis (also returned).  0 where p lies on the axis
   (a pointed apex: the caller picks a direction across). */
static inline int rtpi_cone_normal(const rtpi_cone_frame *cf, rtpi_v3 p, rtpi_v3 *n,
                                   rtpi_v3 *q, double *h)
{
    rtpi_v3 f = v3_sub(p, cf->b), a;
    double ql;
    *h = v3_dot(f, cf->w);
    a = v3_madd(f, cf->w, -*h);
    ql = v3_len(a);
    if (!(ql > 0.0))
        return 0;
    *q = v3_mul(a, 1.0 / ql);
    *n = v3_norm(v3_madd(*q, cf->w, -cf->k));
    return 1;
}

/* The normals (ng, ns) and material rtpi_surface_from_point gives at the
   float position p on prim, without uv: for a sphere, a triangle without
   vertex normals and a cone off its axis by their own arithmetic, inline
   (a moved light asks this of every recorded hit); else by
   rtpi_surface_from_point. */
static inline uint32_t rtpi_surface_normals(const rtp_scene *s, uint32_t prim, rtpi_v3 p,
                                            rtpi_v3 *ng, rtpi_v3 *ns)
{
    rtpi_surface sf;
    size_t i = prim;
    if (i < s->ntris) {
        const rtpi_tri *tr = &s->tris[i];
        if (tr->n[0] == RTPI_NONE) {
            *ng = *ns = rtpi_tri_normal(s, tr);
            return tr->mat;
        }
    } else if ((i -= s->ntris) < s->nspheres) {
        const rtpi_sphere *sp = &s->spheres[i];
        rtpi_v3 n = rtpi_sphere_normal(sp, p);
        if (sp->r < 0.0f)
            n = v3_mul(n, -1.0);
        *ng = *ns = n;
        return sp->mat;
    } else if ((i -= s->nspheres) < s->ncones) {
        const rtpi_cone_frame *cf = &s->cframes[i];
        rtpi_v3 n, q;
        double h;
        if (cf->ok && rtpi_cone_normal(cf, p, &n, &q, &h)) {
            *ng = *ns = n;
            return s->cones[i].mat;
        }
    }
    {
        /* (p holds floats already: exact) */
        const float pf[3] = {(float)p.x, (float)p.y, (float)p.z};
        rtpi_surface_from_point(s, prim, pf, 0, &sf);
    }
    *ng = sf.ng;
    *ns = sf.ns;
    return sf.mat;
}

/* The shading normal n perturbed by the material's bump map at p/uv
   (Blinn 1978; solid procedural bumps, or an image height map on triangles
   with uvs); n unchanged without a bump. */
rtpi_v3 rtpi_bump_normal(const rtp_scene *s, const rtpi_material *m,
                         uint32_t prim, rtpi_v3 p, const double uv[2],
                         rtpi_v3 n);

/* The texture's part of c_obj at p/uv: for an image texture the image's
   colour (c_obj = colour * it; v wrapped, but on a sphere or cone held
   to the image's edge rows), for a checker 1 in colour cells and 0 in
   color2 cells, else 1 (shade.c). */
void rtpi_texture_factor(const rtp_scene *s, const rtpi_material *m, uint32_t prim,
                         rtpi_v3 p, const double uv[2], double f[3]);

/* rtp_tree.busy of a tree rtp_tree_read_summary read: no nodes, no
   sample index (nodes NULL, start NULL), only its scene and counts. */
#define RTPI_TREE_SUMMARY 3
/* rtp_tree.busy while rtp_tree_trace traces the tree's scene: its
   progress or cancel callback must not use the tree (an edit there
   changed the scene under the rows being traced). */
#define RTPI_TREE_TRACING 4

/* The ray trees of a whole image, with the scene they were traced in
   (rtp_tree in rtp.h).  Sample k's nodes are nodes[start[k] .. start[k+1]). */
struct rtp_tree {
    rtp_allocator alloc;
    int busy; /* 1: an evaluation is under way: its progress or cancel
                 callback must not use the tree (rtpi_tree_busy); 2: the
                 tree of rtp_tree_eval_file's edit callback, without its
                 ray trees: edits only; RTPI_TREE_SUMMARY: read by
                 rtp_tree_read_summary, without ray trees for good:
                 edits and its info only; RTPI_TREE_TRACING: as 1, for
                 rtp_tree_trace's callbacks */
    rtp_scene *scene;      /* owned copy: parameters are edited here */
    rtpi_material *mats0;  /* materials as traced (names not kept) */
    rtpi_light *lights0;   /* lights as traced (names not kept) */
    rtpi_camera cam0;      /* the camera as traced: where scene->camera
                              differs, the next evaluation traces every
                              sample again */
    unsigned long long stale_n; /* count_stale's last count (tree.c), valid
                              while stale_ok: a bump key or a re-trace
                              clears it, so the scan of every node is not
                              made again at each light or colour edit */
    int stale_ok;
    int width, height;     /* image (of the region, when one was traced) */
    int nx, ny;            /* sample grid: image, or corners + 1 (SPD) */
    int full_w, full_h;    /* the whole frame the camera spans */
    int rx, ry;            /* the region's first pixel in the frame */
    int spd, max_depth;
    double min_weight;
    int foreign;           /* some nodes came from a renderer's own tracer
                              (rtp_builder_*), not rtp's trace: class C/D
                              re-traces trace their samples whole */
    rtpi_cnode *nodes;
    size_t nnodes;
    uint64_t *start;       /* nx*ny + 1 */
    uint32_t *vis_ext;     /* nnodes * vis_words, when > 32 lights */
    size_t vis_words;

    /* Caches for evaluation (rebuilt as edits need them). */
    struct rtpi_kdtree *kd;   /* of scene, for shadows of moved lights */
    uint32_t *cur_vis;     /* nnodes * cur_words: visibility now, when a
                              light moved or was added; else NULL */
    size_t cur_words;
    double *cur_pos;       /* 3 per light: position cur_vis holds bits for
                              (NaN: not computed), cur_nl lights */
    size_t cur_nl;
    int cur_mode, cur_res; /* shadow mode and resolution they came from */
    double lb_queries;     /* the shadow queries of the last light decided
                              by a light buffer (light_vis_rows), the
                              next build's expectation (rtpi_lightbuf_build_q);
                              unknown (HUGE_VAL) while lb_queries_known is 0 */
    int lb_queries_known;
    double *tri_nrm;       /* 3 per triangle: its rtpi_tri_normal, made at
                              the first move (vis_row asks it of every
                              hit), NULL in a scene without triangles */
    unsigned char *ball_in; /* nnodes, with cur_vis where the scene has
                              spheres: per node 0 not yet known, 1 a back
                              hit on a sphere whose shadow ray origin, the
                              normal turned inwards, lies in the ball
                              (rtpi_ball_holds), 2 anything else (vis_row) */
    int ball_known;        /* ball_in found for every node (a move whose
                              light had balls), and then */
    unsigned char *ball_sph; /* per sphere 1 where some node on it has
                              ball_in 1, every such node's normal kept in
                              prim_nrm (ball_runs_known: vis_row's runs);
                              NULL without memory */
    double *prim_nrm;      /* 3 per node, with cur_vis where the scene has
                              spheres or cones: the normal
                              rtpi_surface_normals gives at a node on a
                              sphere or cone (ng = ns, before any turn for
                              a back face), 0 0 0 not yet known (vis_row);
                              NULL without them or memory */
    double off_floor;      /* rtpi_offset_floor of the scene and its */
    int prim_floor;        /* per_prim, found at the first move where */
    int floor_ok;          /* floor_ok (the geometry does not change) */
    unsigned char *cone_own; /* nnodes, with prim_nrm where the scene has
                              cones: per node on one, seen from the front
                              (its shadow ray's origin the same for every
                              light), 0 not yet known, else 1 + what
                              rtpi_cone_shadows_own answers, negated
                              (vis_row); on a sphere (cones or spheres:
                              allocated), 1 where the origin lies outside
                              it near its surface, else 2 (ball_own_of) */
    uint32_t *kd_from;     /* nnodes, made at the first exact move where
                              the memory limit holds it with kd's leaf
                              lists (rtpi_kd_paths_make): per node 0 not
                              yet known, else the list of its shadow ray
                              origin's leaf + 2 (1: none), the origin on
                              the side its geometric normal faces
                              (vis_from) */
    unsigned char *kd_from_kt; /* per material, kt > 0 when kd_from's
                              entries were found (a back hit's normal
                              turns with it: rtpi_two_sided) */
    size_t kd_from_nmats;
    double *vrec;          /* per node, made at a move where the memory
                              limit holds it with the evaluation's caches
                              (vrec_make): what a moved light's query at
                              the node takes that no light changes -- the
                              offset's step off the surface
                              (rtpi_offset_eps), then nnodes + 1 bytes of
                              the node's kind (VK_: which normal, turned
                              or not; 0 not yet known), the normals read
                              where they are kept (tri_nrm, prim_nrm,
                              ev_nv); made and read only where ev_nv
                              holds (vis_row) */
    unsigned char *vrec_mat; /* per material what the entries hold for
                              (vrec_key): its two-sidedness and whether
                              it is bumped */
    size_t vrec_nmats;
    size_t nlights0;       /* lights traced; later ones were added */

    /* Evaluation caches (tree.c): the shading steps' results, kept so an
       edit redoes only what it touches. */
    int ev_valid;          /* ev_terms/ev_coeffs hold the state below */
    float *ev_terms;       /* nnodes * RTPI_TERMS(ev_nlights) */
    float *ev_coeffs;      /* samples * RTPI_COEFFS(ev_nlights) */
    float *ev_nv;          /* nnodes * 6: shading normal, view vector */
    double *ev_w;          /* nnodes: the path weight step 2 reaches each
                              node with (0: not reached), as ev_coeffs
                              were made: a material's q in one pass */
    float *ev_samples;     /* the samples' colours (SPD: corners, averaged
                              into pixels); with the caches, or SPD */
    int ev_samples_ok;     /* ev_samples hold ev_coeffs combined with ev_cl */
    double *mv_rest;       /* 3 a sample: rtpi_combine_rest's for light
                              mv_light - 1 where mv_ok (tree.c: a light
                              moved again and again) */
    unsigned char *mv_ok;  /* a sample: 1 where mv_rest holds its rest */
    double *mv_kc;         /* 3 a node: rtpi_light_redo's kc, for moves
                              (tree.c mv_kc_check), or NULL */
    rtpi_material *mv_kc_mats; /* the materials mv_kc was made with */
    size_t mv_kc_nmats;    /* how many (the scene's when it was made) */
    size_t mv_light;       /* 0, or 1 + the light mv_rest is for, while the
                              other terms' coefficients and colours hold */
    unsigned char *ev_mark; /* samples + 8 bytes, then a byte a sample row,
                              all 0 between evaluations: the samples a
                              moved light's pass combined, and the rows
                              that have any (tree.c: mark_row) */
    int ev_inf;            /* some coefficient passed RTPI_COEFF_MAX (a kt
                              of 1e19) since the last full evaluation: no
                              planes (tree.c planes_in_range) */
    size_t ev_nlights;     /* the lights ev_terms and the other caches
                              are made for (set as they are made) */
    double *ev_pos;        /* 3 per light: positions the terms are for */
    int ev_vis_mode, ev_vis_res;
    rtpi_material *ev_mats; /* materials the caches were made with */
    double *ev_cl;         /* the colours of the image's linear form the
                              caches were combined with: background,
                              ambient, then each light (RTPI_COEFFS) */
    int pk_term;           /* the one-term path (tree.c): 0 (none), or
                              1 + the term whose planes pk holds (term 0:
                              background, 1: ambient, 2 + l: light l,
                              2 + nlights + m: kd * colour of material m) */
    float *pk;             /* pixels * 3: the rest P of the image with
                              term pk_term left out, at the pixels where
                              that term's coefficient K is 0 (pixel = P
                              there, P + K c elsewhere: pk_c) */
    int hl_mat;            /* 0, or 1 + the material whose highlights are
                              listed (tree.c: consecutive shine edits) */
    unsigned char *mat_uv; /* per material: 1 where some primitive of it
                              has uvs (an image bump can bend it), made
                              when first asked (tree.c: bump_bends) */
    size_t *hl_idx;        /* their terms' indices in ev_terms */
    double *hl_lrv;        /* log2 (r.v) of each */
    float *hl_w;           /* 4 each: W = path weight * ks * light colour,
                              then the term as the coefficients hold it
                              (hl_restore puts it back) */
    size_t hl_n, hl_cap;
    double hl_shine;       /* the shine the listed terms and the samples
                              were last set for (NaN: not known) */
    size_t *hl_off;        /* per sample of the material: its first one */
    float *hl_p;           /* per sample of the material: colour less them */
    float *pk_c;           /* pixels * 6 at most: P and K of the pixels
                              whose K is not 0, in bands of rows (tree.c,
                              PK_ROWS): an edit reads them in one run.
                              In pk_nz's block, right after the room of
                              the list (pk_build), not a block of its own */
    uint32_t *pk_nz;       /* those pixels (pixels at most, in the same
                              bands): the only ones an edit of the term
                              changes; pk_nnz of them in all.  The block
                              pk_c lies in (its start: freed as pk_nz) */
    uint32_t *pk_seg;      /* per band: how many pk_nz and pk_c hold... */
    size_t *pk_off;        /* ...from this entry on */
    int pk_part;           /* the planes are made only where the material
                              reaches (pk holds P nowhere else) */
    size_t pk_nnz;
    size_t pk_cap;         /* entries pk_c's block has room for (pk_build
                              makes it as large as the planes need) */
    size_t pk_split;       /* bands from entry pk_split on lie in pk_nz's
                              block (entry pk_off - pk_split there); those
                              before, in ev_samples' block, lent while the
                              samples hold nothing (tree.c: pk_lend): 0
                              where none is lent */
    /* colour planes (tree.c: cp_*): an image for other colours of the
       terms (background, ambient, lights) is S + sum K_d (c_d - cS_d) */
    float *cp_s;           /* pixels * 3: S, the full path's image for... */
    float *cp_sown;        /* S's own block, where the first evaluation
                              made the planes (cp_ready); otherwise S
                              lies in ev_samples' */
    double *cp_cl;         /* ...the colours cS (3 per term) */
    int cp_s_ok;           /* S holds for the coefficients now */
    size_t cp_nt;          /* terms: 2 + lights */
    float **cp_k;          /* per term: K of the pixels whose K is not 0,
                              3 floats each, in bands of rows as pk_c
                              (NULL: not made yet), then in the same
                              block their runs (cp_run) */
    uint32_t **cp_run;     /* per term: runs of consecutive such pixels,
                              2 words each (first pixel, length), in the
                              same bands; in cp_k's block, not owned */
    uint32_t **cp_seg;     /* per term, 4 words a band: its first entry
                              of cp_k, their count, its first run, their
                              count (tree.c: CP_KOFF...) */
    size_t *cp_cap;        /* per term: the bytes cp_k's block holds */
    unsigned char *cp_ok;  /* per term: its plane holds */
    size_t *cp_d, cp_nd;   /* the terms whose colour differs from cS... */
    double *cp_dc;         /* ...and by how much (3 each) */
    double *cp_ab;         /* |c_d| + |cS_d| (3 each: cp_lost) */
    double *cp_kmax;       /* per term: the largest |K| per channel */
    double cp_smax[3];     /* the largest |S| per channel */
    int cp_check;          /* pixels are checked for lost digits */
    unsigned cp_gen;       /* counts the snapshots and stale planes */
    unsigned *cp_used;     /* per term: cp_clock when its plane was last used */
    unsigned cp_clock;     /* counts the evaluations by colour planes */
    double *cb_p;          /* a chain's P' (tree.c: cb_chunk), as cp_k's
                              entries of the term, cb_cap of them, for... */
    size_t cb_cap;
    size_t cb_term;        /* ...1 + term j (0: none), with... */
    double *cb_cl;         /* ...the other terms' colours, and... */
    unsigned cb_gen;       /* ...made at this cp_gen */
    double cb_dc[3];       /* c_j - cS_j of the edit */
    const float *last_pixels; /* the image the last evaluation wrote */
    int last_exact;        /* ...and it is the image of the coefficients
                              (tree.c; not a material's P + K x) */
    float *pk_q;           /* samples * 3: q of the material whose kd *
                              colour is the term (rtpi_sample_diffuse) */
    uint32_t *mat_start;   /* per material: its samples in mat_samples */
    uint32_t *mat_samples; /* samples whose trees contain each material */
    uint32_t *mat_nstart;  /* per material: its nodes in mat_nodes */
    uint32_t *mat_nodes;   /* the nodes of each material, ascending */

    /* Large blocks the direction cubes of moved lights used, kept for the
       next move: fresh memory costs a page fault a page (tree.c). */
    struct rtpi_block {
        void *p;
        size_t n;
        int live;
    } blocks[16];
    rtp_allocator cube_alloc; /* the tree's allocator through blocks[] */
    int auto_long;            /* RTP_SHADOWS_AUTO found a light buffer's
                                 lists too long at this many cells a face
                                 (tree.c auto_lb_entries; 0: never): its
                                 later moves at as many or more take
                                 shadow rays at once */
    double auto_tight;        /* RTP_SHADOWS_AUTO without a resolution
                                 halved its light buffer down to 1 cell
                                 and its lists still passed this memory
                                 limit (bytes; 0: never): its later moves
                                 under as much or less take shadow rays
                                 at once (tree.c shadow_mode_for) */
};

/* The memory limit of a trace or re-evaluation given none: 16 GiB. */
#define RTPI_MEMORY_LIMIT (16.0 * 1073741824.0)

/* Traces the listed samples (ascending indices) of t again in t->scene as
   it is now (materials edited; lights where they were traced, or with
   nlights_now > 0 the scene's first nlights_now lights where they are now
   and no others, with light words for as many: every sample traced again,
   the caller then records them as traced) and puts their new trees in
   place of the old; adds the rays cast to *rays and those not followed
   because a sample's tree was full to *capped.  The
   trees may take limit bytes in all, the old and the new together while
   they are spliced (RTP_ERR_LIMIT past it, t unchanged); progress (may
   be NULL) as rtp_trace_options'.  The caller
   drops whatever caches refer to the old nodes.  With redo (one byte a
   material; not with nlights_now) a sample's old tree is kept but below
   the hits of materials whose redo is 1: the rays to the nodes above are
   those a trace casts (t's trees are rtp's own trace of the scene as it
   is but for those materials, tree.c retrace_edited), so their hits and
   light bits are taken from the old tree and only the rays below are
   cast (and counted in *rays); the new trees are a full trace's.  A
   redo of 3 (an SPD tree's material whose kt went from or to 0, so that
   its surfaces turned two-sided or one-sided) casts the shadow rays of
   its first hits too where they are seen from behind. */
/* rtp_trace, with opt's width and height the frame even with spd (a
   builder's tree of corner samples need not be 512x512). */
rtp_status rtpi_trace_sized(const rtp_scene *s, const rtp_trace_options *opt,
                            rtp_image **out, rtp_trace_stats *stats, rtp_error *err);
rtp_status rtpi_retrace(rtp_tree *t, const uint32_t *samples, size_t n, int threads,
                        size_t nlights_now, const unsigned char *redo, double limit, unsigned long long *rays,
                        unsigned long long *capped, void (*progress)(void *, double),
                        int (*cancel)(void *), void *progress_user, rtp_error *err);

/* Resolves samples (nx*ny RGB, from a grid of corners when spd) into
   the image; one routine for trace and reeval so both round alike. */
void rtpi_resolve_samples(const float *samples, int spd, rtp_image *img);
/* SPD: pixel (x, y) of img, the average of its four corner samples (a
   grid of img->width + 1 columns). */
static inline void rtpi_resolve_pixel(const float *samples, rtp_image *img, int x, int y)
{
    size_t w = (size_t)img->width, a = 3 * ((size_t)y * (w + 1) + (size_t)x);
    size_t b = a + 3 * (w + 1);
    float *out = img->pixels + 3 * ((size_t)y * w + (size_t)x);
    int c;
    for (c = 0; c < 3; c++)
        out[c] = 0.25f * (samples[a + c] + samples[a + 3 + c] + samples[b + c] +
                          samples[b + 3 + c]);
}

/* -------------------------------------------------------------- threads */

#define RTPI_MAX_THREADS 256

/* A lock for work that must be serial within a parallel run (a no-op in
   builds without threads, where every run is serial). */
#ifdef RTP_HAVE_THREADS
#include <pthread.h>
typedef pthread_mutex_t rtpi_mutex;
static inline int rtpi_mutex_init(rtpi_mutex *m) { return pthread_mutex_init(m, NULL); }
static inline void rtpi_mutex_lock(rtpi_mutex *m) { pthread_mutex_lock(m); }
static inline void rtpi_mutex_unlock(rtpi_mutex *m) { pthread_mutex_unlock(m); }
static inline void rtpi_mutex_destroy(rtpi_mutex *m) { pthread_mutex_destroy(m); }
#else
typedef int rtpi_mutex;
static inline int rtpi_mutex_init(rtpi_mutex *m) { *m = 0; return 0; }
static inline void rtpi_mutex_lock(rtpi_mutex *m) { (void)m; }
static inline void rtpi_mutex_unlock(rtpi_mutex *m) { (void)m; }
static inline void rtpi_mutex_destroy(rtpi_mutex *m) { (void)m; }
#endif

/* The count of the scenes holding a texture's pixels (rtpi_texture):
   under a lock, as a scene and its tree may be destroyed on two threads
   at once.  alloc: this block's (the image remembers its own). */
struct rtpi_texshare {
    rtp_allocator alloc;
    size_t refs;
    rtpi_mutex m;
};

/* An allocator for threads over one that need not be thread-safe: every
   call through a (the one to hand out) takes one lock. */
/* Whether a is the library's own (thread-safe: malloc's, and mappings). */
int rtpi_allocator_is_default(const rtp_allocator *a);

typedef struct rtpi_locked_alloc {
    rtp_allocator a, inner;
    rtpi_mutex m;
} rtpi_locked_alloc;
/* @return 0, or -1 when no lock could be made (then use inner alone). */
int rtpi_locked_alloc_init(rtpi_locked_alloc *l, const rtp_allocator *inner);
void rtpi_locked_alloc_destroy(rtpi_locked_alloc *l);

/* Work on one row with a thread's context; nonzero stops the whole run. */
typedef int (*rtpi_row_fn)(void *ctx, int row);

/* Runs fn over rows [0, nrows) on nthreads threads (the calling thread is
   one of them and the only one that calls progress); ctx[i] is thread i's
   context.  @return nonzero if some call asked to stop. */
int rtpi_parallel_rows(int nrows, int nthreads, void *const *ctx,
                       rtpi_row_fn fn, void (*progress)(void *, double),
                       void *progress_user);
/* The same for work that needs `stack` bytes of stack (0: as above):
   every row then runs on threads of rtp's own with at least that stack,
   the calling thread waiting and calling progress (where threads can be
   had; else the calling thread runs them, as above). */
int rtpi_parallel_rows_stack(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                             void (*progress)(void *, double), void *progress_user,
                             size_t stack);
/* The same with the caller's cancel, asked after each row the calling
   thread does or relays (with `user`, as progress): nonzero stops the
   rows not yet begun.  @return 2 when cancel stopped it, else as above. */
int rtpi_parallel_rows_cancel(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                              void (*progress)(void *, double), int (*cancel)(void *),
                              void *user, size_t stack);
/* A light buffer's lists past the entries its caller allowed
   (rtpi_lightbuf_build_some's max_entries: RTP_SHADOWS_AUTO's bound, which
   then takes shadow rays): never returned from the public calls; err
   holds RTP_ERR_LIMIT. */
#define RTPI_OVER_ENTRIES ((rtp_status)100)

/* The caller's progress and cancel for a long step inside a call (a
   direction cube's build): progress of the step in [0,1], asked from the
   calling thread only (as rtpi_parallel_rows_cancel's); NULL members:
   none. */
typedef struct rtpi_poll {
    void (*progress)(void *user, double done);
    int (*cancel)(void *user);
    void *user;
} rtpi_poll;
/* rtpi_parallel_rows_cancel with poll's callbacks, the rows' progress
   reported as [lo, lo + span] of the step's (poll NULL: none).  @return
   2 when cancel stopped it, else as rtpi_parallel_rows. */
int rtpi_parallel_rows_poll(int nrows, int nthreads, void *const *ctx, rtpi_row_fn fn,
                            const rtpi_poll *poll, double lo, double span);
/* Whether poll's cancel says to stop now (calling thread only). */
int rtpi_poll_cancelled(const rtpi_poll *poll);
/* A stop shared by the threads of a long row (a direction cube's rows of
   cells, an item buffer's bands): the calling thread reports progress
   and asks cancel now and then from inside its rows, every thread reads
   whether to stop. */
typedef struct rtpi_stopper {
    const rtpi_poll *poll; /* NULL: never stops, nothing reported */
    double lo, span, last; /* the rows' share of the build; last report */
    int stop;              /* cancel said yes (under lock) */
    rtpi_mutex lock;
} rtpi_stopper;
/* 0, or -1 when the lock cannot be made. */
int rtpi_stopper_init(rtpi_stopper *st, const rtpi_poll *poll, double lo, double span);
void rtpi_stopper_destroy(rtpi_stopper *st);
/* From inside a row: on the calling thread (is_main), progress at `done`
   of the rows (reported only forward) and the caller's cancel; on any,
   whether to stop. */
int rtpi_stopper_poll(rtpi_stopper *st, int is_main, double done);
/* The stack a ray tree of max_depth levels needs traced, where it is
   more than a host's thread can be counted on to have (0 otherwise). */
size_t rtpi_trace_stack(int max_depth);

/* 1 when trees of nnodes nodes fit the material lists' 32-bit node
   indices (tree.c; else evaluation takes the full path, without caches,
   and edits that trace samples again are refused). */
int rtpi_material_lists_fit(size_t nnodes);

/* ----------------------------------------------------------------- images */

/* Allocation-size check shared by everything that makes w*h*3 floats. */
int rtpi_image_size_ok(int width, int height);

/* RTP_ERR_CANCELLED: the caller's cancel said to stop (trace.c). */
rtp_status rtpi_cancelled(rtp_error *err);

/* RTP_ERR_ARGUMENT naming fn when t is in the middle of an evaluation
   (called from that evaluation's progress or cancel callback: an edit or
   a write there would be lost or see the tree half changed); else
   RTP_OK. */
rtp_status rtpi_tree_busy(const rtp_tree *t, const char *fn, rtp_error *err);

/* A one-off evaluation fed the trees as they are read (rtp_tree_eval_file;
   treefile.c's reader).  begin: once the file's scene and TREE's sample
   counts are read (t->start set, t->nodes not), can_stream 1 where the
   trees can be handed a band at a time (packed, light bits in the
   nodes); *stream set to 1 takes them so, else they are read whole into
   the tree.  band: sample rows y0 .. y1 - 1, sample y0 nx + i's nodes at
   nodes + start[i] .. nodes + start[i + 1] - 1, each checked as a whole
   read checks it.  An error of either stops the read with it at once.
   end: once begin was called, before the reader returns or frees the
   tree (whether the read failed or not). */
typedef struct rtpi_tree_sink {
    rtp_status (*begin)(void *user, rtp_tree *t, int can_stream, int *stream, rtp_error *err);
    rtp_status (*band)(void *user, rtp_tree *t, int y0, int y1, const rtpi_cnode *nodes,
                       const uint64_t *start, rtp_error *err);
    void (*end)(void *user, rtp_tree *t);
    void *user;
} rtpi_tree_sink;
rtp_status rtpi_tree_read_sink(const char *path, const rtp_allocator *alloc,
                               const rtpi_tree_sink *ts, rtp_tree **out, rtp_error *err);

#endif /* RTP_INTERNAL_H */
