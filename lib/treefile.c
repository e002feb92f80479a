/* treefile.c — the tree file (.rtp): a traced image's ray trees with
 * everything needed to re-evaluate them, little-endian, written and read
 * byte by byte, every section checksummed and every length validated.
 * The format is specified in lib/tree-format.md. */
#include "internal.h"

#include <errno.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>

#define FMT_MAJOR 2
#define FMT_MINOR 0
#define MAX_NAME 255
/* Limits a file may not exceed; beyond them it is rejected before any
   allocation, so a corrupt length cannot ask for absurd memory. */
#define MAX_COUNT 0x7fffffffu
#define MAX_DEPTH_FILE RTP_MAX_DEPTH

static const unsigned char signature[8] = {0x89, 'R', 'T', 'P', '\r', '\n', 0x1a, '\n'};

static const uint32_t crc_table[256] = {
    0x00000000u, 0x77073096u, 0xee0e612cu, 0x990951bau, 0x076dc419u, 0x706af48fu,
    0xe963a535u, 0x9e6495a3u, 0x0edb8832u, 0x79dcb8a4u, 0xe0d5e91eu, 0x97d2d988u,
    0x09b64c2bu, 0x7eb17cbdu, 0xe7b82d07u, 0x90bf1d91u, 0x1db71064u, 0x6ab020f2u,
    0xf3b97148u, 0x84be41deu, 0x1adad47du, 0x6ddde4ebu, 0xf4d4b551u, 0x83d385c7u,
    0x136c9856u, 0x646ba8c0u, 0xfd62f97au, 0x8a65c9ecu, 0x14015c4fu, 0x63066cd9u,
    0xfa0f3d63u, 0x8d080df5u, 0x3b6e20c8u, 0x4c69105eu, 0xd56041e4u, 0xa2677172u,
    0x3c03e4d1u, 0x4b04d447u, 0xd20d85fdu, 0xa50ab56bu, 0x35b5a8fau, 0x42b2986cu,
    0xdbbbc9d6u, 0xacbcf940u, 0x32d86ce3u, 0x45df5c75u, 0xdcd60dcfu, 0xabd13d59u,
    0x26d930acu, 0x51de003au, 0xc8d75180u, 0xbfd06116u, 0x21b4f4b5u, 0x56b3c423u,
    0xcfba9599u, 0xb8bda50fu, 0x2802b89eu, 0x5f058808u, 0xc60cd9b2u, 0xb10be924u,
    0x2f6f7c87u, 0x58684c11u, 0xc1611dabu, 0xb6662d3du, 0x76dc4190u, 0x01db7106u,
    0x98d220bcu, 0xefd5102au, 0x71b18589u, 0x06b6b51fu, 0x9fbfe4a5u, 0xe8b8d433u,
    0x7807c9a2u, 0x0f00f934u, 0x9609a88eu, 0xe10e9818u, 0x7f6a0dbbu, 0x086d3d2du,
    0x91646c97u, 0xe6635c01u, 0x6b6b51f4u, 0x1c6c6162u, 0x856530d8u, 0xf262004eu,
    0x6c0695edu, 0x1b01a57bu, 0x8208f4c1u, 0xf50fc457u, 0x65b0d9c6u, 0x12b7e950u,
    0x8bbeb8eau, 0xfcb9887cu, 0x62dd1ddfu, 0x15da2d49u, 0x8cd37cf3u, 0xfbd44c65u,
    0x4db26158u, 0x3ab551ceu, 0xa3bc0074u, 0xd4bb30e2u, 0x4adfa541u, 0x3dd895d7u,
    0xa4d1c46du, 0xd3d6f4fbu, 0x4369e96au, 0x346ed9fcu, 0xad678846u, 0xda60b8d0u,
    0x44042d73u, 0x33031de5u, 0xaa0a4c5fu, 0xdd0d7cc9u, 0x5005713cu, 0x270241aau,
    0xbe0b1010u, 0xc90c2086u, 0x5768b525u, 0x206f85b3u, 0xb966d409u, 0xce61e49fu,
    0x5edef90eu, 0x29d9c998u, 0xb0d09822u, 0xc7d7a8b4u, 0x59b33d17u, 0x2eb40d81u,
    0xb7bd5c3bu, 0xc0ba6cadu, 0xedb88320u, 0x9abfb3b6u, 0x03b6e20cu, 0x74b1d29au,
    0xead54739u, 0x9dd277afu, 0x04db2615u, 0x73dc1683u, 0xe3630b12u, 0x94643b84u,
    0x0d6d6a3eu, 0x7a6a5aa8u, 0xe40ecf0bu, 0x9309ff9du, 0x0a00ae27u, 0x7d079eb1u,
    0xf00f9344u, 0x8708a3d2u, 0x1e01f268u, 0x6906c2feu, 0xf762575du, 0x806567cbu,
    0x196c3671u, 0x6e6b06e7u, 0xfed41b76u, 0x89d32be0u, 0x10da7a5au, 0x67dd4accu,
    0xf9b9df6fu, 0x8ebeeff9u, 0x17b7be43u, 0x60b08ed5u, 0xd6d6a3e8u, 0xa1d1937eu,
    0x38d8c2c4u, 0x4fdff252u, 0xd1bb67f1u, 0xa6bc5767u, 0x3fb506ddu, 0x48b2364bu,
    0xd80d2bdau, 0xaf0a1b4cu, 0x36034af6u, 0x41047a60u, 0xdf60efc3u, 0xa867df55u,
    0x316e8eefu, 0x4669be79u, 0xcb61b38cu, 0xbc66831au, 0x256fd2a0u, 0x5268e236u,
    0xcc0c7795u, 0xbb0b4703u, 0x220216b9u, 0x5505262fu, 0xc5ba3bbeu, 0xb2bd0b28u,
    0x2bb45a92u, 0x5cb36a04u, 0xc2d7ffa7u, 0xb5d0cf31u, 0x2cd99e8bu, 0x5bdeae1du,
    0x9b64c2b0u, 0xec63f226u, 0x756aa39cu, 0x026d930au, 0x9c0906a9u, 0xeb0e363fu,
    0x72076785u, 0x05005713u, 0x95bf4a82u, 0xe2b87a14u, 0x7bb12baeu, 0x0cb61b38u,
    0x92d28e9bu, 0xe5d5be0du, 0x7cdcefb7u, 0x0bdbdf21u, 0x86d3d2d4u, 0xf1d4e242u,
    0x68ddb3f8u, 0x1fda836eu, 0x81be16cdu, 0xf6b9265bu, 0x6fb077e1u, 0x18b74777u,
    0x88085ae6u, 0xff0f6a70u, 0x66063bcau, 0x11010b5cu, 0x8f659effu, 0xf862ae69u,
    0x616bffd3u, 0x166ccf45u, 0xa00ae278u, 0xd70dd2eeu, 0x4e048354u, 0x3903b3c2u,
    0xa7672661u, 0xd06016f7u, 0x4969474du, 0x3e6e77dbu, 0xaed16a4au, 0xd9d65adcu,
    0x40df0b66u, 0x37d83bf0u, 0xa9bcae53u, 0xdebb9ec5u, 0x47b2cf7fu, 0x30b5ffe9u,
    0xbdbdf21cu, 0xcabac28au, 0x53b39330u, 0x24b4a3a6u, 0xbad03605u, 0xcdd70693u,
    0x54de5729u, 0x23d967bfu, 0xb3667a2eu, 0xc4614ab8u, 0x5d681b02u, 0x2a6f2b94u,
    0xb40bbe37u, 0xc30c8ea1u, 0x5a05df1bu, 0x2d02ef8du,
};

/* CRC-32 (ISO-HDLC, as zlib and PNG).  Long runs go 8 bytes a step
   ("slicing by 8": table k advances a byte's effect by k more bytes),
   several times faster than a byte a step; the tables are made on the
   stack for each long run (8 KiB, ~2k steps), so the library keeps no
   state.  Bytes are assembled explicitly: the same on any byte order. */
#define CRC_SLICE_MIN 65536

/* The 8 tables of slicing-by-8, from crc_table. */
static void crc_slices(uint32_t t[8][256])
{
    int i, k;
    for (i = 0; i < 256; i++) {
        t[0][i] = crc_table[i];
        for (k = 1; k < 8; k++)
            t[k][i] = (t[k - 1][i] >> 8) ^ crc_table[t[k - 1][i] & 0xffu];
    }
}

/* The CRC of n more bytes; t: crc_slices' tables, or NULL (a byte at a
   time). */
static uint32_t crc32_sliced(const uint32_t (*t)[256], uint32_t crc, const unsigned char *p,
                             size_t n)
{
    crc = ~crc;
    if (t)
        for (; n >= 8; n -= 8, p += 8) {
            uint32_t a = crc ^ ((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
                                (uint32_t)p[3] << 24);
            crc = t[7][a & 0xffu] ^ t[6][(a >> 8) & 0xffu] ^ t[5][(a >> 16) & 0xffu] ^
                  t[4][a >> 24] ^ t[3][p[4]] ^ t[2][p[5]] ^ t[1][p[6]] ^ t[0][p[7]];
        }
    while (n--)
        crc = crc_table[(crc ^ *p++) & 0xffu] ^ (crc >> 8);
    return ~crc;
}

static uint32_t crc32_update(uint32_t crc, const unsigned char *p, size_t n)
{
    if (n >= CRC_SLICE_MIN) {
        uint32_t t[8][256];
        crc_slices(t);
        return crc32_sliced((const uint32_t(*)[256])t, crc, p, n);
    }
    return crc32_sliced(NULL, crc, p, n);
}

/* ------------------------------------------------------------ writing */

typedef struct buf {
    const rtp_allocator *a;
    unsigned char *p;
    size_t n, cap;
    int bad;
} buf;

static void put(buf *b, const void *src, size_t n)
{
    if (b->bad || n == 0)
        return;
    if (rtpi_grow(b->a, (void **)&b->p, &b->cap, b->n + n, 1)) {
        b->bad = 1;
        return;
    }
    memcpy(b->p + b->n, src, n);
    b->n += n;
}

static void put_u8(buf *b, unsigned v)
{
    unsigned char c = (unsigned char)v;
    put(b, &c, 1);
}

static void le32(unsigned char *c, uint32_t v)
{
    c[0] = (unsigned char)v;
    c[1] = (unsigned char)(v >> 8);
    c[2] = (unsigned char)(v >> 16);
    c[3] = (unsigned char)(v >> 24);
}

static void put_u32(buf *b, uint32_t v)
{
    unsigned char c[4];
    le32(c, v);
    put(b, c, 4);
}

static void put_u64(buf *b, uint64_t v)
{
    put_u32(b, (uint32_t)v);
    put_u32(b, (uint32_t)(v >> 32));
}

static void put_f32(buf *b, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    put_u32(b, u);
}

static void put_f64(buf *b, double d)
{
    uint64_t u;
    memcpy(&u, &d, 8);
    put_u64(b, u);
}

static void put_str(buf *b, const char *s)
{
    size_t n = s ? strlen(s) : 0;
    if (n > MAX_NAME)
        n = MAX_NAME;
    put_u8(b, (unsigned)n);
    if (n)
        put(b, s, n);
}

/* The file is written as it is made, through a buffer of SINK_CHUNK
   bytes: a section's CRC is summed over its bytes as they pass (from
   crc_at on), so that neither the file nor a section's body is held
   whole (a 1024x1024 tree of 60 MB was built in memory, copied into the
   file's image and written: twice its size in fresh memory, 0.7 s of a
   1.8 s `trace -o` on mount at 1024x1024).  Small sections are made in a
   buf first (their length heads them); TREE's length is counted first
   and its body streamed. */
#define SINK_CHUNK ((size_t)1 << 16)

typedef struct sink {
    FILE *f;
    unsigned char *p;        /* SINK_CHUNK bytes */
    size_t n;                /* bytes in p */
    size_t crc_at;           /* p's bytes from here on are the section's */
    int in_section;
    uint32_t crc;            /* the section's CRC so far */
    unsigned long long total; /* bytes put */
    int bad;                 /* a write failed (errno kept in err) */
    int err;
    uint32_t slices[8][256]; /* crc_slices', made once a file */
} sink;

static void sink_flush(sink *k)
{
    if (k->in_section)
        k->crc = crc32_sliced((const uint32_t(*)[256])k->slices, k->crc, k->p + k->crc_at,
                              k->n - k->crc_at);
    if (!k->bad && k->n && fwrite(k->p, 1, k->n, k->f) != k->n) {
        k->bad = 1;
        k->err = errno;
    }
    k->n = 0;
    k->crc_at = 0;
}

static void sink_put(sink *k, const void *src, size_t n)
{
    const unsigned char *c = (const unsigned char *)src;
    k->total += n;
    while (n) {
        size_t m = SINK_CHUNK - k->n;
        if (m > n)
            m = n;
        memcpy(k->p + k->n, c, m);
        k->n += m;
        c += m;
        n -= m;
        if (k->n == SINK_CHUNK)
            sink_flush(k);
    }
}

/* Room for m more bytes at k->p + k->n (m <= SINK_CHUNK). */
static unsigned char *sink_room(sink *k, size_t m)
{
    if (SINK_CHUNK - k->n < m)
        sink_flush(k);
    return k->p + k->n;
}

/* m bytes written at sink_room's pointer are in. */
static void sink_advance(sink *k, size_t m)
{
    k->n += m;
    k->total += m;
}

static void sink_u32(sink *k, uint32_t v)
{
    le32(sink_room(k, 4), v);
    sink_advance(k, 4);
}

/* A section's head: tag and body length; the CRC runs from the tag. */
static void sink_begin(sink *k, const char *tag, uint64_t len)
{
    unsigned char c[12];
    memcpy(c, tag, 4);
    le32(c + 4, (uint32_t)len);
    le32(c + 8, (uint32_t)(len >> 32));
    k->in_section = 1;
    k->crc = 0;
    k->crc_at = k->n;
    sink_put(k, c, 12);
}

/* ...and its end: the CRC of tag, length and body. */
static void sink_end(sink *k)
{
    k->crc = crc32_sliced((const uint32_t(*)[256])k->slices, k->crc, k->p + k->crc_at,
                          k->n - k->crc_at);
    k->in_section = 0;
    sink_u32(k, k->crc);
    k->crc_at = k->n;
}

/* Appends section `tag` holding body to out (a buf: the sections before
   TREE are made whole first, so that running out of memory writes
   nothing): tag, length, body, CRC of tag+length+body. */
static void put_section(buf *out, const char *tag, const buf *body)
{
    size_t start = out->n;
    put(out, tag, 4);
    put_u64(out, body->n);
    put(out, body->p, body->n);
    if (!out->bad)
        put_u32(out, crc32_update(0, out->p + start, out->n - start));
    if (body->bad)
        out->bad = 1;
}

static void body_reset(buf *b)
{
    b->n = 0;
}

/* Which node fields the file carries: what the scene can use. */
#define NODE_VIS 1u      /* light bits (the scene has lights) */
#define NODE_LINK32 2u   /* full link word (some surface reflects or
                            transmits); else one byte of flags */

