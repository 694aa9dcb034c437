/* AVX2+FMA GEMM micro-kernel (6×16: 12 ymm accumulators, 2 B loads and 6 broadcasts per k),
 * weight widening with F16C / integer shifts, and linear + conv2d on the GEMM engine. */
#include <immintrin.h>

#include "gemm.h"
#include "simd_avx2.h"

#define MR 6
#define NR 16

#define ROW_DECL(i) __m256 c##i##0 = _mm256_setzero_ps(), c##i##1 = _mm256_setzero_ps();
#define ROW_FMA(i)                                                                                           \
    {                                                                                                        \
        __m256 ai = _mm256_broadcast_ss(a + (i));                                                            \
        c##i##0 = _mm256_fmadd_ps(ai, b0, c##i##0);                                                          \
        c##i##1 = _mm256_fmadd_ps(ai, b1, c##i##1);                                                          \
    }
#define ROW_OUT(i)                                                                                           \
    {                                                                                                        \
        float *r = out + (size_t)(i) * ld;                                                                   \
        if (direct && accumulate) {                                                                          \
            c##i##0 = _mm256_add_ps(_mm256_loadu_ps(r), c##i##0);                                            \
            c##i##1 = _mm256_add_ps(_mm256_loadu_ps(r + 8), c##i##1);                                        \
        }                                                                                                    \
        _mm256_storeu_ps(r, c##i##0);                                                                        \
        _mm256_storeu_ps(r + 8, c##i##1);                                                                    \
    }
#define ALL_ROWS(X) X(0) X(1) X(2) X(3) X(4) X(5)

static void micro_6x16(int kc, const void *ap, const void *bp, float *c, size_t ldc, int m, int n, int accumulate) {
    const float *a = ap, *b = bp;
    ALL_ROWS(ROW_DECL)
    /* the C tile is read (accumulate, bias) or written at the end: start fetching it now (it is
     * usually outside L2; the bias epilogue waited on lines the stores had missed) */
    for (int i = 0; i < m; i++) {
        _mm_prefetch((const char *)(c + (size_t)i * ldc), _MM_HINT_T0);
        _mm_prefetch((const char *)(c + (size_t)i * ldc + NR - 1), _MM_HINT_T0);
    }
    for (int k = 0; k < kc; k++) {
        __m256 b0 = _mm256_loadu_ps(b), b1 = _mm256_loadu_ps(b + 8);
        ALL_ROWS(ROW_FMA)
        a += MR;
        b += NR;
    }
    float tile[MR * NR];
    int direct = m == MR && n == NR;
    float *out = direct ? c : tile;
    size_t ld = direct ? ldc : NR;
    ALL_ROWS(ROW_OUT)
    if (direct) return;
    for (int i = 0; i < m; i++)
        for (int j = 0; j < n; j++) {
            float *cij = c + (size_t)i * ldc + j;
            *cij = (accumulate ? *cij : 0.0f) + tile[i * NR + j];
        }
}

static void widen_avx2(float *y, mx_wptr w, size_t off, size_t n) {
    const uint16_t *x = (const uint16_t *)w.data + off;
    size_t i = 0;
    if (w.dtype == MX_F16)
        for (; i + 8 <= n; i += 8) _mm256_storeu_ps(y + i, _mm256_cvtph_ps(_mm_loadu_si128((const __m128i *)(x + i))));
    else
        for (; i + 8 <= n; i += 8) {
            __m256i v = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)(x + i)));
            _mm256_storeu_ps(y + i, _mm256_castsi256_ps(_mm256_slli_epi32(v, 16)));
        }
    for (; i < n; i++) y[i] = mx_w_get(w, off + i);
}

#include "gemm_bias_simd.inc"

static const mx_gemm_kernel kernel_avx2 = {.mr = MR, .nr = NR, .micro = micro_6x16, .add_bias = mx_gemm_add_bias_avx2,
                                          .widen = widen_avx2, .transpose = mx_gemm_transpose};

void mx_linear_avx2(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K) {
    mx_gemm_linear(c, &kernel_avx2, y, x, w, bias, M, N, K);
}

void mx_conv2d_avx2(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                    mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    mx_gemm_conv2d(c, &kernel_avx2, y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad);
}

void mx_conv2d_up2x_avx2(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                         mx_wptr bias, int Cout) {
    mx_gemm_conv2d_up2x(c, &kernel_avx2, y, x, B, Cin, H, W, w, bias, Cout);
}
