/* SE(3) geometric tracking controller (Lee, Leok, McClamroch 2010); see controller.h. */
#include "controller.h"
#include "sitl_math.h"
#include "sitl_sincos.h"

#include <math.h>
#include <string.h>

typedef double vec3[3];
typedef double mat3[3][3];

/* out = a x b + c x d (product-rule derivatives of cross products) */
static void cross_sum(const vec3 a, const vec3 b, const vec3 c, const vec3 d, vec3 out)
{
    vec3 p, q;
    sitl_vec3_cross(p, a, b);
    sitl_vec3_cross(q, c, d);
    for (int i = 0; i < 3; i++) {
        out[i] = p[i] + q[i];
    }
}

/*
 * Unit vector u = v/|v| and its first two time derivatives from those of v:
 *   du  = (dv - u (u.dv)) / n
 *   ddu = (ddv - 2 du (u.dv) - u (du.dv + u.ddv)) / n
 * (from v = n u, dn = u.dv, ddn = du.dv + u.ddv). Returns -1 if |v| ~ 0.
 */
static int normalise_with_derivatives(const vec3 v, const vec3 dv, const vec3 ddv, vec3 u, vec3 du,
                                      vec3 ddu)
{
    double n = sqrt(sitl_vec3_dot(v, v));
    if (!(n > 1e-12)) {
        return -1;
    }
    const double inv_n = 1.0 / n; /* one division, not nine (rounding-level) */
    for (int i = 0; i < 3; i++) {
        u[i] = v[i] * inv_n;
    }
    double dn = sitl_vec3_dot(u, dv);
    for (int i = 0; i < 3; i++) {
        du[i] = (dv[i] - u[i] * dn) * inv_n;
    }
    double ddn = sitl_vec3_dot(du, dv) + sitl_vec3_dot(u, ddv);
    for (int i = 0; i < 3; i++) {
        ddu[i] = (ddv[i] - 2.0 * du[i] * dn - u[i] * ddn) * inv_n;
    }
    return 0;
}

void sitl_controller_default_tuning(sitl_controller_tuning_t *tuning)
{
    /* Attitude 12 rad/s with damping 1.5 keeps a margin against a 0.07-0.1 s
     * first-order motor lag (Crazyflie-class motors); 23 rad/s (RotorPy's
     * Crazyflie gains) diverges with such motors in our simulations. */
    for (int i = 0; i < 3; i++) {
        tuning->position_natural_freq[i] = 2.5;
        tuning->position_damping[i] = 0.8;
        tuning->attitude_natural_freq[i] = 12.0;
        tuning->attitude_damping[i] = 1.5;
    }
    /* Height acts through collective thrust directly (no attitude loop in
     * between), so it can be stiffer. */
    tuning->position_natural_freq[2] = 4.0;
    tuning->position_damping[2] = 0.9;
}

int sitl_controller_init(sitl_controller_t *ctl, double mass, const double inertia[3][3],
                         double gravity, const sitl_controller_tuning_t *tuning)
{
    if (ctl == NULL || inertia == NULL || !isfinite(mass) || mass <= 0.0 || !isfinite(gravity) ||
        gravity <= 0.0) {
        return -1;
    }
    for (int i = 0; i < 3; i++) {
        if (!isfinite(inertia[i][i]) || inertia[i][i] <= 0.0) {
            return -1;
        }
    }
    sitl_controller_tuning_t defaults;
    if (tuning == NULL) {
        sitl_controller_default_tuning(&defaults);
        tuning = &defaults;
    }
    memset(ctl, 0, sizeof(*ctl));
    ctl->mass = mass;
    ctl->gravity = gravity;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            ctl->inertia[i][j] = inertia[i][j];
        }
    }
    /* Gains scale with mass / inertia: the closed loop becomes
     * e'' + 2 zeta wn e' + wn^2 e = 0 per axis, independent of vehicle size. */
    for (int i = 0; i < 3; i++) {
        double wp = tuning->position_natural_freq[i], zp = tuning->position_damping[i];
        double wa = tuning->attitude_natural_freq[i], za = tuning->attitude_damping[i];
        ctl->kx[i] = mass * wp * wp;
        ctl->kv[i] = mass * 2.0 * zp * wp;
        ctl->kR[i] = inertia[i][i] * wa * wa;
        ctl->kw[i] = inertia[i][i] * 2.0 * za * wa;
    }
    return 0;
}

