/*
 * rtp.h — parameterized ray tracing with geometric parameters.
 *
 * rtp traces a scene once with a Whitted ray tracer (its own kd-tree), and
 * keeps what later images need to be re-evaluated without tracing again.
 * This header is the whole public interface of librtp; the command-line
 * tool `rtp` uses nothing else.
 *
 * The flow
 *   rtp_scene_load     NFF (with rtp's additions) or OBJ+MTL -> rtp_scene
 *   rtp_scene_set      edit a parameter by key ("light.0.pos", "mat.2.kd");
 *                      rtp_scene_get reads one back
 *   rtp_trace          the image;  rtp_record: the image and its ray trees
 *   rtp_tree_write/read   the self-contained tree file (.rtp);
 *                      rtp_tree_read_summary checks one, keeping no trees
 *   rtp_tree_set       edit the tree's scene: materials, lights (moved ones
 *                      get new shadows), bumps, even ks/kt/ior (the samples
 *                      concerned are traced again, exactly) and the camera
 *                      (every sample: a full trace); rtp_tree_scene reads it
 *   rtp_tree_eval      the edited image, without tracing (rtp_tree_trace:
 *                      the full trace it must equal)
 *   rtp_image_diff     the error between two images
 * A renderer with its own tracer builds trees with rtp_builder_*.
 *
 * Conventions
 *  - Every function that can fail returns an rtp_status; RTP_OK is 0.
 *    Where an rtp_error* is taken (it may be NULL), a failure fills it with
 *    the status, a message and, for parse errors, the file, line and
 *    column; a success leaves it as it was.
 *  - Stateful objects (rtp_scene, rtp_tree, rtp_builder) are opaque
 *    handles; destroy functions accept NULL.  Plain data (options, images, stats) are structs where a
 *    zero-initialised value means "defaults".
 *  - The library has no global mutable state, never prints and never exits.
 *    A scene that is not being modified may be used from several threads at
 *    once (rtp_trace only reads it); a tree keeps evaluation caches, so one
 *    tree is used by one thread at a time (options.threads parallelise one
 *    call).
 *  - Memory comes from an rtp_allocator (NULL means the library's own on
 *    top of malloc/realloc/free, which on Linux also maps large growing
 *    blocks itself: free what the library made only through it, e.g.
 *    rtp_image_destroy); objects remember the allocator they were created
 *    with.  A caller's allocator gives all three functions (one with some
 *    and not others is RTP_ERR_ARGUMENT; all NULL, the library's own).  A
 *    caller's allocator need not be thread-safe: calls with
 *    options.threads > 1 take a lock around it (two calls of the library
 *    on different threads with one allocator still need it to be, and so
 *    does a call with it from a progress or cancel callback: the workers
 *    of the call reporting, threads > 1 or a deep tree's below, may be
 *    allocating meanwhile, outside that call's lock).
 *  - Stack: any call fits in a thread of 128 KiB (musl's default).
 *    Tracing and evaluating recurse up to 1 KiB a ray-tree level, so the
 *    rays and trees of a max_depth above 32 (up to RTP_MAX_DEPTH) are
 *    traced and evaluated on threads the library starts with the stack
 *    they need, even with threads 0 or 1 (the allocator is then called
 *    from that thread, never from two at once but for a callback's calls:
 *    above); the calling thread waits, and still makes every progress
 *    call.  A build without threads works on the calling thread: give it
 *    1 KiB (more under sanitizers) a level.
 *  - Images are linear RGB floats, row-major, top row first.
 */
#ifndef RTP_RAYTRACE_RTP_H
#define RTP_RAYTRACE_RTP_H

#include <stddef.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The shared library exports exactly the declarations in this header. */
#if defined(__GNUC__) && __GNUC__ >= 4
#pragma GCC visibility push(default)
#endif

/* Before 1.0 a minor version may add fields at the end of the public
   structs (0.2: rtp_trace_stats.capped_rays, rtp_eval_options.memory_limit,
   rtp_eval_stats.capped_rays and camera_moved; 0.3:
   rtp_eval_stats.stale_samples; 0.4: rtp_trace_options.cancel and
   rtp_eval_options.cancel; 0.5: rtp_tree_info.min_weight, and the calls
   rtp_tree_eval_file and rtp_tree_read_summary; light.N.pos of the next
   N adds a light; 0.5.1: the call rtp_tree_trace_opt, a call added, no
   struct changed; 0.6: rtp_eval_stats.shadow_res; 0.6.1:
   RTP_SHADOWS_AUTO without shadow_res takes coarser light buffers under
   the memory limit before shadow rays, as RTP_SHADOWS_LIGHTBUF does;
   0.6.2: RTP_SHADOWS_AUTO without shadow_res, once no light buffer fitted
   a tree's memory limit, takes shadow rays at once on that tree's later
   moves under that limit or a lower one): a program compares rtp_version_number() with the
   RTP_VERSION_NUMBER it was built with. */
#define RTP_VERSION_MAJOR 0
#define RTP_VERSION_MINOR 6
#define RTP_VERSION_PATCH 2
#define RTP_VERSION_NUMBER \
    (RTP_VERSION_MAJOR * 10000 + RTP_VERSION_MINOR * 100 + RTP_VERSION_PATCH)

/** @return RTP_VERSION_NUMBER of the library actually linked. */
unsigned rtp_version_number(void);
/** @return the version as "MAJOR.MINOR.PATCH". */
const char *rtp_version_string(void);

/* The deepest ray tree rtp traces, builds and reads (eye ray = 1): the
   evaluation recurses along a tree's depth. */
#define RTP_MAX_DEPTH 1000
/* The most direction-cube cells per face edge (rtp_eval_options.shadow_res):
   six faces of 8192^2 cells are 400 million. */
