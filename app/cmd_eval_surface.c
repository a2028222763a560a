/* bitfuse eval-surface: accuracy and completeness of a reconstruction
 * against a reference mesh (docs/eval.md). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "mesh/mesh.h"

static const char usage_text[] =
    "usage: bitfuse eval-surface --reference MESH --reconstruction PLY [options]\n"
    "\n"
    "Accuracy: distance from each reconstruction point (its vertices, plus area\n"
    "samples of its triangles if it is a mesh) to the reference surface.\n"
    "Completeness: share of reference surface samples (area-uniform) within the\n"
    "threshold of the reconstruction, and their distances.\n";

static void json_dist(cJSON *o, const eval_dist_stats *d)
{
    cJSON_AddNumberToObject(o, "mean_m", d->mean);
    cJSON_AddNumberToObject(o, "median_m", d->median);
    cJSON_AddNumberToObject(o, "p90_m", d->p90);
    cJSON_AddNumberToObject(o, "rmse_m", d->rmse);
    cJSON_AddNumberToObject(o, "max_m", d->max);
    cJSON_AddNumberToObject(o, "beyond_max_dist", (double)d->n_beyond);
}

static void print_dist_text(const eval_dist_stats *d)
{
    printf("  mean %.6f m  median %.6f  p90 %.6f  rmse %.6f  max %.6f", d->mean, d->median, d->p90, d->rmse,
           d->max);
    if (d->n_beyond) printf("  (%zu beyond --max-dist, left out)", d->n_beyond);
    printf("\n");
}

int cmd_eval_surface(int argc, char **argv)
{
    const char *cmd = "eval-surface", *ref_path = NULL, *rec_path = NULL, *vis_path = NULL;
    bool json = false;
    eval_surface_config cfg = eval_surface_config_default();
    const app_option own[] = {
        APP_OPT("--reference", APP_OPT_STRING, &ref_path, "MESH", "the reference mesh (PLY)", .required = true),
        APP_OPT("--reconstruction", APP_OPT_STRING, &rec_path, "PLY", "the reconstruction: points or a mesh",
                .required = true),
        APP_OPT("--visible", APP_OPT_STRING, &vis_path, "SEEN.ply",
                "completeness over these observed reference points instead of samples of the whole reference"),
        APP_OPT("--threshold", APP_OPT_DOUBLE, &cfg.threshold_m, "M", "completeness / precision threshold, metres",
                .min_open = true),
        APP_OPT("--max-dist", APP_OPT_DOUBLE, &cfg.max_dist_m, "M",
                "distances beyond M are left out of the statistics and counted as beyond (default: no limit)",
                .min_open = true, .no_default = true),
        APP_OPT("--samples-per-m2", APP_OPT_DOUBLE, &cfg.samples_per_m2, "N", "area sampling density (one per 5 mm^2)",
                .min_open = true),
        APP_OPT("--max-samples", APP_OPT_U64, &cfg.max_samples, "N", "cap on samples per mesh", .min = 1),
        APP_OPT("--seed", APP_OPT_U64, &cfg.seed, "N", "sampling seed"),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "machine-readable output on stdout (docs/eval.md)"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {.name = cmd, .usage = usage_text, .tables = tables};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;

    mesh_data ref = {0}, rec = {0}, vis = {0};
    eval_surface_result r;
    bf_status s = mesh_read_ply(ref_path, &ref);
    if (!s) s = mesh_read_ply(rec_path, &rec);
    if (!s && vis_path) s = mesh_read_ply(vis_path, &vis);
    if (!s && ref.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: the reference has no vertices", ref_path);
    if (!s && rec.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: the reconstruction has no vertices", rec_path);
    if (!s && vis_path && vis.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: no visible points", vis_path);
    if (!s) {
        bf_info("eval-surface: reference %u vertices / %u triangles, reconstruction %u vertices / %u "
                "triangles%s",
                ref.n_verts, ref.n_tris, rec.n_verts, rec.n_tris, vis_path ? ", visibility mask" : "");
        s = eval_surface(&ref, &rec, vis_path ? &vis : NULL, &cfg, &r);
    }
    uint32_t ref_v = ref.n_verts, ref_t = ref.n_tris, rec_v = rec.n_verts, rec_t = rec.n_tris;
    mesh_free(&ref);
    mesh_free(&rec);
    mesh_free(&vis);
    if (s) return app_fail(cmd, s);

    const char *source = r.used_visible ? "visible" : ref_t ? "samples" : "vertices";
    if (json) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "reference", ref_path);
        cJSON_AddStringToObject(o, "reconstruction", rec_path);
        if (vis_path) cJSON_AddStringToObject(o, "visible", vis_path);
        else cJSON_AddNullToObject(o, "visible");
        cJSON_AddNumberToObject(o, "reference_vertices", ref_v);
        cJSON_AddNumberToObject(o, "reference_triangles", ref_t);
        cJSON_AddNumberToObject(o, "threshold_m", cfg.threshold_m);
        cJSON_AddNumberToObject(o, "max_dist_m", cfg.max_dist_m);
        cJSON_AddNumberToObject(o, "samples_per_m2", cfg.samples_per_m2);
        cJSON_AddNumberToObject(o, "max_samples", (double)cfg.max_samples);
        cJSON_AddNumberToObject(o, "seed", (double)cfg.seed);
        cJSON *acc = app_json_object(o, "accuracy");
        cJSON_AddNumberToObject(acc, "points", (double)(r.n_rec_vertices + r.n_rec_samples));
        cJSON_AddNumberToObject(acc, "rec_vertices", (double)r.n_rec_vertices);
        cJSON_AddNumberToObject(acc, "rec_samples", (double)r.n_rec_samples);
        json_dist(acc, &r.accuracy);
        cJSON_AddNumberToObject(acc, "within_threshold", r.precision);
        cJSON *com = app_json_object(o, "completeness");
        cJSON_AddNumberToObject(com, "points", (double)r.n_ref_points);
        cJSON_AddStringToObject(com, "source", source);
        cJSON_AddNumberToObject(com, "ratio", r.completeness);
        json_dist(com, &r.completeness_dist);
        cJSON_AddNumberToObject(o, "seconds", r.seconds);
        cJSON_AddNumberToObject(o, "threads", bf_thread_count());
        return (s = app_json_print(o)) == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
    }
    printf("reference %s: %u vertices, %u triangles\n", ref_path, ref_v, ref_t);
    printf("reconstruction %s: %u vertices, %u triangles\n", rec_path, rec_v, rec_t);
    printf("accuracy: %zu reconstruction points (%zu vertices + %zu area samples) to the reference\n",
           r.n_rec_vertices + r.n_rec_samples, r.n_rec_vertices, r.n_rec_samples);
    print_dist_text(&r.accuracy);
    printf("  within %g m: %.2f%%\n", cfg.threshold_m, 100 * r.precision);
    printf("completeness: %.2f%% of %zu reference %s within %g m of the reconstruction\n", 100 * r.completeness,
           r.n_ref_points, r.used_visible ? "points (visibility mask)" : ref_t ? "area samples" : "vertices",
           cfg.threshold_m);
    print_dist_text(&r.completeness_dist);
    printf("time %.2f s on %d threads\n", r.seconds, bf_thread_count());
    return APP_EXIT_OK;
}
