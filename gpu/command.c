/* Recording, barriers, submission and per-stage timestamps. */
#include "gpu_int.h"

#include <stdio.h>
#include <string.h>

/* A submission that takes longer than this is treated as a hung device. */
#define GPU_FENCE_TIMEOUT_NS (600ull * 1000000000ull)

bf_status gpu_begin(gpu_context *ctx)
{
    BF_ASSERT(!ctx->is_recording);
    bf_status status = BF_OK;
    gpu__vk *vk = &ctx->inst.vk;
    GPU__CHECK(vk->ResetCommandBuffer(ctx->cmd, 0), "gpu.cmd");
    VkCommandBufferBeginInfo bi = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
        .flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT,
    };
    GPU__CHECK(vk->BeginCommandBuffer(ctx->cmd, &bi), "gpu.cmd");
    if (ctx->query_pool) vk->CmdResetQueryPool(ctx->cmd, ctx->query_pool, 0, 2 * ctx->stage_cap);
    ctx->is_recording = true;
    ctx->n_stages = 0;
    ctx->is_stage_open = false;
    ctx->label_depth = 0;
fail:
    return status;
}

static void bind(gpu_context *ctx, const gpu_pipeline *p, const gpu_bindings *b, const void *push)
{
    BF_ASSERT(ctx->is_recording);
    BF_ASSERT(p->ctx == ctx);
    gpu__vk *vk = &ctx->inst.vk;
    vk->CmdBindPipeline(ctx->cmd, VK_PIPELINE_BIND_POINT_COMPUTE, p->pipeline);
    if (p->n_buffers) {
        BF_ASSERT(b && b->n_buffers == p->n_buffers);
        BF_ASSERT(b->set_mask == (1u << p->n_buffers) - 1u); /* every slot bound */
        vk->CmdBindDescriptorSets(ctx->cmd, VK_PIPELINE_BIND_POINT_COMPUTE, p->layout, 0, 1, &b->set, 0, NULL);
    }
    if (p->push_bytes) {
        BF_ASSERT(push);
        vk->CmdPushConstants(ctx->cmd, p->layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, p->push_bytes, push);
    }
}

void gpu_cmd_dispatch(gpu_context *ctx, const gpu_pipeline *p, const gpu_bindings *b, const void *push,
                      uint32_t gx, uint32_t gy, uint32_t gz)
{
    const uint32_t *max = ctx->info.limits.max_compute_workgroup_count;
    BF_ASSERT(gx <= max[0] && gy <= max[1] && gz <= max[2]);
    bind(ctx, p, b, push);
    ctx->inst.vk.CmdDispatch(ctx->cmd, gx, gy, gz);
}

void gpu_cmd_dispatch_linear(gpu_context *ctx, const gpu_pipeline *p, const gpu_bindings *b, const void *push,
                             uint32_t n_groups)
{
    uint32_t max_x = ctx->info.limits.max_compute_workgroup_count[0];
    uint32_t gx = n_groups < max_x ? n_groups : max_x;
    gpu_cmd_dispatch(ctx, p, b, push, gx, gx ? (n_groups + gx - 1) / gx : 0, 1);
}

void gpu_cmd_dispatch_indirect(gpu_context *ctx, const gpu_pipeline *p, const gpu_bindings *b, const void *push,
                               const gpu_buffer *args, uint64_t offset)
{
    BF_ASSERT(offset % 4 == 0 && offset + 12 <= args->size);
    bind(ctx, p, b, push);
    ctx->inst.vk.CmdDispatchIndirect(ctx->cmd, args->buffer, offset);
}

void gpu_cmd_barrier(gpu_context *ctx, gpu_barrier kind)
{
    BF_ASSERT(ctx->is_recording);
    VkPipelineStageFlags src = 0, dst = 0;
    VkAccessFlags src_access = 0, dst_access = 0;
    const VkAccessFlags shader_rw = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
    switch (kind) {
    case GPU_BARRIER_COMPUTE:
        src = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        src_access = VK_ACCESS_SHADER_WRITE_BIT;
        dst = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        dst_access = shader_rw;
        break;
    case GPU_BARRIER_INDIRECT:
        src = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        src_access = VK_ACCESS_SHADER_WRITE_BIT;
        /* vkCmdDispatchIndirect reads its arguments in the DRAW_INDIRECT stage. */
        dst = VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        dst_access = VK_ACCESS_INDIRECT_COMMAND_READ_BIT | shader_rw;
        break;
    case GPU_BARRIER_TRANSFER_TO_COMPUTE:
        src = VK_PIPELINE_STAGE_TRANSFER_BIT;
        src_access = VK_ACCESS_TRANSFER_WRITE_BIT;
        dst = VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        dst_access = VK_ACCESS_INDIRECT_COMMAND_READ_BIT | shader_rw;
        break;
    case GPU_BARRIER_COMPUTE_TO_TRANSFER:
        src = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
        src_access = VK_ACCESS_SHADER_WRITE_BIT;
        dst = VK_PIPELINE_STAGE_TRANSFER_BIT;
        dst_access = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
        break;
    case GPU_BARRIER_TRANSFER:
        src = VK_PIPELINE_STAGE_TRANSFER_BIT;
        src_access = VK_ACCESS_TRANSFER_WRITE_BIT;
        dst = VK_PIPELINE_STAGE_TRANSFER_BIT;
        dst_access = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
        break;
    case GPU_BARRIER_HOST:
        src = VK_PIPELINE_STAGE_ALL_COMMANDS_BIT;
        src_access = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
        dst = VK_PIPELINE_STAGE_HOST_BIT;
        dst_access = VK_ACCESS_HOST_READ_BIT;
        break;
    default: BF_ASSERT(!"unknown gpu_barrier");
    }
    VkMemoryBarrier mb = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
        .srcAccessMask = src_access,
        .dstAccessMask = dst_access,
    };
    ctx->inst.vk.CmdPipelineBarrier(ctx->cmd, src, dst, 0, 1, &mb, 0, NULL, 0, NULL);
}

