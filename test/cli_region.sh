#!/bin/sh
# Splitting a frame across machines: regions traced apart (here with
# xargs -P, as a farm would), merged, must equal a whole-frame run bit for
# bit — images, trees, and re-evaluations of the merged tree.
TEST_NAME=region
. "$(dirname "$0")/common.sh"
S=scenes/spheres.nff

for mode in "" "--spd"; do
    if [ -n "$mode" ]; then size=512; regions="0,0,512,200 0,200,300,512 300,200,512,512"
    else size=72; regions="0,0,40,30 40,0,72,30 0,30,72,72"; fi
    $RTP trace $S $mode --size ${size}x$size -o "$T/full.rtp" -i "$T/full.pfm" -q
    # the farm: one job per region, two at a time
    echo $regions | tr ' ' '\n' |
        xargs -P 2 -I R $RTP trace $S $mode --size ${size}x$size --region R \
            -o "$T/part-R.rtp" -i "$T/part-R.pfm" -q
    $RTP merge -o "$T/merged.rtp" -i "$T/merged.pfm" "$T"/part-*.rtp
    cmp -s "$T/full.pfm" "$T/merged.pfm" && ok || bad "merged trees $mode: image differs"
    args=""
    for r in $regions; do args="$args $T/part-$r.pfm@${r%%,*},$(echo $r | cut -d, -f2)"; done
    $RTP merge -i "$T/mimg.pfm" --size ${size}x$size $args
    cmp -s "$T/full.pfm" "$T/mimg.pfm" && ok || bad "merged images $mode differ"
    # the merged tree re-evaluates like the whole one, moved light and class D too
    for kv in "light.key.pos=1,-4,5" "mat.floor.ks=0.3"; do
        $RTP reeval "$T/merged.rtp" --set $kv -i "$T/a.pfm" -q
        $RTP reeval "$T/full.rtp" --set $kv -i "$T/b.pfm" -q
        cmp -s "$T/a.pfm" "$T/b.pfm" && ok || bad "reeval of merged tree $mode --set $kv"
    done
    # a region tree re-evaluates its own pixels like the whole tree does
    r=$(echo $regions | cut -d' ' -f2)
    $RTP reeval "$T/part-$r.rtp" --set light.key.pos=1,-4,5 -i "$T/c.pfm" -q
    $RTP reeval "$T/full.rtp" --set light.key.pos=1,-4,5 --region $r -i "$T/d.pfm" -q
    cmp -s "$T/c.pfm" "$T/d.pfm" && ok || bad "region tree reeval $mode"
    # ... from work on the region only (it evaluated the whole frame and
    # cut the image: samples, shadow queries and re-traces the frame's),
    # in a stream too (the third region: the floor, traced again for ks)
    r=$(echo $regions | cut -d' ' -f3)
    printf 'light.key.pos=1,-4,5\nmat.floor.ks=0.3\nlight.key.color=1,0,0\n' >"$T/ed"
    $RTP reeval "$T/part-$r.rtp" --stream -i "$T/e%d.pfm" --stats "$T/e.json" -q <"$T/ed"
    $RTP reeval "$T/full.rtp" --region $r --stream -i "$T/f%d.pfm" --stats "$T/f.json" -q <"$T/ed"
    for i in 0 1 2; do
        cmp -s "$T/e$i.pfm" "$T/f$i.pfm" && ok || bad "region stream $mode: frame $i differs"
    done
    sed 's/"seconds[^,]*, //; s/"load_seconds[^,]*, //; s/"shadow_seconds[^,]*, //; s/, "file_bytes.*//' \
        "$T/e.json" >"$T/e.work"
    sed 's/"seconds[^,]*, //; s/"load_seconds[^,]*, //; s/"shadow_seconds[^,]*, //; s/, "file_bytes.*//' \
        "$T/f.json" >"$T/f.work"
    cmp -s "$T/e.work" "$T/f.work" && grep -q '"retraced_samples": [1-9]' "$T/f.work" && ok ||
        bad "reeval --region $mode did other work than the region's tree: $(diff "$T/e.work" "$T/f.work" | cut -c 1-400 | head -4)"
    rm -f "$T"/part-*
