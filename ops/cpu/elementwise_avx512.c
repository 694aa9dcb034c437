/* Element-wise ops, norms and softmax, AVX-512F (templates *_simd.inc). */
#include "kernels.h"
#include "simd_avx512.h"
#include "vmath_simd.inc"
#include "activation_simd.inc"
#include "norm_simd.inc"
