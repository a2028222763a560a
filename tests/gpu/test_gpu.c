/* Tests of the gpu module on whatever device is there (lavapipe on a fresh
 * machine). Validation is on in every test and any message fails it, except
 * in validation_hook_counts_deliberate_error. Without any Vulkan device the
 * tests skip. */
#include "test.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ctype.h>

#include "bf_test_shaders_spv.h"
#include "gpu/gpu.h"
#include "shaders/gpu_test.glsl.h" /* tests/gpu/shaders */

/* ------------------------------------------------------------ helpers */

static gpu_config test_config(void)
{
    static char dir[512];
    snprintf(dir, sizeof dir, "%s/cache", bf_test_tmpdir());
    return (gpu_config){.validation = GPU_VALIDATION_ON, .cache_dir = dir};
}

/* Creates a context or skips the test when there is no device at all. */
#define OPEN_CTX(ctx, cfg)                                                 \
    do {                                                                   \
        bf_status _st = gpu_context_create((cfg), &(ctx));                 \
        if (_st == BF_NO_DEVICE) BF_SKIP(bf_last_error());                 \
        CHECK_STATUS(_st, BF_OK);                                          \
    } while (0)

/* Destroys the context and requires that validation said nothing since
 * v0 = gpu_validation_message_total(), destruction included. */
#define CLOSE_CTX_CLEAN(ctx, v0)                                           \
    do {                                                                   \
        CHECK_EQ_INT(gpu_validation_message_count(ctx), 0);                \
        gpu_context_destroy(ctx);                                          \
        CHECK_EQ_INT(gpu_validation_message_total(), (v0));                \
    } while (0)

#define SPV(name) bf_spv_##name, bf_spv_##name##_size

static gpu_pipeline_desc desc_of(const char *name, const uint32_t *spv, size_t size, uint32_t n_buffers,
                                 uint32_t push_bytes, uint32_t local_x)
{
    return (gpu_pipeline_desc){
        .name = name, .spirv = spv, .spirv_bytes = size, .n_buffers = n_buffers,
        .push_bytes = push_bytes, .local_size = {local_x, 1, 1}};
}

static uint32_t xorshift(uint32_t *s)
{
    uint32_t x = *s;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    return *s = x;
}

/* ------------------------------------------------------------ context */

BF_TEST(context_creates_and_reports_device)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    const gpu_device_info *info = gpu_device(ctx);
    CHECK(gpu_device_name(ctx)[0] != '\0');
    CHECK(!strcmp(gpu_device_name(ctx), info->name));
    CHECK(info->is_usable && info->has_buffer_address);
    CHECK(gpu_validation_enabled(ctx));
    CHECK(strcmp(gpu_device_type_name(info->type), "other") != 0);

    gpu_device_info list[GPU_MAX_DEVICES];
    uint32_t n = 0, chosen = 0;
    CHECK_OK(gpu_device_list(&cfg, list, &n, &chosen));
    CHECK(n >= 1 && chosen < n);
    CHECK(!strcmp(list[chosen].name, info->name));
    CHECK(!memcmp(list[chosen].device_uuid, info->device_uuid, VK_UUID_SIZE));
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(destroy_null_is_a_no_op)
{
    gpu_context_destroy(NULL);
    gpu_buffer_destroy(NULL);
    gpu_pipeline_destroy(NULL);
    gpu_bindings_destroy(NULL);
}

/* Reads "key = value" for the first occurrence of key in vulkaninfo's
 * output; false when vulkaninfo is absent or lists more than one device. */
static bool vulkaninfo_value(const char *key, unsigned long long *out)
{
    FILE *f = popen("vulkaninfo 2>/dev/null", "r");
    if (!f) return false;
    char line[1024];
    int n_devices = 0;
    bool found = false;
    while (fgets(line, sizeof line, f)) {
        char *p = line;
        while (*p == ' ' || *p == '\t') p++;
        if (!strncmp(p, "deviceName", 10) && strchr(p, '=')) n_devices++;
        size_t k = strlen(key);
        if (!found && !strncmp(p, key, k) && (p[k] == ' ' || p[k] == '=')) {
            char *eq = strchr(p, '=');
            if (eq) {
                *out = strtoull(eq + 1, NULL, 0);
                found = true;
            }
        }
    }
    pclose(f);
    /* vulkaninfo prints deviceName once in the summary per device and once in
     * the device's properties. */
    return found && n_devices <= 2;
}

