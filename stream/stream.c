/* Chunk streaming between the GPU pools, a CPU cache and a spill folder
 * (stream.h). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "store/store.h"
#include "stream.h"

/* A chunk out of the pools: in the cache (bricks) or on disk. */
typedef struct stream_chunk {
    int32_t key[3];
    hostmap bricks;      /* n_bricks 0 and on_disk: its file holds them */
    uint32_t n_bricks;   /* its bricks, wherever they are */
    bool on_disk;
    uint64_t seq;        /* when it left the pools: the oldest go to disk first */
} stream_chunk;

struct stream {
    stream_config cfg;
    fusion_map *map;
    char spill[4096];
    bool spill_made, spill_owned;
    stream_chunk *chunks;
    uint32_t n_chunks, cap_chunks;
    uint64_t seq;
    uint32_t last_check;
    bool has_checked;
    stream_stats st;
    char spill_error[1024]; /* the first failed spill's message; the disk tier is off after it */
};

stream_config stream_config_default(void)
{
    return (stream_config){.enabled = true, .radius_m = 6.5f, .hysteresis_m = 1.0f, .every_frames = 10,
                           .max_chunks = 16, .high_water = 0.85f, .cache_bytes = 256ull << 20};
}

static uint64_t chunk_bytes(const stream_chunk *c)
{
    return (uint64_t)c->bricks.n_bricks * (sizeof(hostmap_brick) + (c->bricks.rgb565 ? 1024 : 0));
}

bf_status stream_create(const stream_config *cfg_in, fusion_map *map, const char *spill_dir, stream **out)
{
    stream_config cfg = cfg_in ? *cfg_in : stream_config_default();
    if (!map || !out) return bf_fail(BF_INVALID_ARG, "stream_create: NULL argument");
    if (!(cfg.radius_m > 0) || !(cfg.hysteresis_m >= 0) || cfg.every_frames == 0 || cfg.max_chunks == 0 ||
        !(cfg.high_water > 0 && cfg.high_water <= 1))
        return bf_fail(BF_INVALID_ARG, "stream: radius_m > 0, hysteresis_m >= 0, every_frames and max_chunks >= 1, "
                                       "high_water in (0, 1]");
    stream *s = calloc(1, sizeof *s);
    if (!s) return bf_fail(BF_NO_MEMORY, "stream");
    s->cfg = cfg;
    s->map = map;
    if (spill_dir) {
        snprintf(s->spill, sizeof s->spill, "%s", spill_dir);
    } else {
        const char *tmp = getenv("TMPDIR");
        snprintf(s->spill, sizeof s->spill, "%s/bitfuse-spill-XXXXXX", tmp && *tmp ? tmp : "/tmp");
        s->spill_owned = true;
    }
    *out = s;
    return BF_OK;
}

static void remove_spill(stream *s)
{
    if (!s->spill_made) return;
    char path[4400];
    for (uint32_t i = 0; i < s->n_chunks; i++) {
        if (!s->chunks[i].on_disk) continue;
        char name[96];
        snprintf(name, sizeof name, "c_%d_%d_%d.bfc", s->chunks[i].key[0], s->chunks[i].key[1], s->chunks[i].key[2]);
        snprintf(path, sizeof path, "%s/chunks/%s", s->spill, name);
        unlink(path);
    }
    snprintf(path, sizeof path, "%s/chunks", s->spill);
    rmdir(path);
    if (s->spill_owned) rmdir(s->spill);
}

void stream_destroy(stream *s)
{
    if (!s) return;
    remove_spill(s);
    for (uint32_t i = 0; i < s->n_chunks; i++) hostmap_free(&s->chunks[i].bricks);
    free(s->chunks);
    free(s);
}

stream_stats stream_get_stats(const stream *s) { return s->st; }

const char *stream_spill_error(const stream *s) { return s && s->spill_error[0] ? s->spill_error : NULL; }

/* ------------------------------------------------------------ geometry */

