/* app/options.c: the one option parser: both spellings, every kind, bounds
 * and choices refused before anything is written, required options,
 * positional arguments, and help generated from the rows. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app/app.h"
#include "replay/replay.h"
#include "test.h"

typedef struct demo_args {
    const char *seq, *out;
    bool json, sort_keys;
    replay_options ropt;
    fusion_config fc;
    uint32_t iters[4], levels, indent;
    bool noise, quiet;
    float noise_exp;
    int init;
} demo_args;

/* Parses argv (argc entries) into a with the sequence and map rows and a
 * few of each other kind. */
static int parse(int argc, char **argv, demo_args *a)
{
    memset(a, 0, sizeof *a);
    a->fc = fusion_config_default();
    a->iters[0] = 5, a->iters[1] = 4, a->levels = 2;
    a->noise = true;
    const app_option own[] = {
        APP_OPT("--out", APP_OPT_STRING, &a->out, "DIR", "output folder", .required = true),
        APP_OPT("--json", APP_OPT_FLAG, &a->json, NULL, "JSON on stdout"),
        APP_OPT("--indent", APP_OPT_U32, &a->indent, "N", "with --json: spaces per level", .needs = "--json"),
        APP_OPT("--sort-keys", APP_OPT_FLAG, &a->sort_keys, NULL, "with --indent: keys sorted", .needs = "--indent"),
        APP_OPT("--icp-iters", APP_OPT_LIST, a->iters, "A,B", "iterations per level", .max = 1000, .count = &a->levels,
                .max_n = 3),
        APP_OPT("--noise-weights", APP_OPT_CHOICE, &a->noise, "on|off", "weight by the noise"),
        APP_OPT("--noise-exp", APP_OPT_FLOAT, &a->noise_exp, "E", "the weights' exponent",
                .not_with = "--noise-weights=off"),
        APP_OPT("--quiet", APP_OPT_FLAG, &a->quiet, NULL, "no human lines", .not_with = "--json"),
        APP_OPT("--init", APP_OPT_ENUM, &a->init, "groundtruth|identity", "first pose"),
        APP_OPT_END,
    };
    app_option seq[APP_SEQUENCE_ROWS], map[APP_MAP_ROWS];
    app_sequence_options(seq, &a->ropt);
    app_map_options(map, &a->fc, NULL);
    const app_option *tables[] = {own, map, seq, NULL};
    app_command_spec spec = {.name = "test", .usage = "usage: test SEQ --out DIR\n", .tables = tables,
                             .positional = &a->seq, .min_positional = 1, .max_positional = 1,
                             .positional_missing = "no sequence given"};
    return app_options_parse(&spec, argc, argv);
}

BF_TEST(options_parse_good_values_in_both_spellings)
{
    char *argv[] = {"cmd", "seq", "--camera", "fr3", "--depth-scale=1000", "--frames", "25", "--skip-bad-frames",
                    "--json", "--frames=7", "--camera=1,2,3,4", "--out", "o", "--ratio", "0.5", "--icp-iters=10,5,2",
                    "--noise-weights", "off", "--init", "identity"};
    demo_args a;
    CHECK_EQ_INT(parse((int)(sizeof argv / sizeof argv[0]), argv, &a), 0);
    CHECK(!strcmp(a.seq, "seq") && !strcmp(a.out, "o") && a.json);
    CHECK(!strcmp(a.ropt.camera, "1,2,3,4"));
    CHECK(a.ropt.depth_scale == 1000 && a.ropt.max_frames == 7 && a.ropt.skip_bad_frames);
    CHECK(a.fc.voxel_ratio == 0.5f);
    CHECK_EQ_INT(a.levels, 3);
    CHECK(a.iters[0] == 10 && a.iters[1] == 5 && a.iters[2] == 2);
    CHECK(!a.noise);
    CHECK_EQ_INT(a.init, 1);
}

