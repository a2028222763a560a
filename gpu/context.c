/* Loader, instance, validation messenger, device choice and the context. */
#include "gpu_int.h"

#include <ctype.h>
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

_Atomic uint32_t gpu__messages_total;
static const char *const validation_layer = "VK_LAYER_KHRONOS_validation";

/* ------------------------------------------------------------ results */

const char *gpu__vk_result_name(VkResult r)
{
    switch (r) {
#define R(x) case x: return #x;
        R(VK_SUCCESS) R(VK_NOT_READY) R(VK_TIMEOUT) R(VK_INCOMPLETE)
        R(VK_ERROR_OUT_OF_HOST_MEMORY) R(VK_ERROR_OUT_OF_DEVICE_MEMORY)
        R(VK_ERROR_INITIALIZATION_FAILED) R(VK_ERROR_DEVICE_LOST)
        R(VK_ERROR_MEMORY_MAP_FAILED) R(VK_ERROR_LAYER_NOT_PRESENT)
        R(VK_ERROR_EXTENSION_NOT_PRESENT) R(VK_ERROR_FEATURE_NOT_PRESENT)
        R(VK_ERROR_INCOMPATIBLE_DRIVER) R(VK_ERROR_TOO_MANY_OBJECTS)
        R(VK_ERROR_FORMAT_NOT_SUPPORTED) R(VK_ERROR_FRAGMENTED_POOL)
        R(VK_ERROR_OUT_OF_POOL_MEMORY) R(VK_ERROR_INVALID_SHADER_NV)
        R(VK_ERROR_FRAGMENTATION) R(VK_PIPELINE_COMPILE_REQUIRED)
        R(VK_ERROR_UNKNOWN) R(VK_ERROR_OUT_OF_DATE_KHR) R(VK_ERROR_SURFACE_LOST_KHR)
        R(VK_SUBOPTIMAL_KHR) R(VK_ERROR_NATIVE_WINDOW_IN_USE_KHR)
#undef R
    default: return "VK_RESULT_UNKNOWN";
    }
}

bf_status gpu__vk_fail(VkResult r, const char *call, const char *object)
{
    bf_status s;
    switch (r) {
    case VK_ERROR_OUT_OF_HOST_MEMORY:
    case VK_ERROR_OUT_OF_DEVICE_MEMORY:
    case VK_ERROR_OUT_OF_POOL_MEMORY:
    case VK_ERROR_FRAGMENTED_POOL:
    case VK_ERROR_FRAGMENTATION:
    case VK_ERROR_TOO_MANY_OBJECTS: s = BF_NO_MEMORY; break;
    case VK_ERROR_INCOMPATIBLE_DRIVER:
    case VK_ERROR_INITIALIZATION_FAILED: s = BF_NO_DEVICE; break;
    case VK_ERROR_LAYER_NOT_PRESENT:
    case VK_ERROR_EXTENSION_NOT_PRESENT:
    case VK_ERROR_FEATURE_NOT_PRESENT: s = BF_UNSUPPORTED; break;
    default: s = BF_VULKAN; break;
    }
    /* "GPU__CALL(vk->CreateBuffer(ctx->device, ...))" -> "vkCreateBuffer". */
    const char *end = strchr(call, '(');
    const char *start = call;
    if (!strncmp(call, "GPU__CALL(", 10)) {
        start = call + 10;
        end = strchr(start, '(');
    }
    if (!end) end = call + strlen(call);
    for (const char *p = start; p < end; p++)
        if (*p == '.' || *p == '>') start = p + 1;
    int len = (int)(end - start);
    bool has_prefix = len >= 2 && !strncmp(start, "vk", 2);
    return bf_fail(s, "%s%.*s: %s: %s", has_prefix ? "" : "vk", len, start, object ? object : "",
                   gpu__vk_result_name(r));
}

/* ------------------------------------------------------------ messenger */

static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                 VkDebugUtilsMessageTypeFlagsEXT type,
                                                 const VkDebugUtilsMessengerCallbackDataEXT *data,
                                                 void *user)
{
    (void)type;
    gpu_context *ctx = user;
    if (ctx) atomic_fetch_add(&ctx->n_messages, 1);
    atomic_fetch_add(&gpu__messages_total, 1);
    bool is_error = severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    bf_log(is_error ? BF_LOG_ERROR : BF_LOG_WARN, "vulkan validation: %s",
           data && data->pMessage ? data->pMessage : "(no message)");
    return VK_FALSE;
}

static VkDebugUtilsMessengerCreateInfoEXT messenger_info(void *user)
{
    return (VkDebugUtilsMessengerCreateInfoEXT){
        .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT,
        .messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                           VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT,
        .messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT,
        .pfnUserCallback = on_message,
        .pUserData = user,
    };
}

/* ------------------------------------------------------------ instance */

bool gpu__validation_wanted(const gpu_config *cfg)
{
    gpu_validation v = cfg ? cfg->validation : GPU_VALIDATION_ENV;
    if (v == GPU_VALIDATION_ON) return true;
    if (v == GPU_VALIDATION_OFF) return false;
    const char *e = getenv("BITFUSE_VALIDATION");
    return e && e[0] && strcmp(e, "0") != 0;
}

