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
/* NULL is a no-op. */
static inline void rgbd_source_close(rgbd_source *src)
{
    if (src) src->ops->close(src);
}
static inline const bf_intrinsics *rgbd_source_intrinsics(const rgbd_source *src)
{
    return &src->intrinsics;
}

#endif
