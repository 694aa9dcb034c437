/* The networks matex runs, one entry each (registry.c): what weights/networks.h knows of the
 * network in a file (its name = weight-file prefix, its config class), plus its code: the config
 * parse and load from a binder, free, the precision policy's whole-network rule, and its
 * `matex run-net` verbs (name, tensors in and out, the adapter that runs it on mx_net_io).
 * Everything that handles "any network" (run-net, gen-weights' parameter lists, the network
 * tests' loader, the precision policy) goes through this table; it is read when a network is
 * loaded, never inside a forward pass.
 *
 * Adding a network: its file (config parse, load, forward, free, the adapters below), one line in
 * weights/networks.c (name, class) and one entry in registry.c. */
#ifndef MX_NN_REGISTRY_H
#define MX_NN_REGISTRY_H

#include <stddef.h>

#include "../../weights/networks.h"
#include "net_io.h"
#include "netcfg.h"
#include "params.h"

/* Parses config text[0..len) (`what` names it in messages) and loads the network from b into
 * *net (freed by the entry's free, also after a failure). */
typedef int (*mx_net_load_fn)(void **net, const char *text, size_t len, const char *what, mx_binder *b,
                              mx_status *st);
/* One `matex run-net` call of a loaded network: inputs from io, outputs declared on io. */
typedef int (*mx_net_run_fn)(const mx_ctx *c, const void *net, mx_net_io *io, mx_status *st);

typedef struct mx_net_verb {
    const char *name; /* "vae-decode": the run-net NET */
    const char *help; /* its tensors, "latents [B,4,h,w] (unscaled) -> image" (lines after the first
                         indented by 15 spaces, under the usage's column) */
    mx_net_run_fn run;
} mx_net_verb;

#define MX_NET_MAX_VERBS 2

typedef struct mx_net_def {
    const char *kind; /* its entry in weights/networks.h (MX_NET_UNET) */
    mx_net_load_fn load;
    void (*free)(void *net);
    mx_net_verb verbs[MX_NET_MAX_VERBS]; /* unused slots have name NULL */
} mx_net_def;

extern const mx_net_def mx_nets[];
extern const size_t mx_net_count;

/* The entry of network `kind` ("vae"), of a config class, or NULL. */
const mx_net_def *mx_net_named(const char *kind);
const mx_net_def *mx_net_of_class(const char *class_name);
/* The run-net verb `name` and its network (*net), or NULL. */
const mx_net_verb *mx_net_verb_named(const char *name, const mx_net_def **net);

/* The network a config text describes, loaded from b (the entry in *def); NULL def for an unknown
 * class is an error naming the known ones. */
int mx_net_load_config(const mx_net_def **def, void **net, const char *text, size_t len, const char *what,
                       mx_binder *b, mx_status *st);
/* Enumerates the parameter list (names without prefix, shapes) of the network a config text
 * describes into an enumerating binder (mx_binder_enum), through the network's own load code. */
int mx_net_enumerate(mx_binder *b, const char *text, size_t len, const char *what, mx_status *st);

#endif