static bf_status open_loader(const char *path, gpu__vk *vk)
{
    vk->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!vk->lib) return bf_fail(BF_NO_DEVICE, "cannot load the Vulkan loader %s: %s", path, dlerror());
    *(void **)&vk->GetInstanceProcAddr = dlsym(vk->lib, "vkGetInstanceProcAddr");
    if (!vk->GetInstanceProcAddr) {
        dlclose(vk->lib);
        vk->lib = NULL;
        return bf_fail(BF_NO_DEVICE, "%s has no vkGetInstanceProcAddr", path);
    }
#define GPU__LOAD(name) vk->name = (PFN_vk##name)vk->GetInstanceProcAddr(NULL, "vk" #name);
    GPU__VK_GLOBAL(GPU__LOAD)
#undef GPU__LOAD
    if (!vk->CreateInstance || !vk->EnumerateInstanceExtensionProperties ||
        !vk->EnumerateInstanceLayerProperties) {
        dlclose(vk->lib);
        vk->lib = NULL;
        return bf_fail(BF_NO_DEVICE, "%s: incomplete Vulkan loader", path);
    }
    return BF_OK;
}

static bool has_layer(const gpu__vk *vk, const char *name)
{
    VkLayerProperties props[64];
    uint32_t n = 64;
    VkResult r = vk->EnumerateInstanceLayerProperties(&n, props);
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) return false;
    for (uint32_t i = 0; i < n; i++)
        if (!strcmp(props[i].layerName, name)) return true;
    return false;
}

static bool has_instance_extension(const gpu__vk *vk, const char *layer, const char *name)
{
    VkExtensionProperties props[128];
    uint32_t n = 128;
    VkResult r = vk->EnumerateInstanceExtensionProperties(layer, &n, props);
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) return false;
    for (uint32_t i = 0; i < n; i++)
        if (!strcmp(props[i].extensionName, name)) return true;
    return false;
}

bf_status gpu__instance_create(const gpu_config *cfg, bool validation, gpu_context *user,
                               gpu__instance *out)
{
    gpu__instance inst = {0};
    bf_status status = open_loader(cfg && cfg->loader ? cfg->loader : "libvulkan.so.1", &inst.vk);
    if (status != BF_OK) return status;

    uint32_t api = VK_API_VERSION_1_0;
    if (inst.vk.EnumerateInstanceVersion) inst.vk.EnumerateInstanceVersion(&api);
    if (api < VK_API_VERSION_1_2) {
        status = bf_fail(BF_NO_DEVICE, "the Vulkan loader supports %u.%u, bitfuse needs 1.2",
                         VK_API_VERSION_MAJOR(api), VK_API_VERSION_MINOR(api));
        goto fail;
    }

    const char *layers[1];
    uint32_t n_layers = 0;
    const char *exts[2 + GPU__MAX_SURFACE_EXTENSIONS];
    uint32_t n_exts = 0;
    bool has_features = false;
    if (validation) {
        if (!has_layer(&inst.vk, validation_layer)) {
            status = bf_fail(BF_UNSUPPORTED,
                             "Vulkan validation was requested (BITFUSE_VALIDATION=1) but %s is not "
                             "installed (Debian: apt install vulkan-validationlayers)",
                             validation_layer);
            goto fail;
        }
        layers[n_layers++] = validation_layer;
        if (!has_instance_extension(&inst.vk, NULL, VK_EXT_DEBUG_UTILS_EXTENSION_NAME) &&
            !has_instance_extension(&inst.vk, validation_layer, VK_EXT_DEBUG_UTILS_EXTENSION_NAME)) {
            status = bf_fail(BF_UNSUPPORTED, "Vulkan validation needs %s, which is missing",
                             VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
            goto fail;
        }
        exts[n_exts++] = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;
        inst.has_debug_utils = true;
        inst.has_validation = true;
        has_features = has_instance_extension(&inst.vk, validation_layer,
                                              VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME);
        if (has_features) exts[n_exts++] = VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME;
    }

    /* Presentation only when a window is wanted: headless runs ask for nothing more. */
    if (cfg && cfg->make_surface) {
        if (cfg->n_surface_extensions > GPU__MAX_SURFACE_EXTENSIONS) {
            status = bf_fail(BF_INVALID_ARG, "gpu: %u surface extensions (at most %d)", cfg->n_surface_extensions,
                             GPU__MAX_SURFACE_EXTENSIONS);
            goto fail;
        }
        for (uint32_t i = 0; i < cfg->n_surface_extensions; i++) {
            if (!has_instance_extension(&inst.vk, NULL, cfg->surface_extensions[i])) {
                status = bf_fail(BF_UNSUPPORTED, "the Vulkan instance cannot present to a window: %s is missing",
                                 cfg->surface_extensions[i]);
                goto fail;
            }
            exts[n_exts++] = cfg->surface_extensions[i];
        }
        inst.has_surface = true;
    }

    /* Synchronization validation catches a missing or wrong barrier, the
     * error compute code makes most and lavapipe forgives. */
    VkDebugUtilsMessengerCreateInfoEXT msg_info = messenger_info(user);
    VkValidationFeatureEnableEXT enables[] = {VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT};
    VkValidationFeaturesEXT features = {
        .sType = VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT,
        .pNext = &msg_info, /* also reports on vkCreateInstance / vkDestroyInstance */
        .enabledValidationFeatureCount = 1,
        .pEnabledValidationFeatures = enables,
    };
    VkApplicationInfo app = {
        .sType = VK_STRUCTURE_TYPE_APPLICATION_INFO,
        .pApplicationName = "bitfuse",
        .pEngineName = "bitfuse",
        .apiVersion = VK_API_VERSION_1_2,
    };
    VkInstanceCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO,
        .pNext = !validation ? NULL : has_features ? (const void *)&features : (const void *)&msg_info,
        .pApplicationInfo = &app,
        .enabledLayerCount = n_layers,
        .ppEnabledLayerNames = layers,
        .enabledExtensionCount = n_exts,
        .ppEnabledExtensionNames = exts,
    };
    VkResult r = GPU__CALL(inst.vk.CreateInstance(&info, NULL, &inst.instance));
    if (r != VK_SUCCESS) {
        status = gpu__vk_fail(r, "vkCreateInstance", "bitfuse");
        if (r == VK_ERROR_INCOMPATIBLE_DRIVER)
            status = bf_fail(BF_NO_DEVICE, "no Vulkan driver found (vkCreateInstance: %s; Debian: "
                             "apt install mesa-vulkan-drivers)", gpu__vk_result_name(r));
        if (status == BF_VULKAN) status = BF_NO_DEVICE;
        goto fail;
    }

#define GPU__LOAD(name) inst.vk.name = (PFN_vk##name)inst.vk.GetInstanceProcAddr(inst.instance, "vk" #name);
    GPU__VK_INSTANCE(GPU__LOAD)
    if (inst.has_debug_utils) {
        GPU__VK_DEBUG(GPU__LOAD)
    }
    if (inst.has_surface) {
        GPU__VK_SURFACE(GPU__LOAD)
    }
#undef GPU__LOAD
    if (!inst.vk.GetPhysicalDeviceProperties2 || !inst.vk.CreateDevice || !inst.vk.GetDeviceProcAddr) {
        status = bf_fail(BF_NO_DEVICE, "the Vulkan loader lacks 1.2 instance functions");
        goto fail;
    }
    if (inst.has_surface && (!inst.vk.DestroySurfaceKHR || !inst.vk.GetPhysicalDeviceSurfaceSupportKHR)) {
        status = bf_fail(BF_UNSUPPORTED, "the Vulkan loader lacks VK_KHR_surface's functions");
        goto fail;
    }
    if (inst.has_debug_utils) {
        if (!inst.vk.CreateDebugUtilsMessengerEXT) {
            status = bf_fail(BF_UNSUPPORTED, "vkCreateDebugUtilsMessengerEXT is missing");
            goto fail;
        }
        GPU__CHECK(inst.vk.CreateDebugUtilsMessengerEXT(inst.instance, &msg_info, NULL, &inst.messenger),
                   "validation messenger");
    }
    *out = inst;
    return BF_OK;

fail:
    gpu__instance_destroy(&inst);
    return status;
}

