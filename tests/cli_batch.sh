#!/bin/sh
# matex batch: a manifest of tiny-weight jobs in two shards, bad lines and a failing job recorded
# with their line numbers, a rerun that skips what is complete, the shard from Slurm's array
# variables, the same texture as `matex texture`, and SIGTERM mid-run: exit 130, nothing partial,
# the next run completes only the missing jobs.
NAME=batch
. "$(dirname "$0")/lib_cli.sh"
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
SMALL='"steps": 1, "image-size": 64, "texture-size": 128, "render-size": 128, "candidates": 12'
cp "$(dirname "$0")/data/box.obj" "$T/box.obj"
{
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a wooden crate\", \"name\": \"crate\", $SMALL}"
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a metal box\", \"name\": \"metal\", \"seed\": 5, \"depth-weight\": [1.0, 0.5], $SMALL}"
    echo "{\"mesh\": \"nowhere.obj\", \"prompt\": \"a missing mesh\", $SMALL}"
    echo ""
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a stone block\", \"name\": \"stone\", \"negative\": \"blurry\", $SMALL}"
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"oops\" $SMALL}"
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"x\", \"name\": \"frob\", \"frobnicate\": 1}"
} > "$T/m.jsonl"
O="$T/outroot"
check "shard 0/2 exits 1 (a job failed)" [ "$(rc_of "$M" batch "$T/m.jsonl" --weights "$W" -o "$O" --shard 0/2 --json)" = 1 ]
cp "$T/out" "$T/s0.json"
check "shard 1/2 exits 1 (bad lines)" [ "$(rc_of "$M" batch "$T/m.jsonl" --weights "$W" -o "$O" --shard 1/2 --json)" = 1 ]
cp "$T/out" "$T/s1.json"
cat "$T/s0.json" "$T/s1.json"
# job lines 1 2 3 5 6 7 are jobs 0..5: shard 0 has lines 1, 3, 6 and shard 1 lines 2, 5, 7
check "shard 0 summary" grep -q '"shard":"0/2","jobs":3,"done":1,"skipped":0,"failed":2' "$T/s0.json"
check "shard 1 summary" grep -q '"shard":"1/2","jobs":3,"done":2,"skipped":0,"failed":1' "$T/s1.json"
for n in crate metal stone; do
    for f in texture.png mesh.glb report.json; do check "$n/$f" [ -s "$O/$n/$f" ]; done
done
cat "$O/failed.jsonl"
check "failed.jsonl: 3 lines" [ "$(wc -l < "$O/failed.jsonl")" = 3 ]
check "missing mesh recorded with its line" grep -q '"line":3,.*nowhere.obj' "$O/failed.jsonl"
check "bad JSON reported with its line" grep -q '"line":6,.*m.jsonl:6: ' "$O/failed.jsonl"
check "unknown key reported" grep -q '"line":7,.*unknown key \\"frobnicate\\"' "$O/failed.jsonl"
check "rerun: complete jobs skipped" [ "$(rc_of "$M" batch "$T/m.jsonl" --weights "$W" -o "$O" --json)" = 1 ]
check "rerun summary" grep -q '"jobs":6,"done":0,"skipped":3,"failed":3' "$T/out"
check "rerun: failed.jsonl lists each failure once (no duplicate at resume)" [ "$(wc -l < "$O/failed.jsonl")" = 3 ]
check "shard from SLURM_ARRAY_TASK_*" [ "$(SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_TASK_MIN=1 SLURM_ARRAY_TASK_COUNT=2 \
    rc_of "$M" batch "$T/m.jsonl" --weights "$W" -o "$O" --json)" = 1 ]
check "that is shard 1/2" grep -q '"shard":"1/2"' "$T/out"
check "bad --shard exits 2" [ "$(rc_of "$M" batch "$T/m.jsonl" --weights "$W" -o "$O" --shard 2/2)" = 2 ]
check "missing weights exits 1" [ "$(rc_of "$M" batch "$T/m.jsonl" --weights "$T/none.mxw" -o "$T/o2")" = 1 ]
check "naming the file" grep -q "none.mxw" "$T/err"
check "matex texture with the same options" [ "$(rc_of "$M" texture "$T/box.obj" "a metal box" --seed 5 \
    --depth-weight 1.0,0.5 --steps 1 --image-size 64 --texture-size 128 --render-size 128 --candidates 12 \
    --weights "$W" -o "$T/metal_cli")" = 0 ]
check "gives the same texture" cmp -s "$T/metal_cli/texture.exr" "$O/metal/texture.exr"

