/* Streaming fp32 attention, AVX2+FMA: 16 queries in two ymm per tile, 6 keys × 2 of scores and
 * 5 dims × 2 of output sums in registers (attention_lanes_simd.inc). */
#include "kernels.h"
#include "simd_avx2.h"
#include "vmath_simd.inc"
#define ATTQ_TK 6
#define ATTQ_TD 5
#include "attention_lanes_simd.inc"
