/* The networks matex runs (registry.h): one entry per run. */
#include "registry.h"

#include <stdio.h>
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
static void clip_free(void *n) { mx_clip_free(n); }
static void clip_vision_free(void *n) { mx_clip_vision_free(n); }
static void ip_adapter_free(void *n) { mx_ip_adapter_free(n); }

#define CONDITIONING "sample [B,C,H,W], timestep [B] or [1] (I64, I32 or F32),\n               encoder_hidden_states [B,T,D]"

const mx_net_def mx_nets[] = {
    {"unet", MX_NET_UNET,
     CONDITIONING ",\n               optional down_block_res_sample.{i} and mid_block_res_sample,\n"
                  "               optional image_embeds [B,n_images,E] + ip_adapter_scale [1] (the file's ip_adapter.)\n"
                  "               -> out (+ image_tokens [B,n_images,tokens,D])",
     mx_unet_slots, mx_unet_more_slots, mx_unet_load_config, mx_unet_arena_io, mx_unet_run_io, unet_free},
    {"controlnet", MX_NET_CONTROLNET,
     "sample, timestep, encoder_hidden_states (as unet), controlnet_cond [B,3,8H,8W],\n"
     "               conditioning_scale (one float, default 1)\n"
     "               -> down_block_res_sample.{i}, mid_block_res_sample",
     mx_controlnet_slots, mx_controlnet_more_slots, mx_controlnet_load_config, mx_controlnet_arena_io, mx_controlnet_run_io, controlnet_free},
    {"vae-encode", MX_NET_VAE, "image [B,3,H,W] in [-1,1] -> mean, logvar", mx_vae_encode_slots, NULL, mx_vae_load_config, mx_vae_encode_arena_io,
     mx_vae_encode_run_io, vae_free},
    {"vae-decode", MX_NET_VAE, "latents [B,4,h,w] (unscaled) -> image", mx_vae_decode_slots, NULL, mx_vae_load_config, mx_vae_decode_arena_io,
     mx_vae_decode_run_io, vae_free},
    {"clip", MX_NET_TEXT_ENCODER,
     "input_ids [B,T] (I64 or I32) -> last_hidden_state, pooler_output, hidden_states.{i}", mx_clip_slots,
     mx_clip_more_slots, mx_clip_load_config,
     mx_clip_arena_io, mx_clip_run_io, clip_free},
    {"taesd-encode", MX_NET_TAESD, "image [B,3,H,W] in [-1,1] -> latents (SD latents, scaling factor 1)",
     mx_taesd_encode_slots, NULL, mx_taesd_load_config, mx_taesd_encode_arena_io, mx_taesd_encode_run_io, taesd_free},
    {"taesd-decode", MX_NET_TAESD, "latents [B,4,h,w] -> image (in about [-1,1], unclamped)", mx_taesd_decode_slots,
     NULL, mx_taesd_load_config,
     mx_taesd_decode_arena_io, mx_taesd_decode_run_io, taesd_free},
    {"clip-vision", MX_NET_IMAGE_ENCODER,
     "pixel_values [B,3,S,S] (clip-preprocess) -> image_embeds [B,P],\n"
     "               last_hidden_state, penultimate_hidden_state [B,1+(S/patch)^2,D]",
     mx_clip_vision_slots, NULL, mx_clip_vision_load_config, mx_clip_vision_arena_io, mx_clip_vision_run_io, clip_vision_free},
    {"ip-adapter", MX_NET_IP_ADAPTER,
     "image_embeds [B,n_images,E] -> image_tokens [B,n_images,tokens,D] (the UNet's image guidance)",
     mx_ip_adapter_slots, NULL, mx_ip_adapter_load_config, mx_ip_adapter_arena_io, mx_ip_adapter_run_io, ip_adapter_free},
};
const size_t mx_net_count = sizeof mx_nets / sizeof mx_nets[0];

int mx_net_bind(const mx_net_def *def, const void *net, mx_net_io *io, mx_net_slots *s, mx_status *st) {
    *s = (mx_net_slots){0};
    for (const mx_net_slot *p = def->slots; p->name; p++)
        if (mx_net_slots_add(s, p->name, p->flags, st)) return -1;
    if (def->more_slots && def->more_slots(net, s, st)) return -1;
    for (int i = 0; i < s->n; i++) {
        mx_net_bound_slot *b = &s->slot[i];
        if (b->flags & MX_SLOT_OUT) continue;
        b->at = io->find(io, b->name);
        if (b->at < 0 && !(b->flags & MX_SLOT_OPTIONAL))
            return mx_fail(st, MX_EINPUT, "%s: missing input tensor %s", io->source, b->name);
    }
    io->slots = s;
    return 0;
}

const mx_net_def *mx_net_named(const char *name) {
    for (size_t i = 0; name && i < mx_net_count; i++)
        if (!strcmp(mx_nets[i].name, name)) return &mx_nets[i];
    return NULL;
}

const mx_net_def *mx_net_of_kind(const char *kind) {
    for (size_t i = 0; kind && i < mx_net_count; i++)
        if (!strcmp(mx_nets[i].kind, kind)) return &mx_nets[i];
    return NULL;
}

const mx_net_def *mx_net_of_class(const char *class_name) {
    const mx_net_kind *k = mx_net_kind_of_class(class_name);
    return k ? mx_net_of_kind(k->name) : NULL;
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

int mx_net_load_kind(const char *kind, void **net, const mx_weightfile *wf, const char *prefix, mx_binder *b,
                     mx_status *st) {
    char key[96];
    const mx_net_def *def = NULL;
    *net = NULL;
    snprintf(key, sizeof key, "%s.config", prefix ? prefix : kind);
    const char *text = mx_wf_meta(wf, key);
    if (!text)
        return mx_fail(st, MX_EINPUT, "%s: no network '%s' in this weight file (metadata '%s' missing)", mx_wf_path(wf),
                       prefix ? prefix : kind, key);
    int rc = mx_net_load_config(&def, net, text, strlen(text), key, b, st) ? mx_fail_prefix(st, "%s", mx_wf_path(wf)) : 0;
    if (!rc && strcmp(def->kind, kind))
        rc = mx_fail(st, MX_EINPUT, "%s: network '%s' is a %s, expected a %s", mx_wf_path(wf), prefix ? prefix : kind,
                     mx_net_kind_named(def->kind)->class_name, mx_net_kind_named(kind)->class_name);
    if (rc && def) {
        def->free(*net);
        *net = NULL;
    }
    return rc;
}

int mx_net_enumerate(mx_binder *b, const char *text, size_t len, const char *what, mx_status *st) {
    const mx_net_def *def = NULL;
    void *net = NULL;
    if (!b->enumerating) return mx_fail(st, MX_EINTERNAL, "mx_net_enumerate needs an enumerating binder");
    int rc = mx_net_load_config(&def, &net, text, len, what, b, st);
    if (def) def->free(net);
    return rc;
}
