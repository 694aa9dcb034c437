#include "models.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../nn/netcfg.h"
#include "../nn/registry.h"
#include "../nn/sd_pipeline.h"
#include "digest.h"

/* 1 when the file holds a network under this prefix ("controlnet_depth"). */
static int has_network(const mx_weightfile *wf, const char *prefix) {
    char key[96];
    snprintf(key, sizeof key, "%s.config", prefix);
    return mx_wf_meta(wf, key) != NULL;
}

/* Network `kind` under `prefix` (NULL: the kind's name) through its registry entry, its weights
 * kept on the device by binder slot `slot`. */
static int load_net(mx_models *m, const char *kind, const char *prefix, int slot, void **net, mx_status *st) {
    char p[80];
    snprintf(p, sizeof p, "%s.", prefix ? prefix : kind);
    if (mx_binder_wf(&m->wf_binders[slot], m->wf, p, st) ||
        mx_binder_device(&m->binders[slot], &m->wf_binders[slot], m->c, st))
        return -1;
    if (mx_net_load_kind(kind, net, m->wf, prefix, &m->binders[slot], st)) return -1;
    m->kinds[slot] = kind;
    return 0;
}

static int load_taesd(mx_models *m, mx_status *st) {
    m->lcm = mx_wf_meta(m->wf, MX_NET_UNET ".lcm_lora") != NULL;
    return has_network(m->wf, MX_NET_TAESD) ? load_net(m, MX_NET_TAESD, NULL, 5, (void **)&m->taesd, st) : 0;
}

static int load_ip_adapter(mx_models *m, mx_status *st) {
    if (!has_network(m->wf, MX_NET_IP_ADAPTER)) return 0;
    if (load_net(m, MX_NET_IP_ADAPTER, NULL, 6, (void **)&m->ip_adapter, st)) return -1;
    return mx_unet_check_ip(m->unet, m->ip_adapter, st) ? mx_fail_prefix(st, "%s: ip_adapter", mx_wf_path(m->wf)) : 0;
}

/* The style images' encoder and its preprocessing: CLIP's defaults at the tower's image size, or
 * the folder's preprocessor_config.json that convert stored as "image_encoder.processor". */
