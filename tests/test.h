/* A tiny test harness: tests register themselves, main runs them all (or
 * those whose name contains argv[1]) and prints "N passed, N failed".
 * Assertions print the expression and both values (libuv's test/task.h).
 * A test calls BF_SKIP("reason") when its data is absent; a binary whose
 * tests all skipped exits 77, which ctest reports as skipped. */
#ifndef BF_TEST_H
#define BF_TEST_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/core.h"

typedef struct bf_test_case {
    const char *name;
    void (*fn)(void);
} bf_test_case;

void bf__test_register(const char *name, void (*fn)(void));
void bf__test_fail(const char *file, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
void bf__test_skip(const char *reason);
extern int bf__test_failed_now;

#define BF_TEST(name)                                                        \
    static void test_##name(void);                                           \
    __attribute__((constructor)) static void test_reg_##name(void)          \
    {                                                                        \
        bf__test_register(#name, test_##name);                               \
    }                                                                        \
    static void test_##name(void)

/* Every check returns from the test on failure. */
#define CHECK(e)                                                             \
    do {                                                                     \
        if (!(e)) {                                                          \
            bf__test_fail(__FILE__, __LINE__, "CHECK(%s)", #e);              \
            return;                                                          \
        }                                                                    \
    } while (0)

#define CHECK_EQ_INT(a, b)                                                   \
    do {                                                                     \
        long long _a = (long long)(a), _b = (long long)(b);                  \
        if (_a != _b) {                                                      \
            bf__test_fail(__FILE__, __LINE__, "%s == %s: %lld != %lld", #a, #b, _a, _b); \
            return;                                                          \
        }                                                                    \
    } while (0)

#define CHECK_NEAR(a, b, tol)                                                \
    do {                                                                     \
        double _a = (double)(a), _b = (double)(b), _t = (double)(tol);       \
        if (!(fabs(_a - _b) <= _t)) {                                        \
            bf__test_fail(__FILE__, __LINE__, "%s ~ %s: %.9g vs %.9g (diff %.3g > tol %.3g)", \
                          #a, #b, _a, _b, fabs(_a - _b), _t);                \
            return;                                                          \
        }                                                                    \
    } while (0)

#define CHECK_LE(a, b)                                                       \
    do {                                                                     \
        double _a = (double)(a), _b = (double)(b);                           \
        if (!(_a <= _b)) {                                                   \
            bf__test_fail(__FILE__, __LINE__, "%s <= %s: %.9g > %.9g", #a, #b, _a, _b); \
            return;                                                          \
        }                                                                    \
    } while (0)

/* A status-returning call must give the expected status. */
#define CHECK_STATUS(call, expected)                                         \
    do {                                                                     \
        bf_status _s = (call);                                               \
        if (_s != (expected)) {                                              \
            bf__test_fail(__FILE__, __LINE__, "%s: got %s, want %s (%s)", #call, \
                          bf_status_name(_s), bf_status_name(expected), bf_last_error()); \
            return;                                                          \
        }                                                                    \
    } while (0)
#define CHECK_OK(call) CHECK_STATUS(call, BF_OK)

/* The last error message must contain the substring s. */
#define CHECK_ERROR_MENTIONS(s)                                              \
    do {                                                                     \
        if (!strstr(bf_last_error(), (s))) {                                 \
            bf__test_fail(__FILE__, __LINE__, "error message '%s' does not mention '%s'", \
                          bf_last_error(), (s));                             \
            return;                                                          \
        }                                                                    \
    } while (0)

#define BF_SKIP(reason)                                                      \
    do {                                                                     \
        bf__test_skip(reason);                                               \
        return;                                                              \
    } while (0)

/* Path of the shared real data (../shared/data relative to the source root),
 * or NULL when it is absent. sub is appended ("tum/frames"). */
const char *bf_test_data(const char *sub);
/* A fresh empty temporary directory for this test binary. */
const char *bf_test_tmpdir(void);

/* Fails each fault point that run(arg) reaches in turn (core's
 * bf_fault_arm; SQLite's fault-injection walk): every fired fault must come
 * back as BF_NO_MEMORY with a message, and the run after the last point
 * must succeed. run must release whatever it made either way (ASan checks
 * that nothing leaks). Returns the number of fault points walked, or -1
 * (with the offending point printed) on the first wrong outcome. */
int bf_test_fault_walk(bf_status (*run)(void *arg), void *arg);

#endif
