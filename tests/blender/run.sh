#!/bin/sh
# make test-blender: the add-on in a real Blender (Debian's `blender`, 3.4 or later), installed
# from its zip into a scratch user folder (nothing of the user's Blender set-up is read or
# changed): test_addon.py headless (`blender -b`), then test_modal.py with Blender's window
# under xvfb-run (the buttons' modal path; SKIP without xvfb-run, a failure when CI=true).
set -u
BLENDER=${BLENDER:-blender}
command -v "$BLENDER" > /dev/null || { echo "test-blender: $BLENDER not found (apt-get install -y blender)" >&2; exit 1; }
S=$(mktemp -d "${TMPDIR:-/tmp}/matex_blender.XXXXXX")
trap 'rm -rf "$S"' EXIT
export MATEX=$(realpath "${MATEX:-build/matex}") MATEX_ADDON_ZIP=$(realpath "${MATEX_ADDON_ZIP:-build/matex_blender.zip}")
export MATEX_DEMO_WEIGHTS=$(realpath "${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}")
HERE=$(dirname "$0")
fail=0

# run_blender NAME [LAUNCHER...]: one test script in a fresh user folder; prints its check lines
run_blender() {
    name=$1; shift
    d="$S/$name"
    mkdir -p "$d/scripts" "$d/config" "$d/work"
    BLENDER_USER_SCRIPTS="$d/scripts" BLENDER_USER_CONFIG="$d/config" MATEX_BLENDER_TMP="$d/work" \
        "$@" --factory-startup --python-exit-code 1 --python "$HERE/$name.py" > "$d/log" 2>&1
    rc=$?
    grep -E '^(ok|FAIL|SKIP) |^test_' "$d/log"
    if [ $rc -ne 0 ]; then
        echo "test-blender: $name: Blender exited with $rc; its last lines:"
        tail -n 30 "$d/log"
        fail=1
    fi
}

run_blender test_addon "$BLENDER" -b
if command -v xvfb-run > /dev/null; then
    run_blender test_modal xvfb-run -a -s "-screen 0 1280x800x24" "$BLENDER"
elif [ "${CI:-}" = true ]; then
    echo "FAIL test_modal: xvfb-run missing (apt-get install -y xvfb)"; fail=1
else
    echo "SKIP test_modal: no xvfb-run (apt-get install -y xvfb)"
fi
exit $fail
