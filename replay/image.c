/* replay: PNG (libpng) and JPEG (libjpeg) codecs.
 *
 * Both libraries report errors by longjmp from an error callback; each
 * decoder sets the jump target before any library call, keeps the state the
 * error path needs in variables set before setjmp (or volatile), and turns
 * the library's message into a status naming the file. A truncated or
 * corrupt file is BF_FORMAT; nothing calls exit() or leaks.
 *
 * Decoding writes into a caller's buffer so file sources reuse one buffer
 * for every frame; the libraries' own decoder state is theirs to allocate. */
#include "replay_int.h"

#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <jpeglib.h>

/* Images larger than this are refused as malformed headers. */
#define REPLAY_MAX_SIDE 16384u

typedef enum image_kind { IMAGE_PNG, IMAGE_JPEG, IMAGE_OTHER, IMAGE_EMPTY } image_kind;

/* Opens path and sniffs its first bytes. A PNG's stream is left after its
 * 8-byte signature, which the decoder is told it has seen, so a PNG may come
 * through a pipe (no seek); any other stream is rewound, which a pipe
 * cannot be: refused, said so. */
static bf_status image_open(const char *path, FILE **fp, image_kind *kind)
{
    FILE *f = fopen(path, "rb");
    if (!f) return bf_fail(BF_IO, "%s: cannot open: %s", path, strerror(errno));
    unsigned char sig[8] = {0};
    size_t n = fread(sig, 1, sizeof sig, f);
    if (n < sizeof sig && ferror(f)) { /* EIO, or a folder: not an empty file */
        int e = errno;
        fclose(f);
        return bf_fail(BF_IO, "%s: cannot read: %s", path, strerror(e));
    }
    if (n >= 8 && png_sig_cmp(sig, 0, 8) == 0)
        *kind = IMAGE_PNG;
    else if (n >= 3 && sig[0] == 0xFF && sig[1] == 0xD8 && sig[2] == 0xFF)
        *kind = IMAGE_JPEG;
    else if (n == 0)
        *kind = IMAGE_EMPTY;
    else
        *kind = IMAGE_OTHER;
    if (*kind != IMAGE_PNG && fseek(f, 0, SEEK_SET) != 0) {
        int e = errno;
        fclose(f);
        return bf_fail(BF_IO, "%s: cannot seek back after its first bytes (%s): only a PNG may come through a pipe",
                       path, strerror(e));
    }
    *fp = f;
    return BF_OK;
}

/* ------------------------------------------------------------ PNG */

typedef struct png_err {
    const char *path;
    char msg[256];
} png_err;

static void png_on_error(png_structp png, png_const_charp msg)
{
    png_err *e = png_get_error_ptr(png);
    snprintf(e->msg, sizeof e->msg, "%s", msg);
    png_longjmp(png, 1);
}

static void png_on_warning(png_structp png, png_const_charp msg)
{
    png_err *e = png_get_error_ptr(png);
    bf_debug("%s: libpng: %s", e->path, msg);
}

typedef enum png_want { PNG_WANT_HEADER, PNG_WANT_U16, PNG_WANT_RGB8 } png_want;

/* The work between setjmp and teardown, in its own frame so that a longjmp
 * out of libpng clobbers nothing the caller still reads. An allocation is
 * published through *owned at once, for the error path to free. */
