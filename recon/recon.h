/* recon: the full reconstruction loop of one sequence (DESIGN.md section 1):
 * track the frame against the ray-cast of the map, fuse it at the pose
 * found, ray-cast the map at that pose as the next frame's reference (ROF
 * smoothing of it is off by default: track_config.rof_iterations 0).
 * recon_run_sequence runs it over a whole source with the
 * policies every caller shares (first pose, pose source, failures, Ctrl-C);
 * `bitfuse replay`, `live`, `fuse`, `demo`, the tests and the soak
 * benchmark all go through it.
 *
 * Per frame the host waits once per ICP iteration and once for the rest:
 * the frame goes up once (fusion's incoming slot, read by tracking), and
 * fusion, the ray-cast (written straight into the tracking reference) and
 * the reference's pyramids (and its ROF, when on) share one submission
 * (DESIGN.md section 1).
 *
 * Frames tracked badly are not fused (the map stays as it was) and the
 * camera keeps its last good pose; frames without depth are skipped. Both
 * are reported per frame and counted. A lost camera (or one coming back
 * from a gap without depth) is looked for from a few candidate poses per
 * frame and found again (RECON_RELOCALISED) when one fits clearly
 * (recon_reloc_config).
 */
#ifndef BF_RECON_H
#define BF_RECON_H

#include <signal.h>

#include "calib/calib.h"
#include "capture/capture.h"
#include "core/core.h"
#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "render/render.h"
#include "store/store.h"
#include "stream/stream.h"
#include "tracking/tracking.h"

typedef struct recon recon; /* opaque */

/* Relocalisation (recon/reloc.c, DESIGN.md section 6): finding the map
 * again after tracking failed or the depth went away for a while. */
typedef struct recon_reloc_config {
    bool enabled;              /* default true; false: a lost camera keeps the last good pose and is tracked
                                  from there against the reference at that pose, with the per-frame gate */
    uint32_t max_candidates;   /* candidate poses tried per frame (a ray-cast and an ICP each), default 4 */
    float max_gate_intervals;  /* the motion gate grows with the frame intervals since the last good frame,
                                  up to this many times the per-frame gate, default 4; after a longer gap
                                  the frame is searched for as if lost, unless the loop is behind a camera
                                  (recon_set_behind) that gave depth in every frame since: then it is
                                  tracked from the guess with the gate at its cap first, and searched for
                                  when that fit fails a candidate's test */
    float keyframe_m;          /* a good frame this far from every keyframe becomes one, default 0.1 */
    float keyframe_deg;        /* or turned this far, default 10 */
    uint32_t max_keyframes;    /* kept, default 64; beyond, the one nearest to two others is replaced */
    float min_inlier_frac;     /* a candidate is taken only with this inlier fraction, default 0.35 */
    float max_residual_m;      /* and at most this residual, default 0.018, */
    float max_residual_sigma;  /* or its RMS in units of sigma_z(z) at most this, default 2.5 (0: the metric
                                  bound alone): far views fit to 18-21 mm at 1.9-2.3 sigma (docs/tracking.md) */
    /* The agreement check of a candidate that passed the above (reloc.c): the frame's samples that land
       on reference pixels with depth (covered), compared with that depth. */
    uint32_t check_step;       /* every check_step-th pixel of every check_step-th row, default 2 */
    float check_band_m;        /* a sample within this plus 3 sigma_z of the predicted depth agrees, default 0.02 */
    float max_front_frac;      /* the candidate is taken only when at most this fraction of the covered lies in
                                  front of the predicted surface (where the map holds free space), default 0.03 */
    /* Candidates from colour (features/): each keyframe keeps the ORB keypoints of its colour image lifted by
       its depth; a searching frame's keypoints are matched to them and PnP with RANSAC gives a pose wherever
       the frame sees what a keyframe saw, however far from it. With has_calibration the keypoints are the
       colour camera's own, lifted by the depth that camera sees (calib_points_on_colour). These candidates
       come on top of max_candidates. */
    uint32_t features;            /* ORB keypoints per image, default 1000; 0: no colour candidates */
    uint32_t feature_candidates;  /* the poses of the keyframes with most PnP inliers tried first, default 2 */
    uint32_t feature_min_inliers; /* a keyframe's pose counts with at least this many inliers, default 20 */
    bool last_frame;              /* a frame right after a good one whose fit to the map is weak (inliers below
                                     last_frame_below) or that no candidate finds is tracked against that frame's
                                     own depth from its pose (a fast turn into what the map has barely seen), and
                                     takes that pose when it passes the candidates' gates with more inliers;
                                     default true */
    float last_frame_below;       /* default 0.45: TUM fr1/rpy's four starts 12.8 mm mean ATE at 0.45 and 0.5
                                     against 13.6 at 0.35, 12.9 at 0.6, 15.7 at 0.7; the 7-Scenes dev frames fit
                                     the map at 0.56 or more and, taken on the frame before below 0.65, drift
                                     (mean ATE 33.5 mm against 26.9): kept clear of them (docs/tracking.md) */
} recon_reloc_config;

