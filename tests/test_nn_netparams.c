/* Parameter enumeration (the list gen-weights writes) against the reference state dicts:
 * every tiny/mini golden network's safetensors key set and shapes, and the SD1.5-size
 * weights_checksums.json lists (names, shapes; exact u32_wsum checksums of the rule values
 * for the tensors up to 1M elements). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/registry.h"
#include "../pipeline/nn/params.h"
#include "../runtime/json.h"
#include "../weights/golden_rule.h"
#include "nn_golden.h"

static int enumerate(mx_binder *b, const char *net) {
    mx_status st;
    size_t len;
    char *cfg = golden_text(net, "config.json", &len);
    if (!cfg) return fprintf(stderr, "%s: no config.json\n", net), -1;
    int rc = mx_binder_enum(b, &st) || mx_net_enumerate(b, cfg, len, net, &st);
    if (rc) fprintf(stderr, "%s: %s\n", net, st.msg);
    free(cfg);
    return rc ? -1 : 0;
}

static int same_shape(const mx_param_info *p, int ndim, const int64_t *shape) {
    if (p->ndim != ndim) return 0;
    for (int i = 0; i < ndim; i++)
        if (p->shape[i] != shape[i]) return 0;
    return 1;
}

/* Key set and shapes of a golden weight file equal the enumeration. */
static void check_against_file(const char *net, const char *wfile) {
    mx_binder b;
    mx_safetensors f;
    if (!golden_have(net, wfile)) return;
    int ok = enumerate(&b, net) == 0;
    CHECK(ok);
    if (!ok) return;
    if (golden_open(&f, net, wfile)) {
        CHECK(0);
        mx_binder_free(&b);
        return;
    }
    size_t n = mx_binder_enum_count(&b), bad = 0;
    for (size_t i = 0; i < n; i++) {
        const mx_param_info *p = mx_binder_enum_at(&b, i);
        const mx_st_tensor *t = mx_st_find(&f, p->name);
        if (!t || !same_shape(p, t->ndim, t->shape)) {
            if (bad++ < 5) fprintf(stderr, "%s: %s missing or of another shape\n", net, p->name);
        }
    }
    printf("%-20s %zu parameters enumerated, file has %zu, %zu mismatched\n", net, n, f.count, bad);
    CHECK(bad == 0 && n == f.count);
    mx_st_close(&f);
    mx_binder_free(&b);
}

static void check_against_checksums(const char *net, uint64_t seed) {
    mx_binder b;
    mx_status st;
    size_t len;
    if (!golden_have(net, "weights_checksums.json")) return;
    int ok_enum = enumerate(&b, net) == 0;
    CHECK(ok_enum);
    if (!ok_enum) return;
    char *text = golden_text(net, "weights_checksums.json", &len);
    mx_json *root = text ? mx_json_parse(text, len, net, &st) : NULL;
    const mx_json *tensors = mx_json_get(root, "tensors");
    CHECK(tensors != NULL);
    size_t n = mx_binder_enum_count(&b), bad = 0, summed = 0;
    float *buf = malloc(((size_t)1 << 20) * sizeof *buf);
    for (size_t i = 0; tensors && buf && i < n; i++) {
        const mx_param_info *p = mx_binder_enum_at(&b, i);
        const mx_json *t = mx_json_get(tensors, p->name), *shape = mx_json_get(t, "shape");
        int64_t want[5];
        int nd = (int)mx_json_len(shape), ok = t && nd >= 1 && nd <= 5;
        for (int d = 0; ok && d < nd; d++) want[d] = (int64_t)mx_json_num(mx_json_at(shape, (size_t)d));
        ok = ok && same_shape(p, nd, want);
        int64_t numel = mx_shape_numel(p->ndim, p->shape);
        if (ok && numel <= (1 << 20)) { /* exact checksum of the rule values */
            mx_golden_checksum c;
            mx_golden_v1_fill(p->name, p->ndim, p->shape, seed, buf);
            mx_golden_checksum_init(&c);
            mx_golden_checksum_add(&c, buf, (size_t)numel);
            /* JSON numbers are doubles: the 64-bit checksum is compared to 53 bits */
            ok = (double)c.u32_wsum == mx_json_num(mx_json_get(t, "u32_wsum"));
            summed++;
        }
        if (!ok && bad++ < 5) fprintf(stderr, "%s: %s missing, of another shape or checksum\n", net, p->name);
    }
    printf("%-20s %zu parameters enumerated, checksums list %zu, %zu checksummed, %zu mismatched\n", net, n,
           mx_json_len(tensors), summed, bad);
    CHECK(bad == 0 && n == mx_json_len(tensors) && summed > 0);
    free(buf);
    mx_json_free(root);
    free(text);
    mx_binder_free(&b);
}

int main(void) {
    check_against_file("unet_tiny", "diffusion_pytorch_model.safetensors");
    check_against_file("unet_mini", "diffusion_pytorch_model.safetensors");
    check_against_file("controlnet_tiny", "diffusion_pytorch_model.safetensors");
    check_against_file("controlnet_mini", "diffusion_pytorch_model.safetensors");
    check_against_file("vae_tiny", "diffusion_pytorch_model.safetensors");
    check_against_file("vae_mini", "diffusion_pytorch_model.safetensors");
    check_against_file("clip_tiny", "model.safetensors");
    check_against_checksums("sd15_unet", 1);
    check_against_checksums("sd15_controlnet", 2);
    check_against_checksums("sd15_vae", 1);
    check_against_checksums("sd15_clip", 1);
    return mx_test_finish("test_nn_netparams");
}
