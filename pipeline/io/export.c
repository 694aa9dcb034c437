/* Exporters (pipeline/io/export.h): OBJ + MTL, GLB 2.0 with embedded PNGs, output folder. */
#include "export.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../../runtime/atomic_file.h"
#include "../../runtime/buf.h"
#include "../../runtime/fileio.h"
#include "io.h"

/* ---- a growable byte buffer (JSON text and the GLB BIN chunk) ---- */

typedef mx_buf bytes;

static void pad4(bytes *b, unsigned char fill) {
    while (b->len % 4 && !b->oom) mx_buf_put(b, &fill, 1); /* a failed buffer no longer grows */
}

/* ---- OBJ + MTL ---- */

static int face_has_all(const int32_t *idx, int f) {
    return idx && idx[3 * f] >= 0 && idx[3 * f + 1] >= 0 && idx[3 * f + 2] >= 0;
}

static void obj_corner(bytes *b, const mx_mesh *m, int f, int k) {
    int v = m->faces[3 * f + k] + 1;
    int has_uv = face_has_all(m->face_uv, f), has_n = face_has_all(m->face_nrm, f);
    if (has_uv && has_n) mx_buf_printf(b, " %d/%d/%d", v, m->face_uv[3 * f + k] + 1, m->face_nrm[3 * f + k] + 1);
    else if (has_uv) mx_buf_printf(b, " %d/%d", v, m->face_uv[3 * f + k] + 1);
    else if (has_n) mx_buf_printf(b, " %d//%d", v, m->face_nrm[3 * f + k] + 1);
    else mx_buf_printf(b, " %d", v);
}

static void mtl_text(bytes *b, const mx_mesh *m, const char *const *texture_files, int ntex) {
    mx_buf_printf(b, "# matex\n");
    for (int i = 0; i < m->nmat; i++) {
        mx_buf_put(b, "newmtl ", 7);
        mx_buf_put(b, m->mats[i].name, strlen(m->mats[i].name));
        mx_buf_printf(b, "\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nillum 1\n");
        const char *tex = i < ntex ? texture_files[i] : ntex > 0 ? texture_files[0] : NULL;
        if (tex) mx_buf_printf(b, "map_Kd %s\n", tex);
        mx_buf_put(b, "\n", 1);
    }
}

/* "dir/name.obj" -> "dir/name.mtl" (and the bare file name for the mtllib line). */
static void mtl_paths(const char *obj_path, char *mtl_path, size_t cap, const char **mtl_name) {
    snprintf(mtl_path, cap, "%s", obj_path);
    char *dot = strrchr(mtl_path, '.'), *slash = strrchr(mtl_path, '/');
    if (dot && (!slash || dot > slash)) *dot = 0;
    strncat(mtl_path, ".mtl", cap - strlen(mtl_path) - 1);
    slash = strrchr(mtl_path, '/');
    *mtl_name = slash ? slash + 1 : mtl_path;
}

int mx_export_obj(const char *path, const mx_mesh *m, const char *const *texture_files, int ntex, mx_status *st) {
    char mtl_path[1100];
    const char *mtl_name;
    mtl_paths(path, mtl_path, sizeof mtl_path, &mtl_name);
    bytes b = {0};
    mx_buf_printf(&b, "# written by matex: %d vertices, %d triangles\n", m->nverts, m->nfaces);
    if (texture_files) mx_buf_printf(&b, "mtllib %s\n", mtl_name);
    for (int v = 0; v < m->nverts; v++)
        mx_buf_printf(&b, "v %.9g %.9g %.9g\n", m->pos[3 * v], m->pos[3 * v + 1], m->pos[3 * v + 2]);
    for (int t = 0; t < m->nuv; t++) mx_buf_printf(&b, "vt %.9g %.9g\n", m->uv[2 * t], m->uv[2 * t + 1]);
    for (int n = 0; n < m->nnrm; n++)
        mx_buf_printf(&b, "vn %.9g %.9g %.9g\n", m->nrm[3 * n], m->nrm[3 * n + 1], m->nrm[3 * n + 2]);
    int cur = -1;
    for (int f = 0; f < m->nfaces; f++) {
        int mat = m->face_mat ? m->face_mat[f] : 0;
        if (mat != cur && m->nmat > 0) {
            mx_buf_printf(&b, "usemtl %s\n", m->mats[mat].name);
            cur = mat;
        }
        mx_buf_put(&b, "f", 1);
        for (int k = 0; k < 3; k++) obj_corner(&b, m, f, k);
        mx_buf_put(&b, "\n", 1);
    }
    bytes mb = {0};
    if (texture_files) mtl_text(&mb, m, texture_files, ntex);
    int rc;
    if (b.oom || mb.oom) rc = mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    else rc = (texture_files ? mx_atomic_write(mtl_path, mb.p, mb.len, st) : 0) || mx_atomic_write(path, b.p, b.len, st) ? -1 : 0;
    free(b.p);
    free(mb.p);
    return rc;
}

