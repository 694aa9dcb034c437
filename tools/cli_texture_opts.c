#include "cli_texture_opts.h"

#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/geom/masks.h"
#include "../runtime/buf.h"
#include "../runtime/log.h"
#include "cli_args.h"
#include "cli_progress.h"
#include "cli_signals.h"

void mx_cli_texture_options_help(FILE *f) {
    fprintf(f,
            "  --weights FILE           matex weight file (matex convert); required\n"
            "  -o, --output DIR         output folder: texture.png/.exr, mesh.obj/.mtl, mesh.glb, report.json\n"
            "  --seed N                 noise seed (default 0); the same seed gives the same texture\n"
            "  --steps N                denoising steps (default 10; 4 with --fast)\n"
            "  --views N                view budget, front and back included (default 6)\n"
            "  --candidates N           candidate cameras on a Fibonacci sphere (default 40)\n"
            "  --texture-size N         texture side in texels (default 1024)\n"
            "  --render-size N          side of the renders that are backprojected (default 1024)\n"
            "  --image-size N           side of one generated image, multiple of 8 (default 512)\n"
            "  --batch N                most views generated in one batch (default 4)\n"
            "  --negative TEXT          negative prompt (default empty)\n"
            "  --guidance G             classifier-free guidance scale (default 7.5; 1 with --fast: none, batch not doubled)\n"
            "  --fast                   few-step path: LCM scheduler, TAESD encoder/decoder; needs a weight file\n"
            "                           made with convert --lcm-lora FILE --taesd DIR\n"
            "  --grid-depth-weight W    depth control weight of the front+back grid (default 1.0)\n"
            "  --depth-weight A[,B]     depth control weight of the first[,last] later view (default 1.0,0.7)\n"
            "  --inpaint-weight A[,B]   inpainting control weight of the first[,last] later view (default 0.8,1.0)\n"
            "  --frontal-threshold T    min |n.v| of a backprojected pixel (default 0.3)\n"
            "  --normals depth|geometric  normal used by the frontal mask (default depth, as the paper)\n"
            "  --coverage-stop C        stop adding views at this painted fraction (default 0.995)\n"
            "  --front-back-words TEXT  prompt prefix of the grid (default \"front and back view of\")\n"
            "  --up y|z                 up axis of the mesh (default y)\n"
            "  --threads N              CPU threads (default: all)\n"
            "  --precision fp32|bf16    arithmetic of the networks (default bf16 where the CPU has AVX512_BF16,\n"
            "                           else fp32): bf16 products with fp32 sums, about 2x faster\n"
            "  --device D               cpu (default), cpu-strict (activations guarded, for tests) or cuda\n"
            "                           (in binaries built by `make cuda`)\n"
            "  --force                  replace an earlier output of matex (atomically; never other files)\n"
            "  --quiet                  no progress on stderr\n"
            "  --json                   print a JSON summary on stdout\n"
            "  --progress text|json     text: progress lines on stderr (default); json: one JSON object per\n"
            "                           line on stdout per stage and step, then a result line (README)\n"
            "  -h, --help               this help\n");
}

static void print_json_error(const char *msg) {
    mx_buf b = {0};
    mx_buf_printf(&b, "{\"ok\":false,\"error\":");
    mx_buf_json_str(&b, msg);
    mx_buf_printf(&b, "}");
    puts(b.oom ? "{\"ok\":false,\"error\":\"out of memory\"}" : b.p);
    mx_buf_free(&b);
}

int mx_cli_usage_error(const char *verb, int json, const char *fmt, ...) {
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    fprintf(stderr, "matex %s: %s\n(matex %s --help for usage)\n", verb, msg, verb);
    if (json == MX_CLI_JSON_STREAM) mx_cli_progress_result(stdout, 2, msg, NULL, NULL);
    else if (json) print_json_error(msg);
    return 2;
}

static int usage_error(const mx_cli_texture *c, const char *verb, const char *msg, const char *arg) {
    return mx_cli_usage_error(verb, c->json, "%s%s%s", msg, arg ? " " : "", arg ? arg : "");
}

static int parse_int(const char *s, int *out) { return mx_parse_int(s, -2147483647L, 2147483647L, out); }

