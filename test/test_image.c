/* test_image.c — image creation, PFM/PPM/PNG round trips, format sniffing,
 * and hostile input: truncated files at every length, corrupt headers,
 * random byte flips, failing allocators and failing writes. */
#include "check.h"
#include "internal.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdint.h>
#include <string.h>
#include <time.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#if defined(RTP_HAVE_PNG)
#if RTP_HAVE_PNG
#define TEST_PNG 1
#include <png.h>
#include <setjmp.h>
#endif
#endif

/* ------------------------------------------------------------ helpers */

static char tmpdir[256];

static const char *tpath(const char *name)
{
    static char buf[4][512];
    static int k;
    k = (k + 1) % 4;
    snprintf(buf[k], sizeof buf[k], "%s/%s", tmpdir, name);
    return buf[k];
}

static int write_bytes(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    size_t w;
    if (!f)
        return -1;
    w = n ? fwrite(data, 1, n, f) : 0;
    return (fclose(f) == 0 && w == n) ? 0 : -1;
}

static unsigned char *read_bytes(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    unsigned char *buf;
    long len;
    *n = 0;
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    len = ftell(f);
    fseek(f, 0, SEEK_SET);
    buf = (unsigned char *)malloc(len > 0 ? (size_t)len : 1);
    if (buf && len > 0 && fread(buf, 1, (size_t)len, f) != (size_t)len) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    if (buf)
        *n = (size_t)len;
    return buf;
}

static int file_exists(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0;
}

/* Entries in a folder, . and .. excluded (temporaries must not linger). */
static int count_entries(const char *dir)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    int n = 0;
    if (!d)
        return -1;
    while ((e = readdir(d)) != NULL)
        if (strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0)
            n++;
    closedir(d);
    return n;
}

static void remove_all(const char *dir)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    char buf[600];
    if (!d)
        return;
    while ((e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        snprintf(buf, sizeof buf, "%s/%s", dir, e->d_name);
        chmod(buf, 0700);
        remove_all(buf);
        remove(buf);
    }
    closedir(d);
}

/* An allocator that counts live blocks and can fail the k-th call. */
typedef struct counting {
    long live, calls, fail_at; /* fail_at < 0: never */
} counting;

static void *c_malloc(void *u, size_t n)
{
    counting *c = (counting *)u;
    void *p;
    if (c->fail_at >= 0 && c->calls++ == c->fail_at)
        return NULL;
    p = malloc(n);
    if (p)
        c->live++;
    return p;
}

static void *c_realloc(void *u, void *old, size_t n)
{
    counting *c = (counting *)u;
    void *p;
    if (c->fail_at >= 0 && c->calls++ == c->fail_at)
        return NULL;
    p = realloc(old, n);
    if (p && !old)
        c->live++;
    return p;
}

static void c_free(void *u, void *p)
{
    counting *c = (counting *)u;
    if (p)
        c->live--;
    free(p);
}

static rtp_allocator counting_alloc(counting *c)
{
    rtp_allocator a;
    c->live = c->calls = 0;
    c->fail_at = -1;
    a.malloc_fn = c_malloc;
    a.realloc_fn = c_realloc;
    a.free_fn = c_free;
    a.user = c;
    return a;
}

static float bits_to_float(uint32_t u)
{
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static float q8(float x)
{
    int q;
    if (isnan(x) || isinf(x) || !(x > 0.0f))
        q = 0;
    else if (x >= 1.0f)
        q = 255;
    else
        q = (int)((double)x * 255.0 + 0.5);
    return (float)q / 255.0f;
}

static uint32_t rng_state;
static uint32_t rng(void)
{
    rng_state = rng_state * 1664525u + 1013904223u;
    return rng_state >> 8;
}
static float rng_unit(void) { return (float)(rng() & 0xffff) / 65535.0f; }

/* A w x h image of values in [-0.2, 1.2] plus some NaN and infinities. */
static rtp_image *make_test_image(int w, int h)
{
    rtp_image *img = NULL;
    size_t i, n;
    if (rtp_image_create(w, h, NULL, &img, NULL) != RTP_OK)
        return NULL;
    n = (size_t)w * (size_t)h * 3;
    for (i = 0; i < n; i++)
        img->pixels[i] = rng_unit() * 1.4f - 0.2f;
    if (n > 6) {
        img->pixels[1] = bits_to_float(0x7fc00000u);  /* NaN */
        img->pixels[4] = bits_to_float(0x7f800000u);  /* +Inf */
        img->pixels[5] = bits_to_float(0xff800000u);  /* -Inf */
        img->pixels[n - 1] = 127.0f / 255.0f + 0.5f / 255.0f; /* a tie */
    }
    return img;
}

static int same_bits(const rtp_image *a, const rtp_image *b)
{
    return a && b && a->width == b->width && a->height == b->height &&
           memcmp(a->pixels, b->pixels,
                  (size_t)a->width * (size_t)a->height * 3 * sizeof(float)) ==
               0;
}

/* b holds a quantised to 8 bits exactly as the writers promise. */
static int is_quantised(const rtp_image *a, const rtp_image *b)
{
    size_t i, n;
    if (!a || !b || a->width != b->width || a->height != b->height)
        return 0;
    n = (size_t)a->width * (size_t)a->height * 3;
    for (i = 0; i < n; i++)
        if (b->pixels[i] != q8(a->pixels[i])) {
            fprintf(stderr, "sample %lu: %.9g -> %.9g, expected %.9g\n",
                    (unsigned long)i, a->pixels[i], b->pixels[i],
                    q8(a->pixels[i]));
            return 0;
        }
    return 1;
}

/* The bytes rtp writes for img in a format. */
static unsigned char *encode(const rtp_image *img, rtp_image_format fmt,
                             size_t *n)
{
    const char *p = tpath("encode.bin");
    if (rtp_image_write(img, p, fmt, NULL) != RTP_OK)
        return NULL;
    return read_bytes(p, n);
}

static rtp_status read_mem(const void *data, size_t n, rtp_image **out,
                           rtp_error *err)
{
    const char *p = tpath("mem.bin");
    if (write_bytes(p, data, n) != 0)
        return RTP_ERR_IO;
    return rtp_image_read(p, NULL, out, err);
}

static rtp_status read_str(const char *s, rtp_image **out)
{
    return read_mem(s, strlen(s), out, NULL);
}

static void put_le(unsigned char *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    p[0] = (unsigned char)u;
    p[1] = (unsigned char)(u >> 8);
    p[2] = (unsigned char)(u >> 16);
    p[3] = (unsigned char)(u >> 24);
}

static void put_be(unsigned char *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    p[0] = (unsigned char)(u >> 24);
    p[1] = (unsigned char)(u >> 16);
    p[2] = (unsigned char)(u >> 8);
    p[3] = (unsigned char)u;
}

static uint32_t crc32_png(const unsigned char *p, size_t n)
{
    uint32_t c = 0xffffffffu;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        c ^= p[i];
        for (k = 0; k < 8; k++)
            c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return c ^ 0xffffffffu;
}

static void put_u32be(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

/* -------------------------------------------------------------- tests */

static void test_create(void)
{
    rtp_image *img = (rtp_image *)1;
    rtp_error err;
    counting c;
    rtp_allocator a = counting_alloc(&c);
    size_t i;
    int zero = 1;

    CHECK(rtp_image_create(0, 5, NULL, &img, &err) == RTP_ERR_ARGUMENT);
    CHECK(img == NULL);
    CHECK(rtp_image_create(5, -1, NULL, &img, NULL) == RTP_ERR_ARGUMENT);
    CHECK(rtp_image_create(INT_MAX, INT_MAX, NULL, &img, &err) ==
          RTP_ERR_LIMIT);
    CHECK(err.status == RTP_ERR_LIMIT && err.message[0]);
    CHECK(rtp_image_create(65536, 65536, NULL, &img, NULL) == RTP_ERR_LIMIT);
    CHECK(rtp_image_create(1 << 21, 1, NULL, &img, NULL) == RTP_ERR_LIMIT);
    CHECK(rtpi_image_size_ok(1, 1));
    CHECK(rtpi_image_size_ok(16384, 8192));
    CHECK(!rtpi_image_size_ok(16384, 8193));
    CHECK(!rtpi_image_size_ok(0, 1) && !rtpi_image_size_ok(1, -3));
    /* The limits' edges, and products that pass 2^32 (which a 32-bit
       unsigned long, ILP32 or LLP64, wrapped: 2^20 x 2^12 to 0, 2^20 x
       (2^12 + 1) to 2^20, both then allowed) */
    CHECK(rtpi_image_size_ok(1 << 20, 1) && rtpi_image_size_ok(1, 1 << 20));
    CHECK(rtpi_image_size_ok(1 << 20, 1 << 7) && rtpi_image_size_ok(1 << 7, 1 << 20));
    CHECK(!rtpi_image_size_ok(1 << 20, (1 << 7) + 1));
    CHECK(rtpi_image_size_ok(11585, 11585) && !rtpi_image_size_ok(11586, 11586));
    CHECK(!rtpi_image_size_ok(1 << 20, 1 << 12) && !rtpi_image_size_ok(1 << 12, 1 << 20));
    CHECK(!rtpi_image_size_ok(1 << 20, (1 << 12) + 1));
    CHECK(!rtpi_image_size_ok(1 << 20, 1 << 20) && !rtpi_image_size_ok(65536, 65536));
    CHECK(rtp_image_create(1 << 20, 1 << 12, NULL, &img, NULL) == RTP_ERR_LIMIT && !img);

    CHECK(rtp_image_create(7, 3, &a, &img, NULL) == RTP_OK);
    CHECK(img && img->width == 7 && img->height == 3 && img->pixels);
    for (i = 0; img && i < 7 * 3 * 3; i++)
        zero &= img->pixels[i] == 0.0f;
    CHECK(zero);
    CHECK(c.live == 2);
    rtp_image_destroy(img);
    CHECK(c.live == 0);
    rtp_image_destroy(NULL);

    for (c.fail_at = 0; c.fail_at < 2; c.fail_at++) {
        c.calls = 0;
        CHECK(rtp_image_create(7, 3, &a, &img, NULL) == RTP_ERR_NOMEM);
        CHECK(c.live == 0 && img == NULL);
    }
}

static void test_format_from_path(void)
{
    CHECK(rtp_image_format_from_path("a.png") == RTP_IMAGE_PNG);
    CHECK(rtp_image_format_from_path("dir/A.PNG") == RTP_IMAGE_PNG);
    CHECK(rtp_image_format_from_path("x.PpM") == RTP_IMAGE_PPM);
    CHECK(rtp_image_format_from_path("/t/x.y.pfm") == RTP_IMAGE_PFM);
    CHECK(rtp_image_format_from_path("x.Pfm") == RTP_IMAGE_PFM);
    CHECK(rtp_image_format_from_path("x") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("x.jpg") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("x.pngx") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("x.pn") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("dir.png/x") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path(".png") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("-") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path("") == RTP_IMAGE_AUTO);
    CHECK(rtp_image_format_from_path(NULL) == RTP_IMAGE_AUTO);
}

static void test_pfm_exact(void)
{
    static const uint32_t special[] = {
        0x00000001u, /* smallest subnormal */
        0x80000000u, /* -0 */
        0x7f7fffffu, /* largest float */
        0x7f800000u, /* +Inf */
        0xff800000u, /* -Inf */
        0x7fc00001u, /* a NaN with payload */
        0x3eaaaaabu, /* 1/3 */
        0xbf800000u, /* -1 */
        0x00800000u  /* smallest normal */
    };
    rtp_image *img = make_test_image(5, 3), *back = NULL;
    rtp_error err;
    size_t i;
    CHECK(img != NULL);
    if (!img)
        return;
    for (i = 0; i < sizeof special / sizeof *special; i++)
        img->pixels[10 + i] = bits_to_float(special[i]);
    CHECK(rtp_image_write(img, tpath("exact.pfm"), RTP_IMAGE_AUTO, &err) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("exact.pfm"), NULL, &back, &err) == RTP_OK);
    CHECK(same_bits(img, back));
    rtp_image_destroy(back);
    back = NULL;
    /* Explicit format, any name. */
    CHECK(rtp_image_write(img, tpath("exact.bin"), RTP_IMAGE_PFM, &err) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("exact.bin"), NULL, &back, &err) == RTP_OK);
    CHECK(same_bits(img, back));
    rtp_image_destroy(back);
    rtp_image_destroy(img);
}

