/* The converter behind `matex convert` (convert.h). Source files stay mmapped until the
 * weight file is written, so tensors are copied once, converted on the way out; only
 * tensors that change (LoRA merges, F64/integer sources) get their own buffer. */
#include "convert.h"

#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../runtime/buf.h"
#include "../runtime/fileio.h"
#include "../runtime/json.h"
#include "../runtime/log.h"
#include "ip_adapter_file.h"
#include "lora.h"
#include "networks.h"
#include "safetensors.h"
#include "single_file.h"
#include "taesd_file.h"
#include "weights.h"

#define CONVERTER_VERSION "matex-convert 1"
#define MAX_TEXT_FILE ((size_t)64 << 20)
#define MAX_SHARDS 64

typedef mx_buf text_buf;

typedef struct {
    const mx_convert_opts *o;
    mx_wf_writer *w;
    mx_safetensors *files[256]; /* open sources, kept mapped until the file is written */
    size_t n_files;
    void **bufs; /* converted tensor data owned by the converter */
    size_t n_bufs, cap_bufs;
    mx_lora *loras[MX_CONVERT_MAX_EXTRA];
    mx_single_file *singles[MX_CONVERT_MAX_EXTRA + 1]; /* single-file inputs, mapped until the end */
    size_t n_singles;
    text_buf sources; /* provenance: JSON array items */
    char *configs[MX_NET_KIND_MAX]; /* the first config converted of each kind (mx_net_kinds' order) */
    mx_convert_result res;
} converter;

/* ---- small helpers ---- */

/* The configs convert checks against another network's: an IP-Adapter's against the UNet's it
 * is converted with (it must fit the UNet's cross-attentions). */
typedef struct config_check {
    const char *kind, *against;
    int (*check)(const char *config, const char *against_config, const char *path, mx_status *st);
} config_check;

static const config_check config_checks[] = {
    {MX_NET_IP_ADAPTER, MX_NET_UNET, mx_ip_adapter_file_check_unet},
};




static int is_file(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
}

static int is_dir(const char *path) {
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISDIR(sb.st_mode);
}

/* Whole file as NUL-terminated text (at most MAX_TEXT_FILE bytes, no NUL inside). */
static char *read_text(const char *path, mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        mx_fail(st, MX_EINPUT, "%s: cannot open", path);
        return NULL;
    }
    char *buf = malloc(MAX_TEXT_FILE + 1);
    size_t n = buf ? fread(buf, 1, MAX_TEXT_FILE + 1, f) : 0;
    int err = ferror(f);
    fclose(f);
    if (!buf || err || n > MAX_TEXT_FILE || memchr(buf, 0, n)) {
        mx_fail(st, MX_EINPUT, "%s: %s", path,
                !buf ? "out of memory" : err ? "read error" : n > MAX_TEXT_FILE ? "larger than 64 MiB" : "contains NUL bytes");
        free(buf);
        return NULL;
    }
    buf[n] = 0;
    char *shrunk = realloc(buf, n + 1);
    return shrunk ? shrunk : buf;
}

/* Hands p to the converter, which frees it after the file is written (or frees it now on
 * failure). */
static int own_buffer(converter *cv, void *p, mx_status *st) {
    if (cv->n_bufs == cv->cap_bufs) {
        size_t cap = cv->cap_bufs ? cv->cap_bufs * 2 : 64;
        void **nb = realloc(cv->bufs, cap * sizeof *nb);
        if (!nb) {
            free(p);
            return mx_fail(st, MX_ENOMEM, "convert: out of memory");
        }
        cv->bufs = nb;
        cv->cap_bufs = cap;
    }
    cv->bufs[cv->n_bufs++] = p;
    return 0;
}

/* ---- network type from config.json ---- */

/* The network a config names: diffusers' "_class_name", else a known class among transformers'
 * "architectures" or, for the CLIP towers, its "model_type". NULL when none is known. */
