/* bitfuse record: a device (a live camera, or a recorded sequence standing
 * in for one) through the capture thread into a bitfuse log. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "capture/capture.h"
#include "replay/replay.h"

static const char record_usage[] =
    "usage: bitfuse record --device URI --out FILE.bflog [options]\n\n"
    "Records a device into a bitfuse log (docs/formats.md): depth compressed losslessly\n"
    "(zstd), colour as JPEG or zstd, a frame index for seeking. A capture thread reads\n"
    "the device into a bounded queue; when writing falls behind, the oldest queued\n"
    "frame is dropped and counted, the device is never blocked. Ctrl-C stops the\n"
    "recording and keeps every frame recorded so far in a complete log. Writes\n"
    "FILE.stats.json beside the log (frames, dropped, bytes, compression, fps).\n";

typedef struct record_args {
    const char *device, *out;
    replay_options ropt;
    replay_log_config lcfg;
    app_log_codec codec;
    uint32_t queue;
    bool realtime, overwrite;
} record_args;

static int parse_args(const char *cmd, int argc, char **argv, record_args *a)
{
    memset(a, 0, sizeof *a);
    a->codec = (app_log_codec){.colour = REPLAY_LOG_COLOUR_JPEG, .jpeg_quality = 90, .zstd_level = 1};
    a->queue = 8;
    const app_option own[] = {
        APP_OPT("--device", APP_OPT_STRING, &a->device, "URI",
                "freenect:N, openni2:[URI|FILE.oni], v4l2:/dev/videoN (docs/devices.md), or a recorded sequence "
                "standing in for a camera: a TUM, ICL-NUIM or pose-per-frame folder or a .bflog (read whole, nothing "
                "dropped, unless --realtime)",
                .required = true),
        APP_OPT("--out", APP_OPT_STRING, &a->out, "FILE.bflog",
                "the log to write (refused if it exists, unless --overwrite: a recording cannot be made again)",
                .required = true, .check = app_check_log_path),
        APP_OPT("--overwrite", APP_OPT_FLAG, &a->overwrite, NULL, "replace FILE.bflog if it exists"),
        APP_OPT("--queue", APP_OPT_U32, &a->queue, "N", "capture queue length in frames", .min = 1, .max = 1024),
        APP_OPT("--realtime", APP_OPT_FLAG, &a->realtime, NULL,
                "deliver a recorded sequence at its own frame rate, as a camera would (frames are dropped when "
                "writing falls behind)"),
        APP_OPT_END,
    };
    app_command_spec spec = {
        .name = cmd, .usage = record_usage,
        .epilog = "exit codes: 0 ok (also when stopped by Ctrl-C), 1 failure, 2 usage, 3 unreadable input\n"
                  "or device error mid-recording (the log keeps the frames before it), 4 no device,\n"
                  "5 the log could not be written (disk full, I/O error)\n",
    };
    int rc = app_parse_log_command(&spec, own, &a->codec, &a->ropt, &a->lcfg, argc, argv);
    if (!rc) rc = app_check_not_input(cmd, "--out", a->out, a->device);
    if (!rc) rc = app_check_new_recording(cmd, "--out", a->out, a->overwrite);
    /* Before the camera opens: the log's folder is not made for it. */
    return rc ? rc : app_check_out_folder(cmd, "--out", a->out);
}

/* What a recording did, for the summary and stats.json. */
typedef struct record_result {
    replay_log_stats log;
    capture_thread_stats cap;
    double seconds;
    bool is_interrupted;
    bool is_live;
    uint32_t n_unreadable; /* frames a recorded sequence's reader skipped (--skip-bad-frames) */
} record_result;

