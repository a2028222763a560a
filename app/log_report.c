/* What record and convert report about a bitfuse log they wrote. */
#include <dirent.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <errno.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "app.h"
#include "replay/replay.h"
#include "store/store.h"

double app_ratio(uint64_t raw, uint64_t packed) { return packed ? (double)raw / (double)packed : NAN; }

const char *app_colour_name(int colour)
{
    return colour == REPLAY_LOG_COLOUR_JPEG ? "jpeg" : colour == REPLAY_LOG_COLOUR_ZSTD ? "zstd" : "none";
}

void app_json_log_stats(cJSON *o, const replay_log_config *lcfg, const replay_log_stats *L, double seconds)
{
    cJSON_AddStringToObject(o, "colour_codec", app_colour_name(lcfg->colour));
    cJSON_AddNumberToObject(o, "bytes", (double)L->file_bytes);
    cJSON_AddNumberToObject(o, "depth_raw_bytes", (double)L->depth_raw_bytes);
    cJSON_AddNumberToObject(o, "depth_bytes", (double)L->depth_bytes);
    cJSON_AddNumberToObject(o, "rgb_raw_bytes", (double)L->rgb_raw_bytes);
    cJSON_AddNumberToObject(o, "rgb_bytes", (double)L->rgb_bytes);
    cJSON_AddNumberToObject(o, "depth_compression_ratio", app_ratio(L->depth_raw_bytes, L->depth_bytes));
    cJSON_AddNumberToObject(o, "rgb_compression_ratio", app_ratio(L->rgb_raw_bytes, L->rgb_bytes));
    cJSON_AddNumberToObject(o, "compression_ratio",
                            app_ratio(L->depth_raw_bytes + L->rgb_raw_bytes, L->file_bytes));
    cJSON_AddNumberToObject(o, "write_mb_per_s", seconds > 0 ? L->file_bytes / 1e6 / seconds : NAN);
}

const char *app_check_log_path(const char *name, const char *v)
{
    static char msg[512];
    if (replay_is_log_path(v)) return NULL;
    snprintf(msg, sizeof msg, "%s must name a .bflog file, not '%.400s'", name, v);
    return msg;
}

int app_check_not_input(const char *cmd, const char *opt, const char *out, const char *in)
{
    struct stat so, si;
    if (!out || !in || stat(out, &so) != 0 || stat(in, &si) != 0) return 0;
    if (so.st_dev != si.st_dev || so.st_ino != si.st_ino) return 0;
    return app_usage_error(cmd, "%s %s is %s, which is being read: writing there would overwrite it", opt, out, in);
}

static bool canonical(const char *path, char out[PATH_MAX]);

int app_check_not_inside(const char *cmd, const char *opt, const char *out, const char *dir, bool new_too)
{
    char ro[PATH_MAX], rd[PATH_MAX];
    if (!out || !dir || !(new_too ? canonical(out, ro) : realpath(out, ro) != NULL) || !realpath(dir, rd)) return 0;
    size_t n = strlen(rd);
    if (strncmp(ro, rd, n) != 0 || ro[n] != '/') return 0;
    return app_usage_error(cmd, "%s %s is inside %s, which is being read: writing there would overwrite or add to its "
                           "files", opt, out, dir);
}

/* path made absolute and plain (no "." or "..", no trailing or doubled
 * slash): realpath of its longest leading part that exists, then the rest's
 * names ("." dropped, ".." taking the name before it), so a file or folder
 * a run is about to make compares as what it will be; false where it
 * cannot (too long, no working folder). */
