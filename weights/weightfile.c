/* The matex weight file (weights/FORMAT.md): reader (mmap, every field validated before use)
 * and writer (sorted tables, 64-byte aligned data, dtype conversion, temp file + rename). */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../runtime/atomic_file.h"
#include "../runtime/half.h"
#include "weights.h"

#define WF_MAGIC "MATEXWF"
#define WF_VERSION 1
#define WF_HEADER_SIZE 128
#define WF_TENSOR_ENTRY 80
#define WF_META_ENTRY 32
#define WF_ALIGN 64

struct mx_weightfile {
    char *path;
    int fd; /* kept open for mx_wf_fd (the same file as the mapping); -1: none */
    const uint8_t *map;
    size_t len;
    size_t count;
    mx_wtensor *tensors; /* sorted by name */
    size_t meta_count;
    const char **meta_keys; /* sorted */
    const char **meta_vals;
};

static uint32_t rd32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t rd64(const uint8_t *p) { return (uint64_t)rd32(p) | (uint64_t)rd32(p + 4) << 32; }

/* 1 when s[0..n) is valid UTF-8 without NUL bytes. */
static int valid_utf8_text(const uint8_t *s, size_t n) {
    size_t i = 0;
    while (i < n) {
        uint8_t c = s[i];
        size_t k;
        uint32_t cp, min;
        if (c == 0) return 0;
        if (c < 0x80) {
            i++;
            continue;
        }
        if ((c & 0xE0) == 0xC0) k = 2, cp = c & 0x1F, min = 0x80;
        else if ((c & 0xF0) == 0xE0) k = 3, cp = c & 0x0F, min = 0x800;
        else if ((c & 0xF8) == 0xF0) k = 4, cp = c & 0x07, min = 0x10000;
        else return 0;
        if (n - i < k) return 0;
        for (size_t j = 1; j < k; j++) {
            if ((s[i + j] & 0xC0) != 0x80) return 0;
            cp = cp << 6 | (s[i + j] & 0x3F);
        }
        if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
        i += k;
    }
    return 1;
}

typedef struct {
    uint64_t file_size, tensor_count, tensor_off, meta_count, meta_off, str_off, str_size, data_off, data_size;
} wf_header;

/* [off, off + count * entry) inside [lo, len), count bounded before multiplying. */
static int region_ok(uint64_t off, uint64_t count, uint64_t entry, uint64_t lo, uint64_t len) {
    if (off < lo || off > len) return 0;
    return count <= (len - off) / entry;
}

static int check_header(mx_weightfile *wf, wf_header *h, mx_status *st) {
    const uint8_t *m = wf->map;
    const char *path = wf->path;
    if (wf->len < WF_HEADER_SIZE || memcmp(m, WF_MAGIC, 8))
        return mx_fail(st, MX_EINPUT, "%s: not a matex weight file (bad magic)", path);
    if (rd32(m + 8) != WF_VERSION)
        return mx_fail(st, MX_EINPUT, "%s: weight file version %u (this matex reads version %d)", path, rd32(m + 8),
                       WF_VERSION);
    if (rd32(m + 12) != WF_HEADER_SIZE) return mx_fail(st, MX_EINPUT, "%s: bad header size %u", path, rd32(m + 12));
    for (int i = 88; i < WF_HEADER_SIZE; i++)
        if (m[i]) return mx_fail(st, MX_EINPUT, "%s: reserved header bytes are not zero", path);
    h->file_size = rd64(m + 16);
    h->tensor_count = rd64(m + 24);
    h->tensor_off = rd64(m + 32);
    h->meta_count = rd64(m + 40);
    h->meta_off = rd64(m + 48);
    h->str_off = rd64(m + 56);
    h->str_size = rd64(m + 64);
    h->data_off = rd64(m + 72);
    h->data_size = rd64(m + 80);
    if (h->file_size != wf->len)
        return mx_fail(st, MX_EINPUT, "%s: file is %zu bytes but its header says %llu (truncated or damaged)", path,
                       wf->len, (unsigned long long)h->file_size);
    if (!region_ok(h->tensor_off, h->tensor_count, WF_TENSOR_ENTRY, WF_HEADER_SIZE, wf->len))
        return mx_fail(st, MX_EINPUT, "%s: tensor table (%llu entries at %llu) outside the file", path,
                       (unsigned long long)h->tensor_count, (unsigned long long)h->tensor_off);
    if (!region_ok(h->meta_off, h->meta_count, WF_META_ENTRY, WF_HEADER_SIZE, wf->len))
        return mx_fail(st, MX_EINPUT, "%s: metadata table (%llu entries at %llu) outside the file", path,
                       (unsigned long long)h->meta_count, (unsigned long long)h->meta_off);
    if (!region_ok(h->str_off, h->str_size, 1, WF_HEADER_SIZE, wf->len))
        return mx_fail(st, MX_EINPUT, "%s: string area outside the file", path);
    if (!region_ok(h->data_off, h->data_size, 1, WF_HEADER_SIZE, wf->len) || h->data_off % WF_ALIGN)
        return mx_fail(st, MX_EINPUT, "%s: data area outside the file or not 64-byte aligned", path);
    return 0;
}