BF_TEST(options_reject_bad_values_with_a_message_and_write_nothing)
{
    struct {
        char *a, *b, *mention;
    } bad[] = {
        {"--camera", "fr4", "fr4"},           {"--camera", "1,2,3", "1,2,3"},      {"--camera", "0,500,320,240", "zero"},
        {"--camera", NULL, "needs a value"},  {"--depth-scale", "0", "'0'"},       {"--depth-scale", "-5", "-5"},
        {"--depth-scale", "inf", "inf"},      {"--depth-scale", "5000x", "5000x"}, {"--depth-scale", "0x10", "'0x10'"},
        {"--depth-scale", "1e-300", "below 1"}, {"--depth-scale", "2e6", "above"}, {"--frames", "0", "'0'"},
        {"--frames", "-3", "'-3' is below 1"}, {"--frames", "2.5", "2.5"},          {"--frames=", NULL, "''"},
        {"--frames", "99999999999", "too large"},
        {"--ratio", "-1", "--ratio"},         {"--ratio", "100", "above 64"},      {"--window", "7", "even"},
        {"--window", "1000", "above 256"},    {"--icp-iters", "10,x", "'x'"},      {"--icp-iters", "1,2,3,4", "more"},
        {"--icp-iters", "1,", "1,"},          {"--icp-iters", "1,,3", "'1,,3'"},    {"--icp-iters", ",1", "',1'"},
        {"--noise-weights", "yes", "on or off"},
        {"--init", "zero", "groundtruth or identity"},                              {"--json=1", NULL, "no value"},
        {"--cameras", "x", "unknown option '--cameras'"},
        /* The next option is not a value ("--name=--x" is the way to give one). */
        {"--camera", "--json", "--camera needs a value"},
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        char *argv[6] = {"cmd", "seq", "--out", "o", bad[k].a, bad[k].b};
        demo_args a;
        bf_clear_error();
        int rc = parse(bad[k].b ? 6 : 5, argv, &a);
        if (rc != APP_EXIT_USAGE)
            bf__test_fail(__FILE__, __LINE__, "case %zu (%s %s) gave %d", k, bad[k].a, bad[k].b, rc);
        CHECK_EQ_INT(rc, APP_EXIT_USAGE);
        CHECK_ERROR_MENTIONS(bad[k].mention);
        /* Nothing was set by the failure. */
        CHECK(a.ropt.camera == NULL && a.ropt.depth_scale == 0 && a.ropt.max_frames == 0);
        CHECK(a.fc.voxel_ratio == fusion_config_default().voxel_ratio && a.levels == 2 && a.noise && a.init == 0);
    }
}

