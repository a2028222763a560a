/* bitfuse view: a saved map in a window (view/), ray-cast on the GPU
 * (render/) at the window's camera; --screenshot and --exit-after for
 * scripts. The options it shares with bitfuse render mean the same. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "app.h"
#include "gpu/gpu.h"
#include "render/render.h"
#include "replay/replay.h"
#include "view/view.h"

static const char view_usage[] =
    "usage: bitfuse view --map STORE|DIR [--pose \"tx ty tz qx qy qz qw\"] [--camera fx,fy,cx,cy]\n"
    "                    [--size WxH] [--screenshot IMAGE.png --exit-after N]\n\n"
    "Shows a saved map (a scene store, bitfuse replay|live --store; or a folder holding\n"
    "one as DIR/store) in a window, ray-cast on the GPU at the window's camera: left drag\n"
    "orbits about a point ahead, right or middle drag pans, the wheel zooms, Esc or Q\n"
    "closes. The pose is camera to world as in TUM trajectories (the camera looks along\n"
    "+z, y down); without --pose the store's last camera pose, else a view of the whole\n"
    "map. The map's size is in the title bar and over the image's corner. The window needs a display (X11; for\n"
    "scripts xvfb-run) and a Vulkan device that presents to it. docs/view.md.\n";

static const char view_epilog[] =
    "exit codes: 0 ok, 1 failure (also a screenshot not writable), 2 usage (also a bad pose,\n"
    "size or camera), 3 unreadable map, 4 no display, no usable Vulkan device, or a device\n"
    "that cannot present to the window\n";

/* "tx ty tz qx qy qz qw" -> T_wc (a unit quaternion within 1e-3); false with the reason in msg. */
static bool parse_pose(const char *v, bf_se3 *T, char *msg, size_t n)
{
    double a[7];
    int used = 0;
    if (sscanf(v, "%lf %lf %lf %lf %lf %lf %lf %n", &a[0], &a[1], &a[2], &a[3], &a[4], &a[5], &a[6], &used) != 7 ||
        v[used] != '\0') {
        snprintf(msg, n, "--pose \"%s\": expected 7 numbers \"tx ty tz qx qy qz qw\"", v);
        return false;
    }
    for (int i = 0; i < 7; i++)
        if (!isfinite(a[i])) {
            snprintf(msg, n, "--pose \"%s\": not finite", v);
            return false;
        }
    double qn = sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6]);
    if (fabs(qn - 1) > 1e-3) {
        snprintf(msg, n, "--pose \"%s\": the quaternion's norm is %g, not 1", v, qn);
        return false;
    }
    bf_quat q = bf_quat_normalize((bf_quat){.w = a[6], .x = a[3], .y = a[4], .z = a[5]});
    *T = bf_se3_from_qt(q, bf_v3(a[0], a[1], a[2]));
    return true;
}

static const char *check_pose(const char *name, const char *v)
{
    static char msg[512];
    bf_se3 T;
    (void)name;
    return parse_pose(v, &T, msg, sizeof msg) ? NULL : msg;
}

static bool parse_size(const char *v, uint32_t *w, uint32_t *h)
{
    unsigned a, b;
    int used = 0;
    if (sscanf(v, "%ux%u%n", &a, &b, &used) != 2 || v[used] != '\0' || a < 1 || b < 1 || a > 8192 || b > 8192)
        return false;
    *w = a, *h = b;
    return true;
}

static const char *check_size(const char *name, const char *v)
{
    static char msg[256];
    uint32_t w, h;
    if (parse_size(v, &w, &h)) return NULL;
    snprintf(msg, sizeof msg, "%s \"%s\": expected WxH, each 1..8192", name, v);
    return msg;
}

static bool parse_camera(const char *v, double k[4])
{
    int used = 0;
    if (sscanf(v, "%lf,%lf,%lf,%lf%n", &k[0], &k[1], &k[2], &k[3], &used) != 4 || v[used] != '\0') return false;
    return k[0] > 0 && k[1] > 0 && isfinite(k[0]) && isfinite(k[1]) && isfinite(k[2]) && isfinite(k[3]);
}

static const char *check_camera(const char *name, const char *v)
{
    static char msg[256];
    double k[4];
    if (parse_camera(v, k)) return NULL;
    snprintf(msg, sizeof msg, "%s \"%s\": expected fx,fy,cx,cy in pixels (focal lengths above 0)", name, v);
    return msg;
}

static const char *check_png(const char *name, const char *v)
{
    static char msg[256];
    size_t n = strlen(v);
    if (n > 4 && strcasecmp(v + n - 4, ".png") == 0) return NULL;
    snprintf(msg, sizeof msg, "%s %s: the image is written as PNG (a name ending .png)", name, v);
    return msg;
}

