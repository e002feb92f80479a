/*
 * image.c — images in memory and on disk: PNG (libpng, 8-bit), PPM (P6
 * out; P6 and P3 in) and PFM (float, exact).
 *
 * Readers sniff the format from the first bytes, never from the name, and
 * treat every header field and length as hostile: a truncated, corrupt or
 * foreign file gives RTP_ERR_FORMAT naming the file and what is wrong.
 * Pixel memory grows with the data actually read, so a header that claims
 * a huge image costs nothing until its pixels arrive.
 *
 * Writers go to a temporary file beside the target and rename it over the
 * target, so a failed write leaves neither a half-written image nor a
 * stray temporary behind.
 */
#include "internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#if defined(__unix__) || defined(__APPLE__)
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#define RTPI_POSIX_FILES 1
#endif

#if defined(RTP_HAVE_PNG)
#if RTP_HAVE_PNG
#define RTPI_PNG 1
#include <png.h>
#include <setjmp.h>
#endif
#endif

/* Limits: 2^20 pixels a side and 2^27 pixels (1.5 GiB of floats) in all,
   far beyond any image a ray tracer makes, small enough that w*h*3 floats
   fit a size_t everywhere and a fuzzer's memory cap is not hit. */
#define RTPI_IMAGE_MAX_DIM (1L << 20)
#define RTPI_IMAGE_MAX_PIXELS (1UL << 27)

typedef char rtpi_float_is_32_bits[sizeof(float) == 4 ? 1 : -1];

int rtpi_image_size_ok(int width, int height)
{
    if (width <= 0 || height <= 0 || width > RTPI_IMAGE_MAX_DIM ||
        height > RTPI_IMAGE_MAX_DIM)
        return 0;
    /* (in 64 bits: with a 32-bit unsigned long, ILP32 and Windows' LLP64,
       2^20 x 2^12 wrapped to 0 and passed) */
    if ((unsigned long long)width * (unsigned long long)height > RTPI_IMAGE_MAX_PIXELS)
        return 0;
    /* Holds by the limits above; kept for 16-bit size_t paranoia. */
    return (size_t)width * (size_t)height <= (size_t)-1 / (3 * sizeof(float));
}

static size_t row_floats(const rtp_image *img) { return (size_t)img->width * 3; }

/* An image struct without pixels, for readers that grow them. */
static rtp_status image_shell(int width, int height, const rtp_allocator *alloc,
                              rtp_image **out)
{
    rtp_allocator a;
    rtp_image *img;
    rtpi_allocator_init(&a, alloc);
    img = (rtp_image *)rtpi_malloc(&a, sizeof *img);
    if (!img)
        return RTP_ERR_NOMEM;
    img->width = width;
    img->height = height;
    img->pixels = NULL;
    img->alloc = a;
    *out = img;
    return RTP_OK;
}

rtp_status rtp_image_create(int width, int height, const rtp_allocator *alloc,
                            rtp_image **out, rtp_error *err)
{
    rtp_image *img;
    if (!out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_image_create: out is NULL");
    *out = NULL;
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_image_create");
    if (width <= 0 || height <= 0)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "image size %dx%d: both sides must be positive",
                          width, height);
    if (!rtpi_image_size_ok(width, height))
        return rtpi_error(err, RTP_ERR_LIMIT, NULL, 0, 0,
                          "image size %dx%d exceeds the limit (%ld a side, "
                          "%lu pixels)", width, height, RTPI_IMAGE_MAX_DIM,
                          RTPI_IMAGE_MAX_PIXELS);
    if (image_shell(width, height, alloc, &img) != RTP_OK)
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                          "out of memory for a %dx%d image", width, height);
    img->pixels = (float *)rtpi_calloc_array(
        &img->alloc, (size_t)width * (size_t)height * 3, sizeof(float));
    if (!img->pixels) {
        rtpi_free(&img->alloc, img);
        return rtpi_error(err, RTP_ERR_NOMEM, NULL, 0, 0,
                          "out of memory for a %dx%d image", width, height);
    }
    *out = img;
    return RTP_OK;
}

void rtp_image_destroy(rtp_image *image)
{
    rtp_allocator a;
    if (!image)
        return;
    a = image->alloc;
    rtpi_free(&a, image->pixels);
    rtpi_free(&a, image);
}

/* Makes img->pixels hold at least `rows` rows, doubling (up to the
   image's height) so reading costs O(n) copies.  @return 0 or -1. */
static int reserve_rows(rtp_image *img, int *cap_rows, int rows)
{
    size_t ncap;
    float *np;
    if (rows <= *cap_rows)
        return 0;
    if (*cap_rows == 0) {
        /* Start near 1 MiB: small images are read in one allocation. */
        ncap = ((size_t)1 << 20) / (row_floats(img) * sizeof(float));
        if (ncap < 1)
            ncap = 1;
    } else {
        ncap = (size_t)*cap_rows * 2;
    }
    if (ncap < (size_t)rows)
        ncap = (size_t)rows;
    if (ncap > (size_t)img->height)
        ncap = (size_t)img->height;
    np = (float *)rtpi_realloc(&img->alloc, img->pixels,
                               ncap * row_floats(img) * sizeof(float));
    if (!np)
        return -1;
    img->pixels = np;
    *cap_rows = (int)ncap;
    return 0;
}

static char ascii_lower(char c)
{
    return (c >= 'A' && c <= 'Z') ? (char)(c - 'A' + 'a') : c;
}

static int ext_is(const char *ext, const char *want)
{
    while (*ext && *want && ascii_lower(*ext) == *want) {
        ext++;
        want++;
    }
    return *ext == '\0' && *want == '\0';
}

rtp_image_format rtp_image_format_from_path(const char *path)
{
    const char *base, *dot = NULL, *p;
    if (!path)
        return RTP_IMAGE_AUTO;
    base = path;
    for (p = path; *p; p++)
        if (*p == '/' || *p == '\\')
            base = p + 1;
    for (p = base; *p; p++)
        if (*p == '.')
            dot = p;
    if (!dot || dot == base) /* no extension, or a dot file like ".png" */
        return RTP_IMAGE_AUTO;
    if (ext_is(dot + 1, "png"))
        return RTP_IMAGE_PNG;
    if (ext_is(dot + 1, "ppm"))
        return RTP_IMAGE_PPM;
    if (ext_is(dot + 1, "pfm"))
        return RTP_IMAGE_PFM;
    return RTP_IMAGE_AUTO;
}

int rtp_png_supported(void)
{
#ifdef RTPI_PNG
    return 1;
#else
    return 0;
#endif
}

#ifndef RTPI_PNG
static rtp_status no_png(rtp_error *err, const char *name)
{
    return rtpi_error(err, RTP_ERR_UNSUPPORTED, name, 0, 0,
                      "PNG is not supported by this build of rtp (libpng "
                      "was not found when it was built); use .ppm or .pfm");
}
#endif

#ifdef RTPI_PNG
/* libpng's own default limit is 1,000,000 pixels a side (PNG allows
   2^31 - 1): images 1,000,001 to 2^20 wide, which rtp makes and reads as
   PFM, failed as PNG ("Invalid IHDR data").  Sizes are rtp's to limit
   (rtpi_image_size_ok, with its own message). */
static void png_sizes(png_structp png)
{
#ifdef PNG_SET_USER_LIMITS_SUPPORTED
    png_set_user_limits(png, 0x7fffffffu, 0x7fffffffu);
#else
    (void)png;
#endif
}
#endif

/* 8-bit quantisation shared by PNG and PPM: clamp to [0,1], round half up;
   NaN and infinities become 0 so that a bad pixel stands out as black. */
static unsigned char quantize8(float x)
{
    if (isnan(x) || isinf(x) || !(x > 0.0f))
        return 0;
    if (x >= 1.0f)
        return 255;
    return (unsigned char)((double)x * 255.0 + 0.5);
}

/* ===================================================================
 * Writing
 * =================================================================== */

static rtp_status write_failed(rtp_error *err, const char *name, int e)
{
    return rtpi_error(err, RTP_ERR_IO, name, 0, 0, "write failed: %s",
                      e ? strerror(e) : "stream error");
}

/* PFM and PPM pixels are written and read in chunks of about this many
   bytes of floats, a chunk's rows converted in one buffer: a row at a
   time, through stdio's default 4 KiB buffer, a 1024x1024 PFM took
   ~2,050 write calls (15-18 ms) and its read as many read calls.  1 MiB
   makes that ~28, two a chunk (6 ms); beyond it the calls no longer
   show, while the buffer stays small beside the image it holds a part
   of (a 1024x1024 PFM is 12 MiB).  (PNG is left to libpng's 8 KiB
   pieces: a 3 MB PNG of noise is ~770 writes, ~1 ms of its 120 ms of
   compression.) */
