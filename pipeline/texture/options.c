/* mx_texture_opts_check: every option of `matex texture` / `matex enhance` against its valid range,
 * before any work. The messages use the command-line option names (the public API documents the
 * mapping to the struct fields). */
#include <ctype.h>
#include <math.h>

#include "../geom/masks.h"
#include "texture.h"

static int int_in(const char *name, int v, int lo, int hi, mx_status *st) {
    if (v < lo || v > hi) return mx_fail(st, MX_EUSAGE, "%s must be in %d..%d, not %d", name, lo, hi, v);
    return 0;
}

/* lo <= v <= hi (lo_open: lo < v; hi_open: v < hi), and v finite. */
static int float_in(const char *name, float v, float lo, int lo_open, float hi, int hi_open, mx_status *st) {
    int ok = isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
    if (!ok)
        return mx_fail(st, MX_EUSAGE, "%s must be in %c%g, %g%c, not %g", name, lo_open ? '(' : '[', (double)lo,
                       (double)hi, hi_open ? ')' : ']', (double)v);
    return 0;
}

static int blank(const char *s) {
    while (*s && isspace((unsigned char)*s)) s++;
    return *s == 0;
}

static int check_paths(const mx_texture_opts *o, mx_texture_mode mode, mx_status *st) {
    /* the embedding API may give the mesh in memory, an opened model set, and keep the results */
    if (!o->mesh && (!o->mesh_path || !*o->mesh_path)) return mx_fail(st, MX_EUSAGE, "no mesh given");
    if (!o->keep_outputs && (!o->out_dir || !*o->out_dir))
        return mx_fail(st, MX_EUSAGE, "no output folder given (-o)");
    if (mode == MX_TEXTURE_MODE_TRANSFER)
        return !o->source_path || !*o->source_path ? mx_fail(st, MX_EUSAGE, "no source mesh given") : 0;
    if (!o->models && (!o->weights_path || !*o->weights_path))
        return mx_fail(st, MX_EUSAGE, "no weight file given (--weights)");
    if (!o->prompt) return mx_fail(st, MX_EUSAGE, "no prompt given");
    if (mode == MX_TEXTURE_MODE_TEXTURE && blank(o->prompt))
        return mx_fail(st, MX_EUSAGE, "the prompt is empty: describe the texture, e.g. \"a rustic wooden chair\"");
    if (!o->negative_prompt || !o->grid_word) return mx_fail(st, MX_EUSAGE, "--negative and --front-back-words need a text");
    return 0;
}

static int check_sizes(const mx_texture_opts *o, mx_texture_mode mode, mx_status *st) {
    if (int_in("--steps", o->steps, 1, 200, st) ||
        int_in("--views", o->views, mode == MX_TEXTURE_MODE_ENHANCE ? 1 : 2, 64, st) ||
        int_in("--candidates", o->candidates, 1, 4096, st) || int_in("--texture-size", o->tex_size, 16, 8192, st) ||
        int_in("--render-size", o->render_size, 16, 8192, st) || int_in("--batch", o->max_batch, 1, 64, st) ||
        int_in("--threads", o->threads, 0, 1024, st))
        return -1;
    if (o->image_size < 8 || o->image_size > 2048 || o->image_size % 8)
        return mx_fail(st, MX_EUSAGE, "--image-size must be a multiple of 8 in 8..2048, not %d", o->image_size);
    return 0;
}

static int check_weights(const mx_texture_opts *o, mx_status *st) {
    if (float_in("--guidance", o->guidance, 0.0f, 0, 50.0f, 0, st) ||
        float_in("--grid-depth-weight", o->grid_depth_weight, 0.0f, 0, 2.0f, 0, st))
        return -1;
    for (int i = 0; i < 2; i++)
        if (float_in("--depth-weight", o->depth_weight[i], 0.0f, 0, 2.0f, 0, st) ||
            float_in("--inpaint-weight", o->inpaint_weight[i], 0.0f, 0, 2.0f, 0, st))
            return -1;
    /* |n.v| <= 1: a threshold of 1 or more keeps no pixel, and the texture would be all fill */
    if (float_in("--frontal-threshold", o->frontal_threshold, 0.0f, 0, 1.0f, 1, st) ||
        float_in("--coverage-stop", o->coverage_stop, 0.0f, 1, 1.0f, 0, st) ||
        float_in("--strength", o->strength, 0.0f, 1, 1.0f, 0, st))
        return -1;
    return 0;
}

int mx_texture_opts_check(const mx_texture_opts *o, mx_texture_mode mode, mx_status *st) {
    if (check_paths(o, mode, st) || check_sizes(o, mode, st) || check_weights(o, st)) return -1;
    if (o->normal_source != MX_NORMAL_FROM_DEPTH && o->normal_source != MX_NORMAL_GEOMETRIC)
        return mx_fail(st, MX_EUSAGE, "--normals must be depth or geometric");
    if (o->up != MX_UP_Y && o->up != MX_UP_Z) return mx_fail(st, MX_EUSAGE, "--up must be y or z");
    if (o->precision != MX_PREC_FP32 && o->precision != MX_PREC_BF16)
        return mx_fail(st, MX_EUSAGE, "--precision must be fp32 or bf16");
    if ((int)o->device < 0 || (int)o->device >= MX_BACKEND_KINDS)
        return mx_fail(st, MX_EUSAGE, "--device must be cpu, cpu-strict or cuda");
    if (o->fast && mode == MX_TEXTURE_MODE_TRANSFER) return mx_fail(st, MX_EUSAGE, "--fast is for texture and enhance");
    return 0;
}
