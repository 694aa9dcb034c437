#include "cli_api.h"

#include <stdio.h>
#include <string.h>

#include "../pipeline/texture/api_opts.h"

void mx_cli_api_status(const matex_error *err, mx_status *st) {
    st->code = err->code; /* the same numbers */
    snprintf(st->msg, sizeof st->msg, "%s", err->message);
}

/* The API's progress events back to the pipeline's callback of the CLI (user: its options). */
static int forward_progress(void *user, const matex_progress *p) {
    const mx_texture_opts *t = user;
    mx_texture_progress q = {p->stage, p->step, p->steps, p->views_done, p->views_total, p->coverage, p->seconds, p->message};
    return t->progress(t->progress_user, &q);
}

typedef int (*api_fn)(matex_models *, const matex_options *, matex_result **, matex_error *);

static int run_once(api_fn fn, const mx_texture_opts *t, mx_texture_result *res, mx_status *st) {
    matex_error err;
    matex_options o;
    mx_api_options_from_internal(t, &o);
    if (t->progress) {
        o.progress = forward_progress;
        o.progress_user = (void *)t;
    }
    matex_models *m = matex_models_open(t->weights_path, &o, &err);
    if (!m) {
        mx_cli_api_status(&err, st);
        return -1;
    }
    matex_result *r = NULL;
    int rc = fn(m, &o, res ? &r : NULL, &err);
    if (rc) mx_cli_api_status(&err, st);
    if (!rc && res) {
        memset(res, 0, sizeof *res);
        res->coverage = r->coverage;
        res->views = r->views;
        res->seconds = r->seconds;
    }
    matex_result_free(r);
    matex_models_close(m);
    return rc;
}

int mx_cli_api_texture(const mx_texture_opts *t, mx_texture_result *res, mx_status *st) {
    return run_once(matex_texture, t, res, st);
}

int mx_cli_api_enhance(const mx_texture_opts *t, mx_texture_result *res, mx_status *st) {
    return run_once(matex_enhance, t, res, st);
}