/* A string of the string area: inside it, NUL-terminated, valid UTF-8 without NULs. */
static const char *get_string(const mx_weightfile *wf, const wf_header *h, uint64_t off, uint64_t len) {
    if (off < h->str_off || off - h->str_off > h->str_size || len >= h->str_size - (off - h->str_off)) return NULL;
    const uint8_t *s = wf->map + off;
    if (s[len] != 0 || !valid_utf8_text(s, (size_t)len)) return NULL;
    return (const char *)s;
}

static int check_tensor(mx_weightfile *wf, const wf_header *h, size_t i, mx_status *st) {
    const uint8_t *e = wf->map + h->tensor_off + i * WF_TENSOR_ENTRY;
    mx_wtensor *t = &wf->tensors[i];
    const char *path = wf->path;
    t->name = get_string(wf, h, rd64(e), rd32(e + 8));
    if (!t->name) return mx_fail(st, MX_EINPUT, "%s: tensor %zu: bad name (outside the string area or not UTF-8)", path, i);
    if (i > 0 && strcmp(wf->tensors[i - 1].name, t->name) >= 0)
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': names not sorted or duplicated", path, t->name);
    uint32_t dt = rd32(e + 12), ndim = rd32(e + 16);
    if (dt > MX_I32) return mx_fail(st, MX_EINPUT, "%s: tensor '%s': unknown dtype %u", path, t->name, dt);
    if (ndim < 1 || ndim > MX_MAX_DIMS || rd32(e + 20))
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': %u dimensions (1..%d supported)", path, t->name, ndim, MX_MAX_DIMS);
    t->dtype = (mx_dtype)dt;
    t->ndim = (int)ndim;
    uint64_t bytes = mx_dtype_size(t->dtype);
    for (int d = 0; d < MX_MAX_DIMS; d++) {
        uint64_t dim = rd64(e + 24 + 8 * d);
        if (d >= t->ndim) {
            if (dim) return mx_fail(st, MX_EINPUT, "%s: tensor '%s': unused shape entries not zero", path, t->name);
            continue;
        }
        if (dim > (uint64_t)INT64_MAX || (dim && bytes > h->data_size / dim + 1))
            return mx_fail(st, MX_EINPUT, "%s: tensor '%s': shape larger than the data area", path, t->name);
        t->shape[d] = (int64_t)dim;
        bytes *= dim;
    }
    uint64_t off = rd64(e + 64), nbytes = rd64(e + 72);
    if (nbytes != bytes)
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': byte size %llu does not match its shape and dtype (%llu)", path,
                       t->name, (unsigned long long)nbytes, (unsigned long long)bytes);
    if (off % WF_ALIGN || off < h->data_off || off - h->data_off > h->data_size ||
        nbytes > h->data_size - (off - h->data_off))
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': data [%llu, +%llu) outside the data area or not 64-byte aligned",
                       path, t->name, (unsigned long long)off, (unsigned long long)nbytes);
    t->data = wf->map + off;
    t->nbytes = (size_t)nbytes;
    return 0;
}

