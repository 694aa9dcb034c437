#!/bin/sh
# Start-up without OpenImageIO (issue 42): `matex --version`, `--help`, an option error and a
# PNG/EXR-only command never map libOpenImageIO (its ~250 libraries cost 1.3 s and 134 MB); a
# file only OpenImageIO reads (a BMP here) loads the adapter, libmatex_oiio.so, then. The
# libraries a run mapped are read from /proc/self/maps at its exit (tests/maps_at_exit.c, preloaded).
NAME=startup
. "$(dirname "$0")/lib_cli.sh"
HOOK=${BUILD:-build}/tests/maps_at_exit.so
# maps_of COMMAND...: runs it with the hook; $T/maps then lists what it mapped at exit
maps_of() {
    rm -f "$T/maps"
    # ASan must come first among the libraries; the hook uses none of its checks
    env LD_PRELOAD="$(realpath "$HOOK")" MATEX_MAPS_OUT="$T/maps" ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}verify_asan_link_order=0" \
        "$@" > "$T/out" 2> "$T/err"
    grep -q "maps_at_exit" "$T/maps" # the hook ran: the maps were read at exit
}
no_oiio() { [ -s "$T/maps" ] && ! grep -q "libOpenImageIO" "$T/maps"; }
[ -f "$HOOK" ] || { echo "FAIL the hook is not built: $HOOK"; exit 1; }

check "--version: maps read at exit" maps_of "$M" --version
check "--version does not map libOpenImageIO" no_oiio
check "--help: maps read at exit" maps_of "$M" --help
check "--help does not map libOpenImageIO" no_oiio
check "an option error: maps read at exit" maps_of "$M" texture tests/data/box.obj "a box" --image-size 7 -o "$T/o"
check "the option error was refused" grep -q "image-size" "$T/err"
check "an option error does not map libOpenImageIO" no_oiio
write_bmp "$T/rgb.bmp"
check "BMP through the adapter: maps read at exit" maps_of "$M" info "$T/rgb.bmp"
check "BMP read: 2 x 2" grep -q "^size: *2 x 2" "$T/out"
check "a BMP maps libOpenImageIO (the check can see it)" grep -q "libOpenImageIO" "$T/maps"
check "... through libmatex_oiio.so" grep -q "libmatex_oiio.so" "$T/maps"
# A texture job and the PNG and EXR it wrote, read back: no adapter
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
SMALL="--image-size 64 --steps 2 --texture-size 128 --render-size 128 --candidates 8 --views 4"
check "a texture job: maps read at exit" maps_of "$M" texture tests/data/box.obj "a box" --weights "$W" $SMALL -o "$T/job"
check "the texture job wrote its PNG and EXR" [ -s "$T/job/texture.png" ] && [ -s "$T/job/texture.exr" ]
check "a texture job does not map libOpenImageIO" no_oiio
for f in texture.png texture.exr; do
    check "info $f: maps read at exit" maps_of "$M" info "$T/job/$f"
    check "info $f read 128 x 128" grep -q "^size: *128 x 128" "$T/out"
    check "reading $f does not map libOpenImageIO" no_oiio
done
exit $fail
