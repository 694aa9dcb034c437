/* glTF 2.0 / GLB import (pipeline/io/gltf.h). Spec: Khronos glTF 2.0, sections 3.6 (binary
 * data: buffers, buffer views, accessors), 3.5 (node transforms), 3.7 (meshes), 4.4 (GLB). */
#include "gltf.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"
#include "../../runtime/log.h"
#include "io.h"

#define GLB_MAGIC 0x46546C67u      /* "glTF" */
#define GLB_CHUNK_JSON 0x4E4F534Au /* "JSON" */
#define GLB_CHUNK_BIN 0x004E4942u  /* "BIN\0" */
#define MAX_NODE_DEPTH 256
#define MAX_NODE_VISITS 100000 /* node instances; bounds the work of a hostile DAG of children */
#define MAX_FILE_BYTES ((size_t)1 << 31)

typedef struct {
    unsigned char *data;
    size_t len;
} blob;

typedef struct {
    const char *path;
    char dir[1024];
    unsigned char *file; /* the whole .gltf/.glb file */
    size_t file_len;
    mx_json *root;
    blob *buffers; /* [nbuffers]; a GLB's BIN chunk points into file */
    int *buffer_owned;
    size_t nbuffers;
} gltf_doc;

/* Growing arrays of the merged mesh. */
typedef struct {
    float *pos, *uv, *nrm;
    size_t nverts, cap_verts;
    int32_t *faces, *face_mat;
    int32_t *face_has_uv, *face_has_nrm; /* per face: 1 if the primitive had the attribute */
    size_t nfaces, cap_faces;
    int any_uv, any_nrm;
    size_t node_visits;
} merged;

static uint32_t rd_u32(const unsigned char *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static int read_file(const char *path, unsigned char **data, size_t *len, mx_status *st) {
    *data = NULL;
    *len = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open file", path);
    long n = -1;
    if (fseek(f, 0, SEEK_END) == 0) n = ftell(f);
    if (n < 0 || (size_t)n > MAX_FILE_BYTES || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return mx_fail(st, MX_EINPUT, "%s: cannot determine the file size (or larger than 2 GiB)", path);
    }
    unsigned char *buf = malloc((size_t)n + 1);
    if (!buf) {
        fclose(f);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory reading %ld bytes", path, n);
    }
    size_t got = fread(buf, 1, (size_t)n, f);
    fclose(f);
    if (got != (size_t)n) {
        free(buf);
        return mx_fail(st, MX_EINPUT, "%s: short read", path);
    }
    buf[n] = 0;
    *data = buf;
    *len = (size_t)n;
    return 0;
}

/* ---- JSON helpers: indices and counts must be non-negative integers below a limit ---- */

static int get_uint(const mx_json *obj, const char *key, size_t limit, size_t *out, const char *what,
                    const char *path, mx_status *st) {
    const mx_json *j = mx_json_get(obj, key);
    if (!j) return 1; /* absent */
    double v = mx_json_kind(j) == MX_JSON_NUM ? mx_json_num(j) : -1;
    if (!(v >= 0 && v < (double)limit && v == floor(v)))
        return mx_fail(st, MX_EINPUT, "%s: %s.%s must be an integer in [0, %zu)", path, what, key, limit);
    *out = (size_t)v;
    return 0;
}

/* Required index into the array root[array_key]; returns the element. */
static const mx_json *get_ref(const gltf_doc *d, const mx_json *obj, const char *key, const char *array_key,
                              const char *what, mx_status *st) {
    const mx_json *arr = mx_json_get(d->root, array_key);
    size_t n = arr && mx_json_kind(arr) == MX_JSON_ARR ? mx_json_len(arr) : 0, i = 0;
    int rc = get_uint(obj, key, n ? n : 1, &i, what, d->path, st);
    if (rc == 1) {
        mx_fail(st, MX_EINPUT, "%s: %s has no '%s'", d->path, what, key);
        return NULL;
    }
    if (rc < 0) return NULL;
    if (!n) {
        mx_fail(st, MX_EINPUT, "%s: %s.%s refers to a missing '%s' array", d->path, what, key, array_key);
        return NULL;
    }
    const mx_json *e = mx_json_at(arr, i);
    if (mx_json_kind(e) != MX_JSON_OBJ) {
        mx_fail(st, MX_EINPUT, "%s: %s[%zu] is not an object", d->path, array_key, i);
        return NULL;
    }
    return e;
}

static size_t array_len(const mx_json *root, const char *key) {
    const mx_json *a = mx_json_get(root, key);
    return a && mx_json_kind(a) == MX_JSON_ARR ? mx_json_len(a) : 0;
}

/* ---- buffers ---- */

static int b64_value(unsigned char c) {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+' || c == '-') return 62;
    if (c == '/' || c == '_') return 63;
    return -1;
}

/* Decodes the payload of a "data:...;base64," URI. */
static int decode_data_uri(const char *uri, blob *out, const char *what, mx_status *st) {
    const char *comma = strchr(uri, ',');
    if (!comma || !strstr(uri, ";base64") || strstr(uri, ";base64") > comma)
        return mx_fail(st, MX_EINPUT, "%s: only base64 data: URIs are supported", what);
    const char *s = comma + 1;
    size_t n = strlen(s);
    out->data = malloc(n / 4 * 3 + 4);
    out->len = 0;
    if (!out->data) return mx_fail(st, MX_ENOMEM, "%s: out of memory decoding a data: URI", what);
    uint32_t acc = 0;
    int bits = 0;
    for (size_t i = 0; i < n; i++) {
        if (s[i] == '=') break;
        int v = b64_value((unsigned char)s[i]);
        if (v < 0) {
            free(out->data);
            out->data = NULL;
            return mx_fail(st, MX_EINPUT, "%s: bad base64 character in a data: URI", what);
        }
        acc = acc << 6 | (uint32_t)v;
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            out->data[out->len++] = (unsigned char)(acc >> bits);
        }
    }
    return 0;
}