static int cmp_data_ptr(const void *a, const void *b) {
    const mx_wtensor *x = *(const mx_wtensor *const *)a, *y = *(const mx_wtensor *const *)b;
    const uint8_t *px = x->data, *py = y->data;
    return px < py ? -1 : px > py;
}

static int check_no_overlap(mx_weightfile *wf, mx_status *st) {
    if (wf->count < 2) return 0;
    const mx_wtensor **order = malloc(wf->count * sizeof *order);
    if (!order) return mx_fail(st, MX_ENOMEM, "%s: out of memory", wf->path);
    size_t n = 0;
    for (size_t i = 0; i < wf->count; i++)
        if (wf->tensors[i].nbytes) order[n++] = &wf->tensors[i]; /* empty tensors overlap nothing */
    qsort(order, n, sizeof *order, cmp_data_ptr);
    int rc = 0;
    for (size_t i = 1; i < n && !rc; i++) {
        const uint8_t *prev_end = (const uint8_t *)order[i - 1]->data + order[i - 1]->nbytes;
        if ((const uint8_t *)order[i]->data < prev_end)
            rc = mx_fail(st, MX_EINPUT, "%s: tensors '%s' and '%s' overlap", wf->path, order[i - 1]->name,
                         order[i]->name);
    }
    free(order);
    return rc;
}

static int check_meta(mx_weightfile *wf, const wf_header *h, mx_status *st) {
    for (size_t i = 0; i < wf->meta_count; i++) {
        const uint8_t *e = wf->map + h->meta_off + i * WF_META_ENTRY;
        wf->meta_keys[i] = get_string(wf, h, rd64(e), rd64(e + 8));
        wf->meta_vals[i] = get_string(wf, h, rd64(e + 16), rd64(e + 24));
        if (!wf->meta_keys[i] || !wf->meta_vals[i])
            return mx_fail(st, MX_EINPUT, "%s: metadata entry %zu: bad key or value (outside the string area or not UTF-8)",
                           wf->path, i);
        if (i > 0 && strcmp(wf->meta_keys[i - 1], wf->meta_keys[i]) >= 0)
            return mx_fail(st, MX_EINPUT, "%s: metadata key '%s': keys not sorted or duplicated", wf->path,
                           wf->meta_keys[i]);
    }
    return 0;
}

static int map_file(mx_weightfile *wf, mx_status *st) {
    int fd = open(wf->path, O_RDONLY);
    if (fd < 0) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", wf->path, strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) != 0 || !S_ISREG(sb.st_mode)) {
        close(fd);
        return mx_fail(st, MX_EINPUT, "%s: not a regular file", wf->path);
    }
    if (sb.st_size < WF_HEADER_SIZE) {
        close(fd);
        return mx_fail(st, MX_EINPUT, "%s: not a matex weight file (%lld bytes, shorter than the header)", wf->path,
                       (long long)sb.st_size);
    }
    void *m = mmap(NULL, (size_t)sb.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    if (m == MAP_FAILED) {
        close(fd);
        return mx_fail(st, MX_EIO, "%s: mmap failed: %s", wf->path, strerror(errno));
    }
    wf->fd = fd;
    wf->map = m;
    wf->len = (size_t)sb.st_size;
    return 0;
}

