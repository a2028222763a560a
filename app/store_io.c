/* The scene store in the loop's commands (replay, live): reopening a
 * stored scan to resume it, flushing the map into the store as the scan
 * goes (every --store-every seconds, on the store's writer thread) and at
 * the end, and the store's part of stats.json. */
#include <math.h>
#include <string.h>

#include "app.h"
#include "recon/recon.h"

bf_status app_store_open(app_store *st, const char *dir, bool resume, double every_s)
{
    memset(st, 0, sizeof *st);
    st->dir = dir;
    st->every_s = every_s;
    st->last_s = bf_time_s();
    bf_status s = BF_OK;
    /* The lock first, where the folder is there: reading a store another
     * scan is writing, or clearing it, would be reading or deleting its
     * files in flight; that scan is named instead. */
    int lock_fd = -1;
    if (bf_file_exists(dir)) s = store_lock(dir, &lock_fd);
    st->lock_refused = s == BF_INVALID_ARG;
    if (s == BF_OK && resume) {
        s = store_read(dir, &st->map, &st->meta, &st->traj, &st->report);
        if (s == BF_UNSUPPORTED) s = BF_FORMAT; /* a newer store: unreadable here (exit 3) */
        /* The writer rewrites and removes every chunk the index lists that
         * the resumed map lacks: a chunk file that did not load (damaged,
         * or whole but at odds with a damaged store.json) would be lost for
         * good. Refuse, naming it, and let the user decide. */
        /* A listed chunk whose file is gone cannot be lost any more: moving a
         * bad file aside (what the refusal below advises) must let the scan
         * resume. Only a store where nothing listed loaded (chunks/ emptied or
         * not mounted) is refused for missing files alone. */
        if (s == BF_OK && st->report.n_missing && !st->report.n_bad && st->report.n_chunks > st->report.n_unindexed)
            bf_warn("store: %s: %u listed chunk%s gone: the scan resumes without them", dir, st->report.n_missing,
                    st->report.n_missing == 1 ? " is" : "s are");
        else if (s == BF_OK && !st->report.n_bad && st->report.n_missing)
            s = st->report.n_missing == 1
                    ? bf_fail(BF_FORMAT,
                              "%s: the one chunk file its index lists is not there (chunks/ emptied, or not "
                              "mounted?): resuming would start its map anew; put it back, or scan into another folder",
                              dir)
                    : bf_fail(BF_FORMAT,
                              "%s: none of the %u chunk files its index lists is there (chunks/ emptied, or not "
                              "mounted?): resuming would start its map anew; put them back, or scan into another "
                              "folder",
                              dir, st->report.n_missing);
        else if (s == BF_OK && (st->report.n_bad || st->report.n_missing))
            s = bf_fail(BF_FORMAT,
                        "%s: %u chunk file%s could not be loaded and %u listed chunk%s missing (the first: %s): "
                        "resuming would replace or remove them; export what reads (bitfuse export) or move the "
                        "bad files aside first",
                        dir, st->report.n_bad, st->report.n_bad == 1 ? "" : "s", st->report.n_missing,
                        st->report.n_missing == 1 ? " is" : "s are", st->report.first_bad);
        /* A store killed before its first write finished holds no pose to
         * go on from (at most some chunk files of that write): the scan
         * starts anew into it, as if it had never been saved. */
        if (s == BF_OK && st->meta.has_pose) st->is_resumed = true;
        /* The keyframes only help to find the camera: without them (an
         * older store, one killed before its end, a bad file) the scan
         * resumes from the trajectory's poses as before. */
        if (s == BF_OK && st->is_resumed && store_keyframes_read(dir, &st->keyframes) != BF_OK)
            bf_warn("store: %s; the scan resumes with the trajectory's poses as keyframes", bf_last_error());
        /* A map without a pose but with store.json, trajectory.bin or
         * keyframes.bin on disk (each written whole, atomically, after the
         * chunks) is a store whose index and trajectory are damaged or were
         * removed, not one whose first write never finished: clearing it
         * would delete every chunk file. */
        bool was_written = st->report.index_found || st->report.trajectory_found || st->report.keyframes_found;
        if (s == BF_OK && !st->is_resumed && st->map.n_bricks && was_written)
            s = bf_fail(BF_FORMAT,
                        "%s: holds a map (%u chunk files) but no last pose to resume from (store.json and "
                        "trajectory.bin are unreadable or gone): export it (bitfuse export) or scan into another "
                        "folder",
                        dir, st->report.n_chunks);
        if (s == BF_OK && !st->is_resumed) {
            bf_warn("store: %s keeps no last pose (its first write never finished): the scan starts anew into it",
                    dir);
            hostmap_free(&st->map);
            bf_traj_free(&st->traj);
            s = store_clear(dir);
        }
    }
    if (s == BF_OK) s = store_writer_open_locked(dir, resume, lock_fd, &st->writer); /* owns the lock */
    else store_unlock(lock_fd);
    if (s != BF_OK) app_store_close(st);
    return s;
}

