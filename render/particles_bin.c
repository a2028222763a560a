/* Binning particles into bricks (particles_bin.h; Reichl's dissertation,
 * ch. 6). Random access into the bricks is what costs (perf on 10^6
 * particles: 70% of the time in the stores of a per-particle hash lookup
 * and brick write), so the binning is ordered:
 *   1. each particle's key, its brick's Morton code above its cell's place
 *      in the brick (9 bits), and an LSD radix sort of the keys (two
 *      threads, a half each, then one merge that drops repeats: particles
 *      sharing a cell are one sphere);
 *   2. per brick (a run of equal codes), the reach bits of all its cells
 *      gathered into one mask per neighbour brick (a packed table per cell
 *      place), then one lookup per neighbour instead of one per particle;
 *      runs come in Morton order, so the bricks made and touched stay near
 *      each other, and a run's neighbours are looked up (made where new)
 *      and their lines prefetched while the last run's bits are written.
 *      The index is a dense array over the set's brick box where that is
 *      small, else a hash table keeping runs of 64 codes (4x4x4 bricks)
 *      together. Two threads take a half of the runs each, with indexes of
 *      their own; the bricks either made for the other half's codes (a
 *      thin layer along the split) are merged after;
 *   3. the host copy written by both threads, and the octree's node count
 *      from the radix-sorted Morton codes of all bricks.
 * The buffers are kept in the binner for the next binning (a moving set's
 * next step). */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "particles_bin.h"
#include "shaders/fusion.glsl.h"

#define BIN_THREADS 2

/* ------------------------------------------------------------ Morton codes */

/* The 18 (PARTICLES_AXIS_BITS) low bits of v spread to every third bit. */
static uint64_t spread3(uint64_t v)
{
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
}

static uint64_t compact3(uint64_t v)
{
    v &= 0x1249249249249249ull;
    v = (v | v >> 2) & 0x10c30c30c30c30c3ull;
    v = (v | v >> 4) & 0x100f00f00f00f00full;
    v = (v | v >> 8) & 0x1f0000ff0000ffull;
    v = (v | v >> 16) & 0x1f00000000ffffull;
    v = (v | v >> 32) & 0x1fffff;
    return v;
}

/* Morton code of a brick: ancestors k levels up share its code >> 3k. */
static uint64_t morton3(const int64_t b[3])
{
    return spread3((uint64_t)b[0]) << 2 | spread3((uint64_t)b[1]) << 1 | spread3((uint64_t)b[2]);
}

static void unmorton3(uint64_t m, int64_t b[3])
{
    b[0] = (int64_t)compact3(m >> 2), b[1] = (int64_t)compact3(m >> 1), b[2] = (int64_t)compact3(m);
}

/* ------------------------------------------------------------ two threads */

typedef void *(*bin_fn)(void *);

/* fn(args[0]) here and fn(args[1]) on a second thread (or here after,
 * where no thread can be made: the result is the same). */
static void run_two(bin_fn fn, void *a0, void *a1)
{
    pthread_t th;
    bool threaded = BIN_THREADS > 1 && bf_thread_start(&th, fn, a1) == 0;
    fn(a0);
    if (threaded) pthread_join(th, NULL);
    else fn(a1);
}

/* ------------------------------------------------------------ radix sort */

/* Sorts v[0, n) (keys below 2^bits) with tmp[0, n) as scratch: LSD radix,
 * 11-bit digits. */
static void radix_sort(uint64_t *v, uint64_t *tmp, uint64_t n, uint32_t bits)
{
    enum { DIGIT = 11, BUCKETS = 1 << DIGIT };
    static _Thread_local uint64_t count[BUCKETS];
    uint64_t *src = v, *dst = tmp;
    for (uint32_t shift = 0; shift < bits; shift += DIGIT) {
        memset(count, 0, sizeof count);
        for (uint64_t i = 0; i < n; i++) count[(src[i] >> shift) & (BUCKETS - 1)]++;
        uint64_t sum = 0;
        for (uint32_t d = 0; d < BUCKETS; d++) {
            uint64_t c = count[d];
            count[d] = sum;
            sum += c;
        }
        for (uint64_t i = 0; i < n; i++) dst[count[(src[i] >> shift) & (BUCKETS - 1)]++] = src[i];
        uint64_t *t = src;
        src = dst, dst = t;
    }
    if (src != v) memcpy(v, src, n * 8);
}

static uint32_t bits_of(uint64_t x)
{
    return x ? 64u - (uint32_t)__builtin_clzll(x) : 1u;
}

/* Merges the sorted runs a[0, na) and b[0, nb) into out, each value once;
 * returns the count. */
static uint64_t merge_unique(const uint64_t *a, uint64_t na, const uint64_t *b, uint64_t nb, uint64_t *out)
{
    uint64_t i = 0, j = 0, k = 0;
    while (i < na || j < nb) {
        uint64_t x = j >= nb || (i < na && a[i] <= b[j]) ? a[i++] : b[j++];
        if (k == 0 || out[k - 1] != x) out[k++] = x;
    }
    return k;
}

typedef struct sort_job {
    uint64_t *v, *tmp, n;
    uint32_t bits;
    /* Keys of particles: */
    const float *xyz;
    double o[3], inv;
    int64_t lo[3], hi[3]; /* the particles' brick box */
} sort_job;

static void *keys_main(void *arg)
{
    sort_job *j = arg;
    uint64_t hi = 0;
    for (int a = 0; a < 3; a++) j->lo[a] = INT64_MAX, j->hi[a] = -1;
    for (uint64_t i = 0; i < j->n; i++) {
        int64_t g[3];
        for (int a = 0; a < 3; a++) g[a] = (int64_t)floor(((double)j->xyz[3 * i + a] - j->o[a]) * j->inv);
        int64_t b[3] = {g[0] >> 3, g[1] >> 3, g[2] >> 3};
        for (int a = 0; a < 3; a++) {
            if (b[a] < j->lo[a]) j->lo[a] = b[a];
            if (b[a] > j->hi[a]) j->hi[a] = b[a];
        }
        uint64_t k = morton3(b) << 9 | (uint64_t)((g[0] & 7) | (g[1] & 7) << 3 | (g[2] & 7) << 6);
        j->v[i] = k;
        hi |= k;
    }
    radix_sort(j->v, j->tmp, j->n, bits_of(hi));
    return NULL;
}

