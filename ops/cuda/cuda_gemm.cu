/* The one matrix product of the CUDA backend (cuBLASLt), plus the two small kernels around it:
 * rounding an fp32 activation to the weight's type and adding a bias. */
#include "cuda_common.cuh"

#include <stdint.h>
#include <string.h>

static cudaDataType_t cuda_type(mx_dtype dt) {
    if (dt == MX_F16) return CUDA_R_16F;
    if (dt == MX_BF16) return CUDA_R_16BF;
    return CUDA_R_32F;
}

/* Largest power of two (<= 16) that divides the address: cuBLASLt picks kernels by alignment. Capped:
 * buffers of the 64-byte arena at 64/128/256 get one plan, not another algorithm (sum order). */
static uint32_t pointer_alignment(const void *p) {
    uintptr_t a = (uintptr_t)p;
    uint32_t al = 16;
    while (al > 1 && (a & (al - 1))) al >>= 1;
    return al;
}

/* One matrix product's shape: what a plan depends on (the pointers only through their alignment). */
typedef struct gemm_key {
    int ab, transa, transb, m, n, k, batch, pin_n; /* pin_n > 0: the algorithm is the one for n = pin_n */
    long long lda, ldb, ldd, sa, sb, sd; /* leading dimensions, batch strides (elements) */
    uint32_t al_a, al_b, al_d;
} gemm_key;

/* Everything one cuBLASLt call needs: descriptors, layouts and the heuristic's algorithm, made
 * once per shape and kept in the context's plan table (cublasLt descriptors and heuristics cost
 * 10-30 us of host time each; a guided SD1.5 step makes ~800 GEMM calls of ~100 shapes). */
typedef struct gemm_plan {
    gemm_key key;
    cublasLtMatmulDesc_t op;
    cublasLtMatrixLayout_t a, b, d;
    cublasLtMatmulAlgo_t algo;
    int ready;
} gemm_plan;

#define GEMM_PLANS 512 /* open addressing; a full neighbourhood evicts (rebuilt when needed again) */
#define GEMM_PROBES 8

struct mx_cuda_gemm_plans {
    gemm_plan slot[GEMM_PLANS];
};

static void gemm_plan_free(gemm_plan *p) {
    if (p->d) cublasLtMatrixLayoutDestroy(p->d);
    if (p->b) cublasLtMatrixLayoutDestroy(p->b);
    if (p->a) cublasLtMatrixLayoutDestroy(p->a);
    if (p->op) cublasLtMatmulDescDestroy(p->op);
    memset(p, 0, sizeof *p);
}

void mx_cuda_gemm_plans_free(mx_cuda_ctx *c) {
    if (!c->gemm_plans) return;
    for (int i = 0; i < GEMM_PLANS; i++) gemm_plan_free(&c->gemm_plans->slot[i]);
    free(c->gemm_plans);
    c->gemm_plans = NULL;
}

static int lt_ok(cublasStatus_t s, const char *what, const char *step, mx_status *st) {
    if (s == CUBLAS_STATUS_SUCCESS) return 0;
    return mx_fail(st, MX_EINTERNAL, "%s: cuBLASLt %s failed (status %d)", what, step, (int)s);
}

/* A layout of rows x cols (column-major, leading dimension ld), batched when key->batch > 1. */
static int layout_make(cublasLtMatrixLayout_t *l, cudaDataType_t t, int rows, int cols, long long ld, int batch,
                       long long stride, const char *what, const char *name, mx_status *st) {
    int64_t off = stride;
    if (lt_ok(cublasLtMatrixLayoutCreate(l, t, (uint64_t)rows, (uint64_t)cols, ld), what, name, st)) return -1;
    if (batch <= 1) return 0;
    return lt_ok(cublasLtMatrixLayoutSetAttribute(*l, CUBLASLT_MATRIX_LAYOUT_BATCH_COUNT, &batch, sizeof batch), what,
                 name, st) ||
                   lt_ok(cublasLtMatrixLayoutSetAttribute(*l, CUBLASLT_MATRIX_LAYOUT_STRIDED_BATCH_OFFSET, &off,
                                                          sizeof off),
                         what, name, st)
               ? -1
               : 0;
}

