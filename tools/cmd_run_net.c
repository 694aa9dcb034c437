/* matex run-net NET --weights W --inputs IN.safetensors --out OUT.safetensors: runs one network
 * on tensors from a safetensors file and writes its outputs (the parity and debugging tool). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "../pipeline/nn/clip.h"
#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/sd_edit.h"
#include "../pipeline/texture/models.h"
#include "../pipeline/nn/taesd.h"
#include "../pipeline/nn/unet.h"
#include "../pipeline/nn/vae.h"
#include "../runtime/log.h"
#include "../weights/safetensors.h"
#include "../weights/weights.h"
#include "cli.h"
#include "cli_args.h"

#define MAX_OUTS (MX_UNET_MAX_RES + 4)
#define SCRATCH_BYTES ((size_t)256 << 20)

static void usage(FILE *f) {
    fprintf(f,
            "usage: matex run-net NET --weights W.mxw --inputs IN.safetensors --out OUT.safetensors [options]\n"
            "\n"
            "Runs one network of a matex weight file on the tensors of IN and writes its outputs (fp32).\n"
            "NET and its tensors (B = batch; any batch and any valid size):\n"
            "  unet        sample [B,C,H,W], timestep [B] or [1] (I64, I32 or F32), encoder_hidden_states [B,T,D],\n"
            "              optional down_block_res_sample.{i} and mid_block_res_sample   -> out\n"
            "  controlnet  sample, timestep, encoder_hidden_states, controlnet_cond [B,3,8H,8W],\n"
            "              conditioning_scale (one float, default 1)  -> down_block_res_sample.{i}, mid_block_res_sample\n"
            "  vae-encode  image [B,3,H,W] in [-1,1]                  -> mean, logvar\n"
            "  vae-decode  latents [B,4,h,w] (unscaled)               -> image\n"
            "  clip        input_ids [B,T] (I64 or I32)               -> last_hidden_state, pooler_output, hidden_states.{i}\n"
            "  taesd-encode  image [B,3,H,W] in [-1,1]                -> latents (SD latents, scaling factor 1)\n"
            "  taesd-decode  latents [B,4,h,w]                        -> image (in about [-1,1], unclamped)\n"
            "  inpaint-pipeline  (W: a model set with controlnet_depth and controlnet_inpaint; --steps N [--guidance G])\n"
            "              prompt_embeds, negative_prompt_embeds [B,T,D], image [B,3,H,W] in [0,1], mask [B,1,H,W]\n"
            "              (1 = paint), control_depth, control_inpaint [B,3,H,W], noise [B,4,H/8,W/8],\n"
            "              conditioning_scales [2] (depth, inpaint)  -> timesteps, latents_after_step, image\n"
            "  img2img-pipeline  (W: a model set with a depth ControlNet; --steps N [--guidance G])\n"
            "              prompt_embeds, negative_prompt_embeds, image, control_depth, noise, strength [1],\n"
            "              optional conditioning_scales [1] (default 1)  -> timesteps, latents_after_step, image\n"
            "\n"
            "options:\n"
            "  --prefix P      network prefix in the weight file (default unet., controlnet., vae., taesd., text_encoder.;\n"
            "                  e.g. controlnet_depth. for a file with several ControlNets)\n"
            "  --threads N     worker threads (default: all CPUs)\n"
            "  --steps N       pipelines: scheduler steps before strength (required)\n"
            "  --guidance G    pipelines: classifier-free guidance scale (default 7.5)\n"
            "  --device D      cpu (default), cpu-strict (activations guarded: tests) or cuda (`make cuda` builds)\n"
            "  --precision P   fp32 (default) or bf16: bf16 products with fp32 sums where the CPU has\n"
            "                  AVX512_BF16 (linear, conv, attention); elsewhere fp32 with a warning\n"
            "  -h, --help      this help\n");
}

/* Everything one invocation holds; released by io_free. */
typedef struct run_io {
    const char *in_path, *out_path;
    mx_safetensors in;
    int in_open;
    mx_weightfile *wf;
    mx_binder wb, b; /* the weight file's binder; b keeps the weights on the device */
    mx_ctx ctx;
    int ctx_ok;
    mx_arena arena;
    int arena_ok;
    float *tmp[MAX_OUTS * 2];
    int ntmp;
    float *dev[MAX_OUTS * 2]; /* device copies of inputs and outputs */
    int ndev;
    float *out_dev[MAX_OUTS]; /* device output i, fetched into outs[i].data after the run */
    size_t out_n[MAX_OUTS];
    mx_st_out outs[MAX_OUTS];
    char names[MAX_OUTS][48];
    int nout;
} run_io;

