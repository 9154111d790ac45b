/*
 * Fault injection in the SITL (sitl/faults, docs/sitl.md "Faults"): every class
 * fires at its rate, the filter refuses what is wrong with the right status,
 * never reports a non-finite estimate, and follows a rotor that loses thrust;
 * the parser refuses unknown names and out-of-range rates.
 */
#include <math.h>
#include <string.h>

#include "faults.h"
#include "sim.h"
#include "unity.h"

static sitl_options_t opts;
static sitl_result_t result;

void setUp(void)
{
    sitl_options_default(&opts);
    opts.quiet = 1;
}

void tearDown(void)
{
}

static void add(const char *text)
{
    char err[256];
    TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_faults_parse(&opts.faults, text, err, (int)sizeof(err)), err);
}

static void assert_finite_estimate(void)
{
    const propid_estimate_t *e = &result.estimate;
    for (int a = 0; a < 3; ++a) {
        TEST_ASSERT_TRUE(isfinite(e->body_rate[a]) && isfinite(e->gyro_bias[a]));
        TEST_ASSERT_TRUE(isfinite(e->innovation_test_ratio[a]));
    }
    for (int i = 0; i < result.rotor_count; ++i) {
        TEST_ASSERT_TRUE(isfinite(e->thrust_coeff[i]) && isfinite(e->drag_coeff[i]));
        TEST_ASSERT_TRUE(e->thrust_coeff_std[i] > 0.0f && isfinite(e->thrust_coeff_std[i]));
    }
}

/* Every class at once, oracle controller (the vehicle flies on true
 * coefficients, so the flight itself cannot diverge from the filter's faults). */
static void test_every_class_fires_and_the_filter_answers(void)
{
    opts.mode = SITL_MODE_ORACLE;
    opts.duration_s = 20.0;
    add("esc_dropout=0.1");
    add("esc_spike=0.01");
    add("esc_stuck=0.002");
    add("esc_stale=0.001");
    add("gyro_spike=0.005");
    add("gyro_saturation=0.002");
    add("gyro_stuck=0.001");
    add("time_jitter=20");
    add("time_repeat=0.002");
    add("time_backward=0.002");
    add("time_jump=0.0002");
    add("rotor_loss=10");
    TEST_ASSERT_EQUAL_INT_MESSAGE(SITL_EXIT_OK, sitl_run(&opts, &result, NULL), result.message);
    for (int k = 0; k < SITL_FAULT_COUNT; ++k) {
        TEST_ASSERT_TRUE_MESSAGE(result.faults_injected[k] > 0, sitl_fault_name((sitl_fault_class_t)k));
    }
    const propid_counters_t *c = &result.counters;
    TEST_ASSERT_TRUE(c->rejected[-(int)PROPID_ERR_TIME_BACKWARDS] > 0u);
    TEST_ASSERT_TRUE(c->rejected[-(int)PROPID_ERR_GYRO_RANGE] > 0u);
    TEST_ASSERT_TRUE(c->resyncs > 0u);
    TEST_ASSERT_TRUE(c->axis_gated[0] + c->axis_gated[1] + c->axis_gated[2] > 0u);
    assert_finite_estimate();
}

/* Rotor 0 losing 30 % of its thrust at 5 s: 25 s later the coefficients are
 * near the new truth (measured: 6 %). (With stuck gyro axes 10 % of the time
 * on top, the re-opens fuse stuck readings and kf ends ~30 % off: see
 * docs/reliability.md.) */
static void test_recovers_after_a_rotor_loses_thrust(void)
{
    opts.mode = SITL_MODE_ORACLE;
    opts.duration_s = 30.0;
    add("rotor_loss=5");
    TEST_ASSERT_EQUAL_INT_MESSAGE(SITL_EXIT_OK, sitl_run(&opts, &result, NULL), result.message);
    assert_finite_estimate();
    TEST_ASSERT_EQUAL_INT(1, (int)result.faults_injected[SITL_FAULT_ROTOR_LOSS]);
    TEST_ASSERT_TRUE_MESSAGE(result.kf_rel_error_max < 0.15, "kf not recovered after rotor loss");
}

static void test_parser_refuses_bad_text(void)
{
    char err[256];
    sitl_fault_config_t c;
    memset(&c, 0, sizeof(c));
    TEST_ASSERT_EQUAL_INT(-1, sitl_faults_parse(&c, "esc_dropout", err, (int)sizeof(err)));
    TEST_ASSERT_EQUAL_INT(-1, sitl_faults_parse(&c, "esc_dropout=2", err, (int)sizeof(err)));
    TEST_ASSERT_EQUAL_INT(-1, sitl_faults_parse(&c, "cosmic_ray=0.1", err, (int)sizeof(err)));
    TEST_ASSERT_EQUAL_INT(0, sitl_faults_parse(&c, "time_jitter=30", err, (int)sizeof(err)));
    TEST_ASSERT_EQUAL_INT(1, c.enabled);
    TEST_ASSERT_EQUAL_INT(0, sitl_faults_parse(&c, "none", err, (int)sizeof(err)));
    TEST_ASSERT_EQUAL_INT(0, c.enabled);
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_every_class_fires_and_the_filter_answers);
    RUN_TEST(test_recovers_after_a_rotor_loses_thrust);
    RUN_TEST(test_parser_refuses_bad_text);
    return UNITY_END();
}
