/* app: the bitfuse command-line program. Each command lives in its own
 * cmd_*.c and is listed once in main.c's table. */
#ifndef BF_APP_H
#define BF_APP_H

#include <signal.h>
#include <stdio.h>

#include <cjson/cJSON.h>

#include "calib/calib.h"
#include "capture/capture.h"
#include "replay/replay.h"
#include "core/core.h"
#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "export/export.h"
#include "mesh/mesh.h"
#include "render/render.h"
#include "store/store.h"

/* Exit codes scripts can rely on (docs/cli.md). */
enum {
    APP_EXIT_OK = 0,
    APP_EXIT_FAILURE = 1, /* the work itself failed (numerics, pool full...) */
    APP_EXIT_USAGE = 2,   /* bad command line */
    APP_EXIT_INPUT = 3,   /* unreadable or malformed input file */
    APP_EXIT_DEVICE = 4,  /* no usable Vulkan device or a device error */
    APP_EXIT_WRITE = 5,   /* an output could not be written (disk full, I/O error, permissions) */
};

/* main.c: maps a status to an exit code and prints "bitfuse CMD: error:
 * message". */
int app_fail(const char *cmd, bf_status s);
/* The shared real-data folder (meshes/, tum/...): ../shared/data beside the
 * source tree, else beside the current folder; NULL when neither exists. */
const char *app_default_data_dir(void);

/* options.c: the one option parser. A command lists its options as rows
 * (name, kind, destination, bounds, help) in tables; the parser checks every
 * value (bounds, choices, the row's check) before writing it, so a command
 * line is refused before any device opens or any folder is made, and the
 * help text, defaults included, is generated from the same rows. Options
 * take "--name value" or "--name=value". */
typedef enum app_opt_kind {
    APP_OPT_FLAG,   /* bool, set to true; no value */
    APP_OPT_U32,    /* uint32_t within [min, max] */
    APP_OPT_U64,    /* uint64_t, any */
    APP_OPT_DOUBLE, /* double within [min, max] (min excluded with min_open) */
    APP_OPT_FLOAT,  /* float, the same */
    APP_OPT_STRING, /* const char *, borrowed from argv */
    APP_OPT_ENUM,   /* int: codes[k] (or k) for the k-th of meta's "a|b|c" */
    APP_OPT_CHOICE, /* bool: true for the first of meta's "a|b", false for the second */
    APP_OPT_LIST,   /* uint32_t array "A,B,C" within [min, max], its length into *count (1..max_n) */
} app_opt_kind;

#define APP_OPT_LIST_MAX 8   /* values of one list option */
#define APP_OPT_ROWS_MAX 128 /* rows of one command */

typedef struct app_option {
    const char *name;  /* "--ratio"; NULL ends a table */
    app_opt_kind kind;
    void *dest;        /* what the kind says; its value before parsing is the default the help states */
    const char *meta;  /* the value's name in the help ("R"), or the choices ("on|off") */
    const char *help;  /* NULL: an alias, left out of the help */
    double min, max;   /* bounds of numbers and list values; max <= min: no upper bound */
    bool min_open;     /* min itself is refused (a value must be above it) */
    const int *codes;  /* APP_OPT_ENUM: the value of each choice; NULL: its index */
    uint32_t *count;   /* APP_OPT_LIST */
    uint32_t max_n;
    bool required;
    bool no_default;   /* the help states no default (it depends on the input) */
    /* More checks on the value text: NULL, or the whole message. */
    const char *(*check)(const char *name, const char *value);
    /* An option that means nothing without another ("--view"): given
     * alone, it is a usage error rather than silently ignored. */
    const char *needs;
    /* An option it means nothing beside, refused together (exit 2) rather
     * than ignored: "--no-mesh" (given), or "--colour=off" (an on|off
     * option given as off). */
    const char *not_with;
    /* NULL, or set true when the option is given (a default's value given
     * on purpose is then told from the default). */
    bool *given;
} app_option;