#define RTPI_IO_CHUNK ((size_t)1 << 20)

/* Rows of `row_bytes` each in one chunk: at least 1, at most `rows`. */
static size_t chunk_rows(size_t row_bytes, int rows)
{
    size_t k = RTPI_IO_CHUNK / row_bytes;
    if (k < 1)
        k = 1;
    if (k > (size_t)rows)
        k = (size_t)rows;
    return k;
}

/* The stream is the caller's (or stdout) as often as the library's own,
   so its buffering is left alone: big fwrite calls go past a small
   buffer in a call or two each (glibc, musl and the BSDs write a request
   larger than the buffer directly), with no setvbuf on a stream that may
   have been used already. */

/* Little-endian 32-bit floats, PFM's byte order as rtp writes it. */
static void pfm_row_bytes(const float *row, size_t n, unsigned char *out)
{
    size_t i;
    for (i = 0; i < n; i++) {
        uint32_t u;
        memcpy(&u, &row[i], 4);
        out[4 * i + 0] = (unsigned char)(u & 0xff);
        out[4 * i + 1] = (unsigned char)((u >> 8) & 0xff);
        out[4 * i + 2] = (unsigned char)((u >> 16) & 0xff);
        out[4 * i + 3] = (unsigned char)(u >> 24);
    }
}

static void ppm_row_bytes(const float *row, size_t n, unsigned char *out)
{
    size_t i;
    for (i = 0; i < n; i++)
        out[i] = quantize8(row[i]);
}

/* The header (its third line `line3`: PFM's scale, PPM's maximum),
   then every row converted by `convert` (n floats to n * bytes_per
   bytes), `pfm`'s bottom row first as PFM stores them. */
static rtp_status write_rows(const rtp_image *img, FILE *f,
                             const rtp_allocator *a, const char *name,
                             rtp_error *err, const char *line3,
                             size_t bytes_per, int pfm,
                             void (*convert)(const float *, size_t,
                                             unsigned char *))
{
    size_t n = row_floats(img), row_bytes = n * bytes_per, k, j;
    unsigned char *buf;
    int y = 0;
    k = chunk_rows(row_bytes, img->height);
    buf = (unsigned char *)rtpi_malloc_array(a, k, row_bytes);
    if (!buf)
        return rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0,
                          "out of memory writing %s", pfm ? "PFM" : "PPM");
    errno = 0;
    if (fprintf(f, "%s\n%d %d\n%s\n", pfm ? "PF" : "P6", img->width,
                img->height, line3) < 0) {
        rtpi_free(a, buf);
        return write_failed(err, name, errno);
    }
    while (y < img->height) {
        size_t rows = (size_t)(img->height - y) < k
                          ? (size_t)(img->height - y)
                          : k;
        for (j = 0; j < rows; j++) {
            int src = pfm ? img->height - 1 - (y + (int)j) : y + (int)j;
            convert(img->pixels + (size_t)src * n, n, buf + j * row_bytes);
        }
        errno = 0;
        if (fwrite(buf, row_bytes, rows, f) != rows) {
            int e = errno;
            rtpi_free(a, buf);
            return write_failed(err, name, e);
        }
        y += (int)rows;
    }
    rtpi_free(a, buf);
    return RTP_OK;
}

static rtp_status write_pfm(const rtp_image *img, FILE *f,
                            const rtp_allocator *a, const char *name,
                            rtp_error *err)
{
    return write_rows(img, f, a, name, err, "-1.0", 4, 1, pfm_row_bytes);
}

static rtp_status write_ppm(const rtp_image *img, FILE *f,
                            const rtp_allocator *a, const char *name,
                            rtp_error *err)
{
    return write_rows(img, f, a, name, err, "255", 1, 0, ppm_row_bytes);
}

#ifdef RTPI_PNG
/* What libpng's callbacks share with us.  libpng reports errors by
   longjmp; every resource lives in these structs (in the caller's frame,
   not the frame that calls setjmp), so nothing a longjmp skips over is
   lost or left indeterminate. */
typedef struct png_io {
    rtp_allocator alloc;
    FILE *f;
    char msg[160];
    int nomem;    /* an allocation failed */
    int io_errno; /* the stream failed (errno, or -1 if none) */
    int eof;      /* the stream ended early */
} png_io;

static void png_io_init(png_io *io, const rtp_allocator *a, FILE *f)
{
    memset(io, 0, sizeof *io);
    io->alloc = *a;
    io->f = f;
}

static void png_err_fn(png_structp png, png_const_charp msg)
{
    png_io *io = (png_io *)png_get_error_ptr(png);
    if (io) {
        strncpy(io->msg, msg ? msg : "libpng error", sizeof io->msg - 1);
        io->msg[sizeof io->msg - 1] = '\0';
    }
    png_longjmp(png, 1);
}

static void png_warn_fn(png_structp png, png_const_charp msg)
{
    (void)png; /* the library never prints */
    (void)msg;
}

static png_voidp png_malloc_fn(png_structp png, png_alloc_size_t size)
{
    png_io *io = (png_io *)png_get_mem_ptr(png);
    void *p = rtpi_malloc(&io->alloc, size);
    if (!p)
        io->nomem = 1;
    return p;
}

static void png_free_fn(png_structp png, png_voidp p)
{
    png_io *io = (png_io *)png_get_mem_ptr(png);
    rtpi_free(&io->alloc, p);
}

static void png_read_fn(png_structp png, png_bytep data, png_size_t len)
{
    png_io *io = (png_io *)png_get_io_ptr(png);
    if (fread(data, 1, len, io->f) != len) {
        if (ferror(io->f)) {
            io->io_errno = errno ? errno : -1;
            png_error(png, "read error");
        }
        io->eof = 1;
        png_error(png, "file ends early");
    }
}

static void png_write_fn(png_structp png, png_bytep data, png_size_t len)
{
    png_io *io = (png_io *)png_get_io_ptr(png);
    errno = 0;
    if (fwrite(data, 1, len, io->f) != len) {
        io->io_errno = errno ? errno : -1;
        png_error(png, "write error");
    }
}

static void png_flush_fn(png_structp png)
{
    png_io *io = (png_io *)png_get_io_ptr(png);
    errno = 0;
    if (fflush(io->f) != 0) {
        io->io_errno = errno ? errno : -1;
        png_error(png, "write error");
    }
}

typedef struct png_wctx {
    png_io io;
    png_structp png;
    png_infop info;
    const rtp_image *img;
    unsigned char *row;
} png_wctx;

/* The only function that calls setjmp for writing.  Its locals are set
   after setjmp and not used once it returns through longjmp. */
static int png_write_body(png_wctx *c)
{
    int y;
    size_t i, n;
    if (setjmp(png_jmpbuf(c->png)))
        return -1;
    png_set_write_fn(c->png, &c->io, png_write_fn, png_flush_fn);
    png_set_IHDR(c->png, c->info, (png_uint_32)c->img->width,
                 (png_uint_32)c->img->height, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    /* zlib level 3 with the Sub and Up filters only: a rendered 512x512
       image writes in ~10 ms instead of libpng's default 24-39 ms (level
       6, all five filters tried per row) for files 2-10% larger (the SPD
       scenes balls, teapot, gears, mount); a --stream of PNG frames is
       bound by this, not by the edits. */
    png_set_compression_level(c->png, 3);
    png_set_filter(c->png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB | PNG_FILTER_UP);
    png_write_info(c->png, c->info);
    n = row_floats(c->img);
    for (y = 0; y < c->img->height; y++) {
        const float *src = c->img->pixels + (size_t)y * n;
        for (i = 0; i < n; i++)
            c->row[i] = quantize8(src[i]);
        png_write_row(c->png, c->row);
    }
    png_write_end(c->png, c->info);
    return 0;
}

static rtp_status write_png(const rtp_image *img, FILE *f,
                            const rtp_allocator *a, const char *name,
                            rtp_error *err)
{
    png_wctx c;
    rtp_status st = RTP_OK;
    memset(&c, 0, sizeof c);
    png_io_init(&c.io, a, f);
    c.img = img;
    c.row = (unsigned char *)rtpi_malloc(a, row_floats(img));
#ifdef PNG_USER_MEM_SUPPORTED
    c.png = png_create_write_struct_2(PNG_LIBPNG_VER_STRING, &c.io,
                                      png_err_fn, png_warn_fn, &c.io,
                                      png_malloc_fn, png_free_fn);
#else
    c.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &c.io,
                                    png_err_fn, png_warn_fn);
#endif
    if (c.png) {
        png_sizes(c.png);
        c.info = png_create_info_struct(c.png);
    }
    if (!c.row || !c.png || !c.info) {
        st = rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0,
                        "out of memory writing PNG");
    } else if (png_write_body(&c) != 0) {
        if (c.io.nomem)
            st = rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0,
                            "out of memory writing PNG");
        else if (c.io.io_errno)
            st = write_failed(err, name,
                              c.io.io_errno > 0 ? c.io.io_errno : 0);
        else
            st = rtpi_error(err, RTP_ERR_IO, name, 0, 0,
                            "libpng cannot write the image: %s", c.io.msg);
    }
    if (c.png)
        png_destroy_write_struct(&c.png, c.info ? &c.info : NULL);
    rtpi_free(a, c.row);
    return st;
}
#endif /* RTPI_PNG */

