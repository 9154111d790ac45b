/*
 * The filter's input-error terms from the sensor model (sensor_errors.h):
 * the DShot step at the flown hover speed, the latency and the held report's
 * mean age, against an independent computation.
 */
#include <math.h>

#include "esc_telemetry.h"
#include "propid/propid.h"
#include "sensor_errors.h"
#include "sitl_math.h"
#include "unity.h"
#include "vehicle.h"

void setUp(void)
{
}

void tearDown(void)
{
}

/* The speed a whole-microsecond electrical period decodes to (no mantissa
 * shift: periods up to 511 us). */
static double speed_of_period(double period_us, int pole_pairs)
{
    return 2.0 * SITL_PI * 1e6 / (period_us * (double)pole_pairs);
}

/* A preset with the default ESC and its sensor errors at the file's hover. */
static void preset_errors(const char *preset, sitl_vehicle_t *v, sitl_esc_params_t *esc, sitl_sensor_errors_t *errors)
{
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset(preset, v));
    sitl_esc_default_params(esc);
    TEST_ASSERT_EQUAL_INT(0, sitl_sensor_errors(v, esc, NULL, errors));
}

static void test_crazyflie_dshot_step_at_hover(void)
{
    sitl_vehicle_t v;
    sitl_esc_params_t esc;
    sitl_sensor_errors_t e;
    preset_errors("crazyflie-x", &v, &esc, &e);
    double hover = sqrt(0.03 * 9.81 / (4.0 * 2.3e-8));
    TEST_ASSERT_DOUBLE_WITHIN(1e-9 * hover, hover, e.hover_speed);
    /* Hover period 501.9 us: truncated to 501, the next code 502. */
    double period = floor(2.0 * SITL_PI * 1e6 / (hover * 7.0));
    TEST_ASSERT_EQUAL_DOUBLE(501.0, period);
    double step = speed_of_period(period, 7) - speed_of_period(period + 1.0, 7);
    /* The truncation's error is uniform over [0, step): RMS about 0 step / sqrt(3). */
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, step / sqrt(3.0), e.rotor_speed_noise);
    TEST_ASSERT_DOUBLE_WITHIN(0.05, 2.06, e.rotor_speed_noise);
    TEST_ASSERT_EQUAL_INT(1, e.rotor_speed_noise_truncated); /* the split has a mean to share */
    TEST_ASSERT_EQUAL_DOUBLE(SITL_HELD_STEP_TIME_S, e.rotor_speed_noise_time);
    TEST_ASSERT_EQUAL_DOUBLE(esc.latency_s, e.rotor_delay_s);
}

static void test_hummingbird_step_with_mantissa_shift(void)
{
    /* Hover period 1 913 us > 511: the code keeps 9 bits, a step of 4 us. */
    sitl_vehicle_t v;
    sitl_esc_params_t esc;
    sitl_sensor_errors_t e;
    preset_errors("hummingbird-x", &v, &esc, &e);
    double period = floor(2.0 * SITL_PI * 1e6 / (e.hover_speed * 7.0));
    double coded = floor(period / 4.0) * 4.0;
    double step = speed_of_period(coded, 7) - speed_of_period(coded + 4.0, 7);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, step / sqrt(3.0), e.rotor_speed_noise);
}

/* The step at the hover speed the rotors fly: a Crazyflie whose rotors make 6 % more
 * thrust than the file's hovers 3 % slower, at a period above 511 us, where the code
 * keeps 9 bits of a 2 us count: twice the step of the file's hover speed. */
static void test_step_at_the_flown_hover_speed(void)
{
    sitl_vehicle_t v;
    sitl_esc_params_t esc;
    sitl_sensor_errors_t nominal;
    preset_errors("crazyflie-x", &v, &esc, &nominal);
    double flown_kf[SITL_MAX_ROTORS];
    for (int i = 0; i < v.rotor_count; i++) {
        flown_kf[i] = 1.06 * v.rotor[i].thrust_coeff;
    }
    sitl_sensor_errors_t e;
    TEST_ASSERT_EQUAL_INT(0, sitl_sensor_errors(&v, &esc, flown_kf, &e));
    TEST_ASSERT_DOUBLE_WITHIN(1e-9 * e.hover_speed, nominal.hover_speed / sqrt(1.06), e.hover_speed);
    double period = floor(2.0 * SITL_PI * 1e6 / (e.hover_speed * 7.0));
    TEST_ASSERT_TRUE(period > 511.0);
    double coded = floor(period / 2.0) * 2.0;
    double step = speed_of_period(coded, 7) - speed_of_period(coded + 2.0, 7);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, step / sqrt(3.0), e.rotor_speed_noise);
    TEST_ASSERT_TRUE(e.rotor_speed_noise > 1.8 * nominal.rotor_speed_noise);
}

