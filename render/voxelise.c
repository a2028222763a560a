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

/* One (brick, triangle) pair of the bins. */
typedef struct bin_pair {
    uint64_t key;
    uint32_t tri;
} bin_pair;

static int pair_cmp(const void *a, const void *b)
{
    const bin_pair *p = a, *q = b;
    if (p->key != q->key) return p->key < q->key ? -1 : 1;
    return p->tri < q->tri ? -1 : p->tri > q->tri;
}

render_voxelise_config render_voxelise_config_default(void)
{
    return (render_voxelise_config){.chunk_m = 2.0f, .level = 7, .max_pairs = 1ull << 28};
}

/* The (brick, triangle) pairs of every triangle's bounding box, sorted. */
static bf_status bin_triangles(const float *v, const mesh_data *mesh, double brick_m, uint64_t max_pairs,
                               bin_pair **out, uint64_t *n_out)
{
    uint64_t n = 0, cap = (uint64_t)mesh->n_tris * 2 + 16;
    bin_pair *p = bf_malloc(cap * sizeof *p);
    if (!p) return bf_fail(BF_NO_MEMORY, "render: binning %u triangles", mesh->n_tris);
    for (uint32_t t = 0; t < mesh->n_tris; t++) {
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++) {
                double c = v[3 * (size_t)mesh->tri[3 * (size_t)t + k] + a];
                lo[a] = fmin(lo[a], c), hi[a] = fmax(hi[a], c);
            }
        int64_t b0[3], b1[3];
        for (int a = 0; a < 3; a++) b0[a] = (int64_t)floor(lo[a] / brick_m), b1[a] = (int64_t)floor(hi[a] / brick_m);
        uint64_t count = (uint64_t)(b1[0] - b0[0] + 1) * (uint64_t)(b1[1] - b0[1] + 1) * (uint64_t)(b1[2] - b0[2] + 1);
        if (n + count > max_pairs) {
            free(p);
            return bf_fail(BF_INVALID_ARG, "render: the mesh needs more than %llu (brick, triangle) pairs at this level "
                           "(triangle %u spans %llu bricks): choose a coarser level",
                           (unsigned long long)max_pairs, t, (unsigned long long)count);
        }
        if (n + count > cap) {
            while (n + count > cap) cap *= 2;
            bin_pair *q = bf_realloc(p, cap * sizeof *p);
            if (!q) {
                free(p);
                return bf_fail(BF_NO_MEMORY, "render: binning %u triangles", mesh->n_tris);
            }
            p = q;
        }
        for (int64_t z = b0[2]; z <= b1[2]; z++)
            for (int64_t y = b0[1]; y <= b1[1]; y++)
                for (int64_t x = b0[0]; x <= b1[0]; x++) p[n++] = (bin_pair){brick_key(x, y, z), t};
    }
    qsort(p, n, sizeof *p, pair_cmp);
    *out = p;
    *n_out = n;
    return BF_OK;
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
    out->origin_w = bf_v3(floor(lo.x / voxel_m) * voxel_m - brick_m, floor(lo.y / voxel_m) * voxel_m - brick_m,
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
    bin_pair *pairs = NULL;
    uint64_t n_pairs = 0;
    bf_status s = bin_triangles(v, mesh, brick_m, c.max_pairs, &pairs, &n_pairs);
    uint32_t n_bricks = 0;
    for (uint64_t i = 0; s == BF_OK && i < n_pairs; i++) n_bricks += i == 0 || pairs[i].key != pairs[i - 1].key;
    uint64_t *keys = NULL;
    uint32_t *brick_words = NULL, *tri_ids = NULL, *gpu_out = NULL;
    if (s == BF_OK) {
        keys = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * 8);
        brick_words = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_BRICK_WORDS * 4);
        tri_ids = bf_malloc((size_t)(n_pairs ? n_pairs : 1) * 4);
        gpu_out = bf_malloc((size_t)(n_bricks ? n_bricks : 1) * RENDER_VOX_OUT_WORDS * 4);
        out->bricks = bf_calloc(n_bricks ? n_bricks : 1, sizeof *out->bricks);
        if (!keys || !brick_words || !tri_ids || !gpu_out || !out->bricks)
            s = bf_fail(BF_NO_MEMORY, "render: voxelising into %u bricks", n_bricks);
    }
    for (uint64_t i = 0, b = 0; s == BF_OK && i < n_pairs; i++) {
        tri_ids[i] = pairs[i].tri;
        if (i == 0 || pairs[i].key != pairs[i - 1].key) {
            if (i) brick_words[(b - 1) * RENDER_VOX_BRICK_WORDS + 4] = (uint32_t)i;
            keys[b] = pairs[i].key;
            uint32_t *w = brick_words + b * RENDER_VOX_BRICK_WORDS;
            w[0] = (uint32_t)key_x(pairs[i].key), w[1] = (uint32_t)key_y(pairs[i].key);
            w[2] = (uint32_t)key_z(pairs[i].key), w[3] = (uint32_t)i, w[5] = 0;
            b++;
        }
        if (i + 1 == n_pairs) brick_words[(b - 1) * RENDER_VOX_BRICK_WORDS + 4] = (uint32_t)n_pairs;
    }
    free(pairs);
    double t1 = bf_time_s();
    if (s == BF_OK) s = run_pass(ctx, v, mesh, brick_words, n_bricks, tri_ids, n_pairs, (float)voxel_m, gpu_out);
    double t2 = bf_time_s();
    if (s == BF_OK) {
        finish_bricks(keys, gpu_out, n_bricks, c.level, out);
        out->n_bricks = n_bricks;
    }
    if (s == BF_OK && st) {
        st->n_bricks = n_bricks;
        st->n_pairs = n_pairs;
        st->voxel_m = voxel_m;
        st->seconds_bin = t1 - t0;
        st->seconds_gpu = t2 - t1;
        st->seconds = bf_time_s() - t0;
    }
    free(v);
    free(keys);
    free(brick_words);
    free(tri_ids);
    free(gpu_out);
    if (s != BF_OK) hostmap_free(out);
    return s;
}
