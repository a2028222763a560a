/* Depth conversion, pyramids, normal maps, and the ROF
 * smoothing of the reference: host side of shaders/track_depth.comp,
 * track_pyrdown.comp, track_vn.comp, track_rof.comp and
 * track_rof_primal.comp (one binding layout, shaders/track.glsl.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "tracking_int.h"

static bf_status image_pipeline(track_tracker *t, const char *name, const uint32_t *spirv, size_t bytes,
                                uint32_t tile, gpu_pipeline **out)
{
    gpu_pipeline_desc d = {
        .name = name,
        .spirv = spirv,
        .spirv_bytes = bytes,
        .n_buffers = TRACK_IMAGE_BUFFERS,
        .push_bytes = sizeof(track_image_push),
        .local_size = {tile, tile, 1},
    };
    return gpu_pipeline_create(t->ctx, &d, out);
}

static bf_status image_bindings(track_tracker *t, const char *name, gpu_buffer *raw, gpu_bindings **out)
{
    bf_status s = gpu_bindings_create(t->ctx, TRACK_IMAGE_BUFFERS, name, out);
    gpu_buffer *bufs[TRACK_IMAGE_BUFFERS] = {raw, t->counters};
    for (uint32_t i = 0; i < TRACK_IMAGE_BUFFERS && s == BF_OK; i++) s = gpu_bindings_set(*out, i, bufs[i], 0, GPU_WHOLE_SIZE);
    return s;
}

static track_image_set image_set(track_tracker *t, gpu_bindings *b, bool is_ref, uint32_t p_in)
{
    return (track_image_set){
        .b = b,
        .depth = gpu_buffer_address(is_ref ? t->ref_depth : t->frame_depth),
        .normal = gpu_buffer_address(is_ref ? t->ref_normal : t->frame_normal),
        .p_in = gpu_buffer_address(t->rof_p[p_in]),
        .p_out = gpu_buffer_address(t->rof_p[1 - p_in]),
    };
}

bf_status track__pyramid_create(track_tracker *t)
{
    /* track_depth.comp counts valid pixels with subgroup additions. */
    uint32_t need = VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_ARITHMETIC_BIT;
    if ((gpu_device_limits(t->ctx)->subgroup_ops & need) != need)
        return bf_fail(BF_UNSUPPORTED, "tracking: the device lacks subgroup arithmetic in compute shaders");
    bf_status s;
    if ((s = image_pipeline(t, "track.depth", bf_spv_track_depth, bf_spv_track_depth_size, TRACK_IMAGE_TILE,
                            &t->p_depth)) != BF_OK)
        return s;
    if ((s = image_pipeline(t, "track.pyrdown", bf_spv_track_pyrdown, bf_spv_track_pyrdown_size, TRACK_IMAGE_TILE,
                            &t->p_pyrdown)) != BF_OK)
        return s;
    if ((s = image_pipeline(t, "track.smooth", bf_spv_track_smooth, bf_spv_track_smooth_size, TRACK_IMAGE_TILE,
                            &t->p_smooth)) != BF_OK)
        return s;
    if ((s = image_pipeline(t, "track.vn", bf_spv_track_vn, bf_spv_track_vn_size, TRACK_IMAGE_TILE,
                            &t->p_vn)) != BF_OK)
        return s;
    if ((s = image_pipeline(t, "track.rof", bf_spv_track_rof, bf_spv_track_rof_size, TRACK_IMAGE_TILE,
                            &t->p_rof)) != BF_OK)
        return s;
    if ((s = image_pipeline(t, "track.rof_primal", bf_spv_track_rof_primal, bf_spv_track_rof_primal_size,
                            TRACK_IMAGE_TILE, &t->p_primal)) != BF_OK)
        return s;
    gpu_pipeline_desc di = {
        .name = "track.intensity",
        .spirv = bf_spv_track_intensity,
        .spirv_bytes = bf_spv_track_intensity_size,
        .n_buffers = TRACK_INTENSITY_BUFFERS,
        .push_bytes = sizeof(track_intensity_push),
        .local_size = {TRACK_IMAGE_TILE, TRACK_IMAGE_TILE, 1},
    };
    if ((s = gpu_pipeline_create(t->ctx, &di, &t->p_int)) != BF_OK) return s;
    if ((s = gpu_bindings_create(t->ctx, TRACK_INTENSITY_BUFFERS, "track.intensity", &t->b_int)) != BF_OK) return s;
    /* Binding 0 is the frames' colour (track_set_frame_colour), bound per frame. */
    gpu_buffer *ib[TRACK_INTENSITY_BUFFERS] = {t->upload, t->frame_depth, t->frame_int};
    for (uint32_t i = 0; i < TRACK_INTENSITY_BUFFERS && s == BF_OK; i++)
        s = gpu_bindings_set(t->b_int, i, ib[i], 0, GPU_WHOLE_SIZE);
    if (s != BF_OK) return s;
    if ((s = image_bindings(t, "track.frame", t->upload, &t->b_frame)) != BF_OK) return s;
    if ((s = image_bindings(t, "track.ref", t->upload, &t->b_ref)) != BF_OK) return s;
    t->frame_raw_off = 0;
    t->frame_set = image_set(t, t->b_frame, false, 0);
    for (uint32_t k = 0; k < 2; k++) t->ref_set[k] = image_set(t, t->b_ref, true, k);
    /* Zero push constants: every kernel sees a 0 x 0 image and returns. */
    gpu_pipeline *all[] = {t->p_depth, t->p_pyrdown, t->p_smooth, t->p_vn, t->p_rof, t->p_primal, t->p_int};
    return gpu_pipeline_warm_up(t->ctx, all, 7);
}