static float *keep(run_io *io, float *p) {
    if (p && io->ntmp < (int)(sizeof io->tmp / sizeof io->tmp[0])) io->tmp[io->ntmp++] = p;
    else free(p);
    return p;
}

static float *new_floats(run_io *io, size_t n, mx_status *st) {
    float *p = keep(io, calloc(n ? n : 1, sizeof(float)));
    if (!p) mx_fail(st, MX_ENOMEM, "out of memory (%zu floats)", n);
    return p;
}

/* Input tensor as fp32 with its shape checked: want[i] = -1 accepts any size (filled in). */
static float *input(run_io *io, const char *name, int ndim, int64_t *want, int required, mx_status *st) {
    const mx_st_tensor *t = mx_st_find(&io->in, name);
    if (!t) {
        if (required) mx_fail(st, MX_EINPUT, "%s: missing input tensor %s", io->in_path, name);
        return NULL;
    }
    int ok = t->ndim == ndim;
    for (int i = 0; ok && i < ndim; i++) ok = want[i] < 0 ? t->shape[i] > 0 : t->shape[i] == want[i];
    if (!ok) {
        char got[96], exp[96];
        mx_shape_str(t->ndim, t->shape, got, sizeof got);
        mx_shape_str(ndim, want, exp, sizeof exp);
        mx_fail(st, MX_EINPUT, "%s: tensor %s has shape %s, expected %s (-1: any)", io->in_path, name, got, exp);
        return NULL;
    }
    for (int i = 0; i < ndim; i++) {
        if (t->shape[i] > 1 << 20) {
            mx_fail(st, MX_EINPUT, "%s: tensor %s: dimension %d is too large", io->in_path, name, i);
            return NULL;
        }
        want[i] = t->shape[i];
    }
    return keep(io, mx_st_to_f32(&io->in, t, st));
}

/* Timesteps: one per batch item or a single one (any dtype, any shape of 1 or B elements). */
static float *timesteps(run_io *io, int B, mx_status *st) {
    const mx_st_tensor *t = mx_st_find(&io->in, "timestep");
    if (!t) return mx_fail(st, MX_EINPUT, "%s: missing input tensor timestep", io->in_path), NULL;
    int64_t n = t->ndim == 0 ? 1 : mx_shape_numel(t->ndim, t->shape);
    if (n != 1 && n != B)
        return mx_fail(st, MX_EINPUT, "%s: tensor timestep has %lld elements, expected 1 or %d", io->in_path,
                       (long long)n, B), NULL;
    float *v = keep(io, mx_st_to_f32(&io->in, t, st)), *ts = new_floats(io, (size_t)B, st);
    if (!v || !ts) return NULL;
    for (int i = 0; i < B; i++) ts[i] = v[n == 1 ? 0 : i];
    return ts;
}

/* Device memory for n floats, a copy of host data when host is not NULL (freed by io_free). */
static float *on_device(run_io *io, const float *host, size_t n, mx_status *st) {
    if (io->ndev == (int)(sizeof io->dev / sizeof io->dev[0])) return mx_fail(st, MX_EINTERNAL, "too many tensors"), NULL;
    float *p = host ? mx_dev_from_host(&io->ctx, host, n, st) : mx_dev_alloc(&io->ctx, n, st);
    if (p) io->dev[io->ndev++] = p;
    return p;
}

/* The device copy of an optional host input (NULL stays NULL); *err set on failure. */
static const float *dev_input(run_io *io, const float *host, size_t n, int *err, mx_status *st) {
    if (!host) return NULL;
    const float *p = on_device(io, host, n, st);
    if (!p) *err = 1;
    return p;
}

/* A network output: n floats on the device, written as `name` after the run. NULL on failure. */
static float *dev_output(run_io *io, const char *name, int ndim, const int64_t *shape, mx_status *st);

/* The edge out: every device output into its host buffer. */
static int fetch_outputs(run_io *io, mx_status *st) {
    for (int i = 0; i < io->nout; i++)
        if (io->out_dev[i] && mx_download(&io->ctx, (float *)io->outs[i].data, io->out_dev[i], io->out_n[i], st))
            return -1;
    return 0;
}

