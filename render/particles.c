/* The particle renderer's host side (render.h, "particles"; Reichl's
 * dissertation, ch. 6, binary grids for particle rendering): binning on the
 * host into a host copy of the map structure, which fusion_load puts into
 * a fusion_map of the set's own (the same pools, hash and octrees the
 * ray-caster walks), and the particle pass (shaders/render_particles.comp).
 *
 * Binning (render/particles_bin.c: sorted by brick, two threads): each
 * particle sets the bit of the cell holding it (cells of cell_m on the
 * centres' level; only bricks holding centres are made). Three levels up,
 * the coarse level's cells are those bricks: a coarse cell's sign bit says
 * its brick exists, its reach bit that a sphere overlaps it. The ray walks
 * the coarse level only, so the bricks around the spheres that an earlier
 * single-level layout had to allocate empty (86% of the dam break's) are
 * gone, and a ray crosses empty space eight times faster; the traverser
 * searches the bricks of centres near each reached coarse cell on the ray.
 * A moving set is re-binned into the same map, emptied
 * (render_particles_update). */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bf_shaders_spv.h"
#include "particles_bin.h"
#include "render_int.h"
#include "shaders/fusion.glsl.h"

struct render_particles {
    gpu_context *ctx;
    fusion_map *map;
    render_particles_config cfg;
    render_particles_stats stats;
    gpu_pipeline *pipe;
    gpu_bindings *bind;
    gpu_buffer *bound[4]; /* the caster images bound at 3..6 */
    gpu_buffer *resume;   /* binding 8: per pixel, where a ray resumes; made for the image size */
    gpu_buffer *lists;    /* binding 9: two lists of unfinished rays' pixels; made for the image size */
    gpu_buffer *args;     /* binding 10: per dispatch, the next one's group counts and list length */
    gpu_buffer *index;    /* binding 11: the centres' index (render/particles_bin.h) */
    particles_binner *binner; /* kept: a re-binned set touches no new host memory */
    uint32_t brick_cap, node_cap, n_buckets; /* what ps->map holds */
    bool too_many; /* the last binning needed more bricks than a binding holds */
    bool unbound;  /* a failed update left the pass bound to a destroyed map */
    uint32_t cells_per_pass, n_passes, work_budget;
    double box_w[2][3]; /* the particles' box (world), lowest then highest */
    double last_ms;
};

render_particles_config render_particles_config_default(void)
{
    return (render_particles_config){.radius_m = 0.01f, .cell_m = 0.0f, .rgb = 0x00DC8246u};
}

/* ------------------------------------------------------------ binning */

/* The level of the bricks of centres: chunks of about a metre (fusion's
 * default is 2 m; a metre keeps the octree 7 levels deep at the default
 * 1.25 mm cells), and the coarse level (PARTICLES_COARSE_LEVELS above) at
 * least 1 (its lookups go through the parent node). */
static uint32_t bin_level(double cell_m)
{
    double l = floor(log2(1.0 / (8.0 * cell_m)) + 0.5);
    uint32_t min = (uint32_t)PARTICLES_COARSE_LEVELS + 1u;
    return l < min ? min : (l > FUSION_MAX_LEVEL ? FUSION_MAX_LEVEL : (uint32_t)l);
}

/* The config with its defaults filled in, or BF_INVALID_ARG. */
static bf_status check_config(const render_particles_config *in, render_particles_config *out)
{
    render_particles_config c = *in;
    if (!(c.radius_m > 0) || !isfinite(c.radius_m) || c.radius_m > 10)
        return bf_fail(BF_INVALID_ARG, "render: particle radius %g m (above 0, at most 10)", c.radius_m);
    if (c.cell_m == 0) c.cell_m = c.radius_m / 8.0f;
    if (!(c.cell_m >= 1e-5f) || !(c.cell_m <= 2 * c.radius_m))
        return bf_fail(BF_INVALID_ARG, "render: particle cell %g m (10 um .. 2 radii = %g m)", c.cell_m,
                       2 * c.radius_m);
    /* The map's chunk is 8 cells times the level's bricks per edge: fusion
     * takes chunks of at most 64 m. */
    double chunk = c.cell_m * 8.0 * (double)(1u << bin_level(c.cell_m));
    if (chunk > 64)
        return bf_fail(BF_INVALID_ARG, "render: particle cell %g m makes the map's chunks %g m, beyond 64 m: a smaller "
                       "radius or cell", c.cell_m, chunk);
    if (c.work_budget > RENDER_PARTICLES_WORK_BUDGET)
        return bf_fail(BF_INVALID_ARG, "render: particle work budget %u (at most %u)", c.work_budget,
                       RENDER_PARTICLES_WORK_BUDGET);
    *out = c;
    return BF_OK;
}

