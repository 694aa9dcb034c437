/* Fault injection for a test-only build of matex (build/tests/faults/matex_faults; the product
 * code is unchanged). Linked with -Wl,--wrap for the allocation functions, so every
 * allocation made by matex's own code is counted; the write functions are interposed (defined
 * here), so the writes of the image libraries (PNG via OpenImageIO, EXR via OpenEXR) are
 * counted too.
 *   MATEX_FAIL_ALLOC=k   the k-th allocation (1-based) returns NULL (ENOMEM); the others work
 *   MATEX_FAIL_WRITE=k   the k-th write is short (half the bytes, ENOSPC) and every later write
 *                        fails with ENOSPC: a disk that fills up
 *   MATEX_FAULT_REPORT=F at exit, F gets "allocs N sites S" and "writes N sites S": calls made
 *                        and distinct call sites (return addresses) seen, "live L": blocks of
 *                        matex's C allocation functions not freed by exit (a leak check that
 *                        needs no sanitizer, so that a plain fast build can try every k), then
 *                        "first K" for each allocation site: the number of the first allocation
 *                        made there
 * Calls are counted across threads (run with --threads 1 for a reproducible k), from the start
 * of main's constructors on: the shared libraries' own start-up is not matex's to handle. */
#include <dlfcn.h>
#include <errno.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fault.h"

#define MAX_SITES 4096

typedef struct counter {
    atomic_long calls;
    long fail_at; /* 0: never */
    atomic_uintptr_t sites[MAX_SITES]; /* open-addressed set of return addresses */
    long first[MAX_SITES];              /* number of the first call from that site */
} counter;

/* The blocks returned by the wrapped C allocation functions and not yet freed: an
 * open-addressed set of addresses (TOMB marks a removed entry) behind a spin lock. */
#define LIVE_SLOTS (1u << 20)
#define TOMB ((uintptr_t)1)
typedef struct live_set {
    atomic_flag lock;
    long count;
    uintptr_t slot[LIVE_SLOTS];
} live_set;

/* Test-harness state: the wrapped functions have no context argument to carry it. */
static counter allocs, writes;
static atomic_int armed;
static live_set live = {ATOMIC_FLAG_INIT, 0, {0}};

static size_t live_hash(uintptr_t p) { return (size_t)((p >> 4) * 0x9E3779B97F4A7C15ull >> 44) % LIVE_SLOTS; }

static void live_add(void *ptr) {
    if (!ptr || !atomic_load(&armed)) return;
    uintptr_t p = (uintptr_t)ptr;
    while (atomic_flag_test_and_set(&live.lock)) {
    }
    for (size_t i = live_hash(p), n = 0; n < LIVE_SLOTS; i = (i + 1) % LIVE_SLOTS, n++)
        if (live.slot[i] == 0 || live.slot[i] == TOMB) {
            live.slot[i] = p;
            live.count++;
            break;
        }
    atomic_flag_clear(&live.lock);
}

/* A block that is not in the set (allocated by a library, e.g. realpath's) is ignored. */
static void live_remove(void *ptr) {
    if (!ptr) return;
    uintptr_t p = (uintptr_t)ptr;
    while (atomic_flag_test_and_set(&live.lock)) {
    }
    for (size_t i = live_hash(p), n = 0; n < LIVE_SLOTS && live.slot[i]; i = (i + 1) % LIVE_SLOTS, n++)
        if (live.slot[i] == p) {
            live.slot[i] = TOMB;
            live.count--;
            break;
        }
    atomic_flag_clear(&live.lock);
}

static long env_long(const char *name) {
    const char *s = getenv(name);
    return s ? strtol(s, NULL, 10) : 0;
}

static void write_report(void);

/* Runs after the shared libraries' initialisers, before main. */
__attribute__((constructor)) static void init(void) {
    allocs.fail_at = env_long("MATEX_FAIL_ALLOC");
    writes.fail_at = env_long("MATEX_FAIL_WRITE");
    if (getenv("MATEX_FAULT_REPORT")) atexit(write_report);
    atomic_store(&armed, 1);
}

static void add_site(counter *c, uintptr_t site, long k) {
    for (size_t i = (site >> 4) % MAX_SITES, n = 0; n < MAX_SITES; i = (i + 1) % MAX_SITES, n++) {
        uintptr_t cur = 0;
        if (atomic_compare_exchange_strong(&c->sites[i], &cur, site)) c->first[i] = k;
        if (!cur || cur == site) return;
    }
}

static size_t count_sites(counter *c) {
    size_t n = 0;
    for (size_t i = 0; i < MAX_SITES; i++) n += atomic_load(&c->sites[i]) != 0;
    return n;
}

