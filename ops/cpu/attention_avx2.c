/* Streaming attention, AVX2+FMA: 2 queries × 32 keys of scores in 8 ymm accumulators. */
#include "kernels.h"
#include "simd_avx2.h"
#include "vmath_simd.inc"
#define ATT_QG 2
#include "attention_simd.inc"
