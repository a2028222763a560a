/* stats.json and --json output through cJSON (Debian's libcjson): objects
 * are built, then printed once. cJSON writes NaN and infinities as null,
 * which is what JSON allows for "not measured". */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "calib/calib.h"
#include "recon/recon.h"

cJSON *app_json_stats(const char *command)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "command", command);
    cJSON_AddStringToObject(o, "version", BF_VERSION);
    return o;
}

void app_json_series(cJSON *parent, const char *name, const bf_stats *s)
{
    cJSON *o = app_json_object(parent, name);
    cJSON_AddNumberToObject(o, "median", bf_stats_percentile(s, 50));
    cJSON_AddNumberToObject(o, "p95", bf_stats_percentile(s, 95));
    cJSON_AddNumberToObject(o, "mean", bf_stats_mean(s));
}

void app_json_numbers(cJSON *parent, const char *name, const double *v, size_t n)
{
    cJSON *a = cJSON_AddArrayToObject(parent, name);
    for (size_t i = 0; i < n; i++) cJSON_AddItemToArray(a, cJSON_CreateNumber(v[i]));
}

/* cJSON reports an allocation failure as a NULL print. */
static char *print(const cJSON *root, const char *what)
{
    char *text = root ? cJSON_Print(root) : NULL;
    if (!text) bf_fail(BF_NO_MEMORY, "%s: out of memory building the JSON", what);
    return text;
}

bf_status app_json_write(const char *path, cJSON *root)
{
    char *text = print(root, path);
    bf_status s = BF_NO_MEMORY;
    if (text) {
        size_t n = strlen(text);
        text[n] = '\n'; /* the terminator becomes the file's last newline */
        s = bf_write_file_atomic(path, text, n + 1);
    }
    cJSON_free(text);
    cJSON_Delete(root);
    return s;
}

bf_status app_json_write_in(const char *dir, const char *name, cJSON *root)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, name);
    if (s != BF_OK) {
        cJSON_Delete(root);
        return s;
    }
    return app_json_write(path, root);
}

bf_status app_json_print(cJSON *root)
{
    char *text = print(root, "stdout");
    if (text) puts(text);
    cJSON_free(text);
    cJSON_Delete(root);
    return text ? BF_OK : BF_NO_MEMORY;
}

/* A float as it was set (0.1, not 0.100000001): seven significant digits
 * round-trip a float. */
static void add_float(cJSON *o, const char *name, float v)
{
    char buf[32];
    if (!isfinite(v)) {
        cJSON_AddNullToObject(o, name);
        return;
    }
    snprintf(buf, sizeof buf, "%.7g", v);
    cJSON_AddRawToObject(o, name, buf);
}

static void json_sensor(cJSON *parent, const char *name, const bf_sensor *c)
{
    cJSON *o = app_json_object(parent, name);
    add_float(o, "sigma_a", c->sigma_a);
    add_float(o, "sigma_b", c->sigma_b);
    add_float(o, "sigma_c", c->sigma_c);
    add_float(o, "max_depth_m", c->max_depth_m);
}

void app_json_fusion_config(cJSON *parent, const char *name, const fusion_config *c)
{
    cJSON *o = app_json_object(parent, name);
    add_float(o, "chunk_m", c->chunk_m);
    cJSON_AddNumberToObject(o, "max_level", c->max_level);
    add_float(o, "voxel_ratio", c->voxel_ratio);
    add_float(o, "voxel_sigmas", c->voxel_sigmas);
    cJSON_AddNumberToObject(o, "window", c->window);
    cJSON_AddNumberToObject(o, "subcache", c->subcache);
    cJSON_AddNumberToObject(o, "brick_cap", c->brick_cap);
    cJSON_AddNumberToObject(o, "node_cap", c->node_cap);
    cJSON_AddNumberToObject(o, "hash_buckets", c->hash_buckets);
    cJSON_AddNumberToObject(o, "hash_overflow", c->hash_overflow);
    json_sensor(o, "sensor", &c->sensor);
    add_float(o, "conf_weight", c->conf_weight);
    add_float(o, "band_sigmas", c->band_sigmas);
    cJSON_AddNumberToObject(o, "integrate_vpt", c->integrate_vpt);
    cJSON_AddNumberToObject(o, "integrate_bpg", c->integrate_bpg);
    cJSON_AddNumberToObject(o, "max_groups_x", c->max_groups_x);
    cJSON_AddBoolToObject(o, "keep_colour", c->keep_colour);
    cJSON_AddNumberToObject(o, "colour_frames", c->colour_frames);
    cJSON_AddNumberToObject(o, "colour_reach", c->colour_reach);
    cJSON_AddNumberToObject(o, "colour_unit_cap", c->colour_unit_cap);
    cJSON_AddBoolToObject(o, "load_only", c->load_only);
}

