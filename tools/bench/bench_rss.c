/* bench_rss: peak memory (RSS) of the stages of an SD1.5-size `matex texture`, each stage in a child
 * process of its own (so each peak is that stage's), on the fp16 golden-v1 weight file that
 * the benchmarks share (bench_sd15.h: cached outside the repository, made on first use).
 * Per stage: VmHWM (peak RSS), RssFile (weight pages mapped in) and VmHWM - RssFile (about the
 * peak of anonymous memory: arenas, buffers), against the weight file's size.
 * Stages: the VAE decode of one 512x512 view and of the 1024x512 front+back grid, untiled
 * (mx_sd_decode_latents, the old path) and tiled (the texture path); one guided step (UNet + the
 * two ControlNets, CFG) over N views (default 1; the loop runs the networks one view at a time, so
 * N views peak as one). On 2 busy cores the whole run takes many minutes.
 * Usage: bench_rss [--weights PATH] [--threads N] [--tile T] [--views N] [--skip-steps] [--skip-untiled]
 *                  [--skip-decodes] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/sd_pipeline.h"
#include "../../pipeline/nn/vae_tiled.h"
#include "../../weights/weights.h"
#include "../../runtime/log.h"
#include "bench_sd15.h"


typedef struct bench_cfg {
    const char *weights;
    int threads, tile, views, skip_steps, skip_untiled, skip_decodes;
} bench_cfg;

/* kB value of a /proc/self/status field. */
static double status_mb(const char *field) {
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    double v = -1;
    size_t n = strlen(field);
    while (f && fgets(line, sizeof line, f))
        if (!strncmp(line, field, n) && line[n] == ':') v = atof(line + n + 1) / 1024.0;
    if (f) fclose(f);
    return v;
}

typedef struct stage_env {
    mx_weightfile *wf;
    mx_binder bu, bd, bi, bv;
    mx_unet *unet;
    mx_controlnet *cn[2];
    mx_vae *vae;
    mx_ctx ctx;
} stage_env;

/* Network `kind` under `prefix` (NULL: the kind's name), through its registry entry. */
static int bind_net(stage_env *e, const char *kind, const char *prefix, mx_binder *b, void **out, mx_status *st) {
    char p[80];
    snprintf(p, sizeof p, "%s.", prefix ? prefix : kind);
    return mx_binder_wf(b, e->wf, p, st) || mx_net_load_kind(kind, out, e->wf, prefix, b, st) ? -1 : 0;
}

static int env_open(stage_env *e, const bench_cfg *o, mx_status *st) {
    memset(e, 0, sizeof e[0]);
    if (mx_wf_open(&e->wf, o->weights, st) || mx_ctx_create(&e->ctx, o->threads, mx_cpu_best_isa(), (size_t)64 << 20, st))
        return -1;
    return bind_net(e, MX_NET_UNET, NULL, &e->bu, (void **)&e->unet, st) ||
                   bind_net(e, MX_NET_CONTROLNET, MX_NET_CONTROLNET "_depth", &e->bd, (void **)&e->cn[0], st) ||
                   bind_net(e, MX_NET_CONTROLNET, MX_NET_CONTROLNET "_inpaint", &e->bi, (void **)&e->cn[1], st) ||
                   bind_net(e, MX_NET_VAE, NULL, &e->bv, (void **)&e->vae, st)
               ? -1
               : 0;
}

/* Decode of n latents h x w: tile 0 = the untiled pipeline helper. */
static int stage_decode(stage_env *e, int n, int h, int w, int tile, mx_status *st) {
    float *lat = bench_filled((size_t)n * 4 * h * w, -3, 3, 5), *img = malloc(sizeof(float) * n * 3 * 64 * h * w);
    int rc = !lat || !img ? mx_fail(st, MX_ENOMEM, "out of memory")
             : tile     ? mx_vae_decode_image_tiled(&e->ctx, e->vae, lat, n, h, w, tile, img, st)
                        : mx_sd_decode_latents(&e->ctx, e->vae, lat, n, h, w, img, st);
    free(lat);
    free(img);
    return rc;
}

