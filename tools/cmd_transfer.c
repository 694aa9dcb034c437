/* matex transfer SRC_TEXTURED DST_MESH -o OUT_DIR [options]: moves the texture of a textured
 * mesh onto another mesh or UV layout (pipeline/texture/transfer.c). */
#include <stdio.h>
#include <string.h>

#include "../pipeline/geom/masks.h"
#include "cli.h"
#include "cli_args.h"
#include "cli_progress.h"
#include "cli_texture_opts.h"

static void usage(FILE *f) {
    fprintf(f, "usage: matex transfer SRC_TEXTURED DST_MESH -o OUT_DIR [options]\n\n"
               "Renders the source's texture from the views `matex texture` would choose on the destination\n"
               "(front, back, then automatic view selection), backprojects the renders onto the destination's\n"
               "UVs (an atlas is made if it has none), fills the texels no view reached, and writes OUT_DIR like\n"
               "`matex texture`. No networks run. Both meshes must share pose and units. With SRC = DST the\n"
               "report gives the PSNR of the transferred texels against the source texture.\n\n"
               "options:\n"
               "  -o, --output DIR         output folder (required)\n"
               "  --views N                views, front and back included (default 6)\n"
               "  --candidates N           candidate cameras on a Fibonacci sphere (default 40)\n"
               "  --size S                 texture side and render side, 16..8192 (default 1024)\n"
               "  --frontal-threshold T    min |n.v| of a backprojected pixel (default 0.3)\n"
               "  --normals depth|geometric  normal used by the frontal mask (default depth)\n"
               "  --write angle-aware|first-wins  a later view that sees a texel with |n.v| higher by 0.15\n"
               "                           restarts it (default), or the first writer keeps it\n"
               "  --image-size M           send each render through the texture job's model image (crop to\n"
               "                           the object, M x M, back): its resampling at the silhouettes\n"
               "  --background R,G,B       colour behind the source in its renders (default 0,0,0)\n"
               "  --up y|z                 up axis of the meshes (default y)\n"
               "  --threads N              CPU threads (default: all)\n"
               "  --force                  replace an earlier output of matex (atomically; never other files)\n"
               "  --quiet                  no progress on stderr\n"
               "  --json                   print a JSON summary on stdout\n"
               "  --progress text|json     progress lines on stderr (default), or JSON lines on stdout (README)\n"
               "  -h, --help               this help\n");
}

static int parse_int(const char *s, int *out) { return mx_parse_int(s, -2147483647L, 2147483647L, out); }

/* Options with a value: 1 handled, 0 unknown, -1 bad value. Ranges are checked after parsing
 * (mx_texture_opts_check), except --size, which sets two sizes. */
static int parse_valued(mx_texture_opts *o, const char *arg, const char *val) {
    if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) return o->out_dir = val, 1;
    if (!strcmp(arg, "--views")) return parse_int(val, &o->views) ? -1 : 1;
    if (!strcmp(arg, "--candidates")) return parse_int(val, &o->candidates) ? -1 : 1;
    if (!strcmp(arg, "--threads")) return parse_int(val, &o->threads) ? -1 : 1;
    if (!strcmp(arg, "--frontal-threshold")) return mx_parse_float(val, &o->frontal_threshold) ? -1 : 1;
    if (!strcmp(arg, "--size")) {
        if (mx_parse_int(val, 16, 8192, &o->tex_size)) return -1;
        o->render_size = o->tex_size;
        return 1;
    }
    if (!strcmp(arg, "--normals")) {
        if (!strcmp(val, "depth")) return o->normal_source = MX_NORMAL_FROM_DEPTH, 1;
        if (!strcmp(val, "geometric")) return o->normal_source = MX_NORMAL_GEOMETRIC, 1;
        return -1;
    }
    if (!strcmp(arg, "--image-size")) return o->through_model_image = 1, parse_int(val, &o->image_size) ? -1 : 1;
    if (!strcmp(arg, "--background")) {
        float *b = o->background;
        return sscanf(val, "%f,%f,%f", &b[0], &b[1], &b[2]) == 3 && b[0] >= 0 && b[0] <= 1 && b[1] >= 0 && b[1] <= 1 &&
                       b[2] >= 0 && b[2] <= 1
                   ? 1
                   : -1;
    }
    if (!strcmp(arg, "--write")) {
        if (!strcmp(val, "angle-aware")) return o->first_wins = 0, 1;
        if (!strcmp(val, "first-wins")) return o->first_wins = 1, 1;
        return -1;
    }
    if (!strcmp(arg, "--progress")) return mx_cli_progress_parse(val, &(int){0}) ? -1 : 1; /* mode: the pre-scan */
    if (!strcmp(arg, "--up")) {
        if (!strcmp(val, "y")) return o->up = MX_UP_Y, 1;
        if (!strcmp(val, "z")) return o->up = MX_UP_Z, 1;
        return -1;
    }
    return 0;
}

/* -1 to go on, else the exit code. */
static int parse(mx_cli_texture *c, int argc, char **argv) {
    memset(c, 0, sizeof *c);
    mx_texture_opts_default(&c->o);
    c->json = mx_cli_progress_scan(argc, argv); /* usage errors in JSON too */
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return usage(stdout), 0;
        if (!strcmp(arg, "--quiet")) c->o.quiet = 1;
        else if (!strcmp(arg, "--json")) continue; /* read by mx_cli_progress_scan */
        else if (!strcmp(arg, "--force")) c->o.force = 1;
        else if (arg[0] == '-' && arg[1]) {
            if (i + 1 >= argc) return mx_cli_usage_error("transfer", c->json, "missing value after %s", arg);
            int r = parse_valued(&c->o, arg, argv[++i]);
            if (r == 0) return mx_cli_usage_error("transfer", c->json, "unknown option %s", arg);
            if (r < 0) return mx_cli_usage_error("transfer", c->json, "bad value for %s: '%s'", arg, argv[i]);
        } else if (!c->o.source_path) c->o.source_path = arg;
        else if (!c->o.mesh_path) c->o.mesh_path = arg;
        else return mx_cli_usage_error("transfer", c->json, "unexpected argument %s", arg);
    }
    if (!c->o.source_path || !c->o.mesh_path)
        return mx_cli_usage_error("transfer", c->json, "needs SRC_TEXTURED and DST_MESH");
    if (!c->o.out_dir) return mx_cli_usage_error("transfer", c->json, "missing -o OUT_DIR");
    return -1;
}

int cmd_transfer(int argc, char **argv) {
    mx_cli_texture c;
    int rc = parse(&c, argc, argv);
    if (rc >= 0) return rc;
    return mx_cli_texture_run(&c, "transfer", mx_transfer_run);
}
