/* matex transfer SRC_TEXTURED DST_MESH -o OUT [--views K] [--candidates N] [--size S]:
 * moves the texture of a textured mesh onto another mesh or UV layout. Views are chosen
 * on the destination (front, back, then paper Alg. 1 over N Fibonacci candidates); the
 * source is rendered with its texture from each view and the render is backprojected
 * onto the destination's UVs (an atlas is built when it has none); untouched chart texels
 * are filled and the gutter dilated. Both meshes are placed by the source's normalisation
 * (bounding box centred, unit sphere), so they must share their pose and units. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/backproject.h"
#include "../pipeline/geom/export.h"
#include "../pipeline/geom/masks.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/geom/uvatlas.h"
#include "../pipeline/geom/uvfill.h"
#include "../pipeline/geom/views.h"
#include "../runtime/log.h"
#include "cli.h"

#define SELECT_SIZE 256 /* candidate renders for view selection */
#define GUTTER 4

static void usage(FILE *f) {
    fprintf(f, "usage: matex transfer SRC_TEXTURED DST_MESH -o OUT [--views K] [--candidates N] [--size S]\n"
               "       [--image-size M] [--background R,G,B] [--frontal-threshold T] [--write first-wins|angle-aware]\n\n"
               "Renders the source's texture from K views (default 6: front, back, then automatic view\n"
               "selection over N candidates, default 40, on the destination) at S x S (default 1024),\n"
               "backprojects them onto the destination's UVs (an atlas is made if it has none) into an\n"
               "S x S texture, fills the texels no view reached, and writes OUT/texture.png, texture.exr,\n"
               "mesh.obj + mesh.mtl, mesh.glb and report.json. Prints the coverage, and the PSNR against\n"
               "the source texture when SRC and DST are the same file. Both meshes must share pose and units.\n"
               "--image-size M sends each render through the texture job's model image (crop to the object,\n"
               "M x M, back; 0 = off), --background the colour behind the source (default 0,0,0),\n"
               "--frontal-threshold the |n.v| a pixel needs (default 0.3), --write the texel policy (default\n"
               "angle-aware: a later view that sees a texel clearly more frontally replaces it).\n");
}

typedef struct transfer_args {
    const char *src, *dst, *out;
    int views, candidates, size, image_size, write_flags;
    float background[3], frontal_threshold;
} transfer_args;

static int parse_write(const char *s, int *flags) {
    if (!strcmp(s, "first-wins")) *flags = 0;
    else if (!strcmp(s, "angle-aware")) *flags = MX_BACKPROJECT_OVERWRITE;
    else return -1;
    return 0;
}

static int parse_args(int argc, char **argv, transfer_args *a) {
    memset(a, 0, sizeof *a);
    a->views = 6;
    a->candidates = 40;
    a->size = 1024;
    a->frontal_threshold = MX_FRONTAL_THRESHOLD_DEFAULT;
    a->write_flags = MX_BACKPROJECT_OVERWRITE;
    for (int i = 1; i < argc; i++) {
        const char *o = argv[i];
        int has = i + 1 < argc, bad = 0;
        if (!strcmp(o, "--views") && has) a->views = atoi(argv[++i]);
        else if (!strcmp(o, "--image-size") && has) a->image_size = atoi(argv[++i]);
        else if (!strcmp(o, "--frontal-threshold") && has) a->frontal_threshold = (float)atof(argv[++i]);
        else if (!strcmp(o, "--write") && has) bad = parse_write(argv[++i], &a->write_flags);
        else if (!strcmp(o, "--background") && has)
            bad = sscanf(argv[++i], "%f,%f,%f", &a->background[0], &a->background[1], &a->background[2]) != 3;
        else if (!strcmp(o, "--candidates") && has) a->candidates = atoi(argv[++i]);
        else if (!strcmp(o, "--size") && has) a->size = atoi(argv[++i]);
        else if (!strcmp(o, "-o") && has) a->out = argv[++i];
        else if (o[0] == '-' || (a->src && a->dst)) bad = 1;
        if (bad) {
            fprintf(stderr, "matex transfer: unexpected argument '%s'\n", o);
            return 2;
        }
        if (o[0] == '-') continue;
        if (!a->src) a->src = o;
        else a->dst = o;
    }
    if (!a->src || !a->dst || !a->out) {
        usage(stderr);
        return 2;
    }
    if (a->views < 2 || a->views > 64 || a->candidates < 1 || a->candidates > 1000 || a->size < 64 ||
        a->size > 8192 || a->image_size < 0 || a->image_size > 2048 || !(a->frontal_threshold >= 0) ||
        a->frontal_threshold >= 1) {
        fprintf(stderr, "matex transfer: --views must be 2..64, --candidates 1..1000, --size 64..8192, --image-size\n"
                        "0..2048, --frontal-threshold in [0, 1)\n");
        return 2;
    }
    return 0;
}

