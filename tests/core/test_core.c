/* core: SE(3), quaternions, eigen-decomposition, parsing, statistics. */
#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/core.h"
#include "test.h"

/* A deterministic pseudo-random sweep (xorshift) so failures reproduce. */
static double rnd(unsigned *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 17;
    *s ^= *s << 5;
    return (double)*s / 4294967296.0;
}

static double max_abs_diff_R(const double A[3][3], const double B[3][3])
{
    double m = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) m = fmax(m, fabs(A[i][j] - B[i][j]));
    return m;
}

BF_TEST(quaternion_matrix_round_trip_over_all_angles)
{
    unsigned s = 12345;
    for (int k = 0; k < 2000; k++) {
        bf_vec3 axis = bf_v3(rnd(&s) - 0.5, rnd(&s) - 0.5, rnd(&s) - 0.5);
        /* Include angles right at 0 and pi where naive conversions break. */
        double ang = k < 10 ? 0 : k < 20 ? M_PI : k < 30 ? M_PI - 1e-9 : rnd(&s) * M_PI;
        bf_quat q = bf_quat_from_axis_angle(axis, ang);
        double R[3][3], R2[3][3];
        bf_quat_to_mat(q, R);
        bf_quat q2 = bf_quat_from_mat(R);
        bf_quat_to_mat(q2, R2);
        CHECK_LE(max_abs_diff_R(R, R2), 1e-12);
        CHECK_NEAR(bf_quat_angle(q2), ang, 1e-7);
        /* R is orthonormal with det +1. */
        double det = R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) -
                     R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
                     R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
        CHECK_NEAR(det, 1.0, 1e-12);
    }
}

BF_TEST(quaternion_rotation_matches_matrix)
{
    bf_quat q = bf_quat_from_axis_angle(bf_v3(0, 0, 1), M_PI / 2);
    bf_vec3 v = bf_quat_rotate(q, bf_v3(1, 0, 0));
    CHECK_NEAR(v.x, 0, 1e-15);
    CHECK_NEAR(v.y, 1, 1e-15);
    CHECK_NEAR(v.z, 0, 1e-15);
    bf_quat a = bf_quat_from_axis_angle(bf_v3(1, 2, 3), 0.7);
    bf_quat b = bf_quat_from_axis_angle(bf_v3(-1, 0, 2), 1.9);
    bf_vec3 p = bf_v3(0.3, -1.2, 2.5);
    bf_vec3 r1 = bf_quat_rotate(bf_quat_mul(a, b), p);
    bf_vec3 r2 = bf_quat_rotate(a, bf_quat_rotate(b, p));
    CHECK_NEAR(r1.x, r2.x, 1e-14);
    CHECK_NEAR(r1.y, r2.y, 1e-14);
    CHECK_NEAR(r1.z, r2.z, 1e-14);
}

BF_TEST(se3_exp_log_round_trip_including_small_and_near_pi_angles)
{
    unsigned s = 777;
    for (int k = 0; k < 3000; k++) {
        double xi[6], back[6];
        double scale = k % 3 == 0 ? 1e-9 : 1.0;
        for (int i = 0; i < 3; i++) xi[i] = (rnd(&s) - 0.5) * 4;
        bf_vec3 w = bf_v3_normalize(bf_v3(rnd(&s) - 0.5, rnd(&s) - 0.5, rnd(&s) - 0.5));
        double th = k % 5 == 0 ? M_PI - 1e-6 : rnd(&s) * 3.0 * scale;
        xi[3] = w.x * th; xi[4] = w.y * th; xi[5] = w.z * th;
        bf_se3 T = bf_se3_exp(xi);
        bf_se3_log(&T, back);
        bf_se3 T2 = bf_se3_exp(back);
        CHECK_LE(max_abs_diff_R(T.R, T2.R), 1e-9);
        CHECK_NEAR(T.t.x, T2.t.x, 1e-8);
        CHECK_NEAR(T.t.y, T2.t.y, 1e-8);
        CHECK_NEAR(T.t.z, T2.t.z, 1e-8);
        if (th < 3.0) /* away from pi the twist itself is unique */
            for (int i = 0; i < 6; i++) CHECK_NEAR(back[i], xi[i], 1e-8);
    }
}

