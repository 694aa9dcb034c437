/* Style images of a run (style.h): checked before any work, read, digested, encoded once. */
#include "style.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../io/io.h"
#include "../nn/clip_image.h"
#include "digest.h"
#include "models.h"

/* The files of o's list (the table checked that it ends at its first NULL). */
static int count_files(const matex_options *o) {
    int n = 0;
    while (n < MATEX_MAX_STYLE_IMAGES && o->style_images[n]) n++;
    return n;
}

static uint32_t be16(const unsigned char *p) { return (uint32_t)p[0] << 8 | p[1]; }
static uint32_t be32(const unsigned char *p) { return be16(p) << 16 | be16(p + 2); }

/* The size a JPEG declares in its first SOF segment (the segments before it skipped by their
 * lengths); 0 when none is found (the reader then judges the file). */
static void jpeg_size(FILE *f, int64_t *w, int64_t *h) {
    unsigned char seg[9];
    if (fseek(f, 2, SEEK_SET)) return;
    for (int guard = 0; guard < 4096 && fread(seg, 1, 4, f) == 4 && seg[0] == 0xFF; guard++) {
        int marker = seg[1];
        long len = (long)be16(seg + 2);
        int sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
        if (sof) {
            if (fread(seg + 4, 1, 5, f) == 5) *h = be16(seg + 5), *w = be16(seg + 7);
            return;
        }
        if (len < 2 || fseek(f, len - 2, SEEK_CUR)) return;
    }
}

/* What the first bytes of a style image file say: its kind ("PNG", "JPEG", "TIFF" or NULL) and,
 * for PNG and JPEG, the declared size (0 when unknown). */
static const char *probe_image(FILE *f, int64_t *w, int64_t *h) {
    unsigned char head[24] = {0};
    size_t n = fread(head, 1, sizeof head, f);
    *w = *h = 0;
    if (n >= 24 && !memcmp(head, "\x89PNG\r\n\x1a\n", 8) && !memcmp(head + 12, "IHDR", 4)) {
        *w = be32(head + 16);
        *h = be32(head + 20);
        return "PNG";
    }
    if (n >= 3 && head[0] == 0xFF && head[1] == 0xD8 && head[2] == 0xFF) {
        jpeg_size(f, w, h);
        return "JPEG";
    }
    if (n >= 4 && (!memcmp(head, "II*\0", 4) || !memcmp(head, "MM\0*", 4))) return "TIFF";
    return NULL;
}

static int too_many_pixels(const char *what, int64_t w, int64_t h, mx_status *st) {
    if (w * h <= MX_STYLE_MAX_PIXELS) return 0;
    return mx_fail(st, MX_EINPUT,
                   "%s: style image of %lldx%lld pixels is too large (at most %lld pixels, e.g. 5000x5000; the "
                   "encoder sees 224x224 of it: make it smaller)",
                   what, (long long)w, (long long)h, (long long)MX_STYLE_MAX_PIXELS);
}