static void *sort_main(void *arg)
{
    sort_job *j = arg;
    radix_sort(j->v, j->tmp, j->n, j->bits);
    return NULL;
}

/* ------------------------------------------------------------ reach */

/* Sets the reach bits of brick hb (global coordinates b) for the cells a
 * sphere of radius reach (cells) overlaps whose centre lies within half
 * (cells, per axis) of cc: those whose box is within reach of that box.
 * half is 0 on the centres' level (the centre is its cell's middle) and 0.5
 * on the coarse level (anywhere in the coarse cell). */
static void bin_reach(uint32_t conf[16], const int64_t b[3], const double cc[3], double reach, double half)
{
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = (int64_t)floor(cc[a] - reach - half) - b[a] * 8;
        hi[a] = (int64_t)floor(cc[a] + reach + half) - b[a] * 8;
        if (lo[a] < 0) lo[a] = 0;
        if (hi[a] > 7) hi[a] = 7;
    }
    double r2 = reach * reach;
    for (int64_t z = lo[2]; z <= hi[2]; z++) {
        double dz = cc[2] - (double)(b[2] * 8 + z);
        dz = dz < 0 ? -dz : (dz > 1 ? dz - 1 : 0);
        dz = dz > half ? dz - half : 0;
        for (int64_t y = lo[1]; y <= hi[1]; y++) {
            double dy = cc[1] - (double)(b[1] * 8 + y);
            dy = dy < 0 ? -dy : (dy > 1 ? dy - 1 : 0);
            dy = dy > half ? dy - half : 0;
            for (int64_t x = lo[0]; x <= hi[0]; x++) {
                double dx = cc[0] - (double)(b[0] * 8 + x);
                dx = dx < 0 ? -dx : (dx > 1 ? dx - 1 : 0);
                dx = dx > half ? dx - half : 0;
                if (dx * dx + dy * dy + dz * dz > r2) continue;
                conf[brick_word((uint32_t)x, (uint32_t)y, (uint32_t)z)] |=
                    1u << brick_bit((uint32_t)x, (uint32_t)y, (uint32_t)z);
            }
        }
    }
}

/* The reach bits of a centre depend only on its cell's place in its brick
 * (the centre is the cell's middle): for each of the 512 places, which
 * neighbour bricks (offsets -1..1, index ox + 3 oy + 9 oz + 13) it reaches
 * and their masks, packed (a quarter-radius cell reaches 8 of the 27: the
 * table stays in the L2 cache). Built once per reach of at most 8 cells (a
 * brick); beyond, bin_reach runs per cell. With octants (the coarse level)
 * an entry is a place and one octant of its cell, o << 9 | l: centres
 * anywhere in that octant, a quarter cell about its middle. */
#define REACH_PLACES 512u
typedef struct reach_table {
    uint32_t used[8 * REACH_PLACES];      /* bit k: neighbour k is reached */
    uint32_t first[8 * REACH_PLACES + 1]; /* entry e's masks: mask[first[e] ..], in neighbour order */
    uint32_t mask[][16];
} reach_table;

static reach_table *reach_table_make(double reach, double half, bool octants)
{
    if (reach + half > 8.0) return NULL;
    uint32_t n_entries = octants ? 8 * REACH_PLACES : REACH_PLACES;
    uint32_t (*all)[27][16] = bf_calloc(n_entries, sizeof *all);
    uint32_t *used = bf_calloc(n_entries, 4), total = 0;
    if (!all || !used) {
        free(all), free(used);
        return NULL;
    }
    for (uint32_t e = 0; e < n_entries; e++) {
        uint32_t l = e & (REACH_PLACES - 1), o = e >> 9;
        double cc[3] = {(l & 7) + 0.5, ((l >> 3) & 7) + 0.5, (l >> 6) + 0.5};
        if (octants)
            for (int a = 0; a < 3; a++) cc[a] += (o >> a & 1) ? 0.25 : -0.25;
        for (int k = 0; k < 27; k++) {
            int64_t b[3] = {k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1};
            bin_reach(all[e][k], b, cc, reach, octants ? 0.25 : half);
            bool any = false;
            for (int w = 0; w < 16; w++) any |= all[e][k][w] != 0;
            if (any) used[e] |= 1u << k, total++;
        }
    }
    reach_table *t = bf_calloc(1, sizeof *t + (size_t)total * sizeof t->mask[0]);
    if (t) {
        uint32_t m = 0;
        for (uint32_t e = 0; e < n_entries; e++) {
            t->used[e] = used[e];
            t->first[e] = m;
            for (int k = 0; k < 27; k++)
                if (used[e] >> k & 1) memcpy(t->mask[m++], all[e][k], sizeof t->mask[0]);
        }
        t->first[n_entries] = m;
    }
    free(all);
    free(used);
    return t;
}

/* ------------------------------------------------------------ bricks of a half */

typedef struct bin_slot {
    uint64_t key; /* code + 1; 0 = empty */
    uint32_t index;
} bin_slot;

/* Where a half finds its bricks by their global coordinates: a dense
 * array over the set's brick box where that is small (a few bytes per
 * particle), else a hash table. */
typedef struct bin_index {
    uint32_t *dense;    /* brick index + 1 at x + dim x (y + dim y z) from lo; 0 = none */
    uint64_t dense_cap;
    int64_t lo[3], dim[3]; /* dim 0: the hash table */
    bin_slot *slots;    /* else this */
    uint64_t cap;       /* a power of two */
    uint64_t n_slots;
} bin_index;

/* A brick's bits while binning: each plane one cache line. */
typedef struct bin_planes {
    _Alignas(64) uint32_t sign[16];
    uint32_t conf[16];
} bin_planes;

typedef struct bin_part {
    /* in */
    const uint64_t *cells; /* sorted unique cell keys of this half's bricks */
    const uint8_t *octs;   /* NULL, or per cell the octants of it that hold centres (bit x + 2 y + 4 z) */
    uint64_t n_cells;
    const reach_table *rt;
    double reach, half;
    /* out */
    bin_index ix;
    bin_planes *bricks; /* in bricks_mem, aligned */
    void *bricks_mem;
    uint64_t *codes;
    uint32_t n, brick_cap, n_occupied;
    uint64_t max_bricks;
    bool failed;    /* out of memory (the thread cannot set the caller's error) */
    bool too_many;  /* past max_bricks */
} bin_part;

