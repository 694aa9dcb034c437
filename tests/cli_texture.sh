#!/bin/sh
# matex texture / enhance / render / transfer on the command line: exit codes (0, 1 bad input with
# a message naming the file and no output, 2 usage), --json summary, outputs (image sizes and content
# by `matex info`, meshes with UVs, report keys). Uses the demo weights
# that `make test` builds (MATEX_DEMO_WEIGHTS).
NAME=texture
. "$(dirname "$0")/lib_cli.sh"
A=$(data assets)
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
SMALL="--image-size 64 --steps 1 --texture-size 256 --render-size 256 --candidates 12 --quiet"

# image_ok FILE W H: an image of W x H whose pixels are not one flat value (matex info: size and
# per-channel min/max); image_mean FILE: the mean over its channels, 0..1
image_ok() {
    "$M" info "$1" > "$T/img" 2> /dev/null && grep -q "^size: *$2 x $3\$" "$T/img" &&
        awk '/^min:/ { for (i = 2; i <= NF; i++) lo[i] = $i }
             /^max:/ { for (i = 2; i <= NF; i++) if ($i - lo[i] > 0.1) ok = 1 } END { exit !ok }' "$T/img"
}
image_mean() { "$M" info "$1" 2> /dev/null | awk '/^mean:/ { for (i = 2; i <= NF; i++) s += $i; print s / (NF - 1) }'; }
# mesh_ok FILE: a mesh with triangles, every face with UVs
mesh_ok() {
    "$M" info "$1" > "$T/mesh" 2> /dev/null && grep -q "^triangles: *[1-9]" "$T/mesh" &&
        grep -q "^uvs: *yes" "$T/mesh"
}
# report_ok DIR: report.json is UTF-8 and has the keys the README lists
report_ok() {
    iconv -f UTF-8 -t UTF-8 "$1/report.json" > /dev/null 2>&1 || return 1
    for k in views coverage_after stages_s work_s load_s seed weights_digest; do grep -q "\"$k\":" "$1/report.json" || return 1; done
}

check "texture --help exits 0" [ "$(rc_of "$M" texture --help)" = 0 ]
check "texture --help lists --seed" grep -q -- "--seed" "$T/out"
check "enhance --help exits 0" [ "$(rc_of "$M" enhance --help)" = 0 ]
check "missing prompt exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" --weights "$W" -o "$T/a")" = 2 ]
check "unknown option exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --frob 1)" = 2 ]
check "bad number exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --steps ten)" = 2 ]
check "--device cuda exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --device cuda)" = 2 ]
check "--device cuda names the backend it lacks" grep -q "built without that backend" "$T/err"
check "--device tpu exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --device tpu)" = 2 ]
check "steps out of range exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --steps 0)" = 2 ]
# the messages of a bad command line (issue 24 items 5, 7, 12): what is wrong, the valid values
S="$A/spot/spot_triangulated.obj"
check "an unknown option given last exits 2" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --bogus)" = 2 ]
check "... named as unknown" grep -q "unknown option --bogus" "$T/err"
check "... not as a missing value" sh -c "! grep -q 'missing value' '$T/err'"
check "a flag given a value (--fast=1) exits 2" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --fast=1)" = 2 ]
check "... says it takes none" grep -q -- "--fast takes no value (not '1')" "$T/err"
check "--steps=3 is --steps 3" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --steps=0)" = 2 ]
check "... checked as such" grep -q -- "--steps must be an integer in 1..200, not '0'" "$T/err"
check "an option of another verb exits 2" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --strength 0.3)" = 2 ]
check "... says whose it is" grep -q -- "--strength is not an option of texture (it is one of enhance)" "$T/err"
check "--seed -1 exits 2" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --seed -1)" = 2 ]
check "... with the valid range" grep -q -- "--seed must be an integer in 0..18446744073709551615, not '-1'" "$T/err"
check "transfer --background 255,0,0 exits 2" [ "$(rc_of "$M" transfer "$S" "$S" -o "$T/a" --background 255,0,0)" = 2 ]
check "... says it takes three numbers in [0, 1]" grep -qF -- "--background must be three numbers (R,G,B) in [0, 1], not '255,0,0'" "$T/err"
for size in 8 24 72 520; do # the demo UNet has 2 levels: image sizes step by 8 x 2^(2-1) = 16
    check "--image-size $size: refused before any work, exit 2" [ "$(rc_of "$M" texture "$S" x --weights "$W" -o "$T/a" --image-size $size)" = 2 ]
    check "... with the valid sizes" grep -q -- "--image-size must be a multiple of" "$T/err"
    check "... no output" [ ! -e "$T/a" ]
