/* The view step and the enhancement step against diffusers, through `matex run-net` (the
 * binary ./matex, run from the repository root): a model set of the tiny golden networks
 * (UNet, VAE, CLIP, ControlNet depth = controlnet_tiny, ControlNet inpaint =
 * controlnet_tiny_inpaint) converted with `matex convert`, then
 *   inpaint-pipeline on golden/pipeline_controlnet_inpaint_tiny (latent blending, 6 steps)
 *   img2img-pipeline on golden/pipeline_controlnet_img2img_tiny (strength 0.5 of 10 steps)
 *   inpaint-pipeline with a style image on golden/pipeline_controlnet_inpaint_ip_tiny (the set
 *   converted with --ip-adapter golden/ip_adapter_tiny: image_embeds, ip_adapter_scale 0.6)
 * timesteps equal, latents after EVERY step and the decoded image ≤ 1e-4 rel L2. And run-net unet
 * with image_embeds on golden/ip_adapter_tiny (ip_adapter_scale absent: 1): out_scale_1_0 and
 * image_tokens ≤ 1e-4. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <limits.h>
#include <unistd.h>

#include "nn_golden.h"

static char tmpdir[256];

static int sh(const char *cmd) {
    int rc = system(cmd);
    if (rc) fprintf(stderr, "command failed (%d): %s\n", rc, cmd);
    return rc;
}

/* Absolute path of golden folder NET (tests/data/golden or $MATEX_TESTDATA/golden). */
static int golden_dir(char *buf, size_t cap, const char *net) {
    char rel[1024];
    golden_path(rel, sizeof rel, net, "");
    if (!realpath(rel, buf) || strlen(buf) >= cap) return -1;
    return 0;
}

/* tmpdir/set.mxw: a diffusers model folder of symlinks to the golden networks, converted. */
static int make_model_set(void) {
    static const char *nets[8] = {"unet_tiny", "vae_tiny", "clip_tiny", "tokenizer", "pipeline_controlnet_inpaint_tiny",
                                  "controlnet_tiny", "controlnet_tiny_inpaint", "ip_adapter_tiny"};
    char g[8][PATH_MAX], cmd[9 * PATH_MAX + 1024];
    for (int i = 0; i < 8; i++)
        if (golden_dir(g[i], sizeof g[i], nets[i])) return fprintf(stderr, "golden/%s not found\n", nets[i]), -1;
    snprintf(cmd, sizeof cmd,
             "set -e; D=%s/set; mkdir -p $D/scheduler; ln -s %s $D/unet; ln -s %s $D/vae; ln -s %s $D/text_encoder; "
             "ln -s %s $D/tokenizer; cp %s/scheduler_config.json $D/scheduler/; "
             "./matex convert $D --controlnet depth=%s --controlnet inpaint=%s --ip-adapter %s/ip_adapter.safetensors "
             "--dtype f32 --quiet -o %s/set.mxw",
             tmpdir, g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], tmpdir);
    return sh(cmd);
}

static void compare_case(const char *verb, const char *gcase, int steps) {
    char cmd[2048], gin[1024], out[512], label[128];
    golden_path(gin, sizeof gin, gcase, "inputs.safetensors");
    snprintf(out, sizeof out, "%s/%s.safetensors", tmpdir, verb);
    const char *dev = getenv("MX_TEST_DEVICE");
    snprintf(cmd, sizeof cmd,
             "./matex run-net %s --weights %s/set.mxw --inputs %s --out %s --steps %d --guidance 7.5 --device %s 2>/dev/null",
             verb, tmpdir, gin, out, steps, dev && *dev ? dev : "cpu");
    CHECK(sh(cmd) == 0);
    mx_safetensors got, want;
    mx_status st;
    if (mx_st_open(&got, out, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    if (golden_open(&want, gcase, "outputs.safetensors")) {
        CHECK(0);
        mx_st_close(&got);
        return;
    }
    size_t ng, nw, nts, nwts;
    float *gts = golden_f32(&got, "timesteps", &nts), *wts = golden_f32(&want, "timesteps", &nwts);
    CHECK(gts && wts && nts == nwts && memcmp(gts, wts, nts * sizeof(float)) == 0);
    float *g = golden_f32(&got, "latents_after_step", &ng), *w = golden_f32(&want, "latents_after_step", &nw);
    CHECK(g && w && ng == nw && nwts > 0);
    for (size_t s = 0; g && w && ng == nw && nwts > 0 && s < nwts; s++) {
        size_t per = nw / nwts;
        snprintf(label, sizeof label, "%s latents after step %zu/%zu", gcase, s + 1, nwts);
        mx_check_close(label, g + s * per, w + s * per, per, 1e-4);
    }
    free(g);
    free(w);
    g = golden_f32(&got, "image", &ng);
    w = golden_f32(&want, "image", &nw);
    CHECK(g && w && ng == nw);
    snprintf(label, sizeof label, "%s decoded image", gcase);
    if (g && w && ng == nw) mx_check_close(label, g, w, nw, 1e-4);
    free(g);
    free(w);
    free(gts);
    free(wts);
    mx_st_close(&got);
    mx_st_close(&want);
}

/* run-net unet with image_embeds through the set's IP-Adapter (its UNet is unet_tiny). */
static void compare_unet_ip(void) {
    char cmd[2048], gin[1024], out[512];
    golden_path(gin, sizeof gin, "ip_adapter_tiny", "inputs.safetensors");
    snprintf(out, sizeof out, "%s/unet_ip.safetensors", tmpdir);
    const char *dev = getenv("MX_TEST_DEVICE");
    snprintf(cmd, sizeof cmd, "./matex run-net unet --weights %s/set.mxw --inputs %s --out %s --device %s 2>/dev/null",
             tmpdir, gin, out, dev && *dev ? dev : "cpu");
    CHECK(sh(cmd) == 0);
    mx_safetensors got, want;
    mx_status st;
    if (mx_st_open(&got, out, &st) || golden_open(&want, "ip_adapter_tiny", "outputs.safetensors")) {
        CHECK(0);
        return;
    }
    const char *pairs[2][2] = {{"out", "out_scale_1_0"}, {"image_tokens", "image_tokens"}};
    for (int i = 0; i < 2; i++) {
        size_t ng, nw;
        float *g = golden_f32(&got, pairs[i][0], &ng), *w = golden_f32(&want, pairs[i][1], &nw);
        char label[96];
        snprintf(label, sizeof label, "run-net unet + ip_adapter %s", pairs[i][1]);
        CHECK(g && w && ng == nw);
        if (g && w && ng == nw) mx_check_close(label, g, w, nw, 1e-4);
        free(g);
        free(w);
    }
    mx_st_close(&got);
    mx_st_close(&want);
}

int main(void) {
    if (access("./matex", X_OK) != 0) {
        fprintf(stderr, "./matex not found: run from the repository root after `make`\n");
        return 1;
    }
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_pipeline_edit_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    CHECK(make_model_set() == 0);
    compare_case("inpaint-pipeline", "pipeline_controlnet_inpaint_tiny", 6);
    compare_case("img2img-pipeline", "pipeline_controlnet_img2img_tiny", 10);
    compare_case("inpaint-pipeline", "pipeline_controlnet_inpaint_ip_tiny", 6);
    compare_unet_ip();
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmpdir);
    sh(cmd);
    return mx_test_finish("test_tools_run_net_pipelines");
}
