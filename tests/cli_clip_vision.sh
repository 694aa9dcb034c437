#!/bin/sh
# The IP-Adapter's image encoder on the command line: convert --image-encoder (alone, and a single
# network folder), info names it, run-net clip-vision and clip-preprocess run and refuse bad input
# (exit 1 or 2, one message, no output file). Their numbers: tests/test_tools_run_net.c.
NAME=clip_vision
. "$(dirname "$0")/lib_cli.sh"
G=$(data golden)
CV="$G/clip_vision_tiny"
PRE="$G/clip_image_preprocess_tiny/inputs.safetensors"

check "convert --image-encoder" [ "$(rc_of "$M" convert --image-encoder "$CV" -o "$T/cv.mxw" --quiet)" = 0 ]
check "info names the network" sh -c "\"$M\" info '$T/cv.mxw' | grep -q '^image_encoder  *40 '"
check "the config is stored" sh -c "\"$M\" info '$T/cv.mxw' | grep -q 'image_encoder.config'"
check "convert of the folder alone" [ "$(rc_of "$M" convert "$CV" -o "$T/cv2.mxw" --quiet)" = 0 ]
check "... holds the same network" sh -c "\"$M\" info '$T/cv2.mxw' | grep -q '^image_encoder  *40 '"
mkdir -p "$T/ie"
cp "$CV/config.json" "$CV/model.safetensors" "$T/ie/"
cp "$G/clip_image_preprocess_tiny/processor_config.json" "$T/ie/preprocessor_config.json"
check "convert --image-encoder with a preprocessor_config.json" [ "$(rc_of "$M" convert --image-encoder "$T/ie" -o "$T/ie.mxw" --quiet)" = 0 ]
check "... stores it as image_encoder.processor" sh -c "\"$M\" info '$T/ie.mxw' | grep -q 'image_encoder.processor'"
check "--image-encoder of a UNet folder exits 1" [ "$(rc_of "$M" convert --image-encoder "$G/unet_tiny" -o "$T/bad.mxw")" = 1 ]
check "... naming what it holds" grep -q "holds a unet, expected a image_encoder" "$T/err"
check "... and writes nothing" [ ! -e "$T/bad.mxw" ]
check "convert --help names the option" sh -c "\"$M\" convert --help | grep -q -- '--image-encoder DIR'"

check "run-net clip-vision" [ "$(rc_of "$M" run-net clip-vision --weights "$T/cv.mxw" --inputs "$CV/inputs.safetensors" --out "$T/o.safetensors")" = 0 ]
check "... writes its output" [ -s "$T/o.safetensors" ]
check "run-net clip-vision on a file without it exits 1" [ "$(rc_of "$M" run-net clip-vision --weights "$T/cv.mxw" --prefix vae --inputs "$CV/inputs.safetensors" --out "$T/n.safetensors")" = 1 ]
check "... naming the missing config" grep -q "vae.config" "$T/err"
check "run-net clip-vision with the preprocessing's inputs exits 1" [ "$(rc_of "$M" run-net clip-vision --weights "$T/cv.mxw" --inputs "$PRE" --out "$T/n.safetensors")" = 1 ]
check "... naming pixel_values" grep -q "missing input tensor pixel_values" "$T/err"
check "... and writes nothing" [ ! -e "$T/n.safetensors" ]

check "run-net clip-preprocess" [ "$(rc_of "$M" run-net clip-preprocess --size 32 --inputs "$PRE" --out "$T/p.safetensors")" = 0 ]
check "... writes pixel_values" [ -s "$T/p.safetensors" ]
check "run-net clip-preprocess at the default 224" [ "$(rc_of "$M" run-net clip-preprocess --inputs "$PRE" --out "$T/p224.safetensors")" = 0 ]
check "... is 224 on a side" [ "$(stat -c %s "$T/p224.safetensors")" -gt $((3 * 224 * 224 * 4)) ]
check "the tower takes what the preprocessing gives" [ "$(rc_of "$M" run-net clip-vision --weights "$T/cv.mxw" --inputs "$T/p.safetensors" --out "$T/e.safetensors")" = 0 ]
check "clip-preprocess --size 0 exits 2" [ "$(rc_of "$M" run-net clip-preprocess --size 0 --inputs "$PRE" --out "$T/n.safetensors")" = 2 ]
check "clip-preprocess without --out exits 2" [ "$(rc_of "$M" run-net clip-preprocess --inputs "$PRE")" = 2 ]
check "clip-preprocess of another tensor file exits 1" [ "$(rc_of "$M" run-net clip-preprocess --inputs "$CV/inputs.safetensors" --out "$T/n.safetensors")" = 1 ]
check "... naming image_u8_hwc" grep -q "missing input tensor image_u8_hwc" "$T/err"
check "clip-preprocess of a garbage file exits 1" [ "$(printf garbage > "$T/g.safetensors"; rc_of "$M" run-net clip-preprocess --inputs "$T/g.safetensors" --out "$T/n.safetensors")" = 1 ]
check "still no output" [ ! -e "$T/n.safetensors" ]
exit $fail