void track__pyramid_destroy(track_tracker *t)
{
    gpu_bindings_destroy(t->b_ref);
    t->b_ref = NULL;
    gpu_bindings_destroy(t->b_frame);
    gpu_bindings_destroy(t->b_int);
    gpu_pipeline_destroy(t->p_int);
    t->b_int = NULL;
    t->p_int = NULL;
    gpu_pipeline_destroy(t->p_primal);
    gpu_pipeline_destroy(t->p_rof);
    gpu_pipeline_destroy(t->p_vn);
    gpu_pipeline_destroy(t->p_smooth);
    gpu_pipeline_destroy(t->p_pyrdown);
    gpu_pipeline_destroy(t->p_depth);
    t->b_frame = NULL;
    t->p_primal = t->p_rof = t->p_vn = t->p_smooth = t->p_pyrdown = t->p_depth = NULL;
}

bf_status track__upload_depth(track_tracker *t, const uint16_t *depth)
{
    uint8_t *up = gpu_buffer_map(t->upload);
    if (!up) return bf_fail(BF_VULKAN, "tracking: upload buffer is not mapped");
    size_t n = (size_t)t->K.width * t->K.height;
    memcpy(up, depth, n * 2);
    return gpu_buffer_flush(t->upload);
}

static track_image_push base_push(const track_tracker *t, uint32_t l)
{
    track_image_push pc = {
        .width = t->geom.w[l],
        .height = t->geom.h[l],
        .dst_off = t->geom.off[l],
        .unit_m = (float)(1.0 / t->K.depth_scale),
        .max_depth_m = t->cfg.sensor.max_depth_m,
        .sigma_a = t->cfg.sensor.sigma_a,
        .sigma_b = t->cfg.sensor.sigma_b,
        .sigma_c = t->cfg.sensor.sigma_c,
        .lambda0 = t->cfg.rof_lambda0,
        .tau = 0.25f, /* Chambolle 2004: converges in practice up to 1/4 */
    };
    track__level_intrinsics(&t->K, l, &pc.fx, &pc.fy, &pc.cx, &pc.cy);
    return pc;
}

void track__stage_begin(track_tracker *t, const char *name)
{
    if (!t->cfg.profile) gpu_cmd_stage_begin(t->ctx, name);
}
void track__stage_end(track_tracker *t)
{
    if (!t->cfg.profile) gpu_cmd_stage_end(t->ctx);
}
void track__profile_print(track_tracker *t, const char *what)
{
    if (!t->cfg.profile) return;
    const gpu_stage_time *st;
    uint32_t n = gpu_stage_times(t->ctx, &st);
    fprintf(stderr, "track profile %s:", what);
    for (uint32_t i = 0; i < n; i++) fprintf(stderr, " %s %.2f", st[i].name, st[i].ms);
    fprintf(stderr, "\n");
}

static void pstage_begin(track_tracker *t, const gpu_pipeline *p, const track_image_push *pc)
{
    if (!t->cfg.profile) return;
    char name[GPU_STAGE_NAME_MAX];
    const char *k = p == t->p_depth     ? "depth"
                    : p == t->p_pyrdown ? "pyr"
                    : p == t->p_smooth  ? "smooth"
                    : p == t->p_vn      ? "vn"
                    : p == t->p_rof     ? "rof"
                                        : "primal";
    snprintf(name, sizeof name, "%s%ux%u", k, pc->width, pc->height);
    gpu_cmd_stage_begin(t->ctx, name);
}

