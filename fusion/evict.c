/* Chunks out of the GPU pools and back (DESIGN.md section 1, "stream"):
 * eviction moves whole chunks into a host copy and frees their bricks,
 * nodes and hash entries; insertion puts host bricks back. Both run on the
 * host between frames on a full host copy of the index structures, which
 * is rebuilt compactly (the node pool and the hash's overflow list are bump
 * allocators, so only a rebuild gives their space back). Brick slots of the
 * chunks that stay do not move, so the window's work lists and the stamps
 * stay valid. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fusion_int.h"

/* What eviction and insertion edit: the index structures, the stamps and
 * the bit planes of slots [0, high). */
typedef struct host_all {
    fusion_host_map h;
    uint32_t *stamp;
    uint32_t *sign, *conf; /* slots [0, cap) allocated, [0, high) downloaded */
    uint32_t *cmask;       /* colour masks of slots [0, planes) (NULL without colour) */
    uint32_t *chead;       /* colour heads of slots [0, planes) */
    uint32_t *cfree;       /* the colour free stack, whole */
    fusion__colour_host units; /* colour units, edited and uploaded back */
    uint32_t high;         /* one past the highest live slot at load */
    uint32_t planes;       /* slots of sign and conf held: high, or more for an insertion */
} host_all;

static void host_all_free(host_all *a)
{
    fusion__host_map_free(&a->h);
    free(a->stamp);
    free(a->sign);
    free(a->conf);
    free(a->cmask);
    free(a->chead);
    free(a->cfree);
    fusion__colour_host_free(&a->units);
    memset(a, 0, sizeof *a);
}

/* extra: bricks about to be inserted. They take the free stack's top
 * `extra` slots, so the bit planes cover those as well as the live ones. */
static bf_status host_all_load(fusion_map *m, host_all *a, uint32_t extra)
{
    memset(a, 0, sizeof *a);
    uint32_t cap = m->cfg.brick_cap;
    bf_status s = fusion__host_map_load(m, &a->h);
    a->stamp = bf_malloc((size_t)cap * 4);
    if (s == BF_OK && !a->stamp) s = bf_fail(BF_NO_MEMORY, "fusion: host copy for streaming");
    if (s == BF_OK) s = gpu_buffer_download(m->stamp, 0, a->stamp, (uint64_t)cap * 4);
    for (uint32_t b = 0; s == BF_OK && b < cap; b++)
        if (a->h.info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] < m->n_entries) a->high = b + 1;
    size_t planes = a->high;
    uint32_t top = s == BF_OK ? a->h.counters[FUSION_CNT_FREE_TOP] : 0;
    for (uint32_t i = 0; s == BF_OK && i < extra && i < top; i++)
        if ((size_t)a->h.free_stack[top - 1 - i] + 1 > planes) planes = (size_t)a->h.free_stack[top - 1 - i] + 1;
    if (planes > cap) planes = cap;
    a->planes = (uint32_t)planes;
    if (s == BF_OK) {
        a->sign = bf_calloc(planes ? planes : 1, BRICK_WORDS * 4);
        a->conf = bf_calloc(planes ? planes : 1, BRICK_WORDS * 4);
        if (!a->sign || !a->conf) s = bf_fail(BF_NO_MEMORY, "fusion: host copy of %zu bricks", planes);
    }
    if (s == BF_OK && a->high) s = gpu_buffer_download(m->sign, 0, a->sign, (uint64_t)a->high * BRICK_WORDS * 4);
    if (s == BF_OK && a->high) s = gpu_buffer_download(m->conf, 0, a->conf, (uint64_t)a->high * BRICK_WORDS * 4);
    if (s == BF_OK && m->cfg.keep_colour) {
        /* A slot that leaves gives its colour units back; slots above high
         * have none, as every free slot. */
        a->cmask = bf_calloc(planes ? planes : 1, BRICK_WORDS * 4);
        a->chead = bf_malloc((planes ? planes : 1) * 4);
        a->cfree = bf_malloc((size_t)m->cfg.colour_unit_cap * 4);
        if (!a->cmask || !a->chead || !a->cfree) s = bf_fail(BF_NO_MEMORY, "fusion: host copy of the colour masks");
        for (size_t i = 0; s == BF_OK && i < planes; i++) a->chead[i] = FUSION_NONE;
        if (s == BF_OK && a->high) s = gpu_buffer_download(m->cmask, 0, a->cmask, (uint64_t)a->high * BRICK_WORDS * 4);
        if (s == BF_OK && a->high) s = gpu_buffer_download(m->chead, 0, a->chead, (uint64_t)a->high * 4);
        if (s == BF_OK) s = gpu_buffer_download(m->cfree, 0, a->cfree, (uint64_t)m->cfg.colour_unit_cap * 4);
    }
    if (s != BF_OK) host_all_free(a);
    return s;
}

