/* render: the shared ray-casting backend (DESIGN.md section 5; Reichl,
 * Weiss, Westermann 2016, section 5).
 *
 * One ray per pixel: a DDA over the world chunks the ray crosses, in each
 * chunk that exists an octree DDA with a short stack (restart from the root
 * on underflow) down to the finest existing brick, and in the brick a
 * brick traverser. The `surface` traverser steps voxel by voxel until the
 * sign bit changes from front (1) to behind (0); the hit is refined to the
 * zero of a smoothed sign field on the ray (sub-voxel: ICP needs it), for
 * display only confident voxels count. The walk is one GLSL function
 * (shaders/render_walk.glsl.h) and the traverser one function behind one
 * seam (shaders/render_traverse.glsl.h): the particle renderer (below)
 * walks with its `particles` traverser, the mesh renderer will walk with
 * its own.
 *
 * Images stay on the GPU (tracking reads them there); render_download
 * copies them to the host for PNGs and tests.
 */
#ifndef BF_RENDER_H
#define BF_RENDER_H

#include "core/core.h"
#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "hostmap/hostmap.h"
#include "mesh/mesh.h"

typedef struct render_caster render_caster; /* opaque */

/* How a caster is built. */
typedef struct render_config {
    /* Workgroup shape of both passes, default 8 x 8 (RENDER_LOCAL_X/Y); x * y a multiple of 8, at
       most 256. lavapipe puts 8 consecutive invocations in one SIMD vector, so the shape decides
       which rays run in lockstep (bench/bench_render compares shapes, docs/render.md). */
    uint32_t local_x, local_y;
} render_config;

render_config render_config_default(void);

typedef struct render_options {
    bool confident_only; /* only confident voxels are surface (display; recon/'s tracking reference once a
                            window has closed, recon_config.reference_confident); false: every sign bit */
    bool refine;         /* sub-voxel hit: zero of the smoothed sign field on the ray (docs/render.md) */
    float near_m, far_m; /* ray range along the optical axis, default 0.2 / 6 */
    /* Optional start depths (NULL: none): float camera depth per pixel of
     * the caster's size at pixel offset start_offset in start_depth (0 =
     * none), e.g. the frame just fused at this pose. A ray with a start
     * depth z begins at z - (start_margin_m + start_margin_z2 z^2) instead
     * of near_m, skipping the free space in front of the surface the frame
     * saw (docs/render.md). A surface of the map closer than that is not
     * seen on that pixel. */
    gpu_buffer *start_depth;
    uint64_t start_offset;
    float start_margin_m, start_margin_z2;
    bool no_shade;       /* depth and level only: normals and colour are not computed */
    /* With refine: pass by a hit whose refined depth leaves the ray still in front of the
       smoothed surface (a behind voxel's corner grazed at an outline) and go on behind it. The
       mesh renderer's outlines (docs/render.md); default false. */
    bool no_graze;
    /* Optional depth destination (NULL: the caster's depth image): the depth is written as
     * width x height floats from pixel depth_offset of depth_out instead, e.g. straight into the
     * tracking reference (track_reference_target), so nothing is copied. Needs no_shade (the
     * shading pass reads the caster's image); targets.depth then keeps its old content. */
    gpu_buffer *depth_out;
    uint64_t depth_offset;
} render_options;

render_options render_options_tracking(void); /* every sign bit, refined */
render_options render_options_display(void);  /* confident voxels only, refined */

/* The images of the last ray-cast, row-major width x height, on the GPU. */
typedef struct render_targets {
    uint32_t width, height;
    gpu_buffer *depth;  /* float per pixel: camera z of the hit [m]; 0 = no hit */
    gpu_buffer *normal; /* 4 floats per pixel: unit normal in camera coordinates, w = 0; all 0 = no hit */
    gpu_buffer *level;  /* uint per pixel: octree level of the brick hit; FUSION_NONE = no hit */
    gpu_buffer *colour; /* uint per pixel: shaded RGBA8 (R in the low byte); 0 = no hit */
    gpu_buffer *surface_rgb; /* uint per pixel: the map's RGB565 at the hit (shaded casts of a map with colour), 0 = none */
} render_targets;

/* Creates a caster for images of width x height. cfg NULL: the defaults.
 * ctx is borrowed. BF_INVALID_ARG for a bad size or workgroup shape. */
