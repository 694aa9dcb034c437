/* The step cache (step_cache.h). */
#include "step_cache.h"

#include "../../runtime/arena.h"

void mx_step_cache_begin(mx_step_cache *k) {
    if (k) k->cursor = 0;
}

void mx_step_cache_end(mx_step_cache *k, int real_and_ok) {
    if (k && k->mem && real_and_ok) k->recorded = 1;
}

int mx_step_cache_slot(mx_step_cache *k, size_t n, float *placeholder, float **slot, mx_status *st) {
    size_t align = MX_ARENA_ALIGN / sizeof(float), step = (n + align - 1) / align * align;
    if (!k->mem) { /* sizing, or a dry replay when marked recorded */
        k->cursor += step;
        *slot = placeholder;
        return k->recorded;
    }
    if (k->cursor > k->cap || step > k->cap - k->cursor)
        return mx_fail(st, MX_EINTERNAL, "step cache: %zu floats are too few for this forward", k->cap);
    *slot = k->mem + k->cursor;
    k->cursor += step;
    return k->recorded;
}
