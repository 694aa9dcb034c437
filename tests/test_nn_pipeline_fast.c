/* The few-step fast path against diffusers (golden/pipeline_controlnet_lcm_taesd_tiny):
 * StableDiffusionControlNetPipeline with the tiny UNet and ControlNet, LCMScheduler (4 steps, the
 * noise of each step given), guidance 1.0 (no classifier-free guidance: the batch is not doubled),
 * ControlNet scale 0.8 and taesd_tiny as the VAE. Timesteps exactly equal; latents after every
 * step and the image <= 1e-4 rel L2. Also: an LCM loop without a noise source is refused. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/sd_edit.h"
#include "../pipeline/nn/sd_pipeline.h"
#include "../pipeline/nn/taesd.h"
#include "nn_golden.h"
#include "tiny_nets.h"

#define PIPE "pipeline_controlnet_lcm_taesd_tiny"

typedef struct step_io {
    const float *noises; /* [steps - 1, numel] */
    const float *want;   /* [steps, numel] */
    int steps_seen;
} step_io;

static int give_noise(void *user, int step, float *noise, size_t numel) {
    const step_io *io = user;
    memcpy(noise, io->noises + (size_t)step * numel, numel * sizeof *noise);
    return 0;
}

static int on_step(void *user, int step, int n_steps, int64_t t, const float *latents, size_t numel) {
    step_io *io = user;
    char name[64];
    io->steps_seen++;
    snprintf(name, sizeof name, "LCM latents after step %d/%d (t=%lld)", step + 1, n_steps, (long long)t);
    mx_check_close(name, latents, io->want + (size_t)step * numel, numel, 1e-4);
    return 0;
}

/* enhance --fast: the inpaint pipeline at strength 0.5 (the last 2 of the 4 LCM steps) encoding its
 * init image with TAESD; with nothing to paint the final latents are exactly TAESD's encoding of
 * that image (the known region is put back after the last step). */
static void test_edit_keep(const tiny_nets *n, const mx_ctx *c, const mx_sched_config *scfg, const float *ctl,
                           const float *cond, const float *image, const float *noises, size_t nlat) {
    mx_status st = {0};
    mx_sched s;
    size_t npx = (size_t)2 * 64 * 64;
    float *mask = calloc(npx, sizeof *mask), *lat = malloc(nlat * sizeof *lat), *want = malloc(nlat * sizeof *want);
    int ok = mask && lat && want && mx_sched_init(&s, c, scfg, 4, nlat, &st) == 0;
    CHECK(ok);
    if (ok) {
        mx_sd_control control = {n->cnet, ctl, 0.8f, NULL};
        mx_sd_request rq = {.unet = n->unet, .controls = &control, .n_controls = 1, .cond_text = cond, .T = 77,
                            .guidance = 1.0f, .sched = &s};
        step_io io = {noises + nlat, NULL, 0};
        s.noise_fn = give_noise;
        s.noise_user = &io;
        mx_sd_edit e = {NULL, image, mask, noises, 0.5f, n->taesd};
        CHECK(mx_sd_edit_run(&rq, &e, c, 2, 8, 8, lat, &st) == 0);
        CHECK(mx_sched_steps(&s) == 2 && mx_sched_timestep(&s, 0) == 499);
        CHECK(mx_taesd_encode_image(c, n->taesd, image, 2, 64, 64, want, &st) == 0);
        mx_check_close("TAESD-encoded init kept by the fast inpaint", lat, want, nlat, 1e-6);
        mx_sched_free(&s);
    }
    free(mask);
    free(lat);
    free(want);
}

static void test_pipeline(const tiny_nets *n, const mx_ctx *c) {
    mx_safetensors in, out;
    if (golden_open(&in, PIPE, "inputs.safetensors") || golden_open(&out, PIPE, "outputs.safetensors")) {
        CHECK(0);
        return;
    }
    size_t nlat = 0, nctl = 0, ncond = 0, nnoise = 0, nts = 0, nafter = 0, nimg = 0;
    float *lat = golden_f32(&in, "latents", &nlat), *ctl = golden_f32(&in, "control_image", &nctl);
    float *cond = golden_f32(&in, "prompt_embeds", &ncond), *noises = golden_f32(&in, "noises", &nnoise);
    float *ts = golden_f32(&out, "timesteps", &nts), *after = golden_f32(&out, "latents_after_step", &nafter);
    float *img_want = golden_f32(&out, "image", &nimg);
    mx_status st = {0};
    mx_sched_config base, scfg;
    mx_sched s;
    mx_sched_config_sd15(&base);
    mx_sched_config_lcm(&scfg, &base);
    int ok = lat && ctl && cond && noises && ts && after && img_want && nlat == 2 * 4 * 8 * 8 && nts == 4 &&
             nnoise == 3 * nlat && nafter == 4 * nlat && mx_sched_init(&s, c, &scfg, 4, nlat, &st) == 0;
    if (!ok) fprintf(stderr, "fast pipeline setup: %s\n", st.msg);
    CHECK(ok);
    if (ok) {
        int ts_equal = mx_sched_steps(&s) == 4;
        for (int i = 0; ts_equal && i < 4; i++) ts_equal = (float)mx_sched_timestep(&s, i) == ts[i];
        printf("LCM timesteps %s\n", ts_equal ? "equal" : "DIFFER");
        CHECK(ts_equal);
        mx_sd_control control = {n->cnet, ctl, 0.8f, NULL};
        step_io io = {noises, after, 0};
        /* no negative embeddings: guidance 1 must not need them */
        mx_sd_request rq = {.unet = n->unet, .controls = &control, .n_controls = 1, .cond_text = cond, .T = 77,
                            .guidance = 1.0f, .sched = &s, .progress = on_step, .progress_user = &io};
        s.noise_fn = give_noise;
        s.noise_user = &io;
        CHECK(mx_sd_denoise(&rq, c, lat, 2, 8, 8, &st) == 0);
        CHECK(io.steps_seen == 4);
        float *img = malloc(sizeof(float) * nimg);
        int dec = img && mx_taesd_decode_image(c, n->taesd, lat, 2, 8, 8, img, &st) == 0;
        if (!dec) fprintf(stderr, "decode: %s\n", st.msg);
        CHECK(dec);
        if (dec) mx_check_close("LCM + TAESD image", img, img_want, nimg, 1e-4);
        free(img);
        mx_sched_free(&s);
        /* the LCM scheduler without a noise source is refused at its first step */
        CHECK(mx_sched_init(&s, c, &scfg, 4, nlat, &st) == 0);
        rq.progress = NULL;
        CHECK(mx_sd_denoise(&rq, c, lat, 2, 8, 8, &st) != 0 && strstr(st.msg, "noise source"));
        mx_sched_free(&s);
        test_edit_keep(n, c, &scfg, ctl, cond, img_want, noises, nlat);
    }
    free(lat);
    free(ctl);
    free(cond);
    free(noises);
    free(ts);
    free(after);
    free(img_want);
    mx_st_close(&in);
    mx_st_close(&out);
}

int main(void) {
    return tiny_nets_main("test_nn_pipeline_fast", TINY_UNET | TINY_CONTROLNET | TINY_TAESD, test_pipeline);
}
