/* eval: the BVH returns what brute force over all triangles returns, for
 * ray casting and for closest-point queries. */
#include "mesh/mesh.h"
#include "test.h"

/* xorshift, so failures reproduce. */
static double rnd(unsigned *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 17;
    *s ^= *s << 5;
    return (double)*s / 4294967296.0;
}

/* A procedural mesh: a finely tessellated sphere (shared edges, many rays
 * through vertices and edges), a random triangle soup of mixed sizes
 * (overlapping boxes, thin slivers) and a few degenerate triangles. */
static bool make_test_mesh(mesh_data *m, unsigned seed)
{
    const uint32_t n_lat = 24, n_lon = 48, n_soup = 1500, n_degen = 4;
    uint32_t n_sphere_v = (n_lat + 1) * n_lon;
    uint32_t n_sphere_t = 2 * n_lat * n_lon;
    memset(m, 0, sizeof *m);
    m->n_verts = n_sphere_v + 3 * (n_soup + n_degen);
    m->n_tris = n_sphere_t + n_soup + n_degen;
    m->xyz = malloc(sizeof(float) * 3 * m->n_verts);
    m->tri = malloc(sizeof(uint32_t) * 3 * m->n_tris);
    if (!m->xyz || !m->tri) return false;
    uint32_t v = 0, t = 0;
    for (uint32_t i = 0; i <= n_lat; i++)
        for (uint32_t j = 0; j < n_lon; j++) {
            double th = M_PI * i / n_lat, ph = 2 * M_PI * j / n_lon;
            m->xyz[3 * v] = (float)(0.3 * sin(th) * cos(ph) + 0.2);
            m->xyz[3 * v + 1] = (float)(0.3 * sin(th) * sin(ph) - 0.1);
            m->xyz[3 * v + 2] = (float)(0.3 * cos(th) + 0.05);
            v++;
        }
    for (uint32_t i = 0; i < n_lat; i++)
        for (uint32_t j = 0; j < n_lon; j++) {
            uint32_t a = i * n_lon + j, b = i * n_lon + (j + 1) % n_lon;
            uint32_t c = a + n_lon, d = b + n_lon;
            uint32_t q[6] = {a, c, b, b, c, d};
            memcpy(m->tri + 3 * t, q, sizeof q);
            t += 2;
        }
    unsigned s = seed;
    for (uint32_t k = 0; k < n_soup + n_degen; k++) {
        double size = k % 10 == 0 ? 0.8 : k % 3 == 0 ? 0.02 : 0.15;
        double c[3] = {rnd(&s) * 2 - 1, rnd(&s) * 2 - 1, rnd(&s) * 2 - 1};
        for (int e = 0; e < 3; e++) {
            for (int a = 0; a < 3; a++) m->xyz[3 * (v + e) + a] = (float)(c[a] + size * (rnd(&s) - 0.5));
            if (k >= n_soup && e == 2) /* degenerate: third vertex on the first edge or repeated */
                for (int a = 0; a < 3; a++)
                    m->xyz[3 * (v + e) + a] = k % 2 ? m->xyz[3 * v + a] : 0.5f * (m->xyz[3 * v + a] + m->xyz[3 * (v + 1) + a]);
        }
        m->tri[3 * t] = v;
        m->tri[3 * t + 1] = v + 1;
        m->tri[3 * t + 2] = v + 2;
        v += 3;
        t++;
    }
    return true;
}

static bf_vec3 vert(const mesh_data *m, uint32_t t, int k)
{
    const float *p = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t + k];
    return bf_v3(p[0], p[1], p[2]);
}

/* Reference ray-triangle test (Möller-Trumbore written from the paper). */
static bool ref_hit(const mesh_data *m, uint32_t t, bf_vec3 o, bf_vec3 d, double *t_out)
{
    bf_vec3 v0 = vert(m, t, 0), e1 = bf_v3_sub(vert(m, t, 1), v0), e2 = bf_v3_sub(vert(m, t, 2), v0);
    bf_vec3 p = bf_v3_cross(d, e2);
    double det = bf_v3_dot(e1, p);
    if (det == 0) return false;
    bf_vec3 s = bf_v3_sub(o, v0);
    double u = bf_v3_dot(s, p) / det;
    if (u < 0 || u > 1) return false;
    bf_vec3 q = bf_v3_cross(s, e1);
    double v = bf_v3_dot(d, q) / det;
    if (v < 0 || u + v > 1) return false;
    *t_out = bf_v3_dot(e2, q) / det;
    return true;
}

