/* hostmap: the sign-bit map as the host holds it: every live brick with its
 * chunk, level, cell and bit planes, in plain memory. fusion fills one from
 * the GPU (fusion_snapshot_take); export, the tests and, later, the scene
 * store read it without Vulkan. Depends on core (and the brick layout in
 * shaders/fusion.glsl.h). */
#ifndef BF_HOSTMAP_H
#define BF_HOSTMAP_H

#include "core/core.h"

/* One brick. Voxel (x, y, z) has its centre at
 * origin_w + key * chunk_m + ((cell * 8 + (x, y, z)) + 0.5) * voxel_m(level),
 * its sign bit at sign[brick_word(x,y,z)] >> brick_bit(x,y,z) (1 = in
 * front of the surface), likewise its confidence bit. */
typedef struct hostmap_brick {
    int32_t key[3];      /* chunk coordinates */
    uint32_t level;
    uint32_t cell[3];    /* cell of the brick at its level inside the chunk, < 2^level */
    float error;         /* average sigma of the window that last set it [m] */
    uint32_t sign[16];
    uint32_t conf[16];
} hostmap_brick;

typedef struct hostmap {
    float chunk_m;
    bf_vec3 origin_w;      /* world point of the map's origin (chunk (0,0,0)'s corner) */
    uint32_t n_bricks;
    hostmap_brick *bricks; /* malloc'd */
    /* Colour of brick i's voxel (x, y, z) at rgb565[i * 512 + x + 8 y + 64 z]:
       RGB565, 0 = none (black is 0x0001). NULL: the map has no colour.
       malloc'd, freed by hostmap_free. */
    uint16_t *rgb565;
} hostmap;

/* The canonical brick order: chunk key (x, y, z), level, then cell (z, y,
 * x). The scene store's files, the map's digest (store_map_digest) and the
 * exported meshes list bricks in it, so two maps with the same bricks list
 * them alike whatever slots the GPU pools gave them (docs/determinism.md). */
int hostmap_brick_cmp(const hostmap_brick *a, const hostmap_brick *b);
/* Sorts m's bricks, their colours with them, into the canonical order.
 * BF_NO_MEMORY (for the colours' copy) leaves m as it was. */
bf_status hostmap_sort(hostmap *m);
/* Chunks holding at least one brick, of a map in the canonical order
 * (hostmap_sort: a chunk's bricks are together). */
uint32_t hostmap_count_chunks(const hostmap *m);
/* Frees the bricks and leaves an empty map. NULL is a no-op. */
void hostmap_free(hostmap *m);
/* Voxel edge of a level [m]. */
double hostmap_level_voxel_m(float chunk_m, uint32_t level);
/* World position of voxel (x, y, z) of brick b. */
bf_vec3 hostmap_voxel_center_w(const hostmap *m, const hostmap_brick *b, uint32_t x, uint32_t y, uint32_t z);

#endif
