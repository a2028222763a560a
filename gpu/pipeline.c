/* Compute pipelines, binding sets, the persistent pipeline cache, warm-up. */
#include "gpu_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "shaders/bf_common.glsl.h"

/* ------------------------------------------------------------ set layouts */

bf_status gpu__set_layout(gpu_context *ctx, uint32_t n_buffers, VkDescriptorSetLayout *out)
{
    BF_ASSERT(n_buffers <= GPU_MAX_BINDINGS);
    if (ctx->set_layouts[n_buffers]) {
        *out = ctx->set_layouts[n_buffers];
        return BF_OK;
    }
    bf_status status = BF_OK;
    VkDescriptorSetLayoutBinding b[GPU_MAX_BINDINGS];
    for (uint32_t i = 0; i < n_buffers; i++)
        b[i] = (VkDescriptorSetLayoutBinding){
            .binding = i,
            .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
            .descriptorCount = 1,
            .stageFlags = VK_SHADER_STAGE_COMPUTE_BIT,
        };
    VkDescriptorSetLayoutCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO,
        .bindingCount = n_buffers,
        .pBindings = b,
    };
    VkDescriptorSetLayout layout = VK_NULL_HANDLE;
    GPU__CHECK(ctx->inst.vk.CreateDescriptorSetLayout(ctx->device, &info, NULL, &layout), "gpu.set_layout");
    gpu__name(ctx, VK_OBJECT_TYPE_DESCRIPTOR_SET_LAYOUT, (uint64_t)layout, "gpu.set_layout[%u buffers]", n_buffers);
    ctx->set_layouts[n_buffers] = layout;
    *out = layout;
fail:
    return status;
}

/* ------------------------------------------------------------ pipelines */

