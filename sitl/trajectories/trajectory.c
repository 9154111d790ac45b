/* Reference trajectories with analytic derivatives up to snap (see trajectory.h). */
#include "trajectory.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "sitl_sincos.h"

/* M_PI is not in strict C11. */
static const double pi = 3.14159265358979323846;

static void eval_hover(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);
static void eval_step(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);
static void eval_circle(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);
static void eval_lissajous(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);

/* The registry: one row per kind (docs/sitl.md "Adding a trajectory"). */
static const sitl_trajectory_info_t registry[SITL_TRAJ_KIND_COUNT] = {
    [SITL_TRAJ_HOVER] = {"hover", 0, eval_hover},
    [SITL_TRAJ_STEP] = {"step", 0, eval_step},
    [SITL_TRAJ_CIRCLE] = {"circle", 1, eval_circle},
    [SITL_TRAJ_LISSAJOUS] = {"lissajous", 1, eval_lissajous},
};

const sitl_trajectory_info_t *sitl_trajectory_info(sitl_trajectory_kind_t kind)
{
    if ((int)kind < 0 || (int)kind >= SITL_TRAJ_KIND_COUNT) {
        return NULL;
    }
    return &registry[kind];
}

int sitl_trajectory_from_name(const char *name, sitl_trajectory_kind_t *kind)
{
    if (name == NULL || kind == NULL) {
        return -1;
    }
    for (int i = 0; i < SITL_TRAJ_KIND_COUNT; i++) {
        if (strcmp(name, registry[i].name) == 0) {
            *kind = (sitl_trajectory_kind_t)i;
            return 0;
        }
    }
    return -1;
}

const char *sitl_trajectory_name(sitl_trajectory_kind_t kind)
{
    const sitl_trajectory_info_t *info = sitl_trajectory_info(kind);
    return info != NULL ? info->name : "?";
}

void sitl_trajectory_names(char *out, int out_size, const char *separator)
{
    int n = 0;
    out[0] = '\0';
    for (int i = 0; i < SITL_TRAJ_KIND_COUNT && n >= 0 && n < out_size; i++) {
        n += snprintf(out + n, (size_t)(out_size - n), "%s%s", i ? separator : "",
                      registry[i].name);
    }
}

int sitl_trajectory_init(sitl_trajectory_t *traj, sitl_trajectory_kind_t kind,
                         double period_s, const double origin[3])
{
    if (traj == NULL || (int)kind < 0 || (int)kind >= SITL_TRAJ_KIND_COUNT ||
        !isfinite(period_s) || period_s <= 0.0) {
        return -1;
    }
    memset(traj, 0, sizeof(*traj));
    traj->kind = kind;
    traj->period_s = period_s;
    if (origin != NULL) {
        for (int i = 0; i < 3; i++) {
            traj->origin[i] = origin[i];
        }
    }
    /* Defaults for a Crazyflie-class vehicle; docs/results.md gives the reasons. */
    traj->step_time_s = 0.0; /* the reference jumps right after t = 0 */
    traj->step_amplitude_m = 1.0;

    /* About 1.07 m/s around the circle; the start angle splits the start-up
     * transient (the vehicle starts at rest) evenly between x and y. */
    traj->circle_radius_m = 0.85;
    traj->circle_cycles = 2.0;
    traj->circle_start_angle_rad = -1.0;

    /* Large slow Lissajous + small fast Lissajous (paper eq. 9, superimposed).
     * The fast part (about 3 m/s^2 of lateral acceleration at about 1 Hz) is what
     * excites the rotors differentially, which the coefficients need; it stays
     * within what 0.07 s Crazyflie motors follow. z moves slowly only. */
    traj->lissajous_slow.amplitude_m[0] = 0.6;
    traj->lissajous_slow.amplitude_m[1] = 0.5;
    traj->lissajous_slow.amplitude_m[2] = 0.02;
    traj->lissajous_slow.cycles[0] = 1.0;
    traj->lissajous_slow.cycles[1] = 2.0;
    traj->lissajous_slow.cycles[2] = 1.0;
    traj->lissajous_fast.amplitude_m[0] = 0.08;
    traj->lissajous_fast.amplitude_m[1] = 0.08;
    traj->lissajous_fast.amplitude_m[2] = 0.0;
    traj->lissajous_fast.cycles[0] = 10.0;
    traj->lissajous_fast.cycles[1] = 9.0;
    traj->lissajous_fast.cycles[2] = 8.0;

    if (registry[kind].yaws) {
        /* Large slow yaw swings (+-86 deg, 1.5 cycles): the gyro biases are only
         * observable through the gyroscopic coupling, whose signal grows with the
         * yaw excursion. */
        traj->yaw_amplitude_rad = 1.5;
        traj->yaw_cycles = 1.5;
    }
    return 0;
}

/*
 * Derivatives 0..4 of a sin(w t) and a (1 - cos(w t)) at t, from s = sin(w t)
 * and c = cos(w t) (the angles of one evaluation go through sitl_sincos4 together).
 * d^k/dt^k sin(w t) = w^k sin(w t + k pi/2).
 */
