/* matex render MESH [--texture IMG] [--views N] [--size S] [--up y|z] [--force] -o DIR:
 * turntable views (orthographic, 15 degrees above the horizon, the first one the front)
 * as DIR/view_NN.png, and DIR/contact_sheet.png with all of them. Textured when the mesh
 * has UVs and a texture (its own, or --texture for every material), else shaded normals.
 * DIR is staged as for matex texture (pipeline/texture/outdir.h): an error or a signal at any
 * moment leaves no partial folder. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../../pipeline/geom/raster.h"
#include "../../pipeline/io/io.h"
#include "../../pipeline/io/mesh_load.h"
#include "../../pipeline/texture/outdir.h"
#include "../../runtime/buf.h"
#include "../../runtime/log.h"
#include "cli.h"
#include "cli_args.h"
#include "cli_signals.h"
#include "cli_texture_opts.h"
#include "../../runtime/numparse.h"

static void usage(FILE *f) {
    fprintf(f, "usage: matex render MESH [--texture IMG] [--views N] [--size S] [--up y|z] [--force] [--json] -o DIR\n\n"
               "Renders N turntable views (default 8) of S x S pixels (default 512) into DIR/view_NN.png\n"
               "and a contact sheet DIR/contact_sheet.png. Textured when the mesh has UVs and a texture\n"
               "(its materials' own, or IMG for all), else shaded normals.\n"
               "  --up z   the mesh is z-up (CAD, scans); default y-up (glTF, OBJ)\n"
               "  --force  replace DIR when it holds an earlier output of matex (never other files)\n"
               "  --json   print a JSON summary on stdout: {\"ok\":true,\"out\":DIR,\"views\":N} or {\"ok\":false,\"error\":...}\n"
               "exit: 0 done, 1 bad input, 2 usage, 130 interrupted (nothing written)\n");
}

typedef struct render_args {
    const char *mesh, *texture, *out;
    int views, size, force, json;
    mx_up_axis up;
} render_args;

/* An integer option in lo..hi, worded as the other verbs' option errors; 0 or the exit code 2. */
static int int_option(const render_args *a, const char *opt, const char *value, int lo, int hi, int *out) {
    if (mx_parse_int(value, lo, hi, out))
        return mx_cli_usage_error("render", a->json, "%s must be an integer in %d..%d, not '%s'", opt, lo, hi, value);
    return 0;
}

/* 0 ok, 2 usage error (message printed). */
static int parse_args(int argc, char **argv, render_args *a) {
    memset(a, 0, sizeof *a);
    a->views = 8;
    a->size = 512;
    for (int i = 1; i < argc; i++) a->json |= !strcmp(argv[i], "--json"); /* usage errors in JSON too */
    for (int i = 1; i < argc; i++) {
        const char *o = argv[i];
        int has = i + 1 < argc;
        if (!strcmp(o, "--texture") && has) a->texture = argv[++i];
        else if (!strcmp(o, "--views") && has) {
            if (int_option(a, o, argv[++i], 1, 360, &a->views)) return 2;
        } else if (!strcmp(o, "--size") && has) {
            if (int_option(a, o, argv[++i], 16, 4096, &a->size)) return 2;
        }
        else if (!strcmp(o, "-o") && has) a->out = argv[++i];
        else if (!strcmp(o, "--force")) a->force = 1;
        else if (!strcmp(o, "--json")) continue;
        else if (!strcmp(o, "--up") && has) {
            const char *u = argv[++i];
            if (strcmp(u, "y") && strcmp(u, "z")) return mx_cli_usage_error("render", a->json, "--up must be one of y|z, not '%s'", u);
            a->up = u[0] == 'z' ? MX_UP_Z : MX_UP_Y;
        } else if (o[0] == '-' && (!strcmp(o, "--texture") || !strcmp(o, "--views") || !strcmp(o, "--size") ||
                                   !strcmp(o, "-o") || !strcmp(o, "--up"))) {
            return mx_cli_usage_error("render", a->json, "missing value after %s", o);
        } else if (o[0] == '-') {
            return mx_cli_usage_error("render", a->json, "unknown option %s", o);
        } else if (a->mesh) {
            return mx_cli_usage_error("render", a->json, "unexpected argument %s", o);
        } else a->mesh = o;
    }
    if (!a->mesh) return mx_cli_usage_error("render", a->json, "missing MESH");
    if (!a->out) return mx_cli_usage_error("render", a->json, "missing -o DIR");
    return 0;
}

/* Textures per material (ntex of them); 0 when the render is untextured. */
static int load_textures(const render_args *a, const mx_mesh *m, mx_image **tex, int *ntex, mx_status *st) {
    *tex = NULL;
    *ntex = 0;
    if (!m->face_uv && a->texture) /* the texture would have nowhere to go: refused, not shaded normals */
        return mx_fail(st, MX_EINPUT, "%s has no UVs, so --texture %s cannot be mapped onto it (matex texture gives a mesh UVs)",
                       a->mesh, a->texture);
    if (!m->face_uv) return 0;
    int n = m->nmat > 0 ? m->nmat : 1;
    mx_image *t = calloc((size_t)n, sizeof *t);
    if (!t) return mx_fail(st, MX_ENOMEM, "render: out of memory");
    if (a->texture) {
        if (mx_io_read_image(a->texture, &t[0], st)) {
            free(t);
            return -1;
        }
        for (int k = 1; k < n; k++) t[k] = t[0]; /* shared, freed once */
    } else if (m->nmat > 0 && mx_mesh_load_textures(m, t, st)) {
        free(t);
        return -1;
    }
    *tex = t;
    *ntex = n;
    return 0;
}

