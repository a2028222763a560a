/* mesh: the writers (PLY, OBJ + MTL, glTF binary) read back, their atomic
 * failure paths, and simplification through meshoptimizer. */
#include <cjson/cJSON.h>
#include <signal.h>
#include <stdint.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <dirent.h>

#include "fixture.h"
#include "mesh/mesh.h"
#include "test.h"

static void tmp_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", bf_test_tmpdir(), name); }

static bool file_exists(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0;
}

/* Files in dir whose name contains ".tmp.": a writer's leftovers. */
static int count_temp_files(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return 0;
    int n = 0;
    for (struct dirent *e; (e = readdir(d));) n += strstr(e->d_name, ".tmp.") != NULL;
    closedir(d);
    return n;
}

BF_TEST(format_is_chosen_by_extension_or_name)
{
    mesh_format f;
    CHECK_OK(mesh_format_of_path("a/b/room.PLY", &f));
    CHECK_EQ_INT(f, MESH_FORMAT_PLY);
    CHECK_OK(mesh_format_of_path("room.obj", &f));
    CHECK_EQ_INT(f, MESH_FORMAT_OBJ);
    CHECK_OK(mesh_format_of_path("./x.y/room.glb", &f));
    CHECK_EQ_INT(f, MESH_FORMAT_GLB);
    CHECK_STATUS(mesh_format_of_path("room.gltf", &f), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("room.gltf");
    CHECK_STATUS(mesh_format_of_path("dir.ply/room", &f), BF_INVALID_ARG);
    CHECK(mesh_format_parse("GLB", &f) && f == MESH_FORMAT_GLB);
    CHECK(!mesh_format_parse("stl", &f));
    CHECK(!strcmp(mesh_format_name(MESH_FORMAT_OBJ), "obj"));
}

BF_TEST(ply_round_trip_keeps_positions_normals_colours_and_origin)
{
    mesh_data m, r;
    fx_uv_sphere(&m, 0.5, bf_v3(0.1, -0.2, 0.3), 20, 30);
    m.origin = bf_v3(10000.125, -2500.5, 3.0e-3);
    char path[512];
    tmp_path(path, sizeof path, "rt.ply");
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &r));
    CHECK_EQ_INT(r.n_verts, m.n_verts);
    CHECK_EQ_INT(r.n_tris, m.n_tris);
    CHECK(r.normal && r.rgb);
    CHECK(!memcmp(r.xyz, m.xyz, 3 * sizeof(float) * m.n_verts));
    CHECK(!memcmp(r.normal, m.normal, 3 * sizeof(float) * m.n_verts));
    CHECK(!memcmp(r.rgb, m.rgb, 3 * (size_t)m.n_verts));
    CHECK(!memcmp(r.tri, m.tri, 3 * sizeof(uint32_t) * m.n_tris));
    /* Exactly: printed with 17 digits. */
    CHECK(r.origin.x == m.origin.x && r.origin.y == m.origin.y && r.origin.z == m.origin.z);
    mesh_free(&r);
    mesh_free(&m);
    CHECK_EQ_INT(count_temp_files(bf_test_tmpdir()), 0);
}

/* ------------------------------------------------------------ OBJ */

typedef struct obj_read {
    uint32_t n_v, n_vn, n_f, n_p; /* n_p: the vertices p elements name, each in order */
    float *v;    /* 6 per vertex: x y z r g b (colour -1 when absent) */
    float *vn;   /* 3 per normal */
    uint32_t *f; /* 6 per face: v, vn of each corner (1-based, vn 0 when absent) */
    char mtllib[256];
    bool has_origin;
    double origin[3];
} obj_read;

/* A reader for exactly what mesh_write_obj writes (v, vn, f a//a, p, mtllib,
 * usemtl, comments), kept apart from the writer so the two check each
 * other. */