int mx_gltf_uri_name(const char *uri, char *out, size_t cap) {
    size_t n = 0;
    for (const char *p = uri; *p; p++) {
        char c = *p;
        unsigned hi, lo;
        if (c == '%' && sscanf(p + 1, "%1x%1x", &hi, &lo) == 2) {
            c = (char)(hi << 4 | lo);
            p += 2;
        }
        if (n + 1 >= cap) return -1;
        out[n++] = c;
    }
    out[n] = 0;
    return 0;
}

/* Resolves a relative URI against the document folder, decoding %XX escapes. */
static int resolve_uri(const gltf_doc *d, const char *uri, char *out, size_t cap, mx_status *st) {
    size_t n = (size_t)snprintf(out, cap, "%s", d->dir);
    if (n >= cap || mx_gltf_uri_name(uri, out + n, cap - n))
        return mx_fail(st, MX_EINPUT, "%s: uri too long: %s", d->path, uri);
    if (strstr(uri, "://")) return mx_fail(st, MX_EINPUT, "%s: remote uri %s is not supported", d->path, uri);
    return 0;
}

static int load_buffer(gltf_doc *d, size_t i, const blob *glb_bin, mx_status *st) {
    const mx_json *b = mx_json_at(mx_json_get(d->root, "buffers"), i);
    size_t byte_len = 0;
    char what[64];
    snprintf(what, sizeof what, "buffers[%zu]", i);
    if (mx_json_kind(b) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: %s is not an object", d->path, what);
    int rc = get_uint(b, "byteLength", MAX_FILE_BYTES, &byte_len, what, d->path, st);
    if (rc) return rc < 0 ? -1 : mx_fail(st, MX_EINPUT, "%s: %s has no byteLength", d->path, what);
    const char *uri = mx_json_get_str(b, "uri", NULL);
    blob data = {0};
    if (!uri) {
        if (i != 0 || !glb_bin) return mx_fail(st, MX_EINPUT, "%s: %s has no uri and there is no GLB BIN chunk", d->path, what);
        data = *glb_bin;
    } else if (!strncmp(uri, "data:", 5)) {
        if (decode_data_uri(uri, &data, d->path, st)) return -1;
        d->buffer_owned[i] = 1;
    } else {
        char file[2048];
        if (resolve_uri(d, uri, file, sizeof file, st) || read_file(file, &data.data, &data.len, st))
            return mx_fail_prefix(st, "%s: %s", d->path, what);
        d->buffer_owned[i] = 1;
    }
    d->buffers[i] = data;
    if (data.len < byte_len)
        return mx_fail(st, MX_EINPUT, "%s: %s holds %zu bytes but byteLength is %zu", d->path, what, data.len, byte_len);
    d->buffers[i].len = byte_len; /* a GLB BIN chunk may carry up to 3 bytes of padding */
    return 0;
}

/* Splits a GLB container (header + chunks) into its JSON text and BIN chunk. */
static int parse_glb(gltf_doc *d, const char **json, size_t *json_len, blob *bin, mx_status *st) {
    const unsigned char *f = d->file;
    if (d->file_len < 20) return mx_fail(st, MX_EINPUT, "%s: truncated GLB (%zu bytes)", d->path, d->file_len);
    if (rd_u32(f) != GLB_MAGIC) return mx_fail(st, MX_EINPUT, "%s: not a GLB file (bad magic)", d->path);
    if (rd_u32(f + 4) != 2) return mx_fail(st, MX_EINPUT, "%s: GLB version %u (only 2 is supported)", d->path, rd_u32(f + 4));
    size_t total = rd_u32(f + 8);
    if (total > d->file_len)
        return mx_fail(st, MX_EINPUT, "%s: truncated GLB: header says %zu bytes, file has %zu", d->path, total, d->file_len);
    size_t off = 12;
    int chunk = 0;
    *json = NULL;
    bin->data = NULL;
    while (off + 8 <= total) {
        size_t len = rd_u32(f + off);
        uint32_t type = rd_u32(f + off + 4);
        if (len > total - off - 8)
            return mx_fail(st, MX_EINPUT, "%s: GLB chunk %d (%zu bytes at offset %zu) runs past the end", d->path, chunk,
                           len, off);
        if (chunk == 0 && type != GLB_CHUNK_JSON) return mx_fail(st, MX_EINPUT, "%s: first GLB chunk is not JSON", d->path);
        if (chunk == 0) {
            *json = (const char *)f + off + 8;
            *json_len = len;
        } else if (chunk == 1 && type == GLB_CHUNK_BIN) {
            bin->data = d->file + off + 8;
            bin->len = len;
        }
        off += 8 + ((len + 3) & ~(size_t)3);
        chunk++;
    }
    if (!*json) return mx_fail(st, MX_EINPUT, "%s: GLB has no JSON chunk", d->path);
    return 0;
}

static void doc_free(gltf_doc *d) {
    for (size_t i = 0; i < d->nbuffers; i++)
        if (d->buffer_owned && d->buffer_owned[i]) free(d->buffers[i].data);
    free(d->buffers);
    free(d->buffer_owned);
    mx_json_free(d->root);
    free(d->file);
    memset(d, 0, sizeof *d);
}

static int doc_open(gltf_doc *d, const char *path, mx_status *st) {
    memset(d, 0, sizeof *d);
    d->path = path;
    const char *slash = strrchr(path, '/');
    snprintf(d->dir, sizeof d->dir, "%.*s", slash ? (int)(slash - path + 1) : 0, path);
    if (read_file(path, &d->file, &d->file_len, st)) return -1;
    const char *json = (const char *)d->file;
    size_t json_len = d->file_len;
    blob bin = {0};
    int is_glb = d->file_len >= 4 && rd_u32(d->file) == GLB_MAGIC;
    if (is_glb && parse_glb(d, &json, &json_len, &bin, st)) goto fail;
    d->root = mx_json_parse(json, json_len, path, st);
    if (!d->root) goto fail;
    if (mx_json_kind(d->root) != MX_JSON_OBJ) {
        mx_fail(st, MX_EINPUT, "%s: glTF JSON is not an object", path);
        goto fail;
    }
    d->nbuffers = array_len(d->root, "buffers");
    d->buffers = calloc(d->nbuffers + 1, sizeof *d->buffers);
    d->buffer_owned = calloc(d->nbuffers + 1, sizeof *d->buffer_owned);
    if (!d->buffers || !d->buffer_owned) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
        goto fail;
    }
    for (size_t i = 0; i < d->nbuffers; i++)
        if (load_buffer(d, i, bin.data ? &bin : NULL, st)) goto fail;
    return 0;
fail:
    doc_free(d);
    return -1;
}

