/* Fuzz target: replay --expect BASELINE.json (an earlier run's stats.json)
 * through app_expect_load, then the gate itself, app_expect_check, which
 * looks the measures up by name in the baseline and in this run's stats and
 * compares them whatever their types and values, and the stats as replay
 * then prints them. app/expect.c is compiled into the target as it is into
 * the program.
 *
 * The input: BASELINE.json [~~BFZ~~ the --tolerance value [~~BFZ~~ this
 * run's stats.json]]. Without the tolerance the defaults hold (as without
 * --tolerance); without this run's stats (or where they are not a JSON
 * object: the program always builds an object) the baseline is compared
 * with a copy of itself, as a rerun of the same input would be. */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app/app.h"
#include "fuzz.h"

/* The check prints a line per measure on stdout: into /dev/null here (the
 * fuzzer's log would otherwise take gigabytes), the formatting still run. */
static uint32_t check_quietly(const app_expect *e, cJSON *stats, char *why, size_t cap)
{
    static int null_fd = -2;
    if (null_fd == -2) null_fd = open("/dev/null", O_WRONLY | O_CLOEXEC);
    fflush(stdout);
    int saved = null_fd >= 0 ? dup(STDOUT_FILENO) : -1;
    if (saved >= 0) dup2(null_fd, STDOUT_FILENO);
    uint32_t n = app_expect_check(e, stats, why, cap);
    fflush(stdout);
    if (saved >= 0) {
        dup2(saved, STDOUT_FILENO);
        close(saved);
    }
    return n;
}

bf_status fuzz_expect(const uint8_t *data, size_t size)
{
    fuzz_part part[3];
    int n_parts = fuzz_split(data, size, part, 3);
    const char *path = fuzz_write(fuzz_scratch(), "baseline.json", part[0].p, part[0].n);
    if (!path) return BF_IO;
    /* The option's value as the command line hands it: up to a NUL. */
    char *tolerance = NULL;
    if (n_parts >= 2) {
        tolerance = malloc(part[1].n + 1);
        if (!tolerance) return BF_NO_MEMORY;
        memcpy(tolerance, part[1].p, part[1].n);
        tolerance[part[1].n] = '\0';
    }
    app_expect e;
    bf_status s = app_expect_load(&e, path, tolerance);
    free(tolerance);
    if (s != BF_OK) return s;
    cJSON *now = n_parts >= 3 ? cJSON_ParseWithLength((const char *)part[2].p, part[2].n) : NULL;
    if (!cJSON_IsObject(now)) {
        cJSON_Delete(now);
        now = cJSON_Duplicate(e.baseline, true);
    }
    if (now) {
        char moved[2048]; /* replay's size */
        (void)check_quietly(&e, now, moved, sizeof moved);
        /* The run's stats.json, now holding copies of the baseline's values,
         * printed as app_json_write prints it. */
        cJSON_free(cJSON_Print(now));
        cJSON_Delete(now);
    }
    app_expect_free(&e);
    return BF_OK;
}

FUZZ_TARGET(fuzz_expect)
