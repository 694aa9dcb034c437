/* LoRA reading (both key styles) and merging into fp32 weights; see lora.h. */
#include "lora.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "networks.h"
#include "safetensors.h"

typedef struct {
    char *key; /* "unet.<dotted module>", "text_encoder.<dotted module>" or a kohya "lora_unet_..." */
    const mx_st_tensor *down, *up, *alpha;
    int used;
} lora_module;

struct mx_lora {
    mx_safetensors file;
    lora_module *mods; /* sorted by key */
    size_t count;
};

typedef enum { PART_DOWN, PART_UP, PART_ALPHA } lora_part;

static const struct {
    const char *suffix;
    lora_part part;
} lora_suffixes[] = {
    {".lora_A.weight", PART_DOWN},    {".lora_B.weight", PART_UP},
    {".lora_A.default.weight", PART_DOWN}, {".lora_B.default.weight", PART_UP},
    {".lora.down.weight", PART_DOWN}, {".lora.up.weight", PART_UP},
    {"_lora.down.weight", PART_DOWN}, {"_lora.up.weight", PART_UP}, /* attention-processor style */
    {".lora_down.weight", PART_DOWN}, {".lora_up.weight", PART_UP}, /* kohya */
    {".alpha", PART_ALPHA},
};

static int starts_with(const char *s, const char *p) { return !strncmp(s, p, strlen(p)); }

/* Removes every occurrence of `what` from s (in place). */
static void remove_all(char *s, const char *what) {
    size_t n = strlen(what);
    char *p;
    while ((p = strstr(s, what))) memmove(p, p + n, strlen(p + n) + 1);
}

/* The module key of a LoRA tensor key without its suffix: kohya keys stay as they are;
 * diffusers keys get their network prefix and lose the attention-processor wrapping
 * ("attn1.processor.to_out_lora" -> "attn1.to_out.0"). */
static char *module_key(const char *stem, int processor_style) {
    const char *m = stem;
    if (starts_with(m, "lora_unet_") || starts_with(m, "lora_te_")) return strdup(m);
    if (starts_with(m, "base_model.model.")) m += strlen("base_model.model.");
    const char *net = "";
    if (!starts_with(m, MX_NET_UNET ".") && !starts_with(m, MX_NET_TEXT_ENCODER "."))
        net = starts_with(m, "text_model.") ? MX_NET_TEXT_ENCODER "." : MX_NET_UNET ".";
    char *k = malloc(strlen(net) + strlen(m) + 8);
    if (!k) return NULL;
    sprintf(k, "%s%s", net, m);
    remove_all(k, "base_model.model."); /* a PEFT model's own wrapping inside the network prefix */
    if (processor_style) {
        remove_all(k, ".processor");
        size_t n = strlen(k);
        if (n >= 7 && !strcmp(k + n - 7, ".to_out")) strcat(k, ".0");
    }
    return k;
}

static int cmp_module(const void *a, const void *b) { return strcmp(((const lora_module *)a)->key, ((const lora_module *)b)->key); }

static lora_module *find_module(const mx_lora *l, const char *key) {
    size_t lo = 0, hi = l->count;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        int c = strcmp(l->mods[mid].key, key);
        if (c == 0) return &l->mods[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid;
    }
    return NULL;
}

/* One entry per tensor first, then sorted and merged by module key. */
static int collect_parts(mx_lora *l, lora_part *parts, mx_status *st) {
    const char *path = l->file.path;
    for (size_t i = 0; i < l->file.count; i++) {
        const mx_st_tensor *t = &l->file.tensors[i];
        size_t n = strlen(t->name), s = 0, ns = sizeof lora_suffixes / sizeof lora_suffixes[0];
        while (s < ns && !(n > strlen(lora_suffixes[s].suffix) &&
                           !strcmp(t->name + n - strlen(lora_suffixes[s].suffix), lora_suffixes[s].suffix)))
            s++;
        if (s == ns) return mx_fail(st, MX_EINPUT, "%s: unrecognized LoRA key '%s'", path, t->name);
        char *stem = strndup(t->name, n - strlen(lora_suffixes[s].suffix));
        char *key = stem ? module_key(stem, lora_suffixes[s].suffix[0] == '_') : NULL;
        free(stem);
        if (!key) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
        lora_module *m = &l->mods[l->count++];
        memset(m, 0, sizeof *m);
        m->key = key;
        parts[i] = lora_suffixes[s].part;
        if (parts[i] == PART_DOWN) m->down = t;
        else if (parts[i] == PART_UP) m->up = t;
        else m->alpha = t;
    }
    return 0;
}

