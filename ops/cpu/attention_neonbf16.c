/* Streaming attention, aarch64 FEAT_BF16: the NEON template with both products in bf16 (BFDOT)
 * and fp32 sums; 4 queries × 16 keys of scores in 16 q-register accumulators. */
#include "kernels.h"
#include "simd_neon.h"
#include "bf16_neon.h"
#include "vmath_simd.inc"
#undef KFN
#define KFN(name) name##_neonbf16
#define ATT_QG 4
#include "attention_bf16_simd.inc"