#define RTP_MAX_SHADOW_RES 8192

/* What this build of the library has (rtp_features' bits): PNG images
   through libpng, threads (else every call runs on the caller's thread
   whatever its thread count), the OSMesa backend of RTP_SHADOWS_OSMESA.
   Without one, calls that need it fail with RTP_ERR_UNSUPPORTED. */
#define RTP_FEATURE_PNG 1u
#define RTP_FEATURE_THREADS 2u
#define RTP_FEATURE_OSMESA 4u
/** @return the RTP_FEATURE_* bits of the library actually linked. */
unsigned rtp_features(void);

/* ---------------------------------------------------------------- errors */

/* Values are stable once released; new codes are added at the end. */
typedef enum rtp_status {
    RTP_OK = 0,
    RTP_ERR_NOMEM = 1,       /* an allocation failed */
    RTP_ERR_IO = 2,          /* a file could not be opened, read or written */
    RTP_ERR_PARSE = 3,       /* malformed scene, parameter or key text */
    RTP_ERR_ARGUMENT = 4,    /* an invalid argument or option value */
    RTP_ERR_UNSUPPORTED = 5, /* valid, but not supported (e.g. no libpng) */
    RTP_ERR_FORMAT = 6,      /* a binary file is corrupt, truncated or foreign */
    RTP_ERR_LIMIT = 7,       /* a size or memory limit would be exceeded */
    RTP_ERR_KEY = 8,         /* unknown parameter key or index */
    RTP_ERR_CANCELLED = 9    /* the caller's cancel callback said to stop */
} rtp_status;

/** @return a short constant description of a status ("out of memory"). */
const char *rtp_status_string(rtp_status status);

typedef struct rtp_error {
    rtp_status status;
    char file[256];    /* file the error is in, "" if none */
    int line, column;  /* 1-based; 0 when not applicable */
    char message[256]; /* what went wrong, without the position */
} rtp_error;

/** Formats `err` as "file:line:col: message" (as much as is known) into
 *  buf.  @return buf. */
char *rtp_error_format(const rtp_error *err, char *buf, size_t size);

/* ------------------------------------------------------------ allocation */

/* The three behave as malloc, realloc and free (user passed first): a
   block is aligned for any type, as malloc's (rtp keeps doubles and
   pointers in them); realloc_fn is given NULL for a new block, as realloc
   is; rtp never asks for 0 bytes and never frees NULL.  NULL from
   malloc_fn or realloc_fn is an allocation failure (RTP_ERR_NOMEM, or a
   slower path where one exists). */
typedef struct rtp_allocator {
    void *(*malloc_fn)(void *user, size_t size);
    void *(*realloc_fn)(void *user, void *ptr, size_t size);
    void (*free_fn)(void *user, void *ptr);
    void *user;
} rtp_allocator;

/* ----------------------------------------------------------------- scene */

typedef struct rtp_scene rtp_scene;

/** Loads a scene; the format follows the extension: ".obj" is Wavefront
 *  OBJ (+MTL), anything else NFF with rtp's additions (see README.md).
 *  `path` "-" reads NFF from stdin.  Relative paths inside the scene
 *  (include, textures, mtllib) are resolved against the scene's folder.
 *  @return RTP_OK, RTP_ERR_IO, RTP_ERR_PARSE (err has file:line:col),
 *  RTP_ERR_FORMAT (a texture or bump image that cannot be used),
 *  RTP_ERR_LIMIT (an image past the size limit), RTP_ERR_UNSUPPORTED (a PNG
 *  without libpng), RTP_ERR_ARGUMENT or RTP_ERR_NOMEM; *out is NULL on any
 *  failure.  An NFF v block with no view (at equal to from, up along the
 *  view) is read: rtp_trace, rtp_record and rtp_builder_create refuse it,
 *  RTP_ERR_ARGUMENT at its line, unless camera keys (rtp_scene_set) have
 *  repaired it. */
rtp_status rtp_scene_load(const char *path, const rtp_allocator *alloc,
                          rtp_scene **out, rtp_error *err);

/** Like rtp_scene_load from text in memory.  `name` is used in error
 *  messages and to resolve relative paths; `format` is "nff" or "obj".
 *  The size bytes are text: a NUL among them is RTP_ERR_PARSE at its
 *  line and column, as in a file. */
rtp_status rtp_scene_load_memory(const char *text, size_t size,
                                 const char *name, const char *format,
                                 const rtp_allocator *alloc, rtp_scene **out,
                                 rtp_error *err);

void rtp_scene_destroy(rtp_scene *scene);

/** Sets one parameter, e.g. key "light.0.pos" value "1,2,3".  Keys:
 *  light.N.pos|color|intensity|on, mat.N.color|kd|ks|kt|shine|ior|ambient (a
 *  material's own ambient coefficient, one number or r,g,b: once set, kd no
 *  longer moves it, until "kd" unsets it; and the texture and bump keys
 *  the README lists), ambient, background,
 *  camera.from|at|up|angle|hither; N is a 0-based index in file order or
 *  a name the scene gives (a name may hold dots: the field follows the
 *  last).  light.N.pos with N the count of lights (an index) adds light
 *  N there, white and on (rtp_tree_add_light's light).  An image key
 *  (mat.N.texture, mat.N.bump) reads its file each time, "-" stdin (all
 *  of it, one image: rtp_image_read); an image no material uses any more
 *  is freed.  @return RTP_OK, RTP_ERR_KEY, RTP_ERR_PARSE, RTP_ERR_IO,
 *  RTP_ERR_FORMAT, RTP_ERR_LIMIT (an image key's file past the image size
 *  limit) or RTP_ERR_UNSUPPORTED (a PNG without libpng), RTP_ERR_ARGUMENT
 *  (a value out of range: numbers |x| <= 3.4e38, the camera's from, at,
 *  up and hither |x| <= 1e18, as the scene files take them) or
 *  RTP_ERR_NOMEM; a refused edit leaves the
 *  scene as it was. */
