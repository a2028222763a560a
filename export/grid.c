/* The brick index shared by the mesh and point exports: a hash from (level,
 * global brick coordinates) to the snapshot's bricks, the finest-confident-
 * voxel lookup and the smoothed sign field. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "export_int.h"

static uint64_t hash_key(uint32_t level, const int64_t b[3])
{
    uint64_t h = (uint64_t)level * 0x9E3779B97F4A7C15ull;
    for (int a = 0; a < 3; a++) {
        h ^= (uint64_t)b[a] + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
        h *= 0xBF58476D1CE4E5B9ull;
        h ^= h >> 31;
    }
    return h;
}

uint32_t export__grid_find(const export__grid *g, uint32_t level, const int64_t b[3])
{
    if (!g->slots) return EXPORT__NONE;
    for (uint64_t i = hash_key(level, b) & g->mask;; i = (i + 1) & g->mask) {
        const export__slot *sl = &g->slots[i];
        if (sl->idx == EXPORT__NONE) return EXPORT__NONE;
        if (sl->level == level && sl->b[0] == b[0] && sl->b[1] == b[1] && sl->b[2] == b[2]) return sl->idx;
    }
}

/* Inserts brick i, or keeps the better of i and the brick already there. */
static void grid_insert(export__grid *g, uint32_t i)
{
    const hostmap_brick *br = &g->s->bricks[i];
    const int64_t *b = g->bc[i];
    for (uint64_t k = hash_key(br->level, b) & g->mask;; k = (k + 1) & g->mask) {
        export__slot *sl = &g->slots[k];
        if (sl->idx == EXPORT__NONE) {
            sl->idx = i;
            sl->level = br->level;
            memcpy(sl->b, b, sizeof sl->b);
            return;
        }
        if (sl->level == br->level && sl->b[0] == b[0] && sl->b[1] == b[1] && sl->b[2] == b[2]) {
            /* Snapshots should not hold two bricks for one place; if one
             * does, the one with the lower error is the better data. */
            g->n_duplicates++;
            const hostmap_brick *old = &g->s->bricks[sl->idx];
            if (br->error < old->error || (br->error == old->error && i < sl->idx)) sl->idx = i;
            return;
        }
    }
}

static int cmp_brick(const void *pa, const void *pb, void *ctx)
{
    const export__grid *sort_grid = ctx;
    uint32_t a = *(const uint32_t *)pa, b = *(const uint32_t *)pb;
    const hostmap_brick *A = &sort_grid->s->bricks[a], *B = &sort_grid->s->bricks[b];
    if (A->level != B->level) return A->level < B->level ? -1 : 1;
    for (int k = 2; k >= 0; k--) {
        int64_t x = sort_grid->bc[a][k], y = sort_grid->bc[b][k];
        if (x != y) return x < y ? -1 : 1;
    }
    return 0;
}

bool export__grid_sample(const export__grid *g, const int64_t q[3], export__voxel *out)
{
    for (uint32_t k = 0; k < g->n_levels; k++) {
        uint32_t L = g->levels_desc[k];
        uint32_t sh = g->level_max - L + 1;
        int64_t v[3], b[3];
        for (int a = 0; a < 3; a++) {
            v[a] = export__shr(q[a], sh);
            b[a] = export__shr(v[a], 3);
        }
        uint32_t i = export__grid_find(g, L, b);
        if (i == EXPORT__NONE) continue;
        const hostmap_brick *br = &g->s->bricks[i];
        uint32_t x = (uint32_t)(v[0] & 7), y = (uint32_t)(v[1] & 7), z = (uint32_t)(v[2] & 7);
        if (!export__bit(br->conf, x, y, z)) continue;
        out->brick = i;
        out->level = L;
        out->x = x, out->y = y, out->z = z;
        memcpy(out->g, v, sizeof v);
        out->is_free = export__bit(br->sign, x, y, z);
        return true;
    }
    return false;
}

double export__grid_voxel_field(const export__grid *g, uint32_t level, const int64_t v[3])
{
    int64_t b[3] = {export__shr(v[0], 3), export__shr(v[1], 3), export__shr(v[2], 3)};
    uint32_t i = export__grid_find(g, level, b);
    if (i == EXPORT__NONE) return NAN;
    int8_t f = g->sfield[(size_t)i * BRICK_VOXELS + (size_t)((v[2] & 7) * 64 + (v[1] & 7) * 8 + (v[0] & 7))];
    return f == EXPORT__NO_FIELD ? NAN : f / 127.0;
}

/* Field of level-L voxel v, read through nbh when v lies in its 27 bricks
 * (the same bytes the hash would find), else through the hash. */
