/* Writes the fuzz targets' seed corpora (tests/fuzz/corpus/TARGET/) with
 * the project's own writers, plus a few hand-written files and cut-off
 * copies: small valid inputs from which libFuzzer mutates. Run
 *     fuzz_seeds tests/fuzz/corpus
 * to make them anew (BITFUSE_FUZZ build; docs/fuzz.md). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fuzz.h"
#include "mesh/mesh.h"
#include "replay/log_int.h"
#include "store/store.h"

#define W 4
#define H 3

static const char *out_root;
static char tmp_dir[256];

/* A growing byte buffer. */
typedef struct buf {
    uint8_t *p;
    size_t n;
} buf;

static void buf_add(buf *b, const void *p, size_t n)
{
    b->p = realloc(b->p, b->n + n + 1);
    if (!b->p) abort();
    memcpy(b->p + b->n, p, n);
    b->n += n;
}
static void buf_str(buf *b, const char *s) { buf_add(b, s, strlen(s)); }
static void buf_sep(buf *b) { buf_str(b, FUZZ_SEP); }

static void buf_file(buf *b, const char *path)
{
    char *d = NULL;
    size_t n = 0;
    if (bf_read_file(path, &d, &n) != BF_OK) {
        fprintf(stderr, "fuzz_seeds: %s\n", bf_last_error());
        exit(1);
    }
    buf_add(b, d, n);
    free(d);
}

static void check(bf_status s)
{
    if (s != BF_OK) {
        fprintf(stderr, "fuzz_seeds: %s: %s\n", bf_status_name(s), bf_last_error());
        exit(1);
    }
}

/* Writes the seed (and with cut set, its first half as NAME.cut). */
static void seed(const char *target, const char *name, const void *p, size_t n, bool cut)
{
    char dir[4096], file[4200];
    snprintf(dir, sizeof dir, "%s/%s", out_root, target);
    check(bf_mkdir_p(dir));
    snprintf(file, sizeof file, "%s/%s", dir, name);
    FILE *f = fopen(file, "wb");
    if (!f || fwrite(p, 1, n, f) != n || fclose(f) != 0) {
        fprintf(stderr, "fuzz_seeds: cannot write %s\n", file);
        exit(1);
    }
    if (cut) {
        char cut_name[300];
        snprintf(cut_name, sizeof cut_name, "%s.cut", name);
        seed(target, cut_name, p, n / 2, false);
    }
}

static const char *tmp(const char *name)
{
    static char slots[4][4096];
    static int k;
    char *p = slots[k++ % 4];
    snprintf(p, sizeof slots[0], "%s/%s", tmp_dir, name);
    return p;
}

/* ------------------------------------------------------------ images */

static uint16_t depth_px[W * H];
static uint8_t rgb_px[W * H * 3];

static void make_pixels(void)
{
    for (int i = 0; i < W * H; i++) {
        depth_px[i] = (uint16_t)(i == 5 ? 0 : 5000 + 37 * i);
        for (int c = 0; c < 3; c++) rgb_px[3 * i + c] = (uint8_t)(40 * c + 17 * i);
    }
}

static buf file_png_u16(void)
{
    buf b = {0};
    check(replay_png_write_u16(tmp("d.png"), depth_px, W, H));
    buf_file(&b, tmp("d.png"));
    return b;
}

static buf file_png_rgb(void)
{
    buf b = {0};
    check(replay_png_write_rgb8(tmp("c.png"), rgb_px, W, H));
    buf_file(&b, tmp("c.png"));
    return b;
}

static buf file_jpeg(void)
{
    uint8_t out[4096];
    size_t n = 0;
    check(log__jpeg_encode(rgb_px, W, H, 90, out, sizeof out, &n, "seed"));
    buf b = {0};
    buf_add(&b, out, n);
    return b;
}

static void seeds_image(void)
{
    buf d = file_png_u16(), c = file_png_rgb(), j = file_jpeg();
    seed("image", "depth.png", d.p, d.n, true);
    seed("image", "colour.png", c.p, c.n, true);
    seed("image", "colour.jpg", j.p, j.n, true);
    free(d.p), free(c.p), free(j.p);
}

