#!/bin/sh
# Runs every test program and script given, prints one line per test and the closing
# "N passed, N failed, N skipped" line; exits non-zero if any failed. A test that exits 77 did
# not run (e.g. the SD1.5-size cases outside `make test-full`) and counts as skipped. A test that
# passes may have skipped cases whose data is outside the repository ("SKIP REL: ..." lines, see
# tests/util_test.h): they are counted and the first few shown.
# MATEX_TEST_JOBS (default 1; the Makefile passes 2) tests run at once: most of them keep one
# core busy, and each writes only into its own temporary folder. A test starts as soon as any
# running one ends; results are reported in the order given, each once it and every test before
# it have ended.
jobs=${MATEX_TEST_JOBS:-1}
pass=0
fail=0
skip=0
cases_skipped=0
failed=""
queue="" # "pid:path" of the tests started and not yet reported, oldest first

# Runs test $1 into $1.log.tmp, then writes "exit-code seconds" to $1.rc.tmp (renamed into
# place, so the file's presence says the test has ended).
run_one() {
    start=$(date +%s)
    case "$1" in
    *.sh) sh "$1" > "$1.log.tmp" 2>&1 ;;
    *) "$1" > "$1.log.tmp" 2>&1 ;;
    esac
    echo "$? $(( $(date +%s) - start ))" > "$1.rc.part"
    mv "$1.rc.part" "$1.rc.tmp"
}

# The number of started tests that have not ended.
running() {
    n=0
    for e in $queue; do [ -e "${e#*:}.rc.tmp" ] || n=$((n + 1)); done
    echo $n
}

# Waits for the oldest running test and reports it.
report_oldest() {
    entry=${queue%% *}
    queue=${queue#"$entry"}
    queue=${queue# }
    rt=${entry#*:} # not t: the main loop's
    wait "${entry%%:*}"
    rc=1 secs=0 # a test killed before writing its exit code failed
    [ -s "$rt.rc.tmp" ] && read -r rc secs < "$rt.rc.tmp"
    if [ "$rc" -eq 77 ]; then
        skip=$((skip + 1))
        echo "SKIP $(basename "$rt") ($(tail -n 1 "$rt.log.tmp"))"
    elif [ "$rc" -eq 0 ]; then
        pass=$((pass + 1))
        n=$(grep -c '^SKIP ' "$rt.log.tmp")
        if [ "$n" -gt 0 ]; then
            cases_skipped=$((cases_skipped + n))
            echo "PASS $(basename "$rt") (${secs}s; $n case(s) skipped for want of test data)"
            grep '^SKIP ' "$rt.log.tmp" | head -3 | sed 's/^/    /'
        else
            echo "PASS $(basename "$rt") (${secs}s)"
        fi
    else
        fail=$((fail + 1))
        failed="$failed $(basename "$rt")"
        echo "FAIL $(basename "$rt") (exit $rc, ${secs}s)"
        # the failed checks first (a long script's last lines may all be "ok"), then the end
        grep '^FAIL' "$rt.log.tmp" | head -10 | sed 's/^/    /'
        sed 's/^/    /' "$rt.log.tmp" | tail -40
    fi
    rm -f "$rt.log.tmp" "$rt.rc.tmp"
}

# Reports the oldest tests as long as they have ended.
report_ended() {
    while [ -n "$queue" ]; do
        entry=${queue%% *}
        [ -e "${entry#*:}.rc.tmp" ] || return 0
        report_oldest
    done
}

for t in "$@" tests/cli_*.sh; do
    [ -e "$t" ] || continue
    while [ "$(running)" -ge "$jobs" ]; do sleep 0.2; done
    report_ended
    run_one "$t" &
    queue="${queue:+$queue }$!:$t"
done
while [ -n "$queue" ]; do report_oldest; done
[ -n "$failed" ] && echo "failed:$failed"
[ $cases_skipped -gt 0 ] && echo "$cases_skipped case(s) skipped inside passing tests: their data is outside the repository (MATEX_TESTDATA)"
echo "$pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
