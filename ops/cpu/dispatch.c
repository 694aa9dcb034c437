/* The dispatch tables: one per ISA level, each entry the best kernel written for that level
 * (an AVX-512 table falls back to AVX2 or the reference where no wider kernel exists). */
#include "kernels.h"

#define MX_LAYOUT_REF                                                                                        \
    .upsample_nearest2x = mx_upsample_nearest2x_ref, .concat_channels = mx_concat_channels_ref,              \
    .transpose_chw_hwc = mx_transpose_chw_hwc_ref, .transpose_hwc_chw = mx_transpose_hwc_chw_ref,            \
    .resize_bilinear = mx_resize_bilinear_ref, .pad2d = mx_pad2d_ref, .copy = mx_copy_ref, .fill = mx_fill_ref,  \
    .axpy = mx_axpy_ref, .lincomb = mx_lincomb_ref, .clamp = mx_clamp_ref, .affine = mx_affine_ref,           \
    .timestep_embedding = mx_timestep_embedding_ref, .embed_tokens = mx_embed_tokens_ref,       \
    .copy_rect = mx_copy_rect_ref, .tanh = mx_tanh_ref

static const mx_kernels scalar_table = {
    .isa = MX_ISA_SCALAR,
    .linear = mx_linear_ref,
    .conv2d = mx_conv2d_ref,
    .group_norm = mx_group_norm_ref,
    .layer_norm = mx_layer_norm_ref,
    .softmax = mx_softmax_ref,
    .attention = mx_attention_ref,
    .gelu = mx_gelu_ref,
    .quick_gelu = mx_quick_gelu_ref,
    .silu = mx_silu_ref,
    .geglu = mx_geglu_ref,
    .binary = mx_binary_ref,
    .scale = mx_scale_ref,
    MX_LAYOUT_REF,
    .f16_to_f32 = mx_f16_to_f32_ref,
    .f32_to_f16 = mx_f32_to_f16_ref,
    .bf16_to_f32 = mx_bf16_to_f32_ref,
    .f32_to_bf16 = mx_f32_to_bf16_ref,
};

#ifndef MX_NO_X86_SIMD /* non-x86 builds (Makefile) have only the scalar table */
static const mx_kernels avx2_table = {
    .isa = MX_ISA_AVX2,
    .linear = mx_linear_avx2,
    .conv2d = mx_conv2d_avx2,
    .group_norm = mx_group_norm_avx2,
    .layer_norm = mx_layer_norm_avx2,
    .softmax = mx_softmax_avx2,
    .attention = mx_attention_avx2,
    .gelu = mx_gelu_avx2,
    .quick_gelu = mx_quick_gelu_avx2,
    .silu = mx_silu_avx2,
    .geglu = mx_geglu_avx2,
    .binary = mx_binary_avx2,
    .scale = mx_scale_avx2,
    MX_LAYOUT_REF,
    .f16_to_f32 = mx_f16_to_f32_avx2,
    .f32_to_f16 = mx_f32_to_f16_avx2,
    .bf16_to_f32 = mx_bf16_to_f32_avx2,
    .f32_to_bf16 = mx_f32_to_bf16_avx2,
};

/* The AVX-512 entries without a bf16 kernel: shared by the avx512 and avx512bf16 tables. */
#define MX_AVX512_FP32_ONLY                                                                                  \
    .group_norm = mx_group_norm_avx512,                                                                      \
    .layer_norm = mx_layer_norm_avx512,                                                                      \
    .softmax = mx_softmax_avx512,                                                                            \
    .gelu = mx_gelu_avx512,                                                                                  \
    .quick_gelu = mx_quick_gelu_avx512,                                                                      \
    .silu = mx_silu_avx512,                                                                                  \
    .geglu = mx_geglu_avx512,                                                                                \
    .binary = mx_binary_avx512,                                                                              \
    .scale = mx_scale_avx512,                                                                                \
    MX_LAYOUT_REF,                                                                                           \
    .f16_to_f32 = mx_f16_to_f32_avx512,                                                                      \
    .f32_to_f16 = mx_f32_to_f16_avx512,                                                                      \
    .bf16_to_f32 = mx_bf16_to_f32_avx512,                                                                    \
    .f32_to_bf16 = mx_f32_to_bf16_avx512

