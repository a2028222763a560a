/* Where a stored map's colours sit against its surface: every coloured
 * voxel of a scene store by its distance (L1, in voxels of its level) to
 * the nearest confident voxel of the other sign, and the surface voxels
 * (a face neighbour of the other sign) that have a colour. It measures how
 * far the colour pass's union of shells (docs/colour.md) reaches past the
 * surface the export and the views read.
 *
 *   build/bench/bench_colour_shells STORE [--keep-within K --write NEW]
 *
 * (a folder written by `bitfuse replay SEQ --store STORE`). With
 * --keep-within K it also writes the store NEW with the colour taken off
 * every voxel farther than K from the other sign (what a colour rule by
 * the map's own signs would keep), for `bitfuse export NEW` and
 * `bitfuse eval-colour` to score. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hostmap/hostmap.h"
#include "store/store.h"

enum { FAR = 4 }; /* distances past 3 voxels are counted together */

static uint32_t word_of(uint32_t x, uint32_t y, uint32_t z) { return (z >> 1) * 4u + (y >> 2) * 2u + (x >> 2); }
static uint32_t bit_of(uint32_t x, uint32_t y, uint32_t z) { return (z & 1u) * 16u + (y & 3u) * 4u + (x & 3u); }

static long find_brick(const hostmap *m, const int32_t key[3], uint32_t level, const uint32_t cell[3])
{
    hostmap_brick want = {.level = level};
    memcpy(want.key, key, sizeof want.key);
    memcpy(want.cell, cell, sizeof want.cell);
    long lo = 0, hi = (long)m->n_bricks - 1;
    while (lo <= hi) {
        long mid = lo + (hi - lo) / 2;
        int c = hostmap_brick_cmp(&m->bricks[mid], &want);
        if (c == 0) return mid;
        if (c < 0) lo = mid + 1;
        else hi = mid - 1;
    }
    return -1;
}

/* Sign of the voxel at offset d from voxel v of brick i, at the same level:
 * 0 or 1, or -1 where no confident voxel is there. */
static int sign_at(const hostmap *m, long i, const int v[3], const int d[3])
{
    const hostmap_brick *b = &m->bricks[i];
    int64_t n = (int64_t)8 << b->level;
    int32_t key[3];
    uint32_t cell[3], x[3];
    for (int a = 0; a < 3; a++) {
        int64_t g = (int64_t)b->key[a] * n + (int64_t)b->cell[a] * 8 + v[a] + d[a];
        int64_t q = g >= 0 ? g / n : -((-g + n - 1) / n);
        int64_t r = g - q * n;
        key[a] = (int32_t)q, cell[a] = (uint32_t)(r / 8), x[a] = (uint32_t)(r % 8);
    }
    long j = d[0] || d[1] || d[2] ? find_brick(m, key, b->level, cell) : i;
    if (j < 0) return -1;
    const hostmap_brick *o = &m->bricks[j];
    uint32_t w = word_of(x[0], x[1], x[2]), bit = bit_of(x[0], x[1], x[2]);
    if (!((o->conf[w] >> bit) & 1u)) return -1;
    return (int)((o->sign[w] >> bit) & 1u);
}

/* L1 distance to the nearest confident voxel of the other sign, FAR past 3. */
static int distance_to_surface(const hostmap *m, long i, const int v[3], int s)
{
    for (int r = 1; r < FAR; r++)
        for (int dz = -r; dz <= r; dz++)
            for (int dy = -r; dy <= r; dy++)
                for (int dx = -r; dx <= r; dx++) {
                    if (abs(dx) + abs(dy) + abs(dz) != r) continue;
                    int t = sign_at(m, i, v, (int[3]){dx, dy, dz});
                    if (t >= 0 && t != s) return r;
                }
    return FAR;
}

int main(int argc, char **argv)
{
    bool usage = argc != 2 && !(argc == 6 && !strcmp(argv[2], "--keep-within") && !strcmp(argv[4], "--write"));
    if (usage || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        fprintf(usage ? stderr : stdout, "usage: bench_colour_shells STORE [--keep-within K --write NEW]\n"
                                         "Coloured voxels of a scene store by their distance to the surface; with\n"
                                         "--keep-within, NEW is STORE with the colour farther than K voxels taken off.\n");
        return usage ? 2 : 0;
    }
    int keep = argc == 6 ? atoi(argv[3]) : 0;
    if (argc == 6 && keep < 1) {
        fprintf(stderr, "bench_colour_shells: --keep-within %s: a distance of 1 voxel or more\n", argv[3]);
        return 2;
    }
    hostmap m = {0};
    store_meta meta;
    store_report rep;
    bf_traj traj = {0};
    if (store_read(argv[1], &m, &meta, &traj, &rep) != BF_OK) {
        fprintf(stderr, "bench_colour_shells: %s\n", bf_last_error());
        return 3;
    }
    if (!m.rgb565) {
        fprintf(stderr, "bench_colour_shells: %s: the map holds no colour\n", argv[1]);
        hostmap_free(&m);
        return 3;
    }
    long by_distance[FAR + 1] = {0}, confident = 0, surface = 0, surface_coloured = 0, kept_off = 0;
    for (long i = 0; i < (long)m.n_bricks; i++)
        for (int z = 0; z < 8; z++)
            for (int y = 0; y < 8; y++)
                for (int x = 0; x < 8; x++) {
                    int v[3] = {x, y, z};
                    int s = sign_at(&m, i, v, (int[3]){0, 0, 0});
                    if (s < 0) continue;
                    confident++;
                    bool coloured = m.rgb565[i * 512 + x + 8 * y + 64 * z] != 0;
                    int d = distance_to_surface(&m, i, v, s);
                    if (d == 1) surface++, surface_coloured += coloured;
                    if (coloured) by_distance[d]++;
                    if (coloured && keep > 0 && d > keep) m.rgb565[i * 512 + x + 8 * y + 64 * z] = 0, kept_off++;
                }
    long coloured = 0;
    for (int d = 1; d <= FAR; d++) coloured += by_distance[d];
    printf("%s: %u bricks, %ld confident voxels, %ld coloured\n", argv[1], m.n_bricks, confident, coloured);
    printf("| L1 distance to the other sign | 1 | 2 | 3 | more |\n|---|---|---|---|---|\n| coloured voxels |");
    for (int d = 1; d <= FAR; d++) printf(" %ld (%.1f%%) |", by_distance[d], coloured ? 100.0 * by_distance[d] / coloured : 0.0);
    printf("\nsurface voxels (a face neighbour of the other sign): %ld, coloured %ld (%.1f%%)\n", surface,
           surface_coloured, surface ? 100.0 * surface_coloured / surface : 0.0);
    bf_status st = BF_OK;
    if (keep > 0) {
        store_writer *w = NULL;
        st = store_writer_open(argv[5], false, &w);
        if (st == BF_OK) st = store_writer_submit(w, &m, &meta, &traj);
        if (st == BF_OK) st = store_writer_finish(w);
        store_writer_close(w);
        if (st == BF_OK) printf("%s: %ld colours taken off (farther than %d), %ld kept\n", argv[5], kept_off, keep, coloured - kept_off);
        else fprintf(stderr, "bench_colour_shells: %s\n", bf_last_error());
    }
    hostmap_free(&m);
    bf_traj_free(&traj);
    return st == BF_OK ? 0 : 5;
}
