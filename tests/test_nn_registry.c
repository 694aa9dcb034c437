/* The network registry (pipeline/nn/registry.h) against the one list of networks
 * (weights/networks.h): every entry carries the four operations and names a listed network,
 * every listed network has an entry, names are unique, lookups find what they should; every entry
 * declares its tensors as slots (an input and an output at least, no name twice). */
#include <stdio.h>
#include <string.h>

#include "../pipeline/nn/registry.h"
#include "util_test.h"

static void test_entries_complete(void) {
    for (size_t i = 0; i < mx_net_count; i++) {
        const mx_net_def *d = &mx_nets[i];
        CHECK(d->name && d->help && d->slots && d->load && d->arena_bytes && d->run && d->free);
        int ins = 0, outs = 0;
        for (const mx_net_slot *p = d->slots; p->name; p++) {
            ins += !(p->flags & MX_SLOT_OUT), outs += (p->flags & MX_SLOT_OUT) != 0;
            for (const mx_net_slot *q = d->slots; q < p; q++) CHECK(strcmp(p->name, q->name) != 0);
        }
        CHECK(ins > 0 && (outs > 0 || d->more_slots)); /* controlnet's outputs all come from its config */
        CHECK(mx_net_kind_named(d->kind) != NULL); /* the kind is one of the list's */
        CHECK(mx_net_named(d->name) == d);           /* names are unique */
        /* the entries of one network share its load and free */
        const mx_net_def *first = mx_net_of_kind(d->kind);
        CHECK(first && first->load == d->load && first->free == d->free);
    }
}

static void test_every_kind_attached(void) {
    CHECK(mx_net_kind_count <= MX_NET_KIND_MAX);
    for (size_t i = 0; i < mx_net_kind_count; i++) {
        const mx_net_kind *k = &mx_net_kinds[i];
        const mx_net_def *d = mx_net_of_kind(k->name);
        CHECK(d != NULL && !strcmp(d->kind, k->name));
        CHECK(mx_net_of_class(k->class_name) == d);
        CHECK(mx_net_kind_named(k->name) == k && mx_net_kind_of_class(k->class_name) == k);
    }
}

static void test_lookups(void) {
    const mx_net_def *enc = mx_net_named("vae-encode"), *dec = mx_net_named("vae-decode");
    CHECK(enc && dec && enc != dec && !strcmp(enc->kind, MX_NET_VAE) && !strcmp(dec->kind, MX_NET_VAE));
    CHECK(enc->run != dec->run && enc->arena_bytes != dec->arena_bytes);
    CHECK(mx_net_named("vae") == NULL && mx_net_named(NULL) == NULL && mx_net_of_kind("no_such") == NULL);
    CHECK(mx_net_of_class("AutoencoderKL") == mx_net_of_kind(MX_NET_VAE));
}

int main(void) {
    test_entries_complete();
    test_every_kind_attached();
    test_lookups();
    return mx_test_finish("test_nn_registry");
}
