/* Declarations shared by fusion/'s files (SQLite's btreeInt.h idea). */
#ifndef BF_FUSION_INT_H
#define BF_FUSION_INT_H

#include "fusion.h"
#include "shaders/fusion.glsl.h"
#include "shaders/fusion_hash.glsl.h"

/* Work lists of brick slots: FUSION_LIST_* in shaders/fusion.glsl.h. */

struct fusion_map {
    gpu_context *ctx;
    fusion_config cfg;
    bf_intrinsics K;
    bf_vec3 origin_w;
    uint32_t ring_slots;      /* 2n */
    uint32_t n_entries;       /* hash entries: buckets * slots + overflow */

    /* The map (shaders/fusion.glsl.h has the layouts). */
    gpu_buffer *hash, *locks, *nodes, *info, *sign, *conf, *counters;
    gpu_buffer *addresses;    /* FUSION_ADDR_*: hash, nodes, sign, conf and the rings' device addresses */
    uint64_t id;              /* unique in the process (fusion_gpu_view.id) */
    gpu_buffer *free_stack;   /* brick slots not in use, FUSION_CNT_FREE_TOP of them */
    gpu_buffer *stamp;        /* per brick: index of the last frame that touched it */
    /* Colour (shaders/fusion.glsl.h "colour"; NULL without colour). */
    gpu_buffer *cmask;        /* BRICK_WORDS per brick slot: which voxels of each sub-brick have colour */
    gpu_buffer *chead;        /* per brick slot: its first colour unit or FUSION_NONE */
    gpu_buffer *cpool;        /* colour_unit_cap units of FUSION_COLOUR_UNIT_WORDS */
    gpu_buffer *cfree;        /* colour units not in use, FUSION_CNT_COLOUR_TOP of them */
    /* The frame ring. */
    gpu_buffer *frames;       /* ring_slots fusion_frame records */
    gpu_buffer *depth_ring;   /* ring_slots depth images, 2 pixels per word */
    gpu_buffer *colour_ring;  /* ring_slots colour images, RGB565, 2 pixels per word (with colour) */
    gpu_buffer *upload;       /* the incoming slot, host-visible: record, depth (and colour) of the next frame */
    gpu_buffer *readback;     /* host-visible: the counters and a new window's slice starts, per frame */
    /* Work lists. */
    gpu_buffer *samples;      /* retry queue of the allocation passes */
    gpu_buffer *new_list;     /* bricks created by the current frame */
    gpu_buffer *window_list;  /* bricks of the window being integrated, slice by slice */
    gpu_buffer *window_slices; /* its slices' counts and starts (FUSION_SLICE_WORDS) */
    gpu_buffer *trim_list;    /* bricks no window integrates again, for the colour trim */

    /* Pipelines and binding sets, created by each stage's file. */
    gpu_pipeline *p_alloc, *p_alloc_args;
    gpu_bindings *b_alloc, *b_alloc_args;
    gpu_pipeline *p_integrate, *p_integrate_args, *p_window_list;
    gpu_bindings *b_integrate_new, *b_integrate_window, *b_integrate_trim, *b_window_list;
    uint32_t integrate_bpg;   /* list entries per workgroup of the integration kernel */
    gpu_pipeline *p_remove;
    gpu_bindings *b_remove;
    gpu_pipeline *p_colour;
    gpu_bindings *b_colour, *b_colour_trim;
    uint32_t colour_bpg;      /* list entries per workgroup of the colour pass */
    bool colour_registered;   /* colour pixel i shows depth pixel i */
    bf_intrinsics Kc;         /* colour camera (when not registered) */
    bf_se3 T_colour_depth;
    double colour_dist[5];    /* its Brown-Conrady distortion, k1 k2 p1 p2 k3 */
    bool has_colour_frame;    /* the incoming slot's colour is to be fused (the map keeps colour) */

