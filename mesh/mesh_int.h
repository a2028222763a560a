/* Declarations shared by mesh/'s writers: a buffered output file written
 * atomically (a temporary file beside the target, fsync, rename), so a
 * large mesh streams to disk instead of being built in memory first. Not
 * public. */
#ifndef BF_MESH_INT_H
#define BF_MESH_INT_H

#include <stdio.h>
#include <string.h>

#include "mesh.h"

typedef struct mesh__out {
    const char *path; /* borrowed: the target */
    char tmp[4200];   /* the temporary file beside it */
    FILE *f;
    int err;          /* the first errno of a failed write, 0 while all is well */
} mesh__out;

/* Creates the temporary file for path. BF_IO names it. */
bf_status mesh__out_open(mesh__out *o, const char *path);
/* Appends n bytes; a failure is kept and reported by mesh__out_commit. */
void mesh__out_write(mesh__out *o, const void *p, size_t n);
/* printf into the file (one line of text; a failure as above). */
void mesh__out_printf(mesh__out *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Flushes, fsyncs, closes and renames into place; on any failure removes
 * the temporary file and returns BF_IO naming the path. */
bf_status mesh__out_commit(mesh__out *o);
/* Closes and removes the temporary file (after a failure elsewhere). */
void mesh__out_abort(mesh__out *o);

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