BF_TEST(limits_are_sane_and_match_vulkaninfo)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    const gpu_limits *l = gpu_device_limits(ctx);
    /* Minimums required by the Vulkan 1.2 spec ("Required Limits"). */
    CHECK(l->max_storage_buffer_range >= (1ull << 27));
    CHECK(l->max_push_constants_size >= 128);
    CHECK(l->max_compute_workgroup_invocations >= 128);
    CHECK(l->max_compute_workgroup_size[0] >= 128 && l->max_compute_workgroup_size[2] >= 64);
    for (int i = 0; i < 3; i++) CHECK(l->max_compute_workgroup_count[i] >= 65535);
    CHECK(l->max_per_stage_storage_buffers >= 4);
    CHECK(l->subgroup_size >= 1 && (l->subgroup_size & (l->subgroup_size - 1)) == 0);
    CHECK(l->max_memory_allocation_size >= (1ull << 30));
    CHECK(l->n_heaps >= 1 && l->heaps[0].size_bytes > 0);
    if (l->has_timestamps) CHECK(l->timestamp_valid_bits >= 36 && l->timestamp_period_ns > 0);
    if (strstr(gpu_device_name(ctx), "llvmpipe")) { /* lavapipe, as the brief measured it */
        CHECK_EQ_INT(l->max_storage_buffer_range, 128u << 20);
        CHECK_EQ_INT(l->subgroup_size, 8);
    }
    unsigned long long v;
    if (vulkaninfo_value("maxStorageBufferRange", &v)) {
        CHECK_EQ_INT(l->max_storage_buffer_range, v);
        CHECK(vulkaninfo_value("maxPushConstantsSize", &v));
        CHECK_EQ_INT(l->max_push_constants_size, v);
        CHECK(vulkaninfo_value("maxComputeWorkGroupInvocations", &v));
        CHECK_EQ_INT(l->max_compute_workgroup_invocations, v);
        CHECK(vulkaninfo_value("subgroupSize", &v));
        CHECK_EQ_INT(l->subgroup_size, v);
        CHECK(vulkaninfo_value("minStorageBufferOffsetAlignment", &v));
        CHECK_EQ_INT(l->min_storage_buffer_offset_alignment, v);
    } else {
        fprintf(stderr, "  (vulkaninfo absent or several devices: not compared)\n");
    }
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(missing_device_or_loader_gives_no_device)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    gpu_device_info list[GPU_MAX_DEVICES];
    uint32_t n = 0, chosen = 0;
    bf_status s = gpu_device_list(&cfg, list, &n, &chosen);
    if (s == BF_NO_DEVICE) BF_SKIP(bf_last_error());
    CHECK_OK(s);

    setenv("BITFUSE_DEVICE", "no-such-gpu-9000", 1);
    s = gpu_context_create(&cfg, &ctx);
    unsetenv("BITFUSE_DEVICE");
    CHECK_STATUS(s, BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("no-such-gpu-9000");
    CHECK(ctx == NULL); /* untouched on failure */

    cfg.device = "99";
    CHECK_STATUS(gpu_context_create(&cfg, &ctx), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("no such index");
    /* A small number is an index only, never part of a name ("15" in "LLVM 15.0.6"). */
    char past[16];
    snprintf(past, sizeof past, "%u", n);
    cfg.device = past;
    CHECK_STATUS(gpu_context_create(&cfg, &ctx), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("no device");
    cfg.device = "0"; /* an index */
    OPEN_CTX(ctx, &cfg);
    CHECK(!strcmp(gpu_device_name(ctx), list[0].name));
    CHECK_EQ_INT(gpu_validation_message_count(ctx), 0);
    gpu_context_destroy(ctx);
    ctx = NULL;

    gpu_config no_loader = test_config();
    no_loader.loader = "libvulkan-that-is-not-there.so.1";
    CHECK_STATUS(gpu_context_create(&no_loader, &ctx), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("Vulkan loader");
    CHECK_STATUS(gpu_device_list(&no_loader, list, &n, &chosen), BF_NO_DEVICE);

    /* A name matches case-insensitively: the chosen device's name in upper case. */
    char upper[VK_MAX_PHYSICAL_DEVICE_NAME_SIZE];
    snprintf(upper, sizeof upper, "%s", list[chosen].name);
    for (char *p = upper; *p; p++) *p = (char)toupper((unsigned char)*p);
    cfg.device = upper;
    OPEN_CTX(ctx, &cfg);
    CHECK(!strcmp(gpu_device_name(ctx), list[chosen].name));
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* ------------------------------------------------------------ validation */

BF_TEST(validation_hook_counts_deliberate_error)
{
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    uint32_t total0 = gpu_validation_message_total();
    gpu_pipeline *count = NULL;
    gpu_buffer *args = NULL, *counter = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of("test.count", SPV(gpu_test_count), 2, 0, 1);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &count));
    /* The error: dispatch arguments in a buffer made without GPU_USAGE_INDIRECT
     * (VUID-vkCmdDispatchIndirect-buffer-02709). lavapipe ignores usage flags,
     * so the dispatch itself is harmless (vkcube's --force_errors idea). */
    gpu_buffer_desc ad = {.name = "test.args_without_indirect_usage", .size_bytes = 16,
                          .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
    CHECK_OK(gpu_buffer_create(ctx, &ad, &args));
    gpu_buffer_desc cd = {.name = "test.counter", .size_bytes = 64};
    CHECK_OK(gpu_buffer_create(ctx, &cd, &counter));
    CHECK_OK(gpu_buffer_zero(counter));
    const uint32_t groups[4] = {1, 1, 1, 0};
    CHECK_OK(gpu_buffer_upload(args, 0, groups, sizeof groups));
    CHECK_OK(gpu_bindings_create(ctx, 2, "test.count_bindings", &b));
    CHECK_OK(gpu_bindings_set(b, 0, counter, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_bindings_set(b, 1, counter, 0, GPU_WHOLE_SIZE));
    CHECK_EQ_INT(gpu_validation_message_count(ctx), 0);
    fprintf(stderr, "  (the validation error below is deliberate)\n");
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_dispatch_indirect(ctx, count, b, NULL, args, 0);
    CHECK_OK(gpu_submit_wait(ctx));
    CHECK(gpu_validation_message_count(ctx) >= 1);
    CHECK(gpu_validation_message_total() >= total0 + 1);
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(counter);
    gpu_buffer_destroy(args);
    gpu_pipeline_destroy(count);
    gpu_context_destroy(ctx);
}

BF_TEST(validation_without_layer_fails_clearly)
{
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    /* An empty explicit-layer path hides VK_LAYER_KHRONOS_validation. */
    char empty[512];
    snprintf(empty, sizeof empty, "%s/no-layers", bf_test_tmpdir());
    CHECK_OK(bf_mkdir_p(empty));
    char *old = getenv("VK_LAYER_PATH") ? strdup(getenv("VK_LAYER_PATH")) : NULL;
    setenv("VK_LAYER_PATH", empty, 1);
    bf_status s = gpu_context_create(&cfg, &ctx);
    if (old) setenv("VK_LAYER_PATH", old, 1);
    else unsetenv("VK_LAYER_PATH");
    free(old);
    if (s == BF_NO_DEVICE) BF_SKIP(bf_last_error());
    CHECK_STATUS(s, BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("VK_LAYER_KHRONOS_validation");
    CHECK(ctx == NULL);
}

/* ------------------------------------------------------------ buffers */

/* N words through a shader and back; large (above the 4 MiB from which a
 * CPU device's buffers are imported) or not. */
static void round_trip(bool force_staging, bool is_large, bool no_import)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    cfg.force_staging = force_staging;
    cfg.no_host_import = no_import;
    cfg.staging_bytes = 64u << 10; /* several staging chunks per transfer */
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    const uint32_t N = is_large ? 1500007 : 100003; /* not a multiple of the local size */
    uint32_t *host = malloc(N * sizeof *host), *back = malloc(N * sizeof *back);
    CHECK(host && back);
    uint32_t seed = 12345;
    for (uint32_t i = 0; i < N; i++) host[i] = xorshift(&seed);
    host[0] = UINT32_MAX; /* wraps to 0 */

    gpu_pipeline *add = NULL;
    gpu_buffer *data = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of("test.selftest", SPV(selftest), 1, sizeof(struct gpu_test_count), 64);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &add));
    gpu_buffer_desc bd = {.name = "test.data", .size_bytes = N * sizeof(uint32_t) + 64};
    CHECK_OK(gpu_buffer_create(ctx, &bd, &data));
    CHECK(force_staging ? gpu_buffer_map(data) == NULL : true);
    /* Lavapipe (both Mesa 22.3 and 25) offers VK_EXT_external_memory_host:
     * its large buffers are imported, from a mapping aligned to a huge page. */
    bool is_cpu = gpu_device_type(ctx) == VK_PHYSICAL_DEVICE_TYPE_CPU;
    if (strstr(gpu_device_name(ctx), "llvmpipe") || !is_cpu || no_import || force_staging)
        CHECK(gpu_imports_host_memory(ctx) == (is_cpu && !no_import && !force_staging));
    bool want_import = gpu_imports_host_memory(ctx) && is_large;
    CHECK(gpu_buffer_is_imported(data) == want_import);
    CHECK(gpu_buffer_created_zero(data) == want_import);
    if (want_import) { /* our own mapping: aligned to a huge page, zero until written */
        CHECK((uintptr_t)gpu_buffer_map(data) % (2u << 20) == 0);
        const uint32_t *w = gpu_buffer_map(data);
        for (uint32_t i = 0; i < N; i += 4099) CHECK_EQ_INT(w[i], 0);
    }
    CHECK_OK(gpu_buffer_fill(data, N * sizeof(uint32_t), 64, 0xabcdabcdu)); /* guard words */
    CHECK_OK(gpu_buffer_upload(data, 0, host, N * sizeof(uint32_t)));
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.data_bindings", &b));
    CHECK_OK(gpu_bindings_set(b, 0, data, 0, GPU_WHOLE_SIZE));

    struct gpu_test_count pc = {.n = N};
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_dispatch(ctx, add, b, &pc, gpu_groups(N, 64), 1, 1);
    CHECK_OK(gpu_submit_wait(ctx));
    CHECK_OK(gpu_buffer_download(data, 0, back, N * sizeof(uint32_t)));
    for (uint32_t i = 0; i < N; i++)
        if (back[i] != host[i] + 1u) CHECK_EQ_INT(back[i], host[i] + 1u);
    uint32_t guard[16];
    CHECK_OK(gpu_buffer_download(data, N * sizeof(uint32_t), guard, sizeof guard));
    for (int i = 0; i < 16; i++) CHECK_EQ_INT(guard[i], 0xabcdabcdu);
    CHECK_STATUS(gpu_buffer_download(data, 8, back, gpu_buffer_size(data)), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("test.data");

    gpu_bindings_destroy(b);
    gpu_buffer_destroy(data);
    gpu_pipeline_destroy(add);
    free(host);
    free(back);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(buffer_round_trip_shader_adds_one) { round_trip(false, false, false); }
BF_TEST(buffer_round_trip_through_staging_as_on_a_discrete_gpu) { round_trip(true, true, false); }
BF_TEST(large_buffer_round_trip_imported_host_memory) { round_trip(false, true, false); }
BF_TEST(large_buffer_round_trip_driver_memory) { round_trip(false, true, true); }

/* GPU_USAGE_ADDRESS: a device address for buffers in driver memory and in
 * imported host memory (the large one), none without the flag. The fusion
 * tests read through one (the window's depth ring) bit for bit. */
BF_TEST(device_addresses_for_address_buffers_only)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    gpu_buffer *small = NULL, *large = NULL, *plain = NULL;
    const uint32_t addr = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER | GPU_USAGE_ADDRESS;
    gpu_buffer_desc sd = {.name = "test.address_small", .size_bytes = 4096, .usage = addr};
    gpu_buffer_desc ld = {.name = "test.address_large", .size_bytes = 64u << 20, .usage = addr};
    gpu_buffer_desc pd = {.name = "test.plain", .size_bytes = 4096};
    CHECK_OK(gpu_buffer_create(ctx, &sd, &small));
    CHECK_OK(gpu_buffer_create(ctx, &ld, &large));
    CHECK_OK(gpu_buffer_create(ctx, &pd, &plain));
    CHECK(gpu_buffer_address(small) != 0 && gpu_buffer_address(small) % 4 == 0);
    CHECK(gpu_buffer_address(large) != 0 && gpu_buffer_address(large) % 4 == 0);
    CHECK(gpu_buffer_address(small) != gpu_buffer_address(large));
    CHECK(gpu_buffer_address(plain) == 0);
    /* A table of them holds each address as a 64-bit word; a buffer
     * without one is refused, naming it. */
    gpu_buffer *table = NULL, *both[2] = {large, small}, *with_plain[2] = {small, plain};
    CHECK_OK(gpu_address_table_create(ctx, "test.table", both, 2, &table));
    uint64_t words[2] = {0, 0};
    CHECK(table && gpu_buffer_size(table) == 16);
    if (table) CHECK_OK(gpu_buffer_download(table, 0, words, sizeof words));
    CHECK(words[0] == gpu_buffer_address(large) && words[1] == gpu_buffer_address(small));
    gpu_buffer *refused = NULL;
    CHECK_EQ_INT(gpu_address_table_create(ctx, "test.table2", with_plain, 2, &refused), BF_INVALID_ARG);
    CHECK(refused == NULL && strstr(bf_last_error(), "entry 1 (test.plain)") != NULL);
    gpu_buffer_destroy(table);
    gpu_buffer_destroy(plain);
    gpu_buffer_destroy(large);
    gpu_buffer_destroy(small);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(recorded_fill_and_copy)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    gpu_buffer *a = NULL, *up = NULL, *rb = NULL;
    gpu_buffer_desc ad = {.name = "test.a", .size_bytes = 4096};
    gpu_buffer_desc ud = {.name = "test.upload", .size_bytes = 4096, .memory = GPU_MEMORY_UPLOAD,
                          .usage = GPU_USAGE_TRANSFER};
    gpu_buffer_desc rd = {.name = "test.readback", .size_bytes = 4096, .memory = GPU_MEMORY_READBACK,
                          .usage = GPU_USAGE_TRANSFER};
    CHECK_OK(gpu_buffer_create(ctx, &ad, &a));
    CHECK_OK(gpu_buffer_create(ctx, &ud, &up));
    CHECK_OK(gpu_buffer_create(ctx, &rd, &rb));
    uint32_t *u = gpu_buffer_map(up), *r = gpu_buffer_map(rb);
    CHECK(u && r);
    for (uint32_t i = 0; i < 1024; i++) u[i] = i * 7u;
    CHECK_OK(gpu_buffer_flush(up));
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_fill(ctx, a, 0, GPU_WHOLE_SIZE, 0x11111111u);
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER); /* the fill's writes before the copy overwrites part */
    gpu_cmd_copy(ctx, up, 0, a, 1024, 2048);
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER); /* fill and copy into a, before reading a */
    gpu_cmd_copy(ctx, a, 0, rb, 0, 4096);
    CHECK_OK(gpu_submit_wait(ctx));
    for (uint32_t i = 0; i < 1024; i++) {
        uint32_t want = i >= 256 && i < 768 ? (i - 256) * 7u : 0x11111111u;
        if (r[i] != want) CHECK_EQ_INT(r[i], want);
    }
    gpu_buffer_destroy(rb);
    gpu_buffer_destroy(up);
    gpu_buffer_destroy(a);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(too_large_binding_is_refused_and_pools_split)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    const gpu_limits *l = gpu_device_limits(ctx);
    uint64_t range = l->max_storage_buffer_range;
    gpu_buffer *big = NULL;
    gpu_bindings *b = NULL;
    gpu_buffer_desc bd = {.name = "test.big_pool", .size_bytes = range + 4096};
    CHECK_OK(gpu_buffer_create(ctx, &bd, &big));
    CHECK_OK(gpu_bindings_create(ctx, 2, "test.big_bindings", &b));
    CHECK_STATUS(gpu_bindings_set(b, 0, big, 0, GPU_WHOLE_SIZE), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("maxStorageBufferRange");
    CHECK_ERROR_MENTIONS("test.big_pool");
    CHECK_OK(gpu_bindings_set(b, 0, big, 0, range));
    CHECK_OK(gpu_bindings_set(b, 1, big, range, GPU_WHOLE_SIZE));
    CHECK_STATUS(gpu_bindings_set(b, 1, big, range + 1, 16), l->min_storage_buffer_offset_alignment > 1
                                                                 ? BF_INVALID_ARG : BF_OK);

    /* Splitting: whole elements per binding, aligned next offset, enough bindings. */
    const uint32_t elems[] = {4, 12, 64, 1000};
    for (int k = 0; k < 4; k++) {
        uint64_t per = gpu_binding_max_bytes(ctx, elems[k]);
        CHECK(per > 0 && per <= range);
        CHECK_EQ_INT(per % elems[k], 0);
        CHECK_EQ_INT(per % l->min_storage_buffer_offset_alignment, 0);
        CHECK(range - per < (uint64_t)elems[k] * l->min_storage_buffer_offset_alignment);
        uint64_t pool = 3ull << 30;
        uint32_t n = gpu_bindings_needed(ctx, pool, elems[k]);
        CHECK(n * per >= pool && (n - 1) * per < pool);
    }
    if (range == (128u << 20)) CHECK_EQ_INT(gpu_bindings_needed(ctx, 1ull << 30, 64), 8);

    /* A buffer past maxMemoryAllocationSize is refused before allocating. */
    gpu_buffer *huge = NULL;
    gpu_buffer_desc hd = {.name = "test.huge", .size_bytes = l->max_memory_allocation_size + 1};
    CHECK_STATUS(gpu_buffer_create(ctx, &hd, &huge), BF_NO_MEMORY);
    CHECK_ERROR_MENTIONS("test.huge");
    CHECK(huge == NULL);

    gpu_bindings_destroy(b);
    gpu_buffer_destroy(big);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(bad_descriptions_and_full_pools_are_statuses)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    cfg.bindings_cap = 2;
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    const gpu_limits *l = gpu_device_limits(ctx);
    gpu_pipeline *p = NULL;
    gpu_pipeline_desc d = desc_of("test.too_wide", SPV(selftest), 1, 8, l->max_compute_workgroup_invocations + 1);
    CHECK_STATUS(gpu_pipeline_create(ctx, &d, &p), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("maxComputeWorkGroup");
    d = desc_of("test.big_push", SPV(selftest), 1, l->max_push_constants_size + 4, 64);
    CHECK_STATUS(gpu_pipeline_create(ctx, &d, &p), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("maxPushConstantsSize");
    CHECK(p == NULL);

    gpu_bindings *b[3] = {0};
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.b0", &b[0]));
    CHECK_OK(gpu_bindings_create(ctx, 3, "test.b1", &b[1]));
    CHECK_STATUS(gpu_bindings_create(ctx, 1, "test.b2", &b[2]), BF_POOL_FULL);
    gpu_bindings_destroy(b[0]);
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.b2", &b[2])); /* a freed set is reusable */
    gpu_bindings_destroy(b[2]);
    gpu_bindings_destroy(b[1]);

    gpu_buffer *zero = NULL;
    gpu_buffer_desc zd = {.name = "test.empty", .size_bytes = 0};
    CHECK_STATUS(gpu_buffer_create(ctx, &zd, &zero), BF_INVALID_ARG);
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* ------------------------------------------------------------ dispatch */

BF_TEST(indirect_dispatch_runs_shader_written_group_count)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    gpu_pipeline *writer = NULL, *count = NULL;
    gpu_buffer *args = NULL, *counter = NULL, *marks = NULL;
    gpu_bindings *bw = NULL, *bc = NULL;
    gpu_pipeline_desc dw = desc_of("test.indirect_writer", SPV(gpu_test_indirect), 1, sizeof(struct gpu_test_count), 1);
    gpu_pipeline_desc dc = desc_of("test.count", SPV(gpu_test_count), 2, 0, 32);
    CHECK_OK(gpu_pipeline_create(ctx, &dw, &writer));
    CHECK_OK(gpu_pipeline_create(ctx, &dc, &count));
    gpu_buffer_desc ad = {.name = "test.args", .size_bytes = 16,
                          .usage = GPU_USAGE_STORAGE | GPU_USAGE_INDIRECT | GPU_USAGE_TRANSFER};
    gpu_buffer_desc cd = {.name = "test.counter", .size_bytes = 16};
    gpu_buffer_desc md = {.name = "test.marks", .size_bytes = 256 * 4};
    CHECK_OK(gpu_buffer_create(ctx, &ad, &args));
    CHECK_OK(gpu_buffer_create(ctx, &cd, &counter));
    CHECK_OK(gpu_buffer_create(ctx, &md, &marks));
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.writer_bindings", &bw));
    CHECK_OK(gpu_bindings_set(bw, 0, args, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_bindings_create(ctx, 2, "test.count_bindings", &bc));
    CHECK_OK(gpu_bindings_set(bc, 0, counter, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_bindings_set(bc, 1, marks, 0, GPU_WHOLE_SIZE));

    const uint32_t n_groups = 37;
    struct gpu_test_count pc = {.n = n_groups};
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_label_begin(ctx, "test.indirect");
    gpu_cmd_fill(ctx, counter, 0, GPU_WHOLE_SIZE, 0);
    gpu_cmd_fill(ctx, marks, 0, GPU_WHOLE_SIZE, 0);
    /* The zero fills of counter and marks, before count's atomics and stores. */
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    gpu_cmd_dispatch(ctx, writer, bw, &pc, 1, 1, 1);
    /* The writer's group counts in args, before the indirect read of args. */
    gpu_cmd_barrier(ctx, GPU_BARRIER_INDIRECT);
    gpu_cmd_dispatch_indirect(ctx, count, bc, NULL, args, 0);
    gpu_cmd_label_end(ctx);
    CHECK_OK(gpu_submit_wait(ctx));

    uint32_t got[3], c, m[256];
    CHECK_OK(gpu_buffer_download(args, 0, got, sizeof got));
    CHECK_EQ_INT(got[0], n_groups);
    CHECK_EQ_INT(got[1], 1);
    CHECK_EQ_INT(got[2], 1);
    CHECK_OK(gpu_buffer_download(counter, 0, &c, sizeof c));
    CHECK_EQ_INT(c, n_groups);
    CHECK_OK(gpu_buffer_download(marks, 0, m, sizeof m));
    for (uint32_t i = 0; i < 256; i++) CHECK_EQ_INT(m[i], i < n_groups ? i + 1 : 0);

    gpu_bindings_destroy(bc);
    gpu_bindings_destroy(bw);
    gpu_buffer_destroy(marks);
    gpu_buffer_destroy(counter);
    gpu_buffer_destroy(args);
    gpu_pipeline_destroy(count);
    gpu_pipeline_destroy(writer);
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* More groups than the device allows along x (lavapipe: 65535) go out as
 * rows of x and y, and every place is run once (the fusion passes sized by
 * the pools use it: an AMD or Intel GPU's default pools need it). */
BF_TEST(linear_dispatch_beyond_the_x_limit_runs_every_place_once)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    uint32_t max_x = gpu_device_limits(ctx)->max_compute_workgroup_count[0];
    if (max_x > (1u << 20)) printf("  this device takes 2^20+ groups along x: one row only\n");
    const uint32_t local = 4, n_groups = (max_x > (1u << 20) ? 1000 : max_x + 3);
    const uint32_t n = n_groups * local - 2; /* the last group's last places are out of range */
    gpu_pipeline *p = NULL;
    gpu_buffer *marks = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of("test.linear", SPV(gpu_test_linear), 1, sizeof(struct gpu_test_count), local);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &p));
    gpu_buffer_desc md = {.name = "test.marks", .size_bytes = (uint64_t)(n + 8) * 4};
    CHECK_OK(gpu_buffer_create(ctx, &md, &marks));
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.linear_bindings", &b));
    CHECK_OK(gpu_bindings_set(b, 0, marks, 0, GPU_WHOLE_SIZE));
    struct gpu_test_count pc = {.n = n};
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_fill(ctx, marks, 0, GPU_WHOLE_SIZE, 0);
    /* The zero fill -> the marks' stores. */
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    gpu_cmd_dispatch_linear(ctx, p, b, &pc, n_groups);
    CHECK_OK(gpu_submit_wait(ctx));
    uint32_t *m = malloc((size_t)(n + 8) * 4);
    CHECK(m != NULL);
    if (m) {
        CHECK_OK(gpu_buffer_download(marks, 0, m, (uint64_t)(n + 8) * 4));
        uint32_t wrong = 0;
        for (uint32_t i = 0; i < n + 8; i++) wrong += m[i] != (i < n ? i + 1 : 0);
        CHECK_EQ_INT(wrong, 0);
        free(m);
    }
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(marks);
    gpu_pipeline_destroy(p);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(timestamps_are_monotonic_and_nonzero)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    cfg.stage_cap = 3;
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    if (!gpu_device_limits(ctx)->has_timestamps) {
        gpu_context_destroy(ctx);
        BF_SKIP("the device has no timestamps on its compute queue");
    }
    enum { N = 4096 };
    gpu_pipeline *busy = NULL;
    gpu_buffer *data = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of("test.busy", SPV(gpu_test_busy), 1, sizeof(struct gpu_test_count), 64);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &busy));
    gpu_buffer_desc bd = {.name = "test.busy_data", .size_bytes = N * 4};
    CHECK_OK(gpu_buffer_create(ctx, &bd, &data));
    CHECK_OK(gpu_buffer_zero(data));
    CHECK_OK(gpu_bindings_create(ctx, 1, "test.busy_bindings", &b));
    CHECK_OK(gpu_bindings_set(b, 0, data, 0, GPU_WHOLE_SIZE));

    const char *names[] = {"stage.a", "stage.b", "stage.c"};
    struct gpu_test_count pc = {.n = N, .iters = 200};
    CHECK_OK(gpu_begin(ctx));
    for (int s = 0; s < 3; s++) {
        CHECK_OK(gpu_cmd_stage_begin(ctx, names[s]));
        gpu_cmd_dispatch(ctx, busy, b, &pc, gpu_groups(N, 64), 1, 1);
        /* This stage's writes to data, before the next stage reads them. */
        gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_stage_end(ctx);
    }
    CHECK_STATUS(gpu_cmd_stage_begin(ctx, "stage.over_cap"), BF_POOL_FULL);
    gpu_cmd_stage_end(ctx);
    CHECK_OK(gpu_submit_wait(ctx));

    const gpu_stage_time *t = NULL;
    CHECK_EQ_INT(gpu_stage_times(ctx, &t), 3);
    for (int s = 0; s < 3; s++) {
        CHECK(!strcmp(t[s].name, names[s]));
        CHECK(t[s].begin_ticks > 0);
        CHECK(t[s].end_ticks > t[s].begin_ticks);
        CHECK(t[s].ms > 0.0);
        if (s > 0) CHECK(t[s].begin_ticks >= t[s - 1].end_ticks);
        fprintf(stderr, "  %s: %.3f ms\n", t[s].name, t[s].ms);
    }
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(data);
    gpu_pipeline_destroy(busy);
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* ------------------------------------------------------------ shared definitions */

/* Runs a test kernel of two bindings (input words, output words) whose push
 * constants are gpu_test_count {n}, over n_invocations invocations in groups
 * of 64, and reads its output back. */
static void run_in_out(gpu_context *ctx, const char *name, const uint32_t *spv, size_t spv_bytes, const void *in_data,
                       size_t in_bytes, void *out_data, size_t out_bytes, uint32_t n, uint32_t n_invocations)
{
    gpu_pipeline *p = NULL;
    gpu_buffer *in = NULL, *res = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of(name, spv, spv_bytes, 2, sizeof(struct gpu_test_count), 64);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &p));
    gpu_buffer_desc id = {.name = "test.in", .size_bytes = in_bytes};
    gpu_buffer_desc od = {.name = "test.out", .size_bytes = out_bytes};
    CHECK_OK(gpu_buffer_create(ctx, &id, &in));
    CHECK_OK(gpu_buffer_create(ctx, &od, &res));
    CHECK_OK(gpu_buffer_upload(in, 0, in_data, in_bytes));
    CHECK_OK(gpu_bindings_create(ctx, 2, name, &b));
    CHECK_OK(gpu_bindings_set(b, 0, in, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_bindings_set(b, 1, res, 0, GPU_WHOLE_SIZE));
    struct gpu_test_count pc = {.n = n};
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_dispatch(ctx, p, b, &pc, gpu_groups(n_invocations, 64), 1, 1);
    CHECK_OK(gpu_submit_wait(ctx));
    CHECK_OK(gpu_buffer_download(res, 0, out_data, out_bytes));
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(res);
    gpu_buffer_destroy(in);
    gpu_pipeline_destroy(p);
}

BF_TEST(brick_helpers_gpu_equal_cpu)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    enum { N_WORDS = 256, N_OUT = BRICK_VOXELS + 32 * N_WORDS };
    uint32_t words[N_WORDS], out[N_OUT];
    uint32_t seed = 0x9e3779b9u;
    for (int i = 0; i < N_WORDS; i++) words[i] = xorshift(&seed);
    words[0] = 0;
    words[1] = UINT32_MAX;
    words[2] = 0x80000000u;
    words[3] = 1;

    run_in_out(ctx, "test.bits", SPV(gpu_test_bits), words, sizeof words, out, sizeof out, N_WORDS, 32 * N_WORDS);

    /* Every voxel lands on a distinct (word, bit): the mapping is a bijection. */
    uint32_t seen[BRICK_WORDS] = {0};
    for (uint32_t v = 0; v < BRICK_VOXELS; v++) {
        uint32_t x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
        uint32_t want = brick_word(x, y, z) << 8 | brick_bit(x, y, z);
        if (out[v] != want) CHECK_EQ_INT(out[v], want);
        CHECK(brick_word(x, y, z) < BRICK_WORDS && brick_bit(x, y, z) < 32);
        CHECK(!(seen[brick_word(x, y, z)] & (1u << brick_bit(x, y, z))));
        seen[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
    }
    for (uint32_t w = 0; w < BRICK_WORDS; w++) CHECK_EQ_INT(seen[w], UINT32_MAX);
    for (uint32_t k = 0; k < N_WORDS; k++)
        for (uint32_t i = 0; i < 32; i++) {
            uint32_t got = out[BRICK_VOXELS + 32 * k + i], want = brick_rank(words[k], i);
            if (got != want) CHECK_EQ_INT(got, want);
        }
    CHECK_EQ_INT(brick_rank(UINT32_MAX, 31), 31);
    CHECK_EQ_INT(brick_rank(0x80000000u, 31), 0);

    CLOSE_CTX_CLEAN(ctx, v0);
}

static struct gpu_test_params changed(struct gpu_test_params q)
{
    q.n += 1u;
    q.offset -= 1;
    q.scale *= 2.0f;
    q.seed ^= 0xffffffffu;
    for (uint32_t k = 0; k < 4; k++) q.words[k] += k;
    return q;
}

/* The float-to-integer helpers that stand in for int()/uint() in the
 * shaders (lavapipe runs those lane by lane): the integer C's cast gives for
 * every |x| < 2^22, the range clamped beyond. */
BF_TEST(trunc_helpers_gpu_equal_the_c_cast)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    enum { N_EDGE = 24, N = 4096 };
    static const float edge[N_EDGE] = {0.0f, -0.0f, 0.5f, -0.5f, 0.99999994f, -0.99999994f, 1.0f, -1.0f,
                                       1.5f, -1.5f, 2.5f, -2.5f, 639.99994f, 640.0f, 4194303.0f, 4194303.5f,
                                       -4194304.0f, -4194303.5f, 4194304.0f, -4194305.0f, 8388607.0f, 1e9f,
                                       -1e9f, 33000.4f};
    float x[N];
    uint32_t bits[N], out[2 * N];
    uint32_t seed = 0x2545f491u;
    for (int i = 0; i < N; i++) {
        if (i < N_EDGE) {
            x[i] = edge[i];
        } else { /* spread over the range: 2^(0..22) times [-1, 1) */
            float m = (float)(int32_t)xorshift(&seed) / 2147483648.0f;
            x[i] = ldexpf(m, (int)(xorshift(&seed) % 23u));
        }
        memcpy(&bits[i], &x[i], 4);
    }
    run_in_out(ctx, "test.trunc", SPV(gpu_test_trunc), bits, sizeof bits, out, sizeof out, N, N);
    for (int i = 0; i < N; i++) {
        int32_t got_i = (int32_t)out[2 * i];
        uint32_t got_u = out[2 * i + 1];
        if (fabsf(x[i]) < 4194304.0f) {
            int32_t want = BF_TRUNC_I32(x[i]); /* C: the plain cast */
            if (got_i != want) CHECK_EQ_INT(got_i, want);
            if (x[i] >= 0.0f && got_u != BF_TRUNC_U32(x[i])) CHECK_EQ_INT(got_u, BF_TRUNC_U32(x[i]));
        } else { /* beyond: clamped to the range */
            int32_t want = x[i] > 0.0f ? 4194303 : -4194304;
            if (got_i != want) CHECK_EQ_INT(got_i, want);
        }
    }
    CHECK_EQ_INT((int32_t)out[2 * 3], 0);   /* -0.5 truncates to 0, as int() */
    CHECK_EQ_INT((int32_t)out[2 * 9], -1);  /* -1.5 to -1 */
    CHECK_EQ_INT((int32_t)out[2 * 15], 4194303);
    CLOSE_CTX_CLEAN(ctx, v0);
}

BF_TEST(shared_struct_layout_round_trip)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    enum { N = 3 };
    struct gpu_test_params pc = {.n = N, .offset = -7, .scale = 1.5f, .seed = 0xdeadbeefu,
                                 .words = {1, 2, 3, 0xffffffffu}};
    struct gpu_test_params in[N];
    for (int i = 0; i < N; i++)
        in[i] = (struct gpu_test_params){.n = 100u + i, .offset = -1000 * i, .scale = 0.25f * i - 3.0f,
                                         .seed = 0x01020304u << i, .words = {10u * i, 11, 12, 13}};
    uint32_t out[GPU_TEST_PARAMS_WORDS * (N + 1)];
    gpu_pipeline *p = NULL;
    gpu_buffer *src = NULL, *res = NULL;
    gpu_bindings *b = NULL;
    gpu_pipeline_desc d = desc_of("test.layout", SPV(gpu_test_layout), 2, sizeof pc, 8);
    CHECK_OK(gpu_pipeline_create(ctx, &d, &p));
    gpu_buffer_desc sd = {.name = "test.params_in", .size_bytes = sizeof in};
    gpu_buffer_desc od = {.name = "test.params_out", .size_bytes = sizeof out};
    CHECK_OK(gpu_buffer_create(ctx, &sd, &src));
    CHECK_OK(gpu_buffer_create(ctx, &od, &res));
    CHECK_OK(gpu_buffer_upload(src, 0, in, sizeof in));
    CHECK_OK(gpu_buffer_zero(res));
    CHECK_OK(gpu_bindings_create(ctx, 2, "test.layout_bindings", &b));
    CHECK_OK(gpu_bindings_set(b, 0, src, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_bindings_set(b, 1, res, 0, GPU_WHOLE_SIZE));
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_dispatch(ctx, p, b, &pc, 1, 1, 1);
    CHECK_OK(gpu_submit_wait(ctx));
    CHECK_OK(gpu_buffer_download(res, 0, out, sizeof out));

    uint32_t want[GPU_TEST_PARAMS_WORDS];
    memcpy(want, &pc, sizeof want);
    for (uint32_t k = 0; k < GPU_TEST_PARAMS_WORDS; k++) CHECK_EQ_INT(out[k], want[k]);
    for (int i = 0; i < N; i++) {
        struct gpu_test_params q = changed(in[i]);
        memcpy(want, &q, sizeof want);
        for (uint32_t k = 0; k < GPU_TEST_PARAMS_WORDS; k++)
            CHECK_EQ_INT(out[GPU_TEST_PARAMS_WORDS * (i + 1) + k], want[k]);
    }
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(res);
    gpu_buffer_destroy(src);
    gpu_pipeline_destroy(p);
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* ------------------------------------------------------------ pipelines */

static bf_status make_selftest(gpu_context *ctx, gpu_pipeline **out)
{
    gpu_pipeline_desc d = desc_of("test.selftest", SPV(selftest), 1, sizeof(struct gpu_test_count), 64);
    return gpu_pipeline_create(ctx, &d, out);
}

BF_TEST(pipeline_cache_is_written_reloaded_and_survives_corruption)
{
    uint32_t v0 = gpu_validation_message_total();
    char dir[512];
    snprintf(dir, sizeof dir, "%s/cache-test", bf_test_tmpdir());
    gpu_config cfg = test_config();
    cfg.cache_dir = dir;
    gpu_context *ctx = NULL;
    gpu_pipeline *p = NULL;

    OPEN_CTX(ctx, &cfg);
    char path[4096];
    snprintf(path, sizeof path, "%s", gpu_pipeline_cache_path(ctx));
    CHECK(strstr(path, dir) == path);
    CHECK(strstr(path, "pipeline-cache-") != NULL);
    CHECK_EQ_INT(gpu_pipeline_cache_loaded_bytes(ctx), 0); /* fresh directory */
    CHECK_OK(make_selftest(ctx, &p));
    gpu_pipeline_destroy(p);
    uint8_t uuid[VK_UUID_SIZE];
    memcpy(uuid, gpu_device(ctx)->pipeline_cache_uuid, VK_UUID_SIZE);
    CLOSE_CTX_CLEAN(ctx, v0);

    /* Written at destroy, with a header naming this device. */
    char *data = NULL;
    size_t size = 0;
    CHECK_OK(bf_read_file(path, &data, &size));
    CHECK(size >= sizeof(VkPipelineCacheHeaderVersionOne));
    VkPipelineCacheHeaderVersionOne h;
    memcpy(&h, data, sizeof h);
    free(data);
    CHECK_EQ_INT(h.headerVersion, VK_PIPELINE_CACHE_HEADER_VERSION_ONE);
    CHECK(!memcmp(h.pipelineCacheUUID, uuid, VK_UUID_SIZE));

    /* Reloaded by the next context. */
    OPEN_CTX(ctx, &cfg);
    CHECK_EQ_INT(gpu_pipeline_cache_loaded_bytes(ctx), size);
    CHECK_OK(make_selftest(ctx, &p));
    gpu_pipeline_destroy(p);
    CLOSE_CTX_CLEAN(ctx, v0);

    /* Garbage, and a header from another driver, are ignored with a warning. */
    const char garbage[] = "this is not a pipeline cache, but it is long enough to have a header";
    CHECK_OK(bf_write_file_atomic(path, garbage, sizeof garbage));
    OPEN_CTX(ctx, &cfg);
    CHECK_EQ_INT(gpu_pipeline_cache_loaded_bytes(ctx), 0);
    CHECK_OK(make_selftest(ctx, &p));
    gpu_pipeline_destroy(p);
    CLOSE_CTX_CLEAN(ctx, v0);
    h.pipelineCacheUUID[0] ^= 0xff;
    CHECK_OK(bf_write_file_atomic(path, &h, sizeof h));
    OPEN_CTX(ctx, &cfg);
    CHECK_EQ_INT(gpu_pipeline_cache_loaded_bytes(ctx), 0);
    CLOSE_CTX_CLEAN(ctx, v0);

    /* ... and replaced by a good file at destroy. */
    CHECK_OK(bf_read_file(path, &data, &size));
    memcpy(&h, data, sizeof h);
    free(data);
    CHECK(!memcmp(h.pipelineCacheUUID, uuid, VK_UUID_SIZE));
}

BF_TEST(warm_up_runs_every_pipeline)
{
    uint32_t v0 = gpu_validation_message_total();
    gpu_config cfg = test_config();
    gpu_context *ctx = NULL;
    OPEN_CTX(ctx, &cfg);
    gpu_pipeline_desc d[] = {
        desc_of("test.selftest", SPV(selftest), 1, sizeof(struct gpu_test_count), 64),
        desc_of("test.bits", SPV(gpu_test_bits), 2, sizeof(struct gpu_test_count), 64),
        desc_of("test.layout", SPV(gpu_test_layout), 2, sizeof(struct gpu_test_params), 8),
        desc_of("test.indirect_writer", SPV(gpu_test_indirect), 1, sizeof(struct gpu_test_count), 1),
        desc_of("test.count", SPV(gpu_test_count), 2, 0, 32),
        desc_of("test.busy", SPV(gpu_test_busy), 1, sizeof(struct gpu_test_count), 64),
    };
    enum { N = sizeof d / sizeof d[0] };
    gpu_pipeline *p[N] = {0};
    for (int i = 0; i < N; i++) CHECK_OK(gpu_pipeline_create(ctx, &d[i], &p[i]));
    CHECK_OK(gpu_pipeline_warm_up(ctx, p, N));
    uint32_t ls[3];
    gpu_pipeline_local_size(p[0], ls);
    CHECK(ls[0] == 64 && ls[1] == 1 && ls[2] == 1);
    CHECK(!strcmp(gpu_pipeline_name(p[2]), "test.layout"));
    for (int i = N - 1; i >= 0; i--) gpu_pipeline_destroy(p[i]);
    CLOSE_CTX_CLEAN(ctx, v0);
}

/* ------------------------------------------------------------ failure paths */

/* The life of a small GPU stage: context, pipeline, warm-up, buffer, upload,
 * bindings, a timed dispatch, download, teardown. Returns the first failure,
 * having released everything it made. */
static bf_status small_stage(const gpu_config *cfg)
{
    enum { N = 256 };
    uint32_t data[N], back[N];
    for (uint32_t i = 0; i < N; i++) data[i] = i;
    gpu_context *ctx = NULL;
    gpu_pipeline *p = NULL;
    gpu_buffer *buf = NULL;
    gpu_bindings *b = NULL;
    bf_status s = gpu_context_create(cfg, &ctx);
    if (s) goto done;
    gpu_pipeline_desc d = desc_of("fault.selftest", SPV(selftest), 1, sizeof(struct gpu_test_count), 64);
    if ((s = gpu_pipeline_create(ctx, &d, &p))) goto done;
    if ((s = gpu_pipeline_warm_up(ctx, &p, 1))) goto done;
    gpu_buffer_desc bd = {.name = "fault.data", .size_bytes = sizeof data};
    if ((s = gpu_buffer_create(ctx, &bd, &buf))) goto done;
    if ((s = gpu_buffer_upload(buf, 0, data, sizeof data))) goto done;
    if ((s = gpu_bindings_create(ctx, 1, "fault.bindings", &b))) goto done;
    if ((s = gpu_bindings_set(b, 0, buf, 0, GPU_WHOLE_SIZE))) goto done;
    if ((s = gpu_begin(ctx))) goto done;
    gpu_cmd_stage_begin(ctx, "fault.stage");
    struct gpu_test_count pc = {.n = N};
    gpu_cmd_dispatch(ctx, p, b, &pc, gpu_groups(N, 64), 1, 1);
    gpu_cmd_stage_end(ctx);
    if ((s = gpu_submit_wait(ctx))) goto done;
    if ((s = gpu_buffer_download(buf, 0, back, sizeof back))) goto done;
    for (uint32_t i = 0; i < N; i++)
        if (back[i] != i + 1) {
            s = bf_fail(BF_NUMERIC, "fault.data[%u] = %u, want %u", i, back[i], i + 1);
            goto done;
        }
done:
    gpu_bindings_destroy(b);
    gpu_buffer_destroy(buf);
    gpu_pipeline_destroy(p);
    gpu_context_destroy(ctx);
    return s;
}

/* Fails each checked Vulkan call in turn (SQLite's tempfault walk): every
 * failure must come back as BF_NO_MEMORY naming the call, with nothing left
 * behind (validation reports leaked objects at vkDestroyDevice and
 * vkDestroyInstance; LeakSanitizer the host side). */
BF_TEST(every_vulkan_failure_is_a_clean_status)
{
    for (int staged = 0; staged < 2; staged++) {
        gpu_config cfg = test_config();
        cfg.force_staging = staged;
        uint32_t v0 = gpu_validation_message_total();
        bf_status s = small_stage(&cfg);
        if (s == BF_NO_DEVICE) BF_SKIP(bf_last_error());
        CHECK_OK(s);
        uint32_t k = 1;
        for (; k < 1000; k++) {
            bf_fault_arm(k);
            bf_clear_error();
            s = small_stage(&cfg);
            bool is_unfired = bf_fault_arm(0) != 0;
            CHECK_EQ_INT(gpu_validation_message_total(), v0);
            if (is_unfired) break; /* k is past the last call: every point walked */
            if (s == BF_OK) continue; /* recovered (a rejected cache, a cache not saved) */
            if (s != BF_NO_MEMORY) fprintf(stderr, "  call %u: %s\n", k, bf_last_error());
            CHECK_STATUS(s, BF_NO_MEMORY);
            CHECK_ERROR_MENTIONS("VK_ERROR_OUT_OF_DEVICE_MEMORY");
            CHECK(strstr(bf_last_error(), "vk") != NULL); /* names the failed call */
        }
        CHECK_OK(s);
        CHECK(k > 20 && k < 1000);
        fprintf(stderr, "  %s: %u failure points, each clean\n", staged ? "staged" : "mapped", k - 1);
    }
}
