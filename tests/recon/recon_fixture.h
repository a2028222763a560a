/* Shared by the loop's tests: synthetic frames rendered in memory at
 * 320x240 and run through recon (tests/recon/recon_fixture.c). */
#ifndef BF_RECON_FIXTURE_H
#define BF_RECON_FIXTURE_H

#include "eval/eval.h"
#include "mesh/mesh.h"
#include "synth/synth.h"
#include "gpu/gpu.h"
#include "recon/recon.h"

#define W 320
#define H 240

bf_intrinsics test_K(void);
/* With on, test_K and the frames are ICL-NUIM's kind of camera: y up, a
 * negative fy (the same rays, the image's rows flipped). */
void fixture_set_y_up(bool on);
/* A hand-held sideways sweep with a little yaw and bob at 30 Hz, relative
 * to the scene's first view. */
bf_se3 sweep_pose(const synth_scene *sc, uint32_t k);
/* The synthetic room and its sweep's first n poses. */
bf_status room_sweep(synth_scene *sc, bf_se3 *truth, uint32_t n);
/* T turned by deg about its own y axis (a pan). */
bf_se3 panned(const bf_se3 *T, double deg);
double trans_dist(const bf_se3 *A, const bf_se3 *B);
double rot_dist_deg(const bf_se3 *A, const bf_se3 *B);

/* One run of the loop over n frames rendered at true_pose[k]; the loop
 * starts at offset * true_pose[0] (offset moves the whole world) and
 * est[k] receives each frame's pose. mutate (may be NULL) edits frame k's
 * depth before it goes in. */
typedef void (*mutate_fn)(uint32_t k, uint16_t *depth);

typedef struct run_out {
    bf_se3 est[64];
    recon_frame_result fr[64];
    recon_counts counts;
    fusion_stats map;
    mesh_data points; /* surface voxels, world frame */
} run_out;

/* A source of n frames rendered at true_pose[k] (mutate, may be NULL,
 * edits frame k's depth), each carrying offset * true_pose[k] as its
 * ground truth. fr holds the renderer; fixture_render_close closes both. */
typedef struct fixture_render {
    synth_renderer *ren;
    const bf_se3 *true_pose;
    bf_se3 offset;
    mutate_fn mutate;
    uint16_t *depth;
    uint8_t *rgb; /* the colour too, or NULL (depth only) */
    /* With a calibration (run_loop_colour with cfg->loop.has_calibration):
     * the colour camera, its renderer, its pose on the rig, its depth
     * (unused) and its image before the lens; else ren_colour is NULL and
     * the colour is the depth camera's own view. */
    calib_camera colour;
    synth_renderer *ren_colour;
    bf_se3 T_depth_colour;
    uint16_t *depth_colour;
    uint8_t *rgb_pinhole;
    /* Frames the source never delivers (a live queue dropping them), or
     * NULL; the next one after them keeps its own index and time. */
    const bool *dropped;
    uint32_t n, next_k;
} fixture_render;
bf_status fixture_render_open(const synth_scene *sc, const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset,
                              mutate_fn mutate, fixture_render *fr, rgbd_source **src);
void fixture_render_close(fixture_render *fr, rgbd_source *src);
/* The runner's config for the fixture's 320x240 frames. */
recon_run_config fixture_run_config(void);

/* The run above through recon_run_sequence, with the fixture's config. */
bf_status run_loop(gpu_context *ctx, const synth_scene *sc, const bf_se3 *true_pose, uint32_t n,
                   const bf_se3 *offset, mutate_fn mutate, run_out *out);
/* The same with the caller's config. */
bf_status run_loop_with(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                        const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset, mutate_fn mutate, run_out *out);
/* The same with the frames marked in dropped[0, n) never delivered. */
bf_status run_loop_dropping(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                            const bf_se3 *true_pose, uint32_t n, const bool *dropped, run_out *out);
/* The same with colour: the scene's textures, registered to the depth, or
 * with cfg->loop.has_calibration seen by its colour camera (the frames'
 * size; its lens too) from where T_colour_depth puts it. */
bf_status run_loop_colour(gpu_context *ctx, const recon_run_config *cfg, const synth_scene *sc,
                          const bf_se3 *true_pose, uint32_t n, const bf_se3 *offset, mutate_fn mutate, run_out *out);
/* RMS of the position error of a run's first n poses against true_pose [m]. */
double run_rms_error(const run_out *o, const bf_se3 *true_pose, uint32_t n);
/* 90th percentile of the distance from pts to the scene's mesh [m]. */
double surface_p90(const synth_scene *sc, const mesh_data *pts);

#endif
