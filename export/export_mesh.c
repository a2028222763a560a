/* Mesh export: marching cubes (Lorensen & Cline 1987) over one lattice of
 * voxel centres, with corners sampled from the finest confident data,
 * vertices at the zero crossing of the smoothed sign field, then Taubin
 * smoothing (Taubin 1995). docs/export.md explains the choices.
 *
 * Cells are owned by the brick whose voxel holds the cell's first corner
 * (lowest x, y, z), so every cell is visited once; bricks are visited in
 * parallel, each writing its own list of triangles as (lattice edge, t)
 * triples, and the lists are welded in brick order, which makes the result
 * independent of the thread count. */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "export_int.h"

/* ------------------------------------------------------------ case table */

/* Cube corner i has offset (i & 1, i >> 1 & 1, i >> 2 & 1). Edge id
 * a * 4 + bit_b + 2 * bit_c: axis a, and the bits of its lower corner on
 * the two other axes b = a + 1, c = a + 2 (mod 3). */
static uint8_t mc_n_tris[256];
static int8_t mc_tris[256][36];
static pthread_once_t mc_once = PTHREAD_ONCE_INIT;

static int edge_id(int p, int r)
{
    int ax = __builtin_ctz((unsigned)(p ^ r));
    int base = p & r, b = (ax + 1) % 3, c = (ax + 2) % 3;
    return ax * 4 + ((base >> b) & 1) + 2 * ((base >> c) & 1);
}

static int edge_base(int e)
{
    int ax = e / 4, b = (ax + 1) % 3, c = (ax + 2) % 3;
    return ((e & 1) << b) | (((e >> 1) & 1) << c);
}

/* The table is derived rather than typed in. On each cube face, seen from
 * outside the cube with its corners counter-clockwise, every crossing where
 * the boundary walk enters the inside is joined to the next crossing where
 * it leaves. That cuts inside corners off one by one, so an ambiguous face
 * (two inside corners on a diagonal) keeps them apart; the rule depends only
 * on the face's four corners, so the two cells sharing a face cut it the
 * same way and the surface has no cracks. The joined segments close into
 * loops around the cube (each crossing edge is entered on one of its faces
 * and left on the other); each loop is fanned into triangles. Walking with
 * the inside on the right seen from outside makes the loop turn
 * counter-clockwise seen from the free side: normals point to the free side. */
static void mc_build(void)
{
    for (int m = 0; m < 256; m++) {
        int next[12];
        for (int e = 0; e < 12; e++) next[e] = -1;
        for (int a = 0; a < 3; a++)
            for (int s = 0; s < 2; s++) {
                int b = (a + 1) % 3, c = (a + 2) % 3;
                static const int bb[4] = {0, 1, 1, 0}, cc[4] = {0, 0, 1, 1};
                int q[4];
                for (int k = 0; k < 4; k++) {
                    int kk = s ? k : 3 - k;
                    q[k] = (s << a) | (bb[kk] << b) | (cc[kk] << c);
                }
                for (int k = 0; k < 4; k++) {
                    bool in0 = (m >> q[k]) & 1, in1 = (m >> q[(k + 1) % 4]) & 1;
                    if (in0 || !in1) continue;
                    for (int j = 1; j < 4; j++) {
                        int k0 = (k + j) % 4, k1 = (k + j + 1) % 4;
                        if (((m >> q[k0]) & 1) && !((m >> q[k1]) & 1)) {
                            int from = edge_id(q[k], q[(k + 1) % 4]);
                            BF_ASSERT(next[from] < 0);
                            next[from] = edge_id(q[k0], q[k1]);
                            break;
                        }
                    }
                }
            }
        bool used[12] = {false};
        int n = 0;
        for (int e0 = 0; e0 < 12; e0++) {
            if (next[e0] < 0 || used[e0]) continue;
            int loop[12], len = 0;
            for (int e = e0; !used[e]; e = next[e]) {
                BF_ASSERT(next[e] >= 0);
                used[e] = true;
                loop[len++] = e;
            }
            BF_ASSERT(len >= 3);
            for (int k = 1; k + 1 < len; k++) {
                mc_tris[m][3 * n + 0] = (int8_t)loop[0];
                mc_tris[m][3 * n + 1] = (int8_t)loop[k];
                mc_tris[m][3 * n + 2] = (int8_t)loop[k + 1];
                n++;
            }
        }
        BF_ASSERT(n <= 12);
        mc_n_tris[m] = (uint8_t)n;
    }
}

