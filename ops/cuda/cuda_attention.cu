/* Fused multi-head attention (flash-attention style), fp32 math.
 *
 * A block of 4 warps takes QPW*4 queries of one (batch, head). Keys and values stream through
 * shared memory in tiles of 32; lane j of a warp owns key j of the tile, so a score is one lane's
 * dot product and the tile's max and sum are warp shuffles. The softmax is the streaming one:
 * running max m, running sum l, and the output accumulator rescaled by exp(m_old - m_new) whenever
 * the max grows. For the weighted sum of values, lane t owns head dimensions t, t+32, ... (DPL of
 * them), so a warp writes whole rows of the output. The Tq x Tk score matrix is never built.
 *
 * Shared memory: Q tile [QPW*4][D], K tile [32][D+1] (the +1 keeps the lanes' rows on different
 * banks for the even D of SD: 40, 64, 80, 160, 512), V tile [32][D].
 * Tensor cores (mma.sync on fp16 tiles) are the next step; this kernel is the fp32 baseline. */
#include "cuda_common.cuh"

#define ATTN_WARPS 4
#define ATTN_BK 32

typedef struct attn_args {
    float *out;
    const float *q, *k, *v;
    int H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal;
    float scale;
} attn_args;

template <int QPW> __device__ void attn_load_q(float *Qs, const attn_args &a, int b, int h, int q0) {
    const int bq = QPW * ATTN_WARPS;
    for (int idx = threadIdx.x; idx < bq * a.D; idx += blockDim.x) {
        int r = idx / a.D, d = idx % a.D, t = q0 + r;
        Qs[idx] = t < a.Tq ? a.q[((long long)b * a.Tq + t) * a.q_stride + (long long)h * a.D + d] : 0.0f;
    }
}

__device__ void attn_load_kv(float *Ks, float *Vs, const attn_args &a, int b, int h, int k0) {
    for (int idx = threadIdx.x; idx < ATTN_BK * a.D; idx += blockDim.x) {
        int j = idx / a.D, d = idx % a.D, key = k0 + j;
        long long off = ((long long)b * a.Tk + key) * a.kv_stride + (long long)h * a.D + d;
        Ks[j * (a.D + 1) + d] = key < a.Tk ? a.k[off] : 0.0f;
        Vs[j * a.D + d] = key < a.Tk ? a.v[off] : 0.0f;
    }
}

template <int QPW, int DPL> __global__ void flash_attention_kernel(attn_args a) {
    extern __shared__ float smem[];
    const int bq = QPW * ATTN_WARPS, D = a.D;
    float *Qs = smem, *Ks = Qs + bq * D, *Vs = Ks + ATTN_BK * (D + 1);
    int b = blockIdx.y / a.H, h = blockIdx.y % a.H, q0 = blockIdx.x * bq;
    int warp = threadIdx.x >> 5, lane = threadIdx.x & 31;
    float m[QPW], l[QPW], acc[QPW][DPL];
    for (int i = 0; i < QPW; i++) {
        m[i] = -INFINITY;
        l[i] = 0.0f;
        for (int e = 0; e < DPL; e++) acc[i][e] = 0.0f;
    }
    attn_load_q<QPW>(Qs, a, b, h, q0);
    /* With the causal mask no query of this block sees a key at or after q0 + bq. */
    int kend = a.causal && q0 + bq < a.Tk ? q0 + bq : a.Tk;
    for (int k0 = 0; k0 < kend; k0 += ATTN_BK) {
        __syncthreads(); /* the previous tile is consumed (and Q is loaded) */
        attn_load_kv(Ks, Vs, a, b, h, k0);
        __syncthreads();
        int key = k0 + lane;
        float s[QPW], p[QPW];
        for (int i = 0; i < QPW; i++) s[i] = 0.0f;
        const float *kr = Ks + lane * (D + 1);
        for (int d = 0; d < D; d++) {
            float kd = kr[d];
            for (int i = 0; i < QPW; i++) s[i] += Qs[(warp * QPW + i) * D + d] * kd;
        }
        for (int i = 0; i < QPW; i++) {
            int t = q0 + warp * QPW + i;
            int valid = key < a.Tk && (!a.causal || key <= t);
            float sc = valid ? s[i] * a.scale : -INFINITY;
            float m_new = fmaxf(m[i], mx_cuda_warp_max(sc));
            /* m_new stays -inf only while every key so far is masked: nothing to add yet. */
            float corr = m_new == -INFINITY ? 1.0f : expf(m[i] - m_new);
            p[i] = valid ? expf(sc - m_new) : 0.0f;
            l[i] = l[i] * corr + mx_cuda_warp_sum(p[i]);
            m[i] = m_new;
            for (int e = 0; e < DPL; e++) acc[i][e] *= corr;
        }
        for (int j = 0; j < ATTN_BK; j++) {
            float vj[DPL];
            for (int e = 0; e < DPL; e++) {
                int d = lane + 32 * e;
                vj[e] = d < D ? Vs[j * D + d] : 0.0f;
            }
            for (int i = 0; i < QPW; i++) {
                float pj = __shfl_sync(0xffffffffu, p[i], j);
                for (int e = 0; e < DPL; e++) acc[i][e] += pj * vj[e];
            }
        }
    }
    for (int i = 0; i < QPW; i++) {
        int t = q0 + warp * QPW + i;
        if (t >= a.Tq) continue;
        float inv = 1.0f / l[i];
        float *o = a.out + ((long long)b * a.Tq + t) * a.out_stride + (long long)h * D;
        for (int e = 0; e < DPL; e++) {
            int d = lane + 32 * e;
            if (d < D) o[d] = acc[i][e] * inv;
        }
    }
}

