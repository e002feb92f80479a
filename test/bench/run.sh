#!/bin/sh
# make bench: kd-tree build and ray rates and the other bench_* programs,
# SPD full traces at 1 and 2 threads with SPD's ray counts, then the
# error-against-run-time matrix (test/bench/matrix.sh) and its report
# (build/bench/report: test/bench/out/report.md and test/bench/out/errspeed.svg).
# A benchmark, not a test: it reports.
dir=${1:-build/bench}
RTP=${RTP:-./rtp}
out=test/bench/out
mkdir -p "$out"
t0=$(date +%s)

# the compile command make uses for the library, for the header
build=$(dirname "$dir")
src=""
for f in lib/*.c; do [ -f "$f" ] && src=$f && break; done
cmd=""
[ -n "$src" ] && cmd=$(make -n -B V=1 BUILD="$build" "$build/${src%.c}.o" 2>/dev/null |
    grep -e " -c $src" | head -n 1)
cc_used=${cmd%% *}
[ -n "$cc_used" ] || cc_used=${CC:-cc}
flags=${cmd#* }
flags=$(echo "${flags% -c "$src"*}" | sed "s/ *$//")
[ -n "$cmd" ] || flags="(unknown: make -n gave no compile command)"
BENCH_MACHINE="$(uname -srm), $(nproc 2>/dev/null || echo '?') cores, $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: //')"
BENCH_COMPILER="$cc_used: $($cc_used --version 2>/dev/null | head -n 1)"
BENCH_FLAGS=$flags
export BENCH_MACHINE BENCH_COMPILER BENCH_FLAGS

echo "# rtp benchmark"
echo "machine: $BENCH_MACHINE"
echo "compiler: $BENCH_COMPILER"
echo "flags: $BENCH_FLAGS"
echo
for b in "$dir"/bench_*; do
    [ -x "$b" ] && "$b"
done
shared=""
for d in ../shared/scenes ../../shared/scenes; do [ -d "$d/spd" ] && shared=$d && break; done
if [ -z "$shared" ]; then
    echo "skip: ../shared/scenes absent: no SPD timings"
else
    echo
    echo "## SPD scenes, --spd (512x512 from 513x513 corner rays), full trace"
    echo
    echo "| scene | prims | 1 thread s | 2 threads s | eye rays | eye hits | shadow | reflected | refracted | kd build s |"
    echo "|---|---|---|---|---|---|---|---|---|---|"
    get() { echo "$1" | sed -nE "s/.*\"$2\": ([0-9.e+-]+).*/\1/p"; }
    for sc in balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11 lattice_s12; do
        f="$shared/spd/$sc.nff"
        [ -f "$f" ] || continue
        "$RTP" trace "$f" --spd -j 1 -i "$out/$sc.png" --stats "$out/$sc.1.json" -q || continue
        "$RTP" trace "$f" --spd -j 2 -i "$out/$sc.png" --stats "$out/$sc.2.json" -q || continue
        j1=$(cat "$out/$sc.1.json"); j2=$(cat "$out/$sc.2.json")
        prims=$(grep -cE '^(s|c|p|pp) ' "$f")
        printf '| %s | %s | %.3f | %.3f | %s | %s | %s | %s | %s | %.3f |\n' "$sc" "$prims" \
            "$(get "$j1" seconds)" "$(get "$j2" seconds)" "$(get "$j1" eye_rays)" \
            "$(get "$j1" eye_hits)" "$(get "$j1" shadow_rays)" "$(get "$j1" reflected_rays)" \
            "$(get "$j1" refracted_rays)" "$(get "$j1" build_seconds)"
    done
fi

# error against run time: the matrix, then the report (also on stdout)
echo
echo "(error against run time: running test/bench/matrix.sh, a few minutes)" >&2
if RTP=$RTP OUT=$out sh test/bench/matrix.sh && [ -x "$dir/report" ] &&
        "$dir/report" "$out/matrix.tsv" "$out"; then
    cat "$out/report.md"
    echo
    echo "report: $out/report.md, plot: $out/errspeed.svg"
else
    echo "error against run time: the matrix or its report failed (see above)"
fi
echo
echo "make bench: $(( $(date +%s) - t0 )) s wall in total"