static unsigned node_layout(const rtp_tree *t)
{
    unsigned layout = 0;
    size_t i;
    if (t->scene->nlights > 0 && t->vis_words == 0)
        layout |= NODE_VIS;
    for (i = 0; i < t->nnodes; i++)
        if (t->nodes[i].link & ~0xffu) {
            layout |= NODE_LINK32;
            break;
        }
    return layout;
}

/* The bytes of v as TREE writes it: 7 bits a byte, low first, the top
   bit set on every byte but the last. */
static size_t varint_len(uint64_t v)
{
    size_t n = 1;
    while (v >= 0x80) {
        v >>= 7;
        n++;
    }
    return n;
}

/* Format 2 packs each node against nodes it is likely to resemble
   (tree-format.md, "Packed nodes"): a neighbouring sample's tree mostly
   has the same shape and hits the same surface a little further on.  A
   is the node at the same place in the previous sample's tree, else the
   node before it in its own; B, where A is the previous sample's, the
   node at that place in the sample before (the position is predicted as
   2A - B on the coordinates' bit patterns, linear along a surface).
   NULL: none. */
static RTPI_FORCE_INLINE void refs_in(const rtpi_cnode *nodes, const uint64_t *start, size_t k,
                                      size_t j, const rtpi_cnode **a, const rtpi_cnode **b)
{
    *a = *b = NULL;
    if (k >= 1 && start[k] - start[k - 1] > j) {
        *a = &nodes[start[k - 1] + j];
        if (k >= 2 && start[k - 1] - start[k - 2] > j)
            *b = &nodes[start[k - 2] + j];
    } else if (j > 0) {
        *a = &nodes[start[k] + j - 1];
    }
}

static RTPI_FORCE_INLINE void node_refs(const rtp_tree *t, size_t k, size_t j,
                                        const rtpi_cnode **a, const rtpi_cnode **b)
{
    refs_in(t->nodes, t->start, k, j, a, b);
}

/* The most bytes a packed node takes: six 32-bit varints. */
#define PACKED_MAX 30

/* The most nodes (of a band, or of the trees) whose samples' PACKED_MAX
   bytes a node may be asked for at once (read_bands' fast path): n *
   PACKED_MAX within a size_t. */
#define SAMPLE_FAST_MAX ((size_t)-1 / PACKED_MAX)

static uint32_t f32_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    return u;
}

/* The prediction of coordinate i of a node from its references. */
static uint32_t pos_pred(const rtpi_cnode *a, const rtpi_cnode *b, int i)
{
    if (!a)
        return 0;
    if (!b)
        return f32_bits(a->p[i]);
    return 2u * f32_bits(a->p[i]) - f32_bits(b->p[i]); /* (mod 2^32) */
}

/* v as 7 bits a byte, low first, the top bit set on every byte but the
   last (at most 5 bytes); returns the bytes written. */
static size_t put_v32(unsigned char *c, uint32_t v)
{
    size_t n = 0;
    while (v >= 0x80) {
        c[n++] = (unsigned char)((v & 0x7f) | 0x80u);
        v >>= 7;
    }
    c[n++] = (unsigned char)v;
    return n;
}

/* A difference mod 2^32 as a small number when it is small either way
   (0, -1, 1, -2 ... as 0, 1, 2, 3 ...). */
static uint32_t zigzag(uint32_t d)
{
    return (d << 1) ^ (0u - (d >> 31));
}

static uint32_t unzigzag(uint32_t z)
{
    return (z >> 1) ^ (0u - (z & 1u));
}

/* Node n packed against its references into c (PACKED_MAX bytes of
   room); returns the bytes written. */
static size_t pack_node(const rtpi_cnode *n, const rtpi_cnode *a, const rtpi_cnode *b,
                        unsigned layout, unsigned char *c)
{
    size_t at = 0;
    int i;
    for (i = 0; i < 3; i++)
        at += put_v32(c + at, zigzag(f32_bits(n->p[i]) - pos_pred(a, b, i)));
    at += put_v32(c + at, zigzag(n->prim - (a ? a->prim : 0u)));
    if (layout & NODE_VIS)
        at += put_v32(c + at, n->vis ^ (a ? a->vis : 0u));
    if (layout & NODE_LINK32)
        at += put_v32(c + at, n->link ^ (a ? a->link : 0u));
    else
        c[at++] = (unsigned char)((n->link ^ (a ? a->link : 0u)) & 0xffu);
    return at;
}

/* A 32-bit varint from c (avail bytes): the bytes it took, 0 when they
   ran out first, or (size_t)-1 when it is not one (more than 5 bytes, or
   bits beyond 32). */
static RTPI_FORCE_INLINE size_t get_v32(const unsigned char *c, size_t avail, uint32_t *v)
{
    uint32_t x = 0;
    size_t i;
    if (avail && c[0] < 0x80u) { /* (most: light bits, links, primitives) */
        *v = c[0];
        return 1;
    }
    for (i = 0; i < 5; i++) {
        if (i >= avail)
            return 0;
        x |= (uint32_t)(c[i] & 0x7fu) << (7 * i);
        if (!(c[i] & 0x80u)) {
            if (i == 4 && c[i] > 0x0fu)
                return (size_t)-1;
            *v = x;
            return i + 1;
        }
    }
    return (size_t)-1;
}

/* get_v32 where 5 bytes are there: unrolled, no count of them (reading
   the trees, most numbers).  A number that is not one sets *bad (it is
   taken as 5 bytes then, so that the node's next numbers are still read
   within its PACKED_MAX: unpack_node refuses it once they are). */
static RTPI_FORCE_INLINE size_t get_v32_5(const unsigned char *c, uint32_t *v, unsigned *bad)
{
    uint32_t x = c[0];
    if (x < 0x80u) {
        *v = x;
        return 1;
    }
    x = (x & 0x7fu) | (uint32_t)c[1] << 7;
    if (c[1] < 0x80u) {
        *v = x;
        return 2;
    }
    x = (x & 0x3fffu) | (uint32_t)c[2] << 14;
    if (c[2] < 0x80u) {
        *v = x;
        return 3;
    }
    x = (x & 0x1fffffu) | (uint32_t)c[3] << 21;
    if (c[3] < 0x80u) {
        *v = x;
        return 4;
    }
    *bad |= c[4] > 0x0fu;
    *v = (x & 0xfffffffu) | (uint32_t)c[4] << 28;
    return 5;
}

/* Whether the float of bit pattern u is infinite or NaN (its exponent's
   bits all set): isfinite without the float. */
static RTPI_FORCE_INLINE unsigned f32_bits_nonfinite(uint32_t u)
{
    return (u & 0x7f800000u) == 0x7f800000u;
}

/* Node n from its numbers v (layout's: positions, primitive, light bits
   or 0, link) against its references a and b (never NULL: where
   node_refs gives none, a node of zeros for A, and A itself for B, make
   the same predictions, 2A - A being A); returns 1 when a position is
   not finite. */
static RTPI_FORCE_INLINE unsigned node_from(const uint32_t *v, const rtpi_cnode *a,
                                            const rtpi_cnode *b, unsigned layout, rtpi_cnode *n)
{
    /* (the prediction 2A - B on the bit patterns, mod 2^32) */
    uint32_t u0 = unzigzag(v[0]) + 2u * f32_bits(a->p[0]) - f32_bits(b->p[0]);
    uint32_t u1 = unzigzag(v[1]) + 2u * f32_bits(a->p[1]) - f32_bits(b->p[1]);
    uint32_t u2 = unzigzag(v[2]) + 2u * f32_bits(a->p[2]) - f32_bits(b->p[2]);
    memcpy(&n->p[0], &u0, 4);
    memcpy(&n->p[1], &u1, 4);
    memcpy(&n->p[2], &u2, 4);
    n->prim = unzigzag(v[3]) + a->prim;
    n->vis = v[4] ^ a->vis;
    n->link = v[5] ^ a->link;
    if (!(layout & NODE_LINK32))
        n->link &= 0xffu;
    return f32_bits_nonfinite(u0) | f32_bits_nonfinite(u1) | f32_bits_nonfinite(u2);
}

/* unpack_node where PACKED_MAX bytes are there (every number has its 5):
   the numbers read one after the other, a malformed one, or a position
   not finite, setting *bad (the node is refused once they are read);
   returns the bytes taken. */
static RTPI_FORCE_INLINE size_t unpack_node_30(const unsigned char *c, const rtpi_cnode *a,
                                               const rtpi_cnode *b, unsigned layout,
                                               rtpi_cnode *n, unsigned *bad)
{
    size_t at;
    uint32_t v[6];
    at = get_v32_5(c, &v[0], bad);
    at += get_v32_5(c + at, &v[1], bad);
    at += get_v32_5(c + at, &v[2], bad);
    at += get_v32_5(c + at, &v[3], bad);
    v[4] = 0;
    if (layout & NODE_VIS)
        at += get_v32_5(c + at, &v[4], bad);
    if (layout & NODE_LINK32)
        at += get_v32_5(c + at, &v[5], bad);
    else
        v[5] = c[at++];
    *bad |= node_from(v, a, b, layout, n);
    return at;
}

/* Sample k's references (refs_in's, from the sample's neighbours once,
   not their starts a node): A the previous sample's node j while j < *na,
   else the node before; B the sample before's while j < *nb (<= *na),
   else A. */
static RTPI_FORCE_INLINE void sample_refs(const rtpi_cnode *nodes, const uint64_t *start, size_t k,
                                          const rtpi_cnode **pa, size_t *na,
                                          const rtpi_cnode **pb, size_t *nb)
{
    *pa = *pb = nodes;
    *na = *nb = 0;
    if (k >= 1) {
        *pa = nodes + start[k - 1];
        *na = (size_t)(start[k] - start[k - 1]);
        if (k >= 2) {
            *pb = nodes + start[k - 2];
            *nb = (size_t)(start[k - 1] - start[k - 2]);
            *nb = *nb < *na ? *nb : *na;
        }
    }
}

/* A sample's n packed nodes into nd, from p where n PACKED_MAX bytes are
   there (none is short, so every error is an invalid node: a node after
   an invalid one is read within the bytes and not used), against the
   references sample_refs gives (zero: A where none); returns the bytes
   taken, 0 where a node is invalid. */
static RTPI_FORCE_INLINE size_t unpack_sample_30(const unsigned char *p, size_t n,
                                                 const rtpi_cnode *pa, size_t na,
                                                 const rtpi_cnode *pb, size_t nb,
                                                 const rtpi_cnode *zero, unsigned layout,
                                                 size_t nprims, uint32_t vis_mask,
                                                 rtpi_cnode *nd)
{
    const unsigned char *p0 = p;
    unsigned invalid = 0;
    size_t j;
    for (j = 0; j < n; j++, nd++) {
        const rtpi_cnode *ra = j < na ? pa + j : j ? nd - 1 : zero;
        const rtpi_cnode *rb = j < nb ? pb + j : ra;
        p += unpack_node_30(p, ra, rb, layout, nd, &invalid);
        invalid |= (nd->prim >= nprims) | ((nd->vis & ~vis_mask) != 0);
    }
    return invalid ? 0 : (size_t)(p - p0);
}

/* Node n unpacked from c (avail bytes) against its references a and b
   (node_from's): the bytes it took, 0 when they ran out first,
   (size_t)-1 when malformed (a number that is not one, or a position
   not finite). */
static RTPI_FORCE_INLINE size_t unpack_node(const unsigned char *c, size_t avail,
                                            const rtpi_cnode *a, const rtpi_cnode *b,
                                            unsigned layout, rtpi_cnode *n)
{
    size_t at = 0, k;
    uint32_t v[6];
    int i, nv = 4 + ((layout & NODE_VIS) != 0) + ((layout & NODE_LINK32) != 0);
    if (avail >= PACKED_MAX) {
        unsigned bad = 0;
        at = unpack_node_30(c, a, b, layout, n, &bad);
        return bad ? (size_t)-1 : at;
    }
    for (i = 0; i < nv; i++) {
        k = get_v32(c + at, avail - at, &v[i]);
        if (k == 0 || k == (size_t)-1)
            return k;
        at += k;
    }
    if (!(layout & NODE_VIS)) {
        if (layout & NODE_LINK32)
            v[5] = v[4];
        v[4] = 0;
    }
    if (!(layout & NODE_LINK32)) {
        if (at >= avail)
            return 0;
        v[5] = c[at++];
    }
    return node_from(v, a, b, layout, n) ? (size_t)-1 : at;
}

/* Format 2's geometry (tree-format.md, GEOM): each number (the 32 bits
   of an f32, or a u32) as a zigzag varint of its difference from *prev,
   the same number of the group before, which it then becomes. */
static void put_delta(buf *b, uint32_t *prev, uint32_t x)
{
    unsigned char e[5];
    put(b, e, put_v32(e, zigzag(x - *prev)));
    *prev = x;
}

/* n groups of `stride` (at most 3) floats so. */
static void put_packed_f32(buf *b, const float *f, size_t n, int stride)
{
    uint32_t prev[3] = {0, 0, 0};
    size_t i;
    int c;
    for (i = 0; i < n; i++)
        for (c = 0; c < stride; c++)
            put_delta(b, &prev[c], f32_bits(f[i * (size_t)stride + (size_t)c]));
}

/* The byte k whose k / 255 (as float, as the 8-bit image readers make
   texels) is exactly v, or -1. */
static int texel_byte(float v)
{
    long k;
    if (!(v >= 0.0f && v <= 1.0f))
        return -1;
    k = lrintf(v * 255.0f);
    return (float)k / 255.0f == v ? (int)k : -1;
}

/* Textures a material uses now (an image texture, an image bump map)
   or was traced with (an image bump map) get the file's indices 0, 1,
   ... in order (remap[i]); the others are RTPI_NONE, left out of the
   file (a texture replaced or turned off took 12 bytes a texel still, a
   1024x1024 one 12.6 MB).  *used: their count; NULL when out of memory. */
