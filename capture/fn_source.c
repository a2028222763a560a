/* capture: a source whose frames a function makes (capture.h). */
#include "capture.h"

#include <stdlib.h>

typedef struct fn_source {
    rgbd_source base;
    rgbd_frame_fn fn;
    void *user;
    uint32_t next_index;
} fn_source;

static bf_status fn_next(rgbd_source *base, bf_frame *out)
{
    fn_source *p = (fn_source *)base;
    if (p->base.n_frames && p->next_index >= p->base.n_frames) return BF_END;
    bf_status s = p->fn(p->user, p->next_index, out);
    if (s == BF_OK) p->next_index++;
    return s;
}

static void fn_close(rgbd_source *base) { free(base); }

static const rgbd_source_ops fn_ops = {.next = fn_next, .close = fn_close};

bf_status capture_source_from_fn(const bf_intrinsics *K, uint32_t n_frames, bool has_groundtruth, rgbd_frame_fn fn,
                                 void *user, rgbd_source **out)
{
    if (!K || !fn || !out) return bf_fail(BF_INVALID_ARG, "capture_source_from_fn: NULL argument");
    fn_source *p = calloc(1, sizeof *p);
    if (!p) return bf_fail(BF_NO_MEMORY, "frame-function source");
    p->base = (rgbd_source){.ops = &fn_ops, .kind = "memory", .intrinsics = *K, .n_frames = n_frames,
                            .has_groundtruth = has_groundtruth};
    p->fn = fn;
    p->user = user;
    *out = &p->base;
    return BF_OK;
}
