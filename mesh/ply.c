/* PLY meshes and point clouds: reading (ascii, binary little- and
 * big-endian), writing (binary little-endian) and appending.
 *
 * Format: Greg Turk's PLY description (1994), as written by the Stanford
 * tools, CGAL, Open3D and MeshLab. The reader loads the whole file and checks
 * every count against the bytes that are left before allocating, so a header
 * that claims 10^12 vertices fails as BF_FORMAT instead of exhausting memory. */
#include "mesh_int.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------ header */

typedef enum ply_type {
    PLY_NONE,
    PLY_I8,
    PLY_U8,
    PLY_I16,
    PLY_U16,
    PLY_I32,
    PLY_U32,
    PLY_F32,
    PLY_F64
} ply_type;

static const struct {
    const char *name;
    ply_type type;
} ply_type_names[] = {
    {"char", PLY_I8},     {"int8", PLY_I8},     {"uchar", PLY_U8},    {"uint8", PLY_U8},
    {"short", PLY_I16},   {"int16", PLY_I16},   {"ushort", PLY_U16},  {"uint16", PLY_U16},
    {"int", PLY_I32},     {"int32", PLY_I32},   {"uint", PLY_U32},    {"uint32", PLY_U32},
    {"float", PLY_F32},   {"float32", PLY_F32}, {"double", PLY_F64},  {"float64", PLY_F64},
};

static size_t ply_type_size(ply_type t)
{
    switch (t) {
    case PLY_I8:
    case PLY_U8: return 1;
    case PLY_I16:
    case PLY_U16: return 2;
    case PLY_I32:
    case PLY_U32:
    case PLY_F32: return 4;
    case PLY_F64: return 8;
    default: return 0;
    }
}

static bool ply_type_is_int(ply_type t) { return t != PLY_F32 && t != PLY_F64; }

/* What a vertex or face property means to us. */
typedef enum ply_role {
    ROLE_SKIP,
    ROLE_X,
    ROLE_Y,
    ROLE_Z,
    ROLE_NX,
    ROLE_NY,
    ROLE_NZ,
    ROLE_R,
    ROLE_G,
    ROLE_B,
    ROLE_INDICES
} ply_role;

#define PLY_MAX_PROPS 64
#define PLY_MAX_ELEMENTS 16

typedef struct ply_prop {
    ply_type type;       /* scalar type, or the item type of a list */
    ply_type count_type; /* PLY_NONE for a scalar */
    ply_role role;
} ply_prop;

typedef struct ply_element {
    char name[64];
    uint64_t count;
    int n_props;
    ply_prop prop[PLY_MAX_PROPS];
    bool is_vertex, is_face;
} ply_element;

typedef enum ply_format { PLY_ASCII, PLY_BIN_LE, PLY_BIN_BE } ply_format;

/* The body reader: a cursor over the loaded file. */
typedef struct ply_reader {
    const char *path;
    const uint8_t *base, *p, *end; /* base: start of the file, for byte offsets */
    ply_format format;
    size_t line; /* ascii: current line, 1-based */
} ply_reader;

static ply_type ply_parse_type(const char *s)
{
    for (size_t i = 0; i < sizeof ply_type_names / sizeof ply_type_names[0]; i++)
        if (!strcmp(s, ply_type_names[i].name)) return ply_type_names[i].type;
    return PLY_NONE;
}

static ply_role ply_vertex_role(const char *name)
{
    static const struct {
        const char *name;
        ply_role role;
    } roles[] = {
        {"x", ROLE_X},   {"y", ROLE_Y},     {"z", ROLE_Z},       {"nx", ROLE_NX},
        {"ny", ROLE_NY}, {"nz", ROLE_NZ},   {"red", ROLE_R},     {"green", ROLE_G},
        {"blue", ROLE_B},
    };
    for (size_t i = 0; i < sizeof roles / sizeof roles[0]; i++)
        if (!strcmp(name, roles[i].name)) return roles[i].role;
    return ROLE_SKIP;
}

/* Copies the next line of the header into buf (without the line end) and
 * advances *p past it. Returns false at the end of the data. */
