#!/bin/sh
# Builds the demo weight file: tiny random networks of the SD1.5 family (configs in
# tests/data/demo, weights by `matex gen-weights`), the real CLIP tokenizer vocabulary from
# tests/data/golden/tokenizer (MIT, see LICENSE there), assembled as a diffusers model folder
# and converted with `matex convert`. Random weights paint noise: this only exercises the whole
# pipeline. Run from the repository root.
# usage: sh tools/make_demo_weights.sh MATEX OUT.mxw
set -eu
MATEX=$1
OUT=$2
CFG=tests/data/demo
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
mkdir -p "$DIR/unet" "$DIR/controlnet_depth" "$DIR/controlnet_inpaint" "$DIR/vae" "$DIR/text_encoder" \
    "$DIR/tokenizer" "$DIR/scheduler"
net() { # folder config seed weights-file-name
    cp "$CFG/$2" "$DIR/$1/config.json"
    "$MATEX" gen-weights "$DIR/$1/config.json" --seed "$3" -o "$DIR/$1/$4"
}
net unet unet.json 11 diffusion_pytorch_model.safetensors
net controlnet_depth controlnet.json 12 diffusion_pytorch_model.safetensors
net controlnet_inpaint controlnet.json 13 diffusion_pytorch_model.safetensors
net vae vae.json 14 diffusion_pytorch_model.safetensors
net text_encoder clip.json 15 model.safetensors
cp tests/data/golden/tokenizer/vocab.json tests/data/golden/tokenizer/merges.txt "$DIR/tokenizer/"
cp "$CFG/scheduler_config.json" "$DIR/scheduler/scheduler_config.json"
"$MATEX" convert "$DIR" --controlnet "depth=$DIR/controlnet_depth" --controlnet "inpaint=$DIR/controlnet_inpaint" \
    --dtype f32 --quiet -o "$OUT"
# A file with only a UNet: the pipeline tests check that a wrong file is refused clearly.
"$MATEX" convert "$DIR/unet" --dtype f32 --quiet -o "${OUT%.mxw}_unet_only.mxw"