done
# a stream of colour edits re-evaluated region by region equals the
# frame's stream bit for bit where pixels elsewhere in the frame are bright
# (a red of 30: the frame checks its pixels for lost digits, a region
# without such pixels need not).  The chain of one term's edits kept its
# P' in floats, a rounding the frame's checked sums did not make, and a
# pixel that lost digits sent the whole frame down the full path, S made
# anew: frames 3 to 11 of this stream, and frame 3 of the second (a bump
# re-traced elsewhere in the frame, then two ambient edits), a float step
# (5.96e-8) apart at 561 of 561 pixels
$RTP trace $S --size 33x17 --set mat.red.color=30 -o "$T/hdr.rtp" -q
printf '%s\n' ambient=0.742,0.795,0.942 light.key.color=0.840,0.776,0.249 \
    light.key.color=0.901,0.113,0.469 light.fill.color=0.381,0.102,0.249 \
    light.fill.color=0.408,0.182,0.867 background=0.160,0.797,0.139 \
    background=0.127,0.002,0.871 light.fill.color=0.774,0.960,0.166 \
    light.fill.color=0.289,0.961,0.539 light.fill.color=0.182,0.969,0.197 \
    background=0.299,0.361,0.166 light.fill.color=0.264,0.332,0.817 >"$T/cb"
$RTP trace $S --size 33x17 -o "$T/lo.rtp" -q
printf '%s\n' mat.glass.kd=0.816 mat.glass.bump=waves \
    "mat.floor.color=0.749,1.2,0.511 ambient=0.712,0.752,1.14" ambient=0.693,0.156,0.683 >"$T/lo"
for c in "hdr cb 12 0,0,25,8 25,0,33,8 0,8,33,17" "lo lo 4 0,0,33,3 0,3,10,4 10,3,33,4 0,4,33,17"; do
    set -- $c
    tr=$1 ed=$2 nf=$3
    shift 3
    $RTP reeval "$T/$tr.rtp" --stream --stale retrace -i "$T/w%d.pfm" -q <"$T/$ed"
    for r in "$@"; do
        $RTP reeval "$T/$tr.rtp" --stream --stale retrace --region $r -i "$T/r$r-%d.pfm" -q <"$T/$ed"
    done
    i=0
    while [ $i -lt $nf ]; do
        args=""
        for r in "$@"; do args="$args $T/r$r-$i.pfm@${r%%,*},$(echo $r | cut -d, -f2)"; done
        $RTP merge -i "$T/wm.pfm" --size 33x17 $args
        cmp -s "$T/w$i.pfm" "$T/wm.pfm" && ok ||
            bad "$tr stream by regions: frame $i differs: $($RTP diff "$T/w$i.pfm" "$T/wm.pfm")"
        i=$((i + 1))
    done
    rm -f "$T"/r*.pfm "$T"/w*.pfm
done
# merging one whole-frame tree rewrites it in today's format: a format-1
# file (test/golden, written before format 2) comes out as format 2,
# smaller, and re-evaluates to the same image
G=test/golden/format1.rtp
$RTP merge -o "$T/f2.rtp" "$G"
$RTP reeval "$G" --set light.0.color=1,0.5,0.25 -i "$T/a.pfm" -q
$RTP reeval "$T/f2.rtp" --set light.0.color=1,0.5,0.25 -i "$T/b.pfm" -q
cmp -s "$T/a.pfm" "$T/b.pfm" && ok || bad "format-1 file merged into format 2 re-evaluates otherwise"
[ "$(od -An -tu1 -j20 -N1 "$T/f2.rtp" | tr -d ' ')" = 2 ] &&
    [ "$(wc -c < "$T/f2.rtp")" -lt "$(wc -c < "$G")" ] && ok ||
    bad "merged format-1 file is not a smaller format-2 file"
# regions that overlap or leave a gap are refused
$RTP trace $S --size 32x32 --region 0,0,32,20 -o "$T/p1.rtp" -i "$T/p1.pfm" -q
$RTP trace $S --size 32x32 --region 0,10,32,32 -o "$T/p2.rtp" -i "$T/p2.pfm" -q
# info says which part of which frame a region tree holds, in --stats too
$RTP info "$T/p2.rtp" | grep -q "region: pixels 0,10 to 32,32 of a 32x32 frame" && ok ||
    bad "info: no region line"
$RTP info "$T/p2.rtp" --stats - | grep -q '"width": 32, "height": 22, .*"full_width": 32, "full_height": 32, "region_x": 0, "region_y": 10' &&
    ok || bad "info --stats: no region keys: $($RTP info "$T/p2.rtp" --stats -)"
