/* Presentation: a swapchain on the context's surface, filled by a buffer
 * copy (compute queues may copy into images; no graphics pipeline). The
 * shape follows vkcube's (KhronosGroup/Vulkan-Tools cube/cube.c:
 * demo_prepare_buffers), with an acquire fence instead of a semaphore
 * because the context waits for every submission anyway. */
#include "gpu_int.h"

#include <stdlib.h>
#include <string.h>

#define GPU__MAX_IMAGES 8

struct gpu_swapchain {
    gpu_context *ctx;
    VkSwapchainKHR swapchain;
    VkFormat format;
    VkPresentModeKHR mode;
    VkExtent2D extent;
    bool can_read;
    uint32_t n_images;
    VkImage images[GPU__MAX_IMAGES];
    VkSemaphore done[GPU__MAX_IMAGES]; /* the submission that filled image i -> its presentation */
    VkFence acquired;
    uint32_t index;                    /* the acquired image, UINT32_MAX when none */
};

/* 8-bit RGBA or BGRA, UNORM or sRGB: the bytes are copied as they are, and
 * the ray-cast's colours are display values already. */
static bool pick_format(const VkSurfaceFormatKHR *f, uint32_t n, VkSurfaceFormatKHR *out)
{
    static const VkFormat wanted[] = {VK_FORMAT_B8G8R8A8_UNORM, VK_FORMAT_R8G8B8A8_UNORM, VK_FORMAT_B8G8R8A8_SRGB,
                                      VK_FORMAT_R8G8B8A8_SRGB};
    for (size_t w = 0; w < sizeof wanted / sizeof wanted[0]; w++)
        for (uint32_t i = 0; i < n; i++)
            if (f[i].format == wanted[w]) {
                *out = f[i];
                return true;
            }
    return false;
}

/* Mailbox or immediate when offered: a scan's loop should not wait for the
 * display's refresh; FIFO is always there. */
static VkPresentModeKHR pick_mode(const VkPresentModeKHR *m, uint32_t n)
{
    static const VkPresentModeKHR wanted[] = {VK_PRESENT_MODE_MAILBOX_KHR, VK_PRESENT_MODE_IMMEDIATE_KHR};
    for (size_t w = 0; w < 2; w++)
        for (uint32_t i = 0; i < n; i++)
            if (m[i] == wanted[w]) return wanted[w];
    return VK_PRESENT_MODE_FIFO_KHR;
}

static void release_images(gpu_swapchain *sc)
{
    gpu__vk *vk = &sc->ctx->inst.vk;
    for (uint32_t i = 0; i < GPU__MAX_IMAGES; i++)
        if (sc->done[i]) {
            vk->DestroySemaphore(sc->ctx->device, sc->done[i], NULL);
            sc->done[i] = VK_NULL_HANDLE;
        }
    sc->n_images = 0;
}

/* (Re)makes the swapchain at about width x height; the old one is handed to
 * the new as oldSwapchain and destroyed after. */
