/* glTF 2.0 binary (.glb), after the Khronos glTF 2.0 specification: a
 * 12-byte header, a JSON chunk (padded with spaces) and a BIN chunk
 * (padded with zeros), each a multiple of 4 bytes. The JSON is small and of
 * one fixed shape, so it is printed here rather than built through a JSON
 * library; tests/mesh parses it back with cJSON and runs the Khronos
 * validator where it is installed. */
#include <float.h>
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mesh_int.h"

#define GLB_MAGIC 0x46546C67u      /* "glTF" */
#define GLB_CHUNK_JSON 0x4E4F534Au /* "JSON" */
#define GLB_CHUNK_BIN 0x004E4942u  /* "BIN\0" */
#define GL_FLOAT 5126
#define GL_UNSIGNED_INT 5125
#define GL_ARRAY_BUFFER 34962
#define GL_ELEMENT_ARRAY_BUFFER 34963

/* glTF's COLOR_0 is linear; camera colours are sRGB (IEC 61966-2-1). */
static float srgb_to_linear(uint8_t c)
{
    double v = c / 255.0;
    return (float)(v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4));
}

/* A unit normal: glTF requires NORMAL to be unit length, so a zero or
 * broken one (a vertex of degenerate triangles) becomes +z. */
static void unit_normal(const float *n, float out[3])
{
    double l = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
    if (!(l > 1e-12) || !isfinite(l)) {
        out[0] = 0, out[1] = 0, out[2] = 1;
        return;
    }
    for (int k = 0; k < 3; k++) out[k] = (float)(n[k] / l);
}

typedef struct glb_json {
    char *p;
    size_t len, cap;
    bool is_full;
} glb_json;