/* ------------------------------------------------------------ text */

static const char traj_text[] = "# timestamp tx ty tz qx qy qz qw\n"
                                "1.000000 0.1 0.2 0.3 0 0 0 1\n"
                                "1.033000 0.11 0.2 0.3 0.01 0 0 0.99995\n"
                                "1.066000 0.12 0.21 0.3 0.02 0.01 0 0.9997\n";
static const char pose_text[] = "1 0 0 0.1\n0 1 0 0.2\n0 0 1 0.3\n0 0 0 1\n";

static void seeds_text(void)
{
    bf_traj t = {0};
    for (int i = 0; i < 3; i++) {
        bf_se3 T = bf_se3_identity();
        T.t = bf_v3(0.1 * i, 0.2, -0.3);
        check(bf_traj_push(&t, 1.0 + i / 30.0, &T));
    }
    check(replay_traj_write_tum(tmp("traj.txt"), &t));
    bf_traj_free(&t);
    buf b = {0};
    buf_file(&b, tmp("traj.txt"));
    seed("text", "trajectory.txt", b.p, b.n, true);
    free(b.p);
    seed("text", "trajectory_repeat.txt", traj_text, sizeof traj_text - 1, false);
    const char cam[] = "525.0 525.0 319.5 239.5 5000\n";
    seed("text", "camera.txt", cam, sizeof cam - 1, false);
    const char cam_lens[] = "517.3 516.5 318.6 255.3 5000 0.2624 -0.9531 -0.0054 0.0026 1.1633\n";
    seed("text", "camera_lens.txt", cam_lens, sizeof cam_lens - 1, false);
    seed("text", "pose.txt", pose_text, sizeof pose_text - 1, true);
}

/* ------------------------------------------------------------ folders */

/* TUM: two frames sharing the images, ground truth and camera.txt's line. */
static void seed_tum(const char *name, const char *camera_line, const buf *d, const buf *c, bool cut)
{
    buf b = {0};
    buf_str(&b, "tum");
    buf_sep(&b);
    buf_str(&b, "# rgb\n1.000 rgb/c.png\n1.033 rgb/c.jpg\n");
    buf_sep(&b);
    buf_str(&b, "# depth\n1.001 depth/d.png\n1.034 depth/d.png\n");
    buf_sep(&b);
    buf_str(&b, traj_text);
    buf_sep(&b);
    buf_str(&b, camera_line);
    buf_sep(&b);
    buf_add(&b, d->p, d->n);
    buf_sep(&b);
    buf_add(&b, c->p, c->n);
    seed("folder", name, b.p, b.n, cut);
    free(b.p);
}

static void seeds_folder(void)
{
    buf d = file_png_u16(), c = file_png_rgb(), j = file_jpeg();
    seed_tum("tum", "525 525 1.5 1 5000\n", &d, &c, true);
    /* The same with a lens in camera.txt: every frame undistorted. */
    seed_tum("tum_lens", "3 3 1.5 1 5000 0.2624 -0.9531 -0.0054 0.0026 1.1633\n", &d, &c, false);
    /* TUM without colour or ground truth, skipping bad frames. */
    buf b = {0};
    buf_str(&b, "tum skip max2");
    buf_sep(&b);
    buf_sep(&b);
    buf_str(&b, "1.0 depth/d.png\n2.0 depth/missing.png\n3.0 depth/d.png\n");
    buf_sep(&b);
    buf_sep(&b);
    buf_sep(&b);
    buf_add(&b, d.p, d.n);
    seed("folder", "tum_depth_only", b.p, b.n, false);
    free(b.p);
    /* ICL-NUIM: pose.txt, depth/N.png, color/N.png|jpg. */
    b = (buf){0};
    buf_str(&b, "icl");
    buf_sep(&b);
    buf_str(&b, "0 0 0 0 0 0 1\n0.01 0 0 0 0 0 1\n");
    buf_sep(&b);
    buf_str(&b, "481 480 1.5 1 5000\n");
    buf_sep(&b);
    buf_add(&b, d.p, d.n);
    buf_sep(&b);
    buf_add(&b, c.p, c.n);
    seed("folder", "icl", b.p, b.n, true);
    free(b.p);
    /* Pose per frame: camera-intrinsics.txt, 4x4 poses. */
    b = (buf){0};
    buf_str(&b, "pose scale");
    buf_sep(&b);
    buf_str(&b, "585 0 2\n0 585 1.5\n0 0 1\n");
    buf_sep(&b);
    buf_str(&b, pose_text);
    buf_sep(&b);
    buf_str(&b, pose_text);
    buf_sep(&b);
    buf_add(&b, d.p, d.n);
    buf_sep(&b);
    buf_add(&b, j.p, j.n);
    seed("folder", "pose", b.p, b.n, true);
    free(b.p);
    free(d.p), free(c.p), free(j.p);
}

