/* glTF/GLB import: node transforms, UV flip, partial UVs, embedded textures on the shared
 * assets; hand-made hostile files (bogus offsets, out-of-range indices, cycles, truncated and
 * corrupted GLBs) end in a clear error, never a crash. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/geom/image.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/io/gltf.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/fileio.h"
#include "../runtime/log.h"
#include "util_test.h"

static char tmpdir[256];

static void tmp_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmpdir, name); }

static void write_bytes(const char *name, const void *data, size_t n) {
    char p[512];
    tmp_path(p, sizeof p, name);
    FILE *f = fopen(p, "wb");
    if (!f || fwrite(data, 1, n, f) != n) {
        perror(p);
        exit(2);
    }
    fclose(f);
}

/* The whole file (NULL when it cannot be read). */
static unsigned char *read_all(const char *path, size_t *n) {
    mx_status st;
    return (unsigned char *)mx_read_file(path, (size_t)1 << 30, n, &st);
}

/* The binary buffer of the hand-made files: 3 positions (36 bytes), 3 UVs (24), 3 uint16 indices (6+2). */
static void write_bin(void) {
    float buf[3 * 3 + 3 * 2 + 2];
    const float pos[9] = {1, 0, 0, 0, 1, 0, 0, 0, 0}, uv[6] = {0, 0, 1, 0, 0, 0.25f};
    memcpy(buf, pos, sizeof pos);
    memcpy(buf + 9, uv, sizeof uv);
    uint16_t idx[4] = {0, 1, 2, 0};
    memcpy(buf + 15, idx, sizeof idx);
    write_bytes("tri.bin", buf, sizeof buf);
}

/* A glTF document around tri.bin; the %s fields let each test break one thing. */
static void make_gltf(char *text, size_t cap, const char *nodes, const char *accessor_extra, const char *view0,
                      const char *buffer) {
    snprintf(text, cap,
             "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":%s,"
             "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"indices\":2}]}],"
             "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"%s},"
             "{\"bufferView\":1,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
             "{\"bufferView\":2,\"componentType\":5123,\"count\":3,\"type\":\"SCALAR\"}],"
             "\"bufferViews\":[%s,{\"buffer\":0,\"byteOffset\":36,\"byteLength\":24},"
             "{\"buffer\":0,\"byteOffset\":60,\"byteLength\":6}],\"buffers\":[%s]}",
             nodes, accessor_extra, view0, buffer);
}

static void write_gltf(const char *name, const char *nodes, const char *accessor_extra, const char *view0,
                       const char *buffer) {
    char text[4096];
    make_gltf(text, sizeof text, nodes, accessor_extra, view0, buffer);
    write_bytes(name, text, strlen(text));
}

#define GOOD_VIEW "{\"buffer\":0,\"byteLength\":36}"
#define GOOD_BUFFER "{\"uri\":\"tri.bin\",\"byteLength\":68}"

static void test_transforms(void) {
    /* parent: translation (1,2,3), scale 2; child: 90 degrees about z, holds the mesh. */
    write_gltf("tf.gltf",
               "[{\"translation\":[1,2,3],\"scale\":[2,2,2],\"children\":[1]},"
               "{\"rotation\":[0,0,0.70710678,0.70710678],\"mesh\":0}]",
               "", GOOD_VIEW, GOOD_BUFFER);
    char p[512];
    tmp_path(p, sizeof p, "tf.gltf");
    mx_mesh m;
    mx_status st;
    int rc = mx_mesh_load(p, &m, &st);
    CHECK(rc == 0);
    if (rc) {
        printf("tf.gltf: %s\n", st.msg);
        return;
    }
    /* R(90 about z): (1,0,0) -> (0,1,0), (0,1,0) -> (-1,0,0); then *2 + (1,2,3). */
    const float want[9] = {1, 4, 3, -1, 2, 3, 1, 2, 3};
    float err = 0;
    for (int i = 0; i < 9; i++) err = fmaxf(err, fabsf(m.pos[i] - want[i]));
    CHECK(m.nverts == 3 && m.nfaces == 1 && err < 1e-5f);
    CHECK(m.face_uv && m.uv[1] == 1.f && m.uv[5] == 0.75f); /* v flipped to v up */
    CHECK(m.nmat == 1 && !strcmp(m.mats[0].name, "default") && m.face_mat[0] == 0);
    mx_mesh_free(&m);
    /* A mirroring matrix (x -> -x) flips the winding back to counter-clockwise. */
    write_gltf("mirror.gltf", "[{\"matrix\":[-1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],\"mesh\":0}]", "", GOOD_VIEW,
               GOOD_BUFFER);
    tmp_path(p, sizeof p, "mirror.gltf");
    rc = mx_mesh_load(p, &m, &st);
    CHECK(rc == 0);
    if (rc == 0) {
        CHECK(m.pos[0] == -1.f && m.faces[0] == 0 && m.faces[1] == 2 && m.faces[2] == 1);
        mx_mesh_free(&m);
    }
}

