/*
 * Semantics of the public API's life cycle (propid.h): status names, init,
 * reset, reset_rotor, resync, estimate read-out. Rejection paths are in
 * test_reject.c.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "per_rotor_view.h"
#include "propid/propid.h"
#include "unity.h"
#include "test_vehicle.h"

#define ROTORS 4u
#define GYRO_PERIOD_US 2000u

static propid_config_t config;
static propid_filter_t filter;
static propid_filter_t fresh;     /* a just-initialised filter to compare with */
static propid_filter_t snapshot;
static uint64_t now_us;

static void make_config(propid_config_t *out)
{
    test_vehicle_config(out, ROTORS, 0.17f, 0.0f);
}

/* Excite the filter so that every state and covariance entry has moved. */
static void fly(uint32_t samples)
{
    for (uint32_t k = 0; k < samples; ++k) {
        now_us += GYRO_PERIOD_US;
        const float t = 1.0e-6f * (float)now_us;
        const float speeds[ROTORS] = {470.0f + 60.0f * sinf(7.0f * t), 470.0f + 60.0f * sinf(5.0f * t + 1.0f),
                                      470.0f + 60.0f * sinf(3.0f * t + 2.0f), 470.0f + 60.0f * sinf(4.0f * t + 3.0f)};
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
        const float gyro[3] = {0.5f * sinf(3.0f * t), 0.4f * sinf(2.0f * t), 0.3f * sinf(t)};
        const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
    }
}

