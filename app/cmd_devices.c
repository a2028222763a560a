/* bitfuse devices: lists the Vulkan devices, marks the one bitfuse would
 * use and prints the limits it sizes its work by; then the capture
 * backends compiled in and the depth cameras they find. */
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "capture/capture.h"
#include "gpu/gpu.h"

#define DEVICES_MAX_CAMERAS 16

static const char devices_usage[] =
    "usage: bitfuse devices [--device NAME] [--json]\n\n"
    "Lists the Vulkan devices and marks with '*' the one bitfuse would use:\n"
    "discrete GPU first, then integrated, virtual, CPU (lavapipe). A device is\n"
    "picked by a case-insensitive part of its name or by its index, from\n"
    "--device or the BITFUSE_DEVICE environment variable. Prints the limits\n"
    "bitfuse sizes its work by. Then lists the capture backends built in\n"
    "(freenect, openni2, v4l2) and the cameras they find, with the URI to\n"
    "pass to bitfuse (docs/devices.md).\n";

static void uuid_text(const uint8_t *u, char out[2 * VK_UUID_SIZE + 5])
{
    char *p = out;
    for (unsigned i = 0; i < VK_UUID_SIZE; i++)
        p += sprintf(p, "%s%02x", i == 4 || i == 6 || i == 8 || i == 10 ? "-" : "", u[i]);
}

static void json_uints(cJSON *o, const char *name, const uint32_t *v, size_t n)
{
    double d[3];
    for (size_t i = 0; i < n && i < 3; i++) d[i] = v[i];
    app_json_numbers(o, name, d, n < 3 ? n : 3);
}

static cJSON *json_limits(const gpu_limits *l)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "max_storage_buffer_range", (double)l->max_storage_buffer_range);
    cJSON_AddNumberToObject(o, "max_memory_allocation_size", (double)l->max_memory_allocation_size);
    cJSON_AddNumberToObject(o, "min_storage_buffer_offset_alignment", (double)l->min_storage_buffer_offset_alignment);
    cJSON_AddNumberToObject(o, "subgroup_size", l->subgroup_size);
    cJSON_AddNumberToObject(o, "max_compute_workgroup_invocations", l->max_compute_workgroup_invocations);
    json_uints(o, "max_compute_workgroup_size", l->max_compute_workgroup_size, 3);
    json_uints(o, "max_compute_workgroup_count", l->max_compute_workgroup_count, 3);
    cJSON_AddNumberToObject(o, "max_compute_shared_memory_size", l->max_compute_shared_memory_size);
    cJSON_AddNumberToObject(o, "max_push_constants_size", l->max_push_constants_size);
    cJSON_AddNumberToObject(o, "max_per_stage_storage_buffers", l->max_per_stage_storage_buffers);
    cJSON_AddBoolToObject(o, "has_timestamps", l->has_timestamps);
    cJSON_AddNumberToObject(o, "timestamp_valid_bits", l->timestamp_valid_bits);
    cJSON_AddNumberToObject(o, "timestamp_period_ns", l->timestamp_period_ns);
    cJSON_AddNumberToObject(o, "host_import_alignment", (double)l->host_import_alignment);
    cJSON *heaps = cJSON_AddArrayToObject(o, "heaps");
    for (uint32_t h = 0; h < l->n_heaps; h++) {
        cJSON *heap = cJSON_CreateObject();
        cJSON_AddNumberToObject(heap, "size_bytes", (double)l->heaps[h].size_bytes);
        cJSON_AddBoolToObject(heap, "is_device_local", l->heaps[h].is_device_local);
        cJSON_AddItemToArray(heaps, heap);
    }
    return o;
}

