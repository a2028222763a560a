/* The scene store: exact round trips, rewriting only what changed, and a
 * store that always reopens after a corrupt file, a lost index or a write
 * that failed at any point (injected ENOSPC). */
#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "store/store.h"
#include "store/store_int.h"
#include "test.h"

static uint32_t rng_state = 12345u;
static uint32_t rnd(void)
{
    rng_state = rng_state * 1664525u + 1013904223u;
    return rng_state >> 8;
}

/* A map of n_chunks chunks (negative keys too), bricks at levels 3-8 with
 * random bits, in a scrambled order. */
static bf_status make_map(hostmap *m, uint32_t n_chunks, uint32_t per_chunk)
{
    memset(m, 0, sizeof *m);
    m->chunk_m = 2.0f;
    m->origin_w = (bf_vec3){1.25, -3.5, 1000.125};
    m->n_bricks = n_chunks * per_chunk;
    m->bricks = calloc(m->n_bricks, sizeof *m->bricks);
    if (!m->bricks) return BF_NO_MEMORY;
    for (uint32_t c = 0; c < n_chunks; c++)
        for (uint32_t i = 0; i < per_chunk; i++) {
            hostmap_brick *b = &m->bricks[c * per_chunk + i];
            b->key[0] = (int32_t)c - 2, b->key[1] = -(int32_t)(c % 3), b->key[2] = (int32_t)(c * 5);
            b->level = 3 + i % 6;
            /* distinct cells per level: i / 6 enumerates them */
            uint32_t k = i / 6;
            b->cell[0] = k % 8, b->cell[1] = (k / 8) % 8, b->cell[2] = (k / 64) % 8;
            b->error = 0.001f * (float)(rnd() % 1000);
            for (int w = 0; w < 16; w++) b->sign[w] = rnd() ^ (rnd() << 16), b->conf[w] = rnd() ^ (rnd() << 16);
        }
    for (uint32_t i = m->n_bricks; i > 1; i--) { /* scrambled, as a GPU's slots are */
        uint32_t j = rnd() % i;
        hostmap_brick t = m->bricks[i - 1];
        m->bricks[i - 1] = m->bricks[j];
        m->bricks[j] = t;
    }
    return BF_OK;
}

static bf_status copy_map(const hostmap *a, hostmap *b)
{
    *b = *a;
    b->rgb565 = NULL;
    b->bricks = malloc((size_t)a->n_bricks * sizeof *b->bricks + 1);
    if (!b->bricks) return BF_NO_MEMORY;
    memcpy(b->bricks, a->bricks, (size_t)a->n_bricks * sizeof *b->bricks);
    if (a->rgb565) {
        if (!(b->rgb565 = malloc((size_t)a->n_bricks * 1024 + 1))) return BF_NO_MEMORY;
        memcpy(b->rgb565, a->rgb565, (size_t)a->n_bricks * 1024);
    }
    return BF_OK;
}

static store_meta meta_of(const hostmap *m, uint32_t frames)
{
    store_meta meta = {.chunk_m = m->chunk_m, .max_level = 8, .origin_w = m->origin_w, .frames = frames};
    meta.has_pose = true;
    meta.last_pose = bf_se3_from_qt(bf_quat_from_axis_angle((bf_vec3){0.1, 0.7, -0.2}, 0.3), (bf_vec3){0.5, -1.0 / 3.0, 2.0});
    meta.last_t_s = 1305031102.175304;
    return meta;
}

static bf_status make_traj(bf_traj *t, uint32_t n)
{
    memset(t, 0, sizeof *t);
    for (uint32_t i = 0; i < n; i++) {
        bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle((bf_vec3){0, 1, 0}, 0.01 * i), (bf_vec3){0.001 * i, 1.0 / 3.0, -0.5});
        bf_status s = bf_traj_push(t, 1305031102.0 + i / 30.0, &T);
        if (s != BF_OK) return s;
    }
    return BF_OK;
}

static const char *fresh_dir(const char *name)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/%s", bf_test_tmpdir(), name);
    return path;
}

/* Writes m (a copy) with meta and traj into dir through a new writer. */
/* kf (may be NULL) is handed over with the map (taken). */
static bf_status write_store_kf(const char *dir, bool resume, const hostmap *m, const store_meta *meta,
                                const bf_traj *t, store_keyframes *kf, store_write_stats *st)
{
    store_writer *w = NULL;
    hostmap c;
    bf_status s = store_writer_open(dir, resume, &w);
    if (s != BF_OK) return s;
    if (kf) store_writer_keyframes(w, kf);
    if ((s = copy_map(m, &c)) == BF_OK) s = store_writer_submit(w, &c, meta, t);
    hostmap_free(&c);
    bf_status f = store_writer_finish(w);
    if (s == BF_OK) s = f;
    if (st) *st = store_writer_stats(w);
    store_writer_close(w);
    return s;
}