static uint32_t *texture_remap(const rtp_tree *t, uint32_t *used)
{
    const rtp_scene *s = t->scene;
    uint32_t *remap = (uint32_t *)rtpi_malloc_array(&t->alloc, s->ntexs + 1, sizeof *remap);
    size_t i, m;
    *used = 0;
    if (!remap)
        return NULL;
    for (i = 0; i < s->ntexs; i++)
        remap[i] = RTPI_NONE;
    for (m = 0; m < s->nmats; m++) {
        const rtpi_material *mt = &s->mats[m], *m0 = &t->mats0[m];
        if (mt->tex == RTPI_TEX_IMAGE && mt->tex_image < s->ntexs)
            remap[mt->tex_image] = 0;
        if (mt->bump == RTPI_BUMP_IMAGE && mt->bump_image < s->ntexs)
            remap[mt->bump_image] = 0;
        /* the bump map the trees were traced with, too: a bump set back
           to it must read back as unchanged (its index left out, the
           trees read back as stale) */
        if (m0->bump == RTPI_BUMP_IMAGE && m0->bump_image < s->ntexs)
            remap[m0->bump_image] = 0;
    }
    for (i = 0; i < s->ntexs; i++)
        if (remap[i] == 0)
            remap[i] = (*used)++;
    return remap;
}

/* Index i in the file: its new place, or RTPI_NONE (not in use). */
static uint32_t tex_index(const uint32_t *remap, size_t ntexs, int in_use, uint32_t i)
{
    return in_use && i < ntexs ? remap[i] : RTPI_NONE;
}

/* The section TEXB (bytes 1) or TEXR of the textures in use, its body
   len bytes, streamed through the sink (no memory is taken). */
static void write_textures(sink *out, const rtp_scene *s, const uint32_t *remap,
                           uint32_t used, int bytes, uint64_t len)
{
    size_t i, k;
    sink_begin(out, bytes ? "TEXB" : "TEXR", len);
    sink_u32(out, used);
    for (i = 0; i < s->ntexs; i++) {
        const rtp_image *img = s->texs[i].image;
        const char *name = s->texs[i].path;
        size_t n, nm = name ? strlen(name) : 0;
        unsigned char c;
        if (remap[i] == RTPI_NONE)
            continue;
        nm = nm > MAX_NAME ? MAX_NAME : nm; /* (as put_str) */
        c = (unsigned char)nm;
        sink_put(out, &c, 1);
        sink_put(out, name, nm);
        sink_u32(out, (uint32_t)img->width);
        sink_u32(out, (uint32_t)img->height);
        n = (size_t)img->width * img->height * 3;
        for (k = 0; k < n; k++) {
            if (bytes) {
                *sink_room(out, 1) = (unsigned char)texel_byte(img->pixels[k]);
                sink_advance(out, 1);
            } else {
                uint32_t u;
                memcpy(&u, &img->pixels[k], 4);
                sink_u32(out, u);
            }
        }
    }
    sink_end(out);
}

static rtp_status serialize(const rtp_tree *t, sink *out)
{
    const rtp_scene *s = t->scene;
    buf b;
    size_t i, k, ns = (size_t)t->nx * t->ny;
    uint64_t len;
    unsigned layout = node_layout(t);
    buf head; /* the file up to the textures */
    buf tail; /* after them, up to TREE */
    int tex_bytes = 1;
    uint64_t tex_len = 0;
    uint32_t ntex_used, *remap = texture_remap(t, &ntex_used);
    if (!remap)
        return RTP_ERR_NOMEM;
    memset(&b, 0, sizeof b);
    b.a = &t->alloc;
    memset(&head, 0, sizeof head);
    head.a = &t->alloc;

    put(&head, signature, 8);
    /* header: version, then a fixed block with its own CRC */
    body_reset(&b);
    put_u32(&b, (uint32_t)FMT_MAJOR);
    put_u32(&b, (uint32_t)FMT_MINOR);
    put_u32(&b, (uint32_t)t->width);
    put_u32(&b, (uint32_t)t->height);
    put_u32(&b, (uint32_t)t->nx);
    put_u32(&b, (uint32_t)t->ny);
    put_u32(&b, (uint32_t)t->spd);
    put_u32(&b, (uint32_t)t->max_depth);
    put_f64(&b, t->min_weight);
    put_u32(&b, (uint32_t)t->full_w);
    put_u32(&b, (uint32_t)t->full_h);
    put_u32(&b, (uint32_t)t->rx);
    put_u32(&b, (uint32_t)t->ry);
    put_section(&head, "HEAD", &b);

    body_reset(&b);
    for (k = 0; k < 3; k++)
        put_f64(&b, s->camera.from[k]);
    for (k = 0; k < 3; k++)
        put_f64(&b, s->camera.at[k]);
    for (k = 0; k < 3; k++)
        put_f64(&b, s->camera.up[k]);
    put_f64(&b, s->camera.angle);
    put_f64(&b, s->camera.hither);
    for (k = 0; k < 3; k++)
        put_f32(&b, s->background[k]);
    for (k = 0; k < 3; k++)
        put_f32(&b, s->ambient[k]);
    put_f64(&b, s->light_scale);
    put_section(&head, "SCEN", &b);

    body_reset(&b);
    put_u32(&b, (uint32_t)s->nmats);
    for (i = 0; i < s->nmats; i++) {
        const rtpi_material *m = &s->mats[i], *m0 = &t->mats0[i];
        for (k = 0; k < 3; k++)
            put_f32(&b, m->color[k]);
        put_f32(&b, m->kd);
        put_f32(&b, m->ks);
        put_f32(&b, m->shine);
        put_f32(&b, m->kt);
        put_f32(&b, m->ior);
        put_u8(&b, (unsigned)m->tex);
        for (k = 0; k < 3; k++)
            put_f32(&b, m->color2[k]);
        put_f32(&b, m->tex_scale);
        put_u32(&b, tex_index(remap, s->ntexs, m->tex == RTPI_TEX_IMAGE, m->tex_image));
        put_u8(&b, (unsigned)m->bump);
        put_u32(&b, tex_index(remap, s->ntexs, m->bump == RTPI_BUMP_IMAGE, m->bump_image));
        put_f32(&b, m->bump_strength);
        put_f32(&b, m->bump_scale);
        put_str(&b, m->name);
        /* as traced: what decides which edits the trees can evaluate */
        put_f32(&b, m0->ks);
        put_f32(&b, m0->kt);
        put_f32(&b, m0->ior);
        /* (compared with bump_image only; its image is kept in the file) */
        put_u8(&b, (unsigned)m0->bump);
        put_u32(&b, tex_index(remap, s->ntexs, m0->bump == RTPI_BUMP_IMAGE, m0->bump_image));
        put_f32(&b, m0->bump_strength);
        put_f32(&b, m0->bump_scale);
    }
    put_section(&head, "MATL", &b);

    /* MAMB, the ambient coefficients of the materials that have their own
       (mat.N.ambient, NFF's ka), only where one has: a scene without
       them writes today's bytes, and a reader older than the section
       refuses it by name (a required tag) rather than take ka for kd */
    for (i = 0, k = 0; i < s->nmats; i++)
        k += s->mats[i].ka_set != 0;
    if (k) {
        body_reset(&b);
        put_u32(&b, (uint32_t)k);
        for (i = 0; i < s->nmats; i++) {
            const rtpi_material *m = &s->mats[i];
            if (!m->ka_set)
                continue;
            put_u32(&b, (uint32_t)i);
            for (k = 0; k < 3; k++)
                put_f32(&b, m->ka[k]);
        }
        put_section(&head, "MAMB", &b);
    }

    body_reset(&b);
    put_u32(&b, (uint32_t)s->nlights);
    for (i = 0; i < s->nlights; i++) {
        const rtpi_light *l = &s->lights[i];
        for (k = 0; k < 3; k++)
            put_f64(&b, l->pos[k]);
        for (k = 0; k < 3; k++)
            put_f32(&b, l->color[k]);
        put_u8(&b, l->on ? 1u : 0u);
        put_str(&b, l->name);
        for (k = 0; k < 3; k++)
            put_f64(&b, t->lights0[i].pos[k]);
    }
    put_section(&head, "LITE", &b);

    if (ntex_used) {
        /* TEXB, a byte a texel, where every texel of every texture in use
           is one of an 8-bit image's (k / 255 as the image readers make
           it: the byte gives back the very float); else TEXR, four.  Its
           length is counted here and its body streamed after the
           sections before it (write_textures): made whole in a buf and
           then copied into head, as the small sections are, a 4096x4096
           bump map's 50 MB took 300 MB of fresh memory and 2.3 s of a
           `trace -o` (0.55 s without -o) */
        tex_bytes = 1;
        tex_len = 4;
        for (i = 0; i < s->ntexs; i++) {
            const rtp_image *img = s->texs[i].image;
            size_t n = remap[i] != RTPI_NONE ? (size_t)img->width * img->height * 3 : 0;
            for (k = 0; tex_bytes && k < n; k++)
                tex_bytes = texel_byte(img->pixels[k]) >= 0;
        }
        for (i = 0; i < s->ntexs; i++) {
            const char *name = s->texs[i].path;
            size_t nm = name ? strlen(name) : 0;
            if (remap[i] == RTPI_NONE)
                continue;
            tex_len += 1 + (nm > MAX_NAME ? MAX_NAME : nm) + 8 +
                       (uint64_t)s->texs[i].image->width * s->texs[i].image->height * 3 *
                           (tex_bytes ? 1 : 4);
        }
    }

    /* the sections after the textures: made whole before anything is
       written, as those before them */
    memset(&tail, 0, sizeof tail);
    tail.a = &t->alloc;
    body_reset(&b);
    put_u32(&b, (uint32_t)s->npos);
    put_packed_f32(&b, s->pos, s->npos, 3);
    put_u32(&b, (uint32_t)s->nnrm);
    put_packed_f32(&b, s->nrm, s->nnrm, 3);
    put_u32(&b, (uint32_t)s->nuv);
    put_packed_f32(&b, s->uv, s->nuv, 2);
    put_u32(&b, (uint32_t)s->ntris);
    {
        uint32_t prev[10] = {0};
        for (i = 0; i < s->ntris; i++) {
            const rtpi_tri *tr = &s->tris[i];
            for (k = 0; k < 3; k++)
                put_delta(&b, &prev[k], tr->v[k]);
            for (k = 0; k < 3; k++)
                put_delta(&b, &prev[3 + k], tr->n[k]);
            for (k = 0; k < 3; k++)
                put_delta(&b, &prev[6 + k], tr->t[k]);
            put_delta(&b, &prev[9], tr->mat);
        }
    }
    put_u32(&b, (uint32_t)s->nspheres);
    for (i = 0; i < s->nspheres; i++) {
        for (k = 0; k < 4; k++)
            put_f32(&b, k < 3 ? s->spheres[i].c[k] : s->spheres[i].r);
        put_u32(&b, s->spheres[i].mat);
    }
    put_u32(&b, (uint32_t)s->ncones);
    for (i = 0; i < s->ncones; i++) {
        const rtpi_cone *c = &s->cones[i];
        for (k = 0; k < 3; k++)
            put_f32(&b, c->base[k]);
        put_f32(&b, c->rb);
        for (k = 0; k < 3; k++)
            put_f32(&b, c->apex[k]);
        put_f32(&b, c->ra);
        put_u32(&b, c->mat);
    }
    put_section(&tail, "GEOM", &b);

    rtpi_free(b.a, b.p);
    if (head.bad || tail.bad) {
        rtpi_free(&t->alloc, remap);
        rtpi_free(head.a, head.p);
        rtpi_free(tail.a, tail.p);
        return RTP_ERR_NOMEM;
    }
    sink_put(out, head.p, head.n);
    rtpi_free(head.a, head.p);
    if (ntex_used)
        write_textures(out, s, remap, ntex_used, tex_bytes, tex_len);
    rtpi_free(&t->alloc, remap);
    sink_put(out, tail.p, tail.n);
    rtpi_free(tail.a, tail.p);
    /* An empty extension: the trees hold a renderer's own hits
       (rtp_builder_*), which class C/D re-traces replace whole, not
       below the edited materials alone (tree.c retrace_edited); a reader
       that does not know it skips it, and re-traces whole samples. */
    if (t->foreign) {
        sink_begin(out, "frgn", 0);
        sink_end(out);
    }
    /* TREE, streamed: its length first (the nodes packed once to count
       their bytes) */
    len = 8 + 8 + 4 + 1 + (uint64_t)t->nnodes * t->vis_words * 4;
    for (k = 0; k < ns; k++) {
        size_t j, n = (size_t)(t->start[k + 1] - t->start[k]);
        unsigned char c[PACKED_MAX];
        len += varint_len(n);
        for (j = 0; j < n; j++) {
            const rtpi_cnode *ra, *rb;
            node_refs(t, k, j, &ra, &rb);
            len += pack_node(&t->nodes[t->start[k] + j], ra, rb, layout, c);
        }
    }
    sink_begin(out, "TREE", len);
    sink_u32(out, (uint32_t)ns);
    sink_u32(out, (uint32_t)((uint64_t)ns >> 32));
    sink_u32(out, (uint32_t)t->nnodes);
    sink_u32(out, (uint32_t)((uint64_t)t->nnodes >> 32));
    sink_u32(out, (uint32_t)t->vis_words);
    {
        unsigned char c = (unsigned char)layout;
        sink_put(out, &c, 1);
    }
    for (k = 0; k < ns; k++) {
        uint64_t v = t->start[k + 1] - t->start[k];
        unsigned char *c = sink_room(out, 10), *c0 = c;
        while (v >= 0x80) {
            *c++ = (unsigned char)((v & 0x7f) | 0x80u);
            v >>= 7;
        }
        *c++ = (unsigned char)v;
        sink_advance(out, (size_t)(c - c0));
    }
    for (k = 0; k < ns; k++) {
        size_t j, n = (size_t)(t->start[k + 1] - t->start[k]);
        for (j = 0; j < n; j++) {
            const rtpi_cnode *ra, *rb;
            unsigned char *c = sink_room(out, PACKED_MAX);
            node_refs(t, k, j, &ra, &rb);
            sink_advance(out, pack_node(&t->nodes[t->start[k] + j], ra, rb, layout, c));
        }
    }
    for (i = 0; i < t->nnodes * t->vis_words; i++)
        sink_u32(out, t->vis_ext[i]);
    sink_end(out);

    sink_begin(out, "END ", 0);
    sink_end(out);
    sink_flush(out);
    return RTP_OK;
}

