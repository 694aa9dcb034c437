/* Single-file checkpoints (weights/single_file.h, torchzip.h, pickle.h, ldm_names.h).
 * Tiny SD1.x checkpoints are made from the tiny goldens: every diffusers name renamed to the LDM
 * layout by the converter's own inverse rules (and checked to come back unchanged), written as
 * .safetensors and as a torch.save zip (tests/util_ckpt.c), fp32 and fp16. Each converts to
 * the same tensors (names, shapes, dtypes, bytes) as the diffusers folders at the same --dtype.
 * Then the extras (schedule buffers, EMA copy, position_ids, --ema), the ControlNet in both key
 * styles, the architecture refusals, and hostile files: each refused with one message and no
 * output file. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../runtime/fileio.h"
#include "../runtime/json.h"
#include "../runtime/log.h"
#include "../weights/convert.h"
#include "../weights/ldm_names.h"
#include "../weights/safetensors.h"
#include "../weights/weights.h"
#include "util_ckpt.h"
#include "util_test.h"

static char tmp[256], golden[512];

static void in_tmp(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmp, name); }

/* ---- building LDM checkpoints from the goldens ---- */

typedef struct {
    mx_st_tensor t[4096];
    size_t n;
    mx_safetensors src[8];
    size_t n_src;
    void *bufs[4096];
    size_t n_bufs;
} ckpt;

static void ckpt_free(ckpt *c) {
    for (size_t i = 0; i < c->n; i++) free(c->t[i].name);
    for (size_t i = 0; i < c->n_src; i++) mx_st_close(&c->src[i]);
    for (size_t i = 0; i < c->n_bufs; i++) free(c->bufs[i]);
    memset(c, 0, sizeof *c);
}

static mx_st_tensor *ckpt_add(ckpt *c, const char *name, mx_st_dtype dt, int ndim, const int64_t *shape,
                              const void *data, size_t nbytes) {
    mx_st_tensor *t = &c->t[c->n++];
    t->name = strdup(name);
    t->dtype = dt;
    t->ndim = ndim;
    memcpy(t->shape, shape, sizeof(int64_t) * (size_t)ndim);
    t->data = data;
    t->nbytes = nbytes;
    return t;
}

static void *ckpt_own(ckpt *c, size_t n) { return c->bufs[c->n_bufs++] = calloc(1, n ? n : 1); }

static const mx_ldm_layout unet_tiny = {.layers_per_block = 1, .levels = 2, .up_attention = 2};
static const mx_ldm_layout cn_tiny = {.layers_per_block = 1, .levels = 2, .hint_convs = 8};
static const mx_ldm_layout vae_tiny = {.layers_per_block = 1, .levels = 4};
static const mx_ldm_layout clip_tiny = {0};

/* Adds the golden network FILE renamed to the LDM layout under prefix; checks each name's
 * round trip. Returns the number of tensors. */
