/* A test-only LD_PRELOAD library that injects faults into the bitfuse
 * program as a user runs it (tests/fault/test_faults.sh, docs/faults.md):
 *
 * File writes: every write(2), fsync(2) and close(2) on a descriptor opened
 * for writing under FAULT_DIR is a fault point, counted from 1; point
 * FAULT_N fails as FAULT_KIND says:
 *   enospc  the call fails with ENOSPC (a full disk)
 *   eio     the call fails with EIO
 *   short   a write writes half its bytes and returns the count, and every
 *           later write to that descriptor fails with ENOSPC (a disk that
 *           fills in the middle of a write; an fsync or close at N: EIO)
 *   partial a write writes half its bytes and returns the count, nothing
 *           else fails (a signal or a pipe: the caller must go on writing)
 *   full    the call fails with ENOSPC, and so does every later write,
 *           fsync and close of every watched descriptor (a disk one output
 *           filled, which the next output then finds full)
 * Opening a file for writing with stdio (fopen "w"/"a"/"+") under FAULT_DIR
 * is reported on stderr ("fault_shim: stdio stream ..."), because glibc's
 * stdio writes without calling write(2) through the PLT and would escape
 * the injection.
 *
 * Vulkan: when FAULT_VK_N is set, the FAULT_VK_N-th Vulkan allocation
 * (vkAllocateMemory, vkCreateBuffer, vkCreateImage, vkCreateDescriptorPool,
 * vkAllocateDescriptorSets, vkCreateCommandPool, vkAllocateCommandBuffers,
 * vkCreateQueryPool) returns VK_ERROR_OUT_OF_DEVICE_MEMORY; with
 * FAULT_VK_KIND=lost the FAULT_VK_N-th vkQueueSubmit and every later submit
 * and fence wait return VK_ERROR_DEVICE_LOST instead. bitfuse dlopens the
 * loader and asks it for vkGetInstanceProcAddr; the shim's dlsym hands out
 * a wrapper that wraps the calls above.
 *
 * FAULT_DELAY_US: every write(2) and fsync(2) on a watched descriptor first
 * sleeps this long (a slow disk; bench/bench_soak's spill folder).
 *
 * FAULT_REPORT: a file the shim appends to at exit: "points W" (file fault
 * points seen), "vk A S" (Vulkan allocations and submits seen) and, when a
 * fault fired, "fired PATH" or "fired-vk NAME". The environment variables
 * are read by this test harness only, never by bitfuse. */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <vulkan/vulkan.h>

#define MAX_FD 4096

static char dir[PATH_MAX];
static size_t dir_len;
static long fault_n, vk_n, delay_us;
static int kind; /* 0 enospc, 1 eio, 2 short, 3 partial, 4 full */
static _Atomic bool disk_full;
static bool vk_lost;
static _Atomic long points, vk_allocs, vk_submits;
static _Atomic bool lost_now;
static char fired[PATH_MAX + 32];
static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static char *watched[MAX_FD]; /* path of a watched descriptor, or NULL */
static bool broken[MAX_FD];   /* short: later writes fail */

static ssize_t (*real_write)(int, const void *, size_t);
static int (*real_fsync)(int);
static int (*real_fdatasync)(int);
static int (*real_close)(int);
static int (*real_open)(const char *, int, ...);
static int (*real_openat)(int, const char *, int, ...);
static FILE *(*real_fopen)(const char *, const char *);
static void *(*real_dlsym)(void *, const char *);

static void load(void)
{
    static bool done;
    if (done) return;
    /* glibc 2.34 moved dlsym; either version is the real one. dlvsym is
     * not interposed, so this runs before anything else is resolved. */
    *(void **)&real_dlsym = dlvsym(RTLD_NEXT, "dlsym", "GLIBC_2.34");
    if (!real_dlsym) *(void **)&real_dlsym = dlvsym(RTLD_NEXT, "dlsym", "GLIBC_2.2.5");
    *(void **)&real_write = real_dlsym(RTLD_NEXT, "write");
    *(void **)&real_fsync = real_dlsym(RTLD_NEXT, "fsync");
    *(void **)&real_fdatasync = real_dlsym(RTLD_NEXT, "fdatasync");
    *(void **)&real_close = real_dlsym(RTLD_NEXT, "close");
    *(void **)&real_open = real_dlsym(RTLD_NEXT, "open");
    *(void **)&real_openat = real_dlsym(RTLD_NEXT, "openat");
    *(void **)&real_fopen = real_dlsym(RTLD_NEXT, "fopen");
    done = true;
}

