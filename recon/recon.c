/* The reconstruction loop: track, fuse, ray-cast, smooth (recon.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon_int.h"

static bf_status tracker_colour_camera(recon *r);

/* The caster at the camera's size, when the reference is cast at a coarser
 * level: made at create with has_views, else at the first view. */
static bf_status view_caster(recon *r)
{
    if (r->caster) return BF_OK;
    return render_create(r->ctx, &r->cfg.caster, r->K.width, r->K.height, &r->caster);
}

recon_config recon_config_default(void)
{
    recon_config c = {
        .sensor = bf_sensor_kinect1(),
        .fusion = fusion_config_default(),
        .track = track_config_default(),
        .raycast = render_options_tracking(),
        .caster = render_config_default(),
        .min_valid_pixels = 0, /* 0: 1% of the image, set at create */
        .fuse_degenerate = true,
        .skip_repeated = true,
        /* The last motion continued: the same as the last pose on every
         * frame of the real sequences (the finest level's iterations reach
         * the same pose), and tracks the frames a loop behind its camera
         * gets every few intervals: fr1/rpy every 4th frame 181 tracked
         * where the last pose lost 155 (docs/tracking.md, the guess). */
        .constant_velocity = true,
        /* The fringes a window saw too seldom (where Kinect v1 reads
         * worst) and the newest surfaces no window has judged both cost
         * the 7-Scenes dev frames; synthetic frames track a little worse
         * without them (docs/tracking.md, "The confident map as the
         * reference"). */
        .reference_confident = true,
        .fuse_every = 1,
        /* Behind a camera, a quarter of the frames fused: on lavapipe a
         * tracked-only frame costs a quarter to a third of a fused one,
         * and fr1/rpy tracked at every frame with every fourth fused lost
         * none, where every fourth frame alone lost 155 of 181
         * (docs/tracking.md). */
        .fuse_every_behind = 4,
        .start_at_frame = true,
        .stream = stream_config_default(),
        /* Four candidates a lost frame: the last pose, the continued motion
         * and two from the round robin; each costs a reference ray-cast and
         * an ICP (docs/tracking.md, relocalisation). The margins: a right
         * pose keeps 68-92% inliers at a 7-16 mm residual on the real
         * frames (docs/real_frames.md), 75-98% at 15 mm on the noisy
         * synthetic room; a wrong one a few percent at 3-5 cm
         * (track_config_default), at most 11% in tests/recon/test_reloc.c.
         * The inliers carry the margin: 35% against the tracker's 25%, not
         * more, because the fraction counts the frame's samples where the
         * map has nothing: a camera that turned 21 degrees while covered
         * keeps 27-46% at the right pose (the same test). The residual's
         * margin is thin, 18 mm against 20. What separates a wrong pose
         * that slid along a partly mapped wall is the frame's samples in
         * front of the map's predicted surface: at most 1.5% at right poses,
         * 5.4% at that wrong one (max_front_frac, docs/tracking.md). */
        .reloc = {.enabled = true, .max_candidates = 4, .max_gate_intervals = 4, .keyframe_m = 0.1f,
                  .keyframe_deg = 10.0f, .max_keyframes = 64, .min_inlier_frac = 0.35f, .max_residual_m = 0.018f,
                  .max_residual_sigma = 2.5f,
                  .check_step = 2, .check_band_m = 0.02f, .max_front_frac = 0.03f, .features = 1000,
                  .feature_candidates = 2, .feature_min_inliers = 20, .last_frame = true,
                  .last_frame_below = 0.45f},
    };
    /* Voxels of twice the pixel footprint: in the loop this is both faster
     * and more accurate than fusion's own default of 1
     * (docs/bench_replay_sweep.md): a coarser voxel holds the average of
     * more samples, so the sign field the tracker casts is less noisy, and
     * the window integrates a quarter of the voxels. */
    c.fusion.voxel_ratio = 2.0f;
    /* No voxels finer than 3.9 mm (level 6 of 2 m chunks): Kinect v1's
     * depth noise is 1.2 mm at its nearest (sigma_z(z), bf_sensor_kinect1),
     * so level 7's 1.95 mm voxels, which ratio 2 gives surfaces nearer than
     * about 0.8 m (f = 585 px), are below two sigma everywhere in its range
     * and hold the fewest samples each. On the real frames both the
     * trajectory and the surface gain (docs/real_frames.md, "The finest
     * level 6 by default"); the synthetic room never reaches level 7. The
     * level counts from the chunk edge: another --chunk moves this voxel. */
    c.fusion.max_level = 6;
    /* The tracking reference cast at a quarter of the camera's resolution
     * where that still leaves 160 pixels a row (160x120 for 640x480; the
     * tracker's default is half): a pixel of it then spans 4 z / f, about
     * two of ratio 2's voxels, so it still samples what the map resolves,
     * for a sixteenth of the camera's rays. On the real dev frames from
     * four starts the mean ATE is 27.5 against 28.3 mm, on the synthetic
     * room 1.12 against 1.22 mm, and the ray-cast takes 38 instead of 142
     * ms a frame (docs/real_frames.md, "The reference at a quarter of the
     * resolution"). An 80x60 reference of a 320x240 camera is too few
     * samples: the streamed rooms' test then loses frames. */
    c.track.ref_level = RECON_REF_LEVEL_AUTO;
    return c;
}

