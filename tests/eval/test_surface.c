/* eval: surface error (accuracy, completeness), area sampling, kd-tree. */
#include <stdint.h>

#include "eval/eval.h"
#include "mesh/mesh.h"
#include "eval/eval_int.h"
#include "test.h"

/* ------------------------------------------------------------ helpers */

static unsigned rnd_state = 12345;
static double rnd(void)
{
    rnd_state ^= rnd_state << 13;
    rnd_state ^= rnd_state >> 17;
    rnd_state ^= rnd_state << 5;
    return (double)rnd_state / 4294967296.0;
}

static mesh_data mesh_alloc(uint32_t n_verts, uint32_t n_tris)
{
    mesh_data m = {0};
    m.n_verts = n_verts;
    m.n_tris = n_tris;
    m.xyz = malloc((n_verts ? n_verts : 1) * 3 * sizeof(float));
    m.tri = n_tris ? malloc(n_tris * 3 * sizeof(uint32_t)) : NULL;
    BF_ASSERT(m.xyz && (m.tri || !n_tris));
    return m;
}

static void set_v(mesh_data *m, uint32_t i, double x, double y, double z)
{
    m->xyz[3 * i] = (float)x;
    m->xyz[3 * i + 1] = (float)y;
    m->xyz[3 * i + 2] = (float)z;
}

static void set_t(mesh_data *m, uint32_t i, uint32_t a, uint32_t b, uint32_t c)
{
    m->tri[3 * i] = a;
    m->tri[3 * i + 1] = b;
    m->tri[3 * i + 2] = c;
}

/* An axis-aligned box [0,sx] x [0,sy] x [0,sz] as 12 triangles. */
static mesh_data make_box(double sx, double sy, double sz)
{
    mesh_data m = mesh_alloc(8, 12);
    for (uint32_t i = 0; i < 8; i++) set_v(&m, i, (i & 1) * sx, (i >> 1 & 1) * sy, (i >> 2 & 1) * sz);
    static const uint32_t f[6][4] = {{0, 1, 3, 2}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                     {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 3, 7, 5}};
    for (uint32_t k = 0; k < 6; k++) {
        set_t(&m, 2 * k, f[k][0], f[k][1], f[k][2]);
        set_t(&m, 2 * k + 1, f[k][0], f[k][2], f[k][3]);
    }
    return m;
}

/* A latitude-longitude sphere of radius r: poles, n_lat - 1 rings (n_lat
 * even, so one ring is the equator z = 0), n_lon vertices per ring. */
static mesh_data make_uv_sphere(double r, uint32_t n_lat, uint32_t n_lon)
{
    uint32_t n_rings = n_lat - 1;
    mesh_data m = mesh_alloc(2 + n_rings * n_lon, 2 * n_lon * n_rings);
    set_v(&m, 0, 0, 0, r);
    set_v(&m, 1, 0, 0, -r);
    for (uint32_t i = 0; i < n_rings; i++) {
        double th = M_PI * (i + 1) / n_lat;
        /* The equator exactly at z = 0 (cos(pi/2) is 6e-17, not 0). */
        double z = 2 * (i + 1) == n_lat ? 0 : r * cos(th);
        for (uint32_t j = 0; j < n_lon; j++) {
            double ph = 2 * M_PI * j / n_lon;
            set_v(&m, 2 + i * n_lon + j, r * sin(th) * cos(ph), r * sin(th) * sin(ph), z);
        }
    }
    uint32_t t = 0;
    for (uint32_t j = 0; j < n_lon; j++) {
        uint32_t j1 = (j + 1) % n_lon;
        set_t(&m, t++, 0, 2 + j, 2 + j1);
        set_t(&m, t++, 1, 2 + (n_rings - 1) * n_lon + j1, 2 + (n_rings - 1) * n_lon + j);
        for (uint32_t i = 0; i + 1 < n_rings; i++) {
            uint32_t a = 2 + i * n_lon + j, b = 2 + i * n_lon + j1, c = a + n_lon, d = b + n_lon;
            set_t(&m, t++, a, c, d);
            set_t(&m, t++, a, d, b);
        }
    }
    BF_ASSERT(t == m.n_tris);
    return m;
}

