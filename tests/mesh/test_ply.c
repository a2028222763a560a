/* eval: PLY reading (ascii, both binary byte orders), writing, appending and
 * the corrupt-input paths. */
#include <stdint.h>

#include "mesh/mesh.h"
#include "test.h"

static void tmp_path(char *out, size_t cap, const char *name)
{
    snprintf(out, cap, "%s/%s", bf_test_tmpdir(), name);
}

static void write_bytes(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    BF_ASSERT(f);
    BF_ASSERT(fwrite(data, 1, n, f) == n);
    fclose(f);
}

static void write_text(const char *path, const char *text) { write_bytes(path, text, strlen(text)); }

BF_TEST(ply_reads_every_shared_mesh_with_the_published_counts)
{
    static const struct {
        const char *file;
        uint32_t n_verts, n_tris;
    } meshes[] = {
        /* Counts from shared/data/README.md. */
        {"meshes/bunny.ply", 37706, 75408},  {"meshes/armadillo.ply", 26002, 52000},
        {"meshes/dragon.ply", 10000, 19994}, {"meshes/elephant.ply", 2775, 5558},
        {"meshes/fandisk.ply", 6475, 12946}, {"particles/dambreak_29814.ply", 29814, 0},
    };
    if (!bf_test_data("meshes")) BF_SKIP("shared data absent");
    for (size_t k = 0; k < sizeof meshes / sizeof meshes[0]; k++) {
        mesh_data m;
        CHECK_OK(mesh_read_ply(bf_test_data(meshes[k].file), &m));
        CHECK_EQ_INT(m.n_verts, meshes[k].n_verts);
        CHECK_EQ_INT(m.n_tris, meshes[k].n_tris);
        CHECK(m.normal == NULL && m.rgb == NULL);
        for (size_t i = 0; i < 3 * (size_t)m.n_tris; i++) CHECK(m.tri[i] < m.n_verts);
        mesh_free(&m);
    }
    /* The particles' x y z come first among nine floats: check the domain
     * (about 1.6 x 0.67 x 0.45 m, README) so skipped properties do not shift
     * what is read. */
    mesh_data p;
    CHECK_OK(mesh_read_ply(bf_test_data("particles/dambreak_29814.ply"), &p));
    float lo[3] = {1e9f, 1e9f, 1e9f}, hi[3] = {-1e9f, -1e9f, -1e9f};
    for (size_t i = 0; i < p.n_verts; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], p.xyz[3 * i + k]);
            hi[k] = fmaxf(hi[k], p.xyz[3 * i + k]);
        }
    mesh_free(&p);
    CHECK_NEAR(hi[0] - lo[0], 1.6, 0.1);
    CHECK_NEAR(hi[1] - lo[1], 0.67, 0.1);
    CHECK_NEAR(hi[2] - lo[2], 0.45, 0.1);
}

/* A small mesh with every attribute: two triangles, odd values. */
static mesh_data make_quad(void)
{
    mesh_data m = {0};
    m.n_verts = 4;
    m.n_tris = 2;
    m.xyz = malloc(12 * sizeof(float));
    m.normal = malloc(12 * sizeof(float));
    m.rgb = malloc(12);
    m.tri = malloc(6 * sizeof(uint32_t));
    const float xyz[12] = {0, 0, 0, 1.5f, 0, 0, 1.5f, -2.25f, 0, 0, -2.25f, 1e-7f};
    const uint32_t tri[6] = {0, 1, 2, 0, 2, 3};
    memcpy(m.xyz, xyz, sizeof xyz);
    memcpy(m.tri, tri, sizeof tri);
    for (int i = 0; i < 12; i++) {
        m.normal[i] = (i % 3 == 2) ? 1.0f : 0.0f;
        m.rgb[i] = (uint8_t)(i * 21);
    }
    return m;
}

