/* CLIP's image preprocessing (clip_image.h). The resize follows Pillow's libImaging/Resample.c
 * (precompute_coeffs, normalize_coeffs_8bpc, ImagingResampleHorizontal/Vertical_8bpc,
 * ImagingResampleInner) step by step, so that the 8-bit image is PIL's; the sizes and the crop
 * follow transformers' get_resize_output_image_size and center_crop. */
#include "clip_image.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

void mx_clip_image_config_default(mx_clip_image_config *cfg) {
    *cfg = (mx_clip_image_config){.size = 224,
                                  .mean = {0.48145466f, 0.4578275f, 0.40821073f},
                                  .std = {0.26862954f, 0.26130258f, 0.27577711f}};
}

/* An integer member in 1..MX_CLIP_IMAGE_MAX_SIZE of obj (absent: keeps *v). */
static int size_member(const mx_json *obj, const char *key, int *v, const char *what, mx_status *st) {
    const mx_json *j = mx_json_get(obj, key);
    if (!j) return 0;
    double d = mx_json_num(j);
    if (mx_json_kind(j) != MX_JSON_NUM || d != floor(d) || d < 1 || d > MX_CLIP_IMAGE_MAX_SIZE)
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be an integer in [1, %d]", what, key, MX_CLIP_IMAGE_MAX_SIZE);
    *v = (int)d;
    return 0;
}

/* image_mean / image_std: 3 numbers (std positive). */
static int triple_member(const mx_json *root, const char *key, int positive, float v[3], const char *what,
                         mx_status *st) {
    const mx_json *j = mx_json_get(root, key);
    if (!j) return 0;
    if (mx_json_kind(j) != MX_JSON_ARR || mx_json_len(j) != 3)
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be 3 numbers", what, key);
    for (size_t i = 0; i < 3; i++) {
        const mx_json *e = mx_json_at(j, i);
        double d = mx_json_num(e);
        if (mx_json_kind(e) != MX_JSON_NUM || !isfinite(d) || (positive && !(d > 0)))
            return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be 3 %snumbers", what, key, positive ? "positive " : "");
        v[i] = (float)d;
    }
    return 0;
}

