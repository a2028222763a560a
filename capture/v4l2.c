/* capture: Video4Linux2 depth cameras (UVC devices that expose depth as
 * V4L2_PIX_FMT_Z16, such as Intel RealSense D400/SR300 through the uvcvideo
 * driver, and some Orbbec models), with an optional colour node.
 *
 * Streaming is the classic memory-mapped ring (V4L2 API, "Streaming I/O
 * (Memory Mapping)"): REQBUFS, QUERYBUF + mmap per buffer, QBUF all,
 * STREAMON; each frame is poll + DQBUF, copy out, QBUF back. All system
 * calls go through capture_v4l2_io (v4l2_io.h) so tests can fake a device.
 *
 * Timestamps: the driver's buffer timestamp when it says the clock is
 * CLOCK_MONOTONIC (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, uvcvideo's default:
 * the time the first USB packet of the frame arrived), else the monotonic
 * clock when the frame was dequeued. Both are bf_time_s()'s clock. */
#include "v4l2_io.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

/* ------------------------------------------------------------ system calls */

static int sys_open(const char *path, int flags) { return open(path, flags); }
static int sys_ioctl(int fd, unsigned long request, void *arg)
{
    int r;
    do r = ioctl(fd, request, arg);
    while (r == -1 && errno == EINTR);
    return r;
}
static int sys_poll(struct pollfd *fds, nfds_t nfds, int timeout_ms) { return poll(fds, nfds, timeout_ms); }

static const capture_v4l2_io v4l2_io_system = {
    .open = sys_open, .close = close, .ioctl = sys_ioctl, .mmap = mmap, .munmap = munmap, .poll = sys_poll};

const capture_v4l2_io *capture__v4l2_io_system(void) { return &v4l2_io_system; }

/* ------------------------------------------------------------ one node */

typedef struct v4l2_node {
    int fd; /* -1 when closed */
    const char *path;
    const char *role; /* "depth" | "colour", for messages */
    uint32_t pixfmt, width, height, stride;
    void *buf[CAPTURE_V4L2_N_BUFFERS];
    size_t buf_len[CAPTURE_V4L2_N_BUFFERS];
    uint32_t n_buf;
    bool is_streaming;
} v4l2_node;

typedef struct v4l2_source {
    rgbd_source base;
    const capture_v4l2_io *io;
    char uri[512];
    char depth_path[256], colour_path[256];
    v4l2_node depth, colour;
    bool has_colour;
    uint16_t *depth_px;
    uint8_t *rgb_px;        /* on the depth grid, what frames point to */
    uint8_t *rgb_native;    /* colour at its own size, before resizing */
    bool has_rgb_frame;
    double t_rgb_s;
    uint32_t index;
    bool has_seq;
    uint32_t last_seq;
    uint64_t dropped;
} v4l2_source;

static const rgbd_source_ops v4l2_ops;

static void fourcc_str(uint32_t f, char out[5])
{
    for (int i = 0; i < 4; i++) {
        char c = (char)((f >> (8 * i)) & 0xff);
        out[i] = c >= 32 && c < 127 ? c : '?';
    }
    out[4] = 0;
}

/* Opening a node that is not there or not ours is "no device"; the message
 * says which and how to fix permissions (docs/devices.md). */
static bf_status node_open_fail(const char *uri, const v4l2_node *n, int err)
{
    if (err == EACCES || err == EPERM)
        return bf_fail(BF_NO_DEVICE, "%s: cannot open %s node %s: %s (add your user to group 'video', see "
                                     "docs/devices.md)",
                       uri, n->role, n->path, strerror(err));
    return bf_fail(BF_NO_DEVICE, "%s: cannot open %s node %s: %s", uri, n->role, n->path, strerror(err));
}

/* Opens the node, checks it captures by streaming and negotiates the first
 * format of want[] it offers. */