/* ---- GLB ---- */

/* One glTF vertex per distinct (position, uv, normal) corner. */
typedef struct {
    int32_t key[3];
    int32_t corner;
} corner_rec;

static int cmp_corner(const void *x, const void *y) {
    const corner_rec *a = x, *b = y;
    for (int k = 0; k < 3; k++)
        if (a->key[k] != b->key[k]) return a->key[k] < b->key[k] ? -1 : 1;
    return (a->corner > b->corner) - (a->corner < b->corner);
}

typedef struct {
    size_t nv;
    float *pos, *nrm, *uv;  /* [nv][3], [nv][3], [nv][2] */
    uint32_t *corner_vert; /* [nfaces*3] glTF vertex of each corner */
} glb_verts;

/* Area-weighted vertex normals, used for corners without a normal of their own. */
static float *vertex_normals(const mx_mesh *m) {
    float *vn = calloc((size_t)m->nverts * 3 + 1, sizeof(float));
    if (!vn) return NULL;
    for (int f = 0; f < m->nfaces; f++) {
        const int32_t *t = m->faces + 3 * f;
        const float *a = m->pos + 3 * t[0], *b = m->pos + 3 * t[1], *c = m->pos + 3 * t[2];
        float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++) vn[3 * t[k] + j] += n[j];
    }
    for (int v = 0; v < m->nverts; v++) {
        float *n = vn + 3 * v, l = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (l > 0) n[0] /= l, n[1] /= l, n[2] /= l;
        else n[0] = 0, n[1] = 1, n[2] = 0;
    }
    return vn;
}

static void glb_verts_free(glb_verts *g) {
    free(g->pos);
    free(g->nrm);
    free(g->uv);
    free(g->corner_vert);
}

static int split_vertices(const mx_mesh *m, glb_verts *g, mx_status *st) {
    size_t nc = (size_t)m->nfaces * 3;
    corner_rec *c = malloc(nc * sizeof *c + 1);
    float *vn = vertex_normals(m);
    memset(g, 0, sizeof *g);
    g->corner_vert = malloc(nc * sizeof *g->corner_vert + 1);
    g->pos = malloc(nc * 3 * sizeof(float) + 1);
    g->nrm = malloc(nc * 3 * sizeof(float) + 1);
    g->uv = malloc(nc * 2 * sizeof(float) + 1);
    int rc = -1;
    if (!c || !vn || !g->corner_vert || !g->pos || !g->nrm || !g->uv) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory building GLB vertices", m->source_path);
        goto done;
    }
    for (size_t i = 0; i < nc; i++) {
        c[i].key[0] = m->faces[i];
        c[i].key[1] = m->face_uv ? m->face_uv[i] : -1;
        c[i].key[2] = m->face_nrm ? m->face_nrm[i] : -1;
        c[i].corner = (int32_t)i;
    }
    qsort(c, nc, sizeof *c, cmp_corner);
    for (size_t i = 0; i < nc; i++) {
        if (i == 0 || memcmp(c[i].key, c[i - 1].key, sizeof c[i].key)) {
            size_t v = g->nv++;
            int32_t p = c[i].key[0], t = c[i].key[1], n = c[i].key[2];
            memcpy(g->pos + 3 * v, m->pos + 3 * (size_t)p, 3 * sizeof(float));
            memcpy(g->nrm + 3 * v, n >= 0 ? m->nrm + 3 * (size_t)n : vn + 3 * (size_t)p, 3 * sizeof(float));
            g->uv[2 * v] = t >= 0 ? m->uv[2 * (size_t)t] : 0.f;
            g->uv[2 * v + 1] = t >= 0 ? 1.f - m->uv[2 * (size_t)t + 1] : 0.f; /* v up -> glTF v down */
        }
        g->corner_vert[c[i].corner] = (uint32_t)(g->nv - 1);
    }
    rc = 0;
