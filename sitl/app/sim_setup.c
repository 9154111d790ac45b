/* Flight set-up: vehicle, true and Incorrect coefficients, filter config. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "effects_physics.h"
#include "rng.h"
#include "sensor_errors.h"
#include "sim.h"
#include "sitl_math.h"

int sitl_setup_vehicle(const sitl_options_t *opts, sitl_vehicle_t *v, char *err, int err_size)
{
    if (sitl_vehicle_preset(opts->vehicle, v) != 0) {
        size_t len = strlen(opts->vehicle);
        if (len < 5 || strcmp(opts->vehicle + len - 5, ".json") != 0) {
            int n = snprintf(err, (size_t)err_size, "--vehicle: unknown preset '%s' (presets:",
                             opts->vehicle);
            for (int i = 0; sitl_vehicle_preset_names[i] != NULL && n > 0 && n < err_size; i++) {
                n += snprintf(err + n, (size_t)(err_size - n), " %s",
                              sitl_vehicle_preset_names[i]);
            }
            if (n > 0 && n < err_size) {
                snprintf(err + n, (size_t)(err_size - n), "; or a FILE.json)");
            }
            return -1;
        }
        /* Vehicle files carry no motor or rotor-aero data: documented defaults
         * (docs/sitl.md), overridable by the CLI below. */
        memset(v, 0, sizeof(*v));
        v->motor_time_constant = 0.03;
        v->rotor_speed_min = 0.0;
        v->rotor_speed_max = 1e6; /* placeholder until the hover speed is known */
        if (sitl_vehicle_load_json(opts->vehicle, v, err, err_size) != 0) {
            return -1;
        }
        double kf_sum = 0.0;
        for (int i = 0; i < v->rotor_count; i++) {
            kf_sum += v->rotor[i].thrust_coeff;
        }
        /* Thrust-to-weight 4 by default: hover at half the maximum speed. */
        v->rotor_speed_max = 2.0 * sqrt(v->mass * 9.81 / kf_sum);
        if (v->rotor_radius > 0.0) {
            /* Rotor aerodynamics scaled from the Hummingbird preset by radius
             * (dimensional analysis: k_d, k_z ~ R^3, k_h ~ R^2, J_r ~ R^5). */
            double s = v->rotor_radius / 0.10;
            double file_rotor_inertia = v->rotor_inertia;
            v->rotor_drag_coeff = 1.19e-4 * s * s * s;
            v->inflow_coeff = 2.32e-4 * s * s * s;
            v->translational_lift_coeff = 3.39e-3 * s * s;
            v->flapping_coeff = 0.5 * v->rotor_radius * v->rotor_drag_coeff;
            v->rotor_inertia = file_rotor_inertia > 0.0 ? file_rotor_inertia
                                                        : 1.5e-5 * s * s * s * s * s;
            v->rotor_inertia_assumed = file_rotor_inertia > 0.0 ? 0 : 1;
        }
    }
    if (opts->motor_time_constant > 0.0) {
        v->motor_time_constant = opts->motor_time_constant;
    }
    if (opts->rotor_speed_min >= 0.0) {
        v->rotor_speed_min = opts->rotor_speed_min;
    }
    if (opts->rotor_speed_max > 0.0) {
        v->rotor_speed_max = opts->rotor_speed_max;
    }
    return sitl_vehicle_check(v, err, err_size);
}

void sitl_setup_true_coefficients(const sitl_vehicle_t *v, double spread, uint64_t seed,
                                  double *true_kf, double *true_km)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, seed, SITL_RNG_COEFFS);
    for (int i = 0; i < v->rotor_count; i++) {
        true_kf[i] = v->rotor[i].thrust_coeff * sitl_rng_range(&rng, 1.0 - spread, 1.0 + spread);
        true_km[i] = v->rotor[i].drag_coeff * sitl_rng_range(&rng, 1.0 - spread, 1.0 + spread);
    }
}

void sitl_setup_incorrect_coefficients(const sitl_options_t *opts, const sitl_vehicle_t *v,
                                       const double *true_kf, const double *true_km, double *kf,
                                       double *km)
{
    sitl_rng_t rng;
    sitl_rng_init(&rng, sitl_options_vehicle_seed(opts), SITL_RNG_INCORRECT);
    for (int i = 0; i < v->rotor_count; i++) {
        if (!opts->incorrect_random) {
            kf[i] = v->rotor[i].thrust_coeff;
            km[i] = v->rotor[i].drag_coeff;
        } else {
            /* Gaussian around the truth (the paper's Incorrect), kept positive. */
            double a = 1.0 + opts->incorrect_spread * sitl_rng_normal(&rng);
            double b = 1.0 + opts->incorrect_spread * sitl_rng_normal(&rng);
            kf[i] = true_kf[i] * fmax(a, 0.1);
            km[i] = true_km[i] * fmax(b, 0.1);
        }
    }
}

