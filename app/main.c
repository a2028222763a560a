/* bitfuse: real-time RGB-D reconstruction with a sign-bit map. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"

typedef struct app_command {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} app_command;

static const app_command commands[] = {
    {"demo", cmd_demo, "make a short synthetic sequence and evaluate it (built-in data)"},
    {"synth", cmd_synth, "render a synthetic RGB-D sequence with ground truth (TUM folder)"},
    {"replay", cmd_replay, "track and fuse a recorded sequence (the full loop): trajectory, mesh, stats"},
    {"fuse", cmd_fuse, "fuse a sequence with known poses into the map; export mesh and points"},
    {"info", cmd_info, "read a sequence or a scene store and print what it holds"},
    {"render", cmd_render, "ray-cast one view of a saved map and/or particles into PNGs (shaded, depth)"},
    {"export", cmd_export, "write the mesh or the points of a scene store (no loop, no GPU)"},
    {"record", cmd_record, "record a camera (or a sequence) into a bitfuse log (.bflog)"},
    {"convert", cmd_convert, "convert a sequence or log into a TUM folder or a bitfuse log"},
    {"live", cmd_live, "track and fuse a live camera (the full loop); Ctrl-C ends the scan"},
    {"eval-traj", cmd_eval_traj, "trajectory error: ATE and RPE (TUM benchmark rules)"},
    {"eval-surface", cmd_eval_surface, "surface error: accuracy and completeness against a mesh"},
    {"eval-colour", cmd_eval_colour, "colour error: a coloured mesh re-rendered at the frames' poses (PSNR)"},
    {"eval-motion", cmd_eval_motion, "trajectories (or ground truth) against the motion the colour images show"},
    {"calibrate", cmd_calibrate, "calibrate the colour and depth cameras from checkerboard images (calib.json)"},
    {"calibrate-depth", cmd_calibrate_depth, "the depth camera's fixed error pattern from a sequence and its poses"},
    {"view", cmd_view, "show a saved map in a window: orbit, pan, zoom; --screenshot for scripts"},
    {"devices", cmd_devices, "list Vulkan devices and say which one bitfuse uses"},
};
#define N_COMMANDS (sizeof commands / sizeof commands[0])

static void usage(FILE *f)
{
    fprintf(f, "usage: bitfuse COMMAND [options]   (bitfuse COMMAND --help for details)\n"
               "       bitfuse --version\n\ncommands:\n");
    int w = 0;
    for (size_t i = 0; i < N_COMMANDS; i++) w = (int)strlen(commands[i].name) > w ? (int)strlen(commands[i].name) : w;
    for (size_t i = 0; i < N_COMMANDS; i++) fprintf(f, "  %-*s %s\n", w + 1, commands[i].name, commands[i].summary);
    fprintf(f, "\nexit codes: 0 ok, 1 failure, 2 usage, 3 bad input, 4 device error (or no display),\n"
               "            5 an output could not be written (disk full, I/O error)\n"
               "environment: BITFUSE_DEVICE (device name), BITFUSE_LOG (debug|info|warn|error|silent),\n"
               "             BITFUSE_THREADS (CPU threads), BITFUSE_VALIDATION=1 (Vulkan validation),\n"
               "             BITFUSE_PROGRESS=1|0 (the status line), BITFUSE_CACHE_DIR (pipeline cache)\n");
}

int app_fail(const char *cmd, bf_status s)
{
    const char *msg = bf_last_error();
    fprintf(stderr, "bitfuse %s: error: %s\n", cmd, msg[0] ? msg : bf_status_message(s));
    switch (s) {
    case BF_OK: return APP_EXIT_OK;
    case BF_INVALID_ARG: return APP_EXIT_USAGE;
    case BF_IO:
    case BF_FORMAT: return APP_EXIT_INPUT;
    case BF_VULKAN:
    case BF_NO_DEVICE: return APP_EXIT_DEVICE;
    case BF_WRITE: return APP_EXIT_WRITE;
    default: return APP_EXIT_FAILURE;
    }
}

const char *app_default_data_dir(void)
{
    static const char *const candidates[] = {BF_SOURCE_DIR "/../shared/data", "../shared/data"};
    for (size_t i = 0; i < sizeof candidates / sizeof candidates[0]; i++)
        if (bf_file_exists(candidates[i])) return candidates[i];
    return NULL;
}

/* What a command printed must have reached its reader: `--json >
 * results.json` on a full disk exited 0 with the file cut short. A failed
 * command keeps its own exit code. */
static int stdout_status(int rc)
{
    errno = 0;
    if (fflush(stdout) == 0 && !ferror(stdout)) return rc;
    fprintf(stderr, "bitfuse: standard output: write failed: %s\n", errno ? strerror(errno) : "I/O error");
    return rc == APP_EXIT_OK ? APP_EXIT_WRITE : rc;
}

/* An environment setting that is not one of its values is said, not
 * silently read as the default. */
static void check_environment(void)
{
    const char *log = getenv("BITFUSE_LOG");
    if (log && strcmp(log, "debug") && strcmp(log, "info") && strcmp(log, "warn") && strcmp(log, "error") &&
        strcmp(log, "silent"))
        fprintf(stderr, "bitfuse: warning: BITFUSE_LOG='%s' is not debug, info, warn, error or silent: info\n", log);
    const char *threads = getenv("BITFUSE_THREADS");
    uint32_t n;
    if (threads && (!bf_parse_u32(threads, &n) || n < 1 || n > 64))
        fprintf(stderr, "bitfuse: warning: BITFUSE_THREADS='%s' is not a count of 1 to 64 threads: %d used\n",
                threads, bf_thread_count());
}

int main(int argc, char **argv)
{
    app_signals_init();
    check_environment();
    if (argc < 2) {
        usage(stderr);
        return APP_EXIT_USAGE;
    }
    if (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return stdout_status(APP_EXIT_OK);
    }
    if (!strcmp(argv[1], "--version")) {
        printf("bitfuse %s\n", BF_VERSION);
        return stdout_status(APP_EXIT_OK);
    }
    if (argv[1][0] == '-') {
        fprintf(stderr, "bitfuse: unknown option '%s' (options follow the command)\n", argv[1]);
        usage(stderr);
        return APP_EXIT_USAGE;
    }
    for (size_t i = 0; i < N_COMMANDS; i++)
        if (!strcmp(argv[1], commands[i].name)) return stdout_status(commands[i].run(argc - 1, argv + 1));
    fprintf(stderr, "bitfuse: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return APP_EXIT_USAGE;
}