/* Runs of 64 consecutive codes keep together; the runs are scattered. */
static uint64_t slot_of(uint64_t code, uint64_t cap)
{
    uint64_t x = code >> 6;
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdull;
    x ^= x >> 33;
    return ((x << 6) | (code & 63)) & (cap - 1);
}

static bool index_grow(bin_index *ix)
{
    uint64_t cap = ix->cap ? 2 * ix->cap : 1u << 12;
    while (cap < 2 * ix->n_slots + 2) cap *= 2;
    bin_slot *s = bf_calloc(cap, sizeof *s);
    if (!s) return false;
    bf_advise_huge(s, cap * sizeof *s);
    for (uint64_t i = 0; i < ix->cap; i++) {
        if (!ix->slots[i].key) continue;
        uint64_t h = slot_of(ix->slots[i].key - 1, cap);
        while (s[h].key) h = (h + 1) & (cap - 1);
        s[h] = ix->slots[i];
    }
    free(ix->slots);
    ix->slots = s, ix->cap = cap;
    return true;
}

/* The entry of brick c (global coordinates, code its Morton code): in the
 * dense array, or the hash slot holding it or the empty one where it goes. */
static uint32_t *index_entry(const bin_index *ix, const int64_t c[3], uint64_t code, bin_slot **slot)
{
    *slot = NULL;
    if (ix->dim[0]) {
        int64_t x = c[0] - ix->lo[0], y = c[1] - ix->lo[1], z = c[2] - ix->lo[2];
        return &ix->dense[x + ix->dim[0] * (y + ix->dim[1] * z)];
    }
    uint64_t h = slot_of(code, ix->cap);
    while (ix->slots[h].key && ix->slots[h].key != code + 1) h = (h + 1) & (ix->cap - 1);
    *slot = &ix->slots[h];
    return NULL;
}

/* Room for cap bricks, those made kept (64-byte aligned: each plane of a
 * brick is one cache line). */
static bool part_reserve(bin_part *p, uint64_t cap)
{
    if (cap <= p->brick_cap) return true;
    if (cap >= UINT32_MAX) return false;
    void *mem = bf_malloc((size_t)cap * sizeof(bin_planes) + 64);
    uint64_t *codes = mem ? bf_realloc(p->codes, (size_t)cap * 8) : NULL;
    if (!codes) {
        free(mem);
        return false;
    }
    p->codes = codes;
    /* The first binning of a large set spends most of its time in page faults of these. */
    bf_advise_huge(mem, (size_t)cap * sizeof(bin_planes) + 64);
    bf_advise_huge(codes, (size_t)cap * 8);
    bin_planes *b = (bin_planes *)(((uintptr_t)mem + 63) & ~(uintptr_t)63);
    if (p->n) memcpy(b, p->bricks, (size_t)p->n * sizeof *b);
    free(p->bricks_mem);
    p->bricks_mem = mem, p->bricks = b, p->brick_cap = (uint32_t)cap;
    return true;
}

/* The brick c (code its Morton code), or UINT32_MAX. */
static uint32_t part_find(const bin_part *p, const int64_t c[3], uint64_t code)
{
    bin_slot *sl;
    uint32_t *d = index_entry(&p->ix, c, code, &sl);
    if (d) return *d ? *d - 1 : UINT32_MAX;
    return sl->key ? sl->index : UINT32_MAX;
}

/* The index of brick c (code its Morton code), added (empty) when new;
 * UINT32_MAX when out of memory. */
static uint32_t part_brick(bin_part *p, const int64_t c[3], uint64_t code)
{
    bin_slot *sl;
    uint32_t *d = index_entry(&p->ix, c, code, &sl);
    if (d && *d) return *d - 1;
    if (sl && sl->key) return sl->index;
    if (p->n == p->brick_cap && !part_reserve(p, 2 * (uint64_t)p->brick_cap + 1024)) return UINT32_MAX;
    if (d) *d = p->n + 1;
    else sl->key = code + 1, sl->index = p->n;
    memset(&p->bricks[p->n], 0, sizeof p->bricks[p->n]);
    p->codes[p->n] = code;
    /* Keep the table at most half full. */
    if (!d && ++p->ix.n_slots * 2 > p->ix.cap && !index_grow(&p->ix)) return UINT32_MAX;
    return p->n++;
}

/* One brick's run of cells [i, j) and the bricks its spheres reach. */
typedef struct bin_run {
    uint64_t i, j;
    int64_t b[3];
    uint32_t me, used, t[27]; /* its brick; the neighbours reached (bit k) and their bricks */
} bin_run;

/* A run's bricks found (made where new) and its sign bits set; the lines
 * of its neighbours' reach planes prefetched, to be written by
 * run_apply after the next run is prepared (the lookups of one run
 * overlap the memory latency of the last). */