rtp_status rtp_tree_write(const rtp_tree *t, const char *path,
                          unsigned long long *bytes, rtp_error *err)
{
    sink out;
    rtp_status st = RTP_OK;
    char *tmp = NULL, *target = NULL;
    int to_stdout, special, kind;
    if (!t || !path)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "rtp_tree_write: NULL argument");
    if (t->busy)
        return rtpi_tree_busy(t, "rtp_tree_write", err);
    if (t->scene->nlights != t->nlights0)
        return rtpi_error(err, RTP_ERR_UNSUPPORTED, path, 0, 0,
                          "a tree with added lights cannot be saved: its trees hold no "
                          "shadows for them; trace again with the lights in the scene");
    if (memcmp(&t->scene->camera, &t->cam0, sizeof t->cam0) != 0)
        return rtpi_error(err, RTP_ERR_UNSUPPORTED, path, 0, 0,
                          "the camera was edited since the trees were traced: evaluate the "
                          "tree (which traces them again) before saving it");
    /* (what rtp_tree_read takes: a larger tree would be written, and
       then refused) */
    if ((uint64_t)t->nnodes > MAX_COUNT ||
        (t->vis_words && (uint64_t)t->nnodes * t->vis_words > MAX_COUNT))
        return rtpi_error(err, RTP_ERR_LIMIT, path, 0, 0,
                          "%zu nodes%s: a tree file holds at most %u", t->nnodes,
                          t->vis_words ? " (times their light words)" : "", MAX_COUNT);
    memset(&out, 0, sizeof out);
    crc_slices(out.slices);
    out.p = (unsigned char *)rtpi_malloc(&t->alloc, SINK_CHUNK);
    if (!out.p)
        return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory writing tree file");
    kind = strcmp(path, "-") == 0 ? RTPI_WRITE_STDOUT : rtpi_write_kind(path);
    to_stdout = kind == RTPI_WRITE_STDOUT;
    special = kind == RTPI_WRITE_IN_PLACE || kind == RTPI_WRITE_APPEND;
    /* (through a symbolic link: the file it names) */
    if (kind == RTPI_WRITE_FILE &&
        (st = rtpi_write_target(&t->alloc, path, &target, err)) != RTP_OK) {
        rtpi_free(&t->alloc, out.p);
        return st;
    }
    if (to_stdout) {
        out.f = stdout;
    } else if (special) {
        /* a FIFO or a device: written in place; another open file's
           /proc/self/fd name: appended to */
        out.f = fopen(path, kind == RTPI_WRITE_APPEND ? "ab" : "wb");
        if (!out.f) {
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot write: %s", strerror(errno));
            rtpi_free(&t->alloc, out.p);
            rtpi_free(&t->alloc, target);
            return st;
        }
    } else {
        /* written beside the file under a name of its own (two writers
           of one path once shared ".tmp-rtp" and left a corrupt file)
           and renamed into place once whole: a failed write leaves no
           half file and an old file as it was */
        size_t n = strlen(target) + 32;
        tmp = (char *)rtpi_malloc(&t->alloc, n);
        if (!tmp) {
            rtpi_free(&t->alloc, out.p);
            rtpi_free(&t->alloc, target);
            return rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory");
        }
        out.f = rtpi_open_temp(target, tmp, n);
        if (!out.f) {
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0,
                            "cannot create a temporary file beside it: %s", strerror(errno));
            rtpi_free(&t->alloc, tmp);
            rtpi_free(&t->alloc, out.p);
            rtpi_free(&t->alloc, target);
            return st;
        }
    }
    if (serialize(t, &out) != RTP_OK)
        st = rtpi_error(err, RTP_ERR_NOMEM, path, 0, 0, "out of memory writing tree file");
    else if (out.bad || fflush(out.f) != 0)
        st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "write failed: %s",
                        strerror(out.bad ? out.err : errno));
    if (special) {
        if (fclose(out.f) != 0 && st == RTP_OK)
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "write failed: %s", strerror(errno));
    } else if (!to_stdout) {
        /* A tree is costly to make again: its bytes are on the disk
           before the rename (else a crash soon after could leave the
           name on an empty file, the old tree gone) and the rename
           after it (the folder synced) */
        int e = st == RTP_OK ? rtpi_sync_file(out.f) : 0;
        if (e)
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "write failed: cannot sync: %s",
                            strerror(e));
        if (fclose(out.f) != 0 && st == RTP_OK)
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "write failed: %s", strerror(errno));
        if (st == RTP_OK && rename(tmp, target) != 0)
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot rename into place: %s",
                            strerror(errno));
        if (st == RTP_OK && (e = rtpi_sync_dir(target)) != 0)
            st = rtpi_error(err, RTP_ERR_IO, path, 0, 0,
                            "written, but its folder cannot be synced: %s", strerror(e));
        if (st != RTP_OK)
            remove(tmp);
        rtpi_free(&t->alloc, tmp);
    }
    if (bytes)
        *bytes = out.total;
    rtpi_free(&t->alloc, out.p);
    rtpi_free(&t->alloc, target);
    return st;
}

/* ------------------------------------------------------------ reading */

/* A section's bytes as the parsers see them: all of them at p (a file
   in memory), or from a source, a window of the file at a time (rd_src:
   the trees' section of a file or pipe rtp_tree_read reads, so that the
   file's bytes and its nodes are never in memory at once). */
typedef struct rd_src {
    FILE *f;
    unsigned char *buf;
    size_t cap;               /* buf's size: the most one need() asks */
    uint64_t left;            /* the section's bytes not yet read */
    uint32_t crc;             /* of the section's bytes read so far */
    int short_read;           /* the file ended (or failed) before them */
    uint32_t slices[8][256];  /* crc_slices' */
} rd_src;

typedef struct rd {
    const unsigned char *p;
    size_t n, at;
    int bad;
    int nul;     /* a string held a NUL byte (get_str) */
    rd_src *src; /* NULL: every byte at p */
} rd;

/* Moves the window's unread bytes to the front of the source's buffer
   and reads the section's next bytes behind them, summing their CRC.
   @return 1 when at least `want` bytes are then in the window. */
static int refill(rd *r, size_t want)
{
    rd_src *s = r->src;
    size_t have = r->n - r->at;
    if (!s || want > s->cap)
        return 0;
    if (have && r->p + r->at != s->buf)
        memmove(s->buf, r->p + r->at, have);
    while (have < want && s->left && !s->short_read) {
        size_t get = s->cap - have, got;
        if (get > s->left)
            get = (size_t)s->left;
        got = fread(s->buf + have, 1, get, s->f);
        s->crc = crc32_sliced((const uint32_t(*)[256])s->slices, s->crc, s->buf + have, got);
        have += got;
        s->left -= got;
        s->short_read = got < get;
    }
    r->p = s->buf;
    r->n = have;
    r->at = 0;
    return have >= want;
}

static int need(rd *r, size_t n)
{
    if (r->bad || (n > r->n - r->at && !refill(r, n))) {
        r->bad = 1;
        return 0;
    }
    return 1;
}

/* The section's bytes not yet parsed. */
static uint64_t rd_left(const rd *r)
{
    return (uint64_t)(r->n - r->at) + (r->src ? r->src->left : 0u);
}

static unsigned get_u8(rd *r)
{
    if (!need(r, 1))
        return 0;
    return r->p[r->at++];
}

