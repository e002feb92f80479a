#!/bin/sh
# make bench: kd-tree build and ray rates, then SPD full traces at 1 and 2
# threads with SPD's ray counts.  A benchmark, not a test: it reports.
dir=${1:-build/bench}
RTP=${RTP:-./rtp}
out=bench/out
mkdir -p "$out"
echo "# rtp benchmark"
echo "machine: $(uname -srm), $(nproc 2>/dev/null || echo '?') cores, $(grep -m1 'model name' /proc/cpuinfo 2>/dev/null | sed 's/.*: //')"
echo "compiler: $(${CC:-cc} --version | head -n 1)"
echo
for b in "$dir"/bench_*; do
    [ -x "$b" ] && "$b"
done
shared=""
for d in ../shared/scenes ../../shared/scenes; do [ -d "$d/spd" ] && shared=$d && break; done
if [ -z "$shared" ]; then
    echo "skip: ../shared/scenes absent: no SPD timings"
    exit 0
fi
echo
echo "## SPD scenes, --spd (512x512 from 513x513 corner rays), full trace"
echo
echo "| scene | prims | 1 thread s | 2 threads s | eye rays | eye hits | shadow | reflected | refracted | kd build s |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for sc in balls_s4 gears_s4 mount_s6 rings_s7 teapot_s12 tetra_s6 tree_s11 lattice_s12; do
    f="$shared/spd/$sc.nff"
    [ -f "$f" ] || continue
    "$RTP" trace "$f" --spd -j 1 -i "$out/$sc.png" --stats "$out/$sc.1.json" -q || continue
    "$RTP" trace "$f" --spd -j 2 -i "$out/$sc.png" --stats "$out/$sc.2.json" -q || continue
    j1=$(cat "$out/$sc.1.json"); j2=$(cat "$out/$sc.2.json")
    get() { echo "$1" | sed -nE "s/.*\"$2\": ([0-9.e+-]+).*/\1/p"; }
    prims=$(grep -cE '^(s|c|p|pp) ' "$f")
    printf '| %s | %s | %.3f | %.3f | %s | %s | %s | %s | %s | %.3f |\n' "$sc" "$prims" \
        "$(get "$j1" seconds)" "$(get "$j2" seconds)" "$(get "$j1" eye_rays)" \
        "$(get "$j1" eye_hits)" "$(get "$j1" shadow_rays)" "$(get "$j1" reflected_rays)" \
        "$(get "$j1" refracted_rays)" "$(get "$j1" build_seconds)"
done