static void test_pfm_layout(void)
{
    static const char hdr[] = "PF\n2 3\n-1.0\n";
    rtp_image *img = NULL, *back = NULL;
    unsigned char *raw, file[64 + 2 * 2 * 12];
    size_t n, i, h;
    int ok = 1;
    float v;

    /* Written: header, then rows bottom first, little-endian. */
    CHECK(rtp_image_create(2, 3, NULL, &img, NULL) == RTP_OK);
    if (!img)
        return;
    for (i = 0; i < 18; i++)
        img->pixels[i] = (float)i + 0.25f;
    CHECK(rtp_image_write(img, tpath("layout.pfm"), RTP_IMAGE_AUTO, NULL) ==
          RTP_OK);
    raw = read_bytes(tpath("layout.pfm"), &n);
    CHECK(raw && n == strlen(hdr) + 18 * 4);
    if (raw && n == strlen(hdr) + 18 * 4) {
        CHECK(memcmp(raw, hdr, strlen(hdr)) == 0);
        for (i = 0; i < 18; i++) {
            size_t file_row = i / 6, img_row = 2 - file_row;
            unsigned char want[4];
            put_le(want, img->pixels[img_row * 6 + i % 6]);
            ok &= memcmp(raw + strlen(hdr) + 4 * i, want, 4) == 0;
        }
        CHECK(ok);
    }
    free(raw);
    rtp_image_destroy(img);

    /* Hand-made files, both byte orders: file row 0 is the bottom. */
    h = (size_t)sprintf((char *)file, "PF\n2 2\n-1.0\n");
    for (i = 0; i < 12; i++)
        put_le(file + h + 4 * i, (float)(i + 1));
    CHECK(read_mem(file, h + 48, &back, NULL) == RTP_OK);
    if (back) {
        CHECK(back->width == 2 && back->height == 2);
        for (i = 0; i < 6; i++) {
            CHECK(back->pixels[i] == (float)(i + 7));     /* top row */
            CHECK(back->pixels[6 + i] == (float)(i + 1)); /* bottom row */
        }
    }
    rtp_image_destroy(back);
    back = NULL;

    h = (size_t)sprintf((char *)file, "PF\n2 2\n1.0\n");
    for (i = 0; i < 12; i++)
        put_be(file + h + 4 * i, (float)(i + 1) * 0.5f);
    CHECK(read_mem(file, h + 48, &back, NULL) == RTP_OK);
    if (back) {
        CHECK(back->pixels[0] == 3.5f && back->pixels[11] == 3.0f);
        CHECK(back->pixels[6] == 0.5f);
    }
    rtp_image_destroy(back);
    back = NULL;

    /* Spaces instead of newlines and an exponent in the scale. */
    h = (size_t)sprintf((char *)file, "PF 1 1 -0.5e1 ");
    for (i = 0; i < 3; i++)
        put_le(file + h + 4 * i, 2.0f);
    CHECK(read_mem(file, h + 12, &back, NULL) == RTP_OK);
    CHECK(back && back->pixels[2] == 2.0f);
    rtp_image_destroy(back);
    back = NULL;

    /* Grey PFM ("Pf") becomes RGB. */
    h = (size_t)sprintf((char *)file, "Pf\n2 1\n-1\n");
    put_le(file + h, 0.25f);
    put_le(file + h + 4, 0.75f);
    CHECK(read_mem(file, h + 8, &back, NULL) == RTP_OK);
    if (back) {
        CHECK(back->width == 2 && back->height == 1);
        v = back->pixels[3];
        CHECK(back->pixels[0] == 0.25f && back->pixels[2] == 0.25f);
        CHECK(v == 0.75f && back->pixels[5] == 0.75f);
    }
    rtp_image_destroy(back);
}

/* A PFM file's length is the header's: a CRLF header is read as its
   writer meant (the '\n' a header byte, not a pixel's), bytes beyond the
   pixels are an error naming the header ("Pf" over colour data read a
   third of it silently before), and a stream may go on past the image. */
static void test_pfm_file_length(void)
{
    unsigned char file[128];
    rtp_image *back = NULL;
    rtp_error err;
    size_t h, i;
    FILE *f;

    h = (size_t)sprintf((char *)file, "PF\r\n2 1\r\n-1.0\r\n");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 0.125f * (float)(i + 1));
    CHECK(read_mem(file, h + 24, &back, &err) == RTP_OK);
    CHECK(back && back->pixels[0] == 0.125f && back->pixels[5] == 0.75f);
    rtp_image_destroy(back);
    back = NULL;
    /* a first pixel byte 0x0a after a lone '\r' is the pixel's */
    h = (size_t)sprintf((char *)file, "PF\n1 1\n-1.0\r");
    memcpy(file + h, "\n\0\x80\x3e", 4);
    put_le(file + h + 4, 2.0f);
    put_le(file + h + 8, 3.0f);
    CHECK(read_mem(file, h + 12, &back, &err) == RTP_OK);
    if (back) {
        float v;
        uint32_t u = 0x3e80000au;
        memcpy(&v, &u, 4);
        CHECK(back->pixels[0] == v && back->pixels[2] == 3.0f);
    }
    rtp_image_destroy(back);
    back = NULL;

    h = (size_t)sprintf((char *)file, "Pf\n2 1\n-1.0\n");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 0.5f);
    CHECK(read_mem(file, h + 24, &back, &err) == RTP_ERR_FORMAT);
    CHECK(!back && strstr(err.message, "16 bytes after the pixel data") &&
          strstr(err.message, "Pf"));
    h = (size_t)sprintf((char *)file, "PF\n2 1\n-1.0\n");
    for (i = 0; i < 12; i++)
        put_le(file + h + 4 * i, 0.5f);
    CHECK(read_mem(file, h + 48, &back, &err) == RTP_ERR_FORMAT);
    CHECK(!back && strstr(err.message, "24 bytes after"));
    /* a stream: the image, and the rest left for the next read */
    f = fopen(tpath("mem.bin"), "rb");
    CHECK(f != NULL);
    if (f) {
        CHECK(rtp_image_read_stream(f, "s", NULL, &back, &err) == RTP_OK);
        CHECK(back && back->width == 2 && getc(f) != EOF);
        rtp_image_destroy(back);
        fclose(f);
    }
}

