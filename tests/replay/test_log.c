/* replay: the bitfuse log. Round trips (bit exact with zstd colour, within
 * JPEG's error with JPEG), a log cut at every byte offset, flipped bytes in
 * every part of a frame, seeking through the index, a log whose writer died
 * before the index, and recording a real sequence through the capture
 * thread. The test reads the footer and index itself, from the layout in
 * docs/formats.md, to know where each frame's record starts. */
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include "capture/capture.h"
#include "replay/log_int.h"
#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

#define LW 40u
#define LH 30u
#define LN 5u

typedef struct synth_seq {
    uint32_t n, w, h;
    uint16_t *depth[8];
    uint8_t *rgb[8];
    bf_frame f[8];
} synth_seq;

static void synth_free(synth_seq *q)
{
    for (uint32_t k = 0; k < q->n; k++) {
        free(q->depth[k]);
        free(q->rgb[k]);
    }
}

/* Frames with what real ones have: smooth depth with noise, holes (0) and
 * the largest raw value; smooth colour (JPEG's good case) with noise; odd
 * frames without colour or pose; odd timestamps. */
static bool synth_make(synth_seq *q, uint32_t n, uint32_t w, uint32_t h)
{
    memset(q, 0, sizeof *q);
    q->n = n;
    q->w = w;
    q->h = h;
    uint32_t rng = 12345;
    for (uint32_t k = 0; k < n; k++) {
        q->depth[k] = malloc((size_t)w * h * 2);
        q->rgb[k] = malloc((size_t)w * h * 3);
        if (!q->depth[k] || !q->rgb[k]) return false;
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                rng = rng * 1664525u + 1013904223u;
                size_t i = (size_t)y * w + x;
                uint16_t d = (uint16_t)(5000 + 40 * x + 25 * y + 100 * k + (rng >> 28));
                if ((rng >> 20) % 17 == 0) d = 0;
                if (x == 3 && y == 2) d = 65535;
                q->depth[k][i] = d;
                q->rgb[k][3 * i + 0] = (uint8_t)(60 + 3 * x + k);
                q->rgb[k][3 * i + 1] = (uint8_t)(90 + 4 * y);
                q->rgb[k][3 * i + 2] = (uint8_t)(120 + x + y + ((rng >> 24) & 3));
            }
        q->f[k] = (bf_frame){.index = 10 + 2 * k, .width = w, .height = h, .t_depth_s = 1305031102.175304 + k / 30.0,
                             .depth = q->depth[k], .rgb = k == 1 ? NULL : q->rgb[k], .has_pose = k != 2};
        q->f[k].t_rgb_s = q->f[k].t_depth_s + 0.0031 * k;
        q->f[k].T_wc = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, 1, 0.2), 0.1 * k + 0.01),
                                      bf_v3(0.1 * k, -0.7, 1.0 / 3.0));
    }
    return true;
}

static const bf_intrinsics synth_K = {LW, LH, 517.3, 516.5, 318.6, 255.3, 5000};

static bf_status write_log(const char *path, const synth_seq *q, replay_log_colour colour, bool finish)
{
    replay_log_config cfg = {.colour = colour, .device = "synthetic:test", .has_groundtruth = true};
    bf_intrinsics K = synth_K;
    K.width = q->w;
    K.height = q->h;
    replay_log_writer *w;
    bf_status s = replay_log_writer_create(path, &K, &cfg, &w);
    if (s) return s;
    for (uint32_t k = 0; k < q->n && !s; k++) s = replay_log_writer_add(w, &q->f[k]);
    if (!s && finish) s = replay_log_writer_finish(w);
    replay_log_writer_destroy(w);
    return s;
}

static const char *tmp_path(const char *name)
{
    static char p[4][1024];
    static int slot;
    slot = (slot + 1) % 4;
    snprintf(p[slot], sizeof p[slot], "%s/%s", bf_test_tmpdir(), name);
    return p[slot];
}

static size_t file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (size_t)st.st_size : 0;
}