static cJSON *stats_json(const record_args *a, const char *log_path, const record_result *r, bf_status s)
{
    const replay_log_stats *L = &r->log;
    cJSON *o = app_json_stats("record");
    cJSON_AddStringToObject(o, "device", a->device);
    cJSON_AddBoolToObject(o, "live", r->is_live);
    cJSON_AddStringToObject(o, "out", log_path);
    cJSON_AddNumberToObject(o, "frames", L->n_frames);
    cJSON_AddNumberToObject(o, "captured", (double)r->cap.captured);
    cJSON_AddNumberToObject(o, "frames_unreadable", r->n_unreadable);
    cJSON_AddNumberToObject(o, "dropped", (double)r->cap.dropped);
    cJSON_AddBoolToObject(o, "interrupted", r->is_interrupted);
    /* What ended the recording, in the exit code's words, and the message. */
    cJSON_AddStringToObject(o, "status", s == BF_OK ? "ok"
                                         : s == BF_FORMAT || s == BF_IO ? "input_error"
                                         : s == BF_WRITE ? "write_error"
                                         : s == BF_VULKAN || s == BF_NO_DEVICE ? "device_error"
                                                                                : "failure");
    if (s != BF_OK) cJSON_AddStringToObject(o, "error", bf_last_error());
    else cJSON_AddNullToObject(o, "error");
    app_json_log_stats(o, &a->lcfg, L, r->seconds);
    cJSON_AddNumberToObject(o, "seconds", r->seconds);
    cJSON_AddNumberToObject(o, "fps", r->seconds > 0 ? L->n_frames / r->seconds : NAN);
    return o;
}

/* X.stats.json beside X.bflog. */
static bf_status stats_path(const char *log_path, char *out, size_t cap)
{
    size_t n = strlen(log_path);
    if (n + 12 >= cap) return bf_fail(BF_INVALID_ARG, "path too long: %s", log_path);
    snprintf(out, cap, "%.*s.stats.json", (int)(n - 6), log_path); /* minus ".bflog" */
    return BF_OK;
}

/* Records until the device ends, --frames is reached, or Ctrl-C. A device
 * error keeps the log (finished, with the frames before it) and is
 * returned; a writer error leaves the log as a crash would. */
static bf_status record_frames(const record_args *a, rgbd_source *src, replay_log_writer **w, record_result *r)
{
    app_stop_begin(src);
    uint32_t limit = a->ropt.max_frames;
    bf_progress prog;
    char label[96] = "record";
    bf_progress_begin(&prog, label, limit ? limit : src->n_frames);
    prog.label = label;
    bf_frame f;
    bf_status s;
    uint32_t n = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        /* Over an earlier log, the log is made at the first frame: a device
         * that fails before it leaves the earlier one as it was. */
        if (!*w && (s = replay_log_writer_create(a->out, rgbd_source_intrinsics(src), &a->lcfg, w))) break;
        if ((s = replay_log_writer_add(*w, &f))) break;
        n++;
        if (r->is_live || a->realtime)
            snprintf(label, sizeof label, "record (%llu dropped)",
                     (unsigned long long)capture_threaded_stats(src).dropped);
        bf_progress_update(&prog, n);
        if (limit && n >= limit) {
            s = BF_END;
            break;
        }
    }
    bf_progress_end(&prog, n);
    r->cap = capture_threaded_stats(src);
    r->is_interrupted = app_stop_end();
    return s;
}