static bool obj_parse(const char *path, obj_read *o)
{
    memset(o, 0, sizeof *o);
    char *data;
    size_t size;
    if (bf_read_file(path, &data, &size) != BF_OK) return false;
    size_t lines = 1;
    for (size_t i = 0; i < size; i++) lines += data[i] == '\n';
    o->v = malloc(6 * sizeof(float) * lines);
    o->vn = malloc(3 * sizeof(float) * lines);
    o->f = malloc(6 * sizeof(uint32_t) * lines);
    bool ok = o->v && o->vn && o->f;
    for (char *save = NULL, *l = strtok_r(data, "\n", &save); ok && l; l = strtok_r(NULL, "\n", &save)) {
        float a[6] = {0, 0, 0, -1, -1, -1};
        if (!strncmp(l, "v ", 2)) {
            int n = sscanf(l + 2, "%f %f %f %f %f %f", &a[0], &a[1], &a[2], &a[3], &a[4], &a[5]);
            ok = n == 3 || n == 6;
            memcpy(&o->v[6 * o->n_v++], a, sizeof a);
        } else if (!strncmp(l, "vn ", 3)) {
            ok = sscanf(l + 3, "%f %f %f", &a[0], &a[1], &a[2]) == 3;
            memcpy(&o->vn[3 * o->n_vn++], a, 3 * sizeof(float));
        } else if (!strncmp(l, "f ", 2)) {
            uint32_t *f = &o->f[6 * o->n_f++];
            memset(f, 0, 6 * sizeof *f);
            if (sscanf(l + 2, "%u//%u %u//%u %u//%u", &f[0], &f[1], &f[2], &f[3], &f[4], &f[5]) != 6)
                ok = sscanf(l + 2, "%u %u %u", &f[0], &f[2], &f[4]) == 3;
        } else if (!strncmp(l, "p ", 2)) {
            /* Point elements: every index the next vertex in order. */
            for (char *q = l + 1; ok && *q;) {
                char *end;
                unsigned long k = strtoul(q, &end, 10);
                if (end == q) break;
                ok = k == o->n_p + 1;
                o->n_p++, q = end;
            }
        } else if (!strncmp(l, "mtllib ", 7)) {
            snprintf(o->mtllib, sizeof o->mtllib, "%s", l + 7);
        } else if (!strncmp(l, "# origin_w ", 11)) {
            o->has_origin = sscanf(l + 11, "%lf %lf %lf", &o->origin[0], &o->origin[1], &o->origin[2]) == 3;
        } else {
            ok = l[0] == '#' || !strncmp(l, "usemtl ", 7);
        }
    }
    free(data);
    return ok;
}

static void obj_free(obj_read *o) { free(o->v), free(o->vn), free(o->f); }