/* The set's box, origin and level, or BF_INVALID_ARG for a bad position or
 * a set too wide for the cells. */
static bf_status set_frame(const render_particles_config *c, const float *xyz, uint64_t n, bf_vec3 *origin,
                           double box[2][3])
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
    /* The origin a brick below the box less the reach (whole cells): no
     * brick coordinate is negative, padding included. And half a cell more,
     * so the box's lowest corner is a cell's middle: a lattice (a
     * simulation's first step) whose spacing is a whole number of cells
     * keeps its centres exactly; at a cell's face, as from a corner on the
     * grid, they would move by half a cell. */
    double margin = (ceil(c->radius_m / c->cell_m) + 8.5) * c->cell_m;
    for (int a = 0; a < 3; a++)
        if ((hi[a] - lo[a] + 2 * margin) / c->cell_m >= (double)PARTICLES_MAX_CELLS)
            return bf_fail(BF_INVALID_ARG, "render: particles span %g m on axis %d: more than %lld cells of %g m",
                           hi[a] - lo[a], a, (long long)PARTICLES_MAX_CELLS, c->cell_m);
    *origin = bf_v3(lo[0] - margin, lo[1] - margin, lo[2] - margin);
    for (int a = 0; a < 3; a++) box[0][a] = lo[a], box[1][a] = hi[a];
    return BF_OK;
}

/* Coarse bricks a ray walks per dispatch and the dispatches
 * (shaders/render.glsl.h, RENDER_PARTICLES_LOOP_BUDGET). The limit counts a
 * loop's iterations once for the 8 lanes running it in lockstep: a walk
 * step costs at most its descent (the coarse level's depth) and the DDA's
 * 32 steps (cells and skipped sub-bricks), and the searches stop
 * themselves at the work budget. The dispatches after the first run only
 * on the rays left unfinished (a list, indirect group counts): a dispatch
 * with none costs nothing, so there are 28 more than the walk needs, for
 * the rays the searches paused. */
static void pass_budget(uint32_t coarse_level, uint32_t *cells_per_pass, uint32_t *n_passes)
{
    double per_cell = 1.0 + coarse_level + 32.0;
    double k = floor((RENDER_PARTICLES_LOOP_BUDGET - RENDER_PARTICLES_WORK_BUDGET) / per_cell);
    *cells_per_pass = k < 1 ? 1u : (k > 256 ? 256u : (uint32_t)k);
    *n_passes = (RENDER_PARTICLES_MAX_CELLS + *cells_per_pass - 1) / *cells_per_pass + 28;
}

/* The map's buffers and the centres' index -> the pass's bindings 0, 1, 2, 7 and 11. */
static bf_status bind_map(render_particles *ps)
{
    fusion_gpu_view v = fusion_gpu_view_get(ps->map);
    bf_status s = gpu_bindings_set(ps->bind, 0, v.hash, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 1, v.nodes, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 2, v.sign, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 7, v.conf, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 11, ps->index, 0, GPU_WHOLE_SIZE);
    return s;
}

/* The binning's centres' index into ps->index (made larger where it must
 * be, and bound where the bindings exist). */
