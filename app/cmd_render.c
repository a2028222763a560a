/* bitfuse render: one view of a scene (a saved map, a particle set, or
 * both) from a given pose, ray-cast on the GPU (render/), into a shaded
 * PNG and optionally a TUM depth PNG. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "app.h"
#include "gpu/gpu.h"
#include "mesh/mesh.h"
#include "render/render.h"
#include "shaders/fusion.glsl.h"
#include "replay/replay.h"

static const char render_usage[] =
    "usage: bitfuse render [--map STORE|DIR] [--mesh FILE [--mesh-pose P] [--mesh-lod on|off]] [--particles FILE]\n"
    "                      [--particle-radius M] [--particle-cell M] [--particle-lod on|off]\n"
    "                      --pose \"tx ty tz qx qy qz qw\" [--camera fx,fy,cx,cy] --size WxH --out IMAGE.png\n"
    "                      [--depth DEPTH.png] [--near M] [--far M] [--repeat N] [--json]\n\n"
    "Ray-casts one view of a scene on the GPU: a saved map (a scene store, bitfuse\n"
    "replay|live --store; or a folder holding one as DIR/store), a particle set (a PLY\n"
    "with vertex x y z in metres; each particle a sphere of --particle-radius), or both in\n"
    "one image, each pixel the nearest hit of either. The pose is camera to world as in\n"
    "TUM trajectories (the camera looks along +z, y down). IMAGE.png is the shaded view\n"
    "(the map in its colours when it has them, else shaded by octree level; particles in\n"
    "blue); DEPTH.png is 16-bit, 5000 per metre (TUM), 0 where nothing is hit (or beyond\n"
    "13.1 m). The map shows its confident surface. A mesh (--mesh, PLY or OFF, closed,\n"
    "metres; placed by --mesh-pose) is voxelised into the map's own bricks and drawn by\n"
    "the same ray-cast, each part at the level whose voxel is at most a third of a pixel\n"
    "there (level of detail: far parts coarser; --mesh-lod off: all of it at the level of\n"
    "its nearest point). --json prints what the human lines say as one JSON object\n"
    "(docs/cli.md). docs/particles.md, docs/render.md.\n";

static const char render_epilog[] =
    "exit codes: 0 ok, 1 failure, 2 usage (also a bad pose, size or camera), 3 unreadable\n"
    "map, mesh or particle file, 4 no usable Vulkan device, 5 an image could not be written\n";

typedef struct render_args {
    app_scene_args scene;
    const char *pose, *camera, *size, *out, *depth;
    uint32_t repeat;
    bool json;
} render_args;

static int parse_args(int argc, char **argv, render_args *a)
{
    const app_option rows[] = {
        APP_OPT("--pose", APP_OPT_STRING, &a->pose, "\"tx ty tz qx qy qz qw\"",
                "camera to world (TUM: looks along +z, y down)", .required = true, .check = app_check_pose),
        APP_OPT("--camera", APP_OPT_STRING, &a->camera, "fx,fy,cx,cy",
                "intrinsics in pixels (default: 525 * W / 640, the image's centre)", .no_default = true,
                .check = app_check_camera),
        APP_OPT("--size", APP_OPT_STRING, &a->size, "WxH", "image size", .required = true, .check = app_check_size),
        APP_OPT("--out", APP_OPT_STRING, &a->out, "IMAGE.png", "the shaded view (RGB PNG)", .required = true,
                .check = app_check_png),
        APP_OPT("--depth", APP_OPT_STRING, &a->depth, "DEPTH.png", "the depth (16-bit PNG, 5000 per metre, 0: none)",
                .check = app_check_png),
        APP_OPT("--repeat", APP_OPT_U32, &a->repeat, "N", "ray-cast the view N times and report the median GPU time",
                .min = 1, .max = 1000),
        APP_OPT("--json", APP_OPT_FLAG, &a->json, NULL, "machine-readable output on stdout instead of the lines"),
        APP_OPT_END,
    };
    app_option scene[APP_SCENE_ROWS];
    app_scene_options(scene, &a->scene, "a closed triangle mesh (PLY or OFF, metres), voxelised into the map's bricks",
                      "level of detail within the mesh: each part at the level its pixel footprint needs (off: "
                      "the nearest point's level everywhere)");
    const app_option *tables[] = {scene, rows, NULL};
    app_command_spec spec = {.name = "render", .usage = render_usage, .tables = tables, .epilog = render_epilog};
    return app_options_parse(&spec, argc, argv);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static bf_status write_images(const render_images *im, const char *out, const char *depth_path)
{
    bf_status s = replay_png_write_rgb8(out, im->rgb, im->width, im->height);
    if (s != BF_OK || !depth_path) return s;
    size_t n = (size_t)im->width * im->height;
    uint16_t *d = malloc(n * 2);
    if (!d) return bf_fail(BF_NO_MEMORY, "render: depth image");
    for (size_t i = 0; i < n; i++) {
        double v = im->depth[i] > 0 ? floor(im->depth[i] * 5000.0 + 0.5) : 0;
        d[i] = v > 0 && v <= 65535 ? (uint16_t)v : 0;
    }
    s = replay_png_write_u16(depth_path, d, im->width, im->height);
    free(d);
    return s;
}

/* What the human lines say, for --json (docs/cli.md). */
typedef struct render_report {
    const render_args *a;
    uint32_t W, H;
    const char *device, *device_driver;
    double hit_frac;
    uint32_t n_map_bricks, n_bricks, n_tris;
    const store_report *map_rep;       /* the store's damage: chunk files left out, chunks missing */
    const render_voxelise_stats *vst;
    uint32_t level_asked;              /* the finest level the view asked (above vst's when the device held less) */
    const render_particles_stats *pst; /* NULL without particles */
    const double *ms, *ms_p;           /* sorted */
} render_report;