BF_TEST(se3_inverse_and_composition_cancel)
{
    double xi[6] = {0.4, -1.0, 2.0, 0.3, -0.2, 1.1};
    bf_se3 T = bf_se3_exp(xi);
    bf_se3 Ti = bf_se3_inverse(&T);
    bf_se3 I = bf_se3_mul(&T, &Ti);
    bf_se3 Id = bf_se3_identity();
    CHECK_LE(max_abs_diff_R(I.R, Id.R), 1e-15);
    CHECK_LE(bf_v3_norm(I.t), 1e-15);
    bf_vec3 p = bf_v3(1, 2, 3);
    bf_vec3 q = bf_se3_apply(&Ti, bf_se3_apply(&T, p));
    CHECK_LE(bf_v3_norm(bf_v3_sub(p, q)), 1e-14);
    CHECK_NEAR(bf_se3_angle(&T), sqrt(0.09 + 0.04 + 1.21), 1e-12);
}

BF_TEST(se3_far_from_origin_keeps_submillimetre_precision)
{
    /* 10 km from the origin: double keeps ~1e-12 m, float would lose ~1 mm. */
    bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.3), bf_v3(1e4, -1e4, 5e3));
    bf_se3 Ti = bf_se3_inverse(&T);
    bf_vec3 p = bf_v3(1e4 + 0.0001, -1e4, 5e3 + 1.5);
    bf_vec3 q = bf_se3_apply(&T, bf_se3_apply(&Ti, p));
    CHECK_LE(bf_v3_norm(bf_v3_sub(p, q)), 1e-9);
}

BF_TEST(slerp_interpolates_at_constant_angular_speed)
{
    bf_quat a = bf_quat_identity();
    bf_quat b = bf_quat_from_axis_angle(bf_v3(0, 0, 1), 1.2);
    for (int k = 0; k <= 10; k++) {
        double s = k / 10.0;
        bf_quat q = bf_quat_slerp(a, b, s);
        CHECK_NEAR(bf_quat_angle(q), 1.2 * s, 1e-12);
    }
    /* -b is the same rotation: slerp must take the short way. */
    bf_quat nb = {-b.w, -b.x, -b.y, -b.z};
    CHECK_NEAR(bf_quat_angle(bf_quat_slerp(a, nb, 0.5)), 0.6, 1e-12);
    bf_se3 A = bf_se3_identity();
    bf_se3 B = bf_se3_from_qt(b, bf_v3(2, 0, 0));
    bf_se3 M = bf_se3_interpolate(&A, &B, 0.25);
    CHECK_NEAR(M.t.x, 0.5, 1e-15);
    CHECK_NEAR(bf_se3_angle(&M), 0.3, 1e-12);
}

BF_TEST(symmetric_eigen_reconstructs_matrix)
{
    unsigned s = 99;
    double A[36], A0[36], w[6], V[36];
    for (int i = 0; i < 6; i++)
        for (int j = i; j < 6; j++) A[i * 6 + j] = A[j * 6 + i] = rnd(&s) - 0.5;
    memcpy(A0, A, sizeof A);
    bf_sym_eigen(6, A, w, V);
    for (int i = 1; i < 6; i++) CHECK_LE(w[i - 1], w[i]);
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) {
            double r = 0;
            for (int k = 0; k < 6; k++) r += V[i * 6 + k] * w[k] * V[j * 6 + k];
            CHECK_NEAR(r, A0[i * 6 + j], 1e-12);
        }
}

BF_TEST(intrinsics_project_unproject_round_trip_with_negative_fy)
{
    bf_intrinsics K = {640, 480, 481.2, -480.0, 319.5, 239.5, 5000};
    bf_vec3 p = bf_intrinsics_unproject(&K, 100.25, 400.5, 2.5);
    double u, v;
    CHECK(bf_intrinsics_project(&K, p, &u, &v));
    CHECK_NEAR(u, 100.25, 1e-12);
    CHECK_NEAR(v, 400.5, 1e-12);
    CHECK(p.y < 0); /* flipped y: rows below the centre map to -y */
    CHECK(!bf_intrinsics_project(&K, bf_v3(0, 0, -1), &u, &v));
}

