/* matex transfer SRC_TEXTURED DST_MESH -o OUT_DIR [options]: moves the texture of a textured
 * mesh onto another mesh or UV layout (matex_transfer, pipeline/texture/transfer.c). */
#include <stdio.h>

#include "cli.h"
#include "cli_texture_opts.h"

static void usage(FILE *f) {
    fprintf(f, "usage: matex transfer SRC_TEXTURED DST_MESH -o OUT_DIR [options]\n\n"
               "Renders the source's texture from the views `matex texture` would choose on the destination\n"
               "(front, back, then automatic view selection), backprojects the renders onto the destination's\n"
               "UVs (an atlas is made if it has none), fills the texels no view reached, and writes OUT_DIR like\n"
               "`matex texture`. No networks run. Both meshes must share pose and units. With SRC = DST the\n"
               "report gives the PSNR of the transferred texels against the source texture.\n\n"
               "options:\n");
    mx_options_help(f, MX_VERB_TRANSFER);
}

int cmd_transfer(int argc, char **argv) {
    mx_cli_texture c;
    int rc = mx_cli_texture_parse(&c, argc, argv, MX_VERB_TRANSFER, usage);
    if (rc >= 0) return rc;
    return mx_cli_texture_run(&c, "transfer", matex_transfer);
}
