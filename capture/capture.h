/* capture: the rgbd_source interface every frame producer implements (file
 * replays in replay/, live cameras here later), behind one small table of
 * functions (Redis's aeApi* idea).
 *
 * A source owns the pixel buffers of the frames it returns; a frame stays
 * valid until the next rgbd_source_next() or rgbd_source_close(). */
#ifndef BF_CAPTURE_H
#define BF_CAPTURE_H

#include "core/core.h"

typedef struct rgbd_source rgbd_source;

typedef struct rgbd_source_ops {
    /* Fills *out with the next frame; BF_END after the last one. On any other
     * failure the message names the file, frame and reason. */
    bf_status (*next)(rgbd_source *src, bf_frame *out);
    /* Releases everything the source holds, including src itself. */
    void (*close)(rgbd_source *src);
    /* Optional (NULL: not offered). When the next frame's depth time is at or
     * before t_s, passes over it without reading its images: *out gets its
     * index, times and pose (no images) and BF_OK. Else, or when the frame
     * cannot be looked at without reading it, BF_END, and it stays the next
     * frame for next(). A resumed scan passes over the frames it stored. */
    bf_status (*pass)(rgbd_source *src, double t_s, bf_frame *out);
} rgbd_source_ops;

struct rgbd_source {
    const rgbd_source_ops *ops;
    const char *kind;         /* "tum", "icl-nuim", "pose-folder", ... */
    bf_intrinsics intrinsics; /* of the depth image; colour is registered to it */
    uint32_t n_frames;        /* frames it will deliver, 0 if unknown (live) */
    bool has_groundtruth;     /* frames carry T_wc */
};

static inline bf_status rgbd_source_next(rgbd_source *src, bf_frame *out)
{
    return src->ops->next(src, out);
}
/* BF_UNSUPPORTED when the source offers no pass (rgbd_source_ops). */
static inline bf_status rgbd_source_pass(rgbd_source *src, double t_s, bf_frame *out)
{
    return src->ops->pass ? src->ops->pass(src, t_s, out) : BF_UNSUPPORTED;
}
/* NULL is a no-op. */
static inline void rgbd_source_close(rgbd_source *src)
{
    if (src) src->ops->close(src);
}
static inline const bf_intrinsics *rgbd_source_intrinsics(const rgbd_source *src)
{
    return &src->intrinsics;
}

/* A source whose frames a function makes: frames rendered in memory by a
 * test or a benchmark. next() calls fn(user, i, out) for i = 0, 1, ... and
 * returns what it returns; after n_frames frames (0: no limit) it returns
 * BF_END. fn fills *out with buffers it owns, valid until its next call.
 * On success *out owns nothing of user's; rgbd_source_close frees it. */
typedef bf_status (*rgbd_frame_fn)(void *user, uint32_t index, bf_frame *out);
bf_status capture_source_from_fn(const bf_intrinsics *K, uint32_t n_frames, bool has_groundtruth, rgbd_frame_fn fn,
                                 void *user, rgbd_source **out);

/* ------------------------------------------------------------ capture thread
 * capture_threaded() runs any source on its own thread, feeding a bounded
 * queue of deep-copied frames (DESIGN.md section 1: capture thread -> bounded
 * queue -> main loop). The ring of capacity + 2 frame buffers (queued frames,
 * the one the consumer holds, the one the thread fills) is allocated at
 * create, sized from the source's intrinsics: nothing is allocated per frame.
 * When the consumer falls behind, the oldest queued frame is dropped and
 * counted: the device is never blocked and the queue never grows. The
 * thread starts at the consumer's first next(), so a consumer that gets
 * ready after opening the source (recon/ compiles its pipelines first)
 * loses no frame to its start-up. */

typedef struct capture_thread_stats {
    uint64_t captured;  /* frames the thread took from the source */
    uint64_t delivered; /* frames handed to the consumer by next() */
    uint64_t dropped;   /* oldest queued frames overwritten by newer ones */
    uint32_t queued;    /* frames waiting in the queue now */
    bool is_ended;      /* the thread stopped taking frames (end, error or stop) */
    bool drops;         /* a full queue drops its oldest frame (capture_threaded), not waits (_lossless): frames
                           queued then mean the consumer is behind a camera */
} capture_thread_stats;

/* Wraps src in a capture thread with a queue of capacity frames (>= 1),
 * dropping the oldest queued frame when full. The returned source delivers
 * the frames with their own index (a dropped frame leaves a gap); its next()
 * blocks until a frame is queued or the thread ended (BF_END, or the
 * source's error with its message). On success *out owns src: closing *out
 * stops the thread and closes src. On failure src is untouched and still the
 * caller's. src must report its frame size in intrinsics.width/height; a
 * frame of another size ends the stream with BF_FORMAT. */