/* A row: the first five fields in order, then any others by name. */
#define APP_OPT(name_, kind_, dest_, meta_, help_, ...)                                                      \
    {.name = (name_), .kind = (kind_), .dest = (dest_), .meta = (meta_), .help = (help_), __VA_ARGS__}
#define APP_OPT_END {.name = NULL}

typedef struct app_command_spec {
    const char *name;                /* "replay", for messages */
    const char *usage;               /* usage line and description */
    const app_option *const *tables; /* NULL-terminated list of tables */
    const char **positional;         /* max_positional slots for the plain arguments */
    int min_positional, max_positional;
    const char *positional_missing;  /* the message when fewer were given */
    const char *epilog;              /* after the options: exit codes */
} app_command_spec;

/* Prints "bitfuse CMD: message" and where the help is; returns APP_EXIT_USAGE. */
int app_usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* 0: parsed; -1: --help or --version was printed (exit 0); else the usage
 * exit code, the message printed. */
int app_options_parse(const app_command_spec *spec, int argc, char **argv);
void app_options_help(FILE *f, const app_command_spec *spec);

/* Rows several commands share: the sequence options (--camera,
 * --depth-scale, --frames, --skip-bad-frames) and the map options (--ratio,
 * --window, --subcache, --bricks, --chunk, --max-level). */
struct replay_options;
#define APP_SEQUENCE_ROWS 5
#define APP_MAP_ROWS 11
void app_sequence_options(app_option rows[APP_SEQUENCE_ROWS], struct replay_options *o);
/* bricks_given (NULL: not asked): set true when --bricks is given. */
void app_map_options(app_option rows[APP_MAP_ROWS], fusion_config *fc, bool *bricks_given);
/* What the map rows cannot check alone (the sub-cache within the window;
 * the default sub-cache is cut to a shorter window): 0 or the usage exit
 * code, the message printed. */
int app_check_map_options(const char *cmd, fusion_config *fc);
/* After a run failed with s: when the map's pools were refused for this
 * device's storage binding (fusion names its brick_cap / node_cap), a
 * warning names the option that sized them (opt: "--gpu-budget" or
 * "--bricks"; NULL: the device chose, nothing to say). */
void app_pool_hint(const char *cmd, bf_status s, const char *opt);

/* output.c: how a command writes a mesh (export, fuse, replay, live): the
 * file's format and the mesh's detail (docs/export.md). */
typedef struct app_mesh_out {
    int format;             /* a mesh_format; -1: from the file's extension (export) */
    uint32_t max_triangles; /* 0: the full mesh */
    double max_error_m;     /* 0: no bound */
} app_mesh_out;
#define APP_MESH_ROWS 4
/* The rows --format (export) or --mesh-format (the commands writing
 * DIR/mesh.*), --max-triangles, --max-error; o starts as the defaults:
 * for export format -1, else MESH_FORMAT_PLY. */
void app_mesh_options(app_option rows[APP_MESH_ROWS], app_mesh_out *o, bool is_export);
/* Simplifies mesh as o asks (st: what it did) and writes it to path in
 * format f. */
bf_status app_mesh_write(const char *path, mesh_format f, const app_mesh_out *o, mesh_data *mesh,
                         mesh_simplify_stats *st);
/* JSON of one mesh written: "format", "file", "vertices", "triangles" (in
 * the file), "triangles_full" (marching cubes), "origin_w" when not zero,
 * and "simplify" {"max_triangles", "max_error_m", "error_estimate_m",
 * "used_sloppy", "seconds"} when asked for. */
void app_json_mesh_file(cJSON *o, const char *file, mesh_format f, const app_mesh_out *mo, const mesh_data *m,
                        const mesh_simplify_stats *st);

/* output.c: an output that cannot be written (BF_WRITE: disk full, I/O
 * error) does not stop the others: the first failure is kept here and
 * decides the exit code (5), each is warned about, and the work done is
 * written wherever it still can be (docs/faults.md). */