static uint32_t get_u32(rd *r)
{
    const unsigned char *c;
    if (!need(r, 4))
        return 0;
    c = r->p + r->at;
    r->at += 4;
    return (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 | (uint32_t)c[3] << 24;
}

static uint64_t get_u64(rd *r)
{
    uint64_t lo = get_u32(r);
    return lo | (uint64_t)get_u32(r) << 32;
}

static float get_f32(rd *r)
{
    uint32_t u = get_u32(r);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static double get_f64(rd *r)
{
    uint64_t u = get_u64(r);
    double d;
    memcpy(&d, &u, 8);
    return d;
}

static uint64_t get_varint(rd *r)
{
    uint64_t v = 0;
    int shift = 0;
    for (;;) {
        unsigned c = get_u8(r);
        if (r->bad)
            return 0;
        if (shift >= 63 && (c & 0x7e)) {
            r->bad = 1;
            return 0;
        }
        v |= (uint64_t)(c & 0x7f) << shift;
        if (!(c & 0x80))
            return v;
        shift += 7;
        if (shift > 63) {
            r->bad = 1;
            return 0;
        }
    }
}

/* A name, or NULL when empty; *bad on allocation failure. */
static char *get_str(rd *r, const rtp_allocator *a, int *nomem)
{
    unsigned n = get_u8(r);
    char *s;
    if (!n || !need(r, n))
        return NULL;
    s = (char *)rtpi_malloc(a, n + 1);
    if (!s) {
        *nomem = 1;
        return NULL;
    }
    memcpy(s, r->p + r->at, n);
    s[n] = '\0';
    r->at += n;
    if (strlen(s) != n) {
        /* a NUL inside: C would cut the name there (no writer puts one) */
        rtpi_free(a, s);
        r->nul = 1;
        return NULL;
    }
    return s;
}

static int finite3(const float *f)
{
    return isfinite(f[0]) && isfinite(f[1]) && isfinite(f[2]);
}

typedef struct loader {
    const char *name;
    rtp_error *err;
    rtp_tree *t;
    rtp_scene *s;
    const rtp_allocator *a;
    const char *section;
    unsigned major; /* the file's format version (HEAD) */
    const rtpi_tree_sink *sink; /* a one-off evaluation's (NULL: none) */
    int sink_stop; /* the sink refused: its error, not the file's */
    int sink_begun; /* the sink's begin was called: its edits are made,
                       the lights as traced are set (nlights0), its end
                       is due */
    int summary; /* rtp_tree_read_summary's: every node checked, none kept */
} loader;

/* what: the message; detail (may be NULL) follows it, then the section
   by its tag without the blanks that pad it to 4 bytes ("in section
   END " had ended the message in a blank). */
static rtp_status bad(loader *L, const char *what, const char *detail)
{
    int n = 0;
    if (L->section)
        for (n = 4; n > 0 && L->section[n - 1] == ' '; n--)
            ;
    return rtpi_error(L->err, RTP_ERR_FORMAT, L->name, 0, 0, "%s%s%s%.*s", what,
                      detail ? detail : "", n ? " in section " : "", n,
                      L->section ? L->section : "");
}

static rtp_status nomem(loader *L)
{
    return rtpi_error(L->err, RTP_ERR_NOMEM, L->name, 0, 0, "out of memory reading tree file");
}

/* Checks a count against what the remaining bytes can hold. */
static int count_ok(const rd *r, uint64_t count, size_t min_bytes_each)
{
    return count <= MAX_COUNT && (min_bytes_each == 0 || count <= rd_left(r) / min_bytes_each);
}

static rtp_status read_head(loader *L, rd *r)
{
    rtp_tree *t = L->t;
    uint32_t major = get_u32(r), minor = get_u32(r);
    char ver[16];
    (void)minor;
    if (r->bad)
        return bad(L, "header too short", NULL);
    /* (1: nodes as fixed fields; 2: packed) */
    if (major < 1 || major > FMT_MAJOR) {
        snprintf(ver, sizeof ver, "%u", (unsigned)major);
        return bad(L, major > FMT_MAJOR ? "written by a newer rtp: format version "
                                       : "unknown format version ", ver);
    }
    L->major = (unsigned)major;
    t->width = (int)get_u32(r);
    t->height = (int)get_u32(r);
    t->nx = (int)get_u32(r);
    t->ny = (int)get_u32(r);
    t->spd = (int)get_u32(r);
    t->max_depth = (int)get_u32(r);
    t->min_weight = get_f64(r);
    t->full_w = (int)get_u32(r);
    t->full_h = (int)get_u32(r);
    t->rx = (int)get_u32(r);
    t->ry = (int)get_u32(r);
    if (r->bad)
        return bad(L, "header too short", NULL);
    if (!rtpi_image_size_ok(t->full_w, t->full_h))
        return bad(L, "frame size over the limit (2^20 a side, 2^27 pixels)", NULL);
    if (t->rx < 0 || t->ry < 0 || t->width > t->full_w - t->rx ||
        t->height > t->full_h - t->ry)
        return bad(L, "region outside the frame", NULL);
    if (!rtpi_image_size_ok(t->width, t->height) || t->spd < 0 || t->spd > 1 ||
        t->nx != t->width + t->spd || t->ny != t->height + t->spd)
        return bad(L, "invalid image or sample size", NULL);
    if (t->max_depth < 1 || t->max_depth > MAX_DEPTH_FILE)
        return bad(L, "invalid maximum depth", NULL);
    if (!(t->min_weight >= 0.0) || !isfinite(t->min_weight))
        return bad(L, "invalid weight cut-off", NULL);
    return RTP_OK;
}

static rtp_status read_scen(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    int k;
    for (k = 0; k < 3; k++)
        s->camera.from[k] = get_f64(r);
    for (k = 0; k < 3; k++)
        s->camera.at[k] = get_f64(r);
    for (k = 0; k < 3; k++)
        s->camera.up[k] = get_f64(r);
    s->camera.angle = get_f64(r);
    s->camera.hither = get_f64(r);
    for (k = 0; k < 3; k++)
        s->background[k] = get_f32(r);
    for (k = 0; k < 3; k++)
        s->ambient[k] = get_f32(r);
    s->light_scale = get_f64(r);
    if (r->bad)
        return bad(L, "section too short", NULL);
    for (k = 0; k < 3; k++)
        if (!isfinite(s->camera.from[k]) || !isfinite(s->camera.at[k]) || !isfinite(s->camera.up[k]))
            return bad(L, "camera is not finite", NULL);
    if (!finite3(s->background) || !finite3(s->ambient) || !isfinite(s->light_scale) ||
        !isfinite(s->camera.angle) || !isfinite(s->camera.hither))
        return bad(L, "scene values are not finite", NULL);
    /* (light_scale: 1, or 0.5/sqrt(lights) for NFF; the camera as NFF
       and rtp_scene_set take it) */
    if (!(s->light_scale >= 0.0 && s->light_scale <= 1.0) ||
        !(s->camera.angle > 0.0 && s->camera.angle < 180.0) || !(s->camera.hither >= 0.0))
        return bad(L, "scene value out of range (light scale, view angle or hither)", NULL);
    if (rtpi_camera_problem(s))
        return bad(L, rtpi_camera_problem(s), NULL);
    if (s->background[0] < 0.0f || s->background[1] < 0.0f || s->background[2] < 0.0f ||
        s->ambient[0] < 0.0f || s->ambient[1] < 0.0f || s->ambient[2] < 0.0f)
        return bad(L, "negative colour (background or ambient)", NULL);
    s->has_camera = 1;
    L->t->cam0 = s->camera;
    return RTP_OK;
}

static rtp_status read_matl(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    rtp_tree *t = L->t;
    uint32_t n = get_u32(r), i;
    int k, oom = 0;
    if (r->bad || !count_ok(r, n, 78))
        return bad(L, "invalid material count", NULL);
    s->mats = (rtpi_material *)rtpi_calloc_array(L->a, n ? n : 1, sizeof *s->mats);
    t->mats0 = (rtpi_material *)rtpi_calloc_array(L->a, n ? n : 1, sizeof *t->mats0);
    if (!s->mats || !t->mats0)
        return nomem(L);
    s->cap_mats = n;
    for (i = 0; i < n; i++) {
        rtpi_material *m = &s->mats[i];
        for (k = 0; k < 3; k++)
            m->color[k] = get_f32(r);
        m->kd = get_f32(r);
        m->ks = get_f32(r);
        m->shine = get_f32(r);
        m->kt = get_f32(r);
        m->ior = get_f32(r);
        m->tex = (rtpi_tex_kind)get_u8(r);
        for (k = 0; k < 3; k++)
            m->color2[k] = get_f32(r);
        m->tex_scale = get_f32(r);
        m->tex_image = get_u32(r);
        m->bump = (rtpi_bump_kind)get_u8(r);
        m->bump_image = get_u32(r);
        m->bump_strength = get_f32(r);
        m->bump_scale = get_f32(r);
        m->name = get_str(r, L->a, &oom);
        if (r->nul)
            return bad(L, "a material's name holds a NUL byte", NULL);
        s->nmats = i + 1;
        t->mats0[i] = *m;
        t->mats0[i].name = NULL;
        t->mats0[i].ks = get_f32(r);
        t->mats0[i].kt = get_f32(r);
        t->mats0[i].ior = get_f32(r);
        t->mats0[i].bump = (rtpi_bump_kind)get_u8(r);
        t->mats0[i].bump_image = get_u32(r);
        t->mats0[i].bump_strength = get_f32(r);
        t->mats0[i].bump_scale = get_f32(r);
        if (oom)
            return nomem(L);
        if (r->bad)
            return bad(L, "section too short", NULL);
        if (!finite3(m->color) || !finite3(m->color2) || !isfinite(m->kd) || !isfinite(m->ks) ||
            !isfinite(m->shine) || !isfinite(m->kt) || !isfinite(m->ior) ||
            !isfinite(m->tex_scale) || !isfinite(m->bump_strength) ||
            !isfinite(m->bump_scale) || !isfinite(t->mats0[i].ks) ||
            !isfinite(t->mats0[i].kt) || !isfinite(t->mats0[i].ior) ||
            !isfinite(t->mats0[i].bump_strength) || !isfinite(t->mats0[i].bump_scale))
            return bad(L, "material value is not finite", NULL);
        /* what no scene can hold (rtp_scene_set, NFF and MTL refuse it):
           a file saying so was made to, and its image would be NaN */
        if (m->kd < 0.0f || m->ks < 0.0f || m->kt < 0.0f || m->shine < 0.0f || m->ior <= 0.0f ||
            m->color[0] < 0.0f || m->color[1] < 0.0f || m->color[2] < 0.0f ||
            m->color2[0] < 0.0f || m->color2[1] < 0.0f || m->color2[2] < 0.0f ||
            m->tex_scale <= 0.0f || m->bump_scale <= 0.0f || t->mats0[i].ks < 0.0f ||
            t->mats0[i].kt < 0.0f || t->mats0[i].ior <= 0.0f || t->mats0[i].bump_scale <= 0.0f)
            return bad(L, "material value out of range (negative, or an ior or scale of 0)",
                       NULL);
        if ((unsigned)m->tex > RTPI_TEX_IMAGE || (unsigned)m->bump > RTPI_BUMP_NOISE ||
            (unsigned)t->mats0[i].bump > RTPI_BUMP_NOISE)
            return bad(L, "unknown texture or bump kind", NULL);
    }
    return RTP_OK;
}

/* MAMB: u32 count, then per material with its own ambient coefficient
   its index (ascending, each once) and ka[3] (f32, finite, 0 or more). */
static rtp_status read_mamb(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    uint32_t n = get_u32(r), i, idx;
    long prev = -1;
    int k;
    if (r->bad || !count_ok(r, n, 16) || n == 0 || n > s->nmats)
        return bad(L, "invalid count of ambient coefficients", NULL);
    for (i = 0; i < n; i++) {
        rtpi_material *m;
        float ka[3];
        idx = get_u32(r);
        for (k = 0; k < 3; k++)
            ka[k] = get_f32(r);
        if (r->bad)
            return bad(L, "section too short", NULL);
        if (idx >= s->nmats || (long)idx <= prev)
            return bad(L, "material index out of range or not ascending", NULL);
        if (!finite3(ka))
            return bad(L, "ambient coefficient is not finite", NULL);
        if (ka[0] < 0.0f || ka[1] < 0.0f || ka[2] < 0.0f)
            return bad(L, "negative ambient coefficient", NULL);
        prev = (long)idx;
        m = &s->mats[idx];
        memcpy(m->ka, ka, sizeof ka);
        m->ka_set = 1;
        /* (as traced too: mats0 is compared whole where parts merge) */
        memcpy(L->t->mats0[idx].ka, ka, sizeof ka);
        L->t->mats0[idx].ka_set = 1;
    }
    return RTP_OK;
}

static rtp_status read_lite(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    rtp_tree *t = L->t;
    uint32_t n = get_u32(r), i;
    int k, oom = 0;
    unsigned on;
    if (r->bad || !count_ok(r, n, 62))
        return bad(L, "invalid light count", NULL);
    s->lights = (rtpi_light *)rtpi_calloc_array(L->a, n ? n : 1, sizeof *s->lights);
    t->lights0 = (rtpi_light *)rtpi_calloc_array(L->a, n ? n : 1, sizeof *t->lights0);
    if (!s->lights || !t->lights0)
        return nomem(L);
    s->cap_lights = n;
    for (i = 0; i < n; i++) {
        rtpi_light *l = &s->lights[i];
        for (k = 0; k < 3; k++)
            l->pos[k] = get_f64(r);
        for (k = 0; k < 3; k++)
            l->color[k] = get_f32(r);
        on = get_u8(r);
        l->on = on != 0;
        l->name = get_str(r, L->a, &oom);
        if (r->nul)
            return bad(L, "a light's name holds a NUL byte", NULL);
        s->nlights = i + 1;
        for (k = 0; k < 3; k++)
            t->lights0[i].pos[k] = get_f64(r);
        if (oom)
            return nomem(L);
        if (r->bad)
            return bad(L, "section too short", NULL);
        for (k = 0; k < 3; k++)
            if (!isfinite(l->pos[k]) || !isfinite(t->lights0[i].pos[k]))
                return bad(L, "light position is not finite", NULL);
        if (!finite3(l->color))
            return bad(L, "light colour is not finite", NULL);
        if (l->color[0] < 0.0f || l->color[1] < 0.0f || l->color[2] < 0.0f || on > 1)
            return bad(L, "light value out of range (a negative colour, or on not 0 or 1)", NULL);
    }
    return RTP_OK;
}

static rtp_status read_texr(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    uint32_t n = get_u32(r), i;
    int oom = 0;
    /* TEXB: a byte a texel (k / 255), TEXR: an f32 */
    int bytes = L->section && strcmp(L->section, "TEXB") == 0;
    if (r->bad || !count_ok(r, n, 9))
        return bad(L, "invalid texture count", NULL);
    s->texs = (rtpi_texture *)rtpi_calloc_array(L->a, n ? n : 1, sizeof *s->texs);
    if (!s->texs)
        return nomem(L);
    s->cap_texs = n;
    for (i = 0; i < n; i++) {
        uint32_t w, h;
        size_t k, count;
        rtpi_texture *tx = &s->texs[i];
        s->ntexs = i + 1;
        tx->path = get_str(r, L->a, &oom);
        if (oom)
            return nomem(L);
        if (r->nul)
            return bad(L, "a texture's name holds a NUL byte", NULL);
        if (!tx->path)
            tx->path = rtpi_strdup(L->a, "");
        if (!tx->path)
            return nomem(L);
        w = get_u32(r);
        h = get_u32(r);
        if (r->bad || !rtpi_image_size_ok((int)w, (int)h) || w > 0x7fffffffu || h > 0x7fffffffu ||
            !count_ok(r, (uint64_t)w * h, bytes ? 3 : 12))
            return bad(L, "invalid texture size", NULL);
        if (rtp_image_create((int)w, (int)h, L->a, &tx->image, NULL) != RTP_OK)
            return nomem(L);
        count = (size_t)w * h * 3;
        for (k = 0; k < count; k++) {
            float f = bytes ? (float)get_u8(r) / 255.0f : get_f32(r);
            if (!isfinite(f))
                return bad(L, "texture value is not finite", NULL);
            tx->image->pixels[k] = f;
            if (fabs(f) > tx->max_abs)
                tx->max_abs = fabs(f);
        }
        if (r->bad)
            return bad(L, "section too short", NULL);
        if (rtpi_texture_share(L->a, tx))
            return nomem(L);
    }
    return RTP_OK;
}

/* n groups of `stride` 32-bit numbers of GEOM into v, or as the floats
   they are the bits of into f (v NULL): format 1 as they are, format 2
   packed (put_delta; prev: the group before, stride numbers, 0 before
   the first).  0, or 1 when the section ran out (r->bad set), 2 when a
   number is not a varint of 32 bits. */
static int get_words(loader *L, rd *r, uint32_t *v, float *f, size_t n, int stride,
                     uint32_t *prev)
{
    size_t i, at;
    int c;
    for (i = 0; i < n; i++)
        for (c = 0; c < stride; c++) {
            uint32_t x, z = 0;
            size_t used;
            if (L->major == 1) {
                x = get_u32(r);
                if (r->bad)
                    return 1;
            } else {
                /* (fewer than 5 bytes left: get_v32 says whether they
                   end) */
                used = get_v32(r->p + r->at, r->n - r->at, &z);
                if (used == 0) {
                    r->bad = 1;
                    return 1;
                }
                if (used == (size_t)-1)
                    return 2;
                r->at += used;
                x = prev[c] += unzigzag(z);
            }
            at = i * (size_t)stride + (size_t)c;
            if (v) {
                v[at] = x;
            } else {
                float y;
                memcpy(&y, &x, sizeof y);
                f[at] = y;
            }
        }
    return 0;
}

/* n groups of `stride` finite floats of GEOM into f (get_words), or the
   error naming `what`. */
static rtp_status get_floats(loader *L, rd *r, float *f, size_t n, int stride,
                             const char *what)
{
    size_t i;
    uint32_t prev[3] = {0, 0, 0};
    int e = get_words(L, r, NULL, f, n, stride, prev);
    if (e == 1)
        return bad(L, "section too short", NULL);
    if (e == 2)
        return bad(L, what, " is malformed");
    for (i = 0; i < n * (size_t)stride; i++)
        if (!isfinite(f[i]))
            return bad(L, what, " is not finite");
    return RTP_OK;
}

static rtp_status read_geom(loader *L, rd *r)
{
    rtp_scene *s = L->s;
    uint32_t n, i, prev[10] = {0};
    int k;
    rtp_status st;
    /* the fewest bytes a number takes: a varint's 1 (format 2) or 4 */
    const size_t nb = L->major == 1 ? 4 : 1;

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 3 * nb))
        return bad(L, "invalid vertex count", NULL);
    if (n && !(s->pos = (float *)rtpi_malloc_array(L->a, (size_t)n * 3, sizeof *s->pos)))
        return nomem(L);
    s->npos = s->cap_pos = n;
    if ((st = get_floats(L, r, s->pos, n, 3, "vertex")) != RTP_OK)
        return st;

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 3 * nb))
        return bad(L, "invalid normal count", NULL);
    if (n && !(s->nrm = (float *)rtpi_malloc_array(L->a, (size_t)n * 3, sizeof *s->nrm)))
        return nomem(L);
    s->nnrm = s->cap_nrm = n;
    if ((st = get_floats(L, r, s->nrm, n, 3, "normal")) != RTP_OK)
        return st;

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 2 * nb))
        return bad(L, "invalid texture-coordinate count", NULL);
    if (n && !(s->uv = (float *)rtpi_malloc_array(L->a, (size_t)n * 2, sizeof *s->uv)))
        return nomem(L);
    s->nuv = s->cap_uv = n;
    if ((st = get_floats(L, r, s->uv, n, 2, "texture coordinate")) != RTP_OK)
        return st;

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 10 * nb))
        return bad(L, "invalid triangle count", NULL);
    if (n && !(s->tris = (rtpi_tri *)rtpi_malloc_array(L->a, n, sizeof *s->tris)))
        return nomem(L);
    s->ntris = s->cap_tris = n;
    for (i = 0; i < n; i++) {
        rtpi_tri *tr = &s->tris[i];
        uint32_t w[10];
        int has_n, has_t, e = get_words(L, r, w, NULL, 1, 10, prev);
        if (e == 1)
            return bad(L, "section too short", NULL);
        if (e == 2)
            return bad(L, "triangle is malformed", NULL);
        for (k = 0; k < 3; k++) {
            tr->v[k] = w[k];
            tr->n[k] = w[3 + k];
            tr->t[k] = w[6 + k];
        }
        tr->mat = w[9];
        has_n = tr->n[0] != RTPI_NONE;
        has_t = tr->t[0] != RTPI_NONE;
        for (k = 0; k < 3; k++) {
            if (tr->v[k] >= s->npos || (has_n ? tr->n[k] >= s->nnrm : tr->n[k] != RTPI_NONE) ||
                (has_t ? tr->t[k] >= s->nuv : tr->t[k] != RTPI_NONE))
                return bad(L, "triangle index out of range", NULL);
        }
        if (tr->mat >= s->nmats)
            return bad(L, "triangle material out of range", NULL);
    }

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 20))
        return bad(L, "invalid sphere count", NULL);
    if (n && !(s->spheres = (rtpi_sphere *)rtpi_malloc_array(L->a, n, sizeof *s->spheres)))
        return nomem(L);
    s->nspheres = s->cap_spheres = n;
    for (i = 0; i < n; i++) {
        rtpi_sphere *sp = &s->spheres[i];
        for (k = 0; k < 3; k++)
            sp->c[k] = get_f32(r);
        sp->r = get_f32(r);
        sp->mat = get_u32(r);
        if (r->bad)
            return bad(L, "section too short", NULL);
        /* (radius 0: NFF refuses it; nothing could hit it) */
        if (!finite3(sp->c) || !isfinite(sp->r) || sp->r == 0.0f || sp->mat >= s->nmats)
            return bad(L, "invalid sphere", NULL);
    }

    n = get_u32(r);
    if (r->bad || !count_ok(r, n, 36))
        return bad(L, "invalid cone count", NULL);
    if (n && !(s->cones = (rtpi_cone *)rtpi_malloc_array(L->a, n, sizeof *s->cones)))
        return nomem(L);
    s->ncones = s->cap_cones = n;
    for (i = 0; i < n; i++) {
        rtpi_cone *c = &s->cones[i];
        for (k = 0; k < 3; k++)
            c->base[k] = get_f32(r);
        c->rb = get_f32(r);
        for (k = 0; k < 3; k++)
            c->apex[k] = get_f32(r);
        c->ra = get_f32(r);
        c->mat = get_u32(r);
        if (r->bad)
            return bad(L, "section too short", NULL);
        /* (and what NFF refuses: a negative radius, both 0, the apex on
           the base) */
        if (!finite3(c->base) || !finite3(c->apex) || !isfinite(c->rb) || !isfinite(c->ra) ||
            c->mat >= s->nmats || c->rb < 0.0f || c->ra < 0.0f ||
            (c->rb == 0.0f && c->ra == 0.0f) ||
            (c->base[0] == c->apex[0] && c->base[1] == c->apex[1] && c->base[2] == c->apex[2]))
            return bad(L, "invalid cone", NULL);
    }
    if (rtpi_scene_cone_frames(s))
        return nomem(L);
    if (rtpi_scene_nprims(s) >= (size_t)RTPI_NONE)
        return bad(L, "too many primitives", NULL);
    return RTP_OK;
}

