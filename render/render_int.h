/* What render/'s ray-casting passes share on the host (internal to render/). */
#ifndef BF_RENDER_INT_H
#define BF_RENDER_INT_H

#include "render.h"
#include "shaders/render.glsl.h"

/* The view words of a pass's push constants for camera K at world pose
 * T_wc over map: the pose made map-relative (the GPU's floats stay small
 * however far the map is from the world origin, DESIGN.md section 10) and
 * the hash's size from v. */
void render__view_push(render_view_push *p, const fusion_map *map, const fusion_gpu_view *v, const bf_intrinsics *K,
                       const bf_se3 *T_wc, float near_m, float far_m, uint32_t max_level);

#endif