/* Counts one call from `site` and returns its number (1-based; 0 before main). */
static long tick(counter *c, void *site) {
    if (!atomic_load(&armed)) return 0;
    long k = atomic_fetch_add(&c->calls, 1) + 1;
    add_site(c, (uintptr_t)site, k);
    return k;
}

int fault_alloc_fails(void *site) {
    long k = tick(&allocs, site);
    if (!k || k != allocs.fail_at) return 0;
    errno = ENOMEM;
    return 1;
}

/* 0: write normally; 1: the k-th write (short); 2: a later write (nothing written). */
static int write_mode(void *site) {
    long k = tick(&writes, site);
    if (!k || !writes.fail_at || k < writes.fail_at) return 0;
    return k == writes.fail_at ? 1 : 2;
}

static void write_report(void) {
    static ssize_t (*real_write)(int, const void *, size_t);
    real_write = (ssize_t (*)(int, const void *, size_t))dlsym(RTLD_NEXT, "write");
    char line[256];
    int n = snprintf(line, sizeof line, "allocs %ld sites %zu\nwrites %ld sites %zu\nlive %ld\n",
                     atomic_load(&allocs.calls), count_sites(&allocs), atomic_load(&writes.calls), count_sites(&writes),
                     live.count);
    FILE *f = fopen(getenv("MATEX_FAULT_REPORT"), "w");
    if (!f || !real_write) return;
    real_write(fileno(f), line, (size_t)n);
    for (size_t i = 0; i < MAX_SITES; i++)
        if (atomic_load(&allocs.sites[i])) {
            n = snprintf(line, sizeof line, "first %ld\n", allocs.first[i]);
            real_write(fileno(f), line, (size_t)n);
        }
    fclose(f);
}

/* ---- allocations (-Wl,--wrap=NAME: calls to NAME in matex's objects land in __wrap_NAME) ---- */
void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t size);
void *__real_realloc(void *p, size_t n);
void *__real_aligned_alloc(size_t align, size_t n);
int __real_posix_memalign(void **p, size_t align, size_t n);
char *__real_strdup(const char *s);
char *__real_strndup(const char *s, size_t n);

void __real_free(void *p);

static void *track(void *p) {
    live_add(p);
    return p;
}

void *__wrap_malloc(size_t n) { return fault_alloc_fails(__builtin_return_address(0)) ? NULL : track(__real_malloc(n)); }
void *__wrap_calloc(size_t n, size_t size) {
    return fault_alloc_fails(__builtin_return_address(0)) ? NULL : track(__real_calloc(n, size));
}
void *__wrap_realloc(void *p, size_t n) {
    if (fault_alloc_fails(__builtin_return_address(0))) return NULL;
    void *q = __real_realloc(p, n);
    if (q || !n) live_remove(p);
    return track(q);
}
void *__wrap_aligned_alloc(size_t align, size_t n) {
    return fault_alloc_fails(__builtin_return_address(0)) ? NULL : track(__real_aligned_alloc(align, n));
}
int __wrap_posix_memalign(void **p, size_t align, size_t n) {
    if (fault_alloc_fails(__builtin_return_address(0))) return ENOMEM;
    int rc = __real_posix_memalign(p, align, n);
    if (!rc) live_add(*p);
    return rc;
}
char *__wrap_strdup(const char *s) {
    return fault_alloc_fails(__builtin_return_address(0)) ? NULL : track(__real_strdup(s));
}
char *__wrap_strndup(const char *s, size_t n) {
    return fault_alloc_fails(__builtin_return_address(0)) ? NULL : track(__real_strndup(s, n));
}
void __wrap_free(void *p) {
    live_remove(p);
    __real_free(p);
}

/* ---- writes (interposed: the image libraries' calls land here too) ---- */
ssize_t write(int fd, const void *buf, size_t n) {
    static ssize_t (*real)(int, const void *, size_t);
    if (!real) real = (ssize_t (*)(int, const void *, size_t))dlsym(RTLD_NEXT, "write");
    int mode = fd > 2 ? write_mode(__builtin_return_address(0)) : 0;
    if (mode == 0) return real(fd, buf, n);
    if (mode == 1 && n > 1) return real(fd, buf, n / 2);
    errno = ENOSPC;
    return -1;
}

size_t fwrite(const void *buf, size_t size, size_t n, FILE *f) {
    static size_t (*real)(const void *, size_t, size_t, FILE *);
    if (!real) real = (size_t (*)(const void *, size_t, size_t, FILE *))dlsym(RTLD_NEXT, "fwrite");
    int mode = f != stdout && f != stderr ? write_mode(__builtin_return_address(0)) : 0;
    if (mode == 0) return real(buf, size, n, f);
    size_t done = mode == 1 ? real(buf, size, n / 2, f) : 0;
    errno = ENOSPC;
    return done;
}