static bool ply_header_line(const uint8_t **p, const uint8_t *end, char *buf, size_t cap)
{
    if (*p >= end) return false;
    const uint8_t *s = *p, *e = s;
    while (e < end && *e != '\n') e++;
    size_t len = (size_t)(e - s);
    if (len > 0 && s[len - 1] == '\r') len--;
    if (len >= cap) len = cap - 1;
    memcpy(buf, s, len);
    buf[len] = '\0';
    *p = e < end ? e + 1 : e;
    return true;
}

/* Minimum bytes one item of el occupies in the body: used to reject counts
 * that the file cannot possibly hold before allocating for them. */
static size_t ply_min_item_bytes(const ply_element *el, ply_format fmt)
{
    size_t n = 0;
    for (int i = 0; i < el->n_props; i++) {
        if (fmt == PLY_ASCII)
            n += 1; /* at least one digit (a loose bound: truncation gets a line number below) */
        else
            n += ply_type_size(el->prop[i].count_type != PLY_NONE ? el->prop[i].count_type
                                                                  : el->prop[i].type);
    }
    return n;
}

/* ------------------------------------------------------------ values */

static uint64_t ply_load_be(const uint8_t *p, size_t n)
{
    uint64_t v = 0;
    for (size_t i = 0; i < n; i++) v = v << 8 | p[i];
    return v;
}

static uint64_t ply_load_le(const uint8_t *p, size_t n)
{
    uint64_t v = 0;
    for (size_t i = n; i-- > 0;) v = v << 8 | p[i];
    return v;
}

/* Reads one value of type t as a double (every PLY type fits exactly).
 * what/idx name the place for the error message. */
static bf_status ply_read_value(ply_reader *rd, ply_type t, const char *what, uint64_t idx, double *out)
{
    if (rd->format == PLY_ASCII) {
        const uint8_t *p = rd->p;
        size_t last_line = rd->line; /* where the previous value was */
        while (p < rd->end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')) {
            if (*p == '\n') rd->line++;
            p++;
        }
        if (p >= rd->end)
            return bf_fail(BF_FORMAT, "%s: line %zu: %s %llu: file ends early", rd->path, last_line,
                           what, (unsigned long long)idx);
        /* The buffer is NUL-terminated (bf_read_file), so strtod stops. */
        char *e;
        errno = 0;
        double v = strtod((const char *)p, &e);
        if ((const uint8_t *)e == p || ((const uint8_t *)e < rd->end && *e != ' ' && *e != '\t' &&
                                        *e != '\r' && *e != '\n'))
            return bf_fail(BF_FORMAT, "%s: line %zu: %s %llu: not a number", rd->path, rd->line, what,
                           (unsigned long long)idx);
        /* Every PLY integer type fits 32 bits; inf and nan pass the floor
         * test, and a count cast from them is undefined (fuzz_mesh). */
        if (ply_type_is_int(t) && (v != floor(v) || !(fabs(v) <= 4294967295.0)))
            return bf_fail(BF_FORMAT, "%s: line %zu: %s %llu: '%.*s' is not a 32-bit integer", rd->path,
                           rd->line, what, (unsigned long long)idx, (int)((const uint8_t *)e - p), p);
        rd->p = (const uint8_t *)e;
        *out = v;
        return BF_OK;
    }
    size_t n = ply_type_size(t);
    if ((size_t)(rd->end - rd->p) < n)
        return bf_fail(BF_FORMAT, "%s: %s %llu: file truncated at byte %zu", rd->path, what,
                       (unsigned long long)idx, (size_t)(rd->p - rd->base));
    uint64_t bits = rd->format == PLY_BIN_LE ? ply_load_le(rd->p, n) : ply_load_be(rd->p, n);
    rd->p += n;
    switch (t) {
    case PLY_I8: *out = (int8_t)bits; break;
    case PLY_U8: *out = (uint8_t)bits; break;
    case PLY_I16: *out = (int16_t)bits; break;
    case PLY_U16: *out = (uint16_t)bits; break;
    case PLY_I32: *out = (int32_t)bits; break;
    case PLY_U32: *out = (uint32_t)bits; break;
    case PLY_F32: {
        uint32_t b32 = (uint32_t)bits;
        float f;
        memcpy(&f, &b32, 4);
        *out = f;
        break;
    }
    case PLY_F64: {
        double d;
        memcpy(&d, &bits, 8);
        *out = d;
        break;
    }
    default: BF_ASSERT(!"bad PLY type");
    }
    return BF_OK;
}

