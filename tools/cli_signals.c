#include "cli_signals.h"

#include <string.h>
#include <unistd.h>

/* Set by SIGINT/SIGTERM; a run checks it between stages and denoising steps. A signal handler
 * can only reach a flag with static storage. */
static volatile sig_atomic_t interrupted;

static void on_signal(int sig) {
    (void)sig;
    static const char note[] = "matex: interrupted, stopping after the current step\n";
    if (!interrupted) {
        ssize_t n = write(STDERR_FILENO, note, sizeof note - 1); /* async-signal-safe, unlike stdio */
        (void)n;                                                  /* nothing to do if stderr is gone */
    }
    interrupted = 1;
}

static void set_mask(int how) {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    sigprocmask(how, &set, NULL);
}

void mx_cli_signals_block(void) { set_mask(SIG_BLOCK); }

void mx_cli_signals_default(void) { set_mask(SIG_UNBLOCK); }

volatile sig_atomic_t *mx_cli_signals_catch(void) {
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sa.sa_flags = SA_RESTART;
    sigemptyset(&sa.sa_mask);
    interrupted = 0;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    set_mask(SIG_UNBLOCK);
    return &interrupted;
}

int mx_cli_signals_verb_catches(const char *verb) {
    static const char *const verbs[] = {"texture", "enhance", "transfer", "batch", "render"};
    for (size_t i = 0; i < sizeof verbs / sizeof verbs[0]; i++)
        if (!strcmp(verb, verbs[i])) return 1;
    return 0;
}
