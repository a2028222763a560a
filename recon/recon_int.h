/* Declarations shared by recon/'s files (SQLite's btreeInt.h idea). */
#ifndef BF_RECON_INT_H
#define BF_RECON_INT_H

#include "features/features.h"
#include "recon.h"

struct recon {
    gpu_context *ctx;
    recon_config cfg;
    bf_intrinsics K;
    bf_se3 T_first;      /* pose of the first frame with depth */
    bf_se3 T_last;       /* last good pose */
    fusion_map *map;     /* made at create, at T_first's origin */
    bool has_first;      /* the first frame with depth has been fused */
    bool frame_fused;    /* the tracker's frame (this add_frame's) was fused, or tracked only, at T_frame: a
                            view at that pose starts its rays at the frame's depth, as the reference does */
    bf_se3 T_frame;
    bool ref_is_map;     /* the tracking reference is the map's ray-cast at the last fused pose (fuse_and_reference),
                            not a candidate's or the frame before's: a frame may be tracked only against it */
    uint32_t since_fused; /* good frames tracked only since the last fused one (fuse_every) */
    bool is_behind;      /* recon_set_behind */
    bf_intrinsics K_ref; /* the tracking reference's camera: K at track.ref_level */
    render_caster *ref_caster; /* the reference's ray-casts, K_ref's size */
    render_caster *caster;     /* views at K's size: ref_caster when they agree, else made at create (has_views)
                                  or at the first view */
    track_tracker *tracker;
    stream *stream;      /* cfg.stream.enabled: the map's chunks in and out of the pools */
    recon_counts counts;

    /* Relocalisation (reloc.c). */
    bool is_lost;        /* the last frame with depth failed: the next one searches */
    uint32_t good_index; /* the last good frame's index and depth time */
    double good_t_s;
    double dt_s;         /* the frame interval: the last step between two consecutive good frames; 0 unknown */
    bf_se3 V_step;       /* the motion per frame interval over the last good step (kept while lost) */
    bool has_velocity;   /* V_step was measured */
    bf_se3 *keyframes;   /* reloc.max_keyframes poses, allocated at create */
    features_set **kf_features; /* each keyframe's lifted ORB keypoints, or NULL (no colour, or none asked) */
    uint64_t kf_generation;      /* counts keyframes added or replaced: the store writes them when it moved */
    uint32_t n_keyframes; /* held */
    uint32_t reloc_cursor; /* the round robin's next entry (reloc.c) */
    float *ref_host;       /* K_ref's pixels: a candidate's reference depth read back for its check */
    uint16_t *good_depth;  /* reloc.last_frame: the last good frame's depth (K's size), the reference a frame
                              right after it is tracked against when its fit to the map is weak or fails (a
                              copy: the source reuses its buffers; 0.6 MB at 640x480, next to the frame's ms) */
    bool has_good_depth;
    bool depthless_since_good; /* a frame without depth came after the last good one: its view is not the
                                  camera's last */

    /* skip_repeated: the last images, to find the frames that repeat them. */
    bf_repeats repeats;
};

/* reloc.c */
/* T_last moved on by n frame intervals of V_step. */
bf_se3 recon__velocity_pose(const recon *r, double n);
/* f's depth samples the loop can use: a reading within max_depth_m
 * (depth_scale raw units a metre). */
uint32_t recon__depth_in_range(const bf_frame *f, double depth_scale, float max_depth_m);
/* Whether a fit passes what a search's candidate must: no degeneracy, at
 * least reloc.min_inlier_frac inliers, the residual within
 * reloc.max_residual_m (or max_residual_sigma). */
bool recon__passes(const recon *r, const track_result *t);
/* reloc.last_frame: a frame right after a good one (nothing lost or
 * without depth between them, frames a live queue dropped allowed up to
 * the gate's cap), tracked against that frame's depth from its pose with
 * the candidates' gates, when its fit to the map is weak or no candidate
 * found it; *found when it passes (out->track is then its result,
 * out->reloc RECON_RELOC_FRAME). */
bf_status recon__track_last_frame(recon *r, const bf_frame *f, const fusion_frame_slot *slot, double n,
                                  recon_frame_result *out, bool *found);
