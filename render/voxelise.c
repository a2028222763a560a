/* The mesh renderer's voxeliser (render.h, render_voxelise_mesh): a closed
 * triangle mesh into the inside/outside sign bits of the map's bricks at
 * one level, so the `surface` traverser draws it like a reconstructed map.
 *
 * The host bins triangles into the bricks their bounding boxes touch (the
 * surface bricks: every crossing of a column with the surface lies in one
 * of them) and, after the GPU pass (shaders/render_voxelise.comp), adds to
 * each brick the parity its columns carry in from below: the XOR of the
 * column parities of the surface bricks beneath it in the same stack.
 * Bricks without surface are not stored: the traverser treats missing
 * bricks as space without data, which is what lies inside and around a
 * mesh. Method: solid voxelisation by crossing parity (Schwarz and Seidel,
 * "Fast parallel surface and solid voxelization on GPUs", 2010). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "render.h"
#include "shaders/render.glsl.h"

/* The columns' axis. The parity runs along the third coordinate of the
 * binning and the GPU pass; with level of detail that is the map axis most
 * across the camera's view (a column along the view would span near and
 * far), reached by permuting the coordinates: coordinate i of the binning
 * is map axis PERM[axis][i]. */
static const uint32_t PERM[3][3] = {{1, 2, 0}, {2, 0, 1}, {0, 1, 2}};

/* Brick coordinates packed into one key (21 bits each, offset to be
 * non-negative): the bins' hash and the sort order (x, y, then z). */
#define KEY_BITS 21
#define KEY_OFF (1 << (KEY_BITS - 1))

static uint64_t brick_key(int64_t x, int64_t y, int64_t z)
{
    return ((uint64_t)(x + KEY_OFF) << (2 * KEY_BITS)) | ((uint64_t)(y + KEY_OFF) << KEY_BITS) | (uint64_t)(z + KEY_OFF);
}
static int32_t key_x(uint64_t k) { return (int32_t)((k >> (2 * KEY_BITS)) & ((1u << KEY_BITS) - 1)) - KEY_OFF; }
static int32_t key_y(uint64_t k) { return (int32_t)((k >> KEY_BITS) & ((1u << KEY_BITS) - 1)) - KEY_OFF; }
static int32_t key_z(uint64_t k) { return (int32_t)(k & ((1u << KEY_BITS) - 1)) - KEY_OFF; }

/* Open-addressing hash of brick keys -> their index in order of arrival
 * (the bins are counted, then filled, in two passes over the triangles:
 * linear in the pairs, where sorting them cost most of the time). */
typedef struct brick_hash {
    uint64_t *keys; /* 0: empty (a real key has the offset bits set) */
    uint32_t *idx;
    uint32_t cap, n; /* cap a power of two */
} brick_hash;

static uint32_t hash_slot(uint64_t k, uint32_t cap)
{
    k ^= k >> 33, k *= 0xff51afd7ed558ccdull, k ^= k >> 33; /* MurmurHash3's finaliser */
    return (uint32_t)k & (cap - 1);
}

static bf_status hash_grow(brick_hash *h)
{
    brick_hash g = {.cap = h->cap ? 2 * h->cap : 4096, .n = h->n};
    g.keys = bf_calloc(g.cap, 8);
    g.idx = bf_malloc((size_t)g.cap * 4);
    if (!g.keys || !g.idx) {
        free(g.keys);
        free(g.idx);
        return bf_fail(BF_NO_MEMORY, "render: brick hash of %u entries", g.cap);
    }
    for (uint32_t i = 0; i < h->cap; i++) {
        if (!h->keys[i]) continue;
        uint32_t j = hash_slot(h->keys[i], g.cap);
        while (g.keys[j]) j = (j + 1) & (g.cap - 1);
        g.keys[j] = h->keys[i], g.idx[j] = h->idx[i];
    }
    free(h->keys);
    free(h->idx);
    *h = g;
    return BF_OK;
}

/* Index of key, inserted (as the next index) when absent and insert is set;
 * UINT32_MAX when absent and not inserted or out of memory (status in *s). */
static uint32_t hash_get(brick_hash *h, uint64_t key, bool insert, bf_status *s)
{
    if (insert && 2 * (h->n + 1) > h->cap && (*s = hash_grow(h)) != BF_OK) return UINT32_MAX;
    uint32_t j = hash_slot(key, h->cap);
    while (h->keys[j] && h->keys[j] != key) j = (j + 1) & (h->cap - 1);
    if (h->keys[j]) return h->idx[j];
    if (!insert) return UINT32_MAX;
    h->keys[j] = key, h->idx[j] = h->n;
    return h->n++;
}

static int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/* floor() for finite x within int64's range, without the library call
 * (x86-64's baseline has no rounding instruction). */
static inline int64_t ifloor(double x)
{
    int64_t i = (int64_t)x;
    return i - (x < (double)i);
}

/* Triangle t's brick ranges. [b0, b1]: its bounding box grown by half a
 * voxel; those bricks must exist (a surface within half a voxel of a
 * brick's face puts the voxel layer next to it behind, and the ray needs
 * the front voxel before it, in the brick beyond the face; without it a
 * face-on surface there is not hit).
 * [p0, p1], inside it: the bricks where the triangle can cross a column,
 * which are all the GPU pass needs to see it in. A crossing is at a column
 * centre (i + 0.5 voxels) inside the triangle's xy box; a triangle whose
 * box holds no column centre (most, when triangles are smaller than
 * voxels) crosses nothing and is in no pair. (In z the range stays the
 * grown box's: a near-vertical triangle's crossing height, interpolated
 * in float, can land outside its z range, and the bits stay the same.)
 * The test is widened by more than the GPU's float rounding (its
 * coordinates relative to the brick: ~6e-8 of the distance from the
 * origin, in voxels), so the bits are those of every pair being seen.
 * Returns false when [p0, p1] is empty. */
static bool tri_bricks(const float *v, const mesh_data *mesh, uint32_t t, double brick_m, int64_t b0[3], int64_t b1[3],
                       int64_t p0[3], int64_t p1[3])
{
    /* Products with the inverses, not quotients (the divisions were most of
     * this function's time); exact for the power-of-two chunks (2 m). */
    const double voxel = brick_m / 8, grow = voxel / 2 * 1.001, inv_voxel = 1 / voxel, inv_brick = 1 / brick_m;
    const uint32_t *tri = mesh->tri + 3 * (size_t)t;
    const float *q0 = v + 3 * (size_t)tri[0], *q1 = v + 3 * (size_t)tri[1], *q2 = v + 3 * (size_t)tri[2];
    bool any = true;
    for (int a = 0; a < 3; a++) {
        /* (Comparisons, not fmin: no library call on this hot path.) */
        float l = q0[a] < q1[a] ? q0[a] : q1[a], h = q0[a] < q1[a] ? q1[a] : q0[a];
        double lo = l < q2[a] ? l : q2[a], hi = h > q2[a] ? h : q2[a];
        b0[a] = ifloor((lo - grow) * inv_brick), b1[a] = ifloor((hi + grow) * inv_brick);
        p0[a] = b0[a], p1[a] = b1[a];
        if (a == 2) continue;
        /* Column centres in the box: ceil(lo / voxel - 0.5) .. floor(hi / voxel - 0.5). */
        double eps = 1e-4 + 2.4e-7 * (fabs(lo) > fabs(hi) ? fabs(lo) : fabs(hi)) * inv_voxel; /* voxels */
        int64_t c0 = -ifloor(0.5 + eps - lo * inv_voxel), c1 = ifloor(hi * inv_voxel - 0.5 + eps);
        if (c0 > c1) any = false;
        if (floor_div(c0, 8) > p0[a]) p0[a] = floor_div(c0, 8);
        if (floor_div(c1, 8) < p1[a]) p1[a] = floor_div(c1, 8);
        if (p0[a] > p1[a]) any = false;
    }
    return any;
}

