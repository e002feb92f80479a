/* fuzz_crc.h — the tree file's section CRCs for the fuzz targets of
 * its readers (fuzz_tree.c, fuzz_treefile.c): recomputed in a copy of an
 * input so that mutations reach the parsers behind the checksums. */
#ifndef RTP_FUZZ_CRC_H
#define RTP_FUZZ_CRC_H
#include <stddef.h>
#include <stdint.h>

static uint32_t crc32_of(const unsigned char *p, size_t n)
{
    uint32_t c = 0xffffffffu;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        c ^= p[i];
        for (k = 0; k < 8; k++)
            c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return ~c;
}

/* Rewrites every whole section's CRC: tag(4) len(u64 LE) body crc(u32). */
static void fix_crcs(unsigned char *d, size_t n)
{
    size_t at = 8;
    while (n - at >= 16) {
        uint64_t len = 0;
        uint32_t c;
        int k;
        for (k = 7; k >= 0; k--)
            len = len << 8 | d[at + 4 + (size_t)k];
        if (len > n - at - 16)
            return;
        c = crc32_of(d + at, 12 + (size_t)len);
        at += 12 + (size_t)len;
        for (k = 0; k < 4; k++)
            d[at + (size_t)k] = (unsigned char)(c >> (8 * k));
        at += 4;
    }
}

#endif