static bool run_prepare(bin_part *p, uint64_t i, uint64_t j, bin_run *r)
{
    uint64_t code = p->cells[i] >> 9;
    r->i = i, r->j = j;
    unmorton3(code, r->b);
    r->me = part_brick(p, r->b, code);
    if (r->me == UINT32_MAX) return false;
    bin_planes *hb = &p->bricks[r->me];
    for (uint64_t k = i; k < j; k++) {
        uint32_t l = (uint32_t)(p->cells[k] & 511), x = l & 7, y = (l >> 3) & 7, z = l >> 6;
        hb->sign[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
    }
    p->n_occupied++;
    r->used = 0;
    if (!p->rt) return true;
    for (uint64_t k = i; k < j; k++) {
        uint32_t l = (uint32_t)(p->cells[k] & 511);
        if (!p->octs) r->used |= p->rt->used[l];
        for (uint32_t o = p->octs ? p->octs[k] : 0; o; o &= o - 1) r->used |= p->rt->used[(uint32_t)__builtin_ctz(o) << 9 | l];
    }
    for (uint32_t u = r->used; u; u &= u - 1) {
        uint32_t nb = (uint32_t)__builtin_ctz(u);
        int64_t c[3] = {r->b[0] + (int64_t)(nb % 3) - 1, r->b[1] + (int64_t)(nb / 3 % 3) - 1,
                        r->b[2] + (int64_t)(nb / 9) - 1};
        r->t[nb] = nb == 13 ? r->me : part_brick(p, c, morton3(c));
        if (r->t[nb] == UINT32_MAX) return false;
        __builtin_prefetch(p->bricks[r->t[nb]].conf, 1);
    }
    return true;
}

/* The reach bits of a prepared run's spheres, in its brick and its
 * neighbours. */
static bool run_apply(bin_part *p, const bin_run *r)
{
    if (p->rt) {
        uint32_t acc[27][16];
        for (uint32_t u = r->used; u; u &= u - 1) memset(acc[__builtin_ctz(u)], 0, sizeof acc[0]);
        for (uint64_t k = r->i; k < r->j; k++) {
            uint32_t l = (uint32_t)(p->cells[k] & 511), octs = p->octs ? p->octs[k] : 0;
            /* Each octant holding centres (with no octants: the cell, entry l). */
            for (uint32_t e = p->octs ? (uint32_t)__builtin_ctz(octs) << 9 | l : l;;) {
                uint32_t u = p->rt->used[e];
                const uint32_t(*m)[16] = &p->rt->mask[p->rt->first[e]];
                for (; u; u &= u - 1, m++) {
                    uint32_t nb = (uint32_t)__builtin_ctz(u);
                    for (int w = 0; w < 16; w++) acc[nb][w] |= (*m)[w];
                }
                if (!p->octs || !(octs &= octs - 1)) break;
                e = (uint32_t)__builtin_ctz(octs) << 9 | l;
            }
        }
        for (uint32_t u = r->used; u; u &= u - 1) {
            uint32_t nb = (uint32_t)__builtin_ctz(u);
            for (int w = 0; w < 16; w++) p->bricks[r->t[nb]].conf[w] |= acc[nb][w];
        }
        return true;
    }
    /* A reach beyond a brick: every brick of each sphere's box. */
    const int64_t *b = r->b;
    for (uint64_t k = r->i; k < r->j; k++) {
        uint32_t l = (uint32_t)(p->cells[k] & 511);
        double cc[3] = {b[0] * 8 + (l & 7) + 0.5, b[1] * 8 + ((l >> 3) & 7) + 0.5, b[2] * 8 + (l >> 6) + 0.5};
        int64_t lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            lo[a] = (int64_t)floor((cc[a] - p->reach - p->half) / 8.0);
            hi[a] = (int64_t)floor((cc[a] + p->reach + p->half) / 8.0);
        }
        for (int64_t bz = lo[2]; bz <= hi[2]; bz++)
            for (int64_t by = lo[1]; by <= hi[1]; by++)
                for (int64_t bx = lo[0]; bx <= hi[0]; bx++) {
                    int64_t c[3] = {bx, by, bz};
                    uint32_t t = part_brick(p, c, morton3(c));
                    if (t == UINT32_MAX) return false;
                    bin_reach(p->bricks[t].conf, c, cc, p->reach, p->half);
                }
    }
    return true;
}

/* Makes *buf hold at least need elements of size bytes (contents kept). */
static bool reserve(void **buf, uint64_t *cap, uint64_t need, size_t size)
{
    if (need <= *cap) return true;
    uint64_t c = need + need / 4;
    void *nb = bf_realloc(*buf, (size_t)(c * size));
    if (!nb) return false;
    bf_advise_huge(nb, (size_t)(c * size));
    *buf = nb, *cap = c;
    return true;
}

/* A half's bricks. Its buffers are kept from the last binning (a moving
 * set re-binned per step touches no new memory) and cleared here. */
static void *part_main(void *arg)
{
    bin_part *p = arg;
    /* Sized for the bricks of a sparse set (each sphere reaching a
     * neighbour per axis): few grow after. */
    uint64_t runs = 0;
    for (uint64_t i = 0; i < p->n_cells; i++) runs += i == 0 || p->cells[i] >> 9 != p->cells[i - 1] >> 9;
    uint64_t guess = runs * (p->rt ? 4 : 8) + 1024;
    p->n = 0, p->n_occupied = 0, p->failed = false, p->too_many = false;
    bool ok = part_reserve(p, guess);
    bin_index *ix = &p->ix;
    if (ok && ix->dim[0]) {
        uint64_t cells = (uint64_t)(ix->dim[0] * ix->dim[1] * ix->dim[2]);
        ok = reserve((void **)&ix->dense, &ix->dense_cap, cells, 4);
        if (ok) memset(ix->dense, 0, cells * 4);
    } else if (ok) {
        if (ix->cap < 2 * guess) {
            free(ix->slots);
            ix->slots = NULL, ix->cap = 0, ix->n_slots = guess;
            ok = index_grow(ix);
        } else {
            memset(ix->slots, 0, ix->cap * sizeof *ix->slots);
        }
        ix->n_slots = 0;
    }
    if (!ok) {
        p->failed = true;
        return NULL;
    }
    bin_run run[2];
    int cur = 0;
    bool have = false;
    for (uint64_t i = 0; i < p->n_cells;) {
        uint64_t j = i + 1;
        while (j < p->n_cells && p->cells[j] >> 9 == p->cells[i] >> 9) j++;
        if (!run_prepare(p, i, j, &run[cur ^ 1]) || (have && !run_apply(p, &run[cur]))) {
            p->failed = true;
            return NULL;
        }
        cur ^= 1, have = true;
        if (p->n > p->max_bricks) {
            p->too_many = true;
            return NULL;
        }
        i = j;
    }
    if (have && !run_apply(p, &run[cur])) p->failed = true;
    return NULL;
}

static void part_free(bin_part *p)
{
    free(p->ix.dense), free(p->ix.slots), free(p->bricks_mem), free(p->codes);
}

static void brick_or(bin_planes *dst, const bin_planes *src)
{
    for (int w = 0; w < 16; w++) dst->sign[w] |= src->sign[w], dst->conf[w] |= src->conf[w];
}

/* ------------------------------------------------------------ octrees */

/* Distinct ancestors k levels up, for k in [k0, k1], of the bricks m[0, n)
 * (sorted Morton codes: ancestors k levels up share code >> 3k). */
typedef struct count_job {
    const uint64_t *m;
    uint64_t n;
    uint32_t k0, k1;
    uint64_t distinct[FUSION_MAX_LEVEL + 1];
} count_job;

