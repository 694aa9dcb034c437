#include "cli_signals.h"

#include <fcntl.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "../../pipeline/texture/outdir.h"
#include "cli_progress.h"

/* What a second signal says: on stderr, and as the result line's error with --progress json. */
#define SECOND_SIGNAL "interrupted again, stopped now; nothing written"

/* Set by SIGINT/SIGTERM; a run checks it between stages and denoising steps. A signal handler
 * can only reach a flag and the paths below with static storage. */
static volatile sig_atomic_t interrupted;
/* --progress json: the result line a second signal writes on stdout, newline included ("" without
 * the stream: then the first signal says it stops on stderr; with it the run's own result line
 * and its one error line report the first). */
static char stream_result[512];
/* What a second signal removes before ending the process: the run's staging folder (files only)
 * and its output folder's lock; "" when there is none. */
static char stage_path[4200], lock_path[4200];

/* rm of a folder of files with system calls only (async-signal-safe: no malloc, no stdio). */
static void remove_flat_folder(const char *dir) {
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return;
    static char buf[8192];
    long n;
    while ((n = syscall(SYS_getdents64, fd, buf, sizeof buf)) > 0)
        for (long at = 0; at < n;) {
            /* struct linux_dirent64: d_ino (8), d_off (8), d_reclen (2), d_type (1), d_name */
            unsigned short reclen;
            memcpy(&reclen, buf + at + 16, sizeof reclen);
            const char *name = buf + at + 19;
            if (strcmp(name, ".") && strcmp(name, "..")) unlinkat(fd, name, 0);
            at += reclen;
        }
    close(fd);
    rmdir(dir);
}

static void say(int fd, const char *s) {
    ssize_t n = write(fd, s, strlen(s)); /* async-signal-safe, unlike stdio */
    (void)n;                             /* nothing to do if the stream is gone */
}

/* The first signal asks the run to stop after its current step (it then removes its staging
 * folder itself); a second one ends the process now, after removing what the run had staged. */
static void on_signal(int sig) {
    (void)sig;
    if (!interrupted) {
        interrupted = 1;
        if (!stream_result[0]) say(STDERR_FILENO, "matex: interrupted, stopping after the current step (interrupt again to stop now)\n");
        return;
    }
    if (stage_path[0]) remove_flat_folder(stage_path);
    if (lock_path[0]) unlink(lock_path);
    say(STDERR_FILENO, "matex: " SECOND_SIGNAL "\n");
    say(STDOUT_FILENO, stream_result); /* after whole events: each is flushed as one write, and a line
                                          still in stdio's buffer is dropped by _exit, not cut */
    _exit(130);
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
    stream_result[0] = 0;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    set_mask(SIG_UNBLOCK);
    return &interrupted;
}

void mx_cli_signals_progress_json(void) {
    mx_buf b = {0};
    mx_cli_progress_result_line(&b, 130, SECOND_SIGNAL, NULL, NULL);
    mx_buf_printf(&b, "\n");
    int ok = !b.oom && b.len < sizeof stream_result;
    set_mask(SIG_BLOCK); /* the handler never sees a half-copied line */
    memcpy(stream_result, ok ? b.p : "", ok ? b.len + 1 : 1);
    set_mask(SIG_UNBLOCK);
    mx_buf_free(&b);
}

void mx_cli_signals_output(const char *out_dir) {
    char stage[sizeof stage_path], lock[sizeof lock_path];
    int ok = out_dir && !mx_outdir_names(out_dir, stage, lock);
    set_mask(SIG_BLOCK); /* the handler never sees a half-copied path */
    memcpy(stage_path, ok ? stage : "", ok ? sizeof stage : 1);
    memcpy(lock_path, ok ? lock : "", ok ? sizeof lock : 1);
    set_mask(SIG_UNBLOCK);
}

int mx_cli_signals_verb_catches(const char *verb) {
    static const char *const verbs[] = {"texture", "enhance", "transfer", "batch", "render", "serve"};
    for (size_t i = 0; i < sizeof verbs / sizeof verbs[0]; i++)
        if (!strcmp(verb, verbs[i])) return 1;
    return 0;
}
