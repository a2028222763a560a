/* render: the mesh renderer's voxeliser (render_voxelise_mesh), loaded
 * into a map and ray-cast by the `surface` traverser, against the mesh
 * ray-traced on the CPU (mesh_bvh_raycast): silhouettes and depths. A torus
 * (concave, closed, made here) always; the Stanford bunny when the shared
 * data is there. Validation is on. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gpu_fixture.h"
#include "mesh_shapes.h"
#include "mesh/mesh.h"
#include "render/render.h"

static const bf_intrinsics K_VIEW = {200, 150, 170.0, 170.0, 99.5, 74.5, 5000};

/* Camera to world looking at `at` from `dist` away along the direction
 * (yaw about y, pitch about x) of its optical axis. */
static bf_se3 look_at(bf_vec3 at, double dist, double yaw, double pitch)
{
    bf_quat q = bf_quat_mul(bf_quat_from_axis_angle(bf_v3(0, 1, 0), yaw), bf_quat_from_axis_angle(bf_v3(1, 0, 0), pitch));
    bf_vec3 axis = bf_quat_rotate(q, bf_v3(0, 0, 1));
    return bf_se3_from_qt(q, bf_v3_sub(at, bf_v3_scale(axis, dist)));
}

typedef struct view_result {
    double iou;
    double depth_p50, depth_p95, depth_p99; /* |depth - truth| over pixels both hit, in voxels */
    uint32_t n_truth, n_cast_only;
    uint32_t n_off_outline; /* pixels hit by one of the two only, with no neighbour on the other side of the true outline */
} view_result;

/* Ray-casts the voxelised mesh at T_wc and compares with the CPU's ray
 * trace of the mesh itself; depth errors in voxels of voxel_m, or with
 * voxel_m 0 of the level each pixel hit (2 m chunks). */
static void compare_view(gpu_context *ctx, fusion_map *map, const mesh_bvh *bvh, const bf_se3 *T_wc, double voxel_m,
                         bool no_graze, view_result *out)
{
    view_result r = {0};
    render_caster *rc;
    CHECK_OK(render_create(ctx, NULL, K_VIEW.width, K_VIEW.height, &rc));
    render_options ro = render_options_display();
    ro.near_m = 0.05f;
    ro.no_graze = no_graze;
    CHECK_OK(render_raycast(rc, map, &K_VIEW, T_wc, &ro));
    render_images im;
    CHECK_OK(render_download(rc, &im));
    uint32_t n_px = K_VIEW.width * K_VIEW.height, n_and = 0, n_or = 0, n_err = 0;
    double *err = calloc(n_px, sizeof *err);
    uint8_t *mask = calloc(n_px, 1); /* bit 0 truth, bit 1 cast */
    for (uint32_t i = 0; i < n_px; i++) {
        double u = i % K_VIEW.width, v = i / K_VIEW.width;
        bf_vec3 d_c = bf_v3((u - K_VIEW.cx_px) / K_VIEW.fx_px, (v - K_VIEW.cy_px) / K_VIEW.fy_px, 1.0);
        bf_vec3 d_w = bf_v3_sub(bf_se3_apply(T_wc, d_c), T_wc->t);
        mesh_hit hit;
        bool truth = mesh_bvh_raycast(bvh, T_wc->t, d_w, 0.05, 10.0, &hit);
        bool got = im.depth[i] > 0;
        mask[i] = (uint8_t)(truth | got << 1);
        r.n_truth += truth;
        n_and += truth && got, n_or += truth || got;
        if (truth && got) {
            double vox = voxel_m > 0 ? voxel_m : hostmap_level_voxel_m(2.0f, im.level[i]);
            err[n_err++] = fabs(im.depth[i] - hit.t) / vox; /* d_c.z = 1: t is the depth */
        }
    }
    /* A silhouette within a pixel: every pixel the two disagree on touches the true outline. */
    for (uint32_t i = 0; i < n_px; i++) {
        if ((mask[i] & 1) == (mask[i] >> 1)) continue;
        int u = (int)(i % K_VIEW.width), v = (int)(i / K_VIEW.width);
        bool at_outline = false;
        for (int dv = -1; dv <= 1; dv++)
            for (int du = -1; du <= 1; du++) {
                int uu = u + du, vv = v + dv;
                if (uu >= 0 && vv >= 0 && uu < (int)K_VIEW.width && vv < (int)K_VIEW.height)
                    at_outline |= (mask[vv * K_VIEW.width + uu] & 1) != (mask[i] & 1);
            }
        r.n_off_outline += !at_outline;
    }
    free(mask);
    r.iou = n_or ? (double)n_and / n_or : 0;
    r.n_cast_only = n_or - r.n_truth;
    r.depth_p50 = n_err ? bf_percentile_inplace(err, n_err, 50) : INFINITY;
    r.depth_p95 = n_err ? bf_percentile_inplace(err, n_err, 95) : INFINITY;
    r.depth_p99 = n_err ? bf_percentile_inplace(err, n_err, 99) : INFINITY;
    free(err);
    render_images_free(&im);
    render_destroy(rc);
    *out = r;
}