/* Writes colours c[512] into slot b where the slot has none (a brick the
 * map made anew keeps its own); a brick that finds the free stack dry
 * keeps what it had (counted). */
static bf_status slot_colour_fill(fusion_map *m, host_all *a, uint32_t b, const uint16_t *c)
{
    return fusion__colour_fill(m, &a->units, a->cmask + (size_t)b * BRICK_WORDS, &a->chead[b], c, a->cfree,
                               &a->h.counters[FUSION_CNT_COLOUR_TOP], &a->h.counters[FUSION_CNT_FAIL_COLOUR]);
}

/* Uploads what host_all_load read, the bit planes up to max(high, the
 * highest slot now live). */
static bf_status host_all_store(fusion_map *m, const host_all *a, uint32_t high)
{
    m->only_loaded = false; /* slots and nodes anywhere now: fusion_clear resets all */
    m->use.bricks = a->h.counters[FUSION_CNT_BRICKS];
    m->use.nodes = a->h.counters[FUSION_CNT_NODES];
    m->use.overflow = a->h.counters[FUSION_CNT_OVERFLOW];
    bf_status s = fusion__host_map_store(m, &a->h);
    if (s == BF_OK) s = gpu_buffer_upload(m->stamp, 0, a->stamp, (uint64_t)m->cfg.brick_cap * 4);
    if (s == BF_OK && high) s = gpu_buffer_upload(m->sign, 0, a->sign, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && high) s = gpu_buffer_upload(m->conf, 0, a->conf, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && a->cmask && high) s = gpu_buffer_upload(m->cmask, 0, a->cmask, (uint64_t)high * BRICK_WORDS * 4);
    if (s == BF_OK && a->chead && high) s = gpu_buffer_upload(m->chead, 0, a->chead, (uint64_t)high * 4);
    if (s == BF_OK && a->cfree) s = gpu_buffer_upload(m->cfree, 0, a->cfree, (uint64_t)m->cfg.colour_unit_cap * 4);
    if (s == BF_OK && a->units.n)
        s = gpu_buffer_upload(m->cpool, 0, a->units.units, (uint64_t)a->units.n * FUSION_COLOUR_UNIT_WORDS * 4);
    return s;
}

fusion_pool_use fusion_pool_usage(const fusion_map *m)
{
    fusion_pool_use u = m->use;
    u.brick_cap = m->cfg.brick_cap;
    u.node_cap = m->cfg.node_cap;
    u.overflow_cap = m->cfg.hash_overflow;
    return u;
}

bf_status fusion_chunk_keys(fusion_map *m, int32_t (**keys)[3], uint32_t *n)
{
    if (!m || !keys || !n) return bf_fail(BF_INVALID_ARG, "fusion_chunk_keys: NULL argument");
    size_t words = (size_t)m->n_entries * FUSION_ENTRY_WORDS;
    uint32_t *hash = bf_malloc(words * 4);
    if (!hash) return bf_fail(BF_NO_MEMORY, "fusion: chunk list");
    bf_status s = gpu_buffer_download(m->hash, 0, hash, words * 4);
    uint32_t count = 0;
    for (uint32_t e = 0; s == BF_OK && e < m->n_entries; e++)
        count += hash[(size_t)e * FUSION_ENTRY_WORDS + FUSION_ENTRY_STATE] == FUSION_ENTRY_VALID;
    int32_t(*k)[3] = s == BF_OK ? bf_malloc((size_t)(count ? count : 1) * sizeof *k) : NULL;
    if (s == BF_OK && !k) s = bf_fail(BF_NO_MEMORY, "fusion: chunk list");
    uint32_t j = 0;
    for (uint32_t e = 0; s == BF_OK && e < m->n_entries; e++) {
        const uint32_t *w = hash + (size_t)e * FUSION_ENTRY_WORDS;
        if (w[FUSION_ENTRY_STATE] != FUSION_ENTRY_VALID) continue;
        for (int i = 0; i < 3; i++) k[j][i] = (int32_t)w[i];
        j++;
    }
    free(hash);
    if (s != BF_OK) {
        free(k);
        return s;
    }
    *keys = k;
    *n = count;
    return BF_OK;
}

/* ------------------------------------------------------------ rebuild */

/* Copies the subtree of old node `from` (of old_nodes) into new node `to`
 * of h's node pool, renumbering the bricks' owners. */