    /* Schedule (host side). */
    uint32_t n_frames;        /* frames added */
    uint32_t window_first;    /* first frame of the window being integrated */
    uint32_t window_end;      /* one past its last frame */
    uint32_t window_count;    /* bricks in its list (read back when it closed) */
    uint32_t slice_start[FUSION_MAX_SLICES + 1]; /* slice k's first list place (read back with the count) */
    uint32_t window_slices_done;
    bool window_pending;
    /* The window fusion_flush started holds every frame of the sequence (a
     * sequence shorter than a window, on a map not loaded): its confidence
     * threshold is half its frames' weight (integrate.c,
     * window_conf_weight). */
    bool window_whole;
    uint32_t n_windows_done;  /* windows whose last slice has been recorded */
    uint32_t fails_seen;      /* pool-full drops already reported */
    bool has_incoming;        /* the incoming slot holds a frame's depth (fusion_upload_frame) */
    uint32_t incoming_index;  /* its bf_frame index, for messages */
    bool fuse_pending;        /* fusion_cmd_fuse recorded, fusion_finish_frame not yet run */
    bool pending_closes;      /* that frame closes a window: its count comes back in readback */
    uint32_t n_loaded;        /* bricks loaded from a host copy (fusion_load) */
    /* Since the last reset only fusion_load has written the map: its bricks
     * fill slots [0, n_loaded) and its nodes [0, use.nodes), so that is all
     * fusion_clear has to clear. Frames, eviction and insertion end it. */
    bool only_loaded;
    fusion_pool_use use;      /* as of the last finished frame or streaming move */

    double ms_upload, ms_alloc, ms_subcache, ms_window, ms_colour;
    uint32_t colour_first, colour_count; /* the slice the frame's colour pass owes (fusion_cmd_fuse) */
};

/* map.c: a full host copy of the map's index structures (fusion_check;
 * the tests' host inserter edits it and uploads it back). Must not be
 * taken while GPU work is pending. */
typedef struct fusion_host_map {
    uint32_t *hash, *nodes, *info, *counters, *free_stack;
} fusion_host_map;
bf_status fusion__host_map_load(fusion_map *map, fusion_host_map *h);
void fusion__host_map_free(fusion_host_map *h);
/* map.c: n_entries free hash entries (no root, no next) into words. */
void fusion__hash_empty(uint32_t *words, uint32_t n_entries);
/* map.c: fills every buffer with the empty map's state; is_fresh: the
 * buffers are new (fusion_create), so zeroed memory needs no zero fill. */
bf_status fusion__reset(fusion_map *map, bool is_fresh);
/* load.c: inserts a brick into the host copy h as the allocation kernel
 * would (its chunk and nodes created as needed) and says its slot; a brick
 * already there keeps its slot. BF_POOL_FULL when a pool ran out. */
bf_status fusion__host_insert(const fusion_map *map, fusion_host_map *h, const int32_t key[3], uint32_t level,
                              const uint32_t cell[3], uint32_t *slot);
/* load.c: a new chunk's hash entry and root node in h. */
bf_status fusion__host_insert_chunk(const fusion_map *map, fusion_host_map *h, const int32_t key[3], uint32_t *entry);
/* load.c: uploads the host copy's index structures (hash, nodes, brick
 * records, counters, free stack). */
bf_status fusion__host_map_store(fusion_map *map, const fusion_host_map *h);
/* map.c: a binding set named name with bufs[i], whole, at binding i. */
bf_status fusion__bindings_create(fusion_map *map, const char *name, gpu_buffer *const *bufs, uint32_t n,
                                  gpu_bindings **out);
/* map.c: host ring slot of sequence frame index i. */
static inline uint32_t fusion__ring_slot(const fusion_map *map, uint32_t i) { return i % map->ring_slots; }

/* fusion.c: the window-gathering pipeline. */
bf_status fusion__schedule_create(fusion_map *map);
void fusion__schedule_destroy(fusion_map *map);
/* Confident voxels of one brick with a confident 6-neighbour of the other
 * sign inside the brick (a lower bound of the surface voxels). */
uint32_t fusion__brick_surface_voxels(const uint32_t sign[16], const uint32_t conf[16]);

/* alloc.c */
bf_status fusion__alloc_create(fusion_map *map);
void fusion__alloc_destroy(fusion_map *map);
/* Records the allocation passes for the frame in ring slot `slot`. */
void fusion__cmd_alloc(fusion_map *map, uint32_t slot, uint32_t frame_index);

