/* replay: declarations shared by the module's files (not for other modules).
 *
 * The three folder readers (tum.c, icl.c, posefolder.c) only build a list of
 * frame references (paths, times, poses) at open; source.c owns the decoding
 * buffers and delivers frames from that list, so every format shares one
 * next(), one skip rule and one set of size checks. */
#ifndef BF_REPLAY_INT_H
#define BF_REPLAY_INT_H

#include "replay/replay.h"

#include <stdio.h>

/* TUM's associate.py default: colour and depth further apart than this are
 * not a pair; also the reach of a ground-truth pose beyond its range. */
#define REPLAY_MAX_DT_S 0.02

/* Frame times of the numbered layouts (ICL-NUIM, pose folders): 30 Hz. */
#define REPLAY_NUMBERED_FPS 30.0

/* ------------------------------------------------------------ text files */

/* A whole text file read into memory and walked line by line. Fields are
 * split at spaces, tabs and commas (as TUM's associate.py does); empty lines
 * and lines starting with '#' are skipped. */
typedef struct replay__text {
    const char *path; /* borrowed, for messages */
    char *buf;        /* owned, NUL-terminated */
    char *p;          /* start of the next line */
    uint32_t line;    /* 1-based number of the line last returned */
    /* What the file's reader let through and replay__text_warn reports once:
     * quaternions normalised, repeated timestamps dropped (first line, count). */
    uint32_t n_normalised, normalised_line, n_repeats, repeat_line;
    double normalised_norm;
} replay__text;

/* The largest position a pose file may give [m]: a value beyond is corrupt
 * (its square overflows the error measures). */
#define REPLAY_MAX_POSITION_M 1e9
/* BF_IO naming the file if it cannot be read; BF_FORMAT naming the line
 * of a NUL byte (replay__text_nul). */
bf_status replay__text_open(replay__text *t, const char *path);
/* Starts t on text (NUL-terminated, edited in place; path names it in
 * messages): a UTF-8 byte order mark skipped, lone CRs read as line ends.
 * replay__text_open does this on the file it reads. */
void replay__text_begin(replay__text *t, const char *path, char *text);
/* BF_FORMAT naming path and line when text's len bytes hold a NUL: a text
 * file never does, and the readers would stop there (a file padded with
 * zeros after a crash read as its first part alone). */
bf_status replay__text_nul(const char *path, const char *text, size_t len);
/* Whether K's principal point lies more than a quarter of the image from
 * the centre of w x h images (real cameras keep it within a few per cent):
 * a camera for another image size. */
bool replay__principal_point_is_off(const bf_intrinsics *K, uint32_t w, uint32_t h);
/* Refuses a camera no depth camera has for w x h images (such numbers made
 * the map spread over thousands of chunks at seconds a frame): image edges
 * whose rays lie more than 85 degrees off the axis along either image axis
 * (a field of view over 170 degrees, a principal point far out), or a
 * field of view under 0.1 degree; BF_INVALID_ARG when the numbers came from
 * an option (`from_option`), BF_FORMAT naming `path` and `from` otherwise.
 * A size outside 2..8192 a side (the map's limit) is always BF_FORMAT. A
 * camera for larger images is only warned about (above). */
bf_status replay__camera_fits(const bf_intrinsics *K, uint32_t w, uint32_t h, const char *path, const char *from,
                              bool from_option);
void replay__text_close(replay__text *t);
/* Splits the next content line into at most cap fields (modifying the
 * buffer). Returns the number of fields on the line (which may exceed cap;
 * only cap are stored), or -1 at the end of the file. */
int replay__text_next(replay__text *t, char **fields, int cap);
/* Parses a finite number; BF_FORMAT "path:line: what 'x' is not a finite
 * number" otherwise. */
bf_status replay__text_double(const replay__text *t, const char *s, const char *what, double *out);

/* Builds a pose from TUM's order tx ty tz qx qy qz qw. The quaternion is
 * normalised, as TUM's evaluation scripts do (transform44); one off unit
 * length by more than 1e-3 is counted for replay__text_warn. A zero
 * quaternion (|q|^2 below the scripts' 4 eps) has no rotation to give:
 * BF_FORMAT naming file and line. */
bf_status replay__pose_from_fields(replay__text *t, char **f, bf_se3 *T_wc);
/* A line whose timestamp repeats the previous line's: counted for
 * replay__text_warn; the caller keeps the first of the two. */
