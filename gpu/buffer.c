/* Buffers, memory types, synchronous transfers, pool splitting. */
#include "gpu_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/resource.h>

/* The first memory type allowed by type_bits that has all of required and
 * as many of the preferred flag sets (tried in order) as possible. */
static uint32_t find_memory_type(const gpu_context *ctx, uint32_t type_bits, VkMemoryPropertyFlags required,
                                 const VkMemoryPropertyFlags *preferred, int n_preferred)
{
    const VkPhysicalDeviceMemoryProperties *m = &ctx->mem_props;
    for (int p = 0; p <= n_preferred; p++) {
        VkMemoryPropertyFlags want = required | (p < n_preferred ? preferred[p] : 0);
        for (uint32_t i = 0; i < m->memoryTypeCount; i++)
            if ((type_bits & (1u << i)) && (m->memoryTypes[i].propertyFlags & want) == want) return i;
    }
    return UINT32_MAX;
}

/* The device address of a buffer made with GPU_USAGE_ADDRESS, once bound. */
static void set_address(gpu_buffer *buf)
{
    if (!(buf->usage & GPU_USAGE_ADDRESS)) return;
    VkBufferDeviceAddressInfo i = {.sType = VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO, .buffer = buf->buffer};
    buf->address = buf->ctx->inst.vk.GetBufferDeviceAddress(buf->ctx->device, &i);
}

static VkBufferUsageFlags vk_usage(uint32_t usage)
{
    VkBufferUsageFlags u = 0;
    if (usage & GPU_USAGE_STORAGE) u |= VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
    if (usage & GPU_USAGE_INDIRECT) u |= VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT;
    if (usage & GPU_USAGE_TRANSFER) u |= VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    if (usage & GPU_USAGE_ADDRESS) u |= VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT;
    return u;
}

/* The memory type for a buffer of this kind among type_bits: device
 * memory device-local first (on a UMA device and lavapipe it is also
 * host-visible and is then mapped, saving the staging copy); upload memory
 * host-visible, coherent if it can; readback memory host-visible, cached
 * and coherent if it can. */
static uint32_t choose_type(const gpu_context *ctx, gpu_memory kind, uint32_t type_bits)
{
    if (kind == GPU_MEMORY_DEVICE) {
        const VkMemoryPropertyFlags pref[] = {VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT};
        return find_memory_type(ctx, type_bits, 0, pref, 1);
    }
    if (kind == GPU_MEMORY_UPLOAD) {
        const VkMemoryPropertyFlags pref[] = {VK_MEMORY_PROPERTY_HOST_COHERENT_BIT};
        return find_memory_type(ctx, type_bits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, pref, 1);
    }
    const VkMemoryPropertyFlags pref[] = {
        VK_MEMORY_PROPERTY_HOST_CACHED_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT,
        VK_MEMORY_PROPERTY_HOST_CACHED_BIT, VK_MEMORY_PROPERTY_HOST_COHERENT_BIT};
    return find_memory_type(ctx, type_bits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, pref, 3);
}

/* Large buffers on a CPU device (gpu_context.host_import_align). */
static bool wants_import(const gpu_context *ctx, uint64_t bytes)
{
    return ctx->host_import_align && bytes >= GPU_HUGE_PAGE_MIN_BYTES;
}

/* An anonymous private mapping of bytes rounded up to whole huge pages,
 * aligned to one and advised onto them; NULL when the kernel refuses. */
