#!/bin/sh
# matex convert: usage errors (exit 2), a conversion of each tiny golden network (exit 0,
# JSON summary), bad input (exit 1, one message naming the file, no output file left).
NAME=convert
. "$(dirname "$0")/lib_cli.sh"
G=$(data golden)
no_output() { [ ! -e "$T/x.mxw" ] && [ -z "$(ls "$T" | grep '\.tmp\.')" ]; }

check "--help exits 0" [ "$(rc_of "$M" convert --help)" = 0 ]
check "--help prints usage" grep -q "usage: matex convert" "$T/out"
check "no argument exits 2" [ "$(rc_of "$M" convert)" = 2 ]
check "no output exits 2" [ "$(rc_of "$M" convert "$G/unet_tiny")" = 2 ]
check "bad dtype exits 2" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/x.mxw" --dtype f8)" = 2 ]
check "unknown option exits 2" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/x.mxw" --frobnicate)" = 2 ]
check "--lora-scale without --lora exits 2" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/x.mxw" --lora-scale 2)" = 2 ]
check "bad controlnet spec exits 2" [ "$(rc_of "$M" convert -o "$T/x.mxw" --controlnet depth)" = 2 ]
check "usage errors leave no output" no_output

for net in unet_tiny controlnet_tiny vae_tiny clip_tiny; do
    check "$net converts" [ "$(rc_of "$M" convert "$G/$net" -o "$T/$net.mxw" --dtype f32 --json --quiet)" = 0 ]
    check "$net JSON summary" grep -q '"tensors": [1-9]' "$T/out"
    check "$net file written" [ -s "$T/$net.mxw" ]
done
check "named controlnets" [ "$(rc_of "$M" convert --controlnet depth="$G/controlnet_tiny" --controlnet inpaint="$G/controlnet_tiny" -o "$T/cn.mxw" --quiet --json)" = 0 ]
check "two networks" grep -q '"networks": 2' "$T/out"

check "missing folder exits 1" [ "$(rc_of "$M" convert "$T/nope" -o "$T/x.mxw")" = 1 ]
check "message names the folder" grep -q "$T/nope" "$T/err"
mkdir "$T/broken"
cp "$G/unet_tiny/config.json" "$T/broken/"
head -c 5000 "$G/unet_tiny/diffusion_pytorch_model.safetensors" > "$T/broken/diffusion_pytorch_model.safetensors"
check "truncated weights exit 1" [ "$(rc_of "$M" convert "$T/broken" -o "$T/x.mxw")" = 1 ]
check "message names the file" grep -q "broken/diffusion_pytorch_model.safetensors" "$T/err"
check "one error line" [ "$(wc -l < "$T/err")" = 1 ]
check "missing LoRA exits 1" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/x.mxw" --lora "$T/none.safetensors")" = 1 ]
# Single-file checkpoints (torch.save zips in the LDM layout: tests/fuzz/seeds/ckpt, made by
# test_weights_single_file): a model and a ControlNet file convert; a hostile pickle is refused.
S=tests/fuzz/seeds/ckpt
check "single-file model converts" [ "$(rc_of "$M" convert "$S/model.ckpt" --controlnet depth="$S/control.pth" -o "$T/sf.mxw" --quiet --json)" = 0 ]
check "single file: four networks" grep -q '"networks": 4' "$T/out"
check "single file: tokenizer from the shipped copy" sh -c "\"$M\" info \"$T/sf.mxw\" | grep -q tokenizer.vocab"
check "os.system pickle exits 1" [ "$(rc_of "$M" convert "$S/os_system.ckpt" -o "$T/x.mxw")" = 1 ]
check "os.system pickle named" grep -q "global 'os.system' is not allowed" "$T/err"
check "os.system one error line" [ "$(wc -l < "$T/err")" = 1 ]
check "bad input leaves no output" no_output
exit $fail