static bool copy_prefix(const char *src, const char *dst, size_t n)
{
    char *buf;
    size_t len;
    if (bf_read_file(src, &buf, &len) != BF_OK) return false;
    if (n > len) n = len;
    FILE *f = fopen(dst, "wb");
    bool ok = f && fwrite(buf, 1, n, f) == n;
    if (f) ok &= fclose(f) == 0;
    free(buf);
    return ok;
}

static bool flip_byte(const char *path, size_t at)
{
    FILE *f = fopen(path, "r+b");
    if (!f) return false;
    bool ok = fseek(f, (long)at, SEEK_SET) == 0;
    int c = ok ? fgetc(f) : EOF;
    ok = c != EOF && fseek(f, (long)at, SEEK_SET) == 0 && fputc(c ^ 0x5a, f) != EOF;
    return fclose(f) == 0 && ok;
}

static uint64_t le64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

/* Reads the record offsets from the footer and index (docs/formats.md):
 * footer = u64 index offset, u32 count, u32 CRC, "BFLOGEND"; index = "BFIX",
 * u32 count, count x (u64 offset, f64 t), u32 CRC. */
static uint32_t log_offsets(const char *path, uint64_t *off, uint32_t cap, uint64_t *index_at)
{
    char *buf;
    size_t len;
    if (bf_read_file(path, &buf, &len) != BF_OK || len < 24) return 0;
    const uint8_t *b = (const uint8_t *)buf;
    uint32_t n = 0;
    if (!memcmp(b + len - 8, "BFLOGEND", 8)) {
        uint64_t at = le64(b + len - 24);
        n = (uint32_t)(le64(b + len - 16) & 0xffffffffu);
        if (n > cap) n = cap;
        for (uint32_t i = 0; i < n; i++) off[i] = le64(b + at + 8 + 16 * i);
        *index_at = at;
    }
    free(buf);
    return n;
}

/* The frame as read equals frame k of q: depth always exactly; colour
 * exactly (max_rgb_err 0) or within max_rgb_err; times, pose and index
 * exactly. */
static bool frame_equals(const bf_frame *f, const synth_seq *q, uint32_t k, int max_rgb_err)
{
    const bf_frame *e = &q->f[k];
    if (f->index != e->index || f->width != e->width || f->height != e->height) return false;
    if (f->t_depth_s != e->t_depth_s || f->t_rgb_s != e->t_rgb_s || f->has_pose != e->has_pose) return false;
    if (e->has_pose && memcmp(&f->T_wc, &e->T_wc, sizeof f->T_wc) != 0) return false;
    size_t n = (size_t)e->width * e->height;
    if (memcmp(f->depth, e->depth, n * 2) != 0) return false;
    if (!e->rgb) return f->rgb == NULL;
    if (!f->rgb) return false;
    if (max_rgb_err == 0) return memcmp(f->rgb, e->rgb, n * 3) == 0;
    for (size_t i = 0; i < n * 3; i++)
        if (abs((int)f->rgb[i] - (int)e->rgb[i]) > max_rgb_err) return false;
    return true;
}

