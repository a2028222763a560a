/* replay: the bitfuse log as an rgbd_source.
 *
 * At open the reader checks the header, then looks for the footer: when it
 * and the index it points at are whole and consistent, the index gives
 * every frame's offset. Otherwise (a recording cut off by a crash, a damaged
 * index) it walks the frame records from the header on, checking each
 * record header's magic and checksum and that its payload lies within the
 * file, and stops at the first record that is cut off (the log simply ends
 * there, with a warning) or corrupt (delivered as an error naming the frame
 * once the frames before it are replayed). Each frame is checked again when
 * it is read (header checksum, payload CRC-32, decoded size), so corruption
 * is reported for its frame, never crashes, and the frames before it replay.
 *
 * Buffers for one frame (compressed and decoded) are allocated at open from
 * the header's frame size; nothing is allocated per frame (libjpeg keeps its
 * own decoder state per image). */
#include "log_int.h"

#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

typedef struct log__source {
    rgbd_source base;
    char *path;
    FILE *f;
    log__header hdr;
    uint64_t file_size;
    uint64_t *offsets;    /* record offset of each whole frame */
    uint32_t n;           /* frames located (before --frames) */
    uint32_t n_cap;
    bool has_index;
    bf_status tail_status; /* after the last located frame: BF_END or the scan's error */
    char tail_msg[768];
    uint32_t pos;         /* next frame to deliver */
    bool skip_bad;
    atomic_uint n_skipped; /* read while a capture thread may still run: replay_skipped_frames */
    double last_t_s;      /* the depth time of the last frame delivered (-inf before the first) */
    size_t n_px;
    ZSTD_DCtx *zd;
    uint8_t *depth_payload, *rgb_payload;
    uint16_t *depth;
    uint8_t *rgb;
} log__source;

static const rgbd_source_ops log__ops;

/* ------------------------------------------------------------ header */

static bf_status read_at(log__source *ls, uint64_t at, void *buf, size_t n, size_t *got)
{
    if (fseeko(ls->f, (off_t)at, SEEK_SET) != 0)
        return bf_fail(BF_IO, "%s: cannot seek to byte %llu: %s", ls->path, (unsigned long long)at, strerror(errno));
    *got = fread(buf, 1, n, ls->f);
    if (*got < n && ferror(ls->f)) {
        clearerr(ls->f);
        return bf_fail(BF_IO, "%s: read error at byte %llu: %s", ls->path, (unsigned long long)at, strerror(errno));
    }
    return BF_OK;
}

