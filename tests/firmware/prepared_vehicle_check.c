/*
 * The quad builds' filter started from the setup that firmware/codegen/setup_blob.py
 * prepared on the host at build time (from prepared_vehicle.json) is the filter
 * propid_init makes on this processor from the same vehicle, written here in C:
 * to the byte on the host (the same rounding), and on the Cortex-M4F, whose
 * derivation fuses multiply-adds, the same configuration, layout and estimates
 * within float rounding, before and after a flight.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"

extern const propid_setup_t *const propid_vehicle_setup;

/* static: keep the test's stack small on the MCU */
static propid_config_t config;
static propid_filter_t from_config;
static propid_filter_t from_setup;

void setUp(void)
{
    propid_config_default(&config);
    const float arm[4][2] = {{0.12f, -0.12f}, {-0.12f, -0.12f}, {-0.12f, 0.12f}, {0.12f, 0.12f}};
    config.rotor_count = 4u;
    for (uint8_t i = 0; i < 4u; ++i) {
        config.rotor[i].position_m[0] = arm[i][0];
        config.rotor[i].position_m[1] = arm[i][1];
        config.rotor[i].yaw_sign = (i % 2u == 0u) ? 1.0f : -1.0f;
        config.rotor[i].thrust_coeff_nominal = (i % 2u == 0u) ? 5.6e-6f : 5.5e-6f;
        config.rotor[i].drag_coeff_nominal = (i % 2u == 0u) ? 1.4e-7f : 1.3e-7f;
    }
    propid_config_set_inertia_diag(&config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    config.gate_sigma = 4.0f;
    config.gyro_noise_density = 3.0e-4f;
    config.gyro_sample_rate_hz = 1000.0f;
    config.gate_max_consecutive = 40u;
    config.rotor_stale_us = 20000u;
    config.motor_time_constant = 0.02f;
}

void tearDown(void) {}

static void fly(propid_filter_t *filter)
{
    uint64_t t = 1000u;
    for (uint32_t k = 0; k < 400u; ++k) {
        const float phase = (float)(k % 50u) * 0.04f;
        const float speeds[4] = {900.0f + 40.0f * phase, 910.0f - 30.0f * phase, 890.0f + 20.0f * phase,
                                 905.0f - 10.0f * phase};
        const float gyro[3] = {0.02f * phase, -0.02f + 0.01f * phase, 0.004f * phase};
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(filter, t, speeds, 4u));
        TEST_ASSERT_TRUE(propid_push_gyro(filter, t + 1000u, gyro) >= 0);
        t += 1000u;
    }
}

static void assert_close(const float *expected, const float *actual, uint32_t count)
{
    for (uint32_t k = 0; k < count; ++k) {
        TEST_ASSERT_FLOAT_WITHIN(1.0e-4f * fabsf(expected[k]) + 1.0e-12f, expected[k], actual[k]);
    }
}

static void assert_same_filter(void)
{
#if !defined(__arm__)
    TEST_ASSERT_EQUAL_MEMORY(&from_config, &from_setup, sizeof(from_config));
#endif
    TEST_ASSERT_EQUAL_MEMORY(&from_config.config, &from_setup.config, sizeof(from_config.config));
    TEST_ASSERT_EQUAL_MEMORY(&from_config.derived.layout, &from_setup.derived.layout,
                             sizeof(from_config.derived.layout));
    TEST_ASSERT_EQUAL_UINT8(from_config.derived.state_count, from_setup.derived.state_count);
    propid_estimate_t expected;
    propid_estimate_t actual;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&from_config, &expected));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&from_setup, &actual));
    assert_close(expected.body_rate, actual.body_rate, 3u);
    assert_close(expected.thrust_coeff, actual.thrust_coeff, 4u);
    assert_close(expected.thrust_coeff_std, actual.thrust_coeff_std, 4u);
    assert_close(expected.drag_coeff, actual.drag_coeff, 4u);
    assert_close(expected.drag_coeff_std, actual.drag_coeff_std, 4u);
    assert_close(expected.gyro_bias_std, actual.gyro_bias_std, 3u);
    TEST_ASSERT_EQUAL_UINT32(expected.health, actual.health);
}

static void test_host_prepared_setup_starts_the_configured_filter(void)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&from_config, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init_prepared(&from_setup, propid_vehicle_setup));
    assert_same_filter();
    fly(&from_config);
    fly(&from_setup);
    assert_same_filter();
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_host_prepared_setup_starts_the_configured_filter);
    return UNITY_END();
}
