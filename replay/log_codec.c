/* replay: the pieces of the bitfuse log both its writer and reader use:
 * CRC-32, little-endian fields, the frame record header and JPEG in
 * memory. */
#include "log_int.h"

#include <pthread.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

#include <jpeglib.h>
#include <jerror.h>

/* ------------------------------------------------------------ CRC-32 */

/* Reflected polynomial 0xEDB88320 (IEEE 802.3), processed 8 bytes at a
 * time with 8 tables ("slicing-by-8", Kounavis and Berry, Intel 2005): a
 * frame's payload is hundreds of kilobytes, so the byte-wise loop would
 * cost about a millisecond per frame. */
static uint32_t crc_table[8][256];
static pthread_once_t crc_once = PTHREAD_ONCE_INIT;

static void crc_init(void)
{
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        crc_table[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; i++)
        for (int t = 1; t < 8; t++) crc_table[t][i] = (crc_table[t - 1][i] >> 8) ^ crc_table[0][crc_table[t - 1][i] & 0xff];
}

uint32_t log__crc32(uint32_t crc, const void *data, size_t n)
{
    pthread_once(&crc_once, crc_init);
    const uint8_t *p = data;
    uint32_t c = ~crc;
    while (n >= 8) {
        uint32_t a = c ^ ((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24);
        c = crc_table[7][a & 0xff] ^ crc_table[6][(a >> 8) & 0xff] ^ crc_table[5][(a >> 16) & 0xff] ^
            crc_table[4][a >> 24] ^ crc_table[3][p[4]] ^ crc_table[2][p[5]] ^ crc_table[1][p[6]] ^
            crc_table[0][p[7]];
        p += 8;
        n -= 8;
    }
    while (n--) c = crc_table[0][(c ^ *p++) & 0xff] ^ (c >> 8);
    return ~c;
}

/* ------------------------------------------------------------ fields */

void log__put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

void log__put_u64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

void log__put_f64(uint8_t *p, double v)
{
    uint64_t u;
    memcpy(&u, &v, sizeof u);
    log__put_u64(p, u);
}

uint32_t log__get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

uint64_t log__get_u64(const uint8_t *p)
{
    return (uint64_t)log__get_u32(p) | (uint64_t)log__get_u32(p + 4) << 32;
}

double log__get_f64(const uint8_t *p)
{
    uint64_t u = log__get_u64(p);
    double v;
    memcpy(&v, &u, sizeof v);
    return v;
}

/* ------------------------------------------------------------ frame header */

/* Offsets in the frame record header (docs/formats.md has the table). */
enum {
    FH_MAGIC = 0,
    FH_INDEX = 4,
    FH_FLAGS = 8,
    FH_DEPTH_CODEC = 12,
    FH_COLOUR_CODEC = 16,
    FH_DEPTH_SIZE = 20,
    FH_RGB_SIZE = 24,
    FH_RESERVED = 28,
    FH_T_DEPTH = 32,
    FH_T_RGB = 40,
    FH_R = 48,  /* 9 doubles, row-major */
    FH_T = 120, /* 3 doubles */
    FH_PAYLOAD_CRC = 144,
    FH_HEADER_CRC = 148,
};
_Static_assert(FH_HEADER_CRC + 4 == LOG_FRAME_HEADER, "frame header layout");

void log__frame_header_pack(const log__frame_header *h, uint8_t *b)
{
    memset(b, 0, LOG_FRAME_HEADER);
    log__put_u32(b + FH_MAGIC, LOG_FRAME_MAGIC);
    log__put_u32(b + FH_INDEX, h->index);
    log__put_u32(b + FH_FLAGS, h->flags);
    log__put_u32(b + FH_DEPTH_CODEC, h->depth_codec);
    log__put_u32(b + FH_COLOUR_CODEC, h->colour_codec);
    log__put_u32(b + FH_DEPTH_SIZE, h->depth_size);
    log__put_u32(b + FH_RGB_SIZE, h->rgb_size);
    log__put_f64(b + FH_T_DEPTH, h->t_depth_s);
    log__put_f64(b + FH_T_RGB, h->t_rgb_s);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) log__put_f64(b + FH_R + 8 * (3 * r + c), h->T_wc.R[r][c]);
    log__put_f64(b + FH_T, h->T_wc.t.x);
    log__put_f64(b + FH_T + 8, h->T_wc.t.y);
    log__put_f64(b + FH_T + 16, h->T_wc.t.z);
    log__put_u32(b + FH_PAYLOAD_CRC, h->payload_crc);
    log__put_u32(b + FH_HEADER_CRC, log__crc32(0, b, FH_HEADER_CRC));
}

