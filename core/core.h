/* core: errors, logging, math (SE(3) in double), camera intrinsics, frames,
 * timers and a small thread pool. Depends on libc (and pthreads) only.
 *
 * Conventions (see docs/core.md):
 *  - A function that can fail returns bf_status and writes its outputs only
 *    on success. bf_fail() records a message naming file, frame and reason.
 *  - Transforms are named by frames, read right to left: T_wc takes camera
 *    points to world, p_w = T_wc * p_c.
 *  - Poses are kept in double on the CPU (DESIGN.md section 10).
 */
#ifndef BF_CORE_H
#define BF_CORE_H

#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* ---------------------------------------------------------------- status */

/* One table expands into the enum, bf_status_name() and the default message
 * (libuv's UV_ERRNO_MAP). Exit codes of the command-line tool derive from it:
 * see app/ and docs/cli.md. */
#define BF_STATUS_MAP(X)                                                  \
    X(OK, "ok")                                                           \
    X(INVALID_ARG, "invalid argument")                                    \
    X(IO, "input/output error")                                           \
    X(FORMAT, "malformed input")                                          \
    X(NO_MEMORY, "out of host memory")                                    \
    X(POOL_FULL, "pool exhausted")                                        \
    X(VULKAN, "Vulkan error")                                             \
    X(NO_DEVICE, "no suitable device")                                    \
    X(UNSUPPORTED, "unsupported")                                         \
    X(NUMERIC, "numerical failure")                                       \
    X(END, "end of stream")                                               \
    X(WRITE, "cannot write an output file")

typedef enum bf_status {
#define BF__ENUM(name, msg) BF_##name,
    BF_STATUS_MAP(BF__ENUM)
#undef BF__ENUM
    BF_STATUS_COUNT
} bf_status;

const char *bf_status_name(bf_status s);   /* "BF_IO" */
const char *bf_status_message(bf_status s); /* "input/output error" */

/* Records a formatted message for the calling thread and returns s, so that
 * `return bf_fail(BF_IO, "%s: frame %u: depth PNG is 8-bit", path, i);`
 * reports and fails in one line. The message is also logged at debug level. */
