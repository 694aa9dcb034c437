/* run-net clip-preprocess (cli_clip_preprocess.h). */
#include "cli_clip_preprocess.h"

#include <math.h>
#include <stdlib.h>

#include "../../pipeline/nn/clip_image.h"
#include "../../weights/safetensors.h"

/* The 8-bit pixels of image_u8_hwc, checked: 3 dims, 1..4 channels, values integers in 0..255. */
static uint8_t *read_image(const mx_safetensors *in, int *w, int *h, int *channels, mx_status *st) {
    const mx_st_tensor *t = mx_st_find(in, "image_u8_hwc");
    if (!t) return mx_fail(st, MX_EINPUT, "%s: missing input tensor image_u8_hwc", in->path), NULL;
    if (t->ndim != 3 || t->shape[2] < 1 || t->shape[2] > 4 || t->shape[0] < 1 || t->shape[1] < 1 ||
        t->shape[0] > MX_CLIP_IMAGE_MAX_SIDE || t->shape[1] > MX_CLIP_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "%s: image_u8_hwc must be [H, W, C] with C 1..4 and sides 1..%d", in->path,
                       MX_CLIP_IMAGE_MAX_SIDE),
               NULL;
    *h = (int)t->shape[0], *w = (int)t->shape[1], *channels = (int)t->shape[2];
    size_t n = (size_t)*w * (size_t)*h * (size_t)*channels;
    float *f = mx_st_to_f32(in, t, st);
    uint8_t *px = f ? malloc(n) : NULL;
    if (f && !px) mx_fail(st, MX_ENOMEM, "%s: out of memory", in->path);
    for (size_t i = 0; px && i < n; i++) {
        if (!(f[i] >= 0 && f[i] <= 255 && f[i] == floorf(f[i]))) {
            mx_fail(st, MX_EINPUT, "%s: image_u8_hwc value %g at %zu is not an integer in 0..255", in->path, (double)f[i], i);
            free(px);
            px = NULL;
            break;
        }
        px[i] = (uint8_t)f[i];
    }
    free(f);
    return px;
}

int mx_cli_clip_preprocess(const char *in_path, const char *out_path, int size, mx_status *st) {
    mx_safetensors in;
    mx_clip_image_config cfg;
    mx_clip_image_config_default(&cfg);
    if (size < 1 || size > MX_CLIP_IMAGE_MAX_SIZE)
        return mx_fail(st, MX_EUSAGE, "clip-preprocess: --size must be in 1..%d", MX_CLIP_IMAGE_MAX_SIZE);
    if (mx_st_open(&in, in_path, st)) return -1;
    int w, h, channels, rc = -1;
    uint8_t *px = read_image(&in, &w, &h, &channels, st);
    float *pixels = px ? malloc((size_t)3 * size * size * sizeof *pixels) : NULL;
    if (px && !pixels) mx_fail(st, MX_ENOMEM, "clip-preprocess: out of memory");
    if (pixels && mx_clip_image_preprocess(px, w, h, channels, size, cfg.mean, cfg.std, pixels, st) == 0) {
        mx_st_out out = {.name = "pixel_values", .dtype = MX_ST_F32, .ndim = 4, .shape = {1, 3, size, size}, .data = pixels};
        rc = mx_st_write(out_path, &out, 1, st);
    }
    free(pixels);
    free(px);
    mx_st_close(&in);
    return rc;
}
