/*
 * Regression tests of the input and numeric guards under faulty data: each test
 * drives the public API into one failure found by random-call fuzzing and checks
 * the filter's answer (docs/reliability.md, "Findings"):
 *   runaway rate while gated, gating off, an ESC stamp far ahead, an ESC spike
 *   within range, the first gyro sample at a high rate, noise settings out of
 *   range, covariance definiteness.
 */
#include <math.h>
#include <stdio.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "cov_positive_definite.h"
#include "test_rng.h"
#include "test_vehicle.h"
#include "../../firmware/src/propid_internal.h"

#define ROTORS 4u
#define GYRO_PERIOD_US 2000u
#define HOVER_SPEED 470.0f

static propid_config_t config;
static propid_filter_t filter;
static uint64_t now_us;

static void make_config(propid_config_t *out)
{
    test_vehicle_config(out, ROTORS, 0.17f, 0.7853982f);
}

void setUp(void)
{
    make_config(&config);
    now_us = 1000000u;
}

void tearDown(void)
{
}

static void init_filter(void)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
}

static int all_finite(const float *values, uint32_t count)
{
    for (uint32_t i = 0; i < count; ++i) {
        if (!isfinite(values[i])) {
            return 0;
        }
    }
    return 1;
}

/* The invariants every call must keep, accepted or not: finite estimates and
 * innovation ratios, positive finite variances. */
static void assert_sane(void)
{
    propid_estimate_t e;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &e));
    TEST_ASSERT_TRUE(all_finite(e.body_rate, 3u));
    TEST_ASSERT_TRUE(all_finite(e.gyro_bias, 3u));
    TEST_ASSERT_TRUE(all_finite(e.thrust_coeff, ROTORS));
    TEST_ASSERT_TRUE(all_finite(e.drag_coeff, ROTORS));
    TEST_ASSERT_TRUE(all_finite(e.innovation, 3u));
    TEST_ASSERT_TRUE(all_finite(e.innovation_test_ratio, 3u));
    const uint8_t n = filter.derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        TEST_ASSERT_TRUE(isfinite(filter.core.state[i]));
        TEST_ASSERT_TRUE(filter.core.cov[propid_cov_index(i, i)] > 0.0f && isfinite(filter.core.cov[propid_cov_index(i, i)]));
    }
    /* Bounded, not running away: the prediction stops at 2 gyro_range, an
     * update of a correlated axis may move a gated axis' rate a little further. */
    for (uint8_t a = 0; a < 3u; ++a) {
        TEST_ASSERT_TRUE_MESSAGE(fabsf(e.body_rate[a]) <= 4.0f * config.gyro_range, "rate beyond bound");
    }
}

static propid_status_t push(uint64_t time_us, float speed, const float gyro[3])
{
    const float speeds[ROTORS] = {speed, speed * 1.01f, speed * 0.99f, speed * 1.02f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, time_us, speeds, ROTORS));
    return propid_push_gyro(&filter, time_us, gyro);
}

/* Spin the filter up to a fast rotation: 30 rad/s on every axis. */
static void spin_up(void)
{
    const float gyro[3] = {30.0f, 30.0f, 30.0f};
    for (uint32_t k = 0; k < 200u; ++k) {
        now_us += GYRO_PERIOD_US;
        const propid_status_t status = push(now_us, HOVER_SPEED, gyro);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
    }
}

/* Gated samples at the longest allowed gap while the state spins fast: the
 * gyroscopic term integrated without corrections must stay bounded, and so
 * must every innovation ratio; afterwards benign data is accepted again. */
static void run_gated_spin(void)
{
    init_filter();
    spin_up();
    const float wrong[3] = {-30.0f, 30.0f, -30.0f};
    const uint64_t gap = config.max_gyro_gap_us;
    for (uint32_t k = 0; k < 200u; ++k) {
        now_us += gap;
        const propid_status_t status = push(now_us, HOVER_SPEED, wrong);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
        assert_sane();
    }
}

/* Benign data (hover, at rest) is accepted again, never NUMERIC, with finite,
 * bounded numbers; every gated run ends in a re-open within
 * gate_max_consecutive samples. (Coefficients that the garbage taught wrong
 * values are re-learnt only at their random walk's pace: docs/design.md §12.) */
static void assert_recovers(void)
{
    const float rest[3] = {0.01f, -0.02f, 0.03f};
    for (uint32_t k = 0; k < 400u; ++k) {
        now_us += GYRO_PERIOD_US;
        const propid_status_t status = push(now_us, HOVER_SPEED, rest);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
        assert_sane();
        for (uint8_t a = 0; a < 3u; ++a) {
            TEST_ASSERT_TRUE(filter.core.gated_run[a] <= config.gate_max_consecutive);
        }
    }
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(0u, counters.rejected[-(int)PROPID_ERR_NUMERIC]);
}

static void test_gated_rate_stays_bounded_and_recovers(void)
{
    run_gated_spin();
    assert_recovers();
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(0u, counters.rejected[-(int)PROPID_ERR_NUMERIC]);
}

/* The same with a gate that practically never re-opens (65535 in a row): the
 * bound alone keeps the numbers finite, and propid_resync() forgets the rates. */
