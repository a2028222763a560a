/* The ray-caster's host side: targets, pipelines, the map-relative camera
 * transform and the two passes (shaders/render_raycast.comp,
 * shaders/render_shade.comp; parameters in shaders/render.glsl.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "render_int.h"
#include "shaders/fusion.glsl.h"

struct render_caster {
    gpu_context *ctx;
    render_targets targets;
    gpu_pipeline *p_raycast, *p_shade;
    gpu_bindings *b_raycast, *b_shade;
    /* The map whose buffers are bound to b_raycast (fusion_gpu_view.id, 0:
     * none; rebound when another map comes). */
    uint64_t bound_map;
    gpu_buffer *bound_start; /* RENDER_RC_START: the start depths, or the dummy */
    gpu_buffer *bound_depth; /* RENDER_RC_DEPTH: the depth destination, targets.depth or render_options.depth_out */
    gpu_buffer *dummy;       /* 16 bytes bound when there are no start depths */
    double last_ms;
    uint32_t local_x, local_y; /* workgroup shape of both passes */
};

render_options render_options_tracking(void)
{
    return (render_options){.confident_only = false, .refine = true, .near_m = 0.2f, .far_m = 6.0f};
}

render_options render_options_display(void)
{
    return (render_options){.confident_only = true, .refine = true, .near_m = 0.2f, .far_m = 6.0f};
}

