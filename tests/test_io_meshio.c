/* Mesh and image I/O: every shared asset loads with the counts of assets/MANIFEST.md; OBJ
 * details (quads, negative indices, usemtl groups, MTL textures); hostile files end in a
 * clear error; mesh utilities (normalisation, up axis, topology); image read/write. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../pipeline/geom/image.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/io/io.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/log.h"
#include "util_test.h"

/* One row of MANIFEST.md: topology after welding bit-identical positions. */
typedef struct {
    const char *file;
    int nverts, nfaces, has_uv, watertight, boundary, components, nmat;
    float bbox[3];
    int textures; /* materials whose texture decodes */
} asset;

static const asset assets[] = {
    {"spot/spot_triangulated.obj", 2930, 5856, 1, 1, 0, 1, 1, {0.9431f, 1.69f, 1.718f}, 0},
    {"bob/bob_tri.obj", 5344, 10688, 1, 1, 0, 1, 1, {1.856f, 0.9725f, 1.463f}, 1},
    {"blub/blub_triangulated.obj", 7106, 14208, 1, 1, 0, 1, 1, {1.423f, 1.747f, 2.908f}, 0},
    {"spot_ply/spot.ply", 2930, 5856, 0, 1, 0, 1, 1, {0.9431f, 1.69f, 1.718f}, 0},
    {"garment_female_casual/female_casualsuit01.obj", 2197, 4236, 1, 0, 164, 2, 1, {5.41f, 12.85f, 2.531f}, 0},
    {"garment_female_elegant/female_elegantsuit01.obj", 2205, 4192, 1, 0, 220, 2, 1, {8.919f, 8.613f, 2.869f}, 0},
    {"shoes_pair/shoes03.obj", 2222, 4128, 1, 0, 296, 12, 1, {5.134f, 2.414f, 2.761f}, 0},
    {"fedora_hat/fedora.obj", 634, 1244, 1, 0, 22, 1, 1, {2.022f, 1.089f, 2.616f}, 0},
    {"boot/boot.obj", 19931, 39906, 0, 1, 0, 1, 1, {0.307f, 0.2023f, 0.1103f}, 0},
    {"koala/koala.obj", 49999, 99994, 0, 1, 0, 1, 1, {3.781f, 5.366f, 9.27f}, 0},
    {"mountain/mountain.obj", 25600, 50562, 0, 0, 636, 1, 1, {32.99f, 17.86f, 32.98f}, 0},
    {"hammer/hammer.obj", 30082, 60160, 0, 1, 0, 1, 1, {2.951f, 0.6889f, 8.246f}, 0},
    {"wooden_stool/painted_wooden_stool_1k.gltf", 604, 676, 1, 0, 80, 13, 1, {0.3848f, 0.5789f, 0.4061f}, 1},
    {"flight_helmet/FlightHelmet.gltf", 55392, 94722, 1, 0, 296, 82, 6, {0.3666f, 0.716f, 0.3716f}, 6},
    {"cesium_milk_truck/CesiumMilkTruck.glb", 3564, 3624, 1, 0, 8, 13, 4, {4.869f, 2.583f, 2.792f}, 2},
};

static char tmpdir[256];

static void tmp_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmpdir, name); }

static void write_text(const char *name, const char *text) {
    char p[512];
    tmp_path(p, sizeof p, name);
    FILE *f = fopen(p, "wb");
    if (!f) {
        perror(p);
        exit(2);
    }
    fputs(text, f);
    fclose(f);
}

static int close_to(float got, float want) { return fabsf(got - want) <= 0.001f * fmaxf(1.f, fabsf(want)); }

