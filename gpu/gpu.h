/* gpu: the Vulkan context every GPU stage runs on (DESIGN.md section 2).
 *
 * One context owns the loader, instance, device, one compute queue, a
 * pipeline cache (persisted to disk), one command buffer with a fence for
 * per-frame work and a timestamp query pool. Modules own their buffers,
 * pipelines and binding sets and destroy them, newest first, before the
 * context (STYLE.md section 5).
 *
 * The Vulkan loader is opened at run time (dlopen), so a machine without
 * libvulkan gets BF_NO_DEVICE instead of a program that cannot start.
 *
 * A frame looks like this (see docs/gpu.md for a full example):
 *
 *     gpu_begin(ctx);
 *     gpu_cmd_stage_begin(ctx, "fuse");
 *     gpu_cmd_dispatch(ctx, pipe, binds, &push, gpu_groups(n, 64), 1, 1);
 *     gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE);
 *     ...
 *     gpu_cmd_stage_end(ctx);
 *     gpu_submit_wait(ctx);
 *     n = gpu_stage_times(ctx, &times);
 *
 * Nothing on the recording path allocates: command buffer, fence, query pool
 * and descriptor sets are made at create time. Threading: a context and
 * everything made from it are used from one thread at a time.
 */
#ifndef BF_GPU_H
#define BF_GPU_H

#ifndef VK_NO_PROTOTYPES
#define VK_NO_PROTOTYPES /* every Vulkan call goes through gpu/'s loaded table */
#endif
#include <vulkan/vulkan.h>

#include "core/core.h"

enum {
    GPU_MAX_BINDINGS = 16,   /* storage buffers per pipeline / binding set */
    GPU_MAX_SPEC = 16,       /* user specialization constants per pipeline */
    GPU_MAX_HEAPS = 16,
    GPU_MAX_DEVICES = 16,
    GPU_STAGE_NAME_MAX = 32, /* stage names are truncated to 31 characters */
};
/* gpu_bindings_set(): bind from offset to the end of the buffer. */
#define GPU_WHOLE_SIZE UINT64_MAX

typedef struct gpu_context gpu_context;
typedef struct gpu_buffer gpu_buffer;
typedef struct gpu_pipeline gpu_pipeline;
typedef struct gpu_bindings gpu_bindings;

/* ------------------------------------------------------------ devices */

typedef enum gpu_validation {
    GPU_VALIDATION_ENV = 0, /* on when BITFUSE_VALIDATION=1 (the default) */
    GPU_VALIDATION_ON,
    GPU_VALIDATION_OFF,
} gpu_validation;

typedef struct gpu_config {
    /* Device to use: a case-insensitive substring of its name, or a decimal
     * index into gpu_device_list()'s order. NULL: the BITFUSE_DEVICE
     * environment variable, else the best ranked device (discrete,
     * integrated, virtual, CPU, as vkcube ranks them). */
    const char *device;
    gpu_validation validation;
    /* Directory of the pipeline cache file. NULL: BITFUSE_CACHE_DIR, else
     * $XDG_CACHE_HOME/bitfuse, else $HOME/.cache/bitfuse. */
    const char *cache_dir;
    bool no_disk_cache;         /* keep the pipeline cache in memory only */
    uint32_t stage_cap;         /* timestamped stages per submission; 0: 64 */
    uint32_t bindings_cap;      /* gpu_bindings per context; 0: 256 */
    uint64_t staging_bytes;     /* staging buffer when device memory is not mappable; 0: 16 MiB */
    /* Treat device memory as not host-visible, as on a discrete GPU, so that
     * uploads and downloads go through the staging buffer (tests use it). */
    bool force_staging;
    /* On a CPU device (lavapipe) large buffers live in memory bitfuse maps
     * itself and imports (VK_EXT_external_memory_host), so that they can be
     * on huge pages; this keeps the driver's own allocations instead. */
    bool no_host_import;
    const char *loader;         /* Vulkan loader library; NULL: "libvulkan.so.1" */
    /* Presentation to a window (view/), asked for only when one is wanted:
     * the instance extensions the window system needs (GLFW's
     * glfwGetRequiredInstanceExtensions; borrowed) and a function that makes
     * the window's surface on the new instance. The context then owns the
     * surface, enables VK_KHR_swapchain and uses a compute queue family that
     * can present to it (BF_UNSUPPORTED when the device has none). NULL
     * make_surface: headless, nothing of this is requested. */
    const char *const *surface_extensions;
    uint32_t n_surface_extensions;
    bf_status (*make_surface)(void *user, VkInstance instance, VkSurfaceKHR *out);
    void *surface_user;
} gpu_config;

