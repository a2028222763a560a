/* replay: TUM trajectory files (read, write, interpolate) and their errors. */
#include <stdio.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

static bf_se3 pose_at(double a)
{
    return bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, -1, 0.5), a), bf_v3(a, -2 * a, 0.5 + a * a));
}

BF_TEST(traj_write_read_round_trip)
{
    bf_traj tr = {0};
    for (int i = 0; i < 200; i++) {
        bf_se3 T = pose_at(0.03 * i - 2.0); /* includes angles past pi/2, so qw < 0 before flipping */
        CHECK_OK(bf_traj_push(&tr, 1305031102.175304 + 0.033 * i, &T));
    }
    char path[512];
    snprintf(path, sizeof path, "%s/traj_rt.txt", bf_test_tmpdir());
    CHECK_OK(replay_traj_write_tum(path, &tr));
    bf_traj back = {0};
    CHECK_OK(replay_traj_read_tum(path, &back));
    CHECK_EQ_INT(back.n, tr.n);
    for (size_t i = 0; i < tr.n; i++) {
        /* 9 decimals: times within 1e-9 plus the double spacing at 1.3e9 s
         * (2.4e-7); position within 5e-10; rotation within a few 1e-9. */
        CHECK_NEAR(back.t_s[i], tr.t_s[i], 5e-7);
        CHECK_NEAR(back.T_wc[i].t.x, tr.T_wc[i].t.x, 1e-9);
        CHECK_NEAR(back.T_wc[i].t.y, tr.T_wc[i].t.y, 1e-9);
        CHECK_NEAR(back.T_wc[i].t.z, tr.T_wc[i].t.z, 1e-9);
        bf_se3 inv = bf_se3_inverse(&tr.T_wc[i]);
        bf_se3 d = bf_se3_mul(&inv, &back.T_wc[i]);
        CHECK_LE(bf_se3_angle(&d), 1e-8);
    }
    /* Every written quaternion has qw >= 0. */
    char *text;
    CHECK_OK(bf_read_file(path, &text, NULL));
    int bad = 0;
    for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n")) {
        if (line[0] == '#') continue;
        double v[8];
        CHECK_EQ_INT(sscanf(line, "%lf %lf %lf %lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5],
                            &v[6], &v[7]), 8);
        if (v[7] < 0) bad++;
    }
    free(text);
    CHECK_EQ_INT(bad, 0);
    /* A TUM time is written with the fewest decimals that read back as its
     * double (.665900, not the .665899992 its double holds at nine). */
    bf_traj one = {0};
    CHECK_OK(bf_traj_push(&one, 1305031102.6659, &tr.T_wc[0]));
    CHECK_OK(replay_traj_write_tum(path, &one));
    CHECK_OK(bf_read_file(path, &text, NULL));
    CHECK(strstr(text, "\n1305031102.665900 ") != NULL);
    free(text);
    bf_traj_free(&back);
    CHECK_OK(replay_traj_read_tum(path, &back));
    CHECK(back.n == 1 && back.t_s[0] == 1305031102.6659);
    bf_traj_free(&one);
    bf_traj_free(&tr);
    bf_traj_free(&back);
}

BF_TEST(traj_interpolates_linear_position_and_slerp)
{
    bf_traj tr = {0};
    bf_se3 A = bf_se3_from_qt(bf_quat_identity(), bf_v3(0, 0, 0));
    bf_se3 B = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), 1.0), bf_v3(2, 4, -6));
    CHECK_OK(bf_traj_push(&tr, 10.0, &A));
    CHECK_OK(bf_traj_push(&tr, 11.0, &B));
    bf_se3 T;
    CHECK(bf_traj_interpolate(&tr, 10.25, &T));
    CHECK_NEAR(T.t.x, 0.5, 1e-12);
    CHECK_NEAR(T.t.y, 1.0, 1e-12);
    CHECK_NEAR(T.t.z, -1.5, 1e-12);
    CHECK_NEAR(bf_se3_angle(&T), 0.25, 1e-12);
    /* Ends are exact; outside the range there is no pose. */
    CHECK(bf_traj_interpolate(&tr, 11.0, &T));
    CHECK_NEAR(T.t.x, 2, 0);
    CHECK(bf_traj_interpolate(&tr, 10.0, &T));
    CHECK_NEAR(T.t.x, 0, 0);
    CHECK(!bf_traj_interpolate(&tr, 9.999, &T));
    CHECK(!bf_traj_interpolate(&tr, 11.001, &T));
    bf_traj_free(&tr);
    bf_traj empty = {0};
    CHECK(!bf_traj_interpolate(&empty, 0, &T));
}

BF_TEST(traj_reads_real_tum_groundtruth)
{
    const char *p = bf_test_data("tum/fr1_xyz/groundtruth.txt");
    if (!p) BF_SKIP("tum/fr1_xyz absent");
    bf_traj tr = {0};
    CHECK_OK(replay_traj_read_tum(p, &tr));
    CHECK_EQ_INT(tr.n, 3000);
    for (size_t i = 1; i < tr.n; i++) CHECK(tr.t_s[i] > tr.t_s[i - 1]);
    bf_traj_free(&tr);
}

static const char *write_text(const char *name, const char *text)
{
    const char *p = rt_tmp(name);
    return rt_write_text(p, text) ? p : "(write failed)";
}

