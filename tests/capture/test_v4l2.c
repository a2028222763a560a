/* The V4L2 backend against a fake device behind capture_v4l2_io: format
 * negotiation, the mmap buffer queue, dropped buffers, an unplugged device
 * and colour conversion. The fake keeps the kernel's contract as the V4L2
 * API documents it (ENUM_FMT ends with EINVAL, S_FMT adjusts rather than
 * fails, DQBUF on an empty queue is EAGAIN for non-blocking descriptors,
 * ENODEV once the device is gone). */
#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <sys/mman.h>

#include "capture/v4l2_io.h"
#include "test.h"

#define FAKE_FD0 1000
#define FAKE_MAX 2
#define FAKE_PAD 32u /* bytes of row padding, so strides are exercised */

typedef struct fake_node {
    const char *path;
    uint32_t formats[8], n_formats;
    uint32_t width, height, pixfmt;
    uint8_t *mem[CAPTURE_V4L2_N_BUFFERS];
    uint32_t n_buf, len;
    bool is_queued[CAPTURE_V4L2_N_BUFFERS];
    uint32_t next_buf; /* round-robin over queued buffers, as the driver fills */
    bool is_open, is_streaming;
    uint32_t seq;          /* sequence number of the next frame */
    uint32_t drop_seq;     /* this sequence number never reaches the reader (0 = none) */
    uint32_t vanish_after; /* DQBUFs that succeed before ENODEV (0 = never) */
    uint32_t n_dequeued;
    int n_mmap, n_munmap;
    uint32_t reqbufs_count; /* what the backend asked for */
} fake_node;

static fake_node fake[FAKE_MAX];

static fake_node *fake_of(int fd)
{
    return fd >= FAKE_FD0 && fd < FAKE_FD0 + FAKE_MAX && fake[fd - FAKE_FD0].is_open ? &fake[fd - FAKE_FD0] : NULL;
}

/* The colour node (fake[1]) runs no faster than the depth node: a frame
 * exists once the depth frame of the same time does, as with real clocks. */
static bool fake_has_frame(const fake_node *n)
{
    return n != &fake[1] || n->seq < fake[0].seq;
}

static uint32_t bpp_of(uint32_t f) { return f == V4L2_PIX_FMT_Z16 || f == V4L2_PIX_FMT_YUYV ? 2 : 3; }
static uint32_t stride_of(const fake_node *n) { return n->width * bpp_of(n->pixfmt) + FAKE_PAD; }

static int fake_open(const char *path, int flags)
{
    (void)flags;
    for (int i = 0; i < FAKE_MAX; i++)
        if (fake[i].path && !strcmp(fake[i].path, path)) {
            fake[i].is_open = true;
            return FAKE_FD0 + i;
        }
    errno = ENOENT;
    return -1;
}

static int fake_close(int fd)
{
    fake_node *n = fake_of(fd);
    if (!n) return errno = EBADF, -1;
    n->is_open = false;
    return 0;
}

/* Pixel (x, y) of frame seq: a depth in mm that names both. */
static uint16_t fake_depth(uint32_t seq, uint32_t x, uint32_t y) { return (uint16_t)(500 + 100 * seq + x + y); }

static void fake_fill(fake_node *n, uint32_t buf, uint32_t seq)
{
    uint32_t stride = stride_of(n);
    for (uint32_t y = 0; y < n->height; y++) {
        uint8_t *row = n->mem[buf] + (size_t)y * stride;
        memset(row + n->width * bpp_of(n->pixfmt), 0xEE, FAKE_PAD); /* padding must not leak into frames */
        for (uint32_t x = 0; x < n->width; x++) {
            if (n->pixfmt == V4L2_PIX_FMT_Z16) {
                uint16_t d = fake_depth(seq, x, y);
                memcpy(row + 2 * x, &d, 2);
            } else if (n->pixfmt == V4L2_PIX_FMT_YUYV) {
                row[2 * x] = (uint8_t)(16 + seq); /* Y */
                row[2 * x + 1] = 128;             /* U or V: grey */
            } else {
                row[3 * x] = (uint8_t)seq, row[3 * x + 1] = (uint8_t)x, row[3 * x + 2] = (uint8_t)y;
            }
        }
    }
}

