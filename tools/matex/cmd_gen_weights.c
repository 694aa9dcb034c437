/* matex gen-weights CONFIG.json --seed N -o W.safetensors [--dtype f32|f16]: the golden-v1
 * random weights (tests/data/golden/README.md) of a network config, in diffusers/transformers
 * naming, as one safetensors file. The parameter list comes from the networks' own load code
 * (enumerating binder); tensors are generated and written one chunk at a time, so memory stays
 * small even for the SD1.5 UNet. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../ops/ops.h"
#include "../../runtime/atomic_file.h"
#include "../../runtime/fileio.h"
#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/params.h"
#include "../../runtime/log.h"
#include "../../weights/golden_rule.h"
#include "../../weights/ip_adapter_file.h"
#include "cli.h"
#include "cli_args.h"

#define CHUNK ((size_t)1 << 20)
/* alpha of the random LCM-LoRA: merged as alpha / rank = 1/8 of up @ down at rank 64, a small change */
#define LCM_LORA_ALPHA 8.0f

static void usage(FILE *f) {
    fprintf(f, "usage: matex gen-weights CONFIG.json --seed N -o OUT.safetensors [--dtype f32|f16] [--lcm-lora RANK]\n"
               "\n"
               "Writes the golden-v1 rule weights (the rule: tests/data/golden/README.md in the source tree)\n"
               "of the network a diffusers / transformers config.json describes (UNet2DConditionModel,\n"
               "ControlNetModel, AutoencoderKL, CLIPTextModel; IPAdapter: matex's config of an IP-Adapter,\n"
               "written as the published file for `convert --ip-adapter`), with the reference names, so that\n"
               "  mkdir d; cp CONFIG.json d/config.json; matex gen-weights CONFIG.json --seed 1 -o d/diffusion_pytorch_model.safetensors\n"
               "  matex convert d -o w.mxw\n"
               "works.\n\n"
               "  --seed N        rule seed (default 1)\n"
               "  --dtype f32|f16 stored type (default f32; f16 rounds to nearest even)\n"
               "  --lcm-lora RANK instead, a random LoRA of this rank for the UNet of the config, in the keys of\n"
               "                  the public LCM-LoRA for SD1.5 (kohya: lora_unet_*.lora_down/lora_up.weight, .alpha\n"
               "                  = 8) over the modules its trainer adapts: for `matex convert --lcm-lora`\n"
               "  -o, --output F  file to write (temporary name, then renamed)\n"
               "  -h, --help      this help\n");
}


/* The safetensors header for the enumerated list: names are plain dotted identifiers. */
static char *build_header(const mx_binder *b, int f16, size_t *hlen, mx_status *st) {
    size_t n = mx_binder_enum_count(b), cap = 64 + n * 256, len = 0;
    char *h = malloc(cap);
    if (!h) return mx_fail(st, MX_ENOMEM, "out of memory"), NULL;
    uint64_t off = 0;
    len += (size_t)snprintf(h + len, cap - len, "{\"__metadata__\":{\"format\":\"pt\"}");
    for (size_t i = 0; i < n; i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        if (strlen(p->name) > 160 || strpbrk(p->name, "\"\\")) {
            free(h);
            return mx_fail(st, MX_EINTERNAL, "parameter name not writable: %s", p->name), NULL;
        }
        uint64_t bytes = (uint64_t)mx_shape_numel(p->ndim, p->shape) * (f16 ? 2 : 4);
        len += (size_t)snprintf(h + len, cap - len, ",\"%s\":{\"dtype\":\"%s\",\"shape\":[", p->name, f16 ? "F16" : "F32");
        for (int d = 0; d < p->ndim; d++) len += (size_t)snprintf(h + len, cap - len, d ? ",%lld" : "%lld", (long long)p->shape[d]);
        len += (size_t)snprintf(h + len, cap - len, "],\"data_offsets\":[%llu,%llu]}", (unsigned long long)off,
                                (unsigned long long)(off + bytes));
        off += bytes;
    }
    len += (size_t)snprintf(h + len, cap - len, "}");
    while (len % 8) h[len++] = ' ';
    *hlen = len;
    return h;
}