BF_TEST(options_want_required_options_and_positionals)
{
    demo_args a;
    char *no_out[] = {"cmd", "seq"};
    CHECK_EQ_INT(parse(2, no_out, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--out is required");
    char *no_seq[] = {"cmd", "--out", "o"};
    CHECK_EQ_INT(parse(3, no_seq, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("no sequence given");
    char *two[] = {"cmd", "a", "b", "--out", "o"};
    CHECK_EQ_INT(parse(5, two, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("too many arguments ('b')");
    char *sub[] = {"cmd", "a", "--out", "o", "--subcache", "50", "--window", "20"};
    CHECK_EQ_INT(parse(8, sub, &a), 0);
    CHECK_EQ_INT(app_check_map_options("cmd", &a.fc), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--subcache 50");
    /* A window shorter than the default sub-cache alone: the sub-cache follows it. */
    char *window[] = {"cmd", "a", "--out", "o", "--window", "8"};
    CHECK_EQ_INT(parse(6, window, &a), 0);
    CHECK_EQ_INT(app_check_map_options("cmd", &a.fc), 0);
    CHECK_EQ_INT(a.fc.subcache, 8);
    char *both[] = {"cmd", "a", "--out", "o", "--window", "8", "--subcache", "10"};
    CHECK_EQ_INT(parse(8, both, &a), 0);
    CHECK_EQ_INT(app_check_map_options("cmd", &a.fc), APP_EXIT_USAGE);
}

/* An option that means nothing without another is refused alone, in
 * either order with it. */
BF_TEST(options_that_need_another_are_refused_without_it)
{
    demo_args a;
    char *alone[] = {"cmd", "seq", "--out", "o", "--indent", "2"};
    CHECK_EQ_INT(parse(6, alone, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--indent needs --json");
    char *after[] = {"cmd", "seq", "--indent", "2", "--out", "o", "--json"};
    CHECK_EQ_INT(parse(7, after, &a), 0);
    CHECK(a.json && a.indent == 2);
    char *before[] = {"cmd", "seq", "--json", "--indent=3", "--out", "o"};
    CHECK_EQ_INT(parse(6, before, &a), 0);
    CHECK_EQ_INT(a.indent, 3);
    /* A chain missing whole is named whole: not one option a try. */
    char *chain[] = {"cmd", "seq", "--out", "o", "--sort-keys"};
    CHECK_EQ_INT(parse(5, chain, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--sort-keys needs --indent N and --json");
    char *half[] = {"cmd", "seq", "--out", "o", "--sort-keys", "--indent", "2"};
    CHECK_EQ_INT(parse(7, half, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--indent needs --json");
}

/* An option that means nothing beside another is refused with it, in either
 * order, and taken beside that option's other value. */
BF_TEST(options_that_mean_nothing_beside_another_are_refused_with_it)
{
    demo_args a;
    char *flag[] = {"cmd", "seq", "--out", "o", "--quiet", "--json"};
    CHECK_EQ_INT(parse(6, flag, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--quiet means nothing with --json");
    char *off[] = {"cmd", "seq", "--out", "o", "--noise-weights", "off", "--noise-exp", "2"};
    CHECK_EQ_INT(parse(8, off, &a), APP_EXIT_USAGE);
    CHECK_ERROR_MENTIONS("--noise-exp means nothing with --noise-weights off");
    char *on[] = {"cmd", "seq", "--noise-exp", "2", "--out", "o", "--noise-weights", "on"};
    CHECK_EQ_INT(parse(8, on, &a), 0);
    CHECK(a.noise && a.noise_exp == 2.0f);
    char *dflt[] = {"cmd", "seq", "--out", "o", "--noise-exp", "2.5", "--quiet"};
    CHECK_EQ_INT(parse(7, dflt, &a), 0);
    CHECK(a.quiet && a.noise_exp == 2.5f);
}

BF_TEST(help_is_generated_from_the_rows_with_their_defaults)
{
    char *argv[] = {"cmd", "--ratio", "-1", "--help"};
    demo_args a;
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    CHECK(f != NULL);
    FILE *saved = stdout;
    stdout = f;
    int rc = parse(4, argv, &a); /* --help wins over a bad value */
    stdout = saved;
    fclose(f);
    CHECK_EQ_INT(rc, -1);
    CHECK(strstr(buf, "usage: test SEQ --out DIR") != NULL);
    CHECK(strstr(buf, "--ratio R") != NULL && strstr(buf, "default 1\n") != NULL);
    CHECK(strstr(buf, "--icp-iters A,B") != NULL && strstr(buf, "default 5,4") != NULL);
    CHECK(strstr(buf, "--noise-weights on|off") != NULL && strstr(buf, "default on") != NULL);
    CHECK(strstr(buf, "--init groundtruth|identity") != NULL && strstr(buf, "default groundtruth") != NULL);
    CHECK(strstr(buf, "--skip-bad-frames") != NULL && strstr(buf, "--help") != NULL);
    free(buf);
}

BF_TEST(version_is_printed_by_every_command)
{
    char *argv[] = {"cmd", "--ratio", "-1", "--version"};
    demo_args a;
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    CHECK(f != NULL);
    FILE *saved = stdout;
    stdout = f;
    int rc = parse(4, argv, &a); /* like --help, before the values are checked */
    stdout = saved;
    fclose(f);
    CHECK_EQ_INT(rc, -1);
    CHECK(!strcmp(buf, "bitfuse " BF_VERSION "\n"));
    free(buf);
}