/* Writes to f; `name` (may be NULL) is for messages. */
static rtp_status write_to(const rtp_image *img, FILE *f,
                           rtp_image_format format, const char *name,
                           rtp_error *err)
{
    rtp_allocator a;
    rtp_status st;
    rtpi_allocator_init(&a, &img->alloc);
    switch (format) {
    case RTP_IMAGE_PFM:
        st = write_pfm(img, f, &a, name, err);
        break;
    case RTP_IMAGE_PPM:
        st = write_ppm(img, f, &a, name, err);
        break;
    case RTP_IMAGE_PNG:
#ifdef RTPI_PNG
        st = write_png(img, f, &a, name, err);
        break;
#else
        return no_png(err, name);
#endif
    case RTP_IMAGE_AUTO:
    default:
        return rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                          "unknown image format %d", (int)format);
    }
    if (st != RTP_OK)
        return st;
    errno = 0;
    if (fflush(f) != 0 || ferror(f))
        return write_failed(err, name, errno);
    return RTP_OK;
}

static rtp_status check_image(const rtp_image *img, const char *name,
                              rtp_error *err)
{
    if (!img || !img->pixels)
        return rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                          "no image to write");
    if (!rtpi_image_size_ok(img->width, img->height))
        return rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                          "invalid image size %dx%d", img->width,
                          img->height);
    return RTP_OK;
}

rtp_status rtp_image_write_stream(const rtp_image *image, FILE *stream,
                                  rtp_image_format format, rtp_error *err)
{
    rtp_status st = check_image(image, NULL, err);
    if (st != RTP_OK)
        return st;
    if (!stream)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "no stream to write to");
    if (format == RTP_IMAGE_AUTO)
        format = RTP_IMAGE_PFM;
    return write_to(image, stream, format, NULL, err);
}

/* Opens a new, not yet existing file `tmp` beside `path` (tmp has room
   for strlen(path) + 32).  Permissions are those of the file it will
   replace, else the usual 0666 minus umask.
   @return the stream, or NULL with errno set. */
FILE *rtpi_open_temp(const char *path, char *tmp, size_t tmpsize)
{
#ifdef RTPI_POSIX_FILES
    struct stat sb;
    int keep = stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
#endif
    unsigned long seed = (unsigned long)time(NULL) ^
                         ((unsigned long)clock() << 12) ^
                         (unsigned long)(uintptr_t)(void *)tmp;
    int attempt;
#ifdef RTPI_POSIX_FILES
    seed ^= (unsigned long)getpid() << 16;
#endif
    for (attempt = 0; attempt < 64; attempt++) {
        FILE *f;
        /* A 32-bit LCG step: names differ between attempts and between
           processes; O_EXCL settles any collision. */
        seed = (seed * 1103515245UL + 12345UL) & 0xffffffffUL;
        /* in the file's folder (a rename stays within one file system),
           named apart from the file: a name of its own length plus 13
           passed the 255 bytes a name may have for names of 243 up */
        {
            const char *slash = strrchr(path, '/');
            int dir = slash ? (int)(slash - path) + 1 : 0;
            snprintf(tmp, tmpsize, "%.*s.rtp-%08lx.tmp", dir, path, seed);
        }
#ifdef RTPI_POSIX_FILES
        {
            int fd = open(tmp, O_WRONLY | O_CREAT | O_EXCL, 0666);
            if (fd < 0) {
                if (errno == EEXIST)
                    continue;
                return NULL;
            }
            if (keep) {
                /* best effort: the mode, and the owner where rtp may set
                   it (root replacing a user's file left it root's) */
                (void)fchmod(fd, sb.st_mode & 07777);
                if (geteuid() == 0)
                    (void)fchown(fd, sb.st_uid, sb.st_gid);
            }
            f = fdopen(fd, "wb");
            if (!f) {
                int e = errno;
                close(fd);
                remove(tmp);
                errno = e;
            }
            return f;
        }
#else
        f = fopen(tmp, "rb");
        if (f) {
            fclose(f);
            continue;
        }
        return fopen(tmp, "wb");
#endif
    }
    errno = EEXIST;
    return NULL;
}

int rtpi_sync_file(FILE *f)
{
    if (fflush(f) != 0)
        return errno ? errno : EIO;
#ifdef RTPI_POSIX_FILES
    if (fsync(fileno(f)) != 0 && errno != EINVAL)
        return errno;
#endif
    return 0;
}

int rtpi_sync_dir(const char *path)
{
#ifdef RTPI_POSIX_FILES
    const char *slash = strrchr(path, '/');
    char dir[4096];
    int fd, e = 0;
    if (!slash)
        snprintf(dir, sizeof dir, ".");
    else if ((size_t)(slash - path) + 2 > sizeof dir)
        return 0; /* (a path longer than a buffer: left unsynced) */
    else
        snprintf(dir, sizeof dir, "%.*s", slash == path ? 1 : (int)(slash - path), path);
    fd = open(dir, O_RDONLY);
    if (fd < 0)
        return 0; /* (a folder rtp may write but not read: nothing to sync through) */
    if (fsync(fd) != 0 && errno != EINVAL)
        e = errno;
    close(fd);
    return e;
#else
    (void)path;
    return 0;
#endif
}

#ifdef RTPI_POSIX_FILES
/* One step along a chain of symbolic links: cur (a buffer of size bytes)
   becomes the target of the link it names, a relative target taken from
   the link's folder.  1 when it was a link, 0 when not, -1 with errno. */
static int link_step(char *cur, size_t size)
{
    char link[4096];
    struct stat sb;
    ssize_t n;
    const char *slash;
    size_t dir;
    if (lstat(cur, &sb) != 0 || !S_ISLNK(sb.st_mode))
        return 0;
    n = readlink(cur, link, sizeof link - 1);
    if (n < 0)
        return -1;
    link[n] = '\0';
    slash = strrchr(cur, '/');
    dir = link[0] != '/' && slash ? (size_t)(slash - cur) + 1 : 0;
    if (dir + (size_t)n >= size) {
        errno = ENAMETOOLONG;
        return -1;
    }
    memmove(cur + dir, link, (size_t)n + 1);
    return 1;
}
#endif

rtp_status rtpi_write_target(const rtp_allocator *a, const char *path, char **out,
                             rtp_error *err)
{
#ifdef RTPI_POSIX_FILES
    char cur[4096];
    struct stat sb;
    int hops, r;
    *out = NULL;
    if (strlen(path) >= sizeof cur)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot write: %s", strerror(ENAMETOOLONG));
    strcpy(cur, path);
    for (hops = 0; (r = link_step(cur, sizeof cur)) > 0; hops++)
        if (hops == 40)
            return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot write: %s", strerror(ELOOP));
    if (r < 0)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot read the link: %s",
                          strerror(errno));
    if (stat(cur, &sb) == 0 && S_ISREG(sb.st_mode) && access(cur, W_OK) != 0)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot write: %s", strerror(errno));
    *out = rtpi_strdup(a, cur);
#else
    *out = rtpi_strdup(a, path);
#endif
    if (!*out)
        return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory");
    return RTP_OK;
}

#ifdef RTPI_POSIX_FILES
/* Whether path, or a link on its way, is an open file's own name in
   /proc/PID/fd or /dev/fd (the file a descriptor writes, as a shell's
   2>>log makes it): written through it, never replaced. */
static int fd_link(const char *path)
{
    char cur[4096];
    int hops;
    if (strlen(path) >= sizeof cur)
        return 0;
    strcpy(cur, path);
    for (hops = 0; hops < 40; hops++) {
        if (strncmp(cur, "/dev/fd/", 8) == 0 ||
            (strncmp(cur, "/proc/", 6) == 0 && strstr(cur, "/fd/")))
            return 1;
        if (link_step(cur, sizeof cur) <= 0)
            return 0;
    }
    return 0;
}
#endif