$RTP merge -o "$T/x.rtp" "$T/p1.rtp" "$T/p2.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q overlap "$T/err" && ok || bad "overlap not refused"
$RTP merge -o "$T/x.rtp" "$T/p1.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q uncovered "$T/err" && ok || bad "gap not refused"
# parts of another setup are refused with what differs (a farm of many
# jobs: which one ran with another option or --set is the thing to find;
# every such refusal said "another scene, frame or options, or edited
# otherwise")
$RTP trace $S --size 32x32 --region 0,20,32,32 --depth 4 -o "$T/pd.rtp" -q
$RTP merge -o "$T/x.rtp" "$T/p1.rtp" "$T/pd.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q "pd.rtp cannot join .*p1.rtp: it was traced to depth 4, .*p1.rtp to depth 5" "$T/err" &&
    ok || bad "merge of another depth: $(cat "$T/err")"
# the same refusal under long paths says its reason whole (the CLI named
# the parts inside the library's 256-byte message: under a TMPDIR of ~100
# characters it ended at "to depth 4, ")
L="$T/$(printf '%0100d' 0)"
mkdir "$L" && cp "$T/p1.rtp" "$T/pd.rtp" "$L/"
$RTP merge -o "$L/x.rtp" "$L/p1.rtp" "$L/pd.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q "pd.rtp cannot join $L/p1.rtp: it was traced to depth 4, $L/p1.rtp to depth 5\$" "$T/err" &&
    [ ! -e "$L/x.rtp" ] && ok || bad "merge of another depth, long paths: $(cat "$T/err")"
rm -rf "$L"
$RTP trace $S --size 32x32 --region 0,20,32,32 --set mat.red.kd=0.5 -o "$T/pk.rtp" -q
$RTP merge -o "$T/x.rtp" "$T/p1.rtp" "$T/pk.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q "given another mat.1.kd (red) than" "$T/err" &&
    ok || bad "merge of another --set: $(cat "$T/err")"
$RTP trace $S --size 32x32 --region 0,20,32,32 --set light.1.pos=0,0,9 -o "$T/pl.rtp" -q
$RTP merge -o "$T/x.rtp" "$T/pl.rtp" "$T/p1.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q "p1.rtp cannot join .*pl.rtp: it was given another light.1.pos (fill) than" "$T/err" &&
    ok || bad "merge of another light: $(cat "$T/err")"
$RTP trace scenes/prims.nff --size 32x32 --region 0,20,32,32 -o "$T/ps.rtp" -q
$RTP merge -o "$T/x.rtp" "$T/p1.rtp" "$T/ps.rtp" 2>"$T/err"
[ $? -eq 1 ] && grep -q "it was traced from another scene" "$T/err" &&
    ok || bad "merge of another scene: $(cat "$T/err")"
# image regions holding NaN (a region's pixels may be anything) merge as
# they are, and an overlap on a NaN pixel is still found (NaN once marked
# "not covered yet")
printf 'PF\n2 1\n-1.0\n' >"$T/nan.pfm"
printf '\000\000\300\177\000\000\000\000\000\000\000\000\000\000\200\077\000\000\200\077\000\000\200\077' >>"$T/nan.pfm"
tail -c 24 "$T/nan.pfm" >"$T/row"
cat "$T/row" "$T/row" >"$T/rows"
$RTP merge -i "$T/mnan.pfm" --size 2x2 "$T/nan.pfm@0,0" "$T/nan.pfm@0,1" 2>"$T/err" &&
    tail -c 48 "$T/mnan.pfm" | cmp -s - "$T/rows" &&
    ok || bad "merge of regions holding NaN: $(cat "$T/err")"
