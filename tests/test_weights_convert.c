/* The converter: single network folders (f32 exact, f16 rounding, fp16 variant), a model-set
 * folder with tokenizer, scheduler and named ControlNets, a sharded index, LoRA merges in
 * both key styles checked against a direct computation, and bad inputs (one error, no
 * output file). Uses golden/{unet,controlnet,vae,clip}_tiny of tests/data. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../runtime/json.h"
#include "../runtime/log.h"
#include "../weights/convert.h"
#include "../weights/safetensors.h"
#include "../weights/weights.h"
#include "util_test.h"

static char tmp[256], golden[512];

static void in_tmp(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmp, name); }

/* The tiny golden cases are all in tests/data: one folder holds them. */
static void golden_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", golden, name); }

static void link_into(const char *target, const char *linkname) {
    if (symlink(target, linkname)) fprintf(stderr, "symlink %s -> %s failed\n", linkname, target);
}

static int convert_one(const char *input, const char *out, mx_dtype dt, int fp16, mx_status *st) {
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = input;
    o.output = out;
    o.dtype = dt;
    o.prefer_fp16 = fp16;
    return mx_convert(&o, NULL, st);
}

static float half_to_float(uint16_t h) {
    int e = (h >> 10) & 31, m = h & 1023;
    double v = e == 0 ? ldexp(m, -24) : ldexp(1024 + m, e - 25);
    return (float)(h & 0x8000 ? -v : v);
}

static float value_at(const mx_wtensor *t, size_t i) {
    if (t->dtype == MX_F16) {
        uint16_t h;
        memcpy(&h, (const uint8_t *)t->data + 2 * i, 2);
        return half_to_float(h);
    }
    return ((const float *)t->data)[i];
}

/* Every tensor of the safetensors file appears as prefix.name with the same shape; values
 * equal exactly (want_exact) or within fp16 rounding. */