/* Distance from p (world) to chunk key's box. */
static double chunk_distance(const fusion_map *map, const int32_t key[3], bf_vec3 p)
{
    fusion_gpu_view v = fusion_gpu_view_get(map);
    double lo[3] = {v.origin_w.x + key[0] * (double)v.chunk_m, v.origin_w.y + key[1] * (double)v.chunk_m,
                    v.origin_w.z + key[2] * (double)v.chunk_m};
    double q[3] = {p.x, p.y, p.z}, d2 = 0;
    for (int i = 0; i < 3; i++) {
        double d = q[i] < lo[i] ? lo[i] - q[i] : q[i] > lo[i] + v.chunk_m ? q[i] - lo[i] - v.chunk_m : 0;
        d2 += d * d;
    }
    return sqrt(d2);
}

static store_meta spill_meta(const stream *s)
{
    const fusion_config *fc = fusion_get_config(s->map);
    fusion_gpu_view v = fusion_gpu_view_get(s->map);
    return (store_meta){.chunk_m = fc->chunk_m, .max_level = fc->max_level, .origin_w = v.origin_w};
}

/* ------------------------------------------------------------ the cache */

static bf_status cache_push(stream *s, const int32_t key[3], hostmap *bricks)
{
    if (s->n_chunks == s->cap_chunks) {
        uint32_t cap = s->cap_chunks ? 2 * s->cap_chunks : 64;
        stream_chunk *c = bf_realloc(s->chunks, cap * sizeof *c);
        if (!c) return bf_fail(BF_NO_MEMORY, "stream: cache of %u chunks", cap);
        s->chunks = c;
        s->cap_chunks = cap;
    }
    stream_chunk *c = &s->chunks[s->n_chunks++];
    memset(c, 0, sizeof *c);
    memcpy(c->key, key, sizeof c->key);
    c->bricks = *bricks;
    c->n_bricks = bricks->n_bricks;
    memset(bricks, 0, sizeof *bricks);
    c->seq = ++s->seq;
    s->st.cache_bytes += chunk_bytes(c);
    return BF_OK;
}

/* Splits evicted bricks (several chunks) into cache entries. */
static bf_status cache_take(stream *s, hostmap *ev)
{
    bf_status st = BF_OK;
    uint32_t i = 0;
    /* Group by key: a small number of chunks, so a pass per chunk. */
    bool *done = ev->n_bricks ? calloc(ev->n_bricks, 1) : NULL;
    if (ev->n_bricks && !done) return bf_fail(BF_NO_MEMORY, "stream: evicted bricks");
    for (i = 0; st == BF_OK && i < ev->n_bricks; i++) {
        if (done[i]) continue;
        const int32_t *key = ev->bricks[i].key;
        uint32_t n = 0;
        for (uint32_t j = i; j < ev->n_bricks; j++) n += !done[j] && !memcmp(ev->bricks[j].key, key, 12);
        hostmap h = {.chunk_m = ev->chunk_m, .origin_w = ev->origin_w, .n_bricks = n};
        h.bricks = bf_malloc((size_t)n * sizeof *h.bricks);
        if (ev->rgb565) h.rgb565 = bf_malloc((size_t)n * 1024);
        if (!h.bricks || (ev->rgb565 && !h.rgb565)) {
            hostmap_free(&h);
            st = bf_fail(BF_NO_MEMORY, "stream: chunk of %u bricks", n);
            break;
        }
        int32_t k[3] = {key[0], key[1], key[2]};
        uint32_t m = 0;
        for (uint32_t j = i; j < ev->n_bricks; j++)
            if (!done[j] && !memcmp(ev->bricks[j].key, k, 12)) {
                if (h.rgb565) memcpy(h.rgb565 + (size_t)m * 512, ev->rgb565 + (size_t)j * 512, 1024); /* colour with its brick */
                h.bricks[m++] = ev->bricks[j], done[j] = true;
            }
        st = cache_push(s, k, &h);
        hostmap_free(&h);
    }
    free(done);
    return st;
}

