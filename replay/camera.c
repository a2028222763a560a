/* replay: camera presets, --camera specifications and camera.txt. */
#include "replay_int.h"

#include <math.h>
#include <string.h>

/* TUM RGB-D's published calibration per sensor
 * (vision.in.tum.de/data/datasets/rgbd-dataset/file_formats): the colour
 * camera's, to which the OpenNI driver registered the depth, with its
 * distortion d0..d4 (OpenCV's k1 k2 p1 p2 k3; fr3's images were undistorted
 * before publishing, so its are 0). ICL-NUIM's virtual camera (Handa et al.
 * 2014), whose fy is negative, has none. */
typedef struct camera_preset {
    const char *name;
    double fx, fy, cx, cy;
    double dist[CALIB_DIST_N];
} camera_preset;

static const camera_preset presets[] = {
    {"fr1", 517.3, 516.5, 318.6, 255.3, {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}},
    {"fr2", 520.9, 521.0, 325.1, 249.7, {0.2312, -0.7849, -0.0033, -0.0001, 0.9172}},
    {"fr3", 535.4, 539.2, 320.1, 247.6, {0, 0, 0, 0, 0}},
    {"icl", 481.2, -480.0, 319.5, 239.5, {0, 0, 0, 0, 0}},
};

#define CAMERA_EXPECTED "expected fr1, fr2, fr3, icl, fx,fy,cx,cy or fx,fy,cx,cy,k1,k2,p1,p2,k3"

bf_status replay_parse_camera_lens(const char *spec, bf_intrinsics *K, double dist[CALIB_DIST_N])
{
    if (!spec) return bf_fail(BF_INVALID_ARG, "--camera: missing value");
    for (size_t i = 0; i < sizeof presets / sizeof presets[0]; i++)
        if (!strcmp(spec, presets[i].name)) {
            K->fx_px = presets[i].fx;
            K->fy_px = presets[i].fy;
            K->cx_px = presets[i].cx;
            K->cy_px = presets[i].cy;
            memcpy(dist, presets[i].dist, sizeof presets[i].dist);
            return BF_OK;
        }
    double v[4 + CALIB_DIST_N] = {0};
    char buf[512];
    if (strlen(spec) >= sizeof buf) return bf_fail(BF_INVALID_ARG, "--camera: value too long");
    strcpy(buf, spec);
    int n = 0;
    char *save = NULL;
    for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (n == 4 + CALIB_DIST_N || !bf_parse_double(tok, &v[n]))
            return bf_fail(BF_INVALID_ARG, "--camera '%s': " CAMERA_EXPECTED, spec);
        n++;
    }
    if (n != 4 && n != 4 + CALIB_DIST_N) return bf_fail(BF_INVALID_ARG, "--camera '%s': " CAMERA_EXPECTED, spec);
    /* fy < 0 is a y-up camera (ICL-NUIM's); fx < 0 would mirror the image. */
    if (!(v[0] > 0) || v[1] == 0)
        return bf_fail(BF_INVALID_ARG, "--camera '%s': fx must be positive and fy not zero", spec);
    K->fx_px = v[0];
    K->fy_px = v[1];
    K->cx_px = v[2];
    K->cy_px = v[3];
    memcpy(dist, v + 4, CALIB_DIST_N * sizeof *dist);
    return BF_OK;
}

bf_status replay_parse_camera(const char *spec, bf_intrinsics *K)
{
    bf_intrinsics k = *K;
    double dist[CALIB_DIST_N];
    bf_status s = replay_parse_camera_lens(spec, &k, dist);
    if (s != BF_OK) return s;
    /* A preset's lens is dropped; a lens typed in numbers is not a pinhole. */
    if (strchr(spec, ',') && calib_has_distortion(dist))
        return bf_fail(BF_INVALID_ARG, "--camera '%s': a lens (distortion coefficients) is not applied here: give "
                                       "fr1, fr2, fr3, icl or fx,fy,cx,cy (a pinhole)", spec);
    *K = k;
    return BF_OK;
}

bf_status replay__camera_txt_read(const char *path, bf_intrinsics *K, double dist[CALIB_DIST_N])
{
    replay__text t;
    bf_status s = replay__text_open(&t, path);
    if (s != BF_OK) return s;
    enum { MAX_FIELDS = 5 + CALIB_DIST_N };
    char *f[MAX_FIELDS + 1];
    int n = replay__text_next(&t, f, MAX_FIELDS + 1);
    double v[MAX_FIELDS] = {0};
    static const char *const names[MAX_FIELDS] = {"fx", "fy", "cx", "cy", "depth_scale", "k1", "k2", "p1", "p2", "k3"};
    static const char expected[] = "'fx fy cx cy depth_scale' or 'fx fy cx cy depth_scale k1 k2 p1 p2 k3'";
    if (n < 4 || (n > 5 && n != MAX_FIELDS)) {
        s = n < 0 ? bf_fail(BF_FORMAT, "%s: empty, expected %s", path, expected)
                  : bf_fail(BF_FORMAT, "%s:%u: expected %s, found %d fields", path, t.line, expected, n);
        goto done;
    }
    for (int k = 0; k < n; k++)
        if ((s = replay__text_double(&t, f[k], names[k], &v[k]))) goto done;
    /* A negative fy is a y-up camera (ICL-NUIM's); a negative fx would
     * mirror the image, which no camera does. */
    if (!(v[0] > 0) || v[1] == 0) {
        s = bf_fail(BF_FORMAT, "%s:%u: fx must be positive and fy not zero (fx %g, fy %g)", path, t.line, v[0], v[1]);
        goto done;
    }
    /* The range --depth-scale takes: 1 raw unit a metre (a depth in metres
     * as integers) to 1e6 (micrometres). */
    if (n >= 5 && !(v[4] >= 1 && v[4] <= 1e6)) {
        s = bf_fail(BF_FORMAT, "%s:%u: depth_scale %g is not between 1 and 1e6 raw units per metre", path, t.line, v[4]);
        goto done;
    }
    if (replay__text_next(&t, f, MAX_FIELDS + 1) >= 0) {
        s = bf_fail(BF_FORMAT, "%s:%u: expected one line", path, t.line);
        goto done;
    }
    K->fx_px = v[0];
    K->fy_px = v[1];
    K->cx_px = v[2];
    K->cy_px = v[3];
    if (n >= 5) K->depth_scale = v[4];
    memcpy(dist, v + 5, CALIB_DIST_N * sizeof *dist);
done:
    replay__text_close(&t);
    return s;
}

bf_status replay__camera_resolve(const char *dir, const replay_options *opt, replay__camera *cam)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, "camera.txt");
    if (s != BF_OK) return s;
    if (bf_file_exists(path)) {
        bf_intrinsics K = cam->K;
        double dist[CALIB_DIST_N];
        if ((s = replay__camera_txt_read(path, &K, dist))) return s;
        cam->K = K;
        memcpy(cam->dist, dist, sizeof dist);
        cam->origin = "camera.txt";
        cam->is_from_name = false;
    }
    if (opt->camera) {
        if ((s = replay_parse_camera_lens(opt->camera, &cam->K, cam->dist))) return s;
        cam->origin = opt->camera_origin ? opt->camera_origin : "--camera";
        cam->is_from_option = true;
        cam->is_from_name = false;
    }
    if (opt->depth_scale > 0) cam->K.depth_scale = opt->depth_scale;
    return BF_OK;
}
