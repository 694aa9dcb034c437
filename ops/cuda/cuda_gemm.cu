/* The one matrix product of the CUDA backend (cuBLASLt), plus the two small kernels around it:
 * rounding an fp32 activation to the weight's type and adding a bias. */
#include "cuda_common.cuh"

#include <stdint.h>

static cudaDataType_t cuda_type(mx_dtype dt) {
    if (dt == MX_F16) return CUDA_R_16F;
    if (dt == MX_BF16) return CUDA_R_16BF;
    return CUDA_R_32F;
}

/* Largest power of two (<= 256) that divides the address: cuBLASLt picks kernels by alignment. */
static uint32_t pointer_alignment(const void *p) {
    uintptr_t a = (uintptr_t)p;
    uint32_t al = 256;
    while (al > 1 && (a & (al - 1))) al >>= 1;
    return al;
}

/* Everything one cuBLASLt call needs; destroyed by gemm_plan_free whatever happened. */
typedef struct gemm_plan {
    cublasLtMatmulDesc_t op;
    cublasLtMatrixLayout_t a, b, d;
    cublasLtMatmulPreference_t pref;
} gemm_plan;

static void gemm_plan_free(gemm_plan *p) {
    if (p->pref) cublasLtMatmulPreferenceDestroy(p->pref);
    if (p->d) cublasLtMatrixLayoutDestroy(p->d);
    if (p->b) cublasLtMatrixLayoutDestroy(p->b);
    if (p->a) cublasLtMatrixLayoutDestroy(p->a);
    if (p->op) cublasLtMatmulDescDestroy(p->op);
}

static int lt_ok(cublasStatus_t s, const char *what, const char *step, mx_status *st) {
    if (s == CUBLAS_STATUS_SUCCESS) return 0;
    return mx_fail(st, MX_EINTERNAL, "%s: cuBLASLt %s failed (status %d)", what, step, (int)s);
}

static int gemm_plan_make(gemm_plan *p, mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k,
                          const void *A, long long lda, const void *B, long long ldb, float *D, long long ldd,
                          const char *what, mx_status *st) {
    cudaDataType_t t = cuda_type(ab);
    cublasOperation_t ta = transa ? CUBLAS_OP_T : CUBLAS_OP_N, tb = transb ? CUBLAS_OP_T : CUBLAS_OP_N;
    uint64_t ws = c->workspace_bytes;
    uint32_t al_a = pointer_alignment(A), al_b = pointer_alignment(B), al_d = pointer_alignment(D);
    /* CUBLAS_COMPUTE_32F: fp32 accumulation, and for fp32 inputs no TF32 rounding. */
    if (lt_ok(cublasLtMatmulDescCreate(&p->op, CUBLAS_COMPUTE_32F, CUDA_R_32F), what, "desc", st) ||
        lt_ok(cublasLtMatmulDescSetAttribute(p->op, CUBLASLT_MATMUL_DESC_TRANSA, &ta, sizeof ta), what, "transa", st) ||
        lt_ok(cublasLtMatmulDescSetAttribute(p->op, CUBLASLT_MATMUL_DESC_TRANSB, &tb, sizeof tb), what, "transb", st) ||
        lt_ok(cublasLtMatrixLayoutCreate(&p->a, t, transa ? k : m, transa ? m : k, lda), what, "layout A", st) ||
        lt_ok(cublasLtMatrixLayoutCreate(&p->b, t, transb ? n : k, transb ? k : n, ldb), what, "layout B", st) ||
        lt_ok(cublasLtMatrixLayoutCreate(&p->d, CUDA_R_32F, m, n, ldd), what, "layout D", st) ||
        lt_ok(cublasLtMatmulPreferenceCreate(&p->pref), what, "preference", st) ||
        lt_ok(cublasLtMatmulPreferenceSetAttribute(p->pref, CUBLASLT_MATMUL_PREF_MAX_WORKSPACE_BYTES, &ws, sizeof ws),
              what, "workspace preference", st) ||
        lt_ok(cublasLtMatmulPreferenceSetAttribute(p->pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_A_BYTES, &al_a,
                                                   sizeof al_a), what, "alignment A", st) ||
        lt_ok(cublasLtMatmulPreferenceSetAttribute(p->pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_B_BYTES, &al_b,
                                                   sizeof al_b), what, "alignment B", st) ||
        lt_ok(cublasLtMatmulPreferenceSetAttribute(p->pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_C_BYTES, &al_d,
                                                   sizeof al_d), what, "alignment C", st) ||
        lt_ok(cublasLtMatmulPreferenceSetAttribute(p->pref, CUBLASLT_MATMUL_PREF_MIN_ALIGNMENT_D_BYTES, &al_d,
                                                   sizeof al_d), what, "alignment D", st))
        return -1;
    return 0;
}

int mx_cuda_gemm(mx_cuda_ctx *c, mx_dtype ab, int transa, int transb, int m, int n, int k, const void *A,
                 long long lda, const void *B, long long ldb, float *D, long long ldd, const char *what,
                 mx_status *st) {
    gemm_plan p = {};
    cublasLtMatmulHeuristicResult_t h = {};
    int found = 0, rc = -1;
    const float one = 1.0f, zero = 0.0f;
    if (gemm_plan_make(&p, c, ab, transa, transb, m, n, k, A, lda, B, ldb, D, ldd, what, st)) goto done;
    if (lt_ok(cublasLtMatmulAlgoGetHeuristic(c->lt, p.op, p.a, p.b, p.d, p.d, p.pref, 1, &h, &found), what,
              "heuristic", st))
        goto done;
    if (found < 1) {
        mx_fail(st, MX_EINTERNAL, "%s: cuBLASLt has no kernel for %s %dx%dx%d", what, mx_dtype_name(ab), m, n, k);
        goto done;
    }
    /* beta = 0: C is not read, D is written. */
    if (lt_ok(cublasLtMatmul(c->lt, p.op, &one, A, p.a, B, p.b, &zero, D, p.d, D, p.d, &h.algo, c->workspace,
                             c->workspace_bytes, c->stream),
              what, "matmul", st))
        goto done;
    if (ab != MX_F32) c->half_products++;
    rc = 0;
done:
    gemm_plan_free(&p);
    return rc;
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