static int add_output(run_io *io, const char *name, int ndim, const int64_t *shape, const float *data, mx_status *st) {
    if (io->nout == MAX_OUTS) return mx_fail(st, MX_EINTERNAL, "too many outputs");
    mx_st_out *o = &io->outs[io->nout];
    snprintf(io->names[io->nout], sizeof io->names[0], "%s", name);
    o->name = io->names[io->nout];
    o->dtype = MX_ST_F32;
    o->ndim = ndim;
    memcpy(o->shape, shape, (size_t)ndim * sizeof *shape);
    o->data = data;
    io->nout++;
    return 0;
}

static float *dev_output(run_io *io, const char *name, int ndim, const int64_t *shape, mx_status *st) {
    size_t n = (size_t)mx_shape_numel(ndim, shape);
    float *host = new_floats(io, n, st), *d = host ? on_device(io, NULL, n, st) : NULL;
    if (!d || add_output(io, name, ndim, shape, host, st)) return NULL;
    io->out_dev[io->nout - 1] = d;
    io->out_n[io->nout - 1] = n;
    return d;
}

static int make_arena(run_io *io, size_t bytes, mx_status *st) {
    if (mx_arena_create_on(&io->arena, io->ctx.be, bytes, st)) return -1;
    io->arena_ok = 1;
    return 0;
}

/* The binder of the network under `prefix`: weight file, weights kept on the device. */
static int bind_weights(run_io *io, const char *prefix, mx_status *st) {
    return mx_binder_wf(&io->wb, io->wf, prefix, st) || mx_binder_device(&io->b, &io->wb, &io->ctx, st) ? -1 : 0;
}

/* Config text of the network under `prefix` ("<prefix>config" metadata). */
static const char *net_config(run_io *io, const char *prefix, char *key, size_t cap, mx_status *st) {
    snprintf(key, cap, "%sconfig", prefix);
    const char *cfg = mx_wf_meta(io->wf, key);
    if (!cfg) mx_fail(st, MX_EINPUT, "%s: no metadata \"%s\" (wrong --prefix?)", mx_wf_path(io->wf), key);
    return cfg;
}

static int run_unet(run_io *io, const char *prefix, mx_status *st) {
    char key[96];
    mx_unet_config cfg;
    mx_unet *u = NULL;
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_unet_config_parse(&cfg, text, strlen(text), key, st)) return -1;
    if (bind_weights(io, prefix, st) || mx_unet_load(&u, &cfg, &io->b, st)) return -1;
    int rc = -1;
    int64_t ss[4] = {-1, cfg.in_channels, -1, -1}, es[3] = {-1, -1, cfg.cross_attention_dim};
    float *sample = input(io, "sample", 4, ss, 1, st), *ehs = NULL, *ts = NULL, *out;
    if (sample) es[0] = ss[0];
    if (sample) ehs = input(io, "encoder_hidden_states", 3, es, 1, st);
    if (ehs) ts = timesteps(io, (int)ss[0], st);
    if (!ts) goto done;
    int B = (int)ss[0], H = (int)ss[2], W = (int)ss[3], n = mx_unet_num_residuals(&cfg), C, h, w;
    const float *res[MX_UNET_MAX_RES];
    mx_unet_input in = {sample, ts, ehs, B, H, W, (int)es[1], NULL, NULL};
    if (mx_unet_check_sizes(&cfg, B, H, W, in.T, st)) goto done;
    int have = mx_st_find(&io->in, "down_block_res_sample.0") != NULL;
    for (int i = 0; i <= n && (have || mx_st_find(&io->in, "mid_block_res_sample")); i++) {
        char name[48];
        if (i < n) snprintf(name, sizeof name, "down_block_res_sample.%d", i);
        else snprintf(name, sizeof name, "mid_block_res_sample");
        mx_unet_residual_shape(&cfg, i, H, W, &C, &h, &w);
        int64_t rs[4] = {B, C, h, w};
        const float *p = input(io, name, 4, rs, 1, st);
        if (!p) goto done;
        if (i < n) res[i] = p;
        else in.mid_residual = p;
    }
    if (have) in.down_residuals = res;
    size_t bytes;
    int64_t os[4] = {B, cfg.out_channels, H, W};
    int err = 0;
    in.sample = dev_input(io, sample, (size_t)B * cfg.in_channels * H * W, &err, st);
    in.timesteps = dev_input(io, ts, (size_t)B, &err, st);
    in.encoder_hidden_states = dev_input(io, ehs, (size_t)B * in.T * cfg.cross_attention_dim, &err, st);
    for (int i = 0; i <= n && (have || in.mid_residual); i++) {
        mx_unet_residual_shape(&cfg, i, H, W, &C, &h, &w);
        if (i < n && have) res[i] = dev_input(io, res[i], (size_t)B * C * h * w, &err, st);
        if (i == n) in.mid_residual = dev_input(io, in.mid_residual, (size_t)B * C * h * w, &err, st);
    }
    if (err || !(out = dev_output(io, "out", 4, os, st))) goto done;
    if (mx_unet_arena_bytes(u, B, H, W, in.T, &bytes, st) || make_arena(io, bytes, st) ||
        mx_unet_forward(&io->ctx, u, &in, out, &io->arena, st))
        goto done;
    rc = 0;
