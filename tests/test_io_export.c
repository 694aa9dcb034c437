/* Exporters: OBJ and GLB round trips keep positions, faces, UVs and materials; the GLB
 * written is structurally valid glTF 2.0 (chunks, alignment, accessor bounds, POSITION
 * min/max); mx_write_outputs writes the full folder and nothing else. */
#include <dirent.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/geom/image.h"
#include "../pipeline/geom/mesh.h"
#include "../pipeline/io/export.h"
#include "../pipeline/io/io.h"
#include "../pipeline/io/mesh_load.h"
#include "../runtime/fileio.h"
#include "../runtime/json.h"
#include "../runtime/log.h"
#include "util_test.h"

static char tmpdir[256];

static void tmp_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", tmpdir, name); }

static int load_asset(const char *rel, mx_mesh *m) {
    char path[1024];
    mx_status st;
    if (!mx_test_need(path, sizeof path, "assets/%s", rel)) return -1;
    if (mx_mesh_load(path, m, &st) == 0) return 0;
    printf("FAIL load %s: %s\n", rel, st.msg);
    mx_test_failures++;
    return -1;
}

static void make_texture(mx_image *img, int w, int h, float seed) {
    mx_status st;
    if (mx_image_alloc(img, w, h, 3, &st)) exit(2);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++)
                img->data[(y * w + x) * 3 + c] = 0.5f + 0.5f * sinf(seed + 0.3f * x + 0.7f * y + 2.f * c);
}

/* The whole file (NULL when it cannot be read). */
static unsigned char *read_all(const char *path, size_t *n) {
    mx_status st;
    return (unsigned char *)mx_read_file(path, (size_t)1 << 30, n, &st);
}

static int same_ints(const int32_t *a, const int32_t *b, size_t n) { return a && b && !memcmp(a, b, n * sizeof *a); }

/* OBJ keeps the mesh exactly: same arrays, same materials. */
static void test_obj_roundtrip(const char *rel) {
    mx_mesh m, r;
    if (load_asset(rel, &m)) return;
    char path[512];
    tmp_path(path, sizeof path, "rt.obj");
    mx_status st;
    const char *tex[8] = {"a.png", "b.png", "c.png", "d.png", "e.png", "f.png", "g.png", "h.png"};
    int rc = mx_export_obj(path, &m, tex, m.nmat < 8 ? m.nmat : 8, &st);
    CHECK(rc == 0);
    if (rc == 0 && mx_mesh_load(path, &r, &st) == 0) {
        int ok = r.nverts == m.nverts && r.nfaces == m.nfaces && r.nuv == m.nuv && r.nnrm == m.nnrm &&
                 !memcmp(r.pos, m.pos, sizeof(float) * 3 * (size_t)m.nverts) &&
                 same_ints(r.faces, m.faces, 3 * (size_t)m.nfaces) && r.nmat == m.nmat;
        if (m.nuv) ok &= !memcmp(r.uv, m.uv, sizeof(float) * 2 * (size_t)m.nuv) && same_ints(r.face_uv, m.face_uv, 3 * (size_t)m.nfaces);
        if (m.nnrm) ok &= !memcmp(r.nrm, m.nrm, sizeof(float) * 3 * (size_t)m.nnrm);
        if (m.nmat > 1) ok &= same_ints(r.face_mat, m.face_mat, (size_t)m.nfaces);
        for (int i = 0; i < m.nmat && i < r.nmat; i++) ok &= !strcmp(r.mats[i].name, m.mats[i].name);
        printf("OBJ round trip %-40s %s\n", rel, ok ? "ok" : "FAIL");
        if (!ok) mx_test_failures++;
        mx_mesh_free(&r);
    } else {
        printf("OBJ round trip %s: %s\n", rel, st.msg);
        mx_test_failures++;
    }
    mx_mesh_free(&m);
}