/* The heuristic's best algorithm for layouts b and d, within the context's workspace. */
static int plan_algo(gemm_plan *p, mx_cuda_ctx *c, cublasLtMatrixLayout_t b, cublasLtMatrixLayout_t d,
                     const char *what, mx_status *st) {
    const gemm_key *k = &p->key;
    cublasLtMatmulPreference_t pref = NULL;
    cublasLtMatmulHeuristicResult_t h = {};
    uint64_t ws = c->workspace_bytes;
    int found = 0;
    int rc = lt_ok(cublasLtMatmulPreferenceCreate(&pref), what, "preference", st) ||
             lt_ok(cublasLtMatmulPreferenceSetAttribute(pref, CUBLASLT_MATMUL_PREF_MAX_WORKSPACE_BYTES, &ws, sizeof ws),
                   what, "workspace preference", st) ||
             lt_ok(cublasLtMatmulPreferenceSetAttribute(pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_A_BYTES, &k->al_a,
                                                        sizeof k->al_a), what, "alignment A", st) ||
             lt_ok(cublasLtMatmulPreferenceSetAttribute(pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_B_BYTES, &k->al_b,
                                                        sizeof k->al_b), what, "alignment B", st) ||
             lt_ok(cublasLtMatmulPreferenceSetAttribute(pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_C_BYTES, &k->al_d,
                                                        sizeof k->al_d), what, "alignment C", st) ||
             lt_ok(cublasLtMatmulPreferenceSetAttribute(pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_D_BYTES, &k->al_d,
                                                        sizeof k->al_d), what, "alignment D", st) ||
             lt_ok(cublasLtMatmulAlgoGetHeuristic(c->lt, p->op, p->a, b, d, d, pref, 1, &h, &found), what,
                   "heuristic", st)
                 ? -1
                 : 0;
    if (pref) cublasLtMatmulPreferenceDestroy(pref);
    if (rc == 0 && found < 1)
        rc = mx_fail(st, MX_EINTERNAL, "%s: cuBLASLt has no kernel for %s %dx%dx%d", what,
                     mx_dtype_name((mx_dtype)k->ab), k->m, k->n, k->k);
    if (rc == 0) p->algo = h.algo;
    return rc;
}

static int plan_make(gemm_plan *p, mx_cuda_ctx *c, const gemm_key *k, const char *what, mx_status *st) {
    cudaDataType_t t = cuda_type((mx_dtype)k->ab);
    cublasOperation_t ta = k->transa ? CUBLAS_OP_T : CUBLAS_OP_N, tb = k->transb ? CUBLAS_OP_T : CUBLAS_OP_N;
    memset(p, 0, sizeof *p);
    p->key = *k;
    /* CUBLAS_COMPUTE_32F: fp32 accumulation, and for fp32 inputs no TF32 rounding. */
    if (lt_ok(cublasLtMatmulDescCreate(&p->op, CUBLAS_COMPUTE_32F, CUDA_R_32F), what, "desc", st) ||
        lt_ok(cublasLtMatmulDescSetAttribute(p->op, CUBLASLT_MATMUL_DESC_TRANSA, &ta, sizeof ta), what, "transa", st) ||
        lt_ok(cublasLtMatmulDescSetAttribute(p->op, CUBLASLT_MATMUL_DESC_TRANSB, &tb, sizeof tb), what, "transb", st) ||
        layout_make(&p->a, t, k->transa ? k->k : k->m, k->transa ? k->m : k->k, k->lda, k->batch, k->sa, what,
                    "layout A", st) ||
        layout_make(&p->b, t, k->transb ? k->n : k->k, k->transb ? k->k : k->n, k->ldb, k->batch, k->sb, what,
                    "layout B", st) ||
        layout_make(&p->d, CUDA_R_32F, k->m, k->n, k->ldd, k->batch, k->sd, what, "layout D", st)) {
        gemm_plan_free(p);
        return -1;
    }
    int rc = 1; /* pinned: the n = pin_n problem's algorithm, when it runs this shape */
    if (k->pin_n && k->batch == 1) {
        cublasLtMatrixLayout_t b = NULL, d = NULL;
        cublasLtMatmulHeuristicResult_t r = {};
        rc = layout_make(&b, t, k->transb ? k->pin_n : k->k, k->transb ? k->k : k->pin_n, k->ldb, 1, 0, what, "B", st) ||
             layout_make(&d, CUDA_R_32F, k->m, k->pin_n, k->ldd, 1, 0, what, "D", st) || plan_algo(p, c, b, d, what, st) ||
             cublasLtMatmulAlgoCheck(c->lt, p->op, p->a, p->b, p->d, p->d, &p->algo, &r) ||
             r.workspaceSize > c->workspace_bytes;
        if (d) cublasLtMatrixLayoutDestroy(d);
        if (b) cublasLtMatrixLayoutDestroy(b);
    }
    if (rc && plan_algo(p, c, p->b, p->d, what, st)) {
        gemm_plan_free(p);
        return -1;
    }
    p->ready = 1;
    return 0;
}