BF_TEST(obj_round_trip_keeps_positions_colours_normals_faces_and_names_its_material)
{
    mesh_data m;
    fx_uv_sphere(&m, 0.5, bf_v3(0.1, -0.2, 0.3), 20, 30);
    m.origin = bf_v3(-5000.25, 0, 12.5);
    char path[512], mtl[512];
    tmp_path(path, sizeof path, "rt.obj");
    tmp_path(mtl, sizeof mtl, "rt.mtl");
    CHECK_OK(mesh_write_obj(path, &m));
    CHECK(file_exists(mtl));
    obj_read o;
    CHECK(obj_parse(path, &o));
    CHECK(!strcmp(o.mtllib, "rt.mtl"));
    CHECK(o.has_origin && o.origin[0] == m.origin.x && o.origin[2] == m.origin.z);
    CHECK_EQ_INT(o.n_v, m.n_verts);
    CHECK_EQ_INT(o.n_vn, m.n_verts);
    CHECK_EQ_INT(o.n_f, m.n_tris);
    for (uint32_t i = 0; i < m.n_verts; i++) {
        /* Positions to 1e-6 m (6 decimals) plus a float's step at 0.8 m;
         * colours to 4 decimals, which round back to the same byte. */
        for (int k = 0; k < 3; k++) CHECK_NEAR(o.v[6 * i + k], m.xyz[3 * i + k], 0.5e-6 + 1e-7);
        for (int k = 0; k < 3; k++) CHECK_EQ_INT(lroundf(o.v[6 * i + 3 + k] * 255), m.rgb[3 * i + k]);
        for (int k = 0; k < 3; k++) CHECK_NEAR(o.vn[3 * i + k], m.normal[3 * i + k], 0.5e-4 + 1e-7);
    }
    for (uint32_t t = 0; t < m.n_tris; t++)
        for (int k = 0; k < 3; k++) {
            CHECK_EQ_INT(o.f[6 * t + 2 * k], m.tri[3 * t + k] + 1);
            CHECK_EQ_INT(o.f[6 * t + 2 * k + 1], m.tri[3 * t + k] + 1);
        }
    obj_free(&o);

    /* A point cloud: vertices and the point elements naming each once, no
     * material. */
    mesh_data p = {.n_verts = m.n_verts, .xyz = m.xyz};
    tmp_path(path, sizeof path, "pts.obj");
    tmp_path(mtl, sizeof mtl, "pts.mtl");
    CHECK_OK(mesh_write_obj(path, &p));
    CHECK(!file_exists(mtl));
    CHECK(obj_parse(path, &o));
    CHECK_EQ_INT(o.n_v, m.n_verts);
    CHECK_EQ_INT(o.n_vn + o.n_f, 0);
    CHECK_EQ_INT(o.n_p, m.n_verts);
    CHECK(o.v[3] == -1); /* no colour */
    obj_free(&o);
    mesh_free(&m);
}

/* ------------------------------------------------------------ glTF binary */

static uint32_t rd_u32(const uint8_t *p) { return p[0] | p[1] << 8 | p[2] << 16 | (uint32_t)p[3] << 24; }
static float rd_f32(const uint8_t *p)
{
    uint32_t b = rd_u32(p);
    float f;
    memcpy(&f, &b, 4);
    return f;
}

/* A parsed .glb: the JSON and the BIN chunk, after the checks the format
 * makes (header, chunk types, lengths, 4-byte alignment). */
typedef struct glb_read {
    char *file;
    size_t size;
    cJSON *json;
    const uint8_t *bin;
    uint32_t bin_len;
} glb_read;

static bool glb_parse(const char *path, glb_read *g)
{
    memset(g, 0, sizeof *g);
    if (bf_read_file(path, &g->file, &g->size) != BF_OK || g->size < 20) return false;
    const uint8_t *p = (const uint8_t *)g->file;
    if (rd_u32(p) != 0x46546C67u || rd_u32(p + 4) != 2 || rd_u32(p + 8) != g->size || g->size % 4) return false;
    uint32_t json_len = rd_u32(p + 12);
    if (rd_u32(p + 16) != 0x4E4F534Au || json_len % 4 || 20 + (size_t)json_len > g->size) return false;
    g->json = cJSON_ParseWithLength((const char *)p + 20, json_len);
    if (!g->json) return false;
    size_t at = 20 + (size_t)json_len;
    if (at == g->size) return true; /* no BIN chunk: an empty mesh */
    if (at + 8 > g->size) return false;
    g->bin_len = rd_u32(p + at);
    if (rd_u32(p + at + 4) != 0x004E4942u || g->bin_len % 4 || at + 8 + g->bin_len != g->size) return false;
    g->bin = p + at + 8;
    return true;
}

static void glb_free(glb_read *g)
{
    cJSON_Delete(g->json);
    free(g->file);
}

static double jnum(const cJSON *o, const char *name)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
    return cJSON_IsNumber(v) ? v->valuedouble : NAN;
}

/* Accessor k's data: its bytes in BIN after checking its view's bounds and
 * alignment. */
