/* stream: point export (surface voxel centres with normals). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "test.h"

static const bf_vec3 ORIGIN = {-0.75, 0.25, -1.0};

static bool pick_x_below(const void *ctx, bf_vec3 c) { return c.x < *(const double *)ctx; }
static bool pick_x_above(const void *ctx, bf_vec3 c) { return c.x >= *(const double *)ctx; }

/* Distance bound: a surface voxel's centre c and its 6-neighbour c' of the
 * other sign lie on both sides of the surface, |c - c'| = v, and the signed
 * distance is 1-Lipschitz, so |d(c)| <= v: 1 voxel, not 0.5 sqrt(3) (a
 * face parallel to the lattice at 0.9 v from the inside centres makes the
 * inside ones surface voxels at 0.9 v). On average the surface sits halfway:
 * median <= 0.5 voxel (about 0.3 for a smooth shape).
 * Normal bound: the gradient of a 3x3x3 box mean by central differences is
 * a 5-voxel-wide derivative filter; on a sphere of 51+ voxels radius its
 * direction follows the normal to within a few degrees plus the lattice's
 * anisotropy; 20 degrees leaves room for the staircase. */
static void check_points(hostmap *s, const fx_sphere *sp, double v_worst, const char *what)
{
    mesh_data p;
    export_stats st;
    CHECK_OK(export_points(s, &p, &st));
    CHECK(p.n_verts > 0 && p.normal && p.n_tris == 0);
    CHECK_EQ_INT(st.n_points, p.n_verts);
    double *d = malloc(p.n_verts * sizeof *d);
    CHECK(d);
    double max_angle = 0;
    uint32_t n_over_20 = 0;
    for (uint32_t i = 0; i < p.n_verts; i++) {
        bf_vec3 x = bf_v3(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2]);
        d[i] = fabs(fx_sphere_sdf(sp, x));
        bf_vec3 n = bf_v3(p.normal[3 * i], p.normal[3 * i + 1], p.normal[3 * i + 2]);
        double c = bf_v3_dot(n, bf_v3_normalize(bf_v3_sub(x, sp->c)));
        double ang = acos(fmax(-1, fmin(1, c))) * 180 / M_PI;
        max_angle = fmax(max_angle, ang);
        n_over_20 += ang > 20;
    }
    double dmax = 0, dsum = 0;
    uint32_t n_beyond_half_diag = 0;
    for (uint32_t i = 0; i < p.n_verts; i++) {
        dmax = fmax(dmax, d[i]), dsum += d[i];
        n_beyond_half_diag += d[i] > 0.5 * sqrt(3) * v_worst;
    }
    printf("  %s: %u points, mean distance %.3f max %.3f voxels (%.2f %% beyond 0.5 sqrt(3)), normals max %.1f deg, "
           "%.3f s\n",
           what, p.n_verts, dsum / p.n_verts / v_worst, dmax / v_worst, 100.0 * n_beyond_half_diag / p.n_verts,
           max_angle, st.seconds);
    CHECK_LE(dmax, v_worst * (1 + 1e-6));
    CHECK_LE(dsum / p.n_verts, 0.5 * v_worst);
    CHECK_EQ_INT(n_over_20, 0);
    free(d);
    mesh_free(&p);
}

BF_TEST(sphere_surface_points_lie_within_a_voxel_with_normals_within_20_degrees)
{
    hostmap s;
    memset(&s, 0, sizeof s);
    s.chunk_m = 2;
    s.origin_w = ORIGIN;
    fx_sphere sp = {bf_v3(ORIGIN.x - 0.0123, ORIGIN.y + 0.0171, ORIGIN.z + 0.0029), 0.2};
    bf_vec3 lo = bf_v3(sp.c.x - 0.25, sp.c.y - 0.25, sp.c.z - 0.25), hi = bf_v3(sp.c.x + 0.25, sp.c.y + 0.25, sp.c.z + 0.25);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, NULL, NULL, true);
    check_points(&s, &sp, fx_voxel_m(&s, 7), "sphere level 7");
    fx_free(&s);
}

