/* Loading a host copy of a map (a reopened scene store) into an empty map:
 * the index structures are built on the host and uploaded once. The host
 * insertion is also the tests' brick inserter (tests/fusion/insert_ref.c). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fusion_int.h"

static bf_status host_alloc_nodes(const fusion_map *m, fusion_host_map *h, uint32_t n, uint32_t *first)
{
    uint32_t used = h->counters[FUSION_CNT_NODES];
    if (used + n > m->cfg.node_cap) return bf_fail(BF_POOL_FULL, "fusion: node pool full (%u nodes)", m->cfg.node_cap);
    h->counters[FUSION_CNT_NODES] = used + n;
    *first = used;
    return BF_OK;
}

/* A new chunk's hash entry (Niessner et al. 2013's buckets and overflow
 * list, as the allocation kernel inserts) and its root node. */
bf_status fusion__host_insert_chunk(const fusion_map *m, fusion_host_map *h, const int32_t key[3], uint32_t *entry)
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

bf_status fusion__host_insert(const fusion_map *m, fusion_host_map *h, const int32_t key[3], uint32_t level,
                              const uint32_t cell[3], uint32_t *slot)
{
    if (level > m->cfg.max_level || cell[0] >> level || cell[1] >> level || cell[2] >> level)
        return bf_fail(BF_INVALID_ARG, "fusion: cell (%u,%u,%u) outside level %u (max %u)", cell[0], cell[1], cell[2],
                       level, m->cfg.max_level);
    uint32_t entry = fusion_find_chunk(h->hash, key[0], key[1], key[2], m->cfg.hash_buckets, m->cfg.hash_overflow);
    bf_status s = entry == FUSION_NONE ? fusion__host_insert_chunk(m, h, key, &entry) : BF_OK;
    uint32_t node = s == BF_OK ? h->hash[(size_t)entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT] : 0;
    for (uint32_t l = 1; s == BF_OK && l <= level; l++) {
        uint32_t sh = level - l;
        uint32_t oct = fusion_octant(cell[0] >> sh, cell[1] >> sh, cell[2] >> sh);
        uint32_t *child = &h->nodes[(size_t)node * FUSION_NODE_WORDS + FUSION_NODE_CHILD];
        if (*child == FUSION_NONE) {
            uint32_t first = 0;
            if ((s = host_alloc_nodes(m, h, 8, &first)) != BF_OK) break;
            *child = first;
        }
        node = *child + oct;
    }
    if (s != BF_OK) return s;
    uint32_t *brick = &h->nodes[(size_t)node * FUSION_NODE_WORDS + FUSION_NODE_BRICK];
    if (*brick == FUSION_NONE) {
        uint32_t top = h->counters[FUSION_CNT_FREE_TOP];
        if (top == 0) return bf_fail(BF_POOL_FULL, "fusion: brick pool full (%u bricks)", m->cfg.brick_cap);
        uint32_t b = h->free_stack[top - 1];
        h->counters[FUSION_CNT_FREE_TOP] = top - 1;
        h->counters[FUSION_CNT_BRICKS]++;
        *brick = b;
        uint32_t *info = h->info + (size_t)b * FUSION_BRICK_INFO_WORDS;
        info[FUSION_INFO_CHUNK] = entry;
        info[FUSION_INFO_POS] = fusion_pack_pos(cell[0], cell[1], cell[2], level);
        info[FUSION_INFO_NODE] = node;
        float inf = INFINITY;
        memcpy(&info[FUSION_INFO_ERROR], &inf, 4);
    }
    *slot = *brick;
    return BF_OK;
}

bf_status fusion__host_map_store(fusion_map *m, const fusion_host_map *h)
{
    bf_status s = gpu_buffer_upload(m->hash, 0, h->hash, gpu_buffer_size(m->hash));
    if (s == BF_OK) s = gpu_buffer_upload(m->nodes, 0, h->nodes, gpu_buffer_size(m->nodes));
    if (s == BF_OK) s = gpu_buffer_upload(m->info, 0, h->info, gpu_buffer_size(m->info));
    if (s == BF_OK) s = gpu_buffer_upload(m->counters, 0, h->counters, gpu_buffer_size(m->counters));
    if (s == BF_OK) s = gpu_buffer_upload(m->free_stack, 0, h->free_stack, gpu_buffer_size(m->free_stack));
    return s;
}

/* The map's own index structures as h where the host can edit them in
 * place (gpu_buffer_map_cached: lavapipe, most UMA devices), so a load
 * copies none of them down and back up. */
static bool host_map_direct(fusion_map *m, fusion_host_map *h)
{
    *h = (fusion_host_map){gpu_buffer_map_cached(m->hash), gpu_buffer_map_cached(m->nodes),
                           gpu_buffer_map_cached(m->info), gpu_buffer_map_cached(m->counters),
                           gpu_buffer_map_cached(m->free_stack)};
    return h->hash && h->nodes && h->info && h->counters && h->free_stack;
}