typedef struct app_write_failure {
    bf_status s; /* BF_OK, or BF_WRITE once an output failed (BF_INVALID_ARG: app_note_mesh_refused) */
    char message[BF_ERROR_CAP];
    uint32_t n;  /* outputs that failed (each warned about); message is the first's */
} app_write_failure;
/* The summary's words after the first failure: " (the other outputs are
 * written)", or how many more failed. */
static inline const char *app_write_failure_tail(const app_write_failure *w, char *buf, size_t cap)
{
    if (w->n <= 1) return " (the other outputs are written)";
    snprintf(buf, cap, ", and %u other output%s (the warnings above)", w->n - 1, w->n == 2 ? "" : "s");
    return buf;
}
/* s, or BF_OK when s is BF_WRITE (then noted in w and warned about). */
bf_status app_note_write(app_write_failure *w, const char *cmd, bf_status s);
/* The first failure noted as the status (its message restored), or BF_OK. */
bf_status app_write_status(const app_write_failure *w);

/* output.c: what the commands that build a map report about it. */
typedef struct app_map_report {
    fusion_stats map;
    export_stats mesh, points;
    app_mesh_out mesh_out;        /* as asked */
    mesh_simplify_stats simplify; /* of the mesh written */
    char mesh_file[16];           /* "mesh.ply", "mesh.obj" or "mesh.glb"; "" without a mesh */
    bool mesh_skipped;            /* --no-mesh: none was made */
    char mesh_error[BF_ERROR_CAP]; /* why the mesh could not be written ("" if it was, or none was asked) */
    bf_status mesh_refused;       /* BF_INVALID_ARG: simplified to nothing (the cap), the rest written */
    bf_vec3 mesh_origin;          /* the mesh's local origin (zero: world coordinates) */
    uint64_t digest;              /* store_map_digest of the map exported (stats.json's map_digest) */
    uint32_t n_chunks;            /* chunks holding bricks in the map exported (a streamed map's every
                                     one; map.n_chunks: the device's hash entries) */
    uint32_t n_bricks_whole;      /* bricks of the map exported (map.n_bricks: the device's; more when
                                     chunks were streamed out) */
} app_map_report;
/* The mesh lattice's level for a map: the finest level holding a tenth of its bricks. */
uint32_t app_mesh_level(const hostmap *snap);
/* Fills r->map (the pools' statistics), writes out_dir/points.ply and,
 * when mo is not NULL, out_dir/mesh.EXT (EXT from mo's format, simplified
 * as mo asks) of whole (taken; a streamed map's every chunk:
 * recon_snapshot) or, when whole is NULL, of the pools' snapshot. */
bf_status app_export_map(fusion_map *map, hostmap *whole, const char *out_dir, const app_mesh_out *mo,
                         app_map_report *r);
/* A warning when the output folder out holds an earlier run's stats.json:
 * its files this run does not write (another mesh format, views past this
 * run's) stay beside the new ones. */
void app_warn_earlier_run(const char *cmd, const char *out);
/* Usage error (exit 2) when the output folder out holds a sequence (its
 * index, ground truth or image folders), whose files, stats.json among them,
 * a run would overwrite or mix with its own; with results_too, also when it
 * holds an earlier run's stats.json (for commands that write a sequence:
 * synth, convert). 0 when out is new or holds neither. */
int app_check_out_not_sequence(const char *cmd, const char *out, bool results_too);
/* A mesh that app_export_map refused to simplify to nothing (r->mesh_refused)
 * is noted in w as a failure of its own status (exit 2 after the outputs). */
void app_note_mesh_refused(app_write_failure *w, const app_map_report *r);
/* expect.c: replay --expect BASELINE.json --tolerance NAME=VALUE,...: the
 * new stats.json's measures (ATE, surface error, map digest, tracked, lost
 * and relocalised counts; time only when its tolerance is given) against a
 * baseline's (docs/determinism.md). */