static bool brute_raycast(const mesh_data *m, bf_vec3 o, bf_vec3 d, double t_min, double t_max, double *t_best,
                          uint32_t *tri)
{
    bool found = false;
    *t_best = t_max;
    for (uint32_t t = 0; t < m->n_tris; t++) {
        double tt;
        if (ref_hit(m, t, o, d, &tt) && tt > t_min && tt < *t_best) {
            *t_best = tt;
            *tri = t;
            found = true;
        }
    }
    return found;
}

/* Reference closest point on a triangle, by a different route from the
 * BVH's Voronoi-region code: project onto the plane and accept if inside,
 * else the nearest point of the three edges. */
static bf_vec3 seg_closest(bf_vec3 p, bf_vec3 a, bf_vec3 b)
{
    bf_vec3 ab = bf_v3_sub(b, a);
    double l2 = bf_v3_dot(ab, ab), s = l2 > 0 ? bf_v3_dot(bf_v3_sub(p, a), ab) / l2 : 0;
    s = s < 0 ? 0 : s > 1 ? 1 : s;
    return bf_v3_add(a, bf_v3_scale(ab, s));
}

static double ref_closest_dist(const mesh_data *m, uint32_t t, bf_vec3 p)
{
    bf_vec3 a = vert(m, t, 0), b = vert(m, t, 1), c = vert(m, t, 2);
    bf_vec3 n = bf_v3_cross(bf_v3_sub(b, a), bf_v3_sub(c, a));
    double n2 = bf_v3_dot(n, n);
    if (n2 > 1e-30) {
        double h = bf_v3_dot(bf_v3_sub(p, a), n) / n2;
        bf_vec3 q = bf_v3_sub(p, bf_v3_scale(n, h));
        /* Inside if q lies on the inner side of all three edges. */
        double s0 = bf_v3_dot(bf_v3_cross(bf_v3_sub(b, a), bf_v3_sub(q, a)), n);
        double s1 = bf_v3_dot(bf_v3_cross(bf_v3_sub(c, b), bf_v3_sub(q, b)), n);
        double s2 = bf_v3_dot(bf_v3_cross(bf_v3_sub(a, c), bf_v3_sub(q, c)), n);
        if (s0 >= 0 && s1 >= 0 && s2 >= 0) return bf_v3_norm(bf_v3_sub(p, q));
    }
    double d = bf_v3_norm(bf_v3_sub(p, seg_closest(p, a, b)));
    d = fmin(d, bf_v3_norm(bf_v3_sub(p, seg_closest(p, b, c))));
    return fmin(d, bf_v3_norm(bf_v3_sub(p, seg_closest(p, c, a))));
}

static bf_vec3 random_dir(unsigned *s, int k)
{
    /* Every 7th ray is axis-aligned or in an axis plane: zero direction
     * components exercise the slab test's division. */
    bf_vec3 d = bf_v3(rnd(s) * 2 - 1, rnd(s) * 2 - 1, rnd(s) * 2 - 1);
    if (k % 7 == 0) d.x = 0;
    if (k % 14 == 0) d.y = 0;
    if (bf_v3_norm(d) == 0) d.z = 1;
    return d;
}

/* Ray casts against brute force; t within 1e-9 relative and the same
 * triangle unless two triangles are hit at the same t (a shared edge). */