/* Skips n values of type t (binary: by size, bounds-checked). */
static bf_status ply_skip_values(ply_reader *rd, ply_type t, uint64_t n, const char *what, uint64_t idx)
{
    if (rd->format != PLY_ASCII) {
        size_t sz = ply_type_size(t);
        if (n > (uint64_t)(rd->end - rd->p) / sz)
            return bf_fail(BF_FORMAT, "%s: %s %llu: file truncated", rd->path, what,
                           (unsigned long long)idx);
        rd->p += n * sz;
        return BF_OK;
    }
    for (uint64_t k = 0; k < n; k++) {
        double v;
        bf_status s = ply_read_value(rd, t, what, idx, &v);
        if (s != BF_OK) return s;
    }
    return BF_OK;
}

/* ------------------------------------------------------------ reading */

typedef struct ply_tris {
    uint32_t *v;
    size_t n, cap; /* in triangles */
} ply_tris;

static bf_status ply_tris_push(ply_tris *t, uint32_t a, uint32_t b, uint32_t c)
{
    if (t->n == t->cap) {
        size_t nc = t->cap ? 2 * t->cap : 1024;
        uint32_t *nv = bf_realloc(t->v, nc * 3 * sizeof *nv);
        if (!nv) return bf_fail(BF_NO_MEMORY, "out of memory for %zu triangles", nc);
        t->v = nv;
        t->cap = nc;
    }
    t->v[3 * t->n] = a;
    t->v[3 * t->n + 1] = b;
    t->v[3 * t->n + 2] = c;
    t->n++;
    return BF_OK;
}

/* Double positions beyond this far from the file's origin (in its units,
 * metres for a scene: float steps there 0.12 mm) keep their precision
 * through a local origin. */
#define PLY_FAR_M 1024.0

/* Reads the vertices. Positions stored as double far from the origin are
 * kept relative to the first vertex's (rounded to the metre), which
 * shift[] returns, to be added to the mesh's origin: as floats they would
 * lose their millimetres (1 m steps at 1e7 m). */
static bf_status ply_read_vertices(ply_reader *rd, const ply_element *el, mesh_data *m, double shift[3])
{
    for (uint64_t i = 0; i < el->count; i++) {
        for (int k = 0; k < el->n_props; k++) {
            const ply_prop *pr = &el->prop[k];
            if (pr->count_type != PLY_NONE) {
                double cnt;
                bf_status s = ply_read_value(rd, pr->count_type, "vertex", i, &cnt);
                if (!s && cnt < 0)
                    s = bf_fail(BF_FORMAT, "%s: vertex %llu: negative list length", rd->path,
                                (unsigned long long)i);
                if (s == BF_OK) s = ply_skip_values(rd, pr->type, (uint64_t)cnt, "vertex", i);
                if (s != BF_OK) return s;
                continue;
            }
            double v;
            bf_status s = ply_read_value(rd, pr->type, "vertex", i, &v);
            if (s != BF_OK) return s;
            switch (pr->role) {
            case ROLE_X:
            case ROLE_Y:
            case ROLE_Z:
            case ROLE_NX:
            case ROLE_NY:
            case ROLE_NZ: {
                bool is_pos = pr->role <= ROLE_Z;
                if (is_pos && i == 0 && pr->type == PLY_F64 && fabs(v) > PLY_FAR_M && fabs(v) <= MESH_MAX_COORD)
                    shift[pr->role - ROLE_X] = round(v);
                float f = (float)(is_pos ? v - shift[pr->role - ROLE_X] : v);
                if (!isfinite(f) || (is_pos && fabs(v) > MESH_MAX_COORD)) {
                    const char *why = isfinite(f) ? "beyond 1e9 (no scene's coordinate)" : "not finite";
                    if (rd->format == PLY_ASCII)
                        return bf_fail(BF_FORMAT, "%s: line %zu: vertex %llu: %s is %s (%g)", rd->path, rd->line,
                                       (unsigned long long)i, is_pos ? "position" : "normal", why, v);
                    return bf_fail(BF_FORMAT, "%s: vertex %llu: %s is %s (%g)", rd->path, (unsigned long long)i,
                                   is_pos ? "position" : "normal", why, v);
                }
                if (is_pos)
                    m->xyz[3 * i + (pr->role - ROLE_X)] = f;
                else
                    m->normal[3 * i + (pr->role - ROLE_NX)] = f;
                break;
            }
            case ROLE_R:
            case ROLE_G:
            case ROLE_B: {
                /* uchar as is; floating-point colour is taken as [0, 1]. */
                double c = ply_type_is_int(pr->type) ? v : v * 255.0;
                c = isfinite(c) ? fmin(fmax(c, 0), 255) : 0;
                m->rgb[3 * i + (pr->role - ROLE_R)] = (uint8_t)lround(c);
                break;
            }
            default: break;
            }
        }
    }
    return BF_OK;
}

