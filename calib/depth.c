/* calib: the depth camera's fixed error pattern, estimated from a sequence
 * and its trajectory, and taken out of each frame (calib.h, "depth
 * correction"; docs/calibration.md).
 *
 * Structured-light depth (Kinect v1 and its kin) carries an error that is
 * fixed in the image: vertical bands and a slow bowl of a few parts per
 * thousand (Smisek, Jancosek and Pajdla 2011, "3D with Kinect"; Herrera,
 * Kannala and Heikkila 2012). The camera carries it along as it moves, so
 * each frame's surfaces agree best with the map where the camera has not
 * moved: tracking comes up short. The estimate is the self-calibration
 * of Teichman, Miller and Thrun 2013 ("Unsupervised intrinsic calibration of
 * depth sensors via SLAM", CLAMS) in its simplest form: one multiplier per
 * cell of the image, the same at every depth. Pairs of frames some way
 * apart are brought together by the trajectory; where a point of frame a
 * lands on frame b's surface, the relative difference of the two depths is
 * b's error at the landing pixel less a's at the point's pixel. Gathered
 * per cell of the image over all pairs, a cell's mean is its own error less
 * the mean of its partners', which lie all around it from one pair to the
 * next; the multipliers take it out, and the next pass measures what is
 * left (a few passes converge). What pairs cannot see stays: the image's
 * mean (a scale error of the whole image) and, nearly, a linear ramp across
 * it (its value at a cell is the mean of its partners' on every side). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib.h"

calib_depth_config calib_depth_config_default(void)
{
    return (calib_depth_config){
        .cell_px = 16,
        .gaps = {15, 30},
        .stride = 3,
        .iterations = 10,
        .max_depth_m = 4.0f,
        .agree = 0.04f,
        .min_samples = 100,
    };
}

void calib_depth_range(const calib_depth_correction *c, float *lo, float *hi)
{
    *lo = *hi = c->mult[0];
    for (uint32_t i = 1; i < c->grid_w * c->grid_h; i++) {
        *lo = fminf(*lo, c->mult[i]);
        *hi = fmaxf(*hi, c->mult[i]);
    }
}

/* The multiplier at every pixel: bilinear between cell centres, constant
 * beyond the outer centres. */
void calib_depth_map(const calib_depth_correction *c, float *map)
{
    double half = 0.5 * c->cell_px;
    for (uint32_t y = 0; y < c->height; y++) {
        double gy = (y + 0.5 - half) / c->cell_px;
        gy = gy < 0 ? 0 : gy > c->grid_h - 1 ? c->grid_h - 1 : gy;
        uint32_t y0 = (uint32_t)gy, y1 = y0 + 1 < c->grid_h ? y0 + 1 : y0;
        double b = gy - y0;
        for (uint32_t x = 0; x < c->width; x++) {
            double gx = (x + 0.5 - half) / c->cell_px;
            gx = gx < 0 ? 0 : gx > c->grid_w - 1 ? c->grid_w - 1 : gx;
            uint32_t x0 = (uint32_t)gx, x1 = x0 + 1 < c->grid_w ? x0 + 1 : x0;
            double a = gx - x0;
            const float *r0 = c->mult + (size_t)y0 * c->grid_w, *r1 = c->mult + (size_t)y1 * c->grid_w;
            double top = r0[x0] + a * (r0[x1] - r0[x0]), bot = r1[x0] + a * (r1[x1] - r1[x0]);
            map[(size_t)y * c->width + x] = (float)(top + b * (bot - top));
        }
    }
}

void calib_depth_apply(const float *map, const uint16_t *src, uint16_t *dst, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0) {
            dst[i] = 0;
            continue;
        }
        float v = floorf(src[i] * map[i] + 0.5f);
        dst[i] = v < 1.0f ? 1 : v > 65535.0f ? 65535 : (uint16_t)v;
    }
}

/* Scratch of one pass: per cell the sums. */
/* The pairs are split into DEPTH_SLICES fixed slices, each summed on its
 * own and the slices added in order: the same file on any number of
 * threads. */
#define DEPTH_SLICES 8u

typedef struct depth_pass {
    const calib_depth_config *cfg;
    const calib_depth_frames *in;
    uint32_t gw, gh;
    const float *map;     /* the current multipliers per pixel */
    const uint32_t *pair; /* n_pairs (a, b) frame numbers */
    uint32_t n_pairs;
    double *sum;          /* DEPTH_SLICES x cells */
    uint64_t *count;
} depth_pass;

static float depth_at(const depth_pass *p, uint32_t f, size_t i)
{
    uint16_t v = p->in->depth[f][i];
    if (v == 0) return 0.0f;
    float z = (float)(v * p->map[i] / p->in->K.depth_scale);
    return z <= p->cfg->max_depth_m ? z : 0.0f;
}