BF_TEST(log_round_trip_with_zstd_colour_is_bit_exact)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("rt_zstd.bflog");
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_ZSTD, true));
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    CHECK(!strcmp(src->kind, "bflog"));
    CHECK_EQ_INT(src->n_frames, LN);
    CHECK(src->has_groundtruth);
    CHECK(memcmp(&src->intrinsics, &synth_K, sizeof synth_K) == 0);
    bf_frame f;
    for (uint32_t k = 0; k < LN; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_equals(&f, &q, k, 0));
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(log_round_trip_with_jpeg_colour_is_exact_in_depth_and_close_in_colour)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("rt_jpeg.bflog");
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_JPEG, true));
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    bf_frame f;
    for (uint32_t k = 0; k < LN; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        /* Quality 90 quantises each 8x8 DCT coefficient with a step of at
         * most 2 * (100 - 90) / 100 * the base table's (<= 121 for chroma
         * high frequencies); on these smooth gradients plus 2 bits of noise
         * the error stays a few levels; 4:2:0 chroma subsampling of a
         * gradient adds about one. 12 leaves room and still catches a
         * wrong channel order or a shifted row (errors of 30 and more). */
        CHECK(frame_equals(&f, &q, k, 12));
        if (q.f[k].rgb) CHECK(memcmp(f.rgb, q.f[k].rgb, (size_t)LW * LH * 3) != 0); /* really lossy */
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(log_cut_at_every_byte_replays_every_whole_frame)
{
    synth_seq q;
    CHECK(synth_make(&q, 4, 16, 12));
    const char *full = tmp_path("cut_full.bflog"), *cut = tmp_path("cut.bflog");
    CHECK_OK(write_log(full, &q, REPLAY_LOG_COLOUR_ZSTD, true));
    uint64_t off[8], index_at = 0;
    CHECK_EQ_INT(log_offsets(full, off, 8, &index_at), 4);
    size_t size = file_size(full);
    CHECK(copy_prefix(full, cut, size));
    bf_log_level old = bf_log_get_level();
    bf_log_set_level(BF_LOG_ERROR); /* each cut warns once */
    /* Shrink the copy one byte at a time (truncate() keeps the prefix). */
    for (size_t n = size; n-- > 0;) {
        CHECK(truncate(cut, (off_t)n) == 0);
        /* Whole frames: those whose record ends at or before the cut. */
        uint32_t whole = 0;
        for (uint32_t k = 0; k < 4; k++) {
            uint64_t end = k + 1 < 4 ? off[k + 1] : index_at;
            if (end <= n) whole = k + 1;
        }
        rgbd_source *src;
        bf_status s = replay_open(cut, NULL, &src);
        if (whole == 0) {
            if (s != BF_FORMAT) bf_log_set_level(old);
            CHECK_STATUS(s, BF_FORMAT);
            CHECK_ERROR_MENTIONS(cut);
            continue;
        }
        if (s) bf_log_set_level(old);
        CHECK_OK(s);
        CHECK_EQ_INT(src->n_frames, whole);
        bf_frame f;
        for (uint32_t k = 0; k < whole; k++) {
            s = rgbd_source_next(src, &f);
            if (s) bf_log_set_level(old);
            CHECK_OK(s);
            CHECK(frame_equals(&f, &q, k, 0));
        }
        s = rgbd_source_next(src, &f);
        rgbd_source_close(src);
        if (s != BF_END) bf_log_set_level(old);
        CHECK_STATUS(s, BF_END);
    }
    bf_log_set_level(old);
    synth_free(&q);
}

/* Flips one byte at each of several places of frame 2's record (header
 * fields, the header CRC, depth and colour payload): frames 0 and 1 replay
 * exactly, frame 2 fails naming the file and the frame. */
static void check_corrupt_frame(bool with_index)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *good = tmp_path("corrupt_good.bflog"), *bad = tmp_path("corrupt.bflog");
    CHECK_OK(write_log(good, &q, REPLAY_LOG_COLOUR_ZSTD, with_index));
    uint64_t off[8], index_at = 0;
    CHECK_OK(write_log(tmp_path("corrupt_idx.bflog"), &q, REPLAY_LOG_COLOUR_ZSTD, true));
    CHECK_EQ_INT(log_offsets(tmp_path("corrupt_idx.bflog"), off, 8, &index_at), LN);
    size_t rec = off[3] - off[2];
    size_t places[] = {0, 4, 9, 21, 33, 60, 130, 146, 149, 152, 160, rec / 2, rec - 1};
    bf_log_level old = bf_log_get_level();
    for (size_t p = 0; p < sizeof places / sizeof places[0]; p++) {
        CHECK(copy_prefix(good, bad, SIZE_MAX));
        CHECK(flip_byte(bad, off[2] + places[p]));
        rgbd_source *src;
        bf_log_set_level(BF_LOG_ERROR);
        bf_status s = replay_open(bad, NULL, &src);
        bf_log_set_level(old);
        CHECK_OK(s);
        bf_frame f;
        for (uint32_t k = 0; k < 2; k++) {
            CHECK_OK(rgbd_source_next(src, &f));
            CHECK(frame_equals(&f, &q, k, 0));
        }
        bf_clear_error();
        s = rgbd_source_next(src, &f);
        if (s != BF_FORMAT) fprintf(stderr, "  flipped byte %zu of frame 2's record\n", places[p]);
        CHECK_STATUS(s, BF_FORMAT);
        CHECK_ERROR_MENTIONS(bad);
        CHECK_ERROR_MENTIONS("frame 2");
        rgbd_source_close(src);
    }
    synth_free(&q);
}

