/* eval: a whole synthetic sequence: trajectory in, TUM folder out.
 *
 * Placement: the trajectory (any TUM file, e.g. a real motion-capture run)
 * lives in its own world frame. It is moved into the scene by one rigid
 * transform, T_world_traj = T_view * inv(T_traj(t_0)): the first frame's
 * camera lands exactly on the scene's chosen view (for the room: 1.75 m from
 * the table, looking at it) and every later pose is
 * T_wc(t) = T_world_traj * T_traj(t), so all relative motion is the
 * trajectory's own, untouched.
 *
 * Timing: frames at t_0 + i / rate (30 Hz by default), poses interpolated
 * between the trajectory's samples (linear position, slerp rotation), as a
 * sensor following that motion would record them. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "synth_int.h"

#include "replay/replay.h"

/* ------------------------------------------------------------ seen points */

/* The visibility mask: noise-free surface points that got valid depth, one
 * per cell of a grid, so the density is about uniform by area. */
typedef struct seen_set {
    uint64_t *keys;   /* open addressing, 0 = empty */
    size_t cap, n;
    float *xyz;
    size_t xyz_cap;
    double cell_m;
} seen_set;

static bool seen_grow(seen_set *s)
{
    size_t cap = s->cap ? 2 * s->cap : (size_t)1 << 16;
    uint64_t *keys = calloc(cap, sizeof *keys);
    if (!keys) return false;
    for (size_t i = 0; i < s->cap; i++) {
        uint64_t k = s->keys[i];
        if (!k) continue;
        size_t j = synth__mix64(k) & (cap - 1);
        while (keys[j]) j = (j + 1) & (cap - 1);
        keys[j] = k;
    }
    free(s->keys);
    s->keys = keys;
    s->cap = cap;
    return true;
}

static bool seen_add(seen_set *s, bf_vec3 p_in)
{
    /* Cells from the float coordinates that seen.ply stores, centred on
     * multiples of the cell size: the room's walls, floor and table top lie
     * on such multiples, and a boundary cell there would take points from
     * both sides of the plane (double rounding puts hits on either). */
    float pf[3] = {(float)p_in.x, (float)p_in.y, (float)p_in.z};
    int64_t c[3];
    for (int k = 0; k < 3; k++) c[k] = (int64_t)floor(pf[k] / s->cell_m + 0.5);
    uint64_t key = 1; /* never 0 */
    for (int k = 0; k < 3; k++) {
        int64_t v = c[k] + ((int64_t)1 << 20);
        if (v < 0 || v >= ((int64_t)1 << 21)) return true; /* beyond +-5 km: ignore */
        key = (key << 21) | (uint64_t)v;
    }
    if (2 * (s->n + 1) > s->cap && !seen_grow(s)) return false;
    size_t j = synth__mix64(key) & (s->cap - 1);
    while (s->keys[j]) {
        if (s->keys[j] == key) return true;
        j = (j + 1) & (s->cap - 1);
    }
    if (3 * (s->n + 1) > s->xyz_cap) {
        size_t cap = s->xyz_cap ? 2 * s->xyz_cap : 3 * 65536;
        float *xyz = realloc(s->xyz, cap * sizeof *xyz);
        if (!xyz) return false;
        s->xyz = xyz;
        s->xyz_cap = cap;
    }
    s->keys[j] = key;
    memcpy(s->xyz + 3 * s->n, pf, sizeof pf);
    s->n++;
    return true;
}

/* Half the pixels per frame, in both directions every other one, the
 * pattern shifting from frame to frame so four frames cover every pixel. */
static bool seen_collect(seen_set *s, const synth_renderer *r, uint32_t frame, uint32_t w, uint32_t h)
{
    uint32_t ou = frame & 1, ov = (frame >> 1) & 1;
    for (uint32_t v = ov; v < h; v += 2)
        for (uint32_t u = ou; u < w; u += 2) {
            bf_vec3 p;
            if (synth_render_clean_point(r, u, v, &p) && !seen_add(s, p)) return false;
        }
    return true;
}

static void seen_free(seen_set *s)
{
    free(s->keys);
    free(s->xyz);
}

