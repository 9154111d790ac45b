/*
 * Rejection paths of the public API (propid.h): every bad input gets its own
 * status code, leaves config, derived quantities and core state bit-for-bit
 * unchanged, and moves exactly one counter, counters.rejected[-status] (the kept slot PROPID_REJECT_SLOT(status)).
 * The filter is "warm" (has run steps) so an accidental write would show.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "propid/propid.h"
#include "unity.h"
#include "test_vehicle.h"

#define ROTORS 4u
#define GYRO_PERIOD_US 2000u
#define HOVER_SPEED 470.0f

/* static: keep the test's stack small on the MCU */
static propid_config_t config;
static propid_filter_t filter;
static propid_filter_t before;
static uint64_t now_us;

static float nan_value(void)
{
    volatile float zero = 0.0f;
    return zero / zero;
}

static float inf_value(void)
{
    volatile float huge = 3.0e38f;
    return huge * 10.0f;
}

static void make_config(propid_config_t *out)
{
    test_vehicle_config(out, ROTORS, 0.17f, 0.7853982f);
}

static void push_rotors_ok(uint64_t time_us, float speed)
{
    const float speeds[ROTORS] = {speed, speed * 1.01f, speed * 0.99f, speed * 1.02f};
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, time_us, speeds, ROTORS));
}

static void push_gyro_ok(uint64_t time_us)
{
    const float gyro[3] = {0.01f, -0.02f, 0.03f};
    const propid_status_t status = propid_push_gyro(&filter, time_us, gyro);
    TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
}

/* A filter that has run: non-trivial state, covariance, times and counters. */
static void warm_up(void)
{
    make_config(&config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    now_us = 1000000u;
    for (uint32_t k = 0; k < 50u; ++k) {
        now_us += GYRO_PERIOD_US;
        push_rotors_ok(now_us, HOVER_SPEED + (float)k);
        push_gyro_ok(now_us);
    }
}

void setUp(void)
{
    warm_up();
    before = filter;
}

void tearDown(void)
{
}

/* The heart of every test: status as expected, state untouched, one counter up. */
static void assert_rejected(propid_status_t expected, propid_status_t got)
{
    TEST_ASSERT_TRUE(expected < 0);
    TEST_ASSERT_EQUAL_STRING(propid_status_name(expected), propid_status_name(got));
    TEST_ASSERT_EQUAL_MEMORY(&before.config, &filter.config, sizeof(filter.config));
    TEST_ASSERT_EQUAL_MEMORY(&before.derived, &filter.derived, sizeof(filter.derived));
    TEST_ASSERT_EQUAL_MEMORY(&before.core, &filter.core, sizeof(filter.core));
    TEST_ASSERT_EQUAL_UINT32(before.magic, filter.magic);
    propid_kept_counters_t expected_counters = before.counters; /* (the quad build keeps fewer) */
    expected_counters.rejected[PROPID_REJECT_SLOT(expected)]++;
    TEST_ASSERT_EQUAL_MEMORY(&expected_counters, &filter.counters, sizeof(filter.counters));
    /* ... and the public view agrees. */
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    TEST_ASSERT_EQUAL_UINT32(before.counters.rejected[PROPID_REJECT_SLOT(expected)] + 1u,
                             counters.rejected[-(int)expected]);
    before = filter; /* next rejection in the same test starts from here */
}

/* After any rejection a good sample must still be accepted (nothing wedged). */
static void assert_still_accepts(void)
{
    now_us += GYRO_PERIOD_US;
    push_rotors_ok(now_us, HOVER_SPEED);
    push_gyro_ok(now_us);
}

/* ---- NULL pointers -------------------------------------------------------- */

static void test_null_filter_pointers(void)
{
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    propid_estimate_t estimate;
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_init(NULL, &config));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_reset(NULL));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_reset_rotor(NULL, 0u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_resync(NULL, now_us));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_push_rotor_speeds(NULL, now_us, speeds, ROTORS));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_push_gyro(NULL, now_us, gyro));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_get_estimate(NULL, &estimate));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_get_counters(NULL, &counters));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_config_check(NULL, NULL));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL,
                          propid_config_set_symmetric(NULL, ROTORS, 0.17f, 0.0f, 1.0f, 1e-6f, 1e-8f));
    /* The void helpers must tolerate NULL too. */
    propid_config_default(NULL);
    propid_config_set_inertia_diag(NULL, 1.0f, 1.0f, 1.0f);
    /* The warm filter was not involved. */
    TEST_ASSERT_EQUAL_MEMORY(&before, &filter, sizeof(filter));
}

