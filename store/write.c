/* The store's writer: a thread that writes host copies of the map, one
 * chunk file per changed chunk, then the trajectory, the keyframes when
 * new ones came, and the index. */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <sys/file.h>
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <cjson/cJSON.h>
#include <zstd.h>

#include "store_int.h"

typedef struct store_job {
    hostmap map;
    store_meta meta;
    bf_traj traj;
    store_keyframes kf;  /* written with the map when has_kf */
    bool has_kf;
} store_job;

struct store_writer {
    char dir[4096];
    char chunk_dir[4200];
    store_entry *entries;   /* what the store holds now, sorted by key */
    uint32_t n_entries;
    uint32_t flush;         /* writes done (the index's count) */

    pthread_t thread;
    bool has_thread;
    int lock_fd;          /* the store folder, flock'ed while this writer lives (-1: none) */
    pthread_mutex_t mu;
    pthread_cond_t cv;
    bool has_job, running, stop;
    store_job job;
    store_keyframes pending_kf; /* store_writer_keyframes's, for the next job */
    bool has_pending_kf;
    bf_status error;        /* the first failed write's status, and its message */
    char message[1024];
    store_write_stats work;  /* the thread's own counts */
    store_write_stats stats; /* a copy of them under mu, after each write */
};

/* ------------------------------------------------------------ one write */

static bf_status write_chunk(store_stage *stage, const char *chunk_dir, const hostmap *m, const store_group *g,
                             const store_meta *meta, uint64_t *file_bytes)
{
    size_t raw = (size_t)g->n * store__record_bytes(g->has_colour), cap = ZSTD_compressBound(raw);
    uint8_t *rec = bf_malloc(raw), *z = bf_malloc(cap);
    bf_status s = rec && z ? BF_OK : bf_fail(BF_NO_MEMORY, "store: chunk of %u bricks", g->n);
    size_t nz = 0;
    if (s == BF_OK) {
        store__pack(m, g->first, g->n, g->has_colour, rec);
        nz = ZSTD_compress(z, cap, rec, raw, STORE_ZSTD_LEVEL);
        if (ZSTD_isError(nz)) s = bf_fail(BF_IO, "store: zstd: %s", ZSTD_getErrorName(nz));
    }
    char name[96], path[4400];
    store__chunk_name(name, sizeof name, g->key);
    snprintf(path, sizeof path, "%s/%s", chunk_dir, name);
    if (s == BF_OK) {
        store_chunk_header h;
        memset(&h, 0, sizeof h);
        memcpy(h.magic, STORE_CHUNK_MAGIC, sizeof h.magic);
        h.version = g->has_colour ? STORE_CHUNK_VERSION_COLOUR : STORE_VERSION;
        h.header_bytes = STORE_CHUNK_HEADER;
        memcpy(h.key, g->key, sizeof h.key);
        h.n_bricks = g->n;
        h.chunk_m = meta->chunk_m;
        h.record_bytes = (uint32_t)store__record_bytes(g->has_colour);
        h.origin_w[0] = meta->origin_w.x, h.origin_w[1] = meta->origin_w.y, h.origin_w[2] = meta->origin_w.z;
        h.raw_bytes = raw;
        h.payload_bytes = nz;
        h.payload_hash = store__hash(z, nz);
        h.header_hash = store__hash(&h, offsetof(store_chunk_header, header_hash));
        s = stage ? store__write_staged(stage, path, &h, sizeof h, z, nz) /* renamed with the write's other files */
                  : store__write_atomic(path, &h, sizeof h, z, nz);
        *file_bytes = sizeof h + nz;
    }
    free(rec);
    free(z);
    return s;
}

