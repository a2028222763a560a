/* synth: checkerboard views for camera calibration, rendered exactly: each
 * pixel's ray (through the lens's distortion, calib's model) meets the
 * board's plane analytically, and a pixel that an edge of the pattern
 * crosses is averaged over a grid of samples (a box filter, as a sensor's
 * pixel integrates light). Corner detectors then see the sub-pixel
 * positions the geometry gives, and what a calibration recovers can be held
 * to the truth written beside the images. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "synth_int.h"

#include "replay/replay.h"

/* Grey of the parts of the scene, in [0, 1]: a printed board's black ink
 * and white paper, and a background darker than the paper so the white
 * margin stands out as real boards' do. */
#define BOARD_BLACK 0.08
#define BOARD_WHITE 0.90
#define POSE_DRAWS 200
#define EDGE_MARGIN_PX 8.0 /* the margin's outline keeps this far from the image border */

/* ------------------------------------------------------------ poses */

synth_board_config synth_board_config_default(void)
{
    /* The colour camera of a Kinect v1 as synth's sequences have it; the IR
     * camera a little longer in focal length (Kinect's is about 580 px)
     * with its own principal point, 25 mm beside it (the Kinect's baseline
     * between the two) and turned by 0.5 degrees, as a real pair is never
     * exactly parallel. */
    synth_board_config c = {
        .board = {.cols = 9, .rows = 6, .square_m = 0.04},
        .n_views = 15,
        .colour = {.width = 640, .height = 480, .fx_px = 525, .fy_px = 525, .cx_px = 319.5, .cy_px = 239.5},
        .depth = {.width = 640, .height = 480, .fx_px = 580, .fy_px = 580, .cx_px = 314.5, .cy_px = 242.5},
        .supersample = 8,
        .noise_levels = 1.0,
        .seed = 1,
    };
    c.T_colour_depth = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, 1, 0.2), 0.5 * M_PI / 180),
                                      bf_v3(-0.025, 0.001, 0.002));
    return c;
}

static double draw(uint64_t seed, uint32_t k, uint32_t attempt, uint32_t what)
{
    return synth__u01(synth__rng_key(seed, k, attempt * 16 + what, SYNTH_RNG_BOARD));
}

/* True when the margin's four outer corners project inside c's image. */
static bool margin_inside(const synth_board_config *cfg, const calib_camera *c, const bf_se3 *T_cb)
{
    double s = cfg->board.square_m;
    double x0 = -2 * s, y0 = -2 * s, x1 = (cfg->board.cols + 1) * s, y1 = (cfg->board.rows + 1) * s;
    const double xs[4] = {x0, x1, x1, x0}, ys[4] = {y0, y0, y1, y1};
    for (int i = 0; i < 4; i++) {
        /* Edges between the corners: a few points each, as distortion bends them. */
        for (int t = 0; t < 8; t++) {
            double a = t / 8.0;
            double x = xs[i] + a * (xs[(i + 1) % 4] - xs[i]), y = ys[i] + a * (ys[(i + 1) % 4] - ys[i]);
            double u, v;
            if (!calib_project(c, bf_se3_apply(T_cb, bf_v3(x, y, 0)), &u, &v)) return false;
            if (!(u >= EDGE_MARGIN_PX && v >= EDGE_MARGIN_PX && u <= c->width - 1 - EDGE_MARGIN_PX &&
                  v <= c->height - 1 - EDGE_MARGIN_PX))
                return false;
        }
    }
    return true;
}