#define APP_EXPECT_MEASURES 7
typedef struct app_expect {
    const char *path;                /* BASELINE.json (borrowed) */
    cJSON *baseline;                 /* its contents, owned */
    double tol[APP_EXPECT_MEASURES]; /* < 0: not gated */
} app_expect;
/* --tolerance's row check: the list's syntax, names and values. */
const char *app_check_tolerance(const char *name, const char *value);
/* Reads and checks the baseline before any device opens: BF_IO when it
 * cannot be read, BF_FORMAT when it is not a replay's stats.json. */
bf_status app_expect_load(app_expect *e, const char *path, const char *tolerance);
void app_expect_free(app_expect *e);
/* Compares stats (the run's stats.json, before it is written; gets an
 * "expect" object) with the baseline, prints a line per measure, and
 * returns how many moved beyond their tolerance, named with their values in
 * why. */
uint32_t app_expect_check(const app_expect *e, cJSON *stats, char *why, size_t cap);
/* The map's part of stats.json ("map_bytes" .. "mesh") into o. */
void app_json_map(cJSON *o, const app_map_report *r, uint32_t max_level);
/* The mesh's files for a summary's list, each followed by a comma:
 * "mesh.ply,", "mesh.obj,mesh.mtl," or "" when none was written. */
void app_mesh_file_list(const app_map_report *r, char *out, size_t cap);
/* The input's part of stats.json: "frames_unreadable" (frames src skipped
 * under --skip-bad-frames) and "input_error" (the failure of a frame that
 * ended the run early, what was fused before it kept; null when none). */
struct recon_run;
void app_json_input(cJSON *o, const struct recon_run *run, const rgbd_source *src);
/* stats.json's gpu_stage_ms: STAGE -> {median, p95, mean} of the run's
 * series, the tracking stages (track, rof, raycast) when with_tracking. */
void app_json_gpu_stages(cJSON *o, const struct recon_run *run, bool with_tracking);
/* A run's status s, but when it failed after every frame src delivered was
 * skipped as unreadable, the message says so ("no frame could be read (N
 * skipped)") rather than blaming the frames' content. */
bf_status app_input_status(bf_status s, const rgbd_source *src, const char *name);
/* The map's lines of the printed summary. */
void app_print_map(const app_map_report *r, uint32_t max_level);

/* store_io.c: the scene store in replay and live (--store, --resume). */
struct recon_run;
struct recon_resume_state;
struct recon_config;
typedef struct app_store {
    const char *dir;
    double every_s, last_s;     /* flush period (0: only at the end) and the last flush's time */
    store_writer *writer;
    bool is_resumed;            /* the scan goes on from the store's map, pose and trajectory */
    hostmap map;                /* resumed: the map, meta, trajectory and report read */
    store_meta meta;
    bf_traj traj;
    store_report report;
    store_keyframes keyframes;  /* resumed: the relocalisation keyframes read (none when the file is absent or bad) */
    uint64_t kf_generation;     /* the loop's keyframe generation then */
    bool has_kf_generation;
    uint32_t flushes, skipped;  /* flushes handed to the writer; periods skipped while it was busy */
    double ms_flush_max, ms_submit_max; /* the loop's cost of a flush (snapshot and hand-over) */
    store_write_stats stats;    /* the writer's, at the end */
    bool end_failed;            /* the final write (or the writer's last) failed: stats are the last whole write's */
    bool lock_refused;          /* another process was writing the store: nothing of it is this run's */
} app_store;
/* Opens dir for the scan; resume: reads it first (BF_FORMAT when it keeps no pose). */
bf_status app_store_open(app_store *st, const char *dir, bool resume, double every_s);
/* The runner's resume state from the store read; the loop takes the stored map's geometry. */
void app_store_resume_config(app_store *st, struct recon_resume_state *rs, struct recon_config *loop);
/* After each frame: a flush when the period has passed and the writer is free. */
bf_status app_store_frame(app_store *st, struct recon_run *run, const bf_frame *f);
/* The end of the scan (also after Ctrl-C): the final map, then waits for the writer. */
bf_status app_store_finish(app_store *st, struct recon_run *run);
void app_store_json(cJSON *parent, const app_store *st);
/* The summary's line: where the store is and what it holds after the last write. */
void app_store_print(const app_store *st);
void app_store_close(app_store *st);

