/* The public options (include/matex.h) and the pipeline's (texture.h), both ways: the CLI
 * parses into mx_texture_opts and runs through the public API. Pointers are borrowed. */
#ifndef MX_API_OPTS_H
#define MX_API_OPTS_H

#include "../../include/matex.h"
#include "texture.h"

/* Fails only on an unknown device name. */
int mx_api_options_to_internal(const matex_options *o, mx_texture_opts *t, mx_status *st);
void mx_api_options_from_internal(const mx_texture_opts *t, matex_options *o);

#endif