static void expect_fail(const char *name, const char *expect) {
    char p[512];
    tmp_path(p, sizeof p, name);
    mx_mesh m;
    mx_status st = {0};
    int rc = mx_mesh_load(p, &m, &st);
    int ok = rc == -1 && strstr(st.msg, name) && strstr(st.msg, expect) && m.pos == NULL;
    printf("hostile %-20s -> %s %s\n", name, st.msg, ok ? "ok" : "FAIL");
    if (!ok) mx_test_failures++;
    if (rc == 0) mx_mesh_free(&m);
}

static void test_hostile_gltf(void) {
    const char *node = "[{\"mesh\":0}]";
    write_gltf("acc_off.gltf", node, ",\"byteOffset\":4000", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("acc_off.gltf", "overrun");
    write_gltf("acc_count.gltf", node, ",\"byteOffset\":4", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("acc_count.gltf", "overrun");
    write_gltf("view_off.gltf", node, "", "{\"buffer\":0,\"byteOffset\":60,\"byteLength\":36}", GOOD_BUFFER);
    expect_fail("view_off.gltf", "outside buffer");
    write_gltf("view_buf.gltf", node, "", "{\"buffer\":7,\"byteLength\":36}", GOOD_BUFFER);
    expect_fail("view_buf.gltf", "buffer");
    write_gltf("neg_off.gltf", node, ",\"byteOffset\":-8", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("neg_off.gltf", "byteOffset");
    write_gltf("buf_len.gltf", node, "", GOOD_VIEW, "{\"uri\":\"tri.bin\",\"byteLength\":6800}");
    expect_fail("buf_len.gltf", "byteLength");
    write_gltf("no_bin.gltf", node, "", GOOD_VIEW, "{\"uri\":\"nowhere.bin\",\"byteLength\":68}");
    expect_fail("no_bin.gltf", "cannot open");
    write_gltf("cycle.gltf", "[{\"mesh\":0,\"children\":[0]}]", "", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("cycle.gltf", "deeper");
    /* Each node lists the next one 8 times: 8^20 instances unless the loader bounds the work. */
    char dag[4096] = "[";
    for (int i = 0; i < 20; i++) {
        char one[160];
        snprintf(one, sizeof one, "{\"mesh\":0,\"children\":[%d,%d,%d,%d,%d,%d,%d,%d]},", i + 1, i + 1, i + 1, i + 1, i + 1,
                 i + 1, i + 1, i + 1);
        strcat(dag, one);
    }
    strcat(dag, "{\"mesh\":0}]");
    write_gltf("dag.gltf", dag, "", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("dag.gltf", "node instances");
    write_gltf("child.gltf", "[{\"mesh\":0,\"children\":[5]}]", "", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("child.gltf", "out of range");
    write_gltf("mesh_idx.gltf", "[{\"mesh\":3}]", "", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("mesh_idx.gltf", "mesh");
    char text[4096];
    make_gltf(text, sizeof text, node, "", GOOD_VIEW, GOOD_BUFFER);
    memcpy(strstr(text, "5126"), "5130", 4); /* an unknown component type */
    write_bytes("ctype.gltf", text, strlen(text));
    expect_fail("ctype.gltf", "componentType");
    write_gltf("nomesh.gltf", "[{}]", "", GOOD_VIEW, GOOD_BUFFER);
    expect_fail("nomesh.gltf", "no triangles");
    write_bytes("syntax.gltf", "{\"asset\":", 9);
    expect_fail("syntax.gltf", "");
    /* An index past the vertex count: uint16 value 9 in place of 2. */
    unsigned char bin[68];
    char p[512];
    tmp_path(p, sizeof p, "tri.bin");
    size_t n;
    unsigned char *orig = read_all(p, &n);
    CHECK(orig && n == sizeof bin);
    if (!orig) return;
    memcpy(bin, orig, sizeof bin);
    bin[64] = 9;
    write_bytes("bad_idx.bin", bin, sizeof bin);
    write_gltf("bad_idx.gltf", node, "", GOOD_VIEW, "{\"uri\":\"bad_idx.bin\",\"byteLength\":68}");
    expect_fail("bad_idx.gltf", "out of range");
    /* NaN position. */
    memcpy(bin, orig, sizeof bin);
    const float qnan = NAN;
    memcpy(bin + 4, &qnan, 4);
    write_bytes("nan.bin", bin, sizeof bin);
    write_gltf("nan.gltf", node, "", GOOD_VIEW, "{\"uri\":\"nan.bin\",\"byteLength\":68}");
    expect_fail("nan.gltf", "non-finite coordinate");
    free(orig);
}

/* Truncations and byte corruptions of a real GLB: every outcome is a load or a clean error. */
static void test_hostile_glb(void) {
    char src[1024];
    if (!mx_test_need(src, sizeof src, "assets/cesium_milk_truck/CesiumMilkTruck.glb")) return;
    size_t n;
    unsigned char *glb = read_all(src, &n);
    CHECK(glb != NULL);
    if (!glb) return;
    char p[512];
    tmp_path(p, sizeof p, "cut.glb");
    const size_t cuts[] = {0, 3, 11, 12, 19, 20, 100, n / 2, n - 1};
    for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++) {
        write_bytes("cut.glb", glb, cuts[i]);
        mx_mesh m;
        mx_status st = {0};
        int rc = mx_mesh_load(p, &m, &st);
        CHECK(rc == -1 && strstr(st.msg, "cut.glb"));
        if (i == 0 || cuts[i] == n - 1) printf("truncated GLB (%zu bytes) -> %s\n", cuts[i], st.msg);
        if (rc == 0) mx_mesh_free(&m);
    }
    /* Corrupt one 32-bit word of the header/JSON area at a time (deterministic positions). */
    uint32_t json_len = (uint32_t)glb[12] | (uint32_t)glb[13] << 8 | (uint32_t)glb[14] << 16 | (uint32_t)glb[15] << 24;
    unsigned char *bad = malloc(n);
    int loaded = 0, failed = 0;
    uint64_t s = 12345;
    for (int trial = 0; trial < 150 && bad; trial++) {
        memcpy(bad, glb, n);
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        size_t at = (size_t)(s >> 33) % (20 + json_len);
        const char *repl[] = {"9", "-", "\"", "}", "]", "99999999", "\xff"};
        if (at < 20) bad[at] ^= 0x5a;
        else bad[at] = (unsigned char)repl[(s >> 20) % 7][0];
        write_bytes("fuzz.glb", bad, n);
        tmp_path(p, sizeof p, "fuzz.glb");
        mx_mesh m;
        mx_status st = {0};
        if (mx_mesh_load(p, &m, &st) == 0) {
            loaded++;
            mx_mesh_free(&m);
        } else {
            failed++;
            CHECK(st.msg[0] != 0);
        }
    }
    printf("corrupted GLB: %d loaded, %d failed cleanly\n", loaded, failed);
    CHECK(failed > 0);
    free(bad);
    free(glb);
}

static void uv_range(const mx_mesh *m, float r[4], int *with, int *without) {
    r[0] = r[1] = 1e9f;
    r[2] = r[3] = -1e9f;
    *with = *without = 0;
    for (int f = 0; f < m->nfaces; f++) {
        if (m->face_uv[3 * f] < 0) {
            (*without)++;
            continue;
        }
        (*with)++;
        for (int k = 0; k < 3; k++) {
            const float *t = m->uv + 2 * m->face_uv[3 * f + k];
            r[0] = fminf(r[0], t[0]);
            r[1] = fminf(r[1], t[1]);
            r[2] = fmaxf(r[2], t[0]);
            r[3] = fmaxf(r[3], t[1]);
        }
    }
}

/* MANIFEST.md UV ranges are in glTF's own convention (v down): after the flip, v' = 1 - v. */
static void test_assets(void) {
    struct {
        const char *file;
        float range[4];
        int partial;
    } cases[] = {
        {"cesium_milk_truck/CesiumMilkTruck.glb", {0.003f, 0.0091f, 0.9937f, 0.9972f}, 1},
        {"flight_helmet/FlightHelmet.gltf", {0.0071f, 0.0034f, 0.9942f, 0.993f}, 0},
        {"wooden_stool/painted_wooden_stool_1k.gltf", {0.0039f, 0.0039f, 0.9945f, 0.9961f}, 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char path[1024];
        if (!mx_test_need(path, sizeof path, "assets/%s", cases[i].file)) continue;
        mx_mesh m;
        mx_status st;
        if (mx_mesh_load(path, &m, &st)) {
            printf("FAIL %s: %s\n", cases[i].file, st.msg);
            mx_test_failures++;
            continue;
        }
        float r[4];
        int with, without;
        uv_range(&m, r, &with, &without);
        const float *w = cases[i].range;
        int ok = fabsf(r[0] - w[0]) < 1e-3f && fabsf(r[2] - w[2]) < 1e-3f && fabsf(r[1] - (1 - w[3])) < 1e-3f &&
                 fabsf(r[3] - (1 - w[1])) < 1e-3f && (without > 0) == cases[i].partial && with > 0;
        printf("%-44s uv [%.4f %.4f %.4f %.4f] faces with/without uv %d/%d %s\n", cases[i].file, r[0], r[1], r[2], r[3],
               with, without, ok ? "ok" : "FAIL");
        if (!ok) mx_test_failures++;
        mx_mesh_free(&m);
    }
    /* The truck's texture lives inside the GLB: decode it through the "#image0" reference. */
    char path[1024];
    if (!mx_test_need(path, sizeof path, "assets/cesium_milk_truck/CesiumMilkTruck.glb")) return;
    mx_image img;
    mx_status st;
    CHECK(mx_gltf_read_image(path, 0, &img, &st) == 0 && img.w == 2048 && img.h == 2048 && img.c >= 3);
    mx_image_free(&img);
    CHECK(mx_gltf_read_image(path, 7, &img, &st) == -1 && strstr(st.msg, "no such image"));
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_gltf_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    write_bin();
    test_transforms();
    test_hostile_gltf();
    test_hostile_glb();
    test_assets();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) printf("warning: could not remove %s\n", tmpdir);
    return mx_test_finish("test_io_gltf");
}
