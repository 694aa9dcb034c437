/* The command line over the embedding API (include/matex.h): `matex texture`, `matex enhance`
 * and `matex batch` run through matex_models_open / matex_texture / matex_enhance. */
#ifndef MX_CLI_API_H
#define MX_CLI_API_H

#include "../include/matex.h"
#include "../pipeline/texture/texture.h"

/* Copies an API error into a status (the CLI's exit code follows st->code). */
void mx_cli_api_status(const matex_error *err, mx_status *st);

/* Run functions for mx_cli_texture_run: open t->weights_path, run, close. */
int mx_cli_api_texture(const mx_texture_opts *t, mx_texture_result *res, mx_status *st);
int mx_cli_api_enhance(const mx_texture_opts *t, mx_texture_result *res, mx_status *st);

#endif
