/* bitfuse replay and bitfuse live: the full reconstruction loop (track,
 * fuse, ray-cast, smooth) on a recorded sequence or a live device; writes
 * the estimated trajectory, the map's mesh and points, per-frame tracking
 * records and stats.json. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "calib/calib.h"
#include "eval/eval.h"
#include "recon/recon.h"
#include "replay/replay.h"
#include "view/view.h"

static const char replay_usage[] =
    "usage: bitfuse replay SEQUENCE --out DIR [options]\n"
    "\n"
    "Runs the full loop on every frame of SEQUENCE (DESIGN.md section 1): ICP against the\n"
    "ray-cast of the map's confident voxels, fusion at the pose found, ray-cast at that pose.\n"
    "Frames without depth are skipped; frames tracked badly are not fused and keep the\n"
    "last good pose while candidate poses are tried (--reloc). Writes into DIR:\n"
    "  trajectory.txt  TUM format, one line per frame read at its depth timestamp\n"
    "                  (camera to world, like groundtruth.txt)\n"
    "  frames.csv      per frame: state, ICP outcome, inliers, residual, times, the\n"
    "                  relocalising search's candidates tried and the one taken\n"
    "  mesh.ply        triangle mesh of the confident surface (binary PLY; --mesh-format\n"
    "                  obj|glb for mesh.obj + mesh.mtl or mesh.glb, --max-triangles N)\n"
    "  points.ply      surface voxel centres with normals\n"
    "  stats.json      the whole config, time per frame and per stage, tracking counts,\n"
    "                  ATE when the sequence has ground truth, map memory\n"
    "  views/N.png     shaded ray-cast views, with --view-every\n";

static const char replay_epilog[] =
    "exit codes: 0 ok (tracking failures are reported, not fatal), 1 failure (also: a\n"
    "measure moved beyond its --tolerance of --expect's baseline; everything is written),\n"
    "2 usage, 3 bad input (a corrupt frame mid-sequence: what came before it is still\n"
    "written; a baseline that cannot be read), 4 no Vulkan device or a device error\n"
    "(mid-scan: the trajectory so far is written, and the map when the device still\n"
    "answers), 5 an output could not be written (disk full, I/O error: the scan stops, the\n"
    "rest is still written; every file is whole or absent)\n";

static const char live_usage[] =
    "usage: bitfuse live --device URI --out DIR [options]\n"
    "\n"
    "Runs the full loop (as bitfuse replay) on a live camera: a capture thread reads the\n"
    "device into a bounded queue and drops the oldest frame when the loop falls behind\n"
    "(counted in stats.json). Ctrl-C ends the scan: the map is flushed and everything is\n"
    "written as after a replay. Writes the files of bitfuse replay into DIR.\n";

static const char live_epilog[] =
    "exit codes: 0 ok (also when stopped by Ctrl-C), 1 failure, 2 usage, 3 bad input or a\n"
    "device error mid-scan (what was reconstructed is still written), 4 no device, or a\n"
    "GPU error (as for replay), 5 an output could not be written (as for replay)\n";

typedef struct replay_args {
    const char *seq, *out;   /* seq: the sequence, or the device URI (live) */
    bool is_live_cmd, realtime;
    uint32_t queue;
    const char *record_path; /* live: also record into this log */
    bool overwrite;          /* live: --record may replace an existing log */
    int init;                /* 0: the first frame's ground truth, 1: identity */
    replay_options ropt;
    app_calibration cal;    /* --calibration, read by parse_args */
    recon_config rcfg;
    uint32_t view_every;
    bool no_mesh;
    app_mesh_out mesh_out;   /* the mesh file's format and detail */
    bool fuse_at_gt;         /* fuse at the frames' true poses: the tracker's one-step error */
    const char *store;       /* keep the map in this scene store as the scan goes */
    bool resume;             /* continue the scan kept in --store */
    double store_every_s;    /* seconds between the store's flushes (0: only at the end) */
    double gpu_budget_mib;   /* the pools' bytes (0: --bricks decides) */
    double cache_budget_mib; /* the streaming cache's bytes */
    bool auto_budget;        /* neither --gpu-budget nor --bricks: the device decides */
    bool bricks_given;       /* --bricks, even at fusion's default value */
    const char *calibration; /* calib.json: read into cal by parse_args */
    const char *depth_correction; /* depth_correction.json: read into replay_depth_fix by parse_args */
    bool view;               /* show the map in a window as the scan goes (view/) */
    const char *screenshot;  /* with view: the window's last frame, after exit_after frames */
    uint32_t exit_after;     /* with view: end the scan after this many frames shown (0: never) */
    bool overlay;            /* with view: the status line over the image too */
    double view_period_s;    /* with view: seconds between the window's casts of a followed scan */
    const char *expect_path; /* --expect: the baseline stats.json */
    const char *tolerance;   /* --tolerance NAME=VALUE,... */
    app_expect expect;       /* the baseline, read before the device opens */
    const char *ref_path, *vis_path; /* --reference MESH, --visible SEEN.ply */
    mesh_data ref, vis;      /* read before the device opens */
} replay_args;

/* The noise weight's exponent when --depth-correction is given and
 * --noise-exp is not: the default 3 was chosen on depth as it comes, whose
 * far samples carry the camera's pattern at its largest; corrected, they
 * earn more of their inverse variance. On the 7-Scenes dev frames, four
 * starts: mean ATE 22.97 mm against 23.75 at 3, and 12.67 / 28.38 against
 * 12.65 / 31.47 mm with a file calibrated on the other half
 * (docs/real_frames.md, "The depth camera's pattern, the far samples and
 * the noise exponent"). */
#define REPLAY_NOISE_EXP_CORRECTED 2.5f

/* --depth-correction's multipliers (one run per process; 19 KB, so not in
 * replay_args, which is copied). */
static calib_depth_correction replay_depth_fix;

#define LOOP_ROWS 36
#define LIVE_ROWS 6
#define STORE_ROWS 4
#define STREAM_ROWS 5
#define VIEW_ROWS 6

static const char *check_png(const char *name, const char *v)
{
    static char msg[256];
    size_t n = strlen(v);
    if (n > 4 && strcmp(v + n - 4, ".png") == 0) return NULL;
    snprintf(msg, sizeof msg, "%s %s: the image is written as PNG (a name ending .png)", name, v);
    return msg;
}

