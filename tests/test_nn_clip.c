/* CLIP text encoder against transformers 4.39: golden/clip_tiny with fp32 weights (vs outputs)
 * and fp16 weights (vs outputs_fp16w), every hidden state, the pooled output and the last
 * hidden state ≤ 1e-4 rel L2; the scalar and the best kernels; a dry run sizes the arena.
 * With MATEX_FULL=1 also golden/sd15_clip (real CLIP ViT-L/14 size, golden-v1 weights). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/nn/clip.h"
#include "../runtime/fileio.h"
#include "../pipeline/nn/sd_pipeline.h"
#include "../runtime/log.h"
#include "../weights/convert.h"
#include "../weights/golden_rule.h"
#include "../weights/weights.h"
#include "../weights/safetensors.h"
#include "nn_golden.h"


static int load_config(const char *net, mx_clip_config *cfg) {
    char path[1024];
    size_t len;
    golden_path(path, sizeof path, net, "config.json");
    char *text = mx_read_file(path, (size_t)1 << 30, &len, NULL);
    mx_status st = {0};
    int ok = text && mx_clip_config_parse(cfg, text, len, path, &st) == 0;
    if (!ok) fprintf(stderr, "%s: %s\n", path, text ? st.msg : "cannot read");
    free(text);
    return ok ? 0 : -1;
}

/* input_ids [B, T] of the golden case's inputs.safetensors as int32. */
static int32_t *load_ids(const char *net, int *B, int *T) {
    char path[1024];
    golden_path(path, sizeof path, net, "inputs.safetensors");
    mx_safetensors sf;
    mx_status st = {0};
    if (mx_st_open(&sf, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return NULL;
    }
    const mx_st_tensor *t = mx_st_find(&sf, "input_ids");
    float *f = t && t->ndim == 2 ? mx_st_to_f32(&sf, t, &st) : NULL;
    int32_t *ids = NULL;
    if (f) {
        *B = (int)t->shape[0];
        *T = (int)t->shape[1];
        ids = malloc(sizeof(int32_t) * (size_t)(*B) * (size_t)(*T));
        for (int i = 0; ids && i < *B * *T; i++) ids[i] = (int32_t)f[i];
    }
    free(f);
    mx_st_close(&sf);
    return ids;
}

/* Runs the model on the golden inputs and compares every output of golden/NET/outputs_file. */
static void run_and_compare(const mx_clip *m, const mx_ctx *c, const char *net, const char *outputs_file,
                            const char *label) {
    int B, T;
    int32_t *ids = load_ids(net, &B, &T);
    CHECK(ids != NULL);
    if (!ids) return;
    int L = m->cfg.num_hidden_layers, C = m->cfg.hidden_size;
    size_t MC = (size_t)B * T * C;
    float *last = malloc(MC * sizeof(float)), *pooled = malloc((size_t)B * C * sizeof(float));
    float **hs = calloc((size_t)L + 1, sizeof *hs);
    for (int i = 0; i <= L; i++) hs[i] = malloc(MC * sizeof(float));
    mx_status st = {0};
    mx_arena measure, arena;
    mx_arena_measure(&measure);
    float *dlast = golden_dev_alloc(c, MC), *dpooled = golden_dev_alloc(c, (size_t)B * C);
    float **dhs = calloc((size_t)L + 1, sizeof *dhs);
    for (int i = 0; i <= L; i++) dhs[i] = golden_dev_alloc(c, MC);
    CHECK(mx_clip_forward(m, c, &measure, ids, B, T, dlast, dpooled, dhs, &st) == 0);
    CHECK(measure.peak > 0);
    double t0 = mx_now();
    golden_arena(c, &arena, measure.peak);
    int ok = mx_clip_forward(m, c, &arena, ids, B, T, dlast, dpooled, dhs, &st) == 0;
    printf("%s: forward of %d x %d tokens in %.3f s (arena %zu bytes)\n", label, B, T, mx_now() - t0, measure.peak);
    if (!ok) fprintf(stderr, "%s: %s\n", label, st.msg);
    CHECK(ok);
    CHECK(golden_fetch(c, last, dlast, MC) == 0 && golden_fetch(c, pooled, dpooled, (size_t)B * C) == 0);
    for (int i = 0; i <= L; i++) CHECK(golden_fetch(c, hs[i], dhs[i], MC) == 0);
    free(dhs);
    char path[1024], name[64], msg[160];
    golden_path(path, sizeof path, net, outputs_file);
    mx_safetensors sf;
    if (ok && mx_st_open(&sf, path, &st) == 0) {
        for (int i = -2; i <= L; i++) {
            const float *got = i == -2 ? last : i == -1 ? pooled : hs[i];
            size_t n = i == -1 ? (size_t)B * C : MC;
            if (i < 0)
                snprintf(name, sizeof name, "%s", i == -2 ? "last_hidden_state" : "pooler_output");
            else
                snprintf(name, sizeof name, "hidden_states.%d", i);
            const mx_st_tensor *t = mx_st_find(&sf, name);
            float *want = t ? mx_st_to_f32(&sf, t, &st) : NULL;
            CHECK(want != NULL && t->nbytes / 4 == n);
            snprintf(msg, sizeof msg, "%s %s", label, name);
            if (want && t->nbytes / 4 == n) mx_check_close(msg, got, want, n, golden_bound(c, GOLDEN_BF16));
            free(want);
        }
        mx_st_close(&sf);
    } else {
        CHECK(0);
    }
    mx_arena_destroy(&arena);
    for (int i = 0; i <= L; i++) free(hs[i]);
    free(hs);
    free(last);
    free(pooled);
    free(ids);
}

static void test_tiny(const char *weights_file, const char *outputs_file, const mx_ctx *c, const char *label) {
    const char *net = "clip_tiny";
    char path[1100];
    golden_path(path, sizeof path, net, weights_file);
    mx_clip_config cfg;
    CHECK(load_config(net, &cfg) == 0);
    CHECK(cfg.eos_token_id == 999 && cfg.num_hidden_layers == 2);
    mx_safetensors sf;
    mx_status st = {0};
    mx_binder b, db = {0};
    mx_clip *m = NULL;
    if (mx_st_open(&sf, path, &st) || mx_binder_st(&b, &sf, "", &st) || mx_binder_device(&db, &b, c, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    int ok = mx_clip_load(&m, &cfg, &db, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    mx_st_close(&sf); /* the safetensors binder keeps its own copies */
    if (ok) run_and_compare(m, c, net, outputs_file, label);
    if (ok) {
        int32_t ids[2] = {0, 1000}; /* 1000 is past the tiny vocabulary */
        float out[2 * 32];
        mx_arena a;
        CHECK(mx_arena_create(&a, 1 << 20, &st) == 0);
        CHECK(mx_clip_forward(m, c, &a, ids, 1, 2, out, NULL, NULL, &st) != 0 && strstr(st.msg, "1000"));
        mx_arena_destroy(&a);
    }
    mx_clip_free(m);
    mx_binder_free(&db);
    mx_binder_free(&b);
}

/* The production path: `matex convert` of the clip_tiny folder, config from the metadata
 * "text_encoder.config", weights bound with the prefix "text_encoder.". */
static void test_converted(const mx_ctx *c) {
    char dir[1024], path[256];
    golden_path(dir, sizeof dir, "clip_tiny", "");
    snprintf(path, sizeof path, "/tmp/matex_test_clip_%d.mxw", (int)getpid());
    mx_convert_opts opts = {0};
    opts.input = dir;
    opts.output = path;
    opts.dtype = MX_F32;
    mx_convert_result res;
    mx_status st = {0};
    mx_weightfile *wf = NULL;
    mx_binder b = {0}, db = {0};
    mx_clip *m = NULL;
    mx_clip_config cfg;
    const char *cfg_text = NULL;
    int ok = mx_convert(&opts, &res, &st) == 0 && mx_wf_open(&wf, path, &st) == 0;
    if (ok) cfg_text = mx_wf_meta(wf, "text_encoder.config");
    ok = ok && cfg_text && mx_clip_config_parse(&cfg, cfg_text, strlen(cfg_text), "text_encoder.config", &st) == 0 &&
         mx_binder_wf(&b, wf, "text_encoder.", &st) == 0 && mx_binder_device(&db, &b, c, &st) == 0 &&
         mx_clip_load(&m, &cfg, &db, &st) == 0;
    if (!ok) fprintf(stderr, "converted clip_tiny: %s\n", cfg_text || !wf ? st.msg : "no text_encoder.config");
    CHECK(ok);
    if (ok) run_and_compare(m, c, "clip_tiny", "outputs.safetensors", "converted");
    mx_clip_free(m);
    mx_binder_free(&db);
    mx_binder_free(&b);
    if (wf) mx_wf_close(wf);
    remove(path);
}

/* Loading errors name the tensor; an enumerating binder lists every parameter. */
static void test_enumerate_and_errors(void) {
    mx_clip_config cfg;
    mx_clip_config_sd15(&cfg);
    mx_binder b;
    mx_status st = {0};
    mx_clip *m = NULL;
    CHECK(mx_binder_enum(&b, &st) == 0);
    CHECK(mx_clip_load(&m, &cfg, &b, &st) == 0);
    CHECK(mx_binder_enum_count(&b) == 196); /* golden sd15_clip: 196 float tensors */
    CHECK(mx_binder_enum_bytes(&b) == (size_t)123060480 * 4);
    mx_clip_free(m);
    mx_binder_free(&b);
    const char *bad = "{\"hidden_size\": 30, \"num_attention_heads\": 4}";
    CHECK(mx_clip_config_parse(&cfg, bad, strlen(bad), "bad.json", &st) != 0);
    CHECK(strstr(st.msg, "bad.json") != NULL);
    const char *act = "{\"hidden_act\": \"relu\"}";
    CHECK(mx_clip_config_parse(&cfg, act, strlen(act), "act.json", &st) != 0);
}

/* A binder that makes each parameter by the golden-v1 rule when it is asked for. */
typedef struct golden_binder {
    void **bufs;
    size_t n;
} golden_binder;

static int bind_golden(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out,
                       mx_status *st) {
    golden_binder *g = b->impl;
    size_t numel = 1;
    for (int i = 0; i < ndim; i++) numel *= (size_t)shape[i];
    float *p = malloc(numel * sizeof(float));
    void **bufs = realloc(g->bufs, (g->n + 1) * sizeof *bufs);
    if (!p || !bufs) {
        free(p);
        return mx_fail(st, MX_ENOMEM, "out of memory for %s", name);
    }
    g->bufs = bufs;
    g->bufs[g->n++] = p;
    mx_golden_v1_fill(name, ndim, shape, 1, p);
    *out = mx_w_f32(p);
    return 0;
}

/* Text to embeddings in one call (tokenizer + encoder) on the prompts of the sd15_clip inputs. */
static void check_prompt_path(const mx_clip *m, const mx_ctx *c, const char *net) {
    char v[1024], mg[1024], path[1100];
    golden_path(v, sizeof v, "tokenizer", "vocab.json");
    golden_path(mg, sizeof mg, "tokenizer", "merges.txt");
    golden_path(path, sizeof path, net, "outputs.safetensors");
    const char *prompts[2] = {"front and back view of a red leather jacket", ""};
    mx_tokenizer *tok = NULL;
    mx_status st = {0};
    mx_safetensors sf;
    size_t n = (size_t)2 * 77 * m->cfg.hidden_size;
    float *got = malloc(n * sizeof(float)), *want = NULL;
    int dropped[2] = {-1, -1};
    int ok = got && mx_tok_load_files(&tok, v, mg, &st) == 0 &&
             mx_sd_encode_prompts(c, m, tok, prompts, 2, got, dropped, &st) == 0 && mx_st_open(&sf, path, &st) == 0;
    if (!ok) fprintf(stderr, "prompt path: %s\n", st.msg);
    CHECK(ok);
    if (ok) {
        const mx_st_tensor *t = mx_st_find(&sf, "last_hidden_state");
        want = t && t->nbytes / 4 == n ? mx_st_to_f32(&sf, t, &st) : NULL;
        CHECK(want != NULL && dropped[0] == 0 && dropped[1] == 0);
        if (want) mx_check_close("sd15 prompts -> embeddings", got, want, n, golden_bound(c, GOLDEN_BF16));
        mx_st_close(&sf);
    }
    mx_tok_free(tok);
    free(got);
    free(want);
}

static void test_sd15(const mx_ctx *c) {
    const char *net = "sd15_clip";
    if (!golden_have(net, "inputs.safetensors") || !golden_have(net, "outputs.safetensors")) return;
    mx_clip_config cfg;
    CHECK(load_config(net, &cfg) == 0);
    golden_binder g = {0};
    mx_binder b = {0}, db = {0};
    b.bind = bind_golden;
    b.impl = &g;
    mx_clip *m = NULL;
    mx_status st = {0};
    int ok = mx_binder_device(&db, &b, c, &st) == 0 && mx_clip_load(&m, &cfg, &db, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    char label[32];
    golden_label(label, sizeof label, c, "sd15");
    if (ok) run_and_compare(m, c, net, "outputs.safetensors", label);
    if (ok) check_prompt_path(m, c, net);
    mx_clip_free(m);
    mx_binder_free(&db);
    for (size_t i = 0; i < g.n; i++) free(g.bufs[i]);
    free(g.bufs);
}

int main(void) {
    mx_ctx scalar, best;
    mx_status st = {0};
    if (mx_ctx_create_on(&scalar, golden_device(), 1, MX_ISA_SCALAR, 16 << 20, &st) ||
        mx_ctx_create_on(&best, golden_device(), 2, mx_cpu_isa_for(MX_PREC_FP32), 16 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return 1;
    }
    test_tiny("model.safetensors", "outputs.safetensors", &scalar, "fp32 scalar");
    test_tiny("model.safetensors", "outputs.safetensors", &best, "fp32 best");
    test_tiny("model.fp16.safetensors", "outputs_fp16w.safetensors", &best, "fp16w best");
    test_converted(&best);
    test_enumerate_and_errors();
    const char *full = getenv("MATEX_FULL");
    if (full && !strcmp(full, "1")) test_sd15(&best);
    mx_ctx_destroy(&scalar);
    mx_ctx_destroy(&best);
    if (golden_bf16_ctx(&best, "test_nn_clip") == 0) { /* bf16 arithmetic against the fp32 goldens */
        test_tiny("model.safetensors", "outputs.safetensors", &best, "bf16");
        if (full && !strcmp(full, "1")) test_sd15(&best);
        mx_ctx_destroy(&best);
    }
    return mx_test_finish("test_nn_clip");
}
