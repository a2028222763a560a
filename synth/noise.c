/* eval: the Kinect v1 depth sensor model of the synthetic sequences.
 *
 * Source: C. V. Nguyen, S. Izadi, D. Lovell, "Modeling Kinect sensor noise
 * for improved 3D reconstruction and tracking", 3DIMPVT 2012. They fit, from
 * a plane seen at 0.5-3 m and 0-80 degrees:
 *   axial   sigma_z(z, theta) = 0.0012 + 0.0019 (z - 0.4)^2             (m)
 *           + 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2  for theta > 60 deg
 *   lateral sigma_L(theta)    = 0.8 + 0.035 theta / (pi/2 - theta)      (pixels)
 * Their sigma_z is measured on real depth maps, so it already contains the
 * disparity quantisation. The Kinect v1 measures disparity against its
 * projector (baseline ~7.5 cm) in 1/8 pixel steps (Khoshelham and Elberink,
 * "Accuracy and resolution of Kinect depth data", Sensors 2012), so the
 * depth step at z is q(z) = z^2 * (1/8) / (baseline * f).
 *
 * How the total matches the model: the renderer adds a Gaussian of
 * sigma_g = sqrt(sigma_z^2 - q^2 / 12) to the depth, then quantises the
 * disparity. If the quantisation error is uniform on [-q/2, q/2] and
 * independent of the Gaussian, the variances add to exactly sigma_z^2. That
 * holds only when the true depth falls at a uniformly random place between
 * two levels: with one global grid (f = 525) a plane at exactly 2 m
 * (disparity 157.5 steps, half-way between two levels) reads 7 % too noisy
 * and one at 3 m (105 steps, on a level) 7.5 % too quiet, because sigma_g is
 * only about 0.4 q there (simulated; at 1 m, sigma_g = 0.5 q, within 1 %). So each pixel quantises on its own grid, shifted by a fixed random
 * fraction of a step (a per-pixel offset that does not change from frame to
 * frame, like a real sensor's per-pixel sub-pixel matching bias): a pixel's
 * readings still jump between a few fixed levels, and over pixels the error
 * variance is sigma_g^2 + q^2 / 12 = sigma_z^2 for every distance. */
#include <math.h>

#include "synth.h"

double synth_kinect1_axial_sigma(double z_m, double theta_rad)
{
    double s = 0.0012 + 0.0019 * (z_m - 0.4) * (z_m - 0.4);
    if (theta_rad > M_PI / 3 && theta_rad < M_PI / 2) {
        double r = theta_rad / (M_PI / 2 - theta_rad);
        s += 0.0001 / sqrt(z_m) * r * r;
    }
    return s;
}

double synth_kinect1_lateral_sigma_px(double theta_rad)
{
    if (theta_rad < 0) theta_rad = 0;
    if (theta_rad > 1.5) theta_rad = 1.5; /* the formula diverges at pi/2 */
    return 0.8 + 0.035 * theta_rad / (M_PI / 2 - theta_rad);
}

double synth_kinect1_depth_step(double z_m, double fx_px)
{
    return z_m * z_m * SYNTH_KINECT1_DISP_STEP_PX / (SYNTH_KINECT1_BASELINE_M * fx_px);
}

double synth_kinect1_gauss_sigma(double z_m, double theta_rad, double fx_px)
{
    double s = synth_kinect1_axial_sigma(z_m, theta_rad), q = synth_kinect1_depth_step(z_m, fx_px);
    double v = s * s - q * q / 12.0;
    /* Positive over the whole range (at 4.5 m and f = 525 the quantisation
     * holds 31 % of the variance), but keep a floor for exotic intrinsics. */
    return v > 0 ? sqrt(v) : 0;
}

double synth_kinect1_quantize(double z_m, double fx_px, double offset)
{
    if (!(z_m > 0)) return 0;
    double bf = SYNTH_KINECT1_BASELINE_M * fx_px;
    double d_steps = bf / z_m / SYNTH_KINECT1_DISP_STEP_PX;
    double k = floor(d_steps - offset + 0.5);
    double d_q = (k + offset) * SYNTH_KINECT1_DISP_STEP_PX;
    return d_q > 0 ? bf / d_q : 0;
}
