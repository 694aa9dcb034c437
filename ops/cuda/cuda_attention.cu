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
 * This fp32 kernel runs where the projections feeding the attention had fp32 weights
 * (c->attn_fp32: fp32 networks keep fp32 arithmetic). Otherwise the attention runs on tensor
 * cores: for head sizes up to 160 in one fused kernel (flash_mma_kernel, below); for larger heads
 * (the VAE's one head of 512) as q, k, v rounded to fp16 and packed per head, S = Q·Kᵀ and
 * O = P·V as strided-batched cuBLASLt products over the heads (fp32 accumulation, O written
 * straight into `out`), and between them a softmax kernel with fp32 statistics (max, sum) that
 * writes P in fp16. Its queries go in chunks whose score rows fit the scratch; when not even 16
 * fit, the fp32 kernel runs. */
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

/* ---- tensor cores, fused: flash attention on mma.sync (fp16 operands, fp32 accumulators) ----
 *
 * The path for head sizes up to 160 (all of SD1.5's UNet and ControlNets, CLIP): a block of 4 warps
 * takes 64 queries of one (batch, head), each warp 16 of them. Keys and values stream through
 * shared memory in tiles of 64, converted to fp16 on the way in (V transposed, so both products
 * read their B operand as 32-bit pairs). Per tile a warp computes its 16 x 64 scores with
 * m16n8k16 products (the head dimension padded with zeros to DP, a multiple of 16), keeps them in
 * registers, updates the streaming softmax (running max and sum in fp32, exp2 of scores scaled by
 * scale·log2 e), and multiplies P (rounded to fp16, its accumulator fragments reused as the A
 * operand) by the value tile into its 16 x DP output accumulators. Nothing of size Tq x Tk is
 * written: the products read Q, K and V once per query block and write O once.
 * Fragment layouts (PTX ISA, mma.m16n8k16, g = lane / 4, t = lane % 4): A holds rows g and g + 8,
 * columns 2t, 2t+1 and 2t+8, 2t+9; B holds rows (k) 2t, 2t+1 and 2t+8, 2t+9 of column g; the
 * accumulator rows g and g + 8, columns 2t and 2t+1. Shared rows are padded by 8 halves, so the
 * 32 lanes' 32-bit loads fall on 32 different banks. */
#define FA_WARPS 4
#define FA_BQ (16 * FA_WARPS) /* queries per block */
#define FA_BK 64              /* keys per tile */
#define FA_MAX_D 160

__device__ __forceinline__ void mma_16816(float c[4], const unsigned a[4], unsigned b0, unsigned b1) {
    asm volatile("mma.sync.aligned.m16n8k16.row.col.f32.f16.f16.f32 {%0,%1,%2,%3}, {%4,%5,%6,%7}, {%8,%9}, "
                 "{%0,%1,%2,%3};\n"
                 : "+f"(c[0]), "+f"(c[1]), "+f"(c[2]), "+f"(c[3])
                 : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b0), "r"(b1));
}

/* Two floats as one register of two fp16 (lo in the low half, the lower column index). */
__device__ __forceinline__ unsigned half2_bits(float lo, float hi) {
    __half2 h = __floats2half2_rn(lo, hi);
    return *reinterpret_cast<unsigned *>(&h);
}

__device__ __forceinline__ unsigned smem_pair(const __half *p) { return *reinterpret_cast<const unsigned *>(p); }

/* rows x DP halves of a [rows][DP + 8] tile from fp32 rows `stride` apart (row r at src + r·stride,
 * valid while r < nvalid, else 0; columns from D to DP 0); transposed: written as [DP][rows + 8]. */
template <int DP, int ROWS, bool TRANSPOSED>
__device__ __forceinline__ void fa_load_tile(__half *dst, const float *src, long long stride, int nvalid, int D) {
    for (int idx = threadIdx.x; idx < ROWS * DP; idx += blockDim.x) {
        int r = idx / DP, d = idx % DP;
        float v = r < nvalid && d < D ? src[(long long)r * stride + d] : 0.0f;
        dst[TRANSPOSED ? d * (ROWS + 8) + r : r * (DP + 8) + d] = __float2half_rn(v);
    }
}

