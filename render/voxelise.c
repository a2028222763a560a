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
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "render.h"
#include "shaders/render.glsl.h"

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

/* Brick range of triangle t's bounding box. */
static uint64_t tri_bricks(const float *v, const mesh_data *mesh, uint32_t t, double brick_m, int64_t b0[3],
                           int64_t b1[3])
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++) {
            double c = v[3 * (size_t)mesh->tri[3 * (size_t)t + k] + a];
            lo[a] = fmin(lo[a], c), hi[a] = fmax(hi[a], c);
        }
    for (int a = 0; a < 3; a++) b0[a] = (int64_t)floor(lo[a] / brick_m), b1[a] = (int64_t)floor(hi[a] / brick_m);
    return (uint64_t)(b1[0] - b0[0] + 1) * (uint64_t)(b1[1] - b0[1] + 1) * (uint64_t)(b1[2] - b0[2] + 1);
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

static bf_status bin_triangles(const float *v, const mesh_data *mesh, double brick_m, uint64_t max_pairs, bins *out)
{
    memset(out, 0, sizeof *out);
    brick_hash h = {0};
    uint32_t *count = NULL, count_cap = 0;
    bf_status s = hash_grow(&h);
    uint64_t n_pairs = 0;
    /* Pass 1: the bricks and how many triangles each gets. */
    for (uint32_t t = 0; s == BF_OK && t < mesh->n_tris; t++) {
        int64_t b0[3], b1[3];
        uint64_t n = tri_bricks(v, mesh, t, brick_m, b0, b1);
        if (n_pairs + n > max_pairs) {
            s = bf_fail(BF_INVALID_ARG, "render: the mesh needs more than %llu (brick, triangle) pairs at this level "
                        "(triangle %u spans %llu bricks): choose a coarser level",
                        (unsigned long long)max_pairs, t, (unsigned long long)n);
            break;
        }
        n_pairs += n;
        for (int64_t z = b0[2]; s == BF_OK && z <= b1[2]; z++)
            for (int64_t y = b0[1]; s == BF_OK && y <= b1[1]; y++)
                for (int64_t x = b0[0]; s == BF_OK && x <= b1[0]; x++) {
                    uint32_t i = hash_get(&h, brick_key(x, y, z), true, &s);
                    if (s != BF_OK) break;
                    if (i >= count_cap) {
                        uint32_t cap = count_cap ? 2 * count_cap : 4096;
                        uint32_t *c = bf_realloc(count, (size_t)cap * 4);
                        if (!c) {
                            s = bf_fail(BF_NO_MEMORY, "render: counting %u bricks", cap);
                            break;
                        }
                        memset(c + count_cap, 0, (size_t)(cap - count_cap) * 4);
                        count = c, count_cap = cap;
                    }
                    count[i]++;
                }
    }
    uint32_t nb = h.n;
    uint32_t *rank = NULL, *fill = NULL;
    if (s == BF_OK) {
        out->keys = bf_malloc((size_t)(nb ? nb : 1) * 8);
        out->first = bf_malloc((size_t)(nb + 1) * 4);
        out->tri_ids = bf_malloc((size_t)(n_pairs ? n_pairs : 1) * 4);
        rank = bf_malloc((size_t)(nb ? nb : 1) * 4);
        fill = bf_malloc((size_t)(nb ? nb : 1) * 4);
        if (!out->keys || !out->first || !out->tri_ids || !rank || !fill)
            s = bf_fail(BF_NO_MEMORY, "render: bins of %u bricks", nb);
    }
    if (s == BF_OK) {
        /* Bricks in (x, y, z) order: the host's parity sweep walks the stacks. */
        uint32_t k = 0;
        for (uint32_t i = 0; i < h.cap; i++)
            if (h.keys[i]) out->keys[k++] = h.keys[i];
        qsort(out->keys, nb, 8, key_cmp);
        for (uint32_t r = 0; r < nb; r++) rank[hash_get(&h, out->keys[r], false, &s)] = r;
        out->first[0] = 0;
        for (uint32_t r = 0; r < nb; r++) {
            uint32_t i = hash_get(&h, out->keys[r], false, &s);
            out->first[r + 1] = out->first[r] + count[i];
            fill[r] = out->first[r];
        }
    }
    /* Pass 2: the triangles into their bins, in mesh order. */
    for (uint32_t t = 0; s == BF_OK && t < mesh->n_tris; t++) {
        int64_t b0[3], b1[3];
        (void)tri_bricks(v, mesh, t, brick_m, b0, b1);
        for (int64_t z = b0[2]; z <= b1[2]; z++)
            for (int64_t y = b0[1]; y <= b1[1]; y++)
                for (int64_t x = b0[0]; x <= b1[0]; x++)
                    out->tri_ids[fill[rank[hash_get(&h, brick_key(x, y, z), false, &s)]]++] = t;
    }
    out->n_bricks = nb;
    out->n_pairs = n_pairs;
    free(h.keys);
    free(h.idx);
    free(count);
    free(rank);
    free(fill);
    if (s != BF_OK) bins_free(out);
    return s;
}

