/* stream: mesh export from CPU-built snapshots of analytic shapes. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "test.h"

/* World placement: the origin is off the world origin and the shapes sit
 * around it, so chunk keys -1 and 0 both occur on every axis. */
static const bf_vec3 ORIGIN = {0.5, -0.25, 1.0};

static void snap_init(hostmap *s)
{
    memset(s, 0, sizeof *s);
    s->chunk_m = 2.0f;
    s->origin_w = ORIGIN;
}

static fx_sphere test_sphere(void)
{
    /* Centre off every lattice, radius 0.3 m. */
    fx_sphere sp = {bf_v3(ORIGIN.x + 0.0137, ORIGIN.y - 0.0211, ORIGIN.z + 0.0093), 0.3};
    return sp;
}

static void sphere_bounds(const fx_sphere *sp, bf_vec3 *lo, bf_vec3 *hi)
{
    double r = sp->r + 0.05;
    *lo = bf_v3(sp->c.x - r, sp->c.y - r, sp->c.z - r);
    *hi = bf_v3(sp->c.x + r, sp->c.y + r, sp->c.z + r);
}

static bool pick_x_below(const void *ctx, bf_vec3 c) { return c.x < *(const double *)ctx; }
static bool pick_x_above(const void *ctx, bf_vec3 c) { return c.x >= *(const double *)ctx; }

static void print_acc(const char *what, const fx_accuracy *a, double v, const export_stats *st)
{
    printf("  %s: voxel %.2f mm, vertices median %.3f max %.3f vox, area median %.3f p99 %.3f max %.3f vox, "
           "%u bricks, %llu tris %llu verts, %.3f s\n",
           what, v * 1e3, a->vert_median / v, a->vert_max / v, a->area_median / v, a->area_p99 / v, a->area_max / v,
           st->n_bricks, (unsigned long long)st->n_triangles, (unsigned long long)st->n_vertices, st->seconds);
}

/* Tolerances of a sphere voxelized at one level. The binary grid pins the
 * surface only to within a voxel along each axis (the sign flips somewhere
 * between two centres), and marching cubes on it puts every vertex on an
 * edge between an inside and a free centre, so without smoothing a vertex
 * is at most 1 voxel from the surface and terraces give a median near
 * 0.25 voxel (uniform offsets on [0, 0.5]). The smoothed field's zero
 * crossing plus Taubin smoothing average neighbouring crossings, which must
 * bring the median well under that: assert median < 0.25 voxel for the
 * vertices and area samples and max < 1 voxel (what the edge bound gives). */
static void check_sphere_level(uint32_t level)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    fx_voxelize(&s, fx_sphere_sdf, &sp, level, lo, hi, 2, NULL, NULL, true);
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, NULL, &m, &st));
    double v = fx_voxel_m(&s, level);
    CHECK_EQ_INT(st.level_out, level);
    CHECK(m.n_tris > 0 && m.normal);
    fx_topology topo;
    fx_mesh_topology(&m, &topo);
    CHECK_EQ_INT(topo.n_boundary, 0);
    CHECK_EQ_INT(topo.n_nonmanifold, 0);
    CHECK_EQ_INT(topo.n_flipped, 0);
    fx_accuracy acc;
    fx_mesh_accuracy(&m, fx_sphere_sdf, &sp, v, &acc);
    print_acc(level == 6 ? "sphere level 6" : "sphere level 7", &acc, v, &st);
    CHECK_LE(acc.vert_median, 0.25 * v);
    CHECK_LE(acc.area_median, 0.25 * v);
    CHECK_LE(acc.vert_max, 1.0 * v);
    CHECK_LE(acc.area_max, 1.0 * v);
    /* Outward: every vertex normal points away from the centre (on a
     * sphere of 77+ voxels radius the normal is within a few degrees of
     * radial), and the signed volume is positive. */
    uint32_t n_inward = 0;
    for (uint32_t i = 0; i < m.n_verts; i++) {
        bf_vec3 r = bf_v3_normalize(bf_v3(m.xyz[3 * i] - sp.c.x, m.xyz[3 * i + 1] - sp.c.y, m.xyz[3 * i + 2] - sp.c.z));
        if (bf_v3_dot(r, bf_v3(m.normal[3 * i], m.normal[3 * i + 1], m.normal[3 * i + 2])) < cos(30 * M_PI / 180))
            n_inward++;
    }
    CHECK_EQ_INT(n_inward, 0);
    /* Area: 4 pi r^2 within 2 %. A surface that follows the sphere to
     * within the error above has an area off by about 2 * err / r (< 0.2 %
     * here) plus the excess of facets that are tilted against the true
     * surface; marching cubes on a binary grid overestimates by up to ~8 %
     * (terraces), the smoothing is what removes it. */
    double area_true = 4 * M_PI * sp.r * sp.r;
    printf("  area %.5f m^2 vs 4 pi r^2 = %.5f (%+.2f %%)\n", acc.area, area_true, 100 * (acc.area / area_true - 1));
    CHECK_NEAR(acc.area / area_true, 1.0, 0.02);
    mesh_free(&m);
    fx_free(&s);
}

