/* Tiled VAE decode (see vae_tiled.h): tiles through mx_vae_decode, crops, pastes and the linear
 * blend through ops (copy_rect, binary with a broadcast weight ramp). */
#include "vae_tiled.h"

#include <stdlib.h>

#define OVERLAP_FACTOR 0.25 /* diffusers' tile_overlap_factor */

typedef struct tiling {
    int tile, step, blend, limit; /* latent side, latent stride, blend pixels, kept pixels per tile */
    int h, w, ni, nj, f, C;
} tiling;

static void plan(tiling *t, const mx_vae *v, int h, int w, int tile) {
    t->f = mx_vae_factor(v);
    t->C = mx_vae_cfg(v)->out_channels;
    t->tile = tile;
    t->step = (int)(tile * (1.0 - OVERLAP_FACTOR));
    t->blend = (int)(t->f * tile * OVERLAP_FACTOR);
    t->limit = t->f * tile - t->blend;
    t->h = h;
    t->w = w;
    t->ni = (h + t->step - 1) / t->step;
    t->nj = (w + t->step - 1) / t->step;
}

/* Latent rows (or columns) of tile i along a side of n latents. */
static int tile_len(const tiling *t, int i, int n) {
    int left = n - i * t->step;
    return left < t->tile ? left : t->tile;
}

typedef struct tile_buf {
    float *px; /* [C, f*th, f*tw] */
    int H, W;  /* pixels */
} tile_buf;

/* Arena state of one tiled decode. */
typedef struct tiled_run {
    const mx_ctx *c;
    const mx_vae *v;
    mx_arena *a;
    mx_status *st;
    int dry;
    tiling t;
    tile_buf *tiles; /* ni * nj, row-major */
    float *win, *ta, *tb;
    float *ramp_a, *ramp_b; /* blend weights 1 - y/E and y/E, E = t.blend (each blend takes its first E') */
} tiled_run;

static float *take(tiled_run *r, size_t n) {
    float *p = mx_arena_floats(r->a, n, r->st);
    return r->dry ? (float *)r : p; /* a measuring arena hands out NULL: any non-NULL pointer will do */
}

static int alloc_run(tiled_run *r) {
    const tiling *t = &r->t;
    size_t ntiles = (size_t)t->ni * t->nj, side = (size_t)t->f * t->tile;
    r->tiles = calloc(ntiles, sizeof *r->tiles);
    r->ramp_a = malloc(2 * (size_t)t->blend * sizeof(float));
    if (!r->tiles || !r->ramp_a) return mx_fail(r->st, MX_ENOMEM, "tiled VAE decode: out of memory");
    r->ramp_b = r->ramp_a + t->blend;
    for (int i = 0; i < t->ni; i++)
        for (int j = 0; j < t->nj; j++) {
            tile_buf *b = &r->tiles[(size_t)i * t->nj + j];
            b->H = t->f * tile_len(t, i, t->h);
            b->W = t->f * tile_len(t, j, t->w);
            if (!(b->px = take(r, (size_t)t->C * b->H * b->W))) return -1;
        }
    r->win = take(r, (size_t)mx_vae_cfg(r->v)->latent_channels * t->tile * t->tile);
    r->ta = take(r, (size_t)t->C * t->blend * side);
    r->tb = take(r, (size_t)t->C * t->blend * side);
    return r->win && r->ta && r->tb ? 0 : -1;
}

/* The ramps of a blend over E pixels, in float as torch scales by the Python floats y/E. */
static void fill_ramps(tiled_run *r, int E) {
    for (int y = 0; y < E; y++) {
        r->ramp_a[y] = (float)(1.0 - (double)y / E);
        r->ramp_b[y] = (float)((double)y / E);
    }
}

/* b's first E rows (vertical) or columns: a's last E (.. (1 - y/E)) + b's first E (.. y/E). */
static void blend(tiled_run *r, const tile_buf *a, tile_buf *b, int vertical) {
    int E = r->t.blend, C = r->t.C;
    int na = vertical ? a->H : a->W, nb = vertical ? b->H : b->W;
    if (na < E) E = na;
    if (nb < E) E = nb;
    int h = vertical ? E : b->H, w = vertical ? b->W : E;
    int64_t shape[3] = {C, h, w}, wshape[3] = {1, vertical ? E : 1, vertical ? 1 : E};
    fill_ramps(r, E);
    mx_copy_rect(r->c, r->ta, h, w, 0, 0, a->px, a->H, a->W, vertical ? a->H - E : 0, vertical ? 0 : a->W - E, C, h, w);
    mx_copy_rect(r->c, r->tb, h, w, 0, 0, b->px, b->H, b->W, 0, 0, C, h, w);
    mx_binary(r->c, MX_BIN_MUL, r->ta, r->ta, shape, r->ramp_a, wshape, 3);
    mx_binary(r->c, MX_BIN_MUL, r->tb, r->tb, shape, r->ramp_b, wshape, 3);
    mx_add(r->c, r->ta, r->ta, r->tb, (size_t)C * h * w);
    mx_copy_rect(r->c, b->px, b->H, b->W, 0, 0, r->ta, h, w, 0, 0, C, h, w);
}

