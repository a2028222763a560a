/* app: the bitfuse command-line program. Each command lives in its own
 * cmd_*.c and is listed once in main.c's table. */
#ifndef BF_APP_H
#define BF_APP_H

#include "core/core.h"

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

int cmd_demo(int argc, char **argv);
int cmd_synth(int argc, char **argv);
int cmd_fuse(int argc, char **argv);
int cmd_eval_traj(int argc, char **argv);
int cmd_eval_surface(int argc, char **argv);
int cmd_devices(int argc, char **argv);
int cmd_info(int argc, char **argv);

#endif
