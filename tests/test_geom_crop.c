/* The host resamplers of a view and the current textures' dilation on the job's pool: mx_crop_resize
 * (area filter when shrinking, bilinear when growing) and mx_crop_paste equal, bit for bit, a plain
 * per-pixel reference of their definition (camera.h: pixel centres at +0.5, taps clamped to the
 * border, ss x ss samples per output pixel), on no pool, 1 and 3 threads; mx_uv_dilate gives the
 * same texture on any pool, fills exactly `rings` rings around the known texels and changes no
 * texel beyond them; mx_mask_inpaint and mx_bake_texture equal their per-pixel definition on any
 * pool (sizes that are not a multiple of the tasks'). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/camera.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/uvfill.h"
#include "util_test.h"

/* The reference: one bilinear sample at (x, y), clamped to the border. */
static void ref_sample(const mx_image *img, float x, float y, float *out) {
    float fx = x - 0.5f, fy = y - 0.5f;
    int ix = (int)floorf(fx), iy = (int)floorf(fy);
    float tx = fx - (float)ix, ty = fy - (float)iy;
    int xs[2] = {ix, ix + 1}, ys[2] = {iy, iy + 1};
    for (int k = 0; k < 2; k++) {
        xs[k] = xs[k] < 0 ? 0 : xs[k] >= img->w ? img->w - 1 : xs[k];
        ys[k] = ys[k] < 0 ? 0 : ys[k] >= img->h ? img->h - 1 : ys[k];
    }
    for (int c = 0; c < img->c; c++) {
        float a = img->data[((size_t)ys[0] * img->w + xs[0]) * img->c + c];
        float b = img->data[((size_t)ys[0] * img->w + xs[1]) * img->c + c];
        float d = img->data[((size_t)ys[1] * img->w + xs[0]) * img->c + c];
        float e = img->data[((size_t)ys[1] * img->w + xs[1]) * img->c + c];
        out[c] = (a * (1 - tx) + b * tx) * (1 - ty) + (d * (1 - tx) + e * tx) * ty;
    }
}

static void ref_resize(const mx_image *src, mx_crop crop, int size, mx_image *dst) {
    float scale = (float)crop.size / (float)size, px[4];
    int ss = (int)ceilf(scale) < 1 ? 1 : (int)ceilf(scale);
    for (int y = 0; y < size; y++)
        for (int x = 0; x < size; x++) {
            float acc[4] = {0, 0, 0, 0};
            for (int sy = 0; sy < ss; sy++)
                for (int sx = 0; sx < ss; sx++) {
                    float u = (float)crop.x0 + ((float)x + ((float)sx + 0.5f) / (float)ss) * scale;
                    float v = (float)crop.y0 + ((float)y + ((float)sy + 0.5f) / (float)ss) * scale;
                    ref_sample(src, u, v, px);
                    for (int c = 0; c < src->c; c++) acc[c] += px[c];
                }
            for (int c = 0; c < src->c; c++) dst->data[((size_t)y * size + x) * src->c + c] = acc[c] / (float)(ss * ss);
        }
}

static void ref_paste(const mx_image *src, mx_crop crop, mx_image *dst) {
    float scale = (float)src->w / (float)crop.size, px[4];
    int c = src->c < dst->c ? src->c : dst->c;
    for (int y = crop.y0; y < crop.y0 + crop.size && y < dst->h; y++)
        for (int x = crop.x0; x < crop.x0 + crop.size && x < dst->w; x++) {
            if (x < 0 || y < 0) continue;
            ref_sample(src, ((float)(x - crop.x0) + 0.5f) * scale, ((float)(y - crop.y0) + 0.5f) * scale, px);
            for (int k = 0; k < c; k++) dst->data[((size_t)y * dst->w + x) * dst->c + k] = px[k];
        }
}

static int same_image(const mx_image *a, const mx_image *b) {
    return a->w == b->w && a->h == b->h && a->c == b->c &&
           !memcmp(a->data, b->data, (size_t)a->w * a->h * a->c * sizeof(float));
}

static void random_image(mx_image *img, int w, int h, int c, uint64_t seed) {
    mx_status st;
    CHECK(mx_image_alloc(img, w, h, c, &st) == 0);
    mx_fill_random(img->data, (size_t)w * h * c, seed, 0.0f, 1.0f);
}

