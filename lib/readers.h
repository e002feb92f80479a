/*
 * readers.h — what the scene readers (nff.c, obj.c, bezier.c, lex.c)
 * share: a tokenizer that knows line and column, number and path helpers,
 * and extended entry points that report what a file held.  Nothing
 * outside the readers includes this.
 */
#ifndef RTP_READERS_H
#define RTP_READERS_H

#include "internal.h"

#include <float.h>

/* Material index used by the NFF reader for primitives that come before
   any `f` line.  It is replaced by a default material appended after the
   whole file is read, so that material N stays the N-th `f` line. */
#define RTPI_MAT_PENDING 0xfffffffeu

/* Longest token copied for number conversion; longer is a parse error
   (exporters that print 17 significant digits and a long exponent stay
   far below; 63 refused a valid 1.0 padded with zeros to 70 digits). */
#define RTPI_NUM_MAX 400

/* Include nesting allowed below the top-level file. */
#define RTPI_INCLUDE_MAX 8

/* Vertices per polygon/face; more is a parse error.  Ear clipping is
   quadratic: a concave 8192-gon takes about 0.25 s, and no real scene
   comes close (SPD's gears have 144). */
#define RTPI_POLY_MAX 8192

/* A vertex normal (x, y, z) as a unit vector, whatever its length: one
   whose length squared would be no normal double (below 2^-1022, a
   normal under ~1e-154 per component, which v3_norm's square took to 0
   or to a subnormal of few digits) is scaled by its largest component
   first.  A file's 1e-200 0 0 is the direction +x; it had become 0 0 0
   as a float, a zero normal (OBJ: a flat face) or a mix towards none
   (NFF pp).  Normals of a usual length take v3_norm itself, bit for bit
   as before.  Zero stays zero. */
static inline rtpi_v3 rtpi_unit_normal(double x, double y, double z)
{
    double m = fmax(fabs(x), fmax(fabs(y), fabs(z)));
    if (x * x + y * y + z * z >= DBL_MIN || !(m > 0.0))
        return v3_norm(v3(x, y, z));
    return v3_norm(v3(x / m, y / m, z / m));
}

/* A token: bytes [s, s+n) starting at 1-based line and column. */
typedef struct rtpi_tok {
    const char *s;
    size_t n;
    int line, col;
} rtpi_tok;

typedef struct rtpi_lex {
    const char *p, *end;
    const char *line_start;
    int line;
    int commas;      /* ',' separates tokens too (Newell's .bpt) */
    int continuation; /* a '\\' ending a line joins the next (OBJ, MTL) */
    const char *name; /* file name for messages */
    rtp_error *err;
} rtpi_lex;

void rtpi_lex_init(rtpi_lex *lx, const char *text, size_t size,
                   const char *name, rtp_error *err);
/* Next token, skipping white space, newlines and '#' comments.
   @return 1, or 0 at end of text (t then holds the end position). */
int rtpi_lex_next(rtpi_lex *lx, rtpi_tok *t);
/* Next token on the current line only (OBJ/MTL).  @return 1, or 0 at the
   end of the line or text (the newline is not consumed). */
int rtpi_lex_next_inline(rtpi_lex *lx, rtpi_tok *t);
/* Skips to the start of the next line. */
void rtpi_lex_skip_line(rtpi_lex *lx);
/* Current position as a zero-length token (for end-of-input errors). */
void rtpi_lex_here(const rtpi_lex *lx, rtpi_tok *t);

/* Token equals the NUL-terminated word. */
int rtpi_tok_is(const rtpi_tok *t, const char *word);
/* A finite number; @return 0, -1 if the token is not one, -2 if it is a
   decimal number beyond a double's range. */
int rtpi_tok_number(const rtpi_tok *t, double *out);
/* Whether the token was meant as a number, scene number or not: one that
   starts as a number does (a digit, a sign or '.': "1e999", "0x10",
   "-") or strtod's words for what is none ("nan", "inf", "infinity",
   signed or not, any case, "nan(...)").  Where a statement's numbers are
   optional (ka's green, a light's colour, a vertex's w), such a token is
   one of them, said as a bad number by its field, rather than the next
   keyword. */
int rtpi_tok_numlike(const rtpi_tok *t);
/* Whether the token is one of strtod's words for a non-finite value
   ("nan", "-inf", "Infinity", "nan(1)"), which no scene number is. */
int rtpi_tok_nan_inf(const rtpi_tok *t);
/* A decimal integer with an optional sign, |v| <= 2^31-1; @return 0/-1. */
int rtpi_tok_int(const rtpi_tok *t, long *out);
/* Copies the token into buf (at most size-1 bytes, bytes that are not a
   printable ASCII or UTF-8 character shown as '?', long tokens cut with
   "..." between characters) for messages.  @return buf. */
