/* The whole StableDiffusionControlNetPipeline with the tiny golden networks
 * (golden/pipeline_controlnet_tiny): CLIP prompt embeddings, DPM-Solver++ timesteps, the
 * latents after each of the 6 steps (guidance 7.5, ControlNet scale 0.8) and the decoded
 * image, each ≤ 1e-4 rel L2 against diffusers. Also: cancellation from the progress
 * callback, and request validation. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/clip.h"
#include "../pipeline/nn/sd_pipeline.h"
#include "nn_golden.h"
#include "tiny_nets.h"
#include "util_test.h"

#define PIPE "pipeline_controlnet_tiny"

/* Prompt embeddings from the golden ids, compared with the pipeline's. */
static void check_embeddings(const tiny_nets *n, const mx_ctx *c, const mx_safetensors *in,
                             const mx_safetensors *out) {
    const char *ids_name[2] = {"prompt_ids", "negative_prompt_ids"};
    const char *emb_name[2] = {"prompt_embeds", "negative_prompt_embeds"};
    for (int k = 0; k < 2; k++) {
        size_t nid = 0, nemb = 0;
        float *fid = golden_f32(in, ids_name[k], &nid), *want = golden_f32(out, emb_name[k], &nemb);
        float *got = malloc(sizeof(float) * (nemb ? nemb : 1));
        int32_t ids[77];
        mx_status st = {0};
        mx_arena a;
        CHECK(fid && want && nid == 77 && nemb == 77 * (size_t)n->clip_cfg.hidden_size);
        if (fid && want && nid == 77 && nemb == 77 * (size_t)n->clip_cfg.hidden_size) {
            golden_arena(c, &a, (size_t)1 << 20);
            float *dgot = golden_dev_alloc(c, nemb);
            for (int i = 0; i < 77; i++) ids[i] = (int32_t)fid[i];
            CHECK(mx_clip_forward(n->clip, c, &a, ids, 1, 77, dgot, NULL, NULL, &st) == 0);
            CHECK(golden_fetch(c, got, dgot, nemb) == 0);
            mx_check_close(emb_name[k], got, want, nemb, 1e-4);
            mx_arena_destroy(&a);
        }
        free(fid);
        free(want);
        free(got);
    }
}

/* The steps seen by the progress callback (which cancels at cancel_at) and the latents after
 * each step (after_step: downloaded here, as the loop itself never does) against the golden ones. */
typedef struct step_check {
    const float *want; /* [steps, numel] */
    size_t numel;
    int steps_seen, latents_checked;
    int cancel_at;     /* -1: never */
} step_check;

static int on_step(void *user, int step, int n_steps, int64_t t) {
    step_check *sc = user;
    (void)n_steps;
    (void)t;
    sc->steps_seen++;
    return step == sc->cancel_at;
}

static int check_step_latents(void *user, const mx_ctx *c, int step, int n_steps, float *latents, mx_status *st) {
    step_check *sc = user;
    char name[64];
    float *got = malloc(sc->numel * sizeof *got);
    if (!got || mx_download(c, got, latents, sc->numel, st)) return free(got), mx_fail(st, MX_EINTERNAL, "step latents");
    snprintf(name, sizeof name, "latents after step %d/%d", step + 1, n_steps);
    mx_check_close(name, got, sc->want + (size_t)step * sc->numel, sc->numel, 1e-4);
    sc->latents_checked++;
    free(got);
    return 0;
}

/* Downloads through a backend wrapped by the test (count_downloads). */
static mx_backend *counted_be;
static int downloads;

static int counting_to_host(mx_backend *be, void *dst, const void *src, size_t bytes, mx_status *st) {
    (void)be;
    downloads++;
    return counted_be->to_host(counted_be, dst, src, bytes, st);
}

/* The loop never waits for the device: with a progress callback, 6 steps make one download (the
 * final latents), not one per step. */
