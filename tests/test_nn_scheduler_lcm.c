/* LCMScheduler against diffusers (golden/scheduler_lcm: 4 and 6 steps, fixed model outputs, the
 * noise of each step given): timesteps exactly equal, samples and denoised predictions after every
 * step <= 1e-5 rel L2, also with every step's noise drawn before the first (mx_sched_prepare); plus the
 * config parse and the misuse errors. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/scheduler.h"
#include "nn_golden.h"

static void sd15_lcm(mx_sched_config *cfg) {
    mx_sched_config base;
    mx_sched_config_sd15(&base);
    mx_sched_config_lcm(cfg, &base);
}

/* The noise source of a case: noises[step]. */
static int give_noise(void *user, int step, float *noise, size_t numel) {
    memcpy(noise, (const float *)user + (size_t)step * numel, numel * sizeof *noise);
    return 0;
}

/* A noise source that has none: after mx_sched_prepare no step may ask for noise. */
static int refuse_noise(void *user, int step, float *noise, size_t numel) {
    (void)user, (void)step, (void)noise, (void)numel;
    return -1;
}

/* Host-memory scheduler (context NULL), as test_nn_scheduler. prepared: every step's noise drawn by
 * mx_sched_prepare before the first step (as the denoising loop does), the source refusing after it. */
static void run_case(const mx_safetensors *f, const char *name, int steps, int prepared) {
    char key[64], label[128];
    mx_status st;
    size_t n_lat, n_mo, n_noise, n_after, n_den, n_ts;
#define LOAD(var, leaf, cnt) snprintf(key, sizeof key, "%s.%s", name, leaf), var = golden_f32(f, key, cnt)
    float *ts, *x, *mo, *noise, *after, *den;
    LOAD(ts, "timesteps", &n_ts);
    LOAD(x, "x_T", &n_lat);
    LOAD(mo, "model_outputs", &n_mo);
    LOAD(noise, "noises", &n_noise);
    LOAD(after, "samples_after_step", &n_after);
    LOAD(den, "denoised", &n_den);
#undef LOAD
    mx_sched_config cfg;
    mx_sched s;
    sd15_lcm(&cfg);
    int ok = ts && x && mo && noise && after && den && n_ts == (size_t)steps && n_mo == steps * n_lat &&
             n_noise == (steps - 1) * n_lat && n_after == n_mo && n_den == n_mo && !mx_sched_init(&s, NULL, &cfg, steps, n_lat, &st);
    CHECK(ok);
    if (ok) {
        int equal = mx_sched_steps(&s) == steps;
        for (int i = 0; equal && i < steps; i++) equal = (float)mx_sched_timestep(&s, i) == ts[i];
        printf("%-40s %s\n", name, equal ? "timesteps equal" : "timesteps DIFFER");
        CHECK(equal);
        double worst_x = 0, worst_d = 0;
        s.noise_fn = give_noise;
        s.noise_user = noise;
        if (prepared) {
            CHECK(mx_sched_prepare(&s, &st) == 0);
            s.noise_fn = refuse_noise; /* a step that still draws its own noise fails */
        }
        for (int i = 0; equal && i < steps; i++) {
            CHECK(mx_sched_needs_noise(&s) == (i < steps - 1));
            if (mx_sched_step(&s, mo + (size_t)i * n_lat, x, &st)) {
                fprintf(stderr, "%s\n", st.msg);
                CHECK(0);
                break;
            }
            double ex = mx_rel_l2(x, after + (size_t)i * n_lat, n_lat), ed = mx_rel_l2(s.work[0], den + (size_t)i * n_lat, n_lat);
            if (!(ex <= worst_x)) worst_x = ex;
            if (!(ed <= worst_d)) worst_d = ed;
        }
        snprintf(label, sizeof label, "%s%s samples (worst step)", name, prepared ? " prepared" : "");
        printf("%-40s rel_l2=%.3e (bound 1e-05) %s\n", label, worst_x, worst_x <= 1e-5 ? "ok" : "FAIL");
        snprintf(label, sizeof label, "%s%s denoised (worst step)", name, prepared ? " prepared" : "");
        printf("%-40s rel_l2=%.3e (bound 1e-05) %s\n", label, worst_d, worst_d <= 1e-5 ? "ok" : "FAIL");
        CHECK(worst_x <= 1e-5 && worst_d <= 1e-5);
        CHECK(mx_sched_step(&s, mo, x, &st) == -1 && strstr(st.msg, "past the last"));
        mx_sched_free(&s);
    }
    free(ts);
    free(x);
    free(mo);
    free(noise);
    free(after);
    free(den);
}