/* ------------------------------------------------------------ per brick */

typedef struct corner {
    int8_t cls; /* -1 unknown, 0 inside, 1 free */
    float f;    /* smoothed sign field */
} corner;

/* One triangle corner: the lattice edge it sits on (packed) and where. */
typedef struct tri_vert {
    uint64_t k0, k1;
    float t;
} tri_vert;

typedef struct brick_out {
    tri_vert *v;
    size_t n, cap;
    uint64_t n_cells;
    bool failed;
} brick_out;

typedef struct mesh_job {
    const export__grid *g;
    uint32_t lo;            /* lattice level */
    brick_out *out;         /* per entry of g->order */
    size_t first;           /* entry of g->order of the current batch's index 0 */
} mesh_job;

#define COORD_BIAS ((int64_t)1 << 41)
#define COORD_MASK (((uint64_t)1 << 42) - 1)

static void key_pack(const int64_t c[3], int axis, uint64_t *k0, uint64_t *k1)
{
    uint64_t x = (uint64_t)(c[0] + COORD_BIAS) & COORD_MASK, y = (uint64_t)(c[1] + COORD_BIAS) & COORD_MASK,
             z = (uint64_t)(c[2] + COORD_BIAS) & COORD_MASK;
    *k0 = x | (y << 42);
    *k1 = (y >> 22) | (z << 20) | ((uint64_t)axis << 62);
}

static void key_unpack(uint64_t k0, uint64_t k1, int64_t c[3], int *axis)
{
    c[0] = (int64_t)(k0 & COORD_MASK) - COORD_BIAS;
    c[1] = (int64_t)(((k0 >> 42) | (k1 << 22)) & COORD_MASK) - COORD_BIAS;
    c[2] = (int64_t)((k1 >> 20) & COORD_MASK) - COORD_BIAS;
    *axis = (int)(k1 >> 62);
}

/* Corner at lattice point c: the finest confident voxel containing the
 * point classifies it (its sign bit, or, where that voxel is coarser than
 * the lattice, the sign of the interpolated field, so coarse data is not
 * meshed as terraces of fine cells); the field of that voxel's level
 * places vertices. *owner (may be NULL) receives the voxel's brick. */
static corner corner_eval(const mesh_job *j, const int64_t c[3], uint32_t *owner)
{
    const export__grid *g = j->g;
    int64_t q[3];
    for (int a = 0; a < 3; a++) q[a] = export__centre_q(g, j->lo, c[a]);
    export__voxel v;
    corner r = {-1, 0};
    if (owner) *owner = EXPORT__NONE;
    if (!export__grid_sample(g, q, &v)) return r;
    if (owner) *owner = v.brick;
    double f = export__grid_field(g, v.level, q);
    if (isnan(f)) f = v.is_free ? 1 : -1; /* cannot happen: the voxel itself has a field */
    r.f = (float)f;
    if (v.level >= j->lo || f == 0)
        r.cls = v.is_free ? 1 : 0;
    else
        r.cls = f > 0 ? 1 : 0;
    return r;
}

static bool out_reserve(brick_out *o, size_t more)
{
    if (o->n + more <= o->cap) return true;
    size_t cap = o->cap ? o->cap * 2 : 192;
    while (cap < o->n + more) cap *= 2;
    tri_vert *v = bf_realloc(o->v, cap * sizeof *v);
    if (!v) return false;
    o->v = v;
    o->cap = cap;
    return true;
}

/* Marching cubes on the cell whose first corner is lattice point c. */
static void emit_cell(brick_out *o, const int64_t c[3], const corner cr[8])
{
    int m = 0;
    for (int i = 0; i < 8; i++) {
        if (cr[i].cls < 0) return; /* the cell reaches into unknown space */
        m |= (cr[i].cls == 0) << i;
    }
    int n = mc_n_tris[m];
    if (n == 0) return;
    if (!out_reserve(o, 3 * (size_t)n)) {
        o->failed = true;
        return;
    }
    o->n_cells++;
    for (int k = 0; k < 3 * n; k++) {
        int e = mc_tris[m][k], ax = e / 4, i0 = edge_base(e), i1 = i0 | (1 << ax);
        int64_t p[3] = {c[0] + (i0 & 1), c[1] + ((i0 >> 1) & 1), c[2] + ((i0 >> 2) & 1)};
        /* Zero crossing of the field along the edge when the field agrees
         * with the classification at both ends, else the midpoint. */
        float f0 = cr[i0].f, f1 = cr[i1].f, t = 0.5f;
        bool in0 = cr[i0].cls == 0;
        if ((in0 ? f0 < 0 && f1 > 0 : f0 > 0 && f1 < 0)) t = f0 / (f0 - f1);
        tri_vert *tv = &o->v[o->n++];
        key_pack(p, ax, &tv->k0, &tv->k1);
        tv->t = t;
    }
}