/* Blanks before a PFM header's last line end ("-1.0 \n": some writers
   emit it) are the header's, read from a file or a stream; other text
   after the scale is refused naming it.  (The format asks for one
   whitespace character after the scale: the blank was taken for it and
   the '\n' for a pixel byte, "1 byte after the pixel data".) */
static void test_pfm_header_blanks(void)
{
    static const char *const ok_headers[] = {
        "PF\n2 1\n-1.0 \n", "PF\n2 1\n-1.0\t\n", "PF\n2 1\n-1.0 \r\n",
        "PF \n2 1 \n-1.0   \n", "PF\n2 1\n-1.0\n\n", "Pf\n2 1\n-1.0 \n"};
    unsigned char file[256];
    rtp_image *back = NULL;
    rtp_error err;
    size_t h, i, k;
    FILE *f;

    for (k = 0; k < sizeof ok_headers / sizeof *ok_headers; k++) {
        int grey = ok_headers[k][1] == 'f';
        size_t nf = grey ? 2 : 6;
        h = (size_t)sprintf((char *)file, "%s", ok_headers[k]);
        for (i = 0; i < nf; i++)
            put_le(file + h + 4 * i, 0.125f * (float)(i + 1));
        CHECK_MSG(read_mem(file, h + 4 * nf, &back, &err) == RTP_OK,
                  "header %lu: %s", (unsigned long)k, err.message);
        CHECK(back && back->pixels[0] == 0.125f &&
              back->pixels[5] == (grey ? 0.25f : 0.75f));
        rtp_image_destroy(back);
        back = NULL;
    }

    /* A stream: blanks then a line end end the header; the next image
       follows untouched.  A header ended by one blank keeps a first
       pixel byte 0x20 (not followed by a line end) as the pixel's. */
    h = (size_t)sprintf((char *)file, "PF\n2 1\n-1.0  \r\n");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 0.5f * (float)(i + 1));
    h += 24;
    h += (size_t)sprintf((char *)file + h, "PF 1 1 -1 ");
    memcpy(file + h, " \0\0\x3f", 4); /* 0x3f000020 */
    put_le(file + h + 4, 2.0f);
    put_le(file + h + 8, 3.0f);
    h += 12;
    CHECK(write_bytes(tpath("stream.bin"), file, h) == 0);
    f = fopen(tpath("stream.bin"), "rb");
    CHECK(f != NULL);
    if (f) {
        CHECK(rtp_image_read_stream(f, "s", NULL, &back, &err) == RTP_OK);
        CHECK(back && back->pixels[0] == 0.5f && back->pixels[5] == 3.0f);
        rtp_image_destroy(back);
        back = NULL;
        CHECK(rtp_image_read_stream(f, "s", NULL, &back, &err) == RTP_OK);
        CHECK(back && back->pixels[0] == bits_to_float(0x3f000020u) &&
              back->pixels[2] == 3.0f);
        CHECK(getc(f) == EOF);
        rtp_image_destroy(back);
        back = NULL;
        fclose(f);
    }

    /* Text after the scale is not whitespace: refused, named. */
    h = (size_t)sprintf((char *)file, "PF\n2 1\n-1.0 x\n");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 1.0f);
    CHECK(read_mem(file, h + 24, &back, &err) == RTP_ERR_FORMAT);
    CHECK(!back && strstr(err.message, "\"x\" after its scale \"-1.0\""));
    h = (size_t)sprintf((char *)file, "PF\n2 1 3\n-1.0\n");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 1.0f);
    CHECK(read_mem(file, h + 24, &back, &err) == RTP_ERR_FORMAT);
    CHECK(!back && strstr(err.message, "\"-1.0\" after its scale \"3\""));
    /* a blank, then data one byte short: the blank was the header's one
       whitespace and the file is cut */
    h = (size_t)sprintf((char *)file, "PF\n2 1\n-1.0 ");
    for (i = 0; i < 6; i++)
        put_le(file + h + 4 * i, 1.0f);
    CHECK(read_mem(file, h + 23, &back, &err) == RTP_ERR_FORMAT);
    CHECK(!back && strstr(err.message, "truncated"));
}

static void test_ppm(void)
{
    rtp_image *img = make_test_image(9, 4), *back = NULL;
    unsigned char *raw;
    size_t n, i;
    int ok = 1;
    static const unsigned char p6_16[] = "P6\n1 2\n65535\n"
                                         "\xff\xff\x00\x00\x80\x00"
                                         "\x00\x01\x12\x34\xff\xfe";
    if (!img)
        return;
    CHECK(rtp_image_write(img, tpath("a.ppm"), RTP_IMAGE_AUTO, NULL) ==
          RTP_OK);
    raw = read_bytes(tpath("a.ppm"), &n);
    CHECK(raw && n == 11 + 9 * 4 * 3 && memcmp(raw, "P6\n9 4\n255\n", 11) ==
                                            0);
    if (raw && n == 11 + 9 * 4 * 3)
        for (i = 0; i < 9 * 4 * 3; i++)
            ok &= raw[11 + i] == (unsigned char)(q8(img->pixels[i]) * 255.0f +
                                                 0.5f);
    CHECK(ok);
    free(raw);
    CHECK(rtp_image_read(tpath("a.ppm"), NULL, &back, NULL) == RTP_OK);
    CHECK(is_quantised(img, back));
    rtp_image_destroy(back);
    back = NULL;
    rtp_image_destroy(img);

    /* P3 with comments everywhere in the header, maxval 1000. */
    CHECK(read_str("P3 # a comment\n# another\n2 # w\n 1\n1000\n"
                   "0 500 1000\n  250 750 1\n",
                   &back) == RTP_OK);
    if (back) {
        CHECK(back->width == 2 && back->height == 1);
        CHECK(back->pixels[0] == 0.0f && back->pixels[1] == 0.5f);
        CHECK(back->pixels[2] == 1.0f && back->pixels[3] == 0.25f);
        CHECK(back->pixels[5] == 1.0f / 1000.0f);
    }
    rtp_image_destroy(back);
    back = NULL;
    /* The last P3 sample may end the file. */
    CHECK(read_str("P3\n1 1\n255\n255 0 51", &back) == RTP_OK);
    CHECK(back && back->pixels[2] == 0.2f);
    rtp_image_destroy(back);
    back = NULL;

    /* A P3 sample above a maxval below 9 (its digit alone above it: the
       check let 5 under a maxval of 1 through as 5.0) */
    CHECK(read_str("P3\n1 1\n1\n5 0 1\n", &back) == RTP_ERR_FORMAT && !back);
    CHECK(read_str("P3\n1 1\n8\n9 0 1\n", &back) == RTP_ERR_FORMAT && !back);
    CHECK(read_str("P3\n1 1\n9\n9 0 1\n", &back) == RTP_OK);
    CHECK(back && back->pixels[0] == 1.0f);
    rtp_image_destroy(back);
    back = NULL;
    /* A comment right after a header number, as netpbm allows */
    CHECK(read_str("P3\n1 1#size\n255# max\n255 0 51\n", &back) == RTP_OK);
    CHECK(back && back->pixels[0] == 1.0f && back->pixels[2] == 0.2f);
    rtp_image_destroy(back);
    back = NULL;

    /* 16-bit P6, big-endian samples. */
    CHECK(read_mem(p6_16, sizeof p6_16 - 1, &back, NULL) == RTP_OK);
    if (back) {
        CHECK(back->width == 1 && back->height == 2);
        CHECK(back->pixels[0] == 1.0f && back->pixels[1] == 0.0f);
        CHECK(back->pixels[2] == 32768.0f / 65535.0f);
        CHECK(back->pixels[3] == 1.0f / 65535.0f);
        CHECK(back->pixels[4] == (float)0x1234 / 65535.0f);
        CHECK(back->pixels[5] == 65534.0f / 65535.0f);
    }
    rtp_image_destroy(back);
}

static void test_png(void)
{
    rtp_image *img = make_test_image(13, 7), *back = NULL;
    rtp_error err;
    rtp_status st;
    if (!img)
        return;
    st = rtp_image_write(img, tpath("a.png"), RTP_IMAGE_AUTO, &err);
    CHECK(!(rtp_features() & RTP_FEATURE_PNG) == !rtp_png_supported());
    CHECK(!(rtp_features() & RTP_FEATURE_PNG) == (st == RTP_ERR_UNSUPPORTED));
    if (!rtp_png_supported()) {
        static const unsigned char sig[] = "\x89PNG\r\n\x1a\n\0\0\0\rIHDR";
        CHECK(st == RTP_ERR_UNSUPPORTED && strstr(err.message, "PNG"));
        CHECK(!file_exists(tpath("a.png")));
        CHECK(read_mem(sig, sizeof sig - 1, &back, &err) ==
              RTP_ERR_UNSUPPORTED);
        rtp_image_destroy(img);
        SKIP("built without libpng: PNG round trips not run");
    }
    CHECK(st == RTP_OK);
    CHECK(rtp_image_read(tpath("a.png"), NULL, &back, &err) == RTP_OK);
    CHECK(is_quantised(img, back));
    rtp_image_destroy(back);
    rtp_image_destroy(img);
}

#ifdef TEST_PNG
static void t_png_error(png_structp png, png_const_charp msg)
{
    (void)msg;
    png_longjmp(png, 1);
}