bf_status render_create(gpu_context *ctx, const render_config *cfg, uint32_t width, uint32_t height,
                        render_caster **out);
/* NULL is a no-op. */
void render_destroy(render_caster *rc);

/* Ray-casts map from camera pose T_wc (camera to world, double; the caster
 * hands the GPU the map-relative pose, fusion_camera_to_map) with
 * intrinsics K (K's size must be the caster's), in a submission of its own
 * that it waits for: render_cmd_raycast, submit, render_finish_raycast. */
bf_status render_raycast(render_caster *rc, fusion_map *map, const bf_intrinsics *K, const bf_se3 *T_wc,
                         const render_options *opt);
/* Records the same ray-cast into the context's open command buffer
 * (gpu_begin), after a barrier on what was recorded before it (fusion's
 * writes to the map); commands recorded after it see its images (it ends
 * with a barrier). The caller submits, then calls render_finish_raycast. The
 * same arguments and refusals as render_raycast. */
bf_status render_cmd_raycast(render_caster *rc, fusion_map *map, const bf_intrinsics *K, const bf_se3 *T_wc,
                             const render_options *opt);
/* After the submission holding render_cmd_raycast finished: reads its GPU
 * time (render_last_ms). */
void render_finish_raycast(render_caster *rc);
const render_targets *render_get_targets(const render_caster *rc);
/* GPU time of the last ray-cast [ms] (Vulkan timestamps). */
double render_last_ms(const render_caster *rc);

/* Host copies of the images (malloc'd arrays, freed by render_images_free). */
typedef struct render_images {
    uint32_t width, height;
    float *depth;   /* width * height */
    float *normal;  /* 4 * width * height */
    uint32_t *level;
    uint8_t *rgb;   /* 3 * width * height, the shaded view (no hit: black) */
} render_images;

bf_status render_download(render_caster *rc, render_images *out);
void render_images_free(render_images *im);

/* ------------------------------------------------------------ mesh renderer: voxelisation (voxelise.c)
 * A closed triangle mesh becomes inside/outside sign bits of the map's own
 * bricks at one level (DESIGN.md section 5: the mesh renderer shares the
 * ray-casting backend): load the result into a fusion map (fusion_load) and
 * ray-cast it with the `surface` traverser. Only the bricks the surface
 * passes through are made; every voxel of them is confident. Inside is
 * decided by the parity of the surface crossings below a voxel along +z
 * (Schwarz and Seidel 2010), on the GPU; a mesh with holes leaks along the
 * columns through them. */
typedef struct render_voxelise_config {
    float chunk_m;      /* chunk edge of the map it goes into, default 2 m */
    uint32_t level;     /* octree level: voxel edge chunk_m / (8 * 2^level), default 7 (1.95 mm); with lod the finest */
    /* Level of detail by pixel footprint, seen from one camera (default off: every brick at `level`). The
       mesh's box is cut into columns along z, each a brick of the level its farthest depth needs wide; each
       column is voxelised at the level whose voxel is at most a third of the smallest pixel footprint in it
       (render_level_for_footprint at its nearest depth, times the cosine of the image corner's ray), no finer
       than `level`. Columns keep one level from bottom to top, so the parity is exact in each. A column
       wholly behind the camera gets the coarsest level. Seen from elsewhere, the far parts stay coarse. */
    bool lod;
    bf_se3 lod_T_wc;     /* the camera (camera to world) */
    bf_intrinsics lod_K; /* its intrinsics: focal length and image size */
    float lod_near_m;    /* depths nearer than this count as this, 0 (default): 0.05 m */
    uint64_t max_pairs; /* refuse meshes needing more (brick, triangle) pairs, default 2^28 */
    uint32_t max_bricks; /* refuse meshes needing more bricks (the map they go into holds them; with another map
                            merged in, less its bricks), default UINT32_MAX - 1 */
    bool has_origin;    /* the bricks on the grid of a map with this origin (to merge them into it); default
                           false: the mesh's low corner less a brick */
    bf_vec3 origin_w;
} render_voxelise_config;