static const uint8_t *glb_accessor(const glb_read *g, int k, int *component, int *count, const char **type)
{
    const cJSON *acc = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g->json, "accessors"), k);
    if (!acc) return NULL;
    const cJSON *view = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g->json, "bufferViews"),
                                           (int)jnum(acc, "bufferView"));
    if (!view || jnum(view, "buffer") != 0) return NULL;
    double off = jnum(view, "byteOffset"), len = jnum(view, "byteLength");
    *component = (int)jnum(acc, "componentType");
    *count = (int)jnum(acc, "count");
    *type = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(acc, "type"));
    int n_comp = !strcmp(*type, "VEC3") ? 3 : 1;
    if (fmod(off, 4) != 0 || off + len > g->bin_len || len != 4.0 * n_comp * *count) return NULL;
    return g->bin + (size_t)off;
}

static double linear_of(uint8_t c)
{
    double v = c / 255.0;
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

BF_TEST(glb_is_well_formed_and_holds_the_mesh)
{
    mesh_data m;
    fx_uv_sphere(&m, 0.5, bf_v3(0.1, -0.2, 0.3), 20, 30);
    m.origin = bf_v3(10000.125, -2500.5, 0.75);
    m.normal[0] = m.normal[1] = m.normal[2] = 0; /* a degenerate vertex's normal */
    char path[512];
    tmp_path(path, sizeof path, "rt.glb");
    CHECK_OK(mesh_write_glb(path, &m));
    glb_read g;
    CHECK(glb_parse(path, &g));
    const cJSON *asset = cJSON_GetObjectItemCaseSensitive(g.json, "asset");
    CHECK(!strcmp(cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(asset, "version")), "2.0"));
    const cJSON *node = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g.json, "nodes"), 0);
    const cJSON *tr = cJSON_GetObjectItemCaseSensitive(node, "translation");
    CHECK(cJSON_GetArraySize(tr) == 3);
    CHECK(cJSON_GetArrayItem(tr, 0)->valuedouble == m.origin.x && cJSON_GetArrayItem(tr, 1)->valuedouble == m.origin.y &&
          cJSON_GetArrayItem(tr, 2)->valuedouble == m.origin.z);
    const cJSON *prim = cJSON_GetArrayItem(
        cJSON_GetObjectItemCaseSensitive(cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g.json, "meshes"), 0),
                                         "primitives"),
        0);
    CHECK_EQ_INT(jnum(prim, "mode"), 4);
    const cJSON *attr = cJSON_GetObjectItemCaseSensitive(prim, "attributes");
    int comp, count;
    const char *type;
    /* POSITION: the floats as given, min/max exactly theirs. */
    const uint8_t *pos = glb_accessor(&g, (int)jnum(attr, "POSITION"), &comp, &count, &type);
    CHECK(pos && comp == 5126 && count == (int)m.n_verts && !strcmp(type, "VEC3"));
    const cJSON *acc = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g.json, "accessors"), (int)jnum(attr, "POSITION"));
    const cJSON *jmin = cJSON_GetObjectItemCaseSensitive(acc, "min"), *jmax = cJSON_GetObjectItemCaseSensitive(acc, "max");
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < count; i++)
        for (int k = 0; k < 3; k++) {
            float v = rd_f32(pos + 12 * i + 4 * k);
            CHECK(v == m.xyz[3 * i + k]);
            lo[k] = fminf(lo[k], v), hi[k] = fmaxf(hi[k], v);
        }
    for (int k = 0; k < 3; k++) {
        CHECK((float)cJSON_GetArrayItem(jmin, k)->valuedouble == lo[k]);
        CHECK((float)cJSON_GetArrayItem(jmax, k)->valuedouble == hi[k]);
    }
    /* NORMAL: unit, equal to the input where it was unit. */
    const uint8_t *nrm = glb_accessor(&g, (int)jnum(attr, "NORMAL"), &comp, &count, &type);
    CHECK(nrm && comp == 5126 && count == (int)m.n_verts);
    for (int i = 0; i < count; i++) {
        double l2 = 0;
        for (int k = 0; k < 3; k++) l2 += pow(rd_f32(nrm + 12 * i + 4 * k), 2);
        CHECK_NEAR(l2, 1, 1e-5);
        if (i > 0)
            for (int k = 0; k < 3; k++) CHECK_NEAR(rd_f32(nrm + 12 * i + 4 * k), m.normal[3 * i + k], 1e-6);
    }
    /* COLOR_0: linear float of the sRGB bytes. */
    const uint8_t *col = glb_accessor(&g, (int)jnum(attr, "COLOR_0"), &comp, &count, &type);
    CHECK(col && comp == 5126 && count == (int)m.n_verts);
    for (int i = 0; i < count; i++)
        for (int k = 0; k < 3; k++) CHECK_NEAR(rd_f32(col + 12 * i + 4 * k), linear_of(m.rgb[3 * i + k]), 1e-6);
    /* Indices: uint32, the triangles as given. */
    const uint8_t *idx = glb_accessor(&g, (int)jnum(prim, "indices"), &comp, &count, &type);
    CHECK(idx && comp == 5125 && count == 3 * (int)m.n_tris && !strcmp(type, "SCALAR"));
    for (int i = 0; i < count; i++) CHECK_EQ_INT(rd_u32(idx + 4 * i), m.tri[i]);
    glb_free(&g);

    /* A point cloud: mode POINTS, no indices. */
    mesh_data p = {.n_verts = m.n_verts, .xyz = m.xyz};
    tmp_path(path, sizeof path, "pts.glb");
    CHECK_OK(mesh_write_glb(path, &p));
    CHECK(glb_parse(path, &g));
    prim = cJSON_GetArrayItem(
        cJSON_GetObjectItemCaseSensitive(cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g.json, "meshes"), 0),
                                         "primitives"),
        0);
    CHECK_EQ_INT(jnum(prim, "mode"), 0);
    CHECK(!cJSON_HasObjectItem(prim, "indices"));
    CHECK(!cJSON_HasObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(g.json, "nodes"), 0), "translation"));
    glb_free(&g);
    mesh_free(&m);
}