/* A spill that failed (a full disk, an I/O error): the spill folder is
 * scratch space, not an output, so the scan goes on with the chunk kept in
 * the cache, whose budget is then exceeded, rather than end for want of
 * disk; the disk tier stays off for the rest of the run (a full disk stays
 * full, and every retry would cost a failed write per check). Chunks on
 * disk already still come back from it. */
static void spill_failed(stream *s)
{
    snprintf(s->spill_error, sizeof s->spill_error, "%s", bf_last_error());
    s->st.spill_failures++;
    bf_warn("stream: %s: the spill folder is not used again in this run; chunks out of the GPU stay in memory "
            "(the CPU cache grows past its %.1f MiB)",
            s->spill_error, s->cfg.cache_bytes / 1048576.0);
}

/* Over budget: the chunks that left the pools first go to disk. */
static bf_status cache_trim(stream *s)
{
    while (!s->spill_error[0] && s->st.cache_bytes > s->cfg.cache_bytes) {
        stream_chunk *oldest = NULL;
        for (uint32_t i = 0; i < s->n_chunks; i++)
            if (!s->chunks[i].on_disk && (!oldest || s->chunks[i].seq < oldest->seq)) oldest = &s->chunks[i];
        if (!oldest) return BF_OK;
        if (!s->spill_made) {
            if (s->spill_owned && !mkdtemp(s->spill)) {
                bf_fail(BF_WRITE, "stream: cannot make a spill folder %s: %s", s->spill, strerror(errno));
                spill_failed(s);
                return BF_OK;
            }
            s->spill_made = true;
        }
        store_meta meta = spill_meta(s);
        uint64_t bytes = 0;
        bf_status st = store_put_chunks(s->spill, &oldest->bricks, &meta, &bytes);
        if (st == BF_WRITE) { /* the file is absent (written whole or not at all): the chunk stays cached */
            spill_failed(s);
            return BF_OK;
        }
        if (st != BF_OK) return st;
        s->st.cache_bytes -= chunk_bytes(oldest);
        hostmap_free(&oldest->bricks);
        oldest->on_disk = true;
        s->st.to_disk++;
        s->st.disk_bytes += bytes;
    }
    return BF_OK;
}

/* The bricks of cache entry i (read from disk if there), removed from the cache. */
static bf_status cache_pop(stream *s, uint32_t i, hostmap *out)
{
    stream_chunk *c = &s->chunks[i];
    if (c->on_disk) {
        store_meta meta = spill_meta(s);
        bf_status st = store_get_chunk(s->spill, c->key, &meta, out, NULL);
        if (st != BF_OK) return st;
        char path[4400];
        snprintf(path, sizeof path, "%s/chunks/c_%d_%d_%d.bfc", s->spill, c->key[0], c->key[1], c->key[2]);
        unlink(path);
        s->st.from_disk++;
    } else {
        *out = c->bricks;
        s->st.cache_bytes -= chunk_bytes(c);
    }
    s->chunks[i] = s->chunks[--s->n_chunks];
    return BF_OK;
}

/* ------------------------------------------------------------ moves */

typedef struct cand {
    double d;
    uint32_t i;
    int32_t key[3];
} cand;

/* Chunks at the same distance go in key order: the resident chunks come in
 * hash-entry order, which the allocation's atomics choose, and a move of
 * max_chunks at a time must not depend on it (docs/determinism.md). */
static int cand_key_cmp(const cand *a, const cand *b)
{
    for (int i = 0; i < 3; i++)
        if (a->key[i] != b->key[i]) return (a->key[i] > b->key[i]) - (a->key[i] < b->key[i]);
    return 0;
}

static int cand_far_first(const void *a, const void *b)
{
    double x = ((const cand *)a)->d, y = ((const cand *)b)->d;
    return x != y ? (x < y) - (x > y) : cand_key_cmp(a, b);
}

static int cand_near_first(const void *a, const void *b)
{
    double x = ((const cand *)a)->d, y = ((const cand *)b)->d;
    return x != y ? (x > y) - (x < y) : cand_key_cmp(a, b);
}