static int load_tables(mx_weightfile *wf, mx_status *st) {
    wf_header h;
    if (check_header(wf, &h, st)) return -1;
    wf->tensors = calloc(h.tensor_count ? h.tensor_count : 1, sizeof *wf->tensors);
    wf->meta_keys = calloc(h.meta_count ? h.meta_count : 1, sizeof *wf->meta_keys);
    wf->meta_vals = calloc(h.meta_count ? h.meta_count : 1, sizeof *wf->meta_vals);
    if (!wf->tensors || !wf->meta_keys || !wf->meta_vals) return mx_fail(st, MX_ENOMEM, "%s: out of memory", wf->path);
    wf->count = (size_t)h.tensor_count;
    wf->meta_count = (size_t)h.meta_count;
    for (size_t i = 0; i < wf->count; i++)
        if (check_tensor(wf, &h, i, st)) return -1;
    return check_no_overlap(wf, st) || check_meta(wf, &h, st) ? -1 : 0;
}

int mx_wf_open(mx_weightfile **out, const char *path, mx_status *st) {
    *out = NULL;
    mx_weightfile *wf = calloc(1, sizeof *wf);
    if (!wf || !(wf->path = strdup(path))) {
        free(wf);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    }
    wf->fd = -1;
    if (map_file(wf, st) || load_tables(wf, st)) {
        mx_wf_close(wf);
        return -1;
    }
    *out = wf;
    return 0;
}

void mx_wf_close(mx_weightfile *wf) {
    if (!wf) return;
    if (wf->map) munmap((void *)wf->map, wf->len);
    if (wf->fd >= 0) close(wf->fd);
    free(wf->tensors);
    free(wf->meta_keys);
    free(wf->meta_vals);
    free(wf->path);
    free(wf);
}

const char *mx_wf_path(const mx_weightfile *wf) { return wf->path; }
int mx_wf_fd(const mx_weightfile *wf) { return wf->fd; }

const void *mx_wf_map(const mx_weightfile *wf, size_t *len) {
    *len = wf->len;
    return wf->map;
}
size_t mx_wf_count(const mx_weightfile *wf) { return wf->count; }
const mx_wtensor *mx_wf_tensor(const mx_weightfile *wf, size_t i) { return i < wf->count ? &wf->tensors[i] : NULL; }

const mx_wtensor *mx_wf_find(const mx_weightfile *wf, const char *name) {
    size_t lo = 0, hi = wf->count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        int c = strcmp(wf->tensors[mid].name, name);
        if (c == 0) return &wf->tensors[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid;
    }
    return NULL;
}

const mx_wtensor *mx_wf_require(const mx_weightfile *wf, const char *name, int ndim, const int64_t *shape,
                                mx_status *st) {
    const mx_wtensor *t = mx_wf_find(wf, name);
    if (!t) {
        mx_fail(st, MX_EINPUT, "%s: tensor '%s' not found", wf->path, name);
        return NULL;
    }
    int ok = t->ndim == ndim;
    for (int d = 0; ok && d < ndim; d++) ok = shape[d] == -1 || shape[d] == t->shape[d];
    if (!ok) {
        char want[128], got[128];
        mx_fail(st, MX_EINPUT, "%s: tensor '%s' has shape %s, expected %s", wf->path, name,
                mx_shape_str(t->ndim, t->shape, got, sizeof got), mx_shape_str(ndim, shape, want, sizeof want));
        return NULL;
    }
    return t;
}

const char *mx_wf_meta(const mx_weightfile *wf, const char *key) {
    size_t lo = 0, hi = wf->meta_count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        int c = strcmp(wf->meta_keys[mid], key);
        if (c == 0) return wf->meta_vals[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid;
    }
    return NULL;
}

size_t mx_wf_meta_count(const mx_weightfile *wf) { return wf->meta_count; }
const char *mx_wf_meta_key(const mx_weightfile *wf, size_t i) { return i < wf->meta_count ? wf->meta_keys[i] : NULL; }

/* ---- writer ---- */