/* A brick at the lattice level: its 512 voxel centres are lattice points. */
static void mesh_native(const mesh_job *j, uint32_t i, brick_out *o)
{
    const export__grid *g = j->g;
    const hostmap_brick *br = &g->s->bricks[i];
    const int64_t *b = g->bc[i];
    bool fast = !g->has_finer[i];
    static const int n9 = 9;
    corner cr[9 * 9 * 9];
    bool own[8 * 8 * 8];
    const int8_t *sf = g->sfield + (size_t)i * BRICK_VOXELS;
    for (int z = 0; z < n9; z++)
        for (int y = 0; y < n9; y++)
            for (int x = 0; x < n9; x++) {
                corner *r = &cr[(z * n9 + y) * n9 + x];
                bool inside = x < 8 && y < 8 && z < 8;
                if (fast && inside) {
                    bool conf = export__bit(br->conf, (uint32_t)x, (uint32_t)y, (uint32_t)z);
                    own[(z * 8 + y) * 8 + x] = conf;
                    if (conf) {
                        r->cls = export__bit(br->sign, (uint32_t)x, (uint32_t)y, (uint32_t)z) ? 1 : 0;
                        r->f = (float)(sf[z * 64 + y * 8 + x] / 127.0); /* bit-equal to corner_eval at a centre */
                        continue;
                    }
                }
                int64_t c[3] = {b[0] * 8 + x, b[1] * 8 + y, b[2] * 8 + z};
                uint32_t owner;
                *r = corner_eval(j, c, &owner);
                if (inside) own[(z * 8 + y) * 8 + x] = owner == i;
            }
    for (int z = 0; z < 8; z++)
        for (int y = 0; y < 8; y++)
            for (int x = 0; x < 8; x++) {
                if (!own[(z * 8 + y) * 8 + x]) continue;
                corner c8[8];
                for (int k = 0; k < 8; k++)
                    c8[k] = cr[((z + (k >> 2 & 1)) * n9 + y + (k >> 1 & 1)) * n9 + x + (k & 1)];
                int64_t c[3] = {b[0] * 8 + x, b[1] * 8 + y, b[2] * 8 + z};
                emit_cell(o, c, c8);
            }
}

/* Whether every point of level-L voxel v has a finer confident voxel (then
 * it owns no lattice point). Checks the levels up to 3 finer, whose voxels
 * under v lie in one brick; "no" is always safe. */
static bool covered_by_finer(const export__grid *g, uint32_t L, const int64_t v[3])
{
    for (uint32_t k = 0; k < g->n_levels; k++) {
        uint32_t Lf = g->levels_desc[k];
        if (Lf <= L || Lf - L > 3) continue;
        uint32_t d = Lf - L, n = 1u << d;
        int64_t c0[3] = {v[0] * ((int64_t)1 << d), v[1] * ((int64_t)1 << d), v[2] * ((int64_t)1 << d)};
        int64_t b[3] = {export__shr(c0[0], 3), export__shr(c0[1], 3), export__shr(c0[2], 3)};
        uint32_t j = export__grid_find(g, Lf, b);
        if (j == EXPORT__NONE) continue;
        const hostmap_brick *fb = &g->s->bricks[j];
        bool all = true;
        for (uint32_t z = 0; z < n && all; z++)
            for (uint32_t y = 0; y < n && all; y++)
                for (uint32_t x = 0; x < n && all; x++)
                    all = export__bit(fb->conf, (uint32_t)(c0[0] & 7) + x, (uint32_t)(c0[1] & 7) + y,
                                      (uint32_t)(c0[2] & 7) + z);
        if (all) return true;
    }
    return false;
}

/* Whether any brick of a finer level overlaps level-L voxel v (levels more
 * than 3 finer are assumed to: "yes" is always safe). */
static bool overlapped_by_finer(const export__grid *g, uint32_t L, const int64_t v[3])
{
    for (uint32_t k = 0; k < g->n_levels; k++) {
        uint32_t Lf = g->levels_desc[k];
        if (Lf <= L) continue;
        if (Lf - L > 3) return true;
        uint32_t d = Lf - L;
        int64_t b[3] = {export__shr(v[0] * ((int64_t)1 << d), 3), export__shr(v[1] * ((int64_t)1 << d), 3), export__shr(v[2] * ((int64_t)1 << d), 3)};
        if (export__grid_find(g, Lf, b) != EXPORT__NONE) return true;
    }
    return false;
}

