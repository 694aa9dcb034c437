/* CLIP's image preprocessing (pipeline/nn/clip_image.h):
 * - golden/clip_image_preprocess_tiny (transformers' CLIPImageProcessor, PIL's bicubic): the 8-bit
 *   image within 1/255 of PIL's, the normalised pixel_values within (1/255)/std;
 * - awkward sizes (odd, 1 pixel, upscaling, elongated, no resize, downscaling by a large factor)
 *   against a straightforward double-precision reference of the same filter (every input tap,
 *   the 8-bit image between the passes), within 1/255;
 * - gray, gray + alpha and RGBA give what their RGB gives; the processor config; bad input. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/clip_image.h"
#include "nn_golden.h"

#define CASE "clip_image_preprocess_tiny"

/* ---- the reference: PIL's filter written out directly, in double ---- */

static double cubic(double x) { /* Keys, a = -0.5 */
    x = fabs(x);
    if (x < 1) return (1.5 * x - 2.5) * x * x + 1;
    if (x < 2) return ((-0.5 * x + 2.5) * x - 4) * x + 2;
    return 0;
}

static uint8_t round8(double v) { return v <= 0 ? 0 : v >= 255 ? 255 : (uint8_t)floor(v + 0.5); }

/* Output sample o of an axis in -> out: Σ_i cubic((i + 0.5 - centre) / fs) · x(i) over every
 * input i, divided by the sum of the weights. */
static double ref_sample(const uint8_t *x, size_t stride, int in, int out, int o) {
    double scale = (double)in / out, fs = scale < 1 ? 1 : scale, centre = (o + 0.5) * scale, s = 0, ws = 0;
    for (int i = 0; i < in; i++) {
        double w = cubic((i + 0.5 - centre) / fs);
        s += w * x[(size_t)i * stride];
        ws += w;
    }
    return s / ws;
}

/* rgb [h, w, 3] -> [oh, ow, 3]: the horizontal pass, 8 bits, the vertical pass, 8 bits (a pass
 * that keeps its size copies, as PIL). */
static void ref_resize(const uint8_t *in, int w, int h, uint8_t *out, int ow, int oh) {
    uint8_t *tmp = malloc((size_t)ow * h * 3);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < ow; x++)
            for (int c = 0; c < 3; c++)
                tmp[((size_t)y * ow + x) * 3 + c] =
                    ow == w ? in[((size_t)y * w + x) * 3 + c] : round8(ref_sample(in + (size_t)y * w * 3 + c, 3, w, ow, x));
    for (int y = 0; y < oh; y++)
        for (int x = 0; x < ow; x++)
            for (int c = 0; c < 3; c++)
                out[((size_t)y * ow + x) * 3 + c] =
                    oh == h ? tmp[((size_t)y * ow + x) * 3 + c] : round8(ref_sample(tmp + (size_t)x * 3 + c, (size_t)ow * 3, h, oh, y));
    free(tmp);
}

/* The processor of the reference: short side to n, long to int(n · long / short), centre crop. */
static void ref_resize_crop(const uint8_t *rgb, int w, int h, int n, uint8_t *out) {
    int sw = w < h ? n : (int)((double)n * w / h), sh = w < h ? (int)((double)n * h / w) : n;
    uint8_t *r = malloc((size_t)sw * sh * 3);
    ref_resize(rgb, w, h, r, sw, sh);
    int top = (sh - n) / 2, left = (sw - n) / 2;
    for (int y = 0; y < n; y++) memcpy(out + (size_t)y * n * 3, r + ((size_t)(top + y) * sw + left) * 3, (size_t)n * 3);
    free(r);
}

/* Largest difference in 8-bit levels. */
static int max_level_diff(const uint8_t *a, const uint8_t *b, size_t n) {
    int m = 0;
    for (size_t i = 0; i < n; i++) {
        int d = abs((int)a[i] - (int)b[i]);
        if (d > m) m = d;
    }
    return m;
}

/* A deterministic test image with edges and gradients (channels 1..4). */
static uint8_t *pattern(int w, int h, int channels, unsigned seed) {
    uint8_t *p = malloc((size_t)w * h * channels);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < channels; c++) {
                seed = seed * 1103515245u + 12345u;
                int v = ((x * 37 + y * 11 + c * 50) % 256 + (int)((seed >> 16) % 64)) % 256;
                if ((x / 3 + y / 2) % 2) v = 255 - v;
                p[((size_t)y * w + x) * channels + c] = (uint8_t)v;
            }
    return p;
}