static void test_resync_resets_runaway_rate(void)
{
    config.gate_max_consecutive = 65535u;
    init_filter();
    spin_up();
    const float wrong[3] = {-30.0f, 30.0f, -30.0f};
    for (uint32_t k = 0; k < 100u; ++k) {
        now_us += config.max_gyro_gap_us;
        TEST_ASSERT_EQUAL_INT(PROPID_OK_GATED, push(now_us, HOVER_SPEED, wrong));
        assert_sane();
    }
    now_us += GYRO_PERIOD_US;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, now_us));
    TEST_ASSERT_EQUAL_FLOAT(0.0f, filter.core.state[0]);
    TEST_ASSERT_EQUAL_FLOAT(0.0f, filter.core.state[1]);
    TEST_ASSERT_EQUAL_FLOAT(0.0f, filter.core.state[2]);
    /* The anchoring sample sets the rates from the measurement. */
    const float rest[3] = {0.01f, -0.02f, 0.03f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, rest));
    propid_estimate_t e;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &e));
    for (uint8_t a = 0; a < 3u; ++a) {
        TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, rest[a], e.body_rate[a] + e.gyro_bias[a]);
    }
    config.gate_max_consecutive = 25u; /* (the filter keeps its own copy) */
}

/* gate_sigma = 0 (documented: gating off): never a non-finite state. */
static void test_gate_off_never_writes_non_finite(void)
{
    config.gate_sigma = 0.0f;
    run_gated_spin();
    rng_t rng = {77u};
    uint32_t accepted = 0u;
    for (uint32_t k = 0; k < 2000u; ++k) {
        now_us += 1u + (rng_next(&rng) % config.max_gyro_gap_us);
        const float gyro[3] = {rng_range(&rng, -34.0f, 34.0f), rng_range(&rng, -34.0f, 34.0f),
                               rng_range(&rng, -34.0f, 34.0f)};
        /* Wild speeds: refused when no motor could reach them since the
         * previous sample (gaps under 10 ms), fused otherwise. */
        const float speed = rng_range(&rng, 0.0f, 5000.0f);
        const float speeds[ROTORS] = {speed, speed * 1.01f, speed * 0.99f, speed * 1.02f};
        const propid_status_t pushed = propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS);
        TEST_ASSERT_TRUE_MESSAGE(pushed == PROPID_OK || pushed == PROPID_ERR_ROTOR_SPEED_RANGE,
                                 propid_status_name(pushed));
        accepted += pushed == PROPID_OK;
        const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
        TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
        assert_sane();
    }
    TEST_ASSERT_TRUE(accepted > 1000u); /* most gaps exceed 10 ms: the wild speeds are fused */
}

/* One ESC sample stamped an hour ahead must not lock out the rotor stream:
 * gyro samples meanwhile are refused as stale (flag raised), the next correct
 * ESC sample replaces the wild one. */
static void test_esc_stamp_far_ahead_does_not_freeze_input(void)
{
    init_filter();
    const float gyro[3] = {0.01f, -0.02f, 0.03f};
    for (uint32_t k = 0; k < 20u; ++k) {
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
    }
    const float speeds[ROTORS] = {100.0f, 100.0f, 100.0f, 100.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK,
                          propid_push_rotor_speeds(&filter, now_us + 3600000000u, speeds, ROTORS));
    now_us += GYRO_PERIOD_US;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_STALE, propid_push_gyro(&filter, now_us, gyro));
    propid_estimate_t e;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &e));
    TEST_ASSERT_TRUE((e.health & PROPID_HEALTH_ROTOR_STALE) != 0u);
    /* The next correct samples are accepted and the flag clears. */
    for (uint32_t k = 0; k < 5u; ++k) {
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
    }
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &e));
    TEST_ASSERT_TRUE((e.health & PROPID_HEALTH_ROTOR_STALE) == 0u);
    /* A small backward step is still refused. */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_BACKWARDS,
                          propid_push_rotor_speeds(&filter, now_us - 1000u, speeds, ROTORS));
}

/* An ESC outage (docs/integration.md rule 3): gyro samples are ROTOR_STALE once the
 * latest rotor speeds are older than rotor_stale_us; rejected samples do not move the
 * filter's time, so max_gyro_gap_us after the last accepted one they are TIME_JUMP, and
 * stay so when the telemetry is back, until propid_resync. */
static void test_esc_outage_turns_stale_into_time_jump(void)
{
    init_filter();
    const float gyro[3] = {0.01f, -0.02f, 0.03f};
    for (uint32_t k = 0; k < 20u; ++k) {
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
    }
    const uint64_t last_rotor_us = now_us;
    uint64_t last_accepted_us = now_us;
    uint32_t stale = 0u;
    uint32_t jumps = 0u;
    for (uint32_t k = 0; k < 100u; ++k) {
        now_us += GYRO_PERIOD_US;
        const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
        if (now_us - last_accepted_us > config.max_gyro_gap_us) {
            TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_JUMP, status);
            ++jumps;
        } else if (now_us - last_rotor_us > config.rotor_stale_us) {
            TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_STALE, status);
            ++stale;
        } else {
            TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
            last_accepted_us = now_us;
        }
    }
    TEST_ASSERT_TRUE(stale > 0u && jumps > 0u);
    /* The telemetry is back: the gyro is still a time jump away from the filter. */
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    now_us += GYRO_PERIOD_US;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_TIME_JUMP, propid_push_gyro(&filter, now_us, gyro));
    /* Rule 4: resync, push the sample again; the next ones are fused. */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, now_us));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, now_us, gyro) >= 0);
    now_us += GYRO_PERIOD_US;
    TEST_ASSERT_TRUE(push(now_us, HOVER_SPEED, gyro) >= 0);
    assert_sane();
}

