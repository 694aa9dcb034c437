/* bench_nets: the full SD1.5 set (UNet, 2 ControlNets, VAE, CLIP text encoder; configs from
 * tests/data/golden/sd15_*) with golden-v1 rule weights in one fp16 matex weight file under /tmp
 * (generated once by a child process, reused when present). Reports load time, peak RSS, and
 * the time, FLOPs and GFLOP/s of one UNet call (64×64 latent, batch 2, 77 tokens), one
 * ControlNet call, one VAE decode (64×64 latent, batch 1) and one CLIP call (batch 2).
 * Usage: bench_nets [--threads N] [--weights PATH] [--skip-vae] [--skip-controlnet] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../ops/ops.h"
#include "../pipeline/nn/clip.h"
#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/netcfg.h"
#include "../pipeline/nn/unet.h"
#include "../pipeline/nn/vae.h"
#include "../runtime/log.h"
#include "../weights/golden_rule.h"
#include "../weights/weights.h"

#define DEFAULT_WEIGHTS "/tmp/matex_bench_sd15_f16.mxw"

typedef struct net_spec {
    const char *golden;  /* folder under tests/data/golden */
    const char *prefix;  /* in the weight file */
    uint64_t seed;
} net_spec;

static const net_spec nets[] = {
    {"sd15_unet", "unet.", 1},
    {"sd15_controlnet", "controlnet_depth.", 2},
    {"sd15_controlnet", "controlnet_inpaint.", 3},
    {"sd15_vae", "vae.", 1},
    {"sd15_clip", "text_encoder.", 1},
};
#define NNETS (sizeof nets / sizeof nets[0])

static char *read_config(const char *golden) {
    char path[1024];
    snprintf(path, sizeof path, "tests/data/golden/%s/config.json", golden); /* shipped with the sources */
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "bench_nets: cannot open %s\n", path);
        return NULL;
    }
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = n > 0 ? malloc((size_t)n + 1) : NULL;
    if (s && fread(s, 1, (size_t)n, f) == (size_t)n) s[n] = 0;
    else {
        free(s);
        s = NULL;
    }
    fclose(f);
    return s;
}

static double peak_rss_mb(void) {
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_maxrss / 1024.0;
}

/* ---- weight file generation (child process, so the parent's peak RSS is the runtime's) ---- */

typedef struct gen_state {
    mx_wf_writer *w;
    void **bufs;
    size_t nbufs, cap;
} gen_state;

static int gen_net(gen_state *g, const net_spec *ns, mx_status *st) {
    char *cfg = read_config(ns->golden);
    mx_binder b;
    if (!cfg) return mx_fail(st, MX_EIO, "no config for %s", ns->golden);
    char key[96];
    snprintf(key, sizeof key, "%sconfig", ns->prefix);
    int rc = mx_binder_enum(&b, st) || mx_net_enumerate(&b, cfg, strlen(cfg), ns->golden, st) ||
             mx_wf_writer_meta(g->w, key, cfg, st);
    free(cfg);
    for (size_t i = 0; !rc && i < mx_binder_enum_count(&b); i++) {
        const mx_param_info *p = mx_binder_enum_at(&b, i);
        size_t n = (size_t)mx_shape_numel(p->ndim, p->shape);
        float *x = malloc(n * sizeof *x);
        if (!x || g->nbufs == g->cap) {
            free(x);
            rc = mx_fail(st, MX_ENOMEM, "out of memory generating %s", p->name);
            break;
        }
        mx_golden_v1_fill(p->name, p->ndim, p->shape, ns->seed, x);
        char name[256];
        snprintf(name, sizeof name, "%s%s", ns->prefix, p->name);
        if (p->ndim >= 2) { /* fp16 storage for matrices; vectors stay fp32 (as the converter does) */
            uint16_t *h = (uint16_t *)x;
            for (size_t k = 0; k < n; k++) h[k] = mx_float_to_half(x[k]);
            rc = mx_wf_writer_add(g->w, name, MX_F16, p->ndim, p->shape, h, MX_F16, st);
        } else {
            rc = mx_wf_writer_add(g->w, name, MX_F32, p->ndim, p->shape, x, MX_F32, st);
        }
        g->bufs[g->nbufs++] = x;
    }
    mx_binder_free(&b);
    return rc;
}

static int generate(const char *path) {
    mx_status st;
    gen_state g = {0};
    g.cap = 4096;
    g.bufs = calloc(g.cap, sizeof *g.bufs);
    g.w = mx_wf_writer_create(&st);
    int rc = !g.bufs || !g.w;
    for (size_t i = 0; !rc && i < NNETS; i++) rc = gen_net(&g, &nets[i], &st);
    if (!rc) rc = mx_wf_writer_meta(g.w, "provenance", "golden-v1 rule weights (bench_nets)", &st);
    if (!rc) rc = mx_wf_writer_finish(g.w, path, &st);
    if (rc) fprintf(stderr, "bench_nets: generating %s: %s\n", path, st.msg);
    mx_wf_writer_free(g.w);
    for (size_t i = 0; i < g.nbufs; i++) free(g.bufs[i]);
    free(g.bufs);
    return rc ? 1 : 0;
}

