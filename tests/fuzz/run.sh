#!/bin/sh
# `make fuzz`: runs each harness SECONDS seconds under libFuzzer, starting from its seeds and
# regression inputs; the growing corpus stays in BUILD/fuzz-corpus/<H>. Prints one line per
# harness (executions, coverage) and exits non-zero if any crashed, naming the input to copy
# into tests/fuzz/regress/<H>/ once the bug is fixed. The harnesses' own stdout/stderr are closed
# (error messages of rejected inputs); libFuzzer and sanitizer reports still reach the log.
# usage: sh tests/fuzz/run.sh BUILD SECONDS HARNESS...
set -u
# OIIO's worker threads only add waiting to a one-image-at-a-time harness.
export OPENIMAGEIO_OPTIONS="${OPENIMAGEIO_OPTIONS:-threads=1}"
build=$1
secs=$2
shift 2
failed=""
for h in "$@"; do
    corpus=$build/fuzz-corpus/$h
    crashes=$build/fuzz-crashes/$h
    log=$build/fuzz-logs/$h.log
    mkdir -p "$corpus" "$crashes" "$(dirname "$log")"
    regress=tests/fuzz/regress/$h
    [ -d "$regress" ] || regress=
    "$build/tests/fuzz/fuzz_$h" -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=2048 \
        -timeout=30 -close_fd_mask=3 -print_final_stats=1 -artifact_prefix="$crashes/" \
        "$corpus" "tests/fuzz/seeds/$h" $regress > "$log" 2>&1
    rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -n 1)
    if [ $rc -eq 0 ]; then
        echo "fuzz $h: ok, ${execs:-?} executions in ${secs}s, $cov"
    else
        failed="$failed $h"
        echo "fuzz $h: CRASH after ${execs:-?} executions (exit $rc); input: $(ls -t "$crashes" | head -n 1)"
        grep -m 1 -A 12 'ERROR:\|runtime error\|deadly signal' "$log" | sed 's/^/    /'
        echo "    full log: $log; once fixed, copy the input into tests/fuzz/regress/$h/"
    fi
done
[ -z "$failed" ] || { echo "fuzz: crashes in:$failed"; exit 1; }
