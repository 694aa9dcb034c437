/* Rasterizer: fill rule (no cracks, no double coverage) on hand-made meshes, sub-pixel and
 * degenerate triangles, culling convention, UV interpolation, thread-count invariance. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/raster.h"
#include "util_test.h"

#define W 64

/* Front camera (az 0) seeing [-1,1]^2: world (x, y) -> pixel (32 + 32x, 32 - 32y). */
static mx_camera front_camera(void) {
    mx_camera c;
    mx_camera_ortho(&c, 0, 0, 3, 1);
    return c;
}

static void pixel_to_world(float px, float py, float *out) {
    out[0] = (px - 32.0f) / 32.0f;
    out[1] = (32.0f - py) / 32.0f;
    out[2] = 0;
}

/* counts[p] = number of faces covering pixel p, rasterizing each face on its own. */
static void coverage_counts(const mx_mesh *m, mx_pool *pool, int *counts) {
    mx_status st;
    mx_gbuffer gb;
    mx_camera cam = front_camera();
    CHECK(mx_gbuffer_init(&gb, W, W, &st) == 0);
    memset(counts, 0, sizeof(int) * W * W);
    for (int f = 0; f < m->nfaces; f++) {
        mx_mesh one = *m;
        one.faces = m->faces + 3 * f;
        one.nfaces = 1;
        one.face_uv = NULL;
        CHECK(mx_rasterize(&one, NULL, &cam, 0, pool, &gb, &st) == 0);
        for (int i = 0; i < W * W; i++) counts[i] += gb.face[i] >= 0;
    }
    mx_gbuffer_free(&gb);
}

/* Side of point p against the directed edge a->b in pixel space (> 0: left in y-down). */
static double side(const double *a, const double *b, double px, double py) {
    return (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]);
}

/* 1 if pixel centre (x, y) is inside the convex polygon (pixel coords) by more than margin. */
static int inside_convex(const double (*poly)[2], int n, int x, int y, double margin) {
    double px = x + 0.5, py = y + 0.5;
    int pos = 0, neg = 0;
    for (int k = 0; k < n; k++) {
        const double *a = poly[k], *b = poly[(k + 1) % n];
        double len = hypot(b[0] - a[0], b[1] - a[1]);
        double s = side(a, b, px, py) / len;
        if (s > margin) pos++;
        if (s < -margin) neg++;
    }
    return pos == n || neg == n;
}

static int outside_convex(const double (*poly)[2], int n, int x, int y, double margin) {
    double px = x + 0.5, py = y + 0.5;
    for (int k = 0; k < n; k++) {
        const double *a = poly[k], *b = poly[(k + 1) % n];
        double len = hypot(b[0] - a[0], b[1] - a[1]);
        /* polygon given clockwise on screen -> inside is s > 0 */
        if (side(a, b, px, py) / len < -margin) return 1;
    }
    return 0;
}

/* A convex polygon split into a fan around vertex `centre` (index n), every pixel centre
 * inside is covered exactly once, and none outside. */
static void check_fan(const char *name, const double (*poly)[2], int n, const double centre[2],
                      mx_pool *pool) {
    float pos[3 * 17];
    int32_t faces[3 * 16];
    for (int k = 0; k < n; k++) pixel_to_world((float)poly[k][0], (float)poly[k][1], pos + 3 * k);
    pixel_to_world((float)centre[0], (float)centre[1], pos + 3 * n);
    for (int k = 0; k < n; k++) {
        /* counter-clockwise in world = clockwise on screen: (centre, k+1, k) for a
         * screen-clockwise polygon */
        faces[3 * k] = n;
        faces[3 * k + 1] = (k + 1) % n;
        faces[3 * k + 2] = k;
    }
    mx_mesh m = {0};
    m.nverts = n + 1;
    m.nfaces = n;
    m.pos = pos;
    m.faces = faces;
    int counts[W * W];
    coverage_counts(&m, pool, counts);
    int doubles = 0, cracks = 0, strays = 0, covered = 0;
    for (int y = 0; y < W; y++)
        for (int x = 0; x < W; x++) {
            int c = counts[y * W + x];
            covered += c > 0;
            if (c > 1) doubles++;
            if (c == 0 && inside_convex(poly, n, x, y, 1e-3)) cracks++;
            if (c > 0 && outside_convex(poly, n, x, y, 1e-3)) strays++;
        }
    printf("%-28s covered=%d doubles=%d cracks=%d strays=%d\n", name, covered, doubles, cracks, strays);
    CHECK(covered > 0);
    CHECK(doubles == 0);
    CHECK(cracks == 0);
    CHECK(strays == 0);
}

