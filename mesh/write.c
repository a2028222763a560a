/* What the writers share: the format names, the dispatch and the mesh
 * check. */
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