static bool mesh_equal(const mesh_data *a, const mesh_data *b)
{
    if (a->n_verts != b->n_verts || a->n_tris != b->n_tris) return false;
    if (!!a->normal != !!b->normal || !!a->rgb != !!b->rgb) return false;
    if (memcmp(a->xyz, b->xyz, 3 * sizeof(float) * a->n_verts)) return false;
    if (a->normal && memcmp(a->normal, b->normal, 3 * sizeof(float) * a->n_verts)) return false;
    if (a->rgb && memcmp(a->rgb, b->rgb, 3 * (size_t)a->n_verts)) return false;
    if (a->n_tris && memcmp(a->tri, b->tri, 3 * sizeof(uint32_t) * a->n_tris)) return false;
    return true;
}

BF_TEST(ply_write_then_read_gives_the_same_mesh)
{
    char path[512];
    tmp_path(path, sizeof path, "quad.ply");
    mesh_data m = make_quad(), r;
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &r));
    bool same = mesh_equal(&m, &r);
    mesh_free(&r);
    CHECK(same);
    /* Without the optional attributes, and as a point cloud. */
    free(m.normal);
    free(m.rgb);
    m.normal = NULL;
    m.rgb = NULL;
    m.n_tris = 0;
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &r));
    same = mesh_equal(&m, &r);
    mesh_free(&r);
    mesh_free(&m);
    CHECK(same);
}

BF_TEST(ply_write_then_read_round_trips_the_bunny)
{
    if (!bf_test_data("meshes/bunny.ply")) BF_SKIP("shared data absent");
    char path[512];
    tmp_path(path, sizeof path, "bunny_copy.ply");
    mesh_data m, r;
    CHECK_OK(mesh_read_ply(bf_test_data("meshes/bunny.ply"), &m));
    CHECK_OK(mesh_write_ply(path, &m));
    CHECK_OK(mesh_read_ply(path, &r));
    bool same = mesh_equal(&m, &r);
    mesh_free(&m);
    mesh_free(&r);
    CHECK(same);
}

BF_TEST(ply_ascii_with_doubles_polygons_and_extra_properties)
{
    char path[512];
    tmp_path(path, sizeof path, "ascii.ply");
    write_text(path, "ply\r\n"
                     "format ascii 1.0\r\n"
                     "comment CRLF line ends, a quad, an extra element and extra properties\r\n"
                     "element vertex 5\r\n"
                     "property double x\r\nproperty double y\r\nproperty double z\r\n"
                     "property float confidence\r\n"
                     "property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n"
                     "element face 2\r\n"
                     "property int flags\r\n"
                     "property list int uint vertex_indices\r\n"
                     "element edge 1\r\n"
                     "property list uchar int vertex_index\r\n"
                     "end_header\r\n"
                     "0 0 0 nan 255 0 0\r\n"
                     "1 0 0 0.5 0 255 0\r\n"
                     "1 1 0 0.5 0 0 255\r\n"
                     "0 1 0.25 0.5 1 2 3\r\n"
                     "-1e-3 2 3 0.5 4 5 6\r\n"
                     "7 4 0 1 2 3\r\n"
                     "0 3 4 2 1\r\n"
                     "2 0 4\r\n");
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK_EQ_INT(m.n_verts, 5);
    CHECK_EQ_INT(m.n_tris, 3); /* the quad fans into two, plus one triangle */
    CHECK(m.rgb != NULL && m.normal == NULL);
    CHECK_NEAR(m.xyz[3 * 3 + 2], 0.25, 0);
    CHECK_NEAR(m.xyz[3 * 4 + 0], (float)-1e-3, 0);
    CHECK_EQ_INT(m.rgb[3 * 2 + 2], 255);
    CHECK_EQ_INT(m.rgb[3 * 4 + 1], 5);
    const uint32_t want[9] = {0, 1, 2, 0, 2, 3, 4, 2, 1};
    for (int i = 0; i < 9; i++) CHECK_EQ_INT(m.tri[i], want[i]);
    mesh_free(&m);
}

/* Big-endian bytes of a float / int32. */
static uint8_t *put_be32(uint8_t *p, uint32_t v)
{
    for (int i = 3; i >= 0; i--) *p++ = (uint8_t)(v >> (8 * i));
    return p;
}
static uint8_t *put_be_f32(uint8_t *p, float f)
{
    uint32_t b;
    memcpy(&b, &f, 4);
    return put_be32(p, b);
}