static const mx_net_kind *network_kind(const mx_json *cfg) {
    const char *cls = mx_json_get_str(cfg, "_class_name", NULL);
    if (cls) return mx_net_kind_of_class(cls);
    const mx_json *arch = mx_json_get(cfg, "architectures");
    for (size_t i = 0; i < mx_json_len(arch); i++) {
        const mx_net_kind *k = mx_net_kind_of_class(mx_json_str(mx_json_at(arch, i)));
        if (k) return k;
    }
    return mx_net_kind_of_model_type(mx_json_get_str(cfg, "model_type", NULL));
}

/* ---- locating weight files ---- */

typedef struct {
    char paths[MAX_SHARDS][PATH_MAX];
    size_t n;
} weight_files;

/* Reads a sharded index ({"weight_map": {tensor: shard file}}) into the list of shard paths. */
static int read_shard_index(const char *dir, const char *index_path, weight_files *wfs, mx_status *st) {
    char *text = read_text(index_path, st);
    if (!text) return -1;
    mx_json *j = mx_json_parse(text, strlen(text), index_path, st);
    free(text);
    if (!j) return -1;
    const mx_json *map = mx_json_get(j, "weight_map");
    int rc = 0;
    if (mx_json_kind(map) != MX_JSON_OBJ || mx_json_len(map) == 0)
        rc = mx_fail(st, MX_EINPUT, "%s: no weight_map object", index_path);
    for (size_t i = 0; !rc && i < mx_json_len(map); i++) {
        const char *shard = mx_json_str(mx_json_at(map, i));
        if (!shard || !*shard || strchr(shard, '/') || !strcmp(shard, "..")) {
            rc = mx_fail(st, MX_EINPUT, "%s: tensor '%s': bad shard file name", index_path, mx_json_key(map, i));
            break;
        }
        char path[PATH_MAX];
        rc = mx_path_join(path, sizeof path, dir, shard, st);
        size_t k = 0;
        while (!rc && k < wfs->n && strcmp(wfs->paths[k], path)) k++;
        if (!rc && k == wfs->n) {
            if (wfs->n == MAX_SHARDS) rc = mx_fail(st, MX_EINPUT, "%s: more than %d shards", index_path, MAX_SHARDS);
            else snprintf(wfs->paths[wfs->n++], PATH_MAX, "%s", path);
        }
    }
    mx_json_free(j);
    return rc;
}

/* The weights of a network folder: single files first, then sharded indexes; the fp16
 * variants first when asked for, and as a fallback when only they exist; a .bin last. */
static int find_weight_files(const char *dir, int prefer_fp16, weight_files *wfs, mx_status *st) {
    static const char *bases[2] = {"diffusion_pytorch_model", "model"};
    wfs->n = 0;
    for (int pass = 0; pass < 2; pass++) {
        int fp16 = pass == 0 ? prefer_fp16 : !prefer_fp16;
        for (int b = 0; b < 2; b++) {
            char name[128], path[PATH_MAX];
            snprintf(name, sizeof name, "%s%s.safetensors", bases[b], fp16 ? ".fp16" : "");
            if (mx_path_join(path, sizeof path, dir, name, st)) return -1;
            if (is_file(path)) {
                snprintf(wfs->paths[0], PATH_MAX, "%s", path);
                wfs->n = 1;
                return 0;
            }
            snprintf(name, sizeof name, "%s.safetensors.index%s.json", bases[b], fp16 ? ".fp16" : "");
            if (mx_path_join(path, sizeof path, dir, name, st)) return -1;
            if (is_file(path)) return read_shard_index(dir, path, wfs, st);
        }
    }
    /* the PyTorch pickles of older folders (transformers' pytorch_model.bin), through the safe
     * checkpoint reader (torchzip.h, pickle.h: tensors only, no code run) */
    static const char *bins[2] = {"diffusion_pytorch_model.bin", "pytorch_model.bin"};
    for (int b = 0; b < 2; b++) {
        if (mx_path_join(wfs->paths[0], PATH_MAX, dir, bins[b], st)) return -1;
        if (is_file(wfs->paths[0])) {
            wfs->n = 1;
            return 0;
        }
    }
    return mx_fail(st, MX_EINPUT,
                   "%s: no weights found: expected diffusion_pytorch_model.safetensors or model.safetensors "
                   "(or their .fp16 variants, a sharded .safetensors.index.json, or a single .bin)",
                   dir);
}

