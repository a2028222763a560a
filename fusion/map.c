/* The map's buffers: creation, destruction, host copies (snapshot) and the
 * integrity check. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fusion_int.h"

fusion_config fusion_config_default(void)
{
    fusion_config c = {
        .chunk_m = 2.0f,
        .max_level = 8,
        .voxel_ratio = 1.0f,
        .window = 40,
        .subcache = 10,
        .brick_cap = 1u << 20,
        .node_cap = 0,
        .hash_buckets = 4096,
        .hash_overflow = 4096,
        .sensor = bf_sensor_kinect1(),
        .conf_weight = 4.0f,
        .band_sigmas = 3.0f,
        .keep_colour = true,
        .colour_frames = 4,
        .colour_reach = 1,
    };
    return c;
}

static bf_status config_check(const fusion_config *c, const bf_intrinsics *K)
{
    if (!(c->chunk_m > 0.01f && c->chunk_m <= 64.0f))
        return bf_fail(BF_INVALID_ARG, "fusion: chunk_m %g outside (0.01, 64] m", c->chunk_m);
    if (c->max_level > FUSION_MAX_LEVEL)
        return bf_fail(BF_INVALID_ARG, "fusion: max_level %u above %u", c->max_level, FUSION_MAX_LEVEL);
    if (!(c->voxel_ratio > 0.05f && c->voxel_ratio <= 64.0f))
        return bf_fail(BF_INVALID_ARG, "fusion: voxel_ratio %g outside (0.05, 64]", c->voxel_ratio);
    if (!(c->voxel_sigmas >= 0.0f && c->voxel_sigmas <= 64.0f))
        return bf_fail(BF_INVALID_ARG, "fusion: voxel_sigmas %g outside [0, 64]", c->voxel_sigmas);
    if (c->window < 2 || c->window % 2 || c->window > 256)
        return bf_fail(BF_INVALID_ARG, "fusion: window %u must be even, 2..256", c->window);
    if (c->subcache < 1 || c->subcache > c->window)
        return bf_fail(BF_INVALID_ARG, "fusion: subcache %u must be 1..window", c->subcache);
    if (c->brick_cap < 1 || c->node_cap < 9 || c->hash_buckets < 1)
        return bf_fail(BF_INVALID_ARG, "fusion: brick_cap, node_cap and hash_buckets must be positive");
    if (!(c->conf_weight > 0) || !(c->band_sigmas > 0) || !(c->sensor.max_depth_m > 0) || !(c->sensor.sigma_a > 0) ||
        !(c->sensor.sigma_b >= 0))
        return bf_fail(BF_INVALID_ARG, "fusion: weights, band, depth range and sigma must be positive");
    if (c->integrate_vpt > 64 || (c->integrate_vpt & (c->integrate_vpt - 1)))
        return bf_fail(BF_INVALID_ARG, "fusion: integrate_vpt %u (0, or a power of two up to 64)", c->integrate_vpt);
    if (c->integrate_bpg > 1024)
        return bf_fail(BF_INVALID_ARG, "fusion: integrate_bpg %u (0, or 1..1024)", c->integrate_bpg);
    if (c->keep_colour && (c->colour_frames < 1 || c->colour_frames > FUSION_COLOUR_MAX_FRAMES))
        return bf_fail(BF_INVALID_ARG, "fusion: colour_frames %u outside 1..%u", c->colour_frames,
                       FUSION_COLOUR_MAX_FRAMES);
    if (c->colour_reach > 2) return bf_fail(BF_INVALID_ARG, "fusion: colour_reach %u outside 0..2", c->colour_reach);
    if (K->width < 2 || K->height < 2 || K->width > 8192 || K->height > 8192 || !(K->depth_scale > 0) ||
        !isfinite(K->fx_px) || !isfinite(K->fy_px) || K->fx_px == 0 || K->fy_px == 0)
        return bf_fail(BF_INVALID_ARG, "fusion: bad intrinsics (%ux%u, fx %g, fy %g, depth scale %g)", K->width,
                       K->height, K->fx_px, K->fy_px, K->depth_scale);
    return BF_OK;
}

typedef struct buf_plan {
    gpu_buffer **dst;
    const char *name;
    uint64_t bytes;
    gpu_memory memory;
    uint32_t usage;
} buf_plan;

static bf_status create_buffers(fusion_map *m)
{
    const fusion_config *c = &m->cfg;
    /* A map made for loaded bricks takes no frame (fusion_add_frame refuses
     * one): its per-pixel buffers hold one pixel, so a large view's camera
     * does not size them past a binding. */
    uint64_t pixels = c->load_only ? 1 : (uint64_t)m->K.width * m->K.height;
    uint64_t depth_words = (pixels + 1) / 2;
    uint32_t st = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER;
    buf_plan plan[] = {
        /* The ray-cast reads these four through their addresses (FUSION_ADDR_*). */
        {&m->hash, "fusion.hash", (uint64_t)m->n_entries * FUSION_ENTRY_WORDS * 4, GPU_MEMORY_DEVICE, st | GPU_USAGE_ADDRESS},
        {&m->locks, "fusion.locks", (uint64_t)c->hash_buckets * 4, GPU_MEMORY_DEVICE, st},
        {&m->nodes, "fusion.nodes", (uint64_t)c->node_cap * FUSION_NODE_WORDS * 4, GPU_MEMORY_DEVICE, st | GPU_USAGE_ADDRESS},
        {&m->info, "fusion.brick_info", (uint64_t)c->brick_cap * FUSION_BRICK_INFO_WORDS * 4, GPU_MEMORY_DEVICE, st},
        {&m->sign, "fusion.sign_pool", (uint64_t)c->brick_cap * BRICK_WORDS * 4, GPU_MEMORY_DEVICE, st | GPU_USAGE_ADDRESS},
        {&m->conf, "fusion.conf_pool", (uint64_t)c->brick_cap * BRICK_WORDS * 4, GPU_MEMORY_DEVICE, st | GPU_USAGE_ADDRESS},
        {&m->free_stack, "fusion.free_stack", (uint64_t)c->brick_cap * 4, GPU_MEMORY_DEVICE, st},
        {&m->stamp, "fusion.stamp", (uint64_t)c->brick_cap * 4, GPU_MEMORY_DEVICE, st},
        {&m->counters, "fusion.counters", FUSION_CNT_WORDS * 4, GPU_MEMORY_DEVICE, st | GPU_USAGE_INDIRECT},
        {&m->frames, "fusion.frames", (uint64_t)m->ring_slots * FUSION_FRAME_WORDS * 4, GPU_MEMORY_DEVICE, st},
        /* The window and colour passes read it through its address (gpu_buffer_address). */
        {&m->depth_ring, "fusion.depth_ring", (uint64_t)m->ring_slots * depth_words * 4, GPU_MEMORY_DEVICE,
         st | GPU_USAGE_ADDRESS},
        /* Room for the colour whether or not the map keeps it: tracking reads it here. */
        {&m->upload, "fusion.upload", FUSION_FRAME_WORDS * 4 + depth_words * 4 * 2, GPU_MEMORY_UPLOAD, st},
        {&m->readback, "fusion.readback", (FUSION_CNT_WORDS + FUSION_MAX_BUCKETS + 1) * 4, GPU_MEMORY_READBACK, st},
        /* Up to 3 band points per pixel wait for a retry pass. */
        {&m->samples, "fusion.retry", (FUSION_QUEUE_ENTRIES + 2 * 3 * pixels) * 4, GPU_MEMORY_DEVICE,
         st | GPU_USAGE_INDIRECT},
        {&m->new_list, "fusion.new_list", ((uint64_t)FUSION_LIST_HEADER + c->brick_cap) * 4, GPU_MEMORY_DEVICE,
         st | GPU_USAGE_INDIRECT},
        {&m->window_list, "fusion.window_list", ((uint64_t)FUSION_LIST_HEADER + c->brick_cap) * 4,
         GPU_MEMORY_DEVICE, st | GPU_USAGE_INDIRECT},
        {&m->window_slices, "fusion.window_slices", FUSION_SLICE_WORDS * 4, GPU_MEMORY_DEVICE, st},
        /* The bricks whose colour the trim looks at (one word without colour). */
        {&m->trim_list, "fusion.trim_list",
         c->keep_colour && c->colour_reach ? ((uint64_t)FUSION_LIST_HEADER + c->brick_cap) * 4 : (uint64_t)FUSION_LIST_HEADER * 4,
         GPU_MEMORY_DEVICE, st | GPU_USAGE_INDIRECT},
    };
    uint64_t max_binding = gpu_device_limits(m->ctx)->max_storage_buffer_range;
    for (size_t i = 0; i < sizeof plan / sizeof plan[0]; i++) {
        if (plan[i].bytes > max_binding)
            return bf_fail(BF_INVALID_ARG,
                           "fusion: %s needs %llu bytes, above this device's %llu-byte storage binding "
                           "(lower brick_cap / node_cap)",
                           plan[i].name, (unsigned long long)plan[i].bytes, (unsigned long long)max_binding);
        gpu_buffer_desc d = {.name = plan[i].name, .size_bytes = plan[i].bytes, .memory = plan[i].memory,
                             .usage = plan[i].usage};
        bf_status s = gpu_buffer_create(m->ctx, &d, plan[i].dst);
        if (s != BF_OK) return s;
    }
    /* Without colour the colour buffers are one word each: the removal
     * pass binds them whether or not the map keeps colour. */
    uint64_t on = c->keep_colour ? 1 : 0;
    buf_plan colour[] = {
        {&m->colour_ring, "fusion.colour_ring", on ? (uint64_t)m->ring_slots * depth_words * 4 : 4, GPU_MEMORY_DEVICE,
         st | GPU_USAGE_ADDRESS},
        {&m->cmask, "fusion.colour_mask", on ? (uint64_t)c->brick_cap * BRICK_WORDS * 4 : 4, GPU_MEMORY_DEVICE, st},
        {&m->chead, "fusion.colour_head", on ? (uint64_t)c->brick_cap * 4 : 4, GPU_MEMORY_DEVICE, st},
        {&m->cpool, "fusion.colour_pool", on ? (uint64_t)c->colour_unit_cap * FUSION_COLOUR_UNIT_WORDS * 4 : 4,
         GPU_MEMORY_DEVICE, st},
        {&m->cfree, "fusion.colour_free", on ? (uint64_t)c->colour_unit_cap * 4 : 4, GPU_MEMORY_DEVICE, st},
    };
    for (size_t i = 0; i < sizeof colour / sizeof colour[0]; i++) {
        if (colour[i].bytes > max_binding)
            return bf_fail(BF_INVALID_ARG, "fusion: %s needs %llu bytes, above this device's %llu-byte storage binding",
                           colour[i].name, (unsigned long long)colour[i].bytes, (unsigned long long)max_binding);
        gpu_buffer_desc d = {.name = colour[i].name, .size_bytes = colour[i].bytes, .memory = colour[i].memory,
                             .usage = colour[i].usage};
        bf_status s = gpu_buffer_create(m->ctx, &d, colour[i].dst);
        if (s != BF_OK) return s;
    }
    gpu_buffer *a[FUSION_ADDRS];
    a[FUSION_ADDR_HASH] = m->hash;
    a[FUSION_ADDR_NODES] = m->nodes;
    a[FUSION_ADDR_SIGN] = m->sign;
    a[FUSION_ADDR_CONF] = m->conf;
    a[FUSION_ADDR_DEPTH_RING] = m->depth_ring;
    a[FUSION_ADDR_COLOUR_RING] = m->colour_ring;
    return gpu_address_table_create(m->ctx, "fusion.addresses", a, FUSION_ADDRS, &m->addresses);
}