bf_status bf_fail(bf_status s, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
/* The last message recorded by bf_fail() on this thread ("" if none), at
 * most BF_ERROR_CAP - 1 bytes: room for two paths of PATH_MAX and the
 * reason after them. A copy kept for later wants a buffer this size. */
#define BF_ERROR_CAP 10240
const char *bf_last_error(void);
void bf_clear_error(void);

/* ---------------------------------------------------------------- logging */

typedef enum bf_log_level {
    BF_LOG_DEBUG,
    BF_LOG_INFO,
    BF_LOG_WARN,
    BF_LOG_ERROR,
    BF_LOG_SILENT
} bf_log_level;

/* Messages go to stderr with a level prefix. The initial level is INFO, or
 * the BITFUSE_LOG environment variable (debug|info|warn|error|silent). */
void bf_log_set_level(bf_log_level level);
bf_log_level bf_log_get_level(void);
void bf_log(bf_log_level level, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
#define bf_debug(...) bf_log(BF_LOG_DEBUG, __VA_ARGS__)
#define bf_info(...) bf_log(BF_LOG_INFO, __VA_ARGS__)
#define bf_warn(...) bf_log(BF_LOG_WARN, __VA_ARGS__)
#define bf_error(...) bf_log(BF_LOG_ERROR, __VA_ARGS__)

/* A broken invariant: on in release builds too, prints the expression,
 * file and line and aborts (Redis's serverAssert). */
#define BF_ASSERT(e) \
    ((e) ? (void)0 : bf__assert_fail(#e, __FILE__, __LINE__))
_Noreturn void bf__assert_fail(const char *expr, const char *file, int line);

/* ---------------------------------------------------------------- math */

typedef struct bf_vec3 { double x, y, z; } bf_vec3;
/* Unit quaternion, Hamilton convention, w is the real part. */
typedef struct bf_quat { double w, x, y, z; } bf_quat;
/* Rigid transform p' = R p + t, R row-major. */
typedef struct bf_se3 { double R[3][3]; bf_vec3 t; } bf_se3;

static inline bf_vec3 bf_v3(double x, double y, double z) { bf_vec3 v = {x, y, z}; return v; }
static inline bf_vec3 bf_v3_add(bf_vec3 a, bf_vec3 b) { return bf_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline bf_vec3 bf_v3_sub(bf_vec3 a, bf_vec3 b) { return bf_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline bf_vec3 bf_v3_scale(bf_vec3 a, double s) { return bf_v3(a.x * s, a.y * s, a.z * s); }
static inline double bf_v3_dot(bf_vec3 a, bf_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline bf_vec3 bf_v3_cross(bf_vec3 a, bf_vec3 b)
{
    return bf_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
double bf_v3_norm(bf_vec3 a);
bf_vec3 bf_v3_normalize(bf_vec3 a); /* zero stays zero */

bf_quat bf_quat_identity(void);
bf_quat bf_quat_mul(bf_quat a, bf_quat b);
bf_quat bf_quat_conj(bf_quat q);
bf_quat bf_quat_normalize(bf_quat q);
bf_vec3 bf_quat_rotate(bf_quat q, bf_vec3 v);
/* Rotation by angle_rad about a (not necessarily unit) axis. */
bf_quat bf_quat_from_axis_angle(bf_vec3 axis, double angle_rad);
/* Shortest-path spherical interpolation, s in [0,1]. */
bf_quat bf_quat_slerp(bf_quat a, bf_quat b, double s);
/* Angle of the rotation q, in [0, pi]. */
double bf_quat_angle(bf_quat q);
void bf_quat_to_mat(bf_quat q, double R[3][3]);
/* Robust for every rotation (Shepperd's method); result has w >= 0. */
bf_quat bf_quat_from_mat(const double R[3][3]);

bf_se3 bf_se3_identity(void);
bf_se3 bf_se3_from_qt(bf_quat q, bf_vec3 t);
void bf_se3_to_qt(const bf_se3 *T, bf_quat *q, bf_vec3 *t);
bf_se3 bf_se3_mul(const bf_se3 *A, const bf_se3 *B); /* A * B */
bf_se3 bf_se3_inverse(const bf_se3 *T);
bf_vec3 bf_se3_apply(const bf_se3 *T, bf_vec3 p);
bf_vec3 bf_se3_rotate(const bf_se3 *T, bf_vec3 v);
/* Exponential map of a twist xi = (v, w): translation part first, then the
 * rotation vector (so(3)), as in Barfoot's convention. */
bf_se3 bf_se3_exp(const double xi[6]);
void bf_se3_log(const bf_se3 *T, double xi[6]);
/* Rotation angle of T in radians, in [0, pi]; robust near 0 and pi. */
double bf_se3_angle(const bf_se3 *T);
/* Linear translation and slerp rotation between A (s=0) and B (s=1). */
bf_se3 bf_se3_interpolate(const bf_se3 *A, const bf_se3 *B, double s);
/* Row-major 4x4 float for the GPU (only for chunk-relative transforms). */
void bf_se3_to_mat4f(const bf_se3 *T, float out[16]);
bool bf_se3_is_finite(const bf_se3 *T);
/* Finite, and R a rotation: R R^T within tol of the identity (each entry), det R > 0. */
bool bf_se3_is_rigid(const bf_se3 *T, double tol);

/* Symmetric eigen-decomposition by cyclic Jacobi (n <= 6): A is destroyed,
 * eigenvalues ascending in w, eigenvectors in the columns of V. */
void bf_sym_eigen(int n, double *A, double *w, double *V);

/* ---------------------------------------------------------------- camera */

/* Pinhole intrinsics of the depth image (colour is registered to depth).
 * A negative fy (ICL-NUIM) flips the image y axis. */
typedef struct bf_intrinsics {
    uint32_t width, height; /* pixels */
    double fx_px, fy_px, cx_px, cy_px;
    double depth_scale; /* raw depth units per metre (TUM: 5000) */
} bf_intrinsics;

/* The camera of pyramid level l (each level halves the image): size >> l,
 * focal lengths / 2^l, and with pixel centres at integers level l's pixel i
 * covers [2^l i - 1/2, 2^l (i + 1) - 1/2) of the full image, so its centre
 * is at 2^l i + (2^l - 1) / 2: c_l = (c + 1/2) / 2^l - 1/2. */
bf_intrinsics bf_intrinsics_level(const bf_intrinsics *K, uint32_t l);
/* Back-projects pixel (u, v) (pixel centres at integers) at depth z metres. */
bf_vec3 bf_intrinsics_unproject(const bf_intrinsics *K, double u, double v, double z_m);
/* Projects camera point p; returns false when z <= 0. */
bool bf_intrinsics_project(const bf_intrinsics *K, bf_vec3 p_c, double *u, double *v);

/* The depth sensor: its axial noise sigma(z) = sigma_a + sigma_b (z -
 * sigma_c)^2 [m] (bf_sensor_sigma in shaders/bf_common.glsl.h, the one
 * definition C and the shaders use) and its range. Fusion (allocation band,
 * integration weights) and tracking (pyramid thresholds, smoothing, ICP
 * weights) read the same one: recon/ hands its sensor to both. */
typedef struct bf_sensor {
    float sigma_a, sigma_b, sigma_c;
    float max_depth_m; /* samples beyond are ignored */
} bf_sensor;

/* Kinect v1 (Nguyen, Izadi, Lovell 2012: a = 0.0012, b = 0.0019, c = 0.4;
 * range 4.5 m). */
bf_sensor bf_sensor_kinect1(void);

/* ---------------------------------------------------------------- frames */

/* One RGB-D frame. The pixel buffers are borrowed from whoever produced the
 * frame (a source's ring, usually) and stay valid until that producer's next
 * call; copy them to keep them. depth is raw sensor units (0 = no depth),
 * divide by intrinsics.depth_scale for metres. rgb is 8-bit RGB, may be NULL. */
typedef struct bf_frame {
    uint32_t index;       /* 0-based position in the sequence */
    uint32_t width, height;
    double t_depth_s;     /* timestamp of the depth image, seconds */
    double t_rgb_s;       /* timestamp of the colour image (= t_depth_s if none) */
    const uint16_t *depth;
    const uint8_t *rgb;   /* width*height*3 or NULL */
    bool has_pose;        /* ground truth known for this frame */
    bf_se3 T_wc;          /* ground-truth camera-to-world, if has_pose */
} bf_frame;

/* Repeated frames. Real sensor noise makes two captures differ in
 * thousands of pixels, so a depth (colour) image equal byte for byte to the
 * one before is a driver handing on its last image: stale data from an
 * earlier moment. The two streams repeat independently (on 7-Scenes' Kinect
 * 12 of 500 frames repeat the depth alone, 12 the colour alone, 35 both). */
typedef struct bf_repeats {
    uint16_t *depth;      /* the last depth-carrying frame's */
    uint8_t *rgb;         /* the previous frame's colour */
    size_t n;             /* pixels of the buffers */
    bool has_depth, has_rgb;
} bf_repeats;

/* Whether f's depth is the last depth-carrying frame's and whether its
 * colour is the previous frame's (both frames with colour), byte for byte;
 * f's images are kept for the next call. A frame without depth (all zero: a
 * covered lens) repeats nothing and leaves the last depth in place. Either
 * output may be NULL. Starts over when the frame size changes. */
bf_status bf_repeats_note(bf_repeats *r, const bf_frame *f, bool *depth_repeat, bool *rgb_repeat);
void bf_repeats_free(bf_repeats *r); /* zeroes *r; NULL is a no-op */

/* ---------------------------------------------------------------- time */

uint64_t bf_time_ns(void);       /* monotonic */
double bf_time_s(void);          /* monotonic, seconds */

/* Collects durations and reports median and 95th percentile. */
typedef struct bf_stats {
    double *v;
    size_t n, cap;
} bf_stats;
bf_status bf_stats_push(bf_stats *s, double x);
double bf_stats_percentile(const bf_stats *s, double p); /* p in [0,100]; NaN if empty */
double bf_stats_mean(const bf_stats *s);
void bf_stats_free(bf_stats *s);
/* Percentile of an array (sorted in place), linear interpolation. */
double bf_percentile_inplace(double *v, size_t n, double p);

/* Per-second status line on stderr for long work: "label  i/n  rate  eta". */
typedef struct bf_progress {
    const char *label;
    uint64_t total;
    double t_start, t_last;
    bool enabled;         /* off when stderr is not a terminal and BITFUSE_PROGRESS unset */
} bf_progress;
void bf_progress_begin(bf_progress *p, const char *label, uint64_t total);
void bf_progress_update(bf_progress *p, uint64_t done);
void bf_progress_end(bf_progress *p, uint64_t done);

/* ---------------------------------------------------------------- threads */

/* Number of worker threads for CPU work: BITFUSE_THREADS or the core count. */
int bf_thread_count(void);
/* Calls fn(ctx, i) for i in [0, n) on up to bf_thread_count() threads,
 * handing out indices dynamically; returns when all are done. fn must be
 * thread-safe. Falls back to the calling thread if threads cannot start. */
void bf_parallel_for(size_t n, void (*fn)(void *ctx, size_t i), void *ctx);
/* pthread_create with SIGINT and SIGTERM blocked in the new thread, so a
 * Ctrl-C never lands in a thread bitfuse starts and never interrupts a
 * worker's blocking call (a capture thread's open of a pipe or a device
 * read would fail with EINTR). Returns pthread_create's result. */
int bf_thread_start(pthread_t *th, void *(*fn)(void *), void *arg);

/* ---------------------------------------------------------------- files */

/* Reads a whole file; *data is malloc'd and NUL-terminated (size excludes it). */
bf_status bf_read_file(const char *path, char **data, size_t *size);
/* The number of bytes of a UTF-8 byte order mark at the start of text
 * (NUL-terminated or at least len bytes long): 3 or 0. Editors on Windows
 * write one; it is no part of a file's first field. */
size_t bf_bom_bytes(const char *text, size_t len);
/* The offset of the first byte after end (within text's len bytes) that is
 * not white space or NUL, or len if none is: what a parser that stopped at
 * end left over (a JSON file with text after its value, a bad merge). */
size_t bf_trailing_text(const char *text, size_t len, const char *end);
/* Creates a directory and its parents (mkdir -p). */
bf_status bf_mkdir_p(const char *path);
/* Writes data to path atomically: temporary file, fsync, rename (a bf_out
 * of one write). BF_WRITE on failure, path as it was. */
bf_status bf_write_file_atomic(const char *path, const void *data, size_t size);

/* An output file that appears whole or not at all (every file bitfuse
 * writes goes through one, or through bf_write_file_atomic): the bytes go
 * through a buffer into PATH.tmp.PID with write(2), and bf_out_commit
 * flushes, fsyncs, closes and renames it into place (the folder is not
 * fsync'd: an output that must survive a power loss by name calls
 * bf_sync_parent, once per folder). A short write is
 * continued; a failed one (disk full, I/O error) is sticky: later writes do
 * nothing and commit reports it as BF_WRITE, "PATH: write failed: REASON",
 * after removing the temporary file, so PATH keeps its earlier contents (or
 * stays absent). bf_out_abort removes the temporary file. The struct is
 * the caller's; open fills it, commit or abort releases it. */
typedef struct bf_out {
    char path[4096];
    char tmp[4128];
    int fd;        /* -1: closed */
    int err;       /* the first errno, 0 while all is well */
    const char *op; /* what failed: "write", "fsync", "close" */
    char *buf;     /* BF_OUT_BUFFER bytes, at the first bf_out_write */
    size_t n;      /* bytes buffered */
    uint64_t bytes; /* bytes handed over so far */
    int pending;    /* its slot among the pending files (bf_pending_add), or -1 */
} bf_out;
#define BF_OUT_BUFFER (1u << 20)
bf_status bf_out_open(bf_out *o, const char *path);
/* The file a write to path lands in: path, or for a symbolic link the file
 * it names, link by link (a target that does not exist yet joined to its
 * link's folder), so that a write by rename replaces that file and keeps
 * the link. A link another user owns in a sticky, world-writable folder is
 * refused (BF_WRITE), as the kernel's protected_symlinks refuses it. */
bf_status bf_link_target(const char *path, char *out, size_t cap);
void bf_out_write(bf_out *o, const void *p, size_t n);
void bf_out_printf(bf_out *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Flushes what is buffered to the temporary file now (a streamed output
 * such as frames.csv keeps its memory bounded); failures are sticky as
 * above. */
void bf_out_flush(bf_out *o);
bf_status bf_out_commit(bf_out *o);
/* Two files that belong together (an OBJ and its .mtl): both flushed,
 * fsync'd and closed before either is renamed, then first, then second;
 * a failure before the renames leaves both paths as they were. */
bf_status bf_out_commit_both(bf_out *first, bf_out *second);
void bf_out_abort(bf_out *o);
/* Files that exist only until the program finishes them (bf_out's temporary
 * files, a log's .partial): a program killed by a signal removes them in its
 * handler (bf_pending_remove_all), so a second Ctrl-C leaves no half-written
 * file beside the outputs. bf_pending_add copies the path (to the heap)
 * into one of BF_PENDING_MAX slots and returns it, or -1 when all are taken
 * (the file is then not removed on a signal; a store write holds a slot for
 * each file it has put down and not yet renamed); bf_pending_forget(&slot) before the file is
 * renamed or removed sets slot to -1 (-1: nothing). bf_pending_remove_all unlinks every
 * registered path and is async-signal-safe; any thread may add and forget. */
#define BF_PENDING_MAX 4096
int bf_pending_add(const char *path);
void bf_pending_forget(int *slot);
void bf_pending_remove_all(void);
/* fsyncs the folder path is in, so a new name in it survives a power loss
 * (the file's own fsync does not make its name durable). A file system
 * that cannot sync folders (EINVAL, ENOTSUP, EROFS) is not an error. */
bf_status bf_sync_parent(const char *path);
/* fsyncs the folder dir itself, as above. */
bf_status bf_sync_dir(const char *dir);
bool bf_file_exists(const char *path);
/* Joins dir and name into out (size cap); fails with BF_INVALID_ARG if too long. */
bf_status bf_path_join(char *out, size_t cap, const char *dir, const char *name);

/* Strict number parsing: the whole string must be a finite number. */
bool bf_parse_double(const char *s, double *out);
/* v as the fewest significant digits (15 to 17) that read back bit for bit:
 * 517.3, not 517.29999999999995 (%.17g) or a rounded 15. Returns buf. */
#define BF_FMT_DOUBLE_CAP 32
const char *bf_fmt_double(char buf[BF_FMT_DOUBLE_CAP], double v);
bool bf_parse_u32(const char *s, uint32_t *out);

/* ---------------------------------------------------------------- fault injection */

/* One hook for tests to walk every failure path (SQLite's FAULT_INSTALL and
 * tempfault idea): after bf_fault_arm(n), the n-th fault point reached from
 * then on, in any thread, fails (and the countdown stops at 0). The fault
 * points are the checked Vulkan calls in gpu/ and the host allocations of
 * the modules that go through bf_malloc / bf_calloc / bf_realloc (fusion,
 * replay, mesh, eval, export, core's trajectories). bf_fault_arm(0)
 * disarms and returns the countdown it replaced: non-zero means the fault
 * never fired, so the walk is past the last point. Never armed in the
 * product: a disarmed point costs one atomic load. */
uint32_t bf_fault_arm(uint32_t n);
/* True exactly when an armed countdown reaches this point. */
bool bf_fault_now(void);
/* malloc, calloc, realloc, or NULL where a fault fires. */
void *bf_malloc(size_t size);
void *bf_calloc(size_t n, size_t size);
void *bf_realloc(void *p, size_t size);
/* Asks for transparent huge pages over the whole 2 MiB pages of [p, p +
 * bytes) (madvise MADV_HUGEPAGE, which kernels set to "madvise" need): a
 * large buffer filled once then faults once per 2 MiB instead of per 4 KiB
 * page. Call it before the buffer is first written. Advice only: where the
 * kernel has no huge pages to give nothing changes. */
void bf_advise_huge(void *p, size_t bytes);

/* ---------------------------------------------------------------- trajectories */

/* Timestamped camera poses (camera to world, metres), as a TUM trajectory
 * holds them; the file format is replay's (replay_traj_read_tum). */
typedef struct bf_traj {
    size_t n;
    double *t_s;   /* strictly increasing */
    bf_se3 *T_wc;
    size_t cap;    /* entries allocated (managed by push/read; 0 is fine) */
} bf_traj;

/* Appends one pose; grows the arrays. */
bf_status bf_traj_push(bf_traj *traj, double t_s, const bf_se3 *T_wc);
void bf_traj_free(bf_traj *traj);
/* Pose at time t by linear position / slerp rotation between the two
 * neighbouring samples; false if t is outside [t_0, t_n-1]. */
bool bf_traj_interpolate(const bf_traj *traj, double t_s, bf_se3 *T_wc);
/* TUM associate.py's rule for two strictly increasing stamp lists: every
 * pair with |t_a - t_b| < max_dt_s is a candidate; candidates in order of
 * |dt| (ties by a, then b) are taken greedily while neither stamp is taken.
 * On success b_of_a[i] (n_a entries, caller's) is the index in t_b matched
 * to t_a[i], or SIZE_MAX; on failure (out of memory) it is untouched. */
bf_status bf_associate_stamps(const double *t_a, size_t n_a, const double *t_b, size_t n_b, double max_dt_s,
                              size_t *b_of_a);

#endif