/* The triangles of m whose vertices all satisfy sign * z >= 0, with only
 * the vertices they use. */
static mesh_data mesh_half(const mesh_data *m, int sign)
{
    uint32_t *map = malloc(m->n_verts * sizeof *map);
    uint32_t nv = 0, nt = 0;
    for (uint32_t v = 0; v < m->n_verts; v++) map[v] = UINT32_MAX;
    for (uint32_t t = 0; t < m->n_tris; t++) {
        bool keep = true;
        for (int k = 0; k < 3; k++) keep = keep && sign * m->xyz[3 * m->tri[3 * t + k] + 2] >= 0;
        if (!keep) continue;
        nt++;
        for (int k = 0; k < 3; k++)
            if (map[m->tri[3 * t + k]] == UINT32_MAX) map[m->tri[3 * t + k]] = nv++;
    }
    mesh_data h = mesh_alloc(nv, nt);
    for (uint32_t v = 0; v < m->n_verts; v++)
        if (map[v] != UINT32_MAX) memcpy(&h.xyz[3 * map[v]], &m->xyz[3 * v], 3 * sizeof(float));
    nt = 0;
    for (uint32_t t = 0; t < m->n_tris; t++) {
        bool keep = true;
        for (int k = 0; k < 3; k++) keep = keep && sign * m->xyz[3 * m->tri[3 * t + k] + 2] >= 0;
        if (keep) set_t(&h, nt++, map[m->tri[3 * t]], map[m->tri[3 * t + 1]], map[m->tri[3 * t + 2]]);
    }
    free(map);
    return h;
}

static bf_vec3 vtx(const mesh_data *m, uint32_t v)
{
    return bf_v3(m->xyz[3 * (size_t)v], m->xyz[3 * (size_t)v + 1], m->xyz[3 * (size_t)v + 2]);
}

static bf_vec3 face_normal(const mesh_data *m, uint32_t t)
{
    bf_vec3 a = vtx(m, m->tri[3 * t]), b = vtx(m, m->tri[3 * t + 1]), c = vtx(m, m->tri[3 * t + 2]);
    return bf_v3_normalize(bf_v3_cross(bf_v3_sub(b, a), bf_v3_sub(c, a)));
}

/* A point cloud: area samples of m moved by d along their face normal,
 * pointing away from centre (for the convex test meshes: outward). */
static mesh_data displaced_samples(const mesh_data *m, double density, double d, bf_vec3 centre, uint64_t seed)
{
    float *xyz;
    uint32_t *tri;
    size_t n;
    BF_ASSERT(eval_mesh_sample_area(m, density, 10000000, seed, &xyz, &tri, &n) == BF_OK);
    mesh_data pc = mesh_alloc((uint32_t)n, 0);
    for (size_t i = 0; i < n; i++) {
        bf_vec3 p = bf_v3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
        bf_vec3 nrm = face_normal(m, tri[i]);
        if (bf_v3_dot(nrm, bf_v3_sub(p, centre)) < 0) nrm = bf_v3_scale(nrm, -1);
        bf_vec3 q = bf_v3_add(p, bf_v3_scale(nrm, d));
        set_v(&pc, (uint32_t)i, q.x, q.y, q.z);
    }
    free(xyz);
    free(tri);
    return pc;
}

/* ------------------------------------------------------------ kd-tree */