static bf_status header_read(log__source *ls)
{
    uint8_t b[LOG_HEADER_FIXED + LOG_DEVICE_MAX + 4];
    size_t got;
    bf_status s = read_at(ls, 0, b, LOG_HEADER_FIXED, &got);
    if (s != BF_OK) return s;
    if (got >= LOG_MAGIC_LEN && memcmp(b, LOG_MAGIC, LOG_MAGIC_LEN) != 0)
        return bf_fail(BF_FORMAT, "%s: not a bitfuse log (wrong magic bytes)", ls->path);
    if (got < LOG_HEADER_FIXED)
        return bf_fail(BF_FORMAT, "%s: log header is cut off (file of %zu bytes; the header alone takes %u)",
                       ls->path, got, LOG_HEADER_FIXED + 4);
    log__header *h = &ls->hdr;
    h->version = log__get_u32(b + 8);
    if (h->version != LOG_VERSION)
        return bf_fail(BF_FORMAT, "%s: log version %u; this bitfuse reads version %u", ls->path, h->version,
                       LOG_VERSION);
    h->size = log__get_u32(b + 12);
    uint32_t dev_len = log__get_u32(b + 76);
    if (dev_len > LOG_DEVICE_MAX || h->size != LOG_HEADER_FIXED + dev_len + 4)
        return bf_fail(BF_FORMAT, "%s: corrupt log header (device string of %u bytes, header of %u)", ls->path,
                       dev_len, h->size);
    if ((s = read_at(ls, LOG_HEADER_FIXED, b + LOG_HEADER_FIXED, dev_len + 4, &got))) return s;
    if (got < dev_len + 4)
        return bf_fail(BF_FORMAT, "%s: log header is cut off (file of %llu bytes; the header takes %u)", ls->path,
                       (unsigned long long)(LOG_HEADER_FIXED + got), h->size);
    if (log__get_u32(b + LOG_HEADER_FIXED + dev_len) != log__crc32(0, b, LOG_HEADER_FIXED + dev_len))
        return bf_fail(BF_FORMAT, "%s: corrupt log header (checksum mismatch)", ls->path);
    h->K.width = log__get_u32(b + 16);
    h->K.height = log__get_u32(b + 20);
    h->K.fx_px = log__get_f64(b + 24);
    h->K.fy_px = log__get_f64(b + 32);
    h->K.cx_px = log__get_f64(b + 40);
    h->K.cy_px = log__get_f64(b + 48);
    h->K.depth_scale = log__get_f64(b + 56);
    h->colour = log__get_u32(b + 64);
    h->depth_codec = log__get_u32(b + 68);
    h->flags = log__get_u32(b + 72);
    memcpy(h->device, b + LOG_HEADER_FIXED, dev_len);
    h->device[dev_len] = '\0';
    /* The checksum matched, so these came from a writer: refuse what this
     * reader cannot handle rather than what is damaged. */
    if (h->K.width == 0 || h->K.height == 0 || h->K.width > 16384 || h->K.height > 16384)
        return bf_fail(BF_FORMAT, "%s: log frame size %ux%u is outside 1..16384", ls->path, h->K.width, h->K.height);
    if (!(h->K.depth_scale > 0) || !isfinite(h->K.depth_scale) || !isfinite(h->K.fx_px) || !isfinite(h->K.fy_px) ||
        !isfinite(h->K.cx_px) || !isfinite(h->K.cy_px))
        return bf_fail(BF_FORMAT, "%s: log header has invalid intrinsics", ls->path);
    if (h->colour > REPLAY_LOG_COLOUR_JPEG)
        return bf_fail(BF_FORMAT, "%s: unknown colour codec %u in the log header", ls->path, h->colour);
    if (h->depth_codec != LOG_DEPTH_ZSTD)
        return bf_fail(BF_FORMAT, "%s: unknown depth codec %u in the log header", ls->path, h->depth_codec);
    return BF_OK;
}

/* ------------------------------------------------------------ locating frames */

static bf_status offsets_reserve(log__source *ls, uint32_t n)
{
    if (n <= ls->n_cap) return BF_OK;
    uint32_t cap = ls->n_cap ? ls->n_cap : 1024;
    while (cap < n) cap = cap > UINT32_MAX / 2 ? UINT32_MAX : 2 * cap;
    uint64_t *p = bf_realloc(ls->offsets, (size_t)cap * sizeof *p);
    if (!p) return bf_fail(BF_NO_MEMORY, "%s: frame index of %u entries", ls->path, cap);
    ls->offsets = p;
    ls->n_cap = cap;
    return BF_OK;
}

/* Reads the footer and the index it points at. Returns BF_OK with
 * has_index set, BF_OK without it when the footer or index is absent or
 * damaged (the caller scans), or a hard error (I/O, memory). */
