/*
 * ESC rotor-speed telemetry: what the flight controller learns about the
 * rotor speeds, and when.
 *   - one report of all rotors every 1/rate_hz, first at phase_s;
 *   - each report carries the true speed of latency_s (+ esc_delay effect)
 *     before its arrival time, read from a history of the true speeds;
 *   - quantised like bidirectional DShot eRPM telemetry (12-bit e-period:
 *     3-bit exponent, 9-bit mantissa, in microseconds of electrical period,
 *     truncated by the ESC) for a motor with pole_pairs pole pairs, or not at
 *     all; decoded at the code's period (as the flight controllers' drivers
 *     do) or at the middle of the code's period interval (unbiased);
 *   - each report is lost with probability dropout_prob.
 * Defaults and sources: docs/sitl.md.
 */
#ifndef SITL_ESC_TELEMETRY_H
#define SITL_ESC_TELEMETRY_H

#include <stdint.h>

#include "rng.h"
#include "vehicle.h"

typedef struct {
    double rate_hz;
    double phase_s;          /* first report time */
    double latency_s;        /* measurement-to-arrival delay */
    double dropout_prob;     /* 0..1 */
    int quantise_dshot;      /* 1 = DShot e-period encoding, 0 = exact */
    int decode_middle;       /* 1 = decode at the middle of the code's period interval, 0 = at its period */
    int pole_pairs;          /* motor pole pairs (eRPM = pole_pairs * RPM) */
} sitl_esc_params_t;

typedef struct {
    double time;
    double speed[SITL_MAX_ROTORS];
} sitl_speed_sample_t;

typedef struct {
    sitl_esc_params_t params;
    double extra_delay_s;     /* esc_delay effect */
    int rotor_count;
    sitl_speed_sample_t *history;  /* ring buffer of true speeds */
    int capacity;
    int head;                 /* next write slot */
    int size;
    sitl_rng_t rng;
} sitl_esc_telemetry_t;

void sitl_esc_default_params(sitl_esc_params_t *params);
/* The paper: exact speeds at the control rate, no latency, no loss. */
void sitl_esc_paper_params(sitl_esc_params_t *params, double control_rate_hz);

/* history_rate_hz: how often sitl_esc_record() will be called (sizes the buffer).
 * Returns 0, or -1 on allocation failure / bad parameters. */
int sitl_esc_init(sitl_esc_telemetry_t *esc, const sitl_esc_params_t *params, int rotor_count,
                  double extra_delay_s, double history_rate_hz, uint64_t seed);
void sitl_esc_free(sitl_esc_telemetry_t *esc);

/* Remember the true speeds at time t (non-decreasing t). */
void sitl_esc_record(sitl_esc_telemetry_t *esc, double t, const double *speed);

/* The report arriving at time t: returns 1 and fills speed_out, or 0 if lost. */
int sitl_esc_report(sitl_esc_telemetry_t *esc, double t, double *speed_out);

/* DShot e-period round trip of one speed (exposed for tests); decode_middle as
 * in sitl_esc_params_t. */
double sitl_esc_quantise_dshot(double speed_rad_s, int pole_pairs, int decode_middle);

/* Speed step of the DShot e-period code a speed is sent as [rad/s] (the speeds
 * of the code's period and of the next longer period); 0 when stopped. */
double sitl_esc_dshot_step(double speed_rad_s, int pole_pairs);

#endif /* SITL_ESC_TELEMETRY_H */
