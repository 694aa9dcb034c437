/* The CPU dispatch tables, one per ISA level. A level is the previous level's kernels plus the
 * ones it lists as its own: MX_<LEVEL>_KERNELS below is the previous level's macro followed by
 * designated initializers of its own kernels, and a later initializer of a field replaces an
 * earlier one (C11 6.7.9 §19). The chain starts at the scalar level, generated from op_list.h,
 * so every table is full by construction (test_ops_backend checks every compiled table anyway:
 * full, and each entry a kernel of its own op at the table's level or below).
 * A new level: its MX_<LEVEL>_KERNELS, its table, its case in mx_kernels_compiled
 * (docs/DESIGN.md §4). */
#include "kernels.h"

/* Replacing the previous level's entry is the point of the chain, so the compilers' warning about
 * a field initialized twice is off in this file. */
#if defined(__clang__)
#pragma clang diagnostic ignored "-Winitializer-overrides"
#elif defined(__GNUC__)
#pragma GCC diagnostic ignored "-Woverride-init"
#endif

/* scalar: every op's reference (the test oracle). */
#define MX_REF_ENTRY_(name, guard, params, args, cost) .name = mx_##name##_ref,
#define MX_SCALAR_KERNELS MX_OPS(MX_REF_ENTRY_)

/* avx2 (+FMA): the SIMD templates and the GEMM micro-kernel; the layout ops but the transposes,
 * vector, embedding and tanh stay on the reference (memory-bound copies the compiler vectorises,
 * or tiny). */
#define MX_AVX2_KERNELS                                                                                      \
    MX_SCALAR_KERNELS .linear = mx_linear_avx2, .conv2d = mx_conv2d_avx2, .conv2d_up2x = mx_conv2d_up2x_avx2, .group_norm = mx_group_norm_avx2,   \
    .layer_norm = mx_layer_norm_avx2, .attention = mx_attention_avx2, .gelu = mx_gelu_avx2,                   \
    .quick_gelu = mx_quick_gelu_avx2, .silu = mx_silu_avx2, .geglu = mx_geglu_avx2,                         \
    .binary = mx_binary_avx2, .scale = mx_scale_avx2, .transpose_chw_hwc = mx_transpose_chw_hwc_avx2,         \
    .transpose_hwc_chw = mx_transpose_hwc_chw_avx2,

/* avx512: the same kernels on 16-float vectors. */
#define MX_AVX512_KERNELS                                                                                    \
    MX_AVX2_KERNELS .linear = mx_linear_avx512, .conv2d = mx_conv2d_avx512, .conv2d_up2x = mx_conv2d_up2x_avx512, .group_norm = mx_group_norm_avx512, \
    .layer_norm = mx_layer_norm_avx512, .attention = mx_attention_avx512, .gelu = mx_gelu_avx512,             \
    .quick_gelu = mx_quick_gelu_avx512, .silu = mx_silu_avx512, .geglu = mx_geglu_avx512,                   \
    .binary = mx_binary_avx512, .scale = mx_scale_avx512, .transpose_chw_hwc = mx_transpose_chw_hwc_avx512,   \
    .transpose_hwc_chw = mx_transpose_hwc_chw_avx512,

/* avx512bf16: the matrix products in bf16 arithmetic with fp32 sums (vdpbf16ps). */
#define MX_AVX512BF16_KERNELS                                                                                \
    MX_AVX512_KERNELS .linear = mx_linear_avx512bf16, .conv2d = mx_conv2d_avx512bf16, .conv2d_up2x = mx_conv2d_up2x_avx512bf16,                          \
    .attention = mx_attention_avx512bf16,

/* amx: the GEMMs and attention's two products on AMX-BF16 tiles. */
#define MX_AMX_KERNELS                                                                                       \
    MX_AVX512BF16_KERNELS .linear = mx_linear_amx, .conv2d = mx_conv2d_amx, .conv2d_up2x = mx_conv2d_up2x_amx, .attention = mx_attention_amx,