uint32_t recon_min_valid_pixels(const recon_config *cfg, uint32_t width, uint32_t height)
{
    return cfg->min_valid_pixels ? cfg->min_valid_pixels : width * height / 100 + 1;
}

uint32_t recon_ref_level(const bf_intrinsics *K, const track_config *tc)
{
    if (tc->ref_level != RECON_REF_LEVEL_AUTO) return tc->ref_level;
    uint32_t l = 0;
    while (l + 1 < tc->levels && l + 1 <= 2 && (K->width >> (l + 1)) >= RECON_REF_MIN_WIDTH) l++;
    return l;
}

fusion_config recon_fusion_config(const recon_config *cfg)
{
    /* One noise model and range for the whole loop. */
    fusion_config fc = cfg->fusion;
    fc.sensor = cfg->sensor;
    return fc;
}

const char *recon_state_name(recon_frame_state s)
{
    switch (s) {
    case RECON_FIRST: return "first";
    case RECON_TRACKED: return "tracked";
    case RECON_NO_DEPTH: return "no-depth";
    case RECON_LOST: return "lost";
    case RECON_RELOCALISED: return "relocalised";
    case RECON_REPEATED: return "repeated";
    }
    return "?";
}

bool recon_state_ran_icp(recon_frame_state s)
{
    return s == RECON_TRACKED || s == RECON_LOST || s == RECON_RELOCALISED;
}

const char *recon_reloc_kind_name(recon_reloc_kind k)
{
    switch (k) {
    case RECON_RELOC_NONE: return "";
    case RECON_RELOC_LAST: return "last";
    case RECON_RELOC_VELOCITY: return "velocity";
    case RECON_RELOC_TURNED: return "turned";
    case RECON_RELOC_KEYFRAME: return "keyframe";
    case RECON_RELOC_FEATURES: return "features";
    case RECON_RELOC_FRAME: return "frame";
    }
    return "?";
}

