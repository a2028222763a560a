/* fusion: the sign-bit map on the GPU and windowed fusion into it
 * (DESIGN.md sections 3 and 4; Reichl, Weiss, Westermann 2016).
 *
 * A map is a hash of world chunks, each an octree of 8x8x8 bricks at the
 * level each part of the scene needs, with one sign bit and one confidence
 * bit per voxel. Frames are added one at a time with their camera pose;
 * every frame allocates the bricks its depth samples need, integrates new
 * bricks quickly from the last few frames (sub-cache), and integrates a
 * slice of the current window's bricks (the window of n frames slides by
 * n/2; its integration is spread over the next n/2 frames).
 *
 * A frame comes in once, through the frame ring's host-visible incoming
 * slot (fusion_upload_frame), where tracking reads it too; fusing copies it
 * into the ring. fusion_add_frame does a frame in a submission of its own;
 * recon/ records fusion_cmd_fuse into the submission it shares with the
 * ray-cast and the tracking reference.
 *
 * Layout shared with the shaders: shaders/fusion.glsl.h (the chunk lookup:
 * shaders/fusion_hash.glsl.h). Host copies of the map for export and tests:
 * hostmap/hostmap.h (fusion_snapshot_take). See docs/fusion.md.
 */
#ifndef BF_FUSION_H
#define BF_FUSION_H

#include "core/core.h"
#include "gpu/gpu.h"
#include "hostmap/hostmap.h"

typedef struct fusion_map fusion_map; /* opaque */

typedef struct fusion_config {
    float chunk_m;          /* edge of a world chunk [m], default 2 */
    uint32_t max_level;     /* finest octree level, default 8 (~1 mm at 2 m chunks) */
    float voxel_ratio;      /* voxel-to-pixel ratio of the level rule, default 1 */
    float voxel_sigmas;     /* the level rule's voxel is also at least this many sigma(z) of the sensor's
                               noise, 0 (default): the footprint alone (docs/real_frames.md) */
    uint32_t window;        /* n: frames per window, even, default 40 */
    uint32_t subcache;      /* n^: frames for new bricks' quick integration, default 10 */
    uint32_t brick_cap;     /* bricks allocated at create, never grown; default 1 << 20 */
    uint32_t node_cap;      /* octree nodes, default 2 * brick_cap */
    uint32_t hash_buckets;  /* chunk hash buckets, default 4096 */
    uint32_t hash_overflow; /* overflow entries, default 4096 */
    bf_sensor sensor;       /* noise model and range, default Kinect v1 (recon/ sets its own) */
    float conf_weight;      /* accumulated weight that makes a voxel confident, default 4; a
                               window of fewer frames asks as many, the one window of a whole
                               sequence that short half as many (at least 1) */
    float band_sigmas;      /* allocation band around a sample: +-k sigma(z), default 3 */
    /* Shape of the integration kernel (docs/fusion_integrate.md): tuning for benchmarks and
       tests; every choice gives the same bits. 0: chosen by device type (the default). */
    uint32_t integrate_vpt; /* voxels per invocation, a power of two up to 64 */
    uint32_t integrate_bpg; /* list entries (bricks) per workgroup, 1..1024 */
    /* Workgroups per row of the grids the GPU sizes itself (the integration's and the
       allocation retries' indirect dispatches): 0 (default) the device's limit, at most
       65535 (Mesa allows no more along x); tests set a few to run the rows past the first. */
    uint32_t max_groups_x;
    /* Colour (DESIGN.md section 3): RGB565 of the confident voxels near the
       surface, addressed by popcount: a mask word per sub-brick, and per brick a
       chain of colour units of 14 colours each (docs/colour.md, "Layout"). */
    bool keep_colour;       /* default true */
    uint32_t colour_frames; /* frames of each window the colour pass reads, 1..32, default 4 (windows
                               alternate their offsets, so overlapping windows read new frames) */
    uint32_t colour_unit_cap; /* colour units (32 bytes, 14 colours each) allocated at create, default
                                 8 * brick_cap (as many as one storage binding holds) */
    /* The colour trim: bricks no window integrates again (and the whole map
       at fusion_flush) keep colour only on confident voxels within this L1
       distance of a confident voxel of the other sign, and give the units
       they no longer need back (docs/colour.md, "Colour off the surface").
       0: no trim (every shell the frames coloured stays), 1 or 2; default 1. */
    uint32_t colour_reach;
    /* A map that only holds what is loaded or inserted (a store to render, a
       particle set, a voxelised mesh): the frame passes' pipelines are not
       made (0.37 s of lavapipe's create) and frames are refused. Default false. */
    bool load_only;
} fusion_config;

