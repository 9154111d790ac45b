/*
 * Dense baseline of the propid gyro step, for the benchmark only (count_step.c,
 * `make bench`): the same model (propid's own prediction and Jacobian code) in
 * the straightforward dense EKF formulation of a generic small-EKF library, so
 * the instruction counts of the two formulations can be compared on the same
 * input. Not part of the firmware.
 */
#ifndef PROPID_DENSE_EKF_H
#define PROPID_DENSE_EKF_H

#include <stdint.h>

#include "propid/propid.h"

#define DENSE_MAX PROPID_MAX_STATES

typedef struct {
    int n;
    float x[DENSE_MAX];
    float p[DENSE_MAX][DENSE_MAX];
} dense_ekf_t;

/* State and full covariance from an initialised propid filter. */
void dense_ekf_load(dense_ekf_t *dense, const propid_filter_t *model);

/* One gyro step (predict to time_us, fuse the three axes). `model` is a propid
 * filter used only for its model (prediction, Jacobian, rotor inputs, time);
 * its estimate is not updated. Returns 0, or -1 on a numerical failure. */
int dense_ekf_step(dense_ekf_t *dense, propid_filter_t *model, uint64_t time_us,
                   const float gyro[3]);

#endif /* PROPID_DENSE_EKF_H */
