/* The particle renderer's host side (render.h, "particles"; Reichl's
 * dissertation, ch. 6, binary grids for particle rendering): binning on the
 * host into a host copy of the map structure, which fusion_load puts into
 * a fusion_map of the set's own (the same pools, hash and octrees the
 * ray-caster walks), and the particle pass (shaders/render_particles.comp).
 *
 * Binning: each particle sets the bit of the cell holding it (cells of
 * cell_m on the bricks' level, bricks found through an open-addressing
 * table keyed by the global brick coordinate). A sphere reaches up to the
 * radius beyond its cell, into bricks that may hold no particle; the walk
 * only visits bricks that exist, so every brick the sphere's box touches
 * is allocated too (empty), and every cell a sphere overlaps gets a reach
 * bit in the confidence plane: the traverser searches the neighbours only
 * from the first reached cell on the ray. That costs memory and binning
 * time (docs/particles.md counts both) but keeps the traverser's search
 * local and short. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "render.h"
#include "shaders/fusion.glsl.h"
#include "shaders/render.glsl.h"

struct render_particles {
    gpu_context *ctx;
    fusion_map *map;
    render_particles_config cfg;
    render_particles_stats stats;
    gpu_pipeline *pipe;
    gpu_bindings *bind;
    gpu_buffer *bound[4]; /* the caster images bound at 3..6 */
    gpu_buffer *resume;   /* binding 8: per pixel, where a ray resumes; made for the image size */
    uint32_t cells_per_pass, n_passes;
    double last_ms;
};

render_particles_config render_particles_config_default(void)
{
    return (render_particles_config){.radius_m = 0.01f, .cell_m = 0.0f, .rgb = 0x00DC8246u};
}

/* ------------------------------------------------------------ binning */

/* Global brick coordinates are below 2^BIN_AXIS_BITS per axis (the origin
 * sits below the set's box, so they are never negative). */
#define BIN_AXIS_BITS 21
#define BIN_MAX_CELLS ((int64_t)1 << 24)

typedef struct bin_table {
    uint64_t *keys;  /* code + 1; 0 = empty */
    uint32_t *index; /* brick index */
    uint64_t cap;    /* a power of two */
    uint32_t n;
} bin_table;

typedef struct bin_state {
    bin_table t;
    hostmap_brick *bricks;
    uint32_t n, cap;
    uint64_t *codes; /* global brick coordinate code of each brick */
} bin_state;

static uint64_t brick_code(const int64_t b[3])
{
    return ((uint64_t)b[0] << (2 * BIN_AXIS_BITS)) | ((uint64_t)b[1] << BIN_AXIS_BITS) | (uint64_t)b[2];
}

static uint64_t hash64(uint64_t x)
{
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdull;
    x ^= x >> 33;
    return x;
}

static bf_status table_grow(bin_table *t)
{
    uint64_t cap = t->cap ? 2 * t->cap : 1u << 12;
    uint64_t *keys = bf_calloc(cap, 8);
    uint32_t *index = bf_malloc(cap * 4);
    if (!keys || !index) {
        free(keys), free(index);
        return bf_fail(BF_NO_MEMORY, "render: particle bins (%llu entries)", (unsigned long long)cap);
    }
    for (uint64_t i = 0; i < t->cap; i++) {
        if (!t->keys[i]) continue;
        uint64_t h = hash64(t->keys[i]) & (cap - 1);
        while (keys[h]) h = (h + 1) & (cap - 1);
        keys[h] = t->keys[i];
        index[h] = t->index[i];
    }
    free(t->keys), free(t->index);
    t->keys = keys, t->index = index, t->cap = cap;
    return BF_OK;
}