/* ---- buffer views and accessors ---- */

/* The bytes of a buffer view, bounds-checked. stride = 0 when not given. */
static int view_bytes(const gltf_doc *d, const mx_json *view, const unsigned char **data, size_t *len,
                      size_t *stride, const char *what, mx_status *st) {
    size_t buf = 0, off = 0, n = 0;
    *stride = 0;
    if (get_uint(view, "buffer", d->nbuffers ? d->nbuffers : 1, &buf, what, d->path, st) || !d->nbuffers)
        return mx_fail(st, MX_EINPUT, "%s: %s: missing or bad buffer", d->path, what);
    if (get_uint(view, "byteOffset", MAX_FILE_BYTES, &off, what, d->path, st) < 0) return -1;
    if (get_uint(view, "byteLength", MAX_FILE_BYTES, &n, what, d->path, st))
        return mx_fail(st, MX_EINPUT, "%s: %s: missing or bad byteLength", d->path, what);
    if (get_uint(view, "byteStride", 253, stride, what, d->path, st) < 0) return -1;
    if (off > d->buffers[buf].len || n > d->buffers[buf].len - off)
        return mx_fail(st, MX_EINPUT, "%s: %s: bytes [%zu, %zu) outside buffer %zu of %zu bytes", d->path, what, off,
                       off + n, buf, d->buffers[buf].len);
    *data = d->buffers[buf].data + off;
    *len = n;
    return 0;
}

static size_t component_size(size_t type) {
    switch (type) {
    case 5120: case 5121: return 1; /* (unsigned) byte */
    case 5122: case 5123: return 2; /* (unsigned) short */
    case 5125: case 5126: return 4; /* unsigned int, float */
    default: return 0;
    }
}

static double read_component(const unsigned char *p, size_t type, int normalized) {
    switch (type) {
    case 5120: return normalized ? fmax((int8_t)p[0] / 127.0, -1.0) : (int8_t)p[0];
    case 5121: return normalized ? p[0] / 255.0 : p[0];
    case 5122: {
        int16_t v = (int16_t)(p[0] | p[1] << 8);
        return normalized ? fmax(v / 32767.0, -1.0) : v;
    }
    case 5123: {
        uint16_t v = (uint16_t)(p[0] | p[1] << 8);
        return normalized ? v / 65535.0 : v;
    }
    case 5125: return rd_u32(p);
    default: {
        float f;
        memcpy(&f, p, 4);
        return f;
    }
    }
}

static size_t type_components(const char *t) {
    static const char *const names[] = {"SCALAR", "VEC2", "VEC3", "VEC4"};
    for (size_t i = 0; i < 4; i++)
        if (t && !strcmp(t, names[i])) return i + 1;
    return 0;
}

