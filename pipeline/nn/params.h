/* Parameter binding: the one place where a network's code names its tensors.
 * A network's load function asks a binder for each parameter by its reference state-dict
 * name (diffusers / transformers naming, e.g. "down_blocks.0.resnets.0.conv1.weight") and
 * expected shape. The same load code therefore serves three purposes:
 *   - binding to a matex weight file (names prefixed, e.g. "unet."; shapes checked, errors
 *     name the file and the tensor),
 *   - enumerating the parameter list of a config (for `matex gen-weights` and the converter's
 *     completeness check), with no data,
 *   - binding to a safetensors file directly (tests).
 * Implementations live in pipeline/nn/params.c. */
#ifndef MX_PARAMS_H
#define MX_PARAMS_H

#include <stdint.h>

#include "../../ops/ops.h"
#include "../../runtime/status.h"

typedef struct mx_binder mx_binder;
struct mx_binder {
    /* Fills *out for `name` (without prefix) of the given shape; returns 0, or -1 with st
     * naming the file and tensor (missing tensor, wrong shape, unsupported dtype). When
     * enumerating, out->data is NULL and the call only records the name and shape. */
    int (*bind)(mx_binder *b, const char *name, int ndim, const int64_t *shape, mx_wptr *out, mx_status *st);
    void *impl;
    char prefix[64]; /* e.g. "unet." */
    int enumerating; /* 1: no data; network loaders must not read weight values */
};

/* Convenience: builds the shape array from varargs (ndim values of type int64_t). */
int mx_bind(mx_binder *b, mx_wptr *out, mx_status *st, const char *name, int ndim, ...);

/* ---- binders (pipeline/nn/params.c); each is released with mx_binder_free ---- */

struct mx_weightfile;
struct mx_safetensors;

/* Binds "<prefix><name>" in an open matex weight file; data points into the mapping, so the
 * file must stay open while the network is used. */
int mx_binder_wf(mx_binder *b, const struct mx_weightfile *wf, const char *prefix, mx_status *st);
/* Binds "<prefix><name>" in an open safetensors file (prefix may be ""). Each bound tensor
 * is copied into an owned 64-byte aligned buffer (F32/F16/BF16 kept as is, F64 narrowed to
 * F32), so the binder must outlive the network; the file may be closed after loading. */
int mx_binder_st(mx_binder *b, const struct mx_safetensors *f, const char *prefix, mx_status *st);
/* Generates each bound tensor by the golden-v1 rule (weights/golden_rule.h) with `seed` into
 * an owned buffer, stored as MX_F32 or MX_F16 (`dtype`): the SD1.5-size networks without a
 * weight file (tests, benchmarks). Names are used without prefix. */
int mx_binder_rule(mx_binder *b, uint64_t seed, mx_dtype dtype, mx_status *st);
/* Binds through `inner` and keeps each weight, in its stored type, in the memory of c's backend
 * (uploaded once; on a host-visible backend the inner binder's data serves as it is). inner and
 * c must outlive b; free b before inner. */
int mx_binder_device(mx_binder *b, mx_binder *inner, const mx_ctx *c, mx_status *st);
/* Records (name, ndim, shape) of every bind call, binds nothing (out->data = NULL). */
int mx_binder_enum(mx_binder *b, mx_status *st);
void mx_binder_free(mx_binder *b);

/* The list recorded by an enumerating binder, in bind order. */
typedef struct mx_param_info {
    char *name; /* without prefix */
    int ndim;
    int64_t shape[5];
} mx_param_info;
size_t mx_binder_enum_count(const mx_binder *b);
const mx_param_info *mx_binder_enum_at(const mx_binder *b, size_t i);
/* Total bytes an enumerating binder has recorded (in fp32). */
size_t mx_binder_enum_bytes(const mx_binder *b);

#endif
