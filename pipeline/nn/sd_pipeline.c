/* The denoising loop of diffusers' StableDiffusionControlNetPipeline (guess_mode off,
 * control_guidance 0..1) on matex's UNet, ControlNets and schedulers. */
#include "sd_pipeline.h"

#include <stdlib.h>
#include <string.h>

#include "../../ops/record.h"
#include "ae_pass.h"

/* Sizes of one loop. The networks run on one latent at a time, B = its batch (2 with CFG, its
 * uncond and cond halves, else 1): they are batch-independent, so this changes no result and
 * keeps a step's arena and residuals at those of one latent (SD1.5 at 64x64: ~0.25 GB + 54 MB,
 * against ~1 GB + 215 MB when 4 latents went through at once). */
typedef struct sd_dims {
    int n, B, C, h, w, T, Ct;
    size_t lat;      /* n*C*h*w */
    size_t text;     /* T*Ct per item */
    int n_res;       /* down residuals (mid one extra) */
    size_t res_numel[MX_UNET_MAX_RES + 1];
    int ip_sets;     /* image-token sets (0: no image guidance) */
    size_t ip;       /* image-token floats per item */
} sd_dims;

/* Working memory on the context's backend: one block and the arena. text and cond hold every
 * latent's call inputs in call order ([uncond_i; cond_i] per latent i with CFG), x_in, eps and
 * the residuals those of one call. */
typedef struct sd_work {
    float *block;
    float *lat, *x_in, *text, *timesteps, *eps, *guided;
    float *ip; /* per token set its call's image tokens, [uncond; cond] (or cond) */
    float *res[MX_UNET_MAX_RES + 1];
    float *cond[MX_SD_MAX_CONTROLNETS];
    mx_arena arena;
    /* Step caches (step_cache.h) of latent i: caches[i * (1 + n_controls) + j], j = 0 the UNet's,
     * 1 + k ControlNet k's; recorded at the first step, replayed at the others. */
    mx_step_cache *caches;
    float *cache_mem;
    /* The networks' part of a step as one recorded region (ops/record.h): from the second step on
     * the same work on the same buffers (the caches replayed), the timestep in wk->timesteps. */
    mx_record record;
} sd_work;

static size_t control_numel(const mx_controlnet *net, int h, int w) {
    const mx_unet_config *cc = mx_controlnet_cfg(net);
    int f = 1 << (cc->n_cond_emb > 0 ? cc->n_cond_emb - 1 : 0);
    return (size_t)cc->conditioning_channels * (size_t)(f * h) * (size_t)(f * w);
}

/* The image guidance's sizes into d (none: d->ip_sets 0). */
static int check_image_guide(const mx_sd_request *rq, sd_dims *d, mx_status *st) {
    const mx_sd_image_guide *g = rq->image;
    d->ip_sets = 0;
    if (!g || g->scale == 0.0f) return 0;
    if (!g->adapter || !g->cond || (d->B == 2 && !g->uncond) || g->n_tokens < 1 || g->n_tokens > MX_IP_MAX_TOKENS)
        return mx_fail(st, MX_EUSAGE, "sd pipeline: image guidance without adapter or tokens, or with %d tokens",
                       g->n_tokens);
    if (mx_unet_check_ip(rq->unet, g->adapter, st)) return mx_fail_prefix(st, "sd pipeline");
    d->ip_sets = g->per_latent ? d->n : 1;
    d->ip = (size_t)g->n_tokens * (size_t)d->Ct;
    return 0;
}