/* track.ref_level for the loop's tracking reference: the coarsest pyramid
 * level, at most 2, whose image is still at least RECON_REF_MIN_WIDTH pixels
 * wide (160x120 for a 640x480 camera, 160x120 for 320x240). */
#define RECON_REF_LEVEL_AUTO UINT32_MAX
#define RECON_REF_MIN_WIDTH 160u

/* fuse_every's bound: beyond, the reference a frame is tracked against
 * would be seconds old at a camera's rate. */
#define RECON_MAX_FUSE_EVERY 64u

typedef struct recon_config {
    bf_sensor sensor;         /* the depth sensor, default Kinect v1: recon_create hands it to fusion and
                                 tracking (the sensor fields of .fusion and .track are not read) */
    fusion_config fusion;     /* fusion's defaults but voxel_ratio 2 (docs/bench_replay_sweep.md) */
    track_config track;       /* its ref_level may be RECON_REF_LEVEL_AUTO (the default): see there */
    render_options raycast;   /* the tracking reference's ray-cast: refined, from the voxels
                                 reference_confident says */
    bool reference_confident; /* once the map's first fusion window has closed, the tracking reference is
                                 cast from confident voxels only (raycast.confident_only then), the way the
                                 views show the map; before it, from every sign bit. The relocalising search's
                                 casts keep every sign bit. Default true: the real dev frames' four starts give a
                                 mean ATE of 22.9 against 27.2 mm with it (the colour's motion agrees), fr1/rpy the
                                 same; it costs fr1/xyz 11.7 against 10.9, the synthetic room 1.3 against 1.1, and
                                 short windows (a thin first window) a frame found by a search (docs/tracking.md,
                                 "The confident map as the reference") */
    render_config caster;     /* how the loop's casters are built (render's defaults) */
    uint32_t min_valid_pixels; /* a frame with fewer valid depth samples (within the sensor's range) is skipped, default 1% of the image */
    bool fuse_degenerate;     /* fuse frames tracked with a degenerate system (weak directions kept), default true */
    bool constant_velocity;   /* the tracker's guess is the last pose moved on by the last motion per frame
                                 interval over the intervals since the last good frame, not the last pose
                                 (docs/tracking.md, the guess); default true. A step per interval beyond
                                 the tracker's per-frame gate found by a search (a jump) is not continued */
    bool skip_repeated;       /* a frame whose depth is the last depth's byte for byte (a driver that handed on
                                 its last image when a new one was late: 47 of 7-Scenes' 500 dev frames) is
                                 neither tracked nor fused and keeps the last pose, with known poses too; one
                                 whose colour alone repeats is tracked and fused without it (core.h,
                                 bf_repeats); default true */
    /* Tracking every frame, fusing fewer (recon.c, accept): a tracked frame is fused only when it is the
       fuse_every-th since the last fused one; the others are tracked against the reference the last fused
       frame left and only move the pose on. Frames found by a search or on the frame before, frames fused
       at known poses, and any frame after something else became the reference, are always fused. Small
       steps are what ICP tracks: a camera behind which a slow machine drops three of every four frames
       loses a fast turn that the same frames all tracked, a quarter of them fused, hold (docs/tracking.md,
       "Tracking every frame, fusing fewer"). */
    uint32_t fuse_every;        /* default 1: every tracked frame fused */
    uint32_t fuse_every_behind; /* the same while frames wait in a queue that drops (a camera the loop is behind:
                                   recon_set_behind, set by the runner per frame); the larger of the two applies;
                                   default 4; 1: the loop keeps fusing every frame and the queue drops them */
    recon_reloc_config reloc;
    stream_config stream;     /* chunks out of the GPU pools and back (stream.h): on by default; far chunks leave
                                 only beyond its radius or when the pools fill */
    bool start_at_frame;      /* the reference's rays start just in front of the frame's depth (the first frame's
                                 too: track_cmd_frame), default true */
    bool has_views;           /* views at the camera's size will be asked for (recon_render_view): their caster is
                                 made by recon_create with the rest, not at the first view; default false */
    bool has_calibration;     /* calibration holds a calib.json (--calibration); default false */
    calib_result calibration; /* the colour camera and T_colour_depth for registering colour to depth (the
                                 depth camera's pinhole, when the file has it, is already the source's) */
} recon_config;

