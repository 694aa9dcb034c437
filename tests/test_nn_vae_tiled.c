/* Tiled VAE decode (vae_tiled.h) on vae_tiny at diffusers' own tile size for it (sample_size 64 / 8
 * = 8 latents, so 6-latent steps, 16-pixel blends, 48-pixel crops) against diffusers' tiled_decode
 * written out here in plain loops over independently decoded tiles: bit-equal. Where no blend
 * reaches, the output equals the tile's own decode exactly; a latent within one tile decodes
 * exactly as untiled; batch items are independent. The tiled result differs from the untiled
 * decode (tiles see no context beyond their edges, GroupNorm is per tile): that difference is
 * printed for information, no bound is claimed. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/vae_tiled.h"
#include "nn_golden.h"

#define TILE 8
#define LH 20
#define LW 14

static mx_vae *vae;

static int load(golden_weights *g, const mx_ctx *c) {
    mx_status st;
    size_t len;
    mx_vae_config cfg;
    char *text = golden_text("vae_tiny", "config.json", &len);
    int rc = !text || mx_vae_config_parse(&cfg, text, len, "vae_tiny", &st) ||
             golden_weights_open(g, c, "vae_tiny", "diffusion_pytorch_model.safetensors", &st) ||
             mx_vae_load(&vae, &cfg, &g->dev, &st);
    free(text);
    if (rc) fprintf(stderr, "vae_tiny: %s\n", st.msg);
    return rc ? -1 : 0;
}

/* On the test device: latents uploaded, arena on the backend, image fetched; tile 0 = untiled. */
static int decode(const mx_ctx *c, const float *lat, int B, int h, int w, int tile, float *img) {
    mx_status st;
    size_t bytes, nl = (size_t)B * 4 * h * w, ni = (size_t)B * 3 * 64 * h * w;
    mx_arena a;
    int rc = tile ? mx_vae_decode_tiled_arena_bytes(vae, h, w, tile, &bytes, &st)
                  : mx_vae_decode_arena_bytes(vae, B, h, w, &bytes, &st);
    if (rc) return fprintf(stderr, "%s\n", st.msg), -1;
    golden_arena(c, &a, bytes);
    float *dl = golden_dev(c, lat, nl), *di = golden_dev_alloc(c, ni);
    rc = tile ? mx_vae_decode_tiled(c, vae, dl, B, h, w, tile, di, &a, &st)
              : mx_vae_decode(c, vae, dl, B, h, w, di, &a, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    if (golden_fetch(c, img, di, ni)) rc = -1;
    mx_dev_free(c, dl);
    mx_arena_destroy(&a);
    return rc;
}

/* Latent window [4, th, tw] at (r0, c0) of a [4, h, w] latent. */
static void window(const float *lat, int h, int w, int r0, int c0, int th, int tw, float *out) {
    for (int ch = 0; ch < 4; ch++)
        for (int y = 0; y < th; y++) memcpy(out + (ch * th + y) * tw, lat + (ch * h + r0 + y) * w + c0, tw * sizeof(float));
}

typedef struct {
    float *px;
    int H, W;
} tile_img;

/* diffusers' blend_v / blend_h, in place on b (3 channels). */
static void blend_v(const tile_img *a, tile_img *b, int E) {
    if (a->H < E) E = a->H;
    if (b->H < E) E = b->H;
    for (int ch = 0; ch < 3; ch++)
        for (int y = 0; y < E; y++)
            for (int x = 0; x < b->W; x++) {
                float wa = (float)(1.0 - (double)y / E), wb = (float)((double)y / E);
                float *pb = &b->px[(ch * b->H + y) * b->W + x];
                *pb = a->px[(ch * a->H + a->H - E + y) * a->W + x] * wa + *pb * wb;
            }
}

static void blend_h(const tile_img *a, tile_img *b, int E) {
    if (a->W < E) E = a->W;
    if (b->W < E) E = b->W;
    for (int ch = 0; ch < 3; ch++)
        for (int y = 0; y < b->H; y++)
            for (int x = 0; x < E; x++) {
                float wa = (float)(1.0 - (double)x / E), wb = (float)((double)x / E);
                float *pb = &b->px[(ch * b->H + y) * b->W + x];
                *pb = a->px[(ch * a->H + y) * a->W + a->W - E + x] * wa + *pb * wb;
            }
}

/* diffusers' tiled_decode for one item; also returns tile (1, 1) as decoded, before blending. */
static int reference(const mx_ctx *c, const float *lat, float *out, float *tile11) {
    int step = TILE * 3 / 4, E = 8 * TILE / 4, limit = 8 * TILE - E, ni = (LH + step - 1) / step, nj = (LW + step - 1) / step;
    tile_img t[8][8];
    float win[4 * TILE * TILE];
    for (int i = 0; i < ni; i++)
        for (int j = 0; j < nj; j++) {
            int th = LH - i * step < TILE ? LH - i * step : TILE, tw = LW - j * step < TILE ? LW - j * step : TILE;
            t[i][j] = (tile_img){malloc(sizeof(float) * 3 * 64 * th * tw), 8 * th, 8 * tw};
            window(lat, LH, LW, i * step, j * step, th, tw, win);
            if (decode(c, win, 1, th, tw, 0, t[i][j].px)) return -1;
            if (i == 1 && j == 1) memcpy(tile11, t[1][1].px, sizeof(float) * 3 * t[1][1].H * t[1][1].W);
        }
    for (int i = 0; i < ni; i++)
        for (int j = 0; j < nj; j++) {
            if (i > 0) blend_v(&t[i - 1][j], &t[i][j], E);
            if (j > 0) blend_h(&t[i][j - 1], &t[i][j], E);
            int ch_ = t[i][j].H < limit ? t[i][j].H : limit, cw = t[i][j].W < limit ? t[i][j].W : limit;
            for (int ch = 0; ch < 3; ch++)
                for (int y = 0; y < ch_; y++)
                    memcpy(out + (ch * 8 * LH + i * limit + y) * 8 * LW + j * limit, t[i][j].px + (ch * t[i][j].H + y) * t[i][j].W,
                           cw * sizeof(float));
        }
    for (int i = 0; i < ni; i++)
        for (int j = 0; j < nj; j++) free(t[i][j].px);
    return 0;
}

static void check_against_reference(const mx_ctx *c) {
    size_t nl = 4 * LH * LW, ni = 3 * 64 * LH * LW;
    float *lat = malloc(2 * nl * sizeof(float)), *got = malloc(2 * ni * sizeof(float)), *want = malloc(ni * sizeof(float));
    float *tile11 = malloc(3 * 64 * TILE * TILE * sizeof(float)), *plain = malloc(ni * sizeof(float));
    mx_fill_random(lat, 2 * nl, 41, -2.0f, 2.0f);
    CHECK(decode(c, lat, 2, LH, LW, TILE, got) == 0);
    CHECK(reference(c, lat + nl, want, tile11) == 0);
    mx_check_close("tiled decode (item 1 of 2) vs diffusers' algorithm", got + ni, want, ni, 0);
    CHECK(reference(c, lat, want, tile11) == 0);
    mx_check_close("tiled decode (item 0 of 2) vs diffusers' algorithm", got, want, ni, 0);
    /* tile (1, 1) covers output rows/cols 48.. of its 64x64 decode; its rows and cols 16..47 are
     * reached by no blend (the blends take the first 16) and must be its own decode, bit for bit */
    int limit = 48, E = 16, bad = 0;
    for (int ch = 0; ch < 3; ch++)
        for (int y = E; y < limit; y++)
            for (int x = E; x < limit; x++)
                bad += got[(ch * 8 * LH + limit + y) * 8 * LW + limit + x] != tile11[(ch * 64 + y) * 64 + x];
    printf("tile (1,1) outside the blends: %d pixels differ from its own decode\n", bad);
    CHECK(bad == 0);
    CHECK(decode(c, lat, 1, LH, LW, 0, plain) == 0);
    double e = mx_rel_l2(got, plain, ni);
    printf("tiled vs untiled decode (vae_tiny, random weights, 64-pixel tiles): rel_l2=%.3e (information only:\n"
           "  tiles see no context beyond their edges and normalise on their own; no bound is claimed)\n", e);
    free(lat);
    free(got);
    free(want);
    free(tile11);
    free(plain);
}

static void check_small_and_errors(const mx_ctx *c) {
    size_t nl = 4 * TILE * 6, ni = 3 * 64 * TILE * 6;
    float *lat = malloc(2 * nl * sizeof(float)), *a = malloc(2 * ni * sizeof(float)), *b = malloc(2 * ni * sizeof(float));
    mx_fill_random(lat, 2 * nl, 42, -2.0f, 2.0f);
    CHECK(decode(c, lat, 2, TILE, 6, TILE, a) == 0);
    CHECK(decode(c, lat, 2, TILE, 6, 0, b) == 0);
    mx_check_close("within one tile: as untiled", a, b, 2 * ni, 0);
    mx_status st;
    size_t bytes;
    CHECK(mx_vae_decode_tiled_arena_bytes(vae, LH, LW, 6, &bytes, &st) == -1 && strstr(st.msg, "multiple of 4"));
    size_t tiled, whole;
    CHECK(mx_vae_decode_tiled_arena_bytes(vae, 64, 64, 16, &tiled, &st) == 0);
    CHECK(mx_vae_decode_arena_bytes(vae, 1, 64, 64, &whole, &st) == 0);
    printf("arena: 64x64 latent untiled %.1f MB, tiles of 16: %.1f MB\n", whole / 1e6, tiled / 1e6);
    CHECK(tiled * 4 < whole);
    free(lat);
    free(a);
    free(b);
}

int main(void) {
    mx_ctx c;
    golden_weights g;
    if (golden_ctx(&c)) return 1;
    CHECK(load(&g, &c) == 0);
    if (vae) {
        check_against_reference(&c);
        check_small_and_errors(&c);
    }
    mx_vae_free(vae);
    golden_weights_close(&g);
    mx_ctx_destroy(&c);
    return mx_test_finish("test_nn_vae_tiled");
}
