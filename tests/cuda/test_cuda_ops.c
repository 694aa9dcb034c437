/* CUDA ops against the scalar CPU references (the ops/cpu _ref.c files, through mx_kernels_scalar) on random
 * inputs of awkward sizes: relative L2 error <= 1e-5 for fp32 math, <= 1e-2 for fp16/bf16 math;
 * Philox normals equal bit for bit; the kernel table full; a file through the pinned upload ring.
 * Without a CUDA device it checks the table, prints a skip line and exits 77 (built by `make cuda`,
 * run by `make test-cuda`, which stops there). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../ops/cuda/cuda_backend.h"
#include "../../runtime/file_stream.h"
#include "../../runtime/rng.h"
#include "../util_test.h"

#define FP32_BOUND 1e-5
#define HALF_BOUND 1e-2

typedef struct env {
    mx_cuda_ctx *gpu;
    mx_ctx cpu; /* scalar references */
    mx_arena cpu_scratch;
    mx_status st;
} env;

/* Counts a failure and prints the message when a CUDA call failed; returns rc. */
static int gpu_ok(env *e, int rc, const char *what) {
    if (rc != 0) {
        mx_test_failures++;
        fprintf(stderr, "%s: %s\n", what, e->st.msg);
    }
    return rc;
}

static float *rnd(size_t n, uint64_t seed, float lo, float hi) {
    float *x = malloc((n ? n : 1) * sizeof *x);
    if (!x) abort();
    mx_fill_random(x, n, seed, lo, hi);
    return x;
}

/* Device copy of a host buffer (NULL after a counted failure). */
static void *dev_copy(env *e, const void *host, size_t bytes) {
    void *d = NULL;
    if (gpu_ok(e, mx_cuda_alloc(&d, bytes, "test buffer", &e->st), "alloc")) return NULL;
    if (gpu_ok(e, mx_cuda_upload(e->gpu, d, host, bytes, "test upload", &e->st), "upload")) {
        mx_cuda_free(d);
        return NULL;
    }
    return d;
}

static void *dev_zero(env *e, size_t bytes) {
    void *d = NULL;
    if (gpu_ok(e, mx_cuda_alloc(&d, bytes, "test output", &e->st), "alloc")) return NULL;
    if (gpu_ok(e, mx_cuda_memset_zero(e->gpu, d, bytes, "test output", &e->st), "memset")) {
        mx_cuda_free(d);
        return NULL;
    }
    return d;
}

/* Waits for the queued work, downloads n floats of dev and compares them with want. */
static void compare_dev(env *e, const char *name, const float *dev, const float *want, size_t n, double bound) {
    float *got = malloc(n * sizeof *got);
    if (!got) abort();
    if (!gpu_ok(e, mx_cuda_sync(e->gpu, &e->st), name) &&
        !gpu_ok(e, mx_cuda_download(e->gpu, got, dev, n * sizeof *got, name, &e->st), name))
        mx_check_close(name, got, want, n, bound);
    free(got);
}

/* A weight of dtype dt from n random floats: host view (for the reference) and device copy. */
typedef struct test_weight {
    mx_wptr host, dev;
    void *store;
} test_weight;

static test_weight make_weight(env *e, size_t n, uint64_t seed, mx_dtype dt) {
    test_weight w = {{NULL, dt}, {NULL, dt}, NULL};
    float *f = rnd(n, seed, -0.5f, 0.5f);
    if (dt == MX_F32) {
        w.store = f;
    } else {
        uint16_t *h = malloc(n * sizeof *h);
        if (!h) abort();
        for (size_t i = 0; i < n; i++) h[i] = dt == MX_F16 ? mx_float_to_half(f[i]) : mx_float_to_bf16(f[i]);
        free(f);
        w.store = h;
    }
    w.host.data = w.store;
    w.dev.data = dev_copy(e, w.store, n * mx_dtype_size(dt));
    return w;
}

static void free_weight(test_weight *w) {
    mx_cuda_free((void *)w->dev.data);
    free(w->store);
}

static double bound_for(mx_dtype dt) { return dt == MX_F32 ? FP32_BOUND : HALF_BOUND; }

/* ---- the tests ---- */

static void test_linear(env *e, mx_dtype dt, int M, int N, int K) {
    char name[96];
    snprintf(name, sizeof name, "linear %s M=%d N=%d K=%d", mx_dtype_name(dt), M, N, K);
    float *x = rnd((size_t)M * K, 11, -1, 1), *want = malloc((size_t)M * N * sizeof *want);
    test_weight w = make_weight(e, (size_t)N * K, 12, dt), b = make_weight(e, N, 13, dt);
    e->cpu.k->linear(&e->cpu, want, x, w.host, b.host, M, N, K);
    float *dx = dev_copy(e, x, (size_t)M * K * sizeof *x), *dy = dev_zero(e, (size_t)M * N * sizeof *dy);
    if (dx && dy && w.dev.data && b.dev.data &&
        !gpu_ok(e, mx_cuda_linear(e->gpu, dy, dx, w.dev, b.dev, M, N, K, &e->st), name))
        compare_dev(e, name, dy, want, (size_t)M * N, bound_for(dt));
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free_weight(&w);
    free_weight(&b);
    free(x);
    free(want);
}

