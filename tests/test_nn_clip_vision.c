/* CLIP vision tower (CLIPVisionModelWithProjection) against transformers 4.39:
 * golden/clip_vision_tiny with fp32 weights, image_embeds, last_hidden_state and
 * penultimate_hidden_state ≤ 1e-4 rel L2 (scalar and best kernels, and the tower converted into a
 * weight file and loaded through the registry, also from a pytorch_model.bin); the fp16 weights file against the same fp32
 * outputs at the half-precision bound 1e-2 (the case has no outputs_fp16w); bf16 arithmetic at
 * 1e-2 where the CPU has it; the ViT-H/14 parameter list of the published image encoder; config
 * errors. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../pipeline/nn/clip_vision.h"
#include "../pipeline/nn/registry.h"
#include "../weights/convert.h"
#include "../weights/weights.h"
#include "nn_golden.h"
#include "util_ckpt.h"

#define NET "clip_vision_tiny"

static const char *const output_names[3] = {"image_embeds", "last_hidden_state", "penultimate_hidden_state"};

/* Runs m on the golden pixel_values (dry run first, then an arena of exactly its size) and compares
 * the three outputs with golden/NET/outputs.safetensors at `bound`. */
static void run_and_compare(const mx_clip_vision *m, const mx_ctx *c, const char *label, double bound) {
    mx_safetensors in, out;
    if (golden_open(&in, NET, "inputs.safetensors")) {
        CHECK(0);
        return;
    }
    if (golden_open(&out, NET, "outputs.safetensors")) {
        mx_st_close(&in);
        CHECK(0);
        return;
    }
    size_t npix = 0, n[3];
    float *pixels = golden_f32(&in, "pixel_values", &npix), *want[3], *got[3], *dev[3];
    const mx_clip_vision_config *cfg = &m->cfg;
    int S = cfg->image_size, B = (int)(npix / (size_t)(cfg->num_channels * S * S));
    n[0] = (size_t)B * cfg->projection_dim;
    n[1] = n[2] = (size_t)B * mx_clip_vision_tokens(cfg) * cfg->hidden_size;
    for (int i = 0; i < 3; i++) {
        size_t wn = 0;
        want[i] = golden_f32(&out, output_names[i], &wn);
        CHECK(want[i] != NULL && wn == n[i]);
        got[i] = malloc(n[i] * sizeof(float));
        dev[i] = golden_dev_alloc(c, n[i]);
    }
    float *dpix = golden_dev(c, pixels, npix);
    mx_status st = {0};
    mx_arena measure, arena;
    mx_arena_measure(&measure);
    CHECK(mx_clip_vision_forward(m, c, &measure, dpix, B, dev[0], dev[1], dev[2], &st) == 0 && measure.peak > 0);
    golden_arena(c, &arena, measure.peak);
    int ok = mx_clip_vision_forward(m, c, &arena, dpix, B, dev[0], dev[1], dev[2], &st) == 0;
    if (!ok) fprintf(stderr, "%s: %s\n", label, st.msg);
    CHECK(ok);
    for (int i = 0; i < 3; i++) {
        char msg[128];
        snprintf(msg, sizeof msg, "%s %s", label, output_names[i]);
        CHECK(golden_fetch(c, got[i], dev[i], n[i]) == 0);
        if (ok && want[i]) mx_check_close(msg, got[i], want[i], n[i], bound);
    }
    /* the host entry point "style" calls gives the same embeddings */
    float *host_embeds = malloc(n[0] * sizeof(float));
    ok = ok && mx_clip_vision_embed_images(c, m, pixels, B, host_embeds, &st) == 0;
    CHECK(ok);
    if (ok && want[0]) {
        char msg[128];
        snprintf(msg, sizeof msg, "%s image_embeds (host entry)", label);
        mx_check_close(msg, host_embeds, want[0], n[0], bound);
    }
    free(host_embeds);
    mx_arena_destroy(&arena);
    mx_dev_free(c, dpix);
    for (int i = 0; i < 3; i++) {
        free(want[i]);
        free(got[i]);
    }
    free(pixels);
    mx_st_close(&in);
    mx_st_close(&out);
}

static int load_config(mx_clip_vision_config *cfg) {
    size_t len;
    char *text = golden_text(NET, "config.json", &len);
    mx_status st = {0};
    int ok = text && mx_clip_vision_config_parse(cfg, text, len, "config.json", &st) == 0;
    if (!ok) fprintf(stderr, "%s config: %s\n", NET, text ? st.msg : "cannot read");
    free(text);
    return ok ? 0 : -1;
}

