/* The store's reader: the index, the trajectory, every chunk file that
 * checks out; a bad file is reported by name and skipped. */
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <cjson/cJSON.h>
#include <zstd.h>

#include "store_int.h"

/* A chunk file larger than this is not one of ours (a full 2 m chunk at
 * level 8 would hold far fewer bricks than 2^24). */
#define STORE_MAX_CHUNK_BRICKS (1u << 24)
#define STORE_MAX_POSES (1u << 28)
/* The most a zstd payload can expand: a block decodes to at most 128 KiB
 * and takes at least 4 bytes (an RLE block, RFC 8878 section 3.1.1.2), so
 * n bytes decode to at most 32768 n. A header claiming more is refused
 * before its buffer is allocated (a forged 100-byte file asked for 19 GiB). */
#define STORE_ZSTD_MAX_RATIO 32768u

int store__entry_cmp(const void *pa, const void *pb)
{
    const store_entry *a = pa, *b = pb;
    for (int i = 0; i < 3; i++)
        if (a->key[i] != b->key[i]) return a->key[i] < b->key[i] ? -1 : 1;
    return 0;
}

static bool is_file(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

static bool is_dir(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

bool store_exists(const char *dir)
{
    char p[4200];
    if (!dir) return false;
    snprintf(p, sizeof p, "%s/%s", dir, STORE_INDEX_NAME);
    if (is_file(p)) return true;
    snprintf(p, sizeof p, "%s/%s", dir, STORE_CHUNK_DIR);
    return is_dir(p);
}

static bool parse_chunk_name(const char *name, int32_t key[3]);

bool store_is_written(const char *dir)
{
    char p[4200];
    if (!dir) return false;
    snprintf(p, sizeof p, "%s/%s", dir, STORE_INDEX_NAME);
    FILE *f = fopen(p, "rb");
    if (f) {
        char head[512];
        size_t n = fread(head, 1, sizeof head - 1, f);
        fclose(f);
        head[n] = '\0';
        if (strstr(head, "\"" STORE_FORMAT_NAME "\"")) return true;
    }
    snprintf(p, sizeof p, "%s/%s", dir, STORE_CHUNK_DIR);
    DIR *d = opendir(p);
    bool found = false;
    int32_t key[3];
    for (struct dirent *e; d && !found && (e = readdir(d));) found = parse_chunk_name(e->d_name, key);
    if (d) closedir(d);
    return found;
}

/* store_int.h. */
bf_status store__read_file(const char *path, size_t max, uint8_t **out, size_t *n)
{
    FILE *f = fopen(path, "rb");
    if (!f) return bf_fail(BF_IO, "%s: cannot open: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode)) {
        fclose(f);
        return bf_fail(BF_IO, "%s: not a regular file", path);
    }
    if ((uint64_t)st.st_size > max) {
        fclose(f);
        return bf_fail(BF_FORMAT, "%s: %lld bytes, more than a store file may hold", path, (long long)st.st_size);
    }
    size_t len = (size_t)st.st_size;
    uint8_t *p = bf_malloc(len + 1);
    if (!p) {
        fclose(f);
        return bf_fail(BF_NO_MEMORY, "%s: %zu bytes", path, len);
    }
    size_t got = fread(p, 1, len, f);
    bool bad = ferror(f);
    fclose(f);
    if (bad || got != len) {
        free(p);
        return bf_fail(BF_IO, "%s: read failed", path);
    }
    p[len] = 0;
    *out = p;
    *n = len;
    return BF_OK;
}

/* ------------------------------------------------------------ index */

static bool json_doubles(const cJSON *a, double *v, int n)
{
    if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != n) return false;
    for (int i = 0; i < n; i++) {
        const cJSON *x = cJSON_GetArrayItem(a, i);
        if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble)) return false;
        v[i] = x->valuedouble;
    }
    return true;
}