typedef struct view_args {
    const char *map, *pose, *camera, *size, *screenshot;
    double far_m;
    uint32_t exit_after;
    bool overlay;
} view_args;

static int parse_args(int argc, char **argv, view_args *a)
{
    const app_option rows[] = {
        APP_OPT("--map", APP_OPT_STRING, &a->map, "STORE", "the map: a scene store, or a folder holding one as DIR/store",
                .required = true),
        APP_OPT("--pose", APP_OPT_STRING, &a->pose, "\"tx ty tz qx qy qz qw\"",
                "the first camera, camera to world (TUM: looks along +z, y down); default the store's last pose, "
                "else the whole map", .no_default = true, .check = check_pose),
        APP_OPT("--camera", APP_OPT_STRING, &a->camera, "fx,fy,cx,cy",
                "intrinsics in pixels at --size (default: 525 * W / 640, the image's centre); a resized window "
                "scales them", .no_default = true, .check = check_camera),
        APP_OPT("--size", APP_OPT_STRING, &a->size, "WxH", "the window's size", .check = check_size),
        APP_OPT("--far", APP_OPT_DOUBLE, &a->far_m, "M", "farthest depth a ray looks [m]", .min = 0.3, .max = 1000),
        APP_OPT("--overlay", APP_OPT_CHOICE, &a->overlay, "on|off",
                "the map's size also over the image's corner (always in the title)"),
        APP_OPT("--screenshot", APP_OPT_STRING, &a->screenshot, "IMAGE.png",
                "with --exit-after: the window's last frame, read back from the window (RGB PNG)", .check = check_png),
        APP_OPT("--exit-after", APP_OPT_U32, &a->exit_after, "N", "close the window after N frames shown (scripts)",
                .min = 1, .no_default = true),
        APP_OPT_END,
    };
    const app_option *tables[] = {rows, NULL};
    app_command_spec spec = {.name = "view", .usage = view_usage, .tables = tables, .epilog = view_epilog};
    return app_options_parse(&spec, argc, argv);
}

/* A GPU map of the store's size holding its bricks (as bitfuse render loads one). */
typedef struct view_scene {
    fusion_map *map;
    uint32_t n_bricks;
    bool has_pose;
    bf_se3 last_pose;
    bf_vec3 centre_w, half_w; /* the bricks' bounding box */
} view_scene;

static bf_status read_store(const char *path, hostmap *m, store_meta *meta, uint32_t *n_chunks)
{
    char sub[4096];
    const char *dir = path;
    if (!bf_file_exists(path)) return bf_fail(BF_IO, "%s: no such map (store or folder)", path);
    if (!store_exists(path)) {
        snprintf(sub, sizeof sub, "%s/store", path);
        if (!store_exists(sub))
            return bf_fail(BF_FORMAT, "%s: not a scene store (bitfuse replay|live --store), nor a folder holding one "
                                      "as store/", path);
        dir = sub;
    }
    store_report rep;
    bf_status s = store_read(dir, m, meta, NULL, &rep);
    if (s == BF_OK && rep.n_bad) bf_warn("view: %s: %u chunk file(s) left out, the first: %s", dir, rep.n_bad, rep.first_bad);
    if (s == BF_OK && m->n_bricks == 0) s = bf_fail(BF_FORMAT, "%s: the store holds no brick", dir);
    *n_chunks = rep.n_chunks;
    return s;
}

static void bounds(const hostmap *m, view_scene *sc)
{
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY), hi = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < m->n_bricks; i++) {
        bf_vec3 c = hostmap_voxel_center_w(m, &m->bricks[i], 4, 4, 4);
        lo = bf_v3(fmin(lo.x, c.x), fmin(lo.y, c.y), fmin(lo.z, c.z));
        hi = bf_v3(fmax(hi.x, c.x), fmax(hi.y, c.y), fmax(hi.z, c.z));
    }
    sc->centre_w = bf_v3_scale(bf_v3_add(lo, hi), 0.5);
    sc->half_w = bf_v3_scale(bf_v3_sub(hi, lo), 0.5);
}

