#include "job.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/fileio.h"
#include "../../runtime/log.h"
#include "../../runtime/rng.h"
#include "../../runtime/version.h"
#include "../geom/export.h"
#include "../geom/masks.h"
#include "../geom/raster.h"
#include "../geom/uvfill.h"
#include "../io/io.h"
#include "../nn/sd_edit.h"
#include "../nn/vae_tiled.h"
#include "condition.h"
#include "digest.h"
#include "outdir.h"

#define SCRATCH_BYTES ((size_t)64 << 20)
#define CANDIDATE_RENDER_SIZE 256
#define CAMERA_RADIUS 3.0f
#define CAMERA_HALF_EXTENT 1.02f /* the normalised mesh lies in the unit sphere */
#define CROP_MARGIN 0.05f
#define UV_GUTTER 4
/* I′ (the current texture rendered into a view) samples texels bilinearly: known colours are
 * spread this many texels into the unknown ones so that no grey fringe appears at the border
 * of the painted region (the unknown pixels are repainted anyway). */
#define CURRENT_DILATE_TEXELS 4
/* The inpaint pipeline keeps or repaints whole latent cells; a cell is repainted when it or a
 * neighbouring cell holds an untextured pixel (mx_paint_mask_cells). */
#define PAINT_DILATE_CELLS 1
/* VAE decode in tiles of this many latents (384 pixels), one image at a time: bounds the decode's
 * memory at ~1.4x its work (the figures: docs/DESIGN.md §3, "Memory of a run"); blend as diffusers'
 * tiled_decode (pipeline/nn/vae_tiled.h). */
#define VAE_TILE 48
static const float GREY[3] = {0.5f, 0.5f, 0.5f};

/* Sends one event to the progress callback; a non-zero answer stops the run. */
static void emit_progress(mx_job *j, int step, int steps, const char *message) {
    const mx_texture_opts *o = j->o;
    if (!o->progress) return;
    mx_texture_progress p = {.stage = j->rep.phase,
                             .step = step,
                             .steps = steps,
                             .views_done = j->rep.views_done,
                             .views_total = o->pub.views,
                             .coverage = j->sched.chart ? mx_job_coverage(j) : 0.0,
                             .seconds = mx_now() - j->rep.t0,
                             .message = message};
    if (o->progress(o->progress_user, &p)) j->rep.stop = 1;
}