BF_TEST(traj_malformed_files_name_file_and_line)
{
    bf_traj tr = {0};
    const char *p = write_text("traj_unsorted.txt", "# c\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_unsorted.txt:4");
    CHECK_ERROR_MENTIONS("before");
    p = write_text("traj_nan.txt", "1 0 0 0 0 0 0 1\n\n2 0 nan 0 0 0 0 1\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_nan.txt:3");
    CHECK_ERROR_MENTIONS("finite");
    p = write_text("traj_fields.txt", "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_fields.txt:2");
    CHECK_ERROR_MENTIONS("found 7");
    p = write_text("traj_quat0.txt", "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_quat0.txt:2");
    CHECK_ERROR_MENTIONS("zero");
    p = write_text("traj_word.txt", "1 0 0 x 0 0 0 1\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_word.txt:1");
    p = write_text("traj_empty.txt", "# nothing\n");
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_empty.txt");
    CHECK_STATUS(replay_traj_read_tum("/nonexistent/traj.txt", &tr), BF_IO);
    CHECK_ERROR_MENTIONS("/nonexistent/traj.txt");
    /* Outputs untouched on failure. */
    CHECK(tr.n == 0 && tr.t_s == NULL);
}

/* What TUM's scripts read is read: the published ground truth of
 * rgbd_dataset_freiburg2_desk repeats a stamp, and quaternions a little off
 * unit length are normalised (evaluate_rpe.py's transform44). */
/* A file an editor saved with a UTF-8 byte order mark, and one whose lines
 * end in a lone CR, read as any other (the mark was read as part of the
 * first timestamp; CR-only lines as one line). */
BF_TEST(traj_reads_a_byte_order_mark_and_cr_line_ends)
{
    bf_traj tr = {0};
    CHECK_OK(replay_traj_read_tum(write_text("traj_bom.txt", "\xEF\xBB\xBF" "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n"), &tr));
    CHECK_EQ_INT(tr.n, 2);
    CHECK(tr.t_s[0] == 1 && tr.T_wc[1].t.x == 1);
    bf_traj_free(&tr);
    const char *p = write_text("traj_cr.txt", "\xEF\xBB\xBF# t x y z qx qy qz qw\r1 0 0 0 0 0 0 1\r2 1 0 0 0 0 0 1\r"
                                              "3 2 0 0 0 0 0 1\r\n4 3 0 0 0 0 0 1");
    CHECK_OK(replay_traj_read_tum(p, &tr));
    CHECK_EQ_INT(tr.n, 4);
    CHECK(tr.t_s[3] == 4 && tr.T_wc[3].t.x == 3);
    bf_traj_free(&tr);
}

/* A NUL byte (a file padded with zeros after a crash) is refused by line:
 * the reader stopped there and took the first part alone, exit 0. */
BF_TEST(traj_refuses_a_nul_byte)
{
    static const char text[] = "1 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n\0\0003 2 0 0 0 0 0 1\n";
    const char *p = rt_tmp("traj_nul.txt");
    CHECK_OK(bf_write_file_atomic(p, text, sizeof text - 1));
    bf_traj tr = {0};
    CHECK_STATUS(replay_traj_read_tum(p, &tr), BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_nul.txt:3: a NUL byte (byte 32)");
    CHECK_EQ_INT(tr.n, 0);
}

/* A position no camera has (its square overflowed eval-traj's error to inf,
 * exit 0) is refused by file and line; 1e8 m is read. */
BF_TEST(traj_refuses_a_position_beyond_1e9_m)
{
    bf_traj tr = {0};
    CHECK_STATUS(replay_traj_read_tum(write_text("traj_far.txt", "1 0 0 0 0 0 0 1\n2 0 1e300 0 0 0 0 1\n"), &tr),
                 BF_FORMAT);
    CHECK_ERROR_MENTIONS("traj_far.txt:2: ty 1e+300 m is beyond 1e9 m");
    CHECK_OK(replay_traj_read_tum(write_text("traj_far8.txt", "1 0 0 0 0 0 0 1\n2 0 -1e8 0 0 0 0 1\n"), &tr));
    CHECK(tr.T_wc[1].t.y == -1e8);
    bf_traj_free(&tr);
}

BF_TEST(traj_keeps_first_of_repeated_stamp_and_normalises_quaternions)
{
    bf_traj tr = {0};
    const char *p = write_text("traj_dup.txt", "1 0 0 0 0 0 0 1\n"
                                               "2 1 0 0 0 0 0 1\n"
                                               "2 9 0 0 0 0 0 1\n"
                                               "3 3 0 0 0 0 0.6 1.6\n"
                                               "3 9 0 0 0 0 0 1\n"
                                               "4 4 0 0 0 0 0 1.002\n"
                                               "5 5 0 0 0 0 6e200 1.6e201\n");
    CHECK_OK(replay_traj_read_tum(p, &tr));
    CHECK_EQ_INT(tr.n, 5);
    const double t_want[5] = {1, 2, 3, 4, 5}, x_want[5] = {0, 1, 3, 4, 5};
    for (size_t i = 0; i < 5; i++) {
        CHECK(tr.t_s[i] == t_want[i]);
        CHECK(tr.T_wc[i].t.x == x_want[i]);
    }
    /* (0, 0, 0.6, 1.6) normalised: a rotation about z by 2 atan(0.6 / 1.6). */
    bf_quat q;
    bf_vec3 t;
    bf_se3_to_qt(&tr.T_wc[2], &q, &t);
    double n = sqrt(0.6 * 0.6 + 1.6 * 1.6);
    CHECK_NEAR(fabs(q.w), 1.6 / n, 1e-12);
    CHECK_NEAR(fabs(q.z), 0.6 / n, 1e-12);
    CHECK_NEAR(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z, 1, 1e-12);
    /* The same rotation written with components whose squares overflow
     * (until the thirty-fifth session read as no rotation). */
    bf_quat q5;
    bf_se3_to_qt(&tr.T_wc[4], &q5, &t);
    CHECK_NEAR(fabs(q5.w), 1.6 / n, 1e-12);
    CHECK_NEAR(fabs(q5.z), 0.6 / n, 1e-12);
    bf_traj_free(&tr);
}
