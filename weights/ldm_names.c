/* LDM <-> diffusers tensor names (ldm_names.h). Each network has its name rules twice, once per
 * direction, next to each other; test_weights_single_file checks that every diffusers name of
 * the golden networks goes to LDM and back unchanged. */
#include "ldm_names.h"

#include <stdio.h>
#include <string.h>

typedef struct {
    const char *ldm, *diffusers;
} name_rule;

/* Whole-prefix renames. */
static const name_rule unet_top[] = {
    {"time_embed.0.", "time_embedding.linear_1."}, {"time_embed.2.", "time_embedding.linear_2."},
    {"input_blocks.0.0.", "conv_in."},             {"out.0.", "conv_norm_out."},
    {"out.2.", "conv_out."},                       {"middle_block_out.0.", "controlnet_mid_block."},
};
static const name_rule unet_resnet[] = {
    {"in_layers.0.", "norm1."},  {"in_layers.2.", "conv1."},  {"emb_layers.1.", "time_emb_proj."},
    {"out_layers.0.", "norm2."}, {"out_layers.3.", "conv2."}, {"skip_connection.", "conv_shortcut."},
};
static const name_rule vae_top[] = {
    {"encoder.conv_in.", "encoder.conv_in."},   {"encoder.conv_out.", "encoder.conv_out."},
    {"encoder.norm_out.", "encoder.conv_norm_out."}, {"decoder.conv_in.", "decoder.conv_in."},
    {"decoder.conv_out.", "decoder.conv_out."}, {"decoder.norm_out.", "decoder.conv_norm_out."},
    {"quant_conv.", "quant_conv."},             {"post_quant_conv.", "post_quant_conv."},
};
static const name_rule vae_resnet[] = {
    {"norm1.", "norm1."}, {"conv1.", "conv1."}, {"norm2.", "norm2."}, {"conv2.", "conv2."},
    {"nin_shortcut.", "conv_shortcut."},
};
static const name_rule vae_attn[] = {
    {"norm.", "group_norm."}, {"q.", "to_q."}, {"k.", "to_k."}, {"v.", "to_v."}, {"proj_out.", "to_out.0."},
};
static const char *const transformer_parts[] = {"norm.", "proj_in.", "proj_out.", "transformer_blocks."};

#define N(a) (sizeof(a) / sizeof((a)[0]))

static int starts(const char *s, const char *pre) { return !strncmp(s, pre, strlen(pre)); }

/* Matches s against pat, where each '#' stands for a decimal index (1-5 digits); the indices go to
 * v[], *rest to what follows. Returns 1 on a match. */
static int match(const char *s, const char *pat, int *v, const char **rest) {
    int k = 0;
    for (; *pat; pat++) {
        if (*pat != '#') {
            if (*s++ != *pat) return 0;
            continue;
        }
        int n = 0, digits = 0;
        while (*s >= '0' && *s <= '9' && digits < 6) n = n * 10 + (*s++ - '0'), digits++;
        if (!digits || digits > 5) return 0;
        v[k++] = n;
    }
    *rest = s;
    return 1;
}

/* Writes out = head + (rest renamed by the table, in the given direction). */
static int put_renamed(char *out, size_t cap, const char *head, const name_rule *t, size_t n, int to_diffusers,
                       const char *rest) {
    for (size_t i = 0; i < n; i++) {
        const char *from = to_diffusers ? t[i].ldm : t[i].diffusers, *to = to_diffusers ? t[i].diffusers : t[i].ldm;
        if (starts(rest, from) && rest[strlen(from)])
            return snprintf(out, cap, "%s%s%s", head, to, rest + strlen(from)) < (int)cap ? 0 : -1;
    }
    return -1;
}

static int put(char *out, size_t cap, const char *head, const char *rest) {
    if (!*rest) return -1;
    return snprintf(out, cap, "%s%s", head, rest) < (int)cap ? 0 : -1;
}

/* A transformer block's inner names are the same in both layouts. */
static int put_transformer(char *out, size_t cap, const char *head, const char *rest) {
    for (size_t i = 0; i < N(transformer_parts); i++)
        if (starts(rest, transformer_parts[i])) return put(out, cap, head, rest);
    return -1;
}

/* ---- UNet and ControlNet ---- */

