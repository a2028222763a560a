/* eval: the CPU ray tracer behind `bitfuse synth`.
 *
 * A frame is two passes over the rows of the image (bf_parallel_for):
 *  1. trace: one ray per pixel through the pixel centre (true pinhole:
 *     direction ((u - cx) / fx, (v - cy) / fy, 1) in the camera frame, so the
 *     ray parameter of a hit is its depth z). Keeps the noise-free depth, the
 *     incidence angle and, with the Kinect model, whether the projector sees
 *     the point (a shadow ray towards the projector, SYNTH_KINECT1_BASELINE_M
 *     along the camera's +x). Shades the colour: procedural albedo times
 *     ambient + Lambert from the scene's point light.
 *  2. sensor: turns the noise-free buffers into the raw depth image
 *     (noise.c has the model, and docs/synth.md the whole recipe).
 * Every random number is keyed by (seed, frame, pixel, stream), so the image
 * does not depend on the thread count or schedule. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "synth_int.h"

void synth_scene_shade(const synth_scene *sc, uint32_t tri, double u, double v, bf_vec3 p_w, bf_vec3 view_dir,
                       double rgb[3])
{
    const mesh_data *m = &sc->mesh;
    const uint32_t *tv = m->tri + 3 * (size_t)tri;
    bf_vec3 a = bf_v3(m->xyz[3 * tv[0]], m->xyz[3 * tv[0] + 1], m->xyz[3 * tv[0] + 2]);
    bf_vec3 b = bf_v3(m->xyz[3 * tv[1]], m->xyz[3 * tv[1] + 1], m->xyz[3 * tv[1] + 2]);
    bf_vec3 c = bf_v3(m->xyz[3 * tv[2]], m->xyz[3 * tv[2] + 1], m->xyz[3 * tv[2] + 2]);
    bf_vec3 ns = bf_v3_normalize(bf_v3_cross(bf_v3_sub(b, a), bf_v3_sub(c, a)));
    /* Shading normal: interpolated vertex normals, facing the viewer. */
    if (m->normal) {
        double w[3] = {1 - u - v, u, v};
        bf_vec3 acc = bf_v3(0, 0, 0);
        for (int k = 0; k < 3; k++) {
            const float *nn = m->normal + 3 * (size_t)tv[k];
            acc = bf_v3_add(acc, bf_v3_scale(bf_v3(nn[0], nn[1], nn[2]), w[k]));
        }
        if (bf_v3_norm(acc) > 0) ns = bf_v3_normalize(acc);
    }
    if (bf_v3_dot(ns, view_dir) > 0) ns = bf_v3_scale(ns, -1);
    bf_vec3 l = bf_v3_normalize(bf_v3_sub(sc->light_w, p_w));
    double lambert = fmax(0.0, bf_v3_dot(ns, l));
    synth__albedo(sc->tri_material[tri], sc->tri_variant[tri], p_w, rgb);
    for (int k = 0; k < 3; k++) rgb[k] *= 0.35 + 0.65 * lambert;
}

/* Depth jump, in disparity pixels, that marks a depth edge; and the chance
 * that a pixel on an edge reads nothing (the Kinect's ragged edge band). */
#define SYNTH_EDGE_DISPARITY_PX 1.0
#define SYNTH_EDGE_DROP 0.5
/* Colour sensor noise, 8-bit levels (Kinect model only). */
#define SYNTH_COLOUR_SIGMA 1.5

struct synth_renderer {
    const synth_scene *scene;
    mesh_bvh *bvh;
    synth_render_config cfg;
    uint32_t w, h;
    /* Per pixel, from the last frame. */
    double *z_m;          /* noise-free depth, 0 = no hit */
    float *cos_theta;     /* |cos| of the angle between ray and geometric normal */
    uint8_t *is_shadowed; /* the projector does not see the point */
    uint8_t *is_valid;    /* the output depth is valid */
    uint32_t *row_hit, *row_valid;
    bf_se3 T_wc;          /* pose of the last frame */
};

