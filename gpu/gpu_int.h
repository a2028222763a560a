/* Declarations shared by gpu/'s files: the Vulkan function table and the
 * object layouts. Not for other modules. */
#ifndef BF_GPU_INT_H
#define BF_GPU_INT_H

#include <stdatomic.h>

#include "gpu/gpu.h"

/* Mapped buffers from this size on are advised onto huge pages (buffer.c). */
#define GPU_HUGE_PAGE_MIN_BYTES ((VkDeviceSize)4 << 20)

/* Functions the loader exports before any instance exists. */
#define GPU__VK_GLOBAL(X)                    \
    X(EnumerateInstanceVersion)              \
    X(EnumerateInstanceExtensionProperties)  \
    X(EnumerateInstanceLayerProperties)      \
    X(CreateInstance)

/* Instance-level functions (loaded with vkGetInstanceProcAddr). */
#define GPU__VK_INSTANCE(X)                  \
    X(DestroyInstance)                       \
    X(EnumeratePhysicalDevices)              \
    X(GetPhysicalDeviceProperties)           \
    X(GetPhysicalDeviceProperties2)          \
    X(GetPhysicalDeviceFeatures2)            \
    X(GetPhysicalDeviceQueueFamilyProperties) \
    X(GetPhysicalDeviceMemoryProperties)     \
    X(CreateDevice)                          \
    X(GetDeviceProcAddr)                     \
    X(EnumerateDeviceExtensionProperties)

/* From VK_KHR_surface; NULL without presentation (gpu_config.make_surface). */
#define GPU__VK_SURFACE(X)                   \
    X(DestroySurfaceKHR)                     \
    X(GetPhysicalDeviceSurfaceSupportKHR)    \
    X(GetPhysicalDeviceSurfaceCapabilitiesKHR) \
    X(GetPhysicalDeviceSurfaceFormatsKHR)    \
    X(GetPhysicalDeviceSurfacePresentModesKHR)

/* From VK_KHR_swapchain, loaded only with presentation. */
#define GPU__VK_SWAPCHAIN(X)                 \
    X(CreateSwapchainKHR)                    \
    X(DestroySwapchainKHR)                   \
    X(GetSwapchainImagesKHR)                 \
    X(AcquireNextImageKHR)                   \
    X(QueuePresentKHR)

/* From VK_EXT_debug_utils; NULL when it is not enabled. */
#define GPU__VK_DEBUG(X)                     \
    X(CreateDebugUtilsMessengerEXT)          \
    X(DestroyDebugUtilsMessengerEXT)         \
    X(SetDebugUtilsObjectNameEXT)            \
    X(CmdBeginDebugUtilsLabelEXT)            \
    X(CmdEndDebugUtilsLabelEXT)

/* Device-level functions (loaded with vkGetDeviceProcAddr). */
#define GPU__VK_DEVICE(X)                    \
    X(DestroyDevice)                         \
    X(DeviceWaitIdle)                        \
    X(GetDeviceQueue)                        \
    X(QueueSubmit)                           \
    X(CreateBuffer)                          \
    X(DestroyBuffer)                         \
    X(GetBufferMemoryRequirements)           \
    X(AllocateMemory)                        \
    X(FreeMemory)                            \
    X(BindBufferMemory)                      \
    X(MapMemory)                             \
    X(UnmapMemory)                           \
    X(FlushMappedMemoryRanges)               \
    X(InvalidateMappedMemoryRanges)          \
    X(CreateShaderModule)                    \
    X(DestroyShaderModule)                   \
    X(CreateDescriptorSetLayout)             \
    X(DestroyDescriptorSetLayout)            \
    X(CreatePipelineLayout)                  \
    X(DestroyPipelineLayout)                 \
    X(CreateComputePipelines)                \
    X(DestroyPipeline)                       \
    X(CreatePipelineCache)                   \
    X(DestroyPipelineCache)                  \
    X(GetPipelineCacheData)                  \
    X(CreateDescriptorPool)                  \
    X(DestroyDescriptorPool)                 \
    X(AllocateDescriptorSets)                \
    X(FreeDescriptorSets)                    \
    X(UpdateDescriptorSets)                  \
    X(GetBufferDeviceAddress)                \
    X(CreateCommandPool)                     \
    X(DestroyCommandPool)                    \
    X(AllocateCommandBuffers)                \
    X(ResetCommandBuffer)                    \
    X(BeginCommandBuffer)                    \
    X(EndCommandBuffer)                      \
    X(CmdBindPipeline)                       \
    X(CmdBindDescriptorSets)                 \
    X(CmdPushConstants)                      \
    X(CmdDispatch)                           \
    X(CmdDispatchIndirect)                   \
    X(CmdPipelineBarrier)                    \
    X(CmdCopyBuffer)                         \
    X(CmdFillBuffer)                         \
    X(CmdWriteTimestamp)                     \
    X(CmdResetQueryPool)                     \
    X(CreateQueryPool)                       \
    X(DestroyQueryPool)                      \
    X(GetQueryPoolResults)                   \
    X(CreateFence)                           \
    X(DestroyFence)                          \
    X(ResetFences)                           \
    X(WaitForFences)                         \
    X(CreateSemaphore)                       \
    X(DestroySemaphore)                      \
    X(CmdCopyBufferToImage)                  \
    X(CmdCopyImageToBuffer)

