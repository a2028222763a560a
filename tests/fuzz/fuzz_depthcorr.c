/* Fuzz target: the depth correction file (depth_correction.json, read by
 * replay, live and fuse --depth-correction) through calib_depth_read. The
 * input is the file. */
#include "calib/calib.h"
#include "fuzz.h"

bf_status fuzz_depthcorr(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write(fuzz_scratch(), "depth_correction.json", data, size);
    if (!path) return BF_IO;
    /* 19 KB: not on the fuzzer's stack. */
    static calib_depth_correction c;
    return calib_depth_read(path, &c);
}

FUZZ_TARGET(fuzz_depthcorr)
