/* The embedding API (include/matex.h) over the texturing pipeline: model sets opened once
 * (mx_models), public options checked against the option table (options.c) and translated into
 * mx_texture_opts, meshes in memory viewed as an
 * mx_mesh (the job copies them), results moved out of the job (mx_texture_result). */
#include "../../include/matex.h"

#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../runtime/version.h"
#include "../geom/masks.h"
#include "job.h"
#include "models.h"
#include "options.h"
#include "outdir.h"
#include "style.h"

/* Errors pass through unchanged: the public codes are the status codes. */
_Static_assert((int)MATEX_EINPUT == (int)MX_EINPUT && (int)MATEX_EUSAGE == (int)MX_EUSAGE &&
                   (int)MATEX_EIO == (int)MX_EIO && (int)MATEX_ENOMEM == (int)MX_ENOMEM &&
                   (int)MATEX_EINTERNAL == (int)MX_EINTERNAL && (int)MATEX_ECANCELLED == (int)MX_ECANCEL,
               "matex.h error codes");

/* A model set computes on its own context (device, threads, precision): the networks' weights
 * live on its backend, and every run with the set uses it. */
struct matex_models {
    mx_ctx ctx;
    int ctx_ready;
    mx_models m;
};

/* A result as handed out: the public view over the pipeline's result. */
typedef struct api_result {
    matex_result pub;
    mx_texture_result in;
} api_result;

/* The library's version (runtime/version.h); test_texture_api checks that the header's MATEX_VERSION agrees. */
const char *matex_version(void) { return MX_VERSION; }

static void clear_error(matex_error *err) {
    if (!err) return;
    err->code = MATEX_OK;
    err->message[0] = 0;
}

static void set_error(matex_error *err, int code, const char *msg) {
    if (!err) return;
    err->code = code;
    snprintf(err->message, sizeof err->message, "%s", msg);
}

/* The public options as a run's (pointers borrowed; negative prompt and grid words NULL: the defaults). */
static void run_options(const matex_options *o, mx_texture_opts *t) {
    memset(t, 0, sizeof *t);
    t->pub = *o;
    matex_options d;
    matex_options_default(&d);
    if (!t->pub.negative_prompt) t->pub.negative_prompt = d.negative_prompt;
    if (!t->pub.front_back_words) t->pub.front_back_words = d.front_back_words;
}

