/* Scalar references of mx_conv2d and mx_conv2d_up2x: direct convolution, NCHW, zero padding,
 * accumulated in double; conv2d_up2x reads its input through the 2× nearest upsample (pixel (iy, ix)
 * of the upsampled image is x's (iy/2, ix/2)). */
#include "kernels.h"

typedef struct {
    float *y;
    const float *x;
    int B, Cin, H, W, Cout, kh, kw, stride, pad, Ho, Wo;
    int up; /* the input as seen by the conv: x upsampled up× (H, W: its size then) */
    mx_wptr w, bias;
} conv_args;

static double conv_pixel(const conv_args *a, const float *xb, size_t wbase, int oy, int ox) {
    double acc = 0;
    for (int ci = 0; ci < a->Cin; ci++) {
        const float *xc = xb + (size_t)ci * (a->H / a->up) * (a->W / a->up);
        for (int ky = 0; ky < a->kh; ky++) {
            int iy = oy * a->stride - a->pad + ky;
            if (iy < 0 || iy >= a->H) continue;
            for (int kx = 0; kx < a->kw; kx++) {
                int ix = ox * a->stride - a->pad + kx;
                if (ix < 0 || ix >= a->W) continue;
                size_t wi = wbase + ((size_t)ci * a->kh + ky) * a->kw + kx;
                acc += (double)xc[(size_t)(iy / a->up) * (a->W / a->up) + ix / a->up] * mx_w_get(a->w, wi);
            }
        }
    }
    return acc;
}

/* One task = one (batch item, output channel) plane. */
static void conv_plane(void *arg, int task, int thread) {
    (void)thread;
    const conv_args *a = arg;
    int b = task / a->Cout, co = task % a->Cout;
    const float *xb = a->x + (size_t)b * a->Cin * (a->H / a->up) * (a->W / a->up);
    float *yp = a->y + ((size_t)b * a->Cout + co) * a->Ho * a->Wo;
    size_t wbase = (size_t)co * a->Cin * a->kh * a->kw;
    double bias = a->bias.data ? mx_w_get(a->bias, co) : 0.0;
    for (int oy = 0; oy < a->Ho; oy++)
        for (int ox = 0; ox < a->Wo; ox++)
            yp[(size_t)oy * a->Wo + ox] = (float)(conv_pixel(a, xb, wbase, oy, ox) + bias);
}

void mx_conv2d_ref(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                   mx_wptr bias, int Cout, int kh, int kw, int stride, int pad) {
    conv_args a = {y, x, B, Cin, H, W, Cout, kh, kw, stride, pad, 0, 0, 1, w, bias};
    a.Ho = (H + 2 * pad - kh) / stride + 1;
    a.Wo = (W + 2 * pad - kw) / stride + 1;
    mx_par_for(c, B * Cout, conv_plane, &a);
}

void mx_conv2d_up2x_ref(const mx_ctx *c, float *y, const float *x, int B, int Cin, int H, int W, mx_wptr w,
                        mx_wptr bias, int Cout) {
    conv_args a = {y, x, B, Cin, 2 * H, 2 * W, Cout, 3, 3, 1, 1, 2 * H, 2 * W, 2, w, bias};
    mx_par_for(c, B * Cout, conv_plane, &a);
}
