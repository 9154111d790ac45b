/*
 * The rate model and its Jacobian rows (firmware/src/propid_model.c):
 * - the Jacobian rows against central finite differences of the model itself,
 *   for plus and X quads, a hexa and a full (non-diagonal) inertia;
 * - the model against torques computed independently from the geometry
 *   (r x F and yaw_sign * km * Omega^2), including the paper's plus-frame signs;
 * - the derived quantities (inertia inverse, rotor layout of set_symmetric).
 * The model is quadratic in the rates and linear in the coefficients, so a
 * central difference is exact up to rounding: the tolerance only covers float32
 * rounding of the terms involved.
 */
#include <math.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"
#include "../../firmware/src/propid_model.h"

#define TEST_PI 3.14159265358979f

void setUp(void) {}
void tearDown(void) {}

static propid_filter_t filter;

static float rng_uniform(rng_t *rng, float lo, float hi)
{
    return rng_range(rng, lo, hi);
}

static void init_symmetric(uint8_t rotors, float arm, float angle, float kf, float km,
                           float jxx, float jyy, float jzz)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, rotors, arm, angle, 1.0f, kf, km));
    propid_config_set_inertia_diag(&config, jxx, jyy, jzz);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
}

/* Jacobian rows vs central differences at random states and rotor speeds. */
static void check_jacobian(uint32_t seed)
{
    rng_t rng = {seed};
    const uint8_t n_rotors = filter.config.rotor_count;
    const uint8_t active = (uint8_t)(3u + 2u * n_rotors);
    float max_speed = 0.0f;
    /* Pick speeds that give torques of flight magnitude for this vehicle. */
    max_speed = sqrtf(9.81f * 0.5f / (filter.config.rotor[0].thrust_coeff_nominal * (float)n_rotors)) * 1.4f;
    for (int trial = 0; trial < 20; ++trial) {
        float state[PROPID_MAX_STATES];
        float speed_sq[PROPID_MAX_ROTORS];
        memset(state, 0, sizeof(state));
        for (int a = 0; a < 3; ++a) {
            state[a] = rng_uniform(&rng, -4.0f, 4.0f);
        }
        for (uint8_t k = 3u; k < active; ++k) {
            state[k] = rng_uniform(&rng, 0.6f, 1.4f);
        }
        for (uint8_t i = 0; i < n_rotors; ++i) {
            const float s = rng_uniform(&rng, 0.3f, 1.0f) * max_speed;
            speed_sq[i] = s * s;
        }
        float rows[3][PROPID_MAX_STATES];
        propid_model_rate_jacobian(&filter.config, &filter.derived, state, speed_sq, rows);

        float scale = 0.0f; /* size of the terms the derivative is made of */
        float rate_dot[3];
        propid_model_rate_derivative(&filter.config, &filter.derived, state, speed_sq, rate_dot);
        for (int a = 0; a < 3; ++a) {
            scale = fmaxf(scale, fabsf(rate_dot[a]));
        }
        for (uint8_t k = 0; k < active; ++k) {
            const float h = k < 3u ? 0.25f : 0.1f;
            float plus[PROPID_MAX_STATES];
            float minus[PROPID_MAX_STATES];
            memcpy(plus, state, sizeof(plus));
            memcpy(minus, state, sizeof(minus));
            plus[k] += h;
            minus[k] -= h;
            float f_plus[3];
            float f_minus[3];
            propid_model_rate_derivative(&filter.config, &filter.derived, plus, speed_sq, f_plus);
            propid_model_rate_derivative(&filter.config, &filter.derived, minus, speed_sq, f_minus);
            for (int a = 0; a < 3; ++a) {
                const float numeric = (f_plus[a] - f_minus[a]) / (2.0f * h);
                const float column_scale = fmaxf(fabsf(rows[a][k]), 1.0f);
                /* Rounding of f (|f| ~ scale) over the step 2h, plus relative 1e-4. */
                const float tol = 8.0f * 1.2e-7f * (scale + 10.0f) / h + 1.0e-4f * column_scale;
                TEST_ASSERT_FLOAT_WITHIN(tol, numeric, rows[a][k]);
            }
        }
    }
}

