/* capture: a capture thread per source feeding a bounded queue (DESIGN.md
 * section 1).
 *
 * Slots: capacity + 2 frame buffers, allocated at create. At any moment
 * each slot is in exactly one place: the queue (oldest first), the
 * consumer's hands (the frame next() returned last, valid until the next
 * call), the thread's hands (being filled, outside the lock) or the free
 * stack. With at most capacity queued, one held by the consumer and one by
 * the thread, a free slot always exists when the thread needs a new one.
 *
 * The copy from the source into a slot happens outside the lock, so the
 * consumer only ever waits for a pointer swap. When the queue is full the
 * thread either recycles the oldest queued slot (drop, counted) or waits
 * for the consumer (lossless mode, for files).
 *
 * Starting: the thread is made at the consumer's first next(), so frames
 * flow only once the consumer is ready (capture.h).
 *
 * Stopping: capture_threaded_stop() only stores an atomic flag (async-
 * signal-safe). The thread checks it before each frame; the consumer waits
 * with a timeout so it notices the flag even though a signal handler cannot
 * signal a condition variable. */
#include "capture/capture.h"
#include "live_int.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* The consumer re-checks the stop flag this often while it waits [ms]. */
#define CAPTURE_WAIT_SLICE_MS 50
/* After a stop, the consumer waits this long at most for the frame the
 * thread is still reading [ms]. */
#define CAPTURE_STOP_GRACE_MS 1000

typedef struct capture_slot {
    bf_frame meta;      /* pixel pointers are rebound on delivery */
    uint16_t *depth;    /* w*h */
    uint8_t *rgb;       /* w*h*3 */
    bool has_rgb;
} capture_slot;

typedef struct capture_thread {
    rgbd_source base;
    rgbd_source *src;   /* owned */
    bool drop_when_full;
    uint32_t capacity;  /* queued frames at most */
    uint32_t n_slots;   /* capacity + 2 */
    capture_slot *slots;
    size_t n_px;        /* width * height */

    pthread_mutex_t lock;
    pthread_cond_t cond_frame; /* a frame was queued or the thread ended */
    pthread_cond_t cond_space; /* a slot came free (lossless mode) */
    pthread_t thread;
    bool is_started;

    /* Under lock. */
    uint32_t *queue;    /* capacity slot numbers, a ring */
    uint32_t q_head, q_len;
    uint32_t *free_stack;
    uint32_t n_free;
    uint32_t held;      /* slot the consumer holds, or UINT32_MAX */
    bool is_done;       /* the thread has ended */
    bf_status end_status;
    char end_message[512];
    uint64_t n_delivered, n_dropped;

    atomic_bool stop;   /* set by capture_threaded_stop (signal handlers too) */
    atomic_bool closing; /* close(): stop even a lossless wait */
    atomic_uint_fast64_t n_captured;
} capture_thread;

static const rgbd_source_ops capture_thread_ops;

static void slot_release(capture_thread *ct, uint32_t slot)
{
    ct->free_stack[ct->n_free++] = slot;
}

/* Under lock: a free slot (one always exists, see the file comment). */
static uint32_t slot_take(capture_thread *ct)
{
    BF_ASSERT(ct->n_free > 0);
    return ct->free_stack[--ct->n_free];
}

static void finish_thread(capture_thread *ct, bf_status s, const char *msg)
{
    pthread_mutex_lock(&ct->lock);
    ct->is_done = true;
    ct->end_status = s;
    snprintf(ct->end_message, sizeof ct->end_message, "%s", msg ? msg : "");
    pthread_cond_broadcast(&ct->cond_frame);
    pthread_mutex_unlock(&ct->lock);
}

