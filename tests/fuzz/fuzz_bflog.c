/* Fuzz target: a bitfuse log (.bflog: header, frame records, index,
 * footer) through replay_open and the frame reader, every frame read, then
 * a seek and the rest read again.
 *
 * Byte 0 of the input is options, the rest is the file:
 *   bit 0: recompute the checksums (header, each record's header and
 *          payload, index, footer) where the layout lets them be found, so
 *          that mutations reach the code behind the checks; without it the
 *          checks themselves are fuzzed;
 *   bit 1: --skip-bad-frames;
 *   bits 2-6: the frame to seek to after the first pass (modulo frames + 1);
 *   bit 7: the file is named log.bin, found as a log by its magic bytes
 *          (else log.bflog, by its name). */
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "replay/log_int.h"

_Static_assert(LOG_FRAME_HEADER == 152, "the frame record layout below (docs/formats.md)");

/* The record header's fields this needs: sizes, payload CRC, header CRC. */
#define REC_DEPTH_SIZE 20u
#define REC_RGB_SIZE 24u
#define REC_PAYLOAD_CRC 144u
#define REC_HEADER_CRC 148u

static void fix_checksums(uint8_t *b, size_t n)
{
    if (n < LOG_HEADER_FIXED + 4) return;
    uint32_t dev_len = log__get_u32(b + 76);
    if (dev_len > LOG_DEVICE_MAX || LOG_HEADER_FIXED + dev_len + 4 > n) return;
    log__put_u32(b + LOG_HEADER_FIXED + dev_len, log__crc32(0, b, LOG_HEADER_FIXED + dev_len));
    size_t at = LOG_HEADER_FIXED + dev_len + 4;
    while (at + LOG_FRAME_HEADER <= n && log__get_u32(b + at) == LOG_FRAME_MAGIC) {
        uint8_t *r = b + at;
        uint64_t payload = (uint64_t)log__get_u32(r + REC_DEPTH_SIZE) + log__get_u32(r + REC_RGB_SIZE);
        if (payload <= n - at - LOG_FRAME_HEADER)
            log__put_u32(r + REC_PAYLOAD_CRC, log__crc32(0, r + LOG_FRAME_HEADER, (size_t)payload));
        log__put_u32(r + REC_HEADER_CRC, log__crc32(0, r, REC_HEADER_CRC));
        if (payload > n - at - LOG_FRAME_HEADER) return;
        at += LOG_FRAME_HEADER + (size_t)payload;
    }
    /* Index chunk (magic, count, entries, CRC) and footer (offset, count,
     * CRC, magic). */
    if (at + 8 > n || log__get_u32(b + at) != LOG_INDEX_MAGIC) return;
    uint64_t count = log__get_u32(b + at + 4);
    if (count > (n - at - 8) / LOG_INDEX_ENTRY) return;
    size_t crc_at = at + 8 + (size_t)count * LOG_INDEX_ENTRY;
    if (crc_at + 4 > n) return;
    log__put_u32(b + crc_at, log__crc32(0, b + at, crc_at - at));
    if (crc_at + 4 + LOG_FOOTER <= n) {
        uint8_t *foot = b + crc_at + 4;
        log__put_u32(foot + 12, log__crc32(0, foot, 12));
    }
}

static bf_status read_to_end(rgbd_source *src)
{
    bf_frame frame;
    bf_status s;
    while ((s = rgbd_source_next(src, &frame)) == BF_OK) fuzz_touch_frame(&frame);
    return s == BF_END ? BF_OK : s;
}

bf_status fuzz_bflog(const uint8_t *data, size_t size)
{
    if (size < 1) return BF_INVALID_ARG;
    uint8_t flags = data[0];
    uint8_t *file = bf_malloc(size - 1 ? size - 1 : 1);
    if (!file) return BF_NO_MEMORY;
    memcpy(file, data + 1, size - 1);
    if (flags & 1) fix_checksums(file, size - 1);
    const char *path = fuzz_write(fuzz_scratch(), flags & 0x80 ? "log.bin" : "log.bflog", file, size - 1);
    free(file);
    if (!path) return BF_IO;
    replay_options opt = {.skip_bad_frames = flags & 2};
    rgbd_source *src = NULL;
    bf_status s = replay_open(path, &opt, &src);
    if (s != BF_OK) return s;
    s = read_to_end(src);
    bf_status s2 = replay_log_seek(src, ((flags >> 2) & 31u) % (src->n_frames + 1));
    if (s2 == BF_OK) s2 = read_to_end(src);
    rgbd_source_close(src);
    return s != BF_OK ? s : s2;
}

FUZZ_TARGET(fuzz_bflog)
