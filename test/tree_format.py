#!/usr/bin/env python3
"""An independent reader and writer of the rtp tree file (.rtp), written from
lib/tree-format.md alone (not from lib/treefile.c), so that the document and
the code cannot drift apart unnoticed.  test/cli_tree_format.sh runs it.

  tree_format.py FILE...          parse each file completely (every section,
                                  CRC, node and field, as the document says
                                  a reader checks them) and print a summary
  tree_format.py --check RTP FILE...
                                  also: re-encode the parsed file from the
                                  document and require the very bytes rtp
                                  wrote; compare `RTP info` (text and --stats)
                                  with what the file holds
  tree_format.py --stats FILE JSON...
                                  trace's or reeval's --stats of FILE: its
                                  sizes against the file's
  tree_format.py --craft RTP FILE...
                                  write, from each file, files the document
                                  says rtp must accept or must refuse with a
                                  named error (exit 1, no image), and run
                                  `RTP reeval` and `RTP info` on each
                                  (VERBOSE=1: name every case)
Ends with exit 1 when any file or case disagrees, naming each.
"""
import json
import math
import os
import struct
import subprocess
import sys
import zlib

SIGNATURE = b"\x89RTP\r\n\x1a\n"
ORDER = ["HEAD", "SCEN", "MATL", "MAMB", "LITE", "TEX", "GEOM", "TREE", "END "]
NONE32 = 0xFFFFFFFF
MAX_SIDE = 1 << 20
MAX_PIXELS = 1 << 27


class FormatError(Exception):
    pass


def crc(tag, body):
    return zlib.crc32(tag + struct.pack("<Q", len(body)) + body) & 0xFFFFFFFF


def f32_of(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def bits(x):
    return struct.unpack("<I", struct.pack("<f", x))[0]


def unbits(u):
    return struct.unpack("<f", struct.pack("<I", u & 0xFFFFFFFF))[0]


def zz(d):
    d &= 0xFFFFFFFF
    return ((d << 1) ^ (0 - (d >> 31))) & 0xFFFFFFFF


def unzz(u):
    return ((u >> 1) ^ (0 - (u & 1))) & 0xFFFFFFFF


def leb(v):
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


class Reader:
    """Reads one section's body; every read checks the bytes remain."""

    def __init__(self, data, name):
        self.d = data
        self.i = 0
        self.name = name

    def need(self, n, what):
        if n > len(self.d) - self.i:
            raise FormatError("%s: %s truncated" % (self.name, what))

    def take(self, n, what):
        self.need(n, what)
        b = self.d[self.i:self.i + n]
        self.i += n
        return b

    def u8(self, what="u8"):
        return self.take(1, what)[0]

    def u32(self, what="u32"):
        return struct.unpack("<I", self.take(4, what))[0]

    def u64(self, what="u64"):
        return struct.unpack("<Q", self.take(8, what))[0]

    def f32(self, what="f32"):
        v = struct.unpack("<f", self.take(4, what))[0]
        if not math.isfinite(v):
            raise FormatError("%s: %s not finite" % (self.name, what))
        return v

    def f64(self, what="f64"):
        v = struct.unpack("<d", self.take(8, what))[0]
        if not math.isfinite(v):
            raise FormatError("%s: %s not finite" % (self.name, what))
        return v

    def s(self, what="name"):
        n = self.u8(what)
        b = self.take(n, what)
        if b"\0" in b:
            raise FormatError("%s: %s holds a NUL byte" % (self.name, what))
        return b

    def varint(self, maxbytes, maxbits, what):
        v = 0
        for k in range(maxbytes):
            b = self.u8(what)
            v |= (b & 0x7F) << (7 * k)
            if not b & 0x80:
                if v >> maxbits:
                    raise FormatError("%s: %s above %d bits"
                                      % (self.name, what, maxbits))
                return v
        raise FormatError("%s: %s longer than %d bytes"
                          % (self.name, what, maxbytes))

    def v32(self, what):
        return self.varint(5, 32, what)

    def end(self):
        if self.i != len(self.d):
            raise FormatError("%s: %d bytes past its fields"
                              % (self.name, len(self.d) - self.i))


def check_size(w, h, what):
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE and w * h <= MAX_PIXELS):
        raise FormatError("%s %dx%d out of range" % (what, w, h))


def split_sections(data, from_pipe=False):
    """[(tag, body)] of every section, extensions included, CRCs checked
    (from_pipe: as a stream is read, stopping at END)."""
    if data[:8] != SIGNATURE:
        if data[:8] == b"\x89PNG\r\n\x1a\n":
            raise FormatError("a PNG image, not a tree file")
        raise FormatError("not a tree file (signature)")
    i = 8
    out = []
    while True:
        if len(data) - i < 12:
            raise FormatError("section header truncated at %d" % i)
        tag = data[i:i + 4]
        if any(c < 0x20 or c > 0x7E for c in tag):
            raise FormatError("tag not printable ASCII at %d" % i)
        (n,) = struct.unpack("<Q", data[i + 4:i + 12])
        if n > len(data) - i - 12 or len(data) - i - 12 - n < 4:
            raise FormatError("%s: length %d past the file's end"
                              % (tag.decode(), n))
        body = data[i + 12:i + 12 + n]
        (c,) = struct.unpack("<I", data[i + 12 + n:i + 16 + n])
        if c != crc(tag, body):
            raise FormatError("%s: CRC mismatch" % tag.decode())
        out.append((tag, body))
        i += 16 + n
        if tag == b"END ":
            if n:
                raise FormatError("END not empty")
            if i != len(data) and not from_pipe:
                raise FormatError("bytes after END")
            return out


def is_extension(tag):
    return 0x61 <= tag[0] <= 0x7A


def parse(data):
    """The whole file as a dict; FormatError naming the fault otherwise."""
    secs = split_sections(data)
    t = {"file_bytes": len(data), "extensions": [], "tags": []}
    required = []
    for tag, body in secs:
        t["tags"].append(tag)
        if is_extension(tag):
            t["extensions"].append((tag, body))
            continue
        name = tag.decode()
        slot = "TEX" if name in ("TEXR", "TEXB") else name
        if slot not in ORDER:
            raise FormatError("unknown required section %r" % name)
        if required and ORDER.index(slot) <= ORDER.index(required[-1][0]):
            raise FormatError("section out of order: %s" % name)
        required.append((slot, name, body))
    got = [r[0] for r in required]
    for must in ("HEAD", "SCEN", "MATL", "LITE", "GEOM", "TREE", "END "):
        if must not in got:
            raise FormatError("missing section %s" % must)
    by = {r[0]: (r[1], r[2]) for r in required}
    parse_head(t, Reader(by["HEAD"][1], "HEAD"))
    parse_scen(t, Reader(by["SCEN"][1], "SCEN"))
    parse_matl(t, Reader(by["MATL"][1], "MATL"))
    if "MAMB" in by:
        parse_mamb(t, Reader(by["MAMB"][1], "MAMB"))
    parse_lite(t, Reader(by["LITE"][1], "LITE"))
    t["tex_tag"] = None
    t["textures"] = []
    if "TEX" in by:
        t["tex_tag"] = by["TEX"][0]
        parse_tex(t, Reader(by["TEX"][1], by["TEX"][0]), by["TEX"][0])
    check_material_indices(t)
    parse_geom(t, Reader(by["GEOM"][1], "GEOM"))
    parse_tree(t, Reader(by["TREE"][1], "TREE"))
    return t


