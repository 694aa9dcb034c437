/* matex convert: diffusers folders -> one matex weight file (weights/FORMAT.md). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <limits.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../runtime/log.h"
#include "../../weights/convert.h"
#include "cli.h"
#include "cli_args.h"

static void convert_usage(FILE *f) {
    fprintf(f,
            "usage: matex convert [INPUT] -o OUT.mxw [options]\n"
            "\n"
            "Converts a Stable Diffusion 1.x checkpoint into one matex weight file.\n"
            "INPUT is a single-file checkpoint (.safetensors, or a PyTorch zip .ckpt/.pt/.pth) in the original\n"
            "layout (model.diffusion_model.*, first_stage_model.*, cond_stage_model.transformer.*),\n"
            "or a diffusers model-set folder (subfolders unet/, controlnet/, vae/, text_encoder/, tokenizer/,\n"
            "scheduler/; each one present is converted) or a single network folder whose config.json\n"
            "names a UNet2DConditionModel, ControlNetModel, AutoencoderKL, AutoencoderTiny, CLIPTextModel or\n"
            "CLIPVisionModelWithProjection.\n"
            "Tensor names: unet.*, controlnet.*, controlnet_NAME.*, vae.*, taesd.*, text_encoder.*, image_encoder.*,\n"
            "ip_adapter.*\n"
            "\n"
            "options:\n"
            "  -o, --output FILE        weight file to write (written to a temporary name, then renamed)\n"
            "  --dtype f16|bf16|f32     storage type of tensors with 2+ dims (default f16; 1-D stay f32)\n"
            "  --variant fp16           read the *.fp16.safetensors files (used anyway when only they exist)\n"
            "  --controlnet NAME=PATH   add a ControlNet as controlnet_NAME.* (repeatable; NAME in [a-z0-9_]);\n"
            "                           PATH: a folder or a ControlNet v1.0/v1.1 file (.pth or .safetensors)\n"
            "  --vae PATH               replace the model's VAE: a VAE file (LDM or diffusers names, e.g.\n"
            "                           vae-ft-mse-840000-ema-pruned.safetensors) or an AutoencoderKL folder\n"
            "  --ema                    single file: take the EMA copy of the UNet (default: the non-EMA weights)\n"
            "  --tokenizer DIR          CLIP vocabulary (vocab.json, merges.txt) for a single file (default:\n"
            "                           the copy installed with matex, share/matex/tokenizer)\n"
            "  --lora FILE              merge a LoRA (diffusers/PEFT or kohya keys) into UNet and text encoder\n"
            "  --lora-scale S           scale of the preceding --lora (default 1.0)\n"
            "  --lcm-lora FILE          merge the LCM-LoRA (a --lora, recorded so that `texture --fast` may run)\n"
            "  --taesd PATH             add TAESD as taesd.*, the fast decoder: an AutoencoderTiny folder, or the\n"
            "                           original taesd_encoder + taesd_decoder files (one of them, or their folder)\n"
            "  --image-encoder DIR      add the IP-Adapter's CLIP vision tower as image_encoder.*: a transformers\n"
            "                           CLIPVisionModelWithProjection folder (config.json + model.safetensors)\n"
            "  --ip-adapter FILE        add the SD1.5 IP-Adapter (image guidance) as ip_adapter.*: h94/IP-Adapter's\n"
            "                           ip-adapter_sd15.safetensors or .bin, checked against the UNet converted with it\n"
            "  --json                   print a JSON summary on stdout\n"
            "  --quiet                  no progress lines\n"
            "  -h, --help               this help\n"
            "\n"
            "examples:\n"
            "  matex convert v1-5-pruned-emaonly.safetensors --controlnet depth=control_v11f1p_sd15_depth.pth -o sd15.mxw\n"
            "  matex convert stable-diffusion-v1-5 --controlnet depth=control_v11f1p_sd15_depth \\\n"
            "      --controlnet inpaint=control_v11p_sd15_inpaint -o sd15.mxw\n"
            "  matex convert tests/data/golden/unet_tiny -o unet_tiny.mxw --dtype f32   (in the source tree)\n"
            "  fast path: ... --lcm-lora pytorch_lora_weights.safetensors --taesd taesd (then texture --fast)\n");
}

static int parse_dtype(const char *s, mx_dtype *dt) {
    if (!strcmp(s, "f16") || !strcmp(s, "fp16")) *dt = MX_F16;
    else if (!strcmp(s, "bf16")) *dt = MX_BF16;
    else if (!strcmp(s, "f32") || !strcmp(s, "fp32")) *dt = MX_F32;
    else return -1;
    return 0;
}

static int usage_error(const char *msg, const char *arg) {
    fprintf(stderr, "matex convert: %s%s%s\n(matex convert --help for usage)\n", msg, arg ? " " : "", arg ? arg : "");
    return 2;
}

typedef struct {
    mx_convert_opts o;
    int json;
} convert_args;

/* Returns -1 to go on, or an exit code (0 after --help, 2 on a usage error). */
static int parse_args(int argc, char **argv, convert_args *a) {
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i], *val = i + 1 < argc ? argv[i + 1] : NULL;
        int takes = !strcmp(arg, "-o") || !strcmp(arg, "--output") || !strcmp(arg, "--dtype") ||
                    !strcmp(arg, "--variant") || !strcmp(arg, "--controlnet") || !strcmp(arg, "--lora") ||
                    !strcmp(arg, "--lora-scale") || !strcmp(arg, "--lcm-lora") || !strcmp(arg, "--taesd") ||
                    !strcmp(arg, "--tokenizer") || !strcmp(arg, "--vae") || !strcmp(arg, "--image-encoder") ||
                    !strcmp(arg, "--ip-adapter");
        if (takes && !val) return usage_error("missing value after", arg);
        if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) {
            convert_usage(stdout);
            return 0;
        } else if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) {
            a->o.output = val;
        } else if (!strcmp(arg, "--dtype")) {
            if (parse_dtype(val, &a->o.dtype)) return usage_error("--dtype must be f16, bf16 or f32, not", val);
        } else if (!strcmp(arg, "--variant")) {
            if (strcmp(val, "fp16")) return usage_error("--variant accepts only fp16, not", val);
            a->o.prefer_fp16 = 1;
        } else if (!strcmp(arg, "--controlnet")) {
            const char *eq = strchr(val, '=');
            if (!eq || eq == val || !eq[1]) return usage_error("--controlnet wants NAME=DIR, not", val);
            if (a->o.n_controlnets == MX_CONVERT_MAX_EXTRA) return usage_error("too many --controlnet", NULL);
            size_t k = a->o.n_controlnets++;
            argv[i + 1][eq - val] = 0; /* split NAME=DIR in place */
            a->o.controlnets[k].name = val;
            a->o.controlnets[k].dir = eq + 1;
        } else if (!strcmp(arg, "--lora") || !strcmp(arg, "--lcm-lora")) {
            if (a->o.n_loras == MX_CONVERT_MAX_EXTRA) return usage_error("too many --lora", NULL);
            a->o.loras[a->o.n_loras].path = val;
            a->o.loras[a->o.n_loras].lcm = !strcmp(arg, "--lcm-lora");
            a->o.loras[a->o.n_loras++].scale = 1.0f;
        } else if (!strcmp(arg, "--taesd")) {
            a->o.taesd = val;
        } else if (!strcmp(arg, "--image-encoder")) {
            a->o.image_encoder = val;
        } else if (!strcmp(arg, "--vae")) {
            a->o.vae = val;
        } else if (!strcmp(arg, "--ip-adapter")) {
            a->o.ip_adapter = val;
        } else if (!strcmp(arg, "--tokenizer")) {
            a->o.tokenizer = val;
        } else if (!strcmp(arg, "--ema")) {
            a->o.ema = 1;
        } else if (!strcmp(arg, "--lora-scale")) {
            if (a->o.n_loras == 0) return usage_error("--lora-scale must follow a --lora or --lcm-lora", NULL);
            if (mx_parse_float(val, &a->o.loras[a->o.n_loras - 1].scale))
                return usage_error("--lora-scale wants a finite number, not", val);
        } else if (!strcmp(arg, "--json")) {
            a->json = 1;
        } else if (!strcmp(arg, "--quiet")) {
            mx_log_set_level(MX_LOG_WARN);
        } else if (arg[0] == '-' && arg[1]) {
            return usage_error("unknown option", arg);
        } else if (a->o.input) {
            return usage_error("more than one INPUT:", arg);
        } else {
            a->o.input = arg;
        }
        if (takes) i++;
    }
    if (!a->o.output) return usage_error("no output file (-o OUT.mxw)", NULL);
    if (!a->o.input && a->o.n_controlnets == 0 && !a->o.taesd && !a->o.vae && !a->o.image_encoder)
        return usage_error("no INPUT folder or checkpoint file", NULL);
    return -1;
}