/* One crop of a 300 x 260 render (c channels) to `size`, and the image of that size pasted back. */
static void resize_and_paste(mx_pool *pool, const char *pool_name, mx_crop crop, int size, int c) {
    mx_status st;
    mx_image src, want, got, small, canvas_want, canvas_got;
    random_image(&src, 300, 260, c, (uint64_t)(size * 7 + c));
    random_image(&small, size, size, c, (uint64_t)(size * 11 + c));
    CHECK(mx_image_alloc(&want, size, size, c, &st) == 0);
    ref_resize(&src, crop, size, &want);
    int ok_resize = mx_crop_resize(&src, crop, size, pool, &got, &st) == 0 && same_image(&want, &got);
    CHECK(ok_resize);
    random_image(&canvas_want, 300, 260, c, 5);
    random_image(&canvas_got, 300, 260, c, 5);
    ref_paste(&small, crop, &canvas_want);
    mx_crop_paste(&small, crop, pool, &canvas_got);
    int ok_paste = same_image(&canvas_want, &canvas_got);
    CHECK(ok_paste);
    printf("crop (%d,%d) %d -> %d, %d channel(s), %-8s resize %s, paste %s\n", crop.x0, crop.y0, crop.size, size, c,
           pool_name, ok_resize ? "equal" : "DIFFERS", ok_paste ? "equal" : "DIFFERS");
    mx_image_free(&src);
    mx_image_free(&want);
    if (ok_resize) mx_image_free(&got);
    mx_image_free(&small);
    mx_image_free(&canvas_want);
    mx_image_free(&canvas_got);
}

static void test_crops(mx_pool *const *pools, const char *const *names, int npools) {
    const struct {
        mx_crop crop;
        int size;
    } cases[] = {{{10, 20, 233}, 64},   /* shrink: 4 x 4 samples a pixel */
                 {{0, 0, 260}, 100},    /* shrink by 2.6: 3 x 3 */
                 {{40, 5, 50}, 128},    /* grow: bilinear */
                 {{-8, 250, 40}, 33},   /* a box over the border: the taps clamp, the paste skips */
                 {{100, 100, 17}, 17}}; /* 1:1 */
    for (int p = 0; p < npools; p++)
        for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++)
            for (int c = 1; c <= 4; c += 2) resize_and_paste(pools[p], names[p], cases[k].crop, cases[k].size, c);
}

/* Known texels in a few discs; the ring distance (Chebyshev) of every unknown texel to them. */
static void test_dilate(mx_pool *const *pools, const char *const *names, int npools) {
    enum { W = 200, H = 150, RINGS = 4 };
    uint8_t *known = calloc(W * H, 1);
    int *ring = malloc(sizeof(int) * W * H);
    for (int i = 0; i < W * H; i++) {
        int x = i % W, y = i / W;
        known[i] = (x - 50) * (x - 50) + (y - 40) * (y - 40) < 400 || (x - 150) * (x - 150) + (y - 100) * (y - 100) < 100;
    }
    for (int i = 0; i < W * H; i++) { /* brute force: nearest known texel in 8-connected steps */
        ring[i] = known[i] ? 0 : 1 << 20;
        for (int j = 0; j < W * H && !known[i]; j++)
            if (known[j]) {
                int dx = abs(i % W - j % W), dy = abs(i / W - j / W), d = dx > dy ? dx : dy;
                if (d < ring[i]) ring[i] = d;
            }
    }
    mx_image first = {0};
    mx_status st;
    for (int p = 0; p < npools; p++) {
        mx_image tex;
        random_image(&tex, W, H, 3, 9);
        mx_image orig;
        random_image(&orig, W, H, 3, 9);
        CHECK(mx_uv_dilate(&tex, known, RINGS, pools[p], &st) == 0);
        int filled_right = 1;
        for (int i = 0; i < W * H; i++) {
            int changed = memcmp(tex.data + 3 * i, orig.data + 3 * i, 3 * sizeof(float)) != 0;
            if (changed != (ring[i] >= 1 && ring[i] <= RINGS)) filled_right = 0;
        }
        CHECK(filled_right);
        int same = p == 0 || same_image(&first, &tex);
        CHECK(same);
        printf("uv dilate %d rings, %-8s %s, %s\n", RINGS, names[p], filled_right ? "rings 1..4 filled, no others" : "WRONG TEXELS",
               same ? "same texture as serial" : "DIFFERS FROM SERIAL");
        mx_image_free(&orig);
        if (p == 0) first = tex;
        else mx_image_free(&tex);
    }
    mx_image_free(&first);
    free(known);
    free(ring);
}

