/* bitfuse eval-colour: a coloured mesh re-rendered at the input frames'
 * poses against their colour images (PSNR), the real-frame colour check
 * (docs/colour.md). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "calib/calib.h"
#include "eval/eval.h"
#include "mesh/mesh.h"
#include "replay/replay.h"

static const char usage_text[] =
    "usage: bitfuse eval-colour MESH SEQ --trajectory TRAJ [--every N] [--calibration calib.json] [--json]\n"
    "                           [--save DIR]\n"
    "\n"
    "Renders the coloured mesh MESH (replay's mesh.ply) at the pose TRAJ gives each\n"
    "N-th frame of the sequence SEQ (a TUM file matched by timestamp within 0.02 s; the\n"
    "run's own trajectory.txt, in whose frame the mesh is) and compares the rendering\n"
    "with the frame's colour image where the mesh is hit: PSNR per frame and over all.\n"
    "Without a calibration the colour image is taken as registered to depth (the\n"
    "depth camera renders); with one, the colour camera renders from T_colour_depth,\n"
    "through its lens.\n";

/* The pose of timestamp t in tr (nearest within 0.02 s). */
static bool pose_at(const bf_traj *tr, double t, bf_se3 *out)
{
    size_t best = SIZE_MAX;
    double bd = 0.02;
    for (size_t i = 0; i < tr->n; i++)
        if (fabs(tr->t_s[i] - t) < bd) bd = fabs(tr->t_s[i] - t), best = i;
    if (best == SIZE_MAX) return false;
    *out = tr->T_wc[best];
    return true;
}

/* The rendering (left) and the input (right) of frame i as one PNG. */
static bf_status save_pair(const char *dir, uint32_t i, const bf_intrinsics *K, const uint8_t *a, const uint8_t *b)
{
    bf_status s = bf_mkdir_p(dir);
    uint8_t *p = s == BF_OK ? malloc((size_t)K->width * 2 * K->height * 3) : NULL;
    if (s == BF_OK && !p) s = bf_fail(BF_NO_MEMORY, "eval-colour: image");
    if (s != BF_OK) return s;
    for (uint32_t v = 0; v < K->height; v++) {
        memcpy(p + ((size_t)v * K->width * 2) * 3, a + (size_t)v * K->width * 3, (size_t)K->width * 3);
        memcpy(p + ((size_t)v * K->width * 2 + K->width) * 3, b + (size_t)v * K->width * 3, (size_t)K->width * 3);
    }
    char path[4200];
    snprintf(path, sizeof path, "%s/colour_%06u.png", dir, i);
    s = replay_png_write_rgb8(path, p, K->width * 2, K->height);
    free(p);
    return s;
}

