/* The ray-caster's CPU oracle. Deliberately unlike the GPU walk: no octree
 * pointers, no DDA over voxels. A hash set of every brick cell and every
 * ancestor cell of a brick (keyed by chunk, level, cell) answers "which is
 * the finest brick holding this point"; the ray moves from each voxel to
 * just past its exit (in double, relocating the point from scratch every
 * step: no incremental DDA state), and every voxel it lands in is judged
 * by the rule of render.h (front = sign 1; first behind voxel after a front
 * one is the hit; non-confident voxels are unknown when confident_only;
 * space without a brick forgets the front voxel). Where no brick holds the
 * point, the march jumps to the exit of the coarsest cell that holds no
 * brick at all (that jump is exact: nothing there can be hit). */
#include "raycast_ref.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "shaders/fusion.glsl.h"
#include "shaders/render.glsl.h"

typedef struct ref_cell {
    int32_t key[3];
    uint32_t pos;    /* fusion_pack_pos(cell, level) */
    int32_t brick;   /* index into the snapshot, -1: an ancestor only */
    bool used;
} ref_cell;

struct raycast_ref {
    const hostmap *snap;
    uint32_t max_level;
    ref_cell *cells;
    size_t cap; /* power of two */
};

static uint64_t cell_hash(const int32_t key[3], uint32_t pos)
{
    uint64_t h = 1469598103934665603ull;
    uint32_t v[4] = {(uint32_t)key[0], (uint32_t)key[1], (uint32_t)key[2], pos};
    for (int i = 0; i < 4; i++) h = (h ^ v[i]) * 1099511628211ull, h ^= h >> 29;
    return h;
}

static ref_cell *cell_slot(const raycast_ref *r, const int32_t key[3], uint32_t pos)
{
    size_t i = (size_t)cell_hash(key, pos) & (r->cap - 1);
    for (;;) {
        ref_cell *c = &r->cells[i];
        if (!c->used || (c->pos == pos && !memcmp(c->key, key, sizeof c->key))) return c;
        i = (i + 1) & (r->cap - 1);
    }
}

bf_status raycast_ref_create(const hostmap *snap, uint32_t max_level, raycast_ref **out)
{
    raycast_ref *r = calloc(1, sizeof *r);
    if (!r) return bf_fail(BF_NO_MEMORY, "raycast_ref");
    r->snap = snap;
    r->max_level = max_level;
    r->cap = 1024;
    while (r->cap < 4 * (size_t)snap->n_bricks * (max_level + 1)) r->cap *= 2;
    r->cells = calloc(r->cap, sizeof *r->cells);
    if (!r->cells) {
        size_t cap = r->cap;
        free(r);
        return bf_fail(BF_NO_MEMORY, "raycast_ref: %zu cells", cap);
    }
    for (uint32_t b = 0; b < snap->n_bricks; b++) {
        const hostmap_brick *fb = &snap->bricks[b];
        for (uint32_t l = 0; l <= fb->level; l++) {
            uint32_t sh = fb->level - l;
            uint32_t pos = fusion_pack_pos(fb->cell[0] >> sh, fb->cell[1] >> sh, fb->cell[2] >> sh, l);
            ref_cell *c = cell_slot(r, fb->key, pos);
            if (!c->used) {
                c->used = true;
                memcpy(c->key, fb->key, sizeof c->key);
                c->pos = pos;
                c->brick = -1;
            }
            if (l == fb->level) c->brick = (int32_t)b;
        }
    }
    *out = r;
    return BF_OK;
}

void raycast_ref_destroy(raycast_ref *r)
{
    if (!r) return;
    free(r->cells);
    free(r);
}

/* Ray parameter where the ray leaves the box [lo, lo + size]^3. */
static double box_exit(const double o[3], const double d[3], const double lo[3], double size)
{
    double s = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (fabs(d[a]) < 1e-15) continue;
        double bound = d[a] > 0 ? lo[a] + size : lo[a];
        double t = (bound - o[a]) / d[a];
        if (t < s) s = t;
    }
    return s;
}

/* Voxel (global voxel coordinates of level `level` from the map origin) as
 * the sub-voxel field sees it: +1 front, -1 behind, 0 unknown (no brick of
 * exactly that level there, or not confident when confident_only). */
