/* Tiled VAE decode (see vae_tiled.h): tiles through mx_vae_decode, crops, pastes and the linear
 * blend through ops (copy_rect, binary with a broadcast weight ramp uploaded at the edge). In a
 * dry run (measuring arena) the ops return at once and the arena counts the same allocations. */
#include "vae_tiled.h"

#include <stdlib.h>

#include "ae_pass.h"

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
    const mx_ctx *c; /* ops context: the measuring one in a dry run */
    const mx_ctx *dev; /* the caller's context (mx_vae_decode picks its own) */
    const mx_vae *v;
    mx_arena *a;
    mx_status *st;
    tiling t;
    tile_buf *tiles; /* ni * nj, row-major */
    float *win, *ta, *tb;
    float *ramp_a, *ramp_b; /* device: blend weights 1 - y/E and y/E for the current E */
    float *host_ramp;       /* 2 * blend host floats, the upload's source */
} tiled_run;

static int alloc_run(tiled_run *r) {
    const tiling *t = &r->t;
    size_t ntiles = (size_t)t->ni * t->nj, side = (size_t)t->f * t->tile;
    r->tiles = calloc(ntiles, sizeof *r->tiles);
    r->host_ramp = malloc(2 * (size_t)t->blend * sizeof(float));
    if (!r->tiles || !r->host_ramp) return mx_fail(r->st, MX_ENOMEM, "tiled VAE decode: out of memory");
    for (int i = 0; i < t->ni; i++)
        for (int j = 0; j < t->nj; j++) {
            tile_buf *b = &r->tiles[(size_t)i * t->nj + j];
            b->H = t->f * tile_len(t, i, t->h);
            b->W = t->f * tile_len(t, j, t->w);
            if (!(b->px = mx_act_alloc(r->a, (size_t)t->C * b->H * b->W, r->st))) return -1;
        }
    r->win = mx_act_alloc(r->a, (size_t)mx_vae_cfg(r->v)->latent_channels * t->tile * t->tile, r->st);
    r->ta = mx_act_alloc(r->a, (size_t)t->C * t->blend * side, r->st);
    r->tb = mx_act_alloc(r->a, (size_t)t->C * t->blend * side, r->st);
    r->ramp_a = mx_act_alloc(r->a, (size_t)t->blend, r->st);
    r->ramp_b = mx_act_alloc(r->a, (size_t)t->blend, r->st);
    return r->win && r->ta && r->tb && r->ramp_a && r->ramp_b ? 0 : -1;
}

/* The ramps of a blend over E pixels, in float as torch scales by the Python floats y/E; made on
 * the host (constants, like weights) and uploaded. */
static int load_ramps(tiled_run *r, int E) {
    float *a = r->host_ramp, *b = r->host_ramp + E;
    for (int y = 0; y < E; y++) {
        a[y] = (float)(1.0 - (double)y / E);
        b[y] = (float)((double)y / E);
    }
    return mx_upload(r->c, r->ramp_a, a, (size_t)E, r->st) || mx_upload(r->c, r->ramp_b, b, (size_t)E, r->st) ? -1 : 0;
}

/* b's first E rows (vertical) or columns: a's last E (.. (1 - y/E)) + b's first E (.. y/E). */
static int blend(tiled_run *r, const tile_buf *a, tile_buf *b, int vertical) {
    int E = r->t.blend, C = r->t.C;
    int na = vertical ? a->H : a->W, nb = vertical ? b->H : b->W;
    if (na < E) E = na;
    if (nb < E) E = nb;
    int h = vertical ? E : b->H, w = vertical ? b->W : E;
    int64_t shape[3] = {C, h, w}, wshape[3] = {1, vertical ? E : 1, vertical ? 1 : E};
    if (load_ramps(r, E)) return -1;
    mx_copy_rect(r->c, r->ta, h, w, 0, 0, a->px, a->H, a->W, vertical ? a->H - E : 0, vertical ? 0 : a->W - E, C, h, w);
    mx_copy_rect(r->c, r->tb, h, w, 0, 0, b->px, b->H, b->W, 0, 0, C, h, w);
    mx_binary(r->c, MX_BIN_MUL, r->ta, r->ta, shape, r->ramp_a, wshape, 3);
    mx_binary(r->c, MX_BIN_MUL, r->tb, r->tb, shape, r->ramp_b, wshape, 3);
    mx_add(r->c, r->ta, r->ta, r->tb, (size_t)C * h * w);
    mx_copy_rect(r->c, b->px, b->H, b->W, 0, 0, r->ta, h, w, 0, 0, C, h, w);
    return 0;
}

