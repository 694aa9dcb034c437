/* Streaming attention, AVX-512F: 6 queries × 64 keys of scores in 24 zmm accumulators. */
#include "kernels.h"
#include "simd_avx512.h"
#include "vmath_simd.inc"
#define ATT_QG 6
#include "attention_simd.inc"
