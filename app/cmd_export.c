/* bitfuse export: the mesh or the surface points of a scene store, without
 * the loop (and without a GPU: the store is read into a host copy); and
 * bitfuse info on a store. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "mesh/mesh.h"

static const char export_usage[] =
    "usage: bitfuse export STORE --out FILE [--format ply|obj|glb] [--max-triangles N]\n"
    "                      [--max-error M] [--points] [--mesh-level L] [--json]\n\n"
    "Reads the scene store STORE (bitfuse replay|live --store; or a folder holding one\n"
    "as STORE/store) and writes the triangle mesh of its confident surface (marching\n"
    "cubes, as replay's mesh.ply) or, with --points, its surface voxel centres with\n"
    "normals (as points.ply). The format comes from FILE's extension or --format: binary\n"
    "PLY, Wavefront OBJ (+ FILE's .mtl) or glTF binary (.glb). --max-triangles and\n"
    "--max-error simplify the mesh (meshoptimizer). A map beyond 1 km from the world\n"
    "origin is written relative to a local origin, which the file records\n"
    "(docs/export.md). A corrupt chunk file is reported by name and left out; the rest\n"
    "is exported.\n";

static const char export_epilog[] =
    "exit codes: 0 ok (also with chunk files left out: they are warned about), 1 failure,\n"
    "2 usage, 3 no readable store, 5 FILE could not be written (disk full, I/O error, no such\n"
    "folder: nothing is left behind, an earlier FILE stays as it was)\n";

/* Reads a store, warning about what it left out (cmd: whose warning);
 * with refuse_empty, one that holds nothing at all is BF_FORMAT. */
static bf_status read_store(const char *cmd, const char *dir, hostmap *m, store_meta *meta, bf_traj *traj,
                            store_report *rep, bool refuse_empty)
{
    bf_status s = store_read(dir, m, meta, traj, rep);
    if (s == BF_IO && !store_exists(dir)) s = BF_FORMAT; /* not a store: bad input, not an I/O failure */
    if (s == BF_UNSUPPORTED) s = BF_FORMAT;              /* a newer store: unreadable here (exit 3) */
    /* No readable store.json, no trajectory, no chunk file: a folder that only
     * looks like a store (one killed before its first write finished). */
    if (s == BF_OK && refuse_empty && !rep->index_ok && !rep->trajectory_ok && rep->n_chunks == 0 && rep->n_bad == 0)
        s = bf_fail(BF_FORMAT, "%s: holds no chunk file, no readable store.json and no trajectory: not a scene store "
                    "(or one stopped before its first write)", dir);
    if (s == BF_OK && rep->n_bad)
        bf_warn("%s: %s: %u chunk file%s left out, the first: %s", cmd, dir, rep->n_bad, app_s(rep->n_bad),
                rep->first_bad);
    if (s == BF_OK && rep->n_missing)
        bf_warn("%s: %s: %u chunk%s the index lists %s not loaded (a file missing or bad): left out", cmd, dir,
                rep->n_missing, app_s(rep->n_missing), rep->n_missing == 1 ? "was" : "were");
    return s;
}

