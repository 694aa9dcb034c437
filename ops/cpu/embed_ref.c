/* Embeddings computed on the backend: diffusers' sinusoidal timestep embedding and CLIP's
 * token + position embedding. Small; shared by every ISA level. */
#include <math.h>

#include "kernels.h"

/* Float32 arithmetic step by step, as torch evaluates get_timestep_embedding. */
void mx_timestep_embedding_ref(const mx_ctx *c, float *y, const float *t, int B, int dim, int flip_sin_to_cos,
                               float downscale_freq_shift, float max_period) {
    (void)c;
    int half = dim / 2;
    float neg_log = (float)-log((double)max_period);
    for (int b = 0; b < B; b++) {
        float *yb = y + (size_t)b * dim;
        for (int i = 0; i < half; i++) {
            float exponent = neg_log * (float)i / ((float)half - downscale_freq_shift);
            float arg = t[b] * expf(exponent);
            float s = sinf(arg), co = cosf(arg);
            yb[i] = flip_sin_to_cos ? co : s;
            yb[half + i] = flip_sin_to_cos ? s : co;
        }
        if (dim % 2) yb[dim - 1] = 0;
    }
}

void mx_embed_tokens_ref(const mx_ctx *c, float *y, const int32_t *ids, int B, int T, int C, mx_wptr tokens,
                         mx_wptr positions) {
    (void)c;
    for (int b = 0; b < B; b++)
        for (int t = 0; t < T; t++) {
            int id = ids[b * T + t];
            size_t tok = (size_t)(id < 0 ? 0 : id) * (size_t)C, pos = (size_t)t * (size_t)C;
            float *row = y + ((size_t)b * T + t) * C;
            for (int i = 0; i < C; i++)
                row[i] = id < 0 ? mx_w_get(positions, pos + (size_t)i)
                                : mx_w_get(tokens, tok + (size_t)i) + mx_w_get(positions, pos + (size_t)i);
        }
}
