/* bitfuse eval-traj: ATE and RPE of an estimated trajectory against ground
 * truth, by the rules of the TUM RGB-D benchmark tools (docs/eval.md). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "replay/replay.h"

static const char usage_text[] =
    "usage: bitfuse eval-traj GT EST [--json] [--max-dt S] [--delta S | --per-frame]\n"
    "\n"
    "GT and EST are TUM trajectories (t tx ty tz qx qy qz qw, camera-to-world).\n"
    "ATE: positions associated by timestamp (|dt| < 0.02 s, TUM associate.py),\n"
    "aligned by Horn's method (rotation + translation), then rmse/mean/median/\n"
    "std/min/max of the distances (TUM evaluate_ate.py).\n"
    "RPE: relative motion error over pose pairs delta apart (TUM evaluate_rpe.py\n"
    "--fixed_delta, all pairs); by default both per second and per frame, each\n"
    "left out with a warning when the trajectories are too short for it.\n";

static void json_err_stats(cJSON *parent, const char *name, const eval_err_stats *s)
{
    cJSON *o = app_json_object(parent, name);
    cJSON_AddNumberToObject(o, "rmse", s->rmse);
    cJSON_AddNumberToObject(o, "mean", s->mean);
    cJSON_AddNumberToObject(o, "median", s->median);
    cJSON_AddNumberToObject(o, "std", s->std);
    cJSON_AddNumberToObject(o, "min", s->min);
    cJSON_AddNumberToObject(o, "max", s->max);
}

static cJSON *rpe_json(const char *unit, double delta, const eval_rpe_result *r)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "unit", unit);
    cJSON_AddNumberToObject(o, "delta", delta);
    cJSON_AddNumberToObject(o, "pairs", (double)r->n_pairs);
    cJSON_AddNumberToObject(o, "max_dt_s", r->max_dt_s);
    json_err_stats(o, "trans_m", &r->trans);
    json_err_stats(o, "rot_deg", &r->rot);
    return o;
}

int cmd_eval_traj(int argc, char **argv)
{
    const char *cmd = "eval-traj", *paths[2] = {NULL, NULL};
    bool json = false, per_frame_only = false;
    double max_dt = 0, delta_s = 0;
    const app_option own[] = {
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "machine-readable output on stdout (fields in docs/eval.md)"),
        APP_OPT("--max-dt", APP_OPT_DOUBLE, &max_dt, "S",
                "association tolerance in seconds (default: ATE 0.02, RPE twice the median ground-truth "
                "interval, as TUM)",
                .min_open = true, .no_default = true),
        APP_OPT("--delta", APP_OPT_DOUBLE, &delta_s, "S", "RPE only over pairs S seconds apart", .min_open = true,
                .no_default = true),
        APP_OPT("--per-frame", APP_OPT_FLAG, &per_frame_only, NULL, "RPE only over consecutive frames"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = usage_text, .tables = tables, .positional = paths, .min_positional = 2,
        .max_positional = 2, .positional_missing = "needs GT and EST trajectory files",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 a trajectory unreadable or malformed, or too few poses "
                  "matched in time,\n5 standard output could not be written\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    bool delta_given = delta_s > 0;
    if (!delta_given) delta_s = 1.0;
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
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "gt", paths[0]);
        cJSON_AddStringToObject(o, "est", paths[1]);
        cJSON_AddNumberToObject(o, "n_gt", (double)n_gt);
        cJSON_AddNumberToObject(o, "n_est", (double)n_est);
        cJSON *a = app_json_object(o, "ate");
        cJSON_AddNumberToObject(a, "pairs", (double)ate.n_matched);
        cJSON_AddNumberToObject(a, "max_dt_s", max_dt > 0 ? max_dt : 0.02);
        json_err_stats(a, "trans_m", &ate.trans);
        cJSON *T = app_json_object(a, "T_gt_est");
        app_json_numbers(T, "t", (double[]){t.x, t.y, t.z}, 3);
        app_json_numbers(T, "q_xyzw", (double[]){q.x, q.y, q.z, q.w}, 4);
        cJSON *rpe = cJSON_AddArrayToObject(o, "rpe");
        if (do_s) cJSON_AddItemToArray(rpe, rpe_json("s", delta_s, &rpe_s));
        if (do_f) cJSON_AddItemToArray(rpe, rpe_json("frame", 1.0, &rpe_f));
        return (s = app_json_print(o)) == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
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
            printf("RPE per %g s (%zu pairs, |dt| <= %g s)\n", delta_s, r->n_pairs, r->max_dt_s);
        else
            printf("RPE per frame (%zu pairs, |dt| <= %g s)\n", r->n_pairs, r->max_dt_s);
        printf("  trans rmse %.6f m  mean %.6f  median %.6f  std %.6f  min %.6f  max %.6f\n", r->trans.rmse,
               r->trans.mean, r->trans.median, r->trans.std, r->trans.min, r->trans.max);
        printf("  rot   rmse %.4f deg  mean %.4f  median %.4f  std %.4f  min %.4f  max %.4f\n", r->rot.rmse,
               r->rot.mean, r->rot.median, r->rot.std, r->rot.min, r->rot.max);
    }
    return APP_EXIT_OK;
}
