/* The ready-made context (ops.h): a backend (ops/backend.c), a thread pool, a scratch arena and,
 * on request, the packed-weight cache (ops/cpu/wpack.h). Apart from ops.c so that the op layer
 * and the backends stay one way: backend.c uses ops.c's tables, ctx.c uses both. */
#include <stdlib.h>
#include <string.h>

#include "cpu/wpack.h"
#include "ops.h"

int mx_ctx_create(mx_ctx *c, int nthreads, mx_isa isa, size_t scratch_bytes, mx_status *st) {
    return mx_ctx_create_on(c, MX_BACKEND_CPU, nthreads, isa, scratch_bytes, st);
}

int mx_ctx_create_on(mx_ctx *c, mx_backend_kind kind, int nthreads, mx_isa isa, size_t scratch_bytes,
                     mx_status *st) {
    memset(c, 0, sizeof *c);
    if (mx_backend_create(&c->be, kind, isa, st)) return -1;
    c->k = c->be->k;
    c->pool = mx_pool_create(nthreads, st);
    if (!c->pool) {
        mx_ctx_destroy(c); /* the backend is already made */
        return -1;
    }
    c->scratch = malloc(sizeof *c->scratch);
    if (!c->scratch) {
        mx_ctx_destroy(c);
        return mx_fail(st, MX_ENOMEM, "ops context: out of memory");
    }
    if (mx_arena_create(c->scratch, scratch_bytes, st) != 0) {
        free(c->scratch);
        c->scratch = NULL;
        mx_ctx_destroy(c);
        return mx_fail_prefix(st, "ops context scratch");
    }
    return 0;
}

void mx_ctx_destroy(mx_ctx *c) {
    if (c->scratch) {
        mx_arena_destroy(c->scratch);
        free(c->scratch);
    }
    mx_wpack_destroy(c->wpack);
    mx_pool_destroy(c->pool);
    mx_backend_destroy(c->be);
    memset(c, 0, sizeof *c);
}

int mx_ctx_pack_weights(mx_ctx *c, size_t extra_bytes, int sources_mapped, mx_status *st) {
    if (c->wpack || (c->be && c->be->kind != MX_BACKEND_CPU)) return 0;
    return mx_wpack_create(&c->wpack, extra_bytes, sources_mapped, st);
}