void gpu__instance_destroy(gpu__instance *inst)
{
    if (inst->messenger) inst->vk.DestroyDebugUtilsMessengerEXT(inst->instance, inst->messenger, NULL);
    if (inst->instance) inst->vk.DestroyInstance(inst->instance, NULL);
    if (inst->vk.lib) dlclose(inst->vk.lib);
    memset(inst, 0, sizeof *inst);
}

/* ------------------------------------------------------------ devices */

const char *gpu_device_type_name(VkPhysicalDeviceType type)
{
    switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "cpu";
    default: return "other";
    }
}

/* vkcube's ranking: discrete before integrated before virtual before CPU. */
static int type_rank(VkPhysicalDeviceType type)
{
    switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 1;
    default: return 0;
    }
}

static bool device_has_extension(const gpu__vk *vk, VkPhysicalDevice phys, const char *name)
{
    VkExtensionProperties props[512];
    uint32_t n = 512;
    VkResult r = vk->EnumerateDeviceExtensionProperties(phys, NULL, &n, props);
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) return false;
    for (uint32_t i = 0; i < n; i++)
        if (!strcmp(props[i].extensionName, name)) return true;
    return false;
}

void gpu__query_device(const gpu__instance *inst, VkPhysicalDevice phys, gpu_device_info *info)
{
    const gpu__vk *vk = &inst->vk;
    memset(info, 0, sizeof *info);
    VkPhysicalDeviceProperties p0;
    vk->GetPhysicalDeviceProperties(phys, &p0);
    bool is_12 = p0.apiVersion >= VK_API_VERSION_1_2;

    VkPhysicalDeviceSubgroupProperties subgroup = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES};
    VkPhysicalDeviceMaintenance3Properties maint3 = {
        .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MAINTENANCE_3_PROPERTIES, .pNext = &subgroup};
    VkPhysicalDeviceIDProperties ids = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_ID_PROPERTIES, .pNext = &maint3};
    VkPhysicalDeviceDriverProperties driver = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES,
                                               .pNext = &ids};
    VkPhysicalDeviceProperties2 p2 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2,
                                      .pNext = is_12 ? (void *)&driver : (void *)&ids};
    if (p0.apiVersion >= VK_API_VERSION_1_1) vk->GetPhysicalDeviceProperties2(phys, &p2);
    else p2.properties = p0;
    const VkPhysicalDeviceProperties *p = &p2.properties;
    const VkPhysicalDeviceLimits *l = &p->limits;

    snprintf(info->name, sizeof info->name, "%s", p->deviceName);
    info->type = p->deviceType;
    info->vendor_id = p->vendorID;
    info->device_id = p->deviceID;
    info->api_version = p->apiVersion;
    if (is_12) {
        snprintf(info->driver_name, sizeof info->driver_name, "%s", driver.driverName);
        snprintf(info->driver_info, sizeof info->driver_info, "%s", driver.driverInfo);
    }
    memcpy(info->device_uuid, ids.deviceUUID, VK_UUID_SIZE);
    memcpy(info->pipeline_cache_uuid, p->pipelineCacheUUID, VK_UUID_SIZE);

    gpu_limits *lim = &info->limits;
    lim->max_storage_buffer_range = l->maxStorageBufferRange;
    lim->max_memory_allocation_size = maint3.maxMemoryAllocationSize;
    lim->min_storage_buffer_offset_alignment = l->minStorageBufferOffsetAlignment;
    lim->non_coherent_atom_size = l->nonCoherentAtomSize;
    lim->subgroup_size = subgroup.subgroupSize;
    lim->subgroup_ops = (subgroup.supportedStages & VK_SHADER_STAGE_COMPUTE_BIT) ? subgroup.supportedOperations : 0;
    lim->max_compute_workgroup_invocations = l->maxComputeWorkGroupInvocations;
    for (int i = 0; i < 3; i++) {
        lim->max_compute_workgroup_size[i] = l->maxComputeWorkGroupSize[i];
        lim->max_compute_workgroup_count[i] = l->maxComputeWorkGroupCount[i];
    }
    lim->max_compute_shared_memory_size = l->maxComputeSharedMemorySize;
    lim->max_push_constants_size = l->maxPushConstantsSize;
    lim->max_per_stage_storage_buffers = l->maxPerStageDescriptorStorageBuffers;
    lim->timestamp_period_ns = l->timestampPeriod;
    if (p0.apiVersion >= VK_API_VERSION_1_1 &&
        device_has_extension(vk, phys, VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME)) {
        VkPhysicalDeviceExternalMemoryHostPropertiesEXT host = {
            .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_EXTERNAL_MEMORY_HOST_PROPERTIES_EXT};
        VkPhysicalDeviceProperties2 ph = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, .pNext = &host};
        vk->GetPhysicalDeviceProperties2(phys, &ph);
        lim->host_import_alignment = host.minImportedHostPointerAlignment;
    }

    VkPhysicalDeviceMemoryProperties mem;
    vk->GetPhysicalDeviceMemoryProperties(phys, &mem);
    lim->n_heaps = mem.memoryHeapCount < GPU_MAX_HEAPS ? mem.memoryHeapCount : GPU_MAX_HEAPS;
    for (uint32_t i = 0; i < lim->n_heaps; i++) {
        lim->heaps[i].size_bytes = mem.memoryHeaps[i].size;
        lim->heaps[i].is_device_local = mem.memoryHeaps[i].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT;
    }

    /* Prefer a compute queue family without graphics (an async compute
     * queue on discrete GPUs), else any with compute. */
    VkQueueFamilyProperties fams[32];
    uint32_t n_fams = 32;
    vk->GetPhysicalDeviceQueueFamilyProperties(phys, &n_fams, fams);
    uint32_t best = UINT32_MAX;
    for (uint32_t i = 0; i < n_fams; i++) {
        if (!(fams[i].queueFlags & VK_QUEUE_COMPUTE_BIT) || fams[i].queueCount == 0) continue;
        if (best == UINT32_MAX || !(fams[i].queueFlags & VK_QUEUE_GRAPHICS_BIT)) best = i;
        if (!(fams[i].queueFlags & VK_QUEUE_GRAPHICS_BIT)) break;
    }
    /* Buffer device addresses: the fusion window reads the depth ring
     * through one (gpu_buffer_address). Optional in Vulkan 1.2, which every
     * desktop driver and lavapipe offer. */
    if (is_12 && vk->GetPhysicalDeviceFeatures2) {
        VkPhysicalDeviceVulkan12Features f12 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES};
        VkPhysicalDeviceFeatures2 f2 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2, .pNext = &f12};
        vk->GetPhysicalDeviceFeatures2(phys, &f2);
        info->has_buffer_address = f12.bufferDeviceAddress;
    }
    info->is_usable = is_12 && best != UINT32_MAX && info->has_buffer_address;
    if (best != UINT32_MAX) {
        info->queue_family = best;
        lim->timestamp_valid_bits = fams[best].timestampValidBits;
        lim->has_timestamps = fams[best].timestampValidBits > 0 && l->timestampPeriod > 0;
    }
}

