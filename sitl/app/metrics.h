/*
 * Flight metrics (Table 1 style): tracking RMSE per axis and yaw, final
 * errors, and filter convergence times. Convergence time (docs/results.md,
 * the one definition host_tools/propid/table1.py uses too): the first time
 * after which EVERY later estimate stays within 0.1 x the filter's prior
 * standard deviation of that state from the truth — for all kf and km
 * together, and for all three gyro biases together. Never reached (the last
 * sample is outside) = -1.
 */
#ifndef SITL_METRICS_H
#define SITL_METRICS_H

#include "propid/propid.h"
#include "vehicle.h"

typedef struct {
    int rotor_count;
    double kf_tolerance[SITL_MAX_ROTORS];   /* 0.1 x prior std [N/(rad/s)^2] */
    double km_tolerance[SITL_MAX_ROTORS];
    double bias_tolerance;                  /* 0.1 x prior std [rad/s] */
    long samples;
    double sum_sq[3];
    double sum_sq_yaw;                      /* [rad^2] */
    double coeff_converged_since;           /* -1 while outside */
    double bias_converged_since;
    /* Latest values. */
    double position_error[3];
    double yaw_error;                       /* [rad] */
    double kf_rel_error_max;                /* max_i |kf_est/kf_true - 1| */
    double km_rel_error_max;
    double bias_error_max;                  /* max_k |b_est - b_true| [rad/s] */
} sitl_metrics_t;

void sitl_metrics_init(sitl_metrics_t *m, int rotor_count, const double *kf_prior_std,
                       const double *km_prior_std, double bias_prior_std);

void sitl_metrics_add(sitl_metrics_t *m, double t, const double position[3],
                      const double ref_position[3], double yaw, double ref_yaw,
                      const propid_estimate_t *estimate, const double *true_kf,
                      const double *true_km, const double true_bias[3]);

/* RMSE [m] of axis 0..2, yaw RMSE [deg]. */
double sitl_metrics_rmse(const sitl_metrics_t *m, int axis);
double sitl_metrics_rmse_yaw_deg(const sitl_metrics_t *m);

#endif /* SITL_METRICS_H */