typedef struct {
    char *name;
    mx_dtype dtype, src_dtype;
    int ndim;
    int64_t shape[MX_MAX_DIMS];
    const void *data;
    uint64_t nbytes, offset;
} wf_entry;

typedef struct {
    char *key, *value;
} wf_meta;

struct mx_wf_writer {
    wf_entry *entries;
    size_t count, cap;
    wf_meta *meta;
    size_t meta_count, meta_cap;
};

mx_wf_writer *mx_wf_writer_create(mx_status *st) {
    mx_wf_writer *w = calloc(1, sizeof *w);
    if (!w) mx_fail(st, MX_ENOMEM, "weight writer: out of memory");
    return w;
}

void mx_wf_writer_free(mx_wf_writer *w) {
    if (!w) return;
    for (size_t i = 0; i < w->count; i++) free(w->entries[i].name);
    for (size_t i = 0; i < w->meta_count; i++) free(w->meta[i].key), free(w->meta[i].value);
    free(w->entries);
    free(w->meta);
    free(w);
}

static int grow(void **arr, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap) return 0;
    size_t nc = *cap ? *cap * 2 : 64;
    while (nc < need) nc *= 2;
    void *p = realloc(*arr, nc * elem);
    if (!p) return -1;
    *arr = p;
    *cap = nc;
    return 0;
}

int mx_wf_writer_add(mx_wf_writer *w, const char *name, mx_dtype dtype, int ndim, const int64_t *shape,
                     const void *data, mx_dtype src_dtype, mx_status *st) {
    int is_float = dtype != MX_I32, src_float = src_dtype != MX_I32;
    if (mx_dtype_size(dtype) == 0 || mx_dtype_size(src_dtype) == 0 || is_float != src_float)
        return mx_fail(st, MX_EINTERNAL, "weight writer: tensor '%s': cannot store %s data as %s", name,
                       mx_dtype_name(src_dtype), mx_dtype_name(dtype));
    if (!valid_utf8_text((const uint8_t *)name, strlen(name)) || !*name)
        return mx_fail(st, MX_EINPUT, "weight writer: tensor name '%s' is empty or not UTF-8", name);
    int64_t numel = ndim >= 1 && ndim <= MX_MAX_DIMS ? mx_shape_numel(ndim, shape) : -1;
    if (numel < 0 || (uint64_t)numel > ((uint64_t)1 << 60) / 4) {
        char buf[128];
        return mx_fail(st, MX_EINPUT, "weight writer: tensor '%s': bad shape %s", name,
                       mx_shape_str(ndim < 0 ? 0 : ndim > MX_MAX_DIMS ? MX_MAX_DIMS : ndim, shape, buf, sizeof buf));
    }
    if (grow((void **)&w->entries, &w->cap, w->count + 1, sizeof *w->entries))
        return mx_fail(st, MX_ENOMEM, "weight writer: out of memory");
    wf_entry *e = &w->entries[w->count];
    memset(e, 0, sizeof *e);
    if (!(e->name = strdup(name))) return mx_fail(st, MX_ENOMEM, "weight writer: out of memory");
    e->dtype = dtype;
    e->src_dtype = src_dtype;
    e->ndim = ndim;
    memcpy(e->shape, shape, (size_t)ndim * sizeof *shape);
    e->data = data;
    e->nbytes = (uint64_t)numel * mx_dtype_size(dtype);
    w->count++;
    return 0;
}

int mx_wf_writer_meta(mx_wf_writer *w, const char *key, const char *value, mx_status *st) {
    if (!*key || !valid_utf8_text((const uint8_t *)key, strlen(key)) ||
        !valid_utf8_text((const uint8_t *)value, strlen(value)))
        return mx_fail(st, MX_EINPUT, "weight writer: metadata '%s': key empty or key/value not UTF-8", key);
    if (grow((void **)&w->meta, &w->meta_cap, w->meta_count + 1, sizeof *w->meta))
        return mx_fail(st, MX_ENOMEM, "weight writer: out of memory");
    wf_meta *m = &w->meta[w->meta_count];
    m->key = strdup(key);
    m->value = strdup(value);
    if (!m->key || !m->value) {
        free(m->key);
        free(m->value);
        return mx_fail(st, MX_ENOMEM, "weight writer: out of memory");
    }
    w->meta_count++;
    return 0;
}