/* Index of the brick with global coordinates b, added (empty) when new. */
static bf_status bin_brick(bin_state *st, const int64_t b[3], uint32_t *out)
{
    uint64_t key = brick_code(b) + 1;
    uint64_t h = hash64(key) & (st->t.cap - 1);
    while (st->t.keys[h]) {
        if (st->t.keys[h] == key) {
            *out = st->t.index[h];
            return BF_OK;
        }
        h = (h + 1) & (st->t.cap - 1);
    }
    if (st->n == st->cap) {
        uint32_t cap = st->cap ? 2 * st->cap : 1024;
        hostmap_brick *nb = bf_realloc(st->bricks, (size_t)cap * sizeof *nb);
        if (nb) st->bricks = nb;
        uint64_t *nc = nb ? bf_realloc(st->codes, (size_t)cap * 8) : NULL;
        if (nc) st->codes = nc;
        if (!nb || !nc) return bf_fail(BF_NO_MEMORY, "render: %u particle bricks", cap);
        st->cap = cap;
    }
    st->t.keys[h] = key;
    st->t.index[h] = st->n;
    memset(&st->bricks[st->n], 0, sizeof st->bricks[st->n]);
    st->codes[st->n] = key - 1;
    *out = st->n++;
    /* Keep the table at most half full. */
    if (++st->t.n * 2 > st->t.cap) return table_grow(&st->t);
    return BF_OK;
}

/* The level of the bricks: chunks of about a metre (fusion's default is 2
 * m; a metre keeps the octree 6 levels deep at the default 2.5 mm cells). */
static uint32_t bin_level(double cell_m)
{
    double l = floor(log2(1.0 / (8.0 * cell_m)) + 0.5);
    return l < 1 ? 1u : (l > FUSION_MAX_LEVEL ? FUSION_MAX_LEVEL : (uint32_t)l);
}

/* The 21 low bits of v spread to every third bit (Morton order). */
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

/* Morton code of a brick: ancestors k levels up share its code >> 3k. */
static uint64_t morton3(const int64_t b[3])
{
    return spread3((uint64_t)b[0]) << 2 | spread3((uint64_t)b[1]) << 1 | spread3((uint64_t)b[2]);
}

static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* Nodes and chunks the octrees of these bricks need: a chunk's root, and 8
 * children for every node with one (fusion_load builds them so). */
static bf_status count_nodes(const bin_state *st, uint32_t level, uint64_t *n_nodes, uint64_t *n_chunks)
{
    uint64_t *m = bf_malloc((st->n ? st->n : 1) * 8ull);
    if (!m) return bf_fail(BF_NO_MEMORY, "render: particle octrees");
    for (uint32_t i = 0; i < st->n; i++) {
        uint64_t c = st->codes[i], mask = (1ull << BIN_AXIS_BITS) - 1;
        int64_t b[3] = {(int64_t)(c >> (2 * BIN_AXIS_BITS)), (int64_t)((c >> BIN_AXIS_BITS) & mask),
                        (int64_t)(c & mask)};
        m[i] = morton3(b);
    }
    qsort(m, st->n, 8, cmp_u64);
    uint64_t nodes = 0, chunks = 0;
    for (uint32_t k = 1; k <= level; k++) {
        uint64_t distinct = 0;
        for (uint32_t i = 0; i < st->n; i++)
            if (i == 0 || (m[i] >> (3 * k)) != (m[i - 1] >> (3 * k))) distinct++;
        nodes += 8 * distinct; /* the children of each parent k levels up */
        if (k == level) chunks = distinct, nodes += distinct; /* the roots */
    }
    free(m);
    *n_nodes = nodes;
    *n_chunks = chunks;
    return BF_OK;
}

/* Sets the reach bits of brick hb (global coordinates b) for the cells the
 * sphere at cc (cell units) of radius reach (cells) overlaps: those whose
 * box is within reach of the centre. */
static void bin_reach(hostmap_brick *hb, const int64_t b[3], const double cc[3], double reach)
{
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = (int64_t)floor(cc[a] - reach) - b[a] * 8;
        hi[a] = (int64_t)floor(cc[a] + reach) - b[a] * 8;
        if (lo[a] < 0) lo[a] = 0;
        if (hi[a] > 7) hi[a] = 7;
    }
    double r2 = reach * reach;
    for (int64_t z = lo[2]; z <= hi[2]; z++) {
        double dz = cc[2] - (double)(b[2] * 8 + z);
        dz = dz < 0 ? -dz : (dz > 1 ? dz - 1 : 0);
        for (int64_t y = lo[1]; y <= hi[1]; y++) {
            double dy = cc[1] - (double)(b[1] * 8 + y);
            dy = dy < 0 ? -dy : (dy > 1 ? dy - 1 : 0);
            for (int64_t x = lo[0]; x <= hi[0]; x++) {
                double dx = cc[0] - (double)(b[0] * 8 + x);
                dx = dx < 0 ? -dx : (dx > 1 ? dx - 1 : 0);
                if (dx * dx + dy * dy + dz * dz > r2) continue;
                hb->conf[brick_word((uint32_t)x, (uint32_t)y, (uint32_t)z)] |=
                    1u << brick_bit((uint32_t)x, (uint32_t)y, (uint32_t)z);
            }
        }
    }
}