void setUp(void)
{
    make_config(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&fresh, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    now_us = 5000000u;
}

void tearDown(void)
{
}

static void test_status_names_distinct(void)
{
    static const propid_status_t all[] = {
        PROPID_OK, PROPID_OK_GATED, PROPID_OK_QUEUED, PROPID_ERR_NULL, PROPID_ERR_NOT_INITIALISED, PROPID_ERR_CONFIG,
        PROPID_ERR_NOT_FINITE, PROPID_ERR_ROTOR_SPEED_NEGATIVE, PROPID_ERR_ROTOR_SPEED_RANGE,
        PROPID_ERR_ROTOR_COUNT, PROPID_ERR_ROTOR_INDEX, PROPID_ERR_GYRO_RANGE,
        PROPID_ERR_TIME_BACKWARDS, PROPID_ERR_TIME_JUMP, PROPID_ERR_NO_ROTOR_DATA,
        PROPID_ERR_ROTOR_STALE, PROPID_ERR_NUMERIC, PROPID_ERR_ACCEL_RANGE};
    const uint32_t count = (uint32_t)(sizeof all / sizeof all[0]);
    /* Every rejection code has a counter slot. */
    TEST_ASSERT_EQUAL_INT(PROPID_REJECT_SLOTS, 1 - (int)PROPID_ERR_ACCEL_RANGE);
    for (uint32_t i = 0; i < count; ++i) {
        const char *name = propid_status_name(all[i]);
        TEST_ASSERT_NOT_NULL(name);
        TEST_ASSERT_TRUE(strncmp(name, "PROPID_", 7) == 0);
        for (uint32_t j = 0; j < i; ++j) {
            TEST_ASSERT_TRUE_MESSAGE(strcmp(name, propid_status_name(all[j])) != 0, name);
        }
    }
    TEST_ASSERT_EQUAL_STRING("PROPID_OK", propid_status_name(PROPID_OK));
    TEST_ASSERT_EQUAL_STRING("PROPID_ERR_TIME_JUMP", propid_status_name(PROPID_ERR_TIME_JUMP));
    TEST_ASSERT_EQUAL_STRING("PROPID_ERR_ROTOR_STALE", propid_status_name(PROPID_ERR_ROTOR_STALE));
    /* Unknown codes still get a printable, distinct name. */
    const char *unknown = propid_status_name((propid_status_t)-99);
    TEST_ASSERT_NOT_NULL(unknown);
    for (uint32_t i = 0; i < count; ++i) {
        TEST_ASSERT_TRUE(strcmp(unknown, propid_status_name(all[i])) != 0);
    }
}

static void test_init_gives_prior(void)
{
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_UINT8(ROTORS, estimate.rotor_count);
    for (uint8_t i = 0; i < ROTORS; ++i) {
        TEST_ASSERT_EQUAL_FLOAT(config.rotor[i].thrust_coeff_nominal, estimate.thrust_coeff[i]);
        TEST_ASSERT_EQUAL_FLOAT(config.rotor[i].drag_coeff_nominal, estimate.drag_coeff[i]);
        TEST_ASSERT_FLOAT_WITHIN(1e-3f * config.rotor[i].thrust_coeff_nominal,
                                 config.thrust_coeff_rel_std0 * config.rotor[i].thrust_coeff_nominal,
                                 estimate.thrust_coeff_std[i]);
        TEST_ASSERT_FLOAT_WITHIN(1e-3f * config.rotor[i].drag_coeff_nominal,
                                 config.drag_coeff_rel_std0 * config.rotor[i].drag_coeff_nominal,
                                 estimate.drag_coeff_std[i]);
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        TEST_ASSERT_EQUAL_FLOAT(0.0f, estimate.gyro_bias[a]);
        TEST_ASSERT_FLOAT_WITHIN(1e-4f, config.gyro_bias_std0, estimate.gyro_bias_std[a]);
        TEST_ASSERT_FLOAT_WITHIN(1e-4f, config.rate_std0, estimate.body_rate_std[a]);
    }
    TEST_ASSERT_EQUAL_UINT16(0u, estimate.thrust_coeff_converged);
    TEST_ASSERT_EQUAL_UINT16(0u, estimate.drag_coeff_converged);
    TEST_ASSERT_BITS_HIGH(PROPID_HEALTH_NO_ROTOR_DATA, estimate.health);
    TEST_ASSERT_BITS_LOW(PROPID_HEALTH_ALL_CONVERGED, estimate.health);
    /* The filter kept its own copy of the configuration (the quad build: the
     * fields its calls read). */
#if PROPID_GENERAL_VEHICLES
    TEST_ASSERT_EQUAL_MEMORY(&config, &filter.config, sizeof(config));
#else
    /* The quad build's RAM budget (docs/performance.md). */
    TEST_ASSERT_LESS_OR_EQUAL_UINT32(1024u, (uint32_t)sizeof(propid_filter_t));
    TEST_ASSERT_EQUAL_UINT8(config.rotor_count, filter.config.rotor_count);
    TEST_ASSERT_EQUAL_UINT16(config.gate_max_consecutive, filter.config.gate_max_consecutive);
#if PROPID_DELAY_SLOTS > 0
    TEST_ASSERT_EQUAL_INT32(config.rotor_delay_us, filter.config.rotor_delay_us);
#endif
    TEST_ASSERT_EQUAL_UINT32(config.rotor_stale_us, filter.config.rotor_stale_us);
    TEST_ASSERT_EQUAL_UINT32(config.max_gyro_gap_us, filter.config.max_gyro_gap_us);
    TEST_ASSERT_EQUAL_FLOAT(config.max_rotor_speed, filter.config.max_rotor_speed);
    TEST_ASSERT_EQUAL_FLOAT(config.gyro_range, filter.config.gyro_range);
    TEST_ASSERT_EQUAL_FLOAT(config.coeff_rel_min, filter.config.coeff_rel_min);
    TEST_ASSERT_EQUAL_FLOAT(config.coeff_rel_max, filter.config.coeff_rel_max);
    for (uint8_t i = 0; i < ROTORS; ++i) {
        TEST_ASSERT_EQUAL_FLOAT(config.rotor[i].thrust_coeff_nominal, filter.config.rotor[i].thrust_coeff_nominal);
        TEST_ASSERT_EQUAL_FLOAT(config.rotor[i].drag_coeff_nominal, filter.config.rotor[i].drag_coeff_nominal);
    }
#endif
    /* Counters start at zero. */
    propid_counters_t counters;
    static const propid_counters_t zero;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_MEMORY(&zero, &counters, sizeof(counters));
}

static void test_reinit_replaces_everything(void)
{
    fly(100);
    propid_config_t other = config;
    other.rotor[1].thrust_coeff_nominal *= 2.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &other));
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_FLOAT(other.rotor[1].thrust_coeff_nominal, estimate.thrust_coeff[1]);
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(0u, counters.gyro_accepted);
}

static void test_reset_returns_to_prior_keeps_counters(void)
{
    fly(200);
    propid_counters_t counters_before;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters_before));
    TEST_ASSERT_EQUAL_UINT32(200u, counters_before.gyro_accepted);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_reset(&filter));

    /* State and covariance are the prior again, bit for bit. */
    TEST_ASSERT_EQUAL_MEMORY(fresh.core.state, filter.core.state, sizeof(filter.core.state));
    TEST_ASSERT_EQUAL_MEMORY(fresh.core.cov, filter.core.cov, sizeof(filter.core.cov));
    TEST_ASSERT_EQUAL_UINT8(0u, filter.core.has_rotor_data);
    TEST_ASSERT_EQUAL_UINT8(0u, filter.core.has_time);
    TEST_ASSERT_EQUAL_MEMORY(&fresh.config, &filter.config, sizeof(filter.config));
    TEST_ASSERT_EQUAL_MEMORY(&fresh.derived, &filter.derived, sizeof(filter.derived));

    propid_counters_t counters_after;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters_after));
    TEST_ASSERT_EQUAL_MEMORY(&counters_before, &counters_after, sizeof(counters_after));

    /* No time and no rotor data: the clock may start anywhere, even earlier. */
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NO_ROTOR_DATA, propid_push_gyro(&filter, 1000u, gyro));
    const float speeds[ROTORS] = {470.0f, 470.0f, 470.0f, 470.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1000u, speeds, ROTORS));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, 1000u, gyro) >= 0);
}