/* Level of detail (render_voxelise_config.lod): the space is cut into
 * columns along z whose cross-section is a brick of the coarsest level
 * used; every brick of a column is at the column's level, so the parity a
 * column carries up through its bricks stays that of one grid. */
typedef struct lod_plan {
    uint32_t axis;           /* the map axis the columns run along (below) */
    uint32_t coarse, finest; /* the columns are bricks of level `coarse` wide */
    int64_t x0, y0;          /* the first column, in brick coordinates of `coarse` */
    uint32_t nx, ny;
    uint8_t *level;          /* nx * ny: each column's level */
} lod_plan;

/* The bricks of level `level` a triangle's box [b0, b1] touches in the
 * columns of that level: one xy range per column met (all of it without a
 * plan). Returns how many ranges were written to r (at most cap; the count
 * is exact when it exceeds cap, so the caller can size r). */
typedef struct xy_range {
    int64_t x0, x1, y0, y1;
} xy_range;

static uint32_t tri_ranges(const lod_plan *p, uint32_t level, const int64_t b0[3], const int64_t b1[3], xy_range *r,
                           uint32_t cap)
{
    if (!p) {
        if (cap) r[0] = (xy_range){b0[0], b1[0], b0[1], b1[1]};
        return 1;
    }
    int64_t per = (int64_t)1 << (level - p->coarse);
    int64_t c0x = floor_div(b0[0], per), c1x = floor_div(b1[0], per);
    int64_t c0y = floor_div(b0[1], per), c1y = floor_div(b1[1], per);
    uint32_t n = 0;
    for (int64_t cy = c0y; cy <= c1y; cy++)
        for (int64_t cx = c0x; cx <= c1x; cx++) {
            int64_t ix = cx - p->x0, iy = cy - p->y0;
            if (ix < 0 || iy < 0 || ix >= p->nx || iy >= p->ny || p->level[iy * p->nx + ix] != level) continue;
            if (n < cap)
                r[n] = (xy_range){b0[0] > cx * per ? b0[0] : cx * per, b1[0] < (cx + 1) * per - 1 ? b1[0] : (cx + 1) * per - 1,
                                  b0[1] > cy * per ? b0[1] : cy * per, b1[1] < (cy + 1) * per - 1 ? b1[1] : (cy + 1) * per - 1};
            n++;
        }
    return n;
}

static int key_cmp(const void *a, const void *b)
{
    uint64_t p = *(const uint64_t *)a, q = *(const uint64_t *)b;
    return p < q ? -1 : p > q;
}

/* The bins: keys[n_bricks] sorted (x, y, then z), first[n_bricks + 1]
 * offsets into tri_ids (each brick's triangles in mesh order). */
typedef struct bins {
    uint64_t *keys;
    uint32_t *first, *tri_ids;
    uint32_t n_bricks;
    uint64_t n_pairs;
} bins;

static void bins_free(bins *b)
{
    free(b->keys);
    free(b->first);
    free(b->tri_ids);
    memset(b, 0, sizeof *b);
}

/* What the two passes over the triangles share. */
typedef struct bin_pass {
    const float *v;
    const mesh_data *mesh;
    const lod_plan *plan;
    uint32_t level;
    double brick_m;
    xy_range *ranges; /* scratch: a triangle's ranges */
    uint32_t ranges_cap;
} bin_pass;

/* Triangle t's ranges at the pass's level into bp->ranges (grown as
 * needed) and its pair range (tri_bricks; *pairs false when empty);
 * their count, or UINT32_MAX when out of memory. */
static uint32_t pass_ranges(bin_pass *bp, uint32_t t, int64_t b0[3], int64_t b1[3], int64_t p0[3], int64_t p1[3],
                            bool *pairs)
{
    *pairs = tri_bricks(bp->v, bp->mesh, t, bp->brick_m, b0, b1, p0, p1);
    uint32_t n = tri_ranges(bp->plan, bp->level, b0, b1, bp->ranges, bp->ranges_cap);
    if (n > bp->ranges_cap) {
        xy_range *r = bf_realloc(bp->ranges, (size_t)n * sizeof *r);
        if (!r) return UINT32_MAX;
        bp->ranges = r, bp->ranges_cap = n;
        n = tri_ranges(bp->plan, bp->level, b0, b1, bp->ranges, bp->ranges_cap);
    }
    return n;
}

/* Grows a buffer of elements of `size` bytes to hold at least need (kept
 * contents; huge pages asked for: these are filled once, front to back). */
static bool grow_buf(void **buf, uint64_t *cap, uint64_t need, size_t size)
{
    if (need <= *cap) return true;
    uint64_t c = *cap ? *cap : 1u << 16;
    while (c < need) c *= 2;
    void *nb = bf_realloc(*buf, (size_t)(c * size));
    if (!nb) return false;
    bf_advise_huge(nb, (size_t)(c * size));
    *buf = nb, *cap = c;
    return true;
}

/* Pass 1 over triangles [t0, t1): the bricks (a hash of its own), how
 * many pairs each gets, and each pair's brick in triangle order. Two run
 * at once, a half of the triangles each; a failure is kept as status and
 * message (bf_fail's message is the thread's own). */
typedef struct bin_half {
    const float *v;
    const mesh_data *mesh;
    const lod_plan *plan;
    uint32_t level, t0, t1;
    double brick_m;
    uint64_t max_pairs;
    uint32_t max_bricks; /* each half's bricks, like the whole's */
    uint32_t *tri_pairs; /* shared: [t0, t1) written here */
    brick_hash h;
    uint32_t *count, count_cap;
    uint32_t *pair_brick;
    uint64_t pair_cap, n_pairs;
    bf_status s;
    char msg[256];
} bin_half;

