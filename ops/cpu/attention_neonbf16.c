/* Streaming attention, aarch64 FEAT_BF16: the NEON template with both products in bf16 (BFDOT)
 * and fp32 sums; 8 queries in two q registers per tile, 12 keys × 2 of scores and 10 dims × 2
 * of output sums in registers (attention_lanes_simd.inc). */
#include "kernels.h"
#include "simd_neon.h"
#include "bf16_neon.h"
#include "vmath_simd.inc"
#undef KFN
#define KFN(name) name##_neonbf16
#define ATTQ_TK 12
#define ATTQ_TD 10
#define ATTQ_BF16
#include "attention_lanes_simd.inc"
