#include "models.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../nn/netcfg.h"
#include "../nn/sd_pipeline.h"
#include "digest.h"

static const char *config_text(const mx_weightfile *wf, const char *prefix, mx_status *st) {
    char key[96];
    snprintf(key, sizeof key, "%sconfig", prefix);
    const char *text = mx_wf_meta(wf, key);
    if (!text)
        mx_fail(st, MX_EINPUT, "%s: no network '%.*s' in this weight file (metadata '%s' missing)", mx_wf_path(wf),
                (int)strlen(prefix) - 1, prefix, key);
    return text;
}

/* 1 when the file holds a network with this prefix. */
static int has_network(const mx_weightfile *wf, const char *prefix) {
    char key[96];
    snprintf(key, sizeof key, "%sconfig", prefix);
    return mx_wf_meta(wf, key) != NULL;
}

/* The binder of one network: the weight file's, and the device one over it (slot i). */
static int bind_net(mx_models *m, int i, mx_binder *b, const char *prefix, mx_status *st) {
    return mx_binder_wf(&m->wf_binders[i], m->wf, prefix, st) || mx_binder_device(b, &m->wf_binders[i], m->c, st) ? -1
                                                                                                                 : 0;
}

static int load_clip(mx_models *m, mx_status *st) {
    const char *text = config_text(m->wf, "text_encoder.", st);
    if (!text) return -1;
    mx_clip_config cfg;
    if (mx_clip_config_parse(&cfg, text, strlen(text), mx_wf_path(m->wf), st)) return -1;
    if (bind_net(m, 0, &m->b_clip, "text_encoder.", st)) return -1;
    if (mx_clip_load(&m->clip, &cfg, &m->b_clip, st)) return -1;
    m->clip_loaded = 1;
    return 0;
}

static int load_unet_like(mx_models *m, const char *prefix, int controlnet, int slot, mx_binder *b, void **out,
                          mx_status *st) {
    const char *text = config_text(m->wf, prefix, st);
    if (!text) return -1;
    mx_unet_config cfg;
    if (mx_unet_config_parse(&cfg, text, strlen(text), mx_wf_path(m->wf), st)) return -1;
    if (cfg.is_controlnet != controlnet)
        return mx_fail(st, MX_EINPUT, "%s: network '%s' is a %s, expected a %s", mx_wf_path(m->wf), prefix,
                       cfg.is_controlnet ? "ControlNetModel" : "UNet2DConditionModel",
                       controlnet ? "ControlNetModel" : "UNet2DConditionModel");
    if (bind_net(m, slot, b, prefix, st)) return -1;
    if (controlnet) return mx_controlnet_load((mx_controlnet **)out, &cfg, b, st);
    return mx_unet_load((mx_unet **)out, &cfg, b, st);
}

static int load_vae(mx_models *m, mx_status *st) {
    const char *text = config_text(m->wf, "vae.", st);
    if (!text) return -1;
    mx_vae_config cfg;
    if (mx_vae_config_parse(&cfg, text, strlen(text), mx_wf_path(m->wf), st)) return -1;
    if (bind_net(m, 4, &m->b_vae, "vae.", st)) return -1;
    return mx_vae_load(&m->vae, &cfg, &m->b_vae, st);
}

static int load_taesd(mx_models *m, mx_status *st) {
    m->lcm = mx_wf_meta(m->wf, "unet.lcm_lora") != NULL;
    if (!has_network(m->wf, "taesd.")) return 0;
    const char *text = config_text(m->wf, "taesd.", st);
    mx_taesd_config cfg;
    if (mx_taesd_config_parse(&cfg, text, strlen(text), mx_wf_path(m->wf), st)) return -1;
    if (bind_net(m, 5, &m->b_taesd, "taesd.", st)) return -1;
    return mx_taesd_load(&m->taesd, &cfg, &m->b_taesd, st);
}

static int load_ip_adapter(mx_models *m, mx_status *st) {
    if (!has_network(m->wf, "ip_adapter.")) return 0;
    const char *text = config_text(m->wf, "ip_adapter.", st);
    if (bind_net(m, 6, &m->b_ip, "ip_adapter.", st) ||
        mx_ip_adapter_load(&m->ip_adapter, text, strlen(text), mx_wf_path(m->wf), &m->b_ip, st) ||
        mx_unet_check_ip(m->unet, m->ip_adapter, st))
        return mx_fail_prefix(st, "%s: ip_adapter", mx_wf_path(m->wf));
    return 0;
}

/* The style images' encoder and its preprocessing: CLIP's defaults at the tower's image size, or
 * the folder's preprocessor_config.json that convert stored as "image_encoder.processor". */