int cmd_export(int argc, char **argv)
{
    const char *cmd = "export", *dir = NULL, *out = NULL;
    bool points = false, json = false;
    uint32_t level = UINT32_MAX;
    app_mesh_out mo;
    app_option msh[APP_MESH_ROWS];
    app_mesh_options(msh, &mo, true);
    const app_option own[] = {
        APP_OPT("--out", APP_OPT_STRING, &out, "FILE", "the file to write (.ply, .obj or .glb)", .required = true),
        APP_OPT("--points", APP_OPT_FLAG, &points, NULL, "write the surface points instead of the mesh"),
        APP_OPT("--mesh-level", APP_OPT_U32, &level, "L",
                "the mesh lattice's octree level (default: the finest level holding a tenth of the bricks)", .max = 8,
                .no_default = true),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "print what was written as JSON"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, msh, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = export_usage, .tables = tables, .positional = &dir, .min_positional = 1,
        .max_positional = 1, .positional_missing = "no store given", .epilog = export_epilog,
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    /* The format before anything is read: a name it cannot come from is a
     * usage error, and nothing is written. */
    mesh_format fmt = (mesh_format)mo.format;
    if (mo.format < 0 && mesh_format_of_path(out, &fmt) != BF_OK)
        return app_usage_error(cmd, "--out %s: the format comes from the extension (.ply, .obj, .glb) or --format",
                               out);
    if (points && (mo.max_triangles || mo.max_error_m > 0))
        return app_usage_error(cmd, "--max-triangles and --max-error simplify a mesh, not --points");
    if (points && level != UINT32_MAX) return app_usage_error(cmd, "--mesh-level is the mesh's, not --points'");
    /* A run's folder holding its store as DIR/store (replay --out DIR --store
     * DIR/store), as render and view take it. */
    char sub[4096];
    const char *found = app_store_dir(dir, sub, sizeof sub);
    if (found) dir = found;
    else if (bf_file_exists(dir))
        return app_fail(cmd, bf_fail(BF_FORMAT, "%s: not a scene store (bitfuse replay|live --store), nor a folder "
                                                "holding one as store/", dir));
    /* Not into the store it reads (an --out of STORE/store.json replaced its index). */
    if ((rc = app_check_not_inside(cmd, "--out", out, dir, true)) != 0) return rc;
    if ((rc = app_check_out_folder(cmd, "--out", out)) != 0) return rc;
    double t0 = bf_time_s();
    hostmap m = {0};
    store_meta meta;
    store_report rep;
    mesh_data data = {0};
    export_stats st = {0};
    mesh_simplify_stats ss = {0};
    uint32_t mesh_level = 0;
    bf_status s = read_store(cmd, dir, &m, &meta, NULL, &rep, true);
    /* Every chunk left out (bad files, or whole ones at odds with a damaged
     * store.json): an empty file and exit 0 would pass for an export; say
     * so, as render does ("holds no brick"), and write nothing. */
    if (s == BF_OK && m.n_bricks == 0 && rep.n_bad)
        s = bf_fail(BF_FORMAT, "%s: no chunk could be loaded (%u file%s left out, the first: %s): nothing to export",
                    dir, rep.n_bad, rep.n_bad == 1 ? "" : "s", rep.first_bad);
    else if (s == BF_OK && m.n_bricks == 0 && rep.n_missing)
        s = bf_fail(BF_FORMAT, "%s: no chunk could be loaded (the %u chunk file%s the index lists %s gone): nothing to "
                    "export", dir, rep.n_missing, rep.n_missing == 1 ? "" : "s", rep.n_missing == 1 ? "is" : "are");
    if (s == BF_OK && points) {
        s = export_points(&m, &data, &st);
    } else if (s == BF_OK) {
        export_mesh_config mc = export_mesh_config_default();
        mc.max_level = level != UINT32_MAX ? level : app_mesh_level(&m);
        /* A lattice finer than every brick: the mesh is the finest bricks' own. */
        uint32_t finest = 0;
        for (uint32_t i = 0; i < m.n_bricks; i++) finest = m.bricks[i].level > finest ? m.bricks[i].level : finest;
        if (level != UINT32_MAX && level > finest && m.n_bricks) {
            bf_warn("export: --mesh-level %u: the store's finest bricks are at level %u: the mesh is level %u's", level,
                    finest, finest);
            mc.max_level = finest;
        }
        mesh_level = mc.max_level;
        s = export_mesh(&m, &mc, &data, &st);
        /* A lattice too coarse for the scene's surfaces (a wall thinner
         * than a few of its voxels, a surface seen from one side whose band
         * falls between its corners) meshes nothing: say so rather than hand
         * over an empty file as the export. */
        if (s == BF_OK && st.n_triangles == 0 && m.n_bricks)
            bf_warn("export: the mesh at level %u has no triangle: no surface of the store spans a few of that level's "
                    "%g m voxels%s; --points writes its surface voxels",
                    mc.max_level, m.chunk_m / 8.0 / (double)(1u << (mc.max_level > 20 ? 20 : mc.max_level)),
                    mc.max_level < finest ? " (a finer --mesh-level, up to its finest bricks' level, keeps thinner "
                                            "ones)"
                                          : "");
    }
    double t_write = bf_time_s();
    if (s == BF_OK) s = app_mesh_write(out, fmt, &mo, &data, &ss);
    double secs = bf_time_s() - t0;
    if (s == BF_OK && json) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "store", dir);
        cJSON_AddStringToObject(o, "out", out);
        cJSON_AddStringToObject(o, "what", points ? "points" : "mesh");
        cJSON_AddNumberToObject(o, "chunks", rep.n_chunks);
        cJSON_AddNumberToObject(o, "bricks", rep.n_bricks);
        cJSON_AddNumberToObject(o, "chunk_files_left_out", rep.n_bad);
        cJSON_AddNumberToObject(o, "chunks_missing", rep.n_missing);
        if (!points) cJSON_AddNumberToObject(o, "mesh_level", mesh_level); /* the lattice's octree level */
        app_json_mesh_file(o, out, fmt, &mo, &data, &ss);
        cJSON_AddNumberToObject(o, "export_seconds", st.seconds);
        cJSON_AddNumberToObject(o, "write_seconds", bf_time_s() - t_write - ss.seconds);
        cJSON_AddNumberToObject(o, "seconds", secs);
        s = app_json_print(o);
    } else if (s == BF_OK) {
        printf("bitfuse export: %s (%u chunks, %u bricks%s) -> %s (%s): %llu %s%s in %.1f s\n", dir, rep.n_chunks,
               rep.n_bricks, rep.n_bad || rep.n_missing ? ", some chunk files left out" : "", out, mesh_format_name(fmt),
               (unsigned long long)(points ? data.n_verts : data.n_tris), points ? "point" : "triangle",
               app_s(points ? data.n_verts : data.n_tris), secs);
        if (ss.tris_after != ss.tris_before)
            printf("  simplified from %llu triangles in %.1f s (meshoptimizer's error estimate %.2f mm%s)\n",
                   (unsigned long long)ss.tris_before, ss.seconds, 1e3 * ss.error_m,
                   ss.used_sloppy ? "; the cap needed vertex clustering" : "");
        if (data.origin.x != 0 || data.origin.y != 0 || data.origin.z != 0)
            printf("  vertices relative to the local origin (%.3f, %.3f, %.3f) m, recorded in the file\n",
                   data.origin.x, data.origin.y, data.origin.z);
    }
    mesh_free(&data);
    hostmap_free(&m);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}

