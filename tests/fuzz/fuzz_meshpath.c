/* The whole mesh path of `matex texture` on generated meshes: validate, normalise, UV atlas
 * (when the mesh has no UVs), candidate view cache and plan, rasterize + masks of a view,
 * backprojection (splat), bake, chart mask and UV fill. The input bytes drive a generator
 * (mesh_gen below) so that every execution is a mesh of one of the shapes that break
 * geometry code: random soup, flat, degenerate, huge/tiny coordinates, non-manifold fans,
 * thousands of components. */
#include <math.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

#include "../../pipeline/geom/backproject.h"
#include "../../pipeline/geom/camera.h"
#include "../../pipeline/geom/masks.h"
#include "../../pipeline/geom/uvatlas.h"
#include "../../pipeline/geom/uvfill.h"
#include "../../pipeline/geom/views.h"
#include "fuzz.h"

enum { TEX = 64, VIEW = 32, NCAND = 6 };
enum { GEN_RANDOM, GEN_FLAT, GEN_DEGENERATE, GEN_SCALE, GEN_NONMANIFOLD, GEN_COMPONENTS, GEN_KINDS };

typedef struct reader {
    const uint8_t *p;
    size_t n, i;
} reader;

/* The next input byte; 0 once the input is used up, so every input makes a mesh. */
static unsigned next(reader *r) { return r->i < r->n ? r->p[r->i++] : 0; }
static float coord(reader *r) { return (float)(int16_t)(next(r) | next(r) << 8) / 4096.0f; }

static int mesh_alloc(mx_mesh *m, int nverts, int nfaces) {
    memset(m, 0, sizeof *m);
    m->nverts = nverts;
    m->nfaces = nfaces;
    m->pos = calloc((size_t)nverts * 3, sizeof(float));
    m->faces = calloc((size_t)nfaces * 3, sizeof(int32_t));
    snprintf(m->source_path, sizeof m->source_path, "generated");
    return m->pos && m->faces ? 0 : -1;
}

/* Positions of kind `kind`, scaled by 2^exponent. */
static void gen_positions(mx_mesh *m, int kind, reader *r) {
    float s = ldexpf(1.0f, kind == GEN_SCALE ? (int)(next(r) % 250) - 125 : 0);
    for (int v = 0; v < m->nverts; v++) {
        float *p = m->pos + 3 * v;
        if (kind == GEN_COMPONENTS) { /* a small triangle per component, on a grid */
            int c = v / 3, k = v % 3;
            p[0] = (float)(c % 64) + (k == 1) * 0.5f;
            p[1] = (float)(c / 64) + (k == 2) * 0.5f;
            p[2] = coord(r) * 0.01f;
            continue;
        }
        p[0] = coord(r) * s;
        p[1] = coord(r) * s;
        p[2] = kind == GEN_FLAT ? 0.0f : coord(r) * s;
        if (kind == GEN_DEGENERATE && v % 2) memcpy(p, p - 3, 3 * sizeof(float)); /* coincident pairs */
    }
}

static void gen_faces(mx_mesh *m, int kind, reader *r) {
    for (int f = 0; f < m->nfaces; f++) {
        int32_t *t = m->faces + 3 * f;
        if (kind == GEN_COMPONENTS) {
            for (int k = 0; k < 3; k++) t[k] = 3 * f + k;
        } else if (kind == GEN_NONMANIFOLD) { /* every face shares the edge 0-1 */
            t[0] = 0;
            t[1] = 1;
            t[2] = 2 + (int)(next(r) % (unsigned)(m->nverts - 2));
            if (f % 2) t[0] = 1, t[1] = 0;
        } else {
            for (int k = 0; k < 3; k++) t[k] = (int)(next(r) % (unsigned)m->nverts);
        }
    }
}

/* Optional per-corner UVs (any values, NaN-free) and materials. */
static int gen_attributes(mx_mesh *m, unsigned flags, reader *r) {
    if (flags & 1) {
        m->nuv = m->nverts;
        m->uv = malloc(sizeof(float) * 2 * (size_t)m->nuv);
        m->face_uv = malloc(sizeof(int32_t) * 3 * (size_t)m->nfaces);
        if (!m->uv || !m->face_uv) return -1;
        for (int i = 0; i < 2 * m->nuv; i++) m->uv[i] = coord(r);
        memcpy(m->face_uv, m->faces, sizeof(int32_t) * 3 * (size_t)m->nfaces);
    }
    m->nmat = flags & 2 ? 3 : 1;
    m->mats = calloc((size_t)m->nmat, sizeof *m->mats);
    if (!m->mats) return -1;
    if (flags & 2) {
        if (!(m->face_mat = malloc(sizeof(int32_t) * (size_t)m->nfaces))) return -1;
        for (int f = 0; f < m->nfaces; f++) m->face_mat[f] = (int32_t)(next(r) % 3);
    }
    return 0;
}

