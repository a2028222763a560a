/* export: a map far from the world origin exports as precisely as at the
 * origin (local origin), and exported meshes simplified to a triangle cap
 * or an error bound stay near the full mesh. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "shaders/bf_common.glsl.h"
#include "test.h"

/* The map of test_export_mesh: chunk keys -1 and 0 around its origin. */
static const bf_vec3 ORIGIN = {0.5, -0.25, 1.0};

static void sphere_map(hostmap *s, double r, uint32_t level, const int32_t key_shift[3], bf_vec3 origin_w)
{
    memset(s, 0, sizeof *s);
    s->chunk_m = 2.0f;
    s->origin_w = origin_w;
    fx_sphere sp = {bf_v3(origin_w.x + 0.0137, origin_w.y - 0.0211, origin_w.z + 0.0093), r};
    double e = r + 0.05;
    bf_vec3 lo = bf_v3(sp.c.x - e, sp.c.y - e, sp.c.z - e), hi = bf_v3(sp.c.x + e, sp.c.y + e, sp.c.z + e);
    fx_voxelize(s, fx_sphere_sdf, &sp, level, lo, hi, 2, NULL, NULL, true);
    for (uint32_t i = 0; i < s->n_bricks; i++)
        for (int a = 0; a < 3; a++) s->bricks[i].key[a] += key_shift[a];
}

/* The largest distance between far's world points and near's moved by d,
 * vertex by vertex (the export's order depends only on the bricks' relative
 * places, so it is the same); *float_err gets what plain world floats of
 * the far points would have been off by. */
static double far_vs_near(const mesh_data *far, const mesh_data *near, bf_vec3 d, double *float_err)
{
    double e = 0, fe = 0;
    for (uint32_t i = 0; i < far->n_verts; i++) {
        const double o[3] = {far->origin.x, far->origin.y, far->origin.z}, dd[3] = {d.x, d.y, d.z};
        for (int a = 0; a < 3; a++) {
            double w_far = o[a] + far->xyz[3 * i + a], w_near = (double)near->xyz[3 * i + a] + dd[a];
            e = fmax(e, fabs(w_far - w_near));
            fe = fmax(fe, fabs((double)(float)w_far - w_near));
        }
    }
    *float_err = fe;
    return e;
}

/* Requirement: 10 km out, every vertex within 1e-4 m of the same map at
 * the origin moved there. Derivation: positions are computed in double
 * (exact to 1e-12 m here) and rounded once to a float relative to a local
 * origin within the map's extent (|local| < 1 m: step 1.2e-7 m), so the
 * difference is a few 1e-7 m; plain world floats at 10 km have steps of
 * 0.98 mm and would miss the bound (checked, so the test can fail). */
BF_TEST(map_10_km_out_exports_within_0_1_mm_of_the_same_map_at_the_origin)
{
    static const int32_t none[3] = {0, 0, 0}, far_keys[3] = {5000, -3000, 2500};
    /* The far map's world offset: chunk keys and origin_w both moved, the
     * latter by amounts no float holds exactly. */
    bf_vec3 far_origin = bf_v3(ORIGIN.x + 0.3, ORIGIN.y - 0.1, ORIGIN.z + 0.07);
    bf_vec3 d = bf_v3(far_keys[0] * 2.0 + 0.3, far_keys[1] * 2.0 - 0.1, far_keys[2] * 2.0 + 0.07);
    hostmap near, far;
    sphere_map(&near, 0.1, 6, none, ORIGIN);
    sphere_map(&far, 0.1, 6, far_keys, far_origin);
    CHECK(export_local_origin(&near).x == 0 && export_local_origin(&near).y == 0 && export_local_origin(&near).z == 0);
    mesh_data mn, mf, back;
    for (int pass = 0; pass < 2; pass++) {
        const char *what = pass ? "points" : "mesh";
        if (pass == 0) {
            CHECK_OK(export_mesh(&near, NULL, &mn, NULL));
            CHECK_OK(export_mesh(&far, NULL, &mf, NULL));
        } else {
            CHECK_OK(export_points(&near, &mn, NULL));
            CHECK_OK(export_points(&far, &mf, NULL));
        }
        CHECK(mn.origin.x == 0 && mn.origin.y == 0 && mn.origin.z == 0);
        CHECK(fabs(mf.origin.x - 10000) < 2 && fabs(mf.origin.y + 6000) < 2 && fabs(mf.origin.z - 5000) < 2);
        CHECK_EQ_INT(mf.n_verts, mn.n_verts);
        CHECK_EQ_INT(mf.n_tris, mn.n_tris);
        CHECK(mn.n_verts > 1000);
        double float_err, err = far_vs_near(&mf, &mn, d, &float_err);
        printf("  %s 10 km out: %u vertices within %.3g m of the map at the origin (world floats: %.3g m)\n", what,
               mf.n_verts, err, float_err);
        CHECK_LE(err, 1e-4);
        CHECK(float_err > 1e-4);
        /* Through a file: the PLY records the origin and reads back. */
        char path[512];
        snprintf(path, sizeof path, "%s/far_%s.ply", bf_test_tmpdir(), what);
        CHECK_OK(mesh_write_ply(path, &mf));
        CHECK_OK(mesh_read_ply(path, &back));
        CHECK(back.origin.x == mf.origin.x && back.origin.y == mf.origin.y && back.origin.z == mf.origin.z);
        CHECK_LE(far_vs_near(&back, &mn, d, &float_err), 1e-4);
        mesh_free(&back);
        mesh_free(&mn);
        mesh_free(&mf);
    }
    fx_free(&near);
    fx_free(&far);
}

