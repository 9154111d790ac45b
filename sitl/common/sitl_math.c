/* Quaternion, 3x3 and 4x4 helpers (see sitl_math.h). */
#include "sitl_math.h"

int sitl_mat3_inverse(const double m[3][3], double inv[3][3])
{
    double c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    double c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    double c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if (!isfinite(det) || fabs(det) < 1e-300) {
        return -1;
    }
    double k = 1.0 / det;
    inv[0][0] = c00 * k;
    inv[1][0] = c01 * k;
    inv[2][0] = c02 * k;
    inv[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * k;
    inv[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * k;
    inv[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * k;
    inv[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * k;
    inv[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * k;
    inv[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * k;
    return 0;
}

int sitl_mat4_solve(double a[4][4], double b[4][4], int columns, double tol)
{
    for (int col = 0; col < 4; col++) {
        int pivot = col;
        for (int r = col + 1; r < 4; r++) {
            if (fabs(a[r][col]) > fabs(a[pivot][col])) {
                pivot = r;
            }
        }
        if (!(fabs(a[pivot][col]) > tol)) {
            return -1;
        }
        if (pivot != col) {
            for (int j = 0; j < 4; j++) {
                double t = a[col][j];
                a[col][j] = a[pivot][j];
                a[pivot][j] = t;
            }
            for (int j = 0; j < columns; j++) {
                double t = b[col][j];
                b[col][j] = b[pivot][j];
                b[pivot][j] = t;
            }
        }
        /* One division per pivot, not one per element (rounding-level change). */
        const double inv_p = 1.0 / a[col][col];
        for (int j = 0; j < 4; j++) {
            a[col][j] *= inv_p;
        }
        for (int j = 0; j < columns; j++) {
            b[col][j] *= inv_p;
        }
        for (int r = 0; r < 4; r++) {
            if (r != col) {
                double f = a[r][col];
                for (int j = 0; j < 4; j++) {
                    a[r][j] -= f * a[col][j];
                }
                for (int j = 0; j < columns; j++) {
                    b[r][j] -= f * b[col][j];
                }
            }
        }
    }
    return 0;
}

int sitl_mat4_inverse(const double a[4][4], double inv[4][4], double tol)
{
    const double *r0 = a[0], *r1 = a[1], *r2 = a[2], *r3 = a[3];
    /* 2x2 minors of rows 0-1 (top) and rows 2-3 (bottom), by column pair. */
    const double t01 = r0[0] * r1[1] - r0[1] * r1[0], t02 = r0[0] * r1[2] - r0[2] * r1[0];
    const double t03 = r0[0] * r1[3] - r0[3] * r1[0], t12 = r0[1] * r1[2] - r0[2] * r1[1];
    const double t13 = r0[1] * r1[3] - r0[3] * r1[1], t23 = r0[2] * r1[3] - r0[3] * r1[2];
    const double b01 = r2[0] * r3[1] - r2[1] * r3[0], b02 = r2[0] * r3[2] - r2[2] * r3[0];
    const double b03 = r2[0] * r3[3] - r2[3] * r3[0], b12 = r2[1] * r3[2] - r2[2] * r3[1];
    const double b13 = r2[1] * r3[3] - r2[3] * r3[1], b23 = r2[2] * r3[3] - r2[3] * r3[2];
    const double det = (t01 * b23 - t02 * b13 + t03 * b12) + (t12 * b03 - t13 * b02 + t23 * b01);
    if (!(fabs(det) > tol)) {
        return -1;
    }
    const double d = 1.0 / det;
    /* inv = adj(A) / det; the adjugate's columns 0-1 from the bottom minors, 2-3 from the top. */
    inv[0][0] = (r1[1] * b23 - r1[2] * b13 + r1[3] * b12) * d;
    inv[0][1] = (-r0[1] * b23 + r0[2] * b13 - r0[3] * b12) * d;
    inv[0][2] = (r3[1] * t23 - r3[2] * t13 + r3[3] * t12) * d;
    inv[0][3] = (-r2[1] * t23 + r2[2] * t13 - r2[3] * t12) * d;
    inv[1][0] = (-r1[0] * b23 + r1[2] * b03 - r1[3] * b02) * d;
    inv[1][1] = (r0[0] * b23 - r0[2] * b03 + r0[3] * b02) * d;
    inv[1][2] = (-r3[0] * t23 + r3[2] * t03 - r3[3] * t02) * d;
    inv[1][3] = (r2[0] * t23 - r2[2] * t03 + r2[3] * t02) * d;
    inv[2][0] = (r1[0] * b13 - r1[1] * b03 + r1[3] * b01) * d;
    inv[2][1] = (-r0[0] * b13 + r0[1] * b03 - r0[3] * b01) * d;
    inv[2][2] = (r3[0] * t13 - r3[1] * t03 + r3[3] * t01) * d;
    inv[2][3] = (-r2[0] * t13 + r2[1] * t03 - r2[3] * t01) * d;
    inv[3][0] = (-r1[0] * b12 + r1[1] * b02 - r1[2] * b01) * d;
    inv[3][1] = (r0[0] * b12 - r0[1] * b02 + r0[2] * b01) * d;
    inv[3][2] = (-r3[0] * t12 + r3[1] * t02 - r3[2] * t01) * d;
    inv[3][3] = (r2[0] * t12 - r2[1] * t02 + r2[2] * t01) * d;
    return 0;
}

void sitl_quat_to_matrix(const double q[4], double r[3][3])
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    r[0][0] = 1.0 - 2.0 * (y * y + z * z);
    r[0][1] = 2.0 * (x * y - w * z);
    r[0][2] = 2.0 * (x * z + w * y);
    r[1][0] = 2.0 * (x * y + w * z);
    r[1][1] = 1.0 - 2.0 * (x * x + z * z);
    r[1][2] = 2.0 * (y * z - w * x);
    r[2][0] = 2.0 * (x * z - w * y);
    r[2][1] = 2.0 * (y * z + w * x);
    r[2][2] = 1.0 - 2.0 * (x * x + y * y);
}

void sitl_quat_to_matrix_any(const double q[4], double r[3][3])
{
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    double unit[4] = {1.0, 0.0, 0.0, 0.0};
    if (n > 0.0 && isfinite(n)) {
        for (int i = 0; i < 4; ++i) {
            unit[i] = q[i] / n;
        }
    }
    sitl_quat_to_matrix(unit, r);
}

void sitl_quat_from_matrix(const double r[3][3], double q[4])
{
    double trace = r[0][0] + r[1][1] + r[2][2];
    if (trace > 0.0) {
        double s = 2.0 * sqrt(1.0 + trace);
        q[0] = 0.25 * s;
        q[1] = (r[2][1] - r[1][2]) / s;
        q[2] = (r[0][2] - r[2][0]) / s;
        q[3] = (r[1][0] - r[0][1]) / s;
    } else if (r[0][0] > r[1][1] && r[0][0] > r[2][2]) {
        double s = 2.0 * sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]);
        q[0] = (r[2][1] - r[1][2]) / s;
        q[1] = 0.25 * s;
        q[2] = (r[0][1] + r[1][0]) / s;
        q[3] = (r[0][2] + r[2][0]) / s;
    } else if (r[1][1] > r[2][2]) {
        double s = 2.0 * sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]);
        q[0] = (r[0][2] - r[2][0]) / s;
        q[1] = (r[0][1] + r[1][0]) / s;
        q[2] = 0.25 * s;
        q[3] = (r[1][2] + r[2][1]) / s;
    } else {
        double s = 2.0 * sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]);
        q[0] = (r[1][0] - r[0][1]) / s;
        q[1] = (r[0][2] + r[2][0]) / s;
        q[2] = (r[1][2] + r[2][1]) / s;
        q[3] = 0.25 * s;
    }
    if (q[0] < 0.0) { /* one hemisphere, for readable logs */
        for (int i = 0; i < 4; i++) {
            q[i] = -q[i];
        }
    }
}

