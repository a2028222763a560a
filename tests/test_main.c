/* The harness behind tests/test.h. */
#include "test.h"

#include <stdarg.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/core.h"

#define MAX_TESTS 512
static bf_test_case tests[MAX_TESTS];
static int n_tests;
static int skipped_now;
int bf__test_failed_now;

void bf__test_register(const char *name, void (*fn)(void))
{
    if (n_tests < MAX_TESTS) tests[n_tests++] = (bf_test_case){name, fn};
}

void bf__test_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "  FAIL %s:%d: ", file, line);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    bf__test_failed_now = 1;
}

void bf__test_skip(const char *reason)
{
    fprintf(stderr, "  skip: %s\n", reason);
    skipped_now = 1;
}

const char *bf_test_data(const char *sub)
{
    static _Thread_local char path[4096];
    snprintf(path, sizeof path, "%s/../shared/data/%s", BF_SOURCE_DIR, sub ? sub : "");
    struct stat st;
    return stat(path, &st) == 0 ? path : NULL;
}

const char *bf_test_tmpdir(void)
{
    static char dir[256];
    if (!dir[0]) {
        const char *base = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/bitfuse-test-XXXXXX", base ? base : "/tmp");
        if (!mkdtemp(dir)) {
            perror("mkdtemp");
            exit(1);
        }
    }
    return dir;
}

int main(int argc, char **argv)
{
    int passed = 0, failed = 0, skipped = 0;
    for (int i = 0; i < n_tests; i++) {
        if (argc > 1 && !strstr(tests[i].name, argv[1])) continue;
        bf__test_failed_now = skipped_now = 0;
        bf_clear_error();
        fprintf(stderr, "[ RUN  ] %s\n", tests[i].name);
        tests[i].fn();
        if (bf__test_failed_now) {
            failed++;
            fprintf(stderr, "[ FAIL ] %s\n", tests[i].name);
        } else if (skipped_now) {
            skipped++;
            fprintf(stderr, "[ SKIP ] %s\n", tests[i].name);
        } else {
            passed++;
            fprintf(stderr, "[  OK  ] %s\n", tests[i].name);
        }
    }
    printf("%d passed, %d failed, %d skipped\n", passed, failed, skipped);
    if (failed) return 1;
    if (passed == 0 && skipped > 0) return 77;
    return 0;
}