double sitl_setup_true_torque_scale(const sitl_effects_t *effects)
{
    const double e = sitl_effect_strength(effects, SITL_EFFECT_INERTIA_ERROR);
    return e != 0.0 && 1.0 + e > 0.0 ? 1.0 / (1.0 + e) : 1.0; /* as effects_setup.c applies it */
}

/* The diagonal of the aero_damping effect's rate damping at hover [N m s/rad]
 * (effects_rotor.c: rotor i's drag law on its hub velocity omega x r_i, scaled by
 * its speed), the speed every rotor has when the flown coefficients hold the
 * weight: d_a = -(sum_i r_i x F_i(omega = e_a))_a. */
static void hover_aero_damping(const sitl_options_t *opts, const sitl_vehicle_t *v, const double *flown_kf,
                               double damping[3])
{
    const double strength = sitl_effect_strength(&opts->effects, SITL_EFFECT_AERO_DAMPING);
    double kf_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        kf_sum += flown_kf[i];
    }
    const double hover = kf_sum > 0.0 ? sqrt(v->mass * 9.81 / kf_sum) : 0.0;
    for (int a = 0; a < 3; a++) {
        const double unit[3] = {a == 0 ? 1.0 : 0.0, a == 1 ? 1.0 : 0.0, a == 2 ? 1.0 : 0.0};
        double torque = 0.0;
        for (int i = 0; i < v->rotor_count; i++) {
            double force[3];
            double moment[3];
            sitl_aero_damping_rotor(v, v->rotor[i].position, hover, unit, strength, force, moment);
            torque += moment[a];
        }
        damping[a] = -torque;
    }
}

