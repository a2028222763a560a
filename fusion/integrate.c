/* Windowed integration: host side of shaders/fusion_integrate.comp and
 * shaders/fusion_integrate_args.comp (DESIGN.md section 4). The per-voxel
 * math is shared with the CPU oracle tests/fusion/integrate_ref.c through
 * shaders/fusion.glsl.h; docs/fusion_integrate.md describes the rule. */
#include "bf_shaders_spv.h"
#include "fusion_int.h"

enum { INTEGRATE_BUFFERS = 7 }; /* hash, info, sign, conf, frames, depth ring, list */

/* Voxels per invocation of the integration kernel (512 / it invocations
 * per workgroup). On a CPU device (lavapipe) one subgroup per workgroup is
 * the fastest: 64 voxels x 8 invocations, no barrier ever switches between
 * subgroups (lavapipe runs a workgroup's subgroups as coroutines), which
 * halves the per-brick cost against 64 invocations and beats 512 by 4x
 * (docs/fusion_integrate.md). A GPU wants wide workgroups: 2 voxels x 256.
 * fusion_config.integrate_vpt overrides it (benchmarks, tests). Every
 * choice gives the same bits. */
static uint32_t voxels_per_thread(const gpu_context *ctx, uint32_t configured)
{
    const gpu_limits *l = gpu_device_limits(ctx);
    uint32_t vpt = 2;
    if (gpu_device(ctx)->type == VK_PHYSICAL_DEVICE_TYPE_CPU) {
        uint32_t sg = l->subgroup_size ? l->subgroup_size : 8;
        vpt = sg >= 8 ? BRICK_VOXELS / sg : 64;
        if (vpt < 1) vpt = 1;
        if (vpt > 64) vpt = 64;
    }
    if (configured) vpt = configured;
    while (BRICK_VOXELS / vpt > l->max_compute_workgroup_invocations ||
           BRICK_VOXELS / vpt > l->max_compute_workgroup_size[0])
        vpt *= 2;
    return vpt;
}

/* List entries per workgroup. llvmpipe spends about 10 us starting a
 * workgroup of the integration kernel (whatever the workgroup then does:
 * measured with an immediate return), about as much as a (brick, frame)
 * pair costs: on a CPU device a workgroup takes 16 consecutive bricks. A
 * GPU wants one brick per workgroup. fusion_config.integrate_bpg overrides
 * it (benchmarks, tests). Every choice gives the same bits. */
static uint32_t bricks_per_group(const gpu_context *ctx, uint32_t configured)
{
    if (configured) return configured;
    return gpu_device(ctx)->type == VK_PHYSICAL_DEVICE_TYPE_CPU ? 16 : 1;
}

static bf_status bind_all(fusion_map *m, gpu_bindings *b, gpu_buffer *list)
{
    gpu_buffer *bufs[INTEGRATE_BUFFERS] = {m->hash, m->info, m->sign, m->conf, m->frames, m->depth_ring, list};
    bf_status s = BF_OK;
    for (uint32_t i = 0; i < INTEGRATE_BUFFERS && s == BF_OK; i++)
        s = gpu_bindings_set(b, i, bufs[i], 0, GPU_WHOLE_SIZE);
    return s;
}

bf_status fusion__integrate_create(fusion_map *m)
{
    uint32_t vpt = voxels_per_thread(m->ctx, m->cfg.integrate_vpt);
    m->integrate_bpg = bricks_per_group(m->ctx, m->cfg.integrate_bpg);
    gpu_pipeline_desc d = {
        .name = "fusion.integrate",
        .spirv = bf_spv_fusion_integrate,
        .spirv_bytes = bf_spv_fusion_integrate_size,
        .n_buffers = INTEGRATE_BUFFERS,
        .push_bytes = sizeof(fusion_integrate_push),
        .local_size = {BRICK_VOXELS / vpt, 1, 1},
        .spec = &vpt,
        .n_spec = 1,
    };
    bf_status s = gpu_pipeline_create(m->ctx, &d, &m->p_integrate);
    if (s != BF_OK) return s;
    gpu_pipeline_desc a = {
        .name = "fusion.integrate_args",
        .spirv = bf_spv_fusion_integrate_args,
        .spirv_bytes = bf_spv_fusion_integrate_args_size,
        .n_buffers = INTEGRATE_BUFFERS, /* the same binding sets; it reads only the list */
        .push_bytes = sizeof(fusion_integrate_push),
        .local_size = {1, 1, 1},
    };
    if ((s = gpu_pipeline_create(m->ctx, &a, &m->p_integrate_args)) != BF_OK) return s;
    if ((s = gpu_bindings_create(m->ctx, INTEGRATE_BUFFERS, "fusion.integrate_new", &m->b_integrate_new)) != BF_OK)
        return s;
    if ((s = bind_all(m, m->b_integrate_new, m->new_list)) != BF_OK) return s;
    if ((s = gpu_bindings_create(m->ctx, INTEGRATE_BUFFERS, "fusion.integrate_window", &m->b_integrate_window)) !=
        BF_OK)
        return s;
    if ((s = bind_all(m, m->b_integrate_window, m->window_list)) != BF_OK) return s;
    /* The trim list's group counts (fusion__cmd_colour_trim) come from the same args pass. */
    if ((s = gpu_bindings_create(m->ctx, INTEGRATE_BUFFERS, "fusion.integrate_trim", &m->b_integrate_trim)) != BF_OK)
        return s;
    if ((s = bind_all(m, m->b_integrate_trim, m->trim_list)) != BF_OK) return s;
    /* Zero push constants and buffers: both kernels see an empty list. */
    return gpu_pipeline_warm_up(m->ctx, (gpu_pipeline *[]){m->p_integrate, m->p_integrate_args}, 2);
}

