#!/bin/sh
# make instr: instructions each edit class executes (one thread, callgrind)
# on the default SPD scenes, 512x512 from SPD's corner samples; with
# RTP_INSTR_1024=1 at 1024x1024 pixel centres as well; with
# RTP_INSTR_TRACE=1 a full trace's count too (minutes more), and each
# edit's as that count over its own (the moves' counts then differ by
# about 1% from a run without: the trace leaves state behind, such as the
# kd-tree it built).  Deterministic where
# wall-clock time on a shared machine is not: compare a change's counts
# with the counts before it.  Needs valgrind; prints a table and writes it
# to build/instr/instr.md.  With RTP_INSTR_KEEP=1 the callgrind dumps
# (BIN_DIR/cg.SCENE-SIZE.*, one a label) and the trees stay, for
# callgrind_annotate's per-function counts.  Between two builds: run it in
# each checkout, and test/bench/same_bits.sh for their outputs' bytes.
#   run.sh BIN_DIR [SCENE...]
dir=${1:-build/instr}
shift
RTP=${RTP:-./rtp}
shared=""
for d in ../shared ../../shared; do [ -d "$d/scenes/spd" ] && shared=$d && break; done
if ! command -v valgrind >/dev/null 2>&1; then
    echo "make instr: valgrind is not installed (apt-get install valgrind)"
    exit 1
fi
if [ -z "$shared" ]; then
    echo "make instr: ../shared/scenes absent: nothing to measure"
    exit 0
fi
scenes=${*:-balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11}
sizes=512
[ -n "$RTP_INSTR_1024" ] && sizes="512 1024"
out=$dir/instr.md
trace=""
[ -n "$RTP_INSTR_TRACE" ] && trace=trace
labels="full_trace first_eval light_colour_1st light_colour ambient material_kd_1st material_kd move_exact move_lightbuf256 move_itembuf256 move_auto"
{
    echo "## Instructions per evaluation (callgrind, 1 thread; millions)"
    echo
    echo "The edits of bench_reeval, in its order, on one kept image: 1st is the first edit of a term (it makes the planes, but a one- or two-light scene's first evaluation made its lights'), the others the third; the material is the second (the first where the scene has one); moves are light 0's, the third of three (a drag going on; before session 11 the second of two). With RTP_INSTR_TRACE=1: a full trace of the scene (kd-tree build included), and each edit's count as a fraction of it."
    echo
    echo "| scene | size | full trace | first eval | light colour 1st | light colour | ambient | material kd 1st | material kd | move exact | lightbuf:256 | itembuf:256 | auto (default) |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
} >"$out"
cat "$out"
for size in $sizes; do
    for name in $scenes; do
        nff=$shared/scenes/spd/$name.nff
        [ -f "$nff" ] || { echo "make instr: $nff absent: skipped" >&2; continue; }
        tree=$dir/$name-$size.rtp
        if [ "$size" = 512 ]; then
            "$RTP" trace "$nff" --spd -o "$tree" -i "$dir/$name-$size.pfm" -q || continue
        else
            "$RTP" trace "$nff" --size 1024x1024 -o "$tree" -i "$dir/$name-$size.pfm" -q || continue
        fi
        # the second material, as bench_reeval takes (the first is often
        # a background's)
        nm=$("$RTP" info "$tree" | sed -nE 's/.* ([0-9]+) materials.*/\1/p')
        mat=0
        [ "${nm:-1}" -gt 1 ] && mat=1
        rm -f "$dir"/cg."$name"-"$size".*
        valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \
            --callgrind-out-file="$dir/cg.$name-$size.%p" \
            "$dir/instr" "$tree" "$mat" $trace >/dev/null 2>"$dir/cg.$name-$size.log" || {
            echo "make instr: $name at $size failed (see $dir/cg.$name-$size.log)" >&2
            continue
        }
        row="| $name | $size |"
        full=""
        for l in $labels; do
            f=$(grep -l "^desc: Trigger: Client Request: $l\$" "$dir"/cg."$name"-"$size".* 2>/dev/null |
                head -n 1)
            # (totals: the dump's own count; summary runs on across dumps)
            n=$([ -n "$f" ] && sed -nE 's/^totals: ([0-9]+).*/\1/p' "$f" | head -n 1)
            if [ "$l" = full_trace ]; then
                full=$n
                if [ -n "$n" ]; then
                    row="$row $(awk -v n="$n" 'BEGIN { printf "%.1f", n / 1e6 }') |"
                else
                    row="$row — |"
                fi
            elif [ -n "$n" ] && [ -n "$full" ]; then
                row="$row $(awk -v n="$n" -v f="$full" 'BEGIN { printf "%.2f (%.0fx)", n / 1e6, f / n }') |"
            elif [ -n "$n" ]; then
                row="$row $(awk -v n="$n" 'BEGIN { printf "%.2f", n / 1e6 }') |"
            else
                row="$row ? |"
            fi
        done
        echo "$row" | tee -a "$out"
        [ -n "${RTP_INSTR_KEEP:-}" ] ||
            rm -f "$dir"/cg."$name"-"$size".* "$tree" "$dir/$name-$size.pfm"
    done
done