done:
    if (rc) glb_verts_free(g);
    free(c);
    free(vn);
    return rc;
}

typedef struct {
    bytes bin, views, accs, prims, images;
    int nview, nacc, nimg;
} glb_build;

/* A buffer view over bin[off, off + len); target 0 for image data. */
static void add_view(glb_build *b, size_t off, size_t len, int target) {
    mx_buf_printf(&b->views, "%s{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu", b->nview ? "," : "", off, len);
    if (target) mx_buf_printf(&b->views, ",\"target\":%d", target);
    mx_buf_put(&b->views, "}", 1);
    b->nview++;
}

static int add_accessor(glb_build *b, const void *data, size_t count, int ncomp, int ctype, const char *type,
                        int target, const float *minmax) {
    size_t esize = 4 * (size_t)ncomp, off = b->bin.len;
    mx_buf_put(&b->bin, data, count * esize);
    pad4(&b->bin, 0);
    add_view(b, off, count * esize, target);
    mx_buf_printf(&b->accs, "%s{\"bufferView\":%d,\"componentType\":%d,\"count\":%zu,\"type\":\"%s\"", b->nacc ? "," : "",
         b->nview - 1, ctype, count, type);
    if (minmax)
        mx_buf_printf(&b->accs, ",\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]", minmax[0], minmax[1], minmax[2], minmax[3],
             minmax[4], minmax[5]);
    mx_buf_put(&b->accs, "}", 1);
    return b->nacc++;
}

static void position_bounds(const glb_verts *g, float mm[6]) {
    for (int k = 0; k < 3; k++) mm[k] = mm[3 + k] = g->pos[k];
    for (size_t v = 0; v < g->nv; v++)
        for (int k = 0; k < 3; k++) {
            float x = g->pos[3 * v + k];
            if (x < mm[k]) mm[k] = x;
            if (x > mm[3 + k]) mm[3 + k] = x;
        }
}

/* One primitive per material that has faces; all share the vertex accessors. */
static int add_primitives(glb_build *b, const mx_mesh *m, const glb_verts *g, int a_pos, int a_nrm, int a_uv,
                          mx_status *st) {
    uint32_t *idx = malloc((size_t)m->nfaces * 3 * sizeof *idx + 1);
    if (!idx) return mx_fail(st, MX_ENOMEM, "%s: out of memory", m->source_path);
    int nprim = 0;
    for (int mat = 0; mat < m->nmat; mat++) {
        size_t n = 0;
        for (int f = 0; f < m->nfaces; f++)
            if ((m->face_mat ? m->face_mat[f] : 0) == mat)
                for (int k = 0; k < 3; k++) idx[n++] = g->corner_vert[3 * f + k];
        if (!n) continue;
        int a_idx = add_accessor(b, idx, n, 1, 5125, "SCALAR", 34963, NULL);
        mx_buf_printf(&b->prims, "%s{\"attributes\":{\"POSITION\":%d,\"NORMAL\":%d", nprim ? "," : "", a_pos, a_nrm);
        if (a_uv >= 0) mx_buf_printf(&b->prims, ",\"TEXCOORD_0\":%d", a_uv);
        mx_buf_printf(&b->prims, "},\"indices\":%d,\"material\":%d,\"mode\":4}", a_idx, mat);
        nprim++;
    }
    free(idx);
    return 0;
}

