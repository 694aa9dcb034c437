/* The command-line parser of `matex texture` / `matex enhance` (tools/cli_texture_opts.c)
 * and the option check that follows it (mx_texture_opts_check): the input is argv,
 * NUL-separated, after the verb; the first byte picks the verb (bit 0: enhance, prompt optional)
 * and the check's mode. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../tools/cli_texture_opts.h"
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
    mx_cli_texture c;
    int rc = mx_cli_texture_parse(&c, argc, argv, data[0] & 1, no_usage);
    if (rc == -1 && (!c.o.mesh_path || !c.o.prompt || !c.o.weights_path || !c.o.out_dir)) abort();
    mx_status st;
    if (rc == -1) mx_texture_opts_check(&c.o, (mx_texture_mode)(data[0] % 3), &st);
    free(text);
    return 0;
}
