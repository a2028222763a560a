/* fusion: the map on the GPU, brick allocation, the window schedule, pool
 * exhaustion. Validation is on; any message fails a test. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fusion/fusion.h"
#include "fusion/fusion_int.h"
#include "gpu_fixture.h"
#include "shaders/fusion.glsl.h"
#include "store/store.h"

static const bf_intrinsics K_TEST = {160, 120, 130.0, 130.0, 79.5, 59.5, 5000};

/* A fronto-parallel plane at depth z_m (camera looking along +z). */
static uint16_t *plane_depth(const bf_intrinsics *K, double z_m)
{
    uint16_t *d = malloc((size_t)K->width * K->height * 2);
    for (uint32_t i = 0; i < K->width * K->height; i++) d[i] = (uint16_t)lround(z_m * K->depth_scale);
    return d;
}

static bf_frame make_frame(const bf_intrinsics *K, const uint16_t *depth, uint32_t index)
{
    bf_frame f = {.index = index, .width = K->width, .height = K->height, .depth = depth};
    return f;
}

/* fusion_config.max_groups_x of the maps made next (0: the device's). */
static uint32_t s_max_groups_x;

static fusion_config small_config(void)
{
    fusion_config c = fusion_config_default();
    c.max_groups_x = s_max_groups_x;
    c.brick_cap = 1u << 15;
    c.hash_buckets = 64;
    c.hash_overflow = 64;
    c.window = 4;
    c.subcache = 2;
    /* The planes here are confident on one side only, so the colour trim
     * would take every colour off (no mesh passes there either): these
     * tests follow colours through loads and evictions. The trim's own test
     * is in test_fusion_room. */
    c.colour_reach = 0;
    return c;
}

BF_TEST(far_sample_lands_on_coarse_level)
{
    /* f = 525, 2 m chunks: footprints 1.9, 3.8, 7.6 mm pick voxels of
     * 1.95 mm (level 7), 3.9 mm (6), 7.8 mm (5): the closest in ratio. */
    CHECK_EQ_INT(fusion_level_for_footprint(1.0f / 525, 2.0f, 8), 7);
    CHECK_EQ_INT(fusion_level_for_footprint(2.0f / 525, 2.0f, 8), 6);
    CHECK_EQ_INT(fusion_level_for_footprint(4.0f / 525, 2.0f, 8), 5);
    CHECK_EQ_INT(fusion_level_for_footprint(0.1f / 525, 2.0f, 8), 8); /* clamped to the finest */
    CHECK_EQ_INT(fusion_level_for_footprint(0.5f, 2.0f, 8), 0);       /* and to the coarsest */
    /* The boundary between two levels is the geometric mean of their voxels. */
    float v6 = 2.0f / 8 / 64;
    CHECK_EQ_INT(fusion_level_for_footprint(v6 * 0.7f, 2.0f, 8), 7);
    CHECK_EQ_INT(fusion_level_for_footprint(v6 * 0.72f, 2.0f, 8), 6);
    CHECK_NEAR(fusion_voxel_m(2.0f, 6), 2.0 / 512, 0);
}

BF_TEST(level_size_follows_the_noise_where_it_exceeds_the_footprint)
{
    /* Kinect v1: sigma(1 m) = 1.88 mm, sigma(4 m) = 25.8 mm; ratio 2 at f = 585:
     * footprints 3.42 and 13.7 mm. With one sigma the far sample's voxel is its
     * noise (level 3: 31 mm voxels, nearest to 25.8; level 4 without: 15.6 mm),
     * the near one keeps the footprint. */
    bf_sensor k = {.sigma_a = 0.0012f, .sigma_b = 0.0019f, .sigma_c = 0.4f};
    float s1 = bf_sensor_sigma(1.0f, k.sigma_a, k.sigma_b, k.sigma_c), s4 = bf_sensor_sigma(4.0f, k.sigma_a, k.sigma_b, k.sigma_c);
    CHECK_NEAR(fusion_level_size(1.0f, 1.0f / 585, 2.0f, 0.0f, s1), 2.0 / 585, 1e-6);
    CHECK_NEAR(fusion_level_size(4.0f, 1.0f / 585, 2.0f, 0.0f, s4), 8.0 / 585, 1e-6);
    CHECK_NEAR(fusion_level_size(1.0f, 1.0f / 585, 2.0f, 1.0f, s1), 2.0 / 585, 1e-6);
    CHECK_NEAR(fusion_level_size(4.0f, 1.0f / 585, 2.0f, 1.0f, s4), 0.0012 + 0.0019 * 3.6 * 3.6, 1e-6);
    CHECK_EQ_INT(fusion_level_for_footprint(fusion_level_size(4.0f, 1.0f / 585, 2.0f, 1.0f, s4), 2.0f, 8), 3);
    CHECK_EQ_INT(fusion_level_for_footprint(fusion_level_size(4.0f, 1.0f / 585, 2.0f, 0.0f, s4), 2.0f, 8), 4);
}