bf_status synth_renderer_create(const synth_scene *scene, const synth_render_config *cfg, synth_renderer **out)
{
    const bf_intrinsics *K = &cfg->K;
    if (!scene || !out || K->width == 0 || K->height == 0 || !(K->fx_px > 0) || !(K->fy_px != 0) ||
        !isfinite(K->cx_px) || !isfinite(K->cy_px) || !(K->depth_scale > 0))
        return bf_fail(BF_INVALID_ARG, "synth: invalid camera (%ux%u, fx %g, fy %g, depth scale %g)", K->width,
                       K->height, K->fx_px, K->fy_px, K->depth_scale);
    size_t n = (size_t)K->width * K->height;
    synth_renderer *r = calloc(1, sizeof *r);
    if (!r) return bf_fail(BF_NO_MEMORY, "synth: renderer");
    r->scene = scene;
    r->cfg = *cfg;
    r->w = K->width;
    r->h = K->height;
    r->z_m = calloc(n, sizeof *r->z_m);
    r->cos_theta = calloc(n, sizeof *r->cos_theta);
    r->is_shadowed = calloc(n, 1);
    r->is_valid = calloc(n, 1);
    r->row_hit = calloc(r->h, sizeof *r->row_hit);
    r->row_valid = calloc(r->h, sizeof *r->row_valid);
    if (!r->z_m || !r->cos_theta || !r->is_shadowed || !r->is_valid || !r->row_hit || !r->row_valid) {
        synth_renderer_destroy(r);
        return bf_fail(BF_NO_MEMORY, "synth: image buffers for %ux%u", K->width, K->height);
    }
    bf_status s = mesh_bvh_build(&scene->mesh, &r->bvh);
    if (s != BF_OK) {
        synth_renderer_destroy(r);
        return s;
    }
    r->T_wc = bf_se3_identity();
    *out = r;
    return BF_OK;
}

void synth_renderer_destroy(synth_renderer *r)
{
    if (!r) return;
    mesh_bvh_destroy(r->bvh);
    free(r->z_m);
    free(r->cos_theta);
    free(r->is_shadowed);
    free(r->is_valid);
    free(r->row_hit);
    free(r->row_valid);
    free(r);
}

typedef struct frame_job {
    synth_renderer *r;
    uint32_t frame;
    bf_se3 T_wc;
    bf_vec3 projector_w;
    uint16_t *depth;
    uint8_t *rgb;
} frame_job;

static inline bf_vec3 ray_dir_c(const bf_intrinsics *K, uint32_t u, uint32_t v)
{
    return bf_v3((u - K->cx_px) / K->fx_px, (v - K->cy_px) / K->fy_px, 1.0);
}

static bf_vec3 mesh_vert(const mesh_data *m, uint32_t t, int k)
{
    const float *p = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t + k];
    return bf_v3(p[0], p[1], p[2]);
}

static uint8_t to_u8(double x)
{
    x = x * 255.0 + 0.5;
    return (uint8_t)(x < 0 ? 0 : x > 255 ? 255 : x);
}