static void bin_half_run(void *ctx, size_t which)
{
    bin_half *hf = (bin_half *)ctx + which;
    bin_pass bp = {.v = hf->v, .mesh = hf->mesh, .plan = hf->plan, .level = hf->level, .brick_m = hf->brick_m};
    bf_status s = hash_grow(&hf->h);
    uint64_t last_key = 0;
    uint32_t last_i = UINT32_MAX;
    for (uint32_t t = hf->t0; s == BF_OK && t < hf->t1; t++) {
        int64_t b0[3], b1[3], p0[3], p1[3];
        bool pairs;
        uint32_t nr = pass_ranges(&bp, t, b0, b1, p0, p1, &pairs);
        if (nr == UINT32_MAX) {
            s = bf_fail(BF_NO_MEMORY, "render: column ranges of triangle %u", t);
            break;
        }
        /* Pairs: the ranges' bricks inside the pair range. */
        uint64_t n = 0;
        for (uint32_t r = 0; pairs && r < nr; r++) {
            int64_t x0 = bp.ranges[r].x0 > p0[0] ? bp.ranges[r].x0 : p0[0], x1 = bp.ranges[r].x1 < p1[0] ? bp.ranges[r].x1 : p1[0];
            int64_t y0 = bp.ranges[r].y0 > p0[1] ? bp.ranges[r].y0 : p0[1], y1 = bp.ranges[r].y1 < p1[1] ? bp.ranges[r].y1 : p1[1];
            if (x0 <= x1 && y0 <= y1) n += (uint64_t)(x1 - x0 + 1) * (uint64_t)(y1 - y0 + 1) * (uint64_t)(p1[2] - p0[2] + 1);
        }
        if (hf->n_pairs + n > hf->max_pairs || n > UINT32_MAX) {
            s = bf_fail(BF_POOL_FULL, "render: the mesh needs more than %llu (brick, triangle) pairs at level %u "
                        "(triangle %u spans %llu bricks): choose a coarser level",
                        (unsigned long long)hf->max_pairs, hf->level, t, (unsigned long long)n);
            break;
        }
        if (!grow_buf((void **)&hf->pair_brick, &hf->pair_cap, hf->n_pairs + n, 4)) {
            s = bf_fail(BF_NO_MEMORY, "render: %llu (brick, triangle) pairs", (unsigned long long)(hf->n_pairs + n));
            break;
        }
        hf->tri_pairs[t] = (uint32_t)n;
        for (uint32_t r = 0; s == BF_OK && r < nr; r++)
            for (int64_t z = b0[2]; s == BF_OK && z <= b1[2]; z++)
                for (int64_t y = bp.ranges[r].y0; s == BF_OK && y <= bp.ranges[r].y1; y++)
                    for (int64_t x = bp.ranges[r].x0; s == BF_OK && x <= bp.ranges[r].x1; x++) {
                        uint64_t key = brick_key(x, y, z);
                        uint32_t i = key == last_key ? last_i : hash_get(&hf->h, key, true, &s);
                        if (s != BF_OK) break;
                        if (hf->h.n > hf->max_bricks) {
                            /* Faces along the columns add bricks without pairs: caught here, early. */
                            s = bf_fail(BF_POOL_FULL, "render: the mesh needs more than %u bricks at level %u: choose "
                                        "a coarser level", hf->max_bricks, hf->level);
                            break;
                        }
                        last_key = key, last_i = i;
                        if (i >= hf->count_cap) {
                            uint32_t cap = hf->count_cap ? 2 * hf->count_cap : 4096;
                            uint32_t *c = bf_realloc(hf->count, (size_t)cap * 4);
                            if (!c) {
                                s = bf_fail(BF_NO_MEMORY, "render: counting %u bricks", cap);
                                break;
                            }
                            memset(c + hf->count_cap, 0, (size_t)(cap - hf->count_cap) * 4);
                            hf->count = c, hf->count_cap = cap;
                        }
                        if (pairs && x >= p0[0] && x <= p1[0] && y >= p0[1] && y <= p1[1]) {
                            hf->count[i]++;
                            hf->pair_brick[hf->n_pairs++] = i;
                        }
                    }
    }
    free(bp.ranges);
    hf->s = s;
    if (s != BF_OK) snprintf(hf->msg, sizeof hf->msg, "%s", bf_last_error());
}

static void bin_half_free(bin_half *hf)
{
    free(hf->h.keys), free(hf->h.idx), free(hf->count), free(hf->pair_brick);
}

/* Bins the triangles into the bricks of `level` their boxes touch (with a
 * plan: only in the columns of that level). Pass 1 (two threads, a half of
 * the triangles each) finds each (brick, triangle) pair's brick once, in
 * triangle order, and remembers it (a pair whose brick is the last pair's
 * skips the hash probe); the halves' bricks are merged and sorted, and
 * pass 2 only scatters the remembered pairs into the bins, triangles in
 * mesh order. */
