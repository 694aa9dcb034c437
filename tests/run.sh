#!/bin/sh
# Runs every test program and script given, prints one line per test and the closing
# "N passed, N failed" line; exits non-zero if any failed.
pass=0
fail=0
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
    if [ $rc -eq 0 ]; then
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
echo "$pass passed, $fail failed"
[ $fail -eq 0 ]
