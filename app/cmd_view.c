/* bitfuse view: what bitfuse render draws (a saved map, a mesh, particles)
 * in a window (view/), ray-cast on the GPU (render/) at the window's
 * camera; --screenshot and --exit-after for scripts. The options it shares
 * with bitfuse render are render's rows and mean the same (app/scene.c). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "gpu/gpu.h"
#include "mesh/mesh.h"
#include "render/render.h"
#include "replay/replay.h"
#include "view/view.h"

static const char view_usage[] =
    "usage: bitfuse view [--map STORE|DIR] [--mesh FILE [--mesh-pose P] [--mesh-lod on|off]] [--particles FILE]\n"
    "                    [--pose \"tx ty tz qx qy qz qw\"] [--camera fx,fy,cx,cy] [--size WxH] [--near M] [--far M]\n"
    "                    [--particle-radius M] [--particle-cell M] [--particle-lod on|off] [--overlay on|off]\n"
    "                    [--screenshot IMAGE.png --exit-after N]\n\n"
    "Shows what bitfuse render draws, in a window: a saved map (a scene store, bitfuse\n"
    "replay|live --store; or a folder holding one as DIR/store), a closed mesh voxelised\n"
    "into its bricks, particles, each pixel the nearest hit. Left drag orbits about a point\n"
    "ahead, right or middle drag pans, the wheel zooms, Esc or Q closes. The pose is camera\n"
    "to world as in TUM trajectories (the camera looks along +z, y down); without --pose\n"
    "the store's last camera pose, else a view of the whole scene. The scene's size is in\n"
    "the title bar and over the image's corner. The window needs a display (X11; for\n"
    "scripts xvfb-run) and a Vulkan device that presents to it. docs/view.md.\n";

static const char view_epilog[] =
    "exit codes: 0 ok, 1 failure, 2 usage (also a bad pose, size or camera), 3 unreadable\n"
    "map, mesh or particle file, 4 no display, no usable Vulkan device, or a device that\n"
    "cannot present to the window, 5 the screenshot could not be written\n";

typedef struct view_args {
    app_scene_args scene;
    const char *pose, *camera, *size, *screenshot;
    uint32_t exit_after;
    bool overlay;
} view_args;

static int parse_args(int argc, char **argv, view_args *a)
{
    const app_option rows[] = {
        APP_OPT("--pose", APP_OPT_STRING, &a->pose, "\"tx ty tz qx qy qz qw\"",
                "the first camera, camera to world (TUM: looks along +z, y down); default the store's last pose, "
                "else the whole scene", .no_default = true, .check = app_check_pose),
        APP_OPT("--camera", APP_OPT_STRING, &a->camera, "fx,fy,cx,cy",
                "intrinsics in pixels at --size (default: 525 * W / 640, the image's centre); a resized window "
                "scales them", .no_default = true, .check = app_check_camera),
        APP_OPT("--size", APP_OPT_STRING, &a->size, "WxH", "the window's size", .check = app_check_size),
        APP_OPT("--overlay", APP_OPT_CHOICE, &a->overlay, "on|off",
                "the scene's size also over the image's corner (always in the title)"),
        APP_OPT("--screenshot", APP_OPT_STRING, &a->screenshot, "IMAGE.png",
                "with --exit-after: the window's last frame, read back from the window (RGB PNG)",
                .check = app_check_png, .needs = "--exit-after"),
        APP_OPT("--exit-after", APP_OPT_U32, &a->exit_after, "N", "close the window after N frames shown (scripts)",
                .min = 1, .no_default = true),
        APP_OPT_END,
    };
    app_option scene[APP_SCENE_ROWS];
    app_scene_options(scene, &a->scene,
                      "a closed triangle mesh (PLY or OFF, metres), voxelised into the map's bricks at the first "
                      "pose's detail",
                      "level of detail within the mesh, from the first camera (--pose, the store's, else the whole scene's): each part at "
                      "the level its pixel footprint needs there (off: the nearest point's level everywhere)");
    const app_option *tables[] = {scene, rows, NULL};
    app_command_spec spec = {.name = "view", .usage = view_usage, .tables = tables, .epilog = view_epilog};
    return app_options_parse(&spec, argc, argv);
}

/* What the window draws, on the GPU, and where it is. */
typedef struct view_scene {
    fusion_map *map;          /* the store's map and the mesh's bricks; NULL: none */
    render_particles *ps;     /* NULL: none */
    uint64_t n_bricks;        /* the map's bricks and the particles' */
    bool has_pose;
    bf_se3 last_pose;         /* the store's last camera pose */
    bf_vec3 lo_w, hi_w;       /* the bounding box of brick centres, mesh vertices and particles */
    double far_m;             /* the rays' far plane */
} view_scene;