static bf_status copy_tree(const fusion_map *m, const uint32_t *old_nodes, uint32_t from, fusion_host_map *h, uint32_t to,
                           uint32_t entry, uint32_t depth)
{
    if (depth > FUSION_MAX_LEVEL) return bf_fail(BF_NUMERIC, "fusion: octree deeper than %u levels", FUSION_MAX_LEVEL);
    uint32_t brick = old_nodes[(size_t)from * FUSION_NODE_WORDS + FUSION_NODE_BRICK];
    uint32_t child = old_nodes[(size_t)from * FUSION_NODE_WORDS + FUSION_NODE_CHILD];
    h->nodes[(size_t)to * FUSION_NODE_WORDS + FUSION_NODE_BRICK] = brick;
    if (brick < m->cfg.brick_cap) {
        uint32_t *info = h->info + (size_t)brick * FUSION_BRICK_INFO_WORDS;
        info[FUSION_INFO_NODE] = to;
        info[FUSION_INFO_CHUNK] = entry;
    }
    if (child >= m->cfg.node_cap) return BF_OK;
    uint32_t first = h->counters[FUSION_CNT_NODES];
    if (first + 8 > m->cfg.node_cap) return bf_fail(BF_POOL_FULL, "fusion: node pool full in a rebuild");
    h->counters[FUSION_CNT_NODES] = first + 8;
    h->nodes[(size_t)to * FUSION_NODE_WORDS + FUSION_NODE_CHILD] = first;
    for (uint32_t c = 0; c < 8; c++) {
        bf_status s = copy_tree(m, old_nodes, child + c, h, first + c, entry, depth + 1);
        if (s != BF_OK) return s;
    }
    return BF_OK;
}

/* Rebuilds the hash and the node pool of a holding only the chunks whose
 * entries have keep[e] set, compactly; brick slots do not move. */
static bf_status rebuild(fusion_map *m, host_all *a, const bool *keep)
{
    size_t hw = (size_t)m->n_entries * FUSION_ENTRY_WORDS, nw = (size_t)m->cfg.node_cap * FUSION_NODE_WORDS;
    uint32_t *old_hash = a->h.hash, *old_nodes = a->h.nodes;
    uint32_t *hash = bf_malloc(hw * 4), *nodes = bf_malloc(nw * 4);
    if (!hash || !nodes) {
        free(hash);
        free(nodes);
        return bf_fail(BF_NO_MEMORY, "fusion: rebuilding the index");
    }
    fusion__hash_empty(hash, m->n_entries);
    for (size_t i = 0; i < nw; i++) nodes[i] = FUSION_NONE;
    a->h.hash = hash;
    a->h.nodes = nodes;
    a->h.counters[FUSION_CNT_NODES] = 0;
    a->h.counters[FUSION_CNT_OVERFLOW] = 0;
    bf_status s = BF_OK;
    for (uint32_t e = 0; s == BF_OK && e < m->n_entries; e++) {
        const uint32_t *w = old_hash + (size_t)e * FUSION_ENTRY_WORDS;
        if (w[FUSION_ENTRY_STATE] != FUSION_ENTRY_VALID || !keep[e]) continue;
        int32_t key[3] = {(int32_t)w[0], (int32_t)w[1], (int32_t)w[2]};
        uint32_t entry;
        if ((s = fusion__host_insert_chunk(m, &a->h, key, &entry)) != BF_OK) break;
        uint32_t root = a->h.hash[(size_t)entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT];
        s = copy_tree(m, old_nodes, w[FUSION_ENTRY_ROOT], &a->h, root, entry, 0);
    }
    free(old_hash);
    free(old_nodes);
    return s;
}

/* Frees brick slot b in a: its record, stamp and bits cleared, pushed on
 * the free stack, its colour units on theirs. */
static bf_status free_slot(fusion_map *m, host_all *a, uint32_t b)
{
    uint32_t *info = a->h.info + (size_t)b * FUSION_BRICK_INFO_WORDS;
    for (uint32_t k = 0; k < FUSION_BRICK_INFO_WORDS; k++) info[k] = FUSION_NONE;
    a->stamp[b] = FUSION_NONE;
    memset(a->sign + (size_t)b * BRICK_WORDS, 0, BRICK_WORDS * 4);
    memset(a->conf + (size_t)b * BRICK_WORDS, 0, BRICK_WORDS * 4);
    a->h.free_stack[a->h.counters[FUSION_CNT_FREE_TOP]++] = b;
    a->h.counters[FUSION_CNT_BRICKS]--;
    if (!a->cmask) return BF_OK;
    return fusion__colour_release(m, &a->units, a->cmask + (size_t)b * BRICK_WORDS, &a->chead[b], a->cfree,
                                  &a->h.counters[FUSION_CNT_COLOUR_TOP]);
}

