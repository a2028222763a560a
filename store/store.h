/* store: the scene store, a map on disk (DESIGN.md sections 1 and 7;
 * the format: docs/formats.md, "Scene store").
 *
 * A store is a folder: one zstd-compressed file per world chunk
 * (chunks/c_X_Y_Z.bfc, a versioned header with xxHash checksums of itself
 * and of its payload), the scan's trajectory (trajectory.bin, checksummed),
 * its relocalisation keyframes (keyframes.bin, checksummed) and an index (store.json: the map's geometry, the last pose, the chunks
 * with their content digests). Every file is written atomically: a temp
 * file, fsync, rename, then an fsync of the folder, so a file on disk is
 * always a whole one, from this write or from an earlier one.
 *
 * The chunk files are the truth: a reader loads every valid chunk file it
 * finds, reports the ones it must skip (corrupt, truncated, unreadable) by
 * name and loads the rest; the index and the trajectory add the pose and
 * the history, and a store whose index is lost still opens (from the chunk
 * headers and the trajectory).
 *
 * Writing goes through a writer with a thread of its own: the loop hands it
 * a host copy of the map (hostmap) and goes on; the writer rewrites only the
 * chunks whose content changed since its last write. Depends on core,
 * hostmap, zstd, xxHash and cJSON; no Vulkan, so the store can be read,
 * checked and fuzzed without a device.
 */
#ifndef BF_STORE_H
#define BF_STORE_H

#include "core/core.h"
#include "hostmap/hostmap.h"

#define STORE_VERSION 1u

/* The map's geometry and where the scan stands. */
typedef struct store_meta {
    float chunk_m;          /* chunk edge [m] */
    uint32_t max_level;     /* finest octree level the map may hold (read without the index: the finest its bricks hold) */
    bf_vec3 origin_w;       /* world point of chunk (0,0,0)'s corner */
    uint32_t frames;        /* frames the scan has handled (the trajectory's poses) */
    bool has_pose;          /* last_pose is known */
    bf_se3 last_pose;       /* the last good pose (camera to world): where a resumed scan starts */
    double last_t_s;        /* the depth timestamp of the last frame handled */
} store_meta;

/* What a read found. Chunks it skipped were warned about by name. */
typedef struct store_report {
    uint32_t n_chunks;      /* chunk files loaded */
    uint32_t n_bricks;
    uint32_t n_bad;         /* chunk files skipped: corrupt, truncated, unreadable, inconsistent */
    uint32_t n_missing;     /* chunks the index lists with no valid file: absent or bad (a bad one is in n_bad too) */
    uint32_t n_unindexed;   /* valid chunk files the index does not list (written after it) */
    bool index_ok;          /* store.json read and consistent */
    bool trajectory_ok;     /* trajectory.bin read and its checksum right */
    bool index_found;       /* store.json is there, read or not (written whole, after the chunks) */
    bool trajectory_found;  /* trajectory.bin is there, read or not */
    bool keyframes_found;   /* keyframes.bin is there, read or not (written after trajectory.bin) */
    uint64_t bytes_files;   /* bytes of the chunk files loaded */
    uint64_t bytes_raw;     /* their payloads uncompressed */
    uint32_t flush;         /* the index's write count (0 without one) */
    char first_bad[BF_ERROR_CAP]; /* the first skipped file's message, "" if none */
} store_report;

/* The relocalisation keyframes of a scan (keyframes.bin, recon/reloc.c):
 * each keyframe's pose and the ORB keypoints of its colour that its depth
 * lifted, as plain arrays, so a resumed scan can find a camera that starts
 * anywhere a keyframe saw. */
typedef struct store_keyframe {
    bf_se3 T_wc;   /* camera to world */
    uint32_t n;    /* keypoints */
    uint8_t *desc; /* n ORB descriptors of 32 bytes */
    float *xyz;    /* n points in the keyframe's camera [m], x y z each */
} store_keyframe;

typedef struct store_keyframes {
    uint32_t n;
    store_keyframe *kf;
} store_keyframes;

#define STORE_MAX_KEYFRAMES 4096u   /* keyframes a file holds at most */
#define STORE_MAX_KEYPOINTS 100000u /* keypoints of one keyframe at most */

void store_keyframes_free(store_keyframes *k); /* frees the arrays; zeroes *k */
/* Writes dir/keyframes.bin atomically (a temp file, fsync, rename, the
 * folder's fsync); an empty set writes a file of none. */
bf_status store_keyframes_write(const char *dir, const store_keyframes *k);
/* Reads dir/keyframes.bin into *out: a store without the file (written
 * before it existed, or killed before its last write) has none, BF_OK.
 * BF_FORMAT names the file and the reason when it is corrupt or
 * truncated, BF_UNSUPPORTED a newer version; *out is written only on
 * success. */
bf_status store_keyframes_read(const char *dir, store_keyframes *out);

/* True when dir holds a store (its index or its chunks folder). */
bool store_exists(const char *dir);
/* True when dir holds a store beyond doubt: a store.json naming the format,
 * or a chunk file in chunks/ (store_exists takes any chunks/ folder or
 * store.json: right for a folder named as a store, too loose for telling
 * whether a folder met on the way is one). */