typedef struct render_voxelise_stats {
    uint32_t n_bricks;
    uint64_t n_pairs;          /* (brick, triangle) pairs of the bins: a triangle is in a brick's bin only where
                                  its xy box holds one of the brick's column centres */
    uint32_t n_gpu_bricks;     /* bricks with pairs, the GPU pass's (the others flip nothing) */
    double voxel_m;            /* at level_fine */
    uint32_t level_coarse, level_fine; /* the levels used (both `level` without lod; with it the columns' coarsest
                                          and finest) */
    uint32_t bricks_at_level[13];
    uint32_t n_columns;        /* level-of-detail columns (1 without lod) */
    uint32_t column_axis;      /* the map axis the columns and the crossing parity run along: 0 x, 1 y, 2 z
                                  (z without lod; with it the axis most across the view) */
    double seconds, seconds_bin, seconds_gpu; /* all; binning on the host; the GPU pass with its transfers */
} render_voxelise_stats;

render_voxelise_config render_voxelise_config_default(void);
/* Voxelises mesh (placed in the world by T_world_mesh, NULL: identity) into
 * out (its origin_w: cfg's, or the mesh's low corner less a brick). st may
 * be NULL.
 * BF_INVALID_ARG for a vertex that is not finite, an index out of range or a
 * level above 12; BF_POOL_FULL for a mesh that needs more than max_pairs
 * pairs or max_bricks bricks, or more pairs, bricks (72 bytes each, a map's
 * sign pool 64) or listed triangles than one binding of the device holds,
 * at these levels (a coarser level may fit); st's level_coarse and
 * level_fine then say which levels were tried. */
bf_status render_voxelise_mesh(gpu_context *ctx, const mesh_data *mesh, const bf_se3 *T_world_mesh,
                               const render_voxelise_config *cfg, hostmap *out, render_voxelise_stats *st);
/* The level whose voxel is at most a third of the pixel footprint at depth
 * z_m (focal length f_px): a voxel's cube then widens an outline by a sixth
 * of a pixel at most (docs/render.md), clamped to [0, max_level]. */
uint32_t render_level_for_footprint(float chunk_m, double z_m, double f_px, uint32_t max_level);
/* Merges b's bricks into a (same chunk edge and origin): a brick in both
 * becomes the union of the solids (behind where either is behind, confident
 * where either is). b is emptied. BF_INVALID_ARG for maps on other grids. */
bf_status render_hostmap_merge(hostmap *a, hostmap *b);
/* ------------------------------------------------------------ particles
 * The particle renderer (Reichl's dissertation, ch. 6; docs/particles.md):
 * particles binned on the host into the map's own structure (a hash of
 * chunks, octrees, 8x8x8 bricks), one bit per cell, in a fusion_map of
 * their own; the ray-cast walks it on the GPU with the `particles`
 * traverser, which takes each set bit for a sphere of the particle radius
 * at the cell's centre. Positions are quantised to the cell: at most half a
 * cell per axis. */

typedef struct render_particles render_particles; /* opaque: one binned set on the GPU */

typedef struct render_particles_config {
    float radius_m;  /* every particle's sphere, default 0.01 */
    float cell_m;    /* cell edge at the finest level, at most 2 radii; 0 (default): radius / 8 (depths within
                        2 mm of the exact spheres' on 95% of the pixels at a 1 cm radius, docs/particles.md), or
                        radius / 4 where the finer cells' bricks do not fit one binding (large sparse sets) */
    uint32_t rgb;    /* colour, R in the low byte; default a water blue */
    uint32_t work_budget; /* loop iterations a ray's searches take in one dispatch before the ray pauses for the
                             next (lavapipe ends a shader's loops past 65,535); 0 (default):
                             RENDER_PARTICLES_WORK_BUDGET, the most allowed; less only adds dispatches (tests) */
    /* Level of detail (default false: every sphere where its cell puts it): from the depth where a pixel's
       footprint is twice the coarse cell's half-diagonal on, each coarse cell holding centres (8 x 8 x 8 cells)
       is drawn as one sphere of the radius at its centre, its brick of centres unread: the spheres move by at
       most half a pixel there, and hits there report the coarse level (docs/particles.md). */
    bool lod;
} render_particles_config;

render_particles_config render_particles_config_default(void);

