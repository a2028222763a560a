/* The loop's test fixture (recon_fixture.h). */
#include "recon_fixture.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "export/export.h"

static bool y_up;
void fixture_set_y_up(bool on) { y_up = on; }

/* y up: the image's rows run the other way, so cy mirrors too (H - 1 - cy). */
bf_intrinsics test_K(void)
{
    return y_up ? (bf_intrinsics){W, H, 262.5, -262.5, 159.5, H - 1 - 119.5, 5000}
                : (bf_intrinsics){W, H, 262.5, 262.5, 159.5, 119.5, 5000};
}

/* A hand-held sideways sweep with a little yaw and bob at 30 Hz, relative
 * to the scene's first view (the motion of tests/fusion's room test). */
bf_se3 sweep_pose(const synth_scene *sc, uint32_t k)
{
    double s = k / 30.0;
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.15 * sin(s)),
                              bf_v3(0.25 * sin(s), 0.02 * sin(3 * s), 0.05 * (1 - cos(s))));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

bf_status room_sweep(synth_scene *sc, bf_se3 *truth, uint32_t n)
{
    bf_status s = synth_scene_room(NULL, sc);
    for (uint32_t k = 0; s == BF_OK && k < n; k++) truth[k] = sweep_pose(sc, k);
    return s;
}

bf_se3 panned(const bf_se3 *T, double deg)
{
    bf_se3 turn = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), deg * M_PI / 180), bf_v3(0, 0, 0));
    return bf_se3_mul(T, &turn);
}

double trans_dist(const bf_se3 *A, const bf_se3 *B) { return bf_v3_norm(bf_v3_sub(A->t, B->t)); }

double rot_dist_deg(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 Ai = bf_se3_inverse(A), D = bf_se3_mul(&Ai, B);
    double c = (D.R[0][0] + D.R[1][1] + D.R[2][2] - 1) / 2;
    return acos(c > 1 ? 1 : (c < -1 ? -1 : c)) * 180 / M_PI;
}

/* The pinhole image rgb as the colour camera's lens shows it: each pixel
 * takes it where its ray (calib_undistort, the lens's inverse) meets the
 * pinhole's image plane, bilinearly; black outside. */
static void through_lens(const calib_camera *c, const uint8_t *rgb, uint8_t *out)
{
    for (uint32_t v = 0; v < H; v++)
        for (uint32_t u = 0; u < W; u++) {
            uint8_t *o = out + 3 * ((size_t)v * W + u);
            double x, y;
            memset(o, 0, 3);
            if (!calib_undistort(c->dist, (u - c->cx_px) / c->fx_px, (v - c->cy_px) / c->fy_px, &x, &y)) continue;
            double su = c->fx_px * x + c->cx_px, sv = c->fy_px * y + c->cy_px, fu = floor(su), fv = floor(sv);
            if (!(fu >= 0 && fv >= 0 && fu + 1 < W && fv + 1 < H)) continue;
            double a = su - fu, b = sv - fv;
            const uint8_t *p = rgb + 3 * ((size_t)fv * W + (size_t)fu);
            for (int k = 0; k < 3; k++)
                o[k] = (uint8_t)lround((1 - b) * ((1 - a) * p[k] + a * p[3 + k]) +
                                       b * ((1 - a) * p[3 * W + k] + a * p[3 * W + 3 + k]));
        }
}

static bf_status render_frame(void *user, uint32_t i, bf_frame *f)
{
    fixture_render *fr = user;
    (void)i; /* the source's count; frame k is the next one not dropped */
    uint32_t k = fr->next_k;
    while (fr->dropped && k < fr->n && fr->dropped[k]) k++;
    if (k >= fr->n) return BF_END;
    fr->next_k = k + 1;
    bf_status s = synth_render(fr->ren, k, &fr->true_pose[k], fr->depth, fr->ren_colour ? NULL : fr->rgb, NULL);
    if (s == BF_OK && fr->ren_colour) {
        /* The colour camera's own image, from where it sits on the rig,
         * through its lens. */
        bf_se3 Twc = bf_se3_mul(&fr->true_pose[k], &fr->T_depth_colour);
        s = synth_render(fr->ren_colour, k, &Twc, fr->depth_colour, fr->rgb_pinhole, NULL);
        if (s == BF_OK) through_lens(&fr->colour, fr->rgb_pinhole, fr->rgb);
    }
    if (s != BF_OK) return s;
    if (fr->mutate) fr->mutate(k, fr->depth);
    *f = (bf_frame){.index = k, .width = W, .height = H, .t_depth_s = 100 + k / 30.0, .depth = fr->depth,
                    .rgb = fr->rgb, .has_pose = true, .T_wc = bf_se3_mul(&fr->offset, &fr->true_pose[k])};
    f->t_rgb_s = f->t_depth_s;
    return BF_OK;
}

/* The colour camera of a calibration: a pinhole renderer (the renderer has
 * no lens; through_lens adds it), at the frames' size. */
static bf_status colour_renderer(const synth_scene *sc, const calib_result *cal, fixture_render *fr)
{
    const calib_camera *c = &cal->colour;
    if (c->width != W || c->height != H)
        return bf_fail(BF_INVALID_ARG, "fixture: the colour camera must be %ux%u", W, H);
    synth_render_config rc = {.K = {W, H, c->fx_px, c->fy_px, c->cx_px, c->cy_px, 5000}, .noise = SYNTH_NOISE_NONE};
    bf_se3 T_cd = cal->has_depth ? cal->T_colour_depth : bf_se3_identity();
    fr->colour = *c;
    fr->T_depth_colour = bf_se3_inverse(&T_cd);
    fr->depth_colour = malloc((size_t)W * H * sizeof *fr->depth_colour);
    fr->rgb_pinhole = malloc((size_t)W * H * 3);
    if (!fr->depth_colour || !fr->rgb_pinhole) return BF_NO_MEMORY;
    return synth_renderer_create(sc, &rc, &fr->ren_colour);
}

