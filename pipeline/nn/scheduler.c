/* DPM-Solver++ (multistep) and DDIM over the SD1.5 noise schedule, following diffusers 0.35.2
 * (DPMSolverMultistepScheduler, DDIMScheduler). Where the reference computes in float32
 * (betas, alphas_cumprod, sigmas, the per-step coefficients) this code does too, so that the
 * integer timesteps come out identical; the latent updates are the reference's formulas. */
#include "scheduler.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/json.h"

static void config_common_sd15(mx_sched_config *c) {
    memset(c, 0, sizeof *c);
    c->num_train_timesteps = 1000;
    c->beta_start = 0.00085;
    c->beta_end = 0.012;
    c->beta_schedule = MX_BETA_SCALED_LINEAR;
    c->prediction_type = MX_PRED_EPSILON;
    c->timestep_spacing = MX_SPACING_LINSPACE;
    c->steps_offset = 1;
    c->solver_order = 2;
    c->solver_type = MX_SOLVER_MIDPOINT;
    c->lower_order_final = 1;
    c->final_sigmas_type = MX_FINAL_SIGMA_ZERO;
    c->clip_sample_range = 1.0;
}

void mx_sched_config_sd15(mx_sched_config *cfg) {
    config_common_sd15(cfg);
    cfg->kind = MX_SCHED_DPMPP;
}

/* SD1.5's scheduler_config.json for DDIM: leading spacing, set_alpha_to_one false. */
void mx_sched_config_sd15_ddim(mx_sched_config *cfg) {
    config_common_sd15(cfg);
    cfg->kind = MX_SCHED_DDIM;
    cfg->timestep_spacing = MX_SPACING_LEADING;
}

/* ---- config parsing ---- */

/* Looks `s` up in names[0..n); -1 when absent. */
static int pick(const char *s, const char *const *names, int n) {
    for (int i = 0; i < n; i++)
        if (strcmp(s, names[i]) == 0) return i;
    return -1;
}

static int parse_enum(const mx_json *root, const char *key, const char *const *names, int n, int *out,
                      const char *what, mx_status *st) {
    const mx_json *v = mx_json_get(root, key);
    if (!v || mx_json_kind(v) == MX_JSON_NULL) return 0;
    if (mx_json_kind(v) != MX_JSON_STR) return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be a string", what, key);
    int i = pick(mx_json_str(v), names, n);
    if (i < 0) return mx_fail(st, MX_EINPUT, "%s: unsupported %s \"%s\"", what, key, mx_json_str(v));
    *out = i;
    return 0;
}

/* Rejects a boolean option that matex does not implement when it is true. */
static int reject_true(const mx_json *root, const char *key, const char *what, mx_status *st) {
    if (mx_json_get_bool(root, key, 0)) return mx_fail(st, MX_EINPUT, "%s: %s=true is not supported", what, key);
    return 0;
}

/* *v = the integer member key (kept when absent); a value that is not an integer within int's range
 * is refused (a cast would be undefined for it). */
static int get_int(const mx_json *root, const char *key, int *v, const char *what, mx_status *st) {
    double d = mx_json_get_num(root, key, *v);
    if (!(d >= INT_MIN && d <= INT_MAX) || d != floor(d))
        return mx_fail(st, MX_EINPUT, "%s: \"%s\" must be an integer", what, key);
    *v = (int)d;
    return 0;
}