BF_TEST(kdtree_nearest_matches_brute_force)
{
    /* Random points, a block of duplicates and a plane of equal z: the cases
     * that break naive median splits. */
    const size_t n = 5000;
    float *xyz = malloc(n * 3 * sizeof *xyz);
    for (size_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) xyz[3 * i + k] = (float)(rnd() * 2 - 1);
        if (i % 5 == 0) xyz[3 * i + 2] = 0.25f;
        if (i % 7 == 0) memcpy(&xyz[3 * i], &xyz[0], 3 * sizeof(float));
    }
    eval_kdtree *kd;
    CHECK_OK(eval__kdtree_build(xyz, n, &kd));
    for (int q = 0; q < 2000; q++) {
        bf_vec3 p = bf_v3(rnd() * 3 - 1.5, rnd() * 3 - 1.5, rnd() * 3 - 1.5);
        /* Every fourth query far outside the cloud, where the pruning bound
         * sums the distances over several axes (corners of the cloud's box). */
        if (q % 4 == 0) p = bf_v3_scale(p, 4);
        double best = INFINITY;
        for (size_t i = 0; i < n; i++) {
            double dx = xyz[3 * i] - p.x, dy = xyz[3 * i + 1] - p.y, dz = xyz[3 * i + 2] - p.z;
            best = fmin(best, sqrt(dx * dx + dy * dy + dz * dz));
        }
        size_t idx = SIZE_MAX;
        double d = eval__kdtree_nearest(kd, p, INFINITY, &idx);
        if (d != best) eval__kdtree_destroy(kd);
        CHECK_NEAR(d, best, 0);
        double dx = xyz[3 * idx] - p.x, dy = xyz[3 * idx + 1] - p.y, dz = xyz[3 * idx + 2] - p.z;
        CHECK_NEAR(sqrt(dx * dx + dy * dy + dz * dz), best, 0);
        /* A search radius below the answer finds nothing; at it (plus the
         * rounding of sqrt and squaring), finds it. */
        CHECK(eval__kdtree_nearest(kd, p, best * 0.999, NULL) == INFINITY);
        CHECK_NEAR(eval__kdtree_nearest(kd, p, best * (1 + 1e-12), NULL), best, 0);
    }
    eval__kdtree_destroy(kd);
    /* Empty tree: no neighbour. */
    CHECK_OK(eval__kdtree_build(xyz, 0, &kd));
    CHECK(eval__kdtree_nearest(kd, bf_v3(0, 0, 0), INFINITY, NULL) == INFINITY);
    eval__kdtree_destroy(kd);
    free(xyz);
}

/* ------------------------------------------------------------ sampling */

BF_TEST(area_sampling_is_uniform_by_area_and_deterministic)
{
    /* Two separate triangles of area 1 and 3 (m^2). */
    mesh_data m = mesh_alloc(6, 2);
    set_v(&m, 0, 0, 0, 0);
    set_v(&m, 1, 2, 0, 0);
    set_v(&m, 2, 0, 1, 0);
    set_v(&m, 3, 0, 0, 5);
    set_v(&m, 4, 3, 0, 5);
    set_v(&m, 5, 0, 2, 5);
    set_t(&m, 0, 0, 1, 2);
    set_t(&m, 1, 3, 4, 5);
    float *a, *b;
    uint32_t *ta;
    size_t na, nb;
    CHECK_OK(eval_mesh_sample_area(&m, 10000, 1000000, 7, &a, &ta, &na));
    CHECK_EQ_INT(na, 40000); /* round(4 m^2 * 10^4 / m^2) */
    size_t in_big = 0;
    double sx = 0;
    for (size_t i = 0; i < na; i++) {
        in_big += ta[i] == 1;
        CHECK((ta[i] == 1) == (a[3 * i + 2] == 5.0f));
        if (ta[i] == 0) sx += a[3 * i];
    }
    /* Binomial: p = 3/4, sigma = sqrt(p (1 - p) / n) = 0.0022; 5 sigma. */
    CHECK_NEAR((double)in_big / na, 0.75, 5 * sqrt(0.75 * 0.25 / na));
    /* Uniform in the triangle: mean x is the centroid's, 2/3; the x of a
     * uniform point has variance 2/9 here (for vertices 0, 2, 0: (a^2 + b^2 +
     * c^2 - ab - bc - ca) / 18 = 4/18), so 5 sigma of the mean. */
    size_t n_small = na - in_big;
    CHECK_NEAR(sx / n_small, 2.0 / 3, 5 * sqrt(4.0 / 18 / n_small));
    /* Same seed, same samples, whatever the thread count. */
    setenv("BITFUSE_THREADS", "1", 1);
    CHECK_OK(eval_mesh_sample_area(&m, 10000, 1000000, 7, &b, NULL, &nb));
    unsetenv("BITFUSE_THREADS");
    CHECK_EQ_INT(nb, na);
    CHECK(memcmp(a, b, na * 3 * sizeof(float)) == 0);
    free(b);
    CHECK_OK(eval_mesh_sample_area(&m, 10000, 1000000, 8, &b, NULL, &nb));
    CHECK(memcmp(a, b, na * 3 * sizeof(float)) != 0);
    free(b);
    /* The cap. */
    CHECK_OK(eval_mesh_sample_area(&m, 10000, 123, 7, &b, NULL, &nb));
    CHECK_EQ_INT(nb, 123);
    free(b);
    free(a);
    free(ta);
    mesh_free(&m);
}

