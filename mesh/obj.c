/* Wavefront OBJ and its material file (MTL), as MeshLab, Blender and Open3D
 * read them. Colour per vertex is the common "v x y z r g b" extension
 * (MeshLab's and Blender's importers read it); the material is a plain
 * white matte one, so the vertex colours show as they are. A point cloud is
 * its v lines and p elements naming them, no material. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mesh_int.h"

/* Fixed-point text of v with `decimals` digits after the point (at most 9),
 * rounded half away from zero; much faster than printf's %f over millions
 * of numbers. Returns the end. Values beyond 1e9 or not finite go through
 * printf. */
static char *obj_fixed(char *p, double v, int decimals)
{
    static const double scale[] = {1, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9};
    if (!isfinite(v) || fabs(v) >= 1e9) return p + sprintf(p, "%.*f", decimals, v);
    double r = round(fabs(v) * scale[decimals]);
    uint64_t u = (uint64_t)r;
    uint64_t whole = u / (uint64_t)scale[decimals], frac = u % (uint64_t)scale[decimals];
    if (v < 0 && u != 0) *p++ = '-';
    char digits[24];
    int n = 0;
    do digits[n++] = (char)('0' + whole % 10), whole /= 10;
    while (whole);
    while (n) *p++ = digits[--n];
    if (decimals == 0) return p;
    *p++ = '.';
    for (int k = decimals - 1; k >= 0; k--) p[k] = (char)('0' + frac % 10), frac /= 10;
    return p + decimals;
}

static char *obj_u32(char *p, uint32_t v)
{
    char digits[12];
    int n = 0;
    do digits[n++] = (char)('0' + v % 10), v /= 10;
    while (v);
    while (n) *p++ = digits[--n];
    return p;
}

/* path with its extension replaced by .mtl (or .mtl appended), and the
 * file name alone for mtllib. */
static bf_status obj_mtl_path(const char *path, char *out, size_t cap, const char **name)
{
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    size_t stem = dot && (!slash || dot > slash) ? (size_t)(dot - path) : strlen(path);
    if (snprintf(out, cap, "%.*s.mtl", (int)stem, path) >= (int)cap)
        return bf_fail(BF_INVALID_ARG, "path too long: %s", path);
    const char *s = strrchr(out, '/');
    *name = s ? s + 1 : out;
    return BF_OK;
}

bf_status mesh_write_obj(const char *path, const mesh_data *m)
{
    bf_status s = mesh__check(path, m);
    if (s != BF_OK) return s;
    char mtl_path[4200];
    const char *mtl_name = NULL;
    if ((s = obj_mtl_path(path, mtl_path, sizeof mtl_path, &mtl_name)) != BF_OK) return s;
    bool is_mesh = m->n_tris > 0;
    bf_out o;
    if ((s = bf_out_open(&o, path)) != BF_OK) return s;
    bf_out_printf(&o, "# written by bitfuse: %u vertices, %u triangles%s\n", m->n_verts, m->n_tris,
                     m->rgb ? "; vertex colours as v x y z r g b" : "");
    if (mesh__has_origin(m))
        bf_out_printf(&o, "# origin_w %.17g %.17g %.17g (a vertex's world position is origin_w + v)\n",
                         m->origin.x, m->origin.y, m->origin.z);
    if (is_mesh) bf_out_printf(&o, "mtllib %s\n", mtl_name);
    char line[256];
    for (size_t i = 0; i < m->n_verts; i++) {
        char *p = line;
        *p++ = 'v';
        /* 1 micrometre: below a float's step beyond 8 m, and far below the
         * map's voxels. */
        for (int k = 0; k < 3; k++) *p++ = ' ', p = obj_fixed(p, m->xyz[3 * i + k], 6);
        if (m->rgb)
            for (int k = 0; k < 3; k++) *p++ = ' ', p = obj_fixed(p, m->rgb[3 * i + k] / 255.0, 4);
        *p++ = '\n';
        bf_out_write(&o, line, (size_t)(p - line));
    }
    if (is_mesh && m->normal)
        for (size_t i = 0; i < m->n_verts; i++) {
            char *p = line;
            *p++ = 'v', *p++ = 'n';
            for (int k = 0; k < 3; k++) *p++ = ' ', p = obj_fixed(p, m->normal[3 * i + k], 4);
            *p++ = '\n';
            bf_out_write(&o, line, (size_t)(p - line));
        }
    if (is_mesh) bf_out_printf(&o, "usemtl bitfuse\n");
    for (size_t t = 0; t < m->n_tris; t++) {
        char *p = line;
        *p++ = 'f';
        for (int k = 0; k < 3; k++) {
            uint32_t v = m->tri[3 * t + k] + 1; /* OBJ counts from 1 */
            *p++ = ' ';
            p = obj_u32(p, v);
            if (m->normal) *p++ = '/', *p++ = '/', p = obj_u32(p, v);
        }
        *p++ = '\n';
        bf_out_write(&o, line, (size_t)(p - line));
    }
    if (!is_mesh) {
        /* A point cloud's vertices as point elements: readers that build
         * geometry from elements (assimp, Blender's importer, tinyobjloader)
         * drop vertices no element uses, and read a file of bare v lines
         * as empty. 16 points a line. */
        for (uint32_t i = 0; i < m->n_verts; i += 16) {
            char *p = line;
            *p++ = 'p';
            for (uint32_t k = i; k < m->n_verts && k < i + 16; k++) *p++ = ' ', p = obj_u32(p, k + 1);
            *p++ = '\n';
            bf_out_write(&o, line, (size_t)(p - line));
        }
        return bf_out_commit(&o);
    }
    /* The material with the mesh: both written and synced before either is
     * renamed, so a failure leaves the earlier pair as it was (a failed OBJ
     * replaced the .mtl, or left one behind). */
    static const char mtl[] = "# written by bitfuse: a white matte material; the colour is per vertex\n"
                              "newmtl bitfuse\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n";
    bf_out om;
    if ((s = bf_out_open(&om, mtl_path)) != BF_OK) {
        bf_out_abort(&o);
        return s;
    }
    bf_out_write(&om, mtl, sizeof mtl - 1);
    return bf_out_commit_both(&om, &o);
}