BF_TEST(strict_number_parsing_rejects_garbage_and_nan)
{
    double d;
    uint32_t u;
    CHECK(bf_parse_double("1305031102.160407", &d));
    CHECK_NEAR(d, 1305031102.160407, 1e-6);
    CHECK(!bf_parse_double("nan", &d));
    CHECK(!bf_parse_double("1.5x", &d));
    CHECK(!bf_parse_double("", &d));
    CHECK(!bf_parse_double("inf", &d));
    CHECK(bf_parse_u32("4294967295", &u));
    CHECK(!bf_parse_u32("4294967296", &u));
    CHECK(!bf_parse_u32("-1", &u));
}

BF_TEST(percentiles_interpolate_like_numpy)
{
    bf_stats s = {0};
    for (int i = 1; i <= 10; i++) CHECK_OK(bf_stats_push(&s, i));
    CHECK_NEAR(bf_stats_percentile(&s, 50), 5.5, 1e-12);
    CHECK_NEAR(bf_stats_percentile(&s, 95), 9.55, 1e-12);
    CHECK_NEAR(bf_stats_mean(&s), 5.5, 1e-12);
    bf_stats_free(&s);
    CHECK(isnan(bf_stats_percentile(&s, 50)));
}

static void square(void *ctx, size_t i) { ((double *)ctx)[i] = (double)(i * i); }

BF_TEST(parallel_for_visits_every_index_once)
{
    double v[1000];
    memset(v, 0, sizeof v);
    bf_parallel_for(1000, square, v);
    for (int i = 0; i < 1000; i++) CHECK_NEAR(v[i], (double)i * i, 0);
}

static void *report_mask(void *arg)
{
    pthread_sigmask(SIG_BLOCK, NULL, (sigset_t *)arg);
    return NULL;
}

/* A Ctrl-C must reach the main thread's handler, never a worker's blocking
 * call: workers start with SIGINT and SIGTERM blocked, the caller's mask
 * unchanged. */
BF_TEST(threads_start_with_the_stop_signals_blocked)
{
    sigset_t stop, before, after, worker;
    sigemptyset(&stop);
    sigaddset(&stop, SIGINT);
    sigaddset(&stop, SIGTERM);
    pthread_sigmask(SIG_UNBLOCK, &stop, NULL); /* a runner may have started the test with them blocked */
    pthread_sigmask(SIG_BLOCK, NULL, &before);
    CHECK(!sigismember(&before, SIGINT) && !sigismember(&before, SIGTERM));
    pthread_t th;
    CHECK(bf_thread_start(&th, report_mask, &worker) == 0);
    pthread_join(th, NULL);
    CHECK(sigismember(&worker, SIGINT));
    CHECK(sigismember(&worker, SIGTERM));
    CHECK(!sigismember(&worker, SIGUSR1));
    pthread_sigmask(SIG_BLOCK, NULL, &after);
    CHECK(!sigismember(&after, SIGINT) && !sigismember(&after, SIGTERM));
}

BF_TEST(atomic_write_replaces_file_and_reads_back)
{
    char path[512];
    CHECK_OK(bf_path_join(path, sizeof path, bf_test_tmpdir(), "a/b/c"));
    CHECK_OK(bf_mkdir_p(path));
    CHECK_OK(bf_path_join(path, sizeof path, bf_test_tmpdir(), "a/b/c/f.txt"));
    CHECK_OK(bf_write_file_atomic(path, "hello", 5));
    CHECK_OK(bf_write_file_atomic(path, "world!", 6));
    char *data;
    size_t n;
    CHECK_OK(bf_read_file(path, &data, &n));
    CHECK_EQ_INT(n, 6);
    CHECK(!strcmp(data, "world!"));
    free(data);
    CHECK_STATUS(bf_read_file("/nonexistent/file", &data, &n), BF_IO);
    CHECK_ERROR_MENTIONS("/nonexistent/file");
    /* A folder opens for reading on Linux; the read then says why it failed. */
    CHECK_STATUS(bf_read_file(bf_test_tmpdir(), &data, &n), BF_IO);
    CHECK_ERROR_MENTIONS("directory");
}