/* Reads accessor `acc_index` as `ncomp` doubles per element into a malloc'ed array. */
static int read_accessor(const gltf_doc *d, const mx_json *owner, const char *key, size_t want_comp, double **out,
                         size_t *count, mx_status *st) {
    *out = NULL;
    *count = 0;
    char what[96];
    size_t ai = 0;
    get_uint(owner, key, SIZE_MAX, &ai, "primitive", d->path, NULL);
    snprintf(what, sizeof what, "accessors[%zu] (%s)", ai, key);
    const mx_json *acc = get_ref(d, owner, key, "accessors", what, st);
    if (!acc) return -1;
    size_t ctype = 0, n = 0, off = 0, ncomp = type_components(mx_json_get_str(acc, "type", NULL));
    if (get_uint(acc, "componentType", 6000, &ctype, what, d->path, st) || !component_size(ctype))
        return mx_fail(st, MX_EINPUT, "%s: %s: missing or unsupported componentType", d->path, what);
    if (get_uint(acc, "count", (size_t)1 << 28, &n, what, d->path, st) || n == 0)
        return mx_fail(st, MX_EINPUT, "%s: %s: missing, zero or too large count", d->path, what);
    if (ncomp != want_comp)
        return mx_fail(st, MX_EINPUT, "%s: %s: type %s, expected %zu components", d->path, what,
                       mx_json_get_str(acc, "type", "?"), want_comp);
    if (get_uint(acc, "byteOffset", MAX_FILE_BYTES, &off, what, d->path, st) < 0) return -1;
    if (mx_json_get(acc, "sparse")) return mx_fail(st, MX_EINPUT, "%s: %s: sparse accessors are not supported", d->path, what);
    const mx_json *view = get_ref(d, acc, "bufferView", "bufferViews", what, st);
    if (!view) return -1;
    const unsigned char *data;
    size_t len, stride, csize = component_size(ctype), elem = csize * ncomp;
    if (view_bytes(d, view, &data, &len, &stride, what, st)) return -1;
    if (stride == 0) stride = elem;
    if (stride < elem) return mx_fail(st, MX_EINPUT, "%s: %s: byteStride %zu smaller than an element (%zu)", d->path, what, stride, elem);
    if (off > len || (len - off < elem) || (n - 1) > (len - off - elem) / stride)
        return mx_fail(st, MX_EINPUT, "%s: %s: %zu elements at offset %zu, stride %zu overrun its buffer view of %zu bytes",
                       d->path, what, n, off, stride, len);
    double *v = malloc(n * ncomp * sizeof *v);
    if (!v) return mx_fail(st, MX_ENOMEM, "%s: %s: out of memory", d->path, what);
    int normalized = mx_json_get_bool(acc, "normalized", 0);
    for (size_t i = 0; i < n; i++)
        for (size_t k = 0; k < ncomp; k++) v[i * ncomp + k] = read_component(data + off + i * stride + k * csize, ctype, normalized);
    *out = v;
    *count = n;
    return 0;
}

/* ---- node transforms (column-major 4x4, as glTF stores them) ---- */

static void mat_mul(const double a[16], const double b[16], double out[16]) {
    double r[16];
    for (int c = 0; c < 4; c++)
        for (int rr = 0; rr < 4; rr++) {
            double s = 0;
            for (int k = 0; k < 4; k++) s += a[k * 4 + rr] * b[c * 4 + k];
            r[c * 4 + rr] = s;
        }
    memcpy(out, r, sizeof r);
}

static int read_vec(const mx_json *node, const char *key, double *out, size_t n) {
    const mx_json *a = mx_json_get(node, key);
    if (!a) return 0;
    if (mx_json_kind(a) != MX_JSON_ARR || mx_json_len(a) != n) return -1;
    for (size_t i = 0; i < n; i++) {
        const mx_json *e = mx_json_at(a, i);
        if (mx_json_kind(e) != MX_JSON_NUM || !isfinite(mx_json_num(e))) return -1;
        out[i] = mx_json_num(e);
    }
    return 0;
}

/* Local matrix: `matrix`, or T * R * S (rotation a unit quaternion x, y, z, w). */
static int node_local(const gltf_doc *d, const mx_json *node, size_t idx, double m[16], mx_status *st) {
    double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
    static const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    memcpy(m, id, sizeof id);
    if (read_vec(node, "matrix", m, 16) || read_vec(node, "translation", t, 3) || read_vec(node, "rotation", q, 4) ||
        read_vec(node, "scale", s, 3))
        return mx_fail(st, MX_EINPUT, "%s: nodes[%zu]: bad matrix/translation/rotation/scale", d->path, idx);
    if (mx_json_get(node, "matrix")) return 0;
    double qn = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (qn > 0)
        for (int i = 0; i < 4; i++) q[i] /= qn;
    double x = q[0], y = q[1], z = q[2], w = q[3];
    double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),  /* column 0 */
                   2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w),  /* column 1 */
                   2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)}; /* column 2 */
    for (int c = 0; c < 3; c++)
        for (int rr = 0; rr < 3; rr++) m[c * 4 + rr] = r[c * 3 + rr] * s[c];
    for (int k = 0; k < 3; k++) m[12 + k] = t[k];
    return 0;
}

/* ---- merging primitives ---- */