static int voxel_value(const raycast_ref *r, const int64_t g[3], uint32_t level, bool confident_only)
{
    int64_t per = (int64_t)8 << level;
    int32_t key[3];
    uint32_t cell[3], x[3];
    for (int a = 0; a < 3; a++) {
        int64_t k = g[a] >= 0 ? g[a] / per : -((-g[a] + per - 1) / per);
        key[a] = (int32_t)k;
        int64_t in = g[a] - k * per;
        cell[a] = (uint32_t)(in / 8);
        x[a] = (uint32_t)(in % 8);
    }
    const ref_cell *c = cell_slot(r, key, fusion_pack_pos(cell[0], cell[1], cell[2], level));
    if (!c->used || c->brick < 0) return 0;
    const hostmap_brick *b = &r->snap->bricks[c->brick];
    uint32_t w = brick_word(x[0], x[1], x[2]), bit = brick_bit(x[0], x[1], x[2]);
    if (confident_only && !((b->conf[w] >> bit) & 1u)) return 0;
    return ((b->sign[w] >> bit) & 1u) ? 1 : -1;
}

/* The sub-voxel refinement of render.md, written out plainly: Newton steps
 * along the ray on the trilinear interpolation of the 3x3x3 means of the
 * known voxels' signs, from the midpoint depth s0. */
static double subvoxel(const raycast_ref *r, const double o[3], const double d[3], uint32_t level, double s0,
                       bool confident_only)
{
    double v = hostmap_level_voxel_m(r->snap->chunk_m, level);
    double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double step_max = RENDER_SUBVOXEL_MAX_STEP * v / len;
    double lo = s0 - RENDER_SUBVOXEL_MAX_MOVE * step_max, hi = s0 + RENDER_SUBVOXEL_MAX_MOVE * step_max, s = s0;
    for (uint32_t it = 0; it < RENDER_SUBVOXEL_ITERS; it++) {
        double q[3], f[3];
        int64_t G[3];
        for (int a = 0; a < 3; a++) {
            q[a] = (o[a] + s * d[a]) / v - 0.5;
            G[a] = (int64_t)floor(q[a]);
            f[a] = q[a] - (double)G[a];
        }
        double F = 0, grad[3] = {0, 0, 0};
        for (int c = 0; c < 8; c++) {
            int e[3] = {c & 1, (c >> 1) & 1, c >> 2};
            int sum = 0, known = 0;
            for (int dz = -1; dz <= 1; dz++)
                for (int dy = -1; dy <= 1; dy++)
                    for (int dx = -1; dx <= 1; dx++) {
                        int64_t g[3] = {G[0] + e[0] + dx, G[1] + e[1] + dy, G[2] + e[2] + dz};
                        int val = voxel_value(r, g, level, confident_only);
                        sum += val;
                        known += val != 0;
                    }
            double S = known ? (double)sum / known : 0.0, w[3];
            for (int a = 0; a < 3; a++) w[a] = e[a] ? f[a] : 1 - f[a];
            F += w[0] * w[1] * w[2] * S;
            grad[0] += (e[0] ? 1 : -1) * w[1] * w[2] * S;
            grad[1] += (e[1] ? 1 : -1) * w[0] * w[2] * S;
            grad[2] += (e[2] ? 1 : -1) * w[0] * w[1] * S;
        }
        double dFds = (grad[0] * d[0] + grad[1] * d[1] + grad[2] * d[2]) / v;
        if (!(dFds < 0)) break;
        double st = F / dFds;
        st = st < -step_max ? -step_max : (st > step_max ? step_max : st);
        s -= st;
        s = s < lo ? lo : (s > hi ? hi : s);
    }
    return s;
}

