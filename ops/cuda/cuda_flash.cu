/* Attention that never materialises the scores: FlashAttention-2 style on mma.sync m16n8k16 (fp16
 * operands, fp32 softmax statistics and accumulators), for head sizes up to 160 (SD1.5's UNet and
 * ControlNets, CLIP). OFF unless MATEX_CUDA_FLASH=1 (no GPU has run this version yet: docs/cuda-notes.md
 * §9); then it replaces the cuBLASLt path of cuda_attention.cu for networks with fp16/bf16 weights.
 *
 * The kernel is commit 9d25a61's (it passed every op and network test on an H200, and lost to the
 * cuBLASLt path, 482 against 408 us a UNet call, because every block of 64 queries loaded K and V
 * in fp32 and converted them to fp16, V transposed element by element). Here, per batch item, one
 * pass first packs K to fp16 [H][Tkp][DP] and V to fp16 transposed [H][DP][Tkp] (keys padded with
 * zeros to a multiple of 64, the head size to DP, a multiple of 16), so a block loads each K and V
 * tile with 16-byte copies and no conversion.
 *
 * A block of 4 warps takes 64 queries of one head, each warp 16. Per key tile of 64 a warp computes
 * its 16 x 64 scores with m16n8k16 products, keeps them in registers, updates the streaming softmax
 * (running max and sum in fp32, exp2 of scores scaled by scale·log2 e), and multiplies P (rounded
 * to fp16, its accumulator fragments reused as the A operand) by the value tile into its 16 x DP
 * output accumulators. Fragment layouts (PTX ISA, mma.m16n8k16, g = lane / 4, t = lane % 4): A holds
 * rows g and g + 8, columns 2t, 2t+1 and 2t+8, 2t+9; B holds rows (k) 2t, 2t+1 and 2t+8, 2t+9 of
 * column g; the accumulator rows g and g + 8, columns 2t and 2t+1. Shared rows are padded by 8
 * halves, so the 32 lanes' 32-bit loads fall on 32 different banks. */
#include <string.h>

#include "cuda_common.cuh"
extern "C" {
#include "../../runtime/log.h" /* a C header without its own extern "C" */
}

#define FA_WARPS 4
#define FA_BQ (16 * FA_WARPS) /* queries per block */
#define FA_BK 64              /* keys per tile */
#define FA_MAX_D 160

typedef struct flash_args {
    float *out;       /* item b's rows */
    const float *q;   /* item b's rows */
    const __half *kp; /* [H][Tkp][DP] */
    const __half *vt; /* [H][DP][Tkp] */
    int H, Tq, Tk, Tkp, D, q_stride, out_stride, causal;
    float scale;
} flash_args;

/* ---- the packing pass: K and V of one item, fp32 rows (kv_stride apart, head h at h·D) ---- */

/* kp[h][j][d] = k[j][h·D + d] and vt[h][d][j] = v[j][h·D + d] in fp16, 0 where j >= Tk or d >= D.
 * Element i of the padded [Tkp][DP] (K) and [DP][Tkp] (V) planes per thread, so both writes are
 * coalesced; V's reads are strided (a tiled transpose would coalesce them: measure first). Grid y
 * over heads. */
template <int DP>
__global__ void flash_pack_kernel(__half *kp, __half *vt, const float *k, const float *v, int Tk, int Tkp, int D,
                                  long long kv_stride) {
    const unsigned h = blockIdx.y, n = (unsigned)Tkp * DP;
    for (unsigned i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
        unsigned j = i / DP, d = i - j * DP;
        kp[(size_t)h * n + i] = __float2half_rn((int)j < Tk && (int)d < D ? k[(long long)j * kv_stride + h * D + d] : 0.0f);
        d = i / (unsigned)Tkp, j = i - d * (unsigned)Tkp;
        vt[(size_t)h * n + i] = __float2half_rn((int)j < Tk && (int)d < D ? v[(long long)j * kv_stride + h * D + d] : 0.0f);
    }
}

/* ---- the fused kernel ---- */

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