/* Corner-wise comparison: GLB splits vertices, so indices differ but each corner's data must not. */
static int same_corners(const mx_mesh *a, const mx_mesh *b, float *max_uv_err) {
    if (a->nfaces != b->nfaces) return 0;
    *max_uv_err = 0;
    for (int i = 0; i < 3 * a->nfaces; i++) {
        if (memcmp(a->pos + 3 * a->faces[i], b->pos + 3 * b->faces[i], 3 * sizeof(float))) return 0;
        if ((a->face_mat ? a->face_mat[i / 3] : 0) != (b->face_mat ? b->face_mat[i / 3] : 0)) return 0;
        if (a->face_uv && a->face_uv[i] >= 0) {
            if (!b->face_uv || b->face_uv[i] < 0) return 0;
            for (int k = 0; k < 2; k++)
                *max_uv_err = fmaxf(*max_uv_err, fabsf(a->uv[2 * a->face_uv[i] + k] - b->uv[2 * b->face_uv[i] + k]));
        }
    }
    return 1;
}

/* Reads accessor/view/buffer numbers; returns 0 when all bounds hold. */
static int check_accessor(const mx_json *doc, const mx_json *acc, size_t bin_len, const unsigned char *bin) {
    static const int comps[] = {0, 1, 2, 3, 4};
    const char *type = mx_json_get_str(acc, "type", "");
    int nc = !strcmp(type, "SCALAR") ? comps[1] : !strcmp(type, "VEC2") ? comps[2] : !strcmp(type, "VEC3") ? comps[3] : 0;
    int ct = (int)mx_json_get_num(acc, "componentType", 0);
    size_t csize = ct == 5126 || ct == 5125 ? 4 : 0;
    size_t count = (size_t)mx_json_get_num(acc, "count", 0), aoff = (size_t)mx_json_get_num(acc, "byteOffset", 0);
    size_t vi = (size_t)mx_json_get_num(acc, "bufferView", -1);
    const mx_json *views = mx_json_get(doc, "bufferViews");
    if (!nc || !csize || !count || vi >= mx_json_len(views)) return -1;
    const mx_json *v = mx_json_at(views, vi);
    size_t voff = (size_t)mx_json_get_num(v, "byteOffset", 0), vlen = (size_t)mx_json_get_num(v, "byteLength", 0);
    size_t stride = (size_t)mx_json_get_num(v, "byteStride", 0), elem = csize * (size_t)nc;
    if (!stride) stride = elem;
    if (voff % 4 || voff + vlen > bin_len || aoff + stride * (count - 1) + elem > vlen) return -1;
    const mx_json *mn = mx_json_get(acc, "min"), *mx = mx_json_get(acc, "max");
    if (mn && mx && ct == 5126) { /* min/max must be the exact bounds of the data */
        for (int k = 0; k < nc; k++) {
            float lo = INFINITY, hi = -INFINITY;
            for (size_t i = 0; i < count; i++) {
                float x;
                memcpy(&x, bin + voff + aoff + i * stride + 4 * (size_t)k, 4);
                lo = fminf(lo, x);
                hi = fmaxf(hi, x);
            }
            if ((float)mx_json_num(mx_json_at(mn, (size_t)k)) != lo || (float)mx_json_num(mx_json_at(mx, (size_t)k)) != hi)
                return -1;
        }
    }
    return 0;
}

