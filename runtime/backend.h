/* The backend interface: where tensors live and which kernels run them.
 * CPU: host memory, kernels from ops/cpu chosen by cpuid (scalar, AVX2+FMA, AVX-512F).
 * CUDA: device memory, kernels from ops/cuda (built by `make cuda`). */
#ifndef MX_BACKEND_H
#define MX_BACKEND_H

typedef enum { MX_BACKEND_CPU = 0, MX_BACKEND_CUDA = 1 } mx_backend_kind;

/* Instruction-set levels of the CPU kernels, in increasing order. */
typedef enum { MX_ISA_SCALAR = 0, MX_ISA_AVX2 = 1, MX_ISA_AVX512 = 2 } mx_isa;

/* Best level this CPU and OS support (cpuid + xgetbv). MATEX_ISA=scalar|avx2|avx512 lowers it. */
mx_isa mx_cpu_best_isa(void);
const char *mx_isa_name(mx_isa isa);

#endif
