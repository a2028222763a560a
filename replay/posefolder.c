/* replay: folders with one pose file per frame, as Microsoft's 7-Scenes
 * (Shotton et al. 2013) and 3DMatch (Zeng et al. 2017) ship them:
 * frame-NNNNNN.depth.png (16-bit millimetres, 65535 = no depth in 7-Scenes),
 * frame-NNNNNN.color.png|jpg, frame-NNNNNN.pose.txt (4x4 camera-to-world)
 * and camera-intrinsics.txt (3x3 K) in the folder or its parent. */
#include "replay_int.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

/* 7-Scenes' Kinect calibration, used when no camera-intrinsics.txt exists. */
static const bf_intrinsics sevenscenes_camera = {
    .fx_px = 585.0, .fy_px = 585.0, .cx_px = 320.0, .cy_px = 240.0, .depth_scale = 1000};

/* Parses camera-intrinsics.txt: three rows whose first three numbers form K
 * (the 3DMatch form; extra columns, e.g. a 3x4 or 4x4 matrix, are ignored),
 * nine numbers on one line (K row-major) or "fx fy cx cy". */
static bf_status intrinsics_read(const char *path, bf_intrinsics *K)
{
    replay__text t;
    bf_status s = replay__text_open(&t, path);
    if (s != BF_OK) return s;
    /* Up to 4 content lines of up to 16 numbers. */
    double v[4][16];
    int len[4] = {0}, rows = 0, n;
    uint32_t first_line = 0;
    char *f[16];
    while ((n = replay__text_next(&t, f, 16)) >= 0) {
        if (rows == 4 || n > 16) {
            s = bf_fail(BF_FORMAT, "%s:%u: expected a 3x3 camera matrix", path, t.line);
            goto done;
        }
        if (!first_line) first_line = t.line;
        for (int k = 0; k < n; k++)
            if ((s = replay__text_double(&t, f[k], "intrinsic", &v[rows][k]))) goto done;
        len[rows++] = n;
    }
    double M[3][3];
    if (rows == 1 && len[0] == 4) {
        K->fx_px = v[0][0], K->fy_px = v[0][1], K->cx_px = v[0][2], K->cy_px = v[0][3];
        goto check;
    }
    if (rows == 1 && len[0] == 9) {
        for (int k = 0; k < 9; k++) M[k / 3][k % 3] = v[0][k];
    } else if (rows >= 3 && len[0] >= 3 && len[1] >= 3 && len[2] >= 3) {
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) M[i][j] = v[i][j];
    } else {
        s = bf_fail(BF_FORMAT, "%s:%u: expected a 3x3 camera matrix (3 rows of 3 numbers), 9 numbers or fx fy cx cy",
                    path, first_line);
        goto done;
    }
    if (fabs(M[1][0]) > 1e-9 || fabs(M[2][0]) > 1e-9 || fabs(M[2][1]) > 1e-9 || fabs(M[2][2] - 1) > 1e-9) {
        s = bf_fail(BF_FORMAT, "%s:%u: not a camera matrix [fx s cx; 0 fy cy; 0 0 1]", path, first_line);
        goto done;
    }
    if (fabs(M[0][1]) > 1e-9) bf_warn("%s: skew %g ignored", path, M[0][1]);
    K->fx_px = M[0][0], K->fy_px = M[1][1], K->cx_px = M[0][2], K->cy_px = M[1][2];
check:
    /* fy < 0 is a y-up camera; fx < 0 would mirror the image. */
    if (!(K->fx_px > 0) || K->fy_px == 0)
        s = bf_fail(BF_FORMAT, "%s: fx must be positive and fy not zero (fx %g, fy %g)", path, K->fx_px, K->fy_px);
done:
    replay__text_close(&t);
    return s;
}

