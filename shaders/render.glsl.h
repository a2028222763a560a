/* The ray-caster's parameters and pure helpers, as C and GLSL both see them
 * (render/render.h, shaders/render_raycast.comp, shaders/render_shade.comp;
 * DESIGN.md section 5). The map layout it reads is shaders/fusion.glsl.h.
 *
 * Rays live in the map frame (relative to the map origin, in float): the
 * host turns the double T_wc into T_mc = (R, t) with t = T_wc.t - origin_w
 * computed in double, so a map 10 km from the world origin ray-casts exactly
 * as one at the origin (DESIGN.md section 10). The ray of pixel (u, v) is
 * o + s dir with o = t and dir = R ((u - cx)/fx, (v - cy)/fy, 1): dir has
 * camera z 1, so the ray parameter s is the camera depth of the point, and
 * near/far are depths along the optical axis, as render_options says.
 */
#ifndef BF_RENDER_GLSL_H
#define BF_RENDER_GLSL_H

#include "bf_common.glsl.h"
#include "fusion.glsl.h"

/* Workgroup of both passes: 8x8 pixels, so the 8 lanes of a lavapipe
 * subgroup are 8 neighbouring pixels of one row (coherent rays). */
#define RENDER_LOCAL_X 8u
#define RENDER_LOCAL_Y 8u

/* render_push.flags */
#define RENDER_FLAG_CONFIDENT_ONLY 1u /* non-confident voxels are unknown */
#define RENDER_FLAG_REFINE 2u         /* hit between the two voxel centres */
#define RENDER_FLAG_START 4u          /* rays start at the start image's depth minus a margin */
#define RENDER_FLAG_COLOUR 8u         /* look up the map's colour at the hit (RENDER_RC_CMASK .. _CHEAD) */
#define RENDER_FLAG_NO_GRAZE 16u      /* with REFINE: a hit whose refined field stays in front is passed by */

/* Octree cells are addressed by integer coordinates on the finest grid
 * (2^FUSION_MAX_LEVEL = 256 cells per chunk edge); a cell at level L is
 * q >> (8 - L). */
#define RENDER_GRID_BITS 8u
#define RENDER_GRID 256u

/* Entries of the octree walk's short stack (Laine & Karras 2010 keep a
 * full stack; a short one with a restart from the root on underflow is
 * what DESIGN.md section 5 and Reichl 2016 use). 4: the walk keeps it
 * in uvec4s (shaders/render_walk.glsl.h). */
#define RENDER_STACK 4u

/* Bound on the cells a ray may visit: a guard against a corrupt map, far
 * above what a 6 m ray through a room visits (a few hundred). */
#define RENDER_MAX_CELLS 4096u
/* The particle pass walks in bounded dispatches (render/particles.c):
 * lavapipe ends every loop of a shader once its loops together ran 65,535
 * iterations for one call (8 lanes; gallivm's LP_MAX_TGSI_LOOP_ITERATIONS),
 * and a particle search runs loops within loops. Each dispatch walks at
 * most a number of coarse bricks of a ray (render_particles_push.limits)
 * and searches until its count of loop iterations passes a budget of at
 * most RENDER_PARTICLES_WORK_BUDGET (a cell's search is a few hundred),
 * then pauses the ray (a hit of level RENDER_PARTICLES_PAUSED at the depth
 * to resume from); the next dispatch resumes it. A ray walks at most
 * RENDER_PARTICLES_MAX_CELLS coarse bricks in all (docs/particles.md). */
#define RENDER_PARTICLES_LOOP_BUDGET 40000u
#define RENDER_PARTICLES_WORK_BUDGET 30000u
#define RENDER_PARTICLES_PAUSED 0xfffffffeu
#define RENDER_PARTICLES_MAX_CELLS 1024u
#define RENDER_PARTICLES_LIMIT_CELL_BITS 12u
#define RENDER_PARTICLES_COARSE_LEVELS 3u
#define RENDER_PARTICLES_MAX_CELLS 1024u
#define RENDER_PARTICLES_LIMIT_CELL_BITS 12u

/* Sub-voxel refinement of a tracking hit (render_raycast.comp's
 * subvoxel_depth, tests/render/raycast_ref.c in double): Newton steps on the
 * smoothed sign field along the ray, each step at most
 * RENDER_SUBVOXEL_MAX_STEP voxels along the ray, the result at most
 * RENDER_SUBVOXEL_MAX_MOVE steps from the midpoint start (render.md: two
 * steps within a voxel left a noisy map's bias, 4 within 3 remove it). */
