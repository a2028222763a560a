/* The scan's relocalisation keyframes on disk (store.h, keyframes.bin;
 * docs/formats.md). Written by the store's writer with a map when they
 * changed, read when a scan resumes: the file is an aid to finding the
 * camera, so a store without it (older, or killed before its first
 * flush) resumes as before, from the trajectory's poses. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "store_int.h"

void store_keyframes_free(store_keyframes *k)
{
    if (!k) return;
    for (uint32_t i = 0; k->kf && i < k->n; i++) {
        free(k->kf[i].desc);
        free(k->kf[i].xyz);
    }
    free(k->kf);
    memset(k, 0, sizeof *k);
}

static size_t keyframe_bytes(uint32_t n) { return STORE_KEYFRAME_HEADER + (size_t)n * (32 + 12); }

/* keyframes.bin's bytes into *out (malloc'd), its path into path. */
static bf_status keyframes_encode(const char *dir, const store_keyframes *k, char path[4200], uint8_t **out,
                                  size_t *out_bytes)
{
    if (!dir || !k) return bf_fail(BF_INVALID_ARG, "store_keyframes_write: no folder or keyframes");
    snprintf(path, 4200, "%s/%s", dir, STORE_KEYFRAMES_NAME);
    if (k->n > STORE_MAX_KEYFRAMES || (k->n && !k->kf))
        return bf_fail(BF_INVALID_ARG, "%s: %u keyframes, at most %u", path, k->n, STORE_MAX_KEYFRAMES);
    size_t bytes = STORE_KEYFRAMES_HEADER + 8;
    for (uint32_t i = 0; i < k->n; i++) {
        const store_keyframe *f = &k->kf[i];
        bool ok = f->n <= STORE_MAX_KEYPOINTS && (!f->n || (f->desc && f->xyz)) && bf_se3_is_finite(&f->T_wc);
        for (uint32_t j = 0; ok && j < 3 * f->n; j++) ok = isfinite(f->xyz[j]);
        if (!ok)
            return bf_fail(BF_INVALID_ARG, "%s: keyframe %u: %u keypoints (at most %u), or a pose or point not finite",
                           path, i, f->n, STORE_MAX_KEYPOINTS);
        bytes += keyframe_bytes(f->n);
    }
    uint8_t *buf = bf_malloc(bytes), *p = buf;
    if (!buf) return bf_fail(BF_NO_MEMORY, "%s: %u keyframes (%zu bytes)", path, k->n, bytes);
    uint32_t version = STORE_VERSION;
    memcpy(p, STORE_KEYFRAMES_MAGIC, 8), memcpy(p + 8, &version, 4), memcpy(p + 12, &k->n, 4);
    p += STORE_KEYFRAMES_HEADER;
    for (uint32_t i = 0; i < k->n; i++) {
        const store_keyframe *f = &k->kf[i];
        double d[12];
        for (int j = 0; j < 9; j++) d[j] = f->T_wc.R[j / 3][j % 3];
        d[9] = f->T_wc.t.x, d[10] = f->T_wc.t.y, d[11] = f->T_wc.t.z;
        uint32_t zero = 0;
        memcpy(p, d, sizeof d), memcpy(p + 96, &f->n, 4), memcpy(p + 100, &zero, 4);
        p += STORE_KEYFRAME_HEADER;
        if (f->n) memcpy(p, f->desc, (size_t)f->n * 32), memcpy(p + (size_t)f->n * 32, f->xyz, (size_t)f->n * 12);
        p += (size_t)f->n * 44;
    }
    uint64_t h = store__hash(buf, bytes - 8);
    memcpy(p, &h, 8);
    *out = buf;
    *out_bytes = bytes;
    return BF_OK;
}

bf_status store_keyframes_write(const char *dir, const store_keyframes *k)
{
    char path[4200];
    uint8_t *buf = NULL;
    size_t bytes = 0;
    bf_status s = keyframes_encode(dir, k, path, &buf, &bytes);
    if (s == BF_OK) s = store__write_atomic(path, buf, bytes, NULL, 0);
    free(buf);
    return s == BF_OK ? bf_sync_dir(dir) : s;
}

