/* tracking: camera tracking against the map (DESIGN.md section 6;
 * Newcombe et al. 2011 KinectFusion for projective point-to-plane ICP,
 * Reichl's dissertation ch. 8 for the perspective-adapted ROF filter).
 *
 * The reference is a depth image seen from a known pose: the ray-cast of
 * the map at the last pose (render/), or a raw frame. It is smoothed with
 * the ROF filter on its foreground (Chambolle's dual iteration, lambda
 * adapted to depth so near surfaces are smoothed more than far ones), and
 * turned into vertex and normal pyramids (3 levels). A new frame is tracked
 * by projective data association and point-to-plane ICP, coarse to fine;
 * each iteration reduces the 6x6 system on the GPU in partial sums and
 * solves it on the CPU in double.
 *
 * Frames come as raw depth on the GPU (fusion's incoming frame slot,
 * track_frame_gpu) or from the host (track_frame). A reference from the
 * GPU is written in place at track_reference_target (recon/'s ray-cast)
 * and prepared in the caller's submission (track_cmd_reference), so the
 * loop copies nothing. The sensor's noise model and range come from
 * track_config.sensor (the bf_sensor fusion gets too).
 *
 * Poses are camera to world in double. The GPU only ever sees the pose of
 * the new frame relative to the reference camera, so tracking 10 km from
 * the world origin is as accurate as at the origin. Rotations that come
 * in are replaced by the nearest rotation and the estimate is rigid to
 * rounding, so a closed loop (reference and guess at the last estimate)
 * cannot accumulate a non-orthonormal rotation; a rotation with det <= 0
 * is BF_INVALID_ARG.
 */
#ifndef BF_TRACKING_H
#define BF_TRACKING_H

#include "core/core.h"
#include "gpu/gpu.h"

typedef struct track_tracker track_tracker; /* opaque */

#define TRACK_MAX_LEVELS 3u