static void *map_huge(size_t bytes, size_t *out_bytes)
{
    const size_t huge = (size_t)2 << 20;
    size_t n = (bytes + huge - 1) & ~(huge - 1);
    char *p = mmap(NULL, n + huge, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return NULL;
    char *a = (char *)(((uintptr_t)p + huge - 1) & ~(uintptr_t)(huge - 1));
    if (a > p) munmap(p, (size_t)(a - p));
    if (p + n + huge > a + n) munmap(a + n, (size_t)(p + n + huge - (a + n)));
    bf_advise_huge(a, n);
    *out_bytes = n;
    return a;
}

/* Backs buf with memory of our own mapping, imported: anonymous memory
 * takes transparent huge pages where the driver's memfd does not, so the
 * first touch of a large pool faults once per 2 MiB instead of per 4 KiB
 * and the shaders' scattered reads miss the TLB less. false (nothing
 * kept) when any step says no; the caller then allocates as usual. */
static bool import_host(gpu_buffer *buf, const VkMemoryRequirements *req)
{
    gpu_context *ctx = buf->ctx;
    gpu__vk *vk = &ctx->inst.vk;
    size_t n = 0;
    void *p = map_huge((size_t)req->size, &n);
    if (!p) return false;
    const uint64_t max_alloc = ctx->info.limits.max_memory_allocation_size;
    VkMemoryHostPointerPropertiesEXT hp = {.sType = VK_STRUCTURE_TYPE_MEMORY_HOST_POINTER_PROPERTIES_EXT};
    uint32_t type = UINT32_MAX;
    if ((!max_alloc || n <= max_alloc) &&
        ctx->GetMemoryHostPointerPropertiesEXT(ctx->device, VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT, p,
                                               &hp) == VK_SUCCESS)
        type = choose_type(ctx, buf->kind, req->memoryTypeBits & hp.memoryTypeBits);
    VkMemoryPropertyFlags flags = type == UINT32_MAX ? 0 : ctx->mem_props.memoryTypes[type].propertyFlags;
    if (!(flags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT)) goto no;
    VkMemoryAllocateFlagsInfo fl = {.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO,
                                     .flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT};
    VkImportMemoryHostPointerInfoEXT imp = {
        .sType = VK_STRUCTURE_TYPE_IMPORT_MEMORY_HOST_POINTER_INFO_EXT,
        .pNext = (buf->usage & GPU_USAGE_ADDRESS) ? &fl : NULL,
        .handleType = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT,
        .pHostPointer = p,
    };
    VkMemoryAllocateInfo ai = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, .pNext = &imp, .allocationSize = n, .memoryTypeIndex = type};
    if (vk->AllocateMemory(ctx->device, &ai, NULL, &buf->memory) != VK_SUCCESS) goto no;
    if (vk->BindBufferMemory(ctx->device, buf->buffer, buf->memory, 0) != VK_SUCCESS) {
        vk->FreeMemory(ctx->device, buf->memory, NULL);
        buf->memory = VK_NULL_HANDLE;
        goto no;
    }
    gpu__name(ctx, VK_OBJECT_TYPE_DEVICE_MEMORY, (uint64_t)buf->memory, "%s.memory (imported)", buf->name);
    buf->host_alloc = p;
    buf->host_alloc_bytes = n;
    buf->mapped = p; /* the memory is our mapping: no vkMapMemory */
    set_address(buf);
    buf->is_coherent = flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    buf->is_cached = flags & VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
    return true;
no:
    munmap(p, n);
    return false;
}