static void *capture_main(void *arg)
{
    capture_thread *ct = arg;
    uint32_t W = ct->base.intrinsics.width, H = ct->base.intrinsics.height;
    pthread_mutex_lock(&ct->lock);
    uint32_t mine = slot_take(ct);
    pthread_mutex_unlock(&ct->lock);
    for (;;) {
        if (atomic_load(&ct->stop) || atomic_load(&ct->closing)) {
            finish_thread(ct, BF_END, NULL);
            break;
        }
        bf_frame f;
        bf_status s = rgbd_source_next(ct->src, &f);
        if (s != BF_OK) {
            /* bf_last_error() is per thread: hand the message over. */
            finish_thread(ct, s, s == BF_END ? NULL : bf_last_error());
            break;
        }
        if (f.width != W || f.height != H || !f.depth) {
            bf_status e = bf_fail(BF_FORMAT, "%s source: frame %u is %ux%u%s, the source said %ux%u",
                                  ct->src->kind ? ct->src->kind : "capture", f.index, f.width, f.height,
                                  f.depth ? "" : " without depth", W, H);
            finish_thread(ct, e, bf_last_error());
            break;
        }
        atomic_fetch_add(&ct->n_captured, 1);
        capture_slot *sl = &ct->slots[mine];
        memcpy(sl->depth, f.depth, ct->n_px * sizeof *sl->depth);
        sl->has_rgb = f.rgb != NULL;
        if (f.rgb) memcpy(sl->rgb, f.rgb, ct->n_px * 3);
        sl->meta = f;

        pthread_mutex_lock(&ct->lock);
        while (!ct->drop_when_full && ct->q_len == ct->capacity && !atomic_load(&ct->closing))
            pthread_cond_wait(&ct->cond_space, &ct->lock);
        if (atomic_load(&ct->closing)) {
            pthread_mutex_unlock(&ct->lock);
            finish_thread(ct, BF_END, NULL);
            break;
        }
        uint32_t next_mine;
        if (ct->q_len == ct->capacity) {
            /* Full: the oldest queued frame gives its slot to the newest. */
            next_mine = ct->queue[ct->q_head];
            ct->q_head = (ct->q_head + 1) % ct->capacity;
            ct->q_len--;
            ct->n_dropped++;
        } else {
            next_mine = UINT32_MAX;
        }
        ct->queue[(ct->q_head + ct->q_len) % ct->capacity] = mine;
        ct->q_len++;
        mine = next_mine != UINT32_MAX ? next_mine : slot_take(ct);
        pthread_cond_signal(&ct->cond_frame);
        pthread_mutex_unlock(&ct->lock);
    }
    pthread_mutex_lock(&ct->lock);
    slot_release(ct, mine);
    pthread_mutex_unlock(&ct->lock);
    return NULL;
}

/* The thread starts at the consumer's first next(), not at create: a
 * camera or paced recording opened before the consumer is ready (its
 * pipelines compiled) then fills the queue only once frames are taken, so
 * start-up drops nothing. Only the consumer's thread calls this. */
static bf_status start_thread(capture_thread *ct)
{
    if (ct->is_started) return BF_OK;
    int rc = bf_thread_start(&ct->thread, capture_main, ct);
    if (rc != 0) return bf_fail(BF_NO_MEMORY, "capture thread: cannot start a thread: %s", strerror(rc));
    ct->is_started = true;
    return BF_OK;
}

static bf_status capture_next(rgbd_source *base, bf_frame *out)
{
    capture_thread *ct = (capture_thread *)base;
    bf_status st = start_thread(ct);
    if (st != BF_OK) return st;
    pthread_mutex_lock(&ct->lock);
    if (ct->held != UINT32_MAX) {
        slot_release(ct, ct->held);
        ct->held = UINT32_MAX;
        pthread_cond_signal(&ct->cond_space);
    }
    /* After a stop the thread still finishes the frame it is reading (one
     * frame period for a camera): wait for it, but never longer than
     * CAPTURE_STOP_GRACE_MS, in case the device hangs. */
    uint64_t t_stop_ns = 0;
    while (ct->q_len == 0 && !ct->is_done) {
        if (atomic_load(&ct->stop)) {
            uint64_t now = bf_time_ns();
            if (!t_stop_ns) t_stop_ns = now;
            if (now - t_stop_ns > (uint64_t)CAPTURE_STOP_GRACE_MS * 1000000u) break;
        }
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += CAPTURE_WAIT_SLICE_MS * 1000000L;
        if (ts.tv_nsec >= 1000000000L) {
            ts.tv_sec++;
            ts.tv_nsec -= 1000000000L;
        }
        int rc = pthread_cond_timedwait(&ct->cond_frame, &ct->lock, &ts);
        BF_ASSERT(rc == 0 || rc == ETIMEDOUT);
    }
    if (ct->q_len > 0) {
        uint32_t slot = ct->queue[ct->q_head];
        ct->q_head = (ct->q_head + 1) % ct->capacity;
        ct->q_len--;
        ct->held = slot;
        ct->n_delivered++;
        pthread_cond_signal(&ct->cond_space);
        pthread_mutex_unlock(&ct->lock);
        const capture_slot *sl = &ct->slots[slot];
        *out = sl->meta;
        out->depth = sl->depth;
        out->rgb = sl->has_rgb ? sl->rgb : NULL;
        return BF_OK;
    }
    /* Queue empty and the thread ended (or a stop was asked for). */
    bf_status s = ct->is_done ? ct->end_status : BF_END;
    char msg[sizeof ct->end_message];
    memcpy(msg, ct->end_message, sizeof msg);
    pthread_mutex_unlock(&ct->lock);
    if (s == BF_END) return BF_END;
    return msg[0] ? bf_fail(s, "%s", msg) : s;
}

/* Frees the slots and the ring, not ct itself. */
static void capture_free_buffers(capture_thread *ct)
{
    if (ct->slots)
        for (uint32_t i = 0; i < ct->n_slots; i++) {
            free(ct->slots[i].depth);
            free(ct->slots[i].rgb);
        }
    free(ct->slots);
    free(ct->queue);
    free(ct->free_stack);
}

