/* replay: the bitfuse log writer. Frames are compressed into buffers sized
 * at create (zstd's bound for the frame size) and handed to the OS with
 * write(2) frame by frame, so a process that dies loses at most the frame
 * being written (and a fault test's injected write failure reaches it:
 * tests/fault). The index of frame offsets grows in memory
 * (16 bytes a frame; the only growth while recording) and goes to the file
 * in finish(), followed by the footer that points at it. */
#include "log_int.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zstd.h>

struct replay_log_writer {
    char *path;      /* the log's name, in messages */
    char *disk_path; /* what is open: path, or path.partial until finish renames it */
    int fd;          /* -1: closed */
    bf_intrinsics K;
    replay_log_config cfg;
    size_t n_px;
    ZSTD_CCtx *zc;
    uint16_t *swapped;     /* n_px, big-endian hosts only: depth in file order */
    uint8_t *depth_buf;    /* log__depth_bound(n_px) */
    uint8_t *rgb_buf;      /* log__rgb_bound(n_px) */
    uint8_t *index;        /* LOG_INDEX_ENTRY per frame */
    size_t index_cap;      /* frames */
    uint64_t offset;       /* bytes written so far = next record's offset */
    replay_log_stats st;
    bool is_finished, is_broken;
    bool is_opened; /* disk_path is ours: created by this writer */
    int pending;    /* the .partial's slot among the files a signal removes (bf_pending_add), or -1 */
};

/* The file on disk goes (a log without a whole frame, an unfinished
 * .partial): no longer for a signal's handler to remove. */
static void remove_disk_file(replay_log_writer *w)
{
    bf_pending_forget(&w->pending);
    remove(w->disk_path);
}

/* After a failed write: a log that holds no whole frame is no log (it
 * would only fail to open), so it goes; one with frames stays, readable up
 * to its last whole frame. */
static void break_log(replay_log_writer *w)
{
    w->is_broken = true;
    if (w->st.n_frames == 0 && w->fd >= 0) {
        close(w->fd);
        w->fd = -1;
        remove_disk_file(w);
    }
}

/* All n bytes, short writes continued; a failure breaks the log for good. */
static bf_status write_bytes(replay_log_writer *w, const void *p, size_t n)
{
    const uint8_t *c = p;
    while (n > 0) {
        ssize_t k = write(w->fd, c, n);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) {
            bf_status s = bf_fail(BF_WRITE, "%s: write failed at byte %llu: %s", w->path,
                                  (unsigned long long)w->offset, k < 0 ? strerror(errno) : "nothing written");
            break_log(w);
            return s;
        }
        c += k;
        n -= (size_t)k;
        w->offset += (uint64_t)k;
    }
    return BF_OK;
}