bf_status gpu_buffer_create(gpu_context *ctx, const gpu_buffer_desc *desc, gpu_buffer **out)
{
    bf_status status = BF_OK;
    const char *name = desc->name ? desc->name : "unnamed buffer";
    const gpu_limits *lim = &ctx->info.limits;
    if (desc->size_bytes == 0) return bf_fail(BF_INVALID_ARG, "gpu buffer %s: size 0", name);
    if (lim->max_memory_allocation_size && desc->size_bytes > lim->max_memory_allocation_size)
        return bf_fail(BF_NO_MEMORY, "gpu buffer %s: %llu bytes exceed maxMemoryAllocationSize %llu of %s",
                       name, (unsigned long long)desc->size_bytes,
                       (unsigned long long)lim->max_memory_allocation_size, ctx->info.name);
    gpu__vk *vk = &ctx->inst.vk;
    gpu_buffer *buf = calloc(1, sizeof *buf);
    if (!buf) return bf_fail(BF_NO_MEMORY, "gpu buffer %s", name);
    buf->ctx = ctx;
    buf->size = desc->size_bytes;
    buf->kind = desc->memory;
    buf->usage = desc->usage ? desc->usage : GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER;
    snprintf(buf->name, sizeof buf->name, "%s", name);

    const bool is_import = wants_import(ctx, desc->size_bytes);
    /* Declared importable; such a buffer may still be bound to ordinary
     * memory when the import says no. */
    VkExternalMemoryBufferCreateInfo ext = {
        .sType = VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO,
        .handleTypes = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT,
    };
    VkBufferCreateInfo bi = {
        .sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO,
        .pNext = is_import ? &ext : NULL,
        .size = desc->size_bytes,
        .usage = vk_usage(buf->usage),
        .sharingMode = VK_SHARING_MODE_EXCLUSIVE,
    };
    GPU__CHECK(vk->CreateBuffer(ctx->device, &bi, NULL, &buf->buffer), buf->name);
    gpu__name(ctx, VK_OBJECT_TYPE_BUFFER, (uint64_t)buf->buffer, "%s", buf->name);
    VkMemoryRequirements req;
    vk->GetBufferMemoryRequirements(ctx->device, buf->buffer, &req);
    if (is_import && import_host(buf, &req)) {
        *out = buf;
        return BF_OK;
    }

    /* lavapipe (Mesa 25) keeps device memory in a memfd it sizes with
     * ftruncate: past the file-size limit (ulimit -f) that kills the program
     * (SIGXFSZ) or, the signal ignored, faults on first touch (SIGBUS).
     * Refused here instead, by name. */
    struct rlimit fsize;
    if (ctx->info.type == VK_PHYSICAL_DEVICE_TYPE_CPU && getrlimit(RLIMIT_FSIZE, &fsize) == 0 &&
        fsize.rlim_cur != RLIM_INFINITY && req.size > (VkDeviceSize)fsize.rlim_cur) {
        status = bf_fail(BF_NO_MEMORY,
                         "gpu buffer %s: %llu bytes exceed the file-size limit (ulimit -f, %llu bytes): %s keeps "
                         "device memory in files",
                         buf->name, (unsigned long long)req.size, (unsigned long long)fsize.rlim_cur, ctx->info.name);
        goto fail;
    }
    uint32_t type = choose_type(ctx, desc->memory, req.memoryTypeBits);
    bool want_map = desc->memory != GPU_MEMORY_DEVICE || !ctx->force_staging;
    if (type == UINT32_MAX) {
        status = bf_fail(BF_UNSUPPORTED, "gpu buffer %s: no suitable memory type on %s", buf->name, ctx->info.name);
        goto fail;
    }
    VkMemoryPropertyFlags flags = ctx->mem_props.memoryTypes[type].propertyFlags;
    VkMemoryAllocateFlagsInfo fl = {.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO,
                                     .flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT};
    VkMemoryAllocateInfo ai = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO,
        .pNext = (buf->usage & GPU_USAGE_ADDRESS) ? &fl : NULL,
        .allocationSize = req.size,
        .memoryTypeIndex = type,
    };
    VkResult r = GPU__CALL(vk->AllocateMemory(ctx->device, &ai, NULL, &buf->memory));
    if (r != VK_SUCCESS) {
        status = gpu__vk_fail(r, "vkAllocateMemory", buf->name);
        if (status == BF_NO_MEMORY)
            bf_fail(BF_NO_MEMORY, "gpu buffer %s: vkAllocateMemory of %llu bytes of %s memory: %s", buf->name,
                    (unsigned long long)req.size,
                    flags & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT ? "device" : "host-visible",
                    gpu__vk_result_name(r));
        goto fail;
    }
    gpu__name(ctx, VK_OBJECT_TYPE_DEVICE_MEMORY, (uint64_t)buf->memory, "%s.memory", buf->name);
    GPU__CHECK(vk->BindBufferMemory(ctx->device, buf->buffer, buf->memory, 0), buf->name);
    set_address(buf);
    buf->is_coherent = flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    buf->is_cached = flags & VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
    if (want_map && (flags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT))
        GPU__CHECK(vk->MapMemory(ctx->device, buf->memory, 0, VK_WHOLE_SIZE, 0, &buf->mapped), buf->name);
    /* A large buffer the host maps (lavapipe: all of them) on huge pages
     * where the kernel gives them on request: the shaders' scattered reads
     * of the pools miss the TLB less. Elsewhere (device memory mapped
     * through a driver, or Mesa 25's memfd) the advice is refused, harmlessly. */
    if (buf->mapped && req.size >= GPU_HUGE_PAGE_MIN_BYTES) bf_advise_huge(buf->mapped, (size_t)req.size);
    *out = buf;
    return BF_OK;

