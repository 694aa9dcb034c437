/* Style images without networks (issue 26, pipeline/texture/style.h): the path-list option
 * (--style-image given several times, at most MATEX_MAX_STYLE_IMAGES, no empty name), the checks
 * before any work (missing, empty, not an image, too many bytes or pixels by the PNG or JPEG header,
 * images in memory), the read with its digests, what report.json gets, and a model set without the
 * image encoder or the adapter. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../pipeline/texture/models.h"
#include "../pipeline/texture/options.h"
#include "../pipeline/texture/style.h"
#include "util_test.h"

static char tmp[] = "/tmp/matex_test_style.XXXXXX";

static const char *tmp_file(const char *name, const void *bytes, size_t n) {
    static char path[8][256];
    static int next;
    char *p = path[next++ % 8];
    snprintf(p, 256, "%s/%s", tmp, name);
    FILE *f = fopen(p, "wb");
    if (f) {
        if (n) fwrite(bytes, 1, n, f);
        fclose(f);
    }
    return p;
}

/* The refusal of o's style images holds `want` and the code. */
static void expect_refused(const matex_options *o, int code, const char *want) {
    mx_status st;
    mx_status_clear(&st);
    int rc = mx_style_check_inputs(o, &st);
    CHECK(rc == -1 && st.code == code);
    if (!strstr(st.msg, want)) {
        fprintf(stderr, "message '%s' lacks '%s'\n", st.msg, want);
        mx_test_failures++;
    }
    printf("refused: %s\n", st.msg);
}

static void test_option(void) {
    matex_options o;
    mx_status st;
    matex_options_default(&o);
    CHECK(o.style_scale == 0.6f && !o.style_images[0] && !o.n_style_pixels && !o.front_render);
    const mx_option_spec *s = mx_option_find("style_image", MX_VERB_TEXTURE);
    CHECK(s && s == mx_option_find("--style-image", MX_VERB_TEXTURE) && s->type == MX_OPTION_PATHS);
    CHECK(mx_option_find("style-image", MX_VERB_ENHANCE) == s && mx_option_find("style-image", MX_VERB_TRANSFER) == NULL);
    char names[MATEX_MAX_STYLE_IMAGES + 1][24];
    for (int i = 0; i <= MATEX_MAX_STYLE_IMAGES; i++) snprintf(names[i], sizeof names[i], "s%d.png", i);
    for (int i = 0; i < MATEX_MAX_STYLE_IMAGES; i++) CHECK(mx_option_set(s, &o, names[i], &st) == 0);
    for (int i = 0; i < MATEX_MAX_STYLE_IMAGES; i++) CHECK(o.style_images[i] == names[i]); /* in order */
    CHECK(mx_option_set(s, &o, names[MATEX_MAX_STYLE_IMAGES], &st) == -1 && st.code == MX_EUSAGE &&
          strstr(st.msg, "--style-image may be given at most 8 times ('s8.png' is one more)"));
    CHECK(mx_options_check(&o, MX_VERB_TEXTURE, &st) == 0);
    mx_option_clear_paths(s, &o);
    CHECK(!o.style_images[0] && !o.style_images[MATEX_MAX_STYLE_IMAGES - 1]);
    CHECK(mx_option_set(s, &o, "", &st) == -1 && strstr(st.msg, "--style-image must be a file name, not ''"));
    o.style_images[1] = "after-a-null.png"; /* the API's list ends at its first NULL */
    CHECK(mx_options_check(&o, MX_VERB_TEXTURE, &st) == -1 && strstr(st.msg, "--style-image must be at most 8 file names"));
    o.style_images[1] = NULL;
    const mx_option_spec *scale = mx_option_find("style-scale", MX_VERB_TEXTURE);
    CHECK(mx_option_set(scale, &o, "0", &st) == 0 && o.style_scale == 0.0f);
    CHECK(mx_option_set(scale, &o, "2", &st) == 0 && o.style_scale == 2.0f);
    CHECK(mx_option_set(scale, &o, "2.5", &st) == -1 && strstr(st.msg, "--style-scale must be a number in [0, 2], not '2.5'"));
    CHECK(mx_option_set(scale, &o, "-0.1", &st) == -1);
}