BF_TEST(sphere_level6_is_closed_outward_and_within_a_voxel) { check_sphere_level(6); }
BF_TEST(sphere_level7_is_closed_outward_and_within_a_voxel) { check_sphere_level(7); }

/* Half the sphere at level 6, half at level 7: the lattice is level 7 and
 * the level-6 half is sampled on it, so the mesh is closed across the
 * border. With overlap, level 6 covers the whole sphere and level 7 only
 * half: the finer data wins there. Tolerances as for one level, in the
 * coarser level's voxels (the worse half bounds both). */
static void check_transition(bool overlap, uint32_t coarse)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    sp.r = 0.2; /* smaller than the one-level spheres: keeps the ASan run short */
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    double split = ORIGIN.x; /* a chunk border, so brick borders of both levels */
    fx_voxelize(&s, fx_sphere_sdf, &sp, coarse, lo, hi, 2, overlap ? NULL : pick_x_below, &split, true);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, pick_x_above, &split, true);
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, NULL, &m, &st));
    CHECK_EQ_INT(st.level_out, 7);
    CHECK(st.cells_per_level[coarse] > 0 && st.cells_per_level[7] > 0);
    fx_topology topo;
    fx_mesh_topology(&m, &topo);
    CHECK_EQ_INT(topo.n_boundary, 0);
    CHECK_EQ_INT(topo.n_nonmanifold, 0);
    CHECK_EQ_INT(topo.n_flipped, 0);
    double v6 = fx_voxel_m(&s, coarse), v7 = fx_voxel_m(&s, 7);
    fx_accuracy acc;
    fx_mesh_accuracy(&m, fx_sphere_sdf, &sp, v7, &acc);
    print_acc(overlap ? "sphere level 6 + half 7 (overlap)" : coarse == 6 ? "sphere half 6 | half 7" : "sphere half 5 | half 7",
              &acc, v6, &st);
    CHECK_LE(acc.vert_median, 0.25 * v6);
    CHECK_LE(acc.area_median, 0.25 * v6);
    CHECK_LE(acc.vert_max, 1.0 * v6);
    CHECK_LE(acc.area_max, 1.0 * v6);
    /* The fine half is meshed at level 7 from level-7 data: its vertices
     * meet the level-7 bound (away from the border, where coarse corners
     * take part). */
    double fine_max = 0;
    for (uint32_t i = 0; i < m.n_verts; i++) {
        bf_vec3 p = bf_v3(m.xyz[3 * i], m.xyz[3 * i + 1], m.xyz[3 * i + 2]);
        if (p.x > split + 4 * v6) fine_max = fmax(fine_max, fabs(fx_sphere_sdf(&sp, p)));
    }
    printf("  fine half max %.3f level-7 voxels\n", fine_max / v7);
    CHECK_LE(fine_max, 1.0 * v7);
    double area_true = 4 * M_PI * sp.r * sp.r;
    CHECK_NEAR(acc.area / area_true, 1.0, 0.02);
    mesh_free(&m);
    fx_free(&s);
}

BF_TEST(sphere_half_level6_half_level7_has_no_holes) { check_transition(false, 6); }
BF_TEST(finer_overlapping_bricks_win_and_the_mesh_stays_closed) { check_transition(true, 6); }
BF_TEST(two_levels_apart_half_level5_half_level7_has_no_holes) { check_transition(false, 5); }

