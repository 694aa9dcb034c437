/* The original TAESD files (taesd_file.h). */
#include "taesd_file.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../runtime/buf.h"
#include "networks.h"

#define TAESD_MAX_LEVELS 8

static int is_dir(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISDIR(sb.st_mode);
}

/* Finds the encoder and decoder files of path (see mx_taesd_files_given). */
static int find_pair(const char *path, char *enc, char *dec, size_t cap) {
    static const char *const exts[] = {".safetensors", ".pth", ".pt"};
    if (is_dir(path)) {
        char cfg[PATH_MAX];
        snprintf(cfg, sizeof cfg, "%s/config.json", path);
        if (mx_sf_is_file(cfg)) return -1; /* a diffusers AutoencoderTiny folder */
        int found = 0;
        for (size_t i = 0; i < sizeof exts / sizeof exts[0]; i++) {
            char e[PATH_MAX], d[PATH_MAX];
            snprintf(e, sizeof e, "%s/taesd_encoder%s", path, exts[i]);
            snprintf(d, sizeof d, "%s/taesd_decoder%s", path, exts[i]);
            if (!(found & 1) && mx_sf_is_file(e)) snprintf(enc, cap, "%s", e), found |= 1;
            if (!(found & 2) && mx_sf_is_file(d)) snprintf(dec, cap, "%s", d), found |= 2;
        }
        return found == 3 ? 0 : -1;
    }
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    const char *e = strstr(base, "taesd_encoder"), *d = strstr(base, "taesd_decoder");
    if ((!e && !d) || strlen(path) >= cap) return -1;
    size_t at = (size_t)((e ? e : d) - path);
    snprintf(enc, cap, "%s", path);
    snprintf(dec, cap, "%s", path);
    memcpy(enc + at, "taesd_encoder", 13);
    memcpy(dec + at, "taesd_decoder", 13);
    char *other = e ? dec : enc; /* the half not given may have another extension */
    char *dot = strrchr(other + at, '.');
    for (size_t i = 0; dot && !mx_sf_is_file(other) && i < sizeof exts / sizeof exts[0]; i++)
        if ((size_t)(dot - other) + strlen(exts[i]) < cap) strcpy(dot, exts[i]);
    return mx_sf_is_file(enc) && mx_sf_is_file(dec) ? 0 : -1;
}

int mx_taesd_files_given(const char *path) {
    char enc[PATH_MAX], dec[PATH_MAX];
    return find_pair(path, enc, dec, sizeof enc) == 0;
}

static const mx_st_tensor *layer(const mx_safetensors *f, int k, const char *rest) {
    char name[64];
    snprintf(name, sizeof name, "%d.%s", k, rest);
    return mx_st_find(f, name);
}

/* The Sequential of one half: a convolution with bias opens the first level, one without bias
 * (after a stride or an upsample) each next level, blocks (K.conv.0.weight) fill the levels, and
 * the last convolution with bias makes the output. ch[] and blocks[] per level, *out_ch its
 * output channels, *in_ch the first convolution's input channels. */
typedef struct {
    int levels;
    int64_t ch[TAESD_MAX_LEVELS], blocks[TAESD_MAX_LEVELS], in_ch, out_ch;
} taesd_half;

static int read_half(const mx_safetensors *f, int first, taesd_half *h, mx_status *st) {
    memset(h, 0, sizeof *h);
    int closed = 0;
    for (int k = first; k < first + 64; k++) {
        const mx_st_tensor *w = layer(f, k, "weight");
        if (layer(f, k, "conv.0.weight")) {
            if (!h->levels || closed) return mx_fail(st, MX_EINPUT, "%s: layer %d: a block outside a level", f->path, k);
            h->blocks[h->levels - 1]++;
        } else if (w && w->ndim == 4) {
            if (closed) return mx_fail(st, MX_EINPUT, "%s: layer %d after the output convolution", f->path, k);
            int bias = layer(f, k, "bias") != NULL;
            if (!h->levels && bias) {
                h->in_ch = w->shape[1];
            } else if (h->levels && bias) {
                h->out_ch = w->shape[0];
                closed = 1;
                continue;
            } else if (!h->levels || h->levels == TAESD_MAX_LEVELS) {
                return mx_fail(st, MX_EINPUT, "%s: layer %d: not a TAESD layer sequence", f->path, k);
            }
            h->ch[h->levels++] = w->shape[0];
        }
    }
    if (!closed) return mx_fail(st, MX_EINPUT, "%s: no output convolution: not a TAESD encoder or decoder", f->path);
    return 0;
}

