#!/bin/sh
# Style images on the command line (issue 26): a bad --style-image (missing, empty, not an image, too
# large) or --style-scale fails before any work with a message naming it and leaves no output folder
# (weights without the networks: test_texture_style, as every demo file now holds them). With the demo
# weights a style image changes the texture and nothing else (mesh.obj stays byte-identical), by an
# amount that grows with --style-scale (PSNR against the unstyled texture falls about 6 dB per doubling
# of the scale: IP-Adapter adds scale x its attention); scale 0 gives the same bytes as none; the same
# image given twice is that image alone up to rounding (its tokens concatenated under one softmax), two different
# images differ from either alone; report.json records them; --front-render writes front.png as
# matex's own.
NAME=style
. "$(dirname "$0")/lib_cli.sh"
W=${MATEX_DEMO_WEIGHTS:-build/demo/demo.mxw}
S=$(data assets)/spot/spot_triangulated.obj
SMALL="--image-size 64 --steps 1 --texture-size 128 --render-size 128 --candidates 12 --quiet"
O="$T/result"

: > "$T/empty.png"
echo "not a picture" > "$T/notes.png"
# a PNG that declares 10000 x 10000 pixels: refused by its header, before anything is decoded
printf '\211PNG\r\n\032\n\000\000\000\015IHDR\000\000\047\020\000\000\047\020\010\002\000\000\000' > "$T/huge.png"
# refused VERB FILE WHAT: exit 1, the message names FILE and says WHAT, nothing written
refused() {
    check "$1 --style-image $(basename "$2"): exit 1" [ "$(rc_of "$M" $1 "$S" "a cow" --weights "$W" -o "$O" $SMALL --style-image "$2")" = 1 ]
    check "... says: $3" grep -qF "$2: $3" "$T/err"
    check "... no output folder" [ ! -e "$O" ]
}
refused texture "$T/none.png" "cannot open style image: No such file or directory"
refused texture "$T/empty.png" "style image is empty (0 bytes)"
refused texture "$T/notes.png" "style image is not an image (a PNG, JPEG or TIFF file)"
refused texture "$T/huge.png" "style image of 10000x10000 pixels is too large"
refused enhance "$T/notes.png" "style image is not an image"
check "--style-scale 2.5: exit 2" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --style-scale 2.5)" = 2 ]
check "... with the valid range" grep -qF -- "--style-scale must be a number in [0, 2], not '2.5'" "$T/err"
check "--style-image '': exit 2" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --style-image "")" = 2 ]
set -- 1 2 3 4 5 6 7 8 9
many=""
for i; do many="$many --style-image $T/notes.png"; done
check "nine --style-image: exit 2" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL $many)" = 2 ]
check "... at most 8" grep -qF -- "--style-image may be given at most 8 times" "$T/err"
check "--help lists --style-image and --style-scale" sh -c "'$M' texture --help | grep -q -- '--style-image FILE' && '$M' enhance --help | grep -q -- '--style-scale S'"
check "transfer has no --style-image" [ "$(rc_of "$M" transfer "$S" "$S" -o "$O" --style-image "$T/notes.png")" = 2 ]

# with the demo weights (a tiny image encoder and IP-Adapter): what the style image changes (the
# texture, by an amount that follows the scale) and what it does not (the mesh), the report
psnr() { "$M" info "$1" --compare "$2" | sed -n 's/^psnr_db=//p'; } # "inf" when equal
below() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a ~ /^[0-9]+(\.[0-9]+)?$/ && (b == "inf" || a + 0 < b + 0)) }'; } # a (dB) < b
styled() { # styled DIR OPTIONS...: a texture run of the plain one's settings with a style
    d=$1; shift
    [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/$d" $SMALL "$@")" = 0 ]
}
check "no style image" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/plain" $SMALL --front-render)" = 0 ]
cp "$T/plain/texture.png" "$T/style.png" # the style image: the plain run's texture
ST=$T/style.png
P=$T/plain/texture.png
check "--style-image" styled styled --style-image "$ST"
check "... changes the texture (PSNR to the plain one finite)" below "$(psnr "$P" "$T/styled/texture.png")" inf
check "... and not the mesh" cmp -s "$T/plain/mesh.obj" "$T/styled/mesh.obj"
check "--style-scale 0.3" styled half --style-image "$ST" --style-scale 0.3
check "--style-scale 1.2" styled double --style-image "$ST" --style-scale 1.2
d_half=$(psnr "$P" "$T/half/texture.png") d_one=$(psnr "$P" "$T/styled/texture.png") d_two=$(psnr "$P" "$T/double/texture.png")
echo "     PSNR to the plain texture at scale 0.3 / 0.6 / 1.2: $d_half / $d_one / $d_two dB"
check "... a larger scale moves the texture farther: PSNR at 0.6 below 0.3's" below "$d_one" "$d_half"
check "... and at 1.2 below 0.6's" below "$d_two" "$d_one"
check "... doubling the scale 0.3 -> 0.6 doubles the change (PSNR falls 4 to 8 dB)" \
    awk -v a="$d_half" -v b="$d_one" 'BEGIN { exit !(a - b >= 4 && a - b <= 8) }'
check "... report: the image and its digest" grep -q '"style_images":\[{"source":"[^"]*style.png","digest":"[0-9a-f]\{16\}","width":128,"height":128}\]' "$T/styled/report.json"
check "... report: the scale" grep -q '"style_scale":0.6,' "$T/styled/report.json"
check "--style-scale 0" styled zero --style-image "$ST" --style-scale 0
check "... the same texture as no style image (PNG bytes)" cmp -s "$P" "$T/zero/texture.png"
check "... (EXR bytes)" cmp -s "$T/plain/texture.exr" "$T/zero/texture.exr"
check "one style image twice" styled twice --style-image "$ST" --style-image "$ST"
# (bytes equal where the kernels sum 2n keys as they sum n; 92 dB on avx2; a second, different image: ~50 dB)
check "... is that image alone, up to rounding (PSNR above 60 dB)" below 60 "$(psnr "$T/styled/texture.png" "$T/twice/texture.png")"
check "two style images (tokens concatenated)" styled two --style-image "$ST" --style-image "$T/plain/front.png"
check "... differ from the first alone" below "$(psnr "$T/styled/texture.png" "$T/two/texture.png")" inf
check "the second style image alone" styled front --style-image "$T/plain/front.png"
check "... the two differ from it too" below "$(psnr "$T/front/texture.png" "$T/two/texture.png")" inf
check "... both in the report" [ "$(grep -o '"digest"' "$T/two/report.json" | wc -l)" = 2 ]
check "enhance --style-image" [ "$(rc_of "$M" enhance "$T/plain/mesh.obj" "a cow" --weights "$W" -o "$T/enh" $SMALL --style-image "$ST")" = 0 ]
check "... report" grep -q '"style_scale":0.6,' "$T/enh/report.json"

check "--front-render" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --front-render)" = 0 ]
check "... front.png of the image size" sh -c "'$M' info '$O/front.png' | grep -q '^size: *64 x 64'"
check "... listed in the marker" grep -q "^front.png\$" "$O/.matex-output"
check "... --force replaces the folder holding it" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --force)" = 0 ]
check "... and without the option there is none" [ ! -e "$O/front.png" ]
exit $fail
