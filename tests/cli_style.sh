#!/bin/sh
# Style images on the command line (issue 26): a bad --style-image (missing, empty, not an image, too
# large) or --style-scale fails before any work with a message naming it and leaves no output folder
# (weights without the networks: test_texture_style, as every demo file now holds them); with the demo weights a style image changes the texture, scale 0
# gives the same bytes as none, report.json records it; --front-render writes front.png as matex's own.
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

# with the demo weights (a tiny image encoder and IP-Adapter): the style image changes the texture,
# scale 0 gives the same bytes as no style image, the report records it
check "no style image" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/plain" $SMALL --front-render)" = 0 ]
cp "$T/plain/texture.png" "$T/style.png" # the style image: the plain run's texture
ST=$T/style.png
check "--style-image" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/styled" $SMALL --style-image "$ST")" = 0 ]
check "... changes the texture" sh -c "! cmp -s '$T/plain/texture.png' '$T/styled/texture.png'"
check "... report: the image and its digest" grep -q '"style_images":\[{"source":"[^"]*style.png","digest":"[0-9a-f]\{16\}","width":128,"height":128}\]' "$T/styled/report.json"
check "... report: the scale" grep -q '"style_scale":0.6,' "$T/styled/report.json"
check "--style-scale 0" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/zero" $SMALL --style-image "$ST" --style-scale 0)" = 0 ]
check "... the same texture as no style image (PNG bytes)" cmp -s "$T/plain/texture.png" "$T/zero/texture.png"
check "... (EXR bytes)" cmp -s "$T/plain/texture.exr" "$T/zero/texture.exr"
check "two style images (tokens concatenated)" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$T/two" $SMALL --style-image "$ST" --style-image "$T/plain/front.png")" = 0 ]
check "... differ from one" sh -c "! cmp -s '$T/styled/texture.png' '$T/two/texture.png'"
check "... both in the report" [ "$(grep -o '"digest"' "$T/two/report.json" | wc -l)" = 2 ]
check "enhance --style-image" [ "$(rc_of "$M" enhance "$T/plain/mesh.obj" "a cow" --weights "$W" -o "$T/enh" $SMALL --style-image "$ST")" = 0 ]
check "... report" grep -q '"style_scale":0.6,' "$T/enh/report.json"

check "--front-render" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --front-render)" = 0 ]
check "... front.png of the image size" sh -c "'$M' info '$O/front.png' | grep -q '^size: *64 x 64'"
check "... listed in the marker" grep -q "^front.png\$" "$O/.matex-output"
check "... --force replaces the folder holding it" [ "$(rc_of "$M" texture "$S" "a cow" --weights "$W" -o "$O" $SMALL --force)" = 0 ]
check "... and without the option there is none" [ ! -e "$O/front.png" ]
exit $fail