rtp_status rtp_scene_set(rtp_scene *scene, const char *key,
                         const char *value, rtp_error *err);

/** Writes the current value of a key rtp_scene_set takes into buf, as it
 *  takes it: numbers comma-separated in the shortest form that reads back
 *  to the same value; checker and on 0 or 1; texture and bump none, waves,
 *  noise or the image's path ("-" for one read from stdin: setting that
 *  again reads stdin again, at its end by then); mat.N.ambient the effective
 *  coefficient (kd,kd,kd while the material has none of its own).  Also,
 *  read only: light.N.name and mat.N.name ("" when unnamed), and
 *  mat.N.ambient_own, "1" where the material has an ambient coefficient of
 *  its own (set, kd's edits leave it), "0" where it follows kd (set
 *  "kd"; what mat.N.ambient's numbers cannot tell of one set equal to
 *  kd), and file.N, the files a loaded scene read besides its own
 *  (include, bezier and mtllib files as resolved from its folder, in the
 *  order read: outputs that should not replace them; RTP_ERR_KEY past
 *  the last, and for a tree's scene, which reads none).  @return RTP_OK,
 *  RTP_ERR_KEY, or RTP_ERR_ARGUMENT when buf is too small (buf then ""). */
rtp_status rtp_scene_get(const rtp_scene *scene, const char *key, char *buf, size_t size,
                         rtp_error *err);

typedef struct rtp_scene_info {
    size_t triangles, spheres, cones; /* primitives after triangulation */
    size_t materials, lights, textures;
    int width, height;   /* resolution the scene asks for */
} rtp_scene_info;

/* All 0 for a NULL scene; nothing written for a NULL info. */
void rtp_scene_get_info(const rtp_scene *scene, rtp_scene_info *info);

/* ----------------------------------------------------------------- image */

typedef struct rtp_image {
    int width, height;
    float *pixels;            /* width*height*3 floats, top row first */
    rtp_allocator alloc;      /* what pixels came from */
} rtp_image;

/** Allocates a black image.  @return RTP_OK, RTP_ERR_ARGUMENT, RTP_ERR_LIMIT
 *  or RTP_ERR_NOMEM. */
rtp_status rtp_image_create(int width, int height, const rtp_allocator *alloc,
                            rtp_image **out, rtp_error *err);
void rtp_image_destroy(rtp_image *image);

typedef enum rtp_image_format {
    RTP_IMAGE_AUTO = 0, /* from the file extension; stdout "-",
                           rtp_image_write_stream's stream and a pipe or
                           device named without one (/dev/null) mean PFM */
    RTP_IMAGE_PNG = 1,  /* 8-bit sRGB-free: values clamped to [0,1], *255;
                           NaN and +-infinity 0 (a bad pixel shows black) */
    RTP_IMAGE_PPM = 2,  /* binary P6, 8-bit, like PNG */
    RTP_IMAGE_PFM = 3   /* float RGB, little-endian, exact */
} rtp_image_format;

/** @return the format named by path's extension, RTP_IMAGE_AUTO if none. */
rtp_image_format rtp_image_format_from_path(const char *path);

/** Writes an image; path "-" is stdout.  Nothing is left behind on
 *  failure: files are written to a temporary name and renamed (a path
 *  that is not a regular file, as a pipe or a device, is written in
 *  place; a regular file named through /dev/fd/N or /proc/PID/fd/N,
 *  another open file as a shell's 2>>log makes one, is appended to; and
 *  a path naming the process's stdout is written through stdout). */
rtp_status rtp_image_write(const rtp_image *image, const char *path,
                           rtp_image_format format, rtp_error *err);
/** Writes to an open stream. */
rtp_status rtp_image_write_stream(const rtp_image *image, FILE *stream,
                                  rtp_image_format format, rtp_error *err);
/** Reads a PNG, PPM (P3/P6) or PFM; path "-" is stdin (format sniffed).
 *  The image is all the file holds: bytes after a PPM's or PFM's pixels
 *  are RTP_ERR_FORMAT, from stdin or a pipe too (read to its end, or
 *  16 MiB past the image: an endless source is refused; a P6 may end in
 *  one line feed).  rtp_image_read_stream reads one image and
 *  leaves what follows it (the next image of a stream) unread. */
rtp_status rtp_image_read(const char *path, const rtp_allocator *alloc,
                          rtp_image **out, rtp_error *err);
rtp_status rtp_image_read_stream(FILE *stream, const char *name,
                                 const rtp_allocator *alloc, rtp_image **out,
                                 rtp_error *err);
/** @return nonzero if this build can read and write PNG (libpng). */
int rtp_png_supported(void);

/* ----------------------------------------------------------------- trace */

