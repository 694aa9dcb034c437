/* A registry entry's tensors bound to slots (registry.h mx_net_bind, net_io.h): a missing or
 * misspelt input is refused at bind time, naming it; after binding, arena_bytes and run address
 * the tensors by slot only: the io's one by-name function (find) aborts once the call is bound.
 * The run is CLIP's on golden/clip_tiny (its hidden_states.{i} outputs come from the config). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../pipeline/nn/clip.h"
#include "nn_golden.h"

#define MAX_DEV 64

/* An io over a few host tensors; outputs are device buffers counted per slot. */
typedef struct fake_tensor {
    const char *name;
    int ndim;
    int64_t shape[4];
    const float *data;
} fake_tensor;

typedef struct fake_io {
    mx_net_io io;
    const mx_ctx *c;
    const fake_tensor *t;
    int nt;
    int bound; /* set once mx_net_bind returned: a name lookup after it aborts */
    int finds;
    float *dev[MAX_DEV];
    int ndev;
    int outputs[MAX_DEV]; /* times each slot was asked for as an output */
} fake_io;

static int fake_find(mx_net_io *io, const char *name) {
    fake_io *f = io->impl;
    if (f->bound) {
        fprintf(stderr, "input %s looked up by name after binding\n", name);
        abort();
    }
    f->finds++;
    for (int i = 0; i < f->nt; i++)
        if (!strcmp(f->t[i].name, name)) return i;
    return -1;
}

static const fake_tensor *fake_tensor_of(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st) {
    fake_io *f = io->impl;
    int at = io->slots->slot[slot].at;
    if (at < 0) return mx_fail(st, MX_EINPUT, "missing input tensor %s", io->slots->slot[slot].name), NULL;
    const fake_tensor *t = &f->t[at];
    if (t->ndim != ndim) return mx_fail(st, MX_EINPUT, "tensor %s: %d dimensions", t->name, t->ndim), NULL;
    for (int i = 0; i < ndim; i++) {
        if (shape[i] >= 0 && shape[i] != t->shape[i]) return mx_fail(st, MX_EINPUT, "tensor %s: shape", t->name), NULL;
        shape[i] = t->shape[i];
    }
    return t;
}

static int fake_shape(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st) {
    return fake_tensor_of(io, slot, ndim, shape, st) ? 0 : -1;
}

static const float *fake_host(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st) {
    const fake_tensor *t = fake_tensor_of(io, slot, ndim, shape, st);
    return t ? t->data : NULL;
}

static const float *fake_host_flat(mx_net_io *io, int slot, size_t *numel, mx_status *st) {
    int64_t shape[4] = {-1, -1, -1, -1};
    int at = io->slots->slot[slot].at;
    const fake_tensor *t = fake_tensor_of(io, slot, at < 0 ? 0 : ((fake_io *)io->impl)->t[at].ndim, shape, st);
    if (!t) return NULL;
    *numel = (size_t)mx_shape_numel(t->ndim, t->shape);
    return t->data;
}

static float *fake_keep(fake_io *f, float *d, mx_status *st) {
    if (d && f->ndev == MAX_DEV) return mx_fail(st, MX_EINTERNAL, "too many device buffers"), NULL;
    if (d) f->dev[f->ndev++] = d;
    return d;
}

static const float *fake_device(mx_net_io *io, const float *host, size_t n, mx_status *st) {
    fake_io *f = io->impl;
    return fake_keep(f, mx_dev_from_host(f->c, host, n, st), st);
}

static float *fake_output(mx_net_io *io, int slot, int ndim, const int64_t *shape, mx_status *st) {
    fake_io *f = io->impl;
    if (slot < 0 || slot >= MAX_DEV) return mx_fail(st, MX_EINTERNAL, "output slot %d", slot), NULL;
    f->outputs[slot]++;
    return fake_keep(f, mx_dev_alloc(f->c, (size_t)mx_shape_numel(ndim, shape), st), st);
}

static const void *fake_network(mx_net_io *io, const char *kind, mx_status *st) {
    (void)io;
    return mx_fail(st, MX_EINPUT, "no companion network %s", kind), NULL;
}

