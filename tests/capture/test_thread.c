/* capture: the capture thread and its bounded queue. A fake source stands
 * in for a camera: it writes its frame index into every depth pixel, so a
 * delivered frame proves which frame it is and that its buffer was not
 * overwritten while the consumer held it. */
#include <signal.h>
#include <stdatomic.h>
#include <time.h>

#include "capture/capture.h"
#include "test.h"

#define FW 32u
#define FH 24u

typedef struct fake_source {
    rgbd_source base;
    uint32_t next, n;      /* frames delivered so far, frames in all (UINT32_MAX: endless) */
    uint32_t fail_at;      /* frame that fails with BF_FORMAT (UINT32_MAX: none) */
    uint32_t wrong_size_at;
    uint32_t delay_us;     /* per frame: a camera's frame period */
    uint16_t depth[FW * FH];
    uint8_t rgb[FW * FH * 3];
    atomic_int *closed;    /* set on close, if given */
} fake_source;

static void sleep_us(uint32_t us)
{
    struct timespec ts = {us / 1000000u, (long)(us % 1000000u) * 1000L};
    nanosleep(&ts, NULL);
}

static bf_status fake_next(rgbd_source *base, bf_frame *out)
{
    fake_source *fs = (fake_source *)base;
    if (fs->next >= fs->n) return BF_END;
    uint32_t i = fs->next++;
    if (fs->delay_us) sleep_us(fs->delay_us);
    if (i == fs->fail_at) return bf_fail(BF_FORMAT, "fake: frame %u: broken on purpose", i);
    for (uint32_t p = 0; p < FW * FH; p++) fs->depth[p] = (uint16_t)(i + 1);
    for (uint32_t p = 0; p < FW * FH * 3; p++) fs->rgb[p] = (uint8_t)(i * 7);
    *out = (bf_frame){.index = i, .width = FW, .height = i == fs->wrong_size_at ? FH - 1 : FH,
                      .t_depth_s = i / 30.0, .t_rgb_s = i / 30.0, .depth = fs->depth, .rgb = fs->rgb};
    return BF_OK;
}

static void fake_close(rgbd_source *base)
{
    fake_source *fs = (fake_source *)base;
    if (fs->closed) atomic_store(fs->closed, 1);
    free(fs);
}

static const rgbd_source_ops fake_ops = {.next = fake_next, .close = fake_close};

static fake_source *fake_create(uint32_t n)
{
    fake_source *fs = calloc(1, sizeof *fs);
    if (!fs) return NULL;
    fs->base.ops = &fake_ops;
    fs->base.kind = "fake";
    fs->base.intrinsics = (bf_intrinsics){FW, FH, 30, 30, 15.5, 11.5, 1000};
    fs->n = n;
    fs->fail_at = UINT32_MAX;
    fs->wrong_size_at = UINT32_MAX;
    return fs;
}

/* The frame's pixels are the ones the fake wrote for its index. */
static bool frame_is_intact(const bf_frame *f)
{
    if (!f->rgb || f->width != FW || f->height != FH) return false;
    for (uint32_t p = 0; p < FW * FH; p++)
        if (f->depth[p] != (uint16_t)(f->index + 1)) return false;
    for (uint32_t p = 0; p < FW * FH * 3; p++)
        if (f->rgb[p] != (uint8_t)(f->index * 7)) return false;
    return true;
}

/* Polls until cond holds or about 10 s passed. */
#define WAIT_UNTIL(cond)                                                     \
    do {                                                                     \
        for (int _k = 0; _k < 10000 && !(cond); _k++) sleep_us(1000);        \
        CHECK(cond);                                                         \
    } while (0)

