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
 * This fp32 kernel is the fallback; the default path is on tensor cores (below, attention_tc):
 * q, k, v rounded to fp16 and packed per head, S = Q·Kᵀ and O = P·V as strided-batched cuBLASLt
 * products over the heads (fp32 accumulation, O written straight into `out`), and between them a
 * softmax kernel with fp32 statistics (max, sum) that writes P in fp16. Queries go in chunks whose
 * score rows fit the scratch; when not even 16 fit, the fp32 kernel runs. Under MATEX_CUDA_FLASH=1
 * the fused kernel of cuda_flash.cu takes the tensor-core path's place for head sizes up to 160. */
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

/* Dynamic shared memory of a block of the fp32 kernel at head size D. */
template <int QPW> static size_t attn_smem(int D) {
    const int bq = QPW * ATTN_WARPS;
    return sizeof(float) * ((size_t)bq * D + (size_t)ATTN_BK * (D + 1) + (size_t)ATTN_BK * D);
}

/* Lets a variant's blocks take the shared memory of its largest head size (32·DPL), at most what
 * the device grants a block (optin): a larger call then fails at its launch, as before. Once per
 * context, never per call: a replayed CUDA graph runs no host code (docs/cuda-notes.md §11). */
template <int QPW, int DPL> static int attn_allow_smem(int optin, mx_status *st) {
    size_t want = attn_smem<QPW>(32 * DPL);
    int bytes = want < (size_t)optin ? (int)want : optin;
    return mx_cuda_ok(cudaFuncSetAttribute(flash_attention_kernel<QPW, DPL>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                           bytes),
                      "cuda attention: shared memory size", st);
}

int mx_cuda_attention_open(mx_status *st) {
    int dev = 0, optin = 0;
    if (mx_cuda_ok(cudaGetDevice(&dev), "cuda attention: device", st) ||
        mx_cuda_ok(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev),
                   "cuda attention: shared memory per block", st))
        return -1;
    return attn_allow_smem<4, 1>(optin, st) || attn_allow_smem<4, 2>(optin, st) || attn_allow_smem<4, 3>(optin, st) ||
                   attn_allow_smem<4, 4>(optin, st) || attn_allow_smem<4, 5>(optin, st) ||
                   attn_allow_smem<4, 8>(optin, st) || attn_allow_smem<2, 16>(optin, st)
               ? -1
               : 0;
}

template <int QPW, int DPL> static int attn_launch(mx_cuda_ctx *c, const attn_args &a, int B, mx_status *st) {
    const int bq = QPW * ATTN_WARPS;
    size_t smem = attn_smem<QPW>(a.D);
    dim3 grid((unsigned)((a.Tq + bq - 1) / bq), (unsigned)(B * a.H));
    flash_attention_kernel<QPW, DPL><<<grid, 32 * ATTN_WARPS, smem, c->stream>>>(a);
    return mx_cuda_launched("cuda attention", st);
}

/* ---- tensor cores: cuBLASLt products around a softmax ---- */

#define TC_MIN_ROWS 16 /* fewer query rows per chunk than this: the fp32 kernel instead */

/* dst[h][r][d] (fp16, contiguous per head) = src[(r0 + r) * stride + h * D + d] for r < rows.
 * Grid: x over rows·D, y over heads (32-bit indices: the caller keeps rows·D < 2^31). */
__global__ void pack_heads_kernel(__half *dst, const float *src, int rows, int D, long long stride) {
    unsigned n = (unsigned)rows * (unsigned)D, h = blockIdx.y;
    for (unsigned i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
        unsigned r = i / (unsigned)D, d = i - r * (unsigned)D;
        dst[(size_t)h * n + i] = __float2half_rn(src[(long long)r * stride + (long long)h * D + d]);
    }
}

static int pack_heads(mx_cuda_ctx *c, __half *dst, const float *src, int rows, int H, int D, long long stride,
                      mx_status *st) {
    dim3 grid(mx_cuda_blocks((size_t)rows * D, 256), (unsigned)H);
    pack_heads_kernel<<<grid, 256, 0, c->stream>>>(dst, src, rows, D, stride);
    return mx_cuda_launched("cuda attention: pack", st);
}

/* One block per score row (head h, query q0 + r of the chunk): P = softmax(scale · S) over the Tk
 * keys with max and sum in fp32, causal keys (j > query) 0; rows are ld apart (S fp32, P fp16). */
__global__ void softmax_rows_kernel(__half *P, const float *S, int rows_per_head, int Tk, int ld, int q0, int causal,
                                    float scale) {
    __shared__ float shm[32];
    unsigned row = blockIdx.x;
    const float *s = S + (size_t)row * ld;
    __half *p = P + (size_t)row * ld;
    int q = q0 + (int)(row % (unsigned)rows_per_head), keys = causal && q + 1 < Tk ? q + 1 : Tk;
    float m = -INFINITY;
    for (int j = threadIdx.x; j < keys; j += blockDim.x) m = fmaxf(m, s[j]);
    m = mx_cuda_block_max(m, shm);
    float sum = 0.0f;
    for (int j = threadIdx.x; j < keys; j += blockDim.x) sum += expf(scale * (s[j] - m));
    float inv = 1.0f / mx_cuda_block_sum(sum, shm);
    for (int j = threadIdx.x; j < Tk; j += blockDim.x) p[j] = __float2half_rn(j < keys ? expf(scale * (s[j] - m)) * inv : 0.0f);
}

/* Query rows per chunk whose packed queries and scores (fp32 S and fp16 P, H rows of Tkp each)
 * fit `bytes`. */
