/* app/expect.c: replay --expect's gate on stats.json objects, without a
 * device (tests/app/test_determinism.sh runs it through the program). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app/app.h"
#include "test.h"

/* A stats.json of a replay with these measures. */
static cJSON *stats(double ate, const char *digest, int tracked, int lost, double frame_ms)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(cJSON_AddObjectToObject(o, "ate_m"), "rmse", ate);
    cJSON_AddStringToObject(o, "map_digest", digest);
    cJSON *t = cJSON_AddObjectToObject(o, "tracking");
    cJSON_AddNumberToObject(t, "tracked", tracked);
    cJSON_AddNumberToObject(t, "lost", lost);
    cJSON_AddNumberToObject(t, "relocalised", 0);
    cJSON_AddNumberToObject(cJSON_AddObjectToObject(o, "frame_ms"), "median", frame_ms);
    return o;
}

#define write_baseline(path, o) CHECK_OK(app_json_write(path, o)) /* takes o */

/* Measures that moved; 99 when the baseline does not load. */
static uint32_t gate(const char *base, const char *tolerance, cJSON *now, char *why, size_t cap)
{
    app_expect e;
    if (app_expect_load(&e, base, tolerance) != BF_OK) return 99;
    uint32_t n = app_expect_check(&e, now, why, cap);
    app_expect_free(&e);
    return n;
}

BF_TEST(expect_passes_equal_runs_and_names_what_moved)
{
    char base[600], why[1024];
    snprintf(base, sizeof base, "%s/base.json", bf_test_tmpdir());
    write_baseline(base, stats(0.0100, "xxh3:00000000000000aa", 100, 2, 50));
    cJSON *same = stats(0.0100, "xxh3:00000000000000aa", 100, 2, 90);
    CHECK_EQ_INT(gate(base, NULL, same, why, sizeof why), 0); /* time is not gated unless asked */
    cJSON *e = cJSON_GetObjectItem(same, "expect");
    CHECK(cJSON_IsTrue(cJSON_GetObjectItem(e, "passed")));
    CHECK_EQ_INT(cJSON_GetObjectItem(e, "gated")->valueint, 5);
    cJSON_Delete(same);
    /* Within the default 1 mm, and beyond it either way. */
    cJSON *near = stats(0.0105, "xxh3:00000000000000aa", 100, 2, 50);
    CHECK_EQ_INT(gate(base, NULL, near, why, sizeof why), 0);
    cJSON_Delete(near);
    cJSON *better = stats(0.0080, "xxh3:00000000000000bb", 101, 1, 50);
    CHECK_EQ_INT(gate(base, NULL, better, why, sizeof why), 4);
    CHECK(strstr(why, "ate 0.01 -> 0.008") != NULL);
    CHECK(strstr(why, "digest xxh3:00000000000000aa -> xxh3:00000000000000bb") != NULL);
    CHECK(strstr(why, "tracked 100 -> 101") != NULL);
    CHECK(strstr(why, "lost 2 -> 1") != NULL);
    CHECK(strstr(why, "relocalised") == NULL);
    cJSON_Delete(better);
}

BF_TEST(expect_tolerances_replace_defaults_and_time_fails_only_slower)
{
    char base[600], why[1024];
    snprintf(base, sizeof base, "%s/base2.json", bf_test_tmpdir());
    write_baseline(base, stats(0.0100, "xxh3:00000000000000aa", 100, 2, 50));
    cJSON *a = stats(0.0115, "xxh3:00000000000000cc", 100, 3, 61);
    CHECK_EQ_INT(gate(base, "ate=0.002,digest=off,lost=1,time=0.2", a, why, sizeof why), 1);
    CHECK(strstr(why, "time 50 -> 61") != NULL); /* 22% slower */
    cJSON_Delete(a);
    cJSON *faster = stats(0.0100, "xxh3:00000000000000aa", 100, 2, 10);
    CHECK_EQ_INT(gate(base, "time=0", faster, why, sizeof why), 0);
    cJSON_Delete(faster);
    /* A measure the baseline has and the run lacks has moved. */
    cJSON *no_ate = stats(0.01, "xxh3:00000000000000aa", 100, 2, 50);
    cJSON_ReplaceItemInObject(no_ate, "ate_m", cJSON_CreateNull());
    CHECK_EQ_INT(gate(base, NULL, no_ate, why, sizeof why), 1);
    CHECK(strstr(why, "ate 0.01 -> absent") != NULL);
    cJSON_Delete(no_ate);
}

BF_TEST(expect_refuses_bad_tolerances_and_baselines)
{
    CHECK(app_check_tolerance("--tolerance", "ate=0.002,surface=0.001,time=0.5,digest=off") == NULL);
    CHECK(app_check_tolerance("--tolerance", "ate=-1") != NULL);
    CHECK(app_check_tolerance("--tolerance", "ate=") != NULL);
    CHECK(app_check_tolerance("--tolerance", "ate=1x") != NULL);
    CHECK(app_check_tolerance("--tolerance", "ate=nan") != NULL);
    CHECK(app_check_tolerance("--tolerance", "speed=1") != NULL);
    CHECK(app_check_tolerance("--tolerance", "digest=1") != NULL);
    CHECK(app_check_tolerance("--tolerance", "ate") != NULL);
    app_expect e;
    char path[600];
    snprintf(path, sizeof path, "%s/absent.json", bf_test_tmpdir());
    CHECK_STATUS(app_expect_load(&e, path, NULL), BF_IO);
    CHECK_ERROR_MENTIONS("absent.json");
    snprintf(path, sizeof path, "%s/cut.json", bf_test_tmpdir());
    CHECK_OK(bf_write_file_atomic(path, "{\"ate_m\": {", 11));
    CHECK_STATUS(app_expect_load(&e, path, NULL), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not JSON");
    snprintf(path, sizeof path, "%s/two.json", bf_test_tmpdir());
    CHECK_OK(bf_write_file_atomic(path, "{\"ate_m\": {}} x", 15));
    CHECK_STATUS(app_expect_load(&e, path, NULL), BF_FORMAT);
    CHECK_ERROR_MENTIONS("text after the JSON value at byte 14");
    snprintf(path, sizeof path, "%s/other.json", bf_test_tmpdir());
    CHECK_OK(bf_write_file_atomic(path, "[1, 2]", 6));
    CHECK_STATUS(app_expect_load(&e, path, NULL), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not the stats.json of a bitfuse replay");
}