BF_TEST(corrupt_frame_is_named_and_the_frames_before_it_replay)
{
    check_corrupt_frame(true);
}

BF_TEST(corrupt_frame_in_a_log_without_index_is_named_too)
{
    check_corrupt_frame(false);
}

/* Rewrites frame k's record header through fn, with a valid header CRC:
 * what the checksum cannot catch (a writer that took bad values as given). */
static bool rewrite_header(const char *path, uint64_t at, void (*fn)(log__frame_header *))
{
    FILE *f = fopen(path, "r+b");
    uint8_t b[LOG_FRAME_HEADER];
    log__frame_header h;
    bool ok = f && fseek(f, (long)at, SEEK_SET) == 0 && fread(b, 1, sizeof b, f) == sizeof b &&
              log__frame_header_unpack(b, &h);
    if (ok) {
        fn(&h);
        log__frame_header_pack(&h, b);
        ok = fseek(f, (long)at, SEEK_SET) == 0 && fwrite(b, 1, sizeof b, f) == sizeof b;
    }
    if (f) ok = fclose(f) == 0 && ok;
    return ok;
}

static void time_nan(log__frame_header *h) { h->t_depth_s = NAN; }
static void time_back(log__frame_header *h) { h->t_depth_s -= 1.0; }
static double g_t_before; /* the time of the frame before the one rewritten */
static void time_same(log__frame_header *h) { h->t_depth_s = g_t_before; }
static void pose_nan(log__frame_header *h) { h->flags |= LOG_FRAME_HAS_POSE, h->T_wc.t.y = NAN; }
static void pose_scaled(log__frame_header *h)
{
    h->flags |= LOG_FRAME_HAS_POSE;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) h->T_wc.R[i][j] *= 2;
}

/* LN synthetic frames in a finished log at tmp_path(name) (zstd colour):
 * the frames in q, the records' offsets in off, the index's in *index_at. */
static void good_log(synth_seq *q, const char *name, uint64_t off[8], uint64_t *index_at)
{
    CHECK(synth_make(q, LN, LW, LH));
    CHECK_OK(write_log(tmp_path(name), q, REPLAY_LOG_COLOUR_ZSTD, true));
    CHECK_EQ_INT(log_offsets(tmp_path(name), off, 8, index_at), LN);
}

BF_TEST(times_and_poses_a_checksum_cannot_vouch_for_are_refused_by_frame)
{
    synth_seq q;
    uint64_t off[8], index_at;
    good_log(&q, "hdr_good.bflog", off, &index_at);
    const char *good = tmp_path("hdr_good.bflog"), *bad = tmp_path("hdr_bad.bflog");
    struct {
        void (*fn)(log__frame_header *);
        const char *mention;
    } cases[] = {
        {time_nan, "are not finite"},
        {pose_nan, "not a rigid motion"},
        {pose_scaled, "not a rigid motion"},
    };
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        CHECK(copy_prefix(good, bad, SIZE_MAX));
        CHECK(rewrite_header(bad, off[2], cases[c].fn));
        rgbd_source *src;
        CHECK_OK(replay_open(bad, NULL, &src));
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_OK(rgbd_source_next(src, &f));
        bf_clear_error();
        bf_status s = rgbd_source_next(src, &f);
        if (s != BF_FORMAT) fprintf(stderr, "  case %zu (%s)\n", c, cases[c].mention);
        CHECK_STATUS(s, BF_FORMAT);
        CHECK_ERROR_MENTIONS("frame 2 (byte");
        CHECK_ERROR_MENTIONS(cases[c].mention);
        CHECK_OK(rgbd_source_next(src, &f)); /* the rest still reads */
        CHECK(frame_equals(&f, &q, 3, 0));
        rgbd_source_close(src);
    }
    /* A time that does not increase (frame 2 given frame 1's, or a second
     * before it): that frame is dropped with a warning, counted, the rest
     * read, with or without --skip-bad-frames (a camera's clock that
     * repeated must not make its recording unreadable). */
    g_t_before = q.f[1].t_depth_s;
    void (*steps[2])(log__frame_header *) = {time_same, time_back};
    for (int k = 0; k < 2; k++) {
        CHECK(copy_prefix(good, bad, SIZE_MAX));
        CHECK(rewrite_header(bad, off[2], steps[k]));
        rgbd_source *src;
        CHECK_OK(replay_open(bad, NULL, &src));
        bf_frame f;
        bf_log_level old = bf_log_get_level();
        bf_log_set_level(BF_LOG_ERROR);
        uint32_t n = 0, want[] = {0, 1, 3, 4};
        while (rgbd_source_next(src, &f) == BF_OK) {
            CHECK(n < 4 && frame_equals(&f, &q, want[n], 0));
            n++;
        }
        bf_log_set_level(old);
        CHECK_EQ_INT(n, LN - 1);
        CHECK_EQ_INT(replay_skipped_frames(src), 1);
        rgbd_source_close(src);
    }
    synth_free(&q);
}

