/* Layouts shared by the gpu module's test shaders and tests/gpu/test_gpu.c. */
#ifndef BF_GPU_TEST_GLSL_H
#define BF_GPU_TEST_GLSL_H

#include "bf_common.glsl.h"

/* Push constants of gpu_test_layout.comp, and the element of its input
 * buffer: 32-bit scalars only, so std430 and C agree (pinned below). */
struct gpu_test_params {
    bf_u32 n;
    bf_i32 offset;
    bf_f32 scale;
    bf_u32 seed;
    bf_u32 words[4];
};
#define GPU_TEST_PARAMS_WORDS 8u /* the struct as 32-bit words, in order */

/* Push constants of the counting shaders (selftest, indirect, busy). */
struct gpu_test_count {
    bf_u32 n;       /* elements, or groups for gpu_test_indirect */
    bf_u32 iters;   /* work per element (gpu_test_busy) */
};

#ifndef BF_GLSL
#include <stddef.h>
_Static_assert(sizeof(struct gpu_test_params) == 32, "gpu_test_params is 8 words");
_Static_assert(offsetof(struct gpu_test_params, offset) == 4, "std430 offset");
_Static_assert(offsetof(struct gpu_test_params, scale) == 8, "std430 offset");
_Static_assert(offsetof(struct gpu_test_params, seed) == 12, "std430 offset");
_Static_assert(offsetof(struct gpu_test_params, words) == 16, "std430 offset");
_Static_assert(sizeof(struct gpu_test_count) == 8, "gpu_test_count is 2 words");
#endif

#endif