/* Fills the pools with their empty state: no chunk, no node, every brick slot
 * on the free stack (slot 0 on top), empty frame slots. */
void fusion__hash_empty(uint32_t *words, uint32_t n_entries)
{
    for (uint32_t e = 0; e < n_entries; e++) {
        uint32_t *w = words + (size_t)e * FUSION_ENTRY_WORDS;
        memset(w, 0, FUSION_ENTRY_WORDS * 4);
        w[FUSION_ENTRY_ROOT] = FUSION_NONE;
        w[FUSION_ENTRY_NEXT] = FUSION_NONE;
        w[FUSION_ENTRY_STATE] = FUSION_ENTRY_FREE;
    }
}

/* The empty map's counters: every brick slot (and colour unit) free. */
static bf_status counters_empty(fusion_map *m)
{
    uint32_t cnt[FUSION_CNT_WORDS] = {0};
    cnt[FUSION_CNT_FREE_TOP] = m->cfg.brick_cap;
    cnt[FUSION_CNT_COLOUR_TOP] = m->cfg.keep_colour ? m->cfg.colour_unit_cap : 0;
    return gpu_buffer_upload(m->counters, 0, cnt, sizeof cnt);
}

/* Zeroes b, unless it is new and its memory came zeroed (an imported
 * pool: its untouched pages then stay unfaulted until the GPU writes them;
 * for a 10^6 particle set that is the 0.5 GB of its sign and confidence
 * pools). */
