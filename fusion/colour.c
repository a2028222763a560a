/* Colour: host side of shaders/fusion_colour.comp (DESIGN.md section 3).
 * The colour pass runs after each window slice's integration and removal,
 * over the same list entries, reading cfg.colour_frames frames spread over
 * the window. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "fusion_int.h"

enum { COLOUR_BUFFERS = 13 };

bf_status fusion__colour_create(fusion_map *m)
{
    if (!m->cfg.keep_colour) return BF_OK;
    gpu_pipeline_desc d = {
        .name = "fusion.colour",
        .spirv = bf_spv_fusion_colour,
        .spirv_bytes = bf_spv_fusion_colour_size,
        .n_buffers = COLOUR_BUFFERS,
        .push_bytes = sizeof(fusion_colour_push),
        .local_size = {FUSION_COLOUR_LOCAL, 1, 1},
    };
    bf_status s = gpu_pipeline_create(m->ctx, &d, &m->p_colour);
    /* The rings are read through the map's address table (binding 4). */
    gpu_buffer *bufs[COLOUR_BUFFERS] = {m->hash,     m->info,  m->conf,     m->frames, m->addresses,
                                        m->window_list, m->cmask, m->cpool,   m->counters, m->cfree,
                                        m->chead,    m->sign,  m->nodes};
    if (s == BF_OK) s = fusion__bindings_create(m, "fusion.colour", bufs, COLOUR_BUFFERS, &m->b_colour);
    bufs[5] = m->trim_list;
    if (s == BF_OK && m->cfg.colour_reach)
        s = fusion__bindings_create(m, "fusion.colour_trim", bufs, COLOUR_BUFFERS, &m->b_colour_trim);
    /* As the integration: a CPU device pays per workgroup, a GPU wants one brick each. */
    m->colour_bpg = gpu_device(m->ctx)->type == VK_PHYSICAL_DEVICE_TYPE_CPU ? 16 : 1;
    if (s == BF_OK) s = gpu_pipeline_warm_up(m->ctx, (gpu_pipeline *[]){m->p_colour}, 1);
    return s;
}

void fusion__colour_destroy(fusion_map *m)
{
    gpu_bindings_destroy(m->b_colour_trim);
    gpu_bindings_destroy(m->b_colour);
    gpu_pipeline_destroy(m->p_colour);
    m->b_colour = m->b_colour_trim = NULL;
    m->p_colour = NULL;
}

fusion__colour_plan fusion__colour_frames(uint32_t window, uint32_t colour_frames, uint32_t window_first,
                                          uint32_t window_end)
{
    fusion__colour_plan p = {0};
    uint32_t n_window = window_end - window_first;
    uint32_t n = colour_frames < n_window ? colour_frames : n_window;
    if (n == 0) return p;
    /* Frames spread evenly over the window, the first half a stride in.
     * Windows overlap by half: where the slide is a whole number of strides
     * the same offset would read half of each window's frames again, so
     * full windows on the schedule alternate between a quarter and three
     * quarters of a stride in and every colour frame is a new one (twice
     * the frames for the same reads; a voxel a later window made confident
     * finds its colour in that window's own frames). A scan's last window,
     * off the schedule, keeps half a stride. */
    uint32_t stride = n_window / n, slide = window / 2, offset = stride / 2;
    if (stride >= 2 && slide && slide % stride == 0 && n_window == window && window_end % slide == 0)
        offset = (window_end / slide) % 2 ? (3 * stride) / 4 : stride / 4;
    p.first = window_first + offset;
    p.n = n;
    p.stride = stride ? stride : 1;
    return p;
}

