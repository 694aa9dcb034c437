/* The blocked GEMM engine behind linear and conv2d on the SIMD levels (Goto/BLIS scheme):
 * C[M,N] (row stride ldc) = A[M,K] · B[K,N] (+ bias). For each block of kc columns of K,
 * B is packed into NR-column panels by all threads, then tasks over MC×NC tiles of C run the
 * register-blocked micro-kernel on every MR×NR sub-tile; each thread packs the MC-row block
 * of A it works on into its own buffer (MR-row panels; it stays in the thread's L2). Where A
 * is small or a weight (conv) it is packed once for all, and the tasks are whole columns of C
 * (each thread packs the B panels it uses) or whole row blocks (gemm.c's gemm_split). Panels
 * are k-major and zero-padded at the edges. Packing is pluggable, so conv2d packs its B panels
 * straight from (a padded band of) the image, never a full im2col copy. Every split depends on the
 * problem size only, so results do not depend on the thread count.
 * bf16 levels: panels of k-pairs (one 32-bit word = bf16 of k and k+1, an odd last k paired
 * with zero), the operand layout of vdpbf16ps, so the micro-kernel does two k per instruction.
 * The row packers convert each row to pairs (adjacent in a row) and transpose words; the conv
 * packers copy words from a band of the input converted to channel pairs once (gemm_conv.c). The AMX level (gemm_amx.inc) pads each
 * panel's pair rows to whole tiles (pair_align 16) and keeps A panels row-major (a_rows: the
 * tile rows of TDPBF16PS's first operand); its B panels are the same k-pair panels. */
#ifndef MX_OPS_CPU_GEMM_H
#define MX_OPS_CPU_GEMM_H

#include <stddef.h>
#include <stdint.h>

#include "kernels.h"

typedef struct mx_gemm_kernel {
    int mr, nr;
    /* c[m × n] (row stride ldc) = (accumulate ? c : 0) + a[kc][mr] · b[kc][nr]; only the
     * first m rows and n columns are written (m <= mr, n <= nr). With to_pairs the panels are
     * a[(kc+1)/2][mr] and b[(kc+1)/2][nr] words of bf16 pairs. */
    void (*micro)(int kc, const void *a, const void *b, float *c, size_t ldc, int m, int n, int accumulate);
    /* NULL, or micro with the sums started at the bias instead of 0 (not accumulating): bias[j]
     * for column j, or with per_row row i's value at bias[i·MX_GEMM_BIAS_ROW ...] (that many
     * copies of it, laid out so by the engine), and micro_rows then takes the bias the same way
     * (NULL: none); the engine then adds no bias afterwards, so the sums' order is one for every
     * split of the work (results never depend on the batch). */
    void (*micro_bias)(int kc, const void *a, const void *b, float *c, size_t ldc, int m, int n, const float *bias,
                       int per_row);
    /* c[i][j] += bias[i] (per_row) or bias[j], for i < m, j < n: the bias on a finished tile
     * (gemm_bias_simd.inc). */
    void (*add_bias)(float *c, size_t ldc, int m, int n, const float *bias, int per_row);
    /* y[i] = widened x[i] for a weight row (fp32, fp16 or bf16). */
    void (*widen)(float *y, mx_wptr x, size_t offset, size_t n);
    /* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols (the packing transpose). */
    void (*transpose)(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols);
    /* NULL for fp32 panels; else dst[c] = bf16(even[c]) | bf16(odd[c]) << 16 for c < n (odd NULL:
     * zeros), rounding to nearest even: a pair row from two rows (conv: two channels' rows). */
    void (*to_pairs)(uint32_t *dst, const float *even, const float *odd, int n);
    /* With to_pairs: dst[0 .. (n+1)/2) = pairs of the row src[0 .. n). */
    void (*row_pairs)(uint32_t *dst, const float *src, int n);
    /* NULL, or to_pairs and row_pairs of the values' low parts, bf16(x - bf16(x)): the second
     * operands of a split kernel's products (split_of) */
    void (*to_pairs_lo)(uint32_t *dst, const float *even, const float *odd, int n);
    void (*row_pairs_lo)(uint32_t *dst, const float *src, int n);
    /* With to_pairs: pair rows of a panel padded with zeros to a multiple of this (0 or 1: none);
     * a_rows: A panels are a[mr][words] (each row's pairs together) instead of a[words][mr]. */
    int pair_align, a_rows;
    /* NULL, or micro over a B panel read in place instead of packed: step s (a k, or a k-pair) is
     * the nr/2 words at half[0] + offs[s], then the nr/2 at half[1] + offs[s]; n = nr. offs holds
     * MX_GEMM_ROWS_AHEAD entries past the block's steps, addresses to fetch ahead (gemm_conv.c:
     * halves of a panel that each lie in one output row, read from the band). */
    void (*micro_rows)(int kc, const void *a, const uint32_t *const half[2], const int32_t *offs, float *c,
                       size_t ldc, int m, int accumulate, const float *bias, int per_row);
    /* NULL, or called by a thread before and after a run of micro calls (a tile of C): the AMX
     * level loads its tile configuration once there instead of in every micro call (LDTILECFG and
     * TILERELEASE cost a fifth of a 32×32 call's time) */
    void (*begin)(void);
    void (*end)(void);
    /* K blocks of at most this many k (≤ MX_GEMM_KC_MAX); 0: MX_GEMM_KC_SIMD (mx_gemm_kc) */
    int kc_max;
    /* NULL, or the kernel whose panels this one's hold twice, the operand's high parts then its
     * low parts (each in split_of's format): the split product of mx_gemm_linear/conv2d in one pass, its
     * micro-kernel adding hi·lo + hi·hi + lo·hi on the tiles before C is stored once */
    const struct mx_gemm_kernel *split_of;
} mx_gemm_kernel;