static bool json_count(const cJSON *o, const char *name, double max, double *out)
{
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
    if (!cJSON_IsNumber(x) || !(x->valuedouble >= 0 && x->valuedouble <= max) || x->valuedouble != floor(x->valuedouble))
        return false;
    *out = x->valuedouble;
    return true;
}

static bf_status parse_index(const char *path, const cJSON *root, store_meta *meta, store_entry **e_out, uint32_t *n_out,
                             uint32_t *flush)
{
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(root, "format");
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, STORE_FORMAT_NAME) != 0)
        return bf_fail(BF_FORMAT, "%s: not a bitfuse store index (no \"format\": \"%s\")", path, STORE_FORMAT_NAME);
    double v, fl = 0, frames, level, chunk_m;
    if (!json_count(root, "version", 1e9, &v)) return bf_fail(BF_FORMAT, "%s: no version", path);
    if (v > STORE_VERSION)
        return bf_fail(BF_UNSUPPORTED, "%s: store version %.0f; this bitfuse reads version %u and older", path, v,
                       STORE_VERSION);
    json_count(root, "flush", 4e9, &fl);
    const cJSON *cm = cJSON_GetObjectItemCaseSensitive(root, "chunk_m");
    chunk_m = cJSON_IsNumber(cm) ? cm->valuedouble : NAN;
    double o[3];
    if (!(chunk_m > 0 && chunk_m < 1e6) || !json_count(root, "max_level", 8, &level) ||
        !json_doubles(cJSON_GetObjectItemCaseSensitive(root, "origin_w"), o, 3) ||
        !json_count(root, "frames", 4e9, &frames))
        return bf_fail(BF_FORMAT, "%s: chunk_m, max_level (0-8), origin_w or frames missing or out of range", path);
    store_meta m = {.chunk_m = (float)chunk_m, .max_level = (uint32_t)level, .origin_w = {o[0], o[1], o[2]},
                    .frames = (uint32_t)frames};
    const cJSON *p = cJSON_GetObjectItemCaseSensitive(root, "last_pose");
    if (p) {
        double R[9], t[3];
        const cJSON *ts = cJSON_GetObjectItemCaseSensitive(p, "t_s");
        if (!cJSON_IsNumber(ts) || !json_doubles(cJSON_GetObjectItemCaseSensitive(p, "R"), R, 9) ||
            !json_doubles(cJSON_GetObjectItemCaseSensitive(p, "t"), t, 3))
            return bf_fail(BF_FORMAT, "%s: last_pose needs t_s, R (9 numbers) and t (3)", path);
        m.has_pose = true;
        m.last_t_s = ts->valuedouble;
        for (int i = 0; i < 9; i++) m.last_pose.R[i / 3][i % 3] = R[i];
        m.last_pose.t = (bf_vec3){t[0], t[1], t[2]};
        /* cJSON reads 1e999 as inf: a resume from that time would take every
         * frame as stored already. */
        if (!isfinite(m.last_t_s)) return bf_fail(BF_FORMAT, "%s: last_pose.t_s: not finite", path);
        if (!bf_se3_is_rigid(&m.last_pose, 1e-6)) return bf_fail(BF_FORMAT, "%s: last_pose.R: not a rotation", path);
    }
    const cJSON *chunks = cJSON_GetObjectItemCaseSensitive(root, "chunks");
    if (!cJSON_IsArray(chunks)) return bf_fail(BF_FORMAT, "%s: no chunks list", path);
    int n = cJSON_GetArraySize(chunks);
    store_entry *e = n ? bf_calloc((size_t)n, sizeof *e) : NULL;
    if (n && !e) return bf_fail(BF_NO_MEMORY, "%s: %d chunks", path, n);
    for (int i = 0; i < n; i++) {
        const cJSON *c = cJSON_GetArrayItem(chunks, i), *h = cJSON_GetObjectItemCaseSensitive(c, "xxh3");
        double k[3], b, bytes;
        char *end = NULL;
        bool ok = json_doubles(cJSON_GetObjectItemCaseSensitive(c, "key"), k, 3) &&
                  json_count(c, "bricks", STORE_MAX_CHUNK_BRICKS, &b) && json_count(c, "bytes", 1e15, &bytes) &&
                  cJSON_IsString(h) && strlen(h->valuestring) == 16;
        if (ok) e[i].digest = strtoull(h->valuestring, &end, 16);
        for (int a = 0; ok && a < 3; a++) ok = k[a] == floor(k[a]) && fabs(k[a]) < 2147483648.0;
        if (!ok || !end || *end) {
            free(e);
            return bf_fail(BF_FORMAT, "%s: chunk entry %d is malformed", path, i);
        }
        for (int a = 0; a < 3; a++) e[i].key[a] = (int32_t)k[a];
        e[i].n_bricks = (uint32_t)b;
        e[i].file_bytes = (uint64_t)bytes;
    }
    if (n) qsort(e, (size_t)n, sizeof *e, store__entry_cmp);
    for (int i = 1; i < n; i++)
        if (!store__entry_cmp(&e[i - 1], &e[i])) {
            int32_t k[3] = {e[i].key[0], e[i].key[1], e[i].key[2]};
            free(e);
            return bf_fail(BF_FORMAT, "%s: chunk (%d,%d,%d) listed twice", path, k[0], k[1], k[2]);
        }
    *meta = m;
    *e_out = e;
    *n_out = (uint32_t)n;
    *flush = (uint32_t)fl;
    return BF_OK;
}