bf_status gpu_pipeline_create(gpu_context *ctx, const gpu_pipeline_desc *desc, gpu_pipeline **out)
{
    bf_status status = BF_OK;
    const char *name = desc->name ? desc->name : "unnamed pipeline";
    const gpu_limits *lim = &ctx->info.limits;
    uint32_t ls[3] = {desc->local_size[0], desc->local_size[1] ? desc->local_size[1] : 1,
                      desc->local_size[2] ? desc->local_size[2] : 1};
    if (!desc->spirv || desc->spirv_bytes == 0 || desc->spirv_bytes % 4)
        return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: no SPIR-V (or size %zu not a multiple of 4)", name,
                       desc->spirv_bytes);
    if (desc->n_buffers > GPU_MAX_BINDINGS || desc->n_buffers > lim->max_per_stage_storage_buffers)
        return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: %u storage buffers, at most %u (maxPerStageDescriptorStorageBuffers %u)",
                       name, desc->n_buffers, GPU_MAX_BINDINGS, lim->max_per_stage_storage_buffers);
    if (desc->push_bytes % 4 || desc->push_bytes > lim->max_push_constants_size)
        return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: push constants of %u bytes (multiple of 4, at most maxPushConstantsSize %u)",
                       name, desc->push_bytes, lim->max_push_constants_size);
    if (desc->n_spec > GPU_MAX_SPEC || (desc->n_spec && !desc->spec))
        return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: %u specialization constants, at most %u", name,
                       desc->n_spec, GPU_MAX_SPEC);
    if (ls[0] == 0) return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: local_size[0] is 0", name);
    for (int i = 0; i < 3; i++)
        if (ls[i] > lim->max_compute_workgroup_size[i])
            return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: local size %u in %c exceeds maxComputeWorkGroupSize %u",
                           name, ls[i], "xyz"[i], lim->max_compute_workgroup_size[i]);
    if ((uint64_t)ls[0] * ls[1] * ls[2] > lim->max_compute_workgroup_invocations)
        return bf_fail(BF_INVALID_ARG, "gpu pipeline %s: %u x %u x %u invocations exceed maxComputeWorkGroupInvocations %u",
                       name, ls[0], ls[1], ls[2], lim->max_compute_workgroup_invocations);

    gpu__vk *vk = &ctx->inst.vk;
    VkShaderModule module = VK_NULL_HANDLE;
    gpu_pipeline *p = calloc(1, sizeof *p);
    if (!p) return bf_fail(BF_NO_MEMORY, "gpu pipeline %s", name);
    p->ctx = ctx;
    p->n_buffers = desc->n_buffers;
    p->push_bytes = desc->push_bytes;
    memcpy(p->local_size, ls, sizeof ls);
    snprintf(p->name, sizeof p->name, "%s", name);

    VkDescriptorSetLayout set_layout;
    status = gpu__set_layout(ctx, desc->n_buffers, &set_layout);
    if (status != BF_OK) goto fail;
    VkPushConstantRange push = {.stageFlags = VK_SHADER_STAGE_COMPUTE_BIT, .size = desc->push_bytes};
    VkPipelineLayoutCreateInfo li = {
        .sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO,
        .setLayoutCount = 1,
        .pSetLayouts = &set_layout,
        .pushConstantRangeCount = desc->push_bytes ? 1 : 0,
        .pPushConstantRanges = &push,
    };
    GPU__CHECK(vk->CreatePipelineLayout(ctx->device, &li, NULL, &p->layout), p->name);
    gpu__name(ctx, VK_OBJECT_TYPE_PIPELINE_LAYOUT, (uint64_t)p->layout, "%s.layout", p->name);

    VkShaderModuleCreateInfo mi = {
        .sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO,
        .codeSize = desc->spirv_bytes,
        .pCode = desc->spirv,
    };
    GPU__CHECK(vk->CreateShaderModule(ctx->device, &mi, NULL, &module), p->name);
    gpu__name(ctx, VK_OBJECT_TYPE_SHADER_MODULE, (uint64_t)module, "%s.shader", p->name);

    /* Constant ids 0..2 are the local size (BF_LOCAL_SIZE_FROM_SPEC), the
     * caller's constants follow from BF_SPEC_USER. Entries for ids a shader
     * does not declare are ignored by Vulkan. */
    uint32_t values[3 + GPU_MAX_SPEC];
    VkSpecializationMapEntry entries[3 + GPU_MAX_SPEC];
    uint32_t n_entries = 0;
    for (uint32_t i = 0; i < 3 + desc->n_spec; i++) {
        values[i] = i < 3 ? ls[i] : desc->spec[i - 3];
        entries[n_entries++] = (VkSpecializationMapEntry){
            .constantID = i < 3 ? BF_SPEC_LOCAL_SIZE_X + i : BF_SPEC_USER + (i - 3),
            .offset = i * 4,
            .size = 4,
        };
    }
    VkSpecializationInfo spec = {
        .mapEntryCount = n_entries,
        .pMapEntries = entries,
        .dataSize = n_entries * 4,
        .pData = values,
    };
    VkComputePipelineCreateInfo ci = {
        .sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO,
        .stage = {
            .sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO,
            .stage = VK_SHADER_STAGE_COMPUTE_BIT,
            .module = module,
            .pName = "main",
            .pSpecializationInfo = &spec,
        },
        .layout = p->layout,
    };
    GPU__CHECK(vk->CreateComputePipelines(ctx->device, ctx->pipeline_cache, 1, &ci, NULL, &p->pipeline), p->name);
    gpu__name(ctx, VK_OBJECT_TYPE_PIPELINE, (uint64_t)p->pipeline, "%s", p->name);
    vk->DestroyShaderModule(ctx->device, module, NULL);
    *out = p;
    return BF_OK;

fail:
    if (module) vk->DestroyShaderModule(ctx->device, module, NULL);
    gpu_pipeline_destroy(p);
    return status;
}

void gpu_pipeline_destroy(gpu_pipeline *p)
{
    if (!p) return;
    gpu__vk *vk = &p->ctx->inst.vk;
    if (p->pipeline) vk->DestroyPipeline(p->ctx->device, p->pipeline, NULL);
    if (p->layout) vk->DestroyPipelineLayout(p->ctx->device, p->layout, NULL);
#ifndef NDEBUG
    memset(p, 0xff, sizeof *p);
#endif
    free(p);
}

const char *gpu_pipeline_name(const gpu_pipeline *p) { return p->name; }
void gpu_pipeline_local_size(const gpu_pipeline *p, uint32_t out[3]) { memcpy(out, p->local_size, sizeof p->local_size); }

/* ------------------------------------------------------------ bindings */