/* The CLIP vocabulary shipped with matex: PREFIX/share/matex/tokenizer beside the installed binary,
 * or tests/data/golden/tokenizer of the source tree (build/matex, ./matex). */
static const char *default_tokenizer(char *buf, size_t cap) {
    static const char *const rel[] = {"/../share/matex/tokenizer", "/../tests/data/golden/tokenizer", "/tests/data/golden/tokenizer"};
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n <= 0) return NULL;
    exe[n] = 0;
    char *slash = strrchr(exe, '/');
    if (slash) *slash = 0;
    for (size_t i = 0; i < sizeof rel / sizeof rel[0]; i++) {
        struct stat sb;
        char vocab[PATH_MAX + 128];
        snprintf(buf, cap, "%s%s", exe, rel[i]);
        if (snprintf(vocab, sizeof vocab, "%.*s/vocab.json", PATH_MAX, buf) >= (int)sizeof vocab) continue;
        if (stat(vocab, &sb) == 0 && S_ISREG(sb.st_mode)) return buf;
    }
    return NULL;
}

static void print_json_string(const char *s) {
    putchar('"');
    for (; *s; s++) {
        if (*s == '"' || *s == '\\') putchar('\\');
        if ((unsigned char)*s >= 0x20) putchar(*s);
    }
    putchar('"');
}

