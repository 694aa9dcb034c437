/* bench_taesd: TAESD (AutoencoderTiny, tools/bench/taesd_config.json = the public madebyollin/taesd
 * config, golden-v1 rule weights in fp16, made in memory) decoding a 64×64 latent to 512² and
 * encoding 512² back, fp32 and (where the CPU has AVX512_BF16) bf16 right after: seconds, GFLOP
 * and GFLOP/s over CPU time against the measured peak of the cores (bench_sd15.h).
 * Best of 3 runs each. Usage: bench_taesd [--threads N] (run from the repository root). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../pipeline/nn/netcfg.h"
#include "../../pipeline/nn/registry.h"
#include "../../pipeline/nn/taesd.h"
#include "../../runtime/fileio.h"
#include "bench_sd15.h"

#define REPEATS 3

/* Best of `repeats` runs of decode (enc 0) or encode (enc 1): wall and process CPU seconds. */
static int time_pass(const mx_ctx *c, const mx_taesd *t, int enc, int repeats, const float *in, float *out,
                     mx_arena *a, double *wall, double *cpu, mx_status *st) {
    *wall = *cpu = 1e30;
    for (int r = 0; r < repeats; r++) {
        double w0 = mx_now(), c0 = bench_cpu_seconds(CLOCK_PROCESS_CPUTIME_ID);
        int rc = enc ? mx_taesd_encode(c, t, in, 1, 512, 512, out, a, st) : mx_taesd_decode(c, t, in, 1, 64, 64, out, a, st);
        if (rc) return -1;
        double w = mx_now() - w0, cp = bench_cpu_seconds(CLOCK_PROCESS_CPUTIME_ID) - c0;
        if (w < *wall) *wall = w, *cpu = cp;
    }
    return 0;
}

static int run(int threads, int repeats, mx_status *st) {
    size_t len;
    char *text = mx_read_file("tools/bench/taesd_config.json", 1 << 16, &len, st);
    const mx_net_def *def = mx_net_of_kind(MX_NET_TAESD);
    mx_binder b;
    mx_taesd *t = NULL;
    if (!text || mx_binder_rule(&b, 1, MX_F16, st)) {
        free(text);
        return -1;
    }
    int loaded = def->load((void **)&t, text, len, "tools/bench/taesd_config.json", &b, st) == 0;
    free(text);
    if (!loaded) {
        def->free(t);
        mx_binder_free(&b);
        return -1;
    }
    mx_ctx c[2];
    mx_isa bf16_isa = mx_cpu_isa_for(MX_PREC_BF16);
    int nprec = mx_isa_precision(bf16_isa) == MX_PREC_BF16 ? 2 : 1, rc = -1, made = 0;
    size_t nl = (size_t)4 * 64 * 64, ni = (size_t)3 * 512 * 512, db, eb;
    float *lat = malloc(nl * sizeof *lat), *img = malloc(ni * sizeof *img);
    mx_arena a = {0};
    double peak[2] = {0, 0};
    if (!lat || !img || mx_taesd_decode_arena_bytes(t, 1, 64, 64, &db, st) ||
        mx_taesd_encode_arena_bytes(t, 1, 512, 512, &eb, st) || mx_arena_create(&a, db > eb ? db : eb, st))
        goto done;
    for (size_t i = 0; i < nl; i++) lat[i] = (float)((i * 2654435761u) % 2001) / 1000.0f - 1.0f;
    for (made = 0; made < nprec; made++)
        if (mx_ctx_create(&c[made], threads, made ? bf16_isa : mx_cpu_isa_for(MX_PREC_FP32), (size_t)64 << 20, st))
            goto done;
    int nth = mx_pool_threads(c[0].pool);
    for (int p = 0; p < nprec; p++) peak[p] = bench_peak_gflops(&c[p], p);
    double gf = mx_taesd_decode_flops(t, 1, 64, 64) * 1e-9;
    printf("TAESD (public config, random fp16 weights), %d threads; measured peak fp32 %.0f, bf16 %.0f GFLOP/s\n", nth,
           peak[0], peak[1]);
    printf("%-28s %7s %8s %8s %8s %6s\n", "pass (best of repeats)", "GFLOP", "kernels", "wall s", "GFLOP/s", "peak");
    for (int enc = 0; enc < 2; enc++)
        for (int p = 0; p < nprec; p++) {
            double w, cpu;
            if (time_pass(&c[p], t, enc, repeats, enc ? img : lat, enc ? lat : img, &a, &w, &cpu, st)) goto done;
            /* the encoder's FLOPs are not counted by the op layer's dry run here: decode only */
            double rate = gf / (cpu / nth);
            if (enc)
                printf("%-28s %7s %8s %8.3f %8s %6s\n", "encode 512x512 batch 1", "-", mx_isa_name(c[p].k->isa), w, "-",
                       "-");
            else
                printf("%-28s %7.1f %8s %8.3f %8.1f %5.0f%%\n", "decode 64x64 -> 512x512", gf, mx_isa_name(c[p].k->isa),
                       w, rate, 100 * rate / peak[p]);
        }
    rc = 0;
done:
    for (int p = 0; p < made; p++) mx_ctx_destroy(&c[p]);
    mx_arena_destroy(&a);
    free(lat);
    free(img);
    mx_taesd_free(t);
    mx_binder_free(&b);
    return rc;
}

int main(int argc, char **argv) {
    int threads = argc == 3 && !strcmp(argv[1], "--threads") ? atoi(argv[2]) : 0;
    if (argc != 1 && threads < 1) {
        fprintf(stderr, "usage: bench_taesd [--threads N]\n");
        return 2;
    }
    mx_status st;
    mx_status_clear(&st);
    if (run(threads, REPEATS, &st)) {
        fprintf(stderr, "bench_taesd: %s\n", st.msg);
        return 1;
    }
    return 0;
}
