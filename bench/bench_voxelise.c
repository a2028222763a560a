/* The mesh renderer's voxelisation rate (render_voxelise_mesh) against
 * triangle count and level, and the ray-cast of the result at 640x480.
 * Meshes: a shared mesh (default the bunny, scaled to 25 cm) split into
 * four triangles per triangle `--subdivide` times (10^5..10^7 triangles).
 *   bench_voxelise [--mesh PLY] [--size M] [--levels 7,8] [--subdivide 0,1,2,3] [--widths 320,640,1280]
 * Prints one row per (triangles, level): bricks, pairs, binning seconds,
 * GPU seconds, total, triangles per second, the map's bytes (sign,
 * confidence, records, nodes, hash) and per triangle, and the ray-cast's GPU
 * time at each image width (4:3, the mesh filling about half the height). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "render/render.h"

/* Each triangle into four by its edge midpoints (vertices shared only
 * within a triangle: the mesh stays closed as a surface, and the
 * voxeliser reads positions, not connectivity). */
static bf_status subdivide(const mesh_data *in, mesh_data *out)
{
    memset(out, 0, sizeof *out);
    out->n_verts = in->n_tris * 6, out->n_tris = in->n_tris * 4;
    out->origin = in->origin;
    out->xyz = malloc((size_t)out->n_verts * 12);
    out->tri = malloc((size_t)out->n_tris * 12);
    if (!out->xyz || !out->tri) return bf_fail(BF_NO_MEMORY, "bench: subdividing %u triangles", in->n_tris);
    for (uint32_t t = 0; t < in->n_tris; t++) {
        float p[6][3];
        for (int k = 0; k < 3; k++) memcpy(p[k], in->xyz + 3 * (size_t)in->tri[3 * (size_t)t + k], 12);
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++) p[3 + k][a] = 0.5f * (p[k][a] + p[(k + 1) % 3][a]);
        memcpy(out->xyz + 18 * (size_t)t, p, sizeof p);
        uint32_t b = 6 * t, *o = out->tri + 12 * (size_t)t;
        const uint32_t idx[12] = {0, 3, 5, 3, 1, 4, 5, 4, 2, 3, 4, 5};
        for (int k = 0; k < 12; k++) o[k] = b + idx[k];
    }
    return BF_OK;
}

static int parse_list(const char *s, uint32_t *out, int max)
{
    int n = 0;
    while (s && *s && n < max) {
        out[n++] = (uint32_t)strtoul(s, (char **)&s, 10);
        if (*s == ',') s++;
    }
    return n;
}