/* Writes rows (already packed as libpng wants them) with libpng itself,
   for colour types and depths rtp never writes. */
static int write_png_raw(const char *path, int w, int h, int color_type,
                         int depth, int interlace, unsigned char *data,
                         size_t rowbytes, const png_color *palette,
                         int npal, const unsigned char *trns, int ntrns)
{
    FILE *f = fopen(path, "wb");
    png_structp png;
    png_infop info;
    png_bytep rows[256];
    int y;
    if (!f || h > 256) {
        if (f)
            fclose(f);
        return -1;
    }
    png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, t_png_error,
                                  NULL);
    info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        fclose(f);
        return -1;
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, depth, color_type,
                 interlace, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    if (palette)
        png_set_PLTE(png, info, palette, npal);
    if (trns)
        png_set_tRNS(png, info, trns, ntrns, NULL);
    png_write_info(png, info);
    for (y = 0; y < h; y++)
        rows[y] = data + (size_t)y * rowbytes;
    png_write_image(png, rows);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return fclose(f) == 0 ? 0 : -1;
}

/* Widths past libpng's default limit of 1,000,000, within rtp's 2^20:
   written and read as PFM was (they failed "Invalid IHDR data"). */
static void test_png_wide(void)
{
    rtp_image *img = NULL, *back = NULL;
    int i;
    CHECK(rtp_image_create(1040000, 1, NULL, &img, NULL) == RTP_OK);
    if (!img)
        return;
    for (i = 0; i < 3 * 1040000; i++)
        img->pixels[i] = (float)(i % 256) / 255.0f;
    CHECK(rtp_image_write(img, tpath("wide.png"), RTP_IMAGE_AUTO, NULL) == RTP_OK);
    CHECK(rtp_image_read(tpath("wide.png"), NULL, &back, NULL) == RTP_OK);
    CHECK(back && back->width == 1040000 && back->height == 1);
    CHECK(back && back->pixels[3 * 1039999 + 2] == img->pixels[3 * 1039999 + 2]);
    rtp_image_destroy(back);
    rtp_image_destroy(img);
}

static void test_png_kinds(void)
{
    unsigned char data[64 * 64 * 8];
    png_color pal[4] = {{0, 0, 0}, {255, 0, 0}, {0, 128, 255}, {1, 2, 3}};
    unsigned char trns[1] = {0};
    rtp_image *back = NULL;
    int x, y, ok;
    const char *p = tpath("kind.png");

    /* 8-bit grey. */
    for (x = 0; x < 5 * 3; x++)
        data[x] = (unsigned char)(x * 17);
    CHECK(write_png_raw(p, 5, 3, PNG_COLOR_TYPE_GRAY, 8, 0, data, 5, NULL, 0,
                        NULL, 0) == 0);
    CHECK(rtp_image_read(p, NULL, &back, NULL) == RTP_OK);
    ok = back && back->width == 5 && back->height == 3;
    for (x = 0; ok && x < 15; x++)
        ok = back->pixels[3 * x] == (float)(x * 17) / 255.0f &&
             back->pixels[3 * x + 1] == back->pixels[3 * x] &&
             back->pixels[3 * x + 2] == back->pixels[3 * x];
    CHECK(ok);
    rtp_image_destroy(back);
    back = NULL;

    /* 16-bit grey + alpha: alpha is dropped, 16 bits kept. */
    for (x = 0; x < 4; x++) {
        unsigned v = (unsigned)x * 20000u + 1u;
        data[4 * x] = (unsigned char)(v >> 8);
        data[4 * x + 1] = (unsigned char)v;
        data[4 * x + 2] = 0x12;
        data[4 * x + 3] = 0x34;
    }
    CHECK(write_png_raw(p, 4, 1, PNG_COLOR_TYPE_GRAY_ALPHA, 16, 0, data, 16,
                        NULL, 0, NULL, 0) == 0);
    CHECK(rtp_image_read(p, NULL, &back, NULL) == RTP_OK);
    ok = back && back->width == 4 && back->height == 1;
    for (x = 0; ok && x < 4; x++)
        ok = back->pixels[3 * x + 2] ==
             (float)(x * 20000 + 1) / 65535.0f;
    CHECK(ok);
    rtp_image_destroy(back);
    back = NULL;

    /* 2-bit palette with tRNS. */
    data[0] = 0x1b; /* indices 0 1 2 3 */
    data[1] = 0xe4; /* 3 2 1 0 */
    CHECK(write_png_raw(p, 4, 2, PNG_COLOR_TYPE_PALETTE, 2, 0, data, 1, pal,
                        4, trns, 1) == 0);
    CHECK(rtp_image_read(p, NULL, &back, NULL) == RTP_OK);
    ok = back && back->width == 4 && back->height == 2;
    if (ok) {
        ok = back->pixels[3] == 1.0f && back->pixels[4] == 0.0f &&
             back->pixels[7] == 128.0f / 255.0f &&
             back->pixels[9] == 1.0f / 255.0f &&
             back->pixels[12] == 1.0f / 255.0f &&
             back->pixels[21] == 0.0f;
    }
    CHECK(ok);
    rtp_image_destroy(back);
    back = NULL;

    /* Interlaced 8-bit RGBA. */
    for (y = 0; y < 11; y++)
        for (x = 0; x < 9 * 4; x++)
            data[y * 36 + x] = (unsigned char)(y * 31 + x * 7);
    CHECK(write_png_raw(p, 9, 11, PNG_COLOR_TYPE_RGB_ALPHA, 8,
                        PNG_INTERLACE_ADAM7, data, 36, NULL, 0, NULL,
                        0) == 0);
    CHECK(rtp_image_read(p, NULL, &back, NULL) == RTP_OK);
    ok = back && back->width == 9 && back->height == 11;
    for (y = 0; ok && y < 11; y++)
        for (x = 0; ok && x < 9 * 3; x++)
            ok = back->pixels[y * 27 + x] ==
                 (float)(unsigned char)(y * 31 + (x / 3 * 4 + x % 3) * 7) /
                     255.0f;
    CHECK(ok);
    rtp_image_destroy(back);
    back = NULL;

    /* Interlaced 16-bit RGB, taller than the first row allocation. */
    for (y = 0; y < 150; y++)
        for (x = 0; x < 7 * 3; x++) {
            unsigned v = (unsigned)(y * 409 + x * 3001) & 0xffffu;
            data[y * 42 + 2 * x] = (unsigned char)(v >> 8);
            data[y * 42 + 2 * x + 1] = (unsigned char)v;
        }
    CHECK(write_png_raw(p, 7, 150, PNG_COLOR_TYPE_RGB, 16,
                        PNG_INTERLACE_ADAM7, data, 42, NULL, 0, NULL,
                        0) == 0);
    CHECK(rtp_image_read(p, NULL, &back, NULL) == RTP_OK);
    ok = back && back->width == 7 && back->height == 150;
    for (y = 0; ok && y < 150; y++)
        for (x = 0; ok && x < 7 * 3; x++)
            ok = back->pixels[y * 21 + x] ==
                 (float)((unsigned)(y * 409 + x * 3001) & 0xffffu) /
                     65535.0f;
    CHECK(ok);
    rtp_image_destroy(back);
}
#endif

static void test_sniff(void)
{
    rtp_image *img = make_test_image(6, 5), *back = NULL;
    FILE *f;
    int kinds = rtp_png_supported() ? 3 : 2, k;
    rtp_image_format fmts[3] = {RTP_IMAGE_PFM, RTP_IMAGE_PPM, RTP_IMAGE_PNG};
    if (!img)
        return;
    /* Content decides, not the name. */
    CHECK(rtp_image_write(img, tpath("s.png"), RTP_IMAGE_PFM, NULL) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("s.png"), NULL, &back, NULL) == RTP_OK);
    CHECK(same_bits(img, back));
    rtp_image_destroy(back);
    back = NULL;
    CHECK(rtp_image_write(img, tpath("s.dat"), RTP_IMAGE_PPM, NULL) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("s.dat"), NULL, &back, NULL) == RTP_OK);
    CHECK(is_quantised(img, back));
    rtp_image_destroy(back);
    back = NULL;
    if (rtp_png_supported()) {
        CHECK(rtp_image_write(img, tpath("s.pfm"), RTP_IMAGE_PNG, NULL) ==
              RTP_OK);
        CHECK(rtp_image_read(tpath("s.pfm"), NULL, &back, NULL) == RTP_OK);
        CHECK(is_quantised(img, back));
        rtp_image_destroy(back);
        back = NULL;
    }

    /* Several images back to back in one stream: readers take exactly
       their own bytes, as a pipe needs. */
    f = tmpfile();
    CHECK(f != NULL);
    if (f) {
        for (k = 0; k < kinds; k++)
            CHECK(rtp_image_write_stream(img, f, fmts[k], NULL) == RTP_OK);
        CHECK(rtp_image_write_stream(img, f, RTP_IMAGE_AUTO, NULL) ==
              RTP_OK); /* AUTO on a stream: PFM */
        rewind(f);
        for (k = 0; k <= kinds; k++) {
            rtp_error err;
            CHECK(rtp_image_read_stream(f, "pipe", NULL, &back, &err) ==
                  RTP_OK);
            if (k == 0 || k == kinds)
                CHECK(same_bits(img, back));
            else
                CHECK(is_quantised(img, back));
            rtp_image_destroy(back);
            back = NULL;
        }
        CHECK(getc(f) == EOF);
        fclose(f);
    }

    /* "-" reads stdin. */
    if (freopen(tpath("s.png"), "rb", stdin)) {
        CHECK(rtp_image_read("-", NULL, &back, NULL) == RTP_OK);
        CHECK(same_bits(img, back));
        rtp_image_destroy(back);
        back = NULL;
    }
    rtp_image_destroy(img);
}