static int fake_ioctl(int fd, unsigned long req, void *arg)
{
    fake_node *n = fake_of(fd);
    if (!n) return errno = EBADF, -1;
    /* Unplugged: from the next DQBUF on (QBUF of the last good buffer
     * still succeeds, as it raced with the unplug). */
    if (n->vanish_after && n->n_dequeued >= n->vanish_after && req == VIDIOC_DQBUF) return errno = ENODEV, -1;
    switch (req) {
    case VIDIOC_QUERYCAP: {
        struct v4l2_capability *c = arg;
        memset(c, 0, sizeof *c);
        snprintf((char *)c->card, sizeof c->card, "fake %s", n->path);
        snprintf((char *)c->bus_info, sizeof c->bus_info, "usb-fake-1");
        c->capabilities = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING | V4L2_CAP_DEVICE_CAPS;
        c->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
        return 0;
    }
    case VIDIOC_ENUM_FMT: {
        struct v4l2_fmtdesc *d = arg;
        if (d->type != V4L2_BUF_TYPE_VIDEO_CAPTURE || d->index >= n->n_formats) return errno = EINVAL, -1;
        d->pixelformat = n->formats[d->index];
        return 0;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT: {
        struct v4l2_format *f = arg;
        if (req == VIDIOC_S_FMT) {
            if (n->n_buf) return errno = EBUSY, -1;
            for (uint32_t i = 0; i < n->n_formats; i++)
                if (n->formats[i] == f->fmt.pix.pixelformat) n->pixfmt = f->fmt.pix.pixelformat;
        }
        f->fmt.pix.width = n->width;
        f->fmt.pix.height = n->height;
        f->fmt.pix.pixelformat = n->pixfmt;
        f->fmt.pix.bytesperline = stride_of(n);
        f->fmt.pix.sizeimage = stride_of(n) * n->height;
        return 0;
    }
    case VIDIOC_REQBUFS: {
        struct v4l2_requestbuffers *rb = arg;
        if (rb->memory != V4L2_MEMORY_MMAP) return errno = EINVAL, -1;
        for (uint32_t i = 0; i < n->n_buf; i++) free(n->mem[i]);
        n->n_buf = 0;
        if (rb->count == 0) return 0;
        n->reqbufs_count = rb->count;
        n->n_buf = rb->count < CAPTURE_V4L2_N_BUFFERS ? rb->count : CAPTURE_V4L2_N_BUFFERS;
        n->len = stride_of(n) * n->height;
        for (uint32_t i = 0; i < n->n_buf; i++) {
            n->mem[i] = calloc(1, n->len);
            n->is_queued[i] = false;
        }
        rb->count = n->n_buf;
        return 0;
    }
    case VIDIOC_QUERYBUF:
    case VIDIOC_QBUF: {
        struct v4l2_buffer *b = arg;
        if (b->index >= n->n_buf) return errno = EINVAL, -1;
        if (req == VIDIOC_QUERYBUF) {
            b->length = n->len;
            b->m.offset = b->index * 4096u;
        } else {
            if (n->is_queued[b->index]) return errno = EINVAL, -1;
            n->is_queued[b->index] = true;
        }
        return 0;
    }
    case VIDIOC_STREAMON: n->is_streaming = true; return 0;
    case VIDIOC_STREAMOFF: n->is_streaming = false; return 0;
    case VIDIOC_DQBUF: {
        struct v4l2_buffer *b = arg;
        if (!n->is_streaming) return errno = EINVAL, -1;
        if (!fake_has_frame(n)) return errno = EAGAIN, -1;
        for (uint32_t k = 0; k < n->n_buf; k++) {
            uint32_t i = (n->next_buf + k) % n->n_buf;
            if (!n->is_queued[i]) continue;
            if (n->drop_seq && n->seq == n->drop_seq) n->seq++; /* the driver lost it */
            fake_fill(n, i, n->seq);
            n->is_queued[i] = false;
            n->next_buf = (i + 1) % n->n_buf;
            b->index = i;
            b->bytesused = n->len;
            b->sequence = n->seq;
            b->flags = V4L2_BUF_FLAG_MAPPED | V4L2_BUF_FLAG_DONE | V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
            /* 30 Hz from t = 100 s. */
            uint64_t us = 100000000ull + (uint64_t)n->seq * 33333ull;
            b->timestamp.tv_sec = (time_t)(us / 1000000);
            b->timestamp.tv_usec = (suseconds_t)(us % 1000000);
            n->seq++;
            n->n_dequeued++;
            return 0;
        }
        return errno = EAGAIN, -1;
    }
    default: return errno = ENOTTY, -1;
    }
}

static void *fake_mmap(void *addr, size_t len, int prot, int flags, int fd, off_t off)
{
    (void)addr, (void)prot, (void)flags;
    fake_node *n = fake_of(fd);
    uint32_t i = (uint32_t)(off / 4096);
    if (!n || i >= n->n_buf || len != n->len) return errno = EINVAL, MAP_FAILED;
    n->n_mmap++;
    return n->mem[i];
}

static int fake_munmap(void *addr, size_t len)
{
    (void)len;
    for (int k = 0; k < FAKE_MAX; k++)
        for (uint32_t i = 0; i < CAPTURE_V4L2_N_BUFFERS; i++)
            if (fake[k].mem[i] == addr) {
                fake[k].n_munmap++;
                return 0;
            }
    return errno = EINVAL, -1;
}

static int fake_poll(struct pollfd *fds, nfds_t nfds, int timeout_ms)
{
    (void)timeout_ms;
    int ready = 0;
    for (nfds_t i = 0; i < nfds; i++) {
        fake_node *n = fake_of(fds[i].fd);
        fds[i].revents = 0;
        if (!n) {
            fds[i].revents = POLLNVAL;
        } else if (n->vanish_after && n->n_dequeued >= n->vanish_after) {
            fds[i].revents = POLLERR;
        } else if (n->is_streaming && fake_has_frame(n)) {
            for (uint32_t b = 0; b < n->n_buf; b++)
                if (n->is_queued[b]) fds[i].revents = POLLIN;
        }
        if (fds[i].revents) ready++;
    }
    return ready;
}

static const capture_v4l2_io fake_io = {fake_open, fake_close, fake_ioctl, fake_mmap, fake_munmap, fake_poll};

static void fake_reset(void)
{
    for (int k = 0; k < FAKE_MAX; k++) {
        for (uint32_t i = 0; i < fake[k].n_buf; i++) free(fake[k].mem[i]);
        memset(&fake[k], 0, sizeof fake[k]);
    }
}

static void fake_depth_node(const uint32_t *formats, uint32_t n_formats)
{
    fake_reset();
    fake[0].path = "/dev/fake-depth";
    memcpy(fake[0].formats, formats, n_formats * sizeof *formats);
    fake[0].n_formats = n_formats;
    fake[0].width = 64;
    fake[0].height = 48;
    fake[0].pixfmt = formats[0];
}

static bf_status fake_open_source(const char *target, rgbd_source **out)
{
    char uri[128];
    snprintf(uri, sizeof uri, "v4l2:%s", target);
    capture__uri_options opt = {0};
    return capture__v4l2_open_io(&fake_io, uri, target, &opt, out);
}

/* Frame f must hold frame seq of the fake, without row padding. */
static bool frame_is_seq(const bf_frame *f, uint32_t seq)
{
    for (uint32_t y = 0; y < f->height; y++)
        for (uint32_t x = 0; x < f->width; x++)
            if (f->depth[y * f->width + x] != fake_depth(seq, x, y)) return false;
    return true;
}

BF_TEST(v4l2_negotiation_picks_z16_among_several)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_Z16, V4L2_PIX_FMT_MJPEG};
    fake_depth_node(formats, 4);
    rgbd_source *src = NULL;
    CHECK_OK(fake_open_source("/dev/fake-depth", &src));
    CHECK_EQ_INT(fake[0].pixfmt, V4L2_PIX_FMT_Z16);
    CHECK_EQ_INT(src->intrinsics.width, 64);
    CHECK_EQ_INT(src->intrinsics.height, 48);
    CHECK_NEAR(src->intrinsics.depth_scale, 1000, 0);
    CHECK_EQ_INT(src->n_frames, 0);
    CHECK(!strcmp(src->kind, "v4l2"));
    rgbd_source_close(src);
    CHECK(!fake[0].is_open);
    fake_reset();
}