static bf_status build(gpu_swapchain *sc, uint32_t width, uint32_t height)
{
    bf_status status = BF_OK;
    gpu_context *ctx = sc->ctx;
    gpu__vk *vk = &ctx->inst.vk;
    VkSurfaceCapabilitiesKHR caps;
    GPU__CHECK(vk->GetPhysicalDeviceSurfaceCapabilitiesKHR(ctx->phys, ctx->surface, &caps), "gpu.surface");
    VkSurfaceFormatKHR formats[64];
    uint32_t n_formats = 64;
    VkResult r = vk->GetPhysicalDeviceSurfaceFormatsKHR(ctx->phys, ctx->surface, &n_formats, formats);
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) GPU__CHECK_RESULT(r, "vkGetPhysicalDeviceSurfaceFormatsKHR", "gpu.surface");
    VkSurfaceFormatKHR format;
    if (!pick_format(formats, n_formats, &format)) {
        status = bf_fail(BF_UNSUPPORTED, "%s: the window's surface offers no 8-bit RGBA or BGRA format", ctx->info.name);
        goto fail;
    }
    VkPresentModeKHR modes[16];
    uint32_t n_modes = 16;
    r = vk->GetPhysicalDeviceSurfacePresentModesKHR(ctx->phys, ctx->surface, &n_modes, modes);
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) GPU__CHECK_RESULT(r, "vkGetPhysicalDeviceSurfacePresentModesKHR", "gpu.surface");
    if (!(caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT)) {
        status = bf_fail(BF_UNSUPPORTED, "%s: the window's images cannot be copied into (no TRANSFER_DST)",
                         ctx->info.name);
        goto fail;
    }
    /* 0xFFFFFFFF: the surface takes the swapchain's size (vkcube). */
    VkExtent2D extent = caps.currentExtent;
    if (extent.width == UINT32_MAX) {
        extent.width = width < caps.minImageExtent.width ? caps.minImageExtent.width
                       : width > caps.maxImageExtent.width ? caps.maxImageExtent.width : width;
        extent.height = height < caps.minImageExtent.height ? caps.minImageExtent.height
                        : height > caps.maxImageExtent.height ? caps.maxImageExtent.height : height;
    }
    if (extent.width == 0 || extent.height == 0) extent = (VkExtent2D){1, 1}; /* a minimised window */
    uint32_t n_images = caps.minImageCount + 1;
    if (caps.maxImageCount && n_images > caps.maxImageCount) n_images = caps.maxImageCount;
    if (n_images > GPU__MAX_IMAGES) n_images = GPU__MAX_IMAGES;
    bool can_read = caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
    VkSwapchainKHR old = sc->swapchain;
    VkSwapchainCreateInfoKHR info = {
        .sType = VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR,
        .surface = ctx->surface,
        .minImageCount = n_images,
        .imageFormat = format.format,
        .imageColorSpace = format.colorSpace,
        .imageExtent = extent,
        .imageArrayLayers = 1,
        .imageUsage = VK_IMAGE_USAGE_TRANSFER_DST_BIT | (can_read ? VK_IMAGE_USAGE_TRANSFER_SRC_BIT : 0),
        .imageSharingMode = VK_SHARING_MODE_EXCLUSIVE,
        .preTransform = (caps.supportedTransforms & VK_SURFACE_TRANSFORM_IDENTITY_BIT_KHR)
                            ? VK_SURFACE_TRANSFORM_IDENTITY_BIT_KHR : caps.currentTransform,
        .compositeAlpha = (caps.supportedCompositeAlpha & VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR)
                              ? VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR
                              : (VkCompositeAlphaFlagBitsKHR)(caps.supportedCompositeAlpha & -caps.supportedCompositeAlpha),
        .presentMode = pick_mode(modes, n_modes),
        .clipped = VK_TRUE,
        .oldSwapchain = old,
    };
    vk->DeviceWaitIdle(ctx->device); /* nothing may use the old images' semaphores */
    VkSwapchainKHR made = VK_NULL_HANDLE;
    GPU__CHECK(vk->CreateSwapchainKHR(ctx->device, &info, NULL, &made), "gpu.swapchain");
    if (old) vk->DestroySwapchainKHR(ctx->device, old, NULL);
    release_images(sc);
    sc->swapchain = made;
    gpu__name(ctx, VK_OBJECT_TYPE_SWAPCHAIN_KHR, (uint64_t)made, "gpu.swapchain");
    /* The driver may make more images than asked for: every one of them can
     * be acquired, so each needs its place here. */
    uint32_t n = 0;
    GPU__CHECK(vk->GetSwapchainImagesKHR(ctx->device, made, &n, NULL), "gpu.swapchain");
    if (n > GPU__MAX_IMAGES) {
        status = bf_fail(BF_UNSUPPORTED, "gpu.swapchain: the driver made %u images, more than the %d kept", n,
                         GPU__MAX_IMAGES);
        goto fail;
    }
    GPU__CHECK(vk->GetSwapchainImagesKHR(ctx->device, made, &n, sc->images), "gpu.swapchain");
    VkSemaphoreCreateInfo si = {.sType = VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
    for (uint32_t i = 0; i < n; i++) {
        GPU__CHECK(vk->CreateSemaphore(ctx->device, &si, NULL, &sc->done[i]), "gpu.swapchain.done");
        gpu__name(ctx, VK_OBJECT_TYPE_SEMAPHORE, (uint64_t)sc->done[i], "gpu.swapchain.done[%u]", i);
        gpu__name(ctx, VK_OBJECT_TYPE_IMAGE, (uint64_t)sc->images[i], "gpu.swapchain.image[%u]", i);
    }
    sc->n_images = n;
    sc->format = format.format;
    sc->mode = info.presentMode;
    sc->extent = extent;
    sc->can_read = can_read;
    sc->index = UINT32_MAX;
fail:
    return status;
}