typedef struct track_config {
    uint32_t levels;                       /* pyramid levels, 1..3, default 3 */
    uint32_t iterations[TRACK_MAX_LEVELS]; /* per level, finest first, default 15, 5, 4 (KinectFusion: 10, 5, 4) */
    float dist_m;                          /* association distance gate, default 0.1 (finest level; x2 per level up) */
    float angle_deg;                       /* normal angle gate, default 45 (DESIGN.md: 20; docs/tracking.md) */
    float fine_angle_deg;                  /* the gate of the finest level's weighted iterations, default 30;
                                              0: angle_deg */
    bf_sensor sensor;                      /* noise model and range, default Kinect v1 (recon/ sets its own) */
    /* Failure and degeneracy (checked at the end of the finest level). */
    float min_inlier_frac;   /* inliers / valid samples of the frame below this: failure */
    float max_residual_m;    /* RMS point-to-plane residual of the inliers above this: failure, */
    float max_residual_sigma; /* when their RMS of r / sigma_z(z) is above this too (0: the metric gate alone) */
    float max_motion_m;      /* estimated motion from the guess beyond these: failure */
    float max_motion_deg;
    double degenerate_ratio; /* smallest / largest eigenvalue of the scaled system below this: degenerate */
    /* ROF smoothing of the reference (0 iterations: off, the default; 10 is the smoothing's design). */
    uint32_t rof_iterations;
    float rof_lambda0;       /* data weight at 1 m; lambda(z) per the dissertation */
    uint32_t rof_level;      /* pyramid level the ROF runs on: 0 full resolution, 1 half (default; the
                                finest level then keeps the unsmoothed depth, docs/tracking.md) */
    uint32_t ref_level;      /* the reference's finest level: 0 full resolution, 1 half (default: a
                                ray-cast of a quarter of the pixels, docs/tracking.md), 2 a quarter
                                (a sixteenth of the pixels; below levels). References on the
                                GPU then come at (width >> ref_level) x (height >> ref_level); frame
                                levels below it are associated with it. The ROF runs at
                                max(rof_level, ref_level). */
    /* Thresholds and sampling (docs/tracking.md has the reasons). */
    float min_valid_frac;    /* valid depth pixels / all below this: TRACK_NO_DEPTH (frame) or
                                TRACK_NO_REFERENCE (reference); default 0.01 */
    float converged_m;       /* a level stops iterating when the update moves less than this */
    float converged_deg;     /* and turns less than this; 0 and 0: always run all iterations */
    uint32_t finest_sample_step; /* 1: ICP uses every pixel of the finest level; 2: every second one (a
                                    checkerboard), half the cost; 4: every fourth, a quarter (the default;
                                    docs/tracking.md: speed against error) */
    /* Robust weights (iteratively reweighted least squares, docs/tracking.md). */
    float huber_k;           /* Huber threshold on the residual in units of sigma_z(z), default 3; 0: off */
    bool weight_noise;       /* weight residuals by the sensor's noise (sigma_z(1 m) / sigma_z(z))^noise_weight_exp,
                                default true */
    float noise_weight_exp;  /* 2: the inverse noise variance; smaller bounds how much less far samples count
                                (docs/real_frames.md, the noise weight's range); default 3 */
    bool huber_scaled;       /* the Huber threshold is huber_k times the inliers' RMS of r / sigma_z of the
                                level's previous iteration over huber_knee, when that is above 1: real depth
                                departs from the Gaussian model (docs/real_frames.md), default false */
    float huber_knee;        /* the RMS of r / sigma_z a frame that fits the model leaves against the map, >= 1,
                                default 1.3 (the synthetic room: median 1.0, 90th percentile 1.26) */
    /* Kernel shapes and diagnostics (docs/tracking.md): tuning for benchmarks and tests; every
       choice tracks to the same pose within float rounding. */
    uint32_t icp_local;         /* ICP invocations per workgroup, a power of two up to 64, default 64
                                   (fewer where the device allows fewer) */
    uint32_t icp_px_per_thread; /* finest-level pixels each ICP invocation walks, default 16 */
    bool icp_subgroup;          /* subgroup additions in the ICP reduction where the device has them
                                   (default); false: the shared-memory reduction */
    bool parent_normals;        /* the finest level's normals copied from level 1, default true */
    bool profile;               /* every image dispatch its own timed stage, printed to stderr; default false */
    /* The photometric term (docs/real_frames.md): in the iterations of the
     * photo_levels finest levels every inlier also compares its intensity with the
     * reference frame's (the frame the reference was made with, seen at its
     * pose), weighted by photo_weight (sigma_z(1 m) / photo_sigma)^2 against
     * the depth residuals' (sigma_z(1 m) / sigma_z(z))^noise_weight_exp, with
     * Huber's weight beyond huber_k photo_sigma. Needs the frames' colour
     * (track_set_frame_colour); 0: off. */
    float photo_weight;
    float photo_sigma;          /* the intensity noise, luma in [0, 1], default 0.03 */
    uint32_t photo_levels;      /* 1: the finest level only (default), up to levels: all; with
                                   photo_weak_ratio > 0 the finest level decides, so the finest only */
    /* The term is dropped for a frame (its finest level restarted without
     * it) when the frame's intensity gradient energy at the term's rows and
     * the reference's differ by more than this ratio, either way: one of the
     * two is blurred by the camera's motion and their intensities no longer
     * compare (docs/real_frames.md). Default 0.6; 0: never dropped. */
    float photo_sharpness_min;
    /* Where the term runs: 0, in every frame; above 0, only in frames whose
     * geometry leaves a direction weak: the finest level's first system,
     * solved on depth alone, has its smallest eigenvalue below this times
     * its largest (the scaled system of icp_subspace). Then that iteration
     * runs again with the term, and the colour constrains what the depth
     * cannot (a wall or a floor filling the view). Default 0.01. */
    float photo_weak_ratio;
} track_config;

track_config track_config_default(void);

typedef enum track_outcome {
    TRACK_OK = 0,
    TRACK_NO_DEPTH,      /* the frame has too few valid depth samples (empty, NaN, all zero) */
    TRACK_NO_REFERENCE,  /* no reference set, or it has too few valid pixels */
    TRACK_FEW_INLIERS,   /* too few associations passed the gates */
    TRACK_HIGH_RESIDUAL, /* the inliers do not fit */
    TRACK_LARGE_MOTION,  /* the estimate jumped beyond max_motion from the guess */
    TRACK_NUMERIC,       /* the system was singular or not finite */
} track_outcome;

