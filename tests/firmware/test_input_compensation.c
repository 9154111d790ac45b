/*
 * Errors-in-variables compensation of the coefficient update
 * (config.input_error_compensation, docs/math.md §14):
 * - the corrections equal a dense evaluation of the formula from the predicted P
 *   and the model's Jacobian (quad layout, general lists, hexa), with the memory
 *   recursion of a correlated error;
 * - only fused axes whose validity test passes are corrected; the memory follows
 *   the rate gain (a gated axis keeps its whole error);
 * - the correction moves the mean only: the covariance is the uncompensated one;
 * - an error the data cannot carry (most of the information) is withheld;
 * - the configuration check refuses bad values by name, also when compiled out.
 */
#include <math.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "../../firmware/src/propid_internal.h"
#include "per_rotor_view.h"
#include "../../firmware/src/propid_model.h"
#include "input_error_fixture.h"

void setUp(void) {}
void tearDown(void) {}

#if PROPID_WITH_INPUT_NOISE
static propid_filter_t compensated;
static propid_filter_t plain;

/* The fixture's vehicle with an input error of sigma over time and the compensation on. */
static void configure_compensated(propid_config_t *config, uint8_t rotors, int full_inertia, float sigma, float time)
{
    input_error_configure(config, rotors, full_inertia);
    config->rotor_speed_noise = sigma;
    config->rotor_speed_noise_time = time;
    config->input_error_compensation = 1u;
}

/* The fixture's filter off the prior, with a correlated coefficient block. */
static void prepare(propid_filter_t *filter, const propid_config_t *config)
{
    input_error_off_prior(filter, config);
    const uint8_t rotors = config->rotor_count;
    /* Correlations within the coefficient block and with the rates. */
    for (uint8_t k = 0; k + 1u < 2u * rotors; ++k) {
        const uint8_t i = (uint8_t)(PROPID_RATE_STATES + k);
        filter->core.cov[propid_cov_index(i, (uint8_t)(i + 1u))] = 0.2f * filter->core.cov[propid_cov_index(i, i)];
    }
    filter->core.cov[propid_cov_index(0u, PROPID_RATE_STATES)] = 1.0e-3f;
    filter->core.cov[propid_cov_index(1u, PROPID_RATE_STATES + 1u)] = -2.0e-3f;
}

static void check_dense(uint8_t rotors, int full_inertia, float time)
{
    const float sigma = 30.0f;
    const float dt = 0.002f;
    propid_config_t config;
    configure_compensated(&config, rotors, full_inertia, sigma, time);
    prepare(&compensated, &config);
    const float carried_before[3] = {0.5f, 0.0f, 2.0f};
    const float cross_before[3] = {0.3f, 0.0f, 0.7f};
    for (uint8_t a = 0; a < 3u; ++a) {
        compensated.core.input_error_carried[a] = carried_before[a];
        compensated.core.input_error_cross[a] = cross_before[a];
    }
    float rate_next[3];
    float jac_dt[3][PROPID_JAC_ROW];
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_stage(&compensated, dt, rate_next, jac_dt));
    propid_predict_covariance(&compensated.derived, &compensated.core, dt, jac_dt);
    propid_input_compensation_prepare(&compensated, dt);
    const propid_core_t *out = &compensated.core;

    /* Dense: E_a,col = d(omega_dot_a)/d(x_col) at unit speeds, B_ai from it. */
    const propid_filter_t *f = &compensated;
    /* Per rotor (the filter keeps the coefficient blocks in their bases). */
    const propid_core_t per_rotor = per_rotor_core(f);
    const propid_reflection_t basis = propid_drag_basis(&f->derived, &f->config);
    const float *x = per_rotor.state;
    const uint8_t first = PROPID_RATE_STATES;
    const uint8_t coefficients = (uint8_t)(2u * rotors);
    float rows[3][PROPID_MAX_STATES];
    float unit_speed_sq[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotors; ++i) {
        unit_speed_sq[i] = 1.0f;
    }
    propid_model_rate_jacobian(&f->config, &f->derived, x, unit_speed_sq, rows);
    const float rho = time > 0.0f ? expf(-dt / time) : 0.0f;
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t bias = (uint8_t)(f->derived.layout.gyro_bias + a);
        const float s = propid_cov_at(per_rotor.cov, a, a) + 2.0f * propid_cov_at(per_rotor.cov, a, bias) +
                        propid_cov_at(per_rotor.cov, bias, bias) + f->derived.gyro_var;
        const float gain_rate = (propid_cov_at(per_rotor.cov, a, a) + propid_cov_at(per_rotor.cov, a, bias)) / s;
        /* The filter's correction of the kept states, per rotor. */
        float correction[2u * PROPID_MAX_ROTORS];
        for (uint8_t k = 0; k < 2u * rotors; ++k) {
            correction[k] = out->input_product[1u + a][k];
        }
        propid_reflection_apply(&basis, correction + rotors);
        propid_thrust_basis_t thrust;
        propid_thrust_basis_init(&thrust, &f->derived, &f->config);
        propid_thrust_to_rotor(&thrust, correction);
        const float carried = carried_before[a] + 2.0f * rho * cross_before[a] + 1.0f;
        TEST_ASSERT_FLOAT_WITHIN(1.0e-5f * carried, carried, out->input_step_carried[a]);
        TEST_ASSERT_FLOAT_WITHIN(1.0e-5f, gain_rate, out->input_rate_gain[a]);
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, rho * cross_before[a], out->input_step_cross[a]);
        const float weight = carried * dt * dt / s;
        float largest = 0.0f;
        for (uint8_t k = 0; k < coefficients; ++k) {
            float expected = 0.0f;
            for (uint8_t c = 0; c < coefficients; ++c) {
                const uint8_t rotor = (uint8_t)(c % rotors);
                const float b = rows[a][first + rotor] * x[first + rotor] +
                                rows[a][first + rotors + rotor] * x[first + rotors + rotor];
                const float var = 4.0f * sigma * sigma * 0.5f *
                                  (f->core.input_speed_sq[rotor] + f->core.rotor_speed_sq[rotor]);
                expected += weight * var * b * rows[a][first + c] *
                            propid_cov_at(per_rotor.cov, (uint8_t)(first + k), (uint8_t)(first + c));
            }
            largest = fmaxf(largest, fabsf(expected));
            TEST_ASSERT_FLOAT_WITHIN(2.0e-3f * fabsf(expected) + 1.0e-9f, expected, correction[k]);
        }
        if (a < 2u) {
            TEST_ASSERT_TRUE(largest > 0.0f); /* the roll and pitch rows carry thrust */
        }
    }
}