static bf_status load_scene(gpu_context *ctx, const char *path, const bf_intrinsics *K, view_scene *sc)
{
    hostmap m = {0};
    store_meta meta;
    uint32_t n_chunks = 0;
    bf_status s = read_store(path, &m, &meta, &n_chunks);
    fusion_config fc = fusion_config_default();
    fc.chunk_m = m.chunk_m;
    fc.brick_cap = m.n_bricks + 1;
    fc.window = 2;
    fc.subcache = 1;
    fc.keep_colour = m.rgb565 != NULL;
    fc.colour_unit_cap = fc.keep_colour ? 8 * fc.brick_cap : 1; /* 5.5 units a brick on real frames (docs/colour.md) */
    fc.hash_buckets = 64;
    while (fc.hash_buckets < n_chunks * 2) fc.hash_buckets *= 2;
    fc.hash_overflow = fc.hash_buckets;
    /* A fused map holds about 3 nodes a brick (DESIGN.md section 3), a
     * sparse one more: retry with a bigger node pool when it is short. */
    for (uint32_t per = 3; s == BF_OK && per <= 48; per *= 4) {
        fc.node_cap = per * fc.brick_cap + 64;
        s = fusion_create(ctx, &fc, K, m.origin_w, &sc->map);
        if (s == BF_OK) s = fusion_load(sc->map, &m);
        if (s != BF_POOL_FULL || per == 48) break;
        fusion_destroy(sc->map);
        sc->map = NULL;
        s = BF_OK;
    }
    if (s == BF_OK) {
        sc->n_bricks = m.n_bricks;
        sc->has_pose = meta.has_pose;
        sc->last_pose = meta.last_pose;
        bounds(&m, sc);
    }
    hostmap_free(&m);
    return s;
}

/* Without --pose or a stored pose: the camera back from the map's centre
 * along -z by what fits the box in the image, looking along +z. */
static bf_se3 overview_pose(const view_scene *sc, const bf_intrinsics *K)
{
    double r = sqrt(sc->half_w.x * sc->half_w.x + sc->half_w.y * sc->half_w.y + sc->half_w.z * sc->half_w.z);
    double half_fov = atan(0.5 * K->height / K->fy_px);
    bf_se3 T = bf_se3_identity();
    T.t = bf_v3_sub(sc->centre_w, bf_v3(0, 0, fmax(r / sin(half_fov), 0.5)));
    return T;
}

/* The pivot: the map's centre's depth ahead of the camera, at least 0.3 m. */
static double pivot_m(const view_scene *sc, const bf_se3 *T)
{
    bf_vec3 d = bf_v3_sub(sc->centre_w, T->t);
    double z = d.x * T->R[0][2] + d.y * T->R[1][2] + d.z * T->R[2][2];
    return fmax(z, 0.3);
}

/* The intrinsics at the window's size: --camera (or the default) scaled. */
static bf_intrinsics intrinsics_at(const double k[4], uint32_t W0, uint32_t H0, uint32_t w, uint32_t h)
{
    double sx = (double)w / W0, sy = (double)h / H0;
    return (bf_intrinsics){w, h, k[0] * sx, k[1] * sy, (k[2] + 0.5) * sx - 0.5, (k[3] + 0.5) * sy - 0.5, 5000};
}

typedef struct view_loop {
    view_window *win;
    render_caster *caster; /* at the window's size */
    render_caster *coarse; /* at half of it, while the camera moves */
    gpu_context *ctx;
    uint8_t *rgb;
} view_loop;

/* The casters (and the screenshot's pixels) for a window of w x h. */
static bf_status resize(view_loop *L, const view_args *a, uint32_t w, uint32_t h)
{
    render_destroy(L->caster);
    render_destroy(L->coarse);
    L->caster = L->coarse = NULL;
    free(L->rgb);
    L->rgb = NULL;
    bf_status s = render_create(L->ctx, NULL, w, h, &L->caster);
    if (s == BF_OK) s = render_create(L->ctx, NULL, (w + 1) / 2, (h + 1) / 2, &L->coarse);
    if (s == BF_OK && a->screenshot && !(L->rgb = malloc(3ull * w * h)))
        s = bf_fail(BF_NO_MEMORY, "view: screenshot of %ux%u", w, h);
    return s;
}

/* Draws until the window closes or --exit-after frames were shown; the
 * screenshot is the last frame read back from the window. A moving camera
 * is ray-cast at half the window's size (a quarter of the rays: the cast
 * is the frame's cost, about 1 s at 640x480 on lavapipe, docs/view.md) and
 * stretched; once it rests, at full size. With nothing new the loop sleeps
 * in view_wait and shows the last image again twice a second (an exposed
 * window) without casting. --exit-after casts every frame at full size. */
