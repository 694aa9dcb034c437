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

const char *mx_shape_str(int ndim, const int64_t *shape, char *buf, size_t cap) {
    size_t off = 0;
    off += (size_t)snprintf(buf + off, cap - off, "[");
    for (int i = 0; i < ndim && off < cap; i++)
        off += (size_t)snprintf(buf + off, cap - off, i ? ", %lld" : "%lld", (long long)shape[i]);
    if (off < cap) snprintf(buf + off, cap - off, "]");
    return buf;
}