static int check_rays(const mesh_data *m, const mesh_bvh *b, unsigned seed, int n_rays, bf_vec3 lo, bf_vec3 hi,
                      int *n_hits)
{
    unsigned s = seed;
    for (int k = 0; k < n_rays; k++) {
        bf_vec3 o = bf_v3(lo.x + (hi.x - lo.x) * rnd(&s), lo.y + (hi.y - lo.y) * rnd(&s),
                          lo.z + (hi.z - lo.z) * rnd(&s));
        bf_vec3 d = random_dir(&s, k);
        double t_min = k % 5 == 0 ? 0.1 : 0, t_max = k % 11 == 0 ? 0.5 : INFINITY;
        double tb = 0;
        uint32_t trb = 0;
        mesh_hit h;
        bool fb = brute_raycast(m, o, d, t_min, t_max, &tb, &trb);
        bool fv = mesh_bvh_raycast(b, o, d, t_min, t_max, &h);
        if (fb != fv) return k + 1;
        if (!fb) continue;
        (*n_hits)++;
        if (fabs(h.t - tb) > 1e-9 * fmax(1, tb)) return k + 1;
        if (h.tri != trb) {
            double t2;
            if (!ref_hit(m, h.tri, o, d, &t2) || fabs(t2 - tb) > 1e-9 * fmax(1, tb)) return k + 1;
        }
        /* The hit point from barycentrics agrees with o + t d. */
        bf_vec3 v0 = vert(m, h.tri, 0), v1 = vert(m, h.tri, 1), v2 = vert(m, h.tri, 2);
        bf_vec3 pb = bf_v3_add(v0, bf_v3_add(bf_v3_scale(bf_v3_sub(v1, v0), h.u), bf_v3_scale(bf_v3_sub(v2, v0), h.v)));
        if (bf_v3_norm(bf_v3_sub(pb, bf_v3_add(o, bf_v3_scale(d, h.t)))) > 1e-9) return k + 1;
    }
    return 0;
}

static int check_closest(const mesh_data *m, const mesh_bvh *b, unsigned seed, int n_q, bf_vec3 lo, bf_vec3 hi)
{
    unsigned s = seed;
    for (int k = 0; k < n_q; k++) {
        bf_vec3 p = bf_v3(lo.x + (hi.x - lo.x) * rnd(&s), lo.y + (hi.y - lo.y) * rnd(&s),
                          lo.z + (hi.z - lo.z) * rnd(&s));
        double ref = INFINITY;
        for (uint32_t t = 0; t < m->n_tris; t++) ref = fmin(ref, ref_closest_dist(m, t, p));
        double max_d = k % 4 == 0 ? 0.5 * ref + 1e-6 : k % 4 == 1 ? 2 * ref : INFINITY;
        bf_vec3 c;
        uint32_t tri = UINT32_MAX;
        double d = mesh_bvh_closest(b, p, max_d, &c, &tri);
        if (k % 4 == 0 && ref > 2e-6) {
            if (d != INFINITY) return k + 1; /* nothing within max_dist */
            continue;
        }
        if (fabs(d - ref) > 1e-9) return k + 1;
        if (fabs(bf_v3_norm(bf_v3_sub(c, p)) - d) > 1e-9) return k + 1;
        if (tri >= m->n_tris || fabs(ref_closest_dist(m, tri, p) - d) > 1e-9) return k + 1;
    }
    return 0;
}

BF_TEST(bvh_raycast_equals_brute_force_on_procedural_mesh)
{
    mesh_data m;
    CHECK(make_test_mesh(&m, 777));
    mesh_bvh *b = NULL;
    CHECK_OK(mesh_bvh_build(&m, &b));
    int n_hits = 0;
    int bad = check_rays(&m, b, 99, 4000, bf_v3(-1.5, -1.5, -1.5), bf_v3(1.5, 1.5, 1.5), &n_hits);
    mesh_bvh_destroy(b);
    free(m.xyz);
    free(m.tri);
    CHECK_EQ_INT(bad, 0);
    CHECK(n_hits > 1000); /* the test exercised hits, not just misses */
}

BF_TEST(bvh_closest_equals_brute_force_on_procedural_mesh)
{
    mesh_data m;
    CHECK(make_test_mesh(&m, 4242));
    mesh_bvh *b = NULL;
    CHECK_OK(mesh_bvh_build(&m, &b));
    int bad = check_closest(&m, b, 5, 1500, bf_v3(-2, -2, -2), bf_v3(2, 2, 2));
    mesh_bvh_destroy(b);
    free(m.xyz);
    free(m.tri);
    CHECK_EQ_INT(bad, 0);
}

BF_TEST(bvh_empty_mesh_and_bad_input)
{
    mesh_data m = {0};
    mesh_bvh *b = NULL;
    CHECK_OK(mesh_bvh_build(&m, &b));
    mesh_hit h;
    CHECK(!mesh_bvh_raycast(b, bf_v3(0, 0, 0), bf_v3(0, 0, 1), 0, INFINITY, &h));
    CHECK(mesh_bvh_closest(b, bf_v3(0, 0, 0), INFINITY, NULL, NULL) == INFINITY);
    mesh_bvh_destroy(b);
    mesh_bvh_destroy(NULL);
    float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    uint32_t tri[3] = {0, 1, 5};
    mesh_data bad = {.n_verts = 3, .n_tris = 1, .xyz = xyz, .tri = tri};
    b = (mesh_bvh *)&m; /* must stay untouched on failure */
    CHECK_STATUS(mesh_bvh_build(&bad, &b), BF_INVALID_ARG);
    CHECK(b == (mesh_bvh *)&m);
    CHECK_ERROR_MENTIONS("out of range");
}

