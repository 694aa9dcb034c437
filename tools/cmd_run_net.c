/* PLACEHOLDER: replaced by the real verb; must not survive to a submission. */
#include <stdio.h>

#include "cli.h"

int cmd_run_net(int argc, char **argv) {
    (void)argc;
    (void)argv;
    fprintf(stderr, "matex: 'run_net' is not built yet\n");
    return 2;
}