static bf_status load_index(render_particles *ps, const particles_binned *bs)
{
    uint64_t bytes = bs->n_index * 4;
    if (!ps->index || gpu_buffer_size(ps->index) < bytes) {
        gpu_buffer *nb = NULL;
        gpu_buffer_desc d = {.name = "render.particles.index", .size_bytes = bytes + bytes / 4,
                             .memory = GPU_MEMORY_DEVICE, .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
        bf_status s = gpu_buffer_create(ps->ctx, &d, &nb);
        if (s == BF_OK && ps->bind) s = gpu_bindings_set(ps->bind, 11, nb, 0, GPU_WHOLE_SIZE);
        if (s != BF_OK) {
            gpu_buffer_destroy(nb);
            return s;
        }
        gpu_buffer_destroy(ps->index);
        ps->index = nb;
    }
    return gpu_buffer_upload(ps->index, 0, bs->index, bytes);
}

/* A map that only ever holds what is loaded (no frames, no colour) for at
 * least these bricks, nodes and chunks; grow > 1 makes room for a set that
 * grows by that factor, so a moving set seldom needs another. */
static bf_status make_map(render_particles *ps, bf_vec3 origin, const particles_binned *bs, double grow,
                          fusion_map **out)
{
    const render_particles_stats *st = &ps->stats;
    uint64_t bind_bricks = gpu_binding_max_bytes(ps->ctx, 4) / (BRICK_WORDS * 4);
    uint64_t bricks = (uint64_t)(grow * bs->n_bricks) + 1, nodes = (uint64_t)(grow * bs->n_nodes) + 64;
    if (bricks > bind_bricks) bricks = bind_bricks > bs->n_bricks ? bind_bricks : bs->n_bricks;
    fusion_config fc = fusion_config_default();
    fc.chunk_m = st->chunk_m;
    fc.max_level = st->level;
    fc.window = 2;
    fc.subcache = 1;
    fc.keep_colour = false;
    fc.load_only = true;
    fc.brick_cap = (uint32_t)bricks;
    fc.node_cap = (uint32_t)nodes;
    uint32_t buckets = 64;
    while (buckets < 2 * grow * bs->n_chunks) buckets *= 2;
    fc.hash_buckets = buckets;
    fc.hash_overflow = buckets;
    bf_intrinsics K = {8, 8, 8.0, 8.0, 3.5, 3.5, 5000};
    bf_status s = fusion_create(ps->ctx, &fc, &K, origin, out);
    if (s != BF_OK) return s;
    ps->brick_cap = fc.brick_cap, ps->node_cap = fc.node_cap, ps->n_buckets = buckets;
    return BF_OK;
}

/* CPU seconds of the process so far: binning's cost apart from what
 * else shares the cores. */
static double cpu_s(void)
{
    struct timespec t;
    return clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t) == 0 ? (double)t.tv_sec + 1e-9 * (double)t.tv_nsec : 0.0;
}

/* Bins xyz into the set's map: the map emptied and kept where it holds
 * the new bricks, else made anew (grow: room to spare). On failure the map
 * is empty or the old one. */