render_voxelise_config render_voxelise_config_default(void)
{
    return (render_voxelise_config){.chunk_m = 2.0f, .level = 7, .max_pairs = 1ull << 28};
}

/* The GPU pass over the bricks: out gets RENDER_VOX_OUT_WORDS per brick. */
static bf_status run_pass(gpu_context *ctx, const float *v, const mesh_data *mesh, const uint32_t *brick_words,
                          uint32_t n_bricks, const uint32_t *tri_ids, uint64_t n_pairs, float voxel_m, uint32_t *out)
{
    gpu_buffer *buf[5] = {0};
    uint64_t bytes[5] = {(uint64_t)mesh->n_verts * 12, (uint64_t)mesh->n_tris * 12,
                         (uint64_t)n_bricks * RENDER_VOX_BRICK_WORDS * 4, n_pairs * 4,
                         (uint64_t)n_bricks * RENDER_VOX_OUT_WORDS * 4};
    const char *names[5] = {"render.vox_verts", "render.vox_tris", "render.vox_bricks", "render.vox_tri_ids",
                            "render.vox_out"};
    const void *src[4] = {v, mesh->tri, brick_words, tri_ids};
    gpu_pipeline *pipe = NULL;
    gpu_bindings *binds = NULL;
    bf_status s = BF_OK;
    for (int i = 0; i < 5 && s == BF_OK; i++) {
        gpu_buffer_desc d = {.name = names[i], .size_bytes = bytes[i] ? bytes[i] : 4, .memory = GPU_MEMORY_DEVICE};
        s = gpu_buffer_create(ctx, &d, &buf[i]);
        if (s == BF_OK && i < 4 && bytes[i]) s = gpu_buffer_upload(buf[i], 0, src[i], bytes[i]);
    }
    gpu_pipeline_desc pd = {
        .name = "render.voxelise",
        .spirv = bf_spv_render_voxelise,
        .spirv_bytes = bf_spv_render_voxelise_size,
        .n_buffers = 5,
        .push_bytes = sizeof(render_vox_push),
        .local_size = {64, 1, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &pipe);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 5, "render.voxelise", &binds);
    for (uint32_t i = 0; i < 5 && s == BF_OK; i++) s = gpu_bindings_set(binds, i, buf[i], 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = gpu_begin(ctx);
    if (s == BF_OK) {
        render_vox_push pc = {.n_bricks = n_bricks, .voxel_m = voxel_m};
        uint32_t max_x = gpu_device_limits(ctx)->max_compute_workgroup_count[0];
        if (max_x > 65535u) max_x = 65535u;
        uint32_t gx = n_bricks < max_x ? n_bricks : max_x, gy = gpu_groups(n_bricks, gx ? gx : 1);
        if (n_bricks) gpu_cmd_dispatch(ctx, pipe, binds, &pc, gx, gy, 1);
        gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
        s = gpu_submit_wait(ctx);
    }
    if (s == BF_OK && bytes[4]) s = gpu_buffer_download(buf[4], 0, out, bytes[4]);
    gpu_bindings_destroy(binds);
    gpu_pipeline_destroy(pipe);
    for (int i = 4; i >= 0; i--) gpu_buffer_destroy(buf[i]);
    return s;
}

/* Sign and confidence of each brick from its flips and the parity its
 * columns carry in: bricks are in (x, y, z) key order, so a stack of
 * bricks in one column is consecutive, lowest first. */
static void finish_bricks(const uint64_t *keys, const uint32_t *gpu_out, uint32_t n_bricks, uint32_t level,
                          hostmap *out)
{
    uint64_t carry = 0;
    for (uint32_t i = 0; i < n_bricks; i++) {
        if (i == 0 || key_x(keys[i]) != key_x(keys[i - 1]) || key_y(keys[i]) != key_y(keys[i - 1])) carry = 0;
        const uint32_t *g = gpu_out + (size_t)i * RENDER_VOX_OUT_WORDS;
        hostmap_brick *b = &out->bricks[i];
        int32_t B[3] = {key_x(keys[i]), key_y(keys[i]), key_z(keys[i])};
        for (int a = 0; a < 3; a++) {
            /* Chunk key and cell: floor division by the bricks per chunk edge. */
            int32_t per = (int32_t)1 << level;
            b->key[a] = B[a] >= 0 ? B[a] / per : -((-B[a] + per - 1) / per);
            b->cell[a] = (uint32_t)(B[a] - b->key[a] * per);
        }
        b->level = level;
        b->error = 0;
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            uint32_t inside = g[w];
            /* Columns that enter inside: every voxel of them flips. */
            for (uint32_t bit = 0; bit < 32; bit++) {
                uint32_t x = (w & 1) * 4 + (bit & 3), y = ((w >> 1) & 1) * 4 + ((bit >> 2) & 3);
                if ((carry >> (x + 8 * y)) & 1) inside ^= 1u << bit;
            }
            b->sign[w] = ~inside; /* 1: in front of the surface (outside) */
            b->conf[w] = 0xFFFFFFFFu;
        }
        carry ^= (uint64_t)g[BRICK_WORDS] | ((uint64_t)g[BRICK_WORDS + 1] << 32);
    }
}