/* The defaults above. */
fusion_config fusion_config_default(void);

/* Creates an empty map for frames of camera K. origin_w is the world point
 * that becomes the GPU's origin (the first camera position, usually): all
 * GPU coordinates are relative to it, in float. ctx is borrowed and must
 * outlive the map. BF_INVALID_ARG for a bad config (the message says
 * which field), BF_NO_MEMORY when the pools do not fit the device. */
bf_status fusion_create(gpu_context *ctx, const fusion_config *cfg, const bf_intrinsics *K, bf_vec3 origin_w,
                        fusion_map **out);
/* Waits for the map's GPU work and frees it. NULL is a no-op. */
void fusion_destroy(fusion_map *map);

/* The colour camera, when colour pixels do not show what the depth pixel
 * at the same place measured: its intrinsics (the image has the depth
 * image's size), its lens distortion (k1 k2 p1 p2 k3, OpenCV's
 * Brown-Conrady order; NULL: none) and T_colour_depth, which takes
 * depth-camera points to colour-camera points. NULL for Kc or the
 * transform: registered (the default; TUM, registered Kinect and OpenNI2
 * modes). BF_INVALID_ARG for values that are not finite or a zero focal
 * length. */
bf_status fusion_set_colour_camera(fusion_map *map, const bf_intrinsics *Kc, const double *dist,
                                   const bf_se3 *T_colour_depth);

/* Adds one frame seen from T_wc (camera to world): uploads it to the frame
 * ring, allocates bricks, integrates (sub-cache and the current window
 * slice), in one submission that it waits for. Depth must have K's size.
 * BF_POOL_FULL when a pool ran out, and only then: the frame is fused, the
 * requests that did not fit are dropped and counted, the map stays
 * consistent (fusion_check passes).
 * The same as fusion_upload_frame, then fusion_cmd_fuse in a submission of
 * its own, then fusion_finish_frame. */
bf_status fusion_add_frame(fusion_map *map, const bf_frame *f, const bf_se3 *T_wc);

/* ------------------------------------------------------------ the frame ring
 * The ring holds the last 2n frames on the GPU (depth and a record with the
 * map-to-camera transform) for the window's integration. A frame comes in
 * once, through the ring's incoming slot (host-visible): tracking reads it
 * there as a plain buffer and offset, and fusing it copies it into its ring
 * slot on the GPU. recon/ uses the steps below so that fusing, the ray-cast
 * and the tracking reference share one submission (DESIGN.md section 1). */

/* Where an uploaded frame's depth is, as readers on the GPU see it: raw
 * depth in the camera's units (K.depth_scale), width x height uint16 two per
 * word (the lower half first), from byte offset `offset` of `depth`. */
typedef struct fusion_frame_slot {
    gpu_buffer *depth;
    uint64_t offset;        /* bytes, a multiple of 4 */
    /* The frame's colour when it has one (whether or not the map keeps
     * colour: the tracker's photometric term reads it here too): RGB565 two
     * per word (the lower half first), the depth's size, from byte
     * colour_offset (a multiple of 4) of colour; else colour is NULL. */
    gpu_buffer *colour;
    uint64_t colour_offset;
} fusion_frame_slot;

/* Writes f's depth (and its colour, when it has one) into the incoming
 * slot (a host copy; no GPU work) and says where it is (out may be NULL).
 * It stays there until the next upload; readers must have finished with it
 * before then. Depth must have K's size (BF_INVALID_ARG). */
bf_status fusion_upload_frame(fusion_map *map, const bf_frame *f, fusion_frame_slot *out);
/* Records, into the context's open command buffer (gpu_begin), the fusion
 * of the uploaded frame seen from T_wc: its copy into the ring, allocation,
 * the sub-cache pass, the window's slice; it waits (a barrier) for what was
 * recorded before it, and what is recorded after it sees the new map. The
 * caller submits, then calls fusion_finish_frame. BF_INVALID_ARG without an
 * uploaded frame or for a pose that is not finite. */
bf_status fusion_cmd_fuse(fusion_map *map, const bf_se3 *T_wc);
/* After the submission holding fusion_cmd_fuse finished: reads the stage
 * times, the new window's brick count and the pool counters (copied into a
 * host-visible buffer by that submission, so nothing is downloaded), and
 * counts the frame. BF_POOL_FULL as fusion_add_frame. */
