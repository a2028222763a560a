/* recon: one sequence through the loop, with the policies every caller
 * shares (recon.h, "the runner"). */
#include "recon_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

recon_run_config recon_run_config_default(void)
{
    return (recon_run_config){.loop = recon_config_default(), .poses = RECON_POSES_TRACK};
}

void recon_run_free(recon_run *run)
{
    if (!run) return;
    if (run->loop) recon_destroy(run->loop);
    else fusion_destroy(run->map);
    bf_traj_free(&run->est);
    bf_traj_free(&run->gt);
    bf_repeats_free(&run->repeats);
    recon_run_series *t = &run->series;
    bf_stats *all[] = {&t->frame_ms,  &t->track_ms, &t->inlier_frac, &t->residual_mm, &t->rof_ms,
                       &t->raycast_ms, &t->upload_ms, &t->alloc_ms,   &t->subcache_ms, &t->window_ms,
                       &t->colour_ms};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++) bf_stats_free(all[i]);
    memset(run, 0, sizeof *run);
}

static bf_status push_fuse_times(recon_run_series *t, const fusion_stage_ms *ms)
{
    bf_status s = bf_stats_push(&t->upload_ms, ms->upload);
    if (s == BF_OK) s = bf_stats_push(&t->alloc_ms, ms->alloc);
    if (s == BF_OK) s = bf_stats_push(&t->subcache_ms, ms->subcache);
    if (s == BF_OK) s = bf_stats_push(&t->window_ms, ms->window);
    if (s == BF_OK) s = bf_stats_push(&t->colour_ms, ms->colour);
    return s;
}

static bf_status push_series(recon_run_series *t, const recon_frame_result *fr, bool has_loop)
{
    /* A repeated frame costs a comparison, not a frame of the loop: left
     * out of the time per frame, as it is of the work. */
    if (fr->state == RECON_REPEATED) return BF_OK;
    bf_status s = bf_stats_push(&t->frame_ms, fr->ms_frame);
    if (has_loop && recon_state_ran_icp(fr->state)) {
        if (s == BF_OK) s = bf_stats_push(&t->track_ms, fr->ms_track);
        if (s == BF_OK) s = bf_stats_push(&t->inlier_frac, fr->track.inlier_frac);
        if (s == BF_OK && fr->track.outcome == TRACK_OK) s = bf_stats_push(&t->residual_mm, 1e3 * fr->track.residual_m);
    }
    if (fr->fused && has_loop) {
        if (s == BF_OK) s = bf_stats_push(&t->rof_ms, fr->ms_rof);
        if (s == BF_OK) s = bf_stats_push(&t->raycast_ms, fr->ms_raycast);
    }
    if (fr->fused && s == BF_OK) s = push_fuse_times(t, &fr->fuse);
    return s;
}

/* The pose to fuse frame f at with known poses: its ground truth, or the
 * trajectory at its depth timestamp. False when there is none. */
static bool known_pose(const recon_run_config *cfg, const bf_frame *f, bf_se3 *T_wc)
{
    if (cfg->known) return bf_traj_interpolate(cfg->known, f->t_depth_s, T_wc);
    if (!f->has_pose) return false;
    *T_wc = f->T_wc;
    return true;
}

/* A frame fused (or tracked) so far: the run has a map worth keeping. */
static bool has_fused(const recon_run *run)
{
    return run->is_resumed || (run->loop ? run->counts.tracked > 0 : run->n_fused > 0);
}

/* Fusion alone at a known pose: the map, made before the first frame, gets
 * its origin at the first posed frame. A repeated depth is not fused (its
 * pose has moved on from the moment it shows), a colour repeated alone
 * leaves the depth to fuse without it (core.h, "Repeated frames"). */