done
check "--image-size: the networks' step named" grep -q "for these weights" "$T/err"
check "--help generated from the table: ranges" sh -c "'$M' texture --help | grep -q -- '--steps N .*(default 10; 4 with --fast; an integer in 1..200)'"
check "bad --precision exits 2" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$W" -o "$T/a" --precision fp16)" = 2 ]
check "missing weights exits 1" [ "$(rc_of "$M" texture "$A/spot/spot_triangulated.obj" x --weights "$T/none.mxw" -o "$T/a")" = 1 ]
check "the message names the weights" grep -q "none.mxw" "$T/err"
check "missing mesh exits 1" [ "$(rc_of "$M" texture "$T/none.obj" x --weights "$W" -o "$T/a" $SMALL)" = 1 ]
check "the message names the mesh" grep -q "none.obj" "$T/err"
check "no output after a failure" [ ! -e "$T/a" ]
check "texture runs" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "a grey felt hat" --weights "$W" -o "$T/hat" --json $SMALL)" = 0 ]
check "--json summary" grep -q '"ok":true' "$T/out"
# the report names the arithmetic: by default (auto) bf16 where the CPU's bf16 products are faster
# than its fp32 ones (AMD's AVX512_BF16, Intel's AMX), fp32 elsewhere (Intel without AMX tiles)
# (the bf16 level in use, amx or avx512bf16, as --version names it: AMX also needs the kernel's leave)
want=fp32
level=$("$M" --version | sed -n 's/^cpu kernels used on this CPU: fp32 [a-z0-9_]*, bf16 \([a-z0-9_]*\).*/\1/p')
case "$level" in
amx) want=bf16 ;;
avx512bf16) grep -q AuthenticAMD /proc/cpuinfo && want=bf16 ;;
esac
check "report names the precision ($want)" grep -q "\"precision\": *\"$want\"" "$T/hat/report.json"
check "--version names auto's precision ($want)" sh -c "'$M' --version | grep -q '^precision auto on this CPU: $want\$'"
for f in texture.png texture.exr mesh.mtl; do
    check "texture wrote $f" [ -s "$T/hat/$f" ]