/* Generates every tensor chunk by chunk into fp; a LoRA's ".alpha" scalars are `alpha`. */
static int write_tensors(FILE *fp, const mx_binder *b, uint64_t seed, int f16, float alpha, float *buf,
                         uint16_t *hbuf) {
    for (size_t i = 0; i < mx_binder_enum_count(b); i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        uint64_t numel = (uint64_t)mx_shape_numel(p->ndim, p->shape);
        for (uint64_t at = 0; at < numel; at += CHUNK) {
            size_t cnt = numel - at < CHUNK ? (size_t)(numel - at) : CHUNK;
            if (p->ndim == 0 && alpha > 0)
                buf[0] = alpha;
            else
                mx_golden_v1_fill_range(p->name, p->ndim, p->shape, seed, at, cnt, buf);
            if (f16) {
                for (size_t k = 0; k < cnt; k++) hbuf[k] = mx_float_to_half(buf[k]);
                if (fwrite(hbuf, 2, cnt, fp) != cnt) return -1;
            } else if (fwrite(buf, 4, cnt, fp) != cnt) {
                return -1;
            }
        }
    }
    return 0;
}

static int write_file(const char *path, const mx_binder *b, uint64_t seed, int f16, float alpha, mx_status *st) {
    size_t hlen;
    char *hdr = build_header(b, f16, &hlen, st);
    if (!hdr) return -1;
    float *buf = malloc(CHUNK * sizeof *buf);
    uint16_t *hbuf = malloc(CHUNK * sizeof *hbuf);
    mx_atomic_file af;
    int rc = -1;
    if (!buf || !hbuf) {
        mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    } else if (!mx_atomic_open(&af, path, st)) {
        unsigned char len8[8];
        for (int i = 0; i < 8; i++) len8[i] = (unsigned char)((uint64_t)hlen >> (8 * i));
        int ok = fwrite(len8, 1, 8, af.fp) == 8 && fwrite(hdr, 1, hlen, af.fp) == hlen &&
                 write_tensors(af.fp, b, seed, f16, alpha, buf, hbuf) == 0;
        rc = mx_atomic_close(&af, ok, st);
    }
    free(buf);
    free(hbuf);
    free(hdr);
    return rc;
}

/* The modules the LCM-LoRA trainer (diffusers' train_lcm_distill_lora_sd*) adapts in the UNet. */
static const char *const lcm_targets[] = {"to_q", "to_k", "to_v", "to_out.0", "proj_in", "proj_out", "ff.net.0.proj",
                                          "ff.net.2", "conv1", "conv2", "conv_shortcut", "downsamplers.0.conv",
                                          "upsamplers.0.conv", "time_emb_proj"};

static int is_lcm_target(const mx_param_info *p) {
    size_t n = strlen(p->name);
    if ((p->ndim != 2 && p->ndim != 4) || n < 8 || strcmp(p->name + n - 7, ".weight")) return 0;
    for (size_t t = 0; t < sizeof lcm_targets / sizeof lcm_targets[0]; t++) {
        size_t k = strlen(lcm_targets[t]);
        if (n - 7 > k && p->name[n - 8 - k] == '.' && !strncmp(p->name + n - 7 - k, lcm_targets[t], k)) return 1;
    }
    return 0;
}

/* Records in lb the LoRA of rank r for every LCM target of the network in b, in the kohya keys of
 * the published LCM-LoRA for SD1.5: lora_unet_<module with '_'>.lora_down.weight [r, in(, kh, kw)],
 * .lora_up.weight [out, r(, 1, 1)], .alpha (a scalar). */
static int lcm_lora_list(mx_binder *lb, const mx_binder *b, int64_t r, mx_status *st) {
    static const char *const parts[3] = {".lora_down.weight", ".lora_up.weight", ".alpha"};
    mx_wptr unused;
    for (size_t i = 0; i < mx_binder_enum_count(b); i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        if (!is_lcm_target(p)) continue;
        char stem[200];
        int len = snprintf(stem, sizeof stem, "lora_unet_%.*s", (int)(strlen(p->name) - 7), p->name);
        if (len >= (int)sizeof stem) return mx_fail(st, MX_EINTERNAL, "parameter name too long: %s", p->name);
        for (char *c = stem; *c; c++)
            if (*c == '.') *c = '_';
        int conv = p->ndim == 4;
        int64_t shapes[3][4] = {{r, p->shape[1], conv ? p->shape[2] : 0, conv ? p->shape[3] : 0}, {p->shape[0], r, 1, 1}};
        int ndims[3] = {p->ndim, p->ndim, 0};
        for (int k = 0; k < 3; k++) {
            char name[240];
            snprintf(name, sizeof name, "%s%s", stem, parts[k]);
            if (lb->bind(lb, name, ndims[k], shapes[k], &unused, st)) return -1;
        }
    }
    return 0;
}

