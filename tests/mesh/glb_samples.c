/* Writes .glb files of each shape mesh_write_glb makes (a mesh with
 * normals, colours and a far origin; a simplified mesh; a point cloud; an
 * empty mesh) into the folder argv[1], for the Khronos validator
 * (validate_glb.js) to check. */
#include <stdio.h>

#include "fixture.h"

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: glb_samples DIR\n");
        return 2;
    }
    char path[4096];
    mesh_data m, e = {0};
    fx_uv_sphere(&m, 0.5, bf_v3(0.1, -0.2, 0.3), 40, 60);
    m.origin = bf_v3(10000.125, -2500.5, 0.75);
    mesh_data p = {.n_verts = m.n_verts, .xyz = m.xyz, .rgb = m.rgb};
    bf_status s = bf_path_join(path, sizeof path, argv[1], "sphere.glb");
    if (s == BF_OK) s = mesh_write_glb(path, &m);
    if (s == BF_OK) s = bf_path_join(path, sizeof path, argv[1], "points.glb");
    if (s == BF_OK) s = mesh_write_glb(path, &p);
    if (s == BF_OK) s = bf_path_join(path, sizeof path, argv[1], "empty.glb");
    if (s == BF_OK) s = mesh_write_glb(path, &e);
    mesh_simplify_config cfg = {.max_triangles = 500};
    if (s == BF_OK) s = mesh_simplify(&m, &cfg, NULL);
    if (s == BF_OK) s = bf_path_join(path, sizeof path, argv[1], "simplified.glb");
    if (s == BF_OK) s = mesh_write_glb(path, &m);
    mesh_free(&m);
    if (s != BF_OK) fprintf(stderr, "glb_samples: %s\n", bf_last_error());
    return s == BF_OK ? 0 : 1;
}