typedef struct gpu_heap {
    uint64_t size_bytes;
    bool is_device_local;
} gpu_heap;

/* Limits as queried from the device; code sizes its work from these, never
 * from constants (lavapipe: 128 MiB per storage binding, subgroups of 8). */
typedef struct gpu_limits {
    uint64_t max_storage_buffer_range;      /* bytes of one storage binding */
    uint64_t max_memory_allocation_size;    /* bytes of one allocation (maintenance3) */
    uint64_t min_storage_buffer_offset_alignment;
    uint64_t non_coherent_atom_size;
    uint32_t subgroup_size;
    uint32_t subgroup_ops;                  /* VkSubgroupFeatureFlags usable in compute shaders, 0 if none */
    uint32_t max_compute_workgroup_invocations;
    uint32_t max_compute_workgroup_size[3];
    uint32_t max_compute_workgroup_count[3];
    uint32_t max_compute_shared_memory_size;
    uint32_t max_push_constants_size;
    uint32_t max_per_stage_storage_buffers;
    bool has_timestamps;                    /* the compute queue can write timestamps */
    uint32_t timestamp_valid_bits;          /* of the compute queue family, 0 if none */
    float timestamp_period_ns;              /* nanoseconds per timestamp tick */
    /* VK_EXT_external_memory_host's minImportedHostPointerAlignment; 0
     * without the extension. A CPU device's large buffers are imported
     * (gpu_imports_host_memory). */
    uint64_t host_import_alignment;
    uint32_t n_heaps;
    gpu_heap heaps[GPU_MAX_HEAPS];
} gpu_limits;

typedef struct gpu_device_info {
    char name[VK_MAX_PHYSICAL_DEVICE_NAME_SIZE];
    VkPhysicalDeviceType type;
    uint32_t vendor_id, device_id;
    uint32_t api_version;                   /* VK_MAKE_API_VERSION */
    char driver_name[VK_MAX_DRIVER_NAME_SIZE];
    char driver_info[VK_MAX_DRIVER_INFO_SIZE];
    uint8_t device_uuid[VK_UUID_SIZE];
    uint8_t pipeline_cache_uuid[VK_UUID_SIZE];
    bool is_usable;                         /* Vulkan >= 1.2, a compute queue, buffer device addresses */
    bool has_buffer_address;                /* bufferDeviceAddress (Vulkan 1.2's, optional there) */
    uint32_t queue_family;                  /* the compute queue family, if usable */
    gpu_limits limits;
} gpu_device_info;

/* Lists the Vulkan devices (up to GPU_MAX_DEVICES) into out[], in the
 * loader's order, and sets *chosen to the index gpu_context_create() would
 * pick with cfg (NULL: defaults), or UINT32_MAX if none matches.
 * BF_NO_DEVICE when there is no loader, no instance or no device at all. */
bf_status gpu_device_list(const gpu_config *cfg, gpu_device_info out[GPU_MAX_DEVICES],
                          uint32_t *n, uint32_t *chosen);
/* "discrete", "integrated", "virtual", "cpu", "other". */
const char *gpu_device_type_name(VkPhysicalDeviceType type);

/* ------------------------------------------------------------ context */

/* Opens the loader, creates instance and device on the chosen device, logs
 * its name and type. cfg may be NULL (defaults). With validation on, the
 * Khronos layer (with synchronization validation) and a debug-utils
 * messenger are enabled; BF_UNSUPPORTED if the layer is not installed.
 * BF_NO_DEVICE if there is no loader, no device, or none matches the name.
 * On failure *out is untouched. */
bf_status gpu_context_create(const gpu_config *cfg, gpu_context **out);
/* Waits for the device, saves the pipeline cache (a failure is a warning),
 * destroys everything the context owns. All buffers, pipelines and binding
 * sets must be destroyed first. NULL is a no-op. */
void gpu_context_destroy(gpu_context *ctx);

const gpu_device_info *gpu_device(const gpu_context *ctx);
const gpu_limits *gpu_device_limits(const gpu_context *ctx);
const char *gpu_device_name(const gpu_context *ctx);
VkPhysicalDeviceType gpu_device_type(const gpu_context *ctx);
/* Large buffers are backed by memory bitfuse maps itself and imports
 * (gpu_config.no_host_import; a CPU device offering
 * VK_EXT_external_memory_host). */
