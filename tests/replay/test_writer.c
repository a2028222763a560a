/* replay: the TUM-folder writer. */
#include <stdio.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

BF_TEST(writer_writes_index_files_only_at_finish)
{
    const char *dir = rt_fresh_dir("writer_atomic");
    CHECK(dir);
    bf_intrinsics K = {0, 0, 500, 500, 3.5, 2.5, 5000};
    replay_tum_writer *w;
    CHECK_OK(replay_tum_writer_create(dir, &K, &w));
    uint16_t d[4 * 3] = {1, 2, 3};
    uint8_t c[4 * 3 * 3] = {9};
    bf_frame f = {.index = 0, .width = 4, .height = 3, .t_depth_s = 1.0, .t_rgb_s = 1.01, .depth = d, .rgb = c};
    CHECK_OK(replay_tum_writer_add(w, &f));
    char p[1024];
    snprintf(p, sizeof p, "%s/depth.txt", dir);
    CHECK(!bf_file_exists(p));
    snprintf(p, sizeof p, "%s/depth/1.000000.png", dir);
    CHECK(bf_file_exists(p));
    /* Time must advance; size must stay. */
    CHECK_STATUS(replay_tum_writer_add(w, &f), BF_INVALID_ARG);
    f.t_depth_s = 2;
    f.width = 3;
    CHECK_STATUS(replay_tum_writer_add(w, &f), BF_INVALID_ARG);
    CHECK_OK(replay_tum_writer_finish(w));
    snprintf(p, sizeof p, "%s/depth.txt", dir);
    CHECK(bf_file_exists(p));
    snprintf(p, sizeof p, "%s/camera.txt", dir);
    char *cam;
    CHECK_OK(bf_read_file(p, &cam, NULL));
    double v[5];
    CHECK_EQ_INT(sscanf(cam, "%lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4]), 5);
    free(cam);
    CHECK(v[0] == 500 && v[2] == 3.5 && v[3] == 2.5 && v[4] == 5000);
    snprintf(p, sizeof p, "%s/groundtruth.txt", dir);
    CHECK(!bf_file_exists(p)); /* no frame had a pose */
    replay_tum_writer_destroy(w);
    replay_tum_writer_destroy(NULL);
}