/* Copies of each row's value in a row bias for micro_bias: one tile row of fp32 (AMX). */
#define MX_GEMM_BIAS_ROW 16

/* Steps of B rows fetched ahead by micro_rows (and the entries past a K block's steps in offs). */
#define MX_GEMM_ROWS_AHEAD 16

/* Weight rows widened (or gathered, conv) before one packing transpose: MX_GEMM_WIDEN_ROWS ×
 * MX_GEMM_KC_MAX floats of the packers' stack. */
#define MX_GEMM_WIDEN_ROWS 8
/* Widest panel (MR or NR) of any kernel: bounds the packers' stack buffers. */
#define MX_GEMM_PANEL_MAX 32
/* K block of the SIMD levels. Each thread keeps its MC×kc block of A in L2 (240 KiB at 640) and
 * streams kc×NR panels of B; a longer block means fewer passes over C and fewer pack/compute
 * rounds (K = 5120: 8 instead of 16). On Zen 5 (48 KiB L1, 1 MiB L2) 640 was a little faster than
 * 320 on the K ≥ 1280 shapes and no slower on K = 320; 1024 was no better; with 2 threads and
 * column tasks 320 was no faster on the UNet either (the shared machine is too noisy to separate
 * a few percent). */
#define MX_GEMM_KC_SIMD 640
/* Longest K block of any kernel (the AMX level's: gemm_amx.inc); also bounds the packers' row
 * buffers on the stack. */
#define MX_GEMM_KC_MAX 2048

/* The K block length of kernel g. */
static inline int mx_gemm_kc(const mx_gemm_kernel *g) { return g->kc_max > 0 ? g->kc_max : MX_GEMM_KC_SIMD; }

typedef struct mx_gemm_problem mx_gemm_problem;
/* dst[k][r] for k < kc, r < rows: a panel starting at row (A) or column (B) `first`, rows past
 * the matrix edge zero; in the kernel's format (fp32, or k-pairs with to_pairs). */
typedef void (*mx_gemm_pack_fn)(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first,
                                int rows, int k0, int kc);