static int realloc_to(void **p, size_t bytes) {
    void *q = realloc(*p, bytes ? bytes : 1);
    if (!q) return -1;
    *p = q;
    return 0;
}

static size_t grown(size_t cap, size_t need) {
    size_t c = cap ? cap : 1024;
    while (c < need) c *= 2;
    return c;
}

static int reserve(merged *g, size_t verts, size_t faces) {
    if (verts > g->cap_verts) {
        size_t c = grown(g->cap_verts, verts);
        if (realloc_to((void **)&g->pos, c * 3 * sizeof(float)) || realloc_to((void **)&g->uv, c * 2 * sizeof(float)) ||
            realloc_to((void **)&g->nrm, c * 3 * sizeof(float)))
            return -1;
        g->cap_verts = c;
    }
    if (faces > g->cap_faces) {
        size_t c = grown(g->cap_faces, faces);
        if (realloc_to((void **)&g->faces, c * 3 * sizeof(int32_t)) ||
            realloc_to((void **)&g->face_mat, c * sizeof(int32_t)) ||
            realloc_to((void **)&g->face_has_uv, c * sizeof(int32_t)) ||
            realloc_to((void **)&g->face_has_nrm, c * sizeof(int32_t)))
            return -1;
        g->cap_faces = c;
    }
    return 0;
}

/* Triangle list of a primitive from its (or implicit) indices and mode 4/5/6. */
static int primitive_triangles(const double *idx, size_t nidx, size_t mode, int32_t **tri, size_t *ntri) {
    size_t n = mode == 4 ? nidx / 3 : nidx >= 3 ? nidx - 2 : 0;
    *tri = malloc(n * 3 * sizeof(int32_t) + 1);
    *ntri = n;
    if (!*tri) return -1;
    for (size_t i = 0; i < n; i++) {
        size_t a, b, c;
        if (mode == 4) a = 3 * i, b = a + 1, c = a + 2;
        else if (mode == 6) a = 0, b = i + 1, c = i + 2;
        else if (i % 2 == 0) a = i, b = i + 1, c = i + 2;
        else a = i + 1, b = i, c = i + 2; /* strip: odd triangles reversed to keep the winding */
        (*tri)[3 * i] = (int32_t)idx[a];
        (*tri)[3 * i + 1] = (int32_t)idx[b];
        (*tri)[3 * i + 2] = (int32_t)idx[c];
    }
    return 0;
}

typedef struct {
    double *pos, *uv, *nrm, *idx;
    int32_t *tri;
} prim_data;

static void prim_free(prim_data *p) {
    free(p->pos);
    free(p->uv);
    free(p->nrm);
    free(p->idx);
    free(p->tri);
}