static bf_status write_traj(store_writer *w, store_stage *stage, const bf_traj *traj)
{
    size_t n = traj ? traj->n : 0, bytes = STORE_TRAJ_HEADER + n * STORE_TRAJ_POSE_DOUBLES * 8 + 8;
    uint8_t *buf = bf_malloc(bytes);
    if (!buf) return bf_fail(BF_NO_MEMORY, "store: trajectory of %zu poses", n);
    memcpy(buf, STORE_TRAJ_MAGIC, 8);
    uint32_t v = STORE_VERSION, count = (uint32_t)n;
    memcpy(buf + 8, &v, 4);
    memcpy(buf + 12, &count, 4);
    for (size_t i = 0; i < n; i++) {
        double d[STORE_TRAJ_POSE_DOUBLES] = {traj->t_s[i]};
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++) d[1 + 3 * r + c] = traj->T_wc[i].R[r][c];
        d[10] = traj->T_wc[i].t.x, d[11] = traj->T_wc[i].t.y, d[12] = traj->T_wc[i].t.z;
        memcpy(buf + STORE_TRAJ_HEADER + i * sizeof d, d, sizeof d);
    }
    uint64_t h = store__hash(buf, bytes - 8);
    memcpy(buf + bytes - 8, &h, 8);
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", w->dir, STORE_TRAJ_NAME);
    bf_status s = store__write_staged(stage, path, buf, bytes, NULL, 0);
    if (s == BF_OK) w->work.bytes_written += bytes;
    free(buf);
    return s;
}

/* A number that reads back bit for bit (cJSON's own printing settles for 15
 * digits when they compare within an epsilon). */
static cJSON *json_exact(double v)
{
    char text[BF_FMT_DOUBLE_CAP];
    return cJSON_CreateRaw(bf_fmt_double(text, v));
}

static cJSON *json_numbers(const double *v, int n)
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; i < n && a; i++) cJSON_AddItemToArray(a, json_exact(v[i]));
    return a;
}

static bf_status write_index(store_writer *w, store_stage *stage, const store_meta *meta, const store_entry *e,
                             uint32_t n)
{
    cJSON *root = cJSON_CreateObject();
    if (!root) return bf_fail(BF_NO_MEMORY, "store: index");
    cJSON_AddStringToObject(root, "format", STORE_FORMAT_NAME);
    cJSON_AddNumberToObject(root, "version", STORE_VERSION);
    cJSON_AddNumberToObject(root, "flush", w->flush + 1);
    char when[64];
    time_t now = time(NULL);
    struct tm tm;
    strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", gmtime_r(&now, &tm));
    cJSON_AddStringToObject(root, "written_utc", when);
    cJSON_AddItemToObject(root, "chunk_m", json_exact(meta->chunk_m));
    cJSON_AddNumberToObject(root, "max_level", meta->max_level);
    double o[3] = {meta->origin_w.x, meta->origin_w.y, meta->origin_w.z};
    cJSON_AddItemToObject(root, "origin_w", json_numbers(o, 3));
    cJSON_AddNumberToObject(root, "frames", meta->frames);
    if (meta->has_pose) {
        cJSON *p = cJSON_AddObjectToObject(root, "last_pose");
        cJSON_AddItemToObject(p, "t_s", json_exact(meta->last_t_s));
        double R[9], t[3] = {meta->last_pose.t.x, meta->last_pose.t.y, meta->last_pose.t.z};
        for (int r = 0; r < 9; r++) R[r] = meta->last_pose.R[r / 3][r % 3];
        cJSON_AddItemToObject(p, "R", json_numbers(R, 9));
        cJSON_AddItemToObject(p, "t", json_numbers(t, 3));
    }
    uint64_t bricks = 0, bytes = 0;
    cJSON *chunks = cJSON_AddArrayToObject(root, "chunks");
    for (uint32_t i = 0; i < n; i++) {
        cJSON *c = cJSON_CreateObject();
        double k[3] = {e[i].key[0], e[i].key[1], e[i].key[2]};
        char hex[24];
        snprintf(hex, sizeof hex, "%016llx", (unsigned long long)e[i].digest);
        cJSON_AddItemToObject(c, "key", json_numbers(k, 3));
        cJSON_AddNumberToObject(c, "bricks", e[i].n_bricks);
        cJSON_AddNumberToObject(c, "bytes", (double)e[i].file_bytes);
        cJSON_AddStringToObject(c, "xxh3", hex);
        cJSON_AddItemToArray(chunks, c);
        bricks += e[i].n_bricks;
        bytes += e[i].file_bytes;
    }
    cJSON_AddNumberToObject(root, "bricks", (double)bricks);
    cJSON_AddNumberToObject(root, "chunk_bytes", (double)bytes);
    char *text = cJSON_Print(root);
    cJSON_Delete(root);
    if (!text) return bf_fail(BF_NO_MEMORY, "store: index text");
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", w->dir, STORE_INDEX_NAME);
    size_t len = strlen(text);
    bf_status s = store__write_staged(stage, path, text, len, "\n", 1);
    if (s == BF_OK) w->work.bytes_written += len + 1;
    cJSON_free(text);
    return s;
}