static void test_reset_rotor_touches_only_that_rotor(void)
{
    fly(300);
    snapshot = filter;
    const uint8_t rotor = 2u;
    const uint8_t kf = propid_index_thrust_coeff(rotor);
    const uint8_t km = propid_index_drag_coeff(&filter, rotor);
    const uint8_t states = (uint8_t)(6u + 2u * ROTORS);
    /* The flight must have moved the coefficient and correlated it with others. */
    TEST_ASSERT_TRUE(snapshot.core.cov[propid_cov_index(kf, kf)] < fresh.core.cov[propid_cov_index(kf, kf)]);

    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_reset_rotor(&filter, rotor));

    /* Per rotor (the coefficients are kept in their bases): equal up to the
     * rounding of the maps between the bases. */
    const propid_core_t before = per_rotor_core(&snapshot);
    const propid_core_t after = per_rotor_core(&filter);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.0f, after.state[kf]);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 1.0f, after.state[km]);
    /* The prior, up to the cover of the reset's rounding (propid_coeff_basis.c: a
     * few eps times n of each variance of the kept basis, relative). */
    const float kf_prior = fresh.core.cov[propid_cov_index(kf, kf)];
    const float km_prior = fresh.core.cov[propid_cov_index(km, km)];
    TEST_ASSERT_FLOAT_WITHIN(1e-4f * kf_prior, kf_prior, after.cov[propid_cov_index(kf, kf)]);
    TEST_ASSERT_FLOAT_WITHIN(1e-4f * km_prior, km_prior, after.cov[propid_cov_index(km, km)]);
    TEST_ASSERT_TRUE(after.cov[propid_cov_index(kf, kf)] >= kf_prior * (1.0f - 1e-6f));
    for (uint8_t i = 0; i < states; ++i) {
        if (i != kf && i != km) {
            TEST_ASSERT_FLOAT_WITHIN(1e-6f, before.state[i], after.state[i]);
        }
        for (uint8_t j = 0; j < states; ++j) {
            const int touches = (i == kf || i == km || j == kf || j == km);
            const float scale = sqrtf(before.cov[propid_cov_index(i, i)] * before.cov[propid_cov_index(j, j)]);
            if (!touches) {
                /* Unchanged but for the cover of the reset's rounding (a few eps times n
                 * of the kept basis' variances, relative; 2e-5 here). */
                TEST_ASSERT_FLOAT_WITHIN(1e-4f * scale, before.cov[propid_cov_index(i, j)],
                                         after.cov[propid_cov_index(i, j)]);
            } else if (i != j) {
                TEST_ASSERT_FLOAT_WITHIN(1e-5f * scale, 0.0f, after.cov[propid_cov_index(i, j)]);
            }
        }
    }
    /* Not a rejection: no counter moves, clocks kept, still runs. */
    TEST_ASSERT_EQUAL_MEMORY(&snapshot.counters, &filter.counters, sizeof(filter.counters));
    TEST_ASSERT_EQUAL_UINT64(snapshot.core.time_us, filter.core.time_us);
    TEST_ASSERT_EQUAL_UINT64(snapshot.core.rotor_time_us, filter.core.rotor_time_us);
    fly(10);
}

static void test_resync_after_time_jump(void)
{
    fly(100);
    const float gyro[3] = {0.1f, 0.0f, 0.0f};
    const float speeds[ROTORS] = {470.0f, 470.0f, 470.0f, 470.0f};
    const uint64_t later = now_us + 10u * (uint64_t)config.max_gyro_gap_us;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, later, speeds, ROTORS));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_JUMP, propid_push_gyro(&filter, later, gyro));
    snapshot = filter;

    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, later));
    const uint8_t states = (uint8_t)(6u + 2u * ROTORS);
    /* Coefficients and biases kept; body-rate variance back to the prior. */
    for (uint8_t i = 3u; i < states; ++i) {
        TEST_ASSERT_EQUAL_FLOAT(snapshot.core.state[i], filter.core.state[i]);
        for (uint8_t j = 3u; j < states; ++j) {
            TEST_ASSERT_EQUAL_FLOAT(snapshot.core.cov[propid_cov_index(i, j)], filter.core.cov[propid_cov_index(i, j)]);
        }
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        TEST_ASSERT_EQUAL_FLOAT(fresh.core.cov[propid_cov_index(a, a)], filter.core.cov[propid_cov_index(a, a)]);
    }
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(snapshot.counters.resyncs + 1u, counters.resyncs);

    /* The clock runs on from the new anchor. */
    now_us = later;
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, now_us, gyro) >= 0);
    fly(10);
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_BITS_HIGH(PROPID_HEALTH_TIME_RESYNCED, estimate.health);
    TEST_ASSERT_EQUAL_UINT64(now_us, estimate.time_us);

    /* Sticky until reset. */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_reset(&filter));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_BITS_LOW(PROPID_HEALTH_TIME_RESYNCED, estimate.health);
}

