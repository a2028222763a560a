/* Helpers shared by the replay tests (test_util.c). */
#ifndef BF_REPLAY_TEST_H
#define BF_REPLAY_TEST_H

#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "core/core.h"

/* A path in the test binary's temporary folder: tmp/name (static buffer
 * per call slot: the result of the last 8 calls stay valid). */
const char *rt_tmp(const char *name);
/* Writes text to path (creating folders); false on failure. */
bool rt_write_text(const char *path, const char *text);
/* Copies the first n bytes of src to dst (n = SIZE_MAX: whole file). */
bool rt_copy_file(const char *src, const char *dst, size_t n);
size_t rt_file_size(const char *path);
/* A fresh empty folder tmp/name. */
const char *rt_fresh_dir(const char *name);

/* Independent decoders: libpng's simplified png_image API, a different code
 * path from replay/image.c. */
bool rt_png_read_u16(const char *path, uint16_t **pix, uint32_t *w, uint32_t *h);
bool rt_png_read_rgb8(const char *path, uint8_t **pix, uint32_t *w, uint32_t *h);
/* Writes an 8-bit grey PNG (a wrong depth image). */
bool rt_png_write_gray8(const char *path, const uint8_t *pix, uint32_t w, uint32_t h);
/* Writes an RGB JPEG at the given quality with libjpeg. */
bool rt_jpeg_write(const char *path, const uint8_t *rgb, uint32_t w, uint32_t h, int quality);

/* dir/name as a symbolic link to target (real data stays where it is). */
bool rt_link(const char *target, const char *dir, const char *name);
/* Path of dir/name in a static slot (as rt_tmp). */
const char *rt_join(const char *dir, const char *name);

/* Opens the sequence or log at path (a char *), reads every frame and
 * closes it: the status of the first failure, or BF_OK (a fault-walk run). */
bf_status rt_read_all(void *path);

#endif