static void grow(view_scene *sc, bf_vec3 p)
{
    sc->lo_w = bf_v3(fmin(sc->lo_w.x, p.x), fmin(sc->lo_w.y, p.y), fmin(sc->lo_w.z, p.z));
    sc->hi_w = bf_v3(fmax(sc->hi_w.x, p.x), fmax(sc->hi_w.y, p.y), fmax(sc->hi_w.z, p.z));
}

/* Without --pose or a stored pose: the camera back from the scene's centre
 * along -z by what fits its box in the image, looking along +z. */
static bf_se3 overview_pose(const view_scene *sc, const bf_intrinsics *K)
{
    bf_vec3 c = bf_v3_scale(bf_v3_add(sc->lo_w, sc->hi_w), 0.5), h = bf_v3_scale(bf_v3_sub(sc->hi_w, sc->lo_w), 0.5);
    double r = sqrt(h.x * h.x + h.y * h.y + h.z * h.z);
    double half_fov = atan(0.5 * K->height / fabs(K->fy_px)); /* ICL-NUIM's fy is negative */
    bf_se3 T = bf_se3_identity();
    T.t = bf_v3_sub(c, bf_v3(0, 0, fmax(r / sin(half_fov), 0.5)));
    return T;
}

/* The scene's box: the map's brick centres, the mesh's vertices where
 * --mesh-pose puts them, the particles. */
static void scene_box(view_scene *sc, const app_scene_files *f, const hostmap *hm)
{
    sc->lo_w = bf_v3(INFINITY, INFINITY, INFINITY);
    sc->hi_w = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < hm->n_bricks; i++) grow(sc, hostmap_voxel_center_w(hm, &hm->bricks[i], 4, 4, 4));
    const mesh_data *m = &f->mesh;
    for (uint32_t i = 0; i < m->n_verts; i++)
        grow(sc, bf_se3_apply(&f->T_wm, bf_v3(m->origin.x + m->xyz[3 * i], m->origin.y + m->xyz[3 * i + 1],
                                              m->origin.z + m->xyz[3 * i + 2])));
    for (uint32_t i = 0; i < f->n_particles; i++)
        grow(sc, bf_v3(f->xyz[3 * i], f->xyz[3 * i + 1], f->xyz[3 * i + 2]));
}

/* The scene on the GPU as bitfuse render loads it: the map read already
 * (hm, emptied here; meta its store's), the mesh at the detail of the
 * first camera, *T_wc: --pose (has_pose), else the store's last pose,
 * else the view of the whole scene (set here). */
static bf_status load_scene(gpu_context *ctx, const view_args *a, app_scene_files *f, hostmap *map_read,
                            const store_meta *meta, const bf_intrinsics *K, bf_se3 *T_wc, bool has_pose,
                            view_scene *sc)
{
    hostmap hm = *map_read;
    *map_read = (hostmap){0};
    bf_status s = BF_OK;
    sc->has_pose = a->scene.map && meta->has_pose;
    sc->last_pose = meta->last_pose;
    scene_box(sc, f, &hm);
    sc->far_m = a->scene.far_m;
    if (!has_pose && !sc->has_pose) {
        *T_wc = overview_pose(sc, K);
        /* Back far enough to see all of it: the rays reach its far side
         * too, unless --far says otherwise (a 20 m slab's view is 34 m back). */
        bf_vec3 h = bf_v3_scale(bf_v3_sub(sc->hi_w, sc->lo_w), 0.5);
        double reach = sc->hi_w.z - T_wc->t.z + sqrt(h.x * h.x + h.y * h.y);
        if (!a->scene.far_given && isfinite(reach) && reach > sc->far_m) sc->far_m = fmin(reach, 1000.0);
    } else if (!has_pose) {
        *T_wc = sc->last_pose;
    }
    /* Level of detail from the first camera, as bitfuse render does from its pose. */
    if (a->scene.mesh) s = app_scene_add_mesh(ctx, &a->scene, f, T_wc, K, a->scene.mesh_lod, &hm, NULL, NULL);
    if (s == BF_OK && (a->scene.map || a->scene.mesh)) s = app_scene_load_map(ctx, &hm, K, &sc->map);
    sc->n_bricks = hm.n_bricks;
    hostmap_free(&hm);
    if (s == BF_OK && a->scene.particles) {
        s = app_scene_make_particles(ctx, &a->scene, f, &sc->ps);
        if (s == BF_OK) sc->n_bricks += render_particles_get_stats(sc->ps)->n_bricks;
    }
    return s;
}

