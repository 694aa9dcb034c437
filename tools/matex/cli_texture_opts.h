/* The command line of `matex texture`, `matex enhance` and `matex transfer`, parsed by the option
 * table (pipeline/texture/options.h) into the public options, run through the embedding API. */
#ifndef MX_CLI_TEXTURE_OPTS_H
#define MX_CLI_TEXTURE_OPTS_H

#include <stdio.h>

#include "../../include/matex.h"
#include "../../pipeline/texture/options.h"

typedef struct mx_cli_texture {
    matex_options o;
    unsigned verb;            /* MX_VERB_TEXTURE, _ENHANCE or _TRANSFER */
    const char *weights_path; /* --weights (texture, enhance) */
    int json;                 /* stdout: MX_CLI_JSON_NONE, _SUMMARY (--json) or _STREAM (--progress json;
                                 tools/matex/cli_progress.h) */
    int quiet;
    int steps_given, guidance_given; /* --fast sets steps 4 and guidance 1 unless they are given */
} mx_cli_texture;

/* Parses argv (argv[0] = verb name) for `verb`. Positionals: MESH then PROMPT (texture; optional
 * for enhance), SRC_TEXTURED then DST_MESH (transfer). Returns -1 to go on, else the exit code
 * (0 after --help, 2 on a usage error, message printed). */
int mx_cli_texture_parse(mx_cli_texture *c, int argc, char **argv, unsigned verb, void (*usage)(FILE *));
/* One option and its value (NULL for a flag) into c, as the parser does: 0, or -1 with the
 * message in st (an unknown option, a flag given a value, a value out of range). `name` is
 * "--steps", "-o" or a manifest key ("steps"). */
int mx_cli_texture_option(mx_cli_texture *c, const char *name, const char *value, mx_status *st);
/* A usage error: "matex VERB: MESSAGE" and the --help hint on stderr, and on stdout with json
 * {"ok":false,"error":MESSAGE} (the stream's result line when json is MX_CLI_JSON_STREAM).
 * Returns 2 (the usage-error exit code). */
int mx_cli_usage_error(const char *verb, int json, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* {"ok":false,"error":MESSAGE} on stdout: a failed run's --json answer. */
void mx_cli_print_json_error(const char *msg);
/* Checks the options (mx_options_check), opens the weights (texture, enhance), runs the verb's API
 * call with SIGINT/SIGTERM setting its cancel flag, prints errors (also in the --json summary)
 * and returns the exit code: 0, 1 (bad input), 2 (usage), 130 (interrupted: nothing written). */
int mx_cli_texture_run(mx_cli_texture *c, const char *verb,
                       int (*run)(matex_models *, const matex_options *, matex_result **, matex_error *));

#endif