static bf_status write_store(const char *dir, bool resume, const hostmap *m, const store_meta *meta, const bf_traj *t,
                             store_write_stats *st)
{
    return write_store_kf(dir, resume, m, meta, t, NULL, st);
}

/* Same bricks in the same order, every field. */
static bool maps_equal(const hostmap *a, const hostmap *b)
{
    return a->n_bricks == b->n_bricks && a->chunk_m == b->chunk_m && a->origin_w.x == b->origin_w.x &&
           a->origin_w.y == b->origin_w.y && a->origin_w.z == b->origin_w.z &&
           (a->n_bricks == 0 || memcmp(a->bricks, b->bricks, (size_t)a->n_bricks * sizeof *a->bricks) == 0);
}

/* The canonical order of a: the reader's own (digest-equal maps read back in it). */
static bf_status sorted_copy(const hostmap *a, const char *dir, hostmap *out)
{
    store_meta meta = meta_of(a, 1);
    bf_status s = write_store(dir, false, a, &meta, NULL, NULL);
    store_meta m2;
    if (s == BF_OK) s = store_read(dir, out, &m2, NULL, NULL);
    return s;
}

BF_TEST(store_round_trip_is_exact)
{
    hostmap m, back = {0};
    bf_traj t, t2 = {0};
    CHECK_OK(make_map(&m, 7, 50));
    CHECK_OK(make_traj(&t, 40));
    store_meta meta = meta_of(&m, 40), meta2;
    const char *dir = fresh_dir("round");
    store_write_stats st;
    CHECK_OK(write_store(dir, false, &m, &meta, &t, &st));
    CHECK_EQ_INT(st.chunks, 7);
    CHECK_EQ_INT(st.chunks_written, 7);
    CHECK_EQ_INT(st.bricks, 350);
    store_report rep;
    CHECK_OK(store_read(dir, &back, &meta2, &t2, &rep));
    CHECK(rep.index_ok && rep.trajectory_ok);
    CHECK_EQ_INT(rep.n_chunks, 7);
    CHECK_EQ_INT(rep.n_bad + rep.n_missing + rep.n_unindexed, 0);
    CHECK_EQ_INT(back.n_bricks, 350);
    uint64_t d1, d2;
    CHECK_OK(store_map_digest(&m, &d1));
    CHECK_OK(store_map_digest(&back, &d2));
    CHECK(d1 == d2);
    CHECK(memcmp(&meta, &meta2, sizeof meta) == 0 || (meta2.frames == 40 && meta2.has_pose &&
                                                      memcmp(&meta.last_pose, &meta2.last_pose, sizeof meta.last_pose) == 0 &&
                                                      meta.last_t_s == meta2.last_t_s));
    CHECK(meta2.chunk_m == 2.0f && meta2.max_level == 8 && meta2.origin_w.z == 1000.125);
    CHECK_EQ_INT(t2.n, 40);
    CHECK(memcmp(t.t_s, t2.t_s, 40 * sizeof(double)) == 0);
    CHECK(memcmp(t.T_wc, t2.T_wc, 40 * sizeof(bf_se3)) == 0);
    /* Every brick of m is in back, bit for bit: back is m sorted. */
    hostmap sorted = {0};
    CHECK_OK(sorted_copy(&back, fresh_dir("round2"), &sorted));
    CHECK(maps_equal(&back, &sorted));
    /* A digest sees one flipped bit. */
    back.bricks[123].conf[5] ^= 1u << 17;
    CHECK_OK(store_map_digest(&back, &d2));
    CHECK(d1 != d2);
    hostmap_free(&m);
    hostmap_free(&back);
    hostmap_free(&sorted);
    bf_traj_free(&t);
    bf_traj_free(&t2);
}

/* Colour travels with its brick: chunks with a coloured voxel are written
 * as version 2 (colour records), the others stay version 1; reading gives
 * every brick its own colour back in the reader's order, and colour-free
 * chunks none. */
