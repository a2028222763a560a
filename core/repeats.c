/* Repeated frames: a driver handing on its last image (core.h). */
#include "core.h"

#include <stdlib.h>
#include <string.h>

static bool any_depth(const uint16_t *d, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (d[i]) return true;
    return false;
}

static bf_status resize(bf_repeats *r, size_t n, uint32_t index)
{
    if (r->n == n && r->depth && r->rgb) return BF_OK;
    bf_repeats_free(r);
    r->depth = malloc(n * sizeof *r->depth);
    r->rgb = malloc(3 * n);
    if (!r->depth || !r->rgb) {
        bf_repeats_free(r);
        return bf_fail(BF_NO_MEMORY, "repeats: frame %u: %zu pixels", index, n);
    }
    r->n = n;
    return BF_OK;
}

bf_status bf_repeats_note(bf_repeats *r, const bf_frame *f, bool *depth_repeat, bool *rgb_repeat)
{
    bool dr = false, cr = false;
    if (depth_repeat) *depth_repeat = false;
    if (rgb_repeat) *rgb_repeat = false;
    if (!r || !f) return bf_fail(BF_INVALID_ARG, "bf_repeats_note: NULL argument");
    size_t n = (size_t)f->width * f->height;
    if (!n) return BF_OK; /* nothing to compare */
    bf_status s = resize(r, n, f->index);
    if (s != BF_OK) return s;
    if (f->depth && any_depth(f->depth, n)) {
        dr = r->has_depth && !memcmp(r->depth, f->depth, n * sizeof *f->depth);
        if (!dr) memcpy(r->depth, f->depth, n * sizeof *f->depth);
        r->has_depth = true;
    }
    if (f->rgb) {
        cr = r->has_rgb && !memcmp(r->rgb, f->rgb, 3 * n);
        if (!cr) memcpy(r->rgb, f->rgb, 3 * n);
    }
    r->has_rgb = f->rgb != NULL;
    if (depth_repeat) *depth_repeat = dr;
    if (rgb_repeat) *rgb_repeat = cr;
    return BF_OK;
}

void bf_repeats_free(bf_repeats *r)
{
    if (!r) return;
    free(r->depth);
    free(r->rgb);
    memset(r, 0, sizeof *r);
}
