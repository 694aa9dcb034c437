/* What the cuDNN convolution path (cuda_cudnn.cu) decides on the host, with no GPU and no cuDNN:
 * whether to use cuDNN at all, the key of a cached execution plan, and the NCHW <-> NHWC index
 * mapping its layout kernels follow. Plain C (host-only tests: tests/test_ops_cuda_plan.c);
 * the mapping functions are also device functions under nvcc. */
#ifndef MX_CUDNN_PLAN_H
#define MX_CUDNN_PLAN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- whether convolution goes through cuDNN ---- */

/* The cuDNN major version matex's graphs are written for (the backend API of cuDNN 9). */
#define MX_CUDNN_MAJOR 9

/* 1: convolution through cuDNN; 0: today's path (im2col + cuBLASLt), with why[] saying why in one
 * line. env: MATEX_CUDNN's value (NULL: unset; only "1" switches cuDNN on until a GPU run proves
 * it). built: the build has cuDNN's headers (make CUDNN=1). loaded_version: cudnnGetVersion() of
 * the library found at run time (e.g. 91900 for 9.19.0), 0 when none could be loaded, and then
 * load_error says why (dlerror's text; may be NULL). */
int mx_cudnn_decide(const char *env, int built, size_t loaded_version, const char *load_error, char *why,
                    size_t why_size);

/* ---- the key of a cached execution plan ---- */

/* Everything a plan depends on: the device, driver and library it was built for (a plan cache on
 * disk stays valid only for them), and the convolution's shape, types, bias fusion and pointer
 * alignments. Compared field by field; the hash only picks the table slot. */
typedef struct mx_cudnn_conv_key {
    char gpu[64];          /* device name (cudaDeviceProp.name), NUL-padded */
    int cc;                /* compute capability, major*10 + minor */
    int driver;            /* cudaDriverGetVersion */
    long cudnn;            /* cudnnGetVersion */
    int n, cin, h, w;      /* input: n items (the path runs one item per call: n = 1) */
    int cout, kh, kw, stride, pad;
    int wdtype, bdtype;    /* mx_dtype of the weight and of the bias (-1: no bias fused) */
    int align_x, align_w, align_b, align_y; /* byte alignment of each pointer, capped at 16 */
} mx_cudnn_conv_key;

/* A key with every byte defined (padding and the name's tail zeroed), so equal fields give equal
 * bytes. gpu may be NULL (""). */
void mx_cudnn_key_init(mx_cudnn_conv_key *k, const char *gpu, int cc, int driver, long cudnn);
int mx_cudnn_key_equal(const mx_cudnn_conv_key *a, const mx_cudnn_conv_key *b);
uint64_t mx_cudnn_key_hash(const mx_cudnn_conv_key *k);
/* The alignment of address p for a key: the largest power of two dividing it, at most 16. */
int mx_cudnn_align(uintptr_t p);

/* ---- layouts: one item's offsets ---- */

#ifdef __CUDACC__
#define MX_CUDNN_HD __host__ __device__ static inline
#else
#define MX_CUDNN_HD static inline
#endif
/* Offset of (c, y, x) in an item stored NCHW ([C][H][W]) and NHWC ([H][W][C]). A filter KCRS ->
 * KRSC is the same mapping per output channel k with (H, W) = (R, S). */
MX_CUDNN_HD size_t mx_nchw_offset(size_t c, size_t y, size_t x, size_t C, size_t H, size_t W) {
    (void)C;
    return (c * H + y) * W + x;
}
MX_CUDNN_HD size_t mx_nhwc_offset(size_t c, size_t y, size_t x, size_t C, size_t H, size_t W) {
    (void)H;
    return (y * W + x) * C + c;
}
/* The layout kernels see an item as a [rows][cols] matrix and write its transpose: NCHW -> NHWC is
 * rows = C, cols = H*W; NHWC -> NCHW is rows = H*W, cols = C. Source element (r, q), at r*cols + q,
 * goes to: */
MX_CUDNN_HD size_t mx_transpose_dst_offset(size_t r, size_t q, size_t rows) { return q * rows + r; }

#ifdef __cplusplus
}
#endif

#endif