/* Every proper prefix of a valid file must fail with RTP_ERR_FORMAT. */
static void check_prefixes(const unsigned char *data, size_t n, size_t upto,
                           const char *what)
{
    size_t len;
    int bad = 0;
    for (len = 0; len < upto; len++) {
        rtp_image *img = NULL;
        rtp_error err;
        rtp_status st = read_mem(data, len, &img, &err);
        if (st != RTP_ERR_FORMAT || img != NULL ||
            strcmp(err.file, tpath("mem.bin")) != 0 || !err.message[0]) {
            if (bad++ < 3)
                fprintf(stderr, "%s cut to %lu of %lu bytes: status %d\n",
                        what, (unsigned long)len, (unsigned long)n, (int)st);
        }
        rtp_image_destroy(img);
    }
    CHECK_MSG(bad == 0, "%s: %d prefixes not rejected", what, bad);
}

static void test_truncated(void)
{
    static const char p3[] = "P3\n# c\n2 1\n255\n10 20 30 40 50 60\n";
    rtp_image *img = make_test_image(5, 4), *back = NULL;
    unsigned char *data;
    size_t n;
    if (!img)
        return;
    data = encode(img, RTP_IMAGE_PFM, &n);
    CHECK(data && read_mem(data, n, &back, NULL) == RTP_OK);
    rtp_image_destroy(back);
    back = NULL;
    if (data)
        check_prefixes(data, n, n, "PFM");
    free(data);
    data = encode(img, RTP_IMAGE_PPM, &n);
    if (data)
        check_prefixes(data, n, n, "PPM");
    free(data);
    if (rtp_png_supported()) {
        data = encode(img, RTP_IMAGE_PNG, &n);
        CHECK(data != NULL);
        if (data)
            check_prefixes(data, n, n, "PNG");
        free(data);
    }
    /* P3: a cut inside the last number cannot be told from a shorter one. */
    check_prefixes((const unsigned char *)p3, sizeof p3 - 1,
                   (size_t)(strstr(p3, "60") - p3), "P3");
    rtp_image_destroy(img);
}

static void test_corrupt_headers(void)
{
    static const struct {
        const char *text;
        rtp_status want;
    } cases[] = {
        {"PF\n2 2\n0.0\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n-0e5\n", RTP_ERR_FORMAT},
        {"PF\n2 2\nnan\n", RTP_ERR_FORMAT},
        {"PF\n2 2\ninf\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n-1.0x\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n-\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n1e\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n.\n", RTP_ERR_FORMAT},
        {"PF\n2 2\n-1.000000000000000000000000000000000000000000000001\n",
         RTP_ERR_FORMAT},
        {"PF\n2 x\n-1\n", RTP_ERR_FORMAT},
        {"PF\n0 2\n-1\n", RTP_ERR_FORMAT},
        {"PF\n-2 2\n-1\n", RTP_ERR_FORMAT},
        {"PF\n2.5 2\n-1\n", RTP_ERR_FORMAT},
        {"PF\n# no comments in PFM\n1 1\n-1\n", RTP_ERR_FORMAT},
        {"PF\n1 1\n-1\n\x00\x00\x80", RTP_ERR_FORMAT},
        {"P6\n2 2\n0\n............", RTP_ERR_FORMAT},
        {"P6\n2 2\n65536\n", RTP_ERR_FORMAT},
        {"P6\n2 2\n255x\n", RTP_ERR_FORMAT},
        {"P6\n1 1\n100\n\x10\x64\x65", RTP_ERR_FORMAT},
        {"P6\n1 1\n256\n\x01\x00\x01\x01\x00\x00", RTP_ERR_FORMAT},
        {"P6 1 1", RTP_ERR_FORMAT},
        {"P3\n1 1\n255\n1 2 300\n", RTP_ERR_FORMAT},
        {"P3\n1 1\n255\n1 2 x\n", RTP_ERR_FORMAT},
        {"P3\n1 1\n255\n1 2 -3\n", RTP_ERR_FORMAT},
        {"P5\n2 2\n255\n....", RTP_ERR_FORMAT},
        {"P7\n", RTP_ERR_FORMAT},
        {"GIF89a", RTP_ERR_FORMAT},
        {"P", RTP_ERR_FORMAT},
        {"\x89PNX\r\n\x1a\n", RTP_ERR_FORMAT},
        {"PF\n100000000 2\n-1\n", RTP_ERR_LIMIT},
        {"PF\n65536 65536\n-1\n", RTP_ERR_LIMIT},
        {"P6\n2000000 2000000\n255\n", RTP_ERR_LIMIT},
        {"P6\n99999999999999999999999999 1\n255\n", RTP_ERR_LIMIT},
        {"P3\n1 99999999999999999999999999\n255\n", RTP_ERR_LIMIT},
    };
    size_t i;
    for (i = 0; i < sizeof cases / sizeof *cases; i++) {
        rtp_image *img = NULL;
        rtp_error err;
        const char *t = cases[i].text;
        /* Texts with NULs: the length is up to the last visible byte. */
        size_t n = strlen(t);
        rtp_status st;
        if (i == 14)
            n = strlen(t) + 3; /* "\x00\x00\x80" */
        else if (i == 19)
            n = strlen(t) + 5;
        st = read_mem(t, n, &img, &err);
        CHECK_MSG(st == cases[i].want && img == NULL,
                  "case %lu: status %d, want %d (%s)", (unsigned long)i,
                  (int)st, (int)cases[i].want, err.message);
        rtp_image_destroy(img);
    }
}

static void test_corrupt_png(void)
{
    rtp_image *img = make_test_image(4, 3), *back = NULL;
    unsigned char *data;
    size_t n;
    rtp_error err;
    if (!img)
        return;
    if (!rtp_png_supported()) {
        rtp_image_destroy(img);
        SKIP("built without libpng");
    }
    data = encode(img, RTP_IMAGE_PNG, &n);
    CHECK(data && n > 33 && memcmp(data + 12, "IHDR", 4) == 0);
    if (!data || n <= 33) {
        rtp_image_destroy(img);
        free(data);
        return;
    }
    /* A flipped bit in IHDR: CRC error. */
    data[17] ^= 1;
    CHECK(read_mem(data, n, &back, &err) == RTP_ERR_FORMAT);
    CHECK(strstr(err.message, "PNG") != NULL);
    data[17] ^= 1;
    /* Width 0 with a correct CRC. */
    put_u32be(data + 16, 0);
    put_u32be(data + 29, crc32_png(data + 12, 17));
    CHECK(read_mem(data, n, &back, &err) == RTP_ERR_FORMAT);
    /* A huge image with a correct CRC: over rtp's limit before any
       pixel memory is taken. */
    put_u32be(data + 16, 100000);
    put_u32be(data + 20, 100000);
    put_u32be(data + 29, crc32_png(data + 12, 17));
    CHECK(read_mem(data, n, &back, &err) == RTP_ERR_LIMIT);
    /* Large but within the limit, then truncated: a format error and no
       huge allocation up front. */
    put_u32be(data + 16, 10000);
    put_u32be(data + 20, 10000);
    put_u32be(data + 29, crc32_png(data + 12, 17));
    CHECK(read_mem(data, n, &back, &err) == RTP_ERR_FORMAT);
    CHECK(back == NULL);
    free(data);
    rtp_image_destroy(img);
}

/* An allocator that keeps the most bytes it ever had out at once. */
typedef struct peak_bytes {
    size_t now, peak;
} peak_bytes;

static void *pk_malloc(void *u, size_t n)
{
    peak_bytes *c = (peak_bytes *)u;
    size_t *p = (size_t *)malloc(n + sizeof(size_t) * 2);
    if (!p)
        return NULL;
    p[0] = n;
    c->now += n;
    if (c->now > c->peak)
        c->peak = c->now;
    return p + 2; /* (two words: malloc's alignment kept) */
}

static void pk_free(void *u, void *q)
{
    peak_bytes *c = (peak_bytes *)u;
    size_t *p = (size_t *)q;
    if (!p)
        return;
    c->now -= p[-2];
    free(p - 2);
}

static void *pk_realloc(void *u, void *q, size_t n)
{
    size_t *p = (size_t *)q, old = p ? p[-2] : 0;
    void *r = pk_malloc(u, n);
    if (r && p)
        memcpy(r, p, old < n ? old : n);
    if (r)
        pk_free(u, p);
    return r;
}

/* An interlaced PNG that claims 1024x1024 16-bit RGB (6 MiB of rows) and
   ends within its first pass, which holds 1/64 of the pixels: libpng's
   own de-interlacing had rtp take the whole image's rows as that pass
   came in (6 MiB from a 96 KB file; 790 MB from 16 KB of zeros claiming
   11585x11585), where memory should follow the data read.  The zlib
   stream is stored blocks, so the file is as big as its pixel data. */
