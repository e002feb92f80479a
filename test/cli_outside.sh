#!/bin/sh
# CLI tests for the outside world: names that look like options, pipes
# whose reader leaves, and the like.
TEST_NAME=outside
. "$(dirname "$0")/common.sh"

# '--' ends the options, so a file whose name begins with '-' is named as
# itself on every command (it was "unknown option '--'", exit 2, and the
# name itself "unknown option '-s.nff'"); an option after '--' is a file.
cp scenes/spheres.nff "$T/-s.nff"
(
    cd "$T" || exit 1
    R=$RTP; case $R in /*) ;; *) R=$OLDPWD/$R;; esac
    "$R" trace --size 8x6 -o t.rtp -i a.pfm -q -- -s.nff 2>err && [ -s t.rtp ] && [ -s a.pfm ] ||
        { echo "trace -- -s.nff: $(cat err)"; exit 1; }
    cp t.rtp ./-t.rtp && cp a.pfm ./-a.pfm || exit 1
    "$R" reeval -i b.pfm -q -- -t.rtp 2>err && [ -s b.pfm ] ||
        { echo "reeval -- -t.rtp: $(cat err)"; exit 1; }
    "$R" info -- -t.rtp >out 2>err && grep -q '^-t.rtp: 8x6 image' out ||
        { echo "info -- -t.rtp: $(cat out err)"; exit 1; }
    "$R" diff -- -a.pfm b.pfm >out 2>err && grep -q '^pixels 48 ' out ||
        { echo "diff -- -a.pfm b.pfm: $(cat out err)"; exit 1; }
    "$R" merge -o m.rtp -q -- -t.rtp 2>err && cmp -s m.rtp t.rtp ||
        { echo "merge -- -t.rtp: $(cat err)"; exit 1; }
    # after '--' an option is a name: no file '-q' here
    "$R" trace -- -s.nff -q -i c.pfm >/dev/null 2>err
    [ $? -eq 2 ] && grep -q "more than one scene" err ||
        { echo "trace -- -s.nff -q: $(cat err)"; exit 1; }
) >"$T/msg" 2>&1 && ok || bad "'--': $(cat "$T/msg")"

# A scene that cannot be read says why, on stdin as by name: stdin a
# folder was "-: read error" (the name said "is a directory, not a file"),
# and a read error by name gave no reason either.
$RTP trace - -i "$T/d.pfm" -q <"$T" >/dev/null 2>"$T/err"
[ $? -eq 1 ] && grep -qi "^rtp: <stdin>: .*is a directory" "$T/err" && [ ! -e "$T/d.pfm" ] && ok ||
    bad "trace - with stdin a folder: $(cat "$T/err")"
if [ -r /proc/self/mem ]; then
    # (rtp's own /proc/self/mem: open, but a read at 0 fails, EIO)
    $RTP trace /proc/self/mem -i "$T/d.pfm" -q >/dev/null 2>"$T/err"
    rc=$?
    if grep -q "cannot open" "$T/err"; then
        echo "skip: /proc/self/mem cannot be opened here: the read error's reason unchecked" >&2
        skip=$((skip + 1))
    else
        [ $rc -eq 1 ] && grep -q "^rtp: /proc/self/mem: read error: ." "$T/err" && ok ||
            bad "trace of an unreadable file: $(cat "$T/err")"
    fi
else
    echo "skip: no /proc/self/mem: the read error's reason unchecked" >&2
    skip=$((skip + 1))
fi

# A reader that leaves (| head): rtp ends at once by SIGPIPE, as other
# tools do (a shell says 141), silently; with SIGPIPE ignored, the write's
# EPIPE is a failure: exit 1 with a message.
# (where who started the tests ignores SIGPIPE, no child can take it back)
{ yes 2>/dev/null; echo $? >"$T/rc"; } | head -c 1 >/dev/null
if [ "$(cat "$T/rc")" -eq 141 ]; then
    { $RTP trace scenes/spheres.nff --size 400x300 -i - 2>"$T/err"; echo $? >"$T/rc"; } |
        head -c 10 >/dev/null
    [ "$(cat "$T/rc")" -eq 141 ] && [ ! -s "$T/err" ] && ok ||
        bad "trace -i - | head: exit $(cat "$T/rc"): $(cat "$T/err")"
    $RTP trace scenes/spheres.nff --size 200x150 -o "$T/big.rtp" -q
    { printf 'light.0.pos=1,2,3\nlight.0.pos=2,2,3\n' |
        $RTP reeval "$T/big.rtp" --stream -i - 2>"$T/err"; echo $? >"$T/rc"; } |
        head -c 10 >/dev/null
    [ "$(cat "$T/rc")" -eq 141 ] && [ ! -s "$T/err" ] && ok ||
        bad "reeval --stream -i - | head: exit $(cat "$T/rc"): $(cat "$T/err")"
else
    echo "skip: SIGPIPE is ignored here: the exit by SIGPIPE unchecked" >&2
    skip=$((skip + 2))
fi
{ trap '' PIPE; $RTP trace scenes/spheres.nff --size 400x300 -i - 2>"$T/err"; echo $? >"$T/rc"; } |
    head -c 10 >/dev/null
[ "$(cat "$T/rc")" -eq 1 ] && grep -q "write failed: Broken pipe" "$T/err" && ok ||
    bad "trace -i - | head, SIGPIPE ignored: exit $(cat "$T/rc"): $(cat "$T/err")"

# diff over its --fail-above limit with its line to a full stdout: the
# line is lost, so exit 1 with a message, as a lost --stats or --heatmap
# gives (it was exit 3, the write's failure unsaid).
if [ -w /dev/full ]; then
    $RTP trace scenes/spheres.nff --size 8x6 -i "$T/d1.pfm" -q
    $RTP trace scenes/spheres.nff --size 8x6 -i "$T/d2.pfm" -q --set ambient=0.5,0.5,0.5
    $RTP diff "$T/d1.pfm" "$T/d2.pfm" --fail-above rmse=0 >/dev/full 2>"$T/err"
    [ $? -eq 1 ] && grep -q "stdout: write failed: No space left" "$T/err" && ok ||
        bad "diff over its limit, stdout full: $(cat "$T/err")"
    $RTP diff "$T/d1.pfm" "$T/d2.pfm" --fail-above rmse=0 >/dev/null 2>"$T/err"
    [ $? -eq 3 ] && ok || bad "diff over its limit: not exit 3: $(cat "$T/err")"
else
    echo "skip: no /dev/full: diff's lost line unchecked" >&2
    skip=$((skip + 2))
fi

# A signal that ends rtp by default, from a CPU limit (ulimit -t:
# SIGXCPU), a timer (timeout -s ALRM) or a batch system (SIGUSR1), ends it
# as SIGTERM does, leaving no temporary file: a --stream's --stats file
# is one from the start (SIGXCPU, SIGALRM, SIGUSR1, SIGUSR2 and SIGVTALRM
# had left .rtp-stats-XXXXXX).
$RTP trace scenes/spheres.nff --size 8x6 -o "$T/sg.rtp" -q
mkdir -p "$T/sig"
for sig in TERM XCPU ALRM USR1 USR2 VTALRM; do
    rm -f "$T/sig/fifo"; mkfifo "$T/sig/fifo" || { bad "mkfifo"; break; }
    sleep 5 >"$T/sig/fifo" &
    feeder=$!
    $RTP reeval "$T/sg.rtp" --stream -i "$T/sig/f%d.pfm" --stats "$T/sig/s.json" \
        <"$T/sig/fifo" 2>/dev/null &
    pid=$!
    sleep 0.3
    kill -s $sig $pid
    # (wait's stderr: dash reports the job it reaps killed, "Terminated",
    # "CPU time limit exceeded", ..., stray lines among the results)
    wait $pid 2>/dev/null
    rc=$?
    kill $feeder 2>/dev/null
    wait $feeder 2>/dev/null
    rm -f "$T/sig/fifo"
    [ $rc -gt 128 ] && [ -z "$(ls -A "$T/sig")" ] && ok ||
        bad "SIG$sig while --stream waits: exit $rc, left: $(ls -A "$T/sig")"
    rm -rf "$T/sig"; mkdir -p "$T/sig"
done

rm -rf "$T"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
