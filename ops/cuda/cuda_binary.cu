/* Element-wise arithmetic: y = s·x, and y = a op b with numpy broadcasting over 1..5 dims. The shapes become strides once on the host
 * (stride 0 along a broadcast dim), so the kernel only splits the output index. */
#include "cuda_common.cuh"

typedef struct bcast {
    int ndim;
    long long out_shape[MX_MAX_DIMS];
    long long a_stride[MX_MAX_DIMS], b_stride[MX_MAX_DIMS];
} bcast;

static int bcast_make(bcast *bc, const int64_t *ashape, const int64_t *bshape, int ndim, size_t *n, mx_status *st) {
    if (ndim < 1 || ndim > MX_MAX_DIMS) return mx_fail(st, MX_EINPUT, "cuda binary: ndim %d outside 1..5", ndim);
    bc->ndim = ndim;
    long long sa = 1, sb = 1, total = 1;
    for (int d = ndim - 1; d >= 0; d--) {
        long long da = ashape[d], db = bshape[d];
        if (da <= 0 || db <= 0 || (da != db && da != 1 && db != 1))
            return mx_fail(st, MX_EINPUT, "cuda binary: dims %d: %lld and %lld do not broadcast", d, da, db);
        long long dout = da > db ? da : db;
        bc->out_shape[d] = dout;
        bc->a_stride[d] = da == 1 ? 0 : sa;
        bc->b_stride[d] = db == 1 ? 0 : sb;
        sa *= da;
        sb *= db;
        if (total > (1LL << 62) / dout) return mx_fail(st, MX_EINPUT, "cuda binary: element count overflows");
        total *= dout;
    }
    *n = (size_t)total;
    return 0;
}

__device__ __forceinline__ float binary_apply(int op, float a, float b) {
    return op == MX_BIN_ADD ? a + b : op == MX_BIN_SUB ? a - b : a * b;
}

/* Index type I: 32-bit where the output has fewer than 2^32 elements (64-bit divisions per
 * dimension per element made the broadcast kernel 4x slower than memory allows). */
template <typename I> __global__ void binary_kernel(int op, float *y, const float *a, const float *b, bcast bc, I n) {
    for (I i = blockIdx.x * (I)blockDim.x + threadIdx.x; i < n; i += (I)gridDim.x * blockDim.x) {
        I rest = i, ia = 0, ib = 0;
        for (int d = bc.ndim - 1; d >= 0; d--) {
            I dim = (I)bc.out_shape[d], coord = rest % dim;
            rest /= dim;
            ia += coord * (I)bc.a_stride[d];
            ib += coord * (I)bc.b_stride[d];
        }
        y[i] = binary_apply(op, a[ia], b[ib]);
    }
}

/* a and b of one shape: four elements per thread when all three pointers are 16-byte aligned. */
__global__ void binary_same_kernel(int op, float *y, const float *a, const float *b, size_t n) {
    size_t n4 = ((uintptr_t)y | (uintptr_t)a | (uintptr_t)b) & 15 ? 0 : n / 4;
    MX_CUDA_GRID_STRIDE(i, n4) {
        float4 va = ((const float4 *)a)[i], vb = ((const float4 *)b)[i];
        ((float4 *)y)[i] = make_float4(binary_apply(op, va.x, vb.x), binary_apply(op, va.y, vb.y),
                                       binary_apply(op, va.z, vb.z), binary_apply(op, va.w, vb.w));
    }
    MX_CUDA_GRID_STRIDE(j, n - 4 * n4) y[4 * n4 + j] = binary_apply(op, a[4 * n4 + j], b[4 * n4 + j]);
}

static int same_shape(const int64_t *ashape, const int64_t *bshape, int ndim) {
    for (int d = 0; d < ndim; d++)
        if (ashape[d] != bshape[d]) return 0;
    return 1;
}

int mx_cuda_binary(mx_cuda_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
                   const int64_t *bshape, int ndim, mx_status *st) {
    bcast bc = {};
    size_t n = 0;
    if (op != MX_BIN_ADD && op != MX_BIN_SUB && op != MX_BIN_MUL)
        return mx_fail(st, MX_EINPUT, "cuda binary: unknown op %d", (int)op);
    if (ndim >= 1 && ndim <= MX_MAX_DIMS && !mx_shapes_nonempty(ashape, bshape, ndim)) return 0; /* empty: no work */
    if (bcast_make(&bc, ashape, bshape, ndim, &n, st)) return -1;
    if (same_shape(ashape, bshape, ndim))
        binary_same_kernel<<<mx_cuda_blocks((n + 3) / 4, 256), 256, 0, c->stream>>>((int)op, y, a, b, n);
    else if (n < (1ull << 32))
        binary_kernel<unsigned><<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>((int)op, y, a, b, bc, (unsigned)n);
    else
        binary_kernel<size_t><<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>((int)op, y, a, b, bc, n);
    return mx_cuda_launched("cuda binary", st);
}

__global__ void scale_kernel(float *y, const float *x, float s, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) y[i] = s * x[i];
}

int mx_cuda_scale(mx_cuda_ctx *c, float *y, const float *x, float s, size_t n, mx_status *st) {
    if (n == 0) return 0;
    scale_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>(y, x, s, n);
    return mx_cuda_launched("cuda scale", st);
}