static void json_track_config(cJSON *parent, const char *name, const track_config *c)
{
    cJSON *o = app_json_object(parent, name);
    cJSON_AddNumberToObject(o, "levels", c->levels);
    cJSON *it = cJSON_AddArrayToObject(o, "iterations");
    for (uint32_t l = 0; l < c->levels && l < TRACK_MAX_LEVELS; l++)
        cJSON_AddItemToArray(it, cJSON_CreateNumber(c->iterations[l]));
    add_float(o, "dist_m", c->dist_m);
    add_float(o, "angle_deg", c->angle_deg);
    add_float(o, "fine_angle_deg", c->fine_angle_deg);
    json_sensor(o, "sensor", &c->sensor);
    add_float(o, "min_inlier_frac", c->min_inlier_frac);
    add_float(o, "max_residual_m", c->max_residual_m);
    add_float(o, "max_residual_sigma", c->max_residual_sigma);
    add_float(o, "max_motion_m", c->max_motion_m);
    add_float(o, "max_motion_deg", c->max_motion_deg);
    cJSON_AddNumberToObject(o, "degenerate_ratio", c->degenerate_ratio);
    cJSON_AddNumberToObject(o, "rof_iterations", c->rof_iterations);
    add_float(o, "rof_lambda0", c->rof_lambda0);
    cJSON_AddNumberToObject(o, "rof_level", c->rof_level);
    if (c->ref_level == RECON_REF_LEVEL_AUTO) cJSON_AddStringToObject(o, "ref_level", "auto");
    else cJSON_AddNumberToObject(o, "ref_level", c->ref_level);
    add_float(o, "min_valid_frac", c->min_valid_frac);
    add_float(o, "converged_m", c->converged_m);
    add_float(o, "converged_deg", c->converged_deg);
    cJSON_AddNumberToObject(o, "finest_sample_step", c->finest_sample_step);
    add_float(o, "huber_k", c->huber_k);
    cJSON_AddBoolToObject(o, "weight_noise", c->weight_noise);
    add_float(o, "noise_weight_exp", c->noise_weight_exp);
    cJSON_AddBoolToObject(o, "huber_scaled", c->huber_scaled);
    add_float(o, "huber_knee", c->huber_knee);
    add_float(o, "photo_weight", c->photo_weight);
    add_float(o, "photo_sigma", c->photo_sigma);
    cJSON_AddNumberToObject(o, "photo_levels", c->photo_levels);
    add_float(o, "photo_sharpness_min", c->photo_sharpness_min);
    add_float(o, "photo_weak_ratio", c->photo_weak_ratio);
    cJSON_AddNumberToObject(o, "icp_local", c->icp_local);
    cJSON_AddNumberToObject(o, "icp_px_per_thread", c->icp_px_per_thread);
    cJSON_AddBoolToObject(o, "icp_subgroup", c->icp_subgroup);
    cJSON_AddBoolToObject(o, "parent_normals", c->parent_normals);
    cJSON_AddBoolToObject(o, "profile", c->profile);
}

/* --calibration's file as the loop used it, its colour camera scaled to
 * the frames' size where it was calibrated at another (calib.json's own
 * layout, raw: cJSON would print its numbers again with 15 digits), or
 * null. */
static void json_calibration(cJSON *o, const recon_config *c)
{
    char *text = NULL;
    cJSON *cal = c->has_calibration && calib_to_text(&c->calibration, &text) == BF_OK ? cJSON_CreateRaw(text) : NULL;
    free(text);
    if (cal) cJSON_AddItemToObject(o, "calibration", cal);
    else cJSON_AddNullToObject(o, "calibration");
}

void app_json_depth_correction(cJSON *parent, const char *path, const struct calib_depth_correction *c)
{
    if (!path || !c) {
        cJSON_AddNullToObject(parent, "depth_correction");
        return;
    }
    cJSON *o = app_json_object(parent, "depth_correction");
    cJSON_AddStringToObject(o, "file", path);
    cJSON_AddNumberToObject(o, "cell_px", c->cell_px);
    cJSON_AddNumberToObject(o, "grid_w", c->grid_w);
    cJSON_AddNumberToObject(o, "grid_h", c->grid_h);
    float lo, hi;
    calib_depth_range(c, &lo, &hi);
    add_float(o, "min_multiplier", lo);
    add_float(o, "max_multiplier", hi);
    cJSON_AddNumberToObject(o, "rms_before", c->rms_before);
    cJSON_AddNumberToObject(o, "rms_after", c->rms_after);
    /* The lens of the frames it was made from, as the file says (absent:
     * it does not say). */
    if (c->is_lens_known && calib_has_distortion(c->lens)) app_json_numbers(o, "undistorted", c->lens, CALIB_DIST_N);
    else if (c->is_lens_known) cJSON_AddNullToObject(o, "undistorted");
}

