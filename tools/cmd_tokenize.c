/* PLACEHOLDER: replaced by the real verb; must not survive to a submission. */
#include <stdio.h>

#include "cli.h"

int cmd_tokenize(int argc, char **argv) {
    (void)argc;
    (void)argv;
    fprintf(stderr, "matex: 'tokenize' is not built yet\n");
    return 2;
}
