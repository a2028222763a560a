/* Shared setup for tests that run on the Vulkan device: a context with the
 * validation layer on (every message fails the test) and a pipeline cache in
 * the test's temporary directory; skip when the machine has no device. */
#ifndef BF_GPU_FIXTURE_H
#define BF_GPU_FIXTURE_H

#include <stdio.h>

#include "gpu/gpu.h"
#include "test.h"

static inline gpu_config gpu_fixture_config(void)
{
    static char dir[512];
    snprintf(dir, sizeof dir, "%s/cache", bf_test_tmpdir());
    return (gpu_config){.validation = GPU_VALIDATION_ON, .cache_dir = dir};
}

/* Opens ctx or skips the test when there is no Vulkan device at all. */
#define GPU_FIXTURE_OPEN(ctx)                                              \
    do {                                                                   \
        gpu_config _cfg = gpu_fixture_config();                            \
        bf_status _st = gpu_context_create(&_cfg, &(ctx));                 \
        if (_st == BF_NO_DEVICE) BF_SKIP(bf_last_error());                 \
        CHECK_STATUS(_st, BF_OK);                                          \
    } while (0)

/* No validation message so far in this context. */
#define GPU_FIXTURE_CHECK_CLEAN(ctx) CHECK_EQ_INT(gpu_validation_message_count(ctx), 0)

#endif
