/* Samplers over the SD1.5 noise schedule, as diffusers 0.35.2: DPMSolverMultistepScheduler
 * (algorithm "dpmsolver++", orders 1-3, midpoint/heun, lower_order_final, euler_at_final,
 * Karras sigmas, final sigma zero/sigma_min, linspace/leading/trailing spacing, epsilon and
 * v-prediction) and DDIMScheduler (eta 0). The training schedule is computed in float32 as
 * torch does (betas = linspace(sqrt(b0), sqrt(b1))^2, cumulative product in float32), so
 * the integer timesteps equal the reference exactly.
 *
 * Use: mx_sched_init(&s, ctx, &cfg, steps, numel); for i in 0..mx_sched_steps(&s): run the model
 * at timestep mx_sched_timestep(&s, i), then mx_sched_step(&s, eps, latents). The step runs as ops
 * on ctx: eps, latents and the history are memory of ctx's backend.
 *
 * LCMScheduler (scheduler_lcm.c) shares the schedule and this state; its steps draw fresh noise
 * from s->noise_fn (matex's seeded generator, or given noise in tests). */
#ifndef MX_SCHEDULER_H
#define MX_SCHEDULER_H

#include <stddef.h>
#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"

#define MX_SCHED_MAX_TRAIN 4000
#define MX_SCHED_MAX_STEPS 1000

typedef enum { MX_SCHED_DPMPP = 0, MX_SCHED_DDIM = 1, MX_SCHED_LCM = 2 } mx_sched_kind;
typedef enum { MX_BETA_SCALED_LINEAR = 0, MX_BETA_LINEAR = 1 } mx_beta_schedule;
typedef enum { MX_PRED_EPSILON = 0, MX_PRED_V = 1, MX_PRED_SAMPLE = 2 } mx_prediction;
typedef enum { MX_SOLVER_MIDPOINT = 0, MX_SOLVER_HEUN = 1 } mx_solver_type;
typedef enum { MX_SPACING_LINSPACE = 0, MX_SPACING_LEADING = 1, MX_SPACING_TRAILING = 2 } mx_spacing;
typedef enum { MX_FINAL_SIGMA_ZERO = 0, MX_FINAL_SIGMA_MIN = 1 } mx_final_sigma;

typedef struct mx_sched_config {
    mx_sched_kind kind;
    int num_train_timesteps;  /* 1000 */
    double beta_start;        /* 0.00085 */
    double beta_end;          /* 0.012 */
    mx_beta_schedule beta_schedule;
    mx_prediction prediction_type;
    mx_spacing timestep_spacing;
    int steps_offset;         /* 1 for SD1.5 */
    /* DPM-Solver++ */
    int solver_order;         /* 1..3, default 2 */
    mx_solver_type solver_type;
    int lower_order_final;    /* 1 */
    int euler_at_final;       /* 0 */
    int use_karras_sigmas;    /* 0 */
    mx_final_sigma final_sigmas_type;
    /* DDIM */
    int set_alpha_to_one;     /* SD1.5 scheduler_config: 0 */
    int clip_sample;          /* SD1.5: 0 */
    double clip_sample_range; /* 1.0 */
    /* LCM (scheduler_lcm.c) */
    int original_inference_steps; /* 50 */
    double timestep_scaling;      /* 10.0 */
} mx_sched_config;

/* DPM-Solver++ (2M) with the SD1.5 schedule: the matex default. */
void mx_sched_config_sd15(mx_sched_config *cfg);
/* DDIM (eta 0) with the SD1.5 schedule. */
void mx_sched_config_sd15_ddim(mx_sched_config *cfg);
/* LCMScheduler (the few-step sampler of an LCM-LoRA) over the training schedule of base
 * (betas, train steps, offset): original_inference_steps 50, timestep_scaling 10, epsilon. */
void mx_sched_config_lcm(mx_sched_config *cfg, const mx_sched_config *base);
/* Parses a diffusers scheduler_config.json text over the SD1.5 defaults; "_class_name"
 * DDIMScheduler selects DDIM, LCMScheduler LCM, anything else DPM-Solver++. Unsupported options (another
 * algorithm_type, thresholding, other sigma kinds) are errors naming `what` and the key. */
int mx_sched_config_parse(mx_sched_config *cfg, const char *json_text, size_t len, const char *what,
                          mx_status *st);
/* The same from an already parsed JSON object (e.g. a member of a manifest). */
struct mx_json;
int mx_sched_config_from_json(mx_sched_config *cfg, const struct mx_json *obj, const char *what, mx_status *st);

