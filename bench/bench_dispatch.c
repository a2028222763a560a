/* What a dispatch and a pipeline barrier cost on this device, apart from
 * the shader's own work: 100 dispatches of an empty kernel (tests/gpu's
 * gpu_test_busy with no elements: every invocation returns at once) of 0,
 * 1, 64 and 1024 workgroups of 64 invocations, and 100 barriers, each in
 * one timed stage, GPU time from timestamps. On lavapipe a dispatch has a
 * fixed cost (its threads woken and joined) and every workgroup one more,
 * mostly the local invocation indices of each 8 lanes (16 integer
 * divisions by the workgroup's size): why the tracker's image kernels take
 * 8 pixels an invocation and the allocation's args pass is one workgroup
 * (docs/gpu.md, lavapipe notes).
 *
 *   build/bench/bench_dispatch [--reps N]    (N rounds, the median printed; default 5)
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_test_shaders_spv.h"
#include "gpu/gpu.h"
#include "../tests/gpu/shaders/gpu_test.glsl.h"

#define N_CMDS 100u

static double median(double *v, uint32_t n) { return bf_percentile_inplace(v, n, 50); }

/* The GPU time of N_CMDS dispatches of `groups` workgroups (UINT32_MAX: N_CMDS barriers). */
static bf_status time_cmds(gpu_context *ctx, gpu_pipeline *p, gpu_bindings *b, uint32_t groups, double *ms)
{
    bf_status s = gpu_begin(ctx);
    if (s != BF_OK) return s;
    gpu_cmd_stage_begin(ctx, "bench.cmds");
    struct gpu_test_count pc = {.n = 0, .iters = 0};
    for (uint32_t i = 0; i < N_CMDS; i++) {
        if (groups == UINT32_MAX) gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE);
        else gpu_cmd_dispatch_linear(ctx, p, b, &pc, groups);
    }
    gpu_cmd_stage_end(ctx);
    if ((s = gpu_submit_wait(ctx)) != BF_OK) return s;
    *ms = gpu_stage_ms(ctx, "bench.cmds") / N_CMDS;
    return BF_OK;
}

int main(int argc, char **argv)
{
    uint32_t reps = 5;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--reps") && i + 1 < argc) reps = (uint32_t)atoi(argv[++i]);
        else {
            fprintf(stderr, "usage: bench_dispatch [--reps N]\n");
            return strcmp(argv[i], "--help") ? 2 : 0;
        }
    }
    if (reps < 1 || reps > 1000) reps = 5;
    gpu_config cfg = {0};
    gpu_context *ctx = NULL;
    gpu_pipeline *p = NULL;
    gpu_bindings *b = NULL;
    gpu_buffer *data = NULL;
    gpu_buffer_desc bd = {.name = "bench.data", .size_bytes = 4096, .memory = GPU_MEMORY_DEVICE};
    gpu_pipeline_desc pd = {.name = "bench.empty", .spirv = bf_spv_gpu_test_busy, .spirv_bytes = bf_spv_gpu_test_busy_size,
                            .n_buffers = 1, .push_bytes = sizeof(struct gpu_test_count), .local_size = {64, 1, 1}};
    bf_status s = gpu_context_create(&cfg, &ctx);
    if (s == BF_OK) s = gpu_buffer_create(ctx, &bd, &data);
    if (s == BF_OK) s = gpu_buffer_zero(data);
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &p);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 1, "bench.empty", &b);
    if (s == BF_OK) s = gpu_bindings_set(b, 0, data, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_pipeline_warm_up(ctx, &p, 1);
    const uint32_t groups[] = {0, 1, 64, 1024, UINT32_MAX};
    const uint32_t n_kinds = sizeof groups / sizeof groups[0];
    double *ms = calloc((size_t)n_kinds * reps, sizeof *ms);
    if (s == BF_OK && !ms) s = bf_fail(BF_NO_MEMORY, "bench_dispatch: results");
    for (uint32_t r = 0; r < reps && s == BF_OK; r++)
        for (uint32_t k = 0; k < n_kinds && s == BF_OK; k++) s = time_cmds(ctx, p, b, groups[k], &ms[k * reps + r]);
    if (s == BF_OK) {
        printf("%s, %u commands a stage, median of %u rounds\n\n", gpu_device(ctx)->name, N_CMDS, reps);
        printf("| command | us each |\n|---|---|\n");
        for (uint32_t k = 0; k < n_kinds; k++) {
            double m = median(ms + k * reps, reps);
            if (groups[k] == UINT32_MAX) printf("| barrier (compute -> compute) | %.2f |\n", 1e3 * m);
            else printf("| dispatch of %u workgroups of 64 | %.2f |\n", groups[k], 1e3 * m);
        }
    } else {
        fprintf(stderr, "bench_dispatch: %s\n", bf_last_error());
    }
    free(ms);
    gpu_bindings_destroy(b);
    gpu_pipeline_destroy(p);
    gpu_buffer_destroy(data);
    gpu_context_destroy(ctx);
    return s == BF_OK ? 0 : 1;
}