typedef struct rtp_trace_options {
    int width, height;  /* 0: the scene's resolution */
    int spd;            /* nonzero: SPD testing procedure, 512x512
                           (whatever width and height say) from 513x513
                           corner rays, no cut-off, one-sided opaque
                           objects, to max_depth (SPD's is 5, the
                           default) */
    int max_depth;      /* ray-tree depth, eye ray = 1; 0: 5; at most
                           RTP_MAX_DEPTH */
    double min_weight;  /* rays weighing less are not spawned; 0: none
                           (re-evaluating a ks or kt edit of such trees
                           traces the material's samples again) */
    int threads;        /* 0 or 1: one thread, the calling one (deep
                           trees aside: see Stack above); more than 256
                           are taken as 256; negative: RTP_ERR_ARGUMENT */
    double memory_limit; /* bytes the image, samples and trees may take;
                            0: 16 GiB.  Past it: RTP_ERR_LIMIT, before any
                            tracing where the image and one node a sample
                            are over it, else when the trees outgrow it */
    int region[4];      /* x0, y0, x1, y1: trace only pixels x0 <= x < x1,
                           y0 <= y < y1 of the frame (all 0: the frame);
                           the image is the region's; see rtp_tree_merge */
    /* Called now and then from the calling thread with done in [0,1];
       NULL for none.  It and cancel must not modify or destroy the scene
       being traced (rtp_scene_set): the rows traced before and after
       would belong to two scenes. */
    void (*progress)(void *user, double done);
    void *progress_user;
    /* Asked now and then from the calling thread (with progress_user):
       before and after the kd-tree's build and after each row the calling
       thread traces (with several threads it traces a share of them; with
       max_depth above 32 it asks as the workers' rows end); nonzero stops
       the trace as soon as the rows being traced end: RTP_ERR_CANCELLED,
       nothing made (out-parameters NULL).  NULL: never. */
    int (*cancel)(void *user);
} rtp_trace_options;

typedef struct rtp_trace_stats {
    double build_seconds;  /* kd-tree build */
    double trace_seconds;  /* tracing and shading */
    unsigned long long eye_rays, eye_hits, shadow_rays, reflected_rays,
        refracted_rays;
    unsigned long long kd_nodes, kd_leaves, kd_prim_refs;
    int kd_depth;
    int width, height;
    unsigned long long capped_rays; /* rays that hit but were not followed:
                                       their sample's tree had 2^20 nodes
                                       (the image lacks what they carried) */
} rtp_trace_stats;

/** Traces the scene into a new image.  stats may be NULL.
 *  @return RTP_OK, RTP_ERR_ARGUMENT, RTP_ERR_LIMIT, RTP_ERR_NOMEM or
 *  RTP_ERR_CANCELLED (opt->cancel). */
rtp_status rtp_trace(const rtp_scene *scene, const rtp_trace_options *opt,
                     rtp_image **out, rtp_trace_stats *stats, rtp_error *err);

/* ------------------------------------------------------------- ray trees */

/* The ray trees of a traced image together with a copy of the scene they
 * were traced in: enough to re-evaluate the image for new parameters
 * without tracing.  A tree keeps caches for the next evaluation: use one
 * tree from one thread at a time.  The copy shares the scene's texture
 * and bump images, which are read only once loaded: each is freed with
 * the last scene or tree holding it, so the scene and its trees may be
 * destroyed in any order, on any threads.  (A build without threads has
 * no lock to count the holders under: there the copy holds images of
 * its own, as much memory again.) */
typedef struct rtp_tree rtp_tree;

/** Traces like rtp_trace and also keeps every sample's ray tree.  The image
 *  is the evaluation of those trees (rtp_tree_eval of the unedited tree
 *  reproduces it bit for bit).  image and stats may be NULL. */
rtp_status rtp_record(const rtp_scene *scene, const rtp_trace_options *opt,
                      rtp_tree **tree, rtp_image **image,
                      rtp_trace_stats *stats, rtp_error *err);

void rtp_tree_destroy(rtp_tree *tree);

/** The tree's scene with the edits made to it, read only (rtp_scene_get,
 *  rtp_scene_get_info); valid while the tree lives. */
const rtp_scene *rtp_tree_scene(const rtp_tree *tree);

/** Edits a parameter of the tree's scene (keys as rtp_scene_set).  A moved
 *  light is re-evaluated with new shadows (see rtp_eval_options.shadows).
 *  Edits that change where rays go — a new ior, ks or kt raised from 0, or
 *  any ks or kt edit of a tree traced with a weight cut-off (min_weight) —
 *  make the next evaluation trace again
 *  exactly the samples whose trees contain that material (stats report how
 *  many); never an approximation.  A camera key makes the next
 *  evaluation trace every sample again (a full trace into the tree's
 *  trees; stats->camera_moved), and until then rtp_tree_write refuses
 *  the tree.  A refused edit leaves the tree unchanged. */
rtp_status rtp_tree_set(rtp_tree *tree, const char *key, const char *value,
                        rtp_error *err);

/* How a re-evaluation decides which hits see a light that moved. */
typedef enum rtp_shadow_mode {
    RTP_SHADOWS_EXACT = 0,    /* shadow rays through the kd-tree: exact */
    RTP_SHADOWS_LIGHTBUF = 1, /* light buffer: direction cube with sorted
                                 candidate lists per cell: exact, faster
                                 on six of the seven SPD scenes (README) */
    RTP_SHADOWS_ITEMBUF = 2,  /* item buffer from a software z-buffer (the
                                 paper's): approximate at shadow edges; its
                                 checks make it no faster than the light
                                 buffer on the SPD scenes (README) */
    RTP_SHADOWS_OSMESA = 3,   /* the item buffer drawn by OSMesa (builds
                                 with OSMESA=1), from a thread of its own:
                                 the caller's OpenGL binding is untouched */
    RTP_SHADOWS_AUTO = 4      /* exact: the light buffer where the tree has
                                 at least 4 recorded hits a primitive (or,
                                 with no_cache, one or two lights moved
                                 while the tree has no kd-tree and no move
                                 before) unless its lists would be long
                                 (overlapping primitives: past 16 entries
                                 a hit and a primitive, README), else
                                 shadow rays through the kd-tree (the
                                 CLI's default); shadow_res 0:
                                 the light buffer's as RTP_SHADOWS_LIGHTBUF's */
} rtp_shadow_mode;