static void test_shared_edges(mx_pool *pool) {
    /* quads split along a diagonal; the second has corners exactly on pixel centres and
     * edges through pixel centres (where the tie-breaking rule matters) */
    const double quad1[4][2] = {{10.3, 7.7}, {50.1, 12.2}, {44.6, 55.9}, {6.2, 40.4}};
    const double quad2[4][2] = {{8.5, 8.5}, {40.5, 8.5}, {40.5, 40.5}, {8.5, 40.5}};
    const double c1[2] = {10.3, 7.7}, c2[2] = {8.5, 8.5};
    /* a fan whose "centre" is a polygon corner = two triangles sharing one edge */
    check_fan("two triangles (generic)", quad1, 4, c1, pool);
    check_fan("two triangles (on centres)", quad2, 4, c2, pool);
    const double hexa[6][2] = {{32, 6.25}, {54.5, 19}, {54.5, 45}, {32, 57.75}, {9.5, 45}, {9.5, 19}};
    const double hc[2] = {32.5, 32.5};
    check_fan("fan around a vertex", hexa, 6, hc, pool);
    const double hc2[2] = {31.37, 29.81};
    check_fan("fan, off-centre vertex", hexa, 6, hc2, pool);
}

static void test_grid_mesh(mx_pool *pool) {
    /* a jittered 8x8 grid of quads, both diagonals' orientations: watertight coverage */
    enum { G = 8 };
    float pos[3 * (G + 1) * (G + 1)];
    int32_t faces[3 * 2 * G * G];
    uint64_t seed = 7;
    float jitter[2 * (G + 1) * (G + 1)];
    mx_fill_random(jitter, 2 * (G + 1) * (G + 1), seed, -1.5f, 1.5f);
    for (int j = 0; j <= G; j++)
        for (int i = 0; i <= G; i++) {
            int inner = i > 0 && j > 0 && i < G && j < G;
            float px = 4.0f + 7.0f * i + (inner ? jitter[2 * (j * (G + 1) + i)] : 0);
            float py = 4.0f + 7.0f * j + (inner ? jitter[2 * (j * (G + 1) + i) + 1] : 0);
            pixel_to_world(px, py, pos + 3 * (j * (G + 1) + i));
        }
    int nf = 0;
    for (int j = 0; j < G; j++)
        for (int i = 0; i < G; i++) {
            int a = j * (G + 1) + i, b = a + 1, c = a + G + 1, d = c + 1;
            /* screen corners a (top-left), b, d, c: world counter-clockwise is a, c, d / a, d, b */
            if ((i + j) % 2) {
                int32_t t[6] = {a, c, d, a, d, b};
                memcpy(faces + 3 * nf, t, sizeof t);
            } else {
                int32_t t[6] = {a, c, b, b, c, d};
                memcpy(faces + 3 * nf, t, sizeof t);
            }
            nf += 2;
        }
    mx_mesh m = {0};
    m.nverts = (G + 1) * (G + 1);
    m.nfaces = nf;
    m.pos = pos;
    m.faces = faces;
    int counts[W * W];
    coverage_counts(&m, pool, counts);
    const double border[4][2] = {{4, 4}, {4 + 7 * G, 4}, {4 + 7 * G, 4 + 7 * G}, {4, 4 + 7 * G}};
    int doubles = 0, cracks = 0;
    for (int y = 0; y < W; y++)
        for (int x = 0; x < W; x++) {
            if (counts[y * W + x] > 1) doubles++;
            if (counts[y * W + x] == 0 && inside_convex(border, 4, x, y, 1e-3)) cracks++;
        }
    printf("%-28s doubles=%d cracks=%d\n", "jittered grid (128 faces)", doubles, cracks);
    CHECK(doubles == 0);
    CHECK(cracks == 0);
}

static void test_small_and_degenerate(mx_pool *pool) {
    mx_status st;
    mx_gbuffer gb;
    mx_camera cam = front_camera();
    CHECK(mx_gbuffer_init(&gb, W, W, &st) == 0);
    float pos[3 * 9];
    /* 0-2: sub-pixel triangle around the centre of pixel (20, 20); 3-5: sub-pixel between
     * centres; 6-8: collinear (degenerate) */
    const float px[9][2] = {{20.3f, 20.3f}, {20.6f, 20.8f}, {20.8f, 20.4f},
                            {30.6f, 30.6f}, {30.9f, 30.95f}, {30.95f, 30.7f},
                            {5.5f, 5.5f},   {25.5f, 25.5f},  {45.5f, 45.5f}};
    for (int k = 0; k < 9; k++) pixel_to_world(px[k][0], px[k][1], pos + 3 * k);
    int32_t faces[9] = {0, 1, 2, 3, 4, 5, 6, 7, 8};
    mx_mesh m = {0};
    m.nverts = 9;
    m.nfaces = 3;
    m.pos = pos;
    m.faces = faces;
    /* either winding: no culling */
    CHECK(mx_rasterize(&m, NULL, &cam, 0, pool, &gb, &st) == 0);
    int count[3] = {0, 0, 0};
    for (int i = 0; i < W * W; i++)
        if (gb.face[i] >= 0) count[gb.face[i]]++;
    printf("%-28s sub-pixel on centre=%d, between centres=%d, degenerate=%d\n", "small faces",
           count[0], count[1], count[2]);
    CHECK(count[0] == 1 && gb.face[20 * W + 20] == 0);
    CHECK(count[1] == 0);
    CHECK(count[2] == 0);
    mx_gbuffer_free(&gb);
}

