/* Backprojection: splat weights sum to one per pixel, results identical for 1 and 3
 * threads, later views leave T^B texels alone, better-angle overwrite restarts texels,
 * mx_bake_open_texels opens only texels the better view then restarts, UV fill reaches every chart
 * texel. Mesh: a tilted plane of 2 x 32 triangles with UVs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/uvfill.h"
#include "util_test.h"

#define S 200
#define T 128

/* A 5x5-vertex grid in the z = 0 plane, [-0.8, 0.8]^2, UVs over [0.1, 0.9]^2. */
static void make_plane(mx_mesh *m, float *pos, float *uv, int32_t *faces) {
    enum { G = 4 };
    memset(m, 0, sizeof *m);
    for (int j = 0; j <= G; j++)
        for (int i = 0; i <= G; i++) {
            int v = j * (G + 1) + i;
            pos[3 * v] = -0.8f + 1.6f * i / G;
            pos[3 * v + 1] = -0.8f + 1.6f * j / G;
            pos[3 * v + 2] = 0.05f * sinf((float)(i * 3 + j));
            uv[2 * v] = 0.1f + 0.8f * i / G;
            uv[2 * v + 1] = 0.1f + 0.8f * j / G;
        }
    int nf = 0;
    for (int j = 0; j < G; j++)
        for (int i = 0; i < G; i++) {
            int a = j * (G + 1) + i, b = a + 1, c = a + G + 1, d = c + 1;
            int32_t t[6] = {a, b, d, a, d, c};
            memcpy(faces + 3 * nf, t, sizeof t);
            nf += 2;
        }
    m->nverts = (G + 1) * (G + 1);
    m->nfaces = nf;
    m->pos = pos;
    m->faces = faces;
    m->nuv = m->nverts;
    m->uv = uv;
    m->face_uv = faces;
}

static void bake_once(const mx_mesh *m, const mx_camera *cam, const mx_image *img, int threads,
                      mx_bake *bake) {
    mx_status st;
    mx_pool *pool = mx_pool_create(threads, &st);
    mx_gbuffer gb;
    CHECK(mx_gbuffer_init(&gb, S, S, &st) == 0);
    CHECK(mx_rasterize(m, NULL, cam, MX_RASTER_CULL_BACK | MX_RASTER_UV, pool, &gb, &st) == 0);
    CHECK(mx_backproject(bake, &gb, m, img, NULL, 0, pool, &st) == 0);
    mx_gbuffer_free(&gb);
    mx_pool_destroy(pool);
}

/* mx_bake_open_texels before the overwrite pass of a better view: it opens only known texels,
 * enough of them, and each one it opens is one the pass then restarted (sum_w changed). */
static void check_open_texels(const uint8_t *known, const uint8_t *open, const float *sum_w_after,
                              const float *sum_w_before) {
    int opened = 0, opened_unknown = 0, opened_kept = 0;
    for (int t = 0; t < T * T; t++) {
        if (!open[t] && !known[t]) continue;
        if (open[t] && !known[t]) opened_unknown++;
        if (!open[t]) {
            opened++;
            opened_kept += sum_w_after[t] == sum_w_before[t];
        }
    }
    printf("open texels: %d opened by the better view, %d not known before, %d not restarted\n", opened,
           opened_unknown, opened_kept);
    CHECK(opened > 100 && opened_unknown == 0 && opened_kept == 0);
}

/* mx_bake_open_texels opens nothing for the view that wrote the texels (no gain in |n.v|) nor
 * where the mask excludes every pixel, and the known set comes back unchanged. */
static void check_open_texels_closed(const mx_mesh *m, const mx_camera *writer, const mx_camera *better,
                                     const uint8_t *known, mx_pool *pool) {
    mx_status st;
    mx_bake c;
    mx_gbuffer gw, gbt;
    CHECK(mx_bake_init(&c, T, T, 1, &st) == 0);
    CHECK(mx_gbuffer_init(&gw, S, S, &st) == 0 && mx_gbuffer_init(&gbt, S, S, &st) == 0);
    CHECK(mx_rasterize(m, NULL, writer, MX_RASTER_CULL_BACK | MX_RASTER_UV, pool, &gw, &st) == 0);
    CHECK(mx_rasterize(m, NULL, better, MX_RASTER_CULL_BACK | MX_RASTER_UV, pool, &gbt, &st) == 0);
    mx_image img;
    CHECK(mx_image_alloc(&img, S, S, 3, &st) == 0);
    mx_fill_random(img.data, 3 * S * S, 7, 0, 1);
    CHECK(mx_backproject(&c, &gw, m, &img, NULL, 0, pool, &st) == 0);
    CHECK(memcmp(c.known, known, T * T) == 0);
    uint8_t *open = malloc(T * T), *none = calloc(S * S, 1);
    mx_bake_open_texels(&c, &gw, m, NULL, open);
    int same_view = memcmp(open, known, T * T) == 0;
    mx_bake_open_texels(&c, &gbt, m, none, open);
    int masked = memcmp(open, known, T * T) == 0;
    printf("open texels: writer view opens none %d, empty mask opens none %d\n", same_view, masked);
    CHECK(same_view && masked);
    free(open);
    free(none);
    mx_image_free(&img);
    mx_gbuffer_free(&gw);
    mx_gbuffer_free(&gbt);
    mx_bake_free(&c);
}

