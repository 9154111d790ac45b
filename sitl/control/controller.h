/*
 * Geometric tracking controller on SE(3) after Lee, Leok & McClamroch (2010),
 * "Geometric tracking control of a quadrotor UAV on SE(3)", CDC 2010.
 *
 * Frames: world z up, body FLU; attitude is the quaternion (w, x, y, z) that
 * rotates body vectors into the world. Outputs are the collective thrust along
 * body +z [N] and the body moment [N m]; the allocation (allocation.h) turns
 * them into rotor speeds with whatever coefficients the SITL mode provides.
 *
 * Position loop:  F = -kx e_x - kv e_v + m g e3 + m a_d,   f = F . (R e3)
 * Desired attitude: b3_d = F/|F|; b1_d perpendicular to b3_d whose horizontal
 * projection points along the desired yaw (so the ZYX yaw of R_d is exactly
 * the desired yaw; Lee's projection of b1_c differs slightly when tilted).
 * Attitude loop:  M = -kR e_R - kw e_w + w x J w - J (hat(w) R^T R_d w_d - R^T R_d dw_d)
 * The desired body rate w_d and its derivative dw_d come from the analytic
 * derivatives of R_d, computed from dF = m * jerk_d and ddF = m * snap_d and the
 * yaw rate / acceleration (feed-forward only: the derivatives of the feedback
 * terms would need measured acceleration and jerk, so they are left out).
 *
 * Gains: kx, kv scale with the mass and kR, kw with the inertia (per body axis),
 * from natural frequencies and damping ratios, so the same tuning gives the
 * same closed-loop dynamics for a 30 g Crazyflie and a 0.5 kg Hummingbird.
 */
#ifndef SITL_CONTROLLER_H
#define SITL_CONTROLLER_H

#include "trajectory.h"

/* Closed-loop tuning that does not depend on the vehicle's size. */
typedef struct {
    double position_natural_freq[3];  /* [rad/s] x, y, z */
    double position_damping[3];
    double attitude_natural_freq[3];  /* [rad/s] roll, pitch, yaw */
    double attitude_damping[3];
} sitl_controller_tuning_t;

typedef struct {
    double mass;              /* [kg] */
    double inertia[3][3];     /* body inertia [kg m^2] */
    double gravity;           /* [m/s^2], > 0 (acts along -z world) */
    /* Gains actually used (diagonal, per axis), derived from the tuning. */
    double kx[3];             /* [N/m] */
    double kv[3];             /* [N s/m] */
    double kR[3];             /* [N m/rad] */
    double kw[3];             /* [N m s/rad] */
} sitl_controller_t;

/* Measured (or true) vehicle state fed to the controller. */
typedef struct {
    double position[3];       /* world [m] */
    double velocity[3];       /* world [m/s] */
    double quat_wxyz[4];      /* body -> world, unit */
    double body_rate[3];      /* body FLU [rad/s] */
} sitl_vehicle_state_t;

typedef struct {
    double thrust;            /* collective thrust along body +z [N], >= 0 */
    double moment[3];         /* body moment [N m] */
    /* For logging and tests: */
    double desired_rotation[3][3]; /* R_d, body -> world (sitl_quat_from_matrix: its quaternion) */
    double desired_body_rate[3];
    double desired_body_accel[3];
    double position_error[3]; /* e_x = x - x_d [m] */
    double attitude_error[3]; /* e_R [rad-ish] */
} sitl_control_output_t;

/* Default tuning: position x, y wn 2.5 rad/s, zeta 0.8; z wn 4 rad/s, zeta 0.9;
 * attitude wn 12 rad/s, zeta 1.5 on all three axes: robust to first-order motor
 * lags up to ~0.1 s (Crazyflie motors, 0.072 s) as well as fast motors
 * (documented in docs/results.md). */
void sitl_controller_default_tuning(sitl_controller_tuning_t *tuning);

/* Set mass, inertia, gravity and derive the gains from tuning (NULL = default).
 * Returns 0, or -1 on a non-positive/non-finite mass, gravity or inertia diagonal. */
int sitl_controller_init(sitl_controller_t *ctl, double mass, const double inertia[3][3],
                         double gravity, const sitl_controller_tuning_t *tuning);

/* One control step. Pure function of its inputs (no internal state). */
void sitl_controller_update(const sitl_controller_t *ctl, const sitl_vehicle_state_t *state,
                            const sitl_flat_output_t *flat, sitl_control_output_t *out);

#endif /* SITL_CONTROLLER_H */