/* conv2d, or with up conv2d_up2x (a 3×3 conv, pad 1, on the 2× upsample: ks, stride, pad unused). */
static void test_conv_op(env *e, mx_dtype dt, int B, int Cin, int H, int W, int Cout, int ks, int stride, int pad,
                         int up) {
    char name[96];
    if (up)
        snprintf(name, sizeof name, "conv2d_up2x %s %dx%dx%dx%d->%d", mx_dtype_name(dt), B, Cin, H, W, Cout);
    else
        snprintf(name, sizeof name, "conv2d %s %dx%d s%d p%d %dx%dx%dx%d->%d", mx_dtype_name(dt), ks, ks, stride, pad,
                 B, Cin, H, W, Cout);
    if (up) ks = 3;
    int Ho = up ? 2 * H : (H + 2 * pad - ks) / stride + 1, Wo = up ? 2 * W : (W + 2 * pad - ks) / stride + 1;
    size_t nx = (size_t)B * Cin * H * W, ny = (size_t)B * Cout * Ho * Wo;
    float *x = rnd(nx, 21, -1, 1), *want = malloc(ny * sizeof *want);
    test_weight w = make_weight(e, (size_t)Cout * Cin * ks * ks, 22, dt), b = make_weight(e, Cout, 23, dt);
    if (up)
        e->cpu.k->conv2d_up2x(&e->cpu, want, x, B, Cin, H, W, w.host, b.host, Cout);
    else
        e->cpu.k->conv2d(&e->cpu, want, x, B, Cin, H, W, w.host, b.host, Cout, ks, ks, stride, pad);
    float *dx = dev_copy(e, x, nx * sizeof *x), *dy = dev_zero(e, ny * sizeof *dy);
    int rc = dx && dy && w.dev.data && b.dev.data ? 0 : -1;
    if (rc == 0)
        rc = up ? mx_cuda_conv2d_up2x(e->gpu, dy, dx, B, Cin, H, W, w.dev, b.dev, Cout, &e->st)
                : mx_cuda_conv2d(e->gpu, dy, dx, B, Cin, H, W, w.dev, b.dev, Cout, ks, ks, stride, pad, &e->st);
    if (dx && dy && w.dev.data && b.dev.data && !gpu_ok(e, rc, name)) compare_dev(e, name, dy, want, ny, bound_for(dt));
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free_weight(&w);
    free_weight(&b);
    free(x);
    free(want);
}

static void test_conv2d(env *e, mx_dtype dt, int B, int Cin, int H, int W, int Cout, int ks, int stride, int pad) {
    test_conv_op(e, dt, B, Cin, H, W, Cout, ks, stride, pad, 0);
}

/* Groups of more than 4096 values run in several chunks per group (cuda_norm.cu): the larger
 * shapes cover that, with a short last chunk. */
static void test_group_norm(env *e, int B, int C, int HW, int G, int fuse_silu) {
    size_t n = (size_t)B * C * HW;
    char name[96];
    snprintf(name, sizeof name, "group_norm%s %dx%dx%d/%d", fuse_silu ? "+silu fp16 affine" : " fp32 affine", B, C, HW,
             G);
    mx_dtype dt = fuse_silu ? MX_F16 : MX_F32;
    float *x = rnd(n, 31, -2, 3), *want = malloc(n * sizeof *want);
    test_weight g = make_weight(e, C, 32, dt), b = make_weight(e, C, 33, dt);
    e->cpu.k->group_norm(&e->cpu, want, x, B, C, HW, G, g.host, b.host, 1e-5f, fuse_silu);
    float *dx = dev_copy(e, x, n * sizeof *x), *dy = dev_zero(e, n * sizeof *dy);
    if (dx && dy && g.dev.data && b.dev.data &&
        !gpu_ok(e, mx_cuda_group_norm(e->gpu, dy, dx, B, C, HW, G, g.dev, b.dev, 1e-5f, fuse_silu, &e->st), name))
        compare_dev(e, name, dy, want, n, FP32_BOUND); /* fp16 affine weights, fp32 math */
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free_weight(&g);
    free_weight(&b);
    free(x);
    free(want);
}

static void test_layer_norm(env *e) {
    const int M = 19, C = 771;
    size_t n = (size_t)M * C;
    float *x = rnd(n, 41, -1, 2), *want = malloc(n * sizeof *want);
    test_weight g = make_weight(e, C, 42, MX_F32), b = make_weight(e, C, 43, MX_F32);
    e->cpu.k->layer_norm(&e->cpu, want, x, M, C, g.host, b.host, 1e-5f);
    float *dx = dev_copy(e, x, n * sizeof *x);
    /* in place, as the networks call it */
    if (dx && g.dev.data && b.dev.data &&
        !gpu_ok(e, mx_cuda_layer_norm(e->gpu, dx, dx, M, C, g.dev, b.dev, 1e-5f, &e->st), "layer_norm"))
        compare_dev(e, "layer_norm 19x771 in place", dx, want, n, FP32_BOUND);
    mx_cuda_free(dx);
    free_weight(&g);
    free_weight(&b);
    free(x);
    free(want);
}

/* q, k, v are read with row strides wider than H*D (as from a fused qkv projection). */
static void test_attention(env *e, int B, int H, int Tq, int Tk, int D, int causal) {
    char name[96];
    snprintf(name, sizeof name, "attention B=%d H=%d Tq=%d Tk=%d D=%d%s", B, H, Tq, Tk, D, causal ? " causal" : "");
    int qs = H * D + 3, kvs = H * D + 5, os = H * D + 1;
    size_t nq = (size_t)B * Tq * qs, nkv = (size_t)B * Tk * kvs, no = (size_t)B * Tq * os;
    float *q = rnd(nq, 61, -1, 1), *k = rnd(nkv, 62, -1, 1), *v = rnd(nkv, 63, -1, 1);
    float *want = calloc(no, sizeof *want);
    float scale = 1.0f / sqrtf((float)D) * 2.0f; /* sharper than usual: exercises the running max */
    e->cpu.k->attention(&e->cpu, want, q, k, v, B, H, Tq, Tk, D, qs, kvs, os, causal, scale);
    float *dq = dev_copy(e, q, nq * sizeof *q), *dk = dev_copy(e, k, nkv * sizeof *k);
    float *dv = dev_copy(e, v, nkv * sizeof *v), *dout = dev_zero(e, no * sizeof *dout);
    unsigned long long half = mx_cuda_ctx_half_products(e->gpu);
    if (dq && dk && dv && dout &&
        !gpu_ok(e, mx_cuda_attention(e->gpu, dout, dq, dk, dv, B, H, Tq, Tk, D, qs, kvs, os, causal, scale, &e->st),
                name)) {
        /* tensor cores (fp16 inputs) when the scratch holds the scores, else the fp32 kernel */
        int tc = mx_cuda_ctx_half_products(e->gpu) > half;
        snprintf(name + strlen(name), sizeof name - strlen(name), tc ? " [fp16 tensor cores]" : " [fp32]");
        compare_dev(e, name, dout, want, no, tc ? HALF_BOUND : FP32_BOUND); /* the padding columns stay 0 on both sides */
    }
    mx_cuda_free(dq);
    mx_cuda_free(dk);
    mx_cuda_free(dv);
    mx_cuda_free(dout);
    free(q);
    free(k);
    free(v);
    free(want);
}

