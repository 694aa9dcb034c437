/* Build facts for `matex --version`. MX_BUILD_FLAGS and MX_BUILD_SAN come from the Makefile
 * (only this file is compiled with them); the compiler names itself through its predefined
 * macros. */
#include "version.h"

#include <stdlib.h>
#include <string.h>

#ifndef MX_BUILD_FLAGS
#define MX_BUILD_FLAGS "unknown (built outside the Makefile)"
#endif
#ifndef MX_BUILD_SAN
#define MX_BUILD_SAN "none"
#endif

#define MX_STR2(x) #x
#define MX_STR(x) MX_STR2(x)

const char *mx_build_compiler(void) {
#if defined(__clang__)
    return "clang " MX_STR(__clang_major__) "." MX_STR(__clang_minor__) "." MX_STR(__clang_patchlevel__);
#elif defined(__GNUC__)
    return "gcc " __VERSION__;
#else
    return "unknown compiler";
#endif
}

const char *mx_build_flags(void) { return MX_BUILD_FLAGS; }

const char *mx_build_sanitizers(void) { return MX_BUILD_SAN; }

int mx_build_has_isa(mx_isa isa) {
#if defined(MX_WITH_NEON)
    return isa == MX_ISA_SCALAR || isa == MX_ISA_NEON || isa == MX_ISA_NEON_BF16;
#elif defined(MX_NO_X86_SIMD)
    return isa == MX_ISA_SCALAR;
#else
    return isa <= MX_ISA_AMX;
#endif
}

void mx_build_report(FILE *f) {
    fprintf(f, "matex %s\n", MX_VERSION);
    fprintf(f, "compiler: %s\n", mx_build_compiler());
    fprintf(f, "flags: %s\n", mx_build_flags());
    fprintf(f, "sanitizers: %s\n", mx_build_sanitizers());
    fprintf(f, "cpu kernels compiled in:");
    /* the levels are numbered from 0 up; mx_isa_name names each and says "?" past the last */
    for (int i = 0; strcmp(mx_isa_name((mx_isa)i), "?") != 0; i++)
        if (mx_build_has_isa((mx_isa)i)) fprintf(f, " %s", mx_isa_name((mx_isa)i));
    fprintf(f, "\ncpu kernels used on this CPU: fp32 %s, bf16 %s%s\n", mx_isa_name(mx_cpu_isa_for(MX_PREC_FP32)),
            mx_isa_name(mx_cpu_isa_for(MX_PREC_BF16)), getenv("MATEX_ISA") ? " (MATEX_ISA lowers them)" : "");
    fprintf(f, "precision auto on this CPU: %s\n", mx_precision_name(mx_cpu_faster_precision()));
    fprintf(f, "backends: %s\n", mx_backends_compiled());
}
