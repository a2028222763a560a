/* bitfuse replay --expect BASELINE.json [--tolerance ...]: a regression
 * gate for a user's CI. The run's stats.json measures are compared with
 * those of a baseline run's stats.json; a measure that moved beyond its
 * tolerance is named with both values and the command exits 1. A replay is
 * deterministic on one device (docs/determinism.md), so the defaults are
 * tight: the same input, options and device give the same numbers and map
 * digest exactly. Time is gated only when a tolerance for it is given. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"

typedef enum { MEASURE_ABS, MEASURE_SLOWER, MEASURE_EXACT } measure_kind;

typedef struct measure {
    const char *name;  /* as --tolerance names it */
    const char *path;  /* in stats.json, dot-separated */
    const char *unit;
    measure_kind kind; /* ABS: |now - baseline| <= tol; SLOWER: now <= baseline (1 + tol); EXACT: equal */
    double tol;        /* default; < 0: not gated unless --tolerance names it */
} measure;

static const measure measures[APP_EXPECT_MEASURES] = {
    {"ate", "ate_m.rmse", "m", MEASURE_ABS, 0.001},
    {"surface", "surface_m.median", "m", MEASURE_ABS, 0.001},
    {"digest", "map_digest", "", MEASURE_EXACT, 0},
    {"tracked", "tracking.tracked", "frames", MEASURE_ABS, 0},
    {"lost", "tracking.lost", "frames", MEASURE_ABS, 0},
    {"relocalised", "tracking.relocalised", "frames", MEASURE_ABS, 0},
    {"time", "frame_ms.median", "ms", MEASURE_SLOWER, -1},
};

static int measure_index(const char *name, size_t n)
{
    for (int i = 0; i < APP_EXPECT_MEASURES; i++)
        if (strlen(measures[i].name) == n && strncmp(measures[i].name, name, n) == 0) return i;
    return -1;
}

/* Parses one "name=value" of --tolerance (n bytes of item) into tol[];
 * NULL, or what is wrong with it. */
static const char *parse_item(const char *item, size_t n, double tol[APP_EXPECT_MEASURES])
{
    static char msg[256];
    const char *eq = memchr(item, '=', n);
    int i = eq ? measure_index(item, (size_t)(eq - item)) : -1;
    if (!eq || i < 0) {
        snprintf(msg, sizeof msg, "--tolerance: '%.*s' is not NAME=VALUE with NAME one of ate, surface, digest, "
                 "tracked, lost, relocalised, time", (int)n, item);
        return msg;
    }
    size_t vn = n - (size_t)(eq + 1 - item);
    char v[64];
    snprintf(v, sizeof v, "%.*s", (int)(vn < sizeof v ? vn : sizeof v - 1), eq + 1);
    if (strcmp(v, "off") == 0) {
        tol[i] = -1;
        return NULL;
    }
    char *end;
    double x = strtod(v, &end);
    if (measures[i].kind == MEASURE_EXACT) {
        snprintf(msg, sizeof msg, "--tolerance: %s is compared exactly: 'off' or nothing, not '%s'",
                 measures[i].name, v);
        return msg;
    }
    if (!v[0] || *end || !(x >= 0) || isinf(x)) {
        snprintf(msg, sizeof msg, "--tolerance: %s=%s: the tolerance must be a number >= 0 (%s%s) or 'off'",
                 measures[i].name, v, measures[i].kind == MEASURE_SLOWER ? "a fraction: 0.2 allows 20% slower" : "in ",
                 measures[i].kind == MEASURE_SLOWER ? "" : measures[i].unit);
        return msg;
    }
    tol[i] = x;
    return NULL;
}

static const char *parse_tolerance(const char *list, double tol[APP_EXPECT_MEASURES])
{
    for (int i = 0; i < APP_EXPECT_MEASURES; i++) tol[i] = measures[i].tol;
    for (const char *p = list; p && *p;) {
        const char *comma = strchr(p, ',');
        size_t n = comma ? (size_t)(comma - p) : strlen(p);
        const char *why = parse_item(p, n, tol);
        if (why) return why;
        p = comma ? comma + 1 : p + n;
    }
    return NULL;
}

const char *app_check_tolerance(const char *name, const char *value)
{
    (void)name;
    double tol[APP_EXPECT_MEASURES];
    return parse_tolerance(value, tol);
}

/* The value at path ("a.b") in o, NULL when absent. */
static const cJSON *at(const cJSON *o, const char *path)
{
    char key[64];
    while (o && *path) {
        size_t n = strcspn(path, ".");
        snprintf(key, sizeof key, "%.*s", (int)(n < sizeof key ? n : sizeof key - 1), path);
        o = cJSON_GetObjectItemCaseSensitive(o, key);
        path += n + (path[n] == '.');
    }
    return o && !cJSON_IsNull(o) ? o : NULL;
}

