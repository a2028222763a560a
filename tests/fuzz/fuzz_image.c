/* Fuzz target: a depth or colour image (PNG, JPEG) through the decoders the
 * frame reader uses: 16-bit depth PNG, 8-bit RGB from PNG or JPEG, and the
 * header-only size probe. The input is the file; it reads if either
 * decoder takes it. */
#include <stdlib.h>

#include "fuzz.h"
#include "replay/replay_int.h"

bf_status fuzz_image(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write(fuzz_scratch(), "image", data, size);
    if (!path) return BF_IO;
    uint32_t w = 0, h = 0;
    bf_status first = replay__image_size(path, &w, &h);
    uint16_t *depth = NULL;
    bf_status s_depth = replay_png_read_u16(path, &depth, &w, &h);
    if (s_depth == BF_OK) free(depth);
    uint8_t *rgb = NULL;
    bf_status s = replay_image_read_rgb8(path, &rgb, &w, &h);
    if (s == BF_OK) free(rgb);
    if (first != BF_OK) return first;
    return s_depth == BF_OK ? BF_OK : s;
}

FUZZ_TARGET(fuzz_image)