bf_status store__index_read(const char *dir, store_meta *meta, store_entry **e, uint32_t *n, uint32_t *flush)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", dir, STORE_INDEX_NAME);
    uint8_t *text = NULL;
    size_t len = 0;
    bf_status s = store__read_file(path, 1u << 30, &text, &len);
    if (s != BF_OK) return s;
    const char *end = NULL;
    cJSON *root = cJSON_ParseWithLengthOpts((const char *)text, len, &end, false);
    size_t tail = root ? bf_trailing_text((const char *)text, len, end) : len;
    free(text);
    if (root && tail < len) {
        cJSON_Delete(root);
        return bf_fail(BF_FORMAT, "%s: text after the JSON value at byte %zu", path, tail);
    }
    if (!root) return bf_fail(BF_FORMAT, "%s: not valid JSON", path);
    s = parse_index(path, root, meta, e, n, flush);
    cJSON_Delete(root);
    return s;
}

/* ------------------------------------------------------------ trajectory */

bf_status store__read_binary(const char *path, const char *magic, const char *what, size_t max, uint8_t **out,
                             size_t *len, uint32_t *count)
{
    uint8_t *p = NULL;
    size_t n = 0;
    bf_status s = store__read_file(path, max, &p, &n);
    if (s != BF_OK) return s;
    uint32_t v = 0, c = 0;
    if (n >= 16) memcpy(&v, p + 8, 4), memcpy(&c, p + 12, 4);
    uint64_t h = 0;
    if (n < 16 + 8 || memcmp(p, magic, 8) != 0)
        s = bf_fail(BF_FORMAT, "%s: not a bitfuse %s (%zu bytes)", path, what, n);
    else if (v > STORE_VERSION)
        s = bf_fail(BF_UNSUPPORTED, "%s: version %u; this bitfuse reads version %u and older", path, v, STORE_VERSION);
    else if (memcpy(&h, p + n - 8, 8), h != store__hash(p, n - 8))
        s = bf_fail(BF_FORMAT, "%s: checksum mismatch (corrupt or truncated)", path);
    if (s != BF_OK) {
        free(p);
        return s;
    }
    *out = p, *len = n, *count = c;
    return BF_OK;
}