static bf_status bin_triangles(const float *v, const mesh_data *mesh, const lod_plan *plan, uint32_t level,
                               double brick_m, uint64_t max_pairs, uint32_t max_bricks, bins *out)
{
    memset(out, 0, sizeof *out);
    uint32_t *tri_pairs = bf_malloc((size_t)(mesh->n_tris ? mesh->n_tris : 1) * 4);
    if (!tri_pairs) return bf_fail(BF_NO_MEMORY, "render: pairs of %u triangles", mesh->n_tris);
    bin_half hf[2];
    for (int k = 0; k < 2; k++)
        hf[k] = (bin_half){.v = v, .mesh = mesh, .plan = plan, .level = level, .brick_m = brick_m,
                           .max_pairs = max_pairs, .max_bricks = max_bricks, .tri_pairs = tri_pairs,
                           .t0 = k ? mesh->n_tris / 2 : 0, .t1 = k ? mesh->n_tris : mesh->n_tris / 2};
    bf_parallel_for(2, bin_half_run, hf);
    bf_status s = BF_OK;
    for (int k = 0; k < 2 && s == BF_OK; k++)
        if (hf[k].s != BF_OK) s = bf_fail(hf[k].s, "%s", hf[k].msg);
    uint64_t n_pairs = hf[0].n_pairs + hf[1].n_pairs;
    if (s == BF_OK && n_pairs > max_pairs)
        s = bf_fail(BF_POOL_FULL, "render: the mesh needs more than %llu (brick, triangle) pairs at level %u: "
                    "choose a coarser level", (unsigned long long)max_pairs, level);
    /* The second half's bricks into the first's hash (remap: its indices to the merged ones). */
    brick_hash *h = &hf[0].h;
    uint32_t n0 = h->n; /* the first half's own bricks (its counts) */
    uint32_t *remap = s == BF_OK ? bf_malloc((size_t)(hf[1].h.n ? hf[1].h.n : 1) * 4) : NULL;
    if (s == BF_OK && !remap) s = bf_fail(BF_NO_MEMORY, "render: merging %u bricks", hf[1].h.n);
    for (uint32_t j = 0; s == BF_OK && j < hf[1].h.cap; j++)
        if (hf[1].h.keys[j]) remap[hf[1].h.idx[j]] = hash_get(h, hf[1].h.keys[j], true, &s);
    uint32_t nb = h->n;
    if (s == BF_OK && nb > max_bricks)
        s = bf_fail(BF_POOL_FULL, "render: the mesh needs %u bricks at level %u, more than %u: choose a coarser level",
                    nb, level, max_bricks);
    uint32_t *count = NULL, *fill = NULL;
    if (s == BF_OK) {
        count = bf_calloc(nb ? nb : 1, 4);
        out->keys = bf_malloc((size_t)(nb ? nb : 1) * 8);
        out->first = bf_malloc((size_t)(nb + 1) * 4);
        out->tri_ids = bf_malloc((size_t)(n_pairs ? n_pairs : 1) * 4);
        fill = bf_malloc((size_t)(nb ? nb : 1) * 4); /* by merged index: the next free place of its bin */
        if (!count || !out->keys || !out->first || !out->tri_ids || !fill)
            s = bf_fail(BF_NO_MEMORY, "render: bins of %u bricks", nb);
        else
            bf_advise_huge(out->tri_ids, (size_t)n_pairs * 4);
    }
    if (s == BF_OK) {
        for (uint32_t i = 0; i < n0; i++) count[i] += hf[0].count[i];
        for (uint32_t i = 0; i < hf[1].h.n; i++) count[remap[i]] += hf[1].count[i];
        for (uint64_t k = 0; k < hf[1].n_pairs; k++) hf[1].pair_brick[k] = remap[hf[1].pair_brick[k]];
        /* Bricks in (x, y, z) order: the host's parity sweep walks the stacks. */
        uint32_t k = 0;
        for (uint32_t i = 0; i < h->cap; i++)
            if (h->keys[i]) out->keys[k++] = h->keys[i];
        qsort(out->keys, nb, 8, key_cmp);
        out->first[0] = 0;
        for (uint32_t r = 0; r < nb; r++) {
            uint32_t i = hash_get(h, out->keys[r], false, &s);
            out->first[r + 1] = out->first[r] + count[i];
            fill[i] = out->first[r];
        }
        /* Pass 2: each pair into its brick's bin, triangles in mesh order. */
        for (int half = 0; half < 2; half++) {
            uint64_t k2 = 0;
            for (uint32_t t = hf[half].t0; t < hf[half].t1; t++)
                for (uint32_t j = 0; j < tri_pairs[t]; j++) out->tri_ids[fill[hf[half].pair_brick[k2++]]++] = t;
        }
    }
    out->n_bricks = nb;
    out->n_pairs = n_pairs;
    free(remap);
    free(count);
    free(fill);
    free(tri_pairs);
    bin_half_free(&hf[0]);
    bin_half_free(&hf[1]);
    if (s != BF_OK) bins_free(out);
    return s;
}

render_voxelise_config render_voxelise_config_default(void)
{
    return (render_voxelise_config){.chunk_m = 2.0f, .level = 7, .max_pairs = 1ull << 28, .max_bricks = UINT32_MAX - 1};
}

/* The GPU pass over the bricks: out gets RENDER_VOX_OUT_WORDS per brick.
 * tri_xyz: the listed triangles' corners, 9 floats each, in the order
 * tri_ids index. */
