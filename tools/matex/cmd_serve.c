/* matex serve --weights W [--listen ADDR:PORT] [--jobs DIR] [--token-file F] [limits]: the model
 * set loaded once, texturing jobs over HTTP (tools/matex/serve/, docs/SERVE.md). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cli.h"
#include "cli_args.h"
#include "serve/serve.h"

static void serve_usage(FILE *f) {
    fprintf(f, "usage: matex serve --weights W.mxw [options]\n\n"
               "Loads the model set once and textures meshes sent over HTTP (API: docs/SERVE.md): POST /v1/jobs\n"
               "(multipart: mesh, options, style_image), GET /v1/jobs[/ID[/events|/files/NAME]], DELETE /v1/jobs/ID,\n"
               "GET /v1/health, GET /v1/info. Jobs wait in a queue on disk and run one at a time; SIGINT/SIGTERM\n"
               "stops the server.\n\n"
               "options:\n"
               "  --listen ADDR:PORT        where to listen (default 127.0.0.1:8421; [::1]:PORT for IPv6; port 0: any,\n"
               "                            printed); an address that is not loopback needs --token-file\n"
               "  --jobs DIR                the jobs folder (default $XDG_CACHE_HOME/matex/serve-jobs, else\n"
               "                            ~/.cache/matex/serve-jobs); new or empty, or one made by matex serve\n"
               "  --token-file F            clients must send Authorization: Bearer TOKEN (F: one line, mode 0600)\n"
               "  --max-queued N            jobs waiting or running; more is a 429 (default 64)\n"
               "  --keep-jobs N             finished jobs kept, oldest removed first (default 100)\n"
               "  --keep-mb N               ... and at most N MiB of them (default 10240)\n"
               "  --max-upload-mb N         the largest request body (default 256)\n"
               "  --max-connections N       connections at once (default 64)\n"
               "  --max-per-client N        connections at once from one address (default 16)\n"
               "  --client-timeout S        a client silent for S seconds is dropped (default 30)\n"
               "  --on-term requeue|finish  SIGTERM stops the running job and queues it again (default), or lets it finish\n"
               "  -h, --help                this help\n"
               "the model set's options, as matex texture --help describes them:");
    int n;
    const mx_option_spec *t = mx_options_table(&n);
    for (int i = 0; i < n; i++)
        if (t[i].scope == MX_SCOPE_MODELS && (t[i].verbs & MX_VERB_BATCH)) fprintf(f, " --%s", t[i].name);
    fprintf(f, "\na job's options (prompt, seed, steps, ...) are the keys of its request's options part.\n");
}

static int usage_error(const char *msg, const char *arg) {
    fprintf(stderr, "matex serve: %s%s%s\n(matex serve --help for usage)\n", msg, arg ? " " : "", arg ? arg : "");
    return 2;
}

/* ADDR:PORT or [ADDR6]:PORT; 0 or -1. */
static int parse_listen(const char *s, mx_serve_config *c) {
    const char *colon = s[0] == '[' ? strstr(s, "]:") : strrchr(s, ':');
    if (!colon) return -1;
    size_t n = (size_t)(colon - s) - (s[0] == '[');
    if (n == 0 || n >= sizeof c->listen_addr) return -1;
    memcpy(c->listen_addr, s + (s[0] == '['), n);
    c->listen_addr[n] = 0;
    return mx_parse_int(colon + 1 + (s[0] == '['), 0, 65535, &c->port) ? -1 : 0;
}

static void default_jobs_dir(char *out, size_t cap) {
    const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    if (xdg && xdg[0] == '/') snprintf(out, cap, "%s/matex/serve-jobs", xdg);
    else snprintf(out, cap, "%s/.cache/matex/serve-jobs", home && home[0] ? home : "/tmp");
}