int rtpi_write_kind(const char *path)
{
#ifdef RTPI_POSIX_FILES
    struct stat sb, so;
    if (stat(path, &sb) != 0)
        return RTPI_WRITE_FILE;
    /* (stdout's own file whatever its kind: a pipe or terminal behind
       /dev/stdout written in place came before what the caller had
       printed to stdout and not yet flushed) */
    if (fstat(fileno(stdout), &so) == 0 && so.st_dev == sb.st_dev && so.st_ino == sb.st_ino)
        return RTPI_WRITE_STDOUT;
    if (!S_ISREG(sb.st_mode))
        return RTPI_WRITE_IN_PLACE;
    if (fd_link(path))
        return RTPI_WRITE_APPEND;
#else
    (void)path;
#endif
    return RTPI_WRITE_FILE;
}

rtp_status rtp_image_write(const rtp_image *image, const char *path,
                           rtp_image_format format, rtp_error *err)
{
    rtp_allocator a;
    rtp_status st;
    char *tmp, *target;
    int kind;
    size_t tmpsize;
    FILE *f;
    int e;
    if (!path || !*path)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "no file name to write the image to");
    st = check_image(image, path, err);
    if (st != RTP_OK)
        return st;
    if (strcmp(path, "-") == 0) {
        if (format == RTP_IMAGE_AUTO)
            format = RTP_IMAGE_PFM;
        return write_to(image, stdout, format, "<stdout>", err);
    }
    kind = rtpi_write_kind(path);
    if (format == RTP_IMAGE_AUTO) {
        format = rtp_image_format_from_path(path);
        /* a pipe or a device (/dev/null, a user timing a trace), no
           extension in its name: PFM, as stdout's "-" has it */
        if (format == RTP_IMAGE_AUTO && kind != RTPI_WRITE_FILE)
            format = RTP_IMAGE_PFM;
        if (format == RTP_IMAGE_AUTO)
            return rtpi_error(err, RTP_ERR_ARGUMENT, path, 0, 0,
                              "cannot tell the image format from the "
                              "name: use .png, .ppm or .pfm");
    }
    if (format != RTP_IMAGE_PNG && format != RTP_IMAGE_PPM &&
        format != RTP_IMAGE_PFM)
        return rtpi_error(err, RTP_ERR_ARGUMENT, path, 0, 0,
                          "unknown image format %d", (int)format);
#ifndef RTPI_PNG
    if (format == RTP_IMAGE_PNG)
        return no_png(err, path);
#endif
    rtpi_allocator_init(&a, &image->alloc);
    if (kind == RTPI_WRITE_STDOUT) {
        st = write_to(image, stdout, format, path, err);
        if (fflush(stdout) != 0 && st == RTP_OK)
            st = write_failed(err, path, errno);
        return st;
    }
    if (kind == RTPI_WRITE_IN_PLACE || kind == RTPI_WRITE_APPEND) {
        f = fopen(path, kind == RTPI_WRITE_APPEND ? "ab" : "wb");
        if (!f)
            return rtpi_error(err, RTP_ERR_IO, path, 0, 0,
                              "cannot open for writing: %s", strerror(errno));
        st = write_to(image, f, format, path, err);
        errno = 0;
        if (fclose(f) != 0 && st == RTP_OK)
            st = write_failed(err, path, errno);
        return st;
    }

    /* (through a symbolic link: the file it names) */
    if ((st = rtpi_write_target(&a, path, &target, err)) != RTP_OK)
        return st;
    tmpsize = strlen(target) + 32;
    tmp = (char *)rtpi_malloc(&a, tmpsize);
    if (!tmp) {
        rtpi_free(&a, target);
        return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory");
    }
    f = rtpi_open_temp(target, tmp, tmpsize);
    if (!f) {
        e = errno;
        rtpi_free(&a, tmp);
        rtpi_free(&a, target);
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0,
                          "cannot create a temporary file beside it: %s",
                          strerror(e));
    }
    st = write_to(image, f, format, path, err);
    /* No fsync before the rename (a tree file has one, rtpi_sync_file):
       an image is cheap to make again from its tree, and a --stream of
       100 64x48 frames took a median 1.26 s with fsync of each file and
       its folder against 0.06 s without, 20 runs each on this ext4
       (session 40, test/bench/HISTORY.md).  After a crash, a frame
       renamed just before may be empty. */
    errno = 0;
    if (fclose(f) != 0 && st == RTP_OK)
        st = write_failed(err, path, errno);
    if (st == RTP_OK && rename(tmp, target) != 0) {
        e = errno;
        st = rtpi_error(err, RTP_ERR_IO, path, 0, 0,
                        "cannot rename the temporary file %s over it: %s",
                        tmp, strerror(e));
    }
    if (st != RTP_OK)
        remove(tmp);
    rtpi_free(&a, tmp);
    rtpi_free(&a, target);
    return st;
}

/* ===================================================================
 * Reading
 * =================================================================== */

typedef struct reader {
    FILE *f;
    const char *name;
    rtp_error *err;
    /* a regular file's size in bytes (rtp_image_read), or -1 (a pipe,
       a device, or a stream rtp_image_read_stream reads) */
    long long size;
    /* whether the image is all the file holds (rtp_image_read: a path,
       '-' and pipes too, is one image, bytes after it refused as a file's
       are), else a stream's, which may hold the next image after it
       (rtp_image_read_stream) */
    int whole;
    int *term; /* the whitespace character that ended the last number */
} reader;

/* A format error in the file being read. */
#define BAD(r, ...) rtpi_error((r)->err, RTP_ERR_FORMAT, (r)->name, 0, 0, \
                               __VA_ARGS__)

/* The stream stopped: an I/O error if it failed, else a truncated file. */
static rtp_status ended(const reader *r, const char *what)
{
    if (ferror(r->f))
        return rtpi_error(r->err, RTP_ERR_IO, r->name, 0, 0,
                          "read error in the %s: %s", what,
                          errno ? strerror(errno) : "stream error");
    return BAD(r, "truncated: the file ends in the %s", what);
}

static int is_space(int c)
{
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' ||
           c == '\f';
}

static int is_digit(int c) { return c >= '0' && c <= '9'; }

/* Skips whitespace (and, if `comments`, '#' to end of line); @return the
   first other character or EOF. */
static int skip_space(FILE *f, int comments)
{
    int c;
    for (;;) {
        c = getc(f);
        if (comments && c == '#') {
            do
                c = getc(f);
            while (c != EOF && c != '\n' && c != '\r');
            continue;
        }
        if (!is_space(c))
            return c;
    }
}

#define NUM_COMMENTS 1 /* '#' comments may come before the number */
#define NUM_EOF_OK 2   /* the number may end the file (P3's last sample) */

/* Reads a decimal number after optional whitespace.  It must end in one
   whitespace character, which is consumed: netpbm and PFM headers end in
   exactly one before the binary data.  Values above `max` give `over`
   (RTP_ERR_LIMIT for sizes, RTP_ERR_FORMAT otherwise). */
static rtp_status read_number(const reader *r, int flags, const char *what,
                              long max, rtp_status over, long *out)
{
    int c = skip_space(r->f, flags & NUM_COMMENTS);
    long v = 0;
    int big = 0;
    if (c == EOF)
        return ended(r, what);
    if (!is_digit(c))
        return BAD(r, "expected a number for the %s", what);
    while (is_digit(c)) {
        /* (a digit above max first: max - digit is negative, and its
           division by 10 rounds to 0, which let P3's 5 under a maxval of
           1 through) */
        if (c - '0' > max || v > (max - (c - '0')) / 10)
            big = 1;
        else
            v = v * 10 + (c - '0');
        c = getc(r->f);
    }
    if (big)
        return rtpi_error(r->err, over, r->name, 0, 0,
                          "the %s is too large (at most %ld)", what, max);
    if (c == '#' && (flags & NUM_COMMENTS)) {
        /* a comment right after a header number ("1 1#size"): netpbm
           ends it at the line's end, which then ends the number */
        while (c != EOF && c != '\n' && c != '\r')
            c = getc(r->f);
    }
    if (c == EOF && !((flags & NUM_EOF_OK) && !ferror(r->f)))
        return ended(r, what);
    if (c != EOF && !is_space(c))
        return BAD(r, "unexpected character after the %s", what);
    *r->term = c;
    *out = v;
    return RTP_OK;
}

