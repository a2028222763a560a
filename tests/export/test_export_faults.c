/* export: every allocation of both exports fails in turn (SQLite's fault
 * injection walk, libuv's loop_init_oom): the status is BF_NO_MEMORY with a
 * message, the output is untouched, nothing leaks (ASan), and the next
 * export without faults gives the same result as before. */
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "test.h"

static bool same_mesh(const mesh_data *a, const mesh_data *b)
{
    return a->n_verts == b->n_verts && a->n_tris == b->n_tris &&
           !memcmp(a->xyz, b->xyz, (size_t)a->n_verts * 12) &&
           (!a->n_tris || !memcmp(a->tri, b->tri, (size_t)a->n_tris * 12));
}

static bool below(const void *ctx, bf_vec3 c) { return c.x < *(const double *)ctx; }

static void fault_walk(bool points)
{
    hostmap s;
    memset(&s, 0, sizeof s);
    s.chunk_m = 2;
    s.origin_w = bf_v3(0.1, 0.2, 0.3);
    fx_sphere sp = {bf_v3(0.1013, 0.1971, 0.3029), 0.04};
    bf_vec3 lo = bf_v3(sp.c.x - 0.06, sp.c.y - 0.06, sp.c.z - 0.06), hi = bf_v3(sp.c.x + 0.06, sp.c.y + 0.06, sp.c.z + 0.06);
    double split = sp.c.x;
    /* Two levels, so the coarse path's allocations are walked too. */
    fx_voxelize(&s, fx_sphere_sdf, &sp, 6, lo, hi, 2, NULL, NULL, true);
    fx_voxelize(&s, fx_sphere_sdf, &sp, 7, lo, hi, 2, below, &split, true);
    mesh_data ref;
    if (points)
        CHECK_OK(export_points(&s, &ref, NULL));
    else
        CHECK_OK(export_mesh(&s, NULL, &ref, NULL));
    CHECK(ref.n_verts > 0);
    uint32_t n_failed = 0;
    for (long k = 1;; k++) {
        mesh_data m;
        memset(&m, 0xAB, sizeof m);
        mesh_data sentinel = m;
        bf_fault_arm((uint32_t)k);
        bf_status rc = points ? export_points(&s, &m, NULL) : export_mesh(&s, NULL, &m, NULL);
        bool fired = bf_fault_arm(0) == 0;
        if (!fired) {
            /* k is past the last allocation: a clean run. */
            CHECK_OK(rc);
            CHECK(same_mesh(&m, &ref));
            mesh_free(&m);
            break;
        }
        /* A failed per-brick allocation may be one the export does not
         * need in the end only if it still reports it: any fired fault
         * must fail the call. */
        CHECK_STATUS(rc, BF_NO_MEMORY);
        CHECK_ERROR_MENTIONS("no memory");
        CHECK(!memcmp(&m, &sentinel, sizeof m));
        n_failed++;
    }
    printf("  %s: %u allocations failed in turn\n", points ? "points" : "mesh", n_failed);
    CHECK(n_failed >= 8);
    mesh_free(&ref);
    fx_free(&s);
}

BF_TEST(mesh_export_fails_cleanly_at_every_allocation) { fault_walk(false); }
BF_TEST(point_export_fails_cleanly_at_every_allocation) { fault_walk(true); }