static int add_text_meta(converter *cv, const char *dir, const char *file, const char *key, int must_be_json,
                         mx_status *st) {
    char path[PATH_MAX];
    if (mx_path_join(path, sizeof path, dir, file, st)) return -1;
    char *text = read_text(path, st);
    if (!text) return -1;
    int rc = 0;
    if (must_be_json) {
        mx_json *j = mx_json_parse(text, strlen(text), path, st);
        if (!j || mx_json_kind(j) != MX_JSON_OBJ) rc = j ? mx_fail(st, MX_EINPUT, "%s: not a JSON object", path) : -1;
        mx_json_free(j);
    }
    if (!rc && mx_wf_writer_meta(cv->w, key, text, st)) rc = mx_fail_prefix(st, "%s", path);
    free(text);
    return rc;
}

/* ---- adding tensors ---- */

static int lora_targets(const converter *cv, const char *kind) {
    const mx_net_kind *k = mx_net_kind_named(kind);
    return cv->o->n_loras > 0 && k && k->lora_prefix;
}

static int add_integer_tensor(converter *cv, const char *name, const mx_safetensors *f, const mx_st_tensor *t,
                              int ndim, const int64_t *shape, mx_status *st) {
    size_t es = t->dtype == MX_ST_I64 ? 8 : t->dtype == MX_ST_U8 ? 1 : 4, n = t->nbytes / es;
    int32_t *out = malloc((n ? n : 1) * sizeof *out);
    if (!out) return mx_fail(st, MX_ENOMEM, "%s: tensor '%s': out of memory", f->path, t->name);
    if (own_buffer(cv, out, st)) return -1;
    const uint8_t *p = t->data;
    for (size_t i = 0; i < n; i++) {
        int64_t v;
        if (t->dtype == MX_ST_I64) {
            memcpy(&v, p + 8 * i, 8);
        } else if (t->dtype == MX_ST_U8) {
            v = p[i];
        } else {
            int32_t v32;
            memcpy(&v32, p + 4 * i, 4);
            v = v32;
        }
        if (v < INT32_MIN || v > INT32_MAX)
            return mx_fail(st, MX_EINPUT, "%s: tensor '%s': integer value %lld does not fit in i32", f->path, t->name,
                           (long long)v);
        out[i] = (int32_t)v;
    }
    return mx_wf_writer_add(cv->w, name, MX_I32, ndim, shape, out, MX_I32, st);
}

static int merge_loras(converter *cv, const char *kind, const mx_st_tensor *t, int ndim, const int64_t *shape,
                       float *w, mx_status *st) {
    for (size_t k = 0; k < cv->o->n_loras; k++) {
        int r = mx_lora_merge(cv->loras[k], kind, t->name, ndim, shape, w, cv->o->loras[k].scale, st);
        if (r < 0) return -1;
        cv->res.lora_merged += (size_t)r;
    }
    return 0;
}

static int needs_lora(const converter *cv, const char *kind, const char *name) {
    if (!lora_targets(cv, kind)) return 0;
    for (size_t k = 0; k < cv->o->n_loras; k++)
        if (mx_lora_has(cv->loras[k], kind, name)) return 1;
    return 0;
}