static int parse_fields(mx_sched_config *c, const mx_json *root, const char *what, mx_status *st) {
    static const char *const betas[] = {"scaled_linear", "linear"};
    static const char *const preds[] = {"epsilon", "v_prediction", "sample"};
    static const char *const spacings[] = {"linspace", "leading", "trailing"};
    static const char *const solvers[] = {"midpoint", "heun"};
    static const char *const finals[] = {"zero", "sigma_min"};
    static const char *const algos[] = {"dpmsolver++"};
    static const char *const unsupported[] = {"thresholding", "use_exponential_sigmas", "use_beta_sigmas",
                                              "use_lu_lambdas", "use_flow_sigmas", "rescale_betas_zero_snr",
                                              "use_dynamic_shifting"};
    int e, algo = 0;
    if (get_int(root, "num_train_timesteps", &c->num_train_timesteps, what, st) ||
        get_int(root, "steps_offset", &c->steps_offset, what, st) ||
        get_int(root, "solver_order", &c->solver_order, what, st) ||
        get_int(root, "original_inference_steps", &c->original_inference_steps, what, st))
        return -1;
    c->beta_start = mx_json_get_num(root, "beta_start", c->beta_start);
    c->beta_end = mx_json_get_num(root, "beta_end", c->beta_end);
    c->lower_order_final = mx_json_get_bool(root, "lower_order_final", c->lower_order_final);
    c->euler_at_final = mx_json_get_bool(root, "euler_at_final", c->euler_at_final);
    c->use_karras_sigmas = mx_json_get_bool(root, "use_karras_sigmas", c->use_karras_sigmas);
    c->set_alpha_to_one = mx_json_get_bool(root, "set_alpha_to_one", c->set_alpha_to_one);
    c->clip_sample = mx_json_get_bool(root, "clip_sample", c->clip_sample);
    c->clip_sample_range = mx_json_get_num(root, "clip_sample_range", c->clip_sample_range);
    c->timestep_scaling = mx_json_get_num(root, "timestep_scaling", c->timestep_scaling);
    e = (int)c->beta_schedule;
    if (parse_enum(root, "beta_schedule", betas, 2, &e, what, st)) return -1;
    c->beta_schedule = (mx_beta_schedule)e;
    e = (int)c->prediction_type;
    if (parse_enum(root, "prediction_type", preds, 3, &e, what, st)) return -1;
    c->prediction_type = (mx_prediction)e;
    e = (int)c->timestep_spacing;
    if (parse_enum(root, "timestep_spacing", spacings, 3, &e, what, st)) return -1;
    c->timestep_spacing = (mx_spacing)e;
    e = (int)c->solver_type;
    if (parse_enum(root, "solver_type", solvers, 2, &e, what, st)) return -1;
    c->solver_type = (mx_solver_type)e;
    e = (int)c->final_sigmas_type;
    if (parse_enum(root, "final_sigmas_type", finals, 2, &e, what, st)) return -1;
    c->final_sigmas_type = (mx_final_sigma)e;
    if (c->kind == MX_SCHED_DPMPP && parse_enum(root, "algorithm_type", algos, 1, &algo, what, st)) return -1;
    for (size_t i = 0; i < sizeof unsupported / sizeof unsupported[0]; i++)
        if (reject_true(root, unsupported[i], what, st)) return -1;
    const mx_json *tb = mx_json_get(root, "trained_betas");
    if (tb && mx_json_kind(tb) != MX_JSON_NULL)
        return mx_fail(st, MX_EINPUT, "%s: trained_betas is not supported", what);
    return 0;
}

static int validate(const mx_sched_config *c, const char *what, mx_status *st) {
    if (c->num_train_timesteps < 2 || c->num_train_timesteps > MX_SCHED_MAX_TRAIN)
        return mx_fail(st, MX_EINPUT, "%s: num_train_timesteps %d outside 2..%d", what, c->num_train_timesteps,
                       MX_SCHED_MAX_TRAIN);
    if (!(c->beta_start > 0 && c->beta_end > 0 && c->beta_start < 1 && c->beta_end < 1))
        return mx_fail(st, MX_EINPUT, "%s: betas must lie in (0, 1)", what);
    if (c->solver_order < 1 || c->solver_order > 3)
        return mx_fail(st, MX_EINPUT, "%s: solver_order %d outside 1..3", what, c->solver_order);
    if (c->steps_offset < 0 || c->steps_offset >= c->num_train_timesteps)
        return mx_fail(st, MX_EINPUT, "%s: steps_offset %d out of range", what, c->steps_offset);
    if (c->kind == MX_SCHED_LCM &&
        (c->original_inference_steps < 1 || c->original_inference_steps > c->num_train_timesteps ||
         !(c->timestep_scaling > 0 && c->timestep_scaling < 1e6)))
        return mx_fail(st, MX_EINPUT, "%s: LCM original_inference_steps %d or timestep_scaling %g out of range", what,
                       c->original_inference_steps, c->timestep_scaling);
    return 0;
}