/* Double positions far from the origin keep their millimetres: the mesh
 * takes a local origin (the first vertex's, to the metre) on top of the
 * file's own, where floats would step by a metre at 1e7 m. */
BF_TEST(ply_far_double_positions_keep_their_precision_through_a_local_origin)
{
    char path[512];
    tmp_path(path, sizeof path, "far.ply");
    write_text(path, "ply\nformat ascii 1.0\ncomment origin_w 0.5 0 0\nelement vertex 3\n"
                     "property double x\nproperty double y\nproperty double z\n"
                     "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                     "10000000.3 -20000000.7 1.25\n10000000.6 -20000000.7 1.25\n10000000.3 -19999999.7 1.25\n3 0 1 2\n");
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK(m.origin.x == 10000000.5 && m.origin.y == -20000001.0 && m.origin.z == 0.0);
    double x[3] = {10000000.3, 10000000.6, 10000000.3}, y[3] = {-20000000.7, -20000000.7, -19999999.7};
    for (int i = 0; i < 3; i++) {
        CHECK_NEAR(m.origin.x + m.xyz[3 * i] - 0.5, x[i], 1e-6);
        CHECK_NEAR(m.origin.y + m.xyz[3 * i + 1], y[i], 1e-6);
        CHECK_NEAR(m.origin.z + m.xyz[3 * i + 2], 1.25, 0);
    }
    mesh_free(&m);
    /* Near the origin nothing changes. */
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\n"
                     "property double z\nend_header\n1000.25 -3 4\n");
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK(m.origin.x == 0 && m.origin.y == 0 && m.origin.z == 0 && m.xyz[0] == 1000.25f);
    mesh_free(&m);
}

BF_TEST(ply_binary_big_endian_with_normals_and_int_counts)
{
    char path[512];
    tmp_path(path, sizeof path, "be.ply");
    const char *hdr = "ply\nformat binary_big_endian 1.0\nelement vertex 3\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      "property float nx\nproperty float ny\nproperty float nz\n"
                      "element face 1\nproperty list int int vertex_indices\nend_header\n";
    uint8_t buf[1024], *p = buf;
    memcpy(p, hdr, strlen(hdr));
    p += strlen(hdr);
    const float v[3][6] = {{1, 2, 3, 0, 0, 1}, {-4, 5.5f, 6, 0, 1, 0}, {7, 8, -9.25f, 1, 0, 0}};
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 6; k++) p = put_be_f32(p, v[i][k]);
    p = put_be32(p, 3);
    p = put_be32(p, 2);
    p = put_be32(p, 1);
    p = put_be32(p, 0);
    write_bytes(path, buf, (size_t)(p - buf));
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK_EQ_INT(m.n_verts, 3);
    CHECK_EQ_INT(m.n_tris, 1);
    CHECK(m.normal != NULL);
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) {
            CHECK_NEAR(m.xyz[3 * i + k], v[i][k], 0);
            CHECK_NEAR(m.normal[3 * i + k], v[i][3 + k], 0);
        }
    CHECK_EQ_INT(m.tri[0], 2);
    CHECK_EQ_INT(m.tri[2], 0);
    mesh_free(&m);
}

BF_TEST(ply_truncated_at_every_byte_is_a_format_error_naming_the_file)
{
    char path[512], cut[512];
    tmp_path(path, sizeof path, "whole.ply");
    tmp_path(cut, sizeof cut, "cut.ply");
    mesh_data m = make_quad();
    CHECK_OK(mesh_write_ply(path, &m));
    mesh_free(&m);
    char *data;
    size_t size;
    CHECK_OK(bf_read_file(path, &data, &size));
    for (size_t n = 0; n < size; n++) {
        write_bytes(cut, data, n);
        mesh_data r = {0};
        bf_status s = mesh_read_ply(cut, &r);
        if (s != BF_FORMAT) free(data);
        CHECK_STATUS(s, BF_FORMAT);
        CHECK_ERROR_MENTIONS("cut.ply");
        CHECK(r.xyz == NULL); /* untouched on failure */
    }
    free(data);
    CHECK_STATUS(mesh_read_ply("/nonexistent/x.ply", &m), BF_IO);
}