static int parse_processor(mx_clip_image_config *cfg, const mx_json *root, const char *what, mx_status *st) {
    if (mx_json_kind(root) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: not a JSON object", what);
    const mx_json *size = mx_json_get(root, "size"), *crop = mx_json_get(root, "crop_size");
    int crop_h = -1, crop_w = -1;
    if (mx_json_kind(size) == MX_JSON_OBJ ? size_member(size, "shortest_edge", &cfg->size, what, st)
                                          : size_member(root, "size", &cfg->size, what, st))
        return -1;
    if (mx_json_kind(crop) == MX_JSON_OBJ
            ? size_member(crop, "height", &crop_h, what, st) || size_member(crop, "width", &crop_w, what, st)
            : size_member(root, "crop_size", &crop_h, what, st))
        return -1;
    if (mx_json_kind(crop) != MX_JSON_OBJ) crop_w = crop_h;
    if ((crop_h > 0 && crop_h != cfg->size) || (crop_w > 0 && crop_w != cfg->size))
        return mx_fail(st, MX_EINPUT, "%s: crop_size %dx%d differs from the shortest edge %d (not supported)", what, crop_w,
                       crop_h, cfg->size);
    if (mx_json_num(mx_json_get(root, "resample")) != 3 && mx_json_get(root, "resample"))
        return mx_fail(st, MX_EINPUT, "%s: \"resample\" must be 3 (bicubic)", what);
    return triple_member(root, "image_mean", 0, cfg->mean, what, st) ||
                   triple_member(root, "image_std", 1, cfg->std, what, st)
               ? -1
               : 0;
}

int mx_clip_image_config_parse(mx_clip_image_config *cfg, const char *text, size_t len, const char *what,
                               mx_status *st) {
    mx_json *root = mx_json_parse(text, len, what, st);
    if (!root) return -1;
    mx_clip_image_config_default(cfg);
    int rc = parse_processor(cfg, root, what, st);
    mx_json_free(root);
    return rc;
}

/* ---- Pillow's resampling (Resample.c) ---- */

#define PRECISION_BITS (32 - 8 - 2)

/* Pillow's bicubic_filter: Keys' cubic with a = -0.5, support 2. */
static double bicubic(double x) {
    const double a = -0.5;
    if (x < 0.0) x = -x;
    if (x < 1.0) return ((a + 2.0) * x - (a + 3.0)) * x * x + 1;
    if (x < 2.0) return (((x - 5) * x + 8) * x - 4) * a;
    return 0.0;
}

/* The taps of one axis: per output sample its first input (bounds[2i]), its tap count
 * (bounds[2i + 1]) and ksize fixed-point weights (k[i · ksize ...]). */
typedef struct axis_taps {
    int ksize;
    int *bounds;
    int32_t *k;
} axis_taps;

/* precompute_coeffs + normalize_coeffs_8bpc for in_size -> out_size (box 0..in_size). */
static int axis_taps_make(axis_taps *a, int in_size, int out_size, mx_status *st) {
    double scale = (double)in_size / out_size, filterscale = scale < 1.0 ? 1.0 : scale;
    double support = 2.0 * filterscale, ss = 1.0 / filterscale;
    a->ksize = (int)ceil(support) * 2 + 1;
    a->bounds = malloc((size_t)out_size * 2 * sizeof *a->bounds);
    a->k = calloc((size_t)out_size * (size_t)a->ksize, sizeof *a->k);
    double *w = malloc((size_t)a->ksize * sizeof *w);
    if (!a->bounds || !a->k || !w) {
        free(w);
        return mx_fail(st, MX_ENOMEM, "clip image: out of memory for the resize taps");
    }
    for (int xx = 0; xx < out_size; xx++) {
        double center = (xx + 0.5) * scale, ww = 0.0;
        int xmin = (int)(center - support + 0.5), xmax = (int)(center + support + 0.5);
        if (xmin < 0) xmin = 0;
        if (xmax > in_size) xmax = in_size;
        xmax -= xmin;
        for (int x = 0; x < xmax; x++) {
            w[x] = bicubic((x + xmin - center + 0.5) * ss);
            ww += w[x];
        }
        int32_t *k = a->k + (size_t)xx * a->ksize;
        for (int x = 0; x < xmax; x++) {
            double v = ww != 0.0 ? w[x] / ww : w[x];
            k[x] = v < 0 ? (int32_t)(-0.5 + v * (1 << PRECISION_BITS)) : (int32_t)(0.5 + v * (1 << PRECISION_BITS));
        }
        a->bounds[2 * xx] = xmin;
        a->bounds[2 * xx + 1] = xmax;
    }
    free(w);
    return 0;
}

static void axis_taps_free(axis_taps *a) {
    free(a->bounds);
    free(a->k);
}

/* Pillow's clip8: the rounded fixed-point sum to 0..255. */
static uint8_t clip8(int64_t v) {
    if (v >= (int64_t)1 << (PRECISION_BITS + 8)) return 255;
    if (v <= 0) return 0;
    return (uint8_t)(v >> PRECISION_BITS);
}

/* One output value: Σ taps · src[first + i · stride] over 3 interleaved channels. */
static uint8_t tap_sum(const uint8_t *src, size_t stride, const int32_t *k, int n) {
    int64_t s = (int64_t)1 << (PRECISION_BITS - 1);
    for (int i = 0; i < n; i++) s += (int64_t)src[(size_t)i * stride] * k[i];
    return clip8(s);
}

/* RGB rows [rows, in_w, 3] -> [rows, out_w, 3]. */
static void resample_horizontal(uint8_t *out, const uint8_t *in, int rows, int in_w, int out_w, const axis_taps *t) {
    for (int y = 0; y < rows; y++)
        for (int x = 0; x < out_w; x++) {
            const uint8_t *src = in + ((size_t)y * in_w + (size_t)t->bounds[2 * x]) * 3;
            for (int ch = 0; ch < 3; ch++)
                out[((size_t)y * out_w + x) * 3 + ch] = tap_sum(src + ch, 3, t->k + (size_t)x * t->ksize, t->bounds[2 * x + 1]);
        }
}

/* RGB [.., w, 3] -> [out_h, w, 3]; the taps' first rows are relative to `first_row` of in. */
static void resample_vertical(uint8_t *out, const uint8_t *in, int first_row, int w, int out_h, const axis_taps *t) {
    size_t row = (size_t)w * 3;
    for (int y = 0; y < out_h; y++) {
        const uint8_t *src = in + (size_t)(t->bounds[2 * y] - first_row) * row;
        for (size_t i = 0; i < row; i++)
            out[(size_t)y * row + i] = tap_sum(src + i, row, t->k + (size_t)y * t->ksize, t->bounds[2 * y + 1]);
    }
}

/* ImagingResampleInner: horizontal pass over the rows the vertical taps read, then the vertical
 * pass; a pass whose size does not change is skipped. */
static int resize_rgb(const uint8_t *in, int in_w, int in_h, uint8_t *out, int out_w, int out_h, mx_status *st) {
    axis_taps h = {0}, v = {0};
    uint8_t *tmp = NULL;
    int rc = -1;
    if (axis_taps_make(&h, in_w, out_w, st) || axis_taps_make(&v, in_h, out_h, st)) goto done;
    int need_h = out_w != in_w, need_v = out_h != in_h;
    int first = v.bounds[0], last = v.bounds[2 * out_h - 2] + v.bounds[2 * out_h - 1];
    const uint8_t *rows = in;
    if (need_h && need_v) {
        if (!(tmp = malloc((size_t)(last - first) * out_w * 3))) {
            mx_fail(st, MX_ENOMEM, "clip image: out of memory");
            goto done;
        }
        resample_horizontal(tmp, in + (size_t)first * in_w * 3, last - first, in_w, out_w, &h);
        rows = tmp;
    } else if (need_h) {
        resample_horizontal(out, in, in_h, in_w, out_w, &h);
    }
    if (need_v) resample_vertical(out, rows, rows == tmp ? first : 0, out_w, out_h, &v);
    if (!need_h && !need_v) memcpy(out, in, (size_t)in_w * in_h * 3);
    rc = 0;
done:
    free(tmp);
    axis_taps_free(&h);
    axis_taps_free(&v);
    return rc;
}

/* PIL's convert("RGB") of gray, gray + alpha, RGB and RGBA pixels: gray replicated, alpha dropped. */
static void to_rgb(uint8_t *rgb, const uint8_t *px, size_t n, int channels) {
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = px + i * (size_t)channels;
        int gray = channels < 3;
        rgb[3 * i] = p[0];
        rgb[3 * i + 1] = gray ? p[0] : p[1];
        rgb[3 * i + 2] = gray ? p[0] : p[2];
    }
}

