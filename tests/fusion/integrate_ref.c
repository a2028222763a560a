/* The CPU oracle of the windowed integration of one brick (STYLE.md
 * section 1: a test oracle, not a product path). It calls the functions of
 * shaders/fusion.glsl.h that shaders/fusion_integrate.comp calls, in the
 * same order for every voxel, so GPU and CPU agree bit for bit wherever
 * no GPU division lands within its error of a decision (the margins). */
#include <math.h>
#include <string.h>

#include "fusion_ref.h"

static uint32_t voxel_bit(const uint32_t w[BRICK_WORDS], uint32_t x, uint32_t y, uint32_t z)
{
    return (w[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1u;
}

/* Confident voxel of the other sign than `front`. */
static uint32_t other_bit(const fusion_ref_brick *b, uint32_t front, uint32_t x, uint32_t y, uint32_t z)
{
    return voxel_bit(b->conf, x, y, z) & (voxel_bit(b->sign, x, y, z) ^ front);
}

/* Distance of a float to the nearest integer. */
static double edge_distance(float u) { return fabs((double)u - floor((double)u + 0.5)); }

/* Raw depth of pixel (i, j) of a ring image, or UINT32_MAX outside. */
static uint32_t raw_at(const fusion_frame *f, const uint32_t *image, int64_t i, int64_t j)
{
    if (i < 0 || j < 0 || i >= f->width || j >= f->height) return UINT32_MAX;
    uint32_t p = (uint32_t)j * f->width + (uint32_t)i;
    return fusion_depth_raw(image[p >> 1], p);
}

/* Could a GPU division moving (u, v) (pixel coordinates + 1/2) by up to
 * FUSION_REF_TOL px pick another depth? */
static bool pixel_fragile(const fusion_frame *f, const uint32_t *image, float u, float v)
{
    double du = edge_distance(u), dv = edge_distance(v);
    if (du >= FUSION_REF_TOL && dv >= FUSION_REF_TOL) return false;
    int64_t i = (int64_t)floor((double)u), j = (int64_t)floor((double)v);
    /* The other side of the nearest edge in each near direction. */
    int64_t i2 = du < FUSION_REF_TOL ? ((double)u - floor((double)u) < 0.5 ? i - 1 : i + 1) : i;
    int64_t j2 = dv < FUSION_REF_TOL ? ((double)v - floor((double)v) < 0.5 ? j - 1 : j + 1) : j;
    uint32_t r = raw_at(f, image, i, j);
    return raw_at(f, image, i2, j) != r || raw_at(f, image, i, j2) != r || raw_at(f, image, i2, j2) != r;
}

void fusion_ref_integrate(const fusion_integrate_push *pc, const fusion_frame *frames, const uint32_t *depth_ring,
                          fusion_ref_brick *b, fusion_ref_margins *margins)
{
    fusion_ref_margins mg = {.pixel = INFINITY, .sign = INFINITY, .conf = INFINITY, .error_gap = INFINITY};
    bool fragile[BRICK_VOXELS];
    uint32_t level = fusion_pos_level(b->pos);
    uint32_t cell[3] = {fusion_pos_x(b->pos), fusion_pos_y(b->pos), fusion_pos_z(b->pos)};
    float voxel_m = fusion_voxel_m(pc->chunk_m, level);
    uint32_t n_frames = pc->n_frames < FUSION_INTEGRATE_MAX_FRAMES ? pc->n_frames : FUSION_INTEGRATE_MAX_FRAMES;

    fusion_acc acc[BRICK_VOXELS];
    double abs_wd[BRICK_VOXELS];
    bool has_ramp[BRICK_VOXELS];
    uint32_t pairs = 0, sigma_um = 0;
    /* The stepping of every frame in the ring, from the first voxel centre. */
    float p0[3];
    for (int a = 0; a < 3; a++) p0[a] = fusion_voxel_centre(b->key[a], cell[a], 0, pc->chunk_m, voxel_m);
    fusion_step step[FUSION_INTEGRATE_MAX_FRAMES];
    for (uint32_t i = 0; i < n_frames; i++)
        step[i] = fusion_step_make(frames[(pc->frame_first + i) % pc->ring_slots], p0[0], p0[1], p0[2], voxel_m);
    for (uint32_t v = 0; v < BRICK_VOXELS; v++) {
        uint32_t xyz[3] = {v & 7u, (v >> 3) & 7u, v >> 6};
        acc[v] = fusion_acc_zero();
        abs_wd[v] = 0;
        has_ramp[v] = false;
        fragile[v] = false;
        for (uint32_t i = 0; i < n_frames; i++) {
            uint32_t index = pc->frame_first + i, ring = index % pc->ring_slots;
            fusion_frame f = frames[ring];
            if (f.index != index) continue;
            fusion_point c = fusion_step_point(step[i], xyz[0], xyz[1], xyz[2]);
            if (c.z > 0.0f) { /* the same float expressions as fusion_project_step */
                float u = c.x / c.z, w = c.y / c.z;
                double e = fmin(edge_distance(u), edge_distance(w));
                if (e < mg.pixel) mg.pixel = e;
                if (pixel_fragile(&f, depth_ring + (size_t)ring * pc->depth_words, u, w)) fragile[v] = true;
            }
            uint32_t pixel = fusion_project_step(c, f.width, f.height);
            if (pixel == FUSION_NONE) continue;
            uint32_t raw = fusion_depth_raw(depth_ring[(size_t)ring * pc->depth_words + (pixel >> 1)], pixel);
            fusion_obs o = fusion_observe(raw, f.depth_unit_m, c.z, pc->sigma_a, pc->sigma_b, pc->sigma_c);
            acc[v] = fusion_acc_add(acc[v], o);
            if (o.w > 0.0f) {
                abs_wd[v] += fabs((double)o.wd);
                if (o.w < 1.0f) has_ramp[v] = true;
            }
        }
        pairs += acc[v].n;
        sigma_um += acc[v].sigma_um;
        mg.n_observed += acc[v].n > 0;
    }

    float window_err = fusion_window_error(pairs, sigma_um);
    uint32_t has_conf = 0;
    for (uint32_t w = 0; w < BRICK_WORDS; w++) has_conf |= b->conf[w];
    uint32_t may_replace = fusion_may_replace(pc->set_confidence, has_conf != 0, window_err, b->error);
    if (pc->set_confidence && has_conf && pairs > 0 && isfinite(b->error) && b->error > 0)
        mg.error_gap = fabs((double)window_err - b->error) / b->error;
    float psi_conf = fusion_prior_psi(pc->prior_weight, window_err, b->error);
    /* psi_conf came from a division unless the ratio was clamped or unscaled. */
    bool psi_divided = psi_conf != pc->prior_weight * 0.25f && psi_conf != pc->prior_weight * 4.0f &&
                       psi_conf != pc->prior_weight;

    uint32_t new_sign[BRICK_WORDS] = {0}, new_conf[BRICK_WORDS] = {0}, set = 0;
    for (uint32_t v = 0; v < BRICK_VOXELS; v++) {
        uint32_t x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
        uint32_t old_sign = voxel_bit(b->sign, x, y, z), old_conf = voxel_bit(b->conf, x, y, z);
        float psi = 0.0f, phi = 0.0f;
        if (old_conf && pc->set_confidence) {
            uint32_t row_x = 0, row_y = 0, row_z = 0;
            for (uint32_t j = 0; j < 8; j++) {
                row_x |= other_bit(b, old_sign, j, y, z) << j;
                row_y |= other_bit(b, old_sign, x, j, z) << j;
                row_z |= other_bit(b, old_sign, x, y, j) << j;
            }
            psi = psi_conf;
            phi = fusion_prior_phi(old_sign, fusion_prior_steps(row_x, row_y, row_z, x, y, z), voxel_m, window_err);
        }
        uint32_t r = fusion_decide(old_sign, old_conf, acc[v], psi, phi, pc->conf_weight, pc->set_confidence,
                                   may_replace);
        if (r & FUSION_DECIDE_SIGN) new_sign[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
        if (r & FUSION_DECIDE_CONF) new_conf[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
        if (r & FUSION_DECIDE_SET) set = 1;
        /* Margins of the voxels whose sums hold a divided term, and that a
         * decision reads (an observation, or a prior that may win). */
        bool divided = has_ramp[v] || (psi > 0.0f && psi_divided);
        if (divided && acc[v].n > 0) {
            mg.n_divided++;
            double num = (double)psi * phi + (double)acc[v].sum_wd;
            double den = (double)psi + (double)acc[v].sum_w;
            double scale = fabs((double)psi * phi) + abs_wd[v];
            if (scale > 0 && fabs(num) / scale < mg.sign) mg.sign = fabs(num) / scale;
            if (scale > 0 && fabs(num) / scale < FUSION_REF_TOL) fragile[v] = true;
            if (pc->set_confidence) {
                double c = fabs(den - pc->conf_weight) / pc->conf_weight;
                if (c < mg.conf) mg.conf = c;
                if (c < FUSION_REF_TOL) fragile[v] = true;
            }
        }
        if (fragile[v]) {
            mg.fragile[brick_word(x, y, z)] |= 1u << brick_bit(x, y, z);
            mg.n_fragile++;
        }
    }
    memcpy(b->sign, new_sign, sizeof new_sign);
    memcpy(b->conf, new_conf, sizeof new_conf);
    mg.error_written = set && may_replace;
    if (mg.error_written) b->error = window_err;
    mg.n_pairs = pairs;
    mg.window_err = window_err;
    if (margins) *margins = mg;
}