/* neon (aarch64 Advanced SIMD): the avx2 set of kernels on 4-float vectors. */
#define MX_NEON_KERNELS                                                                                      \
    MX_SCALAR_KERNELS .linear = mx_linear_neon, .conv2d = mx_conv2d_neon, .conv2d_up2x = mx_conv2d_up2x_neon, .group_norm = mx_group_norm_neon,   \
    .layer_norm = mx_layer_norm_neon, .attention = mx_attention_neon, .gelu = mx_gelu_neon,                   \
    .quick_gelu = mx_quick_gelu_neon, .silu = mx_silu_neon, .geglu = mx_geglu_neon,                         \
    .binary = mx_binary_neon, .scale = mx_scale_neon, .transpose_chw_hwc = mx_transpose_chw_hwc_neon,         \
    .transpose_hwc_chw = mx_transpose_hwc_chw_neon,

/* neonbf16 (FEAT_BF16): the matrix products in bf16 arithmetic with fp32 sums (BFDOT). */
#define MX_NEONBF16_KERNELS                                                                                  \
    MX_NEON_KERNELS .linear = mx_linear_neonbf16, .conv2d = mx_conv2d_neonbf16, .conv2d_up2x = mx_conv2d_up2x_neonbf16, .attention = mx_attention_neonbf16,

static const mx_kernels scalar_table = {.isa = MX_ISA_SCALAR, MX_SCALAR_KERNELS};

#ifdef MX_WITH_NEON /* aarch64 builds (Makefile) */
static const mx_kernels neon_table = {.isa = MX_ISA_NEON, MX_NEON_KERNELS};
static const mx_kernels neonbf16_table = {.isa = MX_ISA_NEON_BF16, MX_NEONBF16_KERNELS};
#endif

#ifndef MX_NO_X86_SIMD /* x86-64 builds (Makefile); other architectures have only the scalar table */
static const mx_kernels avx2_table = {.isa = MX_ISA_AVX2, MX_AVX2_KERNELS};
static const mx_kernels avx512_table = {.isa = MX_ISA_AVX512, MX_AVX512_KERNELS};
static const mx_kernels avx512bf16_table = {.isa = MX_ISA_AVX512_BF16, MX_AVX512BF16_KERNELS};
static const mx_kernels amx_table = {.isa = MX_ISA_AMX, MX_AMX_KERNELS};
/* The amx level's fp32 layers (mx_kernels_fp32_of): avx512, but linear and conv2d as three bf16
 * products on the tiles (gemm.h: split kernels), ~5e-6 relative instead of fp32's ~5e-7. */
static const mx_kernels amx_fp32_table = {.isa = MX_ISA_AVX512, MX_AVX512_KERNELS .linear = mx_linear_x3_amx,
                                          .conv2d = mx_conv2d_x3_amx, .conv2d_up2x = mx_conv2d_up2x_x3_amx};
#endif

const mx_kernels *mx_kernels_scalar(void) { return &scalar_table; }

const mx_kernels *mx_kernels_compiled(mx_isa isa) {
    switch (isa) {
    case MX_ISA_SCALAR: return &scalar_table;
#ifndef MX_NO_X86_SIMD
    case MX_ISA_AVX2: return &avx2_table;
    case MX_ISA_AVX512: return &avx512_table;
    case MX_ISA_AVX512_BF16: return &avx512bf16_table;
    case MX_ISA_AMX: return &amx_table;
#endif
#ifdef MX_WITH_NEON
    case MX_ISA_NEON: return &neon_table;
    case MX_ISA_NEON_BF16: return &neonbf16_table;
#endif
    default: return NULL;
    }
}

const mx_kernels *mx_kernels_for(mx_isa isa) {
    const mx_kernels *k = mx_kernels_compiled(mx_isa_min(isa, mx_cpu_best_isa()));
    return k ? k : &scalar_table;
}

const mx_kernels *mx_kernels_best(void) { return mx_kernels_for(mx_cpu_isa_for(MX_PREC_FP32)); }

const mx_kernels *mx_kernels_fp32_of(const mx_kernels *k) {
#ifndef MX_NO_X86_SIMD
    if (k == &amx_table) return &amx_fp32_table;
#endif
    return mx_kernels_for(mx_isa_fp32_level(k->isa));
}