recon_config recon_config_default(void);
/* Registers colour to depth in map through cfg's calibration (colour
 * intrinsics and distortion, T_colour_depth); without one colour stays
 * registered (fusion_set_colour_camera). */
bf_status recon_set_colour_camera(fusion_map *map, const recon_config *cfg);
/* The fusion config the loop uses: cfg->fusion with the loop's sensor (also
 * for fusing at known poses without the loop). */
fusion_config recon_fusion_config(const recon_config *cfg);
/* The loop's tracking reference level for this camera: tc->ref_level, or
 * what RECON_REF_LEVEL_AUTO resolves to. */
uint32_t recon_ref_level(const bf_intrinsics *K, const track_config *tc);
/* The depth samples a frame of a w x h camera needs to be tracked
 * (cfg->min_valid_pixels, or its default: 1% of the image). */
uint32_t recon_min_valid_pixels(const recon_config *cfg, uint32_t width, uint32_t height);

/* What happened to one frame. */
typedef enum recon_frame_state {
    RECON_FIRST = 0,  /* the first frame: fused at the initial pose */
    RECON_TRACKED,    /* tracked and fused (with fuse_every or behind a camera, some tracked only: fused false) */
    RECON_NO_DEPTH,   /* too few valid depth samples: skipped */
    RECON_LOST,       /* tracking failed (result.track.outcome says why): not fused */
    RECON_RELOCALISED, /* lost (or after a gap), found again from a candidate pose: fused */
    RECON_REPEATED,   /* the depth repeats the previous frame's byte for byte (skip_repeated): no new data,
                         neither tracked nor fused, the last pose kept */
} recon_frame_state;

const char *recon_state_name(recon_frame_state s);
/* Says whether newer frames already wait for the loop in a queue that drops
 * (a camera it is behind): the frames added from now on are fused at the
 * cadence of fuse_every_behind instead of fuse_every, and a gap beyond
 * reloc.max_gate_intervals is tracked before it is searched for (the queue
 * dropped the frames between). The runner sets it before each frame from
 * its capture thread's queue. */
void recon_set_behind(recon *r, bool behind);
/* True for the states where ICP ran (tracked, lost, relocalised). */
bool recon_state_ran_icp(recon_frame_state s);

/* Where a relocalising search started ICP from. */
typedef enum recon_reloc_kind {
    RECON_RELOC_NONE = 0, /* no candidate was taken */
    RECON_RELOC_LAST,     /* the last good pose */
    RECON_RELOC_VELOCITY, /* the last tracked motion continued over the frames elapsed */
    RECON_RELOC_TURNED,   /* one of those two turned by 10 or 20 degrees (yaw or pitch) */
    RECON_RELOC_KEYFRAME, /* a keyframe's pose */
    RECON_RELOC_FEATURES, /* the pose PnP found from the colour's keypoints matched to a keyframe's */
    RECON_RELOC_FRAME,    /* tracked against the previous good frame's depth (reloc.last_frame) */
} recon_reloc_kind;

/* "", "last", "velocity", "turned", "keyframe", "features", "frame" */
const char *recon_reloc_kind_name(recon_reloc_kind k);