/* ------------------------------------------------------------ image writing
 * Encoding the two PNGs of a frame takes about a third of the render time,
 * on one thread. A writer thread encodes frame i while frame i + 1 renders
 * (two frame buffers in turn), so the cores stay busy. Frames reach the TUM
 * writer in order, one at a time; its first failure stops the run. */

typedef struct png_stage {
    replay_tum_writer *w;
    pthread_t thread;
    bool is_threaded;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    bool has_job, is_quitting;
    bf_frame job;
    bf_status status;
    char msg[1024]; /* bf_last_error() of the writer thread */
} png_stage;

static void *png_stage_main(void *arg)
{
    png_stage *st = arg;
    pthread_mutex_lock(&st->mu);
    for (;;) {
        while (!st->has_job && !st->is_quitting) pthread_cond_wait(&st->cv, &st->mu);
        if (!st->has_job) break;
        bf_frame f = st->job;
        pthread_mutex_unlock(&st->mu);
        bf_status s = st->status ? BF_OK : replay_tum_writer_add(st->w, &f);
        pthread_mutex_lock(&st->mu);
        if (s && !st->status) {
            st->status = s;
            snprintf(st->msg, sizeof st->msg, "%s", bf_last_error());
        }
        st->has_job = false;
        pthread_cond_broadcast(&st->cv);
    }
    pthread_mutex_unlock(&st->mu);
    return NULL;
}

static void png_stage_start(png_stage *st, replay_tum_writer *w)
{
    memset(st, 0, sizeof *st);
    st->w = w;
    if (pthread_mutex_init(&st->mu, NULL)) return;
    if (pthread_cond_init(&st->cv, NULL)) {
        pthread_mutex_destroy(&st->mu);
        return;
    }
    st->is_threaded = bf_thread_start(&st->thread, png_stage_main, st) == 0;
    if (!st->is_threaded) {
        pthread_cond_destroy(&st->cv);
        pthread_mutex_destroy(&st->mu);
    }
}

/* Waits until the previous frame is written; returns its status. */
static bf_status png_stage_wait(png_stage *st)
{
    if (!st->is_threaded) return st->status;
    pthread_mutex_lock(&st->mu);
    while (st->has_job) pthread_cond_wait(&st->cv, &st->mu);
    bf_status s = st->status;
    pthread_mutex_unlock(&st->mu);
    return s ? bf_fail(s, "%s", st->msg) : BF_OK;
}

/* Hands f over (its buffers must stay untouched until the next wait). */
static bf_status png_stage_post(png_stage *st, const bf_frame *f)
{
    bf_status s = png_stage_wait(st);
    if (s != BF_OK) return s;
    if (!st->is_threaded) return st->status = replay_tum_writer_add(st->w, f);
    pthread_mutex_lock(&st->mu);
    st->job = *f;
    st->has_job = true;
    pthread_cond_broadcast(&st->cv);
    pthread_mutex_unlock(&st->mu);
    return BF_OK;
}

/* Waits for the last frame and ends the thread; returns the first failure. */
static bf_status png_stage_stop(png_stage *st)
{
    bf_status s = png_stage_wait(st);
    if (st->is_threaded) {
        pthread_mutex_lock(&st->mu);
        st->is_quitting = true;
        pthread_cond_broadcast(&st->cv);
        pthread_mutex_unlock(&st->mu);
        pthread_join(st->thread, NULL);
        pthread_cond_destroy(&st->cv);
        pthread_mutex_destroy(&st->mu);
        st->is_threaded = false;
    }
    return s;
}

/* ------------------------------------------------------------ outputs */