static uint32_t u32(const unsigned char *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* Structural validation of a GLB per the glTF 2.0 spec (section 4.4 and accessor rules). */
static void check_glb_structure(const char *path, int want_images) {
    size_t n;
    unsigned char *f = read_all(path, &n);
    CHECK(f && n >= 28);
    if (!f || n < 28) return;
    uint32_t jlen = u32(f + 12), blen = n >= 28 + jlen ? u32(f + 20 + jlen) : 0;
    int ok = u32(f) == 0x46546C67u && u32(f + 4) == 2 && u32(f + 8) == n && u32(f + 16) == 0x4E4F534Au && jlen % 4 == 0 &&
             28 + (size_t)jlen <= n && u32(f + 24 + jlen) == 0x004E4942u && blen % 4 == 0 && 28 + jlen + blen == n;
    CHECK(ok);
    mx_status st;
    mx_json *doc = ok ? mx_json_parse((const char *)f + 20, jlen, path, &st) : NULL;
    CHECK(doc != NULL);
    if (doc) {
        const mx_json *accs = mx_json_get(doc, "accessors"), *bufs = mx_json_get(doc, "buffers");
        CHECK(!strcmp(mx_json_get_str(mx_json_get(doc, "asset"), "version", ""), "2.0"));
        CHECK(mx_json_len(bufs) == 1 && (size_t)mx_json_get_num(mx_json_at(bufs, 0), "byteLength", 0) <= blen &&
              (size_t)mx_json_get_num(mx_json_at(bufs, 0), "byteLength", 0) + 3 >= blen);
        int bad = 0;
        for (size_t i = 0; i < mx_json_len(accs); i++) bad += check_accessor(doc, mx_json_at(accs, i), blen, f + 28 + jlen) != 0;
        CHECK(bad == 0 && mx_json_len(accs) >= 3);
        const mx_json *prim = mx_json_at(mx_json_get(mx_json_at(mx_json_get(doc, "meshes"), 0), "primitives"), 0);
        const mx_json *pos = mx_json_at(accs, (size_t)mx_json_get_num(mx_json_get(prim, "attributes"), "POSITION", -1));
        CHECK(pos && mx_json_get(pos, "min") && mx_json_get(pos, "max"));
        CHECK((int)mx_json_len(mx_json_get(doc, "images")) == want_images);
        printf("GLB structure %s: %zu bytes, %zu accessors, %d images %s\n", path, n, mx_json_len(accs), want_images,
               ok && !bad ? "ok" : "FAIL");
        mx_json_free(doc);
    }
    free(f);
}

static void test_glb_roundtrip(const char *rel, int ntex) {
    mx_mesh m, r;
    if (load_asset(rel, &m)) return;
    mx_image tex[8];
    for (int i = 0; i < ntex; i++) make_texture(&tex[i], 32 + 8 * i, 24, (float)i);
    char path[512];
    tmp_path(path, sizeof path, "rt.glb");
    mx_status st;
    double t0 = mx_now();
    int rc = mx_export_glb(path, &m, tex, ntex, &st);
    double t1 = mx_now();
    CHECK(rc == 0);
    if (rc) printf("GLB export: %s\n", st.msg);
    if (rc == 0) check_glb_structure(path, ntex);
    if (rc == 0 && mx_mesh_load(path, &r, &st) == 0) {
        float uv_err = 0;
        int ok = same_corners(&m, &r, &uv_err) && uv_err <= 1e-6f && r.nmat == m.nmat;
        mx_image back[8];
        CHECK(r.nmat <= 8 && mx_mesh_load_textures(&r, back, &st) == 0);
        for (int i = 0; i < r.nmat && i < 8; i++) {
            if (i < ntex) { /* 8-bit PNG: within half a code value */
                float err = back[i].w == tex[i].w && back[i].h == tex[i].h && back[i].c == 3 ? 0 : 1;
                for (int k = 0; !err && k < tex[i].w * tex[i].h * 3; k++) err = fmaxf(err, fabsf(back[i].data[k] - tex[i].data[k]));
                ok &= err <= 0.5f / 255 + 1e-6f;
            } else {
                ok &= back[i].data == NULL;
            }
            mx_image_free(&back[i]);
        }
        printf("GLB round trip %-40s uv err %.2g, export %.0f ms %s\n", rel, uv_err, 1000 * (t1 - t0), ok ? "ok" : "FAIL");
        if (!ok) mx_test_failures++;
        mx_mesh_free(&r);
    } else if (rc == 0) {
        printf("GLB reload: %s\n", st.msg);
        mx_test_failures++;
    }
    for (int i = 0; i < ntex; i++) mx_image_free(&tex[i]);
    mx_mesh_free(&m);
}

static int exists(const char *dir, const char *name) {
    char p[1024];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    return access(p, F_OK) == 0;
}

static int count_tmp_files(const char *dir) {
    DIR *d = opendir(dir);
    if (!d) return -1;
    int c = 0;
    for (struct dirent *e; (e = readdir(d));) c += strstr(e->d_name, ".tmp") != NULL;
    closedir(d);
    return c;
}

static void test_write_outputs(void) {
    mx_mesh m;
    if (load_asset("cesium_milk_truck/CesiumMilkTruck.glb", &m)) return;
    mx_image tex[4];
    for (int i = 0; i < 4; i++) make_texture(&tex[i], 16, 16, (float)i);
    mx_status st;
    char dir[512];
    /* One shared texture. */
    tmp_path(dir, sizeof dir, "out1");
    int rc = mx_write_outputs(dir, &m, tex, 1, "{\"views\":6}", &st);
    CHECK(rc == 0);
    if (rc) printf("write_outputs: %s\n", st.msg);
    CHECK(exists(dir, "texture.png") && exists(dir, "texture.exr") && exists(dir, "mesh.obj") && exists(dir, "mesh.mtl") &&
          exists(dir, "mesh.glb") && exists(dir, "report.json") && !exists(dir, "texture_truck.png"));
    CHECK(count_tmp_files(dir) == 0);
    char p[600];
    snprintf(p, sizeof p, "%s/mesh.obj", dir);
    mx_mesh r;
    if (mx_mesh_load(p, &r, &st) == 0) {
        CHECK(r.nmat == 1 && strstr(r.mats[0].texture_path, "texture.png") && r.nfaces == m.nfaces);
        mx_mesh_free(&r);
    } else {
        CHECK(!"reload mesh.obj");
    }
    /* One texture per material. */
    tmp_path(dir, sizeof dir, "out4");
    rc = mx_write_outputs(dir, &m, tex, 4, NULL, &st);
    CHECK(rc == 0);
    const char *mats[4] = {"truck", "glass", "window_trim", "wheels"};
    for (int i = 0; i < 4; i++) {
        char name[64];
        snprintf(name, sizeof name, "texture_%s.png", mats[i]);
        CHECK(exists(dir, name));
        snprintf(name, sizeof name, "texture_%s.exr", mats[i]);
        CHECK(exists(dir, name));
    }
    CHECK(!exists(dir, "texture.png") && !exists(dir, "texture.exr")); /* no copy of one material's texture */
    snprintf(p, sizeof p, "%s/mesh.glb", dir);
    check_glb_structure(p, 4);
    snprintf(p, sizeof p, "%s/mesh.obj", dir);
    if (mx_mesh_load(p, &r, &st) == 0) {
        CHECK(r.nmat == 4 && strstr(r.mats[3].texture_path, "texture_wheels.png"));
        mx_mesh_free(&r);
    }
    /* Bad calls: wrong texture count, a folder that cannot be created. */
    CHECK(mx_write_outputs(dir, &m, tex, 3, NULL, &st) == -1 && strstr(st.msg, "3 textures for 4 materials"));
    CHECK(mx_write_outputs("/proc/matex_no/such", &m, tex, 1, NULL, &st) == -1 && st.code == MX_EIO);
    for (int i = 0; i < 4; i++) mx_image_free(&tex[i]);
    mx_mesh_free(&m);
}

int main(void) {
    mx_log_set_level(MX_LOG_ERROR);
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_export_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    test_obj_roundtrip("bob/bob_tri.obj");                       /* uv + normals */
    test_obj_roundtrip("flight_helmet/FlightHelmet.gltf");       /* 6 materials */
    test_obj_roundtrip("garment_female_casual/female_casualsuit01.obj");
    test_glb_roundtrip("spot/spot_triangulated.obj", 1);
    test_glb_roundtrip("cesium_milk_truck/CesiumMilkTruck.glb", 4); /* partial UVs, mirrored nodes */
    test_glb_roundtrip("flight_helmet/FlightHelmet.gltf", 3);       /* materials 3..5 untextured */
    test_write_outputs();
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    if (system(cmd) != 0) printf("warning: could not remove %s\n", tmpdir);
    return mx_test_finish("test_io_export");
}