static int add_primitive(const gltf_doc *d, const mx_json *prim, const double world[16], int32_t mat, merged *g,
                         const char *what, mx_status *st) {
    const mx_json *attrs = mx_json_get(prim, "attributes");
    size_t mode = 4, nv = 0, n = 0, ntri = 0;
    if (get_uint(prim, "mode", 7, &mode, what, d->path, st) < 0) return -1;
    if (mode < 4) {
        mx_warn("%s: %s: mode %zu (points/lines) skipped", d->path, what, mode);
        return 0;
    }
    if (mx_json_kind(attrs) != MX_JSON_OBJ || !mx_json_get(attrs, "POSITION"))
        return mx_fail(st, MX_EINPUT, "%s: %s has no POSITION attribute", d->path, what);
    prim_data p = {0};
    int rc = -1;
    if (read_accessor(d, attrs, "POSITION", 3, &p.pos, &nv, st)) goto done;
    if (mx_json_get(attrs, "TEXCOORD_0") && (read_accessor(d, attrs, "TEXCOORD_0", 2, &p.uv, &n, st) || n != nv)) {
        if (p.uv) mx_fail(st, MX_EINPUT, "%s: %s: TEXCOORD_0 has %zu elements, POSITION %zu", d->path, what, n, nv);
        goto done;
    }
    if (mx_json_get(attrs, "NORMAL") && (read_accessor(d, attrs, "NORMAL", 3, &p.nrm, &n, st) || n != nv)) {
        if (p.nrm) mx_fail(st, MX_EINPUT, "%s: %s: NORMAL has %zu elements, POSITION %zu", d->path, what, n, nv);
        goto done;
    }
    if (mx_json_get(prim, "indices")) {
        if (read_accessor(d, prim, "indices", 1, &p.idx, &n, st)) goto done;
        for (size_t i = 0; i < n; i++)
            if (!(p.idx[i] >= 0 && p.idx[i] < (double)nv)) {
                mx_fail(st, MX_EINPUT, "%s: %s: index %.0f out of range (%zu vertices)", d->path, what, p.idx[i], nv);
                goto done;
            }
    } else {
        n = nv;
        p.idx = malloc(nv * sizeof(double));
        if (!p.idx) goto oom;
        for (size_t i = 0; i < nv; i++) p.idx[i] = (double)i;
    }
    if (primitive_triangles(p.idx, n, mode, &p.tri, &ntri)) goto oom;
    if (g->nverts + nv > ((size_t)1 << 28) || g->nfaces + ntri > ((size_t)1 << 28)) {
        mx_fail(st, MX_EINPUT, "%s: too many vertices or faces", d->path);
        goto done;
    }
    if (reserve(g, g->nverts + nv, g->nfaces + ntri)) goto oom;
    /* Normals transform by the inverse transpose: the cofactor matrix of the 3x3 part. */
    const double *M = world;
    double cof[9] = {M[5] * M[10] - M[6] * M[9], M[6] * M[8] - M[4] * M[10], M[4] * M[9] - M[5] * M[8],
                     M[2] * M[9] - M[1] * M[10], M[0] * M[10] - M[2] * M[8], M[1] * M[8] - M[0] * M[9],
                     M[1] * M[6] - M[2] * M[5], M[2] * M[4] - M[0] * M[6], M[0] * M[5] - M[1] * M[4]};
    double det = M[0] * cof[0] + M[4] * cof[1] + M[8] * cof[2];
    for (size_t i = 0; i < nv; i++) {
        const double *q = p.pos + 3 * i;
        float *o = g->pos + 3 * (g->nverts + i);
        for (int r = 0; r < 3; r++) o[r] = (float)(M[r] * q[0] + M[4 + r] * q[1] + M[8 + r] * q[2] + M[12 + r]);
        float *u = g->uv + 2 * (g->nverts + i);
        u[0] = p.uv ? (float)p.uv[2 * i] : 0.f;
        u[1] = p.uv ? (float)(1.0 - p.uv[2 * i + 1]) : 0.f; /* glTF v down -> v up */
        float *nn = g->nrm + 3 * (g->nverts + i);
        double v[3] = {0, 0, 0}, len = 0;
        if (p.nrm)
            for (int r = 0; r < 3; r++) {
                v[r] = cof[3 * r] * p.nrm[3 * i] + cof[3 * r + 1] * p.nrm[3 * i + 1] + cof[3 * r + 2] * p.nrm[3 * i + 2];
                len += v[r] * v[r];
            }
        len = sqrt(len);
        for (int r = 0; r < 3; r++) nn[r] = len > 0 ? (float)(v[r] / len) : 0.f;
    }
    for (size_t t = 0; t < ntri; t++) {
        int32_t *f = g->faces + 3 * (g->nfaces + t);
        int32_t a = p.tri[3 * t], b = p.tri[3 * t + 1], c = p.tri[3 * t + 2];
        if (det < 0) { /* mirrored node: keep counter-clockwise front faces */
            int32_t s = b;
            b = c;
            c = s;
        }
        f[0] = (int32_t)g->nverts + a;
        f[1] = (int32_t)g->nverts + b;
        f[2] = (int32_t)g->nverts + c;
        g->face_mat[g->nfaces + t] = mat;
        g->face_has_uv[g->nfaces + t] = p.uv != NULL;
        g->face_has_nrm[g->nfaces + t] = p.nrm != NULL;
    }
    g->any_uv |= p.uv != NULL;
    g->any_nrm |= p.nrm != NULL;
    g->nverts += nv;
    g->nfaces += ntri;
    rc = 0;
    goto done;
oom:
    mx_fail(st, MX_ENOMEM, "%s: %s: out of memory", d->path, what);
done:
    prim_free(&p);
    return rc;
}