int cmd_eval_colour(int argc, char **argv)
{
    const char *cmd = "eval-colour", *paths[2] = {NULL, NULL}, *traj_path = NULL, *calib_path = NULL, *save = NULL;
    uint32_t every = 25;
    bool json = false;
    const app_option own[] = {
        APP_OPT("--trajectory", APP_OPT_STRING, &traj_path, "TRAJ", "camera poses of the frames (TUM)",
                .required = true),
        APP_OPT("--every", APP_OPT_U32, &every, "N", "compare every N-th frame", .min = 1),
        APP_OPT("--calibration", APP_OPT_STRING, &calib_path, "FILE",
                "calib.json: render from the colour camera (its intrinsics, T_colour_depth)", .no_default = true),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "machine-readable output on stdout"),
        APP_OPT("--save", APP_OPT_STRING, &save, "DIR",
                "write each compared frame's rendering and input side by side (DIR/colour_N.png)", .no_default = true),
        APP_OPT_END,
    };
    replay_options ropt = {0};
    app_option seq[APP_SEQUENCE_ROWS];
    app_sequence_options(seq, &ropt);
    const app_option *tables[] = {own, seq, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = usage_text, .tables = tables, .positional = paths, .min_positional = 2,
        .max_positional = 2, .positional_missing = "needs MESH and SEQ",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 the mesh or sequence unreadable or malformed, or the\n"
                  "mesh seen in none of the frames compared (poses or units wrong), 5 --save's images could not be\n"
                  "written\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;

    mesh_data m = {0};
    mesh_bvh *bvh = NULL;
    bf_traj tr = {0};
    /* With a calibration the colour is the colour camera's own image, never
     * resampled by the depth camera's lens (a TUM folder's preset). */
    app_calibration cal = {0};
    rc = calib_path ? app_calibration_read(cmd, calib_path, paths[1], false, &ropt, &cal) : APP_EXIT_OK;
    if (rc) return rc;
    rgbd_source *src = NULL;
    bf_status s = mesh_read_ply(paths[0], &m);
    if (s == BF_OK && (!m.rgb || m.n_tris == 0))
        s = bf_fail(BF_FORMAT, "%s: a mesh with vertex colour is needed", paths[0]);
    if (s == BF_OK) s = replay_traj_read_tum(traj_path, &tr);
    if (s == BF_OK) s = replay_open(paths[1], &ropt, &src);
    if (s == BF_OK) s = app_calibration_apply(&cal, paths[1], src); /* the colour camera at the frames' size */
    if (s != BF_OK) {
        rgbd_source_close(src);
        mesh_free(&m);
        bf_traj_free(&tr);
        return app_fail(cmd, s);
    }
    bf_intrinsics K = *rgbd_source_intrinsics(src);
    bf_se3 T_dc = bf_se3_identity(); /* colour camera to depth camera */
    const double *dist = NULL;       /* its lens */
    if (calib_path) {
        const calib_camera *c = &cal.cal.colour;
        K.fx_px = c->fx_px, K.fy_px = c->fy_px, K.cx_px = c->cx_px, K.cy_px = c->cy_px;
        dist = c->dist;
        if (cal.cal.has_depth) T_dc = bf_se3_inverse(&cal.cal.T_colour_depth);
    }
    if ((s = mesh_bvh_build(&m, &bvh)) != BF_OK) goto done;
    size_t n_px = (size_t)K.width * K.height;
    uint8_t *img = malloc(n_px * 3), *hit = malloc(n_px);
    if (!img || !hit) s = bf_fail(BF_NO_MEMORY, "eval-colour: images");
    eval_colour_sums all = {0};
    cJSON *frames = json ? cJSON_CreateArray() : NULL;
    uint32_t n_frames = 0, n_skipped = 0, n_no_colour = 0, n_unseen = 0;
    bf_frame f;
    while (s == BF_OK && (s = rgbd_source_next(src, &f)) == BF_OK) {
        if (f.index % every) continue;
        if (!f.rgb) {
            n_no_colour++;
            continue;
        }
        bf_se3 T_wc;
        if (!pose_at(&tr, f.t_depth_s, &T_wc)) {
            n_skipped++;
            continue;
        }
        bf_se3 T_wcol = bf_se3_mul(&T_wc, &T_dc);
        if ((s = eval_colour_render(&m, bvh, &K, dist, &T_wcol, img, hit)) != BF_OK) break;
        eval_colour_sums one = {0};
        eval_colour_compare(img, f.rgb, hit, n_px, &one);
        if (save && (s = save_pair(save, f.index, &K, img, f.rgb)) != BF_OK) break;
        all.sse += one.sse, all.n += one.n;
        n_frames++;
        n_unseen += one.n == 0; /* no pixel of it: in no score */
        double cover = (double)one.n / 3.0 / (double)n_px;
        if (frames) {
            cJSON *o = cJSON_CreateObject();
            cJSON_AddNumberToObject(o, "frame", f.index);
            cJSON_AddNumberToObject(o, "psnr_db", eval_colour_psnr(&one));
            cJSON_AddNumberToObject(o, "coverage", cover);
            cJSON_AddBoolToObject(o, "in_score", one.n > 0); /* a frame where the mesh is not seen is not */
            cJSON_AddItemToArray(frames, o);
        } else {
            printf("  frame %5u  PSNR %6.2f dB  (%.1f%% of the pixels hit)\n", f.index, eval_colour_psnr(&one),
                   100 * cover);
        }
    }
    if (s == BF_END) s = BF_OK;
    free(img);
    free(hit);
    if (s == BF_OK && n_frames == 0 && n_skipped == 0 && n_no_colour)
        s = bf_fail(BF_FORMAT, "%s: no frame every %u has colour", paths[1], every);
    else if (s == BF_OK && n_frames == 0)
        s = bf_fail(BF_FORMAT, "%s: no frame every %u with colour has a pose in %s", paths[1], every, traj_path);
    /* Nothing compared is no score (PSNR nan, exit 0): poses or units wrong. */
    if (s == BF_OK && all.n == 0)
        s = bf_fail(BF_FORMAT, "%s: the mesh is seen in none of the %u frames compared: do the poses of %s and the "
                    "mesh's units (metres) fit?", paths[0], n_frames, traj_path);
    if (s == BF_OK) {
        if (frames) {
            cJSON *o = cJSON_CreateObject();
            cJSON_AddStringToObject(o, "mesh", paths[0]);
            cJSON_AddStringToObject(o, "sequence", paths[1]);
            cJSON_AddNumberToObject(o, "frames", n_frames - n_unseen); /* those in the score */
            cJSON_AddNumberToObject(o, "frames_mesh_unseen", n_unseen);
            cJSON_AddNumberToObject(o, "frames_without_pose", n_skipped);
            cJSON_AddNumberToObject(o, "frames_without_colour", n_no_colour);
            cJSON_AddNumberToObject(o, "psnr_db", eval_colour_psnr(&all));
            cJSON_AddItemToObject(o, "per_frame", frames);
            frames = NULL;
            s = app_json_print(o);
        } else {
            printf("PSNR %.2f dB over %u frames (every %u; %u without a pose, %u without colour, %u where the mesh "
                   "is not seen)\n", eval_colour_psnr(&all), n_frames - n_unseen, every, n_skipped, n_no_colour,
                   n_unseen);
        }
    }
    cJSON_Delete(frames);
done:
    mesh_bvh_destroy(bvh);
    rgbd_source_close(src);
    mesh_free(&m);
    bf_traj_free(&tr);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