static int add_tensor(converter *cv, const char *prefix, const char *kind, const mx_safetensors *f,
                      const mx_st_tensor *t, mx_status *st) {
    char name[1024];
    if (snprintf(name, sizeof name, "%s.%s", prefix, t->name) >= (int)sizeof name)
        return mx_fail(st, MX_EINPUT, "%s: tensor name too long: '%s'", f->path, t->name);
    /* a 0-d tensor (scalar) is stored as shape [1] */
    int64_t one = 1;
    int ndim = t->ndim ? t->ndim : 1;
    const int64_t *shape = t->ndim ? t->shape : &one;
    if (ndim > MX_MAX_DIMS)
        return mx_fail(st, MX_EINPUT, "%s: tensor '%s': %d dimensions (at most %d)", f->path, t->name, ndim, MX_MAX_DIMS);
    if (t->dtype == MX_ST_I64 || t->dtype == MX_ST_I32 || t->dtype == MX_ST_U8) return add_integer_tensor(cv, name, f, t, ndim, shape, st);
    mx_dtype out = ndim >= 2 ? cv->o->dtype : MX_F32;
    if (t->dtype == MX_ST_F64 || needs_lora(cv, kind, t->name)) {
        float *w = mx_st_to_f32(f, t, st);
        if (!w || own_buffer(cv, w, st)) return -1;
        if (merge_loras(cv, kind, t, ndim, shape, w, st)) return -1;
        return mx_wf_writer_add(cv->w, name, out, ndim, shape, w, MX_F32, st);
    }
    mx_dtype src = t->dtype == MX_ST_F16 ? MX_F16 : t->dtype == MX_ST_BF16 ? MX_BF16 : MX_F32;
    return mx_wf_writer_add(cv->w, name, out, ndim, shape, t->data, src, st);
}

static int add_weight_file(converter *cv, const char *prefix, const char *kind, const char *path, mx_status *st) {
    if (cv->n_files == sizeof cv->files / sizeof cv->files[0])
        return mx_fail(st, MX_EINPUT, "%s: too many weight files", path);
    mx_safetensors *f = calloc(1, sizeof *f);
    if (!f) return mx_fail(st, MX_ENOMEM, "convert: out of memory");
    const char *container;
    if (mx_sf_open_tensors(f, path, &container, NULL, st)) { /* safetensors or a PyTorch zip */
        free(f);
        return -1;
    }
    cv->files[cv->n_files++] = f;
    for (size_t i = 0; i < f->count; i++) {
        if (add_tensor(cv, prefix, kind, f, &f->tensors[i], st)) return -1;
        cv->res.tensors++;
    }
    return 0;
}

/* Keeps the first config of each kind, and checks it against the one config_checks names. */
static int add_config(converter *cv, const mx_net_kind *kind, const char *config, const char *path, mx_status *st) {
    if (!kind) return 0;
    char **slot = &cv->configs[kind - mx_net_kinds];
    if (!*slot && !(*slot = strdup(config))) return mx_fail(st, MX_ENOMEM, "convert: out of memory");
    for (size_t i = 0; i < sizeof config_checks / sizeof *config_checks; i++) {
        const mx_net_kind *against = mx_net_kind_named(config_checks[i].against);
        const char *against_config = against ? cv->configs[against - mx_net_kinds] : NULL;
        if (!strcmp(kind->name, config_checks[i].kind) && against_config &&
            config_checks[i].check(config, against_config, path, st))
            return -1;
    }
    return 0;
}

/* A network given by its own option (--vae, --taesd, --image-encoder, --ip-adapter): converted
 * under its kind, it replaces the model set's or checkpoint's network of that kind. */
typedef struct net_option {
    const char *path, *kind;
    int single; /* the single-file opener (MX_SF_VAE_ONLY, ...) when path is not a diffusers folder, or 0 */
} net_option;

static size_t net_options(const mx_convert_opts *o, net_option opt[4]) {
    size_t n = 0;
    if (o->vae) opt[n++] = (net_option){o->vae, MX_NET_VAE, mx_sf_is_file(o->vae) ? MX_SF_VAE_ONLY : 0};
    if (o->taesd)
        opt[n++] = (net_option){o->taesd, MX_NET_TAESD,
                                mx_sf_is_file(o->taesd) || mx_taesd_files_given(o->taesd) ? MX_SF_TAESD : 0};
    if (o->image_encoder) opt[n++] = (net_option){o->image_encoder, MX_NET_IMAGE_ENCODER, 0};
    if (o->ip_adapter) opt[n++] = (net_option){o->ip_adapter, MX_NET_IP_ADAPTER, MX_SF_IP_ADAPTER};
    return n;
}

