/* Command-line options shared by `matex texture` and `matex enhance`. */
#ifndef MX_CLI_TEXTURE_OPTS_H
#define MX_CLI_TEXTURE_OPTS_H

#include <stdio.h>

#include "../pipeline/texture/texture.h"

typedef struct mx_cli_texture {
    mx_texture_opts o;
    int json; /* what goes to stdout: MX_CLI_JSON_NONE, _SUMMARY (--json) or _STREAM (--progress json;
                 tools/cli_progress.h) */
} mx_cli_texture;

/* Parses argv (argv[0] = verb). Positional: MESH then PROMPT (optional when
 * prompt_optional). Returns -1 to go on, else the exit code (0 after --help, 2 on a usage
 * error, message printed). */
int mx_cli_texture_parse(mx_cli_texture *c, int argc, char **argv, int prompt_optional,
                         void (*usage)(FILE *));
/* A usage error: "matex VERB: MESSAGE" and the --help hint on stderr, and on stdout with json
 * {"ok":false,"error":MESSAGE} (the stream's result line when json is MX_CLI_JSON_STREAM).
 * Returns 2 (the usage-error exit code). */
int mx_cli_usage_error(const char *verb, int json, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* The option list (printed by both verbs' --help). */
void mx_cli_texture_options_help(FILE *f);
/* Checks the options (mx_texture_opts_check), runs the verb's function with SIGINT/SIGTERM
 * setting its cancel flag, prints errors (also in the --json summary) and returns the exit
 * code: 0, 1 (bad input), 2 (usage), 130 (interrupted: nothing written). */
int mx_cli_texture_run(mx_cli_texture *c, const char *verb,
                       int (*run)(const mx_texture_opts *, mx_texture_result *, mx_status *));

#endif
