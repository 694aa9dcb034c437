#!/bin/sh
# `make test-arm64`: the aarch64 cross-build (ARM64_BUILD, default build-arm64) run under qemu-user.
# The test programs run on two CPU models: cortex-a72 (Advanced SIMD, no FEAT_BF16: the neon
# level) and max (FEAT_BF16: neonbf16, and neon below it for fp32); the level each model gets is
# read from getauxval by matex itself, so a level a model lacks shows as NOT TESTED, never as passed.
# matex --version (matex-core: matex without the file I/O adapter) must name the level each model
# gets. Then the core library's dependencies (readelf -d: libc, libm, pthreads only) and the tiny
# pipeline through the C API with an in-memory mesh (examples/embed.c on libmatex_core.a).
# Only the repository's tiny goldens run (MATEX_TESTDATA points nowhere: the mini cases take
# minutes each under emulation), on the cpu-strict backend as in `make test`.
B=${ARM64_BUILD:-build-arm64}
XCC=${ARM64_CC:-aarch64-linux-gnu-gcc}
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
SYSROOT=${ARM64_SYSROOT:-/usr/aarch64-linux-gnu}
CPUS="cortex-a72 max"
for tool in qemu-aarch64 aarch64-linux-gnu-readelf; do
    command -v $tool > /dev/null || { echo "test-arm64: $tool not found (Debian: apt-get install qemu-user gcc-aarch64-linux-gnu)"; exit 1; }
done
pass=0
fail=0
failed=""
LOGS=$B/arm64-logs
mkdir -p "$LOGS"
rm -f "$LOGS"/*.log

# run CPU NAME COMMAND...: one test under qemu on CPU model CPU
run() {
    cpu=$1 name=$2
    shift 2
    log="$LOGS/$name.$cpu.log"
    start=$(date +%s)
    env -u CI MATEX_TESTDATA="$B/no-testdata" MX_TEST_DEVICE=cpu-strict MATEX_DEMO_WEIGHTS="$W" \
        qemu-aarch64 -L "$SYSROOT" -cpu "$cpu" "$@" > "$log" 2>&1
    rc=$?
    secs=$(($(date +%s) - start))
    if [ $rc -eq 0 ]; then
        pass=$((pass + 1))
        echo "PASS $name on $cpu (${secs}s)"
    else
        fail=$((fail + 1))
        failed="$failed $name/$cpu"
        echo "FAIL $name on $cpu (exit $rc, ${secs}s)"
        sed 's/^/    /' "$log" | tail -30
    fi
}

# Every program on max; on cortex-a72 those named in ARM64_NOBF16_TESTS (the kernel and level
# tests): the network goldens in fp32 run the same neon kernels on max, and emulation is slow.
for t in "$@"; do run max "$t" "$B/tests/$t"; done
for t in ${ARM64_NOBF16_TESTS:-}; do run cortex-a72 "$t" "$B/tests/$t"; done

# What matex itself picks on each model (getauxval), and MATEX_ISA lowering it.
version_is() {
    cpu=$1 want=$2
    shift 2
    got=$(env "$@" qemu-aarch64 -L "$SYSROOT" -cpu "$cpu" "$B/matex-core" --version 2>&1 | sed -n 's/^cpu kernels used on this CPU: //p')
    case "$got" in
    "$want"*) pass=$((pass + 1)); echo "PASS matex --version on $cpu${1:+ ($*)}: $got" ;;
    *) fail=$((fail + 1)); failed="$failed version/$cpu"; echo "FAIL matex --version on $cpu${1:+ ($*)}: '$got', want '$want'" ;;
    esac
}
version_is cortex-a72 "fp32 neon, bf16 neon"
version_is max "fp32 neon, bf16 neonbf16"
version_is max "fp32 neon, bf16 neon" MATEX_ISA=neon
version_is max "fp32 scalar, bf16 scalar" MATEX_ISA=scalar

# The levels each CPU model exercised, from test_ops_kernels' lines ("LEVEL: NOT TESTED (...)").
for cpu in $CPUS; do
    log="$LOGS/test_ops_kernels.$cpu.log"
    [ -f "$log" ] || continue
    tested=$(sed -n 's/^\(neon[a-z0-9]*\) linear .* ok$/\1/p' "$log" | sort -u | tr '\n' ' ')
    untested=$(sed -n 's/^\(neon[a-z0-9]*\): NOT TESTED.*/\1/p' "$log" | tr '\n' ' ')
    echo "levels on $cpu: tested: ${tested:-none}${untested:+; NOT TESTED: $untested}"
done
for level in neon neonbf16; do
    grep -q "^$level linear .* ok$" "$LOGS"/test_ops_kernels.*.log 2> /dev/null ||
        echo "$level: NOT TESTED on any CPU model of this qemu"
done

# The core library: libc, libm and pthreads only; the tiny pipeline through the C API.
if $XCC -std=c11 -Wall -Wextra -Werror -Iinclude examples/embed.c "$B/libmatex_core.a" -lm -lpthread -o "$B/embed_core"; then
    needed=$(aarch64-linux-gnu-readelf -d "$B/embed_core" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' | tr '\n' ' ')
    echo "embed_core NEEDED: $needed"
    others=$(echo "$needed" | tr ' ' '\n' | grep -v -E '^(libc|libm|libpthread|ld-linux[-a-z0-9_.]*)\.so' | grep -v '^$')
    if [ -z "$others" ]; then
        pass=$((pass + 1))
        echo "PASS core library needs only libc, libm and pthreads"
    else
        fail=$((fail + 1))
        failed="$failed core-deps"
        echo "FAIL core library needs: $others"
    fi
    for cpu in $CPUS; do
        run "$cpu" embed_core "$B/embed_core" --quick "$W"
        grep -q "^cube: [0-9]* views" "$LOGS/embed_core.$cpu.log" || {
            fail=$((fail + 1))
            failed="$failed embed-report/$cpu"
            echo "FAIL embed_core on $cpu: no 'cube: N views' report"
        }
    done
else
    fail=$((fail + 1))
    failed="$failed embed-build"
    echo "FAIL examples/embed.c does not link against $B/libmatex_core.a"
fi

[ -n "$failed" ] && echo "failed:$failed"
echo "test-arm64: $pass passed, $fail failed"
[ $fail -eq 0 ]
