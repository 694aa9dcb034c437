#!/bin/sh
# The embedding example as a user builds it: `make install` into a temporary prefix, then
# examples/embed.c compiled with `pkg-config --cflags --libs matex` against that prefix and run
# on the demo weights: a cube in memory (results in memory) and a small OBJ written to a folder.
# OpenImageIO is in neither: the installed matex finds its adapter in PREFIX/lib, and so would the
# example (matex.pc gives it that RUNPATH).
NAME=embed
. "$(dirname "$0")/lib_cli.sh"
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
eval "${MATEX_MAKE_VARS:-}" # BUILD, CC, SAN ... of the build under test
P="$T/prefix"
check "make install PREFIX=..." sh -c "make -s ${MATEX_MAKE_VARS:-} install PREFIX='$P' > '$T/install.log' 2>&1"
for f in include/matex.h lib/libmatex.a lib/libmatex_io.a lib/libmatex_oiio.so lib/pkgconfig/matex.pc bin/matex; do
    check "installed $f" [ -s "$P/$f" ]
done
export PKG_CONFIG_PATH="$P/lib/pkgconfig"
check "pkg-config knows matex" pkg-config --exists matex
# OpenImageIO is opened on first use, from PREFIX/lib: not linked, found through the RUNPATH
check "pkg-config links no OpenImageIO" sh -c '! pkg-config --libs matex | grep -q OpenImageIO'
check "pkg-config sets the RUNPATH to PREFIX/lib" sh -c "pkg-config --libs matex | grep -q -- '-Wl,-rpath,$P/lib'"
write_bmp "$T/rgb.bmp"
check "the installed matex reads a BMP through PREFIX/lib/libmatex_oiio.so" \
    [ "$(rc_of env -u LD_LIBRARY_PATH "$P/bin/matex" info "$T/rgb.bmp")" = 0 ]
check "... a 2 x 2 image" grep -q "^size: *2 x 2" "$T/out"
check "the example builds with pkg-config" sh -c \
    "${CC:-cc} -std=c11 -Wall -Wextra -Werror examples/embed.c \$(pkg-config --cflags --libs matex) -o '$T/embed'"
check "the example's RUNPATH holds PREFIX/lib" sh -c "readelf -d '$T/embed' | grep -q 'R.*PATH.*$P/lib'"
check "the example maps no OpenImageIO library" sh -c "! ldd '$T/embed' | grep -q OpenImageIO"
cp tests/data/box.obj "$T/box.obj"
check "the example runs" [ "$(rc_of "$T/embed" --quick "$W" "$T/box.obj" "$T/box_out")" = 0 ]
cp "$T/out" "$T/run.txt"; cat "$T/out" "$T/err"
check "cube textured in memory" grep -q "^cube: [0-9]* views, coverage " "$T/run.txt"
check "progress lines" grep -q "finish" "$T/run.txt"
for f in texture.png texture.exr mesh.obj mesh.mtl mesh.glb report.json; do
    check "box output $f" [ -s "$T/box_out/$f" ]
done
check "the report names the mesh" grep -q "box.obj" "$T/box_out/report.json"
check "a missing weight file fails" [ "$(rc_of "$T/embed" --quick "$T/none.mxw")" = 1 ]
check "with a message naming it" grep -q "none.mxw" "$T/err"
exit $fail