/* The first frame whose bricks a window still has to integrate: a brick
 * stamped by it or later must stay. */
static uint32_t protected_from(const fusion_map *m) { return m->n_windows_done || m->window_pending ? m->window_first : 0; }

bf_status fusion_evict_chunks(fusion_map *m, const int32_t (*keys)[3], uint32_t n, hostmap *out, uint32_t *n_evicted)
{
    if (!m || (n && !keys) || !out || !n_evicted) return bf_fail(BF_INVALID_ARG, "fusion_evict_chunks: NULL argument");
    if (m->fuse_pending) return bf_fail(BF_INVALID_ARG, "fusion: eviction while a frame's fusion is pending");
    *n_evicted = 0;
    memset(out, 0, sizeof *out);
    out->chunk_m = m->cfg.chunk_m;
    out->origin_w = m->origin_w;
    if (n == 0) return BF_OK;
    host_all a;
    bf_status s = host_all_load(m, &a, 0);
    if (s != BF_OK) return s;
    bool *keep = bf_malloc(m->n_entries), *evict = bf_calloc(m->n_entries, 1);
    if (!keep || !evict) s = bf_fail(BF_NO_MEMORY, "fusion: eviction");
    if (s == BF_OK) memset(keep, 1, m->n_entries);
    uint32_t from = protected_from(m), n_out = 0;
    /* The chunks asked for that exist; then those whose bricks a window still needs stay. */
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        uint32_t e = fusion_find_chunk(a.h.hash, keys[i][0], keys[i][1], keys[i][2], m->cfg.hash_buckets,
                                       m->cfg.hash_overflow);
        if (e != FUSION_NONE) evict[e] = true;
    }
    for (uint32_t b = 0; s == BF_OK && b < a.high; b++) {
        uint32_t e = a.h.info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK];
        if (e < m->n_entries && evict[e] && a.stamp[b] != FUSION_NONE && a.stamp[b] >= from) evict[e] = false;
    }
    for (uint32_t b = 0; s == BF_OK && b < a.high; b++) {
        uint32_t e = a.h.info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK];
        n_out += e < m->n_entries && evict[e];
    }
    hostmap_brick *bricks = s == BF_OK ? bf_malloc((size_t)(n_out ? n_out : 1) * sizeof *bricks) : NULL;
    if (s == BF_OK && !bricks) s = bf_fail(BF_NO_MEMORY, "fusion: evicting %u bricks", n_out);
    /* Their colour leaves with them. */
    uint16_t *rgb = NULL;
    if (s == BF_OK && a.cmask && !(rgb = bf_malloc((size_t)(n_out ? n_out : 1) * 1024)))
        s = bf_fail(BF_NO_MEMORY, "fusion: colour of %u evicted bricks", n_out);
    uint32_t k = 0;
    for (uint32_t b = 0; s == BF_OK && b < a.high; b++) {
        const uint32_t *info = a.h.info + (size_t)b * FUSION_BRICK_INFO_WORDS;
        uint32_t e = info[FUSION_INFO_CHUNK];
        if (e >= m->n_entries || !evict[e]) continue;
        hostmap_brick *o = &bricks[k++];
        const uint32_t *w = a.h.hash + (size_t)e * FUSION_ENTRY_WORDS;
        for (int i = 0; i < 3; i++) o->key[i] = (int32_t)w[i];
        uint32_t p = info[FUSION_INFO_POS];
        o->level = fusion_pos_level(p);
        o->cell[0] = fusion_pos_x(p), o->cell[1] = fusion_pos_y(p), o->cell[2] = fusion_pos_z(p);
        memcpy(&o->error, &info[FUSION_INFO_ERROR], 4);
        memcpy(o->sign, a.sign + (size_t)b * BRICK_WORDS, sizeof o->sign);
        memcpy(o->conf, a.conf + (size_t)b * BRICK_WORDS, sizeof o->conf);
        if (rgb) s = fusion__colour_expand(m, &a.units, a.cmask + (size_t)b * BRICK_WORDS, a.chead[b],
                                           rgb + (size_t)(k - 1) * 512);
        if (s == BF_OK) s = free_slot(m, &a, b);
    }
    uint32_t n_chunks = 0;
    for (uint32_t e = 0; s == BF_OK && e < m->n_entries; e++)
        if (evict[e]) keep[e] = false, n_chunks++;
    if (s == BF_OK && n_chunks) s = rebuild(m, &a, keep);
    if (s == BF_OK && n_chunks) s = host_all_store(m, &a, a.high);
    free(keep);
    free(evict);
    host_all_free(&a);
    if (s != BF_OK) {
        free(bricks);
        free(rgb);
        return s;
    }
    out->n_bricks = k;
    out->bricks = bricks;
    out->rgb565 = rgb;
    *n_evicted = n_chunks;
    return BF_OK;
}