fail:
    gpu_buffer_destroy(buf);
    return status;
}

void gpu_buffer_destroy(gpu_buffer *buf)
{
    if (!buf) return;
    gpu_context *ctx = buf->ctx;
    gpu__vk *vk = &ctx->inst.vk;
    if (buf->mapped && !buf->host_alloc) vk->UnmapMemory(ctx->device, buf->memory);
    if (buf->buffer) vk->DestroyBuffer(ctx->device, buf->buffer, NULL);
    if (buf->memory) vk->FreeMemory(ctx->device, buf->memory, NULL);
    if (buf->host_alloc) munmap(buf->host_alloc, buf->host_alloc_bytes); /* after the memory that used it */
#ifndef NDEBUG
    memset(buf, 0xff, sizeof *buf);
#endif
    free(buf);
}

uint64_t gpu_buffer_size(const gpu_buffer *buf) { return buf->size; }
uint64_t gpu_buffer_address(const gpu_buffer *buf) { return buf->address; }

bf_status gpu_address_table_create(gpu_context *ctx, const char *name, gpu_buffer *const *bufs, uint32_t n,
                                   gpu_buffer **out)
{
    if (!ctx || !name || !bufs || !out || n == 0) return bf_fail(BF_INVALID_ARG, "gpu: address table: no buffers");
    uint64_t *a = malloc((size_t)n * sizeof *a);
    if (!a) return bf_fail(BF_NO_MEMORY, "gpu: address table %s", name);
    bf_status s = BF_OK;
    for (uint32_t i = 0; i < n && s == BF_OK; i++) {
        a[i] = bufs[i] ? bufs[i]->address : 0;
        if (a[i] == 0)
            s = bf_fail(BF_INVALID_ARG, "gpu: address table %s: entry %u (%s) has no device address", name, i,
                        bufs[i] ? bufs[i]->name : "NULL");
    }
    gpu_buffer_desc d = {.name = name, .size_bytes = (uint64_t)n * sizeof *a, .memory = GPU_MEMORY_DEVICE};
    gpu_buffer *t = NULL;
    if (s == BF_OK) s = gpu_buffer_create(ctx, &d, &t);
    if (s == BF_OK) s = gpu_buffer_upload(t, 0, a, d.size_bytes);
    free(a);
    if (s != BF_OK) {
        gpu_buffer_destroy(t);
        return s;
    }
    *out = t;
    return BF_OK;
}
const char *gpu_buffer_name(const gpu_buffer *buf) { return buf->name; }
VkBuffer gpu_buffer_handle(const gpu_buffer *buf) { return buf->buffer; }
void *gpu_buffer_map(const gpu_buffer *buf) { return buf->mapped; }
void *gpu_buffer_map_cached(const gpu_buffer *buf) { return buf->is_cached && buf->is_coherent ? buf->mapped : NULL; }
bool gpu_buffer_is_imported(const gpu_buffer *buf) { return buf->host_alloc != NULL; }
bool gpu_buffer_created_zero(const gpu_buffer *buf) { return buf->host_alloc != NULL; }

bf_status gpu_buffer_flush(gpu_buffer *buf)
{
    if (!buf->mapped || buf->is_coherent) return BF_OK;
    bf_status status = BF_OK;
    VkMappedMemoryRange range = {
        .sType = VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE, .memory = buf->memory, .size = VK_WHOLE_SIZE};
    GPU__CHECK(buf->ctx->inst.vk.FlushMappedMemoryRanges(buf->ctx->device, 1, &range), buf->name);
fail:
    return status;
}