template <int DP> __global__ void __launch_bounds__(32 * FA_WARPS) flash_mma_kernel(attn_args a) {
    extern __shared__ __half fa_smem[];
    __half *Qs = fa_smem, *Ks = Qs + FA_BQ * (DP + 8), *Vt = Ks + FA_BK * (DP + 8);
    const int b = blockIdx.y / a.H, h = blockIdx.y % a.H, q0 = blockIdx.x * FA_BQ;
    const int warp = threadIdx.x >> 5, lane = threadIdx.x & 31, g = lane >> 2, t = lane & 3;
    const float sl2 = a.scale * 1.4426950408889634f; /* softmax(scale·s) = 2^(sl2·s) / sum */
    const int row0 = q0 + warp * 16 + g, row1 = row0 + 8;
    fa_load_tile<DP, FA_BQ, false>(Qs, a.q + ((long long)b * a.Tq + q0) * a.q_stride + (long long)h * a.D, a.q_stride,
                                  a.Tq - q0, a.D);
    __syncthreads();
    unsigned qf[DP / 16][4]; /* this warp's 16 query rows as A fragments, for every key tile */
    const __half *qw = Qs + warp * 16 * (DP + 8);
    for (int kk = 0; kk < DP / 16; kk++) {
        qf[kk][0] = smem_pair(qw + g * (DP + 8) + kk * 16 + 2 * t);
        qf[kk][1] = smem_pair(qw + (g + 8) * (DP + 8) + kk * 16 + 2 * t);
        qf[kk][2] = smem_pair(qw + g * (DP + 8) + kk * 16 + 8 + 2 * t);
        qf[kk][3] = smem_pair(qw + (g + 8) * (DP + 8) + kk * 16 + 8 + 2 * t);
    }
    float o[DP / 8][4], m0 = -INFINITY, m1 = -INFINITY, l0 = 0.0f, l1 = 0.0f;
    for (int nd = 0; nd < DP / 8; nd++) o[nd][0] = o[nd][1] = o[nd][2] = o[nd][3] = 0.0f;
    /* With the causal mask no query of this block sees a key at or after q0 + FA_BQ. */
    const int kend = a.causal && q0 + FA_BQ < a.Tk ? q0 + FA_BQ : a.Tk;
    const long long kv_base = (long long)b * a.Tk * a.kv_stride + (long long)h * a.D;
    for (int k0 = 0; k0 < kend; k0 += FA_BK) {
        __syncthreads(); /* every warp is done with the previous tile */
        fa_load_tile<DP, FA_BK, false>(Ks, a.k + kv_base + (long long)k0 * a.kv_stride, a.kv_stride, a.Tk - k0, a.D);
        fa_load_tile<DP, FA_BK, true>(Vt, a.v + kv_base + (long long)k0 * a.kv_stride, a.kv_stride, a.Tk - k0, a.D);
        __syncthreads();
        float s[FA_BK / 8][4];
        for (int nt = 0; nt < FA_BK / 8; nt++) {
            s[nt][0] = s[nt][1] = s[nt][2] = s[nt][3] = 0.0f;
            const __half *kr = Ks + (nt * 8 + g) * (DP + 8) + 2 * t;
            for (int kk = 0; kk < DP / 16; kk++) mma_16816(s[nt], qf[kk], smem_pair(kr + kk * 16), smem_pair(kr + kk * 16 + 8));
        }
        float mx0 = -INFINITY, mx1 = -INFINITY;
        for (int nt = 0; nt < FA_BK / 8; nt++)
            for (int e = 0; e < 2; e++) {
                int key = k0 + nt * 8 + 2 * t + e;
                bool in = key < a.Tk;
                s[nt][e] = in && (!a.causal || key <= row0) ? s[nt][e] * sl2 : -INFINITY;
                s[nt][2 + e] = in && (!a.causal || key <= row1) ? s[nt][2 + e] * sl2 : -INFINITY;
                mx0 = fmaxf(mx0, s[nt][e]);
                mx1 = fmaxf(mx1, s[nt][2 + e]);
            }
        for (int off = 1; off < 4; off <<= 1) { /* the 4 lanes of a row group hold its 64 keys */
            mx0 = fmaxf(mx0, __shfl_xor_sync(0xffffffffu, mx0, off));
            mx1 = fmaxf(mx1, __shfl_xor_sync(0xffffffffu, mx1, off));
        }
        float n0 = fmaxf(m0, mx0), n1 = fmaxf(m1, mx1);
        /* a max still -inf: every key so far masked, nothing to add or rescale */
        float c0 = n0 == -INFINITY ? 1.0f : exp2f(m0 - n0), c1 = n1 == -INFINITY ? 1.0f : exp2f(m1 - n1);
        m0 = n0;
        m1 = n1;
        unsigned pf[FA_BK / 8][2]; /* P rounded to fp16, pairs of the accumulator layout */
        for (int nt = 0; nt < FA_BK / 8; nt++) {
            float p0 = n0 == -INFINITY ? 0.0f : exp2f(s[nt][0] - n0), p1 = n0 == -INFINITY ? 0.0f : exp2f(s[nt][1] - n0);
            float p2 = n1 == -INFINITY ? 0.0f : exp2f(s[nt][2] - n1), p3 = n1 == -INFINITY ? 0.0f : exp2f(s[nt][3] - n1);
            l0 = l0 * (nt ? 1.0f : c0) + p0 + p1; /* per-lane partial sums; the row's total at the end */
            l1 = l1 * (nt ? 1.0f : c1) + p2 + p3;
            pf[nt][0] = half2_bits(p0, p1);
            pf[nt][1] = half2_bits(p2, p3);
        }
        for (int nd = 0; nd < DP / 8; nd++) {
            o[nd][0] *= c0;
            o[nd][1] *= c0;
            o[nd][2] *= c1;
            o[nd][3] *= c1;
        }
        for (int kk = 0; kk < FA_BK / 16; kk++) { /* keys kk·16 .. +15: accumulator tiles 2kk, 2kk+1 as A */
            unsigned pa[4] = {pf[2 * kk][0], pf[2 * kk][1], pf[2 * kk + 1][0], pf[2 * kk + 1][1]};
            for (int nd = 0; nd < DP / 8; nd++) {
                const __half *vr = Vt + (nd * 8 + g) * (FA_BK + 8) + kk * 16 + 2 * t;
                mma_16816(o[nd], pa, smem_pair(vr), smem_pair(vr + 8));
            }
        }
    }
    for (int off = 1; off < 4; off <<= 1) {
        l0 += __shfl_xor_sync(0xffffffffu, l0, off);
        l1 += __shfl_xor_sync(0xffffffffu, l1, off);
    }
    float inv0 = 1.0f / l0, inv1 = 1.0f / l1;
    float *out0 = a.out + ((long long)b * a.Tq + row0) * a.out_stride + (long long)h * a.D;
    float *out1 = out0 + 8LL * a.out_stride;
    for (int nd = 0; nd < DP / 8; nd++)
        for (int e = 0; e < 2; e++) {
            int d = nd * 8 + 2 * t + e;
            if (d >= a.D) continue;
            if (row0 < a.Tq) out0[d] = o[nd][e] * inv0;
            if (row1 < a.Tq) out1[d] = o[nd][2 + e] * inv1;
        }
}