BF_TEST(empty_mesh_writes_valid_empty_files)
{
    mesh_data e = {0};
    char path[512];
    static const char *names[] = {"empty.ply", "empty.obj", "empty.glb"};
    for (int k = 0; k < 3; k++) {
        mesh_format f;
        tmp_path(path, sizeof path, names[k]);
        CHECK_OK(mesh_format_of_path(path, &f));
        CHECK_OK(mesh_write(path, f, &e));
        CHECK(file_exists(path));
    }
    mesh_data r;
    tmp_path(path, sizeof path, "empty.ply");
    CHECK_OK(mesh_read_ply(path, &r));
    CHECK_EQ_INT(r.n_verts + r.n_tris, 0);
    mesh_free(&r);
    glb_read g;
    tmp_path(path, sizeof path, "empty.glb");
    CHECK(glb_parse(path, &g));
    CHECK(g.bin == NULL);
    glb_free(&g);
}

/* A write that fails halfway (the file size limit, as a full disk would)
 * leaves the old file as it was and no temporary file, in every format. */
BF_TEST(failed_write_keeps_the_old_file_and_leaves_no_temporary)
{
    mesh_data m;
    fx_uv_sphere(&m, 0.5, bf_v3(0, 0, 0), 100, 200); /* about 1 MB in every format */
    char dir[512], path[600];
    tmp_path(dir, sizeof dir, "fail");
    CHECK_OK(bf_mkdir_p(dir));
    static const char *names[] = {"m.ply", "m.obj", "m.glb"};
    struct rlimit old;
    CHECK(getrlimit(RLIMIT_FSIZE, &old) == 0);
    void (*old_handler)(int) = signal(SIGXFSZ, SIG_IGN); /* write() then fails with EFBIG */
    for (int k = 0; k < 3; k++) {
        mesh_format f;
        snprintf(path, sizeof path, "%s/%s", dir, names[k]);
        CHECK_OK(mesh_format_of_path(path, &f));
        FILE *fp = fopen(path, "w");
        CHECK(fp);
        fputs("old", fp);
        fclose(fp);
        struct rlimit lim = {64 * 1024, old.rlim_max};
        CHECK(setrlimit(RLIMIT_FSIZE, &lim) == 0);
        bf_status s = mesh_write(path, f, &m);
        CHECK(setrlimit(RLIMIT_FSIZE, &old) == 0);
        CHECK_EQ_INT(s, BF_WRITE);
        CHECK_ERROR_MENTIONS(path);
        char *data;
        size_t size;
        CHECK_OK(bf_read_file(path, &data, &size));
        CHECK(size == 3 && !memcmp(data, "old", 3));
        free(data);
        CHECK_EQ_INT(count_temp_files(dir), 0);
    }
    signal(SIGXFSZ, old_handler);
    /* The failed OBJ made no material beside it (the two are renamed together). */
    snprintf(path, sizeof path, "%s/m.mtl", dir);
    CHECK(!file_exists(path));
    /* A folder that does not exist: BF_WRITE naming it, nothing made. */
    snprintf(path, sizeof path, "%s/no/such/dir/m.glb", dir);
    CHECK_STATUS(mesh_write_glb(path, &m), BF_WRITE);
    CHECK_ERROR_MENTIONS("no/such/dir");
    /* An index out of range: refused before anything is written. */
    m.tri[5] = m.n_verts;
    snprintf(path, sizeof path, "%s/bad.obj", dir);
    CHECK_STATUS(mesh_write_obj(path, &m), BF_INVALID_ARG);
    CHECK(!file_exists(path));
    mesh_free(&m);
}