static void check_one_download(mx_sd_request rq, const mx_ctx *c, const mx_sched_config *scfg, const float *start,
                               size_t nlat) {
    mx_status st = {0};
    mx_backend wrap = *c->be;
    mx_ctx cc = *c;
    mx_sched s;
    counted_be = c->be;
    wrap.to_host = counting_to_host;
    cc.be = &wrap;
    step_check sc = {NULL, 0, 0, 0, -1};
    float *lat = malloc(nlat * sizeof *lat);
    CHECK(lat && mx_sched_init(&s, &cc, scfg, 6, nlat, &st) == 0);
    if (!lat) return;
    memcpy(lat, start, nlat * sizeof *lat);
    rq.sched = &s;
    rq.progress = on_step;
    rq.progress_user = &sc;
    rq.after_step = NULL;
    downloads = 0;
    CHECK(mx_sd_denoise(&rq, &cc, lat, 1, 8, 8, &st) == 0);
    printf("denoise, 6 steps with progress: %d download(s)\n", downloads);
    CHECK(sc.steps_seen == 6 && downloads == 1);
    mx_sched_free(&s);
    free(lat);
}

/* Per-item ControlNet weights: a batch of two copies of the golden start at weights 0.8 and
 * 0.5 (plus a second ControlNet at 0 and 0.3): item 0 must end as the golden run at 0.8, item
 * 1 as a plain run at 0.5 + 0.3 = 0.8 too (the golden run at 0.8). */
static void check_item_weights(mx_sd_request *rq, const mx_ctx *c, const mx_sched_config *scfg,
                               const mx_safetensors *in, const float *ctl, const float *cond, const float *unc,
                               const float *want_last, size_t nlat, const mx_controlnet *net) {
    mx_status st = {0};
    mx_sched s;
    float *start = golden_f32(in, "latents", NULL), *lat = malloc(2 * nlat * sizeof(float));
    float *ctl2 = malloc(2 * 3 * 64 * 64 * sizeof(float)), *text2 = malloc(4 * 77 * 32 * sizeof(float));
    if (!start || !lat || !ctl2 || !text2) {
        CHECK(0);
        goto done;
    }
    for (int b = 0; b < 2; b++) {
        memcpy(lat + b * nlat, start, nlat * sizeof(float));
        memcpy(ctl2 + b * 3 * 64 * 64, ctl, 3 * 64 * 64 * sizeof(float));
        memcpy(text2 + b * 77 * 32, cond, 77 * 32 * sizeof(float));
        memcpy(text2 + (2 + b) * 77 * 32, unc, 77 * 32 * sizeof(float));
    }
    float w_a[2] = {0.8f, 0.5f}, w_b[2] = {0.0f, 0.3f};
    mx_sd_control two[2] = {{net, ctl2, 0.0f, w_a}, {net, ctl2, 0.0f, w_b}};
    mx_sd_request r = *rq;
    r.controls = two;
    r.n_controls = 2;
    r.progress = NULL;
    r.cond_text = text2;
    r.uncond_text = text2 + 2 * 77 * 32;
    r.sched = &s;
    int ok = mx_sched_init(&s, c, scfg, 6, 2 * nlat, &st) == 0 && mx_sd_denoise(&r, c, lat, 2, 8, 8, &st) == 0;
    if (!ok) fprintf(stderr, "item weights: %s\n", st.msg);
    CHECK(ok);
    if (ok) {
        mx_check_close("item weights: item 0 at 0.8 + 0", lat, want_last, nlat, 1e-4);
        mx_check_close("item weights: item 1 at 0.5 + 0.3", lat + nlat, want_last, nlat, 1e-4);
    }
    mx_sched_free(&s);
done:
    free(start);
    free(lat);
    free(ctl2);
    free(text2);
}

