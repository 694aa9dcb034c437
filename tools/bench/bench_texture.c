/* End-to-end benchmark of `matex texture` on the CPU with the full SD1.5 architecture
 * (random weights, the cached fp16 file of bench_sd15.h): a run at
 * 2 steps and 4 views (the front+back grid, then 2 inpainting views), stage by stage, with
 * FLOP counts of the networks, extrapolated to the default 10 steps and 6 views.
 * usage: bench_texture [--weights W.mxw] [--mesh MESH] [--threads N] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../pipeline/texture/models.h"
#include "../../runtime/fileio.h"
#include "../../pipeline/texture/texture.h"
#include "../../runtime/json.h"
#include "../../runtime/log.h"
#include "bench_sd15.h"

#define STEPS 2
#define VIEWS 4


/* FLOPs of one denoising step (CFG batch 2 of one latent: its halves shared until the first
 * cross-attention) and of one decode, for one image of h x w latents. */
static void step_flops(const mx_models *m, int h, int w, int n_controlnets, double *step, double *decode) {
    int how = MX_FLOPS_HALVES_EQUAL;
    *step = mx_unet_flops(m->unet, 2, h, w, 77, how);
    if (n_controlnets > 0) *step += mx_controlnet_flops(m->cn_depth, 2, h, w, 77, how);
    if (n_controlnets > 1) *step += mx_controlnet_flops(m->cn_inpaint, 2, h, w, 77, how);
    *decode = mx_vae_decode_flops(m->vae, 1, h, w);
}

static void print_view_rows(const mx_json *views, int steps, const double *step_gflop, const double *dec_gflop) {
    printf("%-8s %-7s %9s %9s %12s %12s %10s\n", "stage", "batch", "az/el", "denoise_s", "per_step_s",
           "step_GFLOP/s", "decode_s");
    int last_batch = -1;
    for (size_t i = 0; i < mx_json_len(views); i++) {
        const mx_json *v = mx_json_at(views, i);
        int batch = (int)mx_json_get_num(v, "batch", -1);
        if (batch == last_batch) continue; /* one row per generated batch */
        last_batch = batch;
        int grid = batch == 0;
        double den = mx_json_get_num(v, "batch_denoise_s", 0), dec = mx_json_get_num(v, "batch_decode_s", 0);
        char pose[32];
        snprintf(pose, sizeof pose, "%.0f/%.0f", mx_json_get_num(v, "azimuth", 0), mx_json_get_num(v, "elevation", 0));
        printf("%-8s %-7d %9s %9.2f %12.2f %12.1f %10.2f (%.0f GFLOP/s)\n", grid ? "grid" : "inpaint", batch, pose,
               den, den / steps, step_gflop[grid ? 0 : 1] / (den / steps), dec, dec_gflop[grid ? 0 : 1] / dec);
    }
}

