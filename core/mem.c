/* Memory advice (core.h, bf_advise_huge). */
#include <stdint.h>
#include <sys/mman.h>

#include "core.h"

void bf_advise_huge(void *p, size_t bytes)
{
#ifdef MADV_HUGEPAGE
    const uintptr_t huge = (uintptr_t)2 << 20;
    uintptr_t lo = ((uintptr_t)p + huge - 1) & ~(huge - 1), hi = ((uintptr_t)p + bytes) & ~(huge - 1);
    /* Advice only: a kernel without transparent huge pages, or with them off, says no and nothing changes. */
    if (p && hi > lo) (void)madvise((void *)lo, hi - lo, MADV_HUGEPAGE);
#else
    (void)p, (void)bytes;
#endif
}