static int count_tmp_files(const char *dir)
{
    DIR *d = opendir(dir);
    int n = 0;
    for (struct dirent *e; d && (e = readdir(d));) n += strstr(e->d_name, ".tmp") != NULL;
    if (d) closedir(d);
    return n;
}

/* bf_out: pieces larger and smaller than its buffer and a line longer than
 * its printf buffer arrive in order; a failure (a file size limit: write
 * fails with EFBIG mid-file) is BF_WRITE naming the file and the reason,
 * the earlier file stays as it was and no temporary file is left; abort
 * leaves nothing. Faults through the program: tests/fault. */
BF_TEST(output_file_is_whole_or_absent)
{
    char dir[512], path[600];
    CHECK_OK(bf_path_join(dir, sizeof dir, bf_test_tmpdir(), "out"));
    CHECK_OK(bf_mkdir_p(dir));
    CHECK_OK(bf_path_join(path, sizeof path, dir, "f.bin"));
    size_t big = BF_OUT_BUFFER + 12345;
    uint8_t *ref = malloc(big + 3000);
    CHECK(ref != NULL);
    for (size_t i = 0; i < big; i++) ref[i] = (uint8_t)(i * 7 + (i >> 9));
    char line[3000];
    memset(line, 'x', sizeof line - 1);
    line[sizeof line - 1] = 0;
    bf_out o;
    CHECK_OK(bf_out_open(&o, path));
    bf_out_write(&o, ref, 10);
    bf_out_write(&o, ref + 10, big - 10); /* larger than the buffer: straight through */
    bf_out_printf(&o, "%s", line);        /* longer than printf's line buffer */
    CHECK_OK(bf_out_commit(&o));
    memcpy(ref + big, line, sizeof line - 1);
    char *data;
    size_t n;
    CHECK_OK(bf_read_file(path, &data, &n));
    CHECK_EQ_INT(n, big + sizeof line - 1);
    CHECK(!memcmp(data, ref, n));
    free(data);
    /* A write that fails mid-file (RLIMIT_FSIZE: EFBIG, SIGXFSZ ignored). */
    struct rlimit old, lim;
    CHECK(getrlimit(RLIMIT_FSIZE, &old) == 0);
    void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN);
    lim = (struct rlimit){65536, old.rlim_max};
    CHECK(setrlimit(RLIMIT_FSIZE, &lim) == 0);
    CHECK_OK(bf_out_open(&o, path));
    bf_out_write(&o, ref, big);
    bf_out_printf(&o, "more"); /* after the failure: nothing */
    bf_status s = bf_out_commit(&o);
    bf_status s2 = bf_write_file_atomic(path, ref, big);
    CHECK(setrlimit(RLIMIT_FSIZE, &old) == 0);
    signal(SIGXFSZ, old_handler);
    CHECK_STATUS(s, BF_WRITE);
    CHECK_ERROR_MENTIONS("too large"); /* strerror(EFBIG), for s2 */
    CHECK_STATUS(s2, BF_WRITE);
    CHECK_OK(bf_read_file(path, &data, &n));
    CHECK_EQ_INT(n, big + sizeof line - 1); /* the earlier file, whole */
    free(data);
    CHECK_EQ_INT(count_tmp_files(dir), 0);
    /* Abort, and a folder that does not exist. */
    CHECK_OK(bf_path_join(path, sizeof path, dir, "g.bin"));
    CHECK_OK(bf_out_open(&o, path));
    bf_out_write(&o, ref, 100);
    bf_out_abort(&o);
    CHECK(!bf_file_exists(path));
    CHECK_EQ_INT(count_tmp_files(dir), 0);
    CHECK_STATUS(bf_out_open(&o, "/nonexistent/dir/h.bin"), BF_WRITE);
    CHECK_ERROR_MENTIONS("/nonexistent/dir/h.bin: cannot create: its folder does not exist");
    CHECK_STATUS(bf_write_file_atomic("/nonexistent/dir/h.bin", "x", 1), BF_WRITE);
    free(ref);
}