static void test_config_and_errors(void) {
    mx_sched_config cfg;
    mx_status st;
    const char *json = "{\"_class_name\": \"LCMScheduler\", \"beta_start\": 0.00085, \"beta_end\": 0.012, "
                       "\"original_inference_steps\": 40, \"timestep_scaling\": 5.0}";
    CHECK(mx_sched_config_parse(&cfg, json, strlen(json), "lcm json", &st) == 0);
    CHECK(cfg.kind == MX_SCHED_LCM && cfg.original_inference_steps == 40 && cfg.timestep_scaling == 5.0);
    int64_t ts[8];
    CHECK(mx_sched_lcm_timesteps(&cfg, 4, ts, &st) == 4 && ts[0] == 999 && ts[1] == 749); /* k = 25 */
    sd15_lcm(&cfg);
    mx_sched s;
    CHECK(mx_sched_init(&s, NULL, &cfg, 51, 16, &st) == -1 && strstr(st.msg, "original_inference_steps"));
    CHECK(mx_sched_init(&s, NULL, &cfg, 4, 16, &st) == 0);
    float mo[16] = {0}, x[16] = {0};
    CHECK(mx_sched_step(&s, mo, x, &st) == -1 && strstr(st.msg, "noise source"));
    mx_sched_free(&s);
}

/* img2img strength as diffusers' img2img/inpaint pipelines apply it to LCMScheduler: its 4-step list
 * [999, 759, 499, 259], then get_timesteps keeps the last int(4 * strength) with set_begin_index;
 * the step noise is asked from step 0 on, and the last kept step returns the denoised sample. */
static void test_strength(void) {
    mx_sched_config cfg;
    mx_status st;
    mx_sched s;
    sd15_lcm(&cfg);
    static const struct {
        float strength;
        int steps;
        int64_t first;
    } cases[] = {{0.5f, 2, 499}, {0.55f, 2, 499}, {0.3f, 1, 259}, {1.0f, 4, 999}, {0.75f, 3, 759}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        CHECK(mx_sched_init(&s, NULL, &cfg, 4, 4, &st) == 0);
        CHECK(mx_sched_set_strength(&s, cases[k].strength, &st) == 0);
        CHECK(mx_sched_steps(&s) == cases[k].steps && mx_sched_timestep(&s, 0) == cases[k].first);
        CHECK(mx_sched_timestep(&s, mx_sched_steps(&s) - 1) == 259);
        float noise[3 * 4] = {0}, mo[4] = {0}, x[4] = {1, 1, 1, 1}; /* noise: steps 0..2 */
        s.noise_fn = give_noise;
        s.noise_user = noise;
        CHECK(mx_sched_prepare(&s, &st) == 0); /* the steps left after the strength cut */
        s.noise_fn = refuse_noise;
        for (int i = 0; i < cases[k].steps; i++) CHECK(mx_sched_step(&s, mo, x, &st) == 0);
        CHECK(mx_sched_step(&s, mo, x, &st) == -1); /* past the last */
        mx_sched_free(&s);
    }
}

int main(void) {
    mx_safetensors f;
    CHECK(golden_open(&f, "scheduler_lcm", "cases.safetensors") == 0);
    run_case(&f, "steps4", 4, 0);
    run_case(&f, "steps6", 6, 0);
    run_case(&f, "steps4", 4, 1);
    run_case(&f, "steps6", 6, 1);
    mx_st_close(&f);
    test_config_and_errors();
    test_strength();
    return mx_test_finish("test_nn_scheduler_lcm");
}
