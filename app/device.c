/* The device part of record and live: what opens a device (capture owns
 * that; app adds the recordings replay reads) and the one Ctrl-C handler,
 * which ends the capture instead of the program. */
#include <errno.h>
#include <signal.h>
#include <stdatomic.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "replay/replay.h"

/* A recording played as a camera is wrapped (paced, threaded), so
 * replay_undistortion no longer sees its lens: it is kept here for the
 * wrapper app_open_device returned last. */
typedef struct recording_open {
    const replay_options *ropt;
    bool has_lens;
    double dist[CALIB_DIST_N], shift_px;
} recording_open;

static struct {
    const rgbd_source *src;
    double dist[CALIB_DIST_N], shift_px;
} g_wrapped_lens;

static bf_status open_recording(void *user, const char *path, rgbd_source **out)
{
    recording_open *r = user;
    bf_status s = replay_open(path, r->ropt, out);
    if (s == BF_OK) r->has_lens = replay_undistortion(*out, r->dist, &r->shift_px);
    return s;
}

bf_status app_open_device(const char *uri, const replay_options *ropt, bool realtime, uint32_t queue, bool *is_live,
                          rgbd_source **out)
{
    recording_open r = {.ropt = ropt};
    bf_status s = capture_open_device(uri, open_recording, &r, realtime, queue, is_live, out);
    g_wrapped_lens.src = s == BF_OK && r.has_lens ? *out : NULL;
    memcpy(g_wrapped_lens.dist, r.dist, sizeof r.dist);
    g_wrapped_lens.shift_px = r.shift_px;
    return s;
}

bool app_undistortion(const rgbd_source *src, double dist[CALIB_DIST_N], double *shift_px)
{
    if (replay_undistortion(src, dist, shift_px)) return true;
    if (!src || src != g_wrapped_lens.src) return false;
    memcpy(dist, g_wrapped_lens.dist, sizeof g_wrapped_lens.dist);
    if (shift_px) *shift_px = g_wrapped_lens.shift_px;
    return true;
}

static rgbd_source *volatile g_stop_src;
static volatile sig_atomic_t g_stopped;
/* Stop signals taken since app_stop_begin: g_stopped is also set by
 * app_stop_request (a closed window, --exit-after, a failed output), which
 * is no Ctrl-C of the user's. Taken with one atomic exchange: two signals
 * handled at once by two threads (a capture thread takes one too) still
 * count as two. */
static atomic_int g_signals;
static struct sigaction g_old_int, g_old_term;

/* Folders this run made, removed on a fatal signal while still empty
 * (rmdir takes only an empty one), the last made first. A slot is filled,
 * then published by the count (release; the handler, on any thread,
 * acquires it). */
enum { MADE_FOLDERS = 3 };
static char g_made[MADE_FOLDERS][4096];
static atomic_int g_n_made;

void app_signals_made_folder(const char *dir)
{
    int n = atomic_load(&g_n_made);
    if (!dir || !dir[0] || n >= MADE_FOLDERS || strlen(dir) >= sizeof g_made[0]) return;
    memcpy(g_made[n], dir, strlen(dir) + 1);
    atomic_store_explicit(&g_n_made, n + 1, memory_order_release);
}

/* Only async-signal-safe calls: unlink, rmdir, signal, raise. The signal
 * is blocked while its handler runs, so the raised one is taken, with the
 * default action, as the handler returns: the shell sees the program
 * killed by it, as before. */
static void on_fatal_signal(int sig)
{
    int saved = errno;
    bf_pending_remove_all();
    for (int i = atomic_load_explicit(&g_n_made, memory_order_acquire) - 1; i >= 0; i--) (void)rmdir(g_made[i]);
    errno = saved;
    signal(sig, SIG_DFL);
    raise(sig);
}

void app_signals_init(void)
{
    struct sigaction sa = {.sa_handler = on_fatal_signal}, old;
    sigemptyset(&sa.sa_mask);
    /* A signal ignored from the start (nohup, a script's background job)
     * stays ignored (app_stop_begin takes SIGINT and SIGTERM during a scan). */
    static const int sigs[] = {SIGINT, SIGTERM, SIGHUP};
    for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++)
        if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler != SIG_IGN) sigaction(sigs[i], &sa, NULL);
    /* A write past the file-size limit (ulimit -f) then fails with EFBIG and
     * is named as any failed write (exit 5, its temporary file removed),
     * rather than killing the program with the file half written. */
    signal(SIGXFSZ, SIG_IGN);
}

static void on_stop_signal(int sig)
{
    if (atomic_exchange(&g_signals, 1)) { /* the second: the user means it */
        on_fatal_signal(sig);
        return;
    }
    g_stopped = 1;
    capture_threaded_stop(g_stop_src); /* sets an atomic flag: async-signal-safe */
    /* Writing the outputs can take seconds: say so, or a second press looks
     * needed. stderr may be a pipe whose reader the same Ctrl-C ended
     * (2>&1 | tee): its SIGPIPE must not end the program here. */
    static const char msg[] = "bitfuse: stopping: the frames so far are being written (a second Ctrl-C abandons "
                              "them)\n";
    int saved = errno;
    struct sigaction ign = {.sa_handler = SIG_IGN}, old;
    sigemptyset(&ign.sa_mask);
    sigaction(SIGPIPE, &ign, &old);
    (void)!write(STDERR_FILENO, msg, sizeof msg - 1);
    sigaction(SIGPIPE, &old, NULL);
    errno = saved;
}

const volatile sig_atomic_t *app_stop_begin(rgbd_source *src)
{
    /* SA_RESTART: a read the signal lands in goes on (a file on a slow disk
     * or a pipe must not fail its frame); the loop sees the flag after it.
     * A second Ctrl-C ends the program (on_stop_signal). */
    struct sigaction sa = {.sa_handler = on_stop_signal, .sa_flags = SA_RESTART};
    sigemptyset(&sa.sa_mask);
    g_stop_src = src;
    g_stopped = 0;
    atomic_store(&g_signals, 0);
    /* Also over a SIGINT ignored from the start (a script's background job,
     * as the tests run it): during a scan Ctrl-C and SIGTERM always stop it,
     * as they did before app_signals_init. */
    sigaction(SIGINT, &sa, &g_old_int);
    sigaction(SIGTERM, &sa, &g_old_term);
    return &g_stopped;
}

void app_stop_request(volatile sig_atomic_t *flag)
{
    if (flag) *flag = 1;
    capture_threaded_stop(g_stop_src); /* live: the capture thread ends its frames */
}

bool app_stop_end(void)
{
    sigaction(SIGINT, &g_old_int, NULL);
    sigaction(SIGTERM, &g_old_term, NULL);
    g_stop_src = NULL;
    return g_stopped;
}
