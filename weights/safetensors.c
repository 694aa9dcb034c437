/* safetensors reader (mmap) and writer. Every number taken from the header is checked:
 * header length against the file, dtype names, shape x dtype size == end - begin, offsets
 * inside the data area. Tensors are sorted by name so lookups are binary searches and
 * duplicate names are refused. */
#include "safetensors.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../runtime/atomic_file.h"
#include "../runtime/buf.h"
#include "../runtime/json.h"
#include "../runtime/half.h"

#define ST_MAX_HEADER ((uint64_t)100 << 20) /* the reference implementation's limit */
#define ST_MAX_DIMS 8

static const struct {
    const char *name;
    mx_st_dtype dt;
    size_t size;
} st_dtypes[] = {
    {"F32", MX_ST_F32, 4}, {"F16", MX_ST_F16, 2}, {"BF16", MX_ST_BF16, 2},
    {"I64", MX_ST_I64, 8}, {"I32", MX_ST_I32, 4}, {"F64", MX_ST_F64, 8}, {"U8", MX_ST_U8, 1},
};

static size_t st_dtype_size(mx_st_dtype dt) {
    for (size_t i = 0; i < sizeof st_dtypes / sizeof st_dtypes[0]; i++)
        if (st_dtypes[i].dt == dt) return st_dtypes[i].size;
    return 0;
}

static const char *st_dtype_name(mx_st_dtype dt) {
    for (size_t i = 0; i < sizeof st_dtypes / sizeof st_dtypes[0]; i++)
        if (st_dtypes[i].dt == dt) return st_dtypes[i].name;
    return "?";
}

/* A JSON number that is a non-negative integer exactly representable in a double. */
static int json_uint(const mx_json *j, uint64_t *out) {
    if (mx_json_kind(j) != MX_JSON_NUM) return -1;
    double v = mx_json_num(j);
    if (!(v >= 0 && v <= 9007199254740992.0) || v != (double)(uint64_t)v) return -1;
    *out = (uint64_t)v;
    return 0;
}

int mx_st_map_file(mx_safetensors *f, const char *path, long long min_len, const char *kind, const char *too_short,
                   mx_status *st) {
    int fd = open(path, O_RDONLY);
    if (fd < 0) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) != 0 || !S_ISREG(sb.st_mode)) {
        close(fd);
        return mx_fail(st, MX_EINPUT, "%s: not a regular file", path);
    }
    if (sb.st_size < min_len) {
        close(fd);
        return mx_fail(st, MX_EINPUT, "%s: not a %s (%lld bytes, %s)", path, kind, (long long)sb.st_size, too_short);
    }
    void *m = mmap(NULL, (size_t)sb.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (m == MAP_FAILED) return mx_fail(st, MX_EIO, "%s: mmap failed: %s", path, strerror(errno));
    f->map = m;
    f->map_len = (size_t)sb.st_size;
    return 0;
}

static int parse_dtype(const mx_json *j, mx_st_dtype *dt, size_t *size) {
    const char *s = mx_json_str(j);
    if (!s) return -1;
    for (size_t i = 0; i < sizeof st_dtypes / sizeof st_dtypes[0]; i++)
        if (!strcmp(s, st_dtypes[i].name)) {
            *dt = st_dtypes[i].dt;
            *size = st_dtypes[i].size;
            return 0;
        }
    return -1;
}

