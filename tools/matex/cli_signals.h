/* SIGINT/SIGTERM for matex. main blocks both as its very first statement, so a signal that
 * arrives during start-up (argument parsing, option checks) waits instead of ending the
 * process at a moment no one chose. A verb that can stop cleanly (texture, enhance, transfer,
 * batch, render) calls mx_cli_signals_catch: its handler is installed, the signals unblocked,
 * and one already pending sets the flag at once, so the run stops at its first check and
 * leaves no output; a second signal ends the process at once, removing what the run had staged
 * (mx_cli_signals_output). For every other verb main calls mx_cli_signals_default (the default
 * action: the process ends). */
#ifndef MX_CLI_SIGNALS_H
#define MX_CLI_SIGNALS_H

#include <signal.h>

void mx_cli_signals_block(void);
void mx_cli_signals_default(void);
/* Installs the handler (it sets the returned flag and says "interrupted" once on stderr),
 * clears the flag, then unblocks the signals. */
volatile sig_atomic_t *mx_cli_signals_catch(void);
/* After mx_cli_signals_catch, for --progress json: the first signal prints nothing (the stream
 * promises one line on stderr for a failed run: its error, and the run's result line reports it);
 * a second one writes the stream's result line on stdout, {"event":"result","ok":false,"exit":130,
 * "error":"interrupted again, ..."}, as well as its line on stderr, before the process ends. */
void mx_cli_signals_progress_json(void);
/* The output folder of the run the signals stop: a second SIGINT/SIGTERM removes its staging
 * folder and lock (pipeline/texture/outdir.h) and ends the process at once with 130 (NULL: none). */
void mx_cli_signals_output(const char *out_dir);
/* Whether a verb calls mx_cli_signals_catch itself (main unblocks for the others). */
int mx_cli_signals_verb_catches(const char *verb);

#endif