def parse_head(t, r):
    t["major"], t["minor"] = r.u32(), r.u32()
    if t["major"] not in (1, 2):
        raise FormatError("written by a newer rtp: format version %d"
                          % t["major"])
    t["width"], t["height"] = r.u32(), r.u32()
    t["nx"], t["ny"] = r.u32(), r.u32()
    t["spd"] = r.u32()
    t["max_depth"] = r.u32()
    t["min_weight"] = r.f64("min_weight")
    t["full_width"], t["full_height"] = r.u32(), r.u32()
    t["region_x"], t["region_y"] = r.u32(), r.u32()
    r.end()
    check_size(t["width"], t["height"], "HEAD: image")
    check_size(t["full_width"], t["full_height"], "HEAD: frame")
    if t["region_x"] + t["width"] > t["full_width"] or \
            t["region_y"] + t["height"] > t["full_height"]:
        raise FormatError("HEAD: region outside the frame")
    if t["spd"] not in (0, 1):
        raise FormatError("HEAD: spd %d" % t["spd"])
    e = 1 if t["spd"] else 0
    if (t["nx"], t["ny"]) != (t["width"] + e, t["height"] + e):
        raise FormatError("HEAD: sample grid %dx%d" % (t["nx"], t["ny"]))
    if not 1 <= t["max_depth"] <= 1000:
        raise FormatError("HEAD: depth %d" % t["max_depth"])
    if t["min_weight"] < 0:
        raise FormatError("HEAD: negative min_weight")


def vec(r, n, f, what):
    return [f(what) for _ in range(n)]


def parse_scen(t, r):
    c = {}
    c["from"] = vec(r, 3, r.f64, "from")
    c["at"] = vec(r, 3, r.f64, "at")
    c["up"] = vec(r, 3, r.f64, "up")
    c["angle"] = r.f64("angle")
    c["hither"] = r.f64("hither")
    c["background"] = vec(r, 3, r.f32, "background")
    c["ambient"] = vec(r, 3, r.f32, "ambient")
    c["light_scale"] = r.f64("light_scale")
    r.end()
    t["scene"] = c
    if not 0 < c["angle"] < 180:
        raise FormatError("SCEN: angle")
    if c["hither"] < 0:
        raise FormatError("SCEN: hither")
    if not 0 <= c["light_scale"] <= 1:
        raise FormatError("SCEN: light scale")
    if min(c["background"] + c["ambient"]) < 0:
        raise FormatError("SCEN: negative colour")
    d = [a - b for a, b in zip(c["at"], c["from"])]
    u = c["up"]
    x = [d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2],
         d[0] * u[1] - d[1] * u[0]]
    nd = math.sqrt(sum(v * v for v in d))
    nu = math.sqrt(sum(v * v for v in u))
    if nd == 0 or not math.sqrt(sum(v * v for v in x)) > 1e-9 * nd * nu:
        raise FormatError("SCEN: no view")


MAT_F = ["kd", "ks", "shine", "kt", "ior"]


def parse_matl(t, r):
    n = r.u32("count")
    # each material takes at least 92 bytes: check before building the list
    r.need(n * 92, "materials")
    mats = []
    for _ in range(n):
        m = {}
        m["color"] = vec(r, 3, r.f32, "color")
        for k in MAT_F:
            m[k] = r.f32(k)
        m["tex"] = r.u8()
        m["color2"] = vec(r, 3, r.f32, "color2")
        m["tex_scale"] = r.f32("tex_scale")
        m["tex_image"] = r.u32()
        m["bump"] = r.u8()
        m["bump_image"] = r.u32()
        m["bump_strength"] = r.f32("bump_strength")
        m["bump_scale"] = r.f32("bump_scale")
        m["name"] = r.s()
        for k in ("ks0", "kt0", "ior0"):
            m[k] = r.f32(k)
        m["bump0"] = r.u8()
        m["bump0_image"] = r.u32()
        m["bump0_strength"] = r.f32("bump0_strength")
        m["bump0_scale"] = r.f32("bump0_scale")
        for k in ("kd", "ks", "kt", "shine", "ks0", "kt0"):
            if m[k] < 0:
                raise FormatError("MATL: negative %s" % k)
        for k in ("tex_scale", "bump_scale", "bump0_scale", "ior", "ior0"):
            if not m[k] > 0:
                raise FormatError("MATL: %s of 0 or less" % k)
        if min(m["color"] + m["color2"]) < 0:
            raise FormatError("MATL: negative colour")
        if m["tex"] > 2 or m["bump"] > 3 or m["bump0"] > 3:
            raise FormatError("MATL: texture or bump kind")
        mats.append(m)
    r.end()
    t["materials"] = mats


def parse_mamb(t, r):
    """The materials' own ambient coefficients: m["ka"] where given."""
    n = r.u32("count")
    mats = t["materials"]
    if n == 0 or n > len(mats):
        raise FormatError("MAMB: count")
    prev = -1
    for _ in range(n):
        i = r.u32()
        ka = vec(r, 3, r.f32, "ka")
        if i >= len(mats) or i <= prev:
            raise FormatError("MAMB: material index")
        if min(ka) < 0:
            raise FormatError("MAMB: negative ka")
        mats[i]["ka"] = ka
        prev = i
    r.end()


def parse_lite(t, r):
    n = r.u32("count")
    r.need(n * 62, "lights")
    lights = []
    for _ in range(n):
        li = {}
        li["pos"] = vec(r, 3, r.f64, "pos")
        li["color"] = vec(r, 3, r.f32, "color")
        li["on"] = r.u8()
        li["name"] = r.s()
        li["pos0"] = vec(r, 3, r.f64, "pos0")
        if min(li["color"]) < 0:
            raise FormatError("LITE: negative colour")
        if li["on"] > 1:
            raise FormatError("LITE: on %d" % li["on"])
        lights.append(li)
    r.end()
    t["lights"] = lights


def texb_value(k):
    return f32_of(f32_of(k) / f32_of(255.0))


TEXB = [texb_value(k) for k in range(256)]
TEXB_SET = set(TEXB)


def parse_tex(t, r, tag):
    n = r.u32("count")
    r.need(n * 9, "textures")
    texs = []
    for _ in range(n):
        x = {"path": r.s("path")}
        x["width"], x["height"] = r.u32(), r.u32()
        check_size(x["width"], x["height"], tag + ": texture")
        cnt = x["width"] * x["height"] * 3
        if tag == "TEXB":
            x["texels"] = list(r.take(cnt, "texels"))
        else:
            raw = r.take(cnt * 4, "texels")
            x["texels"] = list(struct.unpack("<%df" % cnt, raw))
            # (any finite value: a PFM's may be negative)
            if not all(map(math.isfinite, x["texels"])):
                raise FormatError("TEXR: texel not finite")
        texs.append(x)
    r.end()
    t["textures"] = texs


def check_material_indices(t):
    nt = len(t["textures"])
    for m in t["materials"]:
        if m["tex"] == 2 and m["tex_image"] >= nt:
            raise FormatError("MATL: texture index")
        if m["bump"] == 1 and m["bump_image"] >= nt:
            raise FormatError("MATL: bump map index")


def parse_geom(t, r):
    packed = t["major"] >= 2
    g = {}

    def group(count, width, what, is_float):
        rows = []
        prev = [0] * width
        for i in range(count):
            row = []
            for c in range(width):
                if packed:
                    u = (prev[c] + unzz(r.v32(what + " is malformed"))) \
                        & 0xFFFFFFFF
                else:
                    u = r.u32(what)
                prev[c] = u
                row.append(u)
            if is_float:
                fl = [unbits(u) for u in row]
                if not all(map(math.isfinite, fl)):
                    raise FormatError("GEOM: %s not finite" % what)
                rows.append(fl)
            else:
                rows.append(row)
        return rows

    npos = r.u32()
    r.need(npos * (3 if packed else 12), "vertices")
    g["pos"] = group(npos, 3, "vertex", True)
    nn = r.u32()
    r.need(nn * (3 if packed else 12), "normals")
    g["nrm"] = group(nn, 3, "normal", True)
    nuv = r.u32()
    r.need(nuv * (2 if packed else 8), "uvs")
    g["uv"] = group(nuv, 2, "uv", True)
    ntri = r.u32()
    r.need(ntri * (10 if packed else 40), "triangles")
    g["tris"] = group(ntri, 10, "triangle", False)
    nmat = len(t["materials"])
    for tr in g["tris"]:
        if max(tr[0:3]) >= npos:
            raise FormatError("GEOM: vertex index")
        for lo, lim, what in ((3, nn, "normal"), (6, nuv, "uv")):
            ix = tr[lo:lo + 3]
            if ix != [NONE32] * 3 and max(ix) >= lim:
                raise FormatError("GEOM: %s index" % what)
        if tr[9] >= nmat:
            raise FormatError("GEOM: material index")
    ns = r.u32()
    r.need(ns * 20, "spheres")
    g["spheres"] = []
    for _ in range(ns):
        s = vec(r, 4, r.f32, "sphere")
        m = r.u32()
        if s[3] == 0:
            raise FormatError("GEOM: sphere of radius 0")
        if m >= nmat:
            raise FormatError("GEOM: material index")
        g["spheres"].append((s, m))
    nc = r.u32()
    r.need(nc * 36, "cones")
    g["cones"] = []
    for _ in range(nc):
        c = vec(r, 8, r.f32, "cone")
        m = r.u32()
        if c[3] < 0 or c[7] < 0 or (c[3] == 0 and c[7] == 0) \
                or c[0:3] == c[4:7]:
            raise FormatError("GEOM: cone")
        if m >= nmat:
            raise FormatError("GEOM: material index")
        g["cones"].append((c, m))
    r.end()
    g["nprims"] = ntri + ns + nc
    t["geom"] = g


