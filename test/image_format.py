#!/usr/bin/env python3
"""An independent reader and writer of the image files rtp reads and writes
(PFM, PPM and PNG), written from the formats' own specifications alone --
PFM as Debevec and netpbm describe it, netpbm's PPM/PGM, the PNG
specification -- and from README's and scenes/README.md's word on what rtp
makes of them, not from lib/image.c.  test/cli_image_format.sh runs it.

  image_format.py RTP DIR     every check below, in DIR (which it fills);
                              ends with "N passed, N failed" and exit 1 when
                              any case disagrees, naming each (VERBOSE=1:
                              every case)

What it checks:
  - rtp's images (trace's PFM, PNG and PPM, --region, 1x1 and odd sizes;
    merge's PNG and PPM of floats that are negative, above 1, NaN and
    infinite; diff's heat maps) read here to the values rtp meant: PFM the
    very floats, bottom row first; PNG and PPM those floats clamped to
    [0, 1], times 255, rounded half up, NaN and infinities 0, no gamma.
  - images written here in every variant the formats allow (PFM PF/Pf,
    either byte order, any scale; PPM P6/P3 with maxval 1..65535 and
    comments; PNG of every colour type and bit depth, palette with tRNS,
    Adam7, every filter, split IDAT, gAMA/sRGB/iCCP/tEXt) read by rtp (its
    merge, which copies an image into a PFM) to the values the format
    gives: sample / maxval, a palette entry's colour, alpha dropped; and
    that rtp diff, a texture and a bump map see the same values.
  - forms rtp says it does not read (PGM P5/P2, PBM, PAM) and malformed
    files (cut at every length, headers that lie, sizes past the limit,
    a PFM scale of 0 or NaN, bytes after the data, bad CRCs, palette
    indices past the palette) refused with a named error, exit 1, and
    nothing written.
"""
import math
import os
import struct
import subprocess
import sys
import zlib

VERBOSE = os.environ.get("VERBOSE") == "1"
passed = 0
failed = 0
skipped = 0


def ok(what):
    global passed
    passed += 1
    if VERBOSE:
        print("ok:", what)


def bad(what):
    global failed
    failed += 1
    print("FAIL:", what)