/* A texture encoded as PNG, once for its file and the GLB (data NULL: no texture). */
typedef struct png_blob {
    unsigned char *data;
    size_t len;
} png_blob;

static void free_pngs(png_blob *png, int n) {
    for (int i = 0; png && i < n; i++) free(png[i].data);
    free(png);
}

/* The PNGs of textures[0..ntex) (an entry without data has none); what = the messages' prefix. */
static png_blob *encode_pngs(const mx_image *textures, int ntex, const char *what, mx_status *st) {
    png_blob *png = calloc(ntex > 0 ? (size_t)ntex : 1, sizeof *png);
    if (!png) return mx_fail(st, MX_ENOMEM, "%s: out of memory", what), NULL;
    for (int i = 0; textures && i < ntex; i++)
        if (textures[i].data && mx_io_encode_png(&textures[i], &png[i].data, &png[i].len, st)) {
            mx_fail_prefix(st, "%s: texture %d", what, i);
            free_pngs(png, ntex);
            return NULL;
        }
    return png;
}

/* Materials (+ textures, images embedded as PNG buffer views; png[i] of material i, ntex entries). */
static int add_materials(glb_build *b, bytes *mats, bytes *texs, const mx_mesh *m, const png_blob *png, int ntex) {
    for (int i = 0; i < m->nmat; i++) {
        const png_blob *img = i < ntex && png[i].data ? &png[i] : NULL;
        mx_buf_printf(mats, "%s{\"name\":", i ? "," : "");
        mx_buf_json_str(mats, m->mats[i].name);
        mx_buf_printf(mats, ",\"doubleSided\":true,\"pbrMetallicRoughness\":{\"metallicFactor\":0,\"roughnessFactor\":1");
        if (img) {
            size_t off = b->bin.len, len = img->len;
            mx_buf_put(&b->bin, img->data, len);
            pad4(&b->bin, 0);
            add_view(b, off, len, 0);
            mx_buf_printf(&b->images, "%s{\"bufferView\":%d,\"mimeType\":\"image/png\"}", b->nimg ? "," : "", b->nview - 1);
            mx_buf_printf(texs, "%s{\"sampler\":0,\"source\":%d}", b->nimg ? "," : "", b->nimg);
            mx_buf_printf(mats, ",\"baseColorTexture\":{\"index\":%d}", b->nimg);
            b->nimg++;
        }
        mx_buf_put(mats, "}}", 2);
    }
    return 0;
}

static void glb_json(bytes *j, glb_build *b, bytes *mats, bytes *texs) {
    mx_buf_printf(j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"matex\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],");
    mx_buf_printf(j, "\"nodes\":[{\"mesh\":0,\"name\":\"mesh\"}],\"meshes\":[{\"name\":\"mesh\",\"primitives\":[");
    mx_buf_put(j, b->prims.p, b->prims.len);
    mx_buf_printf(j, "]}],\"materials\":[");
    mx_buf_put(j, mats->p, mats->len);
    mx_buf_put(j, "]", 1);
    if (b->nimg) {
        mx_buf_printf(j, ",\"samplers\":[{\"magFilter\":9729,\"minFilter\":9987,\"wrapS\":10497,\"wrapT\":10497}]");
        mx_buf_printf(j, ",\"textures\":[");
        mx_buf_put(j, texs->p, texs->len);
        mx_buf_printf(j, "],\"images\":[");
        mx_buf_put(j, b->images.p, b->images.len);
        mx_buf_put(j, "]", 1);
    }
    mx_buf_printf(j, ",\"accessors\":[");
    mx_buf_put(j, b->accs.p, b->accs.len);
    mx_buf_printf(j, "],\"bufferViews\":[");
    mx_buf_put(j, b->views.p, b->views.len);
    mx_buf_printf(j, "],\"buffers\":[{\"byteLength\":%zu}]}", b->bin.len);
    pad4(j, ' ');
}