int main(void) {
    float pos[75], uv[50];
    int32_t faces[96];
    mx_mesh m;
    make_plane(&m, pos, uv, faces);
    mx_status st;
    mx_image img;
    CHECK(mx_image_alloc(&img, S, S, 3, &st) == 0);
    mx_fill_random(img.data, 3 * S * S, 5, 0, 1);
    mx_camera front, oblique;
    mx_camera_ortho(&front, 0, 0, 3, 1);
    mx_camera_ortho(&oblique, 50, 10, 3, 1);

    /* weights: on the first view every used pixel adds exactly 1 to sum(w) */
    mx_bake a, b;
    CHECK(mx_bake_init(&a, T, T, 1, &st) == 0 && mx_bake_init(&b, T, T, 1, &st) == 0);
    bake_once(&m, &oblique, &img, 1, &a);
    bake_once(&m, &oblique, &img, 3, &b);
    double total = 0;
    for (int t = 0; t < T * T; t++) total += a.sum_w[t];
    mx_gbuffer gb;
    CHECK(mx_gbuffer_init(&gb, S, S, &st) == 0);
    CHECK(mx_rasterize(&m, NULL, &oblique, MX_RASTER_CULL_BACK, NULL, &gb, &st) == 0);
    int64_t npix = 0;
    for (int i = 0; i < S * S; i++) npix += gb.face[i] >= 0;
    printf("sum of weights %.3f, pixels %lld\n", total, (long long)npix);
    CHECK(npix > 1000 && fabs(total - (double)npix) < 1e-3 * (double)npix);
    int same = !memcmp(a.sum_w, b.sum_w, sizeof(float) * T * T) &&
               !memcmp(a.sum_wc, b.sum_wc, sizeof(float) * 3 * T * T) && !memcmp(a.known, b.known, T * T);
    printf("1 vs 3 threads identical: %d\n", same);
    CHECK(same);

    /* a later view leaves T^B texels unchanged */
    float *before = malloc(sizeof(float) * T * T);
    uint8_t *known_before = malloc(T * T);
    memcpy(before, a.sum_w, sizeof(float) * T * T);
    memcpy(known_before, a.known, T * T);
    mx_image img2;
    CHECK(mx_image_alloc(&img2, S, S, 3, &st) == 0);
    mx_fill_random(img2.data, 3 * S * S, 6, 0, 1);
    bake_once(&m, &front, &img2, 2, &a);
    int changed_known = 0, new_known = 0;
    for (int t = 0; t < T * T; t++) {
        if (known_before[t] && a.sum_w[t] != before[t]) changed_known++;
        if (!known_before[t] && a.known[t]) new_known++;
    }
    printf("second view: %d T^B texels changed (want 0), %d new\n", changed_known, new_known);
    CHECK(changed_known == 0);
    CHECK(new_known > 0);

    /* better-angle overwrite: the front view sees the plane head-on, the oblique view at 50 deg */
    mx_pool *pool = mx_pool_create(2, &st);
    CHECK(mx_rasterize(&m, NULL, &front, MX_RASTER_CULL_BACK | MX_RASTER_UV, pool, &gb, &st) == 0);
    uint8_t *open = malloc(T * T);
    mx_bake_open_texels(&b, &gb, &m, NULL, open);
    CHECK(mx_backproject(&b, &gb, &m, &img2, NULL, MX_BACKPROJECT_OVERWRITE, pool, &st) == 0);
    int restarted = 0;
    for (int t = 0; t < T * T; t++) restarted += known_before[t] && b.sum_w[t] != before[t];
    printf("overwrite: %d texels restarted by the better view\n", restarted);
    CHECK(restarted > 100);
    check_open_texels(known_before, open, b.sum_w, before);
    check_open_texels_closed(&m, &oblique, &front, known_before, pool);
    free(open);

    /* UV fill: every chart texel gets a value, gutter texels around the chart too */
    mx_image tex;
    const float fill[3] = {-1, -1, -1};
    CHECK(mx_bake_texture(&a, 0, fill, &tex, &st) == 0);
    uint8_t *chart = malloc(T * T);
    CHECK(mx_uv_chart_mask(&m, 0, 1, T, T, chart, &st) == 0);
    CHECK(mx_uv_fill(&tex, a.known, chart, 2, &st) == 0);
    int missing = 0, charted = 0;
    for (int t = 0; t < T * T; t++) {
        charted += chart[t];
        if (chart[t] && tex.data[3 * t] < 0) missing++;
    }
    int gutter_ok = tex.data[3 * ((T - (int)(0.9f * T) - 2) * T + T / 2)] >= 0; /* 2 rows above the top edge */
    printf("uv fill: %d chart texels, %d left unfilled, gutter filled: %d\n", charted, missing, gutter_ok);
    CHECK(charted > 0.6 * T * T && missing == 0 && gutter_ok);
    CHECK(tex.data[0] < 0); /* far outside: untouched */

    mx_image_free(&tex);
    free(chart);
    free(before);
    free(known_before);
    mx_gbuffer_free(&gb);
    mx_pool_destroy(pool);
    mx_image_free(&img);
    mx_image_free(&img2);
    mx_bake_free(&a);
    mx_bake_free(&b);
    return mx_test_finish("test_geom_backproject");
}
