/*
 * Small double-precision 3-vector, 3x3 / 4x4 matrix and quaternion helpers for
 * the simulator (plant, controller, allocation, sensors share them).
 * Quaternions are (w, x, y, z) and rotate body vectors into the world.
 */
#ifndef SITL_MATH_H
#define SITL_MATH_H

#include <math.h>

#define SITL_PI 3.14159265358979323846
#define SITL_GRAVITY 9.81

static inline void sitl_vec3_set(double out[3], double x, double y, double z)
{
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

static inline void sitl_vec3_copy(double out[3], const double a[3])
{
    out[0] = a[0];
    out[1] = a[1];
    out[2] = a[2];
}

static inline double sitl_vec3_dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static inline double sitl_vec3_norm(const double a[3])
{
    return sqrt(sitl_vec3_dot(a, a));
}

/* out = a x b (out may not alias a or b). */
static inline void sitl_vec3_cross(double out[3], const double a[3], const double b[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* out += s * a */
static inline void sitl_vec3_axpy(double out[3], double s, const double a[3])
{
    out[0] += s * a[0];
    out[1] += s * a[1];
    out[2] += s * a[2];
}

/* out = M a (3x3 row-major), out may not alias a. */
static inline void sitl_mat3_mul_vec(double out[3], const double m[3][3], const double a[3])
{
    for (int i = 0; i < 3; i++) {
        out[i] = m[i][0] * a[0] + m[i][1] * a[1] + m[i][2] * a[2];
    }
}

/* out = A^T B (3x3), out may not alias a or b. */
static inline void sitl_mat3_transpose_mul(double out[3][3], const double a[3][3],
                                           const double b[3][3])
{
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            out[i][j] = a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j];
        }
    }
}

/* vee of the skew part of m, 0.5 vee(m - m^T): for m = hat(v) it returns v. */
static inline void sitl_mat3_vee_skew(double out[3], const double m[3][3])
{
    out[0] = 0.5 * (m[2][1] - m[1][2]);
    out[1] = 0.5 * (m[0][2] - m[2][0]);
    out[2] = 0.5 * (m[1][0] - m[0][1]);
}

/* Solve A X = B for X by Gauss-Jordan with partial pivoting, in place: A is
 * destroyed, B (4 rows, `columns` <= 4 right-hand sides) becomes X. B = I gives
 * the inverse. Returns 0, or -1 when a pivot is not above tol (callers scale
 * the rows to comparable norm first, so tol is relative). */
int sitl_mat4_solve(double a[4][4], double b[4][4], int columns, double tol);

/* inv = A^-1 by cofactors (2x2 minors of the top and bottom row pairs): no pivoting, no
 * branch, for a well-conditioned A with rows of about unit length. Returns 0, or -1 (inv
 * untouched) when |det A| is not above tol. */
int sitl_mat4_inverse(const double a[4][4], double inv[4][4], double tol);

/* Inverse of a 3x3 matrix; returns 0, or -1 if singular. */
int sitl_mat3_inverse(const double m[3][3], double inv[3][3]);

/* Rotation matrix (body -> world) of a unit quaternion. */
void sitl_quat_to_matrix(const double q[4], double r[3][3]);

/* The same for any quaternion: normalised first, identity when it cannot be
 * (zero, non-finite). */
void sitl_quat_to_matrix_any(const double q[4], double r[3][3]);

/* Unit quaternion (w >= 0) of a rotation matrix (Shepperd's branch choice). */
void sitl_quat_from_matrix(const double r[3][3], double q[4]);

/* v_world = R(q) v_body */
void sitl_quat_rotate(const double q[4], const double v_body[3], double v_world[3]);

/* v_body = R(q)^T v_world */
void sitl_quat_rotate_inverse(const double q[4], const double v_world[3], double v_body[3]);

/* Time derivative of q for body rate w: dq = 0.5 q (x) (0, w). */
void sitl_quat_derivative(const double q[4], const double body_rate[3], double dq[4]);

void sitl_quat_normalise(double q[4]);

/* Quaternion of a rotation by yaw about world z. */
void sitl_quat_from_yaw(double yaw, double q[4]);

/* Yaw (ZYX Euler) of a quaternion [rad]. */
double sitl_quat_yaw(const double q[4]);

/* Wrap an angle to (-pi, pi]. */
double sitl_wrap_angle(double angle);

#endif /* SITL_MATH_H */