$RTP merge -i "$T/mnan.pfm" --size 2x2 "$T/nan.pfm@0,0" "$T/nan.pfm@0,0" "$T/nan.pfm@0,1" 2>"$T/err"
[ $? -eq 1 ] && grep -q overlaps "$T/err" && ok || bad "overlap on a NaN pixel not found"
# a CRLF PFM (a text-mode writer's header) reads alike from its path and
# from stdin redirected from it (stdin read it a byte off)
printf 'PF\r\n2 1\r\n-1.0\r\n' >"$T/crlf.pfm"
printf '\000\000\200\076\000\000\000\077\000\000\100\077\315\314\314\075\315\314\114\076\232\231\231\076' >>"$T/crlf.pfm"
$RTP diff "$T/crlf.pfm" - --fail-above max_abs=0 -q <"$T/crlf.pfm" && ok || bad "CRLF PFM from stdin differs"
$RTP trace $S --size 32x32 --region 0,0,99,9 -i "$T/p3.pfm" -q 2>/dev/null
[ $? -eq 1 ] && ok || bad "region outside the frame accepted"
# a region of four fields, none empty: a usage error (strtok took these)
for r in 0,0,8,8, 0,,0,8,8 ,0,0,8,8; do
    $RTP trace $S --size 32x32 --region $r -i "$T/p4.pfm" -q 2>/dev/null
    [ $? -eq 2 ] && [ ! -e "$T/p4.pfm" ] && ok || bad "--region $r accepted"
done
# parts whose texture files differ (the file changed between two farm
# jobs) are another scene: refused, in either order (they merged, the
# image depending on the order)
cp scenes/textured.nff scenes/quad.obj "$T/" && cp scenes/tex4.ppm "$T/tex4.ppm"
$RTP trace "$T/textured.nff" --size 24x24 --region 0,0,24,12 -o "$T/ta.rtp" -q
cp scenes/tex4b.ppm "$T/tex4.ppm"
$RTP trace "$T/textured.nff" --size 24x24 --region 0,12,24,24 -o "$T/tb.rtp" -q
for order in "ta tb" "tb ta"; do
    set -- $order
    $RTP merge -o "$T/tm.rtp" "$T/$1.rtp" "$T/$2.rtp" 2>"$T/err"
    [ $? -eq 1 ] && [ ! -e "$T/tm.rtp" ] && grep -q "$T/$2.rtp" "$T/err" && ok ||
        bad "parts of other texture images merged ($order): $(cat "$T/err")"
done
# merge -o F -i F: the image replaced the merged tree (a usage error, as
# -o - -i - is)
$RTP merge -o "$T/same.pfm" -i "$T/same.pfm" "$T/p1.rtp" "$T/p2.rtp" 2>"$T/err"
[ $? -eq 2 ] && [ ! -e "$T/same.pfm" ] && ok || bad "merge -o F -i F accepted"
# the item buffer's decisions do not depend on where the frame is split
# (an occluder cache kept from the query before made a region's pixel
# next to the split other than the whole frame's: teapot_s6 at 256x256,
# light at -2,1,4, split at column 46, 0.033 at pixel 46,97)
TP=../shared/scenes/spd/teapot_s6.nff
if [ -r "$TP" ]; then
    E="--set light.0.pos=-2,1,4 --shadows itembuf -j1 -q"
    $RTP trace $TP --size 256x256 -o "$T/tf.rtp" -q
    $RTP trace $TP --size 256x256 --region 0,0,46,256 -o "$T/tl.rtp" -q
    $RTP trace $TP --size 256x256 --region 46,0,256,256 -o "$T/tr.rtp" -q
    $RTP reeval "$T/tf.rtp" $E -i "$T/tf.pfm"
    $RTP reeval "$T/tl.rtp" $E -i "$T/tl.pfm"
    $RTP reeval "$T/tr.rtp" $E -i "$T/tr.pfm"
    $RTP merge -i "$T/ts.pfm" --size 256x256 "$T/tl.pfm@0,0" "$T/tr.pfm@46,0"
    cmp -s "$T/tf.pfm" "$T/ts.pfm" && ok ||
        bad "itembuf: split frame differs: $($RTP diff "$T/tf.pfm" "$T/ts.pfm")"
else
    echo "skip: ../shared/scenes/spd/teapot_s6.nff absent: item buffer split not checked" >&2
    skip=$((skip + 1))
fi

# A part named as merge's output is refused, the part kept (a tree merged
# over its first part, an image over its second: exit 0, the part gone)
$RTP trace scenes/spheres.nff --size 40x30 --region 0,0,40,15 -o "$T/q0.rtp" -i "$T/q0.pfm" -q
$RTP trace scenes/spheres.nff --size 40x30 --region 0,15,40,30 -o "$T/q1.rtp" -i "$T/q1.pfm" -q
cp "$T/q0.rtp" "$T/q0.orig"
cp "$T/q1.pfm" "$T/q1.orig"
$RTP merge -o "$T/q0.rtp" "$T/q0.rtp" "$T/q1.rtp" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/q0.rtp" "$T/q0.orig" && grep -q "merge: -o .*q0.rtp is a part .*q0.rtp: writing it would replace it" "$T/err" &&
    [ "$(wc -l <"$T/err")" -eq 1 ] && ok ||
    bad "merge -o over a part: $(cat "$T/err")"