typedef int (*gpu_unary)(mx_cuda_ctx *, float *, size_t, mx_status *);

static void test_unary(env *e, const char *name, void (*ref)(const mx_ctx *, float *, size_t), gpu_unary gpu) {
    const size_t n = 100003;
    float *x = rnd(n, 71, -6, 6), *want = malloc(n * sizeof *want);
    memcpy(want, x, n * sizeof *x);
    ref(&e->cpu, want, n);
    float *dx = dev_copy(e, x, n * sizeof *x);
    if (dx && !gpu_ok(e, gpu(e->gpu, dx, n, &e->st), name)) compare_dev(e, name, dx, want, n, FP32_BOUND);
    mx_cuda_free(dx);
    free(x);
    free(want);
}

static void test_activations(env *e) {
    test_unary(e, "gelu n=100003", e->cpu.k->gelu, mx_cuda_gelu);
    test_unary(e, "quick_gelu n=100003", e->cpu.k->quick_gelu, mx_cuda_quick_gelu);
    test_unary(e, "silu n=100003", e->cpu.k->silu, mx_cuda_silu);
}

static void test_geglu(env *e) {
    const int M = 37, N = 321;
    float *x = rnd((size_t)M * 2 * N, 81, -3, 3), *want = malloc((size_t)M * N * sizeof *want);
    e->cpu.k->geglu(&e->cpu, want, x, M, N);
    float *dx = dev_copy(e, x, (size_t)M * 2 * N * sizeof *x), *dy = dev_zero(e, (size_t)M * N * sizeof *dy);
    if (dx && dy && !gpu_ok(e, mx_cuda_geglu(e->gpu, dy, dx, M, N, &e->st), "geglu"))
        compare_dev(e, "geglu 37x321", dy, want, (size_t)M * N, FP32_BOUND);
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free(x);
    free(want);
}

/* a op b of shapes as and bs (4 dims), a read from `offset` floats into its buffer (an offset of
 * 1 takes the same-shape kernel off its 16-byte vector path). One IEEE operation per element: the
 * results equal the CPU's exactly. */
static void test_binary(env *e, mx_binop op, const int64_t *as, const int64_t *bs, int offset) {
    static const char *ops[] = {"add", "sub", "mul"};
    size_t na = 1, nb = 1, ny = 1;
    for (int d = 0; d < 4; d++) {
        na *= (size_t)as[d];
        nb *= (size_t)bs[d];
        ny *= (size_t)(as[d] > bs[d] ? as[d] : bs[d]);
    }
    char name[96];
    snprintf(name, sizeof name, "binary %s %lldx%lldx%lldx%lld %s, offset %d", ops[op], (long long)as[0],
             (long long)as[1], (long long)as[2], (long long)as[3], na == nb ? "same shape" : "broadcast", offset);
    float *a = rnd(na + offset, 91, -1, 1), *b = rnd(nb, 92, -1, 1), *want = malloc(ny * sizeof *want);
    e->cpu.k->binary(&e->cpu, op, want, a + offset, as, b, bs, 4);
    float *da = dev_copy(e, a, (na + offset) * sizeof *a), *db = dev_copy(e, b, nb * sizeof *b);
    float *dy = dev_zero(e, ny * sizeof *dy);
    if (da && db && dy && !gpu_ok(e, mx_cuda_binary(e->gpu, op, dy, da + offset, as, db, bs, 4, &e->st), name))
        compare_dev(e, name, dy, want, ny, 0.0);
    mx_cuda_free(da);
    mx_cuda_free(db);
    mx_cuda_free(dy);
    free(a);
    free(b);
    free(want);
}

static void test_binary_ops(env *e) {
    static const int64_t as[4] = {2, 3, 1, 5}, bs[4] = {1, 3, 7, 1}, same[4] = {2, 3, 7, 97};
    for (int op = MX_BIN_ADD; op <= MX_BIN_MUL; op++) test_binary(e, (mx_binop)op, as, bs, 0);
    test_binary(e, MX_BIN_ADD, same, same, 0); /* 4074 values: 1018 vectors and a tail of 2 */
    test_binary(e, MX_BIN_MUL, same, same, 1);
}

static void test_scale(env *e) {
    const size_t n = 4099;
    float *x = rnd(n, 101, -1, 1), *want = malloc(n * sizeof *want);
    e->cpu.k->scale(&e->cpu, want, x, 0.18215f, n);
    float *dx = dev_copy(e, x, n * sizeof *x), *dy = dev_zero(e, n * sizeof *dy);
    if (dx && dy && !gpu_ok(e, mx_cuda_scale(e->gpu, dy, dx, 0.18215f, n, &e->st), "scale"))
        compare_dev(e, "scale n=4099", dy, want, n, FP32_BOUND);
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free(x);
    free(want);
}

