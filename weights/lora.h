/* LoRA files merged into UNet and text-encoder weights by `matex convert --lora`.
 * Key styles read (safetensors, F32/F16/BF16):
 *   diffusers / PEFT: "unet.<module>.lora_A.weight" (down) / ".lora_B.weight" (up),
 *                     "<module>.lora.down.weight" / ".lora.up.weight", attention-processor
 *                     style "<...>.processor.to_q_lora.down.weight", optional "<module>.alpha",
 *                     PEFT's "base_model.model." wrapping dropped wherever it sits;
 *                     a module without "unet." / "text_encoder." is a text-encoder module when
 *                     it starts with "text_model.", else a UNet module;
 *   kohya:            "lora_unet_<module with _>.lora_down.weight" / ".lora_up.weight",
 *                     "lora_te_<module>...", "<key>.alpha".
 * Merge: W += scale * (alpha / rank) * up @ down, with up [out, rank(,1,1)] and down
 * [rank, in(,kh,kw)]; a 1x1 conv weight and a linear LoRA (or the reverse) match by size.
 * alpha defaults to rank. */
#ifndef MX_LORA_H
#define MX_LORA_H

#include <stddef.h>
#include <stdint.h>

#include "../runtime/status.h"

typedef struct mx_lora mx_lora;

/* Reads and groups the file's keys into modules; fails on unknown keys, a module without
 * both up and down, or inconsistent ranks. */
int mx_lora_open(mx_lora **out, const char *path, mx_status *st);
void mx_lora_close(mx_lora *l);
size_t mx_lora_module_count(const mx_lora *l);

/* 1 when the LoRA has a module for tensor `name` of network `net` (see mx_lora_merge). */
int mx_lora_has(const mx_lora *l, const char *net, const char *name);
/* If the LoRA has a module for tensor `name` (state-dict name, ending in ".weight") of
 * network `net` ("unet" or "text_encoder"), adds scale * (alpha/rank) * up @ down to w
 * (fp32, shape as given) and returns 1; returns 0 when it has none, -1 on a shape mismatch
 * (message names the LoRA file, module and shapes). Marks the module used. */
int mx_lora_merge(mx_lora *l, const char *net, const char *name, int ndim, const int64_t *shape, float *w,
                  float scale, mx_status *st);
/* After all merges: fails naming the first module that matched no weight. */
int mx_lora_check_all_used(const mx_lora *l, mx_status *st);

#endif
