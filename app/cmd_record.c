/* bitfuse record: a device (a live camera, or a recorded sequence standing
 * in for one) through the capture thread into a bitfuse log. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "capture/capture.h"
#include "replay/replay.h"

static void record_help(FILE *f)
{
    fprintf(f, "usage: bitfuse record --device URI --out FILE.bflog [options]\n\n"
               "Records a device into a bitfuse log (docs/formats.md): depth compressed losslessly\n"
               "(zstd), colour as JPEG or zstd, a frame index for seeking. A capture thread reads\n"
               "the device into a bounded queue; when writing falls behind, the oldest queued\n"
               "frame is dropped and counted, the device is never blocked. Ctrl-C stops the\n"
               "recording and keeps every frame recorded so far in a complete log. Writes\n"
               "FILE.stats.json beside the log (frames, dropped, bytes, compression, fps).\n\n");
    fprintf(f,
            "options:\n"
            "  --device URI       freenect:N, openni2:[URI|FILE.oni], v4l2:/dev/videoN (docs/devices.md),\n"
            "                     or a recorded sequence standing in for a camera: a TUM, ICL-NUIM or\n"
            "                     pose-per-frame folder or a .bflog (read whole, nothing dropped,\n"
            "                     unless --realtime)\n"
            "  --out FILE.bflog   the log to write (replaced if it exists)\n"
            "  --frames N         stop after N frames (default: until the device ends or Ctrl-C)\n"
            "  --colour C         jpeg (default), zstd (lossless) or none\n"
            "  --jpeg-quality Q   1..100, default 90\n"
            "  --zstd-level L     zstd level for depth (and zstd colour), default 1\n"
            "  --queue N          capture queue length in frames, default 8\n"
            "  --realtime         deliver a recorded sequence at its own frame rate, as a camera\n"
            "                     would (frames are dropped when writing falls behind)\n"
            "  --camera C, --depth-scale S, --skip-bad-frames   for a recorded sequence, as in\n"
            "                     bitfuse info (docs/formats.md)\n"
            "  -h, --help         this text\n\n"
            "exit codes: 0 ok (also when stopped by Ctrl-C), 1 failure, 2 usage, 3 unreadable input\n"
            "or device error mid-recording (the log keeps the frames before it), 4 no device\n");
}

/* ------------------------------------------------------------ the command */

typedef struct record_args {
    const char *device, *out;
    replay_options ropt;
    replay_log_config lcfg;
    uint32_t queue;
    bool realtime;
} record_args;

static int parse_args(const char *cmd, int argc, char **argv, record_args *a)
{
    memset(a, 0, sizeof *a);
    a->lcfg.colour = REPLAY_LOG_COLOUR_JPEG;
    a->queue = 8;
    for (int i = 1; i < argc;) {
        const char *o = argv[i];
        if (app_is_help(o)) {
            record_help(stdout);
            return -1;
        }
        int r = replay_parse_option(argc, argv, &i, &a->ropt);
        if (r < 0) return app_usage_error(cmd, "%s", bf_last_error());
        if (r > 0) continue;
        if (!strcmp(o, "--realtime")) {
            a->realtime = true;
            i++;
            continue;
        }
        if (o[0] != '-') return app_usage_error(cmd, "unknown argument '%s'", o);
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v) return app_usage_error(cmd, "%s needs a value", o);
        uint32_t u;
        if (!strcmp(o, "--device")) {
            a->device = v;
        } else if (!strcmp(o, "--out")) {
            a->out = v;
        } else if (!strcmp(o, "--colour") || !strcmp(o, "--color")) {
            if (!strcmp(v, "jpeg")) a->lcfg.colour = REPLAY_LOG_COLOUR_JPEG;
            else if (!strcmp(v, "zstd")) a->lcfg.colour = REPLAY_LOG_COLOUR_ZSTD;
            else if (!strcmp(v, "none")) a->lcfg.colour = REPLAY_LOG_COLOUR_NONE;
            else return app_usage_error(cmd, "--colour takes jpeg, zstd or none, not '%s'", v);
        } else if (!strcmp(o, "--jpeg-quality") && bf_parse_u32(v, &u) && u >= 1 && u <= 100) {
            a->lcfg.jpeg_quality = (int)u;
        } else if (!strcmp(o, "--zstd-level") && bf_parse_u32(v, &u) && u >= 1 && u <= 19) {
            a->lcfg.zstd_level = (int)u;
        } else if (!strcmp(o, "--queue") && bf_parse_u32(v, &u) && u >= 1 && u <= 1024) {
            a->queue = u;
        } else if (!strcmp(o, "--jpeg-quality") || !strcmp(o, "--zstd-level") || !strcmp(o, "--queue")) {
            return app_usage_error(cmd, "bad value for %s: '%s'", o, v);
        } else {
            return app_usage_error(cmd, "unknown option '%s'", o);
        }
        i += 2;
    }
    if (!a->device) return app_usage_error(cmd, "--device is required");
    if (!a->out) return app_usage_error(cmd, "--out is required");
    return 0;
}

