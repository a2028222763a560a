/* Outputs the commands that build a map share (fuse, replay, demo): the
 * mesh and point cloud of the map, the map's part of stats.json and of the
 * printed summary. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "mesh/mesh.h"
#include "recon/recon.h"
#include "replay/replay.h"

/* The mesh lattice level: the finest level that holds at least a tenth of
 * the bricks. A handful of bricks at a finer level (a sample that came very
 * close) must not put the whole room on their lattice, which would multiply
 * the triangles by 4 per level; their detail is averaged onto this one. */
uint32_t app_mesh_level(const hostmap *snap)
{
    uint32_t per_level[32] = {0};
    if (!snap->n_bricks) return 0; /* no brick: not level 31 */
    for (uint32_t i = 0; i < snap->n_bricks; i++) per_level[snap->bricks[i].level & 31]++;
    uint64_t at_or_above = 0;
    for (int l = 31; l >= 0; l--) {
        at_or_above += per_level[l];
        if (10 * at_or_above >= snap->n_bricks) return (uint32_t)l;
    }
    return 0;
}

void app_mesh_options(app_option rows[APP_MESH_ROWS], app_mesh_out *o, bool is_export)
{
    o->format = is_export ? -1 : MESH_FORMAT_PLY;
    o->max_triangles = 0;
    o->max_error_m = 0;
    const app_option format[2] = {
        APP_OPT("--mesh-format", APP_OPT_ENUM, &o->format, "ply|obj|glb",
                "the mesh file's format: DIR/mesh.ply, mesh.obj (+ mesh.mtl) or mesh.glb", .not_with = "--no-mesh"),
        APP_OPT("--format", APP_OPT_ENUM, &o->format, "ply|obj|glb",
                "the file's format: binary PLY, Wavefront OBJ (+ .mtl beside it) or glTF binary (default: from "
                "--out's extension)",
                .no_default = true),
    };
    const app_option r[APP_MESH_ROWS] = {
        format[is_export],
        APP_OPT("--max-triangles", APP_OPT_U32, &o->max_triangles, "N",
                "simplify the mesh to at most N triangles (meshoptimizer; default: the full mesh)", .min = 1,
                .no_default = true, .not_with = "--no-mesh"),
        APP_OPT("--max-error", APP_OPT_DOUBLE, &o->max_error_m, "M",
                "simplify the mesh as far as the surface moves at most M metres (with --max-triangles the cap "
                "still holds)",
                .min_open = true, .no_default = true, .not_with = "--no-mesh"),
        APP_OPT_END,
    };
    memcpy(rows, r, sizeof r);
}

bf_status app_mesh_write(const char *path, mesh_format f, const app_mesh_out *o, mesh_data *mesh,
                         mesh_simplify_stats *st)
{
    mesh_simplify_config sc = {.max_triangles = o->max_triangles, .max_error_m = o->max_error_m};
    bf_status s = mesh_simplify(mesh, &sc, st);
    return s == BF_OK ? mesh_write(path, f, mesh) : s;
}

void app_json_mesh_file(cJSON *o, const char *file, mesh_format f, const app_mesh_out *mo, const mesh_data *m,
                        const mesh_simplify_stats *st)
{
    cJSON_AddStringToObject(o, "format", mesh_format_name(f));
    cJSON_AddStringToObject(o, "file", file);
    cJSON_AddNumberToObject(o, "vertices", (double)m->n_verts);
    cJSON_AddNumberToObject(o, "triangles", (double)m->n_tris);
    cJSON_AddNumberToObject(o, "triangles_full", (double)st->tris_before);
    if (m->origin.x != 0 || m->origin.y != 0 || m->origin.z != 0) {
        double origin[3] = {m->origin.x, m->origin.y, m->origin.z};
        app_json_numbers(o, "origin_w", origin, 3);
    }
    if (mo->max_triangles || mo->max_error_m > 0) {
        cJSON *s = app_json_object(o, "simplify");
        /* The limit not given is null, as elsewhere in bitfuse's JSON. */
        if (mo->max_triangles) cJSON_AddNumberToObject(s, "max_triangles", mo->max_triangles);
        else cJSON_AddNullToObject(s, "max_triangles");
        if (mo->max_error_m > 0) cJSON_AddNumberToObject(s, "max_error_m", mo->max_error_m);
        else cJSON_AddNullToObject(s, "max_error_m");
        cJSON_AddNumberToObject(s, "error_estimate_m", st->error_m);
        cJSON_AddBoolToObject(s, "used_sloppy", st->used_sloppy);
        cJSON_AddNumberToObject(s, "seconds", st->seconds);
    }
}