static void check_asset(const asset *a) {
    char path[1024];
    if (!mx_test_need(path, sizeof path, "assets/%s", a->file)) return;
    mx_mesh m;
    mx_status st;
    double t0 = mx_now();
    if (mx_mesh_load(path, &m, &st)) {
        printf("FAIL load %s: %s\n", a->file, st.msg);
        mx_test_failures++;
        return;
    }
    double t1 = mx_now();
    mx_mesh_topology t;
    CHECK(mx_mesh_topology_compute(&m, 1, &t, NULL, &st) == 0);
    float lo[3], hi[3];
    mx_mesh_bbox(&m, lo, hi);
    mx_image tex[8];
    int ntex = 0;
    CHECK(m.nmat <= 8 && mx_mesh_load_textures(&m, tex, &st) == 0);
    for (int i = 0; i < m.nmat && i < 8; i++) {
        ntex += tex[i].data != NULL && tex[i].w > 0;
        mx_image_free(&tex[i]);
    }
    int ok = m.nverts == a->nverts && m.nfaces == a->nfaces && (m.face_uv != NULL) == a->has_uv &&
             t.watertight == a->watertight && t.boundary_edges == a->boundary && t.components == a->components &&
             t.nonmanifold_edges == 0 && t.degenerate_faces == 0 && m.nmat == a->nmat && ntex == a->textures;
    for (int k = 0; k < 3; k++) ok &= close_to(hi[k] - lo[k], a->bbox[k]);
    printf("%-48s v=%d f=%d uv=%d wt=%d b=%d comp=%d mat=%d tex=%d load %.0f ms %s\n", a->file, m.nverts, m.nfaces,
           m.face_uv != NULL, t.watertight, t.boundary_edges, t.components, m.nmat, ntex, 1000 * (t1 - t0),
           ok ? "ok" : "FAIL");
    if (!ok) mx_test_failures++;
    mx_mesh_free(&m);
}

/* Quads, a pentagon, negative indices, usemtl groups, an MTL with map_Kd and a texture. */
static void test_obj_features(void) {
    write_text("tex_a.png", ""); /* existence is all the loader checks; decoding happens later */
    write_text("feat.mtl", "newmtl red\nKd 1 0 0\nmap_Kd -s 1 1 1 tex_a.png\nnewmtl blue\nmap_Kd missing.png\n");
    write_text("feat.obj", "mtllib feat.mtl\n"
                           "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
                           "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 1\n"
                           "vn 0 0 1\n"
                           "usemtl red\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
                           "usemtl blue\nf -5/-5/-1 -4/-4/-1 -3/-3/-1 -1/-1/-1 -2/-2/-1  # pentagon\n"
                           "usemtl red\nf 1//1 2//1 3//1\n");
    char p[512];
    tmp_path(p, sizeof p, "feat.obj");
    mx_mesh m;
    mx_status st;
    int rc = mx_mesh_load(p, &m, &st);
    CHECK(rc == 0);
    if (rc) {
        printf("feat.obj: %s\n", st.msg);
        return;
    }
    CHECK(m.nverts == 5 && m.nfaces == 2 + 3 + 1 && m.nuv == 5 && m.nnrm == 1);
    CHECK(m.nmat == 2 && !strcmp(m.mats[0].name, "red") && !strcmp(m.mats[1].name, "blue"));
    CHECK(strstr(m.mats[0].texture_path, "tex_a.png") != NULL);
    CHECK(m.mats[1].texture_path[0] == 0); /* missing texture: warning, no path */
    const int32_t want_faces[] = {0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 2, 4, 0, 4, 3, 0, 1, 2};
    const int32_t want_mat[] = {0, 0, 1, 1, 1, 0};
    CHECK(!memcmp(m.faces, want_faces, sizeof want_faces));
    CHECK(m.face_mat && !memcmp(m.face_mat, want_mat, sizeof want_mat));
    CHECK(m.face_uv && m.face_uv[3] == 0 && m.face_uv[11] == 4 && m.face_uv[15] == -1); /* last face has no vt */
    CHECK(m.face_nrm && m.face_nrm[17] == 0);
    mx_mesh_free(&m);
}

/* A binary STL of n separate triangles; with nan, the second vertex of the last one is NaN. */
static void write_binary_stl(const char *name, uint32_t n, int nan) {
    char p[512];
    tmp_path(p, sizeof p, name);
    FILE *f = fopen(p, "wb");
    if (!f) {
        perror(p);
        exit(2);
    }
    char header[80] = "binary stl";
    fwrite(header, 1, sizeof header, f);
    fwrite(&n, 4, 1, f);
    for (uint32_t t = 0; t < n; t++) {
        float v[12] = {0, 0, 1, (float)t, 0, 0, (float)t + 1, 0, 0, (float)t, 1, 0};
        if (nan && t == n - 1) v[7] = NAN;
        uint16_t attr = 0;
        fwrite(v, sizeof v, 1, f);
        fwrite(&attr, 2, 1, f);
    }
    fclose(f);
}

