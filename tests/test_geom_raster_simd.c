/* Rasterizer kernels and parallel paths: the AVX2 triangle kernel against the scalar one
 * (MATEX_ISA=scalar selects it), 1 against 3 threads, bit for bit on every buffer, on
 * a random soup of triangles of every size (sub-pixel to larger than the image, both
 * windings, partly off screen, some without UVs) seen by orthographic and perspective
 * cameras at image sizes that are not multiples of the tile or the vector width. Then
 * the backprojection and the view cache (candidates rendered in parallel or one by one)
 * across thread counts. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/raster.h"
#include "../pipeline/geom/views.h"
#include "../runtime/backend.h"
#include "util_test.h"

#define NFACES 3000

typedef struct soup {
    mx_mesh m;
    float pos[NFACES * 9], uv[NFACES * 6];
    int32_t faces[NFACES * 3], face_uv[NFACES * 3];
} soup;

/* Triangles around random centres; sizes spread over four orders of magnitude. */
static void make_soup(soup *s) {
    float r[NFACES * 13];
    mx_fill_random(r, sizeof r / sizeof *r, 7, 0, 1);
    memset(&s->m, 0, sizeof s->m);
    for (int f = 0; f < NFACES; f++) {
        const float *q = r + 13 * f;
        float size = 0.002f * powf(1000.0f, q[0]) * (f % 97 == 0 ? 3 : 1);
        for (int k = 0; k < 3; k++) {
            for (int d = 0; d < 3; d++)
                s->pos[9 * f + 3 * k + d] = 2.4f * (q[1 + d] - 0.5f) + size * (q[4 + 3 * k + d] - 0.5f) * 2;
            s->faces[3 * f + k] = 3 * f + k;
            s->face_uv[3 * f + k] = f % 53 == 0 && k == 1 ? -1 : 3 * f + k; /* some faces lack UVs */
            s->uv[6 * f + 2 * k] = q[4 + k];
            s->uv[6 * f + 2 * k + 1] = q[7 + k];
        }
    }
    /* the last 128 faces: a grid of quads with corners on pixel centres of the 64 x 64
     * front view (world (x, y) -> pixel (32 + 32x, 32 - 32y)), in front of the rest, where
     * the top-left rule decides */
    for (int q = 0; q < 64; q++) {
        float x0 = (4.5f + 7 * (q % 8) - 32) / 32, x1 = x0 + 7.0f / 32;
        float y0 = (32 - 4.5f - 7 * (q / 8)) / 32, y1 = y0 - 7.0f / 32;
        const float corners[2][9] = {{x0, y0, 2.0f, x0, y1, 2.0f, x1, y1, 2.0f},
                                     {x0, y0, 2.0f, x1, y1, 2.0f, x1, y0, 2.0f}};
        memcpy(s->pos + 9 * (NFACES - 128 + 2 * q), corners, sizeof corners);
    }
    s->m.nverts = 3 * NFACES;
    s->m.nfaces = NFACES;
    s->m.pos = s->pos;
    s->m.faces = s->faces;
    s->m.nuv = 3 * NFACES;
    s->m.uv = s->uv;
    s->m.face_uv = s->face_uv;
    snprintf(s->m.source_path, sizeof s->m.source_path, "random soup");
}

static int same(const void *a, const void *b, size_t n) {
    return (!a && !b) || (a && b && memcmp(a, b, n) == 0);
}

/* Renders with the given ISA setting and pool; returns 0 on success. */
static int render(const mx_mesh *m, const mx_camera *cam, int flags, const char *isa, mx_pool *pool,
                  int w, int h, mx_gbuffer *gb) {
    mx_status st;
    if (isa)
        setenv("MATEX_ISA", isa, 1);
    else
        unsetenv("MATEX_ISA");
    int rc = mx_gbuffer_init(gb, w, h, &st) || mx_rasterize(m, NULL, cam, flags, pool, gb, &st);
    unsetenv("MATEX_ISA");
    if (rc) fprintf(stderr, "render: %s\n", st.msg);
    return rc;
}

