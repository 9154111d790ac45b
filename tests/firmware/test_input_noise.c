/*
 * Rotor-speed input error in the prediction (config.rotor_speed_noise,
 * docs/math.md §14):
 * - off (0) the covariance prediction is bit-identical to the plain one;
 * - on, it adds exactly B Sigma_u B^T dt max(dt, time) to the rate block and
 *   nothing elsewhere, B computed here densely from the model's Jacobian at the
 *   current coefficients (quad layout, general lists, hexa);
 * - with rotor_speed_noise_hold, the span per rotor from how long its value
 *   has stood (dt + 2 age, a change renews it, the configured time its ceiling;
 *   with hold = 2 its floor);
 * - rotor_speed_noise_split adds the rank-one block of the truncation's mean, common to
 *   every rotor, to its spread's;
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
static propid_filter_t with_noise;
static propid_filter_t without_noise;

/* The rate block's expected increment `expected[a][b]` against what `with` added over
 * `plain`; everything outside the rate block bit for bit. */
static void check_rate_block_added(const propid_filter_t *with, const propid_filter_t *plain,
                                   const float expected_block[3][3])
{
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = a; b < 3u; ++b) {
            const float expected = expected_block[a][b];
            const uint32_t k = propid_cov_index(a, b);
            const float added = with->core.cov[k] - plain->core.cov[k];
            TEST_ASSERT_FLOAT_WITHIN(1.0e-3f * fabsf(expected) + 1.0e-6f * fabsf(with->core.cov[k]), expected,
                                     added);
            if (a == b) {
                TEST_ASSERT_TRUE(expected > 0.0f);
            }
        }
    }
    const uint8_t n = with->derived.state_count;
    for (uint8_t i = 0; i < n; ++i) {
        for (uint8_t j = i; j < n; ++j) {
            if (j < 3u) {
                continue;
            }
            const uint32_t k = propid_cov_index(i, j);
            TEST_ASSERT_EQUAL_MEMORY(&plain->core.cov[k], &with->core.cov[k], sizeof(float));
        }
    }
}

static void check_block(const propid_filter_t *with, const propid_filter_t *plain, const float *span, float sigma,
                        float dt)
{
    float gain[3][PROPID_MAX_ROTORS];
    input_error_dense_gain(with, gain);
    float expected[3][3] = {{0.0f}};
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = a; b < 3u; ++b) {
            for (uint8_t i = 0; i < with->config.rotor_count; ++i) {
                const float mean_u = 0.5f * (with->core.input_speed_sq[i] + with->core.rotor_speed_sq[i]);
                expected[a][b] += gain[a][i] * gain[b][i] * 4.0f * sigma * sigma * mean_u * dt * span[i];
            }
        }
    }
    check_rate_block_added(with, plain, (const float (*)[3])expected);
}

static void check_added_block(uint8_t rotors, int full_inertia, float time)
{
    const float sigma = 3.0f;
    const float dt = 0.002f;
    propid_config_t config;
    input_error_configure(&config, rotors, full_inertia);
    input_error_off_prior(&without_noise, &config);
    config.rotor_speed_noise = sigma;
    config.rotor_speed_noise_time = time;
    input_error_off_prior(&with_noise, &config);

    input_error_predict_pair(&without_noise, &with_noise, dt);
    float span[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotors; ++i) {
        span[i] = time > dt ? time : dt;
    }
    check_block(&with_noise, &without_noise, span, sigma, dt);
}

static void test_input_noise_adds_its_block_to_the_rate_covariance(void)
{
    check_added_block(4u, 0, 0.0f);    /* quad layout, one step */
    check_added_block(4u, 0, 0.02f);   /* quad layout, a longer correlation time */
    check_added_block(4u, 1, 0.01f);   /* general lists (full inertia) */
    check_added_block(6u, 0, 0.0f);    /* hexa */
}