static void test_upsample(env *e) {
    const int BC = 5, H = 7, W = 9;
    size_t nx = (size_t)BC * H * W, ny = nx * 4;
    float *x = rnd(nx, 111, -1, 1), *want = malloc(ny * sizeof *want);
    e->cpu.k->upsample_nearest2x(&e->cpu, want, x, BC, H, W);
    float *dx = dev_copy(e, x, nx * sizeof *x), *dy = dev_zero(e, ny * sizeof *dy);
    if (dx && dy && !gpu_ok(e, mx_cuda_upsample_nearest2x(e->gpu, dy, dx, BC, H, W, &e->st), "upsample"))
        compare_dev(e, "upsample_nearest2x 5x7x9", dy, want, ny, 0.0);
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free(x);
    free(want);
}

static void test_concat(env *e) {
    const int B = 2, Ca = 3, Cb = 5, HW = 37;
    size_t na = (size_t)B * Ca * HW, nb = (size_t)B * Cb * HW, ny = na + nb;
    float *a = rnd(na, 121, -1, 1), *b = rnd(nb, 122, -1, 1), *want = malloc(ny * sizeof *want);
    e->cpu.k->concat_channels(&e->cpu, want, a, Ca, b, Cb, B, HW);
    float *da = dev_copy(e, a, na * sizeof *a), *db = dev_copy(e, b, nb * sizeof *b);
    float *dy = dev_zero(e, ny * sizeof *dy);
    if (da && db && dy && !gpu_ok(e, mx_cuda_concat_channels(e->gpu, dy, da, Ca, db, Cb, B, HW, &e->st), "concat"))
        compare_dev(e, "concat_channels 3+5 x37", dy, want, ny, 0.0);
    mx_cuda_free(da);
    mx_cuda_free(db);
    mx_cuda_free(dy);
    free(a);
    free(b);
    free(want);
}

static void test_transpose(env *e, int to_hwc) {
    const int B = 3, C = 45, HW = 67;
    size_t n = (size_t)B * C * HW;
    const char *name = to_hwc ? "transpose_chw_hwc 3x45x67" : "transpose_hwc_chw 3x45x67";
    float *x = rnd(n, 131, -1, 1), *want = malloc(n * sizeof *want);
    if (to_hwc)
        e->cpu.k->transpose_chw_hwc(&e->cpu, want, x, B, C, HW);
    else
        e->cpu.k->transpose_hwc_chw(&e->cpu, want, x, B, C, HW);
    float *dx = dev_copy(e, x, n * sizeof *x), *dy = dev_zero(e, n * sizeof *dy);
    if (dx && dy) {
        int rc = to_hwc ? mx_cuda_transpose_chw_hwc(e->gpu, dy, dx, B, C, HW, &e->st)
                        : mx_cuda_transpose_hwc_chw(e->gpu, dy, dx, B, C, HW, &e->st);
        if (!gpu_ok(e, rc, name)) compare_dev(e, name, dy, want, n, 0.0);
    }
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free(x);
    free(want);
}

/* Philox normals: same seed/stream/index -> same float as runtime/rng.c, bit for bit. A first index
 * above 2^32 exercises the high word of the counter; an odd one starts on a sin value. */
static void test_rng(env *e) {
    const size_t n = (size_t)1 << 20;
    const uint64_t seed = 0x123456789abcdefull, stream = 0x100000003ull, first = ((uint64_t)1 << 33) + 1;
    float *want = malloc(n * sizeof *want), *got = malloc(n * sizeof *got);
    mx_rng_fill_normal(want, n, seed, stream, first);
    float *d = dev_zero(e, n * sizeof *d);
    if (d && !gpu_ok(e, mx_cuda_rng_fill_normal(e->gpu, d, n, seed, stream, first, &e->st), "rng") &&
        !gpu_ok(e, mx_cuda_sync(e->gpu, &e->st), "rng") &&
        !gpu_ok(e, mx_cuda_download(e->gpu, got, d, n * sizeof *got, "rng", &e->st), "rng")) {
        size_t bad = 0;
        for (size_t i = 0; i < n; i++) bad += memcmp(&got[i], &want[i], sizeof *got) != 0;
        printf("%-48s %zu of %zu differ %s\n", "philox normals bit-exact", bad, n, bad ? "FAIL" : "ok");
        CHECK(bad == 0);
    }
    mx_cuda_free(d);
    free(want);
    free(got);
}

/* ---- driver ---- */

static void test_gemm_ops(env *e) {
    test_linear(e, MX_F32, 37, 53, 71);
    test_linear(e, MX_F16, 33, 70, 130);
    test_linear(e, MX_BF16, 77, 96, 64);
    test_conv2d(e, MX_F32, 2, 5, 11, 13, 7, 3, 1, 1);
    test_conv2d(e, MX_F16, 2, 6, 12, 9, 8, 3, 2, 1);
    test_conv2d(e, MX_BF16, 1, 4, 10, 10, 3, 3, 1, 0);
    test_conv2d(e, MX_F32, 2, 9, 7, 5, 6, 1, 1, 0);
    test_conv2d(e, MX_F16, 2, 9, 7, 5, 6, 1, 1, 0);
    test_conv_op(e, MX_F32, 2, 5, 7, 6, 9, 0, 0, 0, 1);
    test_conv_op(e, MX_F16, 1, 12, 1, 3, 7, 0, 0, 0, 1);
}

/* n floats of dev, waited for (NULL after a counted failure). */
static float *download(env *e, const float *dev, size_t n, const char *what) {
    float *h = malloc(n * sizeof *h);
    if (!h) abort();
    if (gpu_ok(e, mx_cuda_sync(e->gpu, &e->st), what) ||
        gpu_ok(e, mx_cuda_download(e->gpu, h, dev, n * sizeof *h, what, &e->st), what)) {
        free(h);
        return NULL;
    }
    return h;
}