bf_status gpu_swapchain_create(gpu_context *ctx, uint32_t width, uint32_t height, gpu_swapchain **out)
{
    if (!ctx->surface)
        return bf_fail(BF_UNSUPPORTED, "gpu: a swapchain needs a context made for a window (gpu_config.make_surface)");
    bf_status status = BF_OK;
    gpu_swapchain *sc = calloc(1, sizeof *sc);
    if (!sc) return bf_fail(BF_NO_MEMORY, "gpu: swapchain");
    sc->ctx = ctx;
    ctx->n_swapchains++;
    VkFenceCreateInfo fi = {.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    GPU__CHECK(ctx->inst.vk.CreateFence(ctx->device, &fi, NULL, &sc->acquired), "gpu.swapchain.acquired");
    gpu__name(ctx, VK_OBJECT_TYPE_FENCE, (uint64_t)sc->acquired, "gpu.swapchain.acquired");
    status = build(sc, width, height);
    if (status != BF_OK) goto fail;
    *out = sc;
    return BF_OK;
fail:
    gpu_swapchain_destroy(sc);
    return status;
}

void gpu_swapchain_destroy(gpu_swapchain *sc)
{
    if (!sc) return;
    gpu_context *ctx = sc->ctx;
    gpu__vk *vk = &ctx->inst.vk;
    vk->DeviceWaitIdle(ctx->device);
    release_images(sc);
    if (sc->swapchain) vk->DestroySwapchainKHR(ctx->device, sc->swapchain, NULL);
    if (sc->acquired) vk->DestroyFence(ctx->device, sc->acquired, NULL);
    ctx->n_swapchains--;
    free(sc);
}

bf_status gpu_swapchain_resize(gpu_swapchain *sc, uint32_t width, uint32_t height)
{
    return build(sc, width, height);
}

gpu_swapchain_info gpu_swapchain_get_info(const gpu_swapchain *sc)
{
    const char *mode = sc->mode == VK_PRESENT_MODE_MAILBOX_KHR     ? "mailbox"
                       : sc->mode == VK_PRESENT_MODE_IMMEDIATE_KHR ? "immediate"
                                                                   : "fifo";
    return (gpu_swapchain_info){
        .width = sc->extent.width,
        .height = sc->extent.height,
        .n_images = sc->n_images,
        .is_bgra = sc->format == VK_FORMAT_B8G8R8A8_UNORM || sc->format == VK_FORMAT_B8G8R8A8_SRGB,
        .can_read = sc->can_read,
        .present_mode = mode,
    };
}

bf_status gpu_swapchain_acquire(gpu_swapchain *sc, bool *is_stale)
{
    bf_status status = BF_OK;
    gpu_context *ctx = sc->ctx;
    gpu__vk *vk = &ctx->inst.vk;
    *is_stale = false;
    sc->index = UINT32_MAX;
    GPU__CHECK(vk->ResetFences(ctx->device, 1, &sc->acquired), "gpu.swapchain.acquired");
    uint32_t index = 0;
    VkResult r = GPU__CALL(vk->AcquireNextImageKHR(ctx->device, sc->swapchain, UINT64_MAX, VK_NULL_HANDLE,
                                                   sc->acquired, &index));
    if (r == VK_ERROR_OUT_OF_DATE_KHR) {
        *is_stale = true;
        return BF_OK;
    }
    if (r != VK_SUBOPTIMAL_KHR) GPU__CHECK_RESULT(r, "vkAcquireNextImageKHR", "gpu.swapchain");
    GPU__CHECK(vk->WaitForFences(ctx->device, 1, &sc->acquired, VK_TRUE, UINT64_MAX), "gpu.swapchain.acquired");
    if (index >= sc->n_images) {
        status = bf_fail(BF_VULKAN, "gpu.swapchain: the driver handed image %u of %u", index, sc->n_images);
        goto fail;
    }
    sc->index = index;
fail:
    return status;
}

static void image_barrier(gpu_context *ctx, VkImage image, VkImageLayout from, VkImageLayout to,
                          VkPipelineStageFlags src_stage, VkAccessFlags src_access, VkPipelineStageFlags dst_stage,
                          VkAccessFlags dst_access)
{
    VkImageMemoryBarrier b = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER,
        .srcAccessMask = src_access,
        .dstAccessMask = dst_access,
        .oldLayout = from,
        .newLayout = to,
        .srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .image = image,
        .subresourceRange = {.aspectMask = VK_IMAGE_ASPECT_COLOR_BIT, .levelCount = 1, .layerCount = 1},
    };
    ctx->inst.vk.CmdPipelineBarrier(ctx->cmd, src_stage, dst_stage, 0, 0, NULL, 0, NULL, 1, &b);
}