/* Writes one map: its changed chunks, the trajectory, the index, then
 * removes the files of chunks it no longer has. Every new file is put down
 * whole first and renamed only when all are: a write that fails (a full
 * disk) leaves the store as the write before it, file for file. */
static bf_status write_map(store_writer *w, store_job *job)
{
    double t0 = bf_time_s();
    store__sort(&job->map);
    store_group *g = NULL;
    uint32_t n = 0;
    bf_status s = store__groups(&job->map, &g, &n);
    store_entry *e = s == BF_OK && n ? bf_calloc(n, sizeof *e) : NULL;
    if (s == BF_OK && n && !e) s = bf_fail(BF_NO_MEMORY, "store: index of %u chunks", n);
    uint64_t written = 0, bytes_before = w->work.bytes_written;
    store_stage chunks = {0}, rest = {0};
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        memcpy(e[i].key, g[i].key, sizeof e[i].key);
        e[i].n_bricks = g[i].n;
        e[i].digest = g[i].digest;
        const store_entry *old = w->n_entries ? bsearch(&e[i], w->entries, w->n_entries, sizeof *e, store__entry_cmp)
                                              : NULL;
        if (old && old->digest == e[i].digest && old->n_bricks == e[i].n_bricks) {
            e[i].file_bytes = old->file_bytes;
            continue;
        }
        s = write_chunk(&chunks, w->chunk_dir, &job->map, &g[i], &job->meta, &e[i].file_bytes);
        if (s == BF_OK) written++, w->work.bytes_written += e[i].file_bytes;
    }
    if (s == BF_OK) s = write_traj(w, &rest, &job->traj);
    if (s == BF_OK && job->has_kf) s = store__keyframes_stage(&rest, w->dir, &job->kf);
    if (s == BF_OK) s = write_index(w, &rest, &job->meta, e, n);
    if (s != BF_OK) store__stage_abort(&chunks);
    /* The chunk files before the index that lists them (a kill in between
     * leaves chunks the old index does not list: loaded, as a reader takes them). */
    if (s == BF_OK) s = store__stage_commit(&chunks);
    if (s == BF_OK && written) s = bf_sync_dir(w->chunk_dir);
    if (s == BF_OK) s = store__stage_commit(&rest);
    else store__stage_abort(&rest);
    if (s == BF_OK) s = bf_sync_dir(w->dir);

    uint64_t removed = 0;
    for (uint32_t i = 0; s == BF_OK && i < w->n_entries; i++) {
        if (n && bsearch(&w->entries[i], e, n, sizeof *e, store__entry_cmp)) continue;
        char name[96], path[4400];
        store__chunk_name(name, sizeof name, w->entries[i].key);
        snprintf(path, sizeof path, "%s/%s", w->chunk_dir, name);
        if (unlink(path) == 0) removed++;
    }
    if (s == BF_OK && removed) bf_sync_dir(w->chunk_dir);
    free(g);
    if (s != BF_OK) {
        free(e);
        w->work.bytes_written = bytes_before; /* a failed write's files are removed */
        return s;
    }
    free(w->entries);
    w->entries = e;
    w->n_entries = n;
    w->flush++;
    store_write_stats *st = &w->work;
    st->writes++;
    st->chunks = n;
    st->bricks = job->map.n_bricks;
    st->chunks_written += written;
    st->chunks_removed += removed;
    if (job->has_kf) st->keyframes = job->kf.n;
    st->bytes_on_disk = 0;
    for (uint32_t i = 0; i < n; i++) st->bytes_on_disk += e[i].file_bytes;
    st->ms_last = 1e3 * (bf_time_s() - t0);
    st->ms_total += st->ms_last;
    if (st->ms_last > st->ms_max) st->ms_max = st->ms_last;
    return BF_OK;
}

