/* The AMX kernels (ops/cpu/gemm_amx.inc, ops/cpu/attention_amx.inc) on the software emulation of
 * the tile operations (ops/cpu/amx_tiles.h, MX_AMX_EMULATE): mx_linear_amx_emu,
 * mx_conv2d_amx_emu and mx_attention_amx_emu, for test_ops_kernels, which runs them only where
 * the CPU has AVX512_BF16 (their packing's). */
#define MX_AMX_EMULATE
#include "../ops/cpu/amx_tiles.h"
#include "../ops/cpu/simd_avx512.h"
#include "../ops/cpu/bf16_avx512.h"
#include "../ops/cpu/vmath_simd.inc"

#define AMX_SFX amx_emu
#include "../ops/cpu/gemm_amx.inc"
#define ATTA_SFX amx_emu
#include "../ops/cpu/attention_amx.inc"