static bf_status png_decode_body(png_structp png, png_infop info, const char *path, png_want want, void *buf,
                                 size_t cap_px, void *volatile *owned, bool do_alloc, uint32_t exp_w,
                                 uint32_t exp_h, uint32_t *w_out, uint32_t *h_out)
{
    png_set_user_limits(png, REPLAY_MAX_SIDE, REPLAY_MAX_SIDE);
    png_read_info(png, info);
    png_uint_32 w, h;
    int depth, color, interlace;
    png_get_IHDR(png, info, &w, &h, &depth, &color, &interlace, NULL, NULL);
    *w_out = (uint32_t)w;
    *h_out = (uint32_t)h;
    if (want == PNG_WANT_HEADER) return BF_OK;
    if (exp_w && (w != exp_w || h != exp_h))
        return bf_fail(BF_FORMAT, "%s: image is %ux%u, expected %ux%u like the sequence's depth images", path,
                       (unsigned)w, (unsigned)h, exp_w, exp_h);
    size_t px_size;
    if (want == PNG_WANT_U16) {
        if (color != PNG_COLOR_TYPE_GRAY || depth != 16)
            return bf_fail(BF_FORMAT, "%s: depth PNG must be 16-bit greyscale, found %d-bit %s", path, depth,
                           color == PNG_COLOR_TYPE_GRAY         ? "greyscale"
                           : color == PNG_COLOR_TYPE_GRAY_ALPHA ? "greyscale+alpha"
                           : color == PNG_COLOR_TYPE_PALETTE    ? "palette"
                                                                : "colour");
        uint16_t probe = 1;
        if (*(uint8_t *)&probe == 1) png_set_swap(png); /* PNG is big-endian */
        px_size = 2;
    } else {
        if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
        if (color == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
        if (color == PNG_COLOR_TYPE_GRAY || color == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
        if (depth == 16) png_set_scale_16(png);
        if (color & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
        px_size = 3;
    }
    int passes = png_set_interlace_handling(png);
    png_read_update_info(png, info);
    size_t row_bytes = (size_t)w * px_size;
    if (png_get_rowbytes(png, info) != row_bytes)
        return bf_fail(BF_FORMAT, "%s: unsupported PNG layout (%d-bit, colour type %d)", path, depth, color);
    if (do_alloc) {
        buf = *owned = bf_malloc(row_bytes * h);
        if (!buf) return bf_fail(BF_NO_MEMORY, "%s: image of %ux%u", path, (unsigned)w, (unsigned)h);
    } else if ((size_t)w * h > cap_px) {
        return bf_fail(BF_FORMAT, "%s: image of %ux%u does not fit the buffer", path, (unsigned)w, (unsigned)h);
    }
    for (int pass = 0; pass < passes; pass++)
        for (png_uint_32 y = 0; y < h; y++) png_read_row(png, (png_bytep)buf + y * row_bytes, NULL);
    png_read_end(png, NULL);
    return BF_OK;
}

/* The one PNG decoder. With PNG_WANT_HEADER only the size is read. buf is
 * either a caller's buffer of cap_px pixels or, with alloc set, ignored and
 * the pixels are malloc'd to the image size (returned through *alloc). */
static bf_status png_decode(FILE *f, const char *path, png_want want, void *buf, size_t cap_px, void **alloc,
                            uint32_t exp_w, uint32_t exp_h, uint32_t *w_out, uint32_t *h_out)
{
    png_err err = {.path = path};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &err, png_on_error, png_on_warning);
    if (!png) return bf_fail(BF_NO_MEMORY, "%s: cannot create a PNG decoder", path);
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_read_struct(&png, NULL, NULL);
        return bf_fail(BF_NO_MEMORY, "%s: cannot create a PNG decoder", path);
    }
    void *volatile owned = NULL;
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, NULL);
        free(owned);
        if (feof(f)) return bf_fail(BF_FORMAT, "%s: truncated PNG (the file ends early)", path);
        return bf_fail(BF_FORMAT, "%s: corrupt PNG (%s)", path, err.msg);
    }
    png_init_io(png, f);
    png_set_sig_bytes(png, 8); /* image_open read them */
    uint32_t w = 0, h = 0;
    bf_status s = png_decode_body(png, info, path, want, buf, cap_px, &owned, alloc != NULL, exp_w, exp_h, &w, &h);
    png_destroy_read_struct(&png, &info, NULL);
    if (s != BF_OK) {
        free(owned);
        return s;
    }
    if (alloc) *alloc = owned;
    *w_out = w;
    *h_out = h;
    return BF_OK;
}

/* ------------------------------------------------------------ JPEG */

typedef struct jpeg_err {
    struct jpeg_error_mgr mgr; /* first: libjpeg casts the pointer */
    jmp_buf jump;
    char msg[JMSG_LENGTH_MAX];
} jpeg_err;

static void jpeg_on_error(j_common_ptr cinfo)
{
    jpeg_err *e = (jpeg_err *)cinfo->err;
    cinfo->err->format_message(cinfo, e->msg);
    longjmp(e->jump, 1);
}

/* libjpeg's default prints warnings (corrupt data it recovered from). */
static void jpeg_on_message(j_common_ptr cinfo)
{
    char msg[JMSG_LENGTH_MAX];
    cinfo->err->format_message(cinfo, msg);
    bf_debug("libjpeg: %s", msg);
}