static bf_status write_scene_ply(const char *dir, const synth_scene *sc)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, "scene.ply");
    if (s != BF_OK) return s;
    /* Vertex colours: the albedo where the vertex sits, for viewing. */
    mesh_data m = sc->mesh;
    m.rgb = malloc((size_t)m.n_verts * 3 + 1);
    uint8_t *done = calloc((size_t)m.n_verts + 1, 1);
    if (!m.rgb || !done) {
        free(m.rgb);
        free(done);
        return bf_fail(BF_NO_MEMORY, "%s: vertex colours", path);
    }
    memset(m.rgb, 255, (size_t)m.n_verts * 3);
    for (uint32_t t = 0; t < m.n_tris; t++)
        for (int k = 0; k < 3; k++) {
            uint32_t vi = m.tri[3 * (size_t)t + k];
            if (done[vi]) continue;
            done[vi] = 1;
            double rgb[3];
            const float *p = m.xyz + 3 * (size_t)vi;
            synth__albedo(sc->tri_material[t], sc->tri_variant[t], bf_v3(p[0], p[1], p[2]), rgb);
            for (int c = 0; c < 3; c++) m.rgb[3 * (size_t)vi + c] = (uint8_t)fmin(255, fmax(0, rgb[c] * 255 + 0.5));
        }
    s = mesh_write_ply(path, &m);
    free(m.rgb);
    free(done);
    return s;
}

static bf_status write_seen_ply(const char *dir, const seen_set *seen)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, "seen.ply");
    if (s != BF_OK) return s;
    mesh_data m = {.n_verts = (uint32_t)seen->n, .xyz = seen->xyz};
    return mesh_write_ply(path, &m);
}

static const char *noise_name(synth_noise n) { return n == SYNTH_NOISE_KINECT1 ? "kinect1" : "none"; }

static bf_status write_stats(const synth_config *cfg, const bf_intrinsics *K, const synth_scene *sc,
                             const synth_result *res, uint32_t n_requested, double t0_s, double p95_s,
                             double cell_m, double rate_hz)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, cfg->out_dir, "stats.json");
    if (s != BF_OK) return s;
    bf_quat q;
    bf_vec3 t;
    bf_se3_to_qt(&res->T_world_traj, &q, &t);
    const double(*R)[3] = res->T_world_traj.R;
    const bf_vec3 *tw = &res->T_world_traj.t;
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "command", "synth");
    if (cfg->version) cJSON_AddStringToObject(o, "version", cfg->version);
    cJSON_AddStringToObject(o, "scene", sc->desc);
    cJSON_AddNumberToObject(o, "scene_triangles", sc->mesh.n_tris);
    cJSON_AddStringToObject(o, "trajectory", cfg->traj_path);
    cJSON_AddNumberToObject(o, "t_first_s", t0_s);
    cJSON_AddNumberToObject(o, "rate_hz", rate_hz);
    cJSON_AddNumberToObject(o, "frames", res->n_frames);
    cJSON_AddNumberToObject(o, "frames_requested", n_requested);
    cJSON_AddStringToObject(o, "noise", noise_name(cfg->noise));
    cJSON_AddNumberToObject(o, "seed", (double)cfg->seed);
    cJSON *cam = cJSON_AddObjectToObject(o, "camera");
    cJSON_AddNumberToObject(cam, "width", K->width);
    cJSON_AddNumberToObject(cam, "height", K->height);
    cJSON_AddNumberToObject(cam, "fx", K->fx_px);
    cJSON_AddNumberToObject(cam, "fy", K->fy_px);
    cJSON_AddNumberToObject(cam, "cx", K->cx_px);
    cJSON_AddNumberToObject(cam, "cy", K->cy_px);
    cJSON_AddNumberToObject(cam, "depth_scale", K->depth_scale);
    cJSON *tpf = cJSON_AddObjectToObject(o, "time_per_frame_s");
    cJSON_AddNumberToObject(tpf, "mean", res->mean_frame_s);
    cJSON_AddNumberToObject(tpf, "median", res->median_frame_s);
    cJSON_AddNumberToObject(tpf, "p95", p95_s);
    cJSON_AddNumberToObject(o, "frames_per_s", res->mean_frame_s > 0 ? 1.0 / res->mean_frame_s : 0);
    cJSON_AddNumberToObject(o, "total_s", res->total_s);
    cJSON_AddNumberToObject(o, "threads", bf_thread_count());
    cJSON_AddNumberToObject(o, "valid_depth_share", res->valid_share);
    cJSON_AddNumberToObject(o, "seen_points", res->n_seen);
    cJSON_AddNumberToObject(o, "seen_cell_m", cell_m);
    cJSON *pl = cJSON_AddObjectToObject(o, "placement");
    cJSON_AddStringToObject(pl, "rule",
                            "T_world_traj = T_view * inv(T_traj(t_first)); rendered pose = T_world_traj * T_traj(t)");
    cJSON_AddItemToObject(pl, "t", cJSON_CreateDoubleArray((double[]){t.x, t.y, t.z}, 3));
    cJSON_AddItemToObject(pl, "q_xyzw", cJSON_CreateDoubleArray((double[]){q.x, q.y, q.z, q.w}, 4));
    cJSON *M = cJSON_AddArrayToObject(pl, "matrix");
    double rows[4][4] = {{R[0][0], R[0][1], R[0][2], tw->x}, {R[1][0], R[1][1], R[1][2], tw->y},
                         {R[2][0], R[2][1], R[2][2], tw->z}, {0, 0, 0, 1}};
    for (int i = 0; i < 4; i++) cJSON_AddItemToArray(M, cJSON_CreateDoubleArray(rows[i], 4));
    char *text = cJSON_Print(o);
    cJSON_Delete(o);
    if (!text) return bf_fail(BF_NO_MEMORY, "%s: out of memory building the JSON", path);
    s = bf_write_file_atomic(path, text, strlen(text));
    cJSON_free(text);
    return s;
}