static void test_input_noise_off_is_the_plain_prediction(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    input_error_off_prior(&without_noise, &config);
    config.rotor_speed_noise_time = 0.05f; /* a time alone switches nothing on */
    input_error_off_prior(&with_noise, &config);
    input_error_predict_pair(&without_noise, &with_noise, 0.002f);
    TEST_ASSERT_EQUAL_MEMORY(without_noise.core.cov, with_noise.core.cov, sizeof(with_noise.core.cov));
}

/* The truncation split (rotor_speed_noise_split): the root mean square sigma = q / sqrt(3)
 * becomes the spread q / sqrt(12) = sigma / 2 per rotor (the filter without the split at
 * sigma / 2) plus the mean q / 2, common to every rotor: exactly the rank-one block along
 * along^T on top, along_a = sum_i B_ai sqrt(3 sigma^2 u_i dt span_i), B dense; nothing
 * outside the rate block. */
static void check_common_block(uint8_t rotors, int full_inertia, float time)
{
    const float sigma = 3.0f;
    const float dt = 0.002f;
    propid_config_t config;
    input_error_configure(&config, rotors, full_inertia);
    config.rotor_speed_noise = 0.5f * sigma;
    config.rotor_speed_noise_time = time;
    input_error_off_prior(&without_noise, &config);
    config.rotor_speed_noise = sigma;
    config.rotor_speed_noise_split = 1u;
    input_error_off_prior(&with_noise, &config);

    input_error_predict_pair(&without_noise, &with_noise, dt);
    const float span = time > dt ? time : dt;
    float gain[3][PROPID_MAX_ROTORS];
    input_error_dense_gain(&with_noise, gain);
    float along[3] = {0.0f, 0.0f, 0.0f};
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t i = 0; i < rotors; ++i) {
            const float mean_u = 0.5f * (with_noise.core.input_speed_sq[i] + with_noise.core.rotor_speed_sq[i]);
            along[a] += gain[a][i] * sqrtf(3.0f * sigma * sigma * mean_u * dt * span);
        }
    }
    float expected[3][3] = {{0.0f}};
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = a; b < 3u; ++b) {
            expected[a][b] = along[a] * along[b];
        }
    }
    check_rate_block_added(&with_noise, &without_noise, (const float (*)[3])expected);
}

static void test_common_input_error_adds_its_rank_one_block(void)
{
    check_common_block(4u, 0, 0.0f);  /* quad layout, one step */
    check_common_block(4u, 0, 1.0f);  /* quad layout, held 1 s */
    check_common_block(4u, 1, 0.01f); /* general lists (full inertia) */
    check_common_block(6u, 0, 0.5f);  /* hexa */
}

/* Six prediction steps of dt from with_noise as set up: from the second step on
 * rotor 0's speed changes every step and rotors 2 and 3 change at the fourth;
 * each step's rate block must be the term with expected_span[step][rotor] dt
 * (rotors past the fourth stand like rotor 1), and the state the plain step's. */
static void check_held_spans(uint8_t rotors, float sigma, float dt, const float expected_span[6][4])
{
    for (uint8_t step = 0; step < 6u; ++step) {
        if (step > 0u) {
            memcpy(with_noise.core.input_speed_sq, with_noise.core.rotor_speed_sq,
                   sizeof(with_noise.core.input_speed_sq));
            with_noise.core.rotor_speed_sq[0] += 100.0f;
            if (step == 3u) {
                with_noise.core.rotor_speed_sq[2] += 100.0f;
                with_noise.core.rotor_speed_sq[3] += 100.0f;
            }
        }
        without_noise = with_noise;
        without_noise.derived.input_noise_var = 0.0f; /* the same step without the term */
        input_error_predict_pair(&without_noise, &with_noise, dt);
        float span[PROPID_MAX_ROTORS];
        for (uint8_t i = 0; i < rotors; ++i) {
            span[i] = dt * expected_span[step][i < 4u ? i : 1u];
        }
        check_block(&with_noise, &without_noise, span, sigma, dt);
        /* Only the covariance moves: the state is the same step's. */
        TEST_ASSERT_EQUAL_MEMORY(without_noise.core.state, with_noise.core.state, sizeof(with_noise.core.state));
    }
}