bf_status app_export_map(fusion_map *map, hostmap *whole, const char *out_dir, const app_mesh_out *mo,
                         app_map_report *r)
{
    char path[4096];
    hostmap snap = {0};
    bf_status s = fusion_get_stats(map, &r->map);
    if (s == BF_OK && whole) snap = *whole, memset(whole, 0, sizeof *whole);
    else if (s == BF_OK) s = fusion_snapshot_take(map, &snap);
    /* The canonical order (slot numbers differ run to run): the same map
     * gives the same files and digest (docs/determinism.md). */
    if (s == BF_OK) s = hostmap_sort(&snap);
    if (s == BF_OK) s = store_map_digest(&snap, &r->digest);
    if (s == BF_OK) r->n_chunks = hostmap_count_chunks(&snap);
    r->n_bricks_whole = snap.n_bricks;
    if (s != BF_OK) {
        hostmap_free(&snap);
        return s;
    }
    mesh_data mesh = {0}, pts = {0};
    char mesh_error[BF_ERROR_CAP] = ""; /* a mesh that cannot be written: the points still are */
    if (mo) {
        r->mesh_out = *mo;
        snprintf(r->mesh_file, sizeof r->mesh_file, "mesh.%s", mesh_format_name((mesh_format)mo->format));
        export_mesh_config mcfg = export_mesh_config_default();
        mcfg.max_level = app_mesh_level(&snap);
        s = export_mesh(&snap, &mcfg, &mesh, &r->mesh);
        if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, r->mesh_file)) == BF_OK)
            s = app_mesh_write(path, (mesh_format)mo->format, mo, &mesh, &r->simplify);
        r->mesh_origin = mesh.origin;
        /* Simplified to nothing (a cap below what clustering keeps): the
         * points are still written, the caller notes it for the exit code. */
        if (s == BF_INVALID_ARG) {
            bf_warn("%s: no mesh written; the points are", bf_last_error());
            snprintf(r->mesh_error, sizeof r->mesh_error, "%s", bf_last_error());
            r->mesh_refused = s;
            r->mesh_file[0] = '\0';
            s = BF_OK;
        }
        if (s == BF_WRITE) {
            snprintf(mesh_error, sizeof mesh_error, "%s", bf_last_error());
            bf_warn("%s; going on with the other outputs", mesh_error);
            /* No file: stats.json says so, with the mesh's own size. */
            snprintf(r->mesh_error, sizeof r->mesh_error, "%s", mesh_error);
            r->mesh_file[0] = '\0';
            s = BF_OK;
        }
    } else {
        r->mesh_skipped = true;
    }
    if (s == BF_OK) s = export_points(&snap, &pts, &r->points);
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, "points.ply")) == BF_OK)
        s = mesh_write_ply(path, &pts);
    /* The first failure is the one named: the mesh's, when the points failed too. */
    if (s == BF_OK && mesh_error[0]) s = bf_fail(BF_WRITE, "%s", mesh_error);
    else if (s == BF_WRITE && mesh_error[0]) s = bf_fail(BF_WRITE, "%s; points.ply neither", mesh_error);
    mesh_free(&mesh);
    mesh_free(&pts);
    hostmap_free(&snap);
    return s;
}

void app_mesh_file_list(const app_map_report *r, char *out, size_t cap)
{
    if (!r->mesh_file[0]) {
        snprintf(out, cap, "%s", "");
        return;
    }
    bool obj = r->mesh_out.format == MESH_FORMAT_OBJ && r->simplify.tris_after > 0; /* no .mtl for no triangle */
    snprintf(out, cap, "%s,%s", r->mesh_file, obj ? "mesh.mtl," : "");
}