/* The reach bits of a centre depend only on its cell's place in its brick
 * (the centre is the cell's middle): for each of the 512 places, the
 * neighbour bricks (offsets -1..1) the sphere overlaps and their 16 words.
 * Built once per set when the reach is at most 8 cells (a brick); beyond,
 * bin_reach runs per particle. */
typedef struct reach_table {
    uint32_t n[512];
    int8_t off[512][27][3];
    uint32_t mask[512][27][16];
} reach_table;

static reach_table *reach_table_make(double reach)
{
    if (reach > 8.0) return NULL;
    reach_table *t = bf_calloc(1, sizeof *t);
    if (!t) return NULL;
    for (uint32_t l = 0; l < 512; l++) {
        double cc[3] = {(l & 7) + 0.5, ((l >> 3) & 7) + 0.5, (l >> 6) + 0.5};
        for (int k = 0; k < 27; k++) {
            int64_t b[3] = {k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1};
            hostmap_brick hb;
            memset(hb.conf, 0, sizeof hb.conf);
            bin_reach(&hb, b, cc, reach);
            bool any = false;
            for (int w = 0; w < 16; w++) any |= hb.conf[w] != 0;
            if (!any) continue;
            uint32_t i = t->n[l]++;
            for (int a = 0; a < 3; a++) t->off[l][i][a] = (int8_t)b[a];
            memcpy(t->mask[l][i], hb.conf, sizeof hb.conf);
        }
    }
    return t;
}

/* Bins the particles into st (bricks with their bits) and the host copy. */
static bf_status bin_particles(const render_particles_config *c, const float *xyz, uint64_t n, bf_vec3 origin,
                               uint32_t level, bin_state *st, render_particles_stats *ps)
{
    double cell = c->cell_m, inv = 1.0 / cell;
    double reach = c->radius_m * inv; /* the sphere's reach beyond the centre [cells] */
    bf_status s = table_grow(&st->t);
    reach_table *rt = reach_table_make(reach); /* NULL: per particle (slower, any reach) */
    for (uint64_t i = 0; s == BF_OK && i < n; i++) {
        double p[3] = {xyz[3 * i] - origin.x, xyz[3 * i + 1] - origin.y, xyz[3 * i + 2] - origin.z};
        int64_t g[3], b[3];
        for (int a = 0; a < 3; a++) g[a] = (int64_t)floor(p[a] * inv), b[a] = g[a] >> 3;
        uint32_t bi = 0;
        s = bin_brick(st, b, &bi);
        if (s != BF_OK) break;
        uint32_t x = (uint32_t)(g[0] & 7), y = (uint32_t)(g[1] & 7), z = (uint32_t)(g[2] & 7);
        uint32_t w = brick_word(x, y, z), bit = 1u << brick_bit(x, y, z);
        hostmap_brick *hb = &st->bricks[bi];
        if (hb->sign[w] & bit) continue; /* the cell is set, its reach done */
        hb->sign[w] |= bit;
        ps->n_cells++;
        /* Every brick the sphere's box touches, and in it the reach bit of
         * every cell the sphere overlaps. */
        if (rt) {
            uint32_t l = x + 8 * y + 64 * z;
            for (uint32_t k = 0; s == BF_OK && k < rt->n[l]; k++) {
                int64_t nb[3] = {b[0] + rt->off[l][k][0], b[1] + rt->off[l][k][1], b[2] + rt->off[l][k][2]};
                s = bin_brick(st, nb, &bi);
                for (int q = 0; s == BF_OK && q < 16; q++) st->bricks[bi].conf[q] |= rt->mask[l][k][q];
            }
            continue;
        }
        double cc[3] = {g[0] + 0.5, g[1] + 0.5, g[2] + 0.5};
        int64_t lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            lo[a] = (int64_t)floor((cc[a] - reach) / 8.0);
            hi[a] = (int64_t)floor((cc[a] + reach) / 8.0);
        }
        for (int64_t bz = lo[2]; s == BF_OK && bz <= hi[2]; bz++)
            for (int64_t by = lo[1]; s == BF_OK && by <= hi[1]; by++)
                for (int64_t bx = lo[0]; s == BF_OK && bx <= hi[0]; bx++) {
                    int64_t nb[3] = {bx, by, bz};
                    s = bin_brick(st, nb, &bi);
                    if (s == BF_OK) bin_reach(&st->bricks[bi], nb, cc, reach);
                }
    }
    free(rt);
    if (s != BF_OK) return s;
    uint32_t per = 1u << level;
    uint64_t mask = (1ull << BIN_AXIS_BITS) - 1;
    for (uint32_t i = 0; i < st->n; i++) {
        hostmap_brick *hb = &st->bricks[i];
        uint64_t code = st->codes[i];
        uint64_t b[3] = {code >> (2 * BIN_AXIS_BITS), (code >> BIN_AXIS_BITS) & mask, code & mask};
        for (int a = 0; a < 3; a++) hb->key[a] = (int32_t)(b[a] >> level), hb->cell[a] = (uint32_t)(b[a] & (per - 1));
        hb->level = level;
        bool any = false;
        for (int w = 0; w < 16; w++) any |= hb->sign[w] != 0;
        if (any) ps->n_bricks++;
        else ps->n_pad_bricks++;
    }
    return BF_OK;
}

