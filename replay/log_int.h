/* replay: the bitfuse log's layout and the helpers its writer (log_write.c)
 * and reader (log_read.c) share (log_codec.c). Private to replay/. The
 * format is described for users in docs/formats.md ("The bitfuse log").
 *
 * Everything is little-endian. A file is
 *   file header | frame record * n | index chunk | footer
 * and a log cut off anywhere after its header (a crash, a full disk) still
 * replays every frame record that is whole: each record carries its own
 * magic, sizes, a CRC32 of its header and a CRC32 of its payload. */
#ifndef BF_REPLAY_LOG_INT_H
#define BF_REPLAY_LOG_INT_H

#include "replay_int.h"

/* "\x89BFLOG\r\n": a high byte and CR LF catch 7-bit and text-mode copies
 * (the trick PNG's signature uses). */
#define LOG_MAGIC "\x89" "BFLOG\r\n"
#define LOG_MAGIC_LEN 8
#define LOG_VERSION 1u
#define LOG_FRAME_MAGIC 0x52464642u /* "BFFR" */
#define LOG_INDEX_MAGIC 0x58494642u /* "BFIX" */
#define LOG_FOOTER_MAGIC "BFLOGEND"

/* File header: fixed part, then the device string, then a CRC32 of both. */
#define LOG_HEADER_FIXED 80u     /* magic .. device_len */
#define LOG_DEVICE_MAX 1024u
/* Frame record header, then depth payload, then colour payload. */
#define LOG_FRAME_HEADER 152u
/* Index chunk: magic, count, entries of (offset u64, t_depth_s f64), CRC32. */
#define LOG_INDEX_ENTRY 16u
/* Footer: index offset u64, frame count u32, CRC32 of those 12 bytes,
 * magic. */
#define LOG_FOOTER 24u

/* Depth codec: zstd of the raw u16 little-endian image. Real Kinect depth
 * holds few distinct values (175 in a TUM fr2 frame: depth comes from
 * quantised disparity), which zstd's matches and literal coding exploit
 * directly; row deltas, byte planes and both together all came out worse
 * (docs/formats.md has the numbers). */
#define LOG_DEPTH_ZSTD 1u

/* Frame flags. */
#define LOG_FRAME_HAS_RGB 1u
#define LOG_FRAME_HAS_POSE 2u

/* Header flags. */
#define LOG_HEADER_HAS_GROUNDTRUTH 1u

/* Decoded header fields. */
typedef struct log__header {
    uint32_t version, size;   /* size: bytes up to the first frame record */
    bf_intrinsics K;
    uint32_t colour;          /* replay_log_colour */
    uint32_t depth_codec;
    uint32_t flags;
    char device[LOG_DEVICE_MAX + 1];
} log__header;

/* One decoded frame record header. */
typedef struct log__frame_header {
    uint32_t index;           /* the frame's index when it was recorded */
    uint32_t flags;
    uint32_t depth_codec, colour_codec;
    uint32_t depth_size, rgb_size; /* payload bytes */
    double t_depth_s, t_rgb_s;
    bf_se3 T_wc;              /* identity when no pose */
    uint32_t payload_crc;
} log__frame_header;

/* CRC-32 (IEEE 802.3, reflected, as zlib's crc32): crc = log__crc32(0, p, n)
 * and chained as log__crc32(crc, more, m). */
uint32_t log__crc32(uint32_t crc, const void *p, size_t n);

/* Little-endian stores and loads. */
void log__put_u32(uint8_t *p, uint32_t v);
void log__put_u64(uint8_t *p, uint64_t v);
void log__put_f64(uint8_t *p, double v);
uint32_t log__get_u32(const uint8_t *p);
uint64_t log__get_u64(const uint8_t *p);
double log__get_f64(const uint8_t *p);

/* Serialises a frame record header (LOG_FRAME_HEADER bytes, including the
 * header CRC in its last 4 bytes). */
void log__frame_header_pack(const log__frame_header *h, uint8_t *buf);
/* Checks magic and header CRC and decodes; false if either is wrong. */
bool log__frame_header_unpack(const uint8_t *buf, log__frame_header *h);

/* Largest payloads a frame of n_px pixels may have; the reader refuses
 * bigger sizes before it allocates or reads anything. */
size_t log__depth_bound(size_t n_px);
size_t log__rgb_bound(size_t n_px);

/* JPEG into / out of memory with libjpeg. encode writes at most cap bytes
 * into out (BF_NO_MEMORY if the image needs more); decode reads exactly a
 * w x h RGB image into rgb (BF_FORMAT with the library's message if the
 * stream is corrupt, truncated or of another size). what names the file and
 * frame in messages. */
bf_status log__jpeg_encode(const uint8_t *rgb, uint32_t w, uint32_t h, int quality, uint8_t *out, size_t cap,
                           size_t *size, const char *what);
bf_status log__jpeg_decode(const uint8_t *in, size_t size, uint32_t w, uint32_t h, uint8_t *rgb,
                           const char *what);

/* Opens a log as a replay source (replay_open dispatches here). */
bf_status replay__log_open(const char *path, const replay_options *opt, rgbd_source **out);
/* True if path is a regular file starting with the log's magic bytes. */
bool replay__log_sniff(const char *path);
/* Frames a log source skipped under skip_bad_frames; 0 for other sources. */
uint32_t replay__log_skipped(const rgbd_source *src);

#endif