void fusion__cmd_colour(fusion_map *m, uint32_t first, uint32_t max_count)
{
    if (!m->p_colour || max_count == 0) return;
    fusion__colour_plan plan = fusion__colour_frames(m->cfg.window, m->cfg.colour_frames, m->window_first, m->window_end);
    if (plan.n == 0) return;
    fusion_colour_push pc = {
        .first = first,
        .max_count = max_count,
        .frame_first = plan.first,
        .n_frames = plan.n,
        .frame_stride = plan.stride,
        .ring_slots = m->ring_slots,
        .depth_words = (uint32_t)(((uint64_t)m->K.width * m->K.height + 1) / 2),
        .registered = m->colour_registered ? 1u : 0u,
        .chunk_m = m->cfg.chunk_m,
        .sigma_a = m->cfg.sensor.sigma_a,
        .sigma_b = m->cfg.sensor.sigma_b,
        .sigma_c = m->cfg.sensor.sigma_c,
        .cfx = (float)m->Kc.fx_px,
        .cfy = (float)m->Kc.fy_px,
        .ccx = (float)m->Kc.cx_px,
        .ccy = (float)m->Kc.cy_px,
        .bricks_per_group = m->colour_bpg,
        .n_buckets = m->cfg.hash_buckets,
        .n_overflow = m->cfg.hash_overflow,
        .mode = FUSION_COLOUR_MODE_FRAMES,
    };
    bf_quat q = bf_quat_from_mat(m->T_colour_depth.R);
    pc.q[0] = (float)q.x, pc.q[1] = (float)q.y, pc.q[2] = (float)q.z, pc.q[3] = (float)q.w;
    for (int i = 0; i < 5; i++) pc.dist[i] = (float)m->colour_dist[i];
    pc.t[0] = (float)m->T_colour_depth.t.x, pc.t[1] = (float)m->T_colour_depth.t.y;
    pc.t[2] = (float)m->T_colour_depth.t.z;
    uint32_t groups = gpu_groups(max_count, m->colour_bpg);
    uint32_t max_x = gpu_device_limits(m->ctx)->max_compute_workgroup_count[0];
    if (max_x > 65535u) max_x = 65535u;
    uint32_t gx = groups < max_x ? groups : max_x, gy = gpu_groups(groups, gx);
    gpu_cmd_dispatch(m->ctx, m->p_colour, m->b_colour, &pc, gx, gy, 1);
}

void fusion__cmd_colour_trim(fusion_map *m)
{
    if (!m->p_colour || !m->b_colour_trim) return;
    /* The group counts from the trim list's count, written into its header. */
    fusion_integrate_push args = {.first = 0,
                                  .max_count = m->cfg.brick_cap,
                                  .max_groups_x = fusion__max_groups_x(m),
                                  .bricks_per_group = m->colour_bpg};
    gpu_cmd_dispatch(m->ctx, m->p_integrate_args, m->b_integrate_trim, &args, 1, 1, 1);
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_INDIRECT);
    fusion_colour_push pc = {
        .first = 0,
        .max_count = m->cfg.brick_cap,
        .chunk_m = m->cfg.chunk_m,
        .bricks_per_group = m->colour_bpg,
        .n_buckets = m->cfg.hash_buckets,
        .n_overflow = m->cfg.hash_overflow,
        .mode = FUSION_COLOUR_MODE_TRIM | m->cfg.colour_reach << 8,
    };
    gpu_cmd_dispatch_indirect(m->ctx, m->p_colour, m->b_colour_trim, &pc, m->trim_list, FUSION_LIST_ARGS * 4);
    /* The trimmed masks and chains, the units given back -> readers and the
     * next colour pass's pops. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
}

void fusion__rgb_to_565(const uint8_t *rgb, uint64_t n_pixels, uint32_t *words)
{
    for (uint64_t i = 0; i < n_pixels; i += 2) {
        const uint8_t *a = rgb + i * 3;
        uint32_t lo = fusion_rgb565(a[0], a[1], a[2]);
        uint32_t hi = i + 1 < n_pixels ? fusion_rgb565(a[3], a[4], a[5]) : 0u;
        words[i / 2] = lo | (hi << 16);
    }
}

bf_status fusion_set_colour_camera(fusion_map *m, const bf_intrinsics *Kc, const double *dist,
                                   const bf_se3 *T_colour_depth)
{
    if (!Kc || !T_colour_depth) {
        m->colour_registered = true;
        return BF_OK;
    }
    bool dist_ok = true;
    for (int i = 0; dist && i < 5; i++) dist_ok = dist_ok && isfinite(dist[i]);
    if (!(Kc->fx_px != 0 && Kc->fy_px != 0) || !isfinite(Kc->fx_px) || !isfinite(Kc->fy_px) ||
        !isfinite(Kc->cx_px) || !isfinite(Kc->cy_px) || !bf_se3_is_finite(T_colour_depth) || !dist_ok)
        return bf_fail(BF_INVALID_ARG,
                       "fusion: colour camera (fx %g, fy %g), its distortion or T_colour_depth is not usable",
                       Kc->fx_px, Kc->fy_px);
    for (int i = 0; i < 5; i++) m->colour_dist[i] = dist ? dist[i] : 0.0;
    m->Kc = *Kc;
    m->T_colour_depth = *T_colour_depth;
    m->colour_registered = false;
    return BF_OK;
}

/* ------------------------------------------------------------ host copies of the units */

