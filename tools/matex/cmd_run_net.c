/* matex run-net NET --weights W --inputs IN.safetensors --out OUT.safetensors: runs one network
 * on tensors from a safetensors file and writes its outputs (the parity and debugging tool). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../ops/ops.h"
#include "../../pipeline/nn/clip_image.h"
#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/sd_edit.h"
#include "../../pipeline/nn/unet.h"
#include "../../pipeline/nn/vae.h"
#include "../../pipeline/texture/models.h"
#include "../../runtime/log.h"
#include "../../weights/safetensors.h"
#include "../../weights/weights.h"
#include "cli.h"
#include "cli_args.h"
#include "cli_clip_preprocess.h"

#define MAX_OUTS (MX_UNET_MAX_RES + 4)
#define SCRATCH_BYTES ((size_t)256 << 20)

static void usage(FILE *f) {
    fprintf(f, "usage: matex run-net NET --weights W.mxw --inputs IN.safetensors --out OUT.safetensors [options]\n"
               "\n"
               "Runs one network of a matex weight file on the tensors of IN and writes its outputs (fp32).\n"
               "NET and its tensors (B = batch; any batch and any valid size):\n");
    for (size_t i = 0; i < mx_net_count; i++) fprintf(f, "  %-12s %s\n", mx_nets[i].name, mx_nets[i].help);
    fprintf(f,
            "  inpaint-pipeline  (W: a model set with controlnet_depth and controlnet_inpaint; --steps N [--guidance G])\n"
            "              prompt_embeds, negative_prompt_embeds [B,T,D], image [B,3,H,W] in [0,1], mask [B,1,H,W]\n"
            "              (1 = paint), control_depth, control_inpaint [B,3,H,W], noise [B,4,H/8,W/8],\n"
            "              conditioning_scales [2] (depth, inpaint), optional image_embeds [B,n_images,E] and\n"
            "              ip_adapter_scale [1] (W with an ip_adapter.; the unconditional half gets a zero embedding)\n"
            "              -> timesteps, latents_after_step, image\n"
            "  img2img-pipeline  (W: a model set with a depth ControlNet; --steps N [--guidance G])\n"
            "              prompt_embeds, negative_prompt_embeds, image, control_depth, noise, strength [1],\n"
            "              optional conditioning_scales [1] (default 1)  -> timesteps, latents_after_step, image\n"
            "  clip-preprocess  (no --weights; --size N, default 224) image_u8_hwc [H,W,C] (C 1..4, 0..255)\n"
            "              -> pixel_values [1,3,N,N]: CLIP's resize (PIL bicubic), centre crop, mean/std\n"
            "\n"
            "options:\n"
            "  --prefix P      network prefix in the weight file (default: the network's, unet., controlnet., vae.,\n"
            "                  text_encoder., taesd.; e.g. controlnet_depth. for a file with several ControlNets)\n"
            "  --threads N     worker threads (default: all CPUs)\n"
            "  --steps N       pipelines: scheduler steps before strength (required)\n"
            "  --guidance G    pipelines: classifier-free guidance scale (default 7.5)\n"
            "  --size N        clip-preprocess: the image side N (default 224)\n"
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
    mx_binder wb2, b2; /* the same for the one companion network (net_io.h network: an IP-Adapter) */
    const mx_net_def *def2;
    void *net2;
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
    mx_net_io iface; /* the network's view of the above (net_io.h); impl = this */
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

static const mx_st_tensor *missing(const run_io *io, const char *name, mx_status *st) {
    mx_fail(st, MX_EINPUT, "%s: missing input tensor %s", io->in_path, name);
    return NULL;
}

/* Input tensor t (NULL: missing), named `name`, with its shape checked: want[i] = -1 accepts any
 * size (filled in). */
static const mx_st_tensor *checked_tensor(run_io *io, const mx_st_tensor *t, const char *name, int ndim, int64_t *want,
                                          mx_status *st) {
    if (!t) return missing(io, name, st);
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
    return t;
}

/* Input tensor `name` with its shape checked (the pipelines' inputs). */
static const mx_st_tensor *input_tensor(run_io *io, const char *name, int ndim, int64_t *want, mx_status *st) {
    return checked_tensor(io, mx_st_find(&io->in, name), name, ndim, want, st);
}