static bf_status read_traj(const char *dir, bf_traj *out)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", dir, STORE_TRAJ_NAME);
    uint8_t *p = NULL;
    size_t len = 0;
    uint32_t n = 0;
    bf_status s = store__read_binary(path, STORE_TRAJ_MAGIC, "trajectory",
                                     (size_t)STORE_TRAJ_HEADER + (size_t)STORE_MAX_POSES * 104 + 8, &p, &len, &n);
    if (s != BF_OK) return s;
    if (len != STORE_TRAJ_HEADER + (size_t)n * STORE_TRAJ_POSE_DOUBLES * 8 + 8)
        s = bf_fail(BF_FORMAT, "%s: %zu bytes where %u poses need %zu", path, len, n,
                    STORE_TRAJ_HEADER + (size_t)n * STORE_TRAJ_POSE_DOUBLES * 8 + 8);
    bf_traj t = {0};
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        double d[STORE_TRAJ_POSE_DOUBLES];
        memcpy(d, p + STORE_TRAJ_HEADER + (size_t)i * sizeof d, sizeof d);
        bf_se3 T;
        for (int k = 0; k < 9; k++) T.R[k / 3][k % 3] = d[1 + k];
        T.t = (bf_vec3){d[10], d[11], d[12]};
        if (!isfinite(d[0]) || !bf_se3_is_finite(&T) || (i && !(d[0] > t.t_s[i - 1])))
            s = bf_fail(BF_FORMAT, "%s: pose %u is not finite or its time does not increase", path, i);
        else
            s = bf_traj_push(&t, d[0], &T);
    }
    free(p);
    if (s != BF_OK) {
        bf_traj_free(&t);
        return s;
    }
    *out = t;
    return BF_OK;
}

/* ------------------------------------------------------------ chunks */

/* Parses "c_X_Y_Z.bfc". */
static bool parse_chunk_name(const char *name, int32_t key[3])
{
    long k[3];
    int used = 0;
    if (sscanf(name, "c_%ld_%ld_%ld.bfc%n", &k[0], &k[1], &k[2], &used) != 3 || name[used] != 0) return false;
    for (int i = 0; i < 3; i++) {
        if (k[i] < INT32_MIN || k[i] > INT32_MAX) return false;
        key[i] = (int32_t)k[i];
    }
    char canon[96];
    store__chunk_name(canon, sizeof canon, key);
    return strcmp(canon, name) == 0;
}

/* The bricks read so far. */
typedef struct brick_list {
    hostmap_brick *b;
    uint16_t *rgb;  /* cap * 512 colours once a chunk had colour, else NULL */
    uint32_t n, cap;
} brick_list;

/* Colour for the list's bricks from now on (earlier ones have none). */
static bf_status list_colour(brick_list *l)
{
    if (l->rgb) return BF_OK;
    l->rgb = bf_calloc((size_t)(l->cap ? l->cap : 1) * 512, 2);
    return l->rgb ? BF_OK : bf_fail(BF_NO_MEMORY, "store: colour of %u bricks", l->cap);
}

static bf_status list_grow(brick_list *l, uint32_t more)
{
    if ((uint64_t)l->n + more > UINT32_MAX) return bf_fail(BF_FORMAT, "store: more than 2^32 bricks");
    if (l->n + more <= l->cap) return BF_OK;
    uint32_t cap = l->cap ? l->cap : 1024;
    while (cap < l->n + more) cap = cap > UINT32_MAX / 2 ? UINT32_MAX : cap * 2;
    hostmap_brick *b = bf_realloc(l->b, (size_t)cap * sizeof *b);
    if (!b) return bf_fail(BF_NO_MEMORY, "store: %u bricks", cap);
    l->b = b;
    if (l->rgb) {
        uint16_t *c = bf_realloc(l->rgb, (size_t)cap * 1024);
        if (!c) return bf_fail(BF_NO_MEMORY, "store: colour of %u bricks", cap);
        memset(c + (size_t)l->cap * 512, 0, (size_t)(cap - l->cap) * 1024);
        l->rgb = c;
    }
    l->cap = cap;
    return BF_OK;
}