static int unet_to_diffusers(mx_ldm_net net, const mx_ldm_layout *l, const char *s, char *out, size_t cap) {
    int v[3], per = l->layers_per_block + 1;
    const char *r;
    char head[96];
    if (net == MX_LDM_UNET && starts(s, "middle_block_out.")) return -1;
    if (put_renamed(out, cap, "", unet_top, N(unet_top), 1, s) == 0) return 0;
    if (match(s, "input_blocks.#.#.", v, &r) && v[0] >= 1) {
        int b = (v[0] - 1) / per, k = (v[0] - 1) % per;
        if (b >= l->levels) return -1;
        if (k < l->layers_per_block && v[1] == 0) {
            snprintf(head, sizeof head, "down_blocks.%d.resnets.%d.", b, k);
            return put_renamed(out, cap, head, unet_resnet, N(unet_resnet), 1, r);
        }
        if (k < l->layers_per_block && v[1] == 1) {
            snprintf(head, sizeof head, "down_blocks.%d.attentions.%d.", b, k);
            return put_transformer(out, cap, head, r);
        }
        if (k == l->layers_per_block && v[1] == 0 && starts(r, "op.")) {
            snprintf(head, sizeof head, "down_blocks.%d.downsamplers.0.conv.", b);
            return put(out, cap, head, r + 3);
        }
        return -1;
    }
    if (match(s, "middle_block.#.", v, &r)) {
        if (v[0] == 1) return put_transformer(out, cap, "mid_block.attentions.0.", r);
        if (v[0] != 0 && v[0] != 2) return -1;
        return put_renamed(out, cap, v[0] ? "mid_block.resnets.1." : "mid_block.resnets.0.", unet_resnet,
                           N(unet_resnet), 1, r);
    }
    if (net == MX_LDM_UNET && match(s, "output_blocks.#.#.", v, &r)) {
        int b = v[0] / per, k = v[0] % per;
        if (b >= l->levels) return -1;
        if (v[1] == 0) {
            snprintf(head, sizeof head, "up_blocks.%d.resnets.%d.", b, k);
            return put_renamed(out, cap, head, unet_resnet, N(unet_resnet), 1, r);
        }
        if (starts(r, "conv.") && k == l->layers_per_block && v[1] == ((l->up_attention >> b) & 1 ? 2 : 1)) {
            snprintf(head, sizeof head, "up_blocks.%d.upsamplers.0.", b);
            return put(out, cap, head, r);
        }
        if (v[1] == 1 && (l->up_attention >> b) & 1) {
            snprintf(head, sizeof head, "up_blocks.%d.attentions.%d.", b, k);
            return put_transformer(out, cap, head, r);
        }
        return -1;
    }
    if (net != MX_LDM_CONTROLNET) return -1;
    if (match(s, "zero_convs.#.0.", v, &r)) {
        snprintf(head, sizeof head, "controlnet_down_blocks.%d.", v[0]);
        return put(out, cap, head, r);
    }
    if (match(s, "input_hint_block.#.", v, &r) && v[0] % 2 == 0 && v[0] / 2 < l->hint_convs) {
        int i = v[0] / 2;
        if (i == 0) return put(out, cap, "controlnet_cond_embedding.conv_in.", r);
        if (i == l->hint_convs - 1) return put(out, cap, "controlnet_cond_embedding.conv_out.", r);
        snprintf(head, sizeof head, "controlnet_cond_embedding.blocks.%d.", i - 1);
        return put(out, cap, head, r);
    }
    return -1;
}