/* ------------------------------------------------------------ known offsets */

/* Box 0.4 x 0.3 x 0.2 m (0.52 m^2); reconstruction = its area samples moved
 * outward by d = 2 mm along the face normal. The box is convex, so each
 * moved point's closest surface point is where it came from: every
 * accuracy distance is d, up to float rounding of coordinates < 0.5 m
 * (6e-8 m) -> tolerance 1e-6. Completeness: a reference point's nearest
 * reconstruction point is at sqrt(d^2 + rho^2) >= d, rho its distance to the
 * nearest sample along the surface, so a threshold below d gives exactly 0.
 * For threshold t = 10 mm it needs rho <= sqrt(t^2 - d^2) = 9.8 mm: with
 * 2e5 samples per m^2, even a quarter disc at a box corner holds
 * 2e5 * pi * 0.0098^2 / 4 = 15 expected samples, P(none) = e^-15: 100%. */
BF_TEST(surface_box_offset_by_d_gives_accuracy_d_and_sharp_completeness)
{
    const double d = 0.002;
    mesh_data box = make_box(0.4, 0.3, 0.2);
    mesh_data rec = displaced_samples(&box, 2e5, d, bf_v3(0.2, 0.15, 0.1), 99);
    eval_surface_config cfg = eval_surface_config_default();
    cfg.threshold_m = 0.01;
    eval_surface_result r;
    CHECK_OK(eval_surface(&box, &rec, NULL, &cfg, &r));
    CHECK_EQ_INT(r.n_rec_vertices, rec.n_verts);
    CHECK_EQ_INT(r.n_rec_samples, 0);
    CHECK_EQ_INT(r.n_ref_points, 104000); /* 0.52 m^2 * 2e5 */
    CHECK(!r.used_ref_vertices);
    CHECK_NEAR(r.accuracy.median, d, 1e-6);
    CHECK_NEAR(r.accuracy.mean, d, 1e-6);
    CHECK_NEAR(r.accuracy.p90, d, 1e-6);
    CHECK_NEAR(r.accuracy.rmse, d, 1e-6);
    CHECK_NEAR(r.accuracy.max, d, 1e-6);
    CHECK_NEAR(r.precision, 1.0, 0);
    CHECK_NEAR(r.completeness, 1.0, 0);
    CHECK_LE(d - 1e-6, r.completeness_dist.median);
    cfg.threshold_m = 0.001;
    CHECK_OK(eval_surface(&box, &rec, NULL, &cfg, &r));
    CHECK_NEAR(r.completeness, 0.0, 0);
    CHECK_NEAR(r.precision, 0.0, 0);
    mesh_free(&rec);
    mesh_free(&box);
}

/* Meshes with local origins of their own (a scan far from the world
 * origin, mesh_data.origin) are measured in one frame: the same box and
 * samples 2 mm off it, the samples kept relative to an origin 1e7 m away
 * and the box in world coordinates there, or the other way round. */