/* As png_decode_body: everything libjpeg may longjmp out of. */
static bf_status jpeg_decode_body(struct jpeg_decompress_struct *cinfo, jpeg_err *err, const char *path,
                                  bool header_only, uint8_t *buf, size_t cap_px, uint8_t *volatile *owned,
                                  bool do_alloc, uint32_t exp_w, uint32_t exp_h, uint32_t *w_out, uint32_t *h_out)
{
    jpeg_read_header(cinfo, TRUE);
    uint32_t w = cinfo->image_width, h = cinfo->image_height;
    *w_out = w;
    *h_out = h;
    if (w == 0 || h == 0 || w > REPLAY_MAX_SIDE || h > REPLAY_MAX_SIDE)
        return bf_fail(BF_FORMAT, "%s: JPEG size %ux%u is out of range", path, w, h);
    if (header_only) return BF_OK;
    if (exp_w && (w != exp_w || h != exp_h))
        return bf_fail(BF_FORMAT, "%s: image is %ux%u, expected %ux%u like the sequence's depth images", path, w,
                       h, exp_w, exp_h);
    if (cinfo->jpeg_color_space == JCS_CMYK || cinfo->jpeg_color_space == JCS_YCCK)
        return bf_fail(BF_FORMAT, "%s: CMYK JPEG is not supported", path);
    if (do_alloc) {
        buf = *owned = bf_malloc((size_t)w * h * 3);
        if (!buf) return bf_fail(BF_NO_MEMORY, "%s: image of %ux%u", path, w, h);
    } else if ((size_t)w * h > cap_px) {
        return bf_fail(BF_FORMAT, "%s: image of %ux%u does not fit the buffer", path, w, h);
    }
    cinfo->out_color_space = JCS_RGB;
    jpeg_start_decompress(cinfo);
    if (cinfo->output_components != 3 || cinfo->output_width != w || cinfo->output_height != h)
        return bf_fail(BF_FORMAT, "%s: JPEG does not decode to RGB", path);
    while (cinfo->output_scanline < h) {
        JSAMPROW row = buf + (size_t)cinfo->output_scanline * w * 3;
        jpeg_read_scanlines(cinfo, &row, 1);
    }
    /* A truncated stream makes libjpeg pad with grey and only warn: treat
     * the warning as the corruption it is. */
    if (err->mgr.num_warnings > 0) {
        char msg[JMSG_LENGTH_MAX];
        err->mgr.format_message((j_common_ptr)cinfo, msg);
        return bf_fail(BF_FORMAT, "%s: corrupt or truncated JPEG (%s)", path, msg);
    }
    jpeg_finish_decompress(cinfo);
    return BF_OK;
}

static bf_status jpeg_decode(FILE *f, const char *path, bool header_only, uint8_t *buf, size_t cap_px,
                             void **alloc, uint32_t exp_w, uint32_t exp_h, uint32_t *w_out, uint32_t *h_out)
{
    struct jpeg_decompress_struct cinfo;
    jpeg_err err;
    memset(&cinfo, 0, sizeof cinfo);
    cinfo.err = jpeg_std_error(&err.mgr);
    err.mgr.error_exit = jpeg_on_error;
    err.mgr.output_message = jpeg_on_message;
    err.msg[0] = '\0';
    uint8_t *volatile owned = NULL;
    if (setjmp(err.jump)) {
        jpeg_destroy_decompress(&cinfo);
        free(owned);
        return bf_fail(BF_FORMAT, "%s: corrupt or truncated JPEG (%s)", path, err.msg);
    }
    jpeg_create_decompress(&cinfo);
    jpeg_stdio_src(&cinfo, f);
    uint32_t w = 0, h = 0;
    bf_status s = jpeg_decode_body(&cinfo, &err, path, header_only, buf, cap_px, &owned, alloc != NULL, exp_w,
                                   exp_h, &w, &h);
    /* destroy also aborts a decompression left half-way. */
    jpeg_destroy_decompress(&cinfo);
    if (s != BF_OK) {
        free(owned);
        return s;
    }
    if (alloc) *alloc = owned;
    *w_out = w;
    *h_out = h;
    return BF_OK;
}

/* ------------------------------------------------------------ entry points */

/* Opens path, decodes it by its content and closes it. PNG_WANT_U16 takes
 * PNG only (depth); RGB8 and the header also take JPEG. */
static bf_status image_read(const char *path, png_want want, void *buf, size_t cap_px, void **alloc,
                            uint32_t exp_w, uint32_t exp_h, uint32_t *w, uint32_t *h)
{
    FILE *f = NULL;
    image_kind kind = IMAGE_OTHER;
    bf_status s = image_open(path, &f, &kind);
    if (s != BF_OK) return s;
    if (kind == IMAGE_PNG)
        s = png_decode(f, path, want, buf, cap_px, alloc, exp_w, exp_h, w, h);
    else if (kind == IMAGE_JPEG && want != PNG_WANT_U16)
        s = jpeg_decode(f, path, want == PNG_WANT_HEADER, buf, cap_px, alloc, exp_w, exp_h, w, h);
    else if (kind == IMAGE_EMPTY)
        s = bf_fail(BF_FORMAT, "%s: empty file (0 bytes)", path);
    else if (kind == IMAGE_JPEG)
        s = bf_fail(BF_FORMAT, "%s: depth image is a JPEG, not a 16-bit PNG (JPEG cannot hold depth)", path);
    else if (want == PNG_WANT_U16)
        s = bf_fail(BF_FORMAT, "%s: depth image is not a PNG", path);
    else
        s = bf_fail(BF_FORMAT, "%s: not a PNG or JPEG file", path);
    fclose(f);
    return s;
}

