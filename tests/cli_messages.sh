#!/bin/sh
# What a new user meets (issue 42, items 2, 3, 5, 6): enhance offers only the options it uses;
# report.json names the verb and its options (enhance's strength, batch's per-job reports); render
# refuses --texture on a mesh without UVs and words its usage errors as the other verbs; a
# staging folder left by kill -9 is removed by the next run into that folder (only one with
# matex's marker); an output written inside an output (make demo's views/) does not block
# --force; messages name what the user gave (an unwritable -o, a non-image to --compare, a text
# file named .obj, batch's counts and nameless lines; render's usage errors and --json); --progress json on an interrupt writes one
# line on stderr; a SIGTERM'd batch leaves no empty output root.
NAME=messages
. tests/lib_cli.sh
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
[ -f "$W" ] || { echo "SKIP: no demo weights ($W)"; exit 77; }
SMALL="--image-size 64 --texture-size 32 --render-size 32 --steps 1 --views 3 --candidates 8"
cp tests/data/box.obj "$T/box.obj"
has() { grep -q -- "$1" "$T/err"; }
lines() { [ "$(wc -l < "$1")" = "$2" ]; }

# item 2: enhance does not offer texture-only options
check "enhance --grid-depth-weight: usage error" [ "$(rc_of "$M" enhance "$T/box.obj" x --weights "$W" -o "$T/e0" --grid-depth-weight 0.5)" = 2 ]
check "... says it is texture's" has "--grid-depth-weight is not an option of enhance (it is one of texture)"
"$M" enhance --help > "$T/help"
check "enhance --help lists none of batch, inpaint-weight, front-back-words" sh -c "! grep -q -e '--batch' -e '--inpaint-weight' -e '--front-back-words' '$T/help'"

# item 3: the report names the verb and every option that shapes the result
check "texture runs" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/tex" $SMALL --quiet)" = 0 ]
check "enhance runs" [ "$(rc_of "$M" enhance "$T/tex/mesh.obj" "a box" --weights "$W" -o "$T/enh" $SMALL --strength 0.25 --quiet)" = 0 ]
check "enhance report: verb" grep -q '"verb":"enhance"' "$T/enh/report.json"
check "enhance report: strength" grep -q '"options":{"strength":0.25,' "$T/enh/report.json"
echo "{\"mesh\": \"box.obj\", \"prompt\": \"box\", \"name\": \"a\", \"steps\": 1, \"image_size\": 64, \"texture_size\": 32, \"render_size\": 32, \"views\": 2}" > "$T/one.jsonl"
check "batch of one job runs" [ "$(rc_of "$M" batch "$T/one.jsonl" --weights "$W" -o "$T/b1")" = 0 ]
check "batch job report: verb and options" grep -q '"verb":"texture","mesh":.*"options":{"seed":0,"steps":1,' "$T/b1/a/report.json"
check "batch says 1 job, not 1 jobs" grep -q "shard 0/1, 1 job: 1 done" "$T/out"

# item 5: render --texture on a mesh without UVs
check "render --texture, no UVs: exit 1" [ "$(rc_of "$M" render "$T/box.obj" --texture "$T/tex/texture.png" -o "$T/r0")" = 1 ]
check "... says the mesh has no UVs" has "box.obj has no UVs, so --texture"
check "... writes nothing" [ ! -e "$T/r0" ]
# a staging folder whose process was killed (-9) is removed by the next run into that folder
"$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/k" --image-size 64 --texture-size 32 --render-size 32 --steps 200 --views 3 --quiet &
pid=$!
n=0
while [ $n -lt 600 ] && ! ls -d "$T/k".partial-* > /dev/null 2>&1; do sleep 0.05; n=$((n + 1)); done
kill -9 $pid
wait $pid 2> /dev/null
check "kill -9 leaves a staging folder (the case)" [ -d "$T/k.partial-$pid" ]
mkdir "$T/k.partial-1"  # not matex's (no marker; pid 1 lives anyway): left alone
check "the next run into the folder succeeds" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/k" $SMALL --quiet)" = 0 ]
check "... and removed the dead run's staging folder" [ ! -e "$T/k.partial-$pid" ]
check "... but not a folder that is not matex's" [ -d "$T/k.partial-1" ]
# make demo's shape: a render into OUT/views, then --force over OUT
check "render into the output's views/" [ "$(rc_of "$M" render "$T/tex/mesh.glb" --views 2 --size 32 -o "$T/tex/views")" = 0 ]
check "--force over an output holding matex's views/" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/tex" $SMALL --quiet --force)" = 0 ]
check "... replaced it" [ ! -e "$T/tex/views" ] && check "... with the new output" [ -s "$T/tex/report.json" ]
mkdir -p "$T/tex/mine" && echo keep > "$T/tex/mine/a.txt"
check "--force over an output holding a user's folder: refused" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/tex" $SMALL --quiet --force)" = 1 ]
check "... and it stays" [ -s "$T/tex/mine/a.txt" ]