/* A box rotated against the lattice (its faces tilted, so neighbouring
 * signs do locate them), and the same box axis-aligned. */
typedef struct rot_box {
    fx_box box;
    bf_se3 T_bw; /* world to box frame */
} rot_box;

static double rot_box_sdf(const void *shape, bf_vec3 p)
{
    const rot_box *r = shape;
    return fx_box_sdf(&r->box, bf_se3_apply(&r->T_bw, p));
}

static void check_box(bool rotated)
{
    hostmap s;
    snap_init(&s);
    rot_box rb;
    rb.box = (fx_box){bf_v3(0, 0, 0), bf_v3(0.15, 0.1, 0.12)};
    bf_se3 T_wb = bf_se3_from_qt(rotated ? bf_quat_from_axis_angle(bf_v3(1, 2, 3), 0.4) : bf_quat_identity(),
                                 bf_v3(ORIGIN.x + 0.011, ORIGIN.y - 0.007, ORIGIN.z + 0.013));
    rb.T_bw = bf_se3_inverse(&T_wb);
    bf_vec3 lo = bf_v3(T_wb.t.x - 0.25, T_wb.t.y - 0.25, T_wb.t.z - 0.25);
    bf_vec3 hi = bf_v3(T_wb.t.x + 0.25, T_wb.t.y + 0.25, T_wb.t.z + 0.25);
    fx_voxelize(&s, rot_box_sdf, &rb, 6, lo, hi, 2, NULL, NULL, true);
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, NULL, &m, &st));
    fx_topology topo;
    fx_mesh_topology(&m, &topo);
    CHECK_EQ_INT(topo.n_boundary, 0);
    CHECK_EQ_INT(topo.n_nonmanifold, 0);
    CHECK_EQ_INT(topo.n_flipped, 0);
    double v = fx_voxel_m(&s, 6);
    fx_accuracy acc;
    fx_mesh_accuracy(&m, rot_box_sdf, &rb, v, &acc);
    print_acc(rotated ? "rotated box level 6" : "axis-aligned box level 6", &acc, v, &st);
    /* Tilted faces: the bound of the sphere test. A face parallel to the
     * lattice is pinned only to the gap between two voxel centres; the
     * midpoint is then up to 0.5 voxel off, and that is the median bound.
     * Edges and corners: Taubin smoothing rounds a right angle over about
     * two voxels, so vertices there stay within 1.5 voxels. */
    CHECK_LE(acc.vert_median, (rotated ? 0.25 : 0.5) * v);
    CHECK_LE(acc.area_median, (rotated ? 0.25 : 0.5) * v);
    CHECK_LE(acc.vert_max, 1.5 * v);
    double area_true = 8 * (0.15 * 0.1 + 0.1 * 0.12 + 0.15 * 0.12);
    printf("  area %.5f vs %.5f (%+.2f %%)\n", acc.area, area_true, 100 * (acc.area / area_true - 1));
    CHECK_NEAR(acc.area / area_true, 1.0, 0.03);
    mesh_free(&m);
    fx_free(&s);
}

BF_TEST(rotated_box_is_closed_and_within_a_quarter_voxel_on_faces) { check_box(true); }
BF_TEST(axis_aligned_box_is_closed_and_within_half_a_voxel_on_faces) { check_box(false); }

static int cmp_u64(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;
    return a < b ? -1 : a > b;
}

/* A tilted plane through a corner shared by eight chunks (keys -1 and 0 on
 * every axis), meshed inside a box: the only open edges are at the box's
 * faces, none at brick or chunk borders inside. */
