// operator new of matex's C++ adapter (pipeline/io) under the fault injector (fault.c): the
// failing allocation throws std::bad_alloc, as a real one would.
#include <cstddef>
#include <new>

#include "fault.h"

extern "C" void *__real__Znwm(std::size_t n);
extern "C" void *__real__Znam(std::size_t n);

extern "C" void *__wrap__Znwm(std::size_t n) {
    if (fault_alloc_fails(__builtin_return_address(0))) throw std::bad_alloc();
    return __real__Znwm(n);
}

extern "C" void *__wrap__Znam(std::size_t n) {
    if (fault_alloc_fails(__builtin_return_address(0))) throw std::bad_alloc();
    return __real__Znam(n);
}
