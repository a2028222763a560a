/* Brick allocation: host side of shaders/fusion_alloc.comp (one pass over
 * every depth sample, then retry passes over the queue of points that lost
 * a lock, DESIGN.md sections 3 and 9). */
#include "bf_shaders_spv.h"
#include "fusion_int.h"

/* Passes after the first (which only queues the points): a point loses at
 * most once per level it creates (chunk, max_level nodes; a brick never
 * loses), so max_level + 2 insertion passes drain the queue; one more as
 * margin, as before pass 0 stopped inserting. */
static uint32_t alloc_retry_passes(const fusion_map *m) { return m->cfg.max_level + 3; }

bf_status fusion__alloc_create(fusion_map *m)
{
    gpu_pipeline_desc d = {
        .name = "fusion.alloc",
        .spirv = bf_spv_fusion_alloc,
        .spirv_bytes = bf_spv_fusion_alloc_size,
        .n_buffers = 11,
        .push_bytes = sizeof(fusion_alloc_push),
        .local_size = {FUSION_ALLOC_LOCAL, 1, 1},
    };
    bf_status s = gpu_pipeline_create(m->ctx, &d, &m->p_alloc);
    if (s != BF_OK) return s;
    gpu_pipeline_desc a = {
        .name = "fusion.alloc_args",
        .spirv = bf_spv_fusion_alloc_args,
        .spirv_bytes = bf_spv_fusion_alloc_args_size,
        .n_buffers = 2,
        .push_bytes = sizeof(fusion_alloc_push),
        .local_size = {64, 1, 1},
    };
    if ((s = gpu_pipeline_create(m->ctx, &a, &m->p_alloc_args)) != BF_OK) return s;
    if ((s = gpu_bindings_create(m->ctx, 11, "fusion.alloc", &m->b_alloc)) != BF_OK) return s;
    gpu_buffer *bufs[11] = {m->hash, m->locks, m->nodes, m->info, m->counters, m->free_stack,
                            m->stamp, m->frames, m->depth_ring, m->samples, m->new_list};
    for (uint32_t i = 0; i < 11 && s == BF_OK; i++) s = gpu_bindings_set(m->b_alloc, i, bufs[i], 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_create(m->ctx, 2, "fusion.alloc_args", &m->b_alloc_args);
    if (s == BF_OK) s = gpu_bindings_set(m->b_alloc_args, 0, m->samples, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(m->b_alloc_args, 1, m->locks, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_pipeline_warm_up(m->ctx, (gpu_pipeline *[]){m->p_alloc, m->p_alloc_args}, 2);
    return s;
}

void fusion__alloc_destroy(fusion_map *m)
{
    gpu_bindings_destroy(m->b_alloc_args);
    gpu_bindings_destroy(m->b_alloc);
    gpu_pipeline_destroy(m->p_alloc_args);
    gpu_pipeline_destroy(m->p_alloc);
    m->b_alloc_args = m->b_alloc = NULL;
    m->p_alloc_args = m->p_alloc = NULL;
}

void fusion__cmd_alloc(fusion_map *m, uint32_t slot, uint32_t frame_index)
{
    uint32_t n_pixels = m->K.width * m->K.height;
    fusion_alloc_push pc = {
        .slot = slot,
        .frame_index = frame_index,
        .pass = 0,
        .queue_cap = 3 * n_pixels,
        .max_level = m->cfg.max_level,
        .n_buckets = m->cfg.hash_buckets,
        .n_overflow = m->cfg.hash_overflow,
        .node_cap = m->cfg.node_cap,
        .chunk_m = m->cfg.chunk_m,
        .voxel_ratio = m->cfg.voxel_ratio,
        .band_sigmas = m->cfg.band_sigmas,
        .max_depth_m = m->cfg.sensor.max_depth_m,
        .sigma_a = m->cfg.sensor.sigma_a,
        .sigma_b = m->cfg.sensor.sigma_b,
        .sigma_c = m->cfg.sensor.sigma_c,
        .voxel_sigmas = m->cfg.voxel_sigmas,
        .max_groups_x = fusion__max_groups_x(m),
    };
    /* Empty retry queues and the frame's new-brick list; clear the locks. */
    gpu_cmd_fill(m->ctx, m->samples, 0, FUSION_QUEUE_ENTRIES * 4, 0);
    gpu_cmd_fill(m->ctx, m->new_list, 0, FUSION_LIST_HEADER * 4, 0);
    gpu_cmd_fill(m->ctx, m->locks, 0, GPU_WHOLE_SIZE, 0);
    /* Publishes the fills (and the frame's upload) to the first pass. */
    gpu_cmd_barrier(m->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    gpu_cmd_dispatch(m->ctx, m->p_alloc, m->b_alloc, &pc, gpu_groups(m->K.width, FUSION_ALLOC_LOCAL),
                     gpu_groups(m->K.height, FUSION_ALLOC_ROWS), 1);
    for (uint32_t p = 1; p <= alloc_retry_passes(m); p++) {
        pc.pass = p;
        /* The previous pass's queue writes -> the args pass reading the count. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_dispatch(m->ctx, m->p_alloc_args, m->b_alloc_args, &pc, 1, 1, 1);
        /* Group counts and cleared locks -> the indirect retry pass. */
        gpu_cmd_barrier(m->ctx, GPU_BARRIER_INDIRECT);
        uint32_t q_in = (p - 1) % 2;
        gpu_cmd_dispatch_indirect(m->ctx, m->p_alloc, m->b_alloc, &pc, m->samples, (4 * q_in + 1) * 4);
    }
}