bool gpu_imports_host_memory(const gpu_context *ctx);

bool gpu_validation_enabled(const gpu_context *ctx);
/* Validation warnings and errors reported for this context so far (each is
 * also logged). Tests require zero. */
uint32_t gpu_validation_message_count(const gpu_context *ctx);
/* The same, summed over every context of the process, including messages
 * reported while a context was being destroyed. */
uint32_t gpu_validation_message_total(void);

/* Names a Vulkan object for validation messages and debuggers
 * ("fusion.sign_pool[1]"); a no-op without VK_EXT_debug_utils. Objects made
 * through this module are named already. */
void gpu_set_name(gpu_context *ctx, VkObjectType type, uint64_t handle, const char *name);

/* Pipeline cache file: "<dir>/pipeline-cache-<deviceUUID>.bin" ("" when
 * no_disk_cache), and how many bytes of it were accepted at create (0: the
 * file was absent or rejected). */
const char *gpu_pipeline_cache_path(const gpu_context *ctx);
size_t gpu_pipeline_cache_loaded_bytes(const gpu_context *ctx);
/* Writes the cache file now (atomically); also done by gpu_context_destroy. */
bf_status gpu_pipeline_cache_save(gpu_context *ctx);

/* ------------------------------------------------------------ buffers */

typedef enum gpu_memory {
    GPU_MEMORY_DEVICE,   /* device-local; mapped too where the device allows (UMA, lavapipe) */
    GPU_MEMORY_UPLOAD,   /* host-visible, for data the CPU writes every frame */
    GPU_MEMORY_READBACK, /* host-visible, cached where possible, for results */
} gpu_memory;

enum gpu_usage {
    GPU_USAGE_STORAGE = 1u << 0,  /* bound to a shader */
    GPU_USAGE_INDIRECT = 1u << 1, /* dispatch arguments */
    GPU_USAGE_TRANSFER = 1u << 2, /* copy / fill source or destination */
    GPU_USAGE_ADDRESS = 1u << 3,  /* read by shaders through its device address (gpu_buffer_address) */
};

typedef struct gpu_buffer_desc {
    const char *name;       /* for messages and the debugger, e.g. "fusion.sign_pool[0]" */
    uint64_t size_bytes;
    gpu_memory memory;
    uint32_t usage;         /* gpu_usage bits; 0: STORAGE | TRANSFER */
} gpu_buffer_desc;

/* Creates a buffer with its own memory. BF_INVALID_ARG for a zero size,
 * BF_NO_MEMORY if the size passes maxMemoryAllocationSize or the device is
 * out of memory (the message names the buffer). The contents are undefined:
 * fill it before reading. ctx must outlive the buffer. */
bf_status gpu_buffer_create(gpu_context *ctx, const gpu_buffer_desc *desc, gpu_buffer **out);
void gpu_buffer_destroy(gpu_buffer *buf); /* NULL is a no-op; the GPU must be done with it */
uint64_t gpu_buffer_size(const gpu_buffer *buf);
/* The buffer's device address, for a shader that reads it through a
 * buffer_reference (GL_EXT_buffer_reference) handed over in its push
 * constants or in a small table buffer it binds; 0 without
 * GPU_USAGE_ADDRESS. On lavapipe a storage-buffer load
 * at a per-lane address is a scalar loop over the lanes, each lane reading
 * the descriptor again and checking its bounds; a load through an address is
 * one gather (docs/gpu.md, lavapipe notes). No bounds check: the shader's
 * indices must stay inside the buffer. */
uint64_t gpu_buffer_address(const gpu_buffer *buf);
/* A table of device addresses for a shader whose push constants have no
 * room for them: a new device buffer holding gpu_buffer_address(bufs[i]) as
 * n 64-bit words (a `uvec2 a[n]` in std430), which the shader binds and
 * reads at uniform indices. BF_INVALID_ARG when a buffer has no address
 * (made without GPU_USAGE_ADDRESS) or n is 0. The table is not updated:
 * the buffers must outlive it. */
bf_status gpu_address_table_create(gpu_context *ctx, const char *name, gpu_buffer *const *bufs, uint32_t n,
                                   gpu_buffer **out);