/* corner_eval for a corner of a coarse brick's cell, without the hash when
 * the corner's voxel is a confident level-L voxel in one of the 27 bricks
 * around, none of them overlapped by finer bricks: then that voxel is the
 * finest confident one there, as corner_eval would find, and the field is
 * computed by the same function on the same bytes. False: use corner_eval. */
static bool coarse_corner(const mesh_job *j, uint32_t L, const export__nbhood *nbh, const int64_t c[3], corner *out)
{
    const export__grid *g = j->g;
    uint32_t sh = g->level_max - L + 1;
    int64_t q[3], u[3];
    int k = 0, mul = 1;
    for (int a = 0; a < 3; a++) {
        q[a] = export__centre_q(g, j->lo, c[a]);
        u[a] = export__shr(q[a], sh);
        int64_t d = export__shr(u[a], 3) - nbh->b[a];
        if (d < -1 || d > 1) return false;
        k += (int)(d + 1) * mul;
        mul *= 3;
    }
    uint32_t n = nbh->idx[k];
    if (n == EXPORT__NONE || g->has_finer[n]) return false;
    const hostmap_brick *br = &g->s->bricks[n];
    uint32_t x = (uint32_t)(u[0] & 7), y = (uint32_t)(u[1] & 7), z = (uint32_t)(u[2] & 7);
    if (!export__bit(br->conf, x, y, z)) return false;
    bool is_free = export__bit(br->sign, x, y, z);
    double f = export__grid_field_nb(g, L, q, nbh);
    if (isnan(f)) f = is_free ? 1 : -1;
    out->f = (float)f;
    out->cls = f == 0 ? (is_free ? 1 : 0) : f > 0 ? 1 : 0; /* L is coarser than the lattice */
    return true;
}

/* A brick coarser than the lattice: each of its voxels holds k^3 lattice
 * points. Voxels whose 3x3x3 neighbourhood is confident, not overlapped by
 * finer bricks and of one field sign cannot produce triangles (every corner
 * of their cells is classified by a field interpolated from that
 * neighbourhood) and are skipped. */
static void mesh_coarse(const mesh_job *j, uint32_t i, brick_out *o)
{
    const export__grid *g = j->g;
    const hostmap_brick *br = &g->s->bricks[i];
    uint32_t L = br->level, d = j->lo - L;
    int64_t k = (int64_t)1 << d;
    const int64_t *b = g->bc[i];
    int8_t sg[10][10][10];
    export__nbhood nbh;
    export__grid_nbhood(g, L, b, &nbh);
    for (int dz = -1; dz <= 1; dz++)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int64_t nb[3] = {b[0] + dx, b[1] + dy, b[2] + dz};
                uint32_t n = export__grid_find(g, L, nb);
                const int8_t *sf = n == EXPORT__NONE ? NULL : g->sfield + (size_t)n * BRICK_VOXELS;
                bool check_each = sf && g->has_finer[n];
                for (int z = 0; z < 8; z++) {
                    int pz = z + 1 + 8 * dz;
                    if (pz < 0 || pz > 9) continue;
                    for (int y = 0; y < 8; y++) {
                        int py = y + 1 + 8 * dy;
                        if (py < 0 || py > 9) continue;
                        for (int x = 0; x < 8; x++) {
                            int px = x + 1 + 8 * dx;
                            if (px < 0 || px > 9) continue;
                            int8_t s = sf ? sf[z * 64 + y * 8 + x] : EXPORT__NO_FIELD;
                            if (check_each && s != EXPORT__NO_FIELD) {
                                int64_t v[3] = {nb[0] * 8 + x, nb[1] * 8 + y, nb[2] * 8 + z};
                                if (overlapped_by_finer(g, L, v)) s = EXPORT__NO_FIELD;
                            }
                            sg[pz][py][px] = (s == EXPORT__NO_FIELD || s == 0) ? 0 : s > 0 ? 1 : -1;
                        }
                    }
                }
            }
    size_t nk = (size_t)(k + 1);
    corner *cr = bf_malloc(nk * nk * nk * sizeof *cr);
    if (!cr) {
        o->failed = true;
        return;
    }
    for (int z = 0; z < 8; z++)
        for (int y = 0; y < 8; y++)
            for (int x = 0; x < 8; x++) {
                if (!export__bit(br->conf, (uint32_t)x, (uint32_t)y, (uint32_t)z)) continue;
                int64_t v[3] = {b[0] * 8 + x, b[1] * 8 + y, b[2] * 8 + z};
                if (g->has_finer[i] && covered_by_finer(g, L, v)) continue;
                int8_t s0 = sg[z + 1][y + 1][x + 1];
                bool uniform = s0 != 0;
                for (int n = 0; n < 27 && uniform; n++)
                    uniform = sg[z + n / 9][y + n / 3 % 3][x + n % 3] == s0;
                if (uniform) continue;
                int64_t c0[3] = {(b[0] * 8 + x) * k, (b[1] * 8 + y) * k, (b[2] * 8 + z) * k};
                for (size_t n = 0; n < nk * nk * nk; n++) {
                    int64_t c[3] = {c0[0] + (int64_t)(n % nk), c0[1] + (int64_t)(n / nk % nk),
                                    c0[2] + (int64_t)(n / (nk * nk))};
                    if (!coarse_corner(j, L, &nbh, c, &cr[n])) cr[n] = corner_eval(j, c, NULL);
                }
                for (int64_t cz = 0; cz < k; cz++)
                    for (int64_t cy = 0; cy < k; cy++)
                        for (int64_t cx = 0; cx < k; cx++) {
                            int64_t c[3] = {c0[0] + cx, c0[1] + cy, c0[2] + cz};
                            if (g->has_finer[i]) {
                                uint32_t owner;
                                corner_eval(j, c, &owner);
                                if (owner != i) continue;
                            }
                            corner c8[8];
                            for (int kk = 0; kk < 8; kk++)
                                c8[kk] = cr[(size_t)((cz + (kk >> 2 & 1)) * (int64_t)nk + cy + (kk >> 1 & 1)) * nk +
                                            (size_t)(cx + (kk & 1))];
                            emit_cell(o, c, c8);
                        }
            }
    free(cr);
}