static void test_png_interlaced_truncated(void)
{
    enum { W = 1024, ROW = W / 8 * 6 + 1, ROWS = 120 };
    size_t raw = (size_t)ROW * ROWS, blocks = (raw + 65534) / 65535, n, i, at;
    unsigned char *d;
    peak_bytes pk = {0, 0};
    rtp_allocator a;
    rtp_image *img = NULL;
    rtp_error err;
    FILE *f;
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (!rtp_png_supported())
        SKIP("built without libpng");
    n = 8 + 25 + 12 + 2 + raw + 5 * blocks;
    d = (unsigned char *)calloc(n, 1);
    CHECK(d != NULL);
    if (!d)
        return;
    memcpy(d, sig, 8);
    put_u32be(d + 8, 13);
    memcpy(d + 12, "IHDR", 4);
    put_u32be(d + 16, W);
    put_u32be(d + 20, W);
    d[24] = 16; /* depth */
    d[25] = 2;  /* RGB */
    d[28] = 1;  /* Adam7 */
    put_u32be(d + 29, crc32_png(d + 12, 17));
    put_u32be(d + 33, (uint32_t)(n - 45)); /* IDAT: the file ends inside it */
    memcpy(d + 37, "IDAT", 4);
    d[41] = 0x78;
    d[42] = 0x01;
    for (i = 0, at = 43; i < blocks; i++) {
        size_t len = raw - i * 65535 < 65535 ? raw - i * 65535 : 65535;
        d[at] = 0; /* stored, not final */
        d[at + 1] = (unsigned char)len;
        d[at + 2] = (unsigned char)(len >> 8);
        d[at + 3] = (unsigned char)~len;
        d[at + 4] = (unsigned char)(~len >> 8);
        at += 5 + len; /* (zero bytes: filter 0, black pixels) */
    }
    CHECK(write_bytes(tpath("ilace.png"), d, at) == 0);
    free(d);
    a.malloc_fn = pk_malloc;
    a.realloc_fn = pk_realloc;
    a.free_fn = pk_free;
    a.user = &pk;
    f = fopen(tpath("ilace.png"), "rb");
    CHECK(f != NULL);
    if (!f)
        return;
    CHECK(rtp_image_read_stream(f, "ilace.png", &a, &img, &err) == RTP_ERR_FORMAT);
    fclose(f);
    CHECK(img == NULL);
    CHECK(pk.now == 0);
    /* the pass's data (92 KB), a row and libpng's own buffers: far
       below the 6 MiB of the image's rows */
    CHECK(pk.peak < (size_t)1 << 20);
    if (pk.peak >= (size_t)1 << 20)
        fprintf(stderr, "  peak %lu bytes\n", (unsigned long)pk.peak);
}

#ifdef TEST_PNG
/* Every small size and the kinds Adam7 treats apart (sub-byte grey,
   8- and 16-bit RGB): interlaced images read as their plain twins. */
static void test_png_interlaced_sizes(void)
{
    unsigned char data[12 * 12 * 6];
    const char *pp = tpath("plain.png"), *pi = tpath("ilace2.png");
    int w, h, k, ok = 1;
    static const int ct[3] = {PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_RGB, PNG_COLOR_TYPE_RGB};
    static const int depth[3] = {4, 8, 16}, bytes_x2[3] = {1, 6, 12};
    for (k = 0; k < 3; k++)
        for (h = 1; h <= 12; h++)
            for (w = 1; w <= 12; w++) {
                rtp_image *a = NULL, *b = NULL;
                size_t rb = ((size_t)w * bytes_x2[k] + 1) / 2, i;
                for (i = 0; i < sizeof data; i++)
                    data[i] = (unsigned char)(rng() >> 7);
                if (write_png_raw(pp, w, h, ct[k], depth[k], 0, data, rb, NULL, 0, NULL,
                                  0) != 0 ||
                    write_png_raw(pi, w, h, ct[k], depth[k], PNG_INTERLACE_ADAM7, data, rb,
                                  NULL, 0, NULL, 0) != 0 ||
                    rtp_image_read(pp, NULL, &a, NULL) != RTP_OK ||
                    rtp_image_read(pi, NULL, &b, NULL) != RTP_OK || !same_bits(a, b)) {
                    if (ok)
                        fprintf(stderr, "  %dx%d kind %d differs\n", w, h, k);
                    ok = 0;
                }
                rtp_image_destroy(a);
                rtp_image_destroy(b);
            }
    CHECK(ok);
}
#endif

/* Random byte changes: any outcome but a crash, a leak or a bad image. */
static void test_fuzz(void)
{
    rtp_image *img = make_test_image(6, 4);
    unsigned seed = (unsigned)time(NULL);
    int kinds = rtp_png_supported() ? 3 : 2, k, iter, bad = 0;
    rtp_image_format fmts[3] = {RTP_IMAGE_PFM, RTP_IMAGE_PPM, RTP_IMAGE_PNG};
    counting c;
    rtp_allocator a = counting_alloc(&c);
    if (!img)
        return;
    fprintf(stderr, "test_fuzz: seed %u\n", seed);
    rng_state = seed;
    for (k = 0; k < kinds; k++) {
        size_t n;
        unsigned char *orig = encode(img, fmts[k], &n), *data;
        CHECK(orig != NULL);
        if (!orig)
            continue;
        data = (unsigned char *)malloc(n);
        for (iter = 0; data && iter < 1500; iter++) {
            rtp_image *back = NULL;
            rtp_status st;
            size_t len = n, j, flips = 1 + rng() % 4;
            memcpy(data, orig, n);
            for (j = 0; j < flips; j++)
                data[rng() % n] = (unsigned char)rng();
            if (rng() % 4 == 0)
                len = rng() % (n + 1);
            if (write_bytes(tpath("fuzz.bin"), data, len) != 0)
                continue;
            st = rtp_image_read(tpath("fuzz.bin"), &a, &back, NULL);
            if (st == RTP_OK)
                bad += !back || !rtpi_image_size_ok(back->width,
                                                    back->height);
            else
                bad += st != RTP_ERR_FORMAT && st != RTP_ERR_LIMIT;
            rtp_image_destroy(back);
            bad += c.live != 0;
        }
        free(data);
        free(orig);
    }
    CHECK_MSG(bad == 0, "%d bad outcomes (seed %u)", bad, seed);
    rtp_image_destroy(img);
}

/* af.bin read with every allocation failing in turn (c's, through a):
   NOMEM and nothing left live each time, until a read that needs no more
   succeeds (width w, or any where w < 0); the bad outcomes. */
static int read_failing(counting *c, const rtp_allocator *a, int w)
{
    long fail;
    int bad = 0;
    for (fail = 0; fail < 1000; fail++) {
        rtp_image *back = NULL;
        rtp_status st;
        c->calls = 0;
        c->fail_at = fail;
        st = rtp_image_read(tpath("af.bin"), a, &back, NULL);
        if (c->calls <= fail) { /* nothing failed: done */
            bad += st != RTP_OK || !back || (w >= 0 && back->width != w);
            rtp_image_destroy(back);
            bad += c->live != 0;
            break;
        }
        bad += st != RTP_ERR_NOMEM || back != NULL || c->live != 0;
        rtp_image_destroy(back);
    }
    return bad + (fail == 1000);
}

/* Every allocation failing in turn: NOMEM, nothing leaked. */
static void test_alloc_failures(void)
{
    static const char p3[] = "P3\n2 1\n255\n10 20 30 40 50 60\n";
    rtp_image *img = make_test_image(40, 30);
    /* PFM, PPM, P3, then PNG where supported. */
    int kinds = rtp_png_supported() ? 4 : 3, k, bad = 0;
    rtp_image_format fmts[4] = {RTP_IMAGE_PFM, RTP_IMAGE_PPM, RTP_IMAGE_AUTO,
                                RTP_IMAGE_PNG};
    counting c;
    rtp_allocator a = counting_alloc(&c);
    if (!img)
        return;
    for (k = 0; k < kinds; k++) {
        size_t n;
        unsigned char *data;
        if (fmts[k] == RTP_IMAGE_AUTO) {
            n = sizeof p3 - 1;
            data = (unsigned char *)malloc(n);
            if (data)
                memcpy(data, p3, n);
        } else {
            data = encode(img, fmts[k], &n);
        }
        if (!data || write_bytes(tpath("af.bin"), data, n) != 0) {
            CHECK(0);
            free(data);
            continue;
        }
        bad += read_failing(&c, &a, -1);
        free(data);
    }
#ifdef TEST_PNG
    {
        /* an interlaced 16-bit PNG: the passes' packed rows and the row
           libpng fills are allocations of their own */
        unsigned char rows[11 * 13 * 6];
        size_t i;
        for (i = 0; i < sizeof rows; i++)
            rows[i] = (unsigned char)(i * 37u);
        CHECK(write_png_raw(tpath("af.bin"), 13, 11, PNG_COLOR_TYPE_RGB, 16,
                            PNG_INTERLACE_ADAM7, rows, 13 * 6, NULL, 0, NULL, 0) == 0);
        bad += read_failing(&c, &a, 13);
    }
#endif
    CHECK_MSG(bad == 0, "%d bad outcomes", bad);
    rtp_image_destroy(img);
}

/* Images bigger than one I/O chunk (1 MiB): every chunk boundary read
   and written right, and stdio's small buffer no longer the unit of I/O
   (a 1024x1024 PFM was ~2,050 write calls and as many reads, a row or
   less at a time). */
