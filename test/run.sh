#!/bin/sh
# Runs every test program in $1 and every test/*.sh script, sums their
# "N passed, N failed[, N skipped]" lines, and ends with the total.
# Each runs with a TMPDIR of its own, removed after it whatever happened
# (a test that returned early on a failure had left its files in /tmp);
# a run that passes and leaves anything there fails.
dir=${1:-build/test}
pass=0; fail=0; skip=0
base=${TMPDIR:-/tmp}
tmp=$base/rtp-test.$$
work=
trap 'rm -f "$tmp" "$tmp.err"; [ -n "$work" ] && rm -rf "$work"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
for t in "$dir"/test_* test/cli_*.sh; do
    [ -e "$t" ] || continue
    case "$t" in *.sh) cmd="sh $t";; *) cmd="$t";; esac
    work=$base/rtp-test.$$.$(basename "$t")
    rm -rf "$work"
    if ! mkdir -m 700 "$work"; then
        echo "FAIL $t: no folder $work for its TMPDIR"
        fail=$((fail + 1)); work=; continue
    fi
    TMPDIR=$work $cmd >"$tmp" 2>"$tmp.err"
    rc=$?
    left=$(ls -A "$work" | head -n 5 | tr '\n' ' ')
    rm -rf "$work"; work=
    line=$(grep -E '^[0-9]+ passed, [0-9]+ failed' "$tmp" | tail -n 1)
    if [ -z "$line" ]; then
        echo "FAIL $t: no result line (exit $rc)"
        cat "$tmp.err" | tail -n 20
        fail=$((fail + 1)); continue
    fi
    p=$(echo "$line" | sed -E 's/^([0-9]+) passed.*/\1/')
    f=$(echo "$line" | sed -E 's/^[0-9]+ passed, ([0-9]+) failed.*/\1/')
    s=$(echo "$line" | sed -nE 's/.*, ([0-9]+) skipped.*/\1/p')
    s=${s:-0}
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then f=1; fi
    if [ -n "$left" ] && [ "$f" -eq 0 ]; then
        echo "FAIL $t: passed, and left in TMPDIR: $left" >>"$tmp.err"
        f=1
    fi
    # A script prints its results and skip: lines only: anything else on
    # its stderr is a command it did not quiet (dash's "Terminated" for a
    # job a test killed, from `wait`, had been a stray line in the output
    # of a run that passed).  The C tests print what they measured there.
    case "$t" in *.sh)
        stray=$(grep -v '^skip:' "$tmp.err" | head -n 3)
        if [ -n "$stray" ] && [ "$f" -eq 0 ]; then
            echo "FAIL $t: passed, and wrote on stderr: $stray" >>"$tmp.err"
            f=1
        fi;;
    esac
    pass=$((pass + p)); fail=$((fail + f)); skip=$((skip + s))
    printf '%-32s %s\n' "$(basename "$t")" "$line"
    if [ "$f" -ne 0 ]; then tail -n 30 "$tmp.err"; fi
    grep '^skip:' "$tmp.err" | sed 's/^/    /'
done
rm -f "$tmp" "$tmp.err"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
