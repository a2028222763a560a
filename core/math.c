/* Vectors, quaternions and SE(3) in double precision. */
#include "core.h"

#include <math.h>
#include <string.h>

double bf_v3_norm(bf_vec3 a) { return sqrt(bf_v3_dot(a, a)); }

bf_vec3 bf_v3_normalize(bf_vec3 a)
{
    double n = bf_v3_norm(a);
    return n > 0 ? bf_v3_scale(a, 1.0 / n) : a;
}

bf_quat bf_quat_identity(void) { bf_quat q = {1, 0, 0, 0}; return q; }

bf_quat bf_quat_mul(bf_quat a, bf_quat b)
{
    bf_quat r = {
        a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
        a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
    };
    return r;
}

bf_quat bf_quat_conj(bf_quat q) { bf_quat r = {q.w, -q.x, -q.y, -q.z}; return r; }

bf_quat bf_quat_normalize(bf_quat q)
{
    double n = sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    if (!(n > 0)) return bf_quat_identity();
    bf_quat r = {q.w / n, q.x / n, q.y / n, q.z / n};
    return r;
}

bf_vec3 bf_quat_rotate(bf_quat q, bf_vec3 v)
{
    double R[3][3];
    bf_quat_to_mat(q, R);
    return bf_v3(R[0][0] * v.x + R[0][1] * v.y + R[0][2] * v.z,
                 R[1][0] * v.x + R[1][1] * v.y + R[1][2] * v.z,
                 R[2][0] * v.x + R[2][1] * v.y + R[2][2] * v.z);
}

bf_quat bf_quat_from_axis_angle(bf_vec3 axis, double angle_rad)
{
    bf_vec3 a = bf_v3_normalize(axis);
    double s = sin(0.5 * angle_rad);
    bf_quat q = {cos(0.5 * angle_rad), a.x * s, a.y * s, a.z * s};
    return q;
}

bf_quat bf_quat_slerp(bf_quat a, bf_quat b, double s)
{
    double d = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
    if (d < 0) { /* shortest path: q and -q are the same rotation */
        b.w = -b.w; b.x = -b.x; b.y = -b.y; b.z = -b.z;
        d = -d;
    }
    double wa, wb;
    if (d > 0.9995) { /* nearly parallel: lerp avoids dividing by sin(~0) */
        wa = 1 - s;
        wb = s;
    } else {
        double th = acos(d), st = sin(th);
        wa = sin((1 - s) * th) / st;
        wb = sin(s * th) / st;
    }
    bf_quat r = {wa * a.w + wb * b.w, wa * a.x + wb * b.x, wa * a.y + wb * b.y, wa * a.z + wb * b.z};
    return bf_quat_normalize(r);
}

double bf_quat_angle(bf_quat q)
{
    q = bf_quat_normalize(q);
    double v = sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    /* atan2 stays accurate near 0 and pi where acos(w) does not. */
    return 2.0 * atan2(v, fabs(q.w));
}

void bf_quat_to_mat(bf_quat q, double R[3][3])
{
    q = bf_quat_normalize(q);
    double w = q.w, x = q.x, y = q.y, z = q.z;
    R[0][0] = 1 - 2 * (y * y + z * z);
    R[0][1] = 2 * (x * y - w * z);
    R[0][2] = 2 * (x * z + w * y);
    R[1][0] = 2 * (x * y + w * z);
    R[1][1] = 1 - 2 * (x * x + z * z);
    R[1][2] = 2 * (y * z - w * x);
    R[2][0] = 2 * (x * z - w * y);
    R[2][1] = 2 * (y * z + w * x);
    R[2][2] = 1 - 2 * (x * x + y * y);
}

