/* bitfuse eval-surface: accuracy and completeness of a reconstruction
 * against a reference mesh (docs/eval.md). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "mesh/mesh.h"

static const char *usage_text =
    "usage: bitfuse eval-surface --reference MESH --reconstruction PLY [options]\n"
    "\n"
    "Accuracy: distance from each reconstruction point (its vertices, plus area\n"
    "samples of its triangles if it is a mesh) to the reference surface.\n"
    "Completeness: share of reference surface samples (area-uniform) within the\n"
    "threshold of the reconstruction, and their distances.\n"
    "\n"
    "  --visible SEEN.ply    completeness over these observed reference points\n"
    "                        instead of samples of the whole reference\n"
    "  --threshold M         completeness / precision threshold, metres (0.01)\n"
    "  --max-dist M          distances beyond M are left out of the statistics\n"
    "                        and counted as beyond (default: no limit)\n"
    "  --samples-per-m2 N    area sampling density (200000: one per 5 mm^2)\n"
    "  --max-samples N       cap on samples per mesh (1000000)\n"
    "  --seed N              sampling seed (1)\n"
    "  --json                machine-readable output on stdout (docs/eval.md)\n";

static void print_dist_json(const eval_dist_stats *d)
{
    printf("\"mean_m\": ");
    bf_json_number(stdout, d->mean, 9);
    printf(", \"median_m\": ");
    bf_json_number(stdout, d->median, 9);
    printf(", \"p90_m\": ");
    bf_json_number(stdout, d->p90, 9);
    printf(", \"rmse_m\": ");
    bf_json_number(stdout, d->rmse, 9);
    printf(", \"max_m\": ");
    bf_json_number(stdout, d->max, 9);
    printf(", \"beyond_max_dist\": %zu", d->n_beyond);
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
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (app_is_help(a)) {
            fputs(usage_text, stdout);
            return APP_EXIT_OK;
        } else if (!strcmp(a, "--json")) {
            json = true;
            continue;
        }
        static const char *const with_value[] = {"--reference", "--reconstruction", "--visible", "--threshold",
                                                 "--max-dist", "--samples-per-m2", "--max-samples", "--seed"};
        bool is_known = false;
        for (size_t k = 0; k < sizeof with_value / sizeof with_value[0]; k++) is_known |= !strcmp(a, with_value[k]);
        if (!is_known) return app_usage_error(cmd, "unknown argument '%s'", a);
        if (!val) return app_usage_error(cmd, "%s needs a value", a);
        double v;
        uint32_t u;
        if (!strcmp(a, "--reference")) {
            ref_path = val;
        } else if (!strcmp(a, "--reconstruction")) {
            rec_path = val;
        } else if (!strcmp(a, "--visible")) {
            vis_path = val;
        } else if (!strcmp(a, "--threshold") || !strcmp(a, "--max-dist") || !strcmp(a, "--samples-per-m2")) {
            if (!bf_parse_double(val, &v) || !(v > 0))
                return app_usage_error(cmd, "%s needs a positive number (got '%s')", a, val);
            if (!strcmp(a, "--threshold"))
                cfg.threshold_m = v;
            else if (!strcmp(a, "--max-dist"))
                cfg.max_dist_m = v;
            else
                cfg.samples_per_m2 = v;
        } else if (!strcmp(a, "--max-samples") || !strcmp(a, "--seed")) {
            if (!bf_parse_u32(val, &u) || (u == 0 && !strcmp(a, "--max-samples")))
                return app_usage_error(cmd, "%s needs a %s integer (got '%s')", a,
                                       strcmp(a, "--seed") ? "positive" : "non-negative", val);
            if (!strcmp(a, "--seed"))
                cfg.seed = u;
            else
                cfg.max_samples = u;
        } else {
            return app_usage_error(cmd, "unknown argument '%s'", a);
        }
        i++;
    }
    if (!ref_path || !rec_path) return app_usage_error(cmd, "needs --reference and --reconstruction");

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
        printf("{\n  \"reference\": ");
        bf_json_string(stdout, ref_path);
        printf(",\n  \"reconstruction\": ");
        bf_json_string(stdout, rec_path);
        printf(",\n  \"visible\": ");
        bf_json_string(stdout, vis_path);
        printf(",\n  \"reference_vertices\": %u,\n  \"reference_triangles\": %u,\n", ref_v, ref_t);
        printf("  \"threshold_m\": %.9g,\n  \"max_dist_m\": ", cfg.threshold_m);
        bf_json_number(stdout, cfg.max_dist_m, 9);
        printf(",\n  \"samples_per_m2\": %.9g,\n  \"max_samples\": %llu,\n  \"seed\": %llu,\n",
               cfg.samples_per_m2, (unsigned long long)cfg.max_samples, (unsigned long long)cfg.seed);
        printf("  \"accuracy\": {\"points\": %zu, \"rec_vertices\": %zu, \"rec_samples\": %zu, ",
               r.n_rec_vertices + r.n_rec_samples, r.n_rec_vertices, r.n_rec_samples);
        print_dist_json(&r.accuracy);
        printf(", \"within_threshold\": %.9g},\n", r.precision);
        printf("  \"completeness\": {\"points\": %zu, \"source\": \"%s\", \"ratio\": %.9g, ", r.n_ref_points,
               source, r.completeness);
        print_dist_json(&r.completeness_dist);
        printf("},\n  \"seconds\": %.3f,\n  \"threads\": %d\n}\n", r.seconds, bf_thread_count());
        return APP_EXIT_OK;
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