static size_t add_golden(ckpt *c, const char *file, mx_ldm_net net, const mx_ldm_layout *l, const char *prefix) {
    char path[700];
    snprintf(path, sizeof path, "%s/%s", golden, file);
    mx_safetensors *f = &c->src[c->n_src];
    mx_status st;
    if (mx_st_open(f, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return 0;
    }
    c->n_src++;
    for (size_t i = 0; i < f->count; i++) {
        const mx_st_tensor *t = &f->tensors[i];
        char ldm[512], back[512], name[600];
        int ok = mx_diffusers_to_ldm(net, l, t->name, ldm, sizeof ldm) == 0;
        ok = ok && mx_ldm_to_diffusers(net, l, ldm, back, sizeof back) == 0 && !strcmp(back, t->name);
        if (!ok) {
            fprintf(stderr, "%s: '%s' -> '%s' -> '%s': no round trip\n", file, t->name, ldm, back);
            mx_test_failures++;
            continue;
        }
        snprintf(name, sizeof name, "%s%s", prefix, ldm);
        mx_st_tensor *o = ckpt_add(c, name, t->dtype, t->ndim, t->shape, t->data, t->nbytes);
        if (net == MX_LDM_VAE && mx_ldm_vae_attn_linear(t->name)) { /* LDM stores a 1x1 convolution */
            o->ndim = 4;
            o->shape[2] = o->shape[3] = 1;
        }
    }
    return f->count;
}

/* The schedule buffers, EMA bookkeeping and position_ids real LDM files carry. */
static void add_extras(ckpt *c, double beta_end) {
    int64_t n1000 = 1000, one = 1, pos_shape[2] = {1, 77};
    float *betas = ckpt_own(c, 4000), *ac = ckpt_own(c, 4000);
    double prod = 1, lo = sqrt(0.00085), hi = sqrt(beta_end);
    for (int i = 0; i < 1000; i++) {
        double s = lo + (hi - lo) * i / 999.0;
        betas[i] = (float)(s * s);
        prod *= 1 - s * s;
        ac[i] = (float)prod;
    }
    ckpt_add(c, "betas", MX_ST_F32, 1, &n1000, betas, 4000);
    ckpt_add(c, "alphas_cumprod", MX_ST_F32, 1, &n1000, ac, 4000);
    float *decay = ckpt_own(c, 4);
    *decay = 0.9999f;
    ckpt_add(c, "model_ema.decay", MX_ST_F32, 0, &one, decay, 4);
    int64_t *pos = ckpt_own(c, 77 * 8);
    for (int i = 0; i < 77; i++) pos[i] = i;
    ckpt_add(c, "cond_stage_model.transformer.text_model.embeddings.position_ids", MX_ST_I64, 2, pos_shape, pos, 77 * 8);
}

/* model_ema.<name without dots> for every UNet tensor, with every value negated. */
static void add_ema(ckpt *c) {
    size_t n = c->n;
    for (size_t i = 0; i < n; i++) {
        const mx_st_tensor *t = &c->t[i];
        if (strncmp(t->name, "model.diffusion_model.", 22) || t->dtype != MX_ST_F32) continue;
        char key[600] = "model_ema.";
        size_t k = strlen(key);
        for (const char *s = t->name + 6; *s; s++)
            if (*s != '.') key[k++] = *s;
        key[k] = 0;
        float *d = ckpt_own(c, t->nbytes);
        memcpy(d, t->data, t->nbytes);
        for (size_t j = 0; j < t->nbytes / 4; j++) d[j] = -d[j];
        ckpt_add(c, key, t->dtype, t->ndim, t->shape, d, t->nbytes);
    }
}

/* Names of the real SD1.5 files (v1-5-pruned-emaonly, control_v11p_sd15_*) and their diffusers
 * names, as diffusers' single-file conversion maps them: an anchor independent of the rules
 * under test (the round trip above cannot see a rule that is wrong both ways). */
static void test_known_names(void) {
    static const mx_ldm_layout sd15 = {.layers_per_block = 2, .levels = 4, .up_attention = 0xE, .hint_convs = 8};
    static const struct {
        mx_ldm_net net;
        const char *ldm, *diffusers;
    } known[] = {
        {MX_LDM_UNET, "time_embed.2.weight", "time_embedding.linear_2.weight"},
        {MX_LDM_UNET, "input_blocks.0.0.bias", "conv_in.bias"},
        {MX_LDM_UNET, "input_blocks.1.0.in_layers.0.weight", "down_blocks.0.resnets.0.norm1.weight"},
        {MX_LDM_UNET, "input_blocks.2.0.in_layers.2.weight", "down_blocks.0.resnets.1.conv1.weight"},
        {MX_LDM_UNET, "input_blocks.3.0.op.weight", "down_blocks.0.downsamplers.0.conv.weight"},
        {MX_LDM_UNET, "input_blocks.4.0.skip_connection.weight", "down_blocks.1.resnets.0.conv_shortcut.weight"},
        {MX_LDM_UNET, "input_blocks.8.1.transformer_blocks.0.attn2.to_k.weight",
         "down_blocks.2.attentions.1.transformer_blocks.0.attn2.to_k.weight"},
        {MX_LDM_UNET, "input_blocks.11.0.out_layers.3.bias", "down_blocks.3.resnets.1.conv2.bias"},
        {MX_LDM_UNET, "input_blocks.10.0.out_layers.0.weight", "down_blocks.3.resnets.0.norm2.weight"},
        {MX_LDM_UNET, "middle_block.1.proj_out.weight", "mid_block.attentions.0.proj_out.weight"},
        {MX_LDM_UNET, "middle_block.2.emb_layers.1.weight", "mid_block.resnets.1.time_emb_proj.weight"},
        {MX_LDM_UNET, "output_blocks.2.1.conv.weight", "up_blocks.0.upsamplers.0.conv.weight"},
        {MX_LDM_UNET, "output_blocks.5.2.conv.bias", "up_blocks.1.upsamplers.0.conv.bias"},
        {MX_LDM_UNET, "output_blocks.3.0.skip_connection.weight", "up_blocks.1.resnets.0.conv_shortcut.weight"},
        {MX_LDM_UNET, "output_blocks.11.1.transformer_blocks.0.norm3.weight",
         "up_blocks.3.attentions.2.transformer_blocks.0.norm3.weight"},
        {MX_LDM_UNET, "out.0.weight", "conv_norm_out.weight"},
        {MX_LDM_UNET, "out.2.bias", "conv_out.bias"},
        {MX_LDM_CONTROLNET, "input_hint_block.0.weight", "controlnet_cond_embedding.conv_in.weight"},
        {MX_LDM_CONTROLNET, "input_hint_block.10.weight", "controlnet_cond_embedding.blocks.4.weight"},
        {MX_LDM_CONTROLNET, "input_hint_block.14.bias", "controlnet_cond_embedding.conv_out.bias"},
        {MX_LDM_CONTROLNET, "zero_convs.11.0.weight", "controlnet_down_blocks.11.weight"},
        {MX_LDM_CONTROLNET, "middle_block_out.0.bias", "controlnet_mid_block.bias"},
        {MX_LDM_CONTROLNET, "input_blocks.7.1.proj_in.weight", "down_blocks.2.attentions.0.proj_in.weight"},
        {MX_LDM_VAE, "encoder.down.0.block.1.norm1.weight", "encoder.down_blocks.0.resnets.1.norm1.weight"},
        {MX_LDM_VAE, "encoder.down.2.block.0.nin_shortcut.weight", "encoder.down_blocks.2.resnets.0.conv_shortcut.weight"},
        {MX_LDM_VAE, "encoder.down.1.downsample.conv.bias", "encoder.down_blocks.1.downsamplers.0.conv.bias"},
        {MX_LDM_VAE, "decoder.up.3.block.2.conv2.weight", "decoder.up_blocks.0.resnets.2.conv2.weight"},
        {MX_LDM_VAE, "decoder.up.1.upsample.conv.weight", "decoder.up_blocks.2.upsamplers.0.conv.weight"},
        {MX_LDM_VAE, "encoder.mid.attn_1.proj_out.weight", "encoder.mid_block.attentions.0.to_out.0.weight"},
        {MX_LDM_VAE, "decoder.mid.attn_1.norm.weight", "decoder.mid_block.attentions.0.group_norm.weight"},
        {MX_LDM_VAE, "decoder.mid.block_2.norm2.bias", "decoder.mid_block.resnets.1.norm2.bias"},
        {MX_LDM_VAE, "encoder.norm_out.weight", "encoder.conv_norm_out.weight"},
        {MX_LDM_VAE, "post_quant_conv.weight", "post_quant_conv.weight"},
        {MX_LDM_CLIP, "text_model.encoder.layers.11.mlp.fc2.bias", "text_model.encoder.layers.11.mlp.fc2.bias"},
        {MX_LDM_CLIP, "embeddings.token_embedding.weight", "text_model.embeddings.token_embedding.weight"},
    };
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++) {
        char out[256];
        int ok = mx_ldm_to_diffusers(known[i].net, &sd15, known[i].ldm, out, sizeof out) == 0 &&
                 !strcmp(out, known[i].diffusers);
        if (!ok) fprintf(stderr, "'%s' should be '%s'\n", known[i].ldm, known[i].diffusers);
        CHECK(ok);
    }
    static const char *const not_names[] = {"input_blocks.3.1.proj_in.weight", "output_blocks.2.2.conv.weight",
                                            "middle_block.3.in_layers.0.weight", "input_blocks.1.0.in_layers.1.weight",
                                            "input_blocks.13.0.in_layers.0.weight", "zero_convs.0.0.weight"};
    for (size_t i = 0; i < sizeof not_names / sizeof not_names[0]; i++) {
        char out[256];
        CHECK(mx_ldm_to_diffusers(MX_LDM_UNET, &sd15, not_names[i], out, sizeof out) != 0);
    }
}

