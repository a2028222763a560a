/* The store's layout shared by the reader and the writer: the canonical
 * brick order, chunk records, names, hashes and atomic writes. */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define XXH_INLINE_ALL
#include <xxhash.h>

#include "store_int.h"

_Static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the store's files are little-endian");

uint64_t store__hash(const void *p, size_t n) { return XXH3_64bits(p, n); }

void store__sort(hostmap *m)
{
    if (hostmap_sort(m) == BF_OK) return;
    /* No memory to carry colour: keep the geometry in order. */
    free(m->rgb565);
    m->rgb565 = NULL;
    bf_clear_error();
    bf_status s = hostmap_sort(m); /* without colour it allocates nothing */
    BF_ASSERT(s == BF_OK);
}

void store__pack(const hostmap *m, uint32_t first, uint32_t n, bool with_colour, uint8_t *buf)
{
    size_t rb = store__record_bytes(with_colour);
    for (uint32_t i = 0; i < n; i++) {
        const hostmap_brick *b = &m->bricks[first + i];
        uint8_t *r = buf + (size_t)i * rb;
        if (with_colour) memcpy(r + STORE_RECORD_BYTES, m->rgb565 + (size_t)(first + i) * 512, 1024);
        r[0] = (uint8_t)b->level;
        for (int k = 0; k < 3; k++) r[1 + k] = (uint8_t)b->cell[k];
        memcpy(r + 4, &b->error, 4);
        memcpy(r + 8, b->sign, 64);
        memcpy(r + 72, b->conf, 64);
    }
}

static bool same_key(const int32_t a[3], const int32_t b[3]) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

bf_status store__groups(const hostmap *m, store_group **out, uint32_t *n_out)
{
    uint32_t n = 0;
    for (uint32_t i = 0; i < m->n_bricks; i++) n += i == 0 || !same_key(m->bricks[i].key, m->bricks[i - 1].key);
    store_group *g = n ? bf_calloc(n, sizeof *g) : NULL;
    uint8_t *buf = NULL;
    uint32_t largest = 0, k = 0;
    if (n && !g) return bf_fail(BF_NO_MEMORY, "store: %u chunks", n);
    for (uint32_t i = 0; i < m->n_bricks; i++) {
        if (i == 0 || !same_key(m->bricks[i].key, m->bricks[i - 1].key)) {
            memcpy(g[k].key, m->bricks[i].key, sizeof g[k].key);
            g[k].first = i;
            k++;
        }
        g[k - 1].n++;
        if (g[k - 1].n > largest) largest = g[k - 1].n;
    }
    if (n && !(buf = bf_malloc((size_t)largest * STORE_COLOUR_RECORD_BYTES))) {
        free(g);
        return bf_fail(BF_NO_MEMORY, "store: records of %u bricks", largest);
    }
    for (uint32_t c = 0; c < n; c++) {
        for (size_t v = 0; m->rgb565 && !g[c].has_colour && v < (size_t)g[c].n * 512; v++)
            g[c].has_colour = m->rgb565[(size_t)g[c].first * 512 + v] != 0;
        store__pack(m, g[c].first, g[c].n, g[c].has_colour, buf);
        g[c].digest = store__hash(buf, (size_t)g[c].n * store__record_bytes(g[c].has_colour));
    }
    free(buf);
    *out = g;
    *n_out = n;
    return BF_OK;
}

static bool is_sorted(const hostmap *m)
{
    for (uint32_t i = 1; i < m->n_bricks; i++)
        if (hostmap_brick_cmp(&m->bricks[i - 1], &m->bricks[i]) > 0) return false;
    return true;
}

/* A copy of map in the canonical order, its colours with it. */
static bf_status sorted_copy(const hostmap *map, hostmap *copy)
{
    size_t n = map->n_bricks;
    *copy = *map;
    copy->bricks = bf_malloc(n * sizeof *copy->bricks + 1);
    copy->rgb565 = map->rgb565 ? bf_malloc(n * 512 * 2 + 1) : NULL;
    if (!copy->bricks || (map->rgb565 && !copy->rgb565)) {
        hostmap_free(copy);
        return bf_fail(BF_NO_MEMORY, "store: digest of %zu bricks", n);
    }
    memcpy(copy->bricks, map->bricks, n * sizeof *copy->bricks);
    if (map->rgb565) memcpy(copy->rgb565, map->rgb565, n * 512 * 2);
    bf_status s = hostmap_sort(copy);
    if (s != BF_OK) hostmap_free(copy);
    return s;
}

bf_status store_map_digest(const hostmap *map, uint64_t *out)
{
    if (!map || !out) return bf_fail(BF_INVALID_ARG, "store_map_digest: NULL argument");
    hostmap copy = {0};
    const hostmap *m = map;
    if (!is_sorted(map)) {
        bf_status s = sorted_copy(map, &copy);
        if (s != BF_OK) return s;
        m = &copy;
    }
    XXH3_state_t st;
    XXH3_64bits_reset(&st);
    uint8_t rec[STORE_RECORD_BYTES];
    for (uint32_t i = 0; i < m->n_bricks; i++) {
        XXH3_64bits_update(&st, m->bricks[i].key, sizeof m->bricks[i].key);
        store__pack(m, i, 1, false, rec);
        XXH3_64bits_update(&st, rec, sizeof rec);
        /* RGB565, little-endian like the files (the assertion above). */
        if (m->rgb565) XXH3_64bits_update(&st, m->rgb565 + (size_t)i * 512, 512 * 2);
    }
    hostmap_free(&copy);
    *out = XXH3_64bits_digest(&st);
    return BF_OK;
}