static bf_status index_read(log__source *ls)
{
    if (ls->file_size < ls->hdr.size + 8u + 4u + LOG_FOOTER) return BF_OK;
    uint8_t foot[LOG_FOOTER];
    size_t got;
    bf_status s = read_at(ls, ls->file_size - LOG_FOOTER, foot, LOG_FOOTER, &got);
    if (s != BF_OK) return s;
    if (got != LOG_FOOTER || memcmp(foot + 16, LOG_FOOTER_MAGIC, 8) != 0) return BF_OK;
    if (log__get_u32(foot + 12) != log__crc32(0, foot, 12)) {
        bf_warn("%s: the log's footer is damaged; finding frames by reading them in order", ls->path);
        return BF_OK;
    }
    uint64_t at = log__get_u64(foot);
    uint32_t n = log__get_u32(foot + 8);
    uint64_t idx_bytes = 8u + (uint64_t)n * LOG_INDEX_ENTRY + 4u;
    if (at < ls->hdr.size || at + idx_bytes != ls->file_size - LOG_FOOTER) {
        bf_warn("%s: the log's footer points outside the file; finding frames by reading them in order", ls->path);
        return BF_OK;
    }
    uint8_t *buf = bf_malloc(idx_bytes);
    if (!buf) return bf_fail(BF_NO_MEMORY, "%s: index of %u frames", ls->path, n);
    if ((s = read_at(ls, at, buf, idx_bytes, &got))) {
        free(buf);
        return s;
    }
    bool ok = got == idx_bytes && log__get_u32(buf) == LOG_INDEX_MAGIC && log__get_u32(buf + 4) == n &&
              log__get_u32(buf + idx_bytes - 4) == log__crc32(0, buf, idx_bytes - 4);
    /* Offsets must increase and leave room for a record header each. */
    uint64_t prev_end = ls->hdr.size;
    for (uint32_t i = 0; ok && i < n; i++) {
        uint64_t o = log__get_u64(buf + 8 + (size_t)i * LOG_INDEX_ENTRY);
        ok = o >= prev_end && o + LOG_FRAME_HEADER <= at;
        prev_end = o + LOG_FRAME_HEADER;
    }
    if (ok && (s = offsets_reserve(ls, n ? n : 1)) == BF_OK) {
        for (uint32_t i = 0; i < n; i++) ls->offsets[i] = log__get_u64(buf + 8 + (size_t)i * LOG_INDEX_ENTRY);
        ls->n = n;
        ls->has_index = true;
    } else if (!ok) {
        bf_warn("%s: the log's index is damaged; finding frames by reading them in order", ls->path);
    }
    free(buf);
    return s;
}

/* Walks the records from the header on (no usable index). */
static bf_status scan(log__source *ls)
{
    uint64_t at = ls->hdr.size;
    size_t depth_bound = log__depth_bound(ls->n_px), rgb_bound = log__rgb_bound(ls->n_px);
    ls->n = 0;
    for (;;) {
        if (at == ls->file_size) break;
        uint8_t b[LOG_FRAME_HEADER];
        size_t got;
        bf_status s = read_at(ls, at, b, sizeof b, &got);
        if (s != BF_OK) return s;
        /* The index chunk of a log whose footer is missing or damaged: the
         * frames end here. */
        if (got >= 4 && log__get_u32(b) == LOG_INDEX_MAGIC) {
            /* Whole frames and an index, but no footer at the end to point at
             * it: cut inside the footer, or bytes appended after it. */
            bf_warn("%s: the log's index starts at byte %llu but its footer is not at the end of the file (cut off, "
                    "or bytes appended after it): %u frames found by reading them in order",
                    ls->path, (unsigned long long)at, ls->n);
            break;
        }
        log__frame_header h;
        if (got < LOG_FRAME_HEADER) {
            bf_warn("%s: the log ends inside frame %u's record header (byte %llu of %llu): the recording was cut "
                    "off; %u whole frames replay",
                    ls->path, ls->n, (unsigned long long)at, (unsigned long long)ls->file_size, ls->n);
            break;
        }
        if (!log__frame_header_unpack(b, &h) || h.depth_size > depth_bound || h.rgb_size > rgb_bound) {
            ls->tail_status = BF_FORMAT;
            snprintf(ls->tail_msg, sizeof ls->tail_msg,
                     "%s: frame %u (byte %llu): corrupt record header (bad magic, checksum or sizes); the "
                     "frames after it cannot be located",
                     ls->path, ls->n, (unsigned long long)at);
            break;
        }
        uint64_t end = at + LOG_FRAME_HEADER + h.depth_size + h.rgb_size;
        if (end > ls->file_size) {
            bf_warn("%s: the log ends inside frame %u (byte %llu of the %llu it needs): the recording was cut off; "
                    "%u whole frames replay",
                    ls->path, ls->n, (unsigned long long)ls->file_size, (unsigned long long)end, ls->n);
            break;
        }
        if ((s = offsets_reserve(ls, ls->n + 1))) return s;
        ls->offsets[ls->n++] = at;
        at = end;
    }
    return BF_OK;
}

