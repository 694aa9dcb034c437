#include "cli_texture_opts.h"

#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/buf.h"
#include "../../pipeline/texture/style.h"
#include "../../runtime/log.h"
#include "cli_progress.h"
#include "cli_signals.h"

void mx_cli_print_json_error(const char *msg) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"ok\":false,\"error\":");
    mx_buf_json_str(&b, msg);
    mx_buf_printf(&b, "}");
    puts(b.oom ? "{\"ok\":false,\"error\":\"out of memory\"}" : b.p);
    mx_buf_free(&b);
}

int mx_cli_usage_error(const char *verb, int json, const char *fmt, ...) {
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    fprintf(stderr, "matex %s: %s\n(matex %s --help for usage)\n", verb, msg, verb);
    if (json == MX_CLI_JSON_STREAM) mx_cli_progress_result(stdout, 2, msg, NULL, NULL);
    else if (json) mx_cli_print_json_error(msg);
    return 2;
}

int mx_cli_texture_option(mx_cli_texture *c, const char *name, const char *value, mx_status *st) {
    const mx_option_spec *s = mx_option_find(name, c->verb);
    const char *dashes = name[0] == '-' ? "" : "--";
    if (!s) {
        const mx_option_spec *other = mx_option_find(name, MX_VERB_TEXTURE | MX_VERB_ENHANCE | MX_VERB_TRANSFER);
        if (other) {
            char verbs[64] = "";
            for (unsigned v = MX_VERB_TEXTURE; v <= MX_VERB_TRANSFER; v <<= 1)
                if (mx_option_find(name, v))
                    snprintf(verbs + strlen(verbs), sizeof verbs - strlen(verbs), "%s%s", verbs[0] ? " and " : "", mx_options_verb_name(v));
            return mx_fail(st, MX_EUSAGE, "%s%s is not an option of %s (it is one of %s)", dashes, name, mx_options_verb_name(c->verb), verbs);
        }
        return mx_fail(st, MX_EUSAGE, "unknown option %s%s", dashes, name);
    }
    int takes_value = s->arg != NULL;
    if (!takes_value && value) return mx_fail(st, MX_EUSAGE, "--%s takes no value (not '%s')", s->name, value);
    if (takes_value && !value) return mx_fail(st, MX_EUSAGE, "missing value after %s%s", dashes, name);
    c->steps_given |= !strcmp(s->name, "steps");
    c->guidance_given |= !strcmp(s->name, "guidance");
    if (s->type != MX_OPTION_CLI) return mx_option_set(s, &c->o, value, st);
    int stream;
    if (!strcmp(s->name, "weights")) c->weights_path = value;
    else if (!strcmp(s->name, "quiet")) c->quiet = 1;
    else if (!strcmp(s->name, "json") && !c->json) c->json = MX_CLI_JSON_SUMMARY; /* the stream wins */
    else if (!strcmp(s->name, "progress") && mx_cli_progress_parse(value, &stream))
        return mx_fail(st, MX_EUSAGE, "--progress must be text or json, not '%s'", value);
    return 0;
}

/* One positional argument (MESH, PROMPT; SRC, DST for transfer); -1 when there is no room. */
static int positional(mx_cli_texture *c, const char *arg) {
    const char **slots[2] = {&c->o.mesh_path, &c->o.prompt};
    if (c->verb == MX_VERB_TRANSFER) slots[0] = &c->o.source_path, slots[1] = &c->o.mesh_path;
    for (int i = 0; i < 2; i++)
        if (!*slots[i]) return *slots[i] = arg, 0;
    return -1;
}

/* What a complete command line must hold; 0 or a usage error's exit code. */
static int check_complete(mx_cli_texture *c, const char *verb) {
    if (c->verb == MX_VERB_TRANSFER) {
        if (!c->o.source_path || !c->o.mesh_path) return mx_cli_usage_error(verb, c->json, "needs SRC_TEXTURED and DST_MESH");
    } else {
        if (!c->o.mesh_path) return mx_cli_usage_error(verb, c->json, "missing MESH");
        if (!c->o.prompt) {
            if (c->verb == MX_VERB_TEXTURE) return mx_cli_usage_error(verb, c->json, "missing PROMPT");
            c->o.prompt = "";
        }
        if (!c->weights_path) return mx_cli_usage_error(verb, c->json, "missing --weights FILE");
    }
    if (!c->o.out_dir) return mx_cli_usage_error(verb, c->json, "missing -o OUT_DIR");
    return 0;
}

