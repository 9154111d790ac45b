/*
 * One closed-loop SITL flight: plant + effects + sensors + the propid filter
 * + trajectory + SE(3) controller + allocation, driven by an event loop in
 * integer nanoseconds (physics steps, IMU samples, ESC reports and control
 * steps each at their own rate; the plant is integrated exactly up to each
 * event). sitl_run() is what propid_sitl's main() calls and what the tests
 * call directly.
 */
#ifndef SITL_SIM_H
#define SITL_SIM_H

#include <stdint.h>
#include <stdio.h>

#include "allocation.h"
#include "controller.h"
#include "esc_telemetry.h"
#include "imu.h"
#include "honesty.h"
#include "metrics.h"
#include "options.h"
#include "plant.h"
#include "propid/propid.h"
#include "trajectory.h"

typedef struct {
    int exit_code;                        /* SITL_EXIT_* */
    int diverged;
    double diverged_at_s;
    char message[256];                    /* error or divergence reason */
    double flown_s;
    double wall_time_s;
    double flight_cpu_s;         /* process CPU time of the flight loop (no set-up) */
    double physics_rate_hz;      /* RK4 rate flown: --physics-rate, or the rule's (physics_rate.h) */
    double rmse[3];                       /* [m] */
    double rmse_yaw_deg;
    double final_position_error_m;        /* norm */
    double final_yaw_error_deg;
    double kf_rel_error_max;              /* final max_i |kf_est/kf_true - 1| */
    double km_rel_error_max;
    double bias_error_max;                /* final max_k |b_est - b_true| [rad/s] */
    double coeff_converged_s;             /* -1 = not converged */
    double bias_converged_s;
    int rotor_count;
    double true_kf[SITL_MAX_ROTORS], true_km[SITL_MAX_ROTORS];
    double used_kf[SITL_MAX_ROTORS], used_km[SITL_MAX_ROTORS]; /* controller's, at the end */
    double true_bias[3];
    double true_accel_bias_z;             /* the accelerometer's z bias at the end [m/s^2] */
    propid_estimate_t estimate;           /* final */
    propid_counters_t counters;
    sitl_honesty_t honesty;               /* NEES, false "converged", recovery (honesty.h) */
    long faults_injected[SITL_FAULT_COUNT]; /* per class (faults.h) */
    long control_steps;
    long log_rows;
    /* Damage detector (--detect-damage): every detection, in order. */
    int detection_count;
    int detection_rotor[SITL_MAX_DAMAGE];   /* 0-based */
    double detection_time_s[SITL_MAX_DAMAGE];
    /* Per --damage: 1 when it struck a vehicle resting on the ground (the contact
     * holds the attitude: the loss leaves no trace in the gyro). */
    int damage_on_ground[SITL_MAX_DAMAGE];
    /* Per --damage: 1 when the vehicle had flown and touched the ground again
     * before it (down after a crash, even where the spinning rotors lift it off
     * by millimetres at that instant). */
    int damage_after_touchdown[SITL_MAX_DAMAGE];
    /* The first time the vehicle, having been off the ground, touched it again
     * (a crash or a landing: the flight is over whatever the wreck does next);
     * -1 if it never did. */
    double touchdown_at_s;
} sitl_result_t;

/* Set-up pieces (sim_setup.c), public for tests. */

/* Vehicle from --vehicle (preset or JSON) with the CLI overrides applied.
 * Returns 0, or -1 with a message. */
int sitl_setup_vehicle(const sitl_options_t *opts, sitl_vehicle_t *vehicle, char *err,
                       int err_size);

/* True coefficients: nominal x U(1-s, 1+s), kf then km per rotor, own stream. */
void sitl_setup_true_coefficients(const sitl_vehicle_t *vehicle, double spread, uint64_t seed,
                                  double *true_kf, double *true_km);

/* Incorrect mode's fixed coefficients (nominal, or truth x (1 + N(0, spread))). */
void sitl_setup_incorrect_coefficients(const sitl_options_t *opts, const sitl_vehicle_t *vehicle,
                                       const double *true_kf, const double *true_km,
                                       double *kf, double *km);

/* s_true: the gain of the true thrust torques in the filter's model, what its thrust-torque
 * scale state s stands for (docs/math.md §9). The gyro sees J^-1 (r_i x z) kf_i; the filter
 * uses the file's J, inertia_error makes the true one (1 + e) J_file, so the true torques
 * are J_file^-1 (r_i x z) kf_i / (1 + e): s_true = 1 / (1 + e), 1 without the effect. */
double sitl_setup_true_torque_scale(const sitl_effects_t *effects);

/* propid configuration from the vehicle file and the IMU model; flown_kf: the thrust
 * coefficients the rotors fly with (--filter-sensor-errors reads the telemetry step at
 * their hover speed; NULL: the file's). Returns the propid_config_check status
 * (bad_field names the field). */
propid_status_t sitl_setup_filter_config(const sitl_options_t *opts,
                                         const sitl_vehicle_t *vehicle, const double *flown_kf,
                                         propid_config_t *config,
                                         const char **bad_field);

/* Ask a running sitl_run() to stop at its next control step (async-signal-safe:
 * it only sets a flag; main() calls it from SIGINT/SIGTERM). The run then ends
 * like a finished one, log closed, with exit code SITL_EXIT_INTERRUPTED. */
void sitl_request_stop(void);

/* Fly. out: where the live and final summaries go (NULL = nowhere). */
int sitl_run(const sitl_options_t *opts, sitl_result_t *result, FILE *out);

/* Summaries (summary.c). */
void sitl_print_final_summary(FILE *out, const sitl_options_t *opts, const sitl_result_t *r);
int sitl_write_summary_json(const char *path, const sitl_options_t *opts,
                            const sitl_result_t *r);

#endif /* SITL_SIM_H */