/* Whether one sample's n nodes (n >= 1) form exactly one preorder tree
   within max_depth (the root at depth 1): each node's link valid, its
   reflected subtree (if any) next, its refracted one (if any) where its
   link says, just after the reflected one, and nothing after the root's
   subtree.  A walk in order, not a call a node (a recursive check took
   a twentieth of a one-off evaluation's instructions): the refracted
   subtrees still to come, where they must start and at what depth, wait
   on a stack; each one's parent is on the path to the node read, one a
   depth, so they are at most max_depth (MAX_DEPTH_FILE). */
static int tree_ok(const rtpi_cnode *nodes, size_t n, int max_depth)
{
    size_t want[MAX_DEPTH_FILE];
    int want_depth[MAX_DEPTH_FILE];
    size_t at = 0, top = 0;
    int depth = 1;
    for (;;) {
        uint32_t link;
        if (at >= n || depth > max_depth)
            return 0;
        link = nodes[at].link;
        if ((link & 0xc0u) || ((link & RTPI_L_REFL) && (link & RTPI_L_REFL_MISS)) ||
            ((link & RTPI_L_REFR) && (link & RTPI_L_REFR_MISS)) ||
            (!(link & RTPI_L_REFR) && (link >> RTPI_L_SHIFT)))
            return 0;
        if (link & RTPI_L_REFR) {
            want[top] = at + (link >> RTPI_L_SHIFT);
            want_depth[top++] = depth + 1;
        }
        at++;
        if (link & RTPI_L_REFL) { /* (its reflected subtree next) */
            depth++;
            continue;
        }
        /* a subtree ended at `at`: the refracted one waiting next, which
           must start there, else the tree ends there */
        if (!top)
            return at == n;
        if (want[--top] != at)
            return 0;
        depth = want_depth[top];
    }
}

/* Every texture a material names is in the file (TEXR or TEXB come
   before GEOM and TREE). */
static size_t texture_missing(const rtp_scene *s)
{
    size_t i;
    for (i = 0; i < s->nmats; i++) {
        const rtpi_material *m = &s->mats[i];
        if ((m->tex == RTPI_TEX_IMAGE && m->tex_image >= s->ntexs) ||
            (m->bump == RTPI_BUMP_IMAGE && m->bump_image >= s->ntexs))
            return i;
    }
    return (size_t)-1;
}

static rtp_status textures_held(loader *L)
{
    size_t i = texture_missing(L->t->scene);
    if (i != (size_t)-1) {
        char what[64];
        snprintf(what, sizeof what, "%zu", i);
        L->section = "MATL";
        return bad(L, "a texture the file does not hold named by material ", what);
    }
    return RTP_OK;
}

/* A format-1 node's fixed fields from c (the layout's node_bytes there):
   the bytes are there (checked a chunk at a time), read directly. */