static void test_pipeline(const tiny_nets *n, const mx_ctx *c) {
    mx_safetensors in, out;
    if (golden_open(&in, PIPE, "inputs.safetensors") || golden_open(&out, PIPE, "outputs.safetensors")) {
        CHECK(0);
        return;
    }
    check_embeddings(n, c, &in, &out);
    size_t nlat = 0, nctl = 0, ncond = 0, nunc = 0, nts = 0, nafter = 0, nimg = 0, lsched = 0;
    float *lat = golden_f32(&in, "latents", &nlat), *ctl = golden_f32(&in, "control_image", &nctl);
    float *cond = golden_f32(&out, "prompt_embeds", &ncond), *unc = golden_f32(&out, "negative_prompt_embeds", &nunc);
    float *ts = golden_f32(&out, "timesteps", &nts), *after = golden_f32(&out, "latents_after_step", &nafter);
    float *img_want = golden_f32(&out, "image", &nimg);
    char *sched_text = golden_text(PIPE, "scheduler_config.json", &lsched);
    mx_status st = {0};
    mx_sched_config scfg;
    mx_sched s;
    int ok = lat && ctl && cond && unc && ts && after && img_want && sched_text && nlat == 4 * 8 * 8 &&
             mx_sched_config_parse(&scfg, sched_text, lsched, "scheduler_config.json", &st) == 0 &&
             mx_sched_init(&s, c, &scfg, 6, nlat, &st) == 0;
    if (!ok) fprintf(stderr, "pipeline setup: %s\n", st.msg);
    CHECK(ok);
    if (ok) {
        int ts_equal = (size_t)mx_sched_steps(&s) == nts;
        for (size_t i = 0; ts_equal && i < nts; i++) ts_equal = (float)mx_sched_timestep(&s, (int)i) == ts[i];
        CHECK(ts_equal);
        mx_sd_control control = {n->cnet, ctl, 0.8f, NULL};
        step_check sc = {after, nlat, 0, 0, -1};
        mx_sd_request rq = {.unet = n->unet, .controls = &control, .n_controls = 1, .cond_text = cond, .uncond_text = unc,
                            .T = 77, .guidance = 7.5f, .sched = &s, .progress = on_step, .progress_user = &sc,
                            .after_step = check_step_latents, .after_step_user = &sc};
        CHECK(mx_sd_denoise(&rq, c, lat, 1, 8, 8, &st) == 0);
        CHECK(sc.steps_seen == 6 && sc.latents_checked == 6);
        rq.after_step = NULL;
        float *img = malloc(sizeof(float) * nimg);
        int dec = img && mx_sd_decode_latents(c, n->vae, lat, 1, 8, 8, img, &st) == 0;
        if (!dec) fprintf(stderr, "decode: %s\n", st.msg);
        CHECK(dec);
        if (dec) mx_check_close("decoded image", img, img_want, nimg, 1e-4);
        free(img);
        mx_sched_free(&s);
        /* two ControlNets at 0.5 and 0.3 sum to the one at 0.8 (residuals are linear in the scale) */
        float *lat2 = golden_f32(&in, "latents", NULL);
        CHECK(lat2 && mx_sched_init(&s, c, &scfg, 6, nlat, &st) == 0);
        mx_sd_control two[2] = {{n->cnet, ctl, 0.5f, NULL}, {n->cnet, ctl, 0.3f, NULL}};
        rq.controls = two;
        rq.n_controls = 2;
        rq.progress = NULL;
        CHECK(lat2 && mx_sd_denoise(&rq, c, lat2, 1, 8, 8, &st) == 0);
        if (lat2) mx_check_close("two ControlNets, 0.5 + 0.3", lat2, after + 5 * nlat, nlat, 1e-4);
        free(lat2);
        lat2 = golden_f32(&in, "latents", NULL);
        if (lat2) check_one_download(rq, c, &scfg, lat2, nlat);
        free(lat2);
        check_item_weights(&rq, c, &scfg, &in, ctl, cond, unc, after + 5 * nlat, nlat, n->cnet);
        rq.controls = &control;
        rq.n_controls = 1;
        rq.progress = on_step;
        mx_sched_free(&s);
        /* a progress callback that returns non-zero stops the loop with an error */
        CHECK(mx_sched_init(&s, c, &scfg, 6, nlat, &st) == 0);
        step_check cancel = {NULL, 0, 0, 0, 1};
        rq.sched = &s;
        rq.progress_user = &cancel;
        CHECK(mx_sd_denoise(&rq, c, lat, 1, 8, 8, &st) != 0 && cancel.steps_seen == 2);
        CHECK(strstr(st.msg, "cancelled") != NULL);
        /* a scheduler sized for other latents is refused */
        mx_sched_free(&s);
        CHECK(mx_sched_init(&s, c, &scfg, 6, nlat * 2, &st) == 0);
        rq.progress = NULL;
        CHECK(mx_sd_denoise(&rq, c, lat, 1, 8, 8, &st) != 0);
        mx_sched_free(&s);
    }
    free(lat);
    free(ctl);
    free(cond);
    free(unc);
    free(ts);
    free(after);
    free(img_want);
    free(sched_text);
    mx_st_close(&in);
    mx_st_close(&out);
}

int main(void) {
    return tiny_nets_main("test_nn_pipeline", TINY_UNET | TINY_CONTROLNET | TINY_VAE | TINY_CLIP, test_pipeline);
}
