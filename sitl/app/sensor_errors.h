/*
 * The filter's input-error terms derived from the simulated sensors' and
 * motors' own specifications (--filter-sensor-errors, docs/sitl.md "Sensor
 * errors from the sensor model"): what an integrator can write down from the
 * ESC telemetry protocol and the vehicle file, without any flight data.
 */
#ifndef SITL_SENSOR_ERRORS_H
#define SITL_SENSOR_ERRORS_H

#include "esc_telemetry.h"
#include "vehicle.h"

/* Correlation time given to the quantisation error decoded at the code's period
 * [s]: a speed held within one telemetry step keeps its error; near hover longer
 * than this fixed time, which the rule keeps at 1 s (its measured figures,
 * docs/sitl.md). */
#define SITL_HELD_STEP_TIME_S 1.0

typedef struct {
    double hover_speed;            /* nominal hover speed [rad/s] */
    double rotor_speed_noise;      /* telemetry step at hover / sqrt(3) [rad/s]; 0: exact speeds */
    double rotor_speed_noise_time; /* its correlation time [s] (with the hold: its ceiling) */
    int rotor_speed_noise_hold;    /* 1: the hold from the telemetry (middle decode) */
    int rotor_speed_noise_truncated; /* 1: that error is a truncation's (the period decode): mean
                                        step / 2, common to every rotor, and spread step / sqrt(12)
                                        (--filter-decode-error-split: rotor_speed_noise_split) */
    double rotor_delay_s;          /* telemetry latency [s] */
} sitl_sensor_errors_t;

/* The step is taken at the hover speed the telemetry shows, sqrt(m g / sum kf) of the
 * coefficients the rotors fly with (flown_kf; NULL: the vehicle file's): a user reads it
 * off the stream in a hover, as `propid replay --rotor-speed-noise auto` reads the step
 * near the stream's median speed. The file's nominal hover speed is not enough: the
 * DShot step doubles where the period crosses 511 us (the Crazyflie hovers at 502 us),
 * so a vehicle a few per cent off its nominal kf has twice the step.
 * 0 on success, -1 on a vehicle without hover (no thrust or mass) or no pole pairs. */
int sitl_sensor_errors(const sitl_vehicle_t *v, const sitl_esc_params_t *esc, const double *flown_kf,
                       sitl_sensor_errors_t *out);

/* Mean age [s] of the newest rotor-speed report the filter holds at a gyro sample
 * (--filter-report-age, docs/math.md §2 "What the prediction misses"): reports
 * every 1 / esc->rate_hz from esc->phase_s, each measured esc->latency_s before it
 * arrives, paired with the gyro sample at t when they arrived by t + latency (the
 * filter told the latency as its delay); gyro samples every 1 / gyro_rate_hz from
 * gyro_first_s. Averaged over one second of gyro samples (the streams' common
 * period for rates in whole hertz). Unlocked clocks average half the report
 * period. */
double sitl_report_mean_age(const sitl_esc_params_t *esc, double gyro_rate_hz, double gyro_first_s);

#endif /* SITL_SENSOR_ERRORS_H */
