/* The IP-Adapter (pipeline/nn/ip_adapter.h) on unet_tiny against golden/ip_adapter_tiny
 * (diffusers' UNet with IPAdapterAttnProcessor2_0): image_tokens and the UNet's output at scales
 * 0.6 and 1.0 within 1e-4 rel L2 on MX_TEST_DEVICE (and within the bf16 bound in bf16 where the
 * CPU has it); scale 0, no tokens and no adapter equal the plain UNet bit for bit; an adapter that
 * does not fit the UNet (layer count, a layer's width, the tokens' width) is refused by the
 * forward. The denoise loop's image guidance (sd_pipeline.h): one token set shared by two latents
 * equals the same set given per latent and scale 0 equals no guidance, bit for bit. The adapter's
 * config and names come from the converter (weights/ip_adapter_file.h), as in a weight file. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/ip_adapter.h"
#include "../pipeline/nn/sd_pipeline.h"
#include "../pipeline/nn/unet.h"
#include "../runtime/log.h"
#include "../weights/convert.h"
#include "../weights/weights.h"
#include "nn_golden.h"

static char tmp[256];

typedef struct nets {
    mx_safetensors uf;
    mx_binder ub, ud, ab, ad_dev;
    mx_weightfile *wf;
    mx_unet *u;
    mx_ip_adapter *ad;
} nets;

/* unet_tiny from its golden files; the adapter converted alone into tmp/ip.mxw and loaded from it;
 * both bound on c's device. */
static int load_nets(const mx_ctx *c, nets *n) {
    mx_status st;
    size_t len;
    char adapter[1024], wpath[300];
    mx_unet_config cfg;
    memset(n, 0, sizeof *n);
    snprintf(wpath, sizeof wpath, "%s/ip.mxw", tmp);
    golden_path(adapter, sizeof adapter, "ip_adapter_tiny", "ip_adapter.safetensors");
    mx_convert_opts o = {.output = wpath, .dtype = MX_F32, .ip_adapter = adapter};
    char *text = golden_text("unet_tiny", "config.json", &len);
    int rc = !text || mx_unet_config_parse(&cfg, text, len, "unet_tiny", &st) ||
             golden_open(&n->uf, "unet_tiny", "diffusion_pytorch_model.safetensors") ||
             mx_binder_st(&n->ub, &n->uf, "", &st) || mx_binder_device(&n->ud, &n->ub, c, &st) ||
             mx_unet_load(&n->u, &cfg, &n->ud, &st) || mx_convert(&o, NULL, &st) || mx_wf_open(&n->wf, wpath, &st) ||
             mx_binder_wf(&n->ab, n->wf, "ip_adapter.", &st) || mx_binder_device(&n->ad_dev, &n->ab, c, &st);
    free(text);
    const char *acfg = rc ? NULL : mx_wf_meta(n->wf, "ip_adapter.config");
    if (!rc && (!acfg || mx_ip_adapter_load(&n->ad, acfg, strlen(acfg), wpath, &n->ad_dev, &st))) rc = -1;
    if (rc) fprintf(stderr, "%s\n", st.msg);
    return rc ? -1 : 0;
}

static void free_nets(nets *n) {
    mx_ip_adapter_free(n->ad);
    mx_unet_free(n->u);
    mx_binder_free(&n->ad_dev);
    mx_binder_free(&n->ab);
    mx_binder_free(&n->ud);
    mx_binder_free(&n->ub);
    if (n->wf) mx_wf_close(n->wf);
    mx_st_close(&n->uf);
}

/* tokens (host) of embeds (host) [n, E] through mx_ip_adapter_tokens on c's device. */
static int run_tokens(const mx_ctx *c, const mx_ip_adapter *ad, const float *embeds, int n, float *tokens) {
    mx_status st;
    size_t bytes, nt = (size_t)n * ad->num_tokens * ad->cross_dim;
    mx_arena a;
    if (mx_ip_adapter_arena_bytes(ad, n, &bytes, &st)) return fprintf(stderr, "%s\n", st.msg), -1;
    golden_arena(c, &a, bytes);
    float *de = golden_dev(c, embeds, (size_t)n * ad->embed_dim), *dt = golden_dev_alloc(c, nt);
    int rc = mx_ip_adapter_tokens(c, ad, de, n, dt, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, tokens, dt, nt)) rc = -1;
    mx_dev_free(c, de);
    mx_arena_destroy(&a);
    return rc;
}

