# Shared by the tests/cli_*.sh scripts (sourced, not run): the binary under test, a scratch
# folder removed on exit, the test data and the checks. Set NAME before sourcing.
M=${MATEX:-./matex}
T=$(mktemp -d "/tmp/matex_cli_${NAME:-test}.XXXXXX")
trap 'rm -rf "$T"' EXIT
fail=0
check() { # check NAME COMMAND...: the command must succeed
    name=$1; shift
    if "$@"; then echo "ok   $name"; else echo "FAIL $name"; fail=1; fi
}
rc_of() { "$@" > "$T/out" 2> "$T/err"; echo $?; } # runs a command, prints its exit code
# signal_twice PID: SIGINT then SIGTERM, both sent while the process is stopped (SIGSTOP) so that
# both arrive before it can act on the first (two SIGINTs would merge into one); then waits for it
# and returns its exit code
signal_twice() {
    kill -STOP "$1"
    kill -INT "$1"
    kill -TERM "$1"
    kill -CONT "$1"
    wait "$1"
}
# Test data as in tests/util_test.h: data REL prints tests/data/<REL> when the repository ships it,
# else $MATEX_TESTDATA/REL (default ../shared). have REL is true when it exists; otherwise it
# prints a SKIP line (a failure when CI=true, where that data must be there).
data() {
    if [ -e "tests/data/$1" ]; then echo "tests/data/$1"; else echo "${MATEX_TESTDATA:-../shared}/$1"; fi
}
have() {
    [ -e "$(data "$1")" ] && return 0
    if [ "${CI:-}" = true ]; then
        echo "FAIL $1: test data missing (not in tests/data nor ${MATEX_TESTDATA:-../shared}; CI must have it)"; fail=1
    else
        echo "SKIP $1: not in tests/data nor ${MATEX_TESTDATA:-../shared} (set MATEX_TESTDATA)"
    fi
    return 1
}
# write_bmp FILE: a 2 x 2 24-bit BMP (54-byte header, two rows of 6 bytes + 2 of padding): an image
# that only OpenImageIO reads (matex reads PNG and EXR itself)
write_bmp() {
    printf '\102\115\106\000\000\000\000\000\000\000\066\000\000\000\050\000\000\000\002\000\000\000\002\000\000\000\001\000\030\000\000\000\000\000\020\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\000\377\000\377\000\000\000\377\000\000\377\377\377\000\000' > "$1"
}