typedef struct gpu__vk {
    void *lib; /* dlopen handle of the loader */
    PFN_vkGetInstanceProcAddr GetInstanceProcAddr;
#define GPU__VK_MEMBER(name) PFN_vk##name name;
    GPU__VK_GLOBAL(GPU__VK_MEMBER)
    GPU__VK_INSTANCE(GPU__VK_MEMBER)
    GPU__VK_DEBUG(GPU__VK_MEMBER)
    GPU__VK_DEVICE(GPU__VK_MEMBER)
    GPU__VK_SURFACE(GPU__VK_MEMBER)
    GPU__VK_SWAPCHAIN(GPU__VK_MEMBER)
#undef GPU__VK_MEMBER
} gpu__vk;

/* An instance with its loader, shared by gpu_device_list and the context. */
typedef struct gpu__instance {
    gpu__vk vk;
    VkInstance instance;
    VkDebugUtilsMessengerEXT messenger;
    bool has_debug_utils;
    bool has_validation;
    bool has_surface;                /* the window system's surface extensions are enabled */
} gpu__instance;

#define GPU__MAX_SURFACE_EXTENSIONS 8

struct gpu_context {
    gpu__instance inst;
    _Atomic uint32_t n_messages;     /* validation warnings and errors */
    VkPhysicalDevice phys;
    gpu_device_info info;
    VkPhysicalDeviceMemoryProperties mem_props;
    VkDevice device;
    VkQueue queue;
    VkSurfaceKHR surface;            /* presentation only (gpu_config.make_surface), owned */
    uint32_t n_swapchains;           /* alive, checked at destroy */
    bool force_staging;
    /* VK_EXT_external_memory_host is enabled: large buffers are imported
     * from our own huge-page mappings (buffer.c); 0 alignment when not. */
    VkDeviceSize host_import_align;
    PFN_vkGetMemoryHostPointerPropertiesEXT GetMemoryHostPointerPropertiesEXT;

    VkPipelineCache pipeline_cache;
    char cache_path[4096];           /* "" when not persisted */
    size_t cache_loaded_bytes;

    /* One set layout per buffer count, made on first use (at create time of
     * a pipeline or binding set, never while recording). */
    VkDescriptorSetLayout set_layouts[GPU_MAX_BINDINGS + 1];
    VkDescriptorPool descriptor_pool;
    uint32_t bindings_cap, n_bindings;

    VkCommandPool command_pool;
    VkCommandBuffer cmd;             /* per-frame work: gpu_begin .. gpu_submit_wait */
    VkFence fence;
    bool is_recording;
    VkCommandBuffer xfer_cmd;        /* synchronous transfers (upload/download/fill) */
    VkFence xfer_fence;
    gpu_buffer *staging;             /* NULL when all device memory is mappable */

    VkQueryPool query_pool;          /* 2 * stage_cap timestamps; NULL without timestamps */
    uint32_t stage_cap, n_stages;
    bool is_stage_open;
    bool is_stage_timed;             /* the open stage got a begin timestamp */
    gpu_stage_time *stages;          /* stage_cap entries */
    uint32_t label_depth;