/* json.c: JSON through cJSON. Objects are built with cJSON's own calls;
 * NaN and infinities come out as null. */
/* The root of a command's stats.json: {"command": command, "version": the
 * program's version}. */
cJSON *app_json_stats(const char *command);
/* A new object, added to parent under name when parent is not NULL. Here,
 * not in json.c, so that expect.c compiles alone (tests/fuzz/fuzz_expect.c
 * links it without json.c's recon and calibration code). */
static inline cJSON *app_json_object(cJSON *parent, const char *name)
{
    cJSON *o = cJSON_CreateObject();
    if (parent && o) cJSON_AddItemToObject(parent, name, o);
    return o;
}
/* The unreadable frames a reader skipped (--skip-bad-frames), through a
 * capture thread or pacing (live, record): read once the thread has ended. */
static inline uint32_t app_skipped_frames(const rgbd_source *src) { return replay_skipped_frames(capture_inner(src)); }
/* "s" after a count other than one: "%u frame%s", n, app_s(n). */
static inline const char *app_s(uint64_t n) { return n == 1 ? "" : "s"; }
/* {"median", "p95", "mean"} of s under name. */
void app_json_series(cJSON *parent, const char *name, const bf_stats *s);
/* An array of n numbers under name. */
void app_json_numbers(cJSON *parent, const char *name, const double *v, size_t n);
/* Every field of the config under name: the loop's ("fusion", "track",
 * "loop") or fusion's alone. */
struct recon_config;
void app_json_recon_config(cJSON *parent, const char *name, const struct recon_config *c);
void app_json_fusion_config(cJSON *parent, const char *name, const fusion_config *c);
/* --depth-correction's file and what it holds under "depth_correction", or
 * null when path or c is NULL. */
struct calib_depth_correction;
void app_json_depth_correction(cJSON *parent, const char *path, const struct calib_depth_correction *c);
/* Write root to path atomically (dir/name), or print it on stdout; each
 * takes root and deletes it. */
bf_status app_json_write(const char *path, cJSON *root);
bf_status app_json_write_in(const char *dir, const char *name, cJSON *root);
bf_status app_json_print(cJSON *root);

/* log_report.c: what record and convert say about the log they wrote. */
struct replay_log_config;
struct replay_log_stats;
double app_ratio(uint64_t raw, uint64_t packed); /* raw / packed, NaN for 0 */
const char *app_colour_name(int colour);         /* a replay_log_colour: "jpeg", "zstd", "none" */
/* colour_codec, bytes by part, compression ratios and write rate into o. */
void app_json_log_stats(cJSON *o, const struct replay_log_config *lcfg, const struct replay_log_stats *L,
                        double seconds);

/* --out / --record checks: the path must end in .bflog. */
const char *app_check_log_path(const char *name, const char *value);
/* A usage error (app_usage_error's code) when opt's path out is the file
 * or folder in, which is being read: writing would destroy what it reads.
 * 0 when they differ or either does not exist yet. */
int app_check_not_input(const char *cmd, const char *opt, const char *out, const char *in);
/* A usage error when opt's recording path exists and overwrite is not
 * given: a camera's recording cannot be made again, and a recording that
 * fails part-way would leave fewer frames than the log it replaced. */
