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
static uint32_t mesh_level(const hostmap *snap)
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

bf_status app_export_map(fusion_map *map, const char *out_dir, bool with_mesh, app_map_report *r)
{
    char path[4096];
    hostmap snap;
    bf_status s = fusion_get_stats(map, &r->map);
    if (s == BF_OK) s = fusion_snapshot_take(map, &snap);
    if (s != BF_OK) return s;
    mesh_data mesh = {0}, pts = {0};
    if (with_mesh) {
        export_mesh_config mcfg = export_mesh_config_default();
        mcfg.max_level = mesh_level(&snap);
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

void app_json_map(FILE *f, const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    uint64_t voxels = (uint64_t)m->n_bricks * 512;
    fprintf(f, "  \"map_bytes\": {\"sign\": %llu, \"confidence\": %llu, \"brick_records\": %llu, "
               "\"nodes\": %llu, \"hash\": %llu, \"total\": %llu, \"reserved\": %llu},\n",
            (unsigned long long)m->bytes_sign, (unsigned long long)m->bytes_conf, (unsigned long long)m->bytes_info,
            (unsigned long long)m->bytes_nodes, (unsigned long long)m->bytes_hash, (unsigned long long)m->bytes_total,
            (unsigned long long)m->bytes_reserved);
    fprintf(f, "  \"chunks\": %u,\n  \"nodes\": %u,\n  \"bricks\": %u,\n  \"bricks_per_level\": [", m->n_chunks,
            m->n_nodes, m->n_bricks);
    for (uint32_t l = 0; l <= max_level && l < 16; l++) fprintf(f, "%s%u", l ? ", " : "", m->bricks_per_level[l]);
    fprintf(f, "],\n  \"allocated_voxels\": %llu,\n  \"confident_voxels\": %llu,\n  \"surface_voxels\": %llu,\n",
            (unsigned long long)voxels, (unsigned long long)m->n_confident_voxels,
            (unsigned long long)r->points.n_points);
    fprintf(f, "  \"bits_per_allocated_voxel\": ");
    bf_json_number(f, voxels ? 8.0 * (double)m->bytes_total / (double)voxels : NAN, 4);
    fprintf(f, ",\n  \"bits_per_surface_voxel\": ");
    bf_json_number(f, r->points.n_points ? 8.0 * (double)m->bytes_total / (double)r->points.n_points : NAN, 4);
    fprintf(f, ",\n  \"tsdf_4byte_bytes_same_voxels\": %llu,\n", (unsigned long long)(voxels * 4));
    fprintf(f, "  \"pool_full_drops\": {\"nodes\": %u, \"bricks\": %u, \"chunks\": %u},\n", m->fail_nodes,
            m->fail_bricks, m->fail_hash);
    fprintf(f, "  \"mesh\": {\"vertices\": %llu, \"triangles\": %llu, \"seconds\": %.3f},\n",
            (unsigned long long)r->mesh.n_vertices, (unsigned long long)r->mesh.n_triangles, r->mesh.seconds);
}

void app_print_map(const app_map_report *r, uint32_t max_level)
{
    const fusion_stats *m = &r->map;
    printf("  map              %u chunks, %u nodes, %u bricks, %.2f MiB (%.2f bits per allocated voxel)\n",
           m->n_chunks, m->n_nodes, m->n_bricks, m->bytes_total / 1048576.0,
           m->n_bricks ? 8.0 * m->bytes_total / (512.0 * m->n_bricks) : 0.0);
    printf("  bricks per level");
    for (uint32_t l = 0; l <= max_level && l < 16; l++)
        if (m->bricks_per_level[l]) printf("  L%u:%u", l, m->bricks_per_level[l]);
    printf("\n  surface          %llu voxels, mesh %llu triangles\n", (unsigned long long)r->points.n_points,
           (unsigned long long)r->mesh.n_triangles);
}

bf_status app_write_json(const char *dir, const char *name, void (*write)(FILE *f, const void *arg), const void *arg)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, name);
    if (s != BF_OK) return s;
    char *buf = NULL;
    size_t len = 0;
    FILE *mf = open_memstream(&buf, &len);
    if (!mf) return bf_fail(BF_NO_MEMORY, "%s: stats buffer", path);
    write(mf, arg);
    fclose(mf);
    s = bf_write_file_atomic(path, buf, len);
    free(buf);
    return s;
}

bool app_parse_map_option(const char *o, const char *v, fusion_config *fc)
{
    double d;
    uint32_t u;
    if (!v) return false;
    if (!strcmp(o, "--ratio") && bf_parse_double(v, &d)) fc->voxel_ratio = (float)d;
    else if (!strcmp(o, "--chunk") && bf_parse_double(v, &d)) fc->chunk_m = (float)d;
    else if (!strcmp(o, "--window") && bf_parse_u32(v, &u)) fc->window = u;
    else if (!strcmp(o, "--subcache") && bf_parse_u32(v, &u)) fc->subcache = u;
    else if (!strcmp(o, "--bricks") && bf_parse_u32(v, &u)) fc->brick_cap = u;
    else if (!strcmp(o, "--max-level") && bf_parse_u32(v, &u)) fc->max_level = u;
    else return false;
    return true;
}