static bf_status invalidate(gpu_buffer *buf)
{
    if (!buf->mapped || buf->is_coherent) return BF_OK;
    bf_status status = BF_OK;
    VkMappedMemoryRange range = {
        .sType = VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE, .memory = buf->memory, .size = VK_WHOLE_SIZE};
    GPU__CHECK(buf->ctx->inst.vk.InvalidateMappedMemoryRanges(buf->ctx->device, 1, &range), buf->name);
fail:
    return status;
}

static bf_status check_range(const gpu_buffer *buf, const char *what, uint64_t offset, uint64_t size)
{
    if (offset > buf->size || size > buf->size - offset)
        return bf_fail(BF_INVALID_ARG, "gpu buffer %s: %s of %llu bytes at %llu passes its end (%llu bytes)",
                       buf->name, what, (unsigned long long)size, (unsigned long long)offset,
                       (unsigned long long)buf->size);
    if (!buf->mapped && !(buf->usage & GPU_USAGE_TRANSFER))
        return bf_fail(BF_INVALID_ARG, "gpu buffer %s: %s needs GPU_USAGE_TRANSFER (not mapped)", buf->name, what);
    return BF_OK;
}

/* ------------------------------------------------------------ transfers */

bf_status gpu__xfer_begin(gpu_context *ctx)
{
    bf_status status = BF_OK;
    gpu__vk *vk = &ctx->inst.vk;
    GPU__CHECK(vk->ResetCommandBuffer(ctx->xfer_cmd, 0), "gpu.xfer_cmd");
    VkCommandBufferBeginInfo bi = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
        .flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT,
    };
    GPU__CHECK(vk->BeginCommandBuffer(ctx->xfer_cmd, &bi), "gpu.xfer_cmd");
fail:
    return status;
}

bf_status gpu__xfer_submit_wait(gpu_context *ctx)
{
    bf_status status = BF_OK;
    gpu__vk *vk = &ctx->inst.vk;
    /* Publishes the transfer writes to the host (read after the fence) and
     * to any later submission. */
    VkMemoryBarrier mb = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
        .srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT,
        .dstAccessMask = VK_ACCESS_HOST_READ_BIT,
    };
    vk->CmdPipelineBarrier(ctx->xfer_cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb,
                           0, NULL, 0, NULL);
    GPU__CHECK(vk->EndCommandBuffer(ctx->xfer_cmd), "gpu.xfer_cmd");
    VkSubmitInfo si = {
        .sType = VK_STRUCTURE_TYPE_SUBMIT_INFO,
        .commandBufferCount = 1,
        .pCommandBuffers = &ctx->xfer_cmd,
    };
    GPU__CHECK(vk->ResetFences(ctx->device, 1, &ctx->xfer_fence), "gpu.xfer_fence");
    GPU__CHECK(vk->QueueSubmit(ctx->queue, 1, &si, ctx->xfer_fence), "gpu.xfer_cmd");
    GPU__CHECK(vk->WaitForFences(ctx->device, 1, &ctx->xfer_fence, VK_TRUE, 600ull * 1000000000ull),
               "gpu.xfer_fence");
    return BF_OK;
fail:
    /* The transfer may still run: settle it so the caller can free the
     * buffers (on a lost device this returns at once). */
    vk->DeviceWaitIdle(ctx->device);
    return status;
}

/* One staged copy of n bytes: host -> staging -> buf (is_up) or back. */
static bf_status staged(gpu_buffer *buf, uint64_t offset, void *host, uint64_t n, bool is_up)
{
    gpu_context *ctx = buf->ctx;
    gpu_buffer *st = ctx->staging;
    BF_ASSERT(st && n <= st->size);
    if (is_up) {
        memcpy(st->mapped, host, n);
        bf_status s = gpu_buffer_flush(st);
        if (s != BF_OK) return s;
    }
    bf_status s = gpu__xfer_begin(ctx);
    if (s != BF_OK) return s;
    VkBufferCopy region = {.srcOffset = is_up ? 0 : offset, .dstOffset = is_up ? offset : 0, .size = n};
    ctx->inst.vk.CmdCopyBuffer(ctx->xfer_cmd, is_up ? st->buffer : buf->buffer, is_up ? buf->buffer : st->buffer,
                               1, &region);
    s = gpu__xfer_submit_wait(ctx);
    if (s != BF_OK) return s;
    if (!is_up) {
        s = invalidate(st);
        if (s != BF_OK) return s;
        memcpy(host, st->mapped, n);
    }
    return BF_OK;
}