int mx_sched_config_from_json(mx_sched_config *cfg, const mx_json *obj, const char *what, mx_status *st) {
    if (mx_json_kind(obj) != MX_JSON_OBJ)
        return mx_fail(st, MX_EINPUT, "%s: scheduler config is not a JSON object", what);
    const char *cls = mx_json_get_str(obj, "_class_name", "");
    if (strcmp(cls, "DDIMScheduler") == 0) {
        mx_sched_config_sd15_ddim(cfg);
    } else if (strcmp(cls, "LCMScheduler") == 0) {
        mx_sched_config sd15;
        mx_sched_config_sd15(&sd15);
        mx_sched_config_lcm(cfg, &sd15);
    } else {
        mx_sched_config_sd15(cfg);
    }
    if (parse_fields(cfg, obj, what, st)) return -1;
    return validate(cfg, what, st);
}

/* diffusers writes configs with Python's json, which emits the non-standard literal
 * -Infinity (lambda_min_clipped); strict JSON rejects it. Outside strings, [-]Infinity is
 * replaced by an equally long finite number (no option matex reads can be infinite). */
static void replace_python_infinity(char *text, size_t len) {
    int in_string = 0;
    for (size_t i = 0; i < len; i++) {
        if (in_string) {
            if (text[i] == '\\')
                i++;
            else if (text[i] == '"')
                in_string = 0;
        } else if (text[i] == '"') {
            in_string = 1;
        } else if (len - i >= 8 && memcmp(text + i, "Infinity", 8) == 0) {
            memcpy(text + i, "1e308   ", 8);
            i += 7;
        }
    }
}

int mx_sched_config_parse(mx_sched_config *cfg, const char *json_text, size_t len, const char *what,
                          mx_status *st) {
    char *text = malloc(len + 1);
    if (!text) return mx_fail(st, MX_ENOMEM, "%s: out of memory", what);
    memcpy(text, json_text, len);
    text[len] = 0;
    replace_python_infinity(text, len);
    mx_json *root = mx_json_parse(text, len, what, st);
    int rc = root ? mx_sched_config_from_json(cfg, root, what, st) : -1;
    mx_json_free(root);
    free(text);
    return rc;
}

/* ---- training schedule ---- */

/* torch.linspace(a, b, n, dtype=float32) with a, b rounded to float and the steps taken in
 * double: of the variants tried this one matches the reference alphas_cumprod best (bit-equal
 * for t < 700, within 1 ulp after), which keeps every golden timestep exact. */
static float linspace_f32(double a, double b, int n, int i) {
    double fa = (float)a, fb = (float)b;
    return (float)(fa + (fb - fa) / (n - 1) * i);
}

/* betas in float32, then alphas_cumprod = cumprod(1 - betas): torch's CPU cumprod accumulates
 * in double and rounds each output to float. */
static void compute_alphas_cumprod(const mx_sched_config *c, float *acp) {
    int n = c->num_train_timesteps;
    double prod = 1.0;
    for (int i = 0; i < n; i++) {
        float beta;
        if (c->beta_schedule == MX_BETA_SCALED_LINEAR) {
            float r = linspace_f32(sqrt(c->beta_start), sqrt(c->beta_end), n, i);
            beta = r * r;
        } else {
            beta = linspace_f32(c->beta_start, c->beta_end, n, i);
        }
        float alpha = 1.0f - beta;
        prod *= (double)alpha;
        acp[i] = (float)prod;
    }
}