static void test_jacobian_plus_quad(void)
{
    init_symmetric(4u, 0.043f, 0.0f, 2.3e-8f, 7.8e-10f, 1.43e-5f, 1.43e-5f, 2.89e-5f);
    check_jacobian(1u);
}

static void test_jacobian_x_quad(void)
{
    init_symmetric(4u, 0.17f, TEST_PI / 4.0f, 5.57e-6f, 1.36e-7f, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    check_jacobian(2u);
}

static void test_jacobian_hexa(void)
{
    init_symmetric(6u, 0.25f, 0.0f, 1.0e-5f, 2.0e-7f, 1.0e-2f, 1.1e-2f, 1.8e-2f);
    check_jacobian(3u);
}

static void test_jacobian_full_inertia_and_offset_rotors(void)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 4u, 0.17f, 0.3f, -1.0f,
                                                                 5.57e-6f, 1.36e-7f));
    /* Rotors off the plane and off-centre, distinct nominals, products of inertia. */
    config.rotor[0].position_m[2] = 0.02f;
    config.rotor[1].position_m[0] += 0.01f;
    config.rotor[2].thrust_coeff_nominal = 6.0e-6f;
    config.rotor[3].drag_coeff_nominal = 1.2e-7f;
    const float inertia[3][3] = {{3.65e-3f, 2.0e-4f, -1.5e-4f},
                                 {2.0e-4f, 3.68e-3f, 1.0e-4f},
                                 {-1.5e-4f, 1.0e-4f, 7.03e-3f}};
    memcpy(config.inertia, inertia, sizeof(inertia));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    check_jacobian(4u);

    /* J * J^-1 = I */
    for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
            float sum = 0.0f;
            for (int c = 0; c < 3; ++c) {
                sum += inertia[a][c] * filter.derived.inertia_inv[c][b];
            }
            TEST_ASSERT_FLOAT_WITHIN(1.0e-5f, a == b ? 1.0f : 0.0f, sum);
        }
    }
}

/* The model against torques built independently: tau = sum r_i x (kf_i u_i z)
 * + sum s_i km_i u_i z, then J^-1 (tau - omega x J omega) with diagonal J. */
