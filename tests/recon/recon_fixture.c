/* The loop's test fixture (recon_fixture.h). */
#include "recon_fixture.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "export/export.h"

bf_intrinsics test_K(void) { return (bf_intrinsics){W, H, 262.5, 262.5, 159.5, 119.5, 5000}; }

/* A hand-held sideways sweep with a little yaw and bob at 30 Hz, relative
 * to the scene's first view (the motion of tests/fusion's room test). */
bf_se3 sweep_pose(const synth_scene *sc, uint32_t k)
{
    double s = k / 30.0;
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.15 * sin(s)),
                              bf_v3(0.25 * sin(s), 0.02 * sin(3 * s), 0.05 * (1 - cos(s))));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

double trans_dist(const bf_se3 *A, const bf_se3 *B) { return bf_v3_norm(bf_v3_sub(A->t, B->t)); }

double rot_dist_deg(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 Ai = bf_se3_inverse(A), D = bf_se3_mul(&Ai, B);
    double c = (D.R[0][0] + D.R[1][1] + D.R[2][2] - 1) / 2;
    return acos(c > 1 ? 1 : (c < -1 ? -1 : c)) * 180 / M_PI;
}

bf_status run_loop(gpu_context *ctx, const synth_scene *sc, const bf_se3 *true_pose, uint32_t n,
                   const bf_se3 *offset, mutate_fn mutate, run_out *out)
{
    bf_intrinsics K = test_K();
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 7};
    synth_renderer *ren = NULL;
    recon *r = NULL;
    uint16_t *depth = malloc((size_t)W * H * sizeof *depth);
    recon_config cfg = recon_config_default();
    /* Ratio 1 at 320x240 gives the voxels of the default ratio 2 at
     * 640x480 (the level rule follows the pixel footprint z / f, and f is
     * half): the tests' surface bounds were set for that size. */
    cfg.fusion.voxel_ratio = 1.0f;
    cfg.fusion.brick_cap = 1u << 17;
    cfg.fusion.window = 10;
    cfg.fusion.subcache = 4;
    bf_se3 T0 = bf_se3_mul(offset, &true_pose[0]);
    bf_status s = depth ? synth_renderer_create(sc, &rc, &ren) : BF_NO_MEMORY;
    if (s == BF_OK) s = recon_create(ctx, &cfg, &K, &T0, &r);
    for (uint32_t k = 0; s == BF_OK && k < n; k++) {
        s = synth_render(ren, k, &true_pose[k], depth, NULL, NULL);
        if (s != BF_OK) break;
        if (mutate) mutate(k, depth);
        bf_frame f = {.index = k, .width = W, .height = H, .t_depth_s = 100 + k / 30.0, .depth = depth};
        f.t_rgb_s = f.t_depth_s;
        s = recon_add_frame(r, &f, &out->fr[k]);
        out->est[k] = out->fr[k].T_wc;
    }
    if (s == BF_OK) s = recon_flush(r);
    if (s == BF_OK) s = fusion_check(recon_map(r));
    if (s == BF_OK) s = fusion_get_stats(recon_map(r), &out->map);
    hostmap snap = {0};
    if (s == BF_OK) s = fusion_snapshot_take(recon_map(r), &snap);
    if (s == BF_OK) s = export_points(&snap, &out->points, NULL);
    hostmap_free(&snap);
    if (r) out->counts = recon_get_counts(r);
    recon_destroy(r);
    synth_renderer_destroy(ren);
    free(depth);
    return s;
}

double surface_p90(const synth_scene *sc, const mesh_data *pts)
{
    eval_surface_config ec = eval_surface_config_default();
    eval_surface_result er;
    if (eval_surface(&sc->mesh, pts, NULL, &ec, &er) != BF_OK) return INFINITY;
    fprintf(stderr, "  surface: %u points, median %.2f mm, p90 %.2f mm\n", pts->n_verts, 1e3 * er.accuracy.median,
            1e3 * er.accuracy.p90);
    return er.accuracy.p90;
}

