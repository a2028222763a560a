/* Fuzz target: the scene store (store.json, trajectory.bin, chunk files)
 * through store_read, a chunk file through store_get_chunk (the streaming
 * tier's reader), and keyframes.bin through store_keyframes_read.
 *
 * The input is FUZZ_SEP-separated parts: 0 options ("fix": recompute the
 * chunk files' header and payload hashes and the trajectory's and the
 * keyframes' hashes, so that mutations reach the code behind them), 1
 * store.json, 2 trajectory.bin, 3-5 chunk files, 6 keyframes.bin. A chunk
 * file is named for the key its header holds (chunks/c_X_Y_Z.bfc), or
 * c_N_0_0.bfc when it is too short to hold one; a part the input does not
 * have is a file that is absent. */
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "store/store_int.h"

#define STORE_PARTS 7
#define STORE_KEYFRAMES_PART 6

static const char *chunk_name(const fuzz_part *p, int k, char *out, size_t cap)
{
    if (p->n >= STORE_CHUNK_HEADER) {
        int32_t key[3];
        memcpy(key, p->p + offsetof(store_chunk_header, key), sizeof key);
        char name[96];
        store__chunk_name(name, sizeof name, key);
        snprintf(out, cap, "%s/%s", STORE_CHUNK_DIR, name);
    } else {
        snprintf(out, cap, "%s/c_%d_0_0.bfc", STORE_CHUNK_DIR, k);
    }
    return out;
}

static void fix_chunk(uint8_t *b, size_t n)
{
    if (n < STORE_CHUNK_HEADER) return;
    uint64_t h = store__hash(b + STORE_CHUNK_HEADER, n - STORE_CHUNK_HEADER);
    memcpy(b + offsetof(store_chunk_header, payload_hash), &h, 8);
    h = store__hash(b, offsetof(store_chunk_header, header_hash));
    memcpy(b + offsetof(store_chunk_header, header_hash), &h, 8);
}

/* trajectory.bin and keyframes.bin: the XXH3-64 of all before the last 8 bytes. */
static void fix_traj(uint8_t *b, size_t n)
{
    if (n < 8) return;
    uint64_t h = store__hash(b, n - 8);
    memcpy(b + n - 8, &h, 8);
}

static const char *write_part(const char *dir, const char *name, const fuzz_part *p, bool fix,
                              void (*fixer)(uint8_t *, size_t))
{
    uint8_t *copy = bf_malloc(p->n ? p->n : 1);
    if (!copy) return NULL;
    memcpy(copy, p->p, p->n);
    if (fix) fixer(copy, p->n);
    const char *path = fuzz_write(dir, name, copy, p->n);
    free(copy);
    return path;
}

bf_status fuzz_store(const uint8_t *data, size_t size)
{
    fuzz_part parts[STORE_PARTS];
    int n = fuzz_split(data, size, parts, STORE_PARTS);
    bool fix = parts[0].n >= 3 && memcmp(parts[0].p, "fix", 3) == 0;
    const char *dir = fuzz_scratch();
    if (n > 1 && !fuzz_write(dir, STORE_INDEX_NAME, parts[1].p, parts[1].n)) return BF_IO;
    if (n > 2 && !write_part(dir, STORE_TRAJ_NAME, &parts[2], fix, fix_traj)) return BF_IO;
    int32_t first_key[3] = {0, 0, 0};
    if (n > STORE_KEYFRAMES_PART &&
        !write_part(dir, STORE_KEYFRAMES_NAME, &parts[STORE_KEYFRAMES_PART], fix, fix_traj))
        return BF_IO;
    for (int k = 3; k < n && k < STORE_KEYFRAMES_PART; k++) {
        char name[160];
        if (!write_part(dir, chunk_name(&parts[k], k - 3, name, sizeof name), &parts[k], fix, fix_chunk))
            return BF_IO;
        if (k == 3 && parts[k].n >= STORE_CHUNK_HEADER)
            memcpy(first_key, parts[k].p + offsetof(store_chunk_header, key), sizeof first_key);
        else if (k == 3)
            first_key[0] = 0;
    }
    hostmap map = {0};
    store_meta meta;
    bf_traj traj = {0};
    store_report rep;
    bf_status s = store_read(dir, &map, &meta, &traj, &rep);
    if (s == BF_OK) {
        hostmap_free(&map);
        bf_traj_free(&traj);
    }
    /* The streaming tier's reader, against the geometry store_read found
     * (or a default one). */
    store_meta m = {.chunk_m = 2.0f, .max_level = 8};
    if (s == BF_OK) m = meta;
    hostmap chunk = {0};
    uint64_t bytes = 0;
    bf_status s2 = store_get_chunk(dir, first_key, &m, &chunk, &bytes);
    if (s2 == BF_OK) hostmap_free(&chunk);
    store_keyframes kf;
    if (store_keyframes_read(dir, &kf) == BF_OK) store_keyframes_free(&kf);
    return s;
}

FUZZ_TARGET(fuzz_store)
