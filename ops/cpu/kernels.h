/* Internal to ops/: the kernel functions behind the dispatch tables (ops/cpu/dispatch.c), the
 * scratch-memory helper and the parallel-for helper they share.
 * Naming: mx_<op>_ref (scalar reference, the test oracle), mx_<op>_avx2, mx_<op>_avx512,
 * mx_<op>_avx512bf16 (bf16 arithmetic, fp32 accumulation), mx_<op>_amx (the same on AMX tiles),
 * mx_<op>_neon and mx_<op>_neonbf16 (aarch64: Advanced SIMD, FEAT_BF16).
 *
 * Files, by op family: <family>_ref.c are the references (linear, conv, norm, attention,
 * activation, binary, layout, vector, embed). gemm.c is the blocked GEMM engine behind linear
 * and conv2d; gemm_<isa>.c holds its micro-kernels (the AVX-512 one written once in
 * gemm_micro_avx512.inc for fp32 and bf16). The other SIMD kernels are written once as templates
 * (attention_lanes_simd.inc, norm_simd.inc, activation_simd.inc, vmath_simd.inc for exp/erfc) over a
 * small vector vocabulary (simd_avx2.h, simd_avx512.h, simd_neon.h) and instantiated per level by
 * attention_<isa>.c and elementwise_<isa>.c (docs/DESIGN.md §4 has the recipe for a new level). */
#ifndef MX_OPS_CPU_KERNELS_H
#define MX_OPS_CPU_KERNELS_H

#include <stddef.h>
#include <stdint.h>

#include "../ops.h"

/* Runs fn over ntasks tasks on c->pool (serially when c or its pool is NULL). */
static inline void mx_par_for(const mx_ctx *c, int ntasks, mx_task_fn fn, void *arg) {
    mx_pool_for(c ? c->pool : NULL, ntasks, fn, arg);
}
static inline int mx_par_threads(const mx_ctx *c) { return mx_pool_threads(c ? c->pool : NULL); }

/* Temporary memory for one kernel call: from c->scratch when it has room, else from the heap
 * (so a small scratch arena costs speed, never correctness). Release in reverse order. */
typedef struct mx_scratch {
    void *p;
    size_t mark;
    int heap;
} mx_scratch;
void *mx_scratch_take(const mx_ctx *c, size_t bytes, mx_scratch *s);
void mx_scratch_release(const mx_ctx *c, mx_scratch *s);

/* The kernels of every op at every CPU level, declared from op_list.h: mx_<op>_<level>(const
 * mx_ctx *c, <the op's params>). Every op has its reference (_ref); a faster level defines only the
 * kernels it lists in dispatch.c, so most of these other names are never defined (nor used). */
#define MX_KERNEL_DECL_(name, guard, params, args, cost)                                                     \
    void mx_##name##_ref(const mx_ctx *c, MX_SPLICE params);                                                 \
    void mx_##name##_avx2(const mx_ctx *c, MX_SPLICE params);                                                \
    void mx_##name##_avx512(const mx_ctx *c, MX_SPLICE params);                                              \
    void mx_##name##_avx512bf16(const mx_ctx *c, MX_SPLICE params);                                          \
    void mx_##name##_amx(const mx_ctx *c, MX_SPLICE params);                                                 \
    void mx_##name##_neon(const mx_ctx *c, MX_SPLICE params);                                                \
    void mx_##name##_neonbf16(const mx_ctx *c, MX_SPLICE params);
MX_OPS(MX_KERNEL_DECL_)

/* The amx level's fp32 layers: linear, conv2d and conv2d_up2x as three bf16 products (gemm_amx.inc). */
void mx_linear_x3_amx(const mx_ctx *c, float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K);
void mx_conv2d_x3_amx(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                      mx_wptr bias, int Cout, int kh, int kw, int stride, int pad);
void mx_conv2d_up2x_x3_amx(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                           mx_wptr bias, int Cout);

/* Elements per task of the element-wise kernels: fixed, so the split never depends on threads. */
#define MX_EW_CHUNK 16384

#endif
