/* bitfuse synth: render a synthetic RGB-D sequence with ground truth. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "synth/synth.h"
#include "replay/replay.h"

static const char synth_usage[] =
    "usage: bitfuse synth --trajectory TUM_TRAJ --frames N --out DIR [options]\n"
    "\n"
    "Renders depth and colour along a trajectory with a CPU ray tracer and writes a TUM\n"
    "RGB-D folder: rgb/, depth/ (16-bit, 5000 per metre), rgb.txt, depth.txt,\n"
    "groundtruth.txt (the poses rendered), camera.txt, scene.ply (reference mesh, world\n"
    "frame), seen.ply (surface points the camera saw with valid depth), stats.json.\n"
    "\n"
    "bitfuse synth --board COLSxROWS --out DIR [options] renders checkerboard views for\n"
    "bitfuse calibrate instead (bitfuse synth --board 9x6 --help).\n";

static const char board_usage[] =
    "usage: bitfuse synth --board COLSxROWS --out DIR [options]\n"
    "\n"
    "Renders views of a planar checkerboard (COLSxROWS inner corners) from varied poses, as\n"
    "the colour camera and the depth (IR) camera beside it see it, with known intrinsics,\n"
    "distortion and transform between them: the ground truth of bitfuse calibrate. Pixels\n"
    "an edge crosses are averaged over a grid of samples. Writes into DIR: colour/NNN.png,\n"
    "ir/NNN.png (8-bit grey), truth.json (the calibration that made them, calib.json's\n"
    "format) and board_poses.txt (TUM: view index, colour camera to board).\n";
/* --camera: a preset or fx,fy,cx,cy: fx positive, fy not zero (negative:
 * a y-up camera, as ICL-NUIM's, which the renderer draws as it is). */
static const char *check_camera(const char *name, const char *v)
{
    static char msg[512];
    bf_intrinsics K = {0};
    /* (replay's messages name --camera and its value already) */
    if (replay_parse_camera(v, &K) != BF_OK) snprintf(msg, sizeof msg, "%s", bf_last_error());
    else if (!(K.fx_px > 0) || K.fy_px == 0) snprintf(msg, sizeof msg, "%s: fx must be positive and fy not zero", name);
    else return NULL;
    return msg;
}

/* --size: WxH, each 16..8192: the tracker's three-level pyramid needs
 * 16 px a side, and a sequence is made to be replayed. */
static bool parse_size(const char *v, unsigned *w, unsigned *h)
{
    char tail;
    return sscanf(v, "%ux%u%c", w, h, &tail) == 2 && *w >= 16 && *h >= 16 && *w <= 8192 && *h <= 8192;
}

static const char *check_size(const char *name, const char *v)
{
    static char msg[512];
    unsigned w, h;
    if (parse_size(v, &w, &h)) return NULL;
    snprintf(msg, sizeof msg, "%s wants WxH, 16x16 to 8192x8192 (e.g. 640x480), not '%.400s'", name, v);
    return msg;
}

static const int noise_codes[] = {SYNTH_NOISE_KINECT1, SYNTH_NOISE_NONE};

/* --distortion: k1,k2,p1,p2,k3, each finite (fewer: the rest 0). */
static bool parse_dist(const char *v, double dist[CALIB_DIST_N])
{
    char buf[256];
    int n = 0;
    snprintf(buf, sizeof buf, "%s", v);
    if (!buf[0] || buf[strlen(buf) - 1] == ',') return false;
    char *save = NULL;
    double d[CALIB_DIST_N] = {0};
    for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (n == CALIB_DIST_N || !bf_parse_double(tok, &d[n])) return false;
        n++;
    }
    memcpy(dist, d, sizeof d);
    return n > 0;
}

static const char *check_dist(const char *name, const char *v)
{
    static char msg[512];
    double d[CALIB_DIST_N];
    if (parse_dist(v, d)) return NULL;
    snprintf(msg, sizeof msg, "%s wants k1[,k2[,p1,p2[,k3]]] (numbers), not '%.400s'", name, v);
    return msg;
}