bf_quat bf_quat_from_mat(const double R[3][3])
{
    double tr = R[0][0] + R[1][1] + R[2][2];
    bf_quat q;
    if (tr > 0) {
        double s = 2 * sqrt(1 + tr);
        q.w = 0.25 * s;
        q.x = (R[2][1] - R[1][2]) / s;
        q.y = (R[0][2] - R[2][0]) / s;
        q.z = (R[1][0] - R[0][1]) / s;
    } else if (R[0][0] > R[1][1] && R[0][0] > R[2][2]) {
        double s = 2 * sqrt(1 + R[0][0] - R[1][1] - R[2][2]);
        q.w = (R[2][1] - R[1][2]) / s;
        q.x = 0.25 * s;
        q.y = (R[0][1] + R[1][0]) / s;
        q.z = (R[0][2] + R[2][0]) / s;
    } else if (R[1][1] > R[2][2]) {
        double s = 2 * sqrt(1 + R[1][1] - R[0][0] - R[2][2]);
        q.w = (R[0][2] - R[2][0]) / s;
        q.x = (R[0][1] + R[1][0]) / s;
        q.y = 0.25 * s;
        q.z = (R[1][2] + R[2][1]) / s;
    } else {
        double s = 2 * sqrt(1 + R[2][2] - R[0][0] - R[1][1]);
        q.w = (R[1][0] - R[0][1]) / s;
        q.x = (R[0][2] + R[2][0]) / s;
        q.y = (R[1][2] + R[2][1]) / s;
        q.z = 0.25 * s;
    }
    if (q.w < 0) { q.w = -q.w; q.x = -q.x; q.y = -q.y; q.z = -q.z; }
    return bf_quat_normalize(q);
}

bf_se3 bf_se3_identity(void)
{
    bf_se3 T;
    memset(&T, 0, sizeof T);
    T.R[0][0] = T.R[1][1] = T.R[2][2] = 1;
    return T;
}

bf_se3 bf_se3_from_qt(bf_quat q, bf_vec3 t)
{
    bf_se3 T;
    bf_quat_to_mat(q, T.R);
    T.t = t;
    return T;
}

void bf_se3_to_qt(const bf_se3 *T, bf_quat *q, bf_vec3 *t)
{
    *q = bf_quat_from_mat(T->R);
    *t = T->t;
}

bf_vec3 bf_se3_rotate(const bf_se3 *T, bf_vec3 v)
{
    return bf_v3(T->R[0][0] * v.x + T->R[0][1] * v.y + T->R[0][2] * v.z,
                 T->R[1][0] * v.x + T->R[1][1] * v.y + T->R[1][2] * v.z,
                 T->R[2][0] * v.x + T->R[2][1] * v.y + T->R[2][2] * v.z);
}

bf_vec3 bf_se3_apply(const bf_se3 *T, bf_vec3 p) { return bf_v3_add(bf_se3_rotate(T, p), T->t); }

bf_se3 bf_se3_mul(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 C;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            C.R[i][j] = A->R[i][0] * B->R[0][j] + A->R[i][1] * B->R[1][j] + A->R[i][2] * B->R[2][j];
    C.t = bf_se3_apply(A, B->t);
    return C;
}

bf_se3 bf_se3_inverse(const bf_se3 *T)
{
    bf_se3 I;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) I.R[i][j] = T->R[j][i];
    I.t = bf_v3_scale(bf_se3_rotate(&I, T->t), -1);
    return I;
}

static void skew(bf_vec3 w, double S[3][3])
{
    S[0][0] = 0;    S[0][1] = -w.z; S[0][2] = w.y;
    S[1][0] = w.z;  S[1][1] = 0;    S[1][2] = -w.x;
    S[2][0] = -w.y; S[2][1] = w.x;  S[2][2] = 0;
}

/* Coefficients A = sin(th)/th, B = (1-cos th)/th^2, C = (th - sin th)/th^3
 * with Taylor series near zero, where the closed forms lose all digits. */
static void exp_coeffs(double th, double *A, double *B, double *C)
{
    double th2 = th * th;
    if (th < 1e-4) {
        *A = 1 - th2 / 6;
        *B = 0.5 - th2 / 24;
        *C = 1.0 / 6 - th2 / 120;
    } else {
        *A = sin(th) / th;
        *B = (1 - cos(th)) / th2;
        *C = (th - sin(th)) / (th2 * th);
    }
}