static double voxel_field_nb(const export__grid *g, uint32_t level, const int64_t v[3], const export__nbhood *nbh)
{
    if (nbh) {
        int k = 0, mul = 1;
        bool near = true;
        for (int a = 0; a < 3 && near; a++) {
            int64_t d = export__shr(v[a], 3) - nbh->b[a];
            near = d >= -1 && d <= 1;
            k += (int)(d + 1) * mul;
            mul *= 3;
        }
        if (near) {
            uint32_t i = nbh->idx[k];
            if (i == EXPORT__NONE) return NAN;
            int8_t f = g->sfield[(size_t)i * BRICK_VOXELS + (size_t)((v[2] & 7) * 64 + (v[1] & 7) * 8 + (v[0] & 7))];
            return f == EXPORT__NO_FIELD ? NAN : f / 127.0;
        }
    }
    return export__grid_voxel_field(g, level, v);
}

double export__grid_field_nb(const export__grid *g, uint32_t level, const int64_t q[3], const export__nbhood *nbh)
{
    uint32_t sh = g->level_max - level + 1;
    int64_t v0[3];
    double f[3];
    for (int a = 0; a < 3; a++) {
        int64_t num = q[a] - ((int64_t)1 << (sh - 1));
        v0[a] = export__shr(num, sh);
        f[a] = (double)(num - v0[a] * ((int64_t)1 << sh)) / (double)((int64_t)1 << sh);
    }
    double sum = 0, wsum = 0;
    for (int c = 0; c < 8; c++) {
        double w = 1;
        int64_t v[3];
        for (int a = 0; a < 3; a++) {
            int bit = (c >> a) & 1;
            v[a] = v0[a] + bit;
            w *= bit ? f[a] : 1 - f[a];
        }
        if (w <= 0) continue;
        double s = voxel_field_nb(g, level, v, nbh);
        if (isnan(s)) continue;
        sum += w * s;
        wsum += w;
    }
    return wsum > 0 ? sum / wsum : NAN;
}

double export__grid_field(const export__grid *g, uint32_t level, const int64_t q[3])
{
    return export__grid_field_nb(g, level, q, NULL);
}

void export__grid_nbhood(const export__grid *g, uint32_t level, const int64_t b[3], export__nbhood *out)
{
    memcpy(out->b, b, sizeof out->b);
    for (int k = 0; k < 27; k++) {
        int64_t nb[3] = {b[0] + k % 3 - 1, b[1] + k / 3 % 3 - 1, b[2] + k / 9 - 1};
        out->idx[k] = export__grid_find(g, level, nb);
    }
}

/* Field of one brick: each confident voxel's mean of +-1 over the confident
 * voxels of its level in the 3x3x3 box around it. */
static void field_brick(void *ctx, size_t k)
{
    export__grid *g = ctx;
    uint32_t i = g->order[k];
    const hostmap_brick *br = &g->s->bricks[i];
    const hostmap_brick *nb[27];
    for (int dz = -1; dz <= 1; dz++)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int64_t b[3] = {g->bc[i][0] + dx, g->bc[i][1] + dy, g->bc[i][2] + dz};
                uint32_t j = export__grid_find(g, br->level, b);
                nb[(dz + 1) * 9 + (dy + 1) * 3 + dx + 1] = j == EXPORT__NONE ? NULL : &g->s->bricks[j];
            }
    /* val: +1 free, -1 inside, 0 unknown, over the brick and a 1-voxel rim. */
    int8_t val[10][10][10];
    for (int z = -1; z <= 8; z++)
        for (int y = -1; y <= 8; y++)
            for (int x = -1; x <= 8; x++) {
                int bx = x < 0 ? 0 : x > 7 ? 2 : 1, by = y < 0 ? 0 : y > 7 ? 2 : 1, bz = z < 0 ? 0 : z > 7 ? 2 : 1;
                const hostmap_brick *n = nb[bz * 9 + by * 3 + bx];
                int8_t v = 0;
                if (n) {
                    uint32_t lx = (uint32_t)(x & 7), ly = (uint32_t)(y & 7), lz = (uint32_t)(z & 7);
                    if (export__bit(n->conf, lx, ly, lz)) v = export__bit(n->sign, lx, ly, lz) ? 1 : -1;
                }
                val[z + 1][y + 1][x + 1] = v;
            }
    int8_t *out = g->sfield + (size_t)i * BRICK_VOXELS;
    for (int z = 0; z < 8; z++)
        for (int y = 0; y < 8; y++)
            for (int x = 0; x < 8; x++) {
                int8_t *o = &out[z * 64 + y * 8 + x];
                if (val[z + 1][y + 1][x + 1] == 0) {
                    *o = EXPORT__NO_FIELD;
                    continue;
                }
                int sum = 0, cnt = 0;
                for (int dz = 0; dz < 3; dz++)
                    for (int dy = 0; dy < 3; dy++)
                        for (int dx = 0; dx < 3; dx++) {
                            int8_t v = val[z + dz][y + dy][x + dx];
                            sum += v;
                            cnt += v != 0;
                        }
                *o = (int8_t)lrint(127.0 * sum / cnt);
            }
}