static void test_corrections_match_the_dense_formula(void)
{
    check_dense(4u, 0, 0.0f);   /* quad layout, white error */
    check_dense(4u, 0, 0.02f);  /* quad layout, an error correlated over 10 steps */
    check_dense(4u, 1, 0.01f);  /* general lists (full inertia) */
    check_dense(6u, 0, 0.0f);   /* hexa */
}

static void test_only_fused_valid_axes_are_corrected(void)
{
    propid_config_t config;
    configure_compensated(&config, 4u, 0, 10.0f, 0.0f);
    prepare(&compensated, &config);
    float before[PROPID_MAX_STATES];
    memcpy(before, compensated.core.state, sizeof(before));
    propid_core_t *work = &compensated.core;
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t k = 0; k < 8u; ++k) {
            work->input_product[1u + a][k] = (float)(a + 1u) * 1.0e-3f * (float)(k + 1u);
        }
        work->input_rate_gain[a] = 0.25f * (float)(a + 1u);
        work->input_step_carried[a] = 1.5f;
        work->input_step_cross[a] = 0.4f;
    }
    work->input_valid[0] = 1u; /* fused, valid: corrected */
    work->input_valid[1] = 0u; /* fused, not valid: withheld */
    work->input_valid[2] = 1u; /* gated: nothing */
    propid_input_compensation_apply(&compensated, 1u << 2);
    for (uint8_t k = 0; k < 8u; ++k) {
        TEST_ASSERT_EQUAL_FLOAT(before[PROPID_RATE_STATES + k] + work->input_product[1][k],
                                compensated.core.state[PROPID_RATE_STATES + k]);
    }
    for (uint8_t k = 0; k < 3u; ++k) { /* rates untouched */
        TEST_ASSERT_EQUAL_FLOAT(before[k], compensated.core.state[k]);
    }
    /* Memory: kept = 1 - K for a fused axis, 1 for the gated one. */
    const float kept[3] = {0.75f, 0.5f, 1.0f};
    for (uint8_t a = 0; a < 3u; ++a) {
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, kept[a] * (0.4f + 1.0f), compensated.core.input_error_cross[a]);
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, kept[a] * kept[a] * 1.5f, compensated.core.input_error_carried[a]);
    }
}

/* Same pushes into a filter with the error term only and one with the compensation. */
static void fly(propid_filter_t *filter, const propid_config_t *config, uint32_t steps, float excitation)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(filter, config));
    uint64_t t = 1000u;
    for (uint32_t k = 0; k < steps; ++k) {
        const float phase = 0.05f * (float)k;
        const float wobble = excitation * sinf(phase);
        /* Roll and pitch torques both excited (X quad: rotors at 45, 135, 225, 315 degrees). */
        const float speeds[4] = {900.0f + wobble, 900.0f + 0.5f * wobble, 900.0f - wobble, 900.0f - 0.5f * wobble};
        TEST_ASSERT_TRUE(propid_push_rotor_speeds(filter, t, speeds, 4u) >= 0);
        const float gyro[3] = {0.2f * sinf(phase + 0.3f) * excitation / 50.0f, 0.1f * cosf(phase), 0.01f};
        TEST_ASSERT_TRUE(propid_push_gyro(filter, t + 500u, gyro) >= 0);
        t += 2000u;
    }
}