static int merge_duplicates(mx_lora *l, mx_status *st) {
    const char *path = l->file.path;
    size_t out = 0;
    for (size_t i = 0; i < l->count; i++) {
        lora_module *m = &l->mods[i];
        if (out > 0 && !strcmp(l->mods[out - 1].key, m->key)) {
            lora_module *d = &l->mods[out - 1];
            if ((m->down && d->down) || (m->up && d->up) || (m->alpha && d->alpha))
                return mx_fail(st, MX_EINPUT, "%s: LoRA module '%s' has a part twice (mixed key styles?)", path, m->key);
            if (m->down) d->down = m->down;
            if (m->up) d->up = m->up;
            if (m->alpha) d->alpha = m->alpha;
            free(m->key);
            continue;
        }
        l->mods[out++] = *m;
    }
    l->count = out;
    return 0;
}

static int check_modules(const mx_lora *l, mx_status *st) {
    const char *path = l->file.path;
    for (size_t i = 0; i < l->count; i++) {
        const lora_module *m = &l->mods[i];
        if (!m->down || !m->up) return mx_fail(st, MX_EINPUT, "%s: LoRA module '%s' lacks its %s matrix", path, m->key, m->down ? "up" : "down");
        int64_t rank = m->down->ndim >= 2 ? m->down->shape[0] : -1;
        int up_ok = (m->up->ndim == 2 || (m->up->ndim == 4 && m->up->shape[2] == 1 && m->up->shape[3] == 1)) &&
                    m->up->shape[1] == rank;
        if (rank <= 0 || (m->down->ndim != 2 && m->down->ndim != 4) || !up_ok)
            return mx_fail(st, MX_EINPUT, "%s: LoRA module '%s': down/up shapes do not form a rank-r product", path, m->key);
        if (m->alpha && (m->alpha->nbytes == 0 || m->alpha->nbytes > 8))
            return mx_fail(st, MX_EINPUT, "%s: LoRA module '%s': alpha is not a scalar", path, m->key);
    }
    return 0;
}

int mx_lora_open(mx_lora **out, const char *path, mx_status *st) {
    *out = NULL;
    mx_lora *l = calloc(1, sizeof *l);
    if (!l) return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    if (mx_st_open(&l->file, path, st)) {
        free(l);
        return mx_fail_prefix(st, "reading LoRA");
    }
    l->mods = calloc(l->file.count ? l->file.count : 1, sizeof *l->mods);
    lora_part *parts = calloc(l->file.count ? l->file.count : 1, sizeof *parts);
    int rc = !l->mods || !parts ? mx_fail(st, MX_ENOMEM, "%s: out of memory", path) : collect_parts(l, parts, st);
    free(parts);
    if (!rc) {
        qsort(l->mods, l->count, sizeof *l->mods, cmp_module);
        rc = merge_duplicates(l, st);
    }
    if (!rc && l->count == 0) rc = mx_fail(st, MX_EINPUT, "%s: no LoRA tensors", path);
    if (!rc) rc = check_modules(l, st);
    if (rc) {
        mx_lora_close(l);
        return -1;
    }
    *out = l;
    return 0;
}

void mx_lora_close(mx_lora *l) {
    if (!l) return;
    for (size_t i = 0; i < l->count; i++) free(l->mods[i].key);
    free(l->mods);
    mx_st_close(&l->file);
    free(l);
}

size_t mx_lora_module_count(const mx_lora *l) { return l->count; }

