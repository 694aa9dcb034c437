/* The networks a weight file can hold, as the files know them: the one list of their names
 * (the weight-file prefix, "unet" -> tensors "unet.*" and metadata "unet.config"), the class
 * their diffusers / transformers config.json names, where they sit in a diffusers model-set
 * folder, and the key prefix of their kohya LoRA modules. The code that runs each network is in
 * pipeline/nn/registry.h, which names these entries (weights/ sits below pipeline/nn, so
 * convert and the LoRA merge read this table without linking the networks). */
#ifndef MX_WEIGHTS_NETWORKS_H
#define MX_WEIGHTS_NETWORKS_H

#include <stddef.h>

typedef struct mx_net_kind {
    const char *name;        /* "unet": the weight-file prefix without its dot */
    const char *class_name;  /* "UNet2DConditionModel": the config's _class_name / architectures[0] */
    int in_model_set;        /* 1: converted from the model-set subfolder of the same name */
    const char *lora_prefix; /* kohya LoRA key prefix ("lora_unet_"), NULL: LoRAs do not apply */
    const char *model_type;  /* transformers' "model_type" naming the class when "architectures" is
                                absent ("clip_text_model"), or NULL */
} mx_net_kind;

/* The list, and its length. */
extern const mx_net_kind mx_net_kinds[];
extern const size_t mx_net_kind_count;

/* The entry of that name / class, or NULL. */
const mx_net_kind *mx_net_kind_named(const char *name);
const mx_net_kind *mx_net_kind_of_class(const char *class_name);
const mx_net_kind *mx_net_kind_of_model_type(const char *model_type);
/* "A, B, ... or E": the known classes, for a message about an unknown one (cut at cap). */
void mx_net_kind_classes(char *buf, size_t cap);

#endif