int main(int argc, char **argv)
{
    const char *path = BF_SOURCE_DIR "/../shared/data/meshes/bunny.ply";
    double size = 0.25;
    uint32_t levels[8] = {7, 8}, subs[8] = {0, 1, 2}, widths[8] = {640};
    int n_levels = 2, n_subs = 3, n_widths = 1;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--mesh") && i + 1 < argc) path = argv[++i];
        else if (!strcmp(argv[i], "--size") && i + 1 < argc) size = atof(argv[++i]);
        else if (!strcmp(argv[i], "--levels") && i + 1 < argc) n_levels = parse_list(argv[++i], levels, 8);
        else if (!strcmp(argv[i], "--subdivide") && i + 1 < argc) n_subs = parse_list(argv[++i], subs, 8);
        else if (!strcmp(argv[i], "--widths") && i + 1 < argc) n_widths = parse_list(argv[++i], widths, 8);
        else {
            fprintf(stderr, "usage: bench_voxelise [--mesh PLY] [--size M] [--levels 7,8] [--subdivide 0,1,2] "
                            "[--widths 320,640]\n");
            return 2;
        }
    }
    mesh_data base;
    if (mesh_read_ply(path, &base) != BF_OK) {
        fprintf(stderr, "bench_voxelise: %s\n", bf_last_error());
        return 1;
    }
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (uint32_t i = 0; i < 3 * base.n_verts; i++)
        lo[i % 3] = base.xyz[i] < lo[i % 3] ? base.xyz[i] : lo[i % 3], hi[i % 3] = base.xyz[i] > hi[i % 3] ? base.xyz[i] : hi[i % 3];
    double ext = 0;
    for (int a = 0; a < 3; a++) ext = hi[a] - lo[a] > ext ? hi[a] - lo[a] : ext;
    for (uint32_t i = 0; i < 3 * base.n_verts; i++) base.xyz[i] = (float)((base.xyz[i] - lo[i % 3]) * size / ext);
    gpu_context *ctx;
    if (gpu_context_create(NULL, &ctx) != BF_OK) {
        fprintf(stderr, "bench_voxelise: %s\n", bf_last_error());
        return 1;
    }
    printf("| triangles | level | voxel [mm] | bricks | pairs | binning [s] | GPU pass [s] | total [s] | M triangles/s | map [MiB] | bytes per triangle |");
    for (int wi = 0; wi < n_widths; wi++) printf(" ray-cast %ux%u [ms] |", widths[wi], widths[wi] * 3 / 4);
    printf("\n|---|---|---|---|---|---|---|---|---|---|---|");
    for (int wi = 0; wi < n_widths; wi++) printf("---|");
    printf("\n");
    for (int si = 0; si < n_subs; si++) {
        mesh_data m = base, next;
        bool owned = false;
        for (uint32_t k = 0; k < subs[si]; k++) {
            if (subdivide(&m, &next) != BF_OK) return 1;
            if (owned) mesh_free(&m);
            m = next, owned = true;
        }
        for (int li = 0; li < n_levels; li++) {
            render_voxelise_config vc = render_voxelise_config_default();
            vc.level = levels[li];
            hostmap hm;
            render_voxelise_stats st;
            if (render_voxelise_mesh(ctx, &m, NULL, &vc, &hm, &st) != BF_OK) {
                fprintf(stderr, "bench_voxelise: %s\n", bf_last_error());
                return 1;
            }
            fusion_config fc = fusion_config_default();
            fc.brick_cap = hm.n_bricks + 64, fc.node_cap = 16 * hm.n_bricks + 1024;
            fc.window = 2, fc.subcache = 1; /* no frames are fused: a small frame ring, no frame pipelines */
            fc.load_only = true;
            double ms[8] = {0}, map_mib = 0;
            for (int wi = 0; wi < n_widths; wi++) {
                uint32_t W = widths[wi], H = W * 3 / 4;
                const bf_intrinsics K = {W, H, 525.0 * W / 640.0, 525.0 * W / 640.0, (W - 1) / 2.0, (H - 1) / 2.0, 5000};
                fusion_map *map;
                render_caster *rc;
                if (fusion_create(ctx, &fc, &K, hm.origin_w, &map) != BF_OK) {
                    fprintf(stderr, "bench_voxelise: %s\n", bf_last_error());
                    break;
                }
                if (fusion_load(map, &hm) == BF_OK && render_create(ctx, NULL, K.width, K.height, &rc) == BF_OK) {
                    fusion_stats fs;
                    if (fusion_get_stats(map, &fs) == BF_OK) map_mib = fs.bytes_total / 1048576.0;
                    bf_vec3 c = bf_v3(hm.origin_w.x + size / 2 + 0.016, hm.origin_w.y + size / 2 + 0.016,
                                      hm.origin_w.z + size / 2 + 0.016);
                    bf_se3 T = bf_se3_from_qt(bf_quat_identity(), bf_v3(c.x, c.y, c.z - 2.0 * size));
                    render_options ro = render_options_display();
                    ro.no_graze = true;
                    for (int r = 0; r < 3; r++) { /* the last of three: compiled and warm */
                        if (render_raycast(rc, map, &K, &T, &ro) != BF_OK) break;
                        ms[wi] = render_last_ms(rc);
                    }
                    render_destroy(rc);
                }
                fusion_destroy(map);
            }
            printf("| %u | %u | %.2f | %u | %llu | %.3f | %.3f | %.3f | %.2f | %.2f | %.1f |", m.n_tris, vc.level,
                   1e3 * st.voxel_m, st.n_bricks, (unsigned long long)st.n_pairs, st.seconds_bin, st.seconds_gpu,
                   st.seconds, m.n_tris / st.seconds / 1e6, map_mib, map_mib * 1048576.0 / m.n_tris);
            for (int wi = 0; wi < n_widths; wi++) printf(" %.1f |", ms[wi]);
            printf("\n");
            fflush(stdout);
            hostmap_free(&hm);
        }
        if (owned) mesh_free(&m);
    }
    mesh_free(&base);
    gpu_context_destroy(ctx);
    return 0;
}
