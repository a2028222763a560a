/* replay: PNG and JPEG codecs against libpng's simplified API, on real TUM
 * frames, and every way a file can be broken. */
#include <stdio.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

BF_TEST(png_reads_real_tum_depth_and_colour_like_an_independent_decoder)
{
    const char *dir = bf_test_data("tum/frames");
    if (!dir) BF_SKIP("tum/frames absent");
    char path[1024];
    snprintf(path, sizeof path, "%s/fr2_desk_a_depth.png", dir);
    uint16_t *d = NULL, *d_ref = NULL;
    uint32_t w, h, w2, h2;
    CHECK_OK(replay_png_read_u16(path, &d, &w, &h));
    CHECK(rt_png_read_u16(path, &d_ref, &w2, &h2));
    CHECK_EQ_INT(w, 640);
    CHECK_EQ_INT(h, 480);
    CHECK_EQ_INT(w2, w);
    CHECK_EQ_INT(h2, h);
    CHECK(memcmp(d, d_ref, (size_t)w * h * 2) == 0);
    /* A desk seen from about a metre: most pixels valid, depths 0.3-10 m. */
    size_t valid = 0;
    for (size_t i = 0; i < (size_t)w * h; i++)
        if (d[i]) {
            valid++;
            CHECK(d[i] >= 0.3 * 5000 && d[i] <= 10 * 5000);
        }
    CHECK(valid > (size_t)w * h / 2);
    free(d);
    free(d_ref);

    snprintf(path, sizeof path, "%s/fr2_desk_a_rgb.png", dir);
    uint8_t *c = NULL, *c_ref = NULL;
    CHECK_OK(replay_image_read_rgb8(path, &c, &w, &h));
    CHECK(rt_png_read_rgb8(path, &c_ref, &w2, &h2));
    CHECK_EQ_INT(w, 640);
    CHECK_EQ_INT(w2, w);
    CHECK_EQ_INT(h2, h);
    CHECK(memcmp(c, c_ref, (size_t)w * h * 3) == 0);
    free(c);
    free(c_ref);
}

BF_TEST(png_write_read_round_trip_is_bit_exact)
{
    enum { W = 67, H = 31 };
    static uint16_t d[W * H];
    static uint8_t c[W * H * 3];
    unsigned s = 7;
    for (int i = 0; i < W * H; i++) {
        s = s * 1103515245u + 12345u;
        d[i] = (uint16_t)(i == 0 ? 0 : i == 1 ? 65535 : s >> 16);
        c[3 * i] = (uint8_t)(s >> 8);
        c[3 * i + 1] = (uint8_t)(s >> 16);
        c[3 * i + 2] = (uint8_t)(s >> 24);
    }
    const char *pd = rt_tmp("rt_depth.png"), *pc = rt_tmp("rt_rgb.png");
    CHECK_OK(replay_png_write_u16(pd, d, W, H));
    CHECK_OK(replay_png_write_rgb8(pc, c, W, H));
    uint16_t *d2;
    uint8_t *c2;
    uint32_t w, h;
    CHECK_OK(replay_png_read_u16(pd, &d2, &w, &h));
    CHECK(w == W && h == H);
    CHECK(memcmp(d, d2, sizeof d) == 0);
    free(d2);
    CHECK(rt_png_read_u16(pd, &d2, &w, &h));
    CHECK(memcmp(d, d2, sizeof d) == 0);
    free(d2);
    CHECK_OK(replay_image_read_rgb8(pc, &c2, &w, &h));
    CHECK(w == W && h == H);
    CHECK(memcmp(c, c2, sizeof c) == 0);
    free(c2);
    /* Bad arguments are refused, not written. */
    CHECK_STATUS(replay_png_write_u16(rt_tmp("rt_zero.png"), d, 0, H), BF_INVALID_ARG);
    CHECK_STATUS(replay_png_write_u16("/nonexistent/dir/x.png", d, W, H), BF_WRITE);
    CHECK_ERROR_MENTIONS("/nonexistent/dir/x.png");
}