/* ------------------------------------------------------------ logs */

static buf make_log(replay_log_colour colour, bool finish, int n_frames)
{
    bf_intrinsics K = {.width = W, .height = H, .fx_px = 5, .fy_px = 5, .cx_px = 1.5, .cy_px = 1, .depth_scale = 5000};
    replay_log_config cfg = {.colour = colour, .device = "seed", .has_groundtruth = true};
    replay_log_writer *w = NULL;
    check(replay_log_writer_create(tmp("l.bflog"), &K, &cfg, &w));
    for (int i = 0; i < n_frames; i++) {
        bf_frame f = {.index = (uint32_t)i, .width = W, .height = H, .t_depth_s = 1.0 + i / 30.0,
                      .t_rgb_s = 1.0 + i / 30.0, .depth = depth_px, .rgb = rgb_px, .has_pose = true,
                      .T_wc = bf_se3_identity()};
        check(replay_log_writer_add(w, &f));
    }
    if (finish) check(replay_log_writer_finish(w));
    replay_log_writer_destroy(w);
    buf b = {0};
    buf_file(&b, tmp("l.bflog"));
    return b;
}

static void seed_log(const char *name, uint8_t flags, const buf *log, bool cut)
{
    buf b = {0};
    buf_add(&b, &flags, 1);
    buf_add(&b, log->p, log->n);
    seed("bflog", name, b.p, b.n, cut);
    free(b.p);
}

static void seeds_bflog(void)
{
    buf a = make_log(REPLAY_LOG_COLOUR_ZSTD, true, 3);
    seed_log("zstd", 0, &a, true);
    seed_log("zstd_fix_seek1", 1 | 1 << 2, &a, false);
    buf j = make_log(REPLAY_LOG_COLOUR_JPEG, true, 2);
    seed_log("jpeg_fix_skip", 3, &j, true);
    buf n = make_log(REPLAY_LOG_COLOUR_NONE, false, 2);
    seed_log("depth_unfinished_fix_sniffed", 1 | 0x80, &n, false);
    free(a.p), free(j.p), free(n.p);
}

/* ------------------------------------------------------------ meshes */