int app_check_new_recording(const char *cmd, const char *opt, const char *path, bool overwrite);
/* A usage error when opt's file out exists inside the folder dir, which is
 * being read (a sequence's index or image): writing would overwrite it;
 * with new_too also a file not there yet (a store reads any chunk file in
 * its folder as one of its own). */
int app_check_not_inside(const char *cmd, const char *opt, const char *out, const char *dir, bool new_too);
/* A usage error when the output folder out is a scene store, or the store
 * the same run writes (store, NULL: none): the run's outputs would go in
 * among the store's files. */
int app_check_out_not_store(const char *cmd, const char *out, const char *store);
/* A usage error when opt's file path exists and does not begin as a JSON
 * object does: a JSON writer's --out that names an image or an index by
 * mistake (--out written before a glob) is not written over. */
int app_check_json_out(const char *cmd, const char *opt, const char *path);
/* The folder a file output goes into exists (checked before the work, not
 * after it): 0, or the failure printed and exit 5 naming the folder; a
 * path too long for the system is a usage error (2). */
int app_check_out_folder(const char *cmd, const char *opt, const char *path);
/* The log's codec options record and convert share (--colour, --jpeg-quality,
 * --zstd-level), applied to a replay_log_config after parsing. */
typedef struct app_log_codec {
    int colour; /* a replay_log_colour */
    uint32_t jpeg_quality, zstd_level;
    bool colour_given, quality_given, level_given; /* on the command line (set by the parser) */
} app_log_codec;
#define APP_LOG_ROWS 5
void app_log_codec_options(app_option rows[APP_LOG_ROWS], app_log_codec *c);
void app_log_codec_apply(const app_log_codec *c, struct replay_log_config *lcfg);
/* Parses a command that writes a log from a source (record, convert): spec
 * with its own rows, then the codec's and the sequence's; the codec lands
 * in lcfg. Returns as app_options_parse. */
int app_parse_log_command(app_command_spec *spec, const app_option *own, app_log_codec *codec,
                          struct replay_options *ropt, struct replay_log_config *lcfg, int argc, char **argv);

/* scene.c: what render and view draw, and the options they share. */
/* "tx ty tz qx qy qz qw" (camera or mesh to world, TUM; a unit quaternion
 * within 1e-3) -> T; false with the reason in msg. */
bool app_parse_pose(const char *v, bf_se3 *T, char *msg, size_t n);
/* "WxH", each 2..8192. */
bool app_parse_size(const char *v, uint32_t *w, uint32_t *h);
/* "fx,fy,cx,cy" in pixels, focal lengths above 0. */
bool app_parse_camera(const char *v, double k[4]);
/* Option rows' checks of the above, and of a name ending .png. */
const char *app_check_pose(const char *name, const char *v);
const char *app_check_size(const char *name, const char *v);
const char *app_check_camera(const char *name, const char *v);
const char *app_check_png(const char *name, const char *v);
/* What render and view draw, as the command line asked for it. */
typedef struct app_scene_args {
    const char *map, *particles, *mesh, *mesh_pose;
    double radius_m, cell_m;
    double near_m, far_m; /* the rays' depth range */
    bool far_given;       /* --far given (view's whole-scene camera otherwise reaches past the scene) */
    bool particle_lod, mesh_lod;
} app_scene_args;
#define APP_SCENE_ROWS 11
/* The options render and view share: --map, --particles and theirs, --mesh
 * and theirs, with each command's own help for --mesh and --mesh-lod (view
 * voxelises at its first pose's detail); sets *a's defaults. */
void app_scene_options(app_option rows[APP_SCENE_ROWS], app_scene_args *a, const char *mesh_help,
                       const char *mesh_lod_help);
/* The usage errors both refuse (app_usage_error's code), 0 when none;
 * verb names what the command does ("render", "show"). */
int app_scene_check(const char *cmd, const char *verb, const app_scene_args *a);
/* The files a scene is drawn from, read before the GPU starts so that a
 * missing or bad one is named first. */
