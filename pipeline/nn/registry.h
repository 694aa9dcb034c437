/* The networks matex runs, one entry per run (registry.c): encode and decode of an autoencoder
 * are two entries of one network. Every entry carries the same four operations, one signature
 * each:
 *
 *   load         the network from its config text and a binder of its weights (*net freed by
 *                free, also after a failure);
 *   arena_bytes  the activation arena one run on io's inputs needs (from their shapes);
 *   run          the run: inputs from io, outputs declared on io, activations on arena a of
 *                arena_bytes; both address the tensors by slot index only, the names (the
 *                entry's slots, plus more_slots' from the loaded config) resolved once by
 *                mx_net_bind;
 *   free         the loaded network.
 *
 * The list of networks (their names = weight-file prefixes, config classes) is
 * weights/networks.h's; this table attaches the code by kind. Everything that handles "any
 * network" (run-net, gen-weights' parameter lists, the network tests' loader, the model set,
 * the benchmarks) goes through it; it is read when a network is loaded, never inside a forward
 * pass (pipeline/nn includes it nowhere else: no network calls back up into it).
 *
 * Adding a network: its file (config parse, load, forward, free and the entry points below), one
 * line in weights/networks.c (name, class), its entries in registry.c, and its tests. */
#ifndef MX_NN_REGISTRY_H
#define MX_NN_REGISTRY_H

#include <stddef.h>

#include "../../weights/networks.h"
#include "../../weights/weights.h"
#include "net_io.h"
#include "netcfg.h"
#include "params.h"

/* Parses config text[0..len) (`what` names it in messages) and loads the network from b into
 * *net (freed by the entry's free, also after a failure). */
typedef int (*mx_net_load_fn)(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st);
/* The arena bytes of one run on io's inputs (their shapes checked). */
typedef int (*mx_net_arena_fn)(const void *net, mx_net_io *io, size_t *bytes, mx_status *st);
/* One run: inputs from io, outputs declared on io, activations on a (arena_bytes big). */
typedef int (*mx_net_run_fn)(const mx_ctx *c, const void *net, mx_net_io *io, mx_arena *a, mx_status *st);

typedef struct mx_net_def {
    const char *name; /* "vae-decode": the run-net NET */
    const char *kind; /* MX_NET_VAE: the network of weights/networks.h it runs */
    const char *help; /* its tensors, "latents [B,4,h,w] (unscaled) -> image" (lines after the first
                         indented by 15 spaces, under the usage's column) */
    const mx_net_slot *slots; /* its inputs and outputs, NULL-terminated: slot i = slots[i] */
    /* The slots its loaded network's config adds after those (NULL: none). */
    int (*more_slots)(const void *net, mx_net_slots *s, mx_status *st);
    mx_net_load_fn load;
    mx_net_arena_fn arena_bytes;
    mx_net_run_fn run;
    void (*free)(void *net);
} mx_net_def;

extern const mx_net_def mx_nets[];
extern const size_t mx_net_count;

/* The slots of def's run on net into s (freed by mx_net_slots_free, also after a failure), each
 * input resolved through io->find; a required input the call lacks is refused, naming it. Sets
 * io->slots = s: from here on arena_bytes and run address the tensors by slot index. */
int mx_net_bind(const mx_net_def *def, const void *net, mx_net_io *io, mx_net_slots *s, mx_status *st);

/* The entry named `name` ("vae-decode"), or NULL. */
const mx_net_def *mx_net_named(const char *name);
/* The first entry of network `kind` (MX_NET_VAE: its load and free), of a config class, or NULL. */
const mx_net_def *mx_net_of_kind(const char *kind);
const mx_net_def *mx_net_of_class(const char *class_name);

/* The network a config text describes, loaded from b (the first entry of its kind in *def); NULL
 * def for an unknown class is an error naming the known ones. */
int mx_net_load_config(const mx_net_def **def, void **net, const char *text, size_t len, const char *what,
                       mx_binder *b, mx_status *st);
/* Network `kind` of weight file wf (config "<prefix>.config", weights "<prefix>.*"; prefix NULL:
 * the kind's name) loaded from b (a binder over those weights) into *net; the config's class must
 * be of that kind. */
int mx_net_load_kind(const char *kind, void **net, const mx_weightfile *wf, const char *prefix, mx_binder *b,
                     mx_status *st);
/* Enumerates the parameter list (names without prefix, shapes) of the network a config text
 * describes into an enumerating binder (mx_binder_enum), through the network's own load code. */
int mx_net_enumerate(mx_binder *b, const char *text, size_t len, const char *what, mx_status *st);

#endif
