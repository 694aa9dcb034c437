/* The command-line parser of `matex texture` / `enhance` / `transfer` (tools/matex/cli_texture_opts.c,
 * driven by the option table) and the option check that follows it (mx_options_check): the input
 * is argv, NUL-separated, after the verb; the first byte picks the verb (mod 3). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../tools/matex/cli_texture_opts.h"
#include "fuzz.h"

#define FUZZ_MAX_ARGS 64

static void no_usage(FILE *f) { (void)f; }

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (!size) return 0;
    char *text = malloc(size); /* data[1..size) plus a closing NUL */
    if (!text) return 0;
    memcpy(text, data + 1, size - 1);
    text[size - 1] = 0;
    char *argv[FUZZ_MAX_ARGS + 2] = {"texture"};
    int argc = 1;
    for (char *p = text; p < text + size && argc <= FUZZ_MAX_ARGS; p += strlen(p) + 1) argv[argc++] = p;
    argv[argc] = NULL;
    static const unsigned verbs[3] = {MX_VERB_TEXTURE, MX_VERB_ENHANCE, MX_VERB_TRANSFER};
    unsigned verb = verbs[data[0] % 3];
    mx_cli_texture c;
    int rc = mx_cli_texture_parse(&c, argc, argv, verb, no_usage);
    int complete = c.o.mesh_path && c.o.out_dir &&
                   (verb == MX_VERB_TRANSFER ? c.o.source_path != NULL : c.o.prompt && c.weights_path);
    if (rc == -1 && !complete) abort();
    mx_status st;
    if (rc == -1) mx_options_check(&c.o, verb, &st);
    free(text);
    return 0;
}