static void test_estimate_is_consistent_with_state(void)
{
    fly(500);
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_EQUAL_UINT64(now_us, estimate.time_us);
    TEST_ASSERT_BITS_LOW(PROPID_HEALTH_NO_ROTOR_DATA, estimate.health);
    const propid_core_t per_rotor = per_rotor_core(&filter);
    for (uint8_t i = 0; i < ROTORS; ++i) {
        const uint8_t kf = propid_index_thrust_coeff(i);
        const uint8_t km = propid_index_drag_coeff(&filter, i);
        TEST_ASSERT_FLOAT_WITHIN(1e-6f * config.rotor[i].thrust_coeff_nominal,
                                 per_rotor.state[kf] * config.rotor[i].thrust_coeff_nominal,
                                 estimate.thrust_coeff[i]);
        TEST_ASSERT_FLOAT_WITHIN(1e-6f * config.rotor[i].drag_coeff_nominal,
                                 per_rotor.state[km] * config.rotor[i].drag_coeff_nominal,
                                 estimate.drag_coeff[i]);
        TEST_ASSERT_TRUE(estimate.thrust_coeff_std[i] > 0.0f);
        TEST_ASSERT_TRUE(estimate.drag_coeff_std[i] > 0.0f);
        /* The stds are the per-rotor ones (the bases mapped back), not the kept
         * blocks' diagonals. */
        const float km_std = sqrtf(per_rotor.cov[propid_cov_index(km, km)]) * config.rotor[i].drag_coeff_nominal;
        TEST_ASSERT_FLOAT_WITHIN(1e-3f * km_std, km_std, estimate.drag_coeff_std[i]);
        const float kf_std = sqrtf(per_rotor.cov[propid_cov_index(kf, kf)]) * config.rotor[i].thrust_coeff_nominal;
        TEST_ASSERT_FLOAT_WITHIN(1e-3f * kf_std, kf_std, estimate.thrust_coeff_std[i]);
        /* "converged" implies "converging" */
        TEST_ASSERT_EQUAL_UINT16(estimate.thrust_coeff_converged,
                                 estimate.thrust_coeff_converged & estimate.thrust_coeff_converging);
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t bias = propid_index_gyro_bias(&filter, a);
        TEST_ASSERT_EQUAL_FLOAT(filter.core.state[bias], estimate.gyro_bias[a]);
        TEST_ASSERT_TRUE(isfinite(estimate.innovation[a]));
    }
    /* Reading is free of side effects. */
    snapshot = filter;
    propid_estimate_t again;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &again));
    TEST_ASSERT_EQUAL_MEMORY(&estimate, &again, sizeof(again));
    TEST_ASSERT_EQUAL_MEMORY(&snapshot, &filter, sizeof(filter));
}

static void test_state_indices(void)
{
    TEST_ASSERT_EQUAL_UINT8(0u, propid_index_rate(0u));
    TEST_ASSERT_EQUAL_UINT8(2u, propid_index_rate(2u));
    TEST_ASSERT_EQUAL_UINT8(3u, propid_index_thrust_coeff(0u));
    TEST_ASSERT_EQUAL_UINT8(3u + ROTORS, propid_index_drag_coeff(&filter, 0u));
    TEST_ASSERT_EQUAL_UINT8(3u + 2u * ROTORS + 2u, propid_index_gyro_bias(&filter, 2u));
    TEST_ASSERT_EQUAL_UINT8(6u + 2u * ROTORS, filter.derived.state_count);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_status_names_distinct);
    RUN_TEST(test_init_gives_prior);
    RUN_TEST(test_reinit_replaces_everything);
    RUN_TEST(test_reset_returns_to_prior_keeps_counters);
    RUN_TEST(test_reset_rotor_touches_only_that_rotor);
    RUN_TEST(test_resync_after_time_jump);
    RUN_TEST(test_estimate_is_consistent_with_state);
    RUN_TEST(test_state_indices);
    return UNITY_END();
}
