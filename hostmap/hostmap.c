/* hostmap: the host copy of the map (hostmap.h). */
#include "hostmap.h"

#include <stdlib.h>
#include <string.h>

#include "shaders/fusion.glsl.h"

_Static_assert(sizeof(((hostmap_brick *)0)->sign) == BRICK_WORDS * 4, "a brick's bit plane is BRICK_WORDS words");

uint32_t hostmap_count_chunks(const hostmap *m)
{
    uint32_t n = 0;
    for (uint32_t i = 0; i < m->n_bricks; i++)
        n += i == 0 || memcmp(m->bricks[i].key, m->bricks[i - 1].key, sizeof m->bricks[i].key) != 0;
    return n;
}

void hostmap_free(hostmap *m)
{
    if (!m) return;
    free(m->bricks);
    free(m->rgb565);
    m->bricks = NULL;
    m->rgb565 = NULL;
    m->n_bricks = 0;
}

double hostmap_level_voxel_m(float chunk_m, uint32_t level) { return (double)fusion_voxel_m(chunk_m, level); }

bf_vec3 hostmap_voxel_center_w(const hostmap *m, const hostmap_brick *b, uint32_t x, uint32_t y, uint32_t z)
{
    double v = hostmap_level_voxel_m(m->chunk_m, b->level);
    uint32_t xyz[3] = {x, y, z};
    double p[3];
    for (int i = 0; i < 3; i++)
        p[i] = (double)b->key[i] * m->chunk_m + ((double)(b->cell[i] * 8 + xyz[i]) + 0.5) * v;
    return bf_v3(m->origin_w.x + p[0], m->origin_w.y + p[1], m->origin_w.z + p[2]);
}

static int cmp_i32(int32_t a, int32_t b) { return (a > b) - (a < b); }
static int cmp_u32(uint32_t a, uint32_t b) { return (a > b) - (a < b); }

int hostmap_brick_cmp(const hostmap_brick *a, const hostmap_brick *b)
{
    int c = 0;
    for (int i = 0; i < 3 && !c; i++) c = cmp_i32(a->key[i], b->key[i]);
    if (!c) c = cmp_u32(a->level, b->level);
    for (int i = 2; i >= 0 && !c; i--) c = cmp_u32(a->cell[i], b->cell[i]);
    return c;
}

static int brick_cmp(const void *pa, const void *pb) { return hostmap_brick_cmp(pa, pb); }

/* Sorting carries each brick's colour along: an index sort (glibc's
 * qsort_r: the store's writer thread and its caller may sort at once), then
 * both arrays in that order. */
static int index_cmp(const void *pa, const void *pb, void *ctx)
{
    const hostmap_brick *base = ctx;
    uint32_t a = *(const uint32_t *)pa, b = *(const uint32_t *)pb;
    int c = hostmap_brick_cmp(&base[a], &base[b]);
    return c ? c : (a > b) - (a < b);
}

bf_status hostmap_sort(hostmap *m)
{
    if (m->n_bricks < 2) return BF_OK;
    if (!m->rgb565) {
        qsort(m->bricks, m->n_bricks, sizeof *m->bricks, brick_cmp);
        return BF_OK;
    }
    uint32_t *idx = bf_malloc((size_t)m->n_bricks * sizeof *idx);
    hostmap_brick *b = bf_malloc((size_t)m->n_bricks * sizeof *b);
    uint16_t *c = bf_malloc((size_t)m->n_bricks * BRICK_VOXELS * 2);
    if (!idx || !b || !c) {
        free(idx), free(b), free(c);
        return bf_fail(BF_NO_MEMORY, "hostmap: sorting %u bricks with their colours", m->n_bricks);
    }
    for (uint32_t i = 0; i < m->n_bricks; i++) idx[i] = i;
    qsort_r(idx, m->n_bricks, sizeof *idx, index_cmp, m->bricks);
    for (uint32_t i = 0; i < m->n_bricks; i++) {
        b[i] = m->bricks[idx[i]];
        memcpy(c + (size_t)i * BRICK_VOXELS, m->rgb565 + (size_t)idx[i] * BRICK_VOXELS, BRICK_VOXELS * 2);
    }
    free(idx);
    free(m->bricks);
    free(m->rgb565);
    m->bricks = b;
    m->rgb565 = c;
    return BF_OK;
}