/* A PNG header (signature, IHDR of w x h, RGB 8-bit), nothing after: enough for the checks. */
static size_t png_header(unsigned char *b, uint32_t w, uint32_t h) {
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    memcpy(b, sig, 8);
    memcpy(b + 8, "\0\0\0\x0dIHDR", 8);
    for (int i = 0; i < 4; i++) b[16 + i] = (unsigned char)(w >> (24 - 8 * i)), b[20 + i] = (unsigned char)(h >> (24 - 8 * i));
    memcpy(b + 24, "\x08\x02\0\0\0", 5);
    return 29;
}

/* A JPEG start: SOI, an APP0 segment to skip, then SOF0 of w x h. */
static size_t jpeg_header(unsigned char *b, uint16_t w, uint16_t h) {
    static const unsigned char head[] = {0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x06, 'J', 'F', 'I', 'F', 0xFF, 0xC0, 0x00, 0x11, 0x08};
    memcpy(b, head, sizeof head);
    b[sizeof head] = (unsigned char)(h >> 8), b[sizeof head + 1] = (unsigned char)h;
    b[sizeof head + 2] = (unsigned char)(w >> 8), b[sizeof head + 3] = (unsigned char)w;
    return sizeof head + 4;
}

static void test_files(void) {
    matex_options o;
    matex_options_default(&o);
    unsigned char b[64];
    o.style_images[0] = tmp_file("none.png", NULL, 0);
    remove(o.style_images[0]);
    expect_refused(&o, MX_EINPUT, "none.png: cannot open style image: No such file or directory");
    o.style_images[0] = tmp_file("empty.png", "", 0);
    expect_refused(&o, MX_EINPUT, "empty.png: style image is empty (0 bytes)");
    o.style_images[0] = tmp_file("text.png", "hello, not an image\n", 20);
    expect_refused(&o, MX_EINPUT, "text.png: style image is not an image (a PNG, JPEG or TIFF file)");
    o.style_images[0] = tmp;
    expect_refused(&o, MX_EINPUT, "style image is not a regular file");
    o.style_images[0] = tmp_file("huge.png", b, png_header(b, 10000, 10000));
    expect_refused(&o, MX_EINPUT, "huge.png: style image of 10000x10000 pixels is too large (at most 25000000 pixels");
    o.style_images[0] = tmp_file("huge.jpg", b, jpeg_header(b, 6000, 6000));
    expect_refused(&o, MX_EINPUT, "huge.jpg: style image of 6000x6000 pixels is too large");
    mx_status st;
    o.style_images[0] = tmp_file("ok.jpg", b, jpeg_header(b, 6000, 4000)); /* 24 Mpixel: a camera photo passes */
    CHECK(mx_style_check_inputs(&o, &st) == 0);
    o.style_images[0] = tmp_file("ok.png", b, png_header(b, 64, 48));
    o.style_images[1] = tmp_file("ok.tif", "II*\0\x08\0\0\0", 8);
    CHECK(mx_style_check_inputs(&o, &st) == 0);
    /* a file past the byte limit (sparse: no disk used) */
    const char *big = tmp_file("big.png", b, png_header(b, 64, 64));
    CHECK(truncate(big, MX_STYLE_MAX_FILE_BYTES + 1) == 0);
    o.style_images[1] = big;
    expect_refused(&o, MX_EINPUT, "big.png: style image file of 67108865 bytes is too large (at most 64 MiB)");
}

static void test_memory(void) {
    matex_options o;
    matex_options_default(&o);
    float px[2 * 3 * 3] = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f, 0.8f, 0.9f, 1.0f, 0.0f, 0.5f};
    matex_image im[MATEX_MAX_STYLE_IMAGES + 1];
    for (int i = 0; i <= MATEX_MAX_STYLE_IMAGES; i++) im[i] = (matex_image){3, 2, 3, px};
    o.style_pixels = im;
    o.n_style_pixels = 1;
    mx_status st;
    CHECK(mx_style_check_inputs(&o, &st) == 0);
    im[0].channels = 2;
    expect_refused(&o, MX_EUSAGE, "style image 0 in memory: 2 channels (1, 3 or 4)");
    im[0] = (matex_image){0, 2, 3, px};
    expect_refused(&o, MX_EUSAGE, "style image 0 in memory: no pixels");
    im[0] = (matex_image){3, 2, 3, NULL};
    expect_refused(&o, MX_EUSAGE, "style image 0 in memory: no pixels");
    im[0] = (matex_image){3, 2, 3, px};
    o.n_style_pixels = MATEX_MAX_STYLE_IMAGES;
    o.style_images[0] = "one-more.png";
    expect_refused(&o, MX_EUSAGE, "9 style images (1 files, 8 in memory): at most 8");
    o.style_images[0] = NULL;
    o.style_pixels = NULL;
    o.n_style_pixels = 1;
    expect_refused(&o, MX_EUSAGE, "n_style_pixels is 1 with style_pixels NULL");
}