/* The geometry every chunk must share: from the index, else the first chunk. */
typedef struct geometry {
    bool known;
    float chunk_m;
    double origin[3];
    uint32_t max_level;
} geometry;

/* Reads one chunk file into l; BF_FORMAT (message naming the file) when it
 * does not check out, and then l is unchanged. */
static bf_status read_chunk(const char *path, const int32_t key[3], geometry *geo, brick_list *l, uint64_t *bytes,
                            uint64_t *raw)
{
    uint8_t *p = NULL, *rec = NULL;
    size_t len = 0;
    bf_status s = store__read_file(path,
                            (size_t)STORE_CHUNK_HEADER +
                                ZSTD_compressBound((size_t)STORE_MAX_CHUNK_BRICKS * STORE_COLOUR_RECORD_BYTES),
                            &p, &len);
    if (s != BF_OK) return s;
    store_chunk_header h;
    memset(&h, 0, sizeof h);
    if (len >= sizeof h) memcpy(&h, p, sizeof h);
    if (len < sizeof h || memcmp(h.magic, STORE_CHUNK_MAGIC, sizeof h.magic) != 0)
        s = bf_fail(BF_FORMAT, "%s: not a bitfuse chunk file (%zu bytes)", path, len);
    else if (h.header_hash != store__hash(&h, offsetof(store_chunk_header, header_hash)))
        s = bf_fail(BF_FORMAT, "%s: header checksum mismatch (corrupt)", path);
    else if (h.version > STORE_CHUNK_VERSION_COLOUR || h.header_bytes != STORE_CHUNK_HEADER ||
             !(h.record_bytes == STORE_RECORD_BYTES ||
               (h.version == STORE_CHUNK_VERSION_COLOUR && h.record_bytes == STORE_COLOUR_RECORD_BYTES)))
        s = bf_fail(BF_UNSUPPORTED, "%s: chunk version %u (header %u, record %u bytes); this bitfuse reads version %u",
                    path, h.version, h.header_bytes, h.record_bytes, STORE_CHUNK_VERSION_COLOUR);
    else if (h.key[0] != key[0] || h.key[1] != key[1] || h.key[2] != key[2])
        s = bf_fail(BF_FORMAT, "%s: holds chunk (%d,%d,%d)", path, h.key[0], h.key[1], h.key[2]);
    else if (h.n_bricks == 0 || h.n_bricks > STORE_MAX_CHUNK_BRICKS ||
             h.raw_bytes != (uint64_t)h.n_bricks * h.record_bytes)
        s = bf_fail(BF_FORMAT, "%s: %u bricks in %llu bytes", path, h.n_bricks, (unsigned long long)h.raw_bytes);
    else if (h.payload_bytes != len - sizeof h)
        s = bf_fail(BF_FORMAT, "%s: payload is %zu bytes, the header says %llu (truncated)", path, len - sizeof h,
                    (unsigned long long)h.payload_bytes);
    else if (h.payload_hash != store__hash(p + sizeof h, len - sizeof h))
        s = bf_fail(BF_FORMAT, "%s: payload checksum mismatch (corrupt)", path);
    else if (h.raw_bytes / STORE_ZSTD_MAX_RATIO > len - sizeof h ||
             ZSTD_getFrameContentSize(p + sizeof h, len - sizeof h) != h.raw_bytes)
        s = bf_fail(BF_FORMAT, "%s: %llu bytes of records cannot come from its %zu-byte payload (corrupt)", path,
                    (unsigned long long)h.raw_bytes, len - sizeof h);
    else if (geo->known && (h.chunk_m != geo->chunk_m || h.origin_w[0] != geo->origin[0] ||
                            h.origin_w[1] != geo->origin[1] || h.origin_w[2] != geo->origin[2]))
        s = bf_fail(BF_FORMAT, "%s: chunk edge %g m or origin differs from the store's (%g m)", path, h.chunk_m,
                    geo->chunk_m);
    else if (!(h.chunk_m > 0) || !isfinite(h.origin_w[0]) || !isfinite(h.origin_w[1]) || !isfinite(h.origin_w[2]))
        s = bf_fail(BF_FORMAT, "%s: chunk edge %g m or its origin is not valid", path, h.chunk_m);
    if (s == BF_OK && !(rec = bf_malloc(h.raw_bytes))) s = bf_fail(BF_NO_MEMORY, "%s: %u bricks", path, h.n_bricks);
    if (s == BF_OK) {
        size_t got = ZSTD_decompress(rec, h.raw_bytes, p + sizeof h, len - sizeof h);
        if (ZSTD_isError(got) || got != h.raw_bytes)
            s = bf_fail(BF_FORMAT, "%s: payload does not decompress to %llu bytes (%s)", path,
                        (unsigned long long)h.raw_bytes, ZSTD_isError(got) ? ZSTD_getErrorName(got) : "size");
    }
    uint32_t max_level = geo->known ? geo->max_level : 8;
    size_t rb = h.record_bytes;
    bool colour = rb == STORE_COLOUR_RECORD_BYTES;
    for (uint32_t i = 0; s == BF_OK && i < h.n_bricks; i++) {
        const uint8_t *r = rec + (size_t)i * rb;
        if (r[0] > max_level || r[1] >> r[0] || r[2] >> r[0] || r[3] >> r[0])
            s = bf_fail(BF_FORMAT, "%s: brick %u: cell (%u,%u,%u) outside level %u (max %u)", path, i, r[1], r[2], r[3],
                        r[0], max_level);
        else if (i && memcmp(r - rb, r, 4) == 0)
            s = bf_fail(BF_FORMAT, "%s: brick %u repeats a cell", path, i);
    }
    if (s == BF_OK) s = list_grow(l, h.n_bricks);
    if (s == BF_OK && colour) s = list_colour(l);
    for (uint32_t i = 0; s == BF_OK && i < h.n_bricks; i++) {
        const uint8_t *r = rec + (size_t)i * rb;
        if (colour) memcpy(l->rgb + (size_t)(l->n + i) * 512, r + STORE_RECORD_BYTES, 1024);
        hostmap_brick *b = &l->b[l->n + i];
        memcpy(b->key, key, sizeof b->key);
        b->level = r[0];
        b->cell[0] = r[1], b->cell[1] = r[2], b->cell[2] = r[3];
        memcpy(&b->error, r + 4, 4);
        memcpy(b->sign, r + 8, 64);
        memcpy(b->conf, r + 72, 64);
    }
    if (s == BF_OK) {
        l->n += h.n_bricks;
        *bytes += len;
        *raw += h.raw_bytes;
        if (!geo->known) {
            geo->known = true;
            geo->chunk_m = h.chunk_m;
            memcpy(geo->origin, h.origin_w, sizeof geo->origin);
            geo->max_level = 8;
        }
    }
    free(p);
    free(rec);
    return s;
}

