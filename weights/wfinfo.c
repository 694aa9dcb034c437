/* `matex info WEIGHTFILE`: what a weight file holds, per network and per tensor. */
#include "wfinfo.h"

#include <string.h>

#include "weights.h"

int mx_wf_is_weightfile(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    char magic[8];
    int ok = fread(magic, 1, 8, f) == 8 && !memcmp(magic, "MATEXWF", 8);
    fclose(f);
    return ok;
}

typedef struct {
    char prefix[64];
    size_t tensors;
    uint64_t params;
    uint64_t bytes[4]; /* by mx_dtype */
} net_summary;

/* "unet.conv_in.weight" -> "unet" */
static void net_of(const char *name, char *out, size_t cap) {
    const char *dot = strchr(name, '.');
    size_t n = dot ? (size_t)(dot - name) : strlen(name);
    if (n >= cap) n = cap - 1;
    memcpy(out, name, n);
    out[n] = 0;
}

static size_t summarize(const mx_weightfile *wf, net_summary *nets, size_t cap) {
    size_t count = 0;
    for (size_t i = 0; i < mx_wf_count(wf); i++) {
        const mx_wtensor *t = mx_wf_tensor(wf, i);
        char net[64];
        net_of(t->name, net, sizeof net);
        size_t k = 0;
        while (k < count && strcmp(nets[k].prefix, net)) k++;
        if (k == count) {
            if (count == cap) {
                k = cap - 1; /* more networks than slots: fold into the last */
            } else {
                memset(&nets[k], 0, sizeof *nets);
                snprintf(nets[k].prefix, sizeof nets[k].prefix, "%s", net);
                count++;
            }
        }
        nets[k].tensors++;
        nets[k].params += (uint64_t)mx_shape_numel(t->ndim, t->shape);
        nets[k].bytes[t->dtype] += t->nbytes;
    }
    return count;
}

static void print_summary(const mx_weightfile *wf, FILE *out) {
    net_summary nets[32];
    size_t n = summarize(wf, nets, 32);
    fprintf(out, "%-24s %8s %14s %10s %10s %10s %8s\n", "network", "tensors", "parameters", "f32 MiB", "f16 MiB",
            "bf16 MiB", "i32 KiB");
    for (size_t k = 0; k < n; k++)
        fprintf(out, "%-24s %8zu %14llu %10.1f %10.1f %10.1f %8.1f\n", nets[k].prefix, nets[k].tensors,
                (unsigned long long)nets[k].params, nets[k].bytes[MX_F32] / 1048576.0,
                nets[k].bytes[MX_F16] / 1048576.0, nets[k].bytes[MX_BF16] / 1048576.0, nets[k].bytes[MX_I32] / 1024.0);
}

static void print_meta(const mx_weightfile *wf, FILE *out) {
    fprintf(out, "\nmetadata (%zu keys)\n", mx_wf_meta_count(wf));
    for (size_t i = 0; i < mx_wf_meta_count(wf); i++) {
        const char *k = mx_wf_meta_key(wf, i), *v = mx_wf_meta(wf, k);
        if (!strcmp(k, "provenance")) fprintf(out, "  %-28s %s\n", k, v);
        else fprintf(out, "  %-28s %zu bytes\n", k, strlen(v));
    }
}

int mx_wf_print_info(const char *path, FILE *out, mx_status *st) {
    mx_weightfile *wf;
    if (mx_wf_open(&wf, path, st)) return -1;
    fprintf(out, "%s: matex weight file, %zu tensors\n\n", path, mx_wf_count(wf));
    print_summary(wf, out);
    print_meta(wf, out);
    fprintf(out, "\ntensors\n");
    for (size_t i = 0; i < mx_wf_count(wf); i++) {
        const mx_wtensor *t = mx_wf_tensor(wf, i);
        char shape[128];
        fprintf(out, "  %-72s %-4s %-22s %zu\n", t->name, mx_dtype_name(t->dtype),
                mx_shape_str(t->ndim, t->shape, shape, sizeof shape), t->nbytes);
    }
    mx_wf_close(wf);
    return 0;
}