void sitl_quat_rotate(const double q[4], const double v_body[3], double v_world[3])
{
    double r[3][3];
    sitl_quat_to_matrix(q, r);
    sitl_mat3_mul_vec(v_world, r, v_body);
}

void sitl_quat_rotate_inverse(const double q[4], const double v_world[3], double v_body[3])
{
    double r[3][3];
    sitl_quat_to_matrix(q, r);
    for (int i = 0; i < 3; i++) {
        v_body[i] = r[0][i] * v_world[0] + r[1][i] * v_world[1] + r[2][i] * v_world[2];
    }
}

void sitl_quat_derivative(const double q[4], const double w[3], double dq[4])
{
    dq[0] = 0.5 * (-q[1] * w[0] - q[2] * w[1] - q[3] * w[2]);
    dq[1] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    dq[2] = 0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2]);
    dq[3] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
}

void sitl_quat_normalise(double q[4])
{
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (n > 0.0 && isfinite(n)) {
        const double inv_n = 1.0 / n; /* once per RK4 step: rounding-level vs four divisions */
        for (int i = 0; i < 4; i++) {
            q[i] *= inv_n;
        }
    }
}

void sitl_quat_from_yaw(double yaw, double q[4])
{
    q[0] = cos(0.5 * yaw);
    q[1] = 0.0;
    q[2] = 0.0;
    q[3] = sin(0.5 * yaw);
}

double sitl_quat_yaw(const double q[4])
{
    return atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]));
}

double sitl_wrap_angle(double angle)
{
    while (angle > SITL_PI) {
        angle -= 2.0 * SITL_PI;
    }
    while (angle <= -SITL_PI) {
        angle += 2.0 * SITL_PI;
    }
    return angle;
}
