/* UV fill quality (issue 13): on every shared asset (an atlas first when it has no UVs), a
 * texture whose colour is a smooth function of the 3D surface point (so it is continuous
 * across UV seams, as a round-trip texture of a real object is) loses 20 % of its chart texels
 * in random discs of 3..12 texels radius; push-pull (mx_uv_fill) and the harmonic fill across
 * seams (mx_uv_fill_harmonic) fill them, and the PSNR of the filled texels against the truth is
 * printed per asset. Bars: the harmonic fill is never more than 0.5 dB below push-pull, and
 * better on average. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/uvatlas.h"
#include "../pipeline/geom/uvfill.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/log.h"
#include "util_test.h"

#define TEX 512
#define HIDE 0.20

static void colour_at(const float p[3], float out[3]) {
    const float tau = 6.28318530718f;
    out[0] = 0.5f + 0.4f * sinf(tau * (1.3f * p[0] + 0.7f * p[1]) + 0.4f);
    out[1] = 0.5f + 0.4f * sinf(tau * (0.9f * p[1] - 1.1f * p[2]) + 2.0f);
    out[2] = 0.5f + 0.4f * cosf(tau * (1.2f * p[2] + 0.8f * p[0]) + 1.0f);
}

/* The truth: for each chart texel, the colour of the surface point of its face under the
 * texel centre (barycentrics in UV, clamped to the triangle). */
static void truth_texture(const mx_mesh *m, const float *pos, const int32_t *face, mx_image *tex) {
    for (int y = 0; y < TEX; y++)
        for (int x = 0; x < TEX; x++) {
            size_t t = (size_t)y * TEX + x;
            float *o = tex->data + 3 * t;
            o[0] = o[1] = o[2] = 0.5f;
            int f = face[t];
            if (f < 0) continue;
            float u = (x + 0.5f) / TEX, v = 1.0f - (y + 0.5f) / TEX, q[3][2];
            for (int k = 0; k < 3; k++) memcpy(q[k], m->uv + 2 * (size_t)m->face_uv[3 * (size_t)f + k], sizeof q[k]);
            float d = (q[1][1] - q[2][1]) * (q[0][0] - q[2][0]) + (q[2][0] - q[1][0]) * (q[0][1] - q[2][1]);
            float b0 = d != 0 ? ((q[1][1] - q[2][1]) * (u - q[2][0]) + (q[2][0] - q[1][0]) * (v - q[2][1])) / d : 1.0f / 3;
            float b1 = d != 0 ? ((q[2][1] - q[0][1]) * (u - q[2][0]) + (q[0][0] - q[2][0]) * (v - q[2][1])) / d : 1.0f / 3;
            float b[3] = {fmaxf(b0, 0), fmaxf(b1, 0), fmaxf(1 - b0 - b1, 0)}, s = b[0] + b[1] + b[2], p[3] = {0, 0, 0};
            for (int k = 0; k < 3; k++)
                for (int c = 0; c < 3; c++) p[c] += b[k] / s * pos[3 * (size_t)m->faces[3 * (size_t)f + k] + c];
            colour_at(p, o);
        }
}

/* known = chart minus random discs, until HIDE of the chart texels are hidden. */
static void hide_blobs(const uint8_t *chart, uint8_t *known, uint64_t seed) {
    size_t n = (size_t)TEX * TEX, nchart = 0, hidden = 0;
    for (size_t t = 0; t < n; t++) nchart += known[t] = chart[t];
    uint64_t s = seed;
    while (hidden < HIDE * (double)nchart) {
        s = s * 6364136223846793005ULL + 1442695040888963407ULL;
        size_t c = (size_t)(s >> 33) % n;
        if (!chart[c]) continue;
        int r = 3 + (int)((s >> 20) % 10), cx = (int)(c % TEX), cy = (int)(c / TEX);
        for (int y = cy - r; y <= cy + r; y++)
            for (int x = cx - r; x <= cx + r; x++) {
                if (x < 0 || y < 0 || x >= TEX || y >= TEX || (x - cx) * (x - cx) + (y - cy) * (y - cy) > r * r) continue;
                size_t t = (size_t)y * TEX + x;
                hidden += known[t];
                known[t] = 0;
            }
    }
}

static double psnr_hidden(const mx_image *got, const mx_image *want, const uint8_t *chart, const uint8_t *known) {
    double se = 0;
    size_t k = 0;
    for (size_t t = 0; t < (size_t)TEX * TEX; t++) {
        if (!chart[t] || known[t]) continue;
        for (int c = 0; c < 3; c++) {
            double d = (double)got->data[3 * t + c] - want->data[3 * t + c];
            se += d * d;
        }
        k += 3;
    }
    return k ? 10 * log10(1.0 / (se / (double)k + 1e-20)) : 0;
}

typedef struct fill_result {
    double pushpull, harmonic;
} fill_result;

