/* Inpaint (latent blending) and img2img starts around the shared denoising loop. */
#include "sd_edit.h"

#include <stdlib.h>
#include <string.h>

/* What the blending step needs; buffers are [n, 4, h, w] except the masks [n, 1, h, w]. */
typedef struct edit_state {
    mx_sched *sched;
    const float *noise;
    float *image_latents, *known, *paint, *keep;
    int64_t lat_shape[4], mask_shape[4];
    size_t numel;
} edit_state;

/* paint = nearest-resize of (mask >= 0.5) to h×w (PyTorch's "nearest": source pixel f·i for
 * an exact factor f), keep = 1 − paint. The mask is a caller input, read once here. */
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
 * (exactly the image latents after the last step). */
static int blend_known(void *user, const mx_ctx *c, int step, int n_steps, float *x, mx_status *st) {
    (void)st;
    edit_state *e = user;
    const float *known = e->image_latents;
    if (step < n_steps - 1) {
        mx_sched_add_noise(e->sched, e->known, e->image_latents, e->noise, e->numel);
        known = e->known;
    }
    mx_binary(c, MX_BIN_MUL, e->known, known, e->lat_shape, e->keep, e->mask_shape, 4);
    mx_binary(c, MX_BIN_MUL, x, x, e->lat_shape, e->paint, e->mask_shape, 4);
    mx_add(c, x, x, e->known, e->numel);
    return 0;
}

static int check_edit(const mx_sd_request *rq, const mx_sd_edit *e, int n, int h, int w, mx_status *st) {
    if (!e->vae || !e->image || !e->noise || !rq->sched || n < 1 || h < 1 || w < 1)
        return mx_fail(st, MX_EUSAGE, "sd edit: missing VAE, image, noise or scheduler, or bad sizes");
    if (rq->after_step) return mx_fail(st, MX_EUSAGE, "sd edit: the request already has an after-step hook");
    if (!(e->strength > 0.0f && e->strength <= 1.0f))
        return mx_fail(st, MX_EUSAGE, "sd edit: strength must be in (0, 1], not %g", (double)e->strength);
    if (mx_vae_cfg(e->vae)->latent_channels != 4 || mx_unet_cfg(rq->unet)->in_channels != 4)
        return mx_fail(st, MX_EUSAGE, "sd edit: needs a 4-channel UNet and VAE latent");
    return 0;
}

int mx_sd_edit_run(const mx_sd_request *rq, const mx_sd_edit *e, const mx_ctx *c, int n, int h, int w,
                   float *latents, mx_status *st) {
    if (check_edit(rq, e, n, h, w, st)) return -1;
    int f = mx_vae_factor(e->vae);
    edit_state es = {rq->sched, e->noise, NULL, NULL, NULL, NULL, {n, 4, h, w}, {n, 1, h, w},
                     (size_t)n * 4 * h * w};
    size_t plane = (size_t)n * h * w;
    float *block = malloc((2 * es.numel + 2 * plane) * sizeof(float));
    if (!block) return mx_fail(st, MX_ENOMEM, "sd edit: out of memory");
    es.image_latents = block;
    es.known = block + es.numel;
    es.paint = block + 2 * es.numel;
    es.keep = es.paint + plane;
    int rc = -1;
    if (mx_sd_encode_image(c, e->vae, e->image, n, h * f, w * f, es.image_latents, st) ||
        mx_sched_set_strength(rq->sched, e->strength, st))
        goto done;
    if (e->mask && e->strength >= 1.0f)
        mx_scale(c, latents, e->noise, mx_sched_init_noise_sigma(rq->sched), es.numel);
    else
        mx_sched_add_noise(rq->sched, latents, es.image_latents, e->noise, es.numel);
    mx_sd_request r = *rq;
    if (e->mask) {
        latent_masks(e->mask, n, h, w, f, es.paint, es.keep);
        r.after_step = blend_known;
        r.after_step_user = &es;
    }
    rc = mx_sd_denoise(&r, c, latents, n, h, w, st);
done:
    free(block);
    return rc;
}