static bf_status fuse_known(const recon_run_config *cfg, const bf_frame *f, const bf_se3 *T_wc, bool stale_depth,
                            bool stale_rgb, recon_run *run, recon_frame_result *fr)
{
    double t0 = bf_time_s();
    memset(fr, 0, sizeof *fr);
    fr->index = f->index;
    fr->state = run->n_fused ? RECON_TRACKED : RECON_FIRST;
    fr->T_wc = *T_wc;
    bf_status s = BF_OK;
    if (stale_depth && run->n_fused) {
        fr->state = RECON_REPEATED;
        run->counts.repeated++;
        return BF_OK;
    }
    /* A frame without one depth sample in the sensor's range adds nothing
     * (a covered lens, a camera starting up, a saturated image): skipped
     * and said so, as the loop does. */
    fr->n_valid = recon__depth_in_range(f, run->depth_scale, cfg->loop.sensor.max_depth_m);
    if (!fr->n_valid) {
        fr->state = RECON_NO_DEPTH;
        run->counts.no_depth++;
        return BF_OK;
    }
    bf_frame g = *f;
    if (stale_rgb) {
        g.rgb = NULL;
        fr->colour_repeated = true;
        run->counts.colour_repeated++;
    }
    if (!run->n_fused) s = fusion_set_origin(run->map, T_wc->t);
    if (s == BF_OK) s = fusion_add_frame(run->map, &g, T_wc);
    fr->fuse = fusion_last_stage_ms(run->map);
    fr->fuse_status = s;
    if (s == BF_POOL_FULL) {
        /* As in the loop: the map stays consistent, what did not fit is
         * dropped and counted, and the frames fused so far are kept. */
        run->counts.pool_full++;
        bf_warn("recon: frame %u: %s", f->index, bf_last_error());
        s = BF_OK;
    }
    if (s != BF_OK) return s;
    fr->fused = true;
    fr->ms_frame = 1e3 * (bf_time_s() - t0);
    run->n_fused++;
    return BF_OK;
}

/* One frame through the loop (made before the first frame, at the
 * identity): the first frame's ground truth becomes the first pose. */
static bf_status track_frame_in_loop(const recon_run_config *cfg, const bf_frame *f, recon_run *run,
                                     recon_frame_result *fr)
{
    bf_status s;
    /* Until a frame starts the map (frames without depth before it are
     * skipped), each frame's ground truth is where the loop starts. */
    if (run->counts.tracked == 0 && !cfg->init_identity && !cfg->resume && f->has_pose &&
        (s = recon_set_first_pose(run->loop, &f->T_wc)) != BF_OK)
        return s;
    if (cfg->poses == RECON_POSES_TRACK_FUSE_GT) {
        s = recon_add_frame_known(run->loop, f, &f->T_wc, fr);
    } else {
        s = recon_add_frame(run->loop, f, fr);
    }
    if (s != BF_OK) return s;
    run->map = recon_map(run->loop);
    run->counts = recon_get_counts(run->loop);
    if (fr->state == RECON_LOST) {
        char tried[96] = "";
        if (fr->reloc_tried)
            snprintf(tried, sizeof tried, "; %u candidate poses tried, %u of them disagreeing with the map",
                     fr->reloc_tried, fr->reloc_rejected);
        /* --fuse-at-groundtruth fuses every frame at its true pose, lost or not. */
        bf_warn("%s: frame %u (t = %.6f): lost (ICP %s, inliers %.0f%%, residual %.1f mm%s): %s", cfg->label,
                f->index, f->t_depth_s, track_outcome_name(fr->track.outcome), 100 * fr->track.inlier_frac,
                1e3 * fr->track.residual_m, tried,
                fr->fused ? "fused at its true pose" : "not fused");
    } else if (fr->state == RECON_RELOCALISED) {
        bf_info("%s: frame %u (t = %.6f): found again from the %s candidate (%u tried; inliers %.0f%%, "
                "residual %.1f mm)",
                cfg->label, f->index, f->t_depth_s, recon_reloc_kind_name(fr->reloc), fr->reloc_tried,
                100 * fr->track.inlier_frac, 1e3 * fr->track.residual_m);
    } else if (fr->state == RECON_NO_DEPTH && fr->track.outcome == TRACK_NO_DEPTH) {
        /* Enough samples in range, too few the tracker can use. */
        bf_warn("%s: frame %u (t = %.6f): %u depth samples within the sensor's %.1f m, too few of them the "
                "tracker could use (without neighbours for a surface normal, or nothing to match): skipped",
                cfg->label, f->index, f->t_depth_s, fr->n_valid, cfg->loop.sensor.max_depth_m);
    } else if (fr->state == RECON_NO_DEPTH) {
        uint32_t need = recon_min_valid_pixels(&cfg->loop, f->width, f->height);
        bf_warn("%s: frame %u (t = %.6f): %u depth samples within the sensor's %.1f m, fewer than the %u a frame "
                "needs: skipped",
                cfg->label, f->index, f->t_depth_s, fr->n_valid, cfg->loop.sensor.max_depth_m, need);
    }
    return BF_OK;
}

/* One frame: loop or known pose, then the series, trajectories and the
 * caller's callback. */
