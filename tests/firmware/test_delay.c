/*
 * Telemetry delay (docs/math.md §12, firmware/src/propid_delay.c):
 * - configuration: the delay must fit the buffer (with the accelerometer the
 *   held IMU stream counts twice), |delay| <= 1 s; a build without the buffer
 *   (PROPID_DELAY_SLOTS = 0) rejects every nonzero delay;
 * - rotor speeds lagging by d, filter configured with d: after the buffer has
 *   released each gyro sample, state and covariance are bit-for-bit those of
 *   the undelayed filter fed the aligned streams; the same for a gyro lagging
 *   (negative delay) and with the accelerometer in the held stream;
 * - input rejections (NaN, range, time backwards, time jump) of held streams
 *   return the code at once and hold nothing;
 * - a full buffer releases its oldest sample early (counted), reset and resync
 *   empty it.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"

void setUp(void) {}
void tearDown(void) {}

#define SIM_PI 3.14159265358979f
#define KF_NOMINAL 5.57e-6f
#define KM_NOMINAL 1.36e-7f

/* static: keeps the test stack small on the Cortex-M4 */
static propid_filter_t delayed;
#if PROPID_DELAY_SLOTS > 0
static propid_filter_t aligned;
static propid_filter_t before;
#endif

static void quad_config(propid_config_t *config)
{
    propid_config_default(config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(config, 4u, 0.17f, SIM_PI / 4.0f, 1.0f,
                                                                 KF_NOMINAL, KM_NOMINAL));
    propid_config_set_inertia_diag(config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    config->gyro_noise_density = 0.003f / sqrtf(500.0f);
}

static void test_delay_configuration_is_validated(void)
{
    propid_config_t config;
    quad_config(&config);
    const char *bad = NULL;
#if PROPID_DELAY_SLOTS > 0
    /* 500 Hz gyro: (slots - 1) samples of 2 ms fit. */
    const int32_t fits_us = (int32_t)(PROPID_DELAY_SLOTS - 1) * 2000;
    config.rotor_delay_us = fits_us;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_delay_us = -fits_us;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_delay_us = fits_us + 1000;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_delay_us", bad);
    config.rotor_delay_us = -fits_us - 1000;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    /* With the accelerometer the held IMU stream is twice as dense: half fits. */
    config.mass = 1.0f;
    config.rotor_delay_us = fits_us;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_delay_us", bad);
    config.rotor_delay_us = fits_us / 2;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_delay_us = -fits_us; /* held rotor samples: one stream */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    /* Beyond 1 s whatever the rate. */
    config.mass = 0.0f;
    config.gyro_sample_rate_hz = 1.0f;
    config.rotor_delay_us = 1000001;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    config.rotor_delay_us = INT32_MIN;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    /* propid_init refuses it too and leaves an initialised filter as it was. */
    quad_config(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    memcpy(&before, &delayed, sizeof(delayed));
    config.rotor_delay_us = fits_us + 1000;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&delayed, &config));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &delayed.core, sizeof(delayed.core));
#else
    config.rotor_delay_us = 1000;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_delay_us", bad);
    config.rotor_delay_us = -1000;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&delayed, &config));
    config.rotor_delay_us = 0;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
#endif
}

#if PROPID_DELAY_SLOTS > 0

/* A synthetic, deterministic sequence: ESC at 250 Hz (every 4 ms), gyro at
 * 500 Hz, accelerometer at 250 Hz, speeds and rates that excite the filter
 * (the values need not obey the model: both filters see the same ones). */
#define ESC_US 4000u
#define GYRO_US 2000u
#define END_US 600000u

static void rotor_sample(uint32_t t_us, float speeds[4])
{
    const float t = (float)t_us * 1.0e-6f;
    for (uint8_t i = 0; i < 4u; ++i) {
        speeds[i] = 900.0f + 120.0f * sinf(2.0f * SIM_PI * (1.7f + 0.9f * (float)i) * t + (float)i);
    }
}

static void gyro_sample(rng_t *rng, uint32_t t_us, float gyro[3])
{
    const float t = (float)t_us * 1.0e-6f;
    gyro[0] = 0.8f * sinf(2.0f * SIM_PI * 1.1f * t) + rng_range(rng, -0.01f, 0.01f);
    gyro[1] = 0.6f * sinf(2.0f * SIM_PI * 1.5f * t + 1.0f) + rng_range(rng, -0.01f, 0.01f);
    gyro[2] = 0.3f * sinf(2.0f * SIM_PI * 0.7f * t + 2.0f) + rng_range(rng, -0.01f, 0.01f);
}