/* rotor_speed_noise_hold (docs/math.md §14, "Hold time from the telemetry"): a
 * rotor whose value changes within the step gets one step's span dt; one whose
 * value has stood for a gets dt + 2 a, bounded by the configured time; a change
 * starts the age again. Five steps of dt = 2 ms, ceiling 10 ms = 5 dt: rotor 0
 * changes every step, rotors 1 to 3 stand, rotors 2 and 3 change at the fourth
 * step. With one configured time every span would be 10 ms. */
static void test_held_input_error_spans_from_the_telemetry(void)
{
    static const uint8_t quad_and_hexa[2] = {4u, 6u};
    for (uint8_t v = 0; v < 2u; ++v) {
        const uint8_t rotors = quad_and_hexa[v];
        const float sigma = 3.0f;
        const float dt = 0.002f;
        propid_config_t config;
        input_error_configure(&config, rotors, 0);
        config.rotor_speed_noise = sigma;
        config.rotor_speed_noise_time = 5.0f * dt;
        config.rotor_speed_noise_hold = 1u;
        input_error_off_prior(&with_noise, &config);
        /* In units of dt, per step and rotor (rotors 4, 5 of the hexa stand like 1):
         * a held error's first full step 1, then 3, 5, ... ((n + 1)^2 - n^2). */
        static const float expected_span[6][4] = {
            {1.0f, 1.0f, 1.0f, 1.0f}, /* step 0: the fixture's speeds differ at both ends */
            {1.0f, 1.0f, 1.0f, 1.0f}, /* the new values' first full step */
            {1.0f, 3.0f, 3.0f, 3.0f}, /* stood one step */
            {1.0f, 5.0f, 1.0f, 1.0f}, /* two: 5 dt (the ceiling); rotors 2 and 3 change */
            {1.0f, 5.0f, 1.0f, 1.0f}, /* 7 dt bounded to 5 dt */
            {1.0f, 5.0f, 3.0f, 3.0f},
        };
        check_held_spans(rotors, sigma, dt, expected_span);
    }
}

/* rotor_speed_noise_hold = 2 (docs/math.md §14, "The hold as a floor"): the same age,
 * with the configured time the span's floor and no ceiling below the configuration's
 * largest time. Same five steps as above, floor 2 dt: a rotor that changes every step
 * keeps 2 dt (the hold alone would give dt), a standing one grows past the 5 dt the
 * ceiling gave (7 dt, 9 dt). */
static void test_held_input_error_with_the_time_as_floor(void)
{
    static const uint8_t quad_and_hexa[2] = {4u, 6u};
    for (uint8_t v = 0; v < 2u; ++v) {
        const uint8_t rotors = quad_and_hexa[v];
        const float sigma = 3.0f;
        const float dt = 0.002f;
        propid_config_t config;
        input_error_configure(&config, rotors, 0);
        config.rotor_speed_noise = sigma;
        config.rotor_speed_noise_time = 2.0f * dt;
        config.rotor_speed_noise_hold = 2u;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, NULL));
        input_error_off_prior(&with_noise, &config);
        static const float expected_span[6][4] = {
            {2.0f, 2.0f, 2.0f, 2.0f}, /* changed: dt, raised to the floor */
            {2.0f, 2.0f, 2.0f, 2.0f}, /* the new values' first full step: dt, floor */
            {2.0f, 3.0f, 3.0f, 3.0f}, /* stood one step */
            {2.0f, 5.0f, 2.0f, 2.0f}, /* rotors 2 and 3 change */
            {2.0f, 7.0f, 2.0f, 2.0f}, /* past the time: no ceiling at 2 dt */
            {2.0f, 9.0f, 3.0f, 3.0f},
        };
        check_held_spans(rotors, sigma, dt, expected_span);
    }
}

