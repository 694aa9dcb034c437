#!/bin/sh
# make test-blender: the add-on in a real, headless Blender (Debian's `blender`, 3.4 or later).
# The add-on is installed from its zip into a scratch user folder (nothing of the user's Blender
# set-up is read or changed), then tests/blender/test_addon.py drives it with the demo weights.
set -u
BLENDER=${BLENDER:-blender}
command -v "$BLENDER" > /dev/null || { echo "test-blender: $BLENDER not found (apt-get install -y blender)" >&2; exit 1; }
S=$(mktemp -d "${TMPDIR:-/tmp}/matex_blender.XXXXXX")
trap 'rm -rf "$S"' EXIT
export BLENDER_USER_SCRIPTS="$S/scripts" BLENDER_USER_CONFIG="$S/config" MATEX_BLENDER_TMP="$S/work"
mkdir -p "$BLENDER_USER_SCRIPTS" "$BLENDER_USER_CONFIG" "$MATEX_BLENDER_TMP"
export MATEX=$(realpath "${MATEX:-build/matex}") MATEX_ADDON_ZIP=$(realpath "${MATEX_ADDON_ZIP:-build/matex_blender.zip}")
export MATEX_DEMO_WEIGHTS=$(realpath "${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}")
"$BLENDER" -b --factory-startup --python-exit-code 1 --python "$(dirname "$0")/test_addon.py" > "$S/log" 2>&1
rc=$?
grep -E '^(ok|FAIL|SKIP) |^test_addon' "$S/log"
if [ $rc -ne 0 ]; then
    echo "test-blender: Blender exited with $rc; its last lines:" >&2
    tail -n 30 "$S/log" >&2
fi
exit $rc
