/*
 * The motor commands as the rotor input's instrument (config.motor_command_instrument,
 * propid_push_motor_command, docs/math.md §16):
 * - white telemetry noise on the rotor speeds attenuates kf (errors in variables);
 *   with the commands' first stage as the input the attenuation is gone;
 * - with exact telemetry the instrument changes nothing that matters (both unbiased);
 * - every rejection leaves the filter bit for bit unchanged and counts its reason;
 *   a stale command falls back to the telemetry as measured;
 * - the configuration check refuses bad fields by name; the instrument off is the
 *   filter as before (a command is refused with PROPID_ERR_CONFIG);
 * - the weak-instrument guard (motor_command_min_f): a rotor whose command does not
 *   follow its speed keeps its telemetry, the others their first stage.
 */
#include <math.h>
#include <string.h>
#ifdef PROPID_TEST_VERBOSE
#include <stdio.h>
#endif

#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"
#include "test_vehicle.h"

void setUp(void) {}
void tearDown(void) {}

#if PROPID_WITH_INSTRUMENT
#define FULL_SPEED 1600.0f
#define MOTOR_LAG 0.02f

static propid_filter_t filter;

static float gaussian(rng_t *rng)
{
    /* Sum of 4 uniforms, unit variance: enough for a noise model. */
    float sum = 0.0f;
    for (int k = 0; k < 4; ++k) {
        sum += rng_range(rng, -1.0f, 1.0f);
    }
    return sum * 0.8660254f;
}

static void quad_config(propid_config_t *config, int instrument)
{
    test_vehicle_config(config, 4u, 0.17f, 0.78539816f);
    config->max_rotor_speed = FULL_SPEED;
    config->gyro_sample_rate_hz = 500.0f;
    config->motor_command_instrument = instrument ? 1u : 0u;
    config->motor_command_lag = MOTOR_LAG;
    config->motor_command_memory = 5.0f;
}

/* An open-loop flight of `seconds`: each rotor's command a sum of two sines about
 * hover, the true speed its first-order lag (MOTOR_LAG), the body integrating the
 * true torques (kf, km at their nominals); gyro at 500 Hz, commands and telemetry
 * (true speed + white noise of telemetry_std) at 250 Hz, the command 1 ms before
 * its telemetry. The rotor `unrelated` (or none: -1) is sent a command its speed
 * does not follow (a sine at a frequency the speeds do not have). kf_ratio gets
 * each rotor's kf / kf_nominal; returns their mean. */
static float fly_guarded(int instrument, float telemetry_std, float seconds, float min_f, int unrelated,
                         float kf_ratio[4])
{
    propid_config_t config;
    quad_config(&config, instrument);
    config.motor_command_min_f = min_f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    rng_t rng = {0x1234567u};
    const float kf = 5.57e-6f;
    const float km = 1.36e-7f;
    const float jxx = 3.65e-3f, jyy = 3.68e-3f, jzz = 7.03e-3f;
    float rate[3] = {0.0f, 0.0f, 0.0f};
    float speed[4] = {1000.0f, 1000.0f, 1000.0f, 1000.0f};
    float command[4];
    const float dt = 0.0005f; /* physics */
    const uint32_t steps = (uint32_t)(seconds / dt);
    for (uint32_t step = 1u; step <= steps; ++step) {
        const uint64_t t_us = (uint64_t)step * 500u;
        const float t = (float)step * dt;
        for (uint8_t i = 0; i < 4u; ++i) {
            const float phase = 1.3f * (float)i;
            const float target = 1000.0f + 120.0f * sinf(2.0f * 3.14159265f * (1.1f + 0.6f * (float)i) * t + phase) +
                                 80.0f * sinf(2.0f * 3.14159265f * (4.3f + 1.7f * (float)i) * t + 2.0f * phase);
            command[i] = target / FULL_SPEED;
            if ((int)i == unrelated) {
                command[i] = (1000.0f + 150.0f * sinf(2.0f * 3.14159265f * 0.37f * t)) / FULL_SPEED;
            }
            speed[i] += (dt / MOTOR_LAG) * (target - speed[i]);
        }
        /* X frame: rotor i at angle pi/4 + i pi/2, yaw sign +, -, +, -. */
        float torque[3] = {0.0f, 0.0f, 0.0f};
        for (uint8_t i = 0; i < 4u; ++i) {
            const float angle = 0.78539816f + 1.5707963f * (float)i;
            const float u = speed[i] * speed[i];
            torque[0] += 0.17f * sinf(angle) * kf * u;
            torque[1] -= 0.17f * cosf(angle) * kf * u;
            torque[2] += ((i % 2u) == 0u ? 1.0f : -1.0f) * km * u;
        }
        rate[0] += dt * torque[0] / jxx;
        rate[1] += dt * torque[1] / jyy;
        rate[2] += dt * torque[2] / jzz;
        if (step % 8u == 6u && instrument) {
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_motor_command(&filter, t_us, command, 4u));
        }
        if (step % 8u == 0u) {
            float measured[4];
            for (uint8_t i = 0; i < 4u; ++i) {
                measured[i] = fmaxf(speed[i] + telemetry_std * gaussian(&rng), 0.0f);
            }
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t_us, measured, 4u));
        }
        if (step % 4u == 0u && step >= 8u) { /* after the first rotor sample */
            const float gyro[3] = {rate[0] + 0.002f * gaussian(&rng), rate[1] + 0.002f * gaussian(&rng),
                                   rate[2] + 0.002f * gaussian(&rng)};
            TEST_ASSERT_TRUE(propid_push_gyro(&filter, t_us, gyro) >= 0);
        }
    }
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    float mean = 0.0f;
    for (uint8_t i = 0; i < 4u; ++i) {
        kf_ratio[i] = estimate.thrust_coeff[i] / kf;
        mean += 0.25f * kf_ratio[i];
    }
    return mean;
}

