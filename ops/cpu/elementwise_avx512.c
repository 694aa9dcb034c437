/* Element-wise ops, norms, softmax and the layout transposes, AVX-512F (templates *_simd.inc). */
#include "kernels.h"
#include "simd_avx512.h"
#include "vmath_simd.inc"
#include "activation_simd.inc"
#include "norm_simd.inc"
#include "transpose_simd.inc"