static bf_status ply_read_faces(ply_reader *rd, const ply_element *el, ply_tris *tris)
{
    for (uint64_t i = 0; i < el->count; i++) {
        for (int k = 0; k < el->n_props; k++) {
            const ply_prop *pr = &el->prop[k];
            bf_status s;
            if (pr->count_type == PLY_NONE) {
                s = ply_skip_values(rd, pr->type, 1, "face", i);
                if (s != BF_OK) return s;
                continue;
            }
            double cnt;
            s = ply_read_value(rd, pr->count_type, "face", i, &cnt);
            if (s != BF_OK) return s;
            if (cnt < 0)
                return bf_fail(BF_FORMAT, "%s: face %llu: negative vertex count %.0f", rd->path,
                               (unsigned long long)i, cnt);
            if (pr->role != ROLE_INDICES) {
                s = ply_skip_values(rd, pr->type, (uint64_t)cnt, "face", i);
                if (s != BF_OK) return s;
                continue;
            }
            /* Fan the polygon around its first vertex as it is read;
             * faces with fewer than three vertices carry no area and are
             * dropped. */
            uint64_t n = (uint64_t)cnt;
            if (rd->format != PLY_ASCII && n > (uint64_t)(rd->end - rd->p) / ply_type_size(pr->type))
                return bf_fail(BF_FORMAT, "%s: face %llu: %llu corners, file truncated", rd->path,
                               (unsigned long long)i, (unsigned long long)n);
            uint32_t first = 0, prev = 0;
            for (uint64_t j = 0; j < n; j++) {
                double v;
                s = ply_read_value(rd, pr->type, "face", i, &v);
                if (s != BF_OK) return s;
                if (v < 0 || v > (double)UINT32_MAX)
                    return bf_fail(BF_FORMAT, "%s: face %llu: corner %llu of %llu: vertex index %.0f out of range%s",
                                   rd->path, (unsigned long long)i, (unsigned long long)j + 1,
                                   (unsigned long long)n, v,
                                   n > 4 ? " (is the face's corner count right?)" : "");
                uint32_t cur = (uint32_t)v;
                if (j == 0)
                    first = cur;
                else if (j >= 2 && (s = ply_tris_push(tris, first, prev, cur)))
                    return s;
                prev = cur;
            }
        }
    }
    return BF_OK;
}

static bf_status ply_skip_element(ply_reader *rd, const ply_element *el)
{
    for (uint64_t i = 0; i < el->count; i++)
        for (int k = 0; k < el->n_props; k++) {
            const ply_prop *pr = &el->prop[k];
            uint64_t n = 1;
            if (pr->count_type != PLY_NONE) {
                double cnt;
                bf_status s = ply_read_value(rd, pr->count_type, el->name, i, &cnt);
                if (s != BF_OK) return s;
                if (cnt < 0)
                    return bf_fail(BF_FORMAT, "%s: %s %llu: negative list length", rd->path, el->name,
                                   (unsigned long long)i);
                n = (uint64_t)cnt;
            }
            bf_status s = ply_skip_values(rd, pr->type, n, el->name, i);
            if (s != BF_OK) return s;
        }
    return BF_OK;
}

