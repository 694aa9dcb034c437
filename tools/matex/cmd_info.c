/* matex info FILE: mesh statistics (counts, UVs, topology, bbox, materials), or the table of
 * contents of a matex weight file. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../../pipeline/geom/mesh.h"
#include "../../pipeline/io/filekind.h"
#include "../../pipeline/io/io.h"
#include "../../pipeline/io/mesh_load.h"
#include "../../runtime/buf.h"
#include "../../runtime/log.h"
#include "../../weights/ip_adapter_file.h"
#include "../../weights/single_file.h"
#include "../../weights/wfinfo.h"
#include "cli.h"
#include "cli_texture_opts.h"

static void usage(FILE *f) {
    fprintf(f, "usage: matex info [--json] FILE\n"
               "       matex info [--json] IMAGE --compare IMAGE2\n\n"
               "FILE is a mesh (.obj .ply .off .stl .gltf .glb), an image (PNG, JPEG, EXR, ...), a matex\n"
               "weight file, or an SD1.x checkpoint (.safetensors .ckpt .pt .pth: architecture, networks,\n"
               "dtypes, skipped keys). For an image: its size, channels and each channel's min, mean and max\n"
               "(0..1 for 8-bit files). With --compare: the PSNR of IMAGE2 against IMAGE (dB, values in 0..1,\n"
               "every channel; \"inf\" when equal), e.g. the same seed's texture on two devices.\n"
               "For a mesh: vertices and triangles as stored (polygons fan-triangulated), UV and normal\n"
               "presence, materials and their textures, and the topology after welding vertices with\n"
               "identical positions: watertightness, boundary and non-manifold edges, components,\n"
               "degenerate faces; the bounding box in the file's units.\n\n"
               "  --json   one JSON object on stdout instead of text (meshes and images)\n"
               "  --help   this text\n");
}

typedef struct {
    int faces_with_uv, faces_with_nrm;
    mx_mesh_topology topo;
    float lo[3], hi[3];
} mesh_stats;

static int count_faces_with(const mx_mesh *m, const int32_t *idx) {
    int n = 0;
    for (int f = 0; idx && f < m->nfaces; f++) n += idx[3 * f] >= 0 && idx[3 * f + 1] >= 0 && idx[3 * f + 2] >= 0;
    return n;
}

static const char *presence(int with, int total) { return with == 0 ? "no" : with == total ? "yes" : "partial"; }

static void json_str(FILE *out, const char *s) {
    mx_buf b = {0};
    mx_buf_json_str(&b, s);
    fputs(b.oom ? "\"\"" : b.p, out);
    mx_buf_free(&b);
}

static void print_text(const char *path, const mx_mesh *m, const mesh_stats *s) {
    printf("file:               %s\n", path);
    printf("vertices:           %d\n", m->nverts);
    printf("triangles:          %d\n", m->nfaces);
    printf("uvs:                %s (%d uv coordinates, %d of %d faces)\n", presence(s->faces_with_uv, m->nfaces), m->nuv,
           s->faces_with_uv, m->nfaces);
    printf("normals:            %s (%d normals)\n", presence(s->faces_with_nrm, m->nfaces), m->nnrm);
    printf("watertight:         %s\n", s->topo.watertight ? "yes" : "no");
    printf("boundary edges:     %d\n", s->topo.boundary_edges);
    printf("non-manifold edges: %d\n", s->topo.nonmanifold_edges);
    printf("components:         %d\n", s->topo.components);
    printf("degenerate faces:   %d\n", s->topo.degenerate_faces);
    printf("bbox min:           %.6g %.6g %.6g\n", s->lo[0], s->lo[1], s->lo[2]);
    printf("bbox max:           %.6g %.6g %.6g\n", s->hi[0], s->hi[1], s->hi[2]);
    printf("bbox size:          %.6g x %.6g x %.6g\n", s->hi[0] - s->lo[0], s->hi[1] - s->lo[1], s->hi[2] - s->lo[2]);
    printf("materials:          %d\n", m->nmat);
    for (int i = 0; i < m->nmat; i++)
        printf("  %d: %s%s%s\n", i, m->mats[i].name, m->mats[i].texture_path[0] ? "  texture: " : "",
               m->mats[i].texture_path);
}

static void print_json(const char *path, const mx_mesh *m, const mesh_stats *s) {
    printf("{\"file\":");
    json_str(stdout, path);
    printf(",\"vertices\":%d,\"triangles\":%d,\"uvs\":\"%s\",\"uv_count\":%d,\"faces_with_uv\":%d", m->nverts, m->nfaces,
           presence(s->faces_with_uv, m->nfaces), m->nuv, s->faces_with_uv);
    printf(",\"normals\":\"%s\",\"watertight\":%s,\"boundary_edges\":%d,\"nonmanifold_edges\":%d,\"components\":%d",
           presence(s->faces_with_nrm, m->nfaces), s->topo.watertight ? "true" : "false", s->topo.boundary_edges,
           s->topo.nonmanifold_edges, s->topo.components);
    printf(",\"degenerate_faces\":%d,\"bbox_min\":[%.9g,%.9g,%.9g],\"bbox_max\":[%.9g,%.9g,%.9g],\"materials\":[",
           s->topo.degenerate_faces, s->lo[0], s->lo[1], s->lo[2], s->hi[0], s->hi[1], s->hi[2]);
    for (int i = 0; i < m->nmat; i++) {
        printf("%s{\"name\":", i ? "," : "");
        json_str(stdout, m->mats[i].name);
        printf(",\"texture\":");
        json_str(stdout, m->mats[i].texture_path);
        printf("}");
    }
    printf("]}\n");
}

/* An image's size, channels and per-channel min, mean and max: what a script checks to see
 * that a texture or a render has content (not empty, not one flat colour). */