/* 1 when an option of its own gives the network of that kind. */
static int given_alone(const mx_convert_opts *o, const char *kind) {
    net_option opt[4];
    size_t n = net_options(o, opt);
    for (size_t i = 0; i < n; i++)
        if (!strcmp(opt[i].kind, kind)) return 1;
    return 0;
}

/* The kind's processor file (its image size, mean, std) as the metadata "<prefix>.processor",
 * when the folder has one. */
static int add_processor(converter *cv, const char *dir, const mx_net_kind *kind, const char *prefix, mx_status *st) {
    char path[PATH_MAX], key[128];
    if (!kind->processor) return 0;
    if (mx_path_join(path, sizeof path, dir, kind->processor, st)) return -1;
    snprintf(key, sizeof key, "%s.processor", prefix);
    return is_file(path) ? add_text_meta(cv, dir, kind->processor, key, 1, st) : 0;
}

/* Converts one network folder under the name prefix ("unet", "controlnet_depth", ...).
 * want_kind: the type the folder must hold, or NULL to accept any. */
static int add_network(converter *cv, const char *dir, const char *prefix, const char *want_kind, mx_status *st) {
    char cfg_path[PATH_MAX];
    if (!is_dir(dir)) return mx_fail(st, MX_EINPUT, "%s: not a folder", dir);
    if (mx_path_join(cfg_path, sizeof cfg_path, dir, "config.json", st)) return -1;
    char *cfg_text = read_text(cfg_path, st);
    if (!cfg_text) return -1;
    mx_json *cfg = mx_json_parse(cfg_text, strlen(cfg_text), cfg_path, st);
    const mx_net_kind *known = cfg ? network_kind(cfg) : NULL;
    const char *kind = known ? known->name : NULL;
    char classes[256];
    mx_net_kind_classes(classes, sizeof classes);
    int rc = 0;
    if (!cfg) rc = -1;
    else if (!kind)
        rc = mx_fail(st, MX_EINPUT, "%s: unknown network type (need _class_name or architectures %s)", cfg_path,
                     classes);
    else if (want_kind && strcmp(kind, want_kind))
        rc = mx_fail(st, MX_EINPUT, "%s: holds a %s, expected a %s", cfg_path, kind, want_kind);
    char resolved_prefix[96];
    snprintf(resolved_prefix, sizeof resolved_prefix, "%s", prefix ? prefix : kind ? kind : "");
    weight_files *wfs = rc ? NULL : malloc(sizeof *wfs);
    if (!rc && !wfs) rc = mx_fail(st, MX_ENOMEM, "convert: out of memory");
    if (!rc) rc = find_weight_files(dir, cv->o->prefer_fp16, wfs, st);
    if (!rc) {
        char key[128];
        snprintf(key, sizeof key, "%s.config", resolved_prefix);
        rc = mx_wf_writer_meta(cv->w, key, cfg_text, st);
    }
    if (!rc) rc = add_config(cv, known, cfg_text, cfg_path, st);
    size_t before = cv->res.tensors;
    if (!rc) {
        mx_buf_printf(&cv->sources, "%s{\"net\": ", cv->sources.len ? ", " : "");
        mx_buf_json_str(&cv->sources, resolved_prefix);
        mx_buf_put(&cv->sources, ", \"files\": [", 12);
    }
    for (size_t i = 0; !rc && i < wfs->n; i++) {
        rc = add_weight_file(cv, resolved_prefix, kind, wfs->paths[i], st);
        if (i) mx_buf_put(&cv->sources, ", ", 2);
        mx_buf_json_str(&cv->sources, wfs->paths[i]);
    }
    if (!rc) {
        mx_buf_put(&cv->sources, "]}", 2);
        cv->res.networks++;
        mx_info("convert: %s <- %s (%zu tensors, %zu file%s)", resolved_prefix, dir, cv->res.tensors - before, wfs->n,
                wfs->n == 1 ? "" : "s");
        rc = add_processor(cv, dir, known, resolved_prefix, st);
    }
    free(wfs);
    mx_json_free(cfg);
    free(cfg_text);
    return rc;
}

/* ---- tokenizer and scheduler ---- */

