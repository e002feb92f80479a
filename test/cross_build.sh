#!/bin/sh
# Reproducible across builds: rtp built by other compilers and at other
# optimisation levels must trace the same images and write the same tree
# files, bit for bit, and re-evaluate light moves (exact and light-buffer
# shadows) and a stream of colour and kd edits (the caches' planes, made
# by SSE2 code or by its plain C twin with -DRTP_NO_SSE2) to the same
# images.  IEEE arithmetic in the same order
# gives the same bits; a difference is a compiler folding what C does not
# let it fold (gcc 12.2 at -O2 dropped the float rounding of hit
# positions, see rtpi_surface_from_point) or an expression whose order is
# left to the compiler, or a libm whose functions round differently on
# another CPU (glibc picks FMA variants of pow, exp, sin... by the CPU;
# .ci/run adds the gcc build with those turned off).  .ci/run keeps each
# build's rtp and calls this
# (not a cli_*.sh: make test has one build).
#   cross_build.sh REFERENCE_RTP OTHER_RTP...
# The project's scenes always; with ../shared the SPD scenes too (at
# 128x128, and balls by the SPD procedure).
[ $# -ge 2 ] || { echo "usage: cross_build.sh REFERENCE_RTP OTHER_RTP..." >&2; exit 2; }
T=${TMPDIR:-/tmp}/rtp-repro.$$
mkdir -p "$T"
trap 'rm -rf "$T"' EXIT
pass=0; fail=0; skip=0
shared=""
for d in ../shared ../../shared; do [ -d "$d/scenes/spd" ] && shared=$d && break; done
[ -n "$shared" ] || { echo "SKIP: ../shared/scenes absent: SPD scenes not compared" >&2; skip=$((skip + 1)); }

# Edits a stream makes from the caches (colour planes, a material's
# planes: the SSE2 code and its plain C twin), light 0 and material 0,
# which every scene here with a light has; $more adds lines.
stream='light.0.color=1,0.6,0.4
mat.0.kd=0.3
light.0.color=0.4,0.6,1
mat.0.kd=0.55'
more=""

# run BUILD_INDEX RTP NAME SCENE ARGS...: trace, then two moves of light
# 0, then the stream of edits
run() {
    i=$1; R=$2; n=$3; sc=$4; shift 4
    "$R" trace "$sc" "$@" -o "$T/$n.$i.rtp" -i "$T/$n.$i.pfm" -q -j2 &&
        "$R" reeval "$T/$n.$i.rtp" --set light.0.pos=2,3,9 --shadows exact \
            -i "$T/$n.$i.exact.pfm" -q -j2 &&
        "$R" reeval "$T/$n.$i.rtp" --set light.0.pos=2,3,9 --shadows lightbuf \
            -i "$T/$n.$i.lightbuf.pfm" -q -j2 &&
        printf '%s\n%s' "$stream" "$more" |
        "$R" reeval "$T/$n.$i.rtp" --stream -i "$T/$n.$i.s%d.pfm" -q -j2
}

# compare NAME SCENE ARGS...
compare() {
    n=$1; sc=$2; shift 2
    i=0
    for R in $builds; do
        run $i "$R" "$n" "$sc" "$@" || { fail=$((fail + 1)); echo "FAIL: $R on $n" >&2; }
        if [ $i -gt 0 ]; then
            diffs=""
            for k in pfm rtp exact.pfm lightbuf.pfm s0.pfm s1.pfm s2.pfm s3.pfm; do
                cmp -s "$T/$n.0.$k" "$T/$n.$i.$k" || diffs="$diffs $k"
            done
            [ -z "$more" ] || for k in s4.pfm s5.pfm; do
                cmp -s "$T/$n.0.$k" "$T/$n.$i.$k" || diffs="$diffs $k"
            done
            if [ -z "$diffs" ]; then
                pass=$((pass + 1))
            else
                fail=$((fail + 1))
                echo "FAIL: $n: $R differs from $first in:$diffs" >&2
            fi
        fi
        i=$((i + 1))
    done
}

builds="$*"
first=$1
for sc in scenes/*.nff; do
    # (a scene without lights has no light 0 to move)
    grep -q '^l ' "$sc" || continue
    compare "$(basename "$sc" .nff)" "$sc" --size 96x72
done
if [ -n "$shared" ]; then
    for sc in "$shared"/scenes/spd/*.nff; do
        compare "$(basename "$sc" .nff)" "$sc" --size 128x128
    done
    # (three lights: light 2's plane made at its first edit)
    more='light.2.color=0.2,0.9,0.5
light.2.color=1,1,1'
    compare balls-spd "$shared/scenes/spd/balls_s4.nff" --spd
    more=""
fi
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