static const char *check_board(const char *name, const char *v)
{
    static char msg[512];
    calib_board b;
    if (calib_parse_board(v, &b) == BF_OK) return NULL;
    snprintf(msg, sizeof msg, "%s: %s", name, bf_last_error());
    return msg;
}

/* Sets camera c from the --camera, --size and --distortion texts (checked). */
static void board_camera(calib_camera *c, const char *camera, const char *size, const char *dist)
{
    bf_intrinsics K = {0};
    unsigned w, h;
    if (camera && replay_parse_camera(camera, &K) == BF_OK)
        c->fx_px = K.fx_px, c->fy_px = K.fy_px, c->cx_px = K.cx_px, c->cy_px = K.cy_px;
    if (size && parse_size(size, &w, &h)) {
        /* The default camera at another size: the same field of view, its
         * principal point where it was in the image (as trajectory mode). */
        if (!camera) {
            double k = (double)w / c->width;
            c->fx_px *= k, c->fy_px *= k;
            c->cx_px = (c->cx_px + 0.5) * k - 0.5, c->cy_px = (c->cy_px + 0.5) * (double)h / c->height - 0.5;
        }
        c->width = w, c->height = h;
    }
    if (dist) parse_dist(dist, c->dist);
}

/* A principal point outside the image: a camera for another image size. */
static void warn_principal_point(const char *what, double cx, double cy, uint32_t w, uint32_t h)
{
    if (!(cx >= 0 && cx <= w && cy >= 0 && cy <= h))
        bf_warn("synth: the %s%scamera's principal point (%g, %g) lies outside its %ux%u images: is it for another "
                "image size?", what, what[0] ? " " : "", cx, cy, w, h);
}