static void test_null_data_pointers(void)
{
    now_us += GYRO_PERIOD_US;
    assert_rejected(PROPID_ERR_NULL, propid_push_rotor_speeds(&filter, now_us, NULL, ROTORS));
    assert_rejected(PROPID_ERR_NULL, propid_push_gyro(&filter, now_us, NULL));
    assert_rejected(PROPID_ERR_NULL, propid_init(&filter, NULL));
    /* The readers take a const filter: NULL output is refused and nothing moves. */
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_get_estimate(&filter, NULL));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NULL, propid_get_counters(&filter, NULL));
    TEST_ASSERT_EQUAL_MEMORY(&before, &filter, sizeof(filter));
    assert_still_accepts();
}

/* ---- not initialised ------------------------------------------------------ */

static void check_not_initialised(uint8_t fill)
{
    static propid_filter_t fresh;
    static propid_filter_t fresh_before;
    memset(&fresh, fill, sizeof(fresh));
    fresh_before = fresh;
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    propid_estimate_t estimate;
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_reset(&fresh));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_reset_rotor(&fresh, 0u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_resync(&fresh, 1000u));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED,
                          propid_push_rotor_speeds(&fresh, 1000u, speeds, ROTORS));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_push_gyro(&fresh, 1000u, gyro));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_get_estimate(&fresh, &estimate));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_get_counters(&fresh, &counters));
    /* Nothing of an uninitialised object is trusted, so nothing is written. */
    TEST_ASSERT_EQUAL_MEMORY(&fresh_before, &fresh, sizeof(fresh));
}

static void test_not_initialised_zeroed(void)
{
    check_not_initialised(0x00u);
}

static void test_not_initialised_garbage(void)
{
    check_not_initialised(0xA5u);
}

static void test_failed_init_leaves_uninitialised(void)
{
    static propid_filter_t fresh;
    memset(&fresh, 0, sizeof(fresh));
    propid_config_t bad = config;
    bad.rotor_count = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_init(&fresh, &bad));
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_NOT_INITIALISED, propid_push_gyro(&fresh, 1000u, gyro));
}

/* ---- configuration, one bad field at a time ------------------------------- */

typedef void (*config_breaker_t)(propid_config_t *bad);

static void check_bad_config_named(config_breaker_t breaker, const char *case_name,
                                   const char *field)
{
    propid_config_t bad = config;
    breaker(&bad);
    const char *bad_field = NULL;
    TEST_ASSERT_EQUAL_INT_MESSAGE(PROPID_ERR_CONFIG, propid_config_check(&bad, &bad_field), case_name);
    TEST_ASSERT_NOT_NULL_MESSAGE(bad_field, case_name);
    TEST_ASSERT_NOT_NULL_MESSAGE(strstr(bad_field, field), bad_field);
    TEST_ASSERT_EQUAL_INT_MESSAGE(PROPID_ERR_CONFIG, propid_config_check(&bad, NULL), case_name);
    /* Re-initialising a running filter with it is refused; the filter runs on. */
    assert_rejected(PROPID_ERR_CONFIG, propid_init(&filter, &bad));
}

#define check_bad_config(breaker, field) check_bad_config_named(breaker, #breaker, field)

#define BREAK(name, statement)                                                                     \
    static void name(propid_config_t *bad)                                                         \
    {                                                                                              \
        statement;                                                                                 \
    }