void fusion__colour_host_free(fusion__colour_host *h)
{
    free(h->units);
    memset(h, 0, sizeof *h);
}

/* Holds units [0, n) on the host; grows by half again at least, so a chain
 * walk downloads a few large ranges, not one unit at a time. */
static bf_status host_ensure(fusion_map *m, fusion__colour_host *h, uint32_t n)
{
    uint32_t cap = m->cfg.colour_unit_cap;
    if (n <= h->n) return BF_OK;
    if (n > cap) return bf_fail(BF_NUMERIC, "fusion: colour unit %u beyond the pool's %u", n - 1, cap);
    uint64_t want = (uint64_t)h->n + h->n / 2 + 4096;
    if (want < n) want = n;
    if (want > cap) want = cap;
    uint32_t *p = bf_realloc(h->units, (size_t)want * FUSION_COLOUR_UNIT_WORDS * 4);
    if (!p) return bf_fail(BF_NO_MEMORY, "fusion: host copy of %llu colour units", (unsigned long long)want);
    h->units = p;
    bf_status s = gpu_buffer_download(m->cpool, (uint64_t)h->n * FUSION_COLOUR_UNIT_WORDS * 4,
                                      p + (size_t)h->n * FUSION_COLOUR_UNIT_WORDS,
                                      (want - h->n) * FUSION_COLOUR_UNIT_WORDS * 4);
    if (s == BF_OK) h->n = (uint32_t)want;
    return s;
}

/* The brick's chain from head into list[FUSION_COLOUR_MAX_UNITS]; *n units. */
static bf_status host_chain(fusion_map *m, fusion__colour_host *h, uint32_t head, uint32_t *list, uint32_t *n)
{
    *n = 0;
    for (uint32_t u = head; u != FUSION_NONE && *n < FUSION_COLOUR_MAX_UNITS;) {
        bf_status s = host_ensure(m, h, u + 1);
        if (s != BF_OK) return s;
        list[(*n)++] = u;
        u = h->units[(size_t)u * FUSION_COLOUR_UNIT_WORDS];
    }
    return BF_OK;
}

/* Voxel (x + 8y + 64z) of colour rank order position i = sub-brick * 32 + bit. */
static uint32_t rank_voxel(uint32_t i)
{
    uint32_t w = i / 32, bit = i % 32;
    uint32_t x = (w & 1) * 4 + (bit & 3), y = ((w >> 1) & 1) * 4 + ((bit >> 2) & 3), z = (w >> 2) * 2 + (bit >> 4);
    return x + 8 * y + 64 * z;
}