/* One DPM-Solver++ step of n views at 64x64 with both ControlNets and guidance 7.5. */
static int stage_step(stage_env *e, int n, mx_status *st) {
    size_t lat = (size_t)n * 4 * 64 * 64, txt = (size_t)n * 77 * 768, ctl = (size_t)n * 3 * 512 * 512;
    float *x = bench_filled(lat, -1, 1, 1), *c = bench_filled(txt, -1, 1, 2), *u = bench_filled(txt, -1, 1, 3);
    float *d = bench_filled(ctl, 0, 1, 4), *p = bench_filled(ctl, 0, 1, 6);
    mx_sched_config cfg;
    mx_sched s;
    mx_sched_config_sd15(&cfg);
    int rc = !x || !c || !u || !d || !p ? mx_fail(st, MX_ENOMEM, "out of memory") : mx_sched_init(&s, &e->ctx, &cfg, 1, lat, st);
    if (!rc) {
        mx_sd_control controls[2] = {{e->cn[0], d, 1.0f, NULL}, {e->cn[1], p, 0.8f, NULL}};
        mx_sd_request rq = {.unet = e->unet, .controls = controls, .n_controls = 2, .cond_text = c, .uncond_text = u,
                            .T = 77, .guidance = 7.5f, .sched = &s};
        rc = mx_sd_denoise(&rq, &e->ctx, x, n, 64, 64, st);
        mx_sched_free(&s);
    }
    free(x), free(c), free(u), free(d), free(p);
    return rc;
}

typedef struct stage {
    const char *name;
    int kind; /* 0 decode, 1 guided step */
    int n, h, w, tiled;
} stage;

static int run_stage(const bench_cfg *o, const stage *sg) {
    mx_status st;
    stage_env e;
    double t0 = mx_now();
    int rc = env_open(&e, o, &st);
    if (!rc) rc = sg->kind ? stage_step(&e, sg->n, &st) : stage_decode(&e, sg->n, sg->h, sg->w, sg->tiled ? o->tile : 0, &st);
    if (rc) {
        fprintf(stderr, "bench_rss: %s: %s\n", sg->name, st.msg);
        return 1;
    }
    double hwm = status_mb("VmHWM"), file = status_mb("RssFile");
    printf("%-36s %7.1f s  peak RSS %7.0f MB  weights mapped in %6.0f MB  peak - mapped %6.0f MB\n", sg->name,
           mx_now() - t0, hwm, file, hwm - file);
    fflush(stdout);
    return 0;
}

int main(int argc, char **argv) {
    char cached[1100];
    bench_cfg o = {NULL, 0, 64, 1, 0, 0, 0}; /* the tile of `texture` (job_generate.c) */
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--weights") && i + 1 < argc) o.weights = argv[++i];
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc) o.threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--tile") && i + 1 < argc) o.tile = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--views") && i + 1 < argc) o.views = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--skip-steps")) o.skip_steps = 1;
        else if (!strcmp(argv[i], "--skip-untiled")) o.skip_untiled = 1;
        else if (!strcmp(argv[i], "--skip-decodes")) o.skip_decodes = 1;
        else {
            fprintf(stderr, "usage: bench_rss [--weights PATH] [--threads N] [--tile T] [--views N] [--skip-steps] "
                            "[--skip-untiled] [--skip-decodes]\n");
            return 2;
        }
    }
    if (!o.weights && bench_sd15_weights(cached, sizeof cached) == 0) o.weights = cached;
    struct stat sb;
    if (!o.weights || stat(o.weights, &sb)) {
        fprintf(stderr, "bench_rss: the SD1.5 weight file %s is missing and could not be made\n", o.weights ? o.weights : cached);
        return 1;
    }
    mx_log_set_level(MX_LOG_WARN);
    printf("weight file %s: %.0f MB; VAE tile %d latents\n", o.weights, sb.st_size / 1048576.0, o.tile);
    fflush(stdout); /* before the children inherit the buffer */
    char tiled_view[64], tiled_grid[64], step[64];
    snprintf(tiled_view, sizeof tiled_view, "vae decode 512x512, tiles of %d", o.tile);
    snprintf(tiled_grid, sizeof tiled_grid, "vae decode 1024x512, tiles of %d", o.tile);
    snprintf(step, sizeof step, "guided step, %d view(s), UNet + 2 CN", o.views);
    const stage stages[] = {
        {"vae decode 512x512, untiled", 0, 1, 64, 64, 0}, {tiled_view, 0, 1, 64, 64, 1},
        {"vae decode 1024x512, untiled", 0, 1, 64, 128, 0}, {tiled_grid, 0, 1, 64, 128, 1},
        {step, 1, o.views, 0, 0, 0},
    };
    int fails = 0;
    for (size_t i = 0; i < sizeof stages / sizeof stages[0]; i++) {
        if ((stages[i].kind == 1 && o.skip_steps) || (stages[i].kind == 0 && (o.skip_decodes || (!stages[i].tiled && o.skip_untiled))))
            continue;
        pid_t pid = fork();
        if (pid == 0) _exit(run_stage(&o, &stages[i]));
        int status = 0;
        fails += pid < 0 || waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status);
    }
    return fails ? 1 : 0;
}