static void accel_sample(uint32_t t_us, float force[3])
{
    force[0] = 0.0f;
    force[1] = 0.0f;
    force[2] = 9.81f + 0.5f * sinf(2.0f * SIM_PI * 0.9f * (float)t_us * 1.0e-6f);
}

/* Feeds `aligned` (no delay, true time order) and `delayed` (configured with
 * delay_us, the rotor stamps moved by delay_us: telemetry lagging for a positive
 * delay, leading for a negative one) and compares state and covariance each time
 * `delayed` has fused as many gyro samples as `aligned`. */
static void expect_delayed_equals_aligned(int32_t delay_us, float mass)
{
    propid_config_t config;
    quad_config(&config);
    config.mass = mass;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&aligned, &config));
    config.rotor_delay_us = delay_us;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    const uint32_t offset_us = 100000u; /* keeps shifted stamps positive */

    /* The aligned filter first, recording its state after each gyro sample. */
    static float state_after[END_US / GYRO_US + 1][PROPID_MAX_STATES];
    static float diag_after[END_US / GYRO_US + 1][PROPID_MAX_STATES];
    rng_t rng = {12345u};
    uint32_t gyro_count = 0u;
    float values[4];
    for (uint32_t t = GYRO_US; t <= END_US; t += GYRO_US) {
        const uint64_t stamp = offset_us + t;
        if (t % ESC_US == 0u || t == GYRO_US) {
            rotor_sample(t, values);
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&aligned, stamp, values, 4u));
        }
        if (mass > 0.0f && t % ESC_US == 0u) {
            accel_sample(t, values);
            TEST_ASSERT_TRUE(propid_push_accel(&aligned, stamp, values) >= 0);
        }
        gyro_sample(&rng, t, values);
        TEST_ASSERT_TRUE(propid_push_gyro(&aligned, stamp, values) >= 0);
        memcpy(state_after[gyro_count], aligned.core.state, sizeof(aligned.core.state));
        for (uint8_t k = 0; k < PROPID_MAX_STATES; ++k) {
            diag_after[gyro_count][k] = aligned.core.cov[propid_cov_index(k, k)];
        }
        gyro_count++;
    }
    TEST_ASSERT_EQUAL_UINT32(gyro_count, aligned.counters.gyro_accepted);

    /* The delayed filter: events in arrival order (rotor stamps moved by the
     * delay; at equal stamps rotor speeds first, as above). */
    rng.state = 12345u;
    uint32_t next_rotor = GYRO_US, next_imu = GYRO_US;
    uint32_t compared = 0u;
    const int64_t shift = delay_us;
    for (uint32_t guard = 0u; guard < 4u * (END_US / GYRO_US) + 16u && next_imu <= END_US; ++guard) {
        const int64_t rotor_arrival = (int64_t)next_rotor + shift;
        const int rotor_first = next_rotor <= END_US + (uint32_t)(shift > 0 ? shift : 0) &&
                                rotor_arrival <= (int64_t)next_imu;
        if (rotor_first) {
            rotor_sample(next_rotor, values);
            const propid_status_t status =
                propid_push_rotor_speeds(&delayed, (uint64_t)((int64_t)offset_us + rotor_arrival), values, 4u);
            TEST_ASSERT_EQUAL_INT(delay_us < 0 ? PROPID_OK_QUEUED : PROPID_OK, status);
            next_rotor = next_rotor == GYRO_US ? ESC_US : next_rotor + ESC_US;
        } else {
            const uint64_t stamp = offset_us + next_imu;
            if (mass > 0.0f && next_imu % ESC_US == 0u) {
                accel_sample(next_imu, values);
                const propid_status_t status = propid_push_accel(&delayed, stamp, values);
                TEST_ASSERT_TRUE(delay_us > 0 ? status == PROPID_OK_QUEUED : status >= 0);
            }
            gyro_sample(&rng, next_imu, values);
            const propid_status_t status = propid_push_gyro(&delayed, stamp, values);
            TEST_ASSERT_TRUE(delay_us > 0 ? status == PROPID_OK_QUEUED : status >= 0);
            next_imu += GYRO_US;
        }
        /* Compare at every point where the delayed filter has caught up a sample. */
        const uint32_t fused = delayed.counters.gyro_accepted;
        if (fused > compared && fused <= gyro_count) {
            compared = fused;
            TEST_ASSERT_EQUAL_MEMORY(state_after[fused - 1u], delayed.core.state, sizeof(delayed.core.state));
            float diag[PROPID_MAX_STATES];
            for (uint8_t k = 0; k < PROPID_MAX_STATES; ++k) {
                diag[k] = delayed.core.cov[propid_cov_index(k, k)];
            }
            TEST_ASSERT_EQUAL_MEMORY(diag_after[fused - 1u], diag, sizeof(diag));
        }
    }
    /* All but the last |delay| of gyro samples were fused and compared. */
    const uint32_t held = delay_us > 0 ? (uint32_t)delay_us / GYRO_US + 1u : 0u;
    TEST_ASSERT_TRUE(compared + held >= gyro_count);
    TEST_ASSERT_TRUE(compared > gyro_count / 2u);
    TEST_ASSERT_EQUAL_UINT32(0u, delayed.counters.delay_overflows);
    uint32_t rejected = 0u;
    for (uint8_t k = 0; k < PROPID_REJECT_SLOTS; ++k) {
        rejected += delayed.counters.rejected[k];
    }
    TEST_ASSERT_EQUAL_UINT32(0u, rejected);
}

