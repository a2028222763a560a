/* Meshes made for the mesh tests. */
#ifndef BF_TEST_MESH_FIXTURE_H
#define BF_TEST_MESH_FIXTURE_H

#include "mesh/mesh.h"

/* A UV sphere of radius r around c: rings x segments quads, split in two,
 * outward normals; colour = the vertex index in 24 bits, so any vertex of a
 * simplified mesh names the one it came from. Aborts on no memory. */
void fx_uv_sphere(mesh_data *m, double r, bf_vec3 c, uint32_t rings, uint32_t segs);

#endif
