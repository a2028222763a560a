/* bitfuse convert: any sequence replay_open reads (TUM, ICL-NUIM, pose
 * folders, bitfuse logs) into a TUM folder or a bitfuse log. Reading runs
 * on the capture thread (lossless: nothing is dropped), so decoding and
 * encoding overlap on two cores. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "capture/capture.h"
#include "replay/replay.h"

static void convert_help(FILE *f)
{
    fprintf(f,
            "usage: bitfuse convert SEQUENCE --out DEST [options]\n\n"
            "Reads SEQUENCE (a TUM, ICL-NUIM or pose-per-frame folder, or a .bflog) and writes it\n"
            "as a bitfuse log when DEST ends in .bflog, else as a TUM folder (docs/formats.md).\n"
            "Depth, timestamps and poses carry over exactly; colour too, except with --colour jpeg.\n"
            "Writes DEST's stats (frames, bytes, compression ratio, fps) to X.stats.json beside\n"
            "X.bflog, or to DEST/stats.json for a folder.\n\n"
            "options:\n"
            "  --out DEST         X.bflog or a folder (created)\n"
            "  --colour C         log colour: zstd (default, lossless), jpeg or none\n"
            "  --jpeg-quality Q   1..100, default 90\n"
            "  --zstd-level L     1..19, default 1\n"
            "%s"
            "  -h, --help         this text\n\n"
            "exit codes: 0 ok, 1 failure, 2 usage, 3 unreadable or malformed input\n",
            replay_options_help());
}

typedef struct convert_args {
    const char *in, *out;
    replay_options ropt;
    replay_log_config lcfg;
    bool to_log;
} convert_args;

static int parse_args(int argc, char **argv, convert_args *a)
{
    const char *cmd = "convert";
    memset(a, 0, sizeof *a);
    a->lcfg.colour = REPLAY_LOG_COLOUR_ZSTD;
    for (int i = 1; i < argc;) {
        const char *o = argv[i];
        if (app_is_help(o)) {
            convert_help(stdout);
            return -1;
        }
        int r = replay_parse_option(argc, argv, &i, &a->ropt);
        if (r < 0) return app_usage_error(cmd, "%s", bf_last_error());
        if (r > 0) continue;
        if (o[0] != '-') {
            if (a->in) return app_usage_error(cmd, "more than one sequence given ('%s' and '%s')", a->in, o);
            a->in = o;
            i++;
            continue;
        }
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v) return app_usage_error(cmd, "%s needs a value", o);
        uint32_t u;
        if (!strcmp(o, "--out")) {
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
        } else if (!strcmp(o, "--jpeg-quality") || !strcmp(o, "--zstd-level")) {
            return app_usage_error(cmd, "bad value for %s: '%s'", o, v);
        } else {
            return app_usage_error(cmd, "unknown option '%s'", o);
        }
        i += 2;
    }
    if (!a->in) return app_usage_error(cmd, "no sequence given");
    if (!a->out) return app_usage_error(cmd, "--out is required");
    a->to_log = replay_is_log_path(a->out);
    return 0;
}

static double ratio(uint64_t raw, uint64_t packed) { return packed ? (double)raw / (double)packed : NAN; }

/* The frames of src into the log or TUM writer (exactly one is set). */
static bf_status convert_frames(rgbd_source *src, replay_log_writer *lw, replay_tum_writer *tw, uint32_t *n_out)
{
    bf_progress prog;
    bf_progress_begin(&prog, "convert", src->n_frames);
    bf_frame f;
    bf_status s;
    uint32_t n = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        s = lw ? replay_log_writer_add(lw, &f) : replay_tum_writer_add(tw, &f);
        if (s) break;
        bf_progress_update(&prog, ++n);
    }
    bf_progress_end(&prog, n);
    *n_out = n;
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
    s = a.to_log ? replay_log_writer_create(a.out, rgbd_source_intrinsics(src), &a.lcfg, &lw)
                 : replay_tum_writer_create(a.out, rgbd_source_intrinsics(src), &tw);
    uint32_t n = 0;
    if (s == BF_OK) s = convert_frames(src, lw, tw, &n);
    uint32_t skipped = replay_skipped_frames(dev);
    replay_log_stats L = {0};
    if (lw) L = replay_log_writer_stats(lw);
    double seconds = bf_time_s() - t0;
    rgbd_source_close(src);
    replay_log_writer_destroy(lw);
    replay_tum_writer_destroy(tw);
    if (s) return app_fail(cmd, s);

    char json_path[4200];
    size_t len = strlen(a.out);
    if (a.to_log)
        snprintf(json_path, sizeof json_path, "%.*s.stats.json", (int)(len - 6), a.out);
    else if ((s = bf_path_join(json_path, sizeof json_path, a.out, "stats.json")))
        return app_fail(cmd, s);
    bf_membuf mb;
    FILE *f = bf_membuf_open(&mb);
    if (!f) return app_fail(cmd, BF_NO_MEMORY);
    fprintf(f, "{\n  \"command\": \"convert\",\n  \"in\": ");
    bf_json_string(f, a.in);
    fprintf(f, ",\n  \"out\": ");
    bf_json_string(f, a.out);
    fprintf(f, ",\n  \"format\": \"%s\",\n  \"frames\": %u,\n  \"skipped\": %u,\n  \"dropped\": 0,\n",
            a.to_log ? "bflog" : "tum", n, skipped);
    if (a.to_log) {
        fprintf(f, "  \"colour_codec\": \"%s\",\n", a.lcfg.colour == REPLAY_LOG_COLOUR_JPEG   ? "jpeg"
                                                    : a.lcfg.colour == REPLAY_LOG_COLOUR_ZSTD ? "zstd"
                                                                                              : "none");
        fprintf(f, "  \"bytes\": %llu,\n  \"depth_raw_bytes\": %llu,\n  \"depth_bytes\": %llu,\n",
                (unsigned long long)L.file_bytes, (unsigned long long)L.depth_raw_bytes,
                (unsigned long long)L.depth_bytes);
        fprintf(f, "  \"rgb_raw_bytes\": %llu,\n  \"rgb_bytes\": %llu,\n  \"depth_compression_ratio\": ",
                (unsigned long long)L.rgb_raw_bytes, (unsigned long long)L.rgb_bytes);
        bf_json_number(f, ratio(L.depth_raw_bytes, L.depth_bytes), 5);
        fprintf(f, ",\n  \"rgb_compression_ratio\": ");
        bf_json_number(f, ratio(L.rgb_raw_bytes, L.rgb_bytes), 5);
        fprintf(f, ",\n  \"compression_ratio\": ");
        bf_json_number(f, ratio(L.depth_raw_bytes + L.rgb_raw_bytes, L.file_bytes), 5);
        fprintf(f, ",\n  \"write_mb_per_s\": ");
        bf_json_number(f, seconds > 0 ? L.file_bytes / 1e6 / seconds : NAN, 5);
        fprintf(f, ",\n");
    }
    fprintf(f, "  \"seconds\": ");
    bf_json_number(f, seconds, 5);
    fprintf(f, ",\n  \"fps\": ");
    bf_json_number(f, seconds > 0 ? n / seconds : NAN, 5);
    fprintf(f, "\n}\n");
    if ((s = bf_membuf_write_atomic(&mb, json_path))) return app_fail(cmd, s);

    printf("bitfuse convert: %u frames (%u skipped) from %s to %s (%s)\n", n, skipped, a.in, a.out,
           a.to_log ? "bitfuse log" : "TUM folder");
    if (a.to_log) {
        printf("  depth     %.2f MB raw -> %.2f MB (%.2fx)\n", L.depth_raw_bytes / 1e6, L.depth_bytes / 1e6,
               ratio(L.depth_raw_bytes, L.depth_bytes));
        if (L.rgb_raw_bytes)
            printf("  colour    %.2f MB raw -> %.2f MB (%.2fx)\n", L.rgb_raw_bytes / 1e6, L.rgb_bytes / 1e6,
                   ratio(L.rgb_raw_bytes, L.rgb_bytes));
        printf("  file      %.2f MB, %.1f MB/s\n", L.file_bytes / 1e6, seconds > 0 ? L.file_bytes / 1e6 / seconds : 0);
    }
    printf("  time      %.2f s, %.1f frames/s; stats in %s\n", seconds, seconds > 0 ? n / seconds : 0.0, json_path);
    return APP_EXIT_OK;
}
