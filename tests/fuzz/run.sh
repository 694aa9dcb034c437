#!/bin/sh
# `make fuzz`: runs each harness SECONDS seconds under libFuzzer, starting from its seeds and
# regression inputs; the growing corpus stays in BUILD/fuzz-corpus/<H>. JOBS harnesses run at
# a time (FUZZ_JOBS, default 2: the whole set in about 5 x SECONDS on 2 cores). Prints one line
# per harness (executions, coverage) and exits non-zero if any crashed, naming the input to copy
# into tests/fuzz/regress/<H>/ once the bug is fixed. The harnesses' own stdout/stderr are closed
# (error messages of rejected inputs); libFuzzer and sanitizer reports still reach the log.
# With FUZZ_CI=1 (`make fuzz-ci`, what CI runs) a run is reproducible instead: a fixed seed, a
# fixed number of executions per harness (ci_runs: about 20 s each on a 2-core machine) and a
# fresh corpus (BUILD/fuzz-corpus-ci), so CI explores exactly the inputs a local `make fuzz-ci`
# explored, and a crash it reports is reproduced by running it again.
# usage: sh tests/fuzz/run.sh BUILD SECONDS HARNESS...
set -u
# OIIO's worker threads only add waiting to a one-image-at-a-time harness.
export OPENIMAGEIO_OPTIONS="${OPENIMAGEIO_OPTIONS:-threads=1}"
build=$1
secs=$2
shift 2
jobs=${FUZZ_JOBS:-2}

# ci_runs H: the executions of harness H under FUZZ_CI (measured rates x ~20 s)
ci_runs() {
    case $1 in
    cli) echo 1000000 ;;
    tokenizer) echo 500000 ;;
    json) echo 120000 ;;
    safetensors) echo 30000 ;;
    gltf | image | obj | weightfile) echo 20000 ;;
    meshio) echo 8000 ;;
    meshpath | ckpt) echo 1500 ;;
    *) echo 10000 ;;
    esac
}

# fuzz_one H: runs harness H, writes its summary line(s) to BUILD/fuzz-logs/H.summary and
# creates BUILD/fuzz-logs/H.failed if it crashed
fuzz_one() {
    h=$1
    corpus=$build/fuzz-corpus/$h
    limit="-max_total_time=$secs"
    if [ "${FUZZ_CI:-0}" = 1 ]; then
        corpus=$build/fuzz-corpus-ci/$h
        rm -rf "$corpus"
        limit="-seed=1 -runs=$(ci_runs "$h") -max_total_time=600"
    fi
    crashes=$build/fuzz-crashes/$h
    log=$build/fuzz-logs/$h.log
    summary=$build/fuzz-logs/$h.summary
    rm -f "$build/fuzz-logs/$h.failed"
    mkdir -p "$corpus" "$crashes"
    regress=tests/fuzz/regress/$h
    [ -d "$regress" ] || regress=
    "$build/tests/fuzz/fuzz_$h" $limit -rss_limit_mb=2048 -malloc_limit_mb=2048 \
        -timeout=30 -close_fd_mask=3 -print_final_stats=1 -artifact_prefix="$crashes/" \
        "$corpus" "tests/fuzz/seeds/$h" $regress > "$log" 2>&1
    rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -n 1)
    if [ $rc -eq 0 ]; then
        echo "fuzz $h: ok, ${execs:-?} executions, $cov" > "$summary"
    else
        touch "$build/fuzz-logs/$h.failed"
        {
            echo "fuzz $h: CRASH after ${execs:-?} executions (exit $rc); input: $(ls -t "$crashes" | head -n 1)"
            grep -m 1 -A 12 'ERROR:\|runtime error\|deadly signal' "$log" | sed 's/^/    /'
            echo "    full log: $log; once fixed, copy the input into tests/fuzz/regress/$h/"
        } > "$summary"
    fi
}

mkdir -p "$build/fuzz-logs"
i=0
for h in "$@"; do
    fuzz_one "$h" &
    i=$((i + 1))
    [ $((i % jobs)) -eq 0 ] && wait
done
wait
failed=""
for h in "$@"; do
    cat "$build/fuzz-logs/$h.summary"
    [ -e "$build/fuzz-logs/$h.failed" ] && failed="$failed $h"
done
[ -z "$failed" ] || { echo "fuzz: crashes in:$failed"; exit 1; }
exit 0