void fusion__integrate_destroy(fusion_map *m)
{
    gpu_bindings_destroy(m->b_integrate_trim);
    gpu_bindings_destroy(m->b_integrate_window);
    gpu_bindings_destroy(m->b_integrate_new);
    gpu_pipeline_destroy(m->p_integrate_args);
    gpu_pipeline_destroy(m->p_integrate);
    m->b_integrate_window = m->b_integrate_new = m->b_integrate_trim = NULL;
    m->p_integrate_args = m->p_integrate = NULL;
}

uint32_t fusion__max_groups_x(const fusion_map *m)
{
    uint32_t max_x = gpu_device_limits(m->ctx)->max_compute_workgroup_count[0];
    if (max_x > 65535u) max_x = 65535u;
    return m->cfg.max_groups_x && m->cfg.max_groups_x < max_x ? m->cfg.max_groups_x : max_x;
}

/* The weight that makes a voxel confident in a window of n frames: the
 * configured one, or n for a window of fewer frames (the first windows of a
 * scan), so a voxel seen in every one of its frames still is. The window
 * that holds a whole sequence shorter than twice the threshold (whole:
 * fusion_flush's one window of a few frames) asks for half its frames'
 * weight instead, at least 1: asked to be seen with full weight in every
 * frame, the voxels just behind a noisy surface rarely were, and 2-7
 * frames made less surface than 1 (docs/fusion.md, "Short sequences"). */
static float window_conf_weight(float conf_weight, uint32_t n_frames, bool whole)
{
    float cap = (float)n_frames;
    if (whole) {
        cap = 0.5f * (float)n_frames;
        if (cap < 1.0f) cap = 1.0f;
    }
    return conf_weight < cap ? conf_weight : cap;
}

fusion_integrate_push fusion__integrate_params(const fusion_map *m, uint32_t first, uint32_t max_count,
                                               uint32_t frame_first, uint32_t n_frames, bool set_confidence)
{
    fusion_integrate_push pc = {
        .first = first,
        .max_count = max_count,
        .frame_first = frame_first,
        .n_frames = n_frames,
        .ring_slots = m->ring_slots,
        .depth_words = (uint32_t)(((uint64_t)m->K.width * m->K.height + 1) / 2),
        .set_confidence = set_confidence ? 1u : 0u,
        .max_groups_x = fusion__max_groups_x(m),
        .chunk_m = m->cfg.chunk_m,
        .conf_weight = window_conf_weight(m->cfg.conf_weight, n_frames, set_confidence && m->window_whole),
        .sigma_a = m->cfg.sensor.sigma_a,
        .sigma_b = m->cfg.sensor.sigma_b,
        .sigma_c = m->cfg.sensor.sigma_c,
        .prior_weight = FUSION_PRIOR_WEIGHT,
        .bricks_per_group = m->integrate_bpg ? m->integrate_bpg : 1,
        .depth_addr_lo = (uint32_t)gpu_buffer_address(m->depth_ring),
        .depth_addr_hi = (uint32_t)(gpu_buffer_address(m->depth_ring) >> 32),
    };
    return pc;
}

void fusion__cmd_integrate(fusion_map *m, gpu_bindings *b, uint32_t first, uint32_t max_count, uint32_t frame_first,
                           uint32_t n_frames, bool set_confidence)
{
    BF_ASSERT(b == m->b_integrate_new || b == m->b_integrate_window);
    BF_ASSERT(n_frames <= FUSION_INTEGRATE_MAX_FRAMES && n_frames <= m->ring_slots);
    gpu_buffer *list = b == m->b_integrate_new ? m->new_list : m->window_list;
    fusion_integrate_push pc = fusion__integrate_params(m, first, max_count, frame_first, n_frames, set_confidence);
    gpu_cmd_dispatch(m->ctx, m->p_integrate_args, b, &pc, 1, 1, 1);
    /* The group counts written into the list's header -> the indirect
     * dispatch reading them. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_INDIRECT);
    gpu_cmd_dispatch_indirect(m->ctx, m->p_integrate, b, &pc, list, FUSION_LIST_ARGS * 4);
    /* The sign, confidence and error writes -> whatever reads the map next
     * (another integration pass over the same bricks, ray-casting); it also
     * orders this dispatch's read of the group counts before the next
     * pass's args write. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
}