BF_TEST(skip_bad_frames_steps_over_a_corrupt_payload)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("skip.bflog");
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_ZSTD, true));
    uint64_t off[8], index_at;
    CHECK_EQ_INT(log_offsets(path, off, 8, &index_at), LN);
    CHECK(flip_byte(path, off[1] + 200)); /* frame 1's depth payload */
    replay_options opt = {.skip_bad_frames = true};
    rgbd_source *src;
    CHECK_OK(replay_open(path, &opt, &src));
    bf_frame f;
    bf_log_level old = bf_log_get_level();
    bf_log_set_level(BF_LOG_ERROR);
    uint32_t want[] = {0, 2, 3, 4};
    for (uint32_t i = 0; i < 4; i++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_equals(&f, &q, want[i], 0));
    }
    bf_log_set_level(old);
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK_EQ_INT(replay_skipped_frames(src), 1);
    rgbd_source_close(src);
    /* Without the option, next() reports frame 1 and then goes on. */
    CHECK_OK(replay_open(path, NULL, &src));
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_FORMAT);
    CHECK_ERROR_MENTIONS("frame 1 (byte");
    CHECK_ERROR_MENTIONS("payload checksum mismatch");
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK(frame_equals(&f, &q, 2, 0));
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(seeking_through_the_index_delivers_that_frame)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("seek.bflog");
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_JPEG, true));
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    bf_frame f;
    uint32_t order[] = {3, 0, 4, 4, 1, 2};
    for (size_t i = 0; i < sizeof order / sizeof order[0]; i++) {
        CHECK_OK(replay_log_seek(src, order[i]));
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_equals(&f, &q, order[i], 12));
    }
    CHECK_OK(rgbd_source_next(src, &f)); /* after frame 2 comes 3 */
    CHECK(frame_equals(&f, &q, 3, 12));
    CHECK_OK(replay_log_seek(src, LN));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK_STATUS(replay_log_seek(src, LN + 1), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("the log has 5 frames");
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(writer_that_never_finished_leaves_a_log_that_replays)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("unfinished.bflog");
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_ZSTD, false));
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    CHECK_EQ_INT(src->n_frames, LN);
    bf_frame f;
    for (uint32_t k = 0; k < LN; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_equals(&f, &q, k, 0));
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);
    synth_free(&q);
}

/* replace_when_finished (a conversion): until finish the log is
 * path.partial and an earlier log at path is untouched; unfinished, the
 * partial goes; finished, it takes path's place. */
