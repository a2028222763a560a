/* stream: mesh export from CPU-built snapshots of analytic shapes. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "test.h"

/* World placement: the origin is off the world origin and the shapes sit
 * around it, so chunk keys -1 and 0 both occur on every axis. */
static const bf_vec3 ORIGIN = {0.5, -0.25, 1.0};

static void snap_init(fusion_snapshot *s)
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

__attribute__((unused)) static bool pick_x_below(const void *ctx, bf_vec3 c) { return c.x < *(const double *)ctx; }
__attribute__((unused)) static bool pick_x_above(const void *ctx, bf_vec3 c) { return c.x >= *(const double *)ctx; }

static void print_acc(const char *what, const fx_accuracy *a, double v, const stream_export_stats *st)
{
    printf("  %s: voxel %.2f mm, vertices median %.3f max %.3f vox, area median %.3f p99 %.3f max %.3f vox, "
           "%llu tris %llu verts, %.3f s\n",
           what, v * 1e3, a->vert_median / v, a->vert_max / v, a->area_median / v, a->area_p99 / v, a->area_max / v,
           (unsigned long long)st->n_triangles, (unsigned long long)st->n_vertices, st->seconds);
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
    fusion_snapshot s;
    snap_init(&s);
    fx_sphere sp = test_sphere();
    bf_vec3 lo, hi;
    sphere_bounds(&sp, &lo, &hi);
    fx_voxelize(&s, fx_sphere_sdf, &sp, level, lo, hi, 2, NULL, NULL, true);
    eval_mesh m;
    stream_export_stats st;
    CHECK_OK(stream_export_mesh(&s, NULL, &m, &st));
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
    eval_mesh_free(&m);
    fx_free(&s);
}

BF_TEST(sphere_level6_is_closed_outward_and_within_a_voxel) { check_sphere_level(6); }
BF_TEST(sphere_level7_is_closed_outward_and_within_a_voxel) { check_sphere_level(7); }
