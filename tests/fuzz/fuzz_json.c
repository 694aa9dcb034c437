/* JSON text: the reader (runtime/json.c) walked in full, then the same bytes as each kind of
 * config the product parses (UNet/ControlNet, VAE, CLIP, scheduler, class name) and as the
 * parameter enumeration of the network it would describe. */
#include <string.h>

#include "../../pipeline/nn/clip.h"
#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/params.h"
#include "../../pipeline/nn/scheduler.h"
#include "../../runtime/json.h"
#include "fuzz.h"

/* Touches every node so that a bad pointer or length shows under the sanitizers. */
static size_t walk(const mx_json *j, int depth) {
    size_t n = 1;
    switch (mx_json_kind(j)) {
    case MX_JSON_STR:
        n += strlen(mx_json_str(j)) <= mx_json_str_len(j);
        break;
    case MX_JSON_NUM:
        n += mx_json_num(j) != 0;
        break;
    case MX_JSON_BOOL:
        n += mx_json_bool(j);
        break;
    case MX_JSON_OBJ:
        for (size_t i = 0; i < mx_json_len(j); i++) {
            const char *k = mx_json_key(j, i);
            n += strlen(k) + (mx_json_get(j, k) != NULL);
            n += walk(mx_json_at(j, i), depth + 1);
        }
        break;
    case MX_JSON_ARR:
        for (size_t i = 0; i < mx_json_len(j); i++) n += walk(mx_json_at(j, i), depth + 1);
        break;
    default:
        break;
    }
    return n;
}

static void parse_configs(const char *text, size_t len) {
    mx_status st;
    mx_unet_config uc;
    mx_vae_config vc;
    mx_clip_config cc;
    mx_sched_config sc;
    char cls[64];
    mx_unet_config_parse(&uc, text, len, "fuzz.json", &st);
    mx_vae_config_parse(&vc, text, len, "fuzz.json", &st);
    mx_clip_config_parse(&cc, text, len, "fuzz.json", &st);
    mx_sched_config_parse(&sc, text, len, "fuzz.json", &st);
    mx_config_class_name(cls, sizeof cls, text, len, "fuzz.json", &st);
    mx_binder b;
    memset(&b, 0, sizeof b);
    if (!mx_binder_enum(&b, &st)) mx_net_enumerate(&b, text, len, "fuzz.json", &st);
    mx_binder_free(&b);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    mx_status st;
    mx_json *root = mx_json_parse((const char *)data, size, "fuzz.json", &st);
    if (root) {
        walk(root, 0);
        mx_json_get_num(root, "a", 0);
        mx_json_get_str(root, "a", "");
        mx_json_get_bool(root, "a", 0);
        mx_json_free(root);
    }
    parse_configs((const char *)data, size);
    return 0;
}