static uint32_t key_hash(const gemm_key *k) {
    const unsigned char *b = (const unsigned char *)k;
    uint32_t h = 2166136261u; /* FNV-1a over the key's bytes (memset first, so padding is 0) */
    for (size_t i = 0; i < sizeof *k; i++) h = (h ^ b[i]) * 16777619u;
    return h;
}

/* The cached plan of k, made on first use. */
static gemm_plan *plan_for(mx_cuda_ctx *c, const gemm_key *k, const char *what, mx_status *st) {
    if (!c->gemm_plans && !(c->gemm_plans = (mx_cuda_gemm_plans *)calloc(1, sizeof *c->gemm_plans))) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory for GEMM plans", what);
        return NULL;
    }
    uint32_t h = key_hash(k);
    gemm_plan *slot = c->gemm_plans->slot, *free_slot = NULL;
    for (int i = 0; i < GEMM_PROBES; i++) {
        gemm_plan *p = &slot[(h + (uint32_t)i) % GEMM_PLANS];
        if (p->ready && memcmp(&p->key, k, sizeof *k) == 0) return p;
        if (!p->ready && !free_slot) free_slot = p;
    }
    if (c->capturing) { /* plans are made by a recorded region's first call, which runs directly */
        char why[160];
        snprintf(why, sizeof why, "%s: a new cuBLASLt plan (%s %dx%dx%d, batch %d)", what,
                 mx_dtype_name((mx_dtype)k->ab), k->m, k->n, k->k, k->batch);
        mx_cuda_not_capturing(c, why, st);
        return NULL;
    }
    if (!free_slot) { /* neighbourhood full: evict the home slot */
        free_slot = &slot[h % GEMM_PLANS];
        gemm_plan_free(free_slot);
    }
    return plan_make(free_slot, c, k, what, st) ? NULL : free_slot;
}

/* Alignment of every batch item's pointer: of the base and of the stride in bytes. */
static uint32_t batch_alignment(const void *p, long long stride, size_t elem, int batch) {
    uint32_t al = pointer_alignment(p);
    if (batch > 1) {
        uint32_t as = pointer_alignment((const void *)(uintptr_t)((unsigned long long)stride * elem));
        if (as < al) al = as;
    }
    return al;
}