static void free_textures(mx_image *tex, int ntex, int shared) {
    for (int k = 0; k < (shared ? 1 : ntex); k++) mx_image_free(&tex[k]);
    free(tex);
}

static int render_views(const render_args *a, const char *dir, const volatile sig_atomic_t *stop, const mx_mesh *m,
                        const float *pos, const mx_image *tex, int ntex, mx_image *sheet, int cols, int tile,
                        mx_pool *pool, mx_status *st) {
    const float bg[3] = {1, 1, 1};
    mx_gbuffer gb;
    if (mx_gbuffer_init(&gb, a->size, a->size, st)) return -1;
    int any_tex = 0;
    for (int k = 0; k < ntex; k++) any_tex |= tex[k].data != NULL;
    int rc = 0;
    for (int v = 0; v < a->views && !rc; v++) {
        if (*stop) {
            rc = mx_fail(st, MX_ECANCEL, "interrupted");
            break;
        }
        mx_camera cam;
        mx_camera_ortho(&cam, 360.0f * (float)v / (float)a->views, 15, 3, 1.05f);
        mx_image img = {0}, small = {0};
        rc = mx_rasterize(m, pos, &cam, MX_RASTER_UV, pool, &gb, st);
        rc = rc || (any_tex ? mx_render_textured(&gb, m, tex, ntex, bg, pool, &img, st)
                            : mx_render_normals(&gb, bg, &img, st));
        char path[4300];
        snprintf(path, sizeof path, "%s/view_%02d.png", dir, v);
        rc = rc || mx_io_write_png(path, &img, st);
        mx_crop full = {0, 0, a->size};
        rc = rc || mx_crop_resize(&img, full, tile, pool, &small, st);
        if (!rc) {
            mx_crop at = {(v % cols) * tile, (v / cols) * tile, tile};
            mx_crop_paste(&small, at, pool, sheet);
        }
        mx_image_free(&img);
        mx_image_free(&small);
    }
    mx_gbuffer_free(&gb);
    return rc;
}

/* --json: the summary of a done run, or its error (msg). */
static void print_json_result(const render_args *a, const char *msg) {
    if (msg) {
        mx_cli_print_json_error(msg);
        return;
    }
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"ok\":true,\"out\":");
    mx_buf_json_str(&b, a->out);
    mx_buf_printf(&b, ",\"views\":%d}", a->views);
    if (!b.oom) puts(b.p);
    mx_buf_free(&b);
}

int cmd_render(int argc, char **argv) {
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return 0;
        }
    render_args a;
    int urc = parse_args(argc, argv, &a);
    if (urc) return urc;
    mx_status st;
    mx_status_clear(&st);
    mx_mesh m = {0};
    float *pos = NULL;
    mx_image *tex = NULL, sheet = {0};
    int ntex = 0;
    mx_pool *pool = NULL;
    int cols = (int)ceil(sqrt((double)a.views)), rows = (a.views + cols - 1) / cols;
    int tile = a.size / 2;
    mx_outdir od = {0};
    volatile sig_atomic_t *stop = mx_cli_signals_catch();
    mx_cli_signals_output(a.out);
    int rc = mx_mesh_load(a.mesh, &m, &st) || mx_mesh_normalized(&m, a.up, &pos, NULL, NULL, &st) ||
             load_textures(&a, &m, &tex, &ntex, &st) || mx_outdir_open(&od, a.out, a.force, (const char *[]){a.mesh, a.texture}, 2, &st);
    rc = rc || !(pool = mx_pool_create(0, &st)) || mx_image_alloc(&sheet, cols * tile, rows * tile, 3, &st);
    if (!rc) {
        for (size_t i = 0; i < (size_t)sheet.w * sheet.h * 3; i++) sheet.data[i] = 1;
        rc = render_views(&a, od.stage, stop, &m, pos, tex, ntex, &sheet, cols, tile, pool, &st);
    }
    char path[4300];
    snprintf(path, sizeof path, "%s/contact_sheet.png", od.stage);
    rc = rc || mx_io_write_png(path, &sheet, &st) || mx_outdir_publish(&od, stop, &st);
    mx_outdir_discard(&od);
    if (rc) fprintf(stderr, "matex render: %s\n", st.msg);
    else mx_info("matex render: %d views of %s in %s", a.views, a.mesh, a.out);
    if (a.json) print_json_result(&a, rc ? st.msg : NULL);
    if (tex) free_textures(tex, ntex, a.texture != NULL);
    mx_image_free(&sheet);
    mx_pool_destroy(pool);
    free(pos);
    mx_mesh_free(&m);
    return !rc ? 0 : st.code == MX_ECANCEL ? 130 : 1;
}
