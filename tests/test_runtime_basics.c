/* Runtime tests: thread-count invariance of every threaded op (bit-exact for 1, 2 and 16
 * threads, at every ISA level), arena exhaustion, tensor shape validation, Philox
 * known-answer vectors (Random123) and the statistics of mx_rng_normal. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ops/ops.h"
#include "../runtime/json.h"
#include "../runtime/jsonw.h"
#include "../runtime/rng.h"
#include "util_test.h"

enum { NTHREADS = 3 };
static const int thread_counts[NTHREADS] = {1, 2, 16};

/* Inputs shared by the op runs: big enough that every op splits into many tasks. */
typedef struct {
    float *x, *w, *q, *k, *v, *big;
    size_t nbig;
} inputs;

/* Runs op number `op` writing into y; returns the output length or 0 past the last op. */
static size_t run_op(const mx_ctx *c, int op, const inputs *in, float *y, const char **name) {
    const int M = 150, N = 70, K = 300;
    switch (op) {
    case 0:
        *name = "linear";
        mx_linear(c, y, in->x, mx_w_f32(in->w), mx_w_f32(in->w + 5), M, N, K);
        return (size_t)M * N;
    case 1:
        *name = "conv2d 3x3";
        mx_conv2d(c, y, in->x, 2, 30, 20, 25, mx_w_f32(in->w), mx_w_f32(in->w), 40, 3, 3, 1, 1);
        return (size_t)2 * 40 * 20 * 25;
    case 2:
        *name = "group_norm+silu";
        mx_group_norm(c, y, in->big, 2, 64, 1000, 32, mx_w_f32(in->w), mx_w_f32(in->w + 64), 1e-5f, 1);
        return (size_t)2 * 64 * 1000;
    case 3:
        *name = "layer_norm";
        mx_layer_norm(c, y, in->x, M, K, mx_w_f32(in->w), mx_w_f32(in->w + K), 1e-5f);
        return (size_t)M * K;
    case 4:
        *name = "attention";
        mx_attention(c, y, in->q, in->k, in->v, 2, 4, 100, 77, 40, 160, 160, 160, 0, 0.158f);
        return (size_t)2 * 100 * 160;
    case 5:
        *name = "attention causal";
        mx_attention(c, y, in->q, in->k, in->v, 1, 2, 77, 77, 64, 128, 128, 128, 1, 0.125f);
        return (size_t)77 * 128;
    case 6:
    case 7:
    case 8:
        memcpy(y, in->big, in->nbig * sizeof *y);
        *name = op == 6 ? "gelu" : op == 7 ? "quick_gelu" : "silu";
        (op == 6 ? mx_gelu : op == 7 ? mx_quick_gelu : mx_silu)(c, y, in->nbig);
        return in->nbig;
    case 9:
        *name = "geglu";
        mx_geglu(c, y, in->x, M, K / 2);
        return (size_t)M * (K / 2);
    case 10: {
        *name = "binary broadcast";
        int64_t as[3] = {2, 64, 1000}, bs[3] = {2, 64, 1};
        mx_binary(c, MX_BIN_ADD, y, in->big, as, in->x, bs, 3);
        return in->nbig;
    }
    case 11:
        *name = "scale";
        mx_scale(c, y, in->big, 0.3f, in->nbig);
        return in->nbig;
    case 12:
        *name = "upsample_nearest2x";
        mx_upsample_nearest2x(c, y, in->big, 64, 20, 25);
        return (size_t)64 * 40 * 50;
    case 13:
        *name = "transpose_chw_hwc";
        mx_transpose_chw_hwc(c, y, in->big, 2, 64, 1000);
        return in->nbig;
    case 14:
        *name = "transpose_hwc_chw";
        mx_transpose_hwc_chw(c, y, in->big, 2, 64, 1000);
        return in->nbig;
    default: return 0;
    }
}