static int mesh_gen(mx_mesh *m, reader *r) {
    int kind = (int)(next(r) % GEN_KINDS);
    unsigned flags = next(r);
    int nverts = 3 + (int)(next(r) % 96), nfaces = 1 + (int)(next(r) % 128);
    if (kind == GEN_COMPONENTS) { /* 1000..5080 separate triangles */
        nfaces = 1000 + 16 * (int)next(r);
        nverts = 3 * nfaces;
    }
    if (mesh_alloc(m, nverts, nfaces)) return -1;
    gen_positions(m, kind, r);
    gen_faces(m, kind, r);
    return gen_attributes(m, flags, r);
}

/* One view: rasterize + masks, splat a colour pattern, bake, fill. */
static void bake_view(const mx_mesh *m, const float *pos, const mx_camera *cam, int nlayers, unsigned flags) {
    mx_status st;
    mx_view_buffers vb;
    mx_bake bake;
    mx_image img = {0}, tex = {0};
    uint8_t *chart = malloc(TEX * TEX);
    int vb_ok = !mx_view_buffers_init(&vb, VIEW, &st), bake_ok = !mx_bake_init(&bake, TEX, TEX, nlayers, &st);
    if (chart && vb_ok && bake_ok && !mx_image_alloc(&img, VIEW, VIEW, 3, &st) &&
        !mx_view_prepare(&vb, m, pos, cam, (flags >> 2) & 1, (float)((flags >> 3) & 3) * 0.3f, NULL, &st)) {
        for (int i = 0; i < VIEW * VIEW * 3; i++) img.data[i] = (float)(i % 7) / 6.0f;
        const float fill[3] = {0.5f, 0.5f, 0.5f};
        if (!mx_backproject(&bake, &vb.gb, m, &img, vb.mask, (flags >> 5) & 1, NULL, &st) &&
            !mx_bake_texture(&bake, nlayers - 1, fill, NULL, &tex, &st) &&
            !mx_uv_chart_mask(m, nlayers - 1, nlayers, TEX, TEX, chart, &st))
            mx_uv_fill(&tex, bake.known + (size_t)(nlayers - 1) * TEX * TEX, chart, 2, &st);
    }
    mx_image_free(&tex);
    mx_image_free(&img);
    if (bake_ok) mx_bake_free(&bake);
    if (vb_ok) mx_view_buffers_free(&vb);
    free(chart);
}

static void plan_views(const mx_mesh *m, const float *pos, const mx_camera *cams, int nlayers) {
    mx_status st;
    mx_view_cache vc;
    if (mx_view_cache_build(&vc, m, pos, cams, NCAND, VIEW, TEX, TEX, nlayers, MX_NORMAL_FROM_DEPTH, 0.3f, 2, NULL,
                            &st))
        return;
    uint8_t *known = calloc((size_t)nlayers * TEX * TEX, 1);
    mx_view_plan plan;
    if (known && !mx_view_plan_make(&vc, known, 4, 0.99, 1, &plan, &st)) mx_view_plan_free(&plan);
    free(known);
    mx_view_cache_free(&vc);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    reader r = {data, size, 0};
    mx_status st;
    mx_mesh m;
    float *pos = NULL;
    unsigned flags = next(&r);
    if (mesh_gen(&m, &r) || mx_mesh_validate(&m, &st) || mx_mesh_normalized(&m, flags & 1, &pos, NULL, NULL, &st))
        goto done;
    mx_uvatlas_opts ao = mx_uvatlas_defaults();
    ao.texture_size = TEX;
    mx_uvatlas_report rep;
    if (m.nuv == 0) {
        if (mx_uvatlas_build(&m, &ao, &rep, &st)) goto done;
        free(m.face_mat); /* one atlas for the whole mesh, as the texture job does */
        m.face_mat = NULL;
    }
    int nlayers = m.face_mat ? m.nmat : 1;
    mx_camera tmpl, cams[NCAND];
    mx_camera_ortho(&tmpl, 0.0f, 0.0f, 3.0f, 1.02f);
    mx_camera_fibonacci(cams, NCAND, &tmpl);
    plan_views(&m, pos, cams, nlayers);
    bake_view(&m, pos, &cams[(flags >> 1) % NCAND], nlayers, flags);
done:
    free(pos);
    mx_mesh_free(&m);
    return 0;
}
