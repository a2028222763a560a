/* replay: line-oriented text files (index files, trajectories, camera
 * files) with messages that name the file and line. */
#include "replay_int.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

bf_status replay__text_open(replay__text *t, const char *path)
{
    char *buf;
    bf_status s = bf_read_file(path, &buf, NULL);
    if (s != BF_OK) return s;
    t->path = path;
    t->buf = t->p = buf;
    t->line = 0;
    return BF_OK;
}

void replay__text_close(replay__text *t)
{
    free(t->buf);
    t->buf = t->p = NULL;
}

static bool is_sep(char c) { return c == ' ' || c == '\t' || c == ',' || c == '\r'; }

int replay__text_next(replay__text *t, char **fields, int cap)
{
    while (*t->p) {
        char *line = t->p;
        char *eol = strchr(line, '\n');
        if (eol) {
            *eol = '\0';
            t->p = eol + 1;
        } else {
            t->p = line + strlen(line);
        }
        t->line++;
        int n = 0;
        char *c = line;
        for (;;) {
            while (*c && is_sep(*c)) c++;
            if (!*c) break;
            if (n == 0 && *c == '#') break; /* comment line */
            if (n < cap) fields[n] = c;
            n++;
            while (*c && !is_sep(*c)) c++;
            if (*c) *c++ = '\0';
        }
        if (n > 0) return n;
    }
    return -1;
}

bf_status replay__text_double(const replay__text *t, const char *s, const char *what, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end != '\0' || errno == ERANGE)
        return bf_fail(BF_FORMAT, "%s:%u: %s '%s' is not a number", t->path, t->line, what, s);
    if (!isfinite(v))
        return bf_fail(BF_FORMAT, "%s:%u: %s '%s' is not a finite number", t->path, t->line, what, s);
    *out = v;
    return BF_OK;
}

bf_status replay__pose_from_fields(const replay__text *t, char **f, bf_se3 *T_wc)
{
    static const char *const names[7] = {"tx", "ty", "tz", "qx", "qy", "qz", "qw"};
    double v[7];
    for (int k = 0; k < 7; k++) {
        bf_status s = replay__text_double(t, f[k], names[k], &v[k]);
        if (s != BF_OK) return s;
    }
    bf_quat q = {v[6], v[3], v[4], v[5]};
    double norm = sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (fabs(norm - 1.0) > 1e-3)
        return bf_fail(BF_FORMAT, "%s:%u: quaternion norm is %.6g, not 1", t->path, t->line, norm);
    *T_wc = bf_se3_from_qt(bf_quat_normalize(q), bf_v3(v[0], v[1], v[2]));
    return BF_OK;
}

bf_status replay__fail_frame(bf_status s, uint32_t frame)
{
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", bf_last_error());
    return bf_fail(s, "%s (frame %u)", msg, frame);
}

bool replay__is_dir(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}