static int cmd_synth_board(int argc, char **argv)
{
    const char *cmd = "synth";
    synth_board_config cfg = synth_board_config_default();
    const char *board = NULL, *camera = NULL, *size = NULL, *dist = NULL, *dcamera = NULL, *dsize = NULL,
               *ddist = NULL;
    const app_option own[] = {
        APP_OPT("--board", APP_OPT_STRING, &board, "COLSxROWS", "inner corners of the checkerboard (e.g. 9x6)",
                .required = true, .check = check_board),
        APP_OPT("--square", APP_OPT_DOUBLE, &cfg.board.square_m, "M", "edge of a square in metres", .min_open = true,
                .max = 1),
        APP_OPT("--views", APP_OPT_U32, &cfg.n_views, "N", "views to render", .min = 1, .max = 1000),
        APP_OPT("--out", APP_OPT_STRING, &cfg.out_dir, "DIR", "output folder", .required = true),
        APP_OPT("--camera", APP_OPT_STRING, &camera, "C",
                "colour intrinsics fx,fy,cx,cy or fr1|fr2|fr3|icl, default 525,525,319.5,239.5 at 640x480 (at another "
                "--size the same field of view)",
                .check = check_camera),
        APP_OPT("--size", APP_OPT_STRING, &size, "WxH", "colour image size, default 640x480", .check = check_size),
        APP_OPT("--distortion", APP_OPT_STRING, &dist, "K1,K2,P1,P2,K3",
                "colour lens distortion (OpenCV's model; missing ones 0), default none", .check = check_dist),
        APP_OPT("--depth-camera", APP_OPT_STRING, &dcamera, "C",
                "IR intrinsics, default 580,580,314.5,242.5 at 640x480 (at another --depth-size the same field of "
                "view)",
                .check = check_camera),
        APP_OPT("--depth-size", APP_OPT_STRING, &dsize, "WxH", "IR image size, default 640x480", .check = check_size),
        APP_OPT("--depth-distortion", APP_OPT_STRING, &ddist, "K1,K2,P1,P2,K3", "IR lens distortion, default none",
                .check = check_dist),
        APP_OPT("--supersample", APP_OPT_U32, &cfg.supersample, "N",
                "samples per pixel side where an edge crosses a pixel", .min = 1, .max = 32),
        APP_OPT("--image-noise", APP_OPT_DOUBLE, &cfg.noise_levels, "L",
                "sensor noise, standard deviation in grey levels", .max = 64),
        APP_OPT("--seed", APP_OPT_U64, &cfg.seed, "S", "seed of the poses and the noise"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {.name = cmd, .usage = board_usage, .tables = tables,
                             .epilog = "The colour camera sits 25 mm to the IR camera's right, turned 0.5 degrees "
                                       "(truth.json has it exactly).\nSee docs/calibration.md.\n"
                                       "exit codes: 0 ok, 2 usage (also a board that does not fit the images: "
                                       "nothing is written), 5 an output could not be written\n"};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    calib_parse_board(board, &cfg.board); /* checked above */
    board_camera(&cfg.colour, camera, size, dist);
    board_camera(&cfg.depth, dcamera, dsize, ddist);
    warn_principal_point("colour", cfg.colour.cx_px, cfg.colour.cy_px, cfg.colour.width, cfg.colour.height);
    warn_principal_point("depth", cfg.depth.cx_px, cfg.depth.cy_px, cfg.depth.width, cfg.depth.height);
    synth_board_result res;
    bf_status s = synth_board_run(&cfg, &res);
    if (s) return app_fail(cmd, s);
    printf("synth: %u views of a %ux%u board (%g m squares) -> %s/{colour,ir}/ in %.1f s\n", res.n_views,
           cfg.board.cols, cfg.board.rows, cfg.board.square_m, cfg.out_dir, res.seconds);
    printf("  truth        %s/truth.json\n", cfg.out_dir);
    return APP_EXIT_OK;
}

int cmd_synth(int argc, char **argv)
{
    const char *cmd = "synth";
    synth_config cfg = {.scene = "room", .noise = SYNTH_NOISE_KINECT1, .seed = 1, .rate_hz = 30, .seen_cell_m = 0.005,
                        .mesh_scale = 1, .version = BF_VERSION};
    const char *data_dir = NULL, *camera = NULL, *size = NULL;
    int noise = SYNTH_NOISE_KINECT1;
    bool scale_given = false, seed_given = false;
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--board") || !strncmp(argv[i], "--board=", 8)) return cmd_synth_board(argc, argv);
    const app_option own[] = {
        APP_OPT("--scene", APP_OPT_STRING, &cfg.scene, "room|rooms:N|MESH.ply",
                "procedural room, a row of N procedural rooms joined by doorways (4 m each along x), or one mesh"),
        APP_OPT("--trajectory", APP_OPT_STRING, &cfg.traj_path, "FILE",
                "TUM trajectory the camera follows; it is moved rigidly so its first pose looks at the scene",
                .required = true),
        APP_OPT("--frames", APP_OPT_U32, &cfg.n_frames, "N", "frames to render; fewer if the trajectory ends", .min = 1,
                .required = true, .no_default = true),
        APP_OPT("--rate", APP_OPT_DOUBLE, &cfg.rate_hz, "HZ", "frame rate along the trajectory's time", .max = 1e5,
                .min_open = true),
        APP_OPT("--noise", APP_OPT_ENUM, &noise, "kinect1|none", "depth noise model (Nguyen et al. 2012)",
                .codes = noise_codes),
        APP_OPT("--seed", APP_OPT_U64, &cfg.seed, "S", "noise seed", .given = &seed_given),
        APP_OPT("--out", APP_OPT_STRING, &cfg.out_dir, "DIR", "output folder", .required = true),
        APP_OPT("--camera", APP_OPT_STRING, &camera, "C",
                "intrinsics fx,fy,cx,cy or fr1|fr2|fr3|icl, default 525,525,319.5,239.5 at 640x480 (at another "
                "--size the same field of view: f = 525 W / 640, the principal point at the centre)",
                .check = check_camera),
        APP_OPT("--size", APP_OPT_STRING, &size, "WxH", "image size, default 640x480", .check = check_size),
        APP_OPT("--data", APP_OPT_STRING, &data_dir, "DIR",
                "shared data folder with meshes/ for the room; default ../shared/data beside the source tree or the "
                "current folder"),
        APP_OPT("--scale", APP_OPT_DOUBLE, &cfg.mesh_scale, "S",
                "multiply a MESH.ply scene's coordinates by S (to metres)",
                .min_open = true, .given = &scale_given),
        APP_OPT("--seen-cell", APP_OPT_DOUBLE, &cfg.seen_cell_m, "M", "grid of seen.ply in metres", .min_open = true),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {.name = cmd, .usage = synth_usage, .tables = tables,
                             .epilog = "Threads: BITFUSE_THREADS (default: all cores). See docs/synth.md.\n"
                                       "exit codes: 0 ok, 1 failure, 2 usage, 3 a mesh, trajectory or particle file "
                                       "unreadable, 5 an output\ncould not be written\n"};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    cfg.noise = (synth_noise)noise;
    /* Not over a sequence (frames past the new count would stay beside it,
     * unlisted), nor over a run's stats.json (convert refuses the same). */
    if ((rc = app_check_out_not_sequence(cmd, cfg.out_dir, true)) != 0) return rc;
    /* Options that would change nothing are refused, not ignored. */
    bool procedural = !strcmp(cfg.scene, "room") || !strncmp(cfg.scene, "rooms:", 6);
    if (scale_given && procedural)
        return app_usage_error(cmd, "--scale scales a MESH.ply scene's coordinates, not the procedural %s", cfg.scene);
    if (seed_given && cfg.noise == SYNTH_NOISE_NONE)
        return app_usage_error(cmd, "--seed seeds the noise: not with --noise none");
    if (camera) replay_parse_camera(camera, &cfg.K); /* checked above */
    unsigned w, h;
    if (size && parse_size(size, &w, &h)) cfg.K.width = w, cfg.K.height = h;
    if (camera)
        warn_principal_point("", cfg.K.cx_px, cfg.K.cy_px, cfg.K.width ? cfg.K.width : 640,
                             cfg.K.height ? cfg.K.height : 480);
    if (!strcmp(cfg.scene, "room")) {
        if (data_dir && !bf_file_exists(data_dir))
            return app_usage_error(cmd, "--data: folder '%s' does not exist", data_dir);
        cfg.data_dir = data_dir ? data_dir : app_default_data_dir();
        if (!cfg.data_dir) bf_info("synth: no shared data folder found: the room has no meshes");
    }
    synth_result res;
    bf_status s = synth_run(&cfg, &res);
    if (s) return app_fail(cmd, s);
    printf("synth: %u frame%s -> %s\n", res.n_frames, app_s(res.n_frames), cfg.out_dir);
    printf("  scene        %u triangles\n", res.n_scene_tris);
    printf("  render       %.3f s per frame (median %.3f), %.2f frames/s on %d threads\n", res.mean_frame_s,
           res.median_frame_s, res.mean_frame_s > 0 ? 1 / res.mean_frame_s : 0, bf_thread_count());
    printf("  end to end   %.1f s in all, %.3f s per frame (PNG encoding, scene and BVH included)\n", res.total_s,
           res.total_s / res.n_frames);
    printf("  valid depth  %.1f %% of pixels (noise %s, seed %llu)\n", 100 * res.valid_share,
           cfg.noise == SYNTH_NOISE_KINECT1 ? "kinect1" : "none", (unsigned long long)cfg.seed);
    printf("  seen.ply     %u points\n", res.n_seen);
    return APP_EXIT_OK;
}