/* The golden's safetensors bound directly (no weight file). */
static void test_tiny(const char *weights_file, const mx_ctx *c, const char *label, double bound) {
    mx_clip_vision_config cfg;
    if (load_config(&cfg)) {
        CHECK(0);
        return;
    }
    CHECK(cfg.hidden_size == 32 && cfg.patch_size == 8 && cfg.image_size == 32 && cfg.projection_dim == 24 &&
          cfg.hidden_act == MX_TF_ACT_GELU && mx_clip_vision_tokens(&cfg) == 17);
    char path[1100];
    golden_path(path, sizeof path, NET, weights_file);
    mx_safetensors sf;
    mx_status st = {0};
    mx_binder b, db = {0};
    mx_clip_vision *m = NULL;
    if (mx_st_open(&sf, path, &st) || mx_binder_st(&b, &sf, "", &st) || mx_binder_device(&db, &b, c, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    int ok = mx_clip_vision_load(&m, &cfg, &db, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    mx_st_close(&sf);
    if (ok) run_and_compare(m, c, label, bound);
    mx_clip_vision_free(m);
    mx_binder_free(&db);
    mx_binder_free(&b);
}

/* The production path: `matex convert` of the golden folder (a single network folder: its
 * model_type names the class), then the registry loads "image_encoder.config" with the prefix
 * "image_encoder." of the weight file. */
static void test_converted(const mx_ctx *c) {
    char dir[1024], path[256];
    golden_path(dir, sizeof dir, NET, "");
    snprintf(path, sizeof path, "/tmp/matex_test_clip_vision_%d.mxw", (int)getpid());
    mx_convert_opts opts = {.image_encoder = dir, .output = path, .dtype = MX_F32};
    mx_convert_result res;
    mx_status st = {0};
    mx_weightfile *wf = NULL;
    mx_binder b = {0}, db = {0};
    const mx_net_def *def = NULL;
    void *net = NULL;
    const char *cfg_text = NULL;
    int ok = mx_convert(&opts, &res, &st) == 0 && res.networks == 1 && res.tensors == 40 &&
             mx_wf_open(&wf, path, &st) == 0;
    if (ok) cfg_text = mx_wf_meta(wf, "image_encoder.config");
    ok = ok && cfg_text && mx_binder_wf(&b, wf, "image_encoder.", &st) == 0 && mx_binder_device(&db, &b, c, &st) == 0 &&
         mx_net_load_config(&def, &net, cfg_text, strlen(cfg_text), "image_encoder.config", &db, &st) == 0;
    if (!ok) fprintf(stderr, "converted %s: %s\n", NET, st.msg);
    CHECK(ok && def == mx_net_named("clip-vision") && !strcmp(def->kind, MX_NET_IMAGE_ENCODER));
    if (ok) run_and_compare(net, c, "converted", golden_bound(c, GOLDEN_BF16));
    if (def) def->free(net);
    mx_binder_free(&db);
    mx_binder_free(&b);
    if (wf) mx_wf_close(wf);
    remove(path);
}

/* A folder holding pytorch_model.bin (the PyTorch zip of the golden weights, as torch.save
 * writes it) instead of model.safetensors converts through the safe checkpoint reader to the
 * same network. */
static void test_converted_bin(const mx_ctx *c) {
    char src[1024], dir[256], path[512], cfg_src[1100];
    golden_path(src, sizeof src, NET, "model.safetensors");
    golden_path(cfg_src, sizeof cfg_src, NET, "config.json");
    snprintf(dir, sizeof dir, "/tmp/matex_test_cv_bin_%d", (int)getpid());
    mx_safetensors sf;
    mx_status st = {0};
    size_t len;
    char *cfg = golden_text(NET, "config.json", &len);
    CHECK(cfg && mkdir(dir, 0700) == 0 && mx_st_open(&sf, src, &st) == 0);
    snprintf(path, sizeof path, "%s/config.json", dir);
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(cfg, 1, len, f) == len);
    if (f) fclose(f);
    snprintf(path, sizeof path, "%s/pytorch_model.bin", dir);
    CHECK(mx_test_write_torchzip(path, sf.tensors, sf.count, 0) == 0);
    mx_st_close(&sf);
    char out[300];
    snprintf(out, sizeof out, "%s.mxw", dir);
    mx_convert_opts opts = {.image_encoder = dir, .output = out, .dtype = MX_F32};
    mx_convert_result res;
    mx_weightfile *wf = NULL;
    mx_binder b = {0}, db = {0};
    mx_clip_vision_config vc;
    mx_clip_vision *m = NULL;
    int ok = mx_convert(&opts, &res, &st) == 0 && res.tensors == 40 && mx_wf_open(&wf, out, &st) == 0 &&
             mx_clip_vision_config_parse(&vc, cfg, len, "config.json", &st) == 0 &&
             mx_binder_wf(&b, wf, "image_encoder.", &st) == 0 && mx_binder_device(&db, &b, c, &st) == 0 &&
             mx_clip_vision_load(&m, &vc, &db, &st) == 0;
    if (!ok) fprintf(stderr, "pytorch_model.bin: %s\n", st.msg);
    CHECK(ok);
    if (ok) run_and_compare(m, c, "from pytorch_model.bin", golden_bound(c, GOLDEN_BF16));
    mx_clip_vision_free(m);
    mx_binder_free(&db);
    mx_binder_free(&b);
    if (wf) mx_wf_close(wf);
    remove(out);
    remove(path);
    snprintf(path, sizeof path, "%s/config.json", dir);
    remove(path);
    rmdir(dir);
    free(cfg);
}

/* The published SD1.5 IP-Adapter's encoder (h94/IP-Adapter models/image_encoder, ViT-H/14): its
 * parameter list, enumerated from the config alone. 632,076,800 parameters = its 2.53 GB fp32
 * model.safetensors. */
static void test_vit_h_parameters(void) {
    const char *vit_h = "{\"architectures\": [\"CLIPVisionModelWithProjection\"], \"hidden_act\": \"gelu\","
                        "\"hidden_size\": 1280, \"image_size\": 224, \"intermediate_size\": 5120,"
                        "\"layer_norm_eps\": 1e-05, \"model_type\": \"clip_vision_model\", \"num_attention_heads\": 16,"
                        "\"num_channels\": 3, \"num_hidden_layers\": 32, \"patch_size\": 14, \"projection_dim\": 1024}";
    mx_binder b;
    mx_status st = {0};
    CHECK(mx_binder_enum(&b, &st) == 0);
    CHECK(mx_net_enumerate(&b, vit_h, strlen(vit_h), "vit-h.json", &st) == 0);
    CHECK(mx_binder_enum_count(&b) == 3 + 2 + 32 * 16 + 2 + 1);
    CHECK(mx_binder_enum_bytes(&b) == (size_t)632076800 * 4);
    mx_binder_free(&b);
}

static void expect_config_error(const char *json, const char *needle) {
    mx_clip_vision_config cfg;
    mx_status st = {0};
    int rc = mx_clip_vision_config_parse(&cfg, json, strlen(json), "bad.json", &st);
    CHECK(rc != 0 && strstr(st.msg, "bad.json") && strstr(st.msg, needle));
    if (rc == 0 || !strstr(st.msg, needle)) fprintf(stderr, "config %s: got '%s'\n", json, st.msg);
}

static void test_config(void) {
    expect_config_error("{\"image_size\": 30, \"patch_size\": 14}", "multiple of patch_size");
    expect_config_error("{\"hidden_size\": 30, \"num_attention_heads\": 4}", "divisible");
    expect_config_error("{\"hidden_act\": \"relu\"}", "relu");
    expect_config_error("{\"patch_size\": 0}", "patch_size");
    expect_config_error("[1]", "JSON object");
    /* a whole CLIPModel config: the vision sizes from vision_config, the projection from the top */
    const char *clip = "{\"projection_dim\": 768, \"vision_config\": {\"hidden_size\": 1024, \"num_attention_heads\": 16,"
                       "\"patch_size\": 14, \"image_size\": 224, \"hidden_act\": \"quick_gelu\"}}";
    mx_clip_vision_config cfg;
    mx_status st = {0};
    CHECK(mx_clip_vision_config_parse(&cfg, clip, strlen(clip), "clip.json", &st) == 0 && cfg.hidden_size == 1024 &&
          cfg.projection_dim == 768 && cfg.hidden_act == MX_TF_ACT_QUICK_GELU && mx_clip_vision_tokens(&cfg) == 257);
}

int main(void) {
    mx_ctx scalar, best;
    mx_status st = {0};
    if (mx_ctx_create_on(&scalar, golden_device(), 1, MX_ISA_SCALAR, 16 << 20, &st) ||
        mx_ctx_create_on(&best, golden_device(), 2, mx_cpu_isa_for(MX_PREC_FP32), 16 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return 1;
    }
    test_tiny("model.safetensors", &scalar, "fp32 scalar", golden_bound(&scalar, GOLDEN_BF16));
    test_tiny("model.safetensors", &best, "fp32 best", golden_bound(&best, GOLDEN_BF16));
    test_tiny("model.fp16.safetensors", &best, "fp16w best", GOLDEN_HALF);
    test_converted(&best);
    test_converted_bin(&best);
    test_vit_h_parameters();
    test_config();
    mx_ctx_destroy(&scalar);
    mx_ctx_destroy(&best);
    if (golden_bf16_ctx(&best, "test_nn_clip_vision") == 0) { /* bf16 arithmetic against the fp32 goldens */
        test_tiny("model.safetensors", &best, "bf16", GOLDEN_BF16);
        mx_ctx_destroy(&best);
    }
    return mx_test_finish("test_nn_clip_vision");
}