/* A file that must fail with a message that names it and `expect`. */
static void expect_fail(const char *name, const char *text, const char *expect) {
    if (text) write_text(name, text);
    char p[512];
    tmp_path(p, sizeof p, name);
    mx_mesh m;
    mx_status st = {0};
    int rc = mx_mesh_load(p, &m, &st);
    int ok = rc == -1 && st.code != 0 && strstr(st.msg, name) && strstr(st.msg, expect) && m.pos == NULL;
    printf("hostile %-22s -> %s %s\n", name, st.msg, ok ? "ok" : "FAIL");
    if (!ok) mx_test_failures++;
    if (rc == 0) mx_mesh_free(&m);
}

static void test_hostile(void) {
    expect_fail("empty.obj", "", "holds no OBJ data");
    expect_fail("text.obj", "just some notes\n", "holds no OBJ data"); /* a text file renamed .obj */
    expect_fail("verts_only.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces");
    expect_fail("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite");
    expect_fail("inf.obj", "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite");
    expect_fail("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range");
    expect_fail("neg_range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", "bad face corner");
    expect_fail("zero_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "bad face corner");
    expect_fail("uv_range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n", "texcoord index");
    expect_fail("line_face.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", "corners");
    expect_fail("garbage.obj", "v 0 zero 0\n", "bad number");
    expect_fail("huge_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n", "bad face corner");
    expect_fail("bad.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n", "cannot read");
    expect_fail("missing.obj", NULL, "cannot open");
    expect_fail("mesh.xyz", "1 2 3\n", "unknown mesh format");
    /* OFF counts are checked before OpenMesh reserves room for them (fuzz_meshio: an 11.9 GB reserve) */
    expect_fail("many.off", "OFF\n3000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "declares 3000000 vertices");
    expect_fail("shifted.off", "OFF\n3 1 0 7\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "counts missing");
    expect_fail("short_vertex.off", "OFF\n3 1 0\n0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "vertex 0");
    expect_fail("face_colour.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 255 0 0\n", "face 0");
    expect_fail("one_line.off", "COFF 0 0 0\n", "line of their own");
    expect_fail("empty.off", "OFF\n0 0 0\n", "no faces");
    expect_fail("signed.off", "OFF\n+3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "counts missing");
    /* Non-finite and absurd coordinates, whatever the format (issue 24 item 10) */
    const char *ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    char ply[512];
    snprintf(ply, sizeof ply, "%snan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ply_head);
    expect_fail("nan.ply", ply, "non-finite coordinate");
    snprintf(ply, sizeof ply, "%s1e39 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ply_head);
    expect_fail("overflow.ply", ply, "non-finite coordinate");
    expect_fail("inf.stl", "solid t\nfacet normal 0 0 1\nouter loop\nvertex inf 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
                           "endloop\nendfacet\nendsolid t\n", "non-finite coordinate");
    write_binary_stl("nan_bin.stl", 4, 1);
    expect_fail("nan_bin.stl", NULL, "non-finite coordinate");
    expect_fail("huge.obj", "v 3e38 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "coordinate out of range");
    expect_fail("huge.off", "OFF\n3 1 0\n0 0 -3e38\n1 0 0\n0 1 0\n3 0 1 2\n", "coordinate out of range");
    /* What the file is, when it is not the mesh its name says (issue 24 item 11) */
    static const char png_magic[] = "\x89PNG\r\n\x1a\n\x01\x02";
    expect_fail("image.obj", png_magic, "a PNG image, not an OBJ mesh");
    expect_fail("image.glb", png_magic, "a PNG image, not a glTF mesh");
    expect_fail("jpeg.stl", "\xff\xd8\xff\xe0 JFIF", "a JPEG image, not an STL mesh");
    expect_fail("zip.ply", "PK\x03\x04 zip", "a zip archive, not a PLY mesh");
    expect_fail("ply_named.obj", ply, "a PLY mesh, not an OBJ mesh");
    expect_fail("glb_named.off", "glTF\x02", "a binary glTF (GLB) mesh, not an OFF mesh");
    expect_fail("cube.txt", "v 0 0 0\n", ".obj .ply .off .stl .gltf .glb");
    expect_fail("noext", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "no file extension");
    snprintf(ply, sizeof ply, "%s0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", ply_head);
    expect_fail("plymesh", ply, "no file extension (its content is a PLY mesh");
    char dir[512];
    tmp_path(dir, sizeof dir, "folder.obj");
    CHECK(mkdir(dir, 0700) == 0);
    expect_fail("folder.obj", NULL, "is a directory, not a mesh file");
    /* A binary STL without NaN still loads: 4 triangles stay 4 */
    write_binary_stl("four.stl", 4, 0);
    tmp_path(dir, sizeof dir, "four.stl");
    mx_mesh b;
    mx_status bst;
    CHECK(mx_mesh_load(dir, &b, &bst) == 0 && b.nfaces == 4);
    if (b.pos) mx_mesh_free(&b);
    /* A missing MTL is a warning; degenerate faces load and are counted. */
    write_text("degen.obj", "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\nf 1 2 4\n");
    char p[512];
    tmp_path(p, sizeof p, "degen.obj");
    mx_mesh m;
    mx_status st;
    int rc = mx_mesh_load(p, &m, &st);
    CHECK(rc == 0);
    if (rc == 0) {
        mx_mesh_topology t;
        CHECK(mx_mesh_topology_compute(&m, 0, &t, NULL, &st) == 0);
        CHECK(t.degenerate_faces == 2 && m.nmat == 1 && m.mats[0].texture_path[0] == 0);
        mx_mesh_free(&m);
    }
    /* In-memory validation: NaN and out-of-range indices in a hand-built mesh. */
    float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    int32_t faces[3] = {0, 1, 2};
    mx_material mat = {.name = "m"};
    mx_mesh h = {.nverts = 3, .nfaces = 1, .pos = pos, .faces = faces, .nmat = 1, .mats = &mat};
    CHECK(mx_mesh_validate(&h, &st) == 0);
    faces[2] = 3;
    CHECK(mx_mesh_validate(&h, &st) == -1 && strstr(st.msg, "out of range"));
    faces[2] = 2;
    pos[4] = NAN;
    CHECK(mx_mesh_validate(&h, &st) == -1 && strstr(st.msg, "non-finite coordinate"));
    pos[4] = -1e30f;
    CHECK(mx_mesh_validate(&h, &st) == -1 && strstr(st.msg, "coordinate out of range"));
    h.nfaces = 0;
    CHECK(mx_mesh_validate(&h, &st) == -1 && strstr(st.msg, "empty"));
}

/* OFF, STL and PLY go through OpenMesh: polygons triangulated, STL corners welded, PLY uv kept. */
static void test_openmesh_formats(void) {
    write_text("quad.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n");
    write_text("two.stl", "solid t\n"
                          "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nendloop\nendfacet\n"
                          "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\n"
                          "endsolid t\n");
    write_text("uv.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                         "property float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\n"
                         "end_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 0.5\n3 0 1 2\n");
    const char *names[] = {"quad.off", "two.stl", "uv.ply"};
    const int want_v[] = {4, 4, 3}, want_f[] = {2, 2, 1}, want_uv[] = {0, 0, 1};
    for (int i = 0; i < 3; i++) {
        char p[512];
        tmp_path(p, sizeof p, names[i]);
        mx_mesh m;
        mx_status st;
        if (mx_mesh_load(p, &m, &st)) {
            printf("FAIL %s: %s\n", names[i], st.msg);
            mx_test_failures++;
            continue;
        }
        mx_mesh_topology t;
        CHECK(mx_mesh_topology_compute(&m, 0, &t, NULL, &st) == 0 && t.degenerate_faces == 0);
        int ok = m.nverts == want_v[i] && m.nfaces == want_f[i] && (m.face_uv != NULL) == want_uv[i];
        if (want_uv[i]) ok &= m.uv[2 * 2 + 1] == 0.5f && m.uv[2 * 1] == 1.f;
        printf("%-10s v=%d f=%d uv=%d %s\n", names[i], m.nverts, m.nfaces, m.face_uv != NULL, ok ? "ok" : "FAIL");
        if (!ok) mx_test_failures++;
        mx_mesh_free(&m);
    }
}

static void test_normalize(void) {
    float pos[12] = {1, 2, 10, 3, 2, 10, 1, 6, 10, 1, 2, 14};
    int32_t faces[6] = {0, 1, 2, 0, 2, 3};
    mx_material mat = {.name = "m"};
    mx_mesh m = {.nverts = 4, .nfaces = 2, .pos = pos, .faces = faces, .nmat = 1, .mats = &mat};
    mx_status st;
    float *p, c[3], s;
    CHECK(mx_mesh_normalized(&m, MX_UP_Y, &p, c, &s, &st) == 0);
    double rmax = 0, lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
    for (int v = 0; v < 4; v++) {
        double r = 0;
        for (int k = 0; k < 3; k++) {
            r += (double)p[3 * v + k] * p[3 * v + k];
            lo[k] = fmin(lo[k], p[3 * v + k]);
            hi[k] = fmax(hi[k], p[3 * v + k]);
        }
        rmax = fmax(rmax, sqrt(r));
    }
    CHECK(fabs(rmax - 1) < 1e-6);
    for (int k = 0; k < 3; k++) CHECK(fabs(lo[k] + hi[k]) < 1e-6);
    CHECK(c[0] == 2 && c[1] == 4 && c[2] == 12);
    CHECK(pos[0] == 1 && pos[11] == 14); /* the mesh is untouched */
    free(p);
    /* z-up: the vertex highest in z ends highest in y. */
    CHECK(mx_mesh_normalized(&m, MX_UP_Z, &p, NULL, NULL, &st) == 0);
    CHECK(p[3 * 3 + 1] > p[1] && p[3 * 3 + 1] > p[3 * 2 + 1] && fabsf(p[3 * 2 + 2] - p[2]) > 0.5f);
    free(p);
    float *n;
    CHECK(mx_mesh_face_normals(&m, pos, &n, &st) == 0);
    CHECK(n[0] == 0 && n[1] == 0 && n[2] == 1); /* triangle in z = 10, counter-clockwise from +z */
    free(n);
}

static uint32_t crc32_of(const unsigned char *p, size_t n) {
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    }
    return c ^ 0xFFFFFFFFu;
}

/* A PNG whose IHDR (CRC intact) declares 16000 x 16000 pixels for its few bytes of image data
 * is refused before the reader allocates them. `png`: a valid small PNG (IHDR first). */
static void check_inflated_png(const unsigned char *png, size_t len) {
    unsigned char *p = malloc(len);
    mx_status st;
    mx_image back;
    CHECK(p && len > 33 && !memcmp(png + 12, "IHDR", 4));
    if (!p || len <= 33) {
        free(p);
        return;
    }
    memcpy(p, png, len);
    const unsigned char side[4] = {0, 0, 0x3E, 0x80}; /* 16000, big-endian */
    memcpy(p + 16, side, 4);
    memcpy(p + 20, side, 4);
    uint32_t crc = crc32_of(p + 12, 17);
    for (int i = 0; i < 4; i++) p[29 + i] = (unsigned char)(crc >> (24 - 8 * i));
    CHECK(mx_io_decode_image(p, len, "inflated png", &back, &st) == -1 &&
          strstr(st.msg, "inflated png: PNG declares 16000x16000 pixels") && back.data == NULL);
    free(p);
}

/* An EXR header is checked before OpenEXR sees it: an attribute declaring more bytes than the
 * file holds (OpenEXR would allocate them: 2 GB for this 40-byte file, found by fuzz_image), a
 * value shorter than its type, an offset table longer than the file. `good`: a valid EXR (written by mx_io_write_exr). */
static void check_hostile_exr(const char *good) {
    static const unsigned char huge_attr[] = "v/1\x01\x02\0\0\0capDate\0string\0\xff\xff\xff\x7f" "0123456789";
    char p[512];
    mx_status st;
    mx_image back;
    tmp_path(p, sizeof p, "huge_attribute.exr");
    FILE *f = fopen(p, "wb");
    CHECK(f && fwrite(huge_attr, 1, sizeof huge_attr - 1, f) == sizeof huge_attr - 1 && !fclose(f));
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "huge_attribute.exr: EXR attribute 'capDate'") &&
          back.data == NULL);
    /* a float of 0 bytes: OpenEXR would read 4 and lose its place in the header */
    static const unsigned char short_float[] = "v/1\x01\x02\0\0\0pixelAspectRatio\0float\0\0\0\0\0\0" "0123456789";
    tmp_path(p, sizeof p, "short_float.exr");
    f = fopen(p, "wb");
    CHECK(f && fwrite(short_float, 1, sizeof short_float - 1, f) == sizeof short_float - 1 && !fclose(f));
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "corrupt EXR attribute 'pixelAspectRatio'") &&
          back.data == NULL);
    /* ZIP (16 lines a block), lines 0..16000, no offset table */
    unsigned char tall[] = "v/1\x01\x02\0\0\0compression\0compression\0\x01\0\0\0\x03"
                                        "dataWindow\0box2i\0\x10\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\x80\x3e\0\0\0" "0123456789";
    tmp_path(p, sizeof p, "tall.exr");
    f = fopen(p, "wb");
    CHECK(f && fwrite(tall, 1, sizeof tall - 1, f) == sizeof tall - 1 && !fclose(f));
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "tall.exr: truncated EXR (1001 scan-line blocks") &&
          back.data == NULL);
    tall[sizeof tall - 14] = 0x40; /* lines 0..0x403e80: too many for any texture */
    f = fopen(p, "wb");
    CHECK(f && fwrite(tall, 1, sizeof tall - 1, f) == sizeof tall - 1 && !fclose(f));
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "tall.exr: unsupported image size 1x4210305") &&
          back.data == NULL);
    /* 16000 x 16000 in 1 x 1 tiles: a 2 GB tile offset table */
    static const unsigned char tiny_tiles[] = "v/1\x01\x02\x02\0\0tiles\0tiledesc\0\x09\0\0\0\x01\0\0\0\x01\0\0\0\0"
                                              "dataWindow\0box2i\0\x10\0\0\0\0\0\0\0\0\0\0\0\x7f\x3e\0\0\x7f\x3e\0\0\0"
                                              "0123456789";
    tmp_path(p, sizeof p, "tiles.exr");
    f = fopen(p, "wb");
    CHECK(f && fwrite(tiny_tiles, 1, sizeof tiny_tiles - 1, f) == sizeof tiny_tiles - 1 && !fclose(f));
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "tiles.exr: truncated EXR (256000000 tile blocks") &&
          back.data == NULL);
    CHECK(mx_io_read_image(good, &back, &st) == 0); /* the checks pass a valid file */
    mx_image_free(&back);
}

