/* Adding frames: upload into the ring, allocation, the sub-cache pass and
 * the window schedule (DESIGN.md section 4).
 *
 * Windows of n frames slide by n/2: when frame e with (e + 1) % (n/2) == 0
 * arrives, the window [e - n + 1, e] closes, its bricks (those stamped by one
 * of its frames) are gathered, and their integration is spread over the next
 * n/2 frames, 2/n of the list per frame, so the frame time stays flat. The
 * ring holds 2n frames, so the window's frames are still there when its last
 * slice runs (e + n/2 - 2n < e - n + 1). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "fusion_int.h"

static uint32_t half_window(const fusion_map *m) { return m->cfg.window / 2; }

static bf_status window_list_create(fusion_map *m)
{
    gpu_pipeline_desc d = {
        .name = "fusion.window_list",
        .spirv = bf_spv_fusion_window_list,
        .spirv_bytes = bf_spv_fusion_window_list_size,
        .n_buffers = 6,
        .push_bytes = sizeof(fusion_window_list_push),
        .local_size = {64, 1, 1},
    };
    bf_status s = gpu_pipeline_create(m->ctx, &d, &m->p_window_list);
    gpu_buffer *bufs[6] = {m->info, m->stamp, m->window_list, m->hash, m->window_slices, m->trim_list};
    if (s == BF_OK) s = fusion__bindings_create(m, "fusion.window_list", bufs, 6, &m->b_window_list);
    return s;
}

static bf_status remove_create(fusion_map *m)
{
    gpu_pipeline_desc d = {
        .name = "fusion.remove",
        .spirv = bf_spv_fusion_remove,
        .spirv_bytes = bf_spv_fusion_remove_size,
        .n_buffers = 12,
        .push_bytes = sizeof(fusion_remove_push),
        .local_size = {64, 1, 1},
    };
    bf_status s = gpu_pipeline_create(m->ctx, &d, &m->p_remove);
    gpu_buffer *bufs[12] = {m->window_list, m->info,     m->nodes,      m->sign,  m->conf,  m->stamp,
                            m->counters,    m->free_stack, m->cmask,    m->cfree, m->chead, m->cpool};
    if (s == BF_OK) s = fusion__bindings_create(m, "fusion.remove", bufs, 12, &m->b_remove);
    return s;
}

bf_status fusion__schedule_create(fusion_map *m)
{
    bf_status s = window_list_create(m);
    if (s == BF_OK) s = remove_create(m);
    if (s == BF_OK) s = gpu_pipeline_warm_up(m->ctx, (gpu_pipeline *[]){m->p_window_list, m->p_remove}, 2);
    return s;
}

void fusion__schedule_destroy(fusion_map *m)
{
    gpu_bindings_destroy(m->b_remove);
    gpu_pipeline_destroy(m->p_remove);
    gpu_bindings_destroy(m->b_window_list);
    gpu_pipeline_destroy(m->p_window_list);
    m->b_remove = m->b_window_list = NULL;
    m->p_remove = m->p_window_list = NULL;
}

static bool trims(const fusion_map *m) { return m->b_colour_trim != NULL; }

/* Records the gathering of the bricks stamped by frames [first, last],
 * slice by slice (shaders/fusion_window_list.comp), and of those stamped
 * last by frames [trim_first, trim_last] into the trim list (none when
 * trim_first > trim_last). */
