/* The fuzz targets' shared helpers (fuzz.h). */
#include "fuzz.h"

#include <ftw.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int fuzz_split(const uint8_t *data, size_t size, fuzz_part *parts, int cap)
{
    const size_t sep_n = sizeof FUZZ_SEP - 1;
    int k = 0;
    size_t start = 0;
    for (int i = 0; i < cap; i++) parts[i] = (fuzz_part){(const uint8_t *)"", 0};
    if (cap <= 0) return 0;
    for (size_t i = 0; k < cap - 1 && i + sep_n <= size; i++)
        if (memcmp(data + i, FUZZ_SEP, sep_n) == 0) {
            parts[k++] = (fuzz_part){data + start, i - start};
            start = i + sep_n;
            i = start - 1;
        }
    parts[k++] = (fuzz_part){data + start, size - start};
    return k;
}

static char scratch[512];

static int remove_one(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st, (void)flag;
    if (ftw->level > 0) remove(path);
    return 0;
}

static void scratch_remove(void)
{
    if (!scratch[0]) return;
    nftw(scratch, remove_one, 16, FTW_DEPTH | FTW_PHYS);
    rmdir(scratch);
}

const char *fuzz_scratch(void)
{
    if (!scratch[0]) {
        const char *base = getenv("TMPDIR");
        struct stat st;
        if (!base || !base[0]) base = stat("/dev/shm", &st) == 0 && S_ISDIR(st.st_mode) ? "/dev/shm" : "/tmp";
        snprintf(scratch, sizeof scratch, "%s/bitfuse-fuzz-%d", base, (int)getpid());
        mkdir(scratch, 0700);
        atexit(scratch_remove);
    }
    nftw(scratch, remove_one, 16, FTW_DEPTH | FTW_PHYS);
    return scratch;
}

const char *fuzz_scratch_name(void) { return scratch; }

const char *fuzz_write(const char *dir, const char *name, const void *p, size_t n)
{
    static char slots[8][4096];
    static int next;
    char *path = slots[next];
    next = (next + 1) % 8;
    if (bf_path_join(path, sizeof slots[0], dir, name) != BF_OK) return NULL;
    for (char *c = path + strlen(dir) + 1; *c; c++)
        if (*c == '/') {
            *c = '\0';
            mkdir(path, 0700);
            *c = '/';
        }
    FILE *f = fopen(path, "wb");
    if (!f) return NULL;
    bool ok = fwrite(p, 1, n, f) == n;
    ok &= fclose(f) == 0;
    return ok ? path : NULL;
}

void fuzz_quiet(void)
{
    static bool done;
    if (done) return;
    done = true;
    bf_log_set_level(BF_LOG_SILENT);
}

static volatile uint32_t fuzz_sink;

void fuzz_touch_frame(const bf_frame *f)
{
    uint32_t sum = 0;
    size_t n_px = (size_t)f->width * f->height;
    for (size_t i = 0; i < n_px; i++) sum += f->depth[i] + (f->rgb ? f->rgb[3 * i + 2] : 0u);
    fuzz_sink += sum;
}
