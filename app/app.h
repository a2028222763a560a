/* app: the bitfuse command-line program. Each command lives in its own
 * cmd_*.c and is listed once in main.c's table. */
#ifndef BF_APP_H
#define BF_APP_H

#include <signal.h>
#include <stdio.h>

#include "capture/capture.h"
#include "core/core.h"
#include "fusion/fusion.h"
#include "export/export.h"

/* Exit codes scripts can rely on (docs/cli.md). */
enum {
    APP_EXIT_OK = 0,
    APP_EXIT_FAILURE = 1, /* the work itself failed (numerics, pool full...) */
    APP_EXIT_USAGE = 2,   /* bad command line */
    APP_EXIT_INPUT = 3,   /* unreadable or malformed input file */
    APP_EXIT_DEVICE = 4,  /* no usable Vulkan device or a device error */
};

/* Maps a status to an exit code and prints "bitfuse CMD: error: message". */
int app_fail(const char *cmd, bf_status s);
/* Prints a usage error and returns APP_EXIT_USAGE. */
int app_usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* The shared real-data folder (meshes/, tum/...): ../shared/data beside the
 * source tree, else beside the current folder; NULL when neither exists. */
const char *app_default_data_dir(void);
/* True if argv[i] is -h or --help. */
bool app_is_help(const char *arg);

/* output.c: what the commands that build a map report about it. */
typedef struct app_map_report {
    fusion_stats map;
    export_stats mesh, points;
} app_map_report;
/* Fills r->map, writes out_dir/points.ply and, with_mesh, out_dir/mesh.ply. */
bf_status app_export_map(fusion_map *map, const char *out_dir, bool with_mesh, app_map_report *r);
/* The map's lines of stats.json ("map_bytes" .. "mesh", each ending ",\n"). */
void app_json_map(FILE *f, const app_map_report *r, uint32_t max_level);
/* The map's lines of the printed summary. */
void app_print_map(const app_map_report *r, uint32_t max_level);
/* The map options fuse, replay and live share (--ratio, --chunk, --window,
 * --subcache, --bricks, --max-level) into fc: true if o with value v was
 * one of them (the caller skips v). */
bool app_parse_map_option(const char *o, const char *v, fusion_config *fc);
/* Writes dir/name atomically from what write() prints. */
bf_status app_write_json(const char *dir, const char *name, void (*write)(FILE *f, const void *arg), const void *arg);

int cmd_demo(int argc, char **argv);
int cmd_synth(int argc, char **argv);
int cmd_fuse(int argc, char **argv);
int cmd_replay(int argc, char **argv);
int cmd_eval_traj(int argc, char **argv);
int cmd_eval_surface(int argc, char **argv);
int cmd_devices(int argc, char **argv);
int cmd_info(int argc, char **argv);
int cmd_record(int argc, char **argv);
int cmd_convert(int argc, char **argv);
int cmd_live(int argc, char **argv);
/* device.c: opens uri (a live URI, or a recorded sequence replay reads
 * standing in for a camera) behind the capture thread, as
 * capture_open_device does. */
struct replay_options;
bf_status app_open_device(const char *uri, const struct replay_options *ropt, bool realtime, uint32_t queue,
                          bool *is_live, rgbd_source **out);
/* Until app_stop_end, Ctrl-C and SIGTERM stop src's capture thread and set
 * the returned flag instead of ending the program; a second one ends it. */
const volatile sig_atomic_t *app_stop_begin(rgbd_source *src);
/* Restores the handlers; true if a signal came. */
bool app_stop_end(void);
/* cmd_replay.c: the full loop on a sequence (replay) or a device (live). */
int app_reconstruct(const char *cmd, int argc, char **argv, bool is_live_cmd);

#endif
