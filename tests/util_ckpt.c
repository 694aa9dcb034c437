/* Checkpoint writers for tests (util_ckpt.h). The pickle opcodes are those torch.save emits
 * with protocol 2 (torch/serialization.py: _save, persistent_id). */
#include "util_ckpt.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void put_le(mx_buf *b, uint64_t v, int n) {
    unsigned char c[8];
    for (int i = 0; i < n; i++) c[i] = (unsigned char)(v >> (8 * i));
    mx_buf_put(b, c, (size_t)n);
}

static uint32_t crc32_of(const void *p, size_t n) {
    uint32_t c = 0xFFFFFFFFu;
    const unsigned char *s = p;
    for (size_t i = 0; i < n; i++) {
        c ^= s[i];
        for (int k = 0; k < 8; k++) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1)));
    }
    return ~c;
}

static int write_buf(const char *path, const mx_buf *b) {
    FILE *f = fopen(path, "wb");
    if (!f) return -1;
    size_t w = b->len ? fwrite(b->p, 1, b->len, f) : 0;
    return (fclose(f) != 0 || w != b->len || b->oom) ? -1 : 0;
}

int mx_test_write_zip(const char *path, const mx_test_zip_entry *e, size_t n) {
    mx_buf b = {0}, cd = {0};
    for (size_t i = 0; i < n; i++) {
        size_t nl = strlen(e[i].name), off = b.len;
        uint64_t sz = e[i].declared_size ? e[i].declared_size : e[i].size;
        uint32_t crc = crc32_of(e[i].data, e[i].size);
        /* pad the extra field so the data starts on a 64-byte boundary, as torch.save does */
        size_t extra = (64 - (off + 30 + nl + 4) % 64) % 64 + 4;
        put_le(&b, 0x04034b50, 4);
        put_le(&b, 20, 2), put_le(&b, 0, 2), put_le(&b, (uint64_t)e[i].method, 2), put_le(&b, 0, 4);
        put_le(&b, crc, 4), put_le(&b, sz, 4), put_le(&b, sz, 4);
        put_le(&b, nl, 2), put_le(&b, extra, 2);
        mx_buf_put(&b, e[i].name, nl);
        put_le(&b, 0x1234, 2), put_le(&b, extra - 4, 2); /* an unknown extra field: padding */
        for (size_t k = 0; k < extra - 4; k++) mx_buf_put(&b, "Z", 1);
        mx_buf_put(&b, e[i].data, e[i].size);
        put_le(&cd, 0x02014b50, 4);
        put_le(&cd, 20, 2), put_le(&cd, 20, 2), put_le(&cd, 0, 2), put_le(&cd, (uint64_t)e[i].method, 2);
        put_le(&cd, 0, 4), put_le(&cd, crc, 4), put_le(&cd, sz, 4), put_le(&cd, sz, 4);
        put_le(&cd, nl, 2), put_le(&cd, 0, 2), put_le(&cd, 0, 2), put_le(&cd, 0, 2), put_le(&cd, 0, 2);
        put_le(&cd, 0, 4), put_le(&cd, off, 4);
        mx_buf_put(&cd, e[i].name, nl);
    }
    size_t cd_off = b.len;
    mx_buf_put(&b, cd.p, cd.len);
    put_le(&b, 0x06054b50, 4);
    put_le(&b, 0, 2), put_le(&b, 0, 2), put_le(&b, n, 2), put_le(&b, n, 2);
    put_le(&b, cd.len, 4), put_le(&b, cd_off, 4), put_le(&b, 0, 2);
    int rc = write_buf(path, &b) || cd.oom;
    mx_buf_free(&b);
    mx_buf_free(&cd);
    return rc ? -1 : 0;
}

static void pk_str(mx_buf *b, const char *s) {
    mx_buf_put(b, "X", 1);
    put_le(b, strlen(s), 4);
    mx_buf_put(b, s, strlen(s));
}

static void pk_int(mx_buf *b, int64_t v) {
    if (v >= 0 && v < 256) {
        mx_buf_put(b, "K", 1);
        put_le(b, (uint64_t)v, 1);
    } else if (v >= INT32_MIN && v <= INT32_MAX) {
        mx_buf_put(b, "J", 1);
        put_le(b, (uint64_t)v, 4);
    } else {
        mx_buf_put(b, "\x8a\x08", 2); /* LONG1 of 8 bytes */
        put_le(b, (uint64_t)v, 8);
    }
}

static const char *storage_type(mx_st_dtype d) {
    switch (d) {
    case MX_ST_F32: return "FloatStorage";
    case MX_ST_F16: return "HalfStorage";
    case MX_ST_BF16: return "BFloat16Storage";
    case MX_ST_I64: return "LongStorage";
    case MX_ST_I32: return "IntStorage";
    case MX_ST_F64: return "DoubleStorage";
    case MX_ST_U8: return "ByteStorage";
    }
    return "?";
}

static size_t elem_size(mx_st_dtype d) {
    return d == MX_ST_U8 ? 1 : d == MX_ST_F16 || d == MX_ST_BF16 ? 2 : d == MX_ST_I64 || d == MX_ST_F64 ? 8 : 4;
}

