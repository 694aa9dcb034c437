/* What `matex --version` reports: the version, how this binary was built (compiler, the flags
 * that change results or speed, sanitizers), the CPU kernel levels compiled in and the one this
 * CPU gets, and the backends compiled in. */
#ifndef MX_VERSION_H
#define MX_VERSION_H

#include <stdio.h>

#include "backend.h"

#define MX_VERSION "0.1.0"

/* "gcc 12.2.0", "clang 14.0.6": the compiler that built this file. */
const char *mx_build_compiler(void);
/* The build's optimisation, floating-point and sanitizer flags (from the Makefile). */
const char *mx_build_flags(void);
/* "address,undefined" in a sanitizer build (make asan), else "none". */
const char *mx_build_sanitizers(void);
/* 1 when the kernels of this ISA level are compiled in (all levels on x86-64, scalar elsewhere). */
int mx_build_has_isa(mx_isa isa);
/* The whole report, one fact per line (backends: mx_backends_compiled of backend.h). */
void mx_build_report(FILE *f);

#endif