/* The window (view/, docs/view.md). */
static void view_options(app_option rows[VIEW_ROWS], replay_args *a)
{
    const app_option r[VIEW_ROWS] = {
        APP_OPT("--view", APP_OPT_FLAG, &a->view, NULL,
                "show the map in a window as the scan goes, following the camera (drag: orbit, pan, wheel: zoom, "
                "F: follow again); closing the window ends the scan as Ctrl-C does, everything kept"),
        APP_OPT("--view-period", APP_OPT_DOUBLE, &a->view_period_s, "S",
                "with --view: seconds between the window's ray-casts while it follows the scan, and at most a fifth "
                "of the loop's time (each is a cast of the map at the frame's size: 0.3-1 s at 640x480 on "
                "lavapipe); a camera moved by hand is cast every frame", .max = 3600, .needs = "--view"),
        APP_OPT("--overlay", APP_OPT_CHOICE, &a->overlay, "on|off",
                "with --view: the frame, tracking state and bricks also over the image's corner (always in the title)",
                .needs = "--view"),
        APP_OPT("--screenshot", APP_OPT_STRING, &a->screenshot, "IMAGE.png",
                "with --view and --exit-after: the window's last frame, read back from the window", .check = check_png,
                .needs = "--exit-after"),
        APP_OPT("--exit-after", APP_OPT_U32, &a->exit_after, "N",
                "with --view: end the scan after N frames shown, as closing the window does (scripts)", .min = 1,
                .no_default = true, .needs = "--view"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

/* Bytes of the pools per brick: sign and confidence planes, its record,
 * stamp and free-stack entry, and three octree nodes (a scan holds 2.2-2.4
 * nodes a brick: docs/streaming.md). */
#define NODES_PER_BRICK 3
#define BYTES_PER_BRICK (2 * 64 + 16 + 4 + 4 + NODES_PER_BRICK * 8)
/* With colour: the brick's colour masks (16 words) and head, and
 * COLOUR_UNITS_PER_BRICK colour units of 32 bytes with their free-stack
 * entries (docs/colour.md: 5.5 a brick on the real frames). */
#define COLOUR_UNITS_PER_BRICK 7
#define COLOUR_BYTES_PER_BRICK (64 + 4 + COLOUR_UNITS_PER_BRICK * (32 + 4))
#define DEFAULT_GPU_BUDGET_MIB 64.0

/* Chunk streaming (stream/stream.h, DESIGN.md section 1). */
static void stream_options(app_option rows[STREAM_ROWS], replay_args *a)
{
    stream_config *sc = &a->rcfg.stream;
    const app_option r[STREAM_ROWS] = {
        APP_OPT("--gpu-budget", APP_OPT_DOUBLE, &a->gpu_budget_mib, "MIB",
                "bytes of the GPU map pools in MiB (bricks, nodes, records, colour; 176 bytes a brick, 496 with "
                "colour); chunks beyond it "
                "stream out (default: --bricks when given, else from the device: 64 on a CPU device, a quarter of a "
                "GPU's memory up to 2048)", .min = 0.1, .no_default = true),
        APP_OPT("--cache-budget", APP_OPT_DOUBLE, &a->cache_budget_mib, "MIB",
                "bytes of the CPU cache of chunks streamed out of the GPU, in MiB; beyond it they go to disk (0: "
                "every one)", .min = 0, .not_with = "--stream=off"),
        APP_OPT("--stream", APP_OPT_CHOICE, &sc->enabled, "on|off",
                "stream chunks out of the GPU pools beyond --stream-radius (or when the pools fill) and back"),
        APP_OPT("--stream-radius", APP_OPT_FLOAT, &sc->radius_m, "M",
                "chunks within M metres of the camera stay in the pools or come back", .min_open = true,
                .not_with = "--stream=off"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

/* The scene store (docs/formats.md, "Scene store"; docs/cli.md). */
static void store_options(app_option rows[STORE_ROWS], replay_args *a)
{
    const app_option r[STORE_ROWS] = {
        APP_OPT("--store", APP_OPT_STRING, &a->store, "STORE",
                "keep the map in this scene store (a folder) as the scan goes: flushed every --store-every "
                "seconds and at the end or at Ctrl-C", .no_default = true),
        APP_OPT("--resume", APP_OPT_FLAG, &a->resume, NULL,
                "reopen --store and continue its scan from its last pose and trajectory (frames of SEQUENCE up to "
                "its last time are skipped)", .needs = "--store"),
        APP_OPT("--store-every", APP_OPT_DOUBLE, &a->store_every_s, "S",
                "seconds between flushes of the map into --store (0: only at the end); a kill loses at most the "
                "work since the last one", .max = 3600, .needs = "--store"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

/* The options of the loop itself: tracking, ray-cast and outputs. */
static const char *check_sample_step(const char *name, const char *v)
{
    static char msg[128];
    if (strcmp(v, "3")) return NULL; /* the range check does the rest */
    snprintf(msg, sizeof msg, "%s: 3 is not a sample step (1, 2 or 4)", name);
    return msg;
}

/* --ref-level's choices: RECON_REF_LEVEL_AUTO is UINT32_MAX, -1 as an int. */
static const int ref_level_codes[] = {-1, 0, 1, 2};

static void loop_options(app_option rows[LOOP_ROWS], replay_args *a)
{
    track_config *tc = &a->rcfg.track;
    const app_option r[LOOP_ROWS] = {
        APP_OPT("--out", APP_OPT_STRING, &a->out, "DIR", "output folder (created)", .required = true),
        APP_OPT("--init", APP_OPT_ENUM, &a->init, "groundtruth|identity",
                "first pose: the first frame's ground truth (when it has one) or the identity"),
        APP_OPT("--icp-iters", APP_OPT_LIST, tc->iterations, "A,B,C",
                "ICP iterations per pyramid level, finest first (1 to 3 values: as many levels)", .max = 1000, .count = &tc->levels,
                .max_n = TRACK_MAX_LEVELS),
        APP_OPT("--huber", APP_OPT_FLOAT, &tc->huber_k, "K",
                "ICP Huber threshold in units of the sensor noise sigma_z(z) (0: plain least squares)"),
        APP_OPT("--noise-weights", APP_OPT_CHOICE, &tc->weight_noise, "on|off",
                "weight ICP residuals by the sensor noise, (sigma_z(1 m) / sigma_z(z))^E (--noise-exp)"),
        APP_OPT("--noise-exp", APP_OPT_FLOAT, &tc->noise_weight_exp, "E",
                "exponent of the ICP noise weight: 2 the inverse variance, smaller lets far samples count more; "
                "default 3, or 2.5 with --depth-correction (far samples corrected for the camera's pattern "
                "count more: docs/calibration.md)",
                .min_open = true, .max = 4, .no_default = true),
        APP_OPT("--icp-stop-m", APP_OPT_FLOAT, &tc->converged_m, "M",
                "a pyramid level stops iterating when an ICP update moves less than M metres and turns less "
                "than --icp-stop-deg (0 and 0: always every iteration)"),
        APP_OPT("--icp-stop-deg", APP_OPT_FLOAT, &tc->converged_deg, "DEG", "see --icp-stop-m"),
        APP_OPT("--icp-sample-step", APP_OPT_U32, &tc->finest_sample_step, "S",
                "ICP samples at the finest level: 1 every pixel, 2 every second one (a checkerboard, half the cost), "
                "4 every fourth (a quarter)",
                .min = 1, .max = 4, .check = check_sample_step),
        APP_OPT("--photometric", APP_OPT_FLOAT, &tc->photo_weight, "W",
                "weight of the photometric term in the finest ICP level (the colour of each inlier against the "
                "reference frame's), relative to a depth residual at 1 m; 0: off"),
        APP_OPT("--photometric-weak", APP_OPT_FLOAT, &tc->photo_weak_ratio, "R",
                "the photometric term only in frames whose depth leaves a direction weak (the finest ICP system's "
                "smallest eigenvalue below R times its largest); 0: in every frame",
                .max = 0.5),
        APP_OPT("--photo-sigma", APP_OPT_FLOAT, &tc->photo_sigma, "S",
                "the photometric term's intensity noise (luma in [0, 1])", .min_open = true, .max = 1),
        APP_OPT("--photo-levels", APP_OPT_U32, &tc->photo_levels, "N",
                "pyramid levels with the photometric term, from the finest (1: the finest only, 3: all; with "
                "--photometric-weak above 0 the finest level decides, so the finest only)",
                .min = 1,
                .max = TRACK_MAX_LEVELS),
        APP_OPT("--photo-sharpness", APP_OPT_FLOAT, &tc->photo_sharpness_min, "R",
                "drop the photometric term for a frame whose intensity gradient energy and the reference's differ "
                "by more than this ratio either way (motion blur); 0: never", .max = 1),
        APP_OPT("--huber-scale", APP_OPT_CHOICE, &tc->huber_scaled, "residuals|sensor",
                "the Huber threshold's unit: sigma_z(z) times the last iteration's RMS of r / sigma_z when above 1, "
                "or sigma_z(z) alone"),
        APP_OPT("--huber-knee", APP_OPT_FLOAT, &tc->huber_knee, "R",
                "with --huber-scale residuals: the RMS of r / sigma_z below which the unit stays sigma_z", .min = 1),
        APP_OPT("--max-residual-sigma", APP_OPT_FLOAT, &tc->max_residual_sigma, "S",
                "a frame whose inliers' RMS residual is over 2 cm counts as lost only when it is also over S times "
                "the sensor's noise at their depths; 0: over 2 cm is lost"),
        APP_OPT("--ref-level", APP_OPT_ENUM, (int *)&tc->ref_level, "auto|0|1|2",
                "resolution of the tracking reference's ray-cast: 0 full, 1 half, 2 quarter; auto: the coarsest "
                "of 0, 1 and 2 that keeps at least 160 pixels a row (a quarter of 640x480, full 160x120)",
                .codes = ref_level_codes),
        APP_OPT("--ref-voxels", APP_OPT_CHOICE, &a->rcfg.reference_confident, "confident|all",
                "the tracking reference's ray-cast: once the first fusion window has closed, the confident "
                "voxels only (those a window saw often enough), or every sign bit (the quick signs of surfaces "
                "seen in the last frames too)"),
        APP_OPT("--guess", APP_OPT_CHOICE, &a->rcfg.constant_velocity, "velocity|last",
                "the tracker's first guess: the last pose moved on by the last motion per frame interval over "
                "the intervals since the last good frame, or the last pose"),
        APP_OPT("--repeated", APP_OPT_CHOICE, &a->rcfg.skip_repeated, "skip|track",
                "a frame whose depth repeats the previous frame's byte for byte (a driver handing on its last "
                "image): skipped, the last pose kept, or tracked and fused like a new one; with skip, a colour "
                "repeated alone is left out of the photometric term and the map's colour"),
        APP_OPT("--max-depth", APP_OPT_FLOAT, &a->rcfg.sensor.max_depth_m, "M",
                "the sensor's range: depth samples beyond M metres are neither tracked nor fused (Kinect v1's "
                "noise grows with the square of the depth); at most 6, the tracking reference's far plane",
                .min = 0.5, .max = 6),
        APP_OPT("--reloc", APP_OPT_CHOICE, &a->rcfg.reloc.enabled, "on|off",
                "look for a lost camera from candidate poses (where its colour matched to a keyframe's puts it, "
                "last pose, continued motion, turns, keyframes) and widen the motion gate with the frames since "
                "the last good one; off: keep the last pose"),
        APP_OPT("--reloc-features", APP_OPT_U32, &a->rcfg.reloc.features, "N",
                "ORB keypoints per keyframe and per searching frame for the candidates from colour (0: none; "
                "with --calibration found in the colour camera's own image)",
                .max = 100000, .not_with = "--reloc=off"),
        APP_OPT("--last-frame", APP_OPT_CHOICE, &a->rcfg.reloc.last_frame, "on|off",
                "with --reloc: a frame right after a good one whose fit to the map is weak (under 45% of its "
                "samples inliers) or that no candidate finds is tracked against that frame's depth, and takes "
                "that pose when it fits with more inliers (a fast turn into what the map has barely seen); off: "
                "the map alone"),
        APP_OPT("--fuse-every", APP_OPT_U32, &a->rcfg.fuse_every, "N",
                "fuse every N-th tracked frame; the others are tracked only, against the reference the last "
                "fused frame left (frames found by a search or on the frame before are always fused)",
                .min = 1, .max = RECON_MAX_FUSE_EVERY),
        APP_OPT("--fuse-every-behind", APP_OPT_U32, &a->rcfg.fuse_every_behind, "N",
                "the same while frames wait in a camera's queue (bitfuse live: a device, or a recording with "
                "--realtime): the loop is behind the camera and tracks more of its frames by fusing fewer (the "
                "larger of the two applies; 1: fuse every frame and let the queue drop them)",
                .min = 1, .max = RECON_MAX_FUSE_EVERY),
        APP_OPT("--ray-start", APP_OPT_CHOICE, &a->rcfg.start_at_frame, "frame|near",
                "the reference's rays start just in front of the tracked frame's depth or at the near plane"),
        APP_OPT("--rof-iters", APP_OPT_U32, &tc->rof_iterations, "N", "ROF iterations on the reference (0: off)"),
        APP_OPT("--rof-lambda", APP_OPT_FLOAT, &tc->rof_lambda0, "L", "ROF data weight at 1 m", .min_open = true),
        APP_OPT("--fine-angle-gate", APP_OPT_FLOAT, &tc->fine_angle_deg, "DEG",
                "the normal-angle gate of the finest level's weighted iterations (0: --angle-gate)", .max = 90),
        APP_OPT("--angle-gate", APP_OPT_FLOAT, &tc->angle_deg, "DEG", "ICP normal-angle gate in degrees", .max = 90,
                .min_open = true),
        APP_OPT("--degenerate-ratio", APP_OPT_DOUBLE, &tc->degenerate_ratio, "R",
                "eigenvalue ratio below which the ICP system counts as degenerate", .max = 1),
        APP_OPT("--view-every", APP_OPT_U32, &a->view_every, "K", "write a shaded view every K frames the loop handled", .min = 1,
                .no_default = true),
        APP_OPT("--no-mesh", APP_OPT_FLAG, &a->no_mesh, NULL, "skip the mesh (points and stats only)"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

static void live_options(app_option rows[LIVE_ROWS], replay_args *a)
{
    const app_option r[LIVE_ROWS] = {
        APP_OPT("--device", APP_OPT_STRING, &a->seq, "URI",
                "freenect:N, openni2:[URI|FILE.oni], v4l2:/dev/videoN (docs/devices.md), or a recorded sequence "
                "standing in for a camera",
                .required = true),
        APP_OPT("--realtime", APP_OPT_FLAG, &a->realtime, NULL,
                "play a recorded sequence at its own frame rate, as a camera would"),
        APP_OPT("--queue", APP_OPT_U32, &a->queue, "N", "capture queue length in frames", .min = 1, .max = 1024),
        APP_OPT("--record", APP_OPT_STRING, &a->record_path, "FILE",
                "also record the frames the loop consumed into a bitfuse log (refused if FILE exists, "
                "unless --overwrite)", .check = app_check_log_path),
        APP_OPT("--overwrite", APP_OPT_FLAG, &a->overwrite, NULL, "let --record replace an existing log",
                .needs = "--record"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

/* The pools' sizes from a byte budget. */
static void set_budget(replay_args *a, double mib)
{
    bool colour = a->rcfg.fusion.keep_colour;
    double bricks = floor(mib * 1048576.0 / (BYTES_PER_BRICK + (colour ? COLOUR_BYTES_PER_BRICK : 0)));
    a->gpu_budget_mib = mib;
    a->rcfg.fusion.brick_cap = bricks > (1u << 26) ? (1u << 26) : (uint32_t)bricks;
    a->rcfg.fusion.node_cap = NODES_PER_BRICK * a->rcfg.fusion.brick_cap;
    a->rcfg.fusion.colour_unit_cap = colour ? COLOUR_UNITS_PER_BRICK * a->rcfg.fusion.brick_cap : 0;
}

/* Without --gpu-budget or --bricks the budget comes from the device: on a
 * CPU device (lavapipe: the pools are the process's memory) 64 MiB, 135,300
 * bricks with colour (381,300 without), 5 times what 500 real frames of a
 * room need (26,700 bricks; with
 * 1 M bricks the pools were 176 MiB of the 466 MiB the real run held
 * resident, docs/streaming.md); on a GPU a quarter of its largest
 * device-local heap, at least 64 MiB and at most 2 GiB. The stream makes
 * room beyond that. */
static void auto_budget(replay_args *a, const gpu_context *ctx)
{
    double mib = DEFAULT_GPU_BUDGET_MIB;
    if (gpu_device_type(ctx) != VK_PHYSICAL_DEVICE_TYPE_CPU) {
        const gpu_limits *l = gpu_device_limits(ctx);
        uint64_t heap = 0;
        for (uint32_t i = 0; i < l->n_heaps; i++)
            if (l->heaps[i].is_device_local && l->heaps[i].size_bytes > heap) heap = l->heaps[i].size_bytes;
        mib = fmin(fmax(heap / 4.0 / 1048576.0, DEFAULT_GPU_BUDGET_MIB), 2048.0);
    }
    set_budget(a, mib);
}

static int parse_args(const char *cmd, bool is_live_cmd, int argc, char **argv, replay_args *a)
{
    memset(a, 0, sizeof *a);
    a->is_live_cmd = is_live_cmd;
    a->queue = 8;
    a->store_every_s = 1.0;
    a->overlay = true;
    a->view_period_s = 0.5;
    a->cache_budget_mib = 256;
    a->rcfg = recon_config_default();
    app_option own[LOOP_ROWS], dev[LIVE_ROWS], map[APP_MAP_ROWS], seq[APP_SEQUENCE_ROWS], sto[STORE_ROWS],
        stm[STREAM_ROWS], msh[APP_MESH_ROWS], vw[VIEW_ROWS];
    const app_option fuse_gt[] = {
        APP_OPT("--fuse-at-groundtruth", APP_OPT_FLAG, &a->fuse_at_gt, NULL,
                "track every frame but fuse it at its true pose: the map is the one the sensor gives and the "
                "trajectory's error is the tracker's own, one frame at a time (needs ground truth; a repeated "
                "depth is skipped as in the loop)"),
        APP_OPT_END,
    };
    loop_options(own, a);
    live_options(dev, a);
    app_map_options(map, &a->rcfg.fusion, &a->bricks_given);
    app_sequence_options(seq, &a->ropt);
    store_options(sto, a);
    stream_options(stm, a);
    app_mesh_options(msh, &a->mesh_out, false);
    view_options(vw, a);
    const app_option cal[] = {
        APP_OPT("--calibration", APP_OPT_STRING, &a->calibration, "FILE",
                "calib.json of bitfuse calibrate: the colour camera and T_colour_depth for registering colour to "
                "depth; when it has the depth camera, its fx, fy, cx, cy replace the sequence's (camera.txt, the "
                "format's or the device's) and its lens is taken out of the depth", .no_default = true),
        APP_OPT("--depth-correction", APP_OPT_STRING, &a->depth_correction, "FILE",
                "depth_correction.json of bitfuse calibrate-depth: the depth camera's fixed error pattern, taken "
                "out of every frame before tracking and fusion (docs/calibration.md)", .no_default = true),
        APP_OPT_END,
    };
    const app_option gate[] = {
        APP_OPT("--expect", APP_OPT_STRING, &a->expect_path, "BASELINE.json",
                "a regression gate: compare this run's stats.json with BASELINE.json (an earlier run's) and exit 1 "
                "naming each measure that moved beyond its tolerance (ATE, surface error, map digest, tracked, lost "
                "and relocalised frames; time only when --tolerance names it); everything is still written",
                .no_default = true),
        APP_OPT("--reference", APP_OPT_STRING, &a->ref_path, "MESH",
                "the true surface (bitfuse synth's scene.ply): the map's surface voxels (points.ply) against it, "
                "stats.json surface_m (accuracy median, p90, completeness within 1 cm), gated by --expect",
                .no_default = true),
        APP_OPT("--visible", APP_OPT_STRING, &a->vis_path, "SEEN.ply",
                "with --reference: completeness over these observed reference points (synth's seen.ply)",
                .no_default = true, .needs = "--reference"),
        APP_OPT("--tolerance", APP_OPT_STRING, &a->tolerance, "NAME=V,...",
                "with --expect: tolerances replacing the defaults ate=0.001 (m, ATE RMSE), surface=0.001 (m, "
                "median), tracked=0, lost=0, relocalised=0 (frames), digest (exact); time=F gates the median "
                "frame time at F times slower (0.2: 20%); NAME=off leaves a measure out",
                .check = app_check_tolerance, .no_default = true, .needs = "--expect"),
        APP_OPT_END,
    };
    const app_option *replay_tables[] = {own, vw, msh, fuse_gt, cal, gate, sto, stm, map, seq, NULL};
    const app_option *live_tables[] = {dev, own, vw, msh, cal, sto, stm, map, seq, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = is_live_cmd ? live_usage : replay_usage,
        .tables = is_live_cmd ? live_tables : replay_tables, .positional = &a->seq,
        .min_positional = is_live_cmd ? 0 : 1, .max_positional = is_live_cmd ? 0 : 1,
        .positional_missing = "no sequence given", .epilog = is_live_cmd ? live_epilog : replay_epilog,
    };
    /* Unset until parsed: its default follows --depth-correction. */
    a->rcfg.track.noise_weight_exp = NAN;
    int rc = app_options_parse(&spec, argc, argv);
    if (isnan(a->rcfg.track.noise_weight_exp))
        a->rcfg.track.noise_weight_exp = a->depth_correction ? REPLAY_NOISE_EXP_CORRECTED
                                                             : recon_config_default().track.noise_weight_exp;
    a->auto_budget = !rc && a->gpu_budget_mib <= 0 && !a->bricks_given;
    if (!rc && a->gpu_budget_mib > 0 && a->bricks_given)
        return app_usage_error(cmd, "--bricks and --gpu-budget both size the map's pools: give one");
    if (!rc && a->gpu_budget_mib > 0 && floor(a->gpu_budget_mib * 1048576.0 / BYTES_PER_BRICK) < 1024)
        return app_usage_error(cmd, "--gpu-budget %g MiB holds fewer than 1024 bricks", a->gpu_budget_mib);
    if (!rc && a->gpu_budget_mib > 0) set_budget(a, a->gpu_budget_mib);
    a->rcfg.stream.cache_bytes = (uint64_t)(a->cache_budget_mib * 1048576.0);
    if (!rc && a->resume && a->fuse_at_gt) return app_usage_error(cmd, "--resume does not go with --fuse-at-groundtruth");
    if (!rc && a->calibration) {
        /* Read and checked here, before any device opens or output is made. */
        /* live on a recording standing in for a camera reads it as replay
         * would: a folder through the file's depth lens. */
        bool is_device = a->is_live_cmd && capture_is_device_uri(a->seq);
        rc = app_calibration_read(cmd, a->calibration, a->seq, is_device, &a->ropt, &a->cal);
        if (rc) return rc;
    }
    if (!rc && a->depth_correction) {
        bf_status s = calib_depth_read(a->depth_correction, &replay_depth_fix);
        if (s != BF_OK) return app_fail(cmd, s);
    }
    if (!rc) rc = app_check_map_options(cmd, &a->rcfg.fusion);
    if (!rc) {
        /* The tracker's values, before the GPU starts (the reference's
         * level is the loop's to choose when auto). */
        track_config tc = a->rcfg.track;
        if (tc.ref_level == RECON_REF_LEVEL_AUTO) tc.ref_level = 0;
        if (track_config_check(&tc) != BF_OK) return app_usage_error(cmd, "%s", bf_last_error());
    }
    if (!rc) rc = app_check_not_input(cmd, "--out", a->out, a->seq);
    if (!rc) rc = app_check_out_not_sequence(cmd, a->out, false); /* another sequence's stats.json, its files */
    if (!rc && a->store && !a->store[0]) rc = app_usage_error(cmd, "--store needs a folder, not ''");
    /* The store's files among the sequence's: the folder would read as a store. */
    if (!rc) rc = app_check_not_input(cmd, "--store", a->store, a->seq);
    if (!rc) rc = app_check_out_not_store(cmd, a->out, a->store);
    if (!rc) rc = app_check_not_input(cmd, "--record", a->record_path, a->seq);
    if (!rc) rc = app_check_new_recording(cmd, "--record", a->record_path, a->overwrite);
    if (!rc && a->ref_path) {
        bf_status s = mesh_read(a->ref_path, &a->ref);
        if (s == BF_OK && a->ref.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: the reference has no vertices", a->ref_path);
        if (s == BF_OK && a->vis_path) s = mesh_read(a->vis_path, &a->vis);
        if (s == BF_OK && a->vis_path && a->vis.n_verts == 0)
            s = bf_fail(BF_FORMAT, "%s: no visible points", a->vis_path);
        if (s != BF_OK) {
            mesh_free(&a->ref);
            mesh_free(&a->vis);
            return app_fail(cmd, s);
        }
    }
    if (!rc && a->expect_path) {
        /* Read and checked last (it owns memory), before any device opens
         * or output is made. */
        bf_status s = app_expect_load(&a->expect, a->expect_path, a->tolerance);
        if (s != BF_OK) {
            mesh_free(&a->ref);
            mesh_free(&a->vis);
            return app_fail(cmd, s);
        }
    }
    return rc;
}

typedef struct replay_result {
    recon_run run;
    app_map_report out;
    bool has_ate;
    eval_ate_result ate;
    char ate_error[512];       /* why no ATE where the frames carry ground truth ("" otherwise) */
    bool has_surface;          /* --reference */
    eval_surface_result surf;
    uint32_t n_views;
    double seconds;
    double t_start_s;          /* bf_time_s() at the command's start */
    size_t cache_loaded_bytes; /* of the pipeline cache file */
    char device[256];
    char device_driver[256]; /* the driver's own words, e.g. Mesa's version */
    app_store store;           /* --store */
    bool has_capture;          /* live: the capture thread's counts */
    bool is_camera;            /* live from a camera (not a recording): every frame is new to a resumed store */
    capture_thread_stats cap;
    uint32_t n_recorded;
} replay_result;

/* Start-up (docs/tracking.md, start-up): seconds from the command's start
 * to the loop being ready (device open, every pipeline compiled, pools
 * allocated; a camera starts after it) and to the first frame done. */
static void json_startup(cJSON *o, const replay_result *r)
{
    cJSON *st = app_json_object(o, "startup");
    double ready = r->run.t_ready_s ? r->run.t_ready_s - r->t_start_s : NAN;
    double first = r->run.t_first_done_s ? r->run.t_first_done_s - r->t_start_s : NAN;
    cJSON_AddNumberToObject(st, "ready_s", ready);
    cJSON_AddNumberToObject(st, "first_frame_done_s", first);
    cJSON_AddNumberToObject(st, "first_frame_ms", r->run.t_first_done_s ? r->run.first_frame_ms : NAN);
    cJSON_AddNumberToObject(st, "pipeline_cache_loaded_bytes", (double)r->cache_loaded_bytes);
}

/* Chunk streaming (stream/): what moved, the memory of each tier. */
static void json_stream(cJSON *o, const replay_args *a, const replay_result *r)
{
    if (!a->rcfg.stream.enabled || !r->run.loop) {
        cJSON_AddNullToObject(o, "stream");
        return;
    }
    stream_stats st = recon_stream_stats(r->run.loop);
    cJSON *s = app_json_object(o, "stream");
    cJSON_AddNumberToObject(s, "pool_bricks", a->rcfg.fusion.brick_cap);
    cJSON_AddNumberToObject(s, "pool_bytes", (double)a->rcfg.fusion.brick_cap *
                                                 (BYTES_PER_BRICK + (a->rcfg.fusion.keep_colour ? COLOUR_BYTES_PER_BRICK : 0)));
    cJSON_AddNumberToObject(s, "checks", st.checks);
    cJSON_AddNumberToObject(s, "pressure_checks", st.pressure_checks);
    cJSON_AddNumberToObject(s, "compactions", st.compactions);
    cJSON_AddNumberToObject(s, "loads_deferred", st.loads_deferred);
    cJSON_AddNumberToObject(s, "chunks_resident", st.resident);
    cJSON_AddNumberToObject(s, "chunks_cached", st.cached);
    cJSON_AddNumberToObject(s, "chunks_on_disk", st.on_disk);
    cJSON_AddNumberToObject(s, "chunks_out", (double)st.chunks_out);
    cJSON_AddNumberToObject(s, "chunks_in", (double)st.chunks_in);
    cJSON_AddNumberToObject(s, "bricks_out", (double)st.bricks_out);
    cJSON_AddNumberToObject(s, "bricks_in", (double)st.bricks_in);
    cJSON_AddNumberToObject(s, "chunks_to_disk", (double)st.to_disk);
    cJSON_AddNumberToObject(s, "chunks_from_disk", (double)st.from_disk);
    cJSON_AddNumberToObject(s, "cache_bytes_max", (double)st.cache_bytes_max);
    cJSON_AddNumberToObject(s, "disk_bytes", (double)st.disk_bytes);
    const char *spill_error = recon_stream_spill_error(r->run.loop);
    if (spill_error) cJSON_AddStringToObject(s, "spill_error", spill_error); /* the scan went on without the disk */
    cJSON_AddNumberToObject(s, "move_ms_max", st.ms_max);
    cJSON_AddNumberToObject(s, "move_ms_total", st.ms_total);
}

/* Frames the capture thread took that the loop never read: those queued
 * (or being queued) when the scan stopped. */
static uint64_t capture_unread(const capture_thread_stats *c)
{
    uint64_t used = c->delivered + c->dropped;
    return c->captured > used ? c->captured - used : 0;
}

static cJSON *stats_json(const replay_args *a, const replay_result *r, const rgbd_source *src)
{
    const recon_run_series *t = &r->run.series;
    const recon_counts *c = &r->run.counts;
    cJSON *o = app_json_stats(a->is_live_cmd ? "live" : "replay");
    cJSON_AddStringToObject(o, a->is_live_cmd ? "source" : "sequence", a->seq);
    cJSON_AddStringToObject(o, "device", r->device);
    cJSON_AddStringToObject(o, "device_driver", r->device_driver);
    app_json_recon_config(o, "config", &a->rcfg);
    /* What the run was asked besides the loop's configuration: a
     * --fuse-at-groundtruth ATE is the tracker's one-step error, not the loop's. */
    cJSON *cf = cJSON_GetObjectItemCaseSensitive(o, "config");
    if (cf) {
        cJSON_AddStringToObject(cf, "poses", a->fuse_at_gt ? "track, fused at the ground truth" : "track");
        cJSON_AddStringToObject(cf, "init", a->init == 1 ? "identity" : "groundtruth");
        cJSON_AddBoolToObject(cf, "resume", a->resume);
    }
    app_json_depth_correction(o, a->depth_correction, a->depth_correction ? &replay_depth_fix : NULL);
    cJSON_AddNumberToObject(o, "frames", c->frames);
    cJSON_AddNumberToObject(o, "frames_already_stored", r->run.n_resume_skipped);
    cJSON_AddBoolToObject(o, "interrupted", r->run.is_interrupted); /* Ctrl-C, SIGTERM, the window closed */
    app_json_input(o, &r->run, src);
    cJSON *tr = app_json_object(o, "tracking");
    cJSON_AddNumberToObject(tr, "tracked", c->tracked);
    cJSON_AddNumberToObject(tr, "lost", c->lost);
    cJSON_AddNumberToObject(tr, "relocalised", c->relocalised);
    cJSON_AddNumberToObject(tr, "last_frame", c->last_frame);
    cJSON_AddNumberToObject(tr, "unfused", c->unfused);
    cJSON_AddNumberToObject(tr, "behind", c->behind);
    cJSON_AddNumberToObject(tr, "keyframes", c->keyframes);
    /* The tracking reference's size (auto resolves per camera). */
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    uint32_t rl = recon_ref_level(K, &a->rcfg.track);
    cJSON *ref = cJSON_AddArrayToObject(tr, "reference_size");
    cJSON_AddItemToArray(ref, cJSON_CreateNumber(K->width >> rl));
    cJSON_AddItemToArray(ref, cJSON_CreateNumber(K->height >> rl));
    cJSON_AddNumberToObject(tr, "no_depth", c->no_depth);
    cJSON_AddNumberToObject(tr, "without_groundtruth", r->run.n_skipped); /* --fuse-at-groundtruth: skipped */
    cJSON_AddNumberToObject(tr, "repeated", c->repeated);
    cJSON_AddNumberToObject(tr, "colour_repeated", c->colour_repeated);
    cJSON_AddNumberToObject(tr, "degenerate", c->degenerate);
    cJSON_AddNumberToObject(tr, "photo_weak", c->photo_weak);
    cJSON_AddNumberToObject(tr, "pool_full", c->pool_full);
    app_json_series(tr, "inlier_fraction", &t->inlier_frac);
    app_json_series(tr, "residual_mm", &t->residual_mm);
    if (r->has_ate) {
        cJSON *ate = app_json_object(o, "ate_m");
        cJSON_AddNumberToObject(ate, "rmse", r->ate.trans.rmse);
        cJSON_AddNumberToObject(ate, "mean", r->ate.trans.mean);
        cJSON_AddNumberToObject(ate, "median", r->ate.trans.median);
        cJSON_AddNumberToObject(ate, "max", r->ate.trans.max);
        cJSON_AddNumberToObject(ate, "pairs", (double)r->ate.n_matched);
        cJSON_AddNumberToObject(ate, "trajectory_poses", (double)r->run.est.n);
    } else {
        cJSON_AddNullToObject(o, "ate_m");
        if (r->ate_error[0]) cJSON_AddStringToObject(o, "ate_error", r->ate_error);
    }
    if (r->has_surface) {
        cJSON *sf = app_json_object(o, "surface_m");
        cJSON_AddStringToObject(sf, "reference", a->ref_path);
        cJSON_AddNumberToObject(sf, "median", r->surf.accuracy.median);
        cJSON_AddNumberToObject(sf, "mean", r->surf.accuracy.mean);
        cJSON_AddNumberToObject(sf, "p90", r->surf.accuracy.p90);
        cJSON_AddNumberToObject(sf, "completeness_1cm", r->surf.completeness);
        cJSON_AddBoolToObject(sf, "over_visible", r->surf.used_visible);
        cJSON_AddNumberToObject(sf, "points", (double)r->surf.n_rec_vertices);
    }
    app_json_series(o, "frame_ms", &t->frame_ms);
    app_json_gpu_stages(o, &r->run, true);
    if (r->has_capture) {
        cJSON *cap = app_json_object(o, "capture");
        cJSON_AddNumberToObject(cap, "captured", (double)r->cap.captured);
        cJSON_AddNumberToObject(cap, "delivered", (double)r->cap.delivered);
        cJSON_AddNumberToObject(cap, "dropped", (double)r->cap.dropped);
        cJSON_AddNumberToObject(cap, "unread_at_stop", (double)capture_unread(&r->cap));
        cJSON_AddBoolToObject(cap, "interrupted", r->run.is_interrupted);
        cJSON_AddNumberToObject(cap, "recorded", r->n_recorded);
    }
    app_json_map(o, &r->out, a->rcfg.fusion.max_level);
    app_store_json(o, &r->store);
    json_stream(o, a, r);
    cJSON_AddNumberToObject(o, "views", r->n_views);
    json_startup(o, r);
    cJSON_AddNumberToObject(o, "seconds", r->seconds);
    return o;
}

static bf_status write_view(recon *rc, const char *out_dir, uint32_t index, const bf_se3 *T_wc)
{
    char dir[4096], name[64], path[4096];
    render_images im = {0};
    bf_status s = bf_path_join(dir, sizeof dir, out_dir, "views");
    if (s == BF_OK) s = bf_mkdir_p(dir);
    if (s == BF_OK) s = recon_render_view(rc, T_wc);
    if (s == BF_OK) s = render_download(recon_caster(rc), &im);
    snprintf(name, sizeof name, "%06u.png", index);
    if (s == BF_OK) s = bf_path_join(path, sizeof path, dir, name);
    if (s == BF_OK) s = replay_png_write_rgb8(path, im.rgb, im.width, im.height);
    render_images_free(&im);
    return s;
}

static void csv_frame(bf_out *csv, const bf_frame *f, const recon_frame_result *fr)
{
    bool ran = recon_state_ran_icp(fr->state);
    bf_out_printf(csv, "%u,%.6f,%s,%s,%d,%u,%u,%.4f,%.3f,%.3g,%.3f,%.3f,%.3f,%.3f,%u,%s,%u,%.3f,%.3f,%.3f,%d,%d,%d\n", f->index, f->t_depth_s,
            recon_state_name(fr->state), ran ? track_outcome_name(fr->track.outcome) : "",
            ran ? (int)fr->track.degenerate : 0, fr->n_valid, ran ? fr->track.n_inliers : 0,
            ran ? fr->track.inlier_frac : 0.0, ran ? 1e3 * fr->track.residual_m : 0.0,
            ran ? fr->track.eig_min / (fr->track.eig_max > 0 ? fr->track.eig_max : 1) : 0.0, fr->ms_frame,
            fr->ms_track, fr->ms_raycast, fr->fuse.alloc + fr->fuse.subcache + fr->fuse.window + fr->fuse.colour, fr->reloc_tried,
            recon_reloc_kind_name(fr->reloc), ran ? fr->track.iterations : 0, ran ? fr->track.residual_sigma : 0.0,
            fr->ms_stream, ran ? fr->track.photo_sharpness : 0.0, ran ? (int)fr->track.photo_dropped : 0,
            ran ? (int)fr->track.photo_weak : 0, (int)fr->fused);
}

/* What the replay writes per frame beside the runner's own records. */
typedef struct replay_sink {
    const replay_args *a;
    bf_out *csv;
    replay_log_writer *log; /* live --record, else NULL */
    replay_result *r;
    view_window *win;       /* --view, else NULL */
    volatile sig_atomic_t *stop; /* --view: set when the window closes (live: the signal flag) */
    uint32_t n_shown;
    double t_stats_s;       /* when the title's map size was last read */
    double t_cast_s;        /* when the window's image was last cast (its end) */
    double cast_s;          /* how long that cast and show took */
    bf_se3 T_shown;         /* the pose it was cast at */
    uint64_t n_bricks;
    app_write_failure wf;   /* an output that failed mid-scan: the scan stopped there */
} replay_sink;

/* The window's frame: the map at the window's camera (the frame's pose
 * while following, so the view just written serves), the state in the
 * title; a closed window or --exit-after frames shown stop the scan. */
static bf_status show_frame(replay_sink *k, recon_run *run, const recon_frame_result *fr, bool has_view)
{
    view_window *w = k->win;
    view_follow(w, &fr->T_wc);
    if (!view_poll(w)) {
        app_stop_request(k->stop);
        return BF_OK;
    }
    bf_se3 T = view_pose(w);
    bf_status s = BF_OK;
    /* A cast is the loop's time: while following, one every --view-period
     * and at most a fifth of the loop's time (the next waits 4 times as
     * long as the last took; the view PNG just written is free); a camera
     * moved by hand, every frame; --exit-after, every frame (its screenshot
     * is that frame). */
    bool is_free = has_view && view_is_following(w);
    bool is_moved = !view_is_following(w) && memcmp(&T, &k->T_shown, sizeof T) != 0;
    bool is_due = k->a->exit_after || is_free || is_moved || k->t_cast_s == 0 ||
                  bf_time_s() - k->t_cast_s >= fmax(k->a->view_period_s, 4 * k->cast_s);
    if (!is_due) {
        view_status vs = {.has_frame = true, .frame = run->est.n, .state = recon_state_name(fr->state),
                          .n_bricks = k->n_bricks};
        view_set_status(w, &vs); /* the title keeps counting */
        return BF_OK;
    }
    double t0 = bf_time_s();
    if (!is_free) s = recon_render_view(run->loop, &T);
    k->T_shown = T;
    /* The map's size costs a download of the pools: read it at most every 2 s. */
    if (s == BF_OK && (k->t_stats_s == 0 || bf_time_s() - k->t_stats_s > 2.0)) {
        fusion_stats st;
        if (fusion_get_stats(run->map, &st) == BF_OK) k->n_bricks = st.n_bricks;
        k->t_stats_s = bf_time_s();
    }
    view_status vs = {.has_frame = true, .frame = run->est.n, .state = recon_state_name(fr->state),
                      .n_bricks = k->n_bricks};
    view_set_status(w, &vs);
    render_caster *caster = s == BF_OK ? recon_caster(run->loop) : NULL;
    if (s == BF_OK && !caster) {
        char why[512];
        snprintf(why, sizeof why, "%s", bf_last_error()); /* bf_fail writes the same buffer */
        s = bf_fail(BF_NO_MEMORY, "view: the loop has no caster: %s", why);
    }
    bool is_last = k->a->exit_after && k->n_shown + 1 == k->a->exit_after, is_shown = false;
    uint8_t *rgb = NULL;
    uint32_t vw = 0, vh = 0;
    view_size(w, &vw, &vh);
    if (s == BF_OK && is_last && k->a->screenshot && !(rgb = malloc(3ull * vw * vh)))
        s = bf_fail(BF_NO_MEMORY, "view: screenshot");
    if (s == BF_OK) s = view_show(w, render_get_targets(caster), rgb, &is_shown);
    k->t_cast_s = bf_time_s();
    k->cast_s = k->t_cast_s - t0;
    if (s == BF_OK && is_shown && ++k->n_shown == k->a->exit_after) {
        if (rgb) s = replay_png_write_rgb8(k->a->screenshot, rgb, vw, vh);
        app_stop_request(k->stop);
    }
    free(rgb);
    return s;
}

/* The scan ended before --exit-after frames were shown (a short sequence, a
 * stop): --screenshot is the map cast once more from the window's camera,
 * so a script that asked for one still gets it. */
static bf_status final_screenshot(replay_sink *k, recon_run *run)
{
    view_window *w = k->win;
    bf_se3 T = view_pose(w);
    bf_status s = recon_render_view(run->loop, &T);
    render_caster *caster = s == BF_OK ? recon_caster(run->loop) : NULL;
    if (s == BF_OK && !caster) s = bf_fail(BF_NO_MEMORY, "view: the loop has no caster");
    uint32_t vw = 0, vh = 0;
    view_size(w, &vw, &vh);
    uint8_t *rgb = s == BF_OK ? malloc(3ull * vw * vh) : NULL;
    if (s == BF_OK && !rgb) s = bf_fail(BF_NO_MEMORY, "view: screenshot");
    bool is_shown = false;
    if (s == BF_OK) s = view_show(w, render_get_targets(caster), rgb, &is_shown);
    if (s == BF_OK && !is_shown) s = bf_fail(BF_WRITE, "%s: the window showed no frame to read back", k->a->screenshot);
    if (s == BF_OK) s = replay_png_write_rgb8(k->a->screenshot, rgb, vw, vh);
    if (s == BF_OK)
        bf_warn("--exit-after %u: the scan ended after %u frame%s shown; %s is the map at its end", k->a->exit_after,
                k->n_shown, app_s(k->n_shown), k->a->screenshot);
    free(rgb);
    return s;
}

/* An output that cannot be written mid-scan (a view, the store, the log,
 * frames.csv) stops the scan as Ctrl-C does, so that what was reconstructed
 * so far is still written (docs/faults.md); the exit code reports it. */
static bf_status stop_on_write_failure(replay_sink *k, bf_status s)
{
    if (s != BF_WRITE) return s;
    const char *cmd = k->a->is_live_cmd ? "live" : "replay";
    bf_warn("%s: the scan stops here: an output cannot be written", cmd);
    app_stop_request(k->stop);
    return app_note_write(&k->wf, cmd, s);
}

static bf_status on_frame(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    replay_sink *k = user;
    if (k->wf.s != BF_OK) return BF_OK; /* stopping: the frame the stop found in flight */
    bf_status s = BF_OK;
    csv_frame(k->csv, f, fr);
    if (k->csv->err) s = bf_fail(BF_WRITE, "%s: write failed: %s", k->csv->path, strerror(k->csv->err));
    if (s == BF_OK && k->log && (s = replay_log_writer_add(k->log, f)) == BF_OK) k->r->n_recorded++;
    /* Every K frames handled, not K indices: a live queue drops frames, and
     * indices that skip would miss most multiples of K. */
    bool has_view = false;
    if (s == BF_OK && k->a->view_every && (run->est.n - 1) % k->a->view_every == 0 &&
        (s = write_view(run->loop, k->a->out, f->index, &fr->T_wc)) == BF_OK) {
        k->r->n_views++;
        has_view = true;
    }
    if (s == BF_OK && k->win && run->loop) s = show_frame(k, run, fr, has_view);
    if (s == BF_OK) s = app_store_frame(&k->r->store, run, f);
    return stop_on_write_failure(k, s);
}

/* --reference: the surface voxels just written (points.ply) against the
 * true surface, as bitfuse demo scores the fused map (distances beyond
 * 0.5 m are left out: a stray voxel must not own the mean). */
static bf_status eval_fused_surface(const replay_args *a, replay_result *r)
{
    char path[4096];
    mesh_data pts = {0};
    bf_status s = bf_path_join(path, sizeof path, a->out, "points.ply");
    if (s == BF_OK) s = mesh_read_ply(path, &pts);
    eval_surface_config scfg = eval_surface_config_default();
    scfg.max_dist_m = 0.5;
    if (s == BF_OK) s = eval_surface(&a->ref, &pts, a->vis_path ? &a->vis : NULL, &scfg, &r->surf);
    r->has_surface = s == BF_OK;
    mesh_free(&pts);
    return s;
}

static void print_summary(const replay_args *a, const replay_result *r, const rgbd_source *src,
                          const app_write_failure *wf)
{
    const recon_counts *c = &r->run.counts;
    const recon_run_series *t = &r->run.series;
    printf("bitfuse %s: %u frame%s on %s: %u tracked (%u relocalised), %u lost, %u without depth (%u degenerate)\n",
           a->is_live_cmd ? "live" : "replay", c->frames, app_s(c->frames), r->device, c->tracked, c->relocalised, c->lost, c->no_depth,
           c->degenerate);
    if (c->last_frame)
        printf("  tracking         %u frame%s fitted the map weakly or not at all and %s tracked against the "
               "frame before %s\n", c->last_frame, app_s(c->last_frame), c->last_frame == 1 ? "was" : "were",
               c->last_frame == 1 ? "it" : "them");
    if (c->unfused)
        printf("  tracking         %u frame%s tracked only, not fused (--fuse-every, --fuse-every-behind; %u "
               "came while the loop was behind the camera)\n", c->unfused, app_s(c->unfused), c->behind);
    uint32_t unreadable = app_skipped_frames(src);
    if (unreadable) printf("  input            %u unreadable frame%s skipped\n", unreadable, app_s(unreadable));
    if (r->run.n_resume_skipped)
        printf("  input            %u frame%s at or before the stored scan's last time passed over as already in "
               "the store (--resume)\n", r->run.n_resume_skipped, app_s(r->run.n_resume_skipped));
    if (r->run.n_skipped)
        printf("  input            %u frame%s without a ground-truth pose skipped (--fuse-at-groundtruth)\n",
               r->run.n_skipped, app_s(r->run.n_skipped));
    if (c->repeated)
        printf("  input            %u frame%s repeated the depth before %s byte for byte: skipped, pose kept\n",
               c->repeated, app_s(c->repeated), c->repeated == 1 ? "it" : "them");
    if (c->colour_repeated)
        printf("  input            %u frame%s repeated only the colour before %s: tracked and fused without it\n",
               c->colour_repeated, app_s(c->colour_repeated), c->colour_repeated == 1 ? "it" : "them");
    if (c->photo_weak)
        printf("  photometric      %u frame%s whose depth left a direction weak %s held by %s colour\n", c->photo_weak,
               app_s(c->photo_weak), c->photo_weak == 1 ? "was" : "were", c->photo_weak == 1 ? "its" : "their");
    if (r->run.source_status != BF_OK)
        printf("  stopped early    %s: what came before it is kept\n", r->run.source_error);
    if (!r->has_capture && r->run.is_interrupted)
        printf("  stopped          by a signal or the window: the frames before it are written\n");
    if (r->has_capture)
        printf("  capture          %llu captured, %llu dropped by the queue of %u, %llu unread at the end%s\n",
               (unsigned long long)r->cap.captured, (unsigned long long)r->cap.dropped, a->queue,
               (unsigned long long)capture_unread(&r->cap),
               !r->run.is_interrupted ? ""
               : a->view                ? " (stopped by a signal, the window or --exit-after)"
                                        : " (stopped by a signal)");
    if (t->frame_ms.n == 0) /* a resumed scan with no new frame */
        printf("  time per frame   no frame processed\n");
    else {
        /* A stage that never ran (no frame tracked after the first) has no median: "-". */
        char m[7][16];
        const bf_stats *st[7] = {&t->track_ms, &t->rof_ms, &t->raycast_ms, &t->alloc_ms, &t->subcache_ms,
                                 &t->window_ms, &t->colour_ms};
        for (int i = 0; i < 7; i++)
            if (st[i]->n) snprintf(m[i], sizeof m[i], "%.1f", bf_stats_percentile(st[i], 50));
            else snprintf(m[i], sizeof m[i], "-");
        printf("  time per frame   median %.1f ms, p95 %.1f ms (GPU median: track %s, ROF %s, ray-cast %s,\n"
               "                   alloc %s, sub-cache %s, window %s, colour %s ms)\n",
               bf_stats_percentile(&t->frame_ms, 50), bf_stats_percentile(&t->frame_ms, 95), m[0], m[1], m[2], m[3],
               m[4], m[5], m[6]);
    }
    /* A resume passes over stored frames, --frames may stop before them,
     * a ground truth may miss some: the ATE then covers part of what
     * trajectory.txt holds, and says which part. */
    if (r->has_ate && r->ate.n_matched < r->run.est.n)
        printf("  trajectory       ATE RMSE %.4f m (median %.4f, max %.4f) over %zu of the %zu poses in trajectory.txt "
               "(those with a ground truth among the frames read)\n",
               r->ate.trans.rmse, r->ate.trans.median, r->ate.trans.max, r->ate.n_matched, r->run.est.n);
    else if (r->has_ate)
        printf("  trajectory       ATE RMSE %.4f m (median %.4f, max %.4f) over %zu pose%s\n", r->ate.trans.rmse,
               r->ate.trans.median, r->ate.trans.max, r->ate.n_matched, app_s(r->ate.n_matched));
    else if (r->ate_error[0])
        printf("  trajectory       ATE not computed: %s\n", r->ate_error);
    else
        printf("  trajectory       no ground truth: ATE not computed\n");
    if (r->has_surface && r->surf.accuracy.n == 0)
        printf("  true surface     no surface voxel of the map within 0.5 m of %s\n", a->ref_path);
    else if (r->has_surface)
        printf("  true surface     map median %.1f mm, p90 %.1f mm from %s; %.1f%% of the %s surface within 1 cm of "
               "the map\n",
               1e3 * r->surf.accuracy.median, 1e3 * r->surf.accuracy.p90, a->ref_path, 100 * r->surf.completeness,
               r->surf.used_visible ? "seen" : "whole");
    app_print_map(&r->out, a->rcfg.fusion.max_level);
    app_store_print(&r->store);
    /* After a failed output the list would claim it: the failure instead. */
    char tail[96];
    if (wf->s != BF_OK)
        printf("  not written      %s%s in %.1f s\n", wf->message, app_write_failure_tail(wf, tail, sizeof tail),
               r->seconds);
    else {
        char files[128];
        app_mesh_file_list(&r->out, files, sizeof files);
        char views[64] = "";
        if (r->n_views) snprintf(views, sizeof views, ",views/ (%u image%s)", r->n_views, app_s(r->n_views));
        printf("  wrote            %s/{trajectory.txt,frames.csv,%spoints.ply,stats.json%s} in %.1f s\n", a->out, files,
               views, r->seconds);
    }
}

/* rmdir takes only empty folders, so whatever was written stays: the
 * store's chunks/, the store if this run made it, then --out if the store
 * was made inside an --out this run made. */
static void remove_unwritten_store(const char *store, bool made_store, bool had_out, const char *out)
{
    char chunks[4200];
    if (snprintf(chunks, sizeof chunks, "%s/chunks", store) < (int)sizeof chunks && rmdir(chunks) == 0 &&
        made_store && rmdir(store) == 0 && !had_out)
        (void)rmdir(out);
}

int app_reconstruct(const char *cmd, int argc, char **argv, bool is_live_cmd)
{
    replay_args a;
    int rc_args = parse_args(cmd, is_live_cmd, argc, argv, &a);
    if (rc_args) return rc_args < 0 ? APP_EXIT_OK : rc_args;
    double t_start = bf_time_s();
    replay_result r;
    memset(&r, 0, sizeof r);
    r.t_start_s = t_start;
    a.rcfg.has_views = a.view_every != 0;
    rgbd_source *src = NULL;
    gpu_context *ctx = NULL;
    replay_log_writer *log = NULL;
    static bf_out csv; /* 8 KiB of paths */
    bool has_csv = false;
    char path[4096];
    const volatile sig_atomic_t *stop = NULL;
    /* replay: set when the window closes or an output fails mid-scan */
    static volatile sig_atomic_t replay_stop;
    view_window *win = NULL;
    app_write_failure wf = {0};  /* outputs that failed: the others are still written */
    bf_status s_loop = BF_OK;    /* the loop failed mid-scan: the work done is still written */
    bool stopped_empty = false;  /* stopped before any frame with depth: no trajectory or map to write */
    char loop_error[BF_ERROR_CAP] = "";
    bool has_map = true;
    /* The input first: a missing one leaves no empty output folder. */
    bf_status s;
    if (is_live_cmd) {
        bool is_live = false;
        s = app_open_device(a.seq, &a.ropt, a.realtime, a.queue, &is_live, &src);
        r.has_capture = s == BF_OK;
        r.is_camera = s == BF_OK && is_live && !capture_is_recording_uri(a.seq);
        /* Ctrl-C ends the scan, not the program: what was seen is kept. */
        if (s == BF_OK) stop = app_stop_begin(src);
    } else {
        s = replay_open(a.seq, &a.ropt, &src);
        /* Ctrl-C or SIGTERM ends a replay's scan as a live one's: the
         * frames done are written, the store flushed, the spill removed. */
        if (s == BF_OK) stop = app_stop_begin(NULL);
    }
    bool signals_on = stop != NULL;
    if (s == BF_OK) s = app_calibration_apply(&a.cal, a.seq, src);
    if (s == BF_OK && a.depth_correction)
        s = app_depth_correction_check(a.depth_correction, &replay_depth_fix, src, &a.cal, a.seq);
    if (s == BF_OK && a.fuse_at_gt && !src->has_groundtruth)
        s = bf_fail(BF_FORMAT, "%s: --fuse-at-groundtruth, but the sequence has no ground truth", a.seq);
    if (s == BF_OK && a.cal.path) {
        a.rcfg.calibration = a.cal.cal; /* its colour camera at the frames' size */
        a.rcfg.has_calibration = true;
    }
    /* The window before any output: no display leaves no folder behind. */
    gpu_config gcfg = {0};
    if (s == BF_OK && a.view) {
        view_config vc = view_config_default();
        const bf_intrinsics *K = rgbd_source_intrinsics(src);
        vc.width = K->width, vc.height = K->height;
        vc.fx_px = K->fx_px;
        vc.title = is_live_cmd ? "bitfuse live" : "bitfuse replay";
        vc.is_following = true;
        vc.overlay = a.overlay;
        s = view_open(&vc, &gcfg, &win);
    }
    replay_stop = 0;
    if (!stop) stop = &replay_stop;
    /* The store is read (to resume) or claimed before anything is made. */
    bool made_store = a.store && !bf_file_exists(a.store);
    bool had_out = bf_file_exists(a.out); /* before a store inside it (--store DIR/store) makes it */
    if (s == BF_OK && a.store) s = app_store_open(&r.store, a.store, a.resume, a.store_every_s);
    /* Only a store this run made or opened is this run's to tidy (a refused
     * "already holds a scene store" must not lose that store's chunks/). */
    bool owns_store = (made_store && !r.store.lock_refused) || r.store.writer != NULL;
    /* A map without colour written over one with: its colour gone for good. */
    if (s == BF_OK && r.store.is_resumed && r.store.map.rgb565 && !a.rcfg.fusion.keep_colour)
        s = bf_fail(BF_INVALID_ARG, "%s: the store holds colour, which --colour off would drop for good: resume it "
                    "with colour", a.store);
    /* (from before the store: --store DIR/store makes DIR) */
    bool made_out = !had_out;
    if (s == BF_OK && !made_out) app_warn_earlier_run(cmd, a.out);
    if (s == BF_OK) s = bf_mkdir_p(a.out);
    if (s == BF_OK && made_out) app_signals_made_folder(a.out);
    if (s == BF_OK && made_store && r.store.writer) {
        char chunks[4200];
        app_signals_made_folder(a.store);
        if (snprintf(chunks, sizeof chunks, "%s/chunks", a.store) < (int)sizeof chunks) app_signals_made_folder(chunks);
    }
    if (s == BF_OK && a.record_path) {
        replay_log_config lc = {.colour = REPLAY_LOG_COLOUR_JPEG, .device = a.seq,
                                .has_groundtruth = src->has_groundtruth};
        s = replay_log_writer_create(a.record_path, rgbd_source_intrinsics(src), &lc, &log);
    }
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, a.out, "frames.csv")) == BF_OK)
        has_csv = (s = bf_out_open(&csv, path)) == BF_OK;
    if (has_csv)
        bf_out_printf(&csv, "index,t_depth_s,state,icp,degenerate,valid,inliers,inlier_frac,residual_mm,eig_ratio,"
                     "frame_ms,track_ms,raycast_ms,fuse_ms,reloc_tried,reloc_from,icp_iterations,residual_sigma,stream_ms,"
                     "photo_sharpness,photo_dropped,photo_weak,fused\n");
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_OK && win) s = view_attach(win, ctx);
    if (s == BF_OK && a.auto_budget) auto_budget(&a, ctx);
    if (s == BF_OK) {
        snprintf(r.device, sizeof r.device, "%s", gpu_device_name(ctx));
        snprintf(r.device_driver, sizeof r.device_driver, "%s", gpu_device(ctx)->driver_info);
        r.cache_loaded_bytes = gpu_pipeline_cache_loaded_bytes(ctx);
    }
    recon_resume_state rs;
    /* The stored map's geometry, in the config stats.json echoes too. */
    if (s == BF_OK && r.store.is_resumed) app_store_resume_config(&r.store, &rs, &a.rcfg);
    /* A camera's clock is its own (freenect's from power-on, V4L2's monotonic
     * one): its frames are all new, whatever their times; only a recording
     * resumed goes on after the frames the store has. */
    if (s == BF_OK && r.store.is_resumed && r.is_camera) rs.t_last_s = -INFINITY;
    if (s == BF_OK) {
        recon_run_config rcfg = {
            .loop = a.rcfg, .poses = a.fuse_at_gt ? RECON_POSES_TRACK_FUSE_GT : RECON_POSES_TRACK,
            /* A device failing or a corrupt frame mid-sequence keeps what was
             * reconstructed before it; the exit code still reports it. */
            .init_identity = a.init == 1, .keep_on_source_error = true, .name = a.seq,
            .label = cmd, .stop = stop, .depth_correction = a.depth_correction ? &replay_depth_fix : NULL,
            .depth_lens = app_calibration_depth_lens(&a.cal),
        };
        if (r.store.is_resumed) rcfg.resume = &rs;
        replay_sink sink = {.a = &a, .csv = &csv, .log = log, .r = &r, .win = win,
                            .stop = (volatile sig_atomic_t *)stop};
        s = app_input_status(recon_run_sequence(ctx, src, &rcfg, on_frame, &sink, &r.run), src, a.seq);
        app_pool_hint(cmd, s, a.auto_budget ? NULL : a.bricks_given ? "--bricks" : "--gpu-budget");
        /* Ctrl-C before any frame with depth came (a live camera still
         * warming up): no trajectory or map to write, and no failure (an
         * output that failed is one). BF_END skips the outputs below and
         * removes the folder this run made when nothing went into it. */
        if (s == BF_FORMAT && r.run.is_interrupted && sink.wf.s == BF_OK && !r.store.is_resumed &&
            r.run.counts.tracked == 0) {
            stopped_empty = true;
            s = BF_END;
        }
        if (s == BF_OK && win && a.screenshot && sink.n_shown < a.exit_after && r.run.loop && view_poll(win))
            s = app_note_write(&sink.wf, cmd, final_screenshot(&sink, &r.run));
        if (sink.wf.s != BF_OK) {
            wf = sink.wf;
            r.run.is_interrupted = false; /* the stop was ours, not a signal's */
        }
        /* Every frame at or before the stored scan's end: nothing new (another
         * sequence than the store's, or one it has scanned to its end). Not
         * when the source failed after them: the frames it could not read are
         * the news, reported as the input's error. */
        if (s == BF_OK && r.store.is_resumed && r.run.counts.frames == 0 && r.run.n_resume_skipped > 0 &&
            r.run.n_skipped == 0 && r.run.source_status == BF_OK)
            bf_warn("%s: all %u frames of %s are at or before the stored scan's last time (t = %.6f s): nothing new "
                    "to scan (the sequence the store was made from, scanned to its end?)", cmd,
                    r.run.n_resume_skipped, a.seq, rs.t_last_s);
        /* The loop failing mid-scan (a lost device, out of memory, the
         * stream's spill folder not writable): the trajectory so far is
         * host data and is written, the map too when it can still be read
         * back; the exit code reports the failure. */
        if ((s == BF_VULKAN || s == BF_NO_MEMORY || s == BF_WRITE) && r.run.est.n > 0) {
            s_loop = s;
            snprintf(loop_error, sizeof loop_error, "%s", bf_last_error());
            bf_warn("%s: %s: the scan stops after %zu frames; writing what was reconstructed", cmd, loop_error,
                    r.run.est.n);
            s = BF_OK;
        }
    }
    if (r.has_capture) r.cap = capture_threaded_stats(src);
    if (signals_on) app_stop_end();
    if (log) {
        bf_status s_log = replay_log_writer_finish(log);
        if (s == BF_OK) s = app_note_write(&wf, cmd, s_log);
        else if (stopped_empty && s_log != BF_OK) stopped_empty = false, s = s_log;
    }
    /* The trajectory first: it is what a crashed export must not lose. */
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, a.out, "trajectory.txt")) == BF_OK)
        s = app_note_write(&wf, cmd, replay_traj_write_tum(path, &r.run.est));
    /* Then the store: the whole map at the end (or at Ctrl-C). */
    if (s == BF_OK && a.store) s = app_note_write(&wf, cmd, app_store_finish(&r.store, &r.run));
    if (s == BF_OK && r.run.gt.n >= 2 && eval_ate(&r.run.gt, &r.run.est, 0, &r.ate) == BF_OK) r.has_ate = true;
    else if (s == BF_OK && r.run.gt.n == 1)
        snprintf(r.ate_error, sizeof r.ate_error, "one frame with a ground-truth pose: an ATE needs two");
    else if (s == BF_OK && r.run.gt.n >= 2)
        snprintf(r.ate_error, sizeof r.ate_error, "%s", bf_last_error());
    hostmap whole = {0};
    if (s == BF_OK && r.run.loop) s = recon_snapshot(r.run.loop, &whole);
    if (s == BF_OK)
        s = app_note_write(&wf, cmd,
                           app_export_map(r.run.map, r.run.loop ? &whole : NULL, a.out, a.no_mesh ? NULL : &a.mesh_out,
                                          &r.out));
    app_note_mesh_refused(&wf, &r.out);
    hostmap_free(&whole);
    if (s_loop != BF_OK && s != BF_OK) {
        /* The device did not answer for the map: the trajectory stays. */
        bf_warn("%s: the map could not be read back (%s): only the trajectory is written", cmd, bf_last_error());
        s = BF_OK;
        has_map = false;
    }
    if (s == BF_OK && has_map && a.ref_path) s = eval_fused_surface(&a, &r);
    r.seconds = bf_time_s() - t_start;
    /* The gate: its outcome goes into stats.json too, and the exit code
     * says it (after everything is written). */
    char moved[2048] = "";
    uint32_t n_moved = 0;
    if (s == BF_OK && has_map) {
        cJSON *o = stats_json(&a, &r, src);
        if (wf.s != BF_OK) cJSON_AddStringToObject(o, "output_error", wf.message);
        if (s_loop != BF_OK) cJSON_AddStringToObject(o, "scan_error", loop_error);
        if (a.expect.baseline) n_moved = app_expect_check(&a.expect, o, moved, sizeof moved);
        s = app_note_write(&wf, cmd, app_json_write_in(a.out, "stats.json", o));
    }
    if (has_csv && s == BF_OK) {
        s = app_note_write(&wf, cmd, bf_out_commit(&csv));
        has_csv = false;
    }
    if (has_csv) bf_out_abort(&csv);
    /* A run that wrote nothing (no device, a failure at start-up) leaves
     * no empty folder it made behind; rmdir takes only an empty one. */
    if (s != BF_OK && made_out) (void)rmdir(a.out);
    /* An output that could not be written leaves the run's results to say
     * (the summary names the failure instead of the files written). */
    if (s == BF_OK && has_map && s_loop == BF_OK) print_summary(&a, &r, src, &wf);
    bf_status s_dev = r.run.source_status;
    if (s == BF_OK && s_dev != BF_OK) bf_fail(s_dev, "%s", r.run.source_error);
    replay_log_writer_destroy(log);
    app_store_close(&r.store);
    view_detach(win);
    recon_run_free(&r.run);
    gpu_context_destroy(ctx);
    view_destroy(win);
    rgbd_source_close(src);
    app_expect_free(&a.expect);
    mesh_free(&a.ref);
    mesh_free(&a.vis);
    /* A run that failed or was stopped before its new store got a write (a
     * corrupt first frame, a failure at start-up) leaves no empty store
     * behind: a bare chunks/ reads as a store, and the next run would be
     * refused ("already holds a scene store: resume it"). */
    /* (A first write that failed, a full disk, renamed none of its files: the same.) */
    bool store_unwritten = r.store.end_failed && r.store.stats.writes == 0;
    if ((s != BF_OK || stopped_empty || store_unwritten) && a.store && !a.resume && owns_store)
        remove_unwritten_store(a.store, made_store, had_out, a.out);
    /* The first failure decides the exit code: a GPU or output failure
     * mid-scan, else a later one, else the source's. */
    if (stopped_empty) {
        printf("bitfuse %s: stopped before any frame with depth: no trajectory or map written\n", cmd);
        return APP_EXIT_OK;
    }
    if (s == BF_OK && s_loop != BF_OK) s = bf_fail(s_loop, "%s", loop_error);
    else if (s == BF_OK) s = app_write_status(&wf);
    if (s == BF_OK && s_dev != BF_OK) return app_fail(cmd, s_dev);
    if (s == BF_OK && n_moved) {
        fprintf(stderr, "bitfuse %s: %u measure%s moved beyond tolerance against %s: %s\n", cmd, n_moved,
                n_moved > 1 ? "s" : "", a.expect_path, moved);
        return APP_EXIT_FAILURE;
    }
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}

int cmd_replay(int argc, char **argv) { return app_reconstruct("replay", argc, argv, false); }
