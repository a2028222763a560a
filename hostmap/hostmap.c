/* hostmap: the host copy of the map (hostmap.h). */
#include "hostmap.h"

#include <stdlib.h>

#include "shaders/fusion.glsl.h"

_Static_assert(sizeof(((hostmap_brick *)0)->sign) == BRICK_WORDS * 4, "a brick's bit plane is BRICK_WORDS words");

void hostmap_free(hostmap *m)
{
    if (!m) return;
    free(m->bricks);
    free(m->rgb565);
    m->bricks = NULL;
    m->rgb565 = NULL;
    m->n_bricks = 0;
}

double hostmap_level_voxel_m(float chunk_m, uint32_t level) { return (double)fusion_voxel_m(chunk_m, level); }

bf_vec3 hostmap_voxel_center_w(const hostmap *m, const hostmap_brick *b, uint32_t x, uint32_t y, uint32_t z)
{
    double v = hostmap_level_voxel_m(m->chunk_m, b->level);
    uint32_t xyz[3] = {x, y, z};
    double p[3];
    for (int i = 0; i < 3; i++)
        p[i] = (double)b->key[i] * m->chunk_m + ((double)(b->cell[i] * 8 + xyz[i]) + 0.5) * v;
    return bf_v3(m->origin_w.x + p[0], m->origin_w.y + p[1], m->origin_w.z + p[2]);
}