bf_status gpu_bindings_create(gpu_context *ctx, uint32_t n_buffers, const char *name, gpu_bindings **out)
{
    bf_status status = BF_OK;
    name = name ? name : "unnamed bindings";
    if (n_buffers > GPU_MAX_BINDINGS)
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s: %u buffers, at most %u", name, n_buffers, GPU_MAX_BINDINGS);
    if (ctx->n_bindings >= ctx->bindings_cap)
        return bf_fail(BF_POOL_FULL, "gpu bindings %s: all %u binding sets in use (gpu_config.bindings_cap)",
                       name, ctx->bindings_cap);
    gpu_bindings *b = calloc(1, sizeof *b);
    if (!b) return bf_fail(BF_NO_MEMORY, "gpu bindings %s", name);
    b->ctx = ctx;
    b->n_buffers = n_buffers;
    snprintf(b->name, sizeof b->name, "%s", name);
    VkDescriptorSetLayout layout;
    status = gpu__set_layout(ctx, n_buffers, &layout);
    if (status != BF_OK) goto fail;
    VkDescriptorSetAllocateInfo ai = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO,
        .descriptorPool = ctx->descriptor_pool,
        .descriptorSetCount = 1,
        .pSetLayouts = &layout,
    };
    VkResult r = GPU__CALL(ctx->inst.vk.AllocateDescriptorSets(ctx->device, &ai, &b->set));
    if (r == VK_ERROR_OUT_OF_POOL_MEMORY || r == VK_ERROR_FRAGMENTED_POOL) {
        status = bf_fail(BF_POOL_FULL, "gpu bindings %s: descriptor pool exhausted (%s)", name, gpu__vk_result_name(r));
        goto fail;
    }
    GPU__CHECK_RESULT(r, "vkAllocateDescriptorSets", b->name);
    gpu__name(ctx, VK_OBJECT_TYPE_DESCRIPTOR_SET, (uint64_t)b->set, "%s", b->name);
    ctx->n_bindings++;
    *out = b;
    return BF_OK;
fail:
    free(b);
    return status;
}

void gpu_bindings_destroy(gpu_bindings *b)
{
    if (!b) return;
    gpu_context *ctx = b->ctx;
    if (b->set) {
        ctx->inst.vk.FreeDescriptorSets(ctx->device, ctx->descriptor_pool, 1, &b->set);
        ctx->n_bindings--;
    }
#ifndef NDEBUG
    memset(b, 0xff, sizeof *b);
#endif
    free(b);
}

bf_status gpu_bindings_set(gpu_bindings *b, uint32_t slot, gpu_buffer *buf, uint64_t offset, uint64_t range)
{
    const gpu_limits *lim = &b->ctx->info.limits;
    if (slot >= b->n_buffers)
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s: slot %u of %u", b->name, slot, b->n_buffers);
    if (!(buf->usage & GPU_USAGE_STORAGE))
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s[%u]: buffer %s lacks GPU_USAGE_STORAGE", b->name, slot, buf->name);
    if (offset >= buf->size)
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s[%u]: offset %llu is past the end of %s (%llu bytes)", b->name,
                       slot, (unsigned long long)offset, buf->name, (unsigned long long)buf->size);
    if (range == GPU_WHOLE_SIZE) range = buf->size - offset;
    if (range == 0 || range > buf->size - offset)
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s[%u]: range %llu at %llu does not fit %s (%llu bytes)", b->name,
                       slot, (unsigned long long)range, (unsigned long long)offset, buf->name,
                       (unsigned long long)buf->size);
    if (range > lim->max_storage_buffer_range)
        return bf_fail(BF_INVALID_ARG,
                       "gpu bindings %s[%u]: %s: a binding of %llu bytes exceeds maxStorageBufferRange %llu "
                       "of %s; split the pool (gpu_bindings_needed)",
                       b->name, slot, buf->name, (unsigned long long)range,
                       (unsigned long long)lim->max_storage_buffer_range, b->ctx->info.name);
    if (lim->min_storage_buffer_offset_alignment && offset % lim->min_storage_buffer_offset_alignment)
        return bf_fail(BF_INVALID_ARG, "gpu bindings %s[%u]: offset %llu into %s is not a multiple of "
                       "minStorageBufferOffsetAlignment %llu", b->name, slot, (unsigned long long)offset, buf->name,
                       (unsigned long long)lim->min_storage_buffer_offset_alignment);
    VkDescriptorBufferInfo bi = {.buffer = buf->buffer, .offset = offset, .range = range};
    VkWriteDescriptorSet w = {
        .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET,
        .dstSet = b->set,
        .dstBinding = slot,
        .descriptorCount = 1,
        .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
        .pBufferInfo = &bi,
    };
    b->ctx->inst.vk.UpdateDescriptorSets(b->ctx->device, 1, &w, 0, NULL);
    b->set_mask |= 1u << slot;
    return BF_OK;
}

/* ------------------------------------------------------------ pipeline cache */

static void hex_uuid(const uint8_t *u, char out[2 * VK_UUID_SIZE + 1])
{
    for (unsigned i = 0; i < VK_UUID_SIZE; i++) snprintf(out + 2 * i, 3, "%02x", u[i]);
}