/* "A" or "A,B" into w[2] (B = A when absent). */
static int parse_pair(const char *s, float w[2]) {
    char buf[64];
    snprintf(buf, sizeof buf, "%s", s);
    char *comma = strchr(buf, ',');
    if (comma) *comma = 0;
    if (mx_parse_float(buf, &w[0])) return -1;
    if (!comma) {
        w[1] = w[0];
        return 0;
    }
    return mx_parse_float(comma + 1, &w[1]);
}

/* Options that take a value; returns 1 if handled, -1 on a bad value, 0 if unknown. */
static int parse_valued(mx_texture_opts *o, const char *arg, const char *val) {
    if (!strcmp(arg, "--weights")) return o->weights_path = val, 1;
    if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) return o->out_dir = val, 1;
    if (!strcmp(arg, "--negative")) return o->negative_prompt = val, 1;
    if (!strcmp(arg, "--front-back-words")) return o->grid_word = val, 1;
    if (!strcmp(arg, "--seed")) return mx_parse_u64(val, &o->seed) ? -1 : 1;
    if (!strcmp(arg, "--steps")) return parse_int(val, &o->steps) ? -1 : 1;
    if (!strcmp(arg, "--views")) return parse_int(val, &o->views) ? -1 : 1;
    if (!strcmp(arg, "--candidates")) return parse_int(val, &o->candidates) ? -1 : 1;
    if (!strcmp(arg, "--texture-size")) return parse_int(val, &o->tex_size) ? -1 : 1;
    if (!strcmp(arg, "--render-size")) return parse_int(val, &o->render_size) ? -1 : 1;
    if (!strcmp(arg, "--image-size")) return parse_int(val, &o->image_size) ? -1 : 1;
    if (!strcmp(arg, "--batch")) return parse_int(val, &o->max_batch) ? -1 : 1;
    if (!strcmp(arg, "--threads")) return parse_int(val, &o->threads) ? -1 : 1;
    if (!strcmp(arg, "--precision")) return mx_precision_parse(val, &o->precision) ? -1 : 1;
    if (!strcmp(arg, "--guidance")) return mx_parse_float(val, &o->guidance) ? -1 : 1;
    if (!strcmp(arg, "--strength")) return mx_parse_float(val, &o->strength) ? -1 : 1;
    if (!strcmp(arg, "--grid-depth-weight")) return mx_parse_float(val, &o->grid_depth_weight) ? -1 : 1;
    if (!strcmp(arg, "--depth-weight")) return parse_pair(val, o->depth_weight) ? -1 : 1;
    if (!strcmp(arg, "--inpaint-weight")) return parse_pair(val, o->inpaint_weight) ? -1 : 1;
    if (!strcmp(arg, "--frontal-threshold")) return mx_parse_float(val, &o->frontal_threshold) ? -1 : 1;
    if (!strcmp(arg, "--coverage-stop")) return mx_parse_float(val, &o->coverage_stop) ? -1 : 1;
    if (!strcmp(arg, "--normals")) {
        if (!strcmp(val, "depth")) return o->normal_source = MX_NORMAL_FROM_DEPTH, 1;
        if (!strcmp(val, "geometric")) return o->normal_source = MX_NORMAL_GEOMETRIC, 1;
        return -1;
    }
    if (!strcmp(arg, "--up")) {
        if (!strcmp(val, "y")) return o->up = MX_UP_Y, 1;
        if (!strcmp(val, "z")) return o->up = MX_UP_Z, 1;
        return -1;
    }
    if (!strcmp(arg, "--progress")) return mx_cli_progress_parse(val, &(int){0}) ? -1 : 1; /* mode: the pre-scan */
    if (!strcmp(arg, "--device")) return mx_backend_parse(val, &o->device, NULL) ? -1 : mx_backend_compiled(o->device) ? 1 : -2;
    return 0;
}

