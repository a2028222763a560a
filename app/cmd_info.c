/* bitfuse info: reads a whole sequence and prints what it holds (format,
 * camera, frames, time span, depth statistics, ground truth). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "replay/replay.h"

static const char info_usage[] =
    "usage: bitfuse info SEQUENCE|STORE [options] [--json]\n\n"
    "Reads every frame of a TUM RGB-D, ICL-NUIM or pose-per-frame folder and prints\n"
    "its kind, intrinsics, frame count, time span, share of pixels with depth,\n"
    "depth range (min/median/max, metres), ground truth, skipped frames, and the frames\n"
    "whose depth or colour repeats the frame before byte for byte (a driver that handed\n"
    "on the last image when a new one was late: no new data, and no motion in it).\n"
    "Of a scene store (replay|live --store; or a folder holding one as STORE/store):\n"
    "chunks, bricks per level, bytes on disk, extent, frames, the last pose, the\n"
    "relocalisation keyframes and any damage found (bad or missing chunk files, an\n"
    "unreadable keyframes.bin).\n";

/* What one pass over the sequence gathers. The depth histogram has one bin
 * per raw value, so the median is exact without keeping any frame. */
#define INFO_REPEATS_LISTED 12

typedef struct info_stats {
    uint32_t n_frames, n_with_pose, n_with_rgb;
    /* Frames whose depth (colour) is the previous frame's byte for byte,
     * and the first few of them. */
    uint32_t n_depth_repeats, n_rgb_repeats;
    uint32_t depth_repeats[INFO_REPEATS_LISTED], rgb_repeats[INFO_REPEATS_LISTED];
    bf_repeats repeats;
    double t_first_s, t_last_s;
    uint64_t n_pixels, n_valid;
    uint64_t *hist; /* 65536 bins of raw depth */
} info_stats;

/* Counts a frame whose depth or colour repeats (core.h, "Repeated frames":
 * the rule the loop skips a depth by and leaves a colour out by). */
static bf_status note_repeats(info_stats *st, const bf_frame *f)
{
    bool dr, cr;
    bf_status s = bf_repeats_note(&st->repeats, f, &dr, &cr);
    if (s != BF_OK) return s;
    if (dr && st->n_depth_repeats < INFO_REPEATS_LISTED) st->depth_repeats[st->n_depth_repeats] = f->index;
    if (cr && st->n_rgb_repeats < INFO_REPEATS_LISTED) st->rgb_repeats[st->n_rgb_repeats] = f->index;
    st->n_depth_repeats += dr;
    st->n_rgb_repeats += cr;
    return BF_OK;
}

static bf_status info_gather(rgbd_source *src, info_stats *st)
{
    bf_progress prog;
    bf_progress_begin(&prog, "info: frames", src->n_frames);
    bf_frame f;
    bf_status s;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        if (st->n_frames == 0) st->t_first_s = f.t_depth_s;
        st->t_last_s = f.t_depth_s;
        st->n_frames++;
        st->n_with_pose += f.has_pose;
        st->n_with_rgb += f.rgb != NULL;
        size_t n = (size_t)f.width * f.height;
        st->n_pixels += n;
        for (size_t i = 0; i < n; i++) st->hist[f.depth[i]]++;
        if ((s = note_repeats(st, &f)) != BF_OK) break;
        bf_progress_update(&prog, st->n_frames);
    }
    bf_progress_end(&prog, st->n_frames);
    bf_repeats_free(&st->repeats);
    if (s != BF_END) return s;
    st->n_valid = st->n_pixels - st->hist[0];
    return BF_OK;
}

/* Raw value at rank k (0-based) among valid pixels. */
static uint32_t hist_rank(const uint64_t *hist, uint64_t k)
{
    uint64_t acc = 0;
    for (uint32_t v = 1; v < 65536; v++) {
        acc += hist[v];
        if (acc > k) return v;
    }
    return 65535;
}

static void print_repeats(const char *what, uint32_t n, const uint32_t *first)
{
    printf("repeats       %u %s frame%s the one before byte for byte", n, what, n == 1 ? " repeats" : "s repeat");
    uint32_t k = n < INFO_REPEATS_LISTED ? n : INFO_REPEATS_LISTED;
    for (uint32_t i = 0; i < k; i++) printf("%s%u", i ? ", " : n == 1 ? " (frame " : " (frames ", first[i]);
    printf("%s\n", n > k ? ", ...)" : k ? ")" : "");
}