static void job_free(store_job *j)
{
    hostmap_free(&j->map);
    bf_traj_free(&j->traj);
    store_keyframes_free(&j->kf);
    memset(j, 0, sizeof *j);
}

bf_status store_put_chunks(const char *dir, hostmap *m, const store_meta *meta, uint64_t *bytes)
{
    if (!dir || !m || !meta) return bf_fail(BF_INVALID_ARG, "store_put_chunks: NULL argument");
    char chunk_dir[4200];
    snprintf(chunk_dir, sizeof chunk_dir, "%s/%s", dir, STORE_CHUNK_DIR);
    bf_status s = bf_mkdir_p(chunk_dir);
    store__sort(m);
    store_group *g = NULL;
    uint32_t n = 0;
    uint64_t total = 0;
    if (s == BF_OK) s = store__groups(m, &g, &n);
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        uint64_t b = 0;
        s = write_chunk(NULL, chunk_dir, m, &g[i], meta, &b);
        total += b;
    }
    free(g);
    if (s == BF_OK && bytes) *bytes = total;
    return s;
}

/* ------------------------------------------------------------ the thread */

static void *writer_main(void *arg)
{
    store_writer *w = arg;
    pthread_mutex_lock(&w->mu);
    for (;;) {
        while (!w->has_job && !w->stop) pthread_cond_wait(&w->cv, &w->mu);
        if (!w->has_job) break;
        store_job job = w->job;
        memset(&w->job, 0, sizeof w->job);
        w->has_job = false;
        w->running = true;
        bool skip = w->error != BF_OK;
        pthread_mutex_unlock(&w->mu);
        bf_status s = skip ? BF_OK : write_map(w, &job);
        job_free(&job);
        pthread_mutex_lock(&w->mu);
        if (s != BF_OK && w->error == BF_OK) {
            w->error = s;
            snprintf(w->message, sizeof w->message, "%s", bf_last_error());
        }
        w->stats = w->work;
        w->running = false;
        pthread_cond_broadcast(&w->cv);
    }
    pthread_mutex_unlock(&w->mu);
    return NULL;
}

/* Waits (holding mu) until no job is queued or running. */
static void wait_idle(store_writer *w)
{
    while (w->has_job || w->running) pthread_cond_wait(&w->cv, &w->mu);
}

static bf_status error_of(store_writer *w)
{
    return w->error == BF_OK ? BF_OK : bf_fail(w->error, "%s", w->message);
}

/* ------------------------------------------------------------ public */

/* Removes the files of dir whose names end in suffix (one level). */
static bf_status unlink_suffix(const char *dir, const char *suffix)
{
    char path[4600];
    size_t k = strlen(suffix);
    bf_status s = BF_OK;
    DIR *d = opendir(dir);
    struct dirent *e;
    while (s == BF_OK && d && (e = readdir(d))) {
        size_t n = strlen(e->d_name);
        if (n <= k || strcmp(e->d_name + n - k, suffix) != 0) continue;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (unlink(path) != 0) s = bf_fail(BF_WRITE, "%s: cannot remove: %s", path, strerror(errno));
    }
    if (d) closedir(d);
    return s;
}

/* One writer a store (store.h): a second scan into it (another terminal,
 * --resume of a store being written) would mix two maps and delete the
 * other's temporary files. */
bf_status store_lock(const char *dir, int *fd)
{
    *fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (*fd < 0) return bf_fail(BF_WRITE, "%s: cannot open the folder: %s", dir, strerror(errno));
    if (flock(*fd, LOCK_EX | LOCK_NB) == 0) return BF_OK;
    int e = errno;
    close(*fd);
    *fd = -1;
    if (e == EWOULDBLOCK)
        return bf_fail(BF_INVALID_ARG, "%s: another bitfuse is writing this store (a scan still running?): wait for it "
                                       "to end, or choose another folder",
                       dir);
    /* NFS emulates flock with fcntl locks, which a folder opened read-only
     * cannot take: no lock there, as before locks came. */
    bf_warn("store: %s: no lock on this file system (%s): a second scan into it is not refused", dir, strerror(e));
    return BF_OK;
}