static int load_image_encoder(mx_models *m, mx_status *st) {
    if (!has_network(m->wf, "image_encoder.")) return 0;
    const char *text = config_text(m->wf, "image_encoder.", st), *processor = mx_wf_meta(m->wf, "image_encoder.processor");
    void *net = NULL;
    int rc = bind_net(m, 7, &m->b_image, "image_encoder.", st) ||
             mx_clip_vision_load_config(&net, text, strlen(text), mx_wf_path(m->wf), &m->b_image, st);
    m->image_encoder = net; /* also after a failure: mx_models_free destroys it */
    if (rc) return mx_fail_prefix(st, "%s: image_encoder", mx_wf_path(m->wf));
    mx_clip_image_config_default(&m->image_processor);
    m->image_processor.size = m->image_encoder->cfg.image_size;
    if (processor && mx_clip_image_config_parse(&m->image_processor, processor, strlen(processor),
                                                "image_encoder.processor", st))
        return mx_fail_prefix(st, "%s", mx_wf_path(m->wf));
    return 0;
}

static int load_scheduler(mx_models *m, mx_status *st) {
    const char *text = mx_wf_meta(m->wf, "scheduler.config");
    if (!text) {
        mx_sched_config_sd15(&m->sched);
        return 0;
    }
    return mx_sched_config_parse(&m->sched, text, strlen(text), mx_wf_path(m->wf), st);
}

static int load_controlnets(mx_models *m, int needs, mx_status *st) {
    const char *depth_prefix = has_network(m->wf, "controlnet_depth.") ? "controlnet_depth."
                               : has_network(m->wf, "controlnet.")     ? "controlnet."
                                                                       : NULL;
    if (depth_prefix && load_unet_like(m, depth_prefix, 1, 2, &m->b_depth, (void **)&m->cn_depth, st)) return -1;
    if (has_network(m->wf, "controlnet_inpaint.") &&
        load_unet_like(m, "controlnet_inpaint.", 1, 3, &m->b_inpaint, (void **)&m->cn_inpaint, st))
        return -1;
    return mx_models_check(m, needs, st);
}

int mx_models_check(const mx_models *m, int needs, mx_status *st) {
    if ((needs & MX_MODELS_NEED_DEPTH) && !m->cn_depth)
        return mx_fail(st, MX_EINPUT, "%s: no depth ControlNet (controlnet_depth.*) in this weight file",
                       mx_wf_path(m->wf));
    if ((needs & MX_MODELS_NEED_INPAINT) && !m->cn_inpaint)
        return mx_fail(st, MX_EINPUT, "%s: no inpainting ControlNet (controlnet_inpaint.*) in this weight file",
                       mx_wf_path(m->wf));
    return 0;
}

const char *mx_models_path(const mx_models *m) { return mx_wf_path(m->wf); }

int mx_models_load(mx_models *m, const mx_ctx *c, const char *path, int needs, mx_status *st) {
    memset(m, 0, sizeof *m);
    m->c = c;
    if (mx_wf_open(&m->wf, path, st)) return -1;
    if (mx_tok_load_weights(&m->tok, m->wf, st) || load_clip(m, st) ||
        load_unet_like(m, "unet.", 0, 1, &m->b_unet, (void **)&m->unet, st) || load_controlnets(m, needs, st) ||
        load_vae(m, st) || load_taesd(m, st) || load_ip_adapter(m, st) || load_image_encoder(m, st) ||
        load_scheduler(m, st)) {
        mx_models_free(m);
        return -1;
    }
    int text_dim = m->clip.cfg.hidden_size, cross = mx_unet_cfg(m->unet)->cross_attention_dim;
    if (text_dim != cross) {
        mx_fail(st, MX_EINPUT, "%s: text encoder width %d does not match the UNet's cross-attention dim %d", path,
                text_dim, cross);
        mx_models_free(m);
        return -1;
    }
    mx_file_digest_hex(c ? c->pool : NULL, path, m->digest);
    return 0;
}

int mx_models_pack_weights(mx_ctx *c, mx_status *st) {
    return mx_ctx_pack_weights(c, MX_MODELS_PACK_EXTRA, 1, st);
}

void mx_models_free(mx_models *m) {
    if (m->clip_loaded) mx_clip_free(&m->clip);
    mx_unet_free(m->unet);
    mx_controlnet_free(m->cn_depth);
    mx_controlnet_free(m->cn_inpaint);
    mx_vae_free(m->vae);
    mx_taesd_free(m->taesd);
    mx_ip_adapter_free(m->ip_adapter);
    mx_clip_vision_destroy(m->image_encoder);
    mx_binder_free(&m->b_clip);
    mx_binder_free(&m->b_unet);
    mx_binder_free(&m->b_depth);
    mx_binder_free(&m->b_inpaint);
    mx_binder_free(&m->b_vae);
    mx_binder_free(&m->b_taesd);
    mx_binder_free(&m->b_ip);
    mx_binder_free(&m->b_image);
    for (int i = 0; i < 8; i++) mx_binder_free(&m->wf_binders[i]);
    mx_tok_free(m->tok);
    mx_wf_close(m->wf);
    memset(m, 0, sizeof *m);
}

int mx_models_text_dim(const mx_models *m) { return m->clip.cfg.hidden_size; }

int mx_models_encode_text(const mx_models *m, const mx_ctx *c, const char *text, float *out, int *n_dropped,
                          mx_status *st) {
    return mx_sd_encode_prompts(c, &m->clip, m->tok, &text, 1, out, n_dropped, st);
}
