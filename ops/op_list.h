/* The list of ops: the one source of the kernel-table fields (struct mx_kernels, ops.h), the mx_*
 * wrappers (declared in ops.h, defined in ops.c), the kernel declarations of every CPU level
 * (ops/cpu/kernels.h), the scalar table (ops/cpu/dispatch.c), the CUDA entry points and table
 * (ops/cuda/cuda_backend.h, cuda_backend.cu), the op count, the op names of error messages and
 * each op's cost in a profile (ops/profile.h).
 *
 * One line per op: X(name, guard, params, args, cost).
 *   void mx_<name>(const mx_ctx *c, <params>) is the wrapper: it does nothing unless `guard` (an
 *   expression of the params; empty sizes are no work) holds, and otherwise calls the entry
 *   <name>(c, <args>) of c's kernel table. args names the params in order. cost (an mx_op_cost
 *   expression of the params, the mx_cost_* helpers of ops.c) is the call's FLOPs and the bytes
 *   it must move at least: its fp32 inputs read once, its outputs written once, weights at
 *   their stored size; read only when a profile is on (the roofline floor of bench_nets).
 * A new op: a line here (with its semantics), its scalar reference mx_<name>_ref in ops/cpu, its
 * CUDA kernel mx_cuda_<name> in ops/cuda, its tests; an op with a weight (mx_wptr) also its strict
 * wrapper in ops/backend.c (tests/test_ops_strict_wrappers.c fails without it). Faster CPU kernels
 * are optional (dispatch.c).
 *
 * Conventions of all ops: ops.h. Output buffers never alias inputs unless an op says "in place". */
#ifndef MX_OP_LIST_H
#define MX_OP_LIST_H