bf_status fusion_compact(fusion_map *m)
{
    if (!m) return bf_fail(BF_INVALID_ARG, "fusion_compact: NULL map");
    if (m->fuse_pending) return bf_fail(BF_INVALID_ARG, "fusion: compaction while a frame's fusion is pending");
    host_all a;
    bf_status s = host_all_load(m, &a, 0);
    if (s != BF_OK) return s;
    bool *keep = bf_malloc(m->n_entries);
    if (!keep) s = bf_fail(BF_NO_MEMORY, "fusion: compaction");
    if (s == BF_OK) memset(keep, 1, m->n_entries);
    if (s == BF_OK) s = rebuild(m, &a, keep);
    if (s == BF_OK) s = host_all_store(m, &a, a.high);
    free(keep);
    host_all_free(&a);
    return s;
}

bf_status fusion_insert_bricks(fusion_map *m, const hostmap *in)
{
    if (!m || !in || (in->n_bricks && !in->bricks)) return bf_fail(BF_INVALID_ARG, "fusion_insert_bricks: NULL argument");
    if (m->fuse_pending) return bf_fail(BF_INVALID_ARG, "fusion: insertion while a frame's fusion is pending");
    if (in->chunk_m != m->cfg.chunk_m || in->origin_w.x != m->origin_w.x || in->origin_w.y != m->origin_w.y ||
        in->origin_w.z != m->origin_w.z)
        return bf_fail(BF_INVALID_ARG, "fusion: bricks of another map (chunk edge or origin differs)");
    if (in->n_bricks == 0) return BF_OK;
    host_all a;
    bf_status s = host_all_load(m, &a, in->n_bricks);
    if (s != BF_OK) return s;
    if (in->n_bricks > a.h.counters[FUSION_CNT_FREE_TOP])
        s = bf_fail(BF_POOL_FULL, "fusion: %u bricks do not fit the %u free slots", in->n_bricks,
                    a.h.counters[FUSION_CNT_FREE_TOP]);
    uint32_t high = a.high;
    for (uint32_t i = 0; s == BF_OK && i < in->n_bricks; i++) {
        const hostmap_brick *b = &in->bricks[i];
        uint32_t slot = 0, before = a.h.counters[FUSION_CNT_BRICKS];
        s = fusion__host_insert(m, &a.h, b->key, b->level, b->cell, &slot);
        if (s == BF_OK && slot >= a.planes)
            s = bf_fail(BF_NUMERIC, "fusion: inserted brick took slot %u beyond %u", slot, a.planes);
        if (s != BF_OK) break;
        uint32_t *sign = a.sign + (size_t)slot * BRICK_WORDS, *conf = a.conf + (size_t)slot * BRICK_WORDS;
        if (a.h.counters[FUSION_CNT_BRICKS] == before) {
            /* The camera came back before the chunk did and made this brick
             * anew: its confident voxels are newer than the stored ones,
             * which fill in only where it has none. */
            for (uint32_t w = 0; w < BRICK_WORDS; w++) {
                uint32_t fill = b->conf[w] & ~conf[w];
                sign[w] = (sign[w] & ~fill) | (b->sign[w] & fill);
                conf[w] |= fill;
            }
        } else {
            memcpy(sign, b->sign, sizeof b->sign);
            memcpy(conf, b->conf, sizeof b->conf);
            memcpy(&a.h.info[(size_t)slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_ERROR], &b->error, 4);
            a.stamp[slot] = FUSION_NONE;
        }
        if (s == BF_OK && in->rgb565 && a.cmask) s = slot_colour_fill(m, &a, slot, in->rgb565 + (size_t)i * 512);
        if (slot + 1 > high) high = slot + 1;
    }
    if (s == BF_OK) s = host_all_store(m, &a, high);
    host_all_free(&a);
    return s;
}

bf_status fusion__colour_load(fusion_map *m, const hostmap *in, const uint32_t *slots)
{
    host_all a;
    bf_status s = host_all_load(m, &a, 0);
    if (s != BF_OK) return s;
    uint32_t high = a.high;
    for (uint32_t i = 0; s == BF_OK && a.cmask && i < in->n_bricks; i++)
        s = slot_colour_fill(m, &a, slots[i], in->rgb565 + (size_t)i * 512);
    if (s == BF_OK) s = host_all_store(m, &a, high);
    host_all_free(&a);
    return s;
}
