/*
 * A known aerodynamic rate damping (config.aero_damping, docs/math.md §17):
 * - the configuration refuses NaN, Inf, negative and too-fast values with the
 *   field named, and the filter stays untouched;
 * - a closed-loop flight whose airframe damps its rates (-D omega): kf and km are
 *   biased with the term off (the damping torque is read as missing rotor torque)
 *   and recovered with the vehicle's D configured.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_rng.h"
#ifdef PROPID_TEST_VERBOSE
#include <stdio.h>
#endif

void setUp(void) {}
void tearDown(void) {}

#define SIM_PI 3.14159265358979f
#define KF_NOMINAL 5.57e-6f
#define KM_NOMINAL 1.36e-7f
#define ARM 0.17f

static propid_filter_t filter; /* static: keeps the test stack small */
static propid_filter_t before;
static const float inertia[3] = {3.65e-3f, 3.68e-3f, 7.03e-3f};
/* The airframe's damping [N m s/rad]: decay rates 3.0 / 3.0 / 2.1 1/s on this inertia. */
static const float damping[3] = {0.011f, 0.011f, 0.015f};

static void quad_config(propid_config_t *config)
{
    propid_config_default(config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(config, 4u, ARM, SIM_PI / 4.0f, 1.0f,
                                                                 KF_NOMINAL, KM_NOMINAL));
    propid_config_set_inertia_diag(config, inertia[0], inertia[1], inertia[2]);
    config->gyro_noise_density = 0.003f / sqrtf(500.0f);
    config->rate_process_noise = 0.5f;
}

static void expect_bad(const propid_config_t *config)
{
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(config, &bad));
    TEST_ASSERT_EQUAL_STRING("aero_damping", bad);
    memcpy(&before, &filter, sizeof(filter));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&filter, config));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &filter.core, sizeof(filter.core));
    TEST_ASSERT_EQUAL_MEMORY(&before.derived, &filter.derived, sizeof(filter.derived));
}

static void test_aero_damping_is_validated(void)
{
    propid_config_t config;
    quad_config(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    const float bad_values[4] = {NAN, INFINITY, -1.0e-3f, 2.0e3f};
    for (uint8_t k = 0; k < 4u; ++k) {
        for (uint8_t a = 0; a < 3u; ++a) {
            quad_config(&config);
            config.aero_damping[a] = bad_values[k];
            expect_bad(&config);
        }
    }
    /* Faster than one gyro gap (50 ms): 1 / (0.05 s) = 20 1/s on Jzz = 7e-3 is 0.14 N m s/rad. */
    quad_config(&config);
    config.aero_damping[2] = 0.15f;
    expect_bad(&config);
    config.aero_damping[2] = 0.13f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, NULL));
}