static int unet_to_ldm(mx_ldm_net net, const mx_ldm_layout *l, const char *s, char *out, size_t cap) {
    int v[3], per = l->layers_per_block + 1;
    const char *r;
    char head[96];
    if (put_renamed(out, cap, "", unet_top, N(unet_top), 0, s) == 0) return 0;
    if (match(s, "down_blocks.#.resnets.#.", v, &r) && v[1] < l->layers_per_block) {
        snprintf(head, sizeof head, "input_blocks.%d.0.", 1 + v[0] * per + v[1]);
        return put_renamed(out, cap, head, unet_resnet, N(unet_resnet), 0, r);
    }
    if (match(s, "down_blocks.#.attentions.#.", v, &r) && v[1] < l->layers_per_block) {
        snprintf(head, sizeof head, "input_blocks.%d.1.", 1 + v[0] * per + v[1]);
        return put_transformer(out, cap, head, r);
    }
    if (match(s, "down_blocks.#.downsamplers.0.conv.", v, &r)) {
        snprintf(head, sizeof head, "input_blocks.%d.0.op.", 1 + v[0] * per + l->layers_per_block);
        return put(out, cap, head, r);
    }
    if (match(s, "mid_block.resnets.#.", v, &r) && v[0] < 2)
        return put_renamed(out, cap, v[0] ? "middle_block.2." : "middle_block.0.", unet_resnet, N(unet_resnet), 0, r);
    if (starts(s, "mid_block.attentions.0.")) return put_transformer(out, cap, "middle_block.1.", s + 23);
    if (net == MX_LDM_UNET && match(s, "up_blocks.#.resnets.#.", v, &r) && v[1] < per) {
        snprintf(head, sizeof head, "output_blocks.%d.0.", v[0] * per + v[1]);
        return put_renamed(out, cap, head, unet_resnet, N(unet_resnet), 0, r);
    }
    if (net == MX_LDM_UNET && match(s, "up_blocks.#.attentions.#.", v, &r) && v[1] < per) {
        snprintf(head, sizeof head, "output_blocks.%d.1.", v[0] * per + v[1]);
        return put_transformer(out, cap, head, r);
    }
    if (net == MX_LDM_UNET && match(s, "up_blocks.#.upsamplers.0.", v, &r) && starts(r, "conv.")) {
        snprintf(head, sizeof head, "output_blocks.%d.%d.", v[0] * per + l->layers_per_block,
                 (l->up_attention >> v[0]) & 1 ? 2 : 1);
        return put(out, cap, head, r);
    }
    if (net != MX_LDM_CONTROLNET) return -1;
    if (match(s, "controlnet_down_blocks.#.", v, &r)) {
        snprintf(head, sizeof head, "zero_convs.%d.0.", v[0]);
        return put(out, cap, head, r);
    }
    if (starts(s, "controlnet_cond_embedding.conv_in.")) return put(out, cap, "input_hint_block.0.", s + 34);
    if (starts(s, "controlnet_cond_embedding.conv_out.")) {
        snprintf(head, sizeof head, "input_hint_block.%d.", 2 * (l->hint_convs - 1));
        return put(out, cap, head, s + 35);
    }
    if (match(s, "controlnet_cond_embedding.blocks.#.", v, &r)) {
        snprintf(head, sizeof head, "input_hint_block.%d.", 2 * (v[0] + 1));
        return put(out, cap, head, r);
    }
    return -1;
}

/* ---- VAE ---- */

static int vae_to_diffusers(const mx_ldm_layout *l, const char *s, char *out, size_t cap) {
    int v[3];
    const char *r;
    char head[96];
    if (put_renamed(out, cap, "", vae_top, N(vae_top), 1, s) == 0) return 0;
    if (match(s, "encoder.down.#.block.#.", v, &r)) {
        snprintf(head, sizeof head, "encoder.down_blocks.%d.resnets.%d.", v[0], v[1]);
        return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 1, r);
    }
    if (match(s, "encoder.down.#.downsample.conv.", v, &r)) {
        snprintf(head, sizeof head, "encoder.down_blocks.%d.downsamplers.0.conv.", v[0]);
        return put(out, cap, head, r);
    }
    if (match(s, "decoder.up.#.block.#.", v, &r) && v[0] < l->levels) {
        snprintf(head, sizeof head, "decoder.up_blocks.%d.resnets.%d.", l->levels - 1 - v[0], v[1]);
        return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 1, r);
    }
    if (match(s, "decoder.up.#.upsample.conv.", v, &r) && v[0] < l->levels) {
        snprintf(head, sizeof head, "decoder.up_blocks.%d.upsamplers.0.conv.", l->levels - 1 - v[0]);
        return put(out, cap, head, r);
    }
    for (int side = 0; side < 2; side++) {
        const char *coder = side ? "decoder" : "encoder";
        char pat[64];
        snprintf(pat, sizeof pat, "%s.mid.block_#.", coder);
        if (match(s, pat, v, &r) && (v[0] == 1 || v[0] == 2)) {
            snprintf(head, sizeof head, "%s.mid_block.resnets.%d.", coder, v[0] - 1);
            return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 1, r);
        }
        snprintf(pat, sizeof pat, "%s.mid.attn_1.", coder);
        if (starts(s, pat)) {
            snprintf(head, sizeof head, "%s.mid_block.attentions.0.", coder);
            return put_renamed(out, cap, head, vae_attn, N(vae_attn), 1, s + strlen(pat));
        }
    }
    return -1;
}