static int check_request(const mx_sd_request *rq, const mx_ctx *c, int n, int h, int w, sd_dims *d,
                         mx_status *st) {
    if (!rq->unet || !rq->sched || !rq->cond_text || n < 1 || h < 1 || w < 1 || rq->T < 1)
        return mx_fail(st, MX_EUSAGE, "sd pipeline: missing UNet, scheduler or prompt, or bad sizes");
    if (rq->n_controls < 0 || rq->n_controls > MX_SD_MAX_CONTROLNETS)
        return mx_fail(st, MX_EUSAGE, "sd pipeline: %d ControlNets (at most %d)", rq->n_controls,
                       MX_SD_MAX_CONTROLNETS);
    const mx_unet_config *uc = mx_unet_cfg(rq->unet);
    if (uc->out_channels != uc->in_channels)
        return mx_fail(st, MX_EUSAGE, "sd pipeline: UNet in/out channels differ (%d, %d)", uc->in_channels,
                       uc->out_channels);
    int cfg_on = rq->guidance > 1.0f;
    if (cfg_on && !rq->uncond_text) return mx_fail(st, MX_EUSAGE, "sd pipeline: guidance needs negative embeddings");
    d->n = n;
    d->B = cfg_on ? 2 : 1;
    d->C = uc->in_channels;
    d->h = h;
    d->w = w;
    d->T = rq->T;
    d->Ct = uc->cross_attention_dim;
    d->lat = (size_t)n * (size_t)d->C * (size_t)h * (size_t)w;
    d->text = (size_t)d->T * (size_t)d->Ct;
    if (rq->sched->numel != d->lat)
        return mx_fail(st, MX_EUSAGE, "sd pipeline: scheduler made for %zu latent values, latents have %zu",
                       rq->sched->numel, d->lat);
    if (rq->sched->c != c) return mx_fail(st, MX_EUSAGE, "sd pipeline: the scheduler runs on another context");
    d->n_res = mx_unet_num_residuals(uc);
    if (d->n_res > MX_UNET_MAX_RES) return mx_fail(st, MX_EUSAGE, "sd pipeline: too many UNet residuals");
    for (int i = 0; i <= d->n_res; i++) {
        int rc, rh, rw;
        mx_unet_residual_shape(uc, i, h, w, &rc, &rh, &rw);
        d->res_numel[i] = (size_t)d->B * (size_t)rc * (size_t)rh * (size_t)rw;
    }
    for (int k = 0; k < rq->n_controls; k++)
        if (!rq->controls[k].net || !rq->controls[k].image)
            return mx_fail(st, MX_EUSAGE, "sd pipeline: ControlNet %d has no network or image", k);
    return check_image_guide(rq, d, st);
}

/* The UNet call of latent i (its image tokens in wk->ip, when it has some). */
static mx_unet_input unet_call(const mx_sd_request *rq, const sd_dims *d, const sd_work *wk, int i) {
    mx_unet_input in = {.B = d->B, .H = d->h, .W = d->w, .T = d->T, .halves_equal = d->B == 2};
    if (d->ip_sets) {
        in.ip = rq->image->adapter;
        in.ip_n = rq->image->n_tokens;
        in.ip_scale = rq->image->scale;
        in.ip_tokens = wk ? wk->ip + (size_t)(d->ip_sets > 1 ? i : 0) * d->B * d->ip : NULL;
    }
    return in;
}

/* The largest arena any network call of the loop needs. */
static int loop_arena_bytes(const mx_sd_request *rq, const sd_dims *d, size_t *bytes, mx_status *st) {
    mx_unet_input dry = unet_call(rq, d, NULL, 0);
    if (mx_unet_call_arena_bytes(rq->unet, &dry, bytes, st)) return -1;
    for (int k = 0; k < rq->n_controls; k++) {
        size_t b;
        if (mx_controlnet_arena_bytes(rq->controls[k].net, d->B, d->h, d->w, d->T, &b, st)) return -1;
        if (b > *bytes) *bytes = b;
    }
    return 0;
}

static void work_free(const mx_ctx *c, sd_work *wk) {
    mx_record_free(c, &wk->record); /* before the memory its replays use */
    mx_dev_free(c, wk->block);
    mx_dev_free(c, wk->cache_mem);
    free(wk->caches);
    mx_arena_destroy(&wk->arena);
}

/* The step caches of every latent and network, in one block of backend memory. */
static int caches_alloc(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk, mx_status *st) {
    int per = 1 + rq->n_controls;
    size_t floats[1 + MX_SD_MAX_CONTROLNETS], total = 0;
    if (mx_unet_cache_floats(rq->unet, d->B, d->h, d->w, d->T, &floats[0], st)) return -1;
    for (int k = 0; k < rq->n_controls; k++)
        if (mx_controlnet_cache_floats(rq->controls[k].net, d->B, d->h, d->w, d->T, &floats[1 + k], st)) return -1;
    for (int j = 0; j < per; j++) total += floats[j] * (size_t)d->n;
    wk->caches = calloc((size_t)d->n * (size_t)per, sizeof *wk->caches);
    if (!wk->caches) return mx_fail(st, MX_ENOMEM, "sd pipeline: out of memory");
    if (!(wk->cache_mem = mx_dev_alloc(c, total, st))) return mx_fail_prefix(st, "sd pipeline step caches");
    float *p = wk->cache_mem;
    for (int i = 0; i < d->n; i++)
        for (int j = 0; j < per; j++) {
            wk->caches[i * per + j] = (mx_step_cache){.mem = p, .cap = floats[j]};
            p += floats[j]; /* a multiple of 16 floats: slots keep 64-byte alignment */
        }
    return 0;
}

