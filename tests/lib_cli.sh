# Shared by the tests/cli_*.sh scripts (sourced, not run): the binary under test, a scratch
# folder removed on exit, and the two checks. Set NAME before sourcing.
SHARED=${MATEX_SHARED:-../shared}
M=${MATEX:-./matex}
T=$(mktemp -d "/tmp/matex_cli_${NAME:-test}.XXXXXX")
trap 'rm -rf "$T"' EXIT
fail=0
check() { # check NAME COMMAND...: the command must succeed
    name=$1; shift
    if "$@"; then echo "ok   $name"; else echo "FAIL $name"; fail=1; fi
}
rc_of() { "$@" > "$T/out" 2> "$T/err"; echo $?; } # runs a command, prints its exit code