static int vae_to_ldm(const mx_ldm_layout *l, const char *s, char *out, size_t cap) {
    int v[3];
    const char *r;
    char head[96];
    if (put_renamed(out, cap, "", vae_top, N(vae_top), 0, s) == 0) return 0;
    if (match(s, "encoder.down_blocks.#.resnets.#.", v, &r)) {
        snprintf(head, sizeof head, "encoder.down.%d.block.%d.", v[0], v[1]);
        return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 0, r);
    }
    if (match(s, "encoder.down_blocks.#.downsamplers.0.conv.", v, &r)) {
        snprintf(head, sizeof head, "encoder.down.%d.downsample.conv.", v[0]);
        return put(out, cap, head, r);
    }
    if (match(s, "decoder.up_blocks.#.resnets.#.", v, &r) && v[0] < l->levels) {
        snprintf(head, sizeof head, "decoder.up.%d.block.%d.", l->levels - 1 - v[0], v[1]);
        return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 0, r);
    }
    if (match(s, "decoder.up_blocks.#.upsamplers.0.conv.", v, &r) && v[0] < l->levels) {
        snprintf(head, sizeof head, "decoder.up.%d.upsample.conv.", l->levels - 1 - v[0]);
        return put(out, cap, head, r);
    }
    for (int side = 0; side < 2; side++) {
        const char *coder = side ? "decoder" : "encoder";
        char pat[64];
        snprintf(pat, sizeof pat, "%s.mid_block.resnets.#.", coder);
        if (match(s, pat, v, &r) && v[0] < 2) {
            snprintf(head, sizeof head, "%s.mid.block_%d.", coder, v[0] + 1);
            return put_renamed(out, cap, head, vae_resnet, N(vae_resnet), 0, r);
        }
        snprintf(pat, sizeof pat, "%s.mid_block.attentions.0.", coder);
        if (starts(s, pat)) {
            snprintf(head, sizeof head, "%s.mid.attn_1.", coder);
            return put_renamed(out, cap, head, vae_attn, N(vae_attn), 0, s + strlen(pat));
        }
    }
    return -1;
}

int mx_ldm_vae_attn_linear(const char *s) {
    for (int side = 0; side < 2; side++) {
        const char *pre = side ? "decoder.mid_block.attentions.0." : "encoder.mid_block.attentions.0.";
        if (!starts(s, pre)) continue;
        const char *r = s + strlen(pre);
        return !strcmp(r, "to_q.weight") || !strcmp(r, "to_k.weight") || !strcmp(r, "to_v.weight") ||
               !strcmp(r, "to_out.0.weight");
    }
    return 0;
}

/* ---- CLIP: the transformers names, under text_model. (older files lack that level) ---- */

static int clip_to_diffusers(const char *s, char *out, size_t cap) {
    if (starts(s, "text_model.")) return put(out, cap, "", s);
    if (starts(s, "embeddings.") || starts(s, "encoder.") || starts(s, "final_layer_norm."))
        return put(out, cap, "text_model.", s);
    return -1;
}

int mx_ldm_to_diffusers(mx_ldm_net net, const mx_ldm_layout *l, const char *ldm, char *out, size_t cap) {
    switch (net) {
    case MX_LDM_UNET:
    case MX_LDM_CONTROLNET: return unet_to_diffusers(net, l, ldm, out, cap);
    case MX_LDM_VAE: return vae_to_diffusers(l, ldm, out, cap);
    case MX_LDM_CLIP: return clip_to_diffusers(ldm, out, cap);
    }
    return -1;
}

int mx_diffusers_to_ldm(mx_ldm_net net, const mx_ldm_layout *l, const char *diffusers, char *out, size_t cap) {
    switch (net) {
    case MX_LDM_UNET:
    case MX_LDM_CONTROLNET: return unet_to_ldm(net, l, diffusers, out, cap);
    case MX_LDM_VAE: return vae_to_ldm(l, diffusers, out, cap);
    case MX_LDM_CLIP: return starts(diffusers, "text_model.") ? put(out, cap, "", diffusers) : -1;
    }
    return -1;
}
