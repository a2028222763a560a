/* bitfuse devices: lists the Vulkan devices, marks the one bitfuse would
 * use and prints the limits it sizes its work by; then the capture
 * backends compiled in and the depth cameras they find. */
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "capture/capture.h"
#include "gpu/gpu.h"

#define DEVICES_MAX_CAMERAS 16

static void devices_help(FILE *f)
{
    fprintf(f,
            "usage: bitfuse devices [--device NAME] [--json]\n\n"
            "Lists the Vulkan devices and marks with '*' the one bitfuse would use:\n"
            "discrete GPU first, then integrated, virtual, CPU (lavapipe). A device is\n"
            "picked by a case-insensitive part of its name or by its index, from\n"
            "--device or the BITFUSE_DEVICE environment variable. Prints the limits\n"
            "bitfuse sizes its work by. Then lists the capture backends built in\n"
            "(freenect, openni2, v4l2) and the cameras they find, with the URI to\n"
            "pass to bitfuse (docs/devices.md).\n\n"
            "options:\n"
            "  --device NAME     the device to mark (as BITFUSE_DEVICE)\n"
            "  --json            print one JSON object on stdout\n"
            "  -h, --help        this text\n\n"
            "exit codes: 0 ok, 2 usage, 4 no (matching) Vulkan device\n");
}

static void print_uuid(const uint8_t *u)
{
    for (unsigned i = 0; i < VK_UUID_SIZE; i++) printf("%s%02x", i == 4 || i == 6 || i == 8 || i == 10 ? "-" : "", u[i]);
}

static void print_json(const gpu_device_info *d, uint32_t n, uint32_t chosen)
{
    printf("{\"chosen\": ");
    if (chosen < n) printf("%u", chosen);
    else printf("null");
    printf(", \"devices\": [");
    for (uint32_t i = 0; i < n; i++) {
        const gpu_limits *l = &d[i].limits;
        printf("%s\n  {\"index\": %u, \"name\": ", i ? "," : "", i);
        bf_json_string(stdout, d[i].name);
        printf(", \"type\": \"%s\", \"is_chosen\": %s, \"is_usable\": %s, \"api_version\": \"%u.%u.%u\", "
               "\"driver\": ",
               gpu_device_type_name(d[i].type), i == chosen ? "true" : "false", d[i].is_usable ? "true" : "false",
               VK_API_VERSION_MAJOR(d[i].api_version), VK_API_VERSION_MINOR(d[i].api_version),
               VK_API_VERSION_PATCH(d[i].api_version));
        bf_json_string(stdout, d[i].driver_info[0] ? d[i].driver_info : d[i].driver_name);
        printf(", \"device_uuid\": \"");
        print_uuid(d[i].device_uuid);
        printf("\",\n   \"limits\": {\"max_storage_buffer_range\": %llu, \"max_memory_allocation_size\": %llu, "
               "\"min_storage_buffer_offset_alignment\": %llu, \"subgroup_size\": %u, "
               "\"max_compute_workgroup_invocations\": %u, \"max_compute_workgroup_size\": [%u, %u, %u], "
               "\"max_compute_workgroup_count\": [%u, %u, %u], \"max_compute_shared_memory_size\": %u, "
               "\"max_push_constants_size\": %u, \"max_per_stage_storage_buffers\": %u, "
               "\"has_timestamps\": %s, \"timestamp_valid_bits\": %u, \"timestamp_period_ns\": %g, "
               "\"heaps\": [",
               (unsigned long long)l->max_storage_buffer_range, (unsigned long long)l->max_memory_allocation_size,
               (unsigned long long)l->min_storage_buffer_offset_alignment, l->subgroup_size,
               l->max_compute_workgroup_invocations, l->max_compute_workgroup_size[0],
               l->max_compute_workgroup_size[1], l->max_compute_workgroup_size[2], l->max_compute_workgroup_count[0],
               l->max_compute_workgroup_count[1], l->max_compute_workgroup_count[2],
               l->max_compute_shared_memory_size, l->max_push_constants_size, l->max_per_stage_storage_buffers,
               l->has_timestamps ? "true" : "false", l->timestamp_valid_bits, (double)l->timestamp_period_ns);
        for (uint32_t h = 0; h < l->n_heaps; h++)
            printf("%s{\"size_bytes\": %llu, \"is_device_local\": %s}", h ? ", " : "",
                   (unsigned long long)l->heaps[h].size_bytes, l->heaps[h].is_device_local ? "true" : "false");
        printf("]}}");
    }
    printf("\n]");
}

/* Appends the capture part to the JSON object print_json left open. */
static void print_json_capture(const capture_device_info *cams, uint32_t n_cams)
{
    printf(", \"capture_backends\": [");
    const char *const *b = capture_backend_names();
    for (int i = 0; b[i]; i++) {
        printf("%s", i ? ", " : "");
        bf_json_string(stdout, b[i]);
    }
    printf("], \"capture_devices\": [");
    for (uint32_t i = 0; i < n_cams && i < DEVICES_MAX_CAMERAS; i++) {
        printf("%s{\"uri\": ", i ? ", " : "");
        bf_json_string(stdout, cams[i].uri);
        printf(", \"name\": ");
        bf_json_string(stdout, cams[i].name);
        printf("}");
    }
    printf("]}\n");
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
               d[i].driver_info[0] ? ", " : "", d[i].driver_info, d[i].is_usable ? "" : "  (not usable: needs Vulkan 1.2 and a compute queue)");
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
        for (uint32_t h = 0; h < l->n_heaps; h++)
            printf("     memory heap %u     %.1f GiB%s\n", h, (double)l->heaps[h].size_bytes / (1u << 30),
                   l->heaps[h].is_device_local ? ", device-local" : "");
    }
}

int cmd_devices(int argc, char **argv)
{
    bool is_json = false;
    gpu_config cfg = {0};
    for (int i = 1; i < argc; i++) {
        if (app_is_help(argv[i])) {
            devices_help(stdout);
            return APP_EXIT_OK;
        } else if (!strcmp(argv[i], "--json")) {
            is_json = true;
        } else if (!strcmp(argv[i], "--device")) {
            if (i + 1 >= argc) return app_usage_error("devices", "--device needs a name or index");
            cfg.device = argv[++i];
        } else {
            return app_usage_error("devices", "unknown argument '%s'", argv[i]);
        }
    }
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
        if (is_json) {
            printf("{\"chosen\": null, \"devices\": []");
            print_json_capture(cams, n_cams);
        } else {
            print_text_capture(cams, n_cams);
        }
        return app_fail("devices", bf_fail(s, "%s", why));
    }
    if (is_json) {
        print_json(devs, n, chosen);
        print_json_capture(cams, n_cams);
    } else {
        print_text(devs, n, chosen);
        print_text_capture(cams, n_cams);
    }
    if (chosen == UINT32_MAX) return app_fail("devices", bf_fail(BF_NO_DEVICE, "%s", why));
    return APP_EXIT_OK;
}