static void test_thread_invariance(mx_isa isa) {
    mx_status st;
    inputs in;
    in.nbig = (size_t)2 * 64 * 1000;
    in.x = malloc((size_t)150 * 300 * sizeof(float));
    in.w = malloc((size_t)70 * 300 * sizeof(float) + 4096);
    in.q = malloc((size_t)2 * 100 * 160 * sizeof(float));
    in.k = malloc((size_t)2 * 77 * 160 * sizeof(float));
    in.v = malloc((size_t)2 * 77 * 160 * sizeof(float));
    in.big = malloc(in.nbig * sizeof(float));
    mx_fill_random(in.x, (size_t)150 * 300, 1, -2, 2);
    mx_fill_random(in.w, (size_t)70 * 300 + 1024, 2, -1, 1);
    mx_fill_random(in.q, (size_t)2 * 100 * 160, 3, -2, 2);
    mx_fill_random(in.k, (size_t)2 * 77 * 160, 4, -2, 2);
    mx_fill_random(in.v, (size_t)2 * 77 * 160, 5, -1, 1);
    mx_fill_random(in.big, in.nbig, 6, -3, 3);
    size_t cap = (size_t)1 << 20;
    float *out[NTHREADS];
    mx_ctx ctx[NTHREADS];
    for (int t = 0; t < NTHREADS; t++) {
        out[t] = malloc(cap * sizeof(float));
        CHECK(mx_ctx_create(&ctx[t], thread_counts[t], isa, (size_t)16 << 20, &st) == 0);
    }
    for (int op = 0;; op++) {
        const char *name = "";
        size_t n = 0;
        for (int t = 0; t < NTHREADS; t++) {
            memset(out[t], 0xff, cap * sizeof(float)); /* NaN everywhere: unwritten outputs show */
            n = run_op(&ctx[t], op, &in, out[t], &name);
        }
        if (n == 0) break;
        int same = memcmp(out[0], out[1], n * sizeof(float)) == 0 && memcmp(out[0], out[2], n * sizeof(float)) == 0;
        int finite = 1;
        for (size_t i = 0; i < n; i++) finite &= isfinite(out[0][i]) != 0;
        printf("%-8s %-22s 1/2/16 threads: %s%s\n", mx_isa_name(ctx[0].k->isa), name, same ? "identical" : "DIFFER",
               finite ? "" : " (non-finite output)");
        CHECK(same && finite);
    }
    for (int t = 0; t < NTHREADS; t++) {
        CHECK(ctx[t].scratch->used == 0); /* kernels give their scratch back */
        mx_ctx_destroy(&ctx[t]);
        free(out[t]);
    }
    free(in.x), free(in.w), free(in.q), free(in.k), free(in.v), free(in.big);
}

/* A scratch arena too small for the kernels must cost speed only: same bits as a roomy one. */
static void test_small_scratch(void) {
    mx_status st;
    mx_ctx roomy, tiny;
    CHECK(mx_ctx_create(&roomy, 2, MX_ISA_AVX512, (size_t)16 << 20, &st) == 0);
    CHECK(mx_ctx_create(&tiny, 2, MX_ISA_AVX512, 256, &st) == 0);
    enum { M = 70, N = 90, K = 200, T = 100, D = 40 };
    float *x = malloc(sizeof(float) * M * K), *w = malloc(sizeof(float) * N * K), *q = malloc(sizeof(float) * T * D);
    float *y0 = malloc(sizeof(float) * M * N), *y1 = malloc(sizeof(float) * M * N);
    mx_fill_random(x, (size_t)M * K, 1, -1, 1);
    mx_fill_random(w, (size_t)N * K, 2, -1, 1);
    mx_fill_random(q, (size_t)T * D, 3, -1, 1);
    mx_linear(&roomy, y0, x, mx_w_f32(w), mx_w_none(), M, N, K);
    mx_linear(&tiny, y1, x, mx_w_f32(w), mx_w_none(), M, N, K);
    CHECK(memcmp(y0, y1, sizeof(float) * M * N) == 0);
    mx_attention(&roomy, y0, q, q, q, 1, 1, T, T, D, D, D, D, 0, 0.2f);
    mx_attention(&tiny, y1, q, q, q, 1, 1, T, T, D, D, D, D, 0, 0.2f);
    CHECK(memcmp(y0, y1, sizeof(float) * T * D) == 0);
    CHECK(tiny.scratch->used == 0 && roomy.scratch->used == 0);
    printf("tiny scratch arena (heap fallback): same results\n");
    free(x), free(w), free(q), free(y0), free(y1);
    mx_ctx_destroy(&roomy);
    mx_ctx_destroy(&tiny);
}

static void test_arena(void) {
    mx_arena a;
    mx_status st;
    mx_status_clear(&st);
    CHECK(mx_arena_create(&a, 1000, &st) == 0);
    void *p1 = mx_arena_alloc(&a, 600, &st);
    CHECK(p1 != NULL && ((uintptr_t)p1 % MX_ARENA_ALIGN) == 0);
    size_t mark = mx_arena_mark(&a);
    void *p2 = mx_arena_alloc(&a, 600, &st);
    CHECK(p2 == NULL);
    CHECK(st.code == MX_ENOMEM);
    CHECK(strstr(st.msg, "out of memory") != NULL);
    printf("arena overrun: \"%s\"\n", st.msg);
    CHECK(mx_arena_floats(&a, SIZE_MAX / 2, &st) == NULL && st.code == MX_ENOMEM);
    mx_arena_reset(&a, mark);
    CHECK(mx_arena_alloc(&a, 300, &st) != NULL);
    mx_arena_destroy(&a);

    mx_arena m;
    mx_arena_measure(&m);
    CHECK(mx_arena_alloc(&m, 100, &st) == NULL);
    CHECK(mx_arena_alloc(&m, 1 << 20, &st) == NULL);
    CHECK(m.peak >= (1 << 20) + 100);
}