static rtp_status read_size(const reader *r, int flags, const char *fmt,
                            int *w, int *h)
{
    long lw, lh;
    rtp_status st;
    st = read_number(r, flags, "width", RTPI_IMAGE_MAX_DIM, RTP_ERR_LIMIT,
                     &lw);
    if (st == RTP_OK)
        st = read_number(r, flags, "height", RTPI_IMAGE_MAX_DIM,
                         RTP_ERR_LIMIT, &lh);
    if (st != RTP_OK)
        return st;
    if (lw == 0 || lh == 0)
        return rtpi_error(r->err, RTP_ERR_FORMAT, r->name, 0, 0,
                          "%s: the image is empty (%ldx%ld)", fmt, lw, lh);
    if (!rtpi_image_size_ok((int)lw, (int)lh))
        return rtpi_error(r->err, RTP_ERR_LIMIT, r->name, 0, 0,
                          "%s: image size %ldx%ld exceeds the limit of %lu "
                          "pixels", fmt, lw, lh, RTPI_IMAGE_MAX_PIXELS);
    *w = (int)lw;
    *h = (int)lh;
    return RTP_OK;
}

static rtp_status out_of_memory(const reader *r)
{
    return rtpi_error(r->err, RTP_ERR_NOMEM, r->name, 0, 0,
                      "out of memory reading the image");
}

/* A pipe's bytes after an image are counted up to this many: an endless
   source behind a valid image (`cat a.pfm /dev/urandom`, `yes`) is then
   refused at once instead of read for ever.  (16 MiB: a whole further
   frame of a 2048x2048 RGB PFM is 48 MiB, so past it the count says
   "over 16777216" rather than a length.) */
#define REST_MAX ((long long)1 << 24)

/* Reads a stream to its end, or REST_MAX + 1 bytes of it: @return the
   bytes read (ferror tells a failed read). */
static long long rest_bytes(FILE *f)
{
    unsigned char buf[4096];
    long long n = 0;
    size_t got;
    while (n <= REST_MAX && (got = fread(buf, 1, sizeof buf, f)) > 0)
        n += (long long)got;
    return n;
}

/* What follows a PPM file's last sample: nothing for P6 (or one line
   feed; data is the pixel data's bytes), blanks and comments for P3.  More (samples, pixels, another image) means the
   header does not describe the data -- a width or height too small read
   every row shifted, silently -- and is refused as bytes after a PFM's
   pixels are, from a pipe too (read to its end).  (A stream read by
   rtp_image_read_stream may carry the next image after it: not checked
   there.) */
static rtp_status ppm_after(const reader *r, int ascii, int w, int h, int first,
                           size_t data)
{
    long pos;
    int c;
    if (!r->whole)
        return RTP_OK;
    if (ascii) {
        c = skip_space(r->f, 1);
        if (c == EOF)
            return ferror(r->f) ? ended(r, "pixel data") : RTP_OK;
        return BAD(r, "PPM: more after the last of the %dx%d pixels' samples: the "
                      "header (P3 %dx%d) does not describe the data", w, h, w, h);
    }
    if (r->size < 0) {
        /* a pipe: its length is known once it is read to its end */
        long long more;
        c = getc(r->f);
        if (c == EOF)
            return ferror(r->f) ? ended(r, "pixel data") : RTP_OK;
        more = 1 + rest_bytes(r->f);
        if (ferror(r->f))
            return ended(r, "bytes after the pixel data");
        if (more == 1 && *r->term == '\r' && first == '\n')
            return BAD(r, "PPM: 1 byte after the pixel data: its maximum value's "
                          "line ends in CR LF? Netpbm's header ends in one "
                          "whitespace character");
        if (more == 1 && c == '\n')
            return RTP_OK;
        return BAD(r, "PPM: %s%lld byte%s after the pixel data: the header (P6 %dx%d) does "
                      "not describe the data (rtp reads one image a file)",
                   more > REST_MAX ? "over " : "", more > REST_MAX ? REST_MAX : more,
                   more == 1 ? "" : "s", w, h);
    }
    pos = ftell(r->f);
    if (pos >= 0 && r->size == pos + 1) {
        /* One byte over: a line feed some writers end the file with (the
           netpbm tools read past it), unless the header's last
           whitespace was a CR -- a header of CR LF lines, whose line
           feed was read as the first sample, every byte one off. */
        int term = EOF, last = EOF;
        if (pos >= (long)data + 1 && fseek(r->f, pos - (long)data - 1, SEEK_SET) == 0)
            term = getc(r->f);
        if (fseek(r->f, pos, SEEK_SET) == 0)
            last = getc(r->f);
        if (term == '\r' && first == '\n')
            return BAD(r, "PPM: 1 byte after the pixel data: its maximum value's "
                          "line ends in CR LF? Netpbm's header ends in one "
                          "whitespace character");
        if (last == '\n' && term != EOF)
            return RTP_OK;
    }
    if (pos >= 0 && r->size > pos)
        return BAD(r, "PPM: %lld byte%s after the pixel data: the header (P6 %dx%d) does "
                      "not describe the data (rtp reads one image a file)",
                   r->size - pos, r->size - pos == 1 ? "" : "s", w, h);
    return RTP_OK;
}

/* Netpbm P6 (binary) or P3 (ASCII) after the two magic bytes. */
static rtp_status read_ppm(const reader *r, int ascii,
                           const rtp_allocator *alloc, rtp_image **out)
{
    rtp_image *img = NULL;
    unsigned char *buf = NULL;
    long maxval;
    int w, h, y, cap = 0, first = -1;
    size_t n, i, bps, k, rows;
    float scale, lut[256];
    rtp_status st;
    char what[64];

    st = read_size(r, NUM_COMMENTS, "PPM", &w, &h);
    if (st == RTP_OK)
        st = read_number(r, NUM_COMMENTS, "maximum value", 65535, RTP_ERR_FORMAT,
                         &maxval);
    if (st != RTP_OK)
        return st;
    if (maxval == 0)
        return BAD(r, "PPM: the maximum value is 0");
    if (image_shell(w, h, alloc, &img) != RTP_OK)
        return out_of_memory(r);
    n = row_floats(img);
    bps = maxval < 256 ? 1 : 2;
    scale = (float)maxval;
    /* The same values as v / scale, without a division per sample. */
    for (i = 0; i < 256; i++)
        lut[i] = (float)i / scale;
    if (ascii) {
        for (y = 0; y < h; y++) {
            float *row;
            if (reserve_rows(img, &cap, y + 1) != 0) {
                st = out_of_memory(r);
                goto done;
            }
            row = img->pixels + (size_t)y * n;
            snprintf(what, sizeof what, "pixel data (row %d of %d)", y + 1,
                     h);
            for (i = 0; i < n; i++) {
                long v;
                /* Comments are not netpbm's here, but harmless; the last
                   sample may end the file without a newline. */
                st = read_number(r,
                                 NUM_COMMENTS | (y == h - 1 && i == n - 1
                                                     ? NUM_EOF_OK
                                                     : 0),
                                 what, maxval, RTP_ERR_FORMAT, &v);
                if (st != RTP_OK)
                    goto done;
                row[i] = (float)v / scale;
            }
        }
        st = ppm_after(r, 1, w, h, 0, 0);
        goto done;
    }
    /* P6: a chunk of rows a read, counted in floats (RTPI_IO_CHUNK) so
       that memory runs a chunk ahead of the data at most. */
    k = chunk_rows(n * sizeof(float), h);
    buf = (unsigned char *)rtpi_malloc_array(&img->alloc, k, n * bps);
    if (!buf) {
        st = out_of_memory(r);
        goto done;
    }
    for (y = 0; y < h; y += (int)rows) {
        size_t got, j;
        rows = (size_t)(h - y) < k ? (size_t)(h - y) : k;
        if (reserve_rows(img, &cap, y + (int)rows) != 0) {
            st = out_of_memory(r);
            goto done;
        }
        got = fread(buf, n * bps, rows, r->f);
        if (y == 0 && got > 0)
            first = buf[0];
        if (got != rows) {
            snprintf(what, sizeof what, "pixel data (row %d of %d)",
                     y + (int)got + 1, h);
            st = ended(r, what);
            goto done;
        }
        for (j = 0; j < rows; j++) {
            const unsigned char *src = buf + j * n * bps;
            float *row = img->pixels + ((size_t)y + j) * n;
            if (maxval == 255) {
                for (i = 0; i < n; i++)
                    row[i] = lut[src[i]];
                continue;
            }
            for (i = 0; i < n; i++) {
                unsigned v = bps == 1 ? src[i]
                                      : ((unsigned)src[2 * i] << 8) |
                                            src[2 * i + 1];
                if ((long)v > maxval) {
                    st = rtpi_error(r->err, RTP_ERR_FORMAT, r->name, 0, 0,
                                    "PPM: sample %u exceeds the maximum "
                                    "value %ld (row %d)", v, maxval,
                                    y + (int)j + 1);
                    goto done;
                }
                row[i] = v < 256 ? lut[v] : (float)v / scale;
            }
        }
    }
    st = ppm_after(r, 0, w, h, first, (size_t)w * (size_t)h * 3 * bps);
done:
    rtpi_free(&img->alloc, buf);
    if (st != RTP_OK) {
        rtp_image_destroy(img);
        return st;
    }
    *out = img;
    return RTP_OK;
}