static void *count_main(void *arg)
{
    count_job *c = arg;
    for (uint32_t k = c->k0; k <= c->k1; k++) {
        uint64_t d = 0;
        for (uint64_t i = 0; i < c->n; i++) d += i == 0 || (c->m[i] >> (3 * k)) != (c->m[i - 1] >> (3 * k));
        c->distinct[k] = d;
    }
    return NULL;
}

/* Nodes and chunks the octrees of these bricks (sorted Morton codes)
 * need: a chunk's root, and 8 children for every node with one
 * (fusion_load builds them so). The levels are counted on two threads. */
static void count_nodes(const uint64_t *m, uint64_t n, uint32_t level, uint64_t *n_nodes, uint64_t *n_chunks)
{
    count_job c[2] = {{.m = m, .n = n, .k0 = 1, .k1 = level / 2}, {.m = m, .n = n, .k0 = level / 2 + 1, .k1 = level}};
    run_two(count_main, &c[0], &c[1]);
    uint64_t nodes = 0;
    for (uint32_t k = 1; k <= level; k++) nodes += 8 * c[k <= level / 2 ? 0 : 1].distinct[k]; /* the children of each parent k levels up */
    *n_chunks = c[1].distinct[level];
    *n_nodes = nodes + *n_chunks; /* and the roots */
}

/* ------------------------------------------------------------ all of it */

struct particles_binner {
    uint64_t *keys, *tmp; /* per particle, then per brick (the octree count) */
    uint64_t keys_cap, tmp_cap;
    uint64_t *ckeys;      /* the coarse level's cell keys: one per brick of the centres */
    uint64_t ckeys_cap;
    uint8_t *coct;        /* per brick of the centres (coarse cell): the octants that hold centres */
    uint64_t coct_cap;
    uint16_t *cone;       /* per brick of the centres: its one cell (x | y << 3 | z << 6), or CONE_MANY */
    uint64_t cone_cap;
    reach_table *rt;      /* the coarse level's */
    double rt_reach, rt_half;
    bin_part part[2];
    hostmap_brick *all;   /* both levels' bricks: the centres', then the coarse level's */
    uint64_t all_cap;
    uint32_t *index;      /* the centres' index (particles_binned.index) */
    uint64_t index_cap;
    uint64_t *cpairs;     /* the coarse bricks' (Morton code, place) pairs, sorted by code: the code
                             alone takes 63 bits in a set wide against its cells */
    uint64_t cpairs_cap;
};

particles_binner *particles_binner_create(void) { return bf_calloc(1, sizeof(particles_binner)); }

void particles_binner_destroy(particles_binner *w)
{
    if (!w) return;
    free(w->keys), free(w->tmp), free(w->ckeys), free(w->coct), free(w->rt), free(w->all);
    free(w->index), free(w->cpairs), free(w->cone);
    part_free(&w->part[0]), part_free(&w->part[1]);
    free(w);
}

/* Sorted unique cell keys of the particles into w->tmp, and their brick box. */
static bf_status sorted_cells(particles_binner *w, const float *xyz, uint64_t n, bf_vec3 origin, double cell_m,
                              uint64_t *n_cells, int64_t lo[3], int64_t hi[3])
{
    if (!reserve((void **)&w->keys, &w->keys_cap, n + 1, 8) || !reserve((void **)&w->tmp, &w->tmp_cap, n + 1, 8))
        return bf_fail(BF_NO_MEMORY, "render: sorting %llu particles", (unsigned long long)n);
    uint64_t *v = w->keys, *tmp = w->tmp, h = n / 2;
    sort_job j[2] = {{.v = v, .tmp = tmp, .n = h, .xyz = xyz}, {.v = v + h, .tmp = tmp + h, .n = n - h, .xyz = xyz + 3 * h}};
    for (int t = 0; t < 2; t++) j[t].o[0] = origin.x, j[t].o[1] = origin.y, j[t].o[2] = origin.z, j[t].inv = 1.0 / cell_m;
    run_two(keys_main, &j[0], &j[1]);
    for (int a = 0; a < 3; a++) {
        lo[a] = j[0].lo[a] < j[1].lo[a] ? j[0].lo[a] : j[1].lo[a];
        hi[a] = j[0].hi[a] > j[1].hi[a] ? j[0].hi[a] : j[1].hi[a];
    }
    *n_cells = merge_unique(v, h, v + h, n - h, tmp);
    return BF_OK;
}

/* The halves' bricks made for the other half's codes, merged into it
 * where it has them; each brick then lives in one half. */
static void merge_halves(bin_part *p, uint64_t split)
{
    for (int a = 0; a < 2; a++) {
        bin_part *me = &p[a], *other = &p[1 - a];
        for (uint32_t i = 0; i < me->n; i++) {
            uint64_t c = me->codes[i];
            if (c == UINT64_MAX || (a == 0 ? c < split : c >= split)) continue;
            int64_t b[3];
            unmorton3(c, b);
            uint32_t k = part_find(other, b, c);
            if (k == UINT32_MAX) continue;
            brick_or(&other->bricks[k], &me->bricks[i]);
            me->codes[i] = UINT64_MAX; /* dropped */
        }
    }
}

/* A half's bricks (those it kept) as the host copy's, and their codes. */
typedef struct emit_job {
    const bin_part *p;
    hostmap_brick *out;
    uint64_t *codes;
    uint32_t level;
} emit_job;

/* A brick of centres' confidence plane: word 0 says which sub-brick words
 * of its sign plane hold centres (bit w), the rest are 0. A sparse set has
 * a centre or two a brick, so the particle traverser reads those words
 * only instead of all 16 (shaders/render_traverse.glsl.h). */
static void centres_summary(const uint32_t sign[16], uint32_t conf[16])
{
    memset(conf, 0, 16 * sizeof *conf);
    for (int w = 0; w < 16; w++) conf[0] |= (uint32_t)(sign[w] != 0) << w;
}

/* A host brick's place (chunk key, cell, level) from its Morton code on
 * its level's grid. */
static void brick_place(hostmap_brick *hb, uint64_t code, uint32_t level)
{
    int64_t b[3];
    unmorton3(code, b);
    uint32_t per = 1u << level;
    for (int a = 0; a < 3; a++) hb->key[a] = (int32_t)(b[a] >> level), hb->cell[a] = (uint32_t)b[a] & (per - 1);
    hb->level = level;
    hb->error = 0;
}