static bf_status render_open(const synth_scene *sc, const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset,
                             mutate_fn mutate, bool colour, const calib_result *cal, fixture_render *fr,
                             rgbd_source **src)
{
    bf_intrinsics K = test_K();
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 7};
    *fr = (fixture_render){.true_pose = true_pose, .offset = *offset, .mutate = mutate, .n = n};
    fr->depth = malloc((size_t)W * H * sizeof *fr->depth);
    fr->rgb = colour ? malloc((size_t)W * H * 3) : NULL;
    bool ok = fr->depth && (!colour || fr->rgb);
    bf_status s = ok ? synth_renderer_create(sc, &rc, &fr->ren) : BF_NO_MEMORY;
    if (s == BF_OK && colour && cal) s = colour_renderer(sc, cal, fr);
    if (s == BF_OK) s = capture_source_from_fn(&K, n, true, render_frame, fr, src);
    if (s != BF_OK) fixture_render_close(fr, NULL);
    return s;
}

bf_status fixture_render_open(const synth_scene *sc, const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset,
                              mutate_fn mutate, fixture_render *fr, rgbd_source **src)
{
    return render_open(sc, true_pose, n, offset, mutate, false, NULL, fr, src);
}

void fixture_render_close(fixture_render *fr, rgbd_source *src)
{
    rgbd_source_close(src);
    synth_renderer_destroy(fr->ren);
    synth_renderer_destroy(fr->ren_colour);
    free(fr->depth);
    free(fr->depth_colour);
    free(fr->rgb_pinhole);
    free(fr->rgb);
    memset(fr, 0, sizeof *fr);
}

recon_run_config fixture_run_config(void)
{
    recon_run_config cfg = recon_run_config_default();
    /* Ratio 1 at 320x240 gives the voxels of the default ratio 2 at
     * 640x480 (the level rule follows the pixel footprint z / f, and f is
     * half): the tests' surface bounds were set for that size. */
    cfg.loop.fusion.voxel_ratio = 1.0f;
    cfg.loop.fusion.brick_cap = 1u << 17;
    cfg.loop.fusion.window = 10;
    cfg.loop.fusion.subcache = 4;
    return cfg;
}

static bf_status keep_result(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    (void)run;
    run_out *out = user;
    out->fr[f->index] = *fr;
    out->est[f->index] = fr->T_wc;
    return BF_OK;
}

bf_status run_loop(gpu_context *ctx, const synth_scene *sc, const bf_se3 *true_pose, uint32_t n,
                   const bf_se3 *offset, mutate_fn mutate, run_out *out)
{
    recon_run_config cfg = fixture_run_config();
    return run_loop_with(ctx, &cfg, sc, true_pose, n, offset, mutate, out);
}

static bf_status run_loop_impl(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                               const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset, mutate_fn mutate,
                               bool colour, const bool *dropped, run_out *out)
{
    /* The frames carry offset * true_pose[k] as ground truth: the loop
     * starts at the first one. */
    fixture_render fr;
    rgbd_source *src = NULL;
    recon_run run;
    memset(&run, 0, sizeof run);
    /* With a calibration the colour is the colour camera's own image. */
    const calib_result *cal = cfg->loop.has_calibration ? &cfg->loop.calibration : NULL;
    bf_status s = render_open(sc, true_pose, n, offset, mutate, colour, cal, &fr, &src);
    fr.dropped = dropped;
    if (s == BF_OK) s = recon_run_sequence(ctx, src, cfg, keep_result, out, &run);
    if (s == BF_OK) s = fusion_check(run.map);
    if (s == BF_OK) s = fusion_get_stats(run.map, &out->map);
    hostmap snap = {0};
    if (s == BF_OK) s = fusion_snapshot_take(run.map, &snap);
    if (s == BF_OK) s = export_points(&snap, &out->points, NULL);
    hostmap_free(&snap);
    out->counts = run.counts;
    recon_run_free(&run);
    if (src) fixture_render_close(&fr, src);
    return s;
}

bf_status run_loop_with(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                        const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset, mutate_fn mutate, run_out *out)
{
    return run_loop_impl(ctx, cfg, sc, true_pose, n, offset, mutate, false, NULL, out);
}

bf_status run_loop_dropping(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                            const bf_se3 *true_pose, uint32_t n, const bool *dropped, run_out *out)
{
    bf_se3 I = bf_se3_identity();
    return run_loop_impl(ctx, cfg, sc, true_pose, n, &I, NULL, false, dropped, out);
}

bf_status run_loop_colour(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                          const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset, mutate_fn mutate, run_out *out)
{
    return run_loop_impl(ctx, cfg, sc, true_pose, n, offset, mutate, true, NULL, out);
}

double run_rms_error(const run_out *o, const bf_se3 *true_pose, uint32_t n)
{
    double sum = 0;
    for (uint32_t k = 0; k < n; k++) sum += pow(trans_dist(&o->est[k], &true_pose[k]), 2);
    return sqrt(sum / n);
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