BF_TEST(surface_of_meshes_with_different_local_origins_is_measured_in_one_frame)
{
    const double d = 0.002;
    mesh_data box = make_box(0.4, 0.3, 0.2);
    mesh_data rec = displaced_samples(&box, 2e4, d, bf_v3(0.2, 0.15, 0.1), 7);
    const bf_vec3 far = bf_v3(1.0e7, -2.0e7, 3.0e6);
    rec.origin = far; /* the samples at far + xyz */
    mesh_data box_far = {0};
    bf_se3 T = bf_se3_identity();
    T.t = far;
    CHECK_OK(mesh_append(&box_far, &box, &T)); /* the box at far, with far as its origin */
    box_far.origin = bf_v3(far.x + 0.5, far.y - 0.25, far.z); /* its vertices shifted to another origin */
    for (uint32_t i = 0; i < box_far.n_verts; i++) box_far.xyz[3 * i] -= 0.5f, box_far.xyz[3 * i + 1] += 0.25f;
    eval_surface_config cfg = eval_surface_config_default();
    eval_surface_result r;
    CHECK_OK(eval_surface(&box_far, &rec, NULL, &cfg, &r));
    CHECK_NEAR(r.accuracy.median, d, 1e-5);
    CHECK_NEAR(r.accuracy.max, d, 1e-5);
    CHECK_OK(eval_surface(&rec, &box_far, NULL, &cfg, &r)); /* the other way: completeness to the points */
    CHECK(r.completeness_dist.n > 0);
    CHECK_LE(r.accuracy.median, 0.02);
    /* A reference in world coordinates (no origin of its own; near enough
     * for float) against the samples kept relative to an origin: the
     * reconstruction's origin is the common frame. */
    const bf_vec3 near = bf_v3(100.0, 200.0, 50.0);
    mesh_data box_world = {0};
    T.t = near;
    CHECK_OK(mesh_append(&box_world, &box, &T));
    for (uint32_t i = 0; i < box_world.n_verts; i++) {
        box_world.xyz[3 * i] += (float)near.x, box_world.xyz[3 * i + 1] += (float)near.y;
        box_world.xyz[3 * i + 2] += (float)near.z;
    }
    box_world.origin = bf_v3(0, 0, 0);
    rec.origin = near;
    CHECK_OK(eval_surface(&box_world, &rec, NULL, &cfg, &r));
    CHECK_NEAR(r.accuracy.median, d, 2e-5);
    mesh_free(&box_world);
    mesh_free(&box_far);
    mesh_free(&rec);
    mesh_free(&box);
}

/* Reference: a unit lat-long sphere mesh (inscribed polyhedron); the
 * reconstruction: 20,000 points of the sphere of radius 1 + d (Fibonacci
 * lattice). Every mesh point lies in the unit ball, so a distance is at
 * least (1 + d) - 1 = d; it is at most (1 + d) - r_in with r_in the smallest
 * distance from the centre to a face plane, computed from the mesh. */
BF_TEST(surface_sphere_offset_by_d_has_median_d_within_the_facet_bound)
{
    const double d = 0.01;
    mesh_data sph = make_uv_sphere(1.0, 64, 128);
    double r_in = 1;
    for (uint32_t t = 0; t < sph.n_tris; t++)
        r_in = fmin(r_in, fabs(bf_v3_dot(face_normal(&sph, t), vtx(&sph, sph.tri[3 * t]))));
    const uint32_t n = 20000;
    mesh_data rec = mesh_alloc(n, 0);
    for (uint32_t i = 0; i < n; i++) {
        double z = 1 - 2 * (i + 0.5) / n, rr = sqrt(1 - z * z), ph = i * M_PI * (3 - sqrt(5.0));
        set_v(&rec, i, (1 + d) * rr * cos(ph), (1 + d) * rr * sin(ph), (1 + d) * z);
    }
    eval_surface_config cfg = eval_surface_config_default();
    cfg.samples_per_m2 = 1e4;
    eval_surface_result r;
    CHECK_OK(eval_surface(&sph, &rec, NULL, &cfg, &r));
    /* 1e-6: float rounding of unit-size coordinates. */
    CHECK_LE(d - 1e-6, r.accuracy.median);
    CHECK_LE(r.accuracy.median, d + (1 - r_in) + 1e-6);
    CHECK_LE(d - 1e-6, r.accuracy.mean);
    CHECK_LE(r.accuracy.max, d + (1 - r_in) + 1e-6);
    mesh_free(&rec);
    mesh_free(&sph);
}

