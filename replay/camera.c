/* replay: camera presets, --camera specifications and camera.txt. */
#include "replay_int.h"

#include <math.h>
#include <string.h>

/* TUM RGB-D's published depth-camera calibration per sensor
 * (vision.in.tum.de/data/datasets/rgbd-dataset/file_formats), and
 * ICL-NUIM's virtual camera (Handa et al. 2014), whose fy is negative. */
typedef struct camera_preset {
    const char *name;
    double fx, fy, cx, cy;
} camera_preset;

static const camera_preset presets[] = {
    {"fr1", 517.3, 516.5, 318.6, 255.3},
    {"fr2", 520.9, 521.0, 325.1, 249.7},
    {"fr3", 535.4, 539.2, 320.1, 247.6},
    {"icl", 481.2, -480.0, 319.5, 239.5},
};

bf_status replay_parse_camera(const char *spec, bf_intrinsics *K)
{
    if (!spec) return bf_fail(BF_INVALID_ARG, "--camera: missing value");
    for (size_t i = 0; i < sizeof presets / sizeof presets[0]; i++)
        if (!strcmp(spec, presets[i].name)) {
            K->fx_px = presets[i].fx;
            K->fy_px = presets[i].fy;
            K->cx_px = presets[i].cx;
            K->cy_px = presets[i].cy;
            return BF_OK;
        }
    double v[4];
    char buf[256];
    if (strlen(spec) >= sizeof buf) return bf_fail(BF_INVALID_ARG, "--camera: value too long");
    strcpy(buf, spec);
    int n = 0;
    char *save = NULL;
    for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (n == 4 || !bf_parse_double(tok, &v[n]))
            return bf_fail(BF_INVALID_ARG,
                           "--camera '%s': expected fr1, fr2, fr3, icl or four numbers fx,fy,cx,cy", spec);
        n++;
    }
    if (n != 4)
        return bf_fail(BF_INVALID_ARG, "--camera '%s': expected fr1, fr2, fr3, icl or four numbers fx,fy,cx,cy",
                       spec);
    if (v[0] == 0 || v[1] == 0)
        return bf_fail(BF_INVALID_ARG, "--camera '%s': focal lengths must not be zero", spec);
    K->fx_px = v[0];
    K->fy_px = v[1];
    K->cx_px = v[2];
    K->cy_px = v[3];
    return BF_OK;
}

bf_status replay__camera_txt_read(const char *path, bf_intrinsics *K)
{
    replay__text t;
    bf_status s = replay__text_open(&t, path);
    if (s != BF_OK) return s;
    char *f[6];
    int n = replay__text_next(&t, f, 6);
    double v[5] = {0, 0, 0, 0, 0};
    static const char *const names[5] = {"fx", "fy", "cx", "cy", "depth_scale"};
    if (n < 4 || n > 5) {
        s = n < 0 ? bf_fail(BF_FORMAT, "%s: empty, expected 'fx fy cx cy depth_scale'", path)
                  : bf_fail(BF_FORMAT, "%s:%u: expected 'fx fy cx cy depth_scale', found %d fields", path, t.line, n);
        goto done;
    }
    for (int k = 0; k < n; k++)
        if ((s = replay__text_double(&t, f[k], names[k], &v[k]))) goto done;
    if (v[0] == 0 || v[1] == 0) {
        s = bf_fail(BF_FORMAT, "%s:%u: focal lengths must not be zero", path, t.line);
        goto done;
    }
    if (n == 5 && !(v[4] > 0)) {
        s = bf_fail(BF_FORMAT, "%s:%u: depth_scale must be positive", path, t.line);
        goto done;
    }
    if (replay__text_next(&t, f, 6) >= 0) {
        s = bf_fail(BF_FORMAT, "%s:%u: expected one line", path, t.line);
        goto done;
    }
    K->fx_px = v[0];
    K->fy_px = v[1];
    K->cx_px = v[2];
    K->cy_px = v[3];
    if (n == 5) K->depth_scale = v[4];
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
        if ((s = replay__camera_txt_read(path, &K))) return s;
        cam->K = K;
        cam->origin = "camera.txt";
    }
    if (opt->camera) {
        if ((s = replay_parse_camera(opt->camera, &cam->K))) return s;
        cam->origin = "--camera";
    }
    if (opt->depth_scale > 0) cam->K.depth_scale = opt->depth_scale;
    return BF_OK;
}