bf_status replay__image_size(const char *path, uint32_t *w, uint32_t *h)
{
    return image_read(path, PNG_WANT_HEADER, NULL, 0, NULL, 0, 0, w, h);
}

static bf_status read_u16(const char *path, uint16_t *buf, size_t cap_px, void **alloc, uint32_t exp_w,
                          uint32_t exp_h, uint32_t *w, uint32_t *h)
{
    return image_read(path, PNG_WANT_U16, buf, cap_px, alloc, exp_w, exp_h, w, h);
}

static bf_status read_rgb8(const char *path, uint8_t *buf, size_t cap_px, void **alloc, uint32_t exp_w,
                           uint32_t exp_h, uint32_t *w, uint32_t *h)
{
    return image_read(path, PNG_WANT_RGB8, buf, cap_px, alloc, exp_w, exp_h, w, h);
}

bf_status replay__png_decode_u16(const char *path, uint16_t *buf, size_t cap_px, uint32_t exp_w, uint32_t exp_h,
                                 uint32_t *w, uint32_t *h)
{
    return read_u16(path, buf, cap_px, NULL, exp_w, exp_h, w, h);
}

bf_status replay__image_decode_rgb8(const char *path, uint8_t *buf, size_t cap_px, uint32_t exp_w, uint32_t exp_h,
                                    uint32_t *w, uint32_t *h)
{
    return read_rgb8(path, buf, cap_px, NULL, exp_w, exp_h, w, h);
}

bf_status replay_png_read_u16(const char *path, uint16_t **pix, uint32_t *w, uint32_t *h)
{
    void *p = NULL;
    uint32_t ww, hh;
    bf_status s = read_u16(path, NULL, 0, &p, 0, 0, &ww, &hh);
    if (s != BF_OK) return s;
    *pix = p;
    *w = ww;
    *h = hh;
    return BF_OK;
}

bf_status replay_image_read_rgb8(const char *path, uint8_t **pix, uint32_t *w, uint32_t *h)
{
    void *p = NULL;
    uint32_t ww, hh;
    bf_status s = read_rgb8(path, NULL, 0, &p, 0, 0, &ww, &hh);
    if (s != BF_OK) return s;
    *pix = p;
    *w = ww;
    *h = hh;
    return BF_OK;
}

/* ------------------------------------------------------------ PNG writing */

static void png_put(png_structp png, png_bytep data, size_t n) { bf_out_write(png_get_io_ptr(png), data, n); }
static void png_no_flush(png_structp png) { (void)png; }

/* Through core's bf_out (a temporary file, fsync, rename), so a reader
 * never sees half a PNG. */
static bf_status png_write(const char *path, const void *pix, uint32_t w, uint32_t h, bool is_u16)
{
    if (!pix || w == 0 || h == 0 || w > REPLAY_MAX_SIDE || h > REPLAY_MAX_SIDE)
        return bf_fail(BF_INVALID_ARG, "%s: cannot write a %ux%u image", path, w, h);
    bf_out out;
    bf_out *o = &out;
    bf_status s = bf_out_open(o, path);
    if (s != BF_OK) return s;
    png_err err = {.path = path};
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &err, png_on_error, png_on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!info) {
        png_destroy_write_struct(&png, NULL);
        bf_out_abort(o);
        return bf_fail(BF_NO_MEMORY, "%s: cannot create a PNG encoder", path);
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        bf_out_abort(o);
        return bf_fail(BF_WRITE, "%s: cannot write PNG (%s)", path, err.msg);
    }
    png_set_write_fn(png, o, png_put, png_no_flush);
    /* Level 3: close to the default's size at a fraction of its time. */
    png_set_compression_level(png, 3);
    png_set_IHDR(png, info, w, h, is_u16 ? 16 : 8, is_u16 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    if (is_u16) {
        uint16_t probe = 1;
        if (*(uint8_t *)&probe == 1) png_set_swap(png);
    }
    size_t row_bytes = (size_t)w * (is_u16 ? 2 : 3);
    for (uint32_t y = 0; y < h; y++) png_write_row(png, (png_const_bytep)pix + y * row_bytes);
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    return bf_out_commit(o);
}

bf_status replay_png_write_u16(const char *path, const uint16_t *pix, uint32_t w, uint32_t h)
{
    return png_write(path, pix, w, h, true);
}

bf_status replay_png_write_rgb8(const char *path, const uint8_t *pix, uint32_t w, uint32_t h)
{
    return png_write(path, pix, w, h, false);
}