/* rows x cols halves from global rows `src_ld` apart into shared rows cols + 8 apart, 16 bytes a copy
 * (cols and src_ld multiples of 8; every source row exists: the packing padded them). */
template <int ROWS, int COLS> __device__ __forceinline__ void copy_tile(__half *dst, const __half *src, int src_ld) {
    for (int idx = threadIdx.x; idx < ROWS * COLS / 8; idx += blockDim.x) {
        int r = idx / (COLS / 8), c8 = (idx % (COLS / 8)) * 8;
        *reinterpret_cast<uint4 *>(dst + r * (COLS + 8) + c8) =
            *reinterpret_cast<const uint4 *>(src + (size_t)r * src_ld + c8);
    }
}

template <int DP> __global__ void __launch_bounds__(32 * FA_WARPS) flash_kernel(flash_args a) {
    extern __shared__ __align__(16) __half fa_smem[];
    __half *Qs = fa_smem, *Ks = Qs + FA_BQ * (DP + 8), *Vt = Ks + FA_BK * (DP + 8);
    const int h = blockIdx.y, q0 = blockIdx.x * FA_BQ;
    const int warp = threadIdx.x >> 5, lane = threadIdx.x & 31, g = lane >> 2, t = lane & 3;
    const float sl2 = a.scale * 1.4426950408889634f; /* softmax(scale·s) = 2^(sl2·s) / sum */
    const int row0 = q0 + warp * 16 + g, row1 = row0 + 8;
    for (int idx = threadIdx.x; idx < FA_BQ * DP; idx += blockDim.x) { /* Q: fp32 rows, once per block */
        int r = idx / DP, d = idx % DP;
        float v = q0 + r < a.Tq && d < a.D ? a.q[(long long)(q0 + r) * a.q_stride + (long long)h * a.D + d] : 0.0f;
        Qs[r * (DP + 8) + d] = __float2half_rn(v);
    }
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
    const __half *kh = a.kp + (size_t)h * a.Tkp * DP, *vh = a.vt + (size_t)h * DP * a.Tkp;
    for (int k0 = 0; k0 < kend; k0 += FA_BK) {
        __syncthreads(); /* every warp is done with the previous tile */
        copy_tile<FA_BK, DP>(Ks, kh + (size_t)k0 * DP, DP);
        copy_tile<DP, FA_BK>(Vt, vh + k0, a.Tkp);
        __syncthreads();
        float s[FA_BK / 8][4];
        for (int nt = 0; nt < FA_BK / 8; nt++) {
            s[nt][0] = s[nt][1] = s[nt][2] = s[nt][3] = 0.0f;
            const __half *kr = Ks + (nt * 8 + g) * (DP + 8) + 2 * t;
            for (int kk = 0; kk < DP / 16; kk++)
                mma_16816(s[nt], qf[kk], smem_pair(kr + kk * 16), smem_pair(kr + kk * 16 + 8));
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
    float *out0 = a.out + (long long)row0 * a.out_stride + (long long)h * a.D;
    float *out1 = out0 + 8LL * a.out_stride;
    for (int nd = 0; nd < DP / 8; nd++)
        for (int e = 0; e < 2; e++) {
            int d = nd * 8 + 2 * t + e;
            if (d >= a.D) continue;
            if (row0 < a.Tq) out0[d] = o[nd][e] * inv0;
            if (row1 < a.Tq) out1[d] = o[nd][2 + e] * inv1;
        }
}

/* ---- launch ---- */

template <int DP> static size_t flash_smem(void) {
    return sizeof(__half) * ((size_t)(FA_BQ + FA_BK) * (DP + 8) + (size_t)DP * (FA_BK + 8));
}

/* Lets the kernel's blocks take their shared memory: once, at context creation (a replayed CUDA
 * graph runs no host code). */
template <int DP> static cudaError_t flash_allow_smem(void) {
    return cudaFuncSetAttribute(flash_kernel<DP>, cudaFuncAttributeMaxDynamicSharedMemorySize, (int)flash_smem<DP>());
}

/* Queues item by item: the packing pass of its K and V, then the fused kernel over its queries and heads. */
template <int DP>
static int flash_queue(mx_cuda_ctx *c, __half *kp, __half *vt, float *out, const float *q, const float *k,
                       const float *v, int B, int H, int Tq, int Tk, int Tkp, int D, int q_stride, int kv_stride,
                       int out_stride, int causal, float scale, mx_status *st) {
    size_t smem = flash_smem<DP>();
    for (int b = 0; b < B; b++) {
        dim3 pgrid(mx_cuda_blocks((size_t)Tkp * DP, 256), (unsigned)H);
        flash_pack_kernel<DP><<<pgrid, 256, 0, c->stream>>>(kp, vt, k + (long long)b * Tk * kv_stride,
                                                             v + (long long)b * Tk * kv_stride, Tk, Tkp, D, kv_stride);
        if (mx_cuda_launched("cuda flash attention: pack", st)) return -1;
        flash_args a = {out + (long long)b * Tq * out_stride, q + (long long)b * Tq * q_stride, kp, vt, H, Tq, Tk, Tkp,
                        D, q_stride, out_stride, causal, scale};
        dim3 grid((unsigned)((Tq + FA_BQ - 1) / FA_BQ), (unsigned)H);
        flash_kernel<DP><<<grid, 32 * FA_WARPS, smem, c->stream>>>(a);
        if (mx_cuda_launched("cuda flash attention", st)) return -1;
    }
    c->half_products++;
    c->flash_calls++;
    return 0;
}

/* K and V of one item in the scratch, then flash_queue; 1 when they do not fit. */
template <int DP>
static int flash_items(mx_cuda_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                       int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal, float scale,
                       mx_status *st) {
    const int Tkp = (Tk + FA_BK - 1) / FA_BK * FA_BK;
    size_t each = (size_t)H * Tkp * DP * sizeof(__half);
    size_t mark = c->scratch_used;
    __half *kp = (__half *)mx_cuda_scratch(c, each, "cuda flash attention K", st);
    __half *vt = kp ? (__half *)mx_cuda_scratch(c, each, "cuda flash attention V", st) : NULL;
    int rc = vt ? flash_queue<DP>(c, kp, vt, out, q, k, v, B, H, Tq, Tk, Tkp, D, q_stride, kv_stride, out_stride, causal,
                              scale, st)
                : 1; /* the scratch cannot hold one item's K and V: the cuBLASLt path */
    c->scratch_used = mark;
    return rc;
}

void mx_cuda_flash_open(mx_cuda_ctx *c) {
    const char *env = getenv("MATEX_CUDA_FLASH");
    c->flash_attn = env && strcmp(env, "1") == 0;
    if (!c->flash_attn) return;
    cudaError_t e = flash_allow_smem<48>();
    if (e == cudaSuccess) e = flash_allow_smem<64>();
    if (e == cudaSuccess) e = flash_allow_smem<80>();
    if (e == cudaSuccess) e = flash_allow_smem<160>();
    if (e == cudaSuccess) return;
    c->flash_attn = 0;
    (void)cudaGetLastError();
    mx_warn("cuda: MATEX_CUDA_FLASH=1 ignored, the fused attention cannot have its shared memory (%s): %s",
            cudaGetErrorName(e), cudaGetErrorString(e));
}

int mx_cuda_flash_attention(mx_cuda_ctx *c, float *out, const float *q, const float *k, const float *v, int B, int H,
                            int Tq, int Tk, int D, int q_stride, int kv_stride, int out_stride, int causal,
                            float scale, mx_status *st) {
    if (!c->flash_attn || D > FA_MAX_D || H > 65535 || (long long)Tk * FA_MAX_D >= (1LL << 31)) return 1;
#define FLASH_(DP)                                                                                                 \
    return flash_items<DP>(c, out, q, k, v, B, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal, scale, st)
    if (D <= 48) FLASH_(48);
    if (D <= 64) FLASH_(64);
    if (D <= 80) FLASH_(80);
    FLASH_(160);
#undef FLASH_
}
