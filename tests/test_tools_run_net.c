/* `matex convert` + `matex run-net` end to end (the binary ./matex, run from the repo root):
 * unet_tiny (plain, and with ip_adapter_tiny's image guidance), the IP-Adapter's tokens,
 * controlnet_tiny (scale 0.5, inputs written here), vae_tiny, clip_vision_tiny, CLIP's image
 * preprocessing and taesd encode/decode against the golden outputs. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nn_golden.h"

static char tmpdir[256];

static int sh(const char *fmt, const char *a, const char *b) {
    char cmd[2048];
    snprintf(cmd, sizeof cmd, fmt, a, b);
    int rc = system(cmd);
    if (rc) fprintf(stderr, "command failed (%d): %s\n", rc, cmd);
    return rc;
}

/* Converts golden network `net` into tmpdir/net.mxw (fp32). */
static int convert(const char *net) {
    char src[1024], dst[512];
    golden_path(src, sizeof src, net, "");
    snprintf(dst, sizeof dst, "%s/%s.mxw", tmpdir, net);
    return sh("./matex convert %s -o %s --dtype f32 --quiet", src, dst);
}

/* Runs on MX_TEST_DEVICE (cpu-strict under make test). */
static int run_net(const char *args, const char *out) {
    char cmd[2300];
    mx_backend_kind device = golden_device();
    snprintf(cmd, sizeof cmd, "./matex run-net %s --device %s --out %s/%s 2>/dev/null", args, mx_backend_name(device),
             tmpdir, out);
    int rc = system(cmd);
    if (rc) fprintf(stderr, "command failed (%d): %s\n", rc, cmd);
    return rc;
}

/* run-net NET on weight file `weights` and input file `inputs` into tmpdir/out. */
static void run_entry(const char *net, const char *weights, const char *inputs, const char *out) {
    char args[2048];
    snprintf(args, sizeof args, "%s --weights %s --inputs %s", net, weights, inputs);
    CHECK(run_net(args, out) == 0);
}