static bf_status bin_and_load(render_particles *ps, const float *xyz, uint64_t n, double grow)
{
    const render_particles_config *c = &ps->cfg;
    bf_vec3 origin = {0, 0, 0};
    double box[2][3];
    bf_status s = set_frame(c, xyz, n, &origin, box);
    if (s != BF_OK) return s;
    render_particles_stats *st = &ps->stats;
    double t0 = bf_time_s(), c0 = cpu_s();
    particles_binned bs;
    /* The pass binds each bit plane whole: one storage binding must hold it
     * (lavapipe: 128 MiB, 2 M bricks). */
    uint64_t max_bricks = gpu_binding_max_bytes(ps->ctx, 4) / (BRICK_WORDS * 4);
    s = particles_bin(ps->binner, xyz, n, origin, c->cell_m, c->radius_m, st->level, max_bricks, &bs);
    double bin_s = bf_time_s() - t0, bin_cpu_s = cpu_s() - c0;
    ps->too_many = bs.too_many;
    if (bs.too_many)
        return bf_fail(BF_NO_MEMORY, "render: %llu particles at %g m cells need more than %llu bricks, the most one "
                                     "binding holds (a larger cell or radius needs fewer)",
                       (unsigned long long)n, c->cell_m, (unsigned long long)max_bricks);
    if (s != BF_OK) return s;
    if (bs.n_bricks > (1u << 28) || bs.n_nodes > (1u << 28))
        return bf_fail(BF_NO_MEMORY, "render: %u particle bricks, %llu nodes", bs.n_bricks,
                       (unsigned long long)bs.n_nodes);
    st->make_s = 0;
    bool fits = ps->map && bs.n_bricks <= ps->brick_cap && bs.n_nodes + 64 <= ps->node_cap &&
                2 * bs.n_chunks <= ps->n_buckets;
    double t1 = bf_time_s();
    if (fits) {
        s = fusion_clear(ps->map);
    } else {
        fusion_map *nm = NULL;
        s = make_map(ps, origin, &bs, grow, &nm);
        if (s == BF_OK) {
            fusion_destroy(ps->map);
            ps->map = nm;
            if (ps->bind) s = bind_map(ps);
            /* Bindings part old, part new: the set stays unusable. */
            ps->unbound = s != BF_OK;
        }
        double made = bf_time_s();
        st->make_s = made - t1;
        t1 = made; /* making the map (its pools) is not loading it */
    }
    if (s == BF_OK) {
        hostmap hm = {.chunk_m = st->chunk_m, .origin_w = origin, .n_bricks = bs.n_bricks, .bricks = bs.bricks};
        s = fusion_load(ps->map, &hm);
    }
    if (s == BF_OK && (s = load_index(ps, &bs)) != BF_OK) {
        /* The pools hold the new set, the index the old one: empty the map
         * (a set that draws nothing) rather than cast a mix. */
        (void)fusion_clear(ps->map);
    }
    if (s != BF_OK) return s;
    st->n_particles = n;
    st->origin_w = origin;
    memcpy(ps->box_w, box, sizeof box);
    st->n_cells = bs.n_cells;
    st->n_bricks = bs.n_occupied;
    st->n_coarse_bricks = bs.n_coarse;
    st->bin_s = bin_s;
    st->bin_cpu_s = bin_cpu_s;
    st->load_s = bf_time_s() - t1;
    st->map_made = !fits;
    st->bytes_used = (uint64_t)bs.n_bricks * (2 * BRICK_WORDS + FUSION_BRICK_INFO_WORDS + 1) * 4 +
                     bs.n_nodes * FUSION_NODE_WORDS * 4 + bs.n_chunks * FUSION_ENTRY_WORDS * 4 + bs.n_index * 4;
    st->bytes_reserved = fusion_reserved_bytes(ps->map) + (ps->index ? gpu_buffer_size(ps->index) : 0);
    return BF_OK;
}

/* The set binned at the cell of c (the level, chunk and dispatches it
 * takes with it). */
static bf_status set_cell(render_particles *ps, const render_particles_config *c, const float *xyz, uint64_t n)
{
    ps->cfg = *c;
    render_particles_stats *st = &ps->stats;
    st->level = bin_level(c->cell_m);
    st->cell_m = c->cell_m;
    st->chunk_m = (float)(c->cell_m * 8.0 * (double)(1u << st->level));
    pass_budget(st->level - PARTICLES_COARSE_LEVELS, &ps->cells_per_pass, &ps->n_passes);
    ps->work_budget = c->work_budget ? c->work_budget : RENDER_PARTICLES_WORK_BUDGET;
    if (ps->map) { /* another cell: another chunk edge */
        fusion_destroy(ps->map);
        ps->map = NULL;
    }
    return bin_and_load(ps, xyz, n, 1.0);
}

bf_status render_particles_check_config(const render_particles_config *cfg)
{
    render_particles_config c;
    return check_config(cfg, &c);
}

