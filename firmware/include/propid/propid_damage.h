/*
 * Propeller damage detector: a bank of one-sided CUSUM tests, one per rotor,
 * on the filter's own normalised gyro innovations projected on the signature
 * a loss of that rotor's coefficients leaves in them (docs/damage.md).
 *
 * Use: after every propid_push_gyro() that returned PROPID_OK or
 * PROPID_OK_GATED, call propid_damage_step(). On a detection it isolates the
 * rotor (largest statistic), re-opens that rotor's kf and km covariance to the
 * prior (the estimates are kept and re-converge in flight), sets
 * PROPID_HEALTH_ROTOR_DAMAGE in the filter's health and counts the event.
 * The allocation that reads the filter's estimates then re-allocates with the
 * new coefficients.
 *
 * Allocation-free, float32, bounded loops; state lives in propid_damage_t.
 */
#ifndef PROPID_DAMAGE_H
#define PROPID_DAMAGE_H

#include <stdbool.h>
#include <stdint.h>

#include "propid/propid.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    /* Design false-alarm rate of the whole bank on a healthy vehicle whose
     * projected innovations are white or AR(1) Gaussian [alarms per flight hour]. */
    float false_alarms_per_hour;
    /* Mean shift of the projected, normalised innovation the test is tuned to
     * detect fastest [standard deviations]; the CUSUM drift is half of it. */
    float design_shift_sigma;
    /* Derived design (docs/math.md §4, "The damage detector's variance floor
     * and design shift, derived"): when > 0, the smallest loss (fraction of a
     * rotor's kf and km) the bank is tuned for: each rotor's design shift is
     * the shift that loss makes in its standardised projection, measured while
     * the bank arms, and the running variances are floored at the gyro noise's
     * share (for a filter whose innovation variances S are wide, e.g. one that
     * carries a held rotor-speed error); design_shift_sigma stays only where the
     * shift cannot be measured. 0 (default): design_shift_sigma for every rotor
     * and a fixed floor of 0.25. */
    float design_loss_fraction;
    /* After a detection the bank is frozen this long while the re-opened
     * coefficients re-converge [s]. */
    float hold_s;
    /* Time constant of the running mean and variance that standardise each
     * rotor's projected innovation (slow model error is not damage) [s]; the
     * bank is armed after 3 of them, from the start and after a detection. */
    float adapt_time_s;
} propid_damage_config_t;

typedef struct {
    propid_damage_config_t config;
    float drift;                           /* CUSUM reference value k [sigma] */
    float threshold;                       /* CUSUM decision threshold h [sigma] */
    float clip;                            /* increments clipped at drift + threshold / 3 [sigma] */
    float arl_samples;                     /* in-control average run length each test is designed for */
    float rotor_drift[PROPID_MAX_ROTORS];  /* each rotor's k, from its design loss (or drift) [sigma] */
    float rotor_threshold[PROPID_MAX_ROTORS]; /* each rotor's h for that k and arl_samples [sigma] */
    float rotor_clip[PROPID_MAX_ROTORS];   /* each rotor's increment clip, k + h / 3 [sigma] */
    float loss_shift[PROPID_MAX_ROTORS];   /* running |g_i| / sd_i: a whole loss' first-sample shift [sigma] */
    float statistic[PROPID_MAX_ROTORS];    /* CUSUM statistic per rotor [sigma] */
    float mean[PROPID_MAX_ROTORS];         /* running mean of the projection */
    float var[PROPID_MAX_ROTORS];          /* running variance of the projection */
    float cov1[PROPID_MAX_ROTORS];         /* running lag-1 autocovariance of the projection */
    float residual_var[PROPID_MAX_ROTORS]; /* running variance of its AR(1) prediction error */
    float previous[PROPID_MAX_ROTORS];     /* previous deviation from the mean, clipped at 3 sigma */
    float offset[PROPID_MAX_ROTORS];       /* rise of the projection made by the filter's re-anchors, decaying */
    float offset_last[PROPID_MAX_ROTORS];  /* the offset of the previous sample */
    float armed_s;                         /* time since (re-)start, arms the bank */
    uint64_t last_time_us;                 /* estimate time of the previous step */
    uint64_t hold_until_us;                /* bank frozen until then */
    uint64_t last_detection_us;            /* time of the latest detection */
    uint32_t detections;                   /* count since init */
    uint32_t reanchors_seen;               /* the filter's gate re-opening count at the last step */
    uint16_t damaged_mask;                 /* bit i: rotor i detected since init */
    uint8_t rotor_count;
    uint8_t has_time;
    uint8_t design_set;                    /* the rotors' k and h were derived since the last (re-)start */
    int8_t last_rotor;                     /* latest isolated rotor, -1 none */
    bool landed;                           /* the caller's ground contact (propid_damage_set_landed) */
} propid_damage_t;

/* Defaults: 1e-3 false alarms per flight hour, design shift 8 sigma (no derived
 * design), hold 0.5 s, adaptation 0.5 s (armed 1.5 s after start and after
 * each detection). */
void propid_damage_config_default(propid_damage_config_t *config);

/* Threshold h of one CUSUM test whose in-control average run length is
 * arl_samples (Siegmund's approximation for unit-variance Gaussian increments
 * and drift k); bisection, 60 iterations. Returns a negative value on bad input. */
float propid_damage_threshold(float drift, float arl_samples);

/* Derive drift and threshold for the filter's rotor count and gyro rate.
 * PROPID_ERR_CONFIG on a bad configuration, PROPID_ERR_NULL, PROPID_ERR_NOT_INITIALISED. */
propid_status_t propid_damage_init(propid_damage_t *detector, const propid_damage_config_t *config,
                                   const propid_filter_t *filter);

/* One step after an accepted gyro sample. *detected_rotor = the isolated rotor
 * (0-based) when this step detected a damage, else -1. PROPID_OK, or an error
 * status (filter untouched) on NULL or an uninitialised filter. */
propid_status_t propid_damage_step(propid_damage_t *detector, propid_filter_t *filter,
                                   int8_t *detected_rotor);

/* Optional ground-contact input (a flight controller's land detector): while
 * landed is true the bank does not test (a vehicle the ground holds leaves no
 * loss in the gyro, and the contact torques the model lacks would read as
 * one, e.g. on a wreck whose rotors still run); it restarts on every landed
 * step, so after take-off it re-learns its moments and arms 3 adaptation
 * times later, as after init. Never called (the default): the detector is as
 * without it. PROPID_OK, PROPID_ERR_NULL, or PROPID_ERR_NOT_INITIALISED on a
 * detector propid_damage_init() has not set up (detector untouched). */
propid_status_t propid_damage_set_landed(propid_damage_t *detector, bool landed);

#ifdef __cplusplus
}
#endif

#endif /* PROPID_DAMAGE_H */