/* Frame b's depth at (u, v): its inverse bilinear between the four pixels
 * around (inverse depth is linear across a plane's image), 0 where one of
 * them has none or they span more than agree (an edge). */
static float depth_between(const depth_pass *p, uint32_t b, double u, double v)
{
    uint32_t w = p->in->K.width;
    uint32_t x0 = (uint32_t)u, y0 = (uint32_t)v;
    double a = u - x0, c = v - y0;
    size_t i = (size_t)y0 * w + x0;
    float z00 = depth_at(p, b, i), z10 = depth_at(p, b, i + 1), z01 = depth_at(p, b, i + w), z11 = depth_at(p, b, i + w + 1);
    float lo = fminf(fminf(z00, z10), fminf(z01, z11)), hi = fmaxf(fmaxf(z00, z10), fmaxf(z01, z11));
    if (!(lo > 0.0f) || hi - lo >= p->cfg->agree * lo) return 0.0f;
    double inv = (1 - c) * ((1 - a) / z00 + a / z10) + c * ((1 - a) / z01 + a / z11);
    return (float)(1.0 / inv);
}

/* Each pixel of frame a seen in frame b: its point's depth in b against
 * b's depth where it lands, r = (z_b - z_a->b) / z_a->b, which is b's error
 * there less a's at the pixel. The cell of the landing point gets +r and
 * the pixel's cell -r, so each cell meets partners on every side. */
static void add_pair(const depth_pass *p, uint32_t a, uint32_t b, double *sum, uint64_t *count)
{
    const bf_intrinsics *K = &p->in->K;
    uint32_t w = K->width, h = K->height, cp = p->cfg->cell_px;
    bf_se3 Tb_inv = bf_se3_inverse(&p->in->T_wc[b]);
    bf_se3 T = bf_se3_mul(&Tb_inv, &p->in->T_wc[a]);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            float z = depth_at(p, a, (size_t)y * w + x);
            if (!(z > 0.0f)) continue;
            bf_vec3 q = bf_se3_apply(&T, bf_intrinsics_unproject(K, x, y, z));
            if (!(q.z > 0.1)) continue;
            double u = K->fx_px * q.x / q.z + K->cx_px, v = K->fy_px * q.y / q.z + K->cy_px;
            if (!(u >= 0 && v >= 0 && u < w - 1 && v < h - 1)) continue;
            float zb = depth_between(p, b, u, v);
            if (!(zb > 0.0f) || fabs(zb - q.z) >= p->cfg->agree * q.z) continue;
            double r = (zb - q.z) / q.z;
            size_t ca = (size_t)(y / cp) * p->gw + x / cp;
            size_t cb = (size_t)((uint32_t)(v + 0.5) / cp) * p->gw + (uint32_t)(u + 0.5) / cp;
            sum[cb] += r;
            count[cb]++;
            sum[ca] -= r;
            count[ca]++;
        }
}

static void add_slice(void *ctx, size_t k)
{
    const depth_pass *p = ctx;
    size_t nc = (size_t)p->gw * p->gh;
    double *sum = p->sum + k * nc;
    uint64_t *count = p->count + k * nc;
    memset(sum, 0, nc * sizeof *sum);
    memset(count, 0, nc * sizeof *count);
    for (uint32_t i = (uint32_t)k; i < p->n_pairs; i += DEPTH_SLICES) add_pair(p, p->pair[2 * i], p->pair[2 * i + 1], sum, count);
}

/* The pairs: a first frame every stride frames (by index) and its partner
 * a gap ahead, where both were given. Returns how many (pair holds 2 per). */
static uint32_t list_pairs(const calib_depth_config *cfg, const calib_depth_frames *in, uint32_t *pair)
{
    uint32_t n = 0;
    for (uint32_t g = 0; g < CALIB_DEPTH_GAPS; g++) {
        uint32_t gap = cfg->gaps[g];
        if (gap == 0) continue;
        for (uint32_t a = 0; a < in->n; a++) {
            if (in->index[a] % cfg->stride != 0) continue;
            /* Frames come in index order: the partner, if given, is ahead. */
            for (uint32_t b = a + 1; b < in->n && in->index[b] <= in->index[a] + gap; b++)
                if (in->index[b] == in->index[a] + gap) {
                    if (pair) pair[2 * n] = a, pair[2 * n + 1] = b;
                    n++;
                }
        }
    }
    return n;
}

/* One pass over every pair: the mean per cell, less the image's mean
 * (the scale stays the sensor's); cells with too few samples keep 0.
 * Returns the RMS over the measured cells; *measured their number. */
