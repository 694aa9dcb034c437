/* The published IP-Adapter file (weights/ip_adapter_file.h) through the converter
 * (`convert --ip-adapter`, with the single network folder golden/unet_tiny): the .safetensors of
 * golden/ip_adapter_tiny and the same tensors as the original repository's .bin (a torch zip of
 * {"image_proj": {...}, "ip_adapter": {...}}, written by tests/util_ckpt.c) give the same tensors
 * and config; the adapter alone converts too. A missing layer (count against the UNet's config), a
 * gap in the numbering, a width that is not the UNet's, a k/v pair of different shapes, a tensor
 * of another adapter: each one message naming the file, and no output file. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../runtime/log.h"
#include "../weights/convert.h"
#include "../weights/safetensors.h"
#include "../weights/weights.h"
#include "util_ckpt.h"
#include "util_test.h"

static char tmp[256], unet_dir[512], adapter[512];

static int cmp_name(const void *a, const void *b) {
    return strcmp(((const mx_st_tensor *)a)->name, ((const mx_st_tensor *)b)->name);
}

/* Converts unet_dir (unless NULL) + the adapter file into tmp/out.mxw; the status in *st. */
static int convert(const char *unet, const char *ip, const char *out, mx_status *st) {
    mx_convert_opts o = {.input = unet, .output = out, .dtype = MX_F32, .ip_adapter = ip};
    mx_status_clear(st);
    return mx_convert(&o, NULL, st);
}

/* Every ip_adapter.* tensor and the config of a and b are equal; returns the count compared. */
static size_t compare_adapters(const char *a, const char *b) {
    mx_weightfile *wa = NULL, *wb = NULL;
    mx_status st;
    size_t same = 0;
    CHECK(mx_wf_open(&wa, a, &st) == 0 && mx_wf_open(&wb, b, &st) == 0);
    for (size_t i = 0; wa && wb && i < mx_wf_count(wa); i++) {
        const mx_wtensor *t = mx_wf_tensor(wa, i), *u = mx_wf_find(wb, t->name);
        if (strncmp(t->name, "ip_adapter.", 11)) continue;
        CHECK(u && u->nbytes == t->nbytes && !memcmp(u->data, t->data, t->nbytes));
        same += u && u->nbytes == t->nbytes && !memcmp(u->data, t->data, t->nbytes);
    }
    const char *ca = wa ? mx_wf_meta(wa, "ip_adapter.config") : NULL, *cb = wb ? mx_wf_meta(wb, "ip_adapter.config") : NULL;
    CHECK(ca && cb && !strcmp(ca, cb));
    if (wa) mx_wf_close(wa);
    if (wb) mx_wf_close(wb);
    return same;
}

static void published_layouts(const mx_safetensors *f) {
    char st_out[300], bin[300], bin_out[300], alone[300];
    mx_status st;
    snprintf(st_out, sizeof st_out, "%s/st.mxw", tmp);
    snprintf(bin, sizeof bin, "%s/ip-adapter_sd15.bin", tmp);
    snprintf(bin_out, sizeof bin_out, "%s/bin.mxw", tmp);
    snprintf(alone, sizeof alone, "%s/alone.mxw", tmp);
    mx_st_tensor sorted[32];
    CHECK(f->count == 12);
    memcpy(sorted, f->tensors, f->count * sizeof *sorted);
    qsort(sorted, f->count, sizeof *sorted, cmp_name); /* one run per group of the nested dict */
    CHECK(mx_test_write_torchzip(bin, sorted, f->count, MX_TEST_NESTED) == 0);
    CHECK(convert(unet_dir, adapter, st_out, &st) == 0);
    CHECK(convert(unet_dir, bin, bin_out, &st) == 0);
    CHECK(convert(NULL, adapter, alone, &st) == 0);
    CHECK(compare_adapters(st_out, bin_out) == 12);
    CHECK(compare_adapters(st_out, alone) == 12);
    mx_weightfile *wf = NULL;
    CHECK(mx_wf_open(&wf, st_out, &st) == 0);
    const char *cfg = wf ? mx_wf_meta(wf, "ip_adapter.config") : NULL;
    CHECK(cfg && strstr(cfg, "\"num_tokens\": 4") && strstr(cfg, "\"image_embed_dim\": 24") &&
          strstr(cfg, "\"hidden_sizes\": [32, 32, 32, 64]"));
    /* the published names under the prefix: image_proj.* and the layer numbers as they are */
    CHECK(wf && mx_wf_find(wf, "ip_adapter.image_proj.proj.weight") && mx_wf_find(wf, "ip_adapter.7.to_v_ip.weight"));
    if (wf) mx_wf_close(wf);
}

