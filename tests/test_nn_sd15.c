/* SD1.5-size networks (weights by the golden-v1 rule, generated in memory) against
 * golden/sd15_{unet,controlnet,vae} (outside the repository, MATEX_TESTDATA): runs only with
 * MATEX_FULL=1 (minutes, GBs). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/unet.h"
#include "../pipeline/nn/vae.h"
#include "../runtime/log.h"
#include "nn_golden.h"

/* bf16_bound: the bound under bf16 arithmetic (nn_golden.h) */
static void compare(const mx_ctx *c, const mx_safetensors *out, const char *label, const char *name, const float *got,
                    double bf16_bound) {
    size_t n;
    char l[192], tag[64];
    float *want = golden_f32(out, name, &n);
    CHECK(want != NULL);
    golden_label(tag, sizeof tag, c, label);
    snprintf(l, sizeof l, "%s %s", tag, name);
    if (want) mx_check_close(l, got, want, n, golden_bound(c, bf16_bound));
    free(want);
}

static void sd15_unet(const mx_ctx *c) {
    mx_status st;
    mx_unet_config cfg;
    golden_weights b;
    mx_unet *u = NULL;
    mx_safetensors in, out;
    size_t len, bytes = 0;
    char *text = golden_text("sd15_unet", "config.json", &len);
    CHECK(text && mx_unet_config_parse(&cfg, text, len, "sd15_unet", &st) == 0);
    free(text);
    double t0 = mx_now();
    CHECK(golden_weights_rule(&b, c, 1, MX_F32, &st) == 0 && mx_unet_load(&u, &cfg, &b.dev, &st) == 0);
    printf("sd15_unet: weights generated in %.1f s\n", mx_now() - t0);
    CHECK(golden_open(&in, "sd15_unet", "inputs.safetensors") == 0 && golden_open(&out, "sd15_unet", "outputs.safetensors") == 0);
    if (!u) return;
    const mx_st_tensor *ts = mx_st_find(&in, "sample"), *te = mx_st_find(&in, "encoder_hidden_states");
    CHECK(ts && te);
    if (!ts || !te) return;
    float *sample = golden_f32(&in, "sample", NULL), *ehs = golden_f32(&in, "encoder_hidden_states", NULL);
    float *tsteps = golden_f32(&in, "timestep", NULL);
    mx_unet_input ui = {.sample = sample, .timesteps = tsteps, .encoder_hidden_states = ehs, .B = (int)ts->shape[0],
                        .H = (int)ts->shape[2], .W = (int)ts->shape[3], .T = (int)te->shape[1]};
    float *got = malloc((size_t)ui.B * cfg.out_channels * ui.H * ui.W * sizeof *got);
    CHECK(mx_unet_arena_bytes(u, ui.B, ui.H, ui.W, ui.T, &bytes, &st) == 0);
    printf("sd15_unet: arena %.1f MB\n", bytes / 1e6);
    int n = mx_unet_num_residuals(&cfg);
    for (int s = -1; s < 2; s++) {
        float *res[MX_UNET_MAX_RES + 1] = {0};
        char name[64];
        if (s >= 0) {
            for (int i = 0; i <= n; i++) {
                char rn[96];
                if (i < n) snprintf(rn, sizeof rn, "residual.scale%d.down_block_res_sample.%d", s, i);
                else snprintf(rn, sizeof rn, "residual.scale%d.mid_block_res_sample", s);
                res[i] = golden_f32(&in, rn, NULL);
            }
            ui.down_residuals = (const float *const *)res;
            ui.mid_residual = res[n];
            snprintf(name, sizeof name, "out_controlnet_scale%d", s);
        } else {
            snprintf(name, sizeof name, "out_plain");
        }
        t0 = mx_now();
        CHECK(golden_run_unet(c, u, &ui, got) == 0);
        printf("sd15_unet %s: %.2f s\n", name, mx_now() - t0);
        compare(c, &out, "sd15_unet", name, got, GOLDEN_BF16);
        for (int i = 0; i <= n; i++) free(res[i]);
    }
    free(got);
    free(sample);
    free(ehs);
    free(tsteps);
    mx_st_close(&in);
    mx_st_close(&out);
    mx_unet_free(u);
    golden_weights_close(&b);
}