BREAK(no_rotors, bad->rotor_count = 0u)
BREAK(too_many_rotors, bad->rotor_count = PROPID_MAX_ROTORS + 1u)
BREAK(position_nan, bad->rotor[2].position_m[1] = nan_value())
BREAK(position_inf, bad->rotor[0].position_m[0] = inf_value())
BREAK(yaw_sign_zero, bad->rotor[1].yaw_sign = 0.0f)
BREAK(yaw_sign_half, bad->rotor[3].yaw_sign = 0.5f)
BREAK(thrust_nominal_zero, bad->rotor[0].thrust_coeff_nominal = 0.0f)
BREAK(thrust_nominal_negative, bad->rotor[3].thrust_coeff_nominal = -5.57e-6f)
BREAK(thrust_nominal_nan, bad->rotor[1].thrust_coeff_nominal = nan_value())
BREAK(drag_nominal_zero, bad->rotor[2].drag_coeff_nominal = 0.0f)
BREAK(drag_nominal_inf, bad->rotor[0].drag_coeff_nominal = inf_value())
BREAK(inertia_negative, bad->inertia[1][1] = -3.68e-3f)
BREAK(inertia_zero, bad->inertia[2][2] = 0.0f)
BREAK(inertia_asymmetric, bad->inertia[0][1] = 1.0e-3f)
BREAK(inertia_nan, bad->inertia[0][0] = nan_value())
BREAK(inertia_singular, {
    bad->inertia[0][0] = 1.0e-3f; bad->inertia[1][1] = 1.0e-3f;
    bad->inertia[0][1] = 1.0e-3f; bad->inertia[1][0] = 1.0e-3f;
})
BREAK(rate_std0_zero, bad->rate_std0 = 0.0f)
BREAK(thrust_std0_negative, bad->thrust_coeff_rel_std0 = -0.1f)
BREAK(drag_std0_nan, bad->drag_coeff_rel_std0 = nan_value())
BREAK(bias_std0_zero, bad->gyro_bias_std0 = 0.0f)
BREAK(noise_density_zero, bad->gyro_noise_density = 0.0f)
BREAK(sample_rate_zero, bad->gyro_sample_rate_hz = 0.0f)
BREAK(process_noise_negative, bad->rate_process_noise = -1.0f)
BREAK(thrust_walk_negative, bad->thrust_coeff_rel_walk = -0.01f)
BREAK(drag_walk_nan, bad->drag_coeff_rel_walk = nan_value())
BREAK(bias_walk_inf, bad->gyro_bias_walk = inf_value())
BREAK(gate_nan, bad->gate_sigma = nan_value())
BREAK(gate_run_zero, bad->gate_max_consecutive = 0u)
BREAK(max_speed_zero, bad->max_rotor_speed = 0.0f)
BREAK(max_speed_nan, bad->max_rotor_speed = nan_value())
BREAK(gyro_range_negative, bad->gyro_range = -1.0f)
BREAK(stale_zero, bad->rotor_stale_us = 0u)
BREAK(gap_zero, bad->max_gyro_gap_us = 0u)
BREAK(clamp_min_zero, bad->coeff_rel_min = 0.0f)
BREAK(clamp_min_above_one, bad->coeff_rel_min = 1.5f)
BREAK(clamp_max_below_one, bad->coeff_rel_max = 0.5f)
BREAK(converged_zero, bad->converged_rel_std = 0.0f)
BREAK(inertia_std_negative, bad->inertia_rel_std = -0.1f)
BREAK(inertia_std_nan, bad->inertia_rel_std = NAN)
BREAK(inertia_std_above_one, bad->inertia_rel_std = 1.5f)
BREAK(motor_tau_zero, bad->motor_time_constant = 0.0f)
BREAK(motor_tau_nan, bad->motor_time_constant = NAN)
BREAK(motor_tau_above_range, bad->motor_time_constant = 7.0f)
#undef BREAK

static void test_bad_config_rotors(void)
{
    check_bad_config(no_rotors, "rotor_count");
    check_bad_config(too_many_rotors, "rotor_count");
    check_bad_config(position_nan, "position_m");
    check_bad_config(position_inf, "position_m");
    check_bad_config(yaw_sign_zero, "yaw_sign");
    check_bad_config(yaw_sign_half, "yaw_sign");
    check_bad_config(thrust_nominal_zero, "thrust_coeff_nominal");
    check_bad_config(thrust_nominal_negative, "thrust_coeff_nominal");
    check_bad_config(thrust_nominal_nan, "thrust_coeff_nominal");
    check_bad_config(drag_nominal_zero, "drag_coeff_nominal");
    check_bad_config(drag_nominal_inf, "drag_coeff_nominal");
    assert_still_accepts();
}