BF_TEST(v4l2_device_without_depth_format_is_clear_error)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG};
    fake_depth_node(formats, 2);
    rgbd_source *src = NULL;
    CHECK_STATUS(fake_open_source("/dev/fake-depth", &src), BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("/dev/fake-depth");
    CHECK_ERROR_MENTIONS("'Z16 '");
    CHECK_ERROR_MENTIONS("'YUYV', 'MJPG'");
    CHECK(src == NULL);
    CHECK(!fake[0].is_open); /* nothing leaked on the way out */
    fake_reset();
}

BF_TEST(v4l2_buffer_queue_streams_frames_in_order)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_Z16};
    fake_depth_node(formats, 1);
    rgbd_source *src = NULL;
    CHECK_OK(fake_open_source("/dev/fake-depth", &src));
    CHECK_EQ_INT(fake[0].reqbufs_count, CAPTURE_V4L2_N_BUFFERS);
    CHECK_EQ_INT(fake[0].n_mmap, CAPTURE_V4L2_N_BUFFERS);
    CHECK(fake[0].is_streaming);
    for (uint32_t i = 0; i < 10; i++) {
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, i);
        CHECK(frame_is_seq(&f, i));
        CHECK(f.rgb == NULL);
        /* The driver's monotonic timestamps, 30 Hz from 100 s. */
        CHECK_NEAR(f.t_depth_s, 100.0 + i * 0.033333, 1e-6);
        CHECK_NEAR(f.t_rgb_s, f.t_depth_s, 0);
        /* Every buffer but none is back in the driver's queue. */
        uint32_t n_queued = 0;
        for (uint32_t b = 0; b < fake[0].n_buf; b++) n_queued += fake[0].is_queued[b];
        CHECK_EQ_INT(n_queued, fake[0].n_buf);
    }
    CHECK_EQ_INT(capture__v4l2_dropped_frames(src), 0);
    rgbd_source_close(src);
    CHECK_EQ_INT(fake[0].n_munmap, fake[0].n_mmap);
    CHECK(!fake[0].is_streaming && !fake[0].is_open);
    fake_reset();
}