/* A brick finer than the lattice (max_level set): the lattice points inside
 * it whose finest confident voxel lies in it. */
static void mesh_fine(const mesh_job *j, uint32_t i, brick_out *o)
{
    const export__grid *g = j->g;
    uint32_t d = g->s->bricks[i].level - j->lo;
    const int64_t *b = g->bc[i];
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = export__shr(b[a] * 8, d);
        hi[a] = export__shr(b[a] * 8 + 7, d);
    }
    for (int64_t z = lo[2]; z <= hi[2]; z++)
        for (int64_t y = lo[1]; y <= hi[1]; y++)
            for (int64_t x = lo[0]; x <= hi[0]; x++) {
                int64_t c[3] = {x, y, z};
                uint32_t owner;
                corner c8[8];
                c8[0] = corner_eval(j, c, &owner);
                if (owner != i) continue;
                for (int kk = 1; kk < 8; kk++) {
                    int64_t ck[3] = {x + (kk & 1), y + (kk >> 1 & 1), z + (kk >> 2 & 1)};
                    c8[kk] = corner_eval(j, ck, NULL);
                }
                emit_cell(o, c, c8);
            }
}

static void mesh_brick(void *ctx, size_t k)
{
    const mesh_job *j = ctx;
    k += j->first;
    uint32_t i = j->g->order[k];
    uint32_t L = j->g->s->bricks[i].level;
    if (L == j->lo)
        mesh_native(j, i, &j->out[k]);
    else if (L < j->lo)
        mesh_coarse(j, i, &j->out[k]);
    else
        mesh_fine(j, i, &j->out[k]);
}

/* ------------------------------------------------------------ weld, smooth */

typedef struct weld_slot {
    uint64_t k0, k1;
    uint32_t idx; /* UINT32_MAX = empty */
} weld_slot;

static uint64_t weld_hash(uint64_t k0, uint64_t k1)
{
    uint64_t h = (k0 * 0x9E3779B97F4A7C15ull) ^ (k1 * 0xC2B2AE3D27D4EB4Full);
    return h ^ (h >> 29);
}

/* Doubles the weld table, re-inserting its entries; false without memory
 * (the old table is then kept for the caller to free). */