bf_status synth_board_pose(const synth_board_config *cfg, uint32_t k, bf_se3 *T_colour_board)
{
    double s = cfg->board.square_m;
    bf_vec3 centre_b = bf_v3((cfg->board.cols - 1) * s / 2, (cfg->board.rows - 1) * s / 2, 0);
    bf_se3 T_dc = bf_se3_inverse(&cfg->T_colour_depth);
    uint32_t n = cfg->n_views ? cfg->n_views : 1;
    for (uint32_t attempt = 0; attempt < POSE_DRAWS; attempt++) {
        /* Later draws come nearer the middle and farther away, so a board
         * that fits at all is placed within the draws. */
        double shrink = 1.0 - (double)attempt / POSE_DRAWS;
        double dist_m = 0.55 + 0.55 * draw(cfg->seed, k, attempt, 0) + 0.6 * (1 - shrink);
        double axis_a = 2 * M_PI * (k + 0.5 * draw(cfg->seed, k, attempt, 1)) / n;
        double tilt = (15 + 30 * draw(cfg->seed, k, attempt, 2)) * M_PI / 180;
        double spin = (draw(cfg->seed, k, attempt, 3) - 0.5) * 40 * M_PI / 180;
        /* Where the centre is seen: up to 15% of the image off the middle. */
        double ox = (draw(cfg->seed, k, attempt, 4) - 0.5) * 0.3 * shrink;
        double oy = (draw(cfg->seed, k, attempt, 5) - 0.5) * 0.3 * shrink;
        bf_quat q_tilt = bf_quat_from_axis_angle(bf_v3(cos(axis_a), sin(axis_a), 0), tilt);
        bf_quat q_spin = bf_quat_from_axis_angle(bf_v3(0, 0, 1), spin);
        bf_se3 T = bf_se3_from_qt(bf_quat_mul(q_tilt, q_spin), bf_v3(0, 0, 0));
        const calib_camera *c = &cfg->colour;
        bf_vec3 centre_c = bf_v3_scale(bf_v3(ox * c->width / c->fx_px, oy * c->height / c->fy_px, 1), dist_m);
        T.t = bf_v3_sub(centre_c, bf_se3_apply(&T, centre_b));
        bf_se3 T_db = bf_se3_mul(&T_dc, &T);
        if (margin_inside(cfg, &cfg->colour, &T) && margin_inside(cfg, &cfg->depth, &T_db)) {
            *T_colour_board = T;
            return BF_OK;
        }
    }
    return bf_fail(BF_INVALID_ARG, "synth: a %ux%u board of %g m squares does not fit both cameras' images in %d "
                                   "draws (view %u): use smaller squares",
                   cfg->board.cols, cfg->board.rows, s, POSE_DRAWS, k);
}

/* ------------------------------------------------------------ rendering */

typedef struct board_job {
    const synth_board_config *cfg;
    const calib_camera *c;
    bf_se3 T_bc;        /* camera to board */
    uint32_t ss, stream;
    uint8_t *grey;
    volatile bool has_failed; /* a row's corner buffer could not be allocated */
} board_job;

/* The board-plane point (x, y) seen along pixel (u, v); false when the ray
 * misses the plane (parallel or behind the camera). */
static bool board_point(const board_job *j, double u, double v, double *x, double *y)
{
    bf_vec3 ray_c;
    if (!calib_unproject(j->c, u, v, &ray_c)) return false;
    bf_vec3 o = j->T_bc.t, d = bf_se3_rotate(&j->T_bc, ray_c);
    if (!(fabs(d.z) > 1e-12)) return false;
    double t = -o.z / d.z;
    if (!(t > 0)) return false;
    *x = o.x + t * d.x;
    *y = o.y + t * d.y;
    return true;
}

/* Behind the board, far away: a grey that varies slowly across the image
 * (no edges a detector could take for the board's). */
static double background_grey(double u, double v) { return 0.35 + 0.1 * sin(u * 0.01) * cos(v * 0.013); }

/* The grey at board point (x, y) seen at pixel (u, v): squares (a, b) =
 * (floor(x/s) + 1, floor(y/s) + 1) in [0, cols] x [0, rows], black where
 * a + b is even; the margin white; beyond it the background. */
static double board_grey(const synth_board_config *cfg, double x, double y, double u, double v)
{
    double s = cfg->board.square_m;
    double a = floor(x / s) + 1, b = floor(y / s) + 1;
    if (a >= 0 && b >= 0 && a <= cfg->board.cols && b <= cfg->board.rows)
        return fmod(a + b, 2.0) == 0 ? BOARD_BLACK : BOARD_WHITE;
    if (a >= -1 && b >= -1 && a <= cfg->board.cols + 1 && b <= cfg->board.rows + 1) return BOARD_WHITE;
    return background_grey(u, v);
}

/* The pattern's cell of board point (x, y): (a, b) as board_grey numbers
 * squares, and one cell for everything beyond the margin (-1 when the ray
 * missed the plane): a pixel whose corners share a cell shows no edge. */