typedef struct transfer_state {
    mx_mesh src, dst;
    float *src_pos, *dst_pos;
    mx_image *src_tex; /* [max(1, src.nmat)] */
    int src_ntex;
    int nlayers;
    mx_camera *cams; /* [2 + candidates] */
    mx_view_cache vc;
    mx_view_buffers vb;
    mx_gbuffer src_gb;
    mx_bake bake;
    mx_image *out_tex; /* [nlayers] */
    int *chosen, nchosen;
    mx_pool *pool;
} transfer_state;

static void state_free(transfer_state *t) {
    for (int k = 0; t->src_tex && k < t->src_ntex; k++) mx_image_free(&t->src_tex[k]);
    for (int k = 0; t->out_tex && k < t->nlayers; k++) mx_image_free(&t->out_tex[k]);
    free(t->src_tex);
    free(t->out_tex);
    free(t->cams);
    free(t->chosen);
    mx_view_cache_free(&t->vc);
    mx_view_buffers_free(&t->vb);
    mx_gbuffer_free(&t->src_gb);
    mx_bake_free(&t->bake);
    mx_pool_destroy(t->pool);
    free(t->src_pos);
    free(t->dst_pos);
    mx_mesh_free(&t->src);
    mx_mesh_free(&t->dst);
}

/* Loads both meshes, the source's textures, and places both by the source's normalisation. */
static int load_inputs(const transfer_args *a, transfer_state *t, mx_status *st) {
    if (mx_mesh_load(a->src, &t->src, st) || mx_mesh_load(a->dst, &t->dst, st)) return -1;
    if (!t->src.face_uv || t->src.nmat < 1)
        return mx_fail(st, MX_EINPUT, "%s: the source has no UVs or no material to take a texture from", a->src);
    t->src_ntex = t->src.nmat;
    t->src_tex = calloc((size_t)t->src_ntex, sizeof *t->src_tex);
    if (!t->src_tex) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    if (mx_mesh_load_textures(&t->src, t->src_tex, st)) return -1;
    int any = 0;
    for (int k = 0; k < t->src_ntex; k++) any |= t->src_tex[k].data != NULL;
    if (!any) return mx_fail(st, MX_EINPUT, "%s: the source has no readable texture", a->src);
    if (!t->dst.face_uv) {
        mx_uvatlas_opts o = mx_uvatlas_defaults();
        o.texture_size = a->size;
        mx_uvatlas_report r;
        if (mx_uvatlas_build(&t->dst, &o, &r, st)) return mx_fail_prefix(st, "%s: uv atlas", a->dst);
        mx_info("transfer: %s has no UVs: atlas with %d charts, %.1f%% of the square used", a->dst, r.charts,
                100 * r.utilisation);
    }
    float center[3], scale;
    if (mx_mesh_normalized(&t->src, MX_UP_Y, &t->src_pos, center, &scale, st)) return -1;
    t->dst_pos = malloc(3 * ((size_t)t->dst.nverts + 1) * sizeof *t->dst_pos);
    if (!t->dst_pos) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    for (size_t i = 0; i < 3 * (size_t)t->dst.nverts; i++) t->dst_pos[i] = (t->dst.pos[i] - center[i % 3]) * scale;
    t->nlayers = t->dst.nmat > 1 ? t->dst.nmat : 1;
    return 0;
}

/* The render through the texture job's model image: crop to the destination's object, resize
 * to image_size, paste back bilinearly (what happens to every generated image). */