void app_json_map(cJSON *o, const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    uint64_t voxels = (uint64_t)m->n_bricks * 512;
    char digest[32];
    snprintf(digest, sizeof digest, "xxh3:%016llx", (unsigned long long)r->digest);
    cJSON_AddStringToObject(o, "map_digest", digest);
    cJSON *b = app_json_object(o, "map_bytes");
    cJSON_AddNumberToObject(b, "sign", (double)m->bytes_sign);
    cJSON_AddNumberToObject(b, "confidence", (double)m->bytes_conf);
    cJSON_AddNumberToObject(b, "brick_records", (double)m->bytes_info);
    cJSON_AddNumberToObject(b, "nodes", (double)m->bytes_nodes);
    cJSON_AddNumberToObject(b, "hash", (double)m->bytes_hash);
    cJSON_AddNumberToObject(b, "total", (double)m->bytes_total);
    cJSON_AddNumberToObject(b, "reserved", (double)m->bytes_reserved);
    cJSON *c = app_json_object(o, "colour");
    cJSON_AddNumberToObject(c, "bytes", (double)m->bytes_colour);
    cJSON_AddNumberToObject(c, "units", m->n_colour_units);
    cJSON_AddNumberToObject(c, "coloured_voxels", (double)m->n_coloured_voxels);
    cJSON_AddNumberToObject(c, "bits_per_allocated_voxel", voxels ? 8.0 * (double)m->bytes_colour / (double)voxels : NAN);
    cJSON_AddNumberToObject(c, "pool_full_events", m->fail_colour);
    cJSON_AddNumberToObject(o, "chunks", m->n_chunks);
    cJSON_AddNumberToObject(o, "chunks_with_bricks", r->n_chunks);
    cJSON_AddNumberToObject(o, "bricks_in_map", r->n_bricks_whole);
    cJSON_AddNumberToObject(o, "nodes", m->n_nodes);
    cJSON_AddNumberToObject(o, "bricks", m->n_bricks);
    cJSON *per_level = cJSON_AddArrayToObject(o, "bricks_per_level");
    for (uint32_t l = 0; l <= max_level && l < 16; l++)
        cJSON_AddItemToArray(per_level, cJSON_CreateNumber(m->bricks_per_level[l]));
    cJSON_AddNumberToObject(o, "allocated_voxels", (double)voxels);
    cJSON_AddNumberToObject(o, "confident_voxels", (double)m->n_confident_voxels);
    cJSON_AddNumberToObject(o, "surface_voxels", (double)r->points.n_points);
    cJSON_AddNumberToObject(o, "bits_per_allocated_voxel",
                            voxels ? 8.0 * (double)m->bytes_total / (double)voxels : NAN);
    cJSON_AddNumberToObject(o, "bits_per_surface_voxel",
                            r->points.n_points ? 8.0 * (double)m->bytes_total / (double)r->points.n_points : NAN);
    cJSON_AddNumberToObject(o, "tsdf_4byte_bytes_same_voxels", (double)(voxels * 4));
    cJSON *drops = app_json_object(o, "pool_full_drops");
    cJSON_AddNumberToObject(drops, "nodes", m->fail_nodes);
    cJSON_AddNumberToObject(drops, "bricks", m->fail_bricks);
    cJSON_AddNumberToObject(drops, "chunks", m->fail_hash);
    cJSON *mesh = app_json_object(o, "mesh");
    if (r->mesh_file[0]) {
        /* What the file holds; the marching-cubes mesh's own size beside. */
        mesh_data shape = {.n_verts = (uint32_t)r->simplify.verts_after, .n_tris = (uint32_t)r->simplify.tris_after,
                           .origin = r->mesh_origin};
        app_json_mesh_file(mesh, r->mesh_file, (mesh_format)r->mesh_out.format, &r->mesh_out, &shape, &r->simplify);
    } else {
        /* No file: skipped (--no-mesh), or made and not written. */
        cJSON_AddNullToObject(mesh, "file");
        if (r->mesh_skipped) cJSON_AddTrueToObject(mesh, "skipped");
        if (r->mesh_error[0]) cJSON_AddStringToObject(mesh, "error", r->mesh_error);
        cJSON_AddNumberToObject(mesh, "vertices", (double)r->mesh.n_vertices);
        cJSON_AddNumberToObject(mesh, "triangles", (double)r->mesh.n_triangles);
    }
    cJSON_AddNumberToObject(mesh, "seconds", r->mesh.seconds);
}

