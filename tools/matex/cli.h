/* The command-line verbs of matex. Each verb lives in tools/matex/cmd_<verb>.c and returns the
 * process exit code: 0 success, 1 bad input (message printed), 2 usage error. */
#ifndef MX_CLI_H
#define MX_CLI_H

#define MX_CLI_VERBS(X)                                                                           \
    X(texture, "texture a mesh from a text prompt (Make-A-Texture)")                              \
    X(enhance, "enhance the texture of a textured mesh (SDEdit over views)")                      \
    X(batch, "texture a catalogue (a manifest of meshes and prompts), sharded and resumable")    \
    X(serve, "serve texturing jobs over HTTP, the model set loaded once")                       \
    X(transfer, "move the texture of a textured mesh onto another mesh or UV layout")             \
    X(render, "render turntable views and a contact sheet of a mesh")                             \
    X(info, "describe a mesh, an image (or compare two), a weight file or a checkpoint")          \
    X(convert, "convert an SD1.x checkpoint or diffusers folders into one matex weight file")     \
    X(gen_weights, "make random weights for a network config (golden-v1 rule)")                  \
    X(run_net, "run one network on tensors from a safetensors file")                              \
    X(tokenize, "print the 77 CLIP token ids of a prompt")                                        \
    X(bench, "run the built-in benchmarks")

#define MX_DECLARE_VERB(name, help) int cmd_##name(int argc, char **argv);
MX_CLI_VERBS(MX_DECLARE_VERB)
#undef MX_DECLARE_VERB

#endif