BF_TEST(ply_ascii_truncation_names_the_line)
{
    char path[512];
    tmp_path(path, sizeof path, "ascii_cut.ply");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                     "property float z\nend_header\n0 0 0\n1 1\n");
    mesh_data m;
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("line 9");
    CHECK_ERROR_MENTIONS("vertex 1");
}

BF_TEST(ply_index_out_of_range_is_a_format_error)
{
    char path[512];
    tmp_path(path, sizeof path, "badindex.ply");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                     "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
    mesh_data m;
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("badindex.ply");
    CHECK_ERROR_MENTIONS("vertex 3 of 3");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                     "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n");
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("face 0");
}

BF_TEST(ply_absurd_counts_fail_without_allocating)
{
    char path[512];
    tmp_path(path, sizeof path, "huge.ply");
    /* 10^12 vertices in a 200-byte file: rejected from the header. */
    write_text(path, "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
                     "property float x\nproperty float y\nproperty float z\nend_header\n");
    mesh_data m;
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("vertex");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\n"
                     "property float x\nproperty float y\nproperty float z\nend_header\n");
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    write_text(path, "ply\nformat ascii 1.0\nelement vertex -3\n"
                     "property float x\nproperty float y\nproperty float z\nend_header\n");
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    /* A face claiming 4 billion corners in a binary body. */
    char buf[512];
    const char *hdr = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
                      "property float x\nproperty float y\nproperty float z\n"
                      "element face 1\nproperty list uint int vertex_indices\nend_header\n";
    size_t n = strlen(hdr);
    memcpy(buf, hdr, n);
    memset(buf + n, 0, 12);
    memset(buf + n + 12, 0xff, 4);
    write_bytes(path, buf, n + 16);
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("face 0");
}

BF_TEST(ply_nan_or_inf_positions_are_format_errors)
{
    char path[512];
    tmp_path(path, sizeof path, "nan.ply");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                     "property float z\nend_header\n0 0 0\n1 nan 0\n");
    mesh_data m;
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("line 9");
    CHECK_ERROR_MENTIONS("vertex 1");
    /* Binary: a double too large for float is infinite after conversion. */
    const char *hdr = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
                      "property double x\nproperty double y\nproperty double z\nend_header\n";
    char buf[512];
    size_t n = strlen(hdr);
    memcpy(buf, hdr, n);
    double v[3] = {0, 1e300, 0};
    memcpy(buf + n, v, sizeof v);
    write_bytes(path, buf, n + sizeof v);
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("vertex 0");
    /* A finite float no scene has (a stray 1e30 stalled eval-surface's
     * distance queries for minutes): refused; 1e8 (100,000 km) is read. */
    v[1] = 1e30;
    memcpy(buf + n, v, sizeof v);
    write_bytes(path, buf, n + sizeof v);
    CHECK_STATUS(mesh_read_ply(path, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("beyond 1e9");
    v[1] = -1e8;
    memcpy(buf + n, v, sizeof v);
    write_bytes(path, buf, n + sizeof v);
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK(m.origin.y + m.xyz[1] == -1e8); /* a double that far: through a local origin */
    mesh_free(&m);
}

BF_TEST(ply_bad_headers_are_format_errors)
{
    static const char *bad[] = {
        "plx\nformat ascii 1.0\nend_header\n",
        "ply\nformat ascii 2.0\nelement vertex 0\nend_header\n",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\n",
        "ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n",
        "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0x\n",
    };
    char path[512];
    tmp_path(path, sizeof path, "badhdr.ply");
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        write_text(path, bad[k]);
        mesh_data m;
        bf_status s = mesh_read_ply(path, &m);
        if (s != BF_FORMAT) fprintf(stderr, "  case %zu\n", k);
        CHECK_STATUS(s, BF_FORMAT);
        CHECK_ERROR_MENTIONS("badhdr.ply");
    }
}

