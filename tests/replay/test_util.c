/* Helpers shared by the replay tests. */
#include <png.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <jpeglib.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

const char *rt_tmp(const char *name)
{
    static char slots[8][1024];
    static int next;
    char *p = slots[next++ & 7];
    snprintf(p, 1024, "%s/%s", bf_test_tmpdir(), name);
    return p;
}

bool rt_write_text(const char *path, const char *text)
{
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash) {
        *slash = '\0';
        if (bf_mkdir_p(dir)) return false;
    }
    FILE *f = fopen(path, "w");
    if (!f) return false;
    fputs(text, f);
    return fclose(f) == 0;
}

bool rt_copy_file(const char *src, const char *dst, size_t n)
{
    char *data;
    size_t size;
    if (bf_read_file(src, &data, &size)) return false;
    if (n < size) size = n;
    FILE *f = fopen(dst, "wb");
    bool ok = f && fwrite(data, 1, size, f) == size;
    if (f && fclose(f) != 0) ok = false;
    free(data);
    return ok;
}

size_t rt_file_size(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 ? (size_t)st.st_size : 0;
}

const char *rt_fresh_dir(const char *name)
{
    const char *p = rt_tmp(name);
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", p);
    if (system(cmd) != 0) return NULL;
    return bf_mkdir_p(p) ? NULL : p;
}

static bool png_image_read(const char *path, uint32_t format, size_t px_bytes, void **pix, uint32_t *w,
                           uint32_t *h)
{
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, path)) return false;
    img.format = format;
    void *buf = malloc((size_t)img.width * img.height * px_bytes);
    if (!buf || !png_image_finish_read(&img, NULL, buf, 0, NULL)) {
        free(buf);
        png_image_free(&img);
        return false;
    }
    *pix = buf;
    *w = img.width;
    *h = img.height;
    return true;
}

bool rt_png_read_u16(const char *path, uint16_t **pix, uint32_t *w, uint32_t *h)
{
    /* A 16-bit grey file is taken as linear: values pass through as is. */
    return png_image_read(path, PNG_FORMAT_LINEAR_Y, 2, (void **)pix, w, h);
}

bool rt_png_read_rgb8(const char *path, uint8_t **pix, uint32_t *w, uint32_t *h)
{
    return png_image_read(path, PNG_FORMAT_RGB, 3, (void **)pix, w, h);
}

bool rt_png_write_gray8(const char *path, const uint8_t *pix, uint32_t w, uint32_t h)
{
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    img.width = w;
    img.height = h;
    img.format = PNG_FORMAT_GRAY;
    return png_image_write_to_file(&img, path, 0, pix, 0, NULL) != 0;
}

bool rt_jpeg_write(const char *path, const uint8_t *rgb, uint32_t w, uint32_t h, int quality)
{
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    struct jpeg_compress_struct c;
    struct jpeg_error_mgr err;
    c.err = jpeg_std_error(&err);
    jpeg_create_compress(&c);
    jpeg_stdio_dest(&c, f);
    c.image_width = w;
    c.image_height = h;
    c.input_components = 3;
    c.in_color_space = JCS_RGB;
    jpeg_set_defaults(&c);
    jpeg_set_quality(&c, quality, TRUE);
    jpeg_start_compress(&c, TRUE);
    while (c.next_scanline < h) {
        JSAMPROW row = (JSAMPROW)(rgb + (size_t)c.next_scanline * w * 3);
        jpeg_write_scanlines(&c, &row, 1);
    }
    jpeg_finish_compress(&c);
    jpeg_destroy_compress(&c);
    return fclose(f) == 0;
}

const char *rt_join(const char *dir, const char *name)
{
    static char slots[8][1024];
    static int next;
    char *p = slots[next++ & 7];
    snprintf(p, 1024, "%s/%s", dir, name);
    return p;
}

bool rt_link(const char *target, const char *dir, const char *name)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    char sub[1024];
    snprintf(sub, sizeof sub, "%s", path);
    char *slash = strrchr(sub, '/');
    *slash = '\0';
    if (bf_mkdir_p(sub)) return false;
    unlink(path);
    return symlink(target, path) == 0;
}

bf_status rt_read_all(void *path)
{
    rgbd_source *src;
    bf_status s = replay_open(path, NULL, &src);
    if (s != BF_OK) return s;
    bf_frame f;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
    }
    rgbd_source_close(src);
    return s == BF_END ? BF_OK : s;
}