#define RENDER_SUBVOXEL_ITERS 4u
/* RENDER_FLAG_NO_GRAZE: a hit is passed by when the smoothed sign field at
 * its refined depth is still above this (in [-1, 1]; 0 on the surface): the
 * ray crossed a corner of a behind voxel without reaching the surface the
 * voxels sample. At most RENDER_GRAZE_MAX such hits a ray. */
#define RENDER_GRAZE_F 0.25f
#define RENDER_GRAZE_MAX 4u
#define RENDER_SUBVOXEL_MAX_STEP 1.0f
#define RENDER_SUBVOXEL_MAX_MOVE 3.0f

/* The camera and the map's hash as a ray-casting pass sees them: the first
 * words of render_push and render_particles_push, filled once for both
 * (render/render_int.h). */
struct render_view_push {
    bf_f32 R[9];             /* camera to map rotation, row-major */
    bf_f32 t[3];             /* camera centre in the map frame [m] */
    bf_f32 fx, fy, cx, cy;   /* pixels */
    bf_u32 width, height;
    bf_f32 near_m, far_m;    /* camera depth range of the ray */
    bf_f32 chunk_m;
    bf_u32 n_buckets;        /* fusion_hash's modulus */
    bf_u32 n_overflow;       /* overflow entries after the buckets' slots */
    bf_u32 max_level;        /* the walk's deepest level */
};
#define RENDER_VIEW_PUSH_WORDS 24u
#ifndef BF_GLSL
typedef struct render_view_push render_view_push;
_Static_assert(sizeof(render_view_push) == RENDER_VIEW_PUSH_WORDS * 4, "render_view_push must match std430");
#endif

/* Bindings of render_raycast.comp. The map's hash, nodes, sign and conf
 * are read through their device addresses (the map's address table,
 * FUSION_ADDR_*; docs/gpu.md, lavapipe notes). */
#define RENDER_RC_ADDR 0u  /* the map's address table */
#define RENDER_RC_DEPTH 1u /* depth written (float), from pixel depth_off */
#define RENDER_RC_LEVEL 2u /* level of the hit (uint) */
#define RENDER_RC_START 3u /* the start image (float, RENDER_FLAG_START) */
#define RENDER_RC_CMASK 4u /* the map's colour masks, units and heads (RENDER_FLAG_COLOUR) */
#define RENDER_RC_CPOOL 5u
#define RENDER_RC_RGB 6u   /* the hit's colour written (RGB565) */
#define RENDER_RC_CHEAD 7u
#define RENDER_RC_BUFFERS 8u

/* Push constants of render_raycast.comp and render_shade.comp. */
struct render_push {
    render_view_push view;
    bf_u32 flags;            /* RENDER_FLAG_* */
    /* RENDER_FLAG_START: a ray whose pixel has depth z > 0 in the start
     * image (RENDER_RC_START, floats from start_off) begins at max(near_m, z -
     * start_margin_m - start_margin_z2 z^2). */
    bf_f32 start_margin_m, start_margin_z2;
    bf_u32 start_off;
    /* The depth image (RENDER_RC_DEPTH) starts at pixel depth_off: 0 for the
     * caster's own, another buffer's level (the tracking reference) else. */
    bf_u32 depth_off;
};
#define RENDER_PUSH_WORDS 29u
#ifndef BF_GLSL
typedef struct render_push render_push;
_Static_assert(sizeof(render_push) == RENDER_PUSH_WORDS * 4, "render_push must match std430");
_Static_assert(__builtin_offsetof(render_push, view.fx) == 48, "render_push.view.fx");
_Static_assert(__builtin_offsetof(render_push, view.width) == 64, "render_push.view.width");
_Static_assert(__builtin_offsetof(render_push, view.chunk_m) == 80, "render_push.view.chunk_m");
_Static_assert(__builtin_offsetof(render_push, flags) == 96, "render_push.flags");
#endif

/* The start of the sub-voxel refinement: halfway, in camera depth, between
 * the centre of the last front voxel and that of the first voxel behind
 * (render.md says why camera depth rather than the projection onto the
 * ray). */
BF_FN bf_f32 render_refine_depth(bf_f32 front_depth, bf_f32 behind_depth)
{
    BF_PRECISE bf_f32 d = 0.5f * (front_depth + behind_depth);
    return d;
}