static bf_status run_pass(gpu_context *ctx, const float *tri_xyz, uint32_t n_tris, const uint32_t *brick_words,
                          uint32_t n_bricks, const uint32_t *tri_ids, uint64_t n_pairs, float chunk_m, uint32_t *out)
{
    gpu_buffer *buf[4] = {0};
    uint64_t bytes[4] = {(uint64_t)n_tris * 36, (uint64_t)n_bricks * RENDER_VOX_BRICK_WORDS * 4, n_pairs * 4,
                         (uint64_t)n_bricks * RENDER_VOX_OUT_WORDS * 4};
    const char *names[4] = {"render.vox_tris", "render.vox_bricks", "render.vox_tri_ids", "render.vox_out"};
    const void *src[3] = {tri_xyz, brick_words, tri_ids};
    gpu_pipeline *pipe = NULL;
    gpu_bindings *binds = NULL;
    bf_status s = BF_OK;
    for (int i = 0; i < 4 && s == BF_OK; i++) {
        gpu_buffer_desc d = {.name = names[i], .size_bytes = bytes[i] ? bytes[i] : 4, .memory = GPU_MEMORY_DEVICE};
        s = gpu_buffer_create(ctx, &d, &buf[i]);
        if (s == BF_OK && i < 3 && bytes[i]) s = gpu_buffer_upload(buf[i], 0, src[i], bytes[i]);
    }
    gpu_pipeline_desc pd = {
        .name = "render.voxelise",
        .spirv = bf_spv_render_voxelise,
        .spirv_bytes = bf_spv_render_voxelise_size,
        .n_buffers = 4,
        .push_bytes = sizeof(render_vox_push),
        .local_size = {64, 1, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &pipe);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 4, "render.voxelise", &binds);
    for (uint32_t i = 0; i < 4 && s == BF_OK; i++) s = gpu_bindings_set(binds, i, buf[i], 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_begin(ctx);
    if (s == BF_OK) {
        render_vox_push pc = {.n_bricks = n_bricks, .chunk_m = chunk_m};
        uint32_t max_x = gpu_device_limits(ctx)->max_compute_workgroup_count[0];
        if (max_x > 65535u) max_x = 65535u;
        uint32_t groups = gpu_groups(n_bricks, 64); /* one invocation a brick */
        uint32_t gx = groups < max_x ? groups : max_x, gy = gpu_groups(groups, gx ? gx : 1);
        if (n_bricks) gpu_cmd_dispatch(ctx, pipe, binds, &pc, gx, gy, 1);
        gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
        s = gpu_submit_wait(ctx);
    }
    if (s == BF_OK && bytes[3]) s = gpu_buffer_download(buf[3], 0, out, bytes[3]);
    gpu_bindings_destroy(binds);
    gpu_pipeline_destroy(pipe);
    for (int i = 3; i >= 0; i--) gpu_buffer_destroy(buf[i]);
    return s;
}

/* Voxel v = x + 8 y + 64 z of the binning's coordinates -> its word and
 * bit in the map's coordinates (word << 5 | bit) for a column axis. */
static void perm_table(uint32_t axis, uint16_t dst[512])
{
    for (uint32_t v = 0; v < 512; v++) {
        uint32_t p[3] = {v & 7, (v >> 3) & 7, v >> 6}, r[3];
        for (int a = 0; a < 3; a++) r[PERM[axis][a]] = p[a];
        dst[v] = (uint16_t)(brick_word(r[0], r[1], r[2]) << 5 | brick_bit(r[0], r[1], r[2]));
    }
}

/* The word's voxels whose columns enter inside: a word holds a 4x4
 * patch of columns (bits 0-15 and again 16-31, two heights), so the 16
 * columns' carry bits make its mask. */
static uint32_t carry_mask(uint64_t carry, uint32_t w)
{
    uint32_t x0 = (w & 1) * 4, y0 = ((w >> 1) & 1) * 4, m = 0;
    for (uint32_t r = 0; r < 4; r++) m |= (uint32_t)((carry >> (x0 + 8 * (y0 + r))) & 0xF) << (4 * r);
    return m | m << 16;
}

/* Sign and confidence of each brick from its flips and the parity its
 * columns carry in: bricks are in (x, y, z) key order, so a stack of
 * bricks in one column is consecutive, lowest first. A brick without
 * pairs (gpu_slot UINT32_MAX) was not in the GPU pass: nothing flips in
 * it. */
static void finish_bricks(const uint64_t *keys, const uint32_t *gpu_out, const uint32_t *gpu_slot, uint32_t n_bricks,
                          uint32_t level, uint32_t axis, hostmap_brick *bricks)
{
    uint16_t dst[512];
    perm_table(axis, dst);
    static const uint32_t none[RENDER_VOX_OUT_WORDS];
    uint64_t carry = 0;
    for (uint32_t i = 0; i < n_bricks; i++) {
        if (i == 0 || key_x(keys[i]) != key_x(keys[i - 1]) || key_y(keys[i]) != key_y(keys[i - 1])) carry = 0;
        const uint32_t *g = gpu_slot[i] == UINT32_MAX ? none : gpu_out + (size_t)gpu_slot[i] * RENDER_VOX_OUT_WORDS;
        hostmap_brick *b = &bricks[i];
        int32_t Bp[3] = {key_x(keys[i]), key_y(keys[i]), key_z(keys[i])}, B[3];
        for (int a = 0; a < 3; a++) B[PERM[axis][a]] = Bp[a];
        for (int a = 0; a < 3; a++) {
            /* Chunk key and cell: floor division by the bricks per chunk edge. */
            int32_t per = (int32_t)1 << level;
            b->key[a] = B[a] >= 0 ? B[a] / per : -((-B[a] + per - 1) / per);
            b->cell[a] = (uint32_t)(B[a] - b->key[a] * per);
        }
        b->level = level;
        b->error = 0;
        uint32_t inside[BRICK_WORDS];
        /* Columns that enter inside: every voxel of them flips. */
        for (uint32_t w = 0; w < BRICK_WORDS; w++) inside[w] = g[w] ^ carry_mask(carry, w);
        if (axis != 2) {
            /* The bits in the binning's coordinates back to the map's. */
            uint32_t perm[BRICK_WORDS] = {0};
            for (uint32_t v = 0; v < 512; v++) {
                uint32_t x = v & 7, y = (v >> 3) & 7, z = v >> 6, d = dst[v];
                perm[d >> 5] |= ((inside[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1u) << (d & 31);
            }
            memcpy(inside, perm, sizeof inside);
        }
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            b->sign[w] = ~inside[w]; /* 1: in front of the surface (outside) */
            b->conf[w] = 0xFFFFFFFFu;
        }
        carry ^= (uint64_t)g[BRICK_WORDS] | ((uint64_t)g[BRICK_WORDS + 1] << 32);
    }
}

/* The footprint's depth factor: a pixel at angle theta off the optical axis
 * spans z cos(theta) / f across its ray (against z / f on the axis), so the
 * widest ray of the image, at its corners, bounds the footprint from below. */
static double lod_cos_max(const bf_intrinsics *K)
{
    double r2 = 0;
    for (int k = 0; k < 4; k++) {
        double u = ((k & 1) ? K->width : 0) - 0.5 - K->cx_px, w = ((k & 2) ? K->height : 0) - 0.5 - K->cy_px;
        double q = (u / K->fx_px) * (u / K->fx_px) + (w / K->fy_px) * (w / K->fy_px);
        r2 = q > r2 ? q : r2;
    }
    return 1.0 / sqrt(1.0 + r2);
}

/* World point of permuted map coordinates q. */
static bf_vec3 unpermute(uint32_t axis, bf_vec3 origin_w, const double q[3])
{
    double r[3];
    for (int i = 0; i < 3; i++) r[PERM[axis][i]] = q[i];
    return bf_v3(origin_w.x + r[0], origin_w.y + r[1], origin_w.z + r[2]);
}

/* Camera depth range of the box [lo, hi] (permuted map metres) seen by T_cw. */
static void box_depths(const bf_se3 *T_cw, uint32_t axis, bf_vec3 origin_w, const double lo[3], const double hi[3],
                       double *z_min, double *z_max)
{
    *z_min = INFINITY, *z_max = -INFINITY;
    for (int k = 0; k < 8; k++) {
        double q[3] = {(k & 1) ? hi[0] : lo[0], (k & 2) ? hi[1] : lo[1], (k & 4) ? hi[2] : lo[2]};
        double z = bf_se3_apply(T_cw, unpermute(axis, origin_w, q)).z;
        *z_min = fmin(*z_min, z), *z_max = fmax(*z_max, z);
    }
}

/* The map axis least along the optical axis of T_wc. */
static uint32_t lod_axis(const bf_se3 *T_wc)
{
    bf_vec3 d = bf_v3_sub(bf_se3_apply(T_wc, bf_v3(0, 0, 1)), T_wc->t);
    double a[3] = {fabs(d.x), fabs(d.y), fabs(d.z)};
    return a[2] <= a[0] && a[2] <= a[1] ? 2 : a[0] <= a[1] ? 0 : 1;
}

/* The level whose voxel is a third of the footprint at depth z (at least
 * near), between coarse and finest. */
static uint32_t lod_level_at(const render_voxelise_config *c, double cos_max, double f_px, double z, uint32_t coarse,
                             uint32_t finest)
{
    double near = c->lod_near_m > 0 ? c->lod_near_m : 0.05;
    uint32_t l = render_level_for_footprint(c->chunk_m, fmax(z, near) * cos_max, f_px, finest);
    return l < coarse ? coarse : l;
}

/* Each column's level from the camera of c (render_voxelise_config.lod):
 * the columns are bricks of the level the mesh's farthest depth needs
 * (coarser where there would be more than 2^20 of them); a column's level
 * is the one its nearest depth needs, but no finer than the nearest
 * vertex's (a surface point lies between its triangle's vertices). */
static bf_status lod_make_plan(const render_voxelise_config *c, uint32_t axis, bf_vec3 origin_w, const float *v,
                               uint32_t n_verts, lod_plan *p)
{
    memset(p, 0, sizeof *p);
    p->axis = axis;
    bf_se3 T_cw = bf_se3_inverse(&c->lod_T_wc);
    double f_px = c->lod_K.fx_px > c->lod_K.fy_px ? c->lod_K.fx_px : c->lod_K.fy_px, cos_max = lod_cos_max(&c->lod_K);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY}, zv = INFINITY;
    for (uint32_t i = 0; i < n_verts; i++) {
        for (int a = 0; a < 3; a++) lo[a] = fmin(lo[a], v[3 * i + a]), hi[a] = fmax(hi[a], v[3 * i + a]);
        double q[3] = {v[3 * i], v[3 * i + 1], v[3 * i + 2]};
        zv = fmin(zv, bf_se3_apply(&T_cw, unpermute(axis, origin_w, q)).z);
    }
    if (!n_verts) lo[0] = lo[1] = lo[2] = hi[0] = hi[1] = hi[2] = zv = 0;
    double z_min, z_max;
    box_depths(&T_cw, axis, origin_w, lo, hi, &z_min, &z_max);
    p->finest = c->level;
    p->coarse = lod_level_at(c, cos_max, f_px, z_max, 0, c->level);
    for (;;) {
        double cell = 8 * hostmap_level_voxel_m(c->chunk_m, p->coarse);
        /* The columns cover the triangles' boxes as the binning grows them
         * (half a voxel, tri_bricks; the coarse level's is the widest): a
         * column cut off there dropped the free bricks beside a face that
         * lies on a brick boundary, and a box drawn from them vanished. */
        double g = cell / 8; /* a whole voxel: more than any level's grow, whatever the rounding */
        p->x0 = (int64_t)floor((lo[0] - g) / cell), p->y0 = (int64_t)floor((lo[1] - g) / cell);
        uint64_t nx = (uint64_t)((int64_t)floor((hi[0] + g) / cell) - p->x0 + 1),
                 ny = (uint64_t)((int64_t)floor((hi[1] + g) / cell) - p->y0 + 1);
        if (nx * ny <= (1u << 20) || p->coarse == 0) {
            p->nx = (uint32_t)nx, p->ny = (uint32_t)ny;
            break;
        }
        p->coarse--;
    }
    p->level = bf_malloc((size_t)p->nx * p->ny);
    if (!p->level) return bf_fail(BF_NO_MEMORY, "render: level of detail over %u x %u columns", p->nx, p->ny);
    double cell = 8 * hostmap_level_voxel_m(c->chunk_m, p->coarse);
    uint32_t finest = p->coarse;
    for (uint32_t iy = 0; iy < p->ny; iy++)
        for (uint32_t ix = 0; ix < p->nx; ix++) {
            double cl[3] = {fmax(lo[0], (double)(p->x0 + ix) * cell), fmax(lo[1], (double)(p->y0 + iy) * cell), lo[2]};
            double ch[3] = {fmin(hi[0], (double)(p->x0 + ix + 1) * cell), fmin(hi[1], (double)(p->y0 + iy + 1) * cell), hi[2]};
            box_depths(&T_cw, axis, origin_w, cl, ch, &z_min, &z_max);
            /* Wholly behind the camera: never seen from it, the coarsest will do. */
            uint32_t l = z_max <= 0 ? p->coarse : lod_level_at(c, cos_max, f_px, fmax(z_min, zv), p->coarse, p->finest);
            p->level[(size_t)iy * p->nx + ix] = (uint8_t)l;
            finest = l > finest ? l : finest;
        }
    p->finest = finest;
    return BF_OK;
}

/* The mesh's vertices in blocks on the worker threads: their world box
 * (and the first that is not finite), then their places relative to the
 * map's origin in the binning's coordinates. */
#define VERT_BLOCK (1u << 18)
typedef struct vert_block {
    bf_vec3 lo;
    uint32_t bad; /* the first vertex that is not finite, UINT32_MAX: none */
} vert_block;
typedef struct vert_job {
    const mesh_data *mesh;
    const bf_se3 *T;
    float *v;
    vert_block *blocks;
    uint32_t n_blocks, axis;
    bf_vec3 origin_w;
} vert_job;

static bf_vec3 vert_world(const vert_job *j, uint32_t i)
{
    const mesh_data *m = j->mesh;
    return bf_se3_apply(j->T, bf_v3(m->origin.x + m->xyz[3 * i], m->origin.y + m->xyz[3 * i + 1],
                                    m->origin.z + m->xyz[3 * i + 2]));
}

static void vert_bounds(void *ctx, size_t b)
{
    vert_job *j = ctx;
    uint32_t i0 = (uint32_t)b * VERT_BLOCK, i1 = i0 + VERT_BLOCK < j->mesh->n_verts ? i0 + VERT_BLOCK : j->mesh->n_verts;
    vert_block r = {.lo = bf_v3(INFINITY, INFINITY, INFINITY), .bad = UINT32_MAX};
    for (uint32_t i = i0; i < i1; i++) {
        bf_vec3 p = vert_world(j, i);
        if (!isfinite(p.x) || !isfinite(p.y) || !isfinite(p.z)) {
            r.bad = i;
            break;
        }
        r.lo = bf_v3(fmin(r.lo.x, p.x), fmin(r.lo.y, p.y), fmin(r.lo.z, p.z));
    }
    j->blocks[b] = r;
}

static void vert_place(void *ctx, size_t b)
{
    vert_job *j = ctx;
    uint32_t i0 = (uint32_t)b * VERT_BLOCK, i1 = i0 + VERT_BLOCK < j->mesh->n_verts ? i0 + VERT_BLOCK : j->mesh->n_verts;
    for (uint32_t i = i0; i < i1; i++) {
        bf_vec3 p = vert_world(j, i);
        double r[3] = {p.x - j->origin_w.x, p.y - j->origin_w.y, p.z - j->origin_w.z};
        for (int k = 0; k < 3; k++) j->v[3 * i + k] = (float)r[PERM[j->axis][k]];
    }
}

/* Only the listed triangles go to the GPU, their corners packed (9 floats
 * each) in the order they are first listed, the ids renumbered in place:
 * most of a finely tessellated mesh is in no pair. */
static bf_status pack_listed_triangles(const float *v, const mesh_data *mesh, uint32_t *tri_ids, uint64_t n_pairs,
                                       float **tri_xyz, uint32_t *n_used)
{
    uint32_t *packed = bf_malloc((size_t)(mesh->n_tris ? mesh->n_tris : 1) * 4);
    float *xyz = bf_malloc((size_t)(n_pairs < mesh->n_tris ? n_pairs : mesh->n_tris) * 36 + 36);
    if (!packed || !xyz) {
        free(packed), free(xyz);
        return bf_fail(BF_NO_MEMORY, "render: packing %llu listed triangles", (unsigned long long)n_pairs);
    }
    memset(packed, 0xFF, (size_t)mesh->n_tris * 4);
    uint32_t n = 0;
    for (uint64_t k = 0; k < n_pairs; k++) {
        uint32_t t = tri_ids[k];
        if (packed[t] == UINT32_MAX) {
            for (int j = 0; j < 3; j++) memcpy(xyz + 9 * (size_t)n + 3 * j, v + 3 * (size_t)mesh->tri[3 * (size_t)t + j], 12);
            packed[t] = n++;
        }
        tri_ids[k] = packed[t];
    }
    free(packed);
    *tri_xyz = xyz, *n_used = n;
    return BF_OK;
}

/* The bins of every level, one after the other: the GPU pass takes them
 * as one list. */
typedef struct level_bins {
    bins b[13];
    uint32_t first_brick[14];
    uint64_t first_pair[14];
} level_bins;

bf_status render_voxelise_mesh(gpu_context *ctx, const mesh_data *mesh, const bf_se3 *T_world_mesh,
                               const render_voxelise_config *cfg, hostmap *out, render_voxelise_stats *st)
{
    if (!ctx || !mesh || !out || (mesh->n_tris && (!mesh->tri || !mesh->xyz)))
        return bf_fail(BF_INVALID_ARG, "render_voxelise_mesh: NULL argument");
    render_voxelise_config c = cfg ? *cfg : render_voxelise_config_default();
    if (!(c.chunk_m > 0) || c.level > 12)
        return bf_fail(BF_INVALID_ARG, "render: voxelising at level %u of %g m chunks (level at most 12)", c.level,
                       (double)c.chunk_m);
    if (c.lod && !(c.lod_K.fx_px > 0 && c.lod_K.fy_px > 0 && c.lod_K.width && c.lod_K.height))
        return bf_fail(BF_INVALID_ARG, "render: level of detail needs the camera's intrinsics");
    memset(out, 0, sizeof *out);
    if (st) memset(st, 0, sizeof *st);
    double t0 = bf_time_s();
    bf_se3 T = T_world_mesh ? *T_world_mesh : bf_se3_identity();
    /* World points; the map's origin is their bounding box's low corner
     * (whole voxels), so brick coordinates start near zero. Both passes
     * over the vertices run in blocks on the worker threads. */
    float *v = bf_malloc((size_t)(mesh->n_verts ? mesh->n_verts : 1) * 12);
    if (!v) return bf_fail(BF_NO_MEMORY, "render: %u mesh vertices", mesh->n_verts);
    bf_advise_huge(v, (size_t)mesh->n_verts * 12);
    /* The grid's origin at the finest level's voxels (coarser levels' bricks nest in the chunks all the same). */
    double voxel_m = hostmap_level_voxel_m(c.chunk_m, c.level), brick_m = 8 * voxel_m;
    vert_job vj = {.mesh = mesh, .T = &T, .v = v, .n_blocks = (mesh->n_verts + VERT_BLOCK - 1) / VERT_BLOCK};
    vj.blocks = bf_calloc(vj.n_blocks ? vj.n_blocks : 1, sizeof *vj.blocks);
    if (!vj.blocks) {
        free(v);
        return bf_fail(BF_NO_MEMORY, "render: %u mesh vertices", mesh->n_verts);
    }
    bf_parallel_for(vj.n_blocks, vert_bounds, &vj);
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY);
    for (uint32_t b = 0; b < vj.n_blocks; b++) {
        if (vj.blocks[b].bad != UINT32_MAX) {
            uint32_t bad = vj.blocks[b].bad;
            free(v), free(vj.blocks);
            return bf_fail(BF_INVALID_ARG, "render: mesh vertex %u is not finite", bad);
        }
        lo = bf_v3(fmin(lo.x, vj.blocks[b].lo.x), fmin(lo.y, vj.blocks[b].lo.y), fmin(lo.z, vj.blocks[b].lo.z));
    }
    if (!mesh->n_verts) lo = bf_v3(0, 0, 0);
    out->chunk_m = c.chunk_m;
    out->origin_w = c.has_origin ? c.origin_w
                                 : bf_v3(floor(lo.x / voxel_m) * voxel_m - brick_m, floor(lo.y / voxel_m) * voxel_m - brick_m,
                                         floor(lo.z / voxel_m) * voxel_m - brick_m);
    uint32_t axis = c.lod ? lod_axis(&c.lod_T_wc) : 2;
    vj.origin_w = out->origin_w, vj.axis = axis;
    bf_parallel_for(vj.n_blocks, vert_place, &vj);
    free(vj.blocks);
    for (uint32_t t = 0; t < 3 * (size_t)mesh->n_tris; t++)
        if (mesh->tri[t] >= mesh->n_verts) {
            free(v);
            return bf_fail(BF_INVALID_ARG, "render: triangle %u names vertex %u of %u", t / 3, mesh->tri[t],
                           mesh->n_verts);
        }
    lod_plan plan = {0};
    bf_status s = c.lod ? lod_make_plan(&c, axis, out->origin_w, v, mesh->n_verts, &plan) : BF_OK;
    uint32_t l_lo = c.lod ? plan.coarse : c.level, l_hi = c.lod ? plan.finest : c.level;
    level_bins lb = {0};
    /* The GPU pass binds the pairs and the bricks whole: beyond the
     * device's largest binding the level is too fine for it (and binning
     * further would only cost time). */
    uint64_t range = gpu_device_limits(ctx)->max_storage_buffer_range;
    uint64_t max_pairs = c.max_pairs < range / 4 ? c.max_pairs : range / 4;
    uint64_t brick_bytes = RENDER_VOX_OUT_WORDS * 4;
    uint32_t max_bricks = c.max_bricks < range / brick_bytes ? c.max_bricks : (uint32_t)(range / brick_bytes);
    if (st) st->level_coarse = l_lo, st->level_fine = l_hi; /* also when it fails: the levels tried */
    for (uint32_t l = l_lo; s == BF_OK && l <= l_hi; l++) {
        bins *bn = &lb.b[l];
        s = bin_triangles(v, mesh, c.lod ? &plan : NULL, l, 8 * hostmap_level_voxel_m(c.chunk_m, l), max_pairs,
                          max_bricks, bn);
        if (s == BF_OK) max_pairs -= bn->n_pairs, max_bricks -= bn->n_bricks;
    }
    uint32_t n_bricks = 0;
    uint64_t n_pairs = 0;
    for (uint32_t l = 0; l <= 12; l++) {
        lb.first_brick[l] = n_bricks, lb.first_pair[l] = n_pairs;
        n_bricks += lb.b[l].n_bricks, n_pairs += lb.b[l].n_pairs;
    }
    lb.first_brick[13] = n_bricks, lb.first_pair[13] = n_pairs;
    uint32_t *brick_words = NULL, *gpu_out = NULL, *tri_ids = NULL, *gpu_slot = NULL;
    if (s == BF_OK) {
        brick_words = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_BRICK_WORDS * 4);
        gpu_out = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_OUT_WORDS * 4);
        gpu_slot = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * 4);
        tri_ids = l_lo == l_hi ? lb.b[l_lo].tri_ids : bf_malloc((size_t)(n_pairs ? n_pairs : 1) * 4);
        out->bricks = bf_calloc(n_bricks ? n_bricks : 1, sizeof *out->bricks);
        if (!brick_words || !gpu_out || !gpu_slot || !tri_ids || !out->bricks)
            s = bf_fail(BF_NO_MEMORY, "render: voxelising into %u bricks", n_bricks);
    }
    uint32_t n_gpu = 0;
    for (uint32_t l = l_lo; s == BF_OK && l <= l_hi; l++) {
        const bins *bn = &lb.b[l];
        if (tri_ids != bn->tri_ids && bn->n_pairs) memcpy(tri_ids + lb.first_pair[l], bn->tri_ids, bn->n_pairs * 4);
        /* Only bricks with pairs go to the GPU: the others (a grown box's
         * edge, or only triangles that hold no column centre) flip nothing. */
        for (uint32_t i = 0; i < bn->n_bricks; i++) {
            gpu_slot[lb.first_brick[l] + i] = UINT32_MAX;
            if (bn->first[i] == bn->first[i + 1]) continue;
            gpu_slot[lb.first_brick[l] + i] = n_gpu;
            uint32_t *w = brick_words + (size_t)n_gpu++ * RENDER_VOX_BRICK_WORDS;
            w[0] = (uint32_t)key_x(bn->keys[i]), w[1] = (uint32_t)key_y(bn->keys[i]), w[2] = (uint32_t)key_z(bn->keys[i]);
            w[3] = (uint32_t)(lb.first_pair[l] + bn->first[i]), w[4] = (uint32_t)(lb.first_pair[l] + bn->first[i + 1]);
            w[5] = l;
        }
    }
    float *tri_xyz = NULL;
    uint32_t n_used = 0;
    if (s == BF_OK) s = pack_listed_triangles(v, mesh, tri_ids, n_pairs, &tri_xyz, &n_used);
    if (s == BF_OK && (uint64_t)n_used * 36 > range)
        s = bf_fail(BF_POOL_FULL, "render: the mesh lists %u triangles at level %u, more than one binding of the "
                    "device holds (%llu MiB): choose a coarser level", n_used, l_hi, (unsigned long long)(range >> 20));
    double t1 = bf_time_s();
    if (s == BF_OK) s = run_pass(ctx, tri_xyz, n_used, brick_words, n_gpu, tri_ids, n_pairs, c.chunk_m, gpu_out);
    free(tri_xyz);
    double t2 = bf_time_s();
    if (s == BF_OK) {
        for (uint32_t l = l_lo; l <= l_hi; l++)
            finish_bricks(lb.b[l].keys, gpu_out, gpu_slot + lb.first_brick[l], lb.b[l].n_bricks, l,
                          axis, out->bricks + lb.first_brick[l]);
        out->n_bricks = n_bricks;
    }
    if (s == BF_OK && st) {
        st->n_bricks = n_bricks;
        st->n_pairs = n_pairs;
        st->n_gpu_bricks = n_gpu;
        st->voxel_m = hostmap_level_voxel_m(c.chunk_m, l_hi);
        st->level_coarse = l_lo, st->level_fine = l_hi;
        for (uint32_t l = l_lo; l <= l_hi; l++) st->bricks_at_level[l] = lb.b[l].n_bricks;
        st->n_columns = c.lod ? plan.nx * plan.ny : 1;
        st->column_axis = axis;
        st->seconds_bin = t1 - t0;
        st->seconds_gpu = t2 - t1;
        st->seconds = bf_time_s() - t0;
    }
    free(v);
    free(plan.level);
    if (tri_ids != lb.b[l_lo].tri_ids) free(tri_ids);
    for (uint32_t l = 0; l <= 12; l++) bins_free(&lb.b[l]);
    free(brick_words);
    free(gpu_out);
    free(gpu_slot);
    if (s != BF_OK) hostmap_free(out);
    return s;
}