BF_TEST(a_log_written_to_replace_one_leaves_it_whole_until_finished)
{
    synth_seq q;
    CHECK(synth_make(&q, LN, LW, LH));
    const char *path = tmp_path("replaced.bflog");
    char partial[1100];
    snprintf(partial, sizeof partial, "%s.partial", path);
    CHECK_OK(write_log(path, &q, REPLAY_LOG_COLOUR_NONE, true));
    char *before;
    size_t n_before;
    CHECK_OK(bf_read_file(path, &before, &n_before));
    replay_log_config cfg = {.colour = REPLAY_LOG_COLOUR_ZSTD, .replace_when_finished = true};
    replay_log_writer *w;
    CHECK_OK(replay_log_writer_create(path, &synth_K, &cfg, &w));
    CHECK_OK(replay_log_writer_add(w, &q.f[0]));
    CHECK(bf_file_exists(partial));
    CHECK_EQ_INT(file_size(path), n_before);
    replay_log_writer_destroy(w); /* unfinished: a failed conversion */
    CHECK(!bf_file_exists(partial));
    char *after;
    size_t n_after;
    CHECK_OK(bf_read_file(path, &after, &n_after));
    CHECK(n_after == n_before && memcmp(after, before, n_before) == 0);
    free(after);
    CHECK_OK(replay_log_writer_create(path, &synth_K, &cfg, &w));
    for (uint32_t k = 0; k < LN; k++) CHECK_OK(replay_log_writer_add(w, &q.f[k]));
    CHECK_OK(replay_log_writer_finish(w));
    replay_log_writer_destroy(w);
    CHECK(!bf_file_exists(partial));
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    bf_frame f;
    for (uint32_t k = 0; k < LN; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(frame_equals(&f, &q, k, 0)); /* the new log's colour, which the old one had not */
    }
    rgbd_source_close(src);
    free(before);
    synth_free(&q);
}

BF_TEST(damaged_index_or_footer_falls_back_to_reading_in_order)
{
    synth_seq q;
    uint64_t off[8], index_at;
    good_log(&q, "idx_good.bflog", off, &index_at);
    const char *good = tmp_path("idx_good.bflog"), *bad = tmp_path("idx_bad.bflog");
    size_t size = file_size(good);
    /* An index offset, the index CRC, the footer's offset, its CRC. */
    size_t places[] = {index_at + 8 + 16 * 2 + 1, size - 24 - 2, size - 24, size - 24 + 13};
    bf_log_level old = bf_log_get_level();
    for (size_t p = 0; p < 4; p++) {
        CHECK(copy_prefix(good, bad, SIZE_MAX));
        CHECK(flip_byte(bad, places[p]));
        rgbd_source *src;
        bf_log_set_level(BF_LOG_ERROR);
        bf_status s = replay_open(bad, NULL, &src);
        bf_log_set_level(old);
        CHECK_OK(s);
        CHECK_EQ_INT(src->n_frames, LN);
        bf_frame f;
        for (uint32_t k = 0; k < LN; k++) {
            CHECK_OK(rgbd_source_next(src, &f));
            CHECK(frame_equals(&f, &q, k, 0));
        }
        CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
        rgbd_source_close(src);
    }
    synth_free(&q);
}