bf_status replay_log_writer_create(const char *path, const bf_intrinsics *K, const replay_log_config *cfg,
                                   replay_log_writer **out)
{
    if (!path || !path[0] || !K || !cfg) return bf_fail(BF_INVALID_ARG, "log writer needs a path, intrinsics and a config");
    if (K->width == 0 || K->height == 0 || K->width > 16384 || K->height > 16384)
        return bf_fail(BF_INVALID_ARG, "%s: frame size %ux%u is outside 1..16384", path, K->width, K->height);
    if (!(isfinite(K->fx_px) && isfinite(K->fy_px) && isfinite(K->cx_px) && isfinite(K->cy_px) &&
          K->depth_scale > 0 && isfinite(K->depth_scale)))
        return bf_fail(BF_INVALID_ARG, "%s: invalid intrinsics for the log", path);
    if (cfg->colour != REPLAY_LOG_COLOUR_NONE && cfg->colour != REPLAY_LOG_COLOUR_ZSTD &&
        cfg->colour != REPLAY_LOG_COLOUR_JPEG)
        return bf_fail(BF_INVALID_ARG, "%s: unknown colour codec %d", path, (int)cfg->colour);
    if (cfg->jpeg_quality < 0 || cfg->jpeg_quality > 100)
        return bf_fail(BF_INVALID_ARG, "%s: JPEG quality %d is outside 1..100", path, cfg->jpeg_quality);
    if (cfg->zstd_level < 0 || cfg->zstd_level > ZSTD_maxCLevel())
        return bf_fail(BF_INVALID_ARG, "%s: zstd level %d is outside 1..%d", path, cfg->zstd_level,
                       ZSTD_maxCLevel());
    size_t dev_len = cfg->device ? strlen(cfg->device) : 0;
    if (dev_len > LOG_DEVICE_MAX) dev_len = LOG_DEVICE_MAX; /* a label: cut, not refused */

    /* A symbolic link is written through (bf_link_target): the finished
     * log's rename replaces the file it names, not the link. */
    char target[4096];
    bf_status sl = bf_link_target(path, target, sizeof target);
    if (sl != BF_OK) return sl;
    path = target;
    replay_log_writer *w = bf_calloc(1, sizeof *w);
    if (!w) return bf_fail(BF_NO_MEMORY, "%s: log writer", path);
    w->fd = -1;
    w->pending = -1;
    bf_status s = BF_OK;
    w->K = *K;
    w->cfg = *cfg;
    w->cfg.device = NULL;
    if (!w->cfg.jpeg_quality) w->cfg.jpeg_quality = 90;
    if (!w->cfg.zstd_level) w->cfg.zstd_level = 1;
    w->n_px = (size_t)K->width * K->height;
    w->path = strdup(path);
    size_t disk_len = strlen(path) + sizeof ".partial";
    w->disk_path = bf_malloc(disk_len);
    if (w->disk_path) snprintf(w->disk_path, disk_len, "%s%s", path, cfg->replace_when_finished ? ".partial" : "");
    w->zc = ZSTD_createCCtx();
    uint16_t probe = 1;
    bool is_le = *(uint8_t *)&probe == 1;
    w->swapped = is_le ? NULL : bf_malloc(2 * w->n_px);
    w->depth_buf = bf_malloc(log__depth_bound(w->n_px));
    w->rgb_buf = cfg->colour ? bf_malloc(log__rgb_bound(w->n_px)) : NULL;
    if (!w->path || !w->disk_path || !w->zc || (!is_le && !w->swapped) || !w->depth_buf ||
        (cfg->colour && !w->rgb_buf)) {
        s = bf_fail(BF_NO_MEMORY, "%s: log writer buffers for %ux%u frames", path, K->width, K->height);
        goto fail;
    }
    if (ZSTD_isError(ZSTD_CCtx_setParameter(w->zc, ZSTD_c_compressionLevel, w->cfg.zstd_level))) {
        s = bf_fail(BF_INVALID_ARG, "%s: zstd refuses level %d", path, w->cfg.zstd_level);
        goto fail;
    }
    /* Registered before it exists: a signal in between removes nothing. */
    if (cfg->replace_when_finished) w->pending = bf_pending_add(w->disk_path);
    w->fd = open(w->disk_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (w->fd < 0) {
        int e = errno;
        bf_pending_forget(&w->pending);
        s = bf_fail(BF_WRITE, "%s: cannot create: %s", w->disk_path, strerror(e));
        goto fail;
    }
    w->is_opened = true;
    uint8_t hdr[LOG_HEADER_FIXED + LOG_DEVICE_MAX + 4];
    memset(hdr, 0, sizeof hdr);
    memcpy(hdr, LOG_MAGIC, LOG_MAGIC_LEN);
    uint32_t hdr_size = LOG_HEADER_FIXED + (uint32_t)dev_len + 4;
    log__put_u32(hdr + 8, LOG_VERSION);
    log__put_u32(hdr + 12, hdr_size);
    log__put_u32(hdr + 16, K->width);
    log__put_u32(hdr + 20, K->height);
    log__put_f64(hdr + 24, K->fx_px);
    log__put_f64(hdr + 32, K->fy_px);
    log__put_f64(hdr + 40, K->cx_px);
    log__put_f64(hdr + 48, K->cy_px);
    log__put_f64(hdr + 56, K->depth_scale);
    log__put_u32(hdr + 64, (uint32_t)cfg->colour);
    log__put_u32(hdr + 68, LOG_DEPTH_ZSTD);
    log__put_u32(hdr + 72, cfg->has_groundtruth ? LOG_HEADER_HAS_GROUNDTRUTH : 0);
    log__put_u32(hdr + 76, (uint32_t)dev_len);
    if (dev_len) memcpy(hdr + LOG_HEADER_FIXED, cfg->device, dev_len);
    log__put_u32(hdr + LOG_HEADER_FIXED + dev_len, log__crc32(0, hdr, LOG_HEADER_FIXED + dev_len));
    if ((s = write_bytes(w, hdr, hdr_size))) goto fail;
    /* A recording written in place keeps its name through a power loss
     * from the start, so a crash-cut log is still there to replay (a
     * warning if the folder will not sync: the frames still go). */
    if (!cfg->replace_when_finished && bf_sync_parent(w->disk_path) != BF_OK) bf_warn("%s", bf_last_error());
    w->st.file_bytes = w->offset;
    *out = w;
    return BF_OK;
fail:
    if (w->fd >= 0) {
        close(w->fd);
        w->fd = -1;
        remove_disk_file(w); /* a header that never made it is no log */
    }
    replay_log_writer_destroy(w);
    return s;
}

bf_status replay_log_writer_add(replay_log_writer *w, const bf_frame *f)
{
    if (w->is_finished) return bf_fail(BF_INVALID_ARG, "%s: log already finished", w->path);
    if (w->is_broken) return bf_fail(BF_WRITE, "%s: an earlier write failed; the log ends before frame %u", w->path, f->index);
    if (!f->depth || f->width != w->K.width || f->height != w->K.height)
        return bf_fail(BF_INVALID_ARG, "%s: frame %u is %ux%u%s, the log's frames are %ux%u", w->path, f->index,
                       f->width, f->height, f->depth ? "" : " without depth", w->K.width, w->K.height);
    if (!isfinite(f->t_depth_s) || !isfinite(f->t_rgb_s))
        return bf_fail(BF_INVALID_ARG, "%s: frame %u: timestamps are not finite", w->path, f->index);
    if (f->has_pose && !bf_se3_is_finite(&f->T_wc))
        return bf_fail(BF_INVALID_ARG, "%s: frame %u: pose is not finite", w->path, f->index);
    if (w->st.n_frames == UINT32_MAX) return bf_fail(BF_INVALID_ARG, "%s: too many frames", w->path);
    if (w->st.n_frames == w->index_cap) {
        size_t cap = w->index_cap ? 2 * w->index_cap : 1024;
        uint8_t *p = bf_realloc(w->index, cap * LOG_INDEX_ENTRY);
        if (!p) return bf_fail(BF_NO_MEMORY, "%s: frame index of %zu entries", w->path, cap);
        w->index = p;
        w->index_cap = cap;
    }

    log__frame_header h = {
        .index = f->index,
        .flags = (f->has_pose ? LOG_FRAME_HAS_POSE : 0u),
        .depth_codec = LOG_DEPTH_ZSTD,
        .t_depth_s = f->t_depth_s,
        .t_rgb_s = f->t_rgb_s,
        .T_wc = f->has_pose ? f->T_wc : bf_se3_identity(),
    };
    const uint16_t *depth = f->depth;
    if (w->swapped) { /* the file is little-endian */
        for (size_t i = 0; i < w->n_px; i++) w->swapped[i] = (uint16_t)(f->depth[i] << 8 | f->depth[i] >> 8);
        depth = w->swapped;
    }
    size_t dz = ZSTD_compress2(w->zc, w->depth_buf, log__depth_bound(w->n_px), depth, 2 * w->n_px);
    if (ZSTD_isError(dz))
        return bf_fail(BF_NO_MEMORY, "%s: frame %u: zstd: %s", w->path, f->index, ZSTD_getErrorName(dz));
    h.depth_size = (uint32_t)dz;
    size_t rz = 0;
    if (f->rgb && w->cfg.colour != REPLAY_LOG_COLOUR_NONE) {
        h.flags |= LOG_FRAME_HAS_RGB;
        h.colour_codec = (uint32_t)w->cfg.colour;
        if (w->cfg.colour == REPLAY_LOG_COLOUR_ZSTD) {
            rz = ZSTD_compress2(w->zc, w->rgb_buf, log__rgb_bound(w->n_px), f->rgb, 3 * w->n_px);
            if (ZSTD_isError(rz))
                return bf_fail(BF_NO_MEMORY, "%s: frame %u: zstd: %s", w->path, f->index, ZSTD_getErrorName(rz));
        } else {
            char what[600];
            snprintf(what, sizeof what, "%s: frame %u", w->path, f->index);
            bf_status s = log__jpeg_encode(f->rgb, f->width, f->height, w->cfg.jpeg_quality, w->rgb_buf,
                                           log__rgb_bound(w->n_px), &rz, what);
            if (s != BF_OK) return s;
        }
        h.rgb_size = (uint32_t)rz;
    }
    h.payload_crc = log__crc32(log__crc32(0, w->depth_buf, dz), w->rgb_buf, rz);
    uint8_t hb[LOG_FRAME_HEADER];
    log__frame_header_pack(&h, hb);

    uint64_t at = w->offset;
    bf_status s;
    if ((s = write_bytes(w, hb, sizeof hb)) || (s = write_bytes(w, w->depth_buf, dz)) ||
        (s = write_bytes(w, w->rgb_buf, rz)))
        return s;
    uint8_t *e = w->index + (size_t)w->st.n_frames * LOG_INDEX_ENTRY;
    log__put_u64(e, at);
    log__put_f64(e + 8, f->t_depth_s);
    w->st.n_frames++;
    w->st.depth_raw_bytes += 2 * w->n_px;
    w->st.depth_bytes += dz;
    if (h.flags & LOG_FRAME_HAS_RGB) {
        w->st.rgb_raw_bytes += 3 * w->n_px;
        w->st.rgb_bytes += rz;
    }
    w->st.file_bytes = w->offset;
    return BF_OK;
}

bf_status replay_log_writer_finish(replay_log_writer *w)
{
    if (w->is_finished) return BF_OK;
    if (w->is_broken) return bf_fail(BF_WRITE, "%s: an earlier write failed; the log has no index", w->path);
    uint64_t index_at = w->offset;
    uint8_t head[8], tail[4], foot[LOG_FOOTER];
    log__put_u32(head, LOG_INDEX_MAGIC);
    log__put_u32(head + 4, w->st.n_frames);
    size_t n_bytes = (size_t)w->st.n_frames * LOG_INDEX_ENTRY;
    log__put_u32(tail, log__crc32(log__crc32(0, head, sizeof head), w->index, n_bytes));
    log__put_u64(foot, index_at);
    log__put_u32(foot + 8, w->st.n_frames);
    log__put_u32(foot + 12, log__crc32(0, foot, 12));
    memcpy(foot + 16, LOG_FOOTER_MAGIC, 8);
    bf_status s;
    if ((s = write_bytes(w, head, sizeof head)) || (s = write_bytes(w, w->index, n_bytes)) ||
        (s = write_bytes(w, tail, sizeof tail)) || (s = write_bytes(w, foot, sizeof foot)))
        return s;
    /* fsync: the footer claims the whole file is there; make it so before
     * anyone relies on it. */
    bool bad = fsync(w->fd) != 0;
    int err = errno;
    if (close(w->fd) != 0 && !bad) bad = true, err = errno;
    w->fd = -1;
    if (bad) {
        bf_status s = bf_fail(BF_WRITE, "%s: cannot finish the log: %s", w->path, strerror(err));
        if (w->st.n_frames == 0 || w->cfg.replace_when_finished) remove_disk_file(w);
        w->is_broken = true;
        return s;
    }
    if (w->cfg.replace_when_finished) {
        bf_pending_forget(&w->pending);
        if (rename(w->disk_path, w->path) != 0) {
            bf_status s = bf_fail(BF_WRITE, "%s: cannot put the finished log in place (from %s): %s", w->path,
                                  w->disk_path, strerror(errno));
            remove_disk_file(w);
            w->is_broken = true;
            return s;
        }
        /* The log is whole and in place: only the rename's durability is
         * in doubt if the folder's fsync fails, so that is a warning. */
        if (bf_sync_parent(w->path) != BF_OK) bf_warn("%s", bf_last_error());
    }
    w->st.file_bytes = w->offset;
    w->is_finished = true;
    return BF_OK;
}

replay_log_stats replay_log_writer_stats(const replay_log_writer *w) { return w->st; }

void replay_log_writer_destroy(replay_log_writer *w)
{
    if (!w) return;
    if (w->fd >= 0) close(w->fd);
    /* A conversion that did not finish is no result: what was at path stays. */
    if (!w->is_finished && w->cfg.replace_when_finished && w->is_opened) remove_disk_file(w);
    ZSTD_freeCCtx(w->zc);
    free(w->swapped);
    free(w->depth_buf);
    free(w->rgb_buf);
    free(w->index);
    free(w->path);
    free(w->disk_path);
    free(w);
}