/* The same as fp32 (freed by io_free). */
static float *input(run_io *io, const char *name, int ndim, int64_t *want, mx_status *st) {
    const mx_st_tensor *t = input_tensor(io, name, ndim, want, st);
    return t ? keep(io, mx_st_to_f32(&io->in, t, st)) : NULL;
}

/* Device memory for n floats, a copy of host data when host is not NULL (freed by io_free). */
static float *on_device(run_io *io, const float *host, size_t n, mx_status *st) {
    if (io->ndev == (int)(sizeof io->dev / sizeof io->dev[0])) return mx_fail(st, MX_EINTERNAL, "too many tensors"), NULL;
    float *p = host ? mx_dev_from_host(&io->ctx, host, n, st) : mx_dev_alloc(&io->ctx, n, st);
    if (p) io->dev[io->ndev++] = p;
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

/* ---- the network's view of the call (net_io.h): slots bound once, by index after that ---- */

/* The handle of input `name`: its index in the inputs' file. */
static int io_find(mx_net_io *n, const char *name) {
    const mx_safetensors *in = &((run_io *)n->impl)->in;
    const mx_st_tensor *t = mx_st_find(in, name);
    return t ? (int)(t - in->tensors) : -1;
}

static const char *slot_name(const mx_net_io *n, int slot) { return n->slots->slot[slot].name; }

/* The tensor of input `slot`, NULL when the call has none. */
static const mx_st_tensor *slot_tensor(const mx_net_io *n, int slot) {
    int at = n->slots->slot[slot].at;
    return at < 0 ? NULL : &((run_io *)n->impl)->in.tensors[at];
}

static int io_shape(mx_net_io *n, int slot, int ndim, int64_t *shape, mx_status *st) {
    return checked_tensor(n->impl, slot_tensor(n, slot), slot_name(n, slot), ndim, shape, st) ? 0 : -1;
}

static const float *io_host(mx_net_io *n, int slot, int ndim, int64_t *shape, mx_status *st) {
    run_io *io = n->impl;
    const mx_st_tensor *t = checked_tensor(io, slot_tensor(n, slot), slot_name(n, slot), ndim, shape, st);
    return t ? keep(io, mx_st_to_f32(&io->in, t, st)) : NULL;
}

static const float *io_host_flat(mx_net_io *n, int slot, size_t *numel, mx_status *st) {
    run_io *io = n->impl;
    const mx_st_tensor *t = slot_tensor(n, slot);
    if (!t) return missing(io, slot_name(n, slot), st), NULL;
    *numel = t->ndim == 0 ? 1 : (size_t)mx_shape_numel(t->ndim, t->shape);
    return keep(io, mx_st_to_f32(&io->in, t, st));
}

static const float *io_device(mx_net_io *n, const float *host, size_t count, mx_status *st) {
    return on_device(n->impl, host, count, st);
}

static float *io_output(mx_net_io *n, int slot, int ndim, const int64_t *shape, mx_status *st) {
    return dev_output(n->impl, slot_name(n, slot), ndim, shape, st);
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

static const void *io_network(mx_net_io *n, const char *kind, mx_status *st) {
    run_io *io = n->impl;
    char prefix[80], key[96];
    const mx_net_def *def = mx_net_of_kind(kind);
    if (io->def2 == def && def) return io->net2;
    if (!def || io->def2) return mx_fail(st, MX_EINTERNAL, "run-net: companion network %s", kind), NULL;
    snprintf(prefix, sizeof prefix, "%s.", kind);
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || mx_binder_wf(&io->wb2, io->wf, prefix, st) || mx_binder_device(&io->b2, &io->wb2, &io->ctx, st))
        return NULL;
    io->def2 = def;
    if (def->load(&io->net2, text, strlen(text), key, &io->b2, st)) return mx_fail_prefix(st, "%s", mx_wf_path(io->wf)), NULL;
    return io->net2;
}

/* Any entry of the registry: its network's config and weights under `prefix`, loaded, its
 * tensors bound to slots, its arena sized from the inputs, run. */
static int run_network(run_io *io, const mx_net_def *def, const char *prefix, mx_status *st) {
    char key[96];
    void *net = NULL;
    mx_net_slots slots = {0};
    const char *text = net_config(io, prefix, key, sizeof key, st);
    if (!text || bind_weights(io, prefix, st)) return -1;
    io->iface = (mx_net_io){.impl = io,
                            .source = io->in_path,
                            .find = io_find,
                            .shape = io_shape,
                            .host = io_host,
                            .host_flat = io_host_flat,
                            .device = io_device,
                            .output = io_output,
                            .network = io_network};
    size_t bytes;
    int rc = def->load(&net, text, strlen(text), key, &io->b, st) || mx_net_bind(def, net, &io->iface, &slots, st) ||
                     def->arena_bytes(net, &io->iface, &bytes, st) || mx_arena_create_on(&io->arena, io->ctx.be, bytes, st)
                 ? -1
                 : 0;
    io->arena_ok = !rc;
    if (!rc) rc = def->run(&io->ctx, net, &io->iface, &io->arena, st);
    mx_net_slots_free(&slots);
    def->free(net);
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
    size_t numel;
} step_record;

static int record_timestep(void *user, int step, int n_steps, int64_t t) {
    (void)n_steps;
    step_record *r = user;
    r->timesteps[step] = t;
    return 0;
}

/* The latents after each step: a download per step, which only this parity output asks for. */
static int record_latents(void *user, const mx_ctx *c, int step, int n_steps, float *lat, mx_status *st) {
    (void)n_steps;
    step_record *r = user;
    return mx_download(c, r->after + (size_t)step * r->numel, lat, r->numel, st);
}

/* The pipeline's tensors, shapes checked against each other and the networks. */
typedef struct pipe_inputs {
    float *cond, *uncond, *image, *mask, *depth, *inpaint, *noise, *scales, *strength;
    int B, T, H, W;
    float *embeds, *ip_scale; /* optional image guidance: [B, n_images, E], [1] */
    int n_images;
} pipe_inputs;

/* The optional image_embeds [B, n_images, E] and ip_adapter_scale [1] (default 1): they need the
 * weight file's ip_adapter. */
static int pipe_read_image_guidance(run_io *io, const mx_models *m, pipe_inputs *p, mx_status *st) {
    int has_embeds = mx_st_find(&io->in, "image_embeds") != NULL;
    if (!has_embeds)
        return mx_st_find(&io->in, "ip_adapter_scale")
                   ? mx_fail(st, MX_EINPUT, "%s: ip_adapter_scale without image_embeds", io->in_path)
                   : 0;
    if (!m->ip_adapter)
        return mx_fail(st, MX_EINPUT, "%s: image_embeds given, but %s has no IP-Adapter (convert --ip-adapter)",
                       io->in_path, mx_models_path(m));
    int64_t es[3] = {p->B, -1, m->ip_adapter->embed_dim}, one[1] = {1};
    if (!(p->embeds = input(io, "image_embeds", 3, es, st))) return -1;
    if (es[1] > MX_IP_MAX_TOKENS / m->ip_adapter->num_tokens)
        return mx_fail(st, MX_EINPUT, "%s: image_embeds: %lld images of %d tokens (at most %d tokens)", io->in_path,
                       (long long)es[1], m->ip_adapter->num_tokens, MX_IP_MAX_TOKENS);
    p->n_images = (int)es[1];
    return mx_st_find(&io->in, "ip_adapter_scale") && !(p->ip_scale = input(io, "ip_adapter_scale", 1, one, st)) ? -1
                                                                                                                   : 0;
}

static int pipe_read_inputs(run_io *io, const mx_models *m, const pipe_opts *po, pipe_inputs *p, mx_status *st) {
    int D = mx_unet_cfg(m->unet)->cross_attention_dim, f = mx_vae_factor(m->vae);
    int64_t es[3] = {-1, -1, D}, is[4] = {-1, 3, -1, -1}, one[1] = {1}, two[1] = {2};
    if (!(p->cond = input(io, "prompt_embeds", 3, es, st)) ||
        !(p->uncond = input(io, "negative_prompt_embeds", 3, es, st)))
        return -1;
    is[0] = es[0];
    if (!(p->image = input(io, "image", 4, is, st))) return -1;
    p->B = (int)is[0], p->T = (int)es[1], p->H = (int)is[2], p->W = (int)is[3];
    if (p->H % f || p->W % f)
        return mx_fail(st, MX_EINPUT, "%s: image is %dx%d, not a multiple of the VAE factor %d", io->in_path, p->W,
                       p->H, f);
    int64_t ms[4] = {p->B, 1, p->H, p->W}, cs[4] = {p->B, 3, p->H, p->W}, ns[4] = {p->B, 4, p->H / f, p->W / f};
    if (!(p->depth = input(io, "control_depth", 4, cs, st)) || !(p->noise = input(io, "noise", 4, ns, st)) ||
        pipe_read_image_guidance(io, m, p, st))
        return -1;
    if (po->inpaint)
        return !(p->mask = input(io, "mask", 4, ms, st)) || !(p->inpaint = input(io, "control_inpaint", 4, cs, st)) ||
                       !(p->scales = input(io, "conditioning_scales", 1, two, st))
                   ? -1
                   : 0;
    if (!(p->strength = input(io, "strength", 1, one, st))) return -1;
    if (mx_st_find(&io->in, "conditioning_scales") && !(p->scales = input(io, "conditioning_scales", 1, one, st)))
        return -1;
    return 0;
}

/* Each item's image tokens (and a zero embedding's, for the unconditional half) into g. */
static int pipe_image_guide(run_io *io, const mx_models *m, const pipe_inputs *p, mx_sd_image_guide *g,
                            mx_status *st) {
    const mx_ip_adapter *ad = m->ip_adapter;
    int n = p->B * p->n_images;
    size_t nt = (size_t)n * ad->num_tokens * ad->cross_dim;
    float *cond = new_floats(io, nt, st), *uncond = cond ? new_floats(io, nt, st) : NULL;
    *g = (mx_sd_image_guide){.adapter = ad, .cond = cond, .uncond = uncond, .n_tokens = p->n_images * ad->num_tokens,
                             .per_latent = 1, .scale = p->ip_scale ? p->ip_scale[0] : 1.0f};
    return uncond ? mx_ip_adapter_guidance_tokens(&io->ctx, ad, p->embeds, n, cond, uncond, st) : -1;
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
    step_record r = {new_floats(io, (size_t)po->steps * numel, st), (int64_t *)new_floats(io, 2 * (size_t)po->steps, st),
                     numel};
    mx_sd_image_guide guide;
    mx_sd_request rq = {.unet = m->unet,
                        .controls = ctl,
                        .n_controls = po->inpaint ? 2 : 1,
                        .cond_text = p->cond,
                        .uncond_text = p->uncond,
                        .T = p->T,
                        .guidance = po->guidance,
                        .sched = &s,
                        .progress = record_timestep,
                        .progress_user = &r,
                        .after_step = record_latents,
                        .after_step_user = &r,
                        .image = p->embeds ? &guide : NULL};
    if (p->embeds && pipe_image_guide(io, m, p, &guide, st)) {
        mx_sched_free(&s);
        return -1;
    }
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
    if (io->def2) io->def2->free(io->net2);
    mx_binder_free(&io->b2);
    mx_binder_free(&io->wb2);
    if (io->arena_ok) mx_arena_destroy(&io->arena);
    mx_binder_free(&io->b);
    mx_binder_free(&io->wb);
    for (int i = 0; i < io->ndev; i++) mx_dev_free(&io->ctx, io->dev[i]);
    if (io->ctx_ok) mx_ctx_destroy(&io->ctx);
    if (io->wf) mx_wf_close(io->wf);
    if (io->in_open) mx_st_close(&io->in);
    for (int i = 0; i < io->ntmp; i++) free(io->tmp[i]);
}

static int is_pipeline(const char *net) { return !strcmp(net, "inpaint-pipeline") || !strcmp(net, "img2img-pipeline"); }

/* "unet, controlnet, ..., img2img-pipeline or clip-preprocess": the NETs, for the usage error. */
static void net_names(char *buf, size_t cap) {
    size_t len = 0;
    for (size_t i = 0; i < mx_net_count && len < cap; i++)
        len += (size_t)snprintf(buf + len, cap - len, "%s, ", mx_nets[i].name);
    if (len < cap) snprintf(buf + len, cap - len, "inpaint-pipeline, img2img-pipeline or clip-preprocess");
}

static int run(run_io *io, const char *net, const char *weights, const char *prefix, int threads, mx_precision prec,
               mx_backend_kind device, const pipe_opts *po, mx_status *st) {
    const mx_net_def *def = mx_net_named(net);
    if (mx_ctx_create_on(&io->ctx, device, threads, mx_cpu_isa_for(prec), SCRATCH_BYTES, st)) return -1;
    io->ctx_ok = 1;
    if (device != MX_BACKEND_CUDA && mx_isa_precision(io->ctx.k->isa) != prec)
        mx_warn("run-net: %s arithmetic is not available on this CPU; using fp32", mx_precision_name(prec));
    if (mx_st_open(&io->in, io->in_path, st)) return -1;
    io->in_open = 1;
    if (def && mx_wf_open(&io->wf, weights, st)) return -1;
    double t0 = mx_now();
    int rc = def ? run_network(io, def, prefix, st) : run_pipeline(io, weights, po, st);
    if (rc || fetch_outputs(io, st)) return -1;
    mx_info("run-net %s on %s: %.3f s", net, mx_backend_name(device), mx_now() - t0);
    return mx_st_write(io->out_path, io->outs, (size_t)io->nout, st);
}

/* run-net clip-preprocess: no weights, no device. */
static int clip_preprocess(const char *in_path, const char *out_path, int size) {
    mx_status st;
    mx_status_clear(&st);
    if (!in_path || !out_path) {
        fprintf(stderr, "matex run-net: clip-preprocess needs --inputs and --out\n");
        return 2;
    }
    if (mx_cli_clip_preprocess(in_path, out_path, size, &st)) {
        fprintf(stderr, "matex run-net: %s\n", st.msg);
        return st.code == MX_EUSAGE ? 2 : 1;
    }
    return 0;
}

int cmd_run_net(int argc, char **argv) {
    const char *net = NULL, *weights = NULL, *prefix = NULL, *device = "cpu", *precision = "fp32";
    int threads = 0, size = 224;
    pipe_opts po = {0, 0, 7.5f};
    mx_precision prec = MX_PREC_FP32;
    const mx_net_def *def = NULL;
    run_io io;
    memset(&io, 0, sizeof io);
    const mx_opt opts[] = {
        {"--weights", NULL, MX_OPT_STR, &weights, 0, 0},
        {"--inputs", NULL, MX_OPT_STR, &io.in_path, 0, 0},
        {"--out", "-o", MX_OPT_STR, &io.out_path, 0, 0},
        {"--prefix", NULL, MX_OPT_STR, &prefix, 0, 0},
        {"--threads", NULL, MX_OPT_INT, &threads, 0, 1024},
        {"--steps", NULL, MX_OPT_INT, &po.steps, 1, MX_SCHED_MAX_STEPS},
        {"--guidance", NULL, MX_OPT_FLOAT, &po.guidance, 0, 0},
        {"--device", NULL, MX_OPT_STR, &device, 0, 0},
        {"--precision", NULL, MX_OPT_STR, &precision, 0, 0},
        {"--size", NULL, MX_OPT_INT, &size, 1, MX_CLIP_IMAGE_MAX_SIZE},
    };
    int parsed = mx_args_parse("run-net", argc, argv, opts, sizeof opts / sizeof opts[0], &net, usage);
    if (parsed) return parsed == 1 ? 0 : 2;
    if (mx_precision_parse(precision, &prec)) {
        fprintf(stderr, "matex run-net: --precision must be fp32 or bf16, not '%s'\n", precision);
        return 2;
    }
    if (net && !strcmp(net, "clip-preprocess")) return clip_preprocess(io.in_path, io.out_path, size);
    int known = net && ((def = mx_net_named(net)) || is_pipeline(net));
    if (!net || !weights || !io.in_path || !io.out_path || !known) {
        char names[256];
        net_names(names, sizeof names);
        if (!net || known) fprintf(stderr, "matex run-net: NET, --weights, --inputs and --out are required\n");
        else fprintf(stderr, "matex run-net: NET must be %s\n", names);
        usage(stderr);
        return 2;
    }
    po.inpaint = !strcmp(net, "inpaint-pipeline");
    if (is_pipeline(net) && (po.steps < 1 || po.steps > MX_SCHED_MAX_STEPS || !(po.guidance >= 0.0f))) {
        fprintf(stderr, "matex run-net: %s needs --steps in 1..%d and a guidance >= 0\n", net, MX_SCHED_MAX_STEPS);
        return 2;
    }
    char pfx[80];
    if (!prefix) prefix = def ? def->kind : "";
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
