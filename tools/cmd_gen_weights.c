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

#include "../ops/ops.h"
#include "../runtime/atomic_file.h"
#include "../runtime/fileio.h"
#include "../pipeline/nn/netcfg.h"
#include "../pipeline/nn/params.h"
#include "../runtime/log.h"
#include "../weights/golden_rule.h"
#include "cli.h"
#include "cli_args.h"

#define CHUNK ((size_t)1 << 20)

static void usage(FILE *f) {
    fprintf(f, "usage: matex gen-weights CONFIG.json --seed N -o OUT.safetensors [--dtype f32|f16]\n"
               "\n"
               "Writes the golden-v1 rule weights (the rule: tests/data/golden/README.md in the source tree)\n"
               "of the network a diffusers / transformers config.json describes (UNet2DConditionModel,\n"
               "ControlNetModel, AutoencoderKL, CLIPTextModel), with the reference state-dict names, so that\n"
               "  mkdir d; cp CONFIG.json d/config.json; matex gen-weights CONFIG.json --seed 1 -o d/diffusion_pytorch_model.safetensors\n"
               "  matex convert d -o w.mxw\n"
               "works.\n\n"
               "  --seed N        rule seed (default 1)\n"
               "  --dtype f32|f16 stored type (default f32; f16 rounds to nearest even)\n"
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

/* Generates every tensor chunk by chunk into fp. */
static int write_tensors(FILE *fp, const mx_binder *b, uint64_t seed, int f16, float *buf, uint16_t *hbuf) {
    for (size_t i = 0; i < mx_binder_enum_count(b); i++) {
        const mx_param_info *p = mx_binder_enum_at(b, i);
        uint64_t numel = (uint64_t)mx_shape_numel(p->ndim, p->shape);
        for (uint64_t at = 0; at < numel; at += CHUNK) {
            size_t cnt = numel - at < CHUNK ? (size_t)(numel - at) : CHUNK;
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

static int write_file(const char *path, const mx_binder *b, uint64_t seed, int f16, mx_status *st) {
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
                 write_tensors(af.fp, b, seed, f16, buf, hbuf) == 0;
        rc = mx_atomic_close(&af, ok, st);
    }
    free(buf);
    free(hbuf);
    free(hdr);
    return rc;
}

int cmd_gen_weights(int argc, char **argv) {
    const char *config = NULL, *out = NULL, *dtype = "f32";
    uint64_t seed = 1;
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
    mx_binder b;
    size_t len = 0;
    mx_status_clear(&st);
    memset(&b, 0, sizeof b);
    char *text = mx_read_file(config, (size_t)64 << 20, &len, &st);
    int rc = !text || mx_binder_enum(&b, &st) || mx_net_enumerate(&b, text, len, config, &st);
    if (!rc) {
        mx_info("gen-weights: %zu tensors, %.1f M parameters", mx_binder_enum_count(&b), mx_binder_enum_bytes(&b) / 4e6);
        rc = write_file(out, &b, seed, f16, &st);
    }
    free(text);
    mx_binder_free(&b);
    if (rc) {
        fprintf(stderr, "matex gen-weights: %s\n", st.msg);
        return 1;
    }
    return 0;
}