/* The image set's addresses into the push constants. */
static track_image_push with_set(const track_image_push *pc, const track_image_set *set)
{
    track_image_push q = *pc;
    q.depth_lo = (uint32_t)set->depth, q.depth_hi = (uint32_t)(set->depth >> 32);
    q.normal_lo = (uint32_t)set->normal, q.normal_hi = (uint32_t)(set->normal >> 32);
    q.p_in_lo = (uint32_t)set->p_in, q.p_in_hi = (uint32_t)(set->p_in >> 32);
    q.p_out_lo = (uint32_t)set->p_out, q.p_out_hi = (uint32_t)(set->p_out >> 32);
    return q;
}

/* The image kernels run on 2D tiles (no integer division for x, y) and take
 * TRACK_IMAGE_PX pixels per invocation. */
static void dispatch(track_tracker *t, gpu_pipeline *p, const track_image_set *set, const track_image_push *pc)
{
    track_image_push q = with_set(pc, set);
    pstage_begin(t, p, pc);
    gpu_cmd_dispatch(t->ctx, p, set->b, &q, gpu_groups(pc->width, TRACK_IMAGE_TILE * TRACK_IMAGE_PX),
                     gpu_groups(pc->height, TRACK_IMAGE_TILE), 1);
    if (t->cfg.profile) gpu_cmd_stage_end(t->ctx);
}

/* Depth of level 0 from the raw input, levels above, then the normal maps
 * of every level, in image set b. */
static void cmd_depth(track_tracker *t, const track_image_set *b, uint32_t level, uint32_t mode, uint32_t counter,
                      uint32_t raw_off)
{
    track_image_push pc = base_push(t, level);
    pc.mode = mode;
    pc.counter = counter;
    pc.raw_off = raw_off;
    dispatch(t, t->p_depth, b, &pc);
}

/* Depth levels first_down.. from the ones below, then the normals of every
 * level from `first` (the image's finest) up. */