bf_status recon_create(gpu_context *ctx, const recon_config *cfg, const bf_intrinsics *K, const bf_se3 *T_wc0,
                       recon **out)
{
    if (!ctx || !cfg || !K || !T_wc0 || !out) return bf_fail(BF_INVALID_ARG, "recon_create: NULL argument");
    /* Fusion, the photometric term and relocalisation read the frames'
     * colour through this camera pixel for pixel: it must be at their size
     * (app_calibration_apply scales a file's). */
    const calib_camera *cc = &cfg->calibration.colour;
    if (cfg->has_calibration && (cc->width != K->width || cc->height != K->height))
        return bf_fail(BF_INVALID_ARG, "recon_create: the colour camera is %ux%u, the frames %ux%u", cc->width,
                       cc->height, K->width, K->height);
    if (!cfg->fuse_every || !cfg->fuse_every_behind || cfg->fuse_every > RECON_MAX_FUSE_EVERY ||
        cfg->fuse_every_behind > RECON_MAX_FUSE_EVERY)
        return bf_fail(BF_INVALID_ARG, "recon_create: fuse_every %u and fuse_every_behind %u must be 1..%u",
                       cfg->fuse_every, cfg->fuse_every_behind, RECON_MAX_FUSE_EVERY);
    recon *r = calloc(1, sizeof *r);
    if (!r) return bf_fail(BF_NO_MEMORY, "recon_create");
    r->ctx = ctx;
    r->cfg = *cfg;
    r->K = *K;
    r->T_first = *T_wc0;
    r->T_last = *T_wc0;
    r->cfg.fusion = recon_fusion_config(cfg);
    r->cfg.track.sensor = r->cfg.sensor;
    r->cfg.min_valid_pixels = recon_min_valid_pixels(cfg, K->width, K->height);
    /* The reference at track.ref_level (recon_config_default: a quarter of
     * the resolution): the ray-cast is the loop's largest cost per ray.
     * track_create checks the level. */
    uint32_t l = r->cfg.track.ref_level = recon_ref_level(K, &r->cfg.track);
    r->K_ref = bf_intrinsics_level(K, l);
    bf_status s = recon__reloc_create(r);
    if (s == BF_OK) s = track_create(ctx, &r->cfg.track, K, &r->tracker);
    if (s == BF_OK) s = render_create(ctx, &r->cfg.caster, r->K_ref.width, r->K_ref.height, &r->ref_caster);
    if (s == BF_OK && l == 0) r->caster = r->ref_caster;
    /* The map and the views' caster now, not at their first use: compiling
     * their pipelines takes seconds on lavapipe, and a camera started after
     * this returns must not wait for it (docs/tracking.md, start-up). */
    if (s == BF_OK) s = fusion_create(ctx, &r->cfg.fusion, K, r->T_first.t, &r->map);
    if (s == BF_OK) s = recon_set_colour_camera(r->map, &r->cfg);
    if (s == BF_OK) s = tracker_colour_camera(r);
    if (s == BF_OK && r->cfg.has_views) s = view_caster(r);
    if (s == BF_OK && r->cfg.stream.enabled) s = stream_create(&r->cfg.stream, r->map, NULL, &r->stream);
    if (s != BF_OK) {
        recon_destroy(r);
        return s;
    }
    *out = r;
    return BF_OK;
}

void recon_destroy(recon *r)
{
    if (!r) return;
    track_destroy(r->tracker);
    stream_destroy(r->stream);
    if (r->caster != r->ref_caster) render_destroy(r->caster);
    render_destroy(r->ref_caster);
    fusion_destroy(r->map);
    recon__reloc_destroy(r);
    bf_repeats_free(&r->repeats);
    free(r);
}

fusion_map *recon_map(recon *r) { return r->map; }

render_caster *recon_caster(recon *r) { return view_caster(r) == BF_OK ? r->caster : NULL; }
recon_counts recon_get_counts(const recon *r) { return r->counts; }

/* Samples the loop can use: a reading within the sensor's range. A frame
 * of readings all beyond it (a saturated 65535, a flat 6 m) holds no more
 * than an empty one: counted as none, it is skipped as one, not made the
 * first frame of a map it cannot start. */
uint32_t recon__depth_in_range(const bf_frame *f, double depth_scale, float max_depth_m)
{
    double max_raw = (double)max_depth_m * depth_scale;
    uint32_t top = max_raw >= 65535.0 ? 65535u : (uint32_t)max_raw;
    uint32_t n = 0;
    size_t np = (size_t)f->width * f->height;
    for (size_t i = 0; i < np; i++) n += f->depth[i] != 0 && f->depth[i] <= top;
    return n;
}

/* Rays of ro start a margin in front of the tracker's frame depth at
 * `level` (docs/render.md): 3 sigma(z) of the sensor noise fusion assumes
 * (a + b (z - c)^2 <= a + b z^2 for the z that matter) bounds the map's
 * surface behind the frame's, plus 2 cm for the map's own error. Without
 * a frame depth at that level the rays start at near_m. */
static void start_at_frame(recon *r, uint32_t level, render_options *ro)
{
    if (track_frame_depth_gpu(r->tracker, level, &ro->start_depth, &ro->start_offset) != BF_OK) return;
    ro->start_margin_m = 0.02f + 3.0f * r->cfg.sensor.sigma_a;
    ro->start_margin_z2 = 3.0f * r->cfg.sensor.sigma_b;
}

/* Fuses the uploaded frame at T and makes the ray-cast of the map at T the
 * next reference, in one submission: fusion, the ray-cast (written straight
 * into the tracker's reference) and the reference's preparation share it,
 * so the frame costs one host wait besides its ICP iterations. first: the
 * uploaded frame (not tracked, so not preprocessed) is the first one; its
 * preprocessing goes into the submission too, so its rays start at its depth
 * as a tracked frame's do (from the near plane the first ray-cast cost about
 * two frames' ray-casts: docs/tracking.md, start-up). */