static void seeds_mesh(void)
{
    float xyz[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    float nrm[] = {0, 0, 1, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    uint8_t rgb[] = {255, 0, 0, 0, 255, 0, 0, 0, 255, 9, 9, 9};
    uint32_t tri[] = {0, 1, 2, 0, 1, 3, 0, 2, 3, 1, 2, 3};
    mesh_data m = {.n_verts = 4, .n_tris = 4, .xyz = xyz, .normal = nrm, .rgb = rgb, .tri = tri,
                   .origin = {10, -2, 0.5}};
    check(mesh_write_ply(tmp("m.ply"), &m));
    buf b = {0};
    buf_file(&b, tmp("m.ply"));
    seed("mesh", "tetra.ply", b.p, b.n, true);
    free(b.p);
    static const char ascii[] = "ply\nformat ascii 1.0\ncomment origin_w 1 2 3\nelement vertex 4\n"
                                "property float x\nproperty float y\nproperty float z\n"
                                "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                                "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                                "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n1 1 0 9 9 9\n"
                                "3 0 1 2\n4 0 1 3 2\n";
    seed("mesh", "ascii.ply", ascii, sizeof ascii - 1, false);
    /* Big-endian doubles and a quad; a particle set (vertices only). */
    buf be = {0};
    buf_str(&be, "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\n"
                 "property double y\nproperty double z\nelement face 1\n"
                 "property list uchar uint vertex_indices\nend_header\n");
    for (int i = 0; i < 9; i++) {
        double v = i % 4 == 0 ? 1.0 : 0.0;
        uint64_t u;
        memcpy(&u, &v, 8);
        for (int k = 7; k >= 0; k--) {
            uint8_t c = (uint8_t)(u >> (8 * k));
            buf_add(&be, &c, 1);
        }
    }
    uint8_t face[] = {3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2};
    buf_add(&be, face, sizeof face);
    seed("mesh", "big_endian.ply", be.p, be.n, false);
    free(be.p);
    static const char particles[] = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                    "property float y\nproperty float z\nend_header\n"
                                    "0.1 0.2 0.3\n0.11 0.2 0.3\n-4 5 6\n";
    seed("mesh", "particles.ply", particles, sizeof particles - 1, false);
    static const char off[] = "OFF\n# a tetrahedron\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                              "3 0 1 2\n3 0 1 3 255 0 0\n3 0 2 3\n4 1 2 3 0\n";
    seed("mesh", "tetra.off", off, sizeof off - 1, true);
}

/* ------------------------------------------------------------ the store */

static void seeds_store(void)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/store", tmp_dir);
    store_writer *w = NULL;
    check(store_writer_open(dir, false, &w));
    hostmap m = {.chunk_m = 2.0f, .origin_w = {0.5, -1, 2}, .n_bricks = 3};
    m.bricks = calloc(3, sizeof *m.bricks);
    m.rgb565 = calloc(3 * 512, 2);
    if (!m.bricks || !m.rgb565) abort();
    int32_t keys[3][3] = {{0, 0, 0}, {0, 0, 0}, {-1, 2, 0}};
    for (int i = 0; i < 3; i++) {
        hostmap_brick *b = &m.bricks[i];
        memcpy(b->key, keys[i], sizeof b->key);
        b->level = i == 1 ? 0 : 2;
        b->cell[0] = (uint32_t)i, b->cell[1] = 1, b->cell[2] = 0;
        b->error = 0.004f;
        for (int k = 0; k < 16; k++) b->sign[k] = 0x0f0f0f0fu * (uint32_t)(k + i), b->conf[k] = ~0u;
    }
    m.rgb565[7] = 0xf800; /* the first chunk has colour (version 2), the other not */
    bf_traj t = {0};
    bf_se3 T = bf_se3_identity();
    check(bf_traj_push(&t, 1.0, &T));
    T.t = bf_v3(0.1, 0, 0);
    check(bf_traj_push(&t, 1.5, &T));
    store_meta meta = {.chunk_m = 2.0f, .max_level = 8, .origin_w = {0.5, -1, 2}, .frames = 2, .has_pose = true,
                       .last_pose = T, .last_t_s = 1.5};
    check(store_writer_submit(w, &m, &meta, &t));
    check(store_writer_finish(w));
    store_writer_close(w);
    bf_traj_free(&t);
    hostmap_free(&m);
    char p[4300];
    buf b = {0};
    buf_str(&b, "fix");
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/store.json", dir);
    buf_file(&b, p);
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/trajectory.bin", dir);
    buf_file(&b, p);
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/chunks/c_0_0_0.bfc", dir);
    buf_file(&b, p);
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/chunks/c_-1_2_0.bfc", dir);
    buf_file(&b, p);
    seed("store", "store_fix", b.p, b.n, true);
    /* The same without the checksum repair; and chunks alone (no index). */
    seed("store", "store", b.p + 3, b.n - 3, false);
    /* With keyframes.bin (part 6; part 5 repeats a chunk file): two
     * keyframes, one with three keypoints, one without. */
    uint8_t desc[3 * 32];
    float xyz[9] = {0.1f, 0.2f, 1.5f, -0.3f, 0.0f, 2.0f, 0.0f, -0.1f, 3.2f};
    for (int i = 0; i < 96; i++) desc[i] = (uint8_t)(37 * i);
    store_keyframe kfs[2] = {{.T_wc = bf_se3_identity(), .n = 3, .desc = desc, .xyz = xyz}, {.T_wc = T}};
    store_keyframes kf = {.n = 2, .kf = kfs};
    check(store_keyframes_write(dir, &kf));
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/chunks/c_-1_2_0.bfc", dir);
    buf_file(&b, p);
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/keyframes.bin", dir);
    buf_file(&b, p);
    seed("store", "store_keyframes_fix", b.p, b.n, false);
    free(b.p);
    b = (buf){0};
    buf_str(&b, "fix");
    buf_sep(&b);
    buf_sep(&b);
    buf_sep(&b);
    snprintf(p, sizeof p, "%s/chunks/c_-1_2_0.bfc", dir);
    buf_file(&b, p);
    seed("store", "chunks_only", b.p, b.n, false);
    free(b.p);
}

/* ------------------------------------------------------------ calibration */

static void seeds_calib(void)
{
    calib_result r = {.colour = {.width = 640, .height = 480, .fx_px = 525, .fy_px = 526, .cx_px = 319.5,
                                 .cy_px = 239.5, .dist = {0.1, -0.2, 0.001, 0.002, 0.05}, .rms_px = 0.3},
                      .has_depth = true,
                      .depth = {.width = 640, .height = 480, .fx_px = 580, .fy_px = 580, .cx_px = 320, .cy_px = 240},
                      .T_colour_depth = bf_se3_identity(),
                      .rms_px = 0.4,
                      .n_views = 12};
    r.T_colour_depth.t = bf_v3(-0.025, 0, 0);
    check(calib_write(tmp("calib.json"), &r));
    buf b = {0};
    buf_file(&b, tmp("calib.json"));
    seed("calib", "colour_depth.json", b.p, b.n, true);
    free(b.p);
    r.has_depth = false;
    check(calib_write(tmp("calib.json"), &r));
    b = (buf){0};
    buf_file(&b, tmp("calib.json"));
    seed("calib", "colour.json", b.p, b.n, false);
    free(b.p);
}

/* ------------------------------------------------------------ depth correction */

static void seeds_depthcorr(void)
{
    static calib_depth_correction c = {.width = 64, .height = 48, .cell_px = 16, .grid_w = 4, .grid_h = 3,
                                       .n_frames = 40, .n_pairs = 20, .n_cells_measured = 12, .rms_before = 0.003,
                                       .rms_after = 0.0002};
    for (uint32_t i = 0; i < 12; i++) c.mult[i] = 1.0f + 0.001f * (float)i - 0.006f;
    check(calib_depth_write(tmp("depth_correction.json"), &c));
    buf b = {0};
    buf_file(&b, tmp("depth_correction.json"));
    seed("depthcorr", "grid_4x3.json", b.p, b.n, true);
    free(b.p);
    /* The same, saying it was made through a lens (TUM fr1's). */
    calib_depth_correction l = c;
    const double fr1[CALIB_DIST_N] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
    l.is_lens_known = true;
    memcpy(l.lens, fr1, sizeof fr1);
    check(calib_depth_write(tmp("depth_correction.json"), &l));
    buf c2 = {0};
    buf_file(&c2, tmp("depth_correction.json"));
    seed("depthcorr", "grid_4x3_lens.json", c2.p, c2.n, false);
    free(c2.p);
}

/* ------------------------------------------------------------ --expect's baseline */

/* The whole stats.json files of replay runs (replay*.json and their
 * combinations) need a device, so they are copied from runs into the corpus
 * (docs/fuzz.md); here the measures --expect looks up, alone: a small input
 * whose every byte the fuzzer's mutations reach. */
static const char measures_json[] = "{\n\t\"command\":\t\"replay\",\n"
                                    "\t\"tracking\":\t{\"tracked\": 20, \"lost\": 0, \"relocalised\": 0},\n"
                                    "\t\"ate_m\":\t{\"rmse\": 0.00042925569921996326},\n"
                                    "\t\"surface_m\":\t{\"median\": 0.003359377384185791},\n"
                                    "\t\"frame_ms\":\t{\"median\": 85.28168500197353},\n"
                                    "\t\"map_digest\":\t\"xxh3:77e3c6a1640b7d66\"\n}\n";
/* A run where every measure moved or changed type, gated with tolerances. */
static const char moved_json[] = "{\"tracking\": {\"tracked\": 19, \"lost\": 1, \"relocalised\": \"1\"}, "
                                 "\"ate_m\": {\"rmse\": 0.0125}, \"surface_m\": null, "
                                 "\"frame_ms\": {\"median\": 1e300}, \"map_digest\": 7}\n";

static void seeds_expect(void)
{
    seed("expect", "measures.json", measures_json, sizeof measures_json - 1, true);
    buf b = {0};
    buf_str(&b, measures_json);
    buf_sep(&b);
    buf_str(&b, "ate=0.002,surface=0.0005,time=0.2");
    buf_sep(&b);
    buf_str(&b, moved_json);
    seed("expect", "measures_moved", b.p, b.n, false);
    free(b.p);
}

/* ------------------------------------------------------------ a V4L2 camera */

static void put(buf *b, uint32_t v, int bytes)
{
    for (int i = 0; i < bytes; i++) {
        uint8_t c = (uint8_t)(v >> (8 * i));
        buf_add(b, &c, 1);
    }
}

/* A node's answers at open (fuzz_v4l2.c): capabilities, formats (indices
 * into its table), size, bytes per line, S_FMT keeps the format. */
static void v4l2_node(buf *b, uint32_t format, uint32_t bpp)
{
    put(b, 0, 1);
    put(b, 2, 1);
    put(b, 4, 1); /* a format it does not want first */
    put(b, format, 1);
    put(b, W, 2);
    put(b, H, 2);
    put(b, W * bpp + 4, 4);
    put(b, 0, 1);
}

static void v4l2_buffers(buf *b, uint32_t bpp)
{
    put(b, 3, 1);
    for (int i = 0; i < 3; i++) put(b, (W * bpp + 4) * H, 4);
}

static void v4l2_frame(buf *b, uint32_t index, uint32_t seq, uint32_t bpp, const void *px)
{
    put(b, 1, 1); /* poll: ready */
    put(b, index, 1);
    put(b, (W * bpp + 4) * H, 4);
    put(b, seq, 4);
    put(b, 2 | 40 << 2, 1);
    for (int y = 0; y < H; y++) {
        buf_add(b, (const uint8_t *)px + (size_t)y * W * bpp, W * bpp);
        put(b, 0, 4);
    }
}

static void seeds_v4l2(void)
{
    buf b = {0};
    put(&b, 0, 1);
    v4l2_node(&b, 0, 2);
    v4l2_buffers(&b, 2);
    for (uint32_t i = 0; i < 3; i++) v4l2_frame(&b, i, i == 2 ? 5 : i, 2, depth_px);
    seed("v4l2", "depth", b.p, b.n, true);
    free(b.p);
    /* Depth and YUYV colour (2 bytes a pixel; the pixels' values do not
     * matter) and BGR24 colour. */
    for (int k = 0; k < 2; k++) {
        uint32_t cbpp = k ? 3 : 2;
        b = (buf){0};
        put(&b, 1, 1);
        v4l2_node(&b, 0, 2);
        v4l2_node(&b, k ? 3 : 1, cbpp);
        v4l2_buffers(&b, 2);
        v4l2_buffers(&b, cbpp);
        for (uint32_t i = 0; i < 2; i++) {
            v4l2_frame(&b, i, i, 2, depth_px);
            v4l2_frame(&b, i, i, cbpp, rgb_px);
            put(&b, 0, 1); /* poll: no newer colour */
        }
        seed("v4l2", k ? "depth_bgr" : "depth_yuyv", b.p, b.n, false);
        free(b.p);
    }
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: fuzz_seeds CORPUS_DIR (tests/fuzz/corpus)\n");
        return 2;
    }
    out_root = argv[1];
    snprintf(tmp_dir, sizeof tmp_dir, "%s", fuzz_scratch());
    make_pixels();
    seeds_image();
    seeds_text();
    seeds_folder();
    seeds_bflog();
    seeds_mesh();
    seeds_store();
    seeds_calib();
    seeds_depthcorr();
    seeds_expect();
    seeds_v4l2();
    return 0;
}
