/* Fuzz target: mesh and particle files: the PLY reader (meshes for
 * eval-surface and render --mesh, particle sets for render --particles,
 * which are PLY vertices) and the OFF reader. The input is the file; both
 * readers read it, and it reads if one of them takes it. */
#include "fuzz.h"
#include "mesh/mesh.h"

static bf_status read_one(const char *path, bf_status (*reader)(const char *, mesh_data *))
{
    mesh_data m = {0};
    bf_status s = reader(path, &m);
    if (s != BF_OK) return s;
    /* Every index must name a vertex: what the BVH and renderers assume. */
    for (uint64_t i = 0; i < 3ull * m.n_tris; i++) BF_ASSERT(m.tri[i] < m.n_verts);
    mesh_free(&m);
    return BF_OK;
}

bf_status fuzz_mesh(const uint8_t *data, size_t size)
{
    const char *dir = fuzz_scratch();
    const char *ply = fuzz_write(dir, "mesh.ply", data, size);
    const char *off = fuzz_write(dir, "mesh.off", data, size);
    if (!ply || !off) return BF_IO;
    bf_status s = read_one(ply, mesh_read_ply);
    bf_status s2 = read_one(off, mesh_read_off);
    return s == BF_OK ? BF_OK : s2;
}

FUZZ_TARGET(fuzz_mesh)