static bf_status fuse_and_reference(recon *r, const bf_frame *f, const bf_se3 *T, bool tracked,
                                    const fusion_frame_slot *first, recon_frame_result *out)
{
    render_options ro = r->cfg.raycast;
    ro.no_shade = true; /* tracking takes its normals from the depth */
    /* reference_confident: the sign bits no window has judged yet (the
     * sub-cache's quick signs, the fringes a window saw too seldom) stay
     * out of the reference once the map has confident ones. Before the
     * first window nothing is confident, and a reference from confident
     * voxels alone would be empty (docs/tracking.md, "The confident map
     * as the reference"). */
    if (r->cfg.reference_confident && fusion_windows_done(r->map) > 0) ro.confident_only = true;
    bf_status s = track_reference_target(r->tracker, &ro.depth_out, &ro.depth_offset);
    if (s != BF_OK) return s;
    if ((s = gpu_begin(r->ctx)) != BF_OK) return s;
    if (r->cfg.start_at_frame && first) s = track_cmd_frame(r->tracker, first->depth, first->offset, f->index);
    /* The reference's rays start in front of the depth this frame saw. */
    if (s == BF_OK && r->cfg.start_at_frame && (tracked || first)) start_at_frame(r, r->cfg.track.ref_level, &ro);
    if (s == BF_OK) s = fusion_cmd_fuse(r->map, T);
    if (s == BF_OK) s = render_cmd_raycast(r->ref_caster, r->map, &r->K_ref, T, &ro);
    if (s == BF_OK) s = track_cmd_reference(r->tracker, T, true);
    /* The counters fusion copied and the reference's count -> the host. */
    gpu_cmd_barrier(r->ctx, GPU_BARRIER_HOST);
    bf_status sw = gpu_submit_wait(r->ctx);
    if (s == BF_OK) s = sw;
    if (s != BF_OK) return s;
    r->frame_fused = true;
    r->T_frame = *T;
    r->ref_is_map = true;
    r->since_fused = 0;
    s = fusion_finish_frame(r->map);
    out->fuse = fusion_last_stage_ms(r->map);
    out->fuse_status = s;
    if (s == BF_POOL_FULL) {
        /* The map stays consistent; what did not fit is dropped and counted. */
        r->counts.pool_full++;
        bf_warn("recon: frame %u: %s", f->index, bf_last_error());
        s = BF_OK;
    }
    if (s != BF_OK) return s;
    out->fused = true;
    render_finish_raycast(r->ref_caster);
    out->ms_raycast = render_last_ms(r->ref_caster);
    return track_finish_reference(r->tracker);
}

static bf_status no_depth(recon *r, recon_frame_result *out)
{
    out->state = RECON_NO_DEPTH;
    r->counts.no_depth++;
    r->depthless_since_good = true;
    return BF_OK;
}

/* fuse_every: whether a good frame is tracked only. Only a plain tracked
 * frame, against the map's ray-cast at the last fused pose: a frame found
 * by a search or on the frame before, or after a frame that left another
 * reference, is fused so that the next one has the map at a pose near its
 * own. With known poses every frame is fused (the tracker's one-step error
 * is measured against the map at the true poses). */
static bool tracks_only(const recon *r, const bf_se3 *known, recon_frame_state state, const recon_frame_result *out)
{
    uint32_t every = r->cfg.fuse_every;
    if (r->is_behind && r->cfg.fuse_every_behind > every) every = r->cfg.fuse_every_behind;
    return every > 1 && !known && state == RECON_TRACKED && out->reloc == RECON_RELOC_NONE && r->ref_is_map &&
           r->since_fused + 1 < every;
}

/* A good frame (tracked or relocalised): fused at its pose, or at *known
 * (recon_add_frame_known), which becomes the last pose; with fuse_every
 * some are tracked only, the reference staying the last fused frame's. */