static void capture_close(rgbd_source *base)
{
    capture_thread *ct = (capture_thread *)base;
    atomic_store(&ct->stop, true);
    atomic_store(&ct->closing, true);
    pthread_mutex_lock(&ct->lock);
    pthread_cond_broadcast(&ct->cond_space);
    pthread_mutex_unlock(&ct->lock);
    /* Waits for the source's current next() to return: one frame period
     * for a camera. */
    if (ct->is_started) pthread_join(ct->thread, NULL);
    rgbd_source_close(ct->src);
    pthread_cond_destroy(&ct->cond_frame);
    pthread_cond_destroy(&ct->cond_space);
    pthread_mutex_destroy(&ct->lock);
    capture_free_buffers(ct);
    memset(ct, 0xff, sizeof *ct); /* poison: a use after close fails loudly */
    free(ct);
}

static const rgbd_source_ops capture_thread_ops = {.next = capture_next, .close = capture_close};

static bf_status capture_create(rgbd_source *src, uint32_t capacity, bool drop_when_full, rgbd_source **out)
{
    if (!src || !out) return bf_fail(BF_INVALID_ARG, "capture thread: no source");
    if (capacity == 0 || capacity > 1024)
        return bf_fail(BF_INVALID_ARG, "capture thread: queue capacity %u is outside 1..1024", capacity);
    uint32_t W = src->intrinsics.width, H = src->intrinsics.height;
    if (W == 0 || H == 0 || W > 16384 || H > 16384)
        return bf_fail(BF_INVALID_ARG, "capture thread: %s source reports a frame size of %ux%u",
                       src->kind ? src->kind : "the", W, H);
    capture_thread *ct = calloc(1, sizeof *ct);
    if (!ct) return bf_fail(BF_NO_MEMORY, "capture thread");
    ct->capacity = capacity;
    ct->n_slots = capacity + 2;
    ct->n_px = (size_t)W * H;
    ct->drop_when_full = drop_when_full;
    ct->slots = calloc(ct->n_slots, sizeof *ct->slots);
    ct->queue = calloc(capacity, sizeof *ct->queue);
    ct->free_stack = calloc(ct->n_slots, sizeof *ct->free_stack);
    if (!ct->slots || !ct->queue || !ct->free_stack) goto oom;
    for (uint32_t i = 0; i < ct->n_slots; i++) {
        ct->slots[i].depth = malloc(ct->n_px * sizeof(uint16_t));
        ct->slots[i].rgb = malloc(ct->n_px * 3);
        if (!ct->slots[i].depth || !ct->slots[i].rgb) goto oom;
        ct->free_stack[ct->n_free++] = ct->n_slots - 1 - i;
    }
    ct->held = UINT32_MAX;
    atomic_init(&ct->stop, false);
    atomic_init(&ct->closing, false);
    atomic_init(&ct->n_captured, 0);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_mutex_init(&ct->lock, NULL);
    pthread_cond_init(&ct->cond_frame, &ca);
    pthread_cond_init(&ct->cond_space, &ca);
    pthread_condattr_destroy(&ca);
    ct->src = src;
    ct->base.ops = &capture_thread_ops;
    ct->base.kind = src->kind;
    ct->base.intrinsics = src->intrinsics;
    ct->base.n_frames = src->n_frames;
    ct->base.has_groundtruth = src->has_groundtruth;
    *out = &ct->base;
    return BF_OK;
oom:
    capture_free_buffers(ct);
    free(ct);
    return bf_fail(BF_NO_MEMORY, "capture thread: %u frame buffers of %ux%u", capacity + 2, W, H);
}

bf_status capture_threaded(rgbd_source *src, uint32_t capacity, rgbd_source **out)
{
    return capture_create(src, capacity, true, out);
}

bf_status capture_threaded_lossless(rgbd_source *src, uint32_t capacity, rgbd_source **out)
{
    return capture_create(src, capacity, false, out);
}

const rgbd_source *capture_inner(const rgbd_source *src)
{
    for (;;) {
        const rgbd_source *in = src && src->ops == &capture_thread_ops ? ((const capture_thread *)src)->src
                                                                         : capture__paced_inner(src);
        if (!in) return src;
        src = in;
    }
}

capture_thread_stats capture_threaded_stats(const rgbd_source *src)
{
    capture_thread_stats st = {0};
    if (!src || src->ops != &capture_thread_ops) return st;
    capture_thread *ct = (capture_thread *)src;
    pthread_mutex_lock(&ct->lock);
    st.delivered = ct->n_delivered;
    st.dropped = ct->n_dropped;
    st.queued = ct->q_len;
    st.is_ended = ct->is_done;
    pthread_mutex_unlock(&ct->lock);
    st.drops = ct->drop_when_full;
    st.captured = atomic_load(&ct->n_captured);
    return st;
}

bf_status capture_threaded_start(rgbd_source *src)
{
    if (!src || src->ops != &capture_thread_ops) return BF_OK;
    return start_thread((capture_thread *)src);
}

void capture_threaded_stop(rgbd_source *src)
{
    if (!src || src->ops != &capture_thread_ops) return;
    atomic_store(&((capture_thread *)src)->stop, true);
}