/* A limit flag: its value into c; 1 when `arg` is none of them, else 0 or 2. */
static int limit_option(mx_serve_config *c, const char *arg, const char *val) {
    int v, rc;
    static const struct { const char *name; long lo, hi; } limits[] = {
        {"--max-queued", 1, 100000}, {"--keep-jobs", 1, 1000000}, {"--keep-mb", 1, 1L << 30}, {"--max-upload-mb", 1, 65536},
        {"--max-connections", 2, 10000}, {"--max-per-client", 1, 10000}, {"--client-timeout", 1, 3600}};
    for (size_t i = 0; i < sizeof limits / sizeof limits[0]; i++) {
        if (strcmp(arg, limits[i].name)) continue;
        if (!val) return usage_error("missing value after", arg);
        if ((rc = mx_arg_int("serve", arg, val, limits[i].lo, limits[i].hi, &v))) return rc;
        switch (i) {
        case 0: c->limits.max_queued = v; break;
        case 1: c->limits.keep_jobs = v; break;
        case 2: c->limits.keep_bytes = (uint64_t)v << 20; break;
        case 3: c->max_upload = (uint64_t)v << 20; break;
        case 4: c->max_connections = v; break;
        case 5: c->max_per_client = v; break;
        default: c->client_timeout = v; break;
        }
        return 0;
    }
    return 1;
}

/* A model-set option of the table (--device, --threads, --precision): 0 or 2; *used: its value was the next argument. */
static int models_option(mx_serve_config *c, const char *arg, const char *val, int *used) {
    char opt[128];
    const char *eq = arg[1] == '-' ? strchr(arg, '=') : NULL;
    snprintf(opt, sizeof opt, "%.*s", eq ? (int)(eq - arg) : (int)strlen(arg), arg);
    const mx_option_spec *s = mx_option_find(opt, MX_VERB_BATCH);
    if (!s || s->scope != MX_SCOPE_MODELS) return usage_error("unknown option (a job's options go in each request)", arg);
    const char *value = eq ? eq + 1 : s->arg ? val : NULL;
    *used = !eq && s->arg && val;
    mx_status st;
    return mx_cli_texture_option(&c->models, opt, value, &st) ? usage_error(st.msg, NULL) : 0;
}

static int parse_args(mx_serve_config *c, char *jobs_default, size_t cap, int argc, char **argv) {
    memset(c, 0, sizeof *c);
    matex_options_default(&c->models.o);
    c->models.verb = MX_VERB_BATCH;
    snprintf(c->listen_addr, sizeof c->listen_addr, "127.0.0.1");
    c->port = 8421;
    c->limits = (mx_serve_limits){64, 100, (uint64_t)10240 << 20};
    c->max_upload = (uint64_t)256 << 20;
    c->max_connections = 64, c->max_per_client = 16, c->client_timeout = 30;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i], *val = i + 1 < argc ? argv[i + 1] : NULL;
        int rc, used = 0;
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return serve_usage(stdout), 0;
        if ((rc = limit_option(c, arg, val)) != 1) {
            if (rc) return rc;
        } else if (!strcmp(arg, "--weights") || !strcmp(arg, "--listen") || !strcmp(arg, "--jobs") ||
                   !strcmp(arg, "--token-file") || !strcmp(arg, "--on-term")) {
            if (!val) return usage_error("missing value after", arg);
            if (!strcmp(arg, "--weights")) c->weights = val;
            else if (!strcmp(arg, "--jobs")) c->jobs_dir = val;
            else if (!strcmp(arg, "--token-file")) c->token_file = val;
            else if (!strcmp(arg, "--listen") && parse_listen(val, c)) return usage_error("--listen wants ADDR:PORT (127.0.0.1:8421, [::1]:8421), not", val);
            else if (!strcmp(arg, "--on-term") && strcmp(val, "requeue") && strcmp(val, "finish"))
                return usage_error("--on-term wants requeue or finish, not", val);
            c->finish_on_term |= !strcmp(arg, "--on-term") && !strcmp(val, "finish");
        } else if (arg[0] == '-' && arg[1]) {
            if ((rc = models_option(c, arg, val, &used))) return rc;
            i += used;
            continue;
        } else {
            return usage_error("unexpected argument", arg);
        }
        i++;
    }
    if (!c->weights) return usage_error("missing --weights FILE", NULL);
    if (!c->jobs_dir) default_jobs_dir(jobs_default, cap), c->jobs_dir = jobs_default;
    return -1;
}

int cmd_serve(int argc, char **argv) {
    mx_serve_config c;
    char jobs[4096];
    int rc = parse_args(&c, jobs, sizeof jobs, argc, argv);
    return rc >= 0 ? rc : mx_serve_run(&c);
}