static bf_status accept(recon *r, const bf_frame *f, const bf_se3 *known, recon_frame_state state,
                        recon_frame_result *out)
{
    out->state = state;
    out->T_wc = out->track.T_wc;
    const bf_se3 *T_new = known ? known : &out->track.T_wc;
    recon__good_frame(r, f, T_new, !out->track.degenerate);
    /* A search's find may be a jump (a camera carried off): a step per
     * interval beyond the tracker's per-frame gate is no motion a camera
     * keeps up, and the next guess is the found pose, not another jump. A
     * tracked step was checked against its guess and is continued. */
    if (state == RECON_RELOCALISED && (bf_v3_norm(r->V_step.t) > r->cfg.track.max_motion_m ||
                                       bf_se3_angle(&r->V_step) * 180.0 / M_PI > r->cfg.track.max_motion_deg))
        r->has_velocity = false;
    r->counts.tracked++;
    if (state == RECON_RELOCALISED) r->counts.relocalised++;
    if (out->reloc == RECON_RELOC_FRAME) r->counts.last_frame++;
    if (out->track.photo_weak) r->counts.photo_weak++;
    if (tracks_only(r, known, state, out)) {
        r->since_fused++;
        r->counts.unfused++;
        /* The tracker's frame depth is this frame's, at its pose: a view
         * there starts its rays in front of it as after a fused frame. */
        r->frame_fused = true;
        r->T_frame = *T_new;
        return BF_OK;
    }
    return fuse_and_reference(r, f, T_new, true, NULL, out);
}

/* A failed frame: not fused (with known poses: fused there), the last good
 * pose kept. */
static bf_status lose(recon *r, const bf_frame *f, const bf_se3 *known, recon_frame_result *out)
{
    out->state = RECON_LOST;
    r->counts.lost++;
    r->is_lost = true;
    r->ref_is_map = false; /* the next good frame is fused, the reference made at its pose */
    if (!known) return BF_OK;
    /* The last pose is this frame's now: the next step is from here. */
    r->T_last = *known;
    r->good_index = f->index;
    r->good_t_s = f->t_depth_s;
    return fuse_and_reference(r, f, known, false, NULL, out);
}

/* A frame once the map exists. The frame goes up once, into fusion's
 * incoming slot: the tracker reads it there, fusing copies it into the
 * ring. The guess is the last motion per frame interval continued over
 * the intervals since the last good frame (constant_velocity, the
 * default: a skipped or dropped frame between them makes it the longer
 * step it is, which catches turns and steps beyond the ICP's reach from
 * the last pose), or the last pose; while lost, the last pose. With reloc, the
 * motion gate grows with the frames elapsed since the last good one, and a
 * frame that fails from its guess, comes while the camera is lost or after
 * a gap longer than the gate's cap is searched for from candidate poses
 * (reloc.c); behind a camera such a gap is tracked from the guess first
 * and searched for when that fit fails a candidate's test. */
static bf_status track_and_fuse(recon *r, const bf_frame *f, const bf_se3 *known, recon_frame_result *out)
{
    fusion_frame_slot slot;
    bool reloc = r->cfg.reloc.enabled && !known;
    /* Beyond the gate's cap the camera may be anywhere the gate no longer
     * bounds (a covered lens): the frame is searched for like a lost one.
     * Not while the loop is behind a camera that gave depth in every frame
     * it took since the last good one: the queue dropped the frames
     * between, the camera moved on as between any two, and the frame is
     * tracked from the continued motion with the gate at its cap first. A
     * search costs several ray-casts and ICPs (400-600 ms on lavapipe),
     * behind which the queue drops a dozen frames more, so every frame
     * after one was a search (docs/tracking.md, the guess). */
    double n = recon__intervals(r, f);
    bool past_cap = n > r->cfg.reloc.max_gate_intervals;
    bool dropped_between = r->is_behind && !r->depthless_since_good;
    bool search_first = reloc && (r->is_lost || (past_cap && !dropped_between));
    bf_status s = fusion_upload_frame(r->map, f, &slot);
    if (s == BF_OK) s = track_set_frame_colour(r->tracker, slot.colour, slot.colour_offset);
    if (s == BF_OK && reloc) s = recon__set_gate(r, n);
    if (s != BF_OK) return s;
    /* The reference was cast at the last good pose: tracking from there
     * tries that candidate (after frames tracked only it is older). */
    bool ref_at_last = r->ref_is_map && r->since_fused == 0;
    /* A loss leaves the motion unknown: the guess is then the last pose. */
    bool cv = r->cfg.constant_velocity && r->has_velocity && !r->is_lost;
    if (!search_first) {
        bf_se3 guess = cv ? recon__velocity_pose(r, n) : r->T_last;
        s = track_frame_gpu(r->tracker, slot.depth, slot.offset, f->index, &guess, &out->track);
        if (s != BF_OK) return s;
        out->ms_track = out->track.ms_gpu;
        bool ok = out->track.outcome == TRACK_OK;
        if (ok && out->track.degenerate) r->counts.degenerate++;
        /* Valid raw samples, but none the tracker can use (all beyond range). */
        if (out->track.outcome == TRACK_NO_DEPTH) return no_depth(r, out);
        /* Across a gap beyond the gate's cap (behind a camera, above) the
         * gate bounds little: the fit must pass what a search's candidate
         * must, else the frame is searched for. Live fr1/rpy's slides
         * there had 27-29% inliers, fr1/xyz's a 19.9 mm residual at 9.5
         * sigma (docs/tracking.md, the guess). */
        if (ok && reloc && past_cap && !recon__passes(r, &out->track)) ok = false;
        if (ok && (r->cfg.fuse_degenerate || !out->track.degenerate)) {
            /* A weak fit to the map: the frame before's pose replaces it
             * when it passes the candidates' gates with more inliers. */
            if (reloc && out->track.inlier_frac < r->cfg.reloc.last_frame_below) {
                track_result map_fit = out->track;
                bool found;
                if ((s = recon__track_last_frame(r, f, &slot, n, out, &found)) != BF_OK) return s;
                if (found && out->track.inlier_frac <= map_fit.inlier_frac) found = false;
                if (!found) {
                    /* The map's fit stands; the attempt's time stays counted. */
                    out->track = map_fit;
                    out->reloc = RECON_RELOC_NONE;
                    out->reloc_tried = 0;
                }
            }
            return accept(r, f, known, RECON_TRACKED, out);
        }
        if (!reloc) return lose(r, f, known, out);
    }
    /* A guess of the last pose was just tried against the reference cast
     * there; after frames tracked only that one is an older pose's, and
     * the last pose is a candidate again, as it is after the continued
     * motion was the guess. */
    recon_reloc_kind skip = !search_first && !cv && ref_at_last ? RECON_RELOC_LAST : RECON_RELOC_NONE;
    bool found;
    if ((s = recon__search(r, f, &slot, n, skip, out, &found)) != BF_OK) return s;
    if (found) return accept(r, f, NULL, RECON_RELOCALISED, out);
    if (out->track.outcome == TRACK_NO_DEPTH) return no_depth(r, out);
    if ((s = recon__track_last_frame(r, f, &slot, n, out, &found)) != BF_OK) return s;
    if (found) return accept(r, f, NULL, RECON_TRACKED, out);
    return lose(r, f, known, out);
}