void gpu_cmd_copy(gpu_context *ctx, const gpu_buffer *src, uint64_t src_offset, gpu_buffer *dst,
                  uint64_t dst_offset, uint64_t size)
{
    BF_ASSERT(ctx->is_recording);
    BF_ASSERT((src->usage & GPU_USAGE_TRANSFER) && (dst->usage & GPU_USAGE_TRANSFER));
    BF_ASSERT(src_offset <= src->size && size <= src->size - src_offset);
    BF_ASSERT(dst_offset <= dst->size && size <= dst->size - dst_offset);
    VkBufferCopy region = {.srcOffset = src_offset, .dstOffset = dst_offset, .size = size};
    ctx->inst.vk.CmdCopyBuffer(ctx->cmd, src->buffer, dst->buffer, 1, &region);
}

void gpu_cmd_fill(gpu_context *ctx, gpu_buffer *dst, uint64_t offset, uint64_t size, uint32_t value)
{
    BF_ASSERT(ctx->is_recording);
    BF_ASSERT(dst->usage & GPU_USAGE_TRANSFER);
    BF_ASSERT(offset % 4 == 0 && offset < dst->size);
    BF_ASSERT(size == GPU_WHOLE_SIZE || (size % 4 == 0 && size <= dst->size - offset));
    ctx->inst.vk.CmdFillBuffer(ctx->cmd, dst->buffer, offset, size == GPU_WHOLE_SIZE ? VK_WHOLE_SIZE : size, value);
}

void gpu_cmd_label_begin(gpu_context *ctx, const char *name)
{
    BF_ASSERT(ctx->is_recording);
    ctx->label_depth++;
    if (!ctx->inst.vk.CmdBeginDebugUtilsLabelEXT) return;
    VkDebugUtilsLabelEXT label = {.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_LABEL_EXT, .pLabelName = name};
    ctx->inst.vk.CmdBeginDebugUtilsLabelEXT(ctx->cmd, &label);
}

void gpu_cmd_label_end(gpu_context *ctx)
{
    BF_ASSERT(ctx->is_recording && ctx->label_depth > 0);
    ctx->label_depth--;
    if (ctx->inst.vk.CmdEndDebugUtilsLabelEXT) ctx->inst.vk.CmdEndDebugUtilsLabelEXT(ctx->cmd);
}

/* Both timestamps are written at BOTTOM_OF_PIPE: the begin stamp when all
 * earlier commands have finished, the end stamp when the stage's own have,
 * so consecutive stages neither overlap nor leave gaps uncounted. */
bf_status gpu_cmd_stage_begin(gpu_context *ctx, const char *name)
{
    BF_ASSERT(ctx->is_recording && !ctx->is_stage_open);
    ctx->is_stage_open = true;
    ctx->is_stage_timed = false;
    gpu_cmd_label_begin(ctx, name);
    if (!ctx->query_pool) return bf_fail(BF_UNSUPPORTED, "gpu stage %s: %s has no timestamps", name, ctx->info.name);
    if (ctx->n_stages >= ctx->stage_cap)
        return bf_fail(BF_POOL_FULL, "gpu stage %s: all %u timed stages of this submission used (gpu_config.stage_cap)",
                       name, ctx->stage_cap);
    gpu_stage_time *st = &ctx->stages[ctx->n_stages];
    *st = (gpu_stage_time){.ms = 0.0};
    snprintf(st->name, sizeof st->name, "%s", name);
    ctx->inst.vk.CmdWriteTimestamp(ctx->cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, ctx->query_pool,
                                   2 * ctx->n_stages);
    ctx->n_stages++;
    ctx->is_stage_timed = true;
    return BF_OK;
}