/* The Vulkan devices (n may be 0) and the cameras as one object. */
static cJSON *devices_json(const gpu_device_info *d, uint32_t n, uint32_t chosen, const capture_device_info *cams,
                           uint32_t n_cams)
{
    cJSON *o = cJSON_CreateObject();
    if (chosen < n) cJSON_AddNumberToObject(o, "chosen", chosen);
    else cJSON_AddNullToObject(o, "chosen");
    cJSON *devs = cJSON_AddArrayToObject(o, "devices");
    for (uint32_t i = 0; i < n; i++) {
        char version[48], uuid[2 * VK_UUID_SIZE + 5];
        snprintf(version, sizeof version, "%u.%u.%u", VK_API_VERSION_MAJOR(d[i].api_version),
                 VK_API_VERSION_MINOR(d[i].api_version), VK_API_VERSION_PATCH(d[i].api_version));
        uuid_text(d[i].device_uuid, uuid);
        cJSON *dev = cJSON_CreateObject();
        cJSON_AddNumberToObject(dev, "index", i);
        cJSON_AddStringToObject(dev, "name", d[i].name);
        cJSON_AddStringToObject(dev, "type", gpu_device_type_name(d[i].type));
        cJSON_AddBoolToObject(dev, "is_chosen", i == chosen);
        cJSON_AddBoolToObject(dev, "is_usable", d[i].is_usable);
        cJSON_AddBoolToObject(dev, "buffer_device_address", d[i].has_buffer_address);
        cJSON_AddStringToObject(dev, "api_version", version);
        cJSON_AddStringToObject(dev, "driver", d[i].driver_info[0] ? d[i].driver_info : d[i].driver_name);
        cJSON_AddStringToObject(dev, "device_uuid", uuid);
        cJSON_AddItemToObject(dev, "limits", json_limits(&d[i].limits));
        cJSON_AddItemToArray(devs, dev);
    }
    const char *const *b = capture_backend_names();
    cJSON *backends = cJSON_AddArrayToObject(o, "capture_backends");
    for (int i = 0; b[i]; i++) cJSON_AddItemToArray(backends, cJSON_CreateString(b[i]));
    cJSON *cameras = cJSON_AddArrayToObject(o, "capture_devices");
    for (uint32_t i = 0; i < n_cams && i < DEVICES_MAX_CAMERAS; i++) {
        cJSON *cam = cJSON_CreateObject();
        cJSON_AddStringToObject(cam, "uri", cams[i].uri);
        cJSON_AddStringToObject(cam, "name", cams[i].name);
        cJSON_AddItemToArray(cameras, cam);
    }
    return o;
}

static void print_text_capture(const capture_device_info *cams, uint32_t n_cams)
{
    printf("\nCapture backends:");
    const char *const *b = capture_backend_names();
    for (int i = 0; b[i]; i++) printf("%s%s", i ? ", " : " ", b[i]);
    if (!b[0]) printf(" none (install libfreenect-dev / libopenni2-dev and rebuild)");
    printf("\nCameras found:%s\n", n_cams ? "" : " none (files work too: openni2:FILE.oni, or fakenect dumps)");
    for (uint32_t i = 0; i < n_cams && i < DEVICES_MAX_CAMERAS; i++)
        printf("  %-28s %s\n", cams[i].uri, cams[i].name);
}