static bf_status node_open(const capture_v4l2_io *io, const char *uri, v4l2_node *n, const uint32_t *want,
                           uint32_t n_want)
{
    n->fd = io->open(n->path, O_RDWR | O_NONBLOCK);
    if (n->fd < 0) return node_open_fail(uri, n, errno);
    struct v4l2_capability cap = {0};
    if (io->ioctl(n->fd, VIDIOC_QUERYCAP, &cap) < 0)
        return bf_fail(BF_NO_DEVICE, "%s: %s is not a V4L2 device (VIDIOC_QUERYCAP: %s)", uri, n->path,
                       strerror(errno));
    uint32_t caps = cap.capabilities & V4L2_CAP_DEVICE_CAPS ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE) || !(caps & V4L2_CAP_STREAMING))
        return bf_fail(BF_UNSUPPORTED, "%s: %s (%.32s) is not a streaming video capture node", uri, n->path,
                       (const char *)cap.card);

    /* The formats it offers, for the choice and for the message. */
    char offered[256] = "";
    size_t off_len = 0;
    uint32_t chosen = 0, chosen_rank = n_want;
    for (uint32_t i = 0;; i++) {
        struct v4l2_fmtdesc d = {.index = i, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
        if (io->ioctl(n->fd, VIDIOC_ENUM_FMT, &d) < 0) {
            if (errno == EINVAL) break; /* the end of the list */
            return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_ENUM_FMT: %s", uri, n->path, strerror(errno));
        }
        char cc[5];
        fourcc_str(d.pixelformat, cc);
        if (off_len + 8 < sizeof offered) off_len += (size_t)snprintf(offered + off_len, sizeof offered - off_len,
                                                                      "%s'%s'", off_len ? ", " : "", cc);
        for (uint32_t k = 0; k < chosen_rank; k++)
            if (d.pixelformat == want[k]) chosen = want[k], chosen_rank = k;
    }
    if (chosen_rank == n_want) {
        char w[64] = "";
        size_t wl = 0;
        for (uint32_t k = 0; k < n_want; k++) {
            char cc[5];
            fourcc_str(want[k], cc);
            wl += (size_t)snprintf(w + wl, sizeof w - wl, "%s'%s'", k ? ", " : "", cc);
        }
        return bf_fail(BF_UNSUPPORTED, "%s: %s (%.32s) offers no %s format bitfuse reads (wants %s; offers %s)",
                       uri, n->path, (const char *)cap.card, n->role, w, off_len ? offered : "none");
    }

    /* Keep the driver's current size, change only the pixel format. */
    struct v4l2_format f = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
    if (io->ioctl(n->fd, VIDIOC_G_FMT, &f) < 0)
        return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_G_FMT: %s", uri, n->path, strerror(errno));
    f.fmt.pix.pixelformat = chosen;
    f.fmt.pix.field = V4L2_FIELD_NONE;
    if (io->ioctl(n->fd, VIDIOC_S_FMT, &f) < 0)
        return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_S_FMT: %s", uri, n->path, strerror(errno));
    char cc[5];
    fourcc_str(chosen, cc);
    if (f.fmt.pix.pixelformat != chosen || f.fmt.pix.width == 0 || f.fmt.pix.height == 0) {
        char got[5];
        fourcc_str(f.fmt.pix.pixelformat, got);
        return bf_fail(BF_UNSUPPORTED, "%s: %s: asked for '%s', driver set '%s' %ux%u", uri, n->path, cc, got,
                       f.fmt.pix.width, f.fmt.pix.height);
    }
    if (f.fmt.pix.width > CAPTURE_V4L2_MAX_SIDE || f.fmt.pix.height > CAPTURE_V4L2_MAX_SIDE)
        return bf_fail(BF_FORMAT, "%s: %s: driver reports '%s' %ux%u, outside 1..%u a side", uri, n->path, cc,
                       f.fmt.pix.width, f.fmt.pix.height, CAPTURE_V4L2_MAX_SIDE);
    uint32_t bpp = chosen == V4L2_PIX_FMT_Z16 || chosen == V4L2_PIX_FMT_YUYV ? 2 : 3;
    n->pixfmt = chosen;
    n->width = f.fmt.pix.width;
    n->height = f.fmt.pix.height;
    n->stride = f.fmt.pix.bytesperline ? f.fmt.pix.bytesperline : f.fmt.pix.width * bpp;
    if (n->stride < n->width * bpp)
        return bf_fail(BF_FORMAT, "%s: %s: driver reports %u bytes per line for %u pixels of '%s'", uri, n->path,
                       n->stride, n->width, cc);
    bf_debug("%s: %s node %s: '%s' %ux%u, %u bytes per line", uri, n->role, n->path, cc, n->width, n->height,
             n->stride);
    return BF_OK;
}

/* Bytes a whole frame of n takes in a buffer: the last row needs no
 * padding. */