def f32(x):
    """x rounded to a float32 (a double rounded once more: exact for one
    +, -, * or / of floats, double having more than 2 * 24 + 2 bits)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def fbits(x):
    return struct.unpack("<I", struct.pack("<f", x))[0]


def unbits(u):
    return struct.unpack("<f", struct.pack("<I", u))[0]


# ------------------------------------------------------------------ PFM

def write_pfm(w, h, rows, grey=False, little=True, scale=None, sep=b"\n",
              tail=b""):
    """rows: h rows top first, each w pixels of 3 float bit patterns (or 1
    for grey).  PFM stores the bottom row first."""
    if scale is None:
        scale = b"-1.0" if little else b"1.0"
    head = (b"Pf" if grey else b"PF") + sep + b"%d %d" % (w, h) + sep + scale + b"\n"
    fmt = "<I" if little else ">I"
    body = bytearray()
    for row in reversed(rows):
        for px in row:
            for u in (px[:1] if grey else px):
                body += struct.pack(fmt, u)
    return head + bytes(body) + tail


class Bad(Exception):
    pass


def read_pfm(data):
    """The spec's reader: 'PF' or 'Pf', whitespace, width, whitespace,
    height, whitespace, scale (its sign the byte order), one whitespace
    character, then w*h*channels 4-byte floats, bottom row first.
    @return (w, h, rows top first of 3 bit patterns)."""
    if data[:2] not in (b"PF", b"Pf"):
        raise Bad("not PFM")
    grey = data[:2] == b"Pf"
    pos = 2
    toks = []
    while len(toks) < 3:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            raise Bad("header ends early")
        toks.append(data[start:pos])
    pos += 1  # one whitespace character
    w, h, scale = int(toks[0]), int(toks[1]), float(toks[2])
    if scale == 0 or scale != scale:
        raise Bad("scale")
    ch = 1 if grey else 3
    need = w * h * ch * 4
    if len(data) - pos != need:
        raise Bad("PFM data is %d bytes, header says %d" % (len(data) - pos, need))
    fmt = "<I" if scale < 0 else ">I"
    rows = []
    for y in range(h):
        row = []
        for x in range(w):
            px = [struct.unpack_from(fmt, data, pos + 4 * ((y * w + x) * ch + c))[0]
                  for c in range(ch)]
            row.append(px * 3 if grey else px)
        rows.append(row)
    rows.reverse()
    return w, h, rows


# ------------------------------------------------------------- netpbm

def write_pnm(magic, w, h, maxval, rows, comments=False, ascii_wrap=70):
    """rows: h rows top first of w tuples of samples (3 for P3/P6, 1 for
    P2/P5).  comments puts a comment between every header token."""
    c = b"# a comment\n" if comments else b""
    head = b"P" + magic + b"\n" + c + b"%d" % w + b" " + c + b"%d\n" % h + c + b"%d" % maxval
    if magic in (b"6", b"5"):
        body = bytearray()
        for row in rows:
            for px in row:
                for v in px:
                    body += bytes([v]) if maxval < 256 else struct.pack(">H", v)
        return head + b"\n" + bytes(body)
    out = [head]
    line = b""
    for row in rows:
        for px in row:
            for v in px:
                t = b"%d" % v
                if len(line) + len(t) + 1 > ascii_wrap:
                    out.append(line)
                    line = b""
                line += (b" " if line else b"") + t
    out.append(line)
    return b"\n".join(out) + b"\n"


def read_ppm(data):
    """P6 or P3: tokens with '#' comments (to the line's end) in the
    header, one whitespace character after maxval, samples of 1 byte
    (maxval < 256) or 2 big-endian.  @return (w, h, maxval, rows)."""
    magic = data[:2]
    if magic not in (b"P6", b"P3"):
        raise Bad("not P6/P3")
    pos = 2
    toks = []
    while len(toks) < 3:
        while pos < len(data):
            if data[pos:pos + 1] == b"#":
                while pos < len(data) and data[pos:pos + 1] not in (b"\n", b"\r"):
                    pos += 1
            elif data[pos:pos + 1].isspace():
                pos += 1
            else:
                break
        start = pos
        while pos < len(data) and data[pos:pos + 1].isdigit():
            pos += 1
        toks.append(int(data[start:pos]))
    w, h, maxval = toks
    if magic == b"P3":
        vals = [int(t) for t in data[pos:].split()]
    else:
        pos += 1
        bps = 1 if maxval < 256 else 2
        vals = [data[pos + i] if bps == 1 else struct.unpack_from(">H", data, pos + 2 * i)[0]
                for i in range(w * h * 3)]
        if len(data) - pos != w * h * 3 * bps:
            raise Bad("P6 data is %d bytes, header says %d" % (len(data) - pos, w * h * 3 * bps))
    rows = [[vals[3 * (y * w + x):3 * (y * w + x) + 3] for x in range(w)] for y in range(h)]
    return w, h, maxval, rows


# ---------------------------------------------------------------- PNG

PNG_SIG = b"\x89PNG\r\n\x1a\n"
# Adam7: (x0, y0, dx, dy) of the seven passes
ADAM7 = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4),
         (1, 0, 2, 2), (0, 1, 1, 2)]
CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}


def chunk(tag, body, crc=None):
    c = zlib.crc32(tag + body) & 0xFFFFFFFF if crc is None else crc
    return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", c)


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def pack_row(samples, depth):
    """One scanline's samples (ints) to bytes, big-endian, MSB first."""
    if depth == 8:
        return bytes(samples)
    if depth == 16:
        return b"".join(struct.pack(">H", s) for s in samples)
    out = bytearray()
    per = 8 // depth
    for i in range(0, len(samples), per):
        b = 0
        grp = samples[i:i + per]
        for j in range(per):
            b = (b << depth) | (grp[j] if j < len(grp) else 0)
        out.append(b)
    return bytes(out)


def unpack_row(raw, depth, n):
    if depth == 8:
        return list(raw[:n])
    if depth == 16:
        return [struct.unpack_from(">H", raw, 2 * i)[0] for i in range(n)]
    out = []
    mask = (1 << depth) - 1
    for i in range(n):
        bit = i * depth
        out.append((raw[bit // 8] >> (8 - depth - bit % 8)) & mask)
    return out


def filter_row(kind, row, prev, bpp):
    out = bytearray([kind])
    for i, x in enumerate(row):
        a = row[i - bpp] if i >= bpp else 0
        b = prev[i] if prev is not None else 0
        c = prev[i - bpp] if prev is not None and i >= bpp else 0
        pred = [0, a, b, (a + b) // 2, paeth(a, b, c)][kind]
        out.append((x - pred) & 0xFF)
    return out


def write_png(w, h, ctype, depth, pixels, palette=None, trns=None,
              interlace=0, extra=(), idat_split=0, filters=(0, 1, 2, 3, 4)):
    """pixels: h rows top first of w tuples of samples (channels of the
    colour type; palette indices for type 3).  Row filters cycle through
    `filters`; extra: (tag, body) chunks before IDAT."""
    ch = CHANNELS[ctype]
    bpp = max(1, ch * depth // 8)
    raw = bytearray()
    k = 0
    passes = ADAM7 if interlace else [(0, 0, 1, 1)]
    for (x0, y0, dx, dy) in passes:
        xs = list(range(x0, w, dx))
        ys = list(range(y0, h, dy))
        if not xs or not ys:
            continue
        prev = None
        for y in ys:
            samples = [s for x in xs for s in pixels[y][x]]
            row = pack_row(samples, depth)
            raw += filter_row(filters[k % len(filters)], row, prev, bpp)
            k += 1
            prev = row
    ihdr = struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, interlace)
    out = PNG_SIG + chunk(b"IHDR", ihdr)
    for tag, body in extra:
        out += chunk(tag, body)
    if palette is not None:
        out += chunk(b"PLTE", b"".join(bytes(p) for p in palette))
    if trns is not None:
        out += chunk(b"tRNS", trns)
    z = zlib.compress(bytes(raw), 9)
    if idat_split:
        for i in range(0, len(z), idat_split):
            out += chunk(b"IDAT", z[i:i + idat_split])
        out += chunk(b"IDAT", b"")  # an empty IDAT is allowed
    else:
        out += chunk(b"IDAT", z)
    return out + chunk(b"IEND", b"")


def chunk_tags(data):
    pos, tags = 8, []
    while pos + 8 <= len(data):
        n, = struct.unpack_from(">I", data, pos)
        tags.append(data[pos + 4:pos + 8])
        pos += 12 + n
    return tags


def read_png(data):
    """A PNG reader from the specification: chunks and CRCs, IHDR, PLTE,
    tRNS, IDAT inflated, unfiltered and de-interlaced.  @return (w, h,
    rgb rows top first of (r, g, b) ints, maxval): what README says rtp
    makes of it -- grey copied to RGB, palette looked up, alpha dropped."""
    if data[:8] != PNG_SIG:
        raise Bad("PNG signature")
    pos = 8
    idat = b""
    palette = None
    ihdr = None
    while True:
        if pos + 12 > len(data):
            raise Bad("PNG ends early")
        n, = struct.unpack_from(">I", data, pos)
        tag = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]
        if len(body) != n or pos + 12 + n > len(data):
            raise Bad("PNG chunk cut")
        c, = struct.unpack_from(">I", data, pos + 8 + n)
        if zlib.crc32(tag + body) & 0xFFFFFFFF != c:
            raise Bad("CRC of " + tag.decode("latin-1"))
        pos += 12 + n
        if tag == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"PLTE":
            palette = [tuple(body[i:i + 3]) for i in range(0, n, 3)]
        elif tag == b"IDAT":
            idat += body
        elif tag == b"IEND":
            break
    if pos != len(data):
        raise Bad("%d bytes after IEND" % (len(data) - pos))
    w, h, depth, ctype, _, _, interlace = ihdr
    ch = CHANNELS[ctype]
    bpp = max(1, ch * depth // 8)
    raw = zlib.decompress(idat)
    out = [[None] * w for _ in range(h)]
    at = 0
    for (x0, y0, dx, dy) in (ADAM7 if interlace else [(0, 0, 1, 1)]):
        xs = list(range(x0, w, dx))
        ys = list(range(y0, h, dy))
        if not xs or not ys:
            continue
        stride = (len(xs) * ch * depth + 7) // 8
        prev = bytearray(stride)
        for y in ys:
            kind = raw[at]
            line = bytearray(raw[at + 1:at + 1 + stride])
            at += 1 + stride
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                line[i] = (line[i] + [0, a, b, (a + b) // 2, paeth(a, b, c)][kind]) & 0xFF
            prev = line
            s = unpack_row(line, depth, len(xs) * ch)
            for j, x in enumerate(xs):
                px = s[j * ch:(j + 1) * ch]
                if ctype == 3:
                    if px[0] >= len(palette):
                        raise Bad("palette index %d past %d entries" % (px[0], len(palette)))
                    out[y][x] = palette[px[0]]
                elif ctype in (0, 4):
                    out[y][x] = (px[0],) * 3
                else:
                    out[y][x] = tuple(px[:3])
    if at != len(raw):
        raise Bad("%d bytes of image data too many" % (len(raw) - at))
    maxval = 255 if ctype == 3 else (1 << depth) - 1
    return w, h, out, maxval


# -------------------------------------------------------- conversions

def quantize8(u):
    """README: clamp to [0, 1], x 255, round half up; NaN, infinities and
    negatives 0."""
    x = unbits(u)
    if x != x or x in (math.inf, -math.inf) or not x > 0:
        return 0
    if x >= 1:
        return 255
    return int(x * 255.0 + 0.5)


def value_bits(v, maxval):
    """A sample v of maxval as the float rtp should read: v / maxval."""
    return fbits(f32(v / maxval))


def run(args, stdin=None):
    p = subprocess.run(args, input=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return p.returncode, p.stdout, p.stderr.decode("utf-8", "replace")


class Ctx:
    def __init__(self, rtp, d):
        self.rtp = rtp
        self.d = d
        self.n = 0
        # a build without libpng reads and writes no PNG (README): its PNG
        # cases are skipped
        self.png = b"built with: png" in run([rtp, "version"])[1]

    def skip_png(self, ext):
        global skipped
        if ext == "png" and not self.png:
            skipped += 1
            return True
        return False

    def path(self, name):
        return os.path.join(self.d, name)

    def put(self, name, data):
        p = self.path(name)
        with open(p, "wb") as f:
            f.write(data)
        return p

    def get(self, name):
        with open(self.path(name), "rb") as f:
            return f.read()

    def through_rtp(self, data, ext, w, h, out_ext="pfm"):
        """rtp reads `data` (an image file named .ext) and writes it as
        out_ext through `rtp merge` (which copies an image's floats into a
        new image).  @return (rc, output bytes or None, stderr)."""
        self.n += 1
        src = self.put("in%d.%s" % (self.n, ext), data)
        dst = self.path("out%d.%s" % (self.n, out_ext))
        if os.path.exists(dst):
            os.remove(dst)
        rc, _, err = run([self.rtp, "merge", "-q", "-i", dst, "--size", "%dx%d" % (w, h),
                          src + "@0,0"])
        out = None
        if os.path.exists(dst):
            with open(dst, "rb") as f:
                out = f.read()
        return rc, out, err

    def expect_read(self, what, data, ext, w, h, want):
        """rtp must read `data` to `want` (rows top first of 3 float bit
        patterns) exactly."""
        if self.skip_png(ext):
            return
        rc, out, err = self.through_rtp(data, ext, w, h)
        if rc != 0 or out is None:
            bad("%s: rtp refused it (exit %d): %s" % (what, rc, err.strip()))
            return
        try:
            ow, oh, rows = read_pfm(out)
        except Bad as e:
            bad("%s: rtp's PFM: %s" % (what, e))
            return
        if (ow, oh) != (w, h):
            bad("%s: read as %dx%d, not %dx%d" % (what, ow, oh, w, h))
            return
        for y in range(h):
            for x in range(w):
                if list(rows[y][x]) != list(want[y][x]):
                    bad("%s: pixel (%d, %d) read as %s, not %s" % (
                        what, x, y, [unbits(u) for u in rows[y][x]],
                        [unbits(u) for u in want[y][x]]))
                    return
        ok(what)

    def expect_refused(self, what, data, ext, w=2, h=2, needle=None):
        """rtp must refuse `data`: exit 1, a message naming the file, and
        no image written."""
        if self.skip_png(ext):
            return True
        rc, out, err = self.through_rtp(data, ext, w, h)
        name = "in%d.%s" % (self.n, ext)
        # (merge's own complaints -- a part that does not fit the frame,
        # pixels in no part -- are not the reader's refusal)
        if rc != 1 or out is not None or name not in err or "\n" != err[-1:] or \
                "merge:" in err:
            bad("%s: not refused by name (exit %d, %s written): %s" % (
                what, rc, "an image" if out is not None else "nothing", err.strip()[:200]))
            return False
        if needle and needle not in err:
            bad("%s: refused without saying %r: %s" % (what, needle, err.strip()))
            return False
        ok(what)
        return True


def pattern(w, h, ch, maxval, seed=1):
    """Samples covering 0, maxval and values between, every pixel apart."""
    rows = []
    k = seed
    for y in range(h):
        row = []
        for x in range(w):
            px = []
            for c in range(ch):
                k = (k * 1103515245 + 12345) & 0x7FFFFFFF
                if (x + y + c) % 7 == 0:
                    px.append(maxval)
                elif (x + 2 * y + c) % 5 == 0:
                    px.append(0)
                else:
                    px.append((k >> 8) % (maxval + 1))
            row.append(tuple(px))
        rows.append(row)
    return rows


# ---------------------------------------------------- 1: rtp's images

def check_rtp_writes(cx, scene):
    rtp = cx.rtp
    for size, region in (("7x5", None), ("1x1", None), ("13x3", None),
                         ("16x12", "3,2,14,9")):
        tag = size + (" region " + region if region else "")
        base = cx.path("t" + size)
        args = [rtp, "trace", scene, "--size", size, "-j", "1", "-q"]
        if region:
            args += ["--region", region]
        w, h = [int(v) for v in size.split("x")]
        if region:
            x0, y0, x1, y1 = [int(v) for v in region.split(",")]
            w, h = x1 - x0, y1 - y0
        for ext in ("pfm", "png", "ppm"):
            if cx.skip_png(ext):
                continue
            rc, _, err = run(args + ["-i", base + "." + ext])
            if rc != 0:
                bad("trace %s -i .%s: exit %d %s" % (tag, ext, rc, err))
                return
        try:
            pw, ph, frows = read_pfm(cx.get("t%s.pfm" % size))
            mw, mh, mmax, mrows = read_ppm(cx.get("t%s.ppm" % size))
            q = [[tuple(quantize8(u) for u in px) for px in row] for row in frows]
            if cx.png:
                png = cx.get("t%s.png" % size)
                nw, nh, nrows, nmax = read_png(png)
                ihdr = struct.unpack(">IIBBBBB", png[16:29])
            else:
                nw, nh, nrows, nmax, ihdr = w, h, q, 255, (w, h, 8, 2, 0, 0, 0)
        except Bad as e:
            bad("trace %s: %s" % (tag, e))
            continue
        if (pw, ph) != (w, h) or (nw, nh) != (w, h) or (mw, mh) != (w, h):
            bad("trace %s: sizes %dx%d %dx%d %dx%d" % (tag, pw, ph, nw, nh, mw, mh))
            continue
        if ihdr[2:] != (8, 2, 0, 0, 0) or nmax != 255 or mmax != 255:
            bad("trace %s: PNG header %s, maxval %d" % (tag, ihdr, mmax))
        if cx.png:
            # README: no gamma chunk (nor sRGB, iCCP): values as computed
            tags = set(chunk_tags(png)) - {b"IHDR", b"IDAT", b"IEND"}
            if tags & {b"gAMA", b"sRGB", b"iCCP", b"cHRM", b"sBIT"}:
                bad("trace %s: the PNG has colour chunks %s" % (tag, sorted(tags)))
            else:
                ok("trace %s: no colour chunks in the PNG" % tag)
        if [list(map(tuple, r)) for r in nrows] != q:
            bad("trace %s: the PNG is not the PFM quantised" % tag)
        else:
            ok("trace %s: PNG = PFM quantised" % tag)
        if [list(map(tuple, r)) for r in mrows] != q:
            bad("trace %s: the PPM is not the PFM quantised" % tag)
        else:
            ok("trace %s: PPM = PFM quantised" % tag)
        # the PFM's rows in the right order: the top row is the sky side;
        # its bit patterns are what rtp reads back (merge copies them)
        rc, out, err = cx.through_rtp(cx.get("t%s.pfm" % size), "pfm", w, h)
        if rc != 0 or out != cx.get("t%s.pfm" % size):
            bad("trace %s: the PFM read and written again is not the same bytes" % tag)
        else:
            ok("trace %s: PFM round trip" % tag)
    # rows in the right order: a scene lit from above, a region of one
    # row at the top and one at the bottom against the whole frame
    whole = cx.path("whole.pfm")
    run([rtp, "trace", scene, "--size", "9x8", "-j", "1", "-q", "-i", whole])
    _, _, wrows = read_pfm(cx.get("whole.pfm"))
    for y in (0, 7):
        part = cx.path("row%d.pfm" % y)
        run([rtp, "trace", scene, "--size", "9x8", "-j", "1", "-q", "-i", part,
             "--region", "0,%d,9,%d" % (y, y + 1)])
        _, _, prow = read_pfm(cx.get("row%d.pfm" % y))
        if prow[0] != wrows[y]:
            bad("region row %d is not the whole frame's row %d (rows flipped?)" % (y, y))
        else:
            ok("region row %d = frame row %d" % (y, y))
    # floats of every kind to PNG and PPM (merge writes them)
    special = [0x00000000, 0x80000000, 0x3F800000, 0xBF800000, 0x7F800000, 0xFF800000,
               0x7FC00000, 0xFFC00000, 0x7F800001, 0x00000001, 0x3F000000,
               fbits(f32(0.5 / 255)), fbits(f32(1.5 / 255)), fbits(f32(254.5 / 255)),
               0x3F7FFFFF, 0x3F800001, 0x7F7FFFFF, fbits(f32(0.1)), fbits(f32(0.2)),
               fbits(f32(0.3)), 0x3B808081, 0x3B808080]
    while len(special) % 3:
        special.append(0x3E800000)
    px = [tuple(special[i:i + 3]) for i in range(0, len(special), 3)]
    w = len(px)
    rows = [px, list(reversed(px))]
    src = write_pfm(w, 2, rows)
    for ext in ("png", "ppm", "pfm"):
        if cx.skip_png(ext):
            continue
        rc, out, err = cx.through_rtp(src, "pfm", w, 2, out_ext=ext)
        if rc != 0 or out is None:
            bad("special floats to .%s: exit %d %s" % (ext, rc, err))
            continue
        try:
            if ext == "pfm":
                got = read_pfm(out)[2]
                want = rows
            elif ext == "png":
                got = read_png(out)[2]
                want = [[tuple(quantize8(u) for u in p) for p in r] for r in rows]
            else:
                got = read_ppm(out)[3]
                want = [[tuple(quantize8(u) for u in p) for p in r] for r in rows]
        except Bad as e:
            bad("special floats to .%s: %s" % (ext, e))
            continue
        got = [[tuple(p) for p in r] for r in got]
        want = [[tuple(p) for p in r] for r in want]
        if got != want:
            diffs = [(x, y, got[y][x], want[y][x]) for y in range(2) for x in range(w)
                     if got[y][x] != want[y][x]]
            bad("special floats to .%s: %d pixels differ, first %s" % (ext, len(diffs), diffs[0]))
        else:
            ok("special floats to .%s" % ext)
    # a noisy image: libpng's PNG in several IDAT chunks
    w, h = 128, 64
    k = 7
    noise = []
    for y in range(h):
        row = []
        for x in range(w):
            px = []
            for c in range(3):
                k = (k * 1103515245 + 12345) & 0x7FFFFFFF
                px.append(fbits(f32((k >> 8) / float(1 << 23) * 1.2 - 0.1)))
            row.append(tuple(px))
        noise.append(row)
    for ext in ("png", "ppm"):
        if cx.skip_png(ext):
            continue
        rc, out, err = cx.through_rtp(write_pfm(w, h, noise), "pfm", w, h, out_ext=ext)
        try:
            got = (read_png(out)[2] if ext == "png" else read_ppm(out)[3]) if rc == 0 else None
        except Bad as e:
            got = None
            err = str(e)
        want = [[tuple(quantize8(u) for u in p) for p in r] for r in noise]
        if got is None or [[tuple(p) for p in r] for r in got] != want:
            bad("noise %dx%d to .%s: %s" % (w, h, ext, err.strip() or "values differ"))
        elif ext == "png" and out.count(b"IDAT") < 2:
            bad("noise to .png: one IDAT chunk (the case meant several)")
        else:
            ok("noise %dx%d to .%s" % (w, h, ext))
    # heat maps: a valid image of the frame's width; the PNG the PFM quantised
    a = cx.put("ha.pfm", write_pfm(3, 2, [[(0x3F000000,) * 3] * 3] * 2))
    b = cx.put("hb.pfm", write_pfm(3, 2, [[(0x3F000000,) * 3, (0x3E800000,) * 3,
                                          (0,) * 3]] * 2))
    maps = {}
    for ext in ("pfm", "png", "ppm"):
        if cx.skip_png(ext):
            maps[ext] = [[tuple(quantize8(u) for u in p) for p in r] for r in maps["pfm"]]
            continue
        hm = cx.path("heat." + ext)
        rc, _, err = run([rtp, "diff", a, b, "-q", "--heatmap", hm])
        if rc != 0 or not os.path.exists(hm):
            bad("diff --heatmap .%s: exit %d %s" % (ext, rc, err))
            continue
        try:
            data = cx.get("heat." + ext)
            maps[ext] = read_pfm(data)[2] if ext == "pfm" else (
                read_png(data)[2] if ext == "png" else read_ppm(data)[3])
        except Bad as e:
            bad("heat map .%s: %s" % (ext, e))
    if len(maps) == 3:
        q = [[tuple(quantize8(u) for u in p) for p in r] for r in maps["pfm"]]
        if [[tuple(p) for p in r] for r in maps["png"]] != q or \
           [[tuple(p) for p in r] for r in maps["ppm"]] != q:
            bad("heat map: the PNG or PPM is not the PFM quantised")
        elif len(q[0]) < 3 or len(q) < 2:
            bad("heat map smaller than the images")
        else:
            ok("heat maps: %dx%d, PNG and PPM the PFM quantised" % (len(q[0]), len(q)))
            # the black pixel (0 error) and the largest error
            top = [tuple(unbits(u) for u in p) for p in maps["pfm"][0][:3]]
            if top[0] != (0.0, 0.0, 0.0) or top[2] != (1.0, 1.0, 1.0):
                bad("heat map's errors 0 and the largest are %s and %s, not black and white"
                    % (top[0], top[2]))
            else:
                ok("heat map: no error black, the largest white")
    # README: the legend below the image, 28 rows (56 from 480 pixels
    # wide), widened where the image is too narrow for its numbers
    for (w, h) in ((3, 2), (479, 2), (480, 2)):
        a = cx.put("da.pfm", write_pfm(w, h, [[(0x3F000000,) * 3] * w] * h))
        b = cx.put("db.pfm", write_pfm(w, h, [[(0x3E000000,) * 3] * w] * h))
        rc, _, err = run([rtp, "diff", a, b, "-q", "--heatmap", cx.path("dims.pfm")])
        try:
            hw, hh = read_pfm(cx.get("dims.pfm"))[:2]
        except (Bad, OSError) as e:
            bad("heat map of %dx%d: exit %d %s %s" % (w, h, rc, err, e))
            continue
        if hh != h + (56 if w >= 480 else 28) or hw < w or (w >= 480 and hw != w):
            bad("heat map of %dx%d is %dx%d" % (w, h, hw, hh))
        else:
            ok("heat map of %dx%d: %dx%d" % (w, h, hw, hh))
    # a 1x1 pair's heat map (its legend wider than the image)
    one = cx.put("one.pfm", write_pfm(1, 1, [[(0x3F000000,) * 3]]))
    for ext in ("pfm", "png", "ppm"):
        if cx.skip_png(ext):
            continue
        hm = cx.path("heat1." + ext)
        rc, _, err = run([rtp, "diff", one, one, "-q", "--heatmap", hm])
        try:
            data = cx.get("heat1." + ext)
            size = read_pfm(data)[:2] if ext == "pfm" else (
                read_png(data)[:2] if ext == "png" else read_ppm(data)[:2])
            ok("1x1 heat map .%s: %dx%d" % (ext, size[0], size[1]))
        except (Bad, OSError) as e:
            bad("1x1 heat map .%s: exit %d %s %s" % (ext, rc, err, e))


# ------------------------------------------ 2: images written here

def check_pfm_variants(cx):
    w, h = 5, 3
    vals = [0x3F800000, 0xC0400000, 0x00000001, 0x7F7FFFFF, 0x3DCCCCCD, 0x12345678,
            0x80000000, 0x40490FDB, 0x3EAAAAAB]
    rows = [[tuple(vals[(x * 3 + y * 7 + c) % len(vals)] ^ (c << 4) for c in range(3))
             for x in range(w)] for y in range(h)]
    grows = [[(p[0],) * 3 for p in r] for r in rows]
    for little in (True, False):
        order = "little" if little else "big"
        scales = [b"-1.0", b"-1", b"-0.5", b"-2.5e3", b"-.5"] if little else \
                 [b"1.0", b"1", b"+1", b"0.25", b"4e-1", b"1."]
        for scale in scales:
            for grey in (False, True):
                data = write_pfm(w, h, rows, grey=grey, little=little, scale=scale)
                cx.expect_read("PFM %s %s-endian scale %s" % ("Pf" if grey else "PF", order,
                                                              scale.decode()),
                               data, "pfm", w, h, grows if grey else rows)
    # header whitespace: spaces, tabs, CRLF, blank before the line end
    for sep, name in ((b" ", "spaces"), (b"\t", "tabs"), (b"\n\n", "blank lines")):
        data = write_pfm(w, h, rows, sep=sep)
        cx.expect_read("PFM header separated by " + name, data, "pfm", w, h, rows)
    # writers' blanks before the scale line's end (a file's size places
    # the data)
    for end in (b"\r\n", b" \n", b"\t\r\n"):
        data = write_pfm(w, h, rows).replace(b"-1.0\n", b"-1.0" + end, 1)
        cx.expect_read("PFM scale line ending %r" % end, data, "pfm", w, h, rows)
    for w1, h1 in ((1, 1), (1, 7), (7, 1)):
        r1 = [[(fbits(f32(x + 10 * y + 0.25)), 0x3F800000, 0) for x in range(w1)]
              for y in range(h1)]
        cx.expect_read("PFM %dx%d" % (w1, h1), write_pfm(w1, h1, r1), "pfm", w1, h1, r1)
        cx.expect_read("PFM %dx%d big-endian" % (w1, h1), write_pfm(w1, h1, r1, little=False),
                       "pfm", w1, h1, r1)


def check_ppm_variants(cx):
    w, h = 5, 3
    for magic in (b"6", b"3"):
        for maxval in (1, 2, 15, 100, 254, 255, 256, 1000, 4095, 65534, 65535):
            px = pattern(w, h, 3, maxval, seed=maxval)
            want = [[tuple(value_bits(v, maxval) for v in p) for p in r] for r in px]
            for comments in (False, True):
                data = write_pnm(magic, w, h, maxval, px, comments=comments)
                cx.expect_read("P%s maxval %d%s" % (magic.decode(), maxval,
                                                   " with comments" if comments else ""),
                               data, "ppm", w, h, want)
    # P3 with one sample a line, and samples run together across lines
    px = pattern(3, 2, 3, 255, seed=3)
    want = [[tuple(value_bits(v, 255) for v in p) for p in r] for r in px]
    cx.expect_read("P3 one sample a line", write_pnm(b"3", 3, 2, 255, px, ascii_wrap=3),
                   "ppm", 3, 2, want)
    # a comment ending the header's number ("255#c\n" then data, netpbm's
    # reader ends the comment with the line and takes the newline as the
    # one whitespace character)
    body = bytes(v for r in px for p in r for v in p)
    cx.expect_read("P6 with a comment right after maxval",
                   b"P6\n3 2\n255#c\n" + body, "ppm", 3, 2, want)
    cx.expect_read("P6 header on one line", b"P6 3 2 255 " + body, "ppm", 3, 2, want)
    cx.expect_read("P6 header tabs and CR", b"P6\t3\r2\r255\r" + body, "ppm", 3, 2, want)


def png_expect(ctype, depth, px, palette):
    if ctype == 3:
        return [[tuple(value_bits(v, 255) for v in palette[p[0]]) for p in r] for r in px]
    maxval = (1 << depth) - 1
    if ctype in (0, 4):
        return [[(value_bits(p[0], maxval),) * 3 for p in r] for r in px]
    return [[tuple(value_bits(v, maxval) for v in p[:3]) for p in r] for r in px]


def check_png_variants(cx):
    sizes = ((5, 3), (1, 1), (9, 10), (3, 1), (1, 9))
    for ctype, depths in sorted(DEPTHS.items()):
        for depth in depths:
            for (w, h) in sizes:
                for interlace in (0, 1):
                    ch = CHANNELS[ctype]
                    palette = trns = None
                    if ctype == 3:
                        n = min(1 << depth, 7 if depth > 2 else 1 << depth)
                        palette = [((37 * i) % 256, (91 * i + 5) % 256, 255 - 13 * i)
                                   for i in range(n)]
                        px = [[((x + 3 * y) % n,) for x in range(w)] for y in range(h)]
                        trns = bytes([0, 128][:n])
                    else:
                        px = pattern(w, h, ch, (1 << depth) - 1, seed=w * 31 + depth)
                        if ctype == 0:
                            trns = struct.pack(">H", px[0][0][0])
                        elif ctype == 2:
                            trns = struct.pack(">HHH", *px[0][0])
                    want = png_expect(ctype, depth, px, palette)
                    name = "PNG type %d depth %d %dx%d%s" % (ctype, depth, w, h,
                                                            " Adam7" if interlace else "")
                    data = write_png(w, h, ctype, depth, px, palette=palette,
                                     interlace=interlace)
                    cx.expect_read(name, data, "png", w, h, want)
                    if (w, h) == (5, 3) and trns is not None:
                        data = write_png(w, h, ctype, depth, px, palette=palette,
                                         trns=trns, interlace=interlace)
                        cx.expect_read(name + " tRNS", data, "png", w, h, want)
    # ancillary chunks rtp reads past, and split IDAT
    w, h = 6, 4
    px = pattern(w, h, 3, 255, seed=9)
    want = png_expect(2, 8, px, None)
    extras = [
        ("gAMA 1.0", [(b"gAMA", struct.pack(">I", 100000))]),
        ("gAMA 1/2.2", [(b"gAMA", struct.pack(">I", 45455))]),
        ("sRGB", [(b"sRGB", b"\x00"), (b"gAMA", struct.pack(">I", 45455))]),
        ("iCCP", [(b"iCCP", b"icc\x00\x00" + zlib.compress(b"\x00" * 128))]),
        ("cHRM", [(b"cHRM", struct.pack(">8I", 31270, 32900, 64000, 33000, 30000,
                                         60000, 15000, 6000))]),
        ("tEXt", [(b"tEXt", b"Comment\x00hello")]),
        ("sBIT", [(b"sBIT", b"\x05\x06\x05")]),
        ("pHYs", [(b"pHYs", struct.pack(">IIB", 2835, 2835, 1))]),
        ("a private chunk", [(b"prIv", b"whatever")]),
    ]
    for name, ex in extras:
        cx.expect_read("PNG with " + name, write_png(w, h, 2, 8, px, extra=ex), "png", w, h, want)
    gama = [(b"gAMA", struct.pack(">I", 45455)), (b"sRGB", b"\x00")]
    for ctype, depth in ((0, 8), (0, 16), (0, 2), (4, 16), (6, 8)):
        pg = pattern(w, h, CHANNELS[ctype], (1 << depth) - 1, seed=ctype + depth)
        cx.expect_read("PNG type %d depth %d with gAMA and sRGB" % (ctype, depth),
                       write_png(w, h, ctype, depth, pg, extra=gama), "png", w, h,
                       png_expect(ctype, depth, pg, None))
    pal = [(i * 40, 255 - i * 40, 7 * i) for i in range(6)]
    pi = [[((x + y) % 6,) for x in range(w)] for y in range(h)]
    cx.expect_read("PNG palette with gAMA and sRGB",
                   write_png(w, h, 3, 4, pi, palette=pal, trns=b"\x10\x20\x30",
                             extra=gama), "png", w, h, png_expect(3, 4, pi, pal))
    cx.expect_read("PNG IDAT split in 7-byte chunks",
                   write_png(w, h, 2, 8, px, idat_split=7), "png", w, h, want)
    for f in range(5):
        cx.expect_read("PNG every row filter %d" % f,
                       write_png(w, h, 2, 8, px, filters=(f,)), "png", w, h, want)
    # 16-bit: every bit of the sample kept
    px16 = [[(65535, 65534, 1), (256, 255, 257), (32768, 32767, 0)]]
    cx.expect_read("PNG 16-bit low bits", write_png(3, 1, 2, 16, px16), "png", 3, 1,
                   png_expect(2, 16, px16, None))


def check_consumers(cx, scene_dir):
    """rtp diff, a texture and a bump map read what merge reads."""
    rtp = cx.rtp
    w, h = 4, 4
    palette = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (200, 100, 50)]
    idx = [[((x + y) % 4,) for x in range(w)] for y in range(h)]
    want = png_expect(3, 8, idx, palette)
    variants = {
        "pal.png": write_png(w, h, 3, 2, idx, palette=palette, trns=b"\x00\x40"),
        "rgb16.png": write_png(w, h, 2, 16, [[tuple(c * 257 for c in palette[p[0]])
                                              for p in r] for r in idx], interlace=1),
        "p3.ppm": write_pnm(b"3", w, h, 255, [[palette[p[0]] for p in r] for r in idx],
                            comments=True),
        "p6.ppm": write_pnm(b"6", w, h, 65535, [[tuple(c * 257 for c in palette[p[0]])
                                                 for p in r] for r in idx]),
        "be.pfm": write_pfm(w, h, want, little=False),
    }
    if not cx.png:
        del variants["pal.png"], variants["rgb16.png"]
    ref = cx.put("ref.pfm", write_pfm(w, h, want))
    for name, data in variants.items():
        p = cx.put(name, data)
        rc, out, err = run([rtp, "diff", ref, p, "--stats", "-", "-q"])
        if rc != 0 or b'"max_abs": 0' not in out.replace(b'"max_abs":0', b'"max_abs": 0'):
            bad("diff of %s against its values: exit %d %s %s" % (name, rc, out[:200], err))
        else:
            ok("diff reads %s to its values" % name)
    # the same through a pipe (no file size to place the data by)
    piped = dict(variants)
    piped["crlf.pfm"] = write_pfm(w, h, want).replace(b"-1.0\n", b"-1.0\r\n", 1)
    piped["blank.pfm"] = write_pfm(w, h, want).replace(b"-1.0\n", b"-1.0 \n", 1)
    piped["grey.pfm"] = write_pfm(w, h, [[(p[0],) * 3 for p in r] for r in want], grey=True,
                                  little=False)
    for name, data in sorted(piped.items()):
        ref_p = ref
        if name == "grey.pfm":
            ref_p = cx.put("ref-grey.pfm", write_pfm(w, h, [[(p[0],) * 3 for p in r]
                                                            for r in want]))
        rc, out, err = run([rtp, "diff", "-", ref_p, "--stats", "-", "-q"], stdin=data)
        if rc != 0 or b'"max_abs": 0' not in out.replace(b'"max_abs":0', b'"max_abs": 0'):
            bad("diff of %s on a pipe: exit %d %s %s" % (name, rc, out[:200], err))
        else:
            ok("diff reads %s on a pipe to its values" % name)
    for name, data in sorted(piped.items()):
        # (P3's last byte is a line feed, and a sample cut short may be
        # another number: it is cut in the middle only)
        for cut in (len(data) // 2,) + (() if data[:2] == b"P3" else (len(data) - 1,)):
            rc, out, err = run([rtp, "diff", "-", ref, "-q"], stdin=data[:cut])
            if rc != 1 or "<stdin>" not in err:
                bad("%s cut to %d bytes on a pipe: exit %d %s" % (name, cut, rc, err.strip()))
                break
        else:
            ok("%s cut on a pipe refused" % name)
    # a texture and a bump map: every variant the same image as the PFM
    base = open(os.path.join(scene_dir, "textured.nff")).read()
    for key in ("texture", "bump"):
        imgs = {}
        for name in ["ref.pfm"] + sorted(variants):
            out = cx.path("%s-%s.pfm" % (key, name))
            sets = ["--set", "mat.1.%s=%s" % (key, cx.path(name))]
            rc, _, err = run([rtp, "trace", os.path.join(scene_dir, "textured.nff"),
                              "--size", "24x18", "-j", "1", "-q", "-i", out] + sets)
            if rc != 0:
                bad("%s %s: exit %d %s" % (key, name, rc, err))
                continue
            imgs[name] = cx.get("%s-%s.pfm" % (key, name))
        same = [n for n in imgs if n != "ref.pfm" and imgs[n] == imgs.get("ref.pfm")]
        if len(same) != len(variants):
            bad("%s: %s trace otherwise than the same image as PFM" % (
                key, sorted(set(variants) - set(same))))
        else:
            ok("%s: every variant traces as its PFM" % key)
    del base
    # a height map's height is the mean of R, G and B (README): red alone
    # bends as a grey of a third of it does
    hs = [0.0, 0.75, 0.375, 1.5, 3.0, 0.75, 0.0, 1.5, 0.375]
    red = [[(fbits(hs[(x + 3 * y) % 9]), 0, 0) for x in range(3)] for y in range(3)]
    grey = [[(fbits(hs[(x + 3 * y) % 9] / 3),) * 3 for x in range(3)] for y in range(3)]
    outs = []
    for name, rows in (("red", red), ("grey", grey)):
        p = cx.put("h-%s.pfm" % name, write_pfm(3, 3, rows))
        out = cx.path("h-%s-out.pfm" % name)
        rc, _, err = run([rtp, "trace", os.path.join(scene_dir, "textured.nff"), "--size",
                          "24x18", "-j", "1", "-q", "-i", out, "--set", "mat.1.bump=" + p,
                          "--set", "mat.1.bump_strength=3"])
        outs.append(cx.get("h-%s-out.pfm" % name) if rc == 0 else err)
    if outs[0] != outs[1] or not isinstance(outs[0], bytes):
        bad("a red height map does not bend as a grey of a third of it")
    else:
        ok("a height is the mean of R, G and B")
    # a texture's values must be finite (scenes/README): a PFM holding NaN
    # or an infinity is refused by name
    for name, u in (("nan", 0x7FC00000), ("inf", 0x7F800000)):
        p = cx.put("tex-%s.pfm" % name, write_pfm(2, 1, [[(0, 0, 0), (0, u, 0)]]))
        out = cx.path("tex-%s-out.pfm" % name)
        rc, _, err = run([rtp, "trace", os.path.join(scene_dir, "textured.nff"), "--size",
                          "8x6", "-q", "-i", out, "--set", "mat.1.texture=" + p])
        if rc != 1 or os.path.exists(out) or "not a finite number" not in err:
            bad("a texture of %s: exit %d %s" % (name, rc, err.strip()))
        else:
            ok("a texture of %s refused" % name)


# ---------------------------------------------------- 3: refusals

def check_refusals(cx):
    w, h = 2, 2
    rows = [[(0x3F800000, 0, 0x3E800000)] * w] * h
    pfm = write_pfm(w, h, rows)
    ppm = write_pnm(b"6", w, h, 255, [[(1, 2, 3)] * w] * h)
    p3 = write_pnm(b"3", w, h, 255, [[(1, 2, 3)] * w] * h)
    png = write_png(w, h, 2, 8, [[(1, 2, 3)] * w] * h)
    pngi = write_png(w, h, 0, 1, [[(1,)] * w] * h, interlace=1)
    pfmg = write_pfm(w, h, rows, grey=True, little=False)
    ppm16 = write_pnm(b"6", w, h, 1000, [[(1, 999, 1000)] * w] * h)
    pngp = write_png(w, h, 3, 2, [[(0,), (2,)], [(1,), (0,)]], palette=[(9, 8, 7)] * 3,
                     trns=b"\x00", interlace=1)
    png16 = write_png(w, h, 6, 16, [[(1, 2, 3, 4), (65535, 0, 256, 9)]] * h)
    # every cut of a small file
    for name, data, ext in (("PFM", pfm, "pfm"), ("big-endian Pf", pfmg, "pfm"),
                            ("P6", ppm, "ppm"), ("16-bit P6", ppm16, "ppm"), ("P3", p3, "ppm"),
                            ("PNG", png, "png"), ("Adam7 PNG", pngi, "png"),
                            ("Adam7 palette PNG", pngp, "png"), ("16-bit RGBA PNG", png16, "png")):
        if cx.skip_png(ext):
            continue
        cut_bad = []
        for n in range(len(data)):
            if name == "P3" and n == len(data) - 1:
                continue  # only the final newline gone: still whole
            rc, out, err = cx.through_rtp(data[:n], ext, w, h)
            if rc != 1 or out is not None or not err.strip():
                cut_bad.append((n, rc, err.strip()[:80]))
        if cut_bad:
            bad("%s cut short: %d of %d lengths not refused, e.g. %s" % (
                name, len(cut_bad), len(data), cut_bad[:3]))
        else:
            ok("%s cut at each of %d lengths refused" % (name, len(data)))
    # forms rtp does not read: refused by name
    cx.expect_refused("PGM P5", write_pnm(b"5", w, h, 255, [[(7,)] * w] * h), "pgm",
                      needle="P5")
    cx.expect_refused("PGM P2", write_pnm(b"2", w, h, 255, [[(7,)] * w] * h), "pgm",
                      needle="P2")
    cx.expect_refused("PBM P4", b"P4\n2 2\n\x00\x00", "pbm", needle="P4")
    cx.expect_refused("PAM P7", b"P7\nWIDTH 1\nHEIGHT 1\nDEPTH 3\nMAXVAL 255\n"
                      b"TUPLTYPE RGB\nENDHDR\n\x01\x02\x03", "pam", 1, 1, needle="P7")
    # PFM header lies
    cx.expect_refused("PFM scale 0", write_pfm(w, h, rows, scale=b"0.0"), "pfm")
    cx.expect_refused("PFM scale -0", write_pfm(w, h, rows, scale=b"-0"), "pfm")
    cx.expect_refused("PFM scale nan", write_pfm(w, h, rows, scale=b"nan"), "pfm")
    cx.expect_refused("PFM scale inf", write_pfm(w, h, rows, scale=b"-inf"), "pfm")
    cx.expect_refused("PFM scale missing", b"PF\n2 2\n" + pfm[pfm.index(b"-1.0\n") + 5:],
                      "pfm")
    cx.expect_refused("PFM Pf header over colour data",
                      b"Pf" + pfm[2:], "pfm")
    cx.expect_refused("PFM PF header over grey data",
                      write_pfm(w, h, rows, grey=True).replace(b"Pf", b"PF", 1), "pfm")
    cx.expect_refused("PFM a byte after the data", pfm + b"\x00", "pfm")
    cx.expect_refused("PFM a row after the data", pfm + b"\x00" * 24, "pfm")
    cx.expect_refused("PFM width 0", b"PF\n0 2\n-1.0\n", "pfm")
    cx.expect_refused("PFM negative width", b"PF\n-2 2\n-1.0\n" + pfm[12:], "pfm")
    cx.expect_refused("PFM width 2^31", b"PF\n2147483648 1\n-1.0\n" + b"\0" * 12, "pfm")
    cx.expect_refused("PFM 2^20 x 2^20", b"PF\n1048576 1048576\n-1.0\n" + b"\0" * 12, "pfm")
    cx.expect_refused("PFM 2^21 x 1", b"PF\n2097152 1\n-1.0\n" + b"\0" * 12, "pfm")
    cx.expect_refused("PFM 3.5 wide", b"PF\n3.5 2\n-1.0\n" + b"\0" * 84, "pfm")
    # PPM header lies
    cx.expect_refused("P6 maxval 0", b"P6\n1 1\n0\n\x00\x00\x00", "ppm", 1, 1)
    cx.expect_refused("P6 maxval 65536", b"P6\n1 1\n65536\n" + b"\0" * 6, "ppm", 1, 1)
    cx.expect_refused("P6 sample above maxval", b"P6\n1 1\n100\n\x01\x02\x65", "ppm", 1, 1)
    cx.expect_refused("P6 16-bit sample above maxval", b"P6\n1 1\n1000\n\0\0\0\0\x03\xe9",
                      "ppm", 1, 1)
    cx.expect_refused("P3 sample above maxval", b"P3\n1 1\n100\n1 2 101\n", "ppm", 1, 1)
    cx.expect_refused("P3 negative sample", b"P3\n1 1\n100\n1 -2 3\n", "ppm", 1, 1)
    cx.expect_refused("P3 a letter", b"P3\n1 1\n100\n1 x 3\n", "ppm", 1, 1)
    cx.expect_refused("P6 huge", b"P6\n1048577 1\n255\n" + b"\0" * 30, "ppm")
    cx.expect_refused("P6 2^20 x 2^20", b"P6\n1048576 1048576\n255\n" + b"\0" * 30, "ppm")
    cx.expect_refused("P6 width 0", b"P6\n0 1\n255\n", "ppm")
    # PNG header lies and corruption
    def png_with(ihdr=None, chunks=None):
        out = PNG_SIG + chunk(b"IHDR", ihdr)
        for tag, body in chunks:
            out += chunk(tag, body)
        return out + chunk(b"IEND", b"")
    idat = chunk(b"IDAT", zlib.compress(b"\0\1\2\3\4\5\6\0\1\2\3\4\5\6"))
    good = png_with(struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0),
                    [(b"IDAT", zlib.compress(b"\0\1\2\3\4\5\6\0\1\2\3\4\5\6"))])
    cx.expect_read("PNG made by hand", good, "png", 2, 2,
                   [[tuple(value_bits(v, 255) for v in (1, 2, 3)),
                     tuple(value_bits(v, 255) for v in (4, 5, 6))]] * 2)
    del idat
    cx.expect_refused("PNG IHDR CRC wrong", good[:29] + bytes([good[29] ^ 1]) + good[30:],
                      "png")
    i = good.index(b"IDAT")
    cx.expect_refused("PNG IDAT CRC wrong", good[:i + 6] + bytes([good[i + 6] ^ 0x40]) +
                      good[i + 7:], "png")
    for (wv, hv, d, t, il) in ((0, 2, 8, 2, 0), (2, 0, 8, 2, 0), (2, 2, 3, 2, 0),
                               (2, 2, 8, 1, 0), (2, 2, 8, 2, 2), (2, 2, 16, 3, 0),
                               (2, 2, 4, 2, 0), (0x80000000, 1, 8, 2, 0),
                               (1 << 20, 1 << 20, 8, 2, 0), ((1 << 20) + 1, 1, 8, 2, 0)):
        ihdr = struct.pack(">IIBBBBB", wv, hv, d, t, 0, 0, il)
        cx.expect_refused("PNG IHDR %dx%d depth %d type %d interlace %d" % (wv, hv, d, t, il),
                          png_with(ihdr, [(b"IDAT", zlib.compress(b"\0" * 14))]), "png")
    for comp, filt in ((1, 0), (0, 1)):
        cx.expect_refused("PNG compression method %d filter method %d" % (comp, filt),
                          png_with(struct.pack(">IIBBBBB", 2, 2, 8, 2, comp, filt, 0),
                                   [(b"IDAT", zlib.compress(b"\0" * 14))]), "png")
    ihdr = struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0)
    cx.expect_refused("PNG without IDAT", png_with(ihdr, []), "png")
    cx.expect_refused("PNG too little image data",
                      png_with(ihdr, [(b"IDAT", zlib.compress(b"\0\1\2\3\4\5\6"))]), "png")
    cx.expect_refused("PNG bad filter type",
                      png_with(ihdr, [(b"IDAT", zlib.compress(b"\7\1\2\3\4\5\6\0\1\2\3\4\5\6"))]),
                      "png")
    cx.expect_refused("PNG IDAT not zlib", png_with(ihdr, [(b"IDAT", b"garbage!")]), "png")
    cx.expect_refused("PNG palette type without PLTE",
                      png_with(struct.pack(">IIBBBBB", 2, 2, 8, 3, 0, 0, 0),
                               [(b"IDAT", zlib.compress(b"\0\0\0\0\0\0"))]), "png")
    cx.expect_refused("PNG unknown critical chunk",
                      png_with(ihdr, [(b"CRIT", b"x"),
                                      (b"IDAT", zlib.compress(b"\0" * 14))]), "png")
    cx.expect_refused("PNG palette index past the palette",
                      write_png(2, 2, 3, 8, [[(0,), (1,)], [(2,), (5,)]],
                                palette=[(1, 2, 3), (4, 5, 6), (7, 8, 9)]), "png")
    cx.expect_refused("PNG 4-bit palette index past the palette",
                      write_png(2, 1, 3, 4, [[(0,), (15,)]],
                                palette=[(1, 2, 3), (4, 5, 6)]), "png", 2, 1)
    cx.expect_refused("PNG palette index just past the palette",
                      write_png(2, 2, 3, 8, [[(0,), (1,)], [(2,), (3,)]],
                                palette=[(1, 2, 3), (4, 5, 6), (7, 8, 9)]), "png",
                      needle="palette index 3")
    cx.expect_refused("PNG Adam7 2-bit palette index past the palette",
                      write_png(3, 3, 3, 2, [[(0,)] * 3, [(1,)] * 3, [(0,), (1,), (2,)]],
                                palette=[(1, 2, 3), (4, 5, 6)], interlace=1), "png", 3, 3,
                      needle="pixel (2, 2)")
    cx.expect_refused("PNG rows past IHDR's height",
                      png_with(ihdr, [(b"IDAT", zlib.compress(b"\0\1\2\3\4\5\6" * 3))]),
                      "png")
    cx.expect_refused("PNG Adam7 rows past IHDR's height",
                      png_with(struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 1),
                               [(b"IDAT", zlib.compress(b"\0" * 40))]), "png")
    cx.expect_refused("PNG bytes after the zlib stream",
                      png_with(ihdr, [(b"IDAT", zlib.compress(b"\0" * 14) + b"junk")]), "png")
    # bytes after IEND are not the image's (a stream may hold the next
    # image there): read past, the image read whole
    cx.expect_read("PNG bytes after IEND", good + b"\0\0\0\0", "png", 2, 2,
                   [[tuple(value_bits(v, 255) for v in (1, 2, 3)),
                     tuple(value_bits(v, 255) for v in (4, 5, 6))]] * 2)
    # PPM: bytes past the raster mean the header does not describe it
    p6 = b"P6\n2 1\n255\n\1\2\3\4\5\6"
    cx.expect_refused("P6 a pixel more than the header says", p6 + b"\7\10\11", "ppm", 2, 1)
    # (one line feed after the data is a writers' quirk the netpbm tools
    # read past: read, as a first sample of 10 before it is)
    p6v = [[tuple(value_bits(v, 255) for v in (1, 2, 3)),
            tuple(value_bits(v, 255) for v in (4, 5, 6))]]
    cx.expect_read("P6 one line feed after the data", p6 + b"\n", "ppm", 2, 1, p6v)
    cx.expect_read("P6 a first sample of 10, a line feed after the data",
                   b"P6\n2 1\n255\n\n\2\3\4\5\6\n", "ppm", 2, 1,
                   [[tuple(value_bits(v, 255) for v in (10, 2, 3)),
                     tuple(value_bits(v, 255) for v in (4, 5, 6))]])
    cx.expect_refused("P6 a byte after the data", p6 + b"x", "ppm", 2, 1)
    cx.expect_refused("P6 two line feeds after the data", p6 + b"\n\n", "ppm", 2, 1)
    cx.expect_refused("P6 a second image after the first", p6 + p6, "ppm", 2, 1)
    # netpbm's header ends in one whitespace character: after a CR LF the
    # line feed would be the first sample, every byte one off
    cx.expect_refused("P6 header lines ending in CR LF",
                      b"P6\r\n2 1\r\n255\r\n\1\2\3\4\5\6", "ppm", 2, 1, needle="CR LF")
    cx.expect_refused("P3 a sample more than the header says",
                      b"P3\n1 1\n255\n1 2 3 4\n", "ppm", 1, 1)
    cx.expect_read("P3 blanks and a comment after the last sample",
                   b"P3\n1 1\n255\n1 2 3 \n# end\n\n", "ppm", 1, 1,
                   [[tuple(value_bits(v, 255) for v in (1, 2, 3))]])
    # whatever is refused, nothing is left in the folder but what was put
    stray = [f for f in os.listdir(cx.d) if f.startswith(".rtp-")]
    if stray:
        bad("temporary files left: %s" % stray)
    else:
        ok("no temporary files left")


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        return 2
    rtp, d = sys.argv[1], sys.argv[2]
    os.makedirs(d, exist_ok=True)
    cx = Ctx(rtp, d)
    here = os.path.dirname(os.path.abspath(__file__))
    scenes = os.path.join(here, "..", "scenes")
    check_rtp_writes(cx, os.path.join(scenes, "spheres.nff"))
    check_pfm_variants(cx)
    check_ppm_variants(cx)
    check_png_variants(cx)
    check_consumers(cx, scenes)
    check_refusals(cx)
    if not cx.png:
        cx.expect_refused("PNG in a build without libpng", write_png(1, 1, 2, 8, [[(1, 2, 3)]]),
                          "pn_", 1, 1, needle="not supported")
    if skipped:
        # (one skip, as a test the build cannot run is one)
        sys.stderr.write("skip: no libpng in this build: %d PNG cases not run\n" % skipped)
    print("%d passed, %d failed, %d skipped" % (passed, failed, 1 if skipped else 0))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
