/* bench_e2e: the one-line end-to-end summary of `make bench`:
 *   bench-e2e: default_s=S fast_s=S unet_b2_64_fp32_s=S unet_b2_64_bf16_s=S peak_rss_mb=M weights_mb=M isa=LEVEL
 * on the SD1.5-architecture model set with random weights (bench_sd15.h, cached outside the
 * repository) and the spot mesh of tests/data/assets.
 * - unet_b2_64_*: one UNet call (batch 2, 64×64 latent, 77 tokens), fp32 and bf16 alternated,
 *   median of 3 each (bf16 "na" without AVX512_BF16).
 * - default_s, peak_rss_mb: a default `matex texture` run (10 steps, 6 views, 1024², its default
 *   precision), timed as a child process whose peak RSS wait4 reports (peak_rss_mb: the larger of the
 *   two runs). About 10-15 minutes on 2 cores, so only with BENCH_E2E=1; otherwise "na".
 * - fast_s: the same with `--fast`, on the fast model set (the same plus a random LCM-LoRA merged and
 *   a random TAESD: sd15_random_f16_fast.mxw beside the other, made once), only with BENCH_E2E=1.
 * - each texture run also prints a line `bench-e2e-run: LABEL wall_s= cpu_s= peak_rss_mb=` with the
 *   stage times of its report.json (stages_s, work_s); BENCH_E2E_FP32=1 adds a default run with
 *   `--precision fp32` (the default before bf16) for the before/after.
 * - isa: the kernel level a default `matex texture` uses.
 * Usage: bench_e2e [--threads N] (MATEX: the matex binary, default ./matex). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../../pipeline/texture/models.h"
#include "../../runtime/fileio.h"
#include "../../runtime/json.h"
#include "bench_sd15.h"

#define UNET_REPEATS 3

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Median seconds of one UNet call per precision (fp32, bf16), the calls alternated; secs[1] = 0
 * without bf16. */
static int time_unet(const char *weights, int threads, double secs[2], mx_status *st) {
    /* host-memory contexts: the weights bound through the fp32 one serve both */
    mx_ctx c[2];
    mx_isa bf16_isa = mx_cpu_isa_for(MX_PREC_BF16);
    int nprec = mx_isa_precision(bf16_isa) == MX_PREC_BF16 ? 2 : 1, rc = -1;
    if (mx_ctx_create(&c[0], threads, mx_cpu_isa_for(MX_PREC_FP32), (size_t)64 << 20, st)) return -1;
    if (nprec == 2 && mx_ctx_create(&c[1], threads, bf16_isa, (size_t)64 << 20, st)) {
        mx_ctx_destroy(&c[0]);
        return -1;
    }
    mx_models m;
    if (mx_models_load(&m, &c[0], weights, 0, st)) {
        for (int p = 0; p < nprec; p++) mx_ctx_destroy(&c[p]);
        return -1;
    }
    int B = 2, H = 64, W = 64, T = 77, D = mx_unet_cfg(m.unet)->cross_attention_dim;
    size_t ns = (size_t)B * mx_unet_cfg(m.unet)->in_channels * H * W, nt = (size_t)B * T * D, bytes;
    float *x = malloc(ns * sizeof *x), *e = malloc(nt * sizeof *e), *out = malloc(ns * sizeof *out), ts[2] = {981, 37};
    mx_arena a = {0};
    double t[2][UNET_REPEATS];
    if (!x || !e || !out) {
        mx_fail(st, MX_ENOMEM, "bench_e2e: out of memory");
        goto done;
    }
    for (size_t i = 0; i < ns; i++) x[i] = (float)((i * 2654435761u) % 2001) / 1000.0f - 1.0f;
    for (size_t i = 0; i < nt; i++) e[i] = (float)((i * 40503u) % 2001) / 1000.0f - 1.0f;
    mx_unet_input in = {.sample = x, .timesteps = ts, .encoder_hidden_states = e, .B = B, .H = H, .W = W, .T = T};
    rc = mx_unet_arena_bytes(m.unet, B, H, W, T, &bytes, st) || mx_arena_create(&a, bytes, st) ? -1 : 0;
    for (int r = 0; r < UNET_REPEATS && rc == 0; r++)
        for (int p = 0; p < nprec && rc == 0; p++) {
            double t0 = mx_now();
            rc = mx_unet_forward(&c[p], m.unet, &in, out, &a, st);
            t[p][r] = mx_now() - t0;
        }
    for (int p = 0; p < 2; p++) {
        if (p < nprec) qsort(t[p], UNET_REPEATS, sizeof(double), cmp_double);
        secs[p] = p < nprec ? t[p][UNET_REPEATS / 2] : 0;
    }
    mx_arena_destroy(&a);
done:
    free(x), free(e), free(out);
    mx_models_free(&m);
    for (int p = 0; p < nprec; p++) mx_ctx_destroy(&c[p]);
    return rc;
}

/* One `matex texture` run as a child process: wall and CPU seconds (user + sys, wait4), peak RSS. */
typedef struct e2e_run {
    const char *label, *precision; /* precision NULL: the default */
    int fast;
    double wall_s, cpu_s, rss_mb;
} e2e_run;

