/*
 * The rotor report's timing error in the prediction (config.rotor_timing_error,
 * docs/math.md §14, "The report's timing"):
 * - on, one step adds exactly along along^T to the rate block, along = B tau
 *   (u_end - u_start) / dt with B = d(omega_dot)/d(u_i) computed here densely from
 *   the model's Jacobian at the current coefficients (quad layout, general lists,
 *   hexa), and nothing elsewhere; beside the speed error it adds the same on top;
 * - speeds that do not change over the step add nothing (bit for bit);
 * - the configuration check refuses bad values by name.
 */
#include <math.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "../../firmware/src/propid_internal.h"
#include "per_rotor_view.h"
#include "../../firmware/src/propid_model.h"
#include "input_error_fixture.h"
#include "test_vehicle.h"

void setUp(void) {}
void tearDown(void) {}

#if PROPID_WITH_INPUT_NOISE
static propid_filter_t with_timing;
static propid_filter_t without_timing;

/* What `with_timing` added over `without_timing` in the step: along along^T in the
 * rate block, everything else bit for bit. */
static void check_timing_block(float tau, float dt)
{
    const uint8_t rotors = with_timing.config.rotor_count;
    float gain[3][PROPID_MAX_ROTORS];
    input_error_dense_gain(&with_timing, gain);
    float along[3] = {0.0f, 0.0f, 0.0f};
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t i = 0; i < rotors; ++i) {
            const float change = with_timing.core.rotor_speed_sq[i] - with_timing.core.input_speed_sq[i];
            along[a] += gain[a][i] * tau * change / dt;
        }
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = a; b < 3u; ++b) {
            const float expected = along[a] * along[b];
            const uint32_t k = propid_cov_index(a, b);
            const float added = with_timing.core.cov[k] - without_timing.core.cov[k];
            TEST_ASSERT_FLOAT_WITHIN(1.0e-3f * fabsf(expected) + 1.0e-6f * fabsf(with_timing.core.cov[k]), expected,
                                     added);
            if (a == b) {
                TEST_ASSERT_TRUE(expected > 0.0f);
            }
        }
    }
    const uint8_t n = with_timing.derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        for (uint8_t j = i; j < n; ++j) {
            if (j < 3u) {
                continue;
            }
            const uint32_t k = propid_cov_index(i, j);
            TEST_ASSERT_EQUAL_MEMORY(&without_timing.core.cov[k], &with_timing.core.cov[k], sizeof(float));
        }
    }
    /* Only the covariance moves: the state is the same step's. */
    TEST_ASSERT_EQUAL_MEMORY(without_timing.core.state, with_timing.core.state, sizeof(with_timing.core.state));
}

/* speed_noise: the rotor-speed error both filters carry (0: none). */
static void check_added_block(uint8_t rotors, int full_inertia, float speed_noise)
{
    const float tau = 0.002f;
    const float dt = 0.002f;
    propid_config_t config;
    input_error_configure(&config, rotors, full_inertia);
    config.rotor_speed_noise = speed_noise;
    config.rotor_speed_noise_time = speed_noise > 0.0f ? 0.01f : 0.0f;
    input_error_off_prior(&without_timing, &config);
    config.rotor_timing_error = tau;
    input_error_off_prior(&with_timing, &config);
    input_error_predict_pair(&without_timing, &with_timing, dt);
    check_timing_block(tau, dt);
}

static void test_report_timing_adds_its_rank_one_block(void)
{
    check_added_block(4u, 0, 0.0f); /* quad layout */
    check_added_block(4u, 1, 0.0f); /* general lists (full inertia) */
    check_added_block(6u, 0, 0.0f); /* hexa */
    check_added_block(4u, 0, 3.0f); /* beside the speed error: the same on top */
    check_added_block(6u, 0, 3.0f);
}

/* A report that stands (the same speeds at both ends of the step) carries no timing
 * error: the step is the one without the term, bit for bit. */
static void test_report_timing_without_a_speed_change_adds_nothing(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    input_error_off_prior(&without_timing, &config);
    memcpy(without_timing.core.input_speed_sq, without_timing.core.rotor_speed_sq,
           sizeof(without_timing.core.input_speed_sq));
    config.rotor_timing_error = 0.01f;
    input_error_off_prior(&with_timing, &config);
    memcpy(with_timing.core.input_speed_sq, with_timing.core.rotor_speed_sq, sizeof(with_timing.core.input_speed_sq));
    input_error_predict_pair(&without_timing, &with_timing, 0.002f);
    TEST_ASSERT_EQUAL_MEMORY(without_timing.core.cov, with_timing.core.cov, sizeof(with_timing.core.cov));
}

static void test_report_timing_config_is_checked(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    const char *bad = NULL;
    const float refused[] = {-1.0e-3f, NAN, INFINITY, 1.01f * PROPID_ROTOR_TIMING_ERROR_MAX};
    for (uint8_t k = 0; k < 4u; ++k) {
        config.rotor_timing_error = refused[k];
        TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
        TEST_ASSERT_EQUAL_STRING("rotor_timing_error", bad);
    }
    config.rotor_timing_error = PROPID_ROTOR_TIMING_ERROR_MAX;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_timing_error = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
}
#else
static void test_report_timing_compiled_out_refuses_the_option(void)
{
    propid_config_t config;
    test_vehicle_config(&config, 4u, 0.17f, 0.785398f);
    config.rotor_timing_error = 0.002f;
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_timing_error", bad);
}
#endif

int main(void)
{
    UNITY_BEGIN();
#if PROPID_WITH_INPUT_NOISE
    RUN_TEST(test_report_timing_adds_its_rank_one_block);
    RUN_TEST(test_report_timing_without_a_speed_change_adds_nothing);
    RUN_TEST(test_report_timing_config_is_checked);
#else
    RUN_TEST(test_report_timing_compiled_out_refuses_the_option);
#endif
    return UNITY_END();
}