/* The map's line when the device holds the whole map. */
static void app_print_map_line(const app_map_report *r, double bits)
{
    const fusion_stats *m = &r->map;
    /* A chunk emptied of its bricks keeps its hash entry (and its memory):
     * a store and `info` count the map's chunks holding bricks, so say both
     * where they differ. */
    char chunks[96];
    if (r->n_chunks != m->n_chunks)
        snprintf(chunks, sizeof chunks, "%u chunks on the device, %u holding bricks in the map", m->n_chunks,
                 r->n_chunks);
    else
        snprintf(chunks, sizeof chunks, "%u chunks", m->n_chunks);
    printf("  map              %s, %u nodes, %u bricks, %.2f MiB (%.2f bits per allocated voxel)\n",
           chunks, m->n_nodes, m->n_bricks, m->bytes_total / 1048576.0, bits);
}

void app_print_map(const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    double bits = m->n_bricks ? 8.0 * m->bytes_total / (512.0 * m->n_bricks) : 0.0;
    if (r->n_bricks_whole != m->n_bricks) {
        /* Streamed: the map (the store's, the export's) and what the device holds of it. */
        printf("  map              %u chunk%s, %u brick%s (the whole map, the chunks streamed out included)\n",
               r->n_chunks, app_s(r->n_chunks), r->n_bricks_whole, app_s(r->n_bricks_whole));
        printf("  on the device    %u chunk%s, %u nodes, %u bricks, %.2f MiB (%.2f bits per allocated voxel)\n",
               m->n_chunks, app_s(m->n_chunks), m->n_nodes, m->n_bricks, m->bytes_total / 1048576.0, bits);
    } else {
        app_print_map_line(r, bits);
    }
    if (m->bytes_colour)
        printf("  colour           %llu voxels, %u units, %.2f MiB (%.2f bits per allocated voxel)\n",
               (unsigned long long)m->n_coloured_voxels, m->n_colour_units, m->bytes_colour / 1048576.0,
               m->n_bricks ? 8.0 * m->bytes_colour / (512.0 * m->n_bricks) : 0.0);
    /* A full pool drops what did not fit and the scan goes on (fusion_finish_frame): the per-frame
     * warnings scroll by, so the summary says what the map lacks. */
    if (m->fail_nodes || m->fail_bricks || m->fail_hash)
        printf("  pools full       requests for %u bricks, %u nodes and %u chunks were dropped: the map lacks\n"
               "                   what they would have added (larger pools: --bricks, or replay's and live's\n"
               "                   --gpu-budget)\n",
               m->fail_bricks, m->fail_nodes, m->fail_hash);
    if (m->fail_colour)
        printf("  colour pool full %u times: those bricks' new colours were not kept\n", m->fail_colour);
    printf("  bricks per level");
    for (uint32_t l = 0; l <= max_level && l < 16; l++)
        if (m->bricks_per_level[l]) printf("  L%u:%u", l, m->bricks_per_level[l]);
    if (r->mesh_skipped)
        printf("\n  surface          %llu voxels, mesh skipped (--no-mesh)", (unsigned long long)r->points.n_points);
    else
        printf("\n  surface          %llu voxels, mesh %llu triangles%s", (unsigned long long)r->points.n_points,
               (unsigned long long)r->mesh.n_triangles, r->mesh_error[0] ? " (not written)" : "");
    if (r->mesh_file[0] && r->simplify.tris_after != r->simplify.tris_before)
        printf(", %s simplified to %llu (meshoptimizer's error estimate %.2f mm)", r->mesh_file,
               (unsigned long long)r->simplify.tris_after, 1e3 * r->simplify.error_m);
    printf("\n");
}

bf_status app_note_write(app_write_failure *w, const char *cmd, bf_status s)
{
    if (s != BF_WRITE) return s;
    if (w->s != BF_OK && !strcmp(w->message, bf_last_error())) return BF_OK; /* the same one again (a sticky writer) */
    bf_warn("%s: %s; the other outputs are still written", cmd, bf_last_error());
    w->n++;
    if (w->s == BF_OK) {
        w->s = s;
        snprintf(w->message, sizeof w->message, "%s", bf_last_error());
    }
    return BF_OK;
}

void app_warn_earlier_run(const char *cmd, const char *out)
{
    char path[4200];
    if (bf_path_join(path, sizeof path, out, "stats.json") == BF_OK && bf_file_exists(path))
        bf_warn("%s: --out %s holds an earlier run's outputs: the files this run does not write (another mesh "
                "format, more views) stay beside its own", cmd, out);
}