static bool above_high_water(const stream *s)
{
    fusion_pool_use u = fusion_pool_usage(s->map);
    return u.bricks > s->cfg.high_water * u.brick_cap || u.nodes > s->cfg.high_water * u.node_cap ||
           u.overflow > s->cfg.high_water * u.overflow_cap;
}

/* Resident chunks beyond radius + hysteresis leave, farthest first; above
 * high water the farthest leave whatever their distance (not the camera's
 * own chunk and its neighbours within one chunk edge). */
static bf_status move_out(stream *s, bf_vec3 p, bool pressure, bool make_room)
{
    int32_t(*keys)[3] = NULL;
    uint32_t n = 0;
    bf_status st = fusion_chunk_keys(s->map, &keys, &n);
    if (st != BF_OK) return st;
    s->st.resident = n;
    cand *c = n ? bf_malloc(n * sizeof *c) : NULL;
    if (n && !c) st = bf_fail(BF_NO_MEMORY, "stream: %u chunks", n);
    uint32_t k = 0;
    /* Chunks waiting to come back need room: then the hysteresis band goes too. */
    double far = s->cfg.radius_m + (make_room ? 0 : s->cfg.hysteresis_m), near = fusion_get_config(s->map)->chunk_m;
    for (uint32_t i = 0; st == BF_OK && i < n; i++) {
        double d = chunk_distance(s->map, keys[i], p);
        if (d > far || (pressure && d > near)) c[k++] = (cand){d, i, {keys[i][0], keys[i][1], keys[i][2]}};
    }
    if (k > 1) qsort(c, k, sizeof *c, cand_far_first);
    if (k > s->cfg.max_chunks) k = s->cfg.max_chunks;
    int32_t(*out)[3] = k ? bf_malloc(k * sizeof *out) : NULL;
    if (k && !out) st = bf_fail(BF_NO_MEMORY, "stream: %u chunks", k);
    for (uint32_t i = 0; st == BF_OK && i < k; i++) memcpy(out[i], keys[c[i].i], sizeof out[i]);
    hostmap ev = {0};
    uint32_t moved = 0;
    if (st == BF_OK && k) st = fusion_evict_chunks(s->map, (const int32_t(*)[3])out, k, &ev, &moved);
    if (st == BF_OK && moved) {
        s->st.chunks_out += moved;
        s->st.bricks_out += ev.n_bricks;
        s->st.resident -= moved;
        if (pressure) s->st.pressure_checks++;
        st = cache_take(s, &ev);
    }
    if (st == BF_OK) st = cache_trim(s);
    /* Nodes left behind by bricks removed as empty fill the node pool;
     * a rebuild gives them back (an eviction above did that already). */
    fusion_pool_use u = fusion_pool_usage(s->map);
    if (st == BF_OK && !moved && u.nodes > s->cfg.high_water * u.node_cap) {
        st = fusion_compact(s->map);
        s->st.compactions++;
    }
    hostmap_free(&ev);
    free(out);
    free(c);
    free(keys);
    return st;
}