static bf_status flush_direct(fusion_map *m)
{
    gpu_buffer *b[] = {m->hash, m->nodes, m->info, m->counters, m->free_stack, m->sign, m->conf};
    bf_status s = BF_OK;
    for (size_t i = 0; i < sizeof b / sizeof b[0] && s == BF_OK; i++) s = gpu_buffer_flush(b[i]);
    return s;
}

bf_status fusion_load(fusion_map *m, const hostmap *in)
{
    if (!m || !in || (in->n_bricks && !in->bricks)) return bf_fail(BF_INVALID_ARG, "fusion_load: NULL argument");
    if (m->n_frames > 0 || m->has_incoming || m->n_loaded)
        return bf_fail(BF_INVALID_ARG, "fusion: a map is loaded only into an empty map");
    if (in->chunk_m != m->cfg.chunk_m)
        return bf_fail(BF_INVALID_ARG, "fusion: the stored map has %g m chunks, this map %g m", in->chunk_m,
                       m->cfg.chunk_m);
    if (in->n_bricks > m->cfg.brick_cap)
        return bf_fail(BF_POOL_FULL, "fusion: %u bricks do not fit a pool of %u", in->n_bricks, m->cfg.brick_cap);
    bf_status s = fusion_set_origin(m, in->origin_w);
    if (s != BF_OK) return s;
    fusion_host_map h;
    /* In place where the host may edit the buffers (the bit planes are
     * only written, so any mapping takes them): no host copies, no
     * uploads. */
    bool direct = host_map_direct(m, &h);
    if (!direct && (s = fusion__host_map_load(m, &h)) != BF_OK) return s;
    /* The free stack hands out slot 0 first: n bricks fill slots [0, n). */
    size_t n = in->n_bricks;
    uint32_t *sign_pool = gpu_buffer_map(m->sign), *conf_pool = gpu_buffer_map(m->conf);
    bool pools_direct = direct && sign_pool && conf_pool;
    uint32_t *sign = pools_direct ? sign_pool : bf_calloc(n ? n : 1, BRICK_WORDS * 4);
    uint32_t *conf = pools_direct ? conf_pool : bf_calloc(n ? n : 1, BRICK_WORDS * 4);
    /* With colour: each brick's slot, for its colour after the geometry. */
    uint32_t *slots = in->rgb565 && m->cfg.keep_colour ? bf_malloc((n ? n : 1) * 4) : NULL;
    if (!sign || !conf || (in->rgb565 && m->cfg.keep_colour && !slots))
        s = bf_fail(BF_NO_MEMORY, "fusion: loading %zu bricks", n);
    uint32_t high = 0;
    for (size_t i = 0; s == BF_OK && i < n; i++) {
        const hostmap_brick *b = &in->bricks[i];
        uint32_t slot = 0, used = h.counters[FUSION_CNT_BRICKS];
        s = fusion__host_insert(m, &h, b->key, b->level, b->cell, &slot);
        if (s == BF_OK && h.counters[FUSION_CNT_BRICKS] == used)
            s = bf_fail(BF_INVALID_ARG, "fusion: brick %zu repeats chunk (%d,%d,%d) level %u cell (%u,%u,%u)", i,
                        b->key[0], b->key[1], b->key[2], b->level, b->cell[0], b->cell[1], b->cell[2]);
        if (s == BF_OK && slot >= n) s = bf_fail(BF_NUMERIC, "fusion: loading: slot %u beyond %zu", slot, n);
        if (s != BF_OK) break;
        memcpy(sign + (size_t)slot * BRICK_WORDS, b->sign, sizeof b->sign);
        memcpy(conf + (size_t)slot * BRICK_WORDS, b->conf, sizeof b->conf);
        memcpy(&h.info[(size_t)slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_ERROR], &b->error, 4);
        if (slots) slots[i] = slot;
        if (slot + 1 > high) high = slot + 1;
    }
    /* Loaded bricks keep no stamp (FUSION_NONE): no window holds them until
     * a frame touches them again. */
    if (s == BF_OK && direct) s = flush_direct(m);
    if (s == BF_OK && !direct) s = fusion__host_map_store(m, &h);
    if (s == BF_OK && high && !pools_direct) s = gpu_buffer_upload(m->sign, 0, sign, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && high && !pools_direct) s = gpu_buffer_upload(m->conf, 0, conf, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && slots) s = fusion__colour_load(m, in, slots);
    if (s == BF_OK) {
        m->n_loaded = (uint32_t)n;
        m->use.bricks = h.counters[FUSION_CNT_BRICKS];
        m->use.nodes = h.counters[FUSION_CNT_NODES];
        m->use.overflow = h.counters[FUSION_CNT_OVERFLOW];
    }
    if (!pools_direct) {
        free(sign);
        free(conf);
    }
    free(slots);
    if (!direct) fusion__host_map_free(&h);
    if (s != BF_OK) {
        /* Back to the empty map it was: nothing half-loaded is left. */
        bf_status r = fusion__reset(m, false);
        if (r != BF_OK) return r;
    }
    return s;
}