static bf_status cache_dir(const gpu_config *cfg, char *out, size_t cap)
{
    const char *dir = cfg && cfg->cache_dir ? cfg->cache_dir : getenv("BITFUSE_CACHE_DIR");
    if (dir && dir[0]) return bf_path_join(out, cap, NULL, dir);
    const char *xdg = getenv("XDG_CACHE_HOME");
    if (xdg && xdg[0]) return bf_path_join(out, cap, xdg, "bitfuse");
    const char *home = getenv("HOME");
    if (!home || !home[0]) return bf_fail(BF_IO, "gpu: no HOME for the pipeline cache (set BITFUSE_CACHE_DIR)");
    return bf_path_join(out, cap, home, ".cache/bitfuse");
}

/* Accepts data only if its header says it was made by this device and
 * driver (Vulkan spec, "Pipeline Cache Header"); else says why not. */
static const char *cache_header_problem(const gpu_context *ctx, const char *data, size_t size)
{
    VkPipelineCacheHeaderVersionOne h;
    if (size < sizeof h) return "shorter than its header";
    memcpy(&h, data, sizeof h);
    if (h.headerSize < sizeof h || h.headerSize > size) return "bad header size";
    if (h.headerVersion != VK_PIPELINE_CACHE_HEADER_VERSION_ONE) return "unknown header version";
    if (h.vendorID != ctx->info.vendor_id || h.deviceID != ctx->info.device_id) return "made by another device";
    if (memcmp(h.pipelineCacheUUID, ctx->info.pipeline_cache_uuid, VK_UUID_SIZE)) return "made by another driver version";
    return NULL;
}

bf_status gpu__pipeline_cache_open(gpu_context *ctx, const gpu_config *cfg)
{
    bf_status status = BF_OK;
    char *data = NULL;
    size_t size = 0;
    if (!(cfg && cfg->no_disk_cache)) {
        char dir[3900], file[96], uuid[2 * VK_UUID_SIZE + 1];
        hex_uuid(ctx->info.device_uuid, uuid);
        snprintf(file, sizeof file, "pipeline-cache-%s.bin", uuid);
        if (cache_dir(cfg, dir, sizeof dir) == BF_OK &&
            bf_path_join(ctx->cache_path, sizeof ctx->cache_path, dir, file) == BF_OK) {
            if (bf_file_exists(ctx->cache_path) && bf_read_file(ctx->cache_path, &data, &size) == BF_OK) {
                const char *problem = cache_header_problem(ctx, data, size);
                if (problem) {
                    bf_warn("gpu: ignoring pipeline cache %s: %s", ctx->cache_path, problem);
                    free(data);
                    data = NULL;
                    size = 0;
                }
            }
        } else {
            bf_warn("gpu: pipeline cache not persisted: %s", bf_last_error());
            ctx->cache_path[0] = '\0';
        }
    }
    VkPipelineCacheCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO,
        .initialDataSize = size,
        .pInitialData = data,
    };
    VkResult r = GPU__CALL(ctx->inst.vk.CreatePipelineCache(ctx->device, &info, NULL, &ctx->pipeline_cache));
    if (r != VK_SUCCESS && data) {
        bf_warn("gpu: pipeline cache %s rejected by the driver (%s); starting empty", ctx->cache_path,
                gpu__vk_result_name(r));
        info.initialDataSize = 0;
        info.pInitialData = NULL;
        size = 0;
        r = ctx->inst.vk.CreatePipelineCache(ctx->device, &info, NULL, &ctx->pipeline_cache);
    }
    free(data);
    GPU__CHECK_RESULT(r, "vkCreatePipelineCache", "gpu.pipeline_cache");
    gpu__name(ctx, VK_OBJECT_TYPE_PIPELINE_CACHE, (uint64_t)ctx->pipeline_cache, "gpu.pipeline_cache");
    ctx->cache_loaded_bytes = size;
    if (size) bf_debug("gpu: pipeline cache %s: %zu bytes loaded", ctx->cache_path, size);
fail:
    return status;
}

