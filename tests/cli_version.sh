#!/bin/sh
# matex --version: exit 0, the version, compiler, flags, sanitizers, the CPU kernel levels
# compiled in and the one used (MATEX_ISA lowers it), the backends.
NAME=version
. "$(dirname "$0")/lib_cli.sh"

check "--version exits 0" [ "$(rc_of "$M" --version)" = 0 ]
check "version line" grep -q "^matex [0-9][0-9]*\.[0-9][0-9]*\.[0-9][0-9]*$" "$T/out"
check "compiler line" grep -q "^compiler: \(gcc\|clang\) [0-9]" "$T/out"
check "flags line" grep -q "^flags: -O[0-3s].* -ffp-contract=off" "$T/out"
check "sanitizers line" grep -q "^sanitizers: \(none\|address,undefined\)$" "$T/out"
check "scalar kernels compiled in" grep -q "^cpu kernels compiled in: scalar" "$T/out"
fp32=$(sed -n 's/^cpu kernels used on this CPU: fp32 \([a-z0-9_]*\), bf16 .*/\1/p' "$T/out")
bf16=$(sed -n 's/^cpu kernels used on this CPU: fp32 [a-z0-9_]*, bf16 \([a-z0-9_]*\).*/\1/p' "$T/out")
check "the fp32 level is compiled in" grep -q "^cpu kernels compiled in:.* $fp32\( \|$\)" "$T/out"
check "the bf16 level is compiled in" grep -q "^cpu kernels compiled in:.* $bf16\( \|$\)" "$T/out"
check "backends line" grep -q "^backends: cpu cpu-strict" "$T/out"
check "MATEX_ISA=scalar exits 0" [ "$(rc_of env MATEX_ISA=scalar "$M" --version)" = 0 ]
check "MATEX_ISA=scalar is used" grep -q "^cpu kernels used on this CPU: fp32 scalar, bf16 scalar (MATEX_ISA lowers them)$" "$T/out"
check "-V is --version" [ "$(rc_of "$M" -V)" = 0 ]
check "-V prints the version" grep -q "^matex [0-9]" "$T/out"
exit $fail