/* Parses the header into elements; on success *body points past end_header. */
static bf_status ply_parse_header(const char *path, const uint8_t *data, size_t size, ply_format *fmt,
                                  ply_element *els, int *n_els, const uint8_t **body, size_t *body_line,
                                  bf_vec3 *origin)
{
    const uint8_t *p = data, *end = data + size;
    char line[512];
    size_t ln = 1;
    if (!ply_header_line(&p, end, line, sizeof line) || strcmp(line, "ply"))
        return bf_fail(BF_FORMAT, "%s: not a PLY file (no 'ply' magic)", path);
    bool have_format = false;
    int n = 0;
    for (;;) {
        ln++;
        if (!ply_header_line(&p, end, line, sizeof line))
            return bf_fail(BF_FORMAT, "%s: header has no end_header", path);
        char w0[64] = "", w1[64] = "", w2[64] = "", w3[64] = "", w4[64] = "";
        int nw = sscanf(line, "%63s %63s %63s %63s %63s", w0, w1, w2, w3, w4);
        /* The local origin of a mesh far from the world origin, as
         * mesh_write_ply records it; other comments are skipped. */
        double o[3];
        if (nw >= 5 && !strcmp(w0, "comment") && !strcmp(w1, "origin_w")) {
            if (!bf_parse_double(w2, &o[0]) || !bf_parse_double(w3, &o[1]) || !bf_parse_double(w4, &o[2]))
                return bf_fail(BF_FORMAT, "%s: line %zu: bad origin comment '%s'", path, ln, line);
            *origin = bf_v3(o[0], o[1], o[2]);
            continue;
        }
        if (nw <= 0 || !strcmp(w0, "comment") || !strcmp(w0, "obj_info")) continue;
        if (!strcmp(w0, "end_header")) break;
        if (!strcmp(w0, "format")) {
            if (nw < 3 || strcmp(w2, "1.0"))
                return bf_fail(BF_FORMAT, "%s: line %zu: unsupported format line '%s'", path, ln, line);
            if (!strcmp(w1, "ascii"))
                *fmt = PLY_ASCII;
            else if (!strcmp(w1, "binary_little_endian"))
                *fmt = PLY_BIN_LE;
            else if (!strcmp(w1, "binary_big_endian"))
                *fmt = PLY_BIN_BE;
            else
                return bf_fail(BF_FORMAT, "%s: line %zu: unknown format '%s'", path, ln, w1);
            have_format = true;
        } else if (!strcmp(w0, "element")) {
            if (nw != 3)
                return bf_fail(BF_FORMAT, "%s: line %zu: bad element line '%s'", path, ln, line);
            if (n == PLY_MAX_ELEMENTS)
                return bf_fail(BF_FORMAT, "%s: line %zu: more than %d elements", path, ln,
                               PLY_MAX_ELEMENTS);
            char *e;
            errno = 0;
            unsigned long long c = strtoull(w2, &e, 10);
            if (*e || w2[0] == '-' || errno)
                return bf_fail(BF_FORMAT, "%s: line %zu: bad element count '%s'", path, ln, w2);
            ply_element *el = &els[n++];
            memset(el, 0, sizeof *el);
            snprintf(el->name, sizeof el->name, "%s", w1);
            el->count = c;
            el->is_vertex = !strcmp(w1, "vertex");
            el->is_face = !strcmp(w1, "face");
        } else if (!strcmp(w0, "property")) {
            if (n == 0)
                return bf_fail(BF_FORMAT, "%s: line %zu: property before any element", path, ln);
            ply_element *el = &els[n - 1];
            if (el->n_props == PLY_MAX_PROPS)
                return bf_fail(BF_FORMAT, "%s: line %zu: more than %d properties", path, ln,
                               PLY_MAX_PROPS);
            ply_prop *pr = &el->prop[el->n_props++];
            const char *name;
            if (!strcmp(w1, "list")) {
                if (nw != 5)
                    return bf_fail(BF_FORMAT, "%s: line %zu: bad list property '%s'", path, ln, line);
                pr->count_type = ply_parse_type(w2);
                pr->type = ply_parse_type(w3);
                if (pr->count_type == PLY_NONE || pr->type == PLY_NONE ||
                    !ply_type_is_int(pr->count_type))
                    return bf_fail(BF_FORMAT, "%s: line %zu: bad list types in '%s'", path, ln, line);
                name = w4;
            } else {
                if (nw != 3)
                    return bf_fail(BF_FORMAT, "%s: line %zu: bad property line '%s'", path, ln, line);
                pr->type = ply_parse_type(w1);
                if (pr->type == PLY_NONE)
                    return bf_fail(BF_FORMAT, "%s: line %zu: unknown type '%s'", path, ln, w1);
                name = w2;
            }
            if (el->is_vertex && pr->count_type == PLY_NONE) pr->role = ply_vertex_role(name);
            if (el->is_face && pr->count_type != PLY_NONE &&
                (!strcmp(name, "vertex_indices") || !strcmp(name, "vertex_index"))) {
                if (!ply_type_is_int(pr->type))
                    return bf_fail(BF_FORMAT, "%s: line %zu: face indices must be integers", path, ln);
                pr->role = ROLE_INDICES;
            }
        } else {
            return bf_fail(BF_FORMAT, "%s: line %zu: unknown header keyword '%s'", path, ln, w0);
        }
    }
    if (!have_format) return bf_fail(BF_FORMAT, "%s: header has no format line", path);
    *n_els = n;
    *body = p;
    *body_line = ln + 1;
    return BF_OK;
}

