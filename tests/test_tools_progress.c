/* `--progress json` (tools/matex/cli_progress.c, README "Progress stream"), read as an integration
 * reads it: the matex binary ($MATEX, default build/matex) runs texture, enhance and transfer
 * with the demo weights; every stdout line must parse as one JSON object (runtime/json.h) with
 * every documented key of its kind; steps count 1..steps within a stage, seconds never go back,
 * coverage stays in [0, 1], and exactly one result line comes last, with the exit code the
 * process returned. A bad weight path and a usage error end in a result line too. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../runtime/json.h"
#include "util_test.h"

#define SMALL "--image-size 64 --steps 2 --texture-size 128 --render-size 128 --candidates 8 --views 4"

static const char *const EVENT_NUMBERS[] = {"step", "steps", "views_done", "views_total", "coverage", "seconds"};

typedef struct stream_stats {
    int lines, steps, stages, results;
    int result_exit; /* -1 when no result line */
    int result_ok;
    char result_error[512];
} stream_stats;

static int has_num(const mx_json *o, const char *k) { return mx_json_kind(mx_json_get(o, k)) == MX_JSON_NUM; }
static int has_str(const mx_json *o, const char *k) { return mx_json_kind(mx_json_get(o, k)) == MX_JSON_STR; }

/* One event line: its keys and the order rules against the line before (*last_seconds, *last_step). */
static void check_event(const mx_json *o, const char *kind, double *last_seconds, int *last_step, stream_stats *s) {
    for (size_t i = 0; i < sizeof EVENT_NUMBERS / sizeof EVENT_NUMBERS[0]; i++) CHECK(has_num(o, EVENT_NUMBERS[i]));
    CHECK(has_str(o, "stage") && has_str(o, "message"));
    double sec = mx_json_get_num(o, "seconds", -1), cov = mx_json_get_num(o, "coverage", -1);
    CHECK(sec >= *last_seconds);
    CHECK(cov >= 0 && cov <= 1);
    *last_seconds = sec;
    int step = (int)mx_json_get_num(o, "step", -1), steps = (int)mx_json_get_num(o, "steps", -1);
    if (!strcmp(kind, "step")) {
        s->steps++;
        CHECK(steps > 0 && step >= 1 && step <= steps);
        CHECK(step == 1 || step == *last_step + 1); /* no step lost between two lines */
        *last_step = step;
    } else {
        s->stages++;
        CHECK(step == 0 && steps == 0);
    }
}

static void check_result(const mx_json *o, stream_stats *s) {
    s->results++;
    s->result_ok = mx_json_get_bool(o, "ok", -1);
    s->result_exit = (int)mx_json_get_num(o, "exit", -1);
    CHECK(s->result_ok == (s->result_exit == 0));
    if (s->result_ok) {
        CHECK(has_str(o, "out") && has_num(o, "coverage") && has_num(o, "views") && has_num(o, "seconds"));
    } else {
        CHECK(has_str(o, "error") && mx_json_str_len(mx_json_get(o, "error")) > 0);
        snprintf(s->result_error, sizeof s->result_error, "%s", mx_json_get_str(o, "error", ""));
    }
}

/* Runs `MATEX ARGS --progress json`, checks every line; returns the process's exit code. */
static int run_stream(const char *args, stream_stats *s) {
    memset(s, 0, sizeof *s);
    s->result_exit = -1;
    const char *matex = getenv("MATEX") ? getenv("MATEX") : "build/matex";
    char cmd[4096], line[8192];
    snprintf(cmd, sizeof cmd, "%s %s --progress json 2>/dev/null", matex, args);
    FILE *p = popen(cmd, "r");
    if (!p) return -1;
    double last_seconds = 0;
    int last_step = 0;
    while (fgets(line, sizeof line, p)) {
        size_t n = strlen(line);
        CHECK(n > 0 && line[n - 1] == '\n'); /* whole lines only */
        s->lines++;
        CHECK(s->results == 0); /* nothing after the result line */
        mx_status st;
        mx_json *o = mx_json_parse(line, n, "progress line", &st);
        CHECK(o && mx_json_kind(o) == MX_JSON_OBJ);
        if (!o) {
            fprintf(stderr, "not JSON: %s(%s)\n", line, st.msg);
            continue;
        }
        const char *kind = mx_json_get_str(o, "event", "");
        if (!strcmp(kind, "result")) check_result(o, s);
        else if (!strcmp(kind, "step") || !strcmp(kind, "stage")) check_event(o, kind, &last_seconds, &last_step, s);
        else CHECK(!"an event of a known kind");
        mx_json_free(o);
    }
    int status = pclose(p);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

int main(void) {
    char mesh[1024], tmp[] = "/tmp/matex_progress.XXXXXX", args[4096];
    if (!mx_test_need(mesh, sizeof mesh, "assets/fedora_hat/fedora.obj")) return mx_test_finish("test_tools_progress");
    if (!mkdtemp(tmp)) return 1;
    const char *w = getenv("MATEX_DEMO_WEIGHTS") ? getenv("MATEX_DEMO_WEIGHTS") : "build/demo/demo.mxw";
    stream_stats s;

    snprintf(args, sizeof args, "texture %s \"a \\\"felt\\\" hat\" --weights %s -o %s/t " SMALL, mesh, w, tmp);
    CHECK(run_stream(args, &s) == 0);
    CHECK(s.results == 1 && s.result_ok == 1 && s.result_exit == 0);
    CHECK(s.steps >= 2 * 2); /* the grid and at least one later view, 2 steps each */
    CHECK(s.stages >= 3);
    printf("texture: %d lines, %d step and %d stage events\n", s.lines, s.steps, s.stages);

    snprintf(args, sizeof args, "enhance %s/t/mesh.obj \"a hat\" --strength 0.5 --weights %s -o %s/e " SMALL, tmp, w,
             tmp);
    CHECK(run_stream(args, &s) == 0);
    CHECK(s.results == 1 && s.result_ok == 1 && s.steps >= 1);
    printf("enhance: %d lines, %d step events\n", s.lines, s.steps);

    snprintf(args, sizeof args, "transfer %s/t/mesh.obj %s --size 128 --candidates 8 -o %s/x", tmp, mesh, tmp);
    CHECK(run_stream(args, &s) == 0);
    CHECK(s.results == 1 && s.result_ok == 1 && s.steps == 0 && s.stages >= 1);

    snprintf(args, sizeof args, "texture %s hat --weights %s/none.mxw -o %s/bad " SMALL, mesh, tmp, tmp);
    CHECK(run_stream(args, &s) == 1);
    CHECK(s.lines == 1 && s.results == 1 && s.result_exit == 1 && strstr(s.result_error, "none.mxw"));
    snprintf(args, sizeof args, "%s/bad", tmp);
    CHECK(access(args, F_OK) != 0); /* no output after a failure */

    snprintf(args, sizeof args, "texture %s hat --weights %s -o %s/u --steps 0", mesh, w, tmp);
    CHECK(run_stream(args, &s) == 2);
    CHECK(s.lines == 1 && s.result_exit == 2 && strstr(s.result_error, "--steps"));

    snprintf(args, sizeof args, "rm -rf %s", tmp);
    CHECK(system(args) == 0);
    return mx_test_finish("test_tools_progress");
}
