/* bitfuse convert: any sequence replay_open reads (TUM, ICL-NUIM, pose
 * folders, bitfuse logs) into a TUM folder or a bitfuse log. Reading runs
 * on the capture thread (lossless: nothing is dropped), so decoding and
 * encoding overlap on two cores. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "app.h"
#include "capture/capture.h"
#include "replay/replay.h"

static const char convert_usage[] =
    "usage: bitfuse convert SEQUENCE --out DEST [options]\n\n"
    "Reads SEQUENCE (a TUM, ICL-NUIM or pose-per-frame folder, or a .bflog) and writes it\n"
    "as a bitfuse log when DEST ends in .bflog (replacing one there once it is whole), else\n"
    "as a TUM folder (docs/formats.md), which must not hold a sequence already.\n"
    "Depth, timestamps and poses carry over exactly; colour too, except with --colour jpeg.\n"
    "Writes DEST's stats (frames, bytes, compression ratio, fps) to X.stats.json beside\n"
    "X.bflog, or to DEST/stats.json for a folder.\n";

typedef struct convert_args {
    const char *in, *out;
    replay_options ropt;
    replay_log_config lcfg;
    app_log_codec codec;
    bool to_log;
} convert_args;

static int parse_args(int argc, char **argv, convert_args *a)
{
    memset(a, 0, sizeof *a);
    a->codec = (app_log_codec){.colour = REPLAY_LOG_COLOUR_ZSTD, .jpeg_quality = 90, .zstd_level = 1};
    const app_option own[] = {
        APP_OPT("--out", APP_OPT_STRING, &a->out, "DEST", "X.bflog or a folder (created)", .required = true),
        APP_OPT_END,
    };
    app_command_spec spec = {
        .name = "convert", .usage = convert_usage, .positional = &a->in, .min_positional = 1, .max_positional = 1,
        .positional_missing = "no sequence given",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 unreadable or malformed input, 5 an output\n"
                  "could not be written (disk full, I/O error)\n",
    };
    int rc = app_parse_log_command(&spec, own, &a->codec, &a->ropt, &a->lcfg, argc, argv);
    if (rc) return rc;
    a->to_log = replay_is_log_path(a->out);
    if (!a->out[0]) return app_usage_error("convert", "--out needs a .bflog file or a folder, not ''");
    /* Checked before the work: the finished log could not be put there. */
    struct stat st;
    if (a->to_log && stat(a->out, &st) == 0 && S_ISDIR(st.st_mode))
        return app_usage_error("convert", "--out %s is a folder: a log needs a file's name", a->out);
    /* A folder keeps PNG images: the log's codecs would be ignored. */
    if (!a->to_log && (a->codec.colour_given || a->codec.quality_given || a->codec.level_given))
        return app_usage_error("convert", "--colour, --jpeg-quality and --zstd-level are a .bflog's codecs; a TUM "
                                          "folder keeps PNG images");
    /* A failed or cut conversion leaves a log already at DEST as it was. */
    a->lcfg.replace_when_finished = true;
    rc = app_check_not_input("convert", "--out", a->out, a->in);
    /* A log's folder is not made for it (a folder's own parents are): named before the work. */
    if (!rc && a->to_log) rc = app_check_out_folder("convert", "--out", a->out);
    /* Not into a sequence (its images would be overwritten one by one, and a
     * conversion failing part-way would leave two sequences mixed under the
     * old index; a log is replaced whole instead), nor over a run's
     * stats.json. */
    return rc || a->to_log ? rc : app_check_out_not_sequence("convert", a->out, true);
}

/* The frames of src into the log or TUM writer (exactly one is set), until
 * the source ends or *stop is set (Ctrl-C: what was converted is kept). */
static bf_status convert_frames(rgbd_source *src, replay_log_writer *lw, replay_tum_writer *tw,
                                const volatile sig_atomic_t *stop, uint32_t *n_out, bool *kept)
{
    *kept = false;
    bf_progress prog;
    bf_progress_begin(&prog, "convert", src->n_frames);
    bf_frame f;
    bf_status s = BF_END;
    uint32_t n = 0;
    while (!*stop && (s = rgbd_source_next(src, &f)) == BF_OK) {
        s = lw ? replay_log_writer_add(lw, &f) : replay_tum_writer_add(tw, &f);
        if (s) break;
        bf_progress_update(&prog, ++n);
    }
    bf_progress_end(&prog, n);
    *n_out = n;
    if (*stop && s == BF_OK) s = BF_END;
    if (*stop && n == 0) return BF_END; /* stopped before any frame: nothing to finish */
    /* A bad input frame ends a folder with the frames before it indexed, so
     * they read (a log keeps an earlier log at DEST as it was instead). */
    if (tw && n > 0 && (s == BF_FORMAT || s == BF_IO)) {
        char msg[BF_ERROR_CAP];
        snprintf(msg, sizeof msg, "%s", bf_last_error());
        if (replay_tum_writer_finish(tw) == BF_OK) {
            *kept = true;
            return bf_fail(s, "%s (the %u frames before it are in the folder)", msg, n);
        }
        return bf_fail(s, "%s", msg);
    }
    if (s != BF_END) return s;
    if (n == 0) return bf_fail(BF_FORMAT, "no frame could be read");
    return lw ? replay_log_writer_finish(lw) : replay_tum_writer_finish(tw);
}

