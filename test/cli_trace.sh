#!/bin/sh
# CLI tests for rtp trace and rtp diff: exit codes, messages, pipes, stats,
# and (when ../shared is present) every SPD scene and mesh renders.
TEST_NAME=cli
. "$(dirname "$0")/common.sh"

expect_rc 0 $RTP --help
expect_rc 2 $RTP
expect_rc 2 $RTP frobnicate
expect_rc 0 $RTP trace --help
# Every --help fits 80 columns, and each command's lists -q, -v and -h
# alike; --help is taken anywhere among the arguments (version took it
# only first: 'rtp version -v --help' was a usage error)
for c in "" trace reeval diff info merge version; do
    $RTP $c --help >"$T/help" 2>&1 && ok || bad "rtp $c --help failed"
    awk 'length > 80 { w = 1 } END { exit w }' "$T/help" && ok ||
        bad "rtp $c --help is wider than 80 columns"
    case $c in trace|reeval|diff|info|merge)
        grep -q '^  -q, --quiet ' "$T/help" && grep -q '^  -v, --verbose ' "$T/help" &&
            grep -q '^  -h, --help ' "$T/help" && ok || bad "rtp $c --help: -q, -v, -h";;
    esac
done
expect_rc 0 $RTP version -v --help
grep -q "usage: rtp version" "$T/out" && ok || bad "version -v --help: $(cat "$T/err")"
# rtp help COMMAND is COMMAND's --help (it printed the command list)
for c in trace reeval diff info merge version; do
    $RTP $c --help >"$T/h1" 2>&1
    $RTP help $c >"$T/h2" 2>&1 && cmp -s "$T/h1" "$T/h2" && ok || bad "rtp help $c is not rtp $c --help"
done
expect_rc 2 $RTP help frobnicate
expect_rc 2 $RTP help trace reeval
expect_rc 2 $RTP trace
expect_rc 2 $RTP trace scenes/spheres.nff --depth zero
expect_rc 1 $RTP trace "$T/does-not-exist.nff" -i "$T/x.pfm"
grep -q "does-not-exist.nff" "$T/err" && ok || bad "missing file not named"

# A parse error names file:line:col and writes no image.
printf 'v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\ns 0 0 zero 1\n' > "$T/bad.nff"
expect_rc 1 $RTP trace "$T/bad.nff" -i "$T/bad.pfm"
grep -q "bad.nff:8:7:" "$T/err" && ok || { bad "parse error position"; cat "$T/err" >&2; }
[ ! -e "$T/bad.pfm" ] && ok || bad "image written on failure"

# Unknown --set key: exit 1 naming the key; no KEY=VALUE at all (no '=',
# or no key before it): a usage error, on trace and reeval alike.
expect_rc 2 $RTP trace scenes/spheres.nff --set =1 -i "$T/x.pfm"
expect_rc 2 $RTP trace scenes/spheres.nff --set mat.red.kd -i "$T/x.pfm"
expect_rc 1 $RTP trace scenes/spheres.nff --set light.99.pos=1,2,3 -i "$T/x.pfm"
grep -q "light.99" "$T/err" && ok || bad "bad key not named"

# Image to a file, to stdout, and diff between them; stats JSON.
expect_rc 0 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/a.pfm" --stats "$T/s.json"
grep -q '"eye_rays": 1200' "$T/s.json" && ok || { bad "stats eye_rays"; cat "$T/s.json" >&2; }
$RTP trace scenes/spheres.nff --size 40x30 -i - 2>"$T/err" | $RTP diff - "$T/a.pfm" --stats "$T/d.json" >/dev/null 2>&1
[ $? -eq 0 ] && ok || bad "pipe trace | diff"
grep -q '"psnr": "inf"' "$T/d.json" && ok || { bad "identical images not inf psnr"; cat "$T/d.json" >&2; }
# BRIEF's --stats keys include `seconds` where they apply: diff's is its
# reading, comparing and heat map, a plain number as trace's and reeval's
grep -Eq '"seconds": [0-9]+\.[0-9]{6}[,}]' "$T/d.json" && ok || { bad "diff stats: no seconds"; cat "$T/d.json" >&2; }
# An infinite pixel against a finite one: every error metric "inf", psnr "-inf"
# (JSON has no infinity), and the printed line says the same.
printf 'PF\n1 1\n-1.0\n\000\000\200\077\000\000\200\077\000\000\200\077' > "$T/one.pfm"
printf 'PF\n1 1\n-1.0\n\000\000\200\177\000\000\200\077\000\000\200\077' > "$T/inf.pfm"
$RTP diff "$T/one.pfm" "$T/inf.pfm" --stats "$T/di.json" >"$T/out" 2>"$T/err"
grep -q '"mae": "inf", "rmse": "inf", "psnr": "-inf", "max_abs": "inf"' "$T/di.json" &&
    grep -q 'psnr -inf dB' "$T/out" && ok || { bad "diff against an infinite pixel"; cat "$T/di.json" "$T/out" "$T/err" >&2; }
# (an 8-bit image: PNG where the build has libpng, which `rtp version` says)
$RTP version >"$T/ver" 2>&1 && grep -q "^built with:" "$T/ver" && ok || bad "version: no 'built with' line"
b8=b.ppm
awk '/^built with:/ { for (i = 3; i <= NF; i++) if ($i == "png") f = 1 } END { exit !f }' "$T/ver" &&
    b8=b.png