static void compare_with_source(const mx_weightfile *wf, const char *st_path, const char *prefix, int want_exact) {
    mx_safetensors f;
    mx_status st;
    if (mx_st_open(&f, st_path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return;
    }
    size_t bad = 0;
    for (size_t i = 0; i < f.count; i++) {
        const mx_st_tensor *s = &f.tensors[i];
        char name[600];
        snprintf(name, sizeof name, "%s.%s", prefix, s->name);
        const mx_wtensor *t = mx_wf_require(wf, name, s->ndim, s->shape, &st);
        if (!t) {
            fprintf(stderr, "%s\n", st.msg);
            bad++;
            continue;
        }
        if (s->ndim == 1 && t->dtype != MX_F32) bad++;
        float *ref = mx_st_to_f32(&f, s, &st);
        for (size_t k = 0; k < t->nbytes / mx_dtype_size(t->dtype); k++) {
            float v = value_at(t, k), r = ref[k];
            if (want_exact ? v != r : fabsf(v - r) > fabsf(r) / 1024 + 1e-7f) bad++;
        }
        free(ref);
    }
    CHECK(bad == 0);
    mx_st_close(&f);
}

static void test_single_networks(void) {
    static const char *nets[4][3] = {{"unet_tiny", "unet", "diffusion_pytorch_model"},
                                     {"controlnet_tiny", "controlnet", "diffusion_pytorch_model"},
                                     {"vae_tiny", "vae", "diffusion_pytorch_model"},
                                     {"clip_tiny", "text_encoder", "model"}};
    for (int i = 0; i < 4; i++) {
        char in[600], out[600], src[700], src16[700], key[64];
        golden_path(in, sizeof in, nets[i][0]);
        in_tmp(out, sizeof out, "single.mxw");
        snprintf(src, sizeof src, "%s/%s.safetensors", in, nets[i][2]);
        snprintf(src16, sizeof src16, "%s/%s.fp16.safetensors", in, nets[i][2]);
        mx_status st;
        mx_weightfile *wf;
        CHECK(convert_one(in, out, MX_F32, 0, &st) == 0);
        if (mx_wf_open(&wf, out, &st) == 0) {
            compare_with_source(wf, src, nets[i][1], 1);
            snprintf(key, sizeof key, "%s.config", nets[i][1]);
            const char *cfg = mx_wf_meta(wf, key);
            mx_json *j = cfg ? mx_json_parse(cfg, strlen(cfg), key, &st) : NULL;
            CHECK(j != NULL);
            mx_json_free(j);
            const char *prov = mx_wf_meta(wf, "provenance");
            j = prov ? mx_json_parse(prov, strlen(prov), "provenance", &st) : NULL;
            CHECK(j && !strcmp(mx_json_get_str(j, "dtype", ""), "f32"));
            mx_json_free(j);
            mx_wf_close(wf);
        } else {
            CHECK(!"converted file opens");
        }
        /* default f16 from fp32 sources: within fp16 rounding; fp16 variant: exact */
        CHECK(convert_one(in, out, MX_F16, 0, &st) == 0);
        if (mx_wf_open(&wf, out, &st) == 0) {
            compare_with_source(wf, src, nets[i][1], 0);
            mx_wf_close(wf);
        }
        CHECK(convert_one(in, out, MX_F16, 1, &st) == 0);
        if (mx_wf_open(&wf, out, &st) == 0) {
            compare_with_source(wf, src16, nets[i][1], 1);
            mx_wf_close(wf);
        }
    }
}

static void test_model_set(void) {
    char set[600], p[700], q[700], out[600];
    in_tmp(set, sizeof set, "set");
    if (mkdir(set, 0755)) return;
    static const char *subs[5][2] = {{"unet", "unet_tiny"}, {"controlnet", "controlnet_tiny"}, {"vae", "vae_tiny"},
                                     {"text_encoder", "clip_tiny"}, {"tokenizer", "tokenizer"}};
    for (int i = 0; i < 5; i++) {
        golden_path(q, sizeof q, subs[i][1]);
        snprintf(p, sizeof p, "%s/%s", set, subs[i][0]);
        link_into(q, p);
    }
    snprintf(p, sizeof p, "%s/scheduler", set);
    mkdir(p, 0755);
    golden_path(q, sizeof q, "pipeline_controlnet_tiny/scheduler_config.json");
    snprintf(p, sizeof p, "%s/scheduler/scheduler_config.json", set);
    link_into(q, p);

    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = set;
    in_tmp(out, sizeof out, "set.mxw");
    o.output = out;
    o.dtype = MX_F16;
    o.n_controlnets = 2;
    char cdir[600];
    golden_path(cdir, sizeof cdir, "controlnet_tiny");
    o.controlnets[0].name = "depth";
    o.controlnets[0].dir = cdir;
    o.controlnets[1].name = "inpaint";
    o.controlnets[1].dir = cdir;
    mx_status st;
    mx_convert_result res;
    int rc = mx_convert(&o, &res, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    CHECK(rc == 0 && res.networks == 6);
    mx_weightfile *wf;
    if (mx_wf_open(&wf, out, &st)) {
        CHECK(!"model set converted");
        return;
    }
    CHECK(mx_wf_find(wf, "unet.conv_in.weight") && mx_wf_find(wf, "controlnet.conv_in.weight"));
    CHECK(mx_wf_find(wf, "controlnet_depth.conv_in.weight") && mx_wf_find(wf, "controlnet_inpaint.conv_in.weight"));
    CHECK(mx_wf_find(wf, "vae.decoder.conv_in.weight") != NULL);
    CHECK(mx_wf_find(wf, "text_encoder.text_model.final_layer_norm.weight") != NULL);
    static const char *keys[] = {"unet.config", "controlnet.config", "controlnet_depth.config", "controlnet_inpaint.config",
                                 "vae.config", "text_encoder.config", "tokenizer.vocab", "tokenizer.merges",
                                 "scheduler.config", "provenance"};
    for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++) CHECK(mx_wf_meta(wf, keys[i]) != NULL);
    const char *vocab = mx_wf_meta(wf, "tokenizer.vocab");
    CHECK(vocab && strlen(vocab) > 100000);
    mx_wf_close(wf);

    /* a folder of the wrong type in a model set is refused */
    snprintf(p, sizeof p, "%s/vae", set);
    unlink(p);
    golden_path(q, sizeof q, "unet_tiny");
    link_into(q, p);
    unlink(out);
    o.n_controlnets = 0;
    CHECK(mx_convert(&o, NULL, &st) == -1 && strstr(st.msg, "expected a vae"));
    CHECK(access(out, F_OK) != 0);
}

/* A sharded copy of vae_tiny (two shards and an index) converts to the same tensors. */
static void test_sharded(void) {
    char dir[600], p[700], q[700], out[600], src[700];
    in_tmp(dir, sizeof dir, "sharded");
    mkdir(dir, 0755);
    golden_path(q, sizeof q, "vae_tiny/config.json");
    snprintf(p, sizeof p, "%s/config.json", dir);
    link_into(q, p);
    golden_path(src, sizeof src, "vae_tiny/diffusion_pytorch_model.safetensors");
    mx_safetensors f;
    mx_status st;
    if (mx_st_open(&f, src, &st)) return;
    mx_st_out *outs = calloc(f.count, sizeof *outs);
    float **vals = calloc(f.count, sizeof *vals);
    size_t half = f.count / 2;
    snprintf(p, sizeof p, "%s/diffusion_pytorch_model.safetensors.index.json", dir);
    FILE *idx = fopen(p, "w");
    fprintf(idx, "{\"metadata\": {}, \"weight_map\": {");
    for (size_t i = 0; i < f.count; i++) {
        vals[i] = mx_st_to_f32(&f, &f.tensors[i], &st);
        outs[i].name = f.tensors[i].name;
        outs[i].dtype = MX_ST_F32;
        outs[i].ndim = f.tensors[i].ndim;
        memcpy(outs[i].shape, f.tensors[i].shape, sizeof outs[i].shape);
        outs[i].data = vals[i];
        fprintf(idx, "%s\"%s\": \"shard-%d.safetensors\"", i ? ", " : "", f.tensors[i].name, i < half ? 1 : 2);
    }
    fprintf(idx, "}}");
    fclose(idx);
    snprintf(p, sizeof p, "%s/shard-1.safetensors", dir);
    CHECK(mx_st_write(p, outs, half, &st) == 0);
    snprintf(p, sizeof p, "%s/shard-2.safetensors", dir);
    CHECK(mx_st_write(p, outs + half, f.count - half, &st) == 0);
    in_tmp(out, sizeof out, "sharded.mxw");
    CHECK(convert_one(dir, out, MX_F32, 0, &st) == 0);
    mx_weightfile *wf;
    if (mx_wf_open(&wf, out, &st) == 0) {
        CHECK(mx_wf_count(wf) == f.count);
        compare_with_source(wf, src, "vae", 1);
        mx_wf_close(wf);
    }
    for (size_t i = 0; i < f.count; i++) free(vals[i]);
    free(vals);
    free(outs);
    mx_st_close(&f);
}

/* ---- LoRA ---- */

typedef struct {
    const char *target; /* tensor in the network, e.g. "down_blocks.0....to_q.weight" */
    const char *down_key, *up_key, *alpha_key;
    int rank, conv_shaped; /* conv_shaped 1: up/down stored as [.., .., 1, 1]; 3: down [r, in, 3, 3] */
    float alpha;
} lora_case;

/* Writes the LoRA file for the cases; down/up values come from a seed. */
static void write_lora(const char *path, const lora_case *cases, int n, const int64_t *out_in, float **down,
                       float **up) {
    mx_st_out outs[16];
    static float alphas[8];
    int k = 0;
    for (int c = 0; c < n; c++) {
        int64_t r = cases[c].rank, o = out_in[2 * c], in = out_in[2 * c + 1];
        down[c] = malloc((size_t)(r * in) * sizeof(float));
        up[c] = malloc((size_t)(o * r) * sizeof(float));
        mx_fill_random(down[c], (size_t)(r * in), 100 + (uint64_t)c, -1, 1);
        mx_fill_random(up[c], (size_t)(o * r), 200 + (uint64_t)c, -1, 1);
        int k3 = cases[c].conv_shaped == 3;
        outs[k++] = (mx_st_out){cases[c].down_key, MX_ST_F32, cases[c].conv_shaped ? 4 : 2,
                                {r, k3 ? in / 9 : in, k3 ? 3 : 1, k3 ? 3 : 1}, down[c]};
        outs[k++] = (mx_st_out){cases[c].up_key, MX_ST_F32, cases[c].conv_shaped ? 4 : 2, {o, r, 1, 1}, up[c]};
        if (cases[c].alpha_key) {
            alphas[c] = cases[c].alpha;
            outs[k++] = (mx_st_out){cases[c].alpha_key, MX_ST_F32, 0, {0}, &alphas[c]};
        }
    }
    mx_status st;
    CHECK(mx_st_write(path, outs, (size_t)k, &st) == 0);
}

/* Converts `net_dir` with the LoRA at `scale` and checks each target against
 * W + scale * (alpha / rank) * up @ down computed here, and every other tensor unchanged. */
static void check_lora(const char *net_dir, const char *src_file, const char *prefix, const lora_case *cases, int n,
                       float scale) {
    char in[600], src[700], lora[600], out[600];
    golden_path(in, sizeof in, net_dir);
    snprintf(src, sizeof src, "%s/%s", in, src_file);
    in_tmp(lora, sizeof lora, "lora.safetensors");
    in_tmp(out, sizeof out, "lora.mxw");
    mx_safetensors f;
    mx_status st;
    if (mx_st_open(&f, src, &st)) {
        CHECK(!"source opens");
        return;
    }
    int64_t out_in[16];
    for (int c = 0; c < n; c++) {
        const mx_st_tensor *t = mx_st_find(&f, cases[c].target);
        CHECK(t != NULL);
        if (!t) return;
        out_in[2 * c] = t->shape[0];
        out_in[2 * c + 1] = (int64_t)(t->nbytes / 4) / t->shape[0];
    }
    float *down[8], *up[8];
    write_lora(lora, cases, n, out_in, down, up);
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = in;
    o.output = out;
    o.dtype = MX_F32;
    o.n_loras = 1;
    o.loras[0].path = lora;
    o.loras[0].scale = scale;
    mx_convert_result res;
    int rc = mx_convert(&o, &res, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    CHECK(rc == 0 && res.lora_merged == (size_t)n);
    mx_weightfile *wf;
    if (!rc && mx_wf_open(&wf, out, &st) == 0) {
        for (size_t i = 0; i < f.count; i++) {
            const mx_st_tensor *s = &f.tensors[i];
            char name[600];
            snprintf(name, sizeof name, "%s.%s", prefix, s->name);
            const mx_wtensor *t = mx_wf_find(wf, name);
            float *w = mx_st_to_f32(&f, s, &st);
            size_t numel = s->nbytes / 4;
            int c = 0;
            while (c < n && strcmp(cases[c].target, s->name)) c++;
            if (c < n) {
                int64_t O = out_in[2 * c], I = out_in[2 * c + 1], r = cases[c].rank;
                double factor = scale * (cases[c].alpha_key ? cases[c].alpha : (double)r) / (double)r;
                for (int64_t a = 0; a < O; a++)
                    for (int64_t b = 0; b < I; b++) {
                        double d = 0;
                        for (int64_t k = 0; k < r; k++) d += (double)up[c][a * r + k] * down[c][k * I + b];
                        w[a * I + b] = (float)(w[a * I + b] + factor * d);
                    }
                char label[700];
                snprintf(label, sizeof label, "lora %s", name);
                mx_check_close(label, (const float *)t->data, w, numel, 1e-6);
                CHECK(mx_rel_l2((const float *)t->data, (const float *)s->data, numel) > 1e-3); /* it changed */
            } else {
                CHECK(t && !memcmp(t->data, w, numel * 4));
            }
            free(w);
        }
        const char *prov = mx_wf_meta(wf, "provenance");
        CHECK(prov && strstr(prov, "lora.safetensors"));
        mx_wf_close(wf);
    }
    for (int c = 0; c < n; c++) free(down[c]), free(up[c]);
    mx_st_close(&f);
}

static void test_lora(void) {
    const lora_case diffusers_unet[] = {
        {"down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.weight",
         "unet.down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.lora_A.weight",
         "unet.down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.lora_B.weight",
         "unet.down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.alpha", 3, 0, 1.5f},
        /* 1x1 conv weight [32, 32, 1, 1] with a linear-shaped LoRA, no alpha */
        {"down_blocks.0.attentions.0.proj_in.weight", "down_blocks.0.attentions.0.proj_in.lora.down.weight",
         "down_blocks.0.attentions.0.proj_in.lora.up.weight", NULL, 2, 0, 0},
        /* attention-processor style */
        {"up_blocks.1.attentions.0.transformer_blocks.0.attn2.to_out.0.weight",
         "unet.up_blocks.1.attentions.0.transformer_blocks.0.attn2.processor.to_out_lora.down.weight",
         "unet.up_blocks.1.attentions.0.transformer_blocks.0.attn2.processor.to_out_lora.up.weight", NULL, 4, 0, 0},
    };
    const lora_case kohya_unet[] = {
        {"down_blocks.0.attentions.0.transformer_blocks.0.attn2.to_k.weight",
         "lora_unet_down_blocks_0_attentions_0_transformer_blocks_0_attn2_to_k.lora_down.weight",
         "lora_unet_down_blocks_0_attentions_0_transformer_blocks_0_attn2_to_k.lora_up.weight",
         "lora_unet_down_blocks_0_attentions_0_transformer_blocks_0_attn2_to_k.alpha", 4, 0, 2.0f},
        {"mid_block.attentions.0.proj_out.weight", "lora_unet_mid_block_attentions_0_proj_out.lora_down.weight",
         "lora_unet_mid_block_attentions_0_proj_out.lora_up.weight", "lora_unet_mid_block_attentions_0_proj_out.alpha",
         2, 1, 1.0f},
    };
    const lora_case kohya_te[] = {
        {"text_model.encoder.layers.0.self_attn.q_proj.weight",
         "lora_te_text_model_encoder_layers_0_self_attn_q_proj.lora_down.weight",
         "lora_te_text_model_encoder_layers_0_self_attn_q_proj.lora_up.weight",
         "lora_te_text_model_encoder_layers_0_self_attn_q_proj.alpha", 2, 0, 4.0f},
        {"text_model.encoder.layers.1.mlp.fc1.weight", "lora_te_text_model_encoder_layers_1_mlp_fc1.lora_down.weight",
         "lora_te_text_model_encoder_layers_1_mlp_fc1.lora_up.weight", NULL, 3, 0, 0},
    };
    const lora_case peft_te[] = {
        {"text_model.encoder.layers.1.self_attn.v_proj.weight",
         "text_encoder.text_model.encoder.layers.1.self_attn.v_proj.lora_A.weight",
         "text_encoder.text_model.encoder.layers.1.self_attn.v_proj.lora_B.weight", NULL, 5, 0, 0},
    };
    /* the module kinds of the LCM-LoRA for SD1.5 (its trainer targets to_q/k/v/out.0, proj_in/out,
     * ff.net.0.proj/ff.net.2, conv1/conv2/conv_shortcut, down/upsampler convs, time_emb_proj; 3x3
     * convs get a 3x3 down and a 1x1 up), in the kohya keys with alpha of the published file */
    const lora_case lcm_kohya[] = {
        {"down_blocks.0.resnets.0.conv1.weight", "lora_unet_down_blocks_0_resnets_0_conv1.lora_down.weight",
         "lora_unet_down_blocks_0_resnets_0_conv1.lora_up.weight", "lora_unet_down_blocks_0_resnets_0_conv1.alpha", 4, 3,
         8.0f},
        {"down_blocks.1.resnets.0.time_emb_proj.weight", "lora_unet_down_blocks_1_resnets_0_time_emb_proj.lora_down.weight",
         "lora_unet_down_blocks_1_resnets_0_time_emb_proj.lora_up.weight",
         "lora_unet_down_blocks_1_resnets_0_time_emb_proj.alpha", 4, 0, 8.0f},
        {"up_blocks.0.upsamplers.0.conv.weight", "lora_unet_up_blocks_0_upsamplers_0_conv.lora_down.weight",
         "lora_unet_up_blocks_0_upsamplers_0_conv.lora_up.weight", "lora_unet_up_blocks_0_upsamplers_0_conv.alpha", 2, 3,
         1.0f},
        {"up_blocks.0.resnets.1.conv_shortcut.weight", "lora_unet_up_blocks_0_resnets_1_conv_shortcut.lora_down.weight",
         "lora_unet_up_blocks_0_resnets_1_conv_shortcut.lora_up.weight",
         "lora_unet_up_blocks_0_resnets_1_conv_shortcut.alpha", 3, 1, 8.0f},
    };
    /* the same kinds in diffusers/PEFT keys (lora_A / lora_B, no alpha) */
    const lora_case lcm_peft[] = {
        {"mid_block.resnets.0.conv1.weight", "unet.mid_block.resnets.0.conv1.lora_A.weight",
         "unet.mid_block.resnets.0.conv1.lora_B.weight", NULL, 4, 3, 0},
        {"down_blocks.0.downsamplers.0.conv.weight", "unet.base_model.model.down_blocks.0.downsamplers.0.conv.lora_A.weight",
         "unet.base_model.model.down_blocks.0.downsamplers.0.conv.lora_B.weight", NULL, 2, 3, 0},
        {"mid_block.attentions.0.transformer_blocks.0.ff.net.0.proj.weight",
         "unet.mid_block.attentions.0.transformer_blocks.0.ff.net.0.proj.lora_A.weight",
         "unet.mid_block.attentions.0.transformer_blocks.0.ff.net.0.proj.lora_B.weight", NULL, 4, 0, 0},
    };
    /* each set of cases converted with its network at a LoRA scale */
#define CASES(a) a, (int)(sizeof a / sizeof a[0])
    const struct {
        const char *net_dir, *src_file, *prefix;
        const lora_case *cases;
        int n;
        float scale;
    } sets[] = {
        {"unet_tiny", "diffusion_pytorch_model.safetensors", "unet", CASES(diffusers_unet), 0.7f},
        {"unet_tiny", "diffusion_pytorch_model.safetensors", "unet", CASES(kohya_unet), -1.25f},
        {"clip_tiny", "model.safetensors", "text_encoder", CASES(kohya_te), 1.0f},
        {"clip_tiny", "model.safetensors", "text_encoder", CASES(peft_te), 0.5f},
        {"unet_tiny", "diffusion_pytorch_model.safetensors", "unet", CASES(lcm_kohya), 1.0f},
        {"unet_tiny", "diffusion_pytorch_model.safetensors", "unet", CASES(lcm_peft), 1.0f},
    };
    for (size_t k = 0; k < sizeof sets / sizeof sets[0]; k++)
        check_lora(sets[k].net_dir, sets[k].src_file, sets[k].prefix, sets[k].cases, sets[k].n, sets[k].scale);
#undef CASES
}

/* ---- bad input: an error naming the problem and no output file ---- */

static void expect_fail(mx_convert_opts *o, const char *fragment) {
    mx_status st;
    mx_status_clear(&st);
    unlink(o->output);
    int rc = mx_convert(o, NULL, &st);
    CHECK(rc == -1);
    if (rc == 0 || !strstr(st.msg, fragment)) {
        fprintf(stderr, "expected an error with '%s', got rc=%d '%s'\n", fragment, rc, st.msg);
        mx_test_failures++;
    }
    CHECK(access(o->output, F_OK) != 0);
}

static void write_file(const char *path, const void *p, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f) return;
    if (fwrite(p, 1, n, f) != n) fprintf(stderr, "short write\n");
    fclose(f);
}

static void test_bad_inputs(void) {
    char out[600], dir[600], p[700], q[700];
    in_tmp(out, sizeof out, "bad.mxw");
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.output = out;
    o.dtype = MX_F16;

    in_tmp(dir, sizeof dir, "missing");
    o.input = dir;
    expect_fail(&o, "not a folder");

    in_tmp(dir, sizeof dir, "empty");
    mkdir(dir, 0755);
    expect_fail(&o, "not a diffusers folder");

    /* config.json of an unknown type */
    snprintf(p, sizeof p, "%s/config.json", dir);
    write_file(p, "{\"_class_name\": \"Foo\"}", 22);
    expect_fail(&o, "unknown network type");
    /* broken JSON */
    write_file(p, "{\"_class_name\": ", 16);
    expect_fail(&o, "invalid JSON");
    /* a UNet config without weights */
    golden_path(q, sizeof q, "unet_tiny/config.json");
    unlink(p);
    link_into(q, p);
    expect_fail(&o, "no weights found");
    /* a truncated safetensors file */
    char src[700];
    golden_path(src, sizeof src, "unet_tiny/diffusion_pytorch_model.safetensors");
    FILE *f = fopen(src, "rb");
    static unsigned char head[100000];
    size_t n = f ? fread(head, 1, sizeof head, f) : 0;
    if (f) fclose(f);
    snprintf(p, sizeof p, "%s/diffusion_pytorch_model.safetensors", dir);
    write_file(p, head, n);
    expect_fail(&o, "outside the data area");

    /* LoRA problems */
    golden_path(dir, sizeof dir, "unet_tiny");
    o.input = dir;
    o.n_loras = 1;
    char lora[600];
    in_tmp(lora, sizeof lora, "bad_lora.safetensors");
    o.loras[0].path = lora;
    o.loras[0].scale = 1;
    float a[64 * 64] = {0};
    mx_st_out unmatched[2] = {{"unet.no_such_block.to_q.lora_A.weight", MX_ST_F32, 2, {2, 32}, a},
                              {"unet.no_such_block.to_q.lora_B.weight", MX_ST_F32, 2, {32, 2}, a}};
    mx_status st;
    mx_st_write(lora, unmatched, 2, &st);
    expect_fail(&o, "matches no UNet");
    mx_st_out wrong_shape[2] = {
        {"unet.down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.lora_A.weight", MX_ST_F32, 2, {2, 33}, a},
        {"unet.down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_q.lora_B.weight", MX_ST_F32, 2, {32, 2}, a}};
    mx_st_write(lora, wrong_shape, 2, &st);
    expect_fail(&o, "does not fit");
    mx_st_out half[1] = {{"lora_unet_x.lora_down.weight", MX_ST_F32, 2, {2, 32}, a}};
    mx_st_write(lora, half, 1, &st);
    expect_fail(&o, "lacks its up");
    mx_st_out odd[1] = {{"something.else", MX_ST_F32, 2, {2, 32}, a}};
    mx_st_write(lora, odd, 1, &st);
    expect_fail(&o, "unrecognized LoRA key");
    o.n_loras = 0;

    /* bad ControlNet name and a ControlNet folder holding something else */
    o.input = NULL;
    o.n_controlnets = 1;
    o.controlnets[0].name = "Depth!";
    golden_path(dir, sizeof dir, "controlnet_tiny");
    o.controlnets[0].dir = dir;
    expect_fail(&o, "name must be");
    o.controlnets[0].name = "depth";
    golden_path(dir, sizeof dir, "vae_tiny");
    expect_fail(&o, "expected a controlnet");
}

/* The few-step path's parts: --taesd adds taesd.* and its config; --lcm-lora merges like --lora
 * and records unet.lcm_lora (only one LCM-LoRA allowed). */
static void test_fast_path_parts(void) {
    char unet[600], taesd[600], lora[600], out[600];
    golden_path(unet, sizeof unet, "unet_tiny");
    golden_path(taesd, sizeof taesd, "taesd_tiny");
    in_tmp(lora, sizeof lora, "lcm.safetensors");
    in_tmp(out, sizeof out, "fast.mxw");
    float down[2 * 128], up[32 * 2];
    mx_fill_random(down, 2 * 128, 1, -1, 1);
    mx_fill_random(up, 32 * 2, 2, -1, 1);
    mx_st_out t[2] = {{"lora_unet_down_blocks_0_resnets_0_time_emb_proj.lora_down.weight", MX_ST_F32, 2, {2, 128}, down},
                      {"lora_unet_down_blocks_0_resnets_0_time_emb_proj.lora_up.weight", MX_ST_F32, 2, {32, 2}, up}};
    mx_status st;
    CHECK(mx_st_write(lora, t, 2, &st) == 0);
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = unet;
    o.output = out;
    o.dtype = MX_F16;
    o.taesd = taesd;
    o.n_loras = 1;
    o.loras[0].path = lora;
    o.loras[0].scale = 1.0f;
    o.loras[0].lcm = 1;
    mx_convert_result res;
    int rc = mx_convert(&o, &res, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    CHECK(rc == 0 && res.networks == 2 && res.lora_merged == 1);
    mx_weightfile *wf;
    if (!rc && mx_wf_open(&wf, out, &st) == 0) {
        const char *mark = mx_wf_meta(wf, "unet.lcm_lora");
        CHECK(mark && strstr(mark, "lcm.safetensors"));
        CHECK(mx_wf_meta(wf, "taesd.config") && mx_wf_find(wf, "taesd.decoder.layers.18.weight"));
        mx_wf_close(wf);
    }
    o.n_loras = 2;
    o.loras[1] = o.loras[0];
    CHECK(mx_convert(&o, &res, &st) == -1 && strstr(st.msg, "more than one LCM-LoRA"));
    o.n_loras = 0;
    o.input = NULL;
    o.taesd = unet; /* a UNet folder is not a TAESD */
    CHECK(mx_convert(&o, &res, &st) == -1 && strstr(st.msg, "expected a taesd"));
}

int main(void) {
    snprintf(tmp, sizeof tmp, "/tmp/mx_test_convert_XXXXXX");
    if (!mkdtemp(tmp)) return 1;
    mx_test_path(golden, sizeof golden, "golden");
    char *abs = realpath(golden, NULL); /* symlinks made in tmp need an absolute target */
    if (abs && strlen(abs) < sizeof golden) memcpy(golden, abs, strlen(abs) + 1);
    free(abs);
    mx_log_set_level(MX_LOG_WARN);
    test_single_networks();
    test_fast_path_parts();
    test_model_set();
    test_sharded();
    test_lora();
    test_bad_inputs();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_weights_convert");
}