/* The surface error of a simplified export against the full one
 * (eval_surface: area samples of the simplified mesh to the full mesh). */
static void error_vs_full(const mesh_data *full, const mesh_data *simple, eval_surface_result *r)
{
    eval_surface_config ec = eval_surface_config_default();
    BF_ASSERT(eval_surface(full, simple, NULL, &ec, r) == BF_OK);
}

/* A level-6 sphere of r = 0.3 m (3.9 mm voxels, 222 k triangles) cut to
 * 20,000 triangles. Derivation of the bounds: an equilateral
 * tessellation of the sphere into N triangles has edge
 * a = sqrt(4 (4 pi r^2 / N) / sqrt 3) = 11.4 mm and chord error
 * a^2 / (6 r) = 0.073 mm; meshoptimizer's triangles are not equilateral
 * and the full mesh is not a sphere (its own bumps, up to 0.4 voxel, are
 * what the quadrics see), so: area samples of the simplified mesh within
 * 0.1 voxel (0.39 mm, 5x the chord) of the full mesh at the median and
 * within its quadric estimate plus the chord at 90 percent, and the
 * simplified mesh as close to the true sphere as the full one (median
 * within 0.05 voxel more). */
BF_TEST(export_simplified_to_a_cap_stays_near_the_full_mesh)
{
    static const int32_t none[3] = {0, 0, 0};
    hostmap s;
    sphere_map(&s, 0.3, 6, none, ORIGIN);
    double v = fx_voxel_m(&s, 6);
    mesh_data full, m;
    CHECK_OK(export_mesh(&s, NULL, &full, NULL));
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    mesh_simplify_config cfg = {.max_triangles = 20000};
    mesh_simplify_stats st;
    CHECK_OK(mesh_simplify(&m, &cfg, &st));
    CHECK_LE(m.n_tris, 20000);
    CHECK(m.n_tris > 15000);
    CHECK(m.normal && !m.rgb);
    fx_topology topo;
    fx_mesh_topology(&m, &topo);
    eval_surface_result r;
    error_vs_full(&full, &m, &r);
    fx_sphere sp = {bf_v3(ORIGIN.x + 0.0137, ORIGIN.y - 0.0211, ORIGIN.z + 0.0093), 0.3};
    fx_accuracy af, as;
    fx_mesh_accuracy(&full, fx_sphere_sdf, &sp, v, &af);
    fx_mesh_accuracy(&m, fx_sphere_sdf, &sp, v, &as);
    double a = sqrt(4 * (4 * M_PI * 0.09 / 20000) / sqrt(3.0)), chord = a * a / (6 * 0.3);
    printf("  sphere 0.3 m level 6: %llu -> %u triangles in %.2f s (%s), estimate %.3f mm; vs full: median %.3f "
           "p90 %.3f max %.3f mm; vs sphere: area median %.3f (full %.3f) max %.3f (full %.3f) mm; open edges %llu\n",
           (unsigned long long)st.tris_before, m.n_tris, st.seconds, st.used_sloppy ? "sloppy" : "collapses",
           1e3 * st.error_m, 1e3 * r.accuracy.median, 1e3 * r.accuracy.p90, 1e3 * r.accuracy.max, 1e3 * as.area_median,
           1e3 * af.area_median, 1e3 * as.area_max, 1e3 * af.area_max, (unsigned long long)topo.n_boundary);
    CHECK(!st.used_sloppy);
    CHECK_EQ_INT(topo.n_boundary, 0); /* the collapses keep a closed mesh closed */
    CHECK_LE(r.accuracy.median, 0.1 * v);
    CHECK_LE(r.accuracy.p90, st.error_m + chord);
    CHECK_LE(as.area_median, af.area_median + 0.05 * v);
    mesh_free(&m);

    /* An error bound of a quarter voxel instead: meshoptimizer's estimate
     * stays within it, and so does the measured p90 (plus the chord of the
     * triangles it leaves, bounded by the cap case's). */
    CHECK_OK(export_mesh(&s, NULL, &m, NULL));
    cfg = (mesh_simplify_config){.max_error_m = 0.25 * v};
    CHECK_OK(mesh_simplify(&m, &cfg, &st));
    error_vs_full(&full, &m, &r);
    printf("  error bound %.3f mm: %llu -> %u triangles, estimate %.3f mm; vs full: median %.3f p90 %.3f max %.3f mm\n",
           0.25 * v * 1e3, (unsigned long long)st.tris_before, m.n_tris, 1e3 * st.error_m, 1e3 * r.accuracy.median,
           1e3 * r.accuracy.p90, 1e3 * r.accuracy.max);
    CHECK_LE(st.error_m, 0.25 * v);
    CHECK_LE(r.accuracy.p90, 0.25 * v + chord);
    CHECK_LE(m.n_tris, full.n_tris / 4);
    mesh_free(&m);
    mesh_free(&full);
    fx_free(&s);
}