BF_TEST(mesh_append_transforms_vertices_normals_and_offsets_indices)
{
    mesh_data a = make_quad(), b = make_quad(), dst = {0};
    bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), M_PI / 2), bf_v3(10, 0, 0));
    CHECK_OK(mesh_append(&dst, &a, NULL));
    CHECK_OK(mesh_append(&dst, &b, &T));
    CHECK_EQ_INT(dst.n_verts, 8);
    CHECK_EQ_INT(dst.n_tris, 4);
    CHECK(dst.normal && dst.rgb);
    /* Vertex 1 of b = (1.5, 0, 0) -> rotated by 90 deg about z -> (0, 1.5, 0) + (10, 0, 0). */
    CHECK_NEAR(dst.xyz[3 * 5 + 0], 10, 1e-6);
    CHECK_NEAR(dst.xyz[3 * 5 + 1], 1.5, 1e-6);
    CHECK_NEAR(dst.normal[3 * 5 + 2], 1, 1e-6);
    CHECK_EQ_INT(dst.tri[6], 4);
    CHECK_EQ_INT(dst.tri[11], 7);
    CHECK_EQ_INT(dst.rgb[3 * 5], b.rgb[3]);
    /* A source without colour gets white; without normals, zero normals. */
    free(a.rgb);
    free(a.normal);
    a.rgb = NULL;
    a.normal = NULL;
    CHECK_OK(mesh_append(&dst, &a, NULL));
    CHECK_EQ_INT(dst.n_verts, 12);
    CHECK_EQ_INT(dst.rgb[3 * 11], 255);
    CHECK_NEAR(dst.normal[3 * 11 + 2], 0, 0);
    mesh_free(&a);
    mesh_free(&b);
    mesh_free(&dst);
    mesh_free(NULL);
}

BF_TEST(ply_large_polygon_fans_into_n_minus_2_triangles)
{
    char path[512];
    tmp_path(path, sizeof path, "polygon.ply");
    FILE *f = fopen(path, "w");
    CHECK(f != NULL);
    const int n = 300;
    fprintf(f, "ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
               "property float z\nelement face 1\nproperty list ushort uint vertex_indices\nend_header\n", n);
    for (int i = 0; i < n; i++) fprintf(f, "%.6f %.6f 0\n", cos(2 * M_PI * i / n), sin(2 * M_PI * i / n));
    fprintf(f, "%d", n);
    for (int i = 0; i < n; i++) fprintf(f, " %d", i);
    fprintf(f, "\n");
    fclose(f);
    mesh_data m;
    CHECK_OK(mesh_read_ply(path, &m));
    CHECK_EQ_INT(m.n_tris, n - 2);
    CHECK_EQ_INT(m.tri[3 * (n - 3)], 0);
    CHECK_EQ_INT(m.tri[3 * (n - 3) + 1], n - 2);
    CHECK_EQ_INT(m.tri[3 * (n - 3) + 2], n - 1);
    mesh_free(&m);
}

BF_TEST(ply_write_to_a_missing_directory_is_a_write_error)
{
    mesh_data m = make_quad();
    bf_status s = mesh_write_ply("/nonexistent-dir/x.ply", &m);
    mesh_free(&m);
    CHECK_STATUS(s, BF_WRITE);
    CHECK_ERROR_MENTIONS("nonexistent-dir");
}

static bf_status read_and_write_ply(void *arg)
{
    char path[512];
    tmp_path(path, sizeof path, "fault_copy.ply");
    mesh_data m;
    bf_status s = mesh_read_ply(arg, &m);
    if (s != BF_OK) return s;
    s = mesh_write_ply(path, &m);
    mesh_free(&m);
    return s;
}

/* Every host allocation of reading and writing a PLY fails in turn: each
 * is a clean BF_NO_MEMORY with a message, nothing leaks (ASan). */
BF_TEST(ply_read_and_write_fail_cleanly_at_every_allocation)
{
    const char *bunny = bf_test_data("meshes/bunny.ply");
    if (!bunny) BF_SKIP("shared data absent");
    char path[4096];
    snprintf(path, sizeof path, "%s", bunny);
    int n = bf_test_fault_walk(read_and_write_ply, path);
    CHECK(n >= 2);
    fprintf(stderr, "  PLY: %d allocations failed in turn\n", n);
}