BF_TEST(bvh_single_triangle_exact_hit_and_closest)
{
    float xyz[9] = {0, 0, 2, 1, 0, 2, 0, 1, 2};
    uint32_t tri[3] = {0, 1, 2};
    mesh_data m = {.n_verts = 3, .n_tris = 1, .xyz = xyz, .tri = tri};
    mesh_bvh *b = NULL;
    CHECK_OK(mesh_bvh_build(&m, &b));
    mesh_hit h;
    CHECK(mesh_bvh_raycast(b, bf_v3(0.25, 0.25, 0), bf_v3(0, 0, 1), 0, INFINITY, &h));
    CHECK_NEAR(h.t, 2.0, 1e-15);
    CHECK_NEAR(h.u, 0.25, 1e-15);
    CHECK_NEAR(h.v, 0.25, 1e-15);
    /* The open interval: a hit exactly at t_max is not a hit. */
    CHECK(!mesh_bvh_raycast(b, bf_v3(0.25, 0.25, 0), bf_v3(0, 0, 1), 0, 2.0, &h));
    bf_vec3 c;
    uint32_t t = 9;
    CHECK_NEAR(mesh_bvh_closest(b, bf_v3(2, 0, 2), INFINITY, &c, &t), 1.0, 1e-15);
    CHECK_EQ_INT(t, 0);
    CHECK_NEAR(c.x, 1.0, 1e-15);
    CHECK(mesh_bvh_closest(b, bf_v3(2, 0, 2), 0.5, &c, &t) == INFINITY);
    mesh_bvh_destroy(b);
}

BF_TEST(bvh_raycast_and_closest_equal_brute_force_on_bunny)
{
    const char *path = bf_test_data("meshes/bunny.ply");
    if (!path) BF_SKIP("shared data absent: meshes/bunny.ply");
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    mesh_bvh *b = NULL;
    CHECK_OK(mesh_bvh_build(&m, &b));
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY), hi = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < m.n_verts; i++) {
        lo = bf_v3(fmin(lo.x, m.xyz[3 * i]), fmin(lo.y, m.xyz[3 * i + 1]), fmin(lo.z, m.xyz[3 * i + 2]));
        hi = bf_v3(fmax(hi.x, m.xyz[3 * i]), fmax(hi.y, m.xyz[3 * i + 1]), fmax(hi.z, m.xyz[3 * i + 2]));
    }
    /* Rays from around the model towards random points inside its box, so
     * most of them hit; a few start inside the model. */
    unsigned s = 31337;
    int bad = 0, n_hits = 0;
    bf_vec3 ext = bf_v3_sub(hi, lo);
    for (int k = 0; k < 400 && !bad; k++) {
        bf_vec3 o = bf_v3(lo.x + ext.x * (3 * rnd(&s) - 1), lo.y + ext.y * (3 * rnd(&s) - 1),
                          lo.z + ext.z * (3 * rnd(&s) - 1));
        bf_vec3 target = bf_v3(lo.x + ext.x * rnd(&s), lo.y + ext.y * rnd(&s), lo.z + ext.z * rnd(&s));
        if (k % 10 == 0) o = bf_v3_add(lo, bf_v3_scale(ext, 0.5));
        bf_vec3 d = bf_v3_sub(target, o);
        double tb = 0;
        uint32_t trb = 0;
        mesh_hit h;
        bool fb = brute_raycast(&m, o, d, 0, INFINITY, &tb, &trb);
        bool fv = mesh_bvh_raycast(b, o, d, 0, INFINITY, &h);
        if (fb != fv || (fb && fabs(h.t - tb) > 1e-9 * fmax(1, tb))) bad = k + 1;
        n_hits += fb;
    }
    if (!bad) bad = check_closest(&m, b, 8, 200, bf_v3_sub(lo, bf_v3_scale(ext, 0.3)), bf_v3_add(hi, bf_v3_scale(ext, 0.3)));
    mesh_bvh_destroy(b);
    mesh_free(&m);
    CHECK_EQ_INT(bad, 0);
    CHECK(n_hits > 200);
}
