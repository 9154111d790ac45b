/*
 * A stuck gyro axis (config.gyro_stuck_samples, docs/reliability.md "A stuck gyro
 * axis"): at the start of a flight, with the library's wide coefficient prior, a
 * reading that stops changing while the vehicle accelerates is not gated: the
 * coefficients explain it, and they leave their truth. With the check on, the
 * repeated reading is not fused. The truth is integrated here from the filter's
 * own model (a quad pitching up under a front/back speed difference).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"
#include "test_vehicle.h"

#define ROTORS 4u
#define GYRO_PERIOD_US 2000u
#define HOVER_SPEED 470.0f
#define STUCK_FROM 4u     /* first sample of the stuck reading (it repeats sample 3's) */
#define STUCK_SAMPLES 50u /* as the SITL's gyro_stuck burst */
#define SAMPLES 160u

static propid_config_t config;
static propid_filter_t filter;

void setUp(void)
{
    test_vehicle_config(&config, ROTORS, 0.17f, 0.7853982f);
}

void tearDown(void)
{
}

typedef struct {
    float worst_kf_rel_error; /* max_i |kf_i / kf_true_i - 1| at the end */
    float burst_kf_rel_error; /* the same after the stuck burst's last sample */
    uint32_t stuck_counted;   /* counters.gyro_stuck */
    uint32_t gated;           /* counters.axis_gated, all axes */
} outcome_t;

/* max_i |kf_i / kf_true_i - 1| of the filter now. */
static float worst_kf_error(const float kf_true[ROTORS])
{
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    float worst = 0.0f;
    for (uint8_t i = 0; i < ROTORS; ++i) {
        TEST_ASSERT_TRUE(isfinite(estimate.thrust_coeff[i]));
        const float error = fabsf(estimate.thrust_coeff[i] / kf_true[i] - 1.0f);
        worst = error > worst ? error : worst;
    }
    return worst;
}

/* Flies SAMPLES gyro samples; the y axis repeats sample STUCK_FROM - 1's reading
 * for STUCK_SAMPLES samples after it (stuck = 0: never). */
static outcome_t fly(uint16_t stuck_samples, int stuck)
{
    config.gyro_stuck_samples = stuck_samples;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    const float truth_scale[ROTORS] = {1.05f, 0.95f, 1.0f, 1.02f};
    float kf_true[ROTORS];
    float km_true[ROTORS];
    float speed[ROTORS];
    float speed_sq[ROTORS];
    for (uint8_t i = 0; i < ROTORS; ++i) {
        kf_true[i] = truth_scale[i] * config.rotor[i].thrust_coeff_nominal;
        km_true[i] = config.rotor[i].drag_coeff_nominal;
        /* The rear rotors faster: a pitch acceleration of ~50 rad/s^2 on this inertia. */
        speed[i] = HOVER_SPEED * (config.rotor[i].position_m[0] < 0.0f ? 1.15f : 0.85f);
        speed_sq[i] = speed[i] * speed[i];
    }
    const float inertia[3] = {config.inertia[0][0], config.inertia[1][1], config.inertia[2][2]};
    const float noise_std = config.gyro_noise_density * sqrtf(config.gyro_sample_rate_hz);
    rng_t rng = {0x5eedu};
    float rate[3] = {0.0f, 0.0f, 0.0f};
    float stuck_value = 0.0f;
    float burst_error = 0.0f;
    uint64_t now_us = 1000000u;
    for (uint32_t k = 0; k < SAMPLES; ++k) {
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speed, ROTORS));
        float gyro[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            gyro[a] = rate[a] + noise_std * rng_normal(&rng);
        }
        if (stuck && k == STUCK_FROM - 1u) {
            stuck_value = gyro[1];
        }
        if (stuck && k >= STUCK_FROM && k < STUCK_FROM + STUCK_SAMPLES) {
            gyro[1] = stuck_value;
        }
        const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
        if (k == STUCK_FROM + STUCK_SAMPLES - 1u) {
            burst_error = worst_kf_error(kf_true);
        }
        /* Truth to the next sample: the filter's model, Euler in 10 substeps. */
        for (int s = 0; s < 10; ++s) {
            float torque[3] = {0.0f, 0.0f, 0.0f};
            for (uint8_t i = 0; i < ROTORS; ++i) {
                const propid_rotor_config_t *rotor = &config.rotor[i];
                torque[0] += rotor->position_m[1] * kf_true[i] * speed_sq[i];
                torque[1] -= rotor->position_m[0] * kf_true[i] * speed_sq[i];
                torque[2] += rotor->yaw_sign * km_true[i] * speed_sq[i];
            }
            const float h[3] = {inertia[0] * rate[0], inertia[1] * rate[1], inertia[2] * rate[2]};
            const float coupling[3] = {rate[1] * h[2] - rate[2] * h[1], rate[2] * h[0] - rate[0] * h[2],
                                       rate[0] * h[1] - rate[1] * h[0]};
            for (uint8_t a = 0; a < 3u; ++a) {
                rate[a] += 1.0e-7f * (float)GYRO_PERIOD_US * (torque[a] - coupling[a]) / inertia[a];
            }
        }
        now_us += GYRO_PERIOD_US;
    }
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    const outcome_t out = {worst_kf_error(kf_true), burst_error, counters.gyro_stuck,
                           counters.axis_gated[0] + counters.axis_gated[1] + counters.axis_gated[2]};
    return out;
}