bf_status fusion_finish_frame(fusion_map *map);
/* Integrates whatever the schedule still owes (the last, partial windows),
 * as at the end of a sequence, then trims every brick's colour
 * (fusion_config.colour_reach). Frames fused after it still fuse, but the
 * bricks they revisit start from trimmed colour: flush once, at the end. */
bf_status fusion_flush(fusion_map *map);

/* ------------------------------------------------------------ statistics */

typedef struct fusion_stats {
    uint32_t n_frames;
    uint32_t n_chunks;               /* live hash entries (each takes hash memory; a chunk emptied of
                                        its bricks keeps its entry) */
    uint32_t n_nodes;
    uint32_t n_bricks;
    uint32_t bricks_per_level[16];
    uint64_t n_confident_voxels;
    uint64_t n_surface_voxels;       /* confident voxels with a confident neighbour of the other sign */
    uint32_t fail_nodes, fail_bricks, fail_hash; /* requests dropped for a full pool */
    uint32_t fail_colour;            /* times a brick's new colours found the colour pool empty */
    uint32_t n_colour_units;         /* colour units in use (14 colours each) */
    uint64_t n_coloured_voxels;
    /* Bytes of map data in use (what the scene needs), by part. */
    uint64_t bytes_sign, bytes_conf, bytes_info, bytes_nodes, bytes_hash, bytes_total;
    uint64_t bytes_colour;           /* colour masks and heads of the live bricks and the units in use (not in bytes_total,
                                        which is the geometry) */
    uint64_t bytes_reserved;         /* allocated at create */
    /* GPU time of the last frame by stage, ms. */
    double ms_upload, ms_alloc, ms_subcache, ms_window, ms_colour;
} fusion_stats;

/* GPU time of the last added frame by stage [ms], from Vulkan timestamps. */
typedef struct fusion_stage_ms {
    double upload, alloc, subcache, window, colour;
} fusion_stage_ms;
fusion_stage_ms fusion_last_stage_ms(const fusion_map *map);

/* Downloads the map (counters, records, bit planes) and fills *out: for
 * reports at the end of a run, not per frame. */
bf_status fusion_get_stats(fusion_map *map, fusion_stats *out);
/* GPU memory the map's pools take (fusion_stats.bytes_reserved, without
 * the download); 0 for NULL. */
uint64_t fusion_reserved_bytes(const fusion_map *map);

/* ------------------------------------------------------------ GPU view */

/* The map's buffers as readers on the GPU see them (render/'s ray-caster):
 * layouts in shaders/fusion.glsl.h. Readers must not write them, and must
 * record their work after fusion_add_frame / fusion_flush returned (those
 * wait for their own submissions) or after fusion_cmd_fuse in the same
 * recording (it ends with a barrier). Valid until fusion_destroy. */
typedef struct fusion_gpu_view {
    gpu_buffer *hash;       /* n_entries entries of FUSION_ENTRY_WORDS */
    gpu_buffer *nodes;      /* FUSION_NODE_WORDS per node */
    gpu_buffer *info;       /* FUSION_BRICK_INFO_WORDS per brick slot */
    gpu_buffer *sign, *conf; /* BRICK_WORDS per brick slot */
    gpu_buffer *addresses;  /* FUSION_ADDRS device addresses (uvec2, FUSION_ADDR_*): hash, nodes, sign, conf,
                               the depth and colour rings */
    uint64_t id;            /* this map's, unique in the process: a reader's bindings follow it */
    gpu_buffer *cmask, *cpool, *chead; /* colour masks, units and heads (one word each when the map keeps no colour) */
    bool has_colour;
    uint32_t n_buckets;     /* hash buckets (fusion_hash's modulus) */
    uint32_t n_entries;     /* buckets * FUSION_BUCKET_SLOTS + overflow */
    uint32_t max_level;
    float chunk_m;
    bf_vec3 origin_w;       /* world point of the GPU's origin (double) */
} fusion_gpu_view;

fusion_gpu_view fusion_gpu_view_get(const fusion_map *map);
/* The camera pose relative to the map origin, T_mc (camera to map frame):
 * T_wc with the origin subtracted from its translation in double. The GPU
 * sees only this (fusion's frame records, the ray-cast), so a map 10 km
 * from the world origin works as one at the origin (DESIGN.md section 10). */