bf_status replay__pose_matrix_read(const char *path, bf_se3 *T_wc)
{
    /* Read into a stack buffer: called once per frame, allocates nothing. */
    char buf[4096];
    FILE *fp = fopen(path, "rb");
    if (!fp) return bf_fail(BF_IO, "%s: cannot open: %s", path, strerror(errno));
    size_t len = fread(buf, 1, sizeof buf - 1, fp);
    bool too_long = !feof(fp) && fgetc(fp) != EOF;
    fclose(fp);
    if (too_long) return bf_fail(BF_FORMAT, "%s: too long for a 4x4 pose matrix", path);
    buf[len] = '\0';
    bf_status sn = replay__text_nul(path, buf, len);
    if (sn != BF_OK) return sn;
    replay__text t = {.buf = NULL};
    replay__text_begin(&t, path, buf);
    double M[4][4] = {{0}};
    uint32_t row_line[4] = {0}; /* each row's line in the file (comments may come between) */
    int rows = 0, n;
    char *f[5];
    while ((n = replay__text_next(&t, f, 5)) >= 0) {
        if (rows == 4) return bf_fail(BF_FORMAT, "%s:%u: more than 4 rows in a 4x4 pose matrix", path, t.line);
        if (n != 4) return bf_fail(BF_FORMAT, "%s:%u: expected 4 numbers per row, found %d", path, t.line, n);
        for (int k = 0; k < 4; k++) {
            bf_status s = replay__text_double(&t, f[k], "pose entry", &M[rows][k]);
            if (s != BF_OK) return s;
        }
        row_line[rows++] = t.line;
    }
    if (rows < 3) return bf_fail(BF_FORMAT, "%s: expected a 4x4 pose matrix, found %d rows", path, rows);
    for (int i = 0; i < 3; i++)
        if (fabs(M[i][3]) > REPLAY_MAX_POSITION_M)
            return bf_fail(BF_FORMAT, "%s:%u: translation %g m is beyond 1e9 m (no camera's position)", path,
                           row_line[i], M[i][3]);
    if (rows == 4 && (fabs(M[3][0]) > 1e-6 || fabs(M[3][1]) > 1e-6 || fabs(M[3][2]) > 1e-6 ||
                      fabs(M[3][3] - 1) > 1e-6))
        return bf_fail(BF_FORMAT, "%s:4: last row of a rigid transform must be 0 0 0 1", path);
    /* Datasets store R rounded to a few digits: accept |R^T R - I| up to
     * 1e-2 and snap R to the nearest rotation via its quaternion. */
    double err = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0;
            for (int k = 0; k < 3; k++) d += M[k][i] * M[k][j];
            err = fmax(err, fabs(d - (i == j)));
        }
    double det = M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                 M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
    if (err > 1e-2 || det < 0)
        return bf_fail(BF_FORMAT, "%s: the 3x3 block is not a rotation (orthogonality error %.3g, det %.3g)", path,
                       err, det);
    double R[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) R[i][j] = M[i][j];
    *T_wc = bf_se3_from_qt(bf_quat_normalize(bf_quat_from_mat(R)), bf_v3(M[0][3], M[1][3], M[2][3]));
    return BF_OK;
}

static bf_status frame_path(replay__list *list, const char *dir, uint32_t k, const char *suffix, const char **out)
{
    char name[64], path[4096];
    snprintf(name, sizeof name, "frame-%06u.%s", k, suffix);
    bf_status s = bf_path_join(path, sizeof path, dir, name);
    if (s != BF_OK) return s;
    *out = replay__list_str(list, path);
    return *out ? BF_OK : BF_NO_MEMORY;
}

bf_status replay__posefolder_list(const char *dir, const replay_options *opt, replay__list *list,
                                  replay__camera *cam)
{
    cam->K = sevenscenes_camera;
    cam->origin = "7-Scenes default camera";
    char path[4096], parent[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, "camera-intrinsics.txt");
    if (s != BF_OK) return s;
    if (!bf_file_exists(path)) {
        /* 3DMatch keeps it next to the seq-NN folders. */
        if ((s = bf_path_join(parent, sizeof parent, dir, "../camera-intrinsics.txt"))) return s;
        if (bf_file_exists(parent)) strcpy(path, parent);
    }
    if (bf_file_exists(path)) {
        if ((s = intrinsics_read(path, &cam->K))) return s;
        cam->origin = "camera-intrinsics.txt";
    }
    if ((s = replay__camera_resolve(dir, opt, cam))) return s;
    list->depth_invalid = 65535;

    const char *colour_ext = NULL;
    for (uint32_t k = 0;; k++) {
        replay__frame_ref f = {0};
        if ((s = frame_path(list, dir, k, "depth.png", &f.depth_path))) return s;
        if (!bf_file_exists(f.depth_path)) break;
        if (k == 0) {
            const char *p;
            if ((s = frame_path(list, dir, 0, "color.png", &p))) return s;
            if (bf_file_exists(p)) colour_ext = "color.png";
            if ((s = frame_path(list, dir, 0, "color.jpg", &p))) return s;
            if (!colour_ext && bf_file_exists(p)) colour_ext = "color.jpg";
        }
        if (colour_ext && (s = frame_path(list, dir, k, colour_ext, &f.rgb_path))) return s;
        const char *pose;
        if ((s = frame_path(list, dir, k, "pose.txt", &pose))) return s;
        if (bf_file_exists(pose)) f.pose_path = pose;
        f.t_depth_s = f.t_rgb_s = (double)k / REPLAY_NUMBERED_FPS;
        if ((s = replay__list_push(list, &f))) return s;
    }
    return BF_OK;
}
