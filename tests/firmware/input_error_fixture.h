/*
 * Shared set-up of the rotor-speed input-error tests (test_input_noise.c,
 * test_input_compensation.c): a Crazyflie-sized vehicle and a filter state off
 * its prior, so that the terms under test are not evaluated at a trivial point.
 */
#ifndef PROPID_TEST_INPUT_ERROR_FIXTURE_H
#define PROPID_TEST_INPUT_ERROR_FIXTURE_H

#include "propid/propid.h"
#include "unity.h"
#include "../../firmware/src/propid_internal.h"
#include "../../firmware/src/propid_model.h"
#include "per_rotor_view.h"

/* Symmetric vehicle of `rotors` rotors; `full_inertia` adds a product of
 * inertia so the general (non-diagonal) inverse is exercised. */
static inline void input_error_configure(propid_config_t *config, uint8_t rotors, int full_inertia)
{
    propid_config_default(config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(config, rotors, 0.17f, 0.785398f, 1.0f,
                                                                 5.57e-6f, 1.36e-7f));
    propid_config_set_inertia_diag(config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    if (full_inertia) {
        config->inertia[0][1] = 1.0e-4f;
        config->inertia[1][0] = 1.0e-4f;
    }
}

/* Initialised filter with coefficients not 1, non-zero rates, and rotor
 * speeds that differ at the two ends of the prediction interval. */
static inline void input_error_off_prior(propid_filter_t *filter, const propid_config_t *config)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, config));
    const uint8_t rotors = config->rotor_count;
    filter->core.state[0] = 0.3f;
    filter->core.state[1] = -0.2f;
    filter->core.state[2] = 0.1f;
    for (uint8_t i = 0; i < rotors; ++i) {
        filter->core.state[PROPID_RATE_STATES + i] = 0.8f + 0.1f * (float)i;
        filter->core.state[PROPID_RATE_STATES + rotors + i] = 1.3f - 0.1f * (float)i;
        const float start = 500.0f + 20.0f * (float)i;
        const float end = 520.0f - 10.0f * (float)i;
        filter->core.input_speed_sq[i] = start * start;
        filter->core.rotor_speed_sq[i] = end * end;
    }
}


/* One prediction step of dt of two filters with the same inputs: `plain`
 * without the term under test, `with_term` with it. */
static inline void input_error_predict_pair(propid_filter_t *plain, propid_filter_t *with_term, float dt)
{
    float rate_next[3];
    float jac_dt[3][PROPID_JAC_ROW];
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_stage(plain, dt, rate_next, jac_dt));
    propid_predict_covariance(&plain->derived, &plain->core, dt, jac_dt);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_stage(with_term, dt, rate_next, jac_dt));
    propid_predict_covariance(&with_term->derived, &with_term->core, dt, jac_dt);
}

/* B_ai = d(omega_dot_a)/d(u_i) densely: the model's coefficient columns at unit
 * inputs times the per-rotor coefficients (the filter keeps the coefficient
 * blocks in their bases, per_rotor_core maps them back). */
static inline void input_error_dense_gain(const propid_filter_t *filter, float gain[3][PROPID_MAX_ROTORS])
{
    const uint8_t rotors = filter->config.rotor_count;
    float rows[3][PROPID_MAX_STATES];
    float unit_speed_sq[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotors; ++i) {
        unit_speed_sq[i] = 1.0f;
    }
    const propid_core_t per_rotor = per_rotor_core(filter);
    const float *x = per_rotor.state;
    propid_model_rate_jacobian(&filter->config, &filter->derived, x, unit_speed_sq, rows);
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t i = 0; i < rotors; ++i) {
            gain[a][i] = rows[a][PROPID_RATE_STATES + i] * x[PROPID_RATE_STATES + i] +
                         rows[a][PROPID_RATE_STATES + rotors + i] * x[PROPID_RATE_STATES + rotors + i];
        }
    }
}

#endif