int cmd_info(int argc, char **argv)
{
    replay_options opt = {0};
    const char *path = NULL;
    bool is_json = false;
    const app_option own[] = {
        APP_OPT("--json", APP_OPT_FLAG, &is_json, NULL, "print the same as one JSON object on stdout"),
        APP_OPT_END,
    };
    app_option seq[APP_SEQUENCE_ROWS];
    app_sequence_options(seq, &opt);
    const app_option *tables[] = {seq, own, NULL};
    app_command_spec spec = {
        .name = "info", .usage = info_usage, .tables = tables, .positional = &path, .min_positional = 1,
        .max_positional = 1, .positional_missing = "no sequence given",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 unreadable or malformed input (also a store of a newer "
                  "version),\n5 standard output could not be written\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    /* A run's folder holding its store as DIR/store (replay --out DIR
     * --store DIR/store), as export, render and view take it, unless DIR is
     * itself a sequence (its index files decide). */
    char sub[4096];
    const char *store = app_store_dir(path, sub, sizeof sub);
    if (store && store != path && !replay_is_sequence_dir(path)) path = store;
    if (store_exists(path)) {
        /* A store holds no frames: the sequence options would mean nothing. */
        if (opt.camera || opt.depth_scale > 0 || opt.max_frames || opt.skip_bad_frames)
            return app_usage_error("info", "%s is a scene store: --camera, --depth-scale, --frames and "
                                           "--skip-bad-frames are for a sequence", path);
        return app_info_store(path, is_json);
    }

    rgbd_source *src = NULL;
    info_stats st = {0};
    st.hist = calloc(65536, sizeof *st.hist);
    if (!st.hist) return app_fail("info", bf_fail(BF_NO_MEMORY, "depth histogram"));
    bf_status s = replay_open(path, &opt, &src);
    if (s == BF_OK) s = info_gather(src, &st);
    /* Every frame skipped (--skip-bad-frames) leaves nothing to describe: a
     * script must not take that sequence for a good one. */
    if (s == BF_OK && st.n_frames == 0)
        s = bf_fail(BF_FORMAT, "%s: no frame could be read (%u skipped)", path, replay_skipped_frames(src));
    if (s) {
        free(st.hist);
        rgbd_source_close(src);
        return app_fail("info", s);
    }
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    double scale = K->depth_scale;
    double d_min = NAN, d_med = NAN, d_max = NAN;
    if (st.n_valid) {
        d_min = hist_rank(st.hist, 0) / scale;
        d_max = hist_rank(st.hist, st.n_valid - 1) / scale;
        /* Median: mean of the two middle ranks for an even count. */
        d_med = 0.5 * (hist_rank(st.hist, (st.n_valid - 1) / 2) + hist_rank(st.hist, st.n_valid / 2)) / scale;
    }
    double valid_share = st.n_pixels ? (double)st.n_valid / (double)st.n_pixels : NAN;
    /* To the microsecond, the stamps' own resolution: the difference of two
     * times near 1.3e9 s carries the doubles' 2.4e-7 s steps (1.2999999523). */
    double span = st.n_frames ? round((st.t_last_s - st.t_first_s) * 1e6) / 1e6 : NAN;
    uint32_t skipped = replay_skipped_frames(src);
    double lens[CALIB_DIST_N], lens_shift = 0;
    bool has_lens = replay_undistortion(src, lens, &lens_shift);

    if (is_json) {
        /* cJSON prints doubles that round-trip: timestamps keep their microseconds. */
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "path", path);
        cJSON_AddStringToObject(o, "kind", src->kind);
        cJSON_AddNumberToObject(o, "width", K->width);
        cJSON_AddNumberToObject(o, "height", K->height);
        cJSON_AddNumberToObject(o, "fx", K->fx_px);
        cJSON_AddNumberToObject(o, "fy", K->fy_px);
        cJSON_AddNumberToObject(o, "cx", K->cx_px);
        cJSON_AddNumberToObject(o, "cy", K->cy_px);
        cJSON_AddNumberToObject(o, "depth_scale", K->depth_scale);
        /* The lens as stats.json's camera object has it. */
        if (has_lens) {
            app_json_numbers(o, "undistorted", lens, CALIB_DIST_N);
            cJSON_AddNumberToObject(o, "undistort_max_shift_px", lens_shift);
        } else {
            cJSON_AddNullToObject(o, "undistorted");
            cJSON_AddNullToObject(o, "undistort_max_shift_px");
        }
        cJSON_AddNumberToObject(o, "frames", st.n_frames);
        cJSON_AddNumberToObject(o, "frames_listed", src->n_frames);
        cJSON_AddNumberToObject(o, "skipped_frames", skipped);
        cJSON_AddNumberToObject(o, "frames_with_colour", st.n_with_rgb);
        cJSON_AddNumberToObject(o, "t_first_s", st.n_frames ? st.t_first_s : NAN);
        cJSON_AddNumberToObject(o, "t_last_s", st.n_frames ? st.t_last_s : NAN);
        cJSON_AddNumberToObject(o, "duration_s", span);
        cJSON_AddNumberToObject(o, "valid_depth_share", valid_share);
        cJSON_AddNumberToObject(o, "depth_min_m", d_min);
        cJSON_AddNumberToObject(o, "depth_median_m", d_med);
        cJSON_AddNumberToObject(o, "depth_max_m", d_max);
        cJSON_AddBoolToObject(o, "has_groundtruth", src->has_groundtruth);
        cJSON_AddNumberToObject(o, "frames_with_pose", st.n_with_pose);
        cJSON_AddNumberToObject(o, "repeated_depth_frames", st.n_depth_repeats);
        cJSON_AddNumberToObject(o, "repeated_colour_frames", st.n_rgb_repeats);
        double first[INFO_REPEATS_LISTED];
        uint32_t k = st.n_depth_repeats < INFO_REPEATS_LISTED ? st.n_depth_repeats : INFO_REPEATS_LISTED;
        for (uint32_t i = 0; i < k; i++) first[i] = st.depth_repeats[i];
        app_json_numbers(o, "repeated_depth_first", first, k);
        k = st.n_rgb_repeats < INFO_REPEATS_LISTED ? st.n_rgb_repeats : INFO_REPEATS_LISTED;
        for (uint32_t i = 0; i < k; i++) first[i] = st.rgb_repeats[i];
        app_json_numbers(o, "repeated_colour_first", first, k);
        s = app_json_print(o);
    } else {
        printf("sequence      %s\n", path);
        printf("kind          %s\n", src->kind);
        printf("camera        %ux%u  fx %.6g  fy %.6g  cx %.6g  cy %.6g  depth scale %.6g per metre\n", K->width,
               K->height, K->fx_px, K->fy_px, K->cx_px, K->cy_px, K->depth_scale);
        if (has_lens)
            printf("lens          k1 %.6g  k2 %.6g  p1 %.6g  p2 %.6g  k3 %.6g: taken out of every frame (pixels move "
                   "up to %.1f px)\n",
                   lens[0], lens[1], lens[2], lens[3], lens[4], lens_shift);
        printf("frames        %u read (%u with colour), %u skipped, %u listed\n", st.n_frames, st.n_with_rgb, skipped,
               src->n_frames);
        if (st.n_frames)
            printf("time          %.6f .. %.6f s (%.3f s)\n", st.t_first_s, st.t_last_s, span);
        printf("valid depth   %.1f %% of pixels\n", 100.0 * (isfinite(valid_share) ? valid_share : 0));
        if (st.n_valid)
            printf("depth         min %.3f m, median %.3f m, max %.3f m\n", d_min, d_med, d_max);
        else
            printf("depth         none\n");
        printf("ground truth  %s (%u of %u frame%s %s a pose)\n", src->has_groundtruth ? "yes" : "no",
               st.n_with_pose, st.n_frames, app_s(st.n_frames), st.n_with_pose == 1 ? "has" : "have");
        print_repeats("depth", st.n_depth_repeats, st.depth_repeats);
        if (st.n_with_rgb) print_repeats("colour", st.n_rgb_repeats, st.rgb_repeats);
    }
    free(st.hist);
    rgbd_source_close(src);
    return s == BF_OK ? APP_EXIT_OK : app_fail("info", s);
}
