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

__global__ void binary_kernel(int op, float *y, const float *a, const float *b, bcast bc, size_t n) {
    MX_CUDA_GRID_STRIDE(i, n) {
        size_t rest = i;
        long long ia = 0, ib = 0;
        for (int d = bc.ndim - 1; d >= 0; d--) {
            long long coord = (long long)(rest % (size_t)bc.out_shape[d]);
            rest /= (size_t)bc.out_shape[d];
            ia += coord * bc.a_stride[d];
            ib += coord * bc.b_stride[d];
        }
        float va = a[ia], vb = b[ib];
        y[i] = op == MX_BIN_ADD ? va + vb : op == MX_BIN_SUB ? va - vb : va * vb;
    }
}

int mx_cuda_binary(mx_cuda_ctx *c, mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b,
                   const int64_t *bshape, int ndim, mx_status *st) {
    bcast bc = {};
    size_t n = 0;
    if (op != MX_BIN_ADD && op != MX_BIN_SUB && op != MX_BIN_MUL)
        return mx_fail(st, MX_EINPUT, "cuda binary: unknown op %d", (int)op);
    if (bcast_make(&bc, ashape, bshape, ndim, &n, st)) return -1;
    binary_kernel<<<mx_cuda_blocks(n, 256), 256, 0, c->stream>>>((int)op, y, a, b, bc, n);
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
