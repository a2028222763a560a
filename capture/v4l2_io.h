/* capture: the thin layer between the V4L2 backend and the kernel. Every
 * system call the backend makes goes through one table, so the tests can
 * put a fake device behind it (format lists, buffer queues, dropped
 * buffers, a device unplugged mid-stream) without a camera or a kernel
 * module. The functions have the libc signatures and errno conventions.
 * Private to capture/ and tests/capture/. */
#ifndef BF_CAPTURE_V4L2_IO_H
#define BF_CAPTURE_V4L2_IO_H

#include <poll.h>
#include <stddef.h>
#include <sys/types.h>

#include "capture/capture.h"
#include "capture/live_int.h"

typedef struct capture_v4l2_io {
    int (*open)(const char *path, int flags);
    int (*close)(int fd);
    int (*ioctl)(int fd, unsigned long request, void *arg);
    void *(*mmap)(void *addr, size_t length, int prot, int flags, int fd, off_t offset);
    int (*munmap)(void *addr, size_t length);
    int (*poll)(struct pollfd *fds, nfds_t nfds, int timeout_ms);
} capture_v4l2_io;

/* The real system calls (ioctl retried on EINTR). */
const capture_v4l2_io *capture__v4l2_io_system(void);

/* capture__v4l2_open with the calls going through io (borrowed; must
 * outlive the source). target is "DEPTH_NODE[,COLOUR_NODE]". */
bf_status capture__v4l2_open_io(const capture_v4l2_io *io, const char *uri, const char *target,
                                const capture__uri_options *opt, rgbd_source **out);

/* Buffers the driver skipped so far, from gaps in the depth node's
 * sequence numbers (0 for a source that is not V4L2). */
uint64_t capture__v4l2_dropped_frames(const rgbd_source *src);

/* The buffers the backend asks the driver for per node: one being filled,
 * one being read, two in reserve so a late reader does not stall it. */
#define CAPTURE_V4L2_N_BUFFERS 4u

/* The largest frame side the backend accepts from a driver (as the image
 * readers do): frame buffers are allocated at open from the driver's size. */
#define CAPTURE_V4L2_MAX_SIDE 16384u

#endif