bf_se3 bf_se3_exp(const double xi[6])
{
    bf_vec3 v = bf_v3(xi[0], xi[1], xi[2]), w = bf_v3(xi[3], xi[4], xi[5]);
    double th = bf_v3_norm(w), A, B, C, S[3][3], S2[3][3];
    exp_coeffs(th, &A, &B, &C);
    skew(w, S);
    bf_se3 T;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            S2[i][j] = S[i][0] * S[0][j] + S[i][1] * S[1][j] + S[i][2] * S[2][j];
    double V[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double I = i == j;
            T.R[i][j] = I + A * S[i][j] + B * S2[i][j];
            V[i][j] = I + B * S[i][j] + C * S2[i][j];
        }
    T.t = bf_v3(V[0][0] * v.x + V[0][1] * v.y + V[0][2] * v.z,
                V[1][0] * v.x + V[1][1] * v.y + V[1][2] * v.z,
                V[2][0] * v.x + V[2][1] * v.y + V[2][2] * v.z);
    return T;
}

/* Solves the 3x3 system M x = b by Cramer's rule (M well conditioned here). */
static bf_vec3 solve3(double M[3][3], bf_vec3 b)
{
    double d = M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) -
               M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
               M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
    double bb[3] = {b.x, b.y, b.z}, x[3];
    for (int k = 0; k < 3; k++) {
        double N[3][3];
        memcpy(N, M, sizeof N);
        for (int i = 0; i < 3; i++) N[i][k] = bb[i];
        x[k] = (N[0][0] * (N[1][1] * N[2][2] - N[1][2] * N[2][1]) -
                N[0][1] * (N[1][0] * N[2][2] - N[1][2] * N[2][0]) +
                N[0][2] * (N[1][0] * N[2][1] - N[1][1] * N[2][0])) / d;
    }
    return bf_v3(x[0], x[1], x[2]);
}

void bf_se3_log(const bf_se3 *T, double xi[6])
{
    bf_quat q = bf_quat_from_mat(T->R); /* w >= 0, so the angle is in [0, pi] */
    double vn = sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    double th = 2 * atan2(vn, q.w);
    bf_vec3 w = vn > 1e-12 ? bf_v3_scale(bf_v3(q.x, q.y, q.z), th / vn)
                           : bf_v3_scale(bf_v3(q.x, q.y, q.z), 2.0); /* th ~ 2 vn */
    double A, B, C, S[3][3], V[3][3];
    exp_coeffs(th, &A, &B, &C);
    skew(w, S);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double s2 = S[i][0] * S[0][j] + S[i][1] * S[1][j] + S[i][2] * S[2][j];
            V[i][j] = (i == j) + B * S[i][j] + C * s2;
        }
    bf_vec3 v = solve3(V, T->t);
    xi[0] = v.x; xi[1] = v.y; xi[2] = v.z;
    xi[3] = w.x; xi[4] = w.y; xi[5] = w.z;
}

double bf_se3_angle(const bf_se3 *T) { return bf_quat_angle(bf_quat_from_mat(T->R)); }

bf_se3 bf_se3_interpolate(const bf_se3 *A, const bf_se3 *B, double s)
{
    bf_quat qa = bf_quat_from_mat(A->R), qb = bf_quat_from_mat(B->R);
    bf_vec3 t = bf_v3_add(bf_v3_scale(A->t, 1 - s), bf_v3_scale(B->t, s));
    return bf_se3_from_qt(bf_quat_slerp(qa, qb, s), t);
}

void bf_se3_to_mat4f(const bf_se3 *T, float out[16])
{
    double t[3] = {T->t.x, T->t.y, T->t.z};
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) out[i * 4 + j] = (float)T->R[i][j];
        out[i * 4 + 3] = (float)t[i];
    }
    out[12] = out[13] = out[14] = 0;
    out[15] = 1;
}

bool bf_se3_is_finite(const bf_se3 *T)
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            if (!isfinite(T->R[i][j])) return false;
    return isfinite(T->t.x) && isfinite(T->t.y) && isfinite(T->t.z);
}

