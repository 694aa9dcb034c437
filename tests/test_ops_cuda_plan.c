/* The host-side decisions of the cuDNN convolution path (ops/cuda/cudnn_plan.h), with no GPU and no
 * cuDNN: the plan-cache keys (equal inputs give equal keys and hashes, any differing field gives
 * an unequal key), the NCHW <-> NHWC index mapping of its layout kernels, and when it falls back to
 * im2col + cuBLASLt (one line saying why). */
#include <stdio.h>
#include <string.h>

#include "../ops/cuda/cudnn_plan.h"
#include "util_test.h"

/* SD1.5's 3x3 conv at the 64x64 latent, fp16 weights and bias, on an H100 with cuDNN 9.19. */
static mx_cudnn_conv_key sd_key(void) {
    mx_cudnn_conv_key k;
    mx_cudnn_key_init(&k, "NVIDIA H100 80GB HBM3", 90, 13000, 91900);
    k.n = 1, k.cin = 320, k.h = 64, k.w = 64, k.cout = 320, k.kh = 3, k.kw = 3, k.stride = 1, k.pad = 1;
    k.wdtype = 1, k.bdtype = 1, k.align_x = k.align_w = k.align_b = k.align_y = 16;
    return k;
}

/* Each field changed alone must give a key unequal to the base (and, for these values, another hash). */
static void test_keys(void) {
    mx_cudnn_conv_key a = sd_key(), b = sd_key();
    CHECK(mx_cudnn_key_equal(&a, &b));
    CHECK(mx_cudnn_key_hash(&a) == mx_cudnn_key_hash(&b));
    mx_cudnn_conv_key v[20];
    int n = 0;
    for (int i = 0; i < 20; i++) v[i] = sd_key();
    mx_cudnn_key_init(&v[n], "NVIDIA H200", 90, 13000, 91900), n++; /* another GPU (shape fields reset) */
    v[n].cc = 80, n++;
    v[n].driver = 12080, n++;
    v[n].cudnn = 91300, n++;
    v[n].n = 2, n++;
    v[n].cin = 640, n++;
    v[n].h = 32, n++;
    v[n].w = 32, n++;
    v[n].cout = 640, n++;
    v[n].kh = 1, n++;
    v[n].kw = 1, n++;
    v[n].stride = 2, n++;
    v[n].pad = 0, n++;
    v[n].wdtype = 2, n++;
    v[n].bdtype = -1, n++;
    v[n].align_x = 8, n++;
    v[n].align_w = 2, n++;
    v[n].align_b = 4, n++;
    v[n].align_y = 8, n++;
    for (int i = 0; i < n; i++) {
        CHECK(!mx_cudnn_key_equal(&a, &v[i]));
        CHECK(mx_cudnn_key_hash(&a) != mx_cudnn_key_hash(&v[i]));
        for (int j = 0; j < i; j++) CHECK(!mx_cudnn_key_equal(&v[i], &v[j]));
    }
    /* the name is compared in full, its tail included */
    mx_cudnn_conv_key x, y;
    mx_cudnn_key_init(&x, "NVIDIA H100 80GB HBM3", 90, 13000, 91900);
    mx_cudnn_key_init(&y, "NVIDIA H100 80GB HBM2", 90, 13000, 91900);
    CHECK(!mx_cudnn_key_equal(&x, &y));
    CHECK(mx_cudnn_align(0x1000) == 16 && mx_cudnn_align(0x1008) == 8 && mx_cudnn_align(0x1002) == 2 &&
          mx_cudnn_align(0x1001) == 1);
}

/* NCHW -> NHWC (and a KCRS filter -> KRSC, the same per output channel) is a bijection, maps
 * (c, y, x) where the layout says, and is what the transposing kernel writes for rows = C,
 * cols = H*W; back, rows = H*W, cols = C. Shapes: odd sizes, one channel, one pixel. */
static void test_layout(void) {
    static const int shapes[][3] = {{3, 5, 7}, {1, 4, 4}, {320, 1, 1}, {4, 3, 2}, {33, 9, 17}};
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        size_t C = (size_t)shapes[s][0], H = (size_t)shapes[s][1], W = (size_t)shapes[s][2], n = C * H * W;
        static unsigned char seen[33 * 9 * 17];
        memset(seen, 0, sizeof seen);
        int bad = 0;
        for (size_t c = 0; c < C; c++)
            for (size_t y = 0; y < H; y++)
                for (size_t x = 0; x < W; x++) {
                    size_t src = mx_nchw_offset(c, y, x, C, H, W), dst = mx_nhwc_offset(c, y, x, C, H, W);
                    bad += src != c * H * W + y * W + x || dst >= n || seen[dst]++;
                    bad += dst != mx_transpose_dst_offset(c, y * W + x, C);     /* NCHW -> NHWC */
                    bad += src != mx_transpose_dst_offset(y * W + x, c, H * W); /* NHWC -> NCHW */
                    bad += dst % C != c || dst / C != y * W + x;
                }
        CHECK(bad == 0);
    }
}

static void test_decide(void) {
    char why[256];
    CHECK(mx_cudnn_decide(NULL, 1, 91900, NULL, why, sizeof why) == 0 && strstr(why, "MATEX_CUDNN=1"));
    CHECK(mx_cudnn_decide("0", 1, 91900, NULL, why, sizeof why) == 0);
    CHECK(mx_cudnn_decide("yes", 1, 91900, NULL, why, sizeof why) == 0);
    CHECK(mx_cudnn_decide("1", 0, 91900, NULL, why, sizeof why) == 0 && strstr(why, "no cuDNN"));
    CHECK(mx_cudnn_decide("1", 1, 0, "libcudnn.so.9: cannot open shared object file", why, sizeof why) == 0 &&
          strstr(why, "cannot open"));
    CHECK(mx_cudnn_decide("1", 1, 0, NULL, why, sizeof why) == 0 && strstr(why, "not found"));
    CHECK(mx_cudnn_decide("1", 1, 8907, NULL, why, sizeof why) == 0 && strstr(why, "8907"));
    CHECK(mx_cudnn_decide("1", 1, 100100, NULL, why, sizeof why) == 0);
    CHECK(mx_cudnn_decide("1", 1, 91900, NULL, why, sizeof why) == 1 && strstr(why, "cuDNN 9.19.0"));
    CHECK(mx_cudnn_decide("1", 1, 90000, NULL, why, sizeof why) == 1);
    CHECK(strchr(why, '\n') == NULL); /* one line */
}

int main(void) {
    test_keys();
    test_layout();
    test_decide();
    return mx_test_finish("test_ops_cuda_plan");
}
