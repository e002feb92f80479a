#!/bin/sh
# test/bench/matrix.sh — the error-against-run-time matrix: scenes x edit classes
# x shadow modes x direction-cube resolutions, measured through the CLI's
# --stats JSON.  Writes test/bench/out/matrix.tsv (one record a line, tab
# separated: kind, scene, edit, method, JSON) for build/bench/report.
#
# Per scene:
#   1. rtp trace -o TREE (the tree file; its size and bytes per node).
#   2. One `rtp reeval --stream --shadows exact --reference` over an edit
#      sequence: an empty first line (the first evaluation builds the
#      caches), then light colour twice, light off, light on, ambient
#      twice, material colour twice, material kd, shine three times, and a moved
#      light.  Edits persist, so each line is timed on warm caches, and each
#      line's --reference traces the same edited scene in full at the same
#      thread count.  The first edit of a term (a light's colour, the
#      ambient, a material's colour) makes the plane(s) the further edits
#      of that term reuse, and the second of consecutive shine edits
#      lists the highlights the further ones reuse: all are shown apart.
#   3. The same sequence again without --reference for every other shadow
#      mode (lightbuf:RES, itembuf:RES, osmesa:RES when rtp has OSMesa, and
#      auto, the CLI's default, at its own resolution): the
#      state before the moved light is identical, so the moved-light image is
#      compared (rtp diff) with the exact run's, which step 2 compared with a
#      full trace; the speed-up uses step 2's reference time for that line.
#
# Environment: RTP (./rtp), OUT (test/bench/out), J (threads, 2), RESES (cube
# resolutions, "256 512 1024 2048"), SCENES (names, overriding the default
# list), KEEP=1 keeps the trees and images.
RTP=${RTP:-./rtp}
out=${OUT:-test/bench/out}
J=${J:-2}
RESES=${RESES:-"256 512 1024 2048"}
work=$out/matrix
tsv=$out/matrix.tsv
rm -rf "$work"
mkdir -p "$work" || exit 1
: > "$tsv" || exit 1
t_start=$(date +%s)
# run a private copy: colleagues relinking ./rtp mid-run cannot break it
i=0
until cp "$RTP" "$work/rtp" 2>/dev/null && "$work/rtp" version >/dev/null 2>&1; do
    i=$((i + 1))
    [ $i -lt 10 ] || { echo "matrix: cannot copy $RTP" >&2; exit 1; }
    sleep 1
done
RTP=$work/rtp

to=""
command -v timeout >/dev/null 2>&1 && to="timeout 600"

meta() { printf 'meta\t%s\t%s\n' "$1" "$2" >> "$tsv"; }
note() { printf 'note\t%s\t%s\n' "$1" "$2" >> "$tsv"; echo "matrix: $1: $2" >&2; }
# record KIND SCENE EDIT METHOD JSONLINE
record() { printf '%s\t%s\t%s\t%s\t%s\n' "$1" "$2" "$3" "$4" "$5" >> "$tsv"; }

# ------------------------------------------------------------- the scenes
shared=""
for d in ../shared/scenes ../../shared/scenes; do [ -d "$d/spd" ] && shared=$d && break; done
list=""
if [ -n "$shared" ]; then
    for sc in ${SCENES:-balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11}; do
        [ -f "$shared/spd/$sc.nff" ] && list="$list $shared/spd/$sc.nff"
    done
    flags="--spd"
    meta scenes "SPD scenes from $shared/spd, --spd (512x512 from 513x513 corner rays, depth 5)"