/* One fp16 conv (SD's 3x3, 320 channels, at 16x16): the same call twice gives the same bytes, and
 * item 1 of a batch of 2 the same bytes as that item alone (deterministic engines; plans of one item). */
static void test_conv_repeatable(env *e) {
    enum { B = 2, C = 320, H = 16, W = 16 };
    size_t plane = (size_t)C * H * W;
    float *x = rnd(B * plane, 31, -1, 1);
    test_weight w = make_weight(e, (size_t)C * C * 9, 32, MX_F16), b = make_weight(e, C, 33, MX_F16);
    float *dx = dev_copy(e, x, B * plane * sizeof *x), *dy = dev_zero(e, B * plane * sizeof *dy);
    float *y2 = NULL, *y2again = NULL, *y1 = NULL;
    if (dx && dy && w.dev.data && b.dev.data &&
        !gpu_ok(e, mx_cuda_conv2d(e->gpu, dy, dx, B, C, H, W, w.dev, b.dev, C, 3, 3, 1, 1, &e->st), "conv B=2") &&
        (y2 = download(e, dy, B * plane, "conv B=2")) &&
        !gpu_ok(e, mx_cuda_conv2d(e->gpu, dy, dx, B, C, H, W, w.dev, b.dev, C, 3, 3, 1, 1, &e->st), "conv again") &&
        (y2again = download(e, dy, B * plane, "conv again")) &&
        !gpu_ok(e, mx_cuda_conv2d(e->gpu, dy, dx + plane, 1, C, H, W, w.dev, b.dev, C, 3, 3, 1, 1, &e->st),
                "conv item 1 alone") &&
        (y1 = download(e, dy, plane, "conv item 1 alone"))) {
        int same = !memcmp(y2, y2again, B * plane * sizeof *y2), alone = !memcmp(y2 + plane, y1, plane * sizeof *y1);
        printf("%-48s %s\n", "conv2d f16 repeated call: same bytes", same ? "ok" : "FAIL");
        printf("%-48s %s\n", "conv2d f16 item alone = item in batch (bytes)", alone ? "ok" : "FAIL");
        CHECK(same);
        CHECK(alone);
    }
    free(y1), free(y2), free(y2again);
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    free_weight(&w);
    free_weight(&b);
    free(x);
}

/* conv2d through cuDNN (ops/cuda/cuda_cudnn.cu) where MATEX_CUDNN=1: fp16 convolutions of SD1.5's
 * kinds (scaled down) and awkward ones at the half bound, and cuDNN must have run SD's 3x3 (a shape
 * no cuDNN engine takes goes through im2col, which these checks cover too). Without MATEX_CUDNN=1,
 * cuDNN must never run. */
static void test_cudnn_conv(env *e) {
    const char *env_on = getenv("MATEX_CUDNN");
    int on = env_on && strcmp(env_on, "1") == 0;
    unsigned long long before = mx_cuda_ctx_cudnn_convs(e->gpu);
    test_conv2d(e, MX_F16, 2, 320, 16, 16, 320, 3, 1, 1); /* a resnet conv of the UNet */
    unsigned long long sd = mx_cuda_ctx_cudnn_convs(e->gpu) - before;
    test_conv2d(e, MX_F16, 2, 4, 17, 13, 32, 3, 1, 1);  /* conv_in: 4 channels */
    test_conv2d(e, MX_F16, 1, 3, 33, 31, 16, 3, 1, 1);  /* the ControlNet hint: 3 channels */
    test_conv2d(e, MX_F16, 1, 64, 15, 15, 64, 3, 2, 1); /* downsample: stride 2, odd size */
    test_conv2d(e, MX_F16, 2, 40, 9, 9, 24, 1, 1, 0);   /* 1x1 */
    test_conv2d(e, MX_F16, 1, 13, 11, 7, 5, 3, 1, 0);   /* odd channels, no padding */
    test_conv_repeatable(e);
    unsigned long long all = mx_cuda_ctx_cudnn_convs(e->gpu) - before;
    printf("%-48s %llu of 8 calls (SD 3x3: %llu) %s\n", on ? "conv2d through cuDNN (MATEX_CUDNN=1)" :
           "conv2d through cuDNN (MATEX_CUDNN unset): none", all, sd, (on ? sd > 0 : all == 0) ? "ok" : "FAIL");
    CHECK(on ? sd > 0 : all == 0);
}

/* A context with a 32 KiB scratch: linear and conv2d must split their work into several chunks/tiles,
 * attention falls back to its fp32 kernel. */
static void test_small_scratch(env *e) {
    mx_cuda_ctx *big = e->gpu, *small = NULL;
    if (gpu_ok(e, mx_cuda_ctx_create(&small, 0, (size_t)32 << 10, &e->st), "small scratch context")) return;
    e->gpu = small;
    test_linear(e, MX_F16, 300, 40, 130);         /* 78 KB of converted rows: 3 chunks */
    test_conv2d(e, MX_F16, 1, 8, 33, 33, 5, 3, 1, 1); /* 1089 pixels x 144 bytes: 6 tiles */
    test_conv2d(e, MX_F16, 2, 8, 33, 33, 5, 3, 1, 1); /* both items per tile: 18 tiles of 64 pixels */
    test_attention(e, 2, 3, 37, 45, 40, 0);           /* scores do not fit: the fp32 kernel */
    test_attention(e, 1, 2, 29, 29, 64, 1);
    e->gpu = big;
    mx_cuda_ctx_destroy(small);
}

