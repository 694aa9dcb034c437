#!/bin/sh
# matex run-net / gen-weights: usage errors (exit 2), bad input (exit 1, one message naming the
# file and tensor, no output file), a clip run, gen-weights -> convert -> run-net round trip.
# Numerical parity of run-net is checked by tests/test_tools_run_net.c.
NAME=run_net
. "$(dirname "$0")/lib_cli.sh"
G=$(data golden)

check "run-net --help exits 0" [ "$(rc_of "$M" run-net --help)" = 0 ]
check "run-net --help prints usage" grep -q "usage: matex run-net" "$T/out"
check "run-net without arguments exits 2" [ "$(rc_of "$M" run-net)" = 2 ]
check "run-net unknown --device exits 2" [ "$(rc_of "$M" run-net unet --weights a --inputs b --out c --device tpu)" = 2 ]
check "run-net --device names the choices" grep -q "cpu, cpu-strict or cuda" "$T/err"
check "run-net --device cuda without a usable CUDA backend fails" [ "$(rc_of "$M" run-net unet --weights a --inputs b --out c --device cuda)" != 0 ]
check "... in one line that names cuda" [ "$(grep -c cuda "$T/err")" = 1 ]
check "run-net unknown NET exits 2" [ "$(rc_of "$M" run-net resnet --weights a --inputs b --out c)" = 2 ]
check "run-net bad --precision exits 2" [ "$(rc_of "$M" run-net unet --precision fp8 --weights a --inputs b --out c)" = 2 ]
check "bad --precision is named" grep -q "precision must be fp32 or bf16" "$T/err"
check "inpaint-pipeline without --steps exits 2" [ "$(rc_of "$M" run-net inpaint-pipeline --weights a --inputs b --out c)" = 2 ]
check "... and says so" grep -q "needs --steps" "$T/err"
check "img2img-pipeline with a bad --guidance exits 2" [ "$(rc_of "$M" run-net img2img-pipeline --weights a --inputs b --out c --steps 4 --guidance x)" = 2 ]
check "gen-weights --help exits 0" [ "$(rc_of "$M" gen-weights --help)" = 0 ]
check "gen-weights bad dtype exits 2" [ "$(rc_of "$M" gen-weights "$G/unet_tiny/config.json" -o "$T/x" --dtype f8)" = 2 ]

check "convert unet_tiny" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/u.mxw" --dtype f32 --quiet)" = 0 ]
# inputs of another network: the missing tensor is named, no output is written
check "missing tensor exits 1" [ "$(rc_of "$M" run-net unet --weights "$T/u.mxw" --inputs "$G/vae_tiny/inputs.safetensors" --out "$T/o.safetensors")" = 1 ]
check "missing tensor is named" grep -q "missing input tensor sample" "$T/err"
check "no output after an error" [ ! -e "$T/o.safetensors" ]
# VAE inputs to the VAE prefix of a UNet-only file: no config under that prefix
check "absent prefix exits 1" [ "$(rc_of "$M" run-net vae-decode --weights "$T/u.mxw" --inputs "$G/vae_tiny/inputs.safetensors" --out "$T/o.safetensors")" = 1 ]
check "absent prefix is named" grep -q "vae.config" "$T/err"
# wrong shape: unet_mini's text states are 48 wide, unet_tiny takes 32
if have golden/unet_mini/inputs.safetensors; then
    check "wrong shape exits 1" [ "$(rc_of "$M" run-net unet --weights "$T/u.mxw" --inputs "$(data golden/unet_mini/inputs.safetensors)" --out "$T/o.safetensors")" = 1 ]
    check "wrong shape is named" grep -q "encoder_hidden_states has shape \[2, 77, 48\]" "$T/err"
fi
check "hostile inputs file exits 1" [ "$(printf 'garbage' > "$T/bad.safetensors"; rc_of "$M" run-net unet --weights "$T/u.mxw" --inputs "$T/bad.safetensors" --out "$T/o.safetensors")" = 1 ]
check "hostile weight file exits 1" [ "$(rc_of "$M" run-net unet --weights "$T/bad.safetensors" --inputs "$G/unet_tiny/inputs.safetensors" --out "$T/o.safetensors")" = 1 ]
check "still no output" [ ! -e "$T/o.safetensors" ]

# clip through run-net
if [ "$(rc_of "$M" convert "$G/clip_tiny" -o "$T/c.mxw" --dtype f32 --quiet)" = 0 ]; then
    check "run-net clip" [ "$(rc_of "$M" run-net clip --weights "$T/c.mxw" --inputs "$G/clip_tiny/inputs.safetensors" --out "$T/c.safetensors")" = 0 ]
    check "clip output written" [ -s "$T/c.safetensors" ]