const char *gpu_buffer_name(const gpu_buffer *buf);
VkBuffer gpu_buffer_handle(const gpu_buffer *buf);
/* Persistent mapping of a host-visible buffer (always for UPLOAD and
 * READBACK), NULL otherwise. Writes must be followed by gpu_buffer_flush()
 * (a no-op on coherent memory) before the GPU reads them. */
void *gpu_buffer_map(const gpu_buffer *buf);
/* The mapping where the host may also read and edit the buffer in place at
 * its own memory's speed (host-cached and coherent: lavapipe, most UMA
 * devices), NULL otherwise (uncached, write-combined mappings are slow to
 * read). */
void *gpu_buffer_map_cached(const gpu_buffer *buf);
/* The buffer's memory is imported from bitfuse's own mapping (huge pages
 * where the kernel gives them; gpu_imports_host_memory). */
bool gpu_buffer_is_imported(const gpu_buffer *buf);
/* The buffer held zeros when it was created (imported: fresh anonymous
 * memory). Its content since is the caller's to know: a new buffer's
 * zero fill can be left out, leaving its pages unfaulted. */
bool gpu_buffer_created_zero(const gpu_buffer *buf);
bf_status gpu_buffer_flush(gpu_buffer *buf);

/* Synchronous transfers: copy size bytes between host memory and the buffer
 * at offset, directly when it is mapped, else through the context's staging
 * buffer (needs GPU_USAGE_TRANSFER). They take effect at once, before any
 * command recorded but not yet submitted; the GPU must not be using the range.
 * BF_INVALID_ARG if the range passes the end. Setup and tests use them; a
 * frame loop records gpu_cmd_copy() from an UPLOAD buffer instead. */
bf_status gpu_buffer_upload(gpu_buffer *buf, uint64_t offset, const void *src, uint64_t size);
bf_status gpu_buffer_download(gpu_buffer *buf, uint64_t offset, void *dst, uint64_t size);
/* Fills size bytes (a multiple of 4, offset too) with the 32-bit value. */
bf_status gpu_buffer_fill(gpu_buffer *buf, uint64_t offset, uint64_t size, uint32_t value);
static inline bf_status gpu_buffer_zero(gpu_buffer *buf) { return gpu_buffer_fill(buf, 0, gpu_buffer_size(buf), 0); }

/* Pools larger than one storage binding are split over several bindings
 * (DESIGN.md section 3). The largest binding that holds whole elements of
 * elem_bytes and keeps the next binding's offset aligned; and how many such
 * bindings a pool of pool_bytes needs. */
uint64_t gpu_binding_max_bytes(const gpu_context *ctx, uint32_t elem_bytes);
uint32_t gpu_bindings_needed(const gpu_context *ctx, uint64_t pool_bytes, uint32_t elem_bytes);

/* ------------------------------------------------------------ pipelines */

typedef struct gpu_pipeline_desc {
    const char *name;           /* "fusion.window" */
    const uint32_t *spirv;      /* bf_spv_<shader> from bf_shaders_spv.h */
    size_t spirv_bytes;         /* bf_spv_<shader>_size */
    uint32_t n_buffers;         /* storage buffers at bindings 0..n-1 of set 0 */
    uint32_t push_bytes;        /* push-constant block size, multiple of 4 */
    /* Local workgroup size, given to the shader as specialization constants
     * 0, 1, 2 (BF_LOCAL_SIZE_FROM_SPEC in shaders/bf_common.glsl.h); y and z
     * default to 1. Checked against the device limits. */
    uint32_t local_size[3];
    const uint32_t *spec;       /* further constants, constant_id BF_SPEC_USER + i */
    uint32_t n_spec;
} gpu_pipeline_desc;

/* Creates (and compiles, through the context's pipeline cache) a compute
 * pipeline. BF_INVALID_ARG if the description breaks a device limit (the
 * message says which), BF_VULKAN for a rejected shader. */
bf_status gpu_pipeline_create(gpu_context *ctx, const gpu_pipeline_desc *desc, gpu_pipeline **out);
void gpu_pipeline_destroy(gpu_pipeline *pipe); /* NULL is a no-op */
const char *gpu_pipeline_name(const gpu_pipeline *pipe);
void gpu_pipeline_local_size(const gpu_pipeline *pipe, uint32_t out[3]);
static inline uint32_t gpu_groups(uint32_t n, uint32_t local) { return (n + local - 1u) / local; }