/* ------------------------------------------------------------ frames */

static bf_status frame_fail(log__source *ls, uint32_t k, uint64_t at, const char *why)
{
    return bf_fail(BF_FORMAT, "%s: frame %u (byte %llu): %s", ls->path, k, (unsigned long long)at, why);
}

static bf_status frame_load(log__source *ls, uint32_t k, bf_frame *out)
{
    uint64_t at = ls->offsets[k];
    uint8_t b[LOG_FRAME_HEADER];
    size_t got = 0;
    char why[256];
    bf_status s = read_at(ls, at, b, sizeof b, &got);
    if (s != BF_OK) return s;
    if (got < LOG_FRAME_HEADER) return frame_fail(ls, k, at, "the file ends inside the record header");
    log__frame_header h;
    if (!log__frame_header_unpack(b, &h))
        return frame_fail(ls, k, at, "corrupt record header (bad magic or header checksum)");
    /* What the checksum cannot vouch for (a writer that took them as given):
     * times and poses as the TUM reader checks them. A rotation stored in
     * doubles is orthonormal to 1e-12; 1e-3 leaves room for poses read from
     * six-decimal text. */
    if (!isfinite(h.t_depth_s) || !isfinite(h.t_rgb_s)) {
        snprintf(why, sizeof why, "its times (depth %g s, colour %g s) are not finite", h.t_depth_s, h.t_rgb_s);
        return frame_fail(ls, k, at, why);
    }
    if ((h.flags & LOG_FRAME_HAS_POSE) && !bf_se3_is_rigid(&h.T_wc, 1e-3))
        return frame_fail(ls, k, at, "its pose is not a rigid motion (not finite, or not a rotation)");
    uint32_t W = ls->hdr.K.width, H = ls->hdr.K.height;
    if (h.depth_size > log__depth_bound(ls->n_px) || h.rgb_size > log__rgb_bound(ls->n_px)) {
        snprintf(why, sizeof why, "payload sizes %u + %u exceed the bounds for %ux%u frames", h.depth_size,
                 h.rgb_size, W, H);
        return frame_fail(ls, k, at, why);
    }
    if (h.depth_codec != LOG_DEPTH_ZSTD) {
        snprintf(why, sizeof why, "unknown depth codec %u", h.depth_codec);
        return frame_fail(ls, k, at, why);
    }
    bool has_rgb = h.flags & LOG_FRAME_HAS_RGB;
    if (has_rgb && h.colour_codec != REPLAY_LOG_COLOUR_ZSTD && h.colour_codec != REPLAY_LOG_COLOUR_JPEG) {
        snprintf(why, sizeof why, "unknown colour codec %u", h.colour_codec);
        return frame_fail(ls, k, at, why);
    }
    size_t need = (size_t)h.depth_size + h.rgb_size;
    if ((s = read_at(ls, at + LOG_FRAME_HEADER, ls->depth_payload, h.depth_size, &got))) return s;
    size_t got2 = 0;
    if (got == h.depth_size && h.rgb_size && (s = read_at(ls, at + LOG_FRAME_HEADER + h.depth_size, ls->rgb_payload,
                                                          h.rgb_size, &got2)))
        return s;
    if (got + got2 < need) {
        snprintf(why, sizeof why, "the file ends inside the payload (%zu of %zu bytes)", got + got2, need);
        return frame_fail(ls, k, at, why);
    }
    uint32_t crc = log__crc32(log__crc32(0, ls->depth_payload, h.depth_size), ls->rgb_payload, h.rgb_size);
    if (crc != h.payload_crc) {
        snprintf(why, sizeof why, "payload checksum mismatch (stored %08x, computed %08x): the frame is corrupt",
                 h.payload_crc, crc);
        return frame_fail(ls, k, at, why);
    }
    /* The checksum matched: a failure below means a writer bug or a forged
     * file, still reported, never trusted. */
    size_t dn = ZSTD_decompressDCtx(ls->zd, ls->depth, 2 * ls->n_px, ls->depth_payload, h.depth_size);
    if (ZSTD_isError(dn) || dn != 2 * ls->n_px) {
        snprintf(why, sizeof why, "depth does not decompress to %ux%u (%s)", W, H,
                 ZSTD_isError(dn) ? ZSTD_getErrorName(dn) : "wrong size");
        return frame_fail(ls, k, at, why);
    }
    uint16_t probe = 1;
    if (*(uint8_t *)&probe != 1) /* the file is little-endian */
        for (size_t i = 0; i < ls->n_px; i++) ls->depth[i] = (uint16_t)(ls->depth[i] << 8 | ls->depth[i] >> 8);
    if (has_rgb) {
        if (h.colour_codec == REPLAY_LOG_COLOUR_ZSTD) {
            size_t cn = ZSTD_decompressDCtx(ls->zd, ls->rgb, 3 * ls->n_px, ls->rgb_payload, h.rgb_size);
            if (ZSTD_isError(cn) || cn != 3 * ls->n_px) {
                snprintf(why, sizeof why, "colour does not decompress to %ux%u (%s)", W, H,
                         ZSTD_isError(cn) ? ZSTD_getErrorName(cn) : "wrong size");
                return frame_fail(ls, k, at, why);
            }
        } else {
            char what[1024];
            snprintf(what, sizeof what, "%s: frame %u (byte %llu)", ls->path, k, (unsigned long long)at);
            if ((s = log__jpeg_decode(ls->rgb_payload, h.rgb_size, W, H, ls->rgb, what))) return s;
        }
    }
    bool has_pose = h.flags & LOG_FRAME_HAS_POSE;
    *out = (bf_frame){
        .index = h.index,
        .width = W,
        .height = H,
        .t_depth_s = h.t_depth_s,
        .t_rgb_s = h.t_rgb_s,
        .depth = ls->depth,
        .rgb = has_rgb ? ls->rgb : NULL,
        .has_pose = has_pose,
        .T_wc = has_pose ? h.T_wc : bf_se3_identity(),
    };
    return BF_OK;
}