BF_TEST(append_keeps_a_far_mesh_local)
{
    mesh_data a, b = {0};
    fx_uv_sphere(&a, 0.5, bf_v3(0, 0, 0), 4, 6);
    a.origin = bf_v3(10000, 0, 0);
    CHECK_OK(mesh_append(&b, &a, NULL));
    CHECK(b.origin.x == 10000);
    CHECK_OK(mesh_append(&b, &a, NULL));
    CHECK_EQ_INT(b.n_verts, 2 * a.n_verts);
    for (uint32_t i = 0; i < a.n_verts; i++)
        for (int k = 0; k < 3; k++) CHECK(b.xyz[3 * (a.n_verts + i) + k] == a.xyz[3 * i + k]);
    mesh_free(&a);
    mesh_free(&b);
}

/* ------------------------------------------------------------ simplification */

/* The largest distance from a vertex of s to the sphere: a sphere's chord
 * error is known, so no reference mesh is needed. */
static double sphere_dev_max(const mesh_data *s, bf_vec3 c, double r)
{
    double d = 0;
    for (uint32_t i = 0; i < s->n_verts; i++)
        d = fmax(d, fabs(bf_v3_norm(bf_v3(s->xyz[3 * i] - c.x, s->xyz[3 * i + 1] - c.y, s->xyz[3 * i + 2] - c.z)) - r));
    return d;
}

/* The largest distance from a triangle's centroid to the sphere. */
static double sphere_chord_max(const mesh_data *s, bf_vec3 c, double r)
{
    double d = 0;
    for (uint32_t t = 0; t < s->n_tris; t++) {
        double p[3] = {0, 0, 0};
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++) p[a] += s->xyz[3 * (size_t)s->tri[3 * t + k] + a] / 3.0;
        d = fmax(d, fabs(bf_v3_norm(bf_v3(p[0] - c.x, p[1] - c.y, p[2] - c.z)) - r));
    }
    return d;
}

