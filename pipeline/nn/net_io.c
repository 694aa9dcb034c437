/* Helpers over the run-net tensor interface (net_io.h). */
#include "net_io.h"

#include <stdio.h>
#include <stdlib.h>

int mx_net_slots_add(mx_net_slots *s, const char *name, int flags, mx_status *st) {
    if (s->n == s->cap) {
        int cap = s->cap ? 2 * s->cap : 16;
        mx_net_bound_slot *p = realloc(s->slot, (size_t)cap * sizeof *p);
        if (!p) return mx_fail(st, MX_ENOMEM, "out of memory");
        s->slot = p, s->cap = cap;
    }
    mx_net_bound_slot *b = &s->slot[s->n];
    if ((size_t)snprintf(b->name, sizeof b->name, "%s", name) >= sizeof b->name)
        return mx_fail(st, MX_EINTERNAL, "tensor name %s is too long", name);
    b->flags = flags;
    b->at = -1;
    s->n++;
    return 0;
}

void mx_net_slots_free(mx_net_slots *s) {
    free(s->slot);
    *s = (mx_net_slots){0};
}

int mx_net_io_has(const mx_net_io *io, int slot) { return io->slots->slot[slot].at >= 0; }

const float *mx_net_io_input(mx_net_io *io, int slot, int ndim, int64_t *shape, mx_status *st) {
    const float *h = io->host(io, slot, ndim, shape, st);
    return h ? io->device(io, h, (size_t)mx_shape_numel(ndim, shape), st) : NULL;
}

const float *mx_net_io_timesteps(mx_net_io *io, int slot, int B, mx_status *st) {
    size_t n;
    const float *v = io->host_flat(io, slot, &n, st);
    if (!v) return NULL;
    if (n != 1 && n != (size_t)B)
        return mx_fail(st, MX_EINPUT, "%s: tensor %s has %zu elements, expected 1 or %d", io->source,
                       io->slots->slot[slot].name, n, B),
               NULL;
    float *ts = malloc((size_t)B * sizeof *ts);
    if (!ts) return mx_fail(st, MX_ENOMEM, "out of memory"), NULL;
    for (int i = 0; i < B; i++) ts[i] = v[n == 1 ? 0 : i];
    const float *d = io->device(io, ts, (size_t)B, st);
    free(ts);
    return d;
}
