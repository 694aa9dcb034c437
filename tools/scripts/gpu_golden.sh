#!/bin/sh
# On a GPU machine: the network test packed by `make gpu-golden-pack` (build-cuda/gpu-golden.tar.gz:
# one test and the golden folder it reads, too large to travel with gpu-check's pack) on the CUDA
# backend (MX_TEST_DEVICE, default cuda), the packed golden through the device binder
# (docs/cuda-notes.md §7). Fails when the test fails or checked no case of a packed golden.
set -u
A=${GPU_GOLDEN_PACK:-build-cuda/gpu-golden.tar.gz}
D=$(dirname "$A")/gpu-golden
[ -f "$A" ] || { echo "gpu_golden: $A missing (make gpu-golden-pack)" >&2; exit 1; }
rm -rf "$D" && tar -C "$(dirname "$A")" -xzf "$A" || exit 1
LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
rc=0
for t in "$D"/test_nn_*; do
    echo "== $(basename "$t") on ${MX_TEST_DEVICE:-cuda}, goldens: $(ls "$D/data/golden" | tr '\n' ' ')"
    MATEX_TESTDATA="$D/data" MX_TEST_DEVICE=${MX_TEST_DEVICE:-cuda} MATEX_FULL=1 "$t" >"$LOG" 2>&1 || rc=1
    cat "$LOG"
    for g in "$D"/data/golden/*; do
        n=$(basename "$g")
        if grep -q "SKIP golden/$n/" "$LOG" || ! grep -q "^$n .* ok$" "$LOG"; then
            echo "FAIL gpu_golden: $(basename "$t") did not check the packed golden $n"
            rc=1
        fi
    done
done
exit $rc