/* A corrupted ESC frame decoded as a speed within range (soak: a 0.7 % rate of
 * such spikes on a Crazyflie circle threw every kf ~90 % off within 0.5 s, no
 * innovation gated, and crashed the vehicle with the damage detector on): a
 * change no motor of the configured time constant can make in the time since
 * the previous sample is refused like an out-of-range speed, with nothing
 * written. A first-order motor covers at most dt / tau of its headroom
 * (max_rotor_speed - speed up, speed down), taken PROPID_MOTOR_SPEEDUP = 2
 * times faster for margin, plus 2 % of the range (telemetry resolution near
 * standstill): a real motor, even twice as fast as configured,
 * passes at any speed and in both directions; once the gap spans tau / 2 any
 * in-range speed passes (no lock-out). */
static void test_esc_spike_within_range_refused(void)
{
    config.motor_time_constant = 0.03f; /* reach per 2 ms sample: 2 x 2 / 30 = 13.3 % of the headroom */
    init_filter();
    const float gyro[3] = {0.01f, -0.02f, 0.03f};
    for (uint32_t k = 0; k < 20u; ++k) {
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
    }
    const float headroom_up = config.max_rotor_speed - HOVER_SPEED;
    /* One rotor jumps by 20 % of its headroom within 2 ms (in range, and inside
     * the former bound of max_rotor_speed per 10 ms: 20 % of the range), then
     * one drops by half (the bound: 13.3 % of the speed + 2 % of the range). */
    float spike[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED + 0.2f * headroom_up, HOVER_SPEED};
    TEST_ASSERT_TRUE(spike[2] - HOVER_SPEED < 0.2f * config.max_rotor_speed);
    static propid_filter_t before;
    memcpy(&before, &filter, sizeof(filter));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_RANGE,
                          propid_push_rotor_speeds(&filter, now_us + GYRO_PERIOD_US, spike, ROTORS));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &filter.core, sizeof(filter.core));
    TEST_ASSERT_EQUAL_MEMORY(&before.config, &filter.config, sizeof(filter.config));
    spike[2] = 0.5f * HOVER_SPEED;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_RANGE,
                          propid_push_rotor_speeds(&filter, now_us + GYRO_PERIOD_US, spike, ROTORS));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &filter.core, sizeof(filter.core));
    /* A motor twice as fast as configured (15 ms) spinning up from hover
     * towards 95 % of max_rotor_speed: exact first-order steps, accepted. */
    float speed = HOVER_SPEED;
    const float fast_step = 1.0f - expf(-2.0f / 15.0f);
    for (uint32_t k = 0; k < 30u; ++k) {
        speed += (config.max_rotor_speed * 0.95f - speed) * fast_step;
        const float ramp[ROTORS] = {speed, speed, speed, speed};
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, ramp, ROTORS));
    }
    /* Refused every 2 ms while the gap is below tau / 2 (a drop to 100 rad/s
     * is 98 % of the headroom down), accepted at 15 ms. */
    const uint64_t last_accepted = now_us;
    const float low[ROTORS] = {100.0f, 100.0f, 100.0f, 100.0f};
    for (uint32_t k = 1; k <= 7u; ++k) {
        TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_SPEED_RANGE,
                              propid_push_rotor_speeds(&filter, last_accepted + k * GYRO_PERIOD_US, low, ROTORS));
    }
    now_us = last_accepted + 15000u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, low, ROTORS));
    /* The configured motor spinning down from full speed with the command at 0. */
    const float full[ROTORS] = {0.95f * config.max_rotor_speed, 0.95f * config.max_rotor_speed,
                                0.95f * config.max_rotor_speed, 0.95f * config.max_rotor_speed};
    now_us += 15000u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, full, ROTORS));
    speed = full[0];
    for (uint32_t k = 0; k < 30u; ++k) {
        speed *= expf(-2.0f / 30.0f);
        const float ramp[ROTORS] = {speed, speed, speed, speed};
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, ramp, ROTORS));
    }
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(9u, counters.rejected[-(int)PROPID_ERR_ROTOR_SPEED_RANGE]);
}

/* The same before the gyro clock is anchored (after init, and after resync). */
static void test_esc_stamp_far_ahead_before_anchor(void)
{
    const float gyro[3] = {0.01f, -0.02f, 0.03f};
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    for (int resynced = 0; resynced < 2; ++resynced) {
        init_filter();
        if (resynced) {
            for (uint32_t k = 0; k < 20u; ++k) {
                now_us += GYRO_PERIOD_US;
                TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
            }
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, now_us + GYRO_PERIOD_US));
        }
        TEST_ASSERT_EQUAL_INT(PROPID_OK,
                              propid_push_rotor_speeds(&filter, now_us + 3600000000u, speeds, ROTORS));
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_ERR_ROTOR_STALE, propid_push_gyro(&filter, now_us, gyro));
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_gyro(&filter, now_us, gyro));
        now_us += GYRO_PERIOD_US;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, gyro));
    }
}