bf_status mesh_read_ply(const char *path, mesh_data *out)
{
    char *data = NULL;
    size_t size = 0;
    bf_status s = bf_read_file(path, &data, &size);
    if (s != BF_OK) return s;

    ply_format fmt = PLY_ASCII;
    ply_element *els = bf_calloc(PLY_MAX_ELEMENTS, sizeof *els);
    mesh_data m = {0};
    ply_tris tris = {0};
    if (!els) {
        s = bf_fail(BF_NO_MEMORY, "%s: out of memory", path);
        goto fail;
    }
    int n_els = 0;
    const uint8_t *body;
    size_t body_line;
    s = ply_parse_header(path, (const uint8_t *)data, size, &fmt, els, &n_els, &body, &body_line, &m.origin);
    if (s != BF_OK) goto fail;

    /* Check the header before touching the body. */
    const ply_element *vel = NULL;
    int n_faces_els = 0;
    for (int e = 0; e < n_els; e++) {
        const ply_element *el = &els[e];
        if (el->count > 0 && el->n_props == 0) {
            s = bf_fail(BF_FORMAT, "%s: element %s has %llu items but no properties", path, el->name,
                        (unsigned long long)el->count);
            goto fail;
        }
        size_t left = size - (size_t)(body - (const uint8_t *)data);
        size_t min = ply_min_item_bytes(el, fmt);
        if (min > 0 && el->count > left / min) {
            s = bf_fail(BF_FORMAT, "%s: element %s claims %llu items, more than the %zu bytes left can hold",
                        path, el->name, (unsigned long long)el->count, left);
            goto fail;
        }
        if (el->is_vertex) {
            if (vel) {
                s = bf_fail(BF_FORMAT, "%s: two vertex elements", path);
                goto fail;
            }
            vel = el;
        }
        if (el->is_face) n_faces_els++;
    }
    if (!vel) {
        s = bf_fail(BF_FORMAT, "%s: no vertex element", path);
        goto fail;
    }
    if (n_faces_els > 1) {
        s = bf_fail(BF_FORMAT, "%s: two face elements", path);
        goto fail;
    }
    if (vel->count > UINT32_MAX) {
        s = bf_fail(BF_FORMAT, "%s: %llu vertices (at most 2^32-1)", path, (unsigned long long)vel->count);
        goto fail;
    }
    unsigned have = 0;
    for (int k = 0; k < vel->n_props; k++)
        if (vel->prop[k].role != ROLE_SKIP) {
            if (have & (1u << vel->prop[k].role)) {
                s = bf_fail(BF_FORMAT, "%s: vertex property repeated", path);
                goto fail;
            }
            have |= 1u << vel->prop[k].role;
        }
    unsigned xyz = 1u << ROLE_X | 1u << ROLE_Y | 1u << ROLE_Z;
    unsigned nrm = 1u << ROLE_NX | 1u << ROLE_NY | 1u << ROLE_NZ;
    unsigned rgb = 1u << ROLE_R | 1u << ROLE_G | 1u << ROLE_B;
    if ((have & xyz) != xyz) {
        s = bf_fail(BF_FORMAT, "%s: vertex element lacks x, y or z", path);
        goto fail;
    }
    m.n_verts = (uint32_t)vel->count;
    size_t nv = (size_t)m.n_verts;
    m.xyz = bf_malloc((nv ? nv : 1) * 3 * sizeof *m.xyz);
    if ((have & nrm) == nrm) m.normal = bf_malloc((nv ? nv : 1) * 3 * sizeof *m.normal);
    if ((have & rgb) == rgb) m.rgb = bf_malloc((nv ? nv : 1) * 3);
    if (!m.xyz || ((have & nrm) == nrm && !m.normal) || ((have & rgb) == rgb && !m.rgb)) {
        s = bf_fail(BF_NO_MEMORY, "%s: out of memory for %u vertices", path, m.n_verts);
        goto fail;
    }
    /* A partial set of normal or colour channels is ignored. */
    for (int k = 0; k < vel->n_props; k++) {
        ply_prop *pr = &els[vel - els].prop[k];
        if ((pr->role >= ROLE_NX && pr->role <= ROLE_NZ && !m.normal) ||
            (pr->role >= ROLE_R && pr->role <= ROLE_B && !m.rgb))
            pr->role = ROLE_SKIP;
    }

    ply_reader rd = {.path = path, .base = (const uint8_t *)data, .p = body, .end = (const uint8_t *)data + size, .format = fmt,
                     .line = body_line};
    double shift[3] = {0, 0, 0};
    for (int e = 0; e < n_els; e++) {
        const ply_element *el = &els[e];
        if (el->is_vertex)
            s = ply_read_vertices(&rd, el, &m, shift);
        else if (el->is_face)
            s = ply_read_faces(&rd, el, &tris);
        else
            s = ply_skip_element(&rd, el);
        if (s != BF_OK) goto fail;
    }
    for (size_t i = 0; i < 3 * tris.n; i++)
        if (tris.v[i] >= m.n_verts) {
            s = bf_fail(BF_FORMAT, "%s: face element: triangle %zu uses vertex %u of %u", path, i / 3,
                        tris.v[i], m.n_verts);
            goto fail;
        }
    if (tris.n > UINT32_MAX) {
        s = bf_fail(BF_FORMAT, "%s: %zu triangles (at most 2^32-1)", path, tris.n);
        goto fail;
    }
    m.n_tris = (uint32_t)tris.n;
    m.tri = tris.v; /* NULL when there are no triangles */
    m.origin = bf_v3(m.origin.x + shift[0], m.origin.y + shift[1], m.origin.z + shift[2]);
    free(els);
    free(data);
    *out = m;
    return BF_OK;

fail:
    free(tris.v);
    mesh_free(&m);
    free(els);
    free(data);
    return s;
}