static void report(void)
{
    const char *path = getenv("FAULT_REPORT");
    if (!path) return;
    FILE *f = real_fopen ? real_fopen(path, "a") : NULL;
    if (!f) return;
    fprintf(f, "points %ld\nvk %ld %ld\n", (long)points, (long)vk_allocs, (long)vk_submits);
    if (fired[0]) fprintf(f, "%s\n", fired);
    fclose(f);
}

__attribute__((constructor)) static void init(void)
{
    load();
    const char *d = getenv("FAULT_DIR");
    if (d && realpath(d, dir)) dir_len = strlen(dir);
    const char *n = getenv("FAULT_N");
    fault_n = n ? atol(n) : 0;
    const char *k = getenv("FAULT_KIND");
    kind = !k || !strcmp(k, "enospc") ? 0 : !strcmp(k, "eio") ? 1 : !strcmp(k, "short") ? 2 : !strcmp(k, "full") ? 4 : 3;
    const char *dl = getenv("FAULT_DELAY_US");
    delay_us = dl ? atol(dl) : 0;
    const char *v = getenv("FAULT_VK_N");
    vk_n = v ? atol(v) : 0;
    const char *vk = getenv("FAULT_VK_KIND");
    vk_lost = vk && !strcmp(vk, "lost");
    atexit(report);
}

/* ------------------------------------------------------------ files */

/* The absolute path of path (its folder resolved: the file may not exist). */
static bool under_dir(int dirfd, const char *path, char *abs)
{
    if (!dir_len) return false;
    char tmp[2 * PATH_MAX + 2], folder[PATH_MAX];
    if (path[0] == '/') {
        snprintf(tmp, sizeof tmp, "%s", path);
    } else {
        char base[PATH_MAX];
        if (dirfd == AT_FDCWD) {
            if (!getcwd(base, sizeof base)) return false;
        } else {
            char link[64];
            snprintf(link, sizeof link, "/proc/self/fd/%d", dirfd);
            ssize_t n = readlink(link, base, sizeof base - 1);
            if (n < 0) return false;
            base[n] = 0;
        }
        snprintf(tmp, sizeof tmp, "%s/%s", base, path);
    }
    char *slash = strrchr(tmp, '/');
    *slash = 0;
    if (!realpath(tmp[0] ? tmp : "/", folder)) return false;
    if (snprintf(abs, PATH_MAX, "%s/%.*s", folder, NAME_MAX, slash + 1) >= PATH_MAX) return false;
    return !strncmp(abs, dir, dir_len) && (abs[dir_len] == '/' || abs[dir_len] == 0);
}

static void watch(int fd, int flags, int dirfd, const char *path)
{
    char abs[PATH_MAX];
    if (fd < 0 || fd >= MAX_FD || !(flags & (O_WRONLY | O_RDWR)) || !under_dir(dirfd, path, abs)) return;
    pthread_mutex_lock(&mu);
    free(watched[fd]);
    watched[fd] = strdup(abs);
    broken[fd] = false;
    pthread_mutex_unlock(&mu);
}

/* The point's outcome: 0 go on, 1 fail, 2 write half. */
static int at_point(int fd, bool is_write)
{
    if (fd < 0 || fd >= MAX_FD || !watched[fd]) return 0;
    if (delay_us > 0) usleep((useconds_t)delay_us);
    if (broken[fd] || disk_full) return 1;
    long k = atomic_fetch_add(&points, 1) + 1;
    if (k != fault_n || (kind == 3 && !is_write)) return 0;
    pthread_mutex_lock(&mu);
    snprintf(fired, sizeof fired, "fired %s", watched[fd]);
    pthread_mutex_unlock(&mu);
    if (kind == 4) disk_full = true;
    if ((kind == 2 || kind == 3) && is_write) {
        if (kind == 2) broken[fd] = true;
        return 2;
    }
    return 1;
}

ssize_t write(int fd, const void *p, size_t n)
{
    load();
    int r = at_point(fd, true);
    if (r == 1) {
        errno = kind == 1 ? EIO : ENOSPC;
        return -1;
    }
    if (r == 2 && n > 1) n /= 2;
    return real_write(fd, p, n);
}

int fsync(int fd)
{
    load();
    if (at_point(fd, false) == 1) {
        errno = kind == 0 || kind == 4 ? ENOSPC : EIO;
        return -1;
    }
    return real_fsync(fd);
}

