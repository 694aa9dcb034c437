#include "tensor.h"

#include <stdio.h>
#include <string.h>

size_t mx_dtype_size(mx_dtype dt) {
    switch (dt) {
    case MX_F32: return 4;
    case MX_F16: return 2;
    case MX_BF16: return 2;
    case MX_I32: return 4;
    }
    return 0;
}

const char *mx_dtype_name(mx_dtype dt) {
    switch (dt) {
    case MX_F32: return "f32";
    case MX_F16: return "f16";
    case MX_BF16: return "bf16";
    case MX_I32: return "i32";
    }
    return "?";
}

int64_t mx_shape_numel(int ndim, const int64_t *shape) {
    int64_t n = 1;
    for (int i = 0; i < ndim; i++) {
        if (shape[i] < 0) return -1;
        if (shape[i] != 0 && n > INT64_MAX / shape[i]) return -1;
        n *= shape[i];
    }
    return n;
}

int mx_tensor_init(mx_tensor *t, mx_dtype dt, int ndim, const int64_t *shape, void *data,
                   const char *what, mx_status *st) {
    if (ndim < 1 || ndim > MX_MAX_DIMS)
        return mx_fail(st, MX_EINPUT, "%s: %d dimensions (1..%d supported)", what, ndim, MX_MAX_DIMS);
    if (mx_dtype_size(dt) == 0) return mx_fail(st, MX_EINPUT, "%s: unknown dtype %d", what, (int)dt);
    int64_t n = mx_shape_numel(ndim, shape);
    if (n < 0 || n > INT64_MAX / 8) {
        char buf[128];
        return mx_fail(st, MX_EINPUT, "%s: bad shape %s", what, mx_shape_str(ndim, shape, buf, sizeof buf));
    }
    memset(t, 0, sizeof *t);
    t->dtype = dt;
    t->ndim = ndim;
    memcpy(t->shape, shape, (size_t)ndim * sizeof *shape);
    t->data = data;
    return 0;
}

int64_t mx_tensor_numel(const mx_tensor *t) { return mx_shape_numel(t->ndim, t->shape); }

size_t mx_tensor_nbytes(const mx_tensor *t) { return (size_t)mx_tensor_numel(t) * mx_dtype_size(t->dtype); }

int mx_tensor_same_shape(const mx_tensor *a, const mx_tensor *b) {
    if (a->ndim != b->ndim) return 0;
    for (int i = 0; i < a->ndim; i++)
        if (a->shape[i] != b->shape[i]) return 0;
    return 1;
}

const char *mx_shape_str(int ndim, const int64_t *shape, char *buf, size_t cap) {
    size_t off = 0;
    off += (size_t)snprintf(buf + off, cap - off, "[");
    for (int i = 0; i < ndim && off < cap; i++)
        off += (size_t)snprintf(buf + off, cap - off, i ? ", %lld" : "%lld", (long long)shape[i]);
    if (off < cap) snprintf(buf + off, cap - off, "]");
    return buf;
}