BF_TEST(jpeg_reads_by_content_and_corrupt_jpeg_is_format_error)
{
    enum { W = 64, H = 48 };
    static uint8_t c[W * H * 3];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            uint8_t *p = c + 3 * (y * W + x);
            p[0] = (uint8_t)(x * 4);
            p[1] = (uint8_t)(y * 5);
            p[2] = 128;
        }
    char pj[1024];
    snprintf(pj, sizeof pj, "%s", rt_tmp("img.jpg"));
    CHECK(rt_jpeg_write(pj, c, W, H, 95));
    uint8_t *c2;
    uint32_t w, h;
    CHECK_OK(replay_image_read_rgb8(pj, &c2, &w, &h));
    CHECK(w == W && h == H);
    /* Quality 95 on a smooth ramp: every channel within a few levels. */
    int max_err = 0;
    for (int i = 0; i < W * H * 3; i++) {
        int e = abs((int)c[i] - (int)c2[i]);
        if (e > max_err) max_err = e;
    }
    free(c2);
    CHECK_LE(max_err, 8);
    /* The same bytes under a .png name are still read as JPEG. */
    const char *renamed = rt_tmp("jpeg_named.png");
    CHECK(rt_copy_file(pj, renamed, SIZE_MAX));
    CHECK_OK(replay_image_read_rgb8(renamed, &c2, &w, &h));
    free(c2);
    /* Truncated at every tenth of the file: a status, never a crash. */
    size_t size = rt_file_size(pj);
    for (int k = 0; k < 10; k++) {
        const char *pt = rt_tmp("img_trunc.jpg");
        CHECK(rt_copy_file(pj, pt, size * (size_t)k / 10));
        bf_status s = replay_image_read_rgb8(pt, &c2, &w, &h);
        CHECK(s == BF_FORMAT);
        CHECK_ERROR_MENTIONS("img_trunc.jpg");
    }
    /* A JPEG is no depth image. */
    CHECK_STATUS(replay_png_read_u16(pj, (uint16_t **)&c2, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("img.jpg");
}

BF_TEST(truncated_png_is_format_error_at_every_length)
{
    const char *dir = bf_test_data("tum/frames");
    if (!dir) BF_SKIP("tum/frames absent");
    char src[1024];
    snprintf(src, sizeof src, "%s/fr2_desk_a_depth.png", dir);
    size_t size = rt_file_size(src);
    CHECK(size > 1000);
    const char *pt = rt_tmp("trunc_depth.png");
    /* Cut inside the signature, the header, the data and just before the
     * end chunk: each is BF_FORMAT naming the file (ASan checks no leak). */
    size_t cuts[] = {0, 4, 8, 20, 40, 100, size / 3, size / 2, size - 13, size - 1};
    for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
        CHECK(rt_copy_file(src, pt, cuts[k]));
        uint16_t *d = NULL;
        uint32_t w, h;
        bf_status s = replay_png_read_u16(pt, &d, &w, &h);
        if (s != BF_FORMAT) bf__test_fail(__FILE__, __LINE__, "cut at %zu: %s", cuts[k], bf_status_name(s));
        CHECK(s == BF_FORMAT);
        CHECK(d == NULL);
        CHECK_ERROR_MENTIONS("trunc_depth.png");
    }
}

BF_TEST(depth_png_with_wrong_bit_depth_or_colour_is_refused)
{
    enum { W = 8, H = 4 };
    uint8_t g[W * H] = {0};
    const char *p8 = rt_tmp("depth8.png");
    CHECK(rt_png_write_gray8(p8, g, W, H));
    uint16_t *d;
    uint32_t w, h;
    CHECK_STATUS(replay_png_read_u16(p8, &d, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("depth8.png");
    CHECK_ERROR_MENTIONS("8-bit");
    uint8_t c[W * H * 3] = {0};
    const char *pc = rt_tmp("depth_rgb.png");
    CHECK_OK(replay_png_write_rgb8(pc, c, W, H));
    CHECK_STATUS(replay_png_read_u16(pc, &d, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("colour");
    /* An 8-bit grey PNG is fine as colour: grey expands to RGB. */
    uint8_t *rgb;
    CHECK_OK(replay_image_read_rgb8(p8, &rgb, &w, &h));
    CHECK(w == W && h == H && rgb[0] == 0);
    free(rgb);
    CHECK_STATUS(replay_png_read_u16(rt_tmp("missing.png"), &d, &w, &h), BF_IO);
    CHECK_ERROR_MENTIONS("missing.png");
    CHECK(rt_write_text(rt_tmp("text.png"), "not an image\n"));
    CHECK_STATUS(replay_image_read_rgb8(rt_tmp("text.png"), &rgb, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("text.png");
}

BF_TEST(corrupt_png_data_is_format_error_naming_the_file)
{
    const char *dir = bf_test_data("tum/frames");
    if (!dir) BF_SKIP("tum/frames absent");
    char src[1024];
    snprintf(src, sizeof src, "%s/fr2_desk_b2_depth.png", dir);
    char *data;
    size_t size;
    CHECK_OK(bf_read_file(src, &data, &size));
    /* Flip bytes in the middle of the image data: a CRC or zlib error. */
    for (size_t i = size / 2; i < size / 2 + 16; i++) data[i] ^= 0x5a;
    const char *p = rt_tmp("corrupt_depth.png");
    FILE *f = fopen(p, "wb");
    CHECK(f);
    CHECK_EQ_INT(fwrite(data, 1, size, f), size);
    fclose(f);
    free(data);
    uint16_t *d = NULL;
    uint32_t w, h;
    CHECK_STATUS(replay_png_read_u16(p, &d, &w, &h), BF_FORMAT);
    CHECK(d == NULL);
    CHECK_ERROR_MENTIONS("corrupt_depth.png");
    CHECK_ERROR_MENTIONS("corrupt PNG");
}

BF_TEST(depth_must_be_png_and_colour_png_or_jpeg_by_content)
{
    static uint8_t c[8 * 6 * 3];
    const char *pj = rt_tmp("depth_as.jpg");
    CHECK(rt_jpeg_write(pj, c, 8, 6, 90));
    uint16_t *d;
    uint8_t *rgb;
    uint32_t w, h;
    /* A JPEG is colour, never depth. */
    CHECK_STATUS(replay_png_read_u16(pj, &d, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("depth image is a JPEG, not a 16-bit PNG");
    const char *pt = rt_tmp("colour_as.txt");
    CHECK(rt_write_text(pt, "not an image\n"));
    CHECK_STATUS(replay_image_read_rgb8(pt, &rgb, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not a PNG or JPEG file");
    CHECK_STATUS(replay_png_read_u16(pt, &d, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("depth image is not a PNG");
    /* A file cut to nothing says so, as depth and as colour. */
    const char *pe = rt_tmp("empty.png");
    CHECK(rt_write_text(pe, ""));
    CHECK_STATUS(replay_png_read_u16(pe, &d, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("empty file (0 bytes)");
    CHECK_STATUS(replay_image_read_rgb8(pe, &rgb, &w, &h), BF_FORMAT);
    CHECK_ERROR_MENTIONS("empty file (0 bytes)");
}