static int cmp_entry(const void *a, const void *b) { return strcmp(((const wf_entry *)a)->name, ((const wf_entry *)b)->name); }
static int cmp_meta(const void *a, const void *b) { return strcmp(((const wf_meta *)a)->key, ((const wf_meta *)b)->key); }

static uint64_t align_up(uint64_t x) { return (x + WF_ALIGN - 1) / WF_ALIGN * WF_ALIGN; }

static void put32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static void put64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* Builds header, tables and string area in one buffer (the data area follows it). */
static uint8_t *build_front(const mx_wf_writer *w, wf_header *h) {
    uint64_t str_size = 0;
    for (size_t i = 0; i < w->count; i++) str_size += strlen(w->entries[i].name) + 1;
    for (size_t i = 0; i < w->meta_count; i++) str_size += strlen(w->meta[i].key) + strlen(w->meta[i].value) + 2;
    h->tensor_count = w->count;
    h->tensor_off = WF_HEADER_SIZE;
    h->meta_count = w->meta_count;
    h->meta_off = h->tensor_off + w->count * WF_TENSOR_ENTRY;
    h->str_off = h->meta_off + w->meta_count * WF_META_ENTRY;
    h->str_size = str_size;
    h->data_off = align_up(h->str_off + str_size);
    uint8_t *buf = calloc(1, h->data_off);
    if (!buf) return NULL;
    uint64_t s = h->str_off;
    for (size_t i = 0; i < w->count; i++) {
        const wf_entry *e = &w->entries[i];
        uint8_t *p = buf + h->tensor_off + i * WF_TENSOR_ENTRY;
        size_t n = strlen(e->name);
        memcpy(buf + s, e->name, n + 1);
        put64(p, s);
        put32(p + 8, (uint32_t)n);
        put32(p + 12, (uint32_t)e->dtype);
        put32(p + 16, (uint32_t)e->ndim);
        for (int d = 0; d < e->ndim; d++) put64(p + 24 + 8 * d, (uint64_t)e->shape[d]);
        put64(p + 64, h->data_off + e->offset);
        put64(p + 72, e->nbytes);
        s += n + 1;
    }
    for (size_t i = 0; i < w->meta_count; i++) {
        uint8_t *p = buf + h->meta_off + i * WF_META_ENTRY;
        const char *kv[2] = {w->meta[i].key, w->meta[i].value};
        for (int k = 0; k < 2; k++) {
            size_t n = strlen(kv[k]);
            memcpy(buf + s, kv[k], n + 1);
            put64(p + 16 * k, s);
            put64(p + 16 * k + 8, n);
            s += n + 1;
        }
    }
    memcpy(buf, WF_MAGIC, 8);
    put32(buf + 8, WF_VERSION);
    put32(buf + 12, WF_HEADER_SIZE);
    put64(buf + 16, h->data_off + h->data_size);
    put64(buf + 24, h->tensor_count);
    put64(buf + 32, h->tensor_off);
    put64(buf + 40, h->meta_count);
    put64(buf + 48, h->meta_off);
    put64(buf + 56, h->str_off);
    put64(buf + 64, h->str_size);
    put64(buf + 72, h->data_off);
    put64(buf + 80, h->data_size);
    return buf;
}

static float load_as_f32(const uint8_t *p, mx_dtype src) {
    uint16_t h;
    float f;
    switch (src) {
    case MX_F16: memcpy(&h, p, 2); return mx_half_to_float(h);
    case MX_BF16: memcpy(&h, p, 2); return mx_bf16_to_float(h);
    default: memcpy(&f, p, 4); return f;
    }
}