static void test_bad_config_inertia(void)
{
    check_bad_config(inertia_negative, "inertia");
    check_bad_config(inertia_zero, "inertia");
    check_bad_config(inertia_asymmetric, "inertia");
    check_bad_config(inertia_nan, "inertia");
    check_bad_config(inertia_singular, "inertia");
    assert_still_accepts();
}

static void test_bad_config_priors_and_noise(void)
{
    check_bad_config(rate_std0_zero, "rate_std0");
    check_bad_config(thrust_std0_negative, "thrust_coeff_rel_std0");
    check_bad_config(drag_std0_nan, "drag_coeff_rel_std0");
    check_bad_config(bias_std0_zero, "gyro_bias_std0");
    check_bad_config(noise_density_zero, "gyro_noise_density");
    check_bad_config(sample_rate_zero, "gyro_sample_rate_hz");
    check_bad_config(process_noise_negative, "rate_process_noise");
    check_bad_config(thrust_walk_negative, "thrust_coeff_rel_walk");
    check_bad_config(drag_walk_nan, "drag_coeff_rel_walk");
    check_bad_config(bias_walk_inf, "gyro_bias_walk");
    assert_still_accepts();
}

static void test_bad_config_guards(void)
{
    check_bad_config(gate_nan, "gate_sigma");
    check_bad_config(gate_run_zero, "gate_max_consecutive");
    check_bad_config(max_speed_zero, "max_rotor_speed");
    check_bad_config(max_speed_nan, "max_rotor_speed");
    check_bad_config(gyro_range_negative, "gyro_range");
    check_bad_config(stale_zero, "rotor_stale_us");
    check_bad_config(gap_zero, "max_gyro_gap_us");
    check_bad_config(clamp_min_zero, "coeff_rel_min");
    check_bad_config(clamp_min_above_one, "coeff_rel_min");
    check_bad_config(clamp_max_below_one, "coeff_rel_max");
    check_bad_config(converged_zero, "converged_rel_std");
    check_bad_config(inertia_std_negative, "inertia_rel_std");
    check_bad_config(inertia_std_nan, "inertia_rel_std");
    check_bad_config(inertia_std_above_one, "inertia_rel_std");
    check_bad_config(motor_tau_zero, "motor_time_constant");
    check_bad_config(motor_tau_nan, "motor_time_constant");
    check_bad_config(motor_tau_above_range, "motor_time_constant");
    assert_still_accepts();
}

static void test_good_config_passes_check(void)
{
    const char *bad_field = "untouched";
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad_field));
    /* Gating off (gate_sigma <= 0) is a documented, valid choice. */
    propid_config_t no_gate = config;
    no_gate.gate_sigma = 0.0f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&no_gate, NULL));
}

static void test_set_symmetric_rejects_bad_arguments(void)
{
    propid_config_t target = config;
    const propid_config_t unchanged = config;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 0u, 0.17f, 0.0f, 1.0f, 5e-6f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_set_symmetric(&target, PROPID_MAX_ROTORS + 1u,
                                                                         0.17f, 0.0f, 1.0f, 5e-6f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 4u, 0.0f, 0.0f, 1.0f, 5e-6f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 4u, nan_value(), 0.0f, 1.0f, 5e-6f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 4u, 0.17f, 0.0f, 0.5f, 5e-6f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 4u, 0.17f, 0.0f, 1.0f, 0.0f, 1e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG,
                          propid_config_set_symmetric(&target, 4u, 0.17f, 0.0f, 1.0f, 5e-6f, -1e-7f));
    TEST_ASSERT_EQUAL_MEMORY(&unchanged, &target, sizeof(target));
}

/* ---- rotor speeds --------------------------------------------------------- */

