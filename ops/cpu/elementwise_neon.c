/* Element-wise ops, norms, softmax and the layout transposes, aarch64 NEON (templates *_simd.inc). */
#include "kernels.h"
#include "simd_neon.h"
#include "vmath_simd.inc"
#include "activation_simd.inc"
#include "norm_simd.inc"
#include "transpose_simd.inc"