bf_status store_get_chunk(const char *dir, const int32_t key[3], const store_meta *meta, hostmap *out, uint64_t *bytes)
{
    if (!dir || !key || !meta || !out) return bf_fail(BF_INVALID_ARG, "store_get_chunk: NULL argument");
    char name[96], path[4400];
    store__chunk_name(name, sizeof name, key);
    snprintf(path, sizeof path, "%s/%s/%s", dir, STORE_CHUNK_DIR, name);
    geometry geo = {true, meta->chunk_m, {meta->origin_w.x, meta->origin_w.y, meta->origin_w.z}, meta->max_level};
    brick_list l = {0};
    uint64_t b = 0, raw = 0;
    bf_status s = read_chunk(path, key, &geo, &l, &b, &raw);
    if (s != BF_OK) {
        free(l.b);
        free(l.rgb);
        return s;
    }
    out->chunk_m = meta->chunk_m;
    out->origin_w = meta->origin_w;
    out->n_bricks = l.n;
    out->bricks = l.b;
    out->rgb565 = l.rgb;
    if (bytes) *bytes = b;
    return BF_OK;
}

static int name_cmp(const void *a, const void *b) { return strcmp(*(char *const *)a, *(char *const *)b); }

/* The chunk files' names in dir/chunks, sorted (*names malloc'd). */
static bf_status list_chunks(const char *chunk_dir, char ***names, uint32_t *n)
{
    *names = NULL;
    *n = 0;
    DIR *d = opendir(chunk_dir);
    if (!d) return errno == ENOENT ? BF_OK : bf_fail(BF_IO, "%s: cannot list: %s", chunk_dir, strerror(errno));
    uint32_t cap = 0;
    bf_status s = BF_OK;
    struct dirent *de;
    while (s == BF_OK && (de = readdir(d))) {
        size_t len = strlen(de->d_name);
        if (len < 5 || strcmp(de->d_name + len - 4, ".bfc") != 0) continue; /* temp files and anything else */
        if (*n == cap) {
            cap = cap ? cap * 2 : 64;
            char **g = bf_realloc(*names, cap * sizeof *g);
            if (!g) {
                s = bf_fail(BF_NO_MEMORY, "%s: listing", chunk_dir);
                break;
            }
            *names = g;
        }
        if (!((*names)[*n] = strdup(de->d_name))) s = bf_fail(BF_NO_MEMORY, "%s: listing", chunk_dir);
        else (*n)++;
    }
    closedir(d);
    if (s == BF_OK && *n) qsort(*names, *n, sizeof **names, name_cmp);
    return s;
}