/* The forward refuses an adapter that does not fit, with the message naming what differs. */
static void check_refusals(const mx_ctx *c, const nets *n, const mx_unet_input *in, float *out) {
    static const char *const want[3] = {"the IP-Adapter has 3 cross-attention layers, the UNet 4",
                                        "IP-Adapter layer 3 (7.to_k_ip) is 32 wide, the UNet's is 64",
                                        "the IP-Adapter's tokens are 16 wide"};
    for (int i = 0; i < 3; i++) {
        mx_ip_adapter bad = *n->ad;
        mx_status st;
        mx_unet_input x = *in;
        if (i == 0) bad.n_layers = 3;
        if (i == 1) bad.hidden[3] = 32;
        if (i == 2) bad.cross_dim = 16;
        x.ip = &bad;
        CHECK(mx_unet_check_ip(n->u, &bad, &st) == -1 && strstr(st.msg, want[i]));
        mx_arena a;
        golden_arena(c, &a, 1 << 20);
        CHECK(mx_unet_forward(c, n->u, &x, out, &a, &st) == -1 && strstr(st.msg, want[i]));
        mx_arena_destroy(&a);
    }
}

/* Two latents through 3 DPM-Solver++ steps of the tiny UNet with guide g (NULL: none) into lat. */
static int denoise_two(const mx_ctx *c, const nets *n, const mx_sd_image_guide *g, float *lat) {
    enum { T = 7, D = 32, NLAT = 2 * 4 * 8 * 8 };
    float cond[2 * T * D], uncond[2 * T * D];
    mx_sched_config cfg;
    mx_sched s;
    mx_status st;
    mx_fill_random(cond, 2 * T * D, 41, -1.0f, 1.0f);
    mx_fill_random(uncond, 2 * T * D, 42, -1.0f, 1.0f);
    mx_fill_random(lat, NLAT, 43, -1.0f, 1.0f);
    mx_sched_config_sd15(&cfg);
    if (mx_sched_init(&s, c, &cfg, 3, NLAT, &st)) return fprintf(stderr, "%s\n", st.msg), -1;
    mx_sd_request rq = {.unet = n->u, .cond_text = cond, .uncond_text = uncond, .T = T, .guidance = 7.5f,
                        .sched = &s, .image = g};
    int rc = mx_sd_denoise(&rq, c, lat, 2, 8, 8, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    mx_sched_free(&s);
    return rc;
}

static void check_pipeline(const mx_ctx *c, const nets *n, const float *embeds) {
    size_t nt = (size_t)n->ad->num_tokens * n->ad->cross_dim, nl = 2 * 4 * 8 * 8;
    float *cond = malloc(2 * nt * sizeof *cond), *uncond = malloc(2 * nt * sizeof *uncond);
    float *lat[4];
    mx_status st;
    for (int i = 0; i < 4; i++) lat[i] = malloc(nl * sizeof(float));
    CHECK(mx_ip_adapter_guidance_tokens(c, n->ad, embeds, 1, cond, uncond, &st) == 0);
    memcpy(cond + nt, cond, nt * sizeof *cond); /* the same set for the second latent */
    memcpy(uncond + nt, uncond, nt * sizeof *uncond);
    mx_sd_image_guide shared = {.adapter = n->ad, .cond = cond, .uncond = uncond, .n_tokens = n->ad->num_tokens,
                                .scale = 0.6f};
    mx_sd_image_guide per_latent = shared, off = shared;
    per_latent.per_latent = 1;
    off.scale = 0.0f;
    CHECK(denoise_two(c, n, &shared, lat[0]) == 0 && denoise_two(c, n, &per_latent, lat[1]) == 0 &&
          denoise_two(c, n, &off, lat[2]) == 0 && denoise_two(c, n, NULL, lat[3]) == 0);
    CHECK(memcmp(lat[0], lat[1], nl * sizeof(float)) == 0);
    CHECK(memcmp(lat[2], lat[3], nl * sizeof(float)) == 0);
    CHECK(mx_rel_l2(lat[0], lat[3], nl) > 1e-3);
    printf("pipeline image guidance: shared = per latent, scale 0 = none (bit for bit); guided differs by %.3g\n",
           mx_rel_l2(lat[0], lat[3], nl));
    for (int i = 0; i < 4; i++) free(lat[i]);
    free(cond);
    free(uncond);
}

static void check_case(const mx_ctx *c, double bound) {
    nets n;
    mx_safetensors in, gout;
    char label[128], name[32];
    CHECK(load_nets(c, &n) == 0);
    CHECK(golden_open(&in, "ip_adapter_tiny", "inputs.safetensors") == 0);
    CHECK(golden_open(&gout, "ip_adapter_tiny", "outputs.safetensors") == 0);
    size_t ns, ne, nt, ni, nw;
    float *sample = golden_f32(&in, "sample", &ns), *ehs = golden_f32(&in, "encoder_hidden_states", &ne);
    float *ts = golden_f32(&in, "timestep", &nt), *embeds = golden_f32(&in, "image_embeds", &ni);
    float *want_tokens = golden_f32(&gout, "image_tokens", &nw);
    const mx_st_tensor *te = mx_st_find(&in, "image_embeds"), *ts_s = mx_st_find(&in, "sample");
    const mx_st_tensor *te_h = mx_st_find(&in, "encoder_hidden_states");
    if (!n.ad || !sample || !ehs || !ts || !embeds || !want_tokens || !te || !ts_s || !te_h || te->ndim != 3) {
        CHECK(0);
        return;
    }
    int B = (int)ts_s->shape[0], n_img = (int)te->shape[1];
    float *tokens = malloc(nw * sizeof *tokens);
    CHECK(nw == (size_t)B * n_img * n.ad->num_tokens * n.ad->cross_dim);
    CHECK(run_tokens(c, n.ad, embeds, B * n_img, tokens) == 0);
    golden_label(label, sizeof label, c, "ip_adapter_tiny image_tokens");
    mx_check_close(label, tokens, want_tokens, nw, bound);

    mx_unet_input ui = {.sample = sample, .timesteps = ts, .encoder_hidden_states = ehs, .B = B,
                        .H = (int)ts_s->shape[2], .W = (int)ts_s->shape[3], .T = (int)te_h->shape[1],
                        .ip = n.ad, .ip_tokens = tokens, .ip_n = n_img * n.ad->num_tokens};
    size_t no = ns; /* out_channels == in_channels */
    float *plain = malloc(no * sizeof *plain), *got = malloc(no * sizeof *got);
    const float scales[2] = {0.6f, 1.0f};
    for (int s = 0; s < 2; s++) {
        size_t nwant;
        snprintf(name, sizeof name, "out_scale_%s", s ? "1_0" : "0_6");
        float *want = golden_f32(&gout, name, &nwant);
        ui.ip_scale = scales[s];
        CHECK(want && nwant == no && golden_run_unet(c, n.u, &ui, got) == 0);
        char what[64];
        snprintf(what, sizeof what, "ip_adapter_tiny %s", name);
        golden_label(label, sizeof label, c, what);
        if (want && nwant == no) mx_check_close(label, got, want, no, bound);
        free(want);
    }
    /* the plain UNet, then each way of giving no guidance: bit for bit */
    mx_unet_input none = ui;
    none.ip = NULL;
    CHECK(golden_run_unet(c, n.u, &none, plain) == 0);
    for (int k = 0; k < 2; k++) {
        mx_unet_input off = ui;
        if (k == 0) off.ip_scale = 0.0f;
        else off.ip_n = 0, off.ip_tokens = NULL;
        CHECK(golden_run_unet(c, n.u, &off, got) == 0);
        CHECK(memcmp(got, plain, no * sizeof *got) == 0);
    }
    printf("ip_adapter_tiny: scale 0 and no tokens equal the plain UNet bit for bit\n");
    ui.ip_scale = 1.0f;
    check_refusals(c, &n, &ui, got);
    check_pipeline(c, &n, embeds);
    free(plain);
    free(got);
    free(tokens);
    free(sample);
    free(ehs);
    free(ts);
    free(embeds);
    free(want_tokens);
    mx_st_close(&in);
    mx_st_close(&gout);
    free_nets(&n);
}

int main(void) {
    mx_log_set_level(MX_LOG_WARN);
    if (!golden_have("ip_adapter_tiny", "ip_adapter.safetensors")) return mx_test_finish("test_nn_ip_adapter");
    snprintf(tmp, sizeof tmp, "/tmp/mx_test_nn_ip_XXXXXX");
    if (!mkdtemp(tmp)) return 1;
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    check_case(&c, golden_bound(&c, GOLDEN_BF16));
    mx_ctx_destroy(&c);
    int bf = golden_bf16_ctx(&c, "test_nn_ip_adapter");
    if (bf == 0) {
        check_case(&c, golden_bound(&c, GOLDEN_BF16));
        mx_ctx_destroy(&c);
    }
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    CHECK(system(cmd) == 0);
    return mx_test_finish("test_nn_ip_adapter");
}
