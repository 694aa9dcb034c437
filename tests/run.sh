#!/bin/sh
# Runs every test program and script given, prints one line per test and the closing
# "N passed, N failed, N skipped" line; exits non-zero if any failed. A test that exits 77 did
# not run (e.g. the SD1.5-size cases outside `make test-full`) and counts as skipped.
pass=0
fail=0
skip=0
failed=""
for t in "$@" tests/cli_*.sh; do
    [ -e "$t" ] || continue
    start=$(date +%s)
    case "$t" in
    *.sh) sh "$t" > "$t.log.tmp" 2>&1 ;;
    *) "$t" > "$t.log.tmp" 2>&1 ;;
    esac
    rc=$?
    secs=$(( $(date +%s) - start ))
    if [ $rc -eq 77 ]; then
        skip=$((skip + 1))
        echo "SKIP $(basename "$t") ($(tail -n 1 "$t.log.tmp"))"
    elif [ $rc -eq 0 ]; then
        pass=$((pass + 1))
        echo "PASS $(basename "$t") (${secs}s)"
    else
        fail=$((fail + 1))
        failed="$failed $(basename "$t")"
        echo "FAIL $(basename "$t") (exit $rc, ${secs}s)"
        sed 's/^/    /' "$t.log.tmp" | tail -40
    fi
    rm -f "$t.log.tmp"
done
[ -n "$failed" ] && echo "failed:$failed"
echo "$pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