template <int QPW, int DPL> static int attn_launch(mx_cuda_ctx *c, const attn_args &a, int B, mx_status *st) {
    const int bq = QPW * ATTN_WARPS;
    size_t smem = sizeof(float) * ((size_t)bq * a.D + (size_t)ATTN_BK * (a.D + 1) + (size_t)ATTN_BK * a.D);
    if (mx_cuda_ok(cudaFuncSetAttribute(flash_attention_kernel<QPW, DPL>,
                                        cudaFuncAttributeMaxDynamicSharedMemorySize, (int)smem),
                   "cuda attention: shared memory size", st))
        return -1;
    dim3 grid((unsigned)((a.Tq + bq - 1) / bq), (unsigned)(B * a.H));
    flash_attention_kernel<QPW, DPL><<<grid, 32 * ATTN_WARPS, smem, c->stream>>>(a);
    return mx_cuda_launched("cuda attention", st);
}

int mx_cuda_attention(mx_cuda_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                      int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal, float scale,
                      mx_status *st) {
    const long long dims[5] = {B, H, Tq, Tk, D};
    if (mx_cuda_check_dims("cuda attention", st, 5, dims)) return -1;
    if (D > MX_CUDA_ATTN_MAX_D)
        return mx_fail(st, MX_EINPUT, "cuda attention: head size %d above %d", D, MX_CUDA_ATTN_MAX_D);
    if ((long long)B * H > 65535) return mx_fail(st, MX_EINPUT, "cuda attention: %d x %d heads too many", B, H);
    if (q_stride < H * D || kv_stride < H * D || out_stride < H * D)
        return mx_fail(st, MX_EINPUT, "cuda attention: a row stride is below heads x head size (%d)", H * D);
    attn_args a = {out, q, k, v, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal, scale};
    int dpl = (D + 31) / 32;
    if (dpl <= 1) return attn_launch<4, 1>(c, a, B, st);
    if (dpl <= 2) return attn_launch<4, 2>(c, a, B, st);
    if (dpl <= 3) return attn_launch<4, 3>(c, a, B, st);
    if (dpl <= 4) return attn_launch<4, 4>(c, a, B, st);
    if (dpl <= 5) return attn_launch<4, 5>(c, a, B, st);
    if (dpl <= 8) return attn_launch<4, 8>(c, a, B, st);
    return attn_launch<2, 16>(c, a, B, st); /* VAE mid-block: one head of 512 */
}