static void bad_file(store_report *rep)
{
    rep->n_bad++;
    if (!rep->first_bad[0]) snprintf(rep->first_bad, sizeof rep->first_bad, "%s", bf_last_error());
    bf_warn("store: %s: skipped", bf_last_error());
}

bf_status store_read(const char *dir, hostmap *map, store_meta *meta, bf_traj *traj, store_report *rep_out)
{
    if (!dir || !map || !meta) return bf_fail(BF_INVALID_ARG, "store_read: NULL argument");
    if (!is_dir(dir))
        return bf_fail(BF_IO, "%s: %s", dir,
                       bf_file_exists(dir) ? "a file, not a folder (a scene store is a folder)" : "no such folder");
    if (!store_exists(dir)) return bf_fail(BF_IO, "%s: not a scene store (no %s, no %s/)", dir, STORE_INDEX_NAME,
                                           STORE_CHUNK_DIR);
    store_report rep;
    memset(&rep, 0, sizeof rep);
    store_meta m;
    memset(&m, 0, sizeof m);
    store_entry *idx = NULL;
    uint32_t n_idx = 0;
    geometry geo = {0};
    char found[4200];
    rep.index_found = snprintf(found, sizeof found, "%s/%s", dir, STORE_INDEX_NAME) < (int)sizeof found &&
                      bf_file_exists(found);
    rep.trajectory_found = snprintf(found, sizeof found, "%s/%s", dir, STORE_TRAJ_NAME) < (int)sizeof found &&
                           bf_file_exists(found);
    rep.keyframes_found = snprintf(found, sizeof found, "%s/%s", dir, STORE_KEYFRAMES_NAME) < (int)sizeof found &&
                          bf_file_exists(found);
    bf_status s = store__index_read(dir, &m, &idx, &n_idx, &rep.flush);
    if (s == BF_UNSUPPORTED) return s;
    if (s == BF_OK) {
        rep.index_ok = true;
        geo = (geometry){true, m.chunk_m, {m.origin_w.x, m.origin_w.y, m.origin_w.z}, m.max_level};
    } else {
        bf_warn("store: %s: the chunk files and the trajectory are read without it", bf_last_error());
        memset(&m, 0, sizeof m);
        m.max_level = 8;
    }
    bf_traj t = {0};
    s = read_traj(dir, &t);
    if (s == BF_UNSUPPORTED) {
        free(idx);
        return s;
    }
    if (s == BF_OK) {
        rep.trajectory_ok = true;
        if (!rep.index_ok && t.n) { /* the last pose from the trajectory */
            m.frames = (uint32_t)t.n;
            m.has_pose = true;
            m.last_pose = t.T_wc[t.n - 1];
            m.last_t_s = t.t_s[t.n - 1];
        }
    } else {
        bf_warn("store: %s: the trajectory is lost; the map and the last pose are not", bf_last_error());
    }
    char chunk_dir[4200], path[4400];
    snprintf(chunk_dir, sizeof chunk_dir, "%s/%s", dir, STORE_CHUNK_DIR);
    char **names = NULL;
    uint32_t n_names = 0;
    brick_list l = {0};
    s = list_chunks(chunk_dir, &names, &n_names);
    bool *seen = s == BF_OK && n_idx ? calloc(n_idx, 1) : NULL;
    if (s == BF_OK && n_idx && !seen) s = bf_fail(BF_NO_MEMORY, "store: index");
    for (uint32_t i = 0; s == BF_OK && i < n_names; i++) {
        store_entry e = {0};
        snprintf(path, sizeof path, "%s/%s", chunk_dir, names[i]);
        if (!parse_chunk_name(names[i], e.key)) {
            bf_fail(BF_FORMAT, "%s: not a chunk file name (c_X_Y_Z.bfc)", path);
            bad_file(&rep);
            continue;
        }
        const store_entry *in = n_idx ? bsearch(&e, idx, n_idx, sizeof e, store__entry_cmp) : NULL;
        bf_status c = read_chunk(path, e.key, &geo, &l, &rep.bytes_files, &rep.bytes_raw);
        if (c == BF_NO_MEMORY) s = c;
        else if (c != BF_OK) bad_file(&rep);
        else rep.n_chunks++, rep.n_unindexed += !in;
        if (in && c == BF_OK) seen[in - idx] = true;
    }
    for (uint32_t i = 0; s == BF_OK && i < n_idx; i++)
        if (!seen[i]) {
            rep.n_missing++;
            store__chunk_name(path, sizeof path, idx[i].key);
            bf_warn("store: %s/%s: listed in the index, not loaded", chunk_dir, path);
        }
    for (uint32_t i = 0; i < n_names; i++) free(names[i]);
    free(names);
    free(seen);
    free(idx);
    /* A store whose writer never finished a write (killed at once) is an
     * empty store; one whose every file is bad is not a store any more. */
    if (s == BF_OK && !rep.index_ok && !rep.trajectory_ok && rep.n_chunks == 0 && rep.n_bad > 0)
        s = bf_fail(BF_FORMAT, "%s: nothing readable: no index, no trajectory, and every chunk file is bad (%s)", dir,
                    rep.first_bad);
    if (s == BF_OK && !rep.index_ok) {
        m.chunk_m = geo.known ? geo.chunk_m : 2.0f;
        m.origin_w = (bf_vec3){geo.origin[0], geo.origin[1], geo.origin[2]};
        /* The level the map was built with is in the index only: the
         * finest level its bricks hold is what the map is known to need. */
        m.max_level = 0;
        for (uint32_t i = 0; i < l.n; i++)
            if (l.b[i].level > m.max_level) m.max_level = l.b[i].level;
    }
    if (s != BF_OK) {
        free(l.b);
        free(l.rgb);
        bf_traj_free(&t);
        return s;
    }
    map->chunk_m = m.chunk_m;
    map->origin_w = m.origin_w;
    map->n_bricks = l.n;
    map->bricks = l.b;
    map->rgb565 = l.rgb;
    store__sort(map);
    rep.n_bricks = l.n;
    *meta = m;
    if (traj) {
        *traj = t;
    } else {
        bf_traj_free(&t);
    }
    if (rep_out) *rep_out = rep;
    return BF_OK;
}