/* The hold with a configured time of one step or less is the plain term, bit for
 * bit: every span is dt either way. */
static void test_held_input_error_within_one_step_is_the_plain_term(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    config.rotor_speed_noise = 3.0f;
    config.rotor_speed_noise_time = 0.001f;
    input_error_off_prior(&without_noise, &config);
    config.rotor_speed_noise_hold = 1u;
    input_error_off_prior(&with_noise, &config);
    for (uint8_t step = 0; step < 3u; ++step) {
        input_error_predict_pair(&without_noise, &with_noise, 0.002f);
        TEST_ASSERT_EQUAL_MEMORY(without_noise.core.cov, with_noise.core.cov, sizeof(with_noise.core.cov));
    }
}

/* The configuration is refused by the field's name. */
static void check_refused(const propid_config_t *config, const char *name)
{
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(config, &bad));
    TEST_ASSERT_EQUAL_STRING(name, bad);
}

/* Each of `values` in `*field` is refused by that field's name. */
static void check_values_refused(propid_config_t *config, float *field, const float *values, uint8_t count,
                                 const char *name)
{
    for (uint8_t k = 0; k < count; ++k) {
        *field = values[k];
        check_refused(config, name);
    }
}

static void test_input_noise_config_is_checked(void)
{
    propid_config_t config;
    input_error_configure(&config, 4u, 0);
    const char *bad = NULL;
    const float bad_noise[] = {-1.0f, NAN, INFINITY, 1.0e5f};
    check_values_refused(&config, &config.rotor_speed_noise, bad_noise, 4u, "rotor_speed_noise");
    config.rotor_speed_noise = 2.0f;
    const float bad_time[] = {-0.1f, NAN, 1.01f * PROPID_ROTOR_SPEED_NOISE_TIME_MAX};
    check_values_refused(&config, &config.rotor_speed_noise_time, bad_time, 3u, "rotor_speed_noise_time");
    config.rotor_speed_noise_time = PROPID_ROTOR_SPEED_NOISE_TIME_MAX;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_speed_noise_time = 0.002f;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    /* The hold: 0, 1 or 2 (the time as floor), with an error size, not with the
     * compensation. */
    config.rotor_speed_noise_hold = 3u;
    check_refused(&config, "rotor_speed_noise_hold");
    config.rotor_speed_noise_hold = 2u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_speed_noise_hold = 1u;
    config.input_error_compensation = 1u;
    check_refused(&config, "rotor_speed_noise_hold");
    config.input_error_compensation = 0u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    /* The split: 0 or 1, of an error of a size, not with the compensation. */
    config.rotor_speed_noise_split = 2u;
    check_refused(&config, "rotor_speed_noise_split");
    config.rotor_speed_noise_split = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_check(&config, &bad));
    config.rotor_speed_noise_hold = 0u;
    config.input_error_compensation = 1u;
    check_refused(&config, "rotor_speed_noise_split");
    config.input_error_compensation = 0u;
    config.rotor_speed_noise_hold = 1u;
    config.rotor_speed_noise = 0.0f;
    check_refused(&config, "rotor_speed_noise_hold");
    config.rotor_speed_noise_hold = 0u;
    check_refused(&config, "rotor_speed_noise_split");
}

/* The largest accepted error (sigma = max_rotor_speed, correlated over 1 s, and over
 * the largest time with the hold from the telemetry, whose held speed here stands for
 * the whole run, and with the hold above a floor of 1 s, growing to that time, split into a
 * common mean and a spread) at full speed with wild body rates: every push is accepted or gated
 * by a status, the estimates stay finite and the variances positive. */