int fdatasync(int fd)
{
    load();
    if (at_point(fd, false) == 1) {
        errno = kind == 0 || kind == 4 ? ENOSPC : EIO;
        return -1;
    }
    return real_fdatasync(fd);
}

int close(int fd)
{
    load();
    int r = at_point(fd, false);
    if (fd >= 0 && fd < MAX_FD && watched[fd]) {
        pthread_mutex_lock(&mu);
        free(watched[fd]);
        watched[fd] = NULL;
        broken[fd] = false;
        pthread_mutex_unlock(&mu);
    }
    int c = real_close(fd);
    if (r == 1) { /* closed all the same, as Linux does (NFS reports late) */
        errno = kind == 0 || kind == 4 ? ENOSPC : EIO;
        return -1;
    }
    return c;
}

int open(const char *path, int flags, ...)
{
    load();
    mode_t mode = 0;
    if (flags & (O_CREAT | O_TMPFILE)) {
        va_list ap;
        va_start(ap, flags);
        mode = va_arg(ap, mode_t);
        va_end(ap);
    }
    int fd = real_open(path, flags, mode);
    watch(fd, flags, AT_FDCWD, path);
    return fd;
}
int open64(const char *path, int flags, ...) __attribute__((alias("open")));

int openat(int dirfd, const char *path, int flags, ...)
{
    load();
    mode_t mode = 0;
    if (flags & (O_CREAT | O_TMPFILE)) {
        va_list ap;
        va_start(ap, flags);
        mode = va_arg(ap, mode_t);
        va_end(ap);
    }
    int fd = real_openat(dirfd, path, flags, mode);
    watch(fd, flags, dirfd, path);
    return fd;
}
int openat64(int dirfd, const char *path, int flags, ...) __attribute__((alias("openat")));

int creat(const char *path, mode_t mode) { return open(path, O_WRONLY | O_CREAT | O_TRUNC, mode); }
int creat64(const char *path, mode_t mode) __attribute__((alias("creat")));

FILE *fopen(const char *path, const char *mode)
{
    load();
    char abs[PATH_MAX];
    if (strpbrk(mode, "wa+") && under_dir(AT_FDCWD, path, abs))
        fprintf(stderr, "fault_shim: stdio stream %s opened for writing: its writes escape the injection\n", abs);
    return real_fopen(path, mode);
}
FILE *fopen64(const char *path, const char *mode) __attribute__((alias("fopen")));

/* ------------------------------------------------------------ Vulkan */

static PFN_vkGetInstanceProcAddr real_gipa;
static PFN_vkGetDeviceProcAddr real_gdpa;
#define VK_FNS(X)                                                                                                     \
    X(AllocateMemory, (VkDevice d, const VkMemoryAllocateInfo *i, const VkAllocationCallbacks *a, VkDeviceMemory *m), \
      (d, i, a, m))                                                                                                   \
    X(CreateBuffer, (VkDevice d, const VkBufferCreateInfo *i, const VkAllocationCallbacks *a, VkBuffer *b), (d, i, a, b)) \
    X(CreateImage, (VkDevice d, const VkImageCreateInfo *i, const VkAllocationCallbacks *a, VkImage *b), (d, i, a, b)) \
    X(CreateDescriptorPool,                                                                                           \
      (VkDevice d, const VkDescriptorPoolCreateInfo *i, const VkAllocationCallbacks *a, VkDescriptorPool *p),         \
      (d, i, a, p))                                                                                                   \
    X(AllocateDescriptorSets, (VkDevice d, const VkDescriptorSetAllocateInfo *i, VkDescriptorSet *s), (d, i, s))    \
    X(CreateCommandPool,                                                                                              \
      (VkDevice d, const VkCommandPoolCreateInfo *i, const VkAllocationCallbacks *a, VkCommandPool *p), (d, i, a, p)) \
    X(AllocateCommandBuffers, (VkDevice d, const VkCommandBufferAllocateInfo *i, VkCommandBuffer *c), (d, i, c))     \
    X(CreateQueryPool, (VkDevice d, const VkQueryPoolCreateInfo *i, const VkAllocationCallbacks *a, VkQueryPool *p), \
      (d, i, a, p))