$RTP merge -i "$T/q1.pfm" --size 40x30 "$T/q0.pfm@0,0" "$T/q1.pfm@0,15" 2>"$T/err"
[ $? -eq 2 ] && cmp -s "$T/q1.pfm" "$T/q1.orig" && ok || bad "merge -i over a part image: $(cat "$T/err")"

# a part's offset past INT_MAX is refused (sscanf's %d wrapped
# 4294967311,0 to 15,0 and merged the part there, exit 0)
$RTP merge -i "$T/qw.pfm" --size 40x30 "$T/q0.pfm@0,0" "$T/q1.pfm@0,4294967311" 2>"$T/err"
[ $? -eq 2 ] && [ ! -e "$T/qw.pfm" ] && grep -q "expected IMAGE@X,Y" "$T/err" && ok ||
    bad "merge of a part at 0,4294967311: $(cat "$T/err")"
# an image part on stdin, -@X,Y (refused as an unknown option)
$RTP merge -i "$T/qs.pfm" --size 40x30 "$T/q0.pfm@0,0" -@0,15 <"$T/q1.pfm" 2>"$T/err" &&
    $RTP merge -i "$T/qf.pfm" --size 40x30 "$T/q0.pfm@0,0" "$T/q1.pfm@0,15" &&
    cmp -s "$T/qs.pfm" "$T/qf.pfm" && ok || bad "merge of an image part on stdin: $(cat "$T/err")"
# merge -o TREE -i IMAGE is one pair, as trace's is: an image that fails
# (a full disk) puts an old tree back and removes a new one (both were
# left, exit 1)
if [ -w /dev/full ]; then
    ln -sf /dev/full "$T/full.pfm"
    cp "$T/q0.rtp" "$T/qm.rtp"
    $RTP merge -o "$T/qm.rtp" -i "$T/full.pfm" "$T/q0.rtp" "$T/q1.rtp" 2>"$T/err"
    [ $? -eq 1 ] && cmp -s "$T/qm.rtp" "$T/q0.rtp" && ok ||
        bad "merge -o old -i full: the tree replaced: $(cat "$T/err")"
    $RTP merge -o "$T/qn.rtp" -i "$T/full.pfm" "$T/q0.rtp" "$T/q1.rtp" 2>"$T/err"
    [ $? -eq 1 ] && [ ! -e "$T/qn.rtp" ] && ok ||
        bad "merge -o new -i full: the tree left: $(cat "$T/err")"
else
    skip=$((skip + 1)); echo "skip: /dev/full not writable: merge's pair not checked" >&2
fi
# '-' and /dev/stdin, two names of one pipe, are two parts from stdin: a
# usage error (the second read it empty: "empty: not an rtp tree file",
# exit 1)
if [ -e /dev/stdin ]; then
    cat "$T/q0.rtp" | $RTP merge -o "$T/qd.rtp" - /dev/stdin "$T/q1.rtp" 2>"$T/err"
    [ $? -eq 2 ] && grep -q "only one part can come from stdin" "$T/err" && ok ||
        bad "merge - /dev/stdin: $(cat "$T/err")"
    cat "$T/q0.pfm" | $RTP diff - /dev/stdin 2>"$T/err" >/dev/null
    [ $? -eq 2 ] && grep -q "only one image can come from stdin" "$T/err" && ok ||
        bad "diff - /dev/stdin: $(cat "$T/err")"
else
    skip=$((skip + 1)); echo "skip: no /dev/stdin: stdin's other name not checked" >&2
fi
# --size with region trees is a usage error (it was ignored: the merged
# frame is the trees', whatever --size said)
$RTP merge -o "$T/qz.rtp" --size 80x60 "$T/q0.rtp" "$T/q1.rtp" 2>"$T/err"
[ $? -eq 2 ] && [ ! -e "$T/qz.rtp" ] && grep -q "size is for region images" "$T/err" && ok ||
    bad "merge of trees with --size: $(cat "$T/err")"

rm -rf "$T"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