expect_rc 0 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/$b8" --set mat.0.color=0,1,0
# An empty scene traces (the background) but says so; -q keeps quiet.
expect_rc 0 $RTP trace - --size 8x6 -i "$T/empty.pfm" </dev/null
# (stdin named <stdin>, as README says every message names it)
grep -q "^rtp: warning: <stdin> has no objects" "$T/err" && ok || bad "empty scene: no warning: $(cat "$T/err")"
expect_rc 0 $RTP trace - --size 8x6 -i "$T/empty.pfm" -q </dev/null
[ ! -s "$T/err" ] && ok || bad "empty scene with -q: $(cat "$T/err")"
# An image or tree '-' with stdout a terminal is a usage error (its bytes
# would go to the screen); into a pipe it is written.  (script(1) gives
# the terminal, where there is one to run.)
if command -v script >/dev/null 2>&1 && script -qc true /dev/null >/dev/null 2>&1; then
    script -qc "$RTP trace scenes/spheres.nff --size 8x6 -i -; echo rc=\$?" /dev/null >"$T/tty" 2>&1
    grep -q "stdout is a terminal" "$T/tty" && grep -q "rc=2" "$T/tty" && ok ||
        bad "image to a terminal not refused: $(cat "$T/tty")"
    script -qc "$RTP trace scenes/spheres.nff --size 8x6 -i - | wc -c; echo rc=\$?" /dev/null >"$T/tty" 2>&1
    grep -q "^ *588" "$T/tty" && grep -q "rc=0" "$T/tty" && ok ||
        bad "image to a pipe from a terminal: $(cat "$T/tty")"
    # progress on a terminal says at once that work began (a large mesh's
    # load and kd-tree were seconds of silence), and ends its line
    # (with two threads the last report could be a worker's row short of
    # 100%: the calling thread reports at the end too)
    script -qc "$RTP trace scenes/spheres.nff --size 8x6 -i '$T/tty.pfm' -j 2" /dev/null >"$T/tty" 2>&1
    grep -q "  0.0%  preparing" "$T/tty" && grep -q "100.0%" "$T/tty" && ok ||
        bad "progress on a terminal: $(od -c "$T/tty" | head)"
else
    echo "cli_trace.sh: no script(1) terminal here: the terminal checks skipped"
    skip=$((skip + 3))