struct mx_gemm_problem {
    int M, N, K;
    /* batch items share A (the weights): item b has C + b·c_batch_stride and, for conv,
     * image + b·image_batch_stride; A is packed once for all of them */
    int batch;
    float *C;
    size_t ldc, c_batch_stride;
    mx_gemm_pack_fn pack_a, pack_b;
    /* operand sources used by the packers */
    mx_wptr a_mat, b_mat; /* row-major matrices for mx_gemm_pack_rows */
    size_t a_ld, b_ld;
    /* conv (gemm_conv.c): a_mat the weights [M][Cin][kh][kw]; image the band of batch item 0:
     * chans planes (band_plane words apart) of rows of band_width 32-bit words (fp32, or bf16
     * channel pairs); K in groups of group_words channel words × kh·kw taps */
    const float *image;
    size_t image_batch_stride, band_plane;
    int Cin, chans, group_words, band_width, kh, kw, stride, Wo;
    int band_fp32; /* bf16 levels, 1×1 stride 1 unpadded: the band is the fp32 input, paired per panel */
    /* 1: K within a group in the order (ci, ky, kx), the weights' own (fp32 levels); 0: (ky, kx,
     * ci), which pair levels need (a pair is two channels at one tap) */
    int taps_inner;
    /* conv2d_up2x: 4, A's M rows are the 2×2 kernels of the 4 phases (row phase·M/4 + co) folded
     * from the M/4 3×3 rows of a_mat (a_ld = Cin·9); 0 for a plain conv (M rows of a_mat) */
    int a_phases;
    /* a split kernel's conv on a band: the band of the inputs' low parts (image's layout) */
    const float *image_lo;
    mx_wptr bias;
    int bias_per_row; /* 1: bias[m] (conv), 0: bias[n] (linear) */
    int kc_block;     /* K blocks of this length (≤ mx_gemm_kc), the last one shorter; 0: the engine's */
    /* 1: the operand is a weight (a_mat of conv, b_mat of linear), the same on every call: its
     * panels are packed once into the context's cache when it has one (wpack.h) */
    int a_weight, b_weight;
    /* A's panels of every K block (mx_gemm_a_panels), or NULL: the engine packs or finds them */
    const float *a_panels;
    /* a split kernel's packers (pack_a = mx_gemm_pack_a_split, pack_b likewise): the high and
     * the low part's, in split_of's format */
    mx_gemm_pack_fn split_a[2], split_b[2];
    /* NULL, or B panels read in place by the kernel's micro_rows instead of packed (conv,
     * gemm_conv.c: a panel of pixels of one output row is rows of the band). rows_in_place
     * fills offs[s] for the steps s of the K block k0..k0+kc, the word offset of B's row s from
     * the panel's address (+ MX_GEMM_ROWS_AHEAD copies of the last), and returns 1, or returns 0
     * where B must be packed. panel_in_place returns 1 when each half of the panel of columns
     * first..first+nr can be read in place, half[h] then its address (row s of B: nr/2 words at
     * half[0] + offs[s], nr/2 at half[1] + offs[s]); else 0. */
    int (*rows_in_place)(const mx_gemm_problem *p, const mx_gemm_kernel *g, int k0, int kc, int32_t *offs);
    int (*panel_in_place)(const mx_gemm_problem *p, const mx_gemm_kernel *g, int first, const uint32_t *half[2]);
};

/* Packs rows of a row-major matrix (a_mat for pack_a, b_mat for pack_b: element (r, k) at
 * r*ld + k), transposed into k-major panels. For A of linear (x) and conv (weights), and for
 * B of linear (weights [N, K], i.e. B^T). */
void mx_gemm_pack_a_rows(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                         int k0, int kc);
void mx_gemm_pack_b_rows(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                         int k0, int kc);
/* The same packers for the low part of the operand (kernels with to_pairs_lo): pairs of
 * bf16(x - bf16(x)), the second operand of a split product (a split kernel's, which never keeps a
 * weight packed once: a_weight and b_weight are 0 there). */
void mx_gemm_pack_a_rows_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc);
void mx_gemm_pack_b_rows_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc);
void mx_gemm_pack_a_conv_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                            int k0, int kc);
void mx_gemm_pack_b_conv_lo(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols,
                            int k0, int kc);

/* conv (gemm_conv.c), K in the order (ky, kx, ci): A from the weights, B columns [first,
 * first+cols) (output pixels) copied from the band. */
void mx_gemm_pack_a_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                         int k0, int kc);
void mx_gemm_pack_b_conv(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols,
                         int k0, int kc);
/* The packers of a split kernel (split_of): the panel's high part by problem.split_a[0] (or
 * split_b[0]), then its low part by split_a[1] (split_b[1]). */
void mx_gemm_pack_a_split(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int rows,
                          int k0, int kc);
void mx_gemm_pack_b_split(const mx_gemm_problem *p, const mx_gemm_kernel *g, void *dst, int first, int cols,
                          int k0, int kc);