static bool contains_ci(const char *hay, const char *needle)
{
    size_t n = strlen(needle);
    for (; *hay; hay++) {
        size_t k = 0;
        while (k < n && hay[k] && tolower((unsigned char)hay[k]) == tolower((unsigned char)needle[k])) k++;
        if (k == n) return true;
    }
    return n == 0;
}

const char *gpu__wanted_device(const gpu_config *cfg)
{
    if (cfg && cfg->device && cfg->device[0]) return cfg->device;
    const char *e = getenv("BITFUSE_DEVICE");
    return e && e[0] ? e : NULL;
}

uint32_t gpu__choose_device(const gpu_device_info *infos, uint32_t n, const char *want)
{
    /* A number below GPU_MAX_DEVICES is an index and only that ("1" was
     * matched against "LLVM 15.0.6" when there was no device 1); a larger
     * one is part of a name ("1080"). */
    uint32_t index;
    bool is_index = want && bf_parse_u32(want, &index);
    if (is_index && index < n) {
        if (infos[index].is_usable) return index;
        bf_fail(BF_NO_DEVICE, "device %u (%s) is not usable: bitfuse needs Vulkan 1.2 with buffer device addresses and a "
                "compute queue", index,
                infos[index].name);
        return UINT32_MAX;
    }
    if (is_index && index < GPU_MAX_DEVICES) {
        bf_fail(BF_NO_DEVICE, "no device %u: %u found (bitfuse devices lists them)", index, n);
        return UINT32_MAX;
    }
    uint32_t best = UINT32_MAX;
    for (uint32_t i = 0; i < n; i++) {
        if (!infos[i].is_usable) continue;
        if (want && !contains_ci(infos[i].name, want)) continue;
        if (best == UINT32_MAX || type_rank(infos[i].type) > type_rank(infos[best].type)) best = i;
    }
    if (best == UINT32_MAX) {
        if (want) {
            char names[512] = "";
            for (uint32_t i = 0; i < n; i++) {
                size_t len = strlen(names);
                snprintf(names + len, sizeof names - len, "%s'%s'", i ? ", " : "", infos[i].name);
            }
            bf_fail(BF_NO_DEVICE, "no usable Vulkan device matches '%s' (BITFUSE_DEVICE or --device%s); "
                    "devices: %s", want, is_index ? "; no such index either" : "", n ? names : "none");
        } else {
            bf_fail(BF_NO_DEVICE, "no usable Vulkan device (%u found; bitfuse needs Vulkan 1.2 with "
                    "buffer device addresses and a compute queue)", n);
        }
    }
    return best;
}

