#!/bin/sh
# Builds the demo weight file: tiny random networks of the SD1.5 family (configs in
# tests/data/demo, weights by `matex gen-weights`), the real CLIP tokenizer vocabulary from
# tests/data/golden/tokenizer (MIT, see LICENSE there), assembled as a diffusers model folder
# and converted with `matex convert`. Random weights paint noise: this only exercises the whole
# pipeline. Run from the repository root.
# Both model sets carry a tiny CLIP vision tower (image_encoder.*, the IP-Adapter's image encoder:
# 32² images, patch 8, projection 24, as golden/clip_vision_tiny) and a tiny IP-Adapter for the demo
# UNet (ip_adapter.*, tests/data/demo/ip_adapter.json: image embeddings of 24, 4 tokens), written by
# gen-weights in the published file's layout.
# Also OUT_unet_only.mxw (a UNet alone) and OUT_fast.mxw (the same set plus a TAESD and a small
# LoRA converted as the LCM-LoRA: what `texture --fast` requires, not a real LCM distillation).
# usage: sh tools/scripts/make_demo_weights.sh MATEX OUT.mxw
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
mkdir -p "$DIR/taesd" "$DIR/image_encoder"
net image_encoder clip_vision.json 17 model.safetensors
net taesd taesd.json 16 diffusion_pytorch_model.safetensors
# A random TAESD decoder paints near black: its last conv gives about 0 in [0, 1] (the VAE's
# gives 0 in [-1, 1], mid grey) with little spread. That conv (decoder.layers.18: the 18 follows
# from num_decoder_blocks in taesd.json) gets bias 0.5 and weights of 1, -1, 0.5, -0.5, 1, -1, 0
# in turn (sum 0: no drift to black or white; 7 does not divide the 144 weights of a channel: the
# channels differ), so that the fast demo paints colour noise around mid grey, as the default
# demo does.
set_f32() { # file tensor 4-byte-pattern (octal escapes, little-endian floats): the tensor's bytes
    n=$(od -An -tu8 -N8 "$1" | tr -d ' ')
    off=$(head -c $((8 + n)) "$1" | tail -c "$n" |
        sed -n "s/.*\"$2\":{[^}]*\"data_offsets\":\[\([0-9]*\),\([0-9]*\)\].*/\1 \2/p")
    [ -n "$off" ] || { echo "make_demo_weights: $2 not in $1" >&2; exit 1; }
    set -- "$1" "$2" "$3" $off
    i=$4
    while [ "$i" -lt "$5" ]; do
        printf "$3"
        i=$((i + ${#3} / 4))
    done | head -c $(($5 - $4)) | dd of="$1" bs=1 seek=$((8 + n + $4)) conv=notrunc 2>/dev/null
}
T=$DIR/taesd/diffusion_pytorch_model.safetensors
set_f32 "$T" decoder.layers.18.bias '\000\000\000\077'                            # 0.5
set_f32 "$T" decoder.layers.18.weight \
    '\000\000\200\077\000\000\200\277\000\000\000\077\000\000\000\277\000\000\200\077\000\000\200\277\000\000\000\000'
"$MATEX" gen-weights "$CFG/ip_adapter.json" --seed 18 -o "$DIR/ip_adapter.safetensors"
cp tests/data/golden/tokenizer/vocab.json tests/data/golden/tokenizer/merges.txt "$DIR/tokenizer/"
cp "$CFG/scheduler_config.json" "$DIR/scheduler/scheduler_config.json"
"$MATEX" convert "$DIR" --controlnet "depth=$DIR/controlnet_depth" --controlnet "inpaint=$DIR/controlnet_inpaint" \
    --image-encoder "$DIR/image_encoder" --ip-adapter "$DIR/ip_adapter.safetensors" --dtype f32 --quiet -o "$OUT"
# A kohya-keyed LoRA of one module (time_embedding.linear_1 of the demo UNet, [128, 32], rank 1),
# every value the float of bytes 0x3c3c3c3c (about 0.0115), as safetensors: 8-byte LE header size,
# the JSON header padded with spaces, the data.
lora_file() {
    k=lora_unet_time_embedding_linear_1
    h="{\"$k.lora_down.weight\":{\"dtype\":\"F32\",\"shape\":[1,32],\"data_offsets\":[0,128]},"
    h="$h\"$k.lora_up.weight\":{\"dtype\":\"F32\",\"shape\":[128,1],\"data_offsets\":[128,640]}}"
    while [ $((${#h} % 8)) -ne 0 ]; do h="$h "; done
    n=${#h}
    {
        printf "$(printf '\\%03o\\%03o' $((n % 256)) $((n / 256)))\\0\\0\\0\\0\\0\\0"
        printf '%s' "$h"
        head -c 640 /dev/zero | tr '\0' '<'
    } > "$1"
}
lora_file "$DIR/lcm_lora.safetensors"
"$MATEX" convert "$DIR" --controlnet "depth=$DIR/controlnet_depth" --controlnet "inpaint=$DIR/controlnet_inpaint" \
    --lcm-lora "$DIR/lcm_lora.safetensors" --taesd "$DIR/taesd" --image-encoder "$DIR/image_encoder" \
    --ip-adapter "$DIR/ip_adapter.safetensors" --dtype f32 --quiet -o "${OUT%.mxw}_fast.mxw"
# A file with only a UNet: the pipeline tests check that a wrong file is refused clearly.
"$MATEX" convert "$DIR/unet" --dtype f32 --quiet -o "${OUT%.mxw}_unet_only.mxw"