static const mx_kernels avx512_table = {
    .isa = MX_ISA_AVX512,
    .linear = mx_linear_avx512,
    .conv2d = mx_conv2d_avx512,
    .attention = mx_attention_avx512,
    MX_AVX512_FP32_ONLY,
};

static const mx_kernels avx512bf16_table = {
    .isa = MX_ISA_AVX512_BF16,
    .linear = mx_linear_avx512bf16,
    .conv2d = mx_conv2d_avx512bf16,
    .attention = mx_attention_avx512bf16,
    MX_AVX512_FP32_ONLY,
};

/* AMX: the GEMMs on tiles; attention has its own kernel (not the GEMM) and stays AVX512_BF16. */
static const mx_kernels amx_table = {
    .isa = MX_ISA_AMX,
    .linear = mx_linear_amx,
    .conv2d = mx_conv2d_amx,
    .attention = mx_attention_avx512bf16,
    MX_AVX512_FP32_ONLY,
};

#endif

#ifdef MX_WITH_NEON /* aarch64 builds (Makefile) */
/* The NEON entries without a bf16 kernel: shared by the neon and neonbf16 tables. */
#define MX_NEON_FP32_ONLY                                                                                    \
    .group_norm = mx_group_norm_neon,                                                                        \
    .layer_norm = mx_layer_norm_neon,                                                                        \
    .softmax = mx_softmax_neon,                                                                              \
    .gelu = mx_gelu_neon,                                                                                    \
    .quick_gelu = mx_quick_gelu_neon,                                                                        \
    .silu = mx_silu_neon,                                                                                    \
    .geglu = mx_geglu_neon,                                                                                  \
    .binary = mx_binary_neon,                                                                                \
    .scale = mx_scale_neon,                                                                                  \
    MX_LAYOUT_REF,                                                                                           \
    .f16_to_f32 = mx_f16_to_f32_neon,                                                                        \
    .f32_to_f16 = mx_f32_to_f16_neon,                                                                        \
    .bf16_to_f32 = mx_bf16_to_f32_neon,                                                                      \
    .f32_to_bf16 = mx_f32_to_bf16_neon

static const mx_kernels neon_table = {
    .isa = MX_ISA_NEON,
    .linear = mx_linear_neon,
    .conv2d = mx_conv2d_neon,
    .attention = mx_attention_neon,
    MX_NEON_FP32_ONLY,
};

static const mx_kernels neonbf16_table = {
    .isa = MX_ISA_NEON_BF16,
    .linear = mx_linear_neonbf16,
    .conv2d = mx_conv2d_neonbf16,
    .attention = mx_attention_neonbf16,
    MX_NEON_FP32_ONLY,
};
#endif

const mx_kernels *mx_kernels_scalar(void) { return &scalar_table; }

const mx_kernels *mx_kernels_for(mx_isa isa) {
    isa = mx_isa_min(isa, mx_cpu_best_isa());
#if defined(MX_WITH_NEON)
    switch (isa) {
    case MX_ISA_NEON_BF16: return &neonbf16_table;
    case MX_ISA_NEON: return &neon_table;
    default: return &scalar_table;
    }
#elif !defined(MX_NO_X86_SIMD)
    switch (isa) {
    case MX_ISA_AMX: return &amx_table;
    case MX_ISA_AVX512_BF16: return &avx512bf16_table;
    case MX_ISA_AVX512: return &avx512_table;
    case MX_ISA_AVX2: return &avx2_table;
    default: return &scalar_table;
    }
#else
    (void)isa;
    return &scalar_table;
#endif
}

const mx_kernels *mx_kernels_best(void) { return mx_kernels_for(mx_cpu_isa_for(MX_PREC_FP32)); }