static void test_rate_derivative_matches_rigid_body(void)
{
    init_symmetric(4u, 0.17f, TEST_PI / 4.0f, 5.57e-6f, 1.36e-7f, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    const float jd[3] = {3.65e-3f, 3.68e-3f, 7.03e-3f};
    rng_t rng = {77u};
    for (int trial = 0; trial < 20; ++trial) {
        float state[PROPID_MAX_STATES];
        float speed_sq[PROPID_MAX_ROTORS];
        memset(state, 0, sizeof(state));
        for (int a = 0; a < 3; ++a) {
            state[a] = rng_uniform(&rng, -3.0f, 3.0f);
        }
        float tau[3] = {0.0f, 0.0f, 0.0f};
        for (uint8_t i = 0; i < 4u; ++i) {
            const propid_rotor_config_t *rotor = &filter.config.rotor[i];
            const float kf_rel = rng_uniform(&rng, 0.7f, 1.3f);
            const float km_rel = rng_uniform(&rng, 0.7f, 1.3f);
            const float speed = rng_uniform(&rng, 300.0f, 1400.0f);
            state[3 + i] = kf_rel;
            state[7 + i] = km_rel;
            speed_sq[i] = speed * speed;
            const float thrust = kf_rel * rotor->thrust_coeff_nominal * speed_sq[i];
            const float *r = rotor->position_m;
            tau[0] += r[1] * thrust - r[2] * 0.0f;
            tau[1] += r[2] * 0.0f - r[0] * thrust;
            tau[2] += rotor->yaw_sign * km_rel * rotor->drag_coeff_nominal * speed_sq[i];
        }
        const float *w = state;
        const float h[3] = {jd[0] * w[0], jd[1] * w[1], jd[2] * w[2]};
        const float gyro[3] = {w[1] * h[2] - w[2] * h[1], w[2] * h[0] - w[0] * h[2],
                               w[0] * h[1] - w[1] * h[0]};
        float rate_dot[3];
        propid_model_rate_derivative(&filter.config, &filter.derived, state, speed_sq, rate_dot);
        for (int a = 0; a < 3; ++a) {
            const float expected = (tau[a] - gyro[a]) / jd[a];
            TEST_ASSERT_FLOAT_WITHIN(1.0e-4f * fmaxf(fabsf(expected), 10.0f), expected, rate_dot[a]);
        }
    }
}

/* Plus frame, rotor 0 on +x with yaw sign +1, rotor 1 on +y (counter-clockwise):
 * more thrust on +x pitches nose down (negative tau_y), more thrust on +y rolls
 * right side down... i.e. positive tau_x; rotor 0's drag yaws positively. */
static void test_plus_frame_signs(void)
{
    init_symmetric(4u, 0.2f, 0.0f, 1.0e-5f, 1.0e-7f, 1.0e-2f, 1.0e-2f, 2.0e-2f);
    float state[PROPID_MAX_STATES];
    memset(state, 0, sizeof(state));
    for (int k = 3; k < 11; ++k) {
        state[k] = 1.0f;
    }
    float speed_sq[PROPID_MAX_ROTORS] = {0.0f};
    float rate_dot[3];
    speed_sq[0] = 1.0e6f; /* only rotor 0 (+x, yaw_sign +1) */
    propid_model_rate_derivative(&filter.config, &filter.derived, state, speed_sq, rate_dot);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, 0.0f, rate_dot[0]);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, -0.2f * 10.0f / 1.0e-2f, rate_dot[1]);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, 0.1f / 2.0e-2f, rate_dot[2]);
    speed_sq[0] = 0.0f;
    speed_sq[1] = 1.0e6f; /* only rotor 1 (+y, yaw_sign -1) */
    propid_model_rate_derivative(&filter.config, &filter.derived, state, speed_sq, rate_dot);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, 0.2f * 10.0f / 1.0e-2f, rate_dot[0]);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, 0.0f, rate_dot[1]);
    TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, -0.1f / 2.0e-2f, rate_dot[2]);
}

static void test_set_symmetric_layout(void)
{
    propid_config_t config;
    propid_config_default(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(&config, 6u, 0.3f, TEST_PI / 6.0f, -1.0f,
                                                                 1.0e-5f, 2.0e-7f));
    TEST_ASSERT_EQUAL_UINT8(6u, config.rotor_count);
    for (uint8_t i = 0; i < 6u; ++i) {
        const float angle = TEST_PI / 6.0f + (float)i * TEST_PI / 3.0f;
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, 0.3f * cosf(angle), config.rotor[i].position_m[0]);
        TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, 0.3f * sinf(angle), config.rotor[i].position_m[1]);
        TEST_ASSERT_EQUAL_FLOAT(i % 2u == 0u ? -1.0f : 1.0f, config.rotor[i].yaw_sign);
    }
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&config, 0u, 0.3f, 0.0f, 1.0f, 1.0e-5f, 2.0e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&config, 4u, 0.3f, 0.0f, 0.5f, 1.0e-5f, 2.0e-7f));
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_jacobian_plus_quad);
    RUN_TEST(test_jacobian_x_quad);
    RUN_TEST(test_jacobian_hexa);
    RUN_TEST(test_jacobian_full_inertia_and_offset_rotors);
    RUN_TEST(test_rate_derivative_matches_rigid_body);
    RUN_TEST(test_plus_frame_signs);
    RUN_TEST(test_set_symmetric_layout);
    return UNITY_END();
}