static int image_info(const char *path, int json) {
    mx_image img;
    mx_status st;
    if (mx_io_read_image(path, &img, &st)) {
        fprintf(stderr, "matex info: %s\n", st.msg);
        return 1;
    }
    double lo[4] = {0}, hi[4] = {0}, sum[4] = {0};
    int c = img.c < 4 ? img.c : 4;
    size_t n = (size_t)img.w * img.h;
    for (int k = 0; k < c; k++) lo[k] = hi[k] = n ? img.data[k] : 0;
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < c; k++) {
            double v = img.data[i * (size_t)img.c + (size_t)k];
            lo[k] = v < lo[k] ? v : lo[k];
            hi[k] = v > hi[k] ? v : hi[k];
            sum[k] += v;
        }
    const char *names[3] = {"min", "mean", "max"};
    if (json) {
        printf("{\"file\":");
        json_str(stdout, path);
        printf(",\"width\":%d,\"height\":%d,\"channels\":%d", img.w, img.h, img.c);
    } else {
        printf("file:     %s\nsize:     %d x %d\nchannels: %d\n", path, img.w, img.h, img.c);
    }
    for (int s = 0; s < 3; s++) {
        printf(json ? ",\"%s\":[" : "%-9s", json ? names[s] : (s == 0 ? "min:" : s == 1 ? "mean:" : "max:"));
        for (int k = 0; k < c; k++) {
            double v = s == 0 ? lo[k] : s == 1 ? (n ? sum[k] / (double)n : 0) : hi[k];
            printf(json ? "%s%.6g" : "%s%.4f", k ? (json ? "," : " ") : (json ? "" : " "), v);
        }
        printf(json ? "]" : "\n");
    }
    if (json) printf("}\n");
    mx_image_free(&img);
    return 0;
}

/* .safetensors, .ckpt, .pt, .pth, .bin: a single-file checkpoint (weights/single_file.h) or an
 * IP-Adapter (weights/ip_adapter_file.h). */
static int is_checkpoint_name(const char *path) {
    static const char *const ext[] = {".safetensors", ".ckpt", ".pt", ".pth", ".bin"};
    size_t n = strlen(path);
    for (size_t i = 0; i < sizeof ext / sizeof ext[0]; i++)
        if (n > strlen(ext[i]) && !strcmp(path + n - strlen(ext[i]), ext[i])) return 1;
    return 0;
}

static int checkpoint_info(const char *path) {
    mx_single_file sf;
    mx_status st;
    mx_status st_other;
    /* a VAE file of its own (vae-ft-mse-...) or an IP-Adapter holds none of a model's networks */
    if (mx_sf_open(&sf, path, 0, &st) && mx_sf_open(&sf, path, MX_SF_VAE_ONLY, &st_other) &&
        mx_ip_adapter_file_open(&sf, path, &st_other)) {
        fprintf(stderr, "matex info: %s\n", st.msg);
        return 1;
    }
    mx_sf_print_info(&sf, stdout);
    mx_sf_close(&sf);
    return 0;
}

static int mesh_info(const char *path, int json) {
    mx_mesh m;
    mx_status st;
    if (mx_mesh_load(path, &m, &st)) {
        fprintf(stderr, "matex info: %s\n", st.msg);
        return 1;
    }
    mesh_stats s;
    s.faces_with_uv = count_faces_with(&m, m.face_uv);
    s.faces_with_nrm = count_faces_with(&m, m.face_nrm);
    mx_mesh_bbox(&m, s.lo, s.hi);
    if (mx_mesh_topology_compute(&m, 1, &s.topo, NULL, &st)) {
        fprintf(stderr, "matex info: %s\n", st.msg);
        mx_mesh_free(&m);
        return 1;
    }
    if (json) print_json(path, &m, &s);
    else print_text(path, &m, &s);
    mx_mesh_free(&m);
    return 0;
}