/* Shaded colour of a hit: Lambert with a headlight (the light sits at the
 * camera, so the cosine is that of the normal with the reversed ray), a
 * little ambient, tinted by the octree level so the level rule shows.
 * cos_theta in [0, 1]. RGBA8, R in the low byte, alpha 255. */
/* The map's colour (RGB565) of a hit, lit the same way but half as
 * strongly: the colour carries the scene, the light only the shape. */
BF_FN bf_u32 render_shade_colour(bf_f32 cos_theta, bf_u32 rgb565)
{
    bf_f32 c = cos_theta < 0.0f ? 0.0f : (cos_theta > 1.0f ? 1.0f : cos_theta);
    bf_f32 i = 0.55f + 0.45f * c;
    bf_u32 r = BF_TRUNC_U32(BF_F32(bf_565_r(rgb565)) * i + 0.5f);
    bf_u32 g = BF_TRUNC_U32(BF_F32(bf_565_g(rgb565)) * i + 0.5f);
    bf_u32 b = BF_TRUNC_U32(BF_F32(bf_565_b(rgb565)) * i + 0.5f);
    return r | (g << 8) | (b << 16) | (255u << 24);
}

BF_FN bf_u32 render_shade(bf_f32 cos_theta, bf_u32 level)
{
    /* One tint per level, cycling every 4: warm for coarse, cool for fine. */
    bf_f32 tr = 1.0f, tg = 1.0f, tb = 1.0f;
    bf_u32 k = level % 4u;
    if (k == 0u) { tr = 1.0f; tg = 0.80f; tb = 0.70f; }
    if (k == 1u) { tr = 0.85f; tg = 1.0f; tb = 0.75f; }
    if (k == 2u) { tr = 0.75f; tg = 0.90f; tb = 1.0f; }
    if (k == 3u) { tr = 1.0f; tg = 0.85f; tb = 1.0f; }
    bf_f32 c = cos_theta < 0.0f ? 0.0f : (cos_theta > 1.0f ? 1.0f : cos_theta);
    bf_f32 i = 0.12f + 0.88f * c;
    bf_u32 r = BF_TRUNC_U32(255.0f * i * tr + 0.5f);
    bf_u32 g = BF_TRUNC_U32(255.0f * i * tg + 0.5f);
    bf_u32 b = BF_TRUNC_U32(255.0f * i * tb + 0.5f);
    return r | (g << 8) | (b << 16) | (255u << 24);
}

/* ------------------------------------------------------------ mesh voxelisation
 * render_voxelise.comp: a closed triangle mesh into inside/outside bits of
 * the map's bricks (the mesh renderer, issue 14), by the parity of the
 * surface crossings along +z columns through voxel centres, as Schwarz and
 * Seidel's solid voxelisation (2010) flips every voxel above a crossing.
 * Per brick of the list one invocation: the brick's triangles (CSR list;
 * the host lists only those whose xy box holds a column centre of the
 * brick) are tested against the column centres their boxes hold;
 * a crossing inside the brick's z range flips the column's voxels above it
 * and toggles the column's parity. The host adds the parity entering each
 * brick from below (the XOR of the parities of the bricks beneath it). */
#define RENDER_VOX_BRICK_WORDS 6u  /* per brick: ix, iy, iz (brick coordinates on its level's grid), tri_begin, tri_end, level */
#define RENDER_VOX_OUT_WORDS 18u   /* per brick: 16 flip words (brick bit layout), 2 column parity words (bit x + 8y) */
struct render_vox_push {
    bf_u32 n_bricks;
    bf_f32 chunk_m;      /* chunk edge: a brick's voxel is chunk_m / (8 * 2^level) */
    bf_u32 pad[2];
};
#ifndef BF_GLSL
typedef struct render_vox_push render_vox_push;
_Static_assert(sizeof(render_vox_push) == 16, "render_vox_push must match std430");
#endif

/* Edge function of 2D point (px, py) against edge a -> b, computed the same
 * way whichever way the edge is walked (the lexicographically smaller end
 * first, the sign flipped back), so two triangles sharing an edge see the
 * exact negatives of each other at a column on it. */
BF_FN bf_f32 render_edge(bf_f32 ax, bf_f32 ay, bf_f32 bx, bf_f32 by, bf_f32 px, bf_f32 py)
{
    bool swap = ax > bx || (ax == bx && ay > by);
    bf_f32 ux = swap ? bx : ax, uy = swap ? by : ay, vx = swap ? ax : bx, vy = swap ? ay : by;
    BF_PRECISE bf_f32 e = (vx - ux) * (py - uy) - (vy - uy) * (px - ux);
    return swap ? -e : e;
}
/* Whether a point exactly on edge a -> b of a counter-clockwise triangle
 * counts (top-left rule): a left edge (going down) or a top edge
 * (horizontal, going left). One of two triangles sharing it counts it. */
