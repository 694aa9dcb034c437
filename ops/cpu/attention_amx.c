/* Attention on AMX-BF16 tiles: the kernel of attention_amx.inc on the AMX intrinsics (this file
 * is built with -mamx-tile -mamx-bf16), for the amx level (dispatch.c). */
#include "amx_tiles.h"
#include "simd_avx512.h"
#include "bf16_avx512.h"
#include "vmath_simd.inc"

#define ATTA_SFX amx
#include "attention_amx.inc"