static void test_lagging_rotor_speeds_equal_the_aligned_filter(void)
{
    expect_delayed_equals_aligned(6000, 0.0f);  /* 1.5 ESC periods */
    expect_delayed_equals_aligned(3000, 0.0f);  /* between samples of both streams */
    expect_delayed_equals_aligned(4000, 0.0f);  /* one ESC period: equal stamps */
}

static void test_lagging_gyro_equals_the_aligned_filter(void)
{
    expect_delayed_equals_aligned(-6000, 0.0f);
    expect_delayed_equals_aligned(-3000, 0.0f);
}

static void test_accelerometer_is_held_with_the_gyro(void)
{
    expect_delayed_equals_aligned(6000, 1.0f);
    expect_delayed_equals_aligned(-6000, 1.0f);
}

/* A held stream's input rejections: code at once, nothing held, core unchanged. */
static void expect_held_rejection(propid_status_t expected, uint64_t t_us, const float *gyro, int accel)
{
    memcpy(&before, &delayed, sizeof(delayed));
    const propid_status_t status =
        accel ? propid_push_accel(&delayed, t_us, gyro) : propid_push_gyro(&delayed, t_us, gyro);
    TEST_ASSERT_EQUAL_INT(expected, status);
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &delayed.core, sizeof(delayed.core));
    TEST_ASSERT_EQUAL_MEMORY(&before.delay, &delayed.delay, sizeof(delayed.delay));
    TEST_ASSERT_EQUAL_UINT32(before.counters.rejected[PROPID_REJECT_SLOT(expected)] + 1u,
                             delayed.counters.rejected[PROPID_REJECT_SLOT(expected)]);
}

static void test_held_samples_are_validated_on_arrival(void)
{
    propid_config_t config;
    quad_config(&config);
    config.mass = 1.0f;
    config.rotor_delay_us = 10000;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    const float still[3] = {0.0f, 0.0f, 0.0f};
    const float hover[3] = {0.0f, 0.0f, 9.81f};
    const float speeds[4] = {900.0f, 900.0f, 900.0f, 900.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&delayed, 1000u, speeds, 4u));
    TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_gyro(&delayed, 1000u, still));
    TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_accel(&delayed, 1000u, hover));
    TEST_ASSERT_EQUAL_INT(2, delayed.delay.count);
    const float nan_gyro[3] = {0.0f, NAN, 0.0f};
    expect_held_rejection(PROPID_ERR_NOT_FINITE, 2000u, nan_gyro, 0);
    const float wild[3] = {0.0f, 0.0f, 100.0f};
    expect_held_rejection(PROPID_ERR_GYRO_RANGE, 2000u, wild, 0);
    expect_held_rejection(PROPID_ERR_TIME_BACKWARDS, 1000u, still, 0);
    expect_held_rejection(PROPID_ERR_TIME_BACKWARDS, 500u, still, 0);
    expect_held_rejection(PROPID_ERR_TIME_JUMP, 1000u + config.max_gyro_gap_us + 1u, still, 0);
    expect_held_rejection(PROPID_ERR_TIME_BACKWARDS, 1000u, hover, 1);
    const float saturated[3] = {0.0f, 0.0f, 1000.0f};
    expect_held_rejection(PROPID_ERR_ACCEL_RANGE, 2000u, saturated, 1);
    expect_held_rejection(PROPID_ERR_NOT_FINITE, 2000u, nan_gyro, 1);
    /* Nothing fused yet (the rotor stream has not reached 1000 + 10000 us). */
    TEST_ASSERT_EQUAL_UINT32(0u, delayed.counters.gyro_accepted);
    TEST_ASSERT_TRUE(delayed.core.has_time == 0u);
    /* The rotor stream reaches it: the held samples are fused. */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&delayed, 11001u, speeds, 4u));
    TEST_ASSERT_EQUAL_UINT32(1u, delayed.counters.gyro_accepted);
    TEST_ASSERT_EQUAL_UINT32(1u, delayed.counters.accel_accepted);
    TEST_ASSERT_EQUAL_INT(0, delayed.delay.count);

    /* Negative delay: held rotor samples are validated on arrival as well. */
    config.rotor_delay_us = -10000;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_rotor_speeds(&delayed, 1000u, speeds, 4u));
    memcpy(&before, &delayed, sizeof(delayed));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_BACKWARDS, propid_push_rotor_speeds(&delayed, 1000u, speeds, 4u));
    const float negative[4] = {900.0f, -1.0f, 900.0f, 900.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_NEGATIVE, propid_push_rotor_speeds(&delayed, 2000u, negative, 4u));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &delayed.core, sizeof(delayed.core));
    TEST_ASSERT_EQUAL_MEMORY(&before.delay, &delayed.delay, sizeof(delayed.delay));
    /* The gyro before the held sample acts: no rotor data yet. */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NO_ROTOR_DATA, propid_push_gyro(&delayed, 10999u, still));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_gyro(&delayed, 11000u, still));
    TEST_ASSERT_EQUAL_INT(0, delayed.delay.count);
}

