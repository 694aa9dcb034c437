#!/bin/sh
# The core library (`make core`, libmatex_core.a: runtime, ops, weights, networks, geometry and
# the method in C, no I/O adapter): examples/embed.c links against it with libc, libm and
# pthreads only (readelf -d NEEDED), textures a cube in memory, and refuses a mesh file clearly.
NAME=core
. "$(dirname "$0")/lib_cli.sh"
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
eval "${MATEX_MAKE_VARS:-}"
B=${BUILD:-build}
SANFLAGS=""
[ "${SAN:-}" = 1 ] && SANFLAGS="-fsanitize=address,undefined"
check "libmatex_core.a exists" [ -s "$B/libmatex_core.a" ]
check "the example links against the core library" sh -c \
    "${CC:-cc} -std=c11 -Wall -Wextra -Werror -Iinclude examples/embed.c '$B/libmatex_core.a' -lm -lpthread $SANFLAGS -o '$T/embed_core'"
readelf -d "$T/embed_core" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' > "$T/needed"
echo "NEEDED: $(tr '\n' ' ' < "$T/needed")"
# sanitizer runtimes (make asan) are the only extra allowed
others=$(grep -v -E '^(libc|libm|libpthread|ld-linux[-a-z0-9_]*)\.so' "$T/needed" | grep -v -E '^lib(a|ub)san\.so' )
check "needs only libc, libm and pthreads" [ -z "$others" ]
check "the core build textures a mesh in memory" [ "$(rc_of "$T/embed_core" --quick "$W")" = 0 ]
check "with its report" grep -q "^cube: [0-9]* views" "$T/out"
check "a mesh file is refused" [ "$(rc_of "$T/embed_core" --quick "$W" tests/data/box.obj "$T/o")" = 1 ]
check "saying the build has no file I/O" grep -q "no file I/O adapter" "$T/err"
echo "libmatex_core.a: $(wc -c < "$B/libmatex_core.a") bytes; embed (core, stripped): $(strip -o "$T/s" "$T/embed_core" && wc -c < "$T/s") bytes"
exit $fail