static void test_golden(void) {
    mx_safetensors in, out;
    if (!golden_have(CASE, "inputs.safetensors") || golden_open(&in, CASE, "inputs.safetensors")) return;
    if (golden_open(&out, CASE, "outputs.safetensors")) {
        mx_st_close(&in);
        CHECK(0);
        return;
    }
    const mx_st_tensor *t = mx_st_find(&in, "image_u8_hwc");
    CHECK(t && t->dtype == MX_ST_U8 && t->ndim == 3 && t->shape[2] == 3);
    size_t nwant = 0;
    float *want = golden_f32(&out, "pixel_values", &nwant);
    size_t len;
    char *text = golden_text(CASE, "processor_config.json", &len);
    mx_clip_image_config cfg;
    mx_status st = {0};
    CHECK(text && mx_clip_image_config_parse(&cfg, text, len, "processor_config.json", &st) == 0 && cfg.size == 32);
    if (t && want && text && t->ndim == 3 && nwant == (size_t)3 * cfg.size * cfg.size) {
        int h = (int)t->shape[0], w = (int)t->shape[1], n = cfg.size;
        size_t plane = (size_t)n * n;
        float *got = malloc(3 * plane * sizeof(float));
        uint8_t *rgb = malloc(3 * plane), *theirs = malloc(3 * plane), *ref = malloc(3 * plane);
        CHECK(mx_clip_image_preprocess(t->data, w, h, 3, n, cfg.mean, cfg.std, got, &st) == 0);
        CHECK(mx_clip_image_resize_crop(t->data, w, h, 3, n, rgb, &st) == 0);
        double worst = 0, worst_norm = 0;
        for (int c = 0; c < 3; c++)
            for (size_t i = 0; i < plane; i++) { /* PIL's 8-bit value back from the normalised one */
                double v = ((double)want[c * plane + i] * cfg.std[c] + cfg.mean[c]) * 255.0;
                theirs[3 * i + c] = round8(v);
                worst = fmax(worst, fabs(v - rgb[3 * i + c]));
                worst_norm = fmax(worst_norm, fabs((double)got[c * plane + i] - want[c * plane + i]) * cfg.std[c] * 255.0);
            }
        ref_resize_crop(t->data, w, h, n, ref);
        printf("golden %dx%d -> %d: max |ours - PIL| = %.4f levels (normalised: %.4f), reference vs PIL %d\n", w, h, n,
               worst, worst_norm, max_level_diff(ref, theirs, 3 * plane));
        CHECK(worst <= 1.0 + 1e-3 && worst_norm <= 1.0 + 1e-3);
        free(got);
        free(rgb);
        free(theirs);
        free(ref);
    } else {
        CHECK(0);
    }
    free(want);
    free(text);
    mx_st_close(&in);
    mx_st_close(&out);
}

/* mx_clip_image_resize_crop on a w×h RGB pattern against the reference, within one level. */
static void check_size(int w, int h, int n) {
    uint8_t *img = pattern(w, h, 3, (unsigned)(w * 131 + h)), *got = malloc((size_t)n * n * 3), *ref = malloc((size_t)n * n * 3);
    mx_status st = {0};
    int ok = mx_clip_image_resize_crop(img, w, h, 3, n, got, &st) == 0;
    if (!ok) fprintf(stderr, "%dx%d -> %d: %s\n", w, h, n, st.msg);
    CHECK(ok);
    if (ok) {
        ref_resize_crop(img, w, h, n, ref);
        int d = max_level_diff(got, ref, (size_t)n * n * 3);
        printf("%5dx%-5d -> %3d: max difference to the reference %d level(s)\n", w, h, n, d);
        CHECK(d <= 1);
    }
    free(img);
    free(got);
    free(ref);
}

static void test_sizes(void) {
    check_size(13, 5, 7);     /* odd, downscale */
    check_size(1, 1, 4);      /* one pixel, upscaled */
    check_size(1, 7, 3);      /* one column: the long side grows to 21, cropped */
    check_size(5, 9, 11);     /* upscaling both */
    check_size(300, 2, 16);   /* elongated: 2400 wide, cropped */
    check_size(16, 20, 16);   /* short side already N: no resize, crop only */
    check_size(20, 16, 16);
    check_size(997, 613, 24); /* a large factor: many taps */
    check_size(64, 48, 32);   /* the golden's shape */
    check_size(224, 224, 224);
}