static void test_rotor_speed_not_finite(void)
{
    float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    now_us += GYRO_PERIOD_US;
    speeds[2] = nan_value();
    assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    speeds[2] = inf_value();
    assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    speeds[2] = -inf_value();
    assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    speeds[2] = HOVER_SPEED;
    speeds[3] = nan_value();
    assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    assert_still_accepts();
}

static void test_rotor_speed_negative(void)
{
    float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    now_us += GYRO_PERIOD_US;
    speeds[0] = -1.0f;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_NEGATIVE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    speeds[0] = HOVER_SPEED;
    speeds[3] = -1.0e-3f;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_NEGATIVE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    assert_still_accepts();
}

static void test_rotor_speed_absurd(void)
{
    float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    now_us += GYRO_PERIOD_US;
    speeds[1] = config.max_rotor_speed * 1.001f;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_RANGE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    speeds[1] = 1.0e30f;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_RANGE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    /* The limit itself is still a speed (reached from hover in the 10 ms a
     * motor needs at least for a whole sweep; faster is refused too). */
    speeds[1] = config.max_rotor_speed;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_RANGE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    now_us += 10000u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
}

static void test_rotor_count_wrong(void)
{
    float speeds[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        speeds[i] = HOVER_SPEED;
    }
    now_us += GYRO_PERIOD_US;
    assert_rejected(PROPID_ERR_ROTOR_COUNT, propid_push_rotor_speeds(&filter, now_us, speeds, 0u));
    assert_rejected(PROPID_ERR_ROTOR_COUNT, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS - 1u));
    assert_rejected(PROPID_ERR_ROTOR_COUNT, propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS + 1u));
    assert_rejected(PROPID_ERR_ROTOR_COUNT, propid_push_rotor_speeds(&filter, now_us, speeds, 255u));
    assert_still_accepts();
}

static void test_rotor_time_backwards(void)
{
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    const uint64_t last = filter.core.rotor_time_us;
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_rotor_speeds(&filter, last - 1u, speeds, ROTORS));
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_rotor_speeds(&filter, 0u, speeds, ROTORS));
    assert_still_accepts();
}

static void test_rotor_time_equal(void)
{
    /* "timestamp not after the previous one of its stream" (propid.h) */
    const float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    assert_rejected(PROPID_ERR_TIME_BACKWARDS,
                    propid_push_rotor_speeds(&filter, filter.core.rotor_time_us, speeds, ROTORS));
    assert_still_accepts();
}

/* ---- gyro ------------------------------------------------------------------ */

static void test_gyro_not_finite(void)
{
    now_us += GYRO_PERIOD_US;
    push_rotors_ok(now_us, HOVER_SPEED);
    before = filter;
    for (uint8_t axis = 0; axis < 3u; ++axis) {
        float gyro[3] = {0.0f, 0.0f, 0.0f};
        gyro[axis] = nan_value();
        assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_gyro(&filter, now_us, gyro));
        gyro[axis] = inf_value();
        assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_gyro(&filter, now_us, gyro));
        gyro[axis] = -inf_value();
        assert_rejected(PROPID_ERR_NOT_FINITE, propid_push_gyro(&filter, now_us, gyro));
    }
    push_gyro_ok(now_us);
}

static void test_gyro_beyond_range(void)
{
    now_us += GYRO_PERIOD_US;
    push_rotors_ok(now_us, HOVER_SPEED);
    before = filter;
    for (uint8_t axis = 0; axis < 3u; ++axis) {
        float gyro[3] = {0.0f, 0.0f, 0.0f};
        gyro[axis] = config.gyro_range * 1.01f;
        assert_rejected(PROPID_ERR_GYRO_RANGE, propid_push_gyro(&filter, now_us, gyro));
        gyro[axis] = -config.gyro_range * 1.01f;
        assert_rejected(PROPID_ERR_GYRO_RANGE, propid_push_gyro(&filter, now_us, gyro));
    }
    push_gyro_ok(now_us);
}

static void test_gyro_time_backwards(void)
{
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_gyro(&filter, now_us - 1u, gyro));
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_gyro(&filter, 0u, gyro));
    assert_still_accepts();
}

