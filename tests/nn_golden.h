/* Helpers for the network parity tests (test_nn_unet/controlnet/vae/clip/pipeline): golden
 * folder paths, config text, fp32 copies of golden tensors, a ready ops context on the device
 * named by MX_TEST_DEVICE (cpu, cpu-strict, cuda; default cpu) and the host <-> device copies
 * at the edges of a network call. Header-only (static). */
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

/* The device of the network tests: MX_TEST_DEVICE, default cpu. */
static inline mx_backend_kind golden_device(void) {
    mx_backend_kind kind = MX_BACKEND_CPU;
    mx_status st;
    const char *name = getenv("MX_TEST_DEVICE");
    if (name && *name && mx_backend_parse(name, &kind, &st)) {
        fprintf(stderr, "MX_TEST_DEVICE: %s\n", st.msg);
        exit(2);
    }
    return kind;
}

/* An ops context computing in precision p (the parity tests default to fp32). */
static inline int golden_ctx_precision(mx_ctx *c, mx_precision p) {
    mx_status st;
    int threads = getenv("MX_TEST_THREADS") ? atoi(getenv("MX_TEST_THREADS")) : 0;
    if (mx_ctx_create_on(c, golden_device(), threads, mx_cpu_isa_for(p), (size_t)64 << 20, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        return -1;
    }
    printf("device %s\n", mx_backend_name(c->be->kind));
    return 0;
}

static inline int golden_ctx(mx_ctx *c) { return golden_ctx_precision(c, MX_PREC_FP32); }

/* A bf16 context when this CPU has bf16 arithmetic (0); else prints that the bf16 parity was
 * not tested and returns 1 (-1 on error). */
static inline int golden_bf16_ctx(mx_ctx *c, const char *test) {
    if (mx_isa_precision(mx_cpu_isa_for(MX_PREC_BF16)) != MX_PREC_BF16) {
        printf("%s: bf16 arithmetic NOT TESTED (no AVX512_BF16 on this CPU, or lowered by MATEX_ISA)\n", test);
        return 1;
    }
    return golden_ctx_precision(c, MX_PREC_BF16);
}

/* Relative L2 bound against the fp32 goldens (../shared/golden/README.md): 1e-4 for fp32
 * arithmetic, 1e-2 for bf16. */
static inline double golden_bound(const mx_ctx *c) {
    return mx_isa_precision(c->k->isa) == MX_PREC_BF16 ? 1e-2 : 1e-4;
}

/* "net" or "net [bf16]": the label of a parity line. */
static inline void golden_label(char *buf, size_t cap, const mx_ctx *c, const char *net) {
    snprintf(buf, cap, "%s%s", net, mx_isa_precision(c->k->isa) == MX_PREC_BF16 ? " [bf16]" : "");
}

/* Backend copy of n host floats (NULL stays NULL); exits on failure. */
static inline float *golden_dev(const mx_ctx *c, const float *host, size_t n) {
    mx_status st;
    if (!host) return NULL;
    float *d = mx_dev_from_host(c, host, n, &st);
    if (!d) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
    return d;
}

/* Backend memory for n floats; exits on failure. */
static inline float *golden_dev_alloc(const mx_ctx *c, size_t n) {
    mx_status st;
    float *d = mx_dev_alloc(c, n, &st);
    if (!d) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
    return d;
}

/* host[0..n) = dev[0..n), then frees dev; returns 0 or -1 (message printed). */
static inline int golden_fetch(const mx_ctx *c, float *host, float *dev, size_t n) {
    mx_status st;
    int rc = mx_download(c, host, dev, n, &st);
    if (rc) fprintf(stderr, "%s\n", st.msg);
    mx_dev_free(c, dev);
    return rc;
}

/* An arena on the context's backend of exactly `bytes`; exits on failure. */
static inline void golden_arena(const mx_ctx *c, mx_arena *a, size_t bytes) {
    mx_status st;
    if (mx_arena_create_on(a, c->be, bytes, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        exit(1);
    }
}

#endif