/* Gray, gray + alpha and RGBA preprocess as the RGB image PIL's convert("RGB") makes of them. */
static void test_channels(void) {
    const int w = 19, h = 11, n = 8;
    float mean[3] = {0.5f, 0.25f, 0.125f}, sd[3] = {0.5f, 0.25f, 2.0f};
    float *want = malloc((size_t)3 * n * n * sizeof(float)), *got = malloc((size_t)3 * n * n * sizeof(float));
    uint8_t *rgb = malloc((size_t)w * h * 3);
    mx_status st = {0};
    for (int channels = 1; channels <= 4; channels++) {
        uint8_t *img = pattern(w, h, channels, 7u);
        for (int i = 0; i < w * h; i++)
            for (int c = 0; c < 3; c++) rgb[3 * i + c] = img[i * channels + (channels < 3 ? 0 : c)];
        CHECK(mx_clip_image_preprocess(rgb, w, h, 3, n, mean, sd, want, &st) == 0);
        CHECK(mx_clip_image_preprocess(img, w, h, channels, n, mean, sd, got, &st) == 0);
        char label[48];
        snprintf(label, sizeof label, "%d channel(s) as RGB", channels);
        mx_check_close(label, got, want, (size_t)3 * n * n, 0);
        free(img);
    }
    /* the normalisation itself: (x / 255 - mean) / std */
    uint8_t white[3] = {255, 255, 255};
    CHECK(mx_clip_image_preprocess(white, 1, 1, 3, 1, mean, sd, got, &st) == 0);
    CHECK(got[0] == 1.0f && got[1] == 3.0f && got[2] == 0.4375f);
    free(want);
    free(got);
    free(rgb);
}

static void expect_error(int w, int h, int channels, int n, const char *needle) {
    uint8_t px[16] = {0};
    uint8_t out[3 * 16];
    mx_status st = {0};
    int rc = mx_clip_image_resize_crop(px, w, h, channels, n, out, &st);
    CHECK(rc != 0 && strstr(st.msg, needle));
    if (rc == 0 || !strstr(st.msg, needle)) fprintf(stderr, "%dx%d c%d n%d: '%s'\n", w, h, channels, n, st.msg);
}

static void test_errors_and_config(void) {
    expect_error(0, 4, 3, 2, "0x4 image");
    expect_error(4, -1, 3, 2, "4x-1 image");
    expect_error(2, 2, 5, 2, "5 channels");
    expect_error(2, 2, 3, 0, "size 0");
    expect_error(65536, 1, 1, 4, "too elongated");
    float mean[3] = {0, 0, 0}, zero_std[3] = {1, 0, 1}, out[3];
    uint8_t px[3] = {1, 2, 3};
    mx_status st = {0};
    CHECK(mx_clip_image_preprocess(px, 1, 1, 3, 1, mean, zero_std, out, &st) != 0 && strstr(st.msg, "std"));
    mx_clip_image_config cfg;
    mx_clip_image_config_default(&cfg);
    CHECK(cfg.size == 224 && cfg.mean[0] == 0.48145466f && cfg.std[2] == 0.27577711f);
    const char *int_size = "{\"size\": 336, \"crop_size\": 336, \"image_std\": [0.5, 0.5, 0.5]}";
    CHECK(mx_clip_image_config_parse(&cfg, int_size, strlen(int_size), "p.json", &st) == 0 && cfg.size == 336 &&
          cfg.std[1] == 0.5f && cfg.mean[1] == 0.4578275f);
    const char *bad[] = {"{\"size\": {\"shortest_edge\": 256}, \"crop_size\": {\"height\": 224, \"width\": 224}}",
                         "{\"resample\": 2}", "{\"image_std\": [1, 0, 1]}", "{\"image_mean\": [1, 2]}", "[]"};
    const char *needles[] = {"crop_size", "resample", "image_std", "image_mean", "JSON object"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        int rc = mx_clip_image_config_parse(&cfg, bad[i], strlen(bad[i]), "p.json", &st);
        CHECK(rc != 0 && strstr(st.msg, "p.json") && strstr(st.msg, needles[i]));
        if (rc == 0 || !strstr(st.msg, needles[i])) fprintf(stderr, "%s: '%s'\n", bad[i], st.msg);
    }
}

int main(void) {
    test_golden();
    test_sizes();
    test_channels();
    test_errors_and_config();
    return mx_test_finish("test_nn_clip_image");
}