/* What becomes of the reflected and refracted subtrees below a normal a
   bump edit changed: their rays would now leave in other directions. */
typedef enum rtp_stale_mode {
    RTP_STALE_KEEP = 0,   /* keep them (the paper's behaviour): fast,
                             approximate; --reference reports the error */
    RTP_STALE_RETRACE = 1 /* trace again the samples that contain the
                             material: exact */
} rtp_stale_mode;

typedef struct rtp_eval_options {
    int threads;            /* 0 or 1: one thread, the calling one (a
                               deep tree's re-trace aside: Stack above);
                               more than 256 are taken as 256; negative:
                               RTP_ERR_ARGUMENT */
    rtp_shadow_mode shadows;
    int shadow_res;         /* direction-cube cells per face edge, at most
                               RTP_MAX_SHADOW_RES; 0: an item buffer's 512
                               (the cells are its accuracy), a light
                               buffer's (LIGHTBUF, AUTO) from the tree's
                               hits: 256 sqrt(hits / 250,000) as a power of
                               two, 64 to 512 (its decisions are exact at
                               any resolution: finer cells shorten the
                               lists a query walks and cost more to fill
                               at each move), halved while the memory
                               limit refuses it (LIGHTBUF and AUTO;
                               AUTO takes shadow rays where even 1 cell
                               does not fit); rtp_eval_stats.shadow_res
                               says which */
    rtp_stale_mode stale;
    int no_cache;           /* 1: a one-off evaluation: keep no caches for
                               later edits (faster once, slower after) */
    /* Called now and then from the calling thread with done in [0,1]
       (at most about a thousand times a step: a re-trace, each moved
       light, the evaluation); NULL for none.  It and cancel may not use
       the tree being evaluated:
       rtp_tree_set, _add_light, _eval, _eval_into, _trace, _write, _crop
       and _merge on it return RTP_ERR_ARGUMENT until the evaluation
       returns (rtp_tree_get_info may be called; rtp_tree_destroy may
       not). */
    void (*progress)(void *user, double done);
    void *progress_user;
    int incremental;        /* 1: the image given to rtp_tree_eval_into still
                               holds what this tree's last evaluation wrote
                               there (the caller's promise): pixels an edit
                               cannot change are not written again.  Ignored
                               when that image (known by its pixels' address)
                               is not the one this tree wrote last; nothing
                               else is checked: an image made anew at the
                               same address, or one another tree's
                               evaluation (a crop's too) wrote since, gets
                               wrong pixels, so set this only for the image
                               this tree wrote last and nothing wrote
                               since.  An evaluation of every sample (the
                               first) with it set also makes the
                               snapshot colour edits start from (12
                               bytes a pixel, kept) and, in a scene of
                               one or two lights, readies the first
                               colour edit of each light: 12 bytes more
                               a pixel each light reaches, kept. */
    double memory_limit;    /* bytes the trees may take while samples are
                               traced again (class D), old and new, and a
                               moved light's direction cube's cells (6
                               shadow_res^2, 9 bytes each for an item
                               buffer, OSMesa's 12 more a face cell, 4
                               for a light buffer, whose per-primitive
                               arrays and lists are counted too before
                               they are made); 0: 16 GiB.
                               Past it: RTP_ERR_LIMIT, the tree as it was
                               (RTP_SHADOWS_AUTO takes shadow rays
                               instead of a cube over it; without
                               shadow_res a coarser light buffer first,
                               halving its cells while they do not fit;
                               where none did down to 1 cell, the tree's
                               later moves under as much or less take
                               shadow rays at once) */
    /* Asked now and then from the calling thread (with progress_user)
       while samples are traced again (class-D edits, RTP_STALE_RETRACE, a
       moved camera) and while moved lights' shadows are decided (on
       either side of a shadow structure's build, inside a light or item
       buffer's build but OSMesa's, and after rows): the long
       evaluations; nonzero stops it as soon as the rows being traced
       or decided end: RTP_ERR_CANCELLED, the tree as it was (the edits
       stay set: the next evaluation traces or decides them).  NULL:
       never. */
    int (*cancel)(void *user);
} rtp_eval_options;

typedef struct rtp_eval_stats {
    double seconds;          /* the whole evaluation */
    double shadow_seconds;   /* of which: deciding moved lights' visibility
                                (0 when none was decided; a re-trace is not
                                counted) */
    unsigned long long samples, nodes;
    unsigned long long shadow_queries; /* node-light pairs decided anew */
    int moved_lights;        /* lights whose visibility was recomputed */
    unsigned long long retraced_samples; /* traced again for a class-D edit */
    unsigned long long retraced_rays;    /* rays those cast (all kinds):
                                            below the edited materials'
                                            hits, the rest kept as traced
                                            (a builder's tree, or a camera
                                            edit: the whole samples') */
    unsigned long long combined_samples; /* samples whose colour was summed
                                            from their coefficients; 0 when
                                            an edit of colours (lights,
                                            ambient, background) or of one
                                            material's kd or colour was made
                                            per pixel from planes */
    unsigned long long written_pixels;   /* pixels written (fewer than the
                                            image's with opt->incremental) */
    rtp_shadow_mode shadows; /* how moved lights' shadows were decided (the
                                mode asked, RTP_SHADOWS_AUTO resolved),
                                where moved_lights > 0 */
    unsigned long long capped_rays; /* re-traced rays that hit but were not
                                       followed (a sample's tree was full,
                                       as rtp_trace_stats says) */
    int camera_moved;        /* 1: the camera was edited, so every sample
                                was traced again (a full trace into the
                                tree's trees) */
    unsigned long long stale_samples; /* samples whose reflected or
                                refracted rays below a changed bump map
                                were kept (RTP_STALE_KEEP): the image is
                                approximate there; 0 otherwise.  An upper
                                bound where another edit traced some of
                                them again (they are counted still) */
    int shadow_res;          /* the light or item buffer's cells a face
                                edge that decided the last moved light (0:
                                shadow rays), where moved_lights > 0 */
} rtp_eval_stats;