/* integrate.c */
bf_status fusion__integrate_create(fusion_map *map);
void fusion__integrate_destroy(fusion_map *map);
/* Records the integration of entries [first, first + max_count) of list
 * (clamped to the list's count on the GPU) against the frames with sequence
 * indices [frame_first, frame_first + n_frames) still in the ring. With
 * set_confidence false only the sign of non-confident voxels is written
 * (the sub-cache's quick pass); with true the window rule applies. */
void fusion__cmd_integrate(fusion_map *map, gpu_bindings *b, uint32_t first, uint32_t max_count,
                           uint32_t frame_first, uint32_t n_frames, bool set_confidence);

/* evict.c: the colours of in's bricks (in->rgb565) into the slots fusion_load
 * gave them (slots[i] for brick i), blocks off the colour free stack. */
bf_status fusion__colour_load(fusion_map *map, const hostmap *in, const uint32_t *slots);
/* colour.c: the colour pass (shaders/fusion_colour.comp). */
bf_status fusion__colour_create(fusion_map *map);
void fusion__colour_destroy(fusion_map *map);
/* Records the colour pass over entries [first, first + max_count) of the
 * window list, reading up to cfg.colour_frames frames of the window. */
void fusion__cmd_colour(fusion_map *map, uint32_t first, uint32_t max_count);
/* Records the trim of the bricks in the trim list (gathered before, in the
 * same submission): their colour off the voxels past cfg.colour_reach. */
void fusion__cmd_colour_trim(fusion_map *map);
/* The frames a window's colour pass reads: n frames from first, stride
 * apart (n 0: none), for the window [window_first, window_end) of a map
 * whose windows are `window` frames long. */
typedef struct fusion__colour_plan {
    uint32_t first, n, stride;
} fusion__colour_plan;
fusion__colour_plan fusion__colour_frames(uint32_t window, uint32_t colour_frames, uint32_t window_first,
                                          uint32_t window_end);
/* Converts an RGB8 image to RGB565 pairs (words of 2 pixels, low first). */
void fusion__rgb_to_565(const uint8_t *rgb, uint64_t n_pixels, uint32_t *words);

/* Host side of the colour layout (shaders/fusion.glsl.h, "colour"): a host
 * copy of the colour units [0, n), downloaded as chains reach further
 * (units are handed out low first) and edited in place; upload [0, n). */
typedef struct fusion__colour_host {
    uint32_t *units; /* n units of FUSION_COLOUR_UNIT_WORDS */
    uint32_t n;
} fusion__colour_host;

void fusion__colour_host_free(fusion__colour_host *h);
/* A brick's colours (masks[BRICK_WORDS], head) expanded to out[512], voxel x + 8y + 64z. */
bf_status fusion__colour_expand(fusion_map *m, fusion__colour_host *h, const uint32_t *masks, uint32_t head,
                                uint16_t *out);
/* Gives a brick colours c[512] (0: none) where it has none, growing its
 * chain off the free stack (cfree, *top); when the stack runs dry the brick
 * keeps what it had and *fail counts it. */
bf_status fusion__colour_fill(fusion_map *m, fusion__colour_host *h, uint32_t *masks, uint32_t *head,
                              const uint16_t *c, uint32_t *cfree, uint32_t *top, uint32_t *fail);
/* Pushes a brick's units on the free stack and clears its masks and head. */
bf_status fusion__colour_release(fusion_map *m, fusion__colour_host *h, uint32_t *masks, uint32_t *head,
                                 uint32_t *cfree, uint32_t *top);

/* ------------------------------------------------------------ integration
 * (integrate.c; the rule is in shaders/fusion.glsl.h and
 * docs/fusion_integrate.md; the CPU oracle is tests/fusion/integrate_ref.c.) */

/* The push constants fusion__cmd_integrate records for a pass (the
 * oracle takes the same block). */
/* Workgroups per row of an indirect grid: fusion_config.max_groups_x. */
uint32_t fusion__max_groups_x(const fusion_map *map);
fusion_integrate_push fusion__integrate_params(const fusion_map *map, uint32_t first, uint32_t max_count,
                                               uint32_t frame_first, uint32_t n_frames, bool set_confidence);

#endif