/* The colour camera of --calibration and T_colour_depth; NULL where the
 * colour is registered to the depth (no calibration). */
const calib_camera *recon__colour_rig(const recon_config *cfg, bf_se3 *T_colour_depth);
bf_status recon__reloc_create(recon *r);  /* the keyframe store; checks cfg.reloc */
void recon__reloc_destroy(recon *r);
/* Frame intervals from the last good frame to f: by the depth timestamps
 * when the interval is known, else by frame indices; at least 1. */
double recon__intervals(const recon *r, const bf_frame *f);
/* The tracker's motion gate for a frame n intervals after the last good
 * one: n times the per-frame gate, capped by reloc.max_gate_intervals. */
bf_status recon__set_gate(recon *r, double n);
/* A good frame at T_new (tracked, first, relocalised): the interval and
 * velocity estimates, and a keyframe when it is far from every keyframe
 * (may_keyframe false: a degenerate pose is not one). */
void recon__good_frame(recon *r, const bf_frame *f, const bf_se3 *T_new, bool may_keyframe);
/* T becomes a keyframe unless it is within a keyframe spacing of one; once
 * reloc.max_keyframes are held it replaces the one the store misses least
 * (whose two nearest others are nearest together). f, the frame seen
 * there (or NULL), gives the keyframe its colour's keypoints. */
void recon__add_keyframe(recon *r, const bf_se3 *T, const bf_frame *f);
/* The keyframes held, with their lifted keypoints, as a store keeps them
 * (*out freed by store_keyframes_free), and back: stored keyframes join as
 * keyframes do (one near a held one is left out), their keypoints only
 * where colour candidates are on. */
bf_status recon__keyframes_export(const recon *r, store_keyframes *out);
void recon__keyframes_import(recon *r, const store_keyframes *k);
/* The agreement check's verdict on one frame sample landing at (x, y) of
 * the reference depth ref (w x h, metres, 0: none) with depth z in the
 * reference camera: off the reference or where it has no depth, within
 * band_m + 3 sigma_z of the surface there, in front of it or behind it,
 * judged against the nearest and the farthest of the four reference
 * pixels around (x, y). */
typedef enum recon__agreement_class {
    RECON_SAMPLE_OFF,
    RECON_SAMPLE_AGREE,
    RECON_SAMPLE_FRONT,
    RECON_SAMPLE_BEHIND
} recon__agreement_class;
recon__agreement_class recon__classify_sample(const float *ref, uint32_t w, uint32_t h, double x, double y,
                                              double z, const bf_sensor *sn, double band_m);
/* A candidate pose from colour (PnP against a keyframe) and its inliers. */
typedef struct recon__colour_pose {
    uint32_t n_inliers;
    bf_se3 T_wc;
} recon__colour_pose;
/* best[0..*n) by inliers, most first, no two the same pose (within 5 cm
 * and 5 degrees), at most cap: p joins unless a pose with as many inliers
 * repeats it, and the poses with fewer that repeat it leave first, so a
 * distinct one is never pushed out for a repeat. */
void recon__keep_pose(recon__colour_pose *best, uint32_t *n, uint32_t cap, const recon__colour_pose *p);
/* Searches for frame f (its raw depth at slot) from at most
 * reloc.max_candidates candidate poses, n intervals after the last good
 * frame, each with the per-frame motion gate; skip names a candidate already tried from the reference at
 * T_last (RECON_RELOC_NONE: none). Leaves the tracker's reference at the
 * last candidate tried. *found says whether one was taken: then
 * out->track.T_wc is the pose and out->reloc its candidate; else
 * out->track is the best candidate's result (or untouched when none ran). */
/* The map ray-cast at T_wc as the tracking reference, in a submission of
 * its own (nothing is fused); its time is added to out->ms_raycast. It has
 * the last fused frame's intensity only at exactly that frame's pose
 * (track_cmd_reference with_frame false). */
bf_status recon__cast_reference(recon *r, const bf_se3 *T_wc, recon_frame_result *out);
bf_status recon__search(recon *r, const bf_frame *f, const fusion_frame_slot *slot, double n, recon_reloc_kind skip,
                        recon_frame_result *out, bool *found);

#endif
