/* Fuzz target: what a V4L2 camera hands the capture backend (capture/
 * v4l2.c): capabilities, formats, sizes, strides, buffer lengths, and per
 * frame the buffer index, bytesused, sequence, flags and pixels. A fake
 * device behind capture_v4l2_io answers every call from the input, in the
 * order the backend makes them, so the input is a script of a driver that
 * may lie; the backend must refuse what it cannot use, never read outside
 * a buffer. Up to 6 frames are read.
 *
 * Byte 0: bit 0 adds a colour node. Then, per node at open: capabilities
 * (1 byte), up to 3 formats (a count and an index into a table each),
 * width, height (2 bytes each), bytes per line (4), whether S_FMT keeps the
 * asked format (1); at start: buffers granted (1), each buffer's length (4).
 * Per poll: one byte, bit 0 set when a buffer is ready (else the wait
 * times out). Per dequeued buffer: index (1), bytesused (4), sequence (4),
 * flags (1), then up to a buffer's length of pixels. The device is
 * unplugged when the input runs out. */
#include <errno.h>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "capture/v4l2_io.h"
#include "fuzz.h"

#define FZ_FD0 100
#define FZ_MAX_BUF 8
#define FZ_MAX_LEN (16u << 20) /* a larger buffer fails to map (ENOMEM) */

typedef struct fz_node {
    char path[600];
    bool is_open, is_streaming, keeps_format;
    uint32_t caps, formats[3], n_formats, width, height, stride, pixfmt;
    uint8_t *mem[FZ_MAX_BUF];
    uint32_t len[FZ_MAX_BUF], n_buf;
    bool is_configured;
} fz_node;

static fz_node fz[2];
static const uint8_t *cur, *end;

static uint32_t take(int bytes)
{
    uint32_t v = 0;
    for (int i = 0; i < bytes && cur < end; i++) v |= (uint32_t)*cur++ << (8 * i);
    return v;
}

static fz_node *node_of(int fd) { return fd >= FZ_FD0 && fd < FZ_FD0 + 2 && fz[fd - FZ_FD0].is_open ? &fz[fd - FZ_FD0] : NULL; }

static int fz_open(const char *path, int flags)
{
    (void)flags;
    for (int i = 0; i < 2; i++)
        if (fz[i].path[0] && !strcmp(fz[i].path, path)) {
            fz[i].is_open = true;
            return FZ_FD0 + i;
        }
    return errno = ENOENT, -1;
}

static int fz_close(int fd)
{
    fz_node *n = node_of(fd);
    if (!n) return errno = EBADF, -1;
    n->is_open = false;
    return 0;
}

/* The node's answers to the open-time calls, read on the first of them. */
static void configure(fz_node *n)
{
    static const uint32_t table[] = {V4L2_PIX_FMT_Z16,   V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_RGB24,
                                     V4L2_PIX_FMT_BGR24, V4L2_PIX_FMT_GREY, V4L2_PIX_FMT_MJPEG};
    if (n->is_configured) return;
    n->is_configured = true;
    uint32_t c = take(1);
    n->caps = (c & 1 ? 0 : V4L2_CAP_VIDEO_CAPTURE) | (c & 2 ? 0 : V4L2_CAP_STREAMING);
    n->n_formats = take(1) % 4;
    for (uint32_t i = 0; i < n->n_formats; i++) n->formats[i] = table[take(1) % 6];
    n->width = take(2);
    n->height = take(2);
    n->stride = take(4);
    n->keeps_format = !(take(1) & 1);
    n->pixfmt = n->n_formats ? n->formats[0] : 0;
}