static void test_the_correction_moves_the_mean_only(void)
{
    /* One step of each from the same state, the validity statistics set to pass:
     * the covariance and the rates are the uncompensated update's, bit for bit. */
    propid_config_t config;
    configure_compensated(&config, 4u, 0, 20.0f, 0.0f);
    prepare(&plain, &config);
    prepare(&compensated, &config);
    for (uint8_t a = 0; a < 3u; ++a) {
        compensated.core.input_information[a] = 1.0f;
        compensated.core.input_information_time = 1.0f;
    }
    const float dt = 0.002f;
    const float gyro[3] = {0.31f, -0.19f, 0.1f};
    float rate_next[3];
    float jac_dt[3][PROPID_JAC_ROW];
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_stage(&plain, dt, rate_next, jac_dt));
    propid_predict_covariance(&plain.derived, &plain.core, dt, jac_dt);
    TEST_ASSERT_EQUAL_UINT32(0u, propid_update_gyro(&plain, gyro));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_stage(&compensated, dt, rate_next, jac_dt));
    propid_predict_covariance(&compensated.derived, &compensated.core, dt, jac_dt);
    propid_input_compensation_prepare(&compensated, dt);
    TEST_ASSERT_EQUAL_UINT32(0u, propid_update_gyro(&compensated, gyro));
    propid_input_compensation_apply(&compensated, 0u);
    const propid_core_t *out = &compensated.core;
    TEST_ASSERT_TRUE(out->input_valid[0] && out->input_valid[1]);
    TEST_ASSERT_EQUAL_MEMORY(plain.core.cov, compensated.core.cov, sizeof(plain.core.cov));
    TEST_ASSERT_EQUAL_MEMORY(plain.core.state, compensated.core.state, 3u * sizeof(float)); /* rates */
    for (uint8_t k = 0; k < 8u; ++k) {
        const float expected = plain.core.state[PROPID_RATE_STATES + k] + out->input_product[1][k] +
                               out->input_product[2][k] + out->input_product[3][k];
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, expected, compensated.core.state[PROPID_RATE_STATES + k]);
        TEST_ASSERT_TRUE(plain.core.state[PROPID_RATE_STATES + k] != compensated.core.state[PROPID_RATE_STATES + k]);
    }
}

static void test_an_error_the_data_cannot_carry_is_withheld(void)
{
    /* Speeds that barely move and an error of 500 rad/s: the error is most of the
     * information, every correction is withheld and the estimates are the ones of
     * the error term alone, bit for bit. */
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    config.rotor_speed_noise = 500.0f;
    fly(&plain, &config, 300u, 1.0f);
    config.input_error_compensation = 1u;
    fly(&compensated, &config, 300u, 1.0f);
    for (uint8_t a = 0; a < 2u; ++a) {
        TEST_ASSERT_TRUE(compensated.core.input_error_information[a] >
                         PROPID_INPUT_ERROR_MAX_SHARE * compensated.core.input_information[a]);
    }
    TEST_ASSERT_EQUAL_MEMORY(plain.core.state, compensated.core.state, sizeof(plain.core.state));
    /* A small error on a well excited flight is corrected. */
    config.input_error_compensation = 0u;
    config.rotor_speed_noise = 2.0f;
    fly(&plain, &config, 300u, 50.0f);
    config.input_error_compensation = 1u;
    fly(&compensated, &config, 300u, 50.0f);
    TEST_ASSERT_TRUE(compensated.core.input_error_information[0] <
                     PROPID_INPUT_ERROR_MAX_SHARE * compensated.core.input_information[0]);
    int moved = 0;
    for (uint8_t k = 0; k < 8u; ++k) {
        moved |= plain.core.state[PROPID_RATE_STATES + k] != compensated.core.state[PROPID_RATE_STATES + k];
    }
    TEST_ASSERT_TRUE(moved);
}

static void test_compensation_config_is_checked(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    const char *bad = NULL;
    config.input_error_compensation = 1u; /* no error size to compensate */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("input_error_compensation", bad);
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&compensated, &config));
    config.rotor_speed_noise = 2.0f;
    config.input_error_compensation = 2u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("input_error_compensation", bad);
    config.input_error_compensation = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
}
#else
static void test_compensation_compiled_out_refuses_the_option(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    config.input_error_compensation = 1u;
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("input_error_compensation", bad);
}
#endif

int main(void)
{
    UNITY_BEGIN();
#if PROPID_WITH_INPUT_NOISE
    RUN_TEST(test_corrections_match_the_dense_formula);
    RUN_TEST(test_only_fused_valid_axes_are_corrected);
    RUN_TEST(test_the_correction_moves_the_mean_only);
    RUN_TEST(test_an_error_the_data_cannot_carry_is_withheld);
    RUN_TEST(test_compensation_config_is_checked);
#else
    RUN_TEST(test_compensation_compiled_out_refuses_the_option);
#endif
    return UNITY_END();
}
