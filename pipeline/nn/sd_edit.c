/* Inpaint (latent blending) and img2img starts around the shared denoising loop. */
#include "sd_edit.h"

#include <stdlib.h>
#include <string.h>

/* What the blending step needs, in backend memory: one block of the image latents, the noise,
 * the known latents [n, 4, h, w] and the masks paint, keep [n, 1, h, w]. */
typedef struct edit_state {
    const mx_sched *sched;
    float *block, *image_latents, *noise, *known, *paint, *keep;
    int64_t lat_shape[4], mask_shape[4];
    size_t numel;
    mx_sd_after_step then; /* the request's own hook, after the blending (may be NULL) */
    void *then_user;
} edit_state;

/* paint = nearest-resize of (mask >= 0.5) to h×w (PyTorch's "nearest": source pixel f·i for
 * an exact factor f), keep = 1 − paint, on the host: the mask is a caller input, read once. */
static void latent_masks(const float *mask, int n, int h, int w, int f, float *paint, float *keep) {
    size_t H = (size_t)h * f, W = (size_t)w * f;
    for (int b = 0; b < n; b++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t o = ((size_t)b * h + y) * w + x;
                paint[o] = mask[(size_t)b * H * W + (size_t)y * f * W + (size_t)x * f] >= 0.5f ? 1.0f : 0.0f;
                keep[o] = 1.0f - paint[o];
            }
}

/* x = (1 − paint) · known + paint · x, known = the image latents noised to the next timestep
 * (a · image + b · noise, as add_noise), exactly the image latents after the last step. */
static int blend_known(void *user, const mx_ctx *c, int step, int n_steps, float *x, mx_status *st) {
    edit_state *e = user;
    const float *known = e->image_latents;
    if (step < n_steps - 1) {
        float coef[2];
        const float *terms[2] = {e->image_latents, e->noise};
        mx_sched_noise_coeffs(e->sched, &coef[0], &coef[1]);
        mx_lincomb(c, e->known, 2, coef, terms, e->numel);
        known = e->known;
    }
    mx_binary(c, MX_BIN_MUL, e->known, known, e->lat_shape, e->keep, e->mask_shape, 4);
    mx_binary(c, MX_BIN_MUL, x, x, e->lat_shape, e->paint, e->mask_shape, 4);
    mx_add(c, x, x, e->known, e->numel);
    return e->then ? e->then(e->then_user, c, step, n_steps, x, st) : 0;
}

static int check_edit(const mx_sd_request *rq, const mx_sd_edit *e, int n, int h, int w, mx_status *st) {
    if ((!e->vae && !e->taesd) || !e->noise || !rq->sched || n < 1 || h < 1 || w < 1)
        return mx_fail(st, MX_EUSAGE, "sd edit: missing VAE, image, noise or scheduler, or bad sizes");
    if (!(e->strength > 0.0f && e->strength <= 1.0f))
        return mx_fail(st, MX_EUSAGE, "sd edit: strength must be in (0, 1], not %g", (double)e->strength);
    int latent_channels = e->taesd ? mx_taesd_cfg(e->taesd)->latent_channels : mx_vae_cfg(e->vae)->latent_channels;
    if (latent_channels != 4 || mx_unet_cfg(rq->unet)->in_channels != 4)
        return mx_fail(st, MX_EUSAGE, "sd edit: needs a 4-channel UNet and VAE latent");
    return 0;
}

/* Host staging [image latents | noise | paint | keep] -> one backend block laid out as
 * edit_state (known between noise and paint). */
static int upload_state(const mx_ctx *c, edit_state *es, const float *host, size_t plane, mx_status *st) {
    size_t total = 3 * es->numel + 2 * plane;
    if (!(es->block = mx_dev_alloc(c, total, st))) return -1;
    es->image_latents = es->block;
    es->noise = es->block + es->numel;
    es->known = es->block + 2 * es->numel;
    es->paint = es->block + 3 * es->numel;
    es->keep = es->paint + plane;
    return mx_upload(c, es->image_latents, host, 2 * es->numel, st) ||
                   mx_upload(c, es->paint, host + 2 * es->numel, 2 * plane, st)
               ? -1
               : 0;
}

int mx_sd_edit_encode(const mx_sd_request *rq, const mx_sd_edit *e, const mx_ctx *c, int n, int h, int w,
                      float *image_latents, mx_status *st) {
    if (check_edit(rq, e, n, h, w, st)) return -1;
    if (!e->image) return mx_fail(st, MX_EUSAGE, "sd edit: no image");
    int f = e->taesd ? mx_taesd_factor(e->taesd) : mx_vae_factor(e->vae);
    return e->taesd ? mx_taesd_encode_image(c, e->taesd, e->image, n, h * f, w * f, image_latents, st)
                    : mx_sd_encode_image(c, e->vae, e->image, n, h * f, w * f, image_latents, st);
}

int mx_sd_edit_run_encoded(const mx_sd_request *rq, const mx_sd_edit *e, const float *image_latents, const mx_ctx *c,
                           int n, int h, int w, float *latents, mx_status *st) {
    if (check_edit(rq, e, n, h, w, st)) return -1;
    int f = e->taesd ? mx_taesd_factor(e->taesd) : mx_vae_factor(e->vae);
    edit_state es = {.sched = rq->sched,
                     .lat_shape = {n, 4, h, w},
                     .mask_shape = {n, 1, h, w},
                     .numel = (size_t)n * 4 * h * w,
                     .then = rq->after_step,
                     .then_user = rq->after_step_user};
    size_t plane = (size_t)n * h * w;
    float *host = malloc((2 * es.numel + 2 * plane) * sizeof(float)); /* image latents, noise, paint, keep */
    if (!host) return mx_fail(st, MX_ENOMEM, "sd edit: out of memory");
    int rc = -1;
    memcpy(host, image_latents, es.numel * sizeof(float));
    if (mx_sched_set_strength(rq->sched, e->strength, st)) goto done;
    memcpy(host + es.numel, e->noise, es.numel * sizeof(float));
    if (e->mask && e->strength >= 1.0f) {
        memcpy(latents, e->noise, es.numel * sizeof(float));
        mx_sched_scale_initial(rq->sched, latents, es.numel);
    } else {
        mx_sched_add_noise(rq->sched, latents, host, e->noise, es.numel);
    }
    mx_sd_request r = *rq;
    if (e->mask) {
        latent_masks(e->mask, n, h, w, f, host + 2 * es.numel, host + 2 * es.numel + plane);
        if (upload_state(c, &es, host, plane, st)) goto done;
        r.after_step = blend_known;
        r.after_step_user = &es;
    }
    rc = mx_sd_denoise(&r, c, latents, n, h, w, st);
done:
    mx_dev_free(c, es.block);
    free(host);
    return rc;
}

int mx_sd_edit_run(const mx_sd_request *rq, const mx_sd_edit *e, const mx_ctx *c, int n, int h, int w,
                   float *latents, mx_status *st) {
    if (check_edit(rq, e, n, h, w, st)) return -1;
    float *image_latents = malloc((size_t)n * 4 * h * w * sizeof(float));
    if (!image_latents) return mx_fail(st, MX_ENOMEM, "sd edit: out of memory");
    int rc = mx_sd_edit_encode(rq, e, c, n, h, w, image_latents, st) ||
                     mx_sd_edit_run_encoded(rq, e, image_latents, c, n, h, w, latents, st)
                 ? -1
                 : 0;
    free(image_latents);
    return rc;
}