fi
# with no -i, the image is the scene's name with .png (.ppm without PNG)
# in the current folder, and written; from stdin, trace.png
mkdir -p "$T/cwd"
here=$(pwd)
case $RTP in /*) rtp_abs=$RTP ;; *) rtp_abs=$here/$RTP ;; esac
(cd "$T/cwd" && "$rtp_abs" trace "$here/scenes/spheres.nff" --size 8x6 -q) &&
    [ -s "$T/cwd/spheres.${b8#b.}" ] && ok || bad "default image spheres.${b8#b.} not written"
(cd "$T/cwd" && "$rtp_abs" trace - --size 8x6 -q <"$here/scenes/spheres.nff") &&
    [ -s "$T/cwd/trace.${b8#b.}" ] && ok || bad "default image trace.${b8#b.} not written"
# ... but never over the input itself (a scene or tree named like its
# image): a usage error, the input kept
cp scenes/spheres.nff "$T/cwd/s.$b8"
(cd "$T/cwd" && "$rtp_abs" trace "s.$b8" --size 8x6 -q 2>"$T/err"); rc=$?
[ $rc -eq 2 ] && cmp -s scenes/spheres.nff "$T/cwd/s.$b8" && grep -q "the default image s.$b8 is the scene itself" "$T/err" &&
    ok || bad "trace's default image over its scene: exit $rc, $(cat "$T/err")"
$RTP trace scenes/spheres.nff --size 8x6 -o "$T/cwd/t.rtp" -q
cp "$T/cwd/t.rtp" "$T/cwd/t.$b8"
(cd "$T/cwd" && "$rtp_abs" reeval "t.$b8" -q 2>"$T/err"); rc=$?
[ $rc -eq 2 ] && cmp -s "$T/cwd/t.rtp" "$T/cwd/t.$b8" && ok ||
    bad "reeval's default image over its tree: exit $rc, $(cat "$T/err")"
expect_rc 2 $RTP reeval "$T/cwd/t.rtp" -i "$T/cwd/t.rtp"
cmp -s "$T/cwd/t.rtp" "$T/cwd/t.$b8" && ok || bad "reeval -i over its tree wrote it"
# --stats and --heatmap naming an input are refused alike (they replaced
# the scene, the tree, the params file or diff's image with JSON or a heat
# map, exit 0)
cp scenes/spheres.nff "$T/cwd/s.nff"
cp "$T/cwd/t.rtp" "$T/cwd/t2.rtp"
printf 'light.0.on=1\n' > "$T/cwd/p.txt"
expect_rc 2 $RTP trace "$T/cwd/s.nff" --size 8x6 -i "$T/cwd/s.pfm" --stats "$T/cwd/s.nff"
expect_rc 2 $RTP trace scenes/spheres.nff --size 8x6 -i "$T/cwd/s.pfm" --params "$T/cwd/p.txt" --stats "$T/cwd/p.txt"
expect_rc 2 $RTP reeval "$T/cwd/t2.rtp" -i "$T/cwd/s.pfm" --stats "$T/cwd/t2.rtp"
expect_rc 2 $RTP reeval "$T/cwd/t2.rtp" -i "$T/cwd/s.pfm" --params "$T/cwd/p.txt" --stats "$T/cwd/p.txt"
echo | $RTP reeval "$T/cwd/t2.rtp" --stream -i "$T/cwd/f%d.pfm" --stats "$T/cwd/t2.rtp" 2>"$T/err"
[ $? -eq 2 ] && ok || bad "reeval --stream --stats over its tree: $(cat "$T/err")"
expect_rc 2 $RTP info "$T/cwd/t2.rtp" --stats "$T/cwd/t2.rtp"
cp "$T/a.pfm" "$T/cwd/a.pfm"
expect_rc 2 $RTP diff "$T/cwd/a.pfm" "$T/a.pfm" --heatmap "$T/cwd/a.pfm"
expect_rc 2 $RTP diff "$T/a.pfm" "$T/cwd/a.pfm" --stats "$T/cwd/a.pfm"
cmp -s scenes/spheres.nff "$T/cwd/s.nff" && cmp -s "$T/cwd/t.rtp" "$T/cwd/t2.rtp" &&
    cmp -s "$T/a.pfm" "$T/cwd/a.pfm" && grep -q '^light.0.on=1$' "$T/cwd/p.txt" && ok ||
    bad "an output over an input replaced it"
# ... with one line naming the option and what the input is, no usage
# lines after it (the options are well formed; "trace s.nff -o s.nff" said
# "s.nff is the input s.nff" and then the usage, as for a bad option); by
# device and inode, so a hard link to the tree is caught under its name
one_line() { # WANT: the one line of $T/err, as a grep pattern
    [ "$(wc -l <"$T/err")" -eq 1 ] && grep -q "$1" "$T/err" && ok ||
        bad "want one line '$1': $(cat "$T/err")"
}
expect_rc 2 $RTP trace "$T/cwd/s.nff" --size 8x6 -o "$T/cwd/s.nff"
one_line "^rtp: trace: -o .*/s.nff is the scene .*/s.nff: writing it would replace it; name another file$"
expect_rc 2 $RTP trace "$T/cwd/s.nff" --size 8x6 -i "$T/cwd/s.pfm" --params "$T/cwd/p.txt" --stats "$T/cwd/p.txt"
one_line "^rtp: trace: --stats .*/p.txt is the --params file .*/p.txt: "
ln -f "$T/cwd/t2.rtp" "$T/cwd/t2link.rtp"
expect_rc 2 $RTP reeval "$T/cwd/t2.rtp" -i "$T/cwd/t2link.rtp"
one_line "^rtp: reeval: -i .*/t2link.rtp is the tree .*/t2.rtp: "
expect_rc 2 $RTP info "$T/cwd/t2.rtp" --stats "$T/cwd/t2link.rtp"
one_line "^rtp: info: --stats .*/t2link.rtp is the tree .*/t2.rtp: "
expect_rc 2 $RTP diff "$T/cwd/a.pfm" "$T/a.pfm" --heatmap "$T/cwd/a.pfm"
one_line "^rtp: diff: --heatmap .*/a.pfm is the image .*/a.pfm: "
expect_rc 2 $RTP trace "$T/cwd/s.nff" --size 8x6 -o "$T/cwd/x.rtp" -i "$T/cwd/x.rtp"
one_line "^rtp: trace: the tree .*/x.rtp and the image .*/x.rtp are one file: give each output its own$"
(cd "$T/cwd" && "$rtp_abs" trace "s.$b8" --size 8x6 2>"$T/err")
one_line "the default image s.$b8 is the scene itself: name the image with -i$"
cmp -s scenes/spheres.nff "$T/cwd/s.nff" && cmp -s "$T/cwd/t.rtp" "$T/cwd/t2.rtp" &&
    cmp -s "$T/a.pfm" "$T/cwd/a.pfm" && grep -q '^light.0.on=1$' "$T/cwd/p.txt" &&
    [ ! -e "$T/cwd/x.rtp" ] && [ ! -e "$T/cwd/s.pfm" ] && ok ||
    bad "an output over an input replaced it, or a refused command wrote"