static int gbuffers_equal(const mx_gbuffer *a, const mx_gbuffer *b) {
    size_t n = (size_t)a->w * a->h;
    int eq = same(a->face, b->face, n * 4) && same(a->depth, b->depth, n * 4) &&
             same(a->depth_unculled, b->depth_unculled, n * 4) && same(a->bary, b->bary, n * 8) &&
             same(a->uv, b->uv, n * 8);
    for (size_t i = 0; eq && i < n; i += 5) { /* normals of visible faces */
        float na[3], nb[3];
        mx_gbuffer_normal(a, (int64_t)i, na);
        mx_gbuffer_normal(b, (int64_t)i, nb);
        eq = memcmp(na, nb, sizeof na) == 0;
    }
    return eq;
}

static int64_t visible_pixels(const mx_gbuffer *gb) {
    int64_t n = 0;
    for (size_t i = 0; i < (size_t)gb->w * gb->h; i++) n += gb->face[i] >= 0;
    return n;
}

static void check_kernels(const mx_mesh *m, mx_pool *pool3) {
    mx_camera cams[4];
    mx_camera_ortho(&cams[0], 20, 10, 3, 1.3f);
    mx_camera_persp(&cams[1], 200, -30, 3.2f, 55);
    mx_camera_ortho(&cams[2], 0, 89, 3, 0.4f); /* zoomed in: triangles larger than the image */
    mx_camera_ortho(&cams[3], 0, 0, 3, 1);     /* the grid's corners on pixel centres (64 x 64) */
    const int sizes[3][2] = {{301, 257}, {1000, 77}, {64, 64}};
    const int flagsets[3] = {MX_RASTER_CULL_BACK | MX_RASTER_UV | MX_RASTER_DEPTH_UNCULLED, MX_RASTER_UV,
                             MX_RASTER_CULL_BACK};
    int cases = 0, equal = 0;
    int64_t visible = 0;
    for (int c = 0; c < 4; c++)
        for (int s = 0; s < 3; s++)
            for (int fl = 0; fl < 3; fl++) {
                mx_gbuffer ref, simd, threads;
                int w = sizes[s][0], h = sizes[s][1];
                if (render(m, &cams[c], flagsets[fl], "scalar", NULL, w, h, &ref) ||
                    render(m, &cams[c], flagsets[fl], NULL, NULL, w, h, &simd) ||
                    render(m, &cams[c], flagsets[fl], NULL, pool3, w, h, &threads)) {
                    CHECK(0);
                    return;
                }
                cases++;
                visible += visible_pixels(&ref);
                equal += gbuffers_equal(&ref, &simd) && gbuffers_equal(&ref, &threads);
                mx_gbuffer_free(&ref);
                mx_gbuffer_free(&simd);
                mx_gbuffer_free(&threads);
            }
    printf("raster scalar vs %s vs 3 threads: %d of %d cases identical, %lld visible pixels\n",
           mx_isa_name(mx_cpu_best_isa()), equal, cases, (long long)visible);
    CHECK(equal == cases && cases == 36);
    CHECK(visible > 10000); /* the soup is actually seen */
}

/* Backprojection of two views (the second with OVERWRITE) with 1 and 3 threads. */
static void check_backprojection(const mx_mesh *m, mx_pool *pool3) {
    mx_status st;
    mx_camera cams[2];
    mx_camera_ortho(&cams[0], 0, 0, 3, 1.3f);
    mx_camera_persp(&cams[1], 120, 40, 3.0f, 60);
    mx_bake bakes[2];
    mx_image img;
    CHECK(mx_bake_init(&bakes[0], 200, 150, 1, &st) == 0 && mx_bake_init(&bakes[1], 200, 150, 1, &st) == 0);
    CHECK(mx_image_alloc(&img, 211, 211, 3, &st) == 0);
    mx_fill_random(img.data, (size_t)211 * 211 * 3, 11, 0, 1);
    for (int t = 0; t < 2; t++) {
        mx_view_buffers vb;
        CHECK(mx_view_buffers_init(&vb, 211, &st) == 0);
        for (int v = 0; v < 2; v++) {
            CHECK(mx_view_prepare(&vb, m, NULL, &cams[v], MX_NORMAL_GEOMETRIC, 0.2f, t ? pool3 : NULL, &st) == 0);
            CHECK(mx_backproject(&bakes[t], &vb.gb, m, &img, vb.mask, v ? MX_BACKPROJECT_OVERWRITE : 0,
                                 t ? pool3 : NULL, &st) == 0);
        }
        mx_view_buffers_free(&vb);
    }
    size_t n = (size_t)200 * 150;
    int64_t known = mx_bake_known_count(&bakes[0]);
    printf("backprojection 1 vs 3 threads: %lld texels known\n", (long long)known);
    CHECK(known > 1000);
    CHECK(same(bakes[0].sum_wc, bakes[1].sum_wc, 12 * n) && same(bakes[0].sum_w, bakes[1].sum_w, 4 * n));
    CHECK(same(bakes[0].known, bakes[1].known, n) && same(bakes[0].quality, bakes[1].quality, 4 * n));
    mx_bake_free(&bakes[0]);
    mx_bake_free(&bakes[1]);
    mx_image_free(&img);
}