int cmd_record(int argc, char **argv)
{
    const char *cmd = "record";
    record_args a;
    int rc = parse_args(cmd, argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    const char *log_path = a.out;
    char json_path[4200];
    bf_status s = stats_path(log_path, json_path, sizeof json_path);
    if (s != BF_OK) return app_fail(cmd, s);

    record_result r;
    memset(&r, 0, sizeof r);
    rgbd_source *src = NULL;
    replay_log_writer *w = NULL;
    double t0 = bf_time_s();
    s = app_open_device(a.device, &a.ropt, a.realtime, a.queue, &r.is_live, &src);
    if (s) return app_fail(cmd, s);
    a.lcfg.device = a.device;
    a.lcfg.has_groundtruth = src->has_groundtruth;
    /* Written in place, as a crash-cut log must still replay. A new log is
     * made now (a folder that is not there fails before the device is read);
     * over an earlier one (--overwrite), at the first frame. */
    bool replaces = bf_file_exists(log_path);
    if (!replaces && (s = replay_log_writer_create(log_path, rgbd_source_intrinsics(src), &a.lcfg, &w))) {
        rgbd_source_close(src);
        return app_fail(cmd, s);
    }
    bf_status rs = record_frames(&a, src, &w, &r);
    bf_status s_dev = rs == BF_END ? BF_OK : rs;
    char dev_err[BF_ERROR_CAP] = "";
    if (s_dev) snprintf(dev_err, sizeof dev_err, "%s", bf_last_error());
    r.n_unreadable = app_skipped_frames(src); /* atomic: the thread may still be reading after a stop */
    rgbd_source_close(src);
    /* Finish even after a device error: every frame before it is kept. A
     * failure before the first frame leaves no log (an earlier one stays). */
    bool none = s_dev && (!w || replay_log_writer_stats(w).n_frames == 0);
    bf_status s_fin = none || !w ? BF_OK : replay_log_writer_finish(w);
    if (w) r.log = replay_log_writer_stats(w);
    r.seconds = bf_time_s() - t0;
    replay_log_writer_destroy(w);
    if (none && !replaces) (void)remove(log_path);
    /* Nothing recorded over an earlier log: its stats.json stays too. */
    bool keep_stats = replaces && !w;
    s = s_dev ? s_dev : s_fin;
    if (s_dev && dev_err[0]) bf_fail(s_dev, "%s", dev_err);
    /* The recording's own failure is the one named, not a later stats.json's. */
    char err[BF_ERROR_CAP] = "";
    if (s) snprintf(err, sizeof err, "%s", bf_last_error());

    bf_status s_json = BF_OK;
    if (!keep_stats) s_json = app_json_write(json_path, stats_json(&a, log_path, &r, s));
    char json_err[BF_ERROR_CAP] = "";
    if (s_json) snprintf(json_err, sizeof json_err, "%s", bf_last_error());
    const replay_log_stats *L = &r.log;
    printf("bitfuse %s: %u frame%s from %s to %s%s\n", cmd, L->n_frames, app_s(L->n_frames), a.device, log_path,
           r.is_interrupted ? " (stopped by a signal; the log is complete up to there)" : "");
    printf("  capture   %llu captured, %llu dropped by the queue of %u\n", (unsigned long long)r.cap.captured,
           (unsigned long long)r.cap.dropped, a.queue);
    if (r.n_unreadable)
        printf("  input     %u unreadable frame%s skipped (--skip-bad-frames)\n", r.n_unreadable, app_s(r.n_unreadable));
    if (L->depth_raw_bytes) /* no frame: no ratio to give */
        printf("  depth     %.2f MB raw -> %.2f MB (%.2fx, zstd)\n", L->depth_raw_bytes / 1e6, L->depth_bytes / 1e6,
               app_ratio(L->depth_raw_bytes, L->depth_bytes));
    if (L->rgb_raw_bytes)
        printf("  colour    %.2f MB raw -> %.2f MB (%.2fx, %s)\n", L->rgb_raw_bytes / 1e6, L->rgb_bytes / 1e6,
               app_ratio(L->rgb_raw_bytes, L->rgb_bytes), app_colour_name(a.lcfg.colour));
    printf("  file      %.2f MB in %.2f s: %.1f frames/s, %.1f MB/s; stats %s %s\n", L->file_bytes / 1e6, r.seconds,
           r.seconds > 0 ? L->n_frames / r.seconds : 0.0, r.seconds > 0 ? L->file_bytes / 1e6 / r.seconds : 0.0,
           keep_stats ? "(the earlier ones) in" : s_json ? "not written to" : "in", json_path);
    if (s && s_json) bf_warn("%s", json_err);
    if (s) return app_fail(cmd, bf_fail(s, "%s", err));
    if (s_json != BF_OK) return app_fail(cmd, bf_fail(s_json, "%s", json_err));
    return APP_EXIT_OK;
}

