/* The networks a weight file can hold (networks.h). */
#include "networks.h"

#include <stdio.h>
#include <string.h>

const mx_net_kind mx_net_kinds[] = {
    {.name = MX_NET_UNET, .class_name = "UNet2DConditionModel", .in_model_set = 1, .lora_prefix = "lora_unet_"},
    {.name = MX_NET_CONTROLNET, .class_name = "ControlNetModel", .in_model_set = 1},
    {.name = MX_NET_VAE, .class_name = "AutoencoderKL", .in_model_set = 1},
    {.name = MX_NET_TEXT_ENCODER, .class_name = "CLIPTextModel", .in_model_set = 1, .lora_prefix = "lora_te_",
     .model_type = "clip_text_model", .needs_tokenizer = 1},
    {.name = MX_NET_TAESD, .class_name = "AutoencoderTiny"},
    {.name = MX_NET_IMAGE_ENCODER, .class_name = "CLIPVisionModelWithProjection", .model_type = "clip_vision_model",
     .processor = "preprocessor_config.json"},
    /* matex's own config of the published adapter file (weights/ip_adapter_file.h) */
    {.name = MX_NET_IP_ADAPTER, .class_name = "IPAdapter"},
};
const size_t mx_net_kind_count = sizeof mx_net_kinds / sizeof mx_net_kinds[0];

const mx_net_kind *mx_net_kind_named(const char *name) {
    for (size_t i = 0; name && i < mx_net_kind_count; i++)
        if (!strcmp(mx_net_kinds[i].name, name)) return &mx_net_kinds[i];
    return NULL;
}

const mx_net_kind *mx_net_kind_of_class(const char *class_name) {
    for (size_t i = 0; class_name && i < mx_net_kind_count; i++)
        if (!strcmp(mx_net_kinds[i].class_name, class_name)) return &mx_net_kinds[i];
    return NULL;
}

const mx_net_kind *mx_net_kind_of_model_type(const char *model_type) {
    for (size_t i = 0; model_type && i < mx_net_kind_count; i++)
        if (mx_net_kinds[i].model_type && !strcmp(mx_net_kinds[i].model_type, model_type)) return &mx_net_kinds[i];
    return NULL;
}

void mx_net_kind_classes(char *buf, size_t cap) {
    size_t len = 0;
    buf[0] = 0;
    for (size_t i = 0; i < mx_net_kind_count && len < cap; i++)
        len += (size_t)snprintf(buf + len, cap - len, "%s%s", i == 0 ? "" : i + 1 < mx_net_kind_count ? ", " : " or ",
                                mx_net_kinds[i].class_name);
}