/* What a recording did, for the summary and stats.json. */
typedef struct record_result {
    replay_log_stats log;
    capture_thread_stats cap;
    double seconds;
    bool is_interrupted;
    bool is_live;
} record_result;

static double ratio(uint64_t raw, uint64_t packed) { return packed ? (double)raw / (double)packed : NAN; }

static void write_stats_json(FILE *f, const char *cmd, const record_args *a, const char *log_path,
                             const record_result *r, bf_status s)
{
    const replay_log_stats *L = &r->log;
    double mb = (double)L->file_bytes / 1e6;
    fprintf(f, "{\n  \"command\": ");
    bf_json_string(f, cmd);
    fprintf(f, ",\n  \"device\": ");
    bf_json_string(f, a->device);
    fprintf(f, ",\n  \"live\": %s,\n  \"out\": ", r->is_live ? "true" : "false");
    bf_json_string(f, log_path);
    fprintf(f, ",\n  \"colour_codec\": \"%s\",\n", a->lcfg.colour == REPLAY_LOG_COLOUR_JPEG   ? "jpeg"
                                                  : a->lcfg.colour == REPLAY_LOG_COLOUR_ZSTD ? "zstd"
                                                                                             : "none");
    fprintf(f, "  \"frames\": %u,\n  \"captured\": %llu,\n  \"dropped\": %llu,\n  \"interrupted\": %s,\n", L->n_frames,
            (unsigned long long)r->cap.captured, (unsigned long long)r->cap.dropped,
            r->is_interrupted ? "true" : "false");
    fprintf(f, "  \"status\": ");
    bf_json_string(f, s == BF_OK ? "ok" : bf_status_name(s));
    fprintf(f, ",\n  \"bytes\": %llu,\n  \"depth_raw_bytes\": %llu,\n  \"depth_bytes\": %llu,\n",
            (unsigned long long)L->file_bytes, (unsigned long long)L->depth_raw_bytes,
            (unsigned long long)L->depth_bytes);
    fprintf(f, "  \"rgb_raw_bytes\": %llu,\n  \"rgb_bytes\": %llu,\n  \"depth_compression_ratio\": ",
            (unsigned long long)L->rgb_raw_bytes, (unsigned long long)L->rgb_bytes);
    bf_json_number(f, ratio(L->depth_raw_bytes, L->depth_bytes), 5);
    fprintf(f, ",\n  \"rgb_compression_ratio\": ");
    bf_json_number(f, ratio(L->rgb_raw_bytes, L->rgb_bytes), 5);
    fprintf(f, ",\n  \"compression_ratio\": ");
    bf_json_number(f, ratio(L->depth_raw_bytes + L->rgb_raw_bytes, L->file_bytes), 5);
    fprintf(f, ",\n  \"seconds\": ");
    bf_json_number(f, r->seconds, 5);
    fprintf(f, ",\n  \"fps\": ");
    bf_json_number(f, r->seconds > 0 ? L->n_frames / r->seconds : NAN, 5);
    fprintf(f, ",\n  \"write_mb_per_s\": ");
    bf_json_number(f, r->seconds > 0 ? mb / r->seconds : NAN, 5);
    fprintf(f, "\n}\n");
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
static bf_status record_frames(const record_args *a, rgbd_source *src, replay_log_writer *w, record_result *r)
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
        if ((s = replay_log_writer_add(w, &f))) break;
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
    if (!replay_is_log_path(a.out)) return app_usage_error(cmd, "--out must name a .bflog file, not '%s'", a.out);
    const char *log_path = a.out;
    char json_path[4200];
    bf_status s = stats_path(log_path, json_path, sizeof json_path);
    if (s) return app_fail(cmd, s);

    record_result r;
    memset(&r, 0, sizeof r);
    rgbd_source *src = NULL;
    replay_log_writer *w = NULL;
    double t0 = bf_time_s();
    s = app_open_device(a.device, &a.ropt, a.realtime, a.queue, &r.is_live, &src);
    if (s) return app_fail(cmd, s);
    a.lcfg.device = a.device;
    a.lcfg.has_groundtruth = src->has_groundtruth;
    if ((s = replay_log_writer_create(log_path, rgbd_source_intrinsics(src), &a.lcfg, &w))) {
        rgbd_source_close(src);
        return app_fail(cmd, s);
    }
    bf_status rs = record_frames(&a, src, w, &r);
    bf_status s_dev = rs == BF_END ? BF_OK : rs;
    char dev_err[1024] = "";
    if (s_dev) snprintf(dev_err, sizeof dev_err, "%s", bf_last_error());
    rgbd_source_close(src);
    /* Finish even after a device error: every frame before it is kept. */
    bf_status s_fin = replay_log_writer_finish(w);
    r.log = replay_log_writer_stats(w);
    r.seconds = bf_time_s() - t0;
    replay_log_writer_destroy(w);
    s = s_dev ? s_dev : s_fin;
    if (s_dev && dev_err[0]) bf_fail(s_dev, "%s", dev_err);

    bf_membuf mb;
    FILE *jf = bf_membuf_open(&mb);
    bf_status s_json = BF_OK;
    if (jf) {
        write_stats_json(jf, cmd, &a, log_path, &r, s);
        s_json = bf_membuf_write_atomic(&mb, json_path);
    }
    const replay_log_stats *L = &r.log;
    printf("bitfuse %s: %u frames from %s to %s%s\n", cmd, L->n_frames, a.device, log_path,
           r.is_interrupted ? " (stopped by a signal; the log is complete up to there)" : "");
    printf("  capture   %llu captured, %llu dropped by the queue of %u\n", (unsigned long long)r.cap.captured,
           (unsigned long long)r.cap.dropped, a.queue);
    printf("  depth     %.2f MB raw -> %.2f MB (%.2fx, zstd)\n", L->depth_raw_bytes / 1e6, L->depth_bytes / 1e6,
           ratio(L->depth_raw_bytes, L->depth_bytes));
    if (L->rgb_raw_bytes)
        printf("  colour    %.2f MB raw -> %.2f MB (%.2fx, %s)\n", L->rgb_raw_bytes / 1e6, L->rgb_bytes / 1e6,
               ratio(L->rgb_raw_bytes, L->rgb_bytes), a.lcfg.colour == REPLAY_LOG_COLOUR_JPEG ? "jpeg" : "zstd");
    printf("  file      %.2f MB in %.2f s: %.1f frames/s, %.1f MB/s; stats in %s\n", L->file_bytes / 1e6, r.seconds,
           r.seconds > 0 ? L->n_frames / r.seconds : 0.0, r.seconds > 0 ? L->file_bytes / 1e6 / r.seconds : 0.0,
           json_path);
    if (s) return app_fail(cmd, s);
    if (!jf || s_json) return app_fail(cmd, jf ? s_json : BF_NO_MEMORY);
    return APP_EXIT_OK;
}

