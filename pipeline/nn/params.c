/* Parameter binders: matex weight file, safetensors file (aligned owned copies) and the
 * enumerating binder used by gen-weights. */
#include "params.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../weights/golden_rule.h"
#include "../../weights/safetensors.h"
#include "../../weights/weights.h"

int mx_bind(mx_binder *b, mx_wptr *out, mx_status *st, const char *name, int ndim, ...) {
    int64_t shape[MX_MAX_DIMS];
    if (ndim < 1 || ndim > MX_MAX_DIMS)
        return mx_fail(st, MX_EINTERNAL, "mx_bind %s: bad ndim %d", name, ndim);
    va_list ap;
    va_start(ap, ndim);
    for (int i = 0; i < ndim; i++) shape[i] = va_arg(ap, int64_t);
    va_end(ap);
    return b->bind(b, name, ndim, shape, out, st);
}

static int full_name(char *buf, size_t cap, const mx_binder *b, const char *name, mx_status *st) {
    int n = snprintf(buf, cap, "%s%s", b->prefix, name);
    if (n < 0 || (size_t)n >= cap) return mx_fail(st, MX_EINTERNAL, "parameter name too long: %s%s", b->prefix, name);
    return 0;
}

static int set_prefix(mx_binder *b, const char *prefix, mx_status *st) {
    if (!prefix) prefix = "";
    if (strlen(prefix) >= sizeof b->prefix) return mx_fail(st, MX_EUSAGE, "weight prefix too long: %s", prefix);
    snprintf(b->prefix, sizeof b->prefix, "%s", prefix);
    return 0;
}

static int shapes_equal(int na, const int64_t *a, int nb, const int64_t *b) {
    if (na != nb) return 0;
    for (int i = 0; i < na; i++)
        if (a[i] != b[i]) return 0;
    return 1;
}

/* ---- matex weight file ---- */

static int bind_wf(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st) {
    const mx_weightfile *wf = b->impl;
    char full[512];
    if (full_name(full, sizeof full, b, name, st)) return -1;
    const mx_wtensor *t = mx_wf_require(wf, full, ndim, shape, st);
    if (!t) return -1;
    if (t->dtype != MX_F32 && t->dtype != MX_F16 && t->dtype != MX_BF16)
        return mx_fail(st, MX_EINPUT, "%s: tensor %s has dtype %s, expected a float type", mx_wf_path(wf), full,
                       mx_dtype_name(t->dtype));
    out->data = t->data;
    out->dtype = t->dtype;
    return 0;
}

int mx_binder_wf(mx_binder *b, const mx_weightfile *wf, const char *prefix, mx_status *st) {
    memset(b, 0, sizeof *b);
    if (set_prefix(b, prefix, st)) return -1;
    b->bind = bind_wf;
    b->impl = (void *)wf;
    return 0;
}

/* ---- safetensors file: owned aligned copies ---- */

typedef struct st_binder {
    const mx_safetensors *f; /* NULL for the rule binder */
    uint64_t seed;           /* rule binder */
    mx_dtype dtype;          /* rule binder: MX_F32 or MX_F16 */
    void **bufs;
    size_t n, cap;
} st_binder;

static void *keep_buffer(st_binder *s, size_t bytes, mx_status *st) {
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 64;
        void **nb = realloc(s->bufs, cap * sizeof *nb);
        if (!nb) return mx_fail(st, MX_ENOMEM, "out of memory binding weights"), NULL;
        s->bufs = nb;
        s->cap = cap;
    }
    void *p = aligned_alloc(64, (bytes + 63) / 64 * 64);
    if (!p) return mx_fail(st, MX_ENOMEM, "out of memory copying a weight (%zu bytes)", bytes), NULL;
    s->bufs[s->n++] = p;
    return p;
}

