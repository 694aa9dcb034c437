/* matex: text-to-texture for 3D meshes. Dispatches to the verbs of tools/matex/cli.h. */
#include <stdio.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../../runtime/version.h"
#include "cli.h"
#include "cli_signals.h"

typedef struct {
    const char *name;
    int (*fn)(int, char **);
    const char *help;
} verb;

#define MX_VERB_ENTRY(name, help) {#name, cmd_##name, help},
static const verb verbs[] = {MX_CLI_VERBS(MX_VERB_ENTRY)};
#undef MX_VERB_ENTRY

static void usage(FILE *f) {
    fprintf(f, "usage: matex VERB [options]   (matex VERB --help for each verb)\n"
               "       matex --version           version, build options, CPU kernels, backends\n\nverbs:\n");
    for (size_t i = 0; i < sizeof verbs / sizeof verbs[0]; i++) {
        char name[32];
        snprintf(name, sizeof name, "%s", verbs[i].name);
        for (char *p = name; *p; p++)
            if (*p == '_') *p = '-';
        fprintf(f, "  %-12s %s\n", name, verbs[i].help);
    }
}

int main(int argc, char **argv) {
    mx_cli_signals_block(); /* first: see cli_signals.h */
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(argv[1], "--version") || !strcmp(argv[1], "-V")) {
        mx_build_report(stdout);
        return 0;
    }
    char want[64];
    snprintf(want, sizeof want, "%s", argv[1]);
    for (char *p = want; *p; p++)
        if (*p == '-') *p = '_';
    if (!mx_cli_signals_verb_catches(want)) mx_cli_signals_default();
    for (size_t i = 0; i < sizeof verbs / sizeof verbs[0]; i++)
        if (!strcmp(verbs[i].name, want)) return verbs[i].fn(argc - 1, argv + 1);
    fprintf(stderr, "matex: unknown verb '%s'\n", argv[1]);
    usage(stderr);
    return 2;
}
