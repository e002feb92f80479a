#!/usr/bin/env python3
"""Randomized differential tester: random --stream edit sets (every class mixed)
against full traces of the scene with the cumulative edits.

    python3 test/fuzz_streams.py [--cases N] [--seed S] [--out DIR] [--minutes M]

Each case traces a scene small (or an --spd region), draws 3-12 lines of 1-4
edits each from classes A-D (light moves, added lights, bumps, ks/kt from 0, ior,
edits back to the traced values, the same key twice), runs them as one
`reeval --stream` and compares every frame with `rtp trace SCENE --set <all edits
so far>` and some frames with a one-off `reeval --set <all edits so far>`.
A frame further than 1e-6 (or than a few float steps of the value, README
"What re-evaluation can change") from its full trace is printed with the
commands that reproduce it.  The stats lines are checked too.
"""
import argparse, glob, json, os, random, shutil, struct, subprocess, sys, time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
RTP = os.path.abspath(os.environ.get("RTP", os.path.join(ROOT, "rtp")))
SHARED = os.path.join(os.path.dirname(ROOT), "shared")
TEX = os.path.join(ROOT, "scenes", "tex4.ppm")
TEXB = os.path.join(ROOT, "scenes", "tex4b.ppm")


def read_pfm(path):
    with open(path, "rb") as f:
        data = f.read()
    parts = data.split(b"\n", 3)
    w, h = map(int, parts[1].split())
    scale = float(parts[2])
    fmt = ("<" if scale < 0 else ">") + "%df" % (w * h * 3)
    return w, h, struct.unpack(fmt, parts[3][: w * h * 12])


def ulp(x):
    import math
    if x != x or math.isinf(x):
        return 0.0
    x = abs(x)
    if x < 1.1754944e-38:
        return 1.4e-45
    e = math.frexp(x)[1]
    return 2.0 ** (e - 24)