BF_TEST(store_keeps_colour_with_its_bricks)
{
    hostmap m, back = {0};
    CHECK_OK(make_map(&m, 5, 40));
    m.rgb565 = calloc((size_t)m.n_bricks * 512, 2);
    CHECK(m.rgb565 != NULL);
    /* Colour only in the chunks with key x in {-2, 0}: value from the brick's identity, so it can be checked. */
    for (uint32_t i = 0; i < m.n_bricks; i++) {
        const hostmap_brick *b = &m.bricks[i];
        if (b->key[0] != -2 && b->key[0] != 0) continue;
        for (uint32_t v = 0; v < 512; v += 3)
            m.rgb565[(size_t)i * 512 + v] = (uint16_t)(1 + (v ^ (b->level * 977u + b->cell[0] * 31u + b->cell[1] * 7u +
                                                                  b->cell[2] + (uint32_t)(b->key[0] + 5) * 4099u)));
    }
    store_meta meta = meta_of(&m, 1), meta2;
    const char *dir = fresh_dir("colour");
    CHECK_OK(write_store(dir, false, &m, &meta, NULL, NULL));
    CHECK_OK(store_read(dir, &back, &meta2, NULL, NULL));
    CHECK_EQ_INT(back.n_bricks, m.n_bricks);
    CHECK(back.rgb565 != NULL);
    uint32_t n_coloured = 0;
    for (uint32_t i = 0; i < back.n_bricks; i++) {
        const hostmap_brick *b = &back.bricks[i];
        bool has = b->key[0] == -2 || b->key[0] == 0;
        for (uint32_t v = 0; v < 512; v++) {
            uint16_t want = has && v % 3 == 0 ? (uint16_t)(1 + (v ^ (b->level * 977u + b->cell[0] * 31u + b->cell[1] * 7u +
                                                                    b->cell[2] + (uint32_t)(b->key[0] + 5) * 4099u)))
                                              : 0;
            CHECK_EQ_INT(back.rgb565[(size_t)i * 512 + v], want);
            n_coloured += want != 0;
        }
    }
    CHECK(n_coloured > 0);
    /* Colour changes a chunk's digest (it is rewritten), not the geometry's. */
    uint64_t d1, d2;
    CHECK_OK(store_map_digest(&m, &d1));
    CHECK_OK(store_map_digest(&back, &d2));
    CHECK(d1 == d2);
    hostmap_free(&m);
    hostmap_free(&back);
}

static uint32_t count_files(const char *dir, const char *suffix)
{
    DIR *d = opendir(dir);
    uint32_t n = 0;
    struct dirent *e;
    while (d && (e = readdir(d))) {
        size_t l = strlen(e->d_name), k = strlen(suffix);
        n += l >= k && strcmp(e->d_name + l - k, suffix) == 0;
    }
    if (d) closedir(d);
    return n;
}