/* f: the frame the loop reads; as_read: the same frame as the source gave
 * it, before its depth was fixed (depth_fix), for on_frame. */
static bf_status run_frame(const recon_run_config *cfg, const bf_frame *f, const bf_frame *as_read,
                           recon_frame_fn on_frame, void *user, recon_run *run)
{
    recon_frame_result fr;
    bf_status s;
    if (cfg->poses == RECON_POSES_KNOWN) {
        bf_se3 T_wc;
        run->counts.frames++; /* the loop counts its own */
        /* Every frame's images count, one without a pose too: the next
         * frame's colour may be that one's (core.h, "Repeated frames"). */
        bool stale_depth = false, stale_rgb = false;
        if (cfg->loop.skip_repeated && (s = bf_repeats_note(&run->repeats, f, &stale_depth, &stale_rgb)) != BF_OK)
            return s;
        if (!known_pose(cfg, f, &T_wc)) {
            run->n_skipped++;
            bf_warn("%s: frame %u (t = %.6f): no pose, skipped", cfg->label, f->index, f->t_depth_s);
            return BF_OK;
        }
        s = fuse_known(cfg, f, &T_wc, stale_depth, stale_rgb, run, &fr);
        if (s == BF_OK && fr.state == RECON_NO_DEPTH)
            bf_warn("%s: frame %u (t = %.6f): no depth sample within the sensor's %.1f m: skipped", cfg->label,
                    f->index, f->t_depth_s, cfg->loop.sensor.max_depth_m);
    } else if (cfg->poses == RECON_POSES_TRACK_FUSE_GT && !f->has_pose) {
        /* Nowhere to fuse it: passed over as a known-pose run passes a
         * frame without one (the loop never sees it), not the end of the run. */
        run->n_skipped++;
        bf_warn("%s: frame %u (t = %.6f): no ground-truth pose (--fuse-at-groundtruth): skipped", cfg->label,
                f->index, f->t_depth_s);
        return BF_OK;
    } else {
        s = track_frame_in_loop(cfg, f, run, &fr);
    }
    if (s == BF_OK && !run->t_first_done_s) {
        run->t_first_done_s = bf_time_s();
        run->first_frame_ms = fr.ms_frame;
    }
    if (s == BF_OK) s = push_series(&run->series, &fr, run->loop != NULL);
    if (s == BF_OK) s = bf_traj_push(&run->est, f->t_depth_s, &fr.T_wc);
    if (s == BF_OK && f->has_pose) s = bf_traj_push(&run->gt, f->t_depth_s, &f->T_wc);
    if (s == BF_OK && on_frame) s = on_frame(user, run, as_read, &fr);
    return s;
}

/* A frame the resumed scan stored: its pose is in the estimates already,
 * its ground truth (for the ATE) joins the run's. */
static bf_status note_stored(recon_run *out, const bf_frame *f)
{
    out->n_resume_skipped++;
    return f->has_pose ? bf_traj_push(&out->gt, f->t_depth_s, &f->T_wc) : BF_OK;
}

/* The end of the frames: BF_END, a stop, or a source failure the run keeps. */
static bf_status finish(const recon_run_config *cfg, bf_status s, recon_run *run)
{
    if (s != BF_END && cfg->keep_on_source_error && has_fused(run) && s != BF_VULKAN && s != BF_NO_MEMORY) {
        run->source_status = s;
        snprintf(run->source_error, sizeof run->source_error, "%s", bf_last_error());
        bf_warn("%s: %s: the source failed (%s); keeping what was reconstructed", cfg->label, cfg->name,
                run->source_error);
        s = BF_END;
    }
    if (s != BF_END) return s;
    if (!has_fused(run))
        return bf_fail(BF_FORMAT, "%s: no frame with %s%s", cfg->name,
                       cfg->poses == RECON_POSES_TRACK_FUSE_GT && run->n_skipped ? "a ground-truth pose and depth"
                       : cfg->poses != RECON_POSES_KNOWN                        ? "depth"
                       : run->counts.no_depth                                   ? "a pose and depth"
                                                                                : "a pose",
                       run->counts.no_depth ? " within the sensor's range" : "");
    return run->loop ? recon_flush(run->loop) : fusion_flush(run->map);
}

/* The loop (or, with known poses, the map) for src's camera, at the
 * identity until the first frame says otherwise. */