static void put_u32(bytes *b, uint32_t v) {
    unsigned char p[4] = {(unsigned char)v, (unsigned char)(v >> 8), (unsigned char)(v >> 16), (unsigned char)(v >> 24)};
    mx_buf_put(b, p, 4);
}

static int check_glb_mesh(const char *path, const mx_mesh *m, mx_status *st) {
    if (m->nfaces <= 0 || m->nmat <= 0) return mx_fail(st, MX_EINPUT, "%s: nothing to export (no faces or materials)", path);
    return 0;
}

/* mx_export_glb with its textures already encoded. */
static int export_glb(const char *path, const mx_mesh *m, const png_blob *png, int ntex, mx_status *st) {
    glb_verts g;
    glb_build b = {0};
    bytes mats = {0}, texs = {0}, json = {0}, out = {0};
    int rc = -1;
    if (check_glb_mesh(path, m, st)) return -1;
    if (split_vertices(m, &g, st)) return -1;
    float mm[6];
    position_bounds(&g, mm);
    int a_pos = add_accessor(&b, g.pos, g.nv, 3, 5126, "VEC3", 34962, mm);
    int a_nrm = add_accessor(&b, g.nrm, g.nv, 3, 5126, "VEC3", 34962, NULL);
    int a_uv = m->face_uv ? add_accessor(&b, g.uv, g.nv, 2, 5126, "VEC2", 34962, NULL) : -1;
    if (add_primitives(&b, m, &g, a_pos, a_nrm, a_uv, st)) goto done;
    add_materials(&b, &mats, &texs, m, png, ntex);
    glb_json(&json, &b, &mats, &texs);
    if (b.bin.oom || json.oom || b.accs.oom || b.views.oom || b.prims.oom || mats.oom) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
        goto done;
    }
    if (12 + 8 + json.len + 8 + b.bin.len > UINT32_MAX) {
        mx_fail(st, MX_EINPUT, "%s: GLB larger than 4 GiB", path);
        goto done;
    }
    put_u32(&out, 0x46546C67u); /* "glTF" */
    put_u32(&out, 2);
    put_u32(&out, (uint32_t)(12 + 8 + json.len + 8 + b.bin.len));
    put_u32(&out, (uint32_t)json.len);
    put_u32(&out, 0x4E4F534Au); /* JSON */
    mx_buf_put(&out, json.p, json.len);
    put_u32(&out, (uint32_t)b.bin.len);
    put_u32(&out, 0x004E4942u); /* BIN */
    mx_buf_put(&out, b.bin.p, b.bin.len);
    if (out.oom) mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    else rc = mx_atomic_write(path, out.p, out.len, st);
done:
    glb_verts_free(&g);
    bytes *all[] = {&b.bin, &b.views, &b.accs, &b.prims, &b.images, &mats, &texs, &json, &out};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++) free(all[i]->p);
    return rc;
}

int mx_export_glb(const char *path, const mx_mesh *m, const mx_image *textures, int ntex, mx_status *st) {
    if (check_glb_mesh(path, m, st)) return -1; /* before the encoding */
    png_blob *png = encode_pngs(textures, ntex, path, st);
    int rc = png ? export_glb(path, m, png, ntex, st) : -1;
    free_pngs(png, ntex);
    return rc;
}

/* ---- the output folder ---- */

/* names[i] = "texture_<name>" with the material name reduced to [A-Za-z0-9_-]; the material
 * index is added when an earlier material already gave that name. */
static void material_texture_name(const mx_mesh *m, int i, char names[][160]) {
    char clean[128];
    size_t n = 0;
    for (const char *s = m->mats[i].name; *s && n + 1 < sizeof clean; s++) {
        char c = *s;
        int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
        clean[n++] = ok ? c : '_';
    }
    clean[n] = 0;
    snprintf(names[i], 160, "texture_%s", n ? clean : "material");
    for (int k = 0; k < i; k++)
        if (!strcmp(names[k], names[i])) {
            snprintf(names[i], 160, "texture_%s_%d", n ? clean : "material", i);
            return;
        }
}