static void put_list(mx_buf *b, const char *key, const int64_t *v, int n) {
    mx_buf_printf(b, ", \"%s\": [", key);
    for (int i = 0; i < n; i++) mx_buf_printf(b, "%s%lld", i ? ", " : "", (long long)v[i]);
    mx_buf_put(b, "]", 1);
}

static int taesd_config(mx_single_file *sf, mx_status *st) {
    taesd_half enc, dec;
    if (read_half(&sf->aux, 0, &enc, st) || read_half(&sf->src, 1, &dec, st)) return -1;
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"_class_name\": \"AutoencoderTiny\", \"matex_source\": \"taesd files\", \"in_channels\": %lld, "
                      "\"out_channels\": %lld, \"latent_channels\": %lld, \"act_fn\": \"relu\", \"upsample_fn\": \"nearest\", "
                      "\"upsampling_scaling_factor\": 2, \"latent_magnitude\": 3, \"latent_shift\": 0.5, \"scaling_factor\": 1.0",
                  (long long)enc.in_ch, (long long)dec.out_ch, (long long)enc.out_ch);
    put_list(&b, "block_out_channels", enc.ch, enc.levels);
    put_list(&b, "encoder_block_out_channels", enc.ch, enc.levels);
    put_list(&b, "decoder_block_out_channels", dec.ch, dec.levels);
    put_list(&b, "num_encoder_blocks", enc.blocks, enc.levels);
    put_list(&b, "num_decoder_blocks", dec.blocks, dec.levels);
    mx_buf_put(&b, "}", 1);
    if (b.oom) {
        mx_buf_free(&b);
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", sf->src.path);
    }
    sf->nets[0].config = b.p;
    return 0;
}

/* encoder K.rest -> encoder.layers.K.rest; decoder K.rest -> decoder.layers.(K-1).rest */
static int add_half(mx_single_file *sf, const mx_safetensors *f, const char *half, int shift, mx_status *st) {
    mx_sf_net *n = &sf->nets[0];
    for (size_t i = 0; i < f->count; i++) {
        const mx_st_tensor *t = &f->tensors[i];
        char *end, name[256];
        long k = strtol(t->name, &end, 10);
        if (end == t->name || *end != '.' || k - shift < 0 || k > 1000 ||
            snprintf(name, sizeof name, "%s.layers.%ld%s", half, k - shift, end) >= (int)sizeof name)
            return mx_fail(st, MX_EINPUT, "%s: tensor '%s' is not a TAESD layer", f->path, t->name);
        mx_st_tensor *o = &n->tensors[n->count];
        *o = *t;
        if (!(o->name = strdup(name))) return mx_fail(st, MX_ENOMEM, "%s: out of memory", f->path);
        n->count++;
    }
    return 0;
}

int mx_taesd_files_open(mx_single_file *sf, const char *path, mx_status *st) {
    memset(sf, 0, sizeof *sf);
    char enc[PATH_MAX], dec[PATH_MAX];
    if (find_pair(path, enc, dec, sizeof enc))
        return mx_fail(st, MX_EINPUT, "%s: not a TAESD file with its other half beside it (taesd_encoder.* and "
                       "taesd_decoder.*: matex needs both)", path);
    const char *container2;
    size_t skipped2 = 0;
    int rc = mx_sf_open_tensors(&sf->src, dec, &sf->container, &sf->skipped, st);
    if (!rc) rc = mx_sf_open_tensors(&sf->aux, enc, &container2, &skipped2, st);
    sf->skipped += skipped2;
    mx_sf_net *n = &sf->nets[0];
    n->kind = MX_NET_TAESD;
    if (!rc && !(n->tensors = calloc(sf->src.count + sf->aux.count + 1, sizeof *n->tensors)))
        rc = mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    if (!rc) sf->n_nets = 1;
    if (!rc) rc = add_half(sf, &sf->aux, "encoder", 0, st);
    if (!rc) rc = add_half(sf, &sf->src, "decoder", 1, st);
    if (!rc) rc = taesd_config(sf, st);
    if (rc) mx_sf_close(sf);
    return rc;
}
