#!/bin/sh
# Replays every checked-in fuzz corpus (test/fuzz/corpus/<target>/, seeds and
# every crash ever found) through its target's replay main.  A target
# passes when it exits 0 with no crash and no sanitizer report.  The
# replay mains are built by `make test` into $BUILD/fuzz (default build).
cd "$(dirname "$0")/.." || exit 1
bin=${RTP_FUZZ_BIN:-${BUILD:-build}/fuzz}
pass=0; fail=0; skip=0
tmp=${TMPDIR:-/tmp}/rtp-fuzz-replay.$$
for dir in test/fuzz/corpus/*/; do
    target=$(basename "$dir")
    exe=$bin/$target
    if [ ! -x "$exe" ]; then
        echo "skip: $target: $exe not built" >&2
        skip=$((skip + 1)); continue
    fi
    "$exe" "$dir" >"$tmp" 2>&1
    rc=$?
    if [ "$rc" -eq 0 ] && ! grep -qE 'ERROR: (Address|Leak|Memory|Thread)Sanitizer|runtime error:|fuzz assertion' "$tmp"; then
        pass=$((pass + 1))
        echo "ok   $target: $(tail -n 1 "$tmp")"
    else
        fail=$((fail + 1))
        echo "FAIL $target (exit $rc)"
        tail -n 30 "$tmp" >&2
    fi
done
rm -f "$tmp"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
