#!/bin/sh
# convert --ip-adapter, info and run-net unet with image_embeds from the command line: the
# published file converts beside a UNet, info names it, run-net unet writes out and
# image_tokens; without the adapter, and with a file that is not one, one clear message and no
# output. gen-weights writes an IPAdapter config in the published layout (what make demo uses).
# Parity: tests/test_nn_ip_adapter.c, tests/test_tools_run_net_pipelines.c.
NAME=ip_adapter
. "$(dirname "$0")/lib_cli.sh"
G=$(data golden)
IN=$G/ip_adapter_tiny/inputs.safetensors

check "convert unet_tiny" [ "$(rc_of "$M" convert "$G/unet_tiny" -o "$T/u.mxw" --dtype f32 --quiet)" = 0 ]
check "image_embeds without an adapter exits 1" [ "$(rc_of "$M" run-net unet --weights "$T/u.mxw" --inputs "$IN" --out "$T/o.safetensors")" = 1 ]
check "... naming the missing ip_adapter.config" grep -q "ip_adapter.config" "$T/err"
check "... and no output" [ ! -e "$T/o.safetensors" ]
check "convert --ip-adapter" [ "$(rc_of "$M" convert "$G/unet_tiny" --ip-adapter "$G/ip_adapter_tiny/ip_adapter.safetensors" -o "$T/ip.mxw" --dtype f32 --quiet)" = 0 ]
check "info names ip_adapter" sh -c "\"$M\" info '$T/ip.mxw' | grep -q '^ip_adapter  *12 '"
check "info of the adapter file" sh -c "\"$M\" info '$G/ip_adapter_tiny/ip_adapter.safetensors' | grep -q 'network: *ip_adapter'"
check "run-net unet with image_embeds" [ "$(rc_of "$M" run-net unet --weights "$T/ip.mxw" --inputs "$IN" --out "$T/o.safetensors")" = 0 ]
check "... writes image_tokens" grep -q '"image_tokens"' "$T/o.safetensors"
check "convert --ip-adapter of a missing file exits 1" [ "$(rc_of "$M" convert "$G/unet_tiny" --ip-adapter "$T/none.bin" -o "$T/x.mxw" --quiet)" = 1 ]
check "... naming it" grep -q "none.bin" "$T/err"
check "convert --ip-adapter of a UNet file exits 1" [ "$(rc_of "$M" convert "$G/unet_tiny" --ip-adapter "$G/unet_tiny/diffusion_pytorch_model.safetensors" -o "$T/x.mxw" --quiet)" = 1 ]
check "... saying it is not part of an IP-Adapter" grep -q "is not part of the SD1.5 IP-Adapter" "$T/err"
check "no output after the errors" [ ! -e "$T/x.mxw" ]
check "gen-weights of the demo adapter" [ "$(rc_of "$M" gen-weights tests/data/demo/ip_adapter.json --seed 5 -o "$T/demo_ip.safetensors")" = 0 ]
check "... in the published names" grep -q '"ip_adapter.7.to_v_ip.weight"' "$T/demo_ip.safetensors"
check "... converts with the UNet it is made for" [ "$(rc_of "$M" convert "$G/unet_tiny" --ip-adapter "$T/demo_ip.safetensors" -o "$T/d.mxw" --quiet)" = 0 ]
exit $fail