/* The config with its defaults filled in, or BF_INVALID_ARG. */
static bf_status check_config(const render_particles_config *in, render_particles_config *out)
{
    render_particles_config c = *in;
    if (!(c.radius_m > 0) || !isfinite(c.radius_m) || c.radius_m > 10)
        return bf_fail(BF_INVALID_ARG, "render: particle radius %g m (above 0, at most 10)", c.radius_m);
    if (c.cell_m == 0) c.cell_m = 0.25f * c.radius_m;
    if (!(c.cell_m >= 1e-5f) || !(c.cell_m <= 2 * c.radius_m))
        return bf_fail(BF_INVALID_ARG, "render: particle cell %g m (10 um .. 2 radii = %g m)", c.cell_m,
                       2 * c.radius_m);
    *out = c;
    return BF_OK;
}

/* The set's box, origin and level, or BF_INVALID_ARG for a bad position or
 * a set too wide for the cells. */
static bf_status set_frame(const render_particles_config *c, const float *xyz, uint64_t n, bf_vec3 *origin)
{
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    for (uint64_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            double v = xyz[3 * i + a];
            if (!isfinite(v))
                return bf_fail(BF_INVALID_ARG, "render: particle %llu: position is not finite", (unsigned long long)i);
            if (i == 0 || v < lo[a]) lo[a] = v;
            if (i == 0 || v > hi[a]) hi[a] = v;
        }
    /* The origin a brick below the box less the reach: no brick coordinate
     * is negative, padding included. */
    double margin = c->radius_m + 8.0 * c->cell_m;
    for (int a = 0; a < 3; a++)
        if ((hi[a] - lo[a] + 2 * margin) / c->cell_m >= (double)BIN_MAX_CELLS)
            return bf_fail(BF_INVALID_ARG, "render: particles span %g m on axis %d: more than %lld cells of %g m",
                           hi[a] - lo[a], a, (long long)BIN_MAX_CELLS, c->cell_m);
    *origin = bf_v3(lo[0] - margin, lo[1] - margin, lo[2] - margin);
    return BF_OK;
}

/* Cells a ray walks per dispatch and the dispatches (shaders/render.glsl.h,
 * RENDER_PARTICLES_LOOP_BUDGET). The limit counts a loop's iterations once
 * for the 8 lanes running it in lockstep; a cell costs at most the reach
 * DDA's 24 steps and a search of up to nb bricks (the segment's box grown
 * by the reach), each at most 20 iterations (its 16 words, the lookup
 * through the cached parent, the brick loop). */