static bf_status zero(gpu_buffer *b, bool is_fresh)
{
    return is_fresh && gpu_buffer_created_zero(b) ? BF_OK : gpu_buffer_zero(b);
}

bf_status fusion__reset(fusion_map *m, bool is_fresh)
{
    const fusion_config *c = &m->cfg;
    bf_status s;
    size_t tmp_words = (size_t)(m->n_entries > c->brick_cap ? m->n_entries : c->brick_cap) * FUSION_ENTRY_WORDS;
    if (c->keep_colour && tmp_words < c->colour_unit_cap) tmp_words = c->colour_unit_cap;
    uint32_t *tmp = malloc(tmp_words * 4);
    if (!tmp) return bf_fail(BF_NO_MEMORY, "fusion: host staging for map init");
    fusion__hash_empty(tmp, m->n_entries);
    s = gpu_buffer_upload(m->hash, 0, tmp, (uint64_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    for (uint32_t i = 0; s == BF_OK && i < c->brick_cap; i++) tmp[i] = c->brick_cap - 1 - i;
    if (s == BF_OK) s = gpu_buffer_upload(m->free_stack, 0, tmp, (uint64_t)c->brick_cap * 4);
    if (c->keep_colour) {
        for (uint32_t i = 0; s == BF_OK && i < c->colour_unit_cap; i++) tmp[i] = c->colour_unit_cap - 1 - i;
        if (s == BF_OK) s = gpu_buffer_upload(m->cfree, 0, tmp, (uint64_t)c->colour_unit_cap * 4);
        if (s == BF_OK) s = zero(m->cmask, is_fresh);
        if (s == BF_OK) s = gpu_buffer_fill(m->chead, 0, gpu_buffer_size(m->chead), FUSION_NONE);
        if (s == BF_OK) s = zero(m->cpool, is_fresh);
    }
    free(tmp);
    if (s == BF_OK) s = zero(m->locks, is_fresh);
    if (s == BF_OK) s = gpu_buffer_fill(m->nodes, 0, gpu_buffer_size(m->nodes), FUSION_NONE);
    if (s == BF_OK) s = gpu_buffer_fill(m->info, 0, gpu_buffer_size(m->info), FUSION_NONE);
    if (s == BF_OK) s = zero(m->sign, is_fresh);
    if (s == BF_OK) s = zero(m->conf, is_fresh);
    if (s == BF_OK) s = gpu_buffer_fill(m->stamp, 0, gpu_buffer_size(m->stamp), FUSION_NONE);
    /* The frame records empty (index FUSION_NONE) leave the depth and
     * colour rings unread until a frame's upload writes its slot with its
     * record (cmd_upload; the passes read a slot only where its record
     * names the frame they want), so the rings, half of the bytes here, are
     * not filled: at 640x480 that is 98 MB of first-touch page faults less
     * at start-up. */
    if (s == BF_OK) s = gpu_buffer_fill(m->frames, 0, gpu_buffer_size(m->frames), FUSION_NONE);
    if (s == BF_OK) s = zero(m->samples, is_fresh);
    if (s == BF_OK) s = zero(m->new_list, is_fresh);
    if (s == BF_OK) s = zero(m->window_list, is_fresh);
    if (s == BF_OK) s = zero(m->window_slices, is_fresh);
    if (s == BF_OK) s = zero(m->trim_list, is_fresh);
    if (s == BF_OK) s = zero(m->readback, is_fresh);
    if (s == BF_OK) s = counters_empty(m);
    m->only_loaded = s == BF_OK;
    return s;
}

/* The pools' first fill on a thread of its own while the pipelines
 * compile: on lavapipe at 640x480 each is about half of fusion_create
 * (0.44 s of fills, mostly first-touch page faults of ~180 MB, and 0.49 s
 * of pipelines, docs/bench_replay.md "Start-up"). Only where every buffer
 * it fills is mapped: the fill is then host writes alone and never meets
 * the queue that the pipelines' warm-ups submit to (those bind a scratch
 * buffer of their own, gpu_pipeline_warm_up). */
typedef struct reset_job {
    fusion_map *m;
    bf_status s;
    char error[512];
} reset_job;

static void *reset_main(void *arg)
{
    reset_job *j = arg;
    j->s = fusion__reset(j->m, true);
    if (j->s != BF_OK) snprintf(j->error, sizeof j->error, "%s", bf_last_error());
    return NULL;
}

static bool reset_is_host_only(const fusion_map *m)
{
    const gpu_buffer *b[] = {m->hash,     m->locks,      m->nodes,      m->info,        m->sign,
                             m->conf,     m->free_stack, m->stamp,      m->counters,    m->frames,
                             m->depth_ring, m->readback, m->samples,    m->new_list,    m->window_list,
                             m->window_slices, m->colour_ring, m->cmask, m->chead,      m->cpool,
                             m->cfree,    m->trim_list};
    for (size_t i = 0; i < sizeof b / sizeof b[0]; i++) {
        if (!gpu_buffer_map(b[i])) return false;
    }
    return true;
}

static bf_status create_pipelines(fusion_map *m)
{
    bf_status s = fusion__alloc_create(m);
    if (s == BF_OK) s = fusion__integrate_create(m);
    if (s == BF_OK) s = fusion__schedule_create(m);
    if (s == BF_OK) s = fusion__colour_create(m);
    return s;
}

bf_status fusion_create(gpu_context *ctx, const fusion_config *cfg, const bf_intrinsics *K, bf_vec3 origin_w,
                        fusion_map **out)
{
    fusion_config c = cfg ? *cfg : fusion_config_default();
    if (c.node_cap == 0) c.node_cap = 2 * c.brick_cap + 64;
    if (c.colour_unit_cap == 0) { /* 8 units a brick (the real frames use 5.5), as one binding holds */
        uint64_t fit = gpu_device_limits(ctx)->max_storage_buffer_range / (FUSION_COLOUR_UNIT_WORDS * 4);
        uint64_t want = 8ull * c.brick_cap;
        c.colour_unit_cap = (uint32_t)(want < fit ? want : fit);
    }
    bf_status s = config_check(&c, K);
    if (s != BF_OK) return s;
    if (!isfinite(origin_w.x) || !isfinite(origin_w.y) || !isfinite(origin_w.z))
        return bf_fail(BF_INVALID_ARG, "fusion: map origin is not finite");
    /* The allocation pass shares pixel cells between neighbouring lanes. */
    uint32_t need = VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_SHUFFLE_RELATIVE_BIT;
    if ((gpu_device_limits(ctx)->subgroup_ops & need) != need)
        return bf_fail(BF_UNSUPPORTED, "fusion: device %s lacks subgroup shuffles in compute shaders",
                       gpu_device_name(ctx));
    fusion_map *m = calloc(1, sizeof *m);
    if (!m) return bf_fail(BF_NO_MEMORY, "fusion: map struct");
    m->ctx = ctx;
    /* A reader that keeps a map's buffers bound (render/) tells maps apart by
     * this, not by buffer pointers a later map may reuse. */
    static uint64_t next_id;
    m->id = __atomic_add_fetch(&next_id, 1, __ATOMIC_RELAXED);
    m->cfg = c;
    m->K = *K;
    m->origin_w = origin_w;
    m->ring_slots = 2 * c.window;
    m->n_entries = c.hash_buckets * FUSION_BUCKET_SLOTS + c.hash_overflow;
    m->colour_registered = true;
    m->Kc = *K;
    m->T_colour_depth = bf_se3_identity();
    if ((s = create_buffers(m)) != BF_OK) goto fail;
    reset_job job = {.m = m, .s = BF_OK};
    pthread_t filler;
    bool threaded = reset_is_host_only(m) && bf_thread_start(&filler, reset_main, &job) == 0;
    if (!threaded) job.s = fusion__reset(m, true);
    /* The filler's status is read only after the join (it writes it). */
    s = !threaded && job.s != BF_OK ? job.s : c.load_only ? BF_OK : create_pipelines(m);
    if (threaded) {
        pthread_join(filler, NULL);
        /* The message was recorded on the filler's thread: again on this one. */
        if (job.s != BF_OK && s == BF_OK) s = bf_fail(job.s, "%s", job.error);
    }
    if (s != BF_OK) goto fail;
    *out = m;
    return BF_OK;
fail:
    fusion_destroy(m);
    return s;
}

void fusion_destroy(fusion_map *m)
{
    if (!m) return;
    fusion__colour_destroy(m);
    fusion__schedule_destroy(m);
    fusion__integrate_destroy(m);
    fusion__alloc_destroy(m);
    gpu_buffer *bufs[] = {m->readback, m->window_slices, m->window_list, m->new_list,
                          m->samples, m->upload, m->depth_ring, m->frames,
                          m->counters, m->stamp, m->free_stack, m->conf, m->sign, m->info, m->nodes,
                          m->locks, m->hash, m->colour_ring, m->cmask, m->chead, m->cpool, m->cfree,
                          m->trim_list, m->addresses};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++) gpu_buffer_destroy(bufs[i]);
    free(m);
}

bf_status fusion__bindings_create(fusion_map *m, const char *name, gpu_buffer *const *bufs, uint32_t n,
                                  gpu_bindings **out)
{
    gpu_bindings *b = NULL;
    bf_status s = gpu_bindings_create(m->ctx, n, name, &b);
    for (uint32_t i = 0; i < n && s == BF_OK; i++) s = gpu_bindings_set(b, i, bufs[i], 0, GPU_WHOLE_SIZE);
    if (s != BF_OK) {
        gpu_bindings_destroy(b);
        return s;
    }
    *out = b;
    return BF_OK;
}

/* ------------------------------------------------------------ host mirror */

void fusion__host_map_free(fusion_host_map *h)
{
    free(h->hash);
    free(h->nodes);
    free(h->info);
    free(h->counters);
    free(h->free_stack);
    memset(h, 0, sizeof *h);
}

static bf_status download_whole(gpu_buffer *b, uint32_t **out)
{
    uint64_t n = gpu_buffer_size(b);
    uint32_t *p = malloc(n);
    if (!p) return bf_fail(BF_NO_MEMORY, "fusion: host copy of %s (%llu bytes)", gpu_buffer_name(b),
                           (unsigned long long)n);
    bf_status s = gpu_buffer_download(b, 0, p, n);
    if (s != BF_OK) {
        free(p);
        return s;
    }
    *out = p;
    return BF_OK;
}

bf_status fusion__host_map_load(fusion_map *m, fusion_host_map *h)
{
    memset(h, 0, sizeof *h);
    bf_status s = download_whole(m->hash, &h->hash);
    if (s == BF_OK) s = download_whole(m->nodes, &h->nodes);
    if (s == BF_OK) s = download_whole(m->info, &h->info);
    if (s == BF_OK) s = download_whole(m->counters, &h->counters);
    if (s == BF_OK) s = download_whole(m->free_stack, &h->free_stack);
    if (s != BF_OK) fusion__host_map_free(h);
    return s;
}

/* Hash entry of chunk key, or FUSION_NONE (the shaders' lookup). */
static uint32_t host_find_chunk(const fusion_map *m, const fusion_host_map *h, const int32_t key[3])
{
    return fusion_find_chunk(h->hash, key[0], key[1], key[2], m->cfg.hash_buckets, m->cfg.hash_overflow);
}

/* ------------------------------------------------------------ snapshot */

/* The colours of the live bricks of slots [0, high) (info: their records),
 * in snapshot order, expanded to 512 per brick (hostmap.rgb565). Units are
 * downloaded as far as the chains reach (the free stack hands out low
 * units first). */
static bf_status snapshot_colour(fusion_map *m, const uint32_t *info, uint32_t high, uint32_t n_live, uint16_t **out)
{
    uint32_t *mask = malloc((size_t)high * BRICK_WORDS * 4 + 4), *head = malloc((size_t)high * 4 + 4);
    uint16_t *rgb = calloc((size_t)n_live * BRICK_VOXELS + 1, 2);
    fusion__colour_host units = {0};
    bf_status s = mask && head && rgb ? BF_OK : bf_fail(BF_NO_MEMORY, "fusion: colour snapshot of %u bricks", n_live);
    if (s == BF_OK && high) s = gpu_buffer_download(m->cmask, 0, mask, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && high) s = gpu_buffer_download(m->chead, 0, head, (uint64_t)high * 4);
    uint32_t k = 0;
    for (uint32_t b = 0; s == BF_OK && b < high; b++) {
        if (info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] >= m->n_entries) continue;
        s = fusion__colour_expand(m, &units, mask + (size_t)b * BRICK_WORDS, head[b], rgb + (size_t)k++ * BRICK_VOXELS);
    }
    free(mask);
    free(head);
    fusion__colour_host_free(&units);
    if (s != BF_OK) {
        free(rgb);
        return s;
    }
    *out = rgb;
    return BF_OK;
}

