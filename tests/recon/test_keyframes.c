/* The relocalisation's host parts (recon/reloc.c): what the keyframe store
 * keeps once it is full, the colour poses kept, and the agreement check's
 * verdict on one sample. No GPU: poses and arrays only. */
#include <math.h>
#include <stdlib.h>

#include "test.h"
#include "recon/recon_int.h"
#include "shaders/bf_common.glsl.h"

/* A loop whose store holds at most n keyframes, spaced 0.1 m or 10 degrees. */
static recon *store_open(uint32_t n)
{
    recon *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    r->cfg = recon_config_default();
    r->cfg.reloc.max_keyframes = n;
    r->K_ref = (bf_intrinsics){.width = 1, .height = 1, .fx_px = 1, .fy_px = 1, .depth_scale = 1000};
    if (recon__reloc_create(r) != BF_OK) {
        free(r);
        return NULL;
    }
    return r;
}

static void store_close(recon *r)
{
    recon__reloc_destroy(r);
    free(r);
}

static bf_se3 at_x(double x) { return bf_se3_from_qt(bf_quat_identity(), bf_v3(x, 0, 0)); }

/* Held: a keyframe within 1 mm of x. */
static bool holds_x(const recon *r, double x)
{
    for (uint32_t i = 0; i < r->n_keyframes; i++)
        if (fabs(r->keyframes[i].t.x - x) < 1e-3 && fabs(r->keyframes[i].t.y) < 1e-9) return true;
    return false;
}

/* A straight scan of 2 m with a keyframe every 0.11 m (19) into a store of
 * 6: the start and the newest stay, and the ones kept cover the path
 * evenly: no gap wider than twice the even spacing (2 m / 5). */
BF_TEST(a_full_store_keeps_where_a_long_scan_began)
{
    recon *r = store_open(6);
    CHECK(r != NULL);
    if (!r) return;
    const uint32_t n = 19;
    for (uint32_t k = 0; k < n; k++) {
        bf_se3 T = at_x(0.11 * k);
        recon__add_keyframe(r, &T, NULL);
    }
    CHECK_EQ_INT(r->n_keyframes, 6);
    CHECK_EQ_INT(r->counts.keyframes, 6);
    CHECK(holds_x(r, 0.0));
    CHECK(holds_x(r, 0.11 * (n - 1)));
    double xs[6];
    for (uint32_t i = 0; i < 6; i++) xs[i] = r->keyframes[i].t.x;
    for (uint32_t i = 0; i < 6; i++)
        for (uint32_t j = i + 1; j < 6; j++)
            if (xs[j] < xs[i]) {
                double t = xs[i];
                xs[i] = xs[j], xs[j] = t;
            }
    double widest = 0;
    for (uint32_t i = 1; i < 6; i++) widest = fmax(widest, xs[i] - xs[i - 1]);
    fprintf(stderr, "  kept x: %.2f %.2f %.2f %.2f %.2f %.2f, widest gap %.2f m\n", xs[0], xs[1], xs[2], xs[3], xs[4],
            xs[5], widest);
    CHECK_LE(widest, 2 * 0.11 * (n - 1) / 5);
    store_close(r);
}

/* Near an existing keyframe (within a spacing): no new one, none replaced. */
BF_TEST(a_pose_near_a_keyframe_adds_nothing)
{
    recon *r = store_open(2);
    CHECK(r != NULL);
    if (!r) return;
    bf_se3 a = at_x(0), b = at_x(0.5), c = at_x(0.05), d = at_x(1.0);
    recon__add_keyframe(r, &a, NULL);
    recon__add_keyframe(r, &b, NULL);
    recon__add_keyframe(r, &c, NULL);
    CHECK_EQ_INT(r->n_keyframes, 2);
    CHECK(holds_x(r, 0.0) && holds_x(r, 0.5));
    /* Full, a far pose: the one nearest to the others and the newcomer
     * (0.5, between 0 and 1) makes way. */
    recon__add_keyframe(r, &d, NULL);
    CHECK(holds_x(r, 0.0) && holds_x(r, 1.0));
    store_close(r);
}

static recon__colour_pose colour_pose(uint32_t inliers, double x)
{
    return (recon__colour_pose){.n_inliers = inliers, .T_wc = at_x(x)};
}

