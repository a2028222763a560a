/* The fuzz targets' inputs as ordinary tests (so they also run in the
 * sanitizer build and on compilers without libFuzzer): every seed of
 * tests/fuzz/corpus/TARGET goes through its target without a crash, the
 * whole ones (all but NAME.cut) without an error, and every input in tests/fuzz/regress/TARGET (each once crashed, hung or
 * leaked in a reader: docs/fuzz.md) is refused with an error that names the
 * file it came through and, where NAME.expect exists, says what it holds. */
#include <dirent.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "test.h"

typedef bf_status (*fuzz_fn)(const uint8_t *data, size_t size);

/* Runs fn on every file of dir; returns the files run (-1: no such dir).
 * With must_fail, a file that reads without error or whose message does
 * not name the scratch folder fails the test; without it, a file that does
 * not end in ".cut" and fails. */
static int run_dir(const char *dir, fuzz_fn fn, bool must_fail)
{
    DIR *d = opendir(dir);
    if (!d) return -1;
    int n = 0;
    struct dirent *de;
    while ((de = readdir(d))) {
        size_t len = strlen(de->d_name);
        if (de->d_name[0] == '.' || (len > 7 && strcmp(de->d_name + len - 7, ".expect") == 0)) continue;
        char path[4096];
        if (bf_path_join(path, sizeof path, dir, de->d_name) != BF_OK) continue;
        char *data = NULL;
        size_t size = 0;
        if (bf_read_file(path, &data, &size) != BF_OK) {
            bf__test_fail(__FILE__, __LINE__, "%s: cannot read", path);
            break;
        }
        bf_clear_error();
        bf_status s = fn((const uint8_t *)data, size);
        free(data);
        n++;
        bool is_cut = len > 4 && strcmp(de->d_name + len - 4, ".cut") == 0;
        if (!must_fail && !is_cut && s != BF_OK) {
            bf__test_fail(__FILE__, __LINE__, "%s: %s: %s", path, bf_status_name(s), bf_last_error());
            break;
        }
        if (must_fail && s == BF_OK) {
            bf__test_fail(__FILE__, __LINE__, "%s: read without an error", path);
            break;
        }
        if (must_fail && !strstr(bf_last_error(), fuzz_scratch_name())) {
            bf__test_fail(__FILE__, __LINE__, "%s: %s: the message does not name the file", path,
                          bf_last_error());
            break;
        }
        /* NAME.expect: what the message must say (the reason the fix gives). */
        char expect_path[4200], *expect = NULL;
        snprintf(expect_path, sizeof expect_path, "%s.expect", path);
        if (must_fail && bf_read_file(expect_path, &expect, NULL) == BF_OK) {
            expect[strcspn(expect, "\n")] = '\0';
            bool found = strstr(bf_last_error(), expect) != NULL;
            if (!found)
                bf__test_fail(__FILE__, __LINE__, "%s: %s: the message does not say '%s'", path, bf_last_error(),
                              expect);
            free(expect);
            if (!found) break;
        }
    }
    closedir(d);
    return n;
}

/* has_regress: tests/fuzz/regress/NAME holds inputs, and a folder that lost
 * them (git keeps no empty folder) fails rather than passing on nothing. */
static void run_target(const char *name, fuzz_fn fn, bool has_regress)
{
    fuzz_quiet();
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/corpus/%s", BF_FUZZ_DIR, name);
    int n_seeds = run_dir(dir, fn, false);
    CHECK(n_seeds > 0);
    snprintf(dir, sizeof dir, "%s/regress/%s", BF_FUZZ_DIR, name);
    int n_regress = run_dir(dir, fn, true);
    if (has_regress) CHECK(n_regress > 0);
}

BF_TEST(image_inputs) { run_target("image", fuzz_image, false); }
BF_TEST(text_inputs) { run_target("text", fuzz_text, false); }
BF_TEST(folder_inputs) { run_target("folder", fuzz_folder, false); }
BF_TEST(bflog_inputs) { run_target("bflog", fuzz_bflog, false); }
BF_TEST(mesh_inputs) { run_target("mesh", fuzz_mesh, true); }
BF_TEST(store_inputs) { run_target("store", fuzz_store, true); }
BF_TEST(calib_inputs) { run_target("calib", fuzz_calib, false); }
BF_TEST(depthcorr_inputs) { run_target("depthcorr", fuzz_depthcorr, false); }
BF_TEST(v4l2_inputs) { run_target("v4l2", fuzz_v4l2, true); }
BF_TEST(expect_inputs) { run_target("expect", fuzz_expect, false); }