/* What a view comparison drew from: the mesh's BVH, the map and its host copy. */
static void free_drawn(mesh_bvh *bvh, fusion_map *map, hostmap *hm)
{
    mesh_bvh_destroy(bvh);
    fusion_destroy(map);
    hostmap_free(hm);
}

/* hm loaded into a map of its own size (sparse bricks: a node path each); NULL on failure. */
static fusion_map *load_map(gpu_context *ctx, const hostmap *hm)
{
    fusion_config fc = fusion_config_default();
    fc.brick_cap = hm->n_bricks + 64;
    fc.node_cap = 16 * hm->n_bricks + 1024;
    fusion_map *map = NULL;
    if (fusion_create(ctx, &fc, &K_VIEW, hm->origin_w, &map) != BF_OK) return NULL;
    if (fusion_load(map, hm) != BF_OK) {
        fusion_destroy(map);
        return NULL;
    }
    return map;
}

/* Voxelises m at level, loads it and checks three views of it. */
static void check_mesh(gpu_context *ctx, const mesh_data *m, uint32_t level, const char *name)
{
    render_voxelise_config vc = render_voxelise_config_default();
    vc.level = level;
    hostmap hm;
    render_voxelise_stats st;
    CHECK_OK(render_voxelise_mesh(ctx, m, NULL, &vc, &hm, &st));
    CHECK(hm.n_bricks > 0);
    fusion_map *map = load_map(ctx, &hm);
    CHECK(map != NULL);
    mesh_bvh *bvh;
    CHECK_OK(mesh_bvh_build(m, &bvh));
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < m->n_verts; i++)
        for (int a = 0; a < 3; a++) lo[a] = fmin(lo[a], m->xyz[3 * i + a]), hi[a] = fmax(hi[a], m->xyz[3 * i + a]);
    bf_vec3 centre = bf_v3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    double size = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    const double views[3][2] = {{0, 0}, {0.7, 0.4}, {-2.2, -0.9}};
    for (int k = 0; k < 6; k++) {
        bool no_graze = k >= 3;
        bf_se3 T = look_at(centre, 1.6 * size, views[k % 3][0], views[k % 3][1]);
        view_result r = {0};
        compare_view(ctx, map, bvh, &T, st.voxel_m, no_graze, &r);
        fprintf(stderr, "  %s level %u (%.2f mm, %u bricks, %.3f s), view %d%s: IoU %.4f (%u pixels hit only by the "
                        "cast, %u off the outline), |depth error| p50 %.2f, p95 %.2f, p99 %.2f voxels (%u pixels hit)\n",
                name, level, 1e3 * st.voxel_m, st.n_bricks, st.seconds, k % 3, no_graze ? ", no_graze" : "", r.iou,
                r.n_cast_only, r.n_off_outline, r.depth_p50, r.depth_p95, r.depth_p99, r.n_truth);
        CHECK(r.n_truth > K_VIEW.width * K_VIEW.height / 10);
        /* Depths lie within the voxel of the level used (the sub-voxel
         * refinement puts the median at a tenth of one). Silhouettes: a
         * voxel whose centre is inside is drawn as its whole cube, so the
         * plain cast's outline grows by up to half a voxel (a sixth of a
         * pixel here: IoU 0.986-0.992); passing by the hits whose refined
         * depth stays in front of the smoothed surface (no_graze, what the
         * mesh renderer casts with) meets the 0.99 (docs/render.md). */
        CHECK(r.iou >= (no_graze ? 0.99 : 0.98));
        CHECK_EQ_INT(r.n_off_outline, 0);
        CHECK_LE(r.depth_p50, 0.25);
        CHECK_LE(r.depth_p95, 1.0);
    }
    free_drawn(bvh, map, &hm);
}