/* One batch item: decode every tile, blend in row-major order, paste the crops. */
static int decode_item(tiled_run *r, const float *lat, float *img) {
    const tiling *t = &r->t;
    int lc = mx_vae_cfg(r->v)->latent_channels;
    for (int i = 0; i < t->ni; i++)
        for (int j = 0; j < t->nj; j++) {
            tile_buf *b = &r->tiles[(size_t)i * t->nj + j];
            int th = b->H / t->f, tw = b->W / t->f;
            if (!r->dry) mx_copy_rect(r->c, r->win, th, tw, 0, 0, lat, t->h, t->w, i * t->step, j * t->step, lc, th, tw);
            if (mx_vae_decode(r->c, r->v, r->win, 1, th, tw, b->px, r->a, r->st)) return -1;
            if (r->dry) continue;
            if (i > 0) blend(r, &r->tiles[(size_t)(i - 1) * t->nj + j], b, 1);
            if (j > 0) blend(r, &r->tiles[(size_t)i * t->nj + j - 1], b, 0);
            int ch = b->H < t->limit ? b->H : t->limit, cw = b->W < t->limit ? b->W : t->limit;
            mx_copy_rect(r->c, img, t->f * t->h, t->f * t->w, i * t->limit, j * t->limit, b->px, b->H, b->W, 0, 0, t->C,
                         ch, cw);
        }
    return 0;
}

int mx_vae_decode_tiled(const mx_ctx *c, const mx_vae *v, const float *latents, int B, int h, int w, int tile,
                        float *image, mx_arena *a, mx_status *st) {
    if (tile < 4 || tile % 4) return mx_fail(st, MX_EUSAGE, "tiled VAE decode: tile %d is not a positive multiple of 4", tile);
    if (B < 1 || h < 1 || w < 1) return mx_fail(st, MX_EINPUT, "tiled VAE decode: bad sizes %d, %dx%d", B, h, w);
    tiled_run r = {c, v, a, st, a->measuring, {0}, NULL, NULL, NULL, NULL, NULL, NULL};
    plan(&r.t, v, h, w, tile);
    size_t mark = mx_arena_mark(a), lat = (size_t)mx_vae_cfg(v)->latent_channels * h * w;
    size_t img = (size_t)r.t.C * r.t.f * h * r.t.f * w;
    if (h <= tile && w <= tile) { /* one tile: untiled, as diffusers; still one item at a time */
        int rc = 0;
        for (int b = 0; !rc && b < B; b++)
            rc = mx_vae_decode(c, v, r.dry ? NULL : latents + b * lat, 1, h, w, r.dry ? NULL : image + b * img, a, st);
        return rc;
    }
    int rc = alloc_run(&r);
    for (int b = 0; !rc && b < B; b++)
        rc = decode_item(&r, r.dry ? NULL : latents + b * lat, r.dry ? NULL : image + b * img);
    mx_arena_reset(a, mark);
    free(r.tiles);
    free(r.ramp_a);
    return rc ? mx_fail_prefix(st, "tiled VAE decode") : 0;
}

int mx_vae_decode_tiled_arena_bytes(const mx_vae *v, int h, int w, int tile, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_arena_measure(&a);
    if (mx_vae_decode_tiled(NULL, v, NULL, 1, h, w, tile, NULL, &a, st)) return -1;
    *bytes = a.peak + 8 * MX_ARENA_ALIGN;
    return 0;
}

int mx_vae_decode_image_tiled(const mx_ctx *c, const mx_vae *v, const float *latents, int n, int h, int w, int tile,
                              float *image, mx_status *st) {
    const mx_vae_config *cfg = mx_vae_cfg(v);
    size_t bytes, nl = (size_t)n * cfg->latent_channels * h * w;
    size_t ni = (size_t)n * cfg->out_channels * h * w * mx_vae_factor(v) * mx_vae_factor(v);
    mx_arena a = {0};
    if (cfg->scaling_factor == 0.0f) return mx_fail(st, MX_EINPUT, "VAE: scaling_factor is 0");
    if (mx_vae_decode_tiled_arena_bytes(v, h, w, tile, &bytes, st) ||
        mx_arena_create(&a, bytes + nl * sizeof(float) + MX_ARENA_ALIGN, st))
        return -1;
    float *scaled = mx_arena_floats(&a, nl, st);
    int rc = -1;
    if (scaled) {
        mx_scale(c, scaled, latents, 1.0f / cfg->scaling_factor, nl);
        rc = mx_vae_decode_tiled(c, v, scaled, n, h, w, tile, image, &a, st);
    }
    if (!rc) {
        mx_affine(c, image, image, 0.5f, 0.5f, ni);
        mx_clamp(c, image, 0.0f, 1.0f, ni);
    }
    mx_arena_destroy(&a);
    return rc;
}
