/* The one option parser every command uses (app.h): a command describes
 * its options as rows of a table, and the parser, the checks and the help
 * text all read that table, so a default or a bound is stated once. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "replay/replay.h"
#include "shaders/fusion.glsl.h"

int app_usage_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "bitfuse %s: ", cmd);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n(see bitfuse %s --help)\n", cmd);
    va_end(ap);
    return APP_EXIT_USAGE;
}

static bool is_help(const char *arg) { return !strcmp(arg, "-h") || !strcmp(arg, "--help"); }

/* The value of argv[*i] if it is row's option, as "--name value" or
 * "--name=value"; *i moves past what was used. NULL with *matched false:
 * another option; NULL with *matched true: the value is missing. A next
 * argument that is an option ("--out --ratio 2") is not taken as the value:
 * "--name=--x" gives a value starting with "--". */
static const char *option_value(const app_option *row, int argc, char **argv, int *i, bool *matched)
{
    size_t len = strlen(row->name);
    const char *a = argv[*i];
    *matched = false;
    if (strncmp(a, row->name, len) != 0 || (a[len] != '\0' && a[len] != '=')) return NULL;
    *matched = true;
    if (row->kind == APP_OPT_FLAG) return a[len] == '=' ? NULL : a;
    if (a[len] == '=') return a + len + 1;
    if (*i + 1 >= argc || !strncmp(argv[*i + 1], "--", 2)) return NULL;
    return argv[++*i];
}

/* The n-th name of "a|b|c" into out; false past the end. */
static bool choice_name(const char *choices, int n, char *out, size_t cap)
{
    const char *p = choices;
    for (int k = 0; k < n; k++) {
        p = strchr(p, '|');
        if (!p) return false;
        p++;
    }
    size_t len = strcspn(p, "|");
    snprintf(out, cap, "%.*s", (int)len, p);
    return true;
}

static int choice_index(const char *choices, const char *v)
{
    char name[64];
    for (int k = 0; choice_name(choices, k, name, sizeof name); k++)
        if (!strcmp(name, v)) return k;
    return -1;
}

/* "a, b or c" for messages. */
static void choices_text(const char *choices, char *out, size_t cap)
{
    char name[64];
    out[0] = '\0';
    int n = 0;
    while (choice_name(choices, n, name, sizeof name)) n++;
    for (int k = 0; k < n; k++) {
        choice_name(choices, k, name, sizeof name);
        size_t used = strlen(out);
        snprintf(out + used, cap - used, "%s%s", k == 0 ? "" : k == n - 1 ? " or " : ", ", name);
    }
}