static bf_status prepare(gpu_context *ctx, rgbd_source *src, const recon_run_config *cfg, recon_run *run)
{
    bf_status s;
    if (cfg->poses == RECON_POSES_KNOWN) {
        fusion_config fc = recon_fusion_config(&cfg->loop);
        s = fusion_create(ctx, &fc, rgbd_source_intrinsics(src), bf_v3(0, 0, 0), &run->map);
        if (s == BF_OK) s = recon_set_colour_camera(run->map, &cfg->loop);
    } else {
        /* Images the tracker's pyramid cannot halve often enough are the
         * sequence's fault (exit 3, naming it), not a usage error. */
        const bf_intrinsics *K = rgbd_source_intrinsics(src);
        uint32_t min_side = track_min_image_side(&cfg->loop.track);
        if (K->width < min_side || K->height < min_side)
            return bf_fail(BF_FORMAT, "%s: images of %ux%u are too small to track (%u pyramid levels need at least %ux%u)",
                           cfg->name, K->width, K->height, cfg->loop.track.levels, min_side, min_side);
        bf_se3 I = bf_se3_identity();
        s = recon_create(ctx, &cfg->loop, K, &I, &run->loop);
        if (s == BF_OK) run->map = recon_map(run->loop);
    }
    const recon_resume_state *rs = cfg->resume;
    if (s == BF_OK && rs) {
        if (cfg->poses == RECON_POSES_KNOWN)
            return bf_fail(BF_INVALID_ARG, "%s: resuming a scan needs the loop (not fusion at known poses)", cfg->name);
        uint32_t last = rs->traj && rs->traj->n ? (uint32_t)rs->traj->n - 1 : 0;
        s = recon_resume(run->loop, rs->map, &rs->T_last, last, rs->traj, rs->keyframes);
        run->is_resumed = s == BF_OK;
        for (size_t i = 0; s == BF_OK && rs->traj && i < rs->traj->n; i++)
            s = bf_traj_push(&run->est, rs->traj->t_s[i], &rs->traj->T_wc[i]);
    }
    run->depth_scale = rgbd_source_intrinsics(src)->depth_scale;
    run->t_ready_s = bf_time_s();
    return s;
}

/* What the runner does to each frame's depth before the loop reads it:
 * the depth camera's lens taken out (a device's or a log's frames; a
 * folder takes out its own), then the camera's fixed pattern. */
typedef struct depth_fix {
    calib_undistort_map lens;
    uint16_t *undistorted; /* the frame's depth through the lens, or NULL: no lens */
    float *map;            /* the correction's multipliers, or NULL: none */
    uint16_t *depth;       /* the corrected depth */
    uint32_t width, height;
} depth_fix;

static void depth_fix_end(depth_fix *d)
{
    calib_undistort_map_free(&d->lens);
    free(d->undistorted);
    free(d->map);
    free(d->depth);
    memset(d, 0, sizeof *d);
}

static bf_status depth_fix_begin(depth_fix *d, const recon_run_config *cfg, const rgbd_source *src)
{
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    const calib_camera *lens = cfg->depth_lens;
    const calib_depth_correction *c = cfg->depth_correction;
    size_t n = (size_t)K->width * K->height;
    d->width = K->width, d->height = K->height;
    bf_status s = BF_OK;
    if (lens && calib_has_distortion(lens->dist)) {
        if (lens->width != K->width || lens->height != K->height)
            return bf_fail(BF_FORMAT, "%s: the depth camera's lens is for %ux%u depth images, the sequence's are %ux%u",
                           cfg->name, lens->width, lens->height, K->width, K->height);
        if ((s = calib_undistort_map_make(lens, &d->lens)) != BF_OK) return s;
        if (!(d->undistorted = malloc(n * sizeof *d->undistorted))) {
            depth_fix_end(d);
            return bf_fail(BF_NO_MEMORY, "%s: undistorting %ux%u depth", cfg->name, K->width, K->height);
        }
        bf_info("%s: the depth camera's lens is taken out of each frame's depth (up to %.1f px)", cfg->name,
                d->lens.max_shift_px);
    }
    if (!c) return BF_OK;
    if (c->width != K->width || c->height != K->height) {
        depth_fix_end(d);
        return bf_fail(BF_FORMAT, "%s: the depth correction is for %ux%u depth images, the sequence's are %ux%u",
                       cfg->name, c->width, c->height, K->width, K->height);
    }
    d->map = malloc(n * sizeof *d->map);
    d->depth = malloc(n * sizeof *d->depth);
    if (!d->map || !d->depth) {
        depth_fix_end(d);
        return bf_fail(BF_NO_MEMORY, "%s: depth correction of %ux%u", cfg->name, c->width, c->height);
    }
    calib_depth_map(c, d->map);
    return BF_OK;
}