static bool weld_grow(weld_slot **ws, uint64_t *cap)
{
    uint64_t nc = *cap * 2;
    weld_slot *n = bf_malloc(nc * sizeof *n);
    if (!n) return false;
    for (uint64_t k = 0; k < nc; k++) n[k].idx = UINT32_MAX;
    for (uint64_t k = 0; k < *cap; k++) {
        const weld_slot *o = &(*ws)[k];
        if (o->idx == UINT32_MAX) continue;
        uint64_t sl = weld_hash(o->k0, o->k1) & (nc - 1);
        while (n[sl].idx != UINT32_MAX) sl = (sl + 1) & (nc - 1);
        n[sl] = *o;
    }
    free(*ws);
    *ws = n;
    *cap = nc;
    return true;
}

typedef struct smooth_job {
    const uint32_t *nb_start, *nb;
    const double *src;
    double *dst;
    double w;
    uint32_t n;
} smooth_job;

#define SMOOTH_BLOCK 4096u

static void smooth_block(void *ctx, size_t blk)
{
    const smooth_job *s = ctx;
    uint32_t end = (uint32_t)((blk + 1) * SMOOTH_BLOCK < s->n ? (blk + 1) * SMOOTH_BLOCK : s->n);
    for (uint32_t v = (uint32_t)(blk * SMOOTH_BLOCK); v < end; v++) {
        uint32_t a = s->nb_start[v], e = s->nb_start[v + 1];
        for (int c = 0; c < 3; c++) {
            double p = s->src[3 * v + c];
            if (e == a) {
                s->dst[3 * v + c] = p;
                continue;
            }
            double m = 0;
            for (uint32_t k = a; k < e; k++) m += s->src[3 * s->nb[k] + c];
            m /= (double)(e - a);
            s->dst[3 * v + c] = p + s->w * (m - p);
        }
    }
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* Taubin's lambda|mu smoothing on the umbrella operator: a positive step
 * then a slightly larger negative one, a low-pass filter that does not
 * shrink the surface. BF_NO_MEMORY leaves pos untouched. */
static bf_status taubin(double *pos, uint32_t n_verts, const uint32_t *tri, uint32_t n_tris, float lambda, float mu,
                        uint32_t iterations)
{
    if (iterations == 0 || n_verts == 0) return BF_OK;
    uint32_t *start = bf_calloc((size_t)n_verts + 1, sizeof *start);
    uint32_t *nb = bf_malloc((size_t)n_tris * 6 * sizeof *nb);
    uint32_t *fill = bf_malloc((size_t)n_verts * sizeof *fill);
    double *tmp = bf_malloc((size_t)n_verts * 3 * sizeof *tmp);
    if (!start || !nb || !fill || !tmp) {
        free(start), free(nb), free(fill), free(tmp);
        return bf_fail(BF_NO_MEMORY, "export: no memory to smooth %u vertices", n_verts);
    }
    for (uint32_t t = 0; t < n_tris; t++)
        for (int k = 0; k < 3; k++) start[tri[3 * t + k] + 1] += 2;
    for (uint32_t v = 0; v < n_verts; v++) start[v + 1] += start[v];
    memcpy(fill, start, (size_t)n_verts * sizeof *fill);
    for (uint32_t t = 0; t < n_tris; t++)
        for (int k = 0; k < 3; k++) {
            uint32_t v = tri[3 * t + k];
            nb[fill[v]++] = tri[3 * t + (k + 1) % 3];
            nb[fill[v]++] = tri[3 * t + (k + 2) % 3];
        }
    /* Unique neighbours, compacted in place. */
    uint32_t w = 0;
    for (uint32_t v = 0; v < n_verts; v++) {
        uint32_t a = start[v], e = start[v + 1];
        qsort(nb + a, e - a, sizeof *nb, cmp_u32);
        start[v] = w;
        for (uint32_t k = a; k < e; k++)
            if (k == a || nb[k] != nb[k - 1]) nb[w++] = nb[k];
    }
    start[n_verts] = w;
    smooth_job sj = {start, nb, pos, tmp, lambda, n_verts};
    size_t blocks = (n_verts + SMOOTH_BLOCK - 1) / SMOOTH_BLOCK;
    for (uint32_t it = 0; it < iterations; it++) {
        sj.src = pos, sj.dst = tmp, sj.w = lambda;
        bf_parallel_for(blocks, smooth_block, &sj);
        sj.src = tmp, sj.dst = pos, sj.w = mu;
        bf_parallel_for(blocks, smooth_block, &sj);
    }
    free(start), free(nb), free(fill), free(tmp);
    return BF_OK;
}

/* ------------------------------------------------------------ public */

#define MESH_BATCH ((size_t)4096)

export_mesh_config export_mesh_config_default(void)
{
    export_mesh_config c = {
        .max_level = UINT32_MAX, .taubin_lambda = 0.5f, .taubin_mu = -0.53f, .taubin_iterations = 5};
    return c;
}

bf_status export_mesh(const hostmap *s, const export_mesh_config *cfg, mesh_data *out,
                             export_stats *st)
{
    double t0 = bf_time_s();
    export_mesh_config c = cfg ? *cfg : export_mesh_config_default();
    if (!out) return bf_fail(BF_INVALID_ARG, "export: mesh output is NULL");
    if (!isfinite(c.taubin_lambda) || !isfinite(c.taubin_mu) || c.taubin_lambda < 0 || c.taubin_lambda > 1 ||
        c.taubin_mu > 0 || c.taubin_mu < -1)
        return bf_fail(BF_INVALID_ARG, "export: Taubin factors lambda %g, mu %g outside [0, 1] and [-1, 0]",
                       (double)c.taubin_lambda, (double)c.taubin_mu);
    pthread_once(&mc_once, mc_build);

    export__grid g;
    bf_status rc = export__grid_build(s, true, &g);
    if (rc != BF_OK) return rc;
    export_stats sx;
    memset(&sx, 0, sizeof sx);
    mesh_data m = {0};
    brick_out *bo = NULL;
    weld_slot *ws = NULL;
    double *pos = NULL;
    uint32_t lo = g.level_max < c.max_level ? g.level_max : c.max_level;
    sx.level_out = lo;
    sx.n_bricks = g.n;
    sx.n_duplicates = g.n_duplicates;
    for (uint32_t k = 0; k < g.n; k++) sx.bricks_per_level[export__level_slot(s->bricks[g.order[k]].level)]++;
    if (g.n == 0) goto done;

    bo = bf_calloc(g.n, sizeof *bo);
    if (!bo) goto fail_mem;
    /* Batches only so that a progress line can follow long exports. */
    mesh_job job = {&g, lo, bo, 0};
    bf_progress prog;
    bf_progress_begin(&prog, "export: mesh bricks", g.n);
    for (size_t b0 = 0; b0 < g.n; b0 += MESH_BATCH) {
        job.first = b0;
        bf_parallel_for(g.n - b0 < MESH_BATCH ? g.n - b0 : MESH_BATCH, mesh_brick, &job);
        bf_progress_update(&prog, b0);
    }
    bf_progress_end(&prog, g.n);
    size_t n_tv = 0;
    for (uint32_t k = 0; k < g.n; k++) {
        if (bo[k].failed) goto fail_mem;
        n_tv += bo[k].n;
        sx.n_cells += bo[k].n_cells;
        sx.cells_per_level[export__level_slot(s->bricks[g.order[k]].level)] += bo[k].n_cells;
    }
    if (n_tv / 3 > UINT32_MAX) {
        rc = bf_fail(BF_UNSUPPORTED, "export: %zu triangles do not fit 32-bit indices", n_tv / 3);
        goto fail;
    }
    m.n_tris = (uint32_t)(n_tv / 3);
    if (m.n_tris == 0) goto done;

    /* Weld: one vertex per lattice edge, numbered in order of first use.
     * A closed mesh has about one vertex per 6 corners (rims more), so the
     * table starts at twice that and doubles when half full: sized by the
     * corners it was the largest block of a big export (24 bytes a corner). */
    uint64_t cap = 16;
    while (cap < n_tv / 3) cap <<= 1;
    size_t pos_cap = n_tv / 4 + 16; /* grown below if the mesh has many rim vertices */
    ws = bf_malloc(cap * sizeof *ws);
    m.tri = bf_malloc(n_tv * sizeof *m.tri);
    pos = bf_malloc(pos_cap * 3 * sizeof *pos);
    if (!ws || !m.tri || !pos) goto fail_mem;
    for (uint64_t k = 0; k < cap; k++) ws[k].idx = UINT32_MAX;
    size_t t_i = 0;
    uint32_t step = 2u << (g.level_max - lo);
    for (uint32_t k = 0; k < g.n; k++) {
        for (size_t v = 0; v < bo[k].n; v++) {
            const tri_vert *tv = &bo[k].v[v];
            uint64_t h = weld_hash(tv->k0, tv->k1);
            uint64_t sl = h & (cap - 1);
            while (ws[sl].idx != UINT32_MAX && (ws[sl].k0 != tv->k0 || ws[sl].k1 != tv->k1)) sl = (sl + 1) & (cap - 1);
            if (ws[sl].idx == UINT32_MAX && 2 * ((uint64_t)m.n_verts + 1) > cap) {
                if (!weld_grow(&ws, &cap)) goto fail_mem;
                sl = h & (cap - 1);
                while (ws[sl].idx != UINT32_MAX) sl = (sl + 1) & (cap - 1);
            }
            if (ws[sl].idx == UINT32_MAX) {
                if (m.n_verts == pos_cap) {
                    double *p = bf_realloc(pos, pos_cap * 2 * 3 * sizeof *pos);
                    if (!p) goto fail_mem;
                    pos = p;
                    pos_cap *= 2;
                }
                ws[sl].k0 = tv->k0, ws[sl].k1 = tv->k1, ws[sl].idx = m.n_verts;
                int64_t cc[3];
                int ax;
                key_unpack(tv->k0, tv->k1, cc, &ax);
                for (int a = 0; a < 3; a++) {
                    double q = (double)export__centre_q(&g, lo, cc[a]) + (a == ax ? (double)tv->t * step : 0.0);
                    pos[3 * (size_t)m.n_verts + a] = q * g.half_m;
                }
                m.n_verts++;
            }
            m.tri[t_i++] = ws[sl].idx;
        }
        free(bo[k].v);
        bo[k].v = NULL;
    }
    free(ws);
    ws = NULL;

    /* Positions stay relative to origin_w while smoothing (small numbers). */
    rc = taubin(pos, m.n_verts, m.tri, m.n_tris, c.taubin_lambda, c.taubin_mu, c.taubin_iterations);
    if (rc != BF_OK) goto fail;
    m.xyz = bf_malloc((size_t)m.n_verts * 3 * sizeof *m.xyz);
    m.normal = bf_calloc((size_t)m.n_verts * 3, sizeof *m.normal);
    double *acc = bf_calloc((size_t)m.n_verts * 3, sizeof *acc);
    if (!m.xyz || !m.normal || !acc) {
        free(acc);
        goto fail_mem;
    }
    for (uint32_t t = 0; t < m.n_tris; t++) {
        const double *a = &pos[3 * (size_t)m.tri[3 * t]], *b = &pos[3 * (size_t)m.tri[3 * t + 1]],
                     *d = &pos[3 * (size_t)m.tri[3 * t + 2]];
        bf_vec3 n = bf_v3_cross(bf_v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]),
                                bf_v3(d[0] - a[0], d[1] - a[1], d[2] - a[2])); /* area-weighted */
        for (int k = 0; k < 3; k++) {
            double *o = &acc[3 * (size_t)m.tri[3 * t + k]];
            o[0] += n.x, o[1] += n.y, o[2] += n.z;
        }
    }
    /* In double up to here; the floats hold positions relative to the
     * local origin (export.h). */
    m.origin = export_local_origin(s);
    bf_vec3 shift = bf_v3_sub(s->origin_w, m.origin);
    for (uint32_t v = 0; v < m.n_verts; v++) {
        bf_vec3 n = bf_v3_normalize(bf_v3(acc[3 * v], acc[3 * v + 1], acc[3 * v + 2]));
        m.normal[3 * v] = (float)n.x, m.normal[3 * v + 1] = (float)n.y, m.normal[3 * v + 2] = (float)n.z;
        m.xyz[3 * v] = (float)(shift.x + pos[3 * v]);
        m.xyz[3 * v + 1] = (float)(shift.y + pos[3 * v + 1]);
        m.xyz[3 * v + 2] = (float)(shift.z + pos[3 * v + 2]);
    }
    free(acc);
    free(pos);
    pos = NULL;
    if ((rc = export__colourise(&g, &m)) != BF_OK) goto fail;
done:
    sx.n_triangles = m.n_tris;
    sx.n_vertices = m.n_verts;
    if (bo) {
        for (uint32_t k = 0; k < g.n; k++) free(bo[k].v);
        free(bo);
    }
    export__grid_free(&g);
    sx.seconds = bf_time_s() - t0;
    *out = m;
    if (st) *st = sx;
    return BF_OK;
fail_mem:
    rc = bf_fail(BF_NO_MEMORY, "export: no memory for the mesh of %u bricks", g.n);
fail:
    if (bo) {
        for (uint32_t k = 0; k < g.n; k++) free(bo[k].v);
        free(bo);
    }
    free(ws);
    free(pos);
    mesh_free(&m);
    export__grid_free(&g);
    return rc;
}