static int tc_chunk_rows(size_t bytes, int H, int D, int Tkp, int Tq) {
    size_t per_row = (size_t)H * Tkp * (sizeof(float) + sizeof(__half)) + (size_t)H * D * sizeof(__half);
    size_t rows = bytes / per_row;
    return rows >= (size_t)Tq ? Tq : (int)rows;
}

/* Batch item b on tensor cores; 1 when the scratch cannot hold a chunk of TC_MIN_ROWS queries. */
static int attention_tc_item(mx_cuda_ctx *c, const attn_args &a, int b, mx_status *st) {
    const int H = a.H, D = a.D, Tkp = (a.Tk + 7) & ~7; /* score rows 16-byte aligned for the fp16 kernels */
    size_t kv = (size_t)H * a.Tk * D;
    __half *Kh = (__half *)mx_cuda_scratch(c, kv * sizeof(__half), "cuda attention", st);
    __half *Vh = Kh ? (__half *)mx_cuda_scratch(c, kv * sizeof(__half), "cuda attention", st) : NULL;
    if (!Vh) return 1;
    size_t left = c->scratch_cap - c->scratch_used;
    int rows = tc_chunk_rows(left > 4096 ? left - 4096 : 0, H, D, Tkp, a.Tq); /* 4096: alignment slack */
    if (rows < TC_MIN_ROWS && rows < a.Tq) return 1;
    __half *Qh = (__half *)mx_cuda_scratch(c, (size_t)H * rows * D * sizeof(__half), "cuda attention", st);
    float *S = Qh ? (float *)mx_cuda_scratch(c, (size_t)H * rows * Tkp * sizeof(float), "cuda attention", st) : NULL;
    __half *P = S ? (__half *)mx_cuda_scratch(c, (size_t)H * rows * Tkp * sizeof(__half), "cuda attention", st) : NULL;
    if (!P) return 1;
    const float *kb = a.k + (long long)b * a.Tk * a.kv_stride, *vb = a.v + (long long)b * a.Tk * a.kv_stride;
    if (pack_heads(c, Kh, kb, a.Tk, H, D, a.kv_stride, st) || pack_heads(c, Vh, vb, a.Tk, H, D, a.kv_stride, st))
        return -1;
    for (int q0 = 0; q0 < a.Tq; q0 += rows) {
        int n = a.Tq - q0 < rows ? a.Tq - q0 : rows;
        const float *qb = a.q + ((long long)b * a.Tq + q0) * a.q_stride;
        float *ob = a.out + ((long long)b * a.Tq + q0) * a.out_stride;
        /* column-major: Sᵀ[Tk x n] = K_h (D x Tk, transposed) · Q_hᵀ (D x n), per head */
        if (pack_heads(c, Qh, qb, n, H, D, a.q_stride, st) ||
            mx_cuda_gemm_batched(c, MX_F16, 1, 0, a.Tk, n, D, Kh, D, (long long)a.Tk * D, Qh, D, (long long)n * D, S,
                                 Tkp, (long long)n * Tkp, H, "cuda attention: Q·K", st))
            return -1;
        softmax_rows_kernel<<<(unsigned)(H * n), 128, 0, c->stream>>>(P, S, n, a.Tk, Tkp, q0, a.causal, a.scale);
        if (mx_cuda_launched("cuda attention: softmax", st)) return -1;
        /* Oᵀ[D x n] = V_h (D x Tk) · Pᵀ (Tk x n), into out's rows (ld out_stride, head h at h·D) */
        if (mx_cuda_gemm_batched(c, MX_F16, 0, 0, D, n, a.Tk, Vh, D, (long long)a.Tk * D, P, Tkp, (long long)n * Tkp, ob,
                                 a.out_stride, D, H, "cuda attention: P·V", st))
            return -1;
    }
    return 0;
}

/* Every batch item on tensor cores; 1 (nothing queued) when the scratch is too small. */
static int attention_tc(mx_cuda_ctx *c, const attn_args &a, int B, mx_status *st) {
    size_t mark = c->scratch_used;
    int rc = 0;
    for (int b = 0; b < B && rc == 0; b++) {
        rc = attention_tc_item(c, a, b, st);
        c->scratch_used = mark;
        if (rc == 1 && b > 0) rc = -1; /* cannot happen: every item needs the same */
    }
    return rc;
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
    if (!c->attn_fp32) { /* MATEX_CUDA_FLASH=1: the fused kernel, no score matrix (cuda_flash.cu) */
        int rc = mx_cuda_flash_attention(c, out, q, k, v, B, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal,
                                         scale, st);
        if (rc <= 0) return rc;
    }
    if (!c->attn_fp32 && (long long)Tk * D < (1LL << 31) && (long long)Tq * D < (1LL << 31)) { /* fp32 stays fp32 */
        int rc = attention_tc(c, a, B, st);
        if (rc <= 0) return rc;
    }
    int dpl = (D + 31) / 32;
    if (dpl <= 1) return attn_launch<4, 1>(c, a, B, st);
    if (dpl <= 2) return attn_launch<4, 2>(c, a, B, st);
    if (dpl <= 3) return attn_launch<4, 3>(c, a, B, st);
    if (dpl <= 4) return attn_launch<4, 4>(c, a, B, st);
    if (dpl <= 5) return attn_launch<4, 5>(c, a, B, st);
    if (dpl <= 8) return attn_launch<4, 8>(c, a, B, st);
    return attn_launch<2, 16>(c, a, B, st); /* VAE mid-block: one head of 512 */
}