BF_TEST(voxelised_torus_renders_like_the_mesh)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    mesh_data m = test_torus(0.12, 0.045, 96, 48);
    check_mesh(ctx, &m, 8, "torus");
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(voxelised_bunny_renders_like_the_mesh)
{
    const char *path = bf_test_data("meshes/bunny.ply");
    if (!path) BF_SKIP("shared data absent");
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    /* About 1 unit across: a 25 cm bunny. */
    for (uint32_t i = 0; i < 3 * m.n_verts; i++) m.xyz[i] *= 0.25f;
    check_mesh(ctx, &m, 8, "bunny");
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* n tori (R 10 cm, r 4 cm) face-on to a camera at the origin looking
 * along +z, at the depths z[i] and the lateral offsets x[i]: one mesh. */
static mesh_data receding_tori(const double *z, const double *x, uint32_t n)
{
    mesh_data one = test_torus(0.1, 0.04, 96, 48), m = {0};
    m.n_verts = n * one.n_verts, m.n_tris = n * one.n_tris;
    m.xyz = malloc((size_t)m.n_verts * 12);
    m.tri = malloc((size_t)m.n_tris * 12);
    for (uint32_t k = 0; k < n; k++) {
        for (uint32_t i = 0; i < one.n_verts; i++) {
            float *p = m.xyz + 3 * ((size_t)k * one.n_verts + i);
            p[0] = one.xyz[3 * i] + (float)x[k], p[1] = one.xyz[3 * i + 1], p[2] = one.xyz[3 * i + 2] + (float)z[k];
        }
        for (uint32_t t = 0; t < 3 * one.n_tris; t++) m.tri[(size_t)k * 3 * one.n_tris + t] = one.tri[t] + k * one.n_verts;
    }
    mesh_free(&one);
    return m;
}

/* Level of detail by pixel footprint within one mesh: tori from 0.5 to 4 m
 * away are voxelised each at the level its footprint needs, and the cast
 * meets the mesh as closely, in voxels of the level each pixel hit, as a
 * mesh voxelised at one level does, with a fraction of the bricks. */
BF_TEST(level_of_detail_follows_the_pixel_footprint)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    const double z[4] = {0.7, 1.5, 3.0, 5.5}, x[4] = {-0.245, -0.075, 0.75, 2.5};
    mesh_data m = receding_tori(z, x, 4);
    bf_se3 T = bf_se3_identity();
    render_voxelise_config vc = render_voxelise_config_default();
    vc.level = 8;
    vc.lod = true, vc.lod_T_wc = T, vc.lod_K = K_VIEW;
    hostmap hm;
    render_voxelise_stats st;
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st));
    /* A third of the footprint z cos(corner) / f (cos 0.81 here): 0.7 m needs level 8 (0.98 mm), 1.5 m
       level 7, 3 m level 6, 5.5 m level 5 (7.8 mm; the cast reaches 6 m). The columns run along x or y, across the view. */
    fprintf(stderr, "  lod: %u bricks over levels %u-%u (%u columns):", st.n_bricks, st.level_coarse, st.level_fine,
            st.n_columns);
    for (uint32_t l = st.level_coarse; l <= st.level_fine; l++) fprintf(stderr, " %u at %u", st.bricks_at_level[l], l);
    fprintf(stderr, "\n");
    CHECK_EQ_INT(st.level_coarse, 5);
    CHECK_EQ_INT(st.level_fine, 8);
    CHECK(st.column_axis != 2);
    for (uint32_t l = 5; l <= 8; l++) CHECK(st.bricks_at_level[l] > 0);
    uint32_t per_level[13] = {0};
    for (uint32_t i = 0; i < hm.n_bricks; i++) per_level[hm.bricks[i].level]++;
    for (uint32_t l = 0; l < 13; l++) CHECK_EQ_INT(per_level[l], st.bricks_at_level[l]);
    /* One level for all (the nearest torus's) needs several times the bricks. */
    render_voxelise_config one = render_voxelise_config_default();
    one.level = 8;
    hostmap h1;
    render_voxelise_stats st1;
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &one, &h1, &st1));
    fprintf(stderr, "  one level: %u bricks at level 8\n", st1.n_bricks);
    CHECK(2 * st.n_bricks < st1.n_bricks);
    hostmap_free(&h1);
    fusion_map *map = load_map(ctx, &hm);
    CHECK(map != NULL);
    mesh_bvh *bvh;
    CHECK_OK(mesh_bvh_build(&m, &bvh));
    view_result r = {0};
    compare_view(ctx, map, bvh, &T, 0, true, &r);
    fprintf(stderr, "  lod view: IoU %.4f (%u pixels off the outline), |depth error| p50 %.2f, p95 %.2f, p99 %.2f "
                    "voxels of the level hit (%u pixels hit)\n", r.iou, r.n_off_outline, r.depth_p50, r.depth_p95,
            r.depth_p99, r.n_truth);
    CHECK(r.n_truth > 3000);
    /* The screen-space error under a pixel: the two silhouettes differ only next to the true outline. */
    CHECK_EQ_INT(r.n_off_outline, 0);
    CHECK(r.iou >= 0.99);
    CHECK_LE(r.depth_p50, 0.25);
    CHECK_LE(r.depth_p95, 1.0);
    free_drawn(bvh, map, &hm);
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A box whose faces lie on the voxel grid, all of it at one level of
 * detail: the columns of the plan cover the bricks the binning grows the
 * faces into (they stopped at the box and dropped the free bricks in front
 * of the face the camera sees: its first known voxels were inside, nothing
 * was drawn), and it is drawn as without the plan. */
