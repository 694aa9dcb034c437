/* matex enhance TEXTURED_MESH ["PROMPT"] --strength S --weights W -o OUT_DIR: SDEdit over views. */
#include <stdio.h>

#include "cli.h"
#include "cli_texture_opts.h"

static void enhance_usage(FILE *f) {
    fprintf(f, "usage: matex enhance TEXTURED_MESH [\"PROMPT\"] --weights W.mxw -o OUT_DIR [--strength S] [options]\n\n"
               "Enhances the texture of a textured mesh (paper: texture enhancement): each view's render is\n"
               "VAE-encoded, noised to strength S (1 = repaint), denoised under the prompt with depth control,\n"
               "and backprojected; texels no view reached keep the original texture.\n\n"
               "options:\n");
    mx_options_help(f, MX_VERB_ENHANCE);
}

int cmd_enhance(int argc, char **argv) {
    mx_cli_texture c;
    int rc = mx_cli_texture_parse(&c, argc, argv, MX_VERB_ENHANCE, enhance_usage);
    if (rc >= 0) return rc;
    return mx_cli_texture_run(&c, "enhance", matex_enhance);
}
