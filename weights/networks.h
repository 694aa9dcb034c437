/* The networks a weight file can hold, as the files know them: the ONE list of their names (the
 * weight-file prefix, "unet" -> tensors "unet.*" and metadata "unet.config"), the class their
 * diffusers / transformers config.json names, where they sit in a diffusers model-set folder, the
 * key prefix of their kohya LoRA modules, and what convert adds beside their tensors.
 * Code names a network by the constants below, never by a string literal. The code that runs
 * each network is attached by kind in pipeline/nn/registry.c (weights/ sits below pipeline/nn:
 * convert, info, gen-weights and the LoRA merge read this list without linking the networks).
 *
 * Adding a network: one constant and one line of mx_net_kinds (networks.c), its file in
 * pipeline/nn and its entries in pipeline/nn/registry.c. */
#ifndef MX_WEIGHTS_NETWORKS_H
#define MX_WEIGHTS_NETWORKS_H

#include <stddef.h>

/* The names (weight-file prefixes without their dot): MX_NET_UNET "." is the prefix. */
#define MX_NET_UNET "unet"
#define MX_NET_CONTROLNET "controlnet"
#define MX_NET_VAE "vae"
#define MX_NET_TEXT_ENCODER "text_encoder"
#define MX_NET_TAESD "taesd"
#define MX_NET_IMAGE_ENCODER "image_encoder"
#define MX_NET_IP_ADAPTER "ip_adapter"

typedef struct mx_net_kind {
    const char *name;        /* MX_NET_UNET: the weight-file prefix without its dot */
    const char *class_name;  /* "UNet2DConditionModel": the config's _class_name / architectures[0] */
    int in_model_set;        /* 1: converted from the model-set subfolder of the same name */
    const char *lora_prefix; /* kohya LoRA key prefix ("lora_unet_"), NULL: LoRAs do not apply */
    const char *model_type;  /* transformers' "model_type" naming the class when "architectures" is
                                absent ("clip_text_model"), or NULL */
    int needs_tokenizer;     /* 1: prompts reach it as token ids: convert adds the CLIP vocabulary */
    const char *processor;   /* a file of its folder convert stores as metadata "<name>.processor"
                                ("preprocessor_config.json"), or NULL */
} mx_net_kind;

/* The list, and its length (at most MX_NET_KIND_MAX: convert keeps one config per kind). */
#define MX_NET_KIND_MAX 16
extern const mx_net_kind mx_net_kinds[];
extern const size_t mx_net_kind_count;

/* The entry of that name / class, or NULL. */
const mx_net_kind *mx_net_kind_named(const char *name);
const mx_net_kind *mx_net_kind_of_class(const char *class_name);
const mx_net_kind *mx_net_kind_of_model_type(const char *model_type);
/* "A, B, ... or E": the known classes, for a message about an unknown one (cut at cap). */
void mx_net_kind_classes(char *buf, size_t cap);

#endif