BF_TEST(plane_across_chunk_borders_with_negative_keys_has_no_cracks)
{
    hostmap s;
    snap_init(&s);
    fx_plane pl = {bf_v3_normalize(bf_v3(0.3, -0.2, 1.0)), 0};
    pl.d = bf_v3_dot(pl.n, bf_v3(ORIGIN.x + 0.0013, ORIGIN.y - 0.0021, ORIGIN.z + 0.0007));
    const uint32_t level = 7;
    double v = fx_voxel_m(&s, level), B = 8 * v, half = 0.1;
    bf_vec3 lo = bf_v3(ORIGIN.x - half, ORIGIN.y - half, ORIGIN.z - half);
    bf_vec3 hi = bf_v3(ORIGIN.x + half, ORIGIN.y + half, ORIGIN.z + half);
    fx_voxelize(&s, fx_plane_sdf, &pl, level, lo, hi, 2, NULL, NULL, true);
    bool has_neg = false, has_pos = false;
    for (uint32_t i = 0; i < s.n_bricks; i++) {
        has_neg |= s.bricks[i].key[0] < 0 && s.bricks[i].key[1] < 0 && s.bricks[i].key[2] < 0;
        has_pos |= s.bricks[i].key[0] >= 0 && s.bricks[i].key[1] >= 0 && s.bricks[i].key[2] >= 0;
    }
    CHECK(has_neg && has_pos);
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, NULL, &m, &st));
    CHECK(m.n_tris > 0);
    /* The meshed region: whole bricks, from floor(lo / B) to floor(hi / B). */
    double rlo[3], rhi[3];
    double lo3[3] = {lo.x - ORIGIN.x, lo.y - ORIGIN.y, lo.z - ORIGIN.z}, hi3[3] = {hi.x - ORIGIN.x, hi.y - ORIGIN.y, hi.z - ORIGIN.z};
    for (int a = 0; a < 3; a++) {
        rlo[a] = floor(lo3[a] / B) * B;
        rhi[a] = (floor(hi3[a] / B) + 1) * B;
    }
    /* Open edges farther than 2 voxels from the region's faces are cracks. */
    uint64_t n_open = 0, n_cracks = 0;
    {
        fx_topology topo;
        fx_mesh_topology(&m, &topo);
        CHECK_EQ_INT(topo.n_nonmanifold, 0);
        CHECK_EQ_INT(topo.n_flipped, 0);
        n_open = topo.n_boundary;
        /* Find the boundary edges themselves: count each undirected edge. */
        size_t n = (size_t)m.n_tris * 3;
        uint64_t *key = malloc(n * sizeof *key);
        CHECK(key);
        for (uint32_t t = 0; t < m.n_tris; t++)
            for (int k = 0; k < 3; k++) {
                uint64_t a = m.tri[3 * t + k], b = m.tri[3 * t + (k + 1) % 3];
                key[3 * t + k] = a < b ? a << 32 | b : b << 32 | a;
            }
        qsort(key, n, sizeof *key, cmp_u64);
        for (size_t i = 0; i < n;) {
            size_t j = i + 1;
            while (j < n && key[j] == key[i]) j++;
            if (j - i == 1) {
                uint32_t a = (uint32_t)(key[i] >> 32), b = (uint32_t)key[i];
                double mid[3];
                double dmin = INFINITY;
                for (int c = 0; c < 3; c++) {
                    mid[c] = (m.xyz[3 * a + c] + m.xyz[3 * b + c]) / 2 - (c == 0 ? ORIGIN.x : c == 1 ? ORIGIN.y : ORIGIN.z);
                    dmin = fmin(dmin, fmin(fabs(mid[c] - rlo[c]), fabs(rhi[c] - mid[c])));
                }
                if (dmin > 2 * v) n_cracks++;
            }
            i = j;
        }
        free(key);
    }
    printf("  plane: %llu open edges, all at the region's faces; %llu elsewhere\n", (unsigned long long)n_open,
           (unsigned long long)n_cracks);
    CHECK(n_open > 0);
    CHECK_EQ_INT(n_cracks, 0);
    fx_accuracy acc;
    fx_mesh_accuracy(&m, fx_plane_sdf, &pl, v, &acc);
    print_acc("plane level 7", &acc, v, &st);
    CHECK_LE(acc.vert_median, 0.25 * v);
    CHECK_LE(acc.vert_max, 1.0 * v);
    /* Normals point to the free side (+n). */
    for (uint32_t i = 0; i < m.n_verts; i++)
        CHECK(bf_v3_dot(pl.n, bf_v3(m.normal[3 * i], m.normal[3 * i + 1], m.normal[3 * i + 2])) > 0.5);
    mesh_free(&m);
    fx_free(&s);
}