/* "<base>.png" (8-bit, its encoding png) and "<base>.exr" (float) of one texture; names[i] becomes
 * the PNG's name. */
static int write_texture_pair(const char *dir, const mx_image *tex, const png_blob *png, int threads, char *name,
                              mx_status *st) {
    char path[1200];
    size_t len = strlen(name);
    snprintf(name + len, 160 - len, ".exr");
    if (mx_path_join(path, sizeof path, dir, name, st) || mx_io_write_exr(path, tex, threads, st)) return -1;
    snprintf(name + len, 160 - len, ".png");
    return mx_path_join(path, sizeof path, dir, name, st) || mx_atomic_write(path, png->data, png->len, st) ? -1 : 0;
}

/* texture.png/.exr for one texture, else texture_<material>.png/.exr per textured material. */
static int write_textures(const char *dir, const mx_mesh *m, const mx_image *textures, const png_blob *png, int ntex,
                          int threads, char names[][160], mx_status *st) {
    for (int i = 0; i < ntex; i++) {
        if (ntex == 1) snprintf(names[0], 160, "texture");
        else material_texture_name(m, i, names);
        if (textures[i].data && write_texture_pair(dir, &textures[i], &png[i], threads, names[i], st)) return -1;
    }
    return 0;
}

int mx_write_output_files(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex, int threads,
                          mx_status *st) {
    if (ntex < 1 || !textures || !textures[0].data) return mx_fail(st, MX_EINPUT, "%s: no texture to write", dir);
    if (ntex > 1 && ntex != m->nmat)
        return mx_fail(st, MX_EINPUT, "%s: %d textures for %d materials (give 1 or one per material)", dir, ntex, m->nmat);
    if (mkdir(dir, 0777) != 0 && errno != EEXIST) return mx_fail(st, MX_EIO, "%s: cannot create folder: %s", dir, strerror(errno));
    /* One shared texture: export a single material so that every face maps to texture.png. */
    mx_mesh one = *m;
    mx_material mat = {.name = "matex"};
    if (ntex == 1) {
        one.nmat = 1;
        one.mats = &mat;
        one.face_mat = NULL;
    }
    char(*names)[160] = calloc((size_t)ntex, sizeof *names);
    const char **name_ptrs = calloc((size_t)ntex, sizeof *name_ptrs);
    char path[1200];
    int rc = -1;
    png_blob *png = NULL;
    if (!names || !name_ptrs) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", dir);
        goto done;
    }
    if (!(png = encode_pngs(textures, ntex, dir, st)) || write_textures(dir, &one, textures, png, ntex, threads, names, st)) goto done;
    for (int i = 0; i < ntex; i++) name_ptrs[i] = textures[i].data ? names[i] : NULL;
    if (mx_path_join(path, sizeof path, dir, "mesh.obj", st) || mx_export_obj(path, &one, name_ptrs, ntex, st)) goto done;
    if (mx_path_join(path, sizeof path, dir, "mesh.glb", st) || export_glb(path, &one, png, ntex, st)) goto done;
    rc = 0;
done:
    free_pngs(png, ntex);
    free(names);
    free(name_ptrs);
    return rc;
}

int mx_write_report(const char *dir, const char *report_json, mx_status *st) {
    char path[1200];
    const char *report = report_json ? report_json : "{}";
    return mx_path_join(path, sizeof path, dir, "report.json", st) || mx_atomic_write(path, report, strlen(report), st) ? -1 : 0;
}

int mx_write_outputs(const char *dir, const mx_mesh *m, const mx_image *textures, int ntex, const char *report_json,
                     mx_status *st) {
    return mx_write_output_files(dir, m, textures, ntex, 1, st) || mx_write_report(dir, report_json, st) ? -1 : 0;
}