/* Runs one workgroup of each pipeline, submits and waits, so drivers that
 * compile on first use (llvmpipe) do it at start-up, not in the first frame.
 * Every binding gets a zero-filled scratch buffer of 64 KiB and the push
 * constants are zero: a shader must be harmless with that input (the usual
 * `if (i >= pc.n) return;` makes it a no-op). */
bf_status gpu_pipeline_warm_up(gpu_context *ctx, gpu_pipeline *const *pipes, uint32_t n);

/* A descriptor set of n_buffers storage buffers, usable with every pipeline
 * of the same n_buffers. Allocated from the context's pool (BF_POOL_FULL
 * past gpu_config.bindings_cap). */
bf_status gpu_bindings_create(gpu_context *ctx, uint32_t n_buffers, const char *name, gpu_bindings **out);
void gpu_bindings_destroy(gpu_bindings *b); /* NULL is a no-op */
/* Binds [offset, offset + range) of buf to slot. BF_INVALID_ARG when range
 * exceeds maxStorageBufferRange (split the pool: gpu_bindings_needed), the
 * offset is misaligned or the range passes the buffer's end. Not while a
 * submission using b may run (gpu_submit_wait returns after it). */
bf_status gpu_bindings_set(gpu_bindings *b, uint32_t slot, gpu_buffer *buf, uint64_t offset, uint64_t range);

/* ------------------------------------------------------------ commands */

/* Starts recording the context's command buffer (the previous submission
 * has finished: gpu_submit_wait waited for it). */
bf_status gpu_begin(gpu_context *ctx);

/* Records a dispatch. push points to the pipeline's push_bytes (NULL if 0);
 * b may be NULL for a pipeline without buffers, else every slot must be set.
 * Group counts must be within maxComputeWorkGroupCount (asserted). */
void gpu_cmd_dispatch(gpu_context *ctx, const gpu_pipeline *pipe, const gpu_bindings *b,
                      const void *push, uint32_t groups_x, uint32_t groups_y, uint32_t groups_z);
/* A one-dimensional dispatch of n_groups groups, spread over x and y when x
 * alone cannot hold them (the shader reads its place as BF_LINEAR_INDEX,
 * shaders/bf_common.glsl.h, and bounds it: the last row may hold more
 * groups than n_groups). */
void gpu_cmd_dispatch_linear(gpu_context *ctx, const gpu_pipeline *pipe, const gpu_bindings *b, const void *push,
                             uint32_t n_groups);
/* The group counts are three uint32 at offset in args (GPU_USAGE_INDIRECT),
 * typically written by an earlier dispatch: put GPU_BARRIER_INDIRECT between. */
void gpu_cmd_dispatch_indirect(gpu_context *ctx, const gpu_pipeline *pipe, const gpu_bindings *b,
                               const void *push, const gpu_buffer *args, uint64_t offset);

/* Execution and memory dependencies between recorded commands. The caller's
 * comment should say which write the barrier publishes and which read waits. */
typedef enum gpu_barrier {
    GPU_BARRIER_COMPUTE,             /* shader writes -> later shader reads and writes */
    GPU_BARRIER_INDIRECT,            /* shader writes -> indirect arguments and shader reads */
    GPU_BARRIER_TRANSFER_TO_COMPUTE, /* copy / fill -> shader reads and writes */
    GPU_BARRIER_COMPUTE_TO_TRANSFER, /* shader writes -> copy / fill */
    GPU_BARRIER_TRANSFER,            /* copy / fill -> copy / fill */
    GPU_BARRIER_HOST,                /* all writes -> host reads after the fence */
} gpu_barrier;
void gpu_cmd_barrier(gpu_context *ctx, gpu_barrier kind);

void gpu_cmd_copy(gpu_context *ctx, const gpu_buffer *src, uint64_t src_offset,
                  gpu_buffer *dst, uint64_t dst_offset, uint64_t size);
/* size and offset multiples of 4, or size GPU_WHOLE_SIZE for the rest. */
void gpu_cmd_fill(gpu_context *ctx, gpu_buffer *dst, uint64_t offset, uint64_t size, uint32_t value);

/* A labelled command range (debuggers, validation messages); nestable. */
void gpu_cmd_label_begin(gpu_context *ctx, const char *name);
void gpu_cmd_label_end(gpu_context *ctx);