BF_TEST(create_rejects_bad_config_with_a_message)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_map *map = NULL;
    fusion_config c = small_config();
    c.window = 5;
    CHECK_STATUS(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("window");
    CHECK(map == NULL);
    c = small_config();
    c.brick_cap = 1u << 24; /* 256 MiB of brick records: above lavapipe's 128 MiB binding */
    c.node_cap = 1u << 16;
    CHECK_STATUS(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("brick_info");
    CHECK_ERROR_MENTIONS("storage binding");
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The bricks a frame of plane depth must allocate, computed on the CPU in
 * double: for every pixel the three band points z + k band, k = -1, 0, 1,
 * at the level of the sample. Cells whose point lies within 1e-4 m of a
 * cell face are marked ambiguous (float on the GPU may round either way). */
typedef struct expect_cell {
    int32_t key[3];
    uint32_t level, cell[3];
    bool ambiguous;
} expect_cell;

static bool same_cell(const expect_cell *a, const hostmap_brick *b)
{
    return a->key[0] == b->key[0] && a->key[1] == b->key[1] && a->key[2] == b->key[2] && a->level == b->level &&
           a->cell[0] == b->cell[0] && a->cell[1] == b->cell[1] && a->cell[2] == b->cell[2];
}

static size_t expected_cells(const bf_intrinsics *K, const fusion_config *c, const bf_se3 *T_mc, double z,
                             expect_cell *out, size_t cap)
{
    size_t n = 0;
    double sigma = c->sensor.sigma_a + c->sensor.sigma_b * (z - c->sensor.sigma_c) * (z - c->sensor.sigma_c);
    uint32_t level = fusion_level_for_footprint(
        fusion_level_size((float)z, (float)(1.0 / K->fx_px), c->voxel_ratio, c->voxel_sigmas, (float)sigma), c->chunk_m,
        c->max_level);
    double cell_m = c->chunk_m / (double)(1u << level);
    for (uint32_t v = 0; v < K->height; v++)
        for (uint32_t u = 0; u < K->width; u++)
            for (int k = -1; k <= 1; k++) {
                double zk = z + k * c->band_sigmas * sigma;
                bf_vec3 p = bf_se3_apply(T_mc, bf_intrinsics_unproject(K, u, v, zk));
                double pc[3] = {p.x, p.y, p.z};
                expect_cell e = {.level = level};
                for (int i = 0; i < 3; i++) {
                    double kf = floor(pc[i] / c->chunk_m);
                    e.key[i] = (int32_t)kf;
                    double q = pc[i] - kf * c->chunk_m;
                    double cf = floor(q / cell_m);
                    e.cell[i] = (uint32_t)cf;
                    double r = q - cf * cell_m;
                    if (r < 1e-4 || cell_m - r < 1e-4) e.ambiguous = true;
                }
                size_t j = 0;
                for (; j < n; j++)
                    if (!memcmp(out[j].key, e.key, sizeof e.key) && out[j].level == e.level &&
                        !memcmp(out[j].cell, e.cell, sizeof e.cell))
                        break;
                if (j == n && n < cap) out[n++] = e;
                else if (j < n && !e.ambiguous) out[j].ambiguous = false;
            }
    return n;
}

/* Runs one plane frame through a fresh map and compares the allocated
 * bricks with the CPU's expectation. */
static void check_plane_allocation_k(const bf_intrinsics *K, bf_vec3 origin_w, bf_se3 T_wc, double z,
                                     float voxel_sigmas, uint32_t want_level)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    c.voxel_sigmas = voxel_sigmas;
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, K, origin_w, &map));
    uint16_t *depth = plane_depth(K, z);
    bf_frame f = make_frame(K, depth, 0);
    CHECK_OK(fusion_add_frame(map, &f, &T_wc));
    CHECK_OK(fusion_check(map));
    hostmap snap;
    CHECK_OK(fusion_snapshot_take(map, &snap));
    bf_se3 T_mc = T_wc;
    T_mc.t = bf_v3_sub(T_wc.t, origin_w);
    size_t cap = 4096;
    expect_cell *exp = malloc(cap * sizeof *exp);
    size_t n = expected_cells(K, &c, &T_mc, z, exp, cap);
    CHECK(n < cap);
    size_t n_sure = 0;
    for (size_t i = 0; i < n; i++) {
        if (exp[i].ambiguous) continue;
        n_sure++;
        bool found = false;
        for (uint32_t b = 0; b < snap.n_bricks && !found; b++) found = same_cell(&exp[i], &snap.bricks[b]);
        if (!found)
            fprintf(stderr, "  missing brick: chunk (%d,%d,%d) level %u cell (%u,%u,%u)\n", exp[i].key[0], exp[i].key[1],
                    exp[i].key[2], exp[i].level, exp[i].cell[0], exp[i].cell[1], exp[i].cell[2]);
        CHECK(found);
    }
    for (uint32_t b = 0; b < snap.n_bricks; b++) {
        bool found = false;
        for (size_t i = 0; i < n && !found; i++) found = same_cell(&exp[i], &snap.bricks[b]);
        CHECK(found);
    }
    CHECK(n_sure > 10);
    CHECK(snap.n_bricks >= n_sure && snap.n_bricks <= n);
    for (uint32_t b = 0; want_level != UINT32_MAX && b < snap.n_bricks; b++) CHECK_EQ_INT(snap.bricks[b].level, want_level);
    fusion_stats st;
    CHECK_OK(fusion_get_stats(map, &st));
    CHECK_EQ_INT(st.n_bricks, snap.n_bricks);
    CHECK_EQ_INT(st.fail_bricks + st.fail_nodes + st.fail_hash, 0);
    free(exp);
    free(depth);
    hostmap_free(&snap);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