done:
    mx_unet_free(u);
    return rc;
}

static int run_controlnet(run_io *io, const char *prefix, mx_status *st) {
    char key[96];
    mx_unet_config cfg;
    mx_controlnet *m = NULL;
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_unet_config_parse(&cfg, text, strlen(text), key, st)) return -1;
    if (!cfg.is_controlnet) return mx_fail(st, MX_EINPUT, "%s: \"%s\" is not a ControlNetModel config", mx_wf_path(io->wf), key);
    if (bind_weights(io, prefix, st) || mx_controlnet_load(&m, &cfg, &io->b, st)) return -1;
    int rc = -1, n = mx_unet_num_residuals(&cfg), f = 1 << (cfg.n_cond_emb - 1), C, h, w;
    int64_t ss[4] = {-1, cfg.in_channels, -1, -1}, es[3] = {-1, -1, cfg.cross_attention_dim}, cs[4], one[1] = {1};
    float *sample = input(io, "sample", 4, ss, 1, st), *ehs = NULL, *ts = NULL, *cond = NULL, *scale = NULL;
    float *down[MX_UNET_MAX_RES + 1];
    if (sample) {
        es[0] = ss[0];
        ehs = input(io, "encoder_hidden_states", 3, es, 1, st);
    }
    if (ehs) ts = timesteps(io, (int)ss[0], st);
    if (ts) {
        cs[0] = ss[0], cs[1] = cfg.conditioning_channels, cs[2] = ss[2] * f, cs[3] = ss[3] * f;
        cond = input(io, "controlnet_cond", 4, cs, 1, st);
    }
    if (!cond) goto done;
    if (mx_st_find(&io->in, "conditioning_scale") && !(scale = input(io, "conditioning_scale", 1, one, 1, st))) goto done;
    int B = (int)ss[0], H = (int)ss[2], W = (int)ss[3];
    mx_controlnet_input in = {sample, ts, ehs, cond, B, H, W, (int)es[1], scale ? scale[0] : 1.0f};
    if (mx_unet_check_sizes(&cfg, B, H, W, in.T, st)) goto done;
    int err = 0;
    in.sample = dev_input(io, sample, (size_t)B * cfg.in_channels * H * W, &err, st);
    in.timesteps = dev_input(io, ts, (size_t)B, &err, st);
    in.encoder_hidden_states = dev_input(io, ehs, (size_t)B * in.T * cfg.cross_attention_dim, &err, st);
    in.cond = dev_input(io, cond, (size_t)B * cs[1] * cs[2] * cs[3], &err, st);
    if (err) goto done;
    for (int i = 0; i <= n; i++) {
        char name[48];
        mx_unet_residual_shape(&cfg, i, H, W, &C, &h, &w);
        int64_t rs[4] = {B, C, h, w};
        if (i < n) snprintf(name, sizeof name, "down_block_res_sample.%d", i);
        else snprintf(name, sizeof name, "mid_block_res_sample");
        if (!(down[i] = dev_output(io, name, 4, rs, st))) goto done;
    }
    size_t bytes;
    if (mx_controlnet_arena_bytes(m, B, H, W, in.T, &bytes, st) || make_arena(io, bytes, st) ||
        mx_controlnet_forward(&io->ctx, m, &in, down, down[n], 0, &io->arena, st))
        goto done;
    rc = 0;
done:
    mx_controlnet_free(m);
    return rc;
}

