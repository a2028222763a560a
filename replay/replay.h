/* replay: file sources behind the rgbd_source interface (TUM RGB-D folders,
 * ICL-NUIM, pose-per-frame folders), the options every sequence-reading
 * command shares, image codecs (PNG, JPEG), TUM trajectory files and the
 * TUM-folder writer used by `bitfuse synth`.
 * Depends on core and capture (the interface only). See docs/formats.md. */
#ifndef BF_REPLAY_H
#define BF_REPLAY_H

#include "capture/capture.h"
#include "core/core.h"

/* ------------------------------------------------------------ opening */

typedef struct replay_options {
    const char *camera;   /* NULL (format default / camera.txt), "fr1", "fr2",
                             "fr3", "icl" or "fx,fy,cx,cy"; borrowed */
    double depth_scale;   /* raw units per metre; 0 = format default */
    uint32_t max_frames;  /* only the first N frames; 0 = all */
    bool skip_bad_frames; /* skip an unreadable frame with a warning */
} replay_options;

/* Opens the sequence at path, detecting its layout:
 *  - TUM RGB-D folder: rgb.txt + depth.txt (+ groundtruth.txt, camera.txt);
 *  - ICL-NUIM: depth/N.png + color/N.png + pose.txt (or TUM-like layout);
 *  - pose-per-frame folder: frame-NNNNNN.{depth.png,color.png|jpg,pose.txt}
 *    + camera-intrinsics.txt.
 * opt may be NULL (defaults). On success *out owns a new source; close it
 * with rgbd_source_close(). Errors name the file and line. */
bf_status replay_open(const char *path, const replay_options *opt, rgbd_source **out);

/* Frames a replay source skipped so far under skip_bad_frames (0 for a
 * source not made by replay_open). Frame indices keep their place in the
 * sequence, so a skipped frame leaves a gap in bf_frame.index. */
uint32_t replay_skipped_frames(const rgbd_source *src);

/* Parses one of the shared sequence options at argv[*i] (--camera,
 * --depth-scale, --frames, --skip-bad-frames), advancing *i past its value.
 * Returns 1 if it consumed an option, 0 if argv[*i] is not one of them, and
 * -1 (with bf_last_error set) if the value is bad. */
int replay_parse_option(int argc, char **argv, int *i, replay_options *opt);
/* Help text for the shared options, one line per option. */
const char *replay_options_help(void);

/* Fills K (fx, fy, cx, cy) from "fr1" | "fr2" | "fr3" (TUM's published
 * calibration), "icl" (ICL-NUIM, fy < 0) or "fx,fy,cx,cy"; width/height/
 * depth_scale are left alone. BF_INVALID_ARG for anything else. */
bf_status replay_parse_camera(const char *spec, bf_intrinsics *K);

/* ------------------------------------------------------------ images */

/* Reads a 16-bit single-channel PNG. *pix is malloc'd (w*h). An 8-bit or
 * colour PNG is BF_FORMAT naming the file and what it found. */
bf_status replay_png_read_u16(const char *path, uint16_t **pix, uint32_t *w, uint32_t *h);
/* Reads a PNG or JPEG (by content) as 8-bit RGB, w*h*3, malloc'd. */
bf_status replay_image_read_rgb8(const char *path, uint8_t **pix, uint32_t *w, uint32_t *h);
bf_status replay_png_write_u16(const char *path, const uint16_t *pix, uint32_t w, uint32_t h);
bf_status replay_png_write_rgb8(const char *path, const uint8_t *pix, uint32_t w, uint32_t h);

/* ------------------------------------------------------------ trajectories */

/* A trajectory in TUM format: one pose per line, "t tx ty tz qx qy qz qw",
 * camera-to-world, metres; '#' lines are comments. */
typedef struct replay_traj {
    size_t n;
    double *t_s;   /* strictly increasing */
    bf_se3 *T_wc;
    size_t cap;    /* entries allocated (managed by push/read; 0 is fine) */
} replay_traj;

/* Reads a TUM trajectory. Unsorted or duplicate timestamps, NaN or a
 * non-unit quaternion (|q| off by more than 1e-3) are BF_FORMAT naming the
 * file and line; an empty file is BF_FORMAT too. */
bf_status replay_traj_read_tum(const char *path, replay_traj *out);
/* Writes atomically, quaternions with qw >= 0, 9 decimals. */
bf_status replay_traj_write_tum(const char *path, const replay_traj *traj);
/* Appends one pose; grows the arrays. */
bf_status replay_traj_push(replay_traj *traj, double t_s, const bf_se3 *T_wc);
void replay_traj_free(replay_traj *traj);
/* Pose at time t by linear position / slerp rotation between the two
 * neighbouring samples; false if t is outside [t_0, t_n-1]. */
bool replay_traj_interpolate(const replay_traj *traj, double t_s, bf_se3 *T_wc);
/* TUM associate.py's rule for two strictly increasing stamp lists: every
 * pair with |t_a - t_b| < max_dt_s is a candidate; candidates in order of
 * |dt| (ties by a, then b) are taken greedily while neither stamp is taken.
 * On success b_of_a[i] (n_a entries, caller's) is the index in t_b matched
 * to t_a[i], or SIZE_MAX; on failure (out of memory) it is untouched. */
bf_status replay_associate_stamps(const double *t_a, size_t n_a, const double *t_b, size_t n_b, double max_dt_s,
                                  size_t *b_of_a);

/* ------------------------------------------------------------ writing */

/* Writes a TUM-format folder: rgb/T.png, depth/T.png (16-bit), rgb.txt,
 * depth.txt, groundtruth.txt (frames with a pose) and camera.txt
 * ("fx fy cx cy depth_scale"). The index files are written atomically by
 * finish(), so an interrupted run leaves no half-valid folder. */
typedef struct replay_tum_writer replay_tum_writer;
bf_status replay_tum_writer_create(const char *dir, const bf_intrinsics *K, replay_tum_writer **out);
bf_status replay_tum_writer_add(replay_tum_writer *w, const bf_frame *f);
bf_status replay_tum_writer_finish(replay_tum_writer *w);
void replay_tum_writer_destroy(replay_tum_writer *w); /* NULL is a no-op */

#endif
