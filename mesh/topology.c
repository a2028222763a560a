/* A mesh's topology: whether it closes (the voxeliser's inside/outside
 * parity needs a closed surface). */
#include <stdlib.h>

#include <meshoptimizer.h>

#include "mesh.h"

static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

bf_status mesh_open_edges(const mesh_data *m, uint64_t *out)
{
    if (!m || !out) return bf_fail(BF_INVALID_ARG, "mesh_open_edges: NULL argument");
    *out = 0;
    if (m->n_tris == 0) return BF_OK;
    /* Vertices at the same position are one (a mesh written face by face
     * repeats them): meshoptimizer's remap welds equal positions. */
    unsigned int *remap = malloc((size_t)(m->n_verts ? m->n_verts : 1) * sizeof *remap);
    uint64_t *edges = malloc((size_t)m->n_tris * 3 * sizeof *edges);
    if (!remap || !edges) {
        free(remap), free(edges);
        return bf_fail(BF_NO_MEMORY, "mesh_open_edges: %u triangles", m->n_tris);
    }
    for (uint64_t i = 0; i < (uint64_t)m->n_tris * 3; i++)
        if (m->tri[i] >= m->n_verts) {
            free(remap), free(edges);
            return bf_fail(BF_INVALID_ARG, "mesh_open_edges: index %u of %u vertices", m->tri[i], m->n_verts);
        }
    meshopt_generateVertexRemap(remap, m->tri, (size_t)m->n_tris * 3, m->xyz, m->n_verts, 3 * sizeof(float));
    size_t n = 0;
    for (uint32_t t = 0; t < m->n_tris; t++)
        for (int k = 0; k < 3; k++) {
            uint64_t a = remap[m->tri[3 * (size_t)t + (size_t)k]], b = remap[m->tri[3 * (size_t)t + (size_t)(k + 1) % 3]];
            if (a == b) continue; /* a degenerate triangle's collapsed edge */
            edges[n++] = a < b ? a << 32 | b : b << 32 | a;
        }
    qsort(edges, n, sizeof *edges, cmp_u64);
    /* A closed surface uses every edge an even number of times (twice where
     * it is a manifold). */
    for (size_t i = 0, j; i < n; i = j) {
        for (j = i + 1; j < n && edges[j] == edges[i];) j++;
        *out += (j - i) & 1u;
    }
    free(remap), free(edges);
    return BF_OK;
}