static void compare(const char *outfile, const char *name, const char *net, const char *ref, const char *refname) {
    char path[512], label[256];
    mx_safetensors got, want;
    mx_status st;
    snprintf(path, sizeof path, "%s/%s", tmpdir, outfile);
    if (mx_st_open(&got, path, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        CHECK(0);
        return;
    }
    CHECK(golden_open(&want, net, ref) == 0);
    size_t ng = 0, nw = 0;
    float *g = golden_f32(&got, name, &ng), *w = golden_f32(&want, refname, &nw);
    CHECK(g && w && ng == nw);
    snprintf(label, sizeof label, "run-net %s %s", net, refname);
    if (g && w && ng == nw) mx_check_close(label, g, w, nw, 1e-4);
    free(g);
    free(w);
    mx_st_close(&got);
    mx_st_close(&want);
}

/* The ControlNet inputs with a single conditioning scale (the golden file stores both). */
static int write_controlnet_inputs(const char *path) {
    mx_safetensors in;
    mx_status st;
    if (golden_open(&in, "controlnet_tiny", "inputs.safetensors")) return -1;
    const char *names[4] = {"sample", "timestep", "encoder_hidden_states", "controlnet_cond"};
    mx_st_out outs[5];
    float *bufs[4] = {0}, scale = 0.5f;
    int ok = 1;
    for (int i = 0; i < 4; i++) {
        const mx_st_tensor *t = mx_st_find(&in, names[i]);
        bufs[i] = golden_f32(&in, names[i], NULL);
        ok = ok && t && bufs[i];
        if (!ok) break;
        outs[i].name = names[i];
        outs[i].dtype = MX_ST_F32;
        outs[i].ndim = t->ndim;
        memcpy(outs[i].shape, t->shape, sizeof t->shape);
        outs[i].data = bufs[i];
    }
    mx_st_out s = {"conditioning_scale", MX_ST_F32, 1, {1}, &scale};
    outs[4] = s;
    if (ok && mx_st_write(path, outs, 5, &st)) {
        fprintf(stderr, "%s\n", st.msg);
        ok = 0;
    }
    for (int i = 0; i < 4; i++) free(bufs[i]);
    mx_st_close(&in);
    return ok ? 0 : -1;
}

int main(void) {
    char args[2048], gin[1024], cnin[512];
    if (access("./matex", X_OK) != 0) {
        fprintf(stderr, "./matex not found: run from the repository root after `make`\n");
        return 1;
    }
    snprintf(tmpdir, sizeof tmpdir, "/tmp/matex_run_net_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;

    CHECK(convert("unet_tiny") == 0);
    golden_path(gin, sizeof gin, "unet_tiny", "inputs.safetensors");
    snprintf(args, sizeof args, "unet --weights %s/unet_tiny.mxw --inputs %s", tmpdir, gin);
    CHECK(run_net(args, "unet.safetensors") == 0);
    compare("unet.safetensors", "out", "unet_tiny", "outputs.safetensors", "out_plain");

    /* the UNet with its companion IP-Adapter (found by kind in the same file), and the adapter's own entry */
    char adapter[1024], unet_dir[1024], ipw[512];
    golden_path(adapter, sizeof adapter, "ip_adapter_tiny", "ip_adapter.safetensors");
    golden_path(unet_dir, sizeof unet_dir, "unet_tiny", "");
    snprintf(ipw, sizeof ipw, "%s/unet_ip.mxw", tmpdir);
    snprintf(args, sizeof args, "%s -o %s --dtype f32 --quiet --ip-adapter ", unet_dir, ipw);
    CHECK(sh("./matex convert %s%s", args, adapter) == 0);
    golden_path(gin, sizeof gin, "ip_adapter_tiny", "inputs.safetensors");
    run_entry("ip-adapter", ipw, gin, "ip.safetensors");
    compare("ip.safetensors", "image_tokens", "ip_adapter_tiny", "outputs.safetensors", "image_tokens");
    run_entry("unet", ipw, gin, "unet_ip.safetensors");
    compare("unet_ip.safetensors", "out", "ip_adapter_tiny", "outputs.safetensors", "out_scale_1_0");
    compare("unet_ip.safetensors", "image_tokens", "ip_adapter_tiny", "outputs.safetensors", "image_tokens");

    CHECK(convert("controlnet_tiny") == 0);
    snprintf(cnin, sizeof cnin, "%s/cn_inputs.safetensors", tmpdir);
    CHECK(write_controlnet_inputs(cnin) == 0);
    snprintf(args, sizeof args, "controlnet --weights %s/controlnet_tiny.mxw --inputs %s", tmpdir, cnin);
    CHECK(run_net(args, "cn.safetensors") == 0);
    compare("cn.safetensors", "down_block_res_sample.3", "controlnet_tiny", "outputs.safetensors",
            "scale1.down_block_res_sample.3");
    compare("cn.safetensors", "mid_block_res_sample", "controlnet_tiny", "outputs.safetensors",
            "scale1.mid_block_res_sample");

    CHECK(convert("vae_tiny") == 0);
    golden_path(gin, sizeof gin, "vae_tiny", "inputs.safetensors");
    snprintf(args, sizeof args, "vae-decode --weights %s/vae_tiny.mxw --inputs %s", tmpdir, gin);
    CHECK(run_net(args, "dec.safetensors") == 0);
    compare("dec.safetensors", "image", "vae_tiny", "outputs.safetensors", "decode");
    snprintf(args, sizeof args, "vae-encode --weights %s/vae_tiny.mxw --inputs %s", tmpdir, gin);
    CHECK(run_net(args, "enc.safetensors") == 0);
    compare("enc.safetensors", "mean", "vae_tiny", "outputs.safetensors", "encode.mean");
    compare("enc.safetensors", "logvar", "vae_tiny", "outputs.safetensors", "encode.logvar");

    CHECK(convert("clip_vision_tiny") == 0); /* a single network folder: its model_type names it */
    golden_path(gin, sizeof gin, "clip_vision_tiny", "inputs.safetensors");
    snprintf(args, sizeof args, "clip-vision --weights %s/clip_vision_tiny.mxw --inputs %s", tmpdir, gin);
    CHECK(run_net(args, "cv.safetensors") == 0);
    const char *cv_outputs[3] = {"image_embeds", "last_hidden_state", "penultimate_hidden_state"};
    for (int i = 0; i < 3; i++)
        compare("cv.safetensors", cv_outputs[i], "clip_vision_tiny", "outputs.safetensors", cv_outputs[i]);
    golden_path(gin, sizeof gin, "clip_image_preprocess_tiny", "inputs.safetensors");
    snprintf(args, sizeof args, "clip-preprocess --size 32 --inputs %s", gin);
    CHECK(run_net(args, "pre.safetensors") == 0);
    compare("pre.safetensors", "pixel_values", "clip_image_preprocess_tiny", "outputs.safetensors", "pixel_values");

    if (golden_have("taesd", "outputs.safetensors")) { /* the full-size TAESD lives outside the repository */
        CHECK(convert("taesd") == 0);
        golden_path(gin, sizeof gin, "taesd", "inputs.safetensors");
        snprintf(args, sizeof args, "taesd-decode --weights %s/taesd.mxw --inputs %s", tmpdir, gin);
        CHECK(run_net(args, "tdec.safetensors") == 0);
        compare("tdec.safetensors", "image", "taesd", "outputs.safetensors", "image_dec");
        snprintf(args, sizeof args, "taesd-encode --weights %s/taesd.mxw --inputs %s", tmpdir, gin);
        CHECK(run_net(args, "tenc.safetensors") == 0);
        compare("tenc.safetensors", "latents", "taesd", "outputs.safetensors", "latents_enc");
    }

    sh("rm -rf %s%s", tmpdir, "");
    return mx_test_finish("test_tools_run_net");
}