static int through_model_image(const transfer_state *t, int image_size, mx_image *img, mx_status *st) {
    size_t n = (size_t)img->w * img->h;
    uint8_t *fg = malloc(n);
    mx_image small = {0};
    if (!fg) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    mx_mask_foreground(&t->vb.gb, fg);
    mx_crop crop = mx_crop_from_mask(fg, img->w, img->h, 0.05f);
    free(fg);
    if (mx_crop_resize(img, crop, image_size, &small, st)) return -1;
    memset(img->data, 0, n * (size_t)img->c * sizeof *img->data);
    mx_crop_paste(&small, crop, img);
    mx_image_free(&small);
    return 0;
}

/* Renders the source from cam (over the background colour) and backprojects it where the
 * destination is visible, frontal, not internal, away from edges, and the source has a surface. */
static int transfer_view(const transfer_args *a, transfer_state *t, const mx_camera *cam, mx_status *st) {
    mx_image img = {0};
    int rc = mx_view_prepare(&t->vb, &t->dst, t->dst_pos, cam, MX_NORMAL_GEOMETRIC, a->frontal_threshold, t->pool,
                             st) ||
             mx_view_erode_edges(&t->vb, mx_view_erode_radius(a->size, a->image_size), st) ||
             mx_rasterize(&t->src, t->src_pos, cam, MX_RASTER_CULL_BACK | MX_RASTER_UV, t->pool, &t->src_gb, st) ||
             mx_render_textured(&t->src_gb, &t->src, t->src_tex, t->src_ntex, a->background, t->pool, &img, st) ||
             (a->image_size > 0 && through_model_image(t, a->image_size, &img, st));
    if (!rc) {
        for (size_t i = 0; i < (size_t)img.w * img.h; i++) t->vb.mask[i] &= t->src_gb.face[i] >= 0;
        rc = mx_backproject(&t->bake, &t->vb.gb, &t->dst, &img, t->vb.mask, a->write_flags, t->pool, st);
    }
    mx_image_free(&img);
    return rc;
}

static int select_and_bake(const transfer_args *a, transfer_state *t, double *coverage, mx_status *st) {
    int ncams = 2 + a->candidates;
    t->cams = malloc((size_t)ncams * sizeof *t->cams);
    t->chosen = malloc((size_t)a->views * sizeof *t->chosen);
    if (!t->cams || !t->chosen) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    mx_camera_ortho(&t->cams[0], 0, 0, 3, 1.05f);
    mx_camera_ortho(&t->cams[1], 180, 0, 3, 1.05f);
    mx_camera_fibonacci(t->cams + 2, a->candidates, &t->cams[0]);
    if (mx_view_cache_build(&t->vc, &t->dst, t->dst_pos, t->cams, ncams, SELECT_SIZE, a->size, a->size,
                            t->nlayers, MX_NORMAL_GEOMETRIC, a->frontal_threshold,
                            mx_view_scale_radius(mx_view_erode_radius(a->size, a->image_size), a->size, SELECT_SIZE),
                            t->pool, st) ||
        mx_view_buffers_init(&t->vb, a->size, st) || mx_gbuffer_init(&t->src_gb, a->size, a->size, st) ||
        mx_bake_init(&t->bake, a->size, a->size, t->nlayers, st))
        return -1;
    for (int k = 0; k < 2; k++) {
        if (transfer_view(a, t, &t->cams[k], st)) return -1;
        t->chosen[t->nchosen++] = k;
    }
    mx_view_plan plan;
    if (mx_view_plan_make(&t->vc, t->bake.known, a->views - 2, 0.995, 16, &plan, st)) return -1;
    int rc = 0;
    for (int k = 0; k < plan.n && !rc; k++) {
        rc = transfer_view(a, t, &t->cams[plan.cand[k]], st);
        t->chosen[t->nchosen++] = plan.cand[k];
    }
    mx_view_plan_free(&plan);
    if (rc) return -1;
    size_t n = (size_t)a->size * a->size * t->nlayers, vis = 0, hit = 0;
    uint8_t *visible = malloc(n);
    if (!visible) return mx_fail(st, MX_ENOMEM, "transfer: out of memory");
    mx_view_cache_visible(&t->vc, visible);
    for (size_t i = 0; i < n; i++) {
        vis += visible[i];
        hit += visible[i] && t->bake.known[i];
    }
    free(visible);
    *coverage = vis ? (double)hit / (double)vis : 0;
    return 0;
}

/* Textures from the bake, filled inside charts (harmonic, across seams) and dilated across
 * their borders. */