else
    echo "FAIL convert clip_tiny"; cat "$T/err"; fail=1
fi

# gen-weights -> convert -> run-net: a diffusers folder made from a config alone
mkdir -p "$T/gen"
cp "$G/unet_tiny/config.json" "$T/gen/config.json"
check "gen-weights f16" [ "$(rc_of "$M" gen-weights "$T/gen/config.json" --seed 3 -o "$T/gen/diffusion_pytorch_model.safetensors" --dtype f16)" = 0 ]
check "convert generated" [ "$(rc_of "$M" convert "$T/gen" -o "$T/g.mxw" --quiet)" = 0 ]
check "run-net on generated" [ "$(rc_of "$M" run-net unet --weights "$T/g.mxw" --inputs "$G/unet_tiny/inputs.safetensors" --out "$T/g.safetensors")" = 0 ]
# bf16 arithmetic where the CPU has it (else fp32 with a warning): runs and writes its output
check "run-net --precision bf16" [ "$(rc_of "$M" run-net unet --precision bf16 --weights "$T/g.mxw" --inputs "$G/unet_tiny/inputs.safetensors" --out "$T/g16.safetensors")" = 0 ]
check "bf16 output written" [ -s "$T/g16.safetensors" ]
check "gen-weights is deterministic" sh -c ""$M" gen-weights '$T/gen/config.json' --seed 3 -o '$T/again.safetensors' --dtype f16 2>/dev/null && cmp -s '$T/again.safetensors' '$T/gen/diffusion_pytorch_model.safetensors'"
check "gen-weights bad config exits 1" [ "$(rc_of "$M" gen-weights "$G/README.md" -o "$T/x.safetensors")" = 1 ]
check "no output for a bad config" [ ! -e "$T/x.safetensors" ]
# gen-weights --lcm-lora: a random LoRA in the LCM-LoRA SD1.5 keys, which convert --lcm-lora merges
check "gen-weights --lcm-lora" [ "$(rc_of "$M" gen-weights "$T/gen/config.json" --lcm-lora 4 -o "$T/lcm.safetensors")" = 0 ]
check "lcm-lora keys in the kohya style with alpha" grep -q "lora_unet_mid_block_attentions_0_transformer_blocks_0_attn1_to_q.alpha" "$T/lcm.safetensors"
check "convert --lcm-lora merges it" sh -c ""$M" convert '$T/gen' --lcm-lora '$T/lcm.safetensors' -o '$T/lcm.mxw' 2>&1 | grep -q 'weight(s) changed by LoRA'"
check "run-net on the merged UNet" [ "$(rc_of "$M" run-net unet --weights "$T/lcm.mxw" --inputs "$G/unet_tiny/inputs.safetensors" --out "$T/l.safetensors")" = 0 ]
check "gen-weights --lcm-lora refuses a VAE" [ "$(rc_of "$M" gen-weights "$G/vae_tiny/config.json" --lcm-lora 4 -o "$T/x.safetensors")" = 1 ]
check "gen-weights --lcm-lora 0 exits 2" [ "$(rc_of "$M" gen-weights "$T/gen/config.json" --lcm-lora 0 -o "$T/x.safetensors")" = 2 ]

# A single-file checkpoint (the tiny goldens in the LDM layout, a torch.save zip written by
# test_weights_single_file) runs the UNet and the VAE exactly as the diffusers folders do.
mkdir "$T/sf"
check "tiny single-file checkpoints written" env MX_WRITE_CKPT_TINY="$T/sf" "${BUILD:-build}/tests/test_weights_single_file"
check "single file converts" [ "$(rc_of "$M" convert "$T/sf/model.ckpt" -o "$T/sf.mxw" --dtype f32 --quiet)" = 0 ]
check "convert vae_tiny" [ "$(rc_of "$M" convert "$G/vae_tiny" -o "$T/v.mxw" --dtype f32 --quiet)" = 0 ]
for w in sf u; do rc_of "$M" run-net unet --threads 1 --weights "$T/$w.mxw" --inputs "$G/unet_tiny/inputs.safetensors" --out "$T/unet_$w.safetensors" > /dev/null; done
check "single-file UNet output = folder UNet output" cmp "$T/unet_sf.safetensors" "$T/unet_u.safetensors"
for w in sf v; do rc_of "$M" run-net vae-decode --threads 1 --weights "$T/$w.mxw" --inputs "$G/vae_tiny/inputs.safetensors" --out "$T/vae_$w.safetensors" > /dev/null; done
check "single-file VAE output = folder VAE output" cmp "$T/vae_sf.safetensors" "$T/vae_v.safetensors"
exit $fail