bf_status fusion_snapshot_take(fusion_map *m, hostmap *out)
{
    uint32_t cap = m->cfg.brick_cap;
    uint32_t *info = malloc((size_t)cap * FUSION_BRICK_INFO_WORDS * 4), *hash = NULL, *sign = NULL, *conf = NULL;
    hostmap_brick *bricks = NULL;
    bf_status s = info ? gpu_buffer_download(m->info, 0, info, (uint64_t)cap * FUSION_BRICK_INFO_WORDS * 4)
                       : bf_fail(BF_NO_MEMORY, "fusion: snapshot");
    /* Live slots are mostly low (the free stack hands out slot 0 first):
     * download the sign and confidence pools only up to the highest. */
    uint32_t n_live = 0, high = 0;
    for (uint32_t b = 0; s == BF_OK && b < cap; b++)
        if (info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] < m->n_entries) n_live++, high = b + 1;
    if (s == BF_OK) {
        hash = malloc((size_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
        sign = malloc((size_t)high * BRICK_WORDS * 4 + 4);
        conf = malloc((size_t)high * BRICK_WORDS * 4 + 4);
        bricks = malloc((size_t)n_live * sizeof *bricks + 1);
        if (!hash || !sign || !conf || !bricks) s = bf_fail(BF_NO_MEMORY, "fusion: snapshot of %u bricks", n_live);
    }
    if (s == BF_OK) s = gpu_buffer_download(m->hash, 0, hash, (uint64_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    if (s == BF_OK && high) s = gpu_buffer_download(m->sign, 0, sign, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && high) s = gpu_buffer_download(m->conf, 0, conf, (uint64_t)high * BRICK_WORDS * 4);
    uint32_t k = 0;
    for (uint32_t b = 0; s == BF_OK && b < high; b++) {
        const uint32_t *in = info + (size_t)b * FUSION_BRICK_INFO_WORDS;
        if (in[FUSION_INFO_CHUNK] >= m->n_entries) continue;
        const uint32_t *e = hash + (size_t)in[FUSION_INFO_CHUNK] * FUSION_ENTRY_WORDS;
        hostmap_brick *o = &bricks[k++];
        for (int i = 0; i < 3; i++) o->key[i] = (int32_t)e[i];
        uint32_t p = in[FUSION_INFO_POS];
        o->level = fusion_pos_level(p);
        o->cell[0] = fusion_pos_x(p), o->cell[1] = fusion_pos_y(p), o->cell[2] = fusion_pos_z(p);
        memcpy(&o->error, &in[FUSION_INFO_ERROR], 4);
        memcpy(o->sign, sign + (size_t)b * BRICK_WORDS, sizeof o->sign);
        memcpy(o->conf, conf + (size_t)b * BRICK_WORDS, sizeof o->conf);
    }
    uint16_t *rgb = NULL;
    if (s == BF_OK && m->cfg.keep_colour) s = snapshot_colour(m, info, high, n_live, &rgb);
    free(info);
    free(hash);
    free(sign);
    free(conf);
    if (s != BF_OK) {
        free(bricks);
        return s;
    }
    out->chunk_m = m->cfg.chunk_m;
    out->origin_w = m->origin_w;
    out->n_bricks = n_live;
    out->bricks = bricks;
    out->rgb565 = rgb;
    return BF_OK;
}

/* ------------------------------------------------------------ integrity */

/* Walks one octree, checking every node and brick it reaches. */
static bf_status check_tree(const fusion_map *m, const fusion_host_map *h, uint32_t entry, uint32_t node, uint32_t level,
                            const uint32_t cell[3], uint8_t *node_seen, uint8_t *brick_seen, uint32_t *n_bricks)
{
    uint32_t n_nodes = h->counters[FUSION_CNT_NODES] < m->cfg.node_cap ? h->counters[FUSION_CNT_NODES] : m->cfg.node_cap;
    if (node >= n_nodes) return bf_fail(BF_NUMERIC, "fusion check: node %u beyond the %u handed out", node, n_nodes);
    if (node_seen[node]++) return bf_fail(BF_NUMERIC, "fusion check: node %u reached twice", node);
    const uint32_t *nd = h->nodes + (size_t)node * FUSION_NODE_WORDS;
    uint32_t b = nd[FUSION_NODE_BRICK];
    if (b == FUSION_LOCKED || nd[FUSION_NODE_CHILD] == FUSION_LOCKED)
        return bf_fail(BF_NUMERIC, "fusion check: node %u still locked", node);
    if (b != FUSION_NONE) {
        if (b >= m->cfg.brick_cap) return bf_fail(BF_NUMERIC, "fusion check: node %u owns brick %u beyond the pool", node, b);
        if (brick_seen[b]++) return bf_fail(BF_NUMERIC, "fusion check: brick %u owned twice", b);
        const uint32_t *in = h->info + (size_t)b * FUSION_BRICK_INFO_WORDS;
        if (in[FUSION_INFO_CHUNK] != entry || in[FUSION_INFO_NODE] != node ||
            in[FUSION_INFO_POS] != fusion_pack_pos(cell[0], cell[1], cell[2], level))
            return bf_fail(BF_NUMERIC, "fusion check: brick %u record (chunk %u node %u pos %08x) disagrees with its "
                           "node %u (chunk %u, level %u cell %u,%u,%u)", b, in[FUSION_INFO_CHUNK], in[FUSION_INFO_NODE],
                           in[FUSION_INFO_POS], node, entry, level, cell[0], cell[1], cell[2]);
        (*n_bricks)++;
    }
    uint32_t child = nd[FUSION_NODE_CHILD];
    if (child == FUSION_NONE) return BF_OK;
    if (level >= m->cfg.max_level) return bf_fail(BF_NUMERIC, "fusion check: node %u at level %u has children", node, level);
    for (uint32_t o = 0; o < 8; o++) {
        uint32_t c[3] = {2 * cell[0] + (o & 1), 2 * cell[1] + ((o >> 1) & 1), 2 * cell[2] + ((o >> 2) & 1)};
        bf_status s = check_tree(m, h, entry, child + o, level + 1, c, node_seen, brick_seen, n_bricks);
        if (s != BF_OK) return s;
    }
    return BF_OK;
}

static bf_status check_map(const fusion_map *m, const fusion_host_map *h)
{
    uint8_t *node_seen = calloc(m->cfg.node_cap, 1), *brick_seen = calloc(m->cfg.brick_cap, 1);
    uint8_t *entry_seen = calloc(m->n_entries, 1);
    bf_status s = node_seen && brick_seen && entry_seen ? BF_OK : bf_fail(BF_NO_MEMORY, "fusion check");
    uint32_t n_bricks = 0, n_chunks = 0;
    for (uint32_t bucket = 0; s == BF_OK && bucket < m->cfg.hash_buckets; bucket++) {
        /* The bucket's slots, then its overflow chain. */
        uint32_t e = bucket * FUSION_BUCKET_SLOTS, k = 0;
        while (s == BF_OK && e != FUSION_NONE) {
            const uint32_t *w = h->hash + (size_t)e * FUSION_ENTRY_WORDS;
            if (entry_seen[e]++) {
                s = bf_fail(BF_NUMERIC, "fusion check: hash entry %u reached twice (cycle?)", e);
                break;
            }
            if (w[FUSION_ENTRY_STATE] == FUSION_ENTRY_VALID) {
                int32_t key[3] = {(int32_t)w[0], (int32_t)w[1], (int32_t)w[2]};
                if (fusion_hash(key[0], key[1], key[2], m->cfg.hash_buckets) != bucket)
                    s = bf_fail(BF_NUMERIC, "fusion check: chunk (%d,%d,%d) in bucket %u, hashes elsewhere", key[0],
                                key[1], key[2], bucket);
                else if (host_find_chunk(m, h, key) != e)
                    s = bf_fail(BF_NUMERIC, "fusion check: chunk (%d,%d,%d) stored twice", key[0], key[1], key[2]);
                uint32_t cell[3] = {0, 0, 0};
                if (s == BF_OK)
                    s = check_tree(m, h, e, w[FUSION_ENTRY_ROOT], 0, cell, node_seen, brick_seen, &n_bricks);
                n_chunks++;
            } else if (w[FUSION_ENTRY_STATE] != FUSION_ENTRY_FREE) {
                s = bf_fail(BF_NUMERIC, "fusion check: hash entry %u in state %u", e, w[FUSION_ENTRY_STATE]);
            }
            k++;
            if (k < FUSION_BUCKET_SLOTS) e++;
            else e = w[FUSION_ENTRY_NEXT];
        }
    }
    uint32_t live = m->cfg.brick_cap - h->counters[FUSION_CNT_FREE_TOP];
    if (s == BF_OK && (n_bricks != live || n_bricks != h->counters[FUSION_CNT_BRICKS]))
        s = bf_fail(BF_NUMERIC, "fusion check: %u bricks in the trees, %u off the free stack, counter says %u", n_bricks,
                    live, h->counters[FUSION_CNT_BRICKS]);
    /* Every slot on the free stack is free, once. */
    for (uint32_t i = 0; s == BF_OK && i < h->counters[FUSION_CNT_FREE_TOP]; i++) {
        uint32_t b = h->free_stack[i];
        if (b >= m->cfg.brick_cap || brick_seen[b]++)
            s = bf_fail(BF_NUMERIC, "fusion check: free stack entry %u (brick %u) is live or repeated", i, b);
        else if (h->info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] != FUSION_NONE)
            s = bf_fail(BF_NUMERIC, "fusion check: free brick %u still has a record", b);
    }
    free(node_seen);
    free(brick_seen);
    free(entry_seen);
    return s;
}

/* The colour units: every live brick's chain holds distinct units, enough
 * for its masks' colours; the free stack holds the others, once each (no
 * unit lost or shared: the colour pass's pops, the removal's and the
 * trim's pushes). */
static bf_status check_colour(fusion_map *m, const fusion_host_map *h)
{
    uint32_t *mask = NULL, *head = NULL, *pool = NULL, *cfree = NULL;
    uint32_t cap = m->cfg.colour_unit_cap;
    uint8_t *seen = calloc(cap ? cap : 1, 1);
    bf_status s = seen ? BF_OK : bf_fail(BF_NO_MEMORY, "fusion check: %u colour units", cap);
    if (s == BF_OK) s = download_whole(m->cmask, &mask);
    if (s == BF_OK) s = download_whole(m->chead, &head);
    if (s == BF_OK) s = download_whole(m->cpool, &pool);
    if (s == BF_OK) s = download_whole(m->cfree, &cfree);
    uint64_t in_chains = 0;
    for (uint32_t b = 0; s == BF_OK && b < m->cfg.brick_cap; b++) {
        if (h->info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] == FUSION_NONE) continue;
        uint32_t colours = 0, n = 0;
        for (uint32_t w = 0; w < BRICK_WORDS; w++) colours += (uint32_t)__builtin_popcount(mask[(size_t)b * BRICK_WORDS + w]);
        for (uint32_t u = head[b]; u != FUSION_NONE; u = pool[(size_t)u * FUSION_COLOUR_UNIT_WORDS], n++) {
            if (u >= cap || seen[u]++ || n >= FUSION_COLOUR_MAX_UNITS) {
                s = bf_fail(BF_NUMERIC, "fusion check: brick %u's colour chain reaches unit %u again or out of range", b, u);
                break;
            }
        }
        in_chains += n;
        if (s == BF_OK && n * FUSION_COLOUR_UNIT_COLOURS < colours)
            s = bf_fail(BF_NUMERIC, "fusion check: brick %u has %u colours in a chain of %u units", b, colours, n);
    }
    uint32_t top = h->counters[FUSION_CNT_COLOUR_TOP];
    if (s == BF_OK && top > cap) s = bf_fail(BF_NUMERIC, "fusion check: colour free stack top %u above its %u units", top, cap);
    for (uint32_t i = 0; s == BF_OK && i < top; i++)
        if (cfree[i] >= cap || seen[cfree[i]]++)
            s = bf_fail(BF_NUMERIC, "fusion check: colour free stack entry %u (unit %u) is in a chain or repeated", i,
                        cfree[i]);
    if (s == BF_OK && in_chains + top != cap)
        s = bf_fail(BF_NUMERIC, "fusion check: %llu colour units in chains and %u free of %u", (unsigned long long)in_chains,
                    top, cap);
    free(seen);
    free(mask);
    free(head);
    free(pool);
    free(cfree);
    return s;
}

bf_status fusion_check(fusion_map *m)
{
    fusion_host_map h;
    bf_status s = fusion__host_map_load(m, &h);
    if (s != BF_OK) return s;
    s = check_map(m, &h);
    if (s == BF_OK && m->cfg.keep_colour) s = check_colour(m, &h);
    fusion__host_map_free(&h);
    return s;
}

fusion_gpu_view fusion_gpu_view_get(const fusion_map *m)
{
    fusion_gpu_view v = {
        .hash = m->hash,
        .nodes = m->nodes,
        .info = m->info,
        .sign = m->sign,
        .conf = m->conf,
        .addresses = m->addresses,
        .id = m->id,
        .cmask = m->cmask,
        .cpool = m->cpool,
        .chead = m->chead,
        .has_colour = m->cfg.keep_colour,
        .n_buckets = m->cfg.hash_buckets,
        .n_entries = m->n_entries,
        .max_level = m->cfg.max_level,
        .chunk_m = m->cfg.chunk_m,
        .origin_w = m->origin_w,
    };
    return v;
}

const fusion_config *fusion_get_config(const fusion_map *m) { return &m->cfg; }

uint32_t fusion_frame_count(const fusion_map *m) { return m->n_frames; }
uint32_t fusion_windows_done(const fusion_map *m) { return m->n_windows_done; }

/* Undoes fusion_load alone: its slots [0, n_loaded), its nodes, the hash and
 * the counters. The load only popped the free stack (it is unchanged below
 * the top) and left stamps, locks, frame slots and lists alone. A particle
 * set re-binned per step (render/particles.c) then clears its own bricks,
 * not the whole pools: 0.4 s of the 10^6 set's step before. */
static bf_status clear_loaded(fusion_map *m)
{
    uint64_t bricks = m->n_loaded, nodes = m->use.nodes;
    uint32_t *tmp = malloc((size_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    if (!tmp) return bf_fail(BF_NO_MEMORY, "fusion: host staging for clearing the map");
    fusion__hash_empty(tmp, m->n_entries);
    bf_status s = gpu_buffer_upload(m->hash, 0, tmp, (uint64_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    free(tmp);
    if (s == BF_OK) s = gpu_buffer_fill(m->nodes, 0, nodes * FUSION_NODE_WORDS * 4, FUSION_NONE);
    if (s == BF_OK) s = gpu_buffer_fill(m->info, 0, bricks * FUSION_BRICK_INFO_WORDS * 4, FUSION_NONE);
    if (s == BF_OK) s = gpu_buffer_fill(m->sign, 0, bricks * BRICK_WORDS * 4, 0);
    if (s == BF_OK) s = gpu_buffer_fill(m->conf, 0, bricks * BRICK_WORDS * 4, 0);
    if (s == BF_OK) s = counters_empty(m);
    return s;
}

bf_status fusion_clear(fusion_map *m)
{
    if (!m) return bf_fail(BF_INVALID_ARG, "fusion_clear: NULL map");
    if (m->n_frames > 0 || m->has_incoming)
        return bf_fail(BF_INVALID_ARG, "fusion: only a map without frames is cleared (a loaded one)");
    /* A failed partial clear falls back to the whole reset. */
    bool partial = m->only_loaded && m->n_loaded > 0 && !m->cfg.keep_colour;
    bf_status s = partial ? clear_loaded(m) : BF_OK;
    if (!partial || s != BF_OK) s = fusion__reset(m, false);
    m->n_loaded = 0;
    m->use.bricks = m->use.nodes = m->use.overflow = 0;
    return s;
}

bf_status fusion_set_origin(fusion_map *m, bf_vec3 origin_w)
{
    if (!isfinite(origin_w.x) || !isfinite(origin_w.y) || !isfinite(origin_w.z))
        return bf_fail(BF_INVALID_ARG, "fusion: map origin is not finite");
    /* Every GPU coordinate is relative to the origin: it may move only
     * while nothing has been placed. */
    if (m->n_frames > 0 || m->has_incoming || m->n_loaded)
        return bf_fail(BF_INVALID_ARG, "fusion: the origin of a map with frames cannot move");
    m->origin_w = origin_w;
    return BF_OK;
}