/* The first frame with depth: fused at the first pose, which it makes the
 * reference's. */
static bf_status first_frame(recon *r, const bf_frame *f, const bf_se3 *known, recon_frame_result *out)
{
    out->state = RECON_FIRST;
    fusion_frame_slot slot;
    bf_status s = known ? recon_set_first_pose(r, known) : BF_OK;
    if (s == BF_OK) s = fusion_upload_frame(r->map, f, &slot);
    if (s == BF_OK) s = track_set_frame_colour(r->tracker, slot.colour, slot.colour_offset);
    if (s == BF_OK) s = fuse_and_reference(r, f, &r->T_first, false, &slot, out);
    if (s == BF_OK) {
        r->has_first = true;
        recon__good_frame(r, f, &r->T_first, true);
        r->counts.tracked++;
    }
    out->T_wc = r->T_first;
    return s;
}

/* After a frame, whatever became of it: streaming and the times. */
static bf_status finish_frame(recon *r, bf_status s, double t0, recon_frame_result *out)
{
    out->ms_rof = out->track.ms_rof; /* the smoothing of this frame's reference */
    /* Far chunks out, near ones in, between frames (stream.h). */
    if (s == BF_OK && out->fused && r->stream) {
        double ts = bf_time_s();
        s = stream_update(r->stream, &r->T_last, out->index, false);
        out->ms_stream = 1e3 * (bf_time_s() - ts);
    }
    out->ms_frame = 1e3 * (bf_time_s() - t0);
    return s;
}

/* known: NULL for the loop; else the frame is tracked as usual but fused
 * at *known, which becomes the last pose (recon_add_frame_known). */