/* The first gyro sample after init or resync is fused at any rate within range,
 * sets the rate and does not pull the bias; the following ones are not gated. */
static void test_first_sample_fused_at_high_rate(void)
{
    for (int resynced = 0; resynced < 2; ++resynced) {
        init_filter();
        const float slow[3] = {0.0f, 0.0f, 0.0f};
        if (resynced) {
            for (uint32_t k = 0; k < 50u; ++k) {
                now_us += GYRO_PERIOD_US;
                TEST_ASSERT_EQUAL_INT(PROPID_OK, push(now_us, HOVER_SPEED, slow));
            }
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, now_us + 100000u));
            now_us += 100000u;
        }
        propid_estimate_t before;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &before));
        /* A vehicle spinning about z at 25 rad/s (rotor speeds balanced: no
         * torque, the rate is constant). */
        const float spin[3] = {0.0f, 0.0f, 25.0f};
        const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
        for (uint32_t k = 0; k < 30u; ++k) {
            now_us += GYRO_PERIOD_US;
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
            TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_gyro(&filter, now_us, spin));
            if (k == 0u) {
                propid_estimate_t first;
                TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &first));
                TEST_ASSERT_FLOAT_WITHIN(1.0e-3f, 25.0f, first.body_rate[2]);
                TEST_ASSERT_FLOAT_WITHIN(1.0e-6f, before.gyro_bias[2], first.gyro_bias[2]);
                TEST_ASSERT_TRUE(first.body_rate_std[2] < 0.1f);
            }
        }
        propid_counters_t counters;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
        TEST_ASSERT_EQUAL_UINT32(0u, counters.axis_gated[0] + counters.axis_gated[1] + counters.axis_gated[2]);
    }
}

/* Noise settings whose one step across the longest gap exceeds the variance
 * ceiling are refused, by name; so are gates below one sigma and absurd gyro
 * noise or sample rates. */
static void check_bad(const char *field)
{
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING(field, bad);
    make_config(&config);
}

static void test_config_bounds_noise_fields(void)
{
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rate_process_noise = 1.0e4f;
    check_bad("rate_process_noise");
    config.thrust_coeff_rel_walk = 1.0e3f;
    check_bad("thrust_coeff_rel_walk");
    config.drag_coeff_rel_walk = 1.0e3f;
    check_bad("drag_coeff_rel_walk");
    config.gyro_bias_walk = 1.0e3f;
    check_bad("gyro_bias_walk");
    config.gyro_noise_density = 1.0e15f;
    check_bad("gyro_noise_density");
    config.gate_sigma = 0.5f;
    check_bad("gate_sigma");
    config.gyro_sample_rate_hz = 1.0e9f;
    check_bad("gyro_sample_rate_hz");
    /* A bias prior float32 cannot hold next to the measurement noise (variance
     * above R / (64 epsilon): P indefinite after the first updates). */
    config.gyro_noise_density = 5.0e-9f;
    check_bad("gyro_bias_std0");
    config.gyro_bias_std0 = 5000.0f;
    check_bad("gyro_bias_std0");
    /* Fuzz finding: a nominal of 2e35 with a wide relative prior overflowed the
     * reported std (relative std x nominal) to Inf. */
    config.rotor[0].drag_coeff_nominal = 2.0e35f;
    check_bad("rotor.drag_coeff_nominal");
    config.rotor[1].thrust_coeff_nominal = 2.0f;
    check_bad("rotor.thrust_coeff_nominal");
    config.thrust_coeff_rel_std0 = 3.0e4f;
    check_bad("thrust_coeff_rel_std0");
    config.drag_coeff_rel_std0 = config.coeff_rel_max * 1.5f;
    check_bad("drag_coeff_rel_std0");
    /* Real-vehicle tuning stays valid (docs/design.md: 2-10 rad/s^2/sqrt(Hz)). */
    config.rate_process_noise = 10.0f;
    config.gate_sigma = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
}

/* Random-call streams of valid samples (random rates, speeds, gaps, occasional
 * outliers and resyncs) on random valid noise settings: P stays positive
 * definite after every accepted sample. */