void gpu_cmd_stage_end(gpu_context *ctx)
{
    BF_ASSERT(ctx->is_recording && ctx->is_stage_open);
    ctx->is_stage_open = false;
    if (ctx->is_stage_timed)
        ctx->inst.vk.CmdWriteTimestamp(ctx->cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, ctx->query_pool,
                                       2 * (ctx->n_stages - 1) + 1);
    gpu_cmd_label_end(ctx);
}

static bf_status read_timestamps(gpu_context *ctx)
{
    bf_status status = BF_OK;
    uint32_t n = ctx->n_stages;
    if (!ctx->query_pool || n == 0) return BF_OK;
    uint64_t ticks[2 * 64];
    const gpu_limits *lim = &ctx->info.limits;
    uint64_t mask = lim->timestamp_valid_bits >= 64 ? UINT64_MAX : (1ull << lim->timestamp_valid_bits) - 1ull;
    for (uint32_t first = 0; first < n; first += 64) {
        uint32_t k = n - first < 64 ? n - first : 64;
        GPU__CHECK(ctx->inst.vk.GetQueryPoolResults(ctx->device, ctx->query_pool, 2 * first, 2 * k, sizeof ticks,
                                                    ticks, sizeof ticks[0],
                                                    VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
                   "gpu.timestamps");
        for (uint32_t i = 0; i < k; i++) {
            gpu_stage_time *st = &ctx->stages[first + i];
            st->begin_ticks = ticks[2 * i] & mask;
            st->end_ticks = ticks[2 * i + 1] & mask;
            /* Differences modulo 2^validBits survive a counter wrap. */
            st->ms = (double)((st->end_ticks - st->begin_ticks) & mask) * lim->timestamp_period_ns * 1e-6;
        }
    }
fail:
    return status;
}

bf_status gpu_submit_wait(gpu_context *ctx) { return gpu__submit_wait_signal(ctx, VK_NULL_HANDLE); }

bf_status gpu__submit_wait_signal(gpu_context *ctx, VkSemaphore semaphore)
{
    BF_ASSERT(ctx->is_recording);
    BF_ASSERT(!ctx->is_stage_open && ctx->label_depth == 0);
    bf_status status = BF_OK;
    gpu__vk *vk = &ctx->inst.vk;
    /* Publishes every write of the submission to host reads after the fence
     * (downloads, mapped READBACK buffers). */
    gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
    ctx->is_recording = false;
    GPU__CHECK(vk->EndCommandBuffer(ctx->cmd), "gpu.cmd");
    VkSubmitInfo si = {
        .sType = VK_STRUCTURE_TYPE_SUBMIT_INFO,
        .commandBufferCount = 1,
        .pCommandBuffers = &ctx->cmd,
        .signalSemaphoreCount = semaphore ? 1 : 0,
        .pSignalSemaphores = &semaphore,
    };
    GPU__CHECK(vk->ResetFences(ctx->device, 1, &ctx->fence), "gpu.fence");
    GPU__CHECK(vk->QueueSubmit(ctx->queue, 1, &si, ctx->fence), "gpu.cmd");
    if (ctx->warming && !ctx->said_compiling) {
        /* Not a fault-injection point (whether it times out is timing): the
         * wait below, at once when this one saw the fence, is the one. */
        VkResult rn = vk->WaitForFences(ctx->device, 1, &ctx->fence, VK_TRUE, GPU__COMPILE_NOTE_NS);
        if (rn == VK_TIMEOUT) {
            ctx->said_compiling = true;
            bf_info("gpu: %s is compiling shaders at their first use (%s); on a machine's first start with this "
                    "driver that takes up to a minute, and the driver's disk cache keeps them for later starts",
                    ctx->info.name, ctx->warming);
        }
    }
    VkResult r = GPU__CALL(vk->WaitForFences(ctx->device, 1, &ctx->fence, VK_TRUE, GPU_FENCE_TIMEOUT_NS));
    if (r == VK_TIMEOUT) {
        status = bf_fail(BF_VULKAN, "vkWaitForFences: gpu.fence: the submission did not finish in %llu s on %s",
                         GPU_FENCE_TIMEOUT_NS / 1000000000ull, ctx->info.name);
        goto fail;
    }
    GPU__CHECK_RESULT(r, "vkWaitForFences", "gpu.fence");
    return read_timestamps(ctx);
fail:
    /* The submission may still run: settle it so the caller can free what
     * it uses (on a lost device this returns at once). */
    vk->DeviceWaitIdle(ctx->device);
    return status;
}

uint32_t gpu_stage_times(const gpu_context *ctx, const gpu_stage_time **out)
{
    *out = ctx->stages;
    return ctx->n_stages;
}

double gpu_stage_ms(const gpu_context *ctx, const char *prefix)
{
    size_t n = strlen(prefix);
    double ms = 0;
    for (uint32_t i = 0; i < ctx->n_stages; i++)
        if (!strncmp(ctx->stages[i].name, prefix, n)) ms += ctx->stages[i].ms;
    return ms;
}