/* ------------------------------------------------------------ info */

int app_info_store(const char *dir, bool json)
{
    hostmap m = {0};
    store_meta meta;
    store_report rep;
    bf_traj traj = {0};
    bf_status s = read_store("info", dir, &m, &meta, &traj, &rep, false);
    if (s != BF_OK) return app_fail("info", s);
    uint32_t per_level[9] = {0};
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < m.n_bricks; i++) {
        const hostmap_brick *b = &m.bricks[i];
        per_level[b->level < 9 ? b->level : 8]++;
        double edge = hostmap_level_voxel_m(m.chunk_m, b->level) * 8;
        double c[3] = {m.origin_w.x + b->key[0] * (double)m.chunk_m + b->cell[0] * edge,
                       m.origin_w.y + b->key[1] * (double)m.chunk_m + b->cell[1] * edge,
                       m.origin_w.z + b->key[2] * (double)m.chunk_m + b->cell[2] * edge};
        for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], c[k]), hi[k] = fmax(hi[k], c[k] + edge);
    }
    double raw = (double)m.n_bricks * 2 * 64;
    /* The relocalisation keyframes a resumed scan starts from: a bad file
     * is damage to report, not a reason to refuse the store. */
    store_keyframes kf = {0};
    bool kf_ok = store_keyframes_read(dir, &kf) == BF_OK;
    if (!kf_ok) bf_warn("info: %s", bf_last_error());
    uint32_t kf_points = 0;
    for (uint32_t i = 0; i < kf.n; i++) kf_points += kf.kf[i].n;
    if (json) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "kind", "bitfuse-store");
        cJSON_AddStringToObject(o, "path", dir);
        cJSON_AddNumberToObject(o, "version", STORE_VERSION);
        cJSON_AddNumberToObject(o, "chunks", rep.n_chunks);
        cJSON_AddNumberToObject(o, "bricks", rep.n_bricks);
        cJSON *pl = cJSON_AddArrayToObject(o, "bricks_per_level");
        for (uint32_t l = 0; l <= meta.max_level && l < 9; l++) cJSON_AddItemToArray(pl, cJSON_CreateNumber(per_level[l]));
        cJSON_AddNumberToObject(o, "bytes_on_disk", (double)rep.bytes_files);
        cJSON_AddNumberToObject(o, "bytes_bit_planes", raw);
        cJSON_AddNumberToObject(o, "chunk_m", meta.chunk_m);
        cJSON_AddNumberToObject(o, "max_level", meta.max_level);
        if (m.n_bricks) {
            app_json_numbers(o, "extent_min_m", lo, 3);
            app_json_numbers(o, "extent_max_m", hi, 3);
        }
        cJSON_AddNumberToObject(o, "frames", meta.frames);
        if (meta.has_pose) {
            bf_quat q = bf_quat_from_mat(meta.last_pose.R);
            double p[8] = {meta.last_t_s, meta.last_pose.t.x, meta.last_pose.t.y, meta.last_pose.t.z, q.x, q.y, q.z, q.w};
            app_json_numbers(o, "last_pose_tum", p, 8);
        }
        /* The write count lives in store.json: unknown without it. */
        if (rep.index_ok) cJSON_AddNumberToObject(o, "flush", rep.flush);
        else cJSON_AddNullToObject(o, "flush");
        cJSON_AddBoolToObject(o, "index_ok", rep.index_ok);
        cJSON_AddBoolToObject(o, "trajectory_ok", rep.trajectory_ok);
        cJSON_AddNumberToObject(o, "bad_chunk_files", rep.n_bad);
        cJSON_AddNumberToObject(o, "missing_chunks", rep.n_missing);
        cJSON_AddNumberToObject(o, "unindexed_chunks", rep.n_unindexed);
        cJSON_AddNumberToObject(o, "keyframes", kf.n);
        cJSON_AddNumberToObject(o, "keyframe_keypoints", kf_points);
        cJSON_AddBoolToObject(o, "keyframes_ok", kf_ok);
        s = app_json_print(o);
    } else {
        if (rep.index_ok)
            printf("%s: bitfuse scene store, version %u, %u write%s\n", dir, STORE_VERSION, rep.flush, app_s(rep.flush));
        else
            printf("%s: bitfuse scene store, version %u, writes unknown (store.json %s)\n", dir, STORE_VERSION,
                   rep.index_found ? "unreadable" : "absent");
        printf("  chunks           %u (%g m), %u bricks:", rep.n_chunks, meta.chunk_m, rep.n_bricks);
        for (uint32_t l = 0; l < 9; l++)
            if (per_level[l]) printf("  L%u:%u", l, per_level[l]);
        printf("\n  bytes            %.2f MiB on disk (bit planes %.2f MiB, %.1fx)\n", rep.bytes_files / 1048576.0,
               raw / 1048576.0, rep.bytes_files ? raw / rep.bytes_files : 0.0);
        if (m.n_bricks)
            printf("  extent           (%.2f, %.2f, %.2f) to (%.2f, %.2f, %.2f) m, %.1f x %.1f x %.1f m\n", lo[0], lo[1],
                   lo[2], hi[0], hi[1], hi[2], hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
        printf("  frames           %u\n", meta.frames);
        if (meta.has_pose) {
            bf_quat q = bf_quat_from_mat(meta.last_pose.R);
            printf("  last pose        %.6f %.4f %.4f %.4f %.4f %.4f %.4f %.4f (TUM)\n", meta.last_t_s, meta.last_pose.t.x,
                   meta.last_pose.t.y, meta.last_pose.t.z, q.x, q.y, q.z, q.w);
        }
        if (kf.n)
            printf("  keyframes        %u, %u colour keypoints (a resumed scan finds the camera from them)\n", kf.n,
                   kf_points);
        if (!kf_ok) printf("  damage           keyframes.bin unreadable (a resumed scan starts from its poses)\n");
        if (!rep.index_ok || !rep.trajectory_ok || rep.n_bad || rep.n_missing)
            printf("  damage           index %s, trajectory %s, %u bad chunk file%s, %u chunk%s missing\n",
                   rep.index_ok ? "ok" : "unreadable", rep.trajectory_ok ? "ok" : "unreadable", rep.n_bad,
                   app_s(rep.n_bad), rep.n_missing, app_s(rep.n_missing));
    }
    store_keyframes_free(&kf);
    hostmap_free(&m);
    bf_traj_free(&traj);
    return s == BF_OK ? APP_EXIT_OK : app_fail("info", s);
}