bf_status capture_threaded(rgbd_source *src, uint32_t capacity, rgbd_source **out);
/* The same, but a full queue makes the thread wait for the consumer instead
 * of dropping: for file sources, where waiting costs nothing and a dropped
 * frame would be lost for good. */
bf_status capture_threaded_lossless(rgbd_source *src, uint32_t capacity, rgbd_source **out);
/* Starts the thread now, before the first next() would (tests that fill
 * the queue first). No-op for a started thread, other sources and NULL.
 * Call it from the consumer's thread. BF_NO_MEMORY when no thread can be
 * made. */
bf_status capture_threaded_start(rgbd_source *src);
/* Counters so far (zeros for a source not made by capture_threaded*). Safe
 * from any thread. */
capture_thread_stats capture_threaded_stats(const rgbd_source *src);
/* Asks the thread to stop taking frames: already queued frames are still
 * delivered, then next() returns BF_END. Only sets an atomic flag, so it is
 * async-signal-safe (call it from a SIGINT handler); no-op for other sources
 * and NULL. */
void capture_threaded_stop(rgbd_source *src);

/* The source a capture thread or pacing wraps (through every layer), or
 * src itself: what a reader's own counts come from (replay_skipped_frames).
 * Those counts are atomic: after a stop whose grace ran out the thread may
 * still be reading, and a count read then misses at most that frame. */
const rgbd_source *capture_inner(const rgbd_source *src);

/* Delivers inner's frames at their own pace: each next() waits until the
 * frame's timestamp, counted from the first frame's, has passed. A recorded
 * sequence behind the capture thread then behaves like a camera. On success
 * *out owns inner; on failure inner is untouched and still the caller's. */
bf_status capture_paced(rgbd_source *inner, rgbd_source **out);

/* ------------------------------------------------------------ live capture
 * (capture/open.c; backends capture/freenect.c, openni2.c, v4l2.c) */

/* Opens a live source by URI (docs/devices.md):
 *   freenect:INDEX[?depth=registered|disparity]   Kinect v1, libfreenect
 *   openni2:  openni2:URI  openni2:FILE.oni       OpenNI2 (PrimeSense, Orbbec,
 *                                                 Xtion; .oni recordings)
 *   v4l2:/dev/videoN[,/dev/videoM]                UVC depth node (Z16) and an
 *                                                 optional colour node
 * Any URI may end in "?camera=fx,fy,cx,cy" (pixels) and "&depth_scale=S"
 * to override what the backend reports. Frames carry the device's
 * timestamps in seconds where it has them (see each backend), else the
 * monotonic clock. On success *out owns the source (rgbd_source_close());
 * n_frames is 0 for live devices. Failures: an unknown scheme is
 * BF_INVALID_ARG; a backend left out of this build is BF_UNSUPPORTED naming
 * the Debian package to install; an absent or unreachable device is
 * BF_NO_DEVICE with the URI in the message (a recording that is not
 * there, openni2:FILE.oni, is BF_IO: missing input). Never crashes on a
 * missing device. */
bf_status capture_open(const char *uri, rgbd_source **out);

/* True when uri starts with a scheme capture_open knows ("freenect:",
 * "openni2:", "v4l2:"), compiled in or not. Anything else (a folder, a
 * .bflog, a path with a colon) is a recording. */
bool capture_is_device_uri(const char *uri);
/* A device URI that names a recording, not a camera (openni2:FILE.oni): its
 * frames carry the recording's own times. */
bool capture_is_recording_uri(const char *uri);

/* Opens what a user names as a device: a live URI (capture_open), or
 * anything else through open_recording (a recorded sequence standing in for
 * a camera; capture does not read files), paced at its own frame rate with
 * realtime. The source then runs behind the capture thread with a queue of
 * queue frames: a camera or a paced recording drops the oldest frame when
 * the consumer falls behind; a recording read as fast as it decodes loses
 * nothing. *is_live says which kind it was. On success *out owns it all. */
typedef bf_status (*capture_open_fn)(void *user, const char *path, rgbd_source **out);
bf_status capture_open_device(const char *uri, capture_open_fn open_recording, void *user, bool realtime,
                              uint32_t queue, bool *is_live, rgbd_source **out);

/* NULL-terminated names of the backends compiled into this build, in the
 * order capture_open tries them ("freenect", "openni2", "v4l2"). */
const char *const *capture_backend_names(void);

/* One device a backend can see now. */
typedef struct capture_device_info {
    char uri[256];  /* what capture_open takes, "freenect:0" */
    char name[256]; /* human-readable, "Kinect v1 (serial A00366...)" */
} capture_device_info;

/* Fills up to cap entries with the devices the compiled backends find and
 * returns how many were found (may exceed cap). Never fails: a backend that
 * cannot look (no USB access) contributes nothing and logs why at debug
 * level. Files (.oni) are not listed. */
uint32_t capture_list_devices(capture_device_info *out, uint32_t cap);

#endif