BF_TEST(store_rewrites_only_changed_chunks)
{
    hostmap m, back = {0};
    CHECK_OK(make_map(&m, 6, 30));
    store_meta meta = meta_of(&m, 10), meta2;
    const char *dir = fresh_dir("incremental");
    store_writer *w = NULL;
    CHECK_OK(store_writer_open(dir, false, &w));
    hostmap c;
    CHECK_OK(copy_map(&m, &c));
    CHECK_OK(store_writer_submit(w, &c, &meta, NULL));
    CHECK(c.bricks == NULL); /* taken */
    /* One brick of one chunk changes; every brick of another goes away. */
    m.bricks[17].sign[3] ^= 0xF0F0u;
    int32_t gone[3];
    memcpy(gone, m.bricks[40].key, sizeof gone);
    uint32_t k = 0;
    for (uint32_t i = 0; i < m.n_bricks; i++)
        if (memcmp(m.bricks[i].key, gone, sizeof gone) != 0 ||
            memcmp(m.bricks[17].key, gone, sizeof gone) == 0) /* (never the changed one's chunk) */
            m.bricks[k++] = m.bricks[i];
    m.n_bricks = k;
    CHECK_OK(copy_map(&m, &c));
    CHECK_OK(store_writer_submit(w, &c, &meta, NULL));
    CHECK_OK(store_writer_finish(w));
    store_write_stats st = store_writer_stats(w);
    store_writer_close(w);
    CHECK_EQ_INT(st.writes, 2);
    CHECK_EQ_INT(st.chunks_written, 6 + 1);
    CHECK_EQ_INT(st.chunks_removed, 1);
    CHECK_EQ_INT(st.chunks, 5);
    char cd[600];
    snprintf(cd, sizeof cd, "%s/chunks", dir);
    CHECK_EQ_INT(count_files(cd, ".bfc"), 5);
    CHECK_EQ_INT(count_files(cd, ".tmp"), 0);
    CHECK_OK(store_read(dir, &back, &meta2, NULL, NULL));
    uint64_t d1, d2;
    CHECK_OK(store_map_digest(&m, &d1));
    CHECK_OK(store_map_digest(&back, &d2));
    CHECK(d1 == d2);
    /* A resumed writer knows the digests: the same map rewrites nothing. */
    CHECK_OK(write_store(dir, true, &m, &meta, NULL, &st));
    CHECK_EQ_INT(st.chunks_written, 0);
    /* Neither a new store over an old one nor a resume of nothing. */
    CHECK_STATUS(store_writer_open(dir, false, &w), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("--resume");
    CHECK_STATUS(store_writer_open(fresh_dir("nothing-here"), true, &w), BF_IO);
    hostmap_free(&m);
    hostmap_free(&back);
}

static bf_status flip_byte(const char *path, long at)
{
    FILE *f = fopen(path, "r+b");
    if (!f) return BF_IO;
    fseek(f, at, at < 0 ? SEEK_END : SEEK_SET);
    int c = fgetc(f);
    fseek(f, -1, SEEK_CUR);
    fputc(c ^ 0x5A, f);
    fclose(f);
    return BF_OK;
}

BF_TEST(store_skips_a_bad_chunk_by_name_and_loads_the_rest)
{
    hostmap m, back = {0};
    CHECK_OK(make_map(&m, 5, 20));
    store_meta meta = meta_of(&m, 3), meta2;
    const char *dir = fresh_dir("corrupt");
    CHECK_OK(write_store(dir, false, &m, &meta, NULL, NULL));
    char bad[600], cut[600], tmp[600];
    snprintf(bad, sizeof bad, "%s/chunks/c_-2_0_0.bfc", dir);
    snprintf(cut, sizeof cut, "%s/chunks/c_0_-2_10.bfc", dir);
    CHECK_OK(flip_byte(bad, -3)); /* in the payload */
    struct stat sb;
    CHECK(stat(cut, &sb) == 0);
    CHECK(truncate(cut, sb.st_size - 10) == 0); /* a partly written file */
    snprintf(tmp, sizeof tmp, "%s/chunks/c_1_1_1.bfc.tmp", dir); /* a write that never finished */
    FILE *f = fopen(tmp, "wb");
    CHECK(f != NULL);
    fputs("BFCHUNK", f);
    fclose(f);
    store_report rep;
    CHECK_OK(store_read(dir, &back, &meta2, NULL, &rep));
    CHECK_EQ_INT(rep.n_bad, 2);
    CHECK_EQ_INT(rep.n_missing, 2);
    CHECK_EQ_INT(rep.n_chunks, 3);
    CHECK_EQ_INT(back.n_bricks, 60);
    CHECK(strstr(rep.first_bad, "c_") != NULL);
    CHECK(strstr(rep.first_bad, "checksum") != NULL || strstr(rep.first_bad, "truncated") != NULL);
    /* Every loaded brick is one of m's, unchanged. */
    for (uint32_t i = 0; i < back.n_bricks; i++) {
        bool found = false;
        for (uint32_t j = 0; j < m.n_bricks && !found; j++)
            found = memcmp(&back.bricks[i], &m.bricks[j], sizeof m.bricks[j]) == 0;
        CHECK(found);
    }
    /* A header flipped: named as corrupt too. */
    CHECK_OK(flip_byte(bad, 20));
    hostmap_free(&back);
    CHECK_OK(store_read(dir, &back, &meta2, NULL, &rep));
    CHECK_EQ_INT(rep.n_bad, 2);
    hostmap_free(&m);
    hostmap_free(&back);
}

BF_TEST(store_opens_without_its_index)
{
    hostmap m, back = {0};
    bf_traj t, t2 = {0};
    CHECK_OK(make_map(&m, 3, 10));
    CHECK_OK(make_traj(&t, 12));
    store_meta meta = meta_of(&m, 12), meta2;
    const char *dir = fresh_dir("noindex");
    CHECK_OK(write_store(dir, false, &m, &meta, &t, NULL));
    char p[600];
    snprintf(p, sizeof p, "%s/store.json", dir);
    /* An index whose last pose's time reads as inf (1e999: a resume would
     * take every frame as stored) or whose R is no rotation is no index:
     * the trajectory gives the pose. */
    for (int k = 0; k < 2; k++) {
        char *text = NULL;
        size_t len = 0;
        CHECK_OK(bf_read_file(p, &text, &len));
        /* The value after the key (the index is written with cJSON_Print). */
        char *at = text ? strstr(text, k ? "\"R\":" : "\"t_s\":") : NULL;
        CHECK(at != NULL);
        if (!at) break;
        at = strchr(at, ':') + 1;
        while (*at == ' ' || *at == '\t' || *at == '\n') at++;
        FILE *g = fopen(p, "w");
        CHECK(g != NULL);
        if (k == 0) { /* the time: 1e999 */
            char *end = at;
            while (*end && *end != ',' && *end != '}' && *end != '\n') end++;
            fprintf(g, "%.*s1e999%s", (int)(at - text), text, end);
        } else { /* R's first entry 2: no rotation */
            char *end = strchr(at, ',');
            fprintf(g, "%.*s[2%s", (int)(at - text), text, end ? end : "");
        }
        fclose(g);
        store_report r0;
        hostmap_free(&back);
        CHECK_OK(store_read(dir, &back, &meta2, NULL, &r0));
        CHECK(!r0.index_ok);
        CHECK(meta2.has_pose && isfinite(meta2.last_t_s));
        CHECK(memcmp(&meta2.last_pose, &t.T_wc[11], sizeof(bf_se3)) == 0);
        CHECK_OK(bf_write_file_atomic(p, text, len)); /* the index back for the next case */
        free(text);
    }
    hostmap_free(&back);
    FILE *f = fopen(p, "w");
    CHECK(f != NULL);
    fputs("{\"format\": \"bitfuse-st", f); /* cut short */
    fclose(f);
    store_report rep;
    CHECK_OK(store_read(dir, &back, &meta2, &t2, &rep));
    CHECK(!rep.index_ok && rep.trajectory_ok);
    CHECK_EQ_INT(back.n_bricks, 30);
    CHECK(meta2.has_pose && meta2.frames == 12);
    CHECK(memcmp(&meta2.last_pose, &t.T_wc[11], sizeof(bf_se3)) == 0);
    CHECK(meta2.origin_w.z == 1000.125 && meta2.chunk_m == 2.0f);
    /* The finest level comes from the bricks: make_map's reach level 8;
     * a map whose bricks stop at level 6 reads back as level 6. */
    CHECK_EQ_INT(meta2.max_level, 8);
    for (uint32_t i = 0; i < m.n_bricks; i++)
        if (m.bricks[i].level > 6) m.bricks[i].level = 6;
    CHECK_OK(hostmap_sort(&m)); /* cells may repeat now: keep one of each */
    uint32_t n = 0;
    for (uint32_t i = 0; i < m.n_bricks; i++)
        if (!n || memcmp(m.bricks[n - 1].key, m.bricks[i].key, sizeof m.bricks[i].key) ||
            m.bricks[n - 1].level != m.bricks[i].level || memcmp(m.bricks[n - 1].cell, m.bricks[i].cell, sizeof m.bricks[i].cell))
            m.bricks[n++] = m.bricks[i];
    m.n_bricks = n;
    const char *dir6 = fresh_dir("noindex6");
    meta.max_level = 6;
    CHECK_OK(write_store(dir6, false, &m, &meta, &t, NULL));
    snprintf(p, sizeof p, "%s/store.json", dir6);
    /* An index with text after it (a bad merge, two writes run together) is no index. */
    f = fopen(p, "a");
    CHECK(f != NULL);
    fputs("\n}{", f);
    fclose(f);
    hostmap_free(&back);
    CHECK_OK(store_read(dir6, &back, &meta2, NULL, &rep));
    CHECK(!rep.index_ok);
    CHECK(remove(p) == 0);
    hostmap_free(&back);
    CHECK_OK(store_read(dir6, &back, &meta2, NULL, &rep));
    CHECK(!rep.index_ok);
    CHECK_EQ_INT(meta2.max_level, 6);
    CHECK_EQ_INT(back.n_bricks, n);
    /* A newer version is refused, not misread. */
    f = fopen(p, "w");
    fputs("{\"format\": \"bitfuse-store\", \"version\": 99}", f);
    fclose(f);
    CHECK_STATUS(store_read(dir, &back, &meta2, NULL, &rep), BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("version 99");
    CHECK_STATUS(store_read(fresh_dir("absent"), &back, &meta2, NULL, &rep), BF_IO);
    hostmap_free(&m);
    hostmap_free(&back);
    bf_traj_free(&t);
    bf_traj_free(&t2);
}

/* A write that fails at any of its points (every write, fsync and
 * allocation in turn, ENOSPC for the file ones) is reported, leaves no
 * temp file, and the store reads as the write before it, chunk for chunk
 * and pose for pose: every new file is renamed only when all are whole (a
 * full disk part-way through replaced some chunk files before). */
static bf_status make_keyframes(store_keyframes *k, uint32_t n);

BF_TEST(store_survives_a_failed_write_at_every_point)
{
    hostmap a, b, back = {0};
    CHECK_OK(make_map(&a, 4, 12));
    CHECK_OK(copy_map(&a, &b));
    for (uint32_t i = 0; i < b.n_bricks; i++) b.bricks[i].sign[0] ^= 1u; /* every chunk changes */
    bf_traj ta, tb, t2 = {0};
    CHECK_OK(make_traj(&ta, 5));
    CHECK_OK(make_traj(&tb, 9));
    store_meta ma = meta_of(&a, 5), mb = meta_of(&b, 9), m2;
    char cd[600];
    uint32_t points = 0;
    for (uint32_t k = 1; k < 200; k++) {
        char name[64];
        snprintf(name, sizeof name, "enospc-%u", k);
        const char *dir = fresh_dir(name);
        snprintf(cd, sizeof cd, "%s/chunks", dir);
        CHECK_OK(write_store(dir, false, &a, &ma, &ta, NULL));
        store_keyframes kf;
        CHECK_OK(make_keyframes(&kf, 3)); /* keyframes.bin staged with the rest */
        bf_fault_arm(k);
        bf_status s = write_store_kf(dir, true, &b, &mb, &tb, &kf, NULL);
        bool fired = bf_fault_arm(0) == 0;
        store_keyframes_free(&kf);
        if (!fired) {
            CHECK_OK(s);
            points = k - 1;
            break;
        }
        /* A fault the writer recovers from (an unreadable index at resume: it rewrites every chunk) ends well. */
        if (s != BF_OK && s != BF_WRITE && s != BF_NO_MEMORY) {
            fprintf(stderr, "  fault %u: %s: %s\n", k, bf_status_name(s), bf_last_error());
            CHECK(false);
        }
        CHECK_EQ_INT(count_files(cd, ".tmp"), 0);
        CHECK_EQ_INT(count_files(dir, ".tmp"), 0);
        store_report rep;
        CHECK_OK(store_read(dir, &back, &m2, &t2, &rep));
        store_keyframes kb = {0};
        bf_status sk = store_keyframes_read(dir, &kb);
        CHECK_OK(sk); /* written with the map, or not at all (the first write had none) */
        CHECK_EQ_INT(kb.n, s == BF_OK ? 3 : 0);
        store_keyframes_free(&kb);
        CHECK_EQ_INT(rep.n_bad, 0);
        CHECK_EQ_INT(back.n_bricks, a.n_bricks);
        /* Failed: the old map and trajectory; recovered: the new ones. */
        const hostmap *want = s == BF_OK ? &b : &a;
        CHECK_EQ_INT(t2.n, s == BF_OK ? 9 : 5);
        CHECK_EQ_INT(m2.frames, s == BF_OK ? 9 : 5);
        for (uint32_t i = 0; i < back.n_bricks; i++) {
            bool found = false;
            for (uint32_t j = 0; j < want->n_bricks && !found; j++)
                found = !memcmp(&back.bricks[i], &want->bricks[j], sizeof want->bricks[j]);
            CHECK(found);
        }
        hostmap_free(&back);
        bf_traj_free(&t2);
    }
    /* 4 chunks (write and fsync each), the trajectory and the index, the allocations. */
    CHECK_LE(12, points);
    hostmap_free(&a);
    hostmap_free(&b);
    bf_traj_free(&ta);
    bf_traj_free(&tb);
}

/* One writer a store: a second one is refused while the first lives (also
 * in this process: the lock is the open folder's), taken once it is closed. */
BF_TEST(store_has_one_writer_at_a_time)
{
    hostmap a;
    CHECK_OK(make_map(&a, 2, 4));
    bf_traj t;
    CHECK_OK(make_traj(&t, 3));
    store_meta m = meta_of(&a, 3);
    const char *dir = fresh_dir("locked");
    CHECK_OK(write_store(dir, false, &a, &m, &t, NULL));
    store_writer *w1 = NULL, *w2 = NULL;
    CHECK_OK(store_writer_open(dir, true, &w1));
    CHECK_STATUS(store_writer_open(dir, true, &w2), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("another bitfuse is writing this store");
    CHECK(w2 == NULL);
    int fd = -1;
    CHECK_STATUS(store_lock(dir, &fd), BF_INVALID_ARG);
    CHECK_OK(store_writer_finish(w1));
    store_writer_close(w1);
    CHECK_OK(store_lock(dir, &fd)); /* released with the writer */
    CHECK_OK(store_writer_open_locked(dir, true, fd, &w2)); /* takes the caller's lock */
    CHECK_OK(store_writer_finish(w2));
    store_writer_close(w2);
    hostmap_free(&a);
    bf_traj_free(&t);
}

/* keyframes.bin: k keyframes of random poses and keypoints (keyframe 1 with
 * none: a keyframe without colour). */
static bf_status make_keyframes(store_keyframes *k, uint32_t n)
{
    memset(k, 0, sizeof *k);
    k->kf = calloc(n, sizeof *k->kf);
    if (!k->kf) return BF_NO_MEMORY;
    k->n = n;
    for (uint32_t i = 0; i < n; i++) {
        store_keyframe *f = &k->kf[i];
        f->T_wc = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.1 * i), bf_v3(0.1 * i, -0.2, 1.5));
        f->n = i == 1 ? 0 : 50 + 7 * i;
        if (!f->n) continue;
        f->desc = malloc((size_t)f->n * 32);
        f->xyz = malloc((size_t)f->n * 12);
        if (!f->desc || !f->xyz) return BF_NO_MEMORY;
        for (uint32_t j = 0; j < f->n * 32; j++) f->desc[j] = (uint8_t)rnd();
        for (uint32_t j = 0; j < f->n * 3; j++) f->xyz[j] = (float)(rnd() % 4000) * 1e-3f;
    }
    return BF_OK;
}

static bool keyframes_equal(const store_keyframes *a, const store_keyframes *b)
{
    if (a->n != b->n) return false;
    for (uint32_t i = 0; i < a->n; i++) {
        const store_keyframe *x = &a->kf[i], *y = &b->kf[i];
        if (memcmp(&x->T_wc, &y->T_wc, sizeof x->T_wc) || x->n != y->n) return false;
        if (x->n && (memcmp(x->desc, y->desc, (size_t)x->n * 32) || memcmp(x->xyz, y->xyz, (size_t)x->n * 12)))
            return false;
    }
    return true;
}

BF_TEST(store_keeps_keyframes_bit_for_bit_and_names_a_bad_file)
{
    const char *dir = fresh_dir("keyframes");
    CHECK(mkdir(dir, 0755) == 0);
    store_keyframes k, back = {0};
    CHECK_OK(make_keyframes(&k, 5));
    /* None kept yet: an empty set, no error (an older store). */
    CHECK_OK(store_keyframes_read(dir, &back));
    CHECK_EQ_INT(back.n, 0);
    CHECK_OK(store_keyframes_write(dir, &k));
    CHECK_OK(store_keyframes_read(dir, &back));
    CHECK(keyframes_equal(&k, &back));
    store_keyframes_free(&back);
    char path[700];
    snprintf(path, sizeof path, "%s/keyframes.bin", dir);
    /* A flipped byte anywhere, the file cut short, a newer version: named,
     * and nothing returned. */
    CHECK_OK(flip_byte(path, 500));
    back.n = 77;
    CHECK_STATUS(store_keyframes_read(dir, &back), BF_FORMAT);
    CHECK(strstr(bf_last_error(), "keyframes.bin") != NULL);
    CHECK_EQ_INT(back.n, 77);
    CHECK_OK(flip_byte(path, 500));
    CHECK_OK(store_keyframes_read(dir, &back));
    store_keyframes_free(&back);
    CHECK(truncate(path, 300) == 0);
    CHECK_STATUS(store_keyframes_read(dir, &back), BF_FORMAT);
    CHECK_OK(store_keyframes_write(dir, &k));
    CHECK_OK(flip_byte(path, 8)); /* the version word's low byte */
    CHECK_STATUS(store_keyframes_read(dir, &back), BF_UNSUPPORTED);
    /* An empty set is a file of none; bad input is refused. */
    store_keyframes none = {0};
    CHECK_OK(store_keyframes_write(dir, &none));
    CHECK_OK(store_keyframes_read(dir, &back));
    CHECK_EQ_INT(back.n, 0);
    k.kf[0].T_wc.t.x = NAN;
    CHECK_STATUS(store_keyframes_write(dir, &k), BF_INVALID_ARG);
    /* A failed write or allocation at any point leaves the file that was
     * there. */
    k.kf[0].T_wc.t.x = 0;
    CHECK_OK(store_keyframes_write(dir, &k));
    store_keyframes k2;
    CHECK_OK(make_keyframes(&k2, 3));
    uint32_t points = 0; /* faults that fired before the clean run (0: it never came) */
    for (uint32_t f = 1; f < 20; f++) {
        bf_fault_arm(f);
        bf_status s = store_keyframes_write(dir, &k2);
        bool fired = bf_fault_arm(0) == 0;
        CHECK_OK(store_keyframes_read(dir, &back));
        CHECK(fired ? s != BF_OK && keyframes_equal(&back, &k) : s == BF_OK && keyframes_equal(&back, &k2));
        store_keyframes_free(&back);
        if (!fired) {
            points = f - 1;
            break;
        }
    }
    /* The buffer, its write and its fsync. */
    CHECK_LE(3, points);
    /* A failed allocation while reading: an error, and nothing returned. */
    points = 0;
    for (uint32_t f = 1; f < 40; f++) {
        back.n = 77;
        bf_fault_arm(f);
        bf_status s = store_keyframes_read(dir, &back);
        bool fired = bf_fault_arm(0) == 0;
        if (!fired) {
            CHECK_OK(s);
            CHECK(keyframes_equal(&back, &k2));
            store_keyframes_free(&back);
            points = f - 1;
            break;
        }
        CHECK_STATUS(s, BF_NO_MEMORY);
        CHECK_EQ_INT(back.n, 77);
    }
    /* The file's bytes, the keyframe array, two keyframes' descriptors and points. */
    CHECK_LE(6, points);
    /* What only a file with a right checksum reaches: too many keyframes,
     * a point not finite, bytes after the last keyframe. */
    uint8_t *raw = NULL;
    size_t len = 0;
    uint32_t count;
    CHECK_OK(store__read_binary(path, STORE_KEYFRAMES_MAGIC, "keyframes file", 1u << 24, &raw, &len, &count));
    CHECK_EQ_INT(count, 3);
    uint32_t many = STORE_MAX_KEYFRAMES + 1;
    float nan_point = NAN;
    struct {
        size_t at, n;
        const void *with;
        const char *says;
    } edits[] = {{12, 4, &many, "more than"},
                 {16 + STORE_KEYFRAME_HEADER + 50 * 32, 4, &nan_point, "not finite"},
                 {12, 4, &(uint32_t){2}, "after the last keyframe"}};
    for (size_t e = 0; e < sizeof edits / sizeof *edits; e++) {
        uint8_t *c = malloc(len);
        CHECK(c != NULL);
        if (!c) break;
        memcpy(c, raw, len);
        memcpy(c + edits[e].at, edits[e].with, edits[e].n);
        uint64_t h = store__hash(c, len - 8);
        memcpy(c + len - 8, &h, 8);
        FILE *fp = fopen(path, "wb");
        CHECK(fp && fwrite(c, 1, len, fp) == len);
        if (fp) fclose(fp);
        free(c);
        CHECK_STATUS(store_keyframes_read(dir, &back), BF_FORMAT);
        CHECK(strstr(bf_last_error(), edits[e].says) != NULL);
    }
    free(raw);
    store_keyframes_free(&k);
    store_keyframes_free(&k2);
}

/* The writer writes keyframes handed to it with the next map, and a map
 * without new ones leaves the file. */
BF_TEST(store_writer_writes_keyframes_with_the_next_map)
{
    const char *dir = fresh_dir("writer-keyframes");
    hostmap a, c;
    CHECK_OK(make_map(&a, 2, 5));
    bf_traj t;
    CHECK_OK(make_traj(&t, 3));
    store_meta meta = meta_of(&a, 3);
    store_keyframes k, kept, back = {0};
    CHECK_OK(make_keyframes(&k, 3));
    CHECK_OK(make_keyframes(&kept, 3));
    /* make_keyframes draws from one generator: make the copy equal. */
    for (uint32_t i = 0; i < k.n; i++) {
        kept.kf[i].T_wc = k.kf[i].T_wc;
        if (k.kf[i].n) memcpy(kept.kf[i].desc, k.kf[i].desc, (size_t)k.kf[i].n * 32);
        if (k.kf[i].n) memcpy(kept.kf[i].xyz, k.kf[i].xyz, (size_t)k.kf[i].n * 12);
    }
    store_writer *w;
    CHECK_OK(store_writer_open(dir, false, &w));
    store_writer_keyframes(w, &k);
    CHECK_EQ_INT(k.n, 0); /* taken */
    /* The map that takes them, then another map with no new keyframes:
     * after each the file holds them. */
    for (int round = 0; round < 2; round++) {
        CHECK_OK(copy_map(&a, &c));
        CHECK_OK(store_writer_submit(w, &c, &meta, &t));
        CHECK_OK(store_writer_finish(w));
        CHECK_OK(store_keyframes_read(dir, &back));
        CHECK(keyframes_equal(&back, &kept));
        store_keyframes_free(&back);
    }
    /* Keyframes handed over and never followed by a map are freed with the writer. */
    CHECK_OK(make_keyframes(&k, 2));
    store_writer_keyframes(w, &k);
    store_writer_close(w);
    store_keyframes_free(&kept);
    hostmap_free(&a);
    bf_traj_free(&t);
}