BF_TEST(v4l2_dropped_buffer_is_counted)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_Z16};
    fake_depth_node(formats, 1);
    fake[0].drop_seq = 3;
    rgbd_source *src = NULL;
    CHECK_OK(fake_open_source("/dev/fake-depth", &src));
    const uint32_t seq_of[] = {0, 1, 2, 4, 5, 6};
    for (uint32_t i = 0; i < 6; i++) {
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, i); /* our indices stay dense; the gap shows in time */
        CHECK(frame_is_seq(&f, seq_of[i]));
        CHECK_NEAR(f.t_depth_s, 100.0 + seq_of[i] * 0.033333, 1e-6);
    }
    CHECK_EQ_INT(capture__v4l2_dropped_frames(src), 1);
    rgbd_source_close(src);
    fake_reset();
}

BF_TEST(v4l2_device_unplugged_mid_stream_is_clear_error)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_Z16};
    fake_depth_node(formats, 1);
    fake[0].vanish_after = 4;
    rgbd_source *src = NULL;
    CHECK_OK(fake_open_source("/dev/fake-depth", &src));
    bf_frame f;
    for (uint32_t i = 0; i < 4; i++) CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("/dev/fake-depth");
    CHECK_ERROR_MENTIONS("frame 4");
    CHECK_ERROR_MENTIONS("disappeared");
    /* Asking again keeps failing the same way, and closing is clean. */
    CHECK_STATUS(rgbd_source_next(src, &f), BF_NO_DEVICE);
    rgbd_source_close(src);
    CHECK_EQ_INT(fake[0].n_munmap, fake[0].n_mmap);
    CHECK(!fake[0].is_open);
    fake_reset();
}

BF_TEST(v4l2_colour_node_yuyv_is_converted)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_Z16};
    fake_depth_node(formats, 1);
    fake[1].path = "/dev/fake-colour";
    fake[1].formats[0] = V4L2_PIX_FMT_MJPEG;
    fake[1].formats[1] = V4L2_PIX_FMT_YUYV;
    fake[1].n_formats = 2;
    fake[1].width = 32; /* half the depth size: resized, not registered */
    fake[1].height = 24;
    fake[1].pixfmt = V4L2_PIX_FMT_MJPEG;
    rgbd_source *src = NULL;
    CHECK_OK(fake_open_source("/dev/fake-depth,/dev/fake-colour", &src));
    CHECK_EQ_INT(fake[1].pixfmt, V4L2_PIX_FMT_YUYV);
    bf_frame f;
    for (int i = 0; i < 3; i++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(f.rgb != NULL);
    }
    /* Grey Y = 16 + seq: (Y - 16) * 1.164 = 1.164 * seq; the newest
     * colour frame is taken each time, at most a few sequence numbers on. */
    CHECK(f.rgb[0] == f.rgb[1] && f.rgb[1] == f.rgb[2]);
    CHECK(f.rgb[(f.width * f.height - 1) * 3] == f.rgb[0]);
    CHECK(f.t_rgb_s >= 100.0);
    rgbd_source_close(src);
    CHECK(!fake[0].is_open && !fake[1].is_open);
    fake_reset();
}

BF_TEST(v4l2_missing_colour_node_releases_depth)
{
    const uint32_t formats[] = {V4L2_PIX_FMT_Z16};
    fake_depth_node(formats, 1);
    rgbd_source *src = NULL;
    CHECK_STATUS(fake_open_source("/dev/fake-depth,/dev/fake-nothing", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("/dev/fake-nothing");
    CHECK_ERROR_MENTIONS("colour");
    CHECK(!fake[0].is_open);
    CHECK_EQ_INT(fake[0].n_munmap, fake[0].n_mmap);
    fake_reset();
}