static double one_pass(depth_pass *p, double *mean, uint32_t *measured)
{
    size_t nc = (size_t)p->gw * p->gh;
    bf_parallel_for(DEPTH_SLICES, add_slice, p);
    for (uint32_t k = 1; k < DEPTH_SLICES; k++)
        for (size_t c = 0; c < nc; c++) {
            p->sum[c] += p->sum[k * nc + c];
            p->count[c] += p->count[k * nc + c];
        }
    double s = 0, n = 0;
    for (size_t c = 0; c < nc; c++)
        if (p->count[c] >= p->cfg->min_samples) {
            s += p->sum[c];
            n += (double)p->count[c];
        }
    double m = n > 0 ? s / n : 0, rr = 0;
    uint32_t k = 0;
    for (size_t c = 0; c < nc; c++) {
        mean[c] = p->count[c] >= p->cfg->min_samples ? p->sum[c] / (double)p->count[c] - m : 0.0;
        if (p->count[c] >= p->cfg->min_samples) {
            rr += mean[c] * mean[c];
            k++;
        }
    }
    *measured = k;
    return k ? sqrt(rr / k) : 0.0;
}

static bf_status check_input(const calib_depth_config *cfg, const calib_depth_frames *in)
{
    if (!cfg || !in || !in->depth || !in->T_wc || !in->index)
        return bf_fail(BF_INVALID_ARG, "calib_depth_estimate: NULL argument");
    const bf_intrinsics *K = &in->K;
    if (K->width == 0 || K->height == 0 || !(K->fx_px > 0) || K->fy_px == 0 || !(K->depth_scale > 0))
        return bf_fail(BF_INVALID_ARG, "calib_depth_estimate: bad intrinsics");
    if (cfg->cell_px < 4 || cfg->stride == 0 || cfg->iterations == 0 || !(cfg->agree > 0) || !(cfg->max_depth_m > 0))
        return bf_fail(BF_INVALID_ARG, "calib_depth_estimate: bad configuration");
    uint32_t gw = (K->width + cfg->cell_px - 1) / cfg->cell_px, gh = (K->height + cfg->cell_px - 1) / cfg->cell_px;
    if ((uint64_t)gw * gh > CALIB_DEPTH_GRID_MAX)
        return bf_fail(BF_INVALID_ARG, "calib_depth_estimate: %ux%u cells of %u px: more than %u", gw, gh,
                       cfg->cell_px, CALIB_DEPTH_GRID_MAX);
    for (uint32_t i = 1; i < in->n; i++)
        if (in->index[i] <= in->index[i - 1])
            return bf_fail(BF_INVALID_ARG, "calib_depth_estimate: frame indices must increase");
    return BF_OK;
}

bf_status calib_depth_estimate(const calib_depth_config *cfg, const calib_depth_frames *in,
                               calib_depth_correction *out)
{
    bf_status s = check_input(cfg, in);
    if (s != BF_OK) return s;
    const bf_intrinsics *K = &in->K;
    calib_depth_correction c = {
        .width = K->width,
        .height = K->height,
        .cell_px = cfg->cell_px,
        .grid_w = (K->width + cfg->cell_px - 1) / cfg->cell_px,
        .grid_h = (K->height + cfg->cell_px - 1) / cfg->cell_px,
    };
    size_t nc = (size_t)c.grid_w * c.grid_h, npx = (size_t)K->width * K->height;
    for (size_t i = 0; i < nc; i++) c.mult[i] = 1.0f;
    uint32_t n_pairs = list_pairs(cfg, in, NULL);
    if (n_pairs == 0)
        return bf_fail(BF_FORMAT, "calib_depth_estimate: no pair of frames %u or %u apart (with a first frame every %u)",
                       cfg->gaps[0], cfg->gaps[1], cfg->stride);
    depth_pass p = {.cfg = cfg, .in = in, .gw = c.grid_w, .gh = c.grid_h, .n_pairs = n_pairs};
    float *map = malloc(npx * sizeof *map);
    uint32_t *pair = malloc(2 * (size_t)n_pairs * sizeof *pair);
    p.sum = malloc(DEPTH_SLICES * nc * sizeof *p.sum);
    p.count = malloc(DEPTH_SLICES * nc * sizeof *p.count);
    double *mean = malloc(nc * sizeof *mean);
    if (!map || !pair || !p.sum || !p.count || !mean) {
        s = bf_fail(BF_NO_MEMORY, "calib_depth_estimate: %zu pixels", npx);
        goto done;
    }
    list_pairs(cfg, in, pair);
    p.map = map;
    p.pair = pair;
    uint32_t measured = 0;
    for (uint32_t it = 0; it <= cfg->iterations; it++) {
        calib_depth_map(&c, map);
        double rms = one_pass(&p, mean, &measured);
        if (it == 0) c.rms_before = rms;
        c.rms_after = rms;
        if (it == cfg->iterations) break; /* the last pass only measures */
        for (size_t k = 0; k < nc; k++) c.mult[k] = (float)(c.mult[k] / (1.0 + mean[k]));
    }
    c.n_frames = in->n;
    c.n_pairs = n_pairs;
    c.n_cells_measured = measured;
    *out = c;
done:
    free(map);
    free(pair);
    free(p.sum);
    free(p.count);
    free(mean);
    return s;
}