typedef struct recon_frame_result {
    uint32_t index;          /* the frame's index */
    recon_frame_state state;
    bf_se3 T_wc;             /* the frame's pose: tracked, or the last good one */
    track_result track;      /* valid where recon_state_ran_icp: a search's best candidate */
    uint32_t reloc_tried;    /* candidate poses tried by a relocalising search this frame, the frame before
                                (reloc.last_frame) among them when tried after the search or taken */
    recon_reloc_kind reloc;  /* RECON_RELOCALISED: the candidate the pose was found from; RECON_TRACKED:
                                RECON_RELOC_FRAME when tracked against the frame before, else none */
    uint32_t reloc_rejected; /* candidates that passed the tracker's gates but disagreed with the map */
    bool fused;
    bool colour_repeated;    /* the colour repeated the previous frame's (skip_repeated): left out */
    bf_status fuse_status;   /* BF_POOL_FULL is reported here and the loop goes on */
    uint32_t n_valid;        /* valid depth samples: a reading within the sensor's range */
    /* Times [ms]: wall clock of the whole frame and GPU time per stage. */
    double ms_frame;
    double ms_track, ms_rof, ms_raycast;
    double ms_stream;        /* the streaming check after the frame (wall clock; 0 when not due) */
    fusion_stage_ms fuse;
} recon_frame_result;

/* T_wc0 is the first frame's pose (the map's origin goes there). Makes
 * everything the loop will use: the map with its pools, the tracker, the
 * reference's caster (and the views' with cfg->has_views), each with its
 * pipelines compiled and run once (gpu_pipeline_warm_up), so no frame
 * waits for a compiler and a camera can start after this returns (DESIGN.md
 * section 1). ctx is borrowed and must outlive the loop. */
bf_status recon_create(gpu_context *ctx, const recon_config *cfg, const bf_intrinsics *K, const bf_se3 *T_wc0,
                       recon **out);
void recon_destroy(recon *r); /* NULL is a no-op */

/* Runs the loop on one frame. Errors are device failures and bad
 * arguments only; tracking failures and pool exhaustion are in *out. */
bf_status recon_add_frame(recon *r, const bf_frame *f, recon_frame_result *out);
/* The tracker's own error, without drift: the frame is tracked against the
 * map as above (out->T_wc is the estimate), but fused at T_known, also when
 * tracking fails (state RECON_LOST, fused true), and T_known becomes the
 * next frame's guess and reference pose; a repeated depth is neither
 * tracked nor fused (skip_repeated), so the next frame is tracked from the
 * last true pose fused. With the true
 * poses the map is the one the sensor would give, and each estimate's error
 * is one step's (`bitfuse replay --fuse-at-groundtruth`). */
bf_status recon_add_frame_known(recon *r, const bf_frame *f, const bf_se3 *T_known, recon_frame_result *out);
/* Integrates what the fusion schedule still owes (end of sequence). */
bf_status recon_flush(recon *r);
/* Sets the first frame's pose when it becomes known after recon_create (the
 * runner makes the loop before the source delivers, then reads the pose
 * from the first frame): T_wc0 of recon_create, and the map's origin.
 * BF_INVALID_ARG once a frame with depth was added; nothing changes then. */
bf_status recon_set_first_pose(recon *r, const bf_se3 *T_wc0);

/* Continues a stored scan (a reopened scene store, store/): loads its map
 * into the loop's empty map (fusion_load; the map's origin becomes the
 * stored one), makes T_last the last good pose, the stored keyframes kf
 * keyframes (or, when kf is NULL or empty, the poses of traj, which may
 * be NULL), and the ray-cast of the map at T_last the tracking
 * reference, so that the next frame is tracked against the stored map
 * rather than fused as a first frame. last_index is the stored scan's last
 * frame index (the motion gate counts frame intervals from it). Before any
 * frame: BF_INVALID_ARG after one; fusion_load's errors. */
bf_status recon_resume(recon *r, const hostmap *map, const bf_se3 *T_last, uint32_t last_index, const bf_traj *traj,
                       const store_keyframes *kf);
/* The relocalisation keyframes held now, each with its colour's lifted
 * keypoints (none where colour candidates are off), for the scene store's
 * keyframes.bin; free *out with store_keyframes_free. */
bf_status recon_keyframes(const recon *r, store_keyframes *out);
/* Changes whenever a keyframe is added or replaced: a caller that keeps
 * them (the scene store) takes them again only when it moved. */
uint64_t recon_keyframes_generation(const recon *r);
/* The whole map as a host copy (for export and the scene store): the
 * pools' bricks and those streamed out of them. */