int cmd_convert(int argc, char **argv) {
    convert_args a;
    memset(&a, 0, sizeof a);
    a.o.dtype = MX_F16;
    int rc = parse_args(argc, argv, &a);
    if (rc >= 0) return rc;
    char tokenizer[PATH_MAX + 64];
    if (!a.o.tokenizer) a.o.tokenizer = default_tokenizer(tokenizer, sizeof tokenizer);
    double t0 = mx_now();
    mx_convert_result res;
    mx_status st;
    mx_status_clear(&st);
    if (mx_convert(&a.o, &res, &st)) {
        fprintf(stderr, "matex convert: %s\n", st.msg);
        return st.code == MX_EUSAGE ? 2 : 1;
    }
    struct stat sb;
    double mib = stat(a.o.output, &sb) == 0 ? (double)sb.st_size / 1048576.0 : 0;
    mx_info("convert: wrote %s: %zu tensors from %zu network(s), %.1f MiB, %zu weight(s) changed by LoRA, %.1f s",
            a.o.output, res.tensors, res.networks, mib, res.lora_merged, mx_now() - t0);
    if (a.json)
    {
        printf("{\"output\": ");
        print_json_string(a.o.output);
        printf(", \"tensors\": %zu, \"networks\": %zu, \"mib\": %.3f, \"lora_merged\": %zu}\n", res.tensors,
               res.networks, mib, res.lora_merged);
    }
    return 0;
}
