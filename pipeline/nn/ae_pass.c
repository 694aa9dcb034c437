/* Autoencoder pass helpers (see ae_pass.h). */
#include "ae_pass.h"

int mx_ae_run(const mx_ctx *c, mx_ae_pass_fn pass, const void *net, const float *in, int B, int H, int W, float *out,
              mx_arena *a, mx_status *st, const char *what) {
    mx_run r;
    mx_run_init(&r, c, a, st);
    size_t mark = mx_arena_mark(a);
    int rc = pass(&r, net, in, B, H, W, out);
    mx_arena_reset(a, mark);
    return rc ? mx_fail_prefix(st, "%s", what) : 0;
}

int mx_ae_dry_run(mx_ae_pass_fn pass, const void *net, int B, int H, int W, size_t *bytes, double *flops,
                  mx_status *st) {
    mx_arena a;
    mx_arena_measure(&a);
    mx_run r;
    mx_run_init(&r, NULL, &a, st);
    if (pass(&r, net, NULL, B, H, W, NULL)) return -1;
    if (bytes) *bytes = a.peak + 4 * MX_ARENA_ALIGN;
    if (flops) *flops = r.flops;
    return 0;
}

int mx_ae_decode_host(const mx_ctx *c, const mx_ae_decoder *d, const float *latents, int n, int h, int w,
                      float *image, mx_status *st) {
    size_t nl = (size_t)n * d->latent_channels * h * w, ni = (size_t)n * d->out_channels * h * w * d->factor * d->factor;
    if (d->scaling_factor == 0.0f) return mx_fail(st, MX_EINPUT, "decoder: scaling_factor is 0");
    mx_arena a = {0};
    float *din = mx_dev_alloc(c, nl, st), *dout = din ? mx_dev_alloc(c, ni, st) : NULL;
    int rc = -1;
    if (dout && !mx_upload(c, din, latents, nl, st) && !mx_arena_create_on(&a, c->be, d->arena_bytes, st)) {
        mx_scale(c, din, din, 1.0f / d->scaling_factor, nl);
        if (!d->decode(c, d->net, din, n, h, w, dout, &a, st)) {
            mx_affine(c, dout, dout, 0.5f, 0.5f, ni);
            mx_clamp(c, dout, dout, 0.0f, 1.0f, ni);
            rc = mx_download(c, image, dout, ni, st);
        }
    }
    mx_arena_destroy(&a);
    mx_dev_free(c, din);
    mx_dev_free(c, dout);
    return rc;
}