/* A timed stage: a labelled range between two timestamps (not nested). When
 * stage_cap stages were recorded, or the device has no timestamps, the
 * range is only labelled and BF_POOL_FULL / BF_UNSUPPORTED is returned. */
bf_status gpu_cmd_stage_begin(gpu_context *ctx, const char *name);
void gpu_cmd_stage_end(gpu_context *ctx);

/* Ends recording, submits to the compute queue and waits on the fence, then
 * reads the stage timestamps. BF_VULKAN on device loss or a timeout. */
bf_status gpu_submit_wait(gpu_context *ctx);

typedef struct gpu_stage_time {
    char name[GPU_STAGE_NAME_MAX];
    double ms;                       /* end - begin, via timestampPeriod */
    uint64_t begin_ticks, end_ticks; /* raw, masked to timestampValidBits */
} gpu_stage_time;
/* Stages of the last submission, in recording order; *out stays valid until
 * the next gpu_begin. Returns their number. */
uint32_t gpu_stage_times(const gpu_context *ctx, const gpu_stage_time **out);
/* The summed time [ms] of the last submission's stages whose names start
 * with prefix ("fusion.window" also counts "fusion.window_list"); 0 when
 * there are none. Several modules record into one submission and each
 * reads its own stages this way. */
double gpu_stage_ms(const gpu_context *ctx, const char *prefix);

/* ------------------------------------------------------------ presentation
 * A swapchain on the context's surface (gpu_config.make_surface). A frame:
 *
 *     gpu_swapchain_acquire(sc, &is_stale);      (stale: gpu_swapchain_resize)
 *     gpu_begin(ctx);
 *     ... a dispatch writing the pixels into a buffer ...
 *     gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
 *     gpu_cmd_copy_to_swapchain(ctx, sc, pixels, 0, readback);
 *     gpu_submit_present(ctx, sc, &is_stale);
 *
 * The image is acquired with a fence the host waits for, so the submission
 * needs no wait semaphore; it signals one per image that the presentation
 * waits on. */
typedef struct gpu_swapchain gpu_swapchain;

typedef struct gpu_swapchain_info {
    uint32_t width, height;  /* the images' extent */
    uint32_t n_images;
    bool is_bgra;            /* B in the low byte of a pixel (else R) */
    bool can_read;           /* gpu_cmd_copy_to_swapchain can copy the image back (TRANSFER_SRC) */
    const char *present_mode; /* "mailbox", "immediate", "fifo" */
} gpu_swapchain_info;

/* A swapchain of about width x height (the surface's extent when it fixes
 * one) of 8-bit RGBA or BGRA images. BF_UNSUPPORTED without a surface or
 * when the surface offers no such format or no transfer destination. */
bf_status gpu_swapchain_create(gpu_context *ctx, uint32_t width, uint32_t height, gpu_swapchain **out);
void gpu_swapchain_destroy(gpu_swapchain *sc); /* waits for the device; NULL is a no-op */
/* Remakes the images at about width x height (a resized window, or a stale
 * swapchain). */
bf_status gpu_swapchain_resize(gpu_swapchain *sc, uint32_t width, uint32_t height);
gpu_swapchain_info gpu_swapchain_get_info(const gpu_swapchain *sc);
/* Acquires the next image and waits until it may be written. *is_stale:
 * the swapchain no longer matches the surface and nothing was acquired
 * (resize it and try again). */
bf_status gpu_swapchain_acquire(gpu_swapchain *sc, bool *is_stale);
/* Records the copy of the acquired image's pixels from src at offset
 * (width * height uint32, rows packed, the image's byte order) into the
 * image and its move to presentation. With readback (GPU_MEMORY_READBACK,
 * at least width * height * 4 bytes; needs can_read) the image as it will
 * be presented is also copied into it: a screenshot of the window. */
void gpu_cmd_copy_to_swapchain(gpu_context *ctx, gpu_swapchain *sc, const gpu_buffer *src, uint64_t offset,
                               gpu_buffer *readback);
/* gpu_submit_wait, then presents the acquired image. *is_stale: the
 * swapchain went out of date (the image may not have been shown). */
bf_status gpu_submit_present(gpu_context *ctx, gpu_swapchain *sc, bool *is_stale);

/* Fault injection for tests: every checked Vulkan call is a fault point of
 * core's bf_fault_arm and fails with VK_ERROR_OUT_OF_DEVICE_MEMORY there,
 * so a test can walk every failure path and require a clean status and no
 * leaked object. */

#endif