static int parse_tensor_entry(mx_safetensors *f, mx_st_tensor *t, const char *name, const mx_json *e,
                              const uint8_t *data, uint64_t data_len, mx_status *st) {
    const char *path = f->path;
    if (mx_json_kind(e) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: tensor '%s': entry is not an object", path, name);
    size_t esize;
    const mx_json *jd = mx_json_get(e, "dtype");
    if (parse_dtype(jd, &t->dtype, &esize)) {
        const char *s = mx_json_str(jd);
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': unsupported dtype '%s' (F32, F16, BF16, F64, I64, I32, U8 are read)",
                       path, name, s ? s : "(missing)");
    }
    const mx_json *js = mx_json_get(e, "shape");
    if (mx_json_kind(js) != MX_JSON_ARR || mx_json_len(js) > ST_MAX_DIMS)
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': shape missing or more than %d dimensions", path, name,
                       ST_MAX_DIMS);
    t->ndim = (int)mx_json_len(js);
    uint64_t bytes = esize;
    for (int d = 0; d < t->ndim; d++) {
        uint64_t dim;
        if (json_uint(mx_json_at(js, (size_t)d), &dim))
            return mx_fail(st, MX_EINPUT, "%s: tensor '%s': shape entry %d is not a non-negative integer", path,
                           name, d);
        t->shape[d] = (int64_t)dim;
        if (dim && bytes > data_len / dim + 1) /* product exceeds the file: stop before overflow */
            bytes = UINT64_MAX;
        else
            bytes *= dim;
    }
    const mx_json *jo = mx_json_get(e, "data_offsets");
    uint64_t begin, end;
    if (mx_json_kind(jo) != MX_JSON_ARR || mx_json_len(jo) != 2 || json_uint(mx_json_at(jo, 0), &begin) ||
        json_uint(mx_json_at(jo, 1), &end))
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': data_offsets must be [begin, end]", path, name);
    if (begin > end || end > data_len)
        return mx_fail(st, MX_EINPUT,
                       "%s: tensor '%s': data_offsets [%llu, %llu] outside the data area of %llu bytes "
                       "(truncated file?)",
                       path, name, (unsigned long long)begin, (unsigned long long)end,
                       (unsigned long long)data_len);
    if (bytes != end - begin)
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': shape x %s size does not match data_offsets (%llu bytes)",
                       path, name, st_dtype_name(t->dtype), (unsigned long long)(end - begin));
    t->data = data + begin;
    t->nbytes = (size_t)bytes;
    return 0;
}

/* Copies the string -> string __metadata__ object back into JSON text. */
static int metadata_to_json(mx_safetensors *f, const mx_json *m, mx_status *st) {
    if (mx_json_kind(m) != MX_JSON_OBJ) return mx_fail(st, MX_EINPUT, "%s: __metadata__ is not an object", f->path);
    size_t cap = 3, n = mx_json_len(m);
    for (size_t i = 0; i < n; i++) {
        const mx_json *v = mx_json_at(m, i);
        if (mx_json_kind(v) != MX_JSON_STR)
            return mx_fail(st, MX_EINPUT, "%s: __metadata__ value of '%s' is not a string", f->path,
                           mx_json_key(m, i));
        /* every byte may become a 6-byte \u00XX escape */
        cap += 6 * (strlen(mx_json_key(m, i)) + mx_json_str_len(v)) + 6;
    }
    char *out = malloc(cap), *o = out;
    if (!out) return mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
    *o++ = '{';
    for (size_t i = 0; i < n; i++) {
        const mx_json *v = mx_json_at(m, i);
        const char *parts[2] = {mx_json_key(m, i), mx_json_str(v)};
        size_t lens[2] = {strlen(parts[0]), mx_json_str_len(v)};
        if (i) *o++ = ',';
        for (int p = 0; p < 2; p++) {
            *o++ = '"';
            for (size_t k = 0; k < lens[p]; k++) {
                unsigned char c = (unsigned char)parts[p][k];
                if (c == '"' || c == '\\') *o++ = '\\', *o++ = (char)c;
                else if (c < 0x20) o += sprintf(o, "\\u%04x", c);
                else *o++ = (char)c;
            }
            *o++ = '"';
            if (p == 0) *o++ = ':';
        }
    }
    *o++ = '}';
    *o = 0;
    f->metadata_json = out;
    return 0;
}

static int cmp_tensor_name(const void *a, const void *b) {
    return strcmp(((const mx_st_tensor *)a)->name, ((const mx_st_tensor *)b)->name);
}