/* bf_fmt_double: what a person wrote comes back as written (517.3, not
 * 517.29999999999995), and every double reads back bit for bit. */
BF_TEST(doubles_are_written_short_and_read_back_exactly)
{
    char b[BF_FMT_DOUBLE_CAP];
    CHECK(!strcmp(bf_fmt_double(b, 517.3), "517.3"));
    CHECK(!strcmp(bf_fmt_double(b, 0.1), "0.1"));
    CHECK(!strcmp(bf_fmt_double(b, 5000), "5000"));
    CHECK(!strcmp(bf_fmt_double(b, -0.0), "-0"));
    CHECK(!strcmp(bf_fmt_double(b, 1.0 / 3.0), "0.3333333333333333"));   /* 16 */
    CHECK(!strcmp(bf_fmt_double(b, 0.1 + 0.2), "0.30000000000000004")); /* all 17 */
    uint64_t x = 0x9E3779B97F4A7C15ull;
    for (int i = 0; i < 100000; i++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        double v;
        memcpy(&v, &x, sizeof v);
        if (!isfinite(v)) continue;
        bf_fmt_double(b, v);
        double back = strtod(b, NULL);
        CHECK(memcmp(&back, &v, sizeof v) == 0);
        if (bf__test_failed_now) return;
    }
}

/* The files a fatal signal's handler removes (bf_pending_*): an open
 * bf_out's temporary file is one until commit or abort, the committed file
 * never is; with every slot taken a file is simply not registered; the
 * slots come back when forgotten. (The handler's slots are never reused: it
 * runs once, as the program ends, so that part comes last.) */
BF_TEST(pending_files_are_the_open_temporaries)
{
    char dir[512], a[600], b[600], extra[600];
    CHECK_OK(bf_path_join(dir, sizeof dir, bf_test_tmpdir(), "pending"));
    CHECK_OK(bf_mkdir_p(dir));
    CHECK_OK(bf_path_join(a, sizeof a, dir, "a.txt"));
    CHECK_OK(bf_path_join(b, sizeof b, dir, "b.txt"));
    bf_out oa, ob;
    /* Every slot taken: the next file is not registered, nothing breaks. */
    int slots[BF_PENDING_MAX];
    for (int i = 0; i < BF_PENDING_MAX; i++) {
        snprintf(extra, sizeof extra, "%s/none-%d", dir, i);
        slots[i] = bf_pending_add(extra);
        CHECK(slots[i] >= 0);
    }
    CHECK_OK(bf_out_open(&ob, b));
    CHECK_EQ_INT(ob.pending, -1);
    bf_out_printf(&ob, "kept");
    CHECK_OK(bf_out_commit(&ob));
    for (int i = 0; i < BF_PENDING_MAX; i++) bf_pending_forget(&slots[i]);
    int none = -1;
    bf_pending_forget(&none); /* nothing */
    /* A failed open releases the slot it took first. */
    CHECK_STATUS(bf_out_open(&oa, "/nonexistent/dir/p.bin"), BF_WRITE);
    for (int i = 0; i < BF_PENDING_MAX; i++) {
        slots[i] = bf_pending_add(extra);
        CHECK(slots[i] >= 0);
    }
    for (int i = 0; i < BF_PENDING_MAX; i++) bf_pending_forget(&slots[i]);
    /* What the signal handler removes. */
    CHECK_OK(bf_out_open(&oa, a));
    bf_out_printf(&oa, "committed\n");
    CHECK_OK(bf_out_commit(&oa));
    CHECK_OK(bf_out_open(&ob, b));
    CHECK(ob.pending >= 0);
    bf_out_printf(&ob, "half");
    bf_out_flush(&ob);
    CHECK_EQ_INT(count_tmp_files(dir), 1);
    bf_pending_remove_all(); /* what the signal handler does */
    CHECK_EQ_INT(count_tmp_files(dir), 0);
    CHECK(bf_file_exists(a)); /* committed: not a pending file */
    bf_out_abort(&ob);        /* the file already gone: no harm */
    CHECK(bf_file_exists(b)); /* the earlier b.txt, untouched */
    bf_pending_remove_all(); /* nothing registered: removes nothing */
    CHECK(bf_file_exists(a) && bf_file_exists(b));
}

