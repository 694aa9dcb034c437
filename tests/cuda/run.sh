#!/bin/sh
# make test-cuda: the CUDA op test first; it skips (77) only when there is no GPU at all (no CUDA
# device and none in nvidia-smi), and then nothing else runs. A GPU that CUDA cannot use (driver too
# old, nvidia-smi sees one but CUDA does not) is a failure. With one, the network goldens and the
# tiny pipeline run on the GPU, also after a failed op test (the Makefile sets MX_TEST_DEVICE=cuda;
# tests/nn_golden.h applies the half-precision bound only to runs that computed in half precision).
ops_test=$1
shift
"$ops_test"
rc=$?
[ $rc -eq 77 ] && exit 0
[ $rc -ne 0 ] && failed=1 # the network tests still run: each is a process of its own
for t in "$@"; do
    "$t"
    rc=$?
    if [ $rc -eq 77 ]; then echo "SKIP $(basename "$t")"; elif [ $rc -ne 0 ]; then echo "FAIL $(basename "$t")"; failed=1; else echo "PASS $(basename "$t")"; fi
done
[ -z "$failed" ]
