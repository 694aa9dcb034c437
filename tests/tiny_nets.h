/* The tiny golden networks a pipeline test needs (golden/unet_tiny, controlnet_tiny, vae_tiny,
 * clip_tiny, taesd_tiny), each loaded from its config.json and diffusers weights, and the main of
 * such a test: a golden context, the networks, the test, everything freed. Header-only (each test
 * is one program); include after nn_golden.h. */
#ifndef MX_TEST_TINY_NETS_H
#define MX_TEST_TINY_NETS_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/clip.h"
#include "../pipeline/nn/controlnet.h"
#include "../pipeline/nn/taesd.h"
#include "../pipeline/nn/unet.h"
#include "../pipeline/nn/vae.h"
#include "nn_golden.h"

enum { TINY_UNET = 1, TINY_CONTROLNET = 2, TINY_VAE = 4, TINY_CLIP = 8, TINY_TAESD = 16 };

typedef struct tiny_nets {
    golden_weights w[5]; /* one slot per network, in the order of the flags */
    mx_unet_config ucfg, ccfg;
    mx_vae_config vcfg;
    mx_clip_config clip_cfg;
    mx_taesd_config tcfg;
    mx_unet *unet;
    mx_controlnet *cnet;
    mx_vae *vae;
    mx_clip *clip;
    mx_taesd *taesd;
} tiny_nets;

/* Reads golden/<net>/config.json into text and binds slot i to its weights file, through the
 * device binder of c. */
static inline char *tiny_open(tiny_nets *n, int i, const mx_ctx *c, const char *net, const char *file, size_t *len,
                              mx_status *st) {
    char *text = golden_text(net, "config.json", len);
    if (!text) return mx_fail(st, MX_EINPUT, "%s/config.json is missing", net), NULL;
    if (golden_weights_open(&n->w[i], c, net, file, st)) {
        free(text);
        return NULL;
    }
    return text;
}

/* Loads the networks named by `which` (TINY_* flags) for context c (weights on its device); on
 * failure st says why and tiny_nets_free still frees what was loaded. */
static inline int tiny_nets_load(tiny_nets *n, const mx_ctx *c, int which, mx_status *st) {
    static const char *const names[5] = {"unet_tiny", "controlnet_tiny", "vae_tiny", "clip_tiny", "taesd_tiny"};
    memset(n, 0, sizeof *n);
    for (int i = 0; i < 5; i++) {
        if (!(which & (1 << i))) continue;
        size_t len;
        char *t = tiny_open(n, i, c, names[i], i == 3 ? "model.safetensors" : "diffusion_pytorch_model.safetensors", &len, st);
        int rc = !t;
        if (!rc && i == 0)
            rc = mx_unet_config_parse(&n->ucfg, t, len, names[i], st) || mx_unet_load(&n->unet, &n->ucfg, &n->w[i].dev, st);
        if (!rc && i == 1)
            rc = mx_unet_config_parse(&n->ccfg, t, len, names[i], st) ||
                 mx_controlnet_load(&n->cnet, &n->ccfg, &n->w[i].dev, st);
        if (!rc && i == 2)
            rc = mx_vae_config_parse(&n->vcfg, t, len, names[i], st) || mx_vae_load(&n->vae, &n->vcfg, &n->w[i].dev, st);
        if (!rc && i == 3) {
            rc = mx_clip_config_parse(&n->clip_cfg, t, len, names[i], st) ||
                 mx_clip_load(&n->clip, &n->clip_cfg, &n->w[i].dev, st);
        }
        if (!rc && i == 4)
            rc = mx_taesd_config_parse(&n->tcfg, t, len, names[i], st) || mx_taesd_load(&n->taesd, &n->tcfg, &n->w[i].dev, st);
        free(t);
        if (rc) return -1;
    }
    return 0;
}

static inline void tiny_nets_free(tiny_nets *n) {
    mx_unet_free(n->unet);
    mx_controlnet_free(n->cnet);
    mx_vae_free(n->vae);
    mx_clip_free(n->clip);
    mx_taesd_free(n->taesd);
    for (int i = 0; i < 5; i++) golden_weights_close(&n->w[i]);
}

/* The whole main of a pipeline test named `name`. */
static inline int tiny_nets_main(const char *name, int which, void (*test)(const tiny_nets *n, const mx_ctx *c)) {
    mx_ctx c;
    mx_status st = {0};
    tiny_nets n;
    if (golden_ctx(&c)) return 1;
    int ok = tiny_nets_load(&n, &c, which, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    if (ok) test(&n, &c);
    tiny_nets_free(&n);
    mx_ctx_destroy(&c);
    return mx_test_finish(name);
}

#endif