/* VE sigma of a training step, float32 as torch: ((1 - acp) / acp) ** 0.5. */
static float ve_sigma_f32(float acp) { return sqrtf((1.0f - acp) / acp); }

/* ---- timesteps ---- */

/* DPM-Solver++ spacing (set_timesteps). Returns the count written. */
static int dpm_timesteps(const mx_sched_config *c, int steps, int64_t *ts) {
    int last = c->num_train_timesteps; /* lambda_min_clipped = -inf: nothing clipped */
    if (c->timestep_spacing == MX_SPACING_LINSPACE) {
        /* np.linspace(0, last-1, steps+1).round()[::-1][:-1] */
        double stepd = (double)(last - 1) / steps;
        for (int k = 0; k < steps; k++) {
            int i = steps - k;
            double v = i == steps ? (double)(last - 1) : (double)i * stepd;
            ts[k] = (int64_t)nearbyint(v);
        }
        return steps;
    }
    if (c->timestep_spacing == MX_SPACING_LEADING) {
        int ratio = last / (steps + 1);
        for (int k = 0; k < steps; k++) ts[k] = (int64_t)(steps - k) * ratio + c->steps_offset;
        return steps;
    }
    /* trailing: np.arange(last, 0, -ratio).round() - 1 */
    double ratio = (double)c->num_train_timesteps / steps;
    int n = (int)ceil((double)last / ratio);
    if (n > steps) n = steps;
    for (int k = 0; k < n; k++) ts[k] = (int64_t)nearbyint((double)last - k * ratio) - 1;
    return n;
}

/* DDIM spacing (DDIMScheduler.set_timesteps). */
static int ddim_timesteps(const mx_sched_config *c, int steps, int64_t *ts) {
    int n_train = c->num_train_timesteps;
    if (c->timestep_spacing == MX_SPACING_LINSPACE) {
        double stepd = steps > 1 ? (double)(n_train - 1) / (steps - 1) : 0.0;
        for (int k = 0; k < steps; k++) {
            int i = steps - 1 - k;
            double v = (steps > 1 && i == steps - 1) ? (double)(n_train - 1) : (double)i * stepd;
            ts[k] = (int64_t)nearbyint(v);
        }
        return steps;
    }
    if (c->timestep_spacing == MX_SPACING_LEADING) {
        int ratio = n_train / steps;
        for (int k = 0; k < steps; k++) ts[k] = (int64_t)(steps - 1 - k) * ratio + c->steps_offset;
        return steps;
    }
    double ratio = (double)n_train / steps;
    for (int k = 0; k < steps; k++) ts[k] = (int64_t)nearbyint((double)n_train - k * ratio) - 1;
    return steps;
}

/* diffusers' _sigma_to_t: piecewise-linear inverse of log-sigma over the training steps. */
static double sigma_to_t(double sigma, const float *log_sigmas, int n) {
    double ls = log(fmax(sigma, 1e-10));
    int count = 0, low = 0;
    /* argmax of cumsum(dists >= 0): the last index where the running count reaches its max */
    int best = -1;
    for (int i = 0; i < n; i++) {
        if (ls - (double)log_sigmas[i] >= 0) count++;
        if (count > best) {
            best = count;
            low = i;
        }
    }
    if (low > n - 2) low = n - 2;
    double lo = log_sigmas[low], hi = log_sigmas[low + 1];
    double w = (lo - ls) / (lo - hi);
    w = w < 0 ? 0 : (w > 1 ? 1 : w);
    return (1 - w) * low + w * (low + 1);
}

/* Karras et al. sigmas between the training schedule's extremes, rho = 7. */
static void karras_sigmas(const float *train_sigmas, int n_train, int steps, double *out) {
    double smin = train_sigmas[0], smax = train_sigmas[n_train - 1];
    double rho = 7.0, lo = pow(smin, 1.0 / rho), hi = pow(smax, 1.0 / rho);
    for (int i = 0; i < steps; i++) {
        double ramp = steps > 1 ? (double)i / (steps - 1) : 0.0;
        out[i] = pow(hi + ramp * (lo - hi), rho);
    }
}

