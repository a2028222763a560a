/* A textured floor for the photometric term's tests (tests/tracking,
 * tests/recon): 8 x 8 m in the plane z = 0, a mosaic of 8 cm squares in the
 * room's eight object colours (mottled: synth's SYNTH_MAT_OBJECT), a texture
 * with edges and gradients at every scale the pyramid sees, seen from 1.8 m
 * at T0. Its shape leaves the slides along it and the turn about its normal
 * free. Static: each test file gets its own copy. */
#ifndef BF_TESTS_MOSAIC_SCENE_H
#define BF_TESTS_MOSAIC_SCENE_H

#include <stdlib.h>

#include "mesh/mesh.h"
#include "synth/synth.h"

static inline bf_status mosaic_scene(synth_scene *sc, bf_se3 *T0)
{
    const uint32_t n = 100;
    const float half = 4.0f, step = 2 * half / (float)n;
    mesh_data m = {0};
    m.n_verts = (n + 1) * (n + 1), m.n_tris = 2 * n * n;
    m.xyz = malloc((size_t)m.n_verts * 3 * sizeof(float));
    m.tri = malloc((size_t)m.n_tris * 3 * sizeof(uint32_t));
    if (!m.xyz || !m.tri) {
        free(m.xyz), free(m.tri);
        return BF_NO_MEMORY;
    }
    for (uint32_t j = 0; j <= n; j++)
        for (uint32_t i = 0; i <= n; i++) {
            float *v = m.xyz + 3 * (size_t)(j * (n + 1) + i);
            v[0] = -half + step * (float)i, v[1] = -half + step * (float)j, v[2] = 0;
        }
    for (uint32_t j = 0; j < n; j++)
        for (uint32_t i = 0; i < n; i++) {
            uint32_t a = j * (n + 1) + i, *t = m.tri + 6 * (size_t)(j * n + i);
            t[0] = a, t[1] = a + 1, t[2] = a + n + 2, t[3] = a, t[4] = a + n + 2, t[5] = a + n + 1;
        }
    *T0 = synth_look_at(bf_v3(0, -1.05, 1.5), bf_v3(0, 0, 0), bf_v3(0, 0, 1));
    bf_status s = synth_scene_from_mesh(&m, T0, sc);
    for (uint32_t k = 0; s == BF_OK && k < sc->mesh.n_tris; k++) {
        uint32_t q = k / 2;
        sc->tri_material[k] = SYNTH_MAT_OBJECT;
        sc->tri_variant[k] = (uint8_t)((q * 2654435761u) >> 29);
    }
    return s;
}

#endif
