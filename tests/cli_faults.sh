#!/bin/sh
# Fault injection on a tiny `matex texture` run (tests/faults/fault.c): the k-th allocation
# fails, or the disk fills up at the k-th write. Each run must end in exit 1 with one clear
# message on stderr, leave nothing behind (no output folder, no temporary sibling), and, in an
# ASan build, report no leak; in any build, leave no block of matex's C allocation functions
# unfreed at exit (the injector's own count: "live" in its report). `make test` samples k;
# MATEX_FAULTS_SWEEP=full (`make faults`, on the fast plain build) tries every k. A run where the failure is absorbed (exit 0) must still have written the
# whole output; such k are counted and listed. MATEX_FAULTS_SWEEP=sites fails the first
# allocation of every allocation site (and every write).
NAME=faults
. "$(dirname "$0")/lib_cli.sh"
F=${MATEX_FAULTS:-build/tests/faults/matex_faults}
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
MESH=$(data assets/fedora_hat/fedora.obj)
SAMPLES=${MATEX_FAULTS_SAMPLES:-8}
OUTPUTS="texture.png texture.exr mesh.obj mesh.mtl mesh.glb report.json"

run() { # run DIR [VAR=k]: the tiny texturing run into DIR/out, stdout/stderr in DIR
    mkdir -p "$1/work"
    env ${2:+"$2"} MATEX_FAULT_REPORT="$1/report" "$F" texture "$MESH" "a grey felt hat" --weights "$W" \
        -o "$1/work/out" --image-size 64 --steps 1 --views 2 --texture-size 64 --render-size 64 --candidates 8 \
        --threads 1 --quiet > "$1/stdout" 2> "$1/stderr"
}

# judge KIND K: one run with the fault; prints "ok", "absorbed" or "BAD <why>" into its result file
judge() {
    d=$T/$1_$2
    run "$d" "MATEX_FAIL_$(echo "$1" | tr a-z A-Z)=$2"
    rc=$?
    left=$(ls -A "$d/work")
    lines=$(wc -l < "$d/stderr")
    live=$(sed -n 's/^live //p' "$d/report" 2> /dev/null)
    if grep -q "Sanitizer\|runtime error" "$d/stderr"; then why="sanitizer report: $(grep -m1 "ERROR\|runtime error" "$d/stderr")"
    elif [ "${live:-0}" -gt 0 ]; then why="leak: $live allocated blocks not freed at exit (exit $rc)"
    elif [ $rc -eq 0 ]; then
        why=absorbed
        for f in $OUTPUTS; do [ -s "$d/work/out/$f" ] || why="exit 0 without $f"; done
    elif [ $rc -ne 1 ]; then why="exit $rc: $(tail -n 2 "$d/stderr" | tr '\n' ' ')"
    elif [ -n "$left" ]; then why="left behind: $left"
    elif [ "$lines" -ne 1 ] || ! grep -q "^matex texture: ..*" "$d/stderr"; then why="stderr is not one message: $(head -c 300 "$d/stderr" | tr '\n' '|')"
    else why=ok
    fi
    echo "$why" > "$T/result_$1_$2"
    [ "$why" = ok ] && rm -rf "$d"
}

# ks KIND N: the k to try among 1..N (all of them in a full sweep, the first allocation of each
# site in a sites sweep, else SAMPLES spread evenly)
ks() {
    sweep=${MATEX_FAULTS_SWEEP:-sample}
    if [ "$sweep" = full ] || [ "$2" -le "$SAMPLES" ] || { [ "$sweep" = sites ] && [ "$1" = write ]; }; then seq 1 "$2"
    elif [ "$sweep" = sites ]; then sed -n 's/^first //p' "$T/base/report" | sort -n
    else seq 0 $((SAMPLES - 1)) | awk -v n="$2" -v s="$SAMPLES" '{ print 1 + int($1 * (n - 1) / (s - 1)) }'
    fi
}

sweep() { # sweep KIND N: two runs at a time
    i=0
    for k in $(ks "$1" "$2"); do
        judge "$1" "$k" &
        i=$((i + 1))
        [ $((i % 2)) -eq 0 ] && wait
    done
    wait
    ok=$(grep -lx ok "$T"/result_"$1"_* | wc -l)
    absorbed=$(grep -lx absorbed "$T"/result_"$1"_* | sed "s|.*_||" | sort -n | tr '\n' ' ')
    bad=$(grep -Lx "ok\|absorbed" "$T"/result_"$1"_* | wc -l)
    echo "$1: $i of $2 k tried ($3 call sites seen): $ok failed cleanly, absorbed at k = ${absorbed:-none}, $bad bad"
    for r in $(grep -Lx "ok\|absorbed" "$T"/result_"$1"_*); do echo "    k=${r##*_}: $(cat "$r")"; done
    [ "$bad" -eq 0 ]
}

check "the fault-free run succeeds" run "$T/base"
for f in $OUTPUTS; do check "the fault-free run wrote $f" [ -s "$T/base/work/out/$f" ]; done
read -r _ allocs _ alloc_sites < "$T/base/report"
write_line=$(sed -n 2p "$T/base/report")
writes=$(echo "$write_line" | cut -d' ' -f2)
write_sites=$(echo "$write_line" | cut -d' ' -f4)
check "allocations were counted" [ "${allocs:-0}" -gt 100 ]
check "writes were counted" [ "${writes:-0}" -gt 5 ]
check "the fault-free run frees every block" [ "$(sed -n 's/^live //p' "$T/base/report")" = 0 ]
check "every failed allocation ends cleanly" sweep alloc "$allocs" "$alloc_sites"
check "every failed write ends cleanly" sweep write "$writes" "$write_sites"
exit $fail
