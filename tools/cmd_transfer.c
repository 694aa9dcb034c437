/* matex transfer SRC_TEXTURED DST_MESH -o OUT_DIR [options]: moves the texture of a textured
 * mesh onto another mesh or UV layout (pipeline/texture/transfer.c). */
#include <stdio.h>
#include <string.h>

#include "../pipeline/geom/masks.h"
#include "cli.h"
#include "cli_args.h"
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
               "  --size S                 texture side and render side (default 1024)\n"
               "  --frontal-threshold T    min |n.v| of a backprojected pixel (default 0.3)\n"
               "  --normals depth|geometric  normal used by the frontal mask (default depth)\n"
               "  --up y|z                 up axis of the meshes (default y)\n"
               "  --threads N              CPU threads (default: all)\n"
               "  --force                  replace an existing non-empty output folder (atomically)\n"
               "  --quiet                  no progress on stderr\n"
               "  --json                   print a JSON summary on stdout\n"
               "  -h, --help               this help\n");
}

static int usage_error(const char *msg, const char *arg) {
    fprintf(stderr, "matex transfer: %s %s\n(matex transfer --help for usage)\n", msg, arg ? arg : "");
    return 2;
}

/* Options with a value; 0 handled, 2 bad value (printed), 1 unknown. */
static int parse_valued(mx_texture_opts *o, const char *arg, const char *val) {
    if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) return o->out_dir = val, 0;
    if (!strcmp(arg, "--views")) return mx_arg_int("transfer", arg, val, 2, 64, &o->views);
    if (!strcmp(arg, "--candidates")) return mx_arg_int("transfer", arg, val, 1, 4096, &o->candidates);
    if (!strcmp(arg, "--threads")) return mx_arg_int("transfer", arg, val, 0, 1024, &o->threads);
    if (!strcmp(arg, "--frontal-threshold")) return mx_arg_float("transfer", arg, val, &o->frontal_threshold);
    if (!strcmp(arg, "--size")) {
        int rc = mx_arg_int("transfer", arg, val, 16, 8192, &o->tex_size);
        o->render_size = o->tex_size;
        return rc;
    }
    if (!strcmp(arg, "--normals") && (!strcmp(val, "depth") || !strcmp(val, "geometric")))
        return o->normal_source = val[0] == 'd' ? MX_NORMAL_FROM_DEPTH : MX_NORMAL_GEOMETRIC, 0;
    if (!strcmp(arg, "--up") && (!strcmp(val, "y") || !strcmp(val, "z"))) return o->up = val[0] == 'z', 0;
    if (!strcmp(arg, "--normals") || !strcmp(arg, "--up")) return usage_error("bad value for", arg);
    return 1;
}

/* -1 to go on, else the exit code. */
static int parse(mx_cli_texture *c, int argc, char **argv) {
    memset(c, 0, sizeof *c);
    mx_texture_opts_default(&c->o);
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) return usage(stdout), 0;
        if (!strcmp(arg, "--quiet")) c->o.quiet = 1;
        else if (!strcmp(arg, "--json")) c->json = 1;
        else if (!strcmp(arg, "--force")) c->o.force = 1;
        else if (arg[0] == '-' && arg[1]) {
            if (i + 1 >= argc) return usage_error("missing value after", arg);
            int rc = parse_valued(&c->o, arg, argv[++i]);
            if (rc == 1) return usage_error("unknown option", arg);
            if (rc) return rc;
        } else if (!c->o.source_path) c->o.source_path = arg;
        else if (!c->o.mesh_path) c->o.mesh_path = arg;
        else return usage_error("unexpected argument", arg);
    }
    if (!c->o.source_path || !c->o.mesh_path) return usage_error("needs SRC_TEXTURED and DST_MESH", NULL);
    if (!c->o.out_dir) return usage_error("missing -o OUT_DIR", NULL);
    return -1;
}

int cmd_transfer(int argc, char **argv) {
    mx_cli_texture c;
    int rc = parse(&c, argc, argv);
    if (rc >= 0) return rc;
    return mx_cli_texture_run(&c, "transfer", mx_transfer_run);
}
