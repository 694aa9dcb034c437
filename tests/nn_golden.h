/* Helpers for the network parity tests (test_nn_unet/controlnet/vae): golden folder paths,
 * config text, fp32 copies of golden tensors, a ready ops context. Header-only (static). */
#ifndef MX_NN_GOLDEN_H
#define MX_NN_GOLDEN_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "../runtime/fileio.h"
#include "../weights/safetensors.h"
#include "util_test.h"

/* Path of golden/NET/FILE in the test data (util_test.h); -1 when absent. */
static inline int golden_path(char *buf, size_t cap, const char *net, const char *file) {
    char rel[512];
    snprintf(rel, sizeof rel, "golden/%s/%s", net, file);
    return mx_test_path(buf, cap, rel);
}

/* 1 when golden/NET/FILE is there; otherwise reports the case skipped (util_test.h), returns 0. */
static inline int golden_have(const char *net, const char *file) {
    char path[1024];
    return mx_test_need(path, sizeof path, "golden/%s/%s", net, file);
}

/* Whole file as a NUL-terminated string (caller frees), or NULL. */
static inline char *golden_text(const char *net, const char *file, size_t *len) {
    char path[1024];
    golden_path(path, sizeof path, net, file);
    return mx_read_file(path, (size_t)1 << 30, len, NULL);
}

static inline int golden_open(mx_safetensors *f, const char *net, const char *file) {
    char path[1024];
    mx_status st;
    golden_path(path, sizeof path, net, file);
    if (mx_st_open(f, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    return 0;
}

/* fp32 copy of a tensor (malloc'ed), with its element count; NULL when absent. */
static inline float *golden_f32(const mx_safetensors *f, const char *name, size_t *n) {
    mx_status st;
    const mx_st_tensor *t = mx_st_find(f, name);
    if (!t) {
        fprintf(stderr, "%s: missing %s\n", f->path, name);
        return NULL;
    }
    float *x = mx_st_to_f32(f, t, &st);
    if (!x) fprintf(stderr, "%s\n", st.msg);
    if (n) *n = (size_t)mx_shape_numel(t->ndim, t->shape);
    return x;
}

static inline int golden_ctx(mx_ctx *c) {
    mx_status st;
    int threads = getenv("MX_TEST_THREADS") ? atoi(getenv("MX_TEST_THREADS")) : 0;
    if (mx_ctx_create(c, threads, mx_cpu_best_isa(), (size_t)64 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    return 0;
}

#endif