# item 6: messages
check "-o in an unwritable place: exit 1" [ "$(rc_of "$M" texture "$T/box.obj" "a box" --weights "$W" -o /proc/matex_out $SMALL)" = 1 ]
check "... names the output folder, not a lock" sh -c "grep -q '/proc/matex_out: cannot create the output folder' '$T/err' && ! grep -q lock '$T/err'"
check "info --compare MESH: exit 1" [ "$(rc_of "$M" info "$T/enh/texture.png" --compare "$T/box.obj")" = 1 ]
check "... says it is not an image" has "box.obj is not an image (it holds text)"
echo "just some notes" > "$T/notes.obj"
check "a text file named .obj: exit 1" [ "$(rc_of "$M" render "$T/notes.obj" -o "$T/r1")" = 1 ]
check "... says it holds no OBJ data" has "notes.obj holds no OBJ data"
cp "$T/one.jsonl" "$T/bad.jsonl" && echo "{not json" >> "$T/bad.jsonl"
check "batch with a bad line: exit 1" [ "$(rc_of "$M" batch "$T/bad.jsonl" --weights "$W" -o "$T/b2")" = 1 ]
check "... names the line without empty brackets" sh -c "grep -q 'matex batch: line 2: failed' '$T/err' && ! grep -q '()' '$T/err'"
check "render --views 0: exit 2" [ "$(rc_of "$M" render "$T/box.obj" --views 0 -o "$T/r2")" = 2 ]
check "... worded as the other verbs, with the --help hint" sh -c "grep -q \"matex render: --views must be an integer in 1..360, not '0'\" '$T/err' && grep -q 'matex render --help for usage' '$T/err'"
check "render without -o: exit 2" [ "$(rc_of "$M" render "$T/box.obj")" = 2 ] && check "... says -o is missing, with the --help hint" sh -c "grep -q 'missing -o DIR' '$T/err' && grep -q 'matex render --help' '$T/err'"
check "render --json: the summary" sh -c "'$M' render '$T/box.obj' --views 2 --size 32 -o '$T/rj' --json | grep -q '^{\"ok\":true,\"out\":\"$T/rj\",\"views\":2}\$'"
check "render --json, a usage error: exit 2" [ "$(rc_of "$M" render "$T/box.obj" --views 0 -o "$T/rj2" --json)" = 2 ]
check "... in JSON on stdout" grep -q '^{"ok":false,"error":"--views must be an integer in 1..360' "$T/out"
# --progress json, interrupted: the result line on stdout, one line on stderr
"$M" texture "$T/box.obj" "a box" --weights "$W" -o "$T/pj" --image-size 64 --texture-size 32 --render-size 32 --steps 200 --views 3 --progress json > "$T/pj.out" 2> "$T/pj.err" &
pid=$!
n=0
while [ $n -lt 600 ] && ! grep -q '"event":"step"' "$T/pj.out"; do sleep 0.05; n=$((n + 1)); done
kill -INT $pid
wait $pid
check "--progress json, SIGINT: exit 130" [ $? = 130 ]
check "... one line on stderr" lines "$T/pj.err" 1
# a batch SIGTERM'd before its first job wrote anything leaves no output root
echo "{\"mesh\": \"box.obj\", \"prompt\": \"box\", \"name\": \"s\", \"steps\": 200, \"image_size\": 64, \"texture_size\": 32, \"render_size\": 32, \"views\": 3}" > "$T/slow.jsonl"
"$M" batch "$T/slow.jsonl" --weights "$W" -o "$T/broot" > /dev/null 2> "$T/bt.err" &
pid=$!
n=0
while [ $n -lt 600 ] && ! ls -d "$T/broot/s".partial-* > /dev/null 2>&1; do sleep 0.05; n=$((n + 1)); done
kill -TERM $pid
wait $pid
check "batch, SIGTERM: exit 130" [ $? = 130 ]
check "... no empty output root left" [ ! -e "$T/broot" ]
exit $fail
