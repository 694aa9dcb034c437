/* Streaming attention, aarch64 NEON: 4 queries × 16 keys of scores in 16 q-register accumulators. */
#include "kernels.h"
#include "simd_neon.h"
#include "vmath_simd.inc"
#define ATT_QG 4
#include "attention_simd.inc"