int app_check_out_not_sequence(const char *cmd, const char *out, bool results_too)
{
    static const char *const held[] = {"depth.txt", "rgb.txt", "groundtruth.txt", "depth", "rgb"};
    char p[4200];
    for (size_t i = 0; i < sizeof held / sizeof *held; i++)
        if (bf_path_join(p, sizeof p, out, held[i]) == BF_OK && bf_file_exists(p))
            return app_usage_error(cmd, "--out %s holds a sequence already (%s): give a new folder, or remove it first",
                                   out, held[i]);
    if (results_too && bf_path_join(p, sizeof p, out, "stats.json") == BF_OK && bf_file_exists(p))
        return app_usage_error(cmd, "--out %s holds an earlier run's outputs (stats.json), which a sequence written "
                               "there would replace: give a new folder, or remove it first", out);
    return 0;
}

void app_note_mesh_refused(app_write_failure *w, const app_map_report *r)
{
    if (r->mesh_refused == BF_OK) return;
    w->n++; /* an output not written, as a failed one */
    if (w->s != BF_OK) return;
    w->s = r->mesh_refused;
    snprintf(w->message, sizeof w->message, "%s", r->mesh_error);
}

bf_status app_write_status(const app_write_failure *w)
{
    return w->s == BF_OK ? BF_OK : bf_fail(w->s, "%s", w->message);
}

void app_json_gpu_stages(cJSON *o, const recon_run *run, bool with_tracking)
{
    const recon_run_series *t = &run->series;
    cJSON *g = app_json_object(o, "gpu_stage_ms");
    if (with_tracking) {
        app_json_series(g, "track", &t->track_ms);
        app_json_series(g, "rof", &t->rof_ms);
        app_json_series(g, "raycast", &t->raycast_ms);
    }
    app_json_series(g, "upload", &t->upload_ms);
    app_json_series(g, "alloc", &t->alloc_ms);
    app_json_series(g, "subcache", &t->subcache_ms);
    app_json_series(g, "window", &t->window_ms);
    app_json_series(g, "colour", &t->colour_ms);
}

void app_json_input(cJSON *o, const recon_run *run, const rgbd_source *src)
{
    /* The camera the frames were read with, and the lens taken out of them. */
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    cJSON *cam = app_json_object(o, "camera");
    cJSON_AddNumberToObject(cam, "width", K->width);
    cJSON_AddNumberToObject(cam, "height", K->height);
    cJSON_AddNumberToObject(cam, "fx", K->fx_px);
    cJSON_AddNumberToObject(cam, "fy", K->fy_px);
    cJSON_AddNumberToObject(cam, "cx", K->cx_px);
    cJSON_AddNumberToObject(cam, "cy", K->cy_px);
    cJSON_AddNumberToObject(cam, "depth_scale", K->depth_scale);
    double dist[CALIB_DIST_N], shift = 0;
    if (app_undistortion(src, dist, &shift)) {
        app_json_numbers(cam, "undistorted", dist, CALIB_DIST_N);
        cJSON_AddNumberToObject(cam, "undistort_max_shift_px", shift);
    } else if (run->has_depth_lens) { /* a calibration's depth lens, taken out by the runner */
        app_json_numbers(cam, "undistorted", run->depth_lens_dist, CALIB_DIST_N);
        cJSON_AddNumberToObject(cam, "undistort_max_shift_px", run->depth_lens_shift_px);
    } else {
        cJSON_AddNullToObject(cam, "undistorted");
        cJSON_AddNullToObject(cam, "undistort_max_shift_px");
    }
    cJSON_AddNumberToObject(o, "frames_unreadable", app_skipped_frames(src));
    if (run->source_status != BF_OK) cJSON_AddStringToObject(o, "input_error", run->source_error);
    else cJSON_AddNullToObject(o, "input_error");
}

bf_status app_input_status(bf_status s, const rgbd_source *src, const char *name)
{
    uint32_t skipped = src ? app_skipped_frames(src) : 0;
    if (s != BF_FORMAT || skipped == 0 || skipped < src->n_frames) return s;
    return bf_fail(BF_FORMAT, "%s: no frame could be read (%u skipped)", name, skipped);
}