static void test_full_buffer_releases_early_and_reset_empties_it(void)
{
    propid_config_t config;
    quad_config(&config);
    config.rotor_delay_us = 20000;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    const float still[3] = {0.0f, 0.0f, 0.0f};
    const float speeds[4] = {900.0f, 900.0f, 900.0f, 900.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&delayed, 1000u, speeds, 4u));
    /* Gyro 20x faster than the configured rate: the buffer overflows. */
    uint64_t t = 1000u;
    for (uint32_t k = 0; k < PROPID_DELAY_SLOTS + 5u; ++k) {
        TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_gyro(&delayed, t, still));
        t += 100u;
    }
    TEST_ASSERT_EQUAL_INT(PROPID_DELAY_SLOTS, delayed.delay.count);
    TEST_ASSERT_EQUAL_UINT32(5u, delayed.counters.delay_overflows);
    TEST_ASSERT_EQUAL_UINT32(5u, delayed.counters.gyro_accepted);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_reset(&delayed));
    TEST_ASSERT_EQUAL_INT(0, delayed.delay.count);
    TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_gyro(&delayed, t, still));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&delayed, t + 100000u));
    TEST_ASSERT_EQUAL_INT(0, delayed.delay.count);
    /* After the resync the held gyro anchors at the new time. */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_BACKWARDS, propid_push_gyro(&delayed, t + 99999u, still));
    TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_gyro(&delayed, t + 100000u, still));

    /* Negative delay: a rotor stream faster than the gyro overflows the same way. */
    config.rotor_delay_us = -20000;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&delayed, &config));
    t = 1000u;
    for (uint32_t k = 0; k < PROPID_DELAY_SLOTS + 3u; ++k) {
        TEST_ASSERT_EQUAL_INT(PROPID_OK_QUEUED, propid_push_rotor_speeds(&delayed, t, speeds, 4u));
        t += 100u;
    }
    TEST_ASSERT_EQUAL_UINT32(3u, delayed.counters.delay_overflows);
    TEST_ASSERT_TRUE(delayed.core.has_rotor_data == 1u);
}

static void test_status_name(void)
{
    TEST_ASSERT_EQUAL_STRING("PROPID_OK_QUEUED", propid_status_name(PROPID_OK_QUEUED));
}
#endif

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_delay_configuration_is_validated);
#if PROPID_DELAY_SLOTS > 0
    RUN_TEST(test_lagging_rotor_speeds_equal_the_aligned_filter);
    RUN_TEST(test_lagging_gyro_equals_the_aligned_filter);
    RUN_TEST(test_accelerometer_is_held_with_the_gyro);
    RUN_TEST(test_held_samples_are_validated_on_arrival);
    RUN_TEST(test_full_buffer_releases_early_and_reset_empties_it);
    RUN_TEST(test_status_name);
#endif
    return UNITY_END();
}
