/* Colour: host side of shaders/fusion_colour.comp (DESIGN.md section 3).
 * The colour pass runs after each window slice's integration and removal,
 * over the same list entries, reading cfg.colour_frames frames spread over
 * the window. */
#include <math.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "fusion_int.h"

enum { COLOUR_BUFFERS = 11 };

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
    gpu_buffer *bufs[COLOUR_BUFFERS] = {m->hash,        m->info,        m->conf,  m->frames,
                                        m->depth_ring,  m->colour_ring, m->window_list, m->cidx,
                                        m->cpool,       m->counters,    m->cfree};
    if (s == BF_OK) s = fusion__bindings_create(m, "fusion.colour", bufs, COLOUR_BUFFERS, &m->b_colour);
    /* As the integration: a CPU device pays per workgroup, a GPU wants one brick each. */
    m->colour_bpg = gpu_device(m->ctx)->type == VK_PHYSICAL_DEVICE_TYPE_CPU ? 16 : 1;
    if (s == BF_OK) s = gpu_pipeline_warm_up(m->ctx, (gpu_pipeline *[]){m->p_colour}, 1);
    return s;
}

void fusion__colour_destroy(fusion_map *m)
{
    gpu_bindings_destroy(m->b_colour);
    gpu_pipeline_destroy(m->p_colour);
    m->b_colour = NULL;
    m->p_colour = NULL;
}

void fusion__cmd_colour(fusion_map *m, uint32_t first, uint32_t max_count)
{
    if (!m->p_colour || max_count == 0) return;
    uint32_t n_window = m->window_end - m->window_first;
    uint32_t n = m->cfg.colour_frames < n_window ? m->cfg.colour_frames : n_window;
    if (n == 0) return;
    /* Frames spread evenly over the window, the first half a stride in. */
    uint32_t stride = n_window / n;
    fusion_colour_push pc = {
        .first = first,
        .max_count = max_count,
        .frame_first = m->window_first + stride / 2,
        .n_frames = n,
        .frame_stride = stride ? stride : 1,
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
    };
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) pc.R[i * 3 + j] = (float)m->T_colour_depth.R[i][j];
    }
    pc.t[0] = (float)m->T_colour_depth.t.x, pc.t[1] = (float)m->T_colour_depth.t.y;
    pc.t[2] = (float)m->T_colour_depth.t.z;
    uint32_t groups = gpu_groups(max_count, m->colour_bpg);
    uint32_t max_x = gpu_device_limits(m->ctx)->max_compute_workgroup_count[0];
    if (max_x > 65535u) max_x = 65535u;
    uint32_t gx = groups < max_x ? groups : max_x, gy = gpu_groups(groups, gx);
    gpu_cmd_dispatch(m->ctx, m->p_colour, m->b_colour, &pc, gx, gy, 1);
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

bf_status fusion_set_colour_camera(fusion_map *m, const bf_intrinsics *Kc, const bf_se3 *T_colour_depth)
{
    if (!Kc || !T_colour_depth) {
        m->colour_registered = true;
        return BF_OK;
    }
    if (!(Kc->fx_px != 0 && Kc->fy_px != 0) || !isfinite(Kc->fx_px) || !isfinite(Kc->fy_px) ||
        !isfinite(Kc->cx_px) || !isfinite(Kc->cy_px) || !bf_se3_is_finite(T_colour_depth))
        return bf_fail(BF_INVALID_ARG, "fusion: colour camera (fx %g, fy %g) or T_colour_depth is not usable",
                       Kc->fx_px, Kc->fy_px);
    m->Kc = *Kc;
    m->T_colour_depth = *T_colour_depth;
    m->colour_registered = false;
    return BF_OK;
}