/* A real image file and one in memory: read, digests (the same pixels, the same digest), report. */
static void test_load_and_report(void) {
    char path[512];
    if (!mx_test_need(path, sizeof path, "assets/spot/spot_texture.png")) return;
    matex_options o;
    matex_options_default(&o);
    float px[12] = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f, 0.8f, 0.9f, 1.0f, 0.0f, 0.5f};
    matex_image im[2] = {{2, 2, 3, px}, {2, 2, 3, px}};
    o.style_images[0] = path;
    o.style_pixels = im;
    o.n_style_pixels = 2;
    o.style_scale = 0.25f;
    mx_style s;
    mx_status st;
    CHECK(mx_style_load(&s, &o, &st) == 0);
    CHECK(s.n == 3 && s.path[0] == path && !s.path[1] && s.img[0].w > 0 && s.img[1].w == 2 && s.img[2].c == 3);
    CHECK(strlen(s.digest[0]) == 16 && !strcmp(s.digest[1], s.digest[2]) && strcmp(s.digest[0], s.digest[1]));
    CHECK(s.img[1].data != px && s.img[1].data[4] == px[4]); /* copied */
    mx_jw w;
    mx_jw_init(&w);
    mx_jw_begin_obj(&w, NULL);
    mx_style_report(&s, &w);
    mx_jw_end_obj(&w);
    const char *text = mx_jw_text(&w);
    printf("report: %s\n", text);
    CHECK(text && strstr(text, "\"style_images\":[{\"source\":") && strstr(text, "spot_texture.png") &&
          strstr(text, "\"source\":\"memory\"") && strstr(text, "\"style_scale\":0.25") && strstr(text, s.digest[0]));
    mx_jw_free(&w);
    mx_style_free(&s);
    CHECK(s.n == 0);
    /* no style image: nothing in the report */
    matex_options_default(&o);
    CHECK(mx_style_load(&s, &o, &st) == 0 && s.n == 0);
    mx_jw_init(&w);
    mx_jw_begin_obj(&w, NULL);
    mx_style_report(&s, &w);
    mx_jw_end_obj(&w);
    CHECK(mx_jw_text(&w) && !strcmp(mx_jw_text(&w), "{}"));
    mx_jw_free(&w);
    mx_style_free(&s);
}

/* A model set without the image encoder or the adapter: the message names what is missing and the
 * convert options that add it (the networks are not touched, only whether they are there). */
static void test_missing_networks(void) {
    const char *path = getenv("MATEX_UNET_ONLY_WEIGHTS");
    mx_models m;
    mx_status st;
    memset(&m, 0, sizeof m);
    if (!path || mx_wf_open(&m.wf, path, &st)) {
        fprintf(stderr, "no weight file in MATEX_UNET_ONLY_WEIGHTS (make test builds build/demo/demo_unet_only.mxw)\n");
        mx_test_failures++;
        return;
    }
    const char *convert = "Add them with: matex convert SD15_DIR --controlnet depth=DIR --controlnet inpaint=DIR "
                          "--image-encoder IMAGE_ENCODER_DIR --ip-adapter ip-adapter_sd15.safetensors -o W.mxw";
    CHECK(mx_style_check_models(&m, &st) == -1 && st.code == MX_EINPUT && strstr(st.msg, path) &&
          strstr(st.msg, "this one has neither") && strstr(st.msg, convert));
    printf("refused: %s\n", st.msg);
    mx_clip_vision encoder;
    m.image_encoder = &encoder;
    CHECK(mx_style_check_models(&m, &st) == -1 && strstr(st.msg, "this one has no ip_adapter.*"));
    m.image_encoder = NULL;
    m.ip_adapter = (mx_ip_adapter *)&encoder;
    CHECK(mx_style_check_models(&m, &st) == -1 && strstr(st.msg, "this one has no image_encoder.*"));
    m.image_encoder = &encoder;
    CHECK(mx_style_check_models(&m, &st) == 0);
    mx_wf_close(m.wf);
}

int main(void) {
    if (!mkdtemp(tmp)) return 1;
    test_option();
    test_files();
    test_memory();
    test_load_and_report();
    test_missing_networks();
    char cmd[600];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
    if (system(cmd)) fprintf(stderr, "could not remove %s\n", tmp);
    return mx_test_finish("test_texture_style");
}