/* The bunny scaled to 0.25 m; reconstruction = area samples moved by
 * d = 1 mm along their face normals. The original point is d away, so every
 * distance is <= d; it is < d only where another part of the surface comes
 * within d (concave folds), a small share of the area, so the median is d.
 * Tolerance: float rounding of 0.25 m coordinates, far below 1e-6. */
BF_TEST(surface_scaled_bunny_offset_by_d_has_median_d)
{
    if (!bf_test_data("meshes/bunny.ply")) BF_SKIP("shared data absent");
    mesh_data bunny;
    CHECK_OK(mesh_read_ply(bf_test_data("meshes/bunny.ply"), &bunny));
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < bunny.n_verts; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], bunny.xyz[3 * i + k]);
            hi[k] = fmaxf(hi[k], bunny.xyz[3 * i + k]);
        }
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    for (size_t i = 0; i < 3 * (size_t)bunny.n_verts; i++) bunny.xyz[i] = (float)(bunny.xyz[i] * 0.25 / ext);
    const double d = 0.001;
    /* Each sample is pushed along its own face normal, whichever side. */
    float *xyz;
    uint32_t *tri;
    size_t n;
    CHECK_OK(eval_mesh_sample_area(&bunny, 2e5, 1000000, 3, &xyz, &tri, &n));
    mesh_data rec = mesh_alloc((uint32_t)n, 0);
    for (size_t i = 0; i < n; i++) {
        bf_vec3 q = bf_v3_add(bf_v3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]),
                              bf_v3_scale(face_normal(&bunny, tri[i]), d));
        set_v(&rec, (uint32_t)i, q.x, q.y, q.z);
    }
    free(xyz);
    free(tri);
    eval_surface_result r;
    CHECK_OK(eval_surface(&bunny, &rec, NULL, NULL, &r));
    CHECK(n > 1000);
    CHECK_NEAR(r.accuracy.median, d, 1e-6);
    CHECK_LE(r.accuracy.max, d + 1e-6);
    mesh_free(&rec);
    mesh_free(&bunny);
}

/* ------------------------------------------------------------ coverage */

/* Reference: unit lat-long sphere; reconstruction: its upper half (the
 * triangles above the equator ring, a mesh, so completeness distances are
 * exact point-to-surface distances). The halves have equal area, so a
 * reference sample is within threshold t of the upper half if it is in it
 * (probability 1/2) or in the band of angular width t / R below the equator
 * (area share sin(t / R) / 2 < t / (2R)). N samples: binomial noise
 * sigma = sqrt(p (1 - p) / N); tolerance 5 sigma + the band. */
BF_TEST(surface_half_coverage_gives_half_completeness_and_visibility_restricts_it)
{
    mesh_data sph = make_uv_sphere(1.0, 64, 128);
    mesh_data upper = mesh_half(&sph, +1), lower = mesh_half(&sph, -1);
    eval_surface_config cfg = eval_surface_config_default();
    cfg.samples_per_m2 = 2e4;
    cfg.threshold_m = 0.001;
    eval_surface_result r;
    CHECK_OK(eval_surface(&sph, &upper, NULL, &cfg, &r));
    double N = (double)r.n_ref_points, band = cfg.threshold_m / 2;
    CHECK(N > 200000);
    CHECK_NEAR(r.completeness, 0.5 + band / 2, 5 * sqrt(0.25 / N) + band / 2);
    /* The reconstruction lies on the reference: accuracy ~ float rounding. */
    CHECK_LE(r.accuracy.max, 1e-6);
    CHECK_EQ_INT(r.n_rec_vertices, upper.n_verts);
    CHECK(r.n_rec_samples > 0);

    /* Visibility: the camera saw only the upper half (its area samples). */
    float *xyz;
    size_t n;
    CHECK_OK(eval_mesh_sample_area(&upper, 2e4, 1000000, 5, &xyz, NULL, &n));
    mesh_data seen = {.n_verts = (uint32_t)n, .xyz = xyz};
    CHECK_OK(eval_surface(&sph, &upper, &seen, &cfg, &r));
    CHECK(r.used_visible);
    CHECK_EQ_INT(r.n_ref_points, n);
    CHECK_NEAR(r.completeness, 1.0, 0);
    /* Seen upper half, reconstructed lower half: only the band counts, a
     * share below t / R of the seen hemisphere (+ 5 sigma). */
    CHECK_OK(eval_surface(&sph, &lower, &seen, &cfg, &r));
    CHECK_LE(r.completeness, cfg.threshold_m + 5 * sqrt(cfg.threshold_m / n));
    mesh_free(&seen);
    mesh_free(&upper);
    mesh_free(&lower);
    mesh_free(&sph);
}

