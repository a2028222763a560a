/* bitfuse synth: render a synthetic RGB-D sequence with ground truth. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "synth/synth.h"
#include "replay/replay.h"

static const char synth_help[] =
    "usage: bitfuse synth --trajectory TUM_TRAJ --frames N --out DIR [options]\n"
    "\n"
    "Renders depth and colour along a trajectory with a CPU ray tracer and writes a TUM\n"
    "RGB-D folder: rgb/, depth/ (16-bit, 5000 per metre), rgb.txt, depth.txt,\n"
    "groundtruth.txt (the poses rendered), camera.txt, scene.ply (reference mesh, world\n"
    "frame), seen.ply (surface points the camera saw with valid depth), stats.json.\n"
    "\n"
    "options:\n"
    "  --scene room|MESH.ply   procedural room (default) or one mesh\n"
    "  --trajectory FILE       TUM trajectory the camera follows (required); it is moved\n"
    "                          rigidly so its first pose looks at the scene\n"
    "  --frames N              frames to render (required); fewer if the trajectory ends\n"
    "  --rate HZ               frame rate along the trajectory's time, default 30\n"
    "  --noise kinect1|none    depth noise model, default kinect1 (Nguyen et al. 2012)\n"
    "  --seed S                noise seed, default 1\n"
    "  --out DIR               output folder (required)\n"
    "  --camera fx,fy,cx,cy    intrinsics, default 525,525,319.5,239.5 (or fr1|fr2|fr3)\n"
    "  --size WxH              image size, default 640x480\n"
    "  --data DIR              shared data folder with meshes/ for the room; default\n"
    "                          ../shared/data beside the source tree or the current folder\n"
    "  --scale S               multiply a MESH.ply scene's coordinates by S (to metres)\n"
    "  --seen-cell M           grid of seen.ply in metres, default 0.005\n"
    "\n"
    "Threads: BITFUSE_THREADS (default: all cores). See docs/synth.md.\n";

static bool parse_u64(const char *s, uint64_t *out)
{
    char *end;
    if (!s[0] || s[0] == '-') return false;
    unsigned long long v = strtoull(s, &end, 10);
    if (*end) return false;
    *out = v;
    return true;
}

int cmd_synth(int argc, char **argv)
{
    const char *cmd = "synth";
    synth_config cfg = {.scene = "room", .noise = SYNTH_NOISE_KINECT1, .seed = 1};
    const char *data_dir = NULL;
    bool has_frames = false;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (app_is_help(a)) {
            fputs(synth_help, stdout);
            return APP_EXIT_OK;
        }
        if (strncmp(a, "--", 2)) return app_usage_error(cmd, "unexpected argument '%s'", a);
        static const char *const known[] = {"--scene", "--trajectory", "--out",   "--data",  "--frames",
                                            "--rate",  "--noise",      "--seed",  "--camera", "--size",
                                            "--scale", "--seen-cell"};
        bool is_known = false;
        for (size_t k = 0; k < sizeof known / sizeof known[0]; k++) is_known |= !strcmp(a, known[k]);
        if (!is_known) return app_usage_error(cmd, "unknown option '%s'", a);
        if (i + 1 >= argc) return app_usage_error(cmd, "%s needs a value", a);
        const char *v = argv[++i];
        if (!strcmp(a, "--scene")) {
            cfg.scene = v;
        } else if (!strcmp(a, "--trajectory")) {
            cfg.traj_path = v;
        } else if (!strcmp(a, "--out")) {
            cfg.out_dir = v;
        } else if (!strcmp(a, "--data")) {
            data_dir = v;
        } else if (!strcmp(a, "--frames")) {
            if (!bf_parse_u32(v, &cfg.n_frames) || cfg.n_frames == 0)
                return app_usage_error(cmd, "--frames wants a positive integer, not '%s'", v);
            has_frames = true;
        } else if (!strcmp(a, "--rate")) {
            if (!bf_parse_double(v, &cfg.rate_hz) || !(cfg.rate_hz > 0) || cfg.rate_hz > 1e5)
                return app_usage_error(cmd, "--rate wants a frequency in Hz, not '%s'", v);
        } else if (!strcmp(a, "--noise")) {
            if (!strcmp(v, "kinect1"))
                cfg.noise = SYNTH_NOISE_KINECT1;
            else if (!strcmp(v, "none"))
                cfg.noise = SYNTH_NOISE_NONE;
            else
                return app_usage_error(cmd, "--noise is kinect1 or none, not '%s'", v);
        } else if (!strcmp(a, "--seed")) {
            if (!parse_u64(v, &cfg.seed)) return app_usage_error(cmd, "--seed wants an integer, not '%s'", v);
        } else if (!strcmp(a, "--camera")) {
            if (replay_parse_camera(v, &cfg.K)) return app_usage_error(cmd, "--camera: %s", bf_last_error());
            if (!(cfg.K.fx_px > 0) || !(cfg.K.fy_px > 0))
                return app_usage_error(cmd, "--camera: focal lengths must be positive");
        } else if (!strcmp(a, "--size")) {
            unsigned w, h;
            char tail;
            if (sscanf(v, "%ux%u%c", &w, &h, &tail) != 2 || w == 0 || h == 0 || w > 8192 || h > 8192)
                return app_usage_error(cmd, "--size wants WxH (e.g. 640x480), not '%s'", v);
            cfg.K.width = w;
            cfg.K.height = h;
        } else if (!strcmp(a, "--scale")) {
            if (!bf_parse_double(v, &cfg.mesh_scale) || !(cfg.mesh_scale > 0))
                return app_usage_error(cmd, "--scale wants a positive number, not '%s'", v);
        } else if (!strcmp(a, "--seen-cell")) {
            if (!bf_parse_double(v, &cfg.seen_cell_m) || !(cfg.seen_cell_m > 0))
                return app_usage_error(cmd, "--seen-cell wants a positive length in metres, not '%s'", v);
        } else {
            return app_usage_error(cmd, "unknown option '%s'", a);
        }
    }
    if (!cfg.traj_path) return app_usage_error(cmd, "--trajectory is required");
    if (!has_frames) return app_usage_error(cmd, "--frames is required");
    if (!cfg.out_dir) return app_usage_error(cmd, "--out is required");
    if (!strcmp(cfg.scene, "room")) {
        if (data_dir && !bf_file_exists(data_dir))
            return app_usage_error(cmd, "--data: folder '%s' does not exist", data_dir);
        cfg.data_dir = data_dir ? data_dir : app_default_data_dir();
        if (!cfg.data_dir) bf_info("synth: no shared data folder found: the room has no meshes");
    }
    synth_result res;
    bf_status s = synth_run(&cfg, &res);
    if (s) return app_fail(cmd, s);
    printf("synth: %u frames -> %s\n", res.n_frames, cfg.out_dir);
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