static int load_image_encoder(mx_models *m, mx_status *st) {
    if (!has_network(m->wf, MX_NET_IMAGE_ENCODER)) return 0;
    const char *processor = mx_wf_meta(m->wf, MX_NET_IMAGE_ENCODER ".processor");
    if (load_net(m, MX_NET_IMAGE_ENCODER, NULL, 7, (void **)&m->image_encoder, st)) return -1;
    mx_clip_image_config_default(&m->image_processor);
    m->image_processor.size = m->image_encoder->cfg.image_size;
    if (processor && mx_clip_image_config_parse(&m->image_processor, processor, strlen(processor),
                                                MX_NET_IMAGE_ENCODER ".processor", st))
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

#define DEPTH_PREFIX MX_NET_CONTROLNET "_depth"
#define INPAINT_PREFIX MX_NET_CONTROLNET "_inpaint"

static int load_controlnets(mx_models *m, int needs, mx_status *st) {
    const char *depth_prefix = has_network(m->wf, DEPTH_PREFIX)        ? DEPTH_PREFIX
                               : has_network(m->wf, MX_NET_CONTROLNET) ? MX_NET_CONTROLNET
                                                                       : NULL;
    if (depth_prefix && load_net(m, MX_NET_CONTROLNET, depth_prefix, 2, (void **)&m->cn_depth, st)) return -1;
    if (has_network(m->wf, INPAINT_PREFIX) &&
        load_net(m, MX_NET_CONTROLNET, INPAINT_PREFIX, 3, (void **)&m->cn_inpaint, st))
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

int mx_models_has_kind(const mx_models *m, const char *kind) {
    for (int i = 0; i < MX_MODELS_NETS; i++)
        if (m->kinds[i] && !strcmp(m->kinds[i], kind)) return 1;
    return 0;
}

const char *mx_models_path(const mx_models *m) { return mx_wf_path(m->wf); }

static void digest_seen(void *arg, const void *buf, size_t n, uint64_t off) {
    mx_digest_stream_add(arg, buf, n, off);
}

/* The weight file onto c's device in one pass (mx_dev_weight_file), its digest from that pass:
 * 1 when streamed, 0 when the backend does not stream files (the digest is then not started). */
static int stream_to_device(mx_models *m, const mx_ctx *c, const char *path, mx_digest_stream *digest,
                            mx_status *st) {
    size_t len;
    const void *map = mx_wf_map(m->wf, &len);
    mx_digest_stream_init(digest, c ? c->pool : NULL, len);
    mx_stream_observer obs = {digest_seen, digest};
    return mx_dev_weight_file(c, mx_wf_fd(m->wf), map, len, path, &obs, st);
}

int mx_models_load(mx_models *m, const mx_ctx *c, const char *path, int needs, mx_status *st) {
    memset(m, 0, sizeof *m);
    m->c = c;
    if (mx_wf_open(&m->wf, path, st)) return -1;
    /* On a GPU the whole file goes to the device in one pass before the networks bind into it,
     * and the digest is taken from that pass; elsewhere the digest reads the file at the end. */
    mx_digest_stream digest;
    int streamed = stream_to_device(m, c, path, &digest, st);
    if (streamed < 0) {
        mx_models_free(m);
        return -1;
    }
    if (mx_tok_load_weights(&m->tok, m->wf, st) || load_net(m, MX_NET_TEXT_ENCODER, NULL, 0, (void **)&m->clip, st) ||
        load_net(m, MX_NET_UNET, NULL, 1, (void **)&m->unet, st) || load_controlnets(m, needs, st) ||
        load_net(m, MX_NET_VAE, NULL, 4, (void **)&m->vae, st) || load_taesd(m, st) || load_ip_adapter(m, st) || load_image_encoder(m, st) ||
        load_scheduler(m, st)) {
        mx_models_free(m);
        return -1;
    }
    int text_dim = m->clip->cfg.hidden_size, cross = mx_unet_cfg(m->unet)->cross_attention_dim;
    if (text_dim != cross) {
        mx_fail(st, MX_EINPUT, "%s: text encoder width %d does not match the UNet's cross-attention dim %d", path,
                text_dim, cross);
        mx_models_free(m);
        return -1;
    }
    if (streamed) mx_digest_stream_hex(&digest, m->digest);
    else mx_file_digest_hex(c ? c->pool : NULL, path, m->digest);
    return 0;
}

int mx_models_pack_weights(mx_ctx *c, mx_status *st) {
    return mx_ctx_pack_weights(c, MX_MODELS_PACK_EXTRA, 1, st);
}

void mx_models_free(mx_models *m) {
    mx_clip_free(m->clip);
    mx_unet_free(m->unet);
    mx_controlnet_free(m->cn_depth);
    mx_controlnet_free(m->cn_inpaint);
    mx_vae_free(m->vae);
    mx_taesd_free(m->taesd);
    mx_ip_adapter_free(m->ip_adapter);
    mx_clip_vision_free(m->image_encoder);
    for (int i = 0; i < MX_MODELS_NETS; i++) {
        mx_binder_free(&m->binders[i]);
        mx_binder_free(&m->wf_binders[i]);
    }
    mx_tok_free(m->tok);
    if (m->wf) {
        size_t len;
        mx_dev_weight_file_drop(m->c, mx_wf_map(m->wf, &len));
    }
    mx_wf_close(m->wf);
    memset(m, 0, sizeof *m);
}

int mx_models_text_dim(const mx_models *m) { return m->clip->cfg.hidden_size; }

int mx_models_encode_text(const mx_models *m, const mx_ctx *c, const char *text, float *out, int *n_dropped,
                          mx_status *st) {
    return mx_sd_encode_prompts(c, m->clip, m->tok, &text, 1, out, n_dropped, st);
}