BF_TEST(full_queue_drops_the_oldest_and_keeps_the_newest)
{
    /* The consumer takes nothing until the thread has read all 50 frames:
     * a queue of 4 must then hold exactly the last 4, the other 46 dropped. */
    fake_source *fs = fake_create(50);
    CHECK(fs);
    rgbd_source *src;
    CHECK_OK(capture_threaded(&fs->base, 4, &src));
    CHECK_OK(capture_threaded_start(src));
    capture_thread_stats st;
    WAIT_UNTIL((st = capture_threaded_stats(src)).is_ended);
    CHECK_EQ_INT(st.captured, 50);
    CHECK_EQ_INT(st.dropped, 46);
    CHECK_EQ_INT(st.queued, 4);
    CHECK_EQ_INT(st.delivered, 0);
    bf_frame f;
    for (uint32_t k = 46; k < 50; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, k);
        CHECK(frame_is_intact(&f));
        CHECK_NEAR(f.t_depth_s, k / 30.0, 0);
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    st = capture_threaded_stats(src);
    CHECK_EQ_INT(st.delivered, 4);
    CHECK_EQ_INT(st.captured, st.delivered + st.dropped);
    /* The wrapper passes the source's description on. */
    CHECK(src->intrinsics.width == FW && src->intrinsics.fx_px == 30 && !strcmp(src->kind, "fake"));
    rgbd_source_close(src);
}

BF_TEST(the_thread_takes_no_frame_before_the_first_next)
{
    /* A consumer that gets ready after opening the camera (recon/ compiles
     * its pipelines) must find the first frame, not a queue of late ones. */
    for (int lossless = 0; lossless < 2; lossless++) {
        fake_source *fs = fake_create(50);
        CHECK(fs);
        rgbd_source *src;
        CHECK_OK(lossless ? capture_threaded_lossless(&fs->base, 4, &src) : capture_threaded(&fs->base, 4, &src));
        sleep_us(20000);
        capture_thread_stats st = capture_threaded_stats(src);
        CHECK_EQ_INT(st.captured, 0);
        CHECK(!st.is_ended);
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_is_intact(&f));
        /* Without drops the first frame is frame 0 (a dropping queue may
         * have moved on while this thread woke up). */
        if (lossless) CHECK_EQ_INT(f.index, 0);
        CHECK_OK(capture_threaded_start(src)); /* started already: nothing happens */
        rgbd_source_close(src);
    }
    CHECK_OK(capture_threaded_start(NULL));
}

BF_TEST(slow_consumer_gets_increasing_intact_frames_and_counts_add_up)
{
    /* A camera at 1 frame per 0.5 ms, a consumer taking 3 ms per frame: it
     * must see frames in order, each intact while held (the thread never
     * writes into the slot the consumer holds), and every captured frame
     * is either delivered or dropped. */
    fake_source *fs = fake_create(400);
    CHECK(fs);
    fs->delay_us = 500;
    rgbd_source *src;
    CHECK_OK(capture_threaded(&fs->base, 3, &src));
    bf_frame f;
    bf_status s;
    int64_t last = -1;
    uint32_t n = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        CHECK((int64_t)f.index > last);
        last = f.index;
        sleep_us(3000);
        CHECK(frame_is_intact(&f)); /* still intact after the wait */
        n++;
    }
    CHECK_STATUS(s, BF_END);
    capture_thread_stats st = capture_threaded_stats(src);
    CHECK_EQ_INT(st.captured, 400);
    CHECK_EQ_INT(st.delivered, n);
    CHECK_EQ_INT(st.captured, st.delivered + st.dropped);
    CHECK(st.dropped > 0);
    CHECK_EQ_INT(last, 399); /* the newest frame always survives */
    rgbd_source_close(src);
}

BF_TEST(lossless_mode_waits_for_the_consumer_instead_of_dropping)
{
    fake_source *fs = fake_create(60);
    CHECK(fs);
    rgbd_source *src;
    CHECK_OK(capture_threaded_lossless(&fs->base, 2, &src));
    bf_frame f;
    for (uint32_t k = 0; k < 60; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, k);
        if (k % 10 == 0) sleep_us(2000);
        CHECK(frame_is_intact(&f));
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    capture_thread_stats st = capture_threaded_stats(src);
    CHECK_EQ_INT(st.dropped, 0);
    CHECK_EQ_INT(st.delivered, 60);
    rgbd_source_close(src);
}

BF_TEST(source_error_arrives_after_the_frames_before_it_with_its_message)
{
    fake_source *fs = fake_create(20);
    CHECK(fs);
    fs->fail_at = 5;
    rgbd_source *src;
    CHECK_OK(capture_threaded_lossless(&fs->base, 8, &src));
    bf_frame f;
    for (uint32_t k = 0; k < 5; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, k);
    }
    bf_clear_error();
    CHECK_STATUS(rgbd_source_next(src, &f), BF_FORMAT);
    /* The message was recorded on the capture thread and travels over. */
    CHECK_ERROR_MENTIONS("fake: frame 5: broken on purpose");
    rgbd_source_close(src);
}

