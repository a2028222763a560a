/* The harness behind tests/test.h. */
#include "test.h"

#include <ftw.h>
#include <stdarg.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/core.h"

/* Sanitizer builds, for every test binary that may open a Vulkan device. */

#if defined(__SANITIZE_ADDRESS__)
#define TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TEST_ASAN 1
#endif
#endif
#ifdef TEST_ASAN
#include <dlfcn.h>
/* The Khronos validation layer (1.3.239 on Debian 12) leaves some 25 KB of
 * C++ allocations behind per context; with validation off these tests leak
 * nothing (checked under ASan). The loader unloads the layer in
 * vkDestroyInstance, after which LeakSanitizer cannot name the module an
 * allocation came from, so a suppression by module cannot match. Pinning the
 * layer (RTLD_NODELETE, RTLD_LOCAL: no symbol interposition) keeps it mapped
 * until exit; the suppression then drops exactly the allocations made inside
 * it. Ours never pass through the layer and stay reported. */
__attribute__((constructor)) static void pin_validation_layer(void)
{
    dlopen("libVkLayer_khronos_validation.so", RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE); /* absent: nothing to pin */
    /* lavapipe (Mesa 22.3.6-1+deb12u2) keeps caches in its own globals; once
     * the loader unloads it they look like leaks from an unknown module.
     * Pinned, they stay reachable and are not reported; the driver frees
     * nothing of ours, so our leaks are still found. */
    dlopen("libvulkan_lvp.so", RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
}
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void) { return "leak:libVkLayer_khronos_validation.so\n"; }
#endif


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

static char tmpdir[256];

const char *bf_test_tmpdir(void)
{
    if (!tmpdir[0]) {
        const char *base = getenv("TMPDIR");
        snprintf(tmpdir, sizeof tmpdir, "%s/bitfuse-test-XXXXXX", base ? base : "/tmp");
        if (!mkdtemp(tmpdir)) {
            perror("mkdtemp");
            exit(1);
        }
    }
    return tmpdir;
}

int bf_test_fault_walk(bf_status (*run)(void *arg), void *arg)
{
    for (uint32_t k = 1; k < 1000000; k++) {
        bf_fault_arm(k);
        bf_clear_error();
        bf_status s = run(arg);
        bool is_fired = bf_fault_arm(0) == 0;
        if (!is_fired) {
            if (s == BF_OK) return (int)k - 1; /* past the last point: a clean run */
            fprintf(stderr, "  fault walk: the run without a fault failed: %s: %s\n", bf_status_name(s),
                    bf_last_error());
            return -1;
        }
        if (s != BF_NO_MEMORY || !bf_last_error()[0]) {
            fprintf(stderr, "  fault walk: point %u gave %s (\"%s\"), want BF_NO_MEMORY with a message\n", k,
                    bf_status_name(s), bf_last_error());
            return -1;
        }
    }
    return -1;
}

static int rm_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st;
    (void)flag;
    (void)ftw;
    return remove(path);
}

/* Removes the temporary directory unless a test failed (then it is kept
 * for inspection and its path printed). */
static void cleanup_tmpdir(const char *dir, int failed)
{
    if (!dir[0]) return;
    if (failed || getenv("BITFUSE_KEEP_TMP")) {
        fprintf(stderr, "test files kept in %s\n", dir);
        return;
    }
    nftw(dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
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
    cleanup_tmpdir(tmpdir, failed);
    printf("%d passed, %d failed, %d skipped\n", passed, failed, skipped);
    if (failed) return 1;
    if (passed == 0 && skipped > 0) return 77;
    return 0;
}