bf_status recon_snapshot(recon *r, hostmap *out);
/* The streaming counts (zero when streaming is off). */
stream_stats recon_stream_stats(const recon *r);
/* The stream's first failed spill (the scan went on with the chunk in
 * memory: stream_spill_error), or NULL. */
const char *recon_stream_spill_error(const recon *r);
/* The map (made by recon_create; empty before the first frame with depth)
 * and the caster at the camera's size, for export, statistics and views
 * (NULL when it cannot be made; bf_last_error says why). */
fusion_map *recon_map(recon *r);
render_caster *recon_caster(recon *r);
/* Ray-casts the map for display at T_wc into the caster's images;
 * render_download gets them. Confident voxels only once the map has some
 * (its first window integrated, fusion_windows_done); before that every
 * sign bit, so a view shows the map from the first frame. */
bf_status recon_render_view(recon *r, const bf_se3 *T_wc);

/* Running counts. */
typedef struct recon_counts {
    uint32_t frames, tracked, lost, no_depth, degenerate, pool_full;
    uint32_t repeated;    /* frames whose depth repeated the previous one's (skip_repeated) */
    uint32_t colour_repeated; /* frames whose colour alone repeated: tracked and fused on depth alone */
    uint32_t relocalised; /* frames found again by a search (also counted in tracked) */
    uint32_t last_frame;  /* frames tracked against the last good frame's depth (reloc.last_frame; also counted
                             in tracked) */
    uint32_t unfused;     /* good frames tracked but not fused (fuse_every, fuse_every_behind; also in tracked) */
    uint32_t behind;      /* frames added while the loop was behind a camera (recon_set_behind) */
    uint32_t photo_weak;  /* good frames whose depth left a direction weak: the photometric term came in
                             (track_config.photo_weak_ratio) */
    uint32_t keyframes;   /* keyframes held now */
} recon_counts;
recon_counts recon_get_counts(const recon *r);

/* ------------------------------------------------------------ the runner
 * One sequence through the loop (recon/runner.c), with the policies in one
 * place:
 * - first pose: the ground truth of the frame that starts the map (the
 *   first with depth in range) when it has one (else the identity), or
 *   the identity with init_identity;
 * - pose source: track (the loop), track but fuse at the frames' ground
 *   truth (recon_add_frame_known), or fuse at known poses without tracking;
 * - a source that fails mid-sequence (a device unplugged) ends the run like
 *   its end when keep_on_source_error: what was reconstructed is flushed
 *   and the failure is reported in source_status;
 * - a progress line, per-frame warnings for lost and skipped frames, and a
 *   stop flag (Ctrl-C) checked before each frame. */

typedef enum recon_pose_source {
    RECON_POSES_TRACK = 0,    /* track every frame, fuse at the pose found */
    RECON_POSES_TRACK_FUSE_GT, /* track every frame (a repeated depth skipped), fuse at its ground truth: the
                                  tracker's one-step error */
    RECON_POSES_KNOWN,        /* no tracking: fuse at known poses, skip frames without one; a full
                                 pool fails the run (the loop drops and counts instead) */
} recon_pose_source;

/* A stored scan to continue (recon_resume): borrowed for the run. */
typedef struct recon_resume_state {
    const hostmap *map;
    bf_se3 T_last;             /* its last good pose */
    double t_last_s;           /* the depth time of its last frame: the source's frames up to it are skipped */
    const bf_traj *traj;       /* its poses so far: the run's estimates start with them; may be NULL */
    const store_keyframes *keyframes; /* its relocalisation keyframes (keyframes.bin); may be NULL */
} recon_resume_state;

typedef struct recon_run_config {
    recon_config loop;
    recon_pose_source poses;
    bool init_identity;        /* start at the identity even when the first frame has ground truth */
    const bf_traj *known;      /* RECON_POSES_KNOWN: poses interpolated at the depth timestamps; NULL: the
                                  frames' own ground truth. Borrowed for the run. */
    bool keep_on_source_error; /* see above; otherwise a source failure is the run's failure */
    const char *name;          /* the source in messages (its path or URI), default "sequence" */
    const char *label;         /* the progress line's and warnings' prefix, default "recon" */
    const volatile sig_atomic_t *stop; /* non-zero ends the run before the next frame; may be NULL */
    const recon_resume_state *resume; /* continue a stored scan: frames of the source with a depth time up to
                                         resume->t_last_s are skipped (their ground truth still counts); NULL:
                                         a new scan. Not with RECON_POSES_KNOWN. */
    /* The depth camera's fixed error pattern taken out of every frame before
     * anything reads it (calib_depth_correction, --depth-correction); its size
     * must be the source's. NULL: the depth as the source gives it. Borrowed. */
    const calib_depth_correction *depth_correction;
    /* The depth camera whose lens is taken out of every frame's depth first
     * (calib_undistort_map, nearest pixel), for a source that gives its
     * frames as the lens made them (a device, a log) while a calibration
     * has the depth camera's distortion; a folder takes out its own. Its
     * size must be the source's. NULL, or no distortion: none. Borrowed. */
    const calib_camera *depth_lens;
} recon_run_config;