static int work_alloc(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk, mx_status *st) {
    memset(wk, 0, sizeof *wk);
    size_t sizes[6 + MX_UNET_MAX_RES + 1 + MX_SD_MAX_CONTROLNETS];
    float **ptrs[6 + MX_UNET_MAX_RES + 1 + MX_SD_MAX_CONTROLNETS];
    size_t per_b = d->lat / (size_t)d->n, np = 0, total = 0;
    sizes[np] = d->lat, ptrs[np++] = &wk->lat;
    sizes[np] = (size_t)d->B * per_b, ptrs[np++] = &wk->x_in;
    sizes[np] = (size_t)d->n * d->B * d->text, ptrs[np++] = &wk->text;
    sizes[np] = (size_t)d->B * per_b, ptrs[np++] = &wk->eps;
    sizes[np] = d->lat, ptrs[np++] = &wk->guided;
    if (d->ip_sets) sizes[np] = (size_t)d->ip_sets * d->B * d->ip, ptrs[np++] = &wk->ip;
    for (int i = 0; i <= d->n_res; i++) sizes[np] = d->res_numel[i], ptrs[np++] = &wk->res[i];
    for (int k = 0; k < rq->n_controls; k++)
        sizes[np] = (size_t)d->n * d->B * control_numel(rq->controls[k].net, d->h, d->w), ptrs[np++] = &wk->cond[k];
    for (size_t i = 0; i < np; i++) total += (sizes[i] + 15) & ~(size_t)15; /* keep 64-byte alignment */
    total += ((size_t)d->B + 15) & ~(size_t)15; /* timesteps */
    wk->block = mx_dev_alloc(c, total, st); /* total is a multiple of 16 floats */
    if (!wk->block) return mx_fail_prefix(st, "sd pipeline");
    float *p = wk->block;
    for (size_t i = 0; i < np; i++) {
        *ptrs[i] = p;
        p += (sizes[i] + 15) & ~(size_t)15;
    }
    wk->timesteps = p;
    size_t bytes;
    if (loop_arena_bytes(rq, d, &bytes, st) || mx_arena_create_on(&wk->arena, c->be, bytes, st) ||
        caches_alloc(rq, c, d, wk, st)) {
        work_free(c, wk);
        return -1;
    }
    return 0;
}

/* Each set of image tokens as its calls take them: [uncond_s; cond_s] (or cond_s). */
static int upload_image_tokens(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk,
                               mx_status *st) {
    for (int s = 0; s < d->ip_sets; s++) {
        float *dst = wk->ip + (size_t)s * d->B * d->ip;
        if ((d->B == 2 && mx_upload(c, dst, rq->image->uncond + (size_t)s * d->ip, d->ip, st)) ||
            mx_upload(c, dst + (d->B == 2 ? d->ip : 0), rq->image->cond + (size_t)s * d->ip, d->ip, st))
            return -1;
    }
    return 0;
}

/* The edge in: latents, and per latent i its call's text [uncond_i; cond_i] (or cond_i) and
 * control images (repeated for both halves) go to the device once; the image tokens too. */
static int upload_inputs(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk,
                         const float *latents, mx_status *st) {
    int cfg_on = d->B == 2;
    if (mx_upload(c, wk->lat, latents, d->lat, st) || upload_image_tokens(rq, c, d, wk, st)) return -1;
    for (int i = 0; i < d->n; i++) {
        float *text = wk->text + (size_t)i * d->B * d->text;
        if ((cfg_on && mx_upload(c, text, rq->uncond_text + (size_t)i * d->text, d->text, st)) ||
            mx_upload(c, text + (cfg_on ? d->text : 0), rq->cond_text + (size_t)i * d->text, d->text, st))
            return -1;
        for (int k = 0; k < rq->n_controls; k++) {
            size_t one = control_numel(rq->controls[k].net, d->h, d->w);
            for (int r = 0; r < d->B; r++)
                if (mx_upload(c, wk->cond[k] + ((size_t)i * d->B + r) * one, rq->controls[k].image + (size_t)i * one, one,
                              st))
                    return -1;
        }
    }
    return 0;
}