static void test_norm_ops(env *e) {
    test_group_norm(e, 2, 12, 37, 4, 0);
    test_group_norm(e, 2, 12, 37, 4, 1);
    test_group_norm(e, 2, 96, 9797, 32, 0); /* 29391 values a group: 8 chunks */
    test_group_norm(e, 1, 64, 128 * 128, 32, 1);
    test_layer_norm(e);
}

static void test_attention_ops(env *e) {
    test_attention(e, 2, 3, 37, 45, 40, 0);
    test_attention(e, 1, 2, 29, 29, 64, 1);
    test_attention(e, 1, 2, 33, 77, 80, 0);
    test_attention(e, 2, 1, 19, 50, 160, 0);
    test_attention(e, 1, 1, 21, 35, 512, 0);
    test_attention(e, 1, 8, 2048, 2048, 40, 1); /* level-2-like: query chunks of ~640 rows, causal offsets */
    test_attention(e, 2, 2, 130, 200, 80, 0);   /* two items, two heads, non-square */
    test_attention(e, 1, 2, 100, 77, 160, 0);   /* SD's cross-attention: 77 keys (rows padded to 80) */
    test_linear(e, MX_F32, 37, 53, 71); /* after an fp32 linear (projection) attention runs in fp32: [fp32] */
    test_attention(e, 2, 3, 37, 45, 40, 0);
    test_attention(e, 1, 1, 21, 35, 512, 0); /* the VAE mid-block's head size on the fp32 kernel */
}

/* Attention in the fused kernel (ops/cuda/cuda_flash.cu) where MATEX_CUDA_FLASH=1, at the half bound:
 * the UNet's shapes (64x64 latent: 4096 queries and keys, 8 heads of 40; cross-attention on 77
 * tokens; the 32x32 level's heads of 80 and the 16x16 level's of 160; the grid's 8192 tokens, one
 * head: the CPU reference takes ~10 s a case) and awkward ones (partial tiles of queries and keys,
 * one key, causal, head sizes 16, 33 and 100 padded to 48, 48 and 160). The fused kernel must have
 * run them all; without MATEX_CUDA_FLASH=1 it must never run. */
static void test_flash_attention(env *e) {
    const char *env_on = getenv("MATEX_CUDA_FLASH");
    int on = env_on && strcmp(env_on, "1") == 0;
    static const int cases[10][6] = {/* B, H, Tq, Tk, D, causal */
                                   {1, 8, 4096, 4096, 40, 0}, {2, 8, 4096, 77, 40, 0}, {1, 8, 1024, 1024, 80, 0},
                                   {2, 8, 256, 77, 160, 0},   {1, 1, 8192, 8192, 40, 0}, {1, 3, 37, 45, 40, 0},
                                   {1, 2, 29, 29, 64, 1},     {2, 1, 100, 1, 16, 0},    {1, 2, 65, 130, 33, 1},
                                   {1, 1, 63, 200, 100, 0}};
    /* off: the small cases only (the UNet's take the CPU reference ~20 s, and the cuBLASLt path they
     * would check has its own cases above) */
    int n = on ? (int)(sizeof cases / sizeof cases[0]) : 5, first = on ? 0 : 5;
    unsigned long long before = mx_cuda_ctx_flash_calls(e->gpu);
    test_linear(e, MX_F16, 33, 70, 130); /* after a half-precision projection: the half-precision path */
    for (int i = first; i < first + n; i++)
        test_attention(e, cases[i][0], cases[i][1], cases[i][2], cases[i][3], cases[i][4], cases[i][5]);
    unsigned long long ran = mx_cuda_ctx_flash_calls(e->gpu) - before;
    printf("%-48s %llu of %d calls %s\n", on ? "attention in the fused kernel (MATEX_CUDA_FLASH=1)" :
           "attention in the fused kernel (unset): none", ran, n, (on ? ran == (unsigned long long)n : ran == 0) ? "ok" : "FAIL");
    CHECK(on ? ran == (unsigned long long)n : ran == 0);
}

/* The small layout, vector and embedding ops (pad, fill, axpy, lincomb, clamp, affine, timestep and
 * token embeddings) against the scalar references: bit-exact except the embeddings' transcendental
 * functions. */
