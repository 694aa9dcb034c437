/* Recorded regions (record.h): the first call direct, later ones through the backend's hook. */
#include "record.h"

#include <string.h>

int mx_ctx_recorded(const mx_ctx *c, mx_record *rec, int (*fn)(void *user, mx_status *st), void *user,
                    mx_status *st) {
    mx_backend *be = c ? c->be : NULL;
    if (++rec->calls == 1 || !be || !be->recorded) return fn(user, st); /* a measuring context has no backend */
    return be->recorded(be, rec, fn, user, st);
}

void mx_record_free(const mx_ctx *c, mx_record *rec) {
    mx_backend *be = c ? c->be : NULL;
    if (be && be->record_drop) be->record_drop(be, rec);
    memset(rec, 0, sizeof *rec);
}
