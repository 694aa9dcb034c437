/* Streaming attention, AVX512_BF16: the AVX-512 template with both products in bf16 (vdpbf16ps)
 * and fp32 sums; 6 queries × 64 keys of scores in 24 zmm accumulators. */
#include "kernels.h"
#include "simd_avx512.h"
#include "bf16_avx512.h"
#include "vmath_simd.inc"
#undef KFN
#define KFN(name) name##_avx512bf16
#define ATT_QG 6
#include "attention_bf16_simd.inc"