void export__grid_free(export__grid *g)
{
    if (!g) return;
    free(g->order);
    free(g->bc);
    free(g->slots);
    free(g->has_finer);
    free(g->sfield);
    memset(g, 0, sizeof *g);
}

bf_status export__grid_build(const hostmap *s, bool with_field, export__grid *g)
{
    memset(g, 0, sizeof *g);
    if (!s) return bf_fail(BF_INVALID_ARG, "export: snapshot is NULL");
    if (!(s->chunk_m > 0) || !isfinite(s->chunk_m))
        return bf_fail(BF_INVALID_ARG, "export: chunk_m %g is not a positive size", (double)s->chunk_m);
    if (s->n_bricks && !s->bricks) return bf_fail(BF_INVALID_ARG, "export: %u bricks but no array", s->n_bricks);
    g->s = s;
    uint32_t present = 0;
    for (uint32_t i = 0; i < s->n_bricks; i++) {
        const hostmap_brick *b = &s->bricks[i];
        if (b->level > EXPORT__MAX_LEVEL)
            return bf_fail(BF_INVALID_ARG, "export: brick %u: level %u beyond %u", i, b->level, EXPORT__MAX_LEVEL);
        for (int a = 0; a < 3; a++)
            if (b->cell[a] >= (1u << b->level))
                return bf_fail(BF_INVALID_ARG, "export: brick %u: cell %u outside a level-%u chunk", i, b->cell[a],
                               b->level);
        present |= 1u << b->level;
    }
    for (int L = (int)EXPORT__MAX_LEVEL; L >= 0; L--)
        if (present & (1u << L)) g->levels_desc[g->n_levels++] = (uint32_t)L;
    g->level_max = g->n_levels ? g->levels_desc[0] : 0;
    g->half_m = (double)s->chunk_m / 8.0 / (double)(1u << g->level_max) / 2.0;
    /* Half-unit coordinates reach |key| * 2^(M + 4); the mesh packs lattice
     * coordinates (|key| * 2^(L + 3)) into 42 bits. Keep both far inside. */
    for (uint32_t i = 0; i < s->n_bricks; i++)
        for (int a = 0; a < 3; a++) {
            int64_t k = s->bricks[i].key[a];
            if ((k < 0 ? -k : k) + 1 > ((int64_t)1 << (40 - 4 - g->level_max)))
                return bf_fail(BF_UNSUPPORTED, "export: brick %u: chunk key %lld too far out for level %u", i,
                               (long long)k, g->level_max);
        }
    if (s->n_bricks == 0) return BF_OK;

    uint64_t cap = 16;
    while (cap < 2ull * s->n_bricks) cap <<= 1;
    g->mask = cap - 1;
    g->slots = bf_malloc(cap * sizeof *g->slots);
    g->bc = bf_malloc((size_t)s->n_bricks * sizeof *g->bc);
    g->has_finer = bf_calloc(s->n_bricks, 1);
    g->order = bf_malloc((size_t)s->n_bricks * sizeof *g->order);
    if (with_field) g->sfield = bf_malloc((size_t)s->n_bricks * BRICK_VOXELS);
    if (!g->slots || !g->bc || !g->has_finer || !g->order || (with_field && !g->sfield)) goto fail_mem;
    for (uint64_t k = 0; k < cap; k++) g->slots[k].idx = EXPORT__NONE;
    for (uint32_t i = 0; i < s->n_bricks; i++) {
        const hostmap_brick *b = &s->bricks[i];
        for (int a = 0; a < 3; a++) g->bc[i][a] = (int64_t)b->key[a] * ((int64_t)1 << b->level) + b->cell[a];
        grid_insert(g, i);
    }
    for (uint64_t k = 0; k < cap; k++)
        if (g->slots[k].idx != EXPORT__NONE) g->order[g->n++] = g->slots[k].idx;
    qsort_r(g->order, g->n, sizeof *g->order, cmp_brick, g);
    /* A brick overlapped by any finer brick: lookups inside it must ask the
     * finer levels first. */
    for (uint32_t k = 0; k < g->n; k++) {
        uint32_t i = g->order[k];
        uint32_t L = s->bricks[i].level;
        for (uint32_t c = 0; c < g->n_levels; c++) {
            uint32_t Lc = g->levels_desc[c];
            if (Lc >= L) continue;
            int64_t b[3];
            for (int a = 0; a < 3; a++) b[a] = export__shr(g->bc[i][a], L - Lc);
            uint32_t j = export__grid_find(g, Lc, b);
            if (j != EXPORT__NONE) g->has_finer[j] = 1;
        }
    }
    if (with_field) bf_parallel_for(g->n, field_brick, g);
    return BF_OK;
fail_mem:
    export__grid_free(g);
    return bf_fail(BF_NO_MEMORY, "export: no memory to index %u bricks", s->n_bricks);
}
