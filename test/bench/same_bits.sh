#!/bin/bash
# same_bits.sh — do two builds of rtp make the same bytes?  A change meant
# to make rtp faster without changing its arithmetic must leave every image
# and tree file as it was; this runs both builds over the same work and
# compares every output with cmp.
#
#   test/bench/same_bits.sh OLD_ROOT NEW_ROOT OUTDIR [SCENE...]
#
# OLD_ROOT and NEW_ROOT are built checkouts (their ./rtp); OUTDIR gets
# old/ and new/ with every output, and differ.txt listing those that
# differ.  The work, per scene (by default the project's scenes, the stiff
# and fuzz scenes, and ../shared's small SPD scenes s1 and s2, traced at
# 96x96, SPD ones with --spd at 128x128; -j1 and -j2 by turns, as a
# recording with one worker writes its tree by another path than with
# several): the trace's image and tree file,
# then six five-line --streams (light 0 moved twice, light 1 moved or
# added, light 0's colour, material 0's kd) in the shadow modes exact -j1,
# lightbuf:256 -j1, lightbuf:64 -j2, itembuf:256 -j2, auto -j2 and
# lightbuf -j1 (its default resolution, which since session 48 follows the
# tree and may differ between the two builds: its answers are exact at any
# resolution, so the frames must not): 33 files a scene.  Prints how many files were compared and how many
# differ; exits 1 when any does (or when a run failed on one side only).
set -u
if [ $# -lt 3 ]; then
    echo "usage: same_bits.sh OLD_ROOT NEW_ROOT OUTDIR [SCENE...]" >&2
    exit 2
fi
old=$(cd "$1" && pwd) || exit 2
new=$(cd "$2" && pwd) || exit 2
out=$3
shift 3
here=$(cd "$(dirname "$0")/../.." && pwd)
shared=""
for d in "$here/../shared" "$here/../../shared"; do
    [ -d "$d/scenes/spd" ] && shared=$d && break
done
if [ $# -gt 0 ]; then
    scenes=("$@")
else
    scenes=("$here"/scenes/*.nff "$here"/scenes/stiff/*.nff "$here"/test/fuzz_scenes/*.nff)
    if [ -n "$shared" ]; then
        scenes+=("$shared"/scenes/spd/*_s1.nff "$shared"/scenes/spd/*_s2.nff)
    else
        echo "same_bits: ../shared absent: the SPD scenes left out" >&2
    fi
fi
mkdir -p "$out/old" "$out/new" || exit 2

# a point moved from light 0 (or from the eye where the scene has no
# light) by a few percent of its distance from the origin, and from the
# origin by as much where it lies at the origin: "X,Y,Z"
move() { # nff fx fy fz
    awk -v fx="$2" -v fy="$3" -v fz="$4" '
        $1 == "from" && !e { ex = $2; ey = $3; ez = $4; e = 1 }
        $1 == "l" && !l { lx = $2; ly = $3; lz = $4; l = 1 }
        END {
            if (!l) { lx = ex; ly = ey; lz = ez }
            r = sqrt(lx * lx + ly * ly + lz * lz)
            if (r == 0) r = 1
            printf "%.9g,%.9g,%.9g\n", lx + fx * r, ly + fy * r, lz + fz * r
        }' "$1"
}

run_side() { # root dir
    local rtp=$1/rtp dir=$2 nff name base opts m mode j st tj=1
    for nff in "${scenes[@]}"; do
        tj=$((3 - tj))
        name=$(basename "$nff" .nff)
        base=$dir/$name
        opts=(--size 96x96)
        case $nff in */spd/*) opts=(--spd --size 128x128) ;; esac
        if ! (cd "$(dirname "$nff")" &&
            "$rtp" trace "$(basename "$nff")" "${opts[@]}" -j$tj -q -o "$base.rtp" -i "$base.pfm"); then
            echo "$name: trace failed" >>"$dir/failed.txt"
            continue
        fi
        st="light.0.pos=$(move "$nff" 0.05 -0.04 0.03)
light.0.pos=$(move "$nff" -0.06 0.05 0.04)
light.1.pos=$(move "$nff" 0.04 0.06 -0.05)
light.0.color=0.5,0.7,1
mat.0.kd=0.35"
        m=0
        for mode in exact:1 lightbuf:256:1 lightbuf:64:2 itembuf:256:2 auto:2 lightbuf:1; do
            j=${mode##*:}
            mode=${mode%:*}
            m=$((m + 1))
            if ! printf '%s\n' "$st" |
                "$rtp" reeval "$base.rtp" --stream --shadows "$mode" -j "$j" -q \
                    -i "$base.s$m.%d.pfm" 2>"$base.s$m.err"; then
                echo "$name: stream $mode failed" >>"$dir/failed.txt"
            fi
        done
    done
}

run_side "$old" "$out/old" &
run_side "$new" "$out/new"
wait
: >"$out/differ.txt"
n=0
d=0
for f in "$out"/old/*.pfm "$out"/old/*.rtp "$out"/old/*.err; do
    [ -e "$f" ] || continue
    n=$((n + 1))
    g=$out/new/$(basename "$f")
    cmp -s "$f" "$g" || { d=$((d + 1)); echo "$(basename "$f")" >>"$out/differ.txt"; }
done
for f in "$out"/new/*.pfm "$out"/new/*.rtp "$out"/new/*.err; do
    [ -e "$out/old/$(basename "$f")" ] ||
        { d=$((d + 1)); echo "$(basename "$f") (new only)" >>"$out/differ.txt"; }
done
fo=$(cat "$out/old/failed.txt" 2>/dev/null)
fn=$(cat "$out/new/failed.txt" 2>/dev/null)
[ "$fo" = "$fn" ] || { d=$((d + 1)); echo "failures differ" >>"$out/differ.txt"; }
echo "same_bits: $n files compared, $d differ (list: $out/differ.txt)"
[ "$d" -eq 0 ]