static int dpm_schedule(mx_sched *s, int steps, mx_status *st) {
    const mx_sched_config *c = &s->cfg;
    int n_train = c->num_train_timesteps;
    float *train_sigmas = malloc(sizeof(float) * (size_t)n_train * 2);
    double *ks = malloc(sizeof(double) * (size_t)steps);
    if (!train_sigmas || !ks) {
        free(train_sigmas);
        free(ks);
        return mx_fail(st, MX_ENOMEM, "scheduler: out of memory");
    }
    float *log_sigmas = train_sigmas + n_train;
    for (int i = 0; i < n_train; i++) {
        train_sigmas[i] = ve_sigma_f32(s->alphas_cumprod[i]);
        log_sigmas[i] = logf(train_sigmas[i]);
    }
    if (c->use_karras_sigmas) {
        karras_sigmas(train_sigmas, n_train, steps, ks);
        for (int i = 0; i < steps; i++) {
            s->timesteps[i] = (int64_t)nearbyint(sigma_to_t(ks[i], log_sigmas, n_train));
            s->sigmas[i] = (float)ks[i];
        }
        s->n_steps = steps;
    } else {
        s->n_steps = dpm_timesteps(c, steps, s->timesteps);
        for (int i = 0; i < s->n_steps; i++) {
            int64_t t = s->timesteps[i];
            s->sigmas[i] = (t >= 0 && t < n_train) ? train_sigmas[t] : train_sigmas[t < 0 ? 0 : n_train - 1];
        }
    }
    s->sigmas[s->n_steps] = c->final_sigmas_type == MX_FINAL_SIGMA_MIN ? train_sigmas[0] : 0.0f;
    free(train_sigmas);
    free(ks);
    return 0;
}

int mx_sched_init(mx_sched *s, const mx_ctx *c, const mx_sched_config *cfg, int num_inference_steps,
                  size_t numel, mx_status *st) {
    memset(s, 0, sizeof *s);
    s->c = c;
    if (validate(cfg, "scheduler", st)) return -1;
    if (num_inference_steps < 1 || num_inference_steps > MX_SCHED_MAX_STEPS ||
        num_inference_steps > cfg->num_train_timesteps)
        return mx_fail(st, MX_EUSAGE, "scheduler: %d steps outside 1..%d", num_inference_steps,
                       cfg->num_train_timesteps < MX_SCHED_MAX_STEPS ? cfg->num_train_timesteps : MX_SCHED_MAX_STEPS);
    if (numel == 0 || numel > ((size_t)1 << 40)) return mx_fail(st, MX_EUSAGE, "scheduler: bad latent size");
    s->cfg = *cfg;
    s->num_inference_steps = num_inference_steps;
    compute_alphas_cumprod(cfg, s->alphas_cumprod);
    if (cfg->kind == MX_SCHED_DDIM) {
        s->n_steps = ddim_timesteps(cfg, num_inference_steps, s->timesteps);
    } else if (cfg->kind == MX_SCHED_LCM) {
        if ((s->n_steps = mx_sched_lcm_timesteps(cfg, num_inference_steps, s->timesteps, st)) < 0) return -1;
    } else if (dpm_schedule(s, num_inference_steps, st)) {
        return -1;
    }
    s->numel = numel;
    size_t noise_steps = cfg->kind == MX_SCHED_LCM ? (size_t)s->n_steps - 1 : 0; /* the last step draws none */
    s->buf = mx_dev_alloc(c, numel * (5 + noise_steps), st);
    if (!s->buf) return mx_fail_prefix(st, "scheduler: %zu latents", numel);
    for (int i = 0; i < 3; i++) s->model_outputs[i] = s->buf + (size_t)i * numel;
    s->work[0] = s->buf + 3 * numel;
    s->work[1] = s->buf + 4 * numel;
    s->noise_dev = s->buf + 5 * numel;
    if (noise_steps && !(s->noise_host = malloc(noise_steps * numel * sizeof(float))))
        return mx_fail(st, MX_ENOMEM, "scheduler: out of memory for %zu noise values", noise_steps * numel);
    return 0;
}

