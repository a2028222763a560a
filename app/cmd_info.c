/* bitfuse info: reads a whole sequence and prints what it holds (format,
 * camera, frames, time span, depth statistics, ground truth). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "replay/replay.h"

static void info_help(FILE *f)
{
    fprintf(f,
            "usage: bitfuse info SEQUENCE [options] [--json]\n\n"
            "Reads every frame of a TUM RGB-D, ICL-NUIM or pose-per-frame folder and prints\n"
            "its kind, intrinsics, frame count, time span, share of pixels with depth,\n"
            "depth range (min/median/max, metres), ground truth and skipped frames.\n\n"
            "options:\n%s"
            "  --json            print the same as one JSON object on stdout\n"
            "  -h, --help        this text\n\n"
            "exit codes: 0 ok, 2 usage, 3 unreadable or malformed input\n",
            replay_options_help());
}

/* What one pass over the sequence gathers. The depth histogram has one bin
 * per raw value, so the median is exact without keeping any frame. */
typedef struct info_stats {
    uint32_t n_frames, n_with_pose, n_with_rgb;
    double t_first_s, t_last_s;
    uint64_t n_pixels, n_valid;
    uint64_t *hist; /* 65536 bins of raw depth */
} info_stats;

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
        bf_progress_update(&prog, st->n_frames);
    }
    bf_progress_end(&prog, st->n_frames);
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

int cmd_info(int argc, char **argv)
{
    replay_options opt = {0};
    const char *path = NULL;
    bool is_json = false;
    for (int i = 1; i < argc;) {
        if (app_is_help(argv[i])) {
            info_help(stdout);
            return APP_EXIT_OK;
        }
        int r = replay_parse_option(argc, argv, &i, &opt);
        if (r < 0) return app_usage_error("info", "%s", bf_last_error());
        if (r > 0) continue;
        if (!strcmp(argv[i], "--json")) {
            is_json = true;
        } else if (argv[i][0] == '-' && argv[i][1] != '\0') {
            return app_usage_error("info", "unknown option '%s'", argv[i]);
        } else if (path) {
            return app_usage_error("info", "more than one sequence given ('%s' and '%s')", path, argv[i]);
        } else {
            path = argv[i];
        }
        i++;
    }
    if (!path) return app_usage_error("info", "no sequence given");

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
    double span = st.n_frames ? st.t_last_s - st.t_first_s : NAN;
    uint32_t skipped = replay_skipped_frames(src);

    if (is_json) {
        printf("{\"path\": ");
        bf_json_string(stdout, path);
        printf(", \"kind\": ");
        bf_json_string(stdout, src->kind);
        printf(", \"width\": %u, \"height\": %u", K->width, K->height);
        printf(", \"fx\": %.10g, \"fy\": %.10g, \"cx\": %.10g, \"cy\": %.10g, \"depth_scale\": %.10g", K->fx_px,
               K->fy_px, K->cx_px, K->cy_px, K->depth_scale);
        printf(", \"frames\": %u, \"frames_listed\": %u, \"skipped_frames\": %u", st.n_frames, src->n_frames,
               skipped);
        printf(", \"frames_with_colour\": %u", st.n_with_rgb);
        /* Timestamps are ~1e9 s with microseconds: 17 digits round-trip a
         * double, 10 would round them to whole seconds. */
        printf(", \"t_first_s\": ");
        bf_json_number(stdout, st.n_frames ? st.t_first_s : NAN, 17);
        printf(", \"t_last_s\": ");
        bf_json_number(stdout, st.n_frames ? st.t_last_s : NAN, 17);
        printf(", \"duration_s\": ");
        bf_json_number(stdout, span, 10);
        printf(", \"valid_depth_share\": ");
        bf_json_number(stdout, valid_share, 10);
        printf(", \"depth_min_m\": ");
        bf_json_number(stdout, d_min, 10);
        printf(", \"depth_median_m\": ");
        bf_json_number(stdout, d_med, 10);
        printf(", \"depth_max_m\": ");
        bf_json_number(stdout, d_max, 10);
        printf(", \"has_groundtruth\": %s, \"frames_with_pose\": %u}\n", src->has_groundtruth ? "true" : "false",
               st.n_with_pose);
    } else {
        printf("sequence      %s\n", path);
        printf("kind          %s\n", src->kind);
        printf("camera        %ux%u  fx %.6g  fy %.6g  cx %.6g  cy %.6g  depth scale %.6g per metre\n", K->width,
               K->height, K->fx_px, K->fy_px, K->cx_px, K->cy_px, K->depth_scale);
        printf("frames        %u read (%u with colour), %u skipped, %u listed\n", st.n_frames, st.n_with_rgb, skipped,
               src->n_frames);
        if (st.n_frames)
            printf("time          %.6f .. %.6f s (%.3f s)\n", st.t_first_s, st.t_last_s, span);
        printf("valid depth   %.1f %% of pixels\n", 100.0 * (isfinite(valid_share) ? valid_share : 0));
        if (st.n_valid)
            printf("depth         min %.3f m, median %.3f m, max %.3f m\n", d_min, d_med, d_max);
        else
            printf("depth         none\n");
        printf("ground truth  %s (%u of %u frames have a pose)\n", src->has_groundtruth ? "yes" : "no",
               st.n_with_pose, st.n_frames);
    }
    free(st.hist);
    rgbd_source_close(src);
    return APP_EXIT_OK;
}