const char *rtpi_tok_show(const rtpi_tok *t, char *buf, size_t size);
/* rtpi_tok_show for a file's name: cut in its middle, its end kept. */
const char *rtpi_tok_show_path(const rtpi_tok *t, char *buf, size_t size);

/* Parse error at a token: file = lx->name. */
rtp_status rtpi_lex_error(const rtpi_lex *lx, const rtpi_tok *t,
                          const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Resolves `rel` (a token) against the folder of `base`: absolute paths
   are kept.  @return a new string from `a`, or NULL (out of memory). */
char *rtpi_path_join(const rtp_allocator *a, const char *base,
                     const char *rel, size_t rel_len);

/* Re-labels an error from a nested file operation (read, texture) with
   the position of the token that asked for it, keeping its status. */
rtp_status rtpi_lex_wrap(const rtpi_lex *lx, const rtpi_tok *t,
                         rtp_status st, const rtp_error *inner,
                         const char *what);

/* 4x3 affine transforms (rows: x' = m[0..2].p + m[3]), as rtpi_read_obj
   takes them. */
void rtpi_xform_identity(double m[12]);
/* m = b * a (a applied first). */
void rtpi_xform_mul(double m[12], const double b[12], const double a[12]);
void rtpi_xform_point(const double *m, const double p[3], double out[3]);
/* Normal matrix: inverse transpose of the linear part (9 doubles).
   @return -1 if the transform is singular. */
int rtpi_xform_normal_matrix(const double *m, double nm[9]);
/* 1 when the transform mirrors (its determinant is negative): a face's
   corners then go round the other way, and are swapped back. */
int rtpi_xform_mirrors(const double *m);

/* Counts of what the NFF source held, before triangulation. */
typedef struct rtpi_nff_stats {
    size_t polygons;     /* p */
    size_t polypatches;  /* pp */
    size_t spheres, cones;
    size_t includes;
} rtpi_nff_stats;

/* rtpi_read_nff that also fills *stats (may be NULL). */
rtp_status rtpi_read_nff_stats(rtp_scene *s, const char *text, size_t size,
                               const char *name, int include_depth,
                               rtpi_nff_stats *stats, rtp_error *err);

/* rtpi_read_obj with a face count (faces as written, before
   triangulation); `faces` may be NULL. */
rtp_status rtpi_read_obj_ex(rtp_scene *s, const char *text, size_t size,
                            const char *name, const double *xform,
                            uint32_t default_mat, size_t *faces,
                            rtp_error *err);

/* The MTL files one scene load has read and the materials each made,
   [first, end) of the scene's: two exports' MTL files both defining
   "Material" make two materials, each OBJ's usemtl finding its own
   MTL's; an MTL read again (the same OBJ included twice) gives its
   materials again, not copies (obj.c). */
typedef struct rtpi_mtl_seen {
    char *path;
    unsigned long long dev, ino; /* the file's identity (stat), where known */
    int has_id;
} rtpi_mtl_seen;
/* Names to indices, open addressing (index + 1 in a slot, 0 empty): the
   named materials ('f') or lights ('l') of the scene being loaded, so that
   a load of 80,000 named materials looks each up in constant time (a
   scan of all of them at each newmtl, usemtl and NFF name made it 21 s).
   Several entries may share a name; probing meets them in the order they
   were added. */
typedef struct rtpi_names {
    uint32_t *slot;
    size_t cap, n;
} rtpi_names;

typedef struct rtpi_mtl_reg {
    rtpi_mtl_seen *v; /* the MTL files read, each once whatever its path's spelling */
    size_t n, cap;
    uint32_t *src;    /* by material: 1 + the MTL file that made it, 0 none */
    size_t nsrc, cap_src;
    rtpi_names mats, lights;
    int synced; /* the scene's names before the load are in */
} rtpi_mtl_reg;
void rtpi_mtl_reg_free(rtpi_mtl_reg *r, const rtp_allocator *a);
/* Adds material or light i (kind 'f' or 'l'), named, to r's index;
   0, or -1 when out of memory. */
int rtpi_reg_add(rtpi_mtl_reg *r, const rtp_scene *s, int kind, uint32_t i);
/* The next material or light of that name after *at (start with *at = 0),
   in the order added: its index, or -1. */
long rtpi_reg_find(rtpi_mtl_reg *r, const rtp_scene *s, int kind, const char *name,
                   size_t n, size_t *at);

/* rtpi_read_obj_ex within a load that has read other OBJ files (an NFF
   scene's includes): `reg` the MTL files read so far, or NULL. */
rtp_status rtpi_read_obj_reg(rtp_scene *s, const char *text, size_t size,
                             const char *name, const double *xform,
                             uint32_t default_mat, size_t *faces,
                             rtpi_mtl_reg *reg, rtp_error *err);

#endif /* RTP_READERS_H */
