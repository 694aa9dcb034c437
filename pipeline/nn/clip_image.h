/* CLIP's image preprocessing (transformers 4.39 CLIPImageProcessor), the input of the vision tower
 * (clip_vision.h): converted to RGB (gray replicated, alpha dropped, as PIL's convert("RGB")), the
 * shorter side resized to N with PIL's bicubic filter (Image.resize(..., BICUBIC, reducing_gap=None):
 * antialiased, support 2 × scale taps, a = -0.5, 22-bit fixed-point coefficients and an 8-bit image
 * between the horizontal and the vertical pass, exactly as Pillow's Resample.c), the longer side to
 * int(N · long / short), centre crop N×N, x / 255, (x - mean) / std per channel. Host code on host
 * arrays: it runs before the tower's input is uploaded. */
#ifndef MX_CLIP_IMAGE_H
#define MX_CLIP_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#include "../../runtime/status.h"

#define MX_CLIP_IMAGE_MAX_SIDE 65536 /* an input side; larger images are refused */
#define MX_CLIP_IMAGE_MAX_SIZE 4096  /* N */

/* The processor's settings: N and the normalisation. */
typedef struct mx_clip_image_config {
    int size;      /* shortest_edge = crop size (224 for the SD1.5 IP-Adapter's encoder) */
    float mean[3]; /* OpenAI CLIP: 0.48145466, 0.4578275, 0.40821073 */
    float std[3];  /* OpenAI CLIP: 0.26862954, 0.26130258, 0.27577711 */
} mx_clip_image_config;

/* OpenAI CLIP's values at N = 224. */
void mx_clip_image_config_default(mx_clip_image_config *cfg);
/* Parses a transformers preprocessor_config.json text: size.shortest_edge (or an int size),
 * crop_size, image_mean, image_std; absent keys keep the defaults. Refused (a message naming
 * `what` and the key): a crop that differs from the shortest edge, a resample other than bicubic
 * (3), a non-positive std. */
int mx_clip_image_config_parse(mx_clip_image_config *cfg, const char *text, size_t len, const char *what,
                               mx_status *st);

/* The 8-bit stage: pixels [h, w, channels] (row-major, channels 1 gray, 2 gray + alpha, 3 RGB,
 * 4 RGBA) -> rgb [size, size, 3], resized and centre-cropped as above. -1 with a message for an
 * empty or too large image, a size outside 1..MX_CLIP_IMAGE_MAX_SIZE, another channel count, or no
 * memory. */
int mx_clip_image_resize_crop(const uint8_t *pixels, int w, int h, int channels, int size, uint8_t *rgb,
                              mx_status *st);

/* The whole preprocessing: pixels as above -> out [3, size, size] (CHW, fp32), normalised with
 * mean[3] and std[3]. What the style image goes through before mx_clip_vision_embed_images. */
int mx_clip_image_preprocess(const uint8_t *pixels, int w, int h, int channels, int size, const float mean[3],
                             const float std[3], float *out, mx_status *st);

#endif