static float fly(int instrument, float telemetry_std, float seconds)
{
    float kf_ratio[4];
    return fly_guarded(instrument, telemetry_std, seconds, 0.0f, -1, kf_ratio);
}

static void test_the_instrument_removes_the_telemetry_noise_attenuation(void)
{
    /* (20 s: off 0.917 / 0.614 / 0.302 at 20 / 40 / 60 rad/s, on 1.001 / 1.010 / 1.019.) */
    const float noisy_off = fly(0, 40.0f, 20.0f);
    const float noisy_on = fly(1, 40.0f, 20.0f);
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
#ifdef PROPID_TEST_VERBOSE
    printf("kf / truth with 40 rad/s telemetry noise: off %.4f, instrument %.4f (%u of %u inputs from the "
           "commands)\n", (double)noisy_off, (double)noisy_on, (unsigned)filter.instrument.inputs,
           (unsigned)counters.rotor_accepted);
#endif
    TEST_ASSERT_TRUE(noisy_off < 0.8f);                         /* the attenuation */
    TEST_ASSERT_FLOAT_WITHIN(0.02f, 1.0f, noisy_on);            /* gone with the instrument */
    TEST_ASSERT_EQUAL_UINT32(counters.rotor_accepted - 50u, filter.instrument.inputs);
}

static void test_the_guard_leaves_a_rotor_with_an_unrelated_command_its_telemetry(void)
{
    /* Rotor 3's command does not follow its speed: its first stage explains nothing
     * of its increments (F ~ 1). Without the guard its input is the fit's nearly
     * constant value and its kf is lost; with F >= 10 it keeps its telemetry
     * (10 rad/s noise: little attenuation) and rotors 0-2 keep their first stage. */
    float unguarded[4];
    float guarded[4];
    (void)fly_guarded(1, 10.0f, 20.0f, 0.0f, 3, unguarded);
    TEST_ASSERT_EQUAL_UINT32(0u, filter.instrument.guarded);
    (void)fly_guarded(1, 10.0f, 20.0f, 10.0f, 3, guarded);
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
#ifdef PROPID_TEST_VERBOSE
    printf("rotor 3 unrelated: kf / truth without the guard %.3f %.3f %.3f %.3f, with F >= 10 %.3f %.3f %.3f %.3f "
           "(%u rotor inputs guarded of %u rotor samples, %u samples with every rotor from the commands)\n",
           (double)unguarded[0], (double)unguarded[1], (double)unguarded[2], (double)unguarded[3],
           (double)guarded[0], (double)guarded[1], (double)guarded[2], (double)guarded[3],
           (unsigned)filter.instrument.guarded, (unsigned)counters.rotor_accepted, (unsigned)filter.instrument.inputs);
#endif
    /* (Measured: without the guard 1.067 0.690 0.885 0.815, with it 1.015 1.001 0.989 0.970.)
     * The unrelated command's fit misleads the filter, on other rotors' kf too. */
    float worst = 0.0f;
    for (uint8_t i = 0; i < 4u; ++i) {
        worst = fmaxf(worst, fabsf(unguarded[i] - 1.0f));
        TEST_ASSERT_FLOAT_WITHIN(0.05f, 1.0f, guarded[i]);
    }
    TEST_ASSERT_TRUE(worst > 0.15f);
    /* Rotor 3 falls back at about every sample after the first 50 (the others only
     * while their fit is young: 5,070 of 4,950). */
    const uint32_t after_start = counters.rotor_accepted - 50u;
    TEST_ASSERT_TRUE(filter.instrument.guarded >= after_start * 9u / 10u);
    TEST_ASSERT_TRUE(filter.instrument.guarded <= after_start * 11u / 10u);
    TEST_ASSERT_EQUAL_UINT32(0u, filter.instrument.inputs); /* never every rotor from the commands */
}