static int64_t board_cell(const synth_board_config *cfg, bool is_hit, double x, double y)
{
    if (!is_hit) return -1;
    double s = cfg->board.square_m;
    double a = floor(x / s) + 1, b = floor(y / s) + 1;
    if (!(a >= -1 && b >= -1 && a <= cfg->board.cols + 1 && b <= cfg->board.rows + 1)) return -2;
    return (int64_t)(b + 1) * 1024 + (int64_t)(a + 1);
}

/* The board points and cells of the pixel corners along image row edge
 * v - 1/2 (u = -1/2 .. w - 1/2). */
typedef struct corner_row {
    double *x, *y;
    int64_t *cell;
} corner_row;

static void corner_row_fill(const board_job *j, double v, corner_row *r)
{
    for (uint32_t i = 0; i <= j->c->width; i++) {
        bool is_hit = board_point(j, i - 0.5, v, &r->x[i], &r->y[i]);
        r->cell[i] = board_cell(j->cfg, is_hit, r->x[i], r->y[i]);
    }
}

/* One pixel: where its four corners share a cell (the footprint of a pixel
 * on the board is nearly a parallelogram, so no edge passes between them)
 * the cell's grey at its centre; else the mean of ss x ss samples. */
static double pixel_grey(const board_job *j, uint32_t u, uint32_t v, const corner_row *top, const corner_row *bottom)
{
    const synth_board_config *cfg = j->cfg;
    int64_t cell = top->cell[u];
    if (cell == top->cell[u + 1] && cell == bottom->cell[u] && cell == bottom->cell[u + 1]) {
        if (cell < 0) return background_grey(u, v);
        double x = 0.25 * (top->x[u] + top->x[u + 1] + bottom->x[u] + bottom->x[u + 1]);
        double y = 0.25 * (top->y[u] + top->y[u + 1] + bottom->y[u] + bottom->y[u + 1]);
        return board_grey(cfg, x, y, u, v);
    }
    double sum = 0;
    for (uint32_t sy = 0; sy < j->ss; sy++)
        for (uint32_t sx = 0; sx < j->ss; sx++) {
            double su = u - 0.5 + (sx + 0.5) / j->ss, sv = v - 0.5 + (sy + 0.5) / j->ss, x, y;
            sum += board_point(j, su, sv, &x, &y) ? board_grey(cfg, x, y, su, sv) : background_grey(su, sv);
        }
    return sum / (j->ss * j->ss);
}

static void render_row(void *ctx, size_t row)
{
    board_job *j = ctx;
    uint32_t w = j->c->width, v = (uint32_t)row;
    size_t n = (size_t)w + 1;
    /* One allocation for the two corner rows (per row, not per image: rows
     * render on several threads). */
    double *buf = malloc(n * 2 * (2 * sizeof(double) + sizeof(int64_t)));
    if (!buf) {
        j->has_failed = true;
        return;
    }
    corner_row top = {buf, buf + n, (int64_t *)(buf + 2 * n)};
    corner_row bottom = {buf + 3 * n, buf + 4 * n, (int64_t *)(buf + 5 * n)};
    corner_row_fill(j, v - 0.5, &top);
    corner_row_fill(j, v + 0.5, &bottom);
    for (uint32_t u = 0; u < w; u++) {
        double g = 255.0 * pixel_grey(j, u, v, &top, &bottom);
        if (j->cfg->noise_levels > 0) {
            double n0, n1;
            synth__gauss2(synth__rng_key(j->cfg->seed, j->stream, v * w + u, SYNTH_RNG_COLOUR), &n0, &n1);
            g += j->cfg->noise_levels * n0;
        }
        j->grey[(size_t)v * w + u] = (uint8_t)fmin(255.0, fmax(0.0, floor(g + 0.5)));
    }
    free(buf);
}

bf_status synth_board_render(const synth_board_config *cfg, const calib_camera *c, const bf_se3 *T_cb,
                             uint32_t stream, uint8_t *grey)
{
    board_job j = {.cfg = cfg, .c = c, .T_bc = bf_se3_inverse(T_cb), .ss = cfg->supersample ? cfg->supersample : 8,
                   .stream = stream, .grey = grey};
    bf_parallel_for(c->height, render_row, &j);
    return j.has_failed ? bf_fail(BF_NO_MEMORY, "synth: board image rows") : BF_OK;
}

