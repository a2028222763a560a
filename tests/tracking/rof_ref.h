/* CPU oracle of the tracking module's ROF filter (shaders/track_rof.comp,
 * track_rof_primal.comp): the same float operations in the same order, and
 * the energies that show the iteration converges. A test oracle, not a
 * product path. Images are w x h, row-major, depth in metres (0 = outside
 * the mask); p holds 2 floats per pixel. */
#ifndef BF_TEST_ROF_REF_H
#define BF_TEST_ROF_REF_H

#include <stdint.h>

/* One dual iteration: p_out from p_in. */
void rof_ref_iterate(const float *f, uint32_t w, uint32_t h, float lambda0, float tau, const float *p_in, float *p_out);
/* u = f - div p / lambda on the mask (0 outside; f where u would be <= 0). */
void rof_ref_primal(const float *f, uint32_t w, uint32_t h, float lambda0, const float *p, float *u);
/* Primal ROF energy E(u) = sum |grad u| + sum lambda(f) / 2 (u - f)^2 on the
 * mask, in double. */
double rof_ref_energy(const float *f, const float *u, uint32_t w, uint32_t h, float lambda0);
/* Dual value D(p) = sum f div p - (div p)^2 / (2 lambda) on the mask: a
 * lower bound of min E (weak duality), reached at the optimum. */
double rof_ref_dual(const float *f, const float *p, uint32_t w, uint32_t h, float lambda0);

#endif