static void test_aero_damping_leaves_the_plain_layout_when_off(void)
{
    propid_config_t config;
    quad_config(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    TEST_ASSERT_EQUAL_UINT8(1u, filter.derived.quad_layout);
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_UINT8(0u, estimate.model_terms & PROPID_TERM_AERO_DAMPING);
    config.aero_damping[1] = damping[1];
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    TEST_ASSERT_EQUAL_UINT8(0u, filter.derived.quad_layout); /* the general step carries the term */
    TEST_ASSERT_EQUAL_UINT8(14u, filter.derived.state_count); /* no state added */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_UINT8(PROPID_TERM_AERO_DAMPING, estimate.model_terms & PROPID_TERM_AERO_DAMPING);
}

/* A 20 s closed-loop flight (rate loop with an integrator, nominal mixer, multi-sine
 * excitation, thrust swing) of an airframe with the torque -damping omega; the filter
 * configured with `configured` as its damping. Returns the mean over rotors of
 * kf_est / kf_true; *km_ratio the same for km. */
static float fly(const float configured[3], float *km_ratio)
{
    propid_config_t config;
    quad_config(&config);
    for (uint8_t a = 0; a < 3u; ++a) {
        config.aero_damping[a] = configured[a];
    }
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    const float per_rotor[4] = {1.04f, 0.97f, 1.02f, 0.96f};
    float kf[4];
    float km[4];
    for (uint8_t i = 0; i < 4u; ++i) {
        kf[i] = per_rotor[i] * KF_NOMINAL;
        km[i] = per_rotor[3u - i] * KM_NOMINAL;
    }
    float rate[3] = {0.0f, 0.0f, 0.0f};
    float integral[3] = {0.0f, 0.0f, 0.0f};
    const float bias[3] = {0.01f, -0.02f, 0.005f};
    rng_t rng = {4242u};
    const float dt = 0.002f;
    const uint32_t steps = 10000u;
    for (uint32_t step = 0; step < steps; ++step) {
        const float t = (float)step * dt;
        float accel_cmd[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            const float phase = (float)a * 1.3f;
            const float excitation = (a < 2u ? 6.0f : 2.0f) * (sinf(2.0f * SIM_PI * 1.1f * t + phase) +
                                                             0.6f * sinf(2.0f * SIM_PI * 2.9f * t + 2.0f * phase));
            integral[a] += rate[a] * dt;
            accel_cmd[a] = excitation - 8.0f * rate[a] - 10.0f * integral[a];
        }
        const float collective = 9.81f * (1.0f + 0.25f * sinf(2.0f * SIM_PI * 0.7f * t));
        float u[4];
        float speed[4];
        for (uint8_t i = 0; i < 4u; ++i) {
            const propid_rotor_config_t *rotor = &config.rotor[i];
            const float share = collective / 4.0f + inertia[0] * accel_cmd[0] / (4.0f * rotor->position_m[1]) -
                                inertia[1] * accel_cmd[1] / (4.0f * rotor->position_m[0]) +
                                rotor->yaw_sign * inertia[2] * accel_cmd[2] * KF_NOMINAL / (4.0f * KM_NOMINAL);
            u[i] = share > 0.0f ? share / KF_NOMINAL : 0.0f;
            speed[i] = sqrtf(u[i]);
        }
        float torque[3] = {-damping[0] * rate[0], -damping[1] * rate[1], -damping[2] * rate[2]};
        for (uint8_t i = 0; i < 4u; ++i) {
            const propid_rotor_config_t *rotor = &config.rotor[i];
            torque[0] += kf[i] * u[i] * rotor->position_m[1];
            torque[1] -= kf[i] * u[i] * rotor->position_m[0];
            torque[2] += rotor->yaw_sign * km[i] * u[i];
        }
        const float gyroscopic[3] = {(inertia[2] - inertia[1]) * rate[1] * rate[2],
                                     (inertia[0] - inertia[2]) * rate[2] * rate[0],
                                     (inertia[1] - inertia[0]) * rate[0] * rate[1]};
        /* Plant: Heun over dt, as the filter's step integrates its model. */
        float slope[3];
        float ahead[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            slope[a] = (torque[a] - gyroscopic[a]) / inertia[a];
            ahead[a] = rate[a] + dt * slope[a];
        }
        for (uint8_t a = 0; a < 3u; ++a) {
            const uint8_t b = (uint8_t)((a + 1u) % 3u);
            const uint8_t c = (uint8_t)((a + 2u) % 3u);
            const float gyroscopic_ahead = (inertia[c] - inertia[b]) * ahead[b] * ahead[c];
            const float slope_ahead = (torque[a] + damping[a] * rate[a] - damping[a] * ahead[a] - gyroscopic_ahead) /
                                      inertia[a];
            rate[a] += 0.5f * dt * (slope[a] + slope_ahead);
        }
        const uint64_t t_us = 1000u + (uint64_t)(step + 1u) * 2000u;
        (void)propid_push_rotor_speeds(&filter, t_us - 2000u, speed, 4u);
        float gyro[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            gyro[a] = rate[a] + bias[a] + 0.003f * rng_normal(&rng);
        }
        TEST_ASSERT_TRUE(propid_push_gyro(&filter, t_us, gyro) >= 0);
    }
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    float kf_mean = 0.0f;
    float km_mean = 0.0f;
    for (uint8_t i = 0; i < 4u; ++i) {
        kf_mean += 0.25f * estimate.thrust_coeff[i] / kf[i];
        km_mean += 0.25f * estimate.drag_coeff[i] / km[i];
    }
    *km_ratio = km_mean;
#ifdef PROPID_TEST_VERBOSE
    printf("damping %g %g %g: kf %.4f km %.4f\n", (double)configured[0], (double)configured[1],
           (double)configured[2], (double)kf_mean, (double)km_mean);
#endif
    return kf_mean;
}

static void test_aero_damping_removes_the_damping_bias(void)
{
    const float none[3] = {0.0f, 0.0f, 0.0f};
    float km_off = 0.0f;
    float km_on = 0.0f;
    const float kf_off = fly(none, &km_off);
    const float kf_on = fly(damping, &km_on);
    TEST_ASSERT_TRUE(fabsf(kf_off - 1.0f) > 0.05f); /* biased without the term */
    TEST_ASSERT_TRUE(fabsf(km_off - 1.0f) > 0.05f);
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 1.0f, kf_on); /* recovered with it */
    TEST_ASSERT_FLOAT_WITHIN(0.02f, 1.0f, km_on);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_aero_damping_is_validated);
    RUN_TEST(test_aero_damping_leaves_the_plain_layout_when_off);
    RUN_TEST(test_aero_damping_removes_the_damping_bias);
    return UNITY_END();
}