propid_status_t sitl_setup_filter_config(const sitl_options_t *opts, const sitl_vehicle_t *v,
                                         const double *flown_kf, propid_config_t *c, const char **bad_field)
{
    propid_config_default(c);
    c->rotor_count = (uint8_t)v->rotor_count;
    for (int i = 0; i < v->rotor_count; i++) {
        for (int k = 0; k < 3; k++) {
            c->rotor[i].position_m[k] = (float)v->rotor[i].position[k];
        }
        c->rotor[i].yaw_sign = (float)v->rotor[i].yaw_sign;
        c->rotor[i].thrust_coeff_nominal = (float)v->rotor[i].thrust_coeff;
        c->rotor[i].drag_coeff_nominal = (float)v->rotor[i].drag_coeff;
    }
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            c->inertia[i][j] = (float)v->inertia[i][j];
        }
    }
    /* What an integrator copies from the IMU datasheet and its driver set-up. */
    if (opts->imu.gyro.noise_density > 0.0) {
        c->gyro_noise_density = (float)opts->imu.gyro.noise_density;
    }
    c->gyro_sample_rate_hz = (float)opts->imu.rate_hz;
    if (opts->imu.gyro.range > 0.0) {
        c->gyro_range = (float)opts->imu.gyro.range;
    }
    c->max_rotor_speed = (float)(1.5 * v->rotor_speed_max);
    c->motor_time_constant = (float)v->motor_time_constant; /* the vehicle's motors: the slew test */
    if (opts->prior_kf_rel_std > 0.0) {
        c->thrust_coeff_rel_std0 = (float)opts->prior_kf_rel_std;
    }
    if (opts->prior_km_rel_std > 0.0) {
        c->drag_coeff_rel_std0 = (float)opts->prior_km_rel_std;
    }
    if (opts->prior_bias_std > 0.0) {
        c->gyro_bias_std0 = (float)opts->prior_bias_std;
    }
    if (opts->prior_rate_std > 0.0) {
        c->rate_std0 = (float)opts->prior_rate_std;
    }
    if (opts->filter_rate_noise >= 0.0) {
        c->rate_process_noise = (float)opts->filter_rate_noise;
    }
    if (opts->filter_coeff_walk >= 0.0) {
        c->thrust_coeff_rel_walk = (float)opts->filter_coeff_walk;
        c->drag_coeff_rel_walk = (float)opts->filter_coeff_walk;
    }
    if (opts->filter_bias_walk >= 0.0) {
        c->gyro_bias_walk = (float)opts->filter_bias_walk;
    }
    c->disturbance_torque = opts->filter_disturbance ? 1u : 0u;
    c->disturbance_bandwidth = (float)opts->filter_disturbance_bandwidth; /* checked by propid_init */
    if (opts->filter_accel) {
        c->mass = (float)v->mass;
    }
    if (opts->prior_accel_bias_std > 0.0) {
        c->accel_bias_std0 = (float)opts->prior_accel_bias_std;
    }
    if (opts->filter_accel_noise > 0.0) {
        c->accel_noise_std = (float)opts->filter_accel_noise;
    }
    if (opts->filter_accel_error_std > 0.0) {
        c->accel_error_std = (float)opts->filter_accel_error_std;
        c->accel_error_time = (float)opts->filter_accel_error_time;
    }
    c->torque_scale = opts->filter_torque_scale ? 1u : 0u; /* without the accelerometer: a config error */
    if (opts->filter_rotor_inertia) {
        for (int i = 0; i < v->rotor_count; i++) {
            c->rotor_inertia[i] = (float)v->rotor_inertia;
        }
    }
    c->rotor_delay_us = (int32_t)lround(opts->filter_esc_delay_s * 1e6);
    c->rotor_speed_noise = (float)opts->filter_rotor_speed_noise;
    c->rotor_speed_noise_time = (float)opts->filter_rotor_speed_noise_time;
    c->inertia_rel_std = (float)opts->filter_inertia_rel_std;
    c->gyro_stuck_samples = (uint16_t)lround(opts->filter_gyro_stuck_samples);
    c->input_error_compensation = (uint8_t)(opts->filter_input_error_compensation != 0);
    if (opts->filter_aero_damping) {
        double damping[3];
        hover_aero_damping(opts, v, flown_kf, damping);
        for (int a = 0; a < 3; a++) {
            c->aero_damping[a] = (float)damping[a];
        }
    }
    if (opts->filter_instrument) {
        c->motor_command_instrument = 1u;
        c->motor_command_lag = (float)v->motor_time_constant;
    }
    int held_by_rule = 0;
    if (opts->filter_sensor_errors) {
        sitl_sensor_errors_t e;
        if (sitl_sensor_errors(v, &opts->esc, flown_kf, &e) != 0) {
            if (bad_field != NULL) {
                *bad_field = "filter-sensor-errors (vehicle without hover)";
            }
            return PROPID_ERR_CONFIG;
        }
        c->rotor_speed_noise = (float)e.rotor_speed_noise;
        c->rotor_speed_noise_time = (float)e.rotor_speed_noise_time;
        c->rotor_delay_us = (int32_t)lround(e.rotor_delay_s * 1e6);
        c->input_error_compensation = 0u; /* the truncation's error is not classical (sensor_errors.c) */
        held_by_rule = e.rotor_speed_noise_hold;
        c->rotor_speed_noise_split = (uint8_t)(opts->filter_decode_error_split && e.rotor_speed_noise_truncated);
        if (opts->filter_rotor_speed_noise_hold == 2) {
            /* The hold as a floor: the rule's fixed time is the floor, whatever the decode. */
            c->rotor_speed_noise_time = (float)SITL_HELD_STEP_TIME_S;
        }
    }
    if (opts->filter_report_age) {
        /* The trapezoid of the reports held at a step's two ends lags the step by
         * the held report's mean age (docs/math.md §2); the delay buffer can move
         * the pairing only by whole gyro periods, so the nearest whole number of
         * them is added: what is left is at most half a period. */
        const double gyro_first_s = opts->imu_sample_at_start ? 0.0 : 1.0 / opts->imu.rate_hz;
        const double age = sitl_report_mean_age(&opts->esc, opts->imu.rate_hz, gyro_first_s);
        const double periods = floor(age * opts->imu.rate_hz + 0.5);
        c->rotor_delay_us += (int32_t)lround(periods * 1e6 / opts->imu.rate_hz);
    }
    /* After the sensor errors, which set the error's size and ceiling time (and,
     * decoded at the code's middle, the hold). */
    c->rotor_speed_noise_hold = (uint8_t)(opts->filter_rotor_speed_noise_hold == 2
                                              ? 2
                                              : (opts->filter_rotor_speed_noise_hold != 0 || held_by_rule));
    return propid_config_check(c, bad_field);
}