static int usage(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static int usage(const char *cmd, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    bf_fail(BF_INVALID_ARG, "%s", msg); /* for callers and tests that read it back */
    return app_usage_error(cmd, "%s", msg);
}

/* A number within the row's bounds; the message says which bound. */
static int check_bounds(const char *cmd, const app_option *row, const char *v, double x)
{
    if (row->min_open ? !(x > row->min) : !(x >= row->min))
        return usage(cmd, "%s: '%s' is %s %g", row->name, v, row->min_open ? "not above" : "below", row->min);
    if (row->max > row->min && x > row->max) return usage(cmd, "%s: '%s' is above %g", row->name, v, row->max);
    return 0;
}

static int parse_number(const char *cmd, const app_option *row, const char *v, double *x)
{
    uint32_t u;
    bool is_whole = row->kind == APP_OPT_U32 || row->kind == APP_OPT_LIST;
    if (is_whole ? !bf_parse_u32(v, &u) : !bf_parse_double(v, x)) {
        /* Digits alone that do not fit: a whole number, too large. */
        bool digits = v[0] != '\0' && strspn(v, "0123456789") == strlen(v);
        if (is_whole && digits)
            return usage(cmd, "%s: %s is too large (at most %.0f)", row->name, v,
                         row->max > row->min ? row->max : (double)UINT32_MAX);
        /* A negative whole number: below the least, not "not whole". */
        if (is_whole && v[0] == '-' && v[1] && strspn(v + 1, "0123456789") == strlen(v + 1) &&
            strspn(v + 1, "0") != strlen(v + 1))
            return usage(cmd, "%s: '%s' is below %g", row->name, v, row->min);
        return usage(cmd, "%s: '%s' is not %s", row->name, v, is_whole ? "a whole number" : "a number");
    }
    if (is_whole) *x = u;
    return check_bounds(cmd, row, v, *x);
}

/* "A,B,C" into the row's array, all or nothing. */
static int parse_list(const char *cmd, const app_option *row, const char *v)
{
    uint32_t vals[APP_OPT_LIST_MAX], n = 0;
    char buf[256];
    /* Every value between commas: an empty one (",", "1,,3") is refused,
     * not skipped. */
    if (!v[0] || strlen(v) >= sizeof buf || strstr(v, ",,") || v[0] == ',' || v[strlen(v) - 1] == ',')
        return usage(cmd, "%s: '%.200s' is not a list A,B,...", row->name, v);
    snprintf(buf, sizeof buf, "%s", v);
    for (char *tok = buf, *next; tok; tok = next) {
        next = strchr(tok, ',');
        if (next) *next++ = '\0';
        double x;
        if (n == row->max_n || n == APP_OPT_LIST_MAX)
            return usage(cmd, "%s: '%s' has more than %u values", row->name, v, row->max_n);
        int rc = parse_number(cmd, row, tok, &x);
        if (rc) return rc;
        vals[n++] = (uint32_t)x;
    }
    memcpy(row->dest, vals, n * sizeof *vals);
    *row->count = n;
    return 0;
}

/* Checks v and writes it to the row's destination; nothing is written
 * when v is refused. */
static int set_value(const char *cmd, const app_option *row, const char *v)
{
    double x = 0;
    int rc = 0;
    if (row->check) {
        const char *why = row->check(row->name, v);
        if (why) return usage(cmd, "%s", why);
    }
    switch (row->kind) {
    case APP_OPT_FLAG: *(bool *)row->dest = true; break;
    case APP_OPT_STRING: *(const char **)row->dest = v; break;
    case APP_OPT_U32:
    case APP_OPT_DOUBLE:
    case APP_OPT_FLOAT:
        if ((rc = parse_number(cmd, row, v, &x))) return rc;
        if (row->kind == APP_OPT_U32) *(uint32_t *)row->dest = (uint32_t)x;
        else if (row->kind == APP_OPT_DOUBLE) *(double *)row->dest = x;
        else *(float *)row->dest = (float)x;
        break;
    case APP_OPT_U64: {
        char *end;
        if (!v[0] || v[0] == '+') return usage(cmd, "%s: '%s' is not a whole number", row->name, v);
        if (v[0] == '-') {
            char *e;
            long long neg = strtoll(v, &e, 10);
            if (!*e && e != v + 1 && neg < 0) return usage(cmd, "%s: '%s' is below 0", row->name, v);
            return usage(cmd, "%s: '%s' is not a whole number", row->name, v);
        }
        unsigned long long u = strtoull(v, &end, 10);
        if (*end) return usage(cmd, "%s: '%s' is not a whole number", row->name, v);
        if ((rc = check_bounds(cmd, row, v, (double)u))) return rc;
        *(uint64_t *)row->dest = u;
        break;
    }
    case APP_OPT_ENUM:
    case APP_OPT_CHOICE: {
        int k = choice_index(row->meta, v);
        if (k < 0) {
            char text[256];
            choices_text(row->meta, text, sizeof text);
            return usage(cmd, "%s takes %s, not '%s'", row->name, text, v);
        }
        if (row->kind == APP_OPT_ENUM) *(int *)row->dest = row->codes ? row->codes[k] : k;
        else *(bool *)row->dest = k == 0;
        break;
    }
    case APP_OPT_LIST: return parse_list(cmd, row, v);
    }
    return 0;
}

/* The row argv[*i] names (its index among all rows in *k), or NULL. */
static const app_option *find_row(const app_command_spec *spec, int argc, char **argv, int *i, const char **v,
                                  size_t *k)
{
    *k = 0;
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *row = *t; row->name; row++, ++*k) {
            int j = *i;
            bool matched;
            *v = option_value(row, argc, argv, &j, &matched);
            if (matched) {
                *i = j;
                return row;
            }
        }
    return NULL;
}

/* Whether the option called name (or an alias: a row with its
 * destination) was given; *row gets its row. */