# every texture option of a job is a key (the option table); the model set's and force are not,
# and say why; a bad value is one message, file:line prefixed, with the valid range (issue 24 item 8)
{
    echo '{"mesh": "box.obj", "prompt": "x", "name": "neg", "seed": -1}'
    echo '{"mesh": "box.obj", "prompt": "x", "name": "stp", "steps": -3}'
    echo '{"mesh": "box.obj", "prompt": "x", "name": "thr", "threads": 2}'
    echo '{"mesh": "box.obj", "prompt": "x", "name": "frc", "force": true}'
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"x\", \"name\": \"fst\", \"fast\": true, $SMALL}"
} > "$T/keys.jsonl"
check "bad keys: exit 1" [ "$(rc_of "$M" batch "$T/keys.jsonl" --weights "$W" -o "$T/keys")" = 1 ]
cat "$T/err"
check "\"seed\": -1: one message" [ "$(grep -c seed "$T/err")" = 1 ]
check "... file:line and the range" grep -qF "keys.jsonl:1: \"seed\": --seed must be an integer in 0..18446744073709551615, not '-1'" "$T/err"
check "... no command-line usage message" sh -c "! grep -q 'for usage' '$T/err'"
check "\"steps\": -3: file:line and the range" grep -qF "keys.jsonl:2: \"steps\": --steps must be an integer in 1..200, not '-3'" "$T/err"
check "\"threads\": the model set's, given to batch" grep -qF "keys.jsonl:3: \"threads\" is the model set's" "$T/err"
check "\"force\": not a job key, with why" grep -qF "keys.jsonl:4: \"force\" is not a job key: batch skips" "$T/err"
check "\"fast\": true is a key (the demo weights then lack LCM)" grep -q "line 5 (fst): failed: .*--fast needs" "$T/err"
echo '{"mesh": "box.obj", "prompt": "a box", "name": "dflt"}' > "$T/one.jsonl"
check "batch --fast (a default of every job) is taken" [ "$(rc_of "$M" batch "$T/one.jsonl" --weights "$W" -o "$T/one" --fast)" = 1 ]
check "... the job says what --fast needs" grep -q "line 1 (dflt): failed: .*--fast needs" "$T/err"
check "batch --fast=1 exits 2" [ "$(rc_of "$M" batch "$T/one.jsonl" --weights "$W" -o "$T/one" --fast=1)" = 2 ]
check "... says it takes no value" grep -q -- "--fast takes no value" "$T/err"
check "batch --bogus exits 2, named unknown" [ "$(rc_of "$M" batch "$T/one.jsonl" --weights "$W" -o "$T/one" --bogus)" = 2 ]
check "... named unknown" grep -q "unknown option --bogus" "$T/err"
check "texture options on batch's command line are every job's defaults" [ "$(rc_of "$M" batch "$T/one.jsonl" --weights "$W" \
    -o "$T/one" --steps 1 --image-size 64 --texture-size 128 --render-size 128 --candidates 12 --seed 7)" = 0 ]
check "... as the report says" grep -q '"seed":7,"steps":1,' "$T/one/dflt/report.json"