static void test_small_ops(env *e) {
    const int BC = 3, H = 7, W = 9, Hp = H + 1, Wp = W + 2;
    const size_t n = 4099, np = (size_t)BC * Hp * Wp;
    float *x = rnd(n, 131, -1, 1), *y = rnd(n, 132, -1, 1), *want = malloc(n * sizeof *want);
    float *dx = dev_copy(e, x, n * sizeof *x), *dy = dev_copy(e, y, n * sizeof *y), *dz = dev_zero(e, n * sizeof *y);
    if (!dx || !dy || !dz) return;
    e->cpu.k->pad2d(&e->cpu, want, x, BC, H, W, 0, 1, 2, 0);
    if (!gpu_ok(e, mx_cuda_pad2d(e->gpu, dz, dx, BC, H, W, 0, 1, 2, 0, &e->st), "pad2d"))
        compare_dev(e, "pad2d 3x7x9 (0,1,2,0)", dz, want, np, 0.0);
    memcpy(want, y, n * sizeof *y);
    e->cpu.k->axpy(&e->cpu, want, x, -0.7f, n);
    if (!gpu_ok(e, mx_cuda_axpy(e->gpu, dy, dx, -0.7f, n, &e->st), "axpy")) compare_dev(e, "axpy n=4099", dy, want, n, 0.0);
    const float coef[3] = {0.3f, -1.25f, 2.0f};
    const float *const hx[3] = {x, want, x}, *const dxs[3] = {dx, dy, dx};
    float *want2 = malloc(n * sizeof *want2);
    e->cpu.k->lincomb(&e->cpu, want2, 3, coef, hx, n);
    if (!gpu_ok(e, mx_cuda_lincomb(e->gpu, dz, 3, coef, dxs, n, &e->st), "lincomb"))
        compare_dev(e, "lincomb of 3, n=4099", dz, want2, n, 0.0);
    e->cpu.k->clamp(&e->cpu, want2, x, -0.25f, 0.5f, n);
    if (!gpu_ok(e, mx_cuda_clamp(e->gpu, dz, dx, -0.25f, 0.5f, n, &e->st), "clamp")) compare_dev(e, "clamp", dz, want2, n, 0.0);
    e->cpu.k->affine(&e->cpu, want2, x, 0.5f, 0.5f, n);
    if (!gpu_ok(e, mx_cuda_affine(e->gpu, dz, dx, 0.5f, 0.5f, n, &e->st), "affine")) compare_dev(e, "affine", dz, want2, n, 0.0);
    e->cpu.k->fill(&e->cpu, want2, 3.5f, n);
    if (!gpu_ok(e, mx_cuda_fill(e->gpu, dz, 3.5f, n, &e->st), "fill")) compare_dev(e, "fill", dz, want2, n, 0.0);
    const float ts[3] = {999.0f, 1.0f, 500.0f};
    float *dts = dev_copy(e, ts, sizeof ts);
    e->cpu.k->timestep_embedding(&e->cpu, want2, ts, 3, 321, 1, 0.0f, 10000.0f);
    if (dts && !gpu_ok(e, mx_cuda_timestep_embedding(e->gpu, dz, dts, 3, 321, 1, 0.0f, 10000.0f, &e->st), "temb"))
        compare_dev(e, "timestep embedding 3x321", dz, want2, 3 * 321, FP32_BOUND);
    test_weight tok = make_weight(e, 50 * 24, 133, MX_F16), pos = make_weight(e, 5 * 24, 134, MX_F32);
    const int32_t ids[10] = {0, 49, 7, -1, 3, 12, 1, 48, -1, 0}; /* -1: the position row alone */
    e->cpu.k->embed_tokens(&e->cpu, want2, ids, 2, 5, 24, tok.host, pos.host);
    if (tok.dev.data && pos.dev.data &&
        !gpu_ok(e, mx_cuda_embed_tokens(e->gpu, dz, ids, 2, 5, 24, tok.dev, pos.dev, &e->st), "embed"))
        compare_dev(e, "embed_tokens 2x5x24 (fp16 table)", dz, want2, 2 * 5 * 24, 0.0);
    free_weight(&tok);
    free_weight(&pos);
    mx_cuda_free(dts);
    mx_cuda_free(dx);
    mx_cuda_free(dy);
    mx_cuda_free(dz);
    free(x);
    free(y);
    free(want);
    free(want2);
}

/* Empty shapes are no work, as on the CPU (op_list.h): each call returns 0 and queues nothing that
 * faults (NULL data). */
static void test_empty_shapes(env *e) {
    const int64_t s0[2] = {2, 0}, s1[2] = {2, 1};
    mx_cuda_ctx *g = e->gpu;
    mx_status *st = &e->st;
    int bad = 0;
    bad += gpu_ok(e, mx_cuda_binary(g, MX_BIN_ADD, NULL, NULL, s0, NULL, s1, 2, st), "empty binary") != 0;
    bad += gpu_ok(e, mx_cuda_upsample_nearest2x(g, NULL, NULL, 3, 0, 4, st), "empty upsample") != 0;
    bad += gpu_ok(e, mx_cuda_concat_channels(g, NULL, NULL, 2, NULL, 3, 2, 0, st), "empty concat") != 0;
    bad += gpu_ok(e, mx_cuda_transpose_chw_hwc(g, NULL, NULL, 0, 4, 5, st), "empty transpose_chw_hwc") != 0;
    bad += gpu_ok(e, mx_cuda_transpose_hwc_chw(g, NULL, NULL, 2, 4, 0, st), "empty transpose_hwc_chw") != 0;
    bad += gpu_ok(e, mx_cuda_conv2d(g, NULL, NULL, 1, 2, 2, 2, mx_w_none(), mx_w_none(), 3, 5, 5, 1, 1, st),
                  "conv2d kernel larger than the padded input") != 0;
    bad += gpu_ok(e, mx_cuda_sync(g, st), "sync after the empty ops") != 0;
    printf("%-48s %d failed %s\n", "empty shapes: no work", bad, bad ? "FAIL" : "ok");
}

/* concat with one side of 0 channels is a copy of the other. */
static void test_concat_one_side(env *e) {
    const int B = 2, Cb = 3, HW = 5;
    size_t n = (size_t)B * Cb * HW;
    float *b = rnd(n, 123, -1, 1), *want = malloc(n * sizeof *want);
    e->cpu.k->concat_channels(&e->cpu, want, b, 0, b, Cb, B, HW); /* a: not read */
    float *db = dev_copy(e, b, n * sizeof *b), *dy = dev_zero(e, n * sizeof *dy);
    if (db && dy && !gpu_ok(e, mx_cuda_concat_channels(e->gpu, dy, db, 0, db, Cb, B, HW, &e->st), "concat 0+3"))
        compare_dev(e, "concat_channels 0+3 x5", dy, want, n, 0.0);
    mx_cuda_free(db);
    mx_cuda_free(dy);
    free(b);
    free(want);
}

static void test_other_ops(env *e) {
    test_empty_shapes(e);
    test_concat_one_side(e);
    test_activations(e);
    test_geglu(e);
    test_binary_ops(e);
    test_scale(e);
    test_upsample(e);
    test_concat(e);
    test_transpose(e, 1);
    test_transpose(e, 0);
    test_rng(e);
    test_small_ops(e);
}

