/* replay: line-oriented text files (index files, trajectories, camera
 * files) with messages that name the file and line. */
#include "replay_int.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

void replay__text_begin(replay__text *t, const char *path, char *text)
{
    /* An editor's UTF-8 byte order mark is no part of the first field, and
     * a line ended by a lone CR (classic Mac) is a line. */
    text += bf_bom_bytes(text, strlen(text));
    for (char *c = text; *c; c++)
        if (*c == '\r' && c[1] != '\n') *c = '\n';
    t->path = path;
    t->p = text;
    t->line = 0;
}

bf_status replay__text_nul(const char *path, const char *text, size_t len)
{
    const char *nul = memchr(text, '\0', len);
    if (!nul) return BF_OK;
    unsigned line = 1;
    for (const char *c = text; c < nul; c++) line += *c == '\n' || (*c == '\r' && c + 1 < nul && c[1] != '\n');
    return bf_fail(BF_FORMAT, "%s:%u: a NUL byte (byte %zu): not a text file, or one damaged", path, line,
                   (size_t)(nul - text));
}

bf_status replay__text_open(replay__text *t, const char *path)
{
    char *buf;
    size_t len;
    bf_status s = bf_read_file(path, &buf, &len);
    if (s != BF_OK) return s;
    if ((s = replay__text_nul(path, buf, len)) != BF_OK) {
        free(buf);
        return s;
    }
    t->buf = buf;
    replay__text_begin(t, path, buf);
    t->n_normalised = t->normalised_line = t->n_repeats = t->repeat_line = 0;
    t->normalised_norm = 0;
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
    /* Decimal only: strtod also reads C's hex floats (0x1p-3), which no
     * dataset writes and TUM's tools refuse. */
    if (end == s || *end != '\0' || errno == ERANGE || strpbrk(s, "xX"))
        return bf_fail(BF_FORMAT, "%s:%u: %s '%s' is not a number", t->path, t->line, what, s);
    if (!isfinite(v))
        return bf_fail(BF_FORMAT, "%s:%u: %s '%s' is not a finite number", t->path, t->line, what, s);
    *out = v;
    return BF_OK;
}

bf_status replay__pose_from_fields(replay__text *t, char **f, bf_se3 *T_wc)
{
    static const char *const names[7] = {"tx", "ty", "tz", "qx", "qy", "qz", "qw"};
    double v[7];
    for (int k = 0; k < 7; k++) {
        bf_status s = replay__text_double(t, f[k], names[k], &v[k]);
        if (s != BF_OK) return s;
        /* No camera is a million kilometres out: such a value is corrupt,
         * and its square overflows every error measure. */
        if (k < 3 && fabs(v[k]) > REPLAY_MAX_POSITION_M)
            return bf_fail(BF_FORMAT, "%s:%u: %s %g m is beyond 1e9 m (no camera's position)", t->path, t->line,
                           names[k], v[k]);
    }
    bf_quat q = {v[6], v[3], v[4], v[5]};
    double norm2 = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z;
    /* TUM's evaluate_rpe.py (transform44) treats |q|^2 < 4 eps as no rotation: unusable. */
    if (!(norm2 >= 4 * DBL_EPSILON))
        return bf_fail(BF_FORMAT, "%s:%u: quaternion (%g %g %g %g) is zero: no rotation", t->path, t->line, q.x, q.y,
                       q.z, q.w);
    if (!isfinite(norm2)) {
        /* Squares of huge components overflow, and q / inf is no
         * rotation: scaled by the largest component first. */
        double m = fmax(fmax(fabs(q.w), fabs(q.x)), fmax(fabs(q.y), fabs(q.z)));
        q = (bf_quat){q.w / m, q.x / m, q.y / m, q.z / m};
        double n1 = sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
        q = (bf_quat){q.w / n1, q.x / n1, q.y / n1, q.z / n1};
        norm2 = 1.0;
        if (t->n_normalised++ == 0) {
            t->normalised_line = t->line;
            t->normalised_norm = m * n1;
        }
    }
    double norm = sqrt(norm2);
    if (fabs(norm - 1.0) > 1e-3 && t->n_normalised++ == 0) {
        t->normalised_line = t->line;
        t->normalised_norm = norm;
    }
    q = (bf_quat){q.w / norm, q.x / norm, q.y / norm, q.z / norm};
    *T_wc = bf_se3_from_qt(q, bf_v3(v[0], v[1], v[2]));
    return BF_OK;
}

void replay__text_note_repeat(replay__text *t)
{
    if (t->n_repeats++ == 0) t->repeat_line = t->line;
}

void replay__text_warn(const replay__text *t)
{
    if (t->n_repeats)
        bf_warn("%s:%u: timestamp repeats the previous line's: the first kept, this line ignored (%u such line%s in "
                "the file)",
                t->path, t->repeat_line, t->n_repeats, t->n_repeats == 1 ? "" : "s");
    if (t->n_normalised)
        bf_warn("%s:%u: quaternion norm is %.6g, not 1: normalised (%u such line%s in the file)", t->path,
                t->normalised_line, t->normalised_norm, t->n_normalised, t->n_normalised == 1 ? "" : "s");
}

bool replay__principal_point_is_off(const bf_intrinsics *K, uint32_t w, uint32_t h)
{
    return !(fabs(K->cx_px - 0.5 * (w - 1.0)) <= 0.25 * w && fabs(K->cy_px - 0.5 * (h - 1.0)) <= 0.25 * h);
}

bf_status replay__camera_fits(const bf_intrinsics *K, uint32_t w, uint32_t h, const char *path, const char *from,
                              bool from_option)
{
    bf_status s = from_option ? BF_INVALID_ARG : BF_FORMAT;
    if (w < 2 || h < 2 || w > 8192 || h > 8192)
        return bf_fail(BF_FORMAT, "%s: images of %ux%u: bitfuse takes 2 to 8192 pixels a side", path, w, h);
    /* The rays of the image's edges within 85 degrees of the optical axis
     * along either image axis: the edges at most tan(85) |f| from the
     * principal point (a field of view over 170 degrees, or a principal
     * point so far out that the rays graze the image plane, spread the map
     * over thousands of chunks). */
    const double tan_wide = tan(85.0 * M_PI / 180.0), tan_narrow = tan(0.05 * M_PI / 180.0);
    double fx = fabs(K->fx_px), fy = fabs(K->fy_px);
    double ox = fmax(fabs(K->cx_px + 0.5), fabs(K->cx_px + 0.5 - w)), oy = fmax(fabs(K->cy_px + 0.5), fabs(K->cy_px + 0.5 - h));
    if (!(ox <= tan_wide * fx && oy <= tan_wide * fy))
        return bf_fail(s, "%s: the camera (fx %g, fy %g, cx %g, cy %g px, from %s) sees the edges of its %ux%u images "
                          "more than 85 degrees off its axis: not a depth camera for them",
                       path, K->fx_px, K->fy_px, K->cx_px, K->cy_px, from, w, h);
    /* A field of view under 0.1 degree across the image: no depth camera's. */
    if (!(fx <= 0.5 * w / tan_narrow && fy <= 0.5 * h / tan_narrow))
        return bf_fail(s, "%s: the camera's focal lengths (fx %g, fy %g px, from %s) give a field of view under 0.1 "
                          "degree across its %ux%u images: not a depth camera's",
                       path, K->fx_px, K->fy_px, from, w, h);
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