/* GPU bytes in use per particle (0 for an empty set). */
static double bytes_per_particle(const render_particles_stats *st)
{
    return st->n_particles ? (double)st->bytes_used / (double)st->n_particles : 0.0;
}

static cJSON *render_json(const render_report *r)
{
    const render_args *a = r->a;
    cJSON *o = app_json_stats("render");
    cJSON_AddStringToObject(o, "device", r->device);
    cJSON_AddStringToObject(o, "device_driver", r->device_driver);
    cJSON_AddNumberToObject(o, "width", r->W);
    cJSON_AddNumberToObject(o, "height", r->H);
    cJSON_AddStringToObject(o, "out", a->out);
    if (a->depth) cJSON_AddStringToObject(o, "depth", a->depth);
    else cJSON_AddNullToObject(o, "depth");
    cJSON_AddNumberToObject(o, "hit_fraction", r->hit_frac);
    if (a->scene.map) {
        cJSON *m = app_json_object(o, "map");
        cJSON_AddStringToObject(m, "path", a->scene.map);
        cJSON_AddNumberToObject(m, "bricks", r->n_map_bricks);
        cJSON_AddNumberToObject(m, "chunk_files_left_out", r->map_rep->n_bad);
        cJSON_AddNumberToObject(m, "chunks_missing", r->map_rep->n_missing);
    }
    if (a->scene.mesh) {
        const render_voxelise_stats *v = r->vst;
        cJSON *m = app_json_object(o, "mesh");
        cJSON_AddStringToObject(m, "path", a->scene.mesh);
        cJSON_AddNumberToObject(m, "triangles", r->n_tris);
        cJSON_AddNumberToObject(m, "level_coarse", v->level_coarse);
        cJSON_AddNumberToObject(m, "level_fine", v->level_fine);
        cJSON_AddNumberToObject(m, "level_asked", r->level_asked);
        cJSON_AddNumberToObject(m, "voxel_m", v->voxel_m);
        cJSON_AddNumberToObject(m, "bricks", v->n_bricks);
        if (v->level_coarse != v->level_fine) { /* level of detail: the bricks per level and the columns */
            double per[FUSION_MAX_LEVEL + 1];
            uint32_t n = 0;
            for (uint32_t l = v->level_coarse; l <= v->level_fine && n <= FUSION_MAX_LEVEL; l++) per[n++] = v->bricks_at_level[l];
            app_json_numbers(m, "bricks_per_level", per, n);
            cJSON_AddNumberToObject(m, "columns", v->n_columns);
            char axis[2] = {"xyz"[v->column_axis % 3], 0};
            cJSON_AddStringToObject(m, "column_axis", axis);
        }
        cJSON_AddNumberToObject(m, "gpu_bricks", v->n_gpu_bricks);
        cJSON_AddNumberToObject(m, "voxelise_seconds", v->seconds);
        cJSON_AddNumberToObject(m, "binning_seconds", v->seconds_bin);
        cJSON_AddNumberToObject(m, "gpu_pass_seconds", v->seconds_gpu);
        cJSON_AddNumberToObject(m, "triangles_per_second", v->seconds > 0 ? r->n_tris / v->seconds : 0.0);
    }
    if (a->scene.map || a->scene.mesh) cJSON_AddNumberToObject(o, "bricks", r->n_bricks);
    if (r->pst) {
        const render_particles_stats *st = r->pst;
        cJSON *p = app_json_object(o, "particles");
        cJSON_AddStringToObject(p, "path", a->scene.particles);
        cJSON_AddNumberToObject(p, "count", (double)st->n_particles);
        cJSON_AddNumberToObject(p, "radius_m", a->scene.radius_m);
        cJSON_AddNumberToObject(p, "cell_m", st->cell_m);
        cJSON_AddNumberToObject(p, "level", st->level);
        cJSON_AddBoolToObject(p, "lod", a->scene.particle_lod);
        cJSON_AddNumberToObject(p, "cells", (double)st->n_cells);
        cJSON_AddNumberToObject(p, "bricks", st->n_bricks);
        cJSON_AddNumberToObject(p, "coarse_bricks", st->n_coarse_bricks);
        cJSON_AddNumberToObject(p, "binning_seconds", st->bin_s);
        cJSON_AddNumberToObject(p, "binning_cpu_seconds", st->bin_cpu_s);
        cJSON_AddNumberToObject(p, "particles_per_second", st->bin_s > 0 ? (double)st->n_particles / st->bin_s : 0.0);
        cJSON_AddNumberToObject(p, "load_seconds", st->load_s);
        cJSON_AddNumberToObject(p, "make_map_seconds", st->make_s);
        cJSON_AddNumberToObject(p, "gpu_bytes_used", (double)st->bytes_used);
        cJSON_AddNumberToObject(p, "gpu_bytes_reserved", (double)st->bytes_reserved);
        cJSON_AddNumberToObject(p, "gpu_bytes_per_particle", bytes_per_particle(st));
    }
    cJSON *c = app_json_object(o, "raycast_ms");
    cJSON_AddNumberToObject(c, "median", r->ms[a->repeat / 2]);
    app_json_numbers(c, "sorted", r->ms, a->repeat);
    if (r->pst && (a->scene.map || a->scene.mesh))
        cJSON_AddNumberToObject(c, "particles_median", r->ms_p[a->repeat / 2]);
    return o;
}