/* What binning did. */
typedef struct render_particles_stats {
    uint64_t n_particles;
    uint64_t n_cells;       /* set bits: particles sharing a cell count once */
    uint32_t n_bricks;      /* bricks of centres (holding set bits) */
    uint32_t n_coarse_bricks; /* bricks of the coarse level the ray walks (RENDER_PARTICLES_COARSE_LEVELS up: a
                                 cell per brick of centres, and the cells the spheres reach) */
    uint32_t level;         /* the centres' octree level */
    float chunk_m, cell_m;
    bf_vec3 origin_w;       /* the grid's corner: cell i spans origin_w + [i, i + 1) cell_m, its sphere at the middle */
    double bin_s;           /* host binning: cells, bricks, the host copy (wall clock) */
    double bin_cpu_s;       /* the same in CPU seconds of the process (both binning threads) */
    double load_s;          /* the host copy into the GPU pools (emptying them, fusion_load; not making a map) */
    double make_s;          /* making the map anew (its pools filled, its pipelines): 0 when it was reused */
    bool map_made;          /* the last binning made the map anew (the first, or a set grown past its pools) */
    /* GPU memory: the set's structure in use (both levels' bricks with their planes and records, the octree
       nodes, the hash entries and the centres' index; as fusion_stats.bytes_total counts a map), and what
       the set holds allocated (its map's pools, with room to spare for later steps, and the index). */
    uint64_t bytes_used, bytes_reserved;
} render_particles_stats;

/* Bins the n particles xyz (3 n floats, world coordinates [m]) and puts
 * them on the GPU. cfg NULL: the defaults. ctx is borrowed and must
 * outlive the set. BF_INVALID_ARG for a bad radius or cell (the message
 * says which), a position that is not finite (named by index) or a set
 * wider than 2^21 cells; BF_NO_MEMORY when it does not fit. n may be 0 (an
 * empty set: nothing is hit). */
bf_status render_particles_create(gpu_context *ctx, const render_particles_config *cfg, const float *xyz, uint64_t n,
                                  render_particles **out);
/* The radius and cell of cfg checked alone, as render_particles_create
 * checks them before it looks at the particles (BF_INVALID_ARG saying
 * which): a caller tells a bad option from a bad particle file. */
bf_status render_particles_check_config(const render_particles_config *cfg);
/* A moving set's next time step: the n particles xyz binned anew into the
 * same set (radius and cell kept), its GPU pools and pipeline reused, made
 * larger only when the set outgrows them (then with a quarter to spare).
 * The same refusals as render_particles_create; on failure the set holds
 * the last step or, where the failure came after emptying it, nothing (its
 * stats then count 0 particles). Not while a pass that reads the set is in
 * flight (render_scene waits for its own). */
bf_status render_particles_update(render_particles *ps, const float *xyz, uint64_t n);
/* NULL is a no-op. */
void render_particles_destroy(render_particles *ps);
const render_particles_stats *render_particles_get_stats(const render_particles *ps);
/* GPU time of the last particle pass [ms] (Vulkan timestamps). */
double render_particles_last_ms(const render_particles *ps);
/* Rays of the last particle pass continued by a later dispatch, each time
 * one was (a ray the walk's or the searches' budget paused; read back from
 * the GPU: after the pass was waited for, as render_scene does). */
bf_status render_particles_last_resumed(render_particles *ps, uint64_t *rays);

/* Records the particle pass into the context's open command buffer: it
 * writes the caster's depth, level, normal and colour images (no shading
 * pass needed). keep_nearer: a pixel's existing hit (a render_cmd_raycast
 * of a map recorded just before) bounds its ray and stays where nothing of
 * the set is nearer; else every pixel is written (0 / FUSION_NONE where
 * nothing is hit). opt gives near_m and far_m; depth_out must be NULL. */
bf_status render_cmd_particles(render_caster *rc, render_particles *ps, const bf_intrinsics *K, const bf_se3 *T_wc,
                               const render_options *opt, bool keep_nearer);
/* One scene in one image: the map (NULL: none; shaded as opt says) and
 * the particles (NULL: none) from camera T_wc, each pixel the nearest hit
 * of either, in one submission that it waits for. At least one of map and
 * ps. The caster's images then hold the scene (render_download). */
bf_status render_scene(render_caster *rc, fusion_map *map, render_particles *ps, const bf_intrinsics *K,
                       const bf_se3 *T_wc, const render_options *opt);

#endif