static void *emit_main(void *arg)
{
    emit_job *e = arg;
    uint64_t k = 0;
    for (uint32_t i = 0; i < e->p->n; i++) {
        uint64_t c = e->p->codes[i];
        if (c == UINT64_MAX) continue;
        hostmap_brick *hb = &e->out[k];
        brick_place(hb, c, e->level);
        memcpy(hb->sign, e->p->bricks[i].sign, sizeof hb->sign);
        memcpy(hb->conf, e->p->bricks[i].conf, sizeof hb->conf);
        e->codes[k++] = c;
    }
    return NULL;
}

/* What one level's binning made. */
typedef struct level_binned {
    uint64_t k;            /* bricks, written to w->all from the caller's offset */
    uint32_t n_occupied;
    uint64_t n_nodes, n_chunks;
} level_binned;

/* Bins the sorted cell keys cells[0, n_cells) (bricks in box lo..hi) on
 * octree level `level` (the coarse level), each set cell's spheres
 * reaching `reach` cells beyond a box of half cells about its middle, into
 * w->all from offset `off` (and the bricks' sorted codes into w->tmp for
 * the caller). */
static bf_status bin_one_level(particles_binner *w, const uint64_t *cells, const uint8_t *octs, uint64_t n_cells,
                               const int64_t lo[3], const int64_t hi[3], double reach, double half, uint32_t level,
                               uint64_t max_bricks, uint64_t off, bool *too_many, level_binned *out)
{
    memset(out, 0, sizeof *out);
    if (w->rt_reach != reach || w->rt_half != half || !w->rt) {
        free(w->rt);
        w->rt = reach_table_make(reach, half, octs != NULL); /* NULL: per cell (slower, any reach) */
        w->rt_reach = reach, w->rt_half = half;
        if (!w->rt && reach + half <= 8.0) return bf_fail(BF_NO_MEMORY, "render: particle reach table");
    }
    /* The halves split between two bricks. */
    uint64_t mid = n_cells / 2;
    while (mid > 0 && mid < n_cells && cells[mid] >> 9 == cells[mid - 1] >> 9) mid++;
    bin_part *p = w->part;
    p[0].cells = cells, p[0].n_cells = mid;
    p[1].cells = cells + mid, p[1].n_cells = n_cells - mid;
    /* Octants only through the table (beyond it bin_reach takes the whole cell: more bits, still all). */
    p[0].octs = octs && w->rt ? octs : NULL, p[1].octs = octs && w->rt ? octs + mid : NULL;
    /* A dense index where the box of the bricks the spheres reach takes at
     * most 4 M entries or 4 a cell (16 bytes), else the hash. */
    int64_t pad = (int64_t)ceil((reach + half) / 8.0), box = n_cells ? 1 : 0;
    for (int a = 0; a < 3 && n_cells; a++) box *= hi[a] - lo[a] + 1 + 2 * pad;
    bool dense = n_cells && box <= (int64_t)(4 * n_cells > (1u << 22) ? 4 * n_cells : (1u << 22));
    for (int h = 0; h < 2; h++) {
        p[h].rt = w->rt, p[h].reach = reach, p[h].half = half, p[h].max_bricks = max_bricks;
        for (int a = 0; a < 3; a++) p[h].ix.lo[a] = lo[a] - pad, p[h].ix.dim[a] = dense ? hi[a] - lo[a] + 1 + 2 * pad : 0;
    }
    run_two(part_main, &p[0], &p[1]);
    if (p[0].failed || p[1].failed) return bf_fail(BF_NO_MEMORY, "render: particle bricks");
    if (p[0].too_many || p[1].too_many) {
        *too_many = true;
        return bf_fail(BF_NO_MEMORY, "render: the particles need more than %llu bricks", (unsigned long long)max_bricks);
    }
    merge_halves(p, mid < n_cells ? cells[mid] >> 9 : UINT64_MAX);
    /* Both halves' bricks into one array, and their codes sorted for the octrees. */
    uint64_t k0 = 0, k = 0;
    for (uint32_t i = 0; i < p[0].n; i++) k0 += p[0].codes[i] != UINT64_MAX;
    for (uint32_t i = 0; i < p[1].n; i++) k += p[1].codes[i] != UINT64_MAX;
    k += k0;
    if (off + k > max_bricks) {
        *too_many = true;
        return bf_fail(BF_NO_MEMORY, "render: the particles need more than %llu bricks", (unsigned long long)max_bricks);
    }
    if (off + k >= UINT32_MAX || !reserve((void **)&w->all, &w->all_cap, off + k + 1, sizeof *w->all) ||
        !reserve((void **)&w->keys, &w->keys_cap, k + 1, 8) || !reserve((void **)&w->tmp, &w->tmp_cap, k + 1, 8))
        return bf_fail(BF_NO_MEMORY, "render: %llu particle bricks", (unsigned long long)(off + k));
    uint64_t *codes = w->keys;
    emit_job e[2] = {{&p[0], w->all + off, codes, level}, {&p[1], w->all + off + k0, codes + k0, level}};
    run_two(emit_main, &e[0], &e[1]);
    out->n_occupied = p[0].n_occupied + p[1].n_occupied;
    uint64_t top = 0;
    for (uint64_t i = 0; i < k; i++) top |= codes[i];
    sort_job j[2] = {{.v = codes, .tmp = w->tmp, .n = k0, .bits = bits_of(top)},
                     {.v = codes + k0, .tmp = w->tmp + k0, .n = k - k0, .bits = bits_of(top)}};
    run_two(sort_main, &j[0], &j[1]);
    uint64_t n_unique = merge_unique(codes, k0, codes + k0, k - k0, w->tmp);
    count_nodes(w->tmp, n_unique, level, &out->n_nodes, &out->n_chunks);
    out->k = k;
    return n_unique == k ? BF_OK : bf_fail(BF_NUMERIC, "render: %llu particle bricks made twice", (unsigned long long)(k - n_unique));
}

/* A half of the centres' level: each run of its sorted cells is one brick
 * (the centres reach nothing), written straight into the host copy in
 * order, with its code. */
