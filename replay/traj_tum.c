/* replay: trajectories in the TUM RGB-D benchmark's text format
 * ("t tx ty tz qx qy qz qw", camera-to-world; Sturm et al. 2012). */
#include "replay_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

bf_status replay_traj_read_tum(const char *path, bf_traj *out)
{
    replay__text txt;
    bf_status s = replay__text_open(&txt, path);
    if (s != BF_OK) return s;
    bf_traj tr = {0};
    char *f[8];
    int n;
    while ((n = replay__text_next(&txt, f, 8)) >= 0) {
        if (n != 8) {
            s = bf_fail(BF_FORMAT, "%s:%u: expected 8 fields (t tx ty tz qx qy qz qw), found %d", path,
                        txt.line, n);
            goto fail;
        }
        double t;
        bf_se3 T;
        if ((s = replay__text_double(&txt, f[0], "timestamp", &t))) goto fail;
        if ((s = replay__pose_from_fields(&txt, f + 1, &T))) goto fail;
        /* A repeated stamp (TUM's own rgbd_dataset_freiburg2_desk has one):
         * the first is kept, as a reader walking the file in order would. */
        if (tr.n > 0 && t == tr.t_s[tr.n - 1]) {
            replay__text_note_repeat(&txt);
            continue;
        }
        if (tr.n > 0 && !(t > tr.t_s[tr.n - 1])) {
            s = bf_fail(BF_FORMAT, "%s:%u: timestamp %.6f is before the previous one (%.6f)", path, txt.line, t,
                        tr.t_s[tr.n - 1]);
            goto fail;
        }
        if ((s = bf_traj_push(&tr, t, &T))) goto fail;
    }
    if (tr.n == 0) {
        s = bf_fail(BF_FORMAT, "%s: no poses in the file", path);
        goto fail;
    }
    replay__text_warn(&txt);
    replay__text_close(&txt);
    *out = tr;
    return BF_OK;
fail:
    bf_traj_free(&tr);
    replay__text_close(&txt);
    return s;
}

/* The fewest decimals, 6 to 9, that read back as the same double: a TUM
 * time of 1305031102.6659 prints as .665900, not as the .665899992 its
 * double holds at nine; a time no such form reproduces keeps nine. */
static int time_decimals(double t)
{
    char s[64];
    for (int p = 6; p < 9; p++) {
        snprintf(s, sizeof s, "%.*f", p, t);
        if (strtod(s, NULL) == t) return p;
    }
    return 9;
}

bf_status replay_traj_write_tum(const char *path, const bf_traj *traj)
{
    /* One line is at most 8 numbers of ~30 characters. */
    size_t cap = 128 + traj->n * 8 * 32;
    char *buf = bf_malloc(cap);
    if (!buf) return bf_fail(BF_NO_MEMORY, "%s: %zu poses", path, traj->n);
    size_t len = (size_t)snprintf(buf, cap, "# timestamp tx ty tz qx qy qz qw (camera-to-world, metres)\n");
    for (size_t i = 0; i < traj->n; i++) {
        if (!bf_se3_is_finite(&traj->T_wc[i]) || !isfinite(traj->t_s[i])) {
            free(buf);
            return bf_fail(BF_INVALID_ARG, "%s: pose %zu is not finite", path, i);
        }
        bf_quat q;
        bf_vec3 t;
        bf_se3_to_qt(&traj->T_wc[i], &q, &t);
        if (q.w < 0) q = (bf_quat){-q.w, -q.x, -q.y, -q.z};
        int n = snprintf(buf + len, cap - len, "%.*f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", time_decimals(traj->t_s[i]),
                         traj->t_s[i], t.x, t.y, t.z, q.x, q.y, q.z, q.w);
        if (n < 0 || (size_t)n >= cap - len) {
            free(buf);
            return bf_fail(BF_INVALID_ARG, "%s: pose %zu does not fit the line format", path, i);
        }
        len += (size_t)n;
    }
    bf_status s = bf_write_file_atomic(path, buf, len);
    free(buf);
    return s;
}