void replay__text_note_repeat(replay__text *t);
/* One warning per file for what was accepted but not as written: the
 * first line, the value and how many lines more. */
void replay__text_warn(const replay__text *t);

/* Copies the last error and fails with "<old message> (frame N)". */
bf_status replay__fail_frame(bf_status s, uint32_t frame);

/* ------------------------------------------------------------ images */

/* Header only: size of a PNG or JPEG (detected by content). */
bf_status replay__image_size(const char *path, uint32_t *w, uint32_t *h);
/* Decodes a 16-bit grey PNG into buf, which holds cap_px pixels. When
 * exp_w/exp_h are non-zero a different size is BF_FORMAT. */
bf_status replay__png_decode_u16(const char *path, uint16_t *buf, size_t cap_px,
                                 uint32_t exp_w, uint32_t exp_h, uint32_t *w, uint32_t *h);
/* Decodes a PNG or JPEG into 8-bit RGB (cap_px pixels of 3 bytes). */
bf_status replay__image_decode_rgb8(const char *path, uint8_t *buf, size_t cap_px,
                                    uint32_t exp_w, uint32_t exp_h, uint32_t *w, uint32_t *h);

/* ------------------------------------------------------------ sources */

/* One frame of a file sequence, as listed at open. */
typedef struct replay__frame_ref {
    double t_depth_s, t_rgb_s;
    const char *depth_path; /* in the sequence's string arena */
    const char *rgb_path;   /* NULL if the sequence has no colour */
    const char *pose_path;  /* pose-per-frame folders: read at next(), else NULL */
    bool has_pose;
    bf_se3 T_wc;
} replay__frame_ref;

/* A growing list of frame references plus the arena their strings live in.
 * Grows only while the sequence is opened. */
typedef struct replay__list {
    replay__frame_ref *v;
    uint32_t n, cap;
    uint16_t depth_invalid; /* raw value meaning "no depth" besides 0
                               (7-Scenes: 65535), mapped to 0; 0 = none */
    char **strings; /* every string strdup'd for the list */
    size_t n_strings, strings_cap;
} replay__list;

bf_status replay__list_push(replay__list *l, const replay__frame_ref *f);
/* strdup into the list's arena; NULL on out of memory (status recorded). */
const char *replay__list_str(replay__list *l, const char *s);
void replay__list_free(replay__list *l);

/* Camera settings a folder reader resolves before the source is built. */
typedef struct replay__camera {
    bf_intrinsics K;   /* fx, fy, cx, cy, depth_scale (size filled later) */
    double dist[CALIB_DIST_N]; /* the lens's distortion (all 0: a pinhole): the source undistorts */
    bool is_from_option; /* --camera set it (a bad lens is a usage error, else bad input) */
    bool is_from_name;   /* a TUM folder's name chose the preset (nothing overrode it) */
    const char *origin; /* "fr2 preset", "camera.txt", ... for logs */
} replay__camera;

/* Applies the precedence every format shares: the user's --camera and
 * --depth-scale, then camera.txt in dir (if present), then the format's
 * defaults already in cam. */
bf_status replay__camera_resolve(const char *dir, const replay_options *opt, replay__camera *cam);
/* Reads "fx fy cx cy depth_scale" (depth_scale optional) or "fx fy cx cy
 * depth_scale k1 k2 p1 p2 k3"; dist is all 0 without the five. */
bf_status replay__camera_txt_read(const char *path, bf_intrinsics *K, double dist[CALIB_DIST_N]);

/* Builds the source from a frame list (taking ownership of it, also on
 * failure), probing the first readable frame for the image size; path
 * names the sequence in warnings, kind its layout ("tum", ...). */
bf_status replay__source_create(const char *path, const char *kind, replay__list *list, const replay__camera *cam,
                                const replay_options *opt, rgbd_source **out);

/* The format readers: each fills a frame list and a camera. */
bf_status replay__tum_list(const char *dir, const replay_options *opt, replay__list *list, replay__camera *cam);
bf_status replay__icl_list(const char *dir, const replay_options *opt, replay__list *list, replay__camera *cam);
bf_status replay__posefolder_list(const char *dir, const replay_options *opt, replay__list *list,
                                  replay__camera *cam);
/* Reads a 4x4 camera-to-world matrix (4 rows of 4 numbers). */
bf_status replay__pose_matrix_read(const char *path, bf_se3 *T_wc);

bool replay__is_dir(const char *path);

#endif