#define X(name, params, args)                                                                                         \
    static PFN_vk##name real_##name;                                                                                  \
    static VKAPI_ATTR VkResult VKAPI_CALL wrap_##name params                                                         \
    {                                                                                                                 \
        long k = atomic_fetch_add(&vk_allocs, 1) + 1;                                                                 \
        if (!vk_lost && k == vk_n) {                                                                                  \
            snprintf(fired, sizeof fired, "fired-vk vk" #name);                                                       \
            return VK_ERROR_OUT_OF_DEVICE_MEMORY;                                                                     \
        }                                                                                                             \
        return real_##name args;                                                                                      \
    }
VK_FNS(X)
#undef X

static PFN_vkQueueSubmit real_QueueSubmit;
static PFN_vkWaitForFences real_WaitForFences;
static PFN_vkDeviceWaitIdle real_DeviceWaitIdle;
static PFN_vkQueueWaitIdle real_QueueWaitIdle;

static VKAPI_ATTR VkResult VKAPI_CALL wrap_QueueSubmit(VkQueue q, uint32_t n, const VkSubmitInfo *s, VkFence f)
{
    long k = atomic_fetch_add(&vk_submits, 1) + 1;
    if (vk_lost && k == vk_n) {
        snprintf(fired, sizeof fired, "fired-vk vkQueueSubmit (device lost)");
        atomic_store(&lost_now, true);
    }
    return atomic_load(&lost_now) ? VK_ERROR_DEVICE_LOST : real_QueueSubmit(q, n, s, f);
}
static VKAPI_ATTR VkResult VKAPI_CALL wrap_WaitForFences(VkDevice d, uint32_t n, const VkFence *f, VkBool32 all,
                                                         uint64_t t)
{
    return atomic_load(&lost_now) ? VK_ERROR_DEVICE_LOST : real_WaitForFences(d, n, f, all, t);
}
/* Teardown waits for idle: a lost device says so but the real one (nothing
 * was submitted after the loss) is idle. */
static VKAPI_ATTR VkResult VKAPI_CALL wrap_DeviceWaitIdle(VkDevice d)
{
    VkResult r = real_DeviceWaitIdle(d);
    return atomic_load(&lost_now) ? VK_ERROR_DEVICE_LOST : r;
}
static VKAPI_ATTR VkResult VKAPI_CALL wrap_QueueWaitIdle(VkQueue q)
{
    VkResult r = real_QueueWaitIdle(q);
    return atomic_load(&lost_now) ? VK_ERROR_DEVICE_LOST : r;
}

static PFN_vkVoidFunction wrapped(const char *name, PFN_vkVoidFunction real)
{
    if (!real || !name) return real;
#define X(n, params, args)                                                                                            \
    if (!strcmp(name, "vk" #n)) {                                                                                     \
        real_##n = (PFN_vk##n)real;                                                                                   \
        return (PFN_vkVoidFunction)wrap_##n;                                                                          \
    }
    VK_FNS(X)
    X(QueueSubmit, , )
    X(WaitForFences, , )
    X(DeviceWaitIdle, , )
    X(QueueWaitIdle, , )
#undef X
    return real;
}

static VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL wrap_gdpa(VkDevice d, const char *name)
{
    if (name && !strcmp(name, "vkGetDeviceProcAddr")) return (PFN_vkVoidFunction)wrap_gdpa;
    return wrapped(name, real_gdpa(d, name));
}

static VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL wrap_gipa(VkInstance inst, const char *name)
{
    if (name && !strcmp(name, "vkGetInstanceProcAddr")) return (PFN_vkVoidFunction)wrap_gipa;
    if (name && !strcmp(name, "vkGetDeviceProcAddr")) {
        real_gdpa = (PFN_vkGetDeviceProcAddr)real_gipa(inst, name);
        return real_gdpa ? (PFN_vkVoidFunction)wrap_gdpa : NULL;
    }
    return wrapped(name, real_gipa(inst, name));
}

/* Only the program's own look-up in the loader (libvulkan.so) is wrapped:
 * the loader's look-ups in the driver and the layers go through as they are. */
void *dlsym(void *handle, const char *name)
{
    load();
    void *p = real_dlsym(handle, name);
    if (!vk_n || !p || strcmp(name, "vkGetInstanceProcAddr") != 0 || handle == RTLD_NEXT ||
        handle == RTLD_DEFAULT)
        return p;
    Dl_info info;
    if (!dladdr(p, &info) || !info.dli_fname || !strstr(info.dli_fname, "libvulkan.so")) return p;
    real_gipa = (PFN_vkGetInstanceProcAddr)p;
    return (void *)wrap_gipa;
}
