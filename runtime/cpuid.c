/* mx_cpu_best_isa. x86: cpuid for the instruction sets, xgetbv for the OS saving their
 * registers, and for AMX Linux's permission to use the tile data (Documentation/arch/x86/xstate.rst:
 * the first tile instruction of a process without it gets SIGILL; the permission is per process
 * and asking again is harmless). aarch64: the kernel's hardware capabilities (getauxval).
 * MATEX_ISA can only lower the level (asking for more than the CPU has would crash with an
 * illegal instruction). */
#include <stdlib.h>
#include <string.h>

#include "backend.h"
#include "log.h"

#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#if defined(__linux__)
#include <sys/syscall.h>
#include <unistd.h>
#endif

static unsigned long long read_xcr0(void) {
    unsigned int lo, hi;
    __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
    return ((unsigned long long)hi << 32) | lo;
}

/* Asks Linux for the AMX tile data (XSTATE component 18, XFEATURE_XTILEDATA) and checks that
 * it was granted: arch_prctl(ARCH_REQ_XCOMP_PERM = 0x1023, 18), ARCH_GET_XCOMP_PERM = 0x1022. */
static int amx_permitted(void) {
#if defined(__linux__) && defined(SYS_arch_prctl)
    unsigned long long perm = 0;
    if (syscall(SYS_arch_prctl, 0x1023, 18) != 0) return 0;
    if (syscall(SYS_arch_prctl, 0x1022, &perm) != 0) return 0;
    return (perm >> 18) & 1;
#else
    return 0;
#endif
}

/* AMX-TILE (leaf 7 EDX bit 24) and AMX-BF16 (bit 22), the tile config and data state enabled in
 * XCR0 (bits 17, 18), and the permission. */
static int amx_usable(unsigned int leaf7_edx, unsigned long long xcr0) {
    if (!((leaf7_edx >> 24) & 1) || !((leaf7_edx >> 22) & 1)) return 0;
    if ((xcr0 & 0x60000) != 0x60000) return 0;
    return amx_permitted();
}

static mx_isa detect_isa(void) {
    unsigned int a, b, c, d;
    if (!__get_cpuid(1, &a, &b, &c, &d)) return MX_ISA_SCALAR;
    int fma = (c >> 12) & 1, osxsave = (c >> 27) & 1, avx = (c >> 28) & 1, f16c = (c >> 29) & 1;
    if (!osxsave || !avx) return MX_ISA_SCALAR;
    unsigned long long xcr0 = read_xcr0();
    if ((xcr0 & 0x6) != 0x6) return MX_ISA_SCALAR; /* SSE and AVX state */
    if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return MX_ISA_SCALAR;
    int avx2 = (b >> 5) & 1;
    if (!avx2 || !fma || !f16c) return MX_ISA_SCALAR;
    int avx512 = ((b >> 16) & 1) && ((b >> 17) & 1) && ((b >> 30) & 1) && ((b >> 31) & 1); /* F DQ BW VL */
    if (!avx512 || (xcr0 & 0xE0) != 0xE0) return MX_ISA_AVX2; /* opmask, ZMM0-15 high, ZMM16-31 */
    unsigned int leaf7_edx = d;
    /* leaf 7 subleaf 1, EAX bit 5: AVX512_BF16 (vdpbf16ps, vcvtne2ps2bf16); the AMX level also
     * uses it (packing, attention) */
    if (!__get_cpuid_count(7, 1, &a, &b, &c, &d) || !((a >> 5) & 1)) return MX_ISA_AVX512;
    return amx_usable(leaf7_edx, xcr0) ? MX_ISA_AMX : MX_ISA_AVX512_BF16;
}

/* cpuid leaf 0's vendor string, "GenuineIntel", in EBX EDX ECX. */
static int cpu_is_intel(void) {
    unsigned int a, b, c, d;
    return __get_cpuid(0, &a, &b, &c, &d) && b == 0x756e6547u && d == 0x49656e69u && c == 0x6c65746eu;
}
#elif defined(__aarch64__) && defined(__linux__) && defined(MX_WITH_NEON)
#include <sys/auxv.h>

/* HWCAP_ASIMD (AT_HWCAP bit 1) and HWCAP2_BF16 (AT_HWCAP2 bit 14: BFDOT, BFMMLA, BFCVT), the
 * values of Linux's arch/arm64/include/uapi/asm/hwcap.h, spelt out for older libc headers. */
#define MX_HWCAP_ASIMD (1UL << 1)
#define MX_HWCAP2_BF16 (1UL << 14)