#define MX_OPS(X)                                                                                            \
    /* y[M,N] = x[M,K] · w[N,K]^T + bias[N]. */                                                              \
    X(linear, M > 0 && N > 0, (float *y, const float *x, mx_wptr w, mx_wptr bias, int M, int N, int K),       \
      (y, x, w, bias, M, N, K),                                                                              \
      mx_cost_linear(w, M, N, K))                                                                            \
    /* 2-D convolution, NCHW, kernel kh x kw (1x1 or 3x3 in SD; any size is correct), zero padding `pad` */   \
    /* on each side; Ho = (H + 2 pad - kh)/stride + 1, same for Wo; a kernel larger than the padded */       \
    /* input has no output (no work). */                                                                     \
    X(conv2d, B > 0 && Cout > 0 && H + 2 * pad >= kh && W + 2 * pad >= kw,                                   \
      (float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w, mx_wptr bias, int Cout, int kh,     \
       int kw, int stride, int pad),                                                                         \
      (y, x, B, Cin, H, W, w, bias, Cout, kh, kw, stride, pad),                                              \
      mx_cost_conv2d(B, Cin, H, W, w, Cout, kh, kw, stride, pad))                                            \
    /* conv2d (3x3, padding 1, stride 1) of the nearest-neighbour 2x upsample of x [B, Cin, H, W]: */         \
    /* y [B, Cout, 2H, 2W]; the upsampled input is never stored. Its cost counts the products of */         \
    /* its phase form (each output pixel's 3x3 taps read 2x2 input pixels: 16 taps per input pixel */      \
    /* and output channel, not 36), which the SIMD levels compute. */                                      \
    X(conv2d_up2x, B > 0 && Cout > 0 && H > 0 && W > 0,                                                      \
      (float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w, mx_wptr bias, int Cout),            \
      (y, x, B, Cin, H, W, w, bias, Cout),                                                                   \
      mx_cost_conv2d_up2x(B, Cin, H, W, w, Cout))                                                            \
    /* Group norm over (C/groups channels × HW) per batch item and group, biased variance, then */           \
    /* per-channel affine; fuse_silu applies SiLU after. y may equal x (in place). */                        \
    X(group_norm, B > 0 && C > 0 && HW > 0,                                                                  \
      (float *y, const float *x, int B, int C, int HW, int groups, mx_wptr gamma, mx_wptr beta, float eps,    \
       int fuse_silu),                                                                                       \
      (y, x, B, C, HW, groups, gamma, beta, eps, fuse_silu),                                                 \
      mx_cost_elementwise((double)B * C * HW, 2))                                                            \
    /* Layer norm over the last dimension C of x[M, C]. y may equal x. */                                    \
    X(layer_norm, M > 0 && C > 0, (float *y, const float *x, int M, int C, mx_wptr gamma, mx_wptr beta, float eps), \
      (y, x, M, C, gamma, beta, eps),                                                                        \
      mx_cost_elementwise((double)M * C, 2))                                                                 \
    /* Multi-head attention, softmax(q·k^T·scale [+ causal mask]) · v, streaming over keys (never builds */  \
    /* the Tq×Tk score matrix). q: [B, Tq, ·] with head h of token t at q + (b*Tq + t)*q_stride + h*D; */    \
    /* k, v likewise with kv_stride and Tk tokens; out: [B, Tq, ·] with out_stride. causal: key j is */      \
    /* masked for query i when j > i. */                                                                     \
    X(attention, B > 0 && H > 0 && Tq > 0 && Tk > 0 && D > 0,                                                \
      (float *out, const float *q, const float *k, const float *v, int B, int H, int Tq, int Tk, int D,       \
       int q_stride, int kv_stride, int out_stride, int causal, float scale),                                \
      (out, q, k, v, B, H, Tq, Tk, D, q_stride, kv_stride, out_stride, causal, scale),                       \
      mx_cost_attention(B, H, Tq, Tk, D))                                                                    \
    /* In place: GELU with erf, quick-GELU x·σ(1.702x) (CLIP), SiLU x·σ(x), tanh (TAESD's latent clamp */    \
    /* 3 tanh(x / 3)). */                                                                                    \
    X(gelu, 1, (float *x, size_t n), (x, n),                                                                 \
      mx_cost_elementwise((double)n, 2))                                                                     \
    X(quick_gelu, 1, (float *x, size_t n), (x, n),                                                           \
      mx_cost_elementwise((double)n, 2))                                                                     \
    X(silu, 1, (float *x, size_t n), (x, n),                                                                 \
      mx_cost_elementwise((double)n, 2))                                                                     \
    X(tanh, 1, (float *x, size_t n), (x, n),                                                                 \
      mx_cost_elementwise((double)n, 2))                                                                     \
    /* GEGLU (diffusers): x[M, 2N] = [h | g]; y[M, N] = h * gelu(g). */                                      \
    X(geglu, M > 0 && N > 0, (float *y, const float *x, int M, int N), (y, x, M, N),                         \
      mx_cost_elementwise((double)M * N, 3))                                                                 \
    /* y = a op b with numpy broadcasting over ndim (1..5) dims; y has the broadcast shape. y may equal */   \
    /* a when a has the output shape. A size-0 dim in either shape: no work. */                              \
    X(binary, mx_shapes_nonempty(ashape, bshape, ndim),                                                      \
      (mx_binop op, float *y, const float *a, const int64_t *ashape, const float *b, const int64_t *bshape,   \
       int ndim),                                                                                            \
      (op, y, a, ashape, b, bshape, ndim),                                                                   \
      mx_cost_binary(ashape, bshape, ndim))                                                                  \
    /* y = s * x (y may equal x). */                                                                         \
    X(scale, 1, (float *y, const float *x, float s, size_t n), (y, x, s, n),                                 \
      mx_cost_elementwise((double)n, 2))                                                                     \
    /* Nearest-neighbour 2× upsample of BC planes of H×W into 2H×2W. */                                      \
    X(upsample_nearest2x, BC > 0 && H > 0 && W > 0, (float *y, const float *x, int BC, int H, int W),        \
      (y, x, BC, H, W),                                                                                      \
      mx_cost_elementwise(5.0 * BC * H * W, 1))                                                              \
    /* Channel concat of a[B, Ca, HW] and b[B, Cb, HW] into y[B, Ca+Cb, HW]. */                              \
    X(concat_channels, B > 0 && HW > 0 && Ca + Cb > 0,                                                       \
      (float *y, const float *a, int Ca, const float *b, int Cb, int B, int HW),                             \
      (y, a, Ca, b, Cb, B, HW),                                                                              \
      mx_cost_elementwise((double)(Ca + Cb) * B * HW, 2))                                                    \
    /* [B, C, HW] <-> [B, HW, C]. */                                                                         \
    X(transpose_chw_hwc, B > 0 && C > 0 && HW > 0, (float *y, const float *x, int B, int C, int HW),         \
      (y, x, B, C, HW),                                                                                      \
      mx_cost_elementwise((double)B * C * HW, 2))                                                            \
    X(transpose_hwc_chw, B > 0 && C > 0 && HW > 0, (float *y, const float *x, int B, int C, int HW),         \
      (y, x, B, C, HW),                                                                                      \
      mx_cost_elementwise((double)B * C * HW, 2))                                                            \
    /* Rectangle copy over BC planes: y[p, y0 + r, x0 + q] = x[p, sy0 + r, sx0 + q] for r < h, q < w, */    \
    /* with y planes Hy×Wy and x planes Hx×Wx (the rectangle must lie inside both). Crops, pastes, tiles. */ \
    X(copy_rect, BC > 0 && h > 0 && w > 0,                                                                   \
      (float *y, int Hy, int Wy, int y0, int x0, const float *x, int Hx, int Wx, int sy0, int sx0, int BC,    \
       int h, int w),                                                                                        \
      (y, Hy, Wy, y0, x0, x, Hx, Wx, sy0, sx0, BC, h, w),                                                    \
      mx_cost_elementwise((double)BC * h * w, 2))                                                            \
    /* Zero padding of BC planes H×W by (top, bottom, left, right) rows/columns, each >= 0 (diffusers' */    \
    /* asymmetric Downsample2D pad is (0, 1, 0, 1)). */                                                      \
    X(pad2d, BC > 0 && H > 0 && W > 0,                                                                       \
      (float *y, const float *x, int BC, int H, int W, int top, int bottom, int left, int right),            \
      (y, x, BC, H, W, top, bottom, left, right),                                                            \
      mx_cost_elementwise((double)BC * ((double)H * W + (double)(H + top + bottom) * (W + left + right)), 1)) \
    /* y = x over n floats (no overlap); y[i] = v. */                                                        \
    X(copy, n, (float *y, const float *x, size_t n), (y, x, n),                                              \
      mx_cost_elementwise((double)n, 2))                                                                     \
    X(fill, n, (float *y, float v, size_t n), (y, v, n),                                                     \
      mx_cost_elementwise((double)n, 1))                                                                     \
    /* y += s·x; y = Σ_j coef[j]·x[j] (k <= MX_LINCOMB_MAX terms, summed left to right; y may be one of */   \
    /* the x); y = clamp(x, lo, hi); y = a·x + b. */                                                         \
    X(axpy, n, (float *y, const float *x, float s, size_t n), (y, x, s, n),                                  \
      mx_cost_elementwise((double)n, 3))                                                                     \
    X(lincomb, n && k >= 1 && k <= MX_LINCOMB_MAX,                                                           \
      (float *y, int k, const float *coef, const float *const *x, size_t n), (y, k, coef, x, n),             \
      mx_cost_elementwise((double)n, k + 1))                                                                 \
    X(clamp, n, (float *y, const float *x, float lo, float hi, size_t n), (y, x, lo, hi, n),                 \
      mx_cost_elementwise((double)n, 2))                                                                     \
    X(affine, n, (float *y, const float *x, float a, float b, size_t n), (y, x, a, b, n),                    \
      mx_cost_elementwise((double)n, 2))                                                                     \
    /* Sinusoidal timestep embedding exactly as diffusers' get_timestep_embedding: half = dim/2, */          \
    /* exponent_k = -ln(max_period) * k / (half - downscale_freq_shift), emb = t * exp(exponent); */         \
    /* out = [sin | cos] (or [cos | sin] when flip_sin_to_cos); zero pad if dim odd. y: [B, dim]. */         \
    /* SD1.5: flip_sin_to_cos=1, downscale_freq_shift=0, max_period=10000. */                                \
    X(timestep_embedding, B > 0 && dim > 0,                                                                  \
      (float *y, const float *t, int B, int dim, int flip_sin_to_cos, float downscale_freq_shift,            \
       float max_period),                                                                                    \
      (y, t, B, dim, flip_sin_to_cos, downscale_freq_shift, max_period),                                     \
      mx_cost_elementwise((double)B * dim, 1))                                                               \
    /* y[b, t, :] = tokens[ids[b·T + t], :] + positions[t, :] (C columns). ids are HOST integers, already */ \
    /* checked against the vocabulary by the caller; a negative id takes no token row, y = positions[t] */  \
    /* (CLIP vision: the class token at t = 0, the patch rows added after). */                              \
    X(embed_tokens, B > 0 && T > 0 && C > 0,                                                                 \
      (float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens, mx_wptr positions),                \
      (y, ids, B, T, C, tokens, positions),                                                                  \
      mx_cost_elementwise((double)B * T * C, 3))

#define MX_LINCOMB_MAX 4

/* The contents of a parenthesised list: MX_SPLICE params is the parameter list of one op. */
#define MX_SPLICE(...) __VA_ARGS__

/* The number of ops (what tests and messages count). Op names are the list's names (#name). */
#define MX_OP_ONE_(name, guard, params, args, cost) +1
enum { MX_OP_COUNT = 0 MX_OPS(MX_OP_ONE_) };

#endif