bf_status app_expect_load(app_expect *e, const char *path, const char *tolerance)
{
    memset(e, 0, sizeof *e);
    e->path = path;
    const char *why = parse_tolerance(tolerance, e->tol);
    if (why) return bf_fail(BF_INVALID_ARG, "%s", why);
    char *text = NULL;
    size_t n = 0;
    bf_status s = bf_read_file(path, &text, &n);
    if (s != BF_OK) {
        char why_read[512];
        snprintf(why_read, sizeof why_read, "%s", bf_last_error()); /* bf_fail writes the same buffer */
        return bf_fail(s, "--expect: %s", why_read);
    }
    const char *end = NULL;
    e->baseline = cJSON_ParseWithLengthOpts(text, n, &end, false);
    size_t tail = e->baseline ? bf_trailing_text(text, n, end) : n;
    if (tail < n) {
        cJSON_Delete(e->baseline);
        e->baseline = NULL;
        free(text);
        return bf_fail(BF_FORMAT, "%s: --expect: text after the JSON value at byte %zu", path, tail);
    }
    if (!e->baseline) {
        const char *err = cJSON_GetErrorPtr();
        size_t off = err && err >= text && err <= text + n ? (size_t)(err - text) : n;
        free(text);
        return bf_fail(BF_FORMAT, "%s: --expect: not JSON (byte %zu)", path, off);
    }
    free(text);
    bool has_any = false;
    for (int i = 0; i < APP_EXPECT_MEASURES; i++) has_any |= at(e->baseline, measures[i].path) != NULL;
    if (!cJSON_IsObject(e->baseline) || !has_any) {
        app_expect_free(e);
        return bf_fail(BF_FORMAT, "%s: --expect: not the stats.json of a bitfuse replay (none of ate_m, "
                       "map_digest, tracking, frame_ms in it)", path);
    }
    return BF_OK;
}

void app_expect_free(app_expect *e)
{
    cJSON_Delete(e->baseline);
    e->baseline = NULL;
}

static void describe(const cJSON *v, char *out, size_t cap)
{
    if (!v) snprintf(out, cap, "absent");
    else if (cJSON_IsString(v)) snprintf(out, cap, "%s", v->valuestring);
    else if (cJSON_IsNumber(v)) snprintf(out, cap, "%.6g", v->valuedouble);
    else snprintf(out, cap, "not a number");
}

/* Whether now is within tolerance of base (both present). */
static bool within(const measure *m, double tol, const cJSON *base, const cJSON *now)
{
    if (m->kind == MEASURE_EXACT)
        return cJSON_IsString(base) && cJSON_IsString(now) && strcmp(base->valuestring, now->valuestring) == 0;
    if (!cJSON_IsNumber(base) || !cJSON_IsNumber(now)) return false;
    double b = base->valuedouble, x = now->valuedouble;
    if (m->kind == MEASURE_SLOWER) return x <= b * (1 + tol);
    return fabs(x - b) <= tol;
}

uint32_t app_expect_check(const app_expect *e, cJSON *stats, char *why, size_t cap)
{
    cJSON *o = app_json_object(stats, "expect");
    cJSON_AddStringToObject(o, "baseline", e->path);
    cJSON *list = cJSON_AddObjectToObject(o, "measures");
    uint32_t n_moved = 0, n_gated = 0;
    size_t used = 0;
    if (cap) why[0] = 0;
    for (int i = 0; i < APP_EXPECT_MEASURES; i++) {
        const measure *m = &measures[i];
        const cJSON *base = at(e->baseline, m->path), *now = at(stats, m->path);
        if (e->tol[i] < 0 || !base) continue; /* not gated, or nothing to compare with */
        n_gated++;
        bool ok = now && within(m, e->tol[i], base, now);
        char b[96], x[96];
        describe(base, b, sizeof b);
        describe(now, x, sizeof x);
        cJSON *r = cJSON_AddObjectToObject(list, m->name);
        cJSON_AddStringToObject(r, "path", m->path);
        cJSON_AddItemToObject(r, "baseline", cJSON_Duplicate(base, true));
        cJSON_AddItemToObject(r, "now", now ? cJSON_Duplicate(now, true) : cJSON_CreateNull());
        if (m->kind != MEASURE_EXACT) cJSON_AddNumberToObject(r, "tolerance", e->tol[i]);
        cJSON_AddBoolToObject(r, "ok", ok);
        char tol[64] = "";
        if (m->kind == MEASURE_ABS)
            snprintf(tol, sizeof tol, ", tolerance %g%s%s", e->tol[i], *m->unit ? " " : "", m->unit);
        if (m->kind == MEASURE_SLOWER) snprintf(tol, sizeof tol, ", tolerance %g%% slower", 100 * e->tol[i]);
        /* The unit after a number only ("-> absent", not "-> absent m"). */
        bool unit = *m->unit && cJSON_IsNumber(now);
        printf("  expect %-11s %s -> %s%s%s%s: %s\n", m->name, b, x, unit ? " " : "", unit ? m->unit : "", tol,
               ok ? "ok" : "MOVED");
        if (ok) continue;
        n_moved++;
        if (used < cap) {
            int k = snprintf(why + used, cap - used, "%s%s %s -> %s%s", n_moved > 1 ? "; " : "", m->name, b, x, tol);
            used += k > 0 ? (size_t)k : 0;
        }
    }
    if (n_gated == 0) printf("  expect           nothing gated: %s holds none of the measures left on\n", e->path);
    cJSON_AddNumberToObject(o, "gated", n_gated);
    cJSON_AddNumberToObject(o, "moved", n_moved);
    cJSON_AddBoolToObject(o, "passed", n_moved == 0);
    return n_moved;
}