BF_TEST(level_of_detail_draws_a_box_on_the_grid)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    const double lo[3] = {-0.25, -0.1875, 1.0}, hi[3] = {0.25, 0.1875, 1.5}; /* whole level-5 voxels (7.8125 mm) */
    mesh_data m = test_box(lo, hi);
    bf_se3 T = bf_se3_identity();
    render_voxelise_config vc = render_voxelise_config_default();
    vc.level = 5; /* the finest allowed, coarser than the footprint wants everywhere: one level */
    vc.lod = true, vc.lod_T_wc = T, vc.lod_K = K_VIEW;
    hostmap hm;
    render_voxelise_stats st;
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st));
    CHECK_EQ_INT(st.level_coarse, 5);
    CHECK_EQ_INT(st.level_fine, 5);
    fusion_map *map = load_map(ctx, &hm);
    CHECK(map != NULL);
    mesh_bvh *bvh;
    CHECK_OK(mesh_bvh_build(&m, &bvh));
    view_result r = {0};
    compare_view(ctx, map, bvh, &T, st.voxel_m, true, &r);
    fprintf(stderr, "  box at one level of detail: %u bricks, IoU %.4f (%u pixels hit)\n", st.n_bricks, r.iou, r.n_truth);
    CHECK(r.n_truth > K_VIEW.width * K_VIEW.height / 10);
    CHECK(r.iou >= 0.97);
    free_drawn(bvh, map, &hm);
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A mesh 300 m away is walked to in every direction: from 256 m on, a
 * float's step is over twice the walk's nudge, which rounded away, and a
 * ray going toward lower coordinates stayed on its cell's face (only the
 * quadrant of rays with positive x and y hit). The 50 m face at 275 m
 * covers 170 px x 25 / 275 = 15.5 px each side of the centre: about 31 x 31
 * pixels, a quarter of them in each quadrant, at 275 m. */
