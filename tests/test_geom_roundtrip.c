/* Round trip on every UV-carrying test asset: a smooth, colourful procedural texture
 * (periodic in UV, so repeat-wrapped UVs stay consistent) is rendered from the views that
 * view selection picks, at 1024^2, and backprojected onto the same UVs (1024^2 texture).
 * Bars: PSNR >= 30 dB over covered texels, and coverage >= 99% of the texels visible from
 * some candidate view. "Visible from some candidate": the texel under some usable pixel
 * (foreground, not internal, frontal) of one of the 2 + 16 candidates rendered at 1024^2
 * (16 candidates instead of 40 keep the test fast; the same cache drives view selection).
 * Views: front and back, then Alg. 1 until 99.5% simulated coverage (at most all 16 candidates). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/views.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/log.h"
#include "util_test.h"

#define TEX 1024
#define VIEW 1024
#define CACHE 1024
#define NCAND 16

static void procedural(float u, float v, int layer, float out[3]) {
    const float tau = 6.28318530718f;
    out[0] = 0.5f + 0.4f * sinf(tau * (3 * u + 1 * v) + 0.3f * layer);
    out[1] = 0.5f + 0.4f * sinf(tau * (1 * u - 2 * v) + 2.1f + 0.7f * layer);
    out[2] = 0.5f + 0.4f * cosf(tau * (2 * u + 3 * v) + 4.2f + 1.1f * layer);
}

static int make_textures(mx_image *tex, int nlayers, mx_status *st) {
    for (int l = 0; l < nlayers; l++) {
        if (mx_image_alloc(&tex[l], TEX, TEX, 3, st)) return -1;
        for (int y = 0; y < TEX; y++)
            for (int x = 0; x < TEX; x++)
                procedural((x + 0.5f) / TEX, 1.0f - (y + 0.5f) / TEX, l,
                           tex[l].data + 3 * ((size_t)y * TEX + x));
    }
    return 0;
}

static int bake_view(mx_bake *bake, mx_view_buffers *vb, const mx_mesh *m, const float *pos,
                     const mx_camera *cam, const mx_image *tex, int nlayers, mx_pool *pool,
                     mx_status *st) {
    const float bg[3] = {1, 1, 1};
    mx_image img = {0};
    int rc = mx_view_prepare(vb, m, pos, cam, MX_NORMAL_GEOMETRIC, 0.1f, pool, st);
    rc = rc || mx_render_textured(&vb->gb, m, tex, nlayers, bg, pool, &img, st);
    rc = rc || mx_backproject(bake, &vb->gb, m, &img, vb->mask, 0, pool, st);
    mx_image_free(&img);
    return rc;
}

typedef struct result {
    double psnr, coverage, planned_coverage;
    int views;
} result;

static void measure(const mx_bake *bake, const mx_view_cache *vc, const mx_image *tex, result *r) {
    size_t plane = (size_t)TEX * TEX, n = plane * bake->nlayers;
    uint8_t *visible = malloc(n);
    mx_view_cache_visible(vc, visible);
    size_t vis = 0, hit = 0, covered = 0;
    double se = 0;
    for (size_t t = 0; t < n; t++) {
        vis += visible[t];
        hit += visible[t] && bake->known[t];
        if (!bake->known[t]) continue;
        covered++;
        const float *want = tex[t / plane].data + 3 * (t % plane);
        for (int c = 0; c < 3; c++) {
            double d = bake->sum_wc[3 * t + c] / bake->sum_w[t] - want[c];
            se += d * d;
        }
    }
    r->coverage = vis ? (double)hit / (double)vis : 0;
    r->psnr = covered ? 10 * log10(1.0 / (se / (3.0 * covered) + 1e-20)) : 0;
    free(visible);
}

static int roundtrip(const char *path, mx_pool *pool, result *r, mx_status *st) {
    mx_mesh m = {0};
    if (mx_mesh_load(path, &m, st)) return -1;
    float *pos = NULL;
    int nlayers = m.nmat > 1 ? m.nmat : 1;
    mx_image tex[64] = {{0}};
    mx_camera cands[2 + NCAND];
    mx_camera_ortho(&cands[0], 0, 0, 3, 1.05f);
    mx_camera_ortho(&cands[1], 180, 0, 3, 1.05f);
    mx_camera_fibonacci(cands + 2, NCAND, &cands[0]);
    mx_view_cache vc = {0};
    mx_view_buffers vb = {0};
    mx_bake bake = {0};
    mx_view_plan plan = {0};
    int rc = nlayers > 64 || mx_mesh_normalized(&m, MX_UP_Y, &pos, NULL, NULL, st) ||
             make_textures(tex, nlayers, st) ||
             mx_view_cache_build(&vc, &m, pos, cands, 2 + NCAND, CACHE, TEX, TEX, nlayers, MX_NORMAL_GEOMETRIC, 0.1f, 0, pool, st) ||
             mx_view_buffers_init(&vb, VIEW, st) || mx_bake_init(&bake, TEX, TEX, nlayers, st);
    for (int k = 0; !rc && k < 2; k++) rc = bake_view(&bake, &vb, &m, pos, &cands[k], tex, nlayers, pool, st);
    rc = rc || mx_view_plan_make(&vc, bake.known, NCAND, 0.995, 16, &plan, st);
    for (int k = 0; !rc && k < plan.n; k++)
        rc = bake_view(&bake, &vb, &m, pos, &cands[plan.cand[k]], tex, nlayers, pool, st);
    if (!rc) {
        measure(&bake, &vc, tex, r);
        r->views = 2 + plan.n;
        r->planned_coverage = plan.coverage;
    }
    mx_view_plan_free(&plan);
    mx_bake_free(&bake);
    mx_view_buffers_free(&vb);
    mx_view_cache_free(&vc);
    for (int l = 0; l < nlayers && l < 64; l++) mx_image_free(&tex[l]);
    free(pos);
    mx_mesh_free(&m);
    return rc;
}

int main(void) {
    static const char *assets[] = {
        "spot/spot_triangulated.obj",
        "bob/bob_tri.obj",
        "blub/blub_triangulated.obj",
        "garment_female_casual/female_casualsuit01.obj",
        "garment_female_elegant/female_elegantsuit01.obj",
        "shoes_pair/shoes03.obj",
        "fedora_hat/fedora.obj",
        "wooden_stool/painted_wooden_stool_1k.gltf",
        "flight_helmet/FlightHelmet.gltf",
        "cesium_milk_truck/CesiumMilkTruck.glb",
    };
    mx_log_set_level(MX_LOG_ERROR);
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    for (size_t a = 0; a < sizeof assets / sizeof *assets; a++) {
        result r = {0};
        char path[2048];
        if (!mx_test_need(path, sizeof path, "assets/%s", assets[a])) continue;
        double t0 = mx_now();
        int rc = roundtrip(path, pool, &r, &st);
        if (rc) printf("%-50s error: %s\n", assets[a], st.msg);
        else
            printf("%-48s views=%2d PSNR=%.2f dB coverage=%.2f%% (simulated %.2f%%) %.2fs\n", assets[a],
                   r.views, r.psnr, 100 * r.coverage, 100 * r.planned_coverage, mx_now() - t0);
        CHECK(rc == 0);
        CHECK(r.psnr >= 30);
        CHECK(r.coverage >= 0.99);
    }
    mx_pool_destroy(pool);
    return mx_test_finish("test_geom_roundtrip");
}