/* Starts fetching rows first..first+n-1, columns k0..k0+kc-1, of a row-major weight matrix. */
void mx_gemm_prefetch_rows(mx_wptr src, size_t ld, int first, int n, int k0, int kc);
/* Zeros what a packer left of a k-major panel dst[words][width] for a K block of kc: columns
 * valid..width of the kc rows (or pair rows), and the pair_align padding rows. */
void mx_gemm_zero_panel_tail(const mx_gemm_kernel *g, void *dst, int width, int valid, int kc);

/* The bias epilogues (gemm_bias_simd.inc) of the AVX2, AVX-512 (also the bf16 and AMX levels) and
 * NEON (also neonbf16) files. */
void mx_gemm_add_bias_avx2(float *c, size_t ldc, int m, int n, const float *bias, int per_row);
void mx_gemm_add_bias_avx512(float *c, size_t ldc, int m, int n, const float *bias, int per_row);
void mx_gemm_add_bias_neon(float *c, size_t ldc, int m, int n, const float *bias, int per_row);
/* The AVX-512 weight widening (gemm_avx512.c), also used by the bf16 levels. */
void mx_gemm_widen_avx512(float *y, mx_wptr w, size_t off, size_t n);
/* The NEON weight widening (gemm_neon.c), also used by the neonbf16 level. */
void mx_gemm_widen_neon(float *y, mx_wptr w, size_t off, size_t n);
/* The AVX512_BF16 to_pairs and to_pairs_lo (gemm_avx512bf16.c), also used by the AMX level. */
void mx_gemm_to_pairs_avx512bf16(uint32_t *dst, const float *even, const float *odd, int n);
void mx_gemm_to_pairs_lo_avx512bf16(uint32_t *dst, const float *even, const float *odd, int n);
/* 32-bit words per row (A) or column (B) of a packed panel for a K block of kc: kc for fp32
 * panels, (kc+1)/2 k-pairs rounded up to pair_align for bf16 ones. */
static inline size_t mx_gemm_panel_words(const mx_gemm_kernel *g, int kc) {
    if (g->split_of) return 2 * mx_gemm_panel_words(g->split_of, kc);
    if (!g->to_pairs) return (size_t)kc;
    size_t kp = (size_t)(kc + 1) / 2, align = g->pair_align > 1 ? (size_t)g->pair_align : 1;
    return (kp + align - 1) / align * align;
}

/* A's panels of every K block, for a caller that runs one problem over many B (conv2d's blocks
 * of output rows; set problem.a_panels): the context's cached ones for a weight it holds or
 * takes now (else NULL), or packed by all threads into dst (mx_gemm_a_panels_floats of them). */
const float *mx_gemm_cached_a_panels(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p);
size_t mx_gemm_a_panels_floats(const mx_gemm_kernel *g, const mx_gemm_problem *p);
const float *mx_gemm_pack_a_panels(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p, float *dst);

/* Returns -1 (and writes nothing) when no memory for the packed panels could be had. */
int mx_gemm_run(const mx_ctx *c, const mx_gemm_kernel *g, const mx_gemm_problem *p);

/* linear and conv2d on top of mx_gemm_run, for a given micro-kernel; they fall back to the
 * scalar reference when mx_gemm_run has no memory. With a split kernel (split_of) they compute
 * the split product: each operand split as hi = bf16(x) and lo = bf16(x - hi), x·w ≈ hi·hi +
 * lo·hi + hi·lo (lo·lo, ~2^-16 of it, dropped), summed in fp32: near fp32 accuracy (~5e-6
 * relative L2 per product, fp32 ~5e-7, bf16 ~2.4e-3) at three times the bf16 work. The AMX
 * level's fp32 layers (dispatch.c), where the tiles outrun fp32 FMAs 15 to 1: one pass, both
 * parts packed once, the three products added on the tiles, C written once (three passes of the
 * plain kernel wrote C three times and read it back twice: 1×1 convs of 320-1280 channels and
 * linear layers of K 512 ~25-35 % slower, 2 Xeon cores). */
void mx_gemm_linear(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, mx_wptr w, mx_wptr bias,
                    int M, int N, int K);