static bf_status run_window(view_loop *L, view_scene *sc, const view_args *a, const double k[4], uint32_t W0, uint32_t H0)
{
    render_options opt = render_options_display();
    opt.far_m = (float)a->far_m;
    uint32_t cw = 0, ch = 0, shown = 0;
    bf_se3 T_last;
    memset(&T_last, 0, sizeof T_last);
    double t_last = 0;
    bool is_coarse = false;
    const render_caster *last = NULL;
    bf_status s = BF_OK;
    view_status st = {.n_bricks = sc->n_bricks};
    while (s == BF_OK && view_poll(L->win)) {
        uint32_t w, h;
        view_size(L->win, &w, &h);
        bf_se3 T = view_pose(L->win);
        bool is_resized = w != cw || h != ch, has_moved = memcmp(&T, &T_last, sizeof T) != 0;
        bool cast = a->exit_after || is_resized || has_moved || is_coarse;
        if (!cast && bf_time_s() - t_last < 0.5) {
            view_wait(L->win, 0.1);
            continue;
        }
        if (is_resized) {
            s = resize(L, a, w, h);
            cw = w, ch = h;
            last = NULL;
        }
        double t0 = bf_time_s();
        if (s == BF_OK && (cast || !last)) {
            bool coarse = !a->exit_after && has_moved && !is_resized;
            render_caster *c = coarse ? L->coarse : L->caster;
            const render_targets *t = render_get_targets(c);
            bf_intrinsics K = intrinsics_at(k, W0, H0, t->width, t->height);
            s = render_raycast(c, sc->map, &K, &T, &opt);
            is_coarse = coarse;
            last = c;
        }
        double t1 = bf_time_s();
        bool is_last = a->exit_after && shown + 1 == a->exit_after, is_shown = false;
        view_set_status(L->win, &st);
        if (s == BF_OK) s = view_show(L->win, render_get_targets(last), is_last ? L->rgb : NULL, &is_shown);
        if (s != BF_OK || !is_shown) continue;
        bf_debug("view: frame %u: ray-cast %.1f ms (GPU %.1f, %ux%u), shown in %.1f ms", shown + 1, 1e3 * (t1 - t0),
                 render_last_ms(last), render_get_targets(last)->width, render_get_targets(last)->height,
                 1e3 * (bf_time_s() - t1));
        T_last = T;
        t_last = bf_time_s();
        if (++shown == a->exit_after) {
            if (a->screenshot) {
                s = replay_png_write_rgb8(a->screenshot, L->rgb, w, h);
                if (s != BF_OK) return s;
                printf("bitfuse view: %u frames shown at %ux%u, the last in %s\n", shown, w, h, a->screenshot);
            }
            break;
        }
    }
    return s;
}

int cmd_view(int argc, char **argv)
{
    const char *cmd = "view";
    view_args a = {.size = "640x480", .far_m = 13.1, .overlay = true};
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    if (a.screenshot && !a.exit_after)
        return app_usage_error(cmd, "--screenshot needs --exit-after N (the frame it saves)");
    uint32_t W = 640, H = 480;
    parse_size(a.size, &W, &H);
    double k[4] = {525.0 * W / 640.0, 525.0 * W / 640.0, (W - 1) / 2.0, (H - 1) / 2.0};
    if (a.camera) parse_camera(a.camera, k);
    bf_intrinsics K = {W, H, k[0], k[1], k[2], k[3], 5000};
    bf_se3 T_wc = bf_se3_identity();
    char msg[512];
    if (a.pose) parse_pose(a.pose, &T_wc, msg, sizeof msg);

    /* The map's file before the window: a bad path is named first. */
    bf_status s = bf_file_exists(a.map) ? BF_OK : bf_fail(BF_IO, "%s: no such map (store or folder)", a.map);
    view_config vc = view_config_default();
    vc.width = W, vc.height = H;
    vc.title = "bitfuse view";
    vc.overlay = a.overlay;
    gpu_config gcfg = {0};
    view_loop L = {0};
    view_scene sc = {0};
    if (s == BF_OK) s = view_open(&vc, &gcfg, &L.win);
    if (s == BF_OK) s = gpu_context_create(&gcfg, &L.ctx);
    if (s == BF_OK) s = load_scene(L.ctx, a.map, &K, &sc);
    if (s == BF_OK) s = view_attach(L.win, L.ctx);
    if (s == BF_OK) {
        if (!a.pose) T_wc = sc.has_pose ? sc.last_pose : overview_pose(&sc, &K);
        view_set_pose(L.win, &T_wc, pivot_m(&sc, &T_wc));
        s = run_window(&L, &sc, &a, k, W, H);
    }
    bool is_write_failure = s == BF_IO && sc.map;
    view_detach(L.win);
    render_destroy(L.caster);
    render_destroy(L.coarse);
    fusion_destroy(sc.map);
    gpu_context_destroy(L.ctx);
    view_destroy(L.win);
    free(L.rgb);
    if (s == BF_OK) return APP_EXIT_OK;
    int code = app_fail(cmd, s);
    return is_write_failure ? APP_EXIT_FAILURE : code;
}
