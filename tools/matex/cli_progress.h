/* The machine-readable progress stream of `matex texture`, `enhance` and `transfer`
 * (`--progress json`, README "Progress stream"): one JSON object per line on stdout, flushed
 * at once, for every stage line and every denoising step, then one final "result" line. It is
 * the interface integrations (the Blender add-on in blender/, any other front end) read, so
 * its keys only ever grow. `--progress text` (the default) keeps the human lines on stderr. */
#ifndef MX_CLI_PROGRESS_H
#define MX_CLI_PROGRESS_H

#include <stdio.h>

#include "../../pipeline/texture/texture.h"
#include "../../runtime/buf.h"

/* What a verb prints on stdout: nothing, the one-line --json summary, or the stream. */
enum { MX_CLI_JSON_NONE = 0, MX_CLI_JSON_SUMMARY = 1, MX_CLI_JSON_STREAM = 2 };

/* Pre-scan of argv (before parsing, so that usage errors come out in the chosen form too):
 * MX_CLI_JSON_STREAM with `--progress json`, else MX_CLI_JSON_SUMMARY with --json, else NONE. */
int mx_cli_progress_scan(int argc, char **argv);
/* The value of --progress: "text" -> 0, "json" -> 1 into *json; -1 for anything else. */
int mx_cli_progress_parse(const char *val, int *json);
/* A progress callback (mx_texture_progress_fn): user is the FILE * the stream goes to.
 * Never cancels (returns 0). */
int mx_cli_progress_event(void *user, const mx_texture_progress *p);
/* The same for the public API's events (matex_options.progress; user: the FILE *). */
int mx_cli_progress_api_event(void *user, const matex_progress *p);
/* The final line. exit_code 0: ok with out and res; else error (the one-line message). */
void mx_cli_progress_result(FILE *f, int exit_code, const char *error, const char *out, const mx_texture_result *res);
/* The same line, without its newline, appended to b (cli_signals.c writes it from its handler). */
void mx_cli_progress_result_line(mx_buf *b, int exit_code, const char *error, const char *out,
                                 const mx_texture_result *res);

#endif