/* The candidate cache: serial (no pool) and one candidate per task (3 threads). */
static void check_view_cache(const mx_mesh *m, mx_pool *pool3) {
    mx_status st;
    mx_camera tmpl, cands[12];
    mx_camera_ortho(&tmpl, 0, 0, 3, 1.3f);
    mx_camera_fibonacci(cands, 12, &tmpl);
    mx_view_cache a, b;
    CHECK(mx_view_cache_build(&a, m, NULL, cands, 12, 96, 128, 128, 1, MX_NORMAL_GEOMETRIC, 0.1f, 0, NULL, &st) == 0);
    CHECK(mx_view_cache_build(&b, m, NULL, cands, 12, 96, 128, 128, 1, MX_NORMAL_GEOMETRIC, 0.1f, 0, pool3, &st) == 0);
    int equal = 0;
    int64_t total = 0;
    for (int c = 0; c < 12; c++) {
        total += a.ntexels[c];
        equal += a.ntexels[c] == b.ntexels[c] &&
                 same(a.texels[c], b.texels[c], (size_t)a.ntexels[c] * sizeof *a.texels[c]);
    }
    printf("view cache serial vs parallel: %d of 12 candidates identical, %lld texels\n", equal,
           (long long)total);
    CHECK(equal == 12);
    CHECK(total > 1000);
    mx_view_cache_free(&a);
    mx_view_cache_free(&b);
}

/* Out-of-range indices (now checked inside the parallel count pass) are errors naming the face. */
static void check_bad_indices(soup *s, mx_pool *pool3) {
    mx_status st;
    mx_camera cam;
    mx_camera_ortho(&cam, 0, 0, 3, 1.3f);
    mx_gbuffer gb;
    CHECK(mx_gbuffer_init(&gb, 64, 64, &st) == 0);
    s->face_uv[3 * 2500 + 1] = s->m.nuv;
    int rc = mx_rasterize(&s->m, NULL, &cam, MX_RASTER_UV, pool3, &gb, &st);
    CHECK(rc != 0 && strstr(st.msg, "face 2500 uses UV") != NULL);
    s->face_uv[3 * 2500 + 1] = 3 * 2500 + 1;
    s->faces[3 * 1234 + 2] = -5;
    rc = mx_rasterize(&s->m, NULL, &cam, 0, pool3, &gb, &st);
    CHECK(rc != 0 && strstr(st.msg, "face 1234 uses vertex -5") != NULL);
    s->faces[3 * 1234 + 2] = 3 * 1234 + 2;
    CHECK(mx_rasterize(&s->m, NULL, &cam, MX_RASTER_UV, pool3, &gb, &st) == 0);
    mx_gbuffer_free(&gb);
}

int main(void) {
    mx_status st;
    static soup s;
    make_soup(&s);
    mx_pool *pool3 = mx_pool_create(3, &st);
    CHECK(pool3 != NULL);
    if (pool3) {
        check_kernels(&s.m, pool3);
        check_backprojection(&s.m, pool3);
        check_view_cache(&s.m, pool3);
        check_bad_indices(&s, pool3);
    }
    mx_pool_destroy(pool3);
    return mx_test_finish("test_geom_raster_simd");
}