/* One batch item: decode every tile, blend in row-major order, paste the crops. */
static int decode_item(tiled_run *r, const float *lat, float *img) {
    const tiling *t = &r->t;
    int lc = mx_vae_cfg(r->v)->latent_channels;
    for (int i = 0; i < t->ni; i++)
        for (int j = 0; j < t->nj; j++) {
            tile_buf *b = &r->tiles[(size_t)i * t->nj + j];
            int th = b->H / t->f, tw = b->W / t->f;
            mx_copy_rect(r->c, r->win, th, tw, 0, 0, lat, t->h, t->w, i * t->step, j * t->step, lc, th, tw);
            if (mx_vae_decode(r->dev, r->v, r->win, 1, th, tw, b->px, r->a, r->st)) return -1;
            if (i > 0 && blend(r, &r->tiles[(size_t)(i - 1) * t->nj + j], b, 1)) return -1;
            if (j > 0 && blend(r, &r->tiles[(size_t)i * t->nj + j - 1], b, 0)) return -1;
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
    tiled_run r = {mx_run_ctx(c, a), c, v, a, st, {0}, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
    plan(&r.t, v, h, w, tile);
    size_t mark = mx_arena_mark(a), lat = (size_t)mx_vae_cfg(v)->latent_channels * h * w;
    size_t img = (size_t)r.t.C * r.t.f * h * r.t.f * w;
    int rc = 0;
    if (h <= tile && w <= tile) { /* one tile: untiled, as diffusers; still one item at a time */
        for (int b = 0; !rc && b < B; b++)
            rc = mx_vae_decode(c, v, latents + b * lat, 1, h, w, image + b * img, a, st);
        return rc;
    }
    rc = alloc_run(&r);
    for (int b = 0; !rc && b < B; b++)
        rc = decode_item(&r, latents + b * lat, image + b * img);
    mx_arena_reset(a, mark);
    free(r.tiles);
    free(r.host_ramp);
    return rc ? mx_fail_prefix(st, "tiled VAE decode") : 0;
}

int mx_vae_decode_tiled_arena_bytes(const mx_vae *v, int h, int w, int tile, size_t *bytes, mx_status *st) {
    mx_arena a;
    mx_arena_measure(&a);
    if (mx_vae_decode_tiled(NULL, v, mx_act_placeholder(), 1, h, w, tile, mx_act_placeholder(), &a, st)) return -1;
    *bytes = a.peak + 8 * MX_ARENA_ALIGN;
    return 0;
}

typedef struct tiled_net {
    const mx_vae *v;
    int tile;
} tiled_net;

static int decode_tiled_dev(const mx_ctx *c, const void *net, const float *latents, int n, int h, int w, float *image,
                            mx_arena *a, mx_status *st) {
    const tiled_net *t = net;
    return mx_vae_decode_tiled(c, t->v, latents, n, h, w, t->tile, image, a, st);
}

int mx_vae_decode_image_tiled(const mx_ctx *c, const mx_vae *v, const float *latents, int n, int h, int w, int tile,
                              float *image, mx_status *st) {
    const mx_vae_config *cfg = mx_vae_cfg(v);
    tiled_net t = {v, tile};
    mx_ae_coder d = {decode_tiled_dev, &t, cfg->latent_channels, cfg->out_channels, mx_vae_factor(v),
                     cfg->scaling_factor, 0};
    if (mx_vae_decode_tiled_arena_bytes(v, h, w, tile, &d.arena_bytes, st)) return -1;
    return mx_ae_decode_host(c, &d, latents, n, h, w, image, st);
}
