/* Streaming attention, AVX512_BF16: the AVX-512 template with both products in bf16 (vdpbf16ps)
 * and fp32 sums; 32 queries in two zmm per tile, 12 keys × 2 of scores and 10 dims × 2 of output
 * sums in registers (attention_lanes_simd.inc). */
#include "kernels.h"
#include "simd_avx512.h"
#include "bf16_avx512.h"
#include "vmath_simd.inc"
#undef KFN
#define KFN(name) name##_avx512bf16
#define ATTQ_TK 12
#define ATTQ_TD 10
#define ATTQ_BF16
#include "attention_lanes_simd.inc"