bf_status render_voxelise_mesh(gpu_context *ctx, const mesh_data *mesh, const bf_se3 *T_world_mesh,
                               const render_voxelise_config *cfg, hostmap *out, render_voxelise_stats *st)
{
    if (!ctx || !mesh || !out || (mesh->n_tris && (!mesh->tri || !mesh->xyz)))
        return bf_fail(BF_INVALID_ARG, "render_voxelise_mesh: NULL argument");
    render_voxelise_config c = cfg ? *cfg : render_voxelise_config_default();
    if (!(c.chunk_m > 0) || c.level > 12)
        return bf_fail(BF_INVALID_ARG, "render: voxelising at level %u of %g m chunks (level at most 12)", c.level,
                       (double)c.chunk_m);
    memset(out, 0, sizeof *out);
    if (st) memset(st, 0, sizeof *st);
    double t0 = bf_time_s();
    bf_se3 T = T_world_mesh ? *T_world_mesh : bf_se3_identity();
    /* World points; the map's origin is their bounding box's low corner
     * (whole voxels), so brick coordinates start near zero. */
    float *v = bf_malloc((size_t)(mesh->n_verts ? mesh->n_verts : 1) * 12);
    if (!v) return bf_fail(BF_NO_MEMORY, "render: %u mesh vertices", mesh->n_verts);
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY);
    double voxel_m = hostmap_level_voxel_m(c.chunk_m, c.level), brick_m = 8 * voxel_m;
    for (uint32_t i = 0; i < mesh->n_verts; i++) {
        bf_vec3 p = bf_se3_apply(&T, bf_v3(mesh->origin.x + mesh->xyz[3 * i], mesh->origin.y + mesh->xyz[3 * i + 1],
                                           mesh->origin.z + mesh->xyz[3 * i + 2]));
        if (!isfinite(p.x) || !isfinite(p.y) || !isfinite(p.z)) {
            free(v);
            return bf_fail(BF_INVALID_ARG, "render: mesh vertex %u is not finite", i);
        }
        lo = bf_v3(fmin(lo.x, p.x), fmin(lo.y, p.y), fmin(lo.z, p.z));
    }
    if (!mesh->n_verts) lo = bf_v3(0, 0, 0);
    out->chunk_m = c.chunk_m;
    out->origin_w = c.has_origin ? c.origin_w
                                 : bf_v3(floor(lo.x / voxel_m) * voxel_m - brick_m, floor(lo.y / voxel_m) * voxel_m - brick_m,
                                         floor(lo.z / voxel_m) * voxel_m - brick_m);
    for (uint32_t i = 0; i < mesh->n_verts; i++) {
        bf_vec3 p = bf_se3_apply(&T, bf_v3(mesh->origin.x + mesh->xyz[3 * i], mesh->origin.y + mesh->xyz[3 * i + 1],
                                           mesh->origin.z + mesh->xyz[3 * i + 2]));
        v[3 * i] = (float)(p.x - out->origin_w.x), v[3 * i + 1] = (float)(p.y - out->origin_w.y);
        v[3 * i + 2] = (float)(p.z - out->origin_w.z);
    }
    for (uint32_t t = 0; t < 3 * (size_t)mesh->n_tris; t++)
        if (mesh->tri[t] >= mesh->n_verts) {
            free(v);
            return bf_fail(BF_INVALID_ARG, "render: triangle %u names vertex %u of %u", t / 3, mesh->tri[t],
                           mesh->n_verts);
        }
    bins bn;
    bf_status s = bin_triangles(v, mesh, brick_m, c.max_pairs, &bn);
    uint32_t n_bricks = s == BF_OK ? bn.n_bricks : 0;
    uint32_t *brick_words = NULL, *gpu_out = NULL;
    if (s == BF_OK) {
        brick_words = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_BRICK_WORDS * 4);
        gpu_out = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_OUT_WORDS * 4);
        out->bricks = bf_calloc(n_bricks ? n_bricks : 1, sizeof *out->bricks);
        if (!brick_words || !gpu_out || !out->bricks) s = bf_fail(BF_NO_MEMORY, "render: voxelising into %u bricks", n_bricks);
    }
    for (uint32_t i = 0; s == BF_OK && i < n_bricks; i++) {
        uint32_t *w = brick_words + (size_t)i * RENDER_VOX_BRICK_WORDS;
        w[0] = (uint32_t)key_x(bn.keys[i]), w[1] = (uint32_t)key_y(bn.keys[i]), w[2] = (uint32_t)key_z(bn.keys[i]);
        w[3] = bn.first[i], w[4] = bn.first[i + 1], w[5] = 0;
    }
    double t1 = bf_time_s();
    if (s == BF_OK) s = run_pass(ctx, v, mesh, brick_words, n_bricks, bn.tri_ids, bn.n_pairs, (float)voxel_m, gpu_out);
    double t2 = bf_time_s();
    if (s == BF_OK) {
        finish_bricks(bn.keys, gpu_out, n_bricks, c.level, out);
        out->n_bricks = n_bricks;
    }
    if (s == BF_OK && st) {
        st->n_bricks = n_bricks;
        st->n_pairs = bn.n_pairs;
        st->voxel_m = voxel_m;
        st->seconds_bin = t1 - t0;
        st->seconds_gpu = t2 - t1;
        st->seconds = bf_time_s() - t0;
    }
    free(v);
    bins_free(&bn);
    free(brick_words);
    free(gpu_out);
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