/* Converts count elements from src (possibly unaligned) into out in the entry's dtype. */
static void convert_chunk(const wf_entry *e, const uint8_t *src, size_t count, uint8_t *out) {
    size_t ss = mx_dtype_size(e->src_dtype), ds = mx_dtype_size(e->dtype);
    if (e->src_dtype == e->dtype) {
        memcpy(out, src, count * ds);
        return;
    }
    for (size_t i = 0; i < count; i++) {
        float f = load_as_f32(src + i * ss, e->src_dtype);
        uint16_t h;
        switch (e->dtype) {
        case MX_F16: h = mx_float_to_half(f); memcpy(out + 2 * i, &h, 2); break;
        case MX_BF16: h = mx_float_to_bf16(f); memcpy(out + 2 * i, &h, 2); break;
        default: memcpy(out + 4 * i, &f, 4); break;
        }
    }
}

static int write_data(FILE *fp, const mx_wf_writer *w, uint64_t pos) {
    enum { CHUNK = 1 << 16 };
    static const uint8_t zeros[WF_ALIGN];
    uint8_t *buf = malloc(CHUNK * 4);
    if (!buf) return -1;
    int rc = 0;
    for (size_t i = 0; i < w->count && !rc; i++) {
        const wf_entry *e = &w->entries[i];
        if (fwrite(zeros, 1, e->offset - pos, fp) != e->offset - pos) rc = -1;
        uint64_t numel = e->nbytes / mx_dtype_size(e->dtype);
        size_t ss = mx_dtype_size(e->src_dtype), ds = mx_dtype_size(e->dtype);
        for (uint64_t k = 0; k < numel && !rc; k += CHUNK) {
            size_t n = numel - k < CHUNK ? (size_t)(numel - k) : CHUNK;
            convert_chunk(e, (const uint8_t *)e->data + k * ss, n, buf);
            if (fwrite(buf, ds, n, fp) != n) rc = -1;
        }
        pos = e->offset + e->nbytes;
    }
    free(buf);
    return rc;
}

static int check_unique(const mx_wf_writer *w, mx_status *st) {
    for (size_t i = 1; i < w->count; i++)
        if (!strcmp(w->entries[i - 1].name, w->entries[i].name))
            return mx_fail(st, MX_EINPUT, "weight writer: tensor '%s' added twice", w->entries[i].name);
    for (size_t i = 1; i < w->meta_count; i++)
        if (!strcmp(w->meta[i - 1].key, w->meta[i].key))
            return mx_fail(st, MX_EINPUT, "weight writer: metadata key '%s' added twice", w->meta[i].key);
    return 0;
}

int mx_wf_writer_finish(mx_wf_writer *w, const char *path, mx_status *st) {
    if (w->count) qsort(w->entries, w->count, sizeof *w->entries, cmp_entry);
    if (w->meta_count) qsort(w->meta, w->meta_count, sizeof *w->meta, cmp_meta);
    if (check_unique(w, st)) return -1;
    wf_header h = {0};
    uint64_t off = 0; /* relative to the data area */
    for (size_t i = 0; i < w->count; i++) {
        w->entries[i].offset = off;
        off = align_up(off + w->entries[i].nbytes);
    }
    h.data_size = w->count ? w->entries[w->count - 1].offset + w->entries[w->count - 1].nbytes : 0;
    uint8_t *front = build_front(w, &h);
    if (!front) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);

    mx_atomic_file af;
    if (mx_atomic_open(&af, path, st)) {
        free(front);
        return -1;
    }
    int ok = fwrite(front, 1, h.data_off, af.fp) == h.data_off && write_data(af.fp, w, 0) == 0;
    free(front);
    return mx_atomic_close(&af, ok, st);
}
