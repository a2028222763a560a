/* Outputs the commands that build a map share (fuse, replay, demo): the
 * mesh and point cloud of the map, the map's part of stats.json and of the
 * printed summary. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "mesh/mesh.h"

/* The mesh lattice level: the finest level that holds at least a tenth of
 * the bricks. A handful of bricks at a finer level (a sample that came very
 * close) must not put the whole room on their lattice, which would multiply
 * the triangles by 4 per level; their detail is averaged onto this one. */
uint32_t app_mesh_level(const hostmap *snap)
{
    uint32_t per_level[32] = {0};
    for (uint32_t i = 0; i < snap->n_bricks; i++) per_level[snap->bricks[i].level & 31]++;
    uint64_t at_or_above = 0;
    for (int l = 31; l >= 0; l--) {
        at_or_above += per_level[l];
        if (10 * at_or_above >= snap->n_bricks) return (uint32_t)l;
    }
    return 0;
}

bf_status app_export_map(fusion_map *map, hostmap *whole, const char *out_dir, bool with_mesh, app_map_report *r)
{
    char path[4096];
    hostmap snap = {0};
    bf_status s = fusion_get_stats(map, &r->map);
    if (s == BF_OK && whole) snap = *whole, memset(whole, 0, sizeof *whole);
    else if (s == BF_OK) s = fusion_snapshot_take(map, &snap);
    if (s != BF_OK) return s;
    mesh_data mesh = {0}, pts = {0};
    if (with_mesh) {
        export_mesh_config mcfg = export_mesh_config_default();
        mcfg.max_level = app_mesh_level(&snap);
        s = export_mesh(&snap, &mcfg, &mesh, &r->mesh);
        if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, "mesh.ply")) == BF_OK)
            s = mesh_write_ply(path, &mesh);
    }
    if (s == BF_OK) s = export_points(&snap, &pts, &r->points);
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, "points.ply")) == BF_OK)
        s = mesh_write_ply(path, &pts);
    mesh_free(&mesh);
    mesh_free(&pts);
    hostmap_free(&snap);
    return s;
}

void app_json_map(cJSON *o, const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    uint64_t voxels = (uint64_t)m->n_bricks * 512;
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
    cJSON_AddNumberToObject(c, "blocks", m->n_colour_blocks);
    cJSON_AddNumberToObject(c, "coloured_voxels", (double)m->n_coloured_voxels);
    cJSON_AddNumberToObject(c, "bits_per_allocated_voxel", voxels ? 8.0 * (double)m->bytes_colour / (double)voxels : NAN);
    cJSON_AddNumberToObject(c, "blocks_dropped_pool_full", m->fail_colour);
    cJSON_AddNumberToObject(o, "chunks", m->n_chunks);
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
    cJSON_AddNumberToObject(mesh, "vertices", (double)r->mesh.n_vertices);
    cJSON_AddNumberToObject(mesh, "triangles", (double)r->mesh.n_triangles);
    cJSON_AddNumberToObject(mesh, "seconds", r->mesh.seconds);
}

void app_print_map(const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    printf("  map              %u chunks, %u nodes, %u bricks, %.2f MiB (%.2f bits per allocated voxel)\n",
           m->n_chunks, m->n_nodes, m->n_bricks, m->bytes_total / 1048576.0,
           m->n_bricks ? 8.0 * m->bytes_total / (512.0 * m->n_bricks) : 0.0);
    if (m->bytes_colour)
        printf("  colour           %llu voxels, %u blocks, %.2f MiB (%.2f bits per allocated voxel)\n",
               (unsigned long long)m->n_coloured_voxels, m->n_colour_blocks, m->bytes_colour / 1048576.0,
               m->n_bricks ? 8.0 * m->bytes_colour / (512.0 * m->n_bricks) : 0.0);
    printf("  bricks per level");
    for (uint32_t l = 0; l <= max_level && l < 16; l++)
        if (m->bricks_per_level[l]) printf("  L%u:%u", l, m->bricks_per_level[l]);
    printf("\n  surface          %llu voxels, mesh %llu triangles\n", (unsigned long long)r->points.n_points,
           (unsigned long long)r->mesh.n_triangles);
}