static void test_covariance_stays_positive_definite_under_random_calls(void)
{
    rng_t rng = {2024u};
    uint32_t checks = 0u;
    uint32_t failures = 0u;
    for (uint32_t trial = 0; trial < 12u; ++trial) {
        make_config(&config);
        config.gyro_noise_density = 5.0e-4f * (0.01f + rng_range(&rng, 0.0f, 10.0f));
        config.rate_process_noise = rng_range(&rng, 0.01f, 20.0f);
        config.thrust_coeff_rel_walk = rng_range(&rng, 0.0f, 0.2f);
        config.drag_coeff_rel_walk = rng_range(&rng, 0.0f, 0.2f);
        config.gyro_bias_walk = rng_range(&rng, 0.0f, 1.0e-2f);
        config.gate_sigma = (trial % 3u == 0u) ? 0.0f : rng_range(&rng, 1.0f, 10.0f);
        init_filter();
        for (uint32_t k = 0; k < 600u; ++k) {
            now_us += 1u + (rng_next(&rng) % (2u * GYRO_PERIOD_US));
            const float scale = (rng_next(&rng) % 50u == 0u) ? 30.0f : 3.0f;
            const float gyro[3] = {rng_range(&rng, -scale, scale), rng_range(&rng, -scale, scale),
                                   rng_range(&rng, -scale, scale)};
            const float speeds[ROTORS] = {rng_range(&rng, 0.0f, 1500.0f), rng_range(&rng, 0.0f, 1500.0f),
                                          rng_range(&rng, 0.0f, 1500.0f), rng_range(&rng, 0.0f, 1500.0f)};
            const propid_status_t pushed = propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS);
            /* (a jump faster than any motor is refused: the previous speeds hold) */
            TEST_ASSERT_TRUE(pushed == PROPID_OK || pushed == PROPID_ERR_ROTOR_SPEED_RANGE);
            if (rng_next(&rng) % 500u == 0u) {
                TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_resync(&filter, now_us));
            }
            const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
            TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
            assert_sane();
            checks++;
            failures += test_cov_positive_definite(&filter) ? 0u : 1u;
        }
    }
    TEST_ASSERT_TRUE(checks > 7000u);
    TEST_ASSERT_EQUAL_UINT32(0u, failures);
}


/* Fuzz finding (tests/fuzz/corpus/regression-gyroscopic-inflation): a quad with
 * Iyy 1000x and Izz 1e-4x their defaults, rotors still, spinning at 3.4 rad/s
 * about z. The gyroscopic coupling (Ixx - Iyy) omega_x / Izz of -5e5 /s
 * inflated P_zz from 0.0026 to 7e4 (4 500 times the rate ceiling R / (64
 * epsilon) = 16.4) in one 10.8 ms prediction, correlated -0.9999 with omega_x
 * through omega_y. The gyro one pass tests each axis' S after the earlier axes'
 * terms: z's S, about 16 after the x term, passed, and the rounding of
 * ~epsilon 7e4 in the z rows left P with a negative eigenvalue. A rate
 * variance outside its bounds now sends the sample to the generic path, which
 * applies the ceilings first. The exact call sequence of the fuzz input, then
 * the same sample for a while; P tested (Cholesky in double) every time. */
static void test_covariance_definite_after_gyroscopic_rate_inflation(void)
{
    propid_config_set_inertia_diag(&config, 3.65e-3f, 0x1.d70a3ep+1f, 0x1.796b94p-21f); /* 3.68, 7.03e-7 */
    init_filter();
    const float still[ROTORS] = {0.0f, 0.0f, 0.0f, 0.0f};
    const float anchor[3] = {0x1.7e4b4p-4f, 0x1.fffffep-120f, 0x1.b33334p+1f}; /* 0.0933, ~0, 3.4 */
    const float next[3] = {0x1.7e4b4p-4f, 0x1.7e4b4p-4f, 0x1.afc964p+1f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1005281u, still, ROTORS));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_gyro(&filter, 1010201u, anchor));
    TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, 1021043u, next) >= 0);
    TEST_ASSERT_TRUE_MESSAGE(test_cov_positive_definite(&filter), "P not positive definite after the inflating step");
    uint64_t t = 1021043u;
    for (uint32_t k = 0; k < 200u; ++k) {
        t += 2000u;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t, still, ROTORS));
        TEST_ASSERT_TRUE(propid_push_gyro(&filter, t, next) >= 0);
        assert_sane();
        TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    }
}

#if PROPID_MAX_ROTORS >= 5
/* Fuzz finding (tests/fuzz/corpus/regression-rate-prior-1e10): a five-rotor
 * vehicle with one rotor's kf 1000x its nominal, a rate prior std of 1e5 rad/s
 * and a quiet gyro (R = 1.25e-6). At 4059 rad/s one prediction inflated the
 * rate variances from 0.6 to 3.9e7 with correlations of +-1 to that kf; the
 * three updates of the next sample then left P with a negative eigenvalue
 * (float32 rounding of ~epsilon 3.9e7 on every rate element, far above R).
 * The rate variance is now held below R / (64 epsilon), its prior too. The
 * exact call sequence of the fuzz input, P tested (Cholesky in double) after
 * every accepted gyro sample. */
