/* LCMScheduler of diffusers 0.35.2 (scheduling_lcm.py) on the shared schedule of scheduler.c:
 * the timestep list of set_timesteps (strength 1) and the multistep consistency step
 *   x0      = (x - sqrt(1 - a_t) eps) / sqrt(a_t)                    (epsilon prediction)
 *   denoised = c_out x0 + c_skip x,  c_skip = s^2 / (T^2 + s^2), c_out = T / sqrt(T^2 + s^2),
 *              T = t * timestep_scaling, s = sigma_data = 0.5
 *   x_prev  = sqrt(a_prev) denoised + sqrt(1 - a_prev) noise          (denoised at the last step)
 * with a_prev the alpha product of the next timestep in the list (of t itself at the last step).
 * Coefficients in float32 as torch computes them; the latent updates go through ops on s->c, the
 * fresh noise comes from s->noise_fn on the host and is uploaded (the edge). */
#include <math.h>
#include <string.h>

#include "../../ops/ops.h"
#include "scheduler.h"

#define LCM_SIGMA_DATA 0.5f

void mx_sched_config_lcm(mx_sched_config *cfg, const mx_sched_config *base) {
    *cfg = *base;
    cfg->kind = MX_SCHED_LCM;
    cfg->prediction_type = MX_PRED_EPSILON;
    cfg->set_alpha_to_one = 1;
    cfg->clip_sample = 0;
    cfg->original_inference_steps = 50;
    cfg->timestep_scaling = 10.0;
}

int mx_sched_lcm_timesteps(const mx_sched_config *c, int steps, int64_t *ts, mx_status *st) {
    int orig = c->original_inference_steps;
    if (orig < 1 || orig > c->num_train_timesteps)
        return mx_fail(st, MX_EINPUT, "LCM scheduler: original_inference_steps %d outside 1..%d", orig,
                       c->num_train_timesteps);
    if (steps < 1 || steps > orig)
        return mx_fail(st, MX_EUSAGE, "LCM scheduler: %d steps outside 1..%d (original_inference_steps)", steps, orig);
    int64_t k = c->num_train_timesteps / orig;
    double stride = (double)orig / steps; /* np.linspace(0, orig, steps, endpoint=False), floored */
    for (int j = 0; j < steps; j++) {
        int idx = (int)floor(j * stride);
        ts[j] = (int64_t)(orig - idx) * k - 1; /* reversed list of (i + 1) k - 1, i < orig */
    }
    return steps;
}

int mx_sched_needs_noise(const mx_sched *s) {
    return s->cfg.kind == MX_SCHED_LCM && s->step_index < s->n_steps - 1;
}

int mx_sched_prepare(mx_sched *s, mx_status *st) {
    if (s->cfg.kind != MX_SCHED_LCM || s->noise_ready) return 0;
    int first = s->step_index - s->begin, left = s->n_steps - 1 - s->step_index; /* steps that draw noise */
    if (left > 0 && !s->noise_fn)
        return mx_fail(st, MX_EUSAGE, "LCM scheduler: step %d needs a noise source", s->step_index);
    for (int k = 0; k < left; k++)
        if (s->noise_fn(s->noise_user, first + k, s->noise_host + (size_t)k * s->numel, s->numel))
            return mx_fail(st, MX_EINTERNAL, "LCM scheduler: no noise for step %d", first + k + 1);
    if (left > 0 && mx_upload(s->c, s->noise_dev, s->noise_host, (size_t)left * s->numel, st)) return -1;
    s->noise_ready = 1;
    s->noise_first = s->step_index;
    return 0;
}

/* The fresh noise of the current step, on the device (drawn with every later step's by mx_sched_prepare). */
static const float *step_noise(mx_sched *s, mx_status *st) {
    if (mx_sched_prepare(s, st)) return NULL;
    return s->noise_dev + (size_t)(s->step_index - s->noise_first) * s->numel;
}

int mx_sched_lcm_step(mx_sched *s, const float *mo, float *x, mx_status *st) {
    const mx_ctx *c = s->c;
    if (s->cfg.kind != MX_SCHED_LCM) return mx_fail(st, MX_EINTERNAL, "scheduler: not an LCM scheduler");
    if (s->step_index >= s->n_steps)
        return mx_fail(st, MX_EUSAGE, "scheduler: step %d past the last of %d", s->step_index, s->n_steps);
    const float *noise = NULL;
    if (mx_sched_needs_noise(s) && !(noise = step_noise(s, st))) return -1;
    int64_t t = s->timesteps[s->step_index];
    int64_t prev = s->step_index + 1 < s->n_steps ? s->timesteps[s->step_index + 1] : t;
    if (t < 0 || t >= s->cfg.num_train_timesteps || prev >= s->cfg.num_train_timesteps)
        return mx_fail(st, MX_EINTERNAL, "scheduler: timestep %lld out of range", (long long)t);
    float at = s->alphas_cumprod[t];
    float ap = prev >= 0 ? s->alphas_cumprod[prev] : (s->cfg.set_alpha_to_one ? 1.0f : s->alphas_cumprod[0]);
    float T = (float)t * (float)s->cfg.timestep_scaling, s2 = LCM_SIGMA_DATA * LCM_SIGMA_DATA;
    float c_skip = s2 / (T * T + s2), c_out = T / sqrtf(T * T + s2);
    size_t n = s->numel;
    float *den = s->work[0], *tmp = s->model_outputs[0];
    /* x0 = (x - sqrt(1 - a_t) eps) / sqrt(a_t) */
    mx_scale(c, den, mo, -sqrtf(1.0f - at), n);
    mx_add(c, den, den, x, n);
    mx_scale(c, den, den, 1.0f / sqrtf(at), n);
    /* denoised = c_out x0 + c_skip x */
    mx_scale(c, den, den, c_out, n);
    mx_scale(c, tmp, x, c_skip, n);
    mx_add(c, den, den, tmp, n);
    if (noise) {
        mx_scale(c, x, den, sqrtf(ap), n);
        mx_scale(c, tmp, noise, sqrtf(1.0f - ap), n);
        mx_add(c, x, x, tmp, n);
    } else {
        mx_copy(c, x, den, n);
    }
    s->step_index++;
    return 0;
}
