#!/bin/sh
# A short fixed-seed run of test/fuzz_streams.py: random --stream lines
# mixing every edit class (optical, moved and added lights, bumps with
# --stale retrace, ks/kt from 0 and ior, camera, edits back to the traced
# values), each frame against `rtp trace` of the scene with the edits so far,
# some against a one-off `reeval`, -j1 against -j2, and the --stats lines
# (stale_samples, moved_lights, shadows, written_pixels, --reference's
# max_abs) against what happened.  Longer campaigns:
# python3 test/fuzz_streams.py --minutes 20 --seed N.  Skipped without python3.
TEST_NAME=fzs
. "$(dirname "$0")/common.sh"
export RTP
trap 'rm -rf "$T" "$T.log"' EXIT
need_python "random edit streams"
# (then four SPD cases of fuzz_scenes/backfaces_spd.nff: surfaces seen from
# behind given kt from 0, whose re-traced hits had kept their light bits)
if python3 test/fuzz_streams.py --cases 16 --seed 1 --out "$T" >"$T.log" 2>&1 &&
    python3 test/fuzz_streams.py --cases 4 --seed 2 --spd 1 --out "$T" \
        --scene test/fuzz_scenes/backfaces_spd.nff >>"$T.log" 2>&1; then
    n=$(sed -n 's/^frames compared \([0-9]*\) .*/\1/p' "$T.log" | awk '{ s += $1 } END { print s + 0 }')
    echo "${n:-0} passed, 0 failed, 0 skipped"
else
    cat "$T.log" >&2
    rm -f "$T.log"
    echo "0 passed, 1 failed, 0 skipped"
    exit 1
fi
rm -f "$T.log"
