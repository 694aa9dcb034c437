/* LD_PRELOAD hook for tests/cli_startup.sh: at exit, copies the process's /proc/self/maps (the
 * libraries it has mapped, the dlopen'ed ones included) to the file named by MATEX_MAPS_OUT. */
#include <stdio.h>
#include <stdlib.h>

__attribute__((destructor)) static void copy_maps_at_exit(void) {
    const char *path = getenv("MATEX_MAPS_OUT");
    if (!path) return;
    FILE *in = fopen("/proc/self/maps", "r"), *out = fopen(path, "w");
    char buf[4096];
    size_t n;
    while (in && out && (n = fread(buf, 1, sizeof buf, in)) > 0) fwrite(buf, 1, n, out);
    if (in) fclose(in);
    if (out) fclose(out);
}