static bf_status enumerate(const gpu__instance *inst, VkPhysicalDevice phys[GPU_MAX_DEVICES],
                           gpu_device_info infos[GPU_MAX_DEVICES], uint32_t *n)
{
    uint32_t count = GPU_MAX_DEVICES;
    VkResult r = GPU__CALL(inst->vk.EnumeratePhysicalDevices(inst->instance, &count, phys));
    if (r != VK_SUCCESS && r != VK_INCOMPLETE) {
        bf_status s = gpu__vk_fail(r, "vkEnumeratePhysicalDevices", "instance");
        return s == BF_VULKAN ? BF_NO_DEVICE : s;
    }
    if (count == 0) return bf_fail(BF_NO_DEVICE, "no Vulkan device (no driver installed? Debian: mesa-vulkan-drivers)");
    for (uint32_t i = 0; i < count; i++) gpu__query_device(inst, phys[i], &infos[i]);
    *n = count;
    return BF_OK;
}

bf_status gpu_device_list(const gpu_config *cfg, gpu_device_info out[GPU_MAX_DEVICES], uint32_t *n,
                          uint32_t *chosen)
{
    gpu__instance inst;
    bf_status status = gpu__instance_create(cfg, false, NULL, &inst);
    if (status != BF_OK) return status;
    VkPhysicalDevice phys[GPU_MAX_DEVICES];
    uint32_t count = 0;
    status = enumerate(&inst, phys, out, &count);
    gpu__instance_destroy(&inst);
    if (status != BF_OK) return status;
    *n = count;
    *chosen = gpu__choose_device(out, count, gpu__wanted_device(cfg));
    return BF_OK;
}

/* ------------------------------------------------------------ context */

void gpu__name(gpu_context *ctx, VkObjectType type, uint64_t handle, const char *fmt, ...)
{
    if (!ctx->inst.vk.SetDebugUtilsObjectNameEXT || !handle) return;
    char name[128];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(name, sizeof name, fmt, ap);
    va_end(ap);
    gpu_set_name(ctx, type, handle, name);
}

void gpu_set_name(gpu_context *ctx, VkObjectType type, uint64_t handle, const char *name)
{
    if (!ctx->inst.vk.SetDebugUtilsObjectNameEXT || !handle || !ctx->device) return;
    VkDebugUtilsObjectNameInfoEXT info = {
        .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_OBJECT_NAME_INFO_EXT,
        .objectType = type,
        .objectHandle = handle,
        .pObjectName = name,
    };
    ctx->inst.vk.SetDebugUtilsObjectNameEXT(ctx->device, &info); /* naming never fails the caller */
}