static void sd15_controlnet(const mx_ctx *c) {
    mx_status st;
    mx_unet_config cfg;
    golden_weights b;
    mx_controlnet *m = NULL;
    mx_safetensors in, out;
    size_t len;
    char *text = golden_text("sd15_controlnet", "config.json", &len);
    CHECK(text && mx_unet_config_parse(&cfg, text, len, "sd15_controlnet", &st) == 0);
    free(text);
    CHECK(golden_weights_rule(&b, c, 2, MX_F32, &st) == 0 && mx_controlnet_load(&m, &cfg, &b.dev, &st) == 0);
    CHECK(golden_open(&in, "sd15_controlnet", "inputs.safetensors") == 0 &&
          golden_open(&out, "sd15_controlnet", "outputs.safetensors") == 0);
    if (!m) return;
    const mx_st_tensor *ts = mx_st_find(&in, "sample"), *te = mx_st_find(&in, "encoder_hidden_states");
    CHECK(ts && te);
    if (!ts || !te) return;
    float *sample = golden_f32(&in, "sample", NULL), *ehs = golden_f32(&in, "encoder_hidden_states", NULL);
    float *tsteps = golden_f32(&in, "timestep", NULL), *cond = golden_f32(&in, "controlnet_cond", NULL);
    mx_controlnet_input ci = {sample, tsteps, ehs, cond, (int)ts->shape[0], (int)ts->shape[2], (int)ts->shape[3],
                              (int)te->shape[1], 1.0f, 0};
    int n = mx_unet_num_residuals(&cfg), C, h, w;
    float *res[MX_UNET_MAX_RES + 1];
    for (int i = 0; i <= n; i++) {
        mx_unet_residual_shape(&cfg, i, ci.H, ci.W, &C, &h, &w);
        res[i] = malloc((size_t)ci.B * C * h * w * sizeof(float));
    }
    const float scales[2] = {1.0f, 0.5f};
    for (int s = 0; s < 2; s++) {
        ci.scale = scales[s];
        double t0 = mx_now();
        CHECK(golden_run_controlnet(c, m, &ci, res, res[n], 0) == 0);
        printf("sd15_controlnet scale %g: %.2f s\n", scales[s], mx_now() - t0);
        for (int i = 0; i <= n; i++) {
            char name[96];
            if (i < n) snprintf(name, sizeof name, "scale%d.down_block_res_sample.%d", s, i);
            else snprintf(name, sizeof name, "scale%d.mid_block_res_sample", s);
            compare(c, &out, "sd15_controlnet", name, res[i], GOLDEN_BF16);
        }
    }
    for (int i = 0; i <= n; i++) free(res[i]);
    free(sample);
    free(ehs);
    free(tsteps);
    free(cond);
    mx_st_close(&in);
    mx_st_close(&out);
    mx_controlnet_free(m);
    golden_weights_close(&b);
}

static void sd15_vae(const mx_ctx *c, mx_dtype dt, const char *outfile) {
    mx_status st;
    mx_vae_config cfg;
    golden_weights b;
    mx_vae *v = NULL;
    mx_safetensors in, out;
    size_t len;
    char *text = golden_text("sd15_vae", "config.json", &len);
    CHECK(text && mx_vae_config_parse(&cfg, text, len, "sd15_vae", &st) == 0);
    free(text);
    CHECK(golden_weights_rule(&b, c, 1, dt, &st) == 0 && mx_vae_load(&v, &cfg, &b.dev, &st) == 0);
    CHECK(golden_open(&in, "sd15_vae", "inputs.safetensors") == 0 && golden_open(&out, "sd15_vae", outfile) == 0);
    if (!v) return;
    const mx_st_tensor *ti = mx_st_find(&in, "image");
    CHECK(ti != NULL);
    if (!ti) return;
    float *img = golden_f32(&in, "image", NULL), *lat = golden_f32(&in, "latents", NULL);
    int B = (int)ti->shape[0], H = (int)ti->shape[2], W = (int)ti->shape[3], f = mx_vae_factor(v);
    size_t nl = (size_t)B * cfg.latent_channels * (H / f) * (W / f), ni = (size_t)B * cfg.out_channels * H * W;
    float *mean = malloc(nl * sizeof(float)), *logvar = malloc(nl * sizeof(float)), *dec = malloc(ni * sizeof(float));
    double t0 = mx_now();
    CHECK(golden_vae_encode(c, v, img, B, H, W, mean, logvar) == 0);
    printf("sd15_vae encode: %.2f s\n", mx_now() - t0);
    compare(c, &out, outfile, "encode.mean", mean, GOLDEN_BF16);
    compare(c, &out, outfile, "encode.logvar", logvar, GOLDEN_BF16);
    t0 = mx_now();
    CHECK(golden_vae_decode(c, v, lat, B, H / f, W / f, dec) == 0);
    printf("sd15_vae decode: %.2f s\n", mx_now() - t0);
    compare(c, &out, outfile, "decode", dec, GOLDEN_BF16);
    CHECK(golden_vae_decode(c, v, mean, B, H / f, W / f, dec) == 0);
    compare(c, &out, outfile, "decode_of_encode_mean", dec, GOLDEN_BF16);
    free(mean);
    free(logvar);
    free(dec);
    free(img);
    free(lat);
    mx_st_close(&in);
    mx_st_close(&out);
    mx_vae_free(v);
    golden_weights_close(&b);
}

/* A case runs where both its inputs and its outputs are at hand (a GPU run carries only some). */
static int have_case(const char *net) {
    return golden_have(net, "inputs.safetensors") && golden_have(net, "outputs.safetensors");
}

int main(void) {
    const char *full = getenv("MATEX_FULL");
    if (!full || strcmp(full, "1")) {
        printf("test_nn_sd15: SD1.5-size parity runs only with MATEX_FULL=1 (make test-full)\n");
        return MX_TEST_SKIP;
    }
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    int vae = have_case("sd15_vae"), cn = have_case("sd15_controlnet"), unet = have_case("sd15_unet");
    if (vae) {
        sd15_vae(&c, MX_F32, "outputs.safetensors");
        sd15_vae(&c, MX_F16, "outputs_fp16w.safetensors");
    }
    if (cn) sd15_controlnet(&c);
    if (unet) sd15_unet(&c);
    mx_ctx_destroy(&c);
    if ((vae || cn || unet) && golden_bf16_ctx(&c, "test_nn_sd15") == 0) { /* bf16 arithmetic, fp32 goldens */
        if (vae) sd15_vae(&c, MX_F32, "outputs.safetensors");
        if (cn) sd15_controlnet(&c);
        if (unet) sd15_unet(&c);
        mx_ctx_destroy(&c);
    }
    return mx_test_finish("test_nn_sd15");
}