bf_status store__keyframes_stage(store_stage *stage, const char *dir, const store_keyframes *k)
{
    char path[4200];
    uint8_t *buf = NULL;
    size_t bytes = 0;
    bf_status s = keyframes_encode(dir, k, path, &buf, &bytes);
    if (s == BF_OK) s = store__write_staged(stage, path, buf, bytes, NULL, 0);
    free(buf);
    return s;
}

/* Keyframe i of the file at *at (len bytes left): its arrays copied. */
static bf_status parse_keyframe(const char *path, uint32_t i, const uint8_t *p, size_t left, store_keyframe *f,
                                size_t *used)
{
    if (left < STORE_KEYFRAME_HEADER) return bf_fail(BF_FORMAT, "%s: keyframe %u is cut short (truncated?)", path, i);
    double d[12];
    uint32_t n;
    memcpy(d, p, sizeof d), memcpy(&n, p + 96, 4);
    for (int j = 0; j < 9; j++) f->T_wc.R[j / 3][j % 3] = d[j];
    f->T_wc.t = (bf_vec3){d[9], d[10], d[11]};
    if (!bf_se3_is_finite(&f->T_wc) || n > STORE_MAX_KEYPOINTS)
        return bf_fail(BF_FORMAT, "%s: keyframe %u: a pose not finite or %u keypoints", path, i, n);
    if (left < keyframe_bytes(n))
        return bf_fail(BF_FORMAT, "%s: keyframe %u: %u keypoints need %zu bytes, %zu left (truncated?)", path, i, n,
                       keyframe_bytes(n), left);
    f->n = n;
    f->desc = n ? bf_malloc((size_t)n * 32) : NULL;
    f->xyz = n ? bf_malloc((size_t)n * 12) : NULL;
    if (n && (!f->desc || !f->xyz)) return bf_fail(BF_NO_MEMORY, "%s: keyframe %u: %u keypoints", path, i, n);
    if (n) memcpy(f->desc, p + STORE_KEYFRAME_HEADER, (size_t)n * 32);
    if (n) memcpy(f->xyz, p + STORE_KEYFRAME_HEADER + (size_t)n * 32, (size_t)n * 12);
    for (uint32_t j = 0; j < 3 * n; j++)
        if (!isfinite(f->xyz[j])) return bf_fail(BF_FORMAT, "%s: keyframe %u: a point not finite", path, i);
    *used = keyframe_bytes(n);
    return BF_OK;
}

bf_status store_keyframes_read(const char *dir, store_keyframes *out)
{
    if (!dir || !out) return bf_fail(BF_INVALID_ARG, "store_keyframes_read: no folder or output");
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", dir, STORE_KEYFRAMES_NAME);
    struct stat st;
    if (stat(path, &st) != 0 && errno == ENOENT) { /* none kept: the trajectory's poses are the keyframes */
        memset(out, 0, sizeof *out);
        return BF_OK;
    }
    uint8_t *p = NULL;
    size_t len = 0;
    uint32_t n = 0;
    size_t max = STORE_KEYFRAMES_HEADER + 8 + (size_t)STORE_MAX_KEYFRAMES * keyframe_bytes(STORE_MAX_KEYPOINTS);
    bf_status s = store__read_binary(path, STORE_KEYFRAMES_MAGIC, "keyframes file", max, &p, &len, &n);
    if (s != BF_OK) return s;
    if (n > STORE_MAX_KEYFRAMES) s = bf_fail(BF_FORMAT, "%s: %u keyframes, more than %u", path, n, STORE_MAX_KEYFRAMES);
    store_keyframes k = {0};
    if (s == BF_OK && n) {
        k.kf = bf_calloc(n, sizeof *k.kf);
        if (!k.kf) s = bf_fail(BF_NO_MEMORY, "%s: %u keyframes", path, n);
    }
    size_t at = STORE_KEYFRAMES_HEADER, end = len - 8;
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        size_t used = 0;
        k.n = i + 1; /* what store_keyframes_free must free */
        s = parse_keyframe(path, i, p + at, end - at, &k.kf[i], &used);
        at += used;
    }
    if (s == BF_OK && at != end)
        s = bf_fail(BF_FORMAT, "%s: %zu bytes after the last keyframe", path, end - at);
    free(p);
    if (s != BF_OK) {
        store_keyframes_free(&k);
        return s;
    }
    k.n = n;
    *out = k;
    return BF_OK;
}