/* Prints the run's stage times (report.json: stages_s, work_s) on one line. */
static void print_stages(const e2e_run *r, const char *out_dir) {
    char path[256];
    size_t len;
    mx_status st;
    snprintf(path, sizeof path, "%s/report.json", out_dir);
    char *text = mx_read_file(path, (size_t)16 << 20, &len, &st);
    mx_json *rep = text ? mx_json_parse(text, len, path, &st) : NULL;
    printf("bench-e2e-run: %s wall_s=%.1f cpu_s=%.1f peak_rss_mb=%.0f", r->label, r->wall_s, r->cpu_s, r->rss_mb);
    const char *objs[2] = {"stages_s", "work_s"};
    for (int o = 0; rep && o < 2; o++) {
        const mx_json *s = mx_json_get(rep, objs[o]);
        for (size_t i = 0; i < mx_json_len(s); i++) printf(" %s=%.1f", mx_json_key(s, i), mx_json_num(mx_json_at(s, i)));
    }
    printf("\n");
    mx_json_free(rep);
    free(text);
}

/* Runs `matex texture` on spot with the defaults (plus --fast / --precision). Returns -1 when it fails. */
static int run_texture(const char *matex, const char *weights, int threads, e2e_run *r) {
    char out[] = "/tmp/matex_bench_e2e.XXXXXX", dir[64], thr[16];
    if (!mkdtemp(out)) return -1;
    snprintf(dir, sizeof dir, "%s/o", out);
    snprintf(thr, sizeof thr, "%d", threads);
    const char *argv[20] = {matex, "texture", "tests/data/assets/spot/spot_triangulated.obj",
                            "a black-and-white dairy cow", "--weights", weights, "-o", dir, "--threads", thr, "--quiet"};
    int n = 11;
    if (r->fast) argv[n++] = "--fast";
    if (r->precision) argv[n++] = "--precision", argv[n++] = r->precision;
    double t0 = mx_now();
    pid_t pid = fork();
    if (pid == 0) {
        execv(matex, (char *const *)argv);
        _exit(127);
    }
    int status = 0;
    struct rusage ru;
    int ok = pid > 0 && wait4(pid, &status, 0, &ru) == pid && WIFEXITED(status) && !WEXITSTATUS(status);
    r->wall_s = mx_now() - t0;
    r->cpu_s = ok ? ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) : 0;
    r->rss_mb = ok ? ru.ru_maxrss / 1024.0 : 0;
    if (ok) print_stages(r, dir);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", out);
    return system(cmd) == 0 && ok ? 0 : -1;
}

static void fmt(char *buf, size_t cap, double v, const char *f) {
    if (v > 0)
        snprintf(buf, cap, f, v);
    else
        snprintf(buf, cap, "na");
}

int main(int argc, char **argv) {
    int threads = 2;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--threads") && i + 1 < argc)
            threads = atoi(argv[++i]);
        else {
            fprintf(stderr, "usage: bench_e2e [--threads N]\n");
            return 2;
        }
    }
    setvbuf(stdout, NULL, _IOLBF, 0); /* each run's line shows up as it ends */
    const char *matex = getenv("MATEX") ? getenv("MATEX") : "./matex";
    const char *e2e = getenv("BENCH_E2E"), *e2e_fp32 = getenv("BENCH_E2E_FP32");
    int run_e2e = e2e && !strcmp(e2e, "1");
    char weights[1100], fast_weights[1100];
    if (bench_sd15_weights(weights, sizeof weights) ||
        (run_e2e && bench_sd15_file(fast_weights, sizeof fast_weights, 1))) {
        fprintf(stderr, "bench_e2e: cannot make the SD1.5 weight files in the cache\n");
        return 1;
    }
    mx_status st;
    mx_status_clear(&st);
    double unet[2];
    if (time_unet(weights, threads, unet, &st)) {
        fprintf(stderr, "bench_e2e: %s\n", st.msg);
        return 1;
    }
    printf("bench-e2e-unet: fp32_s=%.2f bf16_s=%.2f (median of %d, alternated)\n", unet[0], unet[1], UNET_REPEATS);
    e2e_run def = {"default", NULL, 0, 0, 0, 0}, fast = {"fast", NULL, 1, 0, 0, 0}, fp32 = {"default-fp32", "fp32", 0, 0, 0, 0};
    if (run_e2e && (run_texture(matex, weights, threads, &def) || run_texture(matex, fast_weights, threads, &fast))) {
        fprintf(stderr, "bench_e2e: a matex texture run failed\n");
        return 1;
    }
    /* the fp32 run (the default before bf16): the before/after of the per-stage breakdown; optional,
     * so its failure leaves the summary line */
    if (run_e2e && e2e_fp32 && !strcmp(e2e_fp32, "1") && run_texture(matex, weights, threads, &fp32))
        fprintf(stderr, "bench_e2e: the --precision fp32 matex texture run failed\n");
    if (!run_e2e)
        printf("bench_e2e: the matex texture runs are opt-in (BENCH_E2E=1, ~10-15 min on 2 cores; BENCH_E2E_FP32=1 adds "
               "an fp32 run)\n");
    char d[32], f[32], u0[32], u1[32], r[32];
    fmt(d, sizeof d, def.wall_s, "%.1f");
    fmt(f, sizeof f, fast.wall_s, "%.1f");
    fmt(u0, sizeof u0, unet[0], "%.2f");
    fmt(u1, sizeof u1, unet[1], "%.2f");
    fmt(r, sizeof r, def.rss_mb > fast.rss_mb ? def.rss_mb : fast.rss_mb, "%.0f");
    printf("bench-e2e: default_s=%s fast_s=%s unet_b2_64_fp32_s=%s unet_b2_64_bf16_s=%s peak_rss_mb=%s "
           "weights_mb=%.0f isa=%s\n",
           d, f, u0, u1, r, bench_file_mb(weights), mx_isa_name(mx_cpu_isa_for(MX_PREC_BF16)));
    return 0;
}