BF_TEST(simplify_meets_the_cap_and_keeps_each_vertex_with_its_attributes)
{
    mesh_data full, m;
    bf_vec3 c = bf_v3(0.2, 0.1, -0.3);
    fx_uv_sphere(&full, 1.0, c, 150, 300); /* 90,000 triangles */
    fx_uv_sphere(&m, 1.0, c, 150, 300);
    mesh_simplify_config cfg = {.max_triangles = 5000};
    mesh_simplify_stats st;
    CHECK_OK(mesh_simplify(&m, &cfg, &st));
    CHECK_EQ_INT(st.tris_before, full.n_tris);
    CHECK_LE(m.n_tris, 5000);
    CHECK(m.n_tris >= 4000); /* it got near the cap, not far below */
    CHECK_EQ_INT(st.tris_after, m.n_tris);
    CHECK_EQ_INT(st.verts_after, m.n_verts);
    CHECK(!st.used_sloppy);
    /* Every vertex is one of the input's, with its normal and colour (the
     * colour encodes the input index), and every vertex is used. */
    uint8_t *used = calloc(m.n_verts, 1);
    for (uint32_t i = 0; i < 3 * m.n_tris; i++) used[m.tri[i]] = 1;
    for (uint32_t i = 0; i < m.n_verts; i++) {
        uint32_t v = m.rgb[3 * i] | m.rgb[3 * i + 1] << 8 | (uint32_t)m.rgb[3 * i + 2] << 16;
        CHECK(v < full.n_verts);
        CHECK(!memcmp(&m.xyz[3 * i], &full.xyz[3 * (size_t)v], 3 * sizeof(float)));
        CHECK(!memcmp(&m.normal[3 * i], &full.normal[3 * (size_t)v], 3 * sizeof(float)));
        CHECK(used[i]);
    }
    free(used);
    /* Chord error of N triangles on a unit sphere: area 4 pi / N each, an
     * equilateral one of that area has edge a = sqrt(4 A / sqrt 3) and
     * lies at most a^2 / 6 inside the sphere (its circumradius a / sqrt 3
     * squared over 2 r): 1.0 mm for N = 5000. meshoptimizer's triangles
     * are not equilateral: its estimate stays within 3x that. The quadrics
     * bound the vertices' distance to the input's planes (vertices stay on
     * the sphere); a flat triangle between them bulges inside by its own
     * chord on top: the triangles' centres (near their farthest point)
     * stay within twice the estimate plus the input's own chord error. */
    CHECK_LE(sphere_dev_max(&m, c, 1.0), 1e-6);
    double a = sqrt(4 * (4 * M_PI / 5000) / sqrt(3.0)), chord = a * a / 6;
    double before = sphere_chord_max(&full, c, 1.0);
    printf("  sphere 1 m: %u -> %u triangles (estimate %.3g mm, centroid max %.3g mm, equilateral chord %.3g mm)\n",
           full.n_tris, m.n_tris, 1e3 * st.error_m, 1e3 * sphere_chord_max(&m, c, 1.0), 1e3 * chord);
    CHECK(st.error_m > 0 && st.error_m <= 3 * chord);
    CHECK_LE(sphere_chord_max(&m, c, 1.0), 2 * st.error_m + before);
    mesh_free(&m);
    mesh_free(&full);
}