static int run_vae(run_io *io, const char *prefix, int decode, mx_status *st) {
    char key[96];
    mx_vae_config cfg;
    mx_vae *v = NULL;
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_vae_config_parse(&cfg, text, strlen(text), key, st)) return -1;
    if (bind_weights(io, prefix, st) || mx_vae_load(&v, &cfg, &io->b, st)) return -1;
    int rc = -1, f = mx_vae_factor(v), lc = cfg.latent_channels;
    size_t bytes;
    if (decode) {
        int64_t ls[4] = {-1, lc, -1, -1};
        float *lat = input(io, "latents", 4, ls, 1, st), *img;
        if (!lat) goto done;
        int B = (int)ls[0], h = (int)ls[2], w = (int)ls[3];
        int64_t os[4] = {B, cfg.out_channels, (int64_t)h * f, (int64_t)w * f};
        if (mx_vae_decode_arena_bytes(v, B, h, w, &bytes, st) || make_arena(io, bytes, st) ||
            !(lat = on_device(io, lat, (size_t)B * lc * h * w, st)) || !(img = dev_output(io, "image", 4, os, st)) ||
            mx_vae_decode(&io->ctx, v, lat, B, h, w, img, &io->arena, st))
            goto done;
        rc = 0;
    } else {
        int64_t is[4] = {-1, cfg.in_channels, -1, -1};
        float *img = input(io, "image", 4, is, 1, st), *mean, *logvar;
        if (!img) goto done;
        int B = (int)is[0], H = (int)is[2], W = (int)is[3];
        if (mx_vae_encode_arena_bytes(v, B, H, W, &bytes, st) || make_arena(io, bytes, st)) goto done;
        int64_t os[4] = {B, lc, H / f, W / f};
        if (!(img = on_device(io, img, (size_t)B * cfg.in_channels * H * W, st)) ||
            !(mean = dev_output(io, "mean", 4, os, st)) || !(logvar = dev_output(io, "logvar", 4, os, st)) ||
            mx_vae_encode(&io->ctx, v, img, B, H, W, mean, logvar, &io->arena, st))
            goto done;
        rc = 0;
    }
done:
    mx_vae_free(v);
    return rc;
}

/* TAESD: image -> latents (encode) or latents -> image (decode), one input and one output. */
static int run_taesd(run_io *io, const char *prefix, int decode, mx_status *st) {
    char key[96];
    mx_taesd_config cfg;
    mx_taesd *t = NULL;
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_taesd_config_parse(&cfg, text, strlen(text), key, st)) return -1;
    if (bind_weights(io, prefix, st) || mx_taesd_load(&t, &cfg, &io->b, st)) return -1;
    int rc = -1, f = mx_taesd_factor(t), cin = decode ? cfg.latent_channels : cfg.in_channels;
    int cout = decode ? cfg.out_channels : cfg.latent_channels;
    int64_t is[4] = {-1, cin, -1, -1};
    float *x = input(io, decode ? "latents" : "image", 4, is, 1, st), *y;
    size_t bytes;
    if (!x) goto done;
    int B = (int)is[0], H = (int)is[2], W = (int)is[3], Ho = decode ? H * f : H / f, Wo = decode ? W * f : W / f;
    int64_t os[4] = {B, cout, Ho, Wo};
    if ((decode ? mx_taesd_decode_arena_bytes(t, B, H, W, &bytes, st) : mx_taesd_encode_arena_bytes(t, B, H, W, &bytes, st)) ||
        make_arena(io, bytes, st) || !(x = on_device(io, x, (size_t)B * cin * H * W, st)) ||
        !(y = dev_output(io, decode ? "image" : "latents", 4, os, st)) ||
        (decode ? mx_taesd_decode(&io->ctx, t, x, B, H, W, y, &io->arena, st)
                : mx_taesd_encode(&io->ctx, t, x, B, H, W, y, &io->arena, st)))
        goto done;
    rc = 0;
done:
    mx_taesd_free(t);
    return rc;
}