static void test_gyro_time_equal(void)
{
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_gyro(&filter, now_us, gyro));
    assert_still_accepts();
}

static void test_gyro_time_jump(void)
{
    const uint64_t jump = now_us + (uint64_t)config.max_gyro_gap_us + 1u;
    push_rotors_ok(jump, HOVER_SPEED);
    before = filter;
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    assert_rejected(PROPID_ERR_TIME_JUMP, propid_push_gyro(&filter, jump, gyro));
    /* A huge jump (uint64 far future) too. */
    assert_rejected(PROPID_ERR_TIME_JUMP, propid_push_gyro(&filter, UINT64_MAX, gyro));
    /* Exactly the limit is not a jump. */
    const uint64_t limit = now_us + (uint64_t)config.max_gyro_gap_us;
    const propid_status_t status = propid_push_gyro(&filter, limit, gyro);
    TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
}

static void test_gyro_without_rotor_data(void)
{
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&filter, &config));
    before = filter;
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    assert_rejected(PROPID_ERR_NO_ROTOR_DATA, propid_push_gyro(&filter, 1000u, gyro));
    assert_rejected(PROPID_ERR_NO_ROTOR_DATA, propid_push_gyro(&filter, 3000u, gyro));
    propid_estimate_t estimate;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&filter, &estimate));
    TEST_ASSERT_BITS_HIGH(PROPID_HEALTH_NO_ROTOR_DATA, estimate.health);
}

static void test_gyro_with_stale_rotor_data(void)
{
    /* ESC telemetry stops while the gyro goes on: accepted while the latest rotor
     * speeds are young enough, rejected as stale from the first sample past the limit. */
    const uint64_t rotor_time = filter.core.rotor_time_us;
    const float gyro[3] = {0.01f, 0.0f, -0.01f};
    uint32_t accepted = 0u;
    for (uint32_t k = 0; k < 1000u; ++k) {
        now_us += GYRO_PERIOD_US;
        if (now_us - rotor_time <= (uint64_t)config.rotor_stale_us) {
            const propid_status_t status = propid_push_gyro(&filter, now_us, gyro);
            TEST_ASSERT_TRUE_MESSAGE(status >= 0, propid_status_name(status));
            ++accepted;
            continue;
        }
        before = filter;
        assert_rejected(PROPID_ERR_ROTOR_STALE, propid_push_gyro(&filter, now_us, gyro));
        break;
    }
    TEST_ASSERT_TRUE(accepted > 0u);
    TEST_ASSERT_TRUE_MESSAGE(now_us - rotor_time > (uint64_t)config.rotor_stale_us, "never stale");
    /* Fresh rotor data heals it. */
    push_rotors_ok(now_us, HOVER_SPEED);
    push_gyro_ok(now_us);
}

static void test_reset_rotor_index_out_of_range(void)
{
    assert_rejected(PROPID_ERR_ROTOR_INDEX, propid_reset_rotor(&filter, ROTORS));
    assert_rejected(PROPID_ERR_ROTOR_INDEX, propid_reset_rotor(&filter, PROPID_MAX_ROTORS));
    assert_rejected(PROPID_ERR_ROTOR_INDEX, propid_reset_rotor(&filter, 255u));
    assert_still_accepts();
}

/* Every rejection slot used above must be distinct: a mixed run counts each once. */
static void test_counters_separate_reasons(void)
{
    const float gyro[3] = {0.0f, 0.0f, 0.0f};
    float speeds[ROTORS] = {HOVER_SPEED, HOVER_SPEED, HOVER_SPEED, HOVER_SPEED};
    now_us += GYRO_PERIOD_US;
    assert_rejected(PROPID_ERR_ROTOR_COUNT, propid_push_rotor_speeds(&filter, now_us, speeds, 3u));
    speeds[0] = -5.0f;
    assert_rejected(PROPID_ERR_ROTOR_SPEED_NEGATIVE,
                    propid_push_rotor_speeds(&filter, now_us, speeds, ROTORS));
    assert_rejected(PROPID_ERR_TIME_BACKWARDS, propid_push_gyro(&filter, 1u, gyro));
    assert_rejected(PROPID_ERR_ROTOR_INDEX, propid_reset_rotor(&filter, 9u));
    propid_counters_t counters;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_counters(&filter, &counters));
    uint32_t total = 0u;
    for (uint32_t slot = 0; slot < PROPID_REJECT_SLOTS; ++slot) {
        total += counters.rejected[slot];
    }
    TEST_ASSERT_EQUAL_UINT32(4u, total);
    TEST_ASSERT_EQUAL_UINT32(0u, counters.rejected[0]);
}

