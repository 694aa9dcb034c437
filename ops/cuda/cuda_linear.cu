/* Linear layer y[M,N] = x[M,K] · w[N,K]^T + bias[N] on cuBLASLt.
 * Row-major y is column-major y^T (N x M), so y^T = w · x^T with w read transposed:
 * in column-major terms A = w (stored K x N, ld K, op T), B = x (stored K x M, ld K, op N).
 * With fp16/bf16 weights the rows of x are rounded to the weight's type in the scratch buffer,
 * as many rows at a time as it holds, and each chunk of rows is one GEMM. */
#include "cuda_common.cuh"

/* Rows of x that fit the free scratch once converted (at least 1, or 0 when not even one fits). */
static long long rows_per_chunk(const mx_cuda_ctx *c, int K, size_t esize, int M) {
    size_t free_bytes = c->scratch_cap > c->scratch_used + 256 ? c->scratch_cap - c->scratch_used - 256 : 0;
    long long r = (long long)(free_bytes / ((size_t)K * esize));
    if (r >= M) return M;
    return r >= 16 ? r / 16 * 16 : r; /* whole 16-row groups keep the chunks' D pointers aligned */
}

static int linear_half(mx_cuda_ctx *c, float *y, const float *x, mx_wptr w, int M, int N, int K, mx_status *st) {
    size_t esize = mx_dtype_size(w.dtype);
    long long rows = rows_per_chunk(c, K, esize, M);
    if (rows < 1)
        return mx_fail(st, MX_ENOMEM, "cuda linear: scratch too small for one converted row (%zu bytes)",
                       (size_t)K * esize);
    size_t mark = c->scratch_used;
    void *xc = mx_cuda_scratch(c, (size_t)rows * K * esize, "cuda linear input", st);
    int rc = xc ? 0 : -1;
    for (long long r0 = 0; rc == 0 && r0 < M; r0 += rows) {
        int n = (int)(M - r0 < rows ? M - r0 : rows);
        rc = mx_cuda_convert_from_f32(c, xc, w.dtype, x + r0 * K, (size_t)n * K, "cuda linear input", st);
        if (rc == 0) rc = mx_cuda_gemm(c, w.dtype, 1, 0, N, n, K, w.data, K, xc, K, y + r0 * N, N, "cuda linear", st);
    }
    c->scratch_used = mark;
    return rc;
}

int mx_cuda_linear(mx_cuda_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K,
                   mx_status *st) {
    const long long dims[3] = {M, N, K};
    if (mx_cuda_check_dims("cuda linear", st, 3, dims) || mx_cuda_check_wdtype(w, "cuda linear weight", st))
        return -1;
    c->attn_fp32 = w.dtype == MX_F32; /* the attention this linear feeds computes in its precision */
    int rc = w.dtype == MX_F32 ? mx_cuda_gemm(c, MX_F32, 1, 0, N, M, K, w.data, K, x, K, y, N, "cuda linear", st)
                               : linear_half(c, y, x, w, M, N, K, st);
    if (rc) return -1;
    return mx_cuda_add_bias(c, y, bias, M, N, 1, "cuda linear bias", st);
}