/* PFM's scale: a decimal number whose sign gives the byte order (negative:
   little-endian).  Parsed by hand because strtod follows the locale.
   @return 0 and *little, or -1 if it is not a nonzero number. */
static int parse_scale(const char *s, int *little)
{
    int neg = 0, digits = 0, nonzero = 0;
    if (*s == '+' || *s == '-')
        neg = *s++ == '-';
    for (; is_digit(*s); s++, digits++)
        nonzero |= *s != '0';
    if (*s == '.')
        for (s++; is_digit(*s); s++, digits++)
            nonzero |= *s != '0';
    if (!digits)
        return -1;
    if (*s == 'e' || *s == 'E') {
        s++;
        if (*s == '+' || *s == '-')
            s++;
        if (!is_digit(*s))
            return -1;
        while (is_digit(*s))
            s++;
    }
    if (*s || !nonzero)
        return -1;
    *little = neg;
    return 0;
}

static float pfm_sample(const unsigned char *b, int little)
{
    uint32_t u = little ? (uint32_t)b[0] | (uint32_t)b[1] << 8 |
                              (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24
                        : (uint32_t)b[3] | (uint32_t)b[2] << 8 |
                              (uint32_t)b[1] << 16 | (uint32_t)b[0] << 24;
    float v;
    memcpy(&v, &u, 4);
    return v;
}

/* `count` PFM samples, read as bytes into dst's memory (`bytes`), made
   floats in place: a colour sample's 4 bytes are its float's own; grey
   samples fill the first third and spread to RGB from the last one
   back, each written over bytes already read. */
static void pfm_decode(const unsigned char *bytes, float *dst, size_t count,
                       int little, int grey)
{
    size_t i;
    if (!grey) {
        for (i = 0; i < count; i++)
            dst[i] = pfm_sample(bytes + 4 * i, little);
        return;
    }
    for (i = count; i-- > 0;) {
        float v = pfm_sample(bytes + 4 * i, little);
        dst[3 * i] = dst[3 * i + 1] = dst[3 * i + 2] = v;
    }
}

/* How far PFM's header may run on after its scale: the blanks a writer
   leaves before the line's end ("-1.0 \n", "-1.0\r\n", an empty line),
   not padding of any length; past that the format's one whitespace
   character ends the header. */
#define RTPI_PFM_LINE_TAIL 64

/* Bytes read past PFM's header while looking for its end that prove to
   be pixels: they are the data's first. */
typedef struct pfm_ahead {
    unsigned char bytes[RTPI_PFM_LINE_TAIL];
    size_t n, at;
} pfm_ahead;

/* Finds the end of PFM's header after its scale `scale` and the
   whitespace character `c` that ended it.  The format asks for exactly
   one whitespace character there, but writers put blanks before the
   line's end, which read that way shift every pixel by a byte or two.
   A file's size places the data: what lies between the scale and the
   data is the header's when it is whitespace, and refused, naming it,
   when it is other text ending a line ("-1.0 x", a fourth number).  A
   stream has no size: blanks then a line end are taken as the header's
   (a header ended by one blank whose first pixel byte is 0x0a cannot be
   told from it, and is far rarer than the blank before the newline). */
static rtp_status pfm_header_end(const reader *r, int c, const char *scale,
                                 long long pixel_bytes, pfm_ahead *ah)
{
    size_t i, cap = RTPI_PFM_LINE_TAIL;
    ah->n = ah->at = 0;
    /* (bytes read ahead are never more than this image's pixels: they
       are all taken by its data, never the next image's in a stream) */
    if (pixel_bytes < (long long)cap)
        cap = (size_t)pixel_bytes;
    if (r->size >= 0) {
        long pos = ftell(r->f);
        long long gap = pos >= 0 ? r->size - pixel_bytes - pos : -1;
        int blank = 1, text = 1;
        if (gap <= 0 || gap > (long long)cap)
            return RTP_OK;
        ah->n = fread(ah->bytes, 1, (size_t)gap, r->f);
        for (i = 0; i < ah->n; i++) {
            unsigned char b = ah->bytes[i];
            blank &= is_space(b);
            text &= is_space(b) || (b >= 0x20 && b < 0x7f);
        }
        if (ah->n != (size_t)gap)
            return RTP_OK; /* the pixel data's read reports it */
        if (blank) {
            ah->n = 0;
            return RTP_OK;
        }
        if (text && ah->bytes[ah->n - 1] == '\n' && r->whole) {
            char extra[RTPI_PFM_LINE_TAIL + 1];
            size_t a = 0, b = ah->n, len = 0;
            while (a < b && is_space(ah->bytes[a]))
                a++;
            while (b > a && is_space(ah->bytes[b - 1]))
                b--;
            for (i = a; i < b; i++)
                extra[len++] = is_space(ah->bytes[i]) ? ' ' : (char)ah->bytes[i];
            extra[len] = '\0';
            return BAD(r, "PFM: the header has \"%s\" after its scale \"%s\" "
                          "(its lines: PF or Pf, the width and height, the "
                          "scale)", extra, scale);
        }
        return RTP_OK;
    }
    if (c != ' ' && c != '\t' && c != '\r')
        return RTP_OK;
    while (ah->n < cap) {
        int d = getc(r->f);
        if (d == EOF)
            break;
        ah->bytes[ah->n++] = (unsigned char)d;
        if (d == '\n') {
            ah->n = 0;
            break;
        }
        if (d != ' ' && d != '\t' && d != '\r')
            break;
    }
    return RTP_OK;
}

/* Reads `rows` rows of `row_bytes` into dst, the bytes read ahead of
   them first.  @return the rows read whole. */
static size_t read_rows(FILE *f, pfm_ahead *ah, unsigned char *dst,
                        size_t row_bytes, size_t rows)
{
    size_t want = row_bytes * rows, pre = ah->n - ah->at;
    if (pre > want)
        pre = want;
    memcpy(dst, ah->bytes + ah->at, pre);
    ah->at += pre;
    return (pre + fread(dst + pre, 1, want - pre, f)) / row_bytes;
}

/* PFM after "PF" (colour) or "Pf" (grey, expanded to RGB). */
static rtp_status read_pfm(const reader *r, int grey,
                           const rtp_allocator *alloc, rtp_image **out)
{
    rtp_image *img = NULL;
    char tok[48], what[64];
    int w, h, y, c, little, cap = 0;
    size_t len = 0, n, nin, i, k, rows;
    rtp_status st;
    pfm_ahead ahead;

    st = read_size(r, 0, "PFM", &w, &h);
    if (st != RTP_OK)
        return st;
    c = skip_space(r->f, 0);
    while (c != EOF && !is_space(c)) {
        if (len + 1 >= sizeof tok)
            return BAD(r, "PFM: the scale is too long");
        tok[len++] = (char)c;
        c = getc(r->f);
    }
    tok[len] = '\0';
    if (c == EOF)
        return ended(r, "header");
    if (parse_scale(tok, &little) != 0)
        return BAD(r, "PFM: the scale \"%s\" is not a nonzero number", tok);
    nin = grey ? (size_t)w : 3 * (size_t)w;
    st = pfm_header_end(r, c, tok, (long long)nin * 4 * (long long)h, &ahead);
    if (st != RTP_OK)
        return st;
    if (image_shell(w, h, alloc, &img) != RTP_OK)
        return out_of_memory(r);
    n = row_floats(img);
    k = chunk_rows(n * sizeof(float), h);
    /* Rows arrive bottom first; they are stored in file order and the
       image is flipped at the end, so memory grows with the data (a chunk
       ahead at most).  A chunk's bytes are read into the rows they become
       and converted in place (pfm_decode). */
    for (y = 0; y < h; y += (int)rows) {
        unsigned char *bytes;
        float *dst;
        size_t got;
        rows = (size_t)(h - y) < k ? (size_t)(h - y) : k;
        if (reserve_rows(img, &cap, y + (int)rows) != 0) {
            st = out_of_memory(r);
            goto done;
        }
        dst = img->pixels + (size_t)y * n;
        bytes = (unsigned char *)dst;
        got = read_rows(r->f, &ahead, bytes, nin * 4, rows);
        if (got != rows) {
            snprintf(what, sizeof what,
                     "pixel data (row %d of %d from the bottom)",
                     y + (int)got + 1, h);
            st = ended(r, what);
            goto done;
        }
        pfm_decode(bytes, dst, rows * nin, little, grey);
    }
    if (r->whole) {
        /* A file's header tells its length: bytes beyond it mean the
           header does not describe the data ("Pf" over colour pixels, a
           wrong size), and the image read would be wrong silently.  A
           pipe is read to its end for its length (--stream's frames
           through one are refused as a file of them is).  (A stream read
           by rtp_image_read_stream may carry the next image: not
           checked.) */
        long pos = r->size >= 0 ? ftell(r->f) : -1;
        long long more = pos >= 0 ? r->size - pos : 0;
        if (r->size < 0) {
            more = rest_bytes(r->f);
            if (ferror(r->f)) {
                st = ended(r, "bytes after the pixel data");
                goto done;
            }
        }
        if (more > 0) {
            st = BAD(r, "PFM: %s%lld byte%s after the pixel data: the header (%s %dx%d) "
                        "does not describe the data (rtp reads one image a file)",
                     more > REST_MAX ? "over " : "", more > REST_MAX ? REST_MAX : more,
                     more == 1 ? "" : "s", grey ? "Pf, grey" : "PF, colour", w, h);
            goto done;
        }
    }
    for (y = 0; y < h / 2; y++) {
        float *a = img->pixels + (size_t)y * n;
        float *b = img->pixels + (size_t)(h - 1 - y) * n;
        for (i = 0; i < n; i++) {
            float t = a[i];
            a[i] = b[i];
            b[i] = t;
        }
    }
done:
    if (st != RTP_OK) {
        rtp_image_destroy(img);
        return st;
    }
    *out = img;
    return RTP_OK;
}

#ifdef RTPI_PNG
typedef struct png_rctx {
    png_io io;
    png_structp png;
    png_infop info;
    const rtp_allocator *alloc;
    rtp_image *img;
    int cap_rows;
    unsigned char *row;    /* one row as libpng gives it */
    unsigned char *bytes;  /* an interlaced image's pass rows, packed */
    size_t used, cap;      /* bytes' bytes filled and allocated */
    int too_big;           /* the header asks for more than the limit */
    png_uint_32 w, h;
    png_colorp plte;       /* a palette image's colours (else NULL) */
    int nplte;
    long bad_index;        /* an index past them (else -1), at bad_x, bad_y */
    png_uint_32 bad_x, bad_y;
} png_rctx;

/* n samples (8- or 16-bit, big-endian) to floats in [0, 1]. */
static void png_convert(const unsigned char *src, int wide, float *dst, size_t n)
{
    size_t i;
    if (wide)
        for (i = 0; i < n; i++)
            dst[i] = (float)((unsigned)src[2 * i] << 8 | src[2 * i + 1]) /
                     65535.0f;
    else
        for (i = 0; i < n; i++)
            dst[i] = (float)src[i] / 255.0f;
}

/* n pixels of a row as libpng gives it (RGB samples, or a palette
   image's indices a byte each) to RGB floats at dst.  An index past the
   palette, which the PNG specification makes an error and libpng reads
   as black, is kept in c->bad_index (x: its pixel's place in the row)
   and @return -1. */
static int png_pixels(png_rctx *c, const unsigned char *src, int wide, float *dst,
                      size_t n, png_uint_32 *x)
{
    size_t i;
    if (!c->plte) {
        png_convert(src, wide, dst, 3 * n);
        return 0;
    }
    for (i = 0; i < n; i++) {
        if (src[i] >= c->nplte) {
            c->bad_index = src[i];
            *x = (png_uint_32)i;
            return -1;
        }
        dst[3 * i] = (float)c->plte[src[i]].red / 255.0f;
        dst[3 * i + 1] = (float)c->plte[src[i]].green / 255.0f;
        dst[3 * i + 2] = (float)c->plte[src[i]].blue / 255.0f;
    }
    return 0;
}

/* The only function that calls setjmp for reading; see png_io. */
static int png_read_body(png_rctx *c)
{
    int bit_depth, color_type, interlace, wide;
    size_t rowbytes, y, px;
    if (setjmp(png_jmpbuf(c->png)))
        return -1;
    png_set_read_fn(c->png, &c->io, png_read_fn);
    png_set_sig_bytes(c->png, 8);
    png_read_info(c->png, c->info);
    png_get_IHDR(c->png, c->info, &c->w, &c->h, &bit_depth, &color_type,
                 &interlace, NULL, NULL);
    if (!rtpi_image_size_ok((int)c->w, (int)c->h)) {
        c->too_big = 1;
        return -1;
    }
    /* To RGB, 8 or 16 bits: low-bit grey expanded, tRNS and alpha
       dropped (images are opaque RGB), grey copied to RGB.  No gamma
       handling: values are stored as written, as rtp writes them.  A
       palette image's indices come a byte each and are looked up here
       (png_pixels), each checked against the palette: libpng's expansion
       made one past it black, silently.  (No png_set_interlace_handling:
       Adam7 is undone below.) */
    if (color_type == PNG_COLOR_TYPE_PALETTE) {
        if (!png_get_PLTE(c->png, c->info, &c->plte, &c->nplte) || c->nplte < 1)
            png_error(c->png, "a palette image without a palette");
        png_set_packing(c->png);
    } else {
        png_set_expand(c->png);
        png_set_strip_alpha(c->png);
        png_set_gray_to_rgb(c->png);
    }
    png_read_update_info(c->png, c->info);
    wide = png_get_bit_depth(c->png, c->info) == 16;
    rowbytes = png_get_rowbytes(c->png, c->info);
    px = c->plte ? 1 : wide ? 6 : 3;
    if (png_get_channels(c->png, c->info) != (c->plte ? 1 : 3) || rowbytes != (size_t)c->w * px)
        png_error(c->png, "unexpected row layout after conversion to RGB");
    if (image_shell((int)c->w, (int)c->h, c->alloc, &c->img) != RTP_OK) {
        c->io.nomem = 1;
        return -1;
    }
    /* Image data left over once the last row is read (more rows than
       IHDR's height: "Too much image data"; bytes after the zlib stream:
       "Extra compressed data"), which libpng finds as it reads that row,
       are errors while the rows are read, not libpng's warnings, as bytes
       after a PFM's pixels are: a header that does not describe the data
       was read as a crop of it, silently.  (Only while the rows are read:
       the header's and the trailing ancillary chunks, which rtp does not
       use, keep libpng's leniency.) */
#ifdef PNG_BENIGN_ERRORS_SUPPORTED
    png_set_benign_errors(c->png, 0);
#endif
    /* (libpng copies a whole row's bytes into the row it is given, an
       interlaced pass's row too: its pixels first) */
    c->row = (unsigned char *)rtpi_malloc(&c->io.alloc, rowbytes);
    if (!c->row) {
        c->io.nomem = 1;
        return -1;
    }
    if (interlace == PNG_INTERLACE_NONE) {
        for (y = 0; y < c->h; y++) {
            if (reserve_rows(c->img, &c->cap_rows, (int)y + 1) != 0) {
                c->io.nomem = 1;
                return -1;
            }
            png_read_row(c->png, c->row, NULL);
            if (png_pixels(c, c->row, wide, c->img->pixels + y * row_floats(c->img), c->w,
                           &c->bad_x) != 0) {
                c->bad_y = (png_uint_32)y;
                return -1;
            }
        }
    } else {
        /* Adam7 undone here rather than by libpng, whose de-interlacing
           needs every row of the image from the first pass on: a file of
           16 KB that claimed 11585x11585 16-bit pixels and ended in that
           pass (1/64 of them) took 790 MB before it failed.  Each pass's
           rows come packed (its pixels only) and are appended to c->bytes
           as they come, so memory follows the data the file holds, as a
           plain PNG's rows do; the pixels are placed once every pass has
           been read.  (libpng skips a pass with no rows or no columns, as
           the loop does.) */
        size_t total = (size_t)c->w * c->h * px, r, x;
        float *dst;
        int pass;
        const unsigned char *src;
        for (pass = 0; pass < 7; pass++) {
            size_t cols = PNG_PASS_COLS(c->w, pass), n = cols * px;
            for (r = 0; cols && r < PNG_PASS_ROWS(c->h, pass); r++) {
                png_read_row(c->png, c->row, NULL);
                if (c->used + n > c->cap) {
                    unsigned char *nb;
                    size_t ncap = c->cap ? 2 * c->cap : (size_t)1 << 16;
                    if (ncap < c->used + n)
                        ncap = c->used + n;
                    if (ncap > total)
                        ncap = total;
                    nb = (unsigned char *)rtpi_realloc(&c->io.alloc, c->bytes, ncap);
                    if (!nb) {
                        c->io.nomem = 1;
                        return -1;
                    }
                    c->bytes = nb;
                    c->cap = ncap;
                }
                memcpy(c->bytes + c->used, c->row, n);
                c->used += n;
            }
        }
        if (reserve_rows(c->img, &c->cap_rows, (int)c->h) != 0) {
            c->io.nomem = 1;
            return -1;
        }
        src = c->bytes;
        for (pass = 0; pass < 7; pass++) {
            size_t cols = PNG_PASS_COLS(c->w, pass);
            for (r = 0; cols && r < PNG_PASS_ROWS(c->h, pass); r++) {
                y = PNG_ROW_FROM_PASS_ROW(r, pass);
                for (x = 0; x < cols; x++, src += px) {
                    png_uint_32 col = PNG_COL_FROM_PASS_COL(x, pass);
                    dst = c->img->pixels + 3 * (y * c->w + col);
                    if (png_pixels(c, src, wide, dst, 1, &c->bad_x) != 0) {
                        c->bad_x = col;
                        c->bad_y = (png_uint_32)y;
                        return -1;
                    }
                }
            }
        }
    }
#ifdef PNG_BENIGN_ERRORS_SUPPORTED
    png_set_benign_errors(c->png, 1);
#endif
    /* Up to IEND, so a file cut in its last chunk is caught too. */
    png_read_end(c->png, NULL);
    return 0;
}

static rtp_status read_png(const reader *r, const rtp_allocator *alloc,
                           rtp_image **out)
{
    png_rctx c;
    rtp_allocator a;
    rtp_status st = RTP_OK;
    rtpi_allocator_init(&a, alloc);
    memset(&c, 0, sizeof c);
    png_io_init(&c.io, &a, r->f);
    c.alloc = &a;
    c.bad_index = -1;
#ifdef PNG_USER_MEM_SUPPORTED
    c.png = png_create_read_struct_2(PNG_LIBPNG_VER_STRING, &c.io, png_err_fn,
                                     png_warn_fn, &c.io, png_malloc_fn,
                                     png_free_fn);
#else
    c.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &c.io, png_err_fn,
                                   png_warn_fn);
#endif
    if (c.png) {
        png_sizes(c.png);
        c.info = png_create_info_struct(c.png);
    }
    if (!c.png || !c.info) {
        st = out_of_memory(r);
    } else if (png_read_body(&c) != 0) {
        if (c.too_big)
            st = rtpi_error(r->err, RTP_ERR_LIMIT, r->name, 0, 0,
                            "PNG: image size %lux%lu exceeds the limit of "
                            "%lu pixels", (unsigned long)c.w,
                            (unsigned long)c.h, RTPI_IMAGE_MAX_PIXELS);
        else if (c.bad_index >= 0)
            st = rtpi_error(r->err, RTP_ERR_FORMAT, r->name, 0, 0,
                            "corrupt PNG: pixel (%lu, %lu) is palette index %ld, past "
                            "the palette's %d colours", (unsigned long)c.bad_x,
                            (unsigned long)c.bad_y, c.bad_index, c.nplte);
        else if (c.io.nomem)
            st = out_of_memory(r);
        else if (c.io.io_errno)
            st = rtpi_error(r->err, RTP_ERR_IO, r->name, 0, 0,
                            "read error: %s",
                            c.io.io_errno > 0 ? strerror(c.io.io_errno)
                                              : "stream error");
        else if (c.io.eof)
            st = rtpi_error(r->err, RTP_ERR_FORMAT, r->name, 0, 0,
                            "truncated: the PNG ends early");
        else
            st = rtpi_error(r->err, RTP_ERR_FORMAT, r->name, 0, 0,
                            "corrupt PNG: %s", c.io.msg);
    }
    if (c.png)
        png_destroy_read_struct(&c.png, c.info ? &c.info : NULL, NULL);
    rtpi_free(&a, c.row);
    rtpi_free(&a, c.bytes);
    if (st != RTP_OK) {
        rtp_image_destroy(c.img);
        return st;
    }
    *out = c.img;
    return RTP_OK;
}
#endif /* RTPI_PNG */