/* Chunks out of the pools within the radius come back, nearest first. */
static bf_status move_in(stream *s, bf_vec3 p)
{
    uint32_t k = 0;
    cand *c = s->n_chunks ? bf_malloc(s->n_chunks * sizeof *c) : NULL;
    if (s->n_chunks && !c) return bf_fail(BF_NO_MEMORY, "stream: %u chunks", s->n_chunks);
    for (uint32_t i = 0; i < s->n_chunks; i++) {
        double d = chunk_distance(s->map, s->chunks[i].key, p);
        if (d < s->cfg.radius_m)
            c[k++] = (cand){d, i, {s->chunks[i].key[0], s->chunks[i].key[1], s->chunks[i].key[2]}};
    }
    if (k > 1) qsort(c, k, sizeof *c, cand_near_first);
    if (k > s->cfg.max_chunks) k = s->cfg.max_chunks;
    /* As many as fit below high water, nearest first: the rest wait for
     * the next check (a full pool would refuse them all). */
    fusion_pool_use u = fusion_pool_usage(s->map);
    double room = s->cfg.high_water * u.brick_cap - u.bricks, take = 0;
    uint32_t fit = 0;
    while (fit < k && take + s->chunks[c[fit].i].n_bricks <= room) take += s->chunks[c[fit++].i].n_bricks;
    if (fit < k) {
        s->st.loads_deferred++;
        bf_log(BF_LOG_DEBUG, "stream: %u of %u chunks due back wait: %u bricks in use of %u (room %.0f, the next needs %u)",
               k - fit, k, u.bricks, u.brick_cap, room - take, s->chunks[c[fit].i].n_bricks);
    }
    k = fit;
    /* Pop from the highest index down: cache_pop moves the last entry into
     * the popped one's place. */
    uint32_t *idx = k ? bf_malloc(k * sizeof *idx) : NULL;
    bf_status st = k && !idx ? bf_fail(BF_NO_MEMORY, "stream") : BF_OK;
    for (uint32_t i = 0; st == BF_OK && i < k; i++) idx[i] = c[i].i;
    for (uint32_t i = 0; st == BF_OK && i + 1 < k; i++)
        for (uint32_t j = i + 1; j < k; j++)
            if (idx[j] > idx[i]) {
                uint32_t t = idx[i];
                idx[i] = idx[j], idx[j] = t;
            }
    hostmap all = {0};
    fusion_gpu_view v = fusion_gpu_view_get(s->map);
    all.chunk_m = v.chunk_m;
    all.origin_w = v.origin_w;
    for (uint32_t i = 0; st == BF_OK && i < k; i++) {
        hostmap one = {0};
        st = cache_pop(s, idx[i], &one);
        if (st != BF_OK) break;
        hostmap_brick *b = bf_realloc(all.bricks, ((size_t)all.n_bricks + one.n_bricks + 1) * sizeof *b);
        if (b) all.bricks = b;
        /* Colour with its brick: the merged list has colour once a chunk has (zeros for those without). */
        uint16_t *c = b && (one.rgb565 || all.rgb565)
                          ? bf_realloc(all.rgb565, ((size_t)all.n_bricks + one.n_bricks + 1) * 1024)
                          : NULL;
        if (!b || ((one.rgb565 || all.rgb565) && !c)) {
            st = bf_fail(BF_NO_MEMORY, "stream: %u bricks", all.n_bricks + one.n_bricks);
            hostmap_free(&one);
            break;
        }
        if (c) {
            if (!all.rgb565) memset(c, 0, (size_t)all.n_bricks * 1024);
            all.rgb565 = c;
            if (one.rgb565) memcpy(c + (size_t)all.n_bricks * 512, one.rgb565, (size_t)one.n_bricks * 1024);
            else memset(c + (size_t)all.n_bricks * 512, 0, (size_t)one.n_bricks * 1024);
        }
        memcpy(all.bricks + all.n_bricks, one.bricks, (size_t)one.n_bricks * sizeof *b);
        all.n_bricks += one.n_bricks;
        hostmap_free(&one);
    }
    if (st == BF_OK && all.n_bricks) st = fusion_insert_bricks(s->map, &all);
    if (st == BF_OK) {
        s->st.chunks_in += k;
        s->st.bricks_in += all.n_bricks;
        s->st.resident += k;
    } else if (all.n_bricks) {
        /* They did not fit: back into the cache, nothing lost. */
        bf_status keep = cache_take(s, &all);
        if (keep != BF_OK) st = keep;
    }
    hostmap_free(&all);
    free(idx);
    free(c);
    return st;
}

