/* replay: file sources behind the rgbd_source interface (TUM RGB-D folders,
 * ICL-NUIM, pose-per-frame folders, the project's own log), the options they
 * take (what bitfuse's --camera, --depth-scale, --frames and
 * --skip-bad-frames set), image codecs (PNG, JPEG), TUM trajectory files, the
 * TUM-folder writer used by `bitfuse synth` and the log writer.
 * Depends on core, capture (the interface only) and calib (the lens model and
 * its undistortion map). See docs/formats.md. */
#ifndef BF_REPLAY_H
#define BF_REPLAY_H

#include "calib/calib.h"
#include "capture/capture.h"
#include "core/core.h"

/* ------------------------------------------------------------ opening */

typedef struct replay_options {
    const char *camera;   /* NULL (format default / camera.txt), "fr1", "fr2",
                             "fr3", "icl" or "fx,fy,cx,cy"; borrowed */
    const char *camera_origin; /* what camera came from, for messages (NULL: "--camera"); borrowed */
    double depth_scale;   /* raw units per metre; 0 = format default */
    uint32_t max_frames;  /* only the first N frames; 0 = all */
    bool skip_bad_frames; /* skip an unreadable frame with a warning */
    bool raw_colour;      /* the colour is its own camera's image (a calib.json registers it to the
                             depth): never resampled by the depth camera's lens */
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

/* Fills K (fx, fy, cx, cy) and the lens's distortion from "fr1" | "fr2" |
 * "fr3" (TUM's published calibration, with its distortion), "icl"
 * (ICL-NUIM, fy < 0), "fx,fy,cx,cy" (no distortion) or
 * "fx,fy,cx,cy,k1,k2,p1,p2,k3"; width/height/depth_scale are left alone.
 * BF_INVALID_ARG for anything else. A replay source whose camera has a
 * distortion delivers its frames undistorted (replay_undistortion). */
bf_status replay_parse_camera_lens(const char *spec, bf_intrinsics *K, double dist[CALIB_DIST_N]);
/* The pinhole part, for inputs whose camera is a pinhole (a bitfuse log,
 * whose frames are kept as recorded; synth): a preset's distortion is
 * dropped, numbers with one are refused. */
bf_status replay_parse_camera(const char *spec, bf_intrinsics *K);
/* Whether src (made by replay_open) takes a lens's distortion out of its
 * frames, with the coefficients and the largest shift of a pixel; false for
 * any other source. */
bool replay_undistortion(const rgbd_source *src, double dist[CALIB_DIST_N], double *max_shift_px);

/* ------------------------------------------------------------ images */

/* Reads a 16-bit single-channel PNG. *pix is malloc'd (w*h). An 8-bit or
 * colour PNG is BF_FORMAT naming the file and what it found. */
bf_status replay_png_read_u16(const char *path, uint16_t **pix, uint32_t *w, uint32_t *h);
/* Reads a PNG or JPEG (by content) as 8-bit RGB, w*h*3, malloc'd. */
bf_status replay_image_read_rgb8(const char *path, uint8_t **pix, uint32_t *w, uint32_t *h);
bf_status replay_png_write_u16(const char *path, const uint16_t *pix, uint32_t w, uint32_t h);
bf_status replay_png_write_rgb8(const char *path, const uint8_t *pix, uint32_t w, uint32_t h);

/* ------------------------------------------------------------ trajectories */

/* TUM trajectory files (the type is core's bf_traj): one pose per line,
 * "t tx ty tz qx qy qz qw", camera-to-world, metres; '#' lines are
 * comments. Reading takes what TUM's own scripts take: a timestamp that
 * repeats the previous line's keeps the first line, a quaternion is
 * normalised, and either is reported by one warning naming the file and
 * the first line. A timestamp going back, a number that does not parse or
 * is not finite, a zero quaternion, a line without 8 fields and an empty
 * file are BF_FORMAT naming the file and line. Writing is atomic, quaternions with
 * qw >= 0, 9 decimals. */
bf_status replay_traj_read_tum(const char *path, bf_traj *out);
bf_status replay_traj_write_tum(const char *path, const bf_traj *traj);

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

/* ------------------------------------------------------------ the bitfuse log
 * One file per recording (docs/formats.md, "The bitfuse log"): a header
 * (intrinsics, depth scale, size, device, colour codec), per frame a
 * self-checking record (timestamps, pose, depth compressed losslessly with
 * zstd, colour as zstd or JPEG), and an index + footer at the end for
 * seeking. A log cut off anywhere (a crash) still replays every whole frame.
 * replay_open() opens a path ending in .bflog (or any file starting with the
 * log's magic) as a source. */

typedef enum replay_log_colour {
    REPLAY_LOG_COLOUR_NONE = 0, /* depth only; colour is dropped */
    REPLAY_LOG_COLOUR_ZSTD = 1, /* lossless: zstd of the RGB bytes */
    REPLAY_LOG_COLOUR_JPEG = 2, /* lossy, about 15x smaller than zstd */
} replay_log_colour;

typedef struct replay_log_config {
    replay_log_colour colour; /* default (0 in a zeroed config) NONE: set it */
    int jpeg_quality;         /* 1..100, 0 = 90 */
    int zstd_level;           /* 1..19, 0 = 1 (fast enough for 30 Hz on one core) */
    const char *device;       /* recorded in the header ("freenect:0", a path), borrowed; may be NULL */
    bool has_groundtruth;     /* recorded in the header: frames carry poses */
    /* Written under a temporary name beside path (path.partial) and renamed
     * over path by a successful finish; destroyed unfinished, the temporary
     * goes and a file already at path stays as it was. For a conversion,
     * whose input is still there to start again from; a recording is
     * written in place instead, so that a crash leaves it replayable. */
    bool replace_when_finished;
} replay_log_config;

/* Byte counts so far (the raw sizes are what the frames would take
 * uncompressed: 2 bytes per depth pixel, 3 per colour pixel). */
typedef struct replay_log_stats {
    uint32_t n_frames;
    uint64_t depth_raw_bytes, depth_bytes;
    uint64_t rgb_raw_bytes, rgb_bytes;
    uint64_t file_bytes; /* everything written, headers included */
} replay_log_stats;

typedef struct replay_log_writer replay_log_writer;

/* Creates (or truncates) the log at path and writes its header. K gives the
 * frame size (width/height must be set) and the camera. The file is written
 * in place, not through a temporary name (unless cfg->replace_when_finished):
 * a recording cut off by a crash must stay on disk, and it replays up to its
 * last whole frame. */
bf_status replay_log_writer_create(const char *path, const bf_intrinsics *K, const replay_log_config *cfg,
                                   replay_log_writer **out);
/* Appends one frame (compressed, checksummed, flushed to the OS). A frame of
 * another size or with non-finite times is BF_INVALID_ARG and writes
 * nothing; BF_IO (disk full) leaves the file replayable up to the frame
 * before. The frame's pixels are only read during the call. */
bf_status replay_log_writer_add(replay_log_writer *w, const bf_frame *f);
/* Writes the index and footer, fsyncs and closes the file. After a failed
 * finish the log still replays (the reader scans it without the index). */
bf_status replay_log_writer_finish(replay_log_writer *w);
replay_log_stats replay_log_writer_stats(const replay_log_writer *w);
/* Frees w; a log not finished is left as a crash would leave it (readable,
 * without index). NULL is a no-op. */
void replay_log_writer_destroy(replay_log_writer *w);

/* Seeking in a log source: the next frame delivered is the one at position
 * pos (0-based order in the file, not bf_frame.index, which keeps the index
 * the frame had when it was recorded). BF_INVALID_ARG past the end or for a
 * source that is not a log. */
bf_status replay_log_seek(rgbd_source *src, uint32_t pos);
/* True if path names a log by its extension (".bflog"). */
bool replay_is_log_path(const char *path);
/* Whether folder path holds a sequence replay_open recognises by its index
 * files (TUM's depth.txt or rgb.txt, ICL-NUIM's depth/N.png, a pose-per-frame
 * folder's frame-000000.depth.png); nothing is read. */
bool replay_is_sequence_dir(const char *path);

#endif
