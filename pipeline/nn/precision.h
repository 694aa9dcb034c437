/* The bf16 precision policy: which layers compute in bf16 when a run's context does (--precision
 * bf16; DESIGN.md §4). Everything not named here follows the context. The one rule:
 *
 *   bf16: linear layers, attention, and the convolutions whose input comes out of a GroupNorm
 *         (the resnets' conv1 and conv2, proj_in, the UNet's conv_out): the bulk of the FLOPs.
 *   fp32: the convolutions whose input is not normalised: conv_in, the ControlNet's conditioning
 *         embedding and its zero convolutions, the resnets' 1x1 shortcuts, the downsamplers and
 *         upsamplers, proj_out;
 *         the whole VAE (encoder and decoder).
 *   GroupNorm, LayerNorm, softmax, activations and residual adds are fp32 at every level.
 *
 * Why (measured against the fp32 goldens, rel. L2): bf16 rounds both operands of a product to
 * 8 bits (~1.6e-3 per layer) and the errors of all layers add up. With every layer in bf16 the
 * ControlNet's deepest residual reached 1.29e-2 (mini) and the VAE decode 2.07e-2, an encode then
 * decode 5.6e-2. In the VAE each convolution alone moves the decode by 1e-3 to 7e-3 (the early
 * ones most), so no subset of it may be bf16; it runs in fp32 (it is ~8 % of a default run's
 * FLOPs). In UNet and ControlNet the layers fed by unnormalised activations (large, growing
 * residual streams) carry the largest errors and few FLOPs (~5 %). */
#ifndef MX_NN_PRECISION_H
#define MX_NN_PRECISION_H

/* 1 when the convolution bound at `path` (its parameter path in the network, e.g.
 * "down_blocks.0.resnets.1.conv_shortcut") runs in fp32 under a bf16 context. */
int mx_prec_conv_fp32(const char *path);

/* 1 when the network runs in fp32 under a bf16 context ("vae"). */
int mx_prec_net_fp32(const char *net);

#endif