typedef struct centres_job {
    const uint64_t *cells;
    uint64_t n_cells;
    hostmap_brick *out;
    uint64_t *codes;
    uint32_t level;
} centres_job;

static void *centres_main(void *arg)
{
    centres_job *c = arg;
    uint64_t k = 0;
    for (uint64_t i = 0; i < c->n_cells; k++) {
        uint64_t code = c->cells[i] >> 9;
        hostmap_brick *hb = &c->out[k];
        brick_place(hb, code, c->level);
        memset(hb->sign, 0, sizeof hb->sign);
        for (; i < c->n_cells && c->cells[i] >> 9 == code; i++) {
            uint32_t l = (uint32_t)(c->cells[i] & 511), x = l & 7, y = (l >> 3) & 7, z = l >> 6;
            hb->sign[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
        }
        centres_summary(hb->sign, hb->conf);
        c->codes[k] = code;
    }
    return NULL;
}

/* The centres' level of the sorted cell keys cells[0, n_cells) (n_runs
 * bricks) into w->all from 0, their codes (sorted, as the cells were) into
 * w->tmp. The cells may be w->tmp: they are read before it is written. */
static bf_status bin_centres(particles_binner *w, const uint64_t *cells, uint64_t n_cells, uint64_t n_runs,
                             uint32_t level, uint64_t max_bricks, bool *too_many, level_binned *out)
{
    memset(out, 0, sizeof *out);
    if (n_runs > max_bricks) {
        *too_many = true;
        return bf_fail(BF_NO_MEMORY, "render: the particles need more than %llu bricks", (unsigned long long)max_bricks);
    }
    if (n_runs >= UINT32_MAX || !reserve((void **)&w->all, &w->all_cap, n_runs + 1, sizeof *w->all) ||
        !reserve((void **)&w->keys, &w->keys_cap, n_runs + 1, 8))
        return bf_fail(BF_NO_MEMORY, "render: %llu particle bricks", (unsigned long long)n_runs);
    /* The halves split between two bricks. */
    uint64_t mid = n_cells / 2, k0 = 0;
    while (mid > 0 && mid < n_cells && cells[mid] >> 9 == cells[mid - 1] >> 9) mid++;
    for (uint64_t i = 0; i < mid; i++) k0 += i == 0 || cells[i] >> 9 != cells[i - 1] >> 9;
    centres_job j[2] = {{cells, mid, w->all, w->keys, level},
                        {cells + mid, n_cells - mid, w->all + k0, w->keys + k0, level}};
    run_two(centres_main, &j[0], &j[1]);
    memcpy(w->tmp, w->keys, n_runs * 8);
    count_nodes(w->tmp, n_runs, level, &out->n_nodes, &out->n_chunks);
    out->k = n_runs;
    out->n_occupied = (uint32_t)n_runs;
    return BF_OK;
}

/* The coarse level's cell keys, one per brick of the centres (sorted
 * Morton codes in w->tmp): the coarse brick is the centres' brick three
 * levels up (its Morton code >> 9), the cell the brick's place in it. */
static bf_status coarse_cells(particles_binner *w, uint64_t n, int64_t lo[3], int64_t hi[3])
{
    if (!reserve((void **)&w->ckeys, &w->ckeys_cap, n + 1, 8)) return bf_fail(BF_NO_MEMORY, "render: coarse cells");
    for (int a = 0; a < 3; a++) lo[a] = INT64_MAX, hi[a] = -1;
    for (uint64_t i = 0; i < n; i++) {
        int64_t b[3];
        unmorton3(w->tmp[i], b);
        for (int a = 0; a < 3; a++) {
            int64_t c = b[a] >> 3;
            if (c < lo[a]) lo[a] = c;
            if (c > hi[a]) hi[a] = c;
        }
        w->ckeys[i] = (w->tmp[i] >> 9) << 9 | (uint64_t)((b[0] & 7) | (b[1] & 7) << 3 | (b[2] & 7) << 6);
    }
    return BF_OK;
}

#define CONE_MANY 0xffffu

/* A brick's coordinate on its level's grid (brick units from the origin). */
static void brick_coord(const hostmap_brick *b, int64_t g[3])
{
    for (int a = 0; a < 3; a++) g[a] = (int64_t)b->key[a] << b->level | (int64_t)b->cell[a];
}

static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

/* The centres' index (particles_binned.index) of the n_fine bricks of
 * centres and the n_coarse coarse bricks after them in w->all (brick k of
 * w->all goes to slot k: fusion_load). The bricks of centres are those of
 * w->ckeys and w->cone, in the same order: sorted by Morton code. */
static bf_status centres_index(particles_binner *w, uint64_t n_fine, uint64_t n_coarse)
{
    uint64_t words = PARTICLES_INDEX_HEADER + 16 * n_coarse + n_fine;
    if (!reserve((void **)&w->index, &w->index_cap, words, 4) ||
        !reserve((void **)&w->cpairs, &w->cpairs_cap, 2 * (n_coarse + 1), 8))
        return bf_fail(BF_NO_MEMORY, "render: the particles' index");
    const hostmap_brick *coarse = w->all + n_fine;
    uint32_t *ix = w->index, *first = ix + PARTICLES_INDEX_HEADER, *slots;
    uint64_t slots_at = PARTICLES_INDEX_HEADER + 16 * n_coarse;
    ix[0] = (uint32_t)n_fine, ix[1] = (uint32_t)slots_at;
    slots = ix + slots_at;
    /* Each coarse word's first entry: the set cells of the coarse bricks in
     * slot order, each brick's words in order, each word's bits in order. */
    uint32_t at = 0;
    for (uint64_t j = 0; j < n_coarse; j++) {
        for (int k = 0; k < 16; k++) first[16 * j + k] = at, at += (uint32_t)__builtin_popcount(coarse[j].sign[k]);
        int64_t g[3];
        brick_coord(&coarse[j], g);
        w->cpairs[2 * j] = morton3(g), w->cpairs[2 * j + 1] = j;
    }
    if (at != n_fine)
        return bf_fail(BF_NUMERIC, "render: %u coarse cells hold centres, %llu bricks of centres", at,
                       (unsigned long long)n_fine);
    qsort(w->cpairs, n_coarse, 16, cmp_u64); /* by the first of each pair: the code */
    /* Each brick of centres at its coarse cell's entry (a coarse brick's
     * bricks of centres are consecutive). */
    uint64_t last = UINT64_MAX, j = 0;
    for (uint64_t i = 0; i < n_fine; i++) {
        uint64_t code = w->ckeys[i] >> 9;
        if (code != last) {
            uint64_t lo = 0, hi = n_coarse;
            while (lo < hi) {
                uint64_t mid = (lo + hi) / 2;
                if (w->cpairs[2 * mid] < code) lo = mid + 1;
                else hi = mid;
            }
            if (lo == n_coarse || w->cpairs[2 * lo] != code)
                return bf_fail(BF_NUMERIC, "render: a brick of centres without its coarse brick");
            j = w->cpairs[2 * lo + 1], last = code;
        }
        uint32_t l = (uint32_t)(w->ckeys[i] & 511), x = l & 7, y = l >> 3 & 7, z = l >> 6;
        uint32_t wd = brick_word(x, y, z), bit = brick_bit(x, y, z), sw = coarse[j].sign[wd];
        /* A brick holding one centre: the centre itself (no read of the brick). */
        uint32_t e = (uint32_t)i, c = w->cone[i];
        if (c != CONE_MANY)
            e = PARTICLES_INDEX_ONE | brick_word(c & 7, c >> 3 & 7, c >> 6) << 5 | brick_bit(c & 7, c >> 3 & 7, c >> 6);
        slots[first[16 * j + wd] + (uint32_t)__builtin_popcount(sw & ((1u << bit) - 1u))] = e;
    }
    /* The bricks of centres are where the keys say (every 4096th checked). */
    for (uint64_t i = 0; i < n_fine; i += 4096) {
        int64_t g[3], c[3];
        brick_coord(&w->all[i], g);
        for (int a = 0; a < 3; a++) c[a] = g[a] >> 3;
        if (morton3(c) != w->ckeys[i] >> 9 || (uint64_t)((g[0] & 7) | (g[1] & 7) << 3 | (g[2] & 7) << 6) != (w->ckeys[i] & 511))
            return bf_fail(BF_NUMERIC, "render: brick of centres %llu out of order", (unsigned long long)i);
    }
    return BF_OK;
}

bf_status particles_bin(particles_binner *w, const float *xyz, uint64_t n, bf_vec3 origin, double cell_m,
                        double radius_m, uint32_t level, uint64_t max_bricks, particles_binned *out)
{
    memset(out, 0, sizeof *out);
    if (level < PARTICLES_COARSE_LEVELS)
        return bf_fail(BF_INVALID_ARG, "render: particle bricks on level %u (at least %d)", level,
                       PARTICLES_COARSE_LEVELS);
    uint64_t n_cells = 0;
    int64_t lo[3], hi[3];
    bf_status s = sorted_cells(w, xyz, n, origin, cell_m, &n_cells, lo, hi);
    if (s != BF_OK) return s;
    /* A cell key is a brick's Morton code (18 bits an axis) and its cell in
     * the brick (9 bits) in one 64-bit word: a set wider than 2^21 cells
     * along an axis does not fit. */
    for (int a = 0; a < 3; a++)
        if (lo[a] < 0 || hi[a] >= (int64_t)1 << 18)
            return bf_fail(BF_INVALID_ARG, "render: the particles span %.4g m along %c, over 2^21 cells of %.3g mm: "
                           "give them larger cells (a larger radius or cell size)",
                           (double)(hi[a] - lo[a] + 1) * 8 * cell_m, "xyz"[a], 1e3 * cell_m);
    /* The centres: no reach (the cells are in tmp; the keys buffer takes
     * the brick codes after). */
    level_binned fine, coarse;
    /* The octants of each brick of centres that hold centres (the cells are sorted: a brick's are
       consecutive), for the coarse level's reach below. */
    /* And each brick's one cell where it holds one (the centres' index). */
    if (!reserve((void **)&w->coct, &w->coct_cap, n_cells + 1, 1) ||
        !reserve((void **)&w->cone, &w->cone_cap, n_cells + 1, 2))
        return bf_fail(BF_NO_MEMORY, "render: octants");
    uint64_t nb = 0;
    for (uint64_t i = 0; i < n_cells; i++) {
        uint32_t l = (uint32_t)(w->tmp[i] & 511);
        if (i == 0 || w->tmp[i] >> 9 != w->tmp[i - 1] >> 9) w->coct[nb] = 0, w->cone[nb++] = (uint16_t)l;
        else w->cone[nb - 1] = CONE_MANY;
        w->coct[nb - 1] |= (uint8_t)(1u << ((l >> 2 & 1) | (l >> 5 & 1) << 1 | (l >> 8 & 1) << 2));
    }
    s = bin_centres(w, w->tmp, n_cells, nb, level, max_bricks, &out->too_many, &fine);
    if (s != BF_OK) return s;
    /* The coarse level: a cell per brick of centres, reaching the radius
     * (in coarse cells: a brick of centres) beyond its whole cell. */
    if (s == BF_OK && (s = coarse_cells(w, fine.k, lo, hi)) != BF_OK) return s;
    double reach = radius_m / (8.0 * cell_m);
    if (nb != fine.k) return bf_fail(BF_INVALID_ARG, "render: %llu bricks of centres, %llu with octants",
                                     (unsigned long long)fine.k, (unsigned long long)nb);
    s = bin_one_level(w, w->ckeys, w->coct, fine.k, lo, hi, reach, 0.5, level - PARTICLES_COARSE_LEVELS, max_bricks,
                      fine.k, &out->too_many, &coarse);
    if (s != BF_OK) return s;
    if ((s = centres_index(w, fine.k, coarse.k)) != BF_OK) return s;
    out->index = w->index;
    out->n_index = PARTICLES_INDEX_HEADER + 16 * coarse.k + fine.k;
    out->bricks = w->all;
    out->n_bricks = (uint32_t)(fine.k + coarse.k);
    out->n_occupied = fine.n_occupied;
    out->n_coarse = (uint32_t)coarse.k;
    out->n_cells = n_cells;
    /* Nodes: each level's octrees counted apart (the coarse bricks' nodes
     * are mostly the centres' ancestors: an upper bound). */
    out->n_nodes = fine.n_nodes + coarse.n_nodes;
    out->n_chunks = fine.n_chunks + coarse.n_chunks;
    return BF_OK;
}
