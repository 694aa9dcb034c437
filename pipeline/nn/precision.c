/* The bf16 precision policy (precision.h). */
#include "precision.h"

#include <string.h>

#include "../../weights/networks.h"

/* The fp32 convolutions of UNet and ControlNet by parameter path: first component... */
static const char *const fp32_first[] = {"conv_in", "controlnet_cond_embedding", "controlnet_down_blocks",
                                         "controlnet_mid_block"};
/* ...or last component... */
static const char *const fp32_last[] = {"conv_shortcut", "proj_in", "proj_out"};
/* ...or any component ("down_blocks.0.downsamplers.0.conv"). */
static const char *const fp32_any[] = {"downsamplers"};

static int first_is(const char *path, const char *name) {
    size_t n = strlen(name);
    return !strncmp(path, name, n) && (path[n] == '\0' || path[n] == '.');
}

static int has_component(const char *path, const char *name) {
    size_t n = strlen(name);
    for (const char *p = path; (p = strstr(p, name)) != NULL; p += n)
        if ((p == path || p[-1] == '.') && (p[n] == '\0' || p[n] == '.')) return 1;
    return 0;
}

static int last_is(const char *path, const char *name) {
    const char *dot = strrchr(path, '.');
    return !strcmp(dot ? dot + 1 : path, name);
}

int mx_prec_conv_fp32(const char *path) {
    for (size_t i = 0; i < sizeof fp32_first / sizeof *fp32_first; i++)
        if (first_is(path, fp32_first[i])) return 1;
    for (size_t i = 0; i < sizeof fp32_last / sizeof *fp32_last; i++)
        if (last_is(path, fp32_last[i])) return 1;
    for (size_t i = 0; i < sizeof fp32_any / sizeof *fp32_any; i++)
        if (has_component(path, fp32_any[i])) return 1;
    return 0;
}

int mx_prec_vae_up_block_bf16(int level, int nlevels) { return level >= nlevels - 2; }

/* The networks that run in fp32 throughout under a bf16 context. */
static const char *const fp32_nets[] = {MX_NET_VAE};

int mx_prec_net_fp32(const char *kind) {
    for (size_t i = 0; kind && i < sizeof fp32_nets / sizeof *fp32_nets; i++)
        if (!strcmp(kind, fp32_nets[i])) return 1;
    return 0;
}