static int run_clip(run_io *io, const char *prefix, mx_status *st) {
    char key[96];
    mx_clip_config cfg;
    mx_clip m;
    memset(&m, 0, sizeof m);
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_clip_config_parse(&cfg, text, strlen(text), key, st)) return -1;
    if (bind_weights(io, prefix, st) || mx_clip_load(&m, &cfg, &io->b, st)) return -1;
    int rc = -1, L = cfg.num_hidden_layers, C = cfg.hidden_size;
    int64_t is[2] = {-1, -1};
    float *idf = input(io, "input_ids", 2, is, 1, st), *last, *pooled;
    float **hs = calloc((size_t)L + 1, sizeof *hs);
    int32_t *ids = NULL;
    if (!idf || !hs) goto done;
    int B = (int)is[0], T = (int)is[1];
    if (T > cfg.max_position_embeddings) {
        mx_fail(st, MX_EINPUT, "%s: input_ids has %d tokens, the model takes at most %d", io->in_path, T,
                cfg.max_position_embeddings);
        goto done;
    }
    ids = malloc((size_t)B * T * sizeof *ids);
    if (!ids) goto done;
    for (size_t i = 0; i < (size_t)B * T; i++) ids[i] = (int32_t)idf[i];
    int64_t hshape[3] = {B, T, C}, pshape[2] = {B, C};
    if (!(last = dev_output(io, "last_hidden_state", 3, hshape, st)) ||
        !(pooled = dev_output(io, "pooler_output", 2, pshape, st)))
        goto done;
    for (int i = 0; i <= L; i++) {
        char name[48];
        snprintf(name, sizeof name, "hidden_states.%d", i);
        if (!(hs[i] = dev_output(io, name, 3, hshape, st))) goto done;
    }
    mx_arena dry;
    mx_arena_measure(&dry);
    if (mx_clip_forward(&m, &io->ctx, &dry, ids, B, T, last, pooled, hs, st) ||
        make_arena(io, dry.peak + 4 * MX_ARENA_ALIGN, st) ||
        mx_clip_forward(&m, &io->ctx, &io->arena, ids, B, T, last, pooled, hs, st))
        goto done;
    rc = 0;
done:
    free(ids);
    free(hs);
    mx_clip_free(&m);
    return rc;
}

/* ---- inpaint-pipeline / img2img-pipeline: the view step and the enhancement step on tensors ---- */
typedef struct pipe_opts {
    int inpaint, steps;
    float guidance;
} pipe_opts;

typedef struct step_record {
    float *after; /* [steps, numel] */
    int64_t *timesteps;
} step_record;

static int record_step(void *user, int step, int n_steps, int64_t t, const float *lat, size_t numel) {
    (void)n_steps;
    step_record *r = user;
    memcpy(r->after + (size_t)step * numel, lat, numel * sizeof *lat);
    r->timesteps[step] = t;
    return 0;
}

/* The pipeline's tensors, shapes checked against each other and the networks. */
typedef struct pipe_inputs {
    float *cond, *uncond, *image, *mask, *depth, *inpaint, *noise, *scales, *strength;
    int B, T, H, W;
} pipe_inputs;

static int pipe_read_inputs(run_io *io, const mx_models *m, const pipe_opts *po, pipe_inputs *p, mx_status *st) {
    int D = mx_unet_cfg(m->unet)->cross_attention_dim, f = mx_vae_factor(m->vae);
    int64_t es[3] = {-1, -1, D}, is[4] = {-1, 3, -1, -1}, one[1] = {1}, two[1] = {2};
    if (!(p->cond = input(io, "prompt_embeds", 3, es, 1, st)) ||
        !(p->uncond = input(io, "negative_prompt_embeds", 3, es, 1, st)))
        return -1;
    is[0] = es[0];
    if (!(p->image = input(io, "image", 4, is, 1, st))) return -1;
    p->B = (int)is[0], p->T = (int)es[1], p->H = (int)is[2], p->W = (int)is[3];
    if (p->H % f || p->W % f)
        return mx_fail(st, MX_EINPUT, "%s: image is %dx%d, not a multiple of the VAE factor %d", io->in_path, p->W,
                       p->H, f);
    int64_t ms[4] = {p->B, 1, p->H, p->W}, cs[4] = {p->B, 3, p->H, p->W}, ns[4] = {p->B, 4, p->H / f, p->W / f};
    if (!(p->depth = input(io, "control_depth", 4, cs, 1, st)) || !(p->noise = input(io, "noise", 4, ns, 1, st)))
        return -1;
    if (po->inpaint)
        return !(p->mask = input(io, "mask", 4, ms, 1, st)) || !(p->inpaint = input(io, "control_inpaint", 4, cs, 1, st)) ||
                       !(p->scales = input(io, "conditioning_scales", 1, two, 1, st))
                   ? -1
                   : 0;
    if (!(p->strength = input(io, "strength", 1, one, 1, st))) return -1;
    if (mx_st_find(&io->in, "conditioning_scales") && !(p->scales = input(io, "conditioning_scales", 1, one, 1, st)))
        return -1;
    return 0;
}