static void cmd_window_list(fusion_map *m, uint32_t first, uint32_t last, uint32_t trim_first, uint32_t trim_last)
{
    fusion_window_list_push pc = {.brick_cap = m->cfg.brick_cap, .n_entries = m->n_entries, .first = first,
                                  .last = last, .n_buckets = half_window(m) * FUSION_SLICE_BUCKETS, .pass = FUSION_GATHER_COUNT,
                                  .trim_first = trims(m) ? trim_first : 1, .trim_last = trims(m) ? trim_last : 0};
    uint32_t groups = gpu_groups(m->cfg.brick_cap, 64);
    /* The previous window's slices read the list -> the fills that reset it. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_fill(m->ctx, m->window_list, 0, FUSION_LIST_HEADER * 4, 0);
    gpu_cmd_fill(m->ctx, m->window_slices, 0, GPU_WHOLE_SIZE, 0);
    gpu_cmd_fill(m->ctx, m->trim_list, 0, FUSION_LIST_HEADER * 4, 0);
    /* The cleared counts -> the counting pass. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    gpu_cmd_dispatch_linear(m->ctx, m->p_window_list, m->b_window_list, &pc, groups);
    /* Counts -> their prefix sums -> the scatter. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
    pc.pass = FUSION_GATHER_PREFIX;
    gpu_cmd_dispatch(m->ctx, m->p_window_list, m->b_window_list, &pc, 1, 1, 1);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
    pc.pass = FUSION_GATHER_SCATTER;
    gpu_cmd_dispatch_linear(m->ctx, m->p_window_list, m->b_window_list, &pc, groups);
}

/* The frame record: T_cm takes map points (world minus the map origin) to
 * the camera. Computed in double, handed over in float (DESIGN.md 10). */
static void frame_record(const fusion_map *m, const bf_se3 *T_wc, uint32_t index, fusion_frame *r)
{
    bf_se3 T_mc = fusion_camera_to_map(m, T_wc);
    bf_se3 T_cm = bf_se3_inverse(&T_mc);
    memset(r, 0, sizeof *r);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) r->R[i * 3 + j] = (float)T_cm.R[i][j];
    r->t[0] = (float)T_cm.t.x, r->t[1] = (float)T_cm.t.y, r->t[2] = (float)T_cm.t.z;
    r->fx = (float)m->K.fx_px, r->fy = (float)m->K.fy_px;
    r->cx = (float)m->K.cx_px, r->cy = (float)m->K.cy_px;
    r->depth_unit_m = (float)(1.0 / m->K.depth_scale);
    r->width = m->K.width, r->height = m->K.height;
    r->index = index;
    r->has_colour = m->has_colour_frame ? 1u : 0u;
}

static uint64_t depth_bytes(const fusion_map *m) { return ((uint64_t)m->K.width * m->K.height + 1) / 2 * 4; }

bf_status fusion_upload_frame(fusion_map *m, const bf_frame *f, fusion_frame_slot *out)
{
    if (m->cfg.load_only)
        return bf_fail(BF_INVALID_ARG, "fusion: frame %u: the map was made for loaded bricks only (load_only)", f->index);
    if (f->width != m->K.width || f->height != m->K.height || !f->depth)
        return bf_fail(BF_INVALID_ARG, "fusion: frame %u is %ux%u, the map was made for %ux%u", f->index, f->width,
                       f->height, m->K.width, m->K.height);
    uint8_t *up = gpu_buffer_map(m->upload);
    if (!up) return bf_fail(BF_VULKAN, "fusion: upload buffer is not mapped");
    uint64_t pixels = (uint64_t)m->K.width * m->K.height;
    memcpy(up + FUSION_FRAME_WORDS * 4, f->depth, pixels * 2);
    if (pixels % 2) memset(up + FUSION_FRAME_WORDS * 4 + pixels * 2, 0, 2);
    /* The colour goes into the slot whenever the frame has one (the
     * tracker's photometric term reads it there); it is fused only when the
     * map keeps colour. */
    m->has_colour_frame = m->cfg.keep_colour && f->rgb;
    if (f->rgb) fusion__rgb_to_565(f->rgb, pixels, (uint32_t *)(up + FUSION_FRAME_WORDS * 4 + depth_bytes(m)));
    bf_status s = gpu_buffer_flush(m->upload);
    if (s != BF_OK) return s;
    m->has_incoming = true;
    m->only_loaded = false;
    m->incoming_index = f->index;
    if (out)
        *out = (fusion_frame_slot){.depth = m->upload,
                                   .offset = FUSION_FRAME_WORDS * 4,
                                   .colour = f->rgb ? m->upload : NULL,
                                   .colour_offset = FUSION_FRAME_WORDS * 4 + depth_bytes(m)};
    return BF_OK;
}

/* Writes the record into the incoming slot and records the copy of record
 * and depth into ring slot `slot`. */