static bf_status add_frame(recon *r, const bf_frame *f, const bf_se3 *known, recon_frame_result *out)
{
    if (!r || !f || !out) return bf_fail(BF_INVALID_ARG, "recon_add_frame: NULL argument");
    if (f->width != r->K.width || f->height != r->K.height || !f->depth)
        return bf_fail(BF_INVALID_ARG, "recon: frame %u is %ux%u, the camera %ux%u", f->index, f->width, f->height,
                       r->K.width, r->K.height);
    double t0 = bf_time_s();
    memset(out, 0, sizeof *out);
    r->frame_fused = false; /* the tracker's frame depth is about to be this frame's */
    out->index = f->index;
    out->T_wc = r->T_last;
    out->n_valid = recon__depth_in_range(f, r->K.depth_scale, r->cfg.sensor.max_depth_m);
    r->counts.frames++;
    if (r->is_behind) r->counts.behind++;
    /* Every frame's images count, a skipped one's too: the next frame's
     * colour may be that one's (core.h, "Repeated frames"). A repeated
     * depth is an earlier moment's: neither tracked nor fused, with known
     * poses (--fuse-at-groundtruth) too, whose pose has moved on. A colour
     * repeated alone leaves the frame its new depth: tracked and fused
     * without colour, which would be painted (and compared, by the
     * photometric term) at a pose it was not taken at. */
    bool stale_depth = false, stale_rgb = false;
    bf_status s = r->cfg.skip_repeated ? bf_repeats_note(&r->repeats, f, &stale_depth, &stale_rgb) : BF_OK;
    if (s != BF_OK) return s;
    bf_frame g = *f;
    if (out->n_valid < r->cfg.min_valid_pixels) return finish_frame(r, no_depth(r, out), t0, out);
    if (stale_depth && r->has_first) {
        out->state = RECON_REPEATED;
        r->counts.repeated++;
        return finish_frame(r, BF_OK, t0, out);
    }
    if (stale_rgb) {
        g.rgb = NULL; /* the depth alone */
        out->colour_repeated = true;
        r->counts.colour_repeated++;
    }
    s = r->has_first ? track_and_fuse(r, &g, known, out) : first_frame(r, &g, known, out);
    return finish_frame(r, s, t0, out);
}

bf_status recon_add_frame(recon *r, const bf_frame *f, recon_frame_result *out)
{
    return add_frame(r, f, NULL, out);
}

bf_status recon_add_frame_known(recon *r, const bf_frame *f, const bf_se3 *T_known, recon_frame_result *out)
{
    if (!T_known || !bf_se3_is_finite(T_known)) return bf_fail(BF_INVALID_ARG, "recon_add_frame_known: no pose");
    return add_frame(r, f, T_known, out);
}

bf_status recon_flush(recon *r) { return fusion_flush(r->map); }

void recon_set_behind(recon *r, bool behind)
{
    if (r) r->is_behind = behind;
}

bf_status recon_set_first_pose(recon *r, const bf_se3 *T_wc0)
{
    if (!T_wc0 || !bf_se3_is_finite(T_wc0)) return bf_fail(BF_INVALID_ARG, "recon_set_first_pose: no pose");
    if (r->has_first) return bf_fail(BF_INVALID_ARG, "recon: the first frame has been fused already");
    bf_status s = fusion_set_origin(r->map, T_wc0->t);
    if (s != BF_OK) return s;
    r->T_first = r->T_last = *T_wc0;
    return BF_OK;
}

const calib_camera *recon__colour_rig(const recon_config *cfg, bf_se3 *T_colour_depth)
{
    if (!cfg->has_calibration) return NULL; /* registered: the format's or the device's */
    /* Without the depth camera the file gives no transform: the colour
     * camera's own intrinsics at the depth camera's place. */
    *T_colour_depth = cfg->calibration.has_depth ? cfg->calibration.T_colour_depth : bf_se3_identity();
    return &cfg->calibration.colour;
}

/* The colour camera of --calibration: intrinsics and T_colour_depth. */
static void colour_camera(const recon_config *cfg, bf_intrinsics *Kc, bf_se3 *T)
{
    const calib_camera *c = recon__colour_rig(cfg, T);
    *Kc = (bf_intrinsics){.width = c->width, .height = c->height, .fx_px = c->fx_px, .fy_px = c->fy_px,
                          .cx_px = c->cx_px, .cy_px = c->cy_px, .depth_scale = 1};
}

bf_status recon_set_colour_camera(fusion_map *map, const recon_config *cfg)
{
    if (!cfg->has_calibration) return BF_OK; /* registered: the format's or the device's */
    bf_intrinsics Kc;
    bf_se3 T;
    colour_camera(cfg, &Kc, &T);
    return fusion_set_colour_camera(map, &Kc, cfg->calibration.colour.dist, &T);
}

/* The tracker's photometric term sees the colour as fusion does. */
static bf_status tracker_colour_camera(recon *r)
{
    if (!r->cfg.has_calibration) return BF_OK;
    bf_intrinsics Kc;
    bf_se3 T;
    colour_camera(&r->cfg, &Kc, &T);
    return track_set_colour_camera(r->tracker, &Kc, r->cfg.calibration.colour.dist, &T);
}