static bf_status create_device(gpu_context *ctx)
{
    bf_status status = BF_OK;
    float priority = 1.0f;
    VkDeviceQueueCreateInfo queue = {
        .sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
        .queueFamilyIndex = ctx->info.queue_family,
        .queueCount = 1,
        .pQueuePriorities = &priority,
    };
    const char *exts[2];
    uint32_t n_exts = 0;
    if (ctx->surface) exts[n_exts++] = VK_KHR_SWAPCHAIN_EXTENSION_NAME;
    if (ctx->host_import_align) exts[n_exts++] = VK_EXT_EXTERNAL_MEMORY_HOST_EXTENSION_NAME;
    VkPhysicalDeviceVulkan12Features f12 = {.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES,
                                             .bufferDeviceAddress = VK_TRUE};
    VkDeviceCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO,
        .pNext = &f12,
        .queueCreateInfoCount = 1,
        .pQueueCreateInfos = &queue,
        .enabledExtensionCount = n_exts,
        .ppEnabledExtensionNames = exts,
    };
    GPU__CHECK(ctx->inst.vk.CreateDevice(ctx->phys, &info, NULL, &ctx->device), ctx->info.name);
    gpu__vk *vk = &ctx->inst.vk;
#define GPU__LOAD(fn)                                                            \
    vk->fn = (PFN_vk##fn)vk->GetDeviceProcAddr(ctx->device, "vk" #fn);           \
    if (!vk->fn) {                                                               \
        status = bf_fail(BF_VULKAN, "%s: vk" #fn " is missing", ctx->info.name);   \
        goto fail;                                                               \
    }
    GPU__VK_DEVICE(GPU__LOAD)
    if (ctx->surface) {
        GPU__VK_SWAPCHAIN(GPU__LOAD)
    }
#undef GPU__LOAD
    if (ctx->host_import_align) {
        ctx->GetMemoryHostPointerPropertiesEXT = (PFN_vkGetMemoryHostPointerPropertiesEXT)vk->GetDeviceProcAddr(
            ctx->device, "vkGetMemoryHostPointerPropertiesEXT");
        if (!ctx->GetMemoryHostPointerPropertiesEXT) ctx->host_import_align = 0;
    }
    vk->GetDeviceQueue(ctx->device, ctx->info.queue_family, 0, &ctx->queue);
    gpu__name(ctx, VK_OBJECT_TYPE_DEVICE, (uint64_t)(uintptr_t)ctx->device, "gpu.device");
    gpu__name(ctx, VK_OBJECT_TYPE_QUEUE, (uint64_t)(uintptr_t)ctx->queue, "gpu.compute_queue");
fail:
    return status;
}

static bool needs_staging(const gpu_context *ctx)
{
    if (ctx->force_staging) return true;
    for (uint32_t i = 0; i < ctx->mem_props.memoryTypeCount; i++) {
        VkMemoryPropertyFlags f = ctx->mem_props.memoryTypes[i].propertyFlags;
        if ((f & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT) && !(f & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT)) return true;
    }
    return false;
}

static bf_status create_commands(gpu_context *ctx, const gpu_config *cfg)
{
    bf_status status = BF_OK;
    gpu__vk *vk = &ctx->inst.vk;
    VkCommandPoolCreateInfo pool = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO,
        .flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT,
        .queueFamilyIndex = ctx->info.queue_family,
    };
    GPU__CHECK(vk->CreateCommandPool(ctx->device, &pool, NULL, &ctx->command_pool), "gpu.command_pool");
    gpu__name(ctx, VK_OBJECT_TYPE_COMMAND_POOL, (uint64_t)ctx->command_pool, "gpu.command_pool");
    VkCommandBuffer cmds[2];
    VkCommandBufferAllocateInfo alloc = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO,
        .commandPool = ctx->command_pool,
        .level = VK_COMMAND_BUFFER_LEVEL_PRIMARY,
        .commandBufferCount = 2,
    };
    GPU__CHECK(vk->AllocateCommandBuffers(ctx->device, &alloc, cmds), "gpu.cmd");
    ctx->cmd = cmds[0];
    ctx->xfer_cmd = cmds[1];
    gpu__name(ctx, VK_OBJECT_TYPE_COMMAND_BUFFER, (uint64_t)(uintptr_t)ctx->cmd, "gpu.cmd");
    gpu__name(ctx, VK_OBJECT_TYPE_COMMAND_BUFFER, (uint64_t)(uintptr_t)ctx->xfer_cmd, "gpu.xfer_cmd");
    VkFenceCreateInfo fence = {.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    GPU__CHECK(vk->CreateFence(ctx->device, &fence, NULL, &ctx->fence), "gpu.fence");
    GPU__CHECK(vk->CreateFence(ctx->device, &fence, NULL, &ctx->xfer_fence), "gpu.xfer_fence");
    gpu__name(ctx, VK_OBJECT_TYPE_FENCE, (uint64_t)ctx->fence, "gpu.fence");
    gpu__name(ctx, VK_OBJECT_TYPE_FENCE, (uint64_t)ctx->xfer_fence, "gpu.xfer_fence");

    ctx->stage_cap = cfg && cfg->stage_cap ? cfg->stage_cap : 64;
    ctx->stages = calloc(ctx->stage_cap, sizeof *ctx->stages);
    if (!ctx->stages) {
        status = bf_fail(BF_NO_MEMORY, "gpu: %u stage records", ctx->stage_cap);
        goto fail;
    }
    if (ctx->info.limits.has_timestamps) {
        VkQueryPoolCreateInfo q = {
            .sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO,
            .queryType = VK_QUERY_TYPE_TIMESTAMP,
            .queryCount = 2 * ctx->stage_cap,
        };
        GPU__CHECK(vk->CreateQueryPool(ctx->device, &q, NULL, &ctx->query_pool), "gpu.timestamps");
        gpu__name(ctx, VK_OBJECT_TYPE_QUERY_POOL, (uint64_t)ctx->query_pool, "gpu.timestamps");
    }

    ctx->bindings_cap = cfg && cfg->bindings_cap ? cfg->bindings_cap : 256;
    VkDescriptorPoolSize size = {
        .type = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
        .descriptorCount = ctx->bindings_cap * GPU_MAX_BINDINGS,
    };
    VkDescriptorPoolCreateInfo dp = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO,
        .flags = VK_DESCRIPTOR_POOL_CREATE_FREE_DESCRIPTOR_SET_BIT,
        .maxSets = ctx->bindings_cap,
        .poolSizeCount = 1,
        .pPoolSizes = &size,
    };
    GPU__CHECK(vk->CreateDescriptorPool(ctx->device, &dp, NULL, &ctx->descriptor_pool), "gpu.descriptor_pool");
    gpu__name(ctx, VK_OBJECT_TYPE_DESCRIPTOR_POOL, (uint64_t)ctx->descriptor_pool, "gpu.descriptor_pool");

    if (needs_staging(ctx)) {
        gpu_buffer_desc sd = {
            .name = "gpu.staging",
            .size_bytes = cfg && cfg->staging_bytes ? cfg->staging_bytes : 16u << 20,
            .memory = GPU_MEMORY_READBACK, /* host-visible and cached: serves both directions */
            .usage = GPU_USAGE_TRANSFER,
        };
        status = gpu_buffer_create(ctx, &sd, &ctx->staging);
        if (status != BF_OK) goto fail;
    }
