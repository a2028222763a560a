/* The host brick inserter (a test oracle): builds maps brick by brick
 * without the allocation kernel, editing a host copy of the map's index
 * structures (fusion's own host insertion, fusion/load.c) and uploading it
 * back. The chunk lookup is the shaders' own (shaders/fusion_hash.glsl.h). */
#include <string.h>

#include "fusion_ref.h"

bf_status fusion_ref_insert_brick(fusion_map *m, const int32_t key[3], uint32_t level, const uint32_t cell[3],
                                 uint32_t *slot)
{
    fusion_host_map h;
    bf_status s = fusion__host_map_load(m, &h);
    if (s != BF_OK) return s;
    uint32_t b = 0;
    s = fusion__host_insert(m, &h, key, level, cell, &b);
    if (s == BF_OK) s = fusion__host_map_store(m, &h);
    if (s == BF_OK) *slot = b;
    fusion__host_map_free(&h);
    return s;
}
