#!/bin/sh
# Builds a full-size SD1.5 model set with random weights (the golden-v1 rule; configs from
# tests/data/golden/sd15_*), the real CLIP vocabulary, two ControlNets (depth, inpaint), as an
# fp16 matex weight file: what the end-to-end benchmark times. ~3.6 GB, about a minute.
# With --fast, the file of `matex texture --fast` instead: the same plus a random LCM-LoRA of the
# real rank 64 in the public LCM-LoRA SD1.5 keys (gen-weights --lcm-lora), merged at convert time,
# and a random full-size TAESD (tools/bench/taesd_config.json: the config of madebyollin/taesd).
# usage: sh tools/scripts/make_sd15_weights.sh MATEX OUT.mxw [--fast]
set -eu
MATEX=$1
OUT=$2
FAST=${3:-}
G=tests/data/golden # run from the repository root
DIR=$(mktemp -d "${TMPDIR:-/tmp}/matex_sd15.XXXXXX")
trap 'rm -rf "$DIR"' EXIT
net() { # folder golden-case seed weights-file-name
    mkdir -p "$DIR/$1"
    cp "$G/$2/config.json" "$DIR/$1/config.json"
    "$MATEX" gen-weights "$DIR/$1/config.json" --seed "$3" --dtype f16 -o "$DIR/$1/$4"
}
net unet sd15_unet 1 diffusion_pytorch_model.safetensors
net controlnet_depth sd15_controlnet 2 diffusion_pytorch_model.safetensors
net controlnet_inpaint sd15_controlnet 3 diffusion_pytorch_model.safetensors
net vae sd15_vae 1 diffusion_pytorch_model.safetensors
net text_encoder sd15_clip 1 model.safetensors
mkdir -p "$DIR/tokenizer"
cp "$G/tokenizer/vocab.json" "$G/tokenizer/merges.txt" "$DIR/tokenizer/"
set --
if [ "$FAST" = --fast ]; then
    "$MATEX" gen-weights "$DIR/unet/config.json" --seed 4 --dtype f16 --lcm-lora 64 -o "$DIR/lcm_lora.safetensors"
    mkdir -p "$DIR/taesd"
    cp tools/bench/taesd_config.json "$DIR/taesd/config.json"
    "$MATEX" gen-weights "$DIR/taesd/config.json" --seed 1 --dtype f16 -o "$DIR/taesd/diffusion_pytorch_model.safetensors"
    set -- --lcm-lora "$DIR/lcm_lora.safetensors" --taesd "$DIR/taesd"
fi
"$MATEX" convert "$DIR" --controlnet "depth=$DIR/controlnet_depth" --controlnet "inpaint=$DIR/controlnet_inpaint" \
    "$@" --dtype f16 --quiet -o "$OUT"