# style images (issue 26): a line's style_image (relative to the manifest's folder, like mesh), --theme
# for every job, --theme-from-first (the first job's front.png is the style image of the others)
mkdir -p "$T/st"
cp "$(dirname "$0")/data/box.obj" "$T/st/box.obj"
echo "not a picture" > "$T/st/notes.png"
{
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a box\", \"name\": \"missing\", \"style_image\": \"nope.png\", $SMALL}"
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a box\", \"name\": \"notes\", \"style_image\": [\"notes.png\"], $SMALL}"
    echo "{\"mesh\": \"box.obj\", \"prompt\": \"a box\", \"name\": \"num\", \"style_image\": 3, $SMALL}"
} > "$T/st/bad.jsonl"
check "bad style_image lines: exit 1" [ "$(rc_of "$M" batch "$T/st/bad.jsonl" --weights "$W" -o "$T/st/bad")" = 1 ]
check "... a missing one named relative to the manifest" grep -q "line 1 (missing): failed: .*$T/st/nope.png: cannot open style image" "$T/err"
check "... one that is not an image" grep -q "line 2 (notes): failed: .*$T/st/notes.png: style image is not an image" "$T/err"
check "... a number" grep -q 'line 3 (num): failed: .*"style_image" takes a file name or an array of them' "$T/err"
check "... nothing written for them" [ -z "$(ls "$T/st/bad" | grep -v failed.jsonl)" ]
echo "{\"mesh\": \"box.obj\", \"prompt\": \"a box\", \"name\": \"t\", $SMALL}" > "$T/st/one.jsonl"
check "--theme FILE that is not an image: the job fails" [ "$(rc_of "$M" batch "$T/st/one.jsonl" --weights "$W" -o "$T/st/th" --theme "$T/st/notes.png")" = 1 ]
check "... naming it" grep -q "line 1 (t): failed: .*notes.png: style image is not an image" "$T/err"
check "--theme with --theme-from-first exits 2" [ "$(rc_of "$M" batch "$T/st/one.jsonl" --weights "$W" -o "$T/st/th" --theme "$T/st/notes.png" --theme-from-first)" = 2 ]
check "... saying why" grep -q "theme-from-first takes the style image from the first job" "$T/err"
for i in 1 2 3; do echo "{\"mesh\": \"box.obj\", \"prompt\": \"box $i\", \"name\": \"f$i\", $SMALL}"; done > "$T/st/theme.jsonl"
check "--theme-from-first, shard 1/2 first: its job waits for the theme" [ "$(rc_of "$M" batch "$T/st/theme.jsonl" --weights "$W" -o "$T/st/tf" --theme-from-first --shard 1/2)" = 1 ]
check "... and says where it comes from" grep -q "line 2 (f2): failed: $T/st/tf/f1/front.png: the theme image is not there" "$T/err"
check "--theme-from-first, shard 0/2" [ "$(rc_of "$M" batch "$T/st/theme.jsonl" --weights "$W" -o "$T/st/tf" --theme-from-first --shard 0/2)" = 0 ]
check "... the first job wrote front.png" [ -s "$T/st/tf/f1/front.png" ]
check "... listed as matex's own" grep -q "^front.png\$" "$T/st/tf/f1/.matex-output"
check "... the first job has no style image" sh -c "! grep -q style_images '$T/st/tf/f1/report.json'"
check "... the other jobs without front.png" [ ! -e "$T/st/tf/f3/front.png" ]
check "... f3 styled by f1's front.png" grep -q "\"style_images\":\[{\"source\":\"$T/st/tf/f1/front.png\"" "$T/st/tf/f3/report.json"
check "--theme-from-first, shard 1/2 again: done now" [ "$(rc_of "$M" batch "$T/st/theme.jsonl" --weights "$W" -o "$T/st/tf" --theme-from-first --shard 1/2)" = 0 ]
check "... f2 styled by it too" grep -q "\"source\":\"$T/st/tf/f1/front.png\"" "$T/st/tf/f2/report.json"
ST=$T/st/tf/f1/texture.png # a style image made by the test itself
check "--theme FILE" [ "$(rc_of "$M" batch "$T/st/theme.jsonl" --weights "$W" -o "$T/st/th2" --theme "$ST")" = 0 ]
check "... every job styled by it" [ "$(grep -l "$ST" "$T/st/th2"/f*/report.json | wc -l)" = 3 ]
cp "$ST" "$T/st/own.png"
echo "{\"mesh\": \"box.obj\", \"prompt\": \"box\", \"name\": \"own\", \"style_image\": \"own.png\", $SMALL}" > "$T/st/own.jsonl"
check "a line's style_image replaces --theme" [ "$(rc_of "$M" batch "$T/st/own.jsonl" --weights "$W" -o "$T/st/th3" --theme "$T/st/tf/f1/front.png")" = 0 ]
check "... (only its own in the report)" sh -c "grep -q '\"source\":\"$T/st/own.png\"' '$T/st/th3/own/report.json' && ! grep -q front.png '$T/st/th3/own/report.json'"
# SIGTERM in the middle of a run (what scancel sends), right after the first job is complete
for i in 1 2 3; do echo "{\"mesh\": \"box.obj\", \"prompt\": \"box $i\", \"name\": \"b$i\", $SMALL}"; done > "$T/slow.jsonl"
"$M" batch "$T/slow.jsonl" --weights "$W" -o "$T/slow" --threads 1 --json > "$T/int.json" 2> "$T/int.err" &
pid=$!
i=0
while [ ! -e "$T/slow/b1/report.json" ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done
kill -TERM $pid
wait $pid
rc=$?
cat "$T/int.json"
check "SIGTERM: exit 130" [ $rc = 130 ]
check "SIGTERM: summary says interrupted" grep -q '"interrupted":true' "$T/int.json"
check "SIGTERM: no partial folder left" [ -z "$(ls "$T/slow" | grep partial)" ]
ndone=$(ls "$T/slow" | grep -c '^b')
check "SIGTERM: some jobs missing ($ndone of 3 done)" [ "$ndone" -ge 1 -a "$ndone" -lt 3 ]
check "rerun after SIGTERM" [ "$(rc_of "$M" batch "$T/slow.jsonl" --weights "$W" -o "$T/slow" --threads 1 --json)" = 0 ]
cat "$T/out"
check "it completes only the missing jobs" grep -q "\"done\":$((3 - ndone)),\"skipped\":$ndone,\"failed\":0" "$T/out"
exit $fail