/** Evaluates the trees with the current parameters into a new image.  Lights
 *  that moved since the trace get their shadows decided anew (opt->shadows);
 *  the tree keeps what it computes for the next evaluation, so one tree must
 *  not be evaluated from two threads at once (opt->threads parallelises one
 *  evaluation).  What it keeps, beyond the tree: per node and sample the
 *  shading terms and coefficients (and per node its path weight and its
 *  place in its material's list, 12 bytes), for colour edits a snapshot
 *  image (12 bytes a pixel) and a plane for each colour term edited (16
 *  bytes a pixel, at most 8 kept), for the material last edited in kd
 *  or colour its planes (up to 40 bytes a pixel, 12 a sample; after a kd
 *  edit as far as they fit in the samples' own block, which holds nothing
 *  while kd edits follow one another), after a move a byte a sample (the
 *  samples it changed) and 24 bytes a node (its diffuse colour product,
 *  the part of a lit node's shading that does not depend on where the
 *  light is), after an exact move 4 bytes a node (its point's kd leaf)
 *  and with the scene's kd-tree its leaves' lists of ancestors for walks
 *  from them (9 entries of 8 bytes a leaf and 4 an ancestor, made once
 *  where opt->memory_limit holds them), and for a light moved
 *  alone again and again in a scene of 3 lights or more the sums of every
 *  other term (25 bytes a sample); opt->no_cache keeps none of it. */
rtp_status rtp_tree_eval(rtp_tree *tree, const rtp_eval_options *opt,
                         rtp_image **out, rtp_eval_stats *stats,
                         rtp_error *err);

/** Like rtp_tree_eval into an image the caller keeps (of the tree's size),
 *  so a stream of edits allocates nothing per image. */
rtp_status rtp_tree_eval_into(rtp_tree *tree, const rtp_eval_options *opt,
                              rtp_image *image, rtp_eval_stats *stats,
                              rtp_error *err);

/** Adds a light (white, on) at the given position; it gets the next index.
 *  Its shadows are decided at evaluation like those of a moved light, and
 *  it costs about what a move does: the kept terms and coefficients grow
 *  by the light's own (its visibility, terms and the samples it reaches),
 *  not all made again over every light.  A tree with an added light cannot be written (rtp_tree_write:
 *  RTP_ERR_UNSUPPORTED; the file holds the lights the trees were traced
 *  with, their visibility recorded) nor merged, until a camera edit's
 *  evaluation traces every sample again: that trace casts the shadow rays
 *  of every light where it is then, added ones too, and the trees record
 *  them as traced. */
rtp_status rtp_tree_add_light(rtp_tree *tree, const double pos[3],
                              rtp_error *err);

/** Full-traces the tree's scene as it now is (with every edit), with the
 *  options the tree was traced with: the exact reference a re-evaluation
 *  is compared against.  threads as in rtp_trace_options. */
rtp_status rtp_tree_trace(const rtp_tree *tree, int threads, rtp_image **out,
                          rtp_trace_stats *stats, rtp_error *err);
/** rtp_tree_trace with opt's threads, memory_limit, progress,
 *  progress_user and cancel, as rtp_trace takes them (opt NULL: the
 *  defaults); the size, region, spd, max_depth and min_weight are the
 *  tree's, whatever opt says.  Progress and cancel may not use the tree
 *  being traced, as an evaluation's (rtp_eval_options.progress): those
 *  calls return RTP_ERR_ARGUMENT until the trace returns. */
rtp_status rtp_tree_trace_opt(const rtp_tree *tree, const rtp_trace_options *opt,
                              rtp_image **out, rtp_trace_stats *stats, rtp_error *err);

/** Joins trees traced from regions of one frame (rtp_trace_options.region)
 *  of the same scene with the same options into the whole frame's tree;
 *  the regions must cover the frame without overlapping.  Its evaluation
 *  equals a whole-frame trace bit for bit.  An error names a part by its
 *  index, "parts[K]", and says what differs from parts[0] first (frame,
 *  SPD, depth, min_weight, scene, camera, a material's or light's key).
 *  @return RTP_ERR_ARGUMENT (no parts, a NULL one, parts of different
 *  scenes, frames, options or edits, overlaps or gaps),
 *  RTP_ERR_UNSUPPORTED (a part with an added light), RTP_ERR_NOMEM;
 *  *out is NULL on any failure.  The merged tree takes
 *  parts[0]'s allocator. */
rtp_status rtp_tree_merge(rtp_tree *const *parts, size_t n, rtp_tree **out,
                          rtp_error *err);
/** The inverse: a new tree of the pixels x0 <= x < x1, y0 <= y < y1
 *  (region = {x0, y0, x1, y1}, frame coordinates; all 0: the tree's own
 *  pixels) of a tree's pixels, as tracing that region would have made it
 *  (SPD: with the corner samples around them), edits and added lights
 *  included, caches not.  Evaluated, it gives that region of the tree's
 *  own first evaluation with the same edits, bit for bit, at a cost in
 *  proportion to the region (the tree's scene is copied whole, a small
 *  part).  A tree evaluated before keeps planes from which later edits
 *  are made (README: "Exact"), so its images may come a float rounding
 *  apart from the crop's; both stay within 1e-6 of a full trace.
 *  @return RTP_ERR_ARGUMENT (a NULL argument, a region empty or not
 *  inside the tree's pixels), RTP_ERR_NOMEM; *out is NULL on any
 *  failure. */