static void fake_init(fake_io *f, const mx_ctx *c, const fake_tensor *t, int nt) {
    memset(f, 0, sizeof *f);
    f->c = c, f->t = t, f->nt = nt;
    f->io = (mx_net_io){.impl = f,
                        .source = "fake.safetensors",
                        .find = fake_find,
                        .shape = fake_shape,
                        .host = fake_host,
                        .host_flat = fake_host_flat,
                        .device = fake_device,
                        .output = fake_output,
                        .network = fake_network};
}

static void fake_free(fake_io *f) {
    for (int i = 0; i < f->ndev; i++) mx_dev_free(f->c, f->dev[i]);
}

/* A misspelt input ("latent") is refused by mx_net_bind, naming the one the entry declares. The
 * VAE's slots are all static, so no network is needed. */
static void test_misspelt_input_refused_at_bind(const mx_ctx *c) {
    static const float x[1] = {0};
    const fake_tensor t[1] = {{"latent", 4, {1, 4, 1, 1}, x}};
    fake_io f;
    mx_net_slots s;
    mx_status st = {0};
    fake_init(&f, c, t, 1);
    const mx_net_def *def = mx_net_named("vae-decode");
    CHECK(def && mx_net_bind(def, NULL, &f.io, &s, &st) != 0);
    CHECK(st.code == MX_EINPUT && strstr(st.msg, "fake.safetensors: missing input tensor latents") != NULL);
    CHECK(f.io.slots == NULL); /* not bound */
    mx_net_slots_free(&s);
}

/* CLIP on golden/clip_tiny: bound once (one find, for input_ids; the hidden_states.{i} outputs
 * from the config), then sized and run with name lookups aborting; every output slot is asked
 * for exactly once. A missing input_ids is refused at bind. */
static void test_clip_runs_by_slot(const mx_ctx *c) {
    if (!golden_have("clip_tiny", "model.safetensors")) return;
    golden_net k;
    if (golden_net_load(&k, c, "clip_tiny", "model.safetensors", MX_NET_TEXT_ENCODER)) {
        CHECK(0);
        return;
    }
    const mx_net_def *def = mx_net_named("clip");
    mx_net_slots s;
    mx_status st = {0};
    fake_io f;
    fake_init(&f, c, NULL, 0);
    CHECK(def && mx_net_bind(def, k.net, &f.io, &s, &st) != 0 && strstr(st.msg, "missing input tensor input_ids"));
    mx_net_slots_free(&s);

    float ids[2 * 5];
    for (int i = 0; i < 10; i++) ids[i] = (float)(i * 7 % 50);
    const fake_tensor t[2] = {{"unused", 1, {1}, ids}, {"input_ids", 2, {2, 5}, ids}};
    fake_init(&f, c, t, 2);
    int ok = mx_net_bind(def, k.net, &f.io, &s, &st) == 0;
    if (!ok) fprintf(stderr, "%s\n", st.msg);
    CHECK(ok);
    if (ok) {
        f.bound = 1;
        size_t bytes = 0;
        mx_arena a;
        CHECK(f.finds == 1 && s.slot[0].at == 1);
        CHECK(def->arena_bytes(k.net, &f.io, &bytes, &st) == 0 && bytes > 0);
        golden_arena(c, &a, bytes);
        ok = def->run(c, k.net, &f.io, &a, &st) == 0;
        if (!ok) fprintf(stderr, "%s\n", st.msg);
        CHECK(ok);
        mx_arena_destroy(&a);
        int outs = 0;
        for (int i = 0; i < s.n; i++) {
            int is_out = (s.slot[i].flags & MX_SLOT_OUT) != 0;
            CHECK(i < MAX_DEV && f.outputs[i] == is_out);
            outs += is_out;
        }
        /* last_hidden_state, pooler_output and hidden_states.0..L */
        CHECK(outs == 3 + ((const mx_clip *)k.net)->cfg.num_hidden_layers);
        CHECK(!strcmp(s.slot[3].name, "hidden_states.0"));
    }
    mx_net_slots_free(&s);
    fake_free(&f);
    golden_net_free(&k);
}

int main(void) {
    mx_ctx c;
    if (golden_ctx(&c)) return 1;
    test_misspelt_input_refused_at_bind(&c);
    test_clip_runs_by_slot(&c);
    mx_ctx_destroy(&c);
    return mx_test_finish("test_nn_net_bind");
}