static bf_status log_next(rgbd_source *base, bf_frame *out)
{
    log__source *ls = (log__source *)base;
    while (ls->pos < ls->base.n_frames) {
        uint32_t k = ls->pos++;
        bf_status s = frame_load(ls, k, out);
        /* A time that does not increase (a camera clock that repeated or
         * stepped back while recording) is dropped with a warning, as the
         * TUM reader drops a repeated line: the loop's steps need time to
         * go on, and a log a device wrote that way still reads. */
        if (s == BF_OK && !(out->t_depth_s > ls->last_t_s)) {
            bf_warn("%s: frame %u (byte %llu): its time %.6f s is not after the frame before's (%.6f s): skipped",
                    ls->path, k, (unsigned long long)ls->offsets[k], out->t_depth_s, ls->last_t_s);
            ls->n_skipped++;
            continue;
        }
        if (s == BF_OK) ls->last_t_s = out->t_depth_s;
        if (s == BF_OK) return BF_OK;
        if (!ls->skip_bad || (s != BF_IO && s != BF_FORMAT)) return s;
        bf_warn("skipping frame %u: %s", k, bf_last_error());
        ls->n_skipped++;
    }
    /* The frame the scan could not locate, reported once after the rest. */
    if (ls->pos == ls->n && ls->tail_status != BF_END) {
        ls->pos++;
        if (!ls->skip_bad) return bf_fail(ls->tail_status, "%s", ls->tail_msg);
        bf_warn("%s", ls->tail_msg);
    }
    return BF_END;
}