static mx_isa detect_isa(void) {
    if (!(getauxval(AT_HWCAP) & MX_HWCAP_ASIMD)) return MX_ISA_SCALAR;
    return getauxval(AT_HWCAP2) & MX_HWCAP2_BF16 ? MX_ISA_NEON_BF16 : MX_ISA_NEON;
}
#else
static mx_isa detect_isa(void) { return MX_ISA_SCALAR; }
#endif
#if !defined(__x86_64__) && !defined(__i386__)
static int cpu_is_intel(void) { return 0; }
#endif

/* 0: scalar (on every ladder), 1: x86-64, 2: aarch64. */
static int isa_ladder(mx_isa isa) { return isa == MX_ISA_SCALAR ? 0 : isa <= MX_ISA_AMX ? 1 : 2; }

mx_isa mx_isa_min(mx_isa want, mx_isa best) {
    if (want == MX_ISA_SCALAR || best == MX_ISA_SCALAR || isa_ladder(want) != isa_ladder(best)) return MX_ISA_SCALAR;
    return want < best ? want : best;
}

mx_isa mx_isa_fp32_level(mx_isa isa) {
    switch (isa) {
    case MX_ISA_AVX512_BF16:
    case MX_ISA_AMX: return MX_ISA_AVX512;
    case MX_ISA_NEON_BF16: return MX_ISA_NEON;
    default: return isa;
    }
}

static mx_isa isa_from_env(mx_isa best) {
    const char *e = getenv("MATEX_ISA");
    if (!e || !*e) return best;
    for (int i = 0; i < MX_ISA_COUNT; i++) {
        if (strcmp(e, mx_isa_name((mx_isa)i)) != 0) continue;
        if (isa_ladder((mx_isa)i) != isa_ladder(best) && i != MX_ISA_SCALAR && best != MX_ISA_SCALAR)
            mx_warn("MATEX_ISA=%s: not a level of this CPU's architecture; using scalar", e);
        return mx_isa_min((mx_isa)i, best);
    }
    mx_warn("MATEX_ISA=%s: unknown (use scalar, avx2, avx512, avx512bf16, amx, neon or neonbf16); using %s", e,
            mx_isa_name(best));
    return best;
}

mx_isa mx_cpu_best_isa(void) { return isa_from_env(detect_isa()); }

mx_isa mx_cpu_isa_for(mx_precision p) {
    mx_isa best = mx_cpu_best_isa();
    return p == MX_PREC_FP32 ? mx_isa_fp32_level(best) : best;
}

/* Measured (docs/PERFORMANCE.md): AMX and AMD's AVX512_BF16 (Zen 4, Zen 5) run the networks'
 * bf16 products 1.6-1.8x faster than fp32 FMAs. Intel's cores without usable AMX tiles
 * (Emerald Rapids under a VM that hides them; the AMX Xeon lowered to avx512bf16) issue
 * vdpbf16ps at half the FMA rate: the bf16 UNet took 1.6x the fp32 one's CPU time there, so fp32
 * is both faster and closer. Arm's BF16 stays bf16 (BFMMLA: not yet measured on hardware). */
mx_precision mx_cpu_faster_precision(void) {
    mx_isa best = mx_cpu_best_isa();
    if (best == MX_ISA_AVX512_BF16 && cpu_is_intel()) return MX_PREC_FP32;
    return mx_isa_precision(best);
}

mx_precision mx_isa_precision(mx_isa isa) { return mx_isa_fp32_level(isa) != isa ? MX_PREC_BF16 : MX_PREC_FP32; }

const char *mx_precision_name(mx_precision p) { return p == MX_PREC_BF16 ? "bf16" : "fp32"; }

int mx_precision_parse(const char *s, mx_precision *p) {
    if (!strcmp(s, "fp32"))
        *p = MX_PREC_FP32;
    else if (!strcmp(s, "bf16"))
        *p = MX_PREC_BF16;
    else
        return -1;
    return 0;
}

const char *mx_isa_name(mx_isa isa) {
    switch (isa) {
    case MX_ISA_SCALAR: return "scalar";
    case MX_ISA_AVX2: return "avx2";
    case MX_ISA_AVX512: return "avx512";
    case MX_ISA_AVX512_BF16: return "avx512bf16";
    case MX_ISA_AMX: return "amx";
    case MX_ISA_NEON: return "neon";
    case MX_ISA_NEON_BF16: return "neonbf16";
    case MX_ISA_COUNT: break;
    }
    return "?";
}