static void test_largest_input_noise_keeps_the_filter_finite(void)
{
    const float times[3] = {1.0f, PROPID_ROTOR_SPEED_NOISE_TIME_MAX, 1.0f};
    for (uint8_t run = 0; run < 3u; ++run) {
        propid_config_t config;
        input_error_configure(&config, 4u, 0);
        config.rotor_speed_noise = config.max_rotor_speed;
        config.rotor_speed_noise_time = times[run];
        config.rotor_speed_noise_hold = run;
        config.rotor_speed_noise_split = run == 2u; /* and split, a common part */
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_init(&with_noise, &config));
        uint64_t t = 1000u;
        for (uint32_t k = 0; k < 2000u; ++k) {
            const float spin = config.max_rotor_speed * (0.5f + 0.5f * (float)((k * 7u) % 11u) / 10.0f);
            const float speeds[4] = {spin, config.max_rotor_speed, 0.3f * spin, spin};
            const propid_status_t rotor_status = propid_push_rotor_speeds(&with_noise, t, speeds, 4u);
            TEST_ASSERT_TRUE(rotor_status >= 0 || rotor_status == PROPID_ERR_ROTOR_SPEED_RANGE);
            const float sign = (k % 2u) ? 1.0f : -1.0f;
            const float gyro[3] = {sign * 0.9f * config.gyro_range, -sign * 5.0f, 3.0f};
            TEST_ASSERT_TRUE(propid_push_gyro(&with_noise, t + 500u, gyro) >= 0);
            t += 2000u;
        }
        propid_estimate_t estimate;
        TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_get_estimate(&with_noise, &estimate));
        TEST_ASSERT_EQUAL_UINT32(0u, with_noise.counters.cov_repairs); /* Q_u is positive semi-definite */
        for (uint8_t i = 0; i < 4u; ++i) {
            TEST_ASSERT_TRUE(isfinite(estimate.thrust_coeff[i]) && estimate.thrust_coeff_std[i] > 0.0f);
            TEST_ASSERT_TRUE(isfinite(estimate.drag_coeff[i]) && estimate.drag_coeff_std[i] > 0.0f);
        }
        for (uint8_t a = 0; a < 3u; ++a) {
            TEST_ASSERT_TRUE(isfinite(estimate.body_rate[a]) && estimate.body_rate_std[a] > 0.0f);
            TEST_ASSERT_TRUE(isfinite(estimate.body_rate_std[a]));
        }
    }
}
#else
static void test_input_noise_compiled_out_refuses_the_option(void)
{
    propid_config_t config;
    test_vehicle_config(&config, 4u, 0.17f, 0.785398f);
    config.rotor_speed_noise = 1.0f;
    const char *bad = NULL;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_speed_noise", bad);
    config.rotor_speed_noise = 0.0f;
    config.rotor_speed_noise_split = 1u;
    TEST_ASSERT_EQUAL_INT(PROPID_ERR_CONFIG, propid_config_check(&config, &bad));
    TEST_ASSERT_EQUAL_STRING("rotor_speed_noise_split", bad);
}
#endif

int main(void)
{
    UNITY_BEGIN();
#if PROPID_WITH_INPUT_NOISE
    RUN_TEST(test_input_noise_adds_its_block_to_the_rate_covariance);
    RUN_TEST(test_input_noise_off_is_the_plain_prediction);
    RUN_TEST(test_common_input_error_adds_its_rank_one_block);
    RUN_TEST(test_held_input_error_spans_from_the_telemetry);
    RUN_TEST(test_held_input_error_with_the_time_as_floor);
    RUN_TEST(test_held_input_error_within_one_step_is_the_plain_term);
    RUN_TEST(test_input_noise_config_is_checked);
    RUN_TEST(test_largest_input_noise_keeps_the_filter_finite);
#else
    RUN_TEST(test_input_noise_compiled_out_refuses_the_option);
#endif
    return UNITY_END();
}