static void unpack_node1(const unsigned char *c, unsigned layout, rtpi_cnode *nd)
{
    uint32_t u;
    int j;
    for (j = 0; j < 3; j++, c += 4) {
        u = (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 | (uint32_t)c[3] << 24;
        memcpy(&nd->p[j], &u, 4);
    }
    nd->prim = (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 | (uint32_t)c[3] << 24;
    c += 4;
    nd->vis = 0;
    if (layout & NODE_VIS) {
        nd->vis = (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 |
                  (uint32_t)c[3] << 24;
        c += 4;
    }
    if (layout & NODE_LINK32)
        nd->link = (uint32_t)c[0] | (uint32_t)c[1] << 8 | (uint32_t)c[2] << 16 |
                   (uint32_t)c[3] << 24;
    else
        nd->link = *c;
}

/* A format-1 node's bytes in layout: its fixed fields (16), light bits
   where the nodes hold them, the full link word or its byte of flags. */
static size_t node1_bytes(unsigned layout)
{
    return 16 + ((layout & NODE_VIS) ? 4 : 0) + ((layout & NODE_LINK32) ? 4 : 1);
}

/* A band of a one-off evaluation: whole sample rows up to this many
   nodes (or one row of more), at most BAND_ROWS rows.  2^16 nodes are
   1.5 MB, in cache when the band is evaluated right after it is
   decoded; a band a call of the sink, whose threads start anew each
   band (SPD's 513 rows at 512x512: 10 to 33 bands on the seven scenes). */
#define BAND_NODES ((uint64_t)1 << 16)
#define BAND_ROWS 64

/* The nodes of format 1 read_tree checks a chunk at a time, as many as
   the window holds (all of them when the whole file is in memory): a
   short section is found at a chunk's start, before its nodes. */
static size_t node1_chunk(const rd *r, size_t node_bytes, size_t nnodes)
{
    return r->src ? r->src->cap / node_bytes : nnodes;
}

/* The light words of trees of more than 32 lights (after every node),
   checked as read_tree checks them (nl: the lights they were traced
   with), none kept. */
static rtp_status skip_light_words(loader *L, rd *r, uint32_t words, size_t nl)
{
    size_t i, w, n = L->t->nnodes;
    if (!count_ok(r, (uint64_t)n * words, 4))
        return bad(L, "section too short", NULL);
    for (i = 0; i < n; i++)
        for (w = 0; w < words; w++) {
            uint32_t v = get_u32(r);
            if (w == words - 1 && nl % 32 && v >> (nl % 32))
                return bad(L, "invalid light bits", NULL);
        }
    return RTP_OK;
}

/* The samples' node counts where the trees may be read in bands (a
   one-off evaluation's, a summary's): LEB128, a byte a sample for most,
   an eighth of the index of 64-bit starts a whole read makes (mount_s6
   at 2048x2048: 34 MB), which only that read needs; read in order. */
typedef struct counts {
    unsigned char *b;
    size_t n, cap, at;
} counts;

/* Appends count v (0, or -1 out of memory). */
static int counts_put(const rtp_allocator *a, counts *cn, uint64_t v)
{
    if (cn->cap - cn->n < 10 && rtpi_grow(a, (void **)&cn->b, &cn->cap, cn->n + 10, 1))
        return -1;
    while (v >= 0x80u) {
        cn->b[cn->n++] = (unsigned char)((v & 0x7fu) | 0x80u);
        v >>= 7;
    }
    cn->b[cn->n++] = (unsigned char)v;
    return 0;
}

/* The next count (counts_put's, so never past the end). */
static RTPI_FORCE_INLINE uint64_t counts_next(counts *cn)
{
    uint64_t v = cn->b[cn->at++];
    int shift = 7;
    unsigned char x;
    if (v < 0x80u) /* (most) */
        return v;
    v &= 0x7fu;
    do {
        x = cn->b[cn->at++];
        v |= (uint64_t)(x & 0x7fu) << shift;
        shift += 7;
    } while (x & 0x80u);
    return v;
}

/* The trees of a one-off evaluation (L->sink) or of a summary
   (L->summary: rtp_tree_read_summary): decoded band by band into a
   buffer that holds the band's nodes after the last two samples before
   it (each packed node's references: node_refs), each sample checked as
   read_tree checks it, and handed to the sink (if any); none kept.  Each
   error is read_tree's for the same bytes: the nodes' in file order (a
   format-1 chunk's shortness before its nodes), the light words' after
   them (words: a summary's file of more than 32 lights, nl its lights),
   a malformed tree's last. */
static rtp_status read_bands(loader *L, rd *r, unsigned layout, uint32_t vis_mask,
                             uint32_t words, size_t nl, counts *cn)
{
    rtp_tree *t = L->t;
    size_t nx = (size_t)t->nx, ny = (size_t)t->ny, nprims = rtpi_scene_nprims(L->s);
    size_t y0, y1, c = 0, cap = 0, i, x;
    /* the next row's counts, decoded to see whether the band takes it
       (next_n: their sum; have_next: decoded, not yet in a band) */
    uint64_t *rowc = NULL, next_n = 0;
    int have_next = 0;
    /* format 1: its node's bytes, the nodes read and where the chunk
       whose bytes were asked for ends */
    size_t node_bytes = node1_bytes(layout), chunk = node1_chunk(r, node_bytes, t->nnodes);
    size_t done = 0, chunk_end = 0;
    int malformed = 0;
    rtpi_cnode *band = NULL, zero; /* (zero: unpack_node's A where none) */
    /* bs: band's sample starts, the c carried samples' then the band's */
    uint64_t *bs = (uint64_t *)rtpi_malloc_array(L->a, BAND_ROWS * nx + 3, sizeof *bs);
    rtp_status st = RTP_OK;
    rowc = (uint64_t *)rtpi_malloc_array(L->a, nx, sizeof *rowc);
    memset(&zero, 0, sizeof zero);
    if (!bs || !rowc) {
        rtpi_free(L->a, bs);
        rtpi_free(L->a, rowc);
        return nomem(L);
    }
    bs[0] = 0;
    for (y0 = 0; y0 < ny && st == RTP_OK; y0 = y1) {
        size_t k0 = y0 * nx, k, kn;
        uint64_t need_n, band_n = 0;
        int fast; /* (the band's samples may take the fast path) */
        /* rows while the band holds at most BAND_NODES nodes (its first
           row whatever it holds) and BAND_ROWS rows, their counts after
           the carried samples' */
        for (y1 = y0; y1 < ny; y1++) {
            size_t li = c + (y1 - y0) * nx;
            if (!have_next) {
                for (next_n = 0, x = 0; x < nx; x++)
                    next_n += rowc[x] = counts_next(cn);
                have_next = 1;
            }
            if (y1 > y0 && (y1 - y0 >= BAND_ROWS || band_n + next_n > BAND_NODES))
                break;
            for (x = 0; x < nx; x++)
                bs[li + x + 1] = bs[li + x] + rowc[x];
            band_n += next_n;
            have_next = 0;
        }
        kn = y1 * nx;
        need_n = bs[c + (kn - k0)];
        fast = L->major > 1 && need_n <= SAMPLE_FAST_MAX;
        if (need_n >= cap) {
            /* (at least one more than asked: rtpi_grow's own rule; and
               a buffer even for bands of no node, whose nodes pointer
               the evaluation offsets by 0: not NULL, as a whole read's
               t->nodes is not) */
            size_t want = (size_t)need_n;
            if (rtpi_grow(L->a, (void **)&band, &cap, want + 1, sizeof *band)) {
                st = nomem(L);
                break;
            }
        }
        for (k = k0; k < kn; k++) {
            size_t li = c + (k - k0), j, n = (size_t)(bs[li + 1] - bs[li]);
            /* each packed node's references (sample_refs; li >= 1
               exactly where k >= 1, li >= 2 where k >= 2: the samples
               before k0 that k's references may need are the carried
               ones) */
            const rtpi_cnode *pa, *pb;
            size_t na, nb, j0 = 0;
            sample_refs(band, bs, li, &pa, &na, &pb, &nb);
            /* (most samples: packed, their nodes' most bytes in the
               window: unpack_sample_30) */
            if (fast && r->n - r->at >= n * PACKED_MAX) {
                size_t used = unpack_sample_30(r->p + r->at, n, pa, na, pb, nb, &zero, layout,
                                               nprims, vis_mask, band + bs[li]);
                if (!used && n) {
                    st = bad(L, "invalid node", NULL);
                    goto out;
                }
                r->at += used;
                j0 = n;
            }
            for (j = j0; j < n; j++) {
                rtpi_cnode *nd = &band[bs[li] + j];
                const rtpi_cnode *ra, *rb;
                size_t used;
                if (L->major == 1) {
                    if (done == chunk_end) {
                        chunk_end = t->nnodes - done < chunk ? t->nnodes : done + chunk;
                        if (!need(r, (chunk_end - done) * node_bytes)) {
                            st = bad(L, "section too short", NULL);
                            goto out;
                        }
                    }
                    unpack_node1(r->p + r->at, layout, nd);
                    used = node_bytes;
                    done++;
                } else {
                    if (r->src && r->n - r->at < PACKED_MAX)
                        (void)refill(r, PACKED_MAX); /* (fewer where the section ends) */
                    ra = j < na ? pa + j : j ? nd - 1 : &zero;
                    rb = j < nb ? pb + j : ra;
                    /* (unpack_node refuses a position not finite) */
                    used = unpack_node(r->p + r->at, r->n - r->at, ra, rb, layout, nd);
                }
                if (used == 0)
                    st = bad(L, "section too short", NULL);
                else if (used == (size_t)-1 || (L->major == 1 && !finite3(nd->p)) ||
                         nd->prim >= nprims || (nd->vis & ~vis_mask))
                    st = bad(L, "invalid node", NULL);
                if (st != RTP_OK)
                    goto out;
                r->at += used;
            }
            /* (a malformed tree is reported once every node is read, as
               read_tree does: an invalid node or a short section after it
               is the error then; nothing more is evaluated) */
            if (!malformed && n &&
                !tree_ok(band + bs[li], n, t->max_depth))
                malformed = 1;
        }
        if (malformed || !L->sink)
            goto carry;
        st = L->sink->band(L->sink->user, t, (int)y0, (int)y1, band, bs + c, L->err);
        if (st != RTP_OK) {
            L->sink_stop = 1;
            break;
        }
    carry:
        /* the band's last two samples (of those there are) to the front */
        {
            size_t keep = kn < 2 ? kn : 2, li0 = c + (kn - k0) - keep;
            uint64_t from = bs[li0], nn = bs[c + (kn - k0)] - from;
            if (nn)
                memmove(band, band + from, (size_t)nn * sizeof *band);
            for (i = 0; i <= keep; i++)
                bs[i] = bs[li0 + i] - from;
            c = keep;
        }
    }
    if (st == RTP_OK && words)
        st = skip_light_words(L, r, words, nl);
    if (st == RTP_OK && malformed)
        st = bad(L, "malformed ray tree", NULL);
out:
    rtpi_free(L->a, band);
    rtpi_free(L->a, bs);
    rtpi_free(L->a, rowc);
    return st;
}

static rtp_status read_tree_counts(loader *L, rd *r, counts *cn);

/* The TREE section (read_tree_counts), the counts a banded read keeps
   freed after it. */
static rtp_status read_tree(loader *L, rd *r)
{
    counts cn;
    rtp_status st;
    memset(&cn, 0, sizeof cn);
    st = read_tree_counts(L, r, &cn);
    rtpi_free(L->a, cn.b);
    return st;
}

static rtp_status read_tree_counts(loader *L, rd *r, counts *cn)
{
    rtp_tree *t = L->t;
    rtp_scene *s = L->s;
    uint64_t nsamples = get_u64(r), nnodes = get_u64(r), k, at = 0;
    /* (the lights the file's trees were traced with: a one-off
       evaluation's edits, made before the trees are read, may add some) */
    size_t nl = s->nlights;
    uint32_t words = get_u32(r);
    unsigned layout = get_u8(r);
    size_t i, nprims = rtpi_scene_nprims(s), node_bytes, chunk;
    uint32_t vis_mask;
    rtpi_cnode zero; /* (unpack_node's A where none) */
    int fast; /* (the samples may take the fast path) */
    if (r->bad)
        return bad(L, "section too short", NULL);
    if (nsamples != (uint64_t)t->nx * (uint64_t)t->ny)
        return bad(L, "sample count does not match the image", NULL);
    /* Every sample's node count takes at least one byte: a header asking
       for 2^27 samples must not allocate their index from a tiny file. */
    if (!count_ok(r, nsamples, 1))
        return bad(L, "sample count larger than the section", NULL);
    if (words != (s->nlights > 32 ? (s->nlights + 31) / 32 : 0) || (layout & ~3u) ||
        ((layout & NODE_VIS) != 0) != (s->nlights > 0 && words == 0))
        return bad(L, "node layout does not match the scene", NULL);
    /* (format 1's fixed fields; a packed node takes 5 bytes at least, 6
       with light bits) */
    node_bytes = node1_bytes(layout);
    if (!count_ok(r, nnodes, L->major == 1 ? node_bytes : 5u + ((layout & NODE_VIS) != 0)) ||
        nnodes > (uint64_t)((size_t)-1 / sizeof(rtpi_cnode)))
        return bad(L, "invalid node count", NULL);
    t->nnodes = (size_t)nnodes;
    t->vis_words = words;
    if (L->sink || L->summary) {
        /* (a byte a sample for most, then counts_put grows it) */
        cn->cap = (size_t)nsamples + 10;
        cn->b = (unsigned char *)rtpi_malloc(L->a, cn->cap);
        if (!cn->b)
            return nomem(L);
    } else {
        t->start = (uint64_t *)rtpi_malloc_array(L->a, (size_t)nsamples + 1, sizeof *t->start);
        if (!t->start)
            return nomem(L);
    }
    for (k = 0; k < nsamples; k++) {
        uint64_t c = get_varint(r);
        if (r->bad || c > nnodes - at)
            return bad(L, "sample node counts do not add up", NULL);
        if (t->start)
            t->start[k] = at;
        else if (c < 0x80u && cn->n < cn->cap) /* (most: a byte) */
            cn->b[cn->n++] = (unsigned char)c;
        else if (counts_put(L->a, cn, c) != 0)
            return nomem(L);
        at += c;
    }
    if (t->start)
        t->start[nsamples] = at;
    if (at != nnodes)
        return bad(L, "sample node counts do not add up", NULL);
    vis_mask = s->nlights >= 32 ? 0xffffffffu : ((1u << s->nlights) - 1u);
    if (L->sink) {
        /* a one-off evaluation: its edits now, then the trees a band at a
           time (packed, their light bits in their nodes) or whole */
        rtp_status st;
        int stream = 0;
        if (texture_missing(s) != (size_t)-1) {
            /* (no edits, no evaluation: the file read on as rtp_tree_read
               reads it, and refused as that refuses it, a fault of the
               trees or of what follows them first, tree_end's check of
               the textures last) */
            L->sink = NULL;
            goto whole;
        }
        t->nlights0 = s->nlights;
        L->sink_begun = 1;
        st = L->sink->begin(L->sink->user, t, L->major > 1 && words == 0, &stream, L->err);
        if (st != RTP_OK) {
            L->sink_stop = 1;
            return st;
        }
        if (stream)
            return read_bands(L, r, layout, vis_mask, 0, nl, cn);
    }
    if (L->summary) /* (every file, its light words too) */
        return read_bands(L, r, layout, vis_mask, words, nl, cn);
whole:
    if (!t->start) {
        /* read whole after all: the samples' index from their counts */
        t->start = (uint64_t *)rtpi_malloc_array(L->a, (size_t)nsamples + 1, sizeof *t->start);
        if (!t->start)
            return nomem(L);
        for (k = 0, at = 0; k < nsamples; k++) {
            t->start[k] = at;
            at += counts_next(cn);
        }
        t->start[nsamples] = at;
    }
    t->nodes = (rtpi_cnode *)rtpi_malloc_array(L->a, t->nnodes ? t->nnodes : 1, sizeof *t->nodes);
    if (!t->nodes)
        return nomem(L);
    /* packed: each node's length is known once it is read, so the window
       is kept PACKED_MAX bytes ahead */
    memset(&zero, 0, sizeof zero);
    fast = t->nnodes <= SAMPLE_FAST_MAX;
    for (k = 0; L->major > 1 && k < nsamples; k++) {
        size_t j, n = (size_t)(t->start[k + 1] - t->start[k]);
        /* (the references as read_bands carries them) */
        const rtpi_cnode *pa, *pb;
        size_t na, nb;
        sample_refs(t->nodes, t->start, (size_t)k, &pa, &na, &pb, &nb);
        if (fast && r->n - r->at >= n * PACKED_MAX) { /* (read_bands' fast path) */
            size_t used = unpack_sample_30(r->p + r->at, n, pa, na, pb, nb, &zero, layout,
                                           nprims, vis_mask, t->nodes + t->start[k]);
            if (!used && n)
                return bad(L, "invalid node", NULL);
            r->at += used;
            continue;
        }
        for (j = 0; j < n; j++) {
            rtpi_cnode *nd = &t->nodes[t->start[k] + j];
            const rtpi_cnode *ra = j < na ? pa + j : j ? nd - 1 : &zero;
            const rtpi_cnode *rb = j < nb ? pb + j : ra;
            size_t used;
            if (r->src && r->n - r->at < PACKED_MAX)
                (void)refill(r, PACKED_MAX); /* (fewer where the section ends) */
            used = unpack_node(r->p + r->at, r->n - r->at, ra, rb, layout, nd);
            if (used == 0)
                return bad(L, "section too short", NULL);
            if (used == (size_t)-1 || nd->prim >= nprims || (nd->vis & ~vis_mask))
                return bad(L, "invalid node", NULL);
            r->at += used;
        }
    }
    /* format 1: the nodes as many at a time as the window holds (all of
       them when the whole file is in memory) */
    chunk = node1_chunk(r, node_bytes, t->nnodes);
    for (i = 0; L->major == 1 && i < t->nnodes;) {
        /* the bytes are there (checked once a chunk): read the fields
           directly */
        size_t end = t->nnodes - i < chunk ? t->nnodes : i + chunk;
        const unsigned char *c;
        if (!need(r, (end - i) * node_bytes))
            return bad(L, "section too short", NULL);
        c = r->p + r->at;
        r->at += (end - i) * node_bytes;
        for (; i < end; i++, c += node_bytes) {
            rtpi_cnode *nd = &t->nodes[i];
            unpack_node1(c, layout, nd);
            if (!finite3(nd->p) || nd->prim >= nprims || (nd->vis & ~vis_mask))
                return bad(L, "invalid node", NULL);
        }
    }
    if (words) {
        if (!count_ok(r, (uint64_t)t->nnodes * words, 4))
            return bad(L, "section too short", NULL);
        t->vis_ext = (uint32_t *)rtpi_malloc_array(L->a, t->nnodes * words, sizeof *t->vis_ext);
        if (!t->vis_ext)
            return nomem(L);
        for (i = 0; i < t->nnodes * words; i++)
            t->vis_ext[i] = get_u32(r);
        if (nl % 32)
            for (i = 0; i < t->nnodes; i++)
                if (t->vis_ext[i * words + words - 1] >> (nl % 32))
                    return bad(L, "invalid light bits", NULL);
    }
    /* Each sample's nodes must form exactly one preorder tree within the
       recorded depth, so evaluation can trust every link. */
    for (k = 0; k < nsamples; k++) {
        size_t a = (size_t)t->start[k], n = (size_t)(t->start[k + 1] - t->start[k]);
        if (n && !tree_ok(t->nodes + a, n, t->max_depth))
            return bad(L, "malformed ray tree", NULL);
    }
    return RTP_OK;
}

/* The signature checks, on the file's first min(size, 8) bytes. */
static rtp_status check_signature(loader *L, const unsigned char *data, size_t size)
{
    if (size < 8 || memcmp(data, signature, 8) != 0) {
        if (size >= 8 && memcmp(data, "\x89PNG", 4) == 0)
            return bad(L, "not an rtp tree file (it is a PNG image)", NULL);
        if (size == 0)
            return bad(L, "empty: not an rtp tree file", NULL);
        if (memcmp(data, signature, size < 8 ? size : 8) == 0)
            return bad(L, "truncated: the file ends inside its signature", NULL);
        /* (what else a tree's place is often given: an image rtp wrote,
           or the scene itself) */
        if (size >= 3 && data[0] == 'P' && (data[1] == 'F' || data[1] == 'f') &&
            (data[2] == '\n' || data[2] == '\r' || data[2] == ' '))
            return bad(L, "not an rtp tree file (it is a PFM image)", NULL);
        if (size >= 3 && data[0] == 'P' && (data[1] == '3' || data[1] == '6') &&
            (data[2] == '\n' || data[2] == '\r' || data[2] == ' ' || data[2] == '\t'))
            return bad(L, "not an rtp tree file (it is a PPM image)", NULL);
        {
            size_t i, n = size < 8 ? size : 8;
            int text = 1;
            for (i = 0; i < n; i++)
                text &= (data[i] >= 0x20 && data[i] < 0x7f) || data[i] == '\n' ||
                        data[i] == '\r' || data[i] == '\t';
            if (text)
                return bad(L, "not an rtp tree file (it is text: a scene? rtp trace SCENE -o "
                              "TREE makes a tree)",
                           NULL);
        }
        return bad(L, "not an rtp tree file (wrong signature)", NULL);
    }
    return RTP_OK;
}

static const char *const required_sections[] = {"HEAD", "SCEN", "MATL", "LITE", "GEOM", "TREE"};

/* Whether a tag is 4 printable ASCII bytes, as every tag is: other bytes
   are a corrupt file (and would go to a terminal in the message naming
   the section). */
static int tag_ascii(const char *tag)
{
    int i;
    for (i = 0; i < 4; i++)
        if ((unsigned char)tag[i] < 0x20 || (unsigned char)tag[i] > 0x7e)
            return 0;
    return 1;
}

/* Which section tag is (*idx: its place in required_sections, 6 for
   TEXR, -1 for an extension a reader skips), checked against the ones
   seen before it (added to *seen). */
static rtp_status section_index(loader *L, const char *tag, unsigned *seen, int *idx)
{
    size_t i;
    *idx = -1;
    for (i = 0; i < sizeof required_sections / sizeof *required_sections; i++)
        if (strcmp(tag, required_sections[i]) == 0)
            *idx = (int)i;
    if (*idx < 0 && (strcmp(tag, "TEXR") == 0 || strcmp(tag, "TEXB") == 0))
        *idx = 6; /* (one or the other: a second is a repeated section) */
    if (*idx < 0 && strcmp(tag, "MAMB") == 0)
        *idx = 7; /* (only where a material has its own ambient) */
    if (*idx < 0) {
        /* lower-case first letter: an extension a reader may skip */
        if (strcmp(tag, "frgn") == 0 && L->t)
            L->t->foreign = 1; /* (rtp_tree_write: its body is not read) */
        if (tag[0] >= 'a' && tag[0] <= 'z')
            return RTP_OK;
        return bad(L, "unknown required section (written by a newer rtp?)", NULL);
    }
    if (*seen & (1u << *idx))
        return bad(L, "repeated section", NULL);
    {
        /* The specification's order, HEAD SCEN MATL [MAMB] LITE [TEXR]
           GEOM TREE (rank by *idx): nothing of a later rank seen yet, every
           required section of an earlier rank seen.  (Until session 19
           only what each section needs of the earlier ones was checked,
           so files a reader following the specification refuses were
           taken.) */
        static const int rank[8] = {0, 1, 2, 4, 6, 7, 5, 3};
        int j;
        for (j = 0; j < 8; j++) {
            int had = (*seen >> j) & 1u;
            if ((had && rank[j] > rank[*idx]) || (!had && j < 6 && rank[j] < rank[*idx]))
                return bad(L, "section out of order", NULL);
        }
    }
    *seen |= 1u << *idx;
    return RTP_OK;
}

static rtp_status parse_section(loader *L, int idx, rd *body)
{
    rtp_status st;
    switch (idx) {
    case 0: st = read_head(L, body); break;
    case 1: st = read_scen(L, body); break;
    case 2: st = read_matl(L, body); break;
    case 3: st = read_lite(L, body); break;
    case 4: st = read_geom(L, body); break;
    case 5: st = read_tree(L, body); break;
    case 7: st = read_mamb(L, body); break;
    default: st = read_texr(L, body); break;
    }
    if (st == RTP_OK && rd_left(body) != 0)
        st = bad(L, "unexpected bytes at the end", NULL);
    return st;
}

/* A new tree for the loader, or an error. */
static rtp_status tree_begin(loader *L, const rtp_allocator *a)
{
    rtp_tree *t = (rtp_tree *)rtpi_calloc_array(a, 1, sizeof *t);
    if (!t)
        return rtpi_error(L->err, RTP_ERR_NOMEM, L->name, 0, 0, "out of memory");
    t->alloc = *a;
    L->t = t;
    L->a = &t->alloc;
    if (rtpi_scene_create(a, &t->scene) != RTP_OK) {
        rtp_tree_destroy(t);
        L->t = NULL;
        return rtpi_error(L->err, RTP_ERR_NOMEM, L->name, 0, 0, "out of memory");
    }
    L->s = t->scene;
    return RTP_OK;
}

/* The checks once every section is read; the tree into *out, or freed. */
static rtp_status tree_end(loader *L, unsigned seen, rtp_status st, rtp_tree **out)
{
    rtp_tree *t = L->t;
    size_t i;
    L->section = NULL;
    if (L->sink_begun) {
        /* (its nlights0 set before its edits, which may add lights:
           those were not traced) */
        L->sink_begun = 0;
        L->sink->end(L->sink->user, t);
    } else {
        t->nlights0 = t->scene->nlights;
    }
    if (st == RTP_OK && (seen & 0x3fu) != 0x3fu) {
        for (i = 0; (seen >> i) & 1u; i++)
            ;
        st = bad(L, "a required section is missing: ", required_sections[i]);
    }
    if (st == RTP_OK)
        st = textures_held(L);
    if (st != RTP_OK) {
        rtp_tree_destroy(t);
        return st;
    }
    *out = t;
    return RTP_OK;
}

rtp_status rtp_tree_read_memory(const void *data, size_t size, const char *name,
                                const rtp_allocator *alloc, rtp_tree **out,
                                rtp_error *err)
{
    rtp_allocator a;
    loader L;
    rd r;
    rtp_status st = RTP_OK;
    unsigned seen = 0;

    if (out)
        *out = NULL;
    if (!out || (!data && size))
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0,
                          "rtp_tree_read_memory: NULL argument");
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, "rtp_tree_read_memory");
    if (!name)
        name = "<memory>";
    rtpi_allocator_init(&a, alloc);
    memset(&L, 0, sizeof L);
    L.name = name;
    L.err = err;
    r.p = (const unsigned char *)data;
    r.n = size;
    r.at = 0;
    r.bad = 0;
    r.nul = 0;
    r.src = NULL;
    if ((st = check_signature(&L, r.p, size)) != RTP_OK)
        return st;
    r.at = 8;
    if ((st = tree_begin(&L, &a)) != RTP_OK)
        return st;
    for (;;) {
        char tag[5];
        uint64_t len;
        size_t start = r.at;
        rd body;
        int idx;
        L.section = NULL;
        if (!need(&r, 12)) {
            st = bad(&L, "truncated: missing sections or END", NULL);
            break;
        }
        memcpy(tag, r.p + r.at, 4);
        tag[4] = '\0';
        r.at += 4;
        len = get_u64(&r);
        if (!tag_ascii(tag)) {
            st = bad(&L, "a section tag of bytes other than ASCII: the file is corrupt", NULL);
            break;
        }
        L.section = tag;
        if (len > r.n - r.at || r.n - r.at - (size_t)len < 4) {
            st = bad(&L, "truncated: section longer than the file", NULL);
            break;
        }
        body.p = r.p + r.at;
        body.n = (size_t)len;
        body.at = 0;
        body.bad = 0;
        body.nul = 0;
        body.src = NULL;
        r.at += (size_t)len;
        if (crc32_update(0, r.p + start, r.at - start) != get_u32(&r)) {
            st = bad(&L, "checksum mismatch: the file is corrupt", NULL);
            break;
        }
        if (strcmp(tag, "END ") == 0) {
            /* empty and last (the messages name END: "in section END"
               after them said it twice) */
            L.section = NULL;
            if (len != 0)
                st = bad(&L, "END is not empty", NULL);
            else if (r.at != r.n)
                st = bad(&L, "bytes after END", NULL);
            break;
        }
        if ((st = section_index(&L, tag, &seen, &idx)) != RTP_OK)
            break;
        if (idx >= 0 && (st = parse_section(&L, idx, &body)) != RTP_OK)
            break;
    }
    return tree_end(&L, seen, st, out);
}

/* rtp_tree_read_memory for a stream: a regular file of `size` bytes
   (known), or a pipe of a size not known, read section by section: each
   section but the trees' whole (the scene's, small beside them), the
   trees' through a window of RD_WINDOW bytes, its nodes decoded as they
   arrive.  The file's bytes and the tree's nodes
   are then never in memory at once: a tree of 64 MB (mount_s6 at
   1024x1024) read into memory first took 135 MB, and on the development
   VM memory touched for the first time costs 1-2.7 ms a MiB (the kernel
   zeroing it while the host backs it: 60% of reading that tree).  Every
   error is the one rtp_tree_read_memory gives for those bytes: a section
   is checked against a file's size before it is read (a pipe's ending
   early gives the same message), and the trees' CRC, summed as they
   pass, is compared before any error of their contents is reported. */
#define RD_WINDOW ((size_t)256 << 10)

/* A section's len bytes and its CRC's 4 into *sec (of *cap bytes, grown
   as needed).  From a stream of unknown size (!known) they are read as
   they come, so that a length no stream holds ends as a short read, not
   as an allocation of that length.  @return 0, 1 when the file ends
   first, 2 on a read error, 3 out of memory. */
static int section_bytes(FILE *f, uint64_t len, int known, const rtp_allocator *a,
                         unsigned char **sec, size_t *cap)
{
    size_t have = 0, want;
    if (len > (uint64_t)((size_t)-1 - 4))
        want = (size_t)-1; /* (more than any stream holds: a short read) */
    else
        want = (size_t)len + 4;
    while (have < want) {
        size_t step = want - have, got;
        if (!known && step > (size_t)1 << 20 && step > have)
            step = have > ((size_t)1 << 20) ? have : (size_t)1 << 20;
        if (have + step > *cap) {
            unsigned char *n = (unsigned char *)rtpi_realloc(a, *sec, have + step);
            if (!n)
                return 3;
            *sec = n;
            *cap = have + step;
        }
        got = fread(*sec + have, 1, step, f);
        have += got;
        if (got < step)
            return ferror(f) ? 2 : 1;
    }
    return 0;
}

static rtp_status tree_read_stream(FILE *f, uint64_t size, int known, const char *name,
                                   const rtp_allocator *alloc, const rtpi_tree_sink *ts,
                                   int summary, rtp_tree **out, rtp_error *err)
{
    rtp_allocator a;
    loader L;
    rtp_status st = RTP_OK;
    unsigned seen = 0;
    uint64_t pos;
    unsigned char head[12], *sec = NULL;
    size_t sec_cap = 0;
    rd_src *src = NULL;

    rtpi_allocator_init(&a, alloc);
    memset(&L, 0, sizeof L);
    L.name = name;
    L.err = err;
    L.sink = ts;
    L.summary = summary;
    {
        /* (a stream's size: what it holds, once it holds fewer than 8) */
        size_t n = known && size < 8 ? (size_t)size : 8, got = fread(head, 1, n, f);
        if (ferror(f) || (known && got != n))
            return rtpi_error(err, RTP_ERR_IO, name, 0, 0, "read error");
        if ((st = check_signature(&L, head, known ? (size_t)(size < 8 ? size : 8) : got)) !=
            RTP_OK)
            return st;
    }
    pos = 8;
    if ((st = tree_begin(&L, &a)) != RTP_OK)
        return st;
    for (;;) {
        char tag[5];
        uint64_t len;
        uint32_t crc, want;
        rd body;
        int idx;
        L.section = NULL;
        if ((known && size - pos < 12) || fread(head, 1, 12, f) != 12) {
            st = ferror(f) ? rtpi_error(err, RTP_ERR_IO, name, 0, 0, "read error")
                           : bad(&L, "truncated: missing sections or END", NULL);
            break;
        }
        pos += 12;
        memcpy(tag, head, 4);
        tag[4] = '\0';
        body.p = head + 4;
        body.n = 8;
        body.at = 0;
        body.bad = 0;
        body.nul = 0;
        body.src = NULL;
        len = get_u64(&body);
        L.section = NULL;
        if (!tag_ascii(tag)) {
            st = bad(&L, "a section tag of bytes other than ASCII: the file is corrupt", NULL);
            break;
        }
        L.section = tag;
        if (known && (len > size - pos || size - pos - len < 4)) {
            st = bad(&L, "truncated: section longer than the file", NULL);
            break;
        }
        crc = crc32_update(0, head, 12);
        body.p = NULL;
        body.n = body.at = 0;
        if (strcmp(tag, "TREE") == 0 || (tag[0] >= 'a' && tag[0] <= 'z')) {
            /* through the window; the order checked now, the CRC once
               every byte has passed, and whatever comes first in
               rtp_tree_read_memory's order reported then.  An extension
               too, passing unparsed: it is skipped, not held (a 100 MB
               one took 100 MB, and one claiming more than a pipe brings
               grew as its bytes came) */
            rtp_error perr;
            rtp_status ost, pst = RTP_OK;
            if (!src && !(src = (rd_src *)rtpi_malloc(&a, sizeof *src + RD_WINDOW))) {
                st = rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0, "out of memory reading tree file");
                break;
            }
            src->f = f;
            src->buf = (unsigned char *)(src + 1);
            src->cap = RD_WINDOW;
            src->left = len;
            src->crc = crc;
            src->short_read = 0;
            crc_slices(src->slices);
            body.src = src;
            L.err = &perr;
            ost = section_index(&L, tag, &seen, &idx);
            if (ost == RTP_OK && idx >= 0)
                pst = parse_section(&L, idx, &body);
            L.err = err;
            if (L.sink_stop) {
                /* the sink's own error (an edit refused, no memory, a
                   cancel): now, not after the rest of the file */
                if (err)
                    *err = perr;
                st = pst;
                break;
            }
            /* the rest of the section's bytes, for their CRC */
            while (src->left && !src->short_read) {
                body.at = body.n;
                refill(&body, 1);
            }
            pos += len;
            crc = src->crc;
            if (src->short_read || fread(head, 1, 4, f) != 4) {
                st = ferror(f) ? rtpi_error(err, RTP_ERR_IO, name, 0, 0, "read error")
                               : bad(&L, "truncated: section longer than the file", NULL);
                break;
            }
            pos += 4;
            body.p = head;
            body.n = 4;
            body.at = 0;
            body.bad = 0;
            body.nul = 0;
            body.src = NULL;
            if (crc != get_u32(&body)) {
                st = bad(&L, "checksum mismatch: the file is corrupt", NULL);
                break;
            }
            if (ost != RTP_OK || pst != RTP_OK) {
                if (err)
                    *err = perr;
                st = ost != RTP_OK ? ost : pst;
                break;
            }
            continue;
        }
        /* the whole section and its CRC */
        {
            int r = section_bytes(f, len, known, &a, &sec, &sec_cap);
            if (r) {
                st = r == 1   ? bad(&L, "truncated: section longer than the file", NULL)
                     : r == 2 ? rtpi_error(err, RTP_ERR_IO, name, 0, 0, "read error")
                              : rtpi_error(err, RTP_ERR_NOMEM, name, 0, 0,
                                           "out of memory reading tree file");
                break;
            }
        }
        pos += len + 4;
        crc = crc32_update(crc, sec, (size_t)len);
        want = (uint32_t)sec[len] | (uint32_t)sec[len + 1] << 8 | (uint32_t)sec[len + 2] << 16 |
               (uint32_t)sec[len + 3] << 24;
        if (crc != want) {
            st = bad(&L, "checksum mismatch: the file is corrupt", NULL);
            break;
        }
        if (strcmp(tag, "END ") == 0) {
            /* empty and last (past it only where the size is known: a
               pipe's writer may keep it open, and waiting for its end
               would hang; the messages name END, as above) */
            L.section = NULL;
            if (len != 0)
                st = bad(&L, "END is not empty", NULL);
            else if (known && pos != size)
                st = bad(&L, "bytes after END", NULL);
            break;
        }
        body.p = sec;
        body.n = (size_t)len;
        if ((st = section_index(&L, tag, &seen, &idx)) != RTP_OK)
            break;
        if (idx >= 0 && (st = parse_section(&L, idx, &body)) != RTP_OK)
            break;
    }
    rtpi_free(&a, sec);
    rtpi_free(&a, src);
    return tree_end(&L, seen, st, out);
}

