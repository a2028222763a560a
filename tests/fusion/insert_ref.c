/* The host brick inserter (a test oracle): builds maps brick by brick
 * without the allocation kernel, editing a host copy of the map's index
 * structures and uploading it back. The chunk lookup is the shaders' own
 * (shaders/fusion_hash.glsl.h). */
#include <math.h>
#include <string.h>

#include "fusion_ref.h"

static bf_status host_alloc_nodes(const fusion_map *m, fusion_host_map *h, uint32_t n, uint32_t *first)
{
    uint32_t used = h->counters[FUSION_CNT_NODES];
    if (used + n > m->cfg.node_cap) return bf_fail(BF_POOL_FULL, "fusion: node pool full (%u nodes)", m->cfg.node_cap);
    h->counters[FUSION_CNT_NODES] = used + n;
    *first = used;
    return BF_OK;
}

static bf_status host_insert_chunk(fusion_map *m, fusion_host_map *h, const int32_t key[3], uint32_t *entry)
{
    uint32_t bucket = fusion_hash(key[0], key[1], key[2], m->cfg.hash_buckets), e = FUSION_NONE;
    for (uint32_t k = 0; k < FUSION_BUCKET_SLOTS && e == FUSION_NONE; k++)
        if (h->hash[(size_t)(bucket * FUSION_BUCKET_SLOTS + k) * FUSION_ENTRY_WORDS + FUSION_ENTRY_STATE] ==
            FUSION_ENTRY_FREE)
            e = bucket * FUSION_BUCKET_SLOTS + k;
    if (e == FUSION_NONE) { /* overflow: link from the bucket's last slot */
        uint32_t idx = h->counters[FUSION_CNT_OVERFLOW];
        if (idx >= m->cfg.hash_overflow) return bf_fail(BF_POOL_FULL, "fusion: chunk hash overflow full");
        h->counters[FUSION_CNT_OVERFLOW] = idx + 1;
        e = m->cfg.hash_buckets * FUSION_BUCKET_SLOTS + idx;
        uint32_t *link = h->hash + (size_t)(bucket * FUSION_BUCKET_SLOTS + FUSION_BUCKET_SLOTS - 1) * FUSION_ENTRY_WORDS +
                         FUSION_ENTRY_NEXT;
        while (*link != FUSION_NONE) link = h->hash + (size_t)*link * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT;
        *link = e;
    }
    uint32_t root = 0;
    bf_status s = host_alloc_nodes(m, h, 1, &root);
    if (s != BF_OK) return s;
    uint32_t *w = h->hash + (size_t)e * FUSION_ENTRY_WORDS;
    w[0] = (uint32_t)key[0], w[1] = (uint32_t)key[1], w[2] = (uint32_t)key[2];
    w[FUSION_ENTRY_ROOT] = root;
    w[FUSION_ENTRY_STATE] = FUSION_ENTRY_VALID;
    *entry = e;
    return BF_OK;
}

bf_status fusion_ref_insert_brick(fusion_map *m, const int32_t key[3], uint32_t level, const uint32_t cell[3],
                                 uint32_t *slot)
{
    if (level > m->cfg.max_level || cell[0] >> level || cell[1] >> level || cell[2] >> level)
        return bf_fail(BF_INVALID_ARG, "fusion: cell (%u,%u,%u) outside level %u", cell[0], cell[1], cell[2], level);
    fusion_host_map h;
    bf_status s = fusion__host_map_load(m, &h);
    if (s != BF_OK) return s;
    uint32_t entry = fusion_find_chunk(h.hash, key[0], key[1], key[2], m->cfg.hash_buckets, m->cfg.hash_overflow);
    if (entry == FUSION_NONE) s = host_insert_chunk(m, &h, key, &entry);
    uint32_t node = s == BF_OK ? h.hash[(size_t)entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT] : 0;
    for (uint32_t l = 1; s == BF_OK && l <= level; l++) {
        uint32_t sh = level - l;
        uint32_t oct = fusion_octant(cell[0] >> sh, cell[1] >> sh, cell[2] >> sh);
        uint32_t *child = &h.nodes[(size_t)node * FUSION_NODE_WORDS + FUSION_NODE_CHILD];
        if (*child == FUSION_NONE) {
            uint32_t first = 0;
            if ((s = host_alloc_nodes(m, &h, 8, &first)) != BF_OK) break;
            *child = first;
        }
        node = *child + oct;
    }
    uint32_t *brick = s == BF_OK ? &h.nodes[(size_t)node * FUSION_NODE_WORDS + FUSION_NODE_BRICK] : NULL;
    if (s == BF_OK && *brick == FUSION_NONE) {
        uint32_t top = h.counters[FUSION_CNT_FREE_TOP];
        if (top == 0) {
            s = bf_fail(BF_POOL_FULL, "fusion: brick pool full (%u bricks)", m->cfg.brick_cap);
        } else {
            uint32_t b = h.free_stack[top - 1];
            h.counters[FUSION_CNT_FREE_TOP] = top - 1;
            h.counters[FUSION_CNT_BRICKS]++;
            *brick = b;
            uint32_t *info = h.info + (size_t)b * FUSION_BRICK_INFO_WORDS;
            info[FUSION_INFO_CHUNK] = entry;
            info[FUSION_INFO_POS] = fusion_pack_pos(cell[0], cell[1], cell[2], level);
            info[FUSION_INFO_NODE] = node;
            float inf = INFINITY;
            memcpy(&info[FUSION_INFO_ERROR], &inf, 4);
        }
    }
    if (s == BF_OK) s = gpu_buffer_upload(m->hash, 0, h.hash, gpu_buffer_size(m->hash));
    if (s == BF_OK) s = gpu_buffer_upload(m->nodes, 0, h.nodes, gpu_buffer_size(m->nodes));
    if (s == BF_OK) s = gpu_buffer_upload(m->info, 0, h.info, gpu_buffer_size(m->info));
    if (s == BF_OK) s = gpu_buffer_upload(m->counters, 0, h.counters, gpu_buffer_size(m->counters));
    if (s == BF_OK) *slot = *brick;
    fusion__host_map_free(&h);
    return s;
}

