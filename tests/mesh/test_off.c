/* mesh: the OFF reader against a file written here (a quad fanned into two
 * triangles, comments, a face colour), and its refusals naming the line. */
#include <math.h>
#include <stdio.h>

#include "mesh/mesh.h"
#include "test.h"

static const char *write_file(const char *name, const char *text)
{
    static char path[600];
    snprintf(path, sizeof path, "%s/%s", bf_test_tmpdir(), name);
    FILE *f = fopen(path, "w");
    fputs(text, f);
    fclose(f);
    return path;
}

BF_TEST(off_reads_vertices_and_fans_polygons)
{
    const char *p = write_file("quad.OFF", "OFF\n# a unit quad and a triangle\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
                                           "0.5 0.5 1.5e0\n4 0 1 2 3\n3 0 1 4 255 0 0\n");
    mesh_data m;
    CHECK_OK(mesh_read(p, &m)); /* by the extension, any case */
    CHECK_EQ_INT(m.n_verts, 5);
    CHECK_EQ_INT(m.n_tris, 3);
    const uint32_t want[9] = {0, 1, 2, 0, 2, 3, 0, 1, 4};
    for (int i = 0; i < 9; i++) CHECK_EQ_INT(m.tri[i], want[i]);
    CHECK(m.xyz[3 * 4 + 2] == 1.5f);
    mesh_free(&m);
}

BF_TEST(off_refusals_name_the_line)
{
    mesh_data m;
    const char *p = write_file("bad_index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("line 6");
    CHECK_ERROR_MENTIONS("vertex 7 of 3");
    p = write_file("short.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("ends before");
    /* A count the file cannot hold is refused before anything is allocated
     * for it (the fuzzer's case: 214,746,663 vertices claimed in 18 bytes). */
    p = write_file("huge.off", "OFF\n214746663 3 0\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("214746663 vertices cannot fit in the 1 bytes left");
    p = write_file("tight.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2");
    CHECK_STATUS(mesh_read_off(p, &m), BF_OK);
    CHECK(m.n_verts == 3 && m.n_tris == 1);
    mesh_free(&m);
    p = write_file("nan.off", "OFF\n1 0 0\n0 nan 0\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not a finite number");
    p = write_file("far.off", "OFF\n1 0 0\n0 1e30 0\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("line 3: vertex coordinate 1e+30 is beyond 1e9");
    p = write_file("not.off", "ply\nformat ascii 1.0\n");
    CHECK_STATUS(mesh_read_off(p, &m), BF_FORMAT);
    CHECK_ERROR_MENTIONS("not an OFF file");
    CHECK_STATUS(mesh_read_off("/nonexistent/x.off", &m), BF_IO);
    CHECK_ERROR_MENTIONS("/nonexistent/x.off");
}

/* A tetrahedron closes (every edge shared by two faces); without a face it
 * has a hole whose rim is 3 edges; written face by face (each face its own
 * vertices, as STL-like exports do) it still closes, equal positions being
 * one vertex. */
BF_TEST(open_edges_count_the_rims_of_holes)
{
    static const char *const text[3] = {
        "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n",
        "OFF\n4 3 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n",
        "OFF\n12 4 0\n0 0 0\n0 1 0\n1 0 0\n0 0 0\n1 0 0\n0 0 1\n1 0 0\n0 1 0\n0 0 1\n0 0 0\n0 0 1\n0 1 0\n"
        "3 0 1 2\n3 3 4 5\n3 6 7 8\n3 9 10 11\n",
    };
    static const uint64_t want[3] = {0, 3, 0};
    mesh_data m;
    uint64_t n;
    for (int i = 0; i < 3; i++) {
        CHECK_OK(mesh_read(write_file("tet.off", text[i]), &m));
        CHECK_OK(mesh_open_edges(&m, &n));
        CHECK_EQ_INT(n, want[i]);
        if (i < 2) mesh_free(&m);
    }
    CHECK_EQ_INT(m.n_verts, 12);
    /* A soup vertex moved by a float's step no longer meets its partners:
     * the two edges through it and their two partners become rims. */
    m.xyz[3 * 5 + 2] = nextafterf(1.0f, 2.0f);
    CHECK_OK(mesh_open_edges(&m, &n));
    CHECK_EQ_INT(n, 4);
    m.tri[0] = 12;
    CHECK_STATUS(mesh_open_edges(&m, &n), BF_INVALID_ARG);
    mesh_free(&m);
}