static bf_status cmd_upload(fusion_map *m, const fusion_frame *rec, uint32_t slot)
{
    uint8_t *up = gpu_buffer_map(m->upload);
    if (!up) return bf_fail(BF_VULKAN, "fusion: upload buffer is not mapped");
    memcpy(up, rec, sizeof *rec);
    bf_status s = gpu_buffer_flush(m->upload);
    if (s != BF_OK) return s;
    gpu_cmd_copy(m->ctx, m->upload, 0, m->frames, (uint64_t)slot * sizeof *rec, sizeof *rec);
    gpu_cmd_copy(m->ctx, m->upload, sizeof *rec, m->depth_ring, (uint64_t)slot * depth_bytes(m), depth_bytes(m));
    if (rec->has_colour)
        gpu_cmd_copy(m->ctx, m->upload, sizeof *rec + depth_bytes(m), m->colour_ring, (uint64_t)slot * depth_bytes(m),
                     depth_bytes(m));
    return BF_OK;
}

/* Records this frame's slice of the window being integrated. Its colour
 * pass follows at once with colour_now, else it is left for the frame's
 * own "fusion.colour" stage (m->colour_first, colour_count). */
static void cmd_window_slice(fusion_map *m, bool colour_now)
{
    uint32_t half = half_window(m);
    uint32_t k = m->window_slices_done;
    uint32_t first = m->slice_start[k], per = m->slice_start[k + 1] - first;
    uint32_t n_frames = m->window_end - m->window_first;
    if (per > 0 && first < m->window_count) {
        fusion__cmd_integrate(m, m->b_integrate_window, first, per, m->window_first, n_frames, true);
        /* The slice's new bit planes -> the removal pass reading them. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        fusion_remove_push pc = {first, per, m->window_end - 1, m->cfg.keep_colour ? 1u : 0u};
        gpu_cmd_dispatch_linear(m->ctx, m->p_remove, m->b_remove, &pc, gpu_groups(per, 64));
        /* Removal's reads of the list and the pools -> the next slice's args
         * pass writing the list header and its integration; its pushes of
         * colour blocks -> the colour pass's pops. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        if (m->p_colour && colour_now) {
            fusion__cmd_colour(m, first, per);
            /* The colours and the colour index -> readers and the next slice. */
            gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        } else if (m->p_colour) {
            m->colour_first = first, m->colour_count = per;
        }
    }
    if (++m->window_slices_done >= half) {
        m->window_pending = false;
        m->n_windows_done++;
    }
}

static void read_stage_times(fusion_map *m)
{
    m->ms_upload = gpu_stage_ms(m->ctx, "fusion.upload");
    m->ms_alloc = gpu_stage_ms(m->ctx, "fusion.alloc");
    m->ms_subcache = gpu_stage_ms(m->ctx, "fusion.subcache");
    m->ms_window = gpu_stage_ms(m->ctx, "fusion.window");
    m->ms_colour = m->p_colour ? gpu_stage_ms(m->ctx, "fusion.colour") : 0;
}

/* A gathered window's slices from its bucket starts (the last one is its
 * count): slice k ends at the bucket boundary nearest to k / (n/2) of the
 * list. Slices of whole hash values alone came out up to 1.85x the mean on
 * the real dev frames (buckets hold groups of neighbouring bricks, which
 * vary in size), and the frame with the largest paid for it; with 64
 * buckets a slice the largest is 1.05-1.11x the mean there. */
static void set_slices(fusion_map *m, const uint32_t *starts)
{
    uint32_t half = half_window(m), n_buckets = half * FUSION_SLICE_BUCKETS;
    uint32_t total = starts[n_buckets], b = 0, largest = 0;
    m->slice_start[0] = 0;
    for (uint32_t k = 1; k < half; k++) {
        uint64_t target = ((uint64_t)total * k + half / 2) / half;
        while (b < n_buckets && starts[b + 1] <= target) b++;
        /* starts[b] <= target < starts[b + 1]: the nearer of the two. */
        uint32_t at = b < n_buckets && starts[b + 1] - target < target - starts[b] ? starts[b + 1] : starts[b];
        m->slice_start[k] = at > m->slice_start[k - 1] ? at : m->slice_start[k - 1];
    }
    m->slice_start[half] = total;
    for (uint32_t k = 0; k < half; k++) {
        uint32_t n = m->slice_start[k + 1] - m->slice_start[k];
        largest = n > largest ? n : largest;
    }
    m->window_count = total;
    bf_debug("fusion: window of %u bricks in %u slices, the largest %u (%.2f x the mean)", total, half, largest,
             total ? (double)largest * half / total : 0.0);
}