/* Sum over the ControlNets of their scaled residuals (scale: the ControlNet's weight, or its
 * weight for latent i) into wk->res for latent i's call; returns 1 when any ran. */
static int run_controlnets(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk, int i,
                           mx_status *st) {
    int ran = 0;
    for (int k = 0; k < rq->n_controls; k++) {
        const mx_sd_control *ctl = &rq->controls[k];
        float weight = ctl->item_weights ? ctl->item_weights[i] : ctl->weight;
        if (weight == 0.0f) continue;
        float *cond = wk->cond[k] + (size_t)i * d->B * control_numel(ctl->net, d->h, d->w);
        mx_controlnet_input in = {wk->x_in, wk->timesteps, wk->text + (size_t)i * d->B * d->text, cond, d->B, d->h,
                                  d->w, d->T, weight, d->B == 2};
        mx_step_cache *cache = &wk->caches[i * (1 + rq->n_controls) + 1 + k];
        if (mx_controlnet_forward_cached(c, ctl->net, &in, cache, wk->res, wk->res[d->n_res], ran, &wk->arena, st))
            return mx_fail_prefix(st, "ControlNet %d: ", k), -1;
        ran = 1;
    }
    return ran;
}

/* Classifier-free guidance, out = u + g·(c − u), with the halves of eps [u; c] (c is overwritten). */
static void cfg_combine(const mx_ctx *c, float *out, float *eps, float guidance, size_t n) {
    int64_t shape[1] = {(int64_t)n};
    float *u = eps, *cond = eps + n;
    mx_binary(c, MX_BIN_SUB, cond, cond, shape, u, shape, 1);
    mx_copy(c, out, u, n);
    mx_axpy(c, out, cond, guidance, n);
}

/* Latent i's guided prediction into its slot of wk->guided: ControlNets and UNet on its batch
 * (the step's timestep already in wk->timesteps), then CFG. */
static int predict_one(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk, int i,
                       mx_status *st) {
    size_t per = d->lat / (size_t)d->n;
    for (int r = 0; r < d->B; r++) mx_copy(c, wk->x_in + (size_t)r * per, wk->lat + (size_t)i * per, per);
    int with_res = run_controlnets(rq, c, d, wk, i, st);
    if (with_res < 0) return -1;
    mx_unet_input in = unet_call(rq, d, wk, i);
    in.sample = wk->x_in;
    in.timesteps = wk->timesteps;
    in.encoder_hidden_states = wk->text + (size_t)i * d->B * d->text;
    in.down_residuals = with_res ? (const float *const *)wk->res : NULL;
    in.mid_residual = with_res ? wk->res[d->n_res] : NULL;
    mx_step_cache *cache = &wk->caches[i * (1 + rq->n_controls)];
    if (mx_unet_forward_cached(c, rq->unet, &in, cache, wk->eps, &wk->arena, st)) return mx_fail_prefix(st, "UNet: ");
    if (d->B == 2) cfg_combine(c, wk->guided + (size_t)i * per, wk->eps, rq->guidance, per);
    else mx_copy(c, wk->guided + (size_t)i * per, wk->eps, per);
    return 0;
}

/* The networks' part of one step, every latent: the recorded region of denoise_step. */
typedef struct step_region {
    const mx_sd_request *rq;
    const mx_ctx *c;
    const sd_dims *d;
    sd_work *wk;
} step_region;

static int predict_all(void *user, mx_status *st) {
    step_region *r = user;
    for (int i = 0; i < r->d->n; i++)
        if (predict_one(r->rq, r->c, r->d, r->wk, i, st)) return -1;
    return 0;
}

/* One step: the timestep (every latent's) into its device buffer, the networks latent by latent as
 * one recorded region, then the scheduler update of the latents on the device (outside the region:
 * its coefficients are host scalars that change step by step). */
static int denoise_step(const mx_sd_request *rq, const mx_ctx *c, const sd_dims *d, sd_work *wk, int64_t t,
                        mx_status *st) {
    mx_fill(c, wk->timesteps, (float)t, (size_t)d->B);
    step_region r = {rq, c, d, wk};
    if (mx_ctx_recorded(c, &wk->record, predict_all, &r, st)) return -1;
    return mx_sched_step(rq->sched, wk->guided, wk->lat, st);
}