BF_TEST(non_confident_voxels_never_produce_geometry)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    double split = ORIGIN.x;
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, pick_x_below, &split, true);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, pick_x_above, &split, false);
    /* A finer, non-confident layer over the confident half changes nothing. */
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, pick_x_below, &split, false);
    mesh_data m;
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    CHECK(m.n_tris > 0);
    /* Cells need 8 confident corners: the last confident centres are at
     * split - v/2; smoothing moves the open rim by a fraction of a voxel. */
    double v = fx_voxel_m(&s, 6), xmax = -INFINITY;
    for (uint32_t i = 0; i < m.n_verts; i++) xmax = fmax(xmax, m.xyz[3 * i]);
    CHECK_LE(xmax, split);
    mesh_free(&m);
    mesh_data pts;
    CHECK_OK(export_points(&s, &pts, NULL));
    CHECK(pts.n_verts > 0);
    for (uint32_t i = 0; i < pts.n_verts; i++) CHECK_LE(pts.xyz[3 * i], split - v / 2 + 1e-6);
    mesh_free(&pts);
    /* Nothing confident at all: nothing. */
    for (uint32_t i = 0; i < s.n_bricks; i++) memset(s.bricks[i].conf, 0, sizeof s.bricks[i].conf);
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    CHECK_EQ_INT(m.n_tris, 0);
    CHECK_EQ_INT(m.n_verts, 0);
    CHECK_OK(export_points(&s, &pts, NULL));
    CHECK_EQ_INT(pts.n_verts, 0);
    fx_free(&s);
}

BF_TEST(empty_snapshot_gives_an_empty_mesh)
{
    hostmap s;
    snap_init(&s);
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, NULL, &m, &st));
    CHECK(m.n_verts == 0 && m.n_tris == 0 && m.xyz == NULL && m.tri == NULL);
    CHECK_EQ_INT(st.n_bricks, 0);
    CHECK_OK(export_points(&s, &m, &st));
    CHECK(m.n_verts == 0 && m.xyz == NULL);
}