static int pipe_denoise(run_io *io, const mx_models *m, const pipe_opts *po, const pipe_inputs *p, mx_status *st) {
    int f = mx_vae_factor(m->vae), h = p->H / f, w = p->W / f, rc = -1;
    size_t numel = (size_t)p->B * 4 * h * w;
    mx_sched s;
    if (mx_unet_check_sizes(mx_unet_cfg(m->unet), 2 * p->B, h, w, p->T, st) ||
        mx_sched_init(&s, &io->ctx, &m->sched, po->steps, numel, st))
        return -1;
    mx_sd_control ctl[2] = {{m->cn_depth, p->depth, p->scales ? p->scales[0] : 1.0f, NULL},
                            {m->cn_inpaint, p->inpaint, po->inpaint ? p->scales[1] : 0.0f, NULL}};
    float *lat = new_floats(io, numel, st), *image = new_floats(io, (size_t)p->B * 3 * p->H * p->W, st);
    step_record r = {new_floats(io, (size_t)po->steps * numel, st), (int64_t *)new_floats(io, 2 * (size_t)po->steps, st)};
    mx_sd_request rq = {m->unet, ctl, po->inpaint ? 2 : 1, p->cond, p->uncond, p->T, po->guidance, &s,
                        record_step, &r, NULL, NULL};
    mx_sd_edit e = {m->vae, p->image, p->mask, p->noise, po->inpaint ? 1.0f : p->strength[0], NULL};
    if (lat && image && r.after && r.timesteps && mx_sd_edit_run(&rq, &e, &io->ctx, p->B, h, w, lat, st) == 0 &&
        mx_sd_decode_latents(&io->ctx, m->vae, lat, p->B, h, w, image, st) == 0) {
        int n = mx_sched_steps(&s);
        int64_t ts[1] = {n}, as[5] = {n, p->B, 4, h, w}, is[4] = {p->B, 3, p->H, p->W};
        rc = add_output(io, "timesteps", 1, ts, (const float *)r.timesteps, st) ||
                     add_output(io, "latents_after_step", 5, as, r.after, st) || add_output(io, "image", 4, is, image, st)
                 ? -1
                 : 0;
        io->outs[0].dtype = MX_ST_I64;
    }
    mx_sched_free(&s);
    return rc;
}

static int run_pipeline(run_io *io, const char *weights, const pipe_opts *po, mx_status *st) {
    mx_models m;
    pipe_inputs p;
    memset(&p, 0, sizeof p);
    if (mx_models_load(&m, &io->ctx, weights, MX_MODELS_NEED_DEPTH | (po->inpaint ? MX_MODELS_NEED_INPAINT : 0), st)) return -1;
    int rc = pipe_read_inputs(io, &m, po, &p, st) || pipe_denoise(io, &m, po, &p, st) ? -1 : 0;
    mx_models_free(&m);
    return rc;
}

static void io_free(run_io *io) {
    if (io->arena_ok) mx_arena_destroy(&io->arena);
    mx_binder_free(&io->b);
    mx_binder_free(&io->wb);
    for (int i = 0; i < io->ndev; i++) mx_dev_free(&io->ctx, io->dev[i]);
    if (io->ctx_ok) mx_ctx_destroy(&io->ctx);
    if (io->wf) mx_wf_close(io->wf);
    if (io->in_open) mx_st_close(&io->in);
    for (int i = 0; i < io->ntmp; i++) free(io->tmp[i]);
}

static const char *default_prefix(const char *net) {
    if (!strcmp(net, "unet")) return "unet.";
    if (!strcmp(net, "controlnet")) return "controlnet.";
    if (!strcmp(net, "vae-encode") || !strcmp(net, "vae-decode")) return "vae.";
    if (!strcmp(net, "clip")) return "text_encoder.";
    if (!strcmp(net, "taesd-encode") || !strcmp(net, "taesd-decode")) return "taesd.";
    if (!strcmp(net, "inpaint-pipeline") || !strcmp(net, "img2img-pipeline")) return "";
    return NULL;
}

static int run(run_io *io, const char *net, const char *weights, const char *prefix, int threads, mx_precision prec,
               mx_backend_kind device, const pipe_opts *po, mx_status *st) {
    int pipeline = !*default_prefix(net);
    if (mx_ctx_create_on(&io->ctx, device, threads, mx_cpu_isa_for(prec), SCRATCH_BYTES, st)) return -1;
    io->ctx_ok = 1;
    if (device != MX_BACKEND_CUDA && mx_isa_precision(io->ctx.k->isa) != prec)
        mx_warn("run-net: %s arithmetic is not available on this CPU; using fp32", mx_precision_name(prec));
    if (mx_st_open(&io->in, io->in_path, st)) return -1;
    io->in_open = 1;
    if (!pipeline && mx_wf_open(&io->wf, weights, st)) return -1;
    double t0 = mx_now();
    int rc = pipeline                     ? run_pipeline(io, weights, po, st)
             : !strcmp(net, "unet")       ? run_unet(io, prefix, st)
             : !strcmp(net, "controlnet") ? run_controlnet(io, prefix, st)
             : !strcmp(net, "vae-encode") ? run_vae(io, prefix, 0, st)
             : !strcmp(net, "vae-decode") ? run_vae(io, prefix, 1, st)
             : !strcmp(net, "taesd-encode") ? run_taesd(io, prefix, 0, st)
             : !strcmp(net, "taesd-decode") ? run_taesd(io, prefix, 1, st)
                                          : run_clip(io, prefix, st);
    if (rc || fetch_outputs(io, st)) return -1;
    mx_info("run-net %s on %s: %.3f s", net, mx_backend_name(device), mx_now() - t0);
    return mx_st_write(io->out_path, io->outs, (size_t)io->nout, st);
}

