/* The backend interface: where activations live and which kernels run the ops.
 *
 * A backend owns device memory (the activation arena of a run and the network inputs and
 * outputs), runs every op through its kernel table (struct mx_kernels, ops/ops.h) and copies
 * to or from the host only at the edges (network inputs/outputs, images handed to the
 * geometry code). Network code holds activations as `float *` handles that only ops
 * dereference: on CUDA they are device pointers, on cpu-strict they point into memory that is
 * inaccessible (PROT_NONE) except while one of the backend's kernels runs.
 *
 *   cpu         host memory, the cpuid-chosen SIMD kernels (ops/cpu)
 *   cpu-strict  the same kernels; memory readable only inside them, and a device context:
 *               weights must be device copies (mx_binder_device), as on CUDA (tests prove the seam)
 *   cuda        device memory, the kernels of ops/cuda (in binaries built by `make cuda`)
 *
 * Backends are made by mx_backend_create (ops/backend.c); ops reach them through mx_ctx.be. */
#ifndef MX_BACKEND_H
#define MX_BACKEND_H

#include <stddef.h>

#include "status.h"

typedef enum { MX_BACKEND_CPU = 0, MX_BACKEND_CPU_STRICT = 1, MX_BACKEND_CUDA = 2 } mx_backend_kind;
#define MX_BACKEND_KINDS 3

/* Instruction-set levels of the CPU kernels. Each architecture has its own ladder, in
 * increasing order: x86-64 scalar < avx2 < avx512 < avx512bf16 < amx, aarch64 scalar < neon <
 * neonbf16 (compare levels with mx_isa_min, never across ladders). MX_ISA_AVX512_BF16 is the
 * AVX-512 level with linear, conv2d and attention in bf16 arithmetic (fp32 accumulation), and
 * MX_ISA_AMX the same with linear and conv2d on AMX-BF16 tiles; MX_ISA_NEON_BF16 is the NEON
 * level with those three on FEAT_BF16 (BFDOT): precision choices as much as ISAs, so fp32 work
 * asks for mx_cpu_isa_for(MX_PREC_FP32). */
typedef enum {
    MX_ISA_SCALAR = 0,
    MX_ISA_AVX2 = 1,
    MX_ISA_AVX512 = 2,
    MX_ISA_AVX512_BF16 = 3,
    MX_ISA_AMX = 4,
    MX_ISA_NEON = 5,
    MX_ISA_NEON_BF16 = 6,
    MX_ISA_COUNT
} mx_isa;

/* Arithmetic of the matrix products: fp32, or bf16 inputs with fp32 accumulation. */
typedef enum { MX_PREC_FP32 = 0, MX_PREC_BF16 = 1 } mx_precision;

/* Best level this CPU and OS support (x86: cpuid + xgetbv, for amx also Linux's permission for
 * the tile data, asked at each call: the grant is per process and asking again is harmless, so no
 * process-wide flag remembers it; aarch64: getauxval's HWCAP_ASIMD and HWCAP2_BF16).
 * MATEX_ISA=scalar|avx2|avx512|avx512bf16|amx|neon|neonbf16 lowers it. */
mx_isa mx_cpu_best_isa(void);
/* want, lowered to best when it is above it on the same ladder; scalar when the two are of
 * different architectures. */
mx_isa mx_isa_min(mx_isa want, mx_isa best);
/* The fp32 level a bf16 level is built on (avx512 for avx512bf16 and amx, neon for neonbf16);
 * an fp32 level itself. */
mx_isa mx_isa_fp32_level(mx_isa isa);
/* Best level for a precision: fp32 never gets a bf16 level; bf16 gets the best level, which is
 * an fp32 one when the CPU has no bf16 arithmetic (check with mx_isa_precision). */
mx_isa mx_cpu_isa_for(mx_precision p);
/* The precision auto picks: bf16 where this CPU computes bf16 products faster than fp32 ones,
 * else fp32 (MATEX_ISA lowers it with the levels). */
mx_precision mx_cpu_faster_precision(void);
/* The precision a level computes in. */
mx_precision mx_isa_precision(mx_isa isa);
const char *mx_isa_name(mx_isa isa);
const char *mx_precision_name(mx_precision p);
/* "fp32" or "bf16" into *p; -1 for anything else. */
int mx_precision_parse(const char *s, mx_precision *p);

struct mx_kernels;
struct mx_record;          /* ops/record.h */
struct mx_stream_observer; /* file_stream.h */

typedef struct mx_backend mx_backend;
struct mx_backend {
    mx_backend_kind kind;
    const struct mx_kernels *k; /* the kernels that run every op */
    int host_visible;           /* 1: weights in host memory serve as they are (no upload) */
    /* The kernels of the fp32 level below k when k computes in bf16 (mx_ctx_fp32); NULL: the
     * CPU table mx_kernels_fp32_of(k). */
    const struct mx_kernels *k_fp32;
    /* Device memory, 64-byte aligned; NULL with a message in st when out of memory. */
    void *(*alloc)(mx_backend *be, size_t bytes, mx_status *st);
    void (*release)(mx_backend *be, void *p);
    /* Copies between host and device memory; to_host first waits for queued work and
     * reports any error it raised. */
    int (*to_device)(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st);
    int (*to_host)(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st);
    /* A device copy of a weight's bytes, only read by kernels (mx_dev_weight; NULL: alloc and
     * to_device); freed with release. */
    void *(*weight)(mx_backend *be, const void *src, size_t bytes, mx_status *st);
    /* Optional (NULL: weight() copies each tensor): a whole weight file, open as fd and mapped at
     * map (len bytes), put on the device in one allocation and one pass that shows obs (may be
     * NULL) every chunk; weight() then returns the place in that copy of any bytes inside the
     * mapping, and release() of such a place does nothing. 1 when done (0 is for a file already
     * there: obs saw nothing). weight_file_drop frees the copy of the file mapped at map. */
    int (*weight_file)(mx_backend *be, int fd, const void *map, size_t len, const char *path,
                       const struct mx_stream_observer *obs, mx_status *st);
    void (*weight_file_drop)(mx_backend *be, const void *map);
    /* Optional (NULL: fn just runs): the second and later calls of a recorded region (ops/record.h),
     * fn(user) queueing the same work with the same arguments each time. CUDA with
     * MATEX_CUDA_GRAPH=1 captures the second call as a graph and replays it after; cpu-strict runs
     * fn, fails any alloc, release or host copy made inside it, and fails a later call whose ops or
     * arguments differ from the second's. record_drop frees what recorded kept in rec (rec->graph). */
    int (*recorded)(mx_backend *be, struct mx_record *rec, int (*fn)(void *user, mx_status *st), void *user,
                    mx_status *st);
    void (*record_drop)(mx_backend *be, struct mx_record *rec);
    /* Around every kernel call (NULL: nothing to do); calls nest. */
    void (*enter)(mx_backend *be);
    void (*leave)(mx_backend *be);
    void (*destroy)(mx_backend *be);
    void *impl;
};

/* "cpu", "cpu-strict", "cuda". */
const char *mx_backend_name(mx_backend_kind kind);
/* Parses a --device value; the message lists the accepted names. */
int mx_backend_parse(const char *name, mx_backend_kind *kind, mx_status *st);
/* 1 when this binary has the backend (cuda only in `make cuda` builds). */
int mx_backend_compiled(mx_backend_kind kind);
/* The backends compiled into this binary, space separated ("cpu cpu-strict" or
 * "cpu cpu-strict cuda"), for `matex --version`. */
const char *mx_backends_compiled(void);

#endif