static int bind_st(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st) {
    st_binder *s = b->impl;
    char full[512], want[96], got[96];
    if (full_name(full, sizeof full, b, name, st)) return -1;
    const mx_st_tensor *t = mx_st_find(s->f, full);
    if (!t) return mx_fail(st, MX_EINPUT, "%s: missing tensor %s", s->f->path, full);
    if (!shapes_equal(t->ndim, t->shape, ndim, shape))
        return mx_fail(st, MX_EINPUT, "%s: tensor %s has shape %s, expected %s", s->f->path, full,
                       mx_shape_str(t->ndim, t->shape, got, sizeof got), mx_shape_str(ndim, shape, want, sizeof want));
    size_t n = (size_t)mx_shape_numel(ndim, shape);
    if (t->dtype == MX_ST_F32 || t->dtype == MX_ST_F16 || t->dtype == MX_ST_BF16) {
        size_t es = t->dtype == MX_ST_F32 ? 4 : 2;
        if (t->nbytes != n * es) return mx_fail(st, MX_EINPUT, "%s: tensor %s: byte size does not match its shape", s->f->path, full);
        void *p = keep_buffer(s, t->nbytes, st);
        if (!p) return -1;
        memcpy(p, t->data, t->nbytes);
        out->data = p;
        out->dtype = t->dtype == MX_ST_F32 ? MX_F32 : t->dtype == MX_ST_F16 ? MX_F16 : MX_BF16;
        return 0;
    }
    if (t->dtype == MX_ST_F64) {
        float *tmp = mx_st_to_f32(s->f, t, st);
        if (!tmp) return -1;
        void *p = keep_buffer(s, n * sizeof(float), st);
        if (p) memcpy(p, tmp, n * sizeof(float));
        free(tmp);
        if (!p) return -1;
        out->data = p;
        out->dtype = MX_F32;
        return 0;
    }
    return mx_fail(st, MX_EINPUT, "%s: tensor %s is not a float tensor", s->f->path, full);
}

int mx_binder_st(mx_binder *b, const mx_safetensors *f, const char *prefix, mx_status *st) {
    memset(b, 0, sizeof *b);
    if (set_prefix(b, prefix, st)) return -1;
    st_binder *s = calloc(1, sizeof *s);
    if (!s) return mx_fail(st, MX_ENOMEM, "out of memory");
    s->f = f;
    b->bind = bind_st;
    b->impl = s;
    return 0;
}

/* ---- golden-v1 rule: owned generated copies (shares the safetensors binder's storage) ---- */

static int bind_rule(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st) {
    st_binder *s = b->impl;
    int64_t numel = mx_shape_numel(ndim, shape);
    if (numel < 0) return mx_fail(st, MX_EINTERNAL, "parameter %s: bad shape", name);
    size_t n = (size_t)numel;
    float *f32 = keep_buffer(s, n * sizeof(float), st);
    if (!f32) return -1;
    mx_golden_v1_fill(name, ndim, shape, s->seed, f32);
    out->data = f32;
    out->dtype = MX_F32;
    if (s->dtype == MX_F16) { /* narrowed in place: the fp16 values fill the first half */
        uint16_t *h = (uint16_t *)f32;
        for (size_t i = 0; i < n; i++) h[i] = mx_float_to_half(f32[i]);
        out->dtype = MX_F16;
    }
    return 0;
}

int mx_binder_rule(mx_binder *b, uint64_t seed, mx_dtype dtype, mx_status *st) {
    memset(b, 0, sizeof *b);
    if (dtype != MX_F32 && dtype != MX_F16) return mx_fail(st, MX_EINTERNAL, "mx_binder_rule: dtype must be F32 or F16");
    st_binder *s = calloc(1, sizeof *s);
    if (!s) return mx_fail(st, MX_ENOMEM, "out of memory");
    s->seed = seed;
    s->dtype = dtype;
    b->bind = bind_rule;
    b->impl = s;
    return 0;
}

static void free_st(st_binder *s) {
    for (size_t i = 0; i < s->n; i++) free(s->bufs[i]);
    free(s->bufs);
    free(s);
}

/* ---- enumerating binder ---- */

typedef struct enum_binder {
    mx_param_info *list;
    size_t n, cap;
} enum_binder;

