/* capture: a recorded sequence delivered at its own pace (capture.h). */
#include "capture.h"
#include "live_int.h"

#include <math.h>
#include <stdlib.h>
#include <time.h>

/* next() sleeps until the frame's time since the first frame has passed on
 * the monotonic clock. It runs on the capture thread, so the queue sees a
 * camera's timing. */
typedef struct paced_source {
    rgbd_source base;
    rgbd_source *inner;
    double t0_wall_s, t0_frame_s;
    bool is_started;
} paced_source;

static bf_status paced_next(rgbd_source *base, bf_frame *out)
{
    paced_source *p = (paced_source *)base;
    bf_status s = rgbd_source_next(p->inner, out);
    if (s != BF_OK) return s;
    if (!p->is_started) {
        p->is_started = true;
        p->t0_wall_s = bf_time_s();
        p->t0_frame_s = out->t_depth_s;
    }
    double now = bf_time_s();
    double wait = (out->t_depth_s - p->t0_frame_s) - (now - p->t0_wall_s);
    /* A gap of more than 10 s is a break in the recording, not a pace: the
     * frame comes now, and the pace goes on from it (not a burst of every
     * later frame, each as far behind its time). */
    if (wait >= 10) {
        p->t0_wall_s = now;
        p->t0_frame_s = out->t_depth_s;
    } else if (wait > 0) {
        struct timespec ts = {(time_t)wait, (long)((wait - floor(wait)) * 1e9)};
        nanosleep(&ts, NULL);
    }
    return BF_OK;
}

static void paced_close(rgbd_source *base)
{
    paced_source *p = (paced_source *)base;
    rgbd_source_close(p->inner);
    free(p);
}

static const rgbd_source_ops paced_ops = {.next = paced_next, .close = paced_close};

const rgbd_source *capture__paced_inner(const rgbd_source *src)
{
    return src && src->ops == &paced_ops ? ((const paced_source *)src)->inner : NULL;
}

bf_status capture_paced(rgbd_source *inner, rgbd_source **out)
{
    paced_source *p = calloc(1, sizeof *p);
    if (!p) return bf_fail(BF_NO_MEMORY, "paced source");
    p->base = *inner;
    p->base.ops = &paced_ops;
    p->inner = inner;
    *out = &p->base;
    return BF_OK;
}