bf_status stream_update(stream *s, const bf_se3 *T_wc, uint32_t frame_index, bool force)
{
    if (!s || !T_wc) return bf_fail(BF_INVALID_ARG, "stream_update: NULL argument");
    if (!s->cfg.enabled) return BF_OK;
    bool pressure = above_high_water(s);
    bool due = force || pressure || !s->has_checked || frame_index >= s->last_check + s->cfg.every_frames;
    if (!due) return BF_OK;
    s->has_checked = true;
    s->last_check = frame_index;
    s->st.checks++;
    double t0 = bf_time_s();
    uint64_t before = s->st.chunks_out + s->st.chunks_in;
    /* The bricks of the chunks due back, against the room below high water. */
    double need = 0;
    for (uint32_t i = 0; i < s->n_chunks; i++)
        if (chunk_distance(s->map, s->chunks[i].key, T_wc->t) < s->cfg.radius_m) need += s->chunks[i].n_bricks;
    fusion_pool_use u = fusion_pool_usage(s->map);
    bool make_room = need > s->cfg.high_water * u.brick_cap - u.bricks;
    bf_status st = move_out(s, T_wc->t, pressure, make_room);
    if (st == BF_OK && s->n_chunks) st = move_in(s, T_wc->t);
    if (s->st.chunks_out + s->st.chunks_in != before) {
        s->st.ms_last = 1e3 * (bf_time_s() - t0);
        s->st.ms_total += s->st.ms_last;
        if (s->st.ms_last > s->st.ms_max) s->st.ms_max = s->st.ms_last;
    }
    uint32_t disk = 0;
    for (uint32_t i = 0; i < s->n_chunks; i++) disk += s->chunks[i].on_disk;
    s->st.on_disk = disk;
    s->st.cached = s->n_chunks - disk;
    if (s->st.cache_bytes > s->st.cache_bytes_max) s->st.cache_bytes_max = s->st.cache_bytes;
    return st;
}

bf_status stream_adopt(stream *s, hostmap *map)
{
    if (!s || !map) return bf_fail(BF_INVALID_ARG, "stream_adopt: NULL argument");
    fusion_gpu_view v = fusion_gpu_view_get(s->map);
    if (map->chunk_m != v.chunk_m || map->origin_w.x != v.origin_w.x || map->origin_w.y != v.origin_w.y ||
        map->origin_w.z != v.origin_w.z)
        return bf_fail(BF_INVALID_ARG, "stream: bricks of another map (chunk edge or origin differs)");
    bf_status st = cache_take(s, map);
    hostmap_free(map);
    if (st == BF_OK) st = cache_trim(s);
    return st;
}

/* Bricks in gather order (the pools' first, then the cache's) sorted by
 * chunk, level, cell and that order. */
typedef struct ranked {
    const hostmap_brick *b;
    uint32_t order;
} ranked;

static int ranked_cmp(const void *pa, const void *pb)
{
    const ranked *a = pa, *b = pb;
    for (int i = 0; i < 3; i++)
        if (a->b->key[i] != b->b->key[i]) return a->b->key[i] < b->b->key[i] ? -1 : 1;
    if (a->b->level != b->b->level) return a->b->level < b->b->level ? -1 : 1;
    for (int i = 2; i >= 0; i--)
        if (a->b->cell[i] != b->b->cell[i]) return a->b->cell[i] < b->b->cell[i] ? -1 : 1;
    return (a->order > b->order) - (a->order < b->order);
}

/* A chunk the camera reached again before it came back into the pools is
 * in both: one brick per cell, the pools' winning and the cache's filling
 * in where the pools' has no confident voxel (fusion_insert_bricks' rule). */