static void check_plane_allocation(const bf_intrinsics *K, bf_vec3 origin_w, bf_se3 T_wc, double z)
{
    check_plane_allocation_k(K, origin_w, T_wc, z, 0.0f, UINT32_MAX);
}

BF_TEST(plane_allocates_exactly_the_band_bricks)
{
    /* Camera at the origin looking along +z at a plane 1.3 m away: the
     * plane spans negative and positive x and y, so chunks -1 and 0. */
    check_plane_allocation(&K_TEST, bf_v3(0, 0, 0), bf_se3_identity(), 1.3);
    /* A width whose tiles do not fill the last workgroup. */
    bf_intrinsics K = {164, 118, 130.0, 130.0, 81.5, 58.5, 5000};
    check_plane_allocation(&K, bf_v3(0, 0, 0), bf_se3_identity(), 0.8);
}

/* The allocation's retry passes size their own grid on the GPU, in rows of
 * at most max_groups_x groups (65535 on Mesa's drivers: a depth image over
 * about 1.4 MP queues more). Rows of one, two and three groups place every
 * queued point once: exactly the oracle's bricks, as in one row. */
BF_TEST(allocation_retries_in_many_rows_give_the_band_bricks)
{
    static const uint32_t rows_of[] = {1, 2, 3};
    for (size_t k = 0; k < sizeof rows_of / sizeof rows_of[0] && !bf__test_failed_now; k++) {
        s_max_groups_x = rows_of[k];
        check_plane_allocation(&K_TEST, bf_v3(0, 0, 0), bf_se3_identity(), 1.3);
    }
    s_max_groups_x = 0;
}

BF_TEST(noise_sized_voxels_put_a_far_plane_on_a_coarser_level)
{
    /* A plane 4 m away, f = 130 px: the pixel footprint, 30.8 mm, asks for
     * level 3 (31.3 mm voxels); two sigma(4 m) of Kinect v1, 51.6 mm, for
     * level 2 (62.5 mm). The bricks are exactly the CPU oracle's either way. */
    check_plane_allocation_k(&K_TEST, bf_v3(0, 0, 0), bf_se3_identity(), 4.0, 0.0f, 3);
    check_plane_allocation_k(&K_TEST, bf_v3(0, 0, 0), bf_se3_identity(), 4.0, 2.0f, 2);
}

BF_TEST(allocation_10_km_from_the_origin_matches_the_origin)
{
    /* The map origin sits at the first camera: GPU coordinates stay small
     * and the same bricks come out as at the origin (DESIGN.md section 10). */
    bf_vec3 far = bf_v3(1e4, -1e4, 5e3);
    bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.2), far);
    check_plane_allocation(&K_TEST, far, T, 1.1);
}