ZERO_NODE = (0, 0, 0, 0, 0, 0)


def predictors(P, start, counts, k, j):
    """The nodes node j of sample k is predicted from (the reader's and the
    writer's one rule): A, the same node of the sample before, or the node
    before in this sample, or zeros; B (or None), the same node two samples
    back where A is the sample before's."""
    if k > 0 and counts[k - 1] > j:
        B = P[start[k - 2] + j] if k > 1 and counts[k - 2] > j else None
        return P[start[k - 1] + j], B
    if j > 0:
        return P[start[k] + j - 1], None
    return ZERO_NODE, None


def parse_tree(t, r):
    nl = len(t["lights"])
    samples = r.u64()
    nodes = r.u64()
    vis_words = r.u32()
    layout = r.u8()
    if samples != t["nx"] * t["ny"]:
        raise FormatError("TREE: samples %d, not nx x ny" % samples)
    if layout & ~3:
        raise FormatError("TREE: layout reserved bits")
    if bool(layout & 1) != (1 <= nl <= 32):
        raise FormatError("TREE: vis bit against %d lights" % nl)
    if vis_words != ((nl + 31) // 32 if nl > 32 else 0):
        raise FormatError("TREE: vis_words %d" % vis_words)
    r.need(samples, "counts")
    counts = [r.varint(10, 64, "count") for _ in range(samples)]
    total = 0
    for c in counts:
        if c >= 1 << 31:
            raise FormatError("TREE: count too large")
        total += c
    if total >= 1 << 31 or total != nodes:
        raise FormatError("TREE: counts add to %d, not %d" % (total, nodes))
    start = [0] * (samples + 1)
    for k, c in enumerate(counts):
        start[k + 1] = start[k] + c
    has_vis = layout & 1
    wide = layout & 2
    node_at = r.i
    P = [None] * nodes  # [bits p0, p1, p2, prim, vis, link]
    if t["major"] >= 2:
        r.need(nodes * (5 + (1 if has_vis else 0)), "nodes")
        for k in range(samples):
            for j in range(counts[k]):
                A, B = predictors(P, start, counts, k, j)
                n = [0] * 6
                for i in range(3):
                    pred = (2 * A[i] - B[i]) if B else A[i]
                    n[i] = (pred + unzz(r.v32("node"))) & 0xFFFFFFFF
                n[3] = (A[3] + unzz(r.v32("node"))) & 0xFFFFFFFF
                n[4] = (r.v32("node") ^ A[4]) if has_vis else 0
                if wide:
                    n[5] = r.v32("node") ^ A[5]
                else:
                    n[5] = r.u8("node") ^ (A[5] & 0xFF)
                P[start[k] + j] = n
    else:
        r.need(nodes * (16 + (4 if has_vis else 0) + (4 if wide else 1)),
               "nodes")
        for q in range(nodes):
            n = [r.u32() for _ in range(4)]
            n.append(r.u32() if has_vis else 0)
            n.append(r.u32() if wide else r.u8())
            P[q] = n
    t["node_bytes"] = r.i - node_at
    vis_ext = []
    if vis_words:
        r.need(nodes * vis_words * 4, "vis_ext")
        vis_ext = [r.u32() for _ in range(nodes * vis_words)]
    r.end()
    # every node's fields
    np_ = t["geom"]["nprims"]
    for q, n in enumerate(P):
        for i in range(3):
            if not math.isfinite(unbits(n[i])):
                raise FormatError("TREE: node %d position not finite" % q)
        if n[3] >= np_:
            raise FormatError("TREE: node %d primitive %d" % (q, n[3]))
        if has_vis and nl < 32 and n[4] >> nl:
            raise FormatError("TREE: node %d light bits" % q)
        ln = n[5]
        if ln & 0xC0:
            raise FormatError("TREE: node %d link reserved bits" % q)
        if (ln & 6) == 6 or (ln & 24) == 24:
            raise FormatError("TREE: node %d link both hit and left" % q)
        if not ln & 8 and ln >> 8:
            raise FormatError("TREE: node %d offset without refraction" % q)
    if vis_words and nl % 32:
        for q in range(nodes):
            if vis_ext[q * vis_words + vis_words - 1] >> (nl % 32):
                raise FormatError("TREE: node %d light bits" % q)
    # each sample exactly one preorder tree, no deeper than max_depth
    maxd = t["max_depth"]
    for k in range(samples):
        a, b = start[k], start[k + 1]
        if a == b:
            continue
        # iterative walk: (index, depth) -> end index
        end = walk(P, a, b, maxd)
        if end != b:
            raise FormatError("TREE: sample %d is not one tree" % k)
    t["samples"] = samples
    t["nodes"] = nodes
    t["vis_words"] = vis_words
    t["layout"] = layout
    t["counts"] = counts
    t["node_list"] = P
    t["vis_ext"] = vis_ext


def walk(P, i, b, maxd):
    """End index of the subtree at i (preorder), checking links and depth."""
    # explicit stack: frames [node, depth, state]
    stack = [[i, 1, 0]]
    ret = None
    while stack:
        f = stack[-1]
        q, d, st = f
        ln = P[q][5]
        if st == 0:
            if d > maxd:
                raise FormatError("TREE: node %d deeper than max_depth" % q)
            f[2] = 1
            if ln & 2:
                if q + 1 >= b:
                    raise FormatError("TREE: node %d reflected child outside"
                                      % q)
                stack.append([q + 1, d + 1, 0])
                continue
            ret = q + 1
        if f[2] == 1:
            f[2] = 2
            if ln & 8:
                off = ln >> 8
                if off == 0 or q + off != ret or ret >= b:
                    raise FormatError("TREE: node %d refracted offset %d"
                                      % (q, off))
                stack.append([ret, d + 1, 0])
                continue
        stack.pop()
    return ret


# ---------------------------------------------------------------- writing


def w_u8(v):
    return struct.pack("<B", v)


def w_u32(v):
    return struct.pack("<I", v)


def w_f32(*v):
    return struct.pack("<%df" % len(v), *v)


def w_f64(*v):
    return struct.pack("<%dd" % len(v), *v)


def w_str(b):
    if len(b) > 255:
        raise ValueError("string longer than 255 bytes")
    return w_u8(len(b)) + b


def section(tag, body):
    return tag + struct.pack("<Q", len(body)) + body + w_u32(crc(tag, body))


def encode_sections(t):
    """[(tag, body)] of the required sections, from the parsed values."""
    out = []
    out.append((b"HEAD", struct.pack(
        "<8Id4I", t["major"], t["minor"], t["width"], t["height"], t["nx"],
        t["ny"], t["spd"], t["max_depth"], t["min_weight"], t["full_width"],
        t["full_height"], t["region_x"], t["region_y"])))
    c = t["scene"]
    out.append((b"SCEN", w_f64(*(c["from"] + c["at"] + c["up"]),
                               c["angle"], c["hither"])
                + w_f32(*(c["background"] + c["ambient"]))
                + w_f64(c["light_scale"])))
    b = w_u32(len(t["materials"]))
    for m in t["materials"]:
        b += w_f32(*m["color"], *[m[k] for k in MAT_F]) + w_u8(m["tex"])
        b += w_f32(*m["color2"], m["tex_scale"]) + w_u32(m["tex_image"])
        b += w_u8(m["bump"]) + w_u32(m["bump_image"])
        b += w_f32(m["bump_strength"], m["bump_scale"]) + w_str(m["name"])
        b += w_f32(m["ks0"], m["kt0"], m["ior0"]) + w_u8(m["bump0"])
        b += w_u32(m["bump0_image"])
        b += w_f32(m["bump0_strength"], m["bump0_scale"])
    out.append((b"MATL", b))
    own = [(i, m["ka"]) for i, m in enumerate(t["materials"]) if m.get("ka")]
    if own:
        b = w_u32(len(own))
        for i, ka in own:
            b += w_u32(i) + w_f32(*ka)
        out.append((b"MAMB", b))
    b = w_u32(len(t["lights"]))
    for li in t["lights"]:
        b += w_f64(*li["pos"]) + w_f32(*li["color"]) + w_u8(li["on"])
        b += w_str(li["name"]) + w_f64(*li["pos0"])
    out.append((b"LITE", b))
    if t["textures"]:
        allb = t["tex_tag"] == "TEXB"
        b = w_u32(len(t["textures"]))
        for x in t["textures"]:
            b += w_str(x["path"]) + w_u32(x["width"]) + w_u32(x["height"])
            if allb:
                b += bytes(x["texels"])
            else:
                b += w_f32(*x["texels"])
        out.append((t["tex_tag"].encode(), b))
    g = t["geom"]
    packed = t["major"] >= 2

    def group(rows, is_float):
        b = w_u32(len(rows))
        prev = None
        for row in rows:
            u = [bits(v) for v in row] if is_float else list(row)
            if packed:
                p = prev or [0] * len(u)
                b += b"".join(leb(zz(x - y)) for x, y in zip(u, p))
            else:
                b += b"".join(w_u32(x) for x in u)
            prev = u
        return b

    b = group(g["pos"], True) + group(g["nrm"], True) + group(g["uv"], True)
    b += group(g["tris"], False)
    b += w_u32(len(g["spheres"]))
    for s, m in g["spheres"]:
        b += w_f32(*s) + w_u32(m)
    b += w_u32(len(g["cones"]))
    for cn, m in g["cones"]:
        b += w_f32(*cn) + w_u32(m)
    out.append((b"GEOM", b))
    out.append((b"TREE", encode_tree(t)))
    out.append((b"END ", b""))
    return out


def encode_tree(t):
    counts = t["counts"]
    P = t["node_list"]
    layout = t["layout"]
    b = bytearray(struct.pack("<QQIB", len(counts), len(P), t["vis_words"],
                              layout))
    for c in counts:
        b += leb(c)
    start = [0]
    for c in counts:
        start.append(start[-1] + c)
    if t["major"] >= 2:
        for k in range(len(counts)):
            for j in range(counts[k]):
                A, B = predictors(P, start, counts, k, j)
                n = P[start[k] + j]
                for i in range(3):
                    pred = (2 * A[i] - B[i]) if B else A[i]
                    b += leb(zz(n[i] - pred))
                b += leb(zz(n[3] - A[3]))
                if layout & 1:
                    b += leb(n[4] ^ A[4])
                if layout & 2:
                    b += leb(n[5] ^ A[5])
                else:
                    b += w_u8((n[5] ^ A[5]) & 0xFF)
    else:
        for n in P:
            b += b"".join(w_u32(x) for x in n[:4])
            if layout & 1:
                b += w_u32(n[4])
            b += w_u32(n[5]) if layout & 2 else w_u8(n[5])
    for v in t["vis_ext"]:
        b += w_u32(v)
    return bytes(b)


def encode(t, extensions=()):
    """The whole file; extensions [(position, tag, body)] inserted before the
    required section numbered position (0: before HEAD)."""
    secs = encode_sections(t)
    out = bytearray(SIGNATURE)
    for i, (tag, body) in enumerate(secs):
        for pos, xt, xb in extensions:
            if pos == i:
                out += section(xt, xb)
        out += section(tag, body)
    return bytes(out)


# ---------------------------------------------------------------- summary


def summary(name, t):
    g = t["geom"]
    px = t["width"] * t["height"]
    c = t["scene"]
    fm = lambda v: ",".join("%g" % x for x in v)
    lines = [
        "%s: format %d.%d, %dx%d image, %d samples, depth %d%s"
        % (name, t["major"], t["minor"], t["width"], t["height"],
           t["samples"], t["max_depth"], ", SPD" if t["spd"] else ""),
        "nodes %d (%.3f per sample, %.2f bytes each in the file), layout %d,"
        " vis_words %d" % (t["nodes"], t["nodes"] / t["samples"],
                           t["node_bytes"] / max(t["nodes"], 1), t["layout"],
                           t["vis_words"]),
        "file %d bytes = %.2f x the raw 8-bit RGB image (%d bytes)"
        % (t["file_bytes"], t["file_bytes"] / (3 * px), 3 * px),
        "scene: %d triangles, %d spheres, %d cones; %d materials, %d lights;"
        " %d textures (%s)" % (len(g["tris"]), len(g["spheres"]),
                               len(g["cones"]), len(t["materials"]),
                               len(t["lights"]), len(t["textures"]),
                               t["tex_tag"]),
        "camera: from=%s at=%s up=%s angle=%g hither=%g" % (
            fm(c["from"]), fm(c["at"]), fm(c["up"]), c["angle"], c["hither"]),
        "sections: %s" % " ".join(x.decode() for x in t["tags"]),
    ]
    return "\n".join(lines)


def info_keys(t):
    """What `rtp info --stats` should say, from the file alone."""
    px = t["width"] * t["height"]
    return {"width": t["width"], "height": t["height"],
            "spd": bool(t["spd"]), "pixels": px, "samples": t["samples"],
            "nodes": t["nodes"], "bytes_per_node": 24,
            "lights": len(t["lights"]), "materials": len(t["materials"]),
            "depth": t["max_depth"], "full_width": t["full_width"],
            "full_height": t["full_height"], "region_x": t["region_x"],
            "region_y": t["region_y"], "min_weight": t["min_weight"],
            "file_bytes": t["file_bytes"], "tree_bytes": tree_bytes(t)}


def info_text_keys(text):
    """{'camera.from': '0,-5,1.5', 'light.0.on': '1', 'mat.1.bump': ...}
    and the scene line's counts from `rtp info`'s text."""
    keys = {}
    item = None
    for line in text.splitlines():
        if line.startswith("scene: "):
            keys["scene"] = line[7:]
        elif line.startswith("nodes "):
            keys["nodes_line"] = line
        head, sep, rest = line.partition(":")
        if line.startswith("    "):
            rest, prefix = line, item
        elif sep and (head in ("camera", "environment") or
                      head.startswith(("light.", "mat."))):
            item = head.split(" ")[0]
            prefix = "" if head == "environment" else item
        else:
            continue
        for kv in rest.split():
            if "=" in kv:
                k, v = kv.split("=", 1)
                keys[(prefix + "." if prefix else "") + k] = v
    return keys


def expected_text_keys(t):
    g = t["geom"]
    c = t["scene"]
    pl = lambda n, one, many: "%d %s" % (n, one if n == 1 else many)
    e = {"scene": "%s, %s, %s; %s, %s" % (
        pl(len(g["tris"]), "triangle", "triangles"),
        pl(len(g["spheres"]), "sphere", "spheres"),
        pl(len(g["cones"]), "cone", "cones"),
        pl(len(t["materials"]), "material", "materials"),
        pl(len(t["lights"]), "light", "lights"))}
    e["nodes_line"] = "nodes %d (%.3f per sample), 24 bytes per node, " \
        "trees %d bytes" % (t["nodes"], t["nodes"] / t["samples"],
                            tree_bytes(t))
    for k in ("from", "at", "up", "angle", "hither"):
        e["camera." + k] = c[k]
    e["ambient"], e["background"] = c["ambient"], c["background"]
    for i, li in enumerate(t["lights"]):
        p = "light.%d." % i
        e[p + "pos"], e[p + "color"], e[p + "on"] = li["pos"], li["color"], \
            li["on"]
    for i, m in enumerate(t["materials"]):
        p = "mat.%d." % i
        for k in ("color", "kd", "ks", "kt", "shine", "ior"):
            e[p + k] = m[k]
        if m.get("ka") and m["ka"] != [m["kd"]] * 3:
            e[p + "ambient"] = m["ka"]
        if m["tex"] == 1:
            e[p + "checker"] = 1
            e[p + "color2"] = m["color2"]
            e[p + "checker_scale"] = m["tex_scale"]
        if m["tex"] == 2:
            e[p + "texture"] = t["textures"][m["tex_image"]]["path"].decode()
        if m["bump"]:
            e[p + "bump"] = [None, None, "waves", "noise"][m["bump"]] or \
                t["textures"][m["bump_image"]]["path"].decode()
            e[p + "bump_strength"] = m["bump_strength"]
            e[p + "bump_scale"] = m["bump_scale"]
    return e


def same_value(text, want):
    if isinstance(want, str):
        return text == want
    if not isinstance(want, list):
        want = [want]
    try:
        got = [float(x) for x in text.split(",")]
    except ValueError:
        return False
    return len(got) == len(want) and all(
        abs(a - b) <= 1e-5 * max(abs(b), 1e-30) for a, b in zip(got, want))


def tree_bytes(t):
    """What rtp_tree_info's tree_bytes says of this file (README: the
    trees in memory, 24 bytes a node, 4 a light word, 8 a sample start)."""
    return t["nodes"] * (24 + 4 * t["vis_words"]) + 8 * (t["samples"] + 1)


def check_against_rtp(rtp, path, data, t):
    errs = []
    again = encode(t, [(i, tag, body) for i, (tag, body) in
                       enumerate_extensions(t)])
    if again != data:
        k = next((i for i in range(min(len(again), len(data)))
                  if again[i] != data[i]), min(len(again), len(data)))
        errs.append("re-encoded from the spec differs from rtp's file at "
                    "byte %d (%d vs %d bytes)" % (k, len(again), len(data)))
    errs += writer_rules(t)
    p = subprocess.run([rtp, "info", path, "--stats", "-", "-q"],
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    if p.returncode != 0:
        errs.append("rtp info failed: %s" % p.stderr.decode().strip())
    else:
        got = json.loads(p.stdout)
        for k, v in info_keys(t).items():
            if k not in got:
                errs.append("rtp info --stats has no %s" % k)
            elif got[k] != v and not (isinstance(v, float)
                                      and abs(got[k] - v) <= 1e-6 * abs(v)):
                errs.append("info %s: rtp %r, spec %r" % (k, got[k], v))
    p = subprocess.run([rtp, "info", path], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE)
    got = info_text_keys(p.stdout.decode(errors="replace"))
    for k, v in expected_text_keys(t).items():
        if k not in got:
            errs.append("rtp info's text has no %s" % k)
        elif not same_value(got[k], v):
            errs.append("info %s: rtp %r, spec %r" % (k, got[k], v))
    return errs


def writer_rules(t):
    """What the document says a writer does, beyond the bytes themselves."""
    errs = []
    nt = len(t["textures"])
    used = set()
    for i, m in enumerate(t["materials"]):
        for kind, want, ix in (("tex", 2, "tex_image"),
                               ("bump", 1, "bump_image"),
                               ("bump0", 1, "bump0_image")):
            if m[kind] == want:
                used.add(m[ix])
            elif m[ix] != NONE32:
                errs.append("mat %d: %s not in use but not 0xffffffff"
                            % (i, ix))
    if used != set(range(nt)):
        errs.append("textures written %d, used %s" % (nt, sorted(used)))
    if t["tex_tag"] == "TEXR" and all(
            f32_of(v) in TEXB_SET for x in t["textures"] for v in x["texels"]):
        errs.append("TEXR though every texel is k/255 (TEXB)")
    if t["layout"] & 2 == 0 and any(n[5] & 8 for n in t["node_list"]):
        errs.append("a refracted subtree without full link words")
    return errs


def enumerate_extensions(t):
    """(required-section position, tag, body) of the file's extensions."""
    pos = 0
    out = []
    for tag in t["tags"]:
        if is_extension(tag):
            body = [b for x, b in t["extensions"] if x == tag][0]
            out.append((pos, tag, body))
        else:
            pos += 1
    return out



# ------------------------------------------------------------ crafted files


def raw_file(secs):
    return SIGNATURE + b"".join(section(t, b) for t, b in secs)


def with_secs(t, fn):
    secs = encode_sections(t)
    fn(secs)
    return raw_file(secs)


def idx(secs, tag):
    return [s[0] for s in secs].index(tag)


def patch_body(tag, fn):
    def f(secs):
        i = idx(secs, tag)
        secs[i] = (secs[i][0], fn(secs[i][1]))
    return f


def edited(t, fn):
    import copy
    u = copy.deepcopy(t)
    fn(u)
    return encode(u)


def long_varint(v, n):
    """v as an n-byte LEB128 (longer than the shortest form)."""
    out = bytearray()
    for k in range(n):
        b = (v >> (7 * k)) & 0x7F
        out.append(b | (0x80 if k < n - 1 else 0))
    return bytes(out)


def tree_with_counts(t, enc):
    """TREE body whose sample counts are written by enc(count)."""
    body = encode_tree(t)
    head = 21
    c = b"".join(leb(x) for x in t["counts"])
    return body[:head] + b"".join(enc(x) for x in t["counts"]) + \
        body[head + len(c):]


def cases(t):
    """(name, bytes, expectation): None = accepted, else a word the error
    message must hold (case-insensitive)."""
    nt = len(t["materials"])
    out = []
    acc = lambda n, d: out.append((n, d, None))
    ref = lambda n, d, w: out.append((n, d, w))
    ext = (b"ext1", b"any bytes \x00\xff")
    acc("as written", encode(t))
    for pos in range(len(encode_sections(t)) ):
        acc("extension before required section %d" % pos,
            encode(t, [(pos, ext[0], ext[1])]))
    acc("extensions everywhere, empty ones too",
        encode(t, [(p, b"z   ", b"") for p in range(8)] +
               [(3, b"a~ !", b"\x89RTP")]))
    acc("counts in longer varints (10 bytes)",
        with_secs(t, patch_body(b"TREE", lambda b: tree_with_counts(
            t, lambda x: long_varint(x, 10)))))
    acc("minor version 1 (2.1)", edited(t, lambda u: u.update(minor=1)))
    if t["major"] == 2:
        acc("format 1.0 of the same file",
            edited(t, lambda u: u.update(major=1)))
        acc("full link words though not needed",
            edited(t, lambda u: u.update(layout=u["layout"] | 2)))
    if t["textures"]:
        acc("TEXR though every texel is k/255",
            edited(t, lambda u: [u.update(tex_tag="TEXR")] +
                   [x.update(texels=[TEXB[k] for k in x["texels"]])
                    for x in u["textures"] if u["tex_tag"] == "TEXB"]))
    acc("an unused texture index not 0xffffffff",
        edited(t, lambda u: [m.update(tex_image=12345) for m in
                             u["materials"] if m["tex"] != 2]))
    acc("a UTF-8 name and an empty one",
        edited(t, lambda u: [u["materials"][0].update(
            name="Glas\u00e4".encode()), u["materials"][-1].update(name=b"")]))
    # refused
    ref("an unknown required section", encode(t, [(3, b"ABCD", b"")]),
        "unknown required section")
    if any(m.get("ka") for m in t["materials"]):
        # an older reader's view of MAMB: a required tag it does not know
        ref("MAMB under another upper-case tag",
            with_secs(t, lambda secs: secs.__setitem__(
                idx(secs, b"MAMB"), (b"MAMX", secs[idx(secs, b"MAMB")][1]))),
            "unknown required section")
        def after_lite(secs):
            m = secs.pop(idx(secs, b"MAMB"))
            secs.insert(idx(secs, b"LITE") + 1, m)
        ref("MAMB after LITE", with_secs(t, after_lite), "out of order")
        ref("MAMB twice", with_secs(t, lambda secs: secs.insert(
            idx(secs, b"MAMB"), secs[idx(secs, b"MAMB")])), "repeated")
        ref("MAMB a byte longer (CRC right)",
            with_secs(t, patch_body(b"MAMB", lambda b: b + b"\0")),
            "unexpected bytes")
        ref("MAMB a byte shorter (CRC right)",
            with_secs(t, patch_body(b"MAMB", lambda b: b[:-1])), "MAMB")
        ref("MAMB with a count of 0",
            with_secs(t, patch_body(b"MAMB", lambda b: w_u32(0))), "count")
        first = next(i for i, m in enumerate(t["materials"]) if m.get("ka"))
        ref("MAMB's ka negative", edited(t, lambda u: u["materials"][first]
                                         .update(ka=[0.5, -0.25, 1.0])),
            "negative ambient")
        ref("MAMB's ka NaN", with_secs(t, patch_body(
            b"MAMB", lambda b: b[:8] + struct.pack("<f", float("nan")) +
            b[12:])), "not finite")
        ref("MAMB's ka infinite", with_secs(t, patch_body(
            b"MAMB", lambda b: b[:12] + struct.pack("<f", float("inf")) +
            b[16:])), "not finite")
        ref("MAMB's index past the materials", with_secs(t, patch_body(
            b"MAMB", lambda b: b[:4] + w_u32(nt) + b[8:])), "out of range")
        if sum(1 for m in t["materials"] if m.get("ka")) > 1:
            ref("MAMB's indices not ascending", with_secs(t, patch_body(
                b"MAMB", lambda b: b[:4] + b[20:36] + b[4:20] + b[36:])),
                "ascending")
    else:
        ref("MAMB's index past the materials", with_secs(t, lambda secs:
            secs.insert(idx(secs, b"MATL") + 1, (b"MAMB", w_u32(1) +
                        w_u32(nt) + w_f32(1.0, 1.0, 1.0)))), "out of range")
    ref("major version 3", edited(t, lambda u: u.update(major=3)),
        "newer rtp")
    ref("HEAD 4 bytes longer (CRC right)",
        with_secs(t, patch_body(b"HEAD", lambda b: b + b"\0\0\0\0")), "HEAD")
    ref("TREE a byte shorter (CRC right)",
        with_secs(t, patch_body(b"TREE", lambda b: b[:-1])), "TREE")
    ref("a CRC off by one",
        (lambda d: d[:-1] + bytes([d[-1] ^ 1]))(encode(t)), "checksum")
    ref("an extension's CRC off",
        (lambda d: d[:8 + 12 + 2] + bytes([d[22] ^ 1]) + d[23:])(
            encode(t, [(0, b"ext1", b"abcd")])), "checksum")
    ref("length past the end",
        (lambda d: d[:12] + struct.pack("<Q", 1 << 62) + d[20:])(encode(t)),
        "HEAD")
    ref("SCEN before HEAD",
        with_secs(t, lambda s: s.insert(0, s.pop(1))), "order")
    ref("MATL twice",
        with_secs(t, lambda s: s.insert(3, s[2])), "repeated")
    ref("GEOM missing",
        with_secs(t, lambda s: s.pop(idx(s, b"GEOM"))), "order")
    ref("TEXR and TEXB both",
        with_secs(t, lambda s: s.insert(idx(s, b"LITE") + 1, (b"TEXR", b"\0\0\0\0"))
                  or s.insert(idx(s, b"LITE") + 2, (b"TEXB", b"\0\0\0\0"))),
        "repeated")
    ref("bytes after END", encode(t) + b"\0", "END")
    ref("a tag with a control byte", encode(t, [(2, b"ab\x01d", b"")]),
        "tag")
    ref("a section after END", encode(t) + section(b"ext1", b""), "END")
    ref("counts in 11-byte varints",
        with_secs(t, patch_body(b"TREE", lambda b: tree_with_counts(
            t, lambda x: long_varint(x, 11)))), "TREE")
    ref("a negative kd", edited(t, lambda u: u["materials"][0].update(
        kd=-0.5)), "MATL")
    ref("an ior of 0", edited(t, lambda u: u["materials"][0].update(
        ior=0.0)), "MATL")
    ref("a NUL in a name", edited(t, lambda u: u["materials"][0].update(
        name=b"a\0b")), "MATL")
    ref("a NaN in the camera", edited(t, lambda u: u["scene"].update(
        hither=float("nan"))), "SCEN")
    ref("an angle of 180", edited(t, lambda u: u["scene"].update(
        angle=180.0)), "SCEN")
    ref("no view: at on from", edited(t, lambda u: u["scene"].update(
        at=list(u["scene"]["from"]))), "SCEN")
    ref("light scale 2", edited(t, lambda u: u["scene"].update(
        light_scale=2.0)), "SCEN")
    ref("a negative light colour", edited(t, lambda u: u["lights"][0].update(
        color=[1.0, -1.0, 1.0])) if t["lights"] else None, "LITE")
    ref("image width 0", edited(t, lambda u: u.update(width=0, nx=u["spd"])),
        "HEAD")
    ref("sample grid not the image's", edited(t, lambda u: u.update(
        nx=u["nx"] + 1)), "HEAD")
    ref("depth 0", edited(t, lambda u: u.update(max_depth=0)), "HEAD")
    ref("a material index past the list", edited(
        t, lambda u: u["geom"]["spheres"].__setitem__(
            0, (u["geom"]["spheres"][0][0], nt)))
        if t["geom"]["spheres"] else None, "GEOM")
    ref("a sphere of radius 0", edited(
        t, lambda u: u["geom"]["spheres"][0][0].__setitem__(3, 0.0))
        if t["geom"]["spheres"] else None, "GEOM")
    ref("a vertex index past the list", edited(
        t, lambda u: u["geom"]["tris"][0].__setitem__(
            1, len(u["geom"]["pos"]))) if t["geom"]["tris"] else None, "GEOM")
    if t["nodes"]:
        q = 0
        ref("a node's primitive past the list", edited(
            t, lambda u: u["node_list"][q].__setitem__(
                3, u["geom"]["nprims"])), "TREE")
        ref("a reserved link bit", edited(
            t, lambda u: u["node_list"][q].__setitem__(
                5, u["node_list"][q][5] | 0x40)), "TREE")
        ref("a node offset without refraction", edited(
            t, lambda u: [u.update(layout=u["layout"] | 2),
                          u["node_list"][q].__setitem__(
                              5, u["node_list"][q][5] | 0x300)]), "TREE")
        ref("counts adding to more than nodes", with_secs(t, patch_body(
            b"TREE", lambda b: b[:8] + struct.pack("<Q", t["nodes"] + 1) +
            b[16:])), "TREE")
        ref("sample count not nx x ny", with_secs(t, patch_body(
            b"TREE", lambda b: struct.pack("<Q", t["samples"] + 1) + b[8:])),
            "TREE")
        ref("a node NaN", edited(t, lambda u: u["node_list"][q].__setitem__(
            0, 0x7FC00000)), "TREE")
        # the same at the last node: its sample's bytes are fewer than 30
        # a node (the section ends), so each reader decodes it a node at
        # a time (unpack_node), not by the sample's fast path
        # (unpack_sample_30) the first node takes
        last = t["nodes"] - 1
        ref("the last node's primitive past the list", edited(
            t, lambda u: u["node_list"][last].__setitem__(
                3, u["geom"]["nprims"])), "invalid node")
        ref("the last node NaN", edited(
            t, lambda u: u["node_list"][last].__setitem__(2, 0x7FC00000)),
            "invalid node")
        ref("the last node infinite", edited(
            t, lambda u: u["node_list"][last].__setitem__(1, 0xFF800000)),
            "invalid node")
        if 1 <= len(t["lights"]) < 32:
            ref("a bit for a light that does not exist", edited(
                t, lambda u: u["node_list"][q].__setitem__(
                    4, 1 << len(u["lights"]))), "TREE")
        if t["layout"] & 1:
            ref("no vis words though lights", edited(
                t, lambda u: u.update(layout=u["layout"] & ~1)), "TREE")
        deep = max(range(t["nodes"]), key=lambda q: t["node_list"][q][5] & 10)
        if t["node_list"][deep][5] & 10:
            ref("a tree deeper than max_depth", edited(
                t, lambda u: u.update(max_depth=1)), "TREE")
            ref("a child flag with the sample's last node", edited(
                t, lambda u: [u.update(layout=u["layout"] | 2)] +
                [u["node_list"][u["counts"][0] - 1].__setitem__(5, 2)
                 if u["counts"][0] else None]) if t["counts"][0] else None,
                "TREE")
        # a v32 of 6 bytes: the first node's prim
        if t["major"] == 2:
            ref("a 6-byte node varint", with_secs(t, patch_body(
                b"TREE", lambda b: long_first_node(t, b, 6))), "TREE")
    more_cases(t, out)
    return [c for c in out if c[1] is not None]


def more_cases(t, out):
    """What the document says since a reader from it had to guess."""
    acc = lambda n, d: out.append((n, d, None))
    ref = lambda n, d, w: out.append((n, d, w))
    m0 = lambda **kw: edited(t, lambda u: u["materials"][0].update(**kw))
    if t["lights"]:
        ref("light on=2", edited(t, lambda u: u["lights"][0].update(on=2)),
            "light value out of range")
        acc("a moved light (pos0 differs)", edited(
            t, lambda u: u["lights"][0].update(pos0=[9.0, 9.0, 9.0])))
    ref("spd=2", edited(t, lambda u: u.update(spd=2)), "HEAD")
    ref("a region past the frame", edited(t, lambda u: u.update(
        region_x=u["full_width"] - u["width"] + 1)), "region outside")
    ref("min_weight -1", edited(t, lambda u: u.update(min_weight=-1.0)),
        "HEAD")
    ref("tex kind 3", m0(tex=3), "unknown texture or bump kind")
    ref("bump kind 4", m0(bump=4), "unknown texture or bump kind")
    ref("bump0 kind 4", m0(bump0=4), "unknown texture or bump kind")
    ref("ior0 0", m0(ior0=0.0), "MATL")
    ref("ks0 -1", m0(ks0=-1.0), "MATL")
    ref("bump0_scale 0", m0(bump0_scale=0.0), "MATL")
    ref("color2 -1", m0(color2=[-1.0, 0.0, 0.0]), "MATL")
    ref("checker scale 0", m0(tex_scale=0.0), "MATL")
    ref("hither -1", edited(t, lambda u: u["scene"].update(hither=-1.0)),
        "SCEN")
    ref("a negative ambient", edited(t, lambda u: u["scene"].update(
        ambient=[0.0, -0.1, 0.0])), "SCEN")
    ref("up along the view", edited(t, lambda u: u["scene"].update(
        up=[a - b for a, b in zip(u["scene"]["at"], u["scene"]["from"])])),
        "SCEN")
    acc("bump0 image out of range (never looked up)",
        m0(bump0=1, bump0_image=99))
    acc("a texture no material uses", edited(
        t, lambda u: [u.update(tex_tag=u["tex_tag"] or "TEXB"),
                      u["textures"].append({"path": b"x", "width": 1,
                                            "height": 1,
                                            "texels": [1, 2, 3]})]))
    acc("a negative TEXR texel", edited(
        t, lambda u: [u.update(tex_tag="TEXR")] +
        [x.update(texels=[TEXB[k] for k in x["texels"]])
         for x in u["textures"] if u["tex_tag"] == "TEXB"] +
        [u["textures"].append({"path": b"neg.pfm", "width": 1, "height": 1,
                               "texels": [-0.5, 0.25, 2.0]})]))
    ref("a texture of width 0", edited(
        t, lambda u: [u.update(tex_tag=u["tex_tag"] or "TEXB"),
                      u["textures"].append({"path": b"x", "width": 0,
                                            "height": 1, "texels": []})]),
        "invalid texture size")
    ref("a texture a material names but the file lacks",
        m0(tex=2, tex_image=len(t["textures"])), "texture")
    tn = [i for i, tr in enumerate(t["geom"]["tris"]) if tr[3] != NONE32]
    if tn:
        ref("normals partly absent", edited(
            t, lambda u: u["geom"]["tris"][tn[0]].__setitem__(4, NONE32)),
            "GEOM")
    ta = [i for i, tr in enumerate(t["geom"]["tris"]) if tr[6] == NONE32]
    if ta and t["geom"]["uv"]:
        ref("uvs partly present", edited(
            t, lambda u: u["geom"]["tris"][ta[0]].__setitem__(6, 0)), "GEOM")
    inf, nan = float("inf"), float("nan")
    g = t["geom"]
    if g["pos"]:
        ref("an infinite vertex", edited(
            t, lambda u: u["geom"]["pos"][0].__setitem__(1, inf)), "GEOM")
    if g["nrm"]:
        ref("a NaN normal", edited(
            t, lambda u: u["geom"]["nrm"][0].__setitem__(2, nan)), "GEOM")
    if g["uv"]:
        ref("an infinite uv", edited(
            t, lambda u: u["geom"]["uv"][0].__setitem__(0, -inf)), "GEOM")
    if g["spheres"]:
        ref("an infinite sphere centre", edited(
            t, lambda u: u["geom"]["spheres"][0][0].__setitem__(0, inf)),
            "GEOM")
        acc("a negative sphere (inside visible only)", edited(
            t, lambda u: u["geom"]["spheres"][0][0].__setitem__(
                3, -abs(u["geom"]["spheres"][0][0][3]))))
    if t["lights"]:
        ref("a NaN traced light position", edited(
            t, lambda u: u["lights"][0]["pos0"].__setitem__(0, nan)), "LITE")
        ref("a NUL in a light's name", edited(
            t, lambda u: u["lights"][0].update(name=b"\0")), "LITE")
    if t["textures"]:
        ref("a NUL in a texture's path", edited(
            t, lambda u: u["textures"][0].update(path=b"a\0")), "TEX")
    ref("a NaN min_weight", edited(t, lambda u: u.update(
        min_weight=nan)), "HEAD")
    ref("an infinite light scale", edited(t, lambda u: u["scene"].update(
        light_scale=inf)), "SCEN")
    ref("a NaN bump strength", m0(bump_strength=nan), "MATL")
    acc("a negative bump strength", m0(bump_strength=-2.0))
    ref("depth 1001", edited(t, lambda u: u.update(max_depth=1001)), "HEAD")
    acc("a region at the frame's far corner", edited(t, lambda u: u.update(
        full_width=u["full_width"] + 7, full_height=u["full_height"] + 3,
        region_x=u["region_x"] + 7, region_y=u["region_y"] + 3)))
    ref("a frame of 2^20 + 1 across", edited(t, lambda u: u.update(
        full_width=(1 << 20) + 1)), "HEAD")
    if t["geom"]["cones"]:
        ref("a cone with its apex on its base", edited(
            t, lambda u: [u["geom"]["cones"][0][0].__setitem__(
                4 + k, u["geom"]["cones"][0][0][k]) for k in range(3)]),
            "GEOM")
        ref("a cone with a negative radius", edited(
            t, lambda u: u["geom"]["cones"][0][0].__setitem__(3, -1.0)),
            "GEOM")
    # counts far past the bytes: refused before anything is allocated
    ref("2^31 - 1 materials in a short section", with_secs(t, patch_body(
        b"MATL", lambda b: w_u32(0x7FFFFFFF) + b[4:])), "MATL")
    ref("2^31 - 1 lights in a short section", with_secs(t, patch_body(
        b"LITE", lambda b: w_u32(0x7FFFFFFF) + b[4:])), "LITE")
    ref("2^31 - 1 vertices in a short section", with_secs(t, patch_body(
        b"GEOM", lambda b: w_u32(0x7FFFFFFF) + b[4:])), "GEOM")
    ref("2^40 nodes in a short section", with_secs(t, patch_body(
        b"TREE", lambda b: b[:8] + struct.pack("<Q", 1 << 40) + b[16:])),
        "TREE")
    ref("a 2^20 x 2^7 texture in a short section", edited(
        t, lambda u: [u.update(tex_tag="TEXB"), u["textures"].append(
            {"path": b"x", "width": 1 << 20, "height": 1 << 7,
             "texels": [0] * 3})]), "texture")
    if t["geom"]["cones"]:
        ref("a cone with both radii 0", edited(
            t, lambda u: [u["geom"]["cones"][0][0].__setitem__(3, 0.0),
                          u["geom"]["cones"][0][0].__setitem__(7, 0.0)]),
            "GEOM")
    if t["nodes"]:
        acc("link bit 5 on a node without a reflected child", edited(
            t, lambda u: [n.__setitem__(5, n[5] | 32)
                          for n in u["node_list"] if not n[5] & 2][:1]))
        if t["major"] == 2 and t["geom"]["pos"]:
            def long_vertex(b):
                r = Reader(b[4:], "x")
                v = r.v32("vertex")
                return b[:4] + long_varint(v, 5) + b[4 + r.i:]
            acc("a vertex number in 5 bytes (not the shortest)", with_secs(
                t, patch_body(b"GEOM", long_vertex)))
            ref("a vertex number in 6 bytes", with_secs(
                t, patch_body(b"GEOM", lambda b: b[:4] + long_varint(
                    Reader(b[4:], "x").v32("v"), 6) + b[4 + len(leb(
                        Reader(b[4:], "x").v32("v"))):])), "GEOM")
        if t["major"] == 2:
            acc("node varints in 5 bytes (not the shortest)", with_secs(
                t, patch_body(b"TREE", lambda b: long_first_node(t, b, 5))))
        if t["vis_words"] and len(t["lights"]) % 32:
            ref("a light word's bit past the lights", edited(
                t, lambda u: u["vis_ext"].__setitem__(
                    u["vis_words"] - 1, 1 << (len(u["lights"]) % 32))),
                "invalid light bits")
        refl = [q for q, n in enumerate(t["node_list"]) if n[5] & 2]
        if refl:
            ref("link bits 1 and 2 both", edited(
                t, lambda u: u["node_list"][refl[0]].__setitem__(
                    5, u["node_list"][refl[0]][5] | 4)), "malformed ray tree")
        refr = [q for q, n in enumerate(t["node_list"]) if n[5] & 8]
        if refr:
            ref("a refracted offset one too far", edited(
                t, lambda u: u["node_list"][refr[0]].__setitem__(
                    5, u["node_list"][refr[0]][5] + 256)),
                "malformed ray tree")


def long_first_node(t, b, n):
    """TREE body b with the first node's prim varint written in n bytes."""
    counts = b"".join(leb(x) for x in t["counts"])
    i = 21 + len(counts)
    r = Reader(b[i:], "x")
    for _ in range(3):
        r.v32("p")
    j = i + r.i
    r.v32("prim")
    return b[:j] + long_varint(zz(t["node_list"][0][3]), n) + b[i + r.i:]


def run_rtp(rtp, data, tmp):
    """(exit, stderr, image written?) of `rtp reeval FILE -i IMAGE`, and
    `rtp info FILE`'s exit, and (exit, stderr) of `rtp reeval FILE
    --stream` with no line (rtp_tree_read's whole read, which the others,
    rtp_tree_eval_file's bands and the summary, use only past 32 lights)."""
    f = os.path.join(tmp, "craft.rtp")
    img = os.path.join(tmp, "craft.ppm")
    with open(f, "wb") as fh:
        fh.write(data)
    if os.path.exists(img):
        os.remove(img)
    p = subprocess.run([rtp, "reeval", f, "-i", img, "-q", "-j", "1"],
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    q = subprocess.run([rtp, "info", f, "-q"], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE)
    s = subprocess.run([rtp, "reeval", f, "--stream", "-i", os.devnull, "-q",
                        "-j", "1"], stdin=subprocess.DEVNULL,
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    return p.returncode, p.stderr.decode(errors="replace"), \
        os.path.exists(img), q.returncode, \
        (s.returncode, s.stderr.decode(errors="replace"))


def craft(rtp, path, tmp, verbose=False):
    with open(path, "rb") as fh:
        t = parse(fh.read())
    good = bad = 0
    for name, data, want in cases(t):
        mine = None
        try:
            parse(data)
        except FormatError as e:
            mine = str(e)
        rc, err, img, irc, (src, serr) = run_rtp(rtp, data, tmp)
        why = []
        if want is None:
            if mine is not None:
                why.append("this reader refuses it: %s" % mine)
            if rc != 0 or irc != 0 or not img:
                why.append("rtp refuses it (exit %d, info %d): %s"
                           % (rc, irc, err.strip()))
            if src != 0:
                why.append("rtp reeval --stream refuses it (exit %d): %s"
                           % (src, serr.strip()))
        else:
            if mine is None:
                why.append("this reader accepts it")
            if rc != 1 or irc != 1 or img:
                why.append("rtp exit %d, info %d, image %s"
                           % (rc, irc, "written" if img else "none"))
            elif want.lower() not in err.lower():
                why.append("rtp's message lacks %r: %s" % (want, err.strip()))
            if src != 1:
                why.append("rtp reeval --stream exit %d" % src)
            elif want.lower() not in serr.lower():
                why.append("rtp reeval --stream's message lacks %r: %s"
                           % (want, serr.strip()))
        if verbose:
            print("%s %s: %s" % ("fail" if why else "ok", path, name))
        if why:
            bad += 1
            print("FAIL %s: %s: %s" % (path, name, "; ".join(why)))
        else:
            good += 1
    return good, bad


def main(argv):
    rtp = None
    if len(argv) > 2 and argv[0] == "--craft":
        import tempfile
        good = bad = 0
        with tempfile.TemporaryDirectory() as tmp:
            for path in argv[2:]:
                g, b = craft(argv[1], path, tmp,
                             os.environ.get("VERBOSE") == "1")
                good += g
                bad += b
        print("%d passed, %d failed" % (good, bad))
        return 1 if bad else 0
    if len(argv) > 2 and argv[0] == "--stats":
        # --stats FILE JSON...: trace's or reeval's --stats of FILE
        with open(argv[1], "rb") as fh:
            want = info_keys(parse(fh.read()))
        bad = 0
        for js in argv[2:]:
            with open(js) as fh:
                got = json.load(fh)
            for k in ("pixels", "samples", "nodes", "bytes_per_node",
                      "tree_bytes", "file_bytes"):
                if got.get(k) != want[k]:
                    print("%s: %s %r, the file says %r" % (js, k, got.get(k),
                                                           want[k]))
                    bad += 1
        return 1 if bad else 0
    if len(argv) > 1 and argv[0] == "--check":
        rtp = argv[1]
        argv = argv[2:]
    bad = 0
    for path in argv:
        with open(path, "rb") as f:
            data = f.read()
        try:
            t = parse(data)
        except FormatError as e:
            print("%s: refused: %s" % (path, e))
            bad += 1
            continue
        print(summary(path, t))
        if rtp:
            for e in check_against_rtp(rtp, path, data, t):
                print("%s: DISAGREES: %s" % (path, e))
                bad += 1
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