/* fn: the public function's name (for its argument errors); ts, summary:
   tree_read_stream's. */
static rtp_status read_path(const char *fn, const char *path, const rtp_allocator *alloc,
                            const rtpi_tree_sink *ts, int summary, rtp_tree **out,
                            rtp_error *err)
{
    rtp_allocator a;
    rtp_status st;
    FILE *f;
    struct stat sb;
    int is_stdin, known = 0;
    uint64_t size = 0;
    if (out)
        *out = NULL;
    if (!path || !out)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "%s: NULL argument", fn);
    if (rtpi_allocator_partial(alloc))
        return rtpi_allocator_refused(err, fn);
    rtpi_allocator_init(&a, alloc);
    /* ("" is no file: fopen's error then named none, "cannot open: No
       such file or directory", as rtp_image_read says it) */
    if (!*path)
        return rtpi_error(err, RTP_ERR_ARGUMENT, NULL, 0, 0, "no tree file name");
    is_stdin = strcmp(path, "-") == 0;
    f = is_stdin ? stdin : fopen(path, "rb");
    if (!f)
        return rtpi_error(err, RTP_ERR_IO, path, 0, 0, "cannot open: %s", strerror(errno));
    if (fstat(fileno(f), &sb) == 0) {
        if (S_ISDIR(sb.st_mode)) {
            if (!is_stdin)
                fclose(f);
            return rtpi_error(err, RTP_ERR_IO, is_stdin ? "<stdin>" : path, 0, 0,
                              "is a directory, not a file");
        }
        /* a regular file's size is known: each section is checked
           against it before it is read (else a pipe's bytes as they come) */
        if (S_ISREG(sb.st_mode) && sb.st_size >= 0 && !is_stdin) {
            known = 1;
            size = (uint64_t)sb.st_size;
        }
    }
    /* (stdin is "<stdin>" in errors, as the image and scene readers say) */
    st = tree_read_stream(f, size, known, is_stdin ? "<stdin>" : path, &a, ts, summary, out,
                          err);
    if (!is_stdin)
        fclose(f);
    return st;
}

rtp_status rtp_tree_read(const char *path, const rtp_allocator *alloc, rtp_tree **out,
                         rtp_error *err)
{
    return read_path("rtp_tree_read", path, alloc, NULL, 0, out, err);
}

rtp_status rtp_tree_read_summary(const char *path, const rtp_allocator *alloc, rtp_tree **out,
                                 rtp_error *err)
{
    rtp_status st = read_path("rtp_tree_read_summary", path, alloc, NULL, 1, out, err);
    if (st == RTP_OK)
        (*out)->busy = RTPI_TREE_SUMMARY; /* (for good: it has no ray trees) */
    return st;
}

rtp_status rtpi_tree_read_sink(const char *path, const rtp_allocator *alloc,
                               const rtpi_tree_sink *ts, rtp_tree **out, rtp_error *err)
{
    return read_path("rtp_tree_read", path, alloc, ts, 0, out, err);
}