static void test_images(void) {
    mx_image img, back;
    mx_status st;
    CHECK(mx_image_alloc(&img, 7, 5, 3, &st) == 0);
    for (int i = 0; i < 7 * 5 * 3; i++) img.data[i] = (float)(i % 11) / 10.f;
    img.data[0] = -0.5f; /* clamped */
    char p[512];
    tmp_path(p, sizeof p, "img.png");
    CHECK(mx_io_write_png(p, &img, &st) == 0);
    CHECK(mx_io_read_image(p, &back, &st) == 0);
    CHECK(back.w == 7 && back.h == 5 && back.c == 3);
    float maxerr = 0;
    for (int i = 0; back.data && i < 7 * 5 * 3; i++) {
        float want = fminf(fmaxf(img.data[i], 0.f), 1.f);
        maxerr = fmaxf(maxerr, fabsf(back.data[i] - want));
    }
    CHECK(maxerr <= 0.5f / 255.f + 1e-6f);
    mx_image_free(&back);
    unsigned char *bytes;
    size_t len;
    CHECK(mx_io_encode_png(&img, &bytes, &len, &st) == 0 && len > 8 && !memcmp(bytes, "\x89PNG", 4));
    CHECK(mx_io_decode_image(bytes, len, "memory", &back, &st) == 0 && back.w == 7 && back.h == 5);
    mx_image_free(&back);
    CHECK(mx_io_decode_image(bytes, len / 2, "half png", &back, &st) == -1 && strstr(st.msg, "half png: truncated"));
    check_inflated_png(bytes, len);
    free(bytes);
    CHECK(mx_io_decode_image("GIF89a", 6, "gif bytes", &back, &st) == -1 && strstr(st.msg, "not a PNG"));
    tmp_path(p, sizeof p, "img.exr");
    img.data[0] = 3.25f; /* float EXR keeps values outside [0,1] */
    CHECK(mx_io_write_exr(p, &img, 1, &st) == 0);
    CHECK(mx_io_read_image(p, &back, &st) == 0 && back.w == 7 && back.c == 3);
    CHECK(back.data && !memcmp(back.data, img.data, sizeof(float) * 7 * 5 * 3));
    mx_image_free(&back);
    check_hostile_exr(p);
    tmp_path(p, sizeof p, "not_an_image.png");
    write_text("not_an_image.png", "hello");
    CHECK(mx_io_read_image(p, &back, &st) == -1 && strstr(st.msg, "not_an_image.png") && back.data == NULL);
    tmp_path(p, sizeof p, "no_such_dir/x.png");
    CHECK(mx_io_write_png(p, &img, &st) == -1 && st.code == MX_EIO);
    mx_image_free(&img);
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR); /* the hostile files warn on purpose */
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_meshio_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    for (size_t i = 0; i < sizeof assets / sizeof assets[0]; i++) check_asset(&assets[i]);
    test_obj_features();
    test_hostile();
    test_openmesh_formats();
    test_normalize();
    test_images();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) printf("warning: could not remove %s\n", tmpdir);
    return mx_test_finish("test_io_meshio");
}
