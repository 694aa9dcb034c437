/* The one table of the texturing options (include/matex.h's matex_options): for each option its
 * name, value type, valid range, default, help text, the verbs that take it and whether a batch
 * manifest line may set it. Everything else is derived from it: matex_options_default, the range
 * check of the library (mx_options_check), the command-line parser and --help of texture,
 * enhance, transfer and batch (tools/matex/cli_texture_opts.c), and the keys of a batch manifest
 * (tools/matex/cli_batch_manifest.c). */
#ifndef MX_OPTIONS_H
#define MX_OPTIONS_H

#include <stddef.h>
#include <stdio.h>

#include "../../include/matex.h"
#include "../../runtime/jsonw.h"
#include "../../runtime/status.h"

typedef enum {
    MX_OPTION_FLAG,   /* int set to 1 when given; takes no value */
    MX_OPTION_INT,    /* int in lo..hi (and a multiple of `multiple` when set) */
    MX_OPTION_U64,    /* uint64_t in 0..UINT64_MAX */
    MX_OPTION_FLOAT,  /* finite float in lo..hi (bounds open where said) */
    MX_OPTION_FLOAT2, /* float[2], "A" or "A,B" (B = A when absent), each in lo..hi */
    MX_OPTION_FLOAT3, /* float[3], "A,B,C", each in lo..hi */
    MX_OPTION_TEXT,   /* const char * (borrowed) */
    MX_OPTION_PATHS,  /* const char *[MATEX_MAX_STYLE_IMAGES] (borrowed): each value goes into the first
                         free (NULL) slot, so the option may be given several times */
    MX_OPTION_CHOICE, /* int: the index of the value among `choices` ("depth|geometric") */
    MX_OPTION_CLI     /* handled by the command line itself (--weights, --json, ...): no field */
} mx_option_type;

/* The verbs that take an option (a bit set). MX_VERB_BATCH: `matex batch` takes it on its command
 * line, for the model set (scope MODELS) or as the default of every job (scope JOB). */
enum { MX_VERB_TEXTURE = 1, MX_VERB_ENHANCE = 2, MX_VERB_TRANSFER = 4, MX_VERB_BATCH = 8 };

typedef enum {
    MX_SCOPE_JOB,    /* one run's result: a batch manifest key */
    MX_SCOPE_MODELS, /* how the model set computes (one for a whole batch): not a manifest key */
    MX_SCOPE_RUN     /* where and how one command writes (output, --force, --json): not a manifest key */
} mx_opt_scope;

typedef struct mx_option_spec {
    const char *name;     /* "image-size": --image-size, manifest key "image-size" or "image_size" */
    char short_name;      /* 'o' for -o, else 0 */
    const char *arg;      /* the value's name in --help ("N", "A[,B]"), NULL for a flag */
    mx_option_type type;
    size_t field;         /* offset in matex_options (type-checked where the table is written) */
    size_t twin;          /* int field that gets the same value (--size: texture and render size); 0 none */
    size_t marks;         /* int field set to 1 when the option is given; 0 none */
    double lo, hi;        /* the valid range (numbers) */
    int lo_open, hi_open; /* lo < v, v < hi instead of <= */
    int multiple;         /* INT: the value must be a multiple of it (0: any) */
    const char *choices;  /* CHOICE: "a|b|c" */
    const char *def;      /* the default, written as on the command line (NULL: zero / none) */
    const char *def_help; /* how --help states the default when not `def` itself ("all") */
    unsigned verbs;       /* MX_VERB_* */
    mx_opt_scope scope;
    const char *help;     /* one line; "\n" starts an indented continuation line */
} mx_option_spec;

/* The table, in --help order; *n gets its length. */
const mx_option_spec *mx_options_table(int *n);
/* The option `name` ("image-size", "image_size", "--image-size", "-o") of a verb (MX_VERB_*), or NULL. */
const mx_option_spec *mx_option_find(const char *name, unsigned verb);
/* Parses `value` into o's field(s) and checks its range: MX_EUSAGE with "--NAME must be ... not 'VALUE'". */
int mx_option_set(const mx_option_spec *s, matex_options *o, const char *value, mx_status *st);
/* Empties a path list (MX_OPTION_PATHS; other options are left as they are): a batch manifest's
 * style_image replaces the batch's own. */
void mx_option_clear_paths(const mx_option_spec *s, matex_options *o);
/* One option's value in o within its range (the same message). */
int mx_option_check(const mx_option_spec *s, const matex_options *o, mx_status *st);
/* Every option of a verb within its range (the message names the option, its value and the valid
 * values), before any work: the library's runs call it, the command line calls it after parsing. */
int mx_options_check(const matex_options *o, unsigned verb, mx_status *st);
/* The --help lines of a verb's options (generated from the table). */
void mx_options_help(FILE *f, unsigned verb);
/* The side of the generated images the loaded networks accept: a multiple of `step`, from `step` up
 * (image -> latent by the VAE's factor, then 2^(levels-1) for the UNet's levels: 64 for SD1.5). */
int mx_options_check_image_size(int image_size, int step, mx_status *st);
/* "texture", "enhance", "transfer" or "batch". */
const char *mx_options_verb_name(unsigned verb);
/* report.json's "options": the value of every option of the verb that shapes one run's result (scope
 * JOB), named as batch manifest keys, so that the report reproduces the run. The model set's
 * options (threads, precision, device) are reported as what ran: "threads", "precision", "kernels". */
void mx_options_report(const matex_options *o, unsigned verb, mx_jw *w);

#endif
