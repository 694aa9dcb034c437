/* The manifest of `matex batch`: one JSON object per line,
 *   {"mesh": "chairs/a.obj", "prompt": "a rustic wooden chair", "name": "chair_a", "seed": 3,
 *    "negative": "blurry", "steps": 20, "depth-weight": [1.0, 0.6], ...}
 * mesh (relative to the manifest's folder) and prompt are required; name (the output folder
 * under OUTROOT; default: the mesh's file name without extension) must be unique; every other
 * key is a `matex texture` option of job scope in the option table (pipeline/texture/options.c)
 * without its dashes ("image-size" or "image_size"; "fast": true), set by the same function as
 * the command line (mx_cli_texture_option); "style_image" (a file name or an array of them, relative
 * to the manifest's folder like mesh) replaces the batch's style images (--theme). The model set's options (threads, precision, device)
 * are the batch's own (its command line); output, weights and force are not keys (a job writes
 * OUTROOT/NAME; batch skips a complete job). Blank lines are skipped; a bad line becomes a job
 * with an error, reported with its line number. */
#ifndef MX_BATCH_MANIFEST_H
#define MX_BATCH_MANIFEST_H

#include "cli_texture_opts.h"

typedef struct mx_batch_job {
    int line;           /* 1-based line in the manifest */
    int index;          /* 0-based among the job lines: the shard of a job is index mod N */
    char name[128];     /* output folder name under OUTROOT */
    char error[1024];   /* "" for a good line, else the problem */
    mx_cli_texture c;   /* the parsed options (strings owned by texts) */
    int ntexts;
    char **texts;       /* the strings c borrows, owned */
} mx_batch_job;

typedef struct mx_batch_manifest {
    int njobs;
    mx_batch_job *jobs;
} mx_batch_manifest;

/* Reads every line of the manifest; each job gets -o OUTROOT/NAME, then the batch's defaults
 * (defaults[2k] an option name such as "--steps", defaults[2k+1] its value or NULL for a flag; the
 * command line of matex batch), then its line's keys. The options are parsed for the jobs of shard
 * I/N only (index mod N == I); the names of all (they must be unique across shards). Fails only
 * when the file cannot be read (a bad line is a job with an error). */
int mx_batch_manifest_read(mx_batch_manifest *m, const char *path, const char *const *defaults, int ndefaults,
                           const char *outroot, int shard, int nshards, mx_status *st);
void mx_batch_manifest_free(mx_batch_manifest *m);
/* One job from a JSON object of job keys: those of a line but mesh, name and style_image (the
 * client of `matex serve` sends the mesh and the style images as files; the server names the
 * job), into out_dir. 0, or -1 with the message in j->error (the key's message, as for a line).
 * The strings c borrows are j's: mx_batch_job_free releases them (also after a failure). */
int mx_batch_job_from_options(mx_batch_job *j, const char *text, size_t len, const char *mesh, const char *out_dir,
                              const char *const *style_images, int nstyle);
void mx_batch_job_free(mx_batch_job *j);

#endif