typedef struct app_scene_files {
    float *xyz; /* particle centres, malloc'd */
    uint32_t n_particles;
    mesh_data mesh;
    bf_se3 T_wm; /* --mesh-pose, else the identity */
} app_scene_files;
bf_status app_scene_read_files(const app_scene_args *a, app_scene_files *f);
void app_scene_files_free(app_scene_files *f);
/* The particles of f on the GPU as a asks (a position the grid cannot
 * hold is the file's fault: BF_FORMAT naming it). */
bf_status app_scene_make_particles(gpu_context *ctx, const app_scene_args *a, const app_scene_files *f,
                                   render_particles **out);
/* The map of a scene store, or of DIR/store (BF_FORMAT: neither, or no
 * brick); meta_out and rep_out (each may be NULL) get its meta and what was
 * left out of it (warned about). */
/* The scene store PATH names: PATH itself, or a run's folder holding it as
 * PATH/store (replay --out DIR --store DIR/store), written into buf; NULL
 * when neither is a store. */
const char *app_store_dir(const char *path, char *buf, size_t cap);
bf_status app_scene_read_map(const char *path, hostmap *m, store_meta *meta_out, store_report *rep_out);
/* A host map into a GPU map of its own size (hash, nodes, colour units). */
bf_status app_scene_load_map(gpu_context *ctx, const hostmap *m, const bf_intrinsics *K, fusion_map **out);
/* f's mesh voxelised as camera T_wc (K) sees it (lod: each column at the
 * level its pixel footprint needs; else all at one level from its nearest
 * vertex; nothing nearer than a's near plane counts) into
 * *hm: merged on the grid of the map read there when a has one, else *hm
 * becomes the mesh's own. A mesh too large for the device at those levels
 * is voxelised a level coarser at a time, with a warning; one the grid
 * cannot hold even so is BF_FORMAT naming the file. vst (may be NULL) gets
 * the voxeliser's stats, *level_asked (may be NULL) the finest level the
 * view asked for (above vst's level_fine after such a fallback). */
bf_status app_scene_add_mesh(gpu_context *ctx, const app_scene_args *a, const app_scene_files *f, const bf_se3 *T_wc,
                             const bf_intrinsics *K, bool lod, hostmap *hm, render_voxelise_stats *vst,
                             uint32_t *level_asked);
/* The vertices of a PLY as particle centres (world floats, malloc'd). */
bf_status app_scene_read_particles(const char *path, float **xyz, uint32_t *n);

int cmd_demo(int argc, char **argv);
int cmd_synth(int argc, char **argv);
int cmd_fuse(int argc, char **argv);
int cmd_replay(int argc, char **argv);
int cmd_eval_traj(int argc, char **argv);
int cmd_eval_surface(int argc, char **argv);
int cmd_eval_colour(int argc, char **argv);
int cmd_eval_motion(int argc, char **argv);
int cmd_devices(int argc, char **argv);
int cmd_calibrate(int argc, char **argv);
int cmd_calibrate_depth(int argc, char **argv);
int cmd_export(int argc, char **argv);
int cmd_render(int argc, char **argv);
/* cmd_export.c: bitfuse info on a scene store. */
int app_info_store(const char *dir, bool json);
int cmd_info(int argc, char **argv);
int cmd_record(int argc, char **argv);
int cmd_convert(int argc, char **argv);
int cmd_live(int argc, char **argv);
int cmd_view(int argc, char **argv);
/* device.c: opens uri (a live URI, or a recorded sequence replay reads
 * standing in for a camera) behind the capture thread, as
 * capture_open_device does. */
struct replay_options;
bf_status app_open_device(const char *uri, const struct replay_options *ropt, bool realtime, uint32_t queue,
                          bool *is_live, rgbd_source **out);
/* --calibration (calibration.c), for the commands that read a sequence
 * through it (replay, live, eval-motion, eval-colour). */
