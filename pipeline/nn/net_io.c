/* Helpers over the run-net tensor interface (net_io.h). */
#include "net_io.h"

#include <stdlib.h>

const float *mx_net_io_input(mx_net_io *io, const char *name, int ndim, int64_t *shape, mx_status *st) {
    const float *h = io->host(io, name, ndim, shape, st);
    return h ? io->device(io, h, (size_t)mx_shape_numel(ndim, shape), st) : NULL;
}

const float *mx_net_io_timesteps(mx_net_io *io, int B, mx_status *st) {
    size_t n;
    const float *v = io->host_flat(io, "timestep", &n, st);
    if (!v) return NULL;
    if (n != 1 && n != (size_t)B)
        return mx_fail(st, MX_EINPUT, "%s: tensor timestep has %zu elements, expected 1 or %d", io->source, n, B), NULL;
    float *ts = malloc((size_t)B * sizeof *ts);
    if (!ts) return mx_fail(st, MX_ENOMEM, "out of memory"), NULL;
    for (int i = 0; i < B; i++) ts[i] = v[n == 1 ? 0 : i];
    const float *d = io->device(io, ts, (size_t)B, st);
    free(ts);
    return d;
}
