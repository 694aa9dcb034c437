/* PLACEHOLDER: replaced by the real verb; must not survive to a submission. */
#include <stdio.h>

#include "cli.h"

int cmd_convert(int argc, char **argv) {
    (void)argc;
    (void)argv;
    fprintf(stderr, "matex: 'convert' is not built yet\n");
    return 2;
}