static bool given(const app_command_spec *spec, const bool *seen, const char *name, const app_option **row)
{
    *row = NULL;
    for (const app_option *const *t = spec->tables; *t && !*row; t++)
        for (const app_option *r = *t; r->name; r++)
            if (!strcmp(r->name, name)) {
                *row = r;
                break;
            }
    if (!*row) return false;
    size_t k = 0;
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *r = *t; r->name; r++, k++)
            if (k < APP_OPT_ROWS_MAX && seen[k] && r->dest == (*row)->dest) return true;
    return false;
}

int app_options_parse(const app_command_spec *spec, int argc, char **argv)
{
    for (int i = 1; i < argc; i++)
        if (is_help(argv[i])) {
            app_options_help(stdout, spec);
            return -1;
        } else if (!strcmp(argv[i], "--version")) {
            printf("bitfuse %s\n", BF_VERSION);
            return -1;
        }
    bool seen[APP_OPT_ROWS_MAX] = {false};
    int n_pos = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v;
        size_t k;
        const app_option *row = a[0] == '-' && a[1] ? find_row(spec, argc, argv, &i, &v, &k) : NULL;
        if (row) {
            if (!v) return usage(spec->name, row->kind == APP_OPT_FLAG ? "%s takes no value" : "%s needs a value",
                                 row->name);
            int rc = set_value(spec->name, row, v);
            if (rc) return rc;
            if (k < APP_OPT_ROWS_MAX) seen[k] = true;
            if (row->given) *row->given = true;
        } else if (a[0] == '-' && a[1]) {
            return usage(spec->name, "unknown option '%s'", a);
        } else if (n_pos < spec->max_positional) {
            spec->positional[n_pos++] = a;
        } else if (spec->max_positional == 0) {
            return usage(spec->name, "unknown argument '%s'", a);
        } else {
            return usage(spec->name, "too many arguments ('%s')", a);
        }
    }
    size_t k = 0;
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *row = *t; row->name; row++, k++)
            if (row->required && !(k < APP_OPT_ROWS_MAX && seen[k]))
                return usage(spec->name, "%s is required", row->name);
    k = 0;
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *row = *t; row->name; row++, k++) {
            if (!row->needs || !(k < APP_OPT_ROWS_MAX && seen[k])) continue;
            const app_option *need = NULL;
            if (given(spec, seen, row->needs, &need)) continue;
            /* Every option missing along the chain at once (--screenshot needs
             * --exit-after, which needs --view): one refusal, not one a try. */
            char list[512];
            size_t len = 0;
            for (int depth = 0; depth < 8; depth++) {
                bool meta = need && need->meta && need->kind != APP_OPT_FLAG;
                const char *name = need ? need->name : row->needs;
                int w = snprintf(list + len, sizeof list - len, "%s%s%s%s", depth ? " and " : "", name,
                                 meta ? " " : "", meta ? need->meta : "");
                if (w < 0 || (size_t)w >= sizeof list - len) break;
                len += (size_t)w;
                const app_option *next = NULL;
                if (!need || !need->needs || given(spec, seen, need->needs, &next)) break;
                need = next;
                if (!need) break;
            }
            return usage(spec->name, "%s needs %s", row->name, list);
        }
    k = 0;
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *row = *t; row->name; row++, k++) {
            if (!row->not_with || !(k < APP_OPT_ROWS_MAX && seen[k])) continue;
            char name[64];
            const char *eq = strchr(row->not_with, '=');
            size_t n = eq ? (size_t)(eq - row->not_with) : strlen(row->not_with);
            if (n >= sizeof name) continue;
            memcpy(name, row->not_with, n);
            name[n] = '\0';
            const app_option *other = NULL;
            if (!given(spec, seen, name, &other)) continue;
            bool off = other->kind == APP_OPT_CHOICE && !*(const bool *)other->dest;
            if (!eq || (!strcmp(eq + 1, "off") && off))
                return usage(spec->name, "%s means nothing with %s%s%s: give one of them", row->name, name,
                             eq ? " " : "", eq ? eq + 1 : "");
        }
    if (n_pos < spec->min_positional) return usage(spec->name, "%s", spec->positional_missing);
    return 0;
}