rtp_status rtp_tree_crop(const rtp_tree *tree, const int region[4], rtp_tree **out,
                         rtp_error *err);

typedef struct rtp_tree_info {
    int width, height, spd, max_depth;
    int full_width, full_height, region_x, region_y; /* the frame and where
                                                        this region is */
    unsigned long long samples, nodes;
    unsigned bytes_per_node;  /* size of one node record */
    unsigned long long tree_bytes; /* nodes, visibility and sample index */
    size_t lights, materials, triangles, spheres, cones;
    double min_weight;        /* the trace's cut-off (0: none): a ks or kt
                                 edit of such trees traces again */
} rtp_tree_info;

/* All 0 for a NULL tree; nothing written for a NULL info. */
void rtp_tree_get_info(const rtp_tree *tree, rtp_tree_info *info);

/* The edits of a one-off evaluation of a tree file (rtp_tree_eval_file):
 * called once the file's scene is read, before its trees, with the tree
 * then, which only rtp_tree_set, rtp_tree_add_light, rtp_tree_scene and
 * rtp_tree_get_info may be given (its trees are not there yet: other
 * calls return RTP_ERR_ARGUMENT), and only during the call.  A status but
 * RTP_OK stops the evaluation with it (and err as the function set it). */
typedef rtp_status (*rtp_tree_edit_fn)(void *user, rtp_tree *tree, rtp_error *err);

/** A one-off evaluation of a tree file ("-": stdin): reads it, calls
 *  edit (NULL: none), evaluates, frees the tree.  The image and stats are
 *  those of rtp_tree_read, the same edits and rtp_tree_eval with
 *  opt->no_cache set, bit for bit, and a file those refuse is refused with
 *  the same error.  Where the edits trace nothing again (no class-D edit,
 *  no camera edit, no bump edit with RTP_STALE_RETRACE) and move or add
 *  one light at most, and the file holds at most 32 lights (format 2),
 *  each sample's tree is evaluated as it is read and none is kept: the
 *  memory of the image, the samples' node counts (a byte each for most), a band of
 *  trees and the moved light's direction cube, not of every tree (README: "One-off evaluation"; the moved
 *  light's shadow queries are made first, its cube's build asking
 *  opt->cancel).  Otherwise the trees are read whole first.  info (may be NULL) receives rtp_tree_get_info
 *  of the tree read; stats->seconds is the evaluation's time with the
 *  reading of the trees it was made with (not of the scene before them).
 *  Progress and cancel (opt) are called between bands too.
 *  @return as rtp_tree_read and rtp_tree_eval, or edit's status. */
rtp_status rtp_tree_eval_file(const char *path, const rtp_allocator *alloc,
                              rtp_tree_edit_fn edit, void *user,
                              const rtp_eval_options *opt, rtp_image **out,
                              rtp_tree_info *info, rtp_eval_stats *stats,
                              rtp_error *err);

/** Writes the tree file (format 2.0, nodes and meshes packed:
 *  lib/tree-format.md); "-" is stdout.  Files are written to a temporary
 *  name and renamed: nothing half written is left (pipes, devices, another
 *  open file named through /dev/fd/N and stdout's own file are written as
 *  rtp_image_write writes them).  bytes (may be NULL) receives the bytes
 *  written: the file's size, but where appended to. */
rtp_status rtp_tree_write(const rtp_tree *tree, const char *path,
                          unsigned long long *bytes, rtp_error *err);
/** Reads and validates a tree file of format 1 or 2; "-" is stdin.  A
 *  truncated, corrupt, foreign or newer file gives RTP_ERR_FORMAT naming
 *  what is wrong (the same error rtp_tree_read_memory gives for the same
 *  bytes).  The file is parsed as it is read: its bytes are not held in
 *  memory beside the tree. */
rtp_status rtp_tree_read(const char *path, const rtp_allocator *alloc,
                         rtp_tree **out, rtp_error *err);
rtp_status rtp_tree_read_memory(const void *data, size_t size,
                                const char *name, const rtp_allocator *alloc,
                                rtp_tree **out, rtp_error *err);
/** Reads and validates a tree file ("-": stdin) as rtp_tree_read does,
 *  every check made (checksums, lengths, every node and every sample's
 *  tree) and the same error for the same file, but keeps none of its ray
 *  trees: each band of sample rows is checked and dropped, in the memory
 *  of the scene, the samples' node counts (a byte each for most) and
 *  a band of trees, not of every tree (what `rtp info` does).  *out holds
 *  the scene and the totals (samples, nodes): rtp_tree_get_info gives what it gives of
 *  rtp_tree_read's tree, rtp_tree_scene, rtp_tree_set and
 *  rtp_tree_add_light work; rtp_tree_eval, rtp_tree_eval_into,
 *  rtp_tree_trace, rtp_tree_trace_opt, rtp_tree_write, rtp_tree_merge and
 *  rtp_tree_crop return RTP_ERR_ARGUMENT (read it with rtp_tree_read for
 *  those).
 *  @return as rtp_tree_read. */
rtp_status rtp_tree_read_summary(const char *path, const rtp_allocator *alloc,
                                 rtp_tree **out, rtp_error *err);

/* --------------------------------------------------------------- builder */