static int add_tokenizer(converter *cv, const char *dir, mx_status *st) {
    if (add_text_meta(cv, dir, "vocab.json", "tokenizer.vocab", 1, st) ||
        add_text_meta(cv, dir, "merges.txt", "tokenizer.merges", 0, st))
        return -1;
    mx_info("convert: tokenizer <- %s", dir);
    return 0;
}

/* ---- the whole conversion ---- */

static int convert_model_set(converter *cv, const char *root, mx_status *st) {
    char dir[PATH_MAX];
    size_t found = 0;
    for (size_t i = 0; i < mx_net_kind_count; i++) {
        const char *sub = mx_net_kinds[i].name;
        if (!mx_net_kinds[i].in_model_set) continue;
        if (mx_path_join(dir, sizeof dir, root, sub, st)) return -1;
        if (!is_dir(dir)) continue;
        if (given_alone(cv->o, sub)) continue;
        if (add_network(cv, dir, sub, sub, st)) return -1;
        found++;
    }
    if (mx_path_join(dir, sizeof dir, root, "tokenizer", NULL) == 0 && is_dir(dir)) {
        if (add_tokenizer(cv, dir, st)) return -1;
    } else if (found) {
        mx_warn("convert: %s has no tokenizer/ folder: prompts cannot be tokenized with this file", root);
    }
    if (mx_path_join(dir, sizeof dir, root, "scheduler", NULL) == 0 && is_dir(dir)) {
        if (add_text_meta(cv, dir, "scheduler_config.json", "scheduler.config", 1, st)) return -1;
    }
    if (!found)
        return mx_fail(st, MX_EINPUT,
                       "%s: no config.json and none of unet/, controlnet/, vae/, text_encoder/: not a diffusers folder",
                       root);
    return 0;
}

/* ---- single-file checkpoints (single_file.h) ---- */

static int add_single_net(converter *cv, const mx_single_file *sf, const mx_sf_net *n, const char *prefix,
                          mx_status *st) {
    char key[128];
    snprintf(key, sizeof key, "%s.config", prefix);
    if (mx_wf_writer_meta(cv->w, key, n->config, st)) return -1;
    if (add_config(cv, mx_net_kind_named(n->kind), n->config, sf->src.path, st)) return -1;
    for (size_t i = 0; i < n->count; i++) {
        if (add_tensor(cv, prefix, n->kind, &sf->src, &n->tensors[i], st)) return -1;
        cv->res.tensors++;
    }
    mx_buf_printf(&cv->sources, "%s{\"net\": ", cv->sources.len ? ", " : "");
    mx_buf_json_str(&cv->sources, prefix);
    mx_buf_put(&cv->sources, ", \"files\": [", 12);
    mx_buf_json_str(&cv->sources, sf->src.path);
    mx_buf_put(&cv->sources, "]}", 2);
    cv->res.networks++;
    mx_info("convert: %s <- %s (%zu tensors, %s)", prefix, sf->src.path, n->count, sf->container);
    return 0;
}

/* A single-file checkpoint: its networks under their kinds (the VAE left out when --vae replaces
 * it), or with only = MX_SF_CONTROLNET_ONLY or MX_SF_VAE_ONLY that one network under `prefix`. The
 * CLIP vocabulary comes from o->tokenizer. */