static size_t node_frame_bytes(const v4l2_node *n)
{
    size_t bpp = n->pixfmt == V4L2_PIX_FMT_Z16 || n->pixfmt == V4L2_PIX_FMT_YUYV ? 2 : 3;
    return (size_t)n->stride * (n->height - 1) + (size_t)n->width * bpp;
}

static bf_status node_start(const capture_v4l2_io *io, const char *uri, v4l2_node *n)
{
    struct v4l2_requestbuffers rb = {
        .count = CAPTURE_V4L2_N_BUFFERS, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
    if (io->ioctl(n->fd, VIDIOC_REQBUFS, &rb) < 0)
        return bf_fail(errno == EINVAL ? BF_UNSUPPORTED : BF_NO_DEVICE,
                       "%s: %s: VIDIOC_REQBUFS (memory-mapped streaming): %s", uri, n->path, strerror(errno));
    /* The driver may grant fewer; with one buffer every frame would wait
     * for the copy, so two is the least that streams. */
    if (rb.count < 2 || rb.count > CAPTURE_V4L2_N_BUFFERS)
        return bf_fail(BF_UNSUPPORTED, "%s: %s: driver granted %u buffers (need 2 to %u)", uri, n->path, rb.count,
                       CAPTURE_V4L2_N_BUFFERS);
    for (uint32_t i = 0; i < rb.count; i++) {
        struct v4l2_buffer b = {.index = i, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        if (io->ioctl(n->fd, VIDIOC_QUERYBUF, &b) < 0)
            return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_QUERYBUF %u: %s", uri, n->path, i, strerror(errno));
        if (b.length < node_frame_bytes(n))
            return bf_fail(BF_FORMAT, "%s: %s: buffer %u holds %u bytes, too few for %ux%u", uri, n->path, i,
                           b.length, n->width, n->height);
        void *p = io->mmap(NULL, b.length, PROT_READ | PROT_WRITE, MAP_SHARED, n->fd, (off_t)b.m.offset);
        if (p == MAP_FAILED)
            return bf_fail(BF_NO_MEMORY, "%s: %s: mmap of buffer %u (%u bytes): %s", uri, n->path, i, b.length,
                           strerror(errno));
        n->buf[i] = p;
        n->buf_len[i] = b.length;
        n->n_buf = i + 1;
        if (io->ioctl(n->fd, VIDIOC_QBUF, &b) < 0)
            return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_QBUF %u: %s", uri, n->path, i, strerror(errno));
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (io->ioctl(n->fd, VIDIOC_STREAMON, &type) < 0)
        return bf_fail(BF_NO_DEVICE, "%s: %s: VIDIOC_STREAMON: %s", uri, n->path, strerror(errno));
    n->is_streaming = true;
    return BF_OK;
}

/* Errors are ignored: the device may be gone already, and closing must
 * still release every mapping and the descriptor. */
static void node_close(const capture_v4l2_io *io, v4l2_node *n)
{
    if (n->fd < 0) return;
    if (n->is_streaming) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        io->ioctl(n->fd, VIDIOC_STREAMOFF, &type);
    }
    for (uint32_t i = 0; i < n->n_buf; i++) io->munmap(n->buf[i], n->buf_len[i]);
    if (n->n_buf) {
        struct v4l2_requestbuffers rb = {.count = 0, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        io->ioctl(n->fd, VIDIOC_REQBUFS, &rb);
    }
    io->close(n->fd);
    n->fd = -1;
    n->n_buf = 0;
    n->is_streaming = false;
}

/* The device vanished (unplugged, driver unbound): the kernel answers
 * ENODEV from then on. */
static bf_status node_lost(const v4l2_source *s, const v4l2_node *n, const char *what, int err)
{
    if (err == ENODEV || err == ENXIO || err == EIO)
        return bf_fail(BF_NO_DEVICE, "%s: frame %u: %s node %s disappeared (%s: %s)", s->uri, s->index, n->role,
                       n->path, what, strerror(err));
    return bf_fail(BF_IO, "%s: frame %u: %s node %s: %s: %s", s->uri, s->index, n->role, n->path, what,
                   strerror(err));
}

/* Dequeues one filled buffer, waiting up to timeout_ms. *got = false on
 * timeout. A buffer the driver marks as broken (V4L2_BUF_FLAG_ERROR) is
 * given back and counts as not received. */
static bf_status node_dequeue(v4l2_source *s, v4l2_node *n, int timeout_ms, struct v4l2_buffer *b, bool *got)
{
    const capture_v4l2_io *io = s->io;
    *got = false;
    for (;;) {
        struct pollfd pfd = {.fd = n->fd, .events = POLLIN};
        int r = io->poll(&pfd, 1, timeout_ms);
        if (r < 0) {
            if (errno == EINTR) continue;
            return node_lost(s, n, "poll", errno);
        }
        if (r == 0) return BF_OK;
        /* POLLERR / POLLHUP: DQBUF below reports the reason in errno. */
        memset(b, 0, sizeof *b);
        b->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b->memory = V4L2_MEMORY_MMAP;
        if (io->ioctl(n->fd, VIDIOC_DQBUF, b) < 0) {
            if (errno == EAGAIN && !(pfd.revents & (POLLERR | POLLHUP))) continue;
            return node_lost(s, n, "VIDIOC_DQBUF", errno == EAGAIN ? ENODEV : errno);
        }
        if (b->index >= n->n_buf) return bf_fail(BF_IO, "%s: %s: driver returned buffer %u of %u", s->uri, n->path,
                                                 b->index, n->n_buf);
        if (b->bytesused > n->buf_len[b->index])
            return bf_fail(BF_IO, "%s: %s: driver reports %u bytes used in buffer %u of %zu bytes", s->uri, n->path,
                           b->bytesused, b->index, n->buf_len[b->index]);
        if (b->flags & V4L2_BUF_FLAG_ERROR) {
            bf_debug("%s: %s: buffer %u (sequence %u) marked broken; skipped", s->uri, n->path, b->index,
                     b->sequence);
            if (io->ioctl(n->fd, VIDIOC_QBUF, b) < 0) return node_lost(s, n, "VIDIOC_QBUF", errno);
            continue;
        }
        *got = true;
        return BF_OK;
    }
}

static bf_status node_requeue(v4l2_source *s, v4l2_node *n, struct v4l2_buffer *b)
{
    if (s->io->ioctl(n->fd, VIDIOC_QBUF, b) < 0) return node_lost(s, n, "VIDIOC_QBUF", errno);
    return BF_OK;
}

static double buffer_time_s(const struct v4l2_buffer *b)
{
    if ((b->flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC &&
        (b->timestamp.tv_sec || b->timestamp.tv_usec))
        return (double)b->timestamp.tv_sec + (double)b->timestamp.tv_usec * 1e-6;
    return bf_time_s();
}

/* Converts the colour buffer into rgb_px on the depth grid. */
static bf_status colour_take(v4l2_source *s, const struct v4l2_buffer *b)
{
    v4l2_node *n = &s->colour;
    size_t need = node_frame_bytes(n);
    if (b->bytesused < need) {
        bf_debug("%s: %s: colour buffer of %u bytes, expected %zu; kept the previous colour", s->uri, n->path,
                 b->bytesused, need);
        return BF_OK;
    }
    const uint8_t *p = n->buf[b->index];
    bool same_size = n->width == s->depth.width && n->height == s->depth.height;
    uint8_t *dst = same_size ? s->rgb_px : s->rgb_native;
    if (n->pixfmt == V4L2_PIX_FMT_YUYV) capture__yuyv_to_rgb(p, n->stride, n->width, n->height, dst);
    else if (n->pixfmt == V4L2_PIX_FMT_BGR24) capture__bgr_to_rgb(p, n->stride, n->width, n->height, dst);
    else capture__copy_rows(p, n->stride, (size_t)n->width * 3, n->height, dst);
    bf_status st = same_size ? BF_OK
                             : capture__resize_rgb(dst, n->width, n->height, s->rgb_px, s->depth.width, s->depth.height);
    if (st != BF_OK) return st;
    s->has_rgb_frame = true;
    s->t_rgb_s = buffer_time_s(b);
    return BF_OK;
}

/* Takes the newest colour frame queued so far (older ones are given back
 * unread: the depth frame decides the pace). Before the first colour frame
 * it waits up to one 15 Hz period for it. */
static bf_status colour_update(v4l2_source *s)
{
    int timeout_ms = s->has_rgb_frame ? 0 : 67;
    struct v4l2_buffer b, newest;
    bool has_newest = false, got;
    for (;;) {
        bf_status st = node_dequeue(s, &s->colour, timeout_ms, &b, &got);
        if (st) return st;
        if (!got) break;
        if (has_newest && (st = node_requeue(s, &s->colour, &newest))) return st;
        newest = b;
        has_newest = true;
        timeout_ms = 0;
    }
    if (!has_newest) return BF_OK;
    bf_status st = colour_take(s, &newest);
    bf_status st2 = node_requeue(s, &s->colour, &newest);
    return st ? st : st2;
}

static bf_status v4l2_next(rgbd_source *base, bf_frame *out)
{
    v4l2_source *s = (v4l2_source *)base;
    struct v4l2_buffer b;
    bool got;
    bf_status st = node_dequeue(s, &s->depth, CAPTURE_FRAME_TIMEOUT_MS, &b, &got);
    if (st) return st;
    if (!got)
        return bf_fail(BF_IO, "%s: frame %u: no depth frame from %s within %d ms", s->uri, s->index, s->depth.path,
                       CAPTURE_FRAME_TIMEOUT_MS);
    v4l2_node *n = &s->depth;
    size_t need = node_frame_bytes(n);
    if (b.bytesused < need) {
        bf_status q = node_requeue(s, n, &b);
        if (q) return q;
        return bf_fail(BF_IO, "%s: frame %u: depth buffer holds %u bytes, a %ux%u Z16 image needs %zu", s->uri,
                       s->index, b.bytesused, n->width, n->height, need);
    }
    /* A jump in the driver's sequence number means it had no free buffer
     * for the frames in between (we read too slowly) or lost them. */
    if (s->has_seq && b.sequence != s->last_seq + 1) {
        uint32_t gap = b.sequence - s->last_seq - 1;
        s->dropped += gap;
        bf_debug("%s: frame %u: %u depth frame(s) dropped before sequence %u", s->uri, s->index, gap, b.sequence);
    }
    s->has_seq = true;
    s->last_seq = b.sequence;
    capture__copy_rows(n->buf[b.index], n->stride, (size_t)n->width * 2, n->height, (uint8_t *)s->depth_px);
    double t_depth_s = buffer_time_s(&b);
    if ((st = node_requeue(s, n, &b))) return st;
    if (s->has_colour && (st = colour_update(s))) return st;

    *out = (bf_frame){.index = s->index++,
                      .width = n->width,
                      .height = n->height,
                      .t_depth_s = t_depth_s,
                      .t_rgb_s = s->has_rgb_frame ? s->t_rgb_s : t_depth_s,
                      .depth = s->depth_px,
                      .rgb = s->has_rgb_frame ? s->rgb_px : NULL};
    return BF_OK;
}

static void v4l2_close(rgbd_source *base)
{
    if (!base) return;
    v4l2_source *s = (v4l2_source *)base;
    node_close(s->io, &s->colour);
    node_close(s->io, &s->depth);
    free(s->depth_px);
    free(s->rgb_px);
    free(s->rgb_native);
    free(s);
}

static const rgbd_source_ops v4l2_ops = {.next = v4l2_next, .close = v4l2_close};

uint64_t capture__v4l2_dropped_frames(const rgbd_source *src)
{
    return src && src->ops == &v4l2_ops ? ((const v4l2_source *)src)->dropped : 0;
}

bf_status capture__v4l2_open_io(const capture_v4l2_io *io, const char *uri, const char *target,
                                const capture__uri_options *opt, rgbd_source **out)
{
    (void)opt; /* camera / depth_scale are applied by capture_open */
    v4l2_source *s = calloc(1, sizeof *s);
    if (!s) return bf_fail(BF_NO_MEMORY, "%s: source", uri);
    s->io = io;
    s->depth.fd = s->colour.fd = -1;
    s->depth.role = "depth";
    s->colour.role = "colour";
    snprintf(s->uri, sizeof s->uri, "%s", uri);
    bf_status st;
    const char *comma = strchr(target, ',');
    size_t dlen = comma ? (size_t)(comma - target) : strlen(target);
    if (dlen == 0 || dlen >= sizeof s->depth_path || (comma && strlen(comma + 1) >= sizeof s->colour_path) ||
        (comma && !comma[1])) {
        st = bf_fail(BF_INVALID_ARG, "%s: expected v4l2:/dev/videoN or v4l2:/dev/videoN,/dev/videoM (depth, colour)",
                     uri);
        goto fail;
    }
    memcpy(s->depth_path, target, dlen);
    s->depth.path = s->depth_path;
    if (comma) {
        snprintf(s->colour_path, sizeof s->colour_path, "%s", comma + 1);
        s->colour.path = s->colour_path;
        s->has_colour = true;
    }

    static const uint32_t want_depth[] = {V4L2_PIX_FMT_Z16};
    static const uint32_t want_colour[] = {V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_BGR24, V4L2_PIX_FMT_YUYV};
    if ((st = node_open(io, uri, &s->depth, want_depth, 1))) goto fail;
    if (s->has_colour && (st = node_open(io, uri, &s->colour, want_colour, 3))) goto fail;

    size_t n_px = (size_t)s->depth.width * s->depth.height;
    s->depth_px = malloc(n_px * sizeof *s->depth_px);
    s->rgb_px = s->has_colour ? malloc(n_px * 3) : NULL;
    s->rgb_native = s->has_colour ? malloc((size_t)s->colour.width * s->colour.height * 3) : NULL;
    if (!s->depth_px || (s->has_colour && (!s->rgb_px || !s->rgb_native))) {
        st = bf_fail(BF_NO_MEMORY, "%s: frame buffers for %ux%u", uri, s->depth.width, s->depth.height);
        goto fail;
    }
    if ((st = node_start(io, uri, &s->depth))) goto fail;
    if (s->has_colour && (st = node_start(io, uri, &s->colour))) goto fail;
    if (s->has_colour && (s->colour.width != s->depth.width || s->colour.height != s->depth.height))
        bf_warn("%s: colour %ux%u is resized to depth %ux%u; it is not registered to depth", uri, s->colour.width,
                s->colour.height, s->depth.width, s->depth.height);

    /* V4L2 carries no calibration. The default is a nominal Kinect-class
     * 58 degree horizontal field of view (fx = 525 px at 640 wide) scaled
     * to the width; ?camera=fx,fy,cx,cy gives the real one. */
    double f = 525.0 * s->depth.width / 640.0;
    s->base = (rgbd_source){.ops = &v4l2_ops,
                            .kind = "v4l2",
                            .intrinsics = {.width = s->depth.width,
                                           .height = s->depth.height,
                                           .fx_px = f,
                                           .fy_px = f,
                                           .cx_px = (s->depth.width - 1) * 0.5,
                                           .cy_px = (s->depth.height - 1) * 0.5,
                                           /* Z16 from UVC depth cameras is in mm
                                            * (RealSense's default depth unit). */
                                           .depth_scale = 1000.0}};
    if (!opt || !opt->has_camera)
        bf_info("%s: the device reports no calibration; assuming fx = fy = %.1f px (pass ?camera=fx,fy,cx,cy)", uri,
                f);
    *out = &s->base;
    return BF_OK;
fail:
    v4l2_close(&s->base);
    return st;
}

bf_status capture__v4l2_open(const char *uri, const char *target, const capture__uri_options *opt,
                             rgbd_source **out)
{
    return capture__v4l2_open_io(&v4l2_io_system, uri, target, opt, out);
}

/* Lists /dev/video* nodes that offer Z16 depth; colour-only nodes (every
 * webcam) are left out. */
uint32_t capture__v4l2_list(capture_device_info *out, uint32_t cap)
{
    uint32_t n = 0;
    for (int i = 0; i < 64; i++) {
        char path[32];
        snprintf(path, sizeof path, "/dev/video%d", i);
        int fd = open(path, O_RDWR | O_NONBLOCK);
        if (fd < 0) continue;
        struct v4l2_capability c = {0};
        bool has_z16 = false;
        if (sys_ioctl(fd, VIDIOC_QUERYCAP, &c) == 0) {
            for (uint32_t k = 0; k < 64; k++) {
                struct v4l2_fmtdesc d = {.index = k, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
                if (sys_ioctl(fd, VIDIOC_ENUM_FMT, &d) < 0) break;
                if (d.pixelformat == V4L2_PIX_FMT_Z16) has_z16 = true;
            }
        }
        close(fd);
        if (!has_z16) continue;
        if (n < cap) {
            snprintf(out[n].uri, sizeof out[n].uri, "v4l2:%s", path);
            snprintf(out[n].name, sizeof out[n].name, "%.32s (%.32s), Z16 depth", (const char *)c.card,
                     (const char *)c.bus_info);
        }
        n++;
    }
    return n;
}