static int add_mesh(const gltf_doc *d, size_t mesh_index, const double world[16], int32_t default_mat, merged *g,
                    mx_status *st) {
    const mx_json *mesh = mx_json_at(mx_json_get(d->root, "meshes"), mesh_index);
    const mx_json *prims = mx_json_get(mesh, "primitives");
    if (mx_json_kind(prims) != MX_JSON_ARR) return mx_fail(st, MX_EINPUT, "%s: meshes[%zu] has no primitives", d->path, mesh_index);
    size_t nmat = array_len(d->root, "materials");
    for (size_t i = 0; i < mx_json_len(prims); i++) {
        char what[96];
        snprintf(what, sizeof what, "meshes[%zu].primitives[%zu]", mesh_index, i);
        const mx_json *prim = mx_json_at(prims, i);
        size_t mat = (size_t)default_mat;
        if (mx_json_kind(prim) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: %s is not an object", d->path, what);
        if (get_uint(prim, "material", nmat ? nmat : 1, &mat, what, d->path, st) < 0 || (mx_json_get(prim, "material") && !nmat))
            return mx_fail(st, MX_EINPUT, "%s: %s: bad material index", d->path, what);
        if (add_primitive(d, prim, world, (int32_t)mat, g, what, st)) return -1;
    }
    return 0;
}

static int visit_node(const gltf_doc *d, size_t idx, const double parent[16], int depth, int32_t default_mat, merged *g,
                      mx_status *st) {
    const mx_json *nodes = mx_json_get(d->root, "nodes");
    const mx_json *node = mx_json_at(nodes, idx);
    if (depth > MAX_NODE_DEPTH) return mx_fail(st, MX_EINPUT, "%s: node hierarchy deeper than %d (a cycle?)", d->path, MAX_NODE_DEPTH);
    if (++g->node_visits > MAX_NODE_VISITS)
        return mx_fail(st, MX_EINPUT, "%s: more than %d node instances (shared children?)", d->path, MAX_NODE_VISITS);
    if (mx_json_kind(node) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: nodes[%zu] is not an object", d->path, idx);
    double local[16], world[16];
    if (node_local(d, node, idx, local, st)) return -1;
    mat_mul(parent, local, world);
    size_t mesh = 0, nmesh = array_len(d->root, "meshes"), nnodes = mx_json_len(nodes);
    char what[48];
    snprintf(what, sizeof what, "nodes[%zu]", idx);
    int rc = get_uint(node, "mesh", nmesh ? nmesh : 1, &mesh, what, d->path, st);
    if (rc < 0 || (rc == 0 && !nmesh)) return mx_fail(st, MX_EINPUT, "%s: nodes[%zu]: bad mesh index", d->path, idx);
    if (rc == 0 && add_mesh(d, mesh, world, default_mat, g, st)) return -1;
    const mx_json *kids = mx_json_get(node, "children");
    for (size_t i = 0; kids && i < mx_json_len(kids); i++) {
        const mx_json *k = mx_json_at(kids, i);
        double v = mx_json_kind(k) == MX_JSON_NUM ? mx_json_num(k) : -1;
        if (!(v >= 0 && v < (double)nnodes && v == floor(v)))
            return mx_fail(st, MX_EINPUT, "%s: nodes[%zu].children[%zu] out of range", d->path, idx, i);
        if (visit_node(d, (size_t)v, world, depth + 1, default_mat, g, st)) return -1;
    }
    return 0;
}

/* Root nodes: the default scene's, else scenes[0]'s, else every node that is nobody's child. */
static int visit_roots(const gltf_doc *d, int32_t default_mat, merged *g, mx_status *st) {
    static const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    size_t nnodes = array_len(d->root, "nodes"), nscenes = array_len(d->root, "scenes"), scene = 0;
    if (nscenes) {
        if (get_uint(d->root, "scene", nscenes, &scene, "glTF", d->path, st) < 0) return -1;
        const mx_json *roots = mx_json_get(mx_json_at(mx_json_get(d->root, "scenes"), scene), "nodes");
        for (size_t i = 0; roots && i < mx_json_len(roots); i++) {
            const mx_json *k = mx_json_at(roots, i);
            double v = mx_json_kind(k) == MX_JSON_NUM ? mx_json_num(k) : -1;
            if (!(v >= 0 && v < (double)nnodes && v == floor(v)))
                return mx_fail(st, MX_EINPUT, "%s: scenes[%zu].nodes[%zu] out of range", d->path, scene, i);
            if (visit_node(d, (size_t)v, id, 0, default_mat, g, st)) return -1;
        }
        return 0;
    }
    char *is_child = calloc(nnodes + 1, 1);
    if (!is_child) return mx_fail(st, MX_ENOMEM, "%s: out of memory", d->path);
    const mx_json *nodes = mx_json_get(d->root, "nodes");
    for (size_t i = 0; i < nnodes; i++) {
        const mx_json *kids = mx_json_get(mx_json_at(nodes, i), "children");
        for (size_t k = 0; kids && k < mx_json_len(kids); k++) {
            double v = mx_json_num(mx_json_at(kids, k));
            if (v >= 0 && v < (double)nnodes) is_child[(size_t)v] = 1;
        }
    }
    int rc = 0;
    for (size_t i = 0; i < nnodes && !rc; i++)
        if (!is_child[i]) rc = visit_node(d, i, id, 0, default_mat, g, st);
    free(is_child);
    return rc;
}

/* ---- materials ---- */

/* The images[] index of a material's baseColorTexture, or -1. */
static long base_color_image(const gltf_doc *d, const mx_json *mat) {
    const mx_json *tex = mx_json_get(mx_json_get(mat, "pbrMetallicRoughness"), "baseColorTexture");
    size_t ti = 0, src = 0;
    if (!tex || get_uint(tex, "index", array_len(d->root, "textures") + 1, &ti, "baseColorTexture", d->path, NULL) ||
        ti >= array_len(d->root, "textures"))
        return -1;
    const mx_json *t = mx_json_at(mx_json_get(d->root, "textures"), ti);
    if (get_uint(t, "source", array_len(d->root, "images") + 1, &src, "texture", d->path, NULL) ||
        src >= array_len(d->root, "images"))
        return -1;
    return (long)src;
}

static void material_texture(const gltf_doc *d, long img, char *out, size_t cap) {
    out[0] = 0;
    if (img < 0) return;
    const mx_json *im = mx_json_at(mx_json_get(d->root, "images"), (size_t)img);
    const char *uri = mx_json_get_str(im, "uri", NULL);
    mx_status ignore;
    if (uri && strncmp(uri, "data:", 5)) {
        if (resolve_uri(d, uri, out, cap, &ignore)) out[0] = 0;
        FILE *f = out[0] ? fopen(out, "rb") : NULL;
        if (!f) {
            mx_warn("%s: texture image %s not found; ignored", d->path, uri);
            out[0] = 0;
        } else {
            fclose(f);
        }
        return;
    }
    snprintf(out, cap, "%s#image%ld", d->path, img);
}

static int build_materials(const gltf_doc *d, mx_mesh *m, int need_default, mx_status *st) {
    size_t n = array_len(d->root, "materials");
    m->nmat = (int)n + (need_default || n == 0);
    m->mats = calloc((size_t)m->nmat, sizeof *m->mats);
    if (!m->mats) return mx_fail(st, MX_ENOMEM, "%s: out of memory", d->path);
    for (size_t i = 0; i < n; i++) {
        const mx_json *mat = mx_json_at(mx_json_get(d->root, "materials"), i);
        const char *name = mx_json_get_str(mat, "name", NULL);
        if (name) snprintf(m->mats[i].name, sizeof m->mats[i].name, "%s", name);
        else snprintf(m->mats[i].name, sizeof m->mats[i].name, "material%zu", i);
        material_texture(d, base_color_image(d, mat), m->mats[i].texture_path, sizeof m->mats[i].texture_path);
    }
    if ((size_t)m->nmat > n) snprintf(m->mats[n].name, sizeof m->mats[n].name, "default");
    return 0;
}

/* Moves the merged arrays into the mesh; faces of primitives without UV/normal get index -1. */
static int finish_mesh(const gltf_doc *d, merged *g, mx_mesh *m, mx_status *st) {
    if (g->nfaces == 0) return mx_fail(st, MX_EINPUT, "%s: no triangles in the default scene", d->path);
    m->nverts = (int)g->nverts;
    m->nfaces = (int)g->nfaces;
    m->pos = g->pos;
    m->faces = g->faces;
    m->face_mat = g->face_mat;
    g->pos = NULL;
    g->faces = g->face_mat = NULL;
    int32_t **lists[2] = {&m->face_uv, &m->face_nrm};
    const int32_t *has[2] = {g->face_has_uv, g->face_has_nrm};
    int any[2] = {g->any_uv, g->any_nrm};
    for (int a = 0; a < 2; a++) {
        if (!any[a]) continue;
        *lists[a] = malloc(g->nfaces * 3 * sizeof(int32_t));
        if (!*lists[a]) return mx_fail(st, MX_ENOMEM, "%s: out of memory", d->path);
        for (size_t i = 0; i < 3 * g->nfaces; i++) (*lists[a])[i] = has[a][i / 3] ? m->faces[i] : -1;
    }
    if (g->any_uv) {
        m->nuv = (int)g->nverts;
        m->uv = g->uv;
        g->uv = NULL;
    }
    if (g->any_nrm) {
        m->nnrm = (int)g->nverts;
        m->nrm = g->nrm;
        g->nrm = NULL;
    }
    return 0;
}

static void merged_free(merged *g) {
    free(g->pos);
    free(g->uv);
    free(g->nrm);
    free(g->faces);
    free(g->face_mat);
    free(g->face_has_uv);
    free(g->face_has_nrm);
}

int mx_gltf_load(const char *path, mx_mesh *m, mx_status *st) {
    memset(m, 0, sizeof *m);
    gltf_doc d;
    if (doc_open(&d, path, st)) return -1;
    merged g = {0};
    int32_t default_mat = (int32_t)array_len(d.root, "materials");
    int rc = visit_roots(&d, default_mat, &g, st);
    if (!rc) {
        int need_default = 0;
        for (size_t f = 0; f < g.nfaces; f++) need_default |= g.face_mat[f] == default_mat;
        rc = finish_mesh(&d, &g, m, st);
        if (!rc) rc = build_materials(&d, m, need_default, st);
    }
    merged_free(&g);
    doc_free(&d);
    if (rc) {
        mx_mesh_free(m);
        return -1;
    }
    snprintf(m->source_path, sizeof m->source_path, "%s", path);
    return 0;
}

int mx_gltf_read_image(const char *path, int index, mx_image *img, mx_status *st) {
    memset(img, 0, sizeof *img);
    gltf_doc d;
    if (doc_open(&d, path, st)) return -1;
    int rc = -1;
    char what[1100];
    snprintf(what, sizeof what, "%s image %d", path, index);
    const mx_json *im = mx_json_at(mx_json_get(d.root, "images"), (size_t)index);
    if (index < 0 || (size_t)index >= array_len(d.root, "images") || mx_json_kind(im) != MX_JSON_OBJ) {
        mx_fail(st, MX_EINPUT, "%s: no such image", what);
    } else if (mx_json_get(im, "bufferView")) {
        const mx_json *view = get_ref(&d, im, "bufferView", "bufferViews", what, st);
        const unsigned char *data;
        size_t len, stride;
        if (view && !view_bytes(&d, view, &data, &len, &stride, what, st)) rc = mx_io_decode_image(data, len, what, img, st);
    } else {
        const char *uri = mx_json_get_str(im, "uri", "");
        if (!strncmp(uri, "data:", 5)) {
            blob b = {0};
            if (!decode_data_uri(uri, &b, what, st)) rc = mx_io_decode_image(b.data, b.len, what, img, st);
            free(b.data);
        } else {
            char file[2048];
            if (!resolve_uri(&d, uri, file, sizeof file, st)) rc = mx_io_read_image(file, img, st);
        }
    }
    doc_free(&d);
    return rc;
}