static void test_culling_and_uv(mx_pool *pool) {
    mx_status st;
    mx_gbuffer gb;
    CHECK(mx_gbuffer_init(&gb, W, W, &st) == 0);
    /* counter-clockwise in the z = 0.25 plane, facing +z (the front) */
    float pos[9] = {-0.8f, -0.8f, 0.25f, 0.8f, -0.8f, 0.25f, -0.8f, 0.8f, 0.25f};
    int32_t faces[3] = {0, 1, 2};
    float uv[6] = {0, 0, 1, 0, 0, 1};
    int32_t face_uv[3] = {0, 1, 2};
    mx_mesh m = {0};
    m.nverts = 3;
    m.nfaces = 1;
    m.pos = pos;
    m.faces = faces;
    m.nuv = 3;
    m.uv = uv;
    m.face_uv = face_uv;
    mx_camera front = front_camera(), back;
    mx_camera_ortho(&back, 180, 0, 3, 1);
    CHECK(mx_rasterize(&m, NULL, &front, MX_RASTER_CULL_BACK | MX_RASTER_UV, pool, &gb, &st) == 0);
    int i = 40 * W + 16; /* world (-0.5, -0.25) */
    CHECK(gb.face[i] == 0);
    CHECK(fabsf(gb.depth[i] - 2.75f) < 1e-4f);
    float want_u = (-0.5f + 0.8f + 0.5f / 32) / 1.6f, want_v = (-0.25f + 0.8f - 0.5f / 32) / 1.6f;
    CHECK(gb.uv && fabsf(gb.uv[2 * i] - want_u) < 1e-4f && fabsf(gb.uv[2 * i + 1] - want_v) < 1e-4f);
    float n[3];
    mx_gbuffer_normal(&gb, i, n);
    CHECK(fabsf(n[2] - 1.0f) < 1e-5f);
    CHECK(mx_rasterize(&m, NULL, &back, MX_RASTER_CULL_BACK, pool, &gb, &st) == 0);
    int seen = 0;
    for (int k = 0; k < W * W; k++) seen += gb.face[k] >= 0;
    CHECK(seen == 0);
    CHECK(mx_rasterize(&m, NULL, &back, 0, pool, &gb, &st) == 0);
    seen = 0;
    for (int k = 0; k < W * W; k++) seen += gb.face[k] >= 0;
    CHECK(seen > 0);
    /* a bad vertex index is an error, not a crash */
    int32_t bad[3] = {0, 1, 7};
    m.faces = bad;
    CHECK(mx_rasterize(&m, NULL, &front, 0, pool, &gb, &st) == -1);
    mx_gbuffer_free(&gb);
}

/* Random triangle soup in the unit cube, perspective, 300x200: identical for 1 and 3 threads. */
static void test_thread_invariance(void) {
    enum { NF = 3000 };
    float *pos = malloc(sizeof(float) * 9 * NF);
    int32_t *faces = malloc(sizeof(int32_t) * 3 * NF);
    mx_fill_random(pos, 9 * NF, 11, -0.7f, 0.7f);
    for (int k = 0; k < NF; k++) {
        /* small triangles: corners near the first */
        for (int c = 1; c < 3; c++)
            for (int d = 0; d < 3; d++)
                pos[9 * k + 3 * c + d] = pos[9 * k + d] + 0.15f * pos[9 * k + 3 * c + d];
        for (int c = 0; c < 3; c++) faces[3 * k + c] = 3 * k + c;
    }
    mx_mesh m = {0};
    m.nverts = 3 * NF;
    m.nfaces = NF;
    m.pos = pos;
    m.faces = faces;
    mx_status st;
    mx_camera cam;
    mx_camera_persp(&cam, 30, 20, 3, 40);
    mx_pool *p1 = mx_pool_create(1, &st), *p3 = mx_pool_create(3, &st);
    mx_gbuffer a, b;
    CHECK(mx_gbuffer_init(&a, 300, 200, &st) == 0 && mx_gbuffer_init(&b, 300, 200, &st) == 0);
    CHECK(mx_rasterize(&m, NULL, &cam, 0, p1, &a, &st) == 0);
    CHECK(mx_rasterize(&m, NULL, &cam, 0, p3, &b, &st) == 0);
    size_t n = 300 * 200;
    int same = !memcmp(a.face, b.face, n * 4) && !memcmp(a.depth, b.depth, n * 4) &&
               !memcmp(a.bary, b.bary, n * 8);
    int visible = 0;
    for (size_t i = 0; i < n; i++) visible += a.face[i] >= 0;
    printf("%-28s visible=%d identical=%d\n", "1 vs 3 threads", visible, same);
    CHECK(visible > 1000);
    CHECK(same);
    /* the depth test keeps the nearest face: compare with a brute-force check at a few pixels */
    mx_gbuffer_free(&a);
    mx_gbuffer_free(&b);
    mx_pool_destroy(p1);
    mx_pool_destroy(p3);
    free(pos);
    free(faces);
}

int main(void) {
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    test_shared_edges(pool);
    test_grid_mesh(pool);
    test_small_and_degenerate(pool);
    test_culling_and_uv(pool);
    test_thread_invariance();
    mx_pool_destroy(pool);
    return mx_test_finish("test_geom_raster");
}