fail:
    return status;
}

/* The alignment of host memory a CPU device imports, or 0 where buffers
 * keep the driver's memory. Only a CPU device: its device memory is host
 * memory anyway, and Mesa 25's lavapipe takes it from a memfd (shared
 * memory), which this kernel's transparent huge pages skip; memory we map
 * ourselves is anonymous and takes them (docs/gpu.md, "The driver"). A GPU
 * would read imported memory across the bus. */
static VkDeviceSize host_import_alignment(const gpu_context *ctx, const gpu_config *cfg)
{
    if ((cfg && cfg->no_host_import) || ctx->force_staging || ctx->info.type != VK_PHYSICAL_DEVICE_TYPE_CPU)
        return 0;
    VkDeviceSize a = ctx->info.limits.host_import_alignment;
    /* A power of two that divides a huge page, or not at all. */
    return a && !(a & (a - 1)) && a <= ((VkDeviceSize)2 << 20) ? a : 0;
}

/* The window's surface (made by the caller's function on our instance),
 * and a compute queue family of the chosen device that presents to it:
 * the one device choice picked when it can, else the first that can
 * (presenting from the compute queue keeps one queue and one fence). */
static bf_status open_surface(gpu_context *ctx, const gpu_config *cfg)
{
    bf_status status = cfg->make_surface(cfg->surface_user, ctx->inst.instance, &ctx->surface);
    if (status != BF_OK) {
        ctx->surface = VK_NULL_HANDLE;
        return status;
    }
    gpu__vk *vk = &ctx->inst.vk;
    if (!device_has_extension(&ctx->inst.vk, ctx->phys, VK_KHR_SWAPCHAIN_EXTENSION_NAME))
        return bf_fail(BF_UNSUPPORTED, "%s cannot present to a window: no %s", ctx->info.name,
                       VK_KHR_SWAPCHAIN_EXTENSION_NAME);
    VkQueueFamilyProperties fams[32];
    uint32_t n_fams = 32;
    vk->GetPhysicalDeviceQueueFamilyProperties(ctx->phys, &n_fams, fams);
    uint32_t pick = UINT32_MAX;
    for (uint32_t k = 0; k <= n_fams && pick == UINT32_MAX; k++) {
        uint32_t i = k == 0 ? ctx->info.queue_family : k - 1;
        if (i >= n_fams || !(fams[i].queueFlags & VK_QUEUE_COMPUTE_BIT) || fams[i].queueCount == 0) continue;
        VkBool32 ok = VK_FALSE;
        VkResult r = vk->GetPhysicalDeviceSurfaceSupportKHR(ctx->phys, i, ctx->surface, &ok);
        if (r == VK_SUCCESS && ok) pick = i;
    }
    if (pick == UINT32_MAX)
        return bf_fail(BF_UNSUPPORTED, "%s cannot present to the window: no compute queue family presents to "
                       "its surface", ctx->info.name);
    if (pick != ctx->info.queue_family) {
        ctx->info.queue_family = pick;
        ctx->info.limits.timestamp_valid_bits = fams[pick].timestampValidBits;
        ctx->info.limits.has_timestamps = fams[pick].timestampValidBits > 0 && ctx->info.limits.timestamp_period_ns > 0;
    }
    return BF_OK;
}