/* A write to a symbolic link goes to the file it names, which it replaces
 * (a rename onto the link replaced the link and left the target stale);
 * a link to a file not there yet makes that file, relative to the link. */
BF_TEST(output_through_a_link_writes_its_target)
{
    char dir[512], target[600], link[600], later[600], link2[600];
    CHECK_OK(bf_path_join(dir, sizeof dir, bf_test_tmpdir(), "links"));
    CHECK_OK(bf_mkdir_p(dir));
    snprintf(target, sizeof target, "%s/target.txt", dir);
    snprintf(link, sizeof link, "%s/link.txt", dir);
    snprintf(later, sizeof later, "%s/later.txt", dir);
    snprintf(link2, sizeof link2, "%s/link2.txt", dir);
    CHECK_OK(bf_write_file_atomic(target, "old", 3));
    CHECK(symlink("target.txt", link) == 0);
    CHECK_OK(bf_write_file_atomic(link, "new!", 4));
    struct stat st;
    CHECK(lstat(link, &st) == 0 && S_ISLNK(st.st_mode));
    char *data;
    size_t n;
    CHECK_OK(bf_read_file(target, &data, &n));
    CHECK(n == 4 && !strcmp(data, "new!"));
    free(data);
    CHECK(symlink("later.txt", link2) == 0); /* dangling until written */
    CHECK_OK(bf_write_file_atomic(link2, "made", 4));
    CHECK(lstat(link2, &st) == 0 && S_ISLNK(st.st_mode));
    CHECK_OK(bf_read_file(later, &data, &n));
    CHECK(n == 4 && !strcmp(data, "made"));
    free(data);
    /* A chain of links to a file not made yet makes it; every link stays. */
    char l3[600], l4[600], last[600];
    snprintf(l3, sizeof l3, "%s/l3", dir);
    snprintf(l4, sizeof l4, "%s/l4", dir);
    snprintf(last, sizeof last, "%s/last.txt", dir);
    CHECK(symlink("l4", l3) == 0 && symlink("last.txt", l4) == 0);
    CHECK_OK(bf_write_file_atomic(l3, "end", 3));
    CHECK(lstat(l3, &st) == 0 && S_ISLNK(st.st_mode) && lstat(l4, &st) == 0 && S_ISLNK(st.st_mode));
    CHECK(stat(last, &st) == 0 && st.st_size == 3);
    /* The file replaced keeps its permission bits. */
    CHECK(chmod(target, 0600) == 0);
    CHECK_OK(bf_write_file_atomic(link, "again", 5));
    CHECK(stat(target, &st) == 0 && (st.st_mode & 0777) == 0600);
    CHECK_EQ_INT(count_tmp_files(dir), 0);
    /* Another user's link in a sticky, world-writable folder (/tmp's kind)
     * is not followed (root can make one; others skip this part). */
    if (geteuid() == 0) {
        char shared[620], planted[640];
        snprintf(shared, sizeof shared, "%s/shared", dir);
        snprintf(planted, sizeof planted, "%s/stats.json", shared);
        CHECK(mkdir(shared, 0777) == 0 && chmod(shared, 01777) == 0);
        CHECK(symlink(target, planted) == 0 && lchown(planted, 4321, 4321) == 0);
        CHECK_STATUS(bf_write_file_atomic(planted, "x", 1), BF_WRITE);
        CHECK_ERROR_MENTIONS("another user owns in a shared folder");
        CHECK_OK(bf_read_file(target, &data, &n));
        CHECK(n == 5 && !strcmp(data, "again"));
        free(data);
    }
}

BF_TEST(status_table_names_every_code)
{
    CHECK(!strcmp(bf_status_name(BF_IO), "BF_IO"));
    CHECK(!strcmp(bf_status_name(BF_POOL_FULL), "BF_POOL_FULL"));
    CHECK(!strcmp(bf_status_message(BF_FORMAT), "malformed input"));
    CHECK_STATUS(bf_fail(BF_FORMAT, "%s: line %d: bad", "x.txt", 3), BF_FORMAT);
    CHECK_ERROR_MENTIONS("x.txt: line 3");
}