static int parse_header(mx_safetensors *f, mx_status *st) {
    const uint8_t *m = f->map;
    uint64_t n = 0;
    for (int i = 7; i >= 0; i--) n = (n << 8) | m[i];
    if (n > f->map_len - 8 || n > ST_MAX_HEADER)
        return mx_fail(st, MX_EINPUT, "%s: header length %llu exceeds the file size %zu (truncated or not safetensors)",
                       f->path, (unsigned long long)n, f->map_len);
    mx_json *root = mx_json_parse((const char *)m + 8, (size_t)n, f->path, st);
    if (!root) return -1;
    int rc = -1;
    size_t count = mx_json_len(root);
    if (mx_json_kind(root) != MX_JSON_OBJ) {
        mx_fail(st, MX_EINPUT, "%s: header is not a JSON object", f->path);
        goto done;
    }
    f->tensors = calloc(count ? count : 1, sizeof *f->tensors);
    if (!f->tensors) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
        goto done;
    }
    const uint8_t *data = m + 8 + n;
    uint64_t data_len = f->map_len - 8 - n;
    for (size_t i = 0; i < count; i++) {
        const char *key = mx_json_key(root, i);
        if (!strcmp(key, "__metadata__")) {
            if (f->metadata_json) {
                mx_fail(st, MX_EINPUT, "%s: duplicate __metadata__", f->path);
                goto done;
            }
            if (metadata_to_json(f, mx_json_at(root, i), st)) goto done;
            continue;
        }
        mx_st_tensor *t = &f->tensors[f->count];
        t->name = strdup(key);
        if (!t->name) {
            mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
            goto done;
        }
        f->count++;
        if (parse_tensor_entry(f, t, key, mx_json_at(root, i), data, data_len, st)) goto done;
    }
    qsort(f->tensors, f->count, sizeof *f->tensors, cmp_tensor_name);
    for (size_t i = 1; i < f->count; i++)
        if (!strcmp(f->tensors[i - 1].name, f->tensors[i].name)) {
            mx_fail(st, MX_EINPUT, "%s: duplicate tensor name '%s'", f->path, f->tensors[i].name);
            goto done;
        }
    rc = 0;
done:
    mx_json_free(root);
    return rc;
}

int mx_st_open(mx_safetensors *f, const char *path, mx_status *st) {
    memset(f, 0, sizeof *f);
    f->path = strdup(path);
    if (!f->path) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    if (mx_st_map_file(f, path, 8, "safetensors file", "header length needs 8", st) || parse_header(f, st)) {
        mx_st_close(f);
        return -1;
    }
    return 0;
}

void mx_st_close(mx_safetensors *f) {
    if (!f) return;
    for (size_t i = 0; i < f->count; i++) free(f->tensors[i].name);
    free(f->tensors);
    free(f->metadata_json);
    if (f->map) munmap(f->map, f->map_len);
    free(f->path);
    memset(f, 0, sizeof *f);
}

void mx_st_sort(mx_safetensors *f) { qsort(f->tensors, f->count, sizeof *f->tensors, cmp_tensor_name); }

const mx_st_tensor *mx_st_find(const mx_safetensors *f, const char *name) {
    size_t lo = 0, hi = f->count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        int c = strcmp(f->tensors[mid].name, name);
        if (c == 0) return &f->tensors[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid;
    }
    return NULL;
}

float *mx_st_to_f32(const mx_safetensors *f, const mx_st_tensor *t, mx_status *st) {
    size_t es = st_dtype_size(t->dtype);
    size_t n = es ? t->nbytes / es : 0;
    float *out = malloc((n ? n : 1) * sizeof *out);
    if (!out) {
        mx_fail(st, MX_ENOMEM, "%s: tensor '%s': out of memory for %zu values", f->path, t->name, n);
        return NULL;
    }
    const uint8_t *p = t->data; /* possibly unaligned: read element by element with memcpy */
    for (size_t i = 0; i < n; i++, p += es) {
        switch (t->dtype) {
        case MX_ST_F32: memcpy(&out[i], p, 4); break;
        case MX_ST_F16: {
            uint16_t h;
            memcpy(&h, p, 2);
            out[i] = mx_half_to_float(h);
            break;
        }
        case MX_ST_BF16: {
            uint16_t h;
            memcpy(&h, p, 2);
            out[i] = mx_bf16_to_float(h);
            break;
        }
        case MX_ST_I64: {
            int64_t v;
            memcpy(&v, p, 8);
            out[i] = (float)v;
            break;
        }
        case MX_ST_I32: {
            int32_t v;
            memcpy(&v, p, 4);
            out[i] = (float)v;
            break;
        }
        case MX_ST_F64: {
            double v;
            memcpy(&v, p, 8);
            out[i] = (float)v;
            break;
        }
        case MX_ST_U8: out[i] = (float)*p; break;
        }
    }
    return out;
}