int mx_sd_denoise(const mx_sd_request *rq, const mx_ctx *c, float *latents, int n, int h, int w,
                  mx_status *st) {
    sd_dims d = {0};
    sd_work wk;
    if (check_request(rq, c, n, h, w, &d, st) || work_alloc(rq, c, &d, &wk, st)) return -1;
    int steps = mx_sched_steps(rq->sched), rc = upload_inputs(rq, c, &d, &wk, latents, st);
    if (rc == 0) rc = mx_sched_prepare(rq->sched, st); /* no step copies from the host */
    for (int i = 0; i < steps && rc == 0; i++) {
        int64_t t = mx_sched_timestep(rq->sched, i);
        rc = denoise_step(rq, c, &d, &wk, t, st);
        if (rc == 0 && rq->after_step) rc = rq->after_step(rq->after_step_user, c, i, steps, wk.lat, st);
        if (rc == 0 && rq->progress && rq->progress(rq->progress_user, i, steps, t))
            rc = mx_fail(st, MX_EUSAGE, "sd pipeline: cancelled at step %d of %d", i + 1, steps);
    }
    if (rc == 0) rc = mx_download(c, latents, wk.lat, d.lat, st);
    work_free(c, &wk);
    return rc;
}

int mx_sd_encode_prompts(const mx_ctx *c, const mx_clip *clip, const mx_tokenizer *tok, const char *const *prompts,
                         int n, float *embeds, int *n_dropped, mx_status *st) {
    if (n < 1) return mx_fail(st, MX_EUSAGE, "encode prompts: no prompt");
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)n * MX_CLIP_CONTEXT);
    if (!ids) return mx_fail(st, MX_ENOMEM, "encode prompts: out of memory");
    size_t numel = (size_t)n * MX_CLIP_CONTEXT * (size_t)clip->cfg.hidden_size;
    float *out = NULL;
    int rc = -1;
    mx_arena a = {0};
    for (int i = 0; i < n; i++) {
        mx_tok_result r;
        if (mx_tok_encode(tok, prompts[i], &r, st)) goto done;
        memcpy(ids + (size_t)i * MX_CLIP_CONTEXT, r.ids, sizeof r.ids);
        if (n_dropped) n_dropped[i] = r.n_dropped;
    }
    mx_arena_measure(&a);
    if (mx_clip_forward(clip, c, &a, ids, n, MX_CLIP_CONTEXT, mx_act_placeholder(), NULL, NULL, st)) goto done;
    size_t bytes = a.peak;
    if (mx_arena_create_on(&a, c->be, bytes, st) || !(out = mx_dev_alloc(c, numel, st)) ||
        mx_clip_forward(clip, c, &a, ids, n, MX_CLIP_CONTEXT, out, NULL, NULL, st) ||
        mx_download(c, embeds, out, numel, st))
        goto done;
    rc = 0;
done:
    mx_dev_free(c, out);
    mx_arena_destroy(&a);
    free(ids);
    return rc;
}

static int vae_decode_dev(const mx_ctx *c, const void *net, const float *latents, int n, int h, int w, float *image,
                          mx_arena *a, mx_status *st) {
    return mx_vae_decode(c, net, latents, n, h, w, image, a, st);
}

static int vae_encode_dev(const mx_ctx *c, const void *net, const float *image, int n, int H, int W, float *latents,
                          mx_arena *a, mx_status *st) {
    return mx_vae_encode(c, net, image, n, H, W, latents, NULL, a, st); /* the posterior mean */
}

int mx_sd_decode_latents(const mx_ctx *c, const mx_vae *vae, const float *latents, int n, int h, int w,
                         float *image, mx_status *st) {
    const mx_vae_config *vc = mx_vae_cfg(vae);
    mx_ae_coder d = {vae_decode_dev, vae, vc->latent_channels, vc->out_channels, mx_vae_factor(vae), MX_SD_VAE_SCALE, 0};
    if (mx_vae_decode_arena_bytes(vae, n, h, w, &d.arena_bytes, st)) return -1;
    return mx_ae_decode_host(c, &d, latents, n, h, w, image, st);
}

int mx_sd_encode_image(const mx_ctx *c, const mx_vae *vae, const float *image, int n, int H, int W,
                       float *latents, mx_status *st) {
    const mx_vae_config *vc = mx_vae_cfg(vae);
    mx_ae_coder e = {vae_encode_dev, vae, vc->latent_channels, vc->in_channels, mx_vae_factor(vae), MX_SD_VAE_SCALE, 0};
    if (mx_vae_encode_arena_bytes(vae, n, H, W, &e.arena_bytes, st)) return -1;
    return mx_ae_encode_host(c, &e, image, n, H, W, latents, st);
}