void mx_sched_free(mx_sched *s) {
    mx_dev_free(s->c, s->buf);
    free(s->noise_host);
    s->buf = NULL;
    s->noise_host = NULL;
}

int mx_sched_set_strength(mx_sched *s, float strength, mx_status *st) {
    if (!(strength >= 0.0f && strength <= 1.0f))
        return mx_fail(st, MX_EUSAGE, "scheduler: strength %g outside [0, 1]", (double)strength);
    if (s->step_index != s->begin) return mx_fail(st, MX_EUSAGE, "scheduler: strength set after stepping");
    int init = (int)((float)s->num_inference_steps * strength);
    if (init > s->num_inference_steps) init = s->num_inference_steps;
    int t_start = s->num_inference_steps - init;
    if (t_start < 0) t_start = 0;
    if (t_start > s->n_steps) t_start = s->n_steps;
    s->begin = s->step_index = t_start;
    s->noise_ready = 0; /* drawn for the steps now left */
    return 0;
}

int mx_sched_steps(const mx_sched *s) { return s->n_steps - s->begin; }
int64_t mx_sched_timestep(const mx_sched *s, int i) { return s->timesteps[s->begin + i]; }
float mx_sched_init_noise_sigma(const mx_sched *s) {
    (void)s;
    return 1.0f;
}

/* ---- DPM-Solver++ step ---- */

/* diffusers' _sigma_to_alpha_sigma_t and lambda = log(alpha) - log(sigma), in float32. */
typedef struct dpm_point {
    float alpha, sigma, lambda;
} dpm_point;

static dpm_point dpm_point_at(float ve_sigma) {
    dpm_point p;
    p.alpha = 1.0f / sqrtf(ve_sigma * ve_sigma + 1.0f);
    p.sigma = ve_sigma * p.alpha;
    p.lambda = logf(p.alpha) - logf(p.sigma);
    return p;
}

/* The step arithmetic runs as ops on the scheduler's context (its history lives on that
 * backend); each op sequence evaluates the same float32 expression as diffusers, term by term. */
static void lin2(const mx_sched *s, float *y, float a, const float *x0, float b, const float *x1) {
    const float coef[2] = {a, b};
    const float *const x[2] = {x0, x1};
    mx_lincomb(s->c, y, 2, coef, x, s->numel);
}

/* x0 prediction from the model output at the current step. */
static void dpm_convert(const mx_sched *s, const float *mo, const float *x, float *x0) {
    dpm_point p = dpm_point_at(s->sigmas[s->step_index]);
    switch (s->cfg.prediction_type) {
    case MX_PRED_EPSILON: lin2(s, x0, 1.0f / p.alpha, x, -p.sigma / p.alpha, mo); break;
    case MX_PRED_V: lin2(s, x0, p.alpha, x, -p.sigma, mo); break;
    case MX_PRED_SAMPLE: mx_copy(s->c, x0, mo, s->numel); break;
    }
}

static void dpm_first_order(const mx_sched *s, float *x) {
    dpm_point t = dpm_point_at(s->sigmas[s->step_index + 1]);
    dpm_point s0 = dpm_point_at(s->sigmas[s->step_index]);
    float h = t.lambda - s0.lambda;
    float a = t.sigma / s0.sigma, b = t.alpha * (expf(-h) - 1.0f);
    lin2(s, x, a, x, -b, s->model_outputs[2]);
}

/* d = k·(p − q) into d. */
static void scaled_diff(const mx_sched *s, float *d, const float *p, const float *q, float k) {
    int64_t shape[1] = {(int64_t)s->numel};
    mx_binary(s->c, MX_BIN_SUB, d, p, shape, q, shape, 1);
    mx_scale(s->c, d, d, k, s->numel);
}