void app_json_recon_config(cJSON *parent, const char *name, const recon_config *c)
{
    cJSON *o = app_json_object(parent, name);
    /* The loop hands its sensor to fusion and tracking: echo what they use. */
    fusion_config fc = recon_fusion_config(c);
    track_config tc = c->track;
    tc.sensor = c->sensor;
    json_sensor(o, "sensor", &c->sensor);
    app_json_fusion_config(o, "fusion", &fc);
    json_track_config(o, "track", &tc);
    cJSON *l = app_json_object(o, "loop");
    cJSON_AddNumberToObject(l, "min_valid_pixels", c->min_valid_pixels);
    cJSON_AddBoolToObject(l, "fuse_degenerate", c->fuse_degenerate);
    cJSON_AddBoolToObject(l, "constant_velocity", c->constant_velocity);
    cJSON_AddBoolToObject(l, "reference_confident", c->reference_confident);
    cJSON_AddBoolToObject(l, "skip_repeated", c->skip_repeated);
    cJSON_AddNumberToObject(l, "fuse_every", c->fuse_every);
    cJSON_AddNumberToObject(l, "fuse_every_behind", c->fuse_every_behind);
    cJSON_AddBoolToObject(l, "start_at_frame", c->start_at_frame);
    cJSON *rl = app_json_object(l, "reloc");
    cJSON_AddBoolToObject(rl, "enabled", c->reloc.enabled);
    cJSON_AddNumberToObject(rl, "max_candidates", c->reloc.max_candidates);
    add_float(rl, "max_gate_intervals", c->reloc.max_gate_intervals);
    add_float(rl, "keyframe_m", c->reloc.keyframe_m);
    add_float(rl, "keyframe_deg", c->reloc.keyframe_deg);
    cJSON_AddNumberToObject(rl, "max_keyframes", c->reloc.max_keyframes);
    add_float(rl, "min_inlier_frac", c->reloc.min_inlier_frac);
    add_float(rl, "max_residual_m", c->reloc.max_residual_m);
    add_float(rl, "max_residual_sigma", c->reloc.max_residual_sigma);
    cJSON_AddNumberToObject(rl, "check_step", c->reloc.check_step);
    add_float(rl, "check_band_m", c->reloc.check_band_m);
    add_float(rl, "max_front_frac", c->reloc.max_front_frac);
    cJSON_AddNumberToObject(rl, "features", c->reloc.features);
    cJSON_AddNumberToObject(rl, "feature_candidates", c->reloc.feature_candidates);
    cJSON_AddNumberToObject(rl, "feature_min_inliers", c->reloc.feature_min_inliers);
    cJSON_AddBoolToObject(rl, "last_frame", c->reloc.last_frame);
    add_float(rl, "last_frame_below", c->reloc.last_frame_below);
    cJSON_AddBoolToObject(l, "has_views", c->has_views);
    json_calibration(o, c);
    cJSON *sm = app_json_object(l, "stream");
    cJSON_AddBoolToObject(sm, "enabled", c->stream.enabled);
    add_float(sm, "radius_m", c->stream.radius_m);
    add_float(sm, "hysteresis_m", c->stream.hysteresis_m);
    cJSON_AddNumberToObject(sm, "every_frames", c->stream.every_frames);
    cJSON_AddNumberToObject(sm, "max_chunks", c->stream.max_chunks);
    add_float(sm, "high_water", c->stream.high_water);
    cJSON_AddNumberToObject(sm, "cache_bytes", (double)c->stream.cache_bytes);
    cJSON *r = app_json_object(l, "raycast");
    cJSON_AddBoolToObject(r, "confident_only", c->raycast.confident_only);
    cJSON_AddBoolToObject(r, "refine", c->raycast.refine);
    add_float(r, "near_m", c->raycast.near_m);
    add_float(r, "far_m", c->raycast.far_m);
    add_float(r, "start_margin_m", c->raycast.start_margin_m);
    add_float(r, "start_margin_z2", c->raycast.start_margin_z2);
    cJSON_AddBoolToObject(r, "no_shade", c->raycast.no_shade);
    cJSON *cs = app_json_object(l, "caster");
    cJSON_AddNumberToObject(cs, "local_x", c->caster.local_x);
    cJSON_AddNumberToObject(cs, "local_y", c->caster.local_y);
}
