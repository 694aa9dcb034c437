/* bench_startup: what a short `matex` call costs before it does anything (issue 42: OpenImageIO,
 * once linked in, cost every call 0.5 s of CPU and 134 MB): `matex --version` and an option
 * error (`texture --image-size 7`, exit 2), each run REPS times as a child process; prints the
 * median wall and CPU seconds (user + sys, wait4) and the largest peak RSS, against the goal
 * (≤ 0.05 s of CPU, ≤ 10 MB). Usage: bench_startup [REPS] (default 20); the program is $MATEX
 * (bench.sh sets it to BUILD/matex), else build/matex. Exits 1 when a run does not end as expected. */
#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#define MAX_REPS 200
#define GOAL_CPU_S 0.05
#define GOAL_RSS_MB 10.0

typedef struct startup_case {
    const char *label;
    const char *args[8]; /* after the program, NULL-terminated */
    int want_exit;
} startup_case;

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* One run, its output to /dev/null: wall and CPU seconds, peak RSS in MB. -1 when it did not exit
 * with want_exit. */
static int run_once(const char *matex, const startup_case *c, double *wall, double *cpu, double *rss_mb) {
    const char *argv[10] = {matex};
    for (int i = 0; c->args[i]; i++) argv[i + 1] = c->args[i];
    fflush(stdout); /* or the child's freopen writes the parent's buffered lines again */
    double t0 = now_s();
    pid_t pid = fork();
    if (pid == 0) {
        if (!freopen("/dev/null", "w", stdout) || !freopen("/dev/null", "w", stderr)) _exit(126);
        execv(matex, (char *const *)argv);
        _exit(127);
    }
    int status = 0;
    struct rusage ru;
    if (pid < 0 || wait4(pid, &status, 0, &ru) != pid) return -1;
    *wall = now_s() - t0;
    *cpu = ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
    *rss_mb = ru.ru_maxrss / 1024.0;
    return WIFEXITED(status) && WEXITSTATUS(status) == c->want_exit ? 0 : -1;
}

static int bench_case(const char *matex, const startup_case *c, int reps) {
    double wall[MAX_REPS], cpu[MAX_REPS], rss = 0;
    for (int r = 0; r < reps; r++) {
        double peak;
        if (run_once(matex, c, &wall[r], &cpu[r], &peak)) {
            printf("bench-startup: %s: %s did not exit %d\n", c->label, matex, c->want_exit);
            return -1;
        }
        if (peak > rss) rss = peak;
    }
    qsort(wall, reps, sizeof *wall, cmp_double);
    qsort(cpu, reps, sizeof *cpu, cmp_double);
    double cpu_med = cpu[reps / 2];
    printf("bench-startup: %-14s wall_s=%.3f cpu_s=%.3f peak_rss_mb=%.1f (median of %d; goal cpu_s <= %.2f, "
           "rss <= %.0f MB: %s)\n",
           c->label, wall[reps / 2], cpu_med, rss, reps, GOAL_CPU_S, GOAL_RSS_MB,
           cpu_med <= GOAL_CPU_S && rss <= GOAL_RSS_MB ? "met" : "NOT met");
    return 0;
}

int main(int argc, char **argv) {
    int reps = argc > 1 ? atoi(argv[1]) : 20;
    if (reps < 1 || reps > MAX_REPS) {
        fprintf(stderr, "bench_startup: REPS must be 1 to %d\n", MAX_REPS);
        return 2;
    }
    const char *matex = getenv("MATEX") ? getenv("MATEX") : "build/matex";
    static const startup_case cases[] = {
        {"--version", {"--version", NULL}, 0},
        {"option error", {"texture", "tests/data/box.obj", "a box", "--image-size", "7", NULL}, 2},
    };
    int rc = 0;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) rc |= bench_case(matex, &cases[i], reps);
    return rc ? 1 : 0;
}