BF_TEST(surface_points_across_a_level_transition)
{
    hostmap s;
    memset(&s, 0, sizeof s);
    s.chunk_m = 2;
    s.origin_w = ORIGIN;
    fx_sphere sp = {bf_v3(ORIGIN.x - 0.0123, ORIGIN.y + 0.0171, ORIGIN.z + 0.0029), 0.2};
    bf_vec3 lo = bf_v3(sp.c.x - 0.25, sp.c.y - 0.25, sp.c.z - 0.25), hi = bf_v3(sp.c.x + 0.25, sp.c.y + 0.25, sp.c.z + 0.25);
    double split = ORIGIN.x;
    /* Level 6 everywhere, level 7 over half: level-6 voxels under the
     * confident level-7 half are overridden and give no points. */
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, NULL, NULL, true);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, pick_x_above, &split, true);
    check_points(&s, &sp, fx_voxel_m(&s, 6), "sphere level 6 + half 7");
    mesh_data p;
    export_stats st;
    CHECK_OK(export_points(&s, &p, &st));
    CHECK(st.points_per_level[6] > 0 && st.points_per_level[7] > 0);
    /* Points spaced like level 6 on the left, like level 7 on the right:
     * the right half has about 4 times the points per area. */
    uint32_t left = 0, right = 0;
    for (uint32_t i = 0; i < p.n_verts; i++) *(p.xyz[3 * i] < split ? &left : &right) += 1;
    printf("  left %u right %u\n", left, right);
    CHECK(right > 3 * left && right < 5 * left);
    mesh_free(&p);
    fx_free(&s);
    (void)pick_x_below;
}

/* A point whose voxel has no colour takes the mean of the coloured voxels
 * around it at its level, within two voxels (3x3x3, else 5x5x5), and is
 * grey (160) past that: a plane whose voxels are red up to x index c. */
BF_TEST(uncoloured_points_borrow_colour_from_two_voxels_away_and_no_further)
{
    hostmap s;
    memset(&s, 0, sizeof s);
    s.chunk_m = 2;
    s.origin_w = ORIGIN;
    fx_plane pl = {bf_v3(0, 0, 1), ORIGIN.z + 0.3013};
    double v = fx_voxel_m(&s, 6);
    fx_voxelize(&s, fx_plane_sdf, &pl, 6, bf_v3(ORIGIN.x, ORIGIN.y, ORIGIN.z + 0.25),
                bf_v3(ORIGIN.x + 0.2, ORIGIN.y + 0.1, ORIGIN.z + 0.35), 2, NULL, NULL, true);
    s.rgb565 = calloc((size_t)s.n_bricks * 512, 2);
    CHECK(s.rgb565 != NULL);
    const int64_t c = 20; /* voxels with global x index <= c are red */
    int64_t per_chunk = 1 << 6;
    for (uint32_t i = 0; i < s.n_bricks; i++)
        for (uint32_t x = 0; x < 8; x++) {
            int64_t gx = ((int64_t)s.bricks[i].key[0] * per_chunk + s.bricks[i].cell[0]) * 8 + x;
            if (gx > c) continue;
            for (uint32_t z = 0; z < 8; z++)
                for (uint32_t y = 0; y < 8; y++) s.rgb565[(size_t)i * 512 + x + 8 * y + 64 * z] = 0xF800;
        }
    mesh_data p;
    CHECK_OK(export_points(&s, &p, NULL));
    CHECK(p.rgb != NULL);
    uint32_t n_at[5] = {0, 0, 0, 0, 0}, wrong = 0;
    for (uint32_t i = 0; i < p.n_verts; i++) {
        int64_t gx = (int64_t)floor(((double)p.xyz[3 * i] + p.origin.x - ORIGIN.x) / v);
        int64_t d = gx - c; /* voxels past the last red one */
        const uint8_t *rgb = p.rgb + 3 * i;
        bool red = rgb[0] == 255 && rgb[1] == 0 && rgb[2] == 0, grey = rgb[0] == 160 && rgb[1] == 160 && rgb[2] == 160;
        if (d >= 1 && d <= 4) n_at[d]++;
        if (d <= 2 ? !red : !grey) wrong++;
    }
    fprintf(stderr, "  %u points; 1, 2, 3, 4 voxels past the red: %u, %u, %u, %u; %u wrong\n", p.n_verts, n_at[1],
            n_at[2], n_at[3], n_at[4], wrong);
    CHECK(n_at[1] > 0 && n_at[2] > 0 && n_at[3] > 0);
    CHECK_EQ_INT(wrong, 0);
    mesh_free(&p);
    free(s.rgb565);
    s.rgb565 = NULL;
    fx_free(&s);
}
