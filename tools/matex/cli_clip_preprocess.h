/* `matex run-net clip-preprocess`: CLIP's image preprocessing (pipeline/nn/clip_image.h) on a
 * tensor, the parity tool of the preprocessing as run-net is of the networks. No weights. */
#ifndef MX_CLI_CLIP_PREPROCESS_H
#define MX_CLI_CLIP_PREPROCESS_H

#include "../../runtime/status.h"

/* in_path holds image_u8_hwc [H, W, C] (C 1..4; U8, or any integer-valued type in 0..255);
 * writes pixel_values [1, 3, size, size] (OpenAI CLIP's mean and std) to out_path. */
int mx_cli_clip_preprocess(const char *in_path, const char *out_path, int size, mx_status *st);

#endif