/* The record's header holds its times and pose: the payload is not read.
 * A header that does not read leaves the frame to next(), which reports it. */
static bf_status log_pass(rgbd_source *base, double t_s, bf_frame *out)
{
    log__source *ls = (log__source *)base;
    if (ls->pos >= ls->base.n_frames) return BF_END;
    uint8_t b[LOG_FRAME_HEADER];
    size_t got = 0;
    log__frame_header h;
    if (read_at(ls, ls->offsets[ls->pos], b, sizeof b, &got) != BF_OK || got < LOG_FRAME_HEADER ||
        !log__frame_header_unpack(b, &h) || !(h.t_depth_s <= t_s))
        return BF_END;
    ls->pos++;
    bool has_pose = h.flags & LOG_FRAME_HAS_POSE;
    *out = (bf_frame){.index = h.index, .width = ls->hdr.K.width, .height = ls->hdr.K.height,
                      .t_depth_s = h.t_depth_s, .t_rgb_s = h.t_rgb_s, .has_pose = has_pose,
                      .T_wc = has_pose ? h.T_wc : bf_se3_identity()};
    return BF_OK;
}

static void log_close(rgbd_source *base)
{
    log__source *ls = (log__source *)base;
    if (ls->f) fclose(ls->f);
    ZSTD_freeDCtx(ls->zd);
    free(ls->offsets);
    free(ls->depth_payload);
    free(ls->rgb_payload);
    free(ls->depth);
    free(ls->rgb);
    free(ls->path);
    memset(ls, 0xff, sizeof *ls); /* poison: a use after close fails loudly */
    free(ls);
}

static const rgbd_source_ops log__ops = {.next = log_next, .close = log_close, .pass = log_pass};