static void test_covariance_definite_after_huge_rate_prior_and_torque(void)
{
    test_vehicle_config(&config, 5u, 0x1.33cd68p-2f, 0.7853982f);
    config.rate_std0 = 1.0e5f;
    config.gyro_noise_density = 0x1.a36e3p-15f;   /* 5e-5: a tenth of the default */
    config.rate_process_noise = 0x1.47ae16p-6f;   /* 0.02 */
    config.thrust_coeff_rel_walk = 0x1.0624dep-9f; /* 0.002 */
    config.rotor[0].thrust_coeff_nominal = 0x1.6d0918p-8f; /* 5.57e-3 */
    init_filter();
    const float still[PROPID_MAX_ROTORS] = {0.0f};
    float fast[PROPID_MAX_ROTORS] = {0.0f};
    for (uint8_t i = 0; i < 5u; ++i) {
        fast[i] = 0x1.fb67a6p+11f; /* 4059 rad/s */
    }
    const float g[3] = {1.8f, 1.8f, 1.8f};
    const float g_x[3] = {-2.12f, 1.8f, 1.8f};
    const float g_bad[3] = {-3.4f, NAN, 0.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1007801u, still, 5u));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_gyro(&filter, 1007801u, g));
    TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, 1015602u, g_x) >= 0);
    TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, 1023403u, g) >= 0);
    TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_FINITE, propid_push_gyro(&filter, 1023404u, g_bad));
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1015602u, fast, 5u));
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, 1031205u, g) >= 0);
    TEST_ASSERT_TRUE_MESSAGE(test_cov_positive_definite(&filter), "P not positive definite after the torque step");
    /* and on: the same input for a while, every accepted sample */
    uint64_t t = 1031205u;
    for (uint32_t k = 0; k < 200u; ++k) {
        t += 7801u;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t, fast, 5u));
        TEST_ASSERT_TRUE(propid_push_gyro(&filter, t, g) >= 0);
        TEST_ASSERT_TRUE(test_cov_positive_definite(&filter));
    }
}
#endif

#if PROPID_MAX_ROTORS >= 7
/* Fuzz finding (issue 10 (f), the 10^7-execution run): a seven-rotor vehicle,
 * one rotor with 1000x the nominal kf alone at 3558 rad/s, no rate process
 * noise. Its torque holds the y rate at the -68 rad/s ceiling; about the
 * intermediate axis the gyroscopic coupling (Iyy - Izz) omega_y / Ixx and
 * (Ixx - Iyy) omega_y / Izz stretches the x-z rate block every 5 ms, and with
 * nothing to hold it open the x and z rates become correlated to float32
 * resolution (smallest correlation eigenvalue 1.6e-7). The x update then cuts
 * both variances about 90 times and rounds them by a few epsilon of their
 * predicted size, which turned that eigenvalue to -5.7e-7. The rates' loading
 * (PROPID_RATE_LOADING, docs/math.md §2) keeps the gap above that rounding.
 * The exact call sequence of the fuzz input, then the same samples for a
 * while; P tested (Cholesky in double) after every accepted gyro sample. */
static void test_covariance_definite_with_rates_correlated_by_spin(void)
{
    test_vehicle_config(&config, 7u, 0x1.b6835p-5f, 0.0f); /* arm 0.0535 m */
    config.rate_process_noise = 0x1.ffp-141f;             /* ~1e-42: none */
    config.rotor[0].thrust_coeff_nominal = 0x1.6d0918p-8f; /* 5.57e-3 */
    config.rotor[0].drag_coeff_nominal = 0x1.ep-146f;      /* ~2e-44: none */
    init_filter();
    const float speeds[PROPID_MAX_ROTORS] = {0x1.bcb4b6p+11f}; /* 3558 rad/s, the others still */
    const float small = 0x1.1111p-4f;                          /* 0.0667 */
    const float samples[][3] = {
        {0x1.9999cp-3f, small, small},
        {-small, -0x1.2740dcp+1f, 0x1.55556p-2f},
        {0x1.9999cp-3f, -small, -small},
        {-small, -0x1.2fc964p+0f, -small},
        {-small, -0x1.b33334p+1f, -0x1.8f5c28p+0f},
        {-small, -small, 0x1.55556p-2f},
        {-small, -small, -0x1.47aep-5f},
        {0x1.58bf28p+0f, -0x1.b33334p+1f, -0x1.b33334p+1f},
    };
    const uint64_t times[] = {1005201u, 1006762u, 1011763u, 1014124u, 1019125u, 1024126u, 1029727u, 1029728u};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1000001u, speeds, 7u));
    uint32_t failures = 0u;
    for (uint32_t k = 0; k < sizeof times / sizeof times[0]; ++k) {
        TEST_ASSERT_TRUE(propid_push_gyro(&filter, times[k], samples[k]) >= 0);
        assert_sane();
        failures += test_cov_positive_definite(&filter) ? 0u : 1u;
    }
    TEST_ASSERT_EQUAL_FLOAT(-68.0f, filter.core.state[1]); /* the spin of the finding */
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(0u, failures, "P not positive definite while spinning");
    uint64_t t = times[7];
    for (uint32_t k = 0; k < 400u; ++k) {
        t += 5001u;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t, speeds, 7u));
        TEST_ASSERT_TRUE(propid_push_gyro(&filter, t, samples[k % 8u]) >= 0);
        assert_sane();
        failures += test_cov_positive_definite(&filter) ? 0u : 1u;
    }
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(0u, failures, "P not positive definite while spinning on");
}
#endif

/* One gyro sample, the invariants, and 1 when P is not positive definite after it. */
static uint32_t push_and_count(uint64_t time_us, const float gyro[3])
{
    TEST_ASSERT_TRUE(propid_push_gyro(&filter, time_us, gyro) >= 0);
    assert_sane();
    return test_cov_positive_definite(&filter) ? 0u : 1u;
}