static int finish_textures(const transfer_args *a, transfer_state *t, mx_status *st) {
    const float grey[3] = {0.5f, 0.5f, 0.5f};
    size_t plane = (size_t)a->size * a->size;
    t->out_tex = calloc((size_t)t->nlayers, sizeof *t->out_tex);
    int rc = !t->out_tex ? mx_fail(st, MX_ENOMEM, "transfer: out of memory") : 0;
    for (int l = 0; l < t->nlayers && !rc; l++)
        rc = mx_bake_texture(&t->bake, l, grey, &t->out_tex[l], st) ||
             mx_uv_fill_harmonic(&t->out_tex[l], t->bake.known + l * plane, &t->dst, l, t->nlayers, GUTTER, st);
    return rc;
}

/* PSNR over covered texels against the source's own texture (same mesh and UVs). */
static double psnr_against_source(const transfer_state *t) {
    size_t plane = (size_t)t->bake.w * t->bake.h;
    double se = 0;
    size_t n = 0;
    for (int l = 0; l < t->nlayers; l++) {
        const mx_image *ref = l < t->src_ntex ? &t->src_tex[l] : NULL;
        if (!ref || !ref->data) continue;
        for (size_t i = 0; i < plane; i++) {
            if (!t->bake.known[l * plane + i]) continue;
            float u = ((float)(i % (size_t)t->bake.w) + 0.5f) / (float)t->bake.w;
            float v = 1.0f - ((float)(i / (size_t)t->bake.w) + 0.5f) / (float)t->bake.h;
            float want[4] = {0, 0, 0, 0};
            mx_texture_sample(ref, u, v, want);
            if (ref->c < 3) want[1] = want[2] = want[0];
            const float *got = t->out_tex[l].data + 3 * i;
            for (int c = 0; c < 3; c++) se += ((double)got[c] - want[c]) * ((double)got[c] - want[c]);
            n += 3;
        }
    }
    return n ? 10 * log10(1.0 / (se / (double)n + 1e-20)) : 0;
}

static void write_report(char *buf, size_t cap, const transfer_state *t, double coverage, double psnr,
                         int same, double seconds) {
    size_t o = (size_t)snprintf(buf, cap, "{\n  \"views\": [");
    for (int k = 0; k < t->nchosen && o < cap; k++) {
        const mx_camera *c = &t->cams[t->chosen[k]];
        o += (size_t)snprintf(buf + o, cap - o, "%s{\"azimuth\": %.2f, \"elevation\": %.2f}", k ? ", " : "",
                              c->azimuth, c->elevation);
    }
    if (o < cap)
        o += (size_t)snprintf(buf + o, cap - o, "],\n  \"coverage\": %.6f,\n  \"psnr_db\": ", coverage);
    if (o < cap) o += (size_t)snprintf(buf + o, cap - o, same ? "%.3f" : "null", psnr);
    if (o < cap) snprintf(buf + o, cap - o, ",\n  \"seconds\": %.3f\n}\n", seconds);
}

int cmd_transfer(int argc, char **argv) {
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return 0;
        }
    transfer_args a;
    int urc = parse_args(argc, argv, &a);
    if (urc) return urc;
    double t0 = mx_now();
    mx_status st;
    mx_status_clear(&st);
    transfer_state t;
    memset(&t, 0, sizeof t);
    double coverage = 0, psnr = 0;
    int same = !strcmp(a.src, a.dst);
    int rc = load_inputs(&a, &t, &st) || !(t.pool = mx_pool_create(0, &st)) ||
             select_and_bake(&a, &t, &coverage, &st) || finish_textures(&a, &t, &st);
    if (!rc) {
        if (same) psnr = psnr_against_source(&t);
        char report[8192];
        write_report(report, sizeof report, &t, coverage, psnr, same, mx_now() - t0);
        rc = mx_write_outputs(a.out, &t.dst, t.out_tex, t.nlayers, report, &st);
    }
    if (rc) fprintf(stderr, "matex transfer: %s\n", st.msg);
    else if (same)
        printf("transfer: %d views, coverage %.2f%% of candidate-visible texels, PSNR %.2f dB\n", t.nchosen,
               100 * coverage, psnr);
    else printf("transfer: %d views, coverage %.2f%% of candidate-visible texels\n", t.nchosen, 100 * coverage);
    state_free(&t);
    return rc ? 1 : 0;
}