bf_status fusion__colour_expand(fusion_map *m, fusion__colour_host *h, const uint32_t *masks, uint32_t head,
                                uint16_t *out)
{
    uint32_t list[FUSION_COLOUR_MAX_UNITS], n;
    memset(out, 0, BRICK_VOXELS * sizeof *out);
    bf_status s = host_chain(m, h, head, list, &n);
    uint32_t r = 0;
    for (uint32_t i = 0; s == BF_OK && i < BRICK_VOXELS; i++) {
        if (!((masks[i / 32] >> (i % 32)) & 1)) continue;
        uint32_t k = r / FUSION_COLOUR_UNIT_COLOURS, j = r % FUSION_COLOUR_UNIT_COLOURS;
        if (k >= n) break;
        uint32_t word = h->units[(size_t)list[k] * FUSION_COLOUR_UNIT_WORDS + 1 + j / 2];
        out[rank_voxel(i)] = (uint16_t)(word >> ((j & 1) * 16));
        r++;
    }
    return s;
}

bf_status fusion__colour_fill(fusion_map *m, fusion__colour_host *h, uint32_t *masks, uint32_t *head,
                              const uint16_t *c, uint32_t *cfree, uint32_t *top, uint32_t *fail)
{
    uint16_t have[BRICK_VOXELS];
    bf_status s = fusion__colour_expand(m, h, masks, *head, have);
    if (s != BF_OK) return s;
    uint32_t total = 0, added = 0;
    for (uint32_t v = 0; v < BRICK_VOXELS; v++) {
        if (!have[v] && c[v]) have[v] = c[v], added++;
        total += have[v] != 0;
    }
    if (!added) return BF_OK;
    uint32_t list[FUSION_COLOUR_MAX_UNITS], n;
    if ((s = host_chain(m, h, *head, list, &n)) != BF_OK) return s;
    uint32_t need = (total + FUSION_COLOUR_UNIT_COLOURS - 1) / FUSION_COLOUR_UNIT_COLOURS, n_old = n;
    if (need > n && need - n > *top) {
        (*fail)++;
        return BF_OK; /* the brick keeps what it had */
    }
    while (n < need) {
        uint32_t u = cfree[--*top];
        if ((s = host_ensure(m, h, u + 1)) != BF_OK) return s;
        list[n++] = u;
    }
    for (uint32_t k = n_old; k < n; k++) {
        if (k == 0) *head = list[0];
        else h->units[(size_t)list[k - 1] * FUSION_COLOUR_UNIT_WORDS] = list[k];
        h->units[(size_t)list[k] * FUSION_COLOUR_UNIT_WORDS] = FUSION_NONE;
    }
    /* Packed again in rank order. */
    for (uint32_t k = 0; k < n; k++) memset(&h->units[(size_t)list[k] * FUSION_COLOUR_UNIT_WORDS + 1], 0, 4 * 7);
    memset(masks, 0, BRICK_WORDS * 4);
    uint32_t r = 0;
    for (uint32_t i = 0; i < BRICK_VOXELS; i++) {
        uint16_t col = have[rank_voxel(i)];
        if (!col) continue;
        masks[i / 32] |= 1u << (i % 32);
        uint32_t j = r % FUSION_COLOUR_UNIT_COLOURS;
        h->units[(size_t)list[r / FUSION_COLOUR_UNIT_COLOURS] * FUSION_COLOUR_UNIT_WORDS + 1 + j / 2] |=
            (uint32_t)col << ((j & 1) * 16);
        r++;
    }
    return BF_OK;
}

bf_status fusion__colour_release(fusion_map *m, fusion__colour_host *h, uint32_t *masks, uint32_t *head,
                                 uint32_t *cfree, uint32_t *top)
{
    uint32_t list[FUSION_COLOUR_MAX_UNITS], n;
    bf_status s = host_chain(m, h, *head, list, &n);
    if (s != BF_OK) return s;
    for (uint32_t k = 0; k < n; k++) cfree[(*top)++] = list[k];
    *head = FUSION_NONE;
    memset(masks, 0, BRICK_WORDS * 4);
    return BF_OK;
}