int mx_cli_texture_parse(mx_cli_texture *c, int argc, char **argv, unsigned verb, void (*usage)(FILE *)) {
    const char *name = argv[0];
    memset(c, 0, sizeof *c);
    matex_options_default(&c->o);
    c->verb = verb;
    c->json = mx_cli_progress_scan(argc, argv); /* usage errors in JSON too */
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return usage(stdout), 0;
        if (arg[0] != '-' || !arg[1]) {
            if (positional(c, arg)) return mx_cli_usage_error(name, c->json, "unexpected argument %s", arg);
            continue;
        }
        /* --name=value, --name value, or a flag */
        char opt[128];
        const char *eq = arg[1] == '-' ? strchr(arg, '=') : NULL, *value = NULL;
        snprintf(opt, sizeof opt, "%.*s", eq ? (int)(eq - arg) : (int)strlen(arg), arg);
        const mx_option_spec *s = mx_option_find(opt, verb);
        if (eq) value = eq + 1;
        else if (s && s->arg && i + 1 < argc && strncmp(argv[i + 1], "--", 2)) value = argv[++i]; /* never an option */
        mx_status st;
        if (mx_cli_texture_option(c, opt, value, &st)) return mx_cli_usage_error(name, c->json, "%s", st.msg);
    }
    if (c->o.fast && !c->steps_given) c->o.steps = 4;
    if (c->o.fast && !c->guidance_given) c->o.guidance = 1.0f;
    int rc = check_complete(c, name);
    return rc ? rc : -1;
}

typedef int (*api_fn)(matex_models *, const matex_options *, matex_result **, matex_error *);

/* Opens the weights (none for transfer), runs, closes; *res (owned by the caller) on success. */
static int run_once(api_fn fn, const mx_cli_texture *c, matex_result **res, matex_error *err) {
    matex_models *m = NULL;
    if (c->weights_path && !(m = matex_models_open(c->weights_path, &c->o, err))) return -1;
    int rc = fn(m, &c->o, res, err);
    matex_models_close(m);
    return rc;
}

/* The stream's final line. */
static void stream_result(const mx_cli_texture *c, int code, const char *error, const matex_result *r) {
    mx_texture_result res = {0};
    if (r) res.coverage = r->coverage, res.views = r->views, res.seconds = r->seconds;
    mx_cli_progress_result(stdout, code, error, r ? c->o.out_dir : NULL, r ? &res : NULL);
}

static void print_json_summary(const mx_cli_texture *c, const matex_result *r) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"ok\":true,\"out\":");
    mx_buf_json_str(&b, c->o.out_dir);
    mx_buf_printf(&b, ",\"coverage\":%.6f,\"views\":%d,\"seconds\":%.3f}", r->coverage, r->views, r->seconds);
    if (!b.oom) puts(b.p);
    mx_buf_free(&b);
}

/* A failed run's message on stderr (and stdout with json); the exit code: 2 usage, 130 interrupted, else 1. */
static int run_failed(const mx_cli_texture *c, const char *verb, int code, const char *message) {
    if (code == MATEX_EUSAGE) return mx_cli_usage_error(verb, c->json, "%s", message);
    fprintf(stderr, "matex %s: %s\n", verb, message);
    int exit_code = code == MATEX_ECANCELLED ? 130 : 1;
    if (c->json == MX_CLI_JSON_STREAM) stream_result(c, exit_code, message, NULL);
    else if (c->json) mx_cli_print_json_error(message);
    return exit_code;
}

int mx_cli_texture_run(mx_cli_texture *c, const char *verb, api_fn run) {
    if (c->json == MX_CLI_JSON_STREAM) { /* the events replace the human lines */
        c->quiet = 1;
        c->o.progress = mx_cli_progress_api_event;
        c->o.progress_user = stdout;
    }
    if (c->quiet) mx_log_set_level(MX_LOG_ERROR);
    c->o.verbose = !c->quiet;
    matex_error err = {0};
    mx_status st;
    if (mx_options_check(&c->o, c->verb, &st)) return mx_cli_usage_error(verb, c->json, "%s", st.msg);
    if (mx_style_check_inputs(&c->o, &st)) return run_failed(c, verb, st.code, st.msg); /* before the weights */
    c->o.cancel = mx_cli_signals_catch();
    if (c->json == MX_CLI_JSON_STREAM) mx_cli_signals_progress_json();
    mx_cli_signals_output(c->o.out_dir);
    matex_result *r = NULL;
    int rc = run_once(run, c, c->json ? &r : NULL, &err);
    mx_cli_signals_output(NULL);
    if (rc) return run_failed(c, verb, err.code, err.message);
    if (c->json == MX_CLI_JSON_STREAM) stream_result(c, 0, NULL, r);
    else if (c->json) print_json_summary(c, r);
    matex_result_free(r);
    return 0;
}