static bf_status target_create(gpu_context *ctx, const char *name, uint64_t bytes, gpu_buffer **out)
{
    gpu_buffer_desc d = {.name = name, .size_bytes = bytes, .memory = GPU_MEMORY_DEVICE,
                         .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
    return gpu_buffer_create(ctx, &d, out);
}

render_config render_config_default(void)
{
    return (render_config){.local_x = RENDER_LOCAL_X, .local_y = RENDER_LOCAL_Y};
}

bf_status render_create(gpu_context *ctx, const render_config *cfg, uint32_t width, uint32_t height,
                        render_caster **out)
{
    if (!ctx || !out || width == 0 || height == 0 || width > 16384 || height > 16384)
        return bf_fail(BF_INVALID_ARG, "render: image size %ux%u (1..16384 each)", width, height);
    /* The largest per-pixel target (the normals, 16 bytes) is one binding. */
    uint64_t range = gpu_device_limits(ctx)->max_storage_buffer_range, most = range / 16;
    if ((uint64_t)width * height > most) {
        double k = sqrt((double)most / ((double)width * height));
        return bf_fail(BF_INVALID_ARG, "render: a %ux%u image needs %llu bytes of normals, above this device's "
                       "%llu-byte storage binding: at most %llu pixels (%ux%u at this aspect)",
                       width, height, 16ull * width * height, (unsigned long long)range, (unsigned long long)most,
                       (uint32_t)(k * width), (uint32_t)(k * height));
    }
    render_config c = cfg ? *cfg : render_config_default();
    uint32_t wx = c.local_x, wy = c.local_y;
    if (wx < 1 || wy < 1 || wx * wy > 256 || wx * wy % 8)
        return bf_fail(BF_INVALID_ARG, "render: workgroup %ux%u (x * y a multiple of 8, at most 256)", wx, wy);
    render_caster *rc = calloc(1, sizeof *rc);
    if (!rc) return bf_fail(BF_NO_MEMORY, "render: caster");
    rc->ctx = ctx;
    rc->targets.width = width;
    rc->targets.height = height;
    uint64_t n = (uint64_t)width * height;
    rc->local_x = wx, rc->local_y = wy;
    bf_status s = target_create(ctx, "render.depth", 4 * n, &rc->targets.depth);
    if (s == BF_OK) s = target_create(ctx, "render.normal", 16 * n, &rc->targets.normal);
    if (s == BF_OK) s = target_create(ctx, "render.level", 4 * n, &rc->targets.level);
    if (s == BF_OK) s = target_create(ctx, "render.colour", 4 * n, &rc->targets.colour);
    if (s == BF_OK) s = target_create(ctx, "render.surface_rgb", 4 * n, &rc->targets.surface_rgb);
    gpu_pipeline_desc pr = {
        .name = "render.raycast",
        .spirv = bf_spv_render_raycast,
        .spirv_bytes = bf_spv_render_raycast_size,
        .n_buffers = RENDER_RC_BUFFERS,
        .push_bytes = sizeof(render_push),
        .local_size = {rc->local_x, rc->local_y, 1},
    };
    gpu_pipeline_desc ps = {
        .name = "render.shade",
        .spirv = bf_spv_render_shade,
        .spirv_bytes = bf_spv_render_shade_size,
        .n_buffers = 5,
        .push_bytes = sizeof(render_push),
        .local_size = {rc->local_x, rc->local_y, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pr, &rc->p_raycast);
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &ps, &rc->p_shade);
    if (s == BF_OK) s = target_create(ctx, "render.no_start", 16, &rc->dummy);
    if (s == BF_OK) s = gpu_buffer_zero(rc->dummy);
    if (s == BF_OK) s = gpu_bindings_create(ctx, RENDER_RC_BUFFERS, "render.raycast", &rc->b_raycast);
    if (s == BF_OK) s = gpu_bindings_set(rc->b_raycast, RENDER_RC_RGB, rc->targets.surface_rgb, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(rc->b_raycast, RENDER_RC_START, rc->dummy, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) rc->bound_start = rc->dummy;
    if (s == BF_OK) s = gpu_bindings_create(ctx, 5, "render.shade", &rc->b_shade);
    if (s == BF_OK) s = gpu_bindings_set(rc->b_raycast, RENDER_RC_DEPTH, rc->targets.depth, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) rc->bound_depth = rc->targets.depth;
    if (s == BF_OK) s = gpu_bindings_set(rc->b_raycast, RENDER_RC_LEVEL, rc->targets.level, 0, GPU_WHOLE_SIZE);
    gpu_buffer *shade[5] = {rc->targets.depth, rc->targets.level, rc->targets.normal, rc->targets.colour,
                            rc->targets.surface_rgb};
    for (uint32_t i = 0; i < 5 && s == BF_OK; i++) s = gpu_bindings_set(rc->b_shade, i, shade[i], 0, GPU_WHOLE_SIZE);
    /* Compile now (llvmpipe compiles on first use), not in the first frame. */
    if (s == BF_OK) s = gpu_pipeline_warm_up(ctx, (gpu_pipeline *[]){rc->p_raycast, rc->p_shade}, 2);
    if (s != BF_OK) {
        render_destroy(rc);
        return s;
    }
    *out = rc;
    return BF_OK;
}

void render_destroy(render_caster *rc)
{
    if (!rc) return;
    gpu_bindings_destroy(rc->b_shade);
    gpu_bindings_destroy(rc->b_raycast);
    gpu_pipeline_destroy(rc->p_shade);
    gpu_pipeline_destroy(rc->p_raycast);
    gpu_buffer_destroy(rc->dummy);
    gpu_buffer_destroy(rc->targets.colour);
    gpu_buffer_destroy(rc->targets.surface_rgb);
    gpu_buffer_destroy(rc->targets.level);
    gpu_buffer_destroy(rc->targets.normal);
    gpu_buffer_destroy(rc->targets.depth);
    memset(rc, 0xff, sizeof *rc); /* poison: a use after destroy fails loudly */
    free(rc);
}

/* Binds the map's buffers when another map's (or none) are bound. */
static bf_status bind_map(render_caster *rc, const fusion_gpu_view *v)
{
    if (rc->bound_map == v->id) return BF_OK;
    gpu_buffer *bufs[4] = {v->addresses, v->cmask, v->cpool, v->chead};
    uint32_t at[4] = {RENDER_RC_ADDR, RENDER_RC_CMASK, RENDER_RC_CPOOL, RENDER_RC_CHEAD};
    rc->bound_map = 0;
    bf_status s = BF_OK;
    for (uint32_t i = 0; i < 4 && s == BF_OK; i++) s = gpu_bindings_set(rc->b_raycast, at[i], bufs[i], 0, GPU_WHOLE_SIZE);
    if (s != BF_OK) return s;
    rc->bound_map = v->id;
    return BF_OK;
}

bf_status render_cmd_raycast(render_caster *rc, fusion_map *map, const bf_intrinsics *K, const bf_se3 *T_wc,
                             const render_options *opt)
{
    if (!rc || !map || !K || !T_wc || !opt) return bf_fail(BF_INVALID_ARG, "render: NULL argument");
    if (K->width != rc->targets.width || K->height != rc->targets.height)
        return bf_fail(BF_INVALID_ARG, "render: intrinsics are %ux%u, the caster's images %ux%u", K->width,
                       K->height, rc->targets.width, rc->targets.height);
    if (!(K->fx_px > 0) || !(fabs(K->fy_px) > 0) || !isfinite(K->fy_px) || !isfinite(K->cx_px) || !isfinite(K->cy_px))
        return bf_fail(BF_INVALID_ARG, "render: intrinsics fx %g fy %g cx %g cy %g", K->fx_px, K->fy_px, K->cx_px,
                       K->cy_px);
    if (!bf_se3_is_finite(T_wc)) return bf_fail(BF_INVALID_ARG, "render: camera pose is not finite");
    if (!(opt->near_m > 0) || !(opt->far_m > opt->near_m) || !isfinite(opt->far_m))
        return bf_fail(BF_INVALID_ARG, "render: depth range [%g, %g] m", opt->near_m, opt->far_m);
    uint64_t n_px = (uint64_t)K->width * K->height;
    if (opt->start_depth && (opt->start_offset > UINT32_MAX ||
                             gpu_buffer_size(opt->start_depth) < (opt->start_offset + n_px) * 4))
        return bf_fail(BF_INVALID_ARG, "render: start depths %s hold %llu bytes, %llu floats from %llu needed",
                       gpu_buffer_name(opt->start_depth), (unsigned long long)gpu_buffer_size(opt->start_depth),
                       (unsigned long long)n_px, (unsigned long long)opt->start_offset);
    if (opt->start_depth && !(opt->start_margin_m >= 0 && opt->start_margin_z2 >= 0))
        return bf_fail(BF_INVALID_ARG, "render: start margins %g m, %g / m must be >= 0", opt->start_margin_m,
                       opt->start_margin_z2);
    if (opt->depth_out && (!opt->no_shade || opt->depth_offset > UINT32_MAX ||
                           gpu_buffer_size(opt->depth_out) < (opt->depth_offset + n_px) * 4))
        return bf_fail(BF_INVALID_ARG, "render: depth destination %s (%llu bytes) for %llu floats from %llu%s",
                       gpu_buffer_name(opt->depth_out), (unsigned long long)gpu_buffer_size(opt->depth_out),
                       (unsigned long long)n_px, (unsigned long long)opt->depth_offset,
                       opt->no_shade ? "" : " needs no_shade");
    fusion_gpu_view v = fusion_gpu_view_get(map);
    bf_status s = bind_map(rc, &v);
    if (s != BF_OK) return s;
    gpu_buffer *start = opt->start_depth ? opt->start_depth : rc->dummy;
    if (start != rc->bound_start) {
        if ((s = gpu_bindings_set(rc->b_raycast, RENDER_RC_START, start, 0, GPU_WHOLE_SIZE)) != BF_OK) return s;
        rc->bound_start = start;
    }
    gpu_buffer *depth = opt->depth_out ? opt->depth_out : rc->targets.depth;
    if (depth != rc->bound_depth) {
        if ((s = gpu_bindings_set(rc->b_raycast, RENDER_RC_DEPTH, depth, 0, GPU_WHOLE_SIZE)) != BF_OK) return s;
        rc->bound_depth = depth;
    }

    render_push pc = {
        .flags = (opt->confident_only ? RENDER_FLAG_CONFIDENT_ONLY : 0u) | (opt->refine ? RENDER_FLAG_REFINE : 0u) |
                 (opt->start_depth ? RENDER_FLAG_START : 0u) | (!opt->no_shade && v.has_colour ? RENDER_FLAG_COLOUR : 0u) |
                 (opt->no_graze ? RENDER_FLAG_NO_GRAZE : 0u),
        .start_margin_m = opt->start_margin_m,
        .start_margin_z2 = opt->start_margin_z2,
        .start_off = (uint32_t)opt->start_offset,
        .depth_off = opt->depth_out ? (uint32_t)opt->depth_offset : 0u,
    };
    render__view_push(&pc.view, map, &v, K, T_wc, opt->near_m, opt->far_m, v.max_level);

    uint32_t gx = gpu_groups(K->width, rc->local_x), gy = gpu_groups(K->height, rc->local_y);
    /* The map's writes recorded before (fusion) and the earlier readers of
     * the images -> the ray-cast's reads of the map and writes of the images. */
    gpu_cmd_barrier(rc->ctx, GPU_BARRIER_COMPUTE);
    gpu_cmd_stage_begin(rc->ctx, "render.raycast");
    gpu_cmd_dispatch(rc->ctx, rc->p_raycast, rc->b_raycast, &pc, gx, gy, 1);
    if (!opt->no_shade) {
        /* The depth and level writes of the ray-cast -> the shading pass's reads. */
        gpu_cmd_barrier(rc->ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_dispatch(rc->ctx, rc->p_shade, rc->b_shade, &pc, gx, gy, 1);
    }
    gpu_cmd_stage_end(rc->ctx);
    /* The images -> the readers recorded next (the tracking reference). */
    gpu_cmd_barrier(rc->ctx, GPU_BARRIER_COMPUTE);
    return BF_OK;
}

void render__view_push(render_view_push *p, const fusion_map *map, const fusion_gpu_view *v, const bf_intrinsics *K,
                       const bf_se3 *T_wc, float near_m, float far_m, uint32_t max_level)
{
    bf_se3 T_mc = fusion_camera_to_map(map, T_wc);
    *p = (render_view_push){
        .fx = (float)K->fx_px,
        .fy = (float)K->fy_px,
        .cx = (float)K->cx_px,
        .cy = (float)K->cy_px,
        .width = K->width,
        .height = K->height,
        .near_m = near_m,
        .far_m = far_m,
        .chunk_m = v->chunk_m,
        .n_buckets = v->n_buckets,
        .n_overflow = v->n_entries - v->n_buckets * FUSION_BUCKET_SLOTS,
        .max_level = max_level,
    };
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) p->R[3 * r + c] = (float)T_mc.R[r][c];
    p->t[0] = (float)T_mc.t.x, p->t[1] = (float)T_mc.t.y, p->t[2] = (float)T_mc.t.z;
}

void render_finish_raycast(render_caster *rc) { rc->last_ms = gpu_stage_ms(rc->ctx, "render.raycast"); }

bf_status render_raycast(render_caster *rc, fusion_map *map, const bf_intrinsics *K, const bf_se3 *T_wc,
                         const render_options *opt)
{
    if (!rc) return bf_fail(BF_INVALID_ARG, "render: NULL argument");
    bf_status s = gpu_begin(rc->ctx);
    if (s != BF_OK) return s;
    s = render_cmd_raycast(rc, map, K, T_wc, opt);
    /* All four images -> host downloads (render_download) and later readers. */
    gpu_cmd_barrier(rc->ctx, GPU_BARRIER_HOST);
    bf_status sw = gpu_submit_wait(rc->ctx);
    if (s != BF_OK) return s;
    if (sw != BF_OK) return sw;
    render_finish_raycast(rc);
    return BF_OK;
}

const render_targets *render_get_targets(const render_caster *rc) { return &rc->targets; }

double render_last_ms(const render_caster *rc) { return rc->last_ms; }

bf_status render_download(render_caster *rc, render_images *out)
{
    uint64_t n = (uint64_t)rc->targets.width * rc->targets.height;
    render_images im = {.width = rc->targets.width, .height = rc->targets.height};
    im.depth = malloc(4 * n);
    im.normal = malloc(16 * n);
    im.level = malloc(4 * n);
    im.rgb = malloc(3 * n);
    uint32_t *colour = malloc(4 * n);
    bf_status s = (im.depth && im.normal && im.level && im.rgb && colour)
                      ? BF_OK
                      : bf_fail(BF_NO_MEMORY, "render: host images of %ux%u", im.width, im.height);
    if (s == BF_OK) s = gpu_buffer_download(rc->targets.depth, 0, im.depth, 4 * n);
    if (s == BF_OK) s = gpu_buffer_download(rc->targets.normal, 0, im.normal, 16 * n);
    if (s == BF_OK) s = gpu_buffer_download(rc->targets.level, 0, im.level, 4 * n);
    if (s == BF_OK) s = gpu_buffer_download(rc->targets.colour, 0, colour, 4 * n);
    for (uint64_t i = 0; s == BF_OK && i < n; i++) {
        im.rgb[3 * i + 0] = (uint8_t)(colour[i] & 255u);
        im.rgb[3 * i + 1] = (uint8_t)((colour[i] >> 8) & 255u);
        im.rgb[3 * i + 2] = (uint8_t)((colour[i] >> 16) & 255u);
    }
    free(colour);
    if (s != BF_OK) {
        render_images_free(&im);
        return s;
    }
    *out = im;
    return BF_OK;
}

void render_images_free(render_images *im)
{
    if (!im) return;
    free(im->depth);
    free(im->normal);
    free(im->level);
    free(im->rgb);
    memset(im, 0, sizeof *im);
}