/* ------------------------------------------------------------ the folder */

static bf_status write_grey(const char *dir, const char *sub, uint32_t k, const uint8_t *grey, uint8_t *rgb,
                            uint32_t w, uint32_t h)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/%s/%03u.png", dir, sub, k);
    for (size_t i = 0; i < (size_t)w * h; i++) rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = grey[i];
    return replay_png_write_rgb8(path, rgb, w, h);
}

static bool camera_ok(const calib_camera *c)
{
    return c->width > 0 && c->height > 0 && c->fx_px > 0 && c->fy_px > 0 && isfinite(c->cx_px) &&
           isfinite(c->cy_px);
}

bf_status synth_board_run(const synth_board_config *cfg, synth_board_result *out)
{
    double t0 = bf_time_s();
    if (!camera_ok(&cfg->colour) || !camera_ok(&cfg->depth) || cfg->n_views == 0 || !(cfg->board.square_m > 0) ||
        cfg->board.cols < 2 || cfg->board.rows < 2 || !bf_se3_is_finite(&cfg->T_colour_depth))
        return bf_fail(BF_INVALID_ARG, "synth: board views need two cameras, a board and at least one view");
    const calib_camera *cams[2] = {&cfg->colour, &cfg->depth};
    size_t max_px = 0;
    for (int i = 0; i < 2; i++)
        if ((size_t)cams[i]->width * cams[i]->height > max_px) max_px = (size_t)cams[i]->width * cams[i]->height;
    char path[4200];
    uint8_t *grey = malloc(max_px), *rgb = malloc(3 * max_px);
    bf_se3 *T_cbs = malloc(cfg->n_views * sizeof *T_cbs);
    bf_traj poses = {0};
    bf_status s = grey && rgb && T_cbs ? BF_OK : bf_fail(BF_NO_MEMORY, "synth: board images");
    /* Every view's pose before any folder is made: a board that does not
     * fit leaves nothing behind. */
    for (uint32_t k = 0; k < cfg->n_views && s == BF_OK; k++) s = synth_board_pose(cfg, k, &T_cbs[k]);
    static const char *const subs[2] = {"colour", "ir"};
    for (int i = 0; i < 2 && s == BF_OK; i++) {
        snprintf(path, sizeof path, "%s/%s", cfg->out_dir, subs[i]);
        s = bf_mkdir_p(path);
    }
    bf_se3 T_dc = bf_se3_inverse(&cfg->T_colour_depth);
    for (uint32_t k = 0; k < cfg->n_views && s == BF_OK; k++) {
        bf_se3 T_cb = T_cbs[k], T_db, T_bc;
        T_db = bf_se3_mul(&T_dc, &T_cb);
        T_bc = bf_se3_inverse(&T_cb);
        if ((s = bf_traj_push(&poses, k, &T_bc)) != BF_OK) break;
        const bf_se3 *T[2] = {&T_cb, &T_db};
        for (int i = 0; i < 2 && s == BF_OK; i++) {
            /* Noise streams: view k's colour image 2k, its IR image 2k + 1. */
            s = synth_board_render(cfg, cams[i], T[i], 2 * k + (uint32_t)i, grey);
            if (s == BF_OK) s = write_grey(cfg->out_dir, subs[i], k, grey, rgb, cams[i]->width, cams[i]->height);
        }
    }
    if (s == BF_OK) {
        calib_result truth = {.colour = cfg->colour, .depth = cfg->depth, .has_depth = true,
                              .T_colour_depth = cfg->T_colour_depth, .n_views = cfg->n_views};
        truth.colour.rms_px = truth.depth.rms_px = 0;
        snprintf(path, sizeof path, "%s/truth.json", cfg->out_dir);
        s = calib_write(path, &truth);
    }
    if (s == BF_OK) {
        snprintf(path, sizeof path, "%s/board_poses.txt", cfg->out_dir);
        s = replay_traj_write_tum(path, &poses);
    }
    bf_traj_free(&poses);
    free(T_cbs);
    free(grey);
    free(rgb);
    if (s == BF_OK) {
        out->n_views = cfg->n_views;
        out->seconds = bf_time_s() - t0;
    }
    return s;
}
