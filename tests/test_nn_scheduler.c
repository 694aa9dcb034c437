/* DPM-Solver++ against diffusers: every case of golden/scheduler_dpmsolver_multistep (timesteps
 * exactly equal, sigmas and alphas_cumprod close, latents after every step ≤ 1e-5 rel L2), and
 * DDIM / strength / add_noise / CFG properties that follow from their definitions. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/scheduler.h"
#include "../runtime/fileio.h"
#include "../runtime/json.h"
#include "../weights/safetensors.h"
#include "util_test.h"


static float *load_f32(const mx_safetensors *sf, const char *name, size_t *numel) {
    mx_status st = {0};
    const mx_st_tensor *t = mx_st_find(sf, name);
    if (!t) {
        fprintf(stderr, "%s: no tensor %s\n", sf->path, name);
        return NULL;
    }
    size_t n = 1;
    for (int i = 0; i < t->ndim; i++) n *= (size_t)t->shape[i];
    float *p = mx_st_to_f32(sf, t, &st);
    if (!p) fprintf(stderr, "%s\n", st.msg);
    if (numel) *numel = n;
    return p;
}

/* Runs one golden case: set_timesteps(N), then step(model_outputs[i]) from initial_latents. */
static void run_case(const char *dir, const char *name, const mx_json *c) {
    char path[2200], label[256];
    mx_status st = {0};
    mx_sched_config cfg;
    int steps = (int)mx_json_get_num(c, "num_inference_steps", 0);
    snprintf(label, sizeof label, "%s config", name);
    if (mx_sched_config_from_json(&cfg, mx_json_get(c, "config"), label, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    snprintf(path, sizeof path, "%s/%s.safetensors", dir, name);
    mx_safetensors sf;
    if (mx_st_open(&sf, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    size_t n_ts, n_sig, n_acp, n_lat, n_mo, n_after;
    float *ts = load_f32(&sf, "timesteps", &n_ts);
    float *sig = load_f32(&sf, "sigmas", &n_sig);
    float *acp = load_f32(&sf, "alphas_cumprod", &n_acp);
    float *lat = load_f32(&sf, "initial_latents", &n_lat);
    float *mo = load_f32(&sf, "model_outputs", &n_mo);
    float *after = load_f32(&sf, "latents_after_step", &n_after);
    mx_sched s;
    int ok = ts && sig && acp && lat && mo && after && mx_sched_init(&s, NULL, &cfg, steps, n_lat, &st) == 0;
    CHECK(ok);
    if (!ok) {
        fprintf(stderr, "%s: %s\n", name, st.msg);
        goto done;
    }
    CHECK((size_t)mx_sched_steps(&s) == n_ts);
    int ts_equal = (size_t)mx_sched_steps(&s) == n_ts;
    for (size_t i = 0; ts_equal && i < n_ts; i++) ts_equal = (float)mx_sched_timestep(&s, (int)i) == ts[i];
    printf("%-48s %s\n", name, ts_equal ? "timesteps equal" : "timesteps DIFFER");
    CHECK(ts_equal);
    snprintf(label, sizeof label, "%s alphas_cumprod", name);
    mx_check_close(label, s.alphas_cumprod, acp, n_acp, 1e-7);
    snprintf(label, sizeof label, "%s sigmas", name);
    CHECK(n_sig == (size_t)s.n_steps + 1);
    if (n_sig == (size_t)s.n_steps + 1) mx_check_close(label, s.sigmas, sig, n_sig, 1e-6);
    if (!ts_equal || n_mo != n_ts * n_lat || n_after != n_ts * n_lat) {
        CHECK(0);
        mx_sched_free(&s);
        goto done;
    }
    double worst = 0;
    for (size_t i = 0; i < n_ts; i++) {
        if (mx_sched_step(&s, mo + i * n_lat, lat, &st)) {
            fprintf(stderr, "%s\n", st.msg);
            CHECK(0);
            break;
        }
        double e = mx_rel_l2(lat, after + i * n_lat, n_lat);
        if (!(e <= worst)) worst = e;
    }
    snprintf(label, sizeof label, "%s latents (worst step)", name);
    printf("%-48s rel_l2=%.3e (bound 1e-05) %s\n", label, worst, worst <= 1e-5 ? "ok" : "FAIL");
    CHECK(worst <= 1e-5);
    mx_sched_free(&s);
done:
    free(ts);
    free(sig);
    free(acp);
    free(lat);
    free(mo);
    free(after);
    mx_st_close(&sf);
}

/* Python's json writes -Infinity (lambda_min_clipped), which strict RFC 8259 rejects: replace
 * it in place by an equally long finite number (the value is not used by matex). */
static void replace_infinity(char *text) {
    for (char *p = strstr(text, "-Infinity"); p; p = strstr(p, "-Infinity")) memcpy(p, "-1e308   ", 9);
}

static void test_golden_cases(void) {
    char dir[1024], path[1100];
    mx_test_path(dir, sizeof dir, "golden/scheduler_dpmsolver_multistep");
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    size_t len;
    char *text = mx_read_file(path, (size_t)1 << 30, &len, NULL);
    CHECK(text != NULL);
    if (!text) return;
    replace_infinity(text);
    mx_status st = {0};
    mx_json *root = mx_json_parse(text, len, path, &st);
    CHECK(root != NULL);
    const mx_json *cases = mx_json_get(root, "cases");
    CHECK(mx_json_len(cases) == 9);
    for (size_t i = 0; i < mx_json_len(cases); i++) run_case(dir, mx_json_key(cases, i), mx_json_at(cases, i));
    mx_json_free(root);
    free(text);
}

/* DDIM with the SD1.5 DDIM config: leading timesteps 981, 961, ... and, with eps = the true
 * noise of x_t = sqrt(a)x0 + sqrt(1-a)eps, one step lands exactly on the noised x0 at the
 * previous timestep. */
static void test_ddim(void) {
    mx_sched_config cfg;
    mx_status st = {0};
    mx_sched_config_sd15_ddim(&cfg);
    mx_sched s;
    enum { N = 64 };
    CHECK(mx_sched_init(&s, NULL, &cfg, 50, N, &st) == 0);
    CHECK(mx_sched_steps(&s) == 50);
    CHECK(mx_sched_timestep(&s, 0) == 981 && mx_sched_timestep(&s, 49) == 1);
    float x0[N], eps[N], x[N], want[N];
    mx_fill_random(x0, N, 1, -1, 1);
    mx_fill_random(eps, N, 2, -1, 1);
    mx_sched_add_noise(&s, x, x0, eps, N);
    float a0 = s.alphas_cumprod[981], a1 = s.alphas_cumprod[961];
    for (int i = 0; i < N; i++) {
        CHECK(fabsf(x[i] - (sqrtf(a0) * x0[i] + sqrtf(1 - a0) * eps[i])) < 1e-6f);
        want[i] = sqrtf(a1) * x0[i] + sqrtf(1 - a1) * eps[i];
    }
    CHECK(mx_sched_step(&s, eps, x, &st) == 0);
    mx_check_close("ddim: one exact step", x, want, N, 1e-5);
    mx_sched_free(&s);
}

/* Strength keeps the last floor(steps*strength) timesteps (diffusers img2img), and the DPM
 * add_noise uses the sigma of the first kept step. */
static void test_strength(void) {
    mx_sched_config cfg;
    mx_status st = {0};
    mx_sched_config_sd15(&cfg);
    mx_sched full, s;
    CHECK(mx_sched_init(&full, NULL, &cfg, 10, 4, &st) == 0);
    CHECK(mx_sched_init(&s, NULL, &cfg, 10, 4, &st) == 0);
    CHECK(mx_sched_set_strength(&s, 0.55f, &st) == 0);
    CHECK(mx_sched_steps(&s) == 5);
    CHECK(mx_sched_timestep(&s, 0) == mx_sched_timestep(&full, 5));
    CHECK(mx_sched_set_strength(&s, 1.5f, &st) != 0);
    float x0[4] = {1, -1, 0.5f, 0}, noise[4] = {0, 0, 0, 1}, y[4];
    mx_sched_add_noise(&s, y, x0, noise, 4);
    double acp = s.alphas_cumprod[mx_sched_timestep(&s, 0)];
    CHECK(fabs(y[0] - sqrt(acp)) < 1e-5 && fabs(y[3] - sqrt(1 - acp)) < 1e-5);
    mx_sched_free(&full);
    mx_sched_free(&s);
}

/* (Classifier-free guidance runs as ops in the denoise loop: test_nn_pipeline checks it at 7.5.) */
static void test_config(void) {
    mx_sched_config cfg;
    mx_status st = {0};
    const char *bad = "{\"algorithm_type\": \"sde-dpmsolver++\"}";
    CHECK(mx_sched_config_parse(&cfg, bad, strlen(bad), "bad.json", &st) != 0);
    CHECK(strstr(st.msg, "bad.json") != NULL);
    const char *ddim = "{\"_class_name\": \"DDIMScheduler\", \"timestep_spacing\": \"trailing\"}";
    CHECK(mx_sched_config_parse(&cfg, ddim, strlen(ddim), "ddim.json", &st) == 0);
    CHECK(cfg.kind == MX_SCHED_DDIM && cfg.timestep_spacing == MX_SPACING_TRAILING);
    mx_sched s;
    CHECK(mx_sched_init(&s, NULL, &cfg, 50, 1, &st) == 0); /* np.round(np.arange(1000, 0, -20)) - 1 */
    CHECK(mx_sched_timestep(&s, 0) == 999 && mx_sched_timestep(&s, 1) == 979 && mx_sched_timestep(&s, 49) == 19);
    mx_sched_free(&s);
    /* diffusers writes -Infinity (Python json); "Infinity" inside a string is left alone */
    const char *py = "{\"lambda_min_clipped\": -Infinity, \"_note\": \"Infinity\", \"solver_order\": 3}";
    CHECK(mx_sched_config_parse(&cfg, py, strlen(py), "py.json", &st) == 0 && cfg.solver_order == 3);
    /* integers beyond int's range or with a fraction are refused, not cast (found by fuzz_json) */
    const char *huge = "{\"num_train_timesteps\": 1e120}", *frac = "{\"solver_order\": 2.5}";
    CHECK(mx_sched_config_parse(&cfg, huge, strlen(huge), "huge.json", &st) != 0);
    CHECK(strstr(st.msg, "num_train_timesteps") != NULL);
    CHECK(mx_sched_config_parse(&cfg, frac, strlen(frac), "frac.json", &st) != 0);
    printf("scheduler config refusals: %s\n", st.msg);
}

int main(void) {
    test_golden_cases();
    test_ddim();
    test_strength();
    test_config();
    return mx_test_finish("test_nn_scheduler");
}