/* Reads the slices of the window list gathered in the last submission
 * (fusion_flush; a frame copies them into the readback buffer instead). */
static bf_status read_window_count(fusion_map *m)
{
    size_t n = (size_t)half_window(m) * FUSION_SLICE_BUCKETS + 1;
    uint32_t *starts = malloc(n * sizeof *starts);
    if (!starts) return bf_fail(BF_NO_MEMORY, "fusion: %zu bucket starts", n);
    bf_status s = gpu_buffer_download(m->window_slices, FUSION_SLICE_STARTS * 4, starts, n * sizeof *starts);
    if (s == BF_OK) set_slices(m, starts);
    free(starts);
    return s;
}

/* Closes the window ending with frame `last` (inclusive): gathers its list
 * (this submission) and schedules its slices. */
static void start_window(fusion_map *m, uint32_t last)
{
    m->window_end = last + 1;
    m->window_first = last + 1 >= m->cfg.window ? last + 1 - m->cfg.window : 0;
    m->window_slices_done = 0;
    m->window_pending = true;
    m->window_whole = false;
    m->window_count = 0;
    memset(m->slice_start, 0, sizeof m->slice_start);
    gpu_cmd_stage_begin(m->ctx, "fusion.window_list");
    /* The bricks stamped last in the half window before this one: no
     * window integrates them again (until a frame stamps them anew), and
     * the one before, whose colour pass read them last, is done. */
    uint32_t slide = half_window(m), trim_first = m->window_first >= slide ? m->window_first - slide : 0;
    bool trim = trims(m) && m->window_first > 0;
    cmd_window_list(m, m->window_first, last, trim ? trim_first : 1, trim ? m->window_first - 1 : 0);
    gpu_cmd_stage_end(m->ctx);
    if (trim) {
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_stage_begin(m->ctx, "fusion.colour_trim");
        fusion__cmd_colour_trim(m);
        gpu_cmd_stage_end(m->ctx);
    }
}

/* Records the trim of every brick (the end of a scan: no window follows),
 * loaded ones too (a store written before the trim). */
static void trim_all(fusion_map *m)
{
    if (!trims(m) || m->n_frames == 0) return;
    fusion_window_list_push pc = {.brick_cap = m->cfg.brick_cap, .n_entries = m->n_entries, .first = 1, .last = 0,
                                  .n_buckets = 1, .pass = FUSION_GATHER_COUNT, .trim_first = 0,
                                  .trim_last = UINT32_MAX, .trim_only = 1};
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_fill(m->ctx, m->trim_list, 0, FUSION_LIST_HEADER * 4, 0);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    gpu_cmd_stage_begin(m->ctx, "fusion.colour_trim");
    gpu_cmd_dispatch_linear(m->ctx, m->p_window_list, m->b_window_list, &pc, gpu_groups(m->cfg.brick_cap, 64));
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
    fusion__cmd_colour_trim(m);
    gpu_cmd_stage_end(m->ctx);
}

/* Reports requests dropped for a full pool since the last frame (the map
 * stays consistent: a dropped request changes nothing), from the counters
 * the frame's submission copied into the readback buffer. The caller names
 * the frame (its own index, which fusion's count of frames is not). */
static bf_status check_pools(fusion_map *m, const uint32_t *cnt)
{
    uint32_t fails = cnt[FUSION_CNT_FAIL_NODES] + cnt[FUSION_CNT_FAIL_BRICKS] + cnt[FUSION_CNT_FAIL_HASH];
    if (fails == m->fails_seen) return BF_OK;
    m->fails_seen = fails;
    return bf_fail(BF_POOL_FULL,
                   "fusion: map pools full, requests dropped in all so far: %u nodes (cap %u), %u bricks "
                   "(cap %u), %u chunks (overflow cap %u)",
                   cnt[FUSION_CNT_FAIL_NODES], m->cfg.node_cap, cnt[FUSION_CNT_FAIL_BRICKS], m->cfg.brick_cap,
                   cnt[FUSION_CNT_FAIL_HASH], m->cfg.hash_overflow);
}