/* The process's read and write system calls so far (Linux's
   /proc/self/io), or -1 where it is not kept. */
static long io_calls(const char *which)
{
    FILE *f = fopen("/proc/self/io", "r");
    char line[128];
    long v = -1;
    size_t len = strlen(which);
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f))
        if (strncmp(line, which, len) == 0 && line[len] == ':')
            v = strtol(line + len + 1, NULL, 10);
    fclose(f);
    return v;
}

static void test_io_chunks(void)
{
    rtp_image *img = make_test_image(1024, 300), *back = NULL;
    rtp_error err;
    unsigned char *file, *data;
    size_t h, i, n;
    int y, x;
    if (!img)
        return;

    /* Round trips over several chunks. */
    CHECK(rtp_image_write(img, tpath("big.pfm"), RTP_IMAGE_AUTO, &err) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("big.pfm"), NULL, &back, &err) == RTP_OK);
    CHECK(same_bits(img, back));
    rtp_image_destroy(back);
    back = NULL;
    CHECK(rtp_image_write(img, tpath("big.ppm"), RTP_IMAGE_AUTO, &err) ==
          RTP_OK);
    CHECK(rtp_image_read(tpath("big.ppm"), NULL, &back, &err) == RTP_OK);
    CHECK(is_quantised(img, back));
    rtp_image_destroy(back);
    back = NULL;

    /* The file's byte layout across chunks: row 299 first, little-endian. */
    data = read_bytes(tpath("big.pfm"), &n);
    h = strlen("PF\n1024 300\n-1.0\n");
    CHECK(data && n == h + (size_t)1024 * 300 * 12);
    if (data && n == h + (size_t)1024 * 300 * 12) {
        int ok = 1;
        for (y = 0; y < 300; y += 7)
            for (x = 0; x < 1024 * 3; x += 101) {
                unsigned char want[4];
                put_le(want, img->pixels[(size_t)(299 - y) * 3072 + (size_t)x]);
                ok &= memcmp(data + h + ((size_t)y * 3072 + (size_t)x) * 4,
                             want, 4) == 0;
            }
        CHECK(ok);
    }

    /* Cut in row 200 of 300 (from the bottom): that row is named. */
    if (data) {
        CHECK(read_mem(data, h + (size_t)199 * 12288 + 5, &back, &err) ==
              RTP_ERR_FORMAT);
        CHECK(!back && strstr(err.message, "row 200 of 300"));
    }
    free(data);

    /* Grey, big-endian, several chunks: spread to RGB in place. */
    n = (size_t)700 * 900;
    file = (unsigned char *)malloc(64 + n * 4);
    CHECK(file != NULL);
    if (file) {
        int ok = 1;
        h = (size_t)sprintf((char *)file, "Pf\n700 900\n1.0\n");
        for (i = 0; i < n; i++)
            put_be(file + h + 4 * i, (float)i);
        CHECK(read_mem(file, h + n * 4, &back, &err) == RTP_OK);
        if (back)
            for (y = 0; y < 900; y++)
                for (x = 0; x < 700; x++) {
                    const float *p = back->pixels +
                                     ((size_t)y * 700 + (size_t)x) * 3;
                    float want = (float)((size_t)(899 - y) * 700 + (size_t)x);
                    ok &= p[0] == want && p[1] == want && p[2] == want;
                }
        CHECK(back && ok);
        rtp_image_destroy(back);
        back = NULL;
        free(file);
    }

    /* P6 with 16-bit samples over several chunks; a sample above the
       maximum in a later chunk names its row. */
    n = (size_t)600 * 500 * 3;
    file = (unsigned char *)malloc(64 + n * 2);
    CHECK(file != NULL);
    if (file) {
        int ok = 1;
        h = (size_t)sprintf((char *)file, "P6\n600 500\n1000\n");
        for (i = 0; i < n; i++) {
            file[h + 2 * i] = (unsigned char)((i % 1001) >> 8);
            file[h + 2 * i + 1] = (unsigned char)(i % 1001);
        }
        CHECK(read_mem(file, h + n * 2, &back, &err) == RTP_OK);
        if (back)
            for (i = 0; i < n; i += 37)
                ok &= back->pixels[i] == (float)(i % 1001) / 1000.0f;
        CHECK(back && ok);
        rtp_image_destroy(back);
        back = NULL;
        i = (size_t)400 * 600 * 3 + 5; /* row 401 */
        file[h + 2 * i] = 0x03;
        file[h + 2 * i + 1] = 0xe9; /* 1001 */
        CHECK(read_mem(file, h + n * 2, &back, &err) == RTP_ERR_FORMAT);
        CHECK(!back && strstr(err.message, "(row 401)"));
        free(file);
    }

    /* System calls: 3.6 MB of PFM were ~600 writes and as many reads
       through stdio's 4 KiB buffer, now about two a chunk (the counts
       include /proc/self/io's own reads). */
    if (io_calls("syscw") < 0) {
        fprintf(stderr, "skip: system call counts (no /proc/self/io)\n");
    } else {
        static const char *const names[2] = {"calls.pfm", "calls.ppm"};
        int k;
        for (k = 0; k < 2; k++) {
            long w0 = io_calls("syscw"), w1, r0, r1;
            CHECK(rtp_image_write(img, tpath(names[k]), RTP_IMAGE_AUTO,
                                  &err) == RTP_OK);
            w1 = io_calls("syscw");
            r0 = io_calls("syscr");
            CHECK(rtp_image_read(tpath(names[k]), NULL, &back, &err) ==
                  RTP_OK);
            r1 = io_calls("syscr");
            CHECK(k ? is_quantised(img, back) : same_bits(img, back));
            rtp_image_destroy(back);
            back = NULL;
            CHECK_MSG(w1 - w0 <= 32, "%s: %ld writes", names[k], w1 - w0);
            CHECK_MSG(r1 - r0 <= 32, "%s: %ld reads", names[k], r1 - r0);
        }
    }
    rtp_image_destroy(img);
}

/* A path naming stdout's own file (/dev/stdout, here a link of the
   test's own to /proc/self/fd/1) is written through stdout whatever that
   file is: behind a pipe it was opened and written in place, so the image
   came out before what the program had printed to stdout and not yet
   flushed ("HEAD" after the image).  A child process writes into a pipe;
   the parent reads HEAD, the PFM, TAIL in that order. */
static void test_write_to_stdout_pipe(void)
{
    rtp_image *img = NULL;
    rtp_error err;
    int fd[2], status = 0;
    pid_t pid;
    char link[600], got[256];
    size_t n = 0;
    ssize_t r;
    snprintf(link, sizeof link, "%s", tpath("out1"));
    remove(link);
    if (symlink("/proc/self/fd/1", link) != 0)
        SKIP("cannot make a link to /proc/self/fd/1");
    CHECK(rtp_image_create(1, 1, NULL, &img, &err) == RTP_OK);
    if (!img || pipe(fd) != 0)
        SKIP("no image or no pipe");
    fflush(stdout);
    pid = fork();
    if (pid == 0) {
        close(fd[0]);
        if (dup2(fd[1], 1) < 0)
            _exit(2);
        setvbuf(stdout, NULL, _IOFBF, 4096);
        fputs("HEAD", stdout);
        if (rtp_image_write(img, link, RTP_IMAGE_PFM, &err) != RTP_OK)
            _exit(3);
        fputs("TAIL", stdout);
        fflush(stdout);
        _exit(0);
    }
    close(fd[1]);
    while (n < sizeof got && (r = read(fd[0], got + n, sizeof got - n)) > 0)
        n += (size_t)r;
    close(fd[0]);
    if (pid > 0)
        waitpid(pid, &status, 0);
    CHECK(pid > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0);
    /* "PF\n1 1\n-1.0\n" and 12 bytes of pixels between the two */
    CHECK_MSG(n == 4 + 12 + 12 + 4 && memcmp(got, "HEAD", 4) == 0 &&
                  memcmp(got + 4, "PF\n1 1\n", 7) == 0 && memcmp(got + n - 4, "TAIL", 4) == 0,
              "%zu bytes, starting '%.4s'", n, got);
    rtp_image_destroy(img);
    remove(link);
}

/* A regular file named through /dev/fd/N or /proc/self/fd/N (another open
   file, as a shell's 2>>log makes one) is appended to, by rtp_image_write
   and rtp_tree_write alike, never replaced: rtp.h said /dev/fd/N was
   "written in place" and rtp_tree_write named no exception to its rename,
   where README and the code append. */