BF_TEST(bad_header_or_not_a_log_fails_at_open_naming_the_file)
{
    synth_seq q;
    CHECK(synth_make(&q, 2, LW, LH));
    const char *good = tmp_path("hdr_good.bflog"), *bad = tmp_path("hdr_bad.bflog");
    CHECK_OK(write_log(good, &q, REPLAY_LOG_COLOUR_NONE, true));
    rgbd_source *src;
    struct {
        size_t at;
        const char *says;
    } cases[] = {{0, "not a bitfuse log"}, {8, "log version"}, {20, "checksum"}, {60, "checksum"},
                 {80, "checksum"}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        CHECK(copy_prefix(good, bad, SIZE_MAX));
        CHECK(flip_byte(bad, cases[i].at));
        CHECK_STATUS(replay_open(bad, NULL, &src), BF_FORMAT);
        CHECK_ERROR_MENTIONS(bad);
        CHECK_ERROR_MENTIONS(cases[i].says);
    }
    /* A text file named .bflog. */
    FILE *f = fopen(bad, "wb");
    CHECK(f);
    fputs("hello, not a log\n", f);
    fclose(f);
    CHECK_STATUS(replay_open(bad, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not a bitfuse log");
    /* Colour NONE: frames come back without colour. */
    CHECK_OK(replay_open(good, NULL, &src));
    bf_frame fr;
    CHECK_OK(rgbd_source_next(src, &fr));
    CHECK(fr.rgb == NULL);
    CHECK(memcmp(fr.depth, q.depth[0], (size_t)LW * LH * 2) == 0);
    rgbd_source_close(src);
    /* The options every reader shares: --frames and --camera. */
    replay_options opt = {.max_frames = 1, .camera = "fr2", .depth_scale = 1000};
    CHECK_OK(replay_open(good, &opt, &src));
    CHECK_EQ_INT(src->n_frames, 1);
    CHECK(src->intrinsics.fx_px == 520.9 && src->intrinsics.depth_scale == 1000 && src->intrinsics.width == LW);
    CHECK_OK(rgbd_source_next(src, &fr));
    CHECK_STATUS(rgbd_source_next(src, &fr), BF_END);
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(writer_refuses_frames_that_do_not_fit_and_stays_usable)
{
    synth_seq q;
    CHECK(synth_make(&q, 2, LW, LH));
    const char *path = tmp_path("refuse.bflog");
    replay_log_config cfg = {.colour = REPLAY_LOG_COLOUR_JPEG};
    replay_log_writer *w;
    CHECK_STATUS(replay_log_writer_create(path, &(bf_intrinsics){0, 0, 1, 1, 0, 0, 5000}, &cfg, &w),
                 BF_INVALID_ARG);
    CHECK_OK(replay_log_writer_create(path, &synth_K, &cfg, &w));
    bf_frame f = q.f[0];
    f.width = LW - 1;
    CHECK_STATUS(replay_log_writer_add(w, &f), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("frame 10 is 39x30");
    f = q.f[0];
    f.t_depth_s = NAN;
    CHECK_STATUS(replay_log_writer_add(w, &f), BF_INVALID_ARG);
    CHECK_OK(replay_log_writer_add(w, &q.f[1]));
    replay_log_stats st = replay_log_writer_stats(w);
    CHECK_EQ_INT(st.n_frames, 1);
    CHECK_EQ_INT(st.depth_raw_bytes, LW * LH * 2);
    CHECK_EQ_INT(st.rgb_raw_bytes, 0); /* frame 1 has no colour */
    CHECK_OK(replay_log_writer_finish(w));
    CHECK_EQ_INT(replay_log_writer_stats(w).file_bytes, file_size(path));
    replay_log_writer_destroy(w);
    replay_log_writer_destroy(NULL);
    rgbd_source *src;
    CHECK_OK(replay_open(path, NULL, &src));
    CHECK_EQ_INT(src->n_frames, 1);
    bf_frame r;
    CHECK_OK(rgbd_source_next(src, &r));
    CHECK(frame_equals(&r, &q, 1, 0));
    rgbd_source_close(src);
    synth_free(&q);
}

BF_TEST(recording_a_real_sequence_through_the_capture_thread_is_bit_exact)
{
    /* Three real Kinect frames (TUM fr2 desk) as a TUM folder, recorded the
     * way `bitfuse record` does (capture thread, lossless for a file, zstd
     * colour), replayed and compared with the folder read directly. */
    const char *data = bf_test_data("tum/frames");
    if (!data) BF_SKIP("tum/frames absent");
    char dir[1024], p[1200];
    snprintf(dir, sizeof dir, "%s/real_tum", bf_test_tmpdir());
    static const char *const names[3] = {"a", "b1", "b2"};
    bf_intrinsics K = {0, 0, 520.9, 521.0, 325.1, 249.7, 5000};
    replay_tum_writer *tw;
    CHECK_OK(replay_tum_writer_create(dir, &K, &tw));
    for (int k = 0; k < 3; k++) {
        uint16_t *d;
        uint8_t *c;
        uint32_t w, h;
        snprintf(p, sizeof p, "%s/fr2_desk_%s_depth.png", data, names[k]);
        CHECK_OK(replay_png_read_u16(p, &d, &w, &h));
        snprintf(p, sizeof p, "%s/fr2_desk_%s_rgb.png", data, names[k]);
        CHECK_OK(replay_image_read_rgb8(p, &c, &w, &h));
        bf_frame f = {.index = (uint32_t)k, .width = w, .height = h, .t_depth_s = 100 + k / 30.0,
                      .t_rgb_s = 100 + k / 30.0, .depth = d, .rgb = c, .has_pose = true,
                      .T_wc = bf_se3_from_qt(bf_quat_identity(), bf_v3(k, 0, 0))};
        bf_status s = replay_tum_writer_add(tw, &f);
        free(d);
        free(c);
        CHECK_OK(s);
    }
    CHECK_OK(replay_tum_writer_finish(tw));
    replay_tum_writer_destroy(tw);

    rgbd_source *dev, *thr;
    CHECK_OK(replay_open(dir, NULL, &dev));
    CHECK_OK(capture_threaded_lossless(dev, 2, &thr));
    const char *path = tmp_path("real.bflog");
    replay_log_config cfg = {.colour = REPLAY_LOG_COLOUR_ZSTD, .device = dir, .has_groundtruth = true};
    replay_log_writer *w;
    CHECK_OK(replay_log_writer_create(path, rgbd_source_intrinsics(thr), &cfg, &w));
    bf_frame f;
    bf_status s;
    while ((s = rgbd_source_next(thr, &f)) == BF_OK) CHECK_OK(replay_log_writer_add(w, &f));
    CHECK_STATUS(s, BF_END);
    CHECK_OK(replay_log_writer_finish(w));
    replay_log_stats st = replay_log_writer_stats(w);
    replay_log_writer_destroy(w);
    CHECK_EQ_INT(capture_threaded_stats(thr).dropped, 0);
    rgbd_source_close(thr);
    CHECK_EQ_INT(st.n_frames, 3);
    /* Real depth compresses (measured about 4x with the row-delta filter
     * and zstd level 1); less than 2x would mean the filter is broken. */
    CHECK(st.depth_bytes * 2 < st.depth_raw_bytes);

    rgbd_source *a, *b;
    CHECK_OK(replay_open(dir, NULL, &a));
    CHECK_OK(replay_open(path, NULL, &b));
    CHECK(memcmp(&a->intrinsics, &b->intrinsics, sizeof a->intrinsics) == 0);
    bf_frame fa, fb;
    for (int k = 0; k < 3; k++) {
        CHECK_OK(rgbd_source_next(a, &fa));
        CHECK_OK(rgbd_source_next(b, &fb));
        CHECK_EQ_INT(fb.index, fa.index);
        CHECK(fb.t_depth_s == fa.t_depth_s && fb.t_rgb_s == fa.t_rgb_s && fb.has_pose == fa.has_pose);
        CHECK(memcmp(&fb.T_wc, &fa.T_wc, sizeof fa.T_wc) == 0);
        CHECK(memcmp(fb.depth, fa.depth, (size_t)fa.width * fa.height * 2) == 0);
        CHECK(fa.rgb && fb.rgb && memcmp(fb.rgb, fa.rgb, (size_t)fa.width * fa.height * 3) == 0);
    }
    CHECK_STATUS(rgbd_source_next(b, &fb), BF_END);
    rgbd_source_close(a);
    rgbd_source_close(b);
}

static bf_status write_whole_log(void *arg)
{
    const synth_seq *q = arg;
    return write_log(tmp_path("faults_w.bflog"), q, REPLAY_LOG_COLOUR_ZSTD, true);
}

/* Every host allocation of writing and of reading a log fails in turn. */
BF_TEST(log_writing_and_reading_fail_cleanly_at_every_allocation)
{
    synth_seq q;
    CHECK(synth_make(&q, 3, LW, LH));
    const char *path = tmp_path("faults.bflog");
    bf_status s = write_log(path, &q, REPLAY_LOG_COLOUR_ZSTD, true);
    int n_read = s == BF_OK ? bf_test_fault_walk(rt_read_all, (void *)path) : -1;
    int n_write = s == BF_OK ? bf_test_fault_walk(write_whole_log, &q) : -1;
    synth_free(&q);
    CHECK_OK(s);
    CHECK(n_read >= 4);
    CHECK(n_write >= 3);
    fprintf(stderr, "  log: %d allocations failed in turn reading, %d writing\n", n_read, n_write);
}