/* PSNR (dB) of b against a over every channel, values in 0..1: the CPU-vs-GPU texture check of
 * tools/scripts/gpu_check.sh. */
/* One image of --compare; a file that is no image says so, not the image library's words. */
static int read_compared(const char *path, mx_image *img) {
    mx_status st, kind_st;
    if (!mx_io_read_image(path, img, &st)) return 0;
    const char *kind;
    int definite;
    if (!mx_file_kind_of(path, "an image", &kind, &definite, &kind_st) && !strstr(kind, " image"))
        fprintf(stderr, "matex info: %s is not an image (it holds %s): --compare takes two images\n", path, kind);
    else
        fprintf(stderr, "matex info: %s\n", st.msg);
    return -1;
}

static int image_compare(const char *a_path, const char *b_path, int json) {
    mx_image a = {0}, b = {0};
    int rc = 1;
    if (read_compared(a_path, &a) || read_compared(b_path, &b)) goto done;
    if (a.w != b.w || a.h != b.h || a.c != b.c) {
        fprintf(stderr, "matex info: %s is %d x %d x %d, %s is %d x %d x %d: the sizes must agree\n", a_path, a.w, a.h,
                a.c, b_path, b.w, b.h, b.c);
        goto done;
    }
    size_t n = (size_t)a.w * a.h * a.c;
    double se = 0;
    for (size_t i = 0; i < n; i++) se += ((double)a.data[i] - b.data[i]) * ((double)a.data[i] - b.data[i]);
    double mse = n ? se / (double)n : 0;
    char db[32];
    if (mse > 0) snprintf(db, sizeof db, "%.3f", 10.0 * log10(1.0 / mse));
    else snprintf(db, sizeof db, json ? "null" : "inf");
    if (json) {
        printf("{\"file\":");
        json_str(stdout, a_path);
        printf(",\"compare\":");
        json_str(stdout, b_path);
        printf(",\"psnr_db\":%s}\n", db);
    } else {
        printf("psnr_db=%s\n", db);
    }
    rc = 0;
done:
    mx_image_free(&a);
    mx_image_free(&b);
    return rc;
}

typedef struct info_args {
    const char *file, *compare;
    int json;
} info_args;

/* 0 ok, 1 --help printed, 2 usage error (worded as the other verbs': mx_cli_usage_error). */
static int parse_args(int argc, char **argv, info_args *a) {
    memset(a, 0, sizeof *a);
    for (int i = 1; i < argc; i++) a->json |= !strcmp(argv[i], "--json"); /* usage errors in JSON too */
    for (int i = 1; i < argc; i++) {
        const char *o = argv[i];
        if (!strcmp(o, "--help") || !strcmp(o, "-h")) return usage(stdout), 1;
        else if (!strcmp(o, "--json")) continue;
        else if (!strcmp(o, "--compare") && i + 1 < argc) a->compare = argv[++i];
        else if (!strcmp(o, "--compare")) return mx_cli_usage_error("info", a->json, "missing value after %s", o);
        else if (o[0] == '-' && o[1]) return mx_cli_usage_error("info", a->json, "unknown option %s", o);
        else if (a->file) return mx_cli_usage_error("info", a->json, "unexpected argument %s", o);
        else a->file = o;
    }
    if (!a->file) return mx_cli_usage_error("info", a->json, "missing FILE");
    return 0;
}

int cmd_info(int argc, char **argv) {
    info_args a;
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc == 1 ? 0 : rc;
    if (a.compare) return image_compare(a.file, a.compare, a.json);
    if (mx_wf_is_weightfile(a.file)) {
        if (a.json) return mx_cli_usage_error("info", a.json, "--json is for meshes and images; %s is a weight file", a.file);
        mx_status st;
        if (mx_wf_print_info(a.file, stdout, &st)) {
            fprintf(stderr, "matex info: %s\n", st.msg);
            return 1;
        }
        return 0;
    }
    if (is_checkpoint_name(a.file)) {
        if (a.json) return mx_cli_usage_error("info", a.json, "--json is for meshes and images; %s is a checkpoint", a.file);
        return checkpoint_info(a.file);
    }
    const char *kind;
    int definite;
    mx_status st;
    if (mx_file_kind_of(a.file, "a mesh, an image, a weight file or a checkpoint", &kind, &definite, &st)) {
        fprintf(stderr, "matex info: %s\n", st.msg);
        return 1;
    }
    return strstr(kind, " image") ? image_info(a.file, a.json) : mesh_info(a.file, a.json);
}