static void test_write_through_fd_appends(void)
{
    static const char scene[] = "v from 0 0 5 at 0 0 0 up 0 1 0 angle 40 hither 1 resolution 4 4\n"
                                "l 0 0 5\nf 1 0 0 1 0 1 0 1\ns 0 0 0 1\n";
    rtp_image *img = NULL;
    rtp_scene *s = NULL;
    rtp_tree *t = NULL;
    rtp_error err;
    rtp_trace_options o;
    char path[64], buf[16];
    unsigned long long bytes = 0;
    int k;
    CHECK(rtp_image_create(1, 1, NULL, &img, &err) == RTP_OK);
    CHECK(rtp_scene_load_memory(scene, sizeof scene - 1, "fd.nff", "nff", NULL, &s, &err) ==
          RTP_OK);
    memset(&o, 0, sizeof o);
    if (s)
        CHECK(rtp_record(s, &o, &t, NULL, NULL, &err) == RTP_OK);
    if (!img || !t)
        return;
    for (k = 0; k < 2; k++) {
        const char *name = tpath(k ? "fd-tree.bin" : "fd-image.bin");
        FILE *f = fopen(name, "wb");
        long size;
        int fd;
        CHECK(f && fputs("OLDCONTENT", f) >= 0 && fclose(f) == 0);
        fd = open(name, O_WRONLY);
        CHECK(fd >= 0);
        if (fd < 0)
            continue;
        snprintf(path, sizeof path, k ? "/proc/self/fd/%d" : "/dev/fd/%d", fd);
        if (k)
            CHECK(rtp_tree_write(t, path, &bytes, &err) == RTP_OK);
        else
            CHECK(rtp_image_write(img, path, RTP_IMAGE_PFM, &err) == RTP_OK);
        close(fd);
        f = fopen(name, "rb");
        CHECK(f != NULL);
        if (!f)
            continue;
        CHECK(fread(buf, 1, 10, f) == 10 && memcmp(buf, "OLDCONTENT", 10) == 0);
        CHECK(fseek(f, 0, SEEK_END) == 0);
        size = ftell(f);
        fclose(f);
        CHECK_MSG(size == 10 + (k ? (long)bytes : 12 + 12), "%s: %ld bytes", path, size);
        remove(name);
    }
    rtp_tree_destroy(t);
    rtp_scene_destroy(s);
    rtp_image_destroy(img);
}

static void test_write_errors(void)
{
    rtp_image *img = make_test_image(8, 8), *back = NULL;
    rtp_error err;
    counting c;
    rtp_allocator a = counting_alloc(&c);
    rtp_image *cimg = NULL;
    char sub[400];
    unsigned char *before, *after;
    size_t nb, na;
    int entries, k;
    rtp_image_format fmts[3] = {RTP_IMAGE_PFM, RTP_IMAGE_PPM, RTP_IMAGE_PNG};
    FILE *f;
    struct stat sb;
    if (!img)
        return;

    /* Missing folder; a file used as a folder. */
    CHECK(rtp_image_write(img, tpath("nope/x.pfm"), RTP_IMAGE_AUTO, &err) ==
          RTP_ERR_IO);
    CHECK(strstr(err.file, "nope/x.pfm") != NULL && err.message[0]);
    CHECK(!file_exists(tpath("nope")));
    CHECK(write_bytes(tpath("plain"), "x", 1) == 0);
    CHECK(rtp_image_write(img, tpath("plain/x.ppm"), RTP_IMAGE_AUTO, &err) ==
          RTP_ERR_IO);

    /* A folder we may not write to (root may write anywhere). */
    snprintf(sub, sizeof sub, "%s", tpath("ro"));
    CHECK(mkdir(sub, 0755) == 0);
    if (geteuid() != 0 && chmod(sub, 0555) == 0) {
        char target[500];
        snprintf(target, sizeof target, "%s/x.pfm", sub);
        CHECK(rtp_image_write(img, target, RTP_IMAGE_AUTO, &err) ==
              RTP_ERR_IO);
        CHECK(count_entries(sub) == 0);
        chmod(sub, 0755);
    } else {
        fprintf(stderr, "skip: read-only folder case (running as root)\n");
    }

    /* Unknown extension, bad format value: argument errors, no file. */
    CHECK(rtp_image_write(img, tpath("x.jpg"), RTP_IMAGE_AUTO, &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(!file_exists(tpath("x.jpg")));
    CHECK(rtp_image_write(img, tpath("x.pfm"), (rtp_image_format)9, &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(!file_exists(tpath("x.pfm")));
    CHECK(rtp_image_write(NULL, tpath("x.pfm"), RTP_IMAGE_AUTO, &err) ==
          RTP_ERR_ARGUMENT);

    /* Devices are written in place, never replaced. */
    if (stat("/dev/full", &sb) == 0) {
        CHECK(rtp_image_write(img, "/dev/full", RTP_IMAGE_PFM, &err) ==
              RTP_ERR_IO);
        f = fopen("/dev/full", "wb");
        if (f) {
            CHECK(rtp_image_write_stream(img, f, RTP_IMAGE_PPM, &err) ==
                  RTP_ERR_IO);
            if (rtp_png_supported())
                CHECK(rtp_image_write_stream(img, f, RTP_IMAGE_PNG, &err) ==
                      RTP_ERR_IO);
            fclose(f);
        }
    }
    if (stat("/dev/null", &sb) == 0 && S_ISCHR(sb.st_mode)) {
        CHECK(rtp_image_write(img, "/dev/null", RTP_IMAGE_PFM, &err) ==
              RTP_OK);
        CHECK(stat("/dev/null", &sb) == 0 && S_ISCHR(sb.st_mode));
    }

    /* Overwriting works; a write failing at any allocation leaves the old
       file as it was and no temporary. */
    snprintf(sub, sizeof sub, "%s", tpath("ow"));
    CHECK(mkdir(sub, 0755) == 0);
    CHECK(rtp_image_create(8, 8, &a, &cimg, NULL) == RTP_OK);
    if (!cimg) {
        rtp_image_destroy(img);
        return;
    }
    memcpy(cimg->pixels, img->pixels, 8 * 8 * 3 * sizeof(float));
    for (k = 0; k < (rtp_png_supported() ? 3 : 2); k++) {
        char target[500];
        long fail;
        snprintf(target, sizeof target, "%s/t%d.img", sub, k);
        CHECK(write_bytes(target, "old", 3) == 0);
        entries = count_entries(sub);
        before = read_bytes(target, &nb);
        for (fail = 0; fail < 1000; fail++) {
            rtp_status st;
            c.calls = 0;
            c.fail_at = fail;
            st = rtp_image_write(cimg, target, fmts[k], &err);
            if (c.calls <= fail) {
                CHECK(st == RTP_OK);
                break;
            }
            CHECK(st == RTP_ERR_NOMEM);
            after = read_bytes(target, &na);
            CHECK(after && na == nb && memcmp(before, after, nb) == 0);
            free(after);
            CHECK(count_entries(sub) == entries);
        }
        c.fail_at = -1;
        CHECK(count_entries(sub) == entries);
        CHECK(rtp_image_read(target, NULL, &back, NULL) == RTP_OK);
        CHECK(back && back->width == 8);
        rtp_image_destroy(back);
        back = NULL;
        free(before);
    }
    rtp_image_destroy(cimg);
    CHECK(c.live == 0);

    /* Replacing a file keeps its permissions; a new one gets the usual. */
    {
        char target[500];
        mode_t um = umask(022);
        snprintf(target, sizeof target, "%s/perm.ppm", sub);
        CHECK(write_bytes(target, "old", 3) == 0 && chmod(target, 0640) == 0);
        CHECK(rtp_image_write(img, target, RTP_IMAGE_AUTO, &err) == RTP_OK);
        CHECK(stat(target, &sb) == 0 && (sb.st_mode & 0777) == 0640);
        snprintf(target, sizeof target, "%s/new.ppm", sub);
        CHECK(rtp_image_write(img, target, RTP_IMAGE_AUTO, &err) == RTP_OK);
        CHECK(stat(target, &sb) == 0 && (sb.st_mode & 0777) == 0644);
        umask(um);
    }
    rtp_image_destroy(img);
}

static void test_read_errors(void)
{
    rtp_image *img = (rtp_image *)1;
    rtp_error err;
    CHECK(rtp_image_read(tpath("missing.pfm"), NULL, &img, &err) ==
          RTP_ERR_IO);
    CHECK(img == NULL && strstr(err.file, "missing.pfm"));
    CHECK(rtp_image_read(tmpdir, NULL, &img, &err) == RTP_ERR_IO);
    CHECK(rtp_image_read(NULL, NULL, &img, &err) == RTP_ERR_ARGUMENT);
    CHECK(rtp_image_read_stream(NULL, "x", NULL, &img, &err) ==
          RTP_ERR_ARGUMENT);
    CHECK(read_mem("", 0, &img, &err) == RTP_ERR_FORMAT);
    CHECK(strstr(err.message, "empty") != NULL);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "%s/rtp-test-image.XXXXXX",
             getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    if (!mkdtemp(tmpdir)) {
        fprintf(stderr, "cannot make a temporary folder\n");
        return 1;
    }
    (void)check_shared_scenes; /* check.h's helper, unused here */
    rng_state = 12345;
    RUN(test_create);
    RUN(test_format_from_path);
    RUN(test_pfm_exact);
    RUN(test_pfm_layout);
    RUN(test_pfm_file_length);
    RUN(test_pfm_header_blanks);
    RUN(test_ppm);
    RUN(test_png);
#ifdef TEST_PNG
    RUN(test_png_kinds);
    RUN(test_png_wide);
    RUN(test_png_interlaced_sizes);
#endif
    RUN(test_png_interlaced_truncated);
    RUN(test_sniff);
    RUN(test_truncated);
    RUN(test_corrupt_headers);
    RUN(test_corrupt_png);
    RUN(test_fuzz);
    RUN(test_alloc_failures);
    RUN(test_io_chunks);
    RUN(test_write_errors);
    RUN(test_write_to_stdout_pipe);
    RUN(test_write_through_fd_appends);
    RUN(test_read_errors);
    remove_all(tmpdir);
    remove(tmpdir);
    return check_report();
}