static bf_status transfer(gpu_buffer *buf, uint64_t offset, void *host, uint64_t size, bool is_up)
{
    bf_status s = check_range(buf, is_up ? "upload" : "download", offset, size);
    if (s != BF_OK) return s;
    if (size == 0) return BF_OK;
    if (buf->mapped) {
        if (is_up) {
            memcpy((char *)buf->mapped + offset, host, size);
            return gpu_buffer_flush(buf);
        }
        s = invalidate(buf);
        if (s != BF_OK) return s;
        memcpy(host, (const char *)buf->mapped + offset, size);
        return BF_OK;
    }
    BF_ASSERT(buf->ctx->staging); /* a buffer is unmapped only when staging exists */
    uint64_t chunk = buf->ctx->staging->size;
    for (uint64_t done = 0; done < size; done += chunk) {
        uint64_t n = size - done < chunk ? size - done : chunk;
        s = staged(buf, offset + done, (char *)host + done, n, is_up);
        if (s != BF_OK) return s;
    }
    return BF_OK;
}

bf_status gpu_buffer_upload(gpu_buffer *buf, uint64_t offset, const void *src, uint64_t size)
{
    return transfer(buf, offset, (void *)src, size, true); /* src is only read when is_up */
}

bf_status gpu_buffer_download(gpu_buffer *buf, uint64_t offset, void *dst, uint64_t size)
{
    return transfer(buf, offset, dst, size, false);
}

bf_status gpu_buffer_fill(gpu_buffer *buf, uint64_t offset, uint64_t size, uint32_t value)
{
    if (offset % 4 || size % 4)
        return bf_fail(BF_INVALID_ARG, "gpu buffer %s: fill offset %llu and size %llu must be multiples of 4",
                       buf->name, (unsigned long long)offset, (unsigned long long)size);
    bf_status s = check_range(buf, "fill", offset, size);
    if (s != BF_OK) return s;
    if (size == 0) return BF_OK;
    if (buf->mapped) {
        uint32_t *w = (uint32_t *)((char *)buf->mapped + offset);
        for (uint64_t i = 0; i < size / 4; i++) w[i] = value;
        return gpu_buffer_flush(buf);
    }
    s = gpu__xfer_begin(buf->ctx);
    if (s != BF_OK) return s;
    buf->ctx->inst.vk.CmdFillBuffer(buf->ctx->xfer_cmd, buf->buffer, offset, size, value);
    return gpu__xfer_submit_wait(buf->ctx);
}

/* ------------------------------------------------------------ pool split */

static uint64_t gcd64(uint64_t a, uint64_t b)
{
    while (b) {
        uint64_t t = a % b;
        a = b;
        b = t;
    }
    return a;
}

uint64_t gpu_binding_max_bytes(const gpu_context *ctx, uint32_t elem_bytes)
{
    const gpu_limits *lim = &ctx->info.limits;
    uint64_t e = elem_bytes ? elem_bytes : 1;
    uint64_t a = lim->min_storage_buffer_offset_alignment ? lim->min_storage_buffer_offset_alignment : 1;
    uint64_t step = e / gcd64(e, a) * a; /* lcm: whole elements, aligned next offset */
    return lim->max_storage_buffer_range / step * step;
}

uint32_t gpu_bindings_needed(const gpu_context *ctx, uint64_t pool_bytes, uint32_t elem_bytes)
{
    uint64_t per = gpu_binding_max_bytes(ctx, elem_bytes);
    if (per == 0) return UINT32_MAX; /* one element does not fit a binding */
    uint64_t n = (pool_bytes + per - 1) / per;
    return n > UINT32_MAX ? UINT32_MAX : (uint32_t)n;
}