bool bf_se3_is_rigid(const bf_se3 *T, double tol)
{
    if (!bf_se3_is_finite(T)) return false;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0;
            for (int k = 0; k < 3; k++) d += T->R[i][k] * T->R[j][k];
            if (!(fabs(d - (i == j)) <= tol)) return false;
        }
    double det = T->R[0][0] * (T->R[1][1] * T->R[2][2] - T->R[1][2] * T->R[2][1]) -
                 T->R[0][1] * (T->R[1][0] * T->R[2][2] - T->R[1][2] * T->R[2][0]) +
                 T->R[0][2] * (T->R[1][0] * T->R[2][1] - T->R[1][1] * T->R[2][0]);
    return det > 0;
}

void bf_sym_eigen(int n, double *A, double *w, double *V)
{
    BF_ASSERT(n > 0 && n <= 6);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) V[i * n + j] = i == j;
    for (int sweep = 0; sweep < 100; sweep++) {
        double off = 0, diag = 0;
        for (int i = 0; i < n; i++) {
            diag += A[i * n + i] * A[i * n + i];
            for (int j = i + 1; j < n; j++) off += A[i * n + j] * A[i * n + j];
        }
        if (off <= 1e-30 * (diag + 1e-300)) break;
        for (int p = 0; p < n; p++)
            for (int q = p + 1; q < n; q++) {
                double apq = A[p * n + q];
                if (apq == 0) continue;
                /* Rotation that zeroes A[p][q] (Golub & Van Loan, 8.4). */
                double tau = (A[q * n + q] - A[p * n + p]) / (2 * apq);
                double t = (tau >= 0 ? 1 : -1) / (fabs(tau) + sqrt(1 + tau * tau));
                double c = 1 / sqrt(1 + t * t), s = t * c;
                for (int k = 0; k < n; k++) {
                    double akp = A[k * n + p], akq = A[k * n + q];
                    A[k * n + p] = c * akp - s * akq;
                    A[k * n + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) {
                    double apk = A[p * n + k], aqk = A[q * n + k];
                    A[p * n + k] = c * apk - s * aqk;
                    A[q * n + k] = s * apk + c * aqk;
                }
                for (int k = 0; k < n; k++) {
                    double vkp = V[k * n + p], vkq = V[k * n + q];
                    V[k * n + p] = c * vkp - s * vkq;
                    V[k * n + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int i = 0; i < n; i++) w[i] = A[i * n + i];
    /* Selection sort, ascending, moving eigenvector columns along. */
    for (int i = 0; i < n; i++) {
        int m = i;
        for (int j = i + 1; j < n; j++)
            if (w[j] < w[m]) m = j;
        if (m == i) continue;
        double tw = w[i]; w[i] = w[m]; w[m] = tw;
        for (int k = 0; k < n; k++) {
            double tv = V[k * n + i]; V[k * n + i] = V[k * n + m]; V[k * n + m] = tv;
        }
    }
}

bf_sensor bf_sensor_kinect1(void)
{
    return (bf_sensor){.sigma_a = 0.0012f, .sigma_b = 0.0019f, .sigma_c = 0.4f, .max_depth_m = 4.5f};
}

bf_intrinsics bf_intrinsics_level(const bf_intrinsics *K, uint32_t l)
{
    double s = 1.0 / (double)(1u << l);
    bf_intrinsics L = *K;
    L.width = K->width >> l;
    L.height = K->height >> l;
    L.fx_px = K->fx_px * s;
    L.fy_px = K->fy_px * s;
    L.cx_px = (K->cx_px + 0.5) * s - 0.5;
    L.cy_px = (K->cy_px + 0.5) * s - 0.5;
    return L;
}

bf_vec3 bf_intrinsics_unproject(const bf_intrinsics *K, double u, double v, double z_m)
{
    return bf_v3((u - K->cx_px) * z_m / K->fx_px, (v - K->cy_px) * z_m / K->fy_px, z_m);
}

bool bf_intrinsics_project(const bf_intrinsics *K, bf_vec3 p_c, double *u, double *v)
{
    if (!(p_c.z > 0)) return false;
    *u = K->fx_px * p_c.x / p_c.z + K->cx_px;
    *v = K->fy_px * p_c.y / p_c.z + K->cy_px;
    return true;
}