/* ---- Features compiled out (the quad build, propid_config.h) -------------- */

/* A configuration asking for a compiled-out term is rejected by name, and the
 * compiled-out call rejects like a missing configuration. */
static void test_compiled_out_features_rejected(void)
{
    int checked = 0;
    const char *bad = NULL;
    propid_config_t asked;
#if !PROPID_WITH_ACCEL
    make_config(&asked);
    asked.mass = 0.03f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_STRING("mass", bad);
    const float specific_force[3] = {0.0f, 0.0f, 9.81f};
    assert_rejected(PROPID_ERR_CONFIG, propid_push_accel(&filter, now_us + 1u, specific_force));
    checked++;
#endif
#if !PROPID_WITH_DISTURBANCE
    make_config(&asked);
    asked.disturbance_torque = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_STRING("disturbance_torque", bad);
    checked++;
#endif
#if !PROPID_WITH_ROTOR_INERTIA
    make_config(&asked);
    asked.rotor_inertia[1] = 1.0e-6f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_inertia", bad);
    checked++;
#endif
#if !PROPID_GENERAL_VEHICLES
    /* Without the general path only the quad layout runs: another rotor count,
     * or an inertia whose products couple the axes, is a configuration error
     * (and a good quad still passes). */
    make_config(&asked);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_INT(PROPID_OK,
                          propid_config_set_symmetric(&asked, 3u, 0.17f, 0.0f, 1.0f, 5.57e-6f, 1.36e-7f));
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_count", bad);
    make_config(&asked);
    asked.inertia[0][1] = 1.0e-4f;
    asked.inertia[1][0] = 1.0e-4f;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&asked, &bad));
    TEST_ASSERT_EQUAL_STRING("inertia", bad);
    checked++;
#endif
    (void)bad;
    (void)asked;
    if (checked == 0) {
        TEST_IGNORE_MESSAGE("every optional feature is compiled in");
    }
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_null_filter_pointers);
    RUN_TEST(test_null_data_pointers);
    RUN_TEST(test_not_initialised_zeroed);
    RUN_TEST(test_not_initialised_garbage);
    RUN_TEST(test_failed_init_leaves_uninitialised);
    RUN_TEST(test_good_config_passes_check);
    RUN_TEST(test_bad_config_rotors);
    RUN_TEST(test_bad_config_inertia);
    RUN_TEST(test_bad_config_priors_and_noise);
    RUN_TEST(test_bad_config_guards);
    RUN_TEST(test_set_symmetric_rejects_bad_arguments);
    RUN_TEST(test_rotor_speed_not_finite);
    RUN_TEST(test_rotor_speed_negative);
    RUN_TEST(test_rotor_speed_absurd);
    RUN_TEST(test_rotor_count_wrong);
    RUN_TEST(test_rotor_time_backwards);
    RUN_TEST(test_rotor_time_equal);
    RUN_TEST(test_gyro_not_finite);
    RUN_TEST(test_gyro_beyond_range);
    RUN_TEST(test_gyro_time_backwards);
    RUN_TEST(test_gyro_time_equal);
    RUN_TEST(test_gyro_time_jump);
    RUN_TEST(test_gyro_without_rotor_data);
    RUN_TEST(test_gyro_with_stale_rotor_data);
    RUN_TEST(test_reset_rotor_index_out_of_range);
    RUN_TEST(test_counters_separate_reasons);
    RUN_TEST(test_compiled_out_features_rejected);
    return UNITY_END();
}