void app_store_resume_config(app_store *st, recon_resume_state *rs, recon_config *loop)
{
    rs->map = &st->map;
    rs->T_last = st->meta.last_pose;
    rs->t_last_s = st->meta.last_t_s;
    rs->traj = &st->traj;
    rs->keyframes = &st->keyframes;
    /* The stored map's geometry decides: a chunk edge or a finest level
     * other than the one it was built with cannot hold its bricks. A store
     * read without its index knows only the finest level its bricks hold:
     * the loop's own level stands unless those bricks are finer. */
    uint32_t level = st->meta.max_level;
    if (!st->report.index_ok && loop->fusion.max_level > level) level = loop->fusion.max_level;
    bool from_bricks = !st->report.index_ok && level > loop->fusion.max_level;
    if (loop->fusion.chunk_m != st->meta.chunk_m || loop->fusion.max_level != level)
        bf_info("store: %s: resuming with its chunk edge %g m and finest level %u%s", st->dir, st->meta.chunk_m, level,
                from_bricks ? " (the finest its bricks hold; its index is lost)" : "");
    loop->fusion.chunk_m = st->meta.chunk_m;
    loop->fusion.max_level = level;
}

/* The loop's keyframes to the writer, with the map about to follow, when
 * they changed since the last hand-over: a resumed scan finds the camera
 * from them wherever they saw. Only keyframes with colour's keypoints
 * (relocalisation and colour candidates on): a loop without them leaves
 * the file an earlier session wrote, which is in the same map's frame. A
 * failure is a warning: the map still goes. */
static void hand_keyframes(app_store *st, const recon *loop)
{
    uint64_t gen = recon_keyframes_generation(loop);
    if (st->has_kf_generation && gen == st->kf_generation) return;
    store_keyframes k = {0};
    bf_status s = recon_keyframes(loop, &k);
    bool has_colour = false;
    for (uint32_t i = 0; s == BF_OK && i < k.n; i++) has_colour |= k.kf[i].n > 0;
    if (s == BF_OK && has_colour) store_writer_keyframes(st->writer, &k);
    if (s != BF_OK) bf_warn("store: the keyframes were not kept (a resumed scan starts from its poses): %s", bf_last_error());
    st->kf_generation = gen, st->has_kf_generation = true;
    store_keyframes_free(&k);
}

/* A snapshot of the run's map and where the scan stands, to the writer. */
static bf_status flush(app_store *st, recon_run *run, double t_last_s)
{
    if (run->loop) hand_keyframes(st, run->loop);
    hostmap snap = {0};
    bf_status s = run->loop ? recon_snapshot(run->loop, &snap) : fusion_snapshot_take(run->map, &snap);
    if (s != BF_OK) return s;
    const fusion_config *fc = fusion_get_config(run->map);
    store_meta meta = {.chunk_m = fc->chunk_m, .max_level = fc->max_level, .origin_w = snap.origin_w,
                       .frames = (uint32_t)run->est.n, .last_t_s = t_last_s};
    /* The last estimate is the last good pose (a lost frame reports it). */
    if (run->est.n) {
        meta.has_pose = true;
        meta.last_pose = run->est.T_wc[run->est.n - 1];
    }
    double t0 = bf_time_s();
    s = store_writer_submit(st->writer, &snap, &meta, &run->est);
    hostmap_free(&snap);
    st->ms_submit_max = fmax(st->ms_submit_max, 1e3 * (bf_time_s() - t0));
    st->flushes++;
    st->last_s = bf_time_s();
    return s;
}

bf_status app_store_frame(app_store *st, recon_run *run, const bf_frame *f)
{
    if (!st->writer || st->every_s <= 0 || bf_time_s() - st->last_s < st->every_s) return BF_OK;
    /* Nothing fused yet (a camera still dark): a pose without a map would
     * resume as a scan of nothing. */
    if (!run->is_resumed && (run->loop ? run->counts.tracked : run->n_fused) == 0) return BF_OK;
    if (store_writer_busy(st->writer)) {
        st->skipped++; /* the last write is still going: the next frame tries again */
        return BF_OK;
    }
    double t0 = bf_time_s();
    bf_status s = flush(st, run, f->t_depth_s);
    st->ms_flush_max = fmax(st->ms_flush_max, 1e3 * (bf_time_s() - t0));
    return s;
}