static bool canonical(const char *path, char out[PATH_MAX])
{
    if (!path || !path[0]) return false;
    if (realpath(path, out)) return true;
    char abs[PATH_MAX];
    if (path[0] == '/') {
        if (snprintf(abs, sizeof abs, "%s", path) >= (int)sizeof abs) return false;
    } else {
        char cwd[PATH_MAX];
        if (!getcwd(cwd, sizeof cwd) || snprintf(abs, sizeof abs, "%s/%s", cwd, path) >= (int)sizeof abs) return false;
    }
    /* The longest leading part that resolves: cut at each slash from the end. */
    size_t cut = strlen(abs);
    for (;;) {
        while (cut > 0 && abs[cut] != '/') cut--;
        char c = abs[cut];
        abs[cut] = '\0';
        bool ok = realpath(cut ? abs : "/", out) != NULL;
        abs[cut] = c;
        if (ok) break;
        if (cut == 0) return false;
        cut--;
    }
    /* The names after it. */
    for (char *name = abs + cut; *name;) {
        while (*name == '/') name++;
        size_t len = strcspn(name, "/");
        if (len == 0) break;
        size_t m = strlen(out);
        if (len == 1 && name[0] == '.') {
            /* nothing */
        } else if (len == 2 && name[0] == '.' && name[1] == '.') {
            char *last = strrchr(out, '/');
            if (last && last != out) *last = '\0';
            else snprintf(out, PATH_MAX, "/");
        } else if (snprintf(out + m, PATH_MAX - m, "%s%.*s", m > 1 ? "/" : "", (int)len, name) >= (int)(PATH_MAX - m)) {
            return false;
        }
        name += len;
    }
    return true;
}

/* The nearest folder above path (lexically, from the working folder) that
 * is a scene store, into inside (PATH_MAX); false when none is. */
static bool store_above(const char *path, char *inside)
{
    char p[PATH_MAX];
    if (!canonical(path, p)) return false;
    for (char *slash = strrchr(p, '/'); slash && slash != p; slash = strrchr(p, '/')) {
        *slash = '\0';
        if (store_is_written(p)) {
            snprintf(inside, PATH_MAX, "%s", p);
            return true;
        }
    }
    return false;
}

int app_check_out_not_store(const char *cmd, const char *out, const char *store)
{
    char above[PATH_MAX];
    /* Not inside a store's files either way: its chunks/ would hold a folder
     * that is no chunk, and a reader of the outer store meets the inner's. */
    if (out && store_above(out, above))
        return app_usage_error(cmd, "--out %s is inside the scene store %s: give a folder outside it", out, above);
    if (store && store_above(store, above))
        return app_usage_error(cmd, "--store %s is inside the scene store %s: give a folder outside it", store, above);
    /* A folder holding other files is no store's (a run's results: info and
     * export would then read the store instead of DIR/store; a sequence):
     * the store's files would lie among them. */
    DIR *d = store && !store_exists(store) ? opendir(store) : NULL;
    for (struct dirent *e; d && (e = readdir(d));) {
        /* (dot files and a file system's lost+found are no one's results) */
        if (e->d_name[0] == '.' || !strcmp(e->d_name, "lost+found")) continue;
        char first[256];
        snprintf(first, sizeof first, "%s", e->d_name);
        closedir(d);
        return app_usage_error(cmd, "--store %s holds other files (%s): give the store a folder of its own (an "
                               "empty or new one, e.g. --store %s/store)", store, first, store);
    }
    if (d) closedir(d);
    if (!out) return 0;
    if (store_exists(out))
        return app_usage_error(cmd, "--out %s is a scene store: the outputs would go in among its files; give another "
                               "folder (a store may live inside it, as --store DIR/store)", out);
    char ro[PATH_MAX], rs[PATH_MAX];
    size_t ns = store && canonical(out, ro) && canonical(store, rs) ? strlen(rs) : 0;
    /* Nor inside this run's own store (a new one, not yet on disk). */
    if (ns && !strncmp(ro, rs, ns) && ro[ns] == '/')
        return app_usage_error(cmd, "--out %s is inside --store %s: give a folder outside it", out, store);
    if (ns && !strcmp(ro, rs))
        return app_usage_error(cmd, "--out %s is --store's folder: the outputs would go in among the store's files; "
                               "give the store its own folder (--store %s/store)", out, out);
    return 0;
}

int app_check_json_out(const char *cmd, const char *opt, const char *path)
{
    struct stat st;
    /* Only a regular file is opened (a pipe would block; the writer refuses
     * what is not a regular file). */
    if (!path || stat(path, &st) != 0 || !S_ISREG(st.st_mode)) return 0;
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    int c;
    while ((c = fgetc(f)) == ' ' || c == '\t' || c == '\n' || c == '\r') {}
    fclose(f);
    if (c == '{' || c == EOF) return 0; /* a JSON object, or empty */
    return app_usage_error(cmd, "%s %s exists and is not a JSON file: it is not written over (an image or index "
                                "named by mistake?)", opt, path);
}

