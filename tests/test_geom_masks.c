/* Masks: internal faces flagged on an open garment and never on a closed sphere; the
 * frontal mask's area on a sphere matches the analytic fraction, for geometric and
 * depth-derived normals; crop box around the foreground. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/views.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/log.h"
#include "util_test.h"

#define S 256

/* Closed UV sphere of radius r, counter-clockwise seen from outside. */
static void make_sphere(mx_mesh *m, int stacks, int slices, float r) {
    memset(m, 0, sizeof *m);
    m->nverts = (stacks + 1) * (slices + 1);
    m->pos = malloc(sizeof(float) * 3 * m->nverts);
    m->uv = malloc(sizeof(float) * 2 * m->nverts);
    m->nuv = m->nverts;
    for (int i = 0; i <= stacks; i++)
        for (int j = 0; j <= slices; j++) {
            float th = 3.14159265f * i / stacks, ph = 6.2831853f * j / slices;
            float *p = m->pos + 3 * (i * (slices + 1) + j);
            p[0] = r * sinf(th) * cosf(ph);
            p[1] = r * cosf(th);
            p[2] = r * sinf(th) * sinf(ph);
            m->uv[2 * (i * (slices + 1) + j)] = (float)j / slices;
            m->uv[2 * (i * (slices + 1) + j) + 1] = 1.0f - (float)i / stacks;
        }
    m->faces = malloc(sizeof(int32_t) * 6 * stacks * slices);
    for (int i = 0; i < stacks; i++)
        for (int j = 0; j < slices; j++) {
            int a = i * (slices + 1) + j, b = a + 1, c = a + slices + 1, d = c + 1;
            int32_t t[6] = {a, b, d, a, d, c};
            /* keep the triangles whose corners are distinct (pole caps) */
            for (int k = 0; k < 6; k += 3) {
                float *p0 = m->pos + 3 * t[k], *p1 = m->pos + 3 * t[k + 1], *p2 = m->pos + 3 * t[k + 2];
                float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
                float e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
                float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                              e1[0] * e2[1] - e1[1] * e2[0]};
                float dot = n[0] * p0[0] + n[1] * p0[1] + n[2] * p0[2];
                if (fabsf(dot) < 1e-9f) continue;
                int32_t *f = m->faces + 3 * m->nfaces++;
                f[0] = t[k];
                f[1] = dot > 0 ? t[k + 1] : t[k + 2];
                f[2] = dot > 0 ? t[k + 2] : t[k + 1];
            }
        }
    m->face_uv = m->faces;
}

static void free_sphere(mx_mesh *m) {
    free(m->pos);
    free(m->uv);
    free(m->faces);
}

static void test_sphere(mx_pool *pool) {
    mx_mesh m;
    make_sphere(&m, 64, 128, 1.0f);
    mx_status st;
    mx_view_buffers vb;
    CHECK(mx_view_buffers_init(&vb, S, &st) == 0);
    mx_camera cams[6];
    mx_camera base;
    mx_camera_ortho(&base, 0, 0, 3, 1.1f);
    mx_camera_fibonacci(cams, 6, &base);
    int64_t internal = 0;
    for (int c = 0; c < 6; c++) {
        CHECK(mx_view_prepare(&vb, &m, NULL, &cams[c], MX_NORMAL_GEOMETRIC, 0, pool, &st) == 0);
        mx_mask_internal(vb.gb.depth, vb.gb.depth_unculled, S * S, vb.tmp);
        internal += mx_mask_count(vb.tmp, S * S);
    }
    printf("closed sphere: internal pixels over 6 views = %lld\n", (long long)internal);
    CHECK(internal == 0);
    /* frontal mask: |n.v| >= 0.5 on a unit sphere (ortho) is the disc r <= sqrt(0.75) */
    uint8_t fg[S * S], fr[S * S];
    mx_mask_foreground(&vb.gb, fg);
    int64_t nfg = mx_mask_count(fg, S * S);
    for (int src = 0; src < 2; src++) {
        mx_mask_frontal(&vb.gb, src, 0.5f, fr);
        double frac = (double)mx_mask_count(fr, S * S) / (double)nfg;
        printf("frontal fraction (%s normals) = %.4f (want 0.75)\n", src ? "depth" : "geometric", frac);
        CHECK(fabs(frac - 0.75) < 0.03);
    }
    mx_crop crop = mx_crop_from_mask(fg, S, S, 0.0f);
    /* the unit sphere covers 1/1.1 of the half-extent: ~233 pixels wide, centred */
    printf("crop: x0=%d y0=%d size=%d\n", crop.x0, crop.y0, crop.size);
    CHECK(abs(crop.size - 233) <= 2 && abs(crop.x0 + crop.size / 2 - S / 2) <= 2);
    mx_view_buffers_free(&vb);
    free_sphere(&m);
}

static void test_garment(mx_pool *pool) {
    char path[2048];
    if (!mx_test_need(path, sizeof path, "assets/garment_female_casual/female_casualsuit01.obj")) return;
    mx_mesh m = {0};
    mx_status st;
    float *pos = NULL;
    int ok = mx_mesh_load(path, &m, &st) == 0 && mx_mesh_normalized(&m, MX_UP_Y, &pos, NULL, NULL, &st) == 0;
    if (!ok) printf("garment: %s\n", st.msg);
    CHECK(ok);
    if (!ok) return;
    mx_view_buffers vb;
    CHECK(mx_view_buffers_init(&vb, S, &st) == 0);
    mx_camera cam;
    /* from above, looking into the neck and sleeve openings */
    mx_camera_ortho(&cam, 20, 60, 3, 1.05f);
    CHECK(mx_view_prepare(&vb, &m, pos, &cam, MX_NORMAL_GEOMETRIC, 0, pool, &st) == 0);
    mx_mask_internal(vb.gb.depth, vb.gb.depth_unculled, S * S, vb.tmp);
    int64_t internal = mx_mask_count(vb.tmp, S * S);
    int64_t masked_out = 0;
    for (int i = 0; i < S * S; i++) masked_out += vb.tmp[i] && vb.mask[i];
    printf("garment: internal pixels = %lld, internal pixels left in the backprojection mask = %lld\n",
           (long long)internal, (long long)masked_out);
    CHECK(internal > 50);
    CHECK(masked_out == 0);
    mx_view_buffers_free(&vb);
    free(pos);
    mx_mesh_free(&m);
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    mx_status st;
    mx_pool *pool = mx_pool_create(2, &st);
    test_sphere(pool);
    test_garment(pool);
    mx_pool_destroy(pool);
    return mx_test_finish("test_geom_masks");
}