/* The row's current value as its default ("" when it has none to state). */
static void default_text(const app_option *row, char *out, size_t cap)
{
    out[0] = '\0';
    if (row->no_default) return;
    switch (row->kind) {
    case APP_OPT_FLAG: break;
    case APP_OPT_STRING:
        if (*(const char **)row->dest) snprintf(out, cap, "%s", *(const char **)row->dest);
        break;
    case APP_OPT_U32: snprintf(out, cap, "%u", *(uint32_t *)row->dest); break;
    case APP_OPT_U64: snprintf(out, cap, "%llu", (unsigned long long)*(uint64_t *)row->dest); break;
    case APP_OPT_DOUBLE: snprintf(out, cap, "%g", *(double *)row->dest); break;
    case APP_OPT_FLOAT: snprintf(out, cap, "%g", *(float *)row->dest); break;
    case APP_OPT_CHOICE: choice_name(row->meta, *(bool *)row->dest ? 0 : 1, out, cap); break;
    case APP_OPT_ENUM:
        for (int k = 0; choice_name(row->meta, k, out, cap); k++)
            if ((row->codes ? row->codes[k] : k) == *(int *)row->dest) return;
        out[0] = '\0';
        break;
    case APP_OPT_LIST:
        for (uint32_t k = 0; k < *row->count; k++) {
            size_t used = strlen(out);
            snprintf(out + used, cap - used, "%s%u", k ? "," : "", ((uint32_t *)row->dest)[k]);
        }
        break;
    }
}

/* One option's help: "  --name META", the text wrapped under it, and the
 * default from the destination's value before parsing. */
static void help_row(FILE *f, const app_option *row)
{
    char head[96], def[128], text[1024];
    const char *meta = row->kind == APP_OPT_FLAG ? "" : row->kind == APP_OPT_ENUM || row->kind == APP_OPT_CHOICE
                                                                ? row->meta
                                                                : row->meta ? row->meta : "X";
    snprintf(head, sizeof head, "  %s%s%s", row->name, meta[0] ? " " : "", meta);
    default_text(row, def, sizeof def);
    snprintf(text, sizeof text, "%s%s%s", row->help, def[0] ? ", default " : "", def);
    /* Wrap at 96 columns, continuation lines under the text. */
    const int col = 22, width = 96 - col;
    bool first = true;
    for (const char *p = text; *p;) {
        int n = (int)strlen(p);
        if (n > width) {
            n = width;
            while (n > 0 && p[n] != ' ') n--;
            if (n == 0) n = width;
        }
        if (first) {
            if ((int)strlen(head) >= col) fprintf(f, "%s\n%*s", head, col, "");
            else fprintf(f, "%-*s", col, head);
        } else {
            fprintf(f, "%*s", col, "");
        }
        fprintf(f, "%.*s\n", n, p);
        p += n;
        while (*p == ' ') p++;
        first = false;
    }
}

void app_options_help(FILE *f, const app_command_spec *spec)
{
    fputs(spec->usage, f);
    fputs("\noptions:\n", f);
    for (const app_option *const *t = spec->tables; *t; t++)
        for (const app_option *row = *t; row->name; row++)
            if (row->help) help_row(f, row);
    fprintf(f, "  -h, --help          this text\n");
    fprintf(f, "  --version           the program's version\n");
    if (spec->epilog) fprintf(f, "\n%s", spec->epilog);
}

/* ------------------------------------------------------------ shared rows */

/* replay_parse_camera_lens's message names the value and what was expected. */
static const char *check_camera(const char *name, const char *v)
{
    (void)name;
    bf_intrinsics K = {0};
    double dist[CALIB_DIST_N];
    return replay_parse_camera_lens(v, &K, dist) == BF_OK ? NULL : bf_last_error();
}

