#!/bin/sh
# Runs every test program and script given, prints one line per test and the closing
# "N passed, N failed, N skipped" line; exits non-zero if any failed. A test that exits 77 did
# not run (e.g. the SD1.5-size cases outside `make test-full`) and counts as skipped. A test that
# passes may have skipped cases whose data is outside the repository ("SKIP REL: ..." lines, see
# tests/util_test.h): they are counted and the first few shown.
pass=0
fail=0
skip=0
cases_skipped=0
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
        n=$(grep -c '^SKIP ' "$t.log.tmp")
        if [ "$n" -gt 0 ]; then
            cases_skipped=$((cases_skipped + n))
            echo "PASS $(basename "$t") (${secs}s; $n case(s) skipped for want of test data)"
            grep '^SKIP ' "$t.log.tmp" | head -3 | sed 's/^/    /'
        else
            echo "PASS $(basename "$t") (${secs}s)"
        fi
    else
        fail=$((fail + 1))
        failed="$failed $(basename "$t")"
        echo "FAIL $(basename "$t") (exit $rc, ${secs}s)"
        # the failed checks first (a long script's last lines may all be "ok"), then the end
        grep '^FAIL' "$t.log.tmp" | head -10 | sed 's/^/    /'
        sed 's/^/    /' "$t.log.tmp" | tail -40
    fi
    rm -f "$t.log.tmp"
done
[ -n "$failed" ] && echo "failed:$failed"
[ $cases_skipped -gt 0 ] && echo "$cases_skipped case(s) skipped inside passing tests: their data is outside the repository (MATEX_TESTDATA)"
echo "$pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