int main(int argc, char **argv) {
    char cached[1100];
    const char *weights = NULL;
    const char *mesh = "tests/data/assets/spot/spot_triangulated.obj";
    int threads = 2;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--weights")) weights = argv[i + 1];
        else if (!strcmp(argv[i], "--mesh")) mesh = argv[i + 1];
        else if (!strcmp(argv[i], "--threads")) threads = atoi(argv[i + 1]);
    }
    if (!weights && bench_sd15_weights(cached, sizeof cached) == 0) weights = cached;
    if (!weights) {
        fprintf(stderr, "bench_texture: cannot make %s\n", cached);
        return 1;
    }
    mx_status st;
    mx_models m;
    mx_ctx c; /* only to bind the networks for their FLOP counts */
    if (mx_ctx_create(&c, 1, MX_ISA_SCALAR, 0, &st) ||
        mx_models_load(&m, &c, weights, MX_MODELS_NEED_DEPTH | MX_MODELS_NEED_INPAINT, &st)) {
        fprintf(stderr, "bench_texture: %s\n", st.msg);
        return 1;
    }
    double step_gf[2], dec_gf[2];
    step_flops(&m, 64, 128, 1, &step_gf[0], &dec_gf[0]); /* grid: 1024x512 image, depth only */
    step_flops(&m, 64, 64, 2, &step_gf[1], &dec_gf[1]);  /* a view: 512x512, depth + inpaint */
    mx_models_free(&m);
    mx_ctx_destroy(&c);
    for (int k = 0; k < 2; k++) {
        step_gf[k] *= 1e-9;
        dec_gf[k] *= 1e-9;
    }

    mx_texture_opts o;
    mx_texture_opts_default(&o);
    o.pub.mesh_path = mesh;
    o.pub.prompt = "a black-and-white dairy cow";
    o.weights_path = weights;
    o.pub.out_dir = "/tmp/matex_bench_texture_out";
    o.pub.force = 1; /* the previous run's folder */
    o.pub.steps = STEPS;
    o.pub.views = VIEWS;
    o.pub.batch = 1;
    o.pub.threads = threads;
    o.pub.verbose = 0;
    mx_texture_result r;
    if (mx_texture_run(&o, &r, &st)) {
        fprintf(stderr, "bench_texture: %s\n", st.msg);
        return 1;
    }
    size_t len;
    char *text = mx_read_file("/tmp/matex_bench_texture_out/report.json", (size_t)1 << 30, &len, NULL);
    mx_json *rep = text ? mx_json_parse(text, len, "report.json", &st) : NULL;
    if (!rep) {
        fprintf(stderr, "bench_texture: cannot read the report\n");
        return 1;
    }
    printf("matex texture, full SD1.5 architecture (random fp16 weights), %s, %d threads, %d steps, %d views, "
           "kernels %s\n", mesh, threads, STEPS, r.views, mx_isa_name(mx_cpu_isa_for(mx_texture_opts_precision(&o))));
    printf("FLOPs: grid step (UNet+ControlNet depth, CFG batch 2, 64x128 latent) %.0f GFLOP, decode %.0f GFLOP;\n"
           "       view step (UNet+2 ControlNets, CFG batch 2, 64x64) %.0f GFLOP, decode %.0f GFLOP\n",
           step_gf[0], dec_gf[0], step_gf[1], dec_gf[1]);
    const mx_json *stages = mx_json_get(rep, "stages_s");
    printf("stages (s):");
    for (size_t i = 0; i < mx_json_len(stages); i++)
        printf(" %s=%.2f", mx_json_key(stages, i), mx_json_num(mx_json_at(stages, i)));
    printf(" total=%.2f\n", mx_json_get_num(rep, "total_s", 0));
    const mx_json *views = mx_json_get(rep, "views");
    print_view_rows(views, STEPS, step_gf, dec_gf);
    /* extrapolation to the defaults: 10 steps, grid + 4 inpainting views */
    double grid_step = 0, view_step = 0, grid_dec = 0, view_dec = 0, nview = 0;
    for (size_t i = 0; i < mx_json_len(views); i++) {
        const mx_json *v = mx_json_at(views, i);
        int grid = mx_json_get_num(v, "batch", -1) == 0;
        double den = mx_json_get_num(v, "batch_denoise_s", 0) / STEPS, dec = mx_json_get_num(v, "batch_decode_s", 0);
        if (grid) grid_step = den, grid_dec = dec;
        else view_step += den, view_dec += dec, nview++;
    }
    if (nview > 0) view_step /= nview, view_dec /= nview;
    double est = 10 * grid_step + grid_dec + 4 * (10 * view_step + view_dec);
    printf("per step: grid %.2f s, view %.2f s; per view (10 steps + decode): %.1f s\n", grid_step, view_step,
           10 * view_step + view_dec);
    printf("bench-texture-summary: grid_step_s=%.2f view_step_s=%.2f est_default_run_s=%.1f\n", grid_step, view_step,
           est);
    mx_json_free(rep);
    free(text);
    return 0;
}