/* For renderers that trace rays themselves: hand rtp the hits of every
 * sample's ray tree, then use rtp's evaluation, edits and tree files.
 *
 *   rtp_builder_create(scene, w, h, 0, &b, &err);
 *   for each sample (x, y), row by row or in any order:
 *       root = rtp_builder_hit(b, x, y, RTP_NO_PARENT, RTP_RAY_EYE, &hit, &err);
 *       refl = rtp_builder_hit(b, x, y, root, RTP_RAY_REFLECTED, &hit2, &err);
 *       rtp_builder_miss(b, x, y, root, RTP_RAY_REFRACTED, &err);   background
 *   rtp_builder_finish(b, &tree, &err);
 *
 * A sample with no eye-ray hit shows the background.  The scene gives the
 * materials, lights and geometry the hits refer to; the builder keeps its
 * own copy. */
typedef struct rtp_builder rtp_builder;

#define RTP_NO_PARENT (-1)
typedef enum rtp_ray_kind {
    RTP_RAY_EYE = 0,       /* the sample's first hit (no parent) */
    RTP_RAY_REFLECTED = 1, /* the parent's mirror ray */
    RTP_RAY_REFRACTED = 2  /* the parent's transmitted ray */
} rtp_ray_kind;

typedef struct rtp_hit_record {
    double pos[3];       /* where the ray hit */
    unsigned prim;       /* primitive hit: triangles (after triangulation),
                            then spheres, then cones, in scene order */
    int back;            /* the ray hit the back of the surface */
    int total_internal;  /* total internal reflection at this hit: the
                            transmitted share follows the reflected ray
                            (no refracted ray: finish refuses one) */
    const unsigned char *lights; /* bit i (LSB first): light i seen from
                            here, for every light of the scene, those
                            switched off too (a light.N.on edit shows what
                            these bits say; rtp's trace casts their shadow
                            rays): (lights in the scene + 7) / 8
                            bytes; NULL: none */
} rtp_hit_record;

/** Starts a tree of width x height samples (spd: corner samples of a
 *  width x height image, i.e. (width+1) x (height+1), averaged).  The
 *  scene's camera must give a view (as rtp_trace's): the tree keeps it. */
rtp_status rtp_builder_create(const rtp_scene *scene, int width, int height,
                              int spd, rtp_builder **out, rtp_error *err);
/** The renderer's ray-tree depth limit (eye ray = 1, as
 *  rtp_trace_options.max_depth), 1..RTP_MAX_DEPTH: re-traces of class-D
 *  edits (a ks or kt raised from 0, an ior) and rtp_tree_trace trace to
 *  it.  Without it the tree's depth is its deepest ray handed in, a miss
 *  counting as a ray of its level: a scene whose rays all stop at the
 *  first hit then re-traces a mirror made later one level deep.
 *  rtp_builder_finish refuses rays deeper than the depth set. */
rtp_status rtp_builder_set_depth(rtp_builder *b, int max_depth, rtp_error *err);
/** Adds a hit to sample (x, y) as the given child of node `parent` (an
 *  index returned earlier for the same sample).  @return the new node's
 *  index (>= 0) or a negative rtp_status (see err): test it before
 *  passing it on as a parent (-RTP_ERR_NOMEM is -1, RTP_NO_PARENT's
 *  value). */
int rtp_builder_hit(rtp_builder *b, int x, int y, int parent, rtp_ray_kind kind,
                    const rtp_hit_record *hit, rtp_error *err);
/** Records that the given child ray of `parent` left the scene. */
rtp_status rtp_builder_miss(rtp_builder *b, int x, int y, int parent,
                            rtp_ray_kind kind, rtp_error *err);
/** Validates every sample's tree and makes the rtp_tree; the builder is
 *  consumed (destroyed) either way.  A hit above the tree's depth whose
 *  material reflects (ks > 0) or transmits (kt > 0) but that was given no
 *  such ray (hit or miss; a total internal reflection's is the reflected
 *  one) is the renderer's own cut-off: the tree keeps one
 *  (rtp_tree_info.min_weight > 0), so any ks or kt edit traces the
 *  material's samples again, as for rtp_trace_options.min_weight. */
rtp_status rtp_builder_finish(rtp_builder *b, rtp_tree **out, rtp_error *err);
void rtp_builder_destroy(rtp_builder *b);

/* ------------------------------------------------------------ image diff */

typedef struct rtp_diff_stats {
    double mae, rmse, psnr, max_abs; /* psnr: +HUGE_VAL when identical */
    double share_above;              /* pixels whose max channel error
                                        exceeds the threshold, in [0,1] */
    size_t pixels;
} rtp_diff_stats;

/** Compares two images of equal size channel by channel (peak 1.0); a
 *  pixel whose largest channel error exceeds threshold counts in
 *  share_above (a negative threshold counts every pixel, as 0 counts
 *  every pixel that differs).
 *  @return RTP_OK, or RTP_ERR_ARGUMENT on a size mismatch, a missing
 *  image or stats, or a NaN threshold. */
rtp_status rtp_image_diff(const rtp_image *a, const rtp_image *b,
                          double threshold, rtp_diff_stats *stats,
                          rtp_error *err);

/** Writes a heat map of the per-pixel error of a against b with a colour
 *  legend, in the format the path's extension names (.ppm, .pfm; any other
 *  name: PNG, or PPM where rtp_png_supported() is 0); `scale` is the error shown at full heat (0: the largest
 *  finite error, 1 where there is none; infinite errors show at full
 *  heat; a negative, infinite or NaN scale is RTP_ERR_ARGUMENT). */
rtp_status rtp_diff_heatmap(const rtp_image *a, const rtp_image *b,
                            double scale, const char *png_path,
                            rtp_error *err);

#if defined(__GNUC__) && __GNUC__ >= 4
#pragma GCC visibility pop
#endif

#ifdef __cplusplus
}
#endif
#endif /* RTP_RAYTRACE_RTP_H */