const char *track_outcome_name(track_outcome o); /* "ok", "few-inliers", ... */

typedef struct track_result {
    track_outcome outcome;
    bool degenerate;     /* ill-conditioned (a single plane in view): weak directions kept from the guess */
    bf_se3 T_wc;         /* the estimate when outcome is TRACK_OK, else the guess */
    uint32_t n_valid;    /* valid samples of the frame at the finest level */
    uint32_t n_inliers;  /* associations that passed the gates, last iteration of the finest level */
    double inlier_frac;  /* n_inliers / n_valid */
    double residual_m;   /* RMS point-to-plane residual of the inliers */
    double residual_sigma; /* RMS of the inliers' residual / sigma_z(z): about 1 where the depth fits the
                              sensor model; the Huber unit when above 1 (track_config.huber_scaled) */
    double eig_min, eig_max; /* of the last system (rotation columns scaled by the scene depth) */
    double photo_sharpness; /* the frame's intensity gradient energy over the reference's at the photometric
                               term's rows (first finest-level iteration); 0 where the term did not run */
    bool photo_dropped;     /* the term was dropped for this frame (track_config.photo_sharpness_min) */
    bool photo_weak;        /* the term was brought in for weak geometry (track_config.photo_weak_ratio) */
    uint32_t iterations; /* run in all levels */
    double ms_gpu;       /* GPU time of the tracking (pyramids + ICP), ms */
    double ms_rof;       /* GPU time of the last reference smoothing, ms */
    double ms_frame;     /* GPU time of the frame's preprocessing (depth, pyramids, normals), ms; in ms_gpu */
    double ms_wall;      /* wall time of the frame's preprocessing and ICP (submissions, waits, solves), ms */
    double ms_ref;       /* GPU time of the last reference preparation (ROF, pyramids, normals), ms */
} track_result;

/* BF_INVALID_ARG naming the first value of c out of its range (what does
 * not depend on the camera; track_create checks the rest), so a command
 * line can be refused before any device opens. */
bf_status track_config_check(const track_config *c);
/* The smallest image side the tracker takes: its pyramid halves the image
 * c->levels times and needs two pixels a side at the coarsest. */
static inline uint32_t track_min_image_side(const track_config *c) { return 1u << (c->levels + 1); }
/* ctx is borrowed. Frames and references have K's size. */
bf_status track_create(gpu_context *ctx, const track_config *cfg, const bf_intrinsics *K, track_tracker **out);
void track_destroy(track_tracker *t); /* NULL is a no-op */

/* The reference, written in place (recon/: the ray-cast writes it there,
 * nothing is copied): where a depth image must be written to become the
 * reference, (width >> ref_level) x (height >> ref_level) floats (camera z
 * in metres, 0 = none) from pixel *offset of *buf. Valid until
 * track_destroy. */
bf_status track_reference_target(track_tracker *t, gpu_buffer **buf, uint64_t *offset);
/* Records, into the context's open command buffer (gpu_begin) after the
 * commands that wrote the target (they end with a barrier), the reference's
 * preparation seen from T_wc: ROF smoothing on its foreground, then the
 * vertex and normal pyramids. The caller submits, then calls
 * track_finish_reference; until then there is no reference. with_frame:
 * the frame just preprocessed is the one the reference is made with
 * (recon/ fuses it at T_wc and casts there), so its intensity becomes the
 * reference's for the photometric term; false: a reference from the map
 * alone (a relocalising candidate, a resume) keeps the intensity of the
 * last frame made one only if T_wc is exactly that frame's pose, and else
 * has none: the frame being searched for would otherwise be compared with
 * its own colour (or another pose's), which fits at any candidate pose. */
bf_status track_cmd_reference(track_tracker *t, const bf_se3 *T_wc, bool with_frame);
/* After the submission holding track_cmd_reference finished: the reference
 * takes effect (its valid pixels counted, its pose kept). */
bf_status track_finish_reference(track_tracker *t);
/* Sets the reference from a depth image on the GPU (float camera z in
 * metres per pixel, 0 = none; render_targets.depth) seen from T_wc, in a
 * submission of its own: the image is copied to the target, then as
 * track_cmd_reference. The buffer is read now and may change afterwards. */
