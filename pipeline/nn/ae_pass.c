/* Autoencoder pass helpers (see ae_pass.h). */
#include "ae_pass.h"

int mx_ae_run(const mx_ctx *c, int net_fp32, mx_ae_pass_fn pass, const void *net, const float *in, int B,
              int H, int W, float *out, mx_arena *a, mx_status *st, const char *what) {
    mx_run r;
    mx_run_init_prec(&r, net_fp32, c, a, st);
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

/* One host-to-host call: in (nin floats) uploaded, pre-mapped by y = pa x + pb, run, the output
 * (nout floats) post-mapped by y = qa x + qb, clamped to [lo, hi] when lo < hi, downloaded. */
typedef struct host_call {
    size_t nin, nout;
    float pa, pb, qa, qb, lo, hi;
} host_call;

static int run_host(const mx_ctx *c, const mx_ae_coder *k, const host_call *h, const float *in, int n, int hh, int ww,
                    float *out, mx_status *st) {
    mx_arena a = {0};
    float *din = mx_dev_alloc(c, h->nin, st), *dout = din ? mx_dev_alloc(c, h->nout, st) : NULL;
    int rc = -1;
    if (dout && !mx_upload(c, din, in, h->nin, st) && !mx_arena_create_on(&a, c->be, k->arena_bytes, st)) {
        mx_affine(c, din, din, h->pa, h->pb, h->nin);
        if (!k->run(c, k->net, din, n, hh, ww, dout, &a, st)) {
            mx_affine(c, dout, dout, h->qa, h->qb, h->nout);
            if (h->lo < h->hi) mx_clamp(c, dout, dout, h->lo, h->hi, h->nout);
            rc = mx_download(c, out, dout, h->nout, st);
        }
    }
    mx_arena_destroy(&a);
    mx_dev_free(c, din);
    mx_dev_free(c, dout);
    return rc;
}

int mx_ae_decode_host(const mx_ctx *c, const mx_ae_coder *d, const float *latents, int n, int h, int w,
                      float *image, mx_status *st) {
    if (d->scaling_factor == 0.0f) return mx_fail(st, MX_EINPUT, "decoder: scaling_factor is 0");
    size_t f2 = (size_t)d->factor * d->factor;
    host_call hc = {(size_t)n * d->latent_channels * h * w, (size_t)n * d->image_channels * h * w * f2,
                    1.0f / d->scaling_factor, 0.0f, 0.5f, 0.5f, 0.0f, 1.0f};
    return run_host(c, d, &hc, latents, n, h, w, image, st);
}

int mx_ae_encode_host(const mx_ctx *c, const mx_ae_coder *e, const float *image, int n, int H, int W, float *latents,
                      mx_status *st) {
    size_t f2 = (size_t)e->factor * e->factor;
    host_call hc = {(size_t)n * e->image_channels * H * W, (size_t)n * e->latent_channels * H * W / f2, 2.0f, -1.0f,
                    e->scaling_factor, 0.0f, 0.0f, 0.0f};
    return run_host(c, e, &hc, image, n, H, W, latents, st);
}