bf_status recon_keyframes(const recon *r, store_keyframes *out)
{
    if (!r || !out) return bf_fail(BF_INVALID_ARG, "recon_keyframes: no loop or output");
    return recon__keyframes_export(r, out);
}

uint64_t recon_keyframes_generation(const recon *r) { return r ? r->kf_generation : 0; }

bf_status recon_resume(recon *r, const hostmap *map, const bf_se3 *T_last, uint32_t last_index, const bf_traj *traj,
                       const store_keyframes *kf)
{
    if (!r || !map || !T_last || !bf_se3_is_finite(T_last))
        return bf_fail(BF_INVALID_ARG, "recon_resume: no map or no pose");
    if (r->has_first || r->counts.frames) return bf_fail(BF_INVALID_ARG, "recon: a scan is resumed before its first frame");
    bf_status s;
    if (r->stream) {
        /* The stored map may exceed the pools: it goes to the stream's
         * cache, and the chunks near the last pose come in at once. */
        hostmap copy = *map;
        copy.bricks = map->n_bricks ? bf_malloc((size_t)map->n_bricks * sizeof *copy.bricks) : NULL;
        copy.rgb565 = map->rgb565 && map->n_bricks ? bf_malloc((size_t)map->n_bricks * 1024) : NULL;
        if (map->n_bricks && (!copy.bricks || (map->rgb565 && !copy.rgb565))) {
            hostmap_free(&copy);
            return bf_fail(BF_NO_MEMORY, "recon: resuming %u bricks", map->n_bricks);
        }
        if (map->n_bricks) memcpy(copy.bricks, map->bricks, (size_t)map->n_bricks * sizeof *copy.bricks);
        if (copy.rgb565) memcpy(copy.rgb565, map->rgb565, (size_t)map->n_bricks * 1024);
        s = fusion_set_origin(r->map, map->origin_w);
        if (s == BF_OK) s = stream_adopt(r->stream, &copy);
        hostmap_free(&copy);
        if (s == BF_OK) s = stream_update(r->stream, T_last, last_index, true);
    } else {
        s = fusion_load(r->map, map);
    }
    if (s != BF_OK) return s;
    r->T_first = r->T_last = *T_last;
    r->has_first = true;
    r->good_index = last_index;
    /* The stored keyframes, with their colour's keypoints, find a camera
     * resumed anywhere they saw. They were chosen from the same trajectory
     * by the same rule, so its poses are added only without them: once the
     * store is full, a pose alone would replace a keyframe that has
     * keypoints. */
    if (kf && kf->n) recon__keyframes_import(r, kf);
    else
        for (size_t i = 0; traj && r->keyframes && i < traj->n; i++) recon__add_keyframe(r, &traj->T_wc[i], NULL);
    recon_frame_result tmp;
    memset(&tmp, 0, sizeof tmp);
    return recon__cast_reference(r, T_last, &tmp);
}

bf_status recon_snapshot(recon *r, hostmap *out)
{
    return r->stream ? stream_gather(r->stream, out) : fusion_snapshot_take(r->map, out);
}

stream_stats recon_stream_stats(const recon *r)
{
    stream_stats z;
    memset(&z, 0, sizeof z);
    return r->stream ? stream_get_stats(r->stream) : z;
}

const char *recon_stream_spill_error(const recon *r) { return r->stream ? stream_spill_error(r->stream) : NULL; }

bf_status recon_render_view(recon *r, const bf_se3 *T_wc)
{
    bf_status s = view_caster(r);
    if (s != BF_OK) return s;
    /* Until the first window is integrated nothing is confident and a
     * confident-only view is black: show the sub-cache's quick signs. */
    render_options opt = render_options_display();
    opt.confident_only = fusion_windows_done(r->map) > 0;
    /* At the pose the last frame was fused at, the rays start in front of
     * that frame's depth as the reference's do: a view from the near plane
     * cost 0.4 s at 640x480 on lavapipe, and at a live start the first one
     * outlasted live's queue of 8 frames (docs/tracking.md, start-up). A
     * pixel without depth starts at the near plane. */
    if (r->cfg.start_at_frame && r->frame_fused && !memcmp(T_wc, &r->T_frame, sizeof *T_wc))
        start_at_frame(r, 0, &opt);
    return render_raycast(r->caster, r->map, &r->K, T_wc, &opt);
}