BF_TEST(frame_of_another_size_ends_the_stream_with_format_error)
{
    fake_source *fs = fake_create(10);
    CHECK(fs);
    fs->wrong_size_at = 3;
    rgbd_source *src;
    CHECK_OK(capture_threaded_lossless(&fs->base, 8, &src));
    bf_frame f;
    for (uint32_t k = 0; k < 3; k++) CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_FORMAT);
    CHECK_ERROR_MENTIONS("frame 3 is 32x23");
    rgbd_source_close(src);
}

static rgbd_source *volatile g_stop_src;
static void on_sigint(int sig)
{
    (void)sig;
    capture_threaded_stop(g_stop_src);
}

BF_TEST(stop_from_a_signal_handler_drains_the_queue_then_ends)
{
    /* An endless camera at 1 frame per ms; SIGINT's handler asks for the
     * stop. next() then delivers what was queued and returns BF_END, and
     * close joins the thread and closes the camera. */
    fake_source *fs = fake_create(UINT32_MAX);
    CHECK(fs);
    fs->delay_us = 1000;
    atomic_int closed = 0;
    fs->closed = &closed;
    rgbd_source *src;
    CHECK_OK(capture_threaded(&fs->base, 4, &src));
    struct sigaction sa = {.sa_handler = on_sigint}, old;
    sigemptyset(&sa.sa_mask);
    CHECK(sigaction(SIGINT, &sa, &old) == 0);
    g_stop_src = src;
    bf_frame f;
    bf_status s;
    uint32_t n = 0;
    double t_stop = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        CHECK(frame_is_intact(&f));
        if (++n == 10) {
            raise(SIGINT);
            t_stop = bf_time_s();
        }
        CHECK(n < 100000);
    }
    double waited = bf_time_s() - t_stop;
    sigaction(SIGINT, &old, NULL);
    g_stop_src = NULL;
    CHECK_STATUS(s, BF_END);
    CHECK(n >= 10);
    CHECK_LE(waited, 2.0); /* the stop grace is 1 s; a frame takes 1 ms */
    capture_thread_stats st = capture_threaded_stats(src);
    CHECK(st.is_ended);
    CHECK_EQ_INT(st.delivered, n);
    CHECK_EQ_INT(st.captured, st.delivered + st.dropped);
    rgbd_source_close(src);
    CHECK_EQ_INT(atomic_load(&closed), 1);
}

BF_TEST(close_while_the_thread_waits_for_space_does_not_hang)
{
    fake_source *fs = fake_create(100);
    CHECK(fs);
    rgbd_source *src;
    CHECK_OK(capture_threaded_lossless(&fs->base, 1, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f)); /* the thread now fills the queue and waits */
    WAIT_UNTIL(capture_threaded_stats(src).queued == 1);
    rgbd_source_close(src);
    /* And closing a fresh, unread one, running and never started. */
    fs = fake_create(UINT32_MAX);
    CHECK(fs);
    CHECK_OK(capture_threaded(&fs->base, 2, &src));
    CHECK_OK(capture_threaded_start(src));
    rgbd_source_close(src);
    fs = fake_create(UINT32_MAX);
    CHECK(fs);
    CHECK_OK(capture_threaded(&fs->base, 2, &src));
    rgbd_source_close(src);
}

BF_TEST(bad_arguments_leave_the_source_with_the_caller)
{
    fake_source *fs = fake_create(1);
    CHECK(fs);
    rgbd_source *src = NULL;
    CHECK_STATUS(capture_threaded(&fs->base, 0, &src), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("capacity 0");
    CHECK(src == NULL);
    fs->base.intrinsics.width = 0;
    CHECK_STATUS(capture_threaded(&fs->base, 2, &src), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("frame size of 0x24");
    /* Not a threaded source: the stats are zero and stop is a no-op. */
    capture_thread_stats st = capture_threaded_stats(&fs->base);
    CHECK_EQ_INT(st.captured, 0);
    capture_threaded_stop(&fs->base);
    capture_threaded_stop(NULL);
    rgbd_source_close(&fs->base); /* still ours */
}