/* ------------------------------------------------------------ the sequence */

bf_status synth_run(const synth_config *cfg, synth_result *out)
{
    if (!cfg || !cfg->scene || !cfg->traj_path || !cfg->out_dir)
        return bf_fail(BF_INVALID_ARG, "synth: scene, trajectory and output folder are required");
    if (cfg->n_frames == 0) return bf_fail(BF_INVALID_ARG, "synth: zero frames requested");
    double rate = cfg->rate_hz > 0 ? cfg->rate_hz : 30.0;
    if (!isfinite(rate) || rate > 1e5) return bf_fail(BF_INVALID_ARG, "synth: frame rate %g Hz", rate);
    double cell = cfg->seen_cell_m > 0 ? cfg->seen_cell_m : 0.005;
    bf_intrinsics K = cfg->K;
    if (K.width == 0) K.width = 640;
    if (K.height == 0) K.height = 480;
    if (K.fx_px == 0) {
        /* 640x480's field of view at any size, as render and view take it. */
        K.fx_px = K.fy_px = 525.0 * K.width / 640.0;
        K.cx_px = (K.width - 1) / 2.0;
        K.cy_px = (K.height - 1) / 2.0;
    }
    if (K.depth_scale == 0) K.depth_scale = 5000.0;

    bf_traj traj = {0};
    synth_scene scene = {0};
    synth_renderer *r = NULL;
    replay_tum_writer *w = NULL;
    uint16_t *depth[2] = {NULL, NULL};
    uint8_t *rgb[2] = {NULL, NULL};
    png_stage stage;
    bool has_stage = false;
    seen_set seen = {.cell_m = cell};
    bf_stats times = {0};
    double t_run = bf_time_s();
    bf_status s;
    if ((s = replay_traj_read_tum(cfg->traj_path, &traj))) goto done;
    double t0 = traj.t_s[0], t_end = traj.t_s[traj.n - 1];
    /* Frames whose time lies within the trajectory. */
    uint32_t n_frames = 0;
    while (n_frames < cfg->n_frames && t0 + n_frames / rate <= t_end) n_frames++;
    if (n_frames < cfg->n_frames)
        bf_warn("synth: %s spans %.3f s: only %u of %u frames at %g Hz fit, stopping there", cfg->traj_path,
                t_end - t0, n_frames, cfg->n_frames, rate);

    uint32_t n_rooms = 0;
    if (!strcmp(cfg->scene, "room"))
        s = synth_scene_room(cfg->data_dir, &scene);
    else if (!strncmp(cfg->scene, "rooms:", 6) && !bf_parse_u32(cfg->scene + 6, &n_rooms))
        s = bf_fail(BF_INVALID_ARG, "synth: %s: rooms:N takes a count of 1 to 64 rooms", cfg->scene);
    else if (!strncmp(cfg->scene, "rooms:", 6))
        s = synth_scene_rooms(n_rooms, &scene);
    else
        s = synth_scene_from_ply(cfg->scene, cfg->mesh_scale > 0 ? cfg->mesh_scale : 1.0, &scene);
    if (s != BF_OK) goto done;
    bf_info("synth: scene: %s", scene.desc);

    bf_se3 T_first_inv = bf_se3_inverse(&traj.T_wc[0]);
    bf_se3 T_world_traj = bf_se3_mul(&scene.T_wc_view, &T_first_inv);

    synth_render_config rc = {K, cfg->noise, cfg->seed};
    double t_build = bf_time_s();
    if ((s = synth_renderer_create(&scene, &rc, &r))) goto done;
    bf_info("synth: BVH over %u triangles in %.2f s", scene.mesh.n_tris, bf_time_s() - t_build);
    if ((s = replay_tum_writer_create(cfg->out_dir, &K, &w))) goto done;
    size_t n_pix = (size_t)K.width * K.height;
    for (int k = 0; k < 2; k++) {
        depth[k] = malloc(n_pix * sizeof *depth[k]);
        rgb[k] = malloc(n_pix * 3);
    }
    if (!depth[0] || !rgb[0] || !depth[1] || !rgb[1]) {
        s = bf_fail(BF_NO_MEMORY, "synth: frame buffers");
        goto done;
    }

    png_stage_start(&stage, w);
    has_stage = true;
    bf_progress prog;
    bf_progress_begin(&prog, "synth", n_frames);
    uint64_t n_valid = 0;
    for (uint32_t i = 0; i < n_frames; i++) {
        double t = t0 + i / rate;
        bf_se3 T_traj;
        if (!bf_traj_interpolate(&traj, t, &T_traj)) {
            s = bf_fail(BF_INVALID_ARG, "synth: frame %u: time %.6f outside %s", i, t, cfg->traj_path);
            goto done;
        }
        bf_se3 T_wc = bf_se3_mul(&T_world_traj, &T_traj);
        synth_render_stats st;
        /* Buffer i % 2 was last handed over for frame i - 2, written by now. */
        uint16_t *d = depth[i & 1];
        uint8_t *c = rgb[i & 1];
        if ((s = synth_render(r, i, &T_wc, d, c, &st))) goto done;
        if ((s = bf_stats_push(&times, st.seconds))) goto done;
        n_valid += st.n_valid;
        bf_frame f = {.index = i, .width = K.width, .height = K.height, .t_depth_s = t, .t_rgb_s = t,
                      .depth = d, .rgb = c, .has_pose = true, .T_wc = T_wc};
        if ((s = png_stage_post(&stage, &f))) goto done;
        if (!seen_collect(&seen, r, i, K.width, K.height)) {
            s = bf_fail(BF_NO_MEMORY, "synth: frame %u: seen points", i);
            goto done;
        }
        bf_progress_update(&prog, i + 1);
    }
    bf_progress_end(&prog, n_frames);
    has_stage = false;
    if ((s = png_stage_stop(&stage))) goto done;
    if ((s = replay_tum_writer_finish(w))) goto done;
    if ((s = write_scene_ply(cfg->out_dir, &scene))) goto done;
    if ((s = write_seen_ply(cfg->out_dir, &seen))) goto done;

    synth_result res = {
        .n_frames = n_frames,
        .mean_frame_s = bf_stats_mean(&times),
        .median_frame_s = bf_stats_percentile(&times, 50),
        .valid_share = (double)n_valid / ((double)n_pix * n_frames),
        .T_world_traj = T_world_traj,
        .n_seen = (uint32_t)seen.n,
        .n_scene_tris = scene.mesh.n_tris,
        .total_s = bf_time_s() - t_run, /* stats.json itself excluded */
    };
    if ((s = write_stats(cfg, &K, &scene, &res, cfg->n_frames, t0, bf_stats_percentile(&times, 95), cell, rate)))
        goto done;
    if (out) *out = res;
done:
    if (has_stage) png_stage_stop(&stage); /* the run already failed: keep its status */
    replay_tum_writer_destroy(w);
    synth_renderer_destroy(r);
    synth_scene_free(&scene);
    bf_traj_free(&traj);
    seen_free(&seen);
    bf_stats_free(&times);
    for (int k = 0; k < 2; k++) {
        free(depth[k]);
        free(rgb[k]);
    }
    return s;
}