static int measure(const char *rel, fill_result *r, mx_status *st) {
    char path[2048];
    mx_test_path(path, sizeof path, rel);
    mx_mesh m = {0};
    float *pos = NULL;
    size_t n = (size_t)TEX * TEX;
    uint8_t *chart = malloc(n), *known = malloc(n);
    int32_t *face = malloc(n * sizeof *face);
    mx_image truth = {0}, a = {0}, b = {0};
    int rc = !chart || !known || !face ? mx_fail(st, MX_ENOMEM, "out of memory") : mx_mesh_load(path, &m, st);
    if (!rc && !m.face_uv) {
        mx_uvatlas_opts o = mx_uvatlas_defaults();
        mx_uvatlas_report ar;
        o.texture_size = TEX;
        rc = mx_uvatlas_build(&m, &o, &ar, st);
        free(m.face_mat);
        m.face_mat = NULL;
    }
    int nlayers = m.nmat > 1 && m.face_mat ? m.nmat : 1;
    double sa = 0, sb = 0;
    rc = rc || mx_mesh_normalized(&m, MX_UP_Y, &pos, NULL, NULL, st) || mx_image_alloc(&truth, TEX, TEX, 3, st) ||
         mx_image_alloc(&a, TEX, TEX, 3, st) || mx_image_alloc(&b, TEX, TEX, 3, st);
    for (int l = 0; !rc && l < nlayers; l++) {
        if ((rc = mx_uv_chart_faces(&m, l, nlayers, TEX, TEX, chart, face, st))) break;
        truth_texture(&m, pos, face, &truth);
        hide_blobs(chart, known, 1234 + (uint64_t)l);
        for (size_t t = 0; t < 3 * n; t++) a.data[t] = b.data[t] = known[t / 3] ? truth.data[t] : 0.5f;
        rc = mx_uv_fill(&a, known, chart, 0, st) || mx_uv_fill_harmonic(&b, known, &m, l, nlayers, 0, NULL, st);
        sa += psnr_hidden(&a, &truth, chart, known);
        sb += psnr_hidden(&b, &truth, chart, known);
    }
    r->pushpull = sa / nlayers;
    r->harmonic = sb / nlayers;
    mx_image_free(&truth), mx_image_free(&a), mx_image_free(&b);
    free(chart), free(known), free(face), free(pos);
    mx_mesh_free(&m);
    return rc;
}

typedef struct {
    int n, stop_at, ordered;
    double last;
} tick_log;

static int log_tick(void *user, double done) {
    tick_log *t = user;
    t->ordered = t->ordered && done >= t->last;
    t->last = done;
    t->n++;
    return t->stop_at && t->n >= t->stop_at;
}

/* The fill reports its progress (issue 24 item 13: an 8192² fill ran minutes with no line) and stops
 * when the ticker says so. */
static void test_ticks(void) {
    float pos[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, uv[8] = {0, 0, 1, 0, 1, 1, 0, 1};
    int32_t faces[6] = {0, 1, 2, 0, 2, 3};
    mx_mesh m = {.nverts = 4, .nfaces = 2, .pos = pos, .faces = faces, .nuv = 4, .uv = uv, .face_uv = faces};
    enum { S = 32 };
    uint8_t known[S * S];
    mx_image tex = {0};
    mx_status st;
    CHECK(mx_image_alloc(&tex, S, S, 3, &st) == 0);
    for (int i = 0; i < S * S; i++) known[i] = i % S < S / 2;
    tick_log t = {.ordered = 1};
    mx_uv_fill_ticker ticker = {.tick = log_tick, .user = &t};
    CHECK(mx_uv_fill_harmonic(&tex, known, &m, 0, 1, 0, &ticker, &st) == 0);
    CHECK(t.n == MX_UV_HARMONIC_ITERS / MX_UV_TICK_SWEEPS + 1 && t.ordered && t.last == 1.0);
    tick_log stop = {.ordered = 1, .stop_at = 3};
    ticker.user = &stop;
    CHECK(mx_uv_fill_harmonic(&tex, known, &m, 0, 1, 0, &ticker, &st) == -1 && st.code == MX_ECANCEL && stop.n == 3);
    mx_image_free(&tex);
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    test_ticks();
    double ta = 0, tb = 0;
    int measured = 0;
    printf("%-48s %10s %10s\n", "asset (20% of chart texels hidden in discs)", "push-pull", "harmonic");
    for (size_t k = 0; k < MX_TEST_NASSETS; k++) {
        char rel[256], path[2048];
        snprintf(rel, sizeof rel, "assets/%s", mx_test_assets[k]);
        if (!mx_test_need(path, sizeof path, "%s", rel)) continue;
        fill_result r;
        mx_status st;
        int ok = measure(rel, &r, &st) == 0;
        if (!ok) fprintf(stderr, "%s: %s\n", mx_test_assets[k], st.msg);
        CHECK(ok);
        if (!ok) continue;
        printf("%-48s %7.2f dB %7.2f dB\n", mx_test_assets[k], r.pushpull, r.harmonic);
        CHECK(r.harmonic >= r.pushpull - 0.5);
        ta += r.pushpull;
        tb += r.harmonic;
        measured++;
    }
    if (measured) printf("%-48s %7.2f dB %7.2f dB\n", "mean", ta / measured, tb / measured);
    CHECK(measured == 0 || tb > ta);
    return mx_test_finish("test_geom_uvfill");
}
