/* AutoencoderKL against the golden vectors of vae_tiny and vae_mini (fp32 and fp16 weights):
 * encode -> moments, mean, logvar, std, sample (with the stored noise); decode(latents);
 * decode(encode mean). Plus a non-square image and batch independence. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/vae.h"
#include "nn_golden.h"

typedef struct vae_case {
    golden_net n;
    mx_vae *v;
    mx_vae_config cfg;
} vae_case;

static int load_vae(vae_case *k, const mx_ctx *c, const char *net, const char *wfile) {
    memset(k, 0, sizeof *k);
    if (golden_net_load(&k->n, c, net, wfile, "vae")) return -1;
    k->v = k->n.net;
    k->cfg = *mx_vae_cfg(k->v);
    return 0;
}

static void free_vae(vae_case *k) { golden_net_free(&k->n); }

static void compare(const mx_ctx *c, const mx_safetensors *out, const char *net, const char *outfile, const char *name,
                    const float *got) {
    size_t n;
    char label[160], tag[64];
    float *want = golden_f32(out, name, &n);
    CHECK(want != NULL);
    golden_label(tag, sizeof tag, c, net);
    snprintf(label, sizeof label, "%s %s %s", tag, outfile, name);
    if (want)
        mx_check_close(label, got, want, n, golden_bound(c, GOLDEN_BF16));
    free(want);
}

static void check_golden(const mx_ctx *c, const char *net, const char *wfile, const char *outfile) {
    vae_case k;
    mx_safetensors in, out;
    CHECK(load_vae(&k, c, net, wfile) == 0);
    CHECK(golden_open(&in, net, "inputs.safetensors") == 0);
    CHECK(golden_open(&out, net, outfile) == 0);
    if (!k.v) return;
    float *img = golden_f32(&in, "image", NULL), *noise = golden_f32(&in, "sample_noise", NULL);
    float *lat = golden_f32(&in, "latents", NULL);
    const mx_st_tensor *ti = mx_st_find(&in, "image");
    CHECK(img && noise && lat && ti);
    if (!img || !noise || !lat || !ti) return;
    int B = (int)ti->shape[0], H = (int)ti->shape[2], W = (int)ti->shape[3], f = mx_vae_factor(k.v);
    int lc = k.cfg.latent_channels, h = H / f, w = W / f;
    size_t nl = (size_t)B * lc * h * w, ni = (size_t)B * k.cfg.out_channels * H * W, per = nl / (size_t)B;
    float *mean = malloc(nl * sizeof(float)), *logvar = malloc(nl * sizeof(float)), *tmp = malloc(2 * nl * sizeof(float));
    float *dec = malloc(ni * sizeof(float));
    CHECK(golden_vae_encode(c, k.v, img, B, H, W, mean, logvar) == 0);
    compare(c, &out, net, outfile, "encode.mean", mean);
    compare(c, &out, net, outfile, "encode.logvar", logvar);
    for (int b = 0; b < B; b++) { /* moments = [mean | logvar] per item (no clamping at these values) */
        memcpy(tmp + (size_t)b * 2 * per, mean + (size_t)b * per, per * sizeof(float));
        memcpy(tmp + (size_t)b * 2 * per + per, logvar + (size_t)b * per, per * sizeof(float));
    }
    compare(c, &out, net, outfile, "encode.moments", tmp);
    for (size_t i = 0; i < nl; i++) tmp[i] = expf(0.5f * logvar[i]);
    compare(c, &out, net, outfile, "encode.std", tmp);
    for (size_t i = 0; i < nl; i++) tmp[i] = mean[i] + tmp[i] * noise[i];
    compare(c, &out, net, outfile, "encode.sample", tmp);
    CHECK(golden_vae_decode(c, k.v, lat, B, h, w, dec) == 0);
    compare(c, &out, net, outfile, "decode", dec);
    CHECK(golden_vae_decode(c, k.v, mean, B, h, w, dec) == 0);
    compare(c, &out, net, outfile, "decode_of_encode_mean", dec);
    free(mean);
    free(logvar);
    free(tmp);
    free(dec);
    free(img);
    free(noise);
    free(lat);
    mx_st_close(&in);
    mx_st_close(&out);
    free_vae(&k);
}

/* Non-square: item 1 of a batch of 2 (image 32×64) equals that item alone, for encode and decode. */
static void check_batch_independence(const mx_ctx *c) {
    vae_case k;
    CHECK(load_vae(&k, c, "vae_tiny", "diffusion_pytorch_model.safetensors") == 0);
    if (!k.v) return;
    int f = mx_vae_factor(k.v), H = 4 * f, W = 8 * f, lc = k.cfg.latent_channels;
    size_t ni = (size_t)k.cfg.in_channels * H * W, nl = (size_t)lc * (H / f) * (W / f);
    size_t no = (size_t)k.cfg.out_channels * H * W;
    float *img = malloc(2 * ni * sizeof(float)), *m2 = malloc(2 * nl * sizeof(float)), *m1 = malloc(nl * sizeof(float));
    float *d2 = malloc(2 * no * sizeof(float)), *d1 = malloc(no * sizeof(float));
    mx_fill_random(img, 2 * ni, 21, -1.0f, 1.0f);
    CHECK(golden_vae_encode(c, k.v, img, 2, H, W, m2, NULL) == 0);
    CHECK(golden_vae_encode(c, k.v, img + ni, 1, H, W, m1, NULL) == 0);
    mx_check_close("vae_tiny 32x64 encode: item 1 vs alone", m1, m2 + nl, nl, 1e-6);
    CHECK(golden_vae_decode(c, k.v, m2, 2, H / f, W / f, d2) == 0);
    CHECK(golden_vae_decode(c, k.v, m2 + nl, 1, H / f, W / f, d1) == 0);
    mx_check_close("vae_tiny 32x64 decode: item 1 vs alone", d1, d2 + no, no, 1e-6);
    mx_status st;
    size_t bytes;
    CHECK(mx_vae_encode_arena_bytes(k.v, 1, H + 1, W, &bytes, &st) == -1 && strstr(st.msg, "multiples"));
    free(img);
    free(m2);
    free(m1);
    free(d2);
    free(d1);
    free_vae(&k);
}

int main(void) {
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    check_golden(&c, "vae_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
    check_golden(&c, "vae_tiny", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors");
    int mini = golden_have("vae_mini", "inputs.safetensors"); /* outside the repository */
    if (mini) {
        check_golden(&c, "vae_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        check_golden(&c, "vae_mini", "diffusion_pytorch_model.fp16.safetensors", "outputs_fp16w.safetensors");
    }
    check_batch_independence(&c);
    mx_ctx_destroy(&c);
    if (golden_bf16_ctx(&c, "test_nn_vae") == 0) { /* bf16 arithmetic against the fp32 goldens */
        check_golden(&c, "vae_tiny", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        if (mini) check_golden(&c, "vae_mini", "diffusion_pytorch_model.safetensors", "outputs.safetensors");
        mx_ctx_destroy(&c);
    }
    return mx_test_finish("test_nn_vae");
}
