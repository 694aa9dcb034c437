/* The backend interface: where tensors live and which kernels run them.
 * CPU: host memory, kernels from ops/cpu chosen by cpuid (scalar, AVX2+FMA, AVX-512F).
 * CUDA: device memory, kernels from ops/cuda (built by `make cuda`). */
#ifndef MX_BACKEND_H
#define MX_BACKEND_H

typedef enum { MX_BACKEND_CPU = 0, MX_BACKEND_CUDA = 1 } mx_backend_kind;

/* Instruction-set levels of the CPU kernels, in increasing order. MX_ISA_AVX512_BF16 is the
 * AVX-512 level with linear, conv2d and attention in bf16 arithmetic (fp32 accumulation): a
 * precision choice as much as an ISA, so fp32 work asks for mx_cpu_isa_for(MX_PREC_FP32). */
typedef enum { MX_ISA_SCALAR = 0, MX_ISA_AVX2 = 1, MX_ISA_AVX512 = 2, MX_ISA_AVX512_BF16 = 3 } mx_isa;

/* Arithmetic of the matrix products: fp32, or bf16 inputs with fp32 accumulation. */
typedef enum { MX_PREC_FP32 = 0, MX_PREC_BF16 = 1 } mx_precision;

/* Best level this CPU and OS support (cpuid + xgetbv).
 * MATEX_ISA=scalar|avx2|avx512|avx512bf16 lowers it. */
mx_isa mx_cpu_best_isa(void);
/* Best level for a precision: fp32 never gets a bf16 level; bf16 gets the best level, which is
 * an fp32 one when the CPU has no bf16 arithmetic (check with mx_isa_precision). */
mx_isa mx_cpu_isa_for(mx_precision p);
/* The precision a level computes in. */
mx_precision mx_isa_precision(mx_isa isa);
const char *mx_isa_name(mx_isa isa);
const char *mx_precision_name(mx_precision p);
/* "fp32" or "bf16" into *p; -1 for anything else. */
int mx_precision_parse(const char *s, mx_precision *p);

#endif