/* A model set's own options: the device, threads and precision its context computes with. */
static int check_model_options(const matex_options *o, mx_status *st) {
    static const char *const names[] = {"device", "threads", "precision"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (mx_option_check(mx_option_find(names[i], MX_VERB_TEXTURE), o, st)) return -1;
    mx_backend_kind kind;
    return o->device ? mx_backend_parse(o->device, &kind, st) : 0;
}

matex_models *matex_models_open(const char *weights_path, const matex_options *o, matex_error *err) {
    clear_error(err);
    mx_status st;
    mx_status_clear(&st);
    matex_options defaults;
    if (!o) {
        matex_options_default(&defaults);
        o = &defaults;
    }
    mx_texture_opts t;
    matex_models *m = calloc(1, sizeof *m);
    if (!m) {
        set_error(err, MATEX_ENOMEM, "out of memory");
        return NULL;
    }
    if (!weights_path) {
        mx_fail(&st, MX_EUSAGE, "no weight file given");
    } else if (!check_model_options(o, &st)) {
        run_options(o, &t);
        m->ctx_ready = !mx_job_ctx_create(&m->ctx, &t, &st);
        if (m->ctx_ready && !mx_models_load(&m->m, &m->ctx, weights_path, 0, &st)) {
            if (!mx_models_pack_weights(&m->ctx, &st)) return m;
            mx_models_free(&m->m);
        }
    }
    set_error(err, st.code, st.msg);
    matex_models_close(m);
    return NULL;
}

int matex_models_has_network(const matex_models *m, const char *name) {
    return m && name && mx_models_has_kind(&m->m, name);
}

void matex_models_close(matex_models *m) {
    if (!m) return;
    if (m->m.wf) mx_models_free(&m->m);
    if (m->ctx_ready) mx_ctx_destroy(&m->ctx);
    free(m);
}

/* An mx_mesh that views the caller's arrays (never freed, never written: the job copies it). */
typedef struct mesh_view {
    mx_mesh mesh;
    mx_material *mats;
    mx_image *textures;
} mesh_view;

static int view_mesh(const matex_options *o, mesh_view *v, mx_status *st) {
    memset(v, 0, sizeof *v);
    const matex_mesh *in = o->mesh;
    int nmat = in->face_materials && in->nmaterials > 0 ? in->nmaterials : 1;
    v->mats = calloc((size_t)nmat, sizeof *v->mats);
    v->textures = o->mesh_textures ? calloc((size_t)nmat, sizeof *v->textures) : NULL;
    if (!v->mats || (o->mesh_textures && !v->textures)) return mx_fail(st, MX_ENOMEM, "mesh in memory: out of memory");
    for (int i = 0; i < nmat; i++) snprintf(v->mats[i].name, sizeof v->mats[i].name, "material_%d", i);
    for (int i = 0; v->textures && i < nmat; i++) {
        const matex_image *t = &o->mesh_textures[i];
        v->textures[i] = (mx_image){t->width, t->height, t->channels, t->pixels};
    }
    mx_mesh *m = &v->mesh;
    m->nverts = in->nverts;
    m->nfaces = in->nfaces;
    m->pos = (float *)in->positions;
    m->faces = (int32_t *)in->faces;
    m->nuv = in->uvs && in->face_uvs ? in->nuvs : 0;
    m->uv = m->nuv ? (float *)in->uvs : NULL;
    m->face_uv = m->nuv ? (int32_t *)in->face_uvs : NULL;
    m->nmat = nmat;
    m->mats = v->mats;
    m->face_mat = nmat > 1 ? (int32_t *)in->face_materials : NULL;
    snprintf(m->source_path, sizeof m->source_path, "mesh in memory");
    if (!m->pos || !m->faces) return mx_fail(st, MX_EINPUT, "mesh in memory: no positions or faces");
    return 0;
}

static void result_view(api_result *r) {
    const mx_texture_result *in = &r->in;
    matex_result *p = &r->pub;
    p->coverage = in->coverage;
    p->views = in->views;
    p->seconds = in->seconds;
    p->mesh = (matex_mesh){in->mesh.nverts, in->mesh.nfaces, in->mesh.pos, in->mesh.faces, in->mesh.nuv, in->mesh.uv,
                           in->mesh.face_uv, in->ntex > 1 ? in->mesh.face_mat : NULL, in->ntex};
    p->ntextures = in->ntex;
    p->report_json = in->report_json;
    for (int i = 0; i < in->ntex; i++) {
        const mx_image *t = &in->textures[i];
        p->textures[i] = (matex_image){t->w, t->h, t->c, t->data};
    }
}

/* Forwards the pipeline's progress events (user: the public options). */
static int forward_progress(void *user, const mx_texture_progress *p) {
    const matex_options *o = user;
    matex_progress q = {p->stage, p->step, p->steps, p->views_done, p->views_total, p->coverage, p->seconds, p->message};
    return o->progress(o->progress_user, &q);
}

typedef int (*pipeline_fn)(const mx_texture_opts *, mx_texture_result *, mx_status *);

/* The side a generated image must be a multiple of for these networks: the decoder's factor
 * (image -> latent) times 2^(levels-1) (the UNet halves the latent at each level but the last). */
static int image_step(const mx_models *m, int fast) {
    int factor = fast && m->taesd ? mx_taesd_factor(m->taesd) : mx_vae_factor(m->vae);
    return factor << (mx_unet_cfg(m->unet)->nlevels - 1);
}

/* The options against the table and, for runs with networks, the style images' files and the image
 * size and style images against the networks: before any work. */
static int check_options(const matex_models *m, const matex_options *o, unsigned verb, mx_status *st) {
    if (mx_options_check(o, verb, st)) return -1;
    if (verb == MX_VERB_TRANSFER) return 0;
    if (!m) return mx_fail(st, MX_EUSAGE, "no model set given");
    if (mx_style_check_inputs(o, st)) return -1;
    if ((o->style_images[0] || o->n_style_pixels) && mx_style_check_models(&m->m, st)) return -1;
    return mx_options_check_image_size(o->image_size, image_step(&m->m, o->fast), st);
}

static int run(pipeline_fn fn, unsigned verb, matex_models *m, const matex_options *o, matex_result **result,
               matex_error *err) {
    clear_error(err);
    if (result) *result = NULL;
    if (!o) {
        set_error(err, MATEX_EUSAGE, "no options given");
        return -1;
    }
    mx_status st;
    mx_status_clear(&st);
    mx_texture_opts t;
    if (check_options(m, o, verb, &st)) {
        set_error(err, st.code, st.msg);
        return -1;
    }
    run_options(o, &t);
    t.models = m ? &m->m : NULL;
    if (o->progress) {
        t.progress = forward_progress;
        t.progress_user = (void *)o;
    }
    mesh_view mv;
    memset(&mv, 0, sizeof mv);
    api_result *r = NULL;
    int rc = o->mesh ? view_mesh(o, &mv, &st) : 0;
    if (!rc && o->mesh) {
        t.mesh = &mv.mesh;
        t.mesh_textures = mv.textures;
    }
    if (!rc && result) {
        t.keep_outputs = 1;
        r = calloc(1, sizeof *r);
        if (!r) rc = mx_fail(&st, MX_ENOMEM, "out of memory");
    }
    if (r) r->in.view_bytes = sizeof *r->pub.textures; /* the public views, reserved by the run */
    if (!rc) rc = fn(&t, r ? &r->in : NULL, &st);
    if (!rc && r) r->pub.textures = r->in.views_room;
    free(mv.mats);
    free(mv.textures);
    if (rc) {
        set_error(err, st.code, st.msg);
        if (r) matex_result_free(&r->pub);
        return -1;
    }
    if (r) {
        result_view(r);
        *result = &r->pub;
    }
    return 0;
}

int matex_texture(matex_models *m, const matex_options *o, matex_result **result, matex_error *err) {
    return run(mx_texture_run, MX_VERB_TEXTURE, m, o, result, err);
}

int matex_enhance(matex_models *m, const matex_options *o, matex_result **result, matex_error *err) {
    return run(mx_enhance_run, MX_VERB_ENHANCE, m, o, result, err);
}

int matex_transfer(matex_models *m, const matex_options *o, matex_result **result, matex_error *err) {
    return run(mx_transfer_run, MX_VERB_TRANSFER, m, o, result, err);
}

int matex_result_write(const matex_result *r, const char *out_dir, int force, matex_error *err) {
    clear_error(err);
    if (!r || !out_dir) {
        set_error(err, MATEX_EUSAGE, "no result or no output folder given");
        return -1;
    }
    const api_result *a = (const api_result *)r; /* pub is the first member */
    mx_status st;
    mx_status_clear(&st);
    mx_outdir od;
    memset(&od, 0, sizeof od);
    int rc = mx_outdir_open(&od, out_dir, force, NULL, 0, &st) ||
             mx_outdir_commit(&od, &a->in.mesh, a->in.textures, a->in.ntex, a->in.report_json, NULL, &st);
    mx_outdir_discard(&od);
    if (rc) set_error(err, st.code, st.msg);
    return rc ? -1 : 0;
}

void matex_result_free(matex_result *r) {
    if (!r) return;
    api_result *a = (api_result *)r;
    mx_texture_result_free(&a->in); /* pub.textures is its views_room */
    free(a);
}