/* _rebuild_tensor_v2(('storage', torch.XStorage, 'key', 'cpu', numel), 0, size, stride, False, OrderedDict()) */
static void pk_tensor(mx_buf *b, const mx_st_tensor *t, size_t key) {
    char k[32];
    snprintf(k, sizeof k, "%zu", key);
    mx_buf_printf(b, "ctorch._utils\n_rebuild_tensor_v2\n(");
    mx_buf_put(b, "(", 1);
    pk_str(b, "storage");
    mx_buf_printf(b, "ctorch\n%s\n", storage_type(t->dtype));
    pk_str(b, k);
    pk_str(b, "cpu");
    pk_int(b, (int64_t)(t->nbytes / elem_size(t->dtype)));
    mx_buf_put(b, "tQ", 2); /* TUPLE, BINPERSID */
    pk_int(b, 0);
    mx_buf_put(b, "(", 1);
    for (int d = 0; d < t->ndim; d++) pk_int(b, t->shape[d]);
    mx_buf_put(b, "t(", 2);
    int64_t stride[8], s = 1;
    for (int d = t->ndim; d-- > 0;) stride[d] = s, s *= t->shape[d];
    for (int d = 0; d < t->ndim; d++) pk_int(b, stride[d]);
    mx_buf_put(b, "t\x89", 2); /* requires_grad False */
    mx_buf_printf(b, "ccollections\nOrderedDict\n)R"); /* backward hooks */
    mx_buf_put(b, "tR", 2);
}

/* {"a": {"b.c": tensor, ...}, ...}: plain dicts (EMPTY_DICT, MARK, SETITEMS) by first component. */
static void pk_nested(mx_buf *b, const mx_st_tensor *t, size_t n) {
    mx_buf_put(b, "}(", 2);
    for (size_t i = 0; i < n;) {
        const char *dot = strchr(t[i].name, '.');
        if (!dot) { /* a tensor at the top */
            pk_str(b, t[i].name);
            pk_tensor(b, &t[i], i);
            i++;
            continue;
        }
        size_t glen = (size_t)(dot - t[i].name);
        char group[128];
        snprintf(group, sizeof group, "%.*s", (int)glen, t[i].name);
        pk_str(b, group);
        mx_buf_put(b, "}(", 2);
        for (; i < n && !strncmp(t[i].name, group, glen) && t[i].name[glen] == '.'; i++) {
            pk_str(b, t[i].name + glen + 1);
            pk_tensor(b, &t[i], i);
        }
        mx_buf_put(b, "u", 1);
    }
    mx_buf_put(b, "u", 1);
}

void mx_test_pickle_state_dict(mx_buf *b, const mx_st_tensor *t, size_t n, int wrap) {
    mx_buf_put(b, "\x80\x02", 2);
    if (wrap == 1) {
        mx_buf_put(b, "}q\x00(", 4);
        pk_str(b, "global_step");
        pk_int(b, 7);
        pk_str(b, "state_dict");
    }
    if (wrap == MX_TEST_NESTED) {
        pk_nested(b, t, n);
        mx_buf_put(b, ".", 1);
        return;
    }
    mx_buf_printf(b, "ccollections\nOrderedDict\n)Rq\x01(");
    for (size_t i = 0; i < n; i++) {
        pk_str(b, t[i].name);
        pk_tensor(b, &t[i], i);
    }
    mx_buf_put(b, "u", 1);
    if (wrap == 1) mx_buf_put(b, "u", 1);
    mx_buf_put(b, ".", 1);
}

int mx_test_write_torchzip(const char *path, const mx_st_tensor *t, size_t n, int wrap) {
    mx_buf pk = {0};
    mx_test_pickle_state_dict(&pk, t, n, wrap);
    mx_test_zip_entry *e = calloc(n + 3, sizeof *e);
    char (*names)[48] = calloc(n + 1, sizeof *names);
    int rc = -1;
    if (e && names && !pk.oom) {
        e[0] = (mx_test_zip_entry){.name = "archive/data.pkl", .data = pk.p, .size = pk.len};
        e[1] = (mx_test_zip_entry){.name = "archive/byteorder", .data = "little", .size = 6};
        for (size_t i = 0; i < n; i++) {
            snprintf(names[i], sizeof names[i], "archive/data/%zu", i);
            e[2 + i] = (mx_test_zip_entry){.name = names[i], .data = t[i].data, .size = t[i].nbytes};
        }
        e[2 + n] = (mx_test_zip_entry){.name = "archive/version", .data = "3\n", .size = 2};
        rc = mx_test_write_zip(path, e, n + 3);
    }
    free(e);
    free(names);
    mx_buf_free(&pk);
    return rc;
}

int mx_test_write_safetensors(const char *path, const mx_st_tensor *t, size_t n) {
    static const char *const dt[] = {"F32", "F16", "BF16", "I64", "I32", "F64"};
    mx_buf h = {0}, b = {0};
    size_t off = 0;
    mx_buf_put(&h, "{", 1);
    for (size_t i = 0; i < n; i++) {
        mx_buf_printf(&h, "%s", i ? "," : "");
        mx_buf_json_str(&h, t[i].name);
        mx_buf_printf(&h, ":{\"dtype\":\"%s\",\"shape\":[", dt[t[i].dtype]);
        for (int d = 0; d < t[i].ndim; d++) mx_buf_printf(&h, "%s%lld", d ? "," : "", (long long)t[i].shape[d]);
        mx_buf_printf(&h, "],\"data_offsets\":[%zu,%zu]}", off, off + t[i].nbytes);
        off += t[i].nbytes;
    }
    mx_buf_put(&h, "}", 1);
    while (h.len % 8) mx_buf_put(&h, " ", 1);
    put_le(&b, h.len, 8);
    mx_buf_put(&b, h.p, h.len);
    for (size_t i = 0; i < n; i++) mx_buf_put(&b, t[i].data, t[i].nbytes);
    int rc = h.oom ? -1 : write_buf(path, &b);
    mx_buf_free(&h);
    mx_buf_free(&b);
    return rc;
}