/* Pass 1: trace and shade one row. */
static void trace_row(void *ctx, size_t row)
{
    frame_job *job = ctx;
    synth_renderer *r = job->r;
    const synth_scene *sc = r->scene;
    const mesh_data *m = &sc->mesh;
    const bf_intrinsics *K = &r->cfg.K;
    bool is_kinect = r->cfg.noise == SYNTH_NOISE_KINECT1;
    uint32_t v = (uint32_t)row, hits = 0;
    for (uint32_t u = 0; u < r->w; u++) {
        size_t i = (size_t)v * r->w + u;
        bf_vec3 d = bf_se3_rotate(&job->T_wc, ray_dir_c(K, u, v));
        mesh_hit hit;
        double rgb[3] = {0.1, 0.1, 0.12}; /* background: nothing hit */
        r->z_m[i] = 0;
        r->cos_theta[i] = 0;
        r->is_shadowed[i] = 0;
        if (mesh_bvh_raycast(r->bvh, job->T_wc.t, d, 0, INFINITY, &hit)) {
            hits++;
            bf_vec3 p = bf_v3_add(job->T_wc.t, bf_v3_scale(d, hit.t));
            bf_vec3 a = mesh_vert(m, hit.tri, 0);
            bf_vec3 ng = bf_v3_normalize(bf_v3_cross(bf_v3_sub(mesh_vert(m, hit.tri, 1), a), bf_v3_sub(mesh_vert(m, hit.tri, 2), a)));
            r->z_m[i] = hit.t;
            r->cos_theta[i] = (float)(fabs(bf_v3_dot(ng, d)) / bf_v3_norm(d));
            if (is_kinect) {
                /* Shadow ray from the point to the projector: t in (eps, 1). */
                bf_vec3 to_proj = bf_v3_sub(job->projector_w, p);
                r->is_shadowed[i] = mesh_bvh_raycast(r->bvh, p, to_proj, 1e-5, 1.0 - 1e-5, NULL);
            }
            synth_scene_shade(sc, hit.tri, hit.u, hit.v, p, d, rgb);
        }
        if (job->rgb) {
            uint8_t *o = job->rgb + 3 * i;
            if (is_kinect) {
                /* Per channel the sum of four 16-bit uniforms (Irwin-Hall,
                 * variance 4/12): close to Gaussian and cheaper than
                 * Box-Muller, which only the depth noise needs exactly. */
                uint64_t key = synth__rng_key(r->cfg.seed, job->frame, (uint32_t)i, SYNTH_RNG_COLOUR);
                for (int k = 0; k < 3; k++) {
                    uint64_t h = synth__mix64(key + (uint64_t)k);
                    double sum = 0;
                    for (int j = 0; j < 4; j++) sum += (double)((h >> (16 * j)) & 0xffff) * (1.0 / 65536.0);
                    double g = (sum - 2.0) * sqrt(3.0); /* unit variance */
                    o[k] = to_u8(rgb[k] + g * SYNTH_COLOUR_SIGMA / 255.0);
                }
            } else {
                for (int k = 0; k < 3; k++) o[k] = to_u8(rgb[k]);
            }
        }
    }
    r->row_hit[v] = hits;
}

static uint16_t to_raw(double z_m, double scale)
{
    double x = z_m * scale + 0.5;
    return x >= 1.0 && x < 65536.0 ? (uint16_t)x : 0;
}

/* True if the clean depth at pixel (u, v) has a depth edge next to it. */
static bool is_depth_edge(const synth_renderer *r, uint32_t u, uint32_t v, double bf)
{
    double z = r->z_m[(size_t)v * r->w + u];
    static const int du[4] = {1, -1, 0, 0}, dv[4] = {0, 0, 1, -1};
    for (int k = 0; k < 4; k++) {
        int64_t uu = (int64_t)u + du[k], vv = (int64_t)v + dv[k];
        if (uu < 0 || vv < 0 || uu >= r->w || vv >= r->h) continue;
        double zn = r->z_m[(size_t)vv * r->w + (size_t)uu];
        if (zn <= 0 || fabs(bf / z - bf / zn) > SYNTH_EDGE_DISPARITY_PX) return true;
    }
    return false;
}