static const unsigned char png_signature[8] = {0x89, 'P',  'N',  'G',
                                               '\r', '\n', 0x1a, '\n'};

static rtp_status read_from(FILE *f, const char *name, long long size, int whole,
                            const rtp_allocator *alloc, rtp_image **out,
                            rtp_error *err)
{
    reader r;
    unsigned char sig[8];
    size_t got;
    int term = EOF;
    r.f = f;
    r.name = name;
    r.err = err;
    r.size = size;
    r.whole = whole;
    r.term = &term;
    errno = 0;
    got = fread(sig, 1, 2, f);
    if (got < 2) {
        if (ferror(f))
            return ended(&r, "header");
        return rtpi_error(err, RTP_ERR_FORMAT, name, 0, 0,
                          got ? "truncated: the file is 1 byte long"
                              : "the file is empty");
    }
    if (sig[0] == 'P' && (sig[1] == '6' || sig[1] == '3'))
        return read_ppm(&r, sig[1] == '3', alloc, out);
    if (sig[0] == 'P' && (sig[1] == 'F' || sig[1] == 'f'))
        return read_pfm(&r, sig[1] == 'f', alloc, out);
    if (sig[0] == png_signature[0] && sig[1] == png_signature[1]) {
        got = fread(sig + 2, 1, 6, f);
        if (got < 6)
            return ended(&r, "PNG signature");
        if (memcmp(sig, png_signature, 8) != 0)
            return rtpi_error(err, RTP_ERR_FORMAT, name, 0, 0,
                              "corrupt PNG signature");
#ifdef RTPI_PNG
        return read_png(&r, alloc, out);
#else
        return no_png(err, name);
#endif
    }
    if (sig[0] == 'P' && sig[1] >= '1' && sig[1] <= '7')
        return rtpi_error(err, RTP_ERR_FORMAT, name, 0, 0,
                          "netpbm type P%c is not supported: only P6 and "
                          "P3 colour images", sig[1]);
    /* (an rtp tree file's signature begins 0x89 'R': rtp diff handed a
       tree for an image said only the bytes) */
    if (sig[0] == 0x89 && sig[1] == 'R')
        return rtpi_error(err, RTP_ERR_FORMAT, name, 0, 0,
                          "not an image: an rtp tree file (rtp reeval makes its image)");
    return rtpi_error(err, RTP_ERR_FORMAT, name, 0, 0,
                      "not a PNG, PPM or PFM image (starts with bytes "
                      "0x%02x 0x%02x)", sig[0], sig[1]);
}