static int gemm_run(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                    long long lda, long long sa, const void *B, long long ldb, long long sb, float *D, long long ldd,
                    long long sd, int batch, int pin_n, const char *what, mx_status *st) {
    gemm_key key;
    memset(&key, 0, sizeof key);
    key.pin_n = pin_n;
    size_t es = ab == MX_F32 ? 4 : 2;
    key.ab = (int)ab, key.transa = transa, key.transb = transb, key.m = m, key.n = n, key.k = k;
    key.batch = batch > 1 ? batch : 1;
    key.lda = lda, key.ldb = ldb, key.ldd = ldd;
    if (key.batch > 1) key.sa = sa, key.sb = sb, key.sd = sd;
    key.al_a = batch_alignment(A, key.sa, es, key.batch);
    key.al_b = batch_alignment(B, key.sb, es, key.batch);
    key.al_d = batch_alignment(D, key.sd, sizeof(float), key.batch);
    gemm_plan *p = plan_for(c, &key, what, st);
    if (!p) return -1;
    const float one = 1.0f, zero = 0.0f;
    /* beta = 0: C is not read, D is written. */
    if (lt_ok(cublasLtMatmul(c->lt, p->op, &one, A, p->a, B, p->b, &zero, D, p->d, D, p->d, &p->algo, c->workspace,
                             c->workspace_bytes, c->stream),
              what, "matmul", st))
        return -1;
    if (ab != MX_F32) c->half_products++;
    return 0;
}

int mx_cuda_gemm(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                 long long lda, const void *B, long long ldb, float *D, long long ldd, const char *what,
                 mx_status *st) { /* n (a linear's B·T rows) does not choose the algorithm: batch-independent */
    return gemm_run(c, ab, transa, transb, m, n, k, A, lda, 0, B, ldb, 0, D, ldd, 0, 1, 1024, what, st);
}

int mx_cuda_gemm_batched(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                         long long lda, long long sa, const void *B, long long ldb, long long sb, float *D,
                         long long ldd, long long sd, int batch, const char *what, mx_status *st) {
    return gemm_run(c, ab, transa, transb, m, n, k, A, lda, sa, B, ldb, sb, D, ldd, sd, batch, 0, what, st);
}

template <typename T> __device__ __forceinline__ T from_f32(float v);
template <> __device__ __forceinline__ float from_f32<float>(float v) { return v; }
template <> __device__ __forceinline__ __half from_f32<__half>(float v) { return __float2half_rn(v); }
template <> __device__ __forceinline__ __nv_bfloat16 from_f32<__nv_bfloat16>(float v) {
    return __float2bfloat16_rn(v);
}

template <typename T> __global__ void convert_from_f32_kernel(T *dst, const float *src, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n)
        dst[i] = from_f32<T>(src[i]);
}

int mx_cuda_convert_from_f32(mx_cuda_ctx *c, void *dst, mx_dtype dt, const float *src, size_t n, const char *what,
                             mx_status *st) {
    if (n == 0) return 0;
    unsigned blocks = mx_cuda_blocks(n, 256);
    if (dt == MX_F16)
        convert_from_f32_kernel<__half><<<blocks, 256, 0, c->stream>>>((__half *)dst, src, n);
    else if (dt == MX_BF16)
        convert_from_f32_kernel<__nv_bfloat16><<<blocks, 256, 0, c->stream>>>((__nv_bfloat16 *)dst, src, n);
    else
        return mx_cuda_ok(cudaMemcpyAsync(dst, src, n * sizeof(float), cudaMemcpyDeviceToDevice, c->stream), what,
                          st);
    return mx_cuda_launched(what, st);
}

__global__ void add_bias_kernel(float *y, const void *bias, int dtype, long long outer, int channels,
                                long long inner) {
    size_t n = (size_t)outer * channels * inner;
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t ch = (i / (size_t)inner) % (size_t)channels;
        y[i] += mx_cuda_wload(bias, dtype, ch);
    }
}

int mx_cuda_add_bias(mx_cuda_ctx *c, float *y, mx_wptr bias, long long outer, int channels, long long inner,
                     const char *what, mx_status *st) {
    if (!bias.data) return 0;
    if (mx_cuda_check_wdtype(bias, what, st)) return -1;
    size_t n = (size_t)outer * channels * inner;
    add_bias_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, bias.data, (int)bias.dtype, outer, channels,
                                                                   inner);
    return mx_cuda_launched(what, st);
}