bf_status fusion_cmd_fuse(fusion_map *m, const bf_se3 *T_wc)
{
    if (!m->has_incoming) return bf_fail(BF_INVALID_ARG, "fusion: no frame uploaded to fuse");
    if (!bf_se3_is_finite(T_wc))
        return bf_fail(BF_INVALID_ARG, "fusion: frame %u: camera pose is not finite", m->incoming_index);
    uint32_t index = m->n_frames, slot = fusion__ring_slot(m, index);
    fusion_frame rec;
    frame_record(m, T_wc, index, &rec);
    /* Whatever was recorded before (another module's reads of the map) ->
     * this frame's copies and passes. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_stage_begin(m->ctx, "fusion.upload");
    bf_status s = cmd_upload(m, &rec, slot);
    gpu_cmd_stage_end(m->ctx);
    gpu_cmd_stage_begin(m->ctx, "fusion.alloc");
    fusion__cmd_alloc(m, slot, index);
    gpu_cmd_stage_end(m->ctx);
    /* New bricks and their stamps -> the integration passes. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
    gpu_cmd_stage_begin(m->ctx, "fusion.subcache");
    uint32_t n_sub = index + 1 < m->cfg.subcache ? index + 1 : m->cfg.subcache;
    fusion__cmd_integrate(m, m->b_integrate_new, 0, m->cfg.brick_cap, index + 1 - n_sub, n_sub, false);
    gpu_cmd_stage_end(m->ctx);
    bool closes = (index + 1) % half_window(m) == 0;
    if (m->window_pending) {
        /* Sub-cache writes -> the window slice reading the same bricks. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_stage_begin(m->ctx, "fusion.window");
        m->colour_count = 0;
        cmd_window_slice(m, false);
        gpu_cmd_stage_end(m->ctx);
        if (m->colour_count) { /* its own stage, so its cost shows (docs/colour.md) */
            gpu_cmd_stage_begin(m->ctx, "fusion.colour");
            fusion__cmd_colour(m, m->colour_first, m->colour_count);
            gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
            gpu_cmd_stage_end(m->ctx);
        }
    }
    if (closes) {
        /* Stamps of this frame's allocation -> the gathering pass. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        if (m->window_pending) { /* a slice left over (n/2 of them per window): finish it now */
            while (m->window_pending) cmd_window_slice(m, true);
            gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        }
        start_window(m, index);
    }
    /* The counters (and a new window's brick count) -> their copies into
     * the readback buffer, which the host reads after the fence: no
     * download of its own per frame. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_copy(m->ctx, m->counters, 0, m->readback, 0, FUSION_CNT_WORDS * 4);
    if (closes)
        gpu_cmd_copy(m->ctx, m->window_slices, FUSION_SLICE_STARTS * 4, m->readback, FUSION_CNT_WORDS * 4,
                     (half_window(m) * FUSION_SLICE_BUCKETS + 1) * 4);
    /* The copies -> the host's reads in fusion_finish_frame; the map's
     * writes -> readers recorded next (the ray-cast). */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_HOST);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
    m->fuse_pending = true;
    m->pending_closes = closes;
    return s;
}

bf_status fusion_finish_frame(fusion_map *m)
{
    if (!m->fuse_pending) return bf_fail(BF_INVALID_ARG, "fusion: no frame fused to finish");
    m->fuse_pending = false;
    m->has_incoming = false;
    read_stage_times(m);
    const uint32_t *rb = gpu_buffer_map(m->readback);
    if (!rb) return bf_fail(BF_VULKAN, "fusion: readback buffer is not mapped");
    if (m->pending_closes) set_slices(m, rb + FUSION_CNT_WORDS);
    m->use.bricks = rb[FUSION_CNT_BRICKS];
    m->use.nodes = rb[FUSION_CNT_NODES];
    m->use.overflow = rb[FUSION_CNT_OVERFLOW];
    m->n_frames++;
    return check_pools(m, rb);
}

