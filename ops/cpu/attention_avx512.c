/* Streaming fp32 attention, AVX-512F: 32 queries in two zmm per tile, 12 keys × 2 of scores and
 * 10 dims × 2 of output sums in registers (attention_lanes_simd.inc). */
#include "kernels.h"
#include "simd_avx512.h"
#include "vmath_simd.inc"
#define ATTQ_TK 12
#define ATTQ_TD 10
#include "attention_lanes_simd.inc"