static int cmp_xyz(const void *a, const void *b)
{
    const float *x = a, *y = b;
    for (int k = 0; k < 3; k++)
        if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return 0;
}

/* Vertices are welded by lattice edge whatever the weld table's size.
 * Isolated inside voxels in free space (at odd coordinates, so no cell
 * holds two) each give 8 triangles around 6 vertices, more vertices per
 * triangle than a surface has (1 per 2): 1575 of them make the table (first
 * size: the smallest power of two >= corners / 3) pass half full and grow.
 * Without smoothing a vertex's position is a function of its lattice edge,
 * so two vertices at one place would be a missed weld. */
BF_TEST(weld_table_grows_and_still_welds_every_edge_once)
{
    hostmap s;
    memset(&s, 0, sizeof s);
    s.chunk_m = 2.0f;
    s.n_bricks = 32; /* 4 x 4 x 2 bricks of level 4: 32 x 32 x 16 voxels */
    s.bricks = calloc(s.n_bricks, sizeof *s.bricks);
    BF_ASSERT(s.bricks);
    for (uint32_t i = 0; i < s.n_bricks; i++) {
        hostmap_brick *b = &s.bricks[i];
        b->level = 4;
        b->cell[0] = i & 3, b->cell[1] = (i >> 2) & 3, b->cell[2] = i >> 4;
        for (uint32_t z = 0; z < 8; z++)
            for (uint32_t y = 0; y < 8; y++)
                for (uint32_t x = 0; x < 8; x++) {
                    uint32_t g[3] = {b->cell[0] * 8 + x, b->cell[1] * 8 + y, b->cell[2] * 8 + z};
                    bool is_inside = g[0] % 2 && g[1] % 2 && g[2] % 2 && g[0] < 31 && g[1] < 31 && g[2] < 15;
                    uint32_t w = brick_word(x, y, z), bit = 1u << brick_bit(x, y, z);
                    if (!is_inside) b->sign[w] |= bit;
                    b->conf[w] |= bit;
                }
    }
    export_mesh_config cfg = export_mesh_config_default();
    cfg.taubin_iterations = 0;
    mesh_data m;
    CHECK_OK(export_mesh(&s, &cfg, &m, NULL));
    uint64_t cap0 = 16;
    uint64_t n_corners = 3ull * m.n_tris;
    while (cap0 < n_corners / 3) cap0 <<= 1;
    printf("  isolated voxels: %u triangles, %u vertices (first table %llu slots)\n", m.n_tris, m.n_verts,
           (unsigned long long)cap0);
    CHECK(2ull * m.n_verts > cap0); /* the table grew */
    /* No two vertices at one place: sort positions and compare neighbours. */
    float (*p)[3] = malloc(sizeof *p * m.n_verts);
    memcpy(p, m.xyz, sizeof *p * m.n_verts);
    qsort(p, m.n_verts, sizeof *p, cmp_xyz);
    for (uint32_t i = 1; i < m.n_verts; i++) CHECK(memcmp(p[i], p[i - 1], sizeof *p) != 0);
    free(p);
    mesh_free(&m);
    fx_free(&s);
}
