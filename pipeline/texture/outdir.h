/* The output folder of a run, checked and staged before any expensive work, so that a failure
 * or an interrupt at any moment leaves either what was there before or the complete new folder:
 *   mx_outdir_open: resolves DIR (a link to a folder is followed), refuses a path that is not a
 *     folder, the current folder (or one holding it), a folder holding one of the run's inputs,
 *     and a non-empty folder unless force; even with force it replaces only a folder that matex
 *     wrote: one with the marker file MX_OUTDIR_MARKER, every entry of which the marker lists: a
 *     file, or a sub-folder listed as "NAME/" that is itself matex's output (an output written into
 *     an output, as `make demo`'s views/, is added to the outer marker when published); so never a
 *     user's file or folder, the input mesh or the weights. Creates missing parents and the staging
 *     folder "DIR.partial-PID" beside DIR (same file system, so the final move cannot be
 *     cross-device), marked as matex's from the start: an unwritable location fails at once, not
 *     after the generation. Staging folders of DIR whose process is gone (kill -9) are removed
 *     there, and only those carrying matex's marker;
 *   mx_outdir_commit: writes the files into the staging folder, then puts it in place with one
 *     rename (DIR missing or empty) or one atomic exchange (--force over a non-empty DIR; its old
 *     content is then removed);
 *   mx_outdir_publish: the same move for a staging folder filled by the caller (files written
 *     into od->stage, e.g. by matex render); both write the marker, listing the staged files, last;
 *   mx_outdir_discard: removes the staging folder (after a failure or an interrupt).
 * Two runs into one folder: mx_outdir_open holds a lock (flock on "DIR.matex-lock" beside DIR,
 * released by the kernel if the process dies) until mx_outdir_discard; a second run is refused at
 * once, saying another matex run is writing there. */
#ifndef MX_OUTDIR_H
#define MX_OUTDIR_H

#include <signal.h>

#include "../../runtime/status.h"
#include "../geom/image.h"
#include "../geom/mesh.h"

typedef struct mx_outdir {
    char dir[4096];   /* the output folder, links resolved when it exists */
    char stage[4200]; /* dir + ".partial-PID" */
    char lock[4200];  /* dir + ".matex-lock" */
    int exists;       /* dir existed at open (empty, or non-empty with force) */
    int staged;       /* the staging folder exists */
    int locked;       /* lock_fd holds the lock */
    int lock_fd;
} mx_outdir;

/* The file that marks a folder as matex's output: a first line saying so, then the names of the
 * files matex wrote there, one a line. */
#define MX_OUTDIR_MARKER ".matex-output"

/* inputs[0..ninputs-1]: the files the run reads (mesh, weights, textures; NULL entries skipped):
 * a folder holding one of them is never an output folder. */
int mx_outdir_open(mx_outdir *od, const char *dir, int force, const char *const *inputs, int ninputs, mx_status *st);
/* The staging folder and the lock file mx_outdir_open would use for `dir` in this process (for a
 * signal handler that must remove them: tools/matex/cli_signals.c). */
int mx_outdir_names(const char *dir, char stage[4200], char lock[4200]);
/* cancel (may be NULL) is checked once more after the files are written, before the move. */
int mx_outdir_commit(mx_outdir *od, const mx_mesh *m, const mx_image *textures, int ntex, const char *report_json,
                     const volatile sig_atomic_t *cancel, mx_status *st);
int mx_outdir_publish(mx_outdir *od, const volatile sig_atomic_t *cancel, mx_status *st);
void mx_outdir_discard(mx_outdir *od);

#endif