bool log__frame_header_unpack(const uint8_t *b, log__frame_header *h)
{
    if (log__get_u32(b + FH_MAGIC) != LOG_FRAME_MAGIC) return false;
    if (log__get_u32(b + FH_HEADER_CRC) != log__crc32(0, b, FH_HEADER_CRC)) return false;
    h->index = log__get_u32(b + FH_INDEX);
    h->flags = log__get_u32(b + FH_FLAGS);
    h->depth_codec = log__get_u32(b + FH_DEPTH_CODEC);
    h->colour_codec = log__get_u32(b + FH_COLOUR_CODEC);
    h->depth_size = log__get_u32(b + FH_DEPTH_SIZE);
    h->rgb_size = log__get_u32(b + FH_RGB_SIZE);
    h->t_depth_s = log__get_f64(b + FH_T_DEPTH);
    h->t_rgb_s = log__get_f64(b + FH_T_RGB);
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) h->T_wc.R[r][c] = log__get_f64(b + FH_R + 8 * (3 * r + c));
    h->T_wc.t = bf_v3(log__get_f64(b + FH_T), log__get_f64(b + FH_T + 8), log__get_f64(b + FH_T + 16));
    h->payload_crc = log__get_u32(b + FH_PAYLOAD_CRC);
    return true;
}

/* ------------------------------------------------------------ bounds */

size_t log__depth_bound(size_t n_px) { return ZSTD_compressBound(2 * n_px); }

/* JPEG at quality 100 on noise can exceed the raw size a little (headers,
 * Huffman tables, worst-case code lengths); 64 KiB more than zstd's bound
 * covers it for any image that zstd's bound covers. */
size_t log__rgb_bound(size_t n_px) { return ZSTD_compressBound(3 * n_px) + 65536; }

/* ------------------------------------------------------------ JPEG */

typedef struct log_jpeg_err {
    struct jpeg_error_mgr mgr; /* first: libjpeg casts the pointer */
    jmp_buf jump;
    char msg[JMSG_LENGTH_MAX];
} log_jpeg_err;

static void log_jpeg_on_error(j_common_ptr cinfo)
{
    log_jpeg_err *e = (log_jpeg_err *)cinfo->err;
    cinfo->err->format_message(cinfo, e->msg);
    longjmp(e->jump, 1);
}

static void log_jpeg_on_message(j_common_ptr cinfo)
{
    char msg[JMSG_LENGTH_MAX];
    cinfo->err->format_message(cinfo, msg);
    bf_debug("libjpeg: %s", msg);
}

/* A destination of fixed size: a full buffer is an error, never a
 * reallocation (nothing allocated per frame, and a JPEG beyond the frame's
 * bound could not be read back anyway). */
static void dest_init(j_compress_ptr c) { (void)c; }
static boolean dest_full(j_compress_ptr c)
{
    ERREXIT(c, JERR_BUFFER_SIZE);
    return FALSE;
}
static void dest_term(j_compress_ptr c) { (void)c; }