static void pass_budget(const render_particles_config *c, uint32_t *cells_per_pass, uint32_t *n_passes)
{
    double reach = c->radius_m / c->cell_m;
    double per_axis = floor((8.0 + 2.0 * reach) / 8.0) + 1.0;
    double per_cell = 24.0 + 20.0 * per_axis * per_axis * per_axis;
    double k = floor(RENDER_PARTICLES_LOOP_BUDGET / per_cell);
    *cells_per_pass = k < 1 ? 1u : (k > 256 ? 256u : (uint32_t)k);
    *n_passes = (RENDER_PARTICLES_MAX_CELLS + *cells_per_pass - 1) / *cells_per_pass;
}

bf_status render_particles_create(gpu_context *ctx, const render_particles_config *cfg, const float *xyz, uint64_t n,
                                  render_particles **out)
{
    if (!ctx || !out || (n && !xyz)) return bf_fail(BF_INVALID_ARG, "render_particles_create: NULL argument");
    render_particles_config c;
    render_particles_config def = render_particles_config_default();
    bf_status s = check_config(cfg ? cfg : &def, &c);
    bf_vec3 origin = {0, 0, 0};
    if (s == BF_OK) s = set_frame(&c, xyz, n, &origin);
    if (s != BF_OK) return s;
    render_particles *ps = bf_calloc(1, sizeof *ps);
    if (!ps) return bf_fail(BF_NO_MEMORY, "render: particle set");
    ps->ctx = ctx;
    ps->cfg = c;
    uint32_t level = bin_level(c.cell_m);
    render_particles_stats *st = &ps->stats;
    st->n_particles = n;
    st->origin_w = origin;
    st->level = level;
    st->cell_m = c.cell_m;
    st->chunk_m = (float)(c.cell_m * 8.0 * (double)(1u << level));
    pass_budget(&c, &ps->cells_per_pass, &ps->n_passes);

    double t0 = bf_time_s();
    bin_state bs = {0};
    s = bin_particles(&c, xyz, n, origin, level, &bs, st);
    uint64_t n_nodes = 0, n_chunks = 0;
    if (s == BF_OK) s = count_nodes(&bs, level, &n_nodes, &n_chunks);
    st->bin_s = bf_time_s() - t0;
    if (s == BF_OK && (bs.n > (1u << 28) || n_nodes > (1u << 28)))
        s = bf_fail(BF_NO_MEMORY, "render: %u particle bricks, %llu nodes", bs.n, (unsigned long long)n_nodes);
    /* The pass binds each bit plane whole: one storage binding must hold it
     * (lavapipe: 128 MiB, 2 M bricks). */
    uint64_t plane_bytes = (uint64_t)bs.n * BRICK_WORDS * 4;
    if (s == BF_OK && plane_bytes > gpu_binding_max_bytes(ctx, 4))
        s = bf_fail(BF_NO_MEMORY, "render: %u particle bricks need %.0f MiB bit planes, a binding holds %.0f MiB "
                                  "(a larger cell or radius needs fewer)",
                    bs.n, plane_bytes / 1048576.0, gpu_binding_max_bytes(ctx, 4) / 1048576.0);
    if (s == BF_OK) {
        /* A map that only ever holds what is loaded: no frames, no colour. */
        fusion_config fc = fusion_config_default();
        fc.chunk_m = st->chunk_m;
        fc.max_level = level;
        fc.window = 2;
        fc.subcache = 1;
        fc.keep_colour = false;
        fc.brick_cap = bs.n ? bs.n : 1;
        fc.node_cap = (uint32_t)n_nodes + 64;
        uint32_t buckets = 64;
        while (buckets < 2 * n_chunks) buckets *= 2;
        fc.hash_buckets = buckets;
        fc.hash_overflow = buckets;
        bf_intrinsics K = {8, 8, 8.0, 8.0, 3.5, 3.5, 5000};
        s = fusion_create(ctx, &fc, &K, origin, &ps->map);
    }
    if (s == BF_OK) {
        hostmap hm = {.chunk_m = st->chunk_m, .origin_w = origin, .n_bricks = bs.n, .bricks = bs.bricks};
        double t1 = bf_time_s();
        s = fusion_load(ps->map, &hm);
        st->load_s = bf_time_s() - t1;
    }
    free(bs.t.keys), free(bs.t.index), free(bs.bricks), free(bs.codes);
    gpu_pipeline_desc pd = {
        .name = "render.particles",
        .spirv = bf_spv_render_particles,
        .spirv_bytes = bf_spv_render_particles_size,
        .n_buffers = 9,
        .push_bytes = sizeof(render_particles_push),
        .local_size = {RENDER_LOCAL_X, RENDER_LOCAL_Y, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &ps->pipe);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 9, "render.particles", &ps->bind);
    fusion_gpu_view v = {0};
    if (s == BF_OK) v = fusion_gpu_view_get(ps->map);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 0, v.hash, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 1, v.nodes, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 2, v.sign, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 7, v.conf, 0, GPU_WHOLE_SIZE);
    /* A resume buffer until the first cast makes one for its images (the warm-up binds every slot). */
    gpu_buffer_desc rd = {.name = "render.particles.resume", .size_bytes = 16, .memory = GPU_MEMORY_DEVICE,
                          .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
    if (s == BF_OK) s = gpu_buffer_create(ctx, &rd, &ps->resume);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 8, ps->resume, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_pipeline_warm_up(ctx, &ps->pipe, 1);
    if (s != BF_OK) {
        render_particles_destroy(ps);
        return s;
    }
    *out = ps;
    return BF_OK;
}