void app_sequence_options(app_option rows[APP_SEQUENCE_ROWS], replay_options *o)
{
    const app_option r[APP_SEQUENCE_ROWS] = {
        APP_OPT("--camera", APP_OPT_STRING, &o->camera, "C",
                "intrinsics: fr1 | fr2 | fr3 (TUM's calibration; fr1 and fr2 with their lens distortion, taken "
                "out of every frame), icl (ICL-NUIM), fx,fy,cx,cy in pixels, or fx,fy,cx,cy,k1,k2,p1,p2,k3 with a "
                "lens's distortion (OpenCV's order) (default: camera.txt in the folder, else the format's camera; "
                "a TUM folder named for its sensor, rgbd_dataset_freiburg1_..., takes that sensor's)",
                .check = check_camera),
        APP_OPT("--depth-scale", APP_OPT_DOUBLE, &o->depth_scale, "S",
                "raw depth units per metre, 1 to 1e6 (default: TUM/ICL 5000, pose folders 1000)", .min = 1,
                .max = 1e6, .no_default = true),
        APP_OPT("--frames", APP_OPT_U32, &o->max_frames, "N", "read only the first N frames", .min = 1,
                .no_default = true),
        APP_OPT("--skip-bad-frames", APP_OPT_FLAG, &o->skip_bad_frames, NULL,
                "skip an unreadable frame with a warning instead of failing"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

void app_pool_hint(const char *cmd, bf_status s, const char *opt)
{
    if (s == BF_INVALID_ARG && opt && strstr(bf_last_error(), "storage binding"))
        bf_warn("%s: %s sizes those pools: give a smaller one (bitfuse devices shows this device's binding limit)",
                cmd, opt);
}

/* fusion_create's own bounds (fusion/map.c), checked before a device opens. */
static const char *check_even(const char *name, const char *v)
{
    static char msg[128];
    uint32_t u;
    if (!bf_parse_u32(v, &u) || u % 2 == 0) return NULL;
    snprintf(msg, sizeof msg, "%s must be even, not '%s'", name, v);
    return msg;
}

/* Whether --subcache was given (one command line a process). */
static bool s_subcache_given;

void app_map_options(app_option rows[APP_MAP_ROWS], fusion_config *fc, bool *bricks_given)
{
    s_subcache_given = false;
    const app_option r[APP_MAP_ROWS] = {
        APP_OPT("--ratio", APP_OPT_FLOAT, &fc->voxel_ratio, "R", "voxel-to-pixel ratio of the level rule", .min = 0.05,
                .max = 64, .min_open = true),
        APP_OPT("--voxel-sigmas", APP_OPT_FLOAT, &fc->voxel_sigmas, "K",
                "the level rule's voxel is also at least K times the sensor's depth noise sigma(z) (far samples "
                "get voxels as coarse as their noise); 0: the footprint alone",
                .min = 0, .max = 64),
        APP_OPT("--window", APP_OPT_U32, &fc->window, "N", "frames per fusion window (even)", .min = 2, .max = 256,
                .check = check_even),
        APP_OPT("--subcache", APP_OPT_U32, &fc->subcache, "N",
                "frames of the new-brick pass (at most the window; by default 10, or the window if shorter)", .min = 1,
                .max = 256, .given = &s_subcache_given),
        APP_OPT("--bricks", APP_OPT_U32, &fc->brick_cap, "N",
                "brick pool size (replay and live: instead of --gpu-budget, which with the device sizes it by "
                "default, docs/cli.md \"Streaming\"; fuse: 1048576 by default)",
                .min = 1, .no_default = true, .given = bricks_given),
        APP_OPT("--chunk", APP_OPT_FLOAT, &fc->chunk_m, "M", "chunk edge in metres", .min = 0.01, .max = 64,
                .min_open = true),
        APP_OPT("--max-level", APP_OPT_U32, &fc->max_level, "L",
                "finest octree level (its voxel: the chunk edge / 8 / 2^L, 3.9 mm at level 6 of 2 m chunks)",
                .max = FUSION_MAX_LEVEL),
        APP_OPT("--colour", APP_OPT_CHOICE, &fc->keep_colour, "on|off",
                "keep the frames' colour in the map (RGB565 near the surface; coloured mesh, points and views)"),
        APP_OPT("--colour-frames", APP_OPT_U32, &fc->colour_frames, "N",
                "frames of each window whose colour is fused (overlapping windows read different ones)", .min = 1,
                .max = FUSION_COLOUR_MAX_FRAMES, .not_with = "--colour=off"),
        APP_OPT("--colour-reach", APP_OPT_U32, &fc->colour_reach, "K",
                "bricks no window integrates again, and the whole map at the end, keep colour only within K "
                "voxels (L1) of the surface, giving the rest of their colour memory back; 0: keep every shell "
                "the frames coloured (docs/colour.md)",
                .max = 2, .not_with = "--colour=off"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

int app_check_map_options(const char *cmd, fusion_config *fc)
{
    /* The default follows a short window (--window 8 alone is a whole command line). */
    if (!s_subcache_given && fc->subcache > fc->window) fc->subcache = fc->window;
    if (fc->subcache > fc->window)
        return usage(cmd, "--subcache %u is more than the window of %u frames", fc->subcache, fc->window);
    return 0;
}
