/* matex texture MESH "PROMPT" --weights W -o OUT_DIR: the Make-A-Texture method. */
#include <stdio.h>

#include "cli.h"
#include "cli_texture_opts.h"

static void texture_usage(FILE *f) {
    fprintf(f, "usage: matex texture MESH \"PROMPT\" --weights W.mxw -o OUT_DIR [options]\n\n"
               "Textures MESH (.obj .ply .off .stl .gltf .glb) from a text prompt with Stable Diffusion 1.5 +\n"
               "ControlNet depth and inpaint: front+back grid, automatic view selection, backprojection, UV fill.\n"
               "A mesh without UVs gets a UV atlas; a mesh with UVs keeps them (one texture per material).\n\n"
               "options:\n");
    mx_options_help(f, MX_VERB_TEXTURE);
}

int cmd_texture(int argc, char **argv) {
    mx_cli_texture c;
    int rc = mx_cli_texture_parse(&c, argc, argv, MX_VERB_TEXTURE, texture_usage);
    if (rc >= 0) return rc;
    return mx_cli_texture_run(&c, "texture", matex_texture);
}