    /* Set by gpu_pipeline_warm_up around its wait: a wait past
     * GPU__COMPILE_NOTE_NS is the driver compiling at first dispatch
     * (lavapipe: tens of seconds a shader with a cold Mesa cache), said
     * once a context so a first start is not silent. */
    const char *warming;             /* the pipelines' names, or NULL */
    bool said_compiling;
};
#define GPU__COMPILE_NOTE_NS 2000000000ull

struct gpu_buffer {
    gpu_context *ctx;
    VkBuffer buffer;
    VkDeviceMemory memory;
    uint64_t size;
    uint64_t address;                /* device address (GPU_USAGE_ADDRESS), else 0 */
    uint32_t usage;                  /* gpu_usage bits */
    gpu_memory kind;
    bool is_coherent;
    bool is_cached;                  /* host-cached: host reads of the mapping are ordinary loads */
    void *mapped;                    /* NULL if not (or not to be) mapped */
    void *host_alloc;                /* our mapping the memory was imported from, or NULL */
    size_t host_alloc_bytes;
    char name[64];
};

struct gpu_pipeline {
    gpu_context *ctx;
    VkPipelineLayout layout;
    VkPipeline pipeline;
    uint32_t n_buffers, push_bytes;
    uint32_t local_size[3];
    char name[64];
};

struct gpu_bindings {
    gpu_context *ctx;
    VkDescriptorSet set;
    uint32_t n_buffers;
    uint32_t set_mask;               /* slots bound so far */
    char name[64];
};

extern _Atomic uint32_t gpu__messages_total;

/* A fault point (core's bf_fault_arm): when the armed countdown reaches
 * this call, it is not made and fails instead. */
#define GPU__CALL(call) (bf_fault_now() ? VK_ERROR_OUT_OF_DEVICE_MEMORY : (call))

/* Maps a VkResult to a status and records "call: object: VK_ERROR_..." */
bf_status gpu__vk_fail(VkResult r, const char *call, const char *object);
const char *gpu__vk_result_name(VkResult r);
#define GPU__CHECK(call, object)                                        \
    do {                                                                \
        VkResult gpu__r = GPU__CALL(call);                              \
        if (gpu__r != VK_SUCCESS) {                                     \
            status = gpu__vk_fail(gpu__r, #call, (object));             \
            goto fail;                                                  \
        }                                                               \
    } while (0)
/* The same for a result already in hand (no fault injection point). */
#define GPU__CHECK_RESULT(r, call_name, object)                         \
    do {                                                                \
        if ((r) != VK_SUCCESS) {                                        \
            status = gpu__vk_fail((r), (call_name), (object));          \
            goto fail;                                                  \
        }                                                               \
    } while (0)

/* Opens the loader and creates an instance, with the validation layer and
 * debug utils when validation is set. user is handed to the messenger
 * (a gpu_context or NULL). */
bf_status gpu__instance_create(const gpu_config *cfg, bool validation, gpu_context *user,
                               gpu__instance *out);
void gpu__instance_destroy(gpu__instance *inst);
bool gpu__validation_wanted(const gpu_config *cfg);
/* Fills info for one physical device. */
void gpu__query_device(const gpu__instance *inst, VkPhysicalDevice phys, gpu_device_info *info);
/* Index of the device to use among n, or UINT32_MAX (with a bf_fail message). */
uint32_t gpu__choose_device(const gpu_device_info *infos, uint32_t n, const char *want);
const char *gpu__wanted_device(const gpu_config *cfg);

void gpu__name(gpu_context *ctx, VkObjectType type, uint64_t handle, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
bf_status gpu__set_layout(gpu_context *ctx, uint32_t n_buffers, VkDescriptorSetLayout *out);
bf_status gpu__pipeline_cache_open(gpu_context *ctx, const gpu_config *cfg);
void gpu__pipeline_cache_close(gpu_context *ctx);
/* Runs one recording on the transfer command buffer and waits for it. */
bf_status gpu__xfer_begin(gpu_context *ctx);
bf_status gpu__xfer_submit_wait(gpu_context *ctx);
/* gpu_submit_wait that also signals semaphore (VK_NULL_HANDLE: none), for
 * a presentation waiting on the submission (present.c). */
bf_status gpu__submit_wait_signal(gpu_context *ctx, VkSemaphore semaphore);

#endif
