/* What the writers share: the format names, the dispatch, the atomic
 * streaming output file and the mesh check. */
#include <errno.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "mesh_int.h"

static const char *const format_names[] = {"ply", "obj", "glb"};

const char *mesh_format_name(mesh_format f)
{
    return (unsigned)f < sizeof format_names / sizeof format_names[0] ? format_names[f] : "?";
}

bool mesh_format_parse(const char *name, mesh_format *out)
{
    for (unsigned k = 0; k < sizeof format_names / sizeof format_names[0]; k++)
        if (!strcasecmp(name, format_names[k])) {
            *out = (mesh_format)k;
            return true;
        }
    return false;
}

bf_status mesh_format_of_path(const char *path, mesh_format *out)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash) || !mesh_format_parse(dot + 1, out))
        return bf_fail(BF_INVALID_ARG, "%s: unknown mesh format: the name should end in .ply, .obj or .glb", path);
    return BF_OK;
}

bf_status mesh_write(const char *path, mesh_format f, const mesh_data *m)
{
    switch (f) {
    case MESH_FORMAT_PLY: return mesh_write_ply(path, m);
    case MESH_FORMAT_OBJ: return mesh_write_obj(path, m);
    case MESH_FORMAT_GLB: return mesh_write_glb(path, m);
    }
    return bf_fail(BF_INVALID_ARG, "%s: unknown mesh format %d", path, (int)f);
}

bf_status mesh__check(const char *path, const mesh_data *m)
{
    if (m->n_verts > 0 && !m->xyz) return bf_fail(BF_INVALID_ARG, "%s: mesh has no vertex array", path);
    if (m->n_tris > 0 && !m->tri) return bf_fail(BF_INVALID_ARG, "%s: mesh has no triangle array", path);
    for (size_t i = 0; i < 3 * (size_t)m->n_tris; i++)
        if (m->tri[i] >= m->n_verts)
            return bf_fail(BF_INVALID_ARG, "%s: triangle %zu uses vertex %u of %u", path, i / 3, m->tri[i],
                           m->n_verts);
    return BF_OK;
}

/* ------------------------------------------------------------ the output file */

bf_status mesh__out_open(mesh__out *o, const char *path)
{
    memset(o, 0, sizeof *o);
    o->path = path;
    if (snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%d", path, (int)getpid()) >= (int)sizeof o->tmp)
        return bf_fail(BF_INVALID_ARG, "path too long: %s", path);
    o->f = fopen(o->tmp, "wb");
    if (!o->f) return bf_fail(BF_IO, "%s: cannot create: %s", o->tmp, strerror(errno));
    /* A large buffer: the writers hand over a vertex or a line at a time. */
    setvbuf(o->f, NULL, _IOFBF, 1 << 20);
    return BF_OK;
}

void mesh__out_write(mesh__out *o, const void *p, size_t n)
{
    if (o->err || n == 0) return;
    if (fwrite(p, 1, n, o->f) != n) o->err = errno ? errno : EIO;
}

void mesh__out_printf(mesh__out *o, const char *fmt, ...)
{
    if (o->err) return;
    va_list ap;
    va_start(ap, fmt);
    if (vfprintf(o->f, fmt, ap) < 0) o->err = errno ? errno : EIO;
    va_end(ap);
}

bf_status mesh__out_commit(mesh__out *o)
{
    int e = o->err;
    if (!e && fflush(o->f) != 0) e = errno;
    if (!e && fsync(fileno(o->f)) != 0) e = errno;
    /* Close even after a failure, or the descriptor leaks. */
    if (fclose(o->f) != 0 && !e) e = errno;
    o->f = NULL;
    if (e) {
        unlink(o->tmp);
        return bf_fail(BF_IO, "%s: write failed: %s", o->path, strerror(e));
    }
    if (rename(o->tmp, o->path) != 0) {
        e = errno;
        unlink(o->tmp);
        return bf_fail(BF_IO, "%s: cannot rename into place: %s", o->path, strerror(e));
    }
    return BF_OK;
}

void mesh__out_abort(mesh__out *o)
{
    if (o->f) fclose(o->f);
    o->f = NULL;
    unlink(o->tmp);
}
