/* bitfuse eval-traj: ATE and RPE of an estimated trajectory against ground
 * truth, by the rules of the TUM RGB-D benchmark tools (docs/eval.md). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "replay/replay.h"

static const char *usage_text =
    "usage: bitfuse eval-traj GT EST [--json] [--max-dt S] [--delta S | --per-frame]\n"
    "\n"
    "GT and EST are TUM trajectories (t tx ty tz qx qy qz qw, camera-to-world).\n"
    "ATE: positions associated by timestamp (|dt| < 0.02 s, TUM associate.py),\n"
    "aligned by Horn's method (rotation + translation), then rmse/mean/median/\n"
    "std/min/max of the distances (TUM evaluate_ate.py).\n"
    "RPE: relative motion error over pose pairs delta apart (TUM evaluate_rpe.py\n"
    "--fixed_delta, all pairs); by default both per second and per frame, each\n"
    "left out with a warning when the trajectories are too short for it.\n"
    "\n"
    "  --json        machine-readable output on stdout (fields in docs/eval.md)\n"
    "  --max-dt S    association tolerance in seconds (default: ATE 0.02, RPE\n"
    "                twice the median ground-truth interval, as TUM)\n"
    "  --delta S     RPE only over pairs S seconds apart\n"
    "  --per-frame   RPE only over consecutive frames\n";

static void print_stats_json(const char *name, const eval_err_stats *s, bool last)
{
    printf("      \"%s\": {\"rmse\": %.9g, \"mean\": %.9g, \"median\": %.9g, \"std\": %.9g, "
           "\"min\": %.9g, \"max\": %.9g}%s\n",
           name, s->rmse, s->mean, s->median, s->std, s->min, s->max, last ? "" : ",");
}

int cmd_eval_traj(int argc, char **argv)
{
    const char *cmd = "eval-traj", *paths[2] = {NULL, NULL};
    int n_paths = 0;
    bool json = false, per_frame_only = false, delta_given = false;
    double max_dt = 0, delta_s = 1.0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (app_is_help(a)) {
            fputs(usage_text, stdout);
            return APP_EXIT_OK;
        } else if (!strcmp(a, "--json")) {
            json = true;
        } else if (!strcmp(a, "--per-frame")) {
            per_frame_only = true;
        } else if (!strcmp(a, "--max-dt") || !strcmp(a, "--delta")) {
            double v;
            if (i + 1 >= argc || !bf_parse_double(argv[i + 1], &v) || !(v > 0))
                return app_usage_error(cmd, "%s needs a positive number of seconds", a);
            if (!strcmp(a, "--max-dt")) {
                max_dt = v;
            } else {
                delta_s = v;
                delta_given = true;
            }
            i++;
        } else if (a[0] == '-' && a[1]) {
            return app_usage_error(cmd, "unknown option '%s'", a);
        } else if (n_paths < 2) {
            paths[n_paths++] = a;
        } else {
            return app_usage_error(cmd, "too many arguments ('%s')", a);
        }
    }
    if (n_paths != 2) return app_usage_error(cmd, "needs GT and EST trajectory files");
    if (per_frame_only && delta_given) return app_usage_error(cmd, "--delta and --per-frame exclude each other");

    bf_traj gt = {0}, est = {0};
    eval_ate_result ate;
    eval_rpe_result rpe_s = {0}, rpe_f = {0};
    bool do_s = !per_frame_only, do_f = !delta_given;
    bf_status s = replay_traj_read_tum(paths[0], &gt);
    if (!s) s = replay_traj_read_tum(paths[1], &est);
    if (!s) s = eval_ate(&gt, &est, max_dt, &ate);
    /* Without --delta or --per-frame both RPEs are extras next to the ATE: a
     * sequence too short for one of them (under a second, say) leaves that
     * one out with a warning instead of failing the whole evaluation. */
    bool rpe_optional = !delta_given && !per_frame_only;
    if (!s && do_s) {
        s = eval_rpe(&gt, &est, max_dt, false, delta_s, &rpe_s);
        if (s == BF_FORMAT && rpe_optional) {
            bf_warn("RPE per %g s left out: %s", delta_s, bf_last_error());
            do_s = false;
            s = BF_OK;
        }
    }
    if (!s && do_f) {
        s = eval_rpe(&gt, &est, max_dt, true, 0, &rpe_f);
        if (s == BF_FORMAT && rpe_optional) {
            bf_warn("RPE per frame left out: %s", bf_last_error());
            do_f = false;
            s = BF_OK;
        }
    }
    size_t n_gt = gt.n, n_est = est.n;
    bf_traj_free(&gt);
    bf_traj_free(&est);
    if (s) return app_fail(cmd, s);

    bf_quat q;
    bf_vec3 t;
    bf_se3_to_qt(&ate.T_gt_est, &q, &t);
    if (json) {
        printf("{\n  \"gt\": ");
        bf_json_string(stdout, paths[0]);
        printf(",\n  \"est\": ");
        bf_json_string(stdout, paths[1]);
        printf(",\n  \"n_gt\": %zu,\n  \"n_est\": %zu,\n", n_gt, n_est);
        printf("  \"ate\": {\n    \"pairs\": %zu,\n    \"max_dt_s\": %.9g,\n", ate.n_matched,
               max_dt > 0 ? max_dt : 0.02);
        printf("    \"trans_m\": {\"rmse\": %.9g, \"mean\": %.9g, \"median\": %.9g, \"std\": %.9g, "
               "\"min\": %.9g, \"max\": %.9g},\n",
               ate.trans.rmse, ate.trans.mean, ate.trans.median, ate.trans.std, ate.trans.min, ate.trans.max);
        printf("    \"T_gt_est\": {\"t\": [%.9g, %.9g, %.9g], \"q_xyzw\": [%.9g, %.9g, %.9g, %.9g]}\n  },\n",
               t.x, t.y, t.z, q.x, q.y, q.z, q.w);
        printf("  \"rpe\": [");
        for (int k = 0; k < 2; k++) {
            if ((k == 0 && !do_s) || (k == 1 && !do_f)) continue;
            const eval_rpe_result *r = k == 0 ? &rpe_s : &rpe_f;
            printf("%s\n    {\n      \"unit\": \"%s\",\n      \"delta\": %.9g,\n      \"pairs\": %zu,\n",
                   (k == 1 && do_s) ? "," : "", k == 0 ? "s" : "frame", k == 0 ? delta_s : 1.0, r->n_pairs);
            print_stats_json("trans_m", &r->trans, false);
            print_stats_json("rot_deg", &r->rot, true);
            printf("    }");
        }
        printf("\n  ]\n}\n");
        return APP_EXIT_OK;
    }
    printf("ground truth %s: %zu poses; estimate %s: %zu poses\n", paths[0], n_gt, paths[1], n_est);
    printf("ATE (%zu pairs, |dt| < %g s, Horn-aligned)\n", ate.n_matched, max_dt > 0 ? max_dt : 0.02);
    printf("  rmse %.6f m  mean %.6f  median %.6f  std %.6f  min %.6f  max %.6f\n", ate.trans.rmse,
           ate.trans.mean, ate.trans.median, ate.trans.std, ate.trans.min, ate.trans.max);
    printf("  alignment T_gt_est: t = (%.4f, %.4f, %.4f) m, rotation %.3f deg\n", t.x, t.y, t.z,
           bf_se3_angle(&ate.T_gt_est) * 180 / M_PI);
    for (int k = 0; k < 2; k++) {
        if ((k == 0 && !do_s) || (k == 1 && !do_f)) continue;
        const eval_rpe_result *r = k == 0 ? &rpe_s : &rpe_f;
        if (k == 0)
            printf("RPE per %g s (%zu pairs)\n", delta_s, r->n_pairs);
        else
            printf("RPE per frame (%zu pairs)\n", r->n_pairs);
        printf("  trans rmse %.6f m  mean %.6f  median %.6f  std %.6f  min %.6f  max %.6f\n", r->trans.rmse,
               r->trans.mean, r->trans.median, r->trans.std, r->trans.min, r->trans.max);
        printf("  rot   rmse %.4f deg  mean %.4f  median %.4f  std %.4f  min %.4f  max %.4f\n", r->rot.rmse,
               r->rot.mean, r->rot.median, r->rot.std, r->rot.min, r->rot.max);
    }
    return APP_EXIT_OK;
}