/* The calls libjpeg may longjmp out of, in their own frame (as image.c). */
static void jpeg_encode_body(struct jpeg_compress_struct *c, struct jpeg_destination_mgr *dest, const uint8_t *rgb,
                             uint32_t w, uint32_t h, int quality)
{
    c->dest = dest;
    c->image_width = w;
    c->image_height = h;
    c->input_components = 3;
    c->in_color_space = JCS_RGB;
    jpeg_set_defaults(c);
    jpeg_set_quality(c, quality, TRUE);
    jpeg_start_compress(c, TRUE);
    while (c->next_scanline < h) {
        JSAMPROW row = (JSAMPROW)(rgb + (size_t)c->next_scanline * w * 3);
        jpeg_write_scanlines(c, &row, 1);
    }
    jpeg_finish_compress(c);
}

bf_status log__jpeg_encode(const uint8_t *rgb, uint32_t w, uint32_t h, int quality, uint8_t *out, size_t cap,
                           size_t *size, const char *what)
{
    struct jpeg_compress_struct c;
    log_jpeg_err err;
    memset(&c, 0, sizeof c);
    c.err = jpeg_std_error(&err.mgr);
    err.mgr.error_exit = log_jpeg_on_error;
    err.mgr.output_message = log_jpeg_on_message;
    err.msg[0] = '\0';
    struct jpeg_destination_mgr dest = {
        .next_output_byte = out,
        .free_in_buffer = cap,
        .init_destination = dest_init,
        .empty_output_buffer = dest_full,
        .term_destination = dest_term,
    };
    if (setjmp(err.jump)) {
        jpeg_destroy_compress(&c);
        return bf_fail(BF_FORMAT, "%s: JPEG encoder: %s", what, err.msg);
    }
    jpeg_create_compress(&c);
    jpeg_encode_body(&c, &dest, rgb, w, h, quality);
    jpeg_destroy_compress(&c);
    *size = cap - dest.free_in_buffer;
    return BF_OK;
}

static bf_status jpeg_decode_body(struct jpeg_decompress_struct *d, log_jpeg_err *err, const uint8_t *in,
                                  size_t size, uint32_t w, uint32_t h, uint8_t *rgb, const char *what)
{
    jpeg_mem_src(d, in, (unsigned long)size);
    jpeg_read_header(d, TRUE);
    if (d->image_width != w || d->image_height != h)
        return bf_fail(BF_FORMAT, "%s: colour JPEG is %ux%u, the log's frames are %ux%u", what,
                       (unsigned)d->image_width, (unsigned)d->image_height, w, h);
    d->out_color_space = JCS_RGB;
    jpeg_start_decompress(d);
    if (d->output_components != 3) return bf_fail(BF_FORMAT, "%s: colour JPEG does not decode to RGB", what);
    while (d->output_scanline < h) {
        JSAMPROW row = rgb + (size_t)d->output_scanline * w * 3;
        jpeg_read_scanlines(d, &row, 1);
    }
    /* libjpeg pads a truncated stream with grey and only warns. */
    if (err->mgr.num_warnings > 0) {
        char msg[JMSG_LENGTH_MAX];
        err->mgr.format_message((j_common_ptr)d, msg);
        return bf_fail(BF_FORMAT, "%s: corrupt colour JPEG (%s)", what, msg);
    }
    jpeg_finish_decompress(d);
    return BF_OK;
}

bf_status log__jpeg_decode(const uint8_t *in, size_t size, uint32_t w, uint32_t h, uint8_t *rgb, const char *what)
{
    struct jpeg_decompress_struct d;
    log_jpeg_err err;
    memset(&d, 0, sizeof d);
    d.err = jpeg_std_error(&err.mgr);
    err.mgr.error_exit = log_jpeg_on_error;
    err.mgr.output_message = log_jpeg_on_message;
    err.msg[0] = '\0';
    if (setjmp(err.jump)) {
        jpeg_destroy_decompress(&d);
        return bf_fail(BF_FORMAT, "%s: corrupt colour JPEG (%s)", what, err.msg);
    }
    jpeg_create_decompress(&d);
    bf_status s = jpeg_decode_body(&d, &err, in, size, w, h, rgb, what);
    jpeg_destroy_decompress(&d);
    return s;
}