# '-' where the shell sent stdout to the input: `reeval t.rtp -i - >>
# t.rtp` appended the image to the tree (exit 0; the tree then read
# "bytes after END"), and with `> t.rtp` the tree, emptied by the shell,
# read only "t.rtp: empty: not an rtp tree file"; a --stream and --stats
# - alike, and stdin as the tree
cp "$T/cwd/t2.rtp" "$T/cwd/t3.rtp"
echo light.0.pos=1,2,3 | $RTP reeval "$T/cwd/t3.rtp" --stream -i - >>"$T/cwd/t3.rtp" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/cwd/t2.rtp" "$T/cwd/t3.rtp" && ok || bad "reeval --stream -i - >> TREE"
one_line "^rtp: reeval: -i - writes to standard output, which is the tree .*/t3.rtp: name another file$"
$RTP reeval - --set light.0.pos=1,2,3 -i - <"$T/cwd/t3.rtp" >>"$T/cwd/t3.rtp" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/cwd/t2.rtp" "$T/cwd/t3.rtp" && ok || bad "reeval - -i - < TREE >> TREE"
one_line "^rtp: reeval: -i - writes to standard output, which is the tree (standard input): "
$RTP info "$T/cwd/t3.rtp" --stats - >>"$T/cwd/t3.rtp" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/cwd/t2.rtp" "$T/cwd/t3.rtp" && ok || bad "info --stats - >> TREE"
echo light.0.pos=1,2,3 | $RTP reeval "$T/cwd/t3.rtp" --stream -i - >"$T/cwd/t3.rtp" 2>"$T/err"
[ $? -eq 2 ] && [ ! -s "$T/cwd/t3.rtp" ] && ok || bad "reeval --stream -i - > TREE"
one_line "^rtp: reeval: -i - writes to standard output, which is the tree .*/t3.rtp (empty now: a shell's > empties its file before the command starts): name another file$"
cp "$T/cwd/t2.rtp" "$T/cwd/t4.pfm"
$RTP reeval - -i "$T/cwd/t4.pfm" <"$T/cwd/t4.pfm" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/cwd/t2.rtp" "$T/cwd/t4.pfm" && ok || bad "reeval - -i TREE < TREE"
one_line "^rtp: reeval: -i .*/t4.pfm is the tree (standard input): writing it would replace it; "
cp scenes/spheres.nff "$T/cwd/s3.nff"
$RTP trace "$T/cwd/s3.nff" --size 8x6 -i "$T/cwd/s3.pfm" -o - >>"$T/cwd/s3.nff" 2>"$T/err"
[ $? -eq 2 ] && cmp -s scenes/spheres.nff "$T/cwd/s3.nff" && [ ! -e "$T/cwd/s3.pfm" ] && ok ||
    bad "trace -o - >> SCENE"
one_line "^rtp: trace: -o - writes to standard output, which is the scene .*/s3.nff: name another file$"
expect_rc 3 $RTP diff "$T/a.pfm" "$T/$b8" --fail-above rmse=0.001
expect_rc 0 $RTP diff "$T/a.pfm" "$T/$b8" --fail-above rmse=100
expect_rc 1 $RTP diff "$T/a.pfm" scenes/spheres.nff
# images of different sizes: both named with their sizes
expect_rc 0 $RTP trace scenes/spheres.nff --size 30x40 -i "$T/tall.pfm"
expect_rc 1 $RTP diff "$T/a.pfm" "$T/tall.pfm"
grep -q "a.pfm is 40x30, .*tall.pfm 30x40: image sizes differ" "$T/err" && ok || bad "sizes differ: files not named: $(cat "$T/err")"

# Trees that would outgrow --memory-limit stop with a message naming it,
# leaving no files; a sample's tree full at 2^20 nodes is a warning and a
# stats key (glass balls inside a mirrored sphere, the eye at its centre).
printf 'v\nfrom 0 0 0\nat 0 0 1\nup 0 1 0\nangle 60\nhither 0.01\nresolution 4 4\nb 0.1 0.1 0.1\nl 0.5 0.5 0.5\nf 0.9 0.9 0.9 0.1 0.9 10 0 1\ns 0 0 0 10\nf 0.9 0.9 0.9 0.1 0.5 10 0.5 1.5\ns 0 0 4 2\ns 0 4 3 2\ns 3 -3 3 2\ns -3 -3 -3 2\ns 4 0 -3 2\ns -4 3 -3 2\n' > "$T/trap.nff"
expect_rc 1 $RTP trace "$T/trap.nff" --depth 40 --memory-limit 32 -o "$T/trap.rtp" -i "$T/trap.pfm"
grep -q "memory limit of 32 MiB" "$T/err" && ok || { bad "memory limit not named"; cat "$T/err" >&2; }
# ...and the scene it stopped (an error of no file of its own)
grep -q "^rtp: $T/trap.nff: .*memory limit of 32 MiB" "$T/err" && ok || { bad "scene not named"; cat "$T/err" >&2; }
[ ! -e "$T/trap.rtp" ] && [ ! -e "$T/trap.pfm" ] && ok || bad "files written past the memory limit"
expect_rc 0 $RTP trace "$T/trap.nff" --size 1x1 --depth 40 -o "$T/trap.rtp" --stats "$T/trap.json"
grep -q "warning: 16 rays were not followed" "$T/err" && ok || { bad "no warning of a full tree"; cat "$T/err" >&2; }
grep -q '"capped_rays": 16' "$T/trap.json" && grep -q '"nodes": 1048576' "$T/trap.json" && ok || { bad "capped_rays"; cat "$T/trap.json" >&2; }
# kt 0 traced, kt 0.5 re-traced: over 1 MiB it stops, with room it runs.
expect_rc 0 $RTP trace "$T/trap.nff" --depth 16 --set mat.1.kt=0 -o "$T/trap.rtp"
expect_rc 1 $RTP reeval "$T/trap.rtp" --set mat.1.kt=0.5 --memory-limit 1 -i "$T/trap.pfm"
grep -q "memory limit of 1 MiB while re-tracing" "$T/err" && ok || { bad "re-trace limit"; cat "$T/err" >&2; }
[ ! -e "$T/trap.pfm" ] && ok || bad "image written past the memory limit"
expect_rc 0 $RTP reeval "$T/trap.rtp" --set mat.1.kt=0.5 -i "$T/trap.pfm" --stats "$T/trap.json"
grep -q '"capped_rays": 0' "$T/trap.json" && ok || { bad "reeval capped_rays"; cat "$T/trap.json" >&2; }