static int bind_enum(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st) {
    enum_binder *e = b->impl;
    /* ndim 0: a scalar (a LoRA's alpha, `gen-weights --lcm-lora`); no network binds one */
    if (ndim < 0 || ndim > MX_MAX_DIMS || mx_shape_numel(ndim, shape) < 0)
        return mx_fail(st, MX_EINTERNAL, "parameter %s: bad shape", name);
    if (e->n == e->cap) {
        size_t cap = e->cap ? 2 * e->cap : 256;
        mx_param_info *nl = realloc(e->list, cap * sizeof *nl);
        if (!nl) return mx_fail(st, MX_ENOMEM, "out of memory enumerating parameters");
        e->list = nl;
        e->cap = cap;
    }
    mx_param_info *p = &e->list[e->n];
    p->name = strdup(name);
    if (!p->name) return mx_fail(st, MX_ENOMEM, "out of memory enumerating parameters");
    p->ndim = ndim;
    memset(p->shape, 0, sizeof p->shape);
    memcpy(p->shape, shape, (size_t)ndim * sizeof *shape);
    e->n++;
    *out = mx_w_none();
    return 0;
}

int mx_binder_enum(mx_binder *b, mx_status *st) {
    memset(b, 0, sizeof *b);
    enum_binder *e = calloc(1, sizeof *e);
    if (!e) return mx_fail(st, MX_ENOMEM, "out of memory");
    b->bind = bind_enum;
    b->impl = e;
    b->enumerating = 1;
    return 0;
}

size_t mx_binder_enum_count(const mx_binder *b) {
    return b->enumerating ? ((const enum_binder *)b->impl)->n : 0;
}

const mx_param_info *mx_binder_enum_at(const mx_binder *b, size_t i) {
    if (!b->enumerating || i >= ((const enum_binder *)b->impl)->n) return NULL;
    return &((const enum_binder *)b->impl)->list[i];
}

size_t mx_binder_enum_bytes(const mx_binder *b) {
    size_t total = 0;
    for (size_t i = 0; i < mx_binder_enum_count(b); i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        total += (size_t)mx_shape_numel(p->ndim, p->shape) * sizeof(float);
    }
    return total;
}

/* ---- weights on a device ---- */

typedef struct device_binder {
    mx_binder *inner;
    const mx_ctx *c;
    void **bufs;
    size_t n, cap;
} device_binder;

static int keep_device_buffer(device_binder *d, void *p, mx_status *st) {
    if (d->n == d->cap) {
        size_t cap = d->cap ? 2 * d->cap : 256;
        void **b = realloc(d->bufs, cap * sizeof *b);
        if (!b) return mx_fail(st, MX_ENOMEM, "out of memory binding weights");
        d->bufs = b;
        d->cap = cap;
    }
    d->bufs[d->n++] = p;
    return 0;
}

static int bind_device(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st) {
    device_binder *d = b->impl;
    mx_backend *be = d->c->be;
    if (d->inner->bind(d->inner, name, ndim, shape, out, st)) return -1;
    if (!out->data || !be || be->host_visible) return 0;
    size_t bytes = (size_t)mx_shape_numel(ndim, shape) * mx_dtype_size(out->dtype);
    void *p = mx_dev_weight(d->c, out->data, bytes, st);
    if (!p || keep_device_buffer(d, p, st)) {
        if (p) be->release(be, p);
        return mx_fail_prefix(st, "weight %s%s", d->inner->prefix, name);
    }
    out->data = p;
    return 0;
}

int mx_binder_device(mx_binder *b, mx_binder *inner, const mx_ctx *c, mx_status *st) {
    memset(b, 0, sizeof *b);
    device_binder *d = calloc(1, sizeof *d);
    if (!d) return mx_fail(st, MX_ENOMEM, "out of memory binding weights");
    d->inner = inner;
    d->c = c;
    b->bind = bind_device;
    b->impl = d;
    b->enumerating = inner->enumerating;
    memcpy(b->prefix, inner->prefix, sizeof b->prefix);
    return 0;
}

static void free_device(device_binder *d) {
    for (size_t i = 0; i < d->n; i++) d->c->be->release(d->c->be, d->bufs[i]);
    free(d->bufs);
    free(d);
}

void mx_binder_free(mx_binder *b) {
    if (!b || !b->impl) return;
    if (b->bind == bind_device) {
        free_device(b->impl);
    } else if (b->enumerating) {
        enum_binder *e = b->impl;
        for (size_t i = 0; i < e->n; i++) free(e->list[i].name);
        free(e->list);
        free(e);
    } else if (b->bind == bind_st || b->bind == bind_rule) {
        free_st(b->impl);
    }
    b->impl = NULL;
}