/* The list of b under the names of the published IP-Adapter file (weights/ip_adapter_file.h). */
static int published_ip_adapter(mx_binder *pb, const mx_binder *b, mx_status *st) {
    mx_wptr unused;
    for (size_t i = 0; i < mx_binder_enum_count(b); i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        char name[240];
        mx_ip_adapter_published_name(p->name, name, sizeof name);
        if (pb->bind(pb, name, p->ndim, p->shape, &unused, st)) return -1;
    }
    return 0;
}

int cmd_gen_weights(int argc, char **argv) {
    const char *config = NULL, *out = NULL, *dtype = "f32";
    uint64_t seed = 1;
    int lora_rank = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        }
        int has_val = i + 1 < argc;
        if (!strcmp(a, "--seed") && has_val) {
            if (mx_arg_u64("gen-weights", a, argv[++i], &seed)) return 2;
        } else if ((!strcmp(a, "-o") || !strcmp(a, "--output")) && has_val) {
            out = argv[++i];
        } else if (!strcmp(a, "--dtype") && has_val) {
            dtype = argv[++i];
        } else if (!strcmp(a, "--lcm-lora") && has_val) {
            if (mx_arg_int("gen-weights", a, argv[++i], 1, 1024, &lora_rank)) return 2;
        } else if (a[0] != '-' && !config) {
            config = a;
        } else {
            fprintf(stderr, "matex gen-weights: unknown or incomplete argument '%s'\n", a);
            usage(stderr);
            return 2;
        }
    }
    int f16 = !strcmp(dtype, "f16") || !strcmp(dtype, "fp16");
    if (!config || !out || (!f16 && strcmp(dtype, "f32") && strcmp(dtype, "fp32"))) {
        fprintf(stderr, "matex gen-weights: %s\n", !config || !out ? "CONFIG and -o are required" : "--dtype must be f32 or f16");
        usage(stderr);
        return 2;
    }
    mx_status st;
    mx_binder b, lb;
    size_t len = 0;
    mx_status_clear(&st);
    memset(&b, 0, sizeof b);
    memset(&lb, 0, sizeof lb);
    char *text = mx_read_file(config, (size_t)64 << 20, &len, &st);
    int rc = !text || mx_binder_enum(&b, &st) || mx_net_enumerate(&b, text, len, config, &st);
    if (!rc) {
        mx_info("gen-weights: %zu tensors, %.1f M parameters", mx_binder_enum_count(&b), mx_binder_enum_bytes(&b) / 4e6);
        char cls[64] = "";
        int ip = !mx_config_class_name(cls, sizeof cls, text, len, config, &st) && !strcmp(cls, "IPAdapter");
        if (lora_rank && strcmp(cls, "UNet2DConditionModel"))
            rc = mx_fail(&st, MX_EINPUT, "%s: --lcm-lora needs a UNet2DConditionModel config, not %s", config, cls);
        else if (lora_rank)
            rc = mx_binder_enum(&lb, &st) || lcm_lora_list(&lb, &b, lora_rank, &st);
        else if (ip)
            rc = mx_binder_enum(&lb, &st) || published_ip_adapter(&lb, &b, &st);
        if (!rc) rc = write_file(out, lora_rank || ip ? &lb : &b, seed, f16, lora_rank ? LCM_LORA_ALPHA : 0, &st);
    }
    free(text);
    mx_binder_free(&b);
    if (lb.impl) mx_binder_free(&lb);
    if (rc) {
        fprintf(stderr, "matex gen-weights: %s\n", st.msg);
        return 1;
    }
    return 0;
}