# --spd traces 512x512 to depth 5 with no cut-off: a --size, --depth or
# --min-weight that differs is said to be ignored; the same values are no
# warning (--size 512x512 was said to be ignored, --depth 5 was not)
expect_rc 0 $RTP trace scenes/spheres.nff --spd --size 512x512 --depth 5 -i "$T/spd1.pfm"
[ ! -s "$T/err" ] && ok || bad "--spd --size 512x512 --depth 5: $(cat "$T/err")"
expect_rc 0 $RTP trace scenes/spheres.nff --spd --size 512x256 --depth 4 --min-weight 0.1 -i "$T/spd2.pfm"
grep -q "warning: --spd traces 512x512 to depth 5 with no weight cut-off: --size, --depth, --min-weight ignored" \
    "$T/err" && ok || bad "--spd with other values: $(cat "$T/err")"
cmp -s "$T/spd1.pfm" "$T/spd2.pfm" && ok || bad "--spd with other values: another image"
# ... in either order (--size before --spd alike), and --help says so
# (it said only "512x512": a --size beside it was overridden, which only
# the warning and the README told)
expect_rc 0 $RTP trace scenes/spheres.nff --size 64x64 --spd -i "$T/spd3.pfm" -q
cmp -s "$T/spd1.pfm" "$T/spd3.pfm" && [ ! -s "$T/err" ] && ok || bad "--size 64x64 --spd -q: $(cat "$T/err")"
$RTP trace --help | tr -s ' \n' ' ' | grep -q -- "--spd SPD .* it overrides --size, --depth and --min-weight in any order" &&
    ok || bad "trace --help does not say --spd overrides --size"