/* Fills noise[0..numel) (HOST memory) with the fresh noise of step `step` (0-based among the
 * steps run); returns non-zero on failure. */
typedef int (*mx_sched_noise_fn)(void *user, int step, float *noise, size_t numel);

typedef struct mx_sched {
    mx_sched_config cfg;
    int num_inference_steps;
    int n_steps;                          /* timesteps to run (fewer after mx_sched_set_strength) */
    int begin;                            /* index of the first timestep run (strength) */
    int step_index;                       /* next step, 0-based over the full list */
    int lower_order_nums;
    float alphas_cumprod[MX_SCHED_MAX_TRAIN];
    int64_t timesteps[MX_SCHED_MAX_STEPS];
    float sigmas[MX_SCHED_MAX_STEPS + 1]; /* DPM: VE sigmas, last = final sigma */
    size_t numel;                         /* elements of one latent batch */
    const mx_ctx *c;                      /* the context the step's ops run on */
    float *model_outputs[3];              /* DPM history of converted outputs (x0), newest last */
    float *buf;                           /* backend memory: owns model_outputs and work */
    float *work[2];                       /* LCM: work[0] holds the last step's denoised prediction */
    mx_sched_noise_fn noise_fn;           /* LCM: the fresh noise of a step (set after init) */
    void *noise_user;
    float *noise_host;                    /* LCM: [n_steps - 1][numel] host floats noise_fn fills */
    float *noise_dev;                     /* LCM: their device copy in buf, from step noise_first on */
    int noise_ready, noise_first;         /* LCM: the noise of every step left is on the device */
} mx_sched;

/* Computes the schedule for num_inference_steps and allocates history for latents of numel
 * floats on c's backend (c NULL: host memory, single-threaded ops). c must outlive s. Free with
 * mx_sched_free. */
int mx_sched_init(mx_sched *s, const mx_ctx *c, const mx_sched_config *cfg, int num_inference_steps,
                  size_t numel, mx_status *st);
void mx_sched_free(mx_sched *s);

/* img2img / SDEdit start: keeps the last min(floor(steps*strength), steps) timesteps, as the
 * diffusers img2img pipelines (strength 1 = all steps, 0 = none). Call before the first step. */
int mx_sched_set_strength(mx_sched *s, float strength, mx_status *st);

/* Timesteps left to run and the i-th of them (0 <= i < mx_sched_steps). */
int mx_sched_steps(const mx_sched *s);
int64_t mx_sched_timestep(const mx_sched *s, int i);
/* Scale of the initial noise (1.0 for both samplers here). */
float mx_sched_init_noise_sigma(const mx_sched *s);

/* Before the first step (after mx_sched_set_strength and setting noise_fn): what the steps take
 * from the host goes to the device at once — LCM: the fresh noise of every step left, one upload —
 * so that no step waits on a host copy (the denoising loop calls it; a step does it itself when
 * it was not called). Nothing for the other samplers. */
int mx_sched_prepare(mx_sched *s, mx_status *st);

/* One step: sample (numel floats, backend memory) is replaced by the previous sample given the
 * model output (epsilon, v or x0 per prediction_type) at the current timestep. */
int mx_sched_step(mx_sched *s, const float *model_output, float *sample, mx_status *st);

/* LCM (scheduler_lcm.c): 1 when the next step draws fresh noise (every step but the last); the
 * timesteps of LCMScheduler.set_timesteps (strength 1), the count or -1; mx_sched_step's LCM case. */
int mx_sched_needs_noise(const mx_sched *s);
int mx_sched_lcm_timesteps(const mx_sched_config *cfg, int steps, int64_t *ts, mx_status *st);
int mx_sched_lcm_step(mx_sched *s, const float *model_output, float *sample, mx_status *st);

/* Start latents, on HOST arrays before they enter the denoise loop:
 * noising for the first timestep still to run (SDEdit): y = a·x0 + b·noise with
 * a = sqrt(acp[t]), b = sqrt(1-acp[t]) for DDIM and a = 1/sqrt(sigma^2+1), b = sigma·a
 * for DPM-Solver++ (sigma of the current step), as diffusers' add_noise. y may equal x0 or noise. */
void mx_sched_add_noise(const mx_sched *s, float *y, const float *x0, const float *noise, size_t n);
/* The a, b of mx_sched_add_noise at the current step (the inpaint pipeline noises the known
 * latents with them on the device after every step). */
void mx_sched_noise_coeffs(const mx_sched *s, float *a, float *b);
/* lat *= the initial noise sigma (text-to-image start). */
void mx_sched_scale_initial(const mx_sched *s, float *lat, size_t n);

#endif