int app_check_out_folder(const char *cmd, const char *opt, const char *given)
{
    char dir[4096], target[4096];
    /* Checked first, so that no output is written before a later one fails on it. */
    if (given && strlen(given) >= sizeof dir)
        return app_usage_error(cmd, "%s: a path of %zu characters is too long (at most %zu): %.60s...", opt,
                               strlen(given), sizeof dir - 1, given);
    /* A symbolic link is written through (bf_out): its target's folder is the one that must exist. */
    if (given && bf_link_target(given, target, sizeof target) != BF_OK)
        return app_fail(cmd, bf_fail(BF_WRITE, "%s %s: %s", opt, given, bf_last_error()));
    const char *path = given ? target : NULL;
    const char *slash = path ? strrchr(path, '/') : NULL;
    if (!slash) return 0; /* the working folder */
    size_t n = slash == path ? 1 : (size_t)(slash - path);
    memcpy(dir, path, n);
    dir[n] = 0;
    struct stat st;
    if (stat(dir, &st) == 0 && S_ISDIR(st.st_mode)) return 0;
    int e = errno;
    char shown[8300];
    if (strcmp(given, path)) snprintf(shown, sizeof shown, "%s (a link to %s)", given, path);
    else snprintf(shown, sizeof shown, "%s", given);
    if (stat(dir, &st) == 0)
        return app_fail(cmd, bf_fail(BF_WRITE, "%s %s: %s is not a folder", opt, shown, dir));
    return app_fail(cmd, bf_fail(BF_WRITE, "%s %s: the folder %s %s%s", opt, shown, dir,
                                 e == ENOENT ? "does not exist" : "cannot be used: ", e == ENOENT ? "" : strerror(e)));
}

int app_check_new_recording(const char *cmd, const char *opt, const char *path, bool overwrite)
{
    struct stat st;
    if (!path || overwrite || lstat(path, &st) != 0) return 0;
    return app_usage_error(cmd, "%s %s exists: a recording is not written over it (give --overwrite to replace it, or "
                                "another name)", opt, path);
}

static const int colour_codes[] = {REPLAY_LOG_COLOUR_JPEG, REPLAY_LOG_COLOUR_ZSTD, REPLAY_LOG_COLOUR_NONE};

void app_log_codec_options(app_option rows[APP_LOG_ROWS], app_log_codec *c)
{
    const app_option r[APP_LOG_ROWS] = {
        APP_OPT("--colour", APP_OPT_ENUM, &c->colour, "jpeg|zstd|none", "colour codec (zstd is lossless)",
                .codes = colour_codes, .given = &c->colour_given),
        APP_OPT("--color", APP_OPT_ENUM, &c->colour, "jpeg|zstd|none", NULL, .codes = colour_codes,
                .given = &c->colour_given),
        APP_OPT("--jpeg-quality", APP_OPT_U32, &c->jpeg_quality, "Q", "JPEG quality (with --colour jpeg)", .min = 1,
                .max = 100, .given = &c->quality_given),
        APP_OPT("--zstd-level", APP_OPT_U32, &c->zstd_level, "L", "zstd level for depth (and zstd colour)", .min = 1,
                .max = 19, .given = &c->level_given),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

void app_log_codec_apply(const app_log_codec *c, replay_log_config *lcfg)
{
    lcfg->colour = (replay_log_colour)c->colour;
    lcfg->jpeg_quality = (int)c->jpeg_quality;
    lcfg->zstd_level = (int)c->zstd_level;
}

int app_parse_log_command(app_command_spec *spec, const app_option *own, app_log_codec *codec, replay_options *ropt,
                          replay_log_config *lcfg, int argc, char **argv)
{
    app_option codec_rows[APP_LOG_ROWS], seq[APP_SEQUENCE_ROWS];
    app_log_codec_options(codec_rows, codec);
    app_sequence_options(seq, ropt);
    const app_option *tables[] = {own, codec_rows, seq, NULL};
    spec->tables = tables;
    int rc = app_options_parse(spec, argc, argv);
    spec->tables = NULL; /* they live on this stack */
    /* A quality no codec uses is refused, not ignored. */
    if (rc == 0 && codec->quality_given && codec->colour != REPLAY_LOG_COLOUR_JPEG)
        return app_usage_error(spec->name, "--jpeg-quality is JPEG's: it needs --colour jpeg");
    if (rc == 0) app_log_codec_apply(codec, lcfg);
    return rc;
}