/* The colour candidates' list: most inliers first, one entry per pose. */
BF_TEST(colour_poses_keep_the_best_distinct_ones)
{
    recon__colour_pose best[3];
    uint32_t n = 0;
    recon__colour_pose a = colour_pose(50, 0.0), b = colour_pose(30, 1.0);
    recon__keep_pose(best, &n, 2, &a);
    recon__keep_pose(best, &n, 2, &b);
    CHECK_EQ_INT(n, 2);
    /* A repeat of a (2 cm away) with fewer inliers: nothing changes. */
    recon__colour_pose a_worse = colour_pose(40, 0.02);
    recon__keep_pose(best, &n, 2, &a_worse);
    CHECK_EQ_INT(n, 2);
    CHECK_EQ_INT(best[0].n_inliers, 50);
    CHECK_EQ_INT(best[1].n_inliers, 30);
    /* A repeat of a with more inliers takes its place, and b, a distinct
     * pose, stays although the list was full. */
    recon__colour_pose a_better = colour_pose(60, 0.02);
    recon__keep_pose(best, &n, 2, &a_better);
    CHECK_EQ_INT(n, 2);
    CHECK_EQ_INT(best[0].n_inliers, 60);
    CHECK_NEAR(best[0].T_wc.t.x, 0.02, 1e-12);
    CHECK_EQ_INT(best[1].n_inliers, 30);
    /* A distinct pose between them pushes the last out of a full list; one
     * with fewer than the last does not get in. */
    recon__colour_pose c = colour_pose(45, 2.0), d = colour_pose(10, 3.0);
    recon__keep_pose(best, &n, 2, &c);
    recon__keep_pose(best, &n, 2, &d);
    CHECK_EQ_INT(n, 2);
    CHECK_EQ_INT(best[0].n_inliers, 60);
    CHECK_EQ_INT(best[1].n_inliers, 45);
    /* Turned 10 degrees at the same place is another pose (beyond 5). */
    bf_quat yaw10 = bf_quat_from_axis_angle(bf_v3(0, 1, 0), 10.0 * M_PI / 180);
    recon__colour_pose turned = {.n_inliers = 70, .T_wc = bf_se3_from_qt(yaw10, bf_v3(0.02, 0, 0))};
    recon__keep_pose(best, &n, 3, &turned);
    CHECK_EQ_INT(n, 3);
    CHECK_EQ_INT(best[0].n_inliers, 70);
    CHECK_EQ_INT(best[1].n_inliers, 60);
    CHECK_EQ_INT(best[2].n_inliers, 45);
}

/* The agreement check's verdict on one sample at a silhouette of the
 * reference: a 1 m foreground (columns 0-3) before a 3 m wall (4-7). A
 * sample of the foreground landing just past the edge, where the nearest
 * reference pixel is the wall, belongs to the foreground beside it, so it
 * is not "in front of the map" (the nearest pixel alone said it was); two
 * pixels into the wall it is. Likewise a wall sample just before the edge
 * is not "behind". */
BF_TEST(agreement_judges_a_silhouette_by_the_pixels_around)
{
    float ref[8 * 4];
    for (int v = 0; v < 4; v++)
        for (int u = 0; u < 8; u++) ref[v * 8 + u] = u < 4 ? 1.0f : 3.0f;
    ref[1 * 8 + 6] = 0.0f; /* a hole in the wall */
    const bf_sensor sn = recon_config_default().sensor;
    const double band = 0.02;
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 3.6, 1.2, 1.0, &sn, band), RECON_SAMPLE_AGREE);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 5.4, 2.2, 1.0, &sn, band), RECON_SAMPLE_FRONT);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 3.4, 1.2, 3.0, &sn, band), RECON_SAMPLE_AGREE);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 1.2, 1.2, 3.0, &sn, band), RECON_SAMPLE_BEHIND);
    /* At the border only the pixels that exist count: left of the first
     * column's centre the first column alone, not the second one beside
     * it; right of the last column's centre the last. */
    ref[2 * 8 + 0] = ref[3 * 8 + 0] = 3.0f; /* rows 2-3: column 0 wall, column 1 foreground */
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, -0.3, 2.0, 1.0, &sn, band), RECON_SAMPLE_FRONT);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 0.3, 2.0, 1.0, &sn, band), RECON_SAMPLE_AGREE);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 7.3, 3.3, 1.0, &sn, band), RECON_SAMPLE_FRONT);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 7.3, 3.3, 3.0, &sn, band), RECON_SAMPLE_AGREE);
    /* Off the image, or the nearest pixel without depth: not covered. */
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, -0.6, 1.0, 1.0, &sn, band), RECON_SAMPLE_OFF);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 7.6, 1.0, 1.0, &sn, band), RECON_SAMPLE_OFF);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 6.2, 0.8, 3.0, &sn, band), RECON_SAMPLE_OFF);
    /* The band: 2 cm + 3 sigma_z of the deeper of the two depths. */
    double edge = band + 3.0 * bf_sensor_sigma(1.0f, sn.sigma_a, sn.sigma_b, sn.sigma_c);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 1.0, 1.0, 1.0 - edge + 1e-4, &sn, band), RECON_SAMPLE_AGREE);
    CHECK_EQ_INT(recon__classify_sample(ref, 8, 4, 1.0, 1.0, 1.0 - edge - 1e-4, &sn, band), RECON_SAMPLE_FRONT);
}
