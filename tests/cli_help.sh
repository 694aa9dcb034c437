#!/bin/sh
# Help in step with the code and the README (issue 42): the top-level help's summaries of
# `convert` and `info` name what those verbs take (their own --help); `bench --help` lists the
# MATEX_ISA levels of the code's table, the same as the README, each one accepted by matex (an
# unknown one is warned about); the README's C API example builds under build/ and shows --quick.
NAME=help
. "$(dirname "$0")/lib_cli.sh"
README=${MATEX_README:-README.md}
check "--help exits 0" [ "$(rc_of "$M" --help)" = 0 ]
cp "$T/out" "$T/help"
summary() { sed -n "s/^  $1  *//p" "$T/help"; }
check "convert --help takes single-file checkpoints" sh -c "'$M' convert --help | grep -q 'single-file checkpoint'"
check "... and the summary says so" sh -c "echo '$(summary convert)' | grep -q checkpoint"
check "convert's summary still names diffusers folders" sh -c "echo '$(summary convert)' | grep -q diffusers"
check "info --help takes images and checkpoints" sh -c "'$M' info --help | grep -q 'an image' && '$M' info --help | grep -q 'checkpoint'"
check "... and the summary says so" sh -c "echo '$(summary info)' | grep -q image && echo '$(summary info)' | grep -q checkpoint"

# the MATEX_ISA levels: bench --help, the README, and what matex accepts
levels() { sed -n 's/.*MATEX_ISA=\([a-z0-9|]*\).*/\1/p' | head -n 1 | tr '|' '\n' | sort; }
"$M" bench --help 2>&1 | levels > "$T/bench_levels"
levels < "$README" > "$T/readme_levels"
check "bench --help lists levels" [ -s "$T/bench_levels" ]
check "bench --help and the README list the same levels" cmp -s "$T/bench_levels" "$T/readme_levels"
for l in $(cat "$T/bench_levels"); do
    check "MATEX_ISA=$l is a level matex knows" sh -c "! env MATEX_ISA=$l '$M' --version 2>&1 | grep -q unknown"
done
check "an unknown level is warned about (the check above can fail)" sh -c "env MATEX_ISA=avx9 '$M' --version 2>&1 | grep -q unknown"

# the C API example as the README shows it
check "the README builds examples/embed.c under build/" grep -q "examples/embed.c .*-o build/embed" "$README"
check "the README runs it with --quick for the demo weights" grep -q "build/embed --quick " "$README"
exit $fail