/* ------------------------------------------------------------ writing */

bf_status mesh_write_ply(const char *path, const mesh_data *m)
{
    bf_status s = mesh__check(path, m);
    if (s != BF_OK) return s;
    /* %.17g: a double survives the round trip through text. */
    char origin[160] = "";
    if (mesh__has_origin(m))
        snprintf(origin, sizeof origin, "comment origin_w %.17g %.17g %.17g\n", m->origin.x, m->origin.y, m->origin.z);
    bf_out o;
    if ((s = bf_out_open(&o, path)) != BF_OK) return s;
    bf_out_printf(&o,
                     "ply\nformat binary_little_endian 1.0\ncomment written by bitfuse\n%s"
                     "element vertex %u\nproperty float x\nproperty float y\nproperty float z\n%s%s"
                     "element face %u\nproperty list uchar int vertex_indices\nend_header\n",
                     origin, m->n_verts,
                     m->normal ? "property float nx\nproperty float ny\nproperty float nz\n" : "",
                     m->rgb ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "", m->n_tris);
    uint8_t rec[32];
    for (size_t i = 0; i < m->n_verts; i++) {
        uint8_t *p = rec;
        for (int k = 0; k < 3; k++) p = mesh__put_f32(p, m->xyz[3 * i + k]);
        if (m->normal)
            for (int k = 0; k < 3; k++) p = mesh__put_f32(p, m->normal[3 * i + k]);
        if (m->rgb)
            for (int k = 0; k < 3; k++) *p++ = m->rgb[3 * i + k];
        bf_out_write(&o, rec, (size_t)(p - rec));
    }
    for (size_t i = 0; i < m->n_tris; i++) {
        uint8_t *p = rec;
        *p++ = 3;
        for (int k = 0; k < 3; k++) p = mesh__put_u32(p, m->tri[3 * i + k]);
        bf_out_write(&o, rec, (size_t)(p - rec));
    }
    return bf_out_commit(&o);
}

void mesh_free(mesh_data *m)
{
    if (!m) return;
    free(m->xyz);
    free(m->normal);
    free(m->rgb);
    free(m->tri);
    memset(m, 0, sizeof *m);
}

/* ------------------------------------------------------------ appending */

