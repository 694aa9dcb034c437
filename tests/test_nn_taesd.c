/* AutoencoderTiny (TAESD) against the golden vectors of golden/taesd (MATEX_TESTDATA; the public TAESD
 * architecture, random weights): encode(image).latents and decode(latents).sample, fp32 weights
 * (rel. L2 <= 1e-4) and fp16 weights widened (<= 1e-2 against the fp32 outputs: the weights
 * themselves differ). taesd_tiny (no outputs shipped): batch independence and the config checks. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/taesd.h"
#include "nn_golden.h"

typedef struct taesd_case {
    golden_net n;
    mx_taesd *t;
    mx_taesd_config cfg;
} taesd_case;

static int load_taesd(taesd_case *k, const mx_ctx *c, const char *net, const char *wfile) {
    memset(k, 0, sizeof *k);
    if (golden_net_load(&k->n, c, net, wfile, "taesd")) return -1;
    k->t = k->n.net;
    k->cfg = *mx_taesd_cfg(k->t);
    return 0;
}

static void free_taesd(taesd_case *k) { golden_net_free(&k->n); }

/* One network call on the test device: input uploaded, arena on the backend, output fetched. */
static int run(const mx_ctx *c, const mx_taesd *t, int dec, const float *in, int B, int H, int W, float *out) {
    mx_status st;
    size_t bytes, f = (size_t)mx_taesd_factor(t);
    size_t nin = (size_t)B * (dec ? 4 : 3) * H * W, nout = dec ? (size_t)B * 3 * H * W * f * f : (size_t)B * 4 * (H / f) * (W / f);
    mx_arena a;
    if (dec ? mx_taesd_decode_arena_bytes(t, B, H, W, &bytes, &st) : mx_taesd_encode_arena_bytes(t, B, H, W, &bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    golden_arena(c, &a, bytes);
    float *din = golden_dev(c, in, nin), *dout = golden_dev_alloc(c, nout);
    int rc = dec ? mx_taesd_decode(c, t, din, B, H, W, dout, &a, &st) : mx_taesd_encode(c, t, din, B, H, W, dout, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, out, dout, nout)) rc = -1;
    mx_dev_free(c, din);
    mx_arena_destroy(&a);
    return rc;
}

static int encode(const mx_ctx *c, const mx_taesd *t, const float *img, int B, int H, int W, float *lat) {
    return run(c, t, 0, img, B, H, W, lat);
}

static int decode(const mx_ctx *c, const mx_taesd *t, const float *lat, int B, int h, int w, float *img) {
    return run(c, t, 1, lat, B, h, w, img);
}

static void check_golden(const mx_ctx *c, const char *wfile, double bound) {
    taesd_case k;
    mx_safetensors in, out;
    if (!golden_have("taesd", wfile) || !golden_have("taesd", "outputs.safetensors")) return; /* outside data */
    CHECK(load_taesd(&k, c, "taesd", wfile) == 0);
    CHECK(golden_open(&in, "taesd", "inputs.safetensors") == 0);
    CHECK(golden_open(&out, "taesd", "outputs.safetensors") == 0);
    if (!k.t) return;
    size_t n_enc, n_dec;
    float *img = golden_f32(&in, "image", NULL), *lat = golden_f32(&in, "latents", NULL);
    float *want_enc = golden_f32(&out, "latents_enc", &n_enc), *want_dec = golden_f32(&out, "image_dec", &n_dec);
    const mx_st_tensor *ti = mx_st_find(&in, "image"), *tl = mx_st_find(&in, "latents");
    CHECK(img && lat && want_enc && want_dec && ti && tl);
    if (img && lat && want_enc && want_dec && ti && tl) {
        float *enc = malloc(n_enc * sizeof(float)), *dec = malloc(n_dec * sizeof(float));
        char label[160];
        CHECK(encode(c, k.t, img, (int)ti->shape[0], (int)ti->shape[2], (int)ti->shape[3], enc) == 0);
        snprintf(label, sizeof label, "taesd %s encode latents", wfile);
        mx_check_close(label, enc, want_enc, n_enc, bound);
        CHECK(decode(c, k.t, lat, (int)tl->shape[0], (int)tl->shape[2], (int)tl->shape[3], dec) == 0);
        snprintf(label, sizeof label, "taesd %s decode image", wfile);
        mx_check_close(label, dec, want_dec, n_dec, bound);
        free(enc);
        free(dec);
    }
    free(img);
    free(lat);
    free(want_enc);
    free(want_dec);
    mx_st_close(&in);
    mx_st_close(&out);
    free_taesd(&k);
}

/* Item 1 of a batch of 2 (non-square, 24×40) equals that item alone, for encode and decode. */
static void check_batch_independence(const mx_ctx *c) {
    taesd_case k;
    CHECK(load_taesd(&k, c, "taesd_tiny", "diffusion_pytorch_model.safetensors") == 0);
    if (!k.t) return;
    int f = mx_taesd_factor(k.t), H = 3 * f, W = 5 * f;
    CHECK(f == 8);
    size_t ni = (size_t)3 * H * W, nl = (size_t)4 * (H / f) * (W / f);
    float *img = malloc(2 * ni * sizeof(float)), *l2 = malloc(2 * nl * sizeof(float)), *l1 = malloc(nl * sizeof(float));
    float *d2 = malloc(2 * ni * sizeof(float)), *d1 = malloc(ni * sizeof(float));
    mx_fill_random(img, 2 * ni, 5, -1.0f, 1.0f);
    CHECK(encode(c, k.t, img, 2, H, W, l2) == 0);
    CHECK(encode(c, k.t, img + ni, 1, H, W, l1) == 0);
    mx_check_close("taesd_tiny 24x40 encode: item 1 vs alone", l1, l2 + nl, nl, 1e-6);
    mx_fill_random(l2, 2 * nl, 6, -3.0f, 3.0f);
    CHECK(decode(c, k.t, l2, 2, H / f, W / f, d2) == 0);
    CHECK(decode(c, k.t, l2 + nl, 1, H / f, W / f, d1) == 0);
    mx_check_close("taesd_tiny 24x40 decode: item 1 vs alone", d1, d2 + ni, ni, 1e-6);
    mx_status st;
    size_t bytes;
    CHECK(mx_taesd_encode_arena_bytes(k.t, 1, H + 4, W, &bytes, &st) == -1 && strstr(st.msg, "multiples"));
    CHECK(mx_taesd_decode_flops(k.t, 1, 8, 8) > 0.0);
    free(img);
    free(l2);
    free(l1);
    free(d2);
    free(d1);
    free_taesd(&k);
}

static void check_config_errors(void) {
    mx_taesd_config cfg;
    mx_status st;
    const char *mixed = "{\"_class_name\": \"AutoencoderTiny\", \"block_out_channels\": [16, 32], "
                        "\"num_encoder_blocks\": [1, 1], \"num_decoder_blocks\": [1, 1]}";
    CHECK(mx_taesd_config_parse(&cfg, mixed, strlen(mixed), "mixed", &st) == -1 && strstr(st.msg, "one channel count"));
    const char *counts = "{\"_class_name\": \"AutoencoderTiny\", \"block_out_channels\": [16, 16], "
                         "\"num_encoder_blocks\": [1, 1, 1], \"num_decoder_blocks\": [1, 1]}";
    CHECK(mx_taesd_config_parse(&cfg, counts, strlen(counts), "counts", &st) == -1 &&
          strstr(st.msg, "num_encoder_blocks"));
    const char *act = "{\"_class_name\": \"AutoencoderTiny\", \"block_out_channels\": [16, 16], \"act_fn\": \"silu\", "
                      "\"num_encoder_blocks\": [1, 1], \"num_decoder_blocks\": [1, 1]}";
    CHECK(mx_taesd_config_parse(&cfg, act, strlen(act), "act", &st) == -1 && strstr(st.msg, "act_fn"));
    const char *kl = "{\"_class_name\": \"AutoencoderKL\"}";
    CHECK(mx_taesd_config_parse(&cfg, kl, strlen(kl), "kl", &st) == -1 && strstr(st.msg, "AutoencoderTiny"));
}

int main(void) {
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    check_golden(&c, "diffusion_pytorch_model.safetensors", 1e-4);
    check_golden(&c, "diffusion_pytorch_model.fp16.safetensors", 1e-2);
    check_batch_independence(&c);
    check_config_errors();
    mx_ctx_destroy(&c);
    return mx_test_finish("test_nn_taesd");
}