bf_status gpu_pipeline_cache_save(gpu_context *ctx)
{
    bf_status status = BF_OK;
    char *data = NULL;
    if (!ctx->cache_path[0] || !ctx->pipeline_cache) return BF_OK;
    size_t size = 0;
    GPU__CHECK(ctx->inst.vk.GetPipelineCacheData(ctx->device, ctx->pipeline_cache, &size, NULL), "gpu.pipeline_cache");
    data = malloc(size ? size : 1);
    if (!data) {
        status = bf_fail(BF_NO_MEMORY, "gpu: pipeline cache of %zu bytes", size);
        goto fail;
    }
    GPU__CHECK(ctx->inst.vk.GetPipelineCacheData(ctx->device, ctx->pipeline_cache, &size, data), "gpu.pipeline_cache");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", ctx->cache_path);
    char *slash = strrchr(dir, '/');
    if (slash && slash != dir) {
        *slash = '\0';
        status = bf_mkdir_p(dir);
        if (status != BF_OK) goto fail;
    }
    status = bf_write_file_atomic(ctx->cache_path, data, size);
fail:
    free(data);
    return status;
}

void gpu__pipeline_cache_close(gpu_context *ctx)
{
    if (!ctx->pipeline_cache) return;
    if (gpu_pipeline_cache_save(ctx) != BF_OK) bf_warn("gpu: pipeline cache not saved: %s", bf_last_error());
    ctx->inst.vk.DestroyPipelineCache(ctx->device, ctx->pipeline_cache, NULL);
    ctx->pipeline_cache = VK_NULL_HANDLE;
}

const char *gpu_pipeline_cache_path(const gpu_context *ctx) { return ctx->cache_path; }
size_t gpu_pipeline_cache_loaded_bytes(const gpu_context *ctx) { return ctx->cache_loaded_bytes; }

/* ------------------------------------------------------------ warm-up */

bf_status gpu_pipeline_warm_up(gpu_context *ctx, gpu_pipeline *const *pipes, uint32_t n)
{
    bf_status status = BF_OK;
    gpu_buffer *scratch = NULL;
    gpu_bindings *binds[GPU_MAX_BINDINGS + 1] = {0};
    static const uint32_t zeros[1024]; /* push constants: past any maxPushConstantsSize in use (128..256) */
    if (n == 0) return BF_OK;
    double t0 = bf_time_s();
    gpu_buffer_desc sd = {.name = "gpu.warm_up_scratch", .size_bytes = 64u << 10, .memory = GPU_MEMORY_DEVICE};
    status = gpu_buffer_create(ctx, &sd, &scratch);
    if (status != BF_OK) goto fail;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t nb = pipes[i]->n_buffers;
        if (nb == 0 || binds[nb]) continue;
        char name[64];
        snprintf(name, sizeof name, "gpu.warm_up[%u buffers]", nb);
        status = gpu_bindings_create(ctx, nb, name, &binds[nb]);
        for (uint32_t s = 0; s < nb && !status; s++) status = gpu_bindings_set(binds[nb], s, scratch, 0, GPU_WHOLE_SIZE);
        if (status != BF_OK) goto fail;
    }
    status = gpu_begin(ctx);
    if (status != BF_OK) goto fail;
    gpu_cmd_label_begin(ctx, "gpu.warm_up");
    for (uint32_t i = 0; i < n; i++) {
        const gpu_pipeline *p = pipes[i];
        BF_ASSERT(p->push_bytes <= sizeof zeros);
        /* Each pipeline starts from zeros: the fill waits for the previous
         * warm-up dispatch's writes, the dispatch waits for the fill. */
        gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
        gpu_cmd_fill(ctx, scratch, 0, GPU_WHOLE_SIZE, 0);
        gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
        gpu_cmd_dispatch(ctx, p, binds[p->n_buffers], p->push_bytes ? zeros : NULL, 1, 1, 1);
    }
    gpu_cmd_label_end(ctx);
    char names[256] = "";
    for (uint32_t i = 0, k = 0; i < n && k < sizeof names; i++)
        k += (size_t)snprintf(names + k, sizeof names - k, "%s%s", i ? ", " : "", pipes[i]->name);
    double t_wait = bf_time_s();
    ctx->warming = names;
    status = gpu_submit_wait(ctx);
    ctx->warming = NULL;
    if (status != BF_OK) goto fail;
    double wait_s = bf_time_s() - t_wait;
    if (wait_s * 1e9 > (double)GPU__COMPILE_NOTE_NS)
        bf_info("gpu: compiled %s in %.1f s", names, wait_s);
    bf_debug("gpu: warmed up %u pipelines in %.1f ms", n, 1e3 * (bf_time_s() - t0));

fail:
    for (uint32_t i = 0; i <= GPU_MAX_BINDINGS; i++) gpu_bindings_destroy(binds[i]);
    gpu_buffer_destroy(scratch);
    return status;
}