static int check_image(int w, int h, int channels, int size, mx_status *st) {
    if (w < 1 || h < 1 || w > MX_CLIP_IMAGE_MAX_SIDE || h > MX_CLIP_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "clip image: a %dx%d image (each side must be 1..%d)", w, h, MX_CLIP_IMAGE_MAX_SIDE);
    if (size < 1 || size > MX_CLIP_IMAGE_MAX_SIZE)
        return mx_fail(st, MX_EUSAGE, "clip image: size %d is not in 1..%d", size, MX_CLIP_IMAGE_MAX_SIZE);
    if (channels < 1 || channels > 4)
        return mx_fail(st, MX_EINPUT, "clip image: %d channels (1 gray, 2 gray + alpha, 3 RGB or 4 RGBA)", channels);
    return 0;
}

int mx_clip_image_resize_crop(const uint8_t *pixels, int w, int h, int channels, int size, uint8_t *rgb,
                              mx_status *st) {
    if (check_image(w, h, channels, size, st)) return -1;
    /* transformers: the shorter side becomes `size`, the longer int(size · long / short) */
    int short_side = w < h ? w : h, long_side = w < h ? h : w;
    double scaled = (double)size * long_side / short_side;
    if (scaled > MX_CLIP_IMAGE_MAX_SIDE)
        return mx_fail(st, MX_EINPUT, "clip image: a %dx%d image is too elongated for size %d", w, h, size);
    int new_long = (int)scaled, rw = w < h ? size : new_long, rh = w < h ? new_long : size;
    uint8_t *src = malloc((size_t)w * h * 3), *resized = malloc((size_t)rw * rh * 3);
    int rc = -1;
    if (!src || !resized) {
        mx_fail(st, MX_ENOMEM, "clip image: out of memory for a %dx%d image", w, h);
    } else {
        to_rgb(src, pixels, (size_t)w * h, channels);
        rc = resize_rgb(src, w, h, resized, rw, rh, st);
    }
    if (rc == 0) { /* centre crop, transformers' center_crop: top = (h - size) // 2 */
        int top = (rh - size) / 2, left = (rw - size) / 2;
        for (int y = 0; y < size; y++)
            memcpy(rgb + (size_t)y * size * 3, resized + ((size_t)(top + y) * rw + left) * 3, (size_t)size * 3);
    }
    free(src);
    free(resized);
    return rc;
}

int mx_clip_image_preprocess(const uint8_t *pixels, int w, int h, int channels, int size, const float mean[3],
                             const float std[3], float *out, mx_status *st) {
    for (int ch = 0; ch < 3; ch++)
        if (!(std[ch] > 0) || !isfinite(mean[ch]))
            return mx_fail(st, MX_EUSAGE, "clip image: std must be positive and mean finite (channel %d)", ch);
    if (check_image(w, h, channels, size, st)) return -1;
    size_t plane = (size_t)size * size;
    uint8_t *rgb = malloc(plane * 3);
    if (!rgb) return mx_fail(st, MX_ENOMEM, "clip image: out of memory");
    if (mx_clip_image_resize_crop(pixels, w, h, channels, size, rgb, st)) {
        free(rgb);
        return -1;
    }
    /* transformers: rescale (x · 1/255 in double, stored as float32), then normalize in float32 */
    for (int ch = 0; ch < 3; ch++)
        for (size_t i = 0; i < plane; i++) {
            float x = (float)(rgb[3 * i + ch] * (1.0 / 255.0));
            out[(size_t)ch * plane + i] = (x - mean[ch]) / std[ch];
        }
    free(rgb);
    return 0;
}
