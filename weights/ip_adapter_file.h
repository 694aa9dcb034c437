/* The published IP-Adapter file (h94/IP-Adapter models/ip-adapter_sd15.safetensors, or the .bin of
 * the original repository: a PyTorch zip whose pickle is {"image_proj": {...}, "ip_adapter":
 * {...}}, its two dicts flattened with dots by the pickle reader). Tensors image_proj.proj.*,
 * image_proj.norm.* and ip_adapter.{1,3,5,...}.to_k_ip.weight / to_v_ip.weight (one pair per
 * cross-attention layer of the UNet, numbered over diffusers' unet.attn_processors). They become
 * network "ip_adapter" with names image_proj.* and {1,3,5,...}.to_{k,v}_ip.weight and the config
 * pipeline/nn/ip_adapter.h reads, made from the shapes. Anything else (a "Plus" or FaceID adapter,
 * a gap in the numbering, a shape that does not fit) is refused by name. */
#ifndef MX_IP_ADAPTER_FILE_H
#define MX_IP_ADAPTER_FILE_H

#include "single_file.h"

/* The published name of the network's parameter `name` ("1.to_k_ip.weight" ->
 * "ip_adapter.1.to_k_ip.weight"; image_proj.* as it is): what gen-weights writes for an IPAdapter
 * config, so that its file converts like the published one. */
void mx_ip_adapter_published_name(const char *name, char *buf, size_t cap);

/* Opens the file into sf: one network "ip_adapter". */
int mx_ip_adapter_file_open(mx_single_file *sf, const char *path, mx_status *st);

/* Checks the adapter's config (as mx_ip_adapter_file_open makes it) against a UNet2DConditionModel
 * config: one layer per cross-attention of the UNet, of its width, over its cross_attention_dim.
 * `path` (the adapter file) names the problem. */
int mx_ip_adapter_file_check_unet(const char *adapter_config, const char *unet_config, const char *path,
                                  mx_status *st);

#endif