static int add_single_file(converter *cv, const char *path, int only, const char *prefix, mx_status *st) {
    mx_single_file *sf = calloc(1, sizeof *sf);
    if (!sf) return mx_fail(st, MX_ENOMEM, "convert: out of memory");
    int flags = (cv->o->ema && !only ? MX_SF_EMA : 0) | only;
    if (only == MX_SF_TAESD        ? mx_taesd_files_open(sf, path, st)
        : only == MX_SF_IP_ADAPTER ? mx_ip_adapter_file_open(sf, path, st)
                                   : mx_sf_open(sf, path, flags, st)) {
        free(sf);
        return -1;
    }
    cv->singles[cv->n_singles++] = sf;
    if ((flags & MX_SF_EMA) && !sf->has_ema) return mx_fail(st, MX_EUSAGE, "%s: --ema: the file has no EMA copy", path);
    int has_clip = 0;
    for (size_t k = 0; k < sf->n_nets; k++) {
        const mx_sf_net *n = &sf->nets[k];
        const mx_net_kind *kind = mx_net_kind_named(n->kind);
        has_clip |= kind && kind->needs_tokenizer;
        if (!only && given_alone(cv->o, n->kind)) continue;
        if (add_single_net(cv, sf, n, only ? prefix : n->kind, st)) return -1;
    }
    if (sf->skipped) mx_info("convert: %s: %zu entries skipped (e.g. %s)", path, sf->skipped, sf->skipped_example);
    if (has_clip && cv->o->tokenizer) return add_tokenizer(cv, cv->o->tokenizer, st);
    if (has_clip) mx_warn("convert: no CLIP vocabulary found: prompts cannot be tokenized with this file");
    return 0;
}

static int valid_controlnet_name(const char *s) {
    if (!*s || strlen(s) > 32) return 0;
    for (; *s; s++)
        if (!((*s >= 'a' && *s <= 'z') || (*s >= '0' && *s <= '9') || *s == '_')) return 0;
    return 1;
}

static int convert_inputs(converter *cv, mx_status *st) {
    const mx_convert_opts *o = cv->o;
    if (o->input && mx_sf_is_file(o->input)) {
        if (add_single_file(cv, o->input, 0, NULL, st)) return -1;
    } else if (o->input) {
        char cfg[PATH_MAX];
        if (!is_dir(o->input)) return mx_fail(st, MX_EINPUT, "%s: not a folder or a checkpoint file", o->input);
        if (mx_path_join(cfg, sizeof cfg, o->input, "config.json", st)) return -1;
        if (is_file(cfg) ? add_network(cv, o->input, NULL, NULL, st) : convert_model_set(cv, o->input, st)) return -1;
    }
    for (size_t i = 0; i < o->n_controlnets; i++) {
        char prefix[64];
        if (!valid_controlnet_name(o->controlnets[i].name))
            return mx_fail(st, MX_EUSAGE, "--controlnet %s: the name must be 1-32 of [a-z0-9_]", o->controlnets[i].name);
        snprintf(prefix, sizeof prefix, MX_NET_CONTROLNET "_%s", o->controlnets[i].name);
        if (mx_sf_is_file(o->controlnets[i].dir) ? add_single_file(cv, o->controlnets[i].dir, MX_SF_CONTROLNET_ONLY, prefix, st)
                                                 : add_network(cv, o->controlnets[i].dir, prefix, MX_NET_CONTROLNET, st))
            return -1;
    }
    net_option opt[4];
    size_t n = net_options(o, opt);
    for (size_t i = 0; i < n; i++)
        if (opt[i].single ? add_single_file(cv, opt[i].path, opt[i].single, opt[i].kind, st)
                          : add_network(cv, opt[i].path, opt[i].kind, opt[i].kind, st))
            return -1;
    if (cv->res.networks == 0) return mx_fail(st, MX_EUSAGE, "convert: nothing to convert");
    return 0;
}

static int open_loras(converter *cv, mx_status *st) {
    for (size_t k = 0; k < cv->o->n_loras; k++)
        if (mx_lora_open(&cv->loras[k], cv->o->loras[k].path, st)) return -1;
    return 0;
}

static int check_loras_used(converter *cv, mx_status *st) {
    for (size_t k = 0; k < cv->o->n_loras; k++)
        if (mx_lora_check_all_used(cv->loras[k], st)) return -1;
    return 0;
}

