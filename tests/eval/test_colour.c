/* eval-colour's pieces: the re-rendering of a coloured mesh (a camera-facing
 * quad with a colour per corner: bilinear along its edges, the colour of
 * the nearer triangle inside) and PSNR's arithmetic. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "eval/eval.h"
#include "mesh/mesh.h"
#include "test.h"

/* A 2 x 2 m quad at z = 2 in front of a camera at the origin looking along
 * +z, corners red, green, blue, white; placed at a far local origin, so the
 * renderer must work in the mesh's local frame. */
static void quad(mesh_data *m, bf_vec3 origin)
{
    static float xyz[12] = {-1, -1, 2, 1, -1, 2, 1, 1, 2, -1, 1, 2};
    static uint8_t rgb[12] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
    static uint32_t tri[6] = {0, 1, 2, 0, 2, 3};
    memset(m, 0, sizeof *m);
    m->n_verts = 4, m->n_tris = 2;
    m->xyz = xyz, m->rgb = rgb, m->tri = tri;
    m->origin = origin;
}

/* Renders the quad through dist (NULL: a pinhole) and checks every pixel
 * away from its edge against the point where the pixel's ray meets z = 2:
 * hit or not, and the barycentric colour there. *n_hit: the pixels hit. */
static void check_quad(const double *dist, uint32_t *n_out)
{
    mesh_data m;
    bf_vec3 origin = bf_v3(10000.0, -2000.0, 50.0);
    quad(&m, origin);
    mesh_bvh *bvh;
    CHECK_OK(mesh_bvh_build(&m, &bvh));
    bf_intrinsics K = {64, 48, 40.0, 40.0, 31.5, 23.5, 5000};
    bf_se3 T = bf_se3_identity();
    T.t = origin; /* the camera at the quad's local origin */
    uint8_t rgb[64 * 48 * 3], hit[64 * 48];
    CHECK_OK(eval_colour_render(&m, bvh, &K, dist, &T, rgb, hit));
    /* The quad spans x, y in [-1, 1] at z = 2. */
    uint32_t n_hit = 0;
    *n_out = 0;
    for (uint32_t v = 0; v < 48; v++)
        for (uint32_t u = 0; u < 64; u++) {
            double x = (u - 31.5) / 40.0, y = (v - 23.5) / 40.0;
            if (dist) CHECK(calib_undistort(dist, x, y, &x, &y));
            x *= 2, y *= 2;
            bool inside = fabs(x) < 0.999 && fabs(y) < 0.999;
            size_t i = (size_t)v * 64 + u;
            if (fabs(x) < 1.001 && fabs(y) < 1.001 && !inside) continue; /* the edge itself */
            CHECK_EQ_INT(hit[i], inside ? 1 : 0);
            n_hit += hit[i];
            if (!inside) continue;
            /* Barycentric colour of the triangle holding (x, y): below the
             * diagonal y = x (triangle 0 1 2) or above it (0 2 3). */
            double s = (x + 1) / 2, t = (y + 1) / 2, w[4] = {0, 0, 0, 0};
            if (s >= t) w[0] = 1 - s, w[1] = s - t, w[2] = t;
            else w[0] = 1 - t, w[2] = s, w[3] = t - s;
            for (int c = 0; c < 3; c++) {
                double want = 0;
                for (int k = 0; k < 4; k++) want += w[k] * m.rgb[3 * k + c];
                CHECK(fabs(rgb[3 * i + c] - want) <= 0.5 + 1e-3); /* rounding to 8 bits */
            }
        }
    mesh_bvh_destroy(bvh);
    *n_out = n_hit;
}

BF_TEST(colour_render_interpolates_the_vertex_colours)
{
    uint32_t n;
    check_quad(NULL, &n);
    CHECK(n > 600); /* pixels within 20 px of the centre */
}

BF_TEST(colour_render_sees_through_the_lens)
{
    /* A pincushion lens (k1 > 0) pushes the image outward: the quad
     * covers more pixels than through the pinhole, and every pixel must
     * show what its own undistorted ray meets (a renderer that ignored the
     * lens would show the pinhole's colours, off by up to 2 px here). */
    const double dist[CALIB_DIST_N] = {0.2, 0.05, 0.001, -0.002, 0};
    uint32_t pinhole, lens;
    check_quad(NULL, &pinhole);
    check_quad(dist, &lens);
    CHECK(lens > pinhole + 100);
}

BF_TEST(psnr_is_the_mean_squared_error_in_decibels)
{
    uint8_t a[4 * 3], b[4 * 3], mask[4] = {1, 1, 1, 0};
    for (int i = 0; i < 12; i++) a[i] = 100, b[i] = 100;
    eval_colour_sums s = {0};
    eval_colour_compare(a, b, mask, 4, &s);
    CHECK(isinf(eval_colour_psnr(&s)));
    b[0] = 110;  /* one channel of a compared pixel: MSE 100 / 9 */
    b[11] = 0;   /* a masked pixel counts for nothing */
    eval_colour_sums t = {0};
    eval_colour_compare(a, b, mask, 4, &t);
    CHECK_EQ_INT(t.n, 9);
    CHECK(fabs(eval_colour_psnr(&t) - 10.0 * log10(255.0 * 255.0 / (100.0 / 9.0))) < 1e-9);
    eval_colour_sums none = {0};
    CHECK(isnan(eval_colour_psnr(&none)));
}