int cmd_convert(int argc, char **argv)
{
    const char *cmd = "convert";
    convert_args a;
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    double t0 = bf_time_s();
    rgbd_source *dev = NULL, *src = NULL;
    replay_log_writer *lw = NULL;
    replay_tum_writer *tw = NULL;
    bf_status s = replay_open(a.in, &a.ropt, &dev);
    if (s) return app_fail(cmd, s);
    if ((s = capture_threaded_lossless(dev, 4, &src))) {
        rgbd_source_close(dev);
        return app_fail(cmd, s);
    }
    a.lcfg.device = a.in;
    a.lcfg.has_groundtruth = src->has_groundtruth;
    /* Ctrl-C or SIGTERM ends the conversion as it ends a recording: the
     * frames converted so far are written, whole (a second one kills).
     * Caught before the writer exists, so no signal leaves its .partial. */
    const volatile sig_atomic_t *stop = app_stop_begin(NULL);
    s = a.to_log ? replay_log_writer_create(a.out, rgbd_source_intrinsics(src), &a.lcfg, &lw)
                 : replay_tum_writer_create(a.out, rgbd_source_intrinsics(src), &tw);
    uint32_t n = 0;
    bool kept = false; /* a bad input frame ended the folder with the frames before it */
    if (s == BF_OK) s = convert_frames(src, lw, tw, stop, &n, &kept);
    bool interrupted = app_stop_end();
    uint32_t skipped = app_skipped_frames(dev);
    replay_log_stats L = {0};
    if (lw) L = replay_log_writer_stats(lw);
    double seconds = bf_time_s() - t0;
    rgbd_source_close(src);
    replay_log_writer_destroy(lw);
    replay_tum_writer_destroy(tw);
    if (s == BF_END) { /* stopped before any frame: the writers left nothing (an earlier log stays) */
        char p[4200];
        for (int i = 0; !a.to_log && i < 2; i++) /* a folder's empty image folders (rmdir takes only empty ones) */
            if (snprintf(p, sizeof p, "%s/%s", a.out, i ? "rgb" : "depth") < (int)sizeof p) (void)rmdir(p);
        if (!a.to_log) (void)rmdir(a.out);
        printf("bitfuse convert: stopped by a signal before any frame: nothing written\n");
        return APP_EXIT_OK;
    }
    /* The folder's frames before a bad one are kept: its stats.json says
     * so (input_error), as replay's and fuse's do, and the exit is 3. */
    char input_error[BF_ERROR_CAP] = "";
    bf_status s_input = s;
    if (s && kept) snprintf(input_error, sizeof input_error, "%s", bf_last_error());
    else if (s) return app_fail(cmd, s);

    char json_path[4200];
    size_t len = strlen(a.out);
    if (a.to_log)
        snprintf(json_path, sizeof json_path, "%.*s.stats.json", (int)(len - 6), a.out);
    else if ((s = bf_path_join(json_path, sizeof json_path, a.out, "stats.json")))
        return app_fail(cmd, s);
    cJSON *o = app_json_stats("convert");
    cJSON_AddStringToObject(o, "in", a.in);
    cJSON_AddStringToObject(o, "out", a.out);
    cJSON_AddStringToObject(o, "format", a.to_log ? "bflog" : "tum");
    cJSON_AddNumberToObject(o, "frames", n);
    cJSON_AddNumberToObject(o, "skipped", skipped);
    cJSON_AddNumberToObject(o, "dropped", 0);
    cJSON_AddBoolToObject(o, "interrupted", interrupted);
    if (input_error[0]) cJSON_AddStringToObject(o, "input_error", input_error);
    else cJSON_AddNullToObject(o, "input_error");
    if (a.to_log) app_json_log_stats(o, &a.lcfg, &L, seconds);
    cJSON_AddNumberToObject(o, "seconds", seconds);
    cJSON_AddNumberToObject(o, "fps", seconds > 0 ? n / seconds : NAN);
    if ((s = app_json_write(json_path, o)) != BF_OK) {
        if (input_error[0]) bf_warn("%s: %s", cmd, input_error); /* the folder is cut short: said either way */
        return app_fail(cmd, s);
    }
    if (input_error[0]) return app_fail(cmd, bf_fail(s_input, "%s", input_error));

    printf("bitfuse convert: %u frame%s (%u skipped) from %s to %s (%s)%s\n", n, app_s(n), skipped, a.in, a.out,
           a.to_log ? "bitfuse log" : "TUM folder", interrupted ? " (stopped by a signal; complete up to there)" : "");
    if (a.to_log) {
        printf("  depth     %.2f MB raw -> %.2f MB (%.2fx, zstd)\n", L.depth_raw_bytes / 1e6, L.depth_bytes / 1e6,
               app_ratio(L.depth_raw_bytes, L.depth_bytes));
        if (L.rgb_raw_bytes) /* the codec named, as record names it */
            printf("  colour    %.2f MB raw -> %.2f MB (%.2fx, %s)\n", L.rgb_raw_bytes / 1e6, L.rgb_bytes / 1e6,
                   app_ratio(L.rgb_raw_bytes, L.rgb_bytes), app_colour_name(a.lcfg.colour));
        printf("  file      %.2f MB, %.1f MB/s\n", L.file_bytes / 1e6, seconds > 0 ? L.file_bytes / 1e6 / seconds : 0);
    }
    printf("  time      %.2f s, %.1f frames/s; stats in %s\n", seconds, seconds > 0 ? n / seconds : 0.0, json_path);
    return APP_EXIT_OK;
}