/* Decoded at the middle of the code's period interval the error has no mean left:
 * its spread alone, step / sqrt(12), half the root mean square of the period decode,
 * held while the code stands. */
static void test_middle_decode_gives_the_spread_alone(void)
{
    sitl_vehicle_t v;
    sitl_esc_params_t esc;
    sitl_sensor_errors_t edge;
    preset_errors("crazyflie-x", &v, &esc, &edge);
    esc.decode_middle = 1;
    sitl_sensor_errors_t e;
    TEST_ASSERT_EQUAL_INT(0, sitl_sensor_errors(&v, &esc, NULL, &e));
    double period = floor(2.0 * SITL_PI * 1e6 / (e.hover_speed * 7.0));
    double step = speed_of_period(period, 7) - speed_of_period(period + 1.0, 7);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, step / sqrt(12.0), e.rotor_speed_noise);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 0.5 * edge.rotor_speed_noise, e.rotor_speed_noise);
    TEST_ASSERT_EQUAL_INT(0, e.rotor_speed_noise_truncated); /* no mean to share */
    /* Held as long as the rotor's code stands, up to the firmware's largest time. */
    TEST_ASSERT_EQUAL_INT(1, e.rotor_speed_noise_hold);
    TEST_ASSERT_EQUAL_DOUBLE((double)PROPID_ROTOR_SPEED_NOISE_TIME_MAX, e.rotor_speed_noise_time);
    TEST_ASSERT_EQUAL_INT(0, edge.rotor_speed_noise_hold);
    TEST_ASSERT_EQUAL_DOUBLE(SITL_HELD_STEP_TIME_S, edge.rotor_speed_noise_time);
}

static void test_exact_speeds_have_no_input_noise(void)
{
    sitl_vehicle_t v;
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset("crazyflie-plus", &v));
    sitl_esc_params_t esc;
    sitl_esc_paper_params(&esc, 500.0);
    sitl_sensor_errors_t e;
    TEST_ASSERT_EQUAL_INT(0, sitl_sensor_errors(&v, &esc, NULL, &e));
    TEST_ASSERT_EQUAL_DOUBLE(0.0, e.rotor_speed_noise);
    TEST_ASSERT_EQUAL_DOUBLE(0.0, e.rotor_delay_s);
}

/* The mean age of the newest report at the gyro samples (--filter-report-age),
 * against the instants counted by hand: the default sensors (reports every 2 ms from
 * 0.25 ms, measured 1 ms before arrival; gyro every 1 ms from 1 ms) hold, at the gyro
 * samples, reports aged 0.75 and 1.75 ms in turn: 1.25 ms. The paper's reports at the
 * gyro instants without latency: 0. Reports every 3 ms from 0 against a 1 kHz gyro,
 * no latency: ages 1, 2, 0 ms in turn: 1 ms (half the period, as unlocked clocks
 * average). */
static void test_report_mean_age(void)
{
    sitl_esc_params_t esc;
    sitl_esc_default_params(&esc);
    esc.rate_hz = 500.0;
    esc.phase_s = 0.25e-3;
    esc.latency_s = 1e-3;
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 1.25e-3, sitl_report_mean_age(&esc, 1000.0, 1e-3));
    sitl_esc_paper_params(&esc, 500.0);
    TEST_ASSERT_DOUBLE_WITHIN(1e-9, 0.0, sitl_report_mean_age(&esc, 500.0, 2e-3));
    esc.rate_hz = 1000.0 / 3.0;
    TEST_ASSERT_DOUBLE_WITHIN(2e-6, 1e-3, sitl_report_mean_age(&esc, 1000.0, 1e-3));
}

static void test_rejects_a_vehicle_without_hover(void)
{
    sitl_vehicle_t v;
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset("crazyflie-x", &v));
    for (int i = 0; i < v.rotor_count; i++) {
        v.rotor[i].thrust_coeff = 0.0;
    }
    sitl_esc_params_t esc;
    sitl_esc_default_params(&esc);
    sitl_sensor_errors_t e;
    TEST_ASSERT_EQUAL_INT(-1, sitl_sensor_errors(&v, &esc, NULL, &e));
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_crazyflie_dshot_step_at_hover);
    RUN_TEST(test_hummingbird_step_with_mantissa_shift);
    RUN_TEST(test_middle_decode_gives_the_spread_alone);
    RUN_TEST(test_step_at_the_flown_hover_speed);
    RUN_TEST(test_exact_speeds_have_no_input_noise);
    RUN_TEST(test_report_mean_age);
    RUN_TEST(test_rejects_a_vehicle_without_hover);
    return UNITY_END();
}