static void test_exact_telemetry_is_unbiased_either_way(void)
{
    TEST_ASSERT_FLOAT_WITHIN(0.02f, 1.0f, fly(0, 0.0f, 10.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.02f, 1.0f, fly(1, 0.0f, 10.0f));
}

static void test_rejections_leave_the_filter_unchanged(void)
{
    propid_config_t config;
    quad_config(&config, 1);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    const float good[4] = {0.5f, 0.5f, 0.5f, 0.5f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_motor_command(&filter, 1000u, good, 4u));
    static propid_filter_t before;
    memcpy(&before, &filter, sizeof(filter));
    const float nan_command[4] = {0.5f, NAN, 0.5f, 0.5f};
    const float inf_command[4] = {0.5f, 0.5f, INFINITY, 0.5f};
    const float high[4] = {0.5f, 0.5f, 0.5f, 1.5f};
    const float low[4] = {-0.1f, 0.5f, 0.5f, 0.5f};
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_push_motor_command(NULL, 2000u, good, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_push_motor_command(&filter, 2000u, NULL, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_COUNT, propid_push_motor_command(&filter, 2000u, good, 3u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_FINITE, propid_push_motor_command(&filter, 2000u, nan_command, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_FINITE, propid_push_motor_command(&filter, 2000u, inf_command, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_RANGE, propid_push_motor_command(&filter, 2000u, high, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_RANGE, propid_push_motor_command(&filter, 2000u, low, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_BACKWARDS, propid_push_motor_command(&filter, 1000u, good, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_BACKWARDS, propid_push_motor_command(&filter, 999u, good, 4u));
    /* Only the rejection counters moved. */
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &filter.core, sizeof(filter.core));
    TEST_ASSERT_EQUAL_MEMORY(&before.instrument, &filter.instrument, sizeof(filter.instrument));
    TEST_ASSERT_EQUAL_UINT32(1u, filter.instrument.command_accepted);
    TEST_ASSERT_EQUAL_UINT32(1u, filter.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_ROTOR_COUNT)]);
    TEST_ASSERT_EQUAL_UINT32(2u, filter.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_NOT_FINITE)]);
    TEST_ASSERT_EQUAL_UINT32(2u, filter.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_ROTOR_SPEED_RANGE)]);
    TEST_ASSERT_EQUAL_UINT32(2u, filter.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_TIME_BACKWARDS)]);
    /* Uninitialised filter. */
    static propid_filter_t blank;
    memset(&blank, 0, sizeof(blank));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_push_motor_command(&blank, 2000u, good, 4u));
}

static void test_a_stale_command_leaves_the_telemetry_as_measured(void)
{
    propid_config_t config;
    quad_config(&config, 1);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    /* 60 samples of a fit (commands fresh), then a command older than rotor_stale_us. */
    uint64_t t_us = 1000u;
    for (uint32_t k = 0; k < 60u; ++k, t_us += 4000u) {
        const float c = 0.5f + 0.1f * sinf(0.3f * (float)k);
        const float command[4] = {c, c, c, c};
        const float speed[4] = {c * FULL_SPEED, c * FULL_SPEED, c * FULL_SPEED, c * FULL_SPEED};
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_motor_command(&filter, t_us, command, 4u));
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t_us + 1000u, speed, 4u));
    }
    const uint32_t projected = filter.instrument.inputs;
    TEST_ASSERT_EQUAL_UINT32(10u, projected);
    const float measured[4] = {900.0f, 910.0f, 920.0f, 930.0f};
    t_us += (uint64_t)config.rotor_stale_us + 1000u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t_us, measured, 4u));
    TEST_ASSERT_EQUAL_UINT32(projected, filter.instrument.inputs);
    for (uint8_t i = 0; i < 4u; ++i) {
        TEST_ASSERT_EQUAL_FLOAT(measured[i] * measured[i], filter.core.rotor_speed_sq[i]);
    }
}

static void test_the_configuration_check_names_the_fields(void)
{
    propid_config_t config;
    const char *bad = NULL;
    quad_config(&config, 1);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.motor_command_instrument = 2u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_instrument", bad);
    quad_config(&config, 1);
    config.motor_command_lag = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_lag", bad);
    config.motor_command_lag = NAN;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_lag", bad);
    quad_config(&config, 1);
    config.motor_command_memory = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_memory", bad);
    quad_config(&config, 1);
    config.motor_command_min_f = -1.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_min_f", bad);
    config.motor_command_min_f = NAN;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("motor_command_min_f", bad);
    /* Off: a zero lag and memory are accepted, a command is refused. */
    quad_config(&config, 0);
    config.motor_command_lag = 0.0f;
    config.motor_command_memory = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    const float good[4] = {0.5f, 0.5f, 0.5f, 0.5f};
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_push_motor_command(&filter, 1000u, good, 4u));
    TEST_ASSERT_EQUAL_UINT32(1u, filter.counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_CONFIG)]);
}

#endif /* PROPID_WITH_INSTRUMENT */

int main(void)
{
    UNITY_BEGIN();
#if PROPID_WITH_INSTRUMENT
    RUN_TEST(test_the_instrument_removes_the_telemetry_noise_attenuation);
    RUN_TEST(test_the_guard_leaves_a_rotor_with_an_unrelated_command_its_telemetry);
    RUN_TEST(test_exact_telemetry_is_unbiased_either_way);
    RUN_TEST(test_rejections_leave_the_filter_unchanged);
    RUN_TEST(test_a_stale_command_leaves_the_telemetry_as_measured);
    RUN_TEST(test_the_configuration_check_names_the_fields);
#endif
    return UNITY_END();
}