/* Pass 2: the sensor model, one row. */
static void sense_row(void *ctx, size_t row)
{
    frame_job *job = ctx;
    synth_renderer *r = job->r;
    const bf_intrinsics *K = &r->cfg.K;
    double scale = K->depth_scale, fx = K->fx_px, bf = SYNTH_KINECT1_BASELINE_M * fx;
    double cos_max = cos(SYNTH_KINECT1_MAX_THETA_DEG * M_PI / 180);
    uint32_t v = (uint32_t)row, valid = 0;
    for (uint32_t u = 0; u < r->w; u++) {
        size_t i = (size_t)v * r->w + u;
        uint16_t raw = 0;
        if (r->cfg.noise == SYNTH_NOISE_NONE) {
            raw = r->z_m[i] > 0 ? to_raw(r->z_m[i], scale) : 0;
        } else if (r->z_m[i] > 0) {
            uint32_t pix = (uint32_t)i;
            /* Lateral noise: read the scene at a displaced pixel. */
            double theta = acos(fmin(1.0, (double)r->cos_theta[i])), g0, g1;
            double sl = synth_kinect1_lateral_sigma_px(theta);
            synth__gauss2(synth__rng_key(r->cfg.seed, job->frame, pix, SYNTH_RNG_LATERAL), &g0, &g1);
            int64_t us = (int64_t)floor(u + sl * g0 + 0.5), vs = (int64_t)floor(v + sl * g1 + 0.5);
            us = us < 0 ? 0 : us >= r->w ? r->w - 1 : us;
            vs = vs < 0 ? 0 : vs >= r->h ? r->h - 1 : vs;
            size_t j = (size_t)vs * r->w + (size_t)us;
            double z = r->z_m[j], c = r->cos_theta[j];
            bool is_missing = !(z > 0) || c < cos_max || r->is_shadowed[j];
            if (!is_missing && is_depth_edge(r, (uint32_t)us, (uint32_t)vs, bf))
                is_missing = synth__u01(synth__rng_key(r->cfg.seed, job->frame, pix, SYNTH_RNG_EDGE)) < SYNTH_EDGE_DROP;
            if (!is_missing) {
                /* Axial noise (Gaussian part), then disparity quantisation on
                 * this pixel's grid (noise.c explains the split). */
                double th = acos(fmin(1.0, c)), ga, gb;
                synth__gauss2(synth__rng_key(r->cfg.seed, job->frame, pix, SYNTH_RNG_AXIAL), &ga, &gb);
                double zn = z + synth_kinect1_gauss_sigma(z, th, fx) * ga;
                double offset = synth__u01(synth__rng_key(r->cfg.seed, 0, pix, SYNTH_RNG_DISP_OFFSET));
                double zq = synth_kinect1_quantize(zn, fx, offset);
                if (zq >= SYNTH_KINECT1_Z_MIN_M && zq <= SYNTH_KINECT1_Z_MAX_M) raw = to_raw(zq, scale);
            }
        }
        job->depth[i] = raw;
        r->is_valid[i] = raw != 0;
        valid += raw != 0;
    }
    r->row_valid[v] = valid;
}

bf_status synth_render(synth_renderer *r, uint32_t frame, const bf_se3 *T_wc, uint16_t *depth, uint8_t *rgb,
                      synth_render_stats *st)
{
    if (!r || !T_wc || !depth) return bf_fail(BF_INVALID_ARG, "synth: frame %u: nothing to render into", frame);
    if (!bf_se3_is_finite(T_wc)) return bf_fail(BF_INVALID_ARG, "synth: frame %u: pose is not finite", frame);
    double t0 = bf_time_s();
    frame_job job = {r, frame, *T_wc, bf_se3_apply(T_wc, bf_v3(SYNTH_KINECT1_BASELINE_M, 0, 0)), depth, rgb};
    r->T_wc = *T_wc;
    bf_parallel_for(r->h, trace_row, &job);
    bf_parallel_for(r->h, sense_row, &job);
    if (st) {
        st->n_hit = st->n_valid = 0;
        for (uint32_t v = 0; v < r->h; v++) {
            st->n_hit += r->row_hit[v];
            st->n_valid += r->row_valid[v];
        }
        st->seconds = bf_time_s() - t0;
    }
    return BF_OK;
}

bool synth_render_clean_point(const synth_renderer *r, uint32_t u, uint32_t v, bf_vec3 *p_w)
{
    if (u >= r->w || v >= r->h) return false;
    size_t i = (size_t)v * r->w + u;
    if (!r->is_valid[i] || !(r->z_m[i] > 0)) return false;
    *p_w = bf_se3_apply(&r->T_wc, bf_v3_scale(ray_dir_c(&r->cfg.K, u, v), r->z_m[i]));
    return true;
}
