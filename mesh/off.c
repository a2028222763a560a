/* OFF meshes (Geomview's Object File Format, as the Princeton shape
 * benchmark and CGAL's data ship them): "OFF", then "nv nf ne", nv lines of
 * x y z, nf lines of "n i0 .. i(n-1)" (polygons fanned into triangles; a
 * face may carry a colour after its indices, which is skipped). Comments
 * start with '#'. */
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "mesh.h"

/* A reader over the file's tokens that knows its line for messages. */
typedef struct off_reader {
    FILE *f;
    const char *path;
    uint32_t line;
} off_reader;

/* The next whitespace-separated token (comments skipped) into buf. */
static bool next_token(off_reader *r, char *buf, size_t n)
{
    int c;
    for (;;) {
        c = fgetc(r->f);
        if (c == EOF) return false;
        if (c == '\n') r->line++;
        if (c == '#') {
            while ((c = fgetc(r->f)) != EOF && c != '\n') {}
            if (c == EOF) return false;
            r->line++;
            continue;
        }
        if (!isspace(c)) break;
    }
    size_t k = 0;
    while (c != EOF && !isspace(c) && c != '#') {
        if (k + 1 < n) buf[k++] = (char)c;
        c = fgetc(r->f);
    }
    if (c != EOF) ungetc(c, r->f);
    buf[k] = '\0';
    return true;
}

static bf_status read_double(off_reader *r, const char *what, double *v)
{
    char tok[64], *end;
    if (!next_token(r, tok, sizeof tok)) return bf_fail(BF_FORMAT, "%s: line %u: the file ends before %s", r->path, r->line, what);
    errno = 0;
    *v = strtod(tok, &end);
    if (*end || errno || !isfinite(*v))
        return bf_fail(BF_FORMAT, "%s: line %u: %s \"%s\" is not a finite number", r->path, r->line, what, tok);
    return BF_OK;
}

static bf_status read_count(off_reader *r, const char *what, uint64_t max, uint32_t *v)
{
    char tok[64], *end;
    if (!next_token(r, tok, sizeof tok)) return bf_fail(BF_FORMAT, "%s: line %u: the file ends before %s", r->path, r->line, what);
    errno = 0;
    unsigned long long x = strtoull(tok, &end, 10);
    if (*end || errno || tok[0] == '-' || x > max)
        return bf_fail(BF_FORMAT, "%s: line %u: %s \"%s\" is not a count up to %llu", r->path, r->line, what, tok,
                       (unsigned long long)max);
    *v = (uint32_t)x;
    return BF_OK;
}

/* Skips the rest of the current line (a face's colour). */
static void skip_line(off_reader *r)
{
    int c;
    while ((c = fgetc(r->f)) != EOF && c != '\n') {}
    if (c == '\n') r->line++;
}

bf_status mesh_read_off(const char *path, mesh_data *out)
{
    memset(out, 0, sizeof *out);
    FILE *f = fopen(path, "rb");
    if (!f) return bf_fail(BF_IO, "%s: %s", path, strerror(errno));
    off_reader r = {f, path, 1};
    char tok[64];
    bf_status s = BF_OK;
    if (!next_token(&r, tok, sizeof tok) || strcmp(tok, "OFF") != 0)
        s = bf_fail(BF_FORMAT, "%s: not an OFF file (the first word is not OFF)", path);
    uint32_t nv = 0, nf = 0, ne = 0;
    if (s == BF_OK) s = read_count(&r, "the vertex count", 1u << 28, &nv);
    if (s == BF_OK) s = read_count(&r, "the face count", 1u << 28, &nf);
    if (s == BF_OK) s = read_count(&r, "the edge count", UINT32_MAX, &ne);
    /* The header's count sizes the vertex array: each vertex takes at least
     * 6 bytes of text ("0 0 0" and a separator), so the rest of the file
     * bounds it (a short file claiming 2^28 vertices would ask 3 GB). */
    struct stat st;
    long at = ftell(f);
    if (s == BF_OK && fstat(fileno(f), &st) == 0 && at >= 0 && (uint64_t)nv * 6 > (uint64_t)st.st_size - (uint64_t)at)
        s = bf_fail(BF_FORMAT, "%s: line %u: %u vertices cannot fit in the %llu bytes left (6 or more each)", path,
                    r.line, nv, (unsigned long long)((uint64_t)st.st_size - (uint64_t)at));
    if (s == BF_OK) {
        out->xyz = malloc((size_t)(nv ? nv : 1) * 12);
        if (!out->xyz) s = bf_fail(BF_NO_MEMORY, "%s: %u vertices", path, nv);
    }
    for (uint32_t i = 0; s == BF_OK && i < 3 * nv; i++) {
        double v = 0;
        s = read_double(&r, "a vertex coordinate", &v);
        if (s == BF_OK && fabs(v) > MESH_MAX_COORD)
            s = bf_fail(BF_FORMAT, "%s: line %u: vertex coordinate %g is beyond 1e9 (no scene's coordinate)", path,
                        r.line, v);
        out->xyz[i] = (float)v;
    }
    out->n_verts = nv;
    uint32_t cap = 0;
    for (uint32_t fi = 0; s == BF_OK && fi < nf; fi++) {
        uint32_t n, first = 0, prev = 0;
        s = read_count(&r, "a face's vertex count", 1u << 16, &n);
        if (s == BF_OK && n < 3) s = bf_fail(BF_FORMAT, "%s: line %u: face %u has %u vertices", path, r.line, fi, n);
        for (uint32_t k = 0; s == BF_OK && k < n; k++) {
            uint32_t idx;
            s = read_count(&r, "a vertex index", UINT32_MAX, &idx);
            if (s == BF_OK && idx >= nv)
                s = bf_fail(BF_FORMAT, "%s: line %u: face %u names vertex %u of %u", path, r.line, fi, idx, nv);
            if (s != BF_OK) break;
            if (k == 0) first = idx;
            if (k >= 2) { /* a fan from the first vertex */
                if (out->n_tris == cap) {
                    cap = cap ? 2 * cap : 1024;
                    uint32_t *t = realloc(out->tri, (size_t)cap * 12);
                    if (!t) {
                        s = bf_fail(BF_NO_MEMORY, "%s: %u triangles", path, cap);
                        break;
                    }
                    out->tri = t;
                }
                uint32_t *t = out->tri + 3 * (size_t)out->n_tris++;
                t[0] = first, t[1] = prev, t[2] = idx;
            }
            prev = idx;
        }
        if (s == BF_OK) skip_line(&r);
    }
    fclose(f);
    if (s != BF_OK) mesh_free(out);
    return s;
}

bf_status mesh_read(const char *path, mesh_data *out)
{
    size_t n = strlen(path);
    if (n > 4 && strcasecmp(path + n - 4, ".off") == 0) return mesh_read_off(path, out);
    return mesh_read_ply(path, out);
}
