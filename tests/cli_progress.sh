#!/bin/sh
# `--progress json` at the shell (README "Progress stream"; the JSON of every line is parsed by
# tests/test_tools_progress.c): stdout holds only event lines and ends with the result line,
# stderr holds no progress lines, `--progress text` keeps them on stderr, a bad value is a usage
# error, and SIGINT in the middle of a run ends in a result line with exit 130 and no output (a
# second signal too, at once, with its own result line).
NAME=progress
. "$(dirname "$0")/lib_cli.sh"
A=$(data assets)
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
MESH="$A/fedora_hat/fedora.obj"
SMALL="--image-size 64 --steps 2 --texture-size 128 --render-size 128 --candidates 8 --views 4"

check "texture --progress json exits 0" [ "$(rc_of "$M" texture "$MESH" hat --weights "$W" -o "$T/a" $SMALL --progress json)" = 0 ]
check "every stdout line is an event object" sh -c "! grep -v '^{\"event\":\"[a-z]*\",.*}\$' '$T/out'"
check "step events" grep -q '^{"event":"step","stage":"grid","step":1,"steps":2,' "$T/out"
check "the last line is the result" sh -c "tail -n 1 '$T/out' | grep -q '^{\"event\":\"result\",\"ok\":true,\"exit\":0,\"out\":\"$T/a\",'"
check "one result line" [ "$(grep -c '"event":"result"' "$T/out")" = 1 ]
check "no progress lines on stderr" [ ! -s "$T/err" ]
check "--progress text keeps the lines on stderr" [ "$(rc_of "$M" texture "$MESH" hat --weights "$W" -o "$T/b" $SMALL --progress text)" = 0 ]
check "text: steps on stderr, nothing on stdout" sh -c "grep -q 'grid: step 2/2' '$T/err' && [ ! -s '$T/out' ]"
check "--progress xml exits 2" [ "$(rc_of "$M" texture "$MESH" hat --weights "$W" -o "$T/c" --progress xml)" = 2 ]
check "transfer --progress xml exits 2" [ "$(rc_of "$M" transfer "$T/a/mesh.obj" "$MESH" -o "$T/c" --progress xml)" = 2 ]
check "a failure: the result line carries the message" sh -c "[ \"\$('$M' texture '$MESH' hat --weights '$T/no.mxw' -o '$T/c' --progress json 2>/dev/null)\" = \
'{\"event\":\"result\",\"ok\":false,\"exit\":1,\"error\":\"$T/no.mxw: cannot open: No such file or directory\"}' ]"

# long_run NAME: a run long enough to be caught in the middle, -o $T/NAME, its stdout and stderr in
# $T/NAME.out and .err, started in the background; returns once it reports its first denoising
# step, its process in pid
long_run() {
    "$M" texture "$MESH" hat --weights "$W" -o "$T/$1" --image-size 128 --steps 50 --texture-size 512 --render-size 512 \
        --candidates 12 --progress json > "$T/$1.out" 2> "$T/$1.err" &
    pid=$!
    n=0
    while ! grep -q '"event":"step"' "$T/$1.out" 2>/dev/null && [ $n -lt 600 ]; do sleep 0.05; n=$((n + 1)); done
}

# SIGINT once the first denoising step is reported
long_run int
kill -INT $pid
wait $pid
rc=$?
check "SIGINT exits 130" [ $rc = 130 ]
check "SIGINT: the result line says interrupted" sh -c "tail -n 1 '$T/int.out' | grep -q '^{\"event\":\"result\",\"ok\":false,\"exit\":130,\"error\":\"interrupted\"}\$'"
check "SIGINT: no output folder, no staging folder" sh -c "! ls -d '$T'/int* 2>/dev/null | grep -v '\\.out\$\\|\\.err\$'"

# a second signal ends the run at once with its own result line
long_run twice
signal_twice $pid
rc=$?
check "a second signal exits 130" [ $rc = 130 ]
check "... the last line is its result line" sh -c "tail -n 1 '$T/twice.out' | grep -qx '{\"event\":\"result\",\"ok\":false,\"exit\":130,\"error\":\"interrupted again, stopped now; nothing written\"}'"
check "... one result line, every line an event" sh -c "[ \$(grep -c '\"event\":\"result\"' '$T/twice.out') = 1 ] && ! grep -v '^{\"event\":\"[a-z]*\",.*}\$' '$T/twice.out'"
check "... one line on stderr" [ "$(wc -l < "$T/twice.err")" = 1 ]
check "... no output folder, no staging folder" sh -c "! ls -d '$T'/twice* 2>/dev/null | grep -v '\\.out\$\\|\\.err\$'"
exit $fail