static int check_file(const char *path, mx_status *st) {
    struct stat sb;
    if (stat(path, &sb)) return mx_fail(st, MX_EINPUT, "%s: cannot open style image: %s", path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return mx_fail(st, MX_EINPUT, "%s: style image is not a regular file", path);
    if (sb.st_size == 0) return mx_fail(st, MX_EINPUT, "%s: style image is empty (0 bytes)", path);
    if (sb.st_size > MX_STYLE_MAX_FILE_BYTES)
        return mx_fail(st, MX_EINPUT, "%s: style image file of %lld bytes is too large (at most %lld MiB)", path,
                       (long long)sb.st_size, (long long)(MX_STYLE_MAX_FILE_BYTES >> 20));
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open style image: %s", path, strerror(errno));
    int64_t w, h;
    const char *kind = probe_image(f, &w, &h);
    fclose(f);
    if (!kind) return mx_fail(st, MX_EINPUT, "%s: style image is not an image (a PNG, JPEG or TIFF file)", path);
    return too_many_pixels(path, w, h, st);
}

static int check_memory_image(const matex_image *im, int i, mx_status *st) {
    if (im->width <= 0 || im->height <= 0 || !im->pixels)
        return mx_fail(st, MX_EUSAGE, "style image %d in memory: no pixels (%dx%d)", i, im->width, im->height);
    if (im->channels != 1 && im->channels != 3 && im->channels != 4)
        return mx_fail(st, MX_EUSAGE, "style image %d in memory: %d channels (1, 3 or 4)", i, im->channels);
    char what[64];
    snprintf(what, sizeof what, "style image %d in memory", i);
    return too_many_pixels(what, im->width, im->height, st);
}

int mx_style_check_inputs(const matex_options *o, mx_status *st) {
    int files = count_files(o);
    if (o->n_style_pixels < 0 || (o->n_style_pixels > 0 && !o->style_pixels))
        return mx_fail(st, MX_EUSAGE, "n_style_pixels is %d with style_pixels %s", o->n_style_pixels,
                       o->style_pixels ? "set" : "NULL");
    if (files + o->n_style_pixels > MATEX_MAX_STYLE_IMAGES)
        return mx_fail(st, MX_EUSAGE, "%d style images (%d files, %d in memory): at most %d", files + o->n_style_pixels,
                       files, o->n_style_pixels, MATEX_MAX_STYLE_IMAGES);
    for (int i = 0; i < files; i++)
        if (check_file(o->style_images[i], st)) return -1;
    for (int i = 0; i < o->n_style_pixels; i++)
        if (check_memory_image(&o->style_pixels[i], i, st)) return -1;
    return 0;
}

/* A copy of an image in memory, with the digest of its pixels. */
static int copy_memory_image(mx_style *s, const matex_image *im, mx_status *st) {
    mx_image *d = &s->img[s->n];
    size_t bytes = sizeof(float) * (size_t)im->width * im->height * im->channels;
    if (mx_image_alloc(d, im->width, im->height, im->channels, st)) return -1;
    memcpy(d->data, im->pixels, bytes);
    snprintf(s->digest[s->n], sizeof s->digest[0], "%016llx", (unsigned long long)mx_digest64(im->pixels, bytes));
    s->n++;
    return 0;
}

int mx_style_load(mx_style *s, const matex_options *o, mx_status *st) {
    memset(s, 0, sizeof *s);
    s->scale = o->style_scale;
    if (mx_style_check_inputs(o, st)) return -1;
    for (int i = 0; i < count_files(o); i++) {
        const char *path = o->style_images[i];
        if (mx_io_read_image(path, &s->img[s->n], st)) return mx_fail_prefix(st, "style image");
        s->path[s->n] = path;
        mx_file_digest_hex(NULL, path, s->digest[s->n]);
        s->n++;
        if (too_many_pixels(path, s->img[s->n - 1].w, s->img[s->n - 1].h, st)) return -1;
    }
    for (int i = 0; i < o->n_style_pixels; i++)
        if (copy_memory_image(s, &o->style_pixels[i], st)) return -1;
    return 0;
}

void mx_style_report(const mx_style *s, mx_jw *w) {
    if (!s->n) return;
    mx_jw_begin_arr(w, "style_images");
    for (int i = 0; i < s->n; i++) {
        mx_jw_begin_obj(w, NULL);
        mx_jw_str(w, "source", s->path[i] ? s->path[i] : "memory");
        mx_jw_str(w, "digest", s->digest[i]);
        mx_jw_int(w, "width", s->img[i].w);
        mx_jw_int(w, "height", s->img[i].h);
        mx_jw_end_obj(w);
    }
    mx_jw_end_arr(w);
    mx_jw_num(w, "style_scale", round(s->scale * 1e6) / 1e6); /* as given, not its float's digits (0.600000024) */
}

void mx_style_free(mx_style *s) {
    for (int i = 0; i < s->n; i++) mx_image_free(&s->img[i]);
    free(s->tokens);
    free(s->zero_tokens);
    memset(s, 0, sizeof *s);
}

int mx_style_check_models(const mx_models *m, mx_status *st) {
    if (m->image_encoder && m->ip_adapter) return 0;
    return mx_fail(st, MX_EINPUT,
                   "%s: a style image needs the image encoder and the IP-Adapter in the weight file; this one has %s. "
                   "Add them with: matex convert SD15_DIR --controlnet depth=DIR --controlnet inpaint=DIR "
                   "--image-encoder IMAGE_ENCODER_DIR --ip-adapter ip-adapter_sd15.safetensors -o W.mxw (README, Style images)",
                   mx_models_path(m), !m->image_encoder && !m->ip_adapter ? "neither"
                                      : !m->image_encoder            ? "no image_encoder.*"
                                                                     : "no ip_adapter.*");
}

/* 8-bit code values of an image as read ([0, 1] = code / 255, io.h), what PIL holds. */
static uint8_t *code_values(const mx_image *im, mx_status *st) {
    size_t n = (size_t)im->w * im->h * im->c;
    uint8_t *u = malloc(n);
    if (!u) return mx_fail(st, MX_ENOMEM, "style image: out of memory"), NULL;
    for (size_t i = 0; i < n; i++) {
        float v = im->data[i] * 255.0f + 0.5f;
        u[i] = (uint8_t)(v < 0.0f ? 0.0f : v > 255.0f ? 255.0f : v);
    }
    return u;
}

/* pixel_values [n, 3, S, S] of the images: CLIP's preprocessing (the model set's, S its size). */
static int preprocess(const mx_style *s, const mx_clip_image_config *pc, float *pixels, mx_status *st) {
    size_t per = (size_t)3 * pc->size * pc->size;
    for (int i = 0; i < s->n; i++) {
        const mx_image *im = &s->img[i];
        uint8_t *u = code_values(im, st);
        int rc = !u || mx_clip_image_preprocess(u, im->w, im->h, im->c, pc->size, pc->mean, pc->std, pixels + i * per, st);
        free(u);
        if (rc) return mx_fail_prefix(st, "%s", s->path[i] ? s->path[i] : "style image in memory");
    }
    return 0;
}

int mx_style_encode(mx_style *s, const mx_models *m, const mx_ctx *c, mx_status *st) {
    const mx_clip_vision_config *vc = &m->image_encoder->cfg;
    const mx_clip_image_config *pc = &m->image_processor;
    const mx_ip_adapter *ad = m->ip_adapter;
    if (ad->embed_dim != vc->projection_dim)
        return mx_fail(st, MX_EINPUT, "%s: the IP-Adapter takes image embeddings of %d values, the image encoder gives %d",
                       mx_models_path(m), ad->embed_dim, vc->projection_dim);
    if (pc->size != vc->image_size)
        return mx_fail(st, MX_EINPUT, "%s: the image encoder's preprocessing makes %dx%d images, the tower takes %dx%d",
                       mx_models_path(m), pc->size, pc->size, vc->image_size, vc->image_size);
    float *pixels = malloc(sizeof(float) * 3 * pc->size * pc->size * (size_t)s->n);
    float *embeds = malloc(sizeof(float) * (size_t)vc->projection_dim * s->n);
    s->ntokens = s->n * ad->num_tokens;
    s->dim = ad->cross_dim;
    s->tokens = malloc(sizeof(float) * (size_t)s->ntokens * s->dim);
    s->zero_tokens = malloc(sizeof(float) * (size_t)s->ntokens * s->dim);
    int rc = !pixels || !embeds || !s->tokens || !s->zero_tokens ? mx_fail(st, MX_ENOMEM, "style images: out of memory")
             : preprocess(s, pc, pixels, st) || mx_clip_vision_embed_images(c, m->image_encoder, pixels, s->n, embeds, st) ||
                     mx_ip_adapter_guidance_tokens(c, ad, embeds, s->n, s->tokens, s->zero_tokens, st)
                 ? -1
                 : 0;
    free(pixels);
    free(embeds);
    return rc;
}