/* recon_config_default(), tracking, first pose from ground truth. */
recon_run_config recon_run_config_default(void);

/* Per-frame series over the run: one sample per frame where the stage ran. */
typedef struct recon_run_series {
    bf_stats frame_ms;                      /* wall clock of the whole frame */
    bf_stats track_ms, inlier_frac, residual_mm; /* tracked or lost frames; residual of tracked ones only */
    bf_stats rof_ms, raycast_ms;            /* fused frames with a loop */
    bf_stats upload_ms, alloc_ms, subcache_ms, window_ms, colour_ms; /* fused frames */
} recon_run_series;

/* What a run made. Filled also when the run fails; recon_run_free
 * releases it either way. */
typedef struct recon_run {
    recon *loop;         /* the loop; NULL with RECON_POSES_KNOWN */
    fusion_map *map;     /* the map: the loop's, or the run's own with known poses; made before the first frame */
    recon_counts counts; /* the loop's counts; with known poses frames, pool_full, repeated and colour_repeated */
    uint32_t n_fused, n_skipped; /* RECON_POSES_KNOWN: frames fused; both known-pose modes: frames without a pose */
    double depth_scale;  /* the source's raw depth units per metre */
    uint32_t n_resume_skipped; /* frames of the source the resumed scan had handled already */
    bf_repeats repeats;  /* RECON_POSES_KNOWN with skip_repeated: the last images (the loop keeps its own) */
    bool is_resumed;     /* the run continues a stored scan (recon_run_config.resume) */
    bool has_depth_lens; /* the runner took recon_run_config.depth_lens's lens out of each frame's depth: */
    double depth_lens_dist[CALIB_DIST_N]; /* its coefficients */
    double depth_lens_shift_px;           /* the largest distance a pixel moved */
    bf_traj est;         /* one pose per frame handled: tracked, the last good one, or the known one */
    bf_traj gt;          /* the frames' ground truth, where they have it */
    recon_run_series series;
    bool is_interrupted; /* the stop flag ended the run */
    bf_status source_status; /* keep_on_source_error: the failure that ended the run early, else BF_OK */
    char source_error[1024]; /* its message */
    /* Start-up: bf_time_s() when the loop was ready (every pipeline compiled, the pools allocated; the
       source's first frame is asked for after it) and when the first frame was done (0: none), and the
       loop's wall time of that frame [ms]. */
    double t_ready_s, t_first_done_s;
    double first_frame_ms;
} recon_run;

/* Called after every frame the run handles (frames skipped for want of a
 * known pose excepted); a status other than BF_OK ends the run with it.
 * With known poses fr->state is RECON_FIRST, RECON_TRACKED or (a repeated
 * depth, not fused) RECON_REPEATED, and fr->T_wc the known pose. f is
 * the frame as the source gave it, before the run's depth_lens and
 * depth_correction (what live --record keeps). */
typedef bf_status (*recon_frame_fn)(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr);

/* Runs every frame of src (borrowed) through the loop and flushes the map.
 * The loop (or the map) is made before the first frame is asked for, at
 * the identity; the first pose policy above then moves it. ctx is borrowed
 * and must outlive *out. on_frame may be NULL. Fails with
 * the source's or the loop's status, BF_FORMAT when no frame had depth (or
 * a pose), or no ground truth for RECON_POSES_TRACK_FUSE_GT. */
bf_status recon_run_sequence(gpu_context *ctx, rgbd_source *src, const recon_run_config *cfg, recon_frame_fn on_frame,
                             void *user, recon_run *out);
void recon_run_free(recon_run *run);

#endif