void store__chunk_name(char *out, size_t cap, const int32_t key[3])
{
    snprintf(out, cap, "c_%d_%d_%d.bfc", key[0], key[1], key[2]);
}

static bf_status write_all(int fd, const char *path, const void *p, size_t n)
{
    const uint8_t *c = p;
    while (n) {
        ssize_t k = bf_fault_now() ? (errno = ENOSPC, -1) : write(fd, c, n);
        if (k < 0 && errno == EINTR) continue;
        if (k < 0) return bf_fail(BF_WRITE, "%s: write failed: %s", path, strerror(errno));
        c += k;
        n -= (size_t)k;
    }
    return BF_OK;
}

/* path.tmp written whole and synced; *pending its slot (kept on success). */
static bf_status write_tmp(const char *path, const void *a, size_t na, const void *b, size_t nb, int *pending_out)
{
    char tmp[4200];
    if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp", path) >= sizeof tmp)
        return bf_fail(BF_INVALID_ARG, "%s: path too long", path);
    /* Messages name the file being written, not its temporary name. */
    int pending = bf_pending_add(tmp); /* a program killed by a signal removes it */
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) {
        int e = errno;
        bf_pending_forget(&pending);
        return bf_fail(BF_WRITE, "%s: cannot create %s: %s", path, tmp, strerror(e));
    }
    bf_status s = write_all(fd, path, a, na);
    if (s == BF_OK && nb) s = write_all(fd, path, b, nb);
    if (s == BF_OK && (bf_fault_now() ? (errno = ENOSPC, 1) : fsync(fd) != 0))
        s = bf_fail(BF_WRITE, "%s: fsync failed: %s", path, strerror(errno));
    if (close(fd) != 0 && s == BF_OK) s = bf_fail(BF_WRITE, "%s: close failed: %s", path, strerror(errno));
    if (s != BF_OK) {
        bf_pending_forget(&pending);
        unlink(tmp); /* the earlier version of path, if any, stays whole */
        return s;
    }
    *pending_out = pending;
    return BF_OK;
}

/* Renames path.tmp over path; path.tmp is gone either way. */
static bf_status rename_tmp(const char *path, int *pending)
{
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp", path); /* fits: write_tmp made it */
    bf_pending_forget(pending);
    if (rename(tmp, path) == 0) return BF_OK;
    bf_status s = bf_fail(BF_WRITE, "%s: rename failed: %s", path, strerror(errno));
    unlink(tmp);
    return s;
}

bf_status store__write_atomic(const char *path, const void *a, size_t na, const void *b, size_t nb)
{
    int pending = -1;
    bf_status s = write_tmp(path, a, na, b, nb, &pending);
    return s == BF_OK ? rename_tmp(path, &pending) : s;
}

bf_status store__write_staged(store_stage *stage, const char *path, const void *a, size_t na, const void *b,
                              size_t nb)
{
    if (stage->n == stage->cap) {
        uint32_t cap = stage->cap ? 2 * stage->cap : 16;
        char **p = bf_realloc(stage->paths, cap * sizeof *p);
        if (p) stage->paths = p;
        int *q = p ? bf_realloc(stage->pending, cap * sizeof *q) : NULL;
        if (q) stage->pending = q;
        if (!p || !q) return bf_fail(BF_NO_MEMORY, "%s: the store write's list of %u files", path, cap);
        stage->cap = cap;
    }
    char *name = bf_malloc(strlen(path) + 1);
    if (!name) return bf_fail(BF_NO_MEMORY, "%s: name", path);
    strcpy(name, path);
    int pending = -1;
    bf_status s = write_tmp(path, a, na, b, nb, &pending);
    if (s != BF_OK) {
        free(name);
        return s;
    }
    /* Its slot is kept until the rename: a second Ctrl-C during the write
     * removes every file it has put down. */
    stage->paths[stage->n] = name;
    stage->pending[stage->n++] = pending;
    return BF_OK;
}

static void stage_free(store_stage *stage)
{
    for (uint32_t i = 0; i < stage->n; i++) free(stage->paths[i]);
    free(stage->paths);
    free(stage->pending);
    memset(stage, 0, sizeof *stage);
}

/* Removes the staged files from the first-th on. */
static void unlink_staged(store_stage *stage, uint32_t first)
{
    for (uint32_t i = first; i < stage->n; i++) {
        char tmp[4200];
        snprintf(tmp, sizeof tmp, "%s.tmp", stage->paths[i]);
        bf_pending_forget(&stage->pending[i]);
        unlink(tmp);
    }
}

bf_status store__stage_commit(store_stage *stage)
{
    bf_status s = BF_OK;
    for (uint32_t i = 0; s == BF_OK && i < stage->n; i++)
        if ((s = rename_tmp(stage->paths[i], &stage->pending[i])) != BF_OK) unlink_staged(stage, i + 1);
    stage_free(stage);
    return s;
}

void store__stage_abort(store_stage *stage)
{
    unlink_staged(stage, 0);
    stage_free(stage);
}