bf_status mesh_append(mesh_data *dst, const mesh_data *src, const bf_se3 *T)
{
    if ((uint64_t)dst->n_verts + src->n_verts > UINT32_MAX ||
        (uint64_t)dst->n_tris + src->n_tris > UINT32_MAX)
        return bf_fail(BF_INVALID_ARG, "mesh append: more than 2^32-1 vertices or triangles");
    size_t nv = (size_t)dst->n_verts + src->n_verts, nt = (size_t)dst->n_tris + src->n_tris;
    /* An empty destination takes the source's attributes; otherwise an
     * attribute either side has is kept, the other side's filled with zero
     * normals (unknown) or white. */
    bool is_empty = dst->n_verts == 0;
    bool has_normal = is_empty ? src->normal != NULL : (dst->normal || src->normal);
    bool has_rgb = is_empty ? src->rgb != NULL : (dst->rgb || src->rgb);
    size_t alloc_v = nv ? nv : 1, alloc_t = nt ? nt : 1;
    float *xyz = bf_malloc(alloc_v * 3 * sizeof *xyz);
    float *normal = has_normal ? bf_malloc(alloc_v * 3 * sizeof *normal) : NULL;
    uint8_t *rgb = has_rgb ? bf_malloc(alloc_v * 3) : NULL;
    uint32_t *tri = bf_malloc(alloc_t * 3 * sizeof *tri);
    if (!xyz || !tri || (has_normal && !normal) || (has_rgb && !rgb)) {
        free(xyz);
        free(normal);
        free(rgb);
        free(tri);
        return bf_fail(BF_NO_MEMORY, "mesh append: out of memory for %zu vertices", nv);
    }
    size_t n0 = dst->n_verts;
    if (n0) memcpy(xyz, dst->xyz, n0 * 3 * sizeof *xyz);
    if (dst->n_tris) memcpy(tri, dst->tri, (size_t)dst->n_tris * 3 * sizeof *tri);
    if (normal) {
        if (dst->normal && n0)
            memcpy(normal, dst->normal, n0 * 3 * sizeof *normal);
        else
            memset(normal, 0, n0 * 3 * sizeof *normal);
    }
    if (rgb) {
        if (dst->rgb && n0)
            memcpy(rgb, dst->rgb, n0 * 3);
        else
            memset(rgb, 255, n0 * 3);
    }
    bf_se3 I = bf_se3_identity();
    if (!T) T = &I;
    /* In double: world point T * (src.origin + xyz), less dst's origin. An
     * empty dst takes T * src.origin, so a far mesh stays local. */
    bf_vec3 origin = is_empty ? bf_se3_apply(T, src->origin) : dst->origin;
    for (size_t i = 0; i < src->n_verts; i++) {
        bf_vec3 p = bf_se3_apply(T, bf_v3(src->origin.x + src->xyz[3 * i], src->origin.y + src->xyz[3 * i + 1],
                                          src->origin.z + src->xyz[3 * i + 2]));
        p = bf_v3(p.x - origin.x, p.y - origin.y, p.z - origin.z);
        float *o = &xyz[3 * (n0 + i)];
        o[0] = (float)p.x;
        o[1] = (float)p.y;
        o[2] = (float)p.z;
        if (normal) {
            float *on = &normal[3 * (n0 + i)];
            if (src->normal) {
                bf_vec3 n = bf_se3_rotate(T, bf_v3(src->normal[3 * i], src->normal[3 * i + 1],
                                                   src->normal[3 * i + 2]));
                on[0] = (float)n.x;
                on[1] = (float)n.y;
                on[2] = (float)n.z;
            } else {
                on[0] = on[1] = on[2] = 0;
            }
        }
        if (rgb) {
            uint8_t *oc = &rgb[3 * (n0 + i)];
            if (src->rgb)
                memcpy(oc, &src->rgb[3 * i], 3);
            else
                oc[0] = oc[1] = oc[2] = 255;
        }
    }
    for (size_t i = 0; i < 3 * (size_t)src->n_tris; i++) tri[3 * (size_t)dst->n_tris + i] = (uint32_t)(src->tri[i] + n0);
    mesh_free(dst);
    dst->n_verts = (uint32_t)nv;
    dst->n_tris = (uint32_t)nt;
    dst->xyz = xyz;
    dst->normal = normal;
    dst->rgb = rgb;
    dst->tri = tri;
    dst->origin = origin;
    return BF_OK;
}
