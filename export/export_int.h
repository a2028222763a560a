/* Declarations shared by export/'s files: an index of a snapshot's
 * bricks by (level, global brick coordinates), the "finest confident voxel
 * containing a point" lookup and the smoothed sign field. Not public. */
#ifndef BF_EXPORT_INT_H
#define BF_EXPORT_INT_H

#include "export.h"
#include "shaders/bf_common.glsl.h"

#define EXPORT__MAX_LEVEL 20u
#define EXPORT__NONE UINT32_MAX
/* sfield value of a voxel without a field (not confident). */
#define EXPORT__NO_FIELD INT8_MIN

typedef struct export__slot {
    int64_t b[3];     /* global brick coordinates at the level: key * 2^level + cell */
    uint32_t level;
    uint32_t idx;     /* brick index in the snapshot, EXPORT__NONE = empty slot */
} export__slot;

/* Points are integer "half units" of the finest level M present:
 * q = (p_w - origin_w) / (v(M) / 2), so the centre of voxel g at level L is
 * g * 2^(M-L+1) + 2^(M-L), an integer. */
typedef struct export__grid {
    const hostmap *s;
    uint32_t n;              /* bricks kept (duplicates dropped) */
    uint32_t *order;         /* kept brick indices, sorted by (level, z, y, x) */
    int64_t (*bc)[3];        /* per snapshot brick: global brick coordinates */
    export__slot *slots;
    uint64_t mask;           /* slot count - 1 */
    uint32_t level_max;      /* M */
    uint32_t n_levels;
    uint32_t levels_desc[EXPORT__MAX_LEVEL + 1]; /* present levels, finest first */
    uint8_t *has_finer;      /* per snapshot brick: a brick of a finer level overlaps it */
    int8_t *sfield;          /* per snapshot brick, 512 voxels: round(127 * s), see below */
    uint32_t n_duplicates;
    double half_m;           /* v(M) / 2 */
} export__grid;

/* A voxel found by a lookup. */
typedef struct export__voxel {
    uint32_t brick;          /* snapshot index */
    uint32_t level;
    uint32_t x, y, z;        /* inside the brick */
    int64_t g[3];            /* global voxel coordinates at the level */
    bool is_free;            /* sign bit: in front of the surface */
} export__voxel;

/* Indexes s: validates it, drops duplicates (same level and place: the
 * lower error wins, then the lower index), finds overlaps and, when
 * with_field, computes the smoothed sign field of every confident voxel:
 * s = mean of +1 (free) / -1 (inside) over the confident voxels of the same
 * level in its 3x3x3 neighbourhood (across bricks). Statuses as the public
 * functions; on failure *g holds nothing. */
bf_status export__grid_build(const hostmap *s, bool with_field, export__grid *g);
void export__grid_free(export__grid *g);

/* Snapshot index of the brick at (level, global brick coordinates) or EXPORT__NONE. */
uint32_t export__grid_find(const export__grid *g, uint32_t level, const int64_t b[3]);

/* The finest confident voxel whose cube contains the half-unit point q
 * (cubes are half-open, [lo, hi)). False when no confident voxel does. */
bool export__grid_sample(const export__grid *g, const int64_t q[3], export__voxel *out);

/* The smoothed sign field of level `level` at half-unit point q, trilinear
 * between the 8 surrounding voxel centres of that level that have a field
 * (weights renormalised). NAN when none has. */
double export__grid_field(const export__grid *g, uint32_t level, const int64_t q[3]);

/* The 27 bricks of one level around brick b (index k = (dx+1) + 3 (dy+1)
 * + 9 (dz+1)), to read fields without the hash. */
typedef struct export__nbhood {
    int64_t b[3];
    uint32_t idx[27]; /* snapshot index or EXPORT__NONE */
} export__nbhood;
void export__grid_nbhood(const export__grid *g, uint32_t level, const int64_t b[3], export__nbhood *out);
/* export__grid_field reading voxels in nbh's bricks through nbh: the same
 * arithmetic on the same bytes, so bit-equal to export__grid_field (corner
 * classes decided from it must agree between the cells sharing a corner). */
double export__grid_field_nb(const export__grid *g, uint32_t level, const int64_t q[3], const export__nbhood *nbh);

/* Field of one voxel (level-L global coordinates), NAN when it has none. */
double export__grid_voxel_field(const export__grid *g, uint32_t level, const int64_t v[3]);

static inline bool export__bit(const uint32_t *words, uint32_t x, uint32_t y, uint32_t z)
{
    return (words[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1u;
}

/* Arithmetic shift (floor division by 2^k) for negative coordinates too. */
static inline int64_t export__shr(int64_t v, uint32_t k) { return v >> k; }

/* Half-unit coordinate of the centre of level-L voxel g. */
static inline int64_t export__centre_q(const export__grid *g, uint32_t level, int64_t v)
{
    uint32_t d = g->level_max - level;
    return v * ((int64_t)2 << d) + ((int64_t)1 << d);
}

/* colour.c: per-vertex colour (m->rgb) of the points or mesh m, from the
 * snapshot's colour; nothing when the snapshot has none. */
bf_status export__colourise(const export__grid *g, mesh_data *m);

static inline uint32_t export__level_slot(uint32_t level) { return level < 16 ? level : 15; }

#endif
