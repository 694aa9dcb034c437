/* The named tensors of one network call as `matex run-net` sees them (a safetensors file in,
 * one out). A registry entry (registry.h) declares the names of its inputs and outputs once, as
 * slots: a static table, plus the ones its loaded network's config adds (the UNet's residuals,
 * CLIP's hidden_states.{i}). mx_net_bind resolves them against the io once, when the network is
 * loaded for a call; after that the entry's arena_bytes and run address every tensor by its slot
 * index, never by name. tools/matex/cmd_run_net.c implements the io; every tensor it hands out
 * stays its own (freed after the call). */
#ifndef MX_NN_NET_IO_H
#define MX_NN_NET_IO_H

#include <stddef.h>
#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "../../weights/networks.h"

/* A slot of an entry's static table (terminated by a NULL name). */
enum { MX_SLOT_IN = 0, MX_SLOT_OUT = 1, MX_SLOT_OPTIONAL = 2 /* an input the call may omit */ };
typedef struct mx_net_slot {
    const char *name;
    int flags;
} mx_net_slot;

/* The slots of one call, bound: their names and, for inputs, the io's handle of the tensor. */
typedef struct mx_net_bound_slot {
    char name[48];
    int flags;
    int at; /* inputs: io->find's handle, -1 when the call has none */
} mx_net_bound_slot;
typedef struct mx_net_slots {
    mx_net_bound_slot *slot;
    int n, cap;
} mx_net_slots;

/* Appends slot `name` (index s->n before the call). */
int mx_net_slots_add(mx_net_slots *s, const char *name, int flags, mx_status *st);
void mx_net_slots_free(mx_net_slots *s);

typedef struct mx_net_io mx_net_io;
struct mx_net_io {
    void *impl;
    const char *source;         /* the inputs' file, for messages */
    const mx_net_slots *slots;  /* set by mx_net_bind: what the slot indices below mean */
    /* Binding only (mx_net_bind): the io's handle of input `name`, -1 when the call has none. */
    int (*find)(mx_net_io *io, const char *name);
    /* The shape of input `slot` of ndim dimensions, checked as host checks it, without a copy. */
    int (*shape)(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st);
    /* HOST fp32 copy of input `slot` of ndim dimensions; shape[i] = -1 accepts any size and is
     * filled in, others must match. NULL with st set when missing, of another shape or too large. */
    const float *(*host)(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st);
    /* HOST fp32 copy of input `slot` of any shape, flattened to *numel values (a 0-d tensor is 1). */
    const float *(*host_flat)(mx_net_io *io, int slot, size_t *numel, mx_status *st);
    /* Device copy of n host floats (an input of the call). */
    const float *(*device)(mx_net_io *io, const float *host, size_t n, mx_status *st);
    /* Device memory for output `slot` of this shape, written to the outputs after the call. */
    float *(*output)(mx_net_io *io, int slot, int ndim, const int64_t *shape, mx_status *st);
    /* Another network of the same weight file, by its kind (MX_NET_IP_ADAPTER: prefix
     * "ip_adapter."), loaded with its weights on the device (freed after the call; the same one
     * each time it is asked for); NULL with st set when the file has none. */
    const void *(*network)(mx_net_io *io, const char *kind, mx_status *st);
};

/* 1 when the call holds input `slot`. */
int mx_net_io_has(const mx_net_io *io, int slot);
/* Device copy of input `slot` (shape as io->host). */
const float *mx_net_io_input(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st);
/* Device copy of the timesteps: input `slot` ("timestep") of 1 or B values (any dtype and
 * shape), one per batch item. */
const float *mx_net_io_timesteps(mx_net_io *io, int slot, int B, mx_status *st);

#endif