typedef struct app_calibration {
    const char *path;          /* NULL: no --calibration */
    calib_result cal;          /* as read; after app_calibration_apply, its colour camera at the frames' size */
    char depth_camera[512];    /* the depth camera as --camera's nine numbers (a folder's replay_options.camera) */
    char depth_camera_origin[4200]; /* "the depth camera of PATH", for replay's messages */
    bool is_lens_left;         /* app_calibration_apply: the source gives its depth through the depth camera's
                                  lens (a device, a log), which the reader of the frames takes out */
} app_calibration;
/* Reads and checks path before any device opens or output is made (exit 3
 * naming the file and field; exit 2 when ropt already has a --camera and
 * the file a depth camera), then sets ropt for it: the colour is the colour
 * camera's own image (raw_colour), and a folder is read with the file's
 * depth camera, lens included. is_device: seq is a live URI, not a file or
 * folder. APP_EXIT_OK on success. */
struct replay_options;
int app_calibration_read(const char *cmd, const char *path, const char *seq, bool is_device,
                         struct replay_options *ropt, app_calibration *out);
/* After the sequence opened: the file's depth camera replaces the
 * intrinsics a log or a device gave (the sizes must agree: BF_FORMAT), and
 * a colour camera calibrated at another size than the frames' is scaled to
 * it (c->cal.colour changes: callers copy it after). */
bf_status app_calibration_apply(app_calibration *c, const char *seq, rgbd_source *src);
/* The depth camera whose lens the frames' reader takes out of each depth
 * image (recon_run_config.depth_lens, eval-motion), or NULL: none, or the
 * source took it out. */
const calib_camera *app_calibration_depth_lens(const app_calibration *c);
/* The lens taken out of src's depth, by its reader or (cal's depth lens)
 * by whoever reads its frames: dist filled and returned, or cal's
 * coefficients, or NULL for none. cal may be NULL. */
const double *app_frames_lens(const rgbd_source *src, const app_calibration *cal, double dist[CALIB_DIST_N]);
/* Whether --depth-correction's file (path, read into c) was made in the
 * pixels src's frames are read in: through the lens its reader takes out,
 * or cal's the loop takes out (calib_depth_same_lens), and for their size.
 * BF_FORMAT naming both sizes or both lenses otherwise. cal may be NULL. */
struct calib_depth_correction;
bf_status app_depth_correction_check(const char *path, const struct calib_depth_correction *c,
                                     const rgbd_source *src, const app_calibration *cal, const char *seq);

/* The lens taken out of src's frames: replay_undistortion, or for the
 * recording app_open_device last wrapped as a camera, that recording's. */
bool app_undistortion(const rgbd_source *src, double dist[CALIB_DIST_N], double *shift_px);
/* Ctrl-C, SIGTERM and SIGHUP end the program as their default action does
 * (killed by that signal), after removing the temporary files it has open
 * (bf_pending_remove_all): every output is whole or absent. main calls this
 * first. */
void app_signals_init(void);
/* Until app_stop_end, Ctrl-C and SIGTERM stop src's capture thread and set
 * the returned flag instead of ending the program; a second one ends it as
 * app_signals_init's handler does. */
const volatile sig_atomic_t *app_stop_begin(rgbd_source *src);
/* Stops the scan as Ctrl-C does, from the program (a viewer window
 * closed): sets flag (the run's stop flag) and stops the capture thread
 * of app_stop_begin's source, if any. */
void app_stop_request(volatile sig_atomic_t *flag);
/* A folder this run made (up to three: the output folder, a store and its
 * chunks/): a fatal signal (a second Ctrl-C) removes them, the last made
 * first, while nothing was written into them yet. */
void app_signals_made_folder(const char *dir);
/* Restores the handlers; true if a signal came. */
bool app_stop_end(void);
/* cmd_replay.c: the full loop on a sequence (replay) or a device (live). */
int app_reconstruct(const char *cmd, int argc, char **argv, bool is_live_cmd);

#endif