static void print_text(const gpu_device_info *d, uint32_t n, uint32_t chosen)
{
    printf("Vulkan devices (* = the one bitfuse uses):\n");
    for (uint32_t i = 0; i < n; i++) {
        const gpu_limits *l = &d[i].limits;
        printf("%c %u  %s  [%s, Vulkan %u.%u.%u%s%s]%s\n", i == chosen ? '*' : ' ', i, d[i].name,
               gpu_device_type_name(d[i].type), VK_API_VERSION_MAJOR(d[i].api_version),
               VK_API_VERSION_MINOR(d[i].api_version), VK_API_VERSION_PATCH(d[i].api_version),
               d[i].driver_info[0] ? ", " : "", d[i].driver_info, d[i].is_usable ? "" : "  (not usable: needs Vulkan 1.2 with buffer device addresses and a compute queue)");
        printf("     storage binding   %llu MiB max (maxStorageBufferRange), offsets aligned to %llu bytes\n",
               (unsigned long long)(l->max_storage_buffer_range >> 20),
               (unsigned long long)l->min_storage_buffer_offset_alignment);
        printf("     allocation        %llu MiB max\n", (unsigned long long)(l->max_memory_allocation_size >> 20));
        printf("     subgroup size     %u\n", l->subgroup_size);
        printf("     workgroup         %u invocations, size %u x %u x %u, count %u x %u x %u, %u KiB shared\n",
               l->max_compute_workgroup_invocations, l->max_compute_workgroup_size[0], l->max_compute_workgroup_size[1],
               l->max_compute_workgroup_size[2], l->max_compute_workgroup_count[0], l->max_compute_workgroup_count[1],
               l->max_compute_workgroup_count[2], l->max_compute_shared_memory_size >> 10);
        printf("     push constants    %u bytes, %u storage buffers per stage\n", l->max_push_constants_size,
               l->max_per_stage_storage_buffers);
        if (l->has_timestamps)
            printf("     timestamps        yes, %u valid bits, %g ns per tick\n", l->timestamp_valid_bits,
                   (double)l->timestamp_period_ns);
        else
            printf("     timestamps        no (stage times unavailable)\n");
        if (!l->host_import_alignment)
            printf("     host import       no (VK_EXT_external_memory_host absent)\n");
        else if (d[i].type == VK_PHYSICAL_DEVICE_TYPE_CPU)
            printf("     host import       yes, %llu-byte alignment: buffers of 4 MiB and more are bitfuse's own "
                   "memory, on huge pages\n", (unsigned long long)l->host_import_alignment);
        else
            printf("     host import       offered, %llu-byte alignment; not used on a GPU (its own memory is "
                   "nearer)\n", (unsigned long long)l->host_import_alignment);
        for (uint32_t h = 0; h < l->n_heaps; h++)
            printf("     memory heap %u     %.1f GiB%s\n", h, (double)l->heaps[h].size_bytes / (1u << 30),
                   l->heaps[h].is_device_local ? ", device-local" : "");
    }
}

int cmd_devices(int argc, char **argv)
{
    bool is_json = false;
    gpu_config cfg = {0};
    const app_option own[] = {
        APP_OPT("--device", APP_OPT_STRING, &cfg.device, "NAME", "the device to mark (as BITFUSE_DEVICE)"),
        APP_OPT("--json", APP_OPT_FLAG, &is_json, NULL, "print one JSON object on stdout"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {.name = "devices", .usage = devices_usage, .tables = tables,
                             .epilog = "exit codes: 0 ok, 2 usage, 4 no (matching) Vulkan device, 5 standard output "
                                       "could not be written\n"};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    static gpu_device_info devs[GPU_MAX_DEVICES];
    uint32_t n = 0, chosen = UINT32_MAX;
    bf_status s = gpu_device_list(&cfg, devs, &n, &chosen);
    /* Keep the GPU's message (gpu__choose_device's names what did not
     * match) across the camera search. */
    char why[1024] = "";
    if (s || chosen == UINT32_MAX) snprintf(why, sizeof why, "%s", bf_last_error());
    /* Cameras are looked for after the GPU so its messages stay first. */
    static capture_device_info cams[DEVICES_MAX_CAMERAS];
    uint32_t n_cams = capture_list_devices(cams, DEVICES_MAX_CAMERAS);
    if (s) {
        if (is_json) app_json_print(devices_json(devs, 0, chosen, cams, n_cams));
        else print_text_capture(cams, n_cams);
        return app_fail("devices", bf_fail(s, "%s", why));
    }
    if (is_json) {
        bf_status sj = app_json_print(devices_json(devs, n, chosen, cams, n_cams));
        if (sj != BF_OK) return app_fail("devices", sj);
    } else {
        print_text(devs, n, chosen);
        print_text_capture(cams, n_cams);
    }
    if (chosen == UINT32_MAX) return app_fail("devices", bf_fail(BF_NO_DEVICE, "%s", why));
    return APP_EXIT_OK;
}