/* ---- converting and comparing ---- */

static int convert(const char *input, const char *cn_name, const char *cn_path, const char *out, mx_dtype dt, int fp16,
                   int ema, mx_status *st) {
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = input;
    o.output = out;
    o.dtype = dt;
    o.prefer_fp16 = fp16;
    o.ema = ema;
    char tok[600];
    snprintf(tok, sizeof tok, "%s/tokenizer", golden);
    o.tokenizer = tok;
    if (cn_path) {
        o.n_controlnets = 1;
        o.controlnets[0].name = cn_name;
        o.controlnets[0].dir = cn_path;
    }
    unlink(out);
    int rc = mx_convert(&o, NULL, st);
    if (rc) fprintf(stderr, "convert %s: %s\n", input ? input : cn_path, st->msg);
    return rc;
}

/* Every tensor prefix.* of `want` is in `got` with the same dtype, shape and bytes (values
 * negated when `negated`, the EMA case), and got has no other prefix.* tensor. */
static void compare_net(const char *got_path, const char *want_path, const char *prefix, int negated) {
    mx_weightfile *got, *want;
    mx_status st;
    if (mx_wf_open(&got, got_path, &st) || mx_wf_open(&want, want_path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return;
    }
    size_t pl = strlen(prefix), n_want = 0, n_got = 0, bad = 0;
    for (size_t i = 0; i < mx_wf_count(want); i++) {
        const mx_wtensor *w = mx_wf_tensor(want, i);
        if (strncmp(w->name, prefix, pl) || w->name[pl] != '.') continue;
        n_want++;
        const mx_wtensor *g = mx_wf_find(got, w->name);
        int same = g && g->dtype == w->dtype && g->ndim == w->ndim && g->nbytes == w->nbytes &&
                   !memcmp(g->shape, w->shape, sizeof(int64_t) * (size_t)w->ndim);
        if (same && !negated) same = !memcmp(g->data, w->data, w->nbytes);
        if (same && negated) {
            const float *a = g->data, *b = w->data;
            for (size_t j = 0; j < w->nbytes / 4 && same; j++) same = a[j] == -b[j];
        }
        if (!same && bad++ < 3) fprintf(stderr, "%s: tensor %s differs from %s\n", got_path, w->name, want_path);
    }
    for (size_t i = 0; i < mx_wf_count(got); i++) {
        const char *name = mx_wf_tensor(got, i)->name;
        n_got += !strncmp(name, prefix, pl) && name[pl] == '.';
    }
    if (n_got != n_want) fprintf(stderr, "%s: %zu %s tensors, %s has %zu\n", got_path, n_got, prefix, want_path, n_want);
    CHECK(bad == 0);
    CHECK(n_want > 0 && n_got == n_want);
    mx_wf_close(got);
    mx_wf_close(want);
}

/* The made config names the golden config's sizes. */
static void compare_config(const char *mxw, const char *key, const char *golden_cfg) {
    static const char *const fields[] = {"block_out_channels", "layers_per_block", "cross_attention_dim",
                                         "attention_head_dim", "down_block_types", "up_block_types",
                                         "in_channels", "out_channels", "latent_channels",
                                         "conditioning_embedding_out_channels", "hidden_size", "intermediate_size",
                                         "num_hidden_layers", "vocab_size", "max_position_embeddings",
                                         "num_encoder_blocks", "num_decoder_blocks", "encoder_block_out_channels",
                                         "decoder_block_out_channels"};
    mx_weightfile *wf;
    mx_status st;
    char path[700];
    snprintf(path, sizeof path, "%s/%s", golden, golden_cfg);
    size_t len;
    char *text = mx_read_file(path, 1 << 20, &len, &st);
    if (!text || mx_wf_open(&wf, mxw, &st)) {
        mx_test_failures++;
        free(text);
        return;
    }
    const char *made = mx_wf_meta(wf, key);
    mx_json *a = made ? mx_json_parse(made, strlen(made), key, &st) : NULL, *b = mx_json_parse(text, len, path, &st);
    CHECK(a && b);
    for (size_t i = 0; a && b && i < sizeof fields / sizeof fields[0]; i++) {
        const mx_json *x = mx_json_get(a, fields[i]), *y = mx_json_get(b, fields[i]);
        if (!y) continue;
        int same = x && mx_json_kind(x) == mx_json_kind(y);
        if (same && mx_json_kind(y) == MX_JSON_NUM) same = mx_json_num(x) == mx_json_num(y);
        if (same && mx_json_kind(y) == MX_JSON_ARR) {
            same = mx_json_len(x) == mx_json_len(y);
            for (size_t k = 0; same && k < mx_json_len(y); k++) {
                const mx_json *u = mx_json_at(x, k), *v = mx_json_at(y, k);
                same = mx_json_kind(v) == MX_JSON_NUM ? mx_json_num(u) == mx_json_num(v)
                                                      : mx_json_str(u) && mx_json_str(v) && !strcmp(mx_json_str(u), mx_json_str(v));
            }
        }
        if (!same) fprintf(stderr, "%s: config field %s differs from %s\n", key, fields[i], path);
        CHECK(same);
    }
    mx_json_free(a);
    mx_json_free(b);
    free(text);
    mx_wf_close(wf);
}

static void make_folder_references(const char *dt_name, mx_dtype dt, int fp16) {
    static const char *const nets[] = {"unet_tiny", "vae_tiny", "clip_tiny"};
    mx_status st;
    for (int i = 0; i < 3; i++) {
        char in[700], out[700], name[64];
        snprintf(in, sizeof in, "%s/%s", golden, nets[i]);
        snprintf(name, sizeof name, "ref_%s_%s%s.mxw", nets[i], dt_name, fp16 ? "_fp16src" : "");
        in_tmp(out, sizeof out, name);
        CHECK(convert(in, NULL, NULL, out, dt, fp16, 0, &st) == 0);
    }
    char cn[700], out[700], name[64];
    snprintf(cn, sizeof cn, "%s/controlnet_tiny", golden);
    snprintf(name, sizeof name, "ref_cn_%s%s.mxw", dt_name, fp16 ? "_fp16src" : "");
    in_tmp(out, sizeof out, name);
    CHECK(convert(NULL, "depth", cn, out, dt, fp16, 0, &st) == 0);
}

static void compare_with_references(const char *got, const char *dt_name, int fp16) {
    static const char *const nets[] = {"unet_tiny", "vae_tiny", "clip_tiny"}, *const prefixes[] = {"unet", "vae", "text_encoder"};
    for (int i = 0; i < 3; i++) {
        char ref[700], name[64];
        snprintf(name, sizeof name, "ref_%s_%s%s.mxw", nets[i], dt_name, fp16 ? "_fp16src" : "");
        in_tmp(ref, sizeof ref, name);
        compare_net(got, ref, prefixes[i], 0);
    }
    char ref[700], name[64];
    snprintf(name, sizeof name, "ref_cn_%s%s.mxw", dt_name, fp16 ? "_fp16src" : "");
    in_tmp(ref, sizeof ref, name);
    compare_net(got, ref, "controlnet_depth", 0);
}

/* The whole model (UNet, VAE, CLIP, extras) and a ControlNet file, in both containers. */
static void test_model_files(int fp16) {
    const char *var = fp16 ? ".fp16" : "";
    char f_unet[96], f_vae[96], f_clip[96], f_cn[96];
    snprintf(f_unet, sizeof f_unet, "unet_tiny/diffusion_pytorch_model%s.safetensors", var);
    snprintf(f_vae, sizeof f_vae, "vae_tiny/diffusion_pytorch_model%s.safetensors", var);
    snprintf(f_clip, sizeof f_clip, "clip_tiny/model%s.safetensors", var);
    snprintf(f_cn, sizeof f_cn, "controlnet_tiny/diffusion_pytorch_model%s.safetensors", var);
    ckpt *model = calloc(1, sizeof *model), *cn = calloc(1, sizeof *cn), *bare = calloc(1, sizeof *bare);
    add_golden(model, f_unet, MX_LDM_UNET, &unet_tiny, "model.diffusion_model.");
    add_golden(model, f_vae, MX_LDM_VAE, &vae_tiny, "first_stage_model.");
    add_golden(model, f_clip, MX_LDM_CLIP, &clip_tiny, "cond_stage_model.transformer.");
    add_extras(model, 0.012);
    add_golden(cn, f_cn, MX_LDM_CONTROLNET, &cn_tiny, "control_model.");
    add_golden(bare, f_cn, MX_LDM_CONTROLNET, &cn_tiny, "");
    char st_model[600], zip_model[600], zip_cn[600], st_cn[600];
    in_tmp(st_model, sizeof st_model, fp16 ? "model16.safetensors" : "model.safetensors");
    in_tmp(zip_model, sizeof zip_model, fp16 ? "model16.ckpt" : "model.ckpt");
    in_tmp(zip_cn, sizeof zip_cn, fp16 ? "control16.pth" : "control.pth");
    in_tmp(st_cn, sizeof st_cn, fp16 ? "control16.safetensors" : "control.safetensors");
    CHECK(mx_test_write_safetensors(st_model, model->t, model->n) == 0);
    CHECK(mx_test_write_torchzip(zip_model, model->t, model->n, 1) == 0);
    CHECK(mx_test_write_torchzip(zip_cn, cn->t, cn->n, 0) == 0);
    CHECK(mx_test_write_safetensors(st_cn, bare->t, bare->n) == 0);

    static const struct {
        const char *name;
        mx_dtype dt;
    } dts[2] = {{"f32", MX_F32}, {"f16", MX_F16}};
    for (int d = fp16; d < 2; d++) { /* fp16 sources only at f16: f32 would widen, as the folders do */
        make_folder_references(dts[d].name, dts[d].dt, fp16);
        char out[700];
        mx_status st;
        /* safetensors model + zip (.pth, control_model.*) ControlNet, and the reverse */
        in_tmp(out, sizeof out, "single_a.mxw");
        CHECK(convert(st_model, "depth", zip_cn, out, dts[d].dt, 0, 0, &st) == 0);
        compare_with_references(out, dts[d].name, fp16);
        mx_weightfile *wf;
        if (mx_wf_open(&wf, out, &st) == 0) {
            CHECK(mx_wf_meta(wf, "tokenizer.vocab") != NULL);
            CHECK(mx_wf_find(wf, "text_encoder.text_model.embeddings.position_ids") == NULL);
            mx_wf_close(wf);
        }
        compare_config(out, "unet.config", "unet_tiny/config.json");
        compare_config(out, "vae.config", "vae_tiny/config.json");
        compare_config(out, "controlnet_depth.config", "controlnet_tiny/config.json");
        in_tmp(out, sizeof out, "single_b.mxw");
        CHECK(convert(zip_model, "depth", st_cn, out, dts[d].dt, 0, 0, &st) == 0);
        compare_with_references(out, dts[d].name, fp16);
        /* a single-file ControlNet beside the folder model set works alone too */
        in_tmp(out, sizeof out, "single_c.mxw");
        CHECK(convert(NULL, "depth", zip_cn, out, dts[d].dt, 0, 0, &st) == 0);
    }
    ckpt_free(model);
    ckpt_free(cn);
    ckpt_free(bare);
    free(model);
    free(cn);
    free(bare);
}

static void test_ema(void) {
    ckpt *c = calloc(1, sizeof *c);
    add_golden(c, "unet_tiny/diffusion_pytorch_model.safetensors", MX_LDM_UNET, &unet_tiny, "model.diffusion_model.");
    add_ema(c);
    char file[600], out[600], ref[600];
    in_tmp(file, sizeof file, "ema.ckpt");
    in_tmp(out, sizeof out, "ema.mxw");
    in_tmp(ref, sizeof ref, "ref_unet_tiny_f32.mxw");
    CHECK(mx_test_write_torchzip(file, c->t, c->n, 1) == 0);
    mx_status st;
    CHECK(convert(file, NULL, NULL, out, MX_F32, 0, 0, &st) == 0); /* default: the non-EMA weights */
    compare_net(out, ref, "unet", 0);
    CHECK(convert(file, NULL, NULL, out, MX_F32, 0, 1, &st) == 0);
    compare_net(out, ref, "unet", 1);
    ckpt_free(c);
    free(c);
}

static int convert_vae(const char *input, const char *vae, const char *out, mx_status *st) {
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.input = input;
    o.vae = vae;
    o.output = out;
    o.dtype = MX_F32;
    unlink(out);
    int rc = mx_convert(&o, NULL, st);
    if (rc) fprintf(stderr, "convert --vae %s: %s\n", vae, st->msg);
    return rc;
}

/* --vae: a VAE file of its own (LDM names with a training-loss tensor beside them, values negated
 * so that the replacement shows) replaces the model file's VAE; a diffusers-named file too. */
static void test_vae(void) {
    ckpt *c = calloc(1, sizeof *c);
    add_golden(c, "vae_tiny/diffusion_pytorch_model.safetensors", MX_LDM_VAE, &vae_tiny, "");
    for (size_t i = 0; i < c->n; i++) {
        float *d = ckpt_own(c, c->t[i].nbytes);
        const float *s = c->t[i].data;
        for (size_t j = 0; j < c->t[i].nbytes / 4; j++) d[j] = -s[j];
        c->t[i].data = d;
    }
    int64_t one = 1;
    ckpt_add(c, "loss.logvar", MX_ST_F32, 1, &one, c->t[0].data, 4);
    char vae[600], model[600], out[600], ref_vae[600], ref_unet[600], golden_vae[700];
    in_tmp(vae, sizeof vae, "vae-ft.safetensors");
    in_tmp(model, sizeof model, "model.safetensors");
    in_tmp(out, sizeof out, "vae.mxw");
    in_tmp(ref_vae, sizeof ref_vae, "ref_vae_tiny_f32.mxw");
    in_tmp(ref_unet, sizeof ref_unet, "ref_unet_tiny_f32.mxw");
    snprintf(golden_vae, sizeof golden_vae, "%s/vae_tiny/diffusion_pytorch_model.safetensors", golden);
    CHECK(mx_test_write_safetensors(vae, c->t, c->n) == 0);
    mx_status st;
    CHECK(convert_vae(model, vae, out, &st) == 0);
    compare_net(out, ref_vae, "vae", 1);
    compare_net(out, ref_unet, "unet", 0);
    CHECK(convert_vae(NULL, golden_vae, out, &st) == 0);
    compare_net(out, ref_vae, "vae", 0);
    in_tmp(vae, sizeof vae, "control.pth"); /* a file without a VAE */
    CHECK(convert_vae(NULL, vae, out, &st) != 0 && strstr(st.msg, "no VAE found"));
    ckpt_free(c);
    free(c);
}

static int convert_taesd(const char *taesd, const char *out, mx_status *st) {
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.taesd = taesd;
    o.output = out;
    o.dtype = MX_F32;
    unlink(out);
    int rc = mx_convert(&o, NULL, st);
    if (rc) fprintf(stderr, "convert --taesd %s: %s\n", taesd, st->msg);
    return rc;
}

/* --taesd with the original files (taesd.py's Sequential indices), made from the taesd_tiny golden
 * by the inverse of the renaming: the same tensors and config as the AutoencoderTiny folder. */
static void test_taesd_files(void) {
    char path[700], dir[600], enc[700], dec[700], out[600], ref[600];
    snprintf(path, sizeof path, "%s/taesd_tiny/diffusion_pytorch_model.safetensors", golden);
    mx_safetensors f;
    mx_status st;
    if (mx_st_open(&f, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        mx_test_failures++;
        return;
    }
    ckpt *e = calloc(1, sizeof *e), *d = calloc(1, sizeof *d);
    for (size_t i = 0; i < f.count; i++) {
        const mx_st_tensor *t = &f.tensors[i];
        int enc_half = !strncmp(t->name, "encoder.layers.", 15);
        const char *s = t->name + 15; /* "encoder.layers." and "decoder.layers." */
        char *end, name[256];
        long k = strtol(s, &end, 10);
        CHECK(enc_half || !strncmp(t->name, "decoder.layers.", 15));
        snprintf(name, sizeof name, "%ld%s", enc_half ? k : k + 1, end);
        ckpt_add(enc_half ? e : d, name, t->dtype, t->ndim, t->shape, t->data, t->nbytes);
    }
    in_tmp(dir, sizeof dir, "taesd_orig");
    mkdir(dir, 0755);
    snprintf(enc, sizeof enc, "%s/taesd_encoder.safetensors", dir);
    snprintf(dec, sizeof dec, "%s/taesd_decoder.pth", dir);
    CHECK(mx_test_write_safetensors(enc, e->t, e->n) == 0);
    CHECK(mx_test_write_torchzip(dec, d->t, d->n, 0) == 0);
    in_tmp(out, sizeof out, "taesd.mxw");
    in_tmp(ref, sizeof ref, "ref_taesd.mxw");
    snprintf(path, sizeof path, "%s/taesd_tiny", golden);
    CHECK(convert_taesd(path, ref, &st) == 0);
    const char *given[2] = {dec, dir};
    for (int g = 0; g < 2; g++) {
        CHECK(convert_taesd(given[g], out, &st) == 0);
        compare_net(out, ref, "taesd", 0);
        compare_config(out, "taesd.config", "taesd_tiny/config.json");
    }
    unlink(enc); /* the decoder alone is not enough: the encoder is named */
    CHECK(convert_taesd(dec, out, &st) != 0 && strstr(st.msg, "taesd_encoder.* and taesd_decoder.*"));
    ckpt_free(e);
    ckpt_free(d);
    free(e);
    free(d);
    mx_st_close(&f);
}

/* ---- refusals ---- */

static void expect_refused(const char *file, int controlnet, const char *fragment) {
    char out[600];
    in_tmp(out, sizeof out, "refused.mxw");
    unlink(out);
    mx_convert_opts o;
    memset(&o, 0, sizeof o);
    o.output = out;
    o.dtype = MX_F16;
    if (controlnet) {
        o.n_controlnets = 1;
        o.controlnets[0].name = "x";
        o.controlnets[0].dir = file;
    } else {
        o.input = file;
    }
    mx_status st;
    mx_status_clear(&st);
    int rc = mx_convert(&o, NULL, &st);
    if (rc == 0 || !strstr(st.msg, fragment) || strchr(st.msg, '\n')) {
        fprintf(stderr, "%s: expected one line with '%s', got rc=%d '%s'\n", file, fragment, rc, st.msg);
        mx_test_failures++;
    }
    CHECK(access(out, F_OK) != 0);
}

static void write_model_variant(const char *name, const char *extra_name, int in_channels, double beta_end) {
    ckpt *c = calloc(1, sizeof *c);
    add_golden(c, "unet_tiny/diffusion_pytorch_model.safetensors", MX_LDM_UNET, &unet_tiny, "model.diffusion_model.");
    add_extras(c, beta_end);
    if (extra_name) {
        int64_t one = 1;
        ckpt_add(c, extra_name, MX_ST_F32, 1, &one, c->t[0].data, 4);
    }
    for (size_t i = 0; i < c->n; i++)
        if (!strcmp(c->t[i].name, "model.diffusion_model.input_blocks.0.0.weight") && in_channels != 4) {
            c->t[i].shape[1] = in_channels; /* zeros: only the shape matters here */
            c->t[i].nbytes = (size_t)(c->t[i].shape[0] * in_channels * 9 * 4);
            c->t[i].data = ckpt_own(c, c->t[i].nbytes);
        }
    char path[600];
    in_tmp(path, sizeof path, name);
    CHECK(mx_test_write_safetensors(path, c->t, c->n) == 0);
    ckpt_free(c);
    free(c);
}

static void test_other_architectures(void) {
    char p[600];
    write_model_variant("sdxl.safetensors", "conditioner.embedders.0.x", 4, 0.012);
    in_tmp(p, sizeof p, "sdxl.safetensors");
    expect_refused(p, 0, "SDXL");
    write_model_variant("sd2.safetensors", "cond_stage_model.model.ln_final.weight", 4, 0.012);
    in_tmp(p, sizeof p, "sd2.safetensors");
    expect_refused(p, 0, "2.x");
    write_model_variant("inpaint.safetensors", NULL, 9, 0.012);
    in_tmp(p, sizeof p, "inpaint.safetensors");
    expect_refused(p, 0, "9-channel inpainting UNet");
    write_model_variant("schedule.safetensors", NULL, 4, 0.02);
    in_tmp(p, sizeof p, "schedule.safetensors");
    expect_refused(p, 0, "alphas_cumprod");
    in_tmp(p, sizeof p, "model.safetensors"); /* a model file has no ControlNet */
    expect_refused(p, 1, "no ControlNet found");
}

/* A zip checkpoint whose data.pkl is `pickle` and whose one storage holds `storage_bytes`. */
static void write_hostile(const char *name, const void *pickle, size_t n, size_t storage_bytes, int method,
                          uint64_t declared) {
    char path[600];
    in_tmp(path, sizeof path, name);
    void *storage = calloc(1, storage_bytes ? storage_bytes : 1);
    mx_test_zip_entry e[3] = {
        {.name = "archive/data.pkl", .data = pickle, .size = n},
        {.name = "archive/data/0", .data = storage, .size = storage_bytes, .method = method, .declared_size = declared},
        {.name = "archive/version", .data = "3\n", .size = 2},
    };
    CHECK(mx_test_write_zip(path, e, 3) == 0);
    free(storage);
}

#define PK(s) s, sizeof(s) - 1
/* {'w': _rebuild_tensor_v2(('storage', FloatStorage, '0', 'cpu', NUMEL), OFFSET, (SIZE,), (1,), False, OrderedDict())} */
#define TENSOR_PICKLE(numel, offset, size)                                                                          \
    "\x80\x02}(X\x01\x00\x00\x00w" "ctorch._utils\n_rebuild_tensor_v2\n((X\x07\x00\x00\x00storage"                  \
    "ctorch\nFloatStorage\nX\x01\x00\x00\x00" "0X\x03\x00\x00\x00" "cpu" numel "tQ" offset "(" size "t(K\x01t\x89" \
    "ccollections\nOrderedDict\n)RtRu."

static void test_hostile(void) {
    char p[600];
    /* os.system("touch PWNED") through REDUCE: refused at the GLOBAL, before anything could run */
    write_hostile("os_system.ckpt", PK("\x80\x02}(X\x01\x00\x00\x00w" "cos\nsystem\nX\x0b\x00\x00\x00touch PWNEDtRu."), 16, 0, 0);
    in_tmp(p, sizeof p, "os_system.ckpt");
    expect_refused(p, 0, "global 'os.system' is not allowed");
    CHECK(access("PWNED", F_OK) != 0);
    /* builtins.eval through STACK_GLOBAL (protocol 4) */
    write_hostile("eval.ckpt", PK("\x80\x04}(\x8c\x01w\x8c\x08" "builtins\x8c\x04" "eval\x93\x8c\x04" "1+1\x85Ru."), 16, 0, 0);
    in_tmp(p, sizeof p, "eval.ckpt");
    expect_refused(p, 0, "global 'builtins.eval' is not allowed");
    /* INST/OBJ-style opcodes are not accepted at all */
    write_hostile("inst.ckpt", PK("\x80\x02(ios\nsystem\n."), 16, 0, 0);
    in_tmp(p, sizeof p, "inst.ckpt");
    expect_refused(p, 0, "is not allowed");
    /* a good tensor first, to show the pickle itself is well formed */
    write_hostile("good.ckpt", PK(TENSOR_PICKLE("K\x04", "K\x00", "K\x04")), 16, 0, 0);
    in_tmp(p, sizeof p, "good.ckpt");
    expect_refused(p, 0, "no SD1.x networks found"); /* it opens, it just holds no network */
    /* a storage declaring more elements than its entry holds */
    write_hostile("extent.ckpt", PK(TENSOR_PICKLE("K\x05", "K\x00", "K\x05")), 16, 0, 0);
    in_tmp(p, sizeof p, "extent.ckpt");
    expect_refused(p, 0, "its entry holds 16 bytes");
    /* a view past its storage (offset), and a huge declared size */
    write_hostile("offset.ckpt", PK(TENSOR_PICKLE("K\x04", "K\x02", "K\x04")), 16, 0, 0);
    in_tmp(p, sizeof p, "offset.ckpt");
    expect_refused(p, 0, "extends past its storage");
    write_hostile("huge.ckpt", PK(TENSOR_PICKLE("K\x04", "K\x00", "\x8a\x08\x00\x00\x00\x00\x00\x00\x00\x40")), 16, 0, 0);
    in_tmp(p, sizeof p, "huge.ckpt");
    expect_refused(p, 0, "extends past its storage");
    /* a zip entry declaring more bytes than the file has */
    write_hostile("declared.ckpt", PK(TENSOR_PICKLE("K\x04", "K\x00", "K\x04")), 16, 0, (uint64_t)1 << 31);
    in_tmp(p, sizeof p, "declared.ckpt");
    expect_refused(p, 0, "extend past the end of the file");
    /* a zip bomb: a compressed (DEFLATE) entry is refused without inflating anything */
    write_hostile("bomb.ckpt", PK(TENSOR_PICKLE("K\x04", "K\x00", "K\x04")), 16, 8, (uint64_t)1 << 40);
    in_tmp(p, sizeof p, "bomb.ckpt");
    expect_refused(p, 0, "is compressed (method 8)");
    /* a list appended to itself, and a dict set into itself */
    write_hostile("cycle.ckpt", PK("\x80\x02}(X\x01\x00\x00\x00w]q\x00h\x00" "au."), 16, 0, 0);
    in_tmp(p, sizeof p, "cycle.ckpt");
    expect_refused(p, 0, "cycle");
    write_hostile("cycle2.ckpt", PK("\x80\x02}q\x00X\x01\x00\x00\x00wh\x00s."), 16, 0, 0);
    in_tmp(p, sizeof p, "cycle2.ckpt");
    expect_refused(p, 0, "cycle");
    /* truncated pickle, memo read before write, stack underflow */
    write_hostile("trunc.ckpt", PK("\x80\x02}(X\xff\x00\x00\x00w"), 16, 0, 0);
    in_tmp(p, sizeof p, "trunc.ckpt");
    expect_refused(p, 0, "past the end");
    write_hostile("memo.ckpt", PK("\x80\x02h\x05."), 16, 0, 0);
    in_tmp(p, sizeof p, "memo.ckpt");
    expect_refused(p, 0, "memo entry 5");
    write_hostile("underflow.ckpt", PK("\x80\x02t."), 16, 0, 0);
    in_tmp(p, sizeof p, "underflow.ckpt");
    expect_refused(p, 0, "no mark");
    /* the legacy (pre-1.6) format: a bare pickle */
    in_tmp(p, sizeof p, "legacy.ckpt");
    FILE *f = fopen(p, "wb");
    if (f) {
        fwrite("\x80\x02\x8a\x0a", 1, 4, f);
        fclose(f);
    }
    expect_refused(p, 0, "legacy format");
}

/* Fuzz seeds (tests/fuzz/seeds/ckpt): the tiny model and ControlNet with every dimension shrunk to 1
 * (conv_in keeps its 4 channels, the hint its 3), as torch.save zips, plus the hostile files. */
static void shrink(ckpt *c) {
    static const uint16_t zeros[64];
    for (size_t i = 0; i < c->n; i++) {
        mx_st_tensor *t = &c->t[i];
        if (t->dtype == MX_ST_I64 || !strcmp(t->name, "alphas_cumprod")) continue;
        int keep = strstr(t->name, "input_blocks.0.0.weight") || strstr(t->name, "input_hint_block.0.weight");
        for (int d = 0; d < t->ndim; d++)
            if (!(keep && d == 1)) t->shape[d] = 1;
        t->dtype = MX_ST_F16;
        t->nbytes = keep ? (size_t)t->shape[1] * 2 : 2;
        t->data = zeros;
    }
}

static void write_seeds(const char *dir) {
    static const char *const hostile[] = {"os_system.ckpt", "eval.ckpt", "extent.ckpt", "huge.ckpt", "bomb.ckpt", "cycle.ckpt", "good.ckpt"};
    ckpt *m = calloc(1, sizeof *m), *cn = calloc(1, sizeof *cn);
    add_golden(m, "unet_tiny/diffusion_pytorch_model.safetensors", MX_LDM_UNET, &unet_tiny, "model.diffusion_model.");
    add_golden(m, "vae_tiny/diffusion_pytorch_model.safetensors", MX_LDM_VAE, &vae_tiny, "first_stage_model.");
    add_golden(m, "clip_tiny/model.safetensors", MX_LDM_CLIP, &clip_tiny, "cond_stage_model.transformer.");
    add_extras(m, 0.012);
    add_golden(cn, "controlnet_tiny/diffusion_pytorch_model.safetensors", MX_LDM_CONTROLNET, &cn_tiny, "control_model.");
    shrink(m);
    shrink(cn);
    char p[700];
    snprintf(p, sizeof p, "%s/model.ckpt", dir);
    CHECK(mx_test_write_torchzip(p, m->t, m->n, 1) == 0);
    snprintf(p, sizeof p, "%s/control.pth", dir);
    CHECK(mx_test_write_torchzip(p, cn->t, cn->n, 0) == 0);
    for (size_t i = 0; i < sizeof hostile / sizeof hostile[0]; i++) {
        char cmd[1600];
        snprintf(cmd, sizeof cmd, "cp %s/%s %s/", tmp, hostile[i], dir);
        CHECK(system(cmd) == 0);
    }
    ckpt_free(m);
    ckpt_free(cn);
    free(m);
    free(cn);
}

int main(void) {
    snprintf(tmp, sizeof tmp, "/tmp/mx_test_single_file_XXXXXX");
    if (!mkdtemp(tmp)) return 1;
    mx_test_path(golden, sizeof golden, "golden");
    mx_log_set_level(MX_LOG_WARN);
    test_known_names();
    test_model_files(0);
    test_model_files(1);
    test_ema();
    test_vae();
    test_taesd_files();
    test_other_architectures();
    test_hostile();
    if (getenv("MX_WRITE_CKPT_SEEDS")) write_seeds(getenv("MX_WRITE_CKPT_SEEDS"));
    if (getenv("MX_WRITE_CKPT_TINY")) { /* the tiny fp32 checkpoints, for tests/cli_run_net.sh */
        char cmd[1200];
        snprintf(cmd, sizeof cmd, "cp %s/model.ckpt %s/control.pth %s/", tmp, tmp, getenv("MX_WRITE_CKPT_TINY"));
        CHECK(system(cmd) == 0);
    }
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_weights_single_file");
}
