/* Fuzz target: the calibration file (calib.json, read by replay
 * --calibration and eval-colour) through calib_read. The input is the file. */
#include "calib/calib.h"
#include "fuzz.h"

bf_status fuzz_calib(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write(fuzz_scratch(), "calib.json", data, size);
    if (!path) return BF_IO;
    calib_result r;
    return calib_read(path, &r);
}

FUZZ_TARGET(fuzz_calib)
