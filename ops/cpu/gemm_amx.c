/* AMX-BF16 GEMM: the tile micro-kernel of gemm_amx.inc on the AMX intrinsics (this file alone is
 * built with -mamx-tile -mamx-bf16), behind linear and conv2d (the conv is the engine's implicit
 * GEMM). Chosen only where cpuid reports AMX-TILE and AMX-BF16, XCR0 enables the tile state and
 * Linux granted it (runtime/cpuid.c); attention stays on the AVX512_BF16 kernel. */
#include "amx_tiles.h"
#include "bf16_avx512.h"

#define AMX_SFX amx
#include "gemm_amx.inc"