bf_status fusion_add_frame(fusion_map *m, const bf_frame *f, const bf_se3 *T_wc)
{
    bf_status s = fusion_upload_frame(m, f, NULL);
    if (s == BF_OK && !bf_se3_is_finite(T_wc))
        s = bf_fail(BF_INVALID_ARG, "fusion: frame %u: camera pose is not finite", f->index);
    if (s == BF_OK) s = gpu_begin(m->ctx);
    if (s != BF_OK) return s;
    s = fusion_cmd_fuse(m, T_wc);
    bf_status sw = gpu_submit_wait(m->ctx);
    if (s == BF_OK) s = sw;
    if (s != BF_OK) {
        m->fuse_pending = false;
        /* BF_POOL_FULL is the pools' drops alone (callers go on after it):
         * any other pool that ran out here failed the frame. */
        if (s != BF_POOL_FULL) return s;
        char why[512];
        snprintf(why, sizeof why, "%s", bf_last_error());
        return bf_fail(BF_VULKAN, "fusion: frame %u not fused: %s", f->index, why);
    }
    return fusion_finish_frame(m);
}

bf_status fusion_flush(fusion_map *m)
{
    if (m->n_frames == 0) return BF_OK;
    bf_status s = gpu_begin(m->ctx);
    if (s != BF_OK) return s;
    gpu_cmd_stage_begin(m->ctx, "fusion.window");
    while (m->window_pending) cmd_window_slice(m, true);
    gpu_cmd_stage_end(m->ctx);
    /* The frames after the last closed window have not been in a full
     * window yet: integrate the last n frames as one more window. */
    bool tail = m->window_end < m->n_frames;
    if (tail) {
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        start_window(m, m->n_frames - 1);
        /* Not over a loaded map: its frames are not this window's. */
        m->window_whole = m->window_first == 0 && m->n_loaded == 0;
    }
    if (!tail) trim_all(m);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_HOST);
    if ((s = gpu_submit_wait(m->ctx)) != BF_OK) return s;
    if (!tail) return BF_OK;
    if ((s = read_window_count(m)) != BF_OK) return s;
    if ((s = gpu_begin(m->ctx)) != BF_OK) return s;
    gpu_cmd_stage_begin(m->ctx, "fusion.window");
    while (m->window_pending) cmd_window_slice(m, true);
    gpu_cmd_stage_end(m->ctx);
    trim_all(m);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_HOST);
    return gpu_submit_wait(m->ctx);
}

/* ------------------------------------------------------------ statistics */

bf_se3 fusion_camera_to_map(const fusion_map *m, const bf_se3 *T_wc)
{
    bf_se3 T_mc = *T_wc;
    T_mc.t = bf_v3_sub(T_wc->t, m->origin_w);
    return T_mc;
}

fusion_stage_ms fusion_last_stage_ms(const fusion_map *m)
{
    fusion_stage_ms t = {m->ms_upload, m->ms_alloc, m->ms_subcache, m->ms_window, m->ms_colour};
    return t;
}

uint64_t fusion_reserved_bytes(const fusion_map *m)
{
    if (!m) return 0;
    return gpu_buffer_size(m->hash) + gpu_buffer_size(m->nodes) + gpu_buffer_size(m->info) + gpu_buffer_size(m->sign) +
           gpu_buffer_size(m->conf) + gpu_buffer_size(m->free_stack) + gpu_buffer_size(m->stamp) +
           gpu_buffer_size(m->locks) + gpu_buffer_size(m->cmask) + gpu_buffer_size(m->chead) +
           gpu_buffer_size(m->cpool) + gpu_buffer_size(m->cfree);
}

