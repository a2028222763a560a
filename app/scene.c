/* What bitfuse render and bitfuse view draw: a saved map (a scene store),
 * a mesh voxelised into its bricks, particles; read from files and loaded
 * into the GPU the same way for both. */
#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "app.h"
#include "render/render.h"
#include "shaders/fusion.glsl.h"

/* ------------------------------------------------------------ options render and view share */

void app_scene_options(app_option rows[APP_SCENE_ROWS], app_scene_args *a, const char *mesh_help,
                       const char *mesh_lod_help)
{
    *a = (app_scene_args){.radius_m = 0.01, .near_m = 0.2, .far_m = 13.1, .particle_lod = true, .mesh_lod = true};
    const app_option r[APP_SCENE_ROWS] = {
        APP_OPT("--map", APP_OPT_STRING, &a->map, "STORE",
                "the map: a scene store, or a folder holding one as DIR/store"),
        APP_OPT("--particles", APP_OPT_STRING, &a->particles, "FILE", "particles: a PLY with vertex x y z [m]"),
        APP_OPT("--particle-radius", APP_OPT_DOUBLE, &a->radius_m, "M", "every particle's sphere radius [m]",
                .min = 0, .min_open = true, .max = 10, .needs = "--particles"),
        APP_OPT("--particle-cell", APP_OPT_DOUBLE, &a->cell_m, "M",
                "the particles' grid cell [m] (default: an eighth of the radius, a quarter for sets too large for "
                "that; at most 2 radii)",
                .min = 1e-5, .max = 20, .no_default = true, .needs = "--particles"),
        APP_OPT("--particle-lod", APP_OPT_CHOICE, &a->particle_lod, "on|off",
                "level of detail: where a pixel spans twice a coarse cell's half-diagonal (8 x 8 x 8 cells), each "
                "coarse cell holding particles is drawn as one sphere at its centre (off: every sphere where its "
                "cell puts it)",
                .needs = "--particles"),
        APP_OPT("--mesh", APP_OPT_STRING, &a->mesh, "FILE", mesh_help),
        APP_OPT("--mesh-pose", APP_OPT_STRING, &a->mesh_pose, "\"tx ty tz qx qy qz qw\"",
                "the mesh's pose: mesh to world (default: identity)", .check = app_check_pose),
        APP_OPT("--mesh-lod", APP_OPT_CHOICE, &a->mesh_lod, "on|off", mesh_lod_help, .needs = "--mesh"),
        APP_OPT("--near", APP_OPT_DOUBLE, &a->near_m, "M", "nearest depth a ray looks [m] (a map from a depth camera "
                "holds nothing nearer; a mesh or particles seen from closer need less)", .min = 0.01, .max = 100),
        APP_OPT("--far", APP_OPT_DOUBLE, &a->far_m, "M", "farthest depth a ray looks [m]", .min = 0.3, .max = 1000,
                .given = &a->far_given),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

int app_scene_check(const char *cmd, const char *verb, const app_scene_args *a)
{
    if (a->mesh_pose && !a->mesh) return app_usage_error(cmd, "--mesh-pose without --mesh");
    if (!(a->near_m < a->far_m)) return app_usage_error(cmd, "--near %g is not nearer than --far %g", a->near_m, a->far_m);
    if (!a->map && !a->particles && !a->mesh)
        return app_usage_error(cmd, "nothing to %s: give --map, --mesh, --particles or any of them", verb);
    /* The radius and cell as the particle set takes them (a cell of at most
     * 2 radii, chunks of at most 64 m), before any file is read or device opened. */
    if (a->particles) {
        render_particles_config pc = render_particles_config_default();
        pc.radius_m = (float)a->radius_m;
        pc.cell_m = (float)a->cell_m;
        if (render_particles_check_config(&pc) != BF_OK)
            return app_usage_error(cmd, "--particle-radius %g / --particle-cell: %s", a->radius_m, bf_last_error());
    }
    return 0;
}

bf_status app_scene_read_files(const app_scene_args *a, app_scene_files *f)
{
    char msg[512];
    f->T_wm = bf_se3_identity();
    if (a->mesh_pose) app_parse_pose(a->mesh_pose, &f->T_wm, msg, sizeof msg); /* checked when parsed */
    bf_status s = BF_OK;
    if (a->map && !bf_file_exists(a->map)) s = bf_fail(BF_IO, "%s: no such map (store or folder)", a->map);
    if (s == BF_OK && a->particles) s = app_scene_read_particles(a->particles, &f->xyz, &f->n_particles);
    /* A simulation's dump may hold none yet (an emitter not started): drawn as nothing, but said. */
    if (s == BF_OK && a->particles && f->n_particles == 0)
        bf_warn("%s: no particles (the PLY has no vertex): nothing of them is drawn", a->particles);
    if (s == BF_OK && a->mesh) s = mesh_read(a->mesh, &f->mesh);
    if (s == BF_OK && a->mesh && f->mesh.n_tris == 0) s = bf_fail(BF_FORMAT, "%s: the mesh has no triangle", a->mesh);
    uint64_t open = 0;
    if (s == BF_OK && a->mesh) s = mesh_open_edges(&f->mesh, &open);
    if (s == BF_OK && open)
        bf_warn("%s: the mesh may not be closed (%llu edges that an odd number of triangles share: holes' rims, or "
                "T-junctions): the voxeliser tells inside from outside by crossings, so parts of it may be missing or "
                "filled in (docs/render.md)",
                a->mesh, (unsigned long long)open);
    return s;
}

void app_scene_files_free(app_scene_files *f)
{
    free(f->xyz);
    mesh_free(&f->mesh);
    memset(f, 0, sizeof *f);
}

bf_status app_scene_make_particles(gpu_context *ctx, const app_scene_args *a, const app_scene_files *f,
                                   render_particles **out)
{
    render_particles_config pc = render_particles_config_default();
    pc.radius_m = (float)a->radius_m;
    pc.cell_m = (float)a->cell_m;
    pc.lod = a->particle_lod;
    bf_status s = render_particles_create(ctx, &pc, f->xyz, f->n_particles, out);
    if (s == BF_INVALID_ARG) {
        char msg[512];
        snprintf(msg, sizeof msg, "%s", bf_last_error());
        s = bf_fail(BF_FORMAT, "%s: %s", a->particles, msg);
    }
    return s;
}

/* "tx ty tz qx qy qz qw" -> T_wc; false with the reason in msg. */
bool app_parse_pose(const char *v, bf_se3 *T, char *msg, size_t n)
{
    double a[7];
    int used = 0;
    if (sscanf(v, "%lf %lf %lf %lf %lf %lf %lf %n", &a[0], &a[1], &a[2], &a[3], &a[4], &a[5], &a[6], &used) != 7 ||
        v[used] != '\0') {
        snprintf(msg, n, "\"%s\": expected 7 numbers \"tx ty tz qx qy qz qw\"", v);
        return false;
    }
    for (int i = 0; i < 7; i++)
        if (!isfinite(a[i])) {
            snprintf(msg, n, "\"%s\": not finite", v);
            return false;
        }
    double qn = sqrt(a[3] * a[3] + a[4] * a[4] + a[5] * a[5] + a[6] * a[6]);
    if (fabs(qn - 1) > 1e-3) {
        snprintf(msg, n, "\"%s\": the quaternion's norm is %g, not 1", v, qn);
        return false;
    }
    bf_quat q = bf_quat_normalize((bf_quat){.w = a[6], .x = a[3], .y = a[4], .z = a[5]});
    *T = bf_se3_from_qt(q, bf_v3(a[0], a[1], a[2]));
    return true;
}

const char *app_check_pose(const char *name, const char *v)
{
    static char msg[640];
    char why[512];
    bf_se3 T;
    if (app_parse_pose(v, &T, why, sizeof why)) return NULL;
    snprintf(msg, sizeof msg, "%s %s", name, why); /* --pose or --mesh-pose, whichever it was */
    return msg;
}

/* "WxH" within 2..8192 each. */
bool app_parse_size(const char *v, uint32_t *w, uint32_t *h)
{
    unsigned a, b;
    int used = 0;
    /* 2 at least: a 1x1 view reached the ray-cast's own check ("fusion: bad
     * intrinsics"); digits and one x only (sscanf skips blanks and signs). */
    size_t nd = strspn(v, "0123456789");
    if (!nd || v[nd] != 'x' || !isdigit((unsigned char)v[nd + 1]) || strspn(v + nd + 1, "0123456789") != strlen(v + nd + 1) ||
        sscanf(v, "%ux%u%n", &a, &b, &used) != 2 || v[used] != '\0' || a < 2 ||
        b < 2 || a > 8192 || b > 8192)
        return false;
    *w = a, *h = b;
    return true;
}

const char *app_check_size(const char *name, const char *v)
{
    static char msg[256];
    uint32_t w, h;
    if (app_parse_size(v, &w, &h)) return NULL;
    snprintf(msg, sizeof msg, "%s \"%s\": expected WxH, each 2..8192", name, v);
    return msg;
}

/* "fx,fy,cx,cy" with positive focal lengths. */
bool app_parse_camera(const char *v, double k[4])
{
    int used = 0;
    if (sscanf(v, "%lf,%lf,%lf,%lf%n", &k[0], &k[1], &k[2], &k[3], &used) != 4 || v[used] != '\0') return false;
    return k[0] > 0 && k[1] > 0 && isfinite(k[0]) && isfinite(k[1]) && isfinite(k[2]) && isfinite(k[3]);
}

const char *app_check_camera(const char *name, const char *v)
{
    static char msg[256];
    double k[4];
    if (app_parse_camera(v, k)) return NULL;
    snprintf(msg, sizeof msg, "%s \"%s\": expected fx,fy,cx,cy in pixels (focal lengths above 0)", name, v);
    return msg;
}

const char *app_check_png(const char *name, const char *v)
{
    static char msg[256];
    size_t n = strlen(v);
    if (n > 4 && strcasecmp(v + n - 4, ".png") == 0) return NULL;
    snprintf(msg, sizeof msg, "%s %s: the image is written as PNG (a name ending .png)", name, v);
    return msg;
}

/* ------------------------------------------------------------ the scene */

static int key_cmp(const void *x, const void *y)
{
    return memcmp(x, y, 3 * sizeof(int32_t)) < 0 ? -1 : memcmp(x, y, 3 * sizeof(int32_t)) > 0;
}

/* Chunks a host map touches (for the hash's size); at most its bricks. */
static uint32_t count_chunks(const hostmap *m)
{
    int32_t (*k)[3] = malloc(((size_t)m->n_bricks + 1) * sizeof *k);
    if (!k) return m->n_bricks;
    for (uint32_t i = 0; i < m->n_bricks; i++) memcpy(k[i], m->bricks[i].key, sizeof k[i]);
    qsort(k, m->n_bricks, sizeof *k, key_cmp);
    uint32_t n = 0;
    for (uint32_t i = 0; i < m->n_bricks; i++) n += i == 0 || memcmp(k[i], k[i - 1], sizeof k[i]) != 0;
    free(k);
    return n;
}

const char *app_store_dir(const char *path, char *buf, size_t cap)
{
    if (store_exists(path)) return path;
    if (snprintf(buf, cap, "%s/store", path) < (int)cap && store_exists(buf)) return buf;
    return NULL;
}

/* The map of a store (or DIR/store) on the host. */
bf_status app_scene_read_map(const char *path, hostmap *m, store_meta *meta_out, store_report *rep_out)
{
    char sub[4096];
    const char *dir = app_store_dir(path, sub, sizeof sub);
    if (!dir)
        return bf_fail(BF_FORMAT, "%s: not a scene store (bitfuse replay|live --store), nor a folder holding one "
                                  "as store/", path);
    memset(m, 0, sizeof *m);
    store_meta meta;
    store_report rep;
    bf_status s = store_read(dir, m, &meta, NULL, &rep);
    if (s == BF_UNSUPPORTED) s = BF_FORMAT; /* a newer store: unreadable here (exit 3) */
    if (s == BF_OK && meta_out) *meta_out = meta;
    if (s == BF_OK && rep_out) *rep_out = rep;
    if (s == BF_OK && rep.n_bad)
        bf_warn("%s: %u chunk file%s left out, the first: %s", dir, rep.n_bad, app_s(rep.n_bad), rep.first_bad);
    if (s == BF_OK && rep.n_missing)
        bf_warn("%s: %u chunk%s the index lists %s not loaded (a file missing or bad): left out", dir,
                rep.n_missing, app_s(rep.n_missing), rep.n_missing == 1 ? "was" : "were");
    if (s == BF_OK && m->n_bricks == 0) s = bf_fail(BF_FORMAT, "%s: the store holds no brick", dir);
    if (s != BF_OK) hostmap_free(m);
    return s;
}

/* A host map (a store's, a voxelised mesh's, or both merged) into a GPU map
 * of its own size. */
bf_status app_scene_load_map(gpu_context *ctx, const hostmap *m, const bf_intrinsics *K, fusion_map **out)
{
    uint32_t n_chunks = count_chunks(m);
    bf_status s = BF_OK;
    fusion_config fc = fusion_config_default();
    fc.chunk_m = m->chunk_m;
    fc.brick_cap = m->n_bricks + 1;
    fc.window = 2;
    fc.subcache = 1;
    fc.keep_colour = m->rgb565 != NULL;
    fc.load_only = true; /* drawn, never fused into */
    /* Colour units: each brick's coloured voxels in units of 14 (fusion.glsl.h). */
    uint64_t units = 1;
    for (uint32_t i = 0; m->rgb565 && i < m->n_bricks; i++) {
        uint32_t n = 0;
        for (uint32_t v = 0; v < 512; v++) n += m->rgb565[(size_t)i * 512 + v] != 0;
        units += (n + FUSION_COLOUR_UNIT_COLOURS - 1) / FUSION_COLOUR_UNIT_COLOURS;
    }
    fc.colour_unit_cap = (uint32_t)(units < UINT32_MAX ? units : UINT32_MAX);
    fc.hash_buckets = 64;
    while (fc.hash_buckets < n_chunks * 2) fc.hash_buckets *= 2;
    fc.hash_overflow = fc.hash_buckets;
    fusion_map *map = NULL;
    /* A fused map needs about 3 nodes a brick (DESIGN.md section 3); a sparse
     * one more: grow and retry when the node pool is short. */
    for (uint32_t per = 3; s == BF_OK && per <= 48; per *= 4) {
        fc.node_cap = per * fc.brick_cap + 64;
        s = fusion_create(ctx, &fc, K, m->origin_w, &map);
        if (s == BF_OK) s = fusion_load(map, m);
        if (s == BF_POOL_FULL && per < 48) {
            fusion_destroy(map);
            map = NULL;
            s = BF_OK;
            continue;
        }
        break;
    }
    if (s != BF_OK) {
        fusion_destroy(map);
        return s;
    }
    *out = map;
    return BF_OK;
}

/* The level for the mesh: a third of the pixel footprint at its nearest
 * vertex in front of the camera (render_level_for_footprint). */
static uint32_t mesh_level(const mesh_data *mesh, const bf_se3 *T_wm, const bf_se3 *T_wc, const bf_intrinsics *K,
                           float chunk_m, uint32_t max_level, double near_m)
{
    bf_se3 T_cw = bf_se3_inverse(T_wc);
    double z_min = INFINITY;
    for (uint32_t i = 0; i < mesh->n_verts; i++) {
        bf_vec3 p = bf_v3(mesh->origin.x + mesh->xyz[3 * i], mesh->origin.y + mesh->xyz[3 * i + 1],
                          mesh->origin.z + mesh->xyz[3 * i + 2]);
        bf_vec3 c = bf_se3_apply(&T_cw, bf_se3_apply(T_wm, p));
        double z = c.z > near_m ? c.z : near_m; /* nearer than the rays start: seen no closer than there */
        if (c.z > 0 && z < z_min) z_min = z;
    }
    if (!isfinite(z_min)) z_min = 1.0; /* all behind the camera: any level shows nothing */
    return render_level_for_footprint(chunk_m, z_min, K->fx_px > K->fy_px ? K->fx_px : K->fy_px, max_level);
}

/* How to voxelise a mesh seen by camera T_wc (K), on the grid of map m
 * (NULL: its own): with lod, each column at the level its pixel footprint
 * needs, no finer than fusion's finest; without, all of it at the level
 * whose voxel is a third of the footprint at its nearest vertex in front
 * of the camera. Depths nearer than near_m (the rays' near plane) count as
 * near_m: no ray sees them. */
static render_voxelise_config mesh_config(const mesh_data *mesh, const bf_se3 *T_wm, const bf_se3 *T_wc,
                                          const bf_intrinsics *K, const hostmap *m, bool lod, float near_m)
{
    render_voxelise_config vc = render_voxelise_config_default();
    if (m) vc.chunk_m = m->chunk_m, vc.has_origin = true, vc.origin_w = m->origin_w;
    uint32_t finest = fusion_config_default().max_level;
    if (lod)
        vc.lod = true, vc.lod_T_wc = *T_wc, vc.lod_K = *K, vc.lod_near_m = near_m, vc.level = finest;
    else
        vc.level = mesh_level(mesh, T_wm, T_wc, K, vc.chunk_m, finest, near_m);
    return vc;
}

bf_status app_scene_add_mesh(gpu_context *ctx, const app_scene_args *a, const app_scene_files *f, const bf_se3 *T_wc,
                             const bf_intrinsics *K, bool lod, hostmap *hm, render_voxelise_stats *vst,
                             uint32_t *level_asked)
{
    /* On the map's grid when there is one, so both are one ray-cast. */
    render_voxelise_config vc = mesh_config(&f->mesh, &f->T_wm, T_wc, K, a->map ? hm : NULL, lod, (float)a->near_m);
    /* The map it is drawn from holds its bricks and the store's in one
     * sign pool (a binding of the device). */
    uint64_t pool = gpu_device_limits(ctx)->max_storage_buffer_range / (BRICK_WORDS * 4);
    uint64_t held = (a->map ? hm->n_bricks : 0) + 1;
    if (pool <= held)
        return bf_fail(BF_FORMAT, "%s: the map %s fills the device's largest binding (%llu bricks): no room for the "
                       "mesh's bricks", a->mesh, a->map, (unsigned long long)pool);
    vc.max_bricks = (uint32_t)(pool - held < vc.max_bricks ? pool - held : vc.max_bricks);
    render_voxelise_stats own = {0};
    if (!vst) vst = &own;
    hostmap mh;
    bf_status s = render_voxelise_mesh(ctx, &f->mesh, &f->T_wm, &vc, &mh, vst);
    /* A mesh too large for the device at the levels the view asks (a mesh
     * in millimetres read as metres, a camera inside a building): drawn
     * coarser, a level below the finest tried at a time, and said so. */
    uint32_t asked = vst->level_fine;
    if (level_asked) *level_asked = asked;
    while (s == BF_POOL_FULL && vst->level_fine > 0) {
        vc.level = vst->level_fine - 1;
        s = render_voxelise_mesh(ctx, &f->mesh, &f->T_wm, &vc, &mh, vst);
    }
    if (s == BF_OK && vst->level_fine < asked)
        bf_warn("%s: too large for this device at level %u (%.2f mm voxels): drawn no finer than level %u (%.2f mm); "
                "is it in metres?",
                a->mesh, asked, 1e3 * hostmap_level_voxel_m(vc.chunk_m, asked), vst->level_fine,
                1e3 * hostmap_level_voxel_m(vc.chunk_m, vst->level_fine));
    if (s == BF_POOL_FULL)
        return bf_fail(BF_FORMAT, "%s: too large for this device even at level 0 (%.0f mm voxels; %s): is it in "
                       "metres, and are its triangles as many as it needs?",
                       a->mesh, 1e3 * hostmap_level_voxel_m(vc.chunk_m, 0), bf_last_error());
    if (s == BF_INVALID_ARG) {
        /* What the mesh asks that the grid cannot hold is the file's fault. */
        char msg[512];
        snprintf(msg, sizeof msg, "%s", bf_last_error());
        return bf_fail(BF_FORMAT, "%s: %s", a->mesh, msg);
    }
    if (s != BF_OK) return s;
    if (!a->map) {
        *hm = mh;
        return BF_OK;
    }
    s = render_hostmap_merge(hm, &mh);
    hostmap_free(&mh); /* emptied when merged; left whole when not */
    return s;
}

/* The particles of a PLY (vertex x y z) into world floats. */
bf_status app_scene_read_particles(const char *path, float **xyz, uint32_t *n)
{
    mesh_data md = {0};
    bf_status s = mesh_read_ply(path, &md);
    if (s != BF_OK) return s;
    float *p = malloc((size_t)(md.n_verts ? md.n_verts : 1) * 12);
    if (!p) {
        mesh_free(&md);
        return bf_fail(BF_NO_MEMORY, "%s: %u particles", path, md.n_verts);
    }
    double o[3] = {md.origin.x, md.origin.y, md.origin.z};
    for (size_t i = 0; i < 3 * (size_t)md.n_verts; i++) p[i] = (float)(o[i % 3] + md.xyz[i]);
    *xyz = p;
    *n = md.n_verts;
    mesh_free(&md);
    return BF_OK;
}