BF_TEST(surface_far_points_are_counted_beyond_max_dist_not_averaged)
{
    mesh_data box = make_box(1, 1, 1);
    mesh_data rec = mesh_alloc(3, 0);
    set_v(&rec, 0, 0.5, 0.5, 1.001); /* 1 mm above the top */
    set_v(&rec, 1, 0.5, 0.5, 1.003); /* 3 mm */
    set_v(&rec, 2, 0.5, 0.5, 3.0);   /* 2 m: an outlier */
    eval_surface_config cfg = eval_surface_config_default();
    cfg.max_dist_m = 0.1;
    cfg.samples_per_m2 = 1000;
    eval_surface_result r;
    CHECK_OK(eval_surface(&box, &rec, NULL, &cfg, &r));
    CHECK_EQ_INT(r.accuracy.n, 2);
    CHECK_EQ_INT(r.accuracy.n_beyond, 1);
    CHECK_NEAR(r.accuracy.mean, 0.002, 1e-6);
    CHECK_NEAR(r.accuracy.median, 0.002, 1e-6);
    CHECK_NEAR(r.accuracy.max, 0.003, 1e-6);
    /* p90 interpolates between 1 and 3 mm: 1 + 0.9 * 2 = 2.8 mm. */
    CHECK_NEAR(r.accuracy.p90, 0.0028, 1e-6);
    CHECK_NEAR(r.precision, 2.0 / 3, 1e-12);
    /* Almost no reference sample is within 0.1 m of three points. */
    CHECK(r.completeness_dist.n_beyond > r.n_ref_points / 2);
    mesh_free(&rec);
    mesh_free(&box);
}