void sitl_controller_update(const sitl_controller_t *ctl, const sitl_vehicle_state_t *state,
                            const sitl_flat_output_t *flat, sitl_control_output_t *out)
{
    memset(out, 0, sizeof(*out));
    const double m = ctl->mass;

    /* Position loop: desired force in the world. */
    vec3 force, dforce, ddforce;
    for (int i = 0; i < 3; i++) {
        double ex = state->position[i] - flat->position[i];
        double ev = state->velocity[i] - flat->velocity[i];
        out->position_error[i] = ex;
        force[i] = -ctl->kx[i] * ex - ctl->kv[i] * ev + m * flat->acceleration[i];
        dforce[i] = m * flat->jerk[i]; /* feed-forward only (see controller.h) */
        ddforce[i] = m * flat->snap[i];
    }
    force[2] += m * ctl->gravity;

    mat3 rot;
    sitl_quat_to_matrix_any(state->quat_wxyz, rot);
    vec3 body_z = {rot[0][2], rot[1][2], rot[2][2]};
    double thrust = sitl_vec3_dot(force, body_z);
    out->thrust = thrust > 0.0 ? thrust : 0.0;

    /* Desired attitude and its derivatives: b3 along the force, b1 from yaw. */
    vec3 b3, db3, ddb3;
    if (normalise_with_derivatives(force, dforce, ddforce, b3, db3, ddb3) != 0) {
        /* Free fall commanded: keep the current tilt direction, no feed-forward. */
        for (int i = 0; i < 3; i++) {
            b3[i] = body_z[i];
            db3[i] = 0.0;
            ddb3[i] = 0.0;
        }
    }
    /* Heading: b1 is horizontal-projected onto the yaw direction, i.e. b1 is
     * perpendicular to y_c = (-sin yaw, cos yaw, 0) and to b3. Then the ZYX yaw
     * of R_d equals the desired yaw exactly (Lee's projection of b1_c does not),
     * so the yaw tracking metric measures tracking, not the construction. */
    double sy, cy;
    sitl_sincos(flat->yaw, &sy, &cy);
    double r = flat->yaw_rate, ra = flat->yaw_acceleration;
    vec3 yc = {-sy, cy, 0.0};
    vec3 dyc = {-cy * r, -sy * r, 0.0};
    vec3 ddyc = {-cy * ra + sy * r * r, -sy * ra - cy * r * r, 0.0};

    vec3 c, dc, ddc, tmp;
    sitl_vec3_cross(c, yc, b3);
    cross_sum(dyc, b3, yc, db3, dc);
    cross_sum(ddyc, b3, yc, ddb3, ddc);
    sitl_vec3_cross(tmp, dyc, db3);
    for (int i = 0; i < 3; i++) {
        ddc[i] += 2.0 * tmp[i];
    }
    vec3 b1, db1, ddb1;
    if (normalise_with_derivatives(c, dc, ddc, b1, db1, ddb1) != 0) {
        /* Thrust axis horizontal (never in our flights): keep the body x axis. */
        for (int i = 0; i < 3; i++) {
            b1[i] = rot[i][0];
            db1[i] = 0.0;
            ddb1[i] = 0.0;
        }
    }
    vec3 b2, db2, ddb2;
    sitl_vec3_cross(b2, b3, b1);
    cross_sum(db3, b1, b3, db1, db2);
    cross_sum(ddb3, b1, b3, ddb1, ddb2);
    sitl_vec3_cross(tmp, db3, db1);
    for (int i = 0; i < 3; i++) {
        ddb2[i] += 2.0 * tmp[i];
    }

    mat3 rd, drd, ddrd;
    for (int i = 0; i < 3; i++) {
        rd[i][0] = b1[i];
        rd[i][1] = b2[i];
        rd[i][2] = b3[i];
        drd[i][0] = db1[i];
        drd[i][1] = db2[i];
        drd[i][2] = db3[i];
        ddrd[i][0] = ddb1[i];
        ddrd[i][1] = ddb2[i];
        ddrd[i][2] = ddb3[i];
    }

    /* dR_d = R_d hat(w_d); ddR_d = R_d (hat(w_d)^2 + hat(dw_d)). */
    mat3 m1, m2;
    vec3 rate_d, accel_d;
    sitl_mat3_transpose_mul(m1, rd, drd);
    sitl_mat3_vee_skew(rate_d, m1);
    sitl_mat3_transpose_mul(m2, rd, ddrd);
    /* R_d^T ddR_d = hat(w_d)^2 + hat(dw_d); hat(w_d)^2 is symmetric, so the
     * skew part alone gives dw_d. */
    sitl_mat3_vee_skew(accel_d, m2);

    /* Attitude errors. */
    mat3 rd_t_r, r_t_rd;
    sitl_mat3_transpose_mul(rd_t_r, rd, rot);
    /* R^T R_d = (R_d^T R)^T: each element the same products (a b = b a exactly) summed in
     * the same order, so the transpose is that product bit for bit. */
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            r_t_rd[i][j] = rd_t_r[j][i];
        }
    }
    mat3 skew;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            skew[i][j] = rd_t_r[i][j] - r_t_rd[i][j];
        }
    }
    vec3 e_rot;
    sitl_mat3_vee_skew(e_rot, skew); /* sitl_mat3_vee_skew halves: 0.5 vee(Rd^T R - R^T Rd) */
    vec3 rate_d_body, accel_d_body, e_rate;
    sitl_mat3_mul_vec(rate_d_body, r_t_rd, rate_d);
    sitl_mat3_mul_vec(accel_d_body, r_t_rd, accel_d);
    for (int i = 0; i < 3; i++) {
        e_rate[i] = state->body_rate[i] - rate_d_body[i];
    }

    /* M = -kR eR - kw ew + w x J w - J (w x (R^T Rd wd) - R^T Rd dwd) */
    vec3 jw, gyro, w_cross_wd, feed, jfeed;
    sitl_mat3_mul_vec(jw, ctl->inertia, state->body_rate);
    sitl_vec3_cross(gyro, state->body_rate, jw);
    sitl_vec3_cross(w_cross_wd, state->body_rate, rate_d_body);
    for (int i = 0; i < 3; i++) {
        feed[i] = w_cross_wd[i] - accel_d_body[i];
    }
    sitl_mat3_mul_vec(jfeed, ctl->inertia, feed);
    for (int i = 0; i < 3; i++) {
        out->moment[i] = -ctl->kR[i] * e_rot[i] - ctl->kw[i] * e_rate[i] + gyro[i] - jfeed[i];
        out->attitude_error[i] = e_rot[i];
        out->desired_body_rate[i] = rate_d[i];
        out->desired_body_accel[i] = accel_d[i];
    }
    /* R_d as it is: the flight needs its quaternion only once (the trim), not
     * at every control step. */
    memcpy(out->desired_rotation, rd, sizeof(out->desired_rotation));
}
