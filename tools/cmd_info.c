/* matex info FILE: mesh statistics (counts, UVs, topology, bbox, materials), or the table of
 * contents of a matex weight file. */
#include <stdio.h>
#include <string.h>

#include "../pipeline/geom/mesh.h"
#include "../runtime/log.h"
#include "../weights/single_file.h"
#include "../weights/wfinfo.h"
#include "cli.h"

static void usage(FILE *f) {
    fprintf(f, "usage: matex info [--json] FILE\n\n"
               "FILE is a mesh (.obj .ply .off .stl .gltf .glb), a matex weight file, or an SD1.x checkpoint\n"
               "(.safetensors .ckpt .pt .pth: architecture, networks, dtypes, skipped keys).\n"
               "For a mesh: vertices and triangles as stored (polygons fan-triangulated), UV and normal\n"
               "presence, materials and their textures, and the topology after welding vertices with\n"
               "identical positions: watertightness, boundary and non-manifold edges, components,\n"
               "degenerate faces; the bounding box in the file's units.\n\n"
               "  --json   one JSON object on stdout instead of text (meshes only)\n"
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
    fputc('"', out);
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') fprintf(out, "\\%c", c);
        else if (c < 0x20) fprintf(out, "\\u%04x", c);
        else fputc(c, out);
    }
    fputc('"', out);
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

/* .safetensors, .ckpt, .pt, .pth: a single-file checkpoint (weights/single_file.h). */
static int is_checkpoint_name(const char *path) {
    static const char *const ext[] = {".safetensors", ".ckpt", ".pt", ".pth"};
    size_t n = strlen(path);
    for (size_t i = 0; i < sizeof ext / sizeof ext[0]; i++)
        if (n > strlen(ext[i]) && !strcmp(path + n - strlen(ext[i]), ext[i])) return 1;
    return 0;
}

static int checkpoint_info(const char *path) {
    mx_single_file sf;
    mx_status st;
    mx_status st_vae;
    /* a VAE file of its own (vae-ft-mse-...) holds none of a model's networks */
    if (mx_sf_open(&sf, path, 0, &st) && mx_sf_open(&sf, path, MX_SF_VAE_ONLY, &st_vae)) {
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

int cmd_info(int argc, char **argv) {
    const char *file = NULL;
    int json = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(argv[i], "--json")) {
            json = 1;
        } else if (argv[i][0] == '-' && argv[i][1]) {
            fprintf(stderr, "matex info: unknown option '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        } else if (file) {
            fprintf(stderr, "matex info: one FILE expected, got '%s' and '%s'\n", file, argv[i]);
            return 2;
        } else {
            file = argv[i];
        }
    }
    if (!file) {
        usage(stderr);
        return 2;
    }
    if (mx_wf_is_weightfile(file)) {
        if (json) {
            fprintf(stderr, "matex info: --json is for meshes; %s is a weight file\n", file);
            return 2;
        }
        mx_status st;
        if (mx_wf_print_info(file, stdout, &st)) {
            fprintf(stderr, "matex info: %s\n", st.msg);
            return 1;
        }
        return 0;
    }
    if (is_checkpoint_name(file)) {
        if (json) {
            fprintf(stderr, "matex info: --json is for meshes; %s is a checkpoint\n", file);
            return 2;
        }
        return checkpoint_info(file);
    }
    return mesh_info(file, json);
}