void store_unlock(int fd)
{
    if (fd >= 0) close(fd);
}

bf_status store_clear(const char *dir)
{
    if (!dir) return bf_fail(BF_INVALID_ARG, "store_clear: NULL folder");
    char chunk_dir[4200], path[4600];
    snprintf(chunk_dir, sizeof chunk_dir, "%s/%s", dir, STORE_CHUNK_DIR);
    bf_status s = unlink_suffix(chunk_dir, ".bfc");
    if (s == BF_OK) s = unlink_suffix(chunk_dir, ".tmp");
    /* keyframes.bin too: its poses are in the cleared scan's frame. */
    const char *files[] = {STORE_INDEX_NAME, STORE_TRAJ_NAME, STORE_KEYFRAMES_NAME};
    for (int i = 0; s == BF_OK && i < 3; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        if (unlink(path) != 0 && errno != ENOENT) s = bf_fail(BF_WRITE, "%s: cannot remove: %s", path, strerror(errno));
    }
    return s == BF_OK ? bf_sync_dir(dir) : s;
}

bf_status store_writer_open(const char *dir, bool resume, store_writer **out)
{
    return store_writer_open_locked(dir, resume, -1, out);
}

bf_status store_writer_open_locked(const char *dir, bool resume, int lock_fd, store_writer **out)
{
    if (!dir || !out) {
        store_unlock(lock_fd);
        return bf_fail(BF_INVALID_ARG, "store_writer_open: NULL argument");
    }
    bool exists = store_exists(dir);
    /* The lock before the checks: a store being written is said so first. */
    bf_status s = BF_OK;
    if (lock_fd < 0 && (exists || !resume)) {
        s = bf_mkdir_p(dir);
        if (s == BF_OK) s = store_lock(dir, &lock_fd);
        if (s != BF_OK) return s;
    }
    if (!resume && exists) s = bf_fail(BF_INVALID_ARG, "%s: already holds a scene store: resume it (--resume) or "
                                                       "choose another folder", dir);
    if (resume && !exists) s = bf_fail(BF_IO, "%s: no scene store to resume", dir);
    store_writer *w = s == BF_OK ? calloc(1, sizeof *w) : NULL;
    if (s == BF_OK && !w) s = bf_fail(BF_NO_MEMORY, "store: writer");
    if (s == BF_OK && snprintf(w->dir, sizeof w->dir, "%s", dir) >= (int)sizeof w->dir)
        s = bf_fail(BF_INVALID_ARG, "%s: path too long", dir);
    if (s != BF_OK) {
        free(w);
        store_unlock(lock_fd);
        return s;
    }
    snprintf(w->chunk_dir, sizeof w->chunk_dir, "%s/%s", dir, STORE_CHUNK_DIR);
    w->lock_fd = lock_fd;
    s = bf_mkdir_p(w->chunk_dir);
    if (s == BF_OK) s = bf_sync_dir(dir);
    /* A new scan: a keyframes.bin left in the folder (not a store without
     * its index or chunks) holds poses of another scan's frame. */
    if (s == BF_OK && !resume) {
        char path[4600];
        snprintf(path, sizeof path, "%s/%s", dir, STORE_KEYFRAMES_NAME);
        if (unlink(path) != 0 && errno != ENOENT) s = bf_fail(BF_WRITE, "%s: cannot remove: %s", path, strerror(errno));
    }
    /* Temp files a killed writer left (never read: the reader takes *.bfc only). */
    if (s == BF_OK && resume) s = unlink_suffix(w->dir, ".tmp");
    if (s == BF_OK && resume) s = unlink_suffix(w->chunk_dir, ".tmp");
    if (s == BF_OK && resume) {
        /* Only the digests matter here: a missing or stale index makes the
         * first write rewrite every chunk, which is always right. */
        store_meta meta;
        if (store__index_read(dir, &meta, &w->entries, &w->n_entries, &w->flush) != BF_OK) {
            bf_warn("store: %s: no usable index (%s): the first write rewrites every chunk", dir, bf_last_error());
            w->entries = NULL, w->n_entries = 0, w->flush = 0;
        }
    }
    pthread_mutex_init(&w->mu, NULL);
    pthread_cond_init(&w->cv, NULL);
    if (s == BF_OK && bf_thread_start(&w->thread, writer_main, w) != 0)
        s = bf_fail(BF_NO_MEMORY, "store: cannot start the writer's thread");
    if (s != BF_OK) {
        pthread_mutex_destroy(&w->mu);
        pthread_cond_destroy(&w->cv);
        store_unlock(w->lock_fd);
        free(w->entries);
        free(w);
        return s;
    }
    w->has_thread = true;
    *out = w;
    return BF_OK;
}

