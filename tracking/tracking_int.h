/* Declarations shared by tracking/'s files (SQLite's btreeInt.h idea). */
#ifndef BF_TRACKING_INT_H
#define BF_TRACKING_INT_H

#include "shaders/track.glsl.h"
#include "tracking.h"

/* Local sizes: 8x8 tiles for the per-pixel image kernels; the ICP
 * kernel's workgroup and the pixels each invocation walks are chosen at
 * create (icp.c). */
/* TRACK_IMAGE_TILE, TRACK_IMAGE_PX: shaders/track.glsl.h */

/* A pyramid's geometry: level l is w[l] x h[l] pixels at pixel offset
 * off[l]; n_pix pixels in all. */
typedef struct track_pyramid_geom {
    uint32_t w[TRACK_LEVELS], h[TRACK_LEVELS], off[TRACK_LEVELS];
    uint32_t n_pix;
} track_pyramid_geom;

/* One image kernel pass's buffers: a binding set (raw input, counters) and
 * the device addresses of the pyramids it reads and writes
 * (track_image_push). */
typedef struct track_image_set {
    gpu_bindings *b;
    uint64_t depth, normal, p_in, p_out;
} track_image_set;

struct track_tracker {
    gpu_context *ctx;
    track_config cfg;
    bf_intrinsics K;
    track_pyramid_geom geom;

    /* Frame: raw depth (u16, two per word) on the GPU, pyramids of depth and
     * normal (octahedral uint). Reference: written in place at its finest
     * level (the ray-cast, track_reference_target) or converted from a raw
     * frame, the same pyramids (that level of ref_depth is then the
     * ROF-smoothed depth), the ROF dual fields (ping-pong). */
    gpu_buffer *upload;        /* UPLOAD: u16 depth of a frame given on the host (track_frame, references from frames) */
    uint32_t frame_raw_off;    /* word offset of the frame's raw depth in b_frame's binding 0 (upload, or
                                  the caller's buffer: track_frame_gpu) */
    gpu_buffer *frame_depth, *frame_normal;
    gpu_buffer *ref_depth, *ref_normal;
    gpu_buffer *rof_p[2];      /* after the ROF (and for frames): scratch and the depth pyramid of the normals */
    gpu_buffer *counters;      /* TRACK_CNT_* */
    /* The photometric term: intensity pyramids of the frame and of the
     * frame the reference was made with (track_set_frame_colour). */
    gpu_buffer *frame_int, *ref_int;
    gpu_buffer *colour;        /* borrowed: where the next frames' RGB565 colour is, NULL: none */
    uint32_t colour_off;       /* its word offset */
    bool colour_registered;    /* colour pixel i shows depth pixel i (no colour camera set) */
    bf_intrinsics Kc;          /* else the colour camera, */
    double colour_dist[5];     /* its distortion */
    bf_se3 T_colour_depth;     /* and pose */
    bool frame_has_int;        /* frame_int holds the last preprocessed frame's intensity */
    bool ref_has_int, ref_int_pending; /* ref_int holds the reference frame's (pending: being copied) */
    /* ref_int's image was seen from T_int (kept while no frame replaces
     * it): a reference cast from the map alone at exactly that pose keeps
     * it (track_cmd_reference); pending until the reference finishes. */
    bool int_kept, int_kept_pending;
    bf_se3 T_int, T_int_pending;
    gpu_buffer *partials;      /* icp_groups_max * TRACK_PARTIAL_WORDS floats */

    gpu_pipeline *p_depth, *p_pyrdown, *p_smooth, *p_vn, *p_rof, *p_primal, *p_icp, *p_int;
    gpu_bindings *b_int;       /* the intensity kernel: colour (bound per frame), frame depth, frame_int */
    /* Image binding sets: frame from its raw depth, reference from the upload
     * (a raw frame; unused in place). */
    gpu_bindings *b_frame, *b_ref, *b_icp;
    /* What the image kernels work on: the frame's pyramids, or the
     * reference's with the dual fields 0 -> 1 and 1 -> 0. */
    track_image_set frame_set, ref_set[2];
    gpu_buffer *addresses;     /* the ICP's address table, TRACK_ADDR_* */

    uint32_t icp_local;        /* ICP invocations per workgroup */
    uint32_t icp_px_per_thread;
    uint32_t icp_groups_max;
    bool icp_subgroup;         /* the subgroup-arithmetic kernel is used */
    float *partial_host;       /* icp_groups_max * TRACK_PARTIAL_WORDS, allocated at create */

    /* The reference. */
    bool has_ref;
    bool ref_pending;          /* track_cmd_reference recorded, track_finish_reference not yet run */
    bf_se3 T_wr;               /* camera to world of the reference */
    bf_se3 T_wr_pending;       /* the pose of the reference being prepared */
    uint32_t ref_valid;        /* valid depth pixels at the reference's finest level */
    bool has_frame;            /* frame_depth holds a frame (track_frame_depth_gpu) */
    uint32_t ref_first;        /* that level: cfg.ref_level for a reference from the GPU, 0 for a frame */
    double motion_scale;       /* the motion gate is cfg.max_motion_* times this (track_set_motion_scale) */
    double ms_rof;             /* GPU time of the last smoothing */
    double ms_ref;             /* GPU time of the last reference preparation (smoothing included) */
};

/* tracker.c: the geometry of level l from K. */
void track__level_intrinsics(const bf_intrinsics *K, uint32_t l, float *fx, float *fy, float *cx, float *cy);

/* pyramid.c: pipelines and binding sets of the image kernels. Timed stages
 * of the image kernels (the outer ones are left out when profiling, as
 * stages do not nest); the printout of the last submission's stages. */
void track__stage_begin(track_tracker *t, const char *name);
void track__stage_end(track_tracker *t);
void track__profile_print(track_tracker *t, const char *what);
bf_status track__pyramid_create(track_tracker *t);
void track__pyramid_destroy(track_tracker *t);
/* Records the raw frame (b_frame's binding 0 at frame_raw_off) -> frame pyramids
 * (depth, normal; counts the valid pixels into TRACK_CNT_FRAME_VALID). */
void track__cmd_frame_pyramid(track_tracker *t);
/* Records the frame's intensity pyramid from its colour (t->colour, bound
 * into b_int by the caller) after its depth pyramid. */
void track__cmd_frame_intensity(track_tracker *t);
uint32_t track__int_levels(const track_tracker *t); /* intensity levels made: those the term reads */
/* Records the reference: the count of its valid pixels cleared, depth
 * conversion from the upload (in_place false: a raw frame) or in place at
 * ref_level (a GPU reference), ROF smoothing (its own timed stage
 * "track.rof"), pyramids. */
void track__cmd_reference(track_tracker *t, bool in_place);
/* Writes a frame's depth into the upload buffer. */
bf_status track__upload_depth(track_tracker *t, const uint16_t *depth);

/* icp.c */
bf_status track__icp_create(track_tracker *t);
void track__icp_destroy(track_tracker *t);
/* Runs ICP from the relative pose *T_rc (in/out): the frame's
 * preprocessing (its raw depth bound to b_frame) in the first iteration's
 * submission, then the levels; fills the result's statistics and outcome
 * (NO_DEPTH when the frame has fewer than min_valid depth pixels;
 * NO_REFERENCE is the caller's). */
bf_status track__icp_run(track_tracker *t, bf_se3 *T_rc, uint32_t min_valid, track_result *res);

/* For tests: the ROF iteration count used by the next reference. */
void track__set_rof_iterations(track_tracker *t, uint32_t n);

#endif
