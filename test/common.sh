# The start every test/cli_*.sh script shares, sourced with TEST_NAME set
# (they run from the repository's root): RTP, the binary under test; T, a
# scratch folder removed however the run ends (a run cut short by Ctrl-C
# or a CI timeout leaves nothing behind either); the counts with ok and
# bad; expect_rc.  Each script ends by printing the counts it kept.
RTP=${RTP:-./rtp}
T=${TMPDIR:-/tmp}/rtp-$TEST_NAME.$$
pass=0; fail=0; skip=0
mkdir -p "$T"
trap 'rm -rf "$T"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
ok()  { pass=$((pass + 1)); }
bad() { fail=$((fail + 1)); echo "FAIL: $*" >&2; }
# expect_rc WANT CMD...: CMD exits with WANT (its stdout in $T/out, its
# stderr in $T/err, shown when it does not)
expect_rc() {
    want=$1; shift
    "$@" >"$T/out" 2>"$T/err"; rc=$?
    if [ "$rc" -eq "$want" ]; then ok; else bad "exit $rc (want $want): $*"; cat "$T/err" >&2; fi
}
# need_python WHAT: without python3 (3.6 or later) the script is one skip,
# saying WHAT was not run
need_python() {
    if ! python3 -c 'import sys; sys.exit(sys.version_info < (3, 6))' 2>/dev/null; then
        echo "skip: no python3 (3.6 or later): $1 not run" >&2
        echo "0 passed, 0 failed, 1 skipped"
        exit 0
    fi
}