/* The call sequence the fuzzer found (decoded): the rotors spin at 2434 rad/s
 * for two samples, then at 3642 rad/s while the rate jumps from 1.373 to 2.253
 * rad/s on every axis, then 400 more samples, every fifth one a jump. P must
 * stay positive definite after the prediction-only sample and afterwards. */
static void fly_spin_up_with_rate_jump(uint8_t rotor_count)
{
    float slow[PROPID_MAX_ROTORS] = {0.0f};
    float fast[PROPID_MAX_ROTORS] = {0.0f};
    for (uint8_t i = 0; i < rotor_count; ++i) {
        slow[i] = 0x1.303e5ep+11f; /* 2434 rad/s */
        fast[i] = 0x1.c7337p+11f;  /* 3642 rad/s */
    }
    const float steady[3] = {0x1.5f92c8p+0f, 0x1.5f92c8p+0f, 0x1.5f92c8p+0f}; /* 1.373 rad/s */
    const float jump[3] = {0x1.206d3cp+1f, 0x1.206d3cp+1f, 0x1.206d3cp+1f};   /* 2.253 rad/s */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1000081u, slow, rotor_count));
    uint32_t failures = push_and_count(1007162u, steady);
    failures += push_and_count(1007203u, steady);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1007242u, fast, rotor_count));
    failures += push_and_count(1014364u, jump);
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(0u, failures, "P not positive definite after the prediction");
    uint64_t t = 1014364u;
    for (uint32_t k = 0; k < 400u; ++k) {
        t += 7161u;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, t, fast, rotor_count));
        failures += push_and_count(t, (k % 5u) == 4u ? jump : steady);
    }
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(0u, failures, "P not positive definite later");
}

/* The quad kernel's share of the general-path findings below (docs/math.md
 * §2, "The rate block's loading"): a quad whose four rotors lie on one diagonal line (arms
 * 0.204 m and 0.102 m, both sides) has roll and pitch torques that measure one
 * and the same kf combination, like the two-rotor input below. With a gyro
 * variance 250x below the default (a sample rate configured as 2 Hz, samples
 * every 7 ms) the first updates pin that combination, and the next
 * prediction forms the rate variances from terms far larger than the result.
 * The quad kernel's loading relative to the result (1 + 8 eps) left P after
 * the prediction-only sample (all axes gated) not positive definite (smallest
 * pivot of the correlation matrix's Cholesky factor -2.0e-4, host build);
 * loaded relative to the rounding scale 7 (P_aa + sum_p G_ap^2 P_pp) it is
 * +2.1e-4. Runs on every build: the quad layout takes the generated kernel in
 * each. */

static void test_covariance_definite_with_quad_rates_predicted_from_cancelling_terms(void)
{
    test_vehicle_config(&config, 4u, 0.05f + 0.3f * 131.0f / 255.0f, 0.0f);
    const float c = (0.05f + 0.3f * 131.0f / 255.0f) * 0.70710677f;
    const float on_the_line[4] = {c, -c, 0.5f * c, -0.5f * c}; /* x = y for every rotor */
    for (uint8_t i = 0; i < 4u; ++i) {
        config.rotor[i].position_m[0] = on_the_line[i];
        config.rotor[i].position_m[1] = on_the_line[i];
    }
    config.gyro_sample_rate_hz = 2.0f;
    config.rate_process_noise = 0x1.a36e3p-13f; /* 2e-4 */
    config.gate_max_consecutive = 33667u;
    config.rotor_stale_us = 2206416519u;
    init_filter();
    TEST_ASSERT_EQUAL_UINT8(1u, filter.derived.quad_layout);
    fly_spin_up_with_rate_jump(4u);
}

#if PROPID_GENERAL_VEHICLES
/* Fuzz findings of the 10^7-execution run on the general path (two rotors):
 * the prediction forms each rate variance as a sum of terms (|F| |P| |F|^T)_aa
 * far larger than the result when the rotor coefficients' block is nearly
 * singular, and its rounding is relative to those terms.
 *
 * Two rotors on a diagonal, gyro_sample_rate_hz 0.5 with samples every 7 ms (a
 * gyro noise variance 1000x below the default): the roll torque measures
 * kf0 - kf1, the rate variance is predicted as 0.013 from terms of 41 (dt G =
 * +-15 per unit kf_rel), whose rounding (~eps 41) exceeds the rate's conditional
 * variance given the bias: smallest correlation eigenvalue -3.6e-5 before the
 * rates were loaded relative to their terms. */
static void test_covariance_definite_with_rate_predicted_from_cancelling_terms(void)
{
    test_vehicle_config(&config, 2u, 0.05f + 0.3f * 131.0f / 255.0f, 0.7853982f);
    config.gyro_sample_rate_hz = 0.5f;
    config.rate_process_noise = 0x1.a36e3p-13f; /* 2e-4 */
    config.gate_max_consecutive = 33667u;
    config.rotor_stale_us = 2206416519u;
    init_filter();
    fly_spin_up_with_rate_jump(2u);
}

/* Two rotors, rotor 0's km 1000x its nominal, no drag coefficient walk: rotor
 * 0 alone at 3558 rad/s makes the yaw update measure km_0 (not the yaw basis'
 * z_0: z_0 - z_1), cutting it from 2e-5 to ~1e-10 against drag-block elements
 * of 0.045 (rounding ~eps 0.045): smallest correlation eigenvalue -3.6e-9.
 * The yaw rate's loading relative to its terms (dt G_z,km sigma_km, not the
 * cut combination's) keeps that cut above the rounding. */
