/* stream: which world chunks live in the GPU pools (DESIGN.md section 1,
 * "stream"). Chunks farther from the camera than a safety radius (and not
 * needed by the current window) move out of the pools into a CPU cache;
 * beyond the cache's byte budget they move on to disk (single chunk files
 * of the scene store's format in a spill folder); when the camera comes
 * back within the radius they return to the pools before the tracker's
 * ray-cast can see their space. When the pools fill up regardless, the
 * farthest chunks leave first. So a scan goes on whatever the scene's
 * extent, in bounded GPU and CPU memory.
 *
 * The moves are fusion's (fusion_evict_chunks, fusion_insert_bricks): host
 * work between frames, tens of milliseconds each, done every `every_frames`
 * frames and at most `max_chunks` chunks at a time so the cost is spread.
 * Depends on core, hostmap, fusion and store.
 */
#ifndef BF_STREAM_H
#define BF_STREAM_H

#include "core/core.h"
#include "fusion/fusion.h"
#include "hostmap/hostmap.h"

typedef struct stream stream; /* opaque */

typedef struct stream_config {
    bool enabled;            /* default true */
    float radius_m;          /* chunks within this distance of the camera stay (or come back), default 6.5
                                (Kinect v1's 4.5 m range plus 2 m of travel between checks) */
    float hysteresis_m;      /* they leave only beyond radius + this, default 1 */
    uint32_t every_frames;   /* frames between checks, default 10 */
    uint32_t max_chunks;     /* chunks moved out and in per check, default 16 */
    float high_water;        /* pool use (bricks or nodes) above which the farthest chunks leave whatever their
                                distance, default 0.85 */
    uint64_t cache_bytes;    /* CPU cache budget; beyond it chunks go to disk, default 256 MiB */
} stream_config;

stream_config stream_config_default(void);

typedef struct stream_stats {
    uint32_t checks;             /* checks that moved something or looked */
    uint32_t resident;           /* chunks in the pools at the last check */
    uint32_t cached, on_disk;    /* chunks in the CPU cache, on disk now */
    uint64_t chunks_out, chunks_in; /* chunks moved out of / into the pools, over the run */
    uint64_t bricks_out, bricks_in;
    uint64_t to_disk, from_disk; /* chunks written to / read from the spill folder */
    uint64_t cache_bytes, cache_bytes_max; /* the CPU cache now and at its largest */
    uint64_t disk_bytes;         /* bytes of chunk files written to the spill folder */
    uint32_t pressure_checks;    /* checks that evicted for pool pressure, not distance */
    uint32_t compactions;        /* index rebuilds for a full node pool with nothing to evict */
    uint32_t loads_deferred;     /* checks where near chunks had to wait for room in the pools */
    uint32_t spill_failures;     /* spills that failed (0 or 1: the disk tier is off after one) */
    double ms_last, ms_max, ms_total; /* wall time of the checks that moved chunks */
} stream_stats;

/* Streams map's chunks (borrowed; it must outlive the stream). spill_dir:
 * a folder for the disk tier (created when first needed, removed with its
 * files by stream_destroy); NULL: a fresh folder under $TMPDIR or /tmp. */
bf_status stream_create(const stream_config *cfg, fusion_map *map, const char *spill_dir, stream **out);
/* Waits for nothing (the map must be idle between frames) and frees the
 * cache and the spill folder. NULL is a no-op. */
void stream_destroy(stream *s);

/* After frame `frame_index` was fused with the camera at T_wc: every
 * every_frames frames (or at once when the pools are above high water)
 * moves far chunks out and near ones in. force: check now. */
bf_status stream_update(stream *s, const bf_se3 *T_wc, uint32_t frame_index, bool force);
/* Takes the bricks of map (a host copy of a stored map, same origin and
 * chunk edge) into the cache, to come into the pools as the camera needs
 * them (a resumed scan whose map may exceed the pools); *map is emptied. */
bf_status stream_adopt(stream *s, hostmap *map);
/* The whole map: the pools' snapshot and every chunk out of them (cache
 * and disk), for export and the scene store. */
bf_status stream_gather(stream *s, hostmap *out);
stream_stats stream_get_stats(const stream *s);
/* A chunk file that could not be written (a full disk, an I/O error) does
 * not end the scan: the chunk stays in the CPU cache, a warning names the
 * file and the reason, and no chunk goes to disk for the rest of the run
 * (the cache then grows past cache_bytes). The first failure's message, or
 * NULL when none failed. */
const char *stream_spill_error(const stream *s);

#endif