bf_status replay__log_open(const char *path, const replay_options *opt, rgbd_source **out)
{
    replay_options defaults = {0};
    if (!opt) opt = &defaults;
    log__source *ls = bf_calloc(1, sizeof *ls);
    if (!ls) return bf_fail(BF_NO_MEMORY, "%s: log source", path);
    bf_status s = BF_OK;
    ls->tail_status = BF_END;
    ls->last_t_s = -INFINITY;
    if (!(ls->path = strdup(path))) {
        s = bf_fail(BF_NO_MEMORY, "%s: log source", path);
        goto fail;
    }
    ls->f = fopen(path, "rb");
    if (!ls->f) {
        s = bf_fail(BF_IO, "%s: cannot open: %s", path, strerror(errno));
        goto fail;
    }
    if (fseeko(ls->f, 0, SEEK_END) != 0 || ftello(ls->f) < 0) {
        s = bf_fail(BF_IO, "%s: cannot find the file's size: %s", path, strerror(errno));
        goto fail;
    }
    ls->file_size = (uint64_t)ftello(ls->f);
    if ((s = header_read(ls))) goto fail;
    ls->n_px = (size_t)ls->hdr.K.width * ls->hdr.K.height;
    ls->zd = ZSTD_createDCtx();
    ls->depth_payload = bf_malloc(log__depth_bound(ls->n_px));
    ls->rgb_payload = bf_malloc(log__rgb_bound(ls->n_px));
    ls->depth = bf_malloc(ls->n_px * sizeof *ls->depth);
    ls->rgb = bf_malloc(ls->n_px * 3);
    if (!ls->zd || !ls->depth_payload || !ls->rgb_payload || !ls->depth || !ls->rgb) {
        s = bf_fail(BF_NO_MEMORY, "%s: buffers for %ux%u frames", path, ls->hdr.K.width, ls->hdr.K.height);
        goto fail;
    }
    if ((s = index_read(ls))) goto fail;
    if (!ls->has_index) {
        if ((s = scan(ls))) goto fail;
        bf_debug("%s: no index; %u frames found by reading the records in order", path, ls->n);
    }
    bf_intrinsics K = ls->hdr.K;
    /* A log keeps its frames as recorded (a replay that recorded them had
     * taken any lens out): a preset gives its four numbers, a lens typed in
     * numbers is refused. */
    if (opt->camera && (s = replay_parse_camera(opt->camera, &K))) goto fail;
    if ((s = replay__camera_fits(&K, K.width, K.height, path, opt->camera ? "--camera" : "the log's header",
                                 opt->camera != NULL)))
        goto fail;
    if (opt->camera && replay__principal_point_is_off(&K, K.width, K.height))
        bf_warn("%s: --camera's principal point (%g, %g) lies far from the centre of the log's %ux%u images: is it "
                "for another image size?",
                path, K.cx_px, K.cy_px, K.width, K.height);
    if (opt->depth_scale > 0) K.depth_scale = opt->depth_scale;
    ls->skip_bad = opt->skip_bad_frames;
    ls->base.ops = &log__ops;
    ls->base.kind = "bflog";
    ls->base.intrinsics = K;
    ls->base.n_frames = opt->max_frames && ls->n > opt->max_frames ? opt->max_frames : ls->n;
    ls->base.has_groundtruth = ls->hdr.flags & LOG_HEADER_HAS_GROUNDTRUTH;
    /* A log whose frames are all unreadable still opens, like an empty one
     * (frames are checked as they are read); one without any frame is not
     * a sequence. */
    if (ls->n == 0 && ls->tail_status == BF_END) {
        if (ls->has_index)
            s = bf_fail(BF_FORMAT, "%s: the log holds no frames (recorded without any)", path);
        else
            s = bf_fail(BF_FORMAT, "%s: the log holds no whole frame (%llu bytes: header of %u, then %llu bytes of "
                              "frame 0); the recording was cut off before its first frame",
                    path, (unsigned long long)ls->file_size, ls->hdr.size,
                    (unsigned long long)(ls->file_size - ls->hdr.size));
        goto fail;
    }
    bf_debug("%s: bflog, %u frames, %ux%u, device '%s'%s", path, ls->n, K.width, K.height, ls->hdr.device,
             ls->has_index ? "" : ", no index");
    *out = &ls->base;
    return BF_OK;
fail:
    log_close(&ls->base);
    return s;
}

bf_status replay_log_seek(rgbd_source *src, uint32_t pos)
{
    if (!src || src->ops != &log__ops) return bf_fail(BF_INVALID_ARG, "seeking needs a bitfuse log source");
    log__source *ls = (log__source *)src;
    if (pos > ls->base.n_frames)
        return bf_fail(BF_INVALID_ARG, "%s: cannot seek to frame %u; the log has %u frames", ls->path, pos,
                       ls->base.n_frames);
    ls->pos = pos;
    ls->last_t_s = -INFINITY; /* the order is checked from here on */
    return BF_OK;
}

bool replay__log_sniff(const char *path)
{
    if (replay__is_dir(path)) return false;
    FILE *f = fopen(path, "rb");
    if (!f) return false;
    char m[LOG_MAGIC_LEN];
    bool is_log = fread(m, 1, sizeof m, f) == sizeof m && memcmp(m, LOG_MAGIC, LOG_MAGIC_LEN) == 0;
    fclose(f);
    return is_log;
}

uint32_t replay__log_skipped(const rgbd_source *src)
{
    return src && src->ops == &log__ops ? ((const log__source *)src)->n_skipped : 0;
}

bool replay_is_log_path(const char *path)
{
    size_t n = path ? strlen(path) : 0;
    return n > 6 && strcmp(path + n - 6, ".bflog") == 0;
}