BF_TEST(full_brick_pool_is_reported_and_map_stays_consistent)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    c.brick_cap = 40;
    c.node_cap = 1u << 14; /* only the brick pool runs out */
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    uint16_t *depth = plane_depth(&K_TEST, 0.9);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    bf_se3 T = bf_se3_identity();
    CHECK_STATUS(fusion_add_frame(map, &f, &T), BF_POOL_FULL);
    CHECK_ERROR_MENTIONS("bricks");
    CHECK_OK(fusion_check(map));
    fusion_stats st;
    CHECK_OK(fusion_get_stats(map, &st));
    CHECK_EQ_INT(st.n_bricks, 40);
    CHECK(st.fail_bricks > 0);
    CHECK_EQ_INT(st.fail_nodes, 0);
    /* The same frame again drops again but corrupts nothing. */
    f.index = 1;
    CHECK_STATUS(fusion_add_frame(map, &f, &T), BF_POOL_FULL);
    CHECK_OK(fusion_check(map));
    free(depth);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(chunk_hash_overflow_chains_and_full_overflow_is_counted)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    c.hash_buckets = 1; /* every chunk in one bucket: 4 slots, then the chain */
    c.hash_overflow = 3;
    c.chunk_m = 0.25f;  /* small chunks: the plane spans many */
    c.max_level = 5;
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    uint16_t *depth = plane_depth(&K_TEST, 1.0);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    bf_se3 T = bf_se3_identity();
    CHECK_STATUS(fusion_add_frame(map, &f, &T), BF_POOL_FULL);
    CHECK_ERROR_MENTIONS("chunks");
    CHECK_OK(fusion_check(map));
    fusion_stats st;
    CHECK_OK(fusion_get_stats(map, &st));
    CHECK_EQ_INT(st.n_chunks, 7); /* 4 bucket slots + 3 overflow entries */
    CHECK(st.fail_hash > 0);
    free(depth);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(empty_frame_and_bad_pose_change_nothing)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    uint16_t *depth = calloc((size_t)K_TEST.width * K_TEST.height, 2);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    bf_se3 T = bf_se3_identity();
    for (uint32_t i = 0; i < 6; i++) CHECK_OK(fusion_add_frame(map, &f, &T));
    CHECK_OK(fusion_flush(map));
    fusion_stats st;
    CHECK_OK(fusion_get_stats(map, &st));
    CHECK_EQ_INT(st.n_bricks, 0);
    CHECK_EQ_INT(st.n_chunks, 0);
    bf_se3 bad = T;
    bad.t.x = NAN;
    CHECK_STATUS(fusion_add_frame(map, &f, &bad), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("not finite");
    bf_frame small = f;
    small.width = 80;
    CHECK_STATUS(fusion_add_frame(map, &small, &T), BF_INVALID_ARG);
    CHECK_OK(fusion_check(map));
    free(depth);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(repeated_frames_allocate_nothing_new_and_stay_consistent)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    uint16_t *depth = plane_depth(&K_TEST, 1.2);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    bf_se3 T = bf_se3_identity();
    CHECK_OK(fusion_add_frame(map, &f, &T));
    fusion_stats st1, st2;
    CHECK_OK(fusion_get_stats(map, &st1));
    for (uint32_t i = 1; i < 9; i++) CHECK_OK(fusion_add_frame(map, &f, &T));
    CHECK_OK(fusion_flush(map));
    CHECK_OK(fusion_get_stats(map, &st2));
    CHECK_OK(fusion_check(map));
    CHECK(st2.n_bricks <= st1.n_bricks); /* removal may only shrink it */
    CHECK_EQ_INT(st2.n_nodes, st1.n_nodes);
    CHECK_EQ_INT(st2.n_frames, 9);
    free(depth);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A wall seen in one frame only, then hidden behind a nearer one (a person
 * stepping in front of the camera): no window sees it often enough to make a
 * voxel of it confident, so its bricks go when the window closes. Their chunk
 * keeps its hash entry (its memory is counted); the map's chunks holding
 * bricks, as a store counts them, leave it out. */
BF_TEST(a_chunk_emptied_of_bricks_is_counted_apart)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    /* Chunks are 2 m: the wall at 3 m is in chunk z 1, the one at 1.2 m in chunk z 0. */
    uint16_t *far = plane_depth(&K_TEST, 3.0), *near = plane_depth(&K_TEST, 1.2);
    bf_frame f = make_frame(&K_TEST, far, 0);
    bf_se3 T = bf_se3_identity();
    CHECK_OK(fusion_add_frame(map, &f, &T));
    fusion_stats st0, st1;
    hostmap snap;
    CHECK_OK(fusion_get_stats(map, &st0));
    CHECK(st0.n_bricks > 0);
    CHECK_OK(fusion_snapshot_take(map, &snap));
    CHECK_OK(hostmap_sort(&snap));
    CHECK_EQ_INT(hostmap_count_chunks(&snap), st0.n_chunks);
    hostmap_free(&snap);
    f.depth = near;
    for (uint32_t i = 1; i < 12; i++) {
        f.index = i;
        CHECK_OK(fusion_add_frame(map, &f, &T));
    }
    CHECK_OK(fusion_flush(map));
    CHECK_OK(fusion_check(map));
    CHECK_OK(fusion_get_stats(map, &st1));
    CHECK_OK(fusion_snapshot_take(map, &snap));
    CHECK_OK(hostmap_sort(&snap));
    uint32_t in_chunk_1 = 0;
    for (uint32_t b = 0; b < snap.n_bricks; b++) in_chunk_1 += snap.bricks[b].key[2] == 1;
    CHECK_EQ_INT(in_chunk_1, 0);
    CHECK(st1.n_bricks > 0);
    uint32_t holding = hostmap_count_chunks(&snap);
    CHECK(holding > 0 && holding < st1.n_chunks);
    CHECK_EQ_INT(st1.n_chunks - holding, st0.n_chunks);
    hostmap_free(&snap);
    free(near);
    free(far);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The colour pass's frames over a scan: windows of 40 frames closing every
 * 20, the first one short. Overlapping windows read different frames (the
 * same offset in both read half of them twice), each inside its window,
 * colour_frames of them; a scan's last window, off the schedule, reaches
 * its end. */
BF_TEST(colour_passes_of_overlapping_windows_read_new_frames)
{
    static const uint32_t counts[] = {1, 2, 3, 4, 5, 8};
    const uint32_t window = 40, slide = 20, n_frames = 400;
    for (size_t c = 0; c < sizeof counts / sizeof counts[0]; c++) {
        uint32_t reads[400] = {0}, n_reads = 0;
        for (uint32_t end = slide; end <= n_frames; end += slide) {
            uint32_t first = end >= window ? end - window : 0;
            fusion__colour_plan p = fusion__colour_frames(window, counts[c], first, end);
            CHECK_EQ_INT(p.n, counts[c]);
            for (uint32_t k = 0; k < p.n; k++) {
                uint32_t f = p.first + k * p.stride;
                CHECK(f >= first && f < end);
                if (f < n_frames) reads[f]++, n_reads++;
            }
        }
        /* (The first 20 frames are also read by the short first window,
         * whose stride is half the others': a repeat or two there.) */
        uint32_t twice = 0;
        for (uint32_t f = slide; f < n_frames; f++) twice += reads[f] > 1;
        if (twice) fprintf(stderr, "  colour_frames %u: %u frames read twice\n", counts[c], twice);
        CHECK_EQ_INT(twice, 0);
        CHECK_EQ_INT(n_reads, (n_frames / slide) * counts[c]);
    }
    /* A scan's last window, off the schedule (frames 1-40 of 41), keeps half
     * a stride: its frames reach the scan's end. */
    fusion__colour_plan last = fusion__colour_frames(window, 4, 1, 41);
    CHECK_EQ_INT(last.first, 6);
    CHECK_EQ_INT(last.stride, 10);
    /* A window shorter than its slide (a scan of 7 frames): four of them, one apart. */
    fusion__colour_plan p = fusion__colour_frames(window, 4, 0, 7);
    CHECK_EQ_INT(p.n, 4);
    CHECK_EQ_INT(p.first, 0);
    CHECK_EQ_INT(p.stride, 1);
    CHECK_EQ_INT(fusion__colour_frames(window, 4, 5, 5).n, 0);
}

/* A host copy loaded into a new map (a reopened scene store) is the same
 * map: the same bricks bit for bit at the same world places, reachable by
 * the GPU's lookups (the same frame allocates nothing new there), and a
 * load that does not fit leaves the map empty. */
BF_TEST(map_loaded_from_a_host_copy_is_the_same_map)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    fusion_map *map, *map2, *tiny;
    bf_vec3 origin = bf_v3(10.5, -3.0, 2000.25);
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, origin, &map));
    uint16_t *depth = plane_depth(&K_TEST, 1.2);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    uint8_t *rgb = malloc((size_t)K_TEST.width * K_TEST.height * 3);
    CHECK(rgb != NULL);
    for (uint32_t i = 0; i < K_TEST.width * K_TEST.height; i++)
        rgb[3 * i] = 200, rgb[3 * i + 1] = (uint8_t)(i % 251), rgb[3 * i + 2] = (uint8_t)(i / K_TEST.width);
    f.rgb = rgb; /* colour loads with the map too */
    /* Two poses whose planes cross chunk boundaries (the origin is 0.5 m
     * from one in x). */
    bf_se3 T0 = bf_se3_identity(), T1 = bf_se3_identity();
    T0.t = origin;
    T1.t = bf_v3(origin.x + 0.7, origin.y + 0.2, origin.z - 0.1);
    for (uint32_t i = 0; i < 6; i++) {
        f.index = i;
        CHECK_OK(fusion_add_frame(map, &f, i % 2 ? &T1 : &T0));
    }
    CHECK_OK(fusion_flush(map));
    hostmap a = {0}, b = {0};
    CHECK_OK(fusion_snapshot_take(map, &a));
    fusion_stats sa, sb, sc, sc3;
    CHECK_OK(fusion_get_stats(map, &sa));
    CHECK(sa.n_chunks >= 2 && sa.n_confident_voxels > 0);

    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map2));
    CHECK_OK(fusion_load(map2, &a));
    CHECK_OK(fusion_check(map2));
    CHECK_OK(fusion_snapshot_take(map2, &b));
    CHECK(b.origin_w.x == origin.x && b.origin_w.z == origin.z);
    uint64_t da, db;
    CHECK_OK(store_map_digest(&a, &da));
    CHECK_OK(store_map_digest(&b, &db));
    CHECK(da == db);
    /* The same colours, brick by brick (loaded slots follow a's order). */
    CHECK(a.rgb565 && b.rgb565);
    uint64_t n_col = 0, n_diff = 0;
    for (uint32_t i = 0; i < a.n_bricks && i < b.n_bricks; i++) {
        CHECK(memcmp(a.bricks[i].key, b.bricks[i].key, 12) == 0 && memcmp(a.bricks[i].cell, b.bricks[i].cell, 12) == 0);
        for (uint32_t v = 0; v < 512; v++)
            n_col += a.rgb565[(size_t)i * 512 + v] != 0, n_diff += a.rgb565[(size_t)i * 512 + v] != b.rgb565[(size_t)i * 512 + v];
    }
    CHECK(n_col > 0);
    CHECK_EQ_INT(n_diff, 0);
    CHECK_OK(fusion_get_stats(map2, &sb));
    CHECK_EQ_INT(sb.n_bricks, sa.n_bricks);
    CHECK_EQ_INT(sb.n_chunks, sa.n_chunks);
    CHECK_EQ_INT(sb.n_confident_voxels, sa.n_confident_voxels);
    /* Neither a second load nor a new origin once loaded. */
    CHECK_STATUS(fusion_load(map2, &a), BF_INVALID_ARG);
    CHECK_STATUS(fusion_set_origin(map2, bf_v3(0, 0, 0)), BF_INVALID_ARG);
    /* Emptied (fusion_clear: a particle set's next time step), it is whole
     * and empty and loads the same map again; not once it has frames. */
    CHECK_OK(fusion_clear(map2));
    CHECK_OK(fusion_check(map2));
    CHECK_OK(fusion_get_stats(map2, &sc));
    CHECK_EQ_INT(sc.n_bricks, 0);
    CHECK_OK(fusion_load(map2, &a));
    CHECK_OK(fusion_check(map2));
    hostmap again = {0};
    CHECK_OK(fusion_snapshot_take(map2, &again));
    CHECK_OK(store_map_digest(&again, &db));
    CHECK(da == db);
    hostmap_free(&again);
    /* Without colour a clear undoes only what the load wrote (its slots,
     * nodes, hash and counters): the pools then read as a new map's, and the
     * load edited in place (mapped, host-cached: lavapipe) builds what the
     * staged copies do (force_staging). */
    uint64_t dn[2];
    for (int staged = 0; staged < 2; staged++) {
        gpu_config sc = gpu_fixture_config();
        sc.force_staging = staged;
        gpu_context *cx = NULL;
        CHECK_OK(gpu_context_create(&sc, &cx));
        fusion_config cn = c;
        cn.keep_colour = false;
        cn.load_only = staged == 0; /* and a map without the frame pipelines loads the same */
        fusion_map *m3 = NULL, *fresh = NULL;
        CHECK_OK(fusion_create(cx, &cn, &K_TEST, bf_v3(0, 0, 0), &m3));
        CHECK_OK(fusion_create(cx, &cn, &K_TEST, bf_v3(0, 0, 0), &fresh));
        CHECK(staged ? gpu_buffer_map(fusion_gpu_view_get(m3).nodes) == NULL : true);
        for (int round = 0; round < 2; round++) {
            CHECK_OK(fusion_load(m3, &a));
            CHECK_OK(fusion_check(m3));
            hostmap h3 = {0};
            CHECK_OK(fusion_snapshot_take(m3, &h3));
            uint64_t d3;
            CHECK_OK(store_map_digest(&h3, &d3));
            CHECK_EQ_INT(h3.n_bricks, a.n_bricks);
            hostmap_free(&h3);
            if (round == 0) dn[staged] = d3;
            CHECK(d3 == dn[staged]);
            CHECK_OK(fusion_clear(m3));
            fusion_gpu_view v3 = fusion_gpu_view_get(m3), v4 = fusion_gpu_view_get(fresh);
            gpu_buffer *b3[] = {v3.hash, v3.nodes, v3.info, v3.sign, v3.conf};
            gpu_buffer *b4[] = {v4.hash, v4.nodes, v4.info, v4.sign, v4.conf};
            for (int k = 0; k < 5; k++) {
                uint64_t bytes = gpu_buffer_size(b3[k]);
                CHECK_EQ_INT(bytes, gpu_buffer_size(b4[k]));
                uint8_t *x = malloc(bytes), *y = malloc(bytes);
                CHECK(x && y);
                CHECK_OK(gpu_buffer_download(b3[k], 0, x, bytes));
                CHECK_OK(gpu_buffer_download(b4[k], 0, y, bytes));
                if (memcmp(x, y, bytes) != 0) fprintf(stderr, "  %s differs after the clear\n", gpu_buffer_name(b3[k]));
                CHECK(memcmp(x, y, bytes) == 0);
                free(x);
                free(y);
            }
            CHECK_OK(fusion_get_stats(m3, &sc3));
            CHECK_EQ_INT(sc3.n_bricks, 0);
        }
        if (cn.load_only) {
            CHECK_STATUS(fusion_add_frame(m3, &f, &T0), BF_INVALID_ARG);
            CHECK(strstr(bf_last_error(), "load_only") != NULL);
        }
        fusion_destroy(m3);
        fusion_destroy(fresh);
        GPU_FIXTURE_CHECK_CLEAN(cx);
        gpu_context_destroy(cx);
    }
    CHECK(dn[0] == dn[1]);
    /* The loaded octree is the one the GPU finds: the same frame added to
     * both maps gives bricks at the same places (their bits differ: the
     * original's ring still holds its frames). */
    f.index = 0;
    CHECK_OK(fusion_add_frame(map2, &f, &T0));
    f.index = 6;
    CHECK_OK(fusion_add_frame(map, &f, &T0));
    CHECK_OK(fusion_check(map2));
    CHECK_STATUS(fusion_clear(map2), BF_INVALID_ARG);
    hostmap pa = {0}, pb = {0};
    CHECK_OK(fusion_snapshot_take(map, &pa));
    CHECK_OK(fusion_snapshot_take(map2, &pb));
    CHECK_EQ_INT(pb.n_bricks, pa.n_bricks);
    CHECK(pb.n_bricks > a.n_bricks);
    for (uint32_t i = 0; i < pa.n_bricks; i++) {
        memset(pa.bricks[i].sign, 0, sizeof pa.bricks[i].sign), memset(pa.bricks[i].conf, 0, sizeof pa.bricks[i].conf);
        memset(pb.bricks[i].sign, 0, sizeof pb.bricks[i].sign), memset(pb.bricks[i].conf, 0, sizeof pb.bricks[i].conf);
        pa.bricks[i].error = pb.bricks[i].error = 0;
    }
    CHECK_OK(store_map_digest(&pa, &da));
    CHECK_OK(store_map_digest(&pb, &db));
    CHECK(da == db);
    hostmap_free(&pa);
    hostmap_free(&pb);

    /* Too small a pool: refused, and the map stays empty and whole. */
    fusion_config ct = c;
    ct.brick_cap = a.n_bricks / 2;
    CHECK_OK(fusion_create(ctx, &ct, &K_TEST, bf_v3(0, 0, 0), &tiny));
    CHECK_STATUS(fusion_load(tiny, &a), BF_POOL_FULL);
    hostmap odd = a;
    odd.chunk_m = 1.0f;
    CHECK_STATUS(fusion_load(tiny, &odd), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("chunks");
    CHECK_OK(fusion_check(tiny));
    CHECK_OK(fusion_get_stats(tiny, &sc));
    CHECK_EQ_INT(sc.n_bricks, 0);
    hostmap_free(&a);
    hostmap_free(&b);
    free(depth);
    free(rgb);
    fusion_destroy(tiny);
    fusion_destroy(map2);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Streaming's two moves: chunks evicted into a host copy leave a smaller,
 * consistent map (nodes and hash entries given back), chunks a window
 * still needs stay, and the evicted bricks inserted back give the map it
 * was, bit for bit. */
BF_TEST(evicted_chunks_come_back_bit_for_bit)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    fusion_config c = small_config();
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &c, &K_TEST, bf_v3(0, 0, 0), &map));
    uint16_t *depth = plane_depth(&K_TEST, 1.2);
    bf_frame f = make_frame(&K_TEST, depth, 0);
    /* A colour gradient, so the map keeps colour and the eviction carries it. */
    uint8_t *rgb = malloc((size_t)K_TEST.width * K_TEST.height * 3);
    CHECK(rgb != NULL);
    for (uint32_t i = 0; i < K_TEST.width * K_TEST.height; i++)
        rgb[3 * i] = (uint8_t)(i % K_TEST.width), rgb[3 * i + 1] = (uint8_t)(i / K_TEST.width), rgb[3 * i + 2] = 90;
    f.rgb = rgb;
    bf_se3 A = bf_se3_identity(), Bp = bf_se3_identity();
    Bp.t = bf_v3(10.0, 0.3, 0.0); /* chunks 5 away in x */
    for (uint32_t i = 0; i < 12; i++) {
        f.index = i;
        CHECK_OK(fusion_add_frame(map, &f, i < 4 ? &A : &Bp));
    }
    CHECK_OK(fusion_flush(map));
    hostmap s0 = {0}, s1 = {0}, s2 = {0}, ev = {0}, none = {0};
    fusion_stats st0, st1;
    CHECK_OK(fusion_snapshot_take(map, &s0));
    CHECK_OK(fusion_get_stats(map, &st0));
    int32_t(*keys)[3] = NULL;
    uint32_t nk = 0, n_near = 0, n_far = 0, n_ev = 0;
    CHECK_OK(fusion_chunk_keys(map, &keys, &nk));
    CHECK_EQ_INT(nk, st0.n_chunks);
    int32_t near[16][3], far[16][3];
    for (uint32_t i = 0; i < nk && i < 16; i++) {
        if (keys[i][0] < 3) memcpy(near[n_near++], keys[i], sizeof near[0]);
        else memcpy(far[n_far++], keys[i], sizeof far[0]);
    }
    free(keys);
    CHECK(n_near >= 1 && n_far >= 1);
    /* The chunks of the last frames are in the last window: they stay. */
    CHECK_OK(fusion_evict_chunks(map, (const int32_t(*)[3])far, n_far, &none, &n_ev));
    CHECK_EQ_INT(n_ev, 0);
    CHECK_EQ_INT(none.n_bricks, 0);
    hostmap_free(&none);
    /* The first frames' chunks go. */
    CHECK_OK(fusion_evict_chunks(map, (const int32_t(*)[3])near, n_near, &ev, &n_ev));
    CHECK_EQ_INT(n_ev, n_near);
    CHECK(ev.n_bricks > 0);
    CHECK_OK(fusion_check(map));
    CHECK_OK(fusion_get_stats(map, &st1));
    CHECK_EQ_INT(st1.n_chunks, st0.n_chunks - n_near);
    CHECK_EQ_INT(st1.n_bricks + ev.n_bricks, st0.n_bricks);
    CHECK(st1.n_nodes < st0.n_nodes);
    /* What stayed plus what left is what was. */
    CHECK_OK(fusion_snapshot_take(map, &s1));
    hostmap both = s1; /* the digest covers colour: both carries s1's and ev's */
    both.n_bricks = s1.n_bricks + ev.n_bricks;
    both.bricks = malloc(both.n_bricks * sizeof *both.bricks);
    both.rgb565 = malloc((size_t)both.n_bricks * 512 * 2);
    CHECK(both.bricks != NULL && both.rgb565 != NULL && s1.rgb565 != NULL && ev.rgb565 != NULL);
    memcpy(both.bricks, s1.bricks, s1.n_bricks * sizeof *both.bricks);
    memcpy(both.bricks + s1.n_bricks, ev.bricks, ev.n_bricks * sizeof *both.bricks);
    memcpy(both.rgb565, s1.rgb565, (size_t)s1.n_bricks * 512 * 2);
    memcpy(both.rgb565 + (size_t)s1.n_bricks * 512, ev.rgb565, (size_t)ev.n_bricks * 512 * 2);
    uint64_t d0, d1, d2;
    CHECK_OK(store_map_digest(&s0, &d0));
    CHECK_OK(store_map_digest(&both, &d1));
    CHECK(d0 == d1);
    /* Back in, the map is the one it was. */
    CHECK_OK(fusion_insert_bricks(map, &ev));
    CHECK_OK(fusion_check(map));
    CHECK_OK(fusion_snapshot_take(map, &s2));
    CHECK_OK(store_map_digest(&s2, &d2));
    CHECK(d0 == d2);
    /* Colour left and came back with its bricks: every brick of s0 has the
     * same 512 colours in s2 (found by place). */
    CHECK(s0.rgb565 != NULL && s2.rgb565 != NULL && ev.rgb565 != NULL);
    uint64_t n_col = 0, n_diff = 0;
    for (uint32_t i = 0; i < s0.n_bricks; i++) {
        const hostmap_brick *a = &s0.bricks[i];
        uint32_t j = 0;
        while (j < s2.n_bricks && !(memcmp(s2.bricks[j].key, a->key, 12) == 0 && s2.bricks[j].level == a->level &&
                                    memcmp(s2.bricks[j].cell, a->cell, 12) == 0))
            j++;
        CHECK(j < s2.n_bricks);
        for (uint32_t v = 0; j < s2.n_bricks && v < 512; v++) {
            n_col += s0.rgb565[(size_t)i * 512 + v] != 0;
            n_diff += s0.rgb565[(size_t)i * 512 + v] != s2.rgb565[(size_t)j * 512 + v];
        }
    }
    CHECK(n_col > 0);
    CHECK_EQ_INT(n_diff, 0);
    /* And it goes on fusing. */
    f.index = 12;
    CHECK_OK(fusion_add_frame(map, &f, &A));
    CHECK_OK(fusion_check(map));
    hostmap_free(&s0);
    hostmap_free(&s1);
    hostmap_free(&s2);
    hostmap_free(&ev);
    hostmap_free(&both);
    free(depth);
    free(rgb);
    fusion_destroy(map);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