static bf_status dedupe(hostmap *m)
{
    if (m->n_bricks < 2) return BF_OK;
    ranked *r = bf_malloc((size_t)m->n_bricks * sizeof *r);
    hostmap_brick *o = bf_malloc((size_t)m->n_bricks * sizeof *o);
    uint16_t *oc = m->rgb565 ? bf_calloc((size_t)m->n_bricks * 512, 2) : NULL; /* colour follows its brick */
    if (!r || !o || (m->rgb565 && !oc)) {
        free(r);
        free(o);
        free(oc);
        return bf_fail(BF_NO_MEMORY, "stream: merging %u bricks", m->n_bricks);
    }
    for (uint32_t i = 0; i < m->n_bricks; i++) r[i] = (ranked){&m->bricks[i], i};
    qsort(r, m->n_bricks, sizeof *r, ranked_cmp);
    uint32_t k = 0;
    for (uint32_t i = 0; i < m->n_bricks; i++) {
        bool same = k && !memcmp(o[k - 1].key, r[i].b->key, 12) && o[k - 1].level == r[i].b->level &&
                    !memcmp(o[k - 1].cell, r[i].b->cell, 12);
        if (!same) {
            if (oc) memcpy(oc + (size_t)k * 512, m->rgb565 + (size_t)r[i].order * 512, 512 * 2);
            o[k++] = *r[i].b;
            continue;
        }
        hostmap_brick *w = &o[k - 1];
        for (int j = 0; j < 16; j++) {
            uint32_t fill = r[i].b->conf[j] & ~w->conf[j];
            w->sign[j] = (w->sign[j] & ~fill) | (r[i].b->sign[j] & fill);
            w->conf[j] |= fill;
        }
    }
    free(r);
    free(m->bricks);
    free(m->rgb565);
    m->bricks = o;
    m->rgb565 = oc;
    m->n_bricks = k;
    return BF_OK;
}

bf_status stream_gather(stream *s, hostmap *out)
{
    hostmap snap = {0};
    bf_status st = fusion_snapshot_take(s->map, &snap);
    if (st != BF_OK) return st;
    size_t n = snap.n_bricks;
    store_meta meta = spill_meta(s);
    hostmap *disk = s->n_chunks ? calloc(s->n_chunks, sizeof *disk) : NULL;
    if (s->n_chunks && !disk) st = bf_fail(BF_NO_MEMORY, "stream: gather");
    for (uint32_t i = 0; st == BF_OK && i < s->n_chunks; i++) {
        if (s->chunks[i].on_disk) st = store_get_chunk(s->spill, s->chunks[i].key, &meta, &disk[i], NULL);
        n += s->chunks[i].on_disk ? disk[i].n_bricks : s->chunks[i].bricks.n_bricks;
    }
    hostmap_brick *b = st == BF_OK ? bf_realloc(snap.bricks, (n + 1) * sizeof *b) : NULL;
    if (st == BF_OK && !b) st = bf_fail(BF_NO_MEMORY, "stream: gather of %zu bricks", n);
    if (b) snap.bricks = b;
    /* Colour of the cached chunks comes along (zeros where a chunk has none). */
    uint16_t *c = st == BF_OK && snap.rgb565 ? bf_realloc(snap.rgb565, (n + 1) * 512 * 2) : NULL;
    if (st == BF_OK && snap.rgb565 && !c) st = bf_fail(BF_NO_MEMORY, "stream: colour of %zu bricks", n);
    if (c) {
        memset(c + (size_t)snap.n_bricks * 512, 0, (n + 1 - snap.n_bricks) * 512 * 2);
        snap.rgb565 = c;
    }
    if (st == BF_OK) {
        snap.bricks = b;
        for (uint32_t i = 0; i < s->n_chunks; i++) {
            const hostmap *h = s->chunks[i].on_disk ? &disk[i] : &s->chunks[i].bricks;
            if (snap.rgb565 && h->rgb565)
                memcpy(snap.rgb565 + (size_t)snap.n_bricks * 512, h->rgb565, (size_t)h->n_bricks * 1024);
            memcpy(snap.bricks + snap.n_bricks, h->bricks, (size_t)h->n_bricks * sizeof *b);
            snap.n_bricks += h->n_bricks;
        }
    }
    for (uint32_t i = 0; disk && i < s->n_chunks; i++) hostmap_free(&disk[i]);
    free(disk);
    if (st == BF_OK && s->n_chunks) st = dedupe(&snap);
    if (st != BF_OK) {
        hostmap_free(&snap);
        return st;
    }
    *out = snap;
    return BF_OK;
}
