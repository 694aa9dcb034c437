#!/bin/sh
# make test-cuda: the CUDA op test first; without a GPU it prints its one skip line and nothing
# else runs. With one, the network goldens and the tiny pipeline run on the GPU (the Makefile sets
# MX_TEST_DEVICE=cuda and MX_TEST_MIN_BOUND=1e-2: half-precision arithmetic against the CPU goldens).
ops_test=$1
shift
"$ops_test"
rc=$?
[ $rc -eq 77 ] && exit 0
[ $rc -ne 0 ] && exit $rc
for t in "$@"; do
    "$t"
    rc=$?
    if [ $rc -eq 77 ]; then echo "SKIP $(basename "$t")"; elif [ $rc -ne 0 ]; then echo "FAIL $(basename "$t")"; failed=1; else echo "PASS $(basename "$t")"; fi
done
[ -z "$failed" ]
