/*
 * Body-rate dynamics of the scaled model (internal; exposed for tests):
 *
 *   domega/dt = sum_i thrust_torque_i kf_rel_i u_i + sum_i drag_torque_i km_rel_i u_i
 *               - J^-1 (omega x J omega),          u_i = rotor_speed_i^2
 *
 * with thrust_torque_i = J^-1 (r_i x z) kf_nominal_i and
 * drag_torque_i = J^-1 z yaw_sign_i km_nominal_i (precomputed in propid_derived_t).
 */
#ifndef PROPID_MODEL_H
#define PROPID_MODEL_H

#include "propid/propid.h"

/* Angular acceleration at the scaled state for the given squared rotor speeds. */
void propid_model_rate_derivative(const propid_config_t *config, const propid_derived_t *derived,
                                  const float *state, const float *rotor_speed_sq,
                                  float rate_dot[3]);

/* Jacobian rows of the angular acceleration: rows[a][k] = d rate_dot[a] / d state[k]
 * for k < 3 + 2 * rotor_count (the gyro-bias columns are zero and left untouched). */
void propid_model_rate_jacobian(const propid_config_t *config, const propid_derived_t *derived,
                                const float *state, const float *rotor_speed_sq,
                                float rows[3][PROPID_MAX_STATES]);

/* Both at once, sharing the work; each output may be NULL. */
void propid_model_rates(const propid_config_t *config, const propid_derived_t *derived,
                        const float *state, const float *rotor_speed_sq, float rate_dot[3],
                        float rows[3][PROPID_MAX_STATES]);

#endif /* PROPID_MODEL_H */