static void sine_derivatives(double amplitude, double omega, double s, double c, double out[5])
{
    double w1 = omega, w2 = w1 * omega, w3 = w2 * omega, w4 = w3 * omega;
    out[0] = amplitude * s;
    out[1] = amplitude * w1 * c;
    out[2] = -amplitude * w2 * s;
    out[3] = -amplitude * w3 * c;
    out[4] = amplitude * w4 * s;
}

static void one_minus_cos_derivatives(double amplitude, double omega, double s, double c,
                                      double out[5])
{
    double w1 = omega, w2 = w1 * omega, w3 = w2 * omega, w4 = w3 * omega;
    out[0] = amplitude * (1.0 - c);
    out[1] = amplitude * w1 * s;
    out[2] = amplitude * w2 * c;
    out[3] = -amplitude * w3 * s;
    out[4] = -amplitude * w4 * c;
}

/* Add derivative orders 0..4 of one axis into flat. */
static void add_axis(sitl_flat_output_t *flat, int axis, const double d[5])
{
    flat->position[axis] += d[0];
    flat->velocity[axis] += d[1];
    flat->acceleration[axis] += d[2];
    flat->jerk[axis] += d[3];
    flat->snap[axis] += d[4];
}

/* The back-and-forth yaw's angular rate (circle and Lissajous). */
static double yaw_omega(const sitl_trajectory_t *traj)
{
    return 2.0 * pi * traj->yaw_cycles / traj->period_s;
}

static void set_yaw(sitl_flat_output_t *flat, const sitl_trajectory_t *traj, double omega, double s,
                    double c)
{
    double d[5];
    sine_derivatives(traj->yaw_amplitude_rad, omega, s, c, d);
    flat->yaw = d[0];
    flat->yaw_rate = d[1];
    flat->yaw_acceleration = d[2];
}

static void eval_hover(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat)
{
    (void)traj;
    (void)t;
    (void)flat;
}

static void eval_step(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat)
{
    /* A true step: the controller sees the full error at once. Strictly
     * after step_time_s, so a step at 0 still starts at the origin. */
    if (t > traj->step_time_s) {
        flat->position[0] = traj->step_amplitude_m;
    }
}

static void eval_circle(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat)
{
    /* x = R (cos(phi + w t) - cos phi), y = R (sin(phi + w t) - sin phi):
     * through origin at t = 0; derivatives of cos(a) = sin(a + pi/2). */
    double omega = 2.0 * pi * traj->circle_cycles / traj->period_s;
    double phase = traj->circle_start_angle_rad;
    const double omega_yaw = yaw_omega(traj);
    const double angle[4] = {omega * (t + (phase + 0.5 * pi) / omega), omega * (t + phase / omega),
                             omega_yaw * t, 0.0};
    double s[4], c[4];
    sitl_sincos4(angle, s, c);
    double dx[5], dy[5];
    sine_derivatives(traj->circle_radius_m, omega, s[0], c[0], dx);
    sine_derivatives(traj->circle_radius_m, omega, s[1], c[1], dy);
    dx[0] -= traj->circle_radius_m * cos(phase);
    dy[0] -= traj->circle_radius_m * sin(phase);
    add_axis(flat, 0, dx);
    add_axis(flat, 1, dy);
    set_yaw(flat, traj, omega_yaw, s[2], c[2]);
}

/* Slow part, fast part (x: 1 - cos, y and z: sin, each added in that order), then
 * the yaw: seven angles, their sines and cosines from two sitl_sincos4 calls. */
static void eval_lissajous(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat)
{
    const double two_pi = 2.0 * pi;
    const sitl_lissajous_part_t *part[2] = {&traj->lissajous_slow, &traj->lissajous_fast};
    double omega[8], angle[8], s[8], c[8];
    for (int p = 0; p < 2; p++) {
        for (int axis = 0; axis < 3; axis++) {
            omega[3 * p + axis] = two_pi * part[p]->cycles[axis] / traj->period_s;
        }
    }
    omega[6] = yaw_omega(traj);
    omega[7] = 0.0;
    for (int k = 0; k < 8; k++) {
        angle[k] = omega[k] * t;
    }
    sitl_sincos4(angle, s, c);
    sitl_sincos4(angle + 4, s + 4, c + 4);
    for (int p = 0; p < 2; p++) {
        double d[5];
        const int k = 3 * p;
        one_minus_cos_derivatives(part[p]->amplitude_m[0], omega[k], s[k], c[k], d);
        add_axis(flat, 0, d);
        sine_derivatives(part[p]->amplitude_m[1], omega[k + 1], s[k + 1], c[k + 1], d);
        add_axis(flat, 1, d);
        sine_derivatives(part[p]->amplitude_m[2], omega[k + 2], s[k + 2], c[k + 2], d);
        add_axis(flat, 2, d);
    }
    set_yaw(flat, traj, omega[6], s[6], c[6]);
}

void sitl_trajectory_eval(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat)
{
    memset(flat, 0, sizeof(*flat));
    if (t < 0.0) {
        t = 0.0;
    }
    const sitl_trajectory_info_t *info = sitl_trajectory_info(traj->kind);
    if (info != NULL) {
        info->eval(traj, t, flat);
    }
    for (int i = 0; i < 3; i++) {
        flat->position[i] += traj->origin[i];
    }
}