BF_FN bool render_edge_owns(bf_f32 ax, bf_f32 ay, bf_f32 bx, bf_f32 by)
{
    return by < ay || (by == ay && bx < ax);
}

/* Push constants of render_particles.comp (the particle pass, render/particles.c). */
#define RENDER_PARTICLES_FLAG_KEEP_NEARER 1u /* a pixel's existing hit (the map's) stays where it is nearer */
#define RENDER_PARTICLES_FLAG_FIRST 2u       /* the first dispatch: rays start at near_m */
#define RENDER_PARTICLES_FLAG_LAST 4u        /* the last dispatch: rays not done are misses */
#define RENDER_PARTICLES_FLAG_LIST 8u        /* a later dispatch: the rays of the last one's list, not the image */
#define RENDER_PARTICLES_FLAG_LOD 16u        /* level of detail: far coarse cells drawn as one sphere each */
/* The dispatch's index in flags' high bits: the list and arguments it
 * appends its unfinished rays to (render/particles.c). */
#define RENDER_PARTICLES_PASS_SHIFT 8u
/* Per dispatch in the arguments buffer: the indirect group counts (x, y, z)
 * of the next dispatch and the count of rays appended. */
#define RENDER_PARTICLES_ARGS_WORDS 4u
/* The centres' index (binding 11, render/particles_bin.h): two header words,
 * then per coarse brick and sign word the entry of its first brick of
 * centres, then the bricks' slots. */
#define RENDER_PARTICLES_INDEX_HEADER 2u
/* An entry with this bit is a brick of one centre: its cell in the low 9
 * bits (sign word << 5 | bit), the brick itself not read. */
#define RENDER_PARTICLES_INDEX_ONE 0x80000000u
struct render_particles_push {
    render_view_push view;   /* the particle map's; max_level the walk's (the coarse level) */
    bf_f32 radius_m;         /* every particle's sphere */
    bf_u32 flags;            /* RENDER_PARTICLES_FLAG_*, the dispatch's index << RENDER_PARTICLES_PASS_SHIFT */
    bf_u32 rgb;              /* the particles' colour, R in the low byte */
    bf_u32 limits;           /* per ray and dispatch: coarse bricks walked (bits 0-11) and the searches'
                                work budget (bits 12-31; RENDER_PARTICLES_WORK_BUDGET or less) */
    bf_f32 box_lo;           /* the set's box grown by the radius, map frame: [box_lo, box_hi] on every axis */
    bf_f32 box_hi[3];
};
#define RENDER_PARTICLES_PUSH_WORDS 32u
#ifndef BF_GLSL
typedef struct render_particles_push render_particles_push;
_Static_assert(sizeof(render_particles_push) == RENDER_PARTICLES_PUSH_WORDS * 4, "render_particles_push must match std430");
_Static_assert(__builtin_offsetof(render_particles_push, view.chunk_m) == 80, "render_particles_push.view.chunk_m");
_Static_assert(__builtin_offsetof(render_particles_push, radius_m) == 96, "render_particles_push.radius_m");
_Static_assert(__builtin_offsetof(render_particles_push, rgb) == 104, "render_particles_push.rgb");
#endif

/* Shaded colour of a particle hit: the particles' RGB (R in the low byte)
 * lit by the headlight (cos_theta in [0, 1]) over a little ambient. RGBA8. */
BF_FN bf_u32 render_shade_particle(bf_f32 cos_theta, bf_u32 rgb)
{
    bf_f32 c = cos_theta < 0.0f ? 0.0f : (cos_theta > 1.0f ? 1.0f : cos_theta);
    bf_f32 i = 0.2f + 0.8f * c;
    bf_u32 r = BF_TRUNC_U32(BF_F32(rgb & 255u) * i + 0.5f);
    bf_u32 g = BF_TRUNC_U32(BF_F32((rgb >> 8) & 255u) * i + 0.5f);
    bf_u32 b = BF_TRUNC_U32(BF_F32((rgb >> 16) & 255u) * i + 0.5f);
    return r | (g << 8) | (b << 16) | (255u << 24);
}

#endif