shared=""
for d in ../shared/scenes ../../shared/scenes; do [ -d "$d/spd" ] && shared=$d && break; done
if [ -n "$shared" ]; then
    for f in "$shared"/spd/*.nff "$shared"/meshes/*.obj; do
        if $RTP trace "$f" --size 32x32 -j 2 -i "$T/spd.pfm" 2>"$T/err"; then ok
        else bad "render $f"; cat "$T/err" >&2; fi
    done
else
    echo "skip: ../shared/scenes absent: SPD scenes and meshes not rendered" >&2
    skip=$((skip + 1))
fi

# An NFF light takes the range its light.N.pos key takes (|x| <= 3.4e38;
# it was 1e18, geometry's bound): a light at 1e30 in the scene traces the
# image the key gives, bit for bit; past the range both are refused.
sed 's/^l -4 -5 8 /l -4e29 -5e29 8e29 /' scenes/spheres.nff >"$T/far.nff"
expect_rc 0 $RTP trace "$T/far.nff" --size 40x30 -i "$T/far.pfm"
expect_rc 0 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/key.pfm" --set light.0.pos=-4e29,-5e29,8e29
cmp -s "$T/far.pfm" "$T/key.pfm" && ok || bad "a far NFF light traces unlike its key"
sed 's/^l -4 -5 8 /l -1.7e38 -2.125e38 3.4e38 /' scenes/spheres.nff >"$T/far.nff"
expect_rc 0 $RTP trace "$T/far.nff" --size 40x30 -i "$T/far.pfm"
cmp -s "$T/far.pfm" "$T/key.pfm" && ok || bad "a light at 3.4e38 traces unlike one at 1e30"
sed 's/^l -4 -5 8 /l -4 -5 3.5e38 /' scenes/spheres.nff >"$T/far.nff"
expect_rc 1 $RTP trace "$T/far.nff" --size 40x30 -i "$T/far.pfm"
grep -q "far.nff:12:9: light z 3.5e38 is out of range (|x| <= 3.4e+38)" "$T/err" && ok ||
    { bad "light past the range: message"; cat "$T/err" >&2; }
expect_rc 1 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/far.pfm" --set light.0.pos=-4,-5,3.5e38

# A material's numbers, a light's colour, ambient and background take the
# range their keys take too (float's: the file stopped at 1e18, the key at
# 3.4e38): at 3.4e38 the file traces the key's image, finite (here: a
# kd of 3.4e38 times a colour's sum overflows, as by key); past it the
# file names the field and the key refuses.  The camera is geometry, 1e18
# in the file and now by key too (a key took 1e30).
finite() { # PFM: every value finite (python3 where there is one)
    command -v python3 >/dev/null || return 0
    python3 -c 'import struct, sys, math
d = open(sys.argv[1], "rb").read().split(b"\n", 3)[3]
sys.exit(not all(math.isfinite(x) for x in struct.unpack("<%df" % (len(d) // 4), d)))' "$1"
}
for c in "s/^f 0.8 0.8 0.75 0.9 0 100000 0 0/f 0.8 0.8 0.75 0.9 0 3.4e38 0 0/|mat.floor.shine=3.4e38" \
         "s/^f 0.9 0.2 0.15 0.8 0.2 30 0 0/f 0.9 0.2 0.15 0.8 0.2 30 0 3.4e38/|mat.red.ior=3.4e38" \
         "s/^l 5 -2 4 0.4 0.4 0.5/l 5 -2 4 0.4 0.4 3.4e38/|light.fill.color=0.4,0.4,3.4e38" \
         "s/^ambient 0.05 0.05 0.05/ambient 3.4e38 0.05 0.05/|ambient=3.4e38,0.05,0.05" \
         "s/^b 0.1 0.15 0.3/b 0.1 3.4e38 0.3/|background=0.1,3.4e38,0.3"; do
    sed "${c%%|*}" scenes/spheres.nff >"$T/big.nff"
    $RTP trace "$T/big.nff" --size 40x30 -q -i "$T/big.pfm" 2>"$T/err" &&
        $RTP trace scenes/spheres.nff --size 40x30 -q -i "$T/bigk.pfm" --set "${c#*|}" &&
        cmp -s "$T/big.pfm" "$T/bigk.pfm" && finite "$T/big.pfm" && ok ||
        bad "a value at 3.4e38 in the file unlike its key ${c#*|}: $(cat "$T/err")"
done
sed 's/^f 0.9 0.2 0.15 0.8 0.2 30 0 0/f 0.9 0.2 0.15 0.8 0.2 3.5e38 0 0/' scenes/spheres.nff >"$T/big.nff"
expect_rc 1 $RTP trace "$T/big.nff" --size 40x30 -i "$T/big.pfm"
grep -q "big.nff:25:24: material Shine 3.5e38 is out of range (|x| <= 3.4e+38)" "$T/err" && ok ||
    { bad "a material's exponent past the range: message"; cat "$T/err" >&2; }
expect_rc 1 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/big.pfm" --set mat.red.shine=3.5e38
sed 's/^from 0 -8 3/from 0 -1e18 3/' scenes/spheres.nff >"$T/big.nff"
$RTP trace "$T/big.nff" --size 40x30 -q -i "$T/big.pfm" 2>"$T/err" &&
    $RTP trace scenes/spheres.nff --size 40x30 -q -i "$T/bigk.pfm" --set camera.from=0,-1e18,3 &&
    cmp -s "$T/big.pfm" "$T/bigk.pfm" && finite "$T/big.pfm" && ok ||
    bad "a camera at 1e18 in the file unlike its key: $(cat "$T/err")"
expect_rc 1 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/big.pfm" --set camera.from=0,-1.1e18,3
grep -q "camera.from: -1.1e+18 is out of range (|x| <= 1e+18" "$T/err" && ok ||
    { bad "camera key past geometry's range: message"; cat "$T/err" >&2; }
sed 's/^from 0 -8 3/from 0 -1.1e18 3/' scenes/spheres.nff >"$T/big.nff"
expect_rc 1 $RTP trace "$T/big.nff" --size 40x30 -i "$T/big.pfm"
# a number just past the limit is said with the digits that tell it from
# the limit ("-1e+18 is out of range (|x| <= 1e+18)" of -1.0000001e18)
expect_rc 1 $RTP trace scenes/spheres.nff --size 40x30 -i "$T/big.pfm" --set camera.at=0,-1.0000001e18,3
grep -q "camera.at: -1.0000001e+18 is out of range (|x| <= 1e+18" "$T/err" && ok ||
    { bad "camera key just past geometry's range: message"; cat "$T/err" >&2; }

# The largest side --size takes traces (the limit once counted a sample
# row and column more than the image has)
expect_rc 0 $RTP trace scenes/spheres.nff --size 1048576x1 -i "$T/wide.pfm" -q
rm -f "$T/wide.pfm"

# an empty file name is said as one (a scene, tree or params file named
# "" said "rtp: cannot open: No such file or directory", naming no file:
# which of merge's parts was it?)
$RTP trace scenes/spheres.nff --size 8x8 --region 0,0,8,4 -o "$T/e0.rtp" -q
for c in "trace ''" "reeval '' -i $T/e.pfm" "info ''" "merge -o $T/e.rtp $T/e0.rtp ''" \
         "reeval $T/e0.rtp --params '' -i $T/e.pfm"; do
    eval "$RTP $c" 2>"$T/err"
    [ $? -eq 1 ] && grep -q "no [a-z]* *file name" "$T/err" && ok ||
        bad "rtp $c: $(cat "$T/err")"
done

# rtp info prints a name's control bytes as '?': an MTL's newmtl takes
# ESC, and a tree file any byte but NUL (escape sequences to the terminal)
printf 'newmtl red\033[31mX\nKd 1 0 0\n' >"$T/esc.mtl"
printf 'mtllib esc.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\033[31mX\nf 1 2 3\n' >"$T/esc.obj"
$RTP trace "$T/esc.obj" --size 8x8 -o "$T/esc.rtp" -q
$RTP info "$T/esc.rtp" >"$T/out"
[ $? -eq 0 ] && grep -q '^mat.0 (red?\[31mX):' "$T/out" && ! grep -q "$(printf '\033')" "$T/out" && ok ||
    bad "rtp info printed a name's ESC: $(cat -v "$T/out" | grep mat)"

# a scene is text: a NUL byte is refused where it is read, naming its line
# and column (/dev/zero was read until memory ran out; UTF-16 gave a
# keyword error), in a scene, an include and on stdin
printf 'v\nfrom 0 0 5 # a comment\000\n' >"$T/nul.nff"
$RTP trace "$T/nul.nff" --size 8x8 -i "$T/nul.pfm" 2>"$T/err"
[ $? -eq 1 ] && grep -q "nul.nff:2:23: a NUL byte" "$T/err" && [ ! -e "$T/nul.pfm" ] && ok ||
    bad "NUL in a comment: $(cat "$T/err")"
printf 'include nul.nff\n' >"$T/inc.nff"
$RTP trace "$T/inc.nff" --size 8x8 -i "$T/nul.pfm" 2>"$T/err"
[ $? -eq 1 ] && grep -q "nul.nff:2:23: a NUL byte" "$T/err" && ok ||
    bad "NUL in an include: $(cat "$T/err")"
if [ -r /dev/zero ] && command -v timeout >/dev/null; then
    timeout 60 $RTP trace /dev/zero --size 8x8 -i "$T/nul.pfm" 2>"$T/err"
    [ $? -eq 1 ] && grep -q "/dev/zero:1:1: a NUL byte" "$T/err" && ok ||
        bad "trace /dev/zero: $(cat "$T/err")"
    head -c 100000 /dev/zero | timeout 60 $RTP trace - --size 8x8 -i "$T/nul.pfm" 2>"$T/err"
    [ $? -eq 1 ] && grep -q "1:1: a NUL byte" "$T/err" && ok ||
        bad "trace - of NULs: $(cat "$T/err")"
fi

# A v block with no view (at equal to from) is refused where the frame is
# made, at its line, after the --set keys, which may repair it (it was
# refused as the file was read, which no key could repair)
printf 'v\nfrom 0 0 5\nat 0 0 5\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\nl 1 1 1\nf 1 0 0 0.5 0.5 30 0 1\ns 0 0 0 1\n' >"$T/samept.nff"
expect_rc 1 $RTP trace "$T/samept.nff" -i "$T/samept.pfm" -q
grep -q "samept.nff:3:1: view at equals view from" "$T/err" && [ ! -e "$T/samept.pfm" ] && ok ||
    bad "a v block's at equal to from: $(cat "$T/err")"
expect_rc 1 $RTP trace "$T/samept.nff" -o "$T/samept.rtp" -q --set camera.up=0,0,1
grep -q "samept.nff:3:1: view at equals view from" "$T/err" && ok ||
    bad "a v block's at equal to from, another camera key set: $(cat "$T/err")"
expect_rc 0 $RTP trace "$T/samept.nff" -i "$T/samept.pfm" -q --set camera.at=0,0,0
printf 'v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\nl 1 1 1\nf 1 0 0 0.5 0.5 30 0 1\ns 0 0 0 1\n' >"$T/fixed.nff"
expect_rc 0 $RTP trace "$T/fixed.nff" -i "$T/fixed.pfm" -q
cmp -s "$T/samept.pfm" "$T/fixed.pfm" && ok || bad "a v block repaired by --set camera.at: not the file's image"
printf 'camera.at=0,0,0\n' >"$T/cam.params"
expect_rc 0 $RTP trace "$T/samept.nff" -i "$T/samep2.pfm" -q --params "$T/cam.params"
# keys that make at equal to from again are said as the keys' fault, with
# the scene's name: stdin's is <stdin>, as every message names it (README)
expect_rc 1 $RTP trace - -i "$T/samep3.pfm" -q --set camera.at=0,0,0 --set camera.from=0,0,0 <"$T/fixed.nff"
grep -q "^rtp: <stdin>: camera.at equals camera.from: no view to trace" "$T/err" && [ ! -e "$T/samep3.pfm" ] && ok ||
    bad "keys making at equal to from, scene on stdin: $(cat "$T/err")"

# A tree file is on the disk before its rename and the rename after it:
# fsync of the temporary file, then the rename, then fsync of the folder
# (without them a crash soon after could leave the name on an empty file).
# Seen through strace, where it runs.
if command -v strace >/dev/null 2>&1 &&
    strace -f -o "$T/st" -e trace=openat,open,fsync,rename,renameat,renameat2 \
        $RTP trace scenes/spheres.nff --size 16x12 -o "$T/sync.rtp" -q 2>/dev/null &&
    grep -q "rename" "$T/st"; then
    awk '/\.rtp-[0-9a-f]*\.tmp/ && /open/ && !tmpfd { n = split($0, w, "= "); tmpfd = w[n] + 0 }
         /fsync\(/ { f = $0; sub(/.*fsync\(/, "", f); f += 0
                     if (!renamed && f == tmpfd) filesync = 1; if (renamed) dirsync = 1 }
         /rename/ && /sync\.rtp/ { renamed = 1 }
         END { exit !(tmpfd && filesync && renamed && dirsync) }' "$T/st" && ok ||
        { bad "trace -o: no fsync of the tree before its rename and of its folder after"; cat "$T/st" >&2; }
else
    skip=$((skip + 1)); echo "skip: no strace (or no ptrace): a tree file's fsync not checked" >&2
fi

# --stats joins the outputs' all-or-nothing rule (session 44): a stats file
# that cannot be written (a full device, a file size limit) leaves the image,
# the tree and the heat map as they were before the command, a new one
# removed (trace --stats /dev/full had exited 1 with both written)
mkdir -p "$T/so"
if [ -w /dev/full ]; then
    expect_rc 1 $RTP trace scenes/spheres.nff --size 8x8 -o "$T/so/n.rtp" -i "$T/so/n.pfm" --stats /dev/full
    [ ! -e "$T/so/n.rtp" ] && [ ! -e "$T/so/n.pfm" ] && grep -q "n.pfm: removed: the --stats file could not be written" "$T/err" &&
        ok || bad "trace --stats /dev/full left its outputs: $(ls "$T/so") $(cat "$T/err")"
    $RTP trace scenes/spheres.nff --size 8x8 -q -o "$T/so/o.rtp" -i "$T/so/o.pfm"
    cp "$T/so/o.rtp" "$T/so/o0.rtp"; cp "$T/so/o.pfm" "$T/so/o0.pfm"
    expect_rc 1 $RTP trace scenes/spheres.nff --size 8x8 --set ambient=0.5 -o "$T/so/o.rtp" -i "$T/so/o.pfm" --stats /dev/full
    cmp -s "$T/so/o.rtp" "$T/so/o0.rtp" && cmp -s "$T/so/o.pfm" "$T/so/o0.pfm" &&
        [ -z "$(ls -A "$T/so" | grep -v '^[no]')" ] && ok || bad "trace --stats /dev/full kept new outputs: $(ls -A "$T/so")"
    # --stats - to a full stdout likewise
    expect_rc 1 sh -c "$RTP trace scenes/spheres.nff --size 8x8 -i '$T/so/s.pfm' --stats - >/dev/full"
    [ ! -e "$T/so/s.pfm" ] && ok || bad "trace --stats - >/dev/full left its image"
    # diff's heat map
    expect_rc 1 $RTP diff "$T/so/o.pfm" "$T/so/o.pfm" -q --heatmap "$T/so/h.png" --stats /dev/full
    [ ! -e "$T/so/h.png" ] && ok || bad "diff --stats /dev/full left its heat map"
fi
# a stats file that fails as a regular file (the file size limit: the long
# scene path makes the JSON longer than 1 KiB, the 4x4 image shorter than
# 512 bytes: dash counts ulimit -f in 512-byte blocks, bash in 1 KiB)
P="$(i=0; while [ $i -lt 400 ]; do printf './'; i=$((i + 1)); done)scenes/spheres.nff"
(ulimit -f 1 && exec $RTP trace "$P" --size 4x4 -i "$T/so/l.pfm" --stats "$T/so/l.json") 2>"$T/err"
[ $? -eq 1 ] && [ ! -e "$T/so/l.pfm" ] && [ ! -e "$T/so/l.json" ] && grep -q "File too large" "$T/err" &&
    [ -z "$(ls -A "$T/so" | grep '^\.rtp')" ] && ok || bad "trace --stats over a size limit: $(ls -A "$T/so") $(cat "$T/err")"

# a --stats FIFO that no one reads: SIGTERM while rtp waits on it puts the
# image back (removed: it was new), as a failed stats file does
if mkfifo "$T/so/f.json" 2>/dev/null; then
    $RTP trace scenes/spheres.nff --size 8x8 -i "$T/so/f.pfm" --stats "$T/so/f.json" 2>/dev/null &
    p=$!; n=0
    while [ ! -e "$T/so/f.pfm" ] && [ $n -lt 200 ]; do sleep 0.05; n=$((n + 1)); done
    # (wait's stderr: dash reports the job it reaps killed, "Terminated",
    # a stray line among the results)
    sleep 0.2; kill -TERM $p; wait $p 2>/dev/null; r=$?
    [ $n -lt 200 ] && [ $r -eq 143 ] && [ ! -e "$T/so/f.pfm" ] && [ -z "$(ls -A "$T/so" | grep '^\.rtp')" ] &&
        ok || bad "SIGTERM on a --stats FIFO left its image: rc $r, $n, $(ls -A "$T/so")"
fi

# Messages show a file's name as the library shows a scene's words: ESC,
# C1 (CSI), a right-to-left override and bytes that are not UTF-8 as '?',
# UTF-8 as it is (a scene named "e<ESC>[7mX.nff" turned the terminal's
# text inverse in its error)
mkdir -p "$T/nm"
n=$(printf '%s/nm/e\033[7mX\302\233\351\342\200\256Y.nff' "$T")
printf 'bogus\n' > "$n"
expect_rc 1 $RTP trace "$n" -i "$T/nm/x.pfm"
LC_ALL=C grep -q 'nm/e?\[7mX??????Y\.nff:1:1: unknown keyword' "$T/err" &&
    ! LC_ALL=C grep -q "$(printf '\033')" "$T/err" && ! LC_ALL=C grep -q "$(printf '\233')" "$T/err" &&
    ok || bad "a name's control bytes reached the terminal: $(od -c "$T/err" | head -3)"
# (and a --params file's name before its line and column)
expect_rc 1 $RTP trace scenes/spheres.nff --size 8x8 --params "$n" -i "$T/nm/x.pfm"
LC_ALL=C grep -q 'nm/e?\[7mX??????Y\.nff:1:1: ' "$T/err" && ! LC_ALL=C grep -q "$(printf '\033')" "$T/err" &&
    ok || bad "--params named by control bytes: $(od -c "$T/err" | head -3)"

rm -rf "$T"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