static int ensure_weights(const char *path) {
    struct stat sb;
    if (stat(path, &sb) == 0) return 0;
    printf("generating %s (once)...\n", path);
    fflush(stdout);
    double t0 = mx_now();
    pid_t pid = fork();
    if (pid == 0) _exit(generate(path));
    int status = 0;
    if (pid < 0 || waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status)) return -1;
    printf("generated in %.1f s\n", mx_now() - t0);
    return 0;
}

/* ---- the runs ---- */

static float *filled(size_t n, float lo, float hi, unsigned seed) {
    float *x = malloc(n * sizeof *x);
    unsigned s = seed * 2654435761u + 7;
    for (size_t i = 0; x && i < n; i++) {
        s = s * 1664525u + 1013904223u;
        x[i] = lo + (hi - lo) * (float)(s >> 8) / 16777216.0f;
    }
    return x;
}

static const char *config_of(const mx_weightfile *wf, const char *prefix, mx_status *st) {
    char key[96];
    snprintf(key, sizeof key, "%sconfig", prefix);
    const char *c = mx_wf_meta(wf, key);
    if (!c) mx_fail(st, MX_EINPUT, "%s: no %s", mx_wf_path(wf), key);
    return c;
}

static void report(const char *what, double secs, double flops) {
    printf("%-34s %8.2f s  %8.1f GFLOP  %7.1f GFLOP/s\n", what, secs, flops / 1e9, flops / 1e9 / secs);
}

typedef struct bench_opts {
    int threads, skip_vae, skip_cn;
    const char *weights;
} bench_opts;

