/* The local origin of an export (export.h, export_local_origin): where
 * floats would lose the map's precision, the vertices are stored relative
 * to a point near the map, kept in double. */
#include <math.h>

#include "export_int.h"

bf_vec3 export_local_origin(const hostmap *s)
{
    if (!s || s->n_bricks == 0 || !(s->chunk_m > 0)) return bf_v3(0, 0, 0);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double o[3] = {s->origin_w.x, s->origin_w.y, s->origin_w.z};
    for (uint32_t i = 0; i < s->n_bricks; i++) {
        const hostmap_brick *b = &s->bricks[i];
        double edge = hostmap_level_voxel_m(s->chunk_m, b->level) * 8;
        for (int a = 0; a < 3; a++) {
            double c = o[a] + (double)b->key[a] * s->chunk_m + b->cell[a] * edge;
            lo[a] = fmin(lo[a], c), hi[a] = fmax(hi[a], c + edge);
        }
    }
    double reach = 0;
    for (int a = 0; a < 3; a++) reach = fmax(reach, fmax(fabs(lo[a]), fabs(hi[a])));
    if (reach <= EXPORT_WORLD_FLOAT_M) return bf_v3(0, 0, 0);
    /* Whole metres: the recorded number reads plainly and is exact. */
    return bf_v3(round((lo[0] + hi[0]) / 2), round((lo[1] + hi[1]) / 2), round((lo[2] + hi[2]) / 2));
}
