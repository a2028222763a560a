/* core: the one fault-injection hook (core.h, "fault injection"). */
#include "core.h"

#include <stdatomic.h>
#include <stdlib.h>

static _Atomic uint32_t countdown; /* 0: disarmed */

uint32_t bf_fault_arm(uint32_t n) { return atomic_exchange(&countdown, n); }

bool bf_fault_now(void)
{
    uint32_t n = atomic_load(&countdown);
    while (n > 0 && !atomic_compare_exchange_weak(&countdown, &n, n - 1)) {
    }
    return n == 1;
}

void *bf_malloc(size_t size) { return bf_fault_now() ? NULL : malloc(size); }
void *bf_calloc(size_t n, size_t size) { return bf_fault_now() ? NULL : calloc(n, size); }
void *bf_realloc(void *p, size_t size) { return bf_fault_now() ? NULL : realloc(p, size); }