/* The module of a weight: "<net>.<module>" (diffusers) or "lora_<unet|te>_<module with _>". */
static lora_module *module_for(const mx_lora *l, const char *net, const char *name) {
    size_t n = strlen(name);
    if (n <= 7 || strcmp(name + n - 7, ".weight")) return NULL;
    char *key = malloc(strlen(net) + n + 16);
    if (!key) return NULL;
    sprintf(key, "%s.%.*s", net, (int)(n - 7), name);
    lora_module *m = find_module(l, key);
    if (!m) {
        const mx_net_kind *k = mx_net_kind_named(net);
        const char *kp = k ? k->lora_prefix : NULL;
        if (kp) {
            sprintf(key, "%s%.*s", kp, (int)(n - 7), name);
            for (char *p = key + strlen(kp); *p; p++)
                if (*p == '.') *p = '_';
            m = find_module(l, key);
        }
    }
    free(key);
    return m;
}

int mx_lora_has(const mx_lora *l, const char *net, const char *name) { return module_for(l, net, name) != NULL; }

static int read_alpha(const mx_lora *l, const lora_module *m, double rank, double *alpha, mx_status *st) {
    *alpha = rank;
    if (!m->alpha) return 0;
    float *a = mx_st_to_f32(&l->file, m->alpha, st);
    if (!a) return -1;
    *alpha = a[0];
    free(a);
    return 0;
}

int mx_lora_merge(mx_lora *l, const char *net, const char *name, int ndim, const int64_t *shape, float *w,
                  float scale, mx_status *st) {
    lora_module *m = module_for(l, net, name);
    if (!m) return 0;
    const char *path = l->file.path;
    int64_t out_dim = shape[0], rank = m->down->shape[0], numel = 1;
    for (int d = 0; d < ndim; d++) numel *= shape[d];
    int64_t in_dim = out_dim ? numel / out_dim : 0, down_in = 1;
    for (int d = 1; d < m->down->ndim; d++) down_in *= m->down->shape[d];
    if (ndim < 2 || m->up->shape[0] != out_dim || down_in != in_dim)
        return mx_fail(st, MX_EINPUT, "%s: LoRA module '%s': up [%lld, %lld] @ down [%lld, %lld] does not fit '%s.%s' (%lld x %lld)",
                       path, m->key, (long long)m->up->shape[0], (long long)rank, (long long)rank, (long long)down_in,
                       net, name, (long long)out_dim, (long long)in_dim);
    double alpha;
    float *down = mx_st_to_f32(&l->file, m->down, st), *up = down ? mx_st_to_f32(&l->file, m->up, st) : NULL;
    double *acc = up ? malloc((size_t)(in_dim ? in_dim : 1) * sizeof *acc) : NULL;
    int rc = -1;
    if (down && up && !acc) mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    if (acc && !read_alpha(l, m, (double)rank, &alpha, st)) {
        /* row o of up @ down, accumulated in double over r in order, rows of down read contiguously */
        double factor = (double)scale * alpha / (double)rank;
        for (int64_t o = 0; o < out_dim; o++) {
            for (int64_t i = 0; i < in_dim; i++) acc[i] = 0;
            for (int64_t r = 0; r < rank; r++) {
                double u = up[o * rank + r];
                const float *drow = down + r * in_dim;
                for (int64_t i = 0; i < in_dim; i++) acc[i] += u * (double)drow[i];
            }
            float *wrow = w + o * in_dim;
            for (int64_t i = 0; i < in_dim; i++) wrow[i] = (float)((double)wrow[i] + factor * acc[i]);
        }
        m->used = 1;
        rc = 1;
    }
    free(acc);
    free(down);
    free(up);
    return rc;
}

int mx_lora_check_all_used(const mx_lora *l, mx_status *st) {
    for (size_t i = 0; i < l->count; i++)
        if (!l->mods[i].used)
            return mx_fail(st, MX_EINPUT,
                           "%s: LoRA module '%s' matches no UNet or text-encoder weight (kohya keys must use "
                           "diffusers module names)",
                           l->file.path, l->mods[i].key);
    return 0;
}