void gpu_cmd_copy_to_swapchain(gpu_context *ctx, gpu_swapchain *sc, const gpu_buffer *src, uint64_t offset,
                               gpu_buffer *readback)
{
    BF_ASSERT(ctx->is_recording && sc->ctx == ctx && sc->index != UINT32_MAX);
    uint64_t bytes = 4ull * sc->extent.width * sc->extent.height;
    BF_ASSERT((src->usage & GPU_USAGE_TRANSFER) && offset <= src->size && bytes <= src->size - offset);
    gpu__vk *vk = &ctx->inst.vk;
    VkImage image = sc->images[sc->index];
    VkBufferImageCopy region = {
        .bufferOffset = offset,
        .imageSubresource = {.aspectMask = VK_IMAGE_ASPECT_COLOR_BIT, .layerCount = 1},
        .imageExtent = {sc->extent.width, sc->extent.height, 1},
    };
    /* The image's old content is not wanted: UNDEFINED discards it. The
     * caller's barrier published the pixels' writes to this copy. */
    image_barrier(ctx, image, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                  VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
    vk->CmdCopyBufferToImage(ctx->cmd, src->buffer, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
    VkImageLayout layout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    if (readback) {
        BF_ASSERT(sc->can_read && (readback->usage & GPU_USAGE_TRANSFER) && bytes <= readback->size);
        /* The copy's write -> the read back of the same image. */
        image_barrier(ctx, image, layout, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_PIPELINE_STAGE_TRANSFER_BIT,
                      VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
        layout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
        region.bufferOffset = 0;
        vk->CmdCopyImageToBuffer(ctx->cmd, image, layout, readback->buffer, 1, &region);
    }
    /* The copies -> presentation, which the semaphore orders after the
     * submission (no destination stage or access: vkcube's pre-present barrier). */
    image_barrier(ctx, image, layout, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR, VK_PIPELINE_STAGE_TRANSFER_BIT,
                  VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, 0);
}

bf_status gpu_submit_present(gpu_context *ctx, gpu_swapchain *sc, bool *is_stale)
{
    BF_ASSERT(sc->index != UINT32_MAX);
    *is_stale = false;
    uint32_t index = sc->index;
    sc->index = UINT32_MAX;
    bf_status status = gpu__submit_wait_signal(ctx, sc->done[index]);
    if (status != BF_OK) return status;
    VkPresentInfoKHR pi = {
        .sType = VK_STRUCTURE_TYPE_PRESENT_INFO_KHR,
        .waitSemaphoreCount = 1,
        .pWaitSemaphores = &sc->done[index],
        .swapchainCount = 1,
        .pSwapchains = &sc->swapchain,
        .pImageIndices = &index,
    };
    VkResult r = GPU__CALL(ctx->inst.vk.QueuePresentKHR(ctx->queue, &pi));
    if (r == VK_ERROR_OUT_OF_DATE_KHR || r == VK_SUBOPTIMAL_KHR) {
        *is_stale = true;
        return BF_OK;
    }
    GPU__CHECK_RESULT(r, "vkQueuePresentKHR", "gpu.swapchain");
fail:
    return status;
}