/* A copy of the adapter's tensors without those whose name contains `drop`, with `rename` (if not
 * NULL) given the shape of `like`, plus `extra` (if not NULL; shaped like `like`), written as NAME.safetensors and
 * converted with unet_tiny: it must fail with `want` in the message, naming the file, and leave
 * no output. */
static void refused(const mx_safetensors *f, const char *name, const char *drop, const char *rename,
                    const char *like, const char *extra, const char *want) {
    char path[300], out[300];
    mx_st_tensor t[32];
    size_t n = 0;
    const mx_st_tensor *shape_of = like ? mx_st_find(f, like) : NULL;
    for (size_t i = 0; i < f->count; i++) {
        if (drop && strstr(f->tensors[i].name, drop)) continue;
        t[n] = f->tensors[i];
        if (rename && !strcmp(t[n].name, rename) && shape_of) t[n] = *shape_of, t[n].name = (char *)rename;
        n++;
    }
    if (extra) t[n] = shape_of ? *shape_of : f->tensors[0], t[n++].name = (char *)extra;
    snprintf(path, sizeof path, "%s/%s.safetensors", tmp, name);
    snprintf(out, sizeof out, "%s/%s.mxw", tmp, name);
    CHECK(mx_test_write_safetensors(path, t, n) == 0);
    mx_status st;
    int rc = convert(unet_dir, path, out, &st);
    CHECK(rc != 0 && strstr(st.msg, path) && strstr(st.msg, want));
    CHECK(access(out, F_OK) != 0);
    if (rc == 0 || !strstr(st.msg, want)) fprintf(stderr, "%s: got '%s', want '%s'\n", name, st.msg, want);
}

int main(void) {
    mx_log_set_level(MX_LOG_WARN);
    if (!mx_test_need(unet_dir, sizeof unet_dir, "golden/unet_tiny") ||
        !mx_test_need(adapter, sizeof adapter, "golden/ip_adapter_tiny/ip_adapter.safetensors"))
        return mx_test_finish("test_weights_ip_adapter");
    snprintf(tmp, sizeof tmp, "/tmp/mx_test_ip_adapter_XXXXXX");
    if (!mkdtemp(tmp)) return 1;
    mx_safetensors f;
    mx_status st;
    CHECK(mx_st_open(&f, adapter, &st) == 0);
    published_layouts(&f);
    refused(&f, "missing_layer", "ip_adapter.7.", NULL, NULL, NULL, "3 IP-Adapter layers, but the UNet has 4");
    refused(&f, "gap", "ip_adapter.3.", NULL, NULL, NULL, "ip_adapter.3.to_k_ip.weight missing");
    refused(&f, "width", "ip_adapter.7.to_v_ip", "ip_adapter.7.to_k_ip.weight", "ip_adapter.1.to_k_ip.weight",
            "ip_adapter.7.to_v_ip.weight", "ip_adapter.7 is 32 wide, the UNet's cross-attention layer 3 is 64");
    refused(&f, "kv_pair", NULL, "ip_adapter.5.to_v_ip.weight", "ip_adapter.7.to_v_ip.weight", NULL,
            "'ip_adapter.5.to_v_ip.weight' must be floats of shape [32, 32]");
    refused(&f, "plus", NULL, NULL, NULL, "image_proj.latents", "'image_proj.latents' is not part of the SD1.5 IP-Adapter");
    mx_st_close(&f);
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tmp);
    CHECK(system(cmd) == 0);
    return mx_test_finish("test_weights_ip_adapter");
}