static void test_tensor_shapes(void) {
    char buf[64];
    int64_t ok[2] = {3, 4}, neg[2] = {3, -1}, huge[3] = {INT64_MAX / 2, 4, 4}, zero[2] = {0, 5};
    CHECK(mx_shape_numel(2, ok) == 12 && mx_shape_numel(2, zero) == 0);
    CHECK(mx_shape_numel(2, neg) == -1 && mx_shape_numel(3, huge) == -1);
    CHECK(strcmp(mx_shape_str(2, ok, buf, sizeof buf), "[3, 4]") == 0);
    CHECK(mx_dtype_size(MX_BF16) == 2 && mx_dtype_size((mx_dtype)17) == 0 && strcmp(mx_dtype_name(MX_F16), "f16") == 0);
}

static void test_philox(void) {
    static const uint32_t cases[3][10] = {
        {0, 0, 0, 0, 0, 0, 0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8},
        {0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0x408f276d, 0x41c83b0e, 0xa20bc7c6,
         0x6d5451fd},
        {0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344, 0xa4093822, 0x299f31d0, 0xd16cfe09, 0x94fdcceb, 0x5001e420,
         0x24126ea1},
    };
    for (int i = 0; i < 3; i++) {
        uint32_t out[4];
        mx_philox4x32_10(cases[i], cases[i] + 4, out);
        int ok = memcmp(out, cases[i] + 6, sizeof out) == 0;
        printf("philox4x32-10 known answer %d: %08x %08x %08x %08x %s\n", i, out[0], out[1], out[2], out[3],
               ok ? "ok" : "FAIL");
        CHECK(ok);
    }
}

static void test_rng_normal(void) {
    enum { N = 200000 };
    double sum = 0, sq = 0;
    int tail = 0;
    for (uint64_t i = 0; i < N; i++) {
        double v = mx_rng_normal(42, 7, i);
        sum += v;
        sq += v * v;
        tail += fabs(v) > 1.959964;
    }
    double mean = sum / N, sd = sqrt(sq / N - mean * mean), ptail = (double)tail / N;
    printf("mx_rng_normal: mean %.4f std %.4f P(|x|>1.96) %.4f\n", mean, sd, ptail);
    CHECK(fabs(mean) < 0.01);
    CHECK(fabs(sd - 1) < 0.01);
    CHECK(fabs(ptail - 0.05) < 0.003);
    CHECK(mx_rng_normal(42, 7, 5) == mx_rng_normal(42, 7, 5));
    CHECK(mx_rng_normal(42, 7, 5) != mx_rng_normal(42, 8, 5));
    float buf[4];
    mx_rng_fill_normal(buf, 4, 42, 7, 3);
    CHECK(buf[2] == mx_rng_normal(42, 7, 5));
}

/* The writer's text reads back with the reader: nesting, commas, escapes, numbers. */
static void test_json_writer(void) {
    mx_jw w;
    mx_status st = {0};
    mx_jw_init(&w);
    mx_jw_begin_obj(&w, NULL);
    mx_jw_str(&w, "name", "a \"quoted\"\nline");
    mx_jw_num(&w, "x", 0.25);
    mx_jw_int(&w, "n", -7);
    mx_jw_bool(&w, "ok", 1);
    mx_jw_begin_arr(&w, "views");
    mx_jw_int(&w, NULL, 1);
    mx_jw_begin_obj(&w, NULL);
    mx_jw_int(&w, "k", 2);
    mx_jw_end_obj(&w);
    mx_jw_end_arr(&w);
    mx_jw_end_obj(&w);
    const char *text = mx_jw_text(&w);
    mx_json *j = text ? mx_json_parse(text, strlen(text), "jsonw", &st) : NULL;
    CHECK(j != NULL);
    if (j) {
        CHECK(strcmp(mx_json_get_str(j, "name", ""), "a \"quoted\"\nline") == 0);
        CHECK(mx_json_get_num(j, "x", 0) == 0.25 && mx_json_get_num(j, "n", 0) == -7 && mx_json_get_bool(j, "ok", 0));
        const mx_json *v = mx_json_get(j, "views");
        CHECK(v && mx_json_len(v) == 2 && mx_json_get_num(mx_json_at(v, 1), "k", 0) == 2);
        mx_json_free(j);
    }
    mx_jw_free(&w);
}

int main(void) {
    test_json_writer();
    test_arena();
    test_tensor_shapes();
    test_philox();
    test_rng_normal();
    test_small_scratch();
    for (mx_isa isa = MX_ISA_SCALAR; isa <= MX_ISA_AMX; isa++)
        if (mx_kernels_for(isa)->isa == isa) test_thread_invariance(isa);
    return mx_test_finish("test_runtime_basics");
}