static bf_status traj_copy(const bf_traj *in, bf_traj *out)
{
    memset(out, 0, sizeof *out);
    for (size_t i = 0; in && i < in->n; i++) {
        bf_status s = bf_traj_push(out, in->t_s[i], &in->T_wc[i]);
        if (s != BF_OK) {
            bf_traj_free(out);
            return s;
        }
    }
    return BF_OK;
}

bf_status store_writer_submit(store_writer *w, hostmap *map, const store_meta *meta, const bf_traj *traj)
{
    if (!w || !map || !meta) return bf_fail(BF_INVALID_ARG, "store_writer_submit: NULL argument");
    store_job job = {.map = *map, .meta = *meta};
    memset(map, 0, sizeof *map);
    bf_status s = traj_copy(traj, &job.traj);
    pthread_mutex_lock(&w->mu);
    wait_idle(w);
    if (s == BF_OK) s = error_of(w);
    if (s == BF_OK) {
        job.kf = w->pending_kf, job.has_kf = w->has_pending_kf;
        memset(&w->pending_kf, 0, sizeof w->pending_kf);
        w->has_pending_kf = false;
        w->job = job;
        w->has_job = true;
        pthread_cond_broadcast(&w->cv);
    }
    pthread_mutex_unlock(&w->mu);
    if (s != BF_OK) job_free(&job);
    return s;
}

void store_writer_keyframes(store_writer *w, store_keyframes *k)
{
    if (!w || !k) return;
    pthread_mutex_lock(&w->mu);
    store_keyframes_free(&w->pending_kf);
    w->pending_kf = *k;
    w->has_pending_kf = true;
    pthread_mutex_unlock(&w->mu);
    memset(k, 0, sizeof *k);
}

bool store_writer_busy(store_writer *w)
{
    pthread_mutex_lock(&w->mu);
    bool busy = w->has_job || w->running;
    pthread_mutex_unlock(&w->mu);
    return busy;
}

bf_status store_writer_finish(store_writer *w)
{
    if (!w) return bf_fail(BF_INVALID_ARG, "store_writer_finish: NULL writer");
    pthread_mutex_lock(&w->mu);
    wait_idle(w);
    bf_status s = error_of(w);
    pthread_mutex_unlock(&w->mu);
    return s;
}

store_write_stats store_writer_stats(store_writer *w)
{
    pthread_mutex_lock(&w->mu);
    store_write_stats st = w->stats;
    pthread_mutex_unlock(&w->mu);
    return st;
}

void store_writer_close(store_writer *w)
{
    if (!w) return;
    if (w->has_thread) {
        pthread_mutex_lock(&w->mu);
        wait_idle(w);
        w->stop = true;
        pthread_cond_broadcast(&w->cv);
        pthread_mutex_unlock(&w->mu);
        pthread_join(w->thread, NULL);
    }
    job_free(&w->job);
    store_keyframes_free(&w->pending_kf);
    pthread_mutex_destroy(&w->mu);
    pthread_cond_destroy(&w->cv);
    store_unlock(w->lock_fd); /* the lock with it */
    free(w->entries);
    free(w);
}
