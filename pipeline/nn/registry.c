/* The networks matex runs (registry.h): one entry each. */
#include "registry.h"

#include <string.h>

#include "clip.h"
#include "clip_vision.h"
#include "controlnet.h"
#include "ip_adapter.h"
#include "taesd.h"
#include "unet.h"
#include "vae.h"

/* The typed frees as registry frees. */
static void unet_free(void *n) { mx_unet_free(n); }
static void controlnet_free(void *n) { mx_controlnet_free(n); }
static void vae_free(void *n) { mx_vae_free(n); }
static void taesd_free(void *n) { mx_taesd_free(n); }

#define CONDITIONING "sample [B,C,H,W], timestep [B] or [1] (I64, I32 or F32),\n               encoder_hidden_states [B,T,D]"

const mx_net_def mx_nets[] = {
    {.kind = MX_NET_UNET, .load = mx_unet_load_config, .free = unet_free,
     .verbs = {{"unet", CONDITIONING ",\n               optional down_block_res_sample.{i} and mid_block_res_sample,\n"
                        "               optional image_embeds [B,n_images,E] + ip_adapter_scale [1] (the file's ip_adapter.)\n"
                        "               -> out (+ image_tokens [B,n_images,tokens,D])",
                mx_unet_run_io}}},
    {.kind = MX_NET_CONTROLNET, .load = mx_controlnet_load_config, .free = controlnet_free,
     .verbs = {{"controlnet", "sample, timestep, encoder_hidden_states (as unet), controlnet_cond [B,3,8H,8W],\n"
                              "               conditioning_scale (one float, default 1)\n"
                              "               -> down_block_res_sample.{i}, mid_block_res_sample",
                mx_controlnet_run_io}}},
    {.kind = MX_NET_VAE, .load = mx_vae_load_config, .free = vae_free,
     .verbs = {{"vae-encode", "image [B,3,H,W] in [-1,1] -> mean, logvar", mx_vae_run_encode_io},
               {"vae-decode", "latents [B,4,h,w] (unscaled) -> image", mx_vae_run_decode_io}}},
    {.kind = MX_NET_TEXT_ENCODER, .load = mx_clip_load_config, .free = mx_clip_destroy,
     .verbs = {{"clip", "input_ids [B,T] (I64 or I32) -> last_hidden_state, pooler_output, hidden_states.{i}",
                mx_clip_run_io}}},
    {.kind = MX_NET_TAESD, .load = mx_taesd_load_config, .free = taesd_free,
     .verbs = {{"taesd-encode", "image [B,3,H,W] in [-1,1] -> latents (SD latents, scaling factor 1)",
                mx_taesd_run_encode_io},
               {"taesd-decode", "latents [B,4,h,w] -> image (in about [-1,1], unclamped)", mx_taesd_run_decode_io}}},
    {.kind = MX_NET_IMAGE_ENCODER, .load = mx_clip_vision_load_config, .free = mx_clip_vision_destroy,
     .verbs = {{"clip-vision", "pixel_values [B,3,S,S] (clip-preprocess) -> image_embeds [B,P],\n"
                               "               last_hidden_state, penultimate_hidden_state [B,1+(S/patch)^2,D]",
                mx_clip_vision_run_io}}},
    /* run by the UNet's cross-attentions: run-net unet's image_embeds */
    {.kind = MX_NET_IP_ADAPTER, .load = mx_ip_adapter_load_config, .free = mx_ip_adapter_destroy},
};
const size_t mx_net_count = sizeof mx_nets / sizeof mx_nets[0];

const mx_net_def *mx_net_named(const char *kind) {
    for (size_t i = 0; kind && i < mx_net_count; i++)
        if (!strcmp(mx_nets[i].kind, kind)) return &mx_nets[i];
    return NULL;
}

const mx_net_def *mx_net_of_class(const char *class_name) {
    const mx_net_kind *k = mx_net_kind_of_class(class_name);
    return k ? mx_net_named(k->name) : NULL;
}

const mx_net_verb *mx_net_verb_named(const char *name, const mx_net_def **net) {
    for (size_t i = 0; name && i < mx_net_count; i++)
        for (int v = 0; v < MX_NET_MAX_VERBS && mx_nets[i].verbs[v].name; v++)
            if (!strcmp(mx_nets[i].verbs[v].name, name)) {
                if (net) *net = &mx_nets[i];
                return &mx_nets[i].verbs[v];
            }
    return NULL;
}

int mx_net_load_config(const mx_net_def **def, void **net, const char *text, size_t len, const char *what,
                       mx_binder *b, mx_status *st) {
    char cls[64];
    *net = NULL;
    if (mx_config_class_name(cls, sizeof cls, text, len, what, st)) return -1;
    if (!(*def = mx_net_of_class(cls))) {
        char known[256];
        mx_net_kind_classes(known, sizeof known);
        return mx_fail(st, MX_EINPUT, "%s: \"_class_name\" \"%s\" is not one of %s", what, cls, known);
    }
    return (*def)->load(net, text, len, what, b, st);
}

int mx_net_enumerate(mx_binder *b, const char *text, size_t len, const char *what, mx_status *st) {
    const mx_net_def *def = NULL;
    void *net = NULL;
    if (!b->enumerating) return mx_fail(st, MX_EINTERNAL, "mx_net_enumerate needs an enumerating binder");
    int rc = mx_net_load_config(&def, &net, text, len, what, b, st);
    if (def) def->free(net);
    return rc;
}