def count_bad(a, b, floor=1e-6):
    """pixels whose any channel differs by more than floor"""
    wa, ha, pa = a
    n = set()
    for i, (x, y) in enumerate(zip(pa, b[2])):
        if x != y and not (abs(x - y) <= max(floor, 2 * max(ulp(x), ulp(y)))):
            n.add(i // 3)
    return len(n)


def compare(a, b, steps, floor=1e-6):
    """worst (abs error, allowed) over pixels: allowed = max(1e-6, steps float steps)"""
    wa, ha, pa = a
    wb, hb, pb = b
    if (wa, ha) != (wb, hb):
        return float("inf"), "size %dx%d vs %dx%d" % (wa, ha, wb, hb)
    worst = 0.0
    where = None
    for i, (x, y) in enumerate(zip(pa, pb)):
        if x == y:
            continue
        if x != x and y != y:
            continue
        d = abs(x - y)
        if d != d:
            d = float("inf")
        allow = max(floor, steps * max(ulp(x), ulp(y)))
        if d > allow and (where is None or d - allow > worst):
            worst = d - allow
            where = (i // 3 % wa, i // 3 // wa, i % 3, x, y, d)
    return worst, where


def os_stale(d, k):
    return json.loads(open(os.path.join(d, "o%d.json" % k)).read()).get("stale_samples", 0)


def run(cmd, timeout=120, **kw):
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           timeout=timeout, **kw)
    except subprocess.TimeoutExpired:
        return None
    return p


def info(tree):
    p = run([RTP, "info", tree])
    lights, mats, env = [], [], {}
    cur = None
    for line in p.stdout.decode().splitlines():
        line = line.strip()
        if line.startswith("light."):
            d = dict(kv.split("=", 1) for kv in line.split(": ", 1)[1].split())
            lights.append(d)
        elif line.startswith("mat."):
            d = dict(kv.split("=", 1) for kv in line.split(": ", 1)[1].split())
            mats.append(d)
            cur = d
        elif line.startswith("environment:"):
            env.update(kv.split("=", 1) for kv in line.split(": ", 1)[1].split())
        elif line.startswith("camera:"):
            env.update({"cam." + k: v for k, v in
                        (kv.split("=", 1) for kv in line.split(": ", 1)[1].split())})
        elif cur is not None and "=" in line and not line.startswith(("scene", "nodes", "file")):
            for kv in line.split():
                if "=" in kv:
                    k, v = kv.split("=", 1)
                    cur[k] = v
    return lights, mats, env


def fmt(x):
    return ("%.4g" % x)


def col(r):
    if r.random() < 0.03:   # past 2^50: the full path's bits, overflow included
        return ",".join(r.choice(["1e10", "1e20", "3e30", "3.4e38", "0", "1e-30"]) for _ in range(3))
    if r.random() < 0.08:
        return ",".join(fmt(r.uniform(0, 40)) for _ in range(3))
    if r.random() < 0.3:
        return fmt(r.uniform(0, 1))
    return ",".join(fmt(r.uniform(0, 1)) for _ in range(3))


class Gen:
    def __init__(self, r, lights, mats, env, minw, adds=0.0):
        self.r = r
        self.adds = adds                # share of lines that add a light first
        self.lights = lights
        self.nl = len(lights)           # count of lights so far (added ones too)
        self.mats = mats
        self.env = env
        self.minw = minw
        f = [float(x) for x in env["cam.from"].split(",")]
        a = [float(x) for x in env["cam.at"].split(",")]
        self.at = a
        self.rad = max(1e-3, sum((p - q) ** 2 for p, q in zip(f, a)) ** 0.5)
        # a scene far from the origin against its size (fuzz_scenes/
        # quadrics_far.nff): places written with the digits that size needs
        # (%.4g had put its lights 10 units apart at 1e4 and made the camera's
        # from its at); scenes within 100 sizes of the origin keep %.4g, and
        # with it the streams of earlier seeds
        import math
        far = max(abs(x) for x in a) / self.rad
        self.pfmt = fmt if far <= 100 else \
            (lambda x, d=4 + int(math.ceil(math.log10(far))): "%.*g" % (d, x))
        self.orig_pos = [l["pos"] for l in lights]
        self.cur = {}
        self.amb = set()  # materials given their own ambient coefficient
        # focus: edits on one or two materials and one light, so that they meet
        self.focus = r.random() < 0.4
        self.mf = r.sample(range(len(mats)), min(len(mats), r.randint(1, 2))) if mats else []
        self.lf = r.randrange(len(lights)) if lights else 0

    def mat(self):
        if self.focus and self.mf:
            return self.r.choice(self.mf)
        return self.r.randrange(len(self.mats))

    def light(self):
        if self.focus and self.lf < self.nl and self.r.random() < 0.8:
            return self.lf
        return self.r.randrange(self.nl)

    def pos(self):
        r = self.r
        w = r.random()
        if w < 0.03:   # far away: every mode decides it by shadow rays
            return ",".join(self.pfmt(c + r.uniform(-1, 1) * self.rad * 10 ** r.choice([6, 11, 13])) for c in self.at)
        if w < 0.35:   # round positions: edges through cell centres, lights in planes
            q = r.choice([1, 0.5, 0.25])
            return ",".join(self.pfmt(round((c + r.uniform(-1, 1) * self.rad) / q) * q) for c in self.at)
        return ",".join(self.pfmt(c + r.uniform(-1, 1) * self.rad) for c in self.at)

    def edit(self):
        """one random edit: (class, key, value)"""
        r = self.r
        c = r.choice("AAAABBBCCDDDR")
        if r.random() < 0.03:
            f = [float(x) for x in self.env["cam.from"].split(",")]
            if r.random() < 0.3:
                return ("K", "camera.from", self.env["cam.from"])
            if r.random() < 0.3:
                return ("K", "camera.angle", fmt(r.uniform(20, 70)))
            if r.random() < 0.3:
                a = [float(x) for x in self.env["cam.at"].split(",")]
                return ("K", "camera.at", ",".join(self.pfmt(x + r.uniform(-0.1, 0.1) * self.rad) for x in a))
            return ("K", "camera.from", ",".join(self.pfmt(x + r.uniform(-0.1, 0.1) * self.rad) for x in f))
        nm = len(self.mats)
        if not nm:
            c = r.choice("AB")
        if c == "R":  # back to a traced value
            if r.random() < 0.5 and self.lights:
                i = r.randrange(len(self.lights))
                k = r.choice(["pos", "color", "on"])
                return ("B" if k == "pos" else "A", "light.%d.%s" % (i, k), self.lights[i][k])
            if r.random() < 0.2:
                k = r.choice(["ambient", "background"])
                return ("A", k, self.env[k])
            m = self.mat()
            k = r.choice(["color", "kd", "ks", "kt", "shine", "ior"])
            cl = "D" if k in ("ks", "kt", "ior") else "A"
            return (cl, "mat.%d.%s" % (m, k), self.mats[m][k])
        if c == "A":
            w = r.random()
            if w < 0.16 and self.nl:
                return ("A", "light.%d.color" % self.light(), col(r))
            if w < 0.2 and self.nl:
                return ("A", "light.%d.intensity" % self.light(), "%.3g" % r.uniform(0, 2))
            if w < 0.3 and self.nl:
                return ("A", "light.%d.on" % self.light(), r.choice("01"))
            if w < 0.37:
                return ("A", "ambient", col(r))
            if w < 0.42:
                return ("A", "background", col(r))
            if not nm:
                return ("A", "ambient", col(r))
            m = self.mat()
            k = r.choice(["color", "kd", "kd", "color", "shine", "ks", "kt",
                          "checker", "color2", "checker_scale", "texture", "ambient"])
            if k in ("ks", "kt"):
                # class A only where it stays nonzero and no cut-off
                if float(self.mats[m][k]) == 0 or self.minw:
                    return ("D", "mat.%d.%s" % (m, k), fmt(r.uniform(0, 0.9)))
                return ("A", "mat.%d.%s" % (m, k), fmt(r.uniform(0.01, 0.9)))
            v = {"color": lambda: col(r),
                 "kd": lambda: fmt(r.uniform(0, 1)) if r.random() < 0.97 else r.choice(["1e15", "3e38", "0"]),
                 "shine": lambda: fmt(r.uniform(1, 300)),
                 "checker": lambda: r.choice("01"), "color2": lambda: col(r),
                 "checker_scale": lambda: fmt(r.uniform(0.2, 3)),
                 "texture": lambda: r.choice([TEX, TEXB, "none"]),
                 # (grey or RGB; once set, kd edits no longer move it;
                 # "kd" unsets it, kd's edits moving it again)
                 "ambient": lambda: "kd" if r.random() < 0.15 else
                 fmt(r.uniform(0, 1.5)) if r.random() < 0.4 else col(r)}[k]()
            if k == "ambient":
                self.amb.add(m)
            return ("A", "mat.%d.%s" % (m, k), v)
        if c == "B":
            if r.random() < 0.25:
                self.nl += 1
                return ("B", "light.%d.pos" % (self.nl - 1), self.pos())
            if not self.nl:
                self.nl += 1
                return ("B", "light.0.pos", self.pos())
            return ("B", "light.%d.pos" % self.light(), self.pos())
        if c == "C":
            m = self.mat()
            k = r.choice(["bump", "bump_strength", "bump_scale"])
            v = {"bump": lambda: r.choice(["waves", "noise", "none", TEX]),
                 "bump_strength": lambda: fmt(r.uniform(0, 1.5)),
                 "bump_scale": lambda: fmt(r.uniform(0.05, 2))}[k]()
            return ("C", "mat.%d.%s" % (m, k), v)
        m = self.mat()
        k = r.choice(["ks", "kt", "ior", "ior"])
        if k == "ior":
            return ("D", "mat.%d.ior" % m, r.choice(["1", fmt(r.uniform(0.7, 2.4))]))
        return ("D", "mat.%d.%s" % (m, k), r.choice(["0", fmt(r.uniform(0.01, 0.9))]))

    def reset(self):
        """a line setting every key back to the traced value (added lights off)"""
        es = []
        for i, l in enumerate(self.lights):
            es += [("R", "light.%d.%s" % (i, k), l[k]) for k in ("pos", "color", "on")]
        for i in range(len(self.lights), self.nl):
            es.append(("R", "light.%d.on" % i, "0"))
        es += [("R", k, self.env[k]) for k in ("ambient", "background")]
        es += [("K", "camera." + k, self.env["cam." + k]) for k in ("from", "at", "angle")]
        for i, m in enumerate(self.mats):
            es += [("R", "mat.%d.%s" % (i, k), m[k]) for k in ("color", "kd", "ks", "kt", "shine", "ior")]
            if i in self.amb:
                # (the traced ka where the scene gave one, info's line after
                # the material's; else unset: "kd")
                es.append(("R", "mat.%d.ambient" % i, m.get("ambient", "kd")))
            es.append(("R", "mat.%d.checker" % i, "1" if "checker" in m else "0"))
            for k in ("color2", "checker_scale"):
                if k in m:
                    es.append(("R", "mat.%d.%s" % (i, k), m[k]))
            es.append(("R", "mat.%d.texture" % i, m.get("texture", "none")))
            es.append(("R", "mat.%d.bump" % i, m.get("bump", "none")))
            for k in ("bump_strength", "bump_scale"):
                if k in m:
                    es.append(("R", "mat.%d.%s" % (i, k), m[k]))
        self.r.shuffle(es)  # (bump before its strength: moved to the end below)
        es.sort(key=lambda e: e[1].endswith(("bump_strength", "bump_scale")))
        for e in es:
            self.classify(e)
        return es

    def classify(self, e):
        """ks/kt from 0 (now, after earlier lines) or under a cut-off: class D"""
        cl, k, v = e
        p = k.split(".")
        if p[0] == "mat" and p[-1] in ("ks", "kt"):
            m = int(p[1])
            cur = self.cur.setdefault((m, p[-1]), float(self.mats[m][p[-1]]))
            if cur == 0 or self.minw:
                cl = "D"
            elif float(v) != 0:
                cl = "A"
            self.cur[(m, p[-1])] = float(v)
        return (cl, k, v)

    def line(self):
        r = self.r
        n = r.randint(1, 4)
        es = []
        if self.adds and r.random() < self.adds:  # (no draw by default: same streams)
            self.nl += 1
            es.append(("B", "light.%d.pos" % (self.nl - 1), self.pos()))
        es += [self.classify(self.edit()) for _ in range(n)]
        if r.random() < 0.1:
            es.append(self.classify(es[r.randrange(len(es))]))      # same key twice
        if r.random() < 0.1 and es:
            cl, k, v = es[r.randrange(len(es))]      # same key, another value after
            if k.endswith(".pos"):
                es.append(self.classify((cl, k, self.pos())))
        return es


def scenes():
    out = []
    for p in sorted(glob.glob(os.path.join(ROOT, "scenes", "*.nff"))):
        if "teapot" in p:
            continue
        out.append(p)
    for p in sorted(glob.glob(os.path.join(SHARED, "scenes", "spd", "*_s1.nff"))):
        out.append(p)
    for p in sorted(glob.glob(os.path.join(SHARED, "scenes", "spd", "*_s2.nff"))):
        out.append(p)
    for p in sorted(glob.glob(os.path.join(ROOT, "scenes", "stiff", "*.nff"))):
        out.append(p)
    out += sorted(glob.glob(os.path.join(HERE, "fuzz_scenes", "*.nff")))
    return out


def main():
    ap = argparse.ArgumentParser()
    # (50 by default; with --minutes, as many as the minutes allow: --minutes
    # 10 alone ran its 50 cases in a minute or two)
    ap.add_argument("--cases", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="/tmp/fuzz_streams")
    ap.add_argument("--minutes", type=float, default=0)
    ap.add_argument("--scene", default=None)
    ap.add_argument("--memlimit", type=float, default=0.15, help="share of cases with a low --memory-limit")
    ap.add_argument("--spd", type=float, default=0.15, help="share of SPD scenes' cases traced --spd")
    ap.add_argument("--keep", action="store_true", help="keep passing cases' files")
    ap.add_argument("--lines", default="3,12", help="MIN,MAX lines a stream")
    ap.add_argument("--adds", type=float, default=0.0,
                    help="share of lines that first add a light (lights one by one: "
                         "with --lines 60,80 past 32 and 64)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    print("seed", args.seed, "rtp", RTP)
    sc = sorted(sum((glob.glob(g) for g in args.scene.split(",")), [])) if args.scene else scenes()
    t_end = time.time() + args.minutes * 60 if args.minutes else None
    counts = {}
    nfail = 0
    nframes = 0
    ncases = args.cases if args.cases is not None else (10 ** 9 if args.minutes else 50)
    for case in range(ncases):
        if t_end and time.time() > t_end:
            break
        seed = args.seed * 100003 + case
        nfail0 = nfail
        r = random.Random(seed)
        d = os.path.join(args.out, "c%d" % seed)
        os.makedirs(d, exist_ok=True)
        for f in glob.glob(os.path.join(d, "*")):
            os.unlink(f)
        scene = r.choice(sc)
        topt = []
        spd = "spd" in scene and r.random() < args.spd
        if spd:
            x0, y0 = r.randrange(0, 480), r.randrange(0, 480)
            topt = ["--spd", "--region", "%d,%d,%d,%d" % (x0, y0, x0 + r.randint(8, 32), y0 + r.randint(8, 32))]
        else:
            s = r.choice([16, 24, 32, 48])
            topt = ["--size", "%dx%d" % (s, s), "--depth", str(r.randint(1, 8))]
            if r.random() < 0.3:
                topt += ["--min-weight", r.choice(["0.01", "0.1", "0.3"])]
        tree = os.path.join(d, "t.rtp")
        p = run([RTP, "trace", scene, "-q", "-o", tree, "-i", os.path.join(d, "t.pfm")] + topt)
        if p is None or p.returncode:
            print("TRACE FAIL", scene, topt, p and p.stderr.decode()[:200])
            continue
        lights, mats, env = info(tree)
        minw = "--min-weight" in topt
        g = Gen(r, lights, mats, env, minw, args.adds)
        nlines = r.randint(*map(int, args.lines.split(",")))
        pre, addl, precls = [], [], set()
        if r.random() < 0.12:
            xyz = g.pos()
            addl = ["--add-light", xyz]
            pre = ["--set", "light.%d.pos=%s" % (g.nl, xyz)]
            g.nl += 1
        lines = [g.line() for _ in range(nlines)]
        reset = r.random() < 0.3
        if reset:
            lines.append(g.reset())
            nlines += 1
        ropt = list(addl)
        refmode = r.random() < 0.2
        sh = r.choice(["auto", "exact", "lightbuf", "lightbuf:64", "auto:128", "lightbuf:1024"] +
                      (["itembuf", "itembuf:64", "itembuf:1024"] if refmode else []))
        if refmode:
            ropt += ["--reference"]
        keep = r.random() < 0.2
        ropt += ["--shadows", sh, "--stale", "keep" if keep else "retrace", "-j", r.choice(["1", "2"])]
        if r.random() < args.memlimit:
            # a limit that leaves the trees room but not the evaluation's caches:
            # every line then evaluates every sample (the uncached path)
            tb = json.loads(run([RTP, "info", tree, "--stats", "-", "-q"]).stdout.decode().splitlines()[-1])["tree_bytes"]
            ropt += ["--memory-limit", "%.6f" % (tb * r.uniform(1.5, 4) / 1048576.0)]
        region = None
        if r.random() < 0.2 and not spd:
            w = int(topt[1].split("x")[0])
            x0, y0 = r.randrange(0, w - 2), r.randrange(0, w - 2)
            region = "%d,%d,%d,%d" % (x0, y0, r.randint(x0 + 1, w), r.randint(y0 + 1, w))
            ropt += ["--region", region]
        elif spd and r.random() < 0.3:
            # a part of the SPD region's tree, in the frame's coordinates
            a, b, c, e = map(int, topt[2].split(","))
            x0, y0 = r.randrange(a, c), r.randrange(b, e)
            region = "%d,%d,%d,%d" % (x0, y0, r.randint(x0 + 1, c), r.randint(y0 + 1, e))
            ropt += ["--region", region]
        if r.random() < 0.15 and len(lines) > 1 and lines[0]:
            # the first line's edits as the stream's own --set: no frame of theirs
            precls = set(c for c, _, _ in lines[0])
            for _, kk, v in lines.pop(0):
                ropt += ["--set", "%s=%s" % (kk, v)]
                pre += ["--set", "%s=%s" % (kk, v)]
        for _ in range(r.choice([0, 0, 0, 1, 2])):   # blank and comment lines make frames too
            lines.insert(r.randrange(len(lines) + 1), [])
        nlines = len(lines)
        eol = r.choice(["\n"] * 6 + ["\r\n", "\r"])
        text = eol.join(" ".join("%s=%s" % (k, v) for _, k, v in l) if l else
                        r.choice(["", "  ", "# a comment", "\t# x=1"]) for l in lines) + eol
        with open(os.path.join(d, "stream.txt"), "w") as f:
            f.write(text)
        pat = os.path.join(d, "f%d.pfm")
        stats = os.path.join(d, "stats.json")
        cmd = [RTP, "reeval", tree, "--stream", "-q", "-i", pat, "--stats", stats] + ropt
        p = run(cmd, input=text.encode())
        key = tuple(sorted(set(c for l in lines for c, _, _ in l)))
        counts[key] = counts.get(key, 0) + 1
        tag = "case %d scene %s topt %s ropt %s" % (seed, os.path.basename(scene), " ".join(topt), " ".join(ropt))
        if p is None:
            print("HANG", tag)
            nfail += 1
            continue
        if p.returncode and b"memory limit" in p.stderr:
            counts[("memlimit-skipped",)] = counts.get(("memlimit-skipped",), 0) + 1
            continue
        if p.returncode:
            print("STREAM EXIT", p.returncode, tag, p.stderr.decode()[:300])
            nfail += 1
            continue
        st = [json.loads(x) for x in open(stats)]
        if len(st) != nlines:
            print("STATS LINES", len(st), nlines, tag)
            nfail += 1
        cum = list(pre)
        moved = set(a.split("=")[0] for a in pre[1::2] if ".pos=" in a)
        if r.random() < 0.15:
            jo = ["-j", "2" if "1" in ropt[ropt.index("-j") + 1] else "1"]
            p2 = run([RTP, "reeval", tree, "--stream", "-q", "-i", os.path.join(d, "g%d.pfm")] + ropt + jo, input=text.encode())
            if p2 is not None and p2.returncode and b"memory limit" in p2.stderr:
                pass   # (-j2's re-trace takes a few blocks more: 0.33 MiB against 0.31)
            elif p2 is None or p2.returncode:
                print("J STREAM FAIL", tag)
                nfail += 1
            else:
                for k in range(nlines):
                    if open(os.path.join(d, "g%d.pfm" % k), "rb").read() != open(os.path.join(d, "f%d.pfm" % k), "rb").read():
                        print("J DIFFERS", tag, "frame", k, d)
                        nfail += 1
                        break
        for k, l in enumerate(lines):
            for _, kk, v in l:
                cum += ["--set", "%s=%s" % (kk, v)]
            for _, kk, v in l:
                if kk.endswith(".pos"):
                    moved.add(kk)
            ref = os.path.join(d, "r%d.pfm" % k)
            rc = [RTP, "trace", scene, "-q", "-i", ref] + topt + cum
            if region and spd:
                rc[rc.index("--region") + 1] = region
            elif region:
                rc += ["--region", region]
            q = run(rc)
            fr = os.path.join(d, "f%d.pfm" % k)
            if q.returncode:
                print("REF TRACE FAIL", tag, q.stderr.decode()[:200])
                nfail += 1
                break
            nframes += 1
            steps = 4 if spd else 2
            worst, where = compare(read_pfm(fr), read_pfm(ref), steps)
            s = st[k] if k < len(st) else {}
            bad = []
            if refmode:
                # --reference's max_abs is the frame's own error against the full trace
                fa, fb = read_pfm(fr)[2], read_pfm(ref)[2]
                m = 0.0
                for x, y in zip(fa, fb):
                    if x == y or (x != x and y != y):
                        continue
                    e = abs(x - y)
                    m = max(m, e if e == e else float("inf"))
                rep = s.get("max_abs")
                if rep is None or (float(rep) != m and abs(float(rep) - m) > 1e-6 + 1e-6 * m):
                    bad.append("--reference max_abs %s, measured %g" % (rep, m))
            if where and sh.startswith("itembuf") and moved:
                pass   # (approximate, error reported: checked above)
            elif where and keep and s.get("stale_samples", 0):
                # approximate where stale: no more pixels off than stale samples
                nb = count_bad(read_pfm(fr), read_pfm(ref))
                if nb > s["stale_samples"] and not spd:
                    bad.append("keep: %d pixels off, stale_samples %d" % (nb, s["stale_samples"]))
            elif where:
                bad.append("frame %d vs trace: %s" % (k, where))
            if reset and k == nlines - 1 and not region and not (keep and s.get("stale_samples")):
                w0, wh0 = compare(read_pfm(fr), read_pfm(os.path.join(d, "t.pfm")), 0, 0.0)
                if wh0:
                    print("NOTE reset frame not the traced bits:", tag, wh0, d)
                w0, wh0 = compare(read_pfm(ref), read_pfm(os.path.join(d, "t.pfm")), 0, 0.0)
                if wh0:
                    print("NOTE reset trace not the traced bits:", tag, wh0, d)
            if "written_pixels" in s:
                prev = read_pfm(os.path.join(d, "f%d.pfm" % (k - 1)) if k else os.path.join(d, "t.pfm"))
                cur = read_pfm(fr)
                if k or not region:
                    nch = len(set(i // 3 for i, (x, y) in enumerate(zip(prev[2], cur[2]))
                                  if struct.pack("<f", x) != struct.pack("<f", y)))
                    if nch > s["written_pixels"]:
                        bad.append("%d pixels changed, written_pixels %d" % (nch, s["written_pixels"]))
            if s.get("stale_samples") and not keep:
                bad.append("stale_samples %d with retrace" % s["stale_samples"])
            if s.get("moved_lights", 0) and "shadows" not in s:
                bad.append("moved_lights without shadows")
            if not s.get("moved_lights", 0) and "shadows" in s:
                bad.append("shadows without moved_lights")
            if s.get("moved_lights", 0) > len(moved):
                bad.append("moved_lights %d > moved so far %d" % (s["moved_lights"], len(moved)))
            if sh == "exact" and s.get("shadows", "exact") != "exact":
                bad.append("shadows %s with exact" % s["shadows"])
            if s.get("shadows", "exact") not in ("exact", "lightbuf", "itembuf"):
                bad.append("shadows %s" % s["shadows"])
            if sh.startswith("lightbuf") and s.get("shadows", "lightbuf") not in ("lightbuf", "exact"):
                bad.append("shadows %s with lightbuf" % s["shadows"])
            cls = set(c for c, _, _ in l) | (precls if k == 0 else set())
            if s.get("retraced_samples", 0) and not (cls & set("CDRK")):
                bad.append("retraced %d on class %s line" % (s["retraced_samples"], cls))
            # a one-off with the cumulative edits: sometimes
            if r.random() < 0.25 or (where and True):
                one = os.path.join(d, "o%d.pfm" % k)
                oc = [RTP, "reeval", tree, "-q", "-i", one, "--stats", os.path.join(d, "o%d.json" % k)] + ropt + cum
                q = run(oc)
                if q is not None and q.returncode and b"memory limit" in q.stderr:
                    pass
                elif q is None or q.returncode:
                    bad.append("one-off exit %s %s" % (q and q.returncode, q and q.stderr.decode()[:200]))
                else:
                    w2, wh2 = compare(read_pfm(one), read_pfm(ref), steps)
                    if sh.startswith("itembuf") and moved:
                        wh2 = wh3 = None
                    if wh2 and not (keep and os_stale(d, k)):
                        bad.append("one-off frame %d vs trace: %s" % (k, wh2))
                    if not (sh.startswith("itembuf") and moved):
                        w3, wh3 = compare(read_pfm(one), read_pfm(fr), steps)
                    if wh3 and not (keep and (os_stale(d, k) or s.get("stale_samples"))):
                        bad.append("one-off vs stream frame %d: %s" % (k, wh3))
                    os_ = json.loads(open(os.path.join(d, "o%d.json" % k)).read())
                    # lights away from where the tree traced them (added ones too)
                    cam = any(a.startswith("camera.") for a in cum[1::2])
                    pos = {}
                    for a in cum[1::2]:
                        kk, v = a.split("=", 1)
                        if kk.startswith("light.") and kk.endswith(".pos"):
                            pos[int(kk.split(".")[1])] = tuple(map(float, v.split(",")))
                    want = sum(1 for i, v in pos.items()
                               if i >= len(lights) or v != tuple(map(float, lights[i]["pos"].split(","))))
                    if not cam and os_.get("moved_lights", 0) != want:
                        bad.append("one-off moved_lights %d, %d lights away from the traced" % (os_.get("moved_lights", 0), want))
                    if os_.get("stale_samples") and not keep:
                        bad.append("one-off stale %d" % os_["stale_samples"])
            if bad:
                nfail += 1
                print("FAIL", tag, "line", k)
                for b in bad:
                    print("   ", b)
                print("    dir", d)
                break
        if nfail == nfail0 and not args.keep:
            shutil.rmtree(d, ignore_errors=True)   # (a passing case's files go)
        sys.stdout.flush()
    print("cases by class set:")
    for k in sorted(counts):
        print("   ", "".join(k), counts[k])
    print("frames compared", nframes, "failures", nfail)
    return 1 if nfail else 0


if __name__ == "__main__":
    sys.exit(main())