bf_status track_set_reference_gpu(track_tracker *t, gpu_buffer *depth, const bf_se3 *T_wc);
/* Sets the reference from a raw frame (frame-to-frame tracking, tests):
 * the same path after converting its depth to metres. */
bf_status track_set_reference_frame(track_tracker *t, const bf_frame *f, const bf_se3 *T_wc);

/* Tracks frame f against the reference, starting from guess_wc. Returns
 * BF_OK whenever tracking ran (out->outcome says how it went) and an error
 * only for bad arguments or a device failure. Uploads f's depth to the
 * tracker's own buffer, then as track_frame_gpu. */
bf_status track_frame(track_tracker *t, const bf_frame *f, const bf_se3 *guess_wc, track_result *out);
/* Tracks a frame whose raw depth is already on the GPU: width x height
 * uint16 in K's depth units, two per word (the lower half first), from byte
 * offset `offset` (a multiple of 4) of `depth` (recon/: fusion's incoming
 * frame slot, so the frame is uploaded once). index names the frame in
 * messages. The image must stay there until this returns. */
bf_status track_frame_gpu(track_tracker *t, gpu_buffer *depth, uint64_t offset, uint32_t index,
                          const bf_se3 *guess_wc, track_result *out);

/* The colour camera for the photometric term: Kc (the colour image has the
 * depth image's size), dist (k1 k2 p1 p2 k3, OpenCV's order; NULL: none) and
 * T_colour_depth, which takes depth-camera points to colour-camera points.
 * Kc NULL: colour pixel i shows what depth pixel i measured (the default). */
bf_status track_set_colour_camera(track_tracker *t, const bf_intrinsics *Kc, const double *dist,
                                  const bf_se3 *T_colour_depth);
/* Where the colour of the frames tracked from now on is: RGB565, two per
 * word (the lower half first), the depth image's size, from byte offset
 * `offset` (a multiple of 4) of `buf` (recon/: fusion's incoming slot, next
 * to the depth); buf NULL: the frames have no colour. The frame's
 * intensity pyramid is made with its depth's (track_frame_gpu,
 * track_cmd_frame), so the colour must be there until then; a reference
 * recorded after that frame (track_cmd_reference) keeps its intensity for
 * the photometric term of the frames that follow. */
bf_status track_set_frame_colour(track_tracker *t, gpu_buffer *buf, uint64_t offset);
/* Scales the motion gate of the frames tracked from now on: a result
 * further than scale * max_motion_m or scale * max_motion_deg from its
 * guess is TRACK_LARGE_MOTION. recon/ passes the frame intervals elapsed
 * since its last good frame (capped), so a camera found again after a gap
 * may have moved as far as that time allows; 1 restores the config's gate.
 * BF_INVALID_ARG unless scale is finite and >= 1. */
bf_status track_set_motion_scale(track_tracker *t, double scale);
/* Records, into the context's open command buffer (gpu_begin), the
 * preprocessing of a frame whose raw depth is on the GPU (as for
 * track_frame_gpu) without tracking it: its depth in metres and pyramids,
 * ending with a barrier, so commands recorded after it may read
 * track_frame_depth_gpu's images (recon/: the first frame's reference
 * ray-cast starts at its depth, as every tracked frame's does). The caller
 * submits; the image must stay there until then. */
bf_status track_cmd_frame(track_tracker *t, gpu_buffer *depth, uint64_t offset, uint32_t index);

/* The depth pyramid of the last frame track_frame saw, on the GPU: level l
 * is (width >> l) x (height >> l) floats (metres, 0 = none) from pixel
 * *offset of *buf (recon/ starts the reference's ray-cast there). Valid
 * until the next track_frame. BF_INVALID_ARG before any frame or for a
 * level beyond the pyramid. */
bf_status track_frame_depth_gpu(track_tracker *t, uint32_t level, gpu_buffer **buf, uint64_t *offset);

/* The smoothed reference depth at its finest level (the level it came in
 * at: ref_level for a GPU reference, 0 for a frame), (width >> l) * (height
 * >> l) floats, for tests and snapshots. */
bf_status track_download_reference(track_tracker *t, float *depth);

#endif
