/* Test oracle of the particle renderer: the exact spheres, brute force on
 * the CPU in double (render/particles.c bins them to cells; this does not). */
#ifndef BF_PARTICLES_REF_H
#define BF_PARTICLES_REF_H

#include "core/core.h"

/* Camera depth of the nearest sphere (centre xyz[3i..], radius_m) on each
 * pixel's ray (the ray-caster's rays: through the pixel centre's (u, v),
 * depth = camera z), within [near_m, far_m); 0 where none. depth holds
 * K->width * K->height floats. Each sphere is tested against the pixels of
 * its projected box only, which holds every pixel whose ray it meets. */
void particles_ref_cast(const float *xyz, uint64_t n, double radius_m, const bf_intrinsics *K, const bf_se3 *T_wc,
                        double near_m, double far_m, float *depth);

#endif
