/* A CPU oracle of the ray-caster (a test oracle, not a product path): walks
 * a hostmap in double precision by marching along each ray. */
#ifndef BF_RAYCAST_REF_H
#define BF_RAYCAST_REF_H

#include "fusion/fusion.h"
#include "render/render.h"

typedef struct raycast_ref raycast_ref;

/* Indexes the snapshot's bricks (borrowed: it must outlive the oracle). */
bf_status raycast_ref_create(const hostmap *snap, uint32_t max_level, raycast_ref **out);
void raycast_ref_destroy(raycast_ref *r);

/* Ray-casts like render_raycast: depth[width * height] (0: no hit) and
 * level[] (FUSION_NONE: no hit). */
void raycast_ref_run(const raycast_ref *r, const bf_intrinsics *K, const bf_se3 *T_wc, const render_options *opt,
                     float *depth, uint32_t *level);

#endif