/* The mechanism, without the check: the stuck samples pass the gate and the
 * coefficients take the blame (the sequence is strong enough to show it). */
static void test_stuck_axis_drives_coefficients_away_without_check(void)
{
    const outcome_t clean = fly(0u, 0);
    const outcome_t stuck = fly(0u, 1);
    TEST_ASSERT_TRUE_MESSAGE(clean.worst_kf_rel_error < 0.1f, "the clean sequence must identify kf");
    TEST_ASSERT_TRUE_MESSAGE(stuck.burst_kf_rel_error > 0.25f, "the stuck axis must mislead the filter");
    TEST_ASSERT_TRUE(stuck.worst_kf_rel_error > 0.25f); /* and 0.2 s of clean data do not undo it */
    TEST_ASSERT_EQUAL_UINT32(0u, stuck.stuck_counted);
}

/* With the check on, the repeated reading is not fused. At 2 readings (a sensor
 * whose noise is never quantised to a repeat) kf stays as near its truth as on
 * the clean sequence throughout; at 6 (a quantised 16-bit gyro, the SITL's
 * soak) the 4 repeats fused before the check trips move kf less than the whole
 * burst does and the data after it bring kf back. Counted: exactly the readings
 * from the K-th identical one on (the onset's reading and its STUCK_SAMPLES
 * repeats are identical). */
static void test_stuck_axis_not_fused_with_check(void)
{
    const outcome_t clean = fly(2u, 0);
    TEST_ASSERT_TRUE(clean.worst_kf_rel_error < 0.1f);
    TEST_ASSERT_EQUAL_UINT32(0u, clean.stuck_counted);
    const outcome_t unchecked = fly(0u, 1);
    const outcome_t every = fly(2u, 1);
    TEST_ASSERT_TRUE_MESSAGE(every.burst_kf_rel_error < 0.1f, "kf must not follow the stuck axis");
    TEST_ASSERT_TRUE(every.worst_kf_rel_error < 0.1f);
    TEST_ASSERT_EQUAL_UINT32(STUCK_SAMPLES + 1u - 1u, every.stuck_counted);
    const outcome_t sixth = fly(6u, 1);
    TEST_ASSERT_TRUE(sixth.burst_kf_rel_error < unchecked.burst_kf_rel_error);
    TEST_ASSERT_TRUE(sixth.worst_kf_rel_error < 0.1f);
    TEST_ASSERT_EQUAL_UINT32(STUCK_SAMPLES + 1u - 5u, sixth.stuck_counted);
}

/* The check off is the filter without it, bit for bit, on the clean sequence. */
static void test_check_on_leaves_clean_sequence_identical(void)
{
    (void)fly(0u, 0);
    float state_off[PROPID_MAX_STATES];
    memcpy(state_off, filter.core.state, sizeof(state_off));
    (void)fly(6u, 0);
    TEST_ASSERT_EQUAL_MEMORY(state_off, filter.core.state, sizeof(state_off));
}

static void test_config_refuses_one_sample(void)
{
    config.gyro_stuck_samples = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&filter, &config));
    config.gyro_stuck_samples = 2u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
}

int main(void)
{
    UNITY_BEGIN();
#if PROPID_WITH_GYRO_STUCK_CHECK
    RUN_TEST(test_stuck_axis_drives_coefficients_away_without_check);
    RUN_TEST(test_stuck_axis_not_fused_with_check);
    RUN_TEST(test_check_on_leaves_clean_sequence_identical);
    RUN_TEST(test_config_refuses_one_sample);
#endif
    return UNITY_END();
}