static int run_benchmarks(const bench_opts *o, mx_status *st) {
    mx_weightfile *wf = NULL;
    mx_binder bu, bc[2], bv, bt;
    mx_unet_config ucfg, ccfg;
    mx_vae_config vcfg;
    mx_clip_config tcfg;
    mx_unet *u = NULL;
    mx_controlnet *cn[2] = {NULL, NULL};
    mx_vae *v = NULL;
    mx_clip clip;
    memset(&clip, 0, sizeof clip);
    const char *t;
    double t0 = mx_now();
    if (mx_wf_open(&wf, o->weights, st)) return -1;
    if (!(t = config_of(wf, "unet.", st)) || mx_unet_config_parse(&ucfg, t, strlen(t), "unet.config", st) ||
        mx_binder_wf(&bu, wf, "unet.", st) || mx_unet_load(&u, &ucfg, &bu, st))
        return -1;
    const char *cnp[2] = {"controlnet_depth.", "controlnet_inpaint."};
    for (int i = 0; i < 2; i++)
        if (!(t = config_of(wf, cnp[i], st)) || mx_unet_config_parse(&ccfg, t, strlen(t), cnp[i], st) ||
            mx_binder_wf(&bc[i], wf, cnp[i], st) || mx_controlnet_load(&cn[i], &ccfg, &bc[i], st))
            return -1;
    if (!(t = config_of(wf, "vae.", st)) || mx_vae_config_parse(&vcfg, t, strlen(t), "vae.config", st) ||
        mx_binder_wf(&bv, wf, "vae.", st) || mx_vae_load(&v, &vcfg, &bv, st))
        return -1;
    if (!(t = config_of(wf, "text_encoder.", st)) || mx_clip_config_parse(&tcfg, t, strlen(t), "text_encoder.config", st) ||
        mx_binder_wf(&bt, wf, "text_encoder.", st) || mx_clip_load(&clip, &tcfg, &bt, st))
        return -1;
    printf("%-34s %8.3f s (mmap + bind, 5 networks)\n", "load", mx_now() - t0);

    mx_ctx c;
    if (mx_ctx_create(&c, o->threads, mx_cpu_best_isa(), (size_t)512 << 20, st)) return -1;
    printf("threads %d, isa %s\n", mx_pool_threads(c.pool), mx_isa_name(mx_cpu_best_isa()));
    int B = 2, H = 64, W = 64, T = 77, D = ucfg.cross_attention_dim;
    size_t ns = (size_t)B * ucfg.in_channels * H * W;
    float *sample = filled(ns, -1, 1, 1), *ehs = filled((size_t)B * T * D, -1, 1, 2), ts[2] = {981, 37};
    float *out = malloc(ns * sizeof *out);
    size_t ub, cb, vb;
    mx_arena a;
    if (mx_unet_arena_bytes(u, B, H, W, T, &ub, st) || mx_controlnet_arena_bytes(cn[0], B, H, W, T, &cb, st) ||
        mx_vae_decode_arena_bytes(v, 1, H, W, &vb, st))
        return -1;
    size_t need = ub > cb ? ub : cb;
    if (!o->skip_vae && vb > need) need = vb;
    printf("arena: UNet %.0f MB, ControlNet %.0f MB, VAE decode %.0f MB\n", ub / 1e6, cb / 1e6, vb / 1e6);
    if (mx_arena_create(&a, need, st)) return -1;

    /* residuals of both ControlNets, summed (accumulate), then the UNet with them */
    int nres = mx_unet_num_residuals(&ccfg), C, h, w;
    float *res[MX_UNET_MAX_RES + 1];
    for (int i = 0; i <= nres; i++) {
        mx_unet_residual_shape(&ccfg, i, H, W, &C, &h, &w);
        res[i] = calloc((size_t)B * C * h * w, sizeof(float));
    }
    float *cond = filled((size_t)B * 3 * H * 8 * W * 8, 0, 1, 3);
    if (!o->skip_cn) {
        mx_controlnet_input ci = {sample, ts, ehs, cond, B, H, W, T, 0.8f};
        t0 = mx_now();
        if (mx_controlnet_forward(&c, cn[0], &ci, res, res[nres], 0, &a, st)) return -1;
        report("ControlNet 64x64 batch 2", mx_now() - t0, mx_controlnet_flops(cn[0], B, H, W, T));
    }
    mx_unet_input ui = {sample, ts, ehs, B, H, W, T, o->skip_cn ? NULL : (const float *const *)res,
                        o->skip_cn ? NULL : res[nres]};
    t0 = mx_now();
    if (mx_unet_forward(&c, u, &ui, out, &a, st)) return -1;
    report("UNet 64x64 batch 2 (+residuals)", mx_now() - t0, mx_unet_flops(u, B, H, W, T));
    if (!o->skip_vae) {
        float *img = malloc((size_t)3 * H * 8 * W * 8 * sizeof *img);
        t0 = mx_now();
        if (mx_vae_decode(&c, v, sample, 1, H, W, img, &a, st)) return -1;
        report("VAE decode 64x64 batch 1", mx_now() - t0, mx_vae_decode_flops(v, 1, H, W));
        free(img);
    }
    {
        int32_t ids[2 * 77];
        for (int i = 0; i < 2 * 77; i++) ids[i] = i % 77 == 0 ? 49406 : i % 77 < 9 ? 320 + i % 77 : 49407;
        size_t nt = (size_t)2 * 77 * tcfg.hidden_size;
        float *last = malloc(nt * sizeof *last), *pooled = malloc((size_t)2 * tcfg.hidden_size * sizeof *pooled);
        mx_arena dry, ca;
        mx_arena_measure(&dry);
        if (mx_clip_forward(&clip, &c, &dry, ids, 2, 77, last, pooled, NULL, st) ||
            mx_arena_create(&ca, dry.peak + 256, st))
            return -1;
        t0 = mx_now();
        if (mx_clip_forward(&clip, &c, &ca, ids, 2, 77, last, pooled, NULL, st)) return -1;
        printf("%-34s %8.2f s\n", "CLIP text encoder batch 2", mx_now() - t0);
        mx_arena_destroy(&ca);
        free(last);
        free(pooled);
    }
    printf("%-34s %8.0f MB\n", "peak RSS", peak_rss_mb());
    for (int i = 0; i <= nres; i++) free(res[i]);
    free(cond);
    free(sample);
    free(ehs);
    free(out);
    mx_arena_destroy(&a);
    mx_ctx_destroy(&c);
    mx_unet_free(u);
    mx_controlnet_free(cn[0]);
    mx_controlnet_free(cn[1]);
    mx_vae_free(v);
    mx_clip_free(&clip);
    mx_binder_free(&bu);
    mx_binder_free(&bc[0]);
    mx_binder_free(&bc[1]);
    mx_binder_free(&bv);
    mx_binder_free(&bt);
    mx_wf_close(wf);
    return 0;
}

int main(int argc, char **argv) {
    bench_opts o = {0, 0, 0, DEFAULT_WEIGHTS};
    setvbuf(stdout, NULL, _IOLBF, 0); /* progress lines show up as they happen */
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--threads") && i + 1 < argc) o.threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--weights") && i + 1 < argc) o.weights = argv[++i];
        else if (!strcmp(argv[i], "--skip-vae")) o.skip_vae = 1;
        else if (!strcmp(argv[i], "--skip-controlnet")) o.skip_cn = 1;
        else {
            fprintf(stderr, "usage: bench_nets [--threads N] [--weights PATH] [--skip-vae] [--skip-controlnet]\n");
            return 2;
        }
    }
    if (ensure_weights(o.weights)) {
        fprintf(stderr, "bench_nets: could not generate %s\n", o.weights);
        return 1;
    }
    mx_status st;
    mx_status_clear(&st);
    if (run_benchmarks(&o, &st)) {
        fprintf(stderr, "bench_nets: %s\n", st.msg);
        return 1;
    }
    return 0;
}