static void test_covariance_definite_with_one_drag_coefficient_measured_alone(void)
{
    test_vehicle_config(&config, 2u, 0.05f + 0.3f * 3.0f / 255.0f, 0.0f);
    config.rate_process_noise = 0x1.99999ap-3f;      /* 0.2 */
    config.drag_coeff_rel_walk = 0x1p-149f;          /* none */
    config.gyro_range *= 0.1f;
    config.rotor[0].drag_coeff_nominal = 0x1.1d3672p-13f; /* 1.36e-4 */
    init_filter();
    const float still[PROPID_MAX_ROTORS] = {0.0f};
    const float one[PROPID_MAX_ROTORS] = {0x1.bcb4b6p+11f}; /* 3558 rad/s, rotor 1 still */
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1006481u, still, 2u));
    const float g0[3] = {0x1.78d5p-4f, 0x1.78d5p-4f, 0x1.78d5p-4f};
    uint32_t failures = push_and_count(1000001u, g0);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1011522u, one, 2u));
    const float g1[3] = {0x1.47ae2p-6f, -0x1.b4e8p-8f, -0x1.b4e8p-8f};
    failures += push_and_count(1000042u, g1);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, 1018763u, still, 2u));
    const float g2[3] = {-0x1.0625p-8f, 0x1.11112p-5f, -0x1.5c28f6p-2f};
    failures += push_and_count(1007163u, g2);
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(0u, failures, "P not positive definite after the yaw update");
}
#endif

/* The round-robin integrity check of the row it visits finds a fault in any of
 * the row's elements (every element of the stored triangle: an over-correlated
 * off-diagonal element, 0.1 % beyond a correlation of 1, or a NaN; a negative
 * or NaN diagonal) and repairs P in that prediction; a sound row is left alone.
 * The quad build's check is straight-line code per column on the Cortex-M4
 * (propid_predict.c, quad_row_bad): one column it skipped fails this. */
static void check_row_fault_found(uint8_t row, uint8_t column, float value)
{
    init_filter();
    filter.core.cov[propid_cov_index(row, column)] = value;
    filter.core.check_row = row;
    const uint32_t repairs = filter.counters.cov_repairs;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_step(&filter, 0.002f));
    char message[48];
    snprintf(message, sizeof(message), "fault at (%u, %u) not found", (unsigned)row, (unsigned)column);
    TEST_ASSERT_EQUAL_UINT32_MESSAGE(repairs + 1u, filter.counters.cov_repairs, message);
    TEST_ASSERT_TRUE((filter.core.health & PROPID_HEALTH_COV_REPAIRED) != 0u);
}

static void test_row_check_finds_a_fault_in_every_element(void)
{
    init_filter();
    const uint8_t n = filter.derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        /* Sound: no repair. */
        init_filter();
        filter.core.check_row = i;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_predict_step(&filter, 0.002f));
        TEST_ASSERT_EQUAL_UINT32(0u, filter.counters.cov_repairs);
        for (uint8_t j = i; j < n; ++j) {
            init_filter();
            const float pii = filter.core.cov[propid_cov_index(i, i)];
            const float pjj = filter.core.cov[propid_cov_index(j, j)];
            if (i == j) {
                check_row_fault_found(i, j, -pii);
            } else {
                check_row_fault_found(i, j, 1.001f * sqrtf(pii * pjj));
                check_row_fault_found(i, j, -1.001f * sqrtf(pii * pjj));
            }
            check_row_fault_found(i, j, NAN);
        }
    }
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_gated_rate_stays_bounded_and_recovers);
    RUN_TEST(test_resync_resets_runaway_rate);
    RUN_TEST(test_gate_off_never_writes_non_finite);
    RUN_TEST(test_esc_stamp_far_ahead_does_not_freeze_input);
    RUN_TEST(test_esc_stamp_far_ahead_before_anchor);
    RUN_TEST(test_esc_outage_turns_stale_into_time_jump);
    RUN_TEST(test_esc_spike_within_range_refused);
    RUN_TEST(test_first_sample_fused_at_high_rate);
    RUN_TEST(test_config_bounds_noise_fields);
    RUN_TEST(test_row_check_finds_a_fault_in_every_element);
    RUN_TEST(test_covariance_stays_positive_definite_under_random_calls);
    RUN_TEST(test_covariance_definite_after_gyroscopic_rate_inflation);
#if PROPID_MAX_ROTORS >= 5
    RUN_TEST(test_covariance_definite_after_huge_rate_prior_and_torque);
#endif
#if PROPID_MAX_ROTORS >= 7
    RUN_TEST(test_covariance_definite_with_rates_correlated_by_spin);
#endif
    RUN_TEST(test_covariance_definite_with_quad_rates_predicted_from_cancelling_terms);
#if PROPID_GENERAL_VEHICLES
    RUN_TEST(test_covariance_definite_with_rate_predicted_from_cancelling_terms);
    RUN_TEST(test_covariance_definite_with_one_drag_coefficient_measured_alone);
#endif
    return UNITY_END();
}
