/* app/json.c: what stats.json and --json are built with. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "app/app.h"
#include "recon/recon.h"
#include "test.h"

/* Reads path back with cJSON; NULL if it does not parse. */
static cJSON *read_json(const char *path)
{
    char *text;
    if (bf_read_file(path, &text, NULL) != BF_OK) return NULL;
    cJSON *o = cJSON_Parse(text);
    free(text);
    return o;
}

BF_TEST(json_writes_nan_as_null_and_escapes_strings)
{
    char dir[512];
    snprintf(dir, sizeof dir, "%s", bf_test_tmpdir());
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "name", "a\"b\\c\nd\x01/");
    cJSON_AddNumberToObject(o, "nan", NAN);
    cJSON_AddNumberToObject(o, "inf", -INFINITY);
    cJSON_AddNumberToObject(o, "t", 1305031098.665925);
    bf_stats empty = {0};
    app_json_series(o, "empty", &empty);
    CHECK_OK(app_json_write_in(dir, "x.json", o));
    char path[600];
    snprintf(path, sizeof path, "%s/x.json", dir);
    cJSON *back = read_json(path);
    CHECK(back != NULL);
    CHECK(!strcmp(cJSON_GetObjectItem(back, "name")->valuestring, "a\"b\\c\nd\x01/"));
    CHECK(cJSON_IsNull(cJSON_GetObjectItem(back, "nan")));
    CHECK(cJSON_IsNull(cJSON_GetObjectItem(back, "inf")));
    CHECK(cJSON_GetObjectItem(back, "t")->valuedouble == 1305031098.665925); /* microseconds kept */
    CHECK(cJSON_IsNull(cJSON_GetObjectItem(cJSON_GetObjectItem(back, "empty"), "median")));
    cJSON_Delete(back);
    /* A folder that does not exist: the status says so. */
    CHECK_STATUS(app_json_write("/nonexistent/dir/file.json", cJSON_CreateObject()), BF_WRITE);
}

BF_TEST(json_config_echoes_every_field_as_it_was_set)
{
    recon_config c = recon_config_default();
    c.fusion.voxel_ratio = 0.1f;
    c.track.levels = 2;
    cJSON *o = cJSON_CreateObject();
    app_json_recon_config(o, "config", &c);
    cJSON *cfg = cJSON_GetObjectItem(o, "config");
    cJSON *f = cJSON_GetObjectItem(cfg, "fusion"), *t = cJSON_GetObjectItem(cfg, "track");
    CHECK(f && t && cJSON_GetObjectItem(cfg, "loop"));
    /* 0.1f is written 0.1, not 0.100000001. */
    char *text = cJSON_PrintUnformatted(f);
    CHECK(strstr(text, "\"voxel_ratio\":0.1,") != NULL);
    cJSON_free(text);
    CHECK_EQ_INT(cJSON_GetArraySize(f), 21);  /* every field of fusion_config */
    CHECK_EQ_INT(cJSON_GetArraySize(t), 35);  /* every field of track_config */
    CHECK_EQ_INT(cJSON_GetArraySize(cJSON_GetObjectItem(cfg, "sensor")), 4); /* bf_sensor */
    cJSON *l = cJSON_GetObjectItem(cfg, "loop");
    CHECK_EQ_INT(cJSON_GetArraySize(l), 13); /* recon_config's own fields: 9 scalars, raycast, caster, reloc, stream */
    CHECK_EQ_INT(cJSON_GetArraySize(cJSON_GetObjectItem(l, "reloc")), 17); /* every field of recon_reloc_config */
    CHECK_EQ_INT(cJSON_GetArraySize(cJSON_GetObjectItem(l, "stream")), 7); /* every field of stream_config */
    CHECK(cJSON_GetObjectItem(f, "sensor") && cJSON_GetObjectItem(t, "sensor"));
    CHECK_EQ_INT(cJSON_GetArraySize(cJSON_GetObjectItem(t, "iterations")), 2);
    cJSON_Delete(o);
}