int cmd_render(int argc, char **argv)
{
    const char *cmd = "render";
    render_args a = {.repeat = 1};
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    /* The depth would replace the image it was written beside. */
    if (a.depth && !strcmp(a.depth, a.out))
        return app_usage_error(cmd, "--depth %s is --out's file: give each its own", a.depth);
    if ((rc = app_scene_check(cmd, "render", &a.scene)) != 0) return rc;
    /* Both outputs' folders before the work: a missing --depth folder found
     * after the image was written would leave half of what was asked. */
    if ((rc = app_check_out_folder(cmd, "--out", a.out)) != 0) return rc;
    if (a.depth && (rc = app_check_out_folder(cmd, "--depth", a.depth)) != 0) return rc;
    uint32_t W = 0, H = 0;
    app_parse_size(a.size, &W, &H);
    bf_se3 T_wc;
    char msg[512];
    app_parse_pose(a.pose, &T_wc, msg, sizeof msg);
    double k[4] = {525.0 * W / 640.0, 525.0 * W / 640.0, (W - 1) / 2.0, (H - 1) / 2.0};
    if (a.camera) app_parse_camera(a.camera, k);
    bf_intrinsics K = {W, H, k[0], k[1], k[2], k[3], 5000};

    /* The inputs before the device: a missing file is named before anything starts. */
    app_scene_files f = {0};
    bf_status s = app_scene_read_files(&a.scene, &f);
    hostmap hm = {0};
    store_report map_rep = {0};
    if (s == BF_OK && a.scene.map) s = app_scene_read_map(a.scene.map, &hm, NULL, &map_rep);
    uint32_t n_bricks = 0, n_map_bricks = hm.n_bricks;
    gpu_context *ctx = NULL;
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    fusion_map *map = NULL;
    render_particles *ps = NULL;
    render_caster *caster = NULL;
    render_voxelise_stats vst = {0};
    uint32_t level_asked = 0;
    if (s == BF_OK && a.scene.mesh)
        s = app_scene_add_mesh(ctx, &a.scene, &f, &T_wc, &K, a.scene.mesh_lod, &hm, &vst, &level_asked);
    if (s == BF_OK && (a.scene.map || a.scene.mesh)) s = app_scene_load_map(ctx, &hm, &K, &map);
    n_bricks = hm.n_bricks;
    hostmap_free(&hm);
    if (s == BF_OK && a.scene.particles) s = app_scene_make_particles(ctx, &a.scene, &f, &ps);
    if (s == BF_OK) s = render_create(ctx, NULL, W, H, &caster);
    render_options opt = render_options_display();
    opt.near_m = (float)a.scene.near_m;
    opt.far_m = (float)a.scene.far_m;
    /* A mesh's outline: pass by the hits that graze a voxel's corner (docs/render.md). */
    opt.no_graze = a.scene.mesh != NULL;
    double *ms = calloc(a.repeat, sizeof *ms), *ms_p = calloc(a.repeat, sizeof *ms_p);
    if (s == BF_OK && (!ms || !ms_p)) s = bf_fail(BF_NO_MEMORY, "render: timings");
    for (uint32_t i = 0; s == BF_OK && i < a.repeat; i++) {
        s = render_scene(caster, map, ps, &K, &T_wc, &opt);
        if (s == BF_OK) ms[i] = (map ? render_last_ms(caster) : 0) + (ps ? render_particles_last_ms(ps) : 0);
        if (s == BF_OK) ms_p[i] = ps ? render_particles_last_ms(ps) : 0;
    }
    render_images im = {0};
    if (s == BF_OK) s = render_download(caster, &im);
    if (s == BF_OK) s = write_images(&im, a.out, a.depth);
    if (s == BF_OK) {
        qsort(ms, a.repeat, sizeof *ms, cmp_double);
        qsort(ms_p, a.repeat, sizeof *ms_p, cmp_double);
    }
    if (s == BF_OK && a.json) {
        uint64_t n_hit = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) n_hit += im.depth[i] > 0;
        render_report r = {&a, W, H, gpu_device_name(ctx), gpu_device(ctx)->driver_info, (double)n_hit / ((double)W * H), n_map_bricks, n_bricks,
                           f.mesh.n_tris, &map_rep, &vst, level_asked, ps ? render_particles_get_stats(ps) : NULL, ms, ms_p};
        s = app_json_print(render_json(&r));
    } else if (s == BF_OK) {
        uint64_t n_hit = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) n_hit += im.depth[i] > 0;
        printf("bitfuse render: %ux%u on %s -> %s%s%s: %.1f%% of the pixels hit\n", W, H, gpu_device_name(ctx), a.out,
               a.depth ? ", " : "", a.depth ? a.depth : "", 100.0 * (double)n_hit / ((double)W * H));
        if (a.scene.map) printf("  map              %s: %u bricks\n", a.scene.map, n_map_bricks);
        bool one_level = !a.scene.mesh_lod || vst.level_coarse == vst.level_fine;
        if (a.scene.mesh && one_level)
            printf("  mesh             %s: %u triangle%s at level %u (%.2f mm voxels): "
                   "%u bricks, voxelised in %.3f s (%.2f M triangles/s; binning %.3f s, GPU pass %.3f s over the %u bricks "
                   "with crossings to test)\n",
                   a.scene.mesh, f.mesh.n_tris, app_s(f.mesh.n_tris), vst.level_fine, 1e3 * vst.voxel_m, vst.n_bricks, vst.seconds,
                   vst.seconds > 0 ? 1e-6 * f.mesh.n_tris / vst.seconds : 0.0, vst.seconds_bin, vst.seconds_gpu,
                   vst.n_gpu_bricks);
        if (a.scene.mesh && !one_level) {
            printf("  mesh             %s: %u triangles at levels %u-%u (level of detail, %u columns along %c): %u "
                   "bricks (",
                   a.scene.mesh, f.mesh.n_tris, vst.level_coarse, vst.level_fine, vst.n_columns, "xyz"[vst.column_axis],
                   vst.n_bricks);
            for (uint32_t l = vst.level_coarse; l <= vst.level_fine; l++)
                printf("%s%u at %u", l > vst.level_coarse ? ", " : "", vst.bricks_at_level[l], l);
            printf("), voxelised in %.3f s (%.2f M triangles/s; binning %.3f s, GPU pass %.3f s over the %u bricks with "
                   "crossings to test)\n",
                   vst.seconds, vst.seconds > 0 ? 1e-6 * f.mesh.n_tris / vst.seconds : 0.0, vst.seconds_bin,
                   vst.seconds_gpu, vst.n_gpu_bricks);
        }
        if (a.scene.mesh && level_asked > vst.level_fine)
            printf("                   (the view asked for level %u: too large for this device there)\n", level_asked);
        if (a.scene.map && a.scene.mesh) printf("  together         %u bricks\n", n_bricks);
        if (ps) {
            const render_particles_stats *st = render_particles_get_stats(ps);
            printf("  particles        %s: %llu, radius %.4g m, cell %.4g m (level %u): %llu cells, %u bricks "
                   "(+%u coarse)\n",
                   a.scene.particles, (unsigned long long)st->n_particles, a.scene.radius_m, st->cell_m, st->level,
                   (unsigned long long)st->n_cells, st->n_bricks, st->n_coarse_bricks);
            printf("  binning          %.1f ms on the host (%.2f M particles/s; %.1f ms CPU), %.1f ms into the GPU "
                   "pools (made in %.1f ms)\n",
                   1e3 * st->bin_s, st->bin_s > 0 ? 1e-6 * (double)st->n_particles / st->bin_s : 0.0,
                   1e3 * st->bin_cpu_s, 1e3 * st->load_s, 1e3 * st->make_s);
            printf("  GPU memory       %.1f MB in use, %.0f bytes a particle (%.1f MB allocated)\n",
                   1e-6 * (double)st->bytes_used, bytes_per_particle(st), 1e-6 * (double)st->bytes_reserved);
        }
        printf("  ray-cast         %.1f ms GPU (median of %u)\n", ms[a.repeat / 2], a.repeat);
        if (ps && map) printf("    of which particles %.1f ms\n", ms_p[a.repeat / 2]);
    }
    render_images_free(&im);
    free(ms);
    free(ms_p);
    render_destroy(caster);
    render_particles_destroy(ps);
    fusion_destroy(map);
    gpu_context_destroy(ctx);
    app_scene_files_free(&f);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