BF_TEST(surface_rejects_empty_inputs_and_bad_thresholds)
{
    mesh_data box = make_box(1, 1, 1), empty = {0};
    eval_surface_result r;
    CHECK_STATUS(eval_surface(&box, &empty, NULL, NULL, &r), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("reconstruction");
    CHECK_STATUS(eval_surface(&empty, &box, NULL, NULL, &r), BF_INVALID_ARG);
    CHECK_STATUS(eval_surface(&box, &box, &empty, NULL, &r), BF_INVALID_ARG);
    eval_surface_config cfg = eval_surface_config_default();
    cfg.threshold_m = 0;
    CHECK_STATUS(eval_surface(&box, &box, NULL, &cfg, &r), BF_INVALID_ARG);
    mesh_free(&box);
}

BF_TEST(surface_result_does_not_depend_on_the_thread_count)
{
    mesh_data sph = make_uv_sphere(0.5, 16, 32), box = make_box(0.6, 0.5, 0.4);
    for (uint32_t i = 0; i < box.n_verts * 3; i++) box.xyz[i] -= 0.25f;
    eval_surface_config cfg = eval_surface_config_default();
    cfg.samples_per_m2 = 2e4;
    eval_surface_result a, b;
    setenv("BITFUSE_THREADS", "1", 1);
    bf_status s = eval_surface(&sph, &box, NULL, &cfg, &a);
    unsetenv("BITFUSE_THREADS");
    CHECK_OK(s);
    CHECK_OK(eval_surface(&sph, &box, NULL, &cfg, &b));
    CHECK(a.accuracy.mean == b.accuracy.mean && a.accuracy.p90 == b.accuracy.p90);
    CHECK(a.completeness == b.completeness && a.completeness_dist.median == b.completeness_dist.median);
    mesh_free(&sph);
    mesh_free(&box);
}

/* A point-cloud reference (no triangles) is measured as points: a 50 x 50
 * grid with 1 cm spacing, the reconstruction the same grid 3 mm above it.
 * Each nearest distance is exactly 3 mm (the grid's own point beneath;
 * neighbours are sqrt(0.01^2 + 0.003^2) away), in both directions. */
BF_TEST(surface_point_cloud_reference_is_measured_point_to_point)
{
    mesh_data ref = mesh_alloc(2500, 0), rec = mesh_alloc(2500, 0);
    for (uint32_t i = 0; i < 2500; i++) {
        set_v(&ref, i, 0.01 * (i % 50), 0.01 * (i / 50), 0);
        set_v(&rec, i, 0.01 * (i % 50), 0.01 * (i / 50), 0.003);
    }
    eval_surface_config cfg = eval_surface_config_default();
    cfg.threshold_m = 0.005;
    eval_surface_result r;
    CHECK_OK(eval_surface(&ref, &rec, NULL, &cfg, &r));
    CHECK_EQ_INT(r.n_ref_points, 2500);
    CHECK_NEAR(r.accuracy.max, 0.003, 1e-7);
    CHECK_NEAR(r.accuracy.mean, 0.003, 1e-7);
    CHECK_NEAR(r.completeness_dist.median, 0.003, 1e-7);
    CHECK_NEAR(r.completeness, 1.0, 0);
    CHECK(r.used_ref_vertices);
    mesh_free(&ref);
    mesh_free(&rec);
}

/* Triangles without area (collinear corners) have no area to sample:
 * completeness is over their vertices, and the result says so. */
BF_TEST(surface_reference_without_area_is_measured_at_its_vertices)
{
    mesh_data ref = mesh_alloc(3, 1), rec = mesh_alloc(3, 0);
    for (uint32_t i = 0; i < 3; i++) set_v(&ref, i, 0.1 * i, 0, 0), set_v(&rec, i, 0.1 * i, 0, 0.002);
    ref.tri[0] = 0, ref.tri[1] = 1, ref.tri[2] = 2;
    eval_surface_config cfg = eval_surface_config_default();
    eval_surface_result r;
    CHECK_OK(eval_surface(&ref, &rec, NULL, &cfg, &r));
    CHECK(r.used_ref_vertices);
    CHECK_EQ_INT(r.n_ref_points, 3);
    CHECK_NEAR(r.completeness_dist.max, 0.002, 1e-7);
    mesh_free(&ref);
    mesh_free(&rec);
}

typedef struct surface_job {
    const mesh_data *ref, *rec;
    eval_surface_config cfg;
} surface_job;

static bf_status run_surface(void *arg)
{
    const surface_job *j = arg;
    eval_surface_result r;
    return eval_surface(j->ref, j->rec, NULL, &j->cfg, &r);
}

/* Every host allocation of the surface evaluation fails in turn (also
 * those made by its worker threads): each is a clean BF_NO_MEMORY with a
 * message, nothing leaks (ASan). */
BF_TEST(surface_fails_cleanly_at_every_allocation)
{
    mesh_data box = make_box(0.4, 0.3, 0.2);
    mesh_data rec = displaced_samples(&box, 2e3, 0.002, bf_v3(0.2, 0.15, 0.1), 99);
    surface_job j = {&box, &rec, eval_surface_config_default()};
    j.cfg.samples_per_m2 = 2e3;
    int n = bf_test_fault_walk(run_surface, &j);
    mesh_free(&rec);
    mesh_free(&box);
    CHECK(n >= 4);
    fprintf(stderr, "  surface: %d allocations failed in turn\n", n);
}