/* f's depth replaced by the fixed one (buffers of d, valid until the next
 * frame). */
static bf_status depth_fix_frame(depth_fix *d, bf_frame *f, const char *name)
{
    if ((!d->undistorted && !d->map) || !f->depth) return BF_OK;
    if (f->width != d->width || f->height != d->height)
        return bf_fail(BF_FORMAT, "%s: frame %u is %ux%u, the sequence's depth camera %ux%u", name, f->index, f->width,
                       f->height, d->width, d->height);
    if (d->undistorted) {
        calib_undistort_u16(&d->lens, f->depth, d->undistorted);
        f->depth = d->undistorted;
    }
    if (d->map) {
        calib_depth_apply(d->map, f->depth, d->depth, (size_t)d->width * d->height);
        f->depth = d->depth;
    }
    return BF_OK;
}

bf_status recon_run_sequence(gpu_context *ctx, rgbd_source *src, const recon_run_config *cfg_in,
                             recon_frame_fn on_frame, void *user, recon_run *out)
{
    memset(out, 0, sizeof *out);
    if (!ctx || !src || !cfg_in) return bf_fail(BF_INVALID_ARG, "recon_run_sequence: NULL argument");
    recon_run_config cfg = *cfg_in;
    if (!cfg.name) cfg.name = "sequence";
    if (!cfg.label) cfg.label = "recon";
    /* Everything that compiles pipelines or allocates pools, before the
     * first frame is asked for: a capture thread starts at that request
     * (capture.h), so a camera never waits for the start-up. */
    bf_status s = prepare(ctx, src, &cfg, out);
    if (s != BF_OK) return s;
    depth_fix fix = {0};
    if ((s = depth_fix_begin(&fix, &cfg, src)) != BF_OK) return s;
    if (fix.undistorted) {
        out->has_depth_lens = true;
        memcpy(out->depth_lens_dist, cfg.depth_lens->dist, sizeof out->depth_lens_dist);
        out->depth_lens_shift_px = fix.lens.max_shift_px;
    }
    bf_progress prog;
    bf_progress_begin(&prog, cfg.label, src->n_frames);
    bf_frame f;
    uint32_t seen = 0;
    /* A resumed scan passes over the frames it stored without reading their
     * images, where the source can (a folder, a log); from another source
     * the loop below reads them and leaves them out. */
    while (cfg.resume && !(cfg.stop && *cfg.stop) && rgbd_source_pass(src, cfg.resume->t_last_s, &f) == BF_OK) {
        seen++;
        if ((s = note_stored(out, &f)) != BF_OK) {
            bf_progress_end(&prog, seen);
            depth_fix_end(&fix);
            return s;
        }
        bf_progress_update(&prog, seen);
    }
    while (!(cfg.stop && *cfg.stop) && (s = rgbd_source_next(src, &f)) == BF_OK) {
        seen++;
        /* Frames already waiting behind this one in a queue that drops: the
         * loop is behind the camera and fuses fewer frames to keep up. */
        capture_thread_stats cs = capture_threaded_stats(src);
        recon_set_behind(out->loop, cs.drops && cs.queued > 0);
        const bf_frame as_read = f; /* what on_frame sees (live --record keeps the camera's frames) */
        bf_status sf = depth_fix_frame(&fix, &f, cfg.name);
        if (sf != BF_OK) {
            bf_progress_end(&prog, seen);
            depth_fix_end(&fix);
            return sf;
        }
        if (cfg.resume && f.t_depth_s <= cfg.resume->t_last_s) {
            sf = note_stored(out, &f);
        } else {
            sf = run_frame(&cfg, &f, &as_read, on_frame, user, out);
        }
        if (sf != BF_OK) {
            bf_progress_end(&prog, seen);
            depth_fix_end(&fix);
            return sf;
        }
        bf_progress_update(&prog, seen);
    }
    bf_progress_end(&prog, seen);
    depth_fix_end(&fix);
    /* A stop may also reach the source first (a capture thread told to
     * stop ends its frames): the flag says it was the stop. */
    out->is_interrupted = cfg.stop && *cfg.stop;
    return finish(&cfg, out->is_interrupted ? BF_END : s, out);
}