bf_status gpu_context_create(const gpu_config *cfg, gpu_context **out)
{
    bf_status status = BF_OK;
    gpu_context *ctx = calloc(1, sizeof *ctx);
    if (!ctx) return bf_fail(BF_NO_MEMORY, "gpu: context");
    ctx->force_staging = cfg && cfg->force_staging;
    status = gpu__instance_create(cfg, gpu__validation_wanted(cfg), ctx, &ctx->inst);
    if (status != BF_OK) goto fail;

    VkPhysicalDevice phys[GPU_MAX_DEVICES];
    gpu_device_info infos[GPU_MAX_DEVICES];
    uint32_t n = 0;
    status = enumerate(&ctx->inst, phys, infos, &n);
    if (status != BF_OK) goto fail;
    uint32_t pick = gpu__choose_device(infos, n, gpu__wanted_device(cfg));
    if (pick == UINT32_MAX) {
        status = BF_NO_DEVICE; /* message recorded by gpu__choose_device */
        goto fail;
    }
    ctx->phys = phys[pick];
    ctx->info = infos[pick];
    ctx->inst.vk.GetPhysicalDeviceMemoryProperties(ctx->phys, &ctx->mem_props);
    if (cfg && cfg->make_surface) {
        status = open_surface(ctx, cfg);
        if (status != BF_OK) goto fail;
    }

    ctx->host_import_align = host_import_alignment(ctx, cfg);
    status = create_device(ctx);
    if (status != BF_OK) goto fail;
    status = create_commands(ctx, cfg);
    if (status != BF_OK) goto fail;
    status = gpu__pipeline_cache_open(ctx, cfg);
    if (status != BF_OK) goto fail;

    bf_info("gpu: %s (%s, Vulkan %u.%u.%u%s%s%s%s)", ctx->info.name, gpu_device_type_name(ctx->info.type),
            VK_API_VERSION_MAJOR(ctx->info.api_version), VK_API_VERSION_MINOR(ctx->info.api_version),
            VK_API_VERSION_PATCH(ctx->info.api_version), ctx->inst.has_validation ? ", validation on" : "",
            ctx->staging ? ", staged transfers" : "", ctx->host_import_align ? ", imported host memory" : "",
            ctx->surface ? ", presenting" : "");
    *out = ctx;
    return BF_OK;

fail:
    gpu_context_destroy(ctx);
    return status;
}

void gpu_context_destroy(gpu_context *ctx)
{
    if (!ctx) return;
    gpu__vk *vk = &ctx->inst.vk;
    if (ctx->device) {
        vk->DeviceWaitIdle(ctx->device);
        gpu__pipeline_cache_close(ctx);
        gpu_buffer_destroy(ctx->staging);
        if (ctx->n_bindings)
            bf_warn("gpu: %u binding sets still alive at context destroy", ctx->n_bindings);
        if (ctx->descriptor_pool) vk->DestroyDescriptorPool(ctx->device, ctx->descriptor_pool, NULL);
        for (int i = 0; i <= GPU_MAX_BINDINGS; i++)
            if (ctx->set_layouts[i]) vk->DestroyDescriptorSetLayout(ctx->device, ctx->set_layouts[i], NULL);
        if (ctx->query_pool) vk->DestroyQueryPool(ctx->device, ctx->query_pool, NULL);
        if (ctx->fence) vk->DestroyFence(ctx->device, ctx->fence, NULL);
        if (ctx->xfer_fence) vk->DestroyFence(ctx->device, ctx->xfer_fence, NULL);
        if (ctx->command_pool) vk->DestroyCommandPool(ctx->device, ctx->command_pool, NULL);
        if (ctx->n_swapchains) bf_warn("gpu: %u swapchains still alive at context destroy", ctx->n_swapchains);
        vk->DestroyDevice(ctx->device, NULL);
    }
    if (ctx->surface) vk->DestroySurfaceKHR(ctx->inst.instance, ctx->surface, NULL);
    free(ctx->stages);
    gpu__instance_destroy(&ctx->inst);
#ifndef NDEBUG
    memset(ctx, 0xff, sizeof *ctx); /* poison: a use after destroy faults */
#endif
    free(ctx);
}

const gpu_device_info *gpu_device(const gpu_context *ctx) { return &ctx->info; }
const gpu_limits *gpu_device_limits(const gpu_context *ctx) { return &ctx->info.limits; }
VkPhysicalDeviceType gpu_device_type(const gpu_context *ctx) { return ctx->info.type; }
bool gpu_imports_host_memory(const gpu_context *ctx) { return ctx->host_import_align != 0; }

const char *gpu_device_name(const gpu_context *ctx) { return ctx->info.name; }
bool gpu_validation_enabled(const gpu_context *ctx) { return ctx->inst.has_validation; }
uint32_t gpu_validation_message_count(const gpu_context *ctx) { return atomic_load(&ctx->n_messages); }
uint32_t gpu_validation_message_total(void) { return atomic_load(&gpu__messages_total); }