static void dpm_second_order(const mx_sched *s, float *x) {
    dpm_point t = dpm_point_at(s->sigmas[s->step_index + 1]);
    dpm_point s0 = dpm_point_at(s->sigmas[s->step_index]);
    dpm_point s1 = dpm_point_at(s->sigmas[s->step_index - 1]);
    float h = t.lambda - s0.lambda, h0 = s0.lambda - s1.lambda;
    float r0 = h0 / h, inv_r0 = 1.0f / r0;
    float a = t.sigma / s0.sigma, b = t.alpha * (expf(-h) - 1.0f);
    /* midpoint: - 0.5 b D1; heun: + alpha (e^-h - 1)/h + 1) D1 */
    float c = s->cfg.solver_type == MX_SOLVER_MIDPOINT ? -(0.5f * b) : t.alpha * ((expf(-h) - 1.0f) / h + 1.0f);
    const float *m0 = s->model_outputs[2], *m1 = s->model_outputs[1];
    float *d1 = s->work[0];
    scaled_diff(s, d1, m0, m1, inv_r0);
    const float coef[3] = {a, -b, c};
    const float *const terms[3] = {x, m0, d1};
    mx_lincomb(s->c, x, 3, coef, terms, s->numel);
}

static void dpm_third_order(const mx_sched *s, float *x) {
    dpm_point t = dpm_point_at(s->sigmas[s->step_index + 1]);
    dpm_point s0 = dpm_point_at(s->sigmas[s->step_index]);
    dpm_point s1 = dpm_point_at(s->sigmas[s->step_index - 1]);
    dpm_point s2 = dpm_point_at(s->sigmas[s->step_index - 2]);
    float h = t.lambda - s0.lambda, h0 = s0.lambda - s1.lambda, h1 = s1.lambda - s2.lambda;
    float r0 = h0 / h, r1 = h1 / h;
    float a = t.sigma / s0.sigma, em = expf(-h) - 1.0f;
    float b = t.alpha * em, c1 = t.alpha * (em / h + 1.0f), c2 = t.alpha * ((em + h) / (h * h) - 0.5f);
    float k0 = 1.0f / r0, k1 = 1.0f / r1, k2 = r0 / (r0 + r1), k3 = 1.0f / (r0 + r1);
    const float *m0 = s->model_outputs[2], *m1 = s->model_outputs[1], *m2 = s->model_outputs[0];
    float *d1 = s->work[0], *d2 = s->work[1];
    int64_t shape[1] = {(int64_t)s->numel};
    scaled_diff(s, d1, m0, m1, k0);                           /* d10 */
    scaled_diff(s, d2, m1, m2, k1);                           /* d11 */
    mx_binary(s->c, MX_BIN_SUB, d2, d1, shape, d2, shape, 1); /* d10 - d11 */
    mx_axpy(s->c, d1, d2, k2, s->numel);                      /* d1 = d10 + k2 (d10 - d11) */
    mx_scale(s->c, d2, d2, k3, s->numel);                     /* d2 = k3 (d10 - d11) */
    const float coef[4] = {a, -b, c1, -c2};
    const float *const terms[4] = {x, m0, d1, d2};
    mx_lincomb(s->c, x, 4, coef, terms, s->numel);
}

static int dpm_step(mx_sched *s, const float *mo, float *x) {
    const mx_sched_config *c = &s->cfg;
    int last = s->n_steps - 1;
    int lower_final = s->step_index == last &&
                      (c->euler_at_final || (c->lower_order_final && s->n_steps < 15) ||
                       c->final_sigmas_type == MX_FINAL_SIGMA_ZERO);
    int lower_second = s->step_index == last - 1 && c->lower_order_final && s->n_steps < 15;
    /* rotate the history: model_outputs[2] is the newest */
    float *oldest = s->model_outputs[0];
    s->model_outputs[0] = s->model_outputs[1];
    s->model_outputs[1] = s->model_outputs[2];
    s->model_outputs[2] = oldest;
    dpm_convert(s, mo, x, s->model_outputs[2]);
    if (c->solver_order == 1 || s->lower_order_nums < 1 || lower_final)
        dpm_first_order(s, x);
    else if (c->solver_order == 2 || s->lower_order_nums < 2 || lower_second)
        dpm_second_order(s, x);
    else
        dpm_third_order(s, x);
    if (s->lower_order_nums < c->solver_order) s->lower_order_nums++;
    return 0;
}