void mx_job_progress(mx_job *j, const char *fmt, ...) {
    if (!j->o->pub.verbose && !j->o->progress) return;
    char line[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    if (!!j->o->pub.verbose) fprintf(stderr, "matex: [%7.2fs] %s\n", mx_now() - j->rep.t0, line);
    emit_progress(j, 0, 0, line);
}

void mx_job_set_phase(mx_job *j, const char *stage) { snprintf(j->rep.phase, sizeof j->rep.phase, "%s", stage); }

int mx_job_check_cancel(const mx_job *j, mx_status *st) {
    if (j->rep.stop || (j->o->pub.cancel && *j->o->pub.cancel)) return mx_fail(st, MX_ECANCEL, "interrupted");
    return 0;
}

/* A mesh with UVs keeps them (faces without get an atlas and a texture of their own: one
 * layer per material); a mesh without gets one atlas and one texture. */
static int prepare_uvs(mx_job *j, int need_uvs, mx_status *st) {
    mx_mesh *m = &j->mesh;
    mx_uvatlas_opts ao = mx_uvatlas_defaults();
    ao.texture_size = j->o->pub.texture_size;
    if (m->nuv > 0 && m->face_uv) {
        int atlas_faces = 0;
        if (mx_uvatlas_complete(m, &ao, &j->atlas, &atlas_faces, st)) return -1;
        j->atlas_built = atlas_faces > 0;
        j->nlayers = m->nmat > 1 && m->face_mat ? m->nmat : 1;
        return 0;
    }
    if (need_uvs)
        return mx_fail(st, MX_EINPUT, "%s: the mesh has no UVs (a textured mesh is needed)", m->source_path);
    if (mx_uvatlas_build(m, &ao, &j->atlas, st)) return -1;
    j->atlas_built = 1;
    /* one atlas for the whole mesh: every face renders and exports with material 0 */
    free(m->face_mat);
    m->face_mat = NULL;
    j->nlayers = 1;
    mx_job_progress(j, "UV atlas: %d charts, utilisation %.3f, %.2fs", j->atlas.charts, j->atlas.utilisation,
                    j->atlas.seconds);
    return 0;
}

int mx_job_ctx_create(mx_ctx *c, const mx_texture_opts *o, mx_status *st) {
    return mx_ctx_create_on(c, mx_texture_opts_device(o), o->pub.threads, mx_cpu_isa_for(mx_texture_opts_precision(o)), SCRATCH_BYTES, st);
}

void mx_job_camera(mx_camera *cam, float azimuth, float elevation) {
    mx_camera_ortho(cam, azimuth, elevation, CAMERA_RADIUS, CAMERA_HALF_EXTENT);
}

static int build_candidates(mx_job *j, mx_status *st) {
    int n = j->o->pub.candidates;
    mx_camera tmpl, *cams = calloc((size_t)n, sizeof *cams);
    if (!cams) return mx_fail(st, MX_ENOMEM, "candidate cameras: out of memory");
    mx_job_camera(&tmpl, 0.0f, 0.0f);
    mx_camera_fibonacci(cams, n, &tmpl);
    int rc = mx_view_cache_build(&j->sched.vc, &j->mesh, j->pos, cams, n, CANDIDATE_RENDER_SIZE, j->o->pub.texture_size,
                                 j->o->pub.texture_size, j->nlayers, mx_texture_opts_normals(j->o), j->o->pub.frontal_threshold,
                                 mx_view_scale_radius(mx_view_erode_radius(j->o->pub.render_size, j->o->pub.image_size),
                                                      j->o->pub.render_size, CANDIDATE_RENDER_SIZE),
                                 j->gen.ctx->pool, st);
    free(cams);
    if (rc) return -1;
    j->sched.vc_ready = 1;
    size_t texels = (size_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size;
    j->sched.visible = calloc(texels, 1);
    if (!j->sched.visible) return mx_fail(st, MX_ENOMEM, "visibility mask: out of memory");
    mx_view_cache_visible(&j->sched.vc, j->sched.visible);
    j->sched.n_visible = mx_mask_count(j->sched.visible, (int64_t)texels);
    if (j->sched.n_visible == 0)
        return mx_fail(st, MX_EINPUT, "%s: no view sees any texel of the mesh (are all its faces of zero area?)",
                       j->o->pub.mesh_path);
    return 0;
}

/* Warns, once per job, when `text` is longer than the 75 tokens CLIP reads: how many tokens are
 * dropped (the count `matex tokenize` gives) and where the dropped part begins. */
static int warn_if_truncated(mx_job *j, const char *what, const char *text, mx_status *st) {
    if (j->gen.truncation_warned || !j->gen.models->tok) return 0;
    mx_tok_result r;
    if (mx_tok_encode(j->gen.models->tok, text, &r, st)) return -1;
    if (r.n_dropped == 0) return 0;
    mx_warn("%s longer than the %d tokens CLIP reads: %d%s tokens dropped, from \"%s\"", what, MX_CLIP_CONTEXT - 2,
            r.n_dropped, r.n_dropped + MX_CLIP_CONTEXT - 2 >= MX_TOK_MAX_COUNTED ? " or more" : "", r.dropped_from);
    j->gen.truncation_warned = 1;
    return 0;
}

/* The texels of the mesh (inside a face in UV space), what coverage is measured against. */
static int build_chart(mx_job *j, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    j->sched.chart = malloc(plane * (size_t)j->nlayers);
    if (!j->sched.chart) return mx_fail(st, MX_ENOMEM, "chart mask: out of memory");
    for (int l = 0; l < j->nlayers; l++)
        if (mx_uv_chart_mask(&j->mesh, l, j->nlayers, j->o->pub.texture_size, j->o->pub.texture_size, j->sched.chart + l * plane, st))
            return -1;
    j->sched.n_chart = mx_mask_count(j->sched.chart, (int64_t)(plane * (size_t)j->nlayers));
    return 0;
}

/* A render coarser than the texture leaves texels between a view's pixels: they are filled from
 * their neighbours (backproject.h), and texels no view reaches are filled, not painted. */
static void warn_render_size(const mx_texture_opts *o) {
    if (o->pub.render_size < o->pub.texture_size)
        mx_warn("render size %d is below the texture size %d: a view's pixels are sparser than the texels, so "
                "texels between them are interpolated and fine ones may stay unseen (--render-size %d matches)",
                o->pub.render_size, o->pub.texture_size, o->pub.texture_size);
}

static int encode_negative(mx_job *j, mx_status *st) {
    int C = mx_models_text_dim(j->gen.models);
    j->gen.uncond = malloc(sizeof(float) * MX_CLIP_CONTEXT * (size_t)C);
    if (!j->gen.uncond) return mx_fail(st, MX_ENOMEM, "prompt embeddings: out of memory");
    int dropped = 0;
    if (mx_models_encode_text(j->gen.models, j->gen.ctx, j->o->pub.negative_prompt, j->gen.uncond, &dropped, st)) return -1;
    if (dropped) mx_warn("negative prompt longer than 77 tokens: truncated (%d tokens dropped)", dropped);
    return 0;
}

/* The kernels and arithmetic of a context, for the log and report.json: a CPU level and its
 * precision, or CUDA, "mixed": it computes each product in its weights' type (fp16/bf16 weights on
 * tensor cores with fp32 sums, fp32 weights in fp32; ops/cuda/cuda_backend.h). */
static int on_cuda(const mx_ctx *c) { return c->be && c->be->kind == MX_BACKEND_CUDA; }
static const char *ctx_kernels_name(const mx_ctx *c) { return on_cuda(c) ? "cuda" : mx_isa_name(c->k->isa); }
static const char *ctx_precision_name(const mx_ctx *c) {
    return on_cuda(c) ? "mixed" : mx_precision_name(mx_isa_precision(c->k->isa));
}

static void report_header(mx_job *j) {
    const mx_texture_opts *o = j->o;
    mx_jw *w = &j->rep.json;
    mx_jw_init(w);
    mx_jw_begin_obj(w, NULL);
    mx_jw_str(w, "matex_version", MX_VERSION);
    mx_jw_str(w, "mesh", j->mesh.source_path);
    if (o->pub.source_path) mx_jw_str(w, "source", o->pub.source_path);
    if (j->gen.models) {
        mx_jw_str(w, "prompt", o->pub.prompt);
        mx_jw_str(w, "negative_prompt", o->pub.negative_prompt);
        mx_jw_int(w, "seed", (long long)o->pub.seed);
        mx_jw_int(w, "steps", o->pub.steps);
        mx_jw_bool(w, "fast", o->pub.fast);
        mx_jw_num(w, "guidance", o->pub.guidance);
        mx_jw_int(w, "image_size", o->pub.image_size);
        mx_style_report(&j->gen.style, w);
    }
    mx_jw_int(w, "texture_size", o->pub.texture_size);
    mx_jw_int(w, "render_size", o->pub.render_size);
    mx_jw_int(w, "threads", mx_pool_threads(j->gen.ctx->pool));
    if (j->gen.models) {
        mx_jw_str(w, "precision", ctx_precision_name(j->gen.ctx));
        mx_jw_str(w, "kernels", ctx_kernels_name(j->gen.ctx));
        mx_jw_str(w, "weights", mx_models_path(j->gen.models));
        mx_jw_str(w, "weights_digest", j->gen.models->digest);
    }
    mx_jw_int(w, "faces", j->mesh.nfaces);
    mx_jw_int(w, "vertices", j->mesh.nverts);
    mx_jw_int(w, "textures", j->nlayers);
    mx_jw_bool(w, "uv_atlas_built", j->atlas_built);
    if (j->atlas_built) {
        mx_jw_begin_obj(w, "uv_atlas");
        mx_jw_int(w, "charts", j->atlas.charts);
        mx_jw_num(w, "utilisation", j->atlas.utilisation);
        mx_jw_num(w, "stretch_mean", j->atlas.stretch_mean);
        mx_jw_num(w, "seconds", j->atlas.seconds);
        mx_jw_end_obj(w);
    }
    mx_jw_int(w, "candidate_views", o->pub.candidates);
    mx_jw_num(w, "candidate_visible_texels", (double)j->sched.n_visible);
    mx_jw_num(w, "mesh_texels", (double)j->sched.n_chart);
    mx_jw_begin_arr(w, "views");
}

/* The style images' tokens, once for the whole run (style.h). */
static int encode_style(mx_job *j, mx_status *st) {
    mx_style *s = &j->gen.style;
    if (!s->n) return 0;
    double t = mx_now();
    if (mx_style_check_models(j->gen.models, st) || mx_style_encode(s, j->gen.models, j->gen.ctx, st)) return -1;
    mx_job_progress(j, "style: %d image(s), %d image tokens at scale %.2f, encoded in %.2fs", s->n, s->ntokens,
                    s->scale, mx_now() - t);
    return 0;
}

/* --fast runs the LCM scheduler on an LCM-distilled UNet and decodes with TAESD: both must be in
 * the weight file. */
static int check_fast_models(const mx_job *j, mx_status *st) {
    const mx_models *m = j->gen.models;
    if (m->lcm && m->taesd) return 0;
    return mx_fail(st, MX_EINPUT,
                   "%s: --fast needs a weight file with the LCM-LoRA merged into the UNet and TAESD; this one has %s. "
                   "Make one with: matex convert SD15_DIR --controlnet depth=DIR --controlnet inpaint=DIR "
                   "--lcm-lora lcm-lora-sdv1-5.safetensors --taesd TAESD_DIR -o W.mxw",
                   mx_models_path(m), !m->lcm && !m->taesd ? "neither" : !m->lcm ? "no LCM-LoRA (metadata unet.lcm_lora)"
                                                                                : "no TAESD (taesd.*)");
}

int mx_job_open(mx_job *j, const mx_texture_opts *o, int model_needs, int need_uvs, mx_status *st) {
    memset(j, 0, sizeof *j);
    j->o = o;
    j->rep.t0 = mx_now();
    mx_job_set_phase(j, "load");
    j->rep.psnr_db = NAN;
    j->write_flags = o->pub.first_wins ? 0 : MX_BACKPROJECT_OVERWRITE;
    const char *inputs[] = {o->pub.mesh_path, o->models ? mx_models_path(o->models) : o->weights_path, o->pub.source_path};
    if (model_needs != MX_JOB_NO_MODELS && mx_style_load(&j->gen.style, &o->pub, st)) return -1;
    if (o->pub.out_dir && mx_outdir_open(&j->out, o->pub.out_dir, o->pub.force, inputs, 3, st)) return -1;
    if (o->models) { /* an opened model set computes on its own context */
        j->gen.models = o->models;
        j->gen.ctx = o->models->c;
    } else {
        if (mx_job_ctx_create(&j->gen.own_ctx, o, st)) return -1;
        j->gen.own_ctx_ready = 1;
        j->gen.ctx = &j->gen.own_ctx;
    }
    if (model_needs != MX_JOB_NO_MODELS && !j->gen.models) {
        mx_job_progress(j, "networks on %s in %s arithmetic (kernels %s)%s", mx_texture_opts_device_name(o),
                        ctx_precision_name(j->gen.ctx), ctx_kernels_name(j->gen.ctx),
                        !on_cuda(j->gen.ctx) && mx_isa_precision(j->gen.ctx->k->isa) != mx_texture_opts_precision(o)
                            ? ": bf16 is not available on this CPU"
                            : "");
        if (mx_models_load(&j->gen.own_models, j->gen.ctx, o->weights_path, model_needs, st)) return -1;
        j->gen.own_models_ready = 1;
        j->gen.models = &j->gen.own_models;
        if (j->gen.own_ctx_ready && mx_models_pack_weights(&j->gen.own_ctx, st)) return -1;
        mx_job_progress(j, "loaded weights %s%s", o->weights_path, o->pub.fast ? " (fast: LCM + TAESD)" : "");
    }
    if (model_needs == MX_JOB_NO_MODELS) j->gen.models = NULL;
    else if (mx_models_check(j->gen.models, model_needs, st) || (o->pub.fast && check_fast_models(j, st)) ||
             encode_style(j, st))
        return -1;
    if (mx_job_check_cancel(j, st)) return -1;
    if (o->mesh ? mx_mesh_validate(o->mesh, st) || mx_mesh_clone(o->mesh, &j->mesh, st)
                : mx_mesh_load(o->pub.mesh_path, &j->mesh, st))
        return -1;
    if (prepare_uvs(j, need_uvs, st) || mx_job_check_cancel(j, st)) return -1;
    if (mx_mesh_normalized(&j->mesh, mx_texture_opts_up(o), &j->pos, j->center, &j->scale, st)) return -1;
    if (mx_bake_init(&j->bake, o->pub.texture_size, o->pub.texture_size, j->nlayers, st)) return -1;
    j->bake_ready = 1;
    warn_render_size(o);
    if (build_candidates(j, st) || build_chart(j, st) || mx_job_check_cancel(j, st) ||
        (j->gen.models && (encode_negative(j, st) || (j->o->pub.prompt && warn_if_truncated(j, "prompt", j->o->pub.prompt, st)))))
        return -1;
    mx_job_progress(j, "mesh %s: %d faces, %d texture(s), %d candidate views", j->mesh.source_path, j->mesh.nfaces,
                    j->nlayers, o->pub.candidates);
    report_header(j);
    mx_job_stage_done(j, "load", mx_now() - j->rep.t0);
    return 0;
}

void mx_job_close(mx_job *j) {
    mx_outdir_discard(&j->out);
    for (int i = 0; i < j->gen.prompts.n; i++) {
        free(j->gen.prompts.text[i]);
        free(j->gen.prompts.emb[i]);
    }
    free(j->gen.uncond);
    mx_style_free(&j->gen.style);
    free(j->sched.visible);
    free(j->sched.chart);
    if (j->sched.schedule_ready) mx_view_schedule_free(&j->sched.schedule);
    if (j->sched.vc_ready) mx_view_cache_free(&j->sched.vc);
    if (j->bake_ready) mx_bake_free(&j->bake);
    free(j->pos);
    mx_mesh_free(&j->mesh);
    if (j->gen.own_models_ready) mx_models_free(&j->gen.own_models);
    if (j->gen.own_ctx_ready) mx_ctx_destroy(&j->gen.own_ctx);
    mx_jw_free(&j->rep.json);
    memset(j, 0, sizeof *j);
}

/* Cached CLIP embedding of a prompt ([77][C], owned by the cache). */
static const float *prompt_embedding(mx_job *j, const char *text, mx_status *st) {
    mx_prompt_cache *pc = &j->gen.prompts;
    for (int i = 0; i < pc->n; i++)
        if (!strcmp(pc->text[i], text)) return pc->emb[i];
    if (pc->n == MX_JOB_MAX_PROMPTS) {
        free(pc->text[0]);
        free(pc->emb[0]);
        memmove(pc->text, pc->text + 1, sizeof(pc->text[0]) * (MX_JOB_MAX_PROMPTS - 1));
        memmove(pc->emb, pc->emb + 1, sizeof(pc->emb[0]) * (MX_JOB_MAX_PROMPTS - 1));
        pc->n--;
    }
    size_t floats = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    float *emb = malloc(floats * sizeof *emb);
    char *copy = strdup(text);
    int dropped = 0;
    if (!emb || !copy || mx_models_encode_text(j->gen.models, j->gen.ctx, text, emb, &dropped, st)) {
        free(emb);
        free(copy);
        if (!st->msg[0]) mx_fail(st, MX_ENOMEM, "prompt embeddings: out of memory");
        return NULL;
    }
    if (dropped && warn_if_truncated(j, "view prompt", text, st)) {
        free(emb);
        free(copy);
        return NULL;
    }
    pc->text[pc->n] = copy;
    pc->emb[pc->n] = emb;
    return pc->emb[pc->n++];
}

/* After each denoising step: the progress line and event; non-zero stops the loop. */
static int report_step(void *user, int step, int n_steps, int64_t timestep) {
    mx_job *j = user;
    char line[160];
    snprintf(line, sizeof line, "%s: step %d/%d (t=%lld)", j->rep.phase, step + 1, n_steps, (long long)timestep);
    if (!!j->o->pub.verbose) fprintf(stderr, "matex: [%7.2fs] %s\n", mx_now() - j->rep.t0, line);
    emit_progress(j, step + 1, n_steps, line);
    return j->rep.stop || (j->o->pub.cancel && *j->o->pub.cancel);
}

/* Embeddings of every item, cond and uncond, [n][77][C]. */
static int batch_embeddings(mx_job *j, const mx_gen_batch *b, float *cond, float *uncond, mx_status *st) {
    size_t per = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    for (int i = 0; i < b->n; i++) {
        const float *e = prompt_embedding(j, b->prompts[i], st);
        if (!e) return -1;
        memcpy(cond + i * per, e, per * sizeof *e);
        memcpy(uncond + i * per, j->gen.uncond, per * sizeof *e);
    }
    return 0;
}

/* Runs the denoising of a batch from seeded noise (item i: stream first_stream + i): plain
 * text-to-image, or the inpaint / img2img pipeline when the batch has init images. */
static int denoise_batch(mx_job *j, const mx_gen_batch *b, mx_sd_request *rq, float *lat, float *noise,
                         size_t per_item, int h, int w, mx_status *st) {
    for (int i = 0; i < b->n; i++)
        mx_rng_fill_normal(noise + i * per_item, per_item, j->o->pub.seed, b->first_stream + (uint64_t)i, 0);
    if (!b->init_images) {
        memcpy(lat, noise, per_item * b->n * sizeof *lat);
        mx_sched_scale_initial(rq->sched, lat, per_item * b->n);
        return mx_sd_denoise(rq, j->gen.ctx, lat, b->n, h, w, st);
    }
    mx_sd_edit e = {.vae = j->gen.models->vae,
                    .image = b->init_images,
                    .mask = b->paint_masks,
                    .noise = noise,
                    .strength = b->strength,
                    .taesd = j->o->pub.fast ? j->gen.models->taesd : NULL};
    return mx_sd_edit_run(rq, &e, j->gen.ctx, b->n, h, w, lat, st);
}

/* LCM step noise: item i draws from its own stream (first_stream + i) after its start latents,
 * step k at indices (k + 1) * per_item.., so an item's noise does not depend on its batch. */
typedef struct lcm_noise {
    uint64_t seed, first_stream;
    int n;
    size_t per_item;
} lcm_noise;

static int fill_lcm_noise(void *user, int step, float *noise, size_t numel) {
    const lcm_noise *z = user;
    if (numel != z->per_item * (size_t)z->n) return -1;
    for (int i = 0; i < z->n; i++)
        mx_rng_fill_normal(noise + i * z->per_item, z->per_item, z->seed, z->first_stream + (uint64_t)i,
                           (uint64_t)(step + 1) * z->per_item);
    return 0;
}

static int decode_images(mx_job *j, const float *lat, int n, int h, int w, float *images, mx_status *st) {
    if (j->o->pub.fast) return mx_taesd_decode_image(j->gen.ctx, j->gen.models->taesd, lat, n, h, w, images, st);
    return mx_vae_decode_image_tiled(j->gen.ctx, j->gen.models->vae, lat, n, h, w, VAE_TILE, images, st);
}

/* The run's style tokens for a diffusion call, the same for every item (NULL without style images). */
static const mx_sd_image_guide *style_guide(const mx_job *j, mx_sd_image_guide *g) {
    const mx_style *s = &j->gen.style;
    if (!s->n) return NULL;
    *g = (mx_sd_image_guide){.adapter = j->gen.models->ip_adapter,
                             .cond = s->tokens,
                             .uncond = s->zero_tokens,
                             .n_tokens = s->ntokens,
                             .per_latent = 0,
                             .scale = s->scale};
    return g;
}

int mx_job_generate(mx_job *j, const mx_gen_batch *b, float *images, mx_status *st) {
    int f = j->o->pub.fast ? mx_taesd_factor(j->gen.models->taesd) : mx_vae_factor(j->gen.models->vae);
    if (b->image_h % f || b->image_w % f)
        return mx_fail(st, MX_EINPUT, "image size %dx%d is not a multiple of the VAE factor %d", b->image_w,
                       b->image_h, f);
    int h = b->image_h / f, w = b->image_w / f;
    size_t per_item = (size_t)4 * h * w, per_text = (size_t)MX_CLIP_CONTEXT * mx_models_text_dim(j->gen.models);
    float *lat = malloc(2 * per_item * b->n * sizeof *lat), *noise = lat + per_item * b->n;
    float *cond = malloc(per_text * b->n * sizeof *cond), *uncond = malloc(per_text * b->n * sizeof *uncond);
    mx_sched s;
    mx_sched_config scfg = j->gen.models->sched;
    lcm_noise lcm = {.seed = j->o->pub.seed, .first_stream = b->first_stream, .n = b->n, .per_item = per_item};
    memset(&s, 0, sizeof s);
    int rc = -1, sched_ready = 0;
    if (j->o->pub.fast) mx_sched_config_lcm(&scfg, &j->gen.models->sched);
    if (!lat || !cond || !uncond) {
        mx_fail(st, MX_ENOMEM, "generation buffers: out of memory");
        goto done;
    }
    if (batch_embeddings(j, b, cond, uncond, st)) goto done;
    if (mx_sched_init(&s, j->gen.ctx, &scfg, j->o->pub.steps, per_item * b->n, st)) goto done;
    sched_ready = 1;
    s.noise_fn = fill_lcm_noise;
    s.noise_user = &lcm;
    mx_sd_control controls[2];
    int nc = 0;
    if (b->depth_planes && j->gen.models->cn_depth && (b->w_depth != 0 || b->w_depth_items))
        controls[nc++] = (mx_sd_control){j->gen.models->cn_depth, b->depth_planes, b->w_depth, b->w_depth_items};
    if (b->inpaint_planes && j->gen.models->cn_inpaint && (b->w_inpaint != 0 || b->w_inpaint_items))
        controls[nc++] = (mx_sd_control){j->gen.models->cn_inpaint, b->inpaint_planes, b->w_inpaint, b->w_inpaint_items};
    mx_job_set_phase(j, b->stage);
    mx_sd_image_guide guide;
    mx_sd_request rq = {.unet = j->gen.models->unet,
                        .controls = controls,
                        .n_controls = nc,
                        .cond_text = cond,
                        .uncond_text = uncond,
                        .T = MX_CLIP_CONTEXT,
                        .guidance = j->o->pub.guidance,
                        .sched = &s,
                        .progress = report_step,
                        .progress_user = j,
                        .image = style_guide(j, &guide)};
    double t = mx_now();
    if (denoise_batch(j, b, &rq, lat, noise, per_item, h, w, st)) {
        mx_job_check_cancel(j, st); /* a stop asked by report_step reads "interrupted" */
        goto done;
    }
    j->rep.last_denoise_s = mx_now() - t;
    j->rep.denoise_s += j->rep.last_denoise_s;
    t = mx_now();
    rc = decode_images(j, lat, b->n, h, w, images, st);
    j->rep.last_decode_s = mx_now() - t;
    j->rep.decode_s += j->rep.last_decode_s;
done:
    if (sched_ready) mx_sched_free(&s);
    free(lat);
    free(cond);
    free(uncond);
    return rc;
}

int mx_job_view_prepare(mx_job *j, mx_job_view *v, mx_status *st) {
    int R = j->o->pub.render_size;
    if (mx_view_buffers_init(&v->vb, R, st)) return -1;
    v->vb_ready = 1;
    if (mx_view_prepare(&v->vb, &j->mesh, j->pos, &v->cam, mx_texture_opts_normals(j->o), j->o->pub.frontal_threshold, j->gen.ctx->pool,
                        st) ||
        mx_view_erode_edges(&v->vb, mx_view_erode_radius(R, j->o->pub.image_size), st))
        return -1;
    uint8_t *fg = malloc((size_t)R * R);
    if (!fg) return mx_fail(st, MX_ENOMEM, "view mask: out of memory");
    mx_mask_foreground(&v->vb.gb, fg);
    v->crop = mx_crop_from_mask(fg, R, R, CROP_MARGIN);
    v->untextured_pixels = mx_mask_count(fg, (int64_t)R * R);
    free(fg);
    return 0;
}

void mx_job_view_free(mx_job_view *v) {
    if (v->vb_ready) mx_view_buffers_free(&v->vb);
    v->vb_ready = 0;
}

int mx_job_current_textures(mx_job *j, mx_image *tex, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (int l = 0; l < j->nlayers; l++)
        if (mx_bake_texture(&j->bake, l, GREY, &tex[l], st) ||
            mx_uv_dilate(&tex[l], j->bake.known + l * plane, CURRENT_DILATE_TEXELS, st)) {
            for (int k = 0; k <= l; k++) mx_image_free(&tex[k]);
            return -1;
        }
    return 0;
}

/* crop + resize of a render to the model size, then into the planes. */
static int place_control(const mx_image *full, mx_crop crop, int S, float *planes, int plane_w, int x0,
                         mx_status *st) {
    mx_image small;
    if (mx_crop_resize(full, crop, S, &small, st)) return -1;
    mx_image_to_planes(&small, planes, plane_w, x0);
    mx_image_free(&small);
    return 0;
}

/* Inpainting inputs of a view at the model size: the render of the current textures I′ (init),
 * the paint mask (untextured pixels, grown to whole latent cells) and the inpaint control (I′
 * with the painted pixels at -1). */
static int inpaint_inputs(mx_job *j, mx_job_view *v, const mx_image *tex, const mx_view_planes *p, mx_status *st) {
    int R = j->o->pub.render_size, S = j->o->pub.image_size, rc = -1;
    mx_image rgb = {0}, mask_img = {0}, rgb_s = {0}, mask_s = {0}, paint = {0}, ctl = {0};
    uint8_t *mask = malloc((size_t)R * R), *open = NULL;
    if (!mask) return mx_fail(st, MX_ENOMEM, "inpainting mask: out of memory");
    const uint8_t *known = j->bake.known;
    if (j->write_flags & MX_BACKPROJECT_OVERWRITE) { /* texels this view will take over are repainted */
        if (!(open = malloc((size_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size))) {
            free(mask);
            return mx_fail(st, MX_ENOMEM, "inpainting mask: out of memory");
        }
        mx_bake_open_texels(&j->bake, &v->vb.gb, &j->mesh, v->vb.mask, open);
        known = open;
    }
    mx_mask_inpaint(&v->vb.gb, &j->mesh, NULL, known, j->o->pub.texture_size, j->o->pub.texture_size, mask);
    free(open);
    v->untextured_pixels = mx_mask_count(mask, (int64_t)R * R);
    if (!mx_render_textured(&v->vb.gb, &j->mesh, tex, j->nlayers, GREY, j->gen.ctx->pool, &rgb, st) &&
        !mx_mask_image(mask, R, R, &mask_img, st) && !mx_crop_resize(&rgb, v->crop, S, &rgb_s, st) &&
        !mx_crop_resize(&mask_img, v->crop, S, &mask_s, st) &&
        !mx_paint_mask_cells(&mask_s, mx_vae_factor(j->gen.models->vae), PAINT_DILATE_CELLS, &paint, st) &&
        !mx_inpaint_image(&rgb_s, &paint, &ctl, st)) {
        mx_image_to_planes(&ctl, p->inpaint, p->plane_w, p->x0);
        if (p->init) mx_image_to_planes(&rgb_s, p->init, p->plane_w, p->x0);
        if (p->paint) mx_image_to_planes(&paint, p->paint, p->plane_w, p->x0);
        rc = 0;
    }
    mx_image_free(&rgb);
    mx_image_free(&mask_img);
    mx_image_free(&rgb_s);
    mx_image_free(&mask_s);
    mx_image_free(&paint);
    mx_image_free(&ctl);
    free(mask);
    return rc;
}

int mx_job_view_controls(mx_job *j, mx_job_view *v, const mx_view_planes *p, const mx_image *current,
                         mx_status *st) {
    mx_image depth;
    if (mx_depth_image(&v->vb.gb, &depth, st)) return -1;
    int rc = place_control(&depth, v->crop, j->o->pub.image_size, p->depth, p->plane_w, p->x0, st);
    mx_image_free(&depth);
    if (rc || !p->inpaint) return rc;
    return inpaint_inputs(j, v, current, p, st);
}

int mx_job_backproject(mx_job *j, mx_job_view *v, const float *planes, int plane_w, int x0, mx_status *st) {
    int R = j->o->pub.render_size, S = j->o->pub.image_size;
    double t = mx_now();
    mx_image gen, canvas;
    if (mx_planes_to_image(planes, 3, S, plane_w, x0, S, &gen, st)) return -1;
    if (mx_image_alloc(&canvas, R, R, 3, st)) {
        mx_image_free(&gen);
        return -1;
    }
    mx_crop_paste(&gen, v->crop, &canvas);
    j->rep.backproject_s += mx_now() - t; /* mx_job_backproject_render adds its own time */
    int rc = mx_job_backproject_render(j, v, &canvas, v->vb.mask, st);
    mx_image_free(&gen);
    mx_image_free(&canvas);
    return rc;
}

int mx_job_backproject_render(mx_job *j, mx_job_view *v, const mx_image *img, const uint8_t *mask, mx_status *st) {
    double t = mx_now();
    int rc = mx_backproject(&j->bake, &v->vb.gb, &j->mesh, img, mask, j->write_flags, j->gen.ctx->pool, st);
    j->rep.backproject_s += mx_now() - t;
    if (rc) return -1;
    j->rep.views_done++;
    emit_progress(j, 0, 0, "view backprojected");
    return 0;
}

void mx_job_stage_done(mx_job *j, const char *name, double seconds) {
    if (j->rep.nstages == (int)(sizeof j->rep.stage_s / sizeof j->rep.stage_s[0])) return;
    j->rep.stage_name[j->rep.nstages] = name;
    j->rep.stage_s[j->rep.nstages++] = seconds;
}

/* Fraction of the texels in `of` (n_of of them) that are in T^B. */
static double painted_fraction(const mx_job *j, const uint8_t *of, int64_t n_of) {
    if (n_of == 0) return 1.0;
    int64_t n = (int64_t)j->nlayers * j->o->pub.texture_size * j->o->pub.texture_size, hit = 0;
    for (int64_t i = 0; i < n; i++) hit += of[i] && j->bake.known[i];
    return (double)hit / (double)n_of;
}

double mx_job_coverage(const mx_job *j) { return painted_fraction(j, j->sched.chart, j->sched.n_chart); }

double mx_job_candidate_coverage(const mx_job *j) {
    return painted_fraction(j, j->sched.visible, j->sched.n_visible);
}

int mx_job_schedule_begin(mx_job *j, int max_batch, mx_status *st) {
    mx_view_schedule_params p = {.budget = j->o->pub.views - 2,
                                 .max_batch = max_batch,
                                 .coverage_stop = j->o->pub.coverage_stop,
                                 .min_gain = MX_JOB_MIN_UNTEXTURED_PIXELS};
    if (mx_view_schedule_init(&j->sched.schedule, &j->sched.vc, &p, st)) return -1;
    j->sched.schedule_ready = 1;
    return 0;
}

int mx_job_schedule_next(mx_job *j, int *cand, int *n, mx_status *st) {
    if (mx_view_schedule_next(&j->sched.schedule, j->bake.known, cand, n, st)) return -1;
    if (*n == 0)
        mx_job_progress(j, "view selection: schedule ended after %d views (budget, coverage or gain floor)",
                        j->rep.views_done);
    return 0;
}

void mx_job_view_prompt(const mx_job *j, mx_job_view *v, int grid) {
    const char *prompt = j->o->pub.prompt ? j->o->pub.prompt : "";
    if (grid)
        snprintf(v->prompt, sizeof v->prompt, "%s %s", j->o->pub.front_back_words, prompt);
    else if (j->gen.models)
        snprintf(v->prompt, sizeof v->prompt, "%s view of %s", mx_camera_view_word(&v->cam), prompt);
    else /* transfer: no prompt, the view word names the view in the report */
        snprintf(v->prompt, sizeof v->prompt, "%s view", mx_camera_view_word(&v->cam));
}

void mx_job_report_view(mx_job *j, const mx_job_view *v, const char *stage, int batch, float w_depth,
                        float w_inpaint) {
    mx_jw *w = &j->rep.json;
    mx_jw_begin_obj(w, NULL);
    mx_jw_str(w, "stage", stage);
    mx_jw_int(w, "batch", batch);
    mx_jw_num(w, "azimuth", v->cam.azimuth);
    mx_jw_num(w, "elevation", v->cam.elevation);
    mx_jw_str(w, "view_word", mx_camera_view_word(&v->cam));
    mx_jw_str(w, "prompt", v->prompt);
    mx_jw_num(w, "depth_weight", w_depth);
    mx_jw_num(w, "inpaint_weight", w_inpaint);
    mx_jw_int(w, "untextured_pixels", v->untextured_pixels);
    mx_jw_num(w, "coverage_after", mx_job_coverage(j));
    mx_jw_num(w, "candidate_coverage_after", mx_job_candidate_coverage(j));
    mx_jw_num(w, "batch_denoise_s", j->rep.last_denoise_s);
    mx_jw_num(w, "batch_decode_s", j->rep.last_decode_s);
    mx_jw_num(w, "time_s", mx_now() - j->rep.t0);
    mx_jw_end_obj(w);
}

/* What the fill of one texture reports: a progress line at most every FILL_TICK_S seconds, and the
 * cancel flag at every tick. */
#define FILL_TICK_S 2.0
typedef struct {
    mx_job *j;
    int layer;
    double last;
} fill_ticks;

static int fill_tick(void *user, double done) {
    fill_ticks *f = user;
    if (mx_now() - f->last >= FILL_TICK_S) {
        mx_job_progress(f->j, "uv fill: texture %d/%d, solve %.0f%%", f->layer + 1, f->j->nlayers, 100 * done);
        f->last = mx_now();
    }
    mx_status ignored;
    return mx_job_check_cancel(f->j, &ignored) != 0;
}

/* Harmonic fill across UV seams of every layer's unreached chart texels, gutter dilation. */
int mx_job_fill_textures(mx_job *j, mx_image *tex, mx_status *st) {
    size_t plane = (size_t)j->o->pub.texture_size * j->o->pub.texture_size;
    for (int l = 0; l < j->nlayers; l++) {
        double t = mx_now();
        int64_t open = 0;
        for (size_t i = 0; i < plane; i++) open += j->sched.chart[l * plane + i] && !j->bake.known[l * plane + i];
        mx_job_progress(j, "uv fill: texture %d/%d, %lld texels to fill (%dx%d)", l + 1, j->nlayers, (long long)open,
                        j->o->pub.texture_size, j->o->pub.texture_size);
        fill_ticks ticks = {.j = j, .layer = l, .last = t};
        mx_uv_fill_ticker ticker = {.tick = fill_tick, .user = &ticks};
        if (mx_uv_fill_harmonic(&tex[l], j->bake.known + l * plane, &j->mesh, l, j->nlayers, UV_GUTTER, &ticker, st))
            return -1;
        mx_job_progress(j, "uv fill: texture %d/%d done in %.1fs", l + 1, j->nlayers, mx_now() - t);
        if (mx_job_check_cancel(j, st)) return -1;
    }
    return 0;
}

/* The in-memory result: its containers are allocated before the folder is published, and the
 * textures, mesh and report are moved in after it, so that nothing can fail once the output exists. */
static int result_reserve(const mx_job *j, const char *report, mx_texture_result *res, mx_status *st) {
    size_t view_bytes = res->view_bytes;
    memset(res, 0, sizeof *res);
    res->view_bytes = view_bytes;
    if (!j->o->keep_outputs) return 0;
    res->textures = calloc((size_t)j->nlayers, sizeof *res->textures);
    res->report_json = strdup(report);
    if (view_bytes) res->views_room = calloc((size_t)j->nlayers, view_bytes);
    if (!res->textures || !res->report_json || (view_bytes && !res->views_room)) {
        mx_texture_result_free(res);
        return mx_fail(st, MX_ENOMEM, "result: out of memory");
    }
    return 0;
}

static void result_fill(mx_job *j, mx_image *tex, mx_texture_result *res) {
    res->coverage = mx_job_coverage(j);
    res->candidate_coverage = mx_job_candidate_coverage(j);
    res->views = j->rep.views_done;
    res->seconds = mx_now() - j->rep.t0;
    if (!j->o->keep_outputs) return;
    res->ntex = j->nlayers;
    for (int l = 0; l < j->nlayers; l++) {
        res->textures[l] = tex[l];
        memset(&tex[l], 0, sizeof tex[l]);
    }
    res->mesh = j->mesh;
    memset(&j->mesh, 0, sizeof j->mesh);
}

/* front.png in the staging folder: the textured mesh from the front, cropped to the object as a view
 * is, image_size pixels on the views' grey (what `matex batch --theme-from-first` passes on). */
static int write_front_render(mx_job *j, const mx_image *tex, mx_status *st) {
    mx_job_view v;
    memset(&v, 0, sizeof v);
    mx_job_camera(&v.cam, 0.0f, 0.0f);
    mx_image rgb = {0}, small = {0};
    char path[4300];
    int rc = mx_job_view_prepare(j, &v, st) ||
             mx_render_textured(&v.vb.gb, &j->mesh, tex, j->nlayers, GREY, j->gen.ctx->pool, &rgb, st) ||
             mx_crop_resize(&rgb, v.crop, j->o->pub.image_size, &small, st) ||
             mx_path_join(path, sizeof path, j->out.stage, "front.png", st) || mx_io_write_png(path, &small, st);
    mx_image_free(&rgb);
    mx_image_free(&small);
    mx_job_view_free(&v);
    return rc ? -1 : 0;
}

int mx_job_finish(mx_job *j, mx_image *tex, mx_texture_result *res, mx_status *st) {
    double t = mx_now();
    mx_job_set_phase(j, "finish");
    if (mx_job_check_cancel(j, st) || (!j->keep_unreached && mx_job_fill_textures(j, tex, st))) return -1;
    mx_jw *w = &j->rep.json;
    mx_jw_end_arr(w); /* views */
    mx_jw_num(w, "coverage", mx_job_coverage(j));
    mx_jw_num(w, "candidate_coverage", mx_job_candidate_coverage(j));
    mx_jw_int(w, "views_generated", j->rep.views_done);
    if (!isnan(j->rep.psnr_db)) mx_jw_num(w, "psnr_db", j->rep.psnr_db);
    mx_job_stage_done(j, "uv_fill", mx_now() - t);
    mx_jw_begin_obj(w, "stages_s");
    for (int i = 0; i < j->rep.nstages; i++) mx_jw_num(w, j->rep.stage_name[i], j->rep.stage_s[i]);
    mx_jw_end_obj(w);
    mx_jw_begin_obj(w, "work_s"); /* inside grid and views: the networks and the backprojection */
    mx_jw_num(w, "denoise", j->rep.denoise_s);
    mx_jw_num(w, "decode", j->rep.decode_s);
    mx_jw_num(w, "backproject", j->rep.backproject_s);
    mx_jw_end_obj(w);
    mx_jw_num(w, "total_s", mx_now() - j->rep.t0);
    mx_jw_end_obj(w);
    const char *text = mx_jw_text(w);
    if (!text) return mx_fail(st, MX_ENOMEM, "report: out of memory");
    if (mx_job_check_cancel(j, st) || (res && result_reserve(j, text, res, st))) return -1;
    if (j->o->pub.out_dir && j->o->pub.front_render && write_front_render(j, tex, st)) {
        if (res) mx_texture_result_free(res);
        return -1;
    }
    if (j->o->pub.out_dir && mx_outdir_commit(&j->out, &j->mesh, tex, j->nlayers, text, j->o->pub.cancel, st)) {
        if (res) mx_texture_result_free(res);
        return -1;
    }
    if (j->o->pub.out_dir)
        mx_job_progress(j, "wrote %s (coverage %.4f of the mesh's texels, %.4f of the candidates', %d views)",
                        j->o->pub.out_dir, mx_job_coverage(j), mx_job_candidate_coverage(j), j->rep.views_done);
    if (res) result_fill(j, tex, res);
    return 0;
}

void mx_texture_result_free(mx_texture_result *res) {
    if (!res) return;
    for (int l = 0; l < res->ntex; l++) mx_image_free(&res->textures[l]);
    free(res->textures);
    free(res->report_json);
    free(res->views_room);
    mx_mesh_free(&res->mesh);
    memset(res, 0, sizeof *res);
}
