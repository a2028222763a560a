/* eval: what the synthetic-sequence files (synth.c, room.c, noise.c,
 * render.c) share and nobody else sees: the counter-based random numbers
 * and the procedural textures. */
#ifndef BF_SYNTH_INT_H
#define BF_SYNTH_INT_H

#include <math.h>

#include "synth.h"

/* ------------------------------------------------------------ random numbers
 * Counter-based: every random number is a hash of (seed, frame, pixel,
 * stream), so a pixel's noise does not depend on which thread renders it or
 * in which order (Salmon et al. 2011, "Parallel random numbers: as easy as
 * 1, 2, 3", use the same idea with stronger mixing). The mixer is the
 * SplitMix64 finaliser (Steele, Lea, Flood 2014). */

/* Streams: one per use of randomness in a pixel, so uses never share bits. */
enum {
    SYNTH_RNG_LATERAL = 1,  /* two Gaussians: lateral offset */
    SYNTH_RNG_AXIAL,        /* one Gaussian: axial noise */
    SYNTH_RNG_DISP_OFFSET,  /* per-pixel (frame-independent) disparity grid offset */
    SYNTH_RNG_EDGE,         /* dropping a pixel on a depth edge */
    SYNTH_RNG_COLOUR,       /* colour sensor noise */
    SYNTH_RNG_BOARD,        /* the checkerboard's poses (board.c) */
};

static inline uint64_t synth__mix64(uint64_t z)
{
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static inline uint64_t synth__rng_key(uint64_t seed, uint32_t frame, uint32_t pixel, uint32_t stream)
{
    uint64_t h = synth__mix64(seed);
    h = synth__mix64(h ^ (((uint64_t)frame << 32) | stream));
    return synth__mix64(h ^ pixel);
}

/* Uniform in [0, 1) from the top 53 bits. */
static inline double synth__u01(uint64_t h) { return (double)(h >> 11) * 0x1.0p-53; }

/* Two independent standard normal numbers from one key (Box-Muller). */
static inline void synth__gauss2(uint64_t key, double *g0, double *g1)
{
    double u1 = synth__u01(synth__mix64(key ^ 0x51ed270b27a3c1f5ull));
    double u2 = synth__u01(synth__mix64(key ^ 0x2545f4914f6cdd1dull));
    double r = sqrt(-2.0 * log(1.0 - u1)); /* 1 - u1 in (0, 1]: log is finite */
    *g0 = r * cos(2.0 * M_PI * u2);
    *g1 = r * sin(2.0 * M_PI * u2);
}

/* ------------------------------------------------------------ textures */

/* Albedo (linear, each channel in [0, 1]) of a surface of the given
 * material and variant at world point p: a pure function of its arguments,
 * defined in room.c. */
void synth__albedo(uint8_t material, uint8_t variant, bf_vec3 p_w, double rgb[3]);

#endif