BF_TEST(malformed_snapshots_and_configs_are_rejected)
{
    hostmap s;
    snap_init(&s);
    hostmap_brick b;
    memset(&b, 0, sizeof b);
    b.level = 3;
    b.cell[1] = 8; /* outside a level-3 chunk */
    s.bricks = &b;
    s.n_bricks = 1;
    mesh_data m = {0};
    CHECK_STATUS(export_mesh(&s, NULL, &m, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("cell 8");
    CHECK_STATUS(export_points(&s, &m, NULL), BF_INVALID_ARG);
    b.cell[1] = 0;
    b.level = 21;
    CHECK_STATUS(export_mesh(&s, NULL, &m, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("level 21");
    b.level = 7;
    b.key[2] = -(1 << 30);
    CHECK_STATUS(export_mesh(&s, NULL, &m, NULL), BF_UNSUPPORTED);
    b.key[2] = 0;
    s.chunk_m = 0;
    CHECK_STATUS(export_mesh(&s, NULL, &m, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("chunk_m");
    s.chunk_m = 2;
    export_mesh_config c = export_mesh_config_default();
    c.taubin_mu = 0.5f;
    CHECK_STATUS(export_mesh(&s, &c, &m, NULL), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("Taubin");
    CHECK_STATUS(export_mesh(NULL, NULL, &m, NULL), BF_INVALID_ARG);
    CHECK_STATUS(export_mesh(&s, NULL, NULL, NULL), BF_INVALID_ARG);
    /* Outputs untouched on failure. */
    CHECK(m.xyz == NULL && m.n_verts == 0);
    /* The one valid brick (all unknown) exports to nothing. */
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    CHECK_EQ_INT(m.n_tris, 0);
}

static bool meshes_equal(const mesh_data *a, const mesh_data *b)
{
    return a->n_verts == b->n_verts && a->n_tris == b->n_tris &&
           !memcmp(a->xyz, b->xyz, (size_t)a->n_verts * 3 * sizeof(float)) &&
           !memcmp(a->normal, b->normal, (size_t)a->n_verts * 3 * sizeof(float)) &&
           !memcmp(a->tri, b->tri, (size_t)a->n_tris * 3 * sizeof(uint32_t));
}

BF_TEST(result_does_not_depend_on_brick_order_or_threads_and_duplicates_are_dropped)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    sp.r = 0.1;
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    double split = ORIGIN.x;
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, pick_x_below, &split, true);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, pick_x_above, &split, true);
    mesh_data a, b, pa, pb;
    export_stats sa, sb;
    CHECK_OK(export_mesh(&s, NULL, &a, &sa));
    CHECK_OK(export_points(&s, &pa, NULL));
    /* Reverse and rotate the brick order, then add duplicates of the first
     * ten bricks with a worse error (identical data). */
    uint32_t n = s.n_bricks;
    hostmap_brick *r = malloc(((size_t)n + 10) * sizeof *r);
    CHECK(r);
    for (uint32_t i = 0; i < n; i++) r[i] = s.bricks[(n - 1 - i + n / 3) % n];
    for (uint32_t i = 0; i < 10; i++) {
        r[n + i] = r[i];
        r[n + i].error = 1.0f;
    }
    hostmap t = s;
    t.bricks = r;
    t.n_bricks = n + 10;
    CHECK_OK(export_mesh(&t, NULL, &b, &sb));
    CHECK_OK(export_points(&t, &pb, NULL));
    CHECK_EQ_INT(sb.n_duplicates, 10);
    CHECK_EQ_INT(sb.n_bricks, sa.n_bricks);
    CHECK(meshes_equal(&a, &b));
    /* One thread and three threads: the same bytes. */
    mesh_data c1, c3;
    const char *env = getenv("BITFUSE_THREADS");
    char *saved = env ? strdup(env) : NULL;
    setenv("BITFUSE_THREADS", "1", 1);
    CHECK_OK(export_mesh(&t, NULL, &c1, NULL));
    setenv("BITFUSE_THREADS", "3", 1);
    CHECK_OK(export_mesh(&t, NULL, &c3, NULL));
    if (saved)
        setenv("BITFUSE_THREADS", saved, 1);
    else
        unsetenv("BITFUSE_THREADS");
    free(saved);
    CHECK(meshes_equal(&a, &c1) && meshes_equal(&a, &c3));
    mesh_free(&c1), mesh_free(&c3);
    CHECK(pa.n_verts == pb.n_verts && !memcmp(pa.xyz, pb.xyz, (size_t)pa.n_verts * 12) &&
          !memcmp(pa.normal, pb.normal, (size_t)pa.n_verts * 12));
    mesh_free(&a), mesh_free(&b), mesh_free(&pa), mesh_free(&pb);
    free(r);
    fx_free(&s);
}

BF_TEST(max_level_meshes_fine_data_on_a_coarser_lattice)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    sp.r = 0.15;
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    /* The band must reach past the surface by a lattice voxel (2 data
     * voxels) wherever it is, or cells at its rim have unknown corners. */
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 4, NULL, NULL, true);
    export_mesh_config c = export_mesh_config_default();
    c.max_level = 6;
    mesh_data m;
    export_stats st;
    CHECK_OK(export_mesh(&s, &c, &m, &st));
    CHECK_EQ_INT(st.level_out, 6);
    fx_topology topo;
    fx_mesh_topology(&m, &topo);
    CHECK_EQ_INT(topo.n_boundary, 0);
    CHECK_EQ_INT(topo.n_nonmanifold, 0);
    double v = fx_voxel_m(&s, 6);
    fx_accuracy acc;
    fx_mesh_accuracy(&m, fx_sphere_sdf, &sp, v, &acc);
    print_acc("level-7 sphere on a level-6 lattice", &acc, v, &st);
    CHECK_LE(acc.vert_median, 0.25 * v);
    CHECK_LE(acc.vert_max, 1.0 * v);
    mesh_free(&m);
    fx_free(&s);
}

BF_TEST(exported_mesh_survives_a_ply_round_trip)
{
    hostmap s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    sp.r = 0.1;
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, NULL, NULL, true);
    mesh_data m, back;
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    char path[512];
    snprintf(path, sizeof path, "%s/export_mesh.ply", bf_test_tmpdir());
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &back));
    CHECK(back.normal != NULL);
    CHECK(meshes_equal(&m, &back));
    mesh_free(&back);
    mesh_free(&m);
    CHECK_OK(export_points(&s, &m, NULL));
    snprintf(path, sizeof path, "%s/export_points.ply", bf_test_tmpdir());
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &back));
    CHECK(back.n_tris == 0 && back.n_verts == m.n_verts && !memcmp(back.xyz, m.xyz, (size_t)m.n_verts * 12));
    mesh_free(&back);
    mesh_free(&m);
    fx_free(&s);
}