static void cmd_pyramid(track_tracker *t, const track_image_set *b, uint32_t first, uint32_t first_down)
{
    for (uint32_t l = first_down; l < TRACK_LEVELS; l++) {
        /* Level l - 1's depth writes -> level l's block reads. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        track_image_push pc = base_push(t, l);
        pc.src_off = t->geom.off[l - 1];
        pc.src_width = t->geom.w[l - 1];
        dispatch(t, t->p_pyrdown, b, &pc);
    }
    bool copy_parent = t->cfg.parent_normals && first == 0;
    uint32_t l0 = copy_parent ? 1u : first;
    for (uint32_t pass = 0; pass < 2; pass++) {
        /* The depth pyramid's (pass 0) or the horizontal pass's (pass 1)
         * writes -> this pass's reads. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        for (uint32_t l = l0; l < TRACK_LEVELS; l++) {
            track_image_push pc = base_push(t, l);
            pc.mode = pass;
            dispatch(t, t->p_smooth, b, &pc);
        }
    }
    /* The smoothed depth's writes -> the normal maps' reads. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
    for (uint32_t l = l0; l < TRACK_LEVELS; l++) {
        track_image_push pc = base_push(t, l);
        dispatch(t, t->p_vn, b, &pc);
    }
    if (copy_parent) {
        /* Level 1's normals -> the finest level's copy of them. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        track_image_push pc = base_push(t, 0);
        pc.mode = 1;
        pc.src_off = t->geom.off[1];
        pc.src_width = t->geom.w[1];
        dispatch(t, t->p_vn, b, &pc);
    }
    /* Normal writes -> ICP's reads (and the host's downloads). */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
}

void track__cmd_frame_pyramid(track_tracker *t)
{
    track__stage_begin(t, "track.frame");
    cmd_depth(t, &t->frame_set, 0, TRACK_RAW_U16, TRACK_CNT_FRAME_VALID, t->frame_raw_off);
    cmd_pyramid(t, &t->frame_set, 0, 1);
    t->frame_has_int = t->colour && t->cfg.photo_weight > 0;
    if (t->frame_has_int) track__cmd_frame_intensity(t);
    track__stage_end(t);
}

/* The intensity levels the term reads: photo_levels, or the finest alone
 * where the finest level decides (photo_weak_ratio). */
uint32_t track__int_levels(const track_tracker *t)
{
    uint32_t n = t->cfg.photo_weak_ratio > 0 ? 1 : t->cfg.photo_levels;
    return n < TRACK_LEVELS ? n : TRACK_LEVELS;
}

void track__cmd_frame_intensity(track_tracker *t)
{
    track_intensity_push pc = {
        .mode = t->colour_registered ? TRACK_INT_REGISTERED : TRACK_INT_CAMERA,
        .raw_off = t->colour_off,
        .width = t->geom.w[0],
        .height = t->geom.h[0],
        .cfx = (float)t->Kc.fx_px,
        .cfy = (float)t->Kc.fy_px,
        .ccx = (float)t->Kc.cx_px,
        .ccy = (float)t->Kc.cy_px,
    };
    track__level_intrinsics(&t->K, 0, &pc.fx, &pc.fy, &pc.cx, &pc.cy);
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) pc.R[3 * i + j] = (float)t->T_colour_depth.R[i][j];
        pc.dist[i] = (float)t->colour_dist[i];
    }
    pc.dist[3] = (float)t->colour_dist[3], pc.dist[4] = (float)t->colour_dist[4];
    pc.t[0] = (float)t->T_colour_depth.t.x, pc.t[1] = (float)t->T_colour_depth.t.y, pc.t[2] = (float)t->T_colour_depth.t.z;
    /* The depth pyramid's last barrier made level 0's depth readable. */
    gpu_cmd_dispatch(t->ctx, t->p_int, t->b_int, &pc, gpu_groups(pc.width, TRACK_IMAGE_TILE * TRACK_IMAGE_PX),
                     gpu_groups(pc.height, TRACK_IMAGE_TILE), 1);
    for (uint32_t l = 1; l < track__int_levels(t); l++) {
        /* Level l - 1's writes -> level l's block reads. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        pc.mode = TRACK_INT_DOWN;
        pc.width = t->geom.w[l], pc.height = t->geom.h[l];
        pc.src_off = t->geom.off[l - 1], pc.dst_off = t->geom.off[l], pc.src_width = t->geom.w[l - 1];
        gpu_cmd_dispatch(t->ctx, t->p_int, t->b_int, &pc, gpu_groups(pc.width, TRACK_IMAGE_TILE * TRACK_IMAGE_PX),
                         gpu_groups(pc.height, TRACK_IMAGE_TILE), 1);
    }
    /* The intensity -> ICP's reads. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
}

void track__cmd_reference(track_tracker *t, bool in_place)
{
    const track_image_set *b = t->ref_set;
    uint32_t n_it = t->cfg.rof_iterations;
    /* The image comes in at level l0 (a GPU reference at ref_level, a raw
     * frame at full resolution). The ROF runs on level rl >= l0; levels
     * between keep the unsmoothed depth. */
    uint32_t l0 = in_place ? t->cfg.ref_level : 0;
    uint32_t rl = n_it > 0 && t->cfg.rof_level > l0 ? t->cfg.rof_level : l0;
    track__stage_begin(t, "track.ref");
    /* The previous frame's ICP and pyramid passes read the dual field's
     * buffer (scratch) -> the fills. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_fill(t->ctx, t->rof_p[0], 0, GPU_WHOLE_SIZE, 0);
    gpu_cmd_fill(t->ctx, t->counters, TRACK_CNT_REF_VALID * 4u, 4, 0);
    /* The zero dual field and count -> the depth pass and the first ROF
     * iteration. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    cmd_depth(t, &b[0], l0, in_place ? TRACK_RAW_IN_PLACE : TRACK_RAW_U16, TRACK_CNT_REF_VALID, 0);
    for (uint32_t l = l0 + 1; l <= rl; l++) {
        /* Level l - 1's depth writes -> level l's block reads. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        track_image_push pc = base_push(t, l);
        pc.src_off = t->geom.off[l - 1];
        pc.src_width = t->geom.w[l - 1];
        dispatch(t, t->p_pyrdown, &b[0], &pc);
    }
    track__stage_end(t);

    track__stage_begin(t, "track.rof");
    track_image_push pc = base_push(t, rl);
    /* The same metric smoothing at every level: a detail of size rho at
     * depth z spans rho f_l / z pixels with f_l = f / 2^l, and ROF
     * flattens contrasts below 2 / (lambda r), so lambda scales by 2^l. */
    pc.lambda0 = t->cfg.rof_lambda0 * (float)(1u << rl);
    for (uint32_t it = 0; it < n_it; it++) {
        /* The depth (first) or the previous iteration's dual writes -> this
         * iteration's reads. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        dispatch(t, t->p_rof, &b[it & 1u], &pc);
    }
    if (n_it > 0) {
        /* The last dual field -> the primal solution reading it. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE);
        dispatch(t, t->p_primal, &b[n_it & 1u], &pc);
    }
    track__stage_end(t);

    track__stage_begin(t, "track.ref");
    cmd_pyramid(t, &b[0], l0, rl + 1);
    track__stage_end(t);
}