static void cast_one(const raycast_ref *r, const double o[3], const double d[3], const double zc[3],
                     const render_options *opt, float *depth_out, uint32_t *level_out)
{
    const double chunk = r->snap->chunk_m;
    bool has_front = false;
    double front_depth = 0;
    int64_t prev_voxel = -1;
    double s = opt->near_m;
    *depth_out = 0;
    *level_out = FUSION_NONE;
    while (s < opt->far_m) {
        double p[3], q[3];
        int32_t key[3];
        for (int a = 0; a < 3; a++) {
            p[a] = o[a] + s * d[a];
            key[a] = (int32_t)floor(p[a] / chunk);
            q[a] = p[a] - key[a] * chunk;
        }
        int32_t best = -1;
        uint32_t best_level = 0, free_level = r->max_level + 1;
        for (uint32_t l = 0; l <= r->max_level; l++) {
            double n = (double)(1u << l);
            uint32_t c[3];
            for (int a = 0; a < 3; a++) {
                double f = floor(q[a] * n / chunk);
                c[a] = (uint32_t)(f < 0 ? 0 : (f > n - 1 ? n - 1 : f));
            }
            const ref_cell *rc = cell_slot(r, key, fusion_pack_pos(c[0], c[1], c[2], l));
            if (!rc->used) {
                free_level = l;
                break;
            }
            if (rc->brick >= 0) best = rc->brick, best_level = l;
        }
        if (best < 0) {
            /* Nothing finer than free_level exists here and nothing coarser
             * holds a brick: jump over the whole cell at free_level. */
            has_front = false;
            prev_voxel = -1;
            double size = chunk / (double)(1u << free_level), lo[3];
            for (int a = 0; a < 3; a++) lo[a] = key[a] * chunk + floor(q[a] / size) * size;
            double e = box_exit(o, d, lo, size);
            s = (e > s ? e : s) + 1e-7;
            continue;
        }
        const hostmap_brick *b = &r->snap->bricks[best];
        double v = hostmap_level_voxel_m(chunk, best_level);
        uint32_t x[3];
        double c_w[3];
        for (int a = 0; a < 3; a++) {
            double lo = key[a] * chunk + b->cell[a] * 8 * v;
            double f = floor((p[a] - lo) / v);
            x[a] = (uint32_t)(f < 0 ? 0 : (f > 7 ? 7 : f));
            c_w[a] = lo + (x[a] + 0.5) * v;
        }
        int64_t id = (int64_t)best * 512 + x[0] + 8 * x[1] + 64 * x[2];
        if (id != prev_voxel) {
            prev_voxel = id;
            uint32_t w = brick_word(x[0], x[1], x[2]), bit = brick_bit(x[0], x[1], x[2]);
            bool known = !opt->confident_only || ((b->conf[w] >> bit) & 1u);
            double c_depth = (c_w[0] - o[0]) * zc[0] + (c_w[1] - o[1]) * zc[1] + (c_w[2] - o[2]) * zc[2];
            if (known) {
                if ((b->sign[w] >> bit) & 1u) {
                    has_front = true;
                    front_depth = c_depth;
                } else if (has_front) {
                    double mid = 0.5 * (front_depth + c_depth);
                    *depth_out = (float)(opt->refine ? subvoxel(r, o, d, best_level, mid, opt->confident_only) : s);
                    *level_out = best_level;
                    return;
                }
            }
        }
        /* On to the next voxel: just past this one's exit. */
        double vlo[3] = {c_w[0] - 0.5 * v, c_w[1] - 0.5 * v, c_w[2] - 0.5 * v};
        double e = box_exit(o, d, vlo, v);
        s = (e > s ? e : s) + 1e-7;
    }
}

void raycast_ref_run(const raycast_ref *r, const bf_intrinsics *K, const bf_se3 *T_wc, const render_options *opt,
                     float *depth, uint32_t *level)
{
    double o[3] = {T_wc->t.x - r->snap->origin_w.x, T_wc->t.y - r->snap->origin_w.y,
                   T_wc->t.z - r->snap->origin_w.z};
    double zc[3] = {T_wc->R[0][2], T_wc->R[1][2], T_wc->R[2][2]};
    for (uint32_t v = 0; v < K->height; v++)
        for (uint32_t u = 0; u < K->width; u++) {
            double xc = (u - K->cx_px) / K->fx_px, yc = (v - K->cy_px) / K->fy_px, d[3];
            for (int a = 0; a < 3; a++) d[a] = T_wc->R[a][0] * xc + T_wc->R[a][1] * yc + T_wc->R[a][2];
            size_t i = (size_t)v * K->width + u;
            cast_one(r, o, d, zc, opt, &depth[i], &level[i]);
        }
}