uint32_t render_level_for_footprint(float chunk_m, double z_m, double f_px, uint32_t max_level)
{
    double want = z_m / f_px / 3.0; /* voxel edge at most a third of a pixel */
    uint32_t level = 0;
    while (level < max_level && hostmap_level_voxel_m(chunk_m, level) > want) level++;
    return level;
}

/* Brick identity for the merge: chunk, level, cell. */
static int brick_cmp(const void *a, const void *b)
{
    const hostmap_brick *p = a, *q = b;
    for (int i = 0; i < 3; i++)
        if (p->key[i] != q->key[i]) return p->key[i] < q->key[i] ? -1 : 1;
    if (p->level != q->level) return p->level < q->level ? -1 : 1;
    for (int i = 0; i < 3; i++)
        if (p->cell[i] != q->cell[i]) return p->cell[i] < q->cell[i] ? -1 : 1;
    return 0;
}

static int index_cmp(const void *x, const void *y, void *ctx)
{
    const hostmap_brick *bricks = ctx;
    return brick_cmp(&bricks[*(const uint32_t *)x], &bricks[*(const uint32_t *)y]);
}

bf_status render_hostmap_merge(hostmap *a, hostmap *b)
{
    if (a->chunk_m != b->chunk_m || a->origin_w.x != b->origin_w.x || a->origin_w.y != b->origin_w.y ||
        a->origin_w.z != b->origin_w.z)
        return bf_fail(BF_INVALID_ARG, "render: merging maps on other grids (chunk edge or origin differs)");
    hostmap_brick *all = bf_malloc(((size_t)a->n_bricks + b->n_bricks + 1) * sizeof *all);
    uint16_t *rgb = a->rgb565 ? bf_malloc(((size_t)a->n_bricks + b->n_bricks + 1) * 1024) : NULL;
    if (!all || (a->rgb565 && !rgb)) {
        free(all);
        free(rgb);
        return bf_fail(BF_NO_MEMORY, "render: merging %u and %u bricks", a->n_bricks, b->n_bricks);
    }
    /* a's bricks keep their order (and colour); b's join them, or are
     * folded into the one of a at the same place. */
    memcpy(all, a->bricks, (size_t)a->n_bricks * sizeof *all);
    if (rgb) memcpy(rgb, a->rgb565, (size_t)a->n_bricks * 1024);
    /* a's bricks by place, as indices (a's order stays). */
    uint32_t *order = bf_malloc(((size_t)a->n_bricks + 1) * 4);
    if (!order) {
        free(all), free(rgb);
        return bf_fail(BF_NO_MEMORY, "render: merging %u bricks", a->n_bricks);
    }
    for (uint32_t i = 0; i < a->n_bricks; i++) order[i] = i;
    qsort_r(order, a->n_bricks, 4, index_cmp, a->bricks);
    uint32_t n = a->n_bricks;
    for (uint32_t j = 0; j < b->n_bricks; j++) {
        hostmap_brick *nb = &b->bricks[j];
        uint32_t lo = 0, hi = a->n_bricks; /* first of order[] not below nb */
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2;
            if (brick_cmp(&a->bricks[order[mid]], nb) < 0) lo = mid + 1;
            else hi = mid;
        }
        if (lo < a->n_bricks && brick_cmp(&a->bricks[order[lo]], nb) == 0) {
            hostmap_brick *t = &all[order[lo]];
            for (int w = 0; w < 16; w++) {
                /* Behind (0) where either is confidently behind. */
                uint32_t behind = (~t->sign[w] & t->conf[w]) | (~nb->sign[w] & nb->conf[w]);
                t->sign[w] = ~behind;
                t->conf[w] |= nb->conf[w];
            }
            continue;
        }
        all[n] = *nb;
        if (rgb) memset(rgb + (size_t)n * 512, 0, 1024);
        n++;
    }
    free(order);
    free(a->bricks);
    free(a->rgb565);
    a->bricks = all, a->rgb565 = rgb, a->n_bricks = n;
    hostmap_free(b);
    return BF_OK;
}