/* A message with a long path is kept whole: bf_fail up to BF_ERROR_CAP, and
 * a log line of any length is written whole, once, ending in a newline. */
BF_TEST(long_messages_are_kept_whole)
{
    static char path[6001];
    for (size_t i = 0; i < sizeof path - 1; i++) path[i] = (char)('a' + i % 26);
    path[5999] = 'Z';
    CHECK_STATUS(bf_fail(BF_IO, "%s: the reason", path), BF_IO);
    CHECK(strlen(bf_last_error()) == 6000 + strlen(": the reason"));
    CHECK_ERROR_MENTIONS("Z: the reason");
    char file[4200];
    snprintf(file, sizeof file, "%s/log.txt", bf_test_tmpdir());
    fflush(stderr);
    int saved = dup(2), fd = open(file, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    CHECK(saved >= 0 && fd >= 0);
    dup2(fd, 2);
    close(fd);
    bf_log_level level = bf_log_get_level();
    bf_log_set_level(BF_LOG_INFO);
    bf_warn("%s: the reason", path);
    bf_warn("short");
    bf_log_set_level(level);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    FILE *f = fopen(file, "rb");
    CHECK(f != NULL);
    static char got[8192];
    size_t n = f ? fread(got, 1, sizeof got - 1, f) : 0;
    if (f) fclose(f);
    got[n] = 0;
    const char *want_end = "Z: the reason\nbitfuse: warning: short\n";
    CHECK(n == strlen("bitfuse: warning: ") + 6000 + strlen(want_end) - strlen("Z"));
    CHECK(!strncmp(got, "bitfuse: warning: abc", 21));
    CHECK(n >= strlen(want_end) && !strcmp(got + n - strlen(want_end), want_end));
}

/* A driver's repeats (core.h): depth against the last frame with depth,
 * colour against the previous frame; one changed sample is new data. */
BF_TEST(repeats_are_found_per_stream_byte_for_byte)
{
    enum { PW = 4, PH = 3, PN = PW * PH };
    uint16_t d0[PN], d1[PN], zero[PN] = {0};
    uint8_t c0[3 * PN], c1[3 * PN];
    for (int i = 0; i < PN; i++) d0[i] = d1[i] = (uint16_t)(1000 + i);
    d1[PN - 1]++;
    for (int i = 0; i < 3 * PN; i++) c0[i] = c1[i] = (uint8_t)i;
    c1[0]++;
    bf_frame f = {.width = PW, .height = PH, .depth = d0, .rgb = c0};
    bf_repeats r = {0};
    bool dr = true, cr = true;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, &cr));
    CHECK(!dr && !cr); /* nothing before the first frame */
    CHECK_OK(bf_repeats_note(&r, &f, &dr, &cr));
    CHECK(dr && cr);
    /* New depth, the same colour: the streams are judged apart. */
    f.depth = d1;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, &cr));
    CHECK(!dr && cr);
    f.rgb = c1;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, &cr));
    CHECK(dr && !cr);
    /* A frame without depth repeats nothing and keeps the last depth: the
     * next frame with d1 repeats it. */
    f.depth = zero;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, NULL));
    CHECK(!dr);
    CHECK_OK(bf_repeats_note(&r, &f, &dr, NULL));
    CHECK(!dr);
    f.depth = d1;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, NULL));
    CHECK(dr);
    /* A frame without colour: the next colour is compared with nothing. */
    f.rgb = NULL;
    CHECK_OK(bf_repeats_note(&r, &f, NULL, &cr));
    CHECK(!cr);
    f.rgb = c1;
    CHECK_OK(bf_repeats_note(&r, &f, NULL, &cr));
    CHECK(!cr);
    /* Another size starts over. */
    f.width = PW - 1;
    CHECK_OK(bf_repeats_note(&r, &f, &dr, &cr));
    CHECK(!dr && !cr);
    bf_repeats_free(&r);
    CHECK(r.depth == NULL && r.n == 0);
    bf_repeats_free(NULL);
    CHECK_STATUS(bf_repeats_note(&r, NULL, &dr, &cr), BF_INVALID_ARG);
}