bf_se3 fusion_camera_to_map(const fusion_map *map, const bf_se3 *T_wc);
/* The config the map was created with (defaults filled in). */
const fusion_config *fusion_get_config(const fusion_map *map);
/* Frames added so far. */
uint32_t fusion_frame_count(const fusion_map *map);
/* Windows whose integration has been done (recorded by a finished
 * fusion_cmd_fuse or fusion_flush). Until the first one, no voxel is
 * confident: only the sub-cache's quick, non-confident signs exist. */
uint32_t fusion_windows_done(const fusion_map *map);
/* Moves the GPU's origin (fusion_create's origin_w) while the map is still
 * empty: a map made before its first pose is known (recon/ makes everything
 * before the camera starts) then gets the origin it would have been made
 * with. BF_INVALID_ARG once a frame was uploaded or for a point that is not
 * finite; the map is then unchanged. */
bf_status fusion_set_origin(fusion_map *map, bf_vec3 origin_w);

/* ------------------------------------------------------------ host copies */

/* Downloads every live brick into a host copy (hostmap/hostmap.h). */
bf_status fusion_snapshot_take(fusion_map *map, hostmap *out);

/* Loads a host copy of a map (a reopened scene store, store/) into this
 * map, which must be empty (no frame uploaded, nothing loaded): every
 * brick with its bits and error, in slots [0, n); the map's origin becomes
 * in->origin_w. Loaded bricks belong to no window until a frame touches
 * them. BF_INVALID_ARG for another chunk edge, a level above max_level or a
 * brick given twice; BF_POOL_FULL when the pools cannot hold it. On failure
 * the map is empty again. */
bf_status fusion_load(fusion_map *map, const hostmap *in);
/* Empties a map that holds only what fusion_load put in (no frame
 * uploaded): as fusion_create made it, pools and pipelines kept, ready for
 * the next load (render/'s particle sets, re-binned per time step). After
 * a load it clears only what the load wrote (docs/fusion.md), so buffers
 * of fusion_gpu_view_get are for reading: writes through them are not
 * undone. BF_INVALID_ARG for a map with frames. */
bf_status fusion_clear(fusion_map *map);

/* ------------------------------------------------------------ streaming
 * Chunks out of the pools and back (stream/ decides which; DESIGN.md
 * section 1). Both run between frames, on the host, through a full host
 * copy of the index structures that is rebuilt compactly, so they cost tens
 * of milliseconds: for a few calls per window, not per frame. */

/* How full the pools are, as of the last finished frame, load or
 * streaming move (read back with the frame: no download). */
typedef struct fusion_pool_use {
    uint32_t bricks, brick_cap;
    uint32_t nodes, node_cap;     /* the node pool is a bump allocator: only a rebuild (eviction) compacts it */
    uint32_t overflow, overflow_cap;
} fusion_pool_use;
fusion_pool_use fusion_pool_usage(const fusion_map *map);
/* The keys of the chunks resident in the pools (*keys malloc'd). */
bf_status fusion_chunk_keys(fusion_map *map, int32_t (**keys)[3], uint32_t *n);
/* Moves the chunks keys[0..n) out of the pools into *out (bricks with
 * their bits and error; *out is replaced, the caller frees it) and gives
 * their bricks, nodes and hash entries back. A chunk with a brick a window
 * still has to integrate (stamped by the pending window or later) stays, as
 * does a key that is not resident; *n_evicted counts the chunks moved. */
bf_status fusion_evict_chunks(fusion_map *map, const int32_t (*keys)[3], uint32_t n, hostmap *out,
                              uint32_t *n_evicted);
/* Rebuilds the index of the resident chunks compactly: the node pool is a
 * bump allocator and bricks removed as empty leave their nodes behind, so
 * a long scan in small pools runs out of nodes before bricks. */
bf_status fusion_compact(fusion_map *map);
/* Puts bricks (evicted earlier, same chunk edge and origin) back into the
 * pools. A brick the map made anew meanwhile keeps its confident voxels;
 * the stored ones fill in where it has none. BF_POOL_FULL (nothing
 * inserted) when the free slots do not suffice. */
bf_status fusion_insert_bricks(fusion_map *map, const hostmap *in);

/* Integrity check (SQLite's integrity_check): every hash entry, node and
 * brick is reachable exactly once, brick records agree with the nodes that
 * own them, counters agree with what is live. BF_NUMERIC with a message on
 * the first inconsistency. Downloads the whole map: for tests. */
bf_status fusion_check(fusion_map *map);

#endif