BF_TEST(a_mesh_300_m_away_is_hit_in_every_direction)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    const double lo[3] = {-25, -25, 275}, hi[3] = {25, 25, 325};
    mesh_data m = test_box(lo, hi);
    render_voxelise_config vc = render_voxelise_config_default();
    vc.level = 0; /* 0.25 m voxels: a third of the footprint there */
    hostmap hm;
    render_voxelise_stats st;
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st));
    fusion_map *map = load_map(ctx, &hm);
    CHECK(map != NULL);
    render_caster *rc;
    CHECK_OK(render_create(ctx, NULL, K_VIEW.width, K_VIEW.height, &rc));
    render_options ro = render_options_display();
    ro.far_m = 1000;
    bf_se3 T = bf_se3_identity();
    CHECK_OK(render_raycast(rc, map, &K_VIEW, &T, &ro));
    render_images im;
    CHECK_OK(render_download(rc, &im));
    uint32_t quadrant[4] = {0}, n_hit = 0, n_near = 0;
    for (uint32_t v = 0; v < K_VIEW.height; v++)
        for (uint32_t u = 0; u < K_VIEW.width; u++) {
            float d = im.depth[v * K_VIEW.width + u];
            if (!(d > 0)) continue;
            n_hit++;
            n_near += fabs(d - 275.0) <= 0.25;
            quadrant[(u > K_VIEW.cx_px) + 2 * (v > K_VIEW.cy_px)]++;
        }
    fprintf(stderr, "  box at 275 m: %u pixels hit (%u within a voxel of 275 m), quadrants %u %u %u %u\n", n_hit, n_near,
            quadrant[0], quadrant[1], quadrant[2], quadrant[3]);
    CHECK(n_hit >= 850 && n_hit <= 1100);
    CHECK(n_near >= n_hit * 9 / 10);
    for (int q = 0; q < 4; q++) CHECK(quadrant[q] >= n_hit / 5);
    render_images_free(&im);
    render_destroy(rc);
    fusion_destroy(map);
    hostmap_free(&hm);
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(voxelise_refuses_bad_meshes)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    mesh_data m = test_torus(0.1, 0.03, 8, 6);
    hostmap hm;
    m.tri[5] = m.n_verts; /* out of range */
    CHECK_STATUS(render_voxelise_mesh(ctx, &m, NULL, NULL, &hm, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("triangle 1");
    m.tri[5] = 0;
    m.xyz[4] = NAN;
    CHECK_STATUS(render_voxelise_mesh(ctx, &m, NULL, NULL, &hm, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("vertex 1");
    m.xyz[4] = 0;
    render_voxelise_config vc = render_voxelise_config_default();
    vc.max_pairs = 10;
    CHECK_STATUS(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, NULL), BF_POOL_FULL);
    CHECK_ERROR_MENTIONS("coarser level");
    /* Too many bricks (faces along the columns add bricks without pairs):
     * refused while binning, with the levels tried in the stats; a level
     * coarser fits (render's retry). */
    render_voxelise_stats st;
    vc = render_voxelise_config_default();
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st));
    uint32_t need = hm.n_bricks;
    hostmap_free(&hm);
    CHECK(need > 8);
    /* All but one: each half of the triangles fits, the merged bricks do not. */
    vc.max_bricks = need - 1;
    CHECK_STATUS(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st), BF_POOL_FULL);
    CHECK_ERROR_MENTIONS("bricks at level 7, more than");
    CHECK_EQ_INT(st.level_fine, 7);
    /* A tenth: a half passes it while binning. */
    vc.max_bricks = need / 10;
    CHECK_STATUS(render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st), BF_POOL_FULL);
    CHECK_ERROR_MENTIONS("bricks at level 7: choose");
    CHECK_EQ_INT(st.level_fine, 7);
    /* Coarser until it fits, as render does. */
    while (render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st) == BF_POOL_FULL && st.level_fine > 0)
        vc.level = st.level_fine - 1;
    CHECK(hm.n_bricks > 0 && hm.n_bricks <= need / 10);
    CHECK(vc.level < 7);
    hostmap_free(&hm);
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