bool store_is_written(const char *dir);

/* Reads the store in dir: every valid chunk into *map (bricks in the
 * store's canonical order: chunk key, then level, then cell z, y, x), the
 * geometry and last pose into *meta, the trajectory into *traj (may be
 * NULL). A bad chunk file is skipped with a warning naming it; BF_IO when
 * dir is not a readable store, BF_FORMAT when nothing in it is usable
 * (no index, no trajectory and only bad chunk files), BF_UNSUPPORTED for a
 * newer version. A store whose writer was killed before its first write is
 * empty (no bricks, meta.has_pose false). Outputs are written only on
 * success. */
bf_status store_read(const char *dir, hostmap *map, store_meta *meta, bf_traj *traj, store_report *rep);

/* Single chunk files in dir/chunks, without index or trajectory: a
 * streaming tier on disk (stream/). store_put_chunks writes one file per
 * chunk of m (sorted in place), each atomically (no folder fsync: a spill
 * is not kept across runs), and adds their bytes to *bytes (may be NULL).
 * store_get_chunk reads chunk key's file (checked as store_read checks it)
 * into *out (replaced); BF_IO when it is absent. */
bf_status store_put_chunks(const char *dir, hostmap *m, const store_meta *meta, uint64_t *bytes);
bf_status store_get_chunk(const char *dir, const int32_t key[3], const store_meta *meta, hostmap *out, uint64_t *bytes);

/* xxHash (XXH3, 64 bits) of a map's contents in the canonical order
 * (hostmap_sort): per brick its chunk key and its record as a chunk file
 * holds it without colour (cell, level, error, sign and confidence words),
 * then, when the map has colour, its 512 RGB565 colours. Equal for equal
 * maps whatever the order of their bricks (stats.json's map_digest,
 * docs/determinism.md). A map already in the canonical order is read in
 * place; another is sorted in a copy. */
bf_status store_map_digest(const hostmap *map, uint64_t *out);

/* ------------------------------------------------------------ writing */

typedef struct store_writer store_writer; /* opaque */

typedef struct store_write_stats {
    uint32_t writes;          /* maps written (flushes done) */
    uint32_t chunks;          /* chunks in the store after the last write */
    uint64_t bricks;          /* bricks in it */
    uint64_t chunks_written;  /* chunk files rewritten, over all writes */
    uint64_t chunks_removed;  /* chunk files removed (chunks that became empty) */
    uint64_t bytes_written;   /* bytes of every file written */
    uint64_t bytes_on_disk;   /* chunk file bytes after the last write */
    uint32_t keyframes;       /* keyframes this writer put in keyframes.bin (by a write that finished) */
    double ms_last, ms_max, ms_total; /* wall time of the writes (the writer's thread) */
} store_write_stats;

/* One writer a store: an exclusive flock on the folder dir (which must
 * exist), *fd its descriptor (store_unlock releases; the lock goes with the
 * process, so a kill frees it). BF_INVALID_ARG when another process holds
 * it ("another bitfuse is writing this store"); where the file system has
 * no such locks (NFS without lock support), a warning and *fd = -1. */
bf_status store_lock(const char *dir, int *fd);
void store_unlock(int fd); /* -1: nothing */
/* Opens dir for writing (created if missing), under its lock: lock_fd, one
 * the caller took with store_lock (owned from here, released with the
 * writer or on failure), or -1 to take it here. resume false: dir must not
 * hold a store yet (BF_INVALID_ARG: the message says to resume or choose
 * another folder). resume true: it must (BF_IO otherwise); the writer then
 * knows the stored chunks' digests and rewrites only what changes. */
bf_status store_writer_open_locked(const char *dir, bool resume, int lock_fd, store_writer **out);
bf_status store_writer_open(const char *dir, bool resume, store_writer **out); /* lock_fd -1 */
/* Removes a store's files (chunk files, temp files, trajectory, index, keyframes) and
 * keeps the folder: for a store whose first write never finished (chunk
 * files but no pose), which a resumed scan starts anew. The caller holds
 * the store's lock (store_lock). */
bf_status store_clear(const char *dir);
/* Hands the writer a map to write (taken: *map is emptied) with its meta
 * and trajectory (copied). Waits first while an earlier write is running.
 * Returns at once, the write runs on the writer's thread; an error of an
 * earlier write comes back here (and from store_writer_finish), and then
 * nothing more is written. */
bf_status store_writer_submit(store_writer *w, hostmap *map, const store_meta *meta, const bf_traj *traj);
/* Hands the writer keyframes to write with the next map (taken: *k is
 * emptied; keyframes handed over before and not yet written are
 * replaced). keyframes.bin is written after the trajectory and before the
 * index; a map handed over without new keyframes leaves the file. */
void store_writer_keyframes(store_writer *w, store_keyframes *k);
/* True while a write is running: a caller that flushes periodically skips
 * a flush rather than wait. */
bool store_writer_busy(store_writer *w);
/* Waits for the running write and returns the first error of any write. */
bf_status store_writer_finish(store_writer *w);
store_write_stats store_writer_stats(store_writer *w);
/* Waits for the running write and frees the writer. NULL is a no-op. */
void store_writer_close(store_writer *w);

#endif
