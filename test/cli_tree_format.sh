#!/bin/sh
# lib/tree-format.md against lib/treefile.c: test/tree_format.py, a reader
# and writer of .rtp written from the document alone, parses files rtp
# writes (every section, CRC, node and field; re-encoding them must give
# rtp's very bytes; rtp info's keys and --stats must match what the file
# holds), and writes files the document says rtp must accept (extensions
# anywhere, longer varints, a newer minor, format 1 ...) or refuse by name
# (an unknown required section, a newer major, lengths that disagree,
# right CRCs over wrong data ...).  Skipped without python3.
TEST_NAME=format
. "$(dirname "$0")/common.sh"
need_python "the tree format's independent reader"
PY="python3 test/tree_format.py"

# files of every kind the format holds
lights=""
for i in $(seq 2 41); do lights="$lights --set light.$i.pos=$i,-3,4"; done
$RTP trace scenes/checker.nff --size 8x6 -i "$T/tex.pfm" -q || bad "trace for a PFM texture"
t() { n=$1; shift; $RTP trace "$@" -j 1 -q -o "$T/$n.rtp" || bad "trace $n: $*"; }
t refract scenes/spheres.nff --size 24x18
t texb scenes/textured.nff --size 24x18
t texr scenes/textured.nff --size 24x18 --set mat.1.texture="$T/tex.pfm"
t checker scenes/textured.nff --size 20x10 --set mat.2.checker=1 --set mat.2.checker_scale=0.3
t lights42 scenes/prims.nff --size 16x12 $lights
t nolights scenes/stiff/nolights.nff --size 16x12
t spd scenes/spheres.nff --spd --region 100,200,124,216
t region scenes/spheres.nff --size 40x30 --region 5,7,29,20
t minweight scenes/spheres.nff --size 24x18 --min-weight 0.3 --depth 8
t depth1 scenes/prims.nff --size 16x12 --depth 1
t obj scenes/quad.obj --size 16x12
# materials with their own ambient coefficient (MAMB), grey and RGB
t ambient scenes/textured.nff --size 20x10 --set mat.2.checker=1 --set mat.0.ambient=0.25 \
    --set mat.2.ambient=0.5,0.125,2 --set mat.ball.ambient=0
cp test/golden/format1.rtp "$T/format1.rtp"
# MAMB read back and written again (merge of one file rewrites it): the same bytes
$RTP merge -o "$T/ambient.again" "$T/ambient.rtp" -q && cmp -s "$T/ambient.rtp" "$T/ambient.again" &&
    ok || bad "a tree with MAMB read and written again differs"
for f in "$T"/*.rtp; do
    out=$($PY --check "$RTP" "$f" 2>&1)
    if [ $? -eq 0 ]; then ok; else bad "$(basename "$f"): $(echo "$out" | grep -v '^[a-z]' | head -5)"; fi
done
# trace's and reeval's --stats sizes against the file's
for n in refract lights42 spd; do
    case $n in
    refract) $RTP trace scenes/spheres.nff --size 24x18 -j 1 -q -o "$T/s.rtp" --stats "$T/t.json";;
    lights42) $RTP trace scenes/prims.nff --size 16x12 $lights -j 1 -q -o "$T/s.rtp" --stats "$T/t.json";;
    spd) $RTP trace scenes/spheres.nff --spd --region 100,200,124,216 -j 1 -q -o "$T/s.rtp" --stats "$T/t.json";;
    esac
    $RTP reeval "$T/s.rtp" -i "$T/s.ppm" -j 1 -q --stats "$T/r.json"
    out=$($PY --stats "$T/s.rtp" "$T/t.json" "$T/r.json" 2>&1) && ok || bad "--stats of $n: $out"
done
# and the document's files rtp must accept or refuse
out=$($PY --craft "$RTP" "$T/refract.rtp" "$T/texb.rtp" "$T/lights42.rtp" "$T/format1.rtp" \
    "$T/ambient.rtp" 2>&1)
n=$(echo "$out" | sed -n 's/^\([0-9]*\) passed, \([0-9]*\) failed$/\1 \2/p')
[ -n "$n" ] && pass=$((pass + ${n% *})) && fail=$((fail + ${n#* }))
[ -n "$n" ] && [ "${n#* }" -eq 0 ] || echo "$out" | grep -v passed | head -20 >&2
[ -n "$n" ] || bad "tree_format.py --craft: $(echo "$out" | tail -3)"
# END: a named file refuses bytes after it, standard input stops at END
cat "$T/refract.rtp" >"$T/tail.rtp"; printf 'more' >>"$T/tail.rtp"
$RTP info "$T/tail.rtp" -q 2>"$T/err"
[ $? -eq 1 ] && grep -q "bytes after END" "$T/err" && ok || bad "bytes after END in a file taken"
cat "$T/tail.rtp" | $RTP info - -q && ok || bad "a pipe's bytes after END refused"
$RTP info - -q <"$T/tail.rtp" && ok || bad "standard input from a file: bytes after END refused"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
