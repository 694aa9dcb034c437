/* A restricted reader of the pickles inside PyTorch checkpoints (the data.pkl of a torch.save
 * zip): it understands only what a tensor checkpoint holds, never calls anything, and refuses
 * the rest with a message naming it. Accepted: the opcodes of protocols 2-5 that build plain
 * values (None, bools, ints, floats, strings, bytes, tuples, lists, dicts, the memo), the
 * persistent ids of storages, and these globals, each applied by REDUCE to its expected
 * arguments: collections.OrderedDict, torch._utils._rebuild_tensor_v2, _rebuild_parameter,
 * _rebuild_parameter_with_state, and the torch.*Storage types. Any other global (os.system,
 * builtins.eval, a class to instantiate) ends the reading with "global 'module.name' is not
 * allowed". Sizes are bounded (memo, stack, values), every tensor view is checked against its
 * storage, and containers that would contain themselves are refused. */
#ifndef MX_PICKLE_H
#define MX_PICKLE_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/status.h"
#include "safetensors.h"

/* Finds the bytes of storage KEY (the archive entry data/KEY): returns 0 with *data and
 * *nbytes set, or -1 with a message. */
typedef int (*mx_pickle_storage_fn)(void *ctx, const char *key, const void **data, size_t *nbytes, mx_status *st);

typedef struct mx_pickle_result {
    mx_st_tensor *tensors; /* names malloc'ed; data points into the storages */
    size_t count;
    size_t skipped; /* entries of the state dict that are not tensors */
} mx_pickle_result;

/* Reads the pickle P (N bytes) of a checkpoint: the state dict is the top-level dict, or its
 * "state_dict" entry when it has one. A dict of tensors inside it under a name gives its tensors
 * as "name.key" (the IP-Adapter .bin: {"image_proj": {...}, "ip_adapter": {...}}), one level.
 * `what` names the source in messages. */
int mx_pickle_read_state_dict(const uint8_t *p, size_t n, const char *what, mx_pickle_storage_fn storage, void *ctx,
                              mx_pickle_result *out, mx_status *st);

#endif