static int add_provenance(converter *cv, mx_status *st) {
    text_buf p = {0};
    mx_buf_printf(&p, "{\"converter\": \"%s\", \"dtype\": \"%s\", \"variant\": \"%s\", \"sources\": [", CONVERTER_VERSION,
              mx_dtype_name(cv->o->dtype), cv->o->prefer_fp16 ? "fp16" : "default");
    mx_buf_put(&p, cv->sources.p ? cv->sources.p : "", cv->sources.len);
    mx_buf_put(&p, "], \"lora\": [", 12);
    for (size_t k = 0; k < cv->o->n_loras; k++) {
        mx_buf_printf(&p, "%s{\"file\": ", k ? ", " : "");
        mx_buf_json_str(&p, cv->o->loras[k].path);
        mx_buf_printf(&p, ", \"scale\": %.9g, \"modules\": %zu}", (double)cv->o->loras[k].scale,
                  mx_lora_module_count(cv->loras[k]));
    }
    mx_buf_put(&p, "]}", 2);
    int rc = p.oom || cv->sources.oom ? mx_fail(st, MX_ENOMEM, "convert: out of memory")
                                      : mx_wf_writer_meta(cv->w, "provenance", p.p, st);
    free(p.p);
    return rc;
}

/* "unet.lcm_lora": {"file": ..., "scale": ...} of the LoRA marked as the LCM-LoRA. */
static int add_lcm_mark(converter *cv, mx_status *st) {
    for (size_t k = 0; k < cv->o->n_loras; k++) {
        if (!cv->o->loras[k].lcm) continue;
        text_buf p = {0};
        mx_buf_put(&p, "{\"file\": ", 9);
        mx_buf_json_str(&p, cv->o->loras[k].path);
        mx_buf_printf(&p, ", \"scale\": %.9g}", (double)cv->o->loras[k].scale);
        int rc = p.oom ? mx_fail(st, MX_ENOMEM, "convert: out of memory") : mx_wf_writer_meta(cv->w, MX_NET_UNET ".lcm_lora", p.p, st);
        free(p.p);
        return rc;
    }
    return 0;
}

static void converter_free(converter *cv) {
    mx_wf_writer_free(cv->w);
    for (size_t i = 0; i < cv->n_files; i++) {
        mx_st_close(cv->files[i]);
        free(cv->files[i]);
    }
    for (size_t i = 0; i < cv->n_bufs; i++) free(cv->bufs[i]);
    free(cv->bufs);
    for (size_t k = 0; k < MX_CONVERT_MAX_EXTRA; k++) mx_lora_close(cv->loras[k]);
    for (size_t k = 0; k < cv->n_singles; k++) {
        mx_sf_close(cv->singles[k]);
        free(cv->singles[k]);
    }
    free(cv->sources.p);
    for (size_t k = 0; k < MX_NET_KIND_MAX; k++) free(cv->configs[k]);
}

int mx_convert(const mx_convert_opts *o, mx_convert_result *res, mx_status *st) {
    if (!o->output) return mx_fail(st, MX_EUSAGE, "convert: no output file");
    if (o->dtype != MX_F32 && o->dtype != MX_F16 && o->dtype != MX_BF16)
        return mx_fail(st, MX_EUSAGE, "convert: output dtype must be f32, f16 or bf16");
    if (o->n_controlnets > MX_CONVERT_MAX_EXTRA || o->n_loras > MX_CONVERT_MAX_EXTRA)
        return mx_fail(st, MX_EUSAGE, "convert: at most %d ControlNets and %d LoRAs", MX_CONVERT_MAX_EXTRA,
                       MX_CONVERT_MAX_EXTRA);
    size_t n_lcm = 0;
    for (size_t k = 0; k < o->n_loras; k++) n_lcm += o->loras[k].lcm != 0;
    if (n_lcm > 1) return mx_fail(st, MX_EUSAGE, "convert: more than one LCM-LoRA");
    converter cv = {.o = o};
    int rc = (cv.w = mx_wf_writer_create(st)) ? 0 : -1;
    if (!rc) rc = open_loras(&cv, st);
    if (!rc) rc = convert_inputs(&cv, st);
    if (!rc) rc = check_loras_used(&cv, st);
    if (!rc) rc = add_provenance(&cv, st);
    if (!rc) rc = add_lcm_mark(&cv, st);
    if (!rc) rc = mx_wf_writer_finish(cv.w, o->output, st);
    if (!rc && res) *res = cv.res;
    converter_free(&cv);
    return rc;
}
