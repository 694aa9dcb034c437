#!/bin/sh
# matex info: usage errors (exit 2, worded as the other verbs': mx_cli_usage_error), mesh statistics as text and JSON against
# assets/MANIFEST.md, bad input (exit 1, message naming the file), weight-file dispatch.
NAME=info
. "$(dirname "$0")/lib_cli.sh"
A=$(data assets)

check "--help exits 0" [ "$(rc_of "$M" info --help)" = 0 ]
check "--help prints usage" grep -q "usage: matex info" "$T/out"
check "no argument exits 2" [ "$(rc_of "$M" info)" = 2 ]
check "... worded as the other verbs, with the --help hint" sh -c "grep -qx 'matex info: missing FILE' '$T/err' && grep -qx '(matex info --help for usage)' '$T/err'"
check "unknown option exits 2" [ "$(rc_of "$M" info --frobnicate "$A/spot/spot_triangulated.obj")" = 2 ]
check "... worded as the other verbs" sh -c "grep -qx 'matex info: unknown option --frobnicate' '$T/err' && grep -qx '(matex info --help for usage)' '$T/err' && [ \$(wc -l < '$T/err') = 2 ]"
check "--compare without an image exits 2" [ "$(rc_of "$M" info tests/data/box.obj --compare)" = 2 ]
check "... worded as the other verbs" grep -qx 'matex info: missing value after --compare' "$T/err"
check "two files exit 2" [ "$(rc_of "$M" info tests/data/box.obj tests/data/box.obj)" = 2 ]
check "... worded as the other verbs" grep -qx 'matex info: unexpected argument tests/data/box.obj' "$T/err"
check "--json, a usage error: exit 2" [ "$(rc_of "$M" info --json --frobnicate tests/data/box.obj)" = 2 ]
check "... in JSON on stdout" grep -qx '{"ok":false,"error":"unknown option --frobnicate"}' "$T/out"

check "spot loads" [ "$(rc_of "$M" info "$A/spot/spot_triangulated.obj")" = 0 ]
check "spot triangles" grep -q "^triangles: *5856$" "$T/out"
check "spot vertices" grep -q "^vertices: *2930$" "$T/out"
check "spot watertight" grep -q "^watertight: *yes$" "$T/out"
check "spot has uvs" grep -q "^uvs: *yes" "$T/out"

check "garment loads" [ "$(rc_of "$M" info "$A/garment_female_casual/female_casualsuit01.obj")" = 0 ]
check "garment boundary edges" grep -q "^boundary edges: *164$" "$T/out"
check "garment components" grep -q "^components: *2$" "$T/out"
check "garment open" grep -q "^watertight: *no$" "$T/out"

check "truck --json" [ "$(rc_of "$M" info --json "$A/cesium_milk_truck/CesiumMilkTruck.glb")" = 0 ]
check "truck json counts" grep -q '"vertices":3564,"triangles":3624' "$T/out"
check "truck json partial uvs" grep -q '"uvs":"partial"' "$T/out"
check "truck json topology" grep -q '"boundary_edges":8,"nonmanifold_edges":0,"components":13' "$T/out"
check "truck json materials" grep -q '"name":"wheels"' "$T/out"
check "json is one line" [ "$(wc -l < "$T/out")" = 1 ]

check "ply without uvs" [ "$(rc_of "$M" info "$A/spot_ply/spot.ply")" = 0 ]
check "ply uvs no" grep -q "^uvs: *no" "$T/out"

check "missing file exits 1" [ "$(rc_of "$M" info "$T/nowhere.obj")" = 1 ]
check "missing file named" grep -q "nowhere.obj" "$T/err"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n' > "$T/bad.obj"
check "bad index exits 1" [ "$(rc_of "$M" info "$T/bad.obj")" = 1 ]
check "bad index message" grep -q "bad.obj: face 0: vertex index 7 out of range" "$T/err"
check "bad index no stdout" [ ! -s "$T/out" ]
printf 'glTF\002\000\000\000\377\377\000\000' > "$T/trunc.glb"
check "truncated glb exits 1" [ "$(rc_of "$M" info "$T/trunc.glb")" = 1 ]
check "truncated glb message" grep -q "trunc.glb: truncated GLB" "$T/err"

# A file with the weight-file magic goes to the weight-file reader, which must reject this one.
printf 'MATEXWF\000garbage' > "$T/w.mxw"
check "weight file dispatch exits 1" [ "$(rc_of "$M" info "$T/w.mxw")" = 1 ]
check "weight file error names it" grep -q "w.mxw" "$T/err"
check "weight file --json exits 2" [ "$(rc_of "$M" info --json "$T/w.mxw")" = 2 ]
# images: size, channels and per-channel min/mean/max (what the texture tests check content with)
check "a render for info" [ "$(rc_of "$M" render tests/data/box.obj --views 2 --size 64 -o "$T/img")" = 0 ]
check "info reads an image" [ "$(rc_of "$M" info "$T/img/view_00.png")" = 0 ]
check "info gives its size" grep -q "^size: *64 x 64$" "$T/out"
check "info gives min, mean and max per channel" sh -c "grep -q '^min: *0\.[0-9]* 0\.[0-9]* 0\.[0-9]*$' '$T/out' && grep -q '^mean: ' '$T/out' && grep -q '^max: ' '$T/out'"
check "info --json of an image" [ "$(rc_of "$M" info --json "$T/img/view_00.png")" = 0 ]
check "its JSON has the size" grep -q '"width":64,"height":64,"channels":3,"min":\[' "$T/out"
check "an image compared with itself" [ "$(rc_of "$M" info "$T/img/view_00.png" --compare "$T/img/view_00.png")" = 0 ]
check "... has an infinite PSNR" grep -qx "psnr_db=inf" "$T/out"
check "against another view" [ "$(rc_of "$M" info --json "$T/img/view_00.png" --compare "$T/img/view_01.png")" = 0 ]
check "... a finite PSNR" grep -q '"psnr_db":[0-9][0-9.]*}' "$T/out"
check "images of other sizes: exit 1" [ "$(rc_of "$M" info "$T/img/view_00.png" --compare "$T/img/contact_sheet.png")" = 1 ]
check "... says the sizes must agree" grep -q "sizes must agree" "$T/err"
check "info of a folder exits 1" [ "$(rc_of "$M" info "$T/img")" = 1 ]
check "and says it is a directory" grep -q "img: is a directory" "$T/err"

# Single-file checkpoints: what they hold; a hostile one is refused.
check "checkpoint info" [ "$(rc_of "$M" info tests/fuzz/seeds/ckpt/model.ckpt)" = 0 ]
check "checkpoint container" grep -q "^container: *PyTorch zip" "$T/out"
check "checkpoint networks" grep -q "^network: *text_encoder" "$T/out"
check "checkpoint schedule" grep -q "alphas_cumprod matches" "$T/out"
check "hostile checkpoint exits 1" [ "$(rc_of "$M" info tests/fuzz/seeds/ckpt/eval.ckpt)" = 1 ]
check "hostile checkpoint message" grep -q "builtins.eval" "$T/err"

exit $fail