void render_particles_destroy(render_particles *ps)
{
    if (!ps) return;
    gpu_bindings_destroy(ps->bind);
    gpu_pipeline_destroy(ps->pipe);
    gpu_buffer_destroy(ps->resume);
    fusion_destroy(ps->map);
    memset(ps, 0xff, sizeof *ps); /* poison: a use after destroy fails loudly */
    free(ps);
}

const render_particles_stats *render_particles_get_stats(const render_particles *ps) { return &ps->stats; }

double render_particles_last_ms(const render_particles *ps) { return ps->last_ms; }

/* ------------------------------------------------------------ the pass */

bf_status render_cmd_particles(render_caster *rc, render_particles *ps, const bf_intrinsics *K, const bf_se3 *T_wc,
                               const render_options *opt, bool keep_nearer)
{
    if (!rc || !ps || !K || !T_wc || !opt) return bf_fail(BF_INVALID_ARG, "render: NULL argument");
    const render_targets *tg = render_get_targets(rc);
    if (K->width != tg->width || K->height != tg->height)
        return bf_fail(BF_INVALID_ARG, "render: intrinsics are %ux%u, the caster's images %ux%u", K->width,
                       K->height, tg->width, tg->height);
    if (!(K->fx_px > 0) || !(K->fy_px > 0) || !isfinite(K->cx_px) || !isfinite(K->cy_px))
        return bf_fail(BF_INVALID_ARG, "render: intrinsics fx %g fy %g cx %g cy %g", K->fx_px, K->fy_px, K->cx_px,
                       K->cy_px);
    if (!bf_se3_is_finite(T_wc)) return bf_fail(BF_INVALID_ARG, "render: camera pose is not finite");
    if (!(opt->near_m > 0) || !(opt->far_m > opt->near_m) || !isfinite(opt->far_m))
        return bf_fail(BF_INVALID_ARG, "render: depth range [%g, %g] m", opt->near_m, opt->far_m);
    if (opt->depth_out) return bf_fail(BF_INVALID_ARG, "render: particles write the caster's own depth image");
    gpu_buffer *imgs[4] = {tg->depth, tg->level, tg->normal, tg->colour};
    for (uint32_t i = 0; i < 4; i++) {
        if (ps->bound[i] == imgs[i]) continue;
        bf_status s = gpu_bindings_set(ps->bind, 3 + i, imgs[i], 0, GPU_WHOLE_SIZE);
        if (s != BF_OK) return s;
        ps->bound[i] = imgs[i];
    }
    uint64_t n_px = (uint64_t)K->width * K->height;
    if (gpu_buffer_size(ps->resume) < n_px * 4) {
        /* A new image size: the old buffer's last reader was waited for
         * (render_scene waits; a caller recording its own waits too). */
        gpu_buffer *nb;
        gpu_buffer_desc rd = {.name = "render.particles.resume", .size_bytes = n_px * 4, .memory = GPU_MEMORY_DEVICE,
                              .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
        bf_status s = gpu_buffer_create(ps->ctx, &rd, &nb);
        if (s == BF_OK) s = gpu_bindings_set(ps->bind, 8, nb, 0, GPU_WHOLE_SIZE);
        if (s != BF_OK) {
            gpu_buffer_destroy(nb);
            return s;
        }
        gpu_buffer_destroy(ps->resume);
        ps->resume = nb;
    }
    fusion_gpu_view v = fusion_gpu_view_get(ps->map);
    bf_se3 T_mc = fusion_camera_to_map(ps->map, T_wc);
    render_particles_push pc = {
        .fx = (float)K->fx_px,
        .fy = (float)K->fy_px,
        .cx = (float)K->cx_px,
        .cy = (float)K->cy_px,
        .width = K->width,
        .height = K->height,
        .near_m = opt->near_m,
        .far_m = opt->far_m,
        .chunk_m = v.chunk_m,
        .n_buckets = v.n_buckets,
        .n_overflow = v.n_entries - v.n_buckets * FUSION_BUCKET_SLOTS,
        .max_level = v.max_level,
        .radius_m = ps->cfg.radius_m,
        .flags = keep_nearer ? RENDER_PARTICLES_FLAG_KEEP_NEARER : 0u,
        .rgb = ps->cfg.rgb,
        .cells_per_pass = ps->cells_per_pass,
    };
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) pc.R[3 * r + c] = (float)T_mc.R[r][c];
    pc.t[0] = (float)T_mc.t.x, pc.t[1] = (float)T_mc.t.y, pc.t[2] = (float)T_mc.t.z;
    /* The images' earlier writes (the map's ray-cast and shading) -> this
     * pass's reads and writes of them. */
    gpu_cmd_barrier(ps->ctx, GPU_BARRIER_COMPUTE);
    gpu_cmd_stage_begin(ps->ctx, "render.particles");
    uint32_t flags = pc.flags;
    for (uint32_t p = 0; p < ps->n_passes; p++) {
        pc.flags = flags | (p == 0 ? RENDER_PARTICLES_FLAG_FIRST : 0u) |
                   (p + 1 == ps->n_passes ? RENDER_PARTICLES_FLAG_LAST : 0u);
        /* The last dispatch's resume depths and images -> this one's reads. */
        if (p > 0) gpu_cmd_barrier(ps->ctx, GPU_BARRIER_COMPUTE);
        gpu_cmd_dispatch(ps->ctx, ps->pipe, ps->bind, &pc, gpu_groups(K->width, RENDER_LOCAL_X),
                         gpu_groups(K->height, RENDER_LOCAL_Y), 1);
    }
    gpu_cmd_stage_end(ps->ctx);
    /* The images -> the readers recorded next. */
    gpu_cmd_barrier(ps->ctx, GPU_BARRIER_COMPUTE);
    return BF_OK;
}

bf_status render_scene(render_caster *rc, fusion_map *map, render_particles *ps, const bf_intrinsics *K,
                       const bf_se3 *T_wc, const render_options *opt)
{
    if (!rc || (!map && !ps) || !opt) return bf_fail(BF_INVALID_ARG, "render_scene: nothing to render");
    if (!ps) return render_raycast(rc, map, K, T_wc, opt);
    /* The map and the particles in one submission: the particle pass reads
     * the map's depth where the map's ray-cast wrote it. */
    gpu_context *ctx = ps->ctx;
    bf_status s;
    if ((s = gpu_begin(ctx)) != BF_OK) return s;
    if (map) s = render_cmd_raycast(rc, map, K, T_wc, opt);
    if (s == BF_OK) s = render_cmd_particles(rc, ps, K, T_wc, opt, map != NULL);
    /* The images -> host downloads (render_download). */
    gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
    bf_status sw = gpu_submit_wait(ctx);
    if (s != BF_OK) return s;
    if (sw != BF_OK) return sw;
    if (map) render_finish_raycast(rc);
    ps->last_ms = gpu_stage_ms(ctx, "render.particles");
    return BF_OK;
}
