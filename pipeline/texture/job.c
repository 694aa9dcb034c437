#include "job.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/log.h"
#include "../geom/uvfill.h"
#include "../io/mesh_load.h"

#define SCRATCH_BYTES ((size_t)64 << 20)

const float mx_job_grey[3] = {0.5f, 0.5f, 0.5f};

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

/* A render coarser than the texture leaves texels between a view's pixels: they are filled from
 * their neighbours (backproject.h), and texels no view reaches are filled, not painted. */
static void warn_render_size(const mx_texture_opts *o) {
    if (o->pub.render_size < o->pub.texture_size)
        mx_warn("render size %d is below the texture size %d: a view's pixels are sparser than the texels, so "
                "texels between them are interpolated and fine ones may stay unseen (--render-size %d matches)",
                o->pub.render_size, o->pub.texture_size, o->pub.texture_size);
}

int mx_job_open(mx_job *j, const mx_texture_opts *o, int model_needs, unsigned verb, mx_status *st) {
    memset(j, 0, sizeof *j);
    j->o = o;
    j->verb = verb;
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
                        mx_job_ctx_precision_name(j->gen.ctx), mx_job_ctx_kernels_name(j->gen.ctx),
                        !mx_job_ctx_on_cuda(j->gen.ctx) && mx_isa_precision(j->gen.ctx->k->isa) != mx_texture_opts_precision(o)
                            ? ": bf16 is not available on this CPU"
                            : "");
        double t_load = mx_now();
        if (mx_models_load(&j->gen.own_models, j->gen.ctx, o->weights_path, model_needs, st)) return -1;
        j->gen.own_models_ready = 1;
        j->gen.models = &j->gen.own_models;
        if (j->gen.own_ctx_ready && mx_models_pack_weights(&j->gen.own_ctx, st)) return -1;
        j->rep.load_s = mx_now() - t_load;
        mx_job_progress(j, "loaded weights %s%s", o->weights_path, o->pub.fast ? " (fast: LCM + TAESD)" : "");
    }
    if (model_needs == MX_JOB_NO_MODELS) j->gen.models = NULL;
    else if (mx_models_check(j->gen.models, model_needs, st) || (o->pub.fast && mx_job_check_fast_models(j, st)) ||
             mx_job_encode_style(j, st))
        return -1;
    if (mx_job_check_cancel(j, st)) return -1;
    if (o->mesh ? mx_mesh_validate(o->mesh, st) || mx_mesh_clone(o->mesh, &j->mesh, st)
                : mx_mesh_load(o->pub.mesh_path, &j->mesh, st))
        return -1;
    if (prepare_uvs(j, verb == MX_VERB_ENHANCE, st) || mx_job_check_cancel(j, st)) return -1;
    if (mx_mesh_normalized(&j->mesh, mx_texture_opts_up(o), &j->pos, j->center, &j->scale, st)) return -1;
    if (mx_bake_init(&j->bake, o->pub.texture_size, o->pub.texture_size, j->nlayers, st)) return -1;
    j->bake_ready = 1;
    warn_render_size(o);
    if (mx_job_build_candidates(j, st) || mx_job_build_chart(j, st) || mx_job_check_cancel(j, st) ||
        (j->gen.models && (mx_job_encode_negative(j, st) || (j->o->pub.prompt && mx_job_warn_if_truncated(j, "prompt", j->o->pub.prompt, st)))))
        return -1;
    mx_job_progress(j, "mesh %s: %d faces, %d texture(s), %d candidate views", j->mesh.source_path, j->mesh.nfaces,
                    j->nlayers, o->pub.candidates);
    mx_job_report_header(j);
    mx_job_stage_done(j, "load", mx_now() - j->rep.t0);
    return 0;
}

void mx_job_close(mx_job *j) {
    mx_outdir_discard(&j->out);
    mx_job_gen_free(&j->gen);
    free(j->sched.visible);
    free(j->sched.chart);
    if (j->sched.schedule_ready) mx_view_schedule_free(&j->sched.schedule);
    if (j->sched.vc_ready) mx_view_cache_free(&j->sched.vc);
    if (j->bake_ready) mx_bake_free(&j->bake);
    free(j->pos);
    mx_mesh_free(&j->mesh);
    mx_jw_free(&j->rep.json);
    memset(j, 0, sizeof *j);
}