int mx_cli_texture_parse(mx_cli_texture *c, int argc, char **argv, int prompt_optional, void (*usage)(FILE *)) {
    const char *verb = argv[0];
    memset(c, 0, sizeof *c);
    mx_texture_opts_default(&c->o);
    c->json = mx_cli_progress_scan(argc, argv); /* usage errors in JSON too */
    int npos = 0, steps_given = 0, guidance_given = 0;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(arg, "--quiet")) {
            c->o.quiet = 1;
            continue;
        }
        if (!strcmp(arg, "--json")) continue; /* read by mx_cli_progress_scan */
        if (!strcmp(arg, "--fast")) {
            c->o.fast = 1;
            continue;
        }
        steps_given |= !strcmp(arg, "--steps");
        guidance_given |= !strcmp(arg, "--guidance");
        if (!strcmp(arg, "--force")) {
            c->o.force = 1;
            continue;
        }
        if (arg[0] == '-' && arg[1]) {
            if (i + 1 >= argc) return usage_error(c, verb, "missing value after", arg);
            int r = parse_valued(&c->o, arg, argv[++i]);
            if (r == 0) return usage_error(c, verb, "unknown option", arg);
            if (r == -2)
                return usage_error(c, verb, "this matex was built without that backend (`make cuda` builds one with"
                                            " cuda); --device", argv[i]);
            if (r < 0) return mx_cli_usage_error(verb, c->json, "bad value for %s: '%s'", arg, argv[i]);
            continue;
        }
        if (npos == 0)
            c->o.mesh_path = arg;
        else if (npos == 1)
            c->o.prompt = arg;
        else
            return usage_error(c, verb, "unexpected argument", arg);
        npos++;
    }
    if (c->o.fast && !steps_given) c->o.steps = 4;
    if (c->o.fast && !guidance_given) c->o.guidance = 1.0f;
    if (!c->o.mesh_path) return usage_error(c, verb, "missing MESH", NULL);
    if (!c->o.prompt) {
        if (!prompt_optional) return usage_error(c, verb, "missing PROMPT", NULL);
        c->o.prompt = "";
    }
    if (!c->o.weights_path) return usage_error(c, verb, "missing --weights FILE", NULL);
    if (!c->o.out_dir) return usage_error(c, verb, "missing -o OUT_DIR", NULL);
    return -1;
}


int mx_cli_texture_run(mx_cli_texture *c, const char *verb,
                       int (*run)(const mx_texture_opts *, mx_texture_result *, mx_status *)) {
    if (c->json == MX_CLI_JSON_STREAM) { /* the events replace the human lines */
        c->o.quiet = 1;
        c->o.progress = mx_cli_progress_event;
        c->o.progress_user = stdout;
    }
    if (c->o.quiet) mx_log_set_level(MX_LOG_ERROR);
    mx_status st;
    mx_status_clear(&st);
    mx_texture_result res;
    /* by the verb: run may be the pipeline's function or the API's (tools/cli_api.h) */
    mx_texture_mode mode = !strcmp(verb, "enhance")    ? MX_TEXTURE_MODE_ENHANCE
                           : !strcmp(verb, "transfer") ? MX_TEXTURE_MODE_TRANSFER
                                                       : MX_TEXTURE_MODE_TEXTURE;
    int rc = mx_texture_opts_check(&c->o, mode, &st);
    if (!rc) {
        c->o.cancel = mx_cli_signals_catch();
        rc = run(&c->o, &res, &st);
    }
    if (rc) {
        if (st.code == MX_EUSAGE) return mx_cli_usage_error(verb, c->json, "%s", st.msg);
        fprintf(stderr, "matex %s: %s\n", verb, st.msg);
        int code = st.code == MX_ECANCEL ? 130 : 1;
        if (c->json == MX_CLI_JSON_STREAM) mx_cli_progress_result(stdout, code, st.msg, NULL, NULL);
        else if (c->json) print_json_error(st.msg);
        return code;
    }
    if (c->json == MX_CLI_JSON_STREAM) mx_cli_progress_result(stdout, 0, NULL, c->o.out_dir, &res);
    else if (c->json) {
        mx_buf b = {0};
        mx_buf_printf(&b, "{\"ok\":true,\"out\":");
        mx_buf_json_str(&b, c->o.out_dir);
        mx_buf_printf(&b, ",\"coverage\":%.6f,\"views\":%d,\"seconds\":%.3f}", res.coverage, res.views, res.seconds);
        if (!b.oom) puts(b.p);
        mx_buf_free(&b);
    }
    return 0;
}