bf_status render_particles_create(gpu_context *ctx, const render_particles_config *cfg, const float *xyz, uint64_t n,
                                  render_particles **out)
{
    if (!ctx || !out || (n && !xyz)) return bf_fail(BF_INVALID_ARG, "render_particles_create: NULL argument");
    render_particles_config c;
    render_particles_config def = render_particles_config_default();
    bf_status s = check_config(cfg ? cfg : &def, &c);
    if (s != BF_OK) return s;
    render_particles *ps = bf_calloc(1, sizeof *ps);
    if (!ps) return bf_fail(BF_NO_MEMORY, "render: particle set");
    ps->ctx = ctx;
    ps->binner = particles_binner_create();
    if (!ps->binner) s = bf_fail(BF_NO_MEMORY, "render: particle binning");
    if (s == BF_OK) s = set_cell(ps, &c, xyz, n);
    /* The default cell (cell_m 0) is an eighth of the radius where its
     * bricks fit, else a quarter (sparse sets of many particles: a sphere
     * reaches 27 bricks of eighth-radius cells, 8 of quarter-radius ones). */
    bool auto_cell = !(cfg ? cfg : &def)->cell_m;
    render_particles_config quarter = c;
    quarter.cell_m = c.radius_m / 4.0f;
    render_particles_config unused;
    if (s == BF_NO_MEMORY && ps->too_many && auto_cell && check_config(&quarter, &unused) == BF_OK) {
        c = quarter; /* only where its chunks fit the map (64 m): else the eighth's failure stands */
        s = set_cell(ps, &c, xyz, n);
    }
    gpu_pipeline_desc pd = {
        .name = "render.particles",
        .spirv = bf_spv_render_particles,
        .spirv_bytes = bf_spv_render_particles_size,
        .n_buffers = 12,
        .push_bytes = sizeof(render_particles_push),
        .local_size = {RENDER_LOCAL_X, RENDER_LOCAL_Y, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &ps->pipe);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 12, "render.particles", &ps->bind);
    if (s == BF_OK) s = bind_map(ps);
    /* Resume and list buffers until the first cast makes them for its
     * images (the warm-up binds every slot); the arguments for every
     * dispatch. */
    gpu_buffer_desc rd = {.name = "render.particles.resume", .size_bytes = 16, .memory = GPU_MEMORY_DEVICE,
                          .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
    gpu_buffer_desc ld = rd, ad = rd;
    ld.name = "render.particles.lists";
    ad.name = "render.particles.args";
    ad.size_bytes = (uint64_t)ps->n_passes * RENDER_PARTICLES_ARGS_WORDS * 4;
    ad.usage |= GPU_USAGE_INDIRECT;
    if (s == BF_OK) s = gpu_buffer_create(ctx, &rd, &ps->resume);
    if (s == BF_OK) s = gpu_buffer_create(ctx, &ld, &ps->lists);
    if (s == BF_OK) s = gpu_buffer_create(ctx, &ad, &ps->args);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 8, ps->resume, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 9, ps->lists, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_bindings_set(ps->bind, 10, ps->args, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_pipeline_warm_up(ctx, &ps->pipe, 1);
    if (s != BF_OK) {
        render_particles_destroy(ps);
        return s;
    }
    *out = ps;
    return BF_OK;
}

bf_status render_particles_update(render_particles *ps, const float *xyz, uint64_t n)
{
    if (!ps || (n && !xyz)) return bf_fail(BF_INVALID_ARG, "render_particles_update: NULL argument");
    /* Room for a quarter more when the map must grow. */
    bf_status s = bin_and_load(ps, xyz, n, 1.25);
    if (s != BF_OK && fusion_pool_usage(ps->map).bricks == 0) { /* emptied */
        render_particles_stats *st = &ps->stats;
        st->n_particles = st->n_cells = 0;
        st->n_bricks = st->n_coarse_bricks = 0;
    }
    return s;
}

void render_particles_destroy(render_particles *ps)
{
    if (!ps) return;
    gpu_bindings_destroy(ps->bind);
    gpu_pipeline_destroy(ps->pipe);
    gpu_buffer_destroy(ps->resume);
    gpu_buffer_destroy(ps->lists);
    gpu_buffer_destroy(ps->args);
    gpu_buffer_destroy(ps->index);
    fusion_destroy(ps->map);
    particles_binner_destroy(ps->binner);
    memset(ps, 0xff, sizeof *ps); /* poison: a use after destroy fails loudly */
    free(ps);
}

const render_particles_stats *render_particles_get_stats(const render_particles *ps) { return &ps->stats; }

double render_particles_last_ms(const render_particles *ps) { return ps->last_ms; }

bf_status render_particles_last_resumed(render_particles *ps, uint64_t *rays)
{
    if (!ps || !rays) return bf_fail(BF_INVALID_ARG, "render_particles_last_resumed: NULL argument");
    uint32_t *a = bf_malloc((size_t)ps->n_passes * RENDER_PARTICLES_ARGS_WORDS * 4);
    if (!a) return bf_fail(BF_NO_MEMORY, "render: particle pass counts");
    bf_status s = gpu_buffer_download(ps->args, 0, a, (uint64_t)ps->n_passes * RENDER_PARTICLES_ARGS_WORDS * 4);
    *rays = 0;
    for (uint32_t p = 0; s == BF_OK && p < ps->n_passes; p++) *rays += a[p * RENDER_PARTICLES_ARGS_WORDS + 3];
    free(a);
    return s;
}

/* ------------------------------------------------------------ the pass */

bf_status render_cmd_particles(render_caster *rc, render_particles *ps, const bf_intrinsics *K, const bf_se3 *T_wc,
                               const render_options *opt, bool keep_nearer)
{
    if (!rc || !ps || !K || !T_wc || !opt) return bf_fail(BF_INVALID_ARG, "render: NULL argument");
    const render_targets *tg = render_get_targets(rc);
    if (K->width != tg->width || K->height != tg->height)
        return bf_fail(BF_INVALID_ARG, "render: intrinsics are %ux%u, the caster's images %ux%u", K->width,
                       K->height, tg->width, tg->height);
    if (!(K->fx_px > 0) || !(fabs(K->fy_px) > 0) || !isfinite(K->fy_px) || !isfinite(K->cx_px) || !isfinite(K->cy_px))
        return bf_fail(BF_INVALID_ARG, "render: intrinsics fx %g fy %g cx %g cy %g", K->fx_px, K->fy_px, K->cx_px,
                       K->cy_px);
    if (!bf_se3_is_finite(T_wc)) return bf_fail(BF_INVALID_ARG, "render: camera pose is not finite");
    if (!(opt->near_m > 0) || !(opt->far_m > opt->near_m) || !isfinite(opt->far_m))
        return bf_fail(BF_INVALID_ARG, "render: depth range [%g, %g] m", opt->near_m, opt->far_m);
    if (opt->depth_out) return bf_fail(BF_INVALID_ARG, "render: particles write the caster's own depth image");
    if (ps->unbound) return bf_fail(BF_INVALID_ARG, "render: the particle set lost its pools in a failed update");
    gpu_buffer *imgs[4] = {tg->depth, tg->level, tg->normal, tg->colour};
    for (uint32_t i = 0; i < 4; i++) {
        if (ps->bound[i] == imgs[i]) continue;
        bf_status s = gpu_bindings_set(ps->bind, 3 + i, imgs[i], 0, GPU_WHOLE_SIZE);
        if (s != BF_OK) return s;
        ps->bound[i] = imgs[i];
    }
    uint64_t n_px = (uint64_t)K->width * K->height;
    if (gpu_buffer_size(ps->resume) < n_px * 4) {
        /* A new image size: the old buffers' last reader was waited for
         * (render_scene waits; a caller recording its own waits too). */
        gpu_buffer *nb = NULL, *nl = NULL;
        gpu_buffer_desc rd = {.name = "render.particles.resume", .size_bytes = n_px * 4, .memory = GPU_MEMORY_DEVICE,
                              .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER};
        gpu_buffer_desc ld = rd;
        ld.name = "render.particles.lists";
        ld.size_bytes = 2 * n_px * 4;
        bf_status s = gpu_buffer_create(ps->ctx, &rd, &nb);
        if (s == BF_OK) s = gpu_buffer_create(ps->ctx, &ld, &nl);
        if (s == BF_OK) s = gpu_bindings_set(ps->bind, 8, nb, 0, GPU_WHOLE_SIZE);
        if (s == BF_OK) s = gpu_bindings_set(ps->bind, 9, nl, 0, GPU_WHOLE_SIZE);
        if (s != BF_OK) {
            /* The old buffers stay bound where the new ones were not. */
            gpu_bindings_set(ps->bind, 8, ps->resume, 0, GPU_WHOLE_SIZE);
            gpu_bindings_set(ps->bind, 9, ps->lists, 0, GPU_WHOLE_SIZE);
            gpu_buffer_destroy(nb);
            gpu_buffer_destroy(nl);
            return s;
        }
        gpu_buffer_destroy(ps->resume);
        gpu_buffer_destroy(ps->lists);
        ps->resume = nb, ps->lists = nl;
    }
    fusion_gpu_view v = fusion_gpu_view_get(ps->map);
    render_particles_push pc = {
        .radius_m = ps->cfg.radius_m,
        .flags = (keep_nearer ? RENDER_PARTICLES_FLAG_KEEP_NEARER : 0u) | (ps->cfg.lod ? RENDER_PARTICLES_FLAG_LOD : 0u),
        .rgb = ps->cfg.rgb,
        .limits = ps->cells_per_pass | ps->work_budget << RENDER_PARTICLES_LIMIT_CELL_BITS,
    };
    /* The walk's deepest level is the coarse one. */
    render__view_push(&pc.view, ps->map, &v, K, T_wc, opt->near_m, opt->far_m,
                      ps->stats.level - PARTICLES_COARSE_LEVELS);
    /* The box in the map frame grown by the radius and a cell (rounding):
     * every sphere lies in it. Empty set: a box no ray enters. */
    const render_particles_stats *st = &ps->stats;
    double grow = ps->cfg.radius_m + ps->cfg.cell_m, o[3] = {st->origin_w.x, st->origin_w.y, st->origin_w.z};
    pc.box_lo = st->n_particles ? INFINITY : -1.0f;
    for (int a = 0; a < 3 && st->n_particles; a++) {
        float l = (float)(ps->box_w[0][a] - o[a] - grow);
        if (l < pc.box_lo) pc.box_lo = l;
    }
    for (int a = 0; a < 3; a++) pc.box_hi[a] = st->n_particles ? (float)(ps->box_w[1][a] - o[a] + grow) : -2.0f;
    /* The images' earlier writes (the map's ray-cast and shading) -> this
     * pass's reads and writes of them. */
    gpu_cmd_barrier(ps->ctx, GPU_BARRIER_COMPUTE);
    gpu_cmd_stage_begin(ps->ctx, "render.particles");
    /* The arguments of every dispatch zeroed (the last cast's reads were
     * waited for) -> the dispatches' appends. */
    gpu_cmd_fill(ps->ctx, ps->args, 0, GPU_WHOLE_SIZE, 0);
    gpu_cmd_barrier(ps->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    uint32_t flags = pc.flags;
    for (uint32_t p = 0; p < ps->n_passes; p++) {
        pc.flags = flags | (p == 0 ? RENDER_PARTICLES_FLAG_FIRST : RENDER_PARTICLES_FLAG_LIST) |
                   (p + 1 == ps->n_passes ? RENDER_PARTICLES_FLAG_LAST : 0u) | p << RENDER_PARTICLES_PASS_SHIFT;
        if (p == 0) {
            gpu_cmd_dispatch(ps->ctx, ps->pipe, ps->bind, &pc, gpu_groups(K->width, RENDER_LOCAL_X),
                             gpu_groups(K->height, RENDER_LOCAL_Y), 1);
            continue;
        }
        /* The last dispatch's list, its group counts, resume depths and
         * images -> this one's indirect arguments and reads. */
        gpu_cmd_barrier(ps->ctx, GPU_BARRIER_INDIRECT);
        gpu_cmd_dispatch_indirect(ps->ctx, ps->pipe, ps->bind, &pc, ps->args,
                                  (uint64_t)(p - 1) * RENDER_PARTICLES_ARGS_WORDS * 4);
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
