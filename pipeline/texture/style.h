/* Style images: image guidance of a run (issue 26, the IP-Adapter). The images of
 * matex_options.style_images (files) and style_pixels (in memory) are checked before any work,
 * read once, encoded once per run by the CLIP vision tower (image_encoder, image_embeds) and
 * projected once by the adapter (ip_adapter, 4 tokens an image, concatenated over the images);
 * the same tokens then go to every view of every batch, and the unconditional half of guidance
 * gets the tokens of a zero embedding, as diffusers' pipelines do. report.json records each
 * image's source and digest (digest.h) and the scale. */
#ifndef MX_STYLE_H
#define MX_STYLE_H

#include <stdint.h>

#include "../../include/matex.h"
#include "../../runtime/jsonw.h"
#include "../../runtime/status.h"
#include "../geom/image.h"

struct mx_models;
struct mx_ctx;

/* A style image file larger than this, or an image of more pixels, is refused before it is read
 * (a photo of 24 Mpixel passes; the encoder sees 224 x 224 of it anyway). */
#define MX_STYLE_MAX_FILE_BYTES ((int64_t)64 << 20)
#define MX_STYLE_MAX_PIXELS ((int64_t)25000000)

typedef struct mx_style {
    int n;                                    /* style images (0: no image guidance) */
    mx_image img[MATEX_MAX_STYLE_IMAGES];     /* as read: 1, 3 or 4 channels in [0, 1] */
    const char *path[MATEX_MAX_STYLE_IMAGES]; /* the file, or NULL for an image in memory */
    char digest[MATEX_MAX_STYLE_IMAGES][32];  /* of the file's bytes, or of the pixels in memory */
    float scale;
    int ntokens;        /* image tokens of all images together */
    int dim;            /* their width (the UNet's cross-attention dim) */
    float *tokens;      /* [ntokens][dim] of the images (host) */
    float *zero_tokens; /* [ntokens][dim] of zero embeddings: the unconditional half */
} mx_style;

/* The style images of o without reading their pixels: each file exists, is a regular file, is not
 * empty, is at most MX_STYLE_MAX_FILE_BYTES, starts as a PNG, JPEG or TIFF does and (PNG, JPEG)
 * declares at most MX_STYLE_MAX_PIXELS; the images in memory have a size, pixels and 1, 3 or 4
 * channels; at most MATEX_MAX_STYLE_IMAGES in all. The message names the file. */
int mx_style_check_inputs(const matex_options *o, mx_status *st);
/* The model set can encode style images: it holds image_encoder.* and ip_adapter.* (else the
 * message names the convert options that add them). */
int mx_style_check_models(const struct mx_models *m, mx_status *st);
/* Reads the style images of o (checked first as mx_style_check_inputs) and their digests. */
int mx_style_load(mx_style *s, const matex_options *o, mx_status *st);
/* The image tokens of the loaded images, and those of zero embeddings, on the model set's networks. */
int mx_style_encode(mx_style *s, const struct mx_models *m, const struct mx_ctx *c, mx_status *st);
/* "style_images": [{"source", "digest", "width", "height"}], "style_scale" (nothing without images). */
void mx_style_report(const mx_style *s, mx_jw *w);
void mx_style_free(mx_style *s);

#endif
