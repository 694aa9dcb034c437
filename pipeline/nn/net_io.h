/* The named tensors of one network call as `matex run-net` sees them (a safetensors file in,
 * one out): a registry entry (registry.h) sizes its arena from its inputs' shapes (arena_bytes),
 * then its run asks for its inputs by name with the shape it accepts and declares its outputs. tools/matex/cmd_run_net.c implements it; every tensor it hands out stays its own (freed after
 * the call). */
#ifndef MX_NN_NET_IO_H
#define MX_NN_NET_IO_H

#include <stddef.h>
#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"
#include "../../weights/networks.h"

typedef struct mx_net_io mx_net_io;
struct mx_net_io {
    void *impl;
    const char *source; /* the inputs' file, for messages */
    /* 1 when the inputs hold `name`. */
    int (*has)(mx_net_io *io, const char *name);
    /* The shape of input `name` of ndim dimensions, checked as host checks it, without a copy. */
    int (*shape)(mx_net_io *io, const char *name, int ndim, int64_t *shape, mx_status *st);
    /* HOST fp32 copy of input `name` of ndim dimensions; shape[i] = -1 accepts any size and is
     * filled in, others must match. NULL with st set when missing, of another shape or too large. */
    const float *(*host)(mx_net_io *io, const char *name, int ndim, int64_t *shape, mx_status *st);
    /* HOST fp32 copy of input `name` of any shape, flattened to *numel values (a 0-d tensor is 1). */
    const float *(*host_flat)(mx_net_io *io, const char *name, size_t *numel, mx_status *st);
    /* Device copy of n host floats (an input of the call). */
    const float *(*device)(mx_net_io *io, const float *host, size_t n, mx_status *st);
    /* Device memory for output `name` of this shape, written to the outputs after the call. */
    float *(*output)(mx_net_io *io, const char *name, int ndim, const int64_t *shape, mx_status *st);
    /* Another network of the same weight file, by its kind (MX_NET_IP_ADAPTER: prefix
     * "ip_adapter."), loaded with its weights on the device (freed after the call; the same one
     * each time it is asked for); NULL with st set when the file has none. */
    const void *(*network)(mx_net_io *io, const char *kind, mx_status *st);
};

/* Device copy of input `name` (shape as io->host). */
const float *mx_net_io_input(mx_net_io *io, const char *name, int ndim, int64_t *shape, mx_status *st);
/* Device copy of the timesteps: input "timestep" of 1 or B values (any dtype and shape), one per
 * batch item. */
const float *mx_net_io_timesteps(mx_net_io *io, int B, mx_status *st);

#endif