/* ---- writer ---- */

static int build_write_header(mx_buf *b, const mx_st_out *t, size_t n, uint64_t *data_len, const char *path,
                              mx_status *st) {
    uint64_t off = 0;
    mx_buf_put(b, "{", 1);
    for (size_t i = 0; i < n; i++) {
        if (t[i].dtype != MX_ST_F32 && t[i].dtype != MX_ST_I64)
            return mx_fail(st, MX_EINTERNAL, "%s: tensor '%s': only F32 and I64 are written", path, t[i].name);
        if (t[i].ndim < 0 || t[i].ndim > ST_MAX_DIMS)
            return mx_fail(st, MX_EINTERNAL, "%s: tensor '%s': %d dimensions", path, t[i].name, t[i].ndim);
        int64_t numel = mx_shape_numel(t[i].ndim, t[i].shape);
        size_t es = st_dtype_size(t[i].dtype);
        if (numel < 0 || (uint64_t)numel > (UINT64_MAX - off) / es)
            return mx_fail(st, MX_EINTERNAL, "%s: tensor '%s': bad shape", path, t[i].name);
        uint64_t bytes = (uint64_t)numel * es;
        if (i) mx_buf_put(b, ",", 1);
        mx_buf_json_str(b, t[i].name);
        mx_buf_printf(b, ":{\"dtype\":\"%s\",\"shape\":[", st_dtype_name(t[i].dtype));
        for (int d = 0; d < t[i].ndim; d++) mx_buf_printf(b, d ? ",%lld" : "%lld", (long long)t[i].shape[d]);
        mx_buf_printf(b, "],\"data_offsets\":[%llu,%llu]}", (unsigned long long)off,
                      (unsigned long long)(off + bytes));
        off += bytes;
    }
    mx_buf_put(b, "}", 1);
    while (b->len % 8) mx_buf_put(b, " ", 1); /* data starts 8-byte aligned */
    if (b->oom) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    *data_len = off;
    return 0;
}

static int write_all(FILE *fp, const void *p, size_t n) { return n == 0 || fwrite(p, 1, n, fp) == n ? 0 : -1; }

static int write_body(FILE *fp, const mx_buf *hdr, const mx_st_out *t, size_t n) {
    uint8_t len8[8];
    for (int i = 0; i < 8; i++) len8[i] = (uint8_t)((uint64_t)hdr->len >> (8 * i));
    if (write_all(fp, len8, 8) || write_all(fp, hdr->p, hdr->len)) return -1;
    for (size_t i = 0; i < n; i++) {
        size_t bytes = (size_t)mx_shape_numel(t[i].ndim, t[i].shape) * st_dtype_size(t[i].dtype);
        if (write_all(fp, t[i].data, bytes)) return -1;
    }
    return 0;
}

int mx_st_write(const char *path, const mx_st_out *tensors, size_t n, mx_status *st) {
    mx_buf hdr = {0};
    uint64_t data_len;
    mx_atomic_file af;
    int rc = -1;
    if (!build_write_header(&hdr, tensors, n, &data_len, path, st) && !mx_atomic_open(&af, path, st))
        rc = mx_atomic_close(&af, write_body(af.fp, &hdr, tensors, n) == 0, st);
    mx_buf_free(&hdr);
    return rc;
}
