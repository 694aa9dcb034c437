/* Shared by the C and C++ halves of the fault injector (tests/faults/fault.c). */
#ifndef MX_FAULT_H
#define MX_FAULT_H

#ifdef __cplusplus
extern "C" {
#endif

/* Counts one allocation from `site` (a return address); 1 when it must fail. */
int fault_alloc_fails(void *site);

#ifdef __cplusplus
}
#endif

#endif