/* A file onto the GPU through the pinned ring (mx_cuda_upload_file, what a weight file takes):
 * every byte lands at its offset for 1, 3 and 12 readers on a size of several 4 MiB chunks and a
 * short last one, the observer sees each byte once in order, and a file of another length than
 * said fails naming the file. */
static void seen_sum(void *arg, const void *buf, size_t n, uint64_t off) {
    uint64_t *sum = arg; /* position-weighted: order and offsets count */
    for (size_t i = 0; i < n; i++) *sum += ((const unsigned char *)buf)[i] * (off + i + 1);
}

static void test_upload_file(env *e) {
    const size_t len = ((size_t)13 << 20) + 37;
    unsigned char *data = malloc(len), *back = malloc(len);
    char dir[] = "/tmp/matex_test_cuda_file.XXXXXX", path[64];
    if (!data || !back || !mkdtemp(dir)) abort();
    snprintf(path, sizeof path, "%s/w.bin", dir);
    uint64_t want_sum = 0;
    for (size_t i = 0; i < len; i++) {
        data[i] = (unsigned char)((i * 2654435761u) >> 13);
        want_sum += data[i] * (i + 1);
    }
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(data, 1, len, f) == len);
    if (f) fclose(f);
    FILE *rf = fopen(path, "rb");
    void *dev = NULL;
    if (rf && !gpu_ok(e, mx_cuda_alloc(&dev, len, "test file", &e->st), "alloc")) {
        static const int readers[] = {1, 3, 12};
        for (int r = 0; r < 3; r++) {
            uint64_t sum = 0;
            mx_stream_observer obs = {seen_sum, &sum};
            mx_stream_stats stats;
            int ok = !gpu_ok(e, mx_cuda_memset_zero(e->gpu, dev, len, "test file", &e->st), "memset") &&
                     !gpu_ok(e, mx_cuda_upload_file(e->gpu, dev, fileno(rf), path, len, readers[r], &obs, &stats, &e->st),
                             "upload file") &&
                     !gpu_ok(e, mx_cuda_download(e->gpu, back, dev, len, "test file", &e->st), "download");
            ok = ok && memcmp(back, data, len) == 0 && sum == want_sum && stats.bytes == len;
            printf("cuda upload_file, %d readers: %zu bytes %s (%.1f ms)\n", readers[r], len, ok ? "ok" : "FAIL",
                   1e3 * stats.wall_s);
            CHECK(ok);
        }
        CHECK(mx_cuda_upload_file(e->gpu, dev, fileno(rf), path, len + 64, 3, NULL, NULL, &e->st) == -1 &&
              strstr(e->st.msg, path) && strstr(e->st.msg, "expected"));
    }
    if (rf) fclose(rf);
    mx_cuda_free(dev);
    unlink(path);
    rmdir(dir);
    free(data);
    free(back);
}

/* The CUDA kernel table has every op of ops/op_list.h (no device needed). */
static void test_table_full(void) {
    mx_kernels k;
    mx_cuda_fill_kernels(&k);
    const char *missing = mx_kernels_missing(&k);
    if (missing) printf("FAIL: the cuda table has no kernel for op %s\n", missing);
    CHECK(missing == NULL);
}

/* 1 when nvidia-smi is installed and lists a GPU ("GPU 0: ..."): then "no CUDA device" is a
 * broken setup (driver/runtime mismatch, hidden devices), to fail on, never to skip. */
static int nvidia_smi_sees_gpu(void) {
    FILE *p = popen("nvidia-smi -L 2>/dev/null", "r");
    if (!p) return 0;
    char line[256];
    int gpus = 0;
    while (fgets(line, sizeof line, p))
        if (strncmp(line, "GPU ", 4) == 0) gpus++;
    pclose(p);
    return gpus > 0;
}

/* 0: a device to test on; 1: none (skip, or a failure when nvidia-smi sees a GPU); -1: CUDA failed. */
static int find_device(env *e) {
    int ndev = 0;
    if (mx_cuda_device_count(&ndev, &e->st)) {
        printf("FAIL test-cuda: %s\n", e->st.msg);
        return -1;
    }
    if (ndev > 0) return 0;
    if (nvidia_smi_sees_gpu()) {
        printf("FAIL test-cuda: nvidia-smi lists a GPU but CUDA finds no device (CUDA_VISIBLE_DEVICES? "
               "driver/runtime mismatch?)\n");
        return -1;
    }
    return 1;
}

int main(void) {
    env e;
    memset(&e, 0, sizeof e);
    test_table_full();
    int found = find_device(&e);
    if (found < 0) return 1;
    if (found > 0) {
        if (mx_test_failures) return mx_test_finish("test-cuda");
        printf("test-cuda: the cuda table has all %d ops; no CUDA device (and no GPU in nvidia-smi): the op tests "
               "and the network goldens skipped\n", MX_OP_COUNT);
        return MX_TEST_SKIP;
    }
    if (mx_cuda_ctx_create(&e.gpu, 0, (size_t)64 << 20, &e.st) ||
        mx_arena_create(&e.cpu_scratch, (size_t)16 << 20, &e.st)) {
        fprintf(stderr, "test-cuda: setup: %s\n", e.st.msg);
        mx_cuda_ctx_destroy(e.gpu);
        return 1;
    }
    e.cpu.pool = NULL;
    e.cpu.k = mx_kernels_scalar();
    e.cpu.scratch = &e.cpu_scratch;
    test_gemm_ops(&e);
    test_cudnn_conv(&e);
    test_small_scratch(&e);
    test_norm_ops(&e);
    test_attention_ops(&e);
    test_flash_attention(&e);
    test_other_ops(&e);
    test_upload_file(&e);
    mx_arena_destroy(&e.cpu_scratch);
    mx_cuda_ctx_destroy(e.gpu);
    return mx_test_finish("test-cuda");
}