/* The pivot: the scene's centre's depth ahead of the camera, at least 0.3 m. */
static double pivot_m(const view_scene *sc, const bf_se3 *T)
{
    bf_vec3 d = bf_v3_sub(bf_v3_scale(bf_v3_add(sc->lo_w, sc->hi_w), 0.5), T->t);
    double z = d.x * T->R[0][2] + d.y * T->R[1][2] + d.z * T->R[2][2];
    return isfinite(z) ? fmax(z, 0.3) : 1.0;
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
    opt.near_m = (float)a->scene.near_m;
    opt.far_m = (float)sc->far_m;
    opt.no_graze = a->scene.mesh != NULL; /* a mesh's outline, as bitfuse render draws it (docs/render.md) */
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
            s = render_scene(c, sc->map, sc->ps, &K, &T, &opt);
            is_coarse = coarse;
            last = c;
        }
        double t1 = bf_time_s();
        bool is_last = a->exit_after && shown + 1 == a->exit_after, is_shown = false;
        view_set_status(L->win, &st);
        if (s == BF_OK) s = view_show(L->win, render_get_targets(last), is_last ? L->rgb : NULL, &is_shown);
        if (s == BF_OK && !is_shown) view_wait(L->win, 0.1); /* minimised, or a swapchain remade */
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
    view_args a = {.size = "640x480", .overlay = true};
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    if ((rc = app_scene_check(cmd, "show", &a.scene)) != 0) return rc;
    uint32_t W = 640, H = 480;
    app_parse_size(a.size, &W, &H);
    double k[4] = {525.0 * W / 640.0, 525.0 * W / 640.0, (W - 1) / 2.0, (H - 1) / 2.0};
    if (a.camera) app_parse_camera(a.camera, k);
    bf_intrinsics K = {W, H, k[0], k[1], k[2], k[3], 5000};
    bf_se3 T_wc = bf_se3_identity();
    char msg[512];
    if (a.pose) app_parse_pose(a.pose, &T_wc, msg, sizeof msg);

    /* The files and the map before the window: a bad path or map is named
     * first, also where no window can open. */
    app_scene_files f = {0};
    bf_status s = app_scene_read_files(&a.scene, &f);
    hostmap hm = {0};
    store_meta meta = {0};
    if (s == BF_OK && a.scene.map) s = app_scene_read_map(a.scene.map, &hm, &meta, NULL);
    view_config vc = view_config_default();
    vc.width = W, vc.height = H;
    vc.title = "bitfuse view";
    vc.overlay = a.overlay;
    vc.fx_px = k[0];
    gpu_config gcfg = {0};
    view_loop L = {0};
    view_scene sc = {0};
    if (s == BF_OK) s = view_open(&vc, &gcfg, &L.win);
    if (s == BF_OK) s = gpu_context_create(&gcfg, &L.ctx);
    if (s == BF_OK) s = load_scene(L.ctx, &a, &f, &hm, &meta, &K, &T_wc, a.pose != NULL, &sc);
    if (s == BF_OK) s = view_attach(L.win, L.ctx);
    if (s == BF_OK) {
        view_set_pose(L.win, &T_wc, pivot_m(&sc, &T_wc));
        s = run_window(&L, &sc, &a, k, W, H);
    }
    view_detach(L.win);
    render_destroy(L.caster);
    render_destroy(L.coarse);
    render_particles_destroy(sc.ps);
    fusion_destroy(sc.map);
    gpu_context_destroy(L.ctx);
    view_destroy(L.win);
    free(L.rgb);
    hostmap_free(&hm);
    app_scene_files_free(&f);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
