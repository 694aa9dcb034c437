/* The bf16 precision policy: which layers compute in bf16 when a run's context does (--precision
 * bf16; DESIGN.md §4). Everything not named here follows the context. The one rule:
 *
 *   bf16: linear layers, attention, the 3×3 convolutions fed by a GroupNorm (the resnets' conv1
 *         and conv2, the UNet's conv_out) and the UNet's upsamplers: the bulk of the FLOPs;
 *         and, in the VAE decoder, the 3×3 convolutions of its last two up blocks (the resnets'
 *         conv1 and conv2, and the upsampler between them: 256² and 512² for a 64×64 latent,
 *         55 % of a decode's FLOPs);
 *   fp32: the other convolutions of UNet and ControlNet (conv_in, the ControlNet's conditioning
 *         embedding and zero convolutions, the resnets' 1×1 shortcuts, the downsamplers,
 *         proj_in and proj_out), and the rest of the VAE (the encoder; in the decoder conv_in,
 *         the mid block, the first up blocks, the shortcuts and conv_out);
 *   GroupNorm, LayerNorm, softmax, activations and residual adds are fp32 at every level.
 *   CLIP (text and vision towers) and TAESD follow the context.
 *
 * Why (relative L2 against the fp32 goldens): bf16 rounds both operands of a product to 8 bits
 * (~1.6e-3 per layer) and the errors of the layers add up. With every layer in bf16 the
 * ControlNet's deepest residual reached 1.29e-2 (mini) / 1.03e-2 (SD1.5), the VAE decode 2.07e-2
 * and an encode then decode 5.6e-2. In the VAE the decode moves by 2e-3 to 1e-2 for each group of
 * layers put in bf16 alone, the early ones most (measured on vae_mini: the resnets of the mid
 * block 9.6e-3, of up block 0 7.5e-3, 1 6.6e-3, 2 6.2e-3, 3 4.0e-3; its upsamplers 5.5e-3, 5.1e-3,
 * 3.3e-3; conv_out alone 2.1e-3; up blocks 1-3's resnets together 1.00e-2, with up block 1's
 * upsampler too an encode then decode 1.02e-2), so only the last two up blocks are bf16: decode
 * tiny/mini/SD1.5 7.8e-3/8.2e-3/7.5e-3 (avx512bf16 7.6e-3/8.3e-3/7.5e-3), an encode then decode
 * 8.0e-3/8.7e-3/7.9e-3 (their resnets alone: decode 6.8e-3/7.3e-3/6.9e-3), for 31 % less time per
 * decode on AMX (2 Xeon cores, 512²: 4.9 -> 3.4 s). In UNet and ControlNet the convolutions fed
 * by unnormalised activations (the residual stream) carry more error per FLOP; in fp32 they cost
 * a few % of the FLOPs. The one exception, measured: the upsamplers (full-resolution 3×3 convs, 135 GFLOP of the 1607 of a
 * 64×64 batch-2 UNet call, 0.2 s of it on 2 Zen 5 cores in fp32) move the UNet only from 5.58e-3
 * to 5.70e-3 (SD1.5), 6.10e-3 to 6.36e-3 (mini) and 6.46e-3 to 6.54e-3 (tiny) in bf16; the
 * downsamplers, 11 GFLOP, would move the ControlNet's deepest residual from 6.7e-3 to 8.1e-3;
 * proj_in, fed by a GroupNorm too, takes the ControlNet mini's mid residual from 7.2e-3 to
 * 1.002e-2 (AMX); and the fp32 layers on AMX as two of their three bf16 products (hi·hi +
 * hi(w)·lo(x): only the weights rounded to bf16) take it to 1.09e-2, an encode then decode of
 * vae_mini to 3.6e-2.
 * With this rule: UNet tiny/mini/SD1.5 6.5e-3/6.4e-3/5.7e-3, ControlNet mini/SD1.5
 * 8.9e-3/6.7e-3; CLIP, all bf16, SD1.5 6.7e-3. The upsamplers run as conv2d_up2x, whose phase
 * kernels (sums of 1 to 4 of the 3×3 taps) are rounded to bf16 once (ops/op_list.h): on
 * avx512bf16 the VAE decode mini 8.11e-3 -> 8.32e-3, SD1.5 7.5e-3 -> 7.54e-3, the UNet SD1.5
 * 5.75e-3 -> 5.77e-3. */
#ifndef MX_NN_PRECISION_H
#define MX_NN_PRECISION_H

#include "../../weights/networks.h"

/* 1 when the convolution bound at `path` (its parameter path in the network, e.g.
 * "down_blocks.0.resnets.1.conv_shortcut") runs in fp32 under a bf16 context. */
int mx_prec_conv_fp32(const char *path);

/* 1 when the 3×3 convolutions (the resnets' conv1 and conv2, the upsampler) of the VAE decoder's
 * up block `level` (0 = the first, at the latent's size) of `nlevels` compute in bf16 under a bf16
 * context, although the VAE runs in fp32 otherwise. */
int mx_prec_vae_up_block_bf16(int level, int nlevels);

/* 1 when the network of that kind (weights/networks.h: MX_NET_VAE) runs in fp32 throughout under
 * a bf16 context. A network reads it once, at load (mx_run_init_prec takes the answer). */
int mx_prec_net_fp32(const char *kind);

#endif