void mx_gemm_conv2d(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, int B, int Cin, int H,
                    int W, mx_wptr w, mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
/* conv2d_up2x (op_list.h) in its phase form: the 2×2 conv, padding 1, of x with the 4·Cout phase
 * kernels folded from w (16 products per input pixel and output channel instead of the 36 of a
 * 3×3 conv on the upsampled image), by blocks of rows into scratch, each block interleaved into y. */
void mx_gemm_conv2d_up2x(const mx_ctx *c, const mx_gemm_kernel *g, float *y, const float *x, int B, int Cin, int H,
                         int W, mx_wptr w, mx_wptr bias, int Cout);

#ifdef __AVX__
#include <immintrin.h>

#include "transpose_avx.h"

/* The packing transpose for the SIMD files: 8×8 blocks, then a 4- and a 2-row block, so that
 * MR = 12 (8 + 4) and MR = 6 (4 + 2) panels never fall back to scalar stores. */
static inline void mx_gemm_transpose_4x8(float *dst, size_t dst_ld, const float *src, size_t src_ld) {
    __m256 r0 = _mm256_loadu_ps(src), r1 = _mm256_loadu_ps(src + src_ld);
    __m256 r2 = _mm256_loadu_ps(src + 2 * src_ld), r3 = _mm256_loadu_ps(src + 3 * src_ld);
    __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpackhi_ps(r0, r1);
    __m256 t2 = _mm256_unpacklo_ps(r2, r3), t3 = _mm256_unpackhi_ps(r2, r3);
    /* u_j holds column j in its low lane and column j + 4 in its high lane */
    __m256 u[4] = {_mm256_shuffle_ps(t0, t2, 0x44), _mm256_shuffle_ps(t0, t2, 0xee), _mm256_shuffle_ps(t1, t3, 0x44),
                   _mm256_shuffle_ps(t1, t3, 0xee)};
    for (int j = 0; j < 4; j++) {
        _mm_storeu_ps(dst + (size_t)j * dst_ld, _mm256_castps256_ps128(u[j]));
        _mm_storeu_ps(dst + (size_t)(j + 4) * dst_ld, _mm256_extractf128_ps(u[j], 1));
    }
}

static inline void mx_gemm_transpose_2x8(float *dst, size_t dst_ld, const float *src, size_t src_ld) {
    __m256 r0 = _mm256_loadu_ps(src), r1 = _mm256_loadu_ps(src + src_ld);
    /* pairs (r0[c], r1[c]): t[0] has columns 0, 1 | 4, 5 and t[1] columns 2, 3 | 6, 7 */
    __m256 t[2] = {_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1)};
    for (int h = 0; h < 2; h++) {
        __m128 lo = _mm256_castps256_ps128(t[h]), hi = _mm256_extractf128_ps(t[h], 1);
        _mm_storel_pi((__m64 *)(dst + (size_t)(2 * h) * dst_ld), lo);
        _mm_storeh_pi((__m64 *)(dst + (size_t)(2 * h + 1) * dst_ld), lo);
        _mm_storel_pi((__m64 *)(dst + (size_t)(2 * h + 4) * dst_ld), hi);
        _mm_storeh_pi((__m64 *)(dst + (size_t)(2 * h + 5) * dst_ld), hi);
    }
}

/* dst[c*dst_ld + r] = src[r*src_ld + c] for r < rows, c < cols. */
static inline void mx_gemm_transpose(float *dst, size_t dst_ld, const float *src, size_t src_ld, int rows, int cols) {
    int r = rows / 8 * 8;
    transpose_avx(dst, dst_ld, src, src_ld, r, cols);
    for (int h = 4; h >= 1; h /= 2) {
        if (rows - r < h) continue;
        int c = 0;
        for (; c + 8 <= cols; c += 8) {
            float *d = dst + (size_t)c * dst_ld + r;
            const float *s = src + (size_t)r * src_ld + c;
            if (h == 4)
                mx_gemm_transpose_4x8(d, dst_ld, s, src_ld);
            else if (h == 2)
                mx_gemm_transpose_2x8(d, dst_ld, s, src_ld);
            else
                for (int i = 0; i < 8; i++) d[(size_t)i * dst_ld] = s[i];
        }
        for (; c < cols; c++)
            for (int i = 0; i < h; i++) dst[(size_t)c * dst_ld + r + i] = src[(size_t)(r + i) * src_ld + c];
        r += h;
    }
}
#endif

#endif