static void json_add(glb_json *j, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void json_add(glb_json *j, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(j->p + j->len, j->cap - j->len, fmt, ap);
    va_end(ap);
    if (n < 0 || (size_t)n >= j->cap - j->len)
        j->is_full = true;
    else
        j->len += (size_t)n;
}

/* One bufferView of the BIN chunk. */
static void json_view(glb_json *j, bool *is_first, uint64_t offset, uint64_t length, int target)
{
    json_add(j, "%s{\"buffer\":0,\"byteOffset\":%llu,\"byteLength\":%llu,\"target\":%d}", *is_first ? "" : ",",
             (unsigned long long)offset, (unsigned long long)length, target);
    *is_first = false;
}

bf_status mesh_write_glb(const char *path, const mesh_data *m)
{
    bf_status s = mesh__check(path, m);
    if (s != BF_OK) return s;
    uint64_t nv = m->n_verts, nt = m->n_tris;
    bool has_normal = nv && m->normal, has_rgb = nv && m->rgb, is_mesh = nt > 0;
    /* BIN: positions, normals, colours, indices; every part a multiple of 4. */
    uint64_t off_pos = 0, off_nrm = off_pos + 12 * nv, off_rgb = off_nrm + (has_normal ? 12 * nv : 0);
    uint64_t off_idx = off_rgb + (has_rgb ? 12 * nv : 0), bin_len = off_idx + 12 * nt;
    float lo[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, hi[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
    for (size_t i = 0; i < nv; i++)
        for (int k = 0; k < 3; k++) {
            float v = m->xyz[3 * i + k];
            if (!isfinite(v)) return bf_fail(BF_INVALID_ARG, "%s: vertex %zu is not finite", path, i);
            lo[k] = fminf(lo[k], v), hi[k] = fmaxf(hi[k], v);
        }

    char buf[4096];
    glb_json j = {buf, 0, sizeof buf, false};
    json_add(&j, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"bitfuse\"},\"scene\":0");
    if (nv == 0) {
        json_add(&j, ",\"scenes\":[{}]}");
    } else {
        json_add(&j, ",\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0");
        /* The local origin as the node's translation, in full double. */
        if (mesh__has_origin(m))
            json_add(&j, ",\"translation\":[%.17g,%.17g,%.17g]", m->origin.x, m->origin.y, m->origin.z);
        json_add(&j, "}],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0");
        int acc = 1;
        if (has_normal) json_add(&j, ",\"NORMAL\":%d", acc++);
        if (has_rgb) json_add(&j, ",\"COLOR_0\":%d", acc++);
        json_add(&j, "}");
        if (is_mesh) json_add(&j, ",\"indices\":%d", acc);
        json_add(&j, ",\"mode\":%d,\"material\":0}]}]", is_mesh ? 4 : 0);
        json_add(&j, ",\"materials\":[{\"name\":\"bitfuse\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,1],"
                     "\"metallicFactor\":0,\"roughnessFactor\":1},\"doubleSided\":true}]");
        json_add(&j, ",\"buffers\":[{\"byteLength\":%llu}],\"bufferViews\":[", (unsigned long long)bin_len);
        bool is_first = true;
        json_view(&j, &is_first, off_pos, 12 * nv, GL_ARRAY_BUFFER);
        if (has_normal) json_view(&j, &is_first, off_nrm, 12 * nv, GL_ARRAY_BUFFER);
        if (has_rgb) json_view(&j, &is_first, off_rgb, 12 * nv, GL_ARRAY_BUFFER);
        if (is_mesh) json_view(&j, &is_first, off_idx, 12 * nt, GL_ELEMENT_ARRAY_BUFFER);
        /* min/max in %.9g: a float printed so survives the round trip, and
         * the validator compares them with the data exactly. */
        json_add(&j, "],\"accessors\":[{\"bufferView\":0,\"componentType\":%d,\"count\":%llu,\"type\":\"VEC3\","
                     "\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]}",
                 GL_FLOAT, (unsigned long long)nv, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
        int view = 1;
        if (has_normal)
            json_add(&j, ",{\"bufferView\":%d,\"componentType\":%d,\"count\":%llu,\"type\":\"VEC3\"}", view++,
                     GL_FLOAT, (unsigned long long)nv);
        if (has_rgb)
            json_add(&j, ",{\"bufferView\":%d,\"componentType\":%d,\"count\":%llu,\"type\":\"VEC3\"}", view++,
                     GL_FLOAT, (unsigned long long)nv);
        if (is_mesh)
            json_add(&j, ",{\"bufferView\":%d,\"componentType\":%d,\"count\":%llu,\"type\":\"SCALAR\"}", view,
                     GL_UNSIGNED_INT, (unsigned long long)(3 * nt));
        json_add(&j, "]}");
    }
    BF_ASSERT(!j.is_full);
    while (j.len % 4) buf[j.len++] = ' ';
    uint64_t total = 12 + 8 + j.len + (nv ? 8 + bin_len : 0);
    if (total > UINT32_MAX)
        return bf_fail(BF_UNSUPPORTED, "%s: %llu bytes: beyond glb's 4 GiB (simplify the mesh, or write PLY)", path,
                       (unsigned long long)total);

    bf_out o;
    if ((s = bf_out_open(&o, path)) != BF_OK) return s;
    uint8_t rec[20], *p = rec;
    p = mesh__put_u32(p, GLB_MAGIC);
    p = mesh__put_u32(p, 2);
    p = mesh__put_u32(p, (uint32_t)total);
    p = mesh__put_u32(p, (uint32_t)j.len);
    p = mesh__put_u32(p, GLB_CHUNK_JSON);
    bf_out_write(&o, rec, (size_t)(p - rec));
    bf_out_write(&o, buf, j.len);
    if (nv) {
        p = mesh__put_u32(rec, (uint32_t)bin_len);
        p = mesh__put_u32(p, GLB_CHUNK_BIN);
        bf_out_write(&o, rec, (size_t)(p - rec));
        for (size_t i = 0; i < nv; i++) {
            p = rec;
            for (int k = 0; k < 3; k++) p = mesh__put_f32(p, m->xyz[3 * i + k]);
            bf_out_write(&o, rec, 12);
        }
        for (size_t i = 0; has_normal && i < nv; i++) {
            float n[3];
            unit_normal(&m->normal[3 * i], n);
            p = rec;
            for (int k = 0; k < 3; k++) p = mesh__put_f32(p, n[k]);
            bf_out_write(&o, rec, 12);
        }
        for (size_t i = 0; has_rgb && i < nv; i++) {
            p = rec;
            for (int k = 0; k < 3; k++) p = mesh__put_f32(p, srgb_to_linear(m->rgb[3 * i + k]));
            bf_out_write(&o, rec, 12);
        }
        for (size_t t = 0; t < 3 * nt; t++) {
            p = mesh__put_u32(rec, m->tri[t]);
            bf_out_write(&o, rec, 4);
        }
    }
    return bf_out_commit(&o);
}