static int fz_ioctl(int fd, unsigned long req, void *arg)
{
    fz_node *n = node_of(fd);
    if (!n) return errno = EBADF, -1;
    configure(n);
    switch (req) {
    case VIDIOC_QUERYCAP: {
        struct v4l2_capability *c = arg;
        memset(c, 0, sizeof *c);
        snprintf((char *)c->card, sizeof c->card, "fuzzed");
        c->capabilities = n->caps;
        return 0;
    }
    case VIDIOC_ENUM_FMT: {
        struct v4l2_fmtdesc *d = arg;
        if (d->index >= n->n_formats) return errno = EINVAL, -1;
        d->pixelformat = n->formats[d->index];
        return 0;
    }
    case VIDIOC_G_FMT:
    case VIDIOC_S_FMT: {
        struct v4l2_format *f = arg;
        if (req == VIDIOC_S_FMT && n->keeps_format) n->pixfmt = f->fmt.pix.pixelformat;
        f->fmt.pix.width = n->width;
        f->fmt.pix.height = n->height;
        f->fmt.pix.pixelformat = n->pixfmt;
        f->fmt.pix.bytesperline = n->stride;
        return 0;
    }
    case VIDIOC_REQBUFS: {
        struct v4l2_requestbuffers *rb = arg;
        for (uint32_t i = 0; i < n->n_buf; i++) free(n->mem[i]);
        memset(n->mem, 0, sizeof n->mem);
        n->n_buf = 0;
        if (rb->count == 0) return 0;
        rb->count = take(1) % (FZ_MAX_BUF + 1);
        n->n_buf = rb->count;
        for (uint32_t i = 0; i < n->n_buf; i++) n->len[i] = take(4);
        return 0;
    }
    case VIDIOC_QUERYBUF: {
        struct v4l2_buffer *b = arg;
        if (b->index >= n->n_buf) return errno = EINVAL, -1;
        b->length = n->len[b->index];
        b->m.offset = b->index * 4096u;
        return 0;
    }
    case VIDIOC_QBUF: return ((struct v4l2_buffer *)arg)->index < n->n_buf ? 0 : (errno = EINVAL, -1);
    case VIDIOC_STREAMON: n->is_streaming = true; return 0;
    case VIDIOC_STREAMOFF: n->is_streaming = false; return 0;
    case VIDIOC_DQBUF: {
        struct v4l2_buffer *b = arg;
        if (cur >= end) return errno = ENODEV, -1;
        b->index = take(1);
        b->bytesused = take(4);
        b->sequence = take(4);
        uint32_t fl = take(1);
        b->flags = (fl & 1 ? V4L2_BUF_FLAG_ERROR : 0) | (fl & 2 ? V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC : 0);
        b->timestamp.tv_sec = (time_t)(fl >> 2);
        /* The driver's pixels, into the buffer it names (when it exists). */
        if (b->index < n->n_buf && n->mem[b->index]) {
            size_t k = (size_t)(end - cur) < n->len[b->index] ? (size_t)(end - cur) : n->len[b->index];
            memcpy(n->mem[b->index], cur, k);
            cur += k;
        }
        return 0;
    }
    default: return errno = ENOTTY, -1;
    }
}

static void *fz_mmap(void *addr, size_t len, int prot, int flags, int fd, off_t off)
{
    (void)addr, (void)prot, (void)flags;
    fz_node *n = node_of(fd);
    uint32_t i = (uint32_t)(off / 4096);
    if (!n || i >= n->n_buf || len != n->len[i]) return errno = EINVAL, MAP_FAILED;
    if (len > FZ_MAX_LEN || !(n->mem[i] = calloc(1, len ? len : 1))) return errno = ENOMEM, MAP_FAILED;
    return n->mem[i];
}

static int fz_munmap(void *addr, size_t len)
{
    (void)len;
    for (int k = 0; k < 2; k++)
        for (uint32_t i = 0; i < FZ_MAX_BUF; i++)
            if (fz[k].mem[i] == addr) {
                free(fz[k].mem[i]);
                fz[k].mem[i] = NULL;
                return 0;
            }
    return errno = EINVAL, -1;
}

static int fz_poll(struct pollfd *fds, nfds_t nfds, int timeout_ms)
{
    (void)timeout_ms;
    int ready = 0;
    for (nfds_t i = 0; i < nfds; i++) {
        fds[i].revents = cur >= end ? POLLERR : take(1) & 1 ? POLLIN : 0;
        ready += fds[i].revents != 0;
    }
    return ready;
}

static const capture_v4l2_io fz_io = {fz_open, fz_close, fz_ioctl, fz_mmap, fz_munmap, fz_poll};

bf_status fuzz_v4l2(const uint8_t *data, size_t size)
{
    if (size < 1) return BF_INVALID_ARG;
    memset(fz, 0, sizeof fz);
    cur = data + 1;
    end = data + size;
    /* Device paths in the scratch folder, so that messages name it. */
    const char *dir = fuzz_scratch();
    snprintf(fz[0].path, sizeof fz[0].path, "%s/video0", dir);
    snprintf(fz[1].path, sizeof fz[1].path, "%s/video1", dir);
    char target[1300], uri[1400];
    snprintf(target, sizeof target, "%s%s%s", fz[0].path, data[0] & 1 ? "," : "", data[0] & 1 ? fz[1].path : "");
    snprintf(uri, sizeof uri, "v4l2:%s", target);
    capture__uri_options opt = {0};
    rgbd_source *src = NULL;
    bf_status s = capture__v4l2_open_io(&fz_io, uri, target, &opt, &src);
    if (s == BF_OK) {
        bf_frame frame;
        for (int i = 0; i < 6 && (s = rgbd_source_next(src, &frame)) == BF_OK; i++) fuzz_touch_frame(&frame);
        rgbd_source_close(src);
        /* Unplugged because the script ended: the stream's normal end. */
        if (s == BF_NO_DEVICE && cur >= end) s = BF_OK;
    }
    for (int k = 0; k < 2; k++)
        for (uint32_t i = 0; i < FZ_MAX_BUF; i++) free(fz[k].mem[i]);
    return s;
}

FUZZ_TARGET(fuzz_v4l2)
