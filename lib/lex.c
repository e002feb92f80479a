/* lex.c — the scene readers' tokenizer (line and column for every token),
 * number conversion that rejects NaN and infinities, paths relative to the
 * including file, and 4x3 affine transforms. */
#include "readers.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

void rtpi_lex_init(rtpi_lex *lx, const char *text, size_t size,
                   const char *name, rtp_error *err)
{
    memset(lx, 0, sizeof *lx);
    lx->p = text ? text : "";
    lx->end = lx->p + (text ? size : 0);
    /* a UTF-8 byte-order mark (Notepad writes one) is not text */
    if (lx->end - lx->p >= 3 && memcmp(lx->p, "\xef\xbb\xbf", 3) == 0)
        lx->p += 3;
    lx->line_start = lx->p;
    lx->line = 1;
    lx->name = name;
    lx->err = err;
}

static int is_space(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

/* Whether p ends a line: '\n', or a '\r' not followed by one (classic Mac
   OS text files end lines with '\r' alone).  A '\r' before '\n' is white
   space, the '\n' the line's end.  Without this a CR-only file was one
   line: its first comment ran to the end of the file, and an NFF scene
   with a comment at the top read as no objects at all. */
static int is_eol(const rtpi_lex *lx, const char *p)
{
    return *p == '\n' || (*p == '\r' && (p + 1 >= lx->end || p[1] != '\n'));
}

/* '#' starts a comment only where a word could start: inside one it is
   part of it (a material "Material#25", as 3ds Max names them), so a
   value such as MSVC's "-1.#IND00" is one word, not a number, and not -1
   followed by a comment. */
static int is_sep(const rtpi_lex *lx, char c)
{
    return is_space(c) || c == '\n' || (lx->commas && c == ',');
}

/* At p: a backslash ending its line (OBJ's continuation), when the reader
   allows them; *len the bytes up to the newline. */
static int continues(const rtpi_lex *lx, const char *p, size_t *len)
{
    if (!lx->continuation || *p != '\\')
        return 0;
    if (p + 1 < lx->end && is_eol(lx, p + 1)) {
        *len = 1;
        return 1;
    }
    if (p + 2 < lx->end && p[1] == '\r' && p[2] == '\n') {
        *len = 2;
        return 1;
    }
    return 0;
}

static void newline(rtpi_lex *lx)
{
    lx->p++;
    lx->line++;
    lx->line_start = lx->p;
}

void rtpi_lex_here(const rtpi_lex *lx, rtpi_tok *t)
{
    t->s = lx->p;
    t->n = 0;
    t->line = lx->line;
    t->col = (int)(lx->p - lx->line_start) + 1;
}

static void skip_comment(rtpi_lex *lx)
{
    const char *nl = (const char *)memchr(lx->p, '\n', (size_t)(lx->end - lx->p));
    const char *cr = (const char *)memchr(lx->p, '\r', (size_t)((nl ? nl : lx->end) - lx->p));
    /* (to the '\n', or to a lone '\r' before it) */
    while (cr && !is_eol(lx, cr))
        cr = (const char *)memchr(cr + 1, '\r', (size_t)((nl ? nl : lx->end) - (cr + 1)));
    lx->p = cr ? cr : nl ? nl : lx->end;
}

static void take(rtpi_lex *lx, rtpi_tok *t)
{
    size_t len;
    rtpi_lex_here(lx, t);
    while (lx->p < lx->end && !is_sep(lx, *lx->p) && !continues(lx, lx->p, &len))
        lx->p++;
    t->n = (size_t)(lx->p - t->s);
}

/* The next token, past blanks, comments and continuations; at the end
   of a line, past it too or (inline) stopping there.  (rtpi_lex_next and
   rtpi_lex_next_inline had each their own copy of this loop.) */
static int next_token(rtpi_lex *lx, rtpi_tok *t, int inline_only)
{
    size_t len;
    while (lx->p < lx->end) {
        char c = *lx->p;
        if (is_eol(lx, lx->p)) {
            if (inline_only)
                break;
            newline(lx);
        } else if (continues(lx, lx->p, &len)) {
            /* (inline: at the newline, the statement goes on; else a
               lone continuation, white space) */
            lx->p += len;
            newline(lx);
        } else if (is_space(c) || (lx->commas && c == ','))
            lx->p++;
        else if (c == '#')
            skip_comment(lx);
        else {
            take(lx, t);
            return 1;
        }
    }
    rtpi_lex_here(lx, t);
    return 0;
}

int rtpi_lex_next(rtpi_lex *lx, rtpi_tok *t)
{
    return next_token(lx, t, 0);
}

int rtpi_lex_next_inline(rtpi_lex *lx, rtpi_tok *t)
{
    return next_token(lx, t, 1);
}

void rtpi_lex_skip_line(rtpi_lex *lx)
{
    size_t len;
    for (;;) {
        /* a '#' where a word could start makes the rest a comment, whose
           last backslash continues nothing (as on a line read) */
        const char *q = lx->p;
        int comment = 0;
        for (; q < lx->end && !is_eol(lx, q); q++)
            if (*q == '#' && (q == lx->line_start || is_space(q[-1]))) {
                comment = 1;
                break;
            }
        skip_comment(lx);
        if (lx->p >= lx->end)
            return;
        if (comment) {
            newline(lx);
            return;
        }
        /* a statement read past goes on after a continuation */
        if (lx->p - lx->line_start >= 1 && continues(lx, lx->p - 1, &len)) {
            newline(lx);
            continue;
        }
        if (lx->p - lx->line_start >= 2 && lx->p[-1] == '\r' && continues(lx, lx->p - 2, &len)) {
            newline(lx);
            continue;
        }
        newline(lx);
        return;
    }
}

int rtpi_tok_is(const rtpi_tok *t, const char *word)
{
    size_t n = strlen(word);
    return t->n == n && memcmp(t->s, word, n) == 0;
}

int rtpi_tok_number(const rtpi_tok *t, double *out)
{
    char buf[RTPI_NUM_MAX + 1];
    char *end;
    double d;
    size_t i;
    if (t->n == 0 || t->n > RTPI_NUM_MAX)
        return -1;
    /* strtod also takes "nan", "inf" and hex; only decimal numbers are
       scene numbers, so the first character must start one. */
    if (!(t->s[0] == '-' || t->s[0] == '+' || t->s[0] == '.' ||
          (t->s[0] >= '0' && t->s[0] <= '9')))
        return -1;
    for (i = 0; i < t->n; i++) {
        char c = t->s[i];
        if (c == 'x' || c == 'X' || c == 'n' || c == 'N' || c == 'i' ||
            c == 'I' || c == '\0')
            return -1;
        buf[i] = c;
    }
    buf[t->n] = '\0';
    d = rtpi_strtod(buf, &end);
    if (end != buf + t->n)
        return -1;
    if (!isfinite(d))
        return -2; /* a decimal number beyond a double's range (1e400) */
    *out = d;
    return 0;
}

/* Case-insensitive: the n bytes at s equal the lower-case word. */
static int ci_word(const char *s, size_t n, const char *word)
{
    size_t i;
    if (n != strlen(word))
        return 0;
    for (i = 0; i < n; i++) {
        char c = s[i];
        if (c >= 'A' && c <= 'Z')
            c = (char)(c - 'A' + 'a');
        if (c != word[i])
            return 0;
    }
    return 1;
}

int rtpi_tok_nan_inf(const rtpi_tok *t)
{
    const char *s = t->s;
    size_t n = t->n;
    if (n && (s[0] == '-' || s[0] == '+')) {
        s++;
        n--;
    }
    if (n > 4 && s[n - 1] == ')' && ci_word(s, 4, "nan("))
        return 1;
    return ci_word(s, n, "nan") || ci_word(s, n, "inf") || ci_word(s, n, "infinity");
}

int rtpi_tok_numlike(const rtpi_tok *t)
{
    const char *s = t->s;
    if (t->n == 0)
        return 0;
    if (s[0] == '-' || s[0] == '+' || s[0] == '.' || (s[0] >= '0' && s[0] <= '9'))
        return 1;
    return rtpi_tok_nan_inf(t);
}

int rtpi_tok_int(const rtpi_tok *t, long *out)
{
    size_t i = 0;
    long v = 0;
    int neg = 0;
    if (t->n && (t->s[0] == '-' || t->s[0] == '+')) {
        neg = t->s[0] == '-';
        i = 1;
    }
    if (i == t->n)
        return -1;
    for (; i < t->n; i++) {
        char c = t->s[i];
        if (c < '0' || c > '9')
            return -1;
        v = v * 10 + (c - '0');
        if (v > 0x7fffffffL)
            return -1;
    }
    *out = neg ? -v : v;
    return 0;
}

/* The bytes of the printable UTF-8 character at s (n bytes left): 1 for
   printable ASCII, 2 to 4 for a well-formed sequence that is not a C1
   control (U+0080..U+009F: CSI and others reach a terminal as escapes),
   a surrogate, overlong or past U+10FFFF, a separator or a bidirectional
   control (below); 0 for any other byte, shown as '?'.  (Every byte past ASCII had been '?': a file in /home/jos\xc3\xa9
   read "jos??" in its message.) */
static size_t utf8_shown(const unsigned char *s, size_t n)
{
    unsigned char c = s[0];
    size_t len, k;
    unsigned lo = 0x80, hi = 0xbf;
    if (c >= 0x20 && c < 0x7f)
        return 1;
    if (c >= 0xc2 && c <= 0xdf)
        len = 2;
    else if (c >= 0xe0 && c <= 0xef)
        len = 3;
    else if (c >= 0xf0 && c <= 0xf4)
        len = 4;
    else
        return 0;
    if (n < len)
        return 0;
    /* (the second byte's range: no overlong form, surrogate or past
       U+10FFFF; no C1 control after 0xc2) */
    if (c == 0xc2)
        lo = 0xa0;
    else if (c == 0xe0)
        lo = 0xa0;
    else if (c == 0xed)
        hi = 0x9f;
    else if (c == 0xf0)
        lo = 0x90;
    else if (c == 0xf4)
        hi = 0x8f;
    if (s[1] < lo || s[1] > hi)
        return 0;
    for (k = 2; k < len; k++)
        if ((s[k] & 0xc0) != 0x80)
            return 0;
    /* Nor the characters that move or break the text around them, not
       printable either: the line and paragraph separators U+2028-2029
       (a message cut in two lines), and the bidirectional marks and
       controls U+061C, U+200E-200F, U+202A-202E, U+2066-2069, which
       reorder the rest of the line as a terminal shows it (a name with
       U+202E has a bidi-aware terminal show the rest reversed: the
       "Trojan Source" trick) */
    if (len == 2 && c == 0xd8 && s[1] == 0x9c)
        return 0;
    if (len == 3 && c == 0xe2 &&
        ((s[1] == 0x80 && ((s[2] >= 0x8e && s[2] <= 0x8f) || (s[2] >= 0xa8 && s[2] <= 0xae))) ||
         (s[1] == 0x81 && s[2] >= 0xa6 && s[2] <= 0xa9)))
        return 0;
    return len;
}

/* Appends the shown form of t's bytes [i, end) to buf at *o, whole
   characters while they fit below lim; @return where it stopped. */
static size_t show_part(const rtpi_tok *t, size_t i, size_t end, char *buf, size_t *o,
                        size_t lim)
{
    const unsigned char *u = (const unsigned char *)t->s;
    while (i < end) {
        size_t k = utf8_shown(u + i, end - i);
        if (*o + (k ? k : 1) > lim)
            break;
        if (k) {
            memcpy(buf + *o, u + i, k);
            *o += k;
            i += k;
        } else {
            buf[(*o)++] = '?';
            i++;
        }
    }
    return i;
}

const char *rtpi_tok_show(const rtpi_tok *t, char *buf, size_t size)
{
    size_t i, n = t->n, lim = size > 4 ? size - 4 : 0;
    size_t o = 0;
    if (!size)
        return buf;
    i = show_part(t, 0, n, buf, &o, lim);
    if (i < n && size >= 4) {
        memcpy(buf + o, "...", 3);
        o += 3;
    }
    buf[o < size ? o : size - 1] = '\0';
    return buf;
}

/* rtpi_tok_show for a file's name: one longer than buf cut in its middle,
   so that its end, the file's own name, stays (an error naming a file
   hundreds of bytes of folders deep showed the folders and lost the
   name, "'/tmp/a/b/...'"); a third of the room for its start.  Either
   side of the cut whole characters. */
const char *rtpi_tok_show_path(const rtpi_tok *t, char *buf, size_t size)
{
    size_t head, tail, from, o = 0;
    const unsigned char *u = (const unsigned char *)t->s;
    if (size < 8 || t->n < size)
        return rtpi_tok_show(t, buf, size);
    head = (size - 4) / 3;
    tail = size - 4 - head;
    show_part(t, 0, t->n, buf, &o, head);
    memcpy(buf + o, "...", 3);
    o += 3;
    /* (the end from a character's first byte: a continuation byte there
       would show as '?') */
    from = t->n - tail;
    while (from < t->n && from < t->n - tail + 3 && (u[from] & 0xc0) == 0x80)
        from++;
    show_part(t, from, t->n, buf, &o, size - 1);
    buf[o] = '\0';
    return buf;
}

rtp_status rtpi_lex_error(const rtpi_lex *lx, const rtpi_tok *t,
                          const char *fmt, ...)
{
    /* (the message whole, as rtpi_error takes it: 256 here had cut off
       the reason after a long name, where rtpi_error keeps its end) */
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return rtpi_error(lx->err, RTP_ERR_PARSE, lx->name, t->line, t->col,
                      "%s", msg);
}

rtp_status rtpi_lex_wrap(const rtpi_lex *lx, const rtpi_tok *t,
                         rtp_status st, const rtp_error *inner,
                         const char *what)
{
    /* (a file's name: its start and its end, room left in the message
       for what and the inner reason) */
    char show[96];
    rtpi_tok_show_path(t, show, sizeof show);
    if (st == RTP_ERR_NOMEM)
        return rtpi_error(lx->err, st, lx->name, t->line, t->col,
                          "out of memory");
    /* A fault inside the file read (a NUL byte) is named where it lies,
       as a parse error of the included file's own text is. */
    if (st == RTP_ERR_PARSE && inner && inner->line > 0) {
        if (lx->err)
            *lx->err = *inner;
        return st;
    }
    return rtpi_error(lx->err, st, lx->name, t->line, t->col,
                      "%s '%s': %s", what, show,
                      inner && inner->message[0] ? inner->message
                                                 : rtp_status_string(st));
}

char *rtpi_path_join(const rtp_allocator *a, const char *base,
                     const char *rel, size_t rel_len)
{
    size_t dir = 0, i, n;
    char *out;
    if (base && !(rel_len && rel[0] == '/')) {
        for (i = 0; base[i]; i++)
            if (base[i] == '/')
                dir = i + 1;
    }
    /* A file named "-" beside a scene in the current folder is "./-":
       "-" alone is stdin to the image and file readers, and a scene's
       `texture -` read stdin (the bytes of a --params - or of an image
       a key's "-" names) where the file beside it was meant. */
    if (!dir && rel_len == 1 && rel[0] == '-') {
        base = "./";
        dir = 2;
    }
    n = dir + rel_len;
    if (n < rel_len)
        return NULL;
    out = (char *)rtpi_malloc(a, n + 1);
    if (!out)
        return NULL;
    if (dir)
        memcpy(out, base, dir);
    memcpy(out + dir, rel, rel_len);
    out[n] = '\0';
    return out;
}

void rtpi_xform_identity(double m[12])
{
    memset(m, 0, 12 * sizeof *m);
    m[0] = m[5] = m[10] = 1.0;
}

void rtpi_xform_mul(double m[12], const double b[12], const double a[12])
{
    double r[12];
    int i, j;
    for (i = 0; i < 3; i++) {
        for (j = 0; j < 4; j++) {
            r[4 * i + j] = b[4 * i] * a[j] + b[4 * i + 1] * a[4 + j] +
                           b[4 * i + 2] * a[8 + j];
        }
        r[4 * i + 3] += b[4 * i + 3];
    }
    memcpy(m, r, sizeof r);
}

void rtpi_xform_point(const double *m, const double p[3], double out[3])
{
    double r[3];
    int i;
    if (!m) {
        out[0] = p[0];
        out[1] = p[1];
        out[2] = p[2];
        return;
    }
    for (i = 0; i < 3; i++)
        r[i] = m[4 * i] * p[0] + m[4 * i + 1] * p[1] + m[4 * i + 2] * p[2] +
               m[4 * i + 3];
    out[0] = r[0];
    out[1] = r[1];
    out[2] = r[2];
}

int rtpi_xform_mirrors(const double *m)
{
    double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                 m[2] * (m[4] * m[9] - m[5] * m[8]);
    return det < 0.0;
}

int rtpi_xform_normal_matrix(const double *m, double nm[9])
{
    /* The inverse transpose is the cofactor matrix over the determinant;
       the readers normalise normals afterwards, so only the sign of the
       determinant matters, but a zero one means a flattened object. */
    double a = m[0], b = m[1], c = m[2];
    double d = m[4], e = m[5], f = m[6];
    double g = m[8], h = m[9], k = m[10];
    double det, scale = 0.0;
    int i;
    nm[0] = e * k - f * h;
    nm[1] = f * g - d * k;
    nm[2] = d * h - e * g;
    nm[3] = c * h - b * k;
    nm[4] = a * k - c * g;
    nm[5] = b * g - a * h;
    nm[6] = b * f - c * e;
    nm[7] = c * d - a * f;
    nm[8] = a * e - b * d;
    det = a * nm[0] + b * nm[1] + c * nm[2];
    /* Relative test: a determinant this small against the product of the
       rows' lengths (its bound, Hadamard's) is a transform that squashes
       a dimension to nothing; a strong but regular stretch (scale 1e6 1
       1) is not (against the largest entry cubed it was refused). */
    scale = 1.0;
    for (i = 0; i < 3; i++)
        scale *= sqrt(m[4 * i] * m[4 * i] + m[4 * i + 1] * m[4 * i + 1] +
                      m[4 * i + 2] * m[4 * i + 2]);
    if (!isfinite(det) || !(fabs(det) > 1e-12 * scale))
        return -1;
    for (i = 0; i < 9; i++)
        nm[i] /= det;
    return 0;
}