template <int DP> static int flash_mma_launch(mx_cuda_ctx *c, const attn_args &a, int B, mx_status *st) {
    size_t smem = sizeof(__half) * ((size_t)(FA_BQ + FA_BK) * (DP + 8) + (size_t)DP * (FA_BK + 8));
    if (mx_cuda_ok(cudaFuncSetAttribute(flash_mma_kernel<DP>, cudaFuncAttributeMaxDynamicSharedMemorySize, (int)smem),
                   "cuda attention: shared memory size", st))
        return -1;
    dim3 grid((unsigned)((a.Tq + FA_BQ - 1) / FA_BQ), (unsigned)(B * a.H));
    flash_mma_kernel<DP><<<grid, 32 * FA_WARPS, smem, c->stream>>>(a);
    c->half_products++;
    return mx_cuda_launched("cuda attention (tensor cores)", st);
}

/* The fused tensor-core kernel for head size D (padded to a multiple of 16). */
static int flash_mma(mx_cuda_ctx *c, const attn_args &a, int B, mx_status *st) {
    if (a.D <= 48) return flash_mma_launch<48>(c, a, B, st);
    if (a.D <= 64) return flash_mma_launch<64>(c, a, B, st);
    if (a.D <= 80) return flash_mma_launch<80>(c, a, B, st);
    return flash_mma_launch<160>(c, a, B, st);
}

/* ---- tensor cores, large heads: cuBLASLt products around a softmax ---- */

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
    if (!c->attn_fp32 && D <= FA_MAX_D) return flash_mma(c, a, B, st); /* fp32 networks stay in fp32 */
    if (!c->attn_fp32 && (long long)Tk * D < (1LL << 31) && (long long)Tq * D < (1LL << 31)) {
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
