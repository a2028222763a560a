/* Helpers the fuzz targets share (docs/fuzz.md).
 *
 * Each target is a function fuzz_NAME(data, size) in fuzz_NAME.c that writes
 * the bytes where the real reader looks for them (a file, or a folder of
 * files) and calls that reader, returning its status. Built with
 * BITFUSE_FUZZ (clang) the file also defines libFuzzer's entry point
 * (FUZZ_TARGET); the regression test (test_fuzz.c) calls the same functions
 * on the seed corpora and on every input that once crashed a reader.
 *
 * Readers take paths, so the bytes go through a scratch folder under
 * $TMPDIR (else /dev/shm, else /tmp), emptied before each input. An input
 * for a folder reader holds several files, separated by FUZZ_SEP, in the
 * order the target documents. */
#ifndef BF_FUZZ_H
#define BF_FUZZ_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "core/core.h"

#define FUZZ_SEP "\n~~BFZ~~\n"

typedef struct fuzz_part {
    const uint8_t *p;
    size_t n;
} fuzz_part;

/* Splits data at FUZZ_SEP into up to cap parts (the last takes the rest);
 * the parts not present are empty. Returns how many were present. */
int fuzz_split(const uint8_t *data, size_t size, fuzz_part *parts, int cap);

/* A scratch folder, emptied (made on first use, removed at exit). The
 * string is static and stays valid. */
const char *fuzz_scratch(void);
/* Its name, without emptying it ("" before the first fuzz_scratch). */
const char *fuzz_scratch_name(void);

/* Writes n bytes to dir/name (name may hold folders, made as needed);
 * returns the full path in a static slot (one of 8, reused in turn), or
 * NULL where the name is unusable (too long) or the write failed. */
const char *fuzz_write(const char *dir, const char *name, const void *p, size_t n);

/* Reads every pixel of a frame (ASan then checks the frame is as large
 * as it says). */
void fuzz_touch_frame(const bf_frame *f);

/* Quiet logging (readers warn about every bad input) once per process. */
void fuzz_quiet(void);

/* The libFuzzer entry point for fn, only in the BITFUSE_FUZZ build. */
#ifdef BF_FUZZ_LIBFUZZER
#define FUZZ_TARGET(fn)                                                    \
    int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)          \
    {                                                                      \
        fuzz_quiet();                                                      \
        (void)fn(data, size);                                              \
        return 0;                                                          \
    }
#else
#define FUZZ_TARGET(fn)
#endif

bf_status fuzz_image(const uint8_t *data, size_t size);
bf_status fuzz_text(const uint8_t *data, size_t size);
bf_status fuzz_folder(const uint8_t *data, size_t size);
bf_status fuzz_bflog(const uint8_t *data, size_t size);
bf_status fuzz_mesh(const uint8_t *data, size_t size);
bf_status fuzz_store(const uint8_t *data, size_t size);
bf_status fuzz_calib(const uint8_t *data, size_t size);
bf_status fuzz_depthcorr(const uint8_t *data, size_t size);
bf_status fuzz_v4l2(const uint8_t *data, size_t size);
bf_status fuzz_expect(const uint8_t *data, size_t size);

#endif
