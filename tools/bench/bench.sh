#!/bin/sh
# `make bench`: runs every benchmark program built in BUILD/tools (bench_*), one after the
# other. Usage: sh tools/bench/bench.sh BUILD. Exits non-zero when one fails or none is built.
BUILD=${1:-build}
# the benchmarks that need the SD1.5 model set make it once with this matex (bench_sd15.h)
export MATEX="${MATEX:-$BUILD/matex}"
status=0
found=0
for b in "$BUILD"/tools/bench/bench_*; do
    case "$b" in *.o | *.d) continue ;; esac
    [ -x "$b" ] || continue
    found=1
    echo "== $(basename "$b")"
    # OpenBLAS is the anchor at its best: machines here may set OPENBLAS_CORETYPE/L2_SIZE (to work
    # around old OpenBLAS bugs), which forces slower kernels; the benchmark unsets both for itself.
    # OPENBLAS_THREAD_TIMEOUT=4: its idle workers stop spinning soon after a call, so they do not
    # steal a core from the matex run that the benchmark alternates with.
    env -u OPENBLAS_CORETYPE -u OPENBLAS_L2_SIZE OPENBLAS_THREAD_TIMEOUT=4 "$b"
    rc=$?
    if [ $rc -ne 0 ]; then
        echo "$(basename "$b"): failed (exit $rc)"
        status=1
    fi
done
if [ $found -eq 0 ]; then
    echo "bench.sh: no benchmark programs in $BUILD/tools" >&2
    exit 1
fi
exit $status