int cmd_run_net(int argc, char **argv) {
    const char *net = NULL, *weights = NULL, *prefix = NULL, *device = "cpu";
    int threads = 0;
    pipe_opts po = {0, 0, 7.5f};
    mx_precision prec = MX_PREC_FP32;
    run_io io;
    memset(&io, 0, sizeof io);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        }
        int has_val = i + 1 < argc;
        if (!strcmp(a, "--weights") && has_val) weights = argv[++i];
        else if (!strcmp(a, "--inputs") && has_val) io.in_path = argv[++i];
        else if ((!strcmp(a, "--out") || !strcmp(a, "-o")) && has_val) io.out_path = argv[++i];
        else if (!strcmp(a, "--prefix") && has_val) prefix = argv[++i];
        else if (!strcmp(a, "--threads") && has_val) {
            if (mx_arg_int("run-net", a, argv[++i], 0, 1024, &threads)) return 2;
        } else if (!strcmp(a, "--steps") && has_val) {
            if (mx_arg_int("run-net", a, argv[++i], 1, MX_SCHED_MAX_STEPS, &po.steps)) return 2;
        } else if (!strcmp(a, "--guidance") && has_val) {
            if (mx_parse_float(argv[++i], &po.guidance)) {
                fprintf(stderr, "matex run-net: bad value for --guidance: '%s'\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--device") && has_val) {
            device = argv[++i];
        } else if (!strcmp(a, "--precision") && has_val) {
            if (mx_precision_parse(argv[++i], &prec)) {
                fprintf(stderr, "matex run-net: --precision must be fp32 or bf16, not '%s'\n", argv[i]);
                return 2;
            }
        } else if (a[0] != '-' && !net) net = a;
        else {
            fprintf(stderr, "matex run-net: unknown or incomplete argument '%s'\n", a);
            usage(stderr);
            return 2;
        }
    }
    if (!net || !weights || !io.in_path || !io.out_path || !default_prefix(net)) {
        fprintf(stderr, "matex run-net: %s\n", !net || default_prefix(net) ? "NET, --weights, --inputs and --out are required"
                                                                         : "NET must be clip, unet, controlnet, vae-encode, vae-decode, taesd-encode, taesd-decode, inpaint-pipeline or img2img-pipeline");
        usage(stderr);
        return 2;
    }
    po.inpaint = !strcmp(net, "inpaint-pipeline");
    if (!*default_prefix(net) && (po.steps < 1 || po.steps > MX_SCHED_MAX_STEPS || !(po.guidance >= 0.0f))) {
        fprintf(stderr, "matex run-net: %s needs --steps in 1..%d and a guidance >= 0\n", net, MX_SCHED_MAX_STEPS);
        return 2;
    }
    char pfx[80];
    if (!prefix) prefix = default_prefix(net);
    if (strlen(prefix) > 64) {
        fprintf(stderr, "matex run-net: --prefix is too long\n");
        return 2;
    }
    /* "controlnet_depth" and "controlnet_depth." name the same network */
    snprintf(pfx, sizeof pfx, "%s%s", prefix, *prefix && prefix[strlen(prefix) - 1] != '.' ? "." : "");
    mx_status st;
    mx_status_clear(&st);
    mx_backend_kind kind;
    if (mx_backend_parse(device, &kind, &st)) {
        fprintf(stderr, "matex run-net: --device: %s\n", st.msg);
        return 2;
    }
    int rc = run(&io, net, weights, pfx, threads, prec, kind, &po, &st);
    io_free(&io);
    if (rc) {
        fprintf(stderr, "matex run-net: %s\n", st.msg);
        return st.code == MX_EUSAGE ? 2 : 1;
    }
    return 0;
}