rtp_status rtp_image_read_stream(FILE *stream, const char *name,
                                 const rtp_allocator *alloc, rtp_image **out,
                                 rtp_error *err)
{
    if (!out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                          "rtp_image_read_stream: out is NULL");
    *out = NULL;
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_image_read_stream");
    if (!stream)
        return rtpi_error(err, RTP_ERR_ARGUMENT, name, 0, 0,
                          "no stream to read from");
    return read_from(stream, name ? name : "<stream>", -1, 0, alloc, out, err);
}

rtp_status rtp_image_read(const char *path, const rtp_allocator *alloc,
                          rtp_image **out, rtp_error *err)
{
    FILE *f;
    rtp_status st;
    if (!out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, path, 0, 0,
                          "rtp_image_read: out is NULL");
    *out = NULL;
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_image_read");
    if (!path || !*path)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "no image file name");
    if (strcmp(path, "-") == 0) {
        /* stdin redirected from a file is measured as a file is (a CRLF
           PFM read through '-' was read a byte off) */
        struct stat sb;
        long long size = fstat(fileno(stdin), &sb) == 0 && S_ISREG(sb.st_mode)
                             ? (long long)sb.st_size
                             : -1;
        return read_from(stdin, "<stdin>", size, 1, alloc, out, err);
    }
    f = fopen(path, "rb");
    if (!f)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot open: %s",
                          strerror(errno));
    {
        /* a regular file's size, for PFM's checks (read_pfm) */
        struct stat sb;
        long long size = fstat(fileno(f), &sb) == 0 && S_ISREG(sb.st_mode)
                             ? (long long)sb.st_size
                             : -1;
        st = read_from(f, path, size, 1, alloc, out, err);
    }
    fclose(f);
    return st;
}
