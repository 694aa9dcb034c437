/* The public options (include/matex.h) as the pipeline's (texture.h). Pointers are borrowed. */
#ifndef MX_API_OPTS_H
#define MX_API_OPTS_H

#include "../../include/matex.h"
#include "texture.h"

/* Fails only on an unknown device name. */
int mx_api_options_to_internal(const matex_options *o, mx_texture_opts *t, mx_status *st);

#endif