BF_TEST(simplify_to_an_error_bound_stays_within_it)
{
    mesh_data m;
    bf_vec3 c = bf_v3(0, 0, 0);
    fx_uv_sphere(&m, 1.0, c, 150, 300);
    uint32_t n0 = m.n_tris;
    /* Sphere tessellation error before: rings 1/150 of pi apart. */
    double before = sphere_chord_max(&m, c, 1.0);
    mesh_simplify_config cfg = {.max_error_m = 1e-3};
    mesh_simplify_stats st;
    CHECK_OK(mesh_simplify(&m, &cfg, &st));
    CHECK_LE(st.error_m, 1e-3);
    CHECK_LE(m.n_tris, n0 / 4); /* a bound of 1 mm on a 1 m sphere leaves far fewer triangles */
    /* The quadrics bound the vertices' distance to the input's planes; a
     * flat triangle between them bulges inside by its own chord error on
     * top: within twice the bound plus the input's own. */
    CHECK_LE(sphere_chord_max(&m, c, 1.0), 2e-3 + before);
    printf("  sphere 1 m: %u -> %u triangles for 1 mm (estimate %.3g mm, centroid max %.3g mm)\n", n0, m.n_tris,
           1e3 * st.error_m, 1e3 * sphere_chord_max(&m, c, 1.0));
    /* Nothing to do: a point cloud, or a mesh within its cap, stays. */
    mesh_data p = {.n_verts = m.n_verts, .xyz = m.xyz};
    cfg = (mesh_simplify_config){.max_triangles = 10};
    CHECK_OK(mesh_simplify(&p, &cfg, &st));
    CHECK_EQ_INT(p.n_verts, m.n_verts);
    CHECK(p.xyz == m.xyz);
    uint32_t n1 = m.n_tris;
    cfg = (mesh_simplify_config){.max_triangles = n1};
    CHECK_OK(mesh_simplify(&m, &cfg, &st));
    CHECK_EQ_INT(m.n_tris, n1);
    cfg = (mesh_simplify_config){.max_error_m = -1};
    CHECK_STATUS(mesh_simplify(&m, &cfg, &st), BF_INVALID_ARG);
    mesh_free(&m);
}

BF_TEST(simplify_refuses_a_cap_that_leaves_no_triangle)
{
    mesh_data m;
    fx_uv_sphere(&m, 1.0, bf_v3(0, 0, 0), 40, 80);
    uint32_t n0 = m.n_tris;
    float *xyz = m.xyz;
    /* One triangle: vertex clustering keeps none of a closed sphere (a
     * cell holding a whole triangle's corners drops it); refused, the mesh
     * as it was, the smallest cap that keeps some named. */
    mesh_simplify_config cfg = {.max_triangles = 1};
    CHECK_STATUS(mesh_simplify(&m, &cfg, NULL), BF_INVALID_ARG);
    CHECK(strstr(bf_last_error(), "leaves none") != NULL);
    CHECK(strstr(bf_last_error(), "keeps any has") != NULL);
    CHECK_EQ_INT(m.n_tris, n0);
    CHECK(m.xyz == xyz);
    /* The count it names is a cap that works. */
    unsigned long long fewest = 0;
    const char *at = strstr(bf_last_error(), "keeps any has ");
    CHECK(at && sscanf(at, "keeps any has %llu", &fewest) == 1);
    CHECK(fewest > 1 && fewest < n0);
    cfg.max_triangles = fewest;
    CHECK_OK(mesh_simplify(&m, &cfg, NULL));
    CHECK(m.n_tris > 0 && m.n_tris <= fewest);
    mesh_free(&m);
}

/* One simplification for the fault walk: on failure the mesh must be as it
 * was (all or nothing); a changed mesh is reported as BF_NUMERIC, which
 * the walk refuses. */
static bf_status simplify_once(void *arg)
{
    (void)arg;
    mesh_data m;
    fx_uv_sphere(&m, 1.0, bf_v3(0, 0, 0), 20, 40);
    uint32_t n_tris = m.n_tris, n_verts = m.n_verts;
    float *xyz = m.xyz;
    mesh_simplify_config cfg = {.max_triangles = 300, .max_error_m = 1e-3};
    bf_status s = mesh_simplify(&m, &cfg, NULL);
    if (s != BF_OK && (m.n_tris != n_tris || m.n_verts != n_verts || m.xyz != xyz)) s = BF_NUMERIC;
    mesh_free(&m);
    return s;
}

BF_TEST(simplify_fails_cleanly_at_every_allocation)
{
    int n = bf_test_fault_walk(simplify_once, NULL);
    CHECK(n >= 3);
    printf("  simplify: %d allocations failed in turn\n", n);
}
