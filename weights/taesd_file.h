/* The original TAESD files (madebyollin/taesd: taesd_encoder and taesd_decoder, .safetensors or
 * .pth), the nn.Sequential weights of taesd.py. Renamed as diffusers' convert_tiny_autoencoder
 * script does: encoder K.* -> encoder.layers.K.*, decoder K.* -> decoder.layers.(K-1).* (the
 * original decoder starts with its parameterless Clamp); the AutoencoderTiny config is made from
 * the layer sequence and the shapes. */
#ifndef MX_TAESD_FILE_H
#define MX_TAESD_FILE_H

#include "single_file.h"

/* Whether path names the original files: one of them (the other is found beside it, by name), or
 * a folder without config.json holding both. */
int mx_taesd_files_given(const char *path);

/* Opens the pair into sf: sf->src the decoder, sf->aux the encoder, one network "taesd". */
int mx_taesd_files_open(mx_single_file *sf, const char *path, mx_status *st);

#endif
