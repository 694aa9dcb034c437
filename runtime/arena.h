/* Activation arena: one block, bump allocation, 64-byte alignment, mark/reset.
 * A network is run once in "dry run" mode (measure only: no memory, pointers are NULL)
 * to learn the peak, then for real in an arena of exactly that size.
 * Running out is an error with a message, never an overrun. */
#ifndef MX_ARENA_H
#define MX_ARENA_H

#include <stddef.h>

#include "backend.h"
#include "status.h"

#define MX_ARENA_ALIGN 64

typedef struct mx_arena {
    unsigned char *base; /* NULL in a measuring arena */
    size_t cap;          /* bytes usable; ignored while measuring */
    size_t used;
    size_t peak;
    int measuring;       /* 1: count sizes only, hand out NULL */
    int owns;            /* 1: base was allocated by mx_arena_create / mx_arena_create_on */
    mx_backend *be;      /* the backend whose memory base is (NULL: host heap) */
} mx_arena;

/* n bytes of host memory (n a multiple of MX_ARENA_ALIGN, not 0) aligned to it, for free(), or
 * NULL. The whole 2 MiB pages inside a block of 8 MiB or more are advised to transparent huge
 * pages: activation arenas and step caches are written afresh by every denoising request of a
 * texture job, and one page fault per 4 KiB of them was most of a --fast job's 1.2 M faults
 * (~15 s of system time on the VMs measured). */
void *mx_host_block(size_t n);

int mx_arena_create(mx_arena *a, size_t cap, mx_status *st);
/* An arena in a backend's memory (be NULL: the host heap, as mx_arena_create). Only ops may
 * read or write what it hands out. */
int mx_arena_create_on(mx_arena *a, mx_backend *be, size_t cap, mx_status *st);
/* An arena that only measures (dry run). */
void mx_arena_measure(mx_arena *a);
void mx_arena_destroy(mx_arena *a);

/* Returns 64-byte aligned memory, or NULL with an error in st when the arena is full.
 * In a measuring arena it returns NULL and no error: check a->measuring. */
void *mx_arena_alloc(mx_arena *a, size_t bytes, mx_status *st);
float *mx_arena_floats(mx_arena *a, size_t n, mx_status *st);

/* Mark/reset: free everything allocated after the mark at once. */
size_t mx_arena_mark(const mx_arena *a);
void mx_arena_reset(mx_arena *a, size_t mark);

#endif