done
check "texture.png is 256 x 256 with content" image_ok "$T/hat/texture.png" 256 256
check "texture.exr is 256 x 256 with content" image_ok "$T/hat/texture.exr" 256 256
check "mesh.obj has triangles and UVs" mesh_ok "$T/hat/mesh.obj"
check "mesh.glb has triangles and UVs" mesh_ok "$T/hat/mesh.glb"
check "report.json has its keys" report_ok "$T/hat"
# work_s: the parts of the stages (MX_JOB_WORK_PARTS, job_report.h), each timed where it runs: a
# texture run with later views runs every one, so none may read 0
work_parts() { tr -d '\n ' < "$1/report.json" | grep -o '"work_s":{[^}]*}' | sed 's/^"work_s":{//; s/}$//' | tr ',' '\n'; }
host_parts_named() { [ "$(work_parts "$1" | grep -c '"\(render\|controls\|select\|encode_text\|encode_image\|write\)":')" = 6 ]; }
all_parts_measured() { work_parts "$1" > "$T/parts" && [ -s "$T/parts" ] && ! grep -qv ':[0-9.e-]*[1-9]' "$T/parts"; }
check "work_s has the parts of the host work" host_parts_named "$T/hat"
check "... every part measured (none 0)" all_parts_measured "$T/hat"
# --fast: refused clearly without the LCM-LoRA mark and TAESD, runs 4 LCM steps with them
WF=${MATEX_DEMO_FAST_WEIGHTS:-build/demo/demo_fast.mxw}
check "--fast without LCM/TAESD exits 1" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" x --weights "$W" -o "$T/f" --fast $SMALL)" = 1 ]
check "--fast says what it needs" grep -q -- "--fast needs .*--lcm-lora.*--taesd" "$T/err"
check "no output after --fast is refused" [ ! -e "$T/f" ]
check "--fast refusal names the weight file (not (null))" grep -q "^matex texture: $W: --fast needs" "$T/err"
check "--fast --json: the same, in the JSON" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" x --weights "$W" -o "$T/f" --fast --json $SMALL)" = 1 ]
check "... naming the weight file" grep -q "\"error\":\"$W: --fast needs" "$T/out"
check "... never (null)" sh -c "! grep -q null '$T/out' '$T/err'"
check "texture --fast runs" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$WF" -o "$T/fast" --fast --image-size 64 --texture-size 256 --render-size 256 --candidates 12)" = 0 ]
check "--fast report: 4 steps, guidance 1" grep -q '"steps":4,"fast":true,"guidance":1,' "$T/fast/report.json"
check "--fast ran the LCM timesteps" grep -q "step 4/4 (t=259)" "$T/err"
# the fast demo weights paint colour noise around mid grey, as the default ones (they painted
# near black: mean 0.23 on this mesh before tools/scripts/make_demo_weights.sh set TAESD's last conv)
fast_mean=$(image_mean "$T/fast/texture.png")
echo "fast demo texture mean: $fast_mean"
check "--fast texture has content" image_ok "$T/fast/texture.png" 256 256
check "--fast texture is not near black" awk "BEGIN { exit !($fast_mean > 0.35 && $fast_mean < 0.65) }"
# enhance --fast: LCM at the SDEdit strength (0.5 of 4 steps: the last 2), TAESD encoder and decoder
check "enhance --fast runs" [ "$(rc_of "$M" enhance "$T/hat/mesh.obj" "a blue hat" --strength 0.5 --views 3 --weights "$WF" -o "$T/hatf" --fast --image-size 64 --texture-size 256 --render-size 256 --candidates 12)" = 0 ]
check "enhance --fast ran the last 2 LCM timesteps" sh -c "grep -q 'step 1/2 (t=499)' '$T/err' && grep -q 'step 2/2 (t=259)' '$T/err'"
check "enhance --fast wrote a textured mesh.glb" mesh_ok "$T/hatf/mesh.glb"
check "enhance --fast texture has content" image_ok "$T/hatf/texture.png" 256 256
check "enhance --fast without LCM/TAESD exits 1" [ "$(rc_of "$M" enhance "$T/hat/mesh.obj" x --weights "$W" -o "$T/f" --fast $SMALL)" = 1 ]
check "enhance runs" [ "$(rc_of "$M" enhance "$T/hat/mesh.obj" "a blue hat" --strength 0.5 --views 3 --weights "$W" -o "$T/hat2" $SMALL)" = 0 ]
check "enhance wrote a textured mesh.glb" mesh_ok "$T/hat2/mesh.glb"
check "enhance texture has content" image_ok "$T/hat2/texture.png" 256 256
check "enhance report has its keys" report_ok "$T/hat2"
check "bad strength exits 2" [ "$(rc_of "$M" enhance "$T/hat/mesh.obj" --strength 2 --weights "$W" -o "$T/b")" = 2 ]
check "render runs" [ "$(rc_of "$M" render "$T/hat/mesh.glb" --views 4 --size 128 -o "$T/render")" = 0 ]
check "render wrote a contact sheet with content" image_ok "$T/render/contact_sheet.png" 128 128
check "render wrote 4 views of 128 x 128" sh -c "ls '$T/render'/view_0[0-3].png | wc -l | grep -qx 4"
check "render view 0 has content" image_ok "$T/render/view_00.png" 128 128
check "transfer runs" [ "$(rc_of "$M" transfer "$T/hat/mesh.obj" "$A/fedora_hat/fedora.obj" --size 256 -o "$T/tr")" = 0 ]
check "transfer wrote a textured mesh.glb" mesh_ok "$T/tr/mesh.glb"
check "transfer texture has content" image_ok "$T/tr/texture.png" 256 256
# prompts (issue 24 item 9): bytes that are not UTF-8 reach report.json as \ufffd, valid JSON text
check "a prompt that is not UTF-8 runs" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "$(printf 'a \377\376 hat')" --weights "$W" -o "$T/utf" $SMALL --views 2)" = 0 ]
check "its report is UTF-8 with the bytes escaped" sh -c "iconv -f UTF-8 -t UTF-8 '$T/utf/report.json' > /dev/null && grep -q 'a \\\\ufffd\\\\ufffd hat' '$T/utf/report.json'"
# a long prompt: the warning counts what matex tokenize counts, and quotes a little of it
long=""
for i in $(seq 1 500); do long="$long word$((i % 37))"; done
"$M" tokenize --weights "$W" --json "$long" > "$T/tok" 2> /dev/null
tok_dropped=$(sed -n 's/.*"dropped": \([0-9]*\).*/\1/p' "$T/tok")
check "a long prompt runs" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "$long" --weights "$W" -o "$T/long" ${SMALL% --quiet} --views 2)" = 0 ]
check "its warning counts $tok_dropped dropped tokens, as tokenize" grep -q "prompt longer than the 75 tokens CLIP reads: $tok_dropped tokens dropped" "$T/err"
check "the warning is one short line" sh -c "[ \$(grep -c 'tokens dropped' '$T/err') = 1 ] && [ \$(grep 'tokens dropped' '$T/err' | wc -c) -lt 200 ]"
# transfer times its backprojection like texture does (issue 24 item 12: work_s.backproject was 0)
check "transfer reports its backprojection time" grep -q '"backproject":[0-9.e-]*[1-9]' "$T/tr/report.json"
check "transfer reports both coverages" grep -q '"candidate_coverage":' "$T/tr/report.json"
# a render coarser than the texture leaves texels unseen: a warning says so (issue 24 item 13)
check "coarse render runs" [ "$(rc_of "$M" texture "$A/fedora_hat/fedora.obj" "a hat" --weights "$W" -o "$T/coarse" --views 2 --image-size 64 --steps 1 --texture-size 256 --render-size 128 --candidates 12)" = 0 ]
check "coarse render warns" grep -q "render size 128 is below the texture size 256" "$T/err"
check "the uv fill prints progress" grep -q "uv fill: texture 1/1" "$T/err"
exit $fail