/* ---- DDIM step (eta 0) ---- */

static void ddim_step(mx_sched *s, const float *mo, float *x) {
    const mx_sched_config *c = &s->cfg;
    int64_t t = s->timesteps[s->step_index];
    int64_t prev = t - c->num_train_timesteps / s->num_inference_steps;
    float at = s->alphas_cumprod[t];
    float ap = prev >= 0 ? s->alphas_cumprod[prev] : (c->set_alpha_to_one ? 1.0f : s->alphas_cumprod[0]);
    float bt = 1.0f - at;
    float sa = sqrtf(at), sb = sqrtf(bt), sap = sqrtf(ap), dir = sqrtf(1.0f - ap);
    float lim = (float)c->clip_sample_range;
    float *x0 = s->work[0], *eps = s->work[1];
    const float *e = eps;
    switch (c->prediction_type) {
    case MX_PRED_EPSILON:
        lin2(s, x0, 1.0f / sa, x, -sb / sa, mo);
        e = mo;
        break;
    case MX_PRED_V:
        lin2(s, x0, sa, x, -sb, mo);
        lin2(s, eps, sa, mo, sb, x);
        break;
    default:
        mx_copy(s->c, x0, mo, s->numel);
        lin2(s, eps, 1.0f / sb, x, -sa / sb, x0);
        break;
    }
    if (c->clip_sample) mx_clamp(s->c, x0, x0, -lim, lim, s->numel);
    lin2(s, x, sap, x0, dir, e);
}

int mx_sched_step(mx_sched *s, const float *model_output, float *sample, mx_status *st) {
    if (s->step_index >= s->n_steps)
        return mx_fail(st, MX_EUSAGE, "scheduler: step %d past the last of %d", s->step_index, s->n_steps);
    int64_t t = s->timesteps[s->step_index];
    if (t < 0 || t >= s->cfg.num_train_timesteps)
        return mx_fail(st, MX_EINTERNAL, "scheduler: timestep %lld out of range", (long long)t);
    if (s->cfg.kind == MX_SCHED_LCM) return mx_sched_lcm_step(s, model_output, sample, st);
    if (s->cfg.kind == MX_SCHED_DDIM)
        ddim_step(s, model_output, sample);
    else
        dpm_step(s, model_output, sample);
    s->step_index++;
    return 0;
}

void mx_sched_noise_coeffs(const mx_sched *s, float *a, float *b) {
    int i = s->step_index < s->n_steps ? s->step_index : s->n_steps - 1;
    if (s->cfg.kind == MX_SCHED_DDIM || s->cfg.kind == MX_SCHED_LCM) {
        float acp = s->alphas_cumprod[s->timesteps[i]];
        *a = sqrtf(acp);
        *b = sqrtf(1.0f - acp);
    } else {
        dpm_point p = dpm_point_at(s->sigmas[i]);
        *a = p.alpha;
        *b = p.sigma;
    }
}

void mx_sched_add_noise(const mx_sched *s, float *y, const float *x0, const float *noise, size_t n) {
    float a, b;
    mx_sched_noise_coeffs(s, &a, &b);
    for (size_t k = 0; k < n; k++) y[k] = a * x0[k] + b * noise[k];
}

void mx_sched_scale_initial(const mx_sched *s, float *lat, size_t n) {
    float sigma = mx_sched_init_noise_sigma(s);
    for (size_t k = 0; k < n; k++) lat[k] *= sigma;
}