bf_status app_store_finish(app_store *st, recon_run *run)
{
    if (!st->writer) return BF_OK;
    double t_last = run->est.n ? run->est.t_s[run->est.n - 1] : 0;
    bf_status s = run->map ? flush(st, run, t_last) : BF_OK;
    bf_status f = store_writer_finish(st->writer);
    st->stats = store_writer_stats(st->writer);
    if (s == BF_OK) s = f;
    st->end_failed = s != BF_OK;
    return s;
}

void app_store_json(cJSON *parent, const app_store *st)
{
    if (!st->writer) {
        cJSON_AddNullToObject(parent, "store");
        return;
    }
    cJSON *o = app_json_object(parent, "store");
    cJSON_AddStringToObject(o, "path", st->dir);
    cJSON_AddBoolToObject(o, "resumed", st->is_resumed);
    cJSON_AddNumberToObject(o, "flush_every_s", st->every_s);
    cJSON_AddNumberToObject(o, "writes", st->stats.writes);
    cJSON_AddNumberToObject(o, "writes_skipped_busy", st->skipped);
    /* What the store holds at the end, as the summary says: after a failed
     * last write the write before it, and with none this run, what it held
     * when it was reopened (a failed write renames none of its files). */
    cJSON_AddBoolToObject(o, "last_write_failed", st->end_failed);
    bool held_before = st->end_failed && st->stats.writes == 0;
    cJSON_AddNumberToObject(o, "chunks", held_before ? st->report.n_chunks : st->stats.chunks);
    cJSON_AddNumberToObject(o, "bricks", (double)(held_before ? st->report.n_bricks : st->stats.bricks));
    cJSON_AddNumberToObject(o, "chunk_files_written", (double)st->stats.chunks_written);
    cJSON_AddNumberToObject(o, "chunk_files_removed", (double)st->stats.chunks_removed);
    cJSON_AddNumberToObject(o, "bytes_written", (double)st->stats.bytes_written);
    cJSON_AddNumberToObject(o, "bytes_on_disk", (double)(held_before ? st->report.bytes_files : st->stats.bytes_on_disk));
    cJSON_AddNumberToObject(o, "write_ms_max", st->stats.ms_max);
    cJSON_AddNumberToObject(o, "write_ms_mean", st->stats.writes ? st->stats.ms_total / st->stats.writes : NAN);
    cJSON_AddNumberToObject(o, "loop_flush_ms_max", st->ms_flush_max);
    cJSON_AddNumberToObject(o, "keyframes_written", st->stats.keyframes);
    if (st->is_resumed) {
        cJSON *r = app_json_object(o, "reopened");
        cJSON_AddNumberToObject(r, "frames", st->meta.frames);
        cJSON_AddNumberToObject(r, "chunks", st->report.n_chunks);
        cJSON_AddNumberToObject(r, "bricks", st->report.n_bricks);
        cJSON_AddNumberToObject(r, "bad_chunk_files", st->report.n_bad);
        cJSON_AddNumberToObject(r, "keyframes", st->keyframes.n);
    }
}

void app_store_print(const app_store *st)
{
    if (!st->writer) return;
    /* After a failed last write the writer's figures are its last whole
     * write's (none: the store holds what it held before the run). */
    if (st->end_failed && st->stats.writes == 0) {
        printf("  store            %s: not written (the error above); %s\n", st->dir,
               st->is_resumed ? "it holds what it held before" : "nothing of this scan is in it");
        return;
    }
    printf("  store            %s: %s%u chunk%s, %llu brick%s, %.2f MiB on disk, %u write%s this run", st->dir,
           st->end_failed ? "the last write failed (the error above); the one before holds " : "", st->stats.chunks,
           app_s(st->stats.chunks), (unsigned long long)st->stats.bricks, app_s(st->stats.bricks),
           st->stats.bytes_on_disk / 1048576.0, st->stats.writes, app_s(st->stats.writes));
    if (st->is_resumed) printf(" (resumed after %u frame%s)", st->meta.frames, app_s(st->meta.frames));
    printf("\n");
}

void app_store_close(app_store *st)
{
    store_writer_close(st->writer);
    hostmap_free(&st->map);
    bf_traj_free(&st->traj);
    store_keyframes_free(&st->keyframes);
    st->writer = NULL;
}