else
    if [ -n "${SCENES:-}" ]; then
        for sc in $SCENES; do list="$list scenes/$sc.nff"; done
    else
        list=$(ls scenes/*.nff)
    fi
    flags="--size 256x256"
    meta scenes "the project's own scenes/*.nff at 256x256 (../shared/scenes/spd is absent)"
fi

[ -n "${BENCH_MACHINE:-}" ] || BENCH_MACHINE="$(uname -srm), $(nproc 2>/dev/null || echo '?') cores, $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: //')"
[ -n "${BENCH_COMPILER:-}" ] || BENCH_COMPILER=$(${CC:-cc} --version 2>/dev/null | head -n 1)
meta machine "$BENCH_MACHINE"
meta compiler "$BENCH_COMPILER"
[ -n "${BENCH_FLAGS:-}" ] && meta flags "$BENCH_FLAGS"
meta rtp "$($RTP version 2>/dev/null | head -n 1)"
meta threads "$J"
meta date "$(date -u '+%Y-%m-%d %H:%M UTC')"

# --------------------------------------------------------------- helpers
# the first `l X Y Z` of an NFF file, and a position moved from it by a
# tenth of its distance from the origin (sideways in x and y)
light0() { awk '$1 == "l" && NF >= 4 { print $2, $3, $4; exit }' "$1"; }
moved() {
    echo "$1" | awk '{ d = 0.1 * sqrt($1 * $1 + $2 * $2 + $3 * $3); if (d == 0) d = 0.5;
        printf "%.6g,%.6g,%.6g\n", $1 + 0.6 * d, $2 - 0.8 * d, $3 }'
}
# material indices: 0 for the colour/kd edits; the first with Ks > 0 for
# shine (its highlight is then visible), else 0
shiny() { awk 'BEGIN { n = 0 } $1 == "f" { if ($6 + 0 > 0) { print n; found = 1; exit } n++ }
               END { if (!found) print 0 }' "$1"; }

# stream RUN-NAME TREE SHADOWS [--reference]: runs the edit sequence,
# leaves RUN-NAME.jsonl and images RUN-NAME.N.pfm; returns rtp's status
stream() {
    st_name=$1 st_tree=$2 st_mode=$3
    shift 3
    $to "$RTP" reeval "$st_tree" --stream -j "$J" --shadows "$st_mode" "$@" -q \
        -i "$st_name.%d.pfm" --stats "$st_name.jsonl" < "$work/edits.txt" 2> "$st_name.err"
}

# pair the edit labels with the JSON lines of one run
records() {   # records SCENE METHOD JSONL
    n=0
    while IFS= read -r label; do
        n=$((n + 1))
        j=$(sed -n "${n}p" "$3" 2>/dev/null)
        [ -n "$j" ] || j="n/a"
        record reeval "$1" "$label" "$2" "$j"
    done < "$work/labels.txt"
}

osmesa=""     # decided on the first scene

# ---------------------------------------------------------------- the runs
for f in $list; do
    sc=$(basename "$f" .nff)
    tree=$work/$sc.rtp
    echo "matrix: $sc" >&2
    # shellcheck disable=SC2086
    if ! $to "$RTP" trace "$f" $flags -j "$J" -o "$tree" -i "$work/$sc.trace.ppm" \
            --stats "$work/$sc.trace.json" -q 2> "$work/$sc.trace.err"; then
        note "$sc" "trace failed: $(tail -n 1 "$work/$sc.trace.err")"
        continue
    fi
    record trace "$sc" "full trace" "trace" "$(cat "$work/$sc.trace.json")"

    # the edit sequence (edits.txt) and its labels (labels.txt), line by line
    l0=$(light0 "$f")
    s=$(shiny "$f")
    {
        echo
        if [ -n "$l0" ]; then
            echo "light.0.color=1,0.8,0.6"
            echo "light.0.color=0.6,0.8,1"
            echo "light.0.on=0"
            echo "light.0.on=1"
        fi
        echo "ambient=0.2,0.2,0.25"
        echo "ambient=0.1,0.1,0.15"
        echo "mat.0.color=0.3,0.6,0.9"
        echo "mat.0.color=0.9,0.6,0.3"
        echo "mat.0.kd=0.5"
        echo "mat.$s.shine=20"
        echo "mat.$s.shine=60"
        echo "mat.$s.shine=40"
        [ -n "$l0" ] && echo "light.0.pos=$(moved "$l0")"
    } > "$work/edits.txt"
    {
        echo "first evaluation (builds caches)"
        if [ -n "$l0" ]; then
            echo "light colour (first: builds its planes)"
            echo "light colour"
            echo "light off"
            echo "light on"
        fi
        echo "ambient (first: builds its planes)"
        echo "ambient"
        echo "material colour (first: builds its planes)"
        echo "material colour"
        echo "material kd"
        echo "shine (first)"
        echo "shine (second: lists the highlights)"
        echo "shine"
        [ -n "$l0" ] && echo "moved light"
    } > "$work/labels.txt"
    nlines=$(wc -l < "$work/labels.txt" | tr -d ' ')
    last=$((nlines - 1))     # the moved light's image index (%d counts from 0)

    ex=$work/$sc.exact
    if ! stream "$ex" "$tree" exact --reference; then
        note "$sc" "exact stream failed: $(tail -n 1 "$ex.err")"
    fi
    records "$sc" exact "$ex.jsonl"
    [ -n "$l0" ] || { note "$sc" "no light: no moved-light runs"; continue; }

    if [ -z "$osmesa" ]; then
        if "$RTP" reeval "$tree" --shadows osmesa:64 --set "light.0.pos=$(moved "$l0")" \
                -i "$work/probe.pfm" -q 2> "$work/probe.err"; then
            osmesa=yes
        else
            osmesa=no
            note all "osmesa skipped: $(tail -n 1 "$work/probe.err")"
        fi
        rm -f "$work/probe.pfm"
    fi
    modes=""
    for m in lightbuf itembuf; do
        for r in $RESES; do modes="$modes $m:$r"; done
    done
    if [ "$osmesa" = yes ]; then
        for r in $RESES; do modes="$modes osmesa:$r"; done
    fi
    modes="$modes auto" # the CLI's default: its own method and resolution
    for m in $modes; do
        run=$work/$sc.$(echo "$m" | tr ':' '_')
        if ! stream "$run" "$tree" "$m"; then
            note "$sc" "$m failed: $(tail -n 1 "$run.err")"
        fi
        # only the moved-light line differs from the exact run: record it
        j=$(sed -n "${nlines}p" "$run.jsonl" 2>/dev/null)
        [ -n "$j" ] || j="n/a"
        record reeval "$sc" "moved light" "$m" "$j"
        if [ -f "$run.$last.pfm" ] && [ -f "$ex.$last.pfm" ]; then
            d=$("$RTP" diff "$run.$last.pfm" "$ex.$last.pfm" --threshold 0.00392156863 \
                --stats - -q 2>/dev/null | head -n 1)
            [ -n "$d" ] && record diff "$sc" "moved light" "$m" "$d"
        fi
        [ -n "${KEEP:-}" ] || rm -f "$run".*.pfm
    done
    [ -n "${KEEP:-}" ] || rm -f "$ex".*.pfm "$tree" "$work/$sc.trace.ppm"
done
meta matrix_seconds "$(( $(date +%s) - t_start ))"
echo "matrix: $(wc -l < "$tsv" | tr -d ' ') records in $tsv, $(( $(date +%s) - t_start )) s" >&2