bf_status fusion_get_stats(fusion_map *m, fusion_stats *out)
{
    uint32_t cnt[FUSION_CNT_WORDS];
    bf_status s = gpu_buffer_download(m->counters, 0, cnt, sizeof cnt);
    if (s != BF_OK) return s;
    hostmap snap;
    if ((s = fusion_snapshot_take(m, &snap)) != BF_OK) return s;
    fusion_stats st;
    memset(&st, 0, sizeof st);
    st.n_frames = m->n_frames;
    st.n_nodes = cnt[FUSION_CNT_NODES] < m->cfg.node_cap ? cnt[FUSION_CNT_NODES] : m->cfg.node_cap;
    st.n_bricks = snap.n_bricks;
    st.fail_nodes = cnt[FUSION_CNT_FAIL_NODES];
    st.fail_bricks = cnt[FUSION_CNT_FAIL_BRICKS];
    st.fail_hash = cnt[FUSION_CNT_FAIL_HASH];
    st.fail_colour = cnt[FUSION_CNT_FAIL_COLOUR];
    if (m->cfg.keep_colour)
        st.n_colour_units = m->cfg.colour_unit_cap - (cnt[FUSION_CNT_COLOUR_TOP] < m->cfg.colour_unit_cap
                                                          ? cnt[FUSION_CNT_COLOUR_TOP]
                                                          : m->cfg.colour_unit_cap);
    for (uint32_t i = 0; i < snap.n_bricks; i++) {
        const hostmap_brick *b = &snap.bricks[i];
        st.bricks_per_level[b->level]++;
        for (uint32_t w = 0; w < BRICK_WORDS; w++) st.n_confident_voxels += (uint64_t)__builtin_popcount(b->conf[w]);
        st.n_surface_voxels += fusion__brick_surface_voxels(b->sign, b->conf);
        for (uint32_t v = 0; snap.rgb565 && v < BRICK_VOXELS; v++)
            st.n_coloured_voxels += snap.rgb565[(size_t)i * BRICK_VOXELS + v] != 0;
    }
    hostmap_free(&snap);
    /* Chunks: live hash entries. */
    uint32_t *hash = malloc((size_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    if (!hash) return bf_fail(BF_NO_MEMORY, "fusion: stats");
    s = gpu_buffer_download(m->hash, 0, hash, (uint64_t)m->n_entries * FUSION_ENTRY_WORDS * 4);
    for (uint32_t e = 0; s == BF_OK && e < m->n_entries; e++)
        st.n_chunks += hash[(size_t)e * FUSION_ENTRY_WORDS + FUSION_ENTRY_STATE] == FUSION_ENTRY_VALID;
    free(hash);
    if (s != BF_OK) return s;
    /* Bytes the scene needs: the live part of each pool (a pool grown to fit
     * would hold exactly this); reserved: what create allocated. */
    st.bytes_sign = (uint64_t)st.n_bricks * BRICK_WORDS * 4;
    st.bytes_conf = st.bytes_sign;
    st.bytes_info = (uint64_t)st.n_bricks * (FUSION_BRICK_INFO_WORDS + 1) * 4; /* record + stamp */
    st.bytes_nodes = (uint64_t)st.n_nodes * FUSION_NODE_WORDS * 4;
    st.bytes_hash = (uint64_t)st.n_chunks * FUSION_ENTRY_WORDS * 4;
    st.bytes_colour = m->cfg.keep_colour ? (uint64_t)st.n_bricks * (BRICK_WORDS + 1) * 4 +
                                               (uint64_t)st.n_colour_units * FUSION_COLOUR_UNIT_WORDS * 4
                                         : 0;
    st.bytes_total = st.bytes_sign + st.bytes_conf + st.bytes_info + st.bytes_nodes + st.bytes_hash;
    st.bytes_reserved = fusion_reserved_bytes(m);
    st.ms_upload = m->ms_upload, st.ms_alloc = m->ms_alloc;
    st.ms_subcache = m->ms_subcache, st.ms_window = m->ms_window, st.ms_colour = m->ms_colour;
    *out = st;
    return BF_OK;
}

uint32_t fusion__brick_surface_voxels(const uint32_t sign[16], const uint32_t conf[16])
{
    uint32_t n = 0;
    for (uint32_t z = 0; z < 8; z++)
        for (uint32_t y = 0; y < 8; y++)
            for (uint32_t x = 0; x < 8; x++) {
                uint32_t w = brick_word(x, y, z), bit = brick_bit(x, y, z);
                if (!((conf[w] >> bit) & 1)) continue;
                uint32_t sv = (sign[w] >> bit) & 1;
                int nb[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
                for (int k = 0; k < 6; k++) {
                    int a = (int)x + nb[k][0], b = (int)y + nb[k][1], c = (int)z + nb[k][2];
                    if (a < 0 || b < 0 || c < 0 || a > 7 || b > 7 || c > 7) continue;
                    uint32_t w2 = brick_word(a, b, c), b2 = brick_bit(a, b, c);
                    if (((conf[w2] >> b2) & 1) && ((sign[w2] >> b2) & 1) != sv) {
                        n++;
                        break;
                    }
                }
            }
    return n;
}
