/* Declarations shared by mesh/'s writers (their output file is core's
 * bf_out: streamed through a buffer into a temporary file beside the
 * target, fsync, rename, so a large mesh is never built in memory first
 * and never appears half written). Not public. */
#ifndef BF_MESH_INT_H
#define BF_MESH_INT_H

#include <stdio.h>
#include <string.h>

#include "mesh.h"

/* Little-endian stores (the files' byte order, whatever the host's). */
static inline uint8_t *mesh__put_u32(uint8_t *p, uint32_t b)
{
    for (int i = 0; i < 4; i++) *p++ = (uint8_t)(b >> (8 * i));
    return p;
}

static inline uint8_t *mesh__put_f32(uint8_t *p, float f)
{
    uint32_t b;
    memcpy(&b, &f, 4);
    return mesh__put_u32(p, b);
}

/* BF_INVALID_ARG when a triangle uses a vertex past the end, or vertices
 * come without positions. */
bf_status mesh__check(const char *path, const mesh_data *m);
/* Whether the mesh has a local origin to record. */
static inline bool mesh__has_origin(const mesh_data *m)
{
    return m->origin.x != 0 || m->origin.y != 0 || m->origin.z != 0;
}

#endif