/* A random view of a 2-material mesh over 2 texture layers: mx_mask_inpaint against its definition. */
static void test_mask_inpaint(mx_pool *const *pools, const char *const *names, int npools) {
    enum { W = 301, H = 157, T = 64 };
    mx_status st;
    mx_gbuffer gb;
    CHECK(mx_gbuffer_init(&gb, W, H, &st) == 0);
    float *uv = malloc(sizeof(float) * 2 * W * H);
    uint8_t *known = malloc(2 * T * T), *want = malloc(W * H), *got = malloc(W * H);
    int32_t face_mat[5] = {0, 1, 1, 0, 1};
    mx_mesh m = {0};
    m.nfaces = 5;
    m.nmat = 2;
    m.face_mat = face_mat;
    mx_fill_random(uv, 2 * W * H, 3, -0.5f, 1.5f); /* UVs repeat */
    for (int i = 0; i < W * H; i++) {
        gb.face[i] = (int32_t)((i * 7 + i / W) % 6) - 1; /* -1: background */
        if (i % 97 == 0) uv[2 * i] = NAN;                 /* a face without UVs */
    }
    for (int t = 0; t < 2 * T * T; t++) known[t] = (t * 13) % 5 < 2;
    gb.uv = uv;
    for (int i = 0; i < W * H; i++) {
        int f = gb.face[i];
        want[i] = f >= 0 && isfinite(uv[2 * i]) && !known[(size_t)face_mat[f] * T * T + (size_t)mx_uv_texel(uv[2 * i], uv[2 * i + 1], T, T)];
    }
    for (int p = 0; p < npools; p++) {
        memset(got, 7, W * H);
        mx_mask_inpaint(&gb, &m, NULL, known, T, T, pools[p], got);
        int same = !memcmp(want, got, W * H);
        CHECK(same);
        printf("inpaint mask %dx%d, %-8s %s\n", W, H, names[p], same ? "as defined" : "DIFFERS");
    }
    gb.uv = NULL; /* not the gbuffer's own storage */
    mx_gbuffer_free(&gb);
    free(uv), free(known), free(want), free(got);
}

/* mx_bake_texture of layer 1 of 2 against sum(w c) / sum(w) where known, the fill elsewhere. */
static void test_bake_texture(mx_pool *const *pools, const char *const *names, int npools) {
    enum { T = 131 };
    mx_status st;
    mx_bake b;
    CHECK(mx_bake_init(&b, T, T, 2, &st) == 0);
    const float fill[3] = {0.5f, 0.25f, 0.125f};
    mx_fill_random(b.sum_wc, 2 * T * T * 3, 4, 0.0f, 2.0f);
    mx_fill_random(b.sum_w, 2 * T * T, 5, 0.5f, 2.0f);
    for (int t = 0; t < 2 * T * T; t++) b.known[t] = t % 3 != 0;
    mx_image want;
    CHECK(mx_image_alloc(&want, T, T, 3, &st) == 0);
    for (int t = 0; t < T * T; t++)
        for (int c = 0; c < 3; c++)
            want.data[3 * t + c] = b.known[T * T + t] ? b.sum_wc[3 * (T * T + t) + c] / b.sum_w[T * T + t] : fill[c];
    for (int p = 0; p < npools; p++) {
        mx_image got;
        CHECK(mx_bake_texture(&b, 1, fill, pools[p], &got, &st) == 0);
        int same = same_image(&want, &got);
        CHECK(same);
        printf("bake texture %dx%d, %-8s %s\n", T, T, names[p], same ? "as defined" : "DIFFERS");
        mx_image_free(&got);
    }
    mx_image_free(&want);
    mx_bake_free(&b);
}

int main(void) {
    mx_status st;
    mx_pool *p1 = mx_pool_create(1, &st), *p3 = mx_pool_create(3, &st);
    mx_pool *pools[3] = {NULL, p1, p3};
    const char *names[3] = {"serial,", "1 thread,", "3 threads,"};
    CHECK(p1 && p3);
    test_crops(pools, names, 3);
    test_dilate(pools, names, 3);
    test_mask_inpaint(pools, names, 3);
    test_bake_texture(pools, names, 3);
    mx_pool_destroy(p1);
    mx_pool_destroy(p3);
    return mx_test_finish("test_geom_crop");
}
